//! What can be wrong with a constraint file: one [`Problem`] variant per cause, each with
//! the span of the fault in the file text and the names and numbers its message needs.
//!
//! The message (`Display`) is the only prose; `report::diagnostic` draws it under the
//! source line. Variants are grouped by the stage that finds them: reading the TOML
//! (`model::document`, `model::keys`), building the system (`model::file`), the scene
//! (`model::scene`) and the expectations (`model::expect`). [`locate`] maps a span inside
//! a string value to the file.
//!
//! Not here: finding problems (the stages above), rendering them (`report::diagnostic`).

use super::raw::{AT_STATE, QUANTITIES};
use super::state::ValueError;
use super::system::BuildError;
use std::ops::Range;
use toml::Spanned;

/// One problem in a file: where (a byte range of the file text, when it has a place) and
/// what (the variant; its `Display` is the message).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Problem {
    // Reading the file (`model::document`, `model::keys`).
    /// The file is larger than the loader reads.
    #[error("file is too large ({bytes} bytes; the limit is {limit} bytes, 64 MiB, about 240 000 bodies of a chain)")]
    TooLarge { bytes: usize, limit: usize },
    /// Not TOML: toml's own message (its limits said in the file's terms).
    #[error("{message}")]
    Syntax { span: Option<Range<usize>>, message: String },
    /// A key the schema of its table does not have.
    #[error("unknown key `{key}` {}{}", place(.table), hint(.suggestion, .known))]
    UnknownKey {
        span: Range<usize>,
        key: String,
        /// The schema path of the table (`""` at the top level, `bodies[]`, `scene`, …).
        table: &'static str,
        suggestion: Option<String>,
        known: &'static [&'static str],
    },
    /// No `dimension` at the top level.
    #[error("the file has no `dimension`: add `dimension = 2` or `dimension = 3` at the top")]
    NoDimension { span: Range<usize> },
    /// A value of the wrong TOML type (`what` names it in the file's words).
    #[error("{what} must be {expected}, found {found}")]
    WrongType { span: Range<usize>, what: String, expected: String, found: &'static str },
    /// A required field is missing from a table.
    #[error("{what} has no `{key}` (e.g. `{key} = {example}`)")]
    MissingField { span: Range<usize>, what: String, key: String, example: &'static str },
    /// `nan` or `inf` where a number of the model belongs (`shown` as TOML spells it).
    #[error("{what} must be a finite number, found {shown}")]
    NotFinite { span: Range<usize>, what: String, shown: String },

    // Building the system (`model::file`).
    /// The builder refused a declaration (a name, a clash, an expression).
    #[error("{error}")]
    Build { span: Range<usize>, error: BuildError },
    /// A vector parameter whose length is not the file's dimension.
    #[error("parameter `{name}` has {found} components in a {dim}D file")]
    ParameterComponents { span: Range<usize>, name: String, found: usize, dim: usize },
    /// A mass written as a number that is not positive, normal and finite.
    #[error("a mass must be a positive finite number, found {shown}{}", subnormal(.shown))]
    Mass { span: Range<usize>, shown: String },
    /// A mass symbol given a value (in `[parameters]` or `[scene] initial`) that is not a
    /// positive normal number.
    #[error("`{name}` is the mass of body `{body}`: it must be a positive finite number, found {shown}{}", subnormal(.shown))]
    MassValue { span: Range<usize>, name: String, body: String, shown: String },
    /// A mass written as a string that is a number (`mass = "0.5"`).
    #[error(
        "the mass \"{written}\" is a number in quotes: write it without them (`mass = {written}`), or give the name of a mass symbol"
    )]
    QuotedMass { span: Range<usize>, written: String },
    /// A mass written as a vector.
    #[error("a mass is one number or a scalar symbol's name, found a vector")]
    VectorMass { span: Range<usize> },
    /// Principal moments written with other than three entries.
    #[error("principal moments of inertia are three numbers [I1, I2, I3], found {found}")]
    InertiaLength { span: Range<usize>, found: usize },
    /// An inertia written as a number that is not positive and finite.
    #[error("an inertia must be a positive finite number, found {shown}")]
    Inertia { span: Range<usize>, shown: String },
    /// A body with an `orientation` (so rigid) but no `inertia`.
    #[error(
        "body `{body}` has an `orientation`, so it is rigid, and needs an `inertia`: its moment of inertia about the centre of mass (e.g. `inertia = \"I\"` or `inertia = 0.5`)"
    )]
    NoInertia { span: Range<usize>, body: String },
    /// A rotational key (`inertia`, `torque`, …) on a body without an `orientation`.
    #[error(
        "{what} has `{key}` but no `orientation`: a body is rigid when it has one (e.g. `orientation = \"th\"`), else a point mass"
    )]
    RigidKeyWithoutOrientation { span: Range<usize>, what: String, key: &'static str },
    /// A definition that uses itself, directly or `through` others.
    #[error("definition `{name}` refers to itself (through {through})")]
    Cycle { span: Range<usize>, name: String, through: String },
    /// Nothing to derive.
    #[error("the file has no [[constraints]]")]
    NoConstraints,
    /// A mass symbol without a value, in a file whose `[scene]` needs numbers.
    #[error("the mass `{name}` has no value, and the [scene] needs one: give it in [parameters] or in [scene] initial")]
    MassWithoutValue { span: Range<usize>, name: String },
    /// A mass symbol without a value at the state of an `[[expect]]` `at`.
    #[error(
        "this [[expect]] is checked at a state (`at`), which gives no value to the mass `{name}`: add it to `at` or to [parameters]"
    )]
    MassWithoutValueAt { span: Range<usize>, name: String },

    // The scene and states (`model::scene`, `model::expect`).
    /// A value given to a symbol (`[scene] initial`, `at`) that does not fit it.
    #[error("{error}")]
    Value { span: Range<usize>, error: ValueError },
    /// A `[scene] forces` key that names no body.
    #[error("`{name}` is not a body's force symbol or a body's name ({})", force_symbols(.forces, .without))]
    UnknownForce {
        span: Range<usize>,
        name: String,
        /// The force and torque symbols the file writes.
        forces: Vec<String>,
        /// The bodies whose `force` could not be read (reported there): they have none.
        without: Vec<String>,
    },
    /// A force expression that cannot be a force.
    #[error("in the force on `{name}`: {error}")]
    Force { span: Range<usize>, name: String, error: ForceError },
    /// A rigid body's torque expression that cannot be its torque.
    #[error("in the torque `{name}`: {error}")]
    Torque { span: Range<usize>, name: String, error: ForceError },
    /// A force or torque symbol given both a value in `[scene] initial` and an expression in
    /// `[scene] forces`: located at the expression's key, the value's key a second label.
    #[error(
        "the {what} `{name}` is given twice: a value in [scene] initial (line {initial_line}) and an expression in [scene] forces (line {line}); keep one of them"
    )]
    GivenTwice {
        span: Range<usize>,
        /// The key of the value in `initial`.
        initial: Range<usize>,
        /// `"force"` or `"torque"`.
        what: &'static str,
        /// The force or torque symbol.
        name: String,
        line: usize,
        initial_line: usize,
    },
    /// `dt`, `duration` or `restitution` out of range.
    #[error("`{key}` must be a finite {must} number, found {value}")]
    SceneNumber { span: Range<usize>, key: &'static str, must: &'static str, value: f64 },
    /// A restitution above 1.
    #[error("`restitution` must lie in [0, 1], found {value}")]
    Restitution { span: Range<usize>, value: f64 },

    // Expectations (`model::expect`).
    /// `tolerance` on an entry without `at`.
    #[error(
        "`tolerance` applies to checks at a state (`at = {{ … }}`); formula checks use a fixed relative tolerance of 1e-9"
    )]
    ToleranceWithoutAt { span: Range<usize> },
    /// A tolerance that is not positive and finite.
    #[error("`tolerance` must be a positive finite number, found {shown}")]
    Tolerance { span: Range<usize>, shown: String },
    /// An entry with none of the quantities.
    #[error("this [[expect]] entry checks nothing: give {}", listed(&QUANTITIES, "or"))]
    ChecksNothing { span: Range<usize> },
    /// A quantity other than those of [`AT_STATE`] in an entry with `at`.
    #[error("only {} can be checked at a state (`at`); `{what}` needs a formula check without `at`", listed(&AT_STATE, "and"))]
    NotAtState { span: Range<usize>, what: String },
    /// An `A` key that is not `"k,j"`.
    #[error("an `A` key names two constraints as \"k,j\" (e.g. \"rod1,rod2\"), found \"{key}\"")]
    PairKey { span: Range<usize>, key: String },
    /// A body or constraint name the file does not declare.
    #[error("{}", unknown_name(.kind, .name, .suggestion, .names))]
    UnknownName {
        span: Range<usize>,
        /// `"body"` or `"constraint"`.
        kind: &'static str,
        name: String,
        suggestion: Option<String>,
        /// The names of that kind the file declares.
        names: Vec<String>,
    },
    /// A vector constraint named where one of its rows belongs (`lambda`, `C_dot`, `A`, …).
    #[error("`{name}` is a vector constraint, checked row by row: name its rows, {}", listed_names(.rows))]
    VectorConstraint { span: Range<usize>, name: String, rows: Vec<String> },
    /// An expected formula that does not parse or lower.
    #[error("in the expected `{what}`: {error}")]
    ExpectedFormula { span: Range<usize>, what: String, error: BuildError },
    /// An expected formula of the wrong type.
    #[error("the expected `{what}` must be {want}, found {found}")]
    ExpectedType { span: Range<usize>, what: String, want: &'static str, found: &'static str },
    /// An expected formula (other than `C_ddot`) that uses an acceleration.
    #[error(
        "the expected `{what}` uses the acceleration `{name}`; only `C_ddot` may (forces and λ do not depend on it)"
    )]
    ExpectedAcceleration { span: Range<usize>, what: String, name: String },
    /// A number expected in an entry without `at`.
    #[error("the expected `{what}` is a number: give the state it holds at with `at = {{ … }}`, or write a formula")]
    NumberWithoutAt { span: Range<usize>, what: String },
    /// An expected vector whose length is not the file's dimension.
    #[error("the expected `{what}` has {found} components in a {dim}D file")]
    ExpectedComponents { span: Range<usize>, what: String, found: usize, dim: usize },
    /// An expected number where a vector belongs, or the other way round.
    #[error("the expected `{what}` must be {}", shape(*.vector, *.dim))]
    ExpectedShape { span: Range<usize>, what: String, vector: bool, dim: usize },
}

/// Why a `[scene] forces` expression is not a force.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ForceError {
    #[error("{0}")]
    Build(BuildError),
    #[error("a force must be a vector, found a scalar")]
    Scalar,
    #[error("a force or torque may not depend on `{0}` (an acceleration, a force or a torque)")]
    Depends(String),
    /// A rigid body's torque written as a vector (a 2D torque is a scalar).
    #[error("a 2D torque must be a scalar, found a vector")]
    Vector,
    /// A 3D rigid body's torque written as a scalar (a 3D torque is a world-frame vector).
    #[error("a 3D torque must be a vector in the world frame, found a scalar (no torque: `[0, 0, 0]`)")]
    ScalarTorque,
}

impl Problem {
    /// Where the problem is, as a byte range of the file text (`None`: the whole file).
    pub fn span(&self) -> Option<Range<usize>> {
        use Problem::*;
        match self {
            TooLarge { .. } | NoConstraints => None,
            Syntax { span, .. } => span.clone(),
            UnknownKey { span, .. }
            | NoDimension { span }
            | WrongType { span, .. }
            | MissingField { span, .. }
            | NotFinite { span, .. }
            | Build { span, .. }
            | ParameterComponents { span, .. }
            | Mass { span, .. }
            | QuotedMass { span, .. }
            | MassValue { span, .. }
            | Inertia { span, .. }
            | VectorMass { span }
            | InertiaLength { span, .. }
            | NoInertia { span, .. }
            | RigidKeyWithoutOrientation { span, .. }
            | Cycle { span, .. }
            | MassWithoutValue { span, .. }
            | MassWithoutValueAt { span, .. }
            | Value { span, .. }
            | UnknownForce { span, .. }
            | Force { span, .. }
            | Torque { span, .. }
            | GivenTwice { span, .. }
            | SceneNumber { span, .. }
            | Restitution { span, .. }
            | ToleranceWithoutAt { span }
            | Tolerance { span, .. }
            | ChecksNothing { span }
            | NotAtState { span, .. }
            | PairKey { span, .. }
            | UnknownName { span, .. }
            | VectorConstraint { span, .. }
            | ExpectedFormula { span, .. }
            | ExpectedType { span, .. }
            | ExpectedAcceleration { span, .. }
            | NumberWithoutAt { span, .. }
            | ExpectedComponents { span, .. }
            | ExpectedShape { span, .. } => Some(span.clone()),
        }
    }
}

impl Problem {
    /// A second place the problem is at, with what it is there (the value of a force or
    /// torque also given an expression).
    pub fn also(&self) -> Option<(Range<usize>, &'static str)> {
        match self {
            Problem::GivenTwice { initial, .. } => Some((initial.clone(), "given a value here")),
            _ => None,
        }
    }
}

/// The 1-based line of byte `offset` of `text`.
pub fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

/// In file order, so the messages read top to bottom (unlocated ones first); a problem
/// found twice (by two passes over the same value) is shown once.
pub fn sort(problems: &mut Vec<Problem>) {
    problems.sort_by_key(|p| p.span().map_or((0, 0), |s| (s.start, s.end)));
    problems.dedup_by(|a, b| a.span() == b.span() && a.to_string() == b.to_string());
}

/// `nan` as TOML spells it, other numbers as Rust prints them (`5e-324`, not 324 digits,
/// for the tiny and the huge).
pub fn shown(x: f64) -> String {
    if x.is_nan() {
        "nan".to_string()
    } else if x != 0.0 && x.is_finite() && !(1e-5..1e16).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        x.to_string()
    }
}

/// The hint of a mass that is subnormal (shown in `e` notation, positive, tiny).
fn subnormal(shown: &str) -> &'static str {
    shown.parse::<f64>().map_or("", subnormal_hint)
}

/// The hint of a mass or moment of inertia `x` that is positive but subnormal: its inverse
/// overflows.
pub fn subnormal_hint(x: f64) -> &'static str {
    if x > 0.0 && !x.is_normal() { " (a subnormal number: 1/m overflows)" } else { "" }
}

/// Maps a byte range inside a string value to the file: exact when the string is written
/// without escapes (the common case), else the whole string.
pub fn locate<S: AsRef<str>>(text: &str, value: &Spanned<S>, inner: Range<usize>) -> Range<usize> {
    let outer = value.span();
    let written = text.get(outer.clone()).unwrap_or("");
    let content = value.get_ref().as_ref();
    for quote in ["\"\"\"", "'''", "\"", "'"] {
        if let Some(body) = written.strip_prefix(quote).and_then(|w| w.strip_suffix(quote))
            && body == content
        {
            let start = outer.start + quote.len();
            return (start + inner.start).min(outer.end)..(start + inner.end).min(outer.end);
        }
    }
    outer
}

/// Keys as a message lists them: `` `a`, `b` or `c` `` (with `and` for `conjunction`
/// "and").
fn listed(keys: &[&str], conjunction: &str) -> String {
    let quoted: Vec<String> = keys.iter().map(|k| format!("`{k}`")).collect();
    match quoted.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, init)) => format!("{} {conjunction} {last}", init.join(", ")),
    }
}

/// Names as a message lists them: `` `a.x` and `a.y` ``.
fn listed_names(names: &[String]) -> String {
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    listed(&names, "and")
}

fn place(table: &str) -> String {
    if table.is_empty() { "at the top level".to_string() } else { format!("in `{table}`") }
}

fn hint(suggestion: &Option<String>, known: &[&str]) -> String {
    match suggestion {
        Some(s) => format!("; did you mean `{s}`?"),
        None => format!(" (expected one of: {})", known.join(", ")),
    }
}

fn force_symbols(forces: &[String], without: &[String]) -> String {
    let none = match without {
        [] => String::new(),
        [body] => format!("body `{body}` has no force symbol"),
        bodies => format!(
            "bodies {} have no force symbol",
            bodies.iter().map(|b| format!("`{b}`")).collect::<Vec<_>>().join(", ")
        ),
    };
    match (forces.is_empty(), none.is_empty()) {
        (true, true) => "the file declares no bodies".to_string(),
        (true, false) => none,
        (false, true) => format!("force symbols: {}", forces.join(", ")),
        (false, false) => format!("force symbols: {}; {none}", forces.join(", ")),
    }
}

fn unknown_name(kind: &str, name: &str, suggestion: &Option<String>, names: &[String]) -> String {
    let kinds = match kind {
        "body" => "bodies",
        "rigid body" => "rigid bodies",
        _ => "constraints",
    };
    match suggestion {
        Some(s) => format!("`{name}` is not a {kind} of this file; did you mean `{s}`?"),
        None if names.is_empty() => format!("`{name}` is not a {kind} of this file (it declares no {kinds})"),
        None => format!("`{name}` is not a {kind} of this file ({kinds}: {})", names.join(", ")),
    }
}

fn shape(vector: bool, dim: usize) -> String {
    if vector { format!("a vector of {dim} numbers") } else { "a number".into() }
}
