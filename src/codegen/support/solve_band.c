/* Band Cholesky (the Rust module's solve_band, its operations in its order): solves a x = b
   in place in b for a symmetric positive definite band matrix given as its upper band
   (a[i][d] = A[i][i + d], d <= A_BANDWIDTH), A = R^T R in place in a; b all NaN if A is not
   positive definite. */
void solve_band(double a[][A_BANDWIDTH + 1], double b[]) {
    const int k = CONSTRAINTS, w = A_BANDWIDTH, width = A_BANDWIDTH + 1;
    int i, d, p, q;
    for (i = 0; i < k; i++) {
        for (d = 0; d < (width < k - i ? width : k - i); d++) {
            const int j = i + d;
            /* A[i][j] - sum_p R[p][i] R[p][j] over the rows p < i whose band reaches column j. */
            double acc = a[i][d];
            for (p = (j > w ? j - w : 0); p < i; p++) {
                acc -= a[p][i - p] * a[p][j - p];
            }
            if (d == 0) {
                if (!(acc > 0.0 && isfinite(acc))) {
                    for (p = 0; p < k; p++) {
                        b[p] = NAN;
                    }
                    return;
                }
                a[i][0] = sqrt(acc);
            } else {
                a[i][d] = acc / a[i][0];
            }
        }
    }
    /* R^T y = b, then R x = y (in place in b). */
    for (i = 0; i < k; i++) {
        double acc = b[i];
        for (p = (i > w ? i - w : 0); p < i; p++) {
            acc -= a[p][i - p] * b[p];
        }
        b[i] = acc / a[i][0];
    }
    for (i = k - 1; i >= 0; i--) {
        double acc = b[i];
        for (q = i + 1; q < (k < i + width ? k : i + width); q++) {
            acc -= a[i][q - i] * b[q];
        }
        b[i] = acc / a[i][0];
    }
}
