//! The function table: every function of the expression language that is a call
//! `name(args)` (`sqrt`, `sin`, …, `atan2`), declared once.
//!
//! For each function this file says its name, its arity and argument types (the type
//! rule), its value for any scalar type ([`Func::apply`], the one semantics that the
//! interpreter, the double-double reference, the tape and constant folding all use), its
//! partial derivatives ([`Func::partial`], used by d/dt and ∇ alike), its exact values
//! at rational arguments (the simplifier's `sin(0) = 0`), its inverse (`ln(exp x) = x`)
//! and how people read it ([`Notation`]). Adding a function means adding a variant of
//! [`Func`] and its row in each table here; the parser, type checker, printers,
//! simplifier, derivatives, interpreters, the program lowering, the tape and the
//! generated Rust pick it up from these tables.
//!
//! Design note: the rows are `match`es on [`Func`] rather than a slice of structs with
//! function pointers, because [`Func::apply`] is generic over the scalar type (f64 and
//! double-double) and the compiler checks every `match` for a missing function.
//!
//! Not here: `dot`, `cross`, `norm` and components, which are node kinds of their own
//! (vectors in, structure the simplifier works with); rules that only make sense for one
//! function (`sqrt`'s radicals in `simplify`, its machine instruction in the tape).

use super::eval::Scalar;
use super::graph::{Graph, Id, Ty, TypeError};
use super::num::Rational;

/// The most arguments a function takes: calls store this many slots.
pub const MAX_ARITY: usize = 2;

/// A function of the expression language. The order is the canonical order of calls.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub enum Func {
    Sqrt,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Exp,
    Ln,
    /// `atan2(y, x)`: the angle of the point (x, y).
    Atan2,
}

/// How people read a function (`Style::Text` and `Style::Latex`; `Style::Source` writes
/// `name(args)` for every function).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Notation {
    /// `name(a, b)` in text, `latex\left(a, b\right)` in LaTeX.
    Call { latex: &'static str },
    /// `√a` in text, `\sqrt{a}` in LaTeX.
    Radical,
}

impl Func {
    pub const ALL: [Func; 10] = [
        Func::Sqrt,
        Func::Sin,
        Func::Cos,
        Func::Tan,
        Func::Asin,
        Func::Acos,
        Func::Atan,
        Func::Exp,
        Func::Ln,
        Func::Atan2,
    ];

    /// The name in the expression language, which is also `f64`'s method of that name
    /// (what the generated Rust calls).
    pub fn name(self) -> &'static str {
        match self {
            Func::Sqrt => "sqrt",
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Asin => "asin",
            Func::Acos => "acos",
            Func::Atan => "atan",
            Func::Exp => "exp",
            Func::Ln => "ln",
            Func::Atan2 => "atan2",
        }
    }

    pub fn from_name(name: &str) -> Option<Func> {
        Func::ALL.into_iter().find(|f| f.name() == name)
    }

    /// The type rule: the arguments' types (their number is the arity) and the result's.
    pub fn signature(self) -> (&'static [Ty], Ty) {
        const UNARY: &[Ty] = &[Ty::Scalar];
        const BINARY: &[Ty] = &[Ty::Scalar, Ty::Scalar];
        match self {
            Func::Atan2 => (BINARY, Ty::Scalar),
            _ => (UNARY, Ty::Scalar),
        }
    }

    /// The number of arguments.
    #[inline]
    pub fn arity(self) -> usize {
        self.signature().0.len()
    }

    pub fn notation(self) -> Notation {
        match self {
            Func::Sqrt => Notation::Radical,
            Func::Sin => Notation::Call { latex: "\\sin" },
            Func::Cos => Notation::Call { latex: "\\cos" },
            Func::Tan => Notation::Call { latex: "\\tan" },
            Func::Asin => Notation::Call { latex: "\\operatorname{asin}" },
            Func::Acos => Notation::Call { latex: "\\operatorname{acos}" },
            Func::Atan => Notation::Call { latex: "\\operatorname{atan}" },
            Func::Exp => Notation::Call { latex: "\\exp" },
            Func::Ln => Notation::Call { latex: "\\ln" },
            Func::Atan2 => Notation::Call { latex: "\\operatorname{atan2}" },
        }
    }

    /// The value at `args` (the first [`Func::arity`] entries are read), in any scalar type.
    #[inline]
    pub fn apply<S: Scalar>(self, args: &[S]) -> S {
        let x = args[0];
        match self {
            Func::Sqrt => x.sqrt(),
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Asin => x.asin(),
            Func::Acos => x.acos(),
            Func::Atan => x.atan(),
            Func::Exp => x.exp(),
            Func::Ln => x.ln(),
            Func::Atan2 => x.atan2(args[1]),
        }
    }

    /// ∂f/∂`args[i]` as a graph, where `fu` is the node `f(args)` itself (reused where the
    /// derivative is the function, as for exp). d/dt multiplies it by the argument's
    /// derivative, ∇ by the adjoint.
    pub fn partial(self, g: &mut Graph, i: usize, args: &[Id], fu: Id) -> Result<Id, TypeError> {
        let u = args[0];
        let one = g.int(1);
        Ok(match self {
            // 1 / (2 sqrt u)
            Func::Sqrt => {
                let half = g.num(Rational::new(1, 2));
                let inv = g.powi(fu, -1)?;
                g.mul(vec![half, inv])?
            }
            Func::Sin => g.call(Func::Cos, &[u])?,
            Func::Cos => {
                let s = g.call(Func::Sin, &[u])?;
                g.neg(s)
            }
            // 1 + tan² u
            Func::Tan => {
                let t2 = g.powi(fu, 2)?;
                g.add(vec![one, t2])?
            }
            // ±1 / sqrt(1 − u²)
            Func::Asin | Func::Acos => {
                let u2 = g.powi(u, 2)?;
                let diff = g.sub(one, u2)?;
                let root = g.call(Func::Sqrt, &[diff])?;
                let inv = g.powi(root, -1)?;
                if self == Func::Acos { g.neg(inv) } else { inv }
            }
            // 1 / (1 + u²)
            Func::Atan => {
                let u2 = g.powi(u, 2)?;
                let den = g.add(vec![one, u2])?;
                g.powi(den, -1)?
            }
            Func::Exp => fu,
            Func::Ln => g.powi(u, -1)?,
            // ∂/∂y = x/(x² + y²), ∂/∂x = −y/(x² + y²)
            Func::Atan2 => {
                let (y, x) = (args[0], args[1]);
                let x2 = g.powi(x, 2)?;
                let y2 = g.powi(y, 2)?;
                let den = g.add(vec![x2, y2])?;
                let inv = g.powi(den, -1)?;
                let top = if i == 0 { x } else { g.neg(y) };
                g.mul(vec![top, inv])?
            }
        })
    }

    /// The value at rational arguments when it is rational (`sin(0) = 0`, `ln(1) = 0`, …);
    /// `None` otherwise. Only exact values: nothing is rounded into the canonical form.
    pub fn exact(self, args: &[Rational]) -> Option<Rational> {
        let q = &args[0];
        match self {
            Func::Sin | Func::Tan | Func::Asin | Func::Atan if q.is_zero() => Some(Rational::ZERO),
            Func::Cos | Func::Exp if q.is_zero() => Some(Rational::ONE),
            Func::Ln | Func::Acos if q.is_one() => Some(Rational::ZERO),
            _ => None,
        }
    }

    /// The function `g` with `self(g(x)) = x` for every x, when there is one.
    pub fn inverse(self) -> Option<Func> {
        match self {
            Func::Ln => Some(Func::Exp),
            Func::Exp => Some(Func::Ln),
            _ => None,
        }
    }

    /// The argument slots of a call: the arguments, then the first argument again (or
    /// `fill` when there is none) up to [`MAX_ARITY`], so equal calls are equal arrays.
    pub fn slots<T: Copy>(self, args: &[T], fill: T) -> [T; MAX_ARITY] {
        debug_assert_eq!(args.len(), self.arity());
        let first = args.first().copied().unwrap_or(fill);
        std::array::from_fn(|k| args.get(k).copied().unwrap_or(first))
    }
}
