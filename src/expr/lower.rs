//! Name resolution and type checking: a [`Syntax`] tree becomes graph nodes.
//!
//! Each name is looked up in a [`Scope`] (symbols, definitions, `t`), each function is
//! checked for its arity and argument types, and every node gets a type, scalar or vector,
//! before anything is derived. Errors carry the span of the offending piece of text.
//!
//! Two folds make printing and parsing inverse to each other: a negated number literal is a
//! negative number, and a leading `p/q` of number literals is the rational `p/q` (so the
//! printed `-1/2*x` parses back to the same node). Nothing else is evaluated here.

use super::func::Func;
use super::graph::{Graph, Id, NameMap, Node, Role, Ty, TypeError};
use super::num::Rational;
use super::parse::{STACK_GROWTH, STACK_RED_ZONE};
use super::syntax::{MulOp, RelOp, Relation, Sign, Span, Syntax, SyntaxKind};
use std::collections::hash_map::Entry;

/// The names an expression may use, each bound to a graph node (a symbol or a definition).
/// Keyed by the file's names, so hashed as [`NameMap`] says.
#[derive(Clone, Debug, Default)]
pub struct Scope {
    names: NameMap<String, Id>,
}

impl Scope {
    pub fn new() -> Scope {
        Scope::default()
    }

    pub fn insert(&mut self, name: impl Into<String>, id: Id) {
        self.names.insert(name.into(), id);
    }

    /// Room for `additional` more names.
    pub fn reserve(&mut self, additional: usize) {
        self.names.reserve(additional);
    }

    /// Binds `name` to the node `bind` gives, unless it is bound already (then `bind` is
    /// not called): what else `bind` made, or `None` when the name was taken.
    pub fn insert_new<T>(&mut self, name: &str, bind: impl FnOnce() -> (Id, T)) -> Option<T> {
        match self.names.entry(name.to_string()) {
            Entry::Vacant(slot) => {
                let (id, made) = bind();
                slot.insert(id);
                Some(made)
            }
            Entry::Occupied(_) => None,
        }
    }

    pub fn get(&self, name: &str) -> Option<Id> {
        self.names.get(name).copied()
    }

    pub fn contains(&self, name: &str) -> bool {
        self.names.contains_key(name)
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.names.keys().map(String::as_str)
    }
}

/// What went wrong while resolving or type checking, and where.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{kind}")]
pub struct LowerError {
    pub span: Span,
    pub kind: LowerErrorKind,
}

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LowerErrorKind {
    #[error("unknown symbol `{name}`{}", hint(suggestion))]
    UnknownSymbol { name: String, suggestion: Option<String> },
    #[error("unknown function `{name}`{}", hint(suggestion))]
    UnknownFunction { name: String, suggestion: Option<String> },
    #[error("`{name}` is not a function")]
    NotAFunction { name: String },
    #[error("`{name}` is a function: call it as `{name}(…)`")]
    FunctionAsValue { name: String },
    #[error("`{name}` takes {expected} argument{}, found {found}", if *expected == 1 { "" } else { "s" })]
    Arity { name: String, expected: usize, found: usize },
    #[error("`{function}` needs {expected} here, found {}", found)]
    Argument { function: String, expected: Ty, found: Ty },
    #[error("`^` needs a scalar base, found a vector: write |r|² as `dot(r, r)` and |r| as `norm(r)`")]
    VectorPower,
    /// `pi` used without being declared: the language's numbers are exact, π is not.
    #[error(
        "`pi` is not built in (numbers in formulas are exact): give it a value in [parameters], e.g. `pi = 3.141592653589793`"
    )]
    Pi,
    #[error("number `{text}` is out of range")]
    NumberRange { text: String },
    #[error("a constraint must be a scalar, found a vector: compare components, e.g. `r.x = 0`")]
    VectorConstraint,
    #[error(
        "only `=` relates vectors (one equality per component); for an inequality compare components, e.g. `r.y >= 0`"
    )]
    VectorInequality,
    #[error("`rot` turns a vector by a rigid body's orientation: `{name}` is not an orientation")]
    NotAnOrientation { name: String },
    #[error(
        "the vector `rot` turns must be constant in time (numbers and parameters, in the body's frame): it uses `{name}`"
    )]
    TimeVaryingBodyVector { name: String },
    /// A 3D orientation (a quaternion) outside `rot`: its time derivative is not written
    /// symbolically (d rot(q, s)/dt = ω × rot(q, s) needs none), so nothing else may read it.
    #[error(
        "`{name}` is a 3D orientation (a unit quaternion): it can only turn a vector, as in `rot({name}, s)`; compare points or axes of the body instead"
    )]
    BareQuaternion { name: String },
    #[error("{0}")]
    Type(#[from] TypeError),
}

fn hint(suggestion: &Option<String>) -> String {
    suggestion.as_ref().map(|s| format!(" (did you mean `{s}`?)")).unwrap_or_default()
}

/// The functions of the language that are node kinds of their own (vectors in), with
/// their arity; every other function is in the table of [`Func`].
const VECTOR_FUNCTIONS: [(&str, usize); 5] = [("dot", 2), ("cross", 2), ("norm", 1), ("rot", 2), ("perp", 1)];

/// Whether `name` is a function of the expression language (and so cannot name a symbol).
pub fn is_function_name(name: &str) -> bool {
    Func::from_name(name).is_some() || VECTOR_FUNCTIONS.iter().any(|(f, _)| *f == name)
}

fn function_names() -> impl Iterator<Item = &'static str> {
    Func::ALL.into_iter().map(Func::name).chain(VECTOR_FUNCTIONS.iter().map(|(f, _)| *f))
}

/// The closest candidate within a small edit distance, for "did you mean".
///
/// Among equally close candidates, one differing only in case wins (`L` → `l`, not `F`).
///
/// A name of one or two letters is one edit from every other short name, so there only a
/// different case (`L` for `l`) is offered.
pub fn suggest<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> Option<String> {
    let short = name.chars().count() < 3;
    let limit = (name.chars().count() / 3).max(1);
    candidates
        .map(|c| (edit_distance(name, c), !c.eq_ignore_ascii_case(name), c))
        .filter(|&(d, other, c)| d <= limit && c != name && !(short && other))
        .min()
        .map(|(_, _, c)| c.to_string())
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// Lowers an expression.
pub fn lower(syntax: &Syntax, scope: &Scope, graph: &mut Graph) -> Result<Id, LowerError> {
    Lower { scope, graph }.expr(syntax)
}

/// A constraint: its function `C` (meaning `C = 0` or `C ≥ 0`) and whether it is an inequality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoweredRelation {
    pub c: Id,
    pub inequality: bool,
}

/// Lowers `lhs = rhs` to `C = lhs − rhs`, `lhs >= rhs` to `C = lhs − rhs ≥ 0`, and
/// `lhs <= rhs` to `C = rhs − lhs ≥ 0`; a bare expression is `C` itself. Between vectors
/// only `=` is allowed, and `C` is then a vector: one equality per component (the caller
/// splits it).
pub fn lower_relation(rel: &Relation, scope: &Scope, graph: &mut Graph) -> Result<LoweredRelation, LowerError> {
    let mut l = Lower { scope, graph };
    let lhs = l.expr(&rel.lhs)?;
    let Some((op, op_span, rhs_syntax)) = &rel.rel else {
        if l.graph.ty(lhs) == Ty::Vector {
            return Err(LowerError { span: rel.lhs.span, kind: LowerErrorKind::VectorConstraint });
        }
        return Ok(LoweredRelation { c: lhs, inequality: false });
    };
    let rhs = l.expr(rhs_syntax)?;
    let (lt, rt) = (l.graph.ty(lhs), l.graph.ty(rhs));
    if lt != rt {
        return Err(LowerError { span: *op_span, kind: TypeError::MixedRelation.into() });
    }
    if lt == Ty::Vector && *op != RelOp::Eq {
        return Err(LowerError { span: rel.lhs.span.to(rhs_syntax.span), kind: LowerErrorKind::VectorInequality });
    }
    let span = rel.lhs.span.to(rhs_syntax.span);
    let (a, b) = if *op == RelOp::Le { (rhs, lhs) } else { (lhs, rhs) };
    // `C = 0` written as `expr = 0` is just `expr`.
    let c = if l.graph.is_zero(b) { a } else { l.graph.sub(a, b).map_err(|e| LowerError { span, kind: e.into() })? };
    Ok(LoweredRelation { c, inequality: *op != RelOp::Eq })
}

struct Lower<'a> {
    scope: &'a Scope,
    graph: &'a mut Graph,
}

impl Lower<'_> {
    fn expr(&mut self, s: &Syntax) -> Result<Id, LowerError> {
        stacker::maybe_grow(STACK_RED_ZONE, STACK_GROWTH, || self.expr_inner(s))
    }

    fn expr_inner(&mut self, s: &Syntax) -> Result<Id, LowerError> {
        let at = |kind: TypeError| LowerError { span: s.span, kind: kind.into() };
        match &s.kind {
            SyntaxKind::Number(text) => self.number(text, s.span).map(|q| self.graph.num(q)),
            SyntaxKind::Ident(name) => self.ident(name, s.span),
            SyntaxKind::Paren(inner) => self.expr(inner),
            SyntaxKind::Neg(inner) => {
                if let SyntaxKind::Number(text) = &inner.kind {
                    let q = self.number(text, inner.span)?;
                    return Ok(self.graph.num(q.neg()));
                }
                let x = self.expr(inner)?;
                Ok(self.graph.neg(x))
            }
            SyntaxKind::Sum(terms) => {
                // Exact room: this list becomes a node's `Box<[Id]>`, and a vector with spare room
                // is copied to shrink it (callgrind: 3 % of the bead's derivation without these).
                let mut ids = Vec::with_capacity(terms.len());
                let mut ty = None;
                for (sign, term) in terms {
                    let id = self.term(term, *sign == Sign::Minus)?;
                    let t = self.graph.ty(id);
                    if *ty.get_or_insert(t) != t {
                        return Err(LowerError { span: term.span, kind: TypeError::MixedSum.into() });
                    }
                    ids.push(id);
                }
                self.graph.add(ids).map_err(at)
            }
            SyntaxKind::Product(factors) => self.product(factors, false),
            SyntaxKind::Pow(base, exponent) => {
                let b = self.expr(base)?;
                if self.graph.ty(b) == Ty::Vector {
                    return Err(LowerError { span: base.span, kind: LowerErrorKind::VectorPower });
                }
                let e = self.scalar(exponent, "^")?;
                self.graph.pow(b, e).map_err(at)
            }
            SyntaxKind::Component(inner, axis, axis_span) => {
                let x = self.expr(inner)?;
                if self.graph.ty(x) != Ty::Vector {
                    let kind = LowerErrorKind::Argument {
                        function: format!(".{}", axis.name()),
                        expected: Ty::Vector,
                        found: Ty::Scalar,
                    };
                    return Err(LowerError { span: inner.span, kind });
                }
                self.graph.comp(x, *axis).map_err(|e| LowerError { span: *axis_span, kind: e.into() })
            }
            SyntaxKind::Vector(items) => {
                // Exact room: this list becomes a node's `Box<[Id]>`, and a vector with spare room
                // is copied to shrink it (callgrind: 3 % of the bead's derivation without these).
                let mut ids = Vec::with_capacity(items.len());
                for item in items {
                    ids.push(self.scalar(item, "[…]")?);
                }
                self.graph.vector(ids).map_err(at)
            }
            SyntaxKind::Call { name, name_span, args } => self.call(name, *name_span, args, s.span),
        }
    }

    fn number(&self, text: &str, span: Span) -> Result<Rational, LowerError> {
        Rational::parse_decimal(text)
            .ok_or_else(|| LowerError { span, kind: LowerErrorKind::NumberRange { text: text.to_string() } })
    }

    fn ident(&mut self, name: &str, span: Span) -> Result<Id, LowerError> {
        if let Some(id) = self.scope.get(name) {
            if let Node::Sym(sym) = self.graph.node(id)
                && self.graph.is_quaternion(*sym)
            {
                return Err(LowerError { span, kind: LowerErrorKind::BareQuaternion { name: name.to_string() } });
            }
            return Ok(id);
        }
        if is_function_name(name) {
            return Err(LowerError { span, kind: LowerErrorKind::FunctionAsValue { name: name.to_string() } });
        }
        if name == "pi" {
            return Err(LowerError { span, kind: LowerErrorKind::Pi });
        }
        let suggestion = suggest(name, self.scope.names());
        Err(LowerError { span, kind: LowerErrorKind::UnknownSymbol { name: name.to_string(), suggestion } })
    }

    /// A term of a sum, negated when it followed a `-`.
    fn term(&mut self, term: &Syntax, negate: bool) -> Result<Id, LowerError> {
        match &term.kind {
            _ if !negate => self.expr(term),
            SyntaxKind::Number(text) => Ok(self.graph.num(self.number(text, term.span)?.neg())),
            SyntaxKind::Product(factors) => self.product(factors, true),
            _ => {
                let x = self.expr(term)?;
                Ok(self.graph.neg(x))
            }
        }
    }

    /// The number a literal (or negated literal) stands for, if it is one.
    fn literal(&self, s: &Syntax) -> Result<Option<Rational>, LowerError> {
        match &s.kind {
            SyntaxKind::Number(text) => self.number(text, s.span).map(Some),
            SyntaxKind::Neg(inner) => match &inner.kind {
                SyntaxKind::Number(text) => self.number(text, inner.span).map(|q| Some(q.neg())),
                _ => Ok(None),
            },
            _ => Ok(None),
        }
    }

    /// A product; with `negate` (after a `-` in a sum) its first factor is negated, which is
    /// how the printer writes `a - m*x`.
    fn product(&mut self, factors: &[(MulOp, Syntax)], negate: bool) -> Result<Id, LowerError> {
        // Exact room: this list becomes a node's `Box<[Id]>`, and a vector with spare room
        // is copied to shrink it (callgrind: 3 % of the bead's derivation without these).
        let mut ids = Vec::with_capacity(factors.len());
        let mut rest = factors;
        let mut negate_first = negate;
        // A leading `p` or `p/q` of literals is one rational number.
        if let Some(p) = self.literal(&factors[0].1)? {
            let mut q = p;
            rest = &factors[1..];
            if let Some(((MulOp::Over, d), tail)) = rest.split_first().map(|(h, t)| (h.clone(), t))
                && let Some(d) = self.literal(&d)?
                && !d.is_zero()
            {
                q = q.div(&d).unwrap_or(q);
                rest = tail;
            }
            ids.push(self.graph.num(if negate { q.neg() } else { q }));
            negate_first = false;
        }
        let mut vector: Option<Span> = None;
        for (op, f) in rest {
            let mut id = self.expr(f)?;
            if std::mem::take(&mut negate_first) {
                id = self.graph.neg(id);
            }
            if self.graph.ty(id) == Ty::Vector {
                if *op == MulOp::Over {
                    return Err(LowerError { span: f.span, kind: TypeError::DivideByVector.into() });
                }
                if vector.is_some() {
                    return Err(LowerError { span: f.span, kind: TypeError::VectorProduct.into() });
                }
                vector = Some(f.span);
            }
            if *op == MulOp::Over {
                let minus_one = self.graph.int(-1);
                id = self.graph.pow(id, minus_one).map_err(|e| LowerError { span: f.span, kind: e.into() })?;
            }
            ids.push(id);
        }
        let span = factors[0].1.span.to(factors[factors.len() - 1].1.span);
        self.graph.mul(ids).map_err(|e| LowerError { span, kind: e.into() })
    }

    fn scalar(&mut self, s: &Syntax, function: &str) -> Result<Id, LowerError> {
        let id = self.expr(s)?;
        self.expect(id, Ty::Scalar, s.span, function)
    }

    fn vector(&mut self, s: &Syntax, function: &str) -> Result<Id, LowerError> {
        let id = self.expr(s)?;
        self.expect(id, Ty::Vector, s.span, function)
    }

    fn expect(&self, id: Id, ty: Ty, span: Span, function: &str) -> Result<Id, LowerError> {
        let found = self.graph.ty(id);
        if found == ty {
            return Ok(id);
        }
        Err(LowerError { span, kind: LowerErrorKind::Argument { function: function.to_string(), expected: ty, found } })
    }

    /// The first argument of `rot`: a rigid body's orientation symbol.
    fn orientation(&mut self, s: &Syntax) -> Result<Id, LowerError> {
        // A name is looked up here, not by `ident`, which refuses a 3D orientation elsewhere.
        let id = match &s.kind {
            SyntaxKind::Ident(name) if let Some(id) = self.scope.get(name) => id,
            _ => self.expr(s)?,
        };
        if let Node::Sym(sym) = self.graph.node(id)
            && matches!(self.graph.symbol(*sym).role, Role::Orientation { .. })
        {
            return Ok(id);
        }
        let name = match &s.kind {
            SyntaxKind::Ident(name) => name.to_string(),
            _ => super::print::print(self.graph, id, super::print::Style::Source).unwrap_or_default(),
        };
        Err(LowerError { span: s.span, kind: LowerErrorKind::NotAnOrientation { name } })
    }

    /// Refuses a vector that changes in time (it uses `t` or a body's state) where a
    /// body-frame vector belongs.
    fn constant_in_time(&self, v: Id, span: Span) -> Result<(), LowerError> {
        for s in self.graph.free_symbols(v) {
            let info = self.graph.symbol(s);
            if !matches!(info.role, Role::Parameter | Role::Mass { .. } | Role::Inertia { .. }) {
                return Err(LowerError {
                    span,
                    kind: LowerErrorKind::TimeVaryingBodyVector { name: info.name.clone() },
                });
            }
        }
        Ok(())
    }

    fn call(&mut self, name: &str, name_span: Span, args: &[Syntax], span: Span) -> Result<Id, LowerError> {
        let arity = Func::from_name(name)
            .map(Func::arity)
            .or_else(|| VECTOR_FUNCTIONS.iter().find(|(f, _)| *f == name).map(|(_, n)| *n));
        let Some(arity) = arity else {
            let kind = if self.scope.contains(name) {
                LowerErrorKind::NotAFunction { name: name.to_string() }
            } else {
                LowerErrorKind::UnknownFunction { name: name.to_string(), suggestion: suggest(name, function_names()) }
            };
            return Err(LowerError { span: name_span, kind });
        };
        if args.len() != arity {
            let kind = LowerErrorKind::Arity { name: name.to_string(), expected: arity, found: args.len() };
            return Err(LowerError { span, kind });
        }
        let at = |e: TypeError| LowerError { span, kind: e.into() };
        match name {
            "dot" => {
                let a = self.vector(&args[0], name)?;
                let b = self.vector(&args[1], name)?;
                self.graph.dot(a, b).map_err(at)
            }
            "cross" => {
                let a = self.vector(&args[0], name)?;
                let b = self.vector(&args[1], name)?;
                self.graph.cross(a, b).map_err(at)
            }
            "norm" => {
                let a = self.vector(&args[0], name)?;
                self.graph.norm(a).map_err(at)
            }
            "rot" => {
                let theta = self.orientation(&args[0])?;
                let v = self.vector(&args[1], name)?;
                self.constant_in_time(v, args[1].span)?;
                self.graph.rot(theta, v).map_err(at)
            }
            "perp" => {
                let a = self.vector(&args[0], name)?;
                self.graph.perp(a).map_err(at)
            }
            _ => {
                let f = Func::from_name(name).ok_or_else(|| at(TypeError::ExpectedScalar))?;
                let mut lowered = Vec::new();
                for (arg, &ty) in args.iter().zip(f.signature().0) {
                    let id = self.expr(arg)?;
                    lowered.push(self.expect(id, ty, arg.span, name)?);
                }
                self.graph.call(f, &lowered).map_err(at)
            }
        }
    }
}
