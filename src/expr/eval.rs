//! A plain interpreter of graph nodes over `f64`, for tests and equivalence checks.
//!
//! It walks the reachable nodes once in id order (children first), so it needs no
//! recursion. It is the reference the fast paths are compared against, not a fast path:
//! `numeric` compiles expressions to a flat tape for speed.

use super::graph::{Func, Graph, Id, Node, Symbol, Ty};

/// A value: a scalar, or a vector whose unused trailing components are zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    Scalar(f64),
    Vector([f64; 3]),
}

impl Value {
    pub fn scalar(self) -> Option<f64> {
        match self {
            Value::Scalar(x) => Some(x),
            Value::Vector(_) => None,
        }
    }

    pub fn vector(self) -> Option<[f64; 3]> {
        match self {
            Value::Vector(v) => Some(v),
            Value::Scalar(_) => None,
        }
    }

    /// The components as a slice-like array (a scalar is one entry).
    pub fn components(self, dim: usize) -> Vec<f64> {
        match self {
            Value::Scalar(x) => vec![x],
            Value::Vector(v) => v[..dim].to_vec(),
        }
    }

    pub fn is_finite(self) -> bool {
        match self {
            Value::Scalar(x) => x.is_finite(),
            Value::Vector(v) => v.iter().all(|x| x.is_finite()),
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

/// Evaluates `roots` at `env`.
pub fn eval(graph: &Graph, roots: &[Id], env: &Env) -> Result<Vec<Value>, EvalError> {
    let order = graph.reachable(roots);
    let mut values: Vec<Value> = vec![Value::Scalar(0.0); graph.len()];
    for id in order {
        values[id.index()] = eval_node(graph, graph.node(id), &values, env)?;
    }
    Ok(roots.iter().map(|r| values[r.index()]).collect())
}

/// Evaluates one root to a scalar or vector.
pub fn eval_one(graph: &Graph, root: Id, env: &Env) -> Result<Value, EvalError> {
    Ok(eval(graph, &[root], env)?[0])
}

fn eval_node(graph: &Graph, node: &Node, values: &[Value], env: &Env) -> Result<Value, EvalError> {
    let s = |id: &Id| match values[id.index()] {
        Value::Scalar(x) => x,
        Value::Vector(_) => f64::NAN,
    };
    let v = |id: &Id| match values[id.index()] {
        Value::Vector(x) => x,
        Value::Scalar(_) => [f64::NAN; 3],
    };
    Ok(match node {
        Node::Num(q) => Value::Scalar(q.to_f64()),
        Node::Sym(sym) => match env.get(*sym) {
            Some(x) => x,
            None => return Err(EvalError::Missing(graph.symbol(*sym).name.clone())),
        },
        Node::Vector(xs) => {
            let mut out = [0.0; 3];
            for (o, x) in out.iter_mut().zip(xs.iter()) {
                *o = s(x);
            }
            Value::Vector(out)
        }
        Node::Add(xs) => match graph.ty(xs[0]) {
            Ty::Scalar => Value::Scalar(xs.iter().map(s).sum()),
            Ty::Vector => {
                let mut out = [0.0; 3];
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
            let mut k = 1.0;
            let mut vec = None;
            for x in xs.iter() {
                match values[x.index()] {
                    Value::Scalar(y) => k *= y,
                    Value::Vector(w) => vec = Some(w),
                }
            }
            match vec {
                Some(w) => Value::Vector([k * w[0], k * w[1], k * w[2]]),
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
            Value::Scalar(a[0].hypot(a[1]).hypot(a[2]))
        }
        Node::Comp(a, axis) => Value::Scalar(v(a)[axis.index()]),
        Node::Call(f, a) => Value::Scalar(apply(*f, s(a))),
        Node::Atan2([y, x]) => Value::Scalar(s(y).atan2(s(x))),
    })
}

/// `b^e`, with integer exponents done by `powi` so that negative bases work.
pub fn pow(b: f64, e: f64) -> f64 {
    if e == e.trunc() && e.abs() <= i32::MAX as f64 { b.powi(e as i32) } else { b.powf(e) }
}

/// A scalar function's value.
pub fn apply(f: Func, x: f64) -> f64 {
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
