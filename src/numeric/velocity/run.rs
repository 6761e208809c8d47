//! The run loop of a velocity-level simulation: record the state (rows, |C|, |Ċ|, the
//! energy balance), hand a [`Frame`] to the observer, step with the chosen solver — the same
//! frames and [`Summary`] as `numeric::simulate`, so the CSV writer, the summary and the
//! plots serve both.
//!
//! λ in a frame is the force each row applied over the last step, P/h (XPBD: λ/h²); at
//! step 0 it is 0. The exact solve reports it only at the steps `Settings::lambda_at` names
//! (the others' frames have an empty λ). The energy balance is E = (T − T₀) − W with T = Σ ½ v·v/w over the slots
//! (a rigid body's ½ I ω² too) and the work W = Σ ½ (Fₙ + Fₙ₊₁)·(qₙ₊₁ − qₙ) summed over the
//! recorded states (torques times the turn of the angles): the trapezoid rule along the
//! path, exact for constant forces and linear springs whatever the integrator does between
//! the states, so the figure measures what the solver stores and dissipates, not the
//! quadrature. (The trapezoid in time, ∫ F·v dt, is off by O(dt) at 60 Hz: 8 % of the
//! pinned rod's swing.) A run stops when a constraint is farther from its
//! surface than `blowup` × the scene's size, naming the step and the constraint; for the
//! soft step it also says which hertz would have been stable at the initial state, when the
//! scene is small enough for the eigenvalue analysis (`velocity::stability`).
//!
//! Not here: the solvers (one file each), files or text.

use super::{Settings, Solver, Stepper, stability};
use crate::expr::eval::Env;
use crate::numeric::dynamics::{Dynamics, Remedy, SimError, slot_name};
use crate::numeric::rescale::{Shown, Unit};
use crate::numeric::rotation;
use crate::numeric::simulate::{
    Failure, Frame, Sample, Summary, Unconverged, final_state, initial_state, time_dependent, work_scale,
};
use crate::numeric::solve::CONTACT_TOLERANCE;
use crate::numeric::stabilize::distance;
use crate::numeric::vector::{dot, length_scale};
use std::time::Instant;

/// State vectors up to this size get the stable-hertz hint when a soft step diverges.
pub const HINT_MAX_STATE: usize = 400;

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
        velocity: Some(settings),
        dt: settings.dt,
        ..Summary::default()
    };
    let (mut q, mut v, t0) = initial_state(system, env);
    // A scene far from unit size runs in a power-of-two length unit (`Dynamics::choose_unit`,
    // as `numeric::simulate` does): the steps are linear in the lengths, so the run is the
    // scene's, scaled exactly, and everything reported is converted back.
    let mut unit = None;
    let result = settings.validate().and_then(|()| {
        unit = dynamics.choose_unit(env)?;
        // At least one row evaluation a substep (`simulate::Compile::Auto`'s estimate).
        let evaluations = settings.steps.saturating_mul(settings.substeps as u64);
        summary.compiled = dynamics.compile_rows(settings.compile, evaluations);
        if let Some(u) = &unit {
            (q, v, _) = initial_state(system, &u.to_unit(env));
            summary.unit_exponent = u.exponent;
        }
        run_inner(&mut dynamics, settings, unit.as_ref(), &mut q, &mut v, t0, &mut summary, observe)
    });
    summary.wall_seconds = start.elapsed().as_secs_f64();
    summary.evaluations = dynamics.evaluations;
    // 3D rigid bodies: the last step's rotation vectors into the orientations reported.
    dynamics.rebase(&mut q);
    if let Some(u) = &unit {
        // A run with rigid bodies keeps the scene's unit: every slot here is a body's.
        for x in q.iter_mut().chain(v.iter_mut()) {
            *x = u.vector(*x);
        }
    }
    summary.final_position.clone_from(&q);
    summary.final_velocity.clone_from(&v);
    summary.final_state = final_state(system, &q, &v, dynamics.orientations());
    match result {
        Ok(()) => Ok(summary),
        Err(error) => Err(Box::new(Failure { error, summary })),
    }
}

#[allow(clippy::too_many_arguments)]
fn run_inner(
    dynamics: &mut Dynamics<'_>,
    s: Settings,
    unit: Option<&Unit>,
    q: &mut Vec<[f64; 3]>,
    v: &mut Vec<[f64; 3]>,
    t0: f64,
    summary: &mut Summary,
    observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
) -> Result<(), SimError> {
    let system = dynamics.system();
    // Numbers of the run (in its unit) → the caller's unit, for everything reported.
    let row_back = |k: usize, x: f64| unit.map_or(x, |u| u.row_value(k, x));
    let length_back = |x: f64| unit.map_or(x, |u| u.length(x));
    let energy_back = |x: f64| unit.map_or(x, |u| u.energy(x));
    let mut shown = Shown::default();
    let (q0, v0) = (q.clone(), v.clone());
    let mut stepper = Stepper::new(s, system.constraints.len(), q.len());
    let energy_reported = !time_dependent(system);
    // The scene's size from the bodies' positions: a rigid body's angle is no length.
    let bodies = system.bodies.len();
    let length = length_scale(&q[..bodies]);
    let bound = s.blowup * length;
    let touch = CONTACT_TOLERANCE * length;
    let stride = (s.steps / s.samples.max(1) as u64).max(1);
    let plotted = bodies.min(8);
    let (mut kinetic0, mut work, mut max_energy_error, mut max_kinetic) = (0.0, 0.0, 0.0f64, 0.0f64);
    // `simulate::work_scale` at step 0: the balance's scale for a scene at rest.
    let mut scale0 = 0.0f64;
    // The last recorded state's positions and forces (slots), for the work over a step.
    let (mut q_1, mut force_1) = (q.clone(), vec![[0.0; 3]; q.len()]);
    let mut lambda = vec![0.0; system.constraints.len()];
    // 3D rigid bodies: T from the rows' body-frame ω, the work of the world torques over the
    // turn between the recorded orientations, log(q ⊗ q₋₁*), in place of the rotation vector.
    let three_d = !dynamics.orientations().is_empty();
    let (mut moved, mut force) = (q.clone(), vec![[0.0; 3]; q.len()]);
    let mut orientations_1 = dynamics.orientations().to_vec();
    for n in 0..=s.steps {
        let t = t0 + n as f64 * s.dt;
        dynamics.step = n;
        if three_d {
            dynamics.rebase(q);
            moved.copy_from_slice(q);
            let slots = (bodies..q.len()).step_by(3);
            for ((slot, now), before) in slots.zip(dynamics.orientations()).zip(&mut orientations_1) {
                moved[slot] = rotation::between_orientations(*before, *now);
                *before = *now;
            }
        }
        let rows = dynamics.rows(t, q, v)?;
        // `left`: the largest distance to a surface to be held (an inequality's violation).
        let (mut c_max, mut c_dot_max, mut left) = (0.0f64, 0.0f64, 0.0f64);
        for (k, row) in rows.rows.iter().enumerate() {
            let d = distance(row);
            if d.abs() > bound && (!row.inequality || d < 0.0) {
                let (constraint, value) = (system.constraints[k].name.clone(), row_back(k, row.value));
                let (distance, bound) = (length_back(d), length_back(bound));
                if n == 0 {
                    return Err(SimError::FarStart { time: t, constraint, value, distance: distance.abs(), bound });
                }
                let remedy = match s.solver {
                    Solver::SoftStep if !three_d => remedy(dynamics, t0, &q0, &v0, &s),
                    Solver::Pgs => Remedy::Iterations,
                    _ => Remedy::SubstepsOrDt,
                };
                return Err(SimError::Diverged {
                    step: n,
                    time: t,
                    solver: s.solver.name().into(),
                    constraint,
                    value,
                    distance,
                    bound,
                    remedy,
                });
            }
            let (value, rate) = (row_back(k, row.value), row_back(k, row.rate));
            if row.inequality {
                c_max = c_max.max((-value).max(0.0));
                left = left.max(-d);
                if d <= touch && rate < 0.0 {
                    c_dot_max = c_dot_max.max(-rate);
                }
            } else {
                c_max = c_max.max(value.abs());
                left = left.max(d.abs());
                c_dot_max = c_dot_max.max(rate.abs());
            }
        }
        // The last step's projection (the exact solve's) ended farther than it aimed for.
        if let Some(bound) = stepper.projection_bound.take().filter(|&bound| left > bound) {
            Unconverged::count(&mut summary.unconverged, n, length_back(left), length_back(bound));
        }
        summary.max_abs_c = summary.max_abs_c.max(c_max);
        summary.max_abs_c_dot = summary.max_abs_c_dot.max(c_dot_max);
        let mut kinetic = 0.0;
        let (velocity, position, applied) = if three_d {
            rotation::applied(&rows, &mut force);
            (&rows.velocity[..], &moved[..], &force[..])
        } else {
            (&v[..], &q[..], &rows.force[..])
        };
        for (v, w) in velocity.iter().zip(&rows.inverse_mass) {
            kinetic += 0.5 * dot(v, v) / w;
        }
        if n == 0 {
            kinetic0 = kinetic;
        } else {
            for (((f, f_1), x), x_1) in applied.iter().zip(&force_1).zip(position).zip(&q_1) {
                let mean = [0.5 * (f[0] + f_1[0]), 0.5 * (f[1] + f_1[1]), 0.5 * (f[2] + f_1[2])];
                work += dot(&mean, &[x[0] - x_1[0], x[1] - x_1[1], x[2] - x_1[2]]);
            }
        }
        q_1.copy_from_slice(q);
        force_1.copy_from_slice(applied);
        let energy_error = (kinetic - kinetic0) - work;
        max_energy_error = max_energy_error.max(energy_error.abs());
        max_kinetic = max_kinetic.max(kinetic);
        // The ratio is the same in any unit; the energies themselves may leave the f64 range
        // in the caller's.
        summary.max_kinetic = energy_back(max_kinetic);
        let energy_error = energy_back(energy_error);
        summary.final_energy_error = energy_error;
        if n == 0 {
            scale0 = work_scale(&rows.force, bodies, length);
        }
        let scale = max_kinetic.max(scale0);
        summary.energy_rel_drift =
            energy_reported.then(|| if scale > 0.0 { max_energy_error / scale } else { energy_back(max_energy_error) });
        if n.is_multiple_of(stride) || n == s.steps {
            let position = q[..plotted].iter().map(|x| unit.map_or(*x, |u| u.vector(*x))).collect();
            summary.samples.push(Sample { time: t, max_abs_c: c_max, energy_error, position });
        }
        // λ where it is wanted (`Settings::lambda_at`); elsewhere none, never a stale step's.
        if !s.lambda_at(n) {
            lambda.clear();
        } else if n > 0 {
            stepper.lambda(&mut lambda);
        }
        let frame = Frame {
            step: n,
            time: t,
            position: q,
            velocity: v,
            orientations: dynamics.orientations(),
            rows: &rows,
            lambda: &lambda,
            energy_error: Some(energy_error),
        };
        observe(&frame.shown(unit, &mut shown)).map_err(SimError::Output)?;
        summary.steps = n;
        summary.duration = n as f64 * s.dt;
        if n == s.steps {
            dynamics.recycle(rows);
            break;
        }
        stepper.wants_impulse = s.lambda_at(n + 1);
        stepper.step(dynamics, t, q, v, rows)?;
        for (i, (q, v)) in q.iter().zip(v.iter()).enumerate() {
            if !(q.iter().chain(v).all(|x| x.is_finite())) {
                let body = slot_name(system, i);
                return Err(SimError::NonFinite { step: n + 1, time: t + s.dt, body });
            }
        }
    }
    Ok(())
}

/// What would have kept a diverged soft step stable: the largest stable hertz at the initial
/// state, when the scene is small enough to analyse and it is below the hertz the run used.
fn remedy(dynamics: &mut Dynamics<'_>, t0: f64, q0: &[[f64; 3]], v0: &[[f64; 3]], s: &Settings) -> Remedy {
    if stability::state_len(dynamics.system(), s) > HINT_MAX_STATE {
        return Remedy::SubstepsOrHertz;
    }
    match stability::largest_stable_hertz(dynamics, t0, q0, v0, s) {
        Ok(stability::Limit::Hertz(hertz)) if hertz < s.joint_hertz() => {
            Remedy::StableUpTo { hertz, ran_at: s.joint_hertz() }
        }
        _ => Remedy::SubstepsOrHertz,
    }
}
