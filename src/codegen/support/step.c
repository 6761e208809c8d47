/* The velocity-level step (generate --lang c --solver): the Rust module's step, the same
   operations in the same order (src/codegen/support/step.rs, sweep.rs, soft_step.rs, pgs.rs). */

/* Box2D's b2Softness: bias rate on C/kappa, scale on the effective mass, scale on the
   accumulated impulse. */
typedef struct Softness {
    double bias_rate, mass_scale, impulse_scale;
} Softness;

static const Softness RIGID = {0.0, 1.0, 0.0};

/* b2MakeSoft: omega = 2 pi hertz, a1 = 2 zeta + h omega, a2 = h omega a1, a3 = 1/(1 + a2). */
static Softness make_soft(double hertz, double zeta, double h) {
    Softness s;
    double omega, a1, a2, a3;
    if (hertz == 0.0) {
        return RIGID;
    }
    omega = 2.0 * 3.141592653589793 * hertz;
    a1 = 2.0 * zeta + h * omega;
    a2 = h * omega * a1;
    a3 = 1.0 / (1.0 + a2);
    s.bias_rate = omega / a1;
    s.mass_scale = a2 * a3;
    s.impulse_scale = a3;
    return s;
}

/* How step_with runs one step; step_settings_default() gives Box2D v3's defaults. */
typedef struct StepSettings {
    int substeps, iterations, cap_hertz, relax, warm_start;
    double hertz, damping_ratio, restitution, restitution_threshold, baumgarte;
} StepSettings;

StepSettings step_settings_default(void) {
    StepSettings s;
    s.substeps = 4;
    s.iterations = DEFAULT_ITERATIONS;
    s.hertz = 60.0;
    s.damping_ratio = 2.0;
    s.cap_hertz = 1;
    s.relax = 1;
    s.warm_start = 1;
    s.restitution = 0.0;
    s.restitution_threshold = 1.0;
    s.baumgarte = 0.2;
    return s;
}

static double lg_dot(const double *a, const double *b) {
    double s = 0.0;
    int d;
    for (d = 0; d < DIM; d++) {
        s += a[d] * b[d];
    }
    return s;
}

/* The rows of one substep with their effective masses (from step_rows). */
static void prepare(const State *s, Prepared *p) {
    int k, e;
    step_rows(s, p);
    for (k = 0; k < CONSTRAINTS; k++) {
        double m = 0.0, jv = 0.0;
        for (e = ROW_START[k]; e < ROW_START[k + 1]; e++) {
            m += p->inverse_mass[ROW_BODY[e]] * lg_dot(p->jacobian[e], p->jacobian[e]);
            jv += lg_dot(p->jacobian[e], p->velocity[ROW_BODY[e]]);
        }
        p->time_rate[k] = p->rate[k] - jv;
        p->effective_mass[k] = (m > 0.0 && isfinite(m)) ? 1.0 / m : 0.0;
    }
}

static double row_rate(const Prepared *p, int k, double u[][DIM]) {
    double c = p->time_rate[k];
    int e;
    for (e = ROW_START[k]; e < ROW_START[k + 1]; e++) {
        c += lg_dot(p->jacobian[e], u[ROW_BODY[e]]);
    }
    return c;
}

static void apply(const Prepared *p, int k, double u[][DIM], double impulse) {
    int e, d;
    for (e = ROW_START[k]; e < ROW_START[k + 1]; e++) {
        const int b = ROW_BODY[e];
        const double s = p->inverse_mass[b] * impulse;
        for (d = 0; d < DIM; d++) {
            u[b][d] += s * p->jacobian[e][d];
        }
    }
}

static void kick(const Prepared *p, double u[][DIM], double h) {
    int i, d;
    for (i = 0; i < BODIES; i++) {
        for (d = 0; d < DIM; d++) {
            u[i][d] += h * p->inverse_mass[i] * p->force[i][d];
        }
    }
}

static void drift(double q[][DIM], double u[][DIM], double h) {
    int i, d;
    for (i = 0; i < BODIES; i++) {
        for (d = 0; d < DIM; d++) {
            q[i][d] += h * u[i][d];
        }
    }
}

static void warm_start(const Prepared *p, double u[][DIM], const double *impulse) {
    int k;
    for (k = 0; k < CONSTRAINTS; k++) {
        if (impulse[k] != 0.0) {
            apply(p, k, u, impulse[k]);
        }
    }
}

/* The bias and softness of row k of value c in one pass: 0 the soft step with bias, 1 its
   relax pass, 2 PGS. */
static Softness law(const Prepared *p, int mode, int k, double c, double h, const Softness *joint,
                    const Softness *contact, double beta, double *bias) {
    if (mode == 2) {
        *bias = (INEQUALITY[k] && c > 0.0) ? c / h : beta * c / h;
        return RIGID;
    }
    (void)p;
    if (mode == 1) {
        *bias = (INEQUALITY[k] && c > 0.0) ? c / h : 0.0;
        return RIGID;
    }
    if (!INEQUALITY[k]) {
        *bias = joint->bias_rate * c;
        return *joint;
    }
    if (c > 0.0) {
        *bias = c / h;
        return RIGID;
    }
    *bias = fmax(contact->bias_rate * c, -3.0);
    return *contact;
}

/* One Gauss-Seidel sweep over the rows in file order (P >= 0 on inequality rows). */
static void sweep(const Prepared *p, double u[][DIM], double *impulse, int mode, double h, const Softness *joint,
                  const Softness *contact, double beta) {
    int k;
    for (k = 0; k < CONSTRAINTS; k++) {
        const double m = p->effective_mass[k];
        double bias, rate, old, delta;
        Softness soft;
        if (m == 0.0) {
            continue;
        }
        soft = law(p, mode, k, p->value[k], h, joint, contact, beta, &bias);
        rate = row_rate(p, k, u);
        old = impulse[k];
        delta = -soft.mass_scale * m * (rate + bias) - soft.impulse_scale * old;
        if (INEQUALITY[k]) {
            delta = fmax(old + delta, 0.0) - old;
        }
        impulse[k] = old + delta;
        apply(p, k, u, delta);
    }
}

/* One step of dt in settings->substeps substeps (the Rust module's step_with). */
void step_with(State *s, double impulses[], double dt, const StepSettings *settings) {
    const double h = dt / (double)settings->substeps;
    const double t = state_time(s);
    const double joint_hertz = settings->cap_hertz ? fmin(settings->hertz, 0.25 / h) : settings->hertz;
    const double contact_hertz = settings->cap_hertz ? fmin(30.0, 0.25 / h) : 30.0;
    const Softness joint = make_soft(joint_hertz, settings->damping_ratio, h);
    const Softness contact = make_soft(contact_hertz, 10.0, h);
    const int pgs = SOLVER_PGS;
    double q[BODIES][DIM], v[BODIES][DIM], start_rate[CONSTRAINTS];
    Prepared p;
    int sub, it, k;
    if (!settings->warm_start) {
        for (k = 0; k < CONSTRAINTS; k++) {
            impulses[k] = 0.0;
        }
    }
    prepare(s, &p);
    state_get(s, q, v);
    for (k = 0; k < CONSTRAINTS; k++) {
        start_rate[k] = row_rate(&p, k, v);
    }
    for (sub = 0; sub < settings->substeps; sub++) {
        kick(&p, v, h);
        warm_start(&p, v, impulses);
        for (it = 0; it < settings->iterations; it++) {
            sweep(&p, v, impulses, pgs ? 2 : 0, h, &joint, &contact, settings->baumgarte);
        }
        drift(q, v, h);
        state_put(s, t + (double)(sub + 1) * h, q, v);
        prepare(s, &p);
        if (!pgs && settings->relax) {
            for (it = 0; it < settings->iterations; it++) {
                sweep(&p, v, impulses, 1, h, &joint, &contact, settings->baumgarte);
            }
        }
    }
    if (!pgs && settings->restitution > 0.0) {
        for (k = 0; k < CONSTRAINTS; k++) {
            const double m = p.effective_mass[k];
            const double closing = start_rate[k];
            double old, delta;
            if (!INEQUALITY[k] || m == 0.0 || closing > -settings->restitution_threshold || impulses[k] <= 0.0) {
                continue;
            }
            old = impulses[k];
            delta = fmax(old - m * (row_rate(&p, k, v) + settings->restitution * closing), 0.0) - old;
            impulses[k] = old + delta;
            apply(&p, k, v, delta);
        }
    }
    state_put(s, state_time(s), q, v);
}

/* One step of dt with the defaults; impulses is the warm-start storage (start from zeros). */
void step(State *s, double impulses[], double dt) {
    const StepSettings settings = step_settings_default();
    step_with(s, impulses, dt, &settings);
}
