//! A double-double (≈ 32 significant digits, `twofloat`) evaluation of graph nodes: the
//! reference the f64 formulas are measured against.
//!
//! The evaluation is `expr::eval`'s own interpreter run in this scalar type (the
//! [`Scalar`] implementation here), so a difference is the rounding of f64, not a
//! different formula. Rationals enter exactly when numerator and denominator fit in i64
//! (the usual case); transcendental functions are good to ~1e-23 in twofloat, far below
//! f64's 1e-16.
//!
//! Not here: the interpreter itself (`expr::eval`), linear algebra beyond the small dense
//! solve.

use crate::expr::eval::{Env, EvalError, Scalar, Value, eval_as};
use crate::expr::{Graph, Id, Rational};
use twofloat::TwoFloat;

/// A double-double scalar or vector.
pub type Dd = Value<TwoFloat>;

const ZERO: TwoFloat = TwoFloat::from_f64(0.0);

impl Scalar for TwoFloat {
    const ZERO: TwoFloat = ZERO;
    const ONE: TwoFloat = TwoFloat::from_f64(1.0);
    const NAN: TwoFloat = TwoFloat::NAN;
    fn from_f64(x: f64) -> TwoFloat {
        TwoFloat::from(x)
    }
    /// Exact when numerator and denominator fit in i64 (the usual case).
    fn from_rational(q: &Rational) -> TwoFloat {
        match q.as_small() {
            Some((n, d)) => TwoFloat::from(n) / TwoFloat::from(d),
            None => TwoFloat::from(q.to_f64()),
        }
    }
    fn is_safe_square(self) -> bool {
        self.hi().is_finite() && self.hi() >= f64::MIN_POSITIVE
    }
    /// `m·sqrt((a/m)² + (b/m)²)` with `m = max(|a|, |b|)`: no square leaves the range.
    fn hypot(self, other: TwoFloat) -> TwoFloat {
        let (a, b) = (self.abs(), other.abs());
        let m = if a >= b { a } else { b };
        if m == ZERO || !m.is_valid() {
            return m;
        }
        let (x, y) = (a / m, b / m);
        m * (x * x + y * y).sqrt()
    }
    fn as_i32(self) -> Option<i32> {
        let h = self.hi();
        (self.lo() == 0.0 && h == h.trunc() && h.abs() <= i32::MAX as f64).then_some(h as i32)
    }
    fn powi(self, n: i32) -> TwoFloat {
        TwoFloat::powi(self, n)
    }
    fn powf(self, e: TwoFloat) -> TwoFloat {
        TwoFloat::powf(self, e)
    }
    fn sqrt(self) -> TwoFloat {
        TwoFloat::sqrt(self)
    }
    fn sin(self) -> TwoFloat {
        TwoFloat::sin(self)
    }
    fn cos(self) -> TwoFloat {
        TwoFloat::cos(self)
    }
    fn tan(self) -> TwoFloat {
        TwoFloat::tan(self)
    }
    fn asin(self) -> TwoFloat {
        TwoFloat::asin(self)
    }
    fn acos(self) -> TwoFloat {
        TwoFloat::acos(self)
    }
    fn atan(self) -> TwoFloat {
        TwoFloat::atan(self)
    }
    fn exp(self) -> TwoFloat {
        TwoFloat::exp(self)
    }
    fn ln(self) -> TwoFloat {
        TwoFloat::ln(self)
    }
    fn atan2(self, x: TwoFloat) -> TwoFloat {
        TwoFloat::atan2(self, x)
    }
}

/// Evaluates `roots` at `env` in double-double: the interpreter of `expr::eval`, in
/// this scalar type.
pub fn eval_dd(graph: &Graph, roots: &[Id], env: &Env) -> Result<Vec<Dd>, EvalError> {
    eval_as::<TwoFloat>(graph, roots, env)
}

/// Solves the small dense system `a x = b` in double-double by Gaussian elimination with
/// partial pivoting; None when a pivot vanishes (a singular A has no unique reference).
pub fn solve_dense(mut a: Vec<Vec<TwoFloat>>, mut b: Vec<TwoFloat>) -> Option<Vec<TwoFloat>> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&i, &j| a[i][col].abs().partial_cmp(&a[j][col].abs()).unwrap_or(std::cmp::Ordering::Equal))?;
        if a[pivot][col] == ZERO {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let (top, rest) = a.split_at_mut(col + 1);
        let pivot_row = &top[col];
        for (offset, row) in rest.iter_mut().enumerate() {
            let f = row[col] / pivot_row[col];
            for (x, p) in row[col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * *p;
            }
            let t = b[col];
            b[col + 1 + offset] -= f * t;
        }
    }
    let mut x = vec![ZERO; n];
    for row in (0..n).rev() {
        let mut acc = b[row];
        for k in row + 1..n {
            acc -= a[row][k] * x[k];
        }
        x[row] = acc / a[row][row];
    }
    Some(x)
}
