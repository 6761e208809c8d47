//! Written into a generated module whose A is big and not banded, returned on the heap:
//! `solve`, the elimination of `solve.rs` on A's rows in a `Vec` (no K×K stack frame).
//!
//! The text is `solve.rs`'s but for the type of `a` (a test keeps the two bodies equal).
//! Included with `include_str!` from the first item on; compiled by the crate's tests.
//! Not here: the stack variant (`solve.rs`).

/// Solves `a x = b` by Gaussian elimination with partial pivoting; NaN if `a` is singular.
#[allow(clippy::needless_range_loop)]
fn solve<const K: usize>(mut a: Vec<[f64; K]>, mut b: [f64; K]) -> [f64; K] {
    for col in 0..K {
        let mut p = col;
        for row in col + 1..K {
            if a[row][col].abs() > a[p][col].abs() {
                p = row;
            }
        }
        a.swap(col, p);
        b.swap(col, p);
        let pivot = a[col][col];
        if pivot == 0.0 || !pivot.is_finite() {
            return [f64::NAN; K];
        }
        for row in col + 1..K {
            let f = a[row][col] / pivot;
            if f != 0.0 {
                for c in col..K {
                    a[row][c] -= f * a[col][c];
                }
                b[row] -= f * b[col];
            }
        }
    }
    let mut x = [0.0; K];
    for row in (0..K).rev() {
        let mut acc = b[row];
        for c in row + 1..K {
            acc -= a[row][c] * x[c];
        }
        x[row] = acc / a[row][row];
    }
    x
}
