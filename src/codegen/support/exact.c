/* The exact velocity-level step (generate --lang c --solver exact): the Rust module's
   (src/codegen/support/exact.rs), the same operations in the same order: per substep
   A P = -(J u + dC/dt + C/h) through solve_rows (support/rows.c), then a Newton projection of
   the positions onto C = 0. */

/* Relative tolerance (of the scene's length) and iteration cap of the projection. */
#define LG_PROJECTION_TOLERANCE 1e-13
#define LG_PROJECTION_ITERATIONS 20

/* The rows of a prepared state as the solve reads them. */
static void solve_input(const Prepared *p, Rows *rows) {
    int k, e, d;
    for (k = 0; k < CONSTRAINTS; k++) {
        rows->value[k] = p->value[k];
        rows->rate[k] = p->rate[k];
        rows->bias[k] = p->bias[k];
        rows->inequality[k] = INEQUALITY[k];
    }
    /* The solve's entries in the derivation's order, the step's at ENTRY_AT. */
    for (e = 0; e < ROW_ENTRIES; e++) {
        for (d = 0; d < DIM; d++) {
            rows->jacobian[e][d] = p->jacobian[ENTRY_AT[e]][d];
        }
    }
}

/* A row left out of a solve: an inactive inequality (P = 0). */
static void leave_out(Rows *rows, int k) {
    rows->inequality[k] = 1;
    rows->value[k] = DBL_MAX;
    rows->rate[k] = DBL_MAX;
    rows->bias[k] = 0.0;
}

/* A row enforced with target -bias. */
static void enforce(Rows *rows, int k, double bias) {
    rows->value[k] = 0.0;
    rows->rate[k] = 0.0;
    rows->bias[k] = bias;
}

/* Row k's first-order distance to its surface, (C/kappa)/|J| (+-infinity where J = 0, C != 0). */
static double distance(const Rows *rows, int k) {
    const int from = ROW_START[k], count = ROW_START[k + 1] - from;
    const double n = count > 0 ? lg_safe_norm(&rows->jacobian[from][0], count * DIM) : 0.0;
    const double value = rows->value[k];
    if (n > 0.0 && isfinite(n)) {
        return value / n;
    }
    if (value == 0.0) {
        return 0.0;
    }
    return copysign(INFINITY, value);
}

static double scene_length(const State *s) {
    double x[BODIES > 0 ? BODIES : 1][DIM];
    positions(s, x);
    return length_scale(x, BODIES);
}

/* Newton onto C = 0 (equalities and violated inequalities) until every such row is within
   bound of its surface or max_iterations are spent; q (the state's slots) and the state move
   together, v stays. */
static void project(State *s, double q[][DIM], double v[][DIM], double q0[][4], double bound, int max_iterations) {
    static double unforced[SLOTS][DIM];
    int iterations = 0, k, i, d;
    Prepared p;
    Rows rows;
    Solution x;
    for (;;) {
        double residual = 0.0;
        step_rows(s, &p);
        p.first = first_angular(&p);
        solve_input(&p, &rows);
        for (k = 0; k < CONSTRAINTS; k++) {
            const double at = distance(&rows, k);
            if (!INEQUALITY[k] || at < 0.0) {
                residual = fmax(residual, fabs(at));
            }
        }
        if (residual <= bound || iterations >= max_iterations) {
            return;
        }
        for (k = 0; k < CONSTRAINTS; k++) {
            const double at = distance(&rows, k);
            if (!INEQUALITY[k] || at < 0.0) {
                enforce(&rows, k, rows.value[k]);
            } else {
                leave_out(&rows, k);
            }
        }
        /* dq = M^-1 J^T mu over the rows' slots, a 3D body's turn folded into a world vector. */
        solve_rows(&rows, p.inverse_mass, p.velocity, unforced, scene_length(s), &x);
        fold(&p, x.acceleration);
        for (i = 0; i < SLOTS; i++) {
            for (d = 0; d < DIM; d++) {
                if (isfinite(x.acceleration[i][d])) {
                    q[i][d] += x.acceleration[i][d];
                }
            }
        }
        state_put(s, state_time(s), q, v, q0);
        iterations++;
    }
}

/* One exact step of dt in settings->substeps substeps (the Rust module's step_with); impulses
   receives the impulse of each row over the last substep. */
void step_with(State *s, double impulses[], double dt, const StepSettings *settings) {
    static double unforced[SLOTS][DIM];
    const double h = dt / (double)settings->substeps;
    const double t = state_time(s);
    const double length = scene_length(s);
    double q[SLOTS][DIM], v[SLOTS][DIM], q0[RIGID_3D > 0 ? RIGID_3D : 1][4];
    Prepared p;
    Rows rows;
    Solution x;
    int sub, k, i, d;
    state_get(s, q, v, q0);
    for (sub = 0; sub < settings->substeps; sub++) {
        rebase(q0, q, sub == 0);
        prepare(s, &p);
        solve_input(&p, &rows);
        to_axes(&p, v);
        kick(&p, v, h);
        for (k = 0; k < CONSTRAINTS; k++) {
            /* Target: dC = -(J u + dC/dt + C/h). */
            const double bias = row_rate(&p, k, v) + p.value[k] / h;
            if (INEQUALITY[k] && bias >= 0.0) {
                leave_out(&rows, k);
            } else {
                enforce(&rows, k, bias);
            }
        }
        solve_rows(&rows, p.inverse_mass, p.velocity, unforced, length, &x);
        for (i = 0; i < SLOTS; i++) {
            for (d = 0; d < DIM; d++) {
                if (isfinite(x.acceleration[i][d])) {
                    v[i][d] += x.acceleration[i][d];
                }
            }
        }
        for (k = 0; k < CONSTRAINTS; k++) {
            impulses[k] = x.lambda[k];
        }
        to_world(&p, v);
        drift(&p, q, v, h);
        state_put(s, t + (double)(sub + 1) * h, q, v, q0);
        project(s, q, v, q0, LG_PROJECTION_TOLERANCE * length, LG_PROJECTION_ITERATIONS);
    }
}

/* One exact step of dt with the defaults; impulses receives the last substep's impulses. */
void step(State *s, double impulses[], double dt) {
    const StepSettings settings = step_settings_default();
    step_with(s, impulses, dt, &settings);
}
