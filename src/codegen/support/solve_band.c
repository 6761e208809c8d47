/* L D L^T on a band (the Rust module's solve_band, its operations in its order): solves A x = r for a
   symmetric positive definite band matrix A of half-bandwidth LAMBDA_BANDWIDTH, given as its rows with r
   beside them (a[i] = A[i][i], ..., A[i][i + w], r[i]; zeros past the last column), by A = R^T D R, T = D R in
   place of A's band, y in place of r; x into x. 0 where the rows' solve is needed: a diagonal entry that is
   not a positive normal number, a pivot at or below 1e-10 of its diagonal entry (A singular), or an answer
   not finite. */
int solve_band(double a[][LAMBDA_BANDWIDTH + 2], double x[]) {
    const int k = CONSTRAINTS, w = LAMBDA_BANDWIDTH, last = LAMBDA_BANDWIDTH + 1;
    double inv[CONSTRAINTS];
    int ok = 1, i, d, p, q;
    for (i = 0; i < k; i++) {
        for (d = 0; d < (w + 1 < k - i ? w + 1 : k - i); d++) {
            const int j = i + d;
            /* T[i][j] = A[i][j] - sum_p T[p][i] T[p][j] / d_p over the rows p < i whose band reaches column j. */
            double acc = a[i][d];
            for (p = (j > w ? j - w : 0); p < i; p++) {
                acc -= a[p][i - p] * a[p][j - p] * inv[p];
            }
            if (d == 0) {
                ok &= (a[i][0] >= DBL_MIN) & (acc > 1e-10 * a[i][0]);
                inv[i] = 1.0 / acc;
            }
            a[i][d] = acc;
        }
        /* R^T y = r: y_i = r_i - sum_p R[p][i] y_p with R[p][i] = T[p][i] / d_p. */
        {
            double y = a[i][last];
            for (p = (i > w ? i - w : 0); p < i; p++) {
                y -= a[p][i - p] * inv[p] * a[p][last];
            }
            a[i][last] = y;
        }
    }
    /* D R x = y: x_i = y_i / d_i - sum_q R[i][q] x_q. */
    for (i = k - 1; i >= 0; i--) {
        double acc = a[i][last] * inv[i];
        for (q = i + 1; q < (k < i + w + 1 ? k : i + w + 1); q++) {
            acc -= a[i][q - i] * inv[i] * x[q];
        }
        ok &= isfinite(acc) != 0;
        x[i] = acc;
    }
    return ok;
}
