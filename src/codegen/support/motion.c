/* How the step moves the slots without 3D rigid bodies (the Rust module's motion.rs): the kick
   u += h M^-1 F and the drift q += h u over every slot alike (a 2D rigid body's angular slot
   holds theta, omega, 1/I and tau); the state's slots are the rows' slots, and there is no
   orientation to rebase. */

/* No 3D rigid body: no slot has a principal axis. */
static int first_angular(const Prepared *p) {
    (void)p;
    return SLOTS;
}

static void kick(const Prepared *p, double u[][DIM], double h) {
    int i, d;
    for (i = 0; i < SLOTS; i++) {
        for (d = 0; d < DIM; d++) {
            u[i][d] += h * p->inverse_mass[i] * p->force[i][d];
        }
    }
}

static void to_axes(const Prepared *p, double x[][DIM]) {
    (void)p;
    (void)x;
}


static void drift(const Prepared *p, double q[][DIM], double u[][DIM], double h) {
    int i, d;
    (void)p;
    for (i = 0; i < SLOTS; i++) {
        for (d = 0; d < DIM; d++) {
            q[i][d] += h * u[i][d];
        }
    }
}

/* A correction over the rows' slots into state slots: nothing to turn. */
static void fold(const Prepared *p, double x[][DIM]) {
    (void)p;
    (void)x;
}

static void to_world(const Prepared *p, double x[][DIM]) {
    fold(p, x);
}

static void rebase(double orientations[][4], double q[][DIM], int fresh) {
    (void)orientations;
    (void)q;
    (void)fresh;
}
