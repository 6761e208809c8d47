//! Written into a generated module whose constraints are all equalities and whose A is not
//! tridiagonal (a banded A of half-bandwidth w ≥ 2, or a small dense one as its band of
//! w = K − 1): `solve_band`, L D Lᵀ (Cholesky without square roots) on the band rows of the
//! system A λ = −b that `band_system` writes, O(K w²), with 1/dᵢ kept so the solves
//! multiply. The fast path before the rows' solve (`rows.rs`), which answers wherever this
//! one gives up. A tridiagonal A takes `solve_tridiagonal.rs`, these operations with the
//! loops over the band's zeros left out.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled
//! by the crate's tests. Not here: redundancy and inequalities (`rows.rs`).

/// Solves A x = r for a symmetric positive definite band matrix A of half-bandwidth
/// w = B − 2, given as its rows with r beside them: `a[i]` = [A[i][i], A[i][i + 1], …,
/// A[i][i + w], r[i]] (zeros past the last column), by A = Rᵀ D R (R unit upper triangular),
/// T = D R in place of A's band. `None` where the rows' solve is needed: a diagonal entry
/// that is not a positive normal number (its numbers out of f64's range), a pivot dᵢ at or
/// below 1e-10 of its diagonal entry (the rows' rank tolerance, as `solve_dense`: A singular,
/// constraints redundant), or an answer that is not finite. The checks are gathered, not
/// branched on: a module that gives up has the rows' solve to run anyway.
#[allow(clippy::needless_range_loop)]
fn solve_band<const K: usize, const B: usize>(mut a: [[f64; B]; K]) -> Option<[f64; K]> {
    let w = B - 2;
    // 1/dᵢ of each pivot.
    let mut inv = [0.0; K];
    let mut ok = true;
    for i in 0..K {
        for d in 0..(w + 1).min(K - i) {
            let j = i + d;
            // T[i][j] = A[i][j] − Σₚ T[p][i] T[p][j] / dₚ over the rows p < i whose band reaches column j.
            let mut acc = a[i][d];
            for p in j.saturating_sub(w)..i {
                acc -= a[p][i - p] * a[p][j - p] * inv[p];
            }
            if d == 0 {
                // dᵢ = T[i][i]: positive and above the rank tolerance, A[i][i] a normal number.
                ok &= (a[i][0] >= f64::MIN_POSITIVE) & (acc > 1e-10 * a[i][0]);
                inv[i] = 1.0 / acc;
            }
            a[i][d] = acc;
        }
        // Rᵀ y = r: yᵢ = rᵢ − Σₚ R[p][i] yₚ with R[p][i] = T[p][i] / dₚ (y in place of r).
        let mut y = a[i][B - 1];
        for p in i.saturating_sub(w)..i {
            y -= a[p][i - p] * inv[p] * a[p][B - 1];
        }
        a[i][B - 1] = y;
    }
    // D R x = y: xᵢ = yᵢ / dᵢ − Σ_q R[i][q] x_q.
    let mut x = [0.0; K];
    for i in (0..K).rev() {
        let mut acc = a[i][B - 1] * inv[i];
        for q in i + 1..K.min(i + w + 1) {
            acc -= a[i][q - i] * inv[i] * x[q];
        }
        ok &= acc.is_finite();
        x[i] = acc;
    }
    if ok { Some(x) } else { None }
}
