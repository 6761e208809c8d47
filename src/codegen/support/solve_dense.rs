//! Written into a generated module whose A is a small dense array and whose constraints are
//! all equalities: `solve_dense`, L D Lᵀ (Cholesky without square roots) on the K×K array
//! (2×2: the same pivot rule multiplied out, and Cramer's rule), the fast path before the
//! rows' solve (`rows.rs`), which answers wherever this one gives up.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled
//! by the crate's tests. Not here: banded A (`solve_band.rs`), redundancy and inequalities
//! (`rows.rs`).

/// Solves `a x = b` for a symmetric positive definite `a` by Cholesky in its square-root-free
/// form, A = L D Lᵀ (L below the diagonal and D on it, in place). `None` where the rows' solve
/// is needed: a diagonal entry that is not a positive normal number (its numbers out of f64's
/// range), a pivot dᵢ at or below 1e-10 of its diagonal entry (the rows' rank tolerance on the
/// unit-diagonal Ã: A singular, constraints redundant), or an answer that is not finite.
///
/// A 2×2 `a` (a 2D pin, two rods) takes the same factorisation multiplied out: d₀ = a₀₀ and
/// d₁ = det/a₀₀ with det = a₀₀a₁₁ − a₁₀², so the pivot rule d₁ > 1e-10 a₁₁ reads
/// det > 1e-10 a₀₀a₁₁, and x = adj(A) b / det (Cramer's rule) costs one division where the
/// loops chain three. It also gives up where a₀₀a₁₁ leaves f64's normal range (overflowing,
/// the pivot rule compares ∞ with ∞), which the loops need not: a hand-over, never a wrong
/// answer.
#[allow(dead_code, clippy::needless_range_loop)]
fn solve_dense<const K: usize>(mut a: [[f64; K]; K], mut b: [f64; K]) -> Option<[f64; K]> {
    if K == 2 {
        let (p, q, r) = (a[0][0], a[1][1], a[1][0]);
        let pq = p * q;
        let det = pq - r * r;
        let x = [(q * b[0] - r * b[1]) / det, (p * b[1] - r * b[0]) / det];
        // Every check at once (`&`, one branch): a₀₀ and a₁₁ positive normal numbers (+∞ fails
        // the det check), a₀₀a₁₁ normal, the pivot rule (false for a NaN), x finite.
        let solved = (p >= f64::MIN_POSITIVE)
            & (q >= f64::MIN_POSITIVE)
            & (pq >= f64::MIN_POSITIVE)
            & (det > 1e-10 * pq)
            & x[0].is_finite()
            & x[1].is_finite();
        b[0] = x[0];
        b[1] = x[1];
        return if solved { Some(b) } else { None };
    }
    for i in 0..K {
        let diagonal = a[i][i];
        if !(diagonal.is_normal() && diagonal > 0.0) {
            return None;
        }
        for j in 0..i {
            // L[i][j] = (A[i][j] − Σₚ L[i][p] dₚ L[j][p]) / dⱼ
            let mut acc = a[i][j];
            for p in 0..j {
                acc -= a[i][p] * a[p][p] * a[j][p];
            }
            a[i][j] = acc / a[j][j];
        }
        // dᵢ = A[i][i] − Σₚ L[i][p]² dₚ
        let mut d = diagonal;
        for p in 0..i {
            d -= a[i][p] * a[i][p] * a[p][p];
        }
        if !(d > 1e-10 * diagonal && d.is_finite()) {
            return None;
        }
        a[i][i] = d;
    }
    // L y = b, D z = y, Lᵀ x = z (in place in b).
    for i in 0..K {
        for p in 0..i {
            b[i] -= a[i][p] * b[p];
        }
    }
    for i in 0..K {
        b[i] /= a[i][i];
    }
    for i in (0..K).rev() {
        for p in i + 1..K {
            b[i] -= a[p][i] * b[p];
        }
    }
    if b.iter().all(|x| x.is_finite()) { Some(b) } else { None }
}
