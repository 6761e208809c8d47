/* How the step moves the slots with 3D rigid bodies (the Rust module's motion_3d.rs, the same
   operations in the same order): three slots per body, one per principal axis; the state
   keeps the world omega and, in the first slot, the rotation vector phi since the
   orientation q0 of the substep's start; the kick takes the gyroscopic term at the implicit
   midpoint in the body frame, the drift turns the body exactly. */

/* The Hamilton product a (x) b of quaternions [w, x, y, z]. */
static void product(const double a[4], const double b[4], double out[4]) {
    const double aw = a[0], ax = a[1], ay = a[2], az = a[3];
    const double bw = b[0], bx = b[1], by = b[2], bz = b[3];
    out[0] = aw * bw - ax * bx - ay * by - az * bz;
    out[1] = aw * bx + ax * bw + ay * bz - az * by;
    out[2] = aw * by - ax * bz + ay * bw + az * bx;
    out[3] = aw * bz + ax * by - ay * bx + az * bw;
}

static double lg_dot3(const double a[3], const double b[3]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* exp(1/2 [0, phi]): the rotation by |phi| about phi/|phi|. */
static void lg_exp(const double phi[3], double out[4]) {
    const double angle = sqrt(lg_dot3(phi, phi));
    const double half = 0.5 * angle;
    const double s = angle < 1e-4 ? 0.5 - angle * angle / 48.0 : sin(half) / angle;
    out[0] = cos(half);
    out[1] = s * phi[0];
    out[2] = s * phi[1];
    out[3] = s * phi[2];
}

/* q/|q| in place (unchanged when |q| is zero or not finite). */
static void normalise(double q[4]) {
    double n = -0.0;
    int i;
    for (i = 0; i < 4; i++) {
        n += q[i] * q[i];
    }
    n = sqrt(n);
    if (n > 0.0 && isfinite(n)) {
        for (i = 0; i < 4; i++) {
            q[i] = q[i] / n;
        }
    }
}

/* exp(phi) (x) q0. */
static void turned(const double phi[3], const double q0[4], double out[4]) {
    double e[4];
    lg_exp(phi, e);
    product(e, q0, out);
}

/* The rotation vector of the unit quaternion q, the shorter turn. */
static void lg_log(const double q[4], double out[3]) {
    const double w = q[0] < 0.0 ? -q[0] : q[0];
    const double x = q[0] < 0.0 ? -q[1] : q[1], y = q[0] < 0.0 ? -q[2] : q[2], z = q[0] < 0.0 ? -q[3] : q[3];
    const double n = sqrt(x * x + y * y + z * z);
    const double s = n > 0.0 ? 2.0 * atan2(n, w) / n : 2.0;
    out[0] = s * x;
    out[1] = s * y;
    out[2] = s * z;
}

/* The rotation vector of exp(turn) (x) exp(phi), into phi. */
static void compose(const double turn[3], double phi[3]) {
    double a[4], b[4], c[4];
    lg_exp(turn, a);
    lg_exp(phi, b);
    product(a, b, c);
    lg_log(c, phi);
}

/* The start of a substep: each body's phi folded into its orientation, renormalised, phi = 0
   (fresh: the first substep, where q0 is the state's q, only renormalised). */
static void rebase(double orientations[][4], double q[][DIM], int fresh) {
    const int first = SLOTS - 3 * RIGID_3D;
    int r, d;
    for (r = 0; r < RIGID_3D; r++) {
        const int slot = first + 3 * r;
        if (!fresh) {
            double t[4];
            turned(q[slot], orientations[r], t);
            for (d = 0; d < 4; d++) {
                orientations[r][d] = t[d];
            }
        }
        normalise(orientations[r]);
        for (d = 0; d < 3; d++) {
            q[slot][d] = 0.0;
        }
    }
}

/* The three slots from `slot` of a 3D rigid body: 1/I_k, e_k.omega, e_k.tau - (w_b x I w_b)_k. */
static void axis_slots(Prepared *r, int slot, const double moments[3], const double w[3], const double tau[3],
                       const double e[3][3]) {
    double wb[3], iw[3];
    int k;
    for (k = 0; k < 3; k++) {
        wb[k] = lg_dot3(e[k], w);
    }
    for (k = 0; k < 3; k++) {
        iw[k] = moments[k] * wb[k];
    }
    for (k = 0; k < 3; k++) {
        const int i = (k + 1) % 3, j = (k + 2) % 3;
        const double gyroscopic = wb[i] * iw[j] - wb[j] * iw[i];
        int d;
        r->inverse_mass[slot + k] = 1.0 / moments[k];
        r->velocity[slot + k][0] = wb[k];
        r->velocity[slot + k][1] = 0.0;
        r->velocity[slot + k][2] = 0.0;
        r->force[slot + k][0] = lg_dot3(e[k], tau) - gyroscopic;
        r->force[slot + k][1] = 0.0;
        r->force[slot + k][2] = 0.0;
        for (d = 0; d < 3; d++) {
            r->axes[slot + k][d] = e[k][d];
        }
    }
}

/* The first slot with a principal axis (SLOTS when none). */
static int first_angular(const Prepared *p) {
    int i;
    for (i = 0; i < SLOTS; i++) {
        if (p->axes[i][0] != 0.0 || p->axes[i][1] != 0.0 || p->axes[i][2] != 0.0) {
            return i;
        }
    }
    return SLOTS;
}

/* State slots into the rows' slots: a body's world vector x becomes [e_k.x, 0, 0] in slot k. */
static void to_axes(const Prepared *p, double x[][DIM]) {
    int g, k;
    for (g = p->first; g < SLOTS; g += 3) {
        const double w[3] = {x[g][0], x[g][1], x[g][2]};
        for (k = 0; k < 3; k++) {
            x[g + k][0] = lg_dot3(p->axes[g + k], w);
            x[g + k][1] = 0.0;
            x[g + k][2] = 0.0;
        }
    }
}

/* The rows' slots into state slots: sum_k x_k e_k in the body's first slot, zero in the others. */
static void fold(const Prepared *p, double x[][DIM]) {
    int g, k, d;
    for (g = p->first; g < SLOTS; g += 3) {
        double w[3] = {0.0, 0.0, 0.0};
        for (k = 0; k < 3; k++) {
            const double s = x[g + k][0];
            for (d = 0; d < 3; d++) {
                w[d] += s * p->axes[g + k][d];
            }
        }
        for (d = 0; d < 3; d++) {
            x[g][d] = w[d];
            x[g + 1][d] = 0.0;
            x[g + 2][d] = 0.0;
        }
    }
}

static void to_world(const Prepared *p, double x[][DIM]) {
    fold(p, x);
}

/* I^-1 (w x I w) in the body frame. */
static void gyroscopic(const double inertia[3], const double w[3], double out[3]) {
    int k;
    for (k = 0; k < 3; k++) {
        const int i = (k + 1) % 3, j = (k + 2) % 3;
        out[k] = (inertia[j] - inertia[i]) * w[i] * w[j] / inertia[k];
    }
}

static double lg_det3(double a[3][3]) {
    return a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
           a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
}

/* x with m x = r by Cramer's rule; 0 when m is singular or not finite. */
static int solve3(double m[3][3], const double r[3], double x[3]) {
    const double det = lg_det3(m);
    int c, row, col;
    if (!(isfinite(det) && det != 0.0)) {
        return 0;
    }
    for (c = 0; c < 3; c++) {
        double mc[3][3];
        for (row = 0; row < 3; row++) {
            for (col = 0; col < 3; col++) {
                mc[row][col] = m[row][col];
            }
            mc[row][c] = r[row];
        }
        x[c] = lg_det3(mc) / det;
    }
    return 1;
}

/* omega+ = omega + h (applied - I^-1 (wbar x I wbar)), wbar the midpoint, by Newton. */
static void implicit_midpoint(const double inertia[3], double h, const double w0[3], const double applied[3],
                              double w[3]) {
    double g0[3], scale = 0.0;
    int k, it;
    gyroscopic(inertia, w0, g0);
    for (k = 0; k < 3; k++) {
        w[k] = w0[k] + h * (applied[k] - g0[k]);
    }
    for (k = 0; k < 3; k++) {
        scale = fmax(scale, fabs(w0[k]));
    }
    for (k = 0; k < 3; k++) {
        scale = fmax(scale, fabs(w[k]));
    }
    for (it = 0; it < 50; it++) {
        double mid[3], gm[3], residual[3], jac[3][3] = {{0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}}, step[3];
        double largest = 0.0;
        for (k = 0; k < 3; k++) {
            mid[k] = 0.5 * (w0[k] + w[k]);
        }
        gyroscopic(inertia, mid, gm);
        for (k = 0; k < 3; k++) {
            residual[k] = w[k] - w0[k] - h * (applied[k] - gm[k]);
        }
        for (k = 0; k < 3; k++) {
            const int i = (k + 1) % 3, j = (k + 2) % 3;
            const double c = (inertia[j] - inertia[i]) / inertia[k];
            jac[k][k] = 1.0;
            jac[k][i] += 0.5 * h * c * mid[j];
            jac[k][j] += 0.5 * h * c * mid[i];
        }
        if (!solve3(jac, residual, step)) {
            break;
        }
        for (k = 0; k < 3; k++) {
            w[k] -= step[k];
            largest = fmax(largest, fabs(step[k]));
        }
        if (isnan(largest) || largest <= 4.0 * 2.220446049250313e-16 * fmax(scale, 2.2250738585072014e-308)) {
            break;
        }
    }
}

/* The implicit-midpoint kick of one body in its principal frame (the Rust module's kick_axes). */
static void kick_axes(const double inverse_inertia[3], const double force[3], const double at[3], double h,
                      const double w[3], double out[3]) {
    double inertia[3], g_at[3], applied[3];
    int k;
    for (k = 0; k < 3; k++) {
        inertia[k] = 1.0 / inverse_inertia[k];
    }
    gyroscopic(inertia, at, g_at);
    for (k = 0; k < 3; k++) {
        applied[k] = inverse_inertia[k] * force[k] + g_at[k];
    }
    implicit_midpoint(inertia, h, w, applied, out);
}

/* u += h M^-1 F over the rows' slots, a 3D body's through the implicit-midpoint kick. */
static void kick(const Prepared *p, double u[][DIM], double h) {
    int i, d, g, k;
    for (i = 0; i < p->first; i++) {
        for (d = 0; d < DIM; d++) {
            u[i][d] += h * p->inverse_mass[i] * p->force[i][d];
        }
    }
    for (g = p->first; g < SLOTS; g += 3) {
        double w[3], f[3], at[3], now[3], w1[3];
        for (k = 0; k < 3; k++) {
            w[k] = p->inverse_mass[g + k];
            f[k] = p->force[g + k][0];
            at[k] = p->velocity[g + k][0];
            now[k] = u[g + k][0];
        }
        kick_axes(w, f, at, h, now, w1);
        for (k = 0; k < 3; k++) {
            u[g + k][0] = w1[k];
            u[g + k][1] = 0.0;
            u[g + k][2] = 0.0;
        }
    }
}

/* q += h u, a 3D body's rotation vector turned exactly: phi <- log(exp(h omega) (x) exp(phi)). */
static void drift(const Prepared *p, double q[][DIM], double u[][DIM], double h) {
    int i, d, g;
    for (i = 0; i < p->first; i++) {
        for (d = 0; d < DIM; d++) {
            q[i][d] += h * u[i][d];
        }
    }
    for (g = p->first; g < SLOTS; g += 3) {
        const double turn[3] = {h * u[g][0], h * u[g][1], h * u[g][2]};
        compose(turn, q[g]);
    }
}
