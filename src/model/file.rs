//! Constraint definition files (TOML, DESIGN.md): raw serde structs and their validation.
//!
//! [`RawFile`] mirrors the TOML exactly, with spans; [`load`] validates it into a
//! [`System`] and the numbers `solve` and `simulate` need. Only validation builds the
//! model (the raw structs never leave this module's callers half-checked). Every problem
//! carries a byte span into the file text, so messages point at the fault.
//!
//! Not here: printing or rendering messages (the caller renders [`Problem`]s).

use super::document::read;
use super::expect::{Expectation, RawExpect, resolve};
use super::scene::{RawScene, Scene, validate};
use super::system::{BodySpec, BuildError, MassSpec, System, SystemBuilder};
use crate::expr::lower::LowerError;
use crate::expr::parse::ParseError;
use crate::expr::syntax::{Syntax, SyntaxKind};
use crate::expr::{Symbol, Ty};
use serde::Deserialize;
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::ops::Range;
use toml::Spanned;

/// The largest constraint file read, in bytes.
pub const MAX_FILE_BYTES: usize = 16 << 20;

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
    pub scene: Option<Spanned<RawScene<'a>>>,
    pub expect: Vec<Spanned<RawExpect<'a>>>,
}

/// A parameter value: a number or a vector of numbers (finite, when read from a file).
/// `Deserialize` serves `solve --at STATE` files.
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
}

#[derive(Clone, Debug)]
pub enum RawMass<'a> {
    Number(f64),
    Symbol(Cow<'a, str>),
}

#[derive(Debug)]
pub struct RawConstraint<'a> {
    pub name: Text<'a>,
    /// `None` when missing or not a string (reported by `model::document`).
    pub expr: Option<Text<'a>>,
}

/// One problem in a file: where (a byte range of the file text) and what.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Problem {
    pub span: Option<Range<usize>>,
    pub message: String,
}

/// A validated file: the system, the parameter values, the scene and the expectations.
/// (The raw file is not kept: it borrows the text, and all it said is in these.)
#[derive(Debug)]
pub struct Loaded {
    pub system: System,
    pub values: BTreeMap<String, RawValue>,
    pub scene: Scene,
    pub expect: Vec<Expectation>,
}

/// Parses and validates a constraint file's text. Every problem found is returned.
pub fn load(text: &str) -> Result<Loaded, Vec<Problem>> {
    if text.len() > MAX_FILE_BYTES {
        return Err(vec![Problem {
            span: None,
            message: format!("file is too large ({} bytes; the limit is {MAX_FILE_BYTES})", text.len()),
        }]);
    }
    let mut problems = Vec::new();
    let Some(raw) = read(text, &mut problems) else {
        sort(&mut problems);
        return Err(problems);
    };
    let Some(mut system) = build(text, &raw, &mut problems) else {
        sort(&mut problems);
        return Err(problems);
    };
    let scene = match &raw.scene {
        Some(s) => validate(text, s.get_ref(), &mut system, &mut problems),
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
    let values: BTreeMap<String, RawValue> =
        raw.parameters.iter().map(|(k, v)| (k.get_ref().to_string(), v.get_ref().clone())).collect();
    masses_have_values(&raw, &system, &scene, &expect, &mut problems);
    if !problems.is_empty() {
        sort(&mut problems);
        return Err(problems);
    }
    Ok(Loaded { system, values, scene, expect })
}

/// In file order, so the messages read top to bottom (unlocated ones first); a problem
/// found twice (by two passes over the same value) is shown once.
fn sort(problems: &mut Vec<Problem>) {
    problems.sort_by_key(|p| p.span.as_ref().map_or((0, 0), |s| (s.start, s.end)));
    problems.dedup();
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
        let span = Some(raw_body.get_ref().mass.span());
        if raw.scene.is_some() && !initial.contains(s) {
            problems.push(Problem {
                span,
                message: format!(
                    "the mass `{name}` has no value, and the [scene] needs one: give it in [parameters] or in [scene] initial"
                ),
            });
        }
        for e in expect {
            if let Some(at) = &e.at
                && !at.iter().any(|(x, _)| x == name)
            {
                problems.push(Problem {
                    span: Some(e.span.clone()),
                    message: format!(
                        "this [[expect]] is checked at a state (`at`), which gives no value to the mass `{name}`: add it to `at` or to [parameters]"
                    ),
                });
            }
        }
    }
}

fn build(text: &str, raw: &RawFile<'_>, problems: &mut Vec<Problem>) -> Option<System> {
    let title = raw.title.as_ref().map_or("", |t| t.get_ref().as_ref());
    let dimension = raw.dimension.as_ref()?;
    let mut b = match SystemBuilder::new(title, *dimension.get_ref()) {
        Ok(b) => b,
        Err(e) => {
            problems.push(Problem { span: Some(dimension.span()), message: e.to_string() });
            return None;
        }
    };
    b.reserve(raw.bodies.len(), raw.constraints.len(), raw.parameters.len() + raw.definitions.len());
    let dim = *dimension.get_ref() as usize;
    for (name, value) in &raw.parameters {
        let ty = match value.get_ref() {
            RawValue::Number(_) => Ty::Scalar,
            RawValue::Vector(v) if v.len() == dim => Ty::Vector,
            RawValue::Vector(v) => {
                problems.push(Problem {
                    span: Some(value.span()),
                    message: format!("parameter `{}` has {} components in a {dim}D file", name.get_ref(), v.len()),
                });
                continue;
            }
        };
        if let Err(e) = b.parameter(name.get_ref(), ty) {
            problems.push(Problem { span: Some(name.span()), message: e.to_string() });
        }
    }
    for body in &raw.bodies {
        let body = body.get_ref();
        let mass = match body.mass.get_ref() {
            RawMass::Number(x) if x.is_finite() && *x > 0.0 => MassSpec::Number(*x),
            RawMass::Number(x) => {
                let shown = if x.is_nan() { "nan".to_string() } else { x.to_string() };
                problems.push(Problem {
                    span: Some(body.mass.span()),
                    message: format!("a mass must be a positive finite number, found {shown}"),
                });
                // Declared all the same, so the body's symbols are known where used.
                MassSpec::Number(1.0)
            }
            RawMass::Symbol(s) => MassSpec::Symbol(s),
        };
        let spec = BodySpec {
            name: body.name.get_ref(),
            position: body.position.get_ref(),
            velocity: body.velocity.get_ref(),
            acceleration: body.acceleration.get_ref(),
            force: body.force.get_ref(),
            mass,
        };
        if let Err(e) = b.body(&spec) {
            // Point at the field whose symbol clashes, not just at the body.
            let span = match &e {
                BuildError::Duplicate { name, .. } => [&body.position, &body.velocity, &body.acceleration, &body.force]
                    .into_iter()
                    .find(|f| f.get_ref().as_ref() == name.as_str())
                    .map_or_else(|| body.name.span(), |f| f.span()),
                _ => body.name.span(),
            };
            let span = match (&e, body.mass.get_ref()) {
                (BuildError::Duplicate { name, .. }, RawMass::Symbol(m)) if m.as_ref() == name.as_str() => {
                    body.mass.span()
                }
                _ => span,
            };
            problems.push(Problem { span: Some(span), message: e.to_string() });
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
    if raw.constraints.is_empty() {
        problems.push(Problem { span: None, message: "the file has no [[constraints]]".into() });
    }
    Some(b.finish())
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
    Problem { span: Some(span), message: e.to_string() }
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
                    problems.push(Problem {
                        span: Some(defs[dep].0.span()),
                        message: BuildError::Cycle(name(dep).to_string(), through.join(" → ")).to_string(),
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
