//! The `[[expect]]` entries of a constraint file: their validation (the raw entries are
//! `model::raw::RawExpect`).
//!
//! One entry is one check. Without `at` it holds formulas, in the file's symbols, that the
//! derived ones must equal (`lagrange check` judges equality on the constraint manifold):
//!
//! ```toml
//! [[expect]]
//! force  = { bead = "-(m*dot(v,v) + dot(F,r))/l^2 * r" }   # by body
//! torque = { rod = "cross(rot(th, s), ...)" }               # by rigid body (2D a scalar, 3D a vector)
//! lambda = { wire = "-(m*dot(v,v) + dot(F,r))/(2*l^2)" }   # by constraint
//! C_dot  = { wire = "2*dot(r,v)" }                          # by constraint
//! C_ddot = { wire = "2*dot(v,v) + 2*dot(r,a)" }             # by constraint
//! A      = { "wire,wire" = "4*dot(r,r)/m" }                 # by "constraint,constraint"
//! b      = { wire = "2*dot(r,F)/m + 2*dot(v,v)" }          # by constraint
//! ```
//!
//! With `at = { symbol = value, … }` it holds numbers at that state (`force` by body as a
//! vector, `lambda` by constraint as a number; a formula there is evaluated at the state),
//! compared within the relative `tolerance` (default [`DEFAULT_TOLERANCE`]).
//!
//! Every quantity refers to C as written (DESIGN.md): `lhs = rhs` and `lhs >= rhs` mean
//! C = lhs − rhs, `lhs <= rhs` means C = rhs − lhs; the force on body i is Σₖ λₖ ∇ᵢCₖ, and
//! Aₖⱼ = Σᵢ ∇ᵢCₖ·∇ᵢCⱼ/mᵢ, bₖ = Σᵢ ∇ᵢCₖ·Fᵢ/mᵢ + C̈ₖ|ₐ₌₀. (The derivation's own λ, A, b refer
//! to C/κ; `check` converts.)
//!
//! Not here: judging the entries (`check`).

use super::problem::{Problem, locate, shown};
use super::raw::{AT_STATE, Entries, RawExpect, RawExpected, Text};
use super::state::value;
use super::system::{BuildError, System};
use crate::expr::eval::Value;
use crate::expr::graph::SymbolWalk;
use crate::expr::lower::suggest;
use crate::expr::{Id, Role, Symbol, Ty};
use std::ops::Range;
use toml::Spanned;

/// The relative tolerance of numeric (`at`) checks unless the entry gives one.
pub const DEFAULT_TOLERANCE: f64 = 1e-9;

/// What an item checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// The constraint force on a body.
    Force(usize),
    /// The constraint torque on a rigid body (2D: a scalar; 3D: a vector, world frame).
    Torque(usize),
    /// λ of a constraint, for C as written.
    Lambda(usize),
    CDot(usize),
    CDdot(usize),
    /// Aₖⱼ for C as written.
    A(usize, usize),
    /// bₖ for C as written.
    B(usize),
}

impl Quantity {
    /// The type of the quantity in a file of dimension `dim`: forces are vectors, torques
    /// vectors in 3D (world frame) and scalars in 2D, everything else scalars.
    pub fn ty(self, dim: usize) -> Ty {
        match self {
            Quantity::Force(_) => Ty::Vector,
            Quantity::Torque(_) if dim == 3 => Ty::Vector,
            _ => Ty::Scalar,
        }
    }
}

/// The expected side of an item.
#[derive(Clone, Debug)]
pub enum Expected {
    Formula { id: Id, text: String },
    Numbers(Vec<f64>),
}

/// One checked quantity.
#[derive(Clone, Debug)]
pub struct Item {
    pub quantity: Quantity,
    pub expected: Expected,
    /// Where the item is written (its key).
    pub span: Range<usize>,
}

/// A validated `[[expect]]` entry.
#[derive(Clone, Debug)]
pub struct Expectation {
    pub span: Range<usize>,
    /// The state of a numeric check: values by symbol, in name order.
    pub at: Option<Vec<(Symbol, Value)>>,
    pub tolerance: f64,
    pub items: Vec<Item>,
    pub note: Option<String>,
}

/// Validates every entry against `system`; each problem goes to `problems`, located.
///
/// `written` names every body and constraint the file writes, including those refused: an
/// item naming one of those is dropped quietly (the refusal is the message).
pub fn resolve(
    text: &str,
    raw: &[Spanned<RawExpect<'_>>],
    written: &[&str],
    system: &mut System,
    problems: &mut Vec<Problem>,
) -> Vec<Expectation> {
    let mut out = Vec::new();
    let mut walk = SymbolWalk::default();
    for entry in raw {
        let e = entry.get_ref();
        let mut at = None;
        if let Some(state) = &e.at {
            let mut values = Vec::new();
            for (name, v) in state.get_ref() {
                match value(system, name.get_ref(), v.get_ref()) {
                    Ok(given) => values.push(given),
                    Err(error) => problems.push(Problem::Value { span: name.span(), error }),
                }
            }
            at = Some(values);
        }
        if let (Some(t), None) = (&e.tolerance, &e.at) {
            problems.push(Problem::ToleranceWithoutAt { span: t.span() });
        }
        let tolerance = match &e.tolerance {
            None => DEFAULT_TOLERANCE,
            Some(t) if t.get_ref().is_finite() && *t.get_ref() > 0.0 => *t.get_ref(),
            Some(t) => {
                problems.push(Problem::Tolerance { span: t.span(), shown: shown(*t.get_ref()) });
                DEFAULT_TOLERANCE
            }
        };
        let nothing = e.written == 0;
        let mut r = Resolver { text, system, problems, written, numeric: at.is_some(), items: Vec::new(), walk };
        r.table(&e.force, "force", Target::Body);
        r.table(&e.torque, "torque", Target::RigidBody);
        r.table(&e.lambda, "lambda", Target::Constraint);
        r.table(&e.c_dot, "C_dot", Target::Constraint);
        r.table(&e.c_ddot, "C_ddot", Target::Constraint);
        r.table(&e.a, "A", Target::Pair);
        r.table(&e.b, "b", Target::Constraint);
        let items = r.items;
        walk = r.walk;
        if nothing {
            problems.push(Problem::ChecksNothing { span: entry.span() });
        }
        out.push(Expectation { span: entry.span(), at, tolerance, items, note: e.note.clone() });
    }
    out
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Target {
    Body,
    RigidBody,
    Constraint,
    Pair,
}

struct Resolver<'a> {
    text: &'a str,
    system: &'a mut System,
    problems: &'a mut Vec<Problem>,
    written: &'a [&'a str],
    numeric: bool,
    items: Vec<Item>,
    /// For the symbols of expected formulas, kept from one formula to the next.
    walk: SymbolWalk,
}

impl Resolver<'_> {
    fn problem(&mut self, problem: Problem) {
        self.problems.push(problem);
    }

    fn table(&mut self, entries: &Entries<'_>, what: &str, target: Target) {
        for (key, value) in entries {
            let Some(quantity) = self.quantity(key, what, target) else {
                continue;
            };
            if self.numeric && !AT_STATE.contains(&what) {
                self.problem(Problem::NotAtState { span: key.span(), what: what.to_string() });
                continue;
            }
            if let Some(expected) = self.expected(quantity, what, value) {
                self.items.push(Item { quantity, expected, span: key.span() });
            }
        }
    }

    /// The quantity a key names, or a located problem.
    fn quantity(&mut self, key: &Text<'_>, what: &str, target: Target) -> Option<Quantity> {
        let name = key.get_ref().as_ref();
        match target {
            Target::Body => self.body(name, key.span()).map(Quantity::Force),
            Target::RigidBody => self.rigid_body(name, key.span()).map(Quantity::Torque),
            Target::Constraint => {
                let k = self.constraint(name, key.span())?;
                Some(match what {
                    "lambda" => Quantity::Lambda(k),
                    "C_dot" => Quantity::CDot(k),
                    "C_ddot" => Quantity::CDdot(k),
                    _ => Quantity::B(k),
                })
            }
            Target::Pair => {
                let parts: Vec<&str> = name.split(',').map(str::trim).collect();
                let [k, j] = parts.as_slice() else {
                    self.problem(Problem::PairKey { span: key.span(), key: name.to_string() });
                    return None;
                };
                let k = self.constraint(k, key.span());
                let j = self.constraint(j, key.span());
                Some(Quantity::A(k?, j?))
            }
        }
    }

    fn body(&mut self, name: &str, span: Range<usize>) -> Option<usize> {
        let found = self.system.body_named(name);
        if found.is_none() && !self.written.contains(&name) {
            let names: Vec<&str> = self.system.bodies.iter().map(|b| b.name.as_str()).collect();
            self.problem(unknown(span, "body", name, &names));
        }
        found
    }

    /// A body with an orientation: a torque on a point mass is no quantity.
    fn rigid_body(&mut self, name: &str, span: Range<usize>) -> Option<usize> {
        let body = self.system.body_named(name);
        let found = body.filter(|&i| self.system.bodies[i].rigid.is_some());
        if found.is_none() && (body.is_some() || !self.written.contains(&name)) {
            let names: Vec<&str> =
                self.system.bodies.iter().filter(|b| b.rigid.is_some()).map(|b| b.name.as_str()).collect();
            self.problem(unknown(span, "rigid body", name, &names));
        }
        found
    }

    fn constraint(&mut self, name: &str, span: Range<usize>) -> Option<usize> {
        let found = self.system.constraint_named(name);
        // A vector constraint is its rows `NAME.x`, `NAME.y`(, `NAME.z`): its own name checks
        // nothing, so it is an error naming the rows, not an item left out in silence.
        let rows: Vec<String> = match found {
            Some(_) => Vec::new(),
            None => crate::expr::Axis::ALL[..self.system.dim()]
                .iter()
                .map(|axis| format!("{name}.{}", axis.name()))
                .filter(|row| self.system.constraint_named(row).is_some())
                .collect(),
        };
        if !rows.is_empty() {
            self.problem(Problem::VectorConstraint { span, name: name.to_string(), rows });
            return None;
        }
        if found.is_none() && !self.written.contains(&name) {
            let names: Vec<&str> = self.system.constraints.iter().map(|c| c.name.as_str()).collect();
            self.problem(unknown(span, "constraint", name, &names));
        }
        found
    }

    fn expected(&mut self, quantity: Quantity, what: &str, value: &Spanned<RawExpected<'_>>) -> Option<Expected> {
        let dim = self.system.dim();
        let want = quantity.ty(dim);
        match value.get_ref() {
            RawExpected::Formula(text) => {
                let id = match self.system.expression(text) {
                    Ok(id) => id,
                    Err(e) => {
                        let inner = match &e {
                            BuildError::Parse { error, .. } => Some(error.span.start..error.span.end),
                            BuildError::Lower { error, .. } => Some(error.span.start..error.span.end),
                            _ => None,
                        };
                        let written = Spanned::new(value.span(), text.as_ref());
                        let span = inner.map_or(value.span(), |s| locate(self.text, &written, s));
                        self.problem(Problem::ExpectedFormula { span, what: what.to_string(), error: e });
                        return None;
                    }
                };
                if self.system.graph.ty(id) != want {
                    let (w, f) = if want == Ty::Vector { ("a vector", "a scalar") } else { ("a scalar", "a vector") };
                    let (span, what) = (value.span(), what.to_string());
                    self.problem(Problem::ExpectedType { span, what, want: w, found: f });
                    return None;
                }
                if !matches!(quantity, Quantity::CDdot(_)) {
                    for &s in self.walk.free_symbols(&self.system.graph, id) {
                        let info = self.system.graph.symbol(s);
                        if matches!(info.role, Role::Acceleration { .. } | Role::AngularAcceleration { .. }) {
                            let (span, what, name) = (value.span(), what.to_string(), info.name.clone());
                            self.problem(Problem::ExpectedAcceleration { span, what, name });
                            return None;
                        }
                    }
                }
                Some(Expected::Formula { id, text: text.to_string() })
            }
            numbers if !self.numeric => {
                let _ = numbers;
                self.problem(Problem::NumberWithoutAt { span: value.span(), what: what.to_string() });
                None
            }
            RawExpected::Number(x) if want == Ty::Scalar => Some(Expected::Numbers(vec![*x])),
            RawExpected::Vector(xs) if want == Ty::Vector && xs.len() == dim => Some(Expected::Numbers(xs.clone())),
            RawExpected::Vector(xs) if want == Ty::Vector => {
                let (span, what, found) = (value.span(), what.to_string(), xs.len());
                self.problem(Problem::ExpectedComponents { span, what, found, dim });
                None
            }
            _ => {
                let (span, what, vector) = (value.span(), what.to_string(), want == Ty::Vector);
                self.problem(Problem::ExpectedShape { span, what, vector, dim });
                None
            }
        }
    }
}

fn unknown(span: Range<usize>, kind: &'static str, name: &str, names: &[&str]) -> Problem {
    let suggestion = suggest(name, names.iter().copied());
    let names = if suggestion.is_some() { Vec::new() } else { names.iter().map(|n| n.to_string()).collect() };
    Problem::UnknownName { span, kind, name: name.to_string(), suggestion, names }
}
