//! `lagrange bench`'s results (`precision`) as a text table, JSON (`{"rows": [...],
//! "accuracy": [...]}`) or CSV, and the lines of the work-precision plot.

use crate::numeric::dynamics::SimError;
use crate::precision::accuracy::AccuracyRow;
use crate::precision::{SweepRow, WorkPrecision};
use crate::report::plot::Line;
use serde_json::{Value as Json, json};

/// null for NaN and infinities (JSON has neither).
fn num(x: f64) -> Json {
    if x.is_finite() { json!(x) } else { Json::Null }
}

fn opt(x: Option<f64>) -> Json {
    x.map_or(Json::Null, num)
}

pub fn json(wp: &WorkPrecision, accuracy: &[AccuracyRow]) -> Json {
    let rows: Vec<Json> = wp
        .rows
        .iter()
        .map(|r| {
            json!({
                "integrator": r.integrator, "stabilize": r.stabilize, "dt": r.dt, "steps": r.steps,
                "wall_per_second": num(r.wall_per_second), "max_abs_C": num(r.max_abs_c),
                "max_abs_C_dot": num(r.max_abs_c_dot), "energy_error": opt(r.energy_error),
                "final_error": opt(r.final_error), "status": status(r),
            })
        })
        .collect();
    let accuracy: Vec<Json> = accuracy
        .iter()
        .map(|a| {
            json!({
                "body": label(a), "method": a.method, "states": a.states, "count": a.count,
                "median_rel_error": num(a.median_rel_error), "max_rel_error": num(a.max_rel_error),
                "nanos_per_eval": num(a.nanos_per_eval),
            })
        })
        .collect();
    json!({
        "reference": {"integrator": "rk4", "stabilize": "projection", "dt": wp.reference_dt,
                      "steps": wp.reference_steps, "wall_seconds": num(wp.reference_wall_seconds),
                      "error": wp.reference_error.as_ref().map(|e| reference_failure(wp, e))},
        "rows": rows,
        "accuracy": accuracy,
    })
}

/// An accuracy row's label: the body, `rod (torque)` for a rigid body's constraint torque.
fn label(a: &AccuracyRow) -> String {
    if a.torque { format!("{} (torque)", a.body) } else { a.body.clone() }
}

/// A row's status: `ok`, or why the run stopped.
fn status(r: &SweepRow) -> String {
    r.failure.as_ref().map_or_else(|| "ok".to_string(), ToString::to_string)
}

/// Why the reference run failed, as a sentence.
fn reference_failure(wp: &WorkPrecision, e: &SimError) -> String {
    format!("the reference run (RK4 + projection, dt = {:e}) failed: {e}", wp.reference_dt)
}

fn e(x: f64) -> String {
    if x.is_finite() { format!("{x:.2e}") } else { "-".into() }
}

fn oe(x: Option<f64>) -> String {
    x.map_or("-".into(), e)
}

pub fn text(wp: &WorkPrecision, accuracy: &[AccuracyRow]) -> String {
    let mut s = format!(
        "reference: rk4 + projection, dt = {:.3e} ({} steps, {:.2} s)\n\n",
        wp.reference_dt, wp.reference_steps, wp.reference_wall_seconds
    );
    if let Some(e) = &wp.reference_error {
        s += &format!("warning: {}; final-state errors are unknown\n\n", reference_failure(wp, e));
    }
    s += &format!(
        "{:<8} {:<11} {:>9} {:>8} {:>11} {:>9} {:>9} {:>9} {:>11}  status\n",
        "method", "stabilize", "dt", "steps", "s/sim-s", "max|C|", "max|Ċ|", "energy", "final err"
    );
    for r in &wp.rows {
        s += &format!(
            "{:<8} {:<11} {:>9} {:>8} {:>11} {:>9} {:>9} {:>9} {:>11}  {}\n",
            r.integrator,
            r.stabilize,
            e(r.dt),
            r.steps,
            e(r.wall_per_second),
            e(r.max_abs_c),
            e(r.max_abs_c_dot),
            oe(r.energy_error),
            oe(r.final_error),
            status(r)
        );
    }
    s += "\nformula accuracy (f64 against double-double)\n";
    s += &format!(
        "{:<12} {:<12} {:<7} {:>6} {:>12} {:>12} {:>12}\n",
        "body", "method", "states", "count", "median rel", "max rel", "ns/eval"
    );
    for a in accuracy {
        s += &format!(
            "{:<12} {:<12} {:<7} {:>6} {:>12} {:>12} {:>12.0}\n",
            label(a),
            a.method,
            a.states,
            a.count,
            e(a.median_rel_error),
            e(a.max_rel_error),
            a.nanos_per_eval
        );
    }
    if accuracy.iter().any(|a| a.method == "closed form") {
        // What the column times, so it is not read as the speed of the compiled tape.
        s += "ns/eval of `closed form`: the interpreter (expr::eval) on the closed-form λ J, not the compiled\n";
        s += "tape that `solve` and `simulate` run (`solve` rows: the tape of the rows and the λ solve)\n";
    }
    s
}

fn csv_num(x: f64) -> String {
    if x.is_finite() { format!("{x:e}") } else { String::new() }
}

/// The sweep as CSV (one line per run); the accuracy table follows after a blank line.
pub fn csv(wp: &WorkPrecision, accuracy: &[AccuracyRow]) -> String {
    let mut s = String::from(
        "integrator,stabilize,dt,steps,wall_per_second,max_abs_C,max_abs_C_dot,energy_error,final_error,status\n",
    );
    for r in &wp.rows {
        s += &format!(
            "{},{},{},{},{},{},{},{},{},\"{}\"\n",
            r.integrator,
            r.stabilize,
            csv_num(r.dt),
            r.steps,
            csv_num(r.wall_per_second),
            csv_num(r.max_abs_c),
            csv_num(r.max_abs_c_dot),
            r.energy_error.map_or(String::new(), csv_num),
            r.final_error.map_or(String::new(), csv_num),
            status(r).replace('"', "'")
        );
    }
    s += "\nbody,method,states,count,median_rel_error,max_rel_error,nanos_per_eval\n";
    for a in accuracy {
        s += &format!(
            "{},{},{},{},{},{},{}\n",
            label(a),
            a.method,
            a.states,
            a.count,
            csv_num(a.median_rel_error),
            csv_num(a.max_rel_error),
            csv_num(a.nanos_per_eval)
        );
    }
    s
}

/// One line per method (integrator + stabilisation): (wall time per simulated second, final error).
pub fn lines(wp: &WorkPrecision) -> Vec<Line> {
    let mut lines: Vec<Line> = Vec::new();
    for r in &wp.rows {
        let Some(error) = r.final_error else { continue };
        let label = format!("{} + {}", r.integrator, r.stabilize);
        let point = (r.wall_per_second, error);
        match lines.iter_mut().find(|l| l.label == label) {
            Some(l) => l.points.push(point),
            None => lines.push(Line { label, points: vec![point] }),
        }
    }
    for l in &mut lines {
        l.points.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    lines
}
