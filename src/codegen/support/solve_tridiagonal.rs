//! Written into a generated module whose constraints are all equalities and whose A is
//! tridiagonal (a chain listed in order): `solve_tridiagonal`, L D Lᵀ on the rows of the
//! system A λ = −b that `band_system` writes, O(K). It is `solve_band.rs` at w = 1 with the
//! loops over the band's zeros left out: the same operations in the same order, so the same
//! numbers. The fast path before the rows' solve (`rows.rs`), which answers wherever this
//! one gives up.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled
//! by the crate's tests. Not here: wider bands (`solve_band.rs`), redundancy and
//! inequalities (`rows.rs`).

/// Solves A x = r for a symmetric positive definite tridiagonal A given as its rows with r
/// beside them: `a[k]` = [A[k][k], A[k][k + 1], r[k]] (A[K − 1][K] = 0), by A = L D Lᵀ with
/// Lₖ = L[k][k − 1] = A[k − 1][k] / dₖ₋₁. `None` where the rows' solve is needed: a diagonal
/// entry that is not a positive normal number, a pivot dₖ at or below 1e-10 of its diagonal
/// entry (A singular to the rows' rank tolerance), or an answer that is not finite; the
/// checks are gathered, not branched on.
#[allow(clippy::needless_range_loop)]
fn solve_tridiagonal<const K: usize>(a: &[[f64; 3]; K]) -> Option<[f64; K]> {
    // 1/dₖ, Lₖ, and y (L y = r), then x in place of y.
    let mut inv = [0.0; K];
    let mut l = [0.0; K];
    let mut x = [0.0; K];
    let mut ok = true;
    // Row k − 1's A[k − 1][k], 1/dₖ₋₁ and yₖ₋₁ (zero before the first row).
    let (mut e, mut inv_prev, mut y_prev) = (0.0, 0.0, 0.0);
    for k in 0..K {
        let [diagonal, upper, r] = a[k];
        // dₖ = A[k][k] − A[k − 1][k]² / dₖ₋₁, yₖ = rₖ − Lₖ yₖ₋₁.
        let d = diagonal - e * e * inv_prev;
        ok &= (diagonal >= f64::MIN_POSITIVE) & (d > 1e-10 * diagonal);
        let lk = e * inv_prev;
        let y = r - lk * y_prev;
        inv[k] = 1.0 / d;
        l[k] = lk;
        x[k] = y;
        (e, inv_prev, y_prev) = (upper, inv[k], y);
    }
    // D Lᵀ x = y: x_{K−1} = y_{K−1} / d_{K−1}, xₖ = yₖ / dₖ − Lₖ₊₁ xₖ₊₁.
    let mut next = 0.0;
    for k in (0..K).rev() {
        let xk = if k + 1 < K { x[k] * inv[k] - l[k + 1] * next } else { x[k] * inv[k] };
        ok &= xk.is_finite();
        x[k] = xk;
        next = xk;
    }
    if ok { Some(x) } else { None }
}
