//! A simulation's summary for people (text) and programs (JSON).

use crate::expr::eval::Value;
use crate::numeric::simulate::{Summary, Unconverged};
use crate::numeric::velocity::{Settings as VelocitySettings, Solver};
use serde_json::{Map, Value as Json, json};

fn value_json(v: &Value, dim: usize) -> Json {
    match v {
        Value::Scalar(x) => json!(x),
        Value::Vector(xs) => json!(xs[..dim]),
        Value::Quaternion(q) => json!(q),
    }
}

/// A value as in the JSON (`[1.0,0.0]`), but a non-finite number as Rust writes it (`inf`,
/// `NaN`) where JSON has `null`: a stopped run's last state shows what went wrong.
fn value_text(v: &Value, dim: usize) -> String {
    let number = |x: &f64| if x.is_finite() { json!(x).to_string() } else { x.to_string() };
    match v {
        Value::Scalar(x) => number(x),
        Value::Vector(xs) => format!("[{}]", xs[..dim].iter().map(number).collect::<Vec<_>>().join(",")),
        Value::Quaternion(q) => format!("[{}]", q.iter().map(number).collect::<Vec<_>>().join(",")),
    }
}

/// `{"steps", "duration", "wall_seconds", "max_abs_C", "max_abs_C_dot", "energy_rel_drift", "unit_exponent", "final": {symbol: value}}`,
/// `"unconverged"` when some step's projection missed its tolerance (`Summary::unconverged`),
/// and `"stopped"`: why, when the run stopped before its last step (`stopped`). The final
/// state is where the run stopped, so a number in it may be non-finite: JSON writes it as
/// `null`, and `"stopped"` says which body or constraint went so.
pub fn json(summary: &Summary, dim: usize, stopped: Option<&str>) -> Json {
    let mut last = Map::new();
    for (name, v) in &summary.final_state {
        last.insert(name.clone(), value_json(v, dim));
    }
    let mut out = json!({
        "integrator": summary.integrator,
        "stabilize": stabilization(summary),
        "dt": summary.dt,
        "steps": summary.steps,
        "duration": summary.duration,
        "wall_seconds": summary.wall_seconds,
        "max_abs_C": summary.max_abs_c,
        "max_abs_C_dot": summary.max_abs_c_dot,
        "energy_rel_drift": summary.energy_rel_drift,
        "evaluations": summary.evaluations,
        "unit_exponent": summary.unit_exponent,
        "final": last,
    });
    if let Some(fields) = out.as_object_mut() {
        if let Some(why) = stopped {
            fields.insert("stopped".into(), json!(why));
        }
        if let Some(u) = &summary.unconverged {
            fields.insert(
                "unconverged".into(),
                json!({"steps": u.steps, "first_step": u.first, "max_distance": u.distance, "tolerance": u.bound}),
            );
        }
    }
    out
}

/// How the run held its constraints: the stabilisation's name, or a velocity-level solver's
/// settings in one line (substeps, iterations, stiffness).
pub fn stabilization(summary: &Summary) -> String {
    match &summary.velocity {
        Some(v) => velocity_settings(v),
        None => summary.stabilize.clone(),
    }
}

/// A velocity-level run's settings in one line: `4 substeps × 1 iterations, 60 Hz, ζ = 2`.
pub fn velocity_settings(s: &VelocitySettings) -> String {
    let base = format!("{} substeps × {} iterations", s.substeps, s.iterations());
    let warm = if s.warm_start { "" } else { ", no warm start" };
    match s.solver {
        Solver::SoftStep => format!(
            "{base}, {} Hz, ζ = {}{}{warm}",
            s.joint_hertz(),
            s.damping_ratio,
            if s.relax { "" } else { ", no relax" },
        ),
        Solver::Pgs => format!("{base}, β = {}{warm}", s.baumgarte),
        Solver::Xpbd => format!("{base}, compliance {}", s.compliance),
        Solver::Exact => base,
    }
}

/// A few lines: method, drift, energy, cost, final state.
pub fn text(summary: &Summary, dim: usize) -> String {
    // The simulated time as written, or in scientific notation far from 1 (1e-300 · 3 would
    // print three hundred digits).
    let t = summary.duration;
    let t = if t == 0.0 || (1e-4..1e7).contains(&t.abs()) { format!("{t}") } else { format!("{t:e}") };
    let mut s = format!(
        "{} steps (dt = {:e}, t = {t}) with {} + {}\n",
        summary.steps,
        summary.dt,
        summary.integrator,
        stabilization(summary)
    );
    s += &format!("  max |C|   {:.3e}\n  max |Ċ|   {:.3e}\n", summary.max_abs_c, summary.max_abs_c_dot);
    if let Some(u) = &summary.unconverged {
        s += &unconverged_text(u, summary.steps);
    }
    match summary.energy_rel_drift {
        Some(e) => s += &format!("  energy balance  {e:.3e} of the energy scale (max kinetic energy or Σ|F|·size)\n"),
        None if summary.samples.is_empty() => {
            s += "  energy balance  not measured (the run stopped before its first state)\n"
        }
        None => s += "  energy balance  not reported (a constraint depends on t and does work)\n",
    }
    if summary.unit_exponent != 0 {
        s += &format!(
            "  unit      lengths ran in units of 2^{} (verified homogeneous); every figure is in the scene's units\n",
            summary.unit_exponent
        );
    }
    let per_second = if summary.duration > 0.0 { summary.wall_seconds / summary.duration } else { 0.0 };
    s += &format!(
        "  wall time {:.3} s ({:.3e} s per simulated second, {} row evaluations)\n  final:",
        summary.wall_seconds, per_second, summary.evaluations
    );
    for (name, v) in summary.final_state.iter().take(FINAL_SHOWN) {
        s += &format!(" {name} = {}", value_text(v, dim));
    }
    if let Some(more) = summary.final_state.len().checked_sub(FINAL_SHOWN).filter(|&n| n > 0) {
        s += &format!(" … and {more} more (all of them: --format json or --csv)");
    }
    s
}

/// The summary's warning that the projection did not reach its tolerance: how often, from
/// when, how far it stayed, and the likely causes.
fn unconverged_text(u: &Unconverged, steps: u64) -> String {
    format!(
        "  warning   the projection onto C = 0 did not reach its tolerance {:.1e} in {} of {steps} steps \
         (from step {}; largest distance |C|/‖∇C‖ left {:.3e}): the constraints are not held to it. \
         A gradient that vanishes where C = 0 (a double root, such as dot(r,r) = 0) or a step too \
         large for the projection does this\n",
        u.bound, u.steps, u.first, u.distance
    )
}

/// The text summary's `final:` line shows this many symbols: a 100 × 100 grid's 20 000
/// would be a line of a megabyte (the JSON and the CSV have them all).
const FINAL_SHOWN: usize = 16;
