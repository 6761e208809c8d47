//! Values for symbols, validated: the one place a written number or vector becomes a
//! [`Value`] of a symbol — for `[scene] initial`, `[[expect]] at`, `--at` state files
//! (TOML or JSON) and `--set NAME=VALUE`.
//!
//! [`value`] checks a [`RawValue`] against the symbol it is given to (known, not an
//! acceleration, scalar or vector of the file's dimension, finite; a 3D orientation is a
//! quaternion of four numbers with unit norm within [`QUATERNION_TOLERANCE`], since `rot`
//! does not normalise, else an error naming the body); [`state_file`] and
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
    /// A 3D orientation given as other than four numbers.
    #[error("`{name}` is the orientation of body `{body}`, a unit quaternion [w, x, y, z]: found {found}")]
    QuaternionShape { name: String, body: String, found: String },
    /// A 3D orientation whose quaternion is not unit: `rot` does not normalise.
    #[error(
        "`{name}`, the orientation of body `{body}`, is not a unit quaternion: its norm is {norm} (it must be 1 within {QUATERNION_TOLERANCE:e}; `rot` does not normalise)"
    )]
    NonUnitQuaternion { name: String, body: String, norm: f64 },
}

/// How far from 1 a state's quaternion norm may be (relative: the norm is 1).
pub const QUATERNION_TOLERANCE: f64 = 1e-12;

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
    if let Role::Orientation { body } = info.role
        && system.graph.is_quaternion(s)
    {
        return quaternion(name, &system.bodies[body].name, value).map(|q| (s, q));
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

/// A 3D orientation's value: four finite numbers of norm 1 (within [`QUATERNION_TOLERANCE`]).
fn quaternion(name: &str, body: &str, value: &RawValue) -> Result<Value, ValueError> {
    let shape = |found: String| ValueError::QuaternionShape { name: name.to_string(), body: body.to_string(), found };
    let q: [f64; 4] = match value {
        RawValue::Vector(xs) => xs[..].try_into().map_err(|_| shape(format!("{} numbers", xs.len())))?,
        RawValue::Number(_) => return Err(shape("a number".to_string())),
    };
    if !q.iter().all(|x| x.is_finite()) {
        return Err(ValueError::NotFinite(name.to_string()));
    }
    let norm = crate::expr::eval::norm(q);
    if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
        return Err(ValueError::NonUnitQuaternion { name: name.to_string(), body: body.to_string(), norm });
    }
    Ok(Value::Quaternion(q))
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
        Value::Vector(_) | Value::Quaternion(_) => {
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
    /// The state file is not TOML or JSON (the parser's message, with its line), or a
    /// JSON key is written twice (serde_json's message, naming the key and its line).
    #[error("{0}")]
    Syntax(String),
    /// An entry of a state file that is not a number or a vector of numbers.
    #[error("`{key}` must be a number or a vector of numbers, found {found}{}", table_hint(.found))]
    NotANumber { key: String, found: &'static str },
    /// A vector entry of a state file with a component that is not a number.
    #[error("component {index} of `{key}` must be a number, found {found}")]
    NotAComponent { key: String, index: usize, found: &'static str },
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

fn table_hint(found: &str) -> &'static str {
    if found == "a table" || found == "an array of tables" {
        " (a state file is one flat table `name = value`, e.g. `r = [1.0, 0.0]`; is this a constraint file?)"
    } else {
        ""
    }
}

/// One entry of a state given on the command line, checked against its symbol: the
/// symbol and its value, or why the value does not fit (said of the constraint file).
pub type Given = Result<(Symbol, Value), ValueError>;

/// The symbol values of a `--at` state file: a flat table `name = value`, in name order,
/// each checked by [`value`]; the file's syntax, a key written twice, or an entry that is
/// not a number or a vector of numbers (named) is the error.
pub fn state_file(system: &System, text: &str, format: Format) -> Result<Vec<Given>, StateInputError> {
    let mut table: Vec<(String, RawValue)> = match format {
        Format::Toml => {
            let t: toml::Table = toml::from_str(text).map_err(|e| StateInputError::Syntax(e.to_string()))?;
            t.into_iter().map(|(k, v)| Ok((k.clone(), toml_value(&k, &v)?))).collect::<Result<_, _>>()?
        }
        Format::Json => {
            let Entries(entries) = serde_json::from_str(text).map_err(|e| StateInputError::Syntax(e.to_string()))?;
            entries.into_iter().map(|(k, v)| Ok((k.clone(), json_value(&k, &v)?))).collect::<Result<_, _>>()?
        }
    };
    table.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(table.iter().map(|(name, v)| value(system, name, v)).collect())
}

fn toml_kind(v: &toml::Value) -> &'static str {
    match v {
        toml::Value::String(_) => "a string",
        toml::Value::Integer(_) | toml::Value::Float(_) => "a number",
        toml::Value::Boolean(_) => "a boolean",
        toml::Value::Datetime(_) => "a date",
        toml::Value::Array(_) => "an array",
        toml::Value::Table(_) => "a table",
    }
}

fn toml_number(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(x) => Some(*x),
        _ => None,
    }
}

fn toml_value(key: &str, v: &toml::Value) -> Result<RawValue, StateInputError> {
    if let Some(x) = toml_number(v) {
        return Ok(RawValue::Number(x));
    }
    let toml::Value::Array(xs) = v else {
        return Err(StateInputError::NotANumber { key: key.to_string(), found: toml_kind(v) });
    };
    if xs.iter().any(toml::Value::is_table) {
        return Err(StateInputError::NotANumber { key: key.to_string(), found: "an array of tables" });
    }
    let component = |(i, x): (usize, &toml::Value)| {
        toml_number(x).ok_or(StateInputError::NotAComponent { key: key.to_string(), index: i + 1, found: toml_kind(x) })
    };
    Ok(RawValue::Vector(xs.iter().enumerate().map(component).collect::<Result<_, _>>()?))
}

fn json_kind(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::Object(_) => "a table",
    }
}

fn json_value(key: &str, v: &serde_json::Value) -> Result<RawValue, StateInputError> {
    if let Some(x) = v.as_f64() {
        return Ok(RawValue::Number(x));
    }
    let serde_json::Value::Array(xs) = v else {
        return Err(StateInputError::NotANumber { key: key.to_string(), found: json_kind(v) });
    };
    if xs.iter().any(serde_json::Value::is_object) {
        return Err(StateInputError::NotANumber { key: key.to_string(), found: "an array of tables" });
    }
    let component = |(i, x): (usize, &serde_json::Value)| {
        x.as_f64().ok_or(StateInputError::NotAComponent { key: key.to_string(), index: i + 1, found: json_kind(x) })
    };
    Ok(RawValue::Vector(xs.iter().enumerate().map(component).collect::<Result<_, _>>()?))
}

/// A JSON object's entries in the order written, refusing a key written twice (a map
/// would keep the last value without a word).
struct Entries(Vec<(String, serde_json::Value)>);

impl<'de> serde::Deserialize<'de> for Entries {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Entries;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a table of symbols' values, e.g. {\"r\": [1.0, 0.0]}")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<Entries, A::Error> {
                let mut seen = std::collections::HashSet::new();
                let mut out = Vec::new();
                while let Some((k, v)) = map.next_entry::<String, serde_json::Value>()? {
                    if !seen.insert(k.clone()) {
                        return Err(serde::de::Error::custom(format!("duplicate key `{k}`")));
                    }
                    out.push((k, v));
                }
                Ok(Entries(out))
            }
        }
        d.deserialize_map(Visitor)
    }
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
