/* The velocity-level step (generate --lang c --solver), its shared pieces: the Rust module's
   (src/codegen/support/step.rs), the same operations in the same order, over the slots of
   the rows (the bodies, then the rigid bodies' angular slots). */

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

/* a.b summed from the first product, as the library's velocity::dot_in. */
static double lg_dot(const double *a, const double *b) {
    double s = a[0] * b[0];
    int d;
    for (d = 1; d < DIM; d++) {
        s += a[d] * b[d];
    }
    return s;
}

/* |J_i|^2 of an entry of a UNIT row (every entry +-e/|e|), as the library's velocity::pattern::unit_square:
   exactly 1 where J_i is a number, NaN where it is not (e = 0), so that m_eff is 0 there: 1 + 0 J_0 + 0 J_1 ... */
static double lg_unit_square(const double *j) {
    double s = 1.0;
    int d;
    for (d = 0; d < DIM; d++) {
        s += 0.0 * j[d];
    }
    return s;
}

/* a.b over the components in m (bit d: component d), summed from the first of them, as the library's
   velocity::dot_masked: lg_dot without the products of J's structural zeros. */
static double lg_dot_masked(int m, const double *a, const double *b) {
    double s = 0.0;
    int d, first = 1;
    for (d = 0; d < DIM; d++) {
        if ((m >> d) & 1) {
            s = first ? a[d] * b[d] : s + a[d] * b[d];
            first = 0;
        }
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
            const double square = UNIT[k] ? lg_unit_square(p->jacobian[e]) : lg_dot(p->jacobian[e], p->jacobian[e]);
            m += p->inverse_mass[ROW_BODY[e]] * square;
            if (!STEADY[k]) {
                jv += lg_dot_masked(ENTRY_MASK[e], p->jacobian[e], p->velocity[ROW_BODY[e]]);
            }
        }
        /* 0 exactly where C reads no time. */
        p->time_rate[k] = STEADY[k] ? 0.0 : p->rate[k] - jv;
        p->effective_mass[k] = (m > 0.0 && isfinite(m)) ? 1.0 / m : 0.0;
    }
    p->first = first_angular(p);
}

/* dC/dt + sum of J_i.u_i, in that order over the entries in the step's order, each product over the
   components of the entry's ENTRY_MASK. */
static double row_rate(const Prepared *p, int k, double u[][DIM]) {
    double c = p->time_rate[k];
    int e;
    for (e = ROW_START[k]; e < ROW_START[k + 1]; e++) {
        c += lg_dot_masked(ENTRY_MASK[e], p->jacobian[e], u[ROW_BODY[e]]);
    }
    return c;
}

