//! `lagrange bench`: speed against error. A work-precision sweep of the simulation
//! (integrator × stabilisation × step size against a fine reference run) and the formula
//! accuracy of the derived forces (f64 against double-double).
//!
//! Work-precision. Every method runs the same scene for the same simulated time at ≥ 4
//! step sizes (those that give the same number of steps run once); the reference is the same scene with RK4 + projection at a step 16 times
//! finer than the finest of the sweep. Per run: wall time per simulated second, max |C|,
//! max |Ċ|, the energy balance, and the final-state error: max |qᵢ − qᵢ,ref| over the
//! scene's size, or, where larger, a rigid body's turn from its reference orientation in
//! radians (2D |θ − θ_ref|, 3D the angle of q q_ref*; a point at distance ℓ from the centre
//! moves ℓ times that, so for a body of the scene's size the two measures agree). Plotted as
//! error against time (log-log), a method further down-left is better: less error for the
//! same time.
//!
//! The module is named for what it measures (work against precision); "bench" names the
//! command and the timing benchmarks in `benches/`.
//!
//! Not here: printing or files (`report::precision`, `main.rs`).

pub mod accuracy;
pub mod reference;

use crate::expr::eval::Value;
use crate::model::system::System;
use crate::numeric::dynamics::SimError;
use crate::numeric::integrate::Integrator;
use crate::numeric::rotation::between_orientations;
use crate::numeric::simulate::{MAX_STEPS, Summary};
use crate::numeric::stabilize::Stabilize;
use crate::numeric::vector::{length_scale, safe_norm};
use crate::scenario::Scenario;

/// What to sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    pub integrators: Vec<Integrator>,
    pub stabilizers: Vec<Stabilize>,
    /// Step sizes, at least 4.
    pub steps: Vec<f64>,
    pub duration: f64,
    /// The reference step is the finest step divided by this; 16 by default, so the RK4
    /// reference's error is 16⁴ ≈ 6.5·10⁴ times below what RK4 makes at the finest step and
    /// does not show in any method's error.
    pub refinement: f64,
}

impl Sweep {
    /// Every method, at dt × 4, 2, 1, ½ of the scene's step.
    pub fn new(dt: f64, duration: f64) -> Sweep {
        Sweep {
            integrators: Integrator::ALL.to_vec(),
            stabilizers: vec![Stabilize::None, Stabilize::BAUMGARTE, Stabilize::PROJECTION],
            steps: vec![4.0 * dt, 2.0 * dt, dt, 0.5 * dt],
            duration,
            refinement: 16.0,
        }
    }

    /// The step sizes that run, in order: each gives the duration a whole number of steps
    /// (rounded, at least 1), and a step size whose number equals an earlier one's is the
    /// same run, left out (a duration shorter than a few steps gives one run, not four alike).
    pub fn distinct_steps(&self) -> Vec<(f64, u64)> {
        let mut out: Vec<(f64, u64)> = Vec::with_capacity(self.steps.len());
        for &dt in &self.steps {
            let n = steps_for(self.duration, dt);
            if !out.iter().any(|&(_, m)| m == n) {
                out.push((dt, n));
            }
        }
        out
    }

    pub fn validate(&self) -> Result<(), SweepError> {
        if self.steps.len() < 4 {
            return Err(SweepError::TooFewSteps(self.steps.len()));
        }
        if self.steps.iter().any(|dt| !(dt.is_finite() && *dt > 0.0)) {
            return Err(SweepError::Step);
        }
        if !(self.duration.is_finite() && self.duration > 0.0) {
            return Err(SweepError::Duration(self.duration));
        }
        if self.integrators.is_empty() || self.stabilizers.is_empty() {
            return Err(SweepError::Empty);
        }
        if !(self.refinement.is_finite() && self.refinement >= 1.0) {
            return Err(SweepError::Refinement(self.refinement));
        }
        // The reference run has the most steps: bounded like any run (`MAX_STEPS`).
        let finest = self.steps.iter().copied().fold(f64::INFINITY, f64::min);
        let reference = (self.duration / (finest / self.refinement)).round();
        if reference > MAX_STEPS as f64 {
            return Err(SweepError::TooManySteps { steps: reference });
        }
        Ok(())
    }
}

/// A sweep that cannot run, before any run starts.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum SweepError {
    /// Fewer than 4 step sizes (a slope needs a few points).
    #[error("a sweep needs at least 4 step sizes, found {0}")]
    TooFewSteps(usize),
    /// A step size is zero, negative or not finite.
    #[error("step sizes must be finite and positive")]
    Step,
    /// The simulated time is not a finite positive number.
    #[error("the duration must be positive, found {0}")]
    Duration(f64),
    /// No integrator or no stabilisation to run.
    #[error("nothing to sweep")]
    Empty,
    /// The reference step is not the finest step divided by a finite factor ≥ 1.
    #[error("the reference refinement must be finite and at least 1, found {0}")]
    Refinement(f64),
    /// The reference run would take more than `MAX_STEPS` steps.
    #[error(
        "the reference run would take {steps:.3e} steps, more than the maximum of {} (numeric::simulate::MAX_STEPS); use a larger --dt or a shorter --duration",
        MAX_STEPS
    )]
    TooManySteps { steps: f64 },
}

/// One run of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepRow {
    pub integrator: String,
    pub stabilize: String,
    pub dt: f64,
    pub steps: u64,
    /// Wall seconds per simulated second.
    pub wall_per_second: f64,
    pub max_abs_c: f64,
    pub max_abs_c_dot: f64,
    pub energy_error: Option<f64>,
    /// max |qᵢ − qᵢ,ref| / the scene's size, or a rigid body's turn from its reference
    /// orientation (radians) where larger; None when the run failed.
    pub final_error: Option<f64>,
    /// Why the run stopped, if it did.
    pub failure: Option<SimError>,
}

/// The reference run and the sweep's rows.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkPrecision {
    pub reference_dt: f64,
    pub reference_steps: u64,
    pub reference_wall_seconds: f64,
    /// Why the reference run (RK4 + projection at `reference_dt`) failed, if it did (the
    /// final-state errors are then unknown).
    pub reference_error: Option<SimError>,
    pub rows: Vec<SweepRow>,
}

/// A rigid body's orientation at the end of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Orientation {
    Angle(f64),
    Quaternion([f64; 4]),
}

/// Each rigid body's final orientation (`Summary::final_state`, by its symbol's name), in
/// the order of the bodies.
fn orientations(system: &System, summary: &Summary) -> Vec<Orientation> {
    let named = |name: &str| summary.final_state.iter().find(|(n, _)| n == name).map(|(_, v)| *v);
    let rigid = system.bodies.iter().filter_map(|b| b.rigid.as_ref());
    rigid
        .filter_map(|r| match named(&system.graph.symbol(r.orientation).name)? {
            Value::Scalar(theta) => Some(Orientation::Angle(theta)),
            Value::Quaternion(q) => Some(Orientation::Quaternion(q)),
            Value::Vector(_) => None,
        })
        .collect()
}

/// The angle (radians) of the turn from `b` to `a`: |θ_a − θ_b| in 2D, |log(q_a q_b*)| in
/// 3D (the shorter way round).
fn turn_between(a: Orientation, b: Orientation) -> f64 {
    match (a, b) {
        (Orientation::Angle(x), Orientation::Angle(y)) => (x - y).abs(),
        (Orientation::Quaternion(x), Orientation::Quaternion(y)) => safe_norm(&between_orientations(y, x)),
        // One body is one kind in both runs.
        _ => f64::INFINITY,
    }
}

fn steps_for(duration: f64, dt: f64) -> u64 {
    (duration / dt).round().max(1.0) as u64
}

/// Runs the sweep over `scenario`.
pub fn work_precision(scenario: &Scenario, sweep: &Sweep) -> Result<WorkPrecision, SweepError> {
    sweep.validate()?;
    let run = |integrator, stabilize, dt: f64| -> Result<Summary, SimError> {
        let mut settings = scenario.settings();
        settings.integrator = integrator;
        settings.stabilize = stabilize;
        // Same simulated time for every step: round the step count, then fit dt to it.
        settings.steps = steps_for(sweep.duration, dt);
        settings.dt = sweep.duration / settings.steps as f64;
        scenario.simulate(settings, &mut |_| Ok(())).map_err(|f| f.error)
    };
    let finest = sweep.steps.iter().copied().fold(f64::INFINITY, f64::min);
    let reference_dt = finest / sweep.refinement;
    // A failed reference leaves the final-state errors unknown, not the rest of the table.
    let (reference, reference_error) = match run(Integrator::Rk4, Stabilize::PROJECTION, reference_dt) {
        Ok(s) => (Some(s), None),
        Err(e) => (None, Some(e)),
    };
    // The bodies' positions only: a rigid body's angle (its slot after the bodies) is no length.
    let bodies = scenario.system.bodies.len();
    let reference_position =
        reference.as_ref().map(|r| r.final_position[..bodies.min(r.final_position.len())].to_vec());
    let length = length_scale(reference_position.iter().flatten());
    let reference_turns = reference.as_ref().map(|r| orientations(&scenario.system, r));
    let mut rows = Vec::new();
    for &integrator in &sweep.integrators {
        for &stabilize in &sweep.stabilizers {
            for (dt, steps) in sweep.distinct_steps() {
                let row = match run(integrator, stabilize, dt) {
                    Ok(s) => {
                        let error =
                            reference_position.as_ref().zip(reference_turns.as_ref()).map(|(reference, turns)| {
                                let position = s
                                    .final_position
                                    .iter()
                                    .zip(reference)
                                    .flat_map(|(a, b)| (0..3).map(move |d| (a[d] - b[d]).abs()))
                                    .fold(0.0, f64::max)
                                    / length;
                                let turned = orientations(&scenario.system, &s);
                                turned.iter().zip(turns).map(|(a, b)| turn_between(*a, *b)).fold(position, f64::max)
                            });
                        SweepRow {
                            integrator: integrator.name().into(),
                            stabilize: stabilize.name().into(),
                            dt: s.dt,
                            steps,
                            wall_per_second: s.wall_seconds / s.duration.max(f64::MIN_POSITIVE),
                            max_abs_c: s.max_abs_c,
                            max_abs_c_dot: s.max_abs_c_dot,
                            energy_error: s.energy_rel_drift,
                            final_error: error,
                            failure: None,
                        }
                    }
                    Err(e) => SweepRow {
                        integrator: integrator.name().into(),
                        stabilize: stabilize.name().into(),
                        dt: sweep.duration / steps as f64,
                        steps,
                        wall_per_second: f64::NAN,
                        max_abs_c: f64::NAN,
                        max_abs_c_dot: f64::NAN,
                        energy_error: None,
                        final_error: None,
                        failure: Some(e),
                    },
                };
                rows.push(row);
            }
        }
    }
    let reference_steps = steps_for(sweep.duration, reference_dt);
    Ok(WorkPrecision {
        reference_dt: sweep.duration / reference_steps as f64,
        reference_steps,
        reference_wall_seconds: reference.as_ref().map_or(f64::NAN, |r| r.wall_seconds),
        reference_error,
        rows,
    })
}
