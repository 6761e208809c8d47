//! Checking derived results against expectations: the `[[expect]]` entries of a file
//! (`lagrange check`, `tests/constraint_files.rs`) and an API for users' own tests.
//!
//! A formula check passes at once when the derived and the expected formula have the same
//! canonical form ([`Simplifier::equivalent`](crate::expr::Simplifier::equivalent)). Otherwise both are evaluated at
//! [`STATES`] random states that satisfy the constraints ([`states`]: positions on C = 0,
//! velocities on Ċ = 0, random forces, parameters from the file) and must agree within the
//! relative tolerance [`FORMULA_TOLERANCE`]: a person may write `l^2` where lagrange has
//! `dot(r,r)`, and the two are equal exactly where it matters. Forces and λ of files with
//! several constraints have no closed form; there the derived side is the λ solve
//! (`numeric::solve`, every constraint taken as active) at each state. A rigid body's
//! constraint torque (`torque`, about its centre of mass) is judged like a force; its random
//! states have angles on the whole circle and ω on Ċ = 0 (`states`).
//!
//! A numeric check (`at = { … }`) compares with the numbers lagrange computes at that state
//! (the λ solve, inequalities included), within the entry's relative tolerance.
//!
//! Every quantity refers to C as written (see `model::expect`); the derivation's λ, A and
//! b refer to C/κ and are converted here: λ = λ_κ/κ, Aₖⱼ = κₖκⱼ A_κ, bₖ = κₖ b_κ.
//!
//! Comparison rule, for values x (derived) and y (expected): pass when
//! ‖x − y‖ ≤ tol · max(‖x‖, ‖y‖, 10⁻³).
//!
//! The loaded system is not changed: an expected formula given to the API is parsed in the
//! system's scope into the checked file's own derivation ([`Derivation::expression`]), where
//! derived and expected formulas share one graph.
//!
//! Not here: printing (the CLI prints [`Outcome`]s), reading files except in
//! [`Checked::load`] (`read.rs`, the one file access of the user-test API).
//!
//! ```no_run
//! use lagrange::check::Checked;
//! Checked::load("constraints/bead_on_wire.toml")?
//!     .assert_force("bead", "-(m*dot(v,v) + dot(F,r))/l^2 * r")
//!     .assert_lambda("wire", "-(m*dot(v,v) + dot(F,r))/(2*l^2)");
//! # Ok::<(), lagrange::check::CheckError>(())
//! ```

mod read;
pub use read::read_text;
pub mod states;

use crate::derive::{Derivation, DeriveError, derive};
use crate::expr::eval::{Env, Value, eval_one};
use crate::expr::print::{Style, print};
use crate::expr::{Id, Rational, Role, TypeError};
use crate::model::expect::{Expectation, Expected, Item};
use crate::model::file::{Loaded, load};
use crate::model::scene::{Scene, environment};
use crate::numeric::rows::{RowProgram, angular_slots, world_angular};
use crate::numeric::solve::solve;
use crate::report::diagnostic::render;
use std::fmt;
use std::ops::Range;
use std::path::Path;

pub use crate::model::expect::{DEFAULT_TOLERANCE, Quantity};

/// How many constraint-satisfying states a formula check that is not equal in canonical
/// form is judged at.
pub const STATES: usize = 100;
/// The relative tolerance of formula checks at those states.
pub const FORMULA_TOLERANCE: f64 = 1e-9;

/// Why a file could not be checked at all.
#[derive(Debug, thiserror::Error)]
pub enum CheckError {
    /// The file could not be read.
    #[error("cannot read {path}: {message}")]
    Read { path: String, message: String },
    /// The file is invalid; `rendered` holds every problem, located.
    #[error("{rendered}{count} problem(s) in {path}")]
    Invalid { path: String, rendered: String, count: usize },
    /// The derivation failed.
    #[error("{path}: {error}")]
    Derive { path: String, error: DeriveError },
    /// An expected formula given to the API does not parse, type-check or name a known
    /// body or constraint.
    #[error("{0}")]
    Expected(String),
    /// An internal type error while building the compared formulas.
    #[error("internal type error: {0}")]
    Type(#[from] TypeError),
}

/// The result of one check.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// What was checked, e.g. `force[bead]` or `lambda[rope] at r = [0, -2], v = [0, 0]`.
    pub label: String,
    /// Where the check is written in the file, if it comes from a file.
    pub span: Option<Range<usize>>,
    pub passed: bool,
    /// How it was judged (`canonical form`, `at 100 states on the constraints`, `at the state`).
    pub how: String,
    /// For a failure: the state, both values and their difference.
    pub detail: String,
    /// The `note` of the `[[expect]]` entry the check comes from: shown with a failure.
    pub note: Option<String>,
}

impl fmt::Display for Outcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let verdict = if self.passed { "ok" } else { "FAILED" };
        write!(f, "{verdict}: {} ({})", self.label, self.how)?;
        if !self.detail.is_empty() {
            write!(f, "\n{}", self.detail)?;
        }
        if let (false, Some(note)) = (self.passed, &self.note) {
            write!(f, "\n{}", noted(note))?;
        }
        Ok(())
    }
}

/// An entry's note as a failure shows it: `  note: ` before its first line, each further
/// line indented to match, control characters escaped (a note cannot fake an `ok` line).
pub fn noted(note: &str) -> String {
    let note = crate::report::diagnostic::escape_controls(note.trim_end(), true);
    let mut lines = note.lines();
    let first = lines.next().unwrap_or("");
    lines.fold(format!("  note: {first}"), |out, line| format!("{out}\n        {line}"))
}

/// A loaded, derived file, ready to check expectations against.
#[derive(Debug)]
pub struct Checked {
    /// The name used in messages (the path).
    pub name: String,
    pub loaded: Loaded,
    pub derivation: Derivation,
    program: Option<RowProgram>,
    states: Option<Result<Vec<Env>, String>>,
}

impl Checked {
    /// Reads, validates and derives the constraint file at `path`.
    pub fn load(path: impl AsRef<Path>) -> Result<Checked, CheckError> {
        let path = path.as_ref();
        let text = read::read_text(path)?;
        Checked::from_text(&path.display().to_string(), &text)
    }

    /// Validates and derives a constraint file's text; `name` is used in messages.
    pub fn from_text(name: &str, text: &str) -> Result<Checked, CheckError> {
        let loaded = load(text).map_err(|problems| CheckError::Invalid {
            path: name.to_string(),
            rendered: render(name, text, &problems),
            count: problems.len(),
        })?;
        let derivation =
            derive(&loaded.system).map_err(|error| CheckError::Derive { path: name.to_string(), error })?;
        Ok(Checked { name: name.to_string(), loaded, derivation, program: None, states: None })
    }

    /// Runs every `[[expect]]` entry of the file, in order.
    pub fn run(&mut self) -> Vec<Outcome> {
        let expectations = self.loaded.expect.clone();
        let mut out = Vec::new();
        for e in &expectations {
            for item in &e.items {
                let mut outcome = match &e.at {
                    None => match &item.expected {
                        Expected::Formula { id, .. } => self.judge_formula(item.quantity, *id),
                        Expected::Numbers(_) => Err(CheckError::Expected("numbers need a state (`at`)".into())),
                    },
                    Some(_) => self.judge_at(e, item),
                }
                .unwrap_or_else(|error| Outcome {
                    label: String::new(),
                    span: None,
                    passed: false,
                    how: "not checked".into(),
                    detail: format!("  {error}"),
                    note: None,
                });
                outcome.label = self.label(item.quantity, e);
                outcome.note.clone_from(&e.note);
                outcome.span = Some(item.span.clone());
                out.push(outcome);
            }
        }
        out
    }

    /// Whether the derived constraint force on `body` equals `expected` on the constraints.
    pub fn force(&mut self, body: &str, expected: &str) -> Result<Outcome, CheckError> {
        let i = self.loaded.system.body_named(body).ok_or_else(|| self.unknown("body", body))?;
        self.check(Quantity::Force(i), expected)
    }

    /// Whether the derived constraint torque on the rigid body `body` (2D: a scalar; 3D: a
    /// vector in the world frame; about its centre of mass) equals `expected` on the
    /// constraints.
    pub fn torque(&mut self, body: &str, expected: &str) -> Result<Outcome, CheckError> {
        let s = &self.loaded.system;
        let i = s
            .body_named(body)
            .filter(|&i| s.bodies[i].rigid.is_some())
            .ok_or_else(|| self.unknown("rigid body", body))?;
        self.check(Quantity::Torque(i), expected)
    }

    /// Whether λ of `constraint` (for C as written) equals `expected` on the constraints.
    pub fn lambda(&mut self, constraint: &str, expected: &str) -> Result<Outcome, CheckError> {
        let k = self.constraint(constraint)?;
        self.check(Quantity::Lambda(k), expected)
    }

    /// Whether Ċ of `constraint` equals `expected` on the constraints.
    pub fn c_dot(&mut self, constraint: &str, expected: &str) -> Result<Outcome, CheckError> {
        let k = self.constraint(constraint)?;
        self.check(Quantity::CDot(k), expected)
    }

    /// Whether C̈ of `constraint` equals `expected` on the constraints.
    pub fn c_ddot(&mut self, constraint: &str, expected: &str) -> Result<Outcome, CheckError> {
        let k = self.constraint(constraint)?;
        self.check(Quantity::CDdot(k), expected)
    }

    /// Whether Aₖⱼ (for C as written) equals `expected` on the constraints.
    pub fn a(&mut self, k: &str, j: &str, expected: &str) -> Result<Outcome, CheckError> {
        let (k, j) = (self.constraint(k)?, self.constraint(j)?);
        self.check(Quantity::A(k, j), expected)
    }

    /// Whether bₖ (for C as written) equals `expected` on the constraints.
    pub fn b(&mut self, constraint: &str, expected: &str) -> Result<Outcome, CheckError> {
        let k = self.constraint(constraint)?;
        self.check(Quantity::B(k), expected)
    }

    /// Asserts [`Checked::force`].
    ///
    /// # Panics
    /// When the formulas differ (the message gives the state, both values and the
    /// difference) or `expected` is not a valid expression: this is a test assertion.
    #[track_caller]
    pub fn assert_force(&mut self, body: &str, expected: &str) -> &mut Checked {
        let r = self.force(body, expected);
        self.assert(r)
    }

    /// Asserts [`Checked::torque`]. # Panics: as [`Checked::assert_force`].
    #[track_caller]
    pub fn assert_torque(&mut self, body: &str, expected: &str) -> &mut Checked {
        let r = self.torque(body, expected);
        self.assert(r)
    }

    /// Asserts [`Checked::lambda`]. # Panics: as [`Checked::assert_force`].
    #[track_caller]
    pub fn assert_lambda(&mut self, constraint: &str, expected: &str) -> &mut Checked {
        let r = self.lambda(constraint, expected);
        self.assert(r)
    }

    /// Asserts [`Checked::c_dot`]. # Panics: as [`Checked::assert_force`].
    #[track_caller]
    pub fn assert_c_dot(&mut self, constraint: &str, expected: &str) -> &mut Checked {
        let r = self.c_dot(constraint, expected);
        self.assert(r)
    }

    /// Asserts [`Checked::c_ddot`]. # Panics: as [`Checked::assert_force`].
    #[track_caller]
    pub fn assert_c_ddot(&mut self, constraint: &str, expected: &str) -> &mut Checked {
        let r = self.c_ddot(constraint, expected);
        self.assert(r)
    }

    /// Asserts [`Checked::a`]. # Panics: as [`Checked::assert_force`].
    #[track_caller]
    pub fn assert_a(&mut self, k: &str, j: &str, expected: &str) -> &mut Checked {
        let r = self.a(k, j, expected);
        self.assert(r)
    }

    /// Asserts [`Checked::b`]. # Panics: as [`Checked::assert_force`].
    #[track_caller]
    pub fn assert_b(&mut self, constraint: &str, expected: &str) -> &mut Checked {
        let r = self.b(constraint, expected);
        self.assert(r)
    }

    #[track_caller]
    fn assert(&mut self, r: Result<Outcome, CheckError>) -> &mut Checked {
        match r {
            Ok(o) if o.passed => self,
            Ok(o) => panic!("{}: {o}", self.name),
            Err(e) => panic!("{}: {e}", self.name),
        }
    }

    fn constraint(&self, name: &str) -> Result<usize, CheckError> {
        self.loaded.system.constraint_named(name).ok_or_else(|| self.unknown("constraint", name))
    }

    fn unknown(&self, kind: &str, name: &str) -> CheckError {
        let s = &self.loaded.system;
        let names: Vec<&str> = if kind == "body" {
            s.bodies.iter().map(|b| b.name.as_str()).collect()
        } else if kind == "rigid body" {
            s.bodies.iter().filter(|b| b.rigid.is_some()).map(|b| b.name.as_str()).collect()
        } else {
            s.constraints.iter().map(|c| c.name.as_str()).collect()
        };
        CheckError::Expected(format!("`{name}` is not a {kind} of {} ({kind}s: {})", self.name, names.join(", ")))
    }

    /// Parses `expected` in the file's scope and judges it against `quantity`.
    fn check(&mut self, quantity: Quantity, expected: &str) -> Result<Outcome, CheckError> {
        // Into the derivation's graph, where it can be compared with what was derived.
        let d = &mut self.derivation;
        let id = d
            .expression(&self.loaded.system, expected)
            .map_err(|e| CheckError::Expected(format!("in `{expected}`: {e}")))?;
        let want = quantity.ty(self.loaded.system.dim());
        if d.graph.ty(id) != want {
            return Err(CheckError::Expected(format!("`{expected}` must be a {want:?}, found a {:?}", d.graph.ty(id))));
        }
        let mut outcome = self.judge_formula(quantity, id)?;
        outcome.label = self.label(quantity, &Expectation::default_for_api());
        Ok(outcome)
    }

    fn label(&self, q: Quantity, e: &Expectation) -> String {
        let s = &self.loaded.system;
        let c = |k: usize| s.constraints[k].name.as_str();
        let base = match q {
            Quantity::Force(i) => format!("force[{}]", s.bodies[i].name),
            Quantity::Torque(i) => format!("torque[{}]", s.bodies[i].name),
            Quantity::Lambda(k) => format!("lambda[{}]", c(k)),
            Quantity::CDot(k) => format!("C_dot[{}]", c(k)),
            Quantity::CDdot(k) => format!("C_ddot[{}]", c(k)),
            Quantity::A(k, j) => format!("A[{},{}]", c(k), c(j)),
            Quantity::B(k) => format!("b[{}]", c(k)),
        };
        match &e.at {
            Some(at) => {
                let dim = s.dim();
                let values: Vec<String> = at
                    .iter()
                    .map(|&(n, v)| format!("{} = {}", s.graph.symbol(n).name, crate::model::state::written(v, dim)))
                    .collect();
                format!("{base} at {}", values.join(", "))
            }
            None => base,
        }
    }

    /// The derived formula of `q` for C as written; `None` for forces and λ of several
    /// constraints (no closed form).
    fn derived(&mut self, q: Quantity) -> Result<Option<Id>, TypeError> {
        let d = &mut self.derivation;
        let kappa = |k: usize| d.constraints[k].scale.clone();
        let (id, factor) = match q {
            Quantity::Force(i) => match &d.forces {
                Some(forces) => match forces.iter().find(|(b, _)| *b == i) {
                    Some(&(_, f)) => (f, Rational::ONE),
                    None => (d.graph.zero_vector(), Rational::ONE),
                },
                None => return Ok(None),
            },
            Quantity::Torque(i) => match &d.torques {
                Some(torques) => match torques.iter().find(|(b, _)| *b == i) {
                    Some(&(_, t)) => (t, Rational::ONE),
                    None if self.loaded.system.dim() == 3 => (d.graph.zero_vector(), Rational::ONE),
                    None => (d.graph.int(0), Rational::ONE),
                },
                None => return Ok(None),
            },
            Quantity::Lambda(k) => match d.lambda {
                Some(l) => (l, kappa(k).recip().unwrap_or(Rational::ONE)),
                None => return Ok(None),
            },
            Quantity::CDot(k) => (d.constraints[k].c_dot, Rational::ONE),
            Quantity::CDdot(k) => (d.constraints[k].c_ddot, Rational::ONE),
            Quantity::A(k, j) => match d.a_entry(k, j) {
                Some(a) => (a, kappa(k).mul(&kappa(j))),
                None => (d.graph.int(0), Rational::ONE),
            },
            Quantity::B(k) => (d.b[k], kappa(k)),
        };
        if factor.is_one() {
            return Ok(Some(id));
        }
        Ok(Some(d.simplifier.scaled(&mut d.graph, id, &factor)?))
    }

    /// Judges `expected` against the derived `q`: canonical form first, then states.
    fn judge_formula(&mut self, q: Quantity, expected: Id) -> Result<Outcome, CheckError> {
        let derived = self.derived(q)?;
        if let Some(d) = derived {
            let derivation = &mut self.derivation;
            if derivation.simplifier.equivalent(&mut derivation.graph, d, expected)? {
                return Ok(outcome(true, "equal in canonical form", String::new()));
            }
        }
        let states = match self.states() {
            Ok(s) => s,
            Err(message) => return Ok(outcome(false, "not checked", format!("  {message}"))),
        };
        for env in &states {
            let got = match derived {
                Some(d) => self.eval(d, env),
                None => self.solved(q, env, true),
            };
            let want = self.eval(expected, env);
            let verdict = compare(&got, &want, FORMULA_TOLERANCE);
            if !verdict.0 {
                let detail = self.failure(env, &got, &want, verdict.1, derived, expected);
                self.states = Some(Ok(states));
                return Ok(outcome(
                    false,
                    &format!("at states on the constraints, tolerance {FORMULA_TOLERANCE:e}"),
                    detail,
                ));
            }
        }
        let n = states.len();
        self.states = Some(Ok(states));
        Ok(outcome(true, &format!("equal at {n} random states on the constraints"), String::new()))
    }

    /// Judges a numeric item of an `at` entry.
    fn judge_at(&mut self, e: &Expectation, item: &Item) -> Result<Outcome, CheckError> {
        let at = e.at.clone().unwrap_or_default();
        let scene = Scene { initial: Vec::new(), ..self.loaded.scene.clone() };
        let env = match environment(&self.loaded.system, &self.loaded.values, &scene, &at) {
            Ok(env) => env,
            Err(error) => return Ok(outcome(false, "not checked", format!("  the state is incomplete: {error}"))),
        };
        let got = self.solved(item.quantity, &env, false);
        let want = match &item.expected {
            Expected::Numbers(xs) => Ok(xs.clone()),
            Expected::Formula { id, .. } => self.eval(*id, &env),
        };
        let (passed, diff) = compare(&got, &want, e.tolerance);
        let how = format!("at the state, tolerance {:e}", e.tolerance);
        if passed {
            return Ok(outcome(true, &how, String::new()));
        }
        let detail = format!(
            "  lagrange = {}\n  expected = {}\n  difference: {}",
            show(&got),
            show(&want),
            diff.map_or("-".into(), |d| format!("{d:e}"))
        );
        Ok(outcome(false, &how, detail))
    }

    /// λ (for C as written) or the constraint force from the numeric solve at `env`;
    /// `all_active` treats inequalities as equalities (the closed form's reading).
    fn solved(&mut self, q: Quantity, env: &Env, all_active: bool) -> Result<Vec<f64>, String> {
        let program = match &self.program {
            Some(p) => p,
            None => self.program.insert(RowProgram::new(&self.loaded.system, &self.derivation, &[])),
        };
        let system = &self.loaded.system;
        let mut rows = program.evaluate(system, env).map_err(|e| e.to_string())?;
        if all_active {
            rows.rows.iter_mut().for_each(|r| r.inequality = false);
        }
        let solution = solve(&rows);
        let dim = system.dim();
        match q {
            Quantity::Force(i) => Ok(solution.constraint_force[i][..dim].to_vec()),
            // 2D: the scalar torque; 3D: the world vector of the body's principal slots.
            Quantity::Torque(i) => match angular_slots(system, i) {
                Some(slots) => {
                    let torque = world_angular(&rows, |s| solution.constraint_force[s][0], slots);
                    Ok(torque[..if dim == 3 { 3 } else { 1 }].to_vec())
                }
                None => Err(format!("body `{}` is not rigid", system.bodies[i].name)),
            },
            Quantity::Lambda(k) => Ok(vec![solution.lambda[k] / self.derivation.constraints[k].scale.to_f64()]),
            _ => {
                let id = self.derived(q).map_err(|e| e.to_string())?.ok_or("no formula")?;
                self.eval(id, env)
            }
        }
    }

    fn states(&mut self) -> Result<Vec<Env>, String> {
        if let Some(s) = self.states.take() {
            return s;
        }
        let l = &self.loaded;
        states::sample(&l.system, &self.derivation, &l.values, &l.scene, STATES)
    }

    /// The state, both values and their difference, for a failed formula check.
    fn failure(
        &self,
        env: &Env,
        got: &Result<Vec<f64>, String>,
        want: &Result<Vec<f64>, String>,
        diff: Option<f64>,
        derived: Option<Id>,
        expected: Id,
    ) -> String {
        let g = &self.derivation.graph;
        let mut state = Vec::new();
        for (s, info) in g.symbols() {
            if matches!(info.role, Role::Parameter) {
                continue;
            }
            if let Some(v) = env.get(s) {
                state.push(format!("{} = {}", info.name, show_value(v, g.dim())));
            }
        }
        let formula = derived.and_then(|d| print(g, d, Style::Source).ok()).unwrap_or_else(|| "(the λ solve)".into());
        let wanted = print(g, expected, Style::Source).unwrap_or_default();
        format!(
            "  derived:   {formula}\n  expected:  {wanted}\n  at the state {}\n  derived  = {}\n  expected = {}\n  difference: {}",
            state.join(", "),
            show(got),
            show(want),
            diff.map_or("-".into(), |d| format!("{d:e}"))
        )
    }
}

impl Checked {
    /// A formula of the derivation's graph at `env`, as components.
    fn eval(&self, id: Id, env: &Env) -> Result<Vec<f64>, String> {
        let dim = self.loaded.system.dim();
        eval_one(&self.derivation.graph, id, env).map(|v| v.components(dim)).map_err(|e| e.to_string())
    }
}

impl Expectation {
    fn default_for_api() -> Expectation {
        Expectation { span: 0..0, at: None, tolerance: FORMULA_TOLERANCE, items: Vec::new(), note: None }
    }
}

fn outcome(passed: bool, how: &str, detail: String) -> Outcome {
    Outcome { label: String::new(), span: None, passed, how: how.to_string(), detail, note: None }
}

/// `(passed, ‖x − y‖)`: ‖x − y‖ ≤ tol · max(‖x‖, ‖y‖, 10⁻³), every value finite.
///
/// Computed in units of the largest |component| s, so neither the squares nor the
/// difference overflow: values past ~1.4e154 (whose squares are ∞, which once made every
/// such comparison pass) compare as any others. The returned difference is in the values'
/// own unit (∞ only when it truly exceeds f64's range).
fn compare(x: &Result<Vec<f64>, String>, y: &Result<Vec<f64>, String>, tol: f64) -> (bool, Option<f64>) {
    let (Ok(x), Ok(y)) = (x, y) else {
        return (false, None);
    };
    if x.len() != y.len() || !x.iter().chain(y).all(|v| v.is_finite()) {
        return (false, None);
    }
    let s = x.iter().chain(y).fold(0.0f64, |m, v| m.max(v.abs()));
    if s == 0.0 {
        return (true, Some(0.0));
    }
    let norm = |v: &mut dyn Iterator<Item = f64>| v.map(|a| a * a).sum::<f64>().sqrt();
    // x/s and y/s lie in [−1, 1]: their difference and squares are finite.
    let d = norm(&mut x.iter().zip(y).map(|(a, b)| a / s - b / s));
    let size = norm(&mut x.iter().map(|a| a / s)).max(norm(&mut y.iter().map(|b| b / s)));
    // 10⁻³ in units of s (∞ for a subnormal s: both values are then within 10⁻³ of 0).
    let floor = 1e-3 / s;
    (d <= tol * size.max(floor), Some(d * s))
}

fn show(v: &Result<Vec<f64>, String>) -> String {
    match v {
        Ok(xs) if xs.len() == 1 => format!("{}", xs[0]),
        Ok(xs) => format!("[{}]", xs.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ")),
        Err(e) => format!("cannot evaluate: {e}"),
    }
}

fn show_value(v: Value, dim: usize) -> String {
    show(&Ok(v.components(dim)))
}
