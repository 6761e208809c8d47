//! The `[scene]` table and the numbers of a state: what `solve` and `simulate` start from.
//!
//! `validate` resolves the raw `[scene]` (`model::raw::RawScene`) against a [`System`] into a
//! [`Scene`] (symbols, typed force expressions, timing), reporting every problem with its
//! span. [`environment`] then gives every symbol a number — parameters, the scene's initial
//! state, overrides (`--at`, `--set`, validated by `model::state`), masses, and the external forces evaluated last, since
//! they may depend on all the rest (`F = "m*g"`).
//!
//! Not here: the raw table (`model::raw`), checking a value against its symbol
//! (`model::state`), reading files, the derivation, solving.

use super::problem::{ForceError, Problem, line_of, locate, shown, subnormal_hint};
use super::raw::RawScene;
use super::state::value;
use super::system::{Body, BuildError, Rigid, System};
use crate::expr::eval::{Env, EvalError, Value, eval, eval_one};
use crate::expr::graph::{FastSet, NameMap};
use crate::expr::{Id, Role, Symbol, Ty};

/// A validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Values given in `initial`, by symbol.
    pub initial: Vec<(Symbol, Value)>,
    /// `(body, force expression)`; bodies not listed feel no external force.
    pub forces: Vec<(usize, Id)>,
    /// `(rigid body, torque expression)`, keyed in `forces` by the torque symbol
    /// (`T = "-c*w"`); rigid bodies not listed feel no external torque.
    pub torques: Vec<(usize, Id)>,
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
            torques: Vec::new(),
            dt: Scene::DEFAULT_DT,
            duration: Scene::DEFAULT_DURATION,
            restitution: 0.0,
        }
    }
}

/// What the bodies the builder refused write (reported once, at the refusal): a scene
/// entry naming one of these is not reported again as naming an unknown symbol or body.
#[derive(Default)]
pub(super) struct RefusedBodies<'t> {
    /// Every name a refused body writes: its own and its symbols'.
    pub names: Vec<&'t str>,
    /// The refused bodies' force symbols, for the list of force symbols a message shows.
    pub forces: Vec<&'t str>,
    /// The placeholder names standing in for symbols a body does not write readably (every
    /// body's, refused or not): left out of the names a message lists.
    pub placeholders: Vec<&'t str>,
}

/// Resolves a raw scene against `system`; every problem goes to `problems`.
///
/// An entry naming what a refused body writes (`refused`, reported where it was refused)
/// is left out without a second message.
pub(super) fn validate(
    text: &str,
    raw: &RawScene<'_>,
    system: &mut System,
    refused: &RefusedBodies<'_>,
    problems: &mut Vec<Problem>,
) -> Scene {
    let mut scene = Scene::default();
    for (name, v) in &raw.initial {
        match value(system, name.get_ref(), v.get_ref()) {
            Ok((s, v)) => scene.initial.push((s, v)),
            Err(_) if refused.names.contains(&name.get_ref().as_ref()) => {}
            Err(error) => problems.push(Problem::Value { span: name.span(), error }),
        }
    }
    // The first body a name denotes, as its name or its force symbol's, looked up by name
    // (a search per force made loading a chain of N links quadratic in N).
    let bodies: Vec<Option<usize>> = {
        let mut by_name: NameMap<&str, usize> = NameMap::default();
        if !raw.forces.is_empty() {
            for (i, b) in system.bodies.iter().enumerate() {
                by_name.entry(b.name.as_str()).or_insert(i);
                by_name.entry(system.graph.symbol(b.force).name.as_str()).or_insert(i);
            }
        }
        raw.forces.keys().map(|name| by_name.get(name.get_ref().as_ref()).copied()).collect()
    };
    // Forces written alike (`m*g` on every link of a chain) are one expression: parsed,
    // lowered and checked once (the same text in the same scope is the same node).
    let mut resolved: NameMap<&str, Result<Id, Refused>> = NameMap::default();
    // A rigid body's torque symbol names its torque (2D: a scalar expression, 3D a vector).
    let torque_of = |system: &System, name: &str| {
        system.bodies.iter().position(|b| b.rigid.as_ref().is_some_and(|r| system.graph.symbol(r.torque).name == name))
    };
    // A symbol given both a value in `initial` and an expression here would leave the
    // reader to guess which is used: one of them is an error, located at both.
    let given: NameMap<&str, std::ops::Range<usize>> = if raw.forces.is_empty() {
        NameMap::default()
    } else {
        raw.initial.keys().map(|k| (k.get_ref().as_ref(), k.span())).collect()
    };
    let given_twice = |span: std::ops::Range<usize>, what: &'static str, symbol: &str| {
        given.get(symbol).map(|initial| Problem::GivenTwice {
            line: line_of(text, span.start),
            initial_line: line_of(text, initial.start),
            span,
            initial: initial.clone(),
            what,
            name: symbol.to_string(),
        })
    };
    for ((name, expr), body) in raw.forces.iter().zip(bodies) {
        if body.is_none()
            && let Some(rigid) = torque_of(system, name.get_ref().as_ref())
        {
            problems.extend(given_twice(name.span(), "torque", name.get_ref().as_ref()));
            match torque_expression(system, expr.get_ref()) {
                Ok(id) => scene.torques.push((rigid, id)),
                Err((inner, error)) => {
                    let span = inner.map_or(expr.span(), |s| locate(text, expr, s));
                    problems.push(Problem::Torque { span, name: name.get_ref().to_string(), error })
                }
            }
            continue;
        }
        let Some(body) = body else {
            if refused.names.contains(&name.get_ref().as_ref()) {
                continue;
            }
            // The names the user wrote: a placeholder (a body without a readable `force`,
            // reported there) is not one; such a body is said to have none.
            let placeholder: FastSet<&str> = refused.placeholders.iter().copied().collect();
            let rigid = system.bodies.iter().filter_map(|b| b.rigid.as_ref()).map(|r| r.torque);
            let declared = system.bodies.iter().map(|b| b.force).chain(rigid);
            let declared = declared.map(|s| system.graph.symbol(s).name.as_str());
            let forces = declared
                .chain(refused.forces.iter().copied())
                .filter(|f| !placeholder.contains(f))
                .map(str::to_string)
                .collect();
            let without =
                system.bodies.iter().filter(|b| placeholder.contains(system.graph.symbol(b.force).name.as_str()));
            let without = without.map(|b| b.name.clone()).collect();
            problems.push(Problem::UnknownForce {
                span: name.span(),
                name: name.get_ref().to_string(),
                forces,
                without,
            });
            continue;
        };
        problems.extend(given_twice(name.span(), "force", &system.graph.symbol(system.bodies[body].force).name));
        let result =
            resolved.entry(expr.get_ref().as_ref()).or_insert_with(|| force_expression(system, expr.get_ref()));
        match result.clone() {
            Ok(id) => scene.forces.push((body, id)),
            Err((inner, error)) => {
                let span = inner.map_or(expr.span(), |s| locate(text, expr, s));
                problems.push(Problem::Force { span, name: name.get_ref().to_string(), error })
            }
        }
    }
    let mut positive =
        |value: &Option<toml::Spanned<f64>>, key: &'static str, default: f64, allow_zero: bool| match value {
            None => default,
            Some(x) if x.get_ref().is_finite() && (*x.get_ref() > 0.0 || (allow_zero && *x.get_ref() == 0.0)) => {
                *x.get_ref()
            }
            Some(x) => {
                let must = if allow_zero { "zero or positive" } else { "positive" };
                problems.push(Problem::SceneNumber { span: x.span(), key, must, value: *x.get_ref() });
                default
            }
        };
    scene.dt = positive(&raw.dt, "dt", Scene::DEFAULT_DT, false);
    scene.duration = positive(&raw.duration, "duration", Scene::DEFAULT_DURATION, true);
    scene.restitution = positive(&raw.restitution, "restitution", 0.0, true);
    if let Some(e) = &raw.restitution
        && *e.get_ref() > 1.0
    {
        problems.push(Problem::Restitution { span: e.span(), value: *e.get_ref() });
    }
    scene
}

/// Why a force expression was refused: where in its text (when known), and why.
type Refused = (Option<std::ops::Range<usize>>, ForceError);

/// Parses a force expression: a vector that may use positions, velocities, masses,
/// parameters and `t`, but not accelerations or forces (which it defines).
fn force_expression(system: &mut System, text: &str) -> Result<Id, Refused> {
    let id = system.expression(text).map_err(|e| {
        let span = match &e {
            BuildError::Parse { error, .. } => Some(error.span.start..error.span.end),
            BuildError::Lower { error, .. } => Some(error.span.start..error.span.end),
            _ => None,
        };
        (span, ForceError::Build(e))
    })?;
    if system.graph.ty(id) != Ty::Vector {
        return Err((None, ForceError::Scalar));
    }
    refuse_dependencies(system, id)?;
    Ok(id)
}

/// A force or torque may not depend on what the solve finds (accelerations) or on what the
/// scene defines (forces, torques).
fn refuse_dependencies(system: &System, id: Id) -> Result<(), Refused> {
    for s in system.graph.free_symbols(id) {
        let info = system.graph.symbol(s);
        if matches!(
            info.role,
            Role::Acceleration { .. } | Role::Force { .. } | Role::AngularAcceleration { .. } | Role::Torque { .. }
        ) {
            return Err((None, ForceError::Depends(info.name.clone())));
        }
    }
    Ok(())
}

/// Parses a rigid body's torque expression: a scalar in 2D, a vector (world frame) in 3D,
/// with the dependencies of a force.
fn torque_expression(system: &mut System, text: &str) -> Result<Id, Refused> {
    let id = system.expression(text).map_err(|e| {
        let span = match &e {
            BuildError::Parse { error, .. } => Some(error.span.start..error.span.end),
            BuildError::Lower { error, .. } => Some(error.span.start..error.span.end),
            _ => None,
        };
        (span, ForceError::Build(e))
    })?;
    match (system.dim(), system.graph.ty(id)) {
        (3, Ty::Scalar) => return Err((None, ForceError::ScalarTorque)),
        (3, _) | (_, Ty::Scalar) => {}
        _ => return Err((None, ForceError::Vector)),
    }
    refuse_dependencies(system, id)?;
    Ok(id)
}

/// Why a state could not be given numbers.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StateError {
    #[error("no value for `{0}`: give it in [parameters], [scene] initial, --at or --set")]
    Missing(String),
    #[error("the force on body `{body}` is not finite ({value:?}) at this state")]
    NonFiniteForce { body: String, value: [f64; 3] },
    #[error("a mass must be positive and finite: `{name}` = {}{}", shown(*.value), subnormal_hint(*.value))]
    Mass { name: String, value: f64 },
    #[error(
        "a moment of inertia must be positive and finite: body `{name}` has {}{}",
        shown(*.value),
        if *.value > 0.0 && !.value.is_normal() { " (a subnormal number: 1/I overflows)" } else { "" }
    )]
    Inertia { name: String, value: f64 },
    #[error("the force on body `{body}` cannot be evaluated: {error}")]
    Force { body: String, error: EvalError },
    #[error("the torque on body `{body}` is not finite ({value}) at this state")]
    NonFiniteTorque { body: String, value: f64 },
    #[error("the torque on body `{body}` cannot be evaluated: {error}")]
    Torque { body: String, error: EvalError },
}

/// The bodies' external force and torque symbols that [`environment`] takes as zero: given
/// no value (in the scene's `initial` or `overrides`) and no `[scene] forces` expression. In
/// body order, each body's force before its torque. The commands say so: a scene without
/// gravity is more often a slip than a choice.
pub fn unset_forces(system: &System, scene: &Scene, overrides: &[(Symbol, Value)]) -> Vec<Symbol> {
    // Sets, not a scan of the scene per body: a grid has thousands of each.
    let given: FastSet<Symbol> = scene.initial.iter().chain(overrides).map(|&(s, _)| s).collect();
    let forced: FastSet<usize> = scene.forces.iter().map(|&(b, _)| b).collect();
    let turned: FastSet<usize> = scene.torques.iter().map(|&(b, _)| b).collect();
    let mut unset = Vec::new();
    for (i, body) in system.bodies.iter().enumerate() {
        if !given.contains(&body.force) && !forced.contains(&i) {
            unset.push(body.force);
        }
        if let Some(rigid) = &body.rigid
            && !given.contains(&rigid.torque)
            && !turned.contains(&i)
        {
            unset.push(rigid.torque);
        }
    }
    unset
}

/// Per body, the value at `env` of its expression among `expressions` (`(body, expression)`,
/// the first one a body has) where the body's `symbol` (its force, its torque; `None`: the
/// body has none) has no value in `env` yet; all in one evaluation. The error names the
/// first body whose own expression fails.
fn per_body(
    system: &System,
    env: &Env,
    expressions: &[(usize, Id)],
    symbol: impl Fn(&Body) -> Option<Symbol>,
) -> Result<Vec<Option<Value>>, (String, EvalError)> {
    let mut expression: Vec<Option<Id>> = vec![None; system.bodies.len()];
    for &(i, id) in expressions {
        if let Some(slot) = expression.get_mut(i) {
            slot.get_or_insert(id);
        }
    }
    let wanted: Vec<(usize, Id)> = system
        .bodies
        .iter()
        .enumerate()
        .filter(|(_, b)| symbol(b).is_some_and(|s| env.get(s).is_none()))
        .filter_map(|(i, _)| expression[i].map(|id| (i, id)))
        .collect();
    let roots: Vec<Id> = wanted.iter().map(|&(_, id)| id).collect();
    let values = eval(&system.graph, &roots, env).map_err(|error| {
        let body = wanted
            .iter()
            .find(|&&(_, id)| eval_one(&system.graph, id, env).is_err())
            .map_or_else(String::new, |&(i, _)| system.bodies[i].name.clone());
        (body, error)
    })?;
    let mut computed: Vec<Option<Value>> = vec![None; system.bodies.len()];
    for (&(i, _), v) in wanted.iter().zip(values) {
        computed[i] = Some(v);
    }
    Ok(computed)
}

/// Numbers for every symbol of `system`: parameter values (`Loaded::values`), then the
/// scene's initial values, then `overrides` in order (later wins; validated by
/// `model::state`), then the external forces evaluated at that state
/// (a force symbol given directly keeps its value; forces the scene does not name are zero).
/// `t` defaults to 0. Every position, velocity, mass and parameter must end with a finite value.
/// A rigid body needs its orientation; its angular velocity defaults to 0, its torque is the
/// scene's torque expression (or 0) unless the state gives it, and its inertia must be
/// positive and finite.
pub fn environment(
    system: &System,
    parameters: &[(Symbol, Value)],
    scene: &Scene,
    overrides: &[(Symbol, Value)],
) -> Result<Env, StateError> {
    let mut env = Env::new();
    env.set(system.time, Value::Scalar(0.0));
    for &(s, v) in parameters.iter().chain(&scene.initial).chain(overrides) {
        env.set(s, v);
    }
    let missing = |s: Symbol| StateError::Missing(system.graph.symbol(s).name.clone());
    for &(_, s) in &system.parameters {
        env.get(s).ok_or_else(|| missing(s))?;
    }
    for body in &system.bodies {
        env.get(body.position).ok_or_else(|| missing(body.position))?;
        env.get(body.velocity).ok_or_else(|| missing(body.velocity))?;
        if let Some(rigid) = &body.rigid {
            env.get(rigid.orientation).ok_or_else(|| missing(rigid.orientation))?;
            let three = rigid.nodes.axes.is_some();
            if env.get(rigid.angular_velocity).is_none() {
                env.set(rigid.angular_velocity, if three { Value::Vector([0.0; 3]) } else { Value::Scalar(0.0) });
            }
        }
    }
    // Inertias, masses, forces and torques are evaluated in one pass each (an evaluation
    // walks the graph once, so one per body would cost bodies × graph size for a large scene).
    let rigid: Vec<(&Body, &Rigid)> = system.bodies.iter().filter_map(|b| Some((b, b.rigid.as_ref()?))).collect();
    let inertias: Vec<Id> = rigid.iter().map(|(_, r)| r.inertia).collect();
    let inertias =
        eval(&system.graph, &inertias, &env).map_err(|EvalError::Missing(name)| StateError::Missing(name))?;
    for ((body, rigid), inertia) in rigid.iter().zip(inertias) {
        // 2D: one moment; 3D: the three principal moments, each positive and finite.
        let moments = match inertia {
            Value::Scalar(x) if rigid.nodes.axes.is_none() => vec![x],
            Value::Vector(v) if rigid.nodes.axes.is_some() => v.to_vec(),
            _ => vec![f64::NAN],
        };
        if let Some(&bad) = moments.iter().find(|x| !(x.is_normal() && **x > 0.0)) {
            return Err(StateError::Inertia { name: body.name.clone(), value: bad });
        }
    }
    let masses: Vec<Id> = system.bodies.iter().map(|b| b.mass).collect();
    let masses = eval(&system.graph, &masses, &env).map_err(|EvalError::Missing(name)| StateError::Missing(name))?;
    for (body, m) in system.bodies.iter().zip(masses) {
        let m = m.scalar().unwrap_or(f64::NAN);
        // A subnormal mass (1e-320) is refused as a file's is: 1/m overflows.
        if !(m.is_normal() && m > 0.0) {
            return Err(StateError::Mass { name: body.name.clone(), value: m });
        }
    }
    let computed = per_body(system, &env, &scene.forces, |b| Some(b.force))
        .map_err(|(body, error)| StateError::Force { body, error })?;
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
    // Torques: the state's value, else the scene's expression at this state, else 0.
    let computed = per_body(system, &env, &scene.torques, |b| Some(b.rigid.as_ref()?.torque))
        .map_err(|(body, error)| StateError::Torque { body, error })?;
    for (body, computed) in system.bodies.iter().zip(computed) {
        let Some(rigid) = &body.rigid else { continue };
        if env.get(rigid.torque).is_some() {
            continue;
        }
        let three = rigid.nodes.axes.is_some();
        let value = match computed {
            Some(value) => value,
            None if three => Value::Vector([0.0; 3]),
            None => Value::Scalar(0.0),
        };
        // 3D torques are vectors; the largest non-finite component is the one reported.
        let shown = match value {
            Value::Scalar(x) => x,
            Value::Vector(v) => v.into_iter().find(|x| !x.is_finite()).unwrap_or(0.0),
            Value::Quaternion(_) => f64::NAN,
        };
        if !value.is_finite() || matches!(value, Value::Quaternion(_)) {
            return Err(StateError::NonFiniteTorque { body: body.name.clone(), value: shown });
        }
        env.set(rigid.torque, value);
    }
    Ok(env)
}
