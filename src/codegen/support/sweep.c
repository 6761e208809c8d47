/* The soft step and PGS (generate --lang c --solver soft-step|pgs): the Rust module's
   (src/codegen/support/sweep.rs, soft_step.rs, pgs.rs), the same operations in the same
   order. */

/* Box2D's b2Softness: bias rate on C/kappa, scale on the effective mass, scale on the
   accumulated impulse. */
typedef struct Softness {
    double bias_rate, mass_scale, impulse_scale;
} Softness;

static const Softness LG_RIGID = {0.0, 1.0, 0.0};

/* b2MakeSoft: omega = 2 pi hertz, a1 = 2 zeta + h omega, a2 = h omega a1, a3 = 1/(1 + a2). */
static Softness make_soft(double hertz, double zeta, double h) {
    Softness s;
    double omega, a1, a2, a3;
    if (hertz == 0.0) {
        return LG_RIGID;
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

/* u_i += (1/m_i) J_i impulse over the components of each entry's ENTRY_MASK. */
static void apply(const Prepared *p, int k, double u[][DIM], double impulse) {
    int e, d;
    for (e = ROW_START[k]; e < ROW_START[k + 1]; e++) {
        const int b = ROW_BODY[e];
        const double s = p->inverse_mass[b] * impulse;
        for (d = 0; d < DIM; d++) {
            if ((ENTRY_MASK[e] >> d) & 1) {
                u[b][d] += s * p->jacobian[e][d];
            }
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
        return LG_RIGID;
    }
    (void)p;
    if (mode == 1) {
        *bias = (INEQUALITY[k] && c > 0.0) ? c / h : 0.0;
        return LG_RIGID;
    }
    if (!INEQUALITY[k]) {
        *bias = joint->bias_rate * c;
        return *joint;
    }
    if (c > 0.0) {
        *bias = c / h;
        return LG_RIGID;
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

/* One step of dt in settings->substeps substeps (the Rust module's step_with): the soft step,
   or PGS where SOLVER_PGS. */
void step_with(State *s, double impulses[], double dt, const StepSettings *settings) {
    const double h = dt / (double)settings->substeps;
    const double t = state_time(s);
    const double joint_hertz = settings->cap_hertz ? fmin(settings->hertz, 0.25 / h) : settings->hertz;
    const double contact_hertz = settings->cap_hertz ? fmin(30.0, 0.25 / h) : 30.0;
    const Softness joint = make_soft(joint_hertz, settings->damping_ratio, h);
    const Softness contact = make_soft(contact_hertz, 10.0, h);
    const int pgs = SOLVER_PGS;
    double q[SLOTS][DIM], v[SLOTS][DIM], q0[RIGID_3D > 0 ? RIGID_3D : 1][4], start_rate[CONSTRAINTS > 0 ? CONSTRAINTS : 1];
    Prepared p;
    int sub, it, k;
    if (!settings->warm_start) {
        for (k = 0; k < CONSTRAINTS; k++) {
            impulses[k] = 0.0;
        }
    }
    state_get(s, q, v, q0);
    prepare(s, &p);
    if (!pgs) {
        /* In the rows' slots (a 3D body's omega along its principal axes) for the sweeps. */
        to_axes(&p, v);
    }
    for (k = 0; k < CONSTRAINTS; k++) {
        start_rate[k] = row_rate(&p, k, v);
    }
    for (sub = 0; sub < settings->substeps; sub++) {
        /* 3D rigid bodies: the orientation folded in and renormalised, phi = 0 from here. */
        rebase(q0, q, sub == 0);
        if (pgs) {
            to_axes(&p, v);
        }
        kick(&p, v, h);
        warm_start(&p, v, impulses);
        for (it = 0; it < settings->iterations; it++) {
            sweep(&p, v, impulses, pgs ? 2 : 0, h, &joint, &contact, settings->baumgarte);
        }
        to_world(&p, v);
        drift(&p, q, v, h);
        state_put(s, t + (double)(sub + 1) * h, q, v, q0);
        prepare(s, &p);
        if (!pgs) {
            to_axes(&p, v);
        }
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
    if (!pgs) {
        to_world(&p, v);
    }
    state_put(s, state_time(s), q, v, q0);
}

/* One step of dt with the defaults; impulses is the warm-start storage (start from zeros). */
void step(State *s, double impulses[], double dt) {
    const StepSettings settings = step_settings_default();
    step_with(s, impulses, dt, &settings);
}
