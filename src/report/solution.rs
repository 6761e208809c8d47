//! Layouts of a numeric solve (`lagrange solve`) for people (a table) and programs (JSON).
//!
//! Units: `value`, `rate` and `lambda` refer to C/κ, exactly as `derive --format json` does
//! (its `gradient` is ∇C/κ and its `scale` is κ, repeated here): the force on a body is
//! Σₖ λₖ·gradientₖ, with both taken from the same C/κ. Multiply `value` and `rate` by κ, and
//! divide `lambda` by κ, for C as written.
//!
//! Rigid bodies (a system with one) add `"torques"` and `"angular_accelerations"` (2D: a
//! number per rigid body; point masses do not appear) and `"reactions"`: each constraint's
//! force λₖ Jᵛₖᵢ and, on a rigid body, torque λₖ Jʷₖᵢ on each body it acts on (what an
//! engine's `GetConstraintForce` and `GetConstraintTorque` give). A system of point masses
//! prints exactly what it printed before.
//!
//! Diagnostics arrive as typed causes with constraint indices ([`Diagnostic`]); [`sentence`]
//! is where they become sentences naming the constraints.
//!
//! Not here: solving (`numeric::solve`), writing anything out.

use crate::derive::Derivation;
use crate::expr::{Role, Symbol};
use crate::model::system::System;
use crate::numeric::qp::QpStatus;
use crate::numeric::rows::{Rows, angular_bodies, angular_slots, world_angular};
use crate::numeric::solve::{Diagnostic, MAX_DENSE_ROWS, NonFinite, RowPart, Solution};
use serde_json::{Value, json};
use std::fmt::Write;

fn names(system: &System, rows: &[usize]) -> Vec<String> {
    rows.iter().filter_map(|&k| system.constraints.get(k).map(|c| c.name.clone())).collect()
}

/// The JSON of DESIGN.md: `{"t", "status", "constraints": [{"name", "kind", "value", "rate",
/// "lambda", "active", "scale", "contact"}], "forces": {body: [..]}, "accelerations": {..},
/// "diagnostics": [{"constraints": [names], "message"}]}`. Non-finite numbers become `null`
/// and always come with a diagnostic.
pub fn json(system: &System, derivation: &Derivation, rows: &Rows, solution: &Solution, t: f64) -> Value {
    let dim = system.dim();
    let constraints: Vec<Value> = system
        .constraints
        .iter()
        .enumerate()
        .map(|(k, c)| {
            json!({
                "name": c.name,
                "kind": if c.inequality { "inequality" } else { "equality" },
                "value": rows.rows[k].value,
                "rate": rows.rows[k].rate,
                "lambda": solution.lambda[k],
                "active": solution.active[k],
                "scale": derivation.constraints[k].scale.to_string(),
                "contact": solution.contacts[k].map(|s| s.name()),
            })
        })
        .collect();
    let per_body = |v: &[[f64; 3]]| {
        let mut m = serde_json::Map::new();
        for (i, b) in system.bodies.iter().enumerate() {
            m.insert(b.name.clone(), json!(v[i][..dim]));
        }
        Value::Object(m)
    };
    let mut out = json!({
        "t": t,
        "status": solution.status.name(),
        "constraints": constraints,
        "forces": per_body(&solution.constraint_force),
        "accelerations": per_body(&solution.acceleration),
        "diagnostics": diagnostics(system, derivation, rows, solution).into_iter().map(|(c, m)| json!({
            "constraints": c,
            "message": m,
        })).collect::<Vec<_>>(),
    });
    if system.has_rigid_bodies()
        && let Value::Object(map) = &mut out
    {
        // 2D: a number per rigid body; 3D: the world vector of its principal slots.
        let per_rigid = |v: &[[f64; 3]]| {
            let mut m = serde_json::Map::new();
            for i in angular_bodies(system) {
                let Some(slots) = angular_slots(system, i) else { continue };
                let x = world_angular(rows, |s| v[s][0], slots);
                m.insert(system.bodies[i].name.clone(), if dim == 3 { json!(x) } else { json!(x[0]) });
            }
            Value::Object(m)
        };
        map.insert("torques".into(), per_rigid(&solution.constraint_force));
        map.insert("angular_accelerations".into(), per_rigid(&solution.acceleration));
        let reactions: Vec<Value> = reactions(system, rows, solution)
            .into_iter()
            .map(|r| {
                let mut entry = json!({
                    "constraint": system.constraints[r.constraint].name,
                    "body": system.bodies[r.body].name,
                    "force": r.force[..dim],
                });
                if let (Some(torque), Value::Object(e)) = (r.torque, &mut entry) {
                    e.insert("torque".into(), if dim == 3 { json!(torque) } else { json!(torque[0]) });
                }
                entry
            })
            .collect();
        map.insert("reactions".into(), Value::Array(reactions));
    }
    out
}

/// One constraint's reaction on one body: λₖ Jᵛₖᵢ and, on a rigid body, λₖ Jʷₖᵢ.
struct Reaction {
    constraint: usize,
    body: usize,
    force: [f64; 3],
    /// In the world frame; 2D: the scalar in component 0.
    torque: Option<[f64; 3]>,
}

/// Every constraint's reaction on each body it acts on, constraints in order and bodies in
/// the order of the system (a rigid body's torque beside its force).
fn reactions(system: &System, rows: &Rows, solution: &Solution) -> Vec<Reaction> {
    let mut out = Vec::new();
    for (k, row) in rows.rows.iter().enumerate() {
        let lambda = solution.lambda[k];
        let part = |slot: usize| row.jacobian.iter().find(|(b, _)| *b == slot).map(|(_, j)| j.map(|x| lambda * x));
        for body in 0..system.bodies.len() {
            let force = part(body);
            // λ Jʷ per angular slot, turned into the world frame (3D: three principal slots).
            let torque = angular_slots(system, body).and_then(|slots| {
                let acts = slots.clone().any(|s| part(s).is_some());
                acts.then(|| world_angular(rows, |s| part(s).map_or(0.0, |j| j[0]), slots))
            });
            if force.is_none() && torque.is_none() {
                continue;
            }
            let torque = system.bodies[body].rigid.as_ref().map(|_| torque.unwrap_or([0.0; 3]));
            out.push(Reaction { constraint: k, body, force: force.unwrap_or([0.0; 3]), torque });
        }
    }
    out
}

/// The solver's diagnostics with constraint names, plus one per non-finite C/κ or Ċ/κ,
/// naming its cause.
fn diagnostics(
    system: &System,
    derivation: &Derivation,
    rows: &Rows,
    solution: &Solution,
) -> Vec<(Vec<String>, String)> {
    let mut out: Vec<(Vec<String>, String)> =
        solution.diagnostics.iter().map(|d| (names(system, d.constraints()), sentence(system, d))).collect();
    for (k, row) in rows.rows.iter().enumerate() {
        let name = &system.constraints[k].name;
        let kappa = derivation.constraints[k].scale.to_f64();
        for (what, x) in [("C/κ", row.value), ("Ċ/κ", row.rate)] {
            let Some(cause) = NonFinite::of(x) else { continue };
            let message = if kappa.is_finite() {
                format!("{what} of `{name}` is {} at this state; shown as null", cause_words(cause))
            } else {
                format!(
                    "{what} of `{name}` cannot be computed in f64: κ = {} is beyond f64's range, so C as written overflows; shown as null",
                    scale(derivation, k)
                )
            };
            out.push((names(system, &[k]), message));
        }
    }
    out
}

/// What a non-finite number means, in words.
fn cause_words(cause: NonFinite) -> &'static str {
    match cause {
        NonFinite::Undefined => "undefined (NaN: 0/0, ∞ − ∞, 0·∞ or a root or logarithm of a negative number)",
        NonFinite::Overflow => "beyond f64's range (±∞: an overflow or a division by zero)",
    }
}

/// The row part a non-finite diagnostic names, in words.
fn part_words(system: &System, part: RowPart) -> String {
    let body = |i: usize| system.bodies.get(i).map_or_else(|| i.to_string(), |b| format!("`{}`", b.name));
    match part {
        RowPart::Gradient => "its gradient".into(),
        RowPart::CTerm => "its c term (C̈ at zero acceleration)".into(),
        RowPart::Value => "C/κ".into(),
        RowPart::Rate => "Ċ/κ".into(),
        RowPart::Mass { body: i } => format!("the mass of body {} (zero, negative or not finite)", body(i)),
        RowPart::Velocity { body: i } => format!("the velocity of body {}", body(i)),
        RowPart::Force { body: i } => format!("the external force on body {}", body(i)),
    }
}

/// κ as the table shows it: exact when short, else in scientific notation (from its digits
/// when it is beyond f64's range: `1.000e400`, `1.000e-400`).
fn scale(derivation: &Derivation, k: usize) -> String {
    let kappa = &derivation.constraints[k].scale;
    let exact = kappa.to_string();
    if exact.len() <= 12 {
        return exact;
    }
    let value = kappa.to_f64();
    if value.is_normal() {
        return format!("{value:.3e}");
    }
    // p/q from the leading digits of each and their lengths.
    let (sign, digits) = exact.strip_prefix('-').map_or(("", exact.as_str()), |d| ("-", d));
    let (p, q) = digits.split_once('/').unwrap_or((digits, "1"));
    let lead = |d: &str| {
        let head = &d[..d.len().min(15)];
        (head.parse::<f64>().unwrap_or(1.0) / 10f64.powi(head.len() as i32 - 1), d.len() as i64 - 1)
    };
    let ((mp, ep), (mq, eq)) = (lead(p), lead(q));
    let (mut m, mut e) = (mp / mq, ep - eq);
    if m < 1.0 {
        m *= 10.0;
        e -= 1;
    }
    if (m * 1000.0).round() >= 10_000.0 {
        m /= 10.0;
        e += 1;
    }
    format!("{sign}{m:.3}e{e}")
}

/// "the state is off constraint `wire`: distance … (0.62× the scene's length …), speed off
/// it …" for [`Diagnostic::OffConstraint`]; empty for any other diagnostic.
fn off_words(system: &System, diagnostic: &Diagnostic) -> String {
    let Diagnostic::OffConstraint { constraint, distance, length, normal_speed, speed } = diagnostic else {
        return String::new();
    };
    let name = system.constraints.get(*constraint).map_or_else(|| constraint.to_string(), |c| format!("`{}`", c.name));
    let relative = |x: f64, scale: f64, what: &str| {
        if x == 0.0 { "0".to_string() } else { format!("{x:.3e} ({} {what} {scale:.3e})", share(x, scale)) }
    };
    let speed_words = if *speed > 0.0 {
        relative(normal_speed.abs(), *speed, "the speed scale")
    } else {
        format!("{} (the bodies are at rest)", fmt_e(normal_speed.abs()))
    };
    format!(
        "the state is off constraint {name}: distance |C|/‖∇C‖ = {}, speed off it |Ċ|/‖∇C‖ = {speed_words}",
        relative(distance.abs(), *length, "the scene's length"),
    )
}

/// The note `simulate` prints before a run from a state off a constraint
/// ([`Diagnostic::OffConstraint`]); `projects`: the run projects onto C = 0 and Ċ = 0 at
/// its first step (`--stabilize projection`), else the stabilisation or the solver's bias
/// pulls it back over the run, or nothing does.
pub fn initial_offset_note(system: &System, diagnostic: &Diagnostic, projects: bool) -> String {
    let then =
        if projects { "the first step projects it onto the constraint" } else { "the run starts from it as it is" };
    format!("note: initially {}; {then}", off_words(system, diagnostic))
}

/// A number in the sentences: 0 as `0`, others to four digits.
fn fmt_e(x: f64) -> String {
    if x == 0.0 { "0".into() } else { format!("{x:.3e}") }
}

/// `part` as a share of `whole`: `0.62×`, or `1.0e-6×`.
fn share(part: f64, whole: f64) -> String {
    let r = part / whole;
    if (1e-2..1e3).contains(&r) { format!("{r:.2}×") } else { format!("{r:.1e}×") }
}

/// Names for people: all of them up to [`LISTED_NAMES`], else the first ones and how many
/// there are (a dense block of 3 160 rows is not a paragraph of names; JSON's
/// `"constraints"` keeps them all).
fn short_list(names: &[String]) -> String {
    if names.len() <= LISTED_NAMES {
        return names.join(", ");
    }
    format!("{}, … ({} in all)", names[..LISTED_NAMES - 1].join(", "), names.len())
}

/// The most names a sentence or a diagnostic's label lists in full.
const LISTED_NAMES: usize = 8;

/// A solver diagnostic as a sentence for people, constraints by name (`wire`); an index
/// the system does not have stays a number.
pub fn sentence(system: &System, diagnostic: &Diagnostic) -> String {
    let name = |k: usize| system.constraints.get(k).map_or_else(|| k.to_string(), |c| format!("`{}`", c.name));
    let list = |ks: &[usize]| short_list(&ks.iter().map(|&k| name(k)).collect::<Vec<_>>());
    match diagnostic {
        Diagnostic::NonFiniteRow { constraint, part, cause } => format!(
            "constraint {} cannot be solved here: {} is {}; it is left out",
            name(*constraint),
            part_words(system, *part),
            match (part, cause) {
                (RowPart::Mass { .. }, _) => "unusable",
                (_, c) => cause_words(*c),
            }
        ),
        Diagnostic::ZeroGradient { constraint, unsatisfiable } => format!(
            "singular configuration: the gradient of constraint {} is zero here, so it carries no force (λ = 0){}",
            name(*constraint),
            if *unsatisfiable { "; its C̈ = 0 cannot hold" } else { "" }
        ),
        Diagnostic::InfiniteMass { constraint } => {
            format!("constraint {} acts only on bodies of infinite mass; it carries no force", name(*constraint))
        }
        Diagnostic::Closing { constraint } => format!(
            "contact {} is closing (Ċ < 0): it needs an impulse P = −(1+e) J v / (J M⁻¹ Jᵀ) (numeric::contact::impulses); the force shown holds it as if resting",
            name(*constraint)
        ),
        Diagnostic::Penetrating { constraint } => {
            format!("contact {} is violated (C < 0 beyond the tolerance); it is treated as touching", name(*constraint))
        }
        Diagnostic::LambdaOutOfRange { constraint, lambda } => format!(
            "λ of constraint {} is outside the normal f64 range at this scale ({lambda:e}); the forces and accelerations are exact",
            name(*constraint)
        ),
        Diagnostic::NonFiniteLambda { constraint } => {
            format!("λ of constraint {} came out non-finite; it is set to 0", name(*constraint))
        }
        Diagnostic::Redundant { constraints, rank, size, condition } => format!(
            "redundant or singular constraints ({}): rank {rank} of {size}, condition of the rest ≈ {condition:.1e}; consistent: the λ of least norm √(Σ λ²), λ for C/κ (the pseudo-inverse's)",
            list(constraints)
        ),
        Diagnostic::RedundantSparse { constraints, size, solves } => format!(
            "redundant or singular constraints ({}) in a block of {size} rows, past the {MAX_DENSE_ROWS} of the dense decomposition: rank not computed; consistent: the λ of least norm √(Σ λ²), λ for C/κ, by {solves} sparse solves",
            list(constraints)
        ),
        Diagnostic::Inconsistent { constraints, rank, size, condition, residual } => format!(
            "redundant or singular constraints ({}): rank {rank} of {size}, condition of the rest ≈ {condition:.1e}; inconsistent (relative residual {residual:.1e}), the least-squares λ of least norm √(Σ λ²), λ for C/κ",
            list(constraints)
        ),
        Diagnostic::QpFailed { status, .. } => match status {
            QpStatus::Infeasible => "the contact QP is infeasible: the constraints contradict each other",
            QpStatus::Unbounded => "the contact QP is unbounded: the rows are inconsistent (no λ ≥ 0 balances b)",
            QpStatus::MaxIterations => "the contact QP reached its iteration limit",
            QpStatus::NumericalError => "the contact QP stopped on a numerical error",
            QpStatus::Solved | QpStatus::AlmostSolved | QpStatus::Rejected => {
                "the contact QP was rejected by Clarabel (an internal error)"
            }
        }
        .to_string(),
        Diagnostic::QpInaccurate { status, iterations, residuals, .. } => format!(
            "the contact QP ({status:?}, {iterations} iterations) has poor KKT residuals: stationarity {:.1e}, feasibility {:.1e}, complementarity {:.1e}",
            residuals.stationarity, residuals.feasibility, residuals.complementarity
        ),
        Diagnostic::Restitution { value } => format!("restitution must lie in [0, 1], found {value}; 0 is used"),
        Diagnostic::TooLarge { rows, .. } => format!(
            "too large to solve: {rows} coupled rows need a dense solve (the limit is {MAX_DENSE_ROWS} rows; docs/commands.md, \"solve\"); λ is 0 on them"
        ),
        Diagnostic::MixedScales { raw } => format!(
            "the rescaled unit does not fit {}: their bodies' positions, velocities and forces are near the file's unit, so they are solved in it (the rest in the rescaled unit)",
            list(raw)
        ),
        Diagnostic::OffConstraint { .. } => {
            format!(
                "{}; λ is the force at this state, which the constraint does not allow",
                off_words(system, diagnostic)
            )
        }
        Diagnostic::Rescaled { exponent } => format!(
            "the numbers overflow at this state; solved in a length unit scaled by 2^{exponent} (verified homogeneous) and scaled back"
        ),
    }
}

/// A number of the table; a non-finite one is `null`, as in the JSON, and a diagnostic
/// names its cause.
fn number(x: f64) -> String {
    if !x.is_finite() {
        "null".into()
    } else if x == 0.0 {
        "0".into()
    } else {
        format!("{x:.6e}")
    }
}

/// The note for an external force or torque taken as zero (`model::scene::unset_forces`).
pub fn zero_force_note(system: &System, symbol: Symbol) -> String {
    let sym = system.graph.symbol(symbol);
    let (what, body) = match sym.role {
        Role::Torque { body } => ("torque", body),
        Role::Force { body } => ("force", body),
        _ => ("value", usize::MAX),
    };
    let body = system.bodies.get(body).map_or_else(String::new, |b| format!(" of `{}`", b.name));
    format!("note: the {what} `{}`{body} has no value and no [scene] forces expression: taken as zero", sym.name)
}

/// A readable table of the same numbers.
pub fn text(system: &System, derivation: &Derivation, rows: &Rows, solution: &Solution, t: f64) -> String {
    let dim = system.dim();
    let mut out = String::new();
    let title = if system.title.is_empty() { "lagrange solve" } else { system.title.as_str() };
    let _ = writeln!(out, "{title} at t = {}  (status: {})", crate::model::problem::shown(t), solution.status.name());
    let _ = writeln!(out, "values, rates and λ refer to C/κ (κ: the constant taken out of ∇C, as in `derive`)\n");
    let width = system.constraints.iter().map(|c| c.name.chars().count()).max().unwrap_or(0).max(10);
    let _ = writeln!(
        out,
        "{:<width$}  {:<10}  {:>4}  {:>13}  {:>13}  {:>13}  {:<6}  contact",
        "constraint", "kind", "κ", "C/κ", "Ċ/κ", "λ", "active"
    );
    for (k, c) in system.constraints.iter().enumerate() {
        let line = format!(
            "{:<width$}  {:<10}  {:>4}  {:>13}  {:>13}  {:>13}  {:<6}  {}",
            c.name,
            if c.inequality { "inequality" } else { "equality" },
            scale(derivation, k),
            number(rows.rows[k].value),
            number(rows.rows[k].rate),
            number(solution.lambda[k]),
            if solution.active[k] { "yes" } else { "no" },
            solution.contacts[k].map_or("", |s| s.name()),
        );
        let _ = writeln!(out, "{}", line.trim_end());
    }
    let bw = system.bodies.iter().map(|b| b.name.chars().count()).max().unwrap_or(0).max(4);
    let vector = |v: &[f64; 3]| v[..dim].iter().map(|x| number(*x)).collect::<Vec<_>>().join(", ");
    let _ = writeln!(out, "\n{:<bw$}  constraint force / acceleration", "body");
    for (i, b) in system.bodies.iter().enumerate() {
        let _ = writeln!(out, "{:<bw$}  F_c = [{}]", b.name, vector(&solution.constraint_force[i]));
        let _ = writeln!(out, "{:<bw$}  a   = [{}]", "", vector(&solution.acceleration[i]));
        // A rigid body's constraint torque and angular acceleration, from its angular
        // slot (3D: its principal slots, in the world frame).
        if let Some(slots) = angular_slots(system, i) {
            let torque = world_angular(rows, |s| solution.constraint_force[s][0], slots.clone());
            let alpha = world_angular(rows, |s| solution.acceleration[s][0], slots);
            let show = |x: &[f64; 3]| if dim == 3 { format!("[{}]", vector(x)) } else { number(x[0]) };
            let _ = writeln!(out, "{:<bw$}  T_c = {}", "", show(&torque));
            let _ = writeln!(out, "{:<bw$}  α   = {}", "", show(&alpha));
        }
    }
    if system.has_rigid_bodies() {
        let _ = writeln!(out, "\nreactions (each constraint's force and torque on each body)");
        for r in reactions(system, rows, solution) {
            let torque = r.torque.map_or_else(String::new, |x| {
                if dim == 3 { format!("  T = [{}]", vector(&x)) } else { format!("  T = {}", number(x[0])) }
            });
            let _ = writeln!(
                out,
                "  {} on {}: F = [{}]{torque}",
                system.constraints[r.constraint].name,
                system.bodies[r.body].name,
                vector(&r.force)
            );
        }
    }
    let diags = diagnostics(system, derivation, rows, solution);
    if !diags.is_empty() {
        let _ = writeln!(out, "\ndiagnostics");
        for (c, m) in diags {
            let _ = writeln!(out, "  - [{}] {m}", short_list(&c));
        }
    }
    out
}
