//! The run loop of a velocity-level simulation: record the state (rows, |C|, |Ċ|, the
//! energy balance), hand a [`Frame`] to the observer, step with the chosen solver — the same
//! frames and [`Summary`] as `numeric::simulate`, so the CSV writer, the summary and the
//! plots serve both.
//!
//! λ in a frame is the force each row applied over the last step, P/h (XPBD: λ/h²); at
//! step 0 it is 0. The energy balance is E = (T − T₀) − ∫ Σ F·v dt by the trapezoid rule
//! over the recorded states (the soft constraints store and dissipate energy: the figure
//! measures that, not the quadrature). A run stops when a constraint is farther from its
//! surface than `blowup` × the scene's size, naming the step and the constraint; for the
//! soft step it also says which hertz would have been stable at the initial state, when the
//! scene is small enough for the eigenvalue analysis (`velocity::stability`).
//!
//! Not here: the solvers (one file each), files or text.

use super::{Settings, Solver, Stepper, stability};
use crate::expr::eval::{Env, Value};
use crate::numeric::dynamics::{Dynamics, SimError};
use crate::numeric::simulate::{Failure, Frame, Sample, Summary, initial_state, time_dependent};
use crate::numeric::solve::CONTACT_TOLERANCE;
use crate::numeric::stabilize::distance;
use crate::numeric::vector::length_scale;
use std::time::Instant;

/// State vectors up to this size get the stable-hertz hint when a soft step diverges.
pub const HINT_MAX_STATE: usize = 400;

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Runs `settings.steps` steps from `env`'s state, calling `observe` at every recorded state
/// (step 0 … steps).
pub fn run(
    mut dynamics: Dynamics<'_>,
    env: &Env,
    settings: Settings,
    observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
) -> Result<Summary, Box<Failure>> {
    let start = Instant::now();
    let system = dynamics.system();
    let mut summary = Summary {
        integrator: settings.solver.name().into(),
        stabilize: settings.describe(),
        dt: settings.dt,
        ..Summary::default()
    };
    let (mut q, mut v, t0) = initial_state(system, env);
    let result = settings
        .validate()
        .and_then(|()| run_inner(&mut dynamics, settings, &mut q, &mut v, t0, &mut summary, observe));
    summary.wall_seconds = start.elapsed().as_secs_f64();
    summary.evaluations = dynamics.evaluations;
    summary.final_position.clone_from(&q);
    summary.final_velocity.clone_from(&v);
    for (i, body) in system.bodies.iter().enumerate() {
        summary.final_state.push((system.graph.symbol(body.position).name.clone(), Value::Vector(q[i])));
        summary.final_state.push((system.graph.symbol(body.velocity).name.clone(), Value::Vector(v[i])));
    }
    match result {
        Ok(()) => Ok(summary),
        Err(error) => Err(Box::new(Failure { error, summary })),
    }
}

#[allow(clippy::too_many_arguments)]
fn run_inner(
    dynamics: &mut Dynamics<'_>,
    s: Settings,
    q: &mut Vec<[f64; 3]>,
    v: &mut Vec<[f64; 3]>,
    t0: f64,
    summary: &mut Summary,
    observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
) -> Result<(), SimError> {
    let system = dynamics.system();
    let (q0, v0) = (q.clone(), v.clone());
    let mut stepper = Stepper::new(s, system.constraints.len(), q.len());
    let energy_reported = !time_dependent(system);
    let length = length_scale(q.iter());
    let bound = s.blowup * length;
    let touch = CONTACT_TOLERANCE * length;
    let stride = (s.steps / s.samples.max(1) as u64).max(1);
    let plotted = q.len().min(8);
    let (mut kinetic0, mut work, mut power_1, mut max_energy_error, mut max_kinetic) = (0.0, 0.0, 0.0, 0.0f64, 0.0f64);
    let mut lambda = vec![0.0; system.constraints.len()];
    for n in 0..=s.steps {
        let t = t0 + n as f64 * s.dt;
        dynamics.step = n;
        let rows = dynamics.rows(t, q, v)?;
        let (mut c_max, mut c_dot_max) = (0.0f64, 0.0f64);
        for (k, row) in rows.rows.iter().enumerate() {
            let d = distance(row);
            if d.abs() > bound && (!row.inequality || d < 0.0) {
                let hint = if s.solver == Solver::SoftStep {
                    hint(dynamics, t0, &q0, &v0, &s)
                } else {
                    "; try more --substeps or a smaller --dt".into()
                };
                return Err(SimError::Diverged {
                    step: n,
                    time: t,
                    solver: s.solver.name().into(),
                    constraint: system.constraints[k].name.clone(),
                    value: row.value,
                    distance: d,
                    bound,
                    hint,
                });
            }
            if row.inequality {
                c_max = c_max.max((-row.value).max(0.0));
                if d <= touch && row.rate < 0.0 {
                    c_dot_max = c_dot_max.max(-row.rate);
                }
            } else {
                c_max = c_max.max(row.value.abs());
                c_dot_max = c_dot_max.max(row.rate.abs());
            }
        }
        summary.max_abs_c = summary.max_abs_c.max(c_max);
        summary.max_abs_c_dot = summary.max_abs_c_dot.max(c_dot_max);
        let (mut kinetic, mut power) = (0.0, 0.0);
        for ((v, f), w) in v.iter().zip(&rows.force).zip(&rows.inverse_mass) {
            kinetic += 0.5 * dot(v, v) / w;
            power += dot(f, v);
        }
        if n == 0 {
            kinetic0 = kinetic;
        } else {
            work += 0.5 * (power_1 + power) * s.dt;
        }
        power_1 = power;
        let energy_error = (kinetic - kinetic0) - work;
        max_energy_error = max_energy_error.max(energy_error.abs());
        max_kinetic = max_kinetic.max(kinetic);
        summary.max_kinetic = max_kinetic;
        summary.final_energy_error = energy_error;
        summary.energy_rel_drift =
            energy_reported.then(|| if max_kinetic > 0.0 { max_energy_error / max_kinetic } else { max_energy_error });
        if n.is_multiple_of(stride) || n == s.steps {
            summary.samples.push(Sample { time: t, max_abs_c: c_max, energy_error, position: q[..plotted].to_vec() });
        }
        if n > 0 {
            stepper.lambda(&mut lambda);
        }
        let frame = Frame { step: n, time: t, position: q, velocity: v, rows: &rows, lambda: &lambda, energy_error };
        observe(&frame).map_err(SimError::Output)?;
        summary.steps = n;
        summary.duration = n as f64 * s.dt;
        if n == s.steps {
            dynamics.recycle(rows);
            break;
        }
        stepper.step(dynamics, t, q, v, rows)?;
        for (i, (q, v)) in q.iter().zip(v.iter()).enumerate() {
            if !(q.iter().chain(v).all(|x| x.is_finite())) {
                let body = system.bodies[i].name.clone();
                return Err(SimError::NonFinite { step: n + 1, time: t + s.dt, body });
            }
        }
    }
    Ok(())
}

/// "; stable up to H Hz at the initial state" for a soft step that diverged, when the scene
/// is small enough to analyse.
fn hint(dynamics: &mut Dynamics<'_>, t0: f64, q0: &[[f64; 3]], v0: &[[f64; 3]], s: &Settings) -> String {
    let dim = dynamics.system().dim();
    if stability::state_len(dim, q0.len(), dynamics.system().constraints.len(), s) > HINT_MAX_STATE {
        return "; try more --substeps or a lower --hertz".into();
    }
    match stability::largest_stable_hertz(dynamics, t0, q0, v0, s) {
        Ok(Some(h)) if h < s.joint_hertz() => {
            format!(
                "; at the initial state the soft step is stable up to {h:.3} Hz (--hertz), it ran at {} Hz",
                s.joint_hertz()
            )
        }
        _ => "; try more --substeps or a lower --hertz".into(),
    }
}
