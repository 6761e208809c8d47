//! Written into a generated module whose A is banded (a chain listed in order):
//! `solve_band`, Cholesky on the band, O(K w²).
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled
//! by the crate's tests. Not here: dense A (`solve.rs`, `solve_heap.rs`).

/// Solves `a x = b` for a symmetric positive definite band matrix given as its upper band
/// (`a[i][d]` = A[i][i + d]) by Cholesky, A = RᵀR, in place; NaN if A is not positive definite.
#[allow(clippy::needless_range_loop)]
fn solve_band<const K: usize, const B: usize>(mut a: [[f64; B]; K], mut b: [f64; K]) -> [f64; K] {
    let w = B - 1;
    for i in 0..K {
        for d in 0..B.min(K - i) {
            let j = i + d;
            // A[i][j] − Σₚ R[p][i] R[p][j] over the rows p < i whose band reaches column j.
            let mut acc = a[i][d];
            for p in j.saturating_sub(w)..i {
                acc -= a[p][i - p] * a[p][j - p];
            }
            if d == 0 {
                if !(acc > 0.0 && acc.is_finite()) {
                    return [f64::NAN; K];
                }
                a[i][0] = acc.sqrt();
            } else {
                a[i][d] = acc / a[i][0];
            }
        }
    }
    // Rᵀ y = b, then R x = y (in place in b).
    for i in 0..K {
        let mut acc = b[i];
        for p in i.saturating_sub(w)..i {
            acc -= a[p][i - p] * b[p];
        }
        b[i] = acc / a[i][0];
    }
    for i in (0..K).rev() {
        let mut acc = b[i];
        for q in i + 1..K.min(i + B) {
            acc -= a[i][q - i] * b[q];
        }
        b[i] = acc / a[i][0];
    }
    b
}
