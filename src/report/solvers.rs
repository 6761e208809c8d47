//! `bench --solvers` results (`numeric::velocity::bench`) as a text table, JSON
//! (`{"title", "dt", "reference", "runs": [...], "stable_hertz": [...]}`) or CSV, and the
//! lines of its SVG (max |C| against time per step, one line per solver and stiffness,
//! one point per substep count).
//!
//! Not here: running anything; writing files (`main.rs`).

use crate::numeric::velocity::bench::{Entry, SolverBench};
use crate::numeric::velocity::stability::MAX_HERTZ;
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
        .map(|s| json!({"substeps": s.substeps, "relax": opt(s.relax), "no_relax": opt(s.no_relax)}))
        .collect();
    json!({
        "title": bench.title, "dt": bench.dt, "damping_ratio": bench.damping_ratio,
        "reference": entry_json(&bench.reference),
        "runs": bench.entries.iter().map(entry_json).collect::<Vec<_>>(),
        "stable_hertz": stable,
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

/// "13.565 Hz", or what `None` means.
fn stable(x: Option<f64>) -> String {
    x.map_or(format!("stable up to {MAX_HERTZ:e} Hz (or unstable at any)"), |x| format!("{x:.3} Hz"))
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
    if bench.stable_hertz.is_empty() {
        s += "largest stable hertz: not computed (the state is too large for the eigenvalue analysis)\n";
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
