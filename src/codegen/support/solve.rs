//! Written into a generated module with several constraints and a dense A on the stack:
//! `solve`, Gaussian elimination with partial pivoting (`lambda` calls it on `a_matrix`).
//!
//! This file is the text itself: `codegen::rust` includes it with `include_str!` from the
//! first item on (this note is left out), and the crate's tests compile it as a module.
//! Not here: the heap-A variant (`solve_heap.rs`, the same elimination on rows in a `Vec`).

/// Solves `a x = b` by Gaussian elimination with partial pivoting; NaN if `a` is singular.
#[allow(clippy::needless_range_loop)]
fn solve<const K: usize>(mut a: [[f64; K]; K], mut b: [f64; K]) -> [f64; K] {
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
