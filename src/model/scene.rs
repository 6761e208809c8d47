//! The `[scene]` table and the numbers of a state: what `solve` and `simulate` start from.
//!
//! [`RawScene`] mirrors the TOML; [`validate`] resolves it against a [`System`] into a
//! [`Scene`] (symbols, typed force expressions, timing), reporting every problem with its
//! span. [`environment`] then gives every symbol a number — parameters, the scene's initial
//! state, overrides (`--at`, `--set`), masses, and the external forces evaluated last, since
//! they may depend on all the rest (`F = "m*g"`).
//!
//! Not here: reading files, the derivation, solving.

use super::file::{Problem, RawValue, Text, locate};
use super::system::{BuildError, System};
use crate::expr::eval::{Env, EvalError, Value, eval, eval_one};
use crate::expr::graph::NameMap;
use crate::expr::{Id, Role, Symbol, Ty};
use std::collections::BTreeMap;
use toml::Spanned;

/// The `[scene]` table as written (read by `model::document`; unknown keys are reported
/// by `model::keys`).
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

/// A validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Values given in `initial`, by symbol.
    pub initial: Vec<(Symbol, Value)>,
    /// `(body, force expression)`; bodies not listed feel no external force.
    pub forces: Vec<(usize, Id)>,
    pub dt: f64,
    pub duration: f64,
    pub restitution: f64,
}

impl Scene {
    pub const DEFAULT_DT: f64 = 1e-3;
    pub const DEFAULT_DURATION: f64 = 1.0;
}

impl Default for Scene {
    fn default() -> Scene {
        Scene {
            initial: Vec::new(),
            forces: Vec::new(),
            dt: Scene::DEFAULT_DT,
            duration: Scene::DEFAULT_DURATION,
            restitution: 0.0,
        }
    }
}

/// Resolves a raw scene against `system`; every problem goes to `problems`.
pub fn validate(text: &str, raw: &RawScene<'_>, system: &mut System, problems: &mut Vec<Problem>) -> Scene {
    let mut scene = Scene::default();
    scene.initial.reserve(raw.initial.len());
    scene.forces.reserve(raw.forces.len());
    let dim = system.dim();
    for (name, value) in &raw.initial {
        match value_for(system, name.get_ref(), value.get_ref(), dim) {
            Ok((s, v)) => scene.initial.push((s, v)),
            Err(message) => problems.push(Problem { span: Some(name.span()), message }),
        }
    }
    // The first body a name denotes, as its name or its force symbol's, looked up by name
    // (a search per force made loading a chain of N links quadratic in N).
    let bodies: Vec<Option<usize>> = {
        let mut by_name: NameMap<&str, usize> = NameMap::default();
        if !raw.forces.is_empty() {
            by_name.reserve(2 * system.bodies.len());
            for (i, b) in system.bodies.iter().enumerate() {
                by_name.entry(b.name.as_str()).or_insert(i);
                by_name.entry(system.graph.symbol(b.force).name.as_str()).or_insert(i);
            }
        }
        raw.forces.keys().map(|name| by_name.get(name.get_ref().as_ref()).copied()).collect()
    };
    // Forces written alike (`m*g` on every link of a chain) are one expression: parsed,
    // lowered and checked once (the same text in the same scope is the same node).
    let mut resolved: NameMap<&str, Result<Id, ForceError>> = NameMap::default();
    for ((name, expr), body) in raw.forces.iter().zip(bodies) {
        let Some(body) = body else {
            let forces: Vec<&str> = system.bodies.iter().map(|b| system.graph.symbol(b.force).name.as_str()).collect();
            let known = if forces.is_empty() {
                "the file declares no bodies".to_string()
            } else {
                format!("force symbols: {}", forces.join(", "))
            };
            problems.push(Problem {
                span: Some(name.span()),
                message: format!("`{}` is not a body's force symbol or a body's name ({known})", name.get_ref()),
            });
            continue;
        };
        let result =
            resolved.entry(expr.get_ref().as_ref()).or_insert_with(|| force_expression(system, expr.get_ref()));
        match result.clone() {
            Ok(id) => scene.forces.push((body, id)),
            Err((inner, message)) => {
                let span = inner.map_or(expr.span(), |s| locate(text, expr, s));
                problems.push(Problem {
                    span: Some(span),
                    message: format!("in the force on `{}`: {message}", name.get_ref()),
                })
            }
        }
    }
    let mut positive = |value: &Option<Spanned<f64>>, what: &str, default: f64, allow_zero: bool| match value {
        None => default,
        Some(x) if x.get_ref().is_finite() && (*x.get_ref() > 0.0 || (allow_zero && *x.get_ref() == 0.0)) => {
            *x.get_ref()
        }
        Some(x) => {
            let must = if allow_zero { "zero or positive" } else { "positive" };
            problems.push(Problem {
                span: Some(x.span()),
                message: format!("`{what}` must be a finite {must} number, found {}", x.get_ref()),
            });
            default
        }
    };
    scene.dt = positive(&raw.dt, "dt", Scene::DEFAULT_DT, false);
    scene.duration = positive(&raw.duration, "duration", Scene::DEFAULT_DURATION, true);
    scene.restitution = positive(&raw.restitution, "restitution", 0.0, true);
    if let Some(e) = &raw.restitution
        && *e.get_ref() > 1.0
    {
        problems.push(Problem {
            span: Some(e.span()),
            message: format!("`restitution` must lie in [0, 1], found {}", e.get_ref()),
        });
    }
    scene
}

/// Why a force expression was refused: where in its text (when known), and the message.
type ForceError = (Option<std::ops::Range<usize>>, String);

/// Parses a force expression: a vector that may use positions, velocities, masses,
/// parameters and `t`, but not accelerations or forces (which it defines).
fn force_expression(system: &mut System, text: &str) -> Result<Id, ForceError> {
    let id = system.expression(text).map_err(|e| {
        let span = match &e {
            BuildError::Parse { error, .. } => Some(error.span.start..error.span.end),
            BuildError::Lower { error, .. } => Some(error.span.start..error.span.end),
            _ => None,
        };
        (span, e.to_string())
    })?;
    if system.graph.ty(id) != Ty::Vector {
        return Err((None, "a force must be a vector, found a scalar".into()));
    }
    for s in system.graph.free_symbols(id) {
        let info = system.graph.symbol(s);
        if matches!(info.role, Role::Acceleration { .. } | Role::Force { .. }) {
            return Err((None, format!("a force may not depend on `{}` (an acceleration or a force)", info.name)));
        }
    }
    Ok(id)
}

/// The symbol `name` and `value` as a value of its type, or why not.
pub fn value_for(system: &System, name: &str, value: &RawValue, dim: usize) -> Result<(Symbol, Value), String> {
    let Some(s) = system.graph.symbol_named(name) else {
        let names = system.graph.symbols().map(|(_, info)| info.name.as_str());
        let hint = crate::expr::lower::suggest(name, names);
        return Err(match hint {
            Some(hint) => format!("`{name}` is not a symbol of this file; did you mean `{hint}`?"),
            None => format!("`{name}` is not a symbol of this file"),
        });
    };
    let info = system.graph.symbol(s);
    if matches!(info.role, Role::Acceleration { .. }) {
        return Err(format!("`{name}` is an acceleration: lagrange computes it, it cannot be given"));
    }
    let v = match (info.ty, value) {
        (Ty::Scalar, RawValue::Number(x)) => Value::Scalar(*x),
        (Ty::Vector, RawValue::Vector(xs)) if xs.len() == dim => {
            let mut v = [0.0; 3];
            v[..dim].copy_from_slice(xs);
            Value::Vector(v)
        }
        (Ty::Vector, RawValue::Vector(xs)) => {
            return Err(format!("`{name}` is a vector of {dim} components, found {} numbers", xs.len()));
        }
        (Ty::Vector, RawValue::Number(_)) => return Err(format!("`{name}` is a vector, found a number")),
        (Ty::Scalar, RawValue::Vector(_)) => return Err(format!("`{name}` is a scalar, found a vector")),
    };
    if !v.is_finite() {
        return Err(format!("`{name}` must be finite"));
    }
    Ok((s, v))
}

/// Why a state could not be given numbers.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StateError {
    #[error("no value for `{0}`: give it in [parameters], [scene] initial, --at or --set")]
    Missing(String),
    #[error("{0}")]
    Value(String),
    #[error("the force on body `{body}` is not finite ({value:?}) at this state")]
    NonFiniteForce { body: String, value: [f64; 3] },
    #[error("a mass must be positive and finite: `{name}` = {value}")]
    Mass { name: String, value: f64 },
    #[error("the force on body `{body}` cannot be evaluated: {error}")]
    Force { body: String, error: EvalError },
}

/// Numbers for every symbol of `system`: parameter values, then the scene's initial values,
/// then `overrides` in order (later wins), then the external forces evaluated at that state
/// (a force symbol given directly keeps its value; forces the scene does not name are zero).
/// `t` defaults to 0. Every position, velocity, mass and parameter must end with a finite value.
pub fn environment(
    system: &System,
    parameters: &BTreeMap<String, RawValue>,
    scene: &Scene,
    overrides: &[(String, RawValue)],
) -> Result<Env, StateError> {
    let dim = system.dim();
    let mut env = Env::new();
    env.set(system.time, Value::Scalar(0.0));
    for (name, value) in parameters {
        let (s, v) = value_for(system, name, value, dim).map_err(StateError::Value)?;
        env.set(s, v);
    }
    for &(s, v) in &scene.initial {
        env.set(s, v);
    }
    for (name, value) in overrides {
        let (s, v) = value_for(system, name, value, dim).map_err(StateError::Value)?;
        env.set(s, v);
    }
    let missing = |s: Symbol| StateError::Missing(system.graph.symbol(s).name.clone());
    for &(_, s) in &system.parameters {
        env.get(s).ok_or_else(|| missing(s))?;
    }
    for body in &system.bodies {
        env.get(body.position).ok_or_else(|| missing(body.position))?;
        env.get(body.velocity).ok_or_else(|| missing(body.velocity))?;
    }
    // Masses and forces are evaluated in one pass each (an evaluation walks the graph once,
    // so one per body would cost bodies × graph size for a large scene).
    let masses: Vec<Id> = system.bodies.iter().map(|b| b.mass).collect();
    let masses = eval(&system.graph, &masses, &env).map_err(|EvalError::Missing(name)| StateError::Missing(name))?;
    for (body, m) in system.bodies.iter().zip(masses) {
        let m = m.scalar().unwrap_or(f64::NAN);
        if !(m.is_finite() && m > 0.0) {
            return Err(StateError::Mass { name: body.name.clone(), value: m });
        }
    }
    let mut expression: Vec<Option<Id>> = vec![None; system.bodies.len()];
    for &(i, id) in &scene.forces {
        if let Some(slot) = expression.get_mut(i) {
            slot.get_or_insert(id);
        }
    }
    let wanted: Vec<(usize, Id)> = (0..system.bodies.len())
        .filter(|&i| env.get(system.bodies[i].force).is_none())
        .filter_map(|i| expression[i].map(|id| (i, id)))
        .collect();
    let roots: Vec<Id> = wanted.iter().map(|&(_, id)| id).collect();
    let values = eval(&system.graph, &roots, &env).map_err(|error| {
        // Name the body: the first whose own expression fails.
        let body = wanted
            .iter()
            .find(|&&(_, id)| eval_one(&system.graph, id, &env).is_err())
            .map_or_else(String::new, |&(i, _)| system.bodies[i].name.clone());
        StateError::Force { body, error }
    })?;
    let mut computed: Vec<Option<Value>> = vec![None; system.bodies.len()];
    for (&(i, _), v) in wanted.iter().zip(values) {
        computed[i] = Some(v);
    }
    let mut forces = Vec::new();
    for (i, body) in system.bodies.iter().enumerate() {
        if env.get(body.force).is_some() {
            continue;
        }
        let value = computed[i].unwrap_or(Value::Vector([0.0; 3]));
        let v = value.vector().unwrap_or([f64::NAN; 3]);
        if !value.is_finite() {
            return Err(StateError::NonFiniteForce { body: body.name.clone(), value: v });
        }
        forces.push((body.force, Value::Vector(v)));
    }
    for (s, v) in forces {
        env.set(s, v);
    }
    Ok(env)
}
