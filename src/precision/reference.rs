//! A double-double (≈ 32 significant digits, `twofloat`) evaluation of graph nodes: the
//! reference the f64 formulas are measured against.
//!
//! It walks the same graph as `expr::eval` with the same semantics, so a difference is the
//! rounding of f64, not a different formula. Rationals enter exactly when numerator and
//! denominator fit in i64 (the usual case); transcendental functions are good to ~1e-23
//! in twofloat, far below f64's 1e-16.
//!
//! Not here: f64 evaluation (`expr::eval`), linear algebra beyond the small dense solve.

use crate::expr::eval::{Env, EvalError, Value};
use crate::expr::{Func, Graph, Id, Node, Ty};
use twofloat::TwoFloat;

/// A double-double scalar or vector.
#[derive(Clone, Copy, Debug)]
pub enum Dd {
    Scalar(TwoFloat),
    Vector([TwoFloat; 3]),
}

const ZERO: TwoFloat = TwoFloat::from_f64(0.0);

impl Dd {
    pub fn scalar(self) -> TwoFloat {
        match self {
            Dd::Scalar(x) => x,
            Dd::Vector(_) => TwoFloat::NAN,
        }
    }

    pub fn vector(self) -> [TwoFloat; 3] {
        match self {
            Dd::Vector(v) => v,
            Dd::Scalar(_) => [TwoFloat::NAN; 3],
        }
    }
}

fn from_value(v: Value) -> Dd {
    match v {
        Value::Scalar(x) => Dd::Scalar(TwoFloat::from(x)),
        Value::Vector(v) => Dd::Vector(v.map(TwoFloat::from)),
    }
}

/// `b^e` with integer exponents by repeated multiplication (as `expr::eval::pow`).
fn pow(b: TwoFloat, e: TwoFloat) -> TwoFloat {
    let eh = e.hi();
    if e.lo() == 0.0 && eh == eh.trunc() && eh.abs() <= i32::MAX as f64 { b.powi(eh as i32) } else { b.powf(e) }
}

fn apply(f: Func, x: TwoFloat) -> TwoFloat {
    match f {
        Func::Sqrt => x.sqrt(),
        Func::Sin => x.sin(),
        Func::Cos => x.cos(),
        Func::Tan => x.tan(),
        Func::Asin => x.asin(),
        Func::Acos => x.acos(),
        Func::Atan => x.atan(),
        Func::Exp => x.exp(),
        Func::Ln => x.ln(),
    }
}

/// Evaluates `roots` at `env` in double-double.
pub fn eval_dd(graph: &Graph, roots: &[Id], env: &Env) -> Result<Vec<Dd>, EvalError> {
    let order = graph.reachable(roots);
    let mut values = vec![Dd::Scalar(ZERO); graph.len()];
    for id in order {
        let s = |i: &Id| values[i.index()].scalar();
        let v = |i: &Id| values[i.index()].vector();
        let out = match graph.node(id) {
            Node::Num(q) => Dd::Scalar(match q.as_small() {
                Some((n, d)) => TwoFloat::from(n) / TwoFloat::from(d),
                None => TwoFloat::from(q.to_f64()),
            }),
            Node::Sym(sym) => match env.get(*sym) {
                Some(x) => from_value(x),
                None => return Err(EvalError::Missing(graph.symbol(*sym).name.clone())),
            },
            Node::Vector(xs) => {
                let mut out = [ZERO; 3];
                for (o, x) in out.iter_mut().zip(xs.iter()) {
                    *o = s(x);
                }
                Dd::Vector(out)
            }
            Node::Add(xs) => match graph.ty(xs[0]) {
                Ty::Scalar => Dd::Scalar(xs.iter().fold(ZERO, |a, x| a + s(x))),
                Ty::Vector => {
                    let mut out = [ZERO; 3];
                    for x in xs.iter() {
                        let w = v(x);
                        for k in 0..3 {
                            out[k] += w[k];
                        }
                    }
                    Dd::Vector(out)
                }
            },
            Node::Mul(xs) => {
                let mut k = TwoFloat::from(1.0);
                let mut vec = None;
                for x in xs.iter() {
                    match values[x.index()] {
                        Dd::Scalar(y) => k *= y,
                        Dd::Vector(w) => vec = Some(w),
                    }
                }
                match vec {
                    Some(w) => Dd::Vector(w.map(|c| k * c)),
                    None => Dd::Scalar(k),
                }
            }
            Node::Pow([b, e]) => Dd::Scalar(pow(s(b), s(e))),
            Node::Dot([a, b]) => {
                let (a, b) = (v(a), v(b));
                Dd::Scalar(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            }
            Node::Cross([a, b]) => {
                let (a, b) = (v(a), v(b));
                let z = a[0] * b[1] - a[1] * b[0];
                if graph.dim() == 2 {
                    Dd::Scalar(z)
                } else {
                    Dd::Vector([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], z])
                }
            }
            Node::Norm(a) => {
                let a = v(a);
                Dd::Scalar((a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt())
            }
            Node::Comp(a, axis) => Dd::Scalar(v(a)[axis.index()]),
            Node::Call(f, a) => Dd::Scalar(apply(*f, s(a))),
            Node::Atan2([y, x]) => Dd::Scalar(s(y).atan2(s(x))),
        };
        values[id.index()] = out;
    }
    Ok(roots.iter().map(|r| values[r.index()]).collect())
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
