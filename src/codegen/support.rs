//! The helper functions a generated module carries, as source text: Gaussian elimination
//! (dense A), band Cholesky (banded A), and the range-safe norms and powers the formulas call.
//!
//! They are written into every module that needs them, so the module stays self-contained
//! (no dependency on lagrange or any crate). Not here: anything generated from a formula
//! ([`super::rust`]).

/// Dense A λ = −b for several constraints. A big A that is not banded is passed as a
/// `Vec<[f64; K]>` instead: the same code with that parameter type (see `rust.rs`).
pub(super) const SOLVE: &str =
    "/// Solves `a x = b` by Gaussian elimination with partial pivoting; NaN if `a` is singular.
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

";

/// Banded A λ = −b (a chain listed in order): Cholesky on the band, O(K w²).
pub(super) const SOLVE_BAND: &str =
    "/// Solves `a x = b` for a symmetric positive definite band matrix given as its upper band
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

";

/// What the formulas may call: `norm2`, `norm3`, `powf`; every module carries them.
pub(super) const HELPERS: &str =
    "/// |(x, y)| without overflow or underflow (the plain formula unless it would lose range).
#[allow(dead_code)]
#[inline]
fn norm2(x: f64, y: f64) -> f64 {
    let s = x * x + y * y;
    if s.is_finite() && s >= f64::MIN_POSITIVE { s.sqrt() } else { x.hypot(y) }
}

/// |(x, y, z)| without overflow or underflow.
#[allow(dead_code)]
#[inline]
fn norm3(x: f64, y: f64, z: f64) -> f64 {
    let s = x * x + y * y + z * z;
    if s.is_finite() && s >= f64::MIN_POSITIVE { s.sqrt() } else { x.hypot(y).hypot(z) }
}

/// `b^e`, integer exponents by `powi` so that negative bases work.
#[allow(dead_code)]
#[inline]
fn powf(b: f64, e: f64) -> f64 {
    if e == e.trunc() && e.abs() <= i32::MAX as f64 { b.powi(e as i32) } else { b.powf(e) }
}
";
