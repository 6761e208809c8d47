//! Constraint definition files (TOML, DESIGN.md): validation of the raw file into the model.
//!
//! [`load`] reads the text into a [`RawFile`] (`model::document`) and validates it into a
//! [`System`], the parameters' values, the scene and the expectations ([`Loaded`]). Only
//! validation builds the model: nothing in a [`Loaded`] is raw. Every problem carries a
//! byte span into the file text, so messages point at the fault. `[definitions]` are
//! ordered by Kahn's algorithm (linear, no recursion), cycles reported once.
//!
//! Not here: the raw types (`model::raw`), printing or rendering messages (the caller
//! renders [`Problem`]s).

use super::document::read;
use super::expect::{Expectation, resolve};
pub use super::problem::Problem;
use super::problem::{locate, shown, sort};
use super::raw::{RawBody, RawFile, RawMass, RawRigid, RawValue, Text};
use super::scene::{RefusedBodies, Scene, validate};
use super::system::{BodySpec, BuildError, MassSpec, RigidSpec, System, SystemBuilder};
use crate::expr::eval::Value;
use crate::expr::lower::LowerError;
use crate::expr::parse::ParseError;
use crate::expr::syntax::{Syntax, SyntaxKind};
use crate::expr::{Symbol, Ty};
use std::collections::{HashMap, HashSet};
use std::ops::Range;

/// The largest constraint file read, in bytes (64 MiB): a scene of 10⁵ bodies fits with
/// room to spare (the 100 000-link chain's file is 27 MB; 16 MiB stopped at about 62 000
/// links), while a file that is not a constraint file (or is hostile) is refused before
/// its text is parsed or held in a tree.
pub const MAX_FILE_BYTES: usize = 64 << 20;

/// A validated file: the system, the parameter values, the scene and the expectations.
/// (The raw file is not kept: it borrows the text, and all it said is in these.)
#[derive(Debug)]
pub struct Loaded {
    pub system: System,
    /// The `[parameters]` values, by symbol, in name order.
    pub values: Vec<(Symbol, Value)>,
    pub scene: Scene,
    pub expect: Vec<Expectation>,
}

/// Parses and validates a constraint file's text. Every problem found is returned.
pub fn load(text: &str) -> Result<Loaded, Vec<Problem>> {
    if text.len() > MAX_FILE_BYTES {
        return Err(vec![Problem::TooLarge { bytes: text.len(), limit: MAX_FILE_BYTES }]);
    }
    let mut problems = Vec::new();
    let Some(raw) = read(text, &mut problems) else {
        sort(&mut problems);
        return Err(problems);
    };
    let mut refused = RefusedBodies::default();
    let Some(mut system) = build(text, &raw, &mut refused, &mut problems) else {
        sort(&mut problems);
        return Err(problems);
    };
    let scene = match &raw.scene {
        Some(s) => validate(text, s.get_ref(), &mut system, &refused, &mut problems),
        None => Scene::default(),
    };
    // Names the file writes, valid or not: an expectation naming a body or constraint that
    // was refused (and reported) is left out, not reported again as naming an unknown one.
    let written: Vec<&str> = raw
        .bodies
        .iter()
        .map(|b| b.get_ref().name.get_ref().as_ref())
        .chain(raw.constraints.iter().map(|c| c.get_ref().name.get_ref().as_ref()))
        .collect();
    let expect = resolve(text, &raw.expect, &written, &mut system, &mut problems);
    let values = parameter_values(&raw, &system);
    masses_are_positive(text, &raw, &system, &mut problems);
    masses_have_values(&raw, &system, &scene, &expect, &mut problems);
    if !problems.is_empty() {
        sort(&mut problems);
        return Err(problems);
    }
    Ok(Loaded { system, values, scene, expect })
}

/// The parameters' values, by symbol: each was checked against its symbol when declared,
/// so only a parameter the builder refused (reported) has none.
fn parameter_values(raw: &RawFile<'_>, system: &System) -> Vec<(Symbol, Value)> {
    raw.parameters
        .iter()
        .filter_map(|(name, v)| super::state::value(system, name.get_ref(), v.get_ref()).ok())
        .collect()
}

/// A mass symbol's value, written in `[parameters]` or `[scene] initial`, is a positive normal
/// number: located at the value, so `derive` refuses `m = 0.0` as `solve` would.
///
/// Only numbers written as numbers are judged: a value of the wrong type (reported, held as
/// a placeholder) or not finite (reported) is not reported again.
fn masses_are_positive(text: &str, raw: &RawFile<'_>, system: &System, problems: &mut Vec<Problem>) {
    let mut seen = HashSet::new();
    for body in &system.bodies {
        let crate::expr::Node::Sym(s) = system.graph.node(body.mass) else {
            continue;
        };
        if !seen.insert(*s) {
            continue;
        }
        let name = system.graph.symbol(*s).name.as_str();
        let initial = raw.scene.as_ref().and_then(|sc| sc.get_ref().initial.get(name));
        for v in raw.parameters.get(name).into_iter().chain(initial) {
            let written = text.get(v.span()).is_some_and(|t| t.trim().replace('_', "").parse::<f64>().is_ok());
            if let RawValue::Number(x) = v.get_ref()
                && written
                && x.is_finite()
                && !(x.is_normal() && *x > 0.0)
            {
                problems.push(Problem::MassValue {
                    span: v.span(),
                    name: name.to_string(),
                    body: body.name.clone(),
                    shown: shown(*x),
                });
            }
        }
    }
}

/// A mass symbol that is not a parameter needs a value wherever numbers are computed: from
/// `[scene] initial` when the file has a scene, and from each `at` state of an `[[expect]]`.
/// (Formula checks draw random masses, so they need none.)
fn masses_have_values(
    raw: &RawFile<'_>,
    system: &System,
    scene: &Scene,
    expect: &[Expectation],
    problems: &mut Vec<Problem>,
) {
    // Raw bodies by name and the initial values' symbols, looked up rather than searched
    // per body (quadratic in a long chain); built at the first mass symbol, as most files
    // have none (a parameter or a number is a mass's value).
    let mut lookup: Option<(HashMap<&str, usize>, HashSet<Symbol>)> = None;
    for body in &system.bodies {
        let crate::expr::Node::Sym(s) = system.graph.node(body.mass) else {
            continue;
        };
        if !matches!(system.graph.symbol(*s).role, crate::expr::Role::Mass { .. }) {
            continue;
        }
        let (raw_bodies, initial) = lookup.get_or_insert_with(|| {
            let mut raw_bodies = HashMap::new();
            for (i, b) in raw.bodies.iter().enumerate() {
                raw_bodies.entry(b.get_ref().name.get_ref().as_ref()).or_insert(i);
            }
            (raw_bodies, scene.initial.iter().map(|(x, _)| *x).collect())
        });
        let Some(&raw_body) = raw_bodies.get(body.name.as_str()) else {
            continue;
        };
        let raw_body = &raw.bodies[raw_body];
        let name = &system.graph.symbol(*s).name;
        let span = raw_body.get_ref().mass.span();
        if raw.scene.is_some() && !initial.contains(s) {
            problems.push(Problem::MassWithoutValue { span: span.clone(), name: name.clone() });
        }
        for e in expect {
            if let Some(at) = &e.at
                && !at.iter().any(|(x, _)| x == s)
            {
                problems.push(Problem::MassWithoutValueAt { span: e.span.clone(), name: name.clone() });
            }
        }
    }
}

fn build<'t>(
    text: &str,
    raw: &'t RawFile<'_>,
    refused: &mut RefusedBodies<'t>,
    problems: &mut Vec<Problem>,
) -> Option<System> {
    let title = raw.title.as_ref().map_or("", |t| t.get_ref().as_ref());
    let dimension = raw.dimension.as_ref()?;
    let mut b = match SystemBuilder::new(title, *dimension.get_ref()) {
        Ok(b) => b,
        Err(e) => {
            problems.push(Problem::Build { span: dimension.span(), error: e });
            return None;
        }
    };
    let dim = *dimension.get_ref() as usize;
    for (name, value) in &raw.parameters {
        let ty = match value.get_ref() {
            RawValue::Number(_) => Ty::Scalar,
            RawValue::Vector(v) if v.len() == dim => Ty::Vector,
            RawValue::Vector(v) => {
                problems.push(Problem::ParameterComponents {
                    span: value.span(),
                    name: name.get_ref().to_string(),
                    found: v.len(),
                    dim,
                });
                continue;
            }
        };
        if let Err(e) = b.parameter(name.get_ref(), ty) {
            problems.push(Problem::Build { span: name.span(), error: e });
        }
    }
    for body in &raw.bodies {
        let body = body.get_ref();
        let mass = match body.mass.get_ref() {
            // A subnormal mass (5e-324) makes 1/m infinite: refused with zero and negatives.
            RawMass::Number(x) if x.is_normal() && *x > 0.0 => MassSpec::Number(*x),
            RawMass::Number(x) => {
                problems.push(Problem::Mass { span: body.mass.span(), shown: shown(*x) });
                // Declared all the same, so the body's symbols are known where used.
                MassSpec::Number(1.0)
            }
            // `mass = "0.5"`: a number in quotes, not a name.
            RawMass::Symbol(s) if s.trim().parse::<f64>().is_ok() => {
                problems.push(Problem::QuotedMass { span: body.mass.span(), written: s.to_string() });
                MassSpec::Number(1.0)
            }
            RawMass::Symbol(s) => MassSpec::Symbol(s),
            RawMass::Vector(_) => {
                problems.push(Problem::VectorMass { span: body.mass.span() });
                MassSpec::Number(1.0)
            }
        };
        let spec = BodySpec {
            name: body.name.get_ref(),
            position: body.position.get_ref(),
            velocity: body.velocity.get_ref(),
            acceleration: body.acceleration.get_ref(),
            force: body.force.get_ref(),
            mass,
        };
        refused.placeholders.extend(body.placeholders.iter().map(String::as_str));
        let declared = b.body(&spec);
        if let (Ok(index), Some(rigid)) = (&declared, &body.rigid) {
            declare_rigid(&mut b, *index, body, rigid, problems);
        }
        if let Err(e) = declared {
            // Point at the field whose symbol is refused, not just at the body: the last
            // field that writes it (`velocity = "r"` after `position = "r"` is the clash).
            let named = match &e {
                BuildError::Duplicate { name, .. } | BuildError::BadName(name) | BuildError::Reserved(name) => {
                    Some(name.as_str())
                }
                _ => None,
            };
            let fields = [&body.position, &body.velocity, &body.acceleration, &body.force];
            let span = match (named, body.mass.get_ref()) {
                (Some(n), RawMass::Symbol(m)) if m.as_ref() == n => body.mass.span(),
                (Some(n), _) => fields
                    .into_iter()
                    .rfind(|f| f.get_ref().as_ref() == n)
                    .map_or_else(|| body.name.span(), |f| f.span()),
                (None, _) => body.name.span(),
            };
            // Everything the body writes: its later uses are not reported again.
            refused.names.extend(fields.iter().map(|f| f.get_ref().as_ref()));
            refused.names.push(body.name.get_ref().as_ref());
            if let RawMass::Symbol(m) = body.mass.get_ref() {
                refused.names.push(m.as_ref());
            }
            refused.forces.push(body.force.get_ref().as_ref());
            problems.push(Problem::Build { span, error: e });
        }
    }
    for (name, def_text) in definitions_in_order(raw, problems) {
        if let Err(e) = b.definition(name.get_ref(), def_text.get_ref()) {
            problems.push(build_problem(text, def_text, &e, name.span()));
        }
    }
    for c in &raw.constraints {
        let c = c.get_ref();
        // Without an expression (reported) the constraint is only a name, for `[[expect]]`.
        let Some(expr) = &c.expr else {
            continue;
        };
        if let Err(e) = b.constraint(c.name.get_ref(), expr.get_ref()) {
            problems.push(build_problem(text, expr, &e, c.name.span()));
        }
    }
    // `[[constraint]]` is reported as an unknown key with its "did you mean": not again here.
    let misspelt =
        problems.iter().any(|p| matches!(p, Problem::UnknownKey { suggestion: Some(s), .. } if s == "constraints"));
    if raw.constraints.is_empty() && !raw.constraints_written && !misspelt {
        problems.push(Problem::NoConstraints);
    }
    Some(b.finish())
}

/// The rotational part of a rigid body: its inertia judged (present, positive and finite
/// when a number) and its symbols declared, problems located at their fields.
fn declare_rigid(
    b: &mut SystemBuilder,
    index: usize,
    body: &RawBody<'_>,
    rigid: &RawRigid<'_>,
    problems: &mut Vec<Problem>,
) {
    let inertia = match rigid.inertia.as_ref().map(|i| (i.get_ref(), i.span())) {
        None => {
            problems.push(Problem::NoInertia { span: rigid.orientation.span(), body: body.name.get_ref().to_string() });
            MassSpec::Number(1.0)
        }
        Some((RawMass::Number(x), _)) if x.is_finite() && *x > 0.0 => MassSpec::Number(*x),
        Some((RawMass::Number(x), span)) => {
            problems.push(Problem::Inertia { span, shown: shown(*x) });
            MassSpec::Number(1.0)
        }
        Some((RawMass::Symbol(s), _)) => MassSpec::Symbol(s),
        // Principal moments: three positive finite numbers (a 2D file refuses them in the
        // builder, naming the body).
        Some((RawMass::Vector(_), span)) if b.system().dim() == 2 => {
            let error = BuildError::PrincipalInertia2d(body.name.get_ref().to_string());
            problems.push(Problem::Build { span, error });
            MassSpec::Number(1.0)
        }
        Some((RawMass::Vector(xs), span)) => match xs[..] {
            [a, b, c] if [a, b, c].iter().all(|x| x.is_finite() && *x > 0.0) => MassSpec::Principal([a, b, c]),
            [a, b, c] => {
                let bad = [a, b, c].into_iter().find(|x| !(x.is_finite() && *x > 0.0)).unwrap_or(f64::NAN);
                problems.push(Problem::Inertia { span, shown: shown(bad) });
                MassSpec::Principal([1.0; 3])
            }
            _ => {
                problems.push(Problem::InertiaLength { span: span.clone(), found: xs.len() });
                MassSpec::Principal([1.0; 3])
            }
        },
    };
    // An inertia of the other dimension's kind is reported here and replaced by a
    // placeholder of the right kind, so the body's symbols are still declared (no follow-on
    // "unknown symbol" for its orientation).
    let three = b.system().dim() == 3;
    let inertia = match (inertia, rigid.inertia.as_ref()) {
        (MassSpec::Principal(_), Some(at)) if !three => {
            let error = BuildError::PrincipalInertia2d(body.name.get_ref().to_string());
            problems.push(Problem::Build { span: at.span(), error });
            MassSpec::Number(1.0)
        }
        (MassSpec::Number(_), Some(at)) if three => {
            let error = BuildError::ScalarInertia3d(body.name.get_ref().to_string());
            problems.push(Problem::Build { span: at.span(), error });
            MassSpec::Principal([1.0; 3])
        }
        (MassSpec::Number(_), None) if three => MassSpec::Principal([1.0; 3]),
        (inertia, _) => inertia,
    };
    let spec = RigidSpec {
        orientation: rigid.orientation.get_ref(),
        angular_velocity: rigid.angular_velocity.get_ref(),
        angular_acceleration: rigid.angular_acceleration.get_ref(),
        torque: rigid.torque.get_ref(),
        inertia,
    };
    if let Err(e) = b.rigid(index, &spec) {
        let fields = [&rigid.orientation, &rigid.angular_velocity, &rigid.angular_acceleration, &rigid.torque];
        let span = match &e {
            BuildError::Duplicate { name, .. } => fields
                .into_iter()
                .find(|f| f.get_ref().as_ref() == name.as_str())
                .map(|f| f.span())
                .or_else(|| rigid.inertia.as_ref().map(|i| i.span()))
                .unwrap_or_else(|| rigid.orientation.span()),
            _ => rigid.orientation.span(),
        };
        problems.push(Problem::Build { span, error: e });
    }
}

/// A builder error, located: in the expression text where it has a span, else at `fallback`.
fn build_problem(text: &str, expr: &Text<'_>, e: &BuildError, fallback: Range<usize>) -> Problem {
    let inner = match e {
        BuildError::Parse { error: ParseError { span, .. }, .. } => Some(*span),
        BuildError::Lower { error: LowerError { span, .. }, .. } => Some(*span),
        _ => None,
    };
    let span = match inner {
        Some(s) => locate(text, expr, s.start..s.end.max(s.start)),
        None => fallback,
    };
    Problem::Build { span, error: e.clone() }
}

/// Definitions ordered so that each comes after those it uses (Kahn's algorithm: linear in
/// the definitions and their uses, no recursion); cycles are reported.
///
/// Independent definitions keep the file's (key) order. A definition on a cycle is reported
/// once per cycle closed, as a depth-first walk in key order meets it, naming the path
/// that walk took; it is then left out with every definition that uses it, so none of
/// them is reported again as an unknown symbol.
fn definitions_in_order<'a, 'b>(
    raw: &'a RawFile<'b>,
    problems: &mut Vec<Problem>,
) -> Vec<(&'a Text<'b>, &'a Text<'b>)> {
    let defs: Vec<(&'a Text<'b>, &'a Text<'b>)> = raw.definitions.iter().collect();
    let index: HashMap<&str, usize> = defs.iter().enumerate().map(|(i, (k, _))| (k.get_ref().as_ref(), i)).collect();
    // uses[i]: the definitions definition i names, in key order, each once.
    let mut idents = Vec::new();
    let uses: Vec<Vec<usize>> = defs
        .iter()
        .map(|(_, def_text)| {
            idents.clear();
            if let Ok(syntax) = crate::expr::parse::parse_expr(def_text.get_ref()) {
                collect_idents(&syntax, &mut idents);
            }
            let mut deps: Vec<usize> = idents.iter().filter_map(|n| index.get(n).copied()).collect();
            deps.sort_unstable();
            deps.dedup();
            deps
        })
        .collect();
    // Kahn: a definition is ready once every definition it uses is placed.
    let mut waiting: Vec<usize> = uses.iter().map(Vec::len).collect();
    let mut users: Vec<Vec<usize>> = vec![Vec::new(); defs.len()];
    for (i, deps) in uses.iter().enumerate() {
        for &d in deps {
            users[d].push(i);
        }
    }
    let mut order: Vec<usize> = (0..defs.len()).filter(|&i| waiting[i] == 0).collect();
    let mut next = 0;
    while let Some(&i) = order.get(next) {
        next += 1;
        for &u in &users[i] {
            waiting[u] -= 1;
            if waiting[u] == 0 {
                order.push(u);
            }
        }
    }
    if order.len() < defs.len() {
        report_cycles(&defs, &uses, &waiting, problems);
    }
    order.into_iter().map(|i| defs[i]).collect()
}

/// Reports each cycle among the definitions Kahn's algorithm could not place (`waiting`
/// not zero: on a cycle or using one): a depth-first walk in key order, with an explicit
/// stack, reports the definition that closes a cycle and the path that led to it.
fn report_cycles(defs: &[(&Text<'_>, &Text<'_>)], uses: &[Vec<usize>], waiting: &[usize], problems: &mut Vec<Problem>) {
    const NEW: u8 = 0;
    const ON_PATH: u8 = 1;
    const DONE: u8 = 2;
    let mut state = vec![NEW; defs.len()];
    // The walk's path: each definition with the position of the next use to follow.
    let mut path: Vec<(usize, usize)> = Vec::new();
    let name = |i: usize| defs[i].0.get_ref().as_ref();
    for root in (0..defs.len()).filter(|&i| waiting[i] > 0) {
        if state[root] != NEW {
            continue;
        }
        state[root] = ON_PATH;
        path.push((root, 0));
        while let Some(&mut (i, ref mut at)) = path.last_mut() {
            let Some(&dep) = uses[i].get(*at) else {
                state[i] = DONE;
                path.pop();
                continue;
            };
            *at += 1;
            match state[dep] {
                DONE => {}
                ON_PATH => {
                    let through: Vec<&str> = path.iter().map(|&(p, _)| name(p)).collect();
                    problems.push(Problem::Cycle {
                        span: defs[dep].0.span(),
                        name: name(dep).to_string(),
                        through: through.join(" → "),
                    });
                }
                _ => {
                    state[dep] = ON_PATH;
                    path.push((dep, 0));
                }
            }
        }
    }
}

fn collect_idents<'s>(s: &Syntax<'s>, out: &mut Vec<&'s str>) {
    let mut stack = vec![s];
    while let Some(s) = stack.pop() {
        match &s.kind {
            SyntaxKind::Ident(n) => out.push(n),
            SyntaxKind::Number(_) => {}
            SyntaxKind::Sum(ts) => stack.extend(ts.iter().map(|(_, t)| t)),
            SyntaxKind::Product(fs) => stack.extend(fs.iter().map(|(_, f)| f)),
            SyntaxKind::Neg(x) | SyntaxKind::Paren(x) | SyntaxKind::Component(x, _, _) => stack.push(x),
            SyntaxKind::Pow(a, b) => stack.extend([a.as_ref(), b.as_ref()]),
            SyntaxKind::Call { args, .. } | SyntaxKind::Vector(args) => stack.extend(args.iter()),
        }
    }
}
