/* The rows' solve (generate --lang c): the Rust module's solve_rows, the same operations in
   the same order (src/codegen/support/rows.rs), so with -ffp-contract=off its numbers bit for
   bit. Rows are scaled (J/|J|, then to a unit diagonal), inequality rows classified as
   numeric::contact does, the touching rows solved as equalities, Murty's least-index
   principal pivoting where an inequality would pull, and the lambda of least norm for C/kappa
   where A is singular (cyclic Jacobi). Work arrays come from calloc; where it fails the
   status is LG_FAILED and lambda 0. The module defines CONSTRAINTS, DIM, SLOTS (bodies, then
   one angular slot per rigid body), ROW_ENTRIES, SOLVE_START and SOLVE_SLOT before this. */

/* Where an inequality row stands (LG_EQUALITY for an equality row). */
enum {
    LG_EQUALITY = -1,
    LG_APART = 0,
    LG_SEPARATING = 1,
    LG_RESTING = 2,
    LG_CLOSING = 3,
    LG_PENETRATING = 4
};

/* How a solve went, from best to worst (the Rust module's Status, in its order). */
enum { LG_SOLVED = 0, LG_MINIMUM_NORM = 1, LG_SINGULAR = 2, LG_INACCURATE = 3, LG_INCONSISTENT = 4, LG_FAILED = 5 };

/* The rows at a state: per row C/kappa, its rate, c and whether it is an inequality; J per
   entry, row k's entries being SOLVE_START[k] .. SOLVE_START[k + 1] on slots SOLVE_SLOT[e]. */
typedef struct Rows {
    double value[CONSTRAINTS > 0 ? CONSTRAINTS : 1], rate[CONSTRAINTS > 0 ? CONSTRAINTS : 1];
    double bias[CONSTRAINTS > 0 ? CONSTRAINTS : 1];
    int inequality[CONSTRAINTS > 0 ? CONSTRAINTS : 1];
    double jacobian[ROW_ENTRIES > 0 ? ROW_ENTRIES : 1][DIM];
} Rows;

/* The answer at one state, as lagrange solve gives it: lambda per constraint (for C/kappa),
   each row's contact state (LG_EQUALITY for equalities), the constraint force sum_k lambda_k
   J_ki and the acceleration (F_i + force_i)/m_i per slot, and the status (LG_SOLVED ..). */
typedef struct Solution {
    double lambda[CONSTRAINTS > 0 ? CONSTRAINTS : 1];
    int contact[CONSTRAINTS > 0 ? CONSTRAINTS : 1];
    double force[SLOTS > 0 ? SLOTS : 1][DIM];
    double acceleration[SLOTS > 0 ? SLOTS : 1][DIM];
    int status;
} Solution;

/* Relative tolerance of "touching" and "resting"; pivots and eigenvalues of the unit-diagonal
   A at or below LG_RANK_TOLERANCE are zero. */
#define LG_CONTACT_TOLERANCE 1e-9
#define LG_RANK_TOLERANCE 1e-10

/* Rust's f64::max and f64::signum. */
static double lg_max(double a, double b) {
    return fmax(a, b);
}

static double lg_signum(double x) {
    return isnan(x) ? x : copysign(1.0, x);
}

/* |x| of n numbers without overflow or underflow. */
static double lg_safe_norm(const double *x, int n) {
    double big = 0.0, s = -0.0;
    int i;
    for (i = 0; i < n; i++) {
        big = lg_max(big, fabs(x[i]));
    }
    if (big == 0.0 || !isfinite(big)) {
        return big;
    }
    for (i = 0; i < n; i++) {
        s += (x[i] / big) * (x[i] / big);
    }
    return big * sqrt(s);
}

/* The contact length of a scene at a state: the largest |r_i| (1 when there is none). */
double length_scale(double positions[][DIM], int n) {
    double length = 0.0;
    int i;
    for (i = 0; i < n; i++) {
        length = lg_max(length, lg_safe_norm(positions[i], DIM));
    }
    return (length > 0.0 && isfinite(length)) ? length : 1.0;
}

static int lg_worse(int status, int other) {
    return other > status ? other : status;
}

/* x with L L^T x = b (n x n, row-major). */
static void lg_cholesky_solve(const double *l, const double *b, double *x, int n) {
    int i, p;
    for (i = 0; i < n; i++) {
        x[i] = b[i];
    }
    for (i = 0; i < n; i++) {
        for (p = 0; p < i; p++) {
            x[i] -= l[i * n + p] * x[p];
        }
        x[i] /= l[i * n + i];
    }
    for (i = n - 1; i >= 0; i--) {
        for (p = i + 1; p < n; p++) {
            x[i] -= l[p * n + i] * x[p];
        }
        x[i] /= l[i * n + i];
    }
}

/* L of A = L L^T into l (zeroed by the caller); 0 when a pivot is at or below the rank
   tolerance. */
static int lg_cholesky(const double *a, double *l, int n) {
    int i, j, p;
    for (i = 0; i < n; i++) {
        for (j = 0; j <= i; j++) {
            double acc = a[i * n + j];
            for (p = 0; p < j; p++) {
                acc -= l[i * n + p] * l[j * n + p];
            }
            if (i == j) {
                if (!(acc > LG_RANK_TOLERANCE && isfinite(acc))) {
                    return 0;
                }
                l[i * n + i] = sqrt(acc);
            } else {
                l[i * n + j] = acc / l[j * n + j];
            }
        }
    }
    return 1;
}

/* The largest |x| of n numbers (0 for none). */
static double lg_amax(const double *x, int n) {
    double m = 0.0;
    int i;
    for (i = 0; i < n; i++) {
        m = lg_max(m, fabs(x[i]));
    }
    return m;
}

/* The minimum-norm (least-squares if inconsistent) x of a singular symmetric a x = rhs, of
   least |W x| among the solutions (the Rust module's minimum_norm). 0 when out of memory. */
static int lg_minimum_norm(const double *a, const double *rhs, const double *weight, int n, double *x, int *status) {
    double *s = (double *)calloc((size_t)(2 * n * n + 2 * n + 1), sizeof(double));
    double *v, *w;
    int *null = (int *)calloc((size_t)(n + 1), sizeof(int));
    int i, j, p, q, r, e, sweep, m = 0, normal = 1;
    double largest = 0.0, threshold, top = 0.0, residual, size;
    if (s == NULL || null == NULL) {
        free(s);
        free(null);
        return 0;
    }
    v = s + n * n;
    w = v + n * n;
    for (i = 0; i < n * n; i++) {
        s[i] = a[i];
        v[i] = 0.0;
    }
    for (i = 0; i < n; i++) {
        v[i * n + i] = 1.0;
    }
    for (sweep = 0; sweep < 100; sweep++) {
        double off = -0.0, diag = -0.0;
        for (i = 0; i < n; i++) {
            for (j = 0; j < n; j++) {
                if (j != i) {
                    off += s[i * n + j] * s[i * n + j];
                }
            }
        }
        for (i = 0; i < n; i++) {
            diag += s[i * n + i] * s[i * n + i];
        }
        if (isnan(off) || off <= 1e-32 * diag) {
            break;
        }
        for (p = 0; p < n; p++) {
            for (q = p + 1; q < n; q++) {
                double theta, t, c, sn;
                if (s[p * n + q] == 0.0) {
                    continue;
                }
                /* The rotation that zeroes s[p][q] (Golub & Van Loan, 8.5). */
                theta = (s[q * n + q] - s[p * n + p]) / (2.0 * s[p * n + q]);
                t = lg_signum(theta) / (fabs(theta) + sqrt(theta * theta + 1.0));
                t = theta == 0.0 ? 1.0 : t;
                c = 1.0 / sqrt(t * t + 1.0);
                sn = t * c;
                for (r = 0; r < n; r++) {
                    const double xr = s[r * n + p], yr = s[r * n + q];
                    s[r * n + p] = c * xr - sn * yr;
                    s[r * n + q] = sn * xr + c * yr;
                }
                for (r = 0; r < n; r++) {
                    const double xr = s[p * n + r], yr = s[q * n + r];
                    s[p * n + r] = c * xr - sn * yr;
                    s[q * n + r] = sn * xr + c * yr;
                }
                for (r = 0; r < n; r++) {
                    const double xr = v[r * n + p], yr = v[r * n + q];
                    v[r * n + p] = c * xr - sn * yr;
                    v[r * n + q] = sn * xr + c * yr;
                }
            }
        }
    }
    for (i = 0; i < n; i++) {
        largest = lg_max(largest, fabs(s[i * n + i]));
    }
    threshold = LG_RANK_TOLERANCE * lg_max(largest, DBL_MIN);
    for (i = 0; i < n; i++) {
        x[i] = 0.0;
    }
    for (e = 0; e < n; e++) {
        const double sigma = s[e * n + e];
        if (fabs(sigma) > threshold) {
            double along = -0.0;
            for (r = 0; r < n; r++) {
                along += v[r * n + e] * rhs[r];
            }
            along /= sigma;
            for (r = 0; r < n; r++) {
                x[r] += v[r * n + e] * along;
            }
        }
    }
    for (e = 0; e < n; e++) {
        if (fabs(s[e * n + e]) <= threshold || isnan(s[e * n + e])) {
            null[m++] = e;
        }
    }
    for (i = 0; i < n; i++) {
        top = lg_max(top, fabs(weight[i]));
    }
    for (i = 0; i < n; i++) {
        w[i] = weight[i] / top;
        normal = normal && isnormal(w[i]);
    }
    if (m > 0 && normal) {
        /* min over z of |W (x0 + N z)|: (N^T W^2 N) z = -N^T W^2 x0, scaled to a unit diagonal. */
        double *g = (double *)calloc((size_t)(3 * m * m + 4 * m + n), sizeof(double));
        if (g != NULL) {
            double *unit = g + m * m, *l = unit + m * m, *h = l + m * m, *d = h + m, *hd = d + m, *z = hd + m;
            double *moved = z + m;
            int finite = 1;
            for (i = 0; i < m; i++) {
                for (j = 0; j < m; j++) {
                    double acc = -0.0;
                    for (r = 0; r < n; r++) {
                        acc += w[r] * w[r] * v[r * n + null[i]] * v[r * n + null[j]];
                    }
                    g[i * m + j] = acc;
                }
            }
            for (i = 0; i < m; i++) {
                double acc = -0.0;
                for (r = 0; r < n; r++) {
                    acc += w[r] * w[r] * v[r * n + null[i]] * x[r];
                }
                h[i] = -acc;
            }
            for (i = 0; i < m; i++) {
                d[i] = 1.0 / sqrt(g[i * m + i]);
            }
            for (i = 0; i < m; i++) {
                for (j = 0; j < m; j++) {
                    unit[i * m + j] = g[i * m + j] * d[i] * d[j];
                    l[i * m + j] = 0.0;
                }
            }
            if (lg_cholesky(unit, l, m)) {
                for (i = 0; i < m; i++) {
                    hd[i] = h[i] * d[i];
                }
                lg_cholesky_solve(l, hd, z, m);
                for (r = 0; r < n; r++) {
                    double acc = -0.0;
                    for (i = 0; i < m; i++) {
                        acc += v[r * n + null[i]] * z[i] * d[i];
                    }
                    moved[r] = x[r] + acc;
                    finite = finite && isfinite(moved[r]);
                }
                if (finite) {
                    for (r = 0; r < n; r++) {
                        x[r] = moved[r];
                    }
                }
            }
            free(g);
        }
    }
    residual = 0.0;
    for (p = 0; p < n; p++) {
        double acc = -0.0;
        for (q = 0; q < n; q++) {
            acc += a[p * n + q] * x[q];
        }
        residual = lg_max(residual, fabs(acc - rhs[p]));
    }
    size = lg_amax(rhs, n) + lg_amax(a, n * n) * lg_amax(x, n);
    *status = lg_worse(*status, (size == 0.0 || residual <= sqrt(LG_CONTACT_TOLERANCE) * 1e-2 * size)
                                    ? LG_MINIMUM_NORM
                                    : LG_INCONSISTENT);
    free(s);
    free(null);
    return 1;
}

/* Solves A mu = -b on the rows marked in keep (the others get mu = 0): Cholesky with one step
   of iterative refinement; the minimum-norm solution when A is singular there. 0 when out of
   memory. */
static int lg_subset(const double *a, const double *b, const double *weight, const int *keep, int n, double *x,
                     int *status) {
    int *rows = (int *)calloc((size_t)(n + 1), sizeof(int));
    double *sub = (double *)calloc((size_t)(2 * n * n + 5 * n + 1), sizeof(double));
    double *l, *rhs, *w, *y, *r, *dy;
    int m = 0, p, q, ok = 1;
    if (rows == NULL || sub == NULL) {
        free(rows);
        free(sub);
        return 0;
    }
    for (p = 0; p < n; p++) {
        if (keep[p]) {
            rows[m++] = p;
        }
    }
    l = sub + m * m;
    rhs = l + m * m;
    w = rhs + m;
    y = w + m;
    r = y + m;
    dy = r + m;
    for (p = 0; p < m; p++) {
        for (q = 0; q < m; q++) {
            sub[p * m + q] = a[rows[p] * n + rows[q]];
            l[p * m + q] = 0.0;
        }
        rhs[p] = -b[rows[p]];
        w[p] = weight[rows[p]];
    }
    if (lg_cholesky(sub, l, m)) {
        lg_cholesky_solve(l, rhs, y, m);
        for (p = 0; p < m; p++) {
            double acc = -0.0;
            for (q = 0; q < m; q++) {
                acc += sub[p * m + q] * y[q];
            }
            r[p] = rhs[p] - acc;
        }
        lg_cholesky_solve(l, r, dy, m);
        for (p = 0; p < m; p++) {
            y[p] += dy[p];
        }
    } else {
        ok = lg_minimum_norm(sub, rhs, w, m, y, status);
    }
    for (p = 0; p < n; p++) {
        x[p] = 0.0;
    }
    for (p = 0; ok && p < m; p++) {
        if (isfinite(y[p])) {
            x[rows[p]] = y[p];
        } else {
            *status = lg_worse(*status, LG_FAILED);
            x[rows[p]] = 0.0;
        }
    }
    free(rows);
    free(sub);
    return ok;
}

/* The scaled multipliers: the equality solve when no row is nonnegative, else the LCP by
   Murty's least-index principal pivoting (Murty 1974). 0 when out of memory. */
static int lg_multipliers(const double *a, const double *b, const double *weight, const int *nonnegative, int n,
                          double *x, int *status) {
    int *in_set = (int *)calloc((size_t)(2 * n + 1), sizeof(int));
    int *everything, any = 0, p, q, round, first = LG_SOLVED, settled = 0;
    double scale = 1.0;
    if (in_set == NULL) {
        return 0;
    }
    everything = in_set + n;
    for (p = 0; p < n; p++) {
        everything[p] = 1;
        any = any || nonnegative[p];
    }
    if (!any) {
        const int ok = lg_subset(a, b, weight, everything, n, x, status);
        free(in_set);
        return ok;
    }
    /* Every touching inequality as an equality first: if they all push, that is the answer. */
    if (!lg_subset(a, b, weight, everything, n, x, &first)) {
        free(in_set);
        return 0;
    }
    for (p = 0; p < n; p++) {
        scale = lg_max(scale, fabs(x[p]));
    }
    if (first == LG_SOLVED) {
        int all = 1;
        for (p = 0; p < n; p++) {
            all = all && (!nonnegative[p] || x[p] >= -LG_CONTACT_TOLERANCE * scale);
        }
        settled = all;
    }
    if (!settled) {
        double *w = (double *)calloc((size_t)(n + 1), sizeof(double));
        int done = 0;
        if (w == NULL) {
            free(in_set);
            return 0;
        }
        for (p = 0; p < n; p++) {
            in_set[p] = !nonnegative[p] || x[p] > 0.0;
        }
        for (round = 0; round < 200 * n + 1000 && !done; round++) {
            int s = LG_SOLVED, flip = -1;
            if (!lg_subset(a, b, weight, in_set, n, x, &s)) {
                free(w);
                free(in_set);
                return 0;
            }
            scale = 1.0;
            for (p = 0; p < n; p++) {
                scale = lg_max(scale, fabs(b[p]));
            }
            for (p = 0; p < n; p++) {
                scale = lg_max(scale, fabs(x[p]));
            }
            for (p = 0; p < n; p++) {
                double acc = -0.0;
                for (q = 0; q < n; q++) {
                    acc += a[p * n + q] * x[q];
                }
                w[p] = acc + b[p];
            }
            for (p = 0; p < n && flip < 0; p++) {
                if (nonnegative[p] &&
                    ((in_set[p] && x[p] < -LG_CONTACT_TOLERANCE * scale) ||
                     (!in_set[p] && w[p] < -LG_CONTACT_TOLERANCE * scale))) {
                    flip = p;
                }
            }
            if (flip < 0) {
                *status = lg_worse(*status, s);
                done = 1;
            } else {
                in_set[flip] = !in_set[flip];
            }
        }
        if (!done) {
            *status = lg_worse(*status, LG_INACCURATE);
        }
        free(w);
    }
    for (p = 0; p < n; p++) {
        if (nonnegative[p]) {
            x[p] = lg_max(x[p], 0.0);
        }
    }
    free(in_set);
    return 1;
}

/* lambda, the forces and the accelerations at a state over SLOTS slots (inverse masses,
   velocities, forces), the Rust module's solve_rows. */
void solve_rows(const Rows *rows, const double inverse_mass[], double velocity[][DIM], double force[][DIM],
                double length, Solution *out) {
    const int k = CONSTRAINTS, n = SLOTS;
    int q, e, i, c, p, r, m = 0, status = LG_SOLVED;
    int *bad_body = (int *)calloc((size_t)(n + 2 * k + 1), sizeof(int));
    int *index = bad_body + n, *nonnegative = index + k;
    double *norm = (double *)calloc((size_t)(3 * k + ROW_ENTRIES * DIM + 1), sizeof(double));
    double *jacobi = norm + k, *weight = jacobi + k, *scaled = weight + k;
    double *a = NULL, *b = NULL, *mu = NULL;
    for (q = 0; q < k; q++) {
        out->lambda[q] = 0.0;
        out->contact[q] = LG_EQUALITY;
    }
    for (i = 0; i < n; i++) {
        for (c = 0; c < DIM; c++) {
            out->force[i][c] = 0.0;
        }
    }
    if (bad_body == NULL || norm == NULL) {
        goto failed;
    }
    for (i = 0; i < n; i++) {
        const double w = inverse_mass[i];
        int bad = !(isfinite(w) && w >= 0.0);
        for (c = 0; c < DIM; c++) {
            bad = bad || !isfinite(force[i][c]);
        }
        for (c = 0; c < DIM; c++) {
            bad = bad || !isfinite(velocity[i][c]);
        }
        bad_body[i] = bad;
    }
    /* Scaling: |J_k|, 1/sqrt(A_kk) and the scaled J_k per usable row. */
    for (q = 0; q < k; q++) {
        double nq = 0.0, a_kk = -0.0, d;
        int finite;
        norm[q] = 0.0;
        jacobi[q] = 0.0;
        for (e = SOLVE_START[q]; e < SOLVE_START[q + 1]; e++) {
            double pair[2];
            pair[0] = nq;
            pair[1] = lg_safe_norm(rows->jacobian[e], DIM);
            nq = lg_safe_norm(pair, 2);
        }
        /* The contact state, as numeric::contact::classify gives it. */
        if (rows->inequality[q]) {
            double speed = 0.0;
            for (e = SOLVE_START[q]; e < SOLVE_START[q + 1]; e++) {
                speed = lg_max(speed, lg_safe_norm(velocity[SOLVE_SLOT[e]], DIM));
            }
            if (!(nq > 0.0 && isfinite(nq))) {
                out->contact[q] = rows->value[q] >= 0.0 ? LG_APART : LG_PENETRATING;
            } else {
                const double distance = rows->value[q] / nq, rate = rows->rate[q] / nq;
                const double tol = LG_CONTACT_TOLERANCE;
                if (distance > tol * length) {
                    out->contact[q] = LG_APART;
                } else if (isnan(distance) || distance < -tol * length) {
                    out->contact[q] = LG_PENETRATING;
                } else if (rate > tol * speed) {
                    out->contact[q] = LG_SEPARATING;
                } else if (rate < -tol * speed) {
                    out->contact[q] = LG_CLOSING;
                } else {
                    out->contact[q] = LG_RESTING;
                }
            }
        }
        finite = isfinite(nq) && isfinite(rows->bias[q]);
        for (e = SOLVE_START[q]; e < SOLVE_START[q + 1]; e++) {
            finite = finite && !bad_body[SOLVE_SLOT[e]];
        }
        finite = finite && (!rows->inequality[q] || (isfinite(rows->value[q]) && isfinite(rows->rate[q])));
        if (!finite) {
            status = lg_worse(status, LG_FAILED);
            continue;
        }
        if (nq == 0.0) {
            status = lg_worse(status, LG_SINGULAR);
            continue;
        }
        for (e = SOLVE_START[q]; e < SOLVE_START[q + 1]; e++) {
            double sq = -0.0;
            for (c = 0; c < DIM; c++) {
                const double u = rows->jacobian[e][c] / nq;
                sq += u * u;
            }
            a_kk += sq * inverse_mass[SOLVE_SLOT[e]];
        }
        if (!(a_kk > 0.0 && isfinite(a_kk))) {
            status = lg_worse(status, LG_SINGULAR);
            continue;
        }
        d = 1.0 / sqrt(a_kk);
        norm[q] = nq;
        jacobi[q] = d;
        for (e = SOLVE_START[q]; e < SOLVE_START[q + 1]; e++) {
            for (c = 0; c < DIM; c++) {
                scaled[e * DIM + c] = (rows->jacobian[e][c] / nq) * d;
            }
        }
    }
    /* Candidates: usable equalities, and inequality rows touching without separating. */
    for (q = 0; q < k; q++) {
        if (norm[q] > 0.0 && out->contact[q] != LG_APART && out->contact[q] != LG_SEPARATING) {
            index[m++] = q;
        }
    }
    a = (double *)calloc((size_t)(m * m + 2 * m + 1), sizeof(double));
    if (a == NULL) {
        goto failed;
    }
    b = a + m * m;
    mu = b + m;
    /* b_p = sum_i J_pi . F_i w_i + c_p, and A_pr = sum_i J_pi . J_ri w_i over shared slots. */
    for (p = 0; p < m; p++) {
        const int qp = index[p];
        double ext = -0.0;
        for (e = SOLVE_START[qp]; e < SOLVE_START[qp + 1]; e++) {
            const int slot = SOLVE_SLOT[e];
            double dot = -0.0;
            for (c = 0; c < DIM; c++) {
                dot += scaled[e * DIM + c] * force[slot][c];
            }
            ext += dot * inverse_mass[slot];
        }
        b[p] = ext + (rows->bias[qp] / norm[qp]) * jacobi[qp];
        nonnegative[p] = rows->inequality[qp];
        weight[p] = jacobi[qp] / norm[qp];
    }
    for (p = 0; p < m; p++) {
        for (r = p; r < m; r++) {
            double x = 0.0;
            for (e = SOLVE_START[index[p]]; e < SOLVE_START[index[p] + 1]; e++) {
                int f;
                for (f = SOLVE_START[index[r]]; f < SOLVE_START[index[r] + 1]; f++) {
                    if (SOLVE_SLOT[f] == SOLVE_SLOT[e]) {
                        double dot = -0.0;
                        for (c = 0; c < DIM; c++) {
                            dot += scaled[e * DIM + c] * scaled[f * DIM + c];
                        }
                        x += dot * inverse_mass[SOLVE_SLOT[e]];
                        break;
                    }
                }
            }
            a[p * m + r] = x;
            a[r * m + p] = x;
        }
    }
    /* lambda_q/mu_p: the minimum norm is taken in lambda (for C/kappa), as solve takes it. */
    if (!lg_multipliers(a, b, weight, nonnegative, m, mu, &status)) {
        goto failed;
    }
    for (p = 0; p < m; p++) {
        q = index[p];
        out->lambda[q] = (mu[p] * jacobi[q]) / norm[q];
        for (e = SOLVE_START[q]; e < SOLVE_START[q + 1]; e++) {
            for (c = 0; c < DIM; c++) {
                out->force[SOLVE_SLOT[e]][c] += mu[p] * scaled[e * DIM + c];
            }
        }
    }
    for (i = 0; i < n; i++) {
        for (c = 0; c < DIM; c++) {
            out->acceleration[i][c] = (force[i][c] + out->force[i][c]) * inverse_mass[i];
        }
    }
    out->status = status;
    free(bad_body);
    free(norm);
    free(a);
    return;
failed:
    for (q = 0; q < k; q++) {
        out->lambda[q] = 0.0;
    }
    for (i = 0; i < n; i++) {
        for (c = 0; c < DIM; c++) {
            out->force[i][c] = 0.0;
            out->acceleration[i][c] = force[i][c] * inverse_mass[i];
        }
    }
    out->status = LG_FAILED;
    free(bad_body);
    free(norm);
    free(a);
}

/* x * 2^e without an intermediate overflow or underflow of the factor (once x is 0, infinite
   or NaN it stays so: the Rust module's pow2 gives the same). */
double pow2(double x, long long e) {
    while (e > 1000 && isfinite(x) && x != 0.0) {
        x *= ldexp(1.0, 1000);
        e -= 1000;
    }
    while (e < -1000 && isfinite(x) && x != 0.0) {
        x *= ldexp(1.0, -1000);
        e += 1000;
    }
    if (e > 1000 || e < -1000) {
        return x;
    }
    return x * ldexp(1.0, (int)e);
}

/* Rust's `x as i64`: saturating, NaN to 0. */
static long long lg_to_i64(double x) {
    if (isnan(x)) {
        return 0;
    }
    if (x >= 9223372036854775807.0) {
        return 9223372036854775807LL;
    }
    if (x <= -9223372036854775807.0) {
        return -9223372036854775807LL - 1;
    }
    return (long long)x;
}

/* Whether every number the solve reads is finite. */
int rows_finite(const Rows *rows, const double inverse_mass[], double velocity[][DIM], double force[][DIM]) {
    int i, c, q;
    for (i = 0; i < SLOTS; i++) {
        if (!isfinite(inverse_mass[i])) {
            return 0;
        }
        for (c = 0; c < DIM; c++) {
            if (!isfinite(velocity[i][c]) || !isfinite(force[i][c])) {
                return 0;
            }
        }
    }
    for (q = 0; q < CONSTRAINTS; q++) {
        if (!isfinite(rows->value[q]) || !isfinite(rows->rate[q]) || !isfinite(rows->bias[q])) {
            return 0;
        }
    }
    for (q = 0; q < ROW_ENTRIES; q++) {
        for (c = 0; c < DIM; c++) {
            if (!isfinite(rows->jacobian[q][c])) {
                return 0;
            }
        }
    }
    return 1;
}

/* The degree p of each row into p[] if at (a state scaled by 2^e) and half (by 2^(e-1))
   differ exactly as a homogeneous row would (C, its rate, c by 2^p, J by 2^(p-1)); else 0. */
int degrees(const Rows *at, const Rows *half, long long p[]) {
    int q, e, c;
    for (q = 0; q < CONSTRAINTS; q++) {
        const double xs[3] = {at->value[q], at->rate[q], at->bias[q]};
        const double ys[3] = {half->value[q], half->rate[q], half->bias[q]};
        int found = 0, i, ok = 1;
        long long degree = 0;
        for (i = 0; i < 3 && !found; i++) {
            if (xs[i] != 0.0) {
                degree = lg_to_i64(round(log2(xs[i] / ys[i])));
                found = 1;
            }
        }
        for (e = SOLVE_START[q]; e < SOLVE_START[q + 1] && !found; e++) {
            for (c = 0; c < DIM && !found; c++) {
                if (at->jacobian[e][c] != 0.0) {
                    degree = lg_to_i64(round(log2(at->jacobian[e][c] / half->jacobian[e][c])));
                    /* Saturating, as the Rust module's `saturating_add`. */
                    degree = degree == LLONG_MAX ? LLONG_MAX : degree + 1;
                    found = 1;
                }
            }
        }
        for (i = 0; i < 3; i++) {
            ok = ok && xs[i] == pow2(ys[i], degree);
        }
        for (e = SOLVE_START[q]; e < SOLVE_START[q + 1]; e++) {
            for (c = 0; c < DIM; c++) {
                ok = ok && at->jacobian[e][c] == pow2(half->jacobian[e][c], degree == LLONG_MIN ? LLONG_MIN : degree - 1);
            }
        }
        if (!ok) {
            return 0;
        }
        p[q] = degree;
    }
    return 1;
}
