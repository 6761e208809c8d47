//! `bench --solvers` results (`numeric::velocity::bench`) as a text table, JSON
//! (`{"title", "dt", "reference", "runs": [...], "stable_hertz": [...]}`, each limit a number
//! or null with its kind beside it) or CSV, and the
//! lines of its SVG (max |C| against time per step, one line per solver and stiffness,
//! one point per substep count).
//!
//! Not here: running anything; writing files (`main.rs`).

use crate::numeric::velocity::bench::{Entry, NotAnalysed, SolverBench};
use crate::numeric::velocity::stability::{Limit, MAX_HERTZ};
use crate::report::plot::Line;
use serde_json::{Value as Json, json};
use std::fmt::Write;

fn num(x: f64) -> Json {
    if x.is_finite() { json!(x) } else { Json::Null }
}

fn opt(x: Option<f64>) -> Json {
    x.map_or(Json::Null, num)
}

fn entry_json(e: &Entry) -> Json {
    json!({
        "solver": e.solver.name(), "substeps": e.substeps, "iterations": e.iterations,
        "hertz": opt(e.hertz), "steps": e.steps, "max_abs_C": num(e.max_abs_c),
        "max_abs_C_dot": num(e.max_abs_c_dot), "energy_drift": opt(e.energy_drift),
        "jitter": num(e.jitter), "deviation": opt(e.deviation),
        "seconds_per_step": num(e.seconds_per_step), "failure": e.failure.as_ref().map(ToString::to_string),
    })
}

pub fn json(bench: &SolverBench) -> Json {
    let stable: Vec<Json> = bench
        .stable_hertz
        .iter()
        .map(|s| {
            json!({
                "substeps": s.substeps, "relax": opt(s.relax.hertz()), "no_relax": opt(s.no_relax.hertz()),
                "relax_limit": limit_kind(s.relax), "no_relax_limit": limit_kind(s.no_relax),
            })
        })
        .collect();
    json!({
        "title": bench.title, "dt": bench.dt, "damping_ratio": bench.damping_ratio,
        "reference": entry_json(&bench.reference),
        "runs": bench.entries.iter().map(entry_json).collect::<Vec<_>>(),
        "stable_hertz": stable,
        "stable_hertz_not_computed": bench.not_analysed.map(|why| match why {
            NotAnalysed::TooLarge => "too large",
            NotAnalysed::Rigid3d => "3D rigid bodies",
            NotAnalysed::Moving => "moving",
            NotAnalysed::Contacts => "inequality rows",
        }),
    })
}

fn sci(x: f64) -> String {
    format!("{x:.2e}")
}

fn maybe(x: Option<f64>) -> String {
    x.map_or("—".into(), sci)
}

fn label(e: &Entry) -> String {
    match e.hertz {
        Some(h) => format!("{} {h} Hz", e.solver.name()),
        None => e.solver.name().to_string(),
    }
}

/// JSON's word for a limit: `"hertz"` (the number beside it), or why there is none.
fn limit_kind(x: Limit) -> &'static str {
    match x {
        Limit::Hertz(_) => "hertz",
        Limit::UnstableAtAll => "unstable at any",
        Limit::StableThroughout => "stable throughout",
        Limit::Moving => "moving",
        Limit::Contacts => "inequality rows",
        Limit::NoRadius => "no radius",
        Limit::Rigid3d => "3D rigid bodies",
    }
}

/// "13.565 Hz", or why there is no number.
fn stable(x: Limit) -> String {
    match x {
        Limit::Hertz(x) => format!("{x:.3} Hz"),
        Limit::UnstableAtAll => "unstable already at 1e-3 Hz".to_string(),
        Limit::StableThroughout => format!("stable up to {MAX_HERTZ:e} Hz and beyond"),
        Limit::Moving => "not analysed (the state is not at rest in equilibrium)".to_string(),
        Limit::Contacts => "not analysed (inequality rows)".to_string(),
        Limit::NoRadius => {
            "not computed (the eigenvalue iteration did not converge, or the step is not finite there)".to_string()
        }
        Limit::Rigid3d => "not analysed (3D rigid bodies)".to_string(),
    }
}

/// One line per run, the reference first, then the stable hertz.
pub fn text(bench: &SolverBench) -> String {
    let mut s = format!(
        "{}: velocity-level solvers at dt = {:e} (ζ = {} for the soft step); reference: exact-velocity × {} substeps\n",
        bench.title, bench.dt, bench.damping_ratio, bench.reference.substeps
    );
    let _ = writeln!(
        s,
        "{:<22} {:>8} {:>5} {:>6} {:>10} {:>10} {:>10} {:>10} {:>10} {:>11}  status",
        "solver", "substeps", "iter", "steps", "max |C|", "max |Ċ|", "energy", "jitter", "deviation", "s/step"
    );
    for e in std::iter::once(&bench.reference).chain(&bench.entries) {
        let _ = writeln!(
            s,
            "{:<22} {:>8} {:>5} {:>6} {:>10} {:>10} {:>10} {:>10} {:>10} {:>11}  {}",
            label(e),
            e.substeps,
            e.iterations,
            e.steps,
            sci(e.max_abs_c),
            sci(e.max_abs_c_dot),
            maybe(e.energy_drift),
            sci(e.jitter),
            maybe(e.deviation),
            sci(e.seconds_per_step),
            e.failure.as_ref().map_or("ok".to_string(), |f| format!("stopped: {f}"))
        );
    }
    if let Some(why) = bench.not_analysed {
        s += match why {
            NotAnalysed::TooLarge => {
                "largest stable hertz: not computed (the state is too large for the eigenvalue analysis)\n"
            }
            NotAnalysed::Rigid3d => {
                "largest stable hertz: not computed (3D rigid bodies: the linearised step's spectral radius does not decide their stability)\n"
            }
            NotAnalysed::Contacts => {
                "largest stable hertz: not computed (inequality rows: at rest a contact touches, where the clamp P ≥ 0 makes the step not differentiable)\n"
            }
            NotAnalysed::Moving => {
                "largest stable hertz: not computed (the initial state is not at rest in equilibrium: the linearised step there also grows with the motion itself, so its spectral radius does not single out the solver's stability)\n"
            }
        };
    } else {
        s += "largest stable hertz of the soft step at the initial state (spectral radius ≤ 1, cap lifted):\n";
        for h in &bench.stable_hertz {
            let _ = writeln!(
                s,
                "  {} substeps: {} with relax, {} without",
                h.substeps,
                stable(h.relax),
                stable(h.no_relax)
            );
        }
    }
    s
}

/// A header and one line per run (the reference first).
pub fn csv(bench: &SolverBench) -> String {
    let mut s = String::from(
        "solver,hertz,substeps,iterations,steps,max_abs_C,max_abs_C_dot,energy_drift,jitter,deviation,seconds_per_step,status\n",
    );
    let field = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x:e}"));
    for e in std::iter::once(&bench.reference).chain(&bench.entries) {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{:e},{:e},{},{:e},{},{:e},{}",
            e.solver.name(),
            field(e.hertz),
            e.substeps,
            e.iterations,
            e.steps,
            e.max_abs_c,
            e.max_abs_c_dot,
            field(e.energy_drift),
            e.jitter,
            field(e.deviation),
            e.seconds_per_step,
            if e.failure.is_some() { "stopped" } else { "ok" }
        );
    }
    s
}

/// max |C| against time per step: one line per solver (the soft step: per stiffness as run),
/// one point per substep count that finished.
pub fn lines(bench: &SolverBench) -> Vec<Line> {
    let mut lines: Vec<Line> = Vec::new();
    for e in bench.entries.iter().filter(|e| e.failure.is_none()) {
        let name = label(e);
        let point = (e.seconds_per_step, e.max_abs_c);
        match lines.iter_mut().find(|l| l.label == name) {
            Some(l) => l.points.push(point),
            None => lines.push(Line { label: name, points: vec![point] }),
        }
    }
    lines
}
