//! The interpreter of graph nodes, generic over the scalar type: `f64` (the reference
//! semantics of every fast path, and what `solve` uses for the scene's forces and masses)
//! and double-double (`bench::reference`, the yardstick of f64's rounding).
//!
//! It walks the reachable nodes once in id order (children first), so it needs no
//! recursion. One walk for every scalar type means one meaning of each operation: `b^e`
//! is [`pow`], `|a|` is [`norm`] and functions are [`Func::apply`](super::Func::apply) whatever the precision,
//! so a difference between two precisions is rounding, never a different formula.
//!
//! Not here: speed (`numeric` compiles expressions to a flat tape, with the same
//! semantics: [`norm`] and [`pow`] are its too), scalar types' implementations other
//! than f64's (double-double's is in `bench::reference`).

use super::graph::{Graph, Id, Node, Symbol, Ty};
use super::num::Rational;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub};

/// What the interpreter needs of a number type: field operations, the functions of the
/// table ([`Func::apply`](super::Func::apply)), and exact entry of rationals where the type can hold them.
pub trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + MulAssign
{
    const ZERO: Self;
    const ONE: Self;
    /// The value of a wrong-typed operand (a scalar read as a vector, or the reverse).
    const NAN: Self;
    fn from_f64(x: f64) -> Self;
    /// `q`, as close as the type allows.
    fn from_rational(q: &Rational) -> Self;
    /// Whether `x² + y² + …` summed to this can be square-rooted as it is: finite and not
    /// below the smallest normal number (else [`norm`] rescales through `hypot`).
    fn is_safe_square(self) -> bool;
    /// `sqrt(self² + other²)` without overflow or underflow.
    fn hypot(self, other: Self) -> Self;
    /// `self` if it is an integer that fits in `i32`.
    fn as_i32(self) -> Option<i32>;
    fn powi(self, n: i32) -> Self;
    fn powf(self, e: Self) -> Self;
    fn sqrt(self) -> Self;
    fn sin(self) -> Self;
    fn cos(self) -> Self;
    fn tan(self) -> Self;
    fn asin(self) -> Self;
    fn acos(self) -> Self;
    fn atan(self) -> Self;
    fn exp(self) -> Self;
    fn ln(self) -> Self;
    fn atan2(self, x: Self) -> Self;
}

impl Scalar for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    const NAN: f64 = f64::NAN;
    fn from_f64(x: f64) -> f64 {
        x
    }
    fn from_rational(q: &Rational) -> f64 {
        q.to_f64()
    }
    #[inline]
    fn is_safe_square(self) -> bool {
        self.is_finite() && self >= f64::MIN_POSITIVE
    }
    #[inline]
    fn hypot(self, other: f64) -> f64 {
        f64::hypot(self, other)
    }
    #[inline]
    fn as_i32(self) -> Option<i32> {
        (self == self.trunc() && self.abs() <= i32::MAX as f64).then_some(self as i32)
    }
    fn powi(self, n: i32) -> f64 {
        f64::powi(self, n)
    }
    fn powf(self, e: f64) -> f64 {
        f64::powf(self, e)
    }
    #[inline]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
    fn sin(self) -> f64 {
        f64::sin(self)
    }
    fn cos(self) -> f64 {
        f64::cos(self)
    }
    fn tan(self) -> f64 {
        f64::tan(self)
    }
    fn asin(self) -> f64 {
        f64::asin(self)
    }
    fn acos(self) -> f64 {
        f64::acos(self)
    }
    fn atan(self) -> f64 {
        f64::atan(self)
    }
    fn exp(self) -> f64 {
        f64::exp(self)
    }
    fn ln(self) -> f64 {
        f64::ln(self)
    }
    fn atan2(self, x: f64) -> f64 {
        f64::atan2(self, x)
    }
}

/// `b^e`, with integer exponents done by `powi` so that negative bases work.
#[inline]
pub fn pow<S: Scalar>(b: S, e: S) -> S {
    match e.as_i32() {
        Some(n) => b.powi(n),
        None => b.powf(e),
    }
}

/// `|x|`, overflow-safe: the square root of the sum of squares when that sum is a finite
/// normal number (the common case, one rounding per operation), otherwise `hypot` folded
/// over the components, so |r| ≈ 1e155 or 1e−160 still comes out right. The one meaning
/// of `norm`: the interpreter, the double-double reference, the tape and the generated
/// code all compute this.
#[inline]
pub fn norm<S: Scalar, const N: usize>(x: [S; N]) -> S {
    let mut s = x[0] * x[0];
    for &c in &x[1..] {
        s += c * c;
    }
    if s.is_safe_square() { s.sqrt() } else { x[1..].iter().fold(x[0], |h, &c| h.hypot(c)) }
}

/// A value: a scalar, or a vector whose unused trailing components are zero, or a 3D
/// orientation's quaternion [w, x, y, z] (the value of an orientation symbol in 3D only).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<S = f64> {
    Scalar(S),
    Vector([S; 3]),
    Quaternion([S; 4]),
}

/// R(q) u for a quaternion q = [w, x, y, z] (Hamilton), not normalised: the matrix of
/// DESIGN.md, "Rigid bodies",
/// [[1−2(y²+z²), 2(xy−wz), 2(xz+wy)], [2(xy+wz), 1−2(x²+z²), 2(yz−wx)], [2(xz−wy), 2(yz+wx), 1−2(x²+y²)]].
/// The one meaning of `rot` in 3D: the interpreter's; the tape lowers the same products.
pub fn rotate<S: Scalar>(q: [S; 4], u: [S; 3]) -> [S; 3] {
    let [w, x, y, z] = q;
    let two = S::ONE + S::ONE;
    let m = [
        [S::ONE - two * (y * y + z * z), two * (x * y - w * z), two * (x * z + w * y)],
        [two * (x * y + w * z), S::ONE - two * (x * x + z * z), two * (y * z - w * x)],
        [two * (x * z - w * y), two * (y * z + w * x), S::ONE - two * (x * x + y * y)],
    ];
    m.map(|row| row[0] * u[0] + row[1] * u[1] + row[2] * u[2])
}

impl<S: Scalar> Value<S> {
    pub fn scalar(self) -> Option<S> {
        match self {
            Value::Scalar(x) => Some(x),
            Value::Vector(_) | Value::Quaternion(_) => None,
        }
    }

    pub fn vector(self) -> Option<[S; 3]> {
        match self {
            Value::Vector(v) => Some(v),
            Value::Scalar(_) | Value::Quaternion(_) => None,
        }
    }

    pub fn quaternion(self) -> Option<[S; 4]> {
        match self {
            Value::Quaternion(q) => Some(q),
            Value::Scalar(_) | Value::Vector(_) => None,
        }
    }

    /// The scalar, or NaN for a vector.
    pub fn scalar_or_nan(self) -> S {
        self.scalar().unwrap_or(S::NAN)
    }

    /// The vector, or NaNs for a scalar.
    pub fn vector_or_nan(self) -> [S; 3] {
        self.vector().unwrap_or([S::NAN; 3])
    }

    /// The same value in another scalar type.
    pub fn map<T>(self, f: impl Fn(S) -> T) -> Value<T> {
        match self {
            Value::Scalar(x) => Value::Scalar(f(x)),
            Value::Vector(v) => Value::Vector(v.map(f)),
            Value::Quaternion(q) => Value::Quaternion(q.map(f)),
        }
    }
}

impl Value {
    /// The components as a slice-like array (a scalar is one entry).
    pub fn components(self, dim: usize) -> Vec<f64> {
        match self {
            Value::Scalar(x) => vec![x],
            Value::Vector(v) => v[..dim].to_vec(),
            Value::Quaternion(q) => q.to_vec(),
        }
    }

    pub fn is_finite(self) -> bool {
        match self {
            Value::Scalar(x) => x.is_finite(),
            Value::Vector(v) => v.iter().all(|x| x.is_finite()),
            Value::Quaternion(q) => q.iter().all(|x| x.is_finite()),
        }
    }
}

/// Values of symbols, indexed by symbol.
#[derive(Clone, Debug, Default)]
pub struct Env {
    values: Vec<Option<Value>>,
}

impl Env {
    pub fn new() -> Env {
        Env::default()
    }

    pub fn set(&mut self, s: Symbol, v: Value) {
        if self.values.len() <= s.index() {
            self.values.resize(s.index() + 1, None);
        }
        self.values[s.index()] = Some(v);
    }

    pub fn get(&self, s: Symbol) -> Option<Value> {
        self.values.get(s.index()).copied().flatten()
    }
}

/// Why an expression could not be evaluated.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EvalError {
    #[error("no value for `{0}`")]
    Missing(String),
}

/// Evaluates `roots` at `env` in f64.
pub fn eval(graph: &Graph, roots: &[Id], env: &Env) -> Result<Vec<Value>, EvalError> {
    eval_as::<f64>(graph, roots, env)
}

/// Evaluates one root to a scalar or vector, in f64.
pub fn eval_one(graph: &Graph, root: Id, env: &Env) -> Result<Value, EvalError> {
    Ok(eval(graph, &[root], env)?[0])
}

/// Evaluates `roots` at `env` (values given in f64) in the scalar type `S`.
pub fn eval_as<S: Scalar>(graph: &Graph, roots: &[Id], env: &Env) -> Result<Vec<Value<S>>, EvalError> {
    let order = graph.reachable(roots);
    let mut values: Vec<Value<S>> = vec![Value::Scalar(S::ZERO); graph.len()];
    for id in order {
        values[id.index()] = eval_node(graph, graph.node(id), &values, env)?;
    }
    Ok(roots.iter().map(|r| values[r.index()]).collect())
}

fn eval_node<S: Scalar>(graph: &Graph, node: &Node, values: &[Value<S>], env: &Env) -> Result<Value<S>, EvalError> {
    let s = |id: &Id| values[id.index()].scalar_or_nan();
    let v = |id: &Id| values[id.index()].vector_or_nan();
    Ok(match node {
        Node::Num(q) => Value::Scalar(S::from_rational(q)),
        Node::Sym(sym) => match env.get(*sym) {
            Some(x) => x.map(S::from_f64),
            None => return Err(EvalError::Missing(graph.symbol(*sym).name.clone())),
        },
        Node::Vector(xs) => {
            let mut out = [S::ZERO; 3];
            for (o, x) in out.iter_mut().zip(xs.iter()) {
                *o = s(x);
            }
            Value::Vector(out)
        }
        Node::Add(xs) => match graph.ty(xs[0]) {
            // From the first term, as f64's `Sum` (which starts from −0) gives.
            Ty::Scalar => Value::Scalar(xs[1..].iter().fold(s(&xs[0]), |acc, x| acc + s(x))),
            Ty::Vector => {
                let mut out = [S::ZERO; 3];
                for x in xs.iter() {
                    let w = v(x);
                    for k in 0..3 {
                        out[k] += w[k];
                    }
                }
                Value::Vector(out)
            }
        },
        Node::Mul(xs) => {
            let mut k = S::ONE;
            let mut vec = None;
            for x in xs.iter() {
                match values[x.index()] {
                    Value::Scalar(y) => k *= y,
                    Value::Vector(w) => vec = Some(w),
                    // Never a factor: the lowering allows a quaternion only in `rot`.
                    Value::Quaternion(_) => k *= S::NAN,
                }
            }
            match vec {
                Some(w) => Value::Vector(w.map(|c| k * c)),
                None => Value::Scalar(k),
            }
        }
        Node::Pow([b, e]) => Value::Scalar(pow(s(b), s(e))),
        Node::Dot([a, b]) => {
            let (a, b) = (v(a), v(b));
            Value::Scalar(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
        }
        Node::Cross([a, b]) => {
            let (a, b) = (v(a), v(b));
            let z = a[0] * b[1] - a[1] * b[0];
            if graph.dim() == 2 {
                Value::Scalar(z)
            } else {
                Value::Vector([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], z])
            }
        }
        Node::Norm(a) => {
            let a = v(a);
            Value::Scalar(if graph.dim() == 2 { norm([a[0], a[1]]) } else { norm(a) })
        }
        Node::Comp(a, axis) => Value::Scalar(v(a)[axis.index()]),
        Node::Call(f, _) => {
            let mut args = [S::ZERO; super::func::MAX_ARITY];
            for (arg, c) in args.iter_mut().zip(node.children()) {
                *arg = s(c);
            }
            Value::Scalar(f.apply(&args))
        }
        Node::Rot([q, u]) if graph.dim() == 3 => {
            let q = values[q.index()].quaternion().unwrap_or([S::NAN; 4]);
            Value::Vector(rotate(q, v(u)))
        }
        Node::Rot([theta, u]) => {
            let (th, u) = (s(theta), v(u));
            let (sin, cos) = (th.sin(), th.cos());
            Value::Vector([cos * u[0] - sin * u[1], sin * u[0] + cos * u[1], S::ZERO])
        }
        Node::Perp(a) => {
            let a = v(a);
            Value::Vector([-a[1], a[0], S::ZERO])
        }
    })
}
