//! Values for symbols, validated: the one place a written number or vector becomes a
//! [`Value`] of a symbol — for `[scene] initial`, `[[expect]] at`, `--at` state files
//! (TOML or JSON) and `--set NAME=VALUE`.
//!
//! [`value`] checks a [`RawValue`] against the symbol it is given to (known, not an
//! acceleration, scalar or vector of the file's dimension, finite); [`state_file`] and
//! [`assignment`] read the command line's forms of a state and check each entry the same
//! way, so a caller holds `(Symbol, Value)` pairs and never a raw value. Each entry comes
//! out [`Given`]: checked, its misfit kept rather than returned at once, so that a command
//! line's syntax errors are all reported before any value that does not fit (the order
//! `lagrange solve` has always reported them in).
//!
//! Not here: reading files (the caller passes the text), the scene's forces and the full
//! environment of a state (`model::scene::environment`).

use super::raw::RawValue;
use super::system::System;
use crate::expr::eval::Value;
use crate::expr::{Role, Symbol, Ty};
use std::collections::BTreeMap;

/// Why a value does not fit the symbol it is given to.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ValueError {
    #[error("`{name}` is not a symbol of this file{}", hint(.suggestion))]
    NotASymbol { name: String, suggestion: Option<String> },
    #[error("`{0}` is an acceleration: lagrange computes it, it cannot be given")]
    Acceleration(String),
    #[error("`{name}` is a vector of {dim} components, found {found} numbers")]
    Components { name: String, dim: usize, found: usize },
    #[error("`{0}` is a vector, found a number")]
    NumberForVector(String),
    #[error("`{0}` is a scalar, found a vector")]
    VectorForScalar(String),
    #[error("`{0}` must be finite")]
    NotFinite(String),
}

fn hint(suggestion: &Option<String>) -> String {
    suggestion.as_ref().map_or_else(String::new, |s| format!("; did you mean `{s}`?"))
}

/// The symbol `name` of `system` and `value` as a value of its type, or why not.
pub fn value(system: &System, name: &str, value: &RawValue) -> Result<(Symbol, Value), ValueError> {
    let dim = system.dim();
    let Some(s) = system.graph.symbol_named(name) else {
        let names = system.graph.symbols().map(|(_, info)| info.name.as_str());
        let suggestion = crate::expr::lower::suggest(name, names);
        return Err(ValueError::NotASymbol { name: name.to_string(), suggestion });
    };
    let info = system.graph.symbol(s);
    if matches!(info.role, Role::Acceleration { .. } | Role::AngularAcceleration { .. }) {
        return Err(ValueError::Acceleration(name.to_string()));
    }
    let v = match (info.ty, value) {
        (Ty::Scalar, RawValue::Number(x)) => Value::Scalar(*x),
        (Ty::Vector, RawValue::Vector(xs)) if xs.len() == dim => {
            let mut v = [0.0; 3];
            v[..dim].copy_from_slice(xs);
            Value::Vector(v)
        }
        (Ty::Vector, RawValue::Vector(xs)) => {
            return Err(ValueError::Components { name: name.to_string(), dim, found: xs.len() });
        }
        (Ty::Vector, RawValue::Number(_)) => return Err(ValueError::NumberForVector(name.to_string())),
        (Ty::Scalar, RawValue::Vector(_)) => return Err(ValueError::VectorForScalar(name.to_string())),
    };
    if !v.is_finite() {
        return Err(ValueError::NotFinite(name.to_string()));
    }
    Ok((s, v))
}

/// Every `(name, value)` of `entries` checked by [`value`], in order; the first misfit is
/// the error. (For programs that build a state by hand.)
pub fn values<S: AsRef<str>>(system: &System, entries: &[(S, RawValue)]) -> Result<Vec<(Symbol, Value)>, ValueError> {
    entries.iter().map(|(name, v)| value(system, name.as_ref(), v)).collect()
}

/// A value as the command line shows it: a number as Rust prints it, a vector as
/// `[x, y]` (its first `dim` components).
pub fn written(v: Value, dim: usize) -> String {
    match v {
        Value::Scalar(x) => x.to_string(),
        Value::Vector(_) => {
            format!("[{}]", v.components(dim).iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", "))
        }
    }
}

/// The language of a state file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Toml,
    Json,
}

impl Format {
    /// By the file's extension (`.toml`, `.json`), if it is one of those.
    pub fn of(path: &std::path::Path) -> Option<Format> {
        match path.extension().and_then(|e| e.to_str()) {
            Some("toml") => Some(Format::Toml),
            Some("json") => Some(Format::Json),
            _ => None,
        }
    }
}

/// Why a state given on the command line cannot be used.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StateInputError {
    /// The state file is not a flat TOML or JSON table of numbers and vectors (the
    /// parser's message, with its line).
    #[error("{0}")]
    Syntax(String),
    /// `--set` without `=`.
    #[error("expected NAME=VALUE, e.g. --set r=[1,0] or --set m=2")]
    NoEquals,
    /// `--set NAME=VALUE` whose VALUE is neither a number nor a vector.
    #[error("`{0}` is not a number or a vector [x, y]")]
    NotAValue(String),
    /// `--set NAME=VALUE` whose VALUE is not finite.
    #[error("`{0}` must be finite")]
    NotFinite(String),
}

/// One entry of a state given on the command line, checked against its symbol: the
/// symbol and its value, or why the value does not fit (said of the constraint file).
pub type Given = Result<(Symbol, Value), ValueError>;

/// The symbol values of a `--at` state file: a flat table `name = value`, in name order,
/// each checked by [`value`]; the file's syntax is the error.
pub fn state_file(system: &System, text: &str, format: Format) -> Result<Vec<Given>, StateInputError> {
    let table: BTreeMap<String, RawValue> = match format {
        Format::Toml => toml::from_str(text).map_err(|e| StateInputError::Syntax(e.to_string()))?,
        Format::Json => serde_json::from_str(text).map_err(|e| StateInputError::Syntax(e.to_string()))?,
    };
    Ok(table.iter().map(|(name, v)| value(system, name, v)).collect())
}

/// `NAME=VALUE` (`--set`), VALUE a finite number or a vector `[x, y]`, checked by [`value`];
/// the syntax is the error.
pub fn assignment(system: &System, arg: &str) -> Result<Given, StateInputError> {
    let Some((name, text)) = arg.split_once('=') else {
        return Err(StateInputError::NoEquals);
    };
    let (name, text) = (name.trim(), text.trim());
    let parsed = match text.parse::<f64>() {
        Ok(x) => RawValue::Number(x),
        Err(_) => serde_json::from_str::<RawValue>(text).map_err(|_| StateInputError::NotAValue(text.to_string()))?,
    };
    let finite = match &parsed {
        RawValue::Number(x) => x.is_finite(),
        RawValue::Vector(v) => v.iter().all(|x| x.is_finite()),
    };
    if !finite {
        return Err(StateInputError::NotFinite(name.to_string()));
    }
    Ok(value(system, name, &parsed))
}
