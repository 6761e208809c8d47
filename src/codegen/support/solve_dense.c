/* L D L^T (the Rust module's solve_dense, its operations in its order): solves a x = b in
   place in b for a symmetric positive definite a (CONSTRAINTS x CONSTRAINTS, overwritten).
   0 where the rows' solve is needed: a diagonal entry that is not a positive normal number,
   a pivot at or below 1e-10 of its diagonal entry (A singular), or an answer not finite.
   2 x 2: the pivot rule multiplied out (det > 1e-10 a00 a11, a00 a11 normal) and Cramer's rule. */
int solve_dense(double a[][CONSTRAINTS], double b[]) {
    const int k = CONSTRAINTS;
    int i, j, p;
    if (k == 2) {
        const double pp = a[0][0], q = a[1][1], r = a[1][0];
        const double pq = pp * q;
        const double det = pq - r * r;
        const double x0 = (q * b[0] - r * b[1]) / det, x1 = (pp * b[1] - r * b[0]) / det;
        b[0] = x0;
        b[1] = x1;
        return pp >= DBL_MIN && q >= DBL_MIN && pq >= DBL_MIN && det > 1e-10 * pq && isfinite(x0) && isfinite(x1);
    }
    for (i = 0; i < k; i++) {
        const double diagonal = a[i][i];
        double d;
        if (!(isnormal(diagonal) && diagonal > 0.0)) {
            return 0;
        }
        for (j = 0; j < i; j++) {
            /* L[i][j] = (A[i][j] - sum_p L[i][p] d_p L[j][p]) / d_j */
            double acc = a[i][j];
            for (p = 0; p < j; p++) {
                acc -= a[i][p] * a[p][p] * a[j][p];
            }
            a[i][j] = acc / a[j][j];
        }
        /* d_i = A[i][i] - sum_p L[i][p]^2 d_p */
        d = diagonal;
        for (p = 0; p < i; p++) {
            d -= a[i][p] * a[i][p] * a[p][p];
        }
        if (!(d > 1e-10 * diagonal && isfinite(d))) {
            return 0;
        }
        a[i][i] = d;
    }
    /* L y = b, D z = y, L^T x = z (in place in b). */
    for (i = 0; i < k; i++) {
        for (p = 0; p < i; p++) {
            b[i] -= a[i][p] * b[p];
        }
    }
    for (i = 0; i < k; i++) {
        b[i] /= a[i][i];
    }
    for (i = k - 1; i >= 0; i--) {
        for (p = i + 1; p < k; p++) {
            b[i] -= a[p][i] * b[p];
        }
    }
    for (i = 0; i < k; i++) {
        if (!isfinite(b[i])) {
            return 0;
        }
    }
    return 1;
}
