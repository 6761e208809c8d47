/* L D L^T of a tridiagonal A (the Rust module's solve_tridiagonal, its operations in its order): solves
   A x = r given as the rows a[k] = A[k][k], A[k][k + 1], r[k] (A[K - 1][K] = 0), x into x. 0 where the rows'
   solve is needed: a diagonal entry that is not a positive normal number, a pivot at or below 1e-10 of its
   diagonal entry (A singular), or an answer not finite. */
int solve_tridiagonal(double a[][3], double x[]) {
    const int n = CONSTRAINTS;
    double inv[CONSTRAINTS], l[CONSTRAINTS];
    double e = 0.0, inv_prev = 0.0, y_prev = 0.0, next = 0.0;
    int ok = 1, k;
    for (k = 0; k < n; k++) {
        const double diagonal = a[k][0], upper = a[k][1], r = a[k][2];
        /* d_k = A[k][k] - A[k - 1][k]^2 / d_{k-1}, y_k = r_k - L_k y_{k-1}. */
        const double d = diagonal - e * e * inv_prev;
        const double lk = e * inv_prev;
        const double y = r - lk * y_prev;
        ok &= (diagonal >= DBL_MIN) & (d > 1e-10 * diagonal);
        inv[k] = 1.0 / d;
        l[k] = lk;
        x[k] = y;
        e = upper;
        inv_prev = inv[k];
        y_prev = y;
    }
    /* D L^T x = y: x_{K-1} = y_{K-1} / d_{K-1}, x_k = y_k / d_k - L_{k+1} x_{k+1}. */
    for (k = n - 1; k >= 0; k--) {
        const double xk = k + 1 < n ? x[k] * inv[k] - l[k + 1] * next : x[k] * inv[k];
        ok &= isfinite(xk) != 0;
        x[k] = xk;
        next = xk;
    }
    return ok;
}
