//! The solver bench (`lagrange bench FILE --solvers`): every velocity-level solver × substeps
//! (× stiffness for the soft step) on one scene, next to the exact velocity solve at the
//! finest substep as the reference, with the soft step's largest stable hertz at the initial
//! state (`velocity::stability`; not for 3D rigid bodies, whose runs it measures all the same).
//!
//! Per run: max |C| and max |Ċ| (C/κ, as the rows), the largest energy balance |E| relative
//! to the larger of the largest kinetic energy and the work scale (the run's
//! `energy_rel_drift`, `simulate::work_scale`), the jitter (the spread max − min of each row's λ = P/h over the
//! second half of the run, relative to the largest mean |λ|: 0 for a scene at rest solved
//! exactly), the final state's distance from the reference run relative to the scene's size
//! (the bodies' positions: a rigid body's angle enters through the points its joints hold),
//! and the wall time per step. A run that diverges keeps its figures up to the step it
//! stopped at and says why.
//!
//! Not here: text, JSON, CSV and SVG (`report::solvers`).

use super::run::run;
use super::stability::{
    Limit, at_rest_in_equilibrium, has_inequalities, has_rigid_3d, largest_stable_hertz, state_len,
};
use super::{Settings, Solver};
use crate::expr::eval::Env;
use crate::model::system::System;
use crate::numeric::dynamics::{Dynamics, SimError};
use crate::numeric::rows::RowProgram;
use crate::numeric::simulate::{SettingsError, Summary, initial_state};
use crate::numeric::solve::safe_norm;

/// A scene ready to run: the system, its rows and its initial state (what
/// `scenario::Scenario` holds, without the file).
#[derive(Clone, Copy)]
pub struct Scene<'a> {
    pub system: &'a System,
    pub program: &'a RowProgram,
    pub env: &'a Env,
    /// The scene's coefficient of restitution.
    pub restitution: f64,
}

/// What the bench runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    pub dt: f64,
    pub steps: u64,
    pub substeps: Vec<usize>,
    /// The soft step's stiffnesses (each capped at a quarter of the substep rate; a capped
    /// value equal to an earlier one is not run twice).
    pub hertz: Vec<f64>,
    pub damping_ratio: f64,
    /// Iterations per substep (None: each solver's default).
    pub iterations: Option<usize>,
    /// State vectors up to this length get the stability analysis.
    pub stability_max_state: usize,
}

impl Plan {
    /// Substeps 1, 2, 4, 8; the soft step at 15, 30 and 60 Hz with ζ = 2.
    pub fn new(dt: f64, steps: u64) -> Plan {
        Plan {
            dt,
            steps,
            substeps: vec![1, 2, 4, 8],
            hertz: vec![15.0, 30.0, 60.0],
            damping_ratio: 2.0,
            iterations: None,
            stability_max_state: 600,
        }
    }
}

/// One run of the bench.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub solver: Solver,
    pub substeps: usize,
    pub iterations: usize,
    /// The soft step's stiffness as run (after the cap); None for the other solvers.
    pub hertz: Option<f64>,
    pub steps: u64,
    pub max_abs_c: f64,
    pub max_abs_c_dot: f64,
    pub energy_drift: Option<f64>,
    pub jitter: f64,
    /// |q − q_reference| at the end, over the scene's size (None when either run stopped).
    pub deviation: Option<f64>,
    pub seconds_per_step: f64,
    /// Why the run stopped early.
    pub failure: Option<SimError>,
}

/// The soft step's largest stable hertz at the initial state, per substep count (a step
/// that cannot be evaluated there counts as [`Limit::NoRadius`]).
#[derive(Clone, Debug, PartialEq)]
pub struct StableHertz {
    pub substeps: usize,
    pub relax: Limit,
    pub no_relax: Limit,
}

/// The bench's results.
#[derive(Clone, Debug, PartialEq)]
pub struct SolverBench {
    pub title: String,
    pub dt: f64,
    pub damping_ratio: f64,
    pub reference: Entry,
    pub entries: Vec<Entry>,
    /// Empty when not analysed (`not_analysed` says why).
    pub stable_hertz: Vec<StableHertz>,
    pub not_analysed: Option<NotAnalysed>,
}

/// Why the bench has no stable hertz.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NotAnalysed {
    /// The state is longer than [`Plan::stability_max_state`].
    TooLarge,
    /// The scene has 3D rigid bodies ([`Limit::Rigid3d`]).
    Rigid3d,
    /// The initial state is not at rest in equilibrium ([`Limit::Moving`]).
    Moving,
    /// The scene has inequality rows ([`Limit::Contacts`]).
    Contacts,
}

/// Runs `settings`, recording λ over the second half; returns the entry and the final positions.
fn measure(scene: Scene<'_>, settings: Settings) -> (Entry, Option<Vec<[f64; 3]>>) {
    let half = settings.steps / 2;
    let rows = scene.system.constraints.len();
    let (mut lo, mut hi, mut sum, mut count) =
        (vec![f64::INFINITY; rows], vec![f64::NEG_INFINITY; rows], vec![0.0; rows], 0u64);
    let dynamics = Dynamics::new(scene.system, scene.program.clone(), scene.env.clone());
    let bodies = scene.system.bodies.len();
    let result = run(dynamics, scene.env, settings, &mut |frame| {
        if frame.step > half {
            for (k, &l) in frame.lambda.iter().enumerate() {
                lo[k] = lo[k].min(l);
                hi[k] = hi[k].max(l);
                sum[k] += l;
            }
            count += 1;
        }
        Ok(())
    });
    let (summary, failure, end): (Summary, Option<SimError>, _) = match result {
        Ok(s) => {
            let end = s.final_position[..bodies].to_vec();
            (s, None, Some(end))
        }
        Err(f) => (f.summary, Some(f.error), None),
    };
    let scale = sum.iter().map(|s| (s / count.max(1) as f64).abs()).fold(0.0, f64::max);
    let spread =
        lo.iter().zip(&hi).filter(|(l, h)| l.is_finite() && h.is_finite()).map(|(l, h)| h - l).fold(0.0, f64::max);
    let jitter = if count > 0 && scale > 0.0 { spread / scale } else { 0.0 };
    let steps = summary.steps;
    let entry = Entry {
        solver: settings.solver,
        substeps: settings.substeps,
        iterations: settings.iterations(),
        hertz: (settings.solver == Solver::SoftStep).then(|| settings.joint_hertz()),
        steps,
        max_abs_c: summary.max_abs_c,
        max_abs_c_dot: summary.max_abs_c_dot,
        energy_drift: summary.energy_rel_drift,
        jitter,
        deviation: None,
        seconds_per_step: summary.wall_seconds / steps.max(1) as f64,
        failure,
    };
    (entry, end)
}

/// The bench of `plan` on `scene`.
pub fn solver_bench(scene: Scene<'_>, plan: &Plan) -> Result<SolverBench, SimError> {
    if plan.substeps.is_empty() || plan.substeps.contains(&0) {
        return Err(SimError::Settings(SettingsError::Substeps));
    }
    let settings_for = |solver: Solver, substeps: usize, hertz: f64| {
        let mut s = Settings::new(solver, plan.dt, 0.0);
        s.steps = plan.steps;
        s.substeps = substeps;
        s.iterations = plan.iterations;
        s.hertz = hertz;
        s.damping_ratio = plan.damping_ratio;
        s.restitution = scene.restitution;
        s
    };
    let finest = plan.substeps.iter().copied().max().unwrap_or(1);
    let reference_settings = settings_for(Solver::Exact, finest, 60.0);
    reference_settings.validate()?;
    let (reference, end) = measure(scene, reference_settings);
    let (q0, v0, t0) = initial_state(scene.system, scene.env);
    let size = q0[..scene.system.bodies.len()].iter().map(safe_norm).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let mut entries = Vec::new();
    for solver in [Solver::SoftStep, Solver::Pgs, Solver::Xpbd, Solver::Exact] {
        for &substeps in &plan.substeps {
            let mut seen: Vec<f64> = Vec::new();
            let hertz: &[f64] = if solver == Solver::SoftStep { &plan.hertz } else { &[60.0] };
            for &h in hertz {
                let settings = settings_for(solver, substeps, h);
                settings.validate()?;
                if solver == Solver::SoftStep {
                    if seen.contains(&settings.joint_hertz()) {
                        continue;
                    }
                    seen.push(settings.joint_hertz());
                }
                let (mut entry, q) = measure(scene, settings);
                if let (Some(q), Some(r)) = (&q, &end) {
                    let d = q
                        .iter()
                        .zip(r)
                        .map(|(a, b)| safe_norm(&[a[0] - b[0], a[1] - b[1], a[2] - b[2]]))
                        .fold(0.0, f64::max);
                    entry.deviation = Some(d / size);
                }
                entries.push(entry);
            }
        }
    }
    let mut stable_hertz = Vec::new();
    let probe = settings_for(Solver::SoftStep, 1, 60.0);
    let mut dynamics = Dynamics::new(scene.system, scene.program.clone(), scene.env.clone());
    let not_analysed = if has_rigid_3d(scene.system) {
        Some(NotAnalysed::Rigid3d)
    } else if state_len(scene.system, &probe) > plan.stability_max_state {
        Some(NotAnalysed::TooLarge)
    } else if has_inequalities(scene.system) {
        Some(NotAnalysed::Contacts)
    } else if !at_rest_in_equilibrium(&mut dynamics, t0, &q0, &v0).unwrap_or(false) {
        Some(NotAnalysed::Moving)
    } else {
        None
    };
    if not_analysed.is_none() {
        for &substeps in &plan.substeps {
            let mut limit = |relax: bool| {
                let s = Settings { relax, ..settings_for(Solver::SoftStep, substeps, 60.0) };
                largest_stable_hertz(&mut dynamics, t0, &q0, &v0, &s).unwrap_or(Limit::NoRadius)
            };
            let (relax, no_relax) = (limit(true), limit(false));
            stable_hertz.push(StableHertz { substeps, relax, no_relax });
        }
    }
    Ok(SolverBench {
        title: scene.system.title.clone(),
        dt: plan.dt,
        damping_ratio: plan.damping_ratio,
        reference,
        entries,
        stable_hertz,
        not_analysed,
    })
}
