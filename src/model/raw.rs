//! Every raw type of a constraint file: the TOML as written, with spans, before any meaning.
//!
//! `model::document` fills these from the spanned TOML tree (and `model::state` reads
//! [`RawValue`]s from `--at` files and `--set`); validation (`model::file`, `scene`,
//! `expect`, `state`) turns them into the model. Nothing past validation sees them: a
//! [`crate::model::file::Loaded`] holds symbols and [`crate::expr::eval::Value`]s.
//!
//! Not here: reading (`model::document`), validation, messages (`model::problem`).

use serde::Deserialize;
use std::borrow::Cow;
use std::collections::BTreeMap;
use toml::Spanned;

/// A string as written, with its span: borrowed from the file text unless TOML escapes
/// made it differ (a file of a thousand bodies holds thousands of them, and allocating
/// each was a tenth of loading it).
pub type Text<'a> = Spanned<Cow<'a, str>>;

/// A file as written, read field by field from the spanned TOML tree by `model::document`
/// (every missing field and wrong type is a problem there; what could not be read is left
/// out here). Unknown keys are reported, all of them, by `model::keys`.
#[derive(Debug, Default)]
pub struct RawFile<'a> {
    pub title: Option<Text<'a>>,
    /// `None` when missing or not an integer (already reported).
    pub dimension: Option<Spanned<i64>>,
    pub parameters: BTreeMap<Text<'a>, Spanned<RawValue>>,
    pub definitions: BTreeMap<Text<'a>, Text<'a>>,
    pub bodies: Vec<Spanned<RawBody<'a>>>,
    pub constraints: Vec<Spanned<RawConstraint<'a>>>,
    /// Whether the file writes `constraints` at all, readable or not (an entry without a
    /// `name` is reported and left out of `constraints`; the file is not "without
    /// constraints" then).
    pub constraints_written: bool,
    pub scene: Option<Spanned<RawScene<'a>>>,
    pub expect: Vec<Spanned<RawExpect<'a>>>,
}

/// A value as written: a number or a vector of numbers (finite, when read from a
/// constraint file). `Deserialize` reads `--at` state files and `--set` vectors
/// (`model::state`); serde's messages name this type, so its name is part of them.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum RawValue {
    Number(f64),
    Vector(Vec<f64>),
}

/// A body as written. A symbol field that is missing or not a string (reported by
/// `model::document`) holds a placeholder name, `unread_<field>_<n>`, and a mass that is not
/// a number or a string holds 1: the body stays declared, so its other symbols are not
/// reported again as unknown wherever they are used. (A file with a problem derives nothing.)
#[derive(Debug)]
pub struct RawBody<'a> {
    pub name: Text<'a>,
    pub position: Text<'a>,
    pub velocity: Text<'a>,
    pub acceleration: Text<'a>,
    pub mass: Spanned<RawMass<'a>>,
    pub force: Text<'a>,
    /// The rotational keys of a rigid body, present when the body has an `orientation`.
    pub rigid: Option<RawRigid<'a>>,
    /// The placeholder names among this body's symbols (empty when every one was read):
    /// never shown to the user, who did not write them.
    pub placeholders: Vec<String>,
}

/// A rigid body's rotational keys as written (placeholders as in [`RawBody`]).
#[derive(Debug)]
pub struct RawRigid<'a> {
    pub orientation: Text<'a>,
    pub angular_velocity: Text<'a>,
    pub angular_acceleration: Text<'a>,
    pub torque: Text<'a>,
    /// `None` when missing (reported by `model::file`, at the orientation).
    pub inertia: Option<Spanned<RawMass<'a>>>,
}

/// A body's mass as written: a number or the name of a symbol.
#[derive(Clone, Debug)]
pub enum RawMass<'a> {
    Number(f64),
    Symbol(Cow<'a, str>),
    /// A vector literal: a 3D rigid body's principal moments (refused for a mass).
    Vector(Vec<f64>),
}

/// A constraint as written.
#[derive(Debug)]
pub struct RawConstraint<'a> {
    pub name: Text<'a>,
    /// `None` when missing or not a string (reported by `model::document`).
    pub expr: Option<Text<'a>>,
}

/// The `[scene]` table as written.
#[derive(Debug, Default)]
pub struct RawScene<'a> {
    /// Initial values of positions, velocities and other symbols (`t`, masses).
    pub initial: BTreeMap<Text<'a>, Spanned<RawValue>>,
    /// External force per body: the force symbol (or the body's name) → an expression.
    pub forces: BTreeMap<Text<'a>, Text<'a>>,
    pub dt: Option<Spanned<f64>>,
    pub duration: Option<Spanned<f64>>,
    /// Coefficient of restitution for closing contacts, in [0, 1].
    pub restitution: Option<Spanned<f64>>,
}

/// The quantities an `[[expect]]` entry can write, by key, in the order they are read and
/// listed in messages.
pub const QUANTITIES: [&str; 7] = ["force", "torque", "lambda", "C_dot", "C_ddot", "A", "b"];

/// The quantities an entry with `at` can check: those the solve at a state gives numbers
/// for. Validation refuses the others there, and its message lists these.
pub const AT_STATE: [&str; 3] = ["force", "torque", "lambda"];

/// The `name = expected` entries of one quantity of an `[[expect]]`.
pub type Entries<'a> = BTreeMap<Text<'a>, Spanned<RawExpected<'a>>>;

/// One `[[expect]]` entry as written.
#[derive(Debug, Default)]
pub struct RawExpect<'a> {
    pub force: Entries<'a>,
    /// The constraint torque on a rigid body, by body.
    pub torque: Entries<'a>,
    pub lambda: Entries<'a>,
    /// `C_dot` in the file.
    pub c_dot: Entries<'a>,
    /// `C_ddot` in the file.
    pub c_ddot: Entries<'a>,
    /// `A` in the file.
    pub a: Entries<'a>,
    pub b: Entries<'a>,
    pub at: Option<Spanned<BTreeMap<Text<'a>, Spanned<RawValue>>>>,
    pub tolerance: Option<Spanned<f64>>,
    /// How many of the [`QUANTITIES`] the entry writes, read or not (an entry whose
    /// quantities were all unreadable is not also "checking nothing").
    pub written: usize,
    /// Free text, shown by `check` with each failure of the entry's checks.
    pub note: Option<String>,
}

/// An expected value as written: a formula, a number or a vector.
#[derive(Clone, Debug)]
pub enum RawExpected<'a> {
    Formula(Cow<'a, str>),
    Number(f64),
    Vector(Vec<f64>),
}
