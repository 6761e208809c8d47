//! The run loop: integrate, stabilise, handle contacts, measure drift and energy, and hand
//! every state to an observer (CSV writer, progress bar) — with a summary at the end.
//!
//! A step: record the state (rows, λ, |C|, |Ċ|, energy balance) → integrate with the
//! acceleration just solved → project positions (Newton) → velocity solve (closing
//! contacts with restitution; with projection also Ċ = 0 for equalities). The state is
//! checked after every step: a NaN or a constraint farther from its surface than the
//! scene's size stops the run with the step and the constraint named, and what was
//! observed so far stays with the observer.
//!
//! Energy balance: E(t) = (T(t) − T(0)) − W(t), with T = ½ Σ mᵢ|vᵢ|² and W the work of the
//! external forces, ∫ Σ Fᵢ·vᵢ dt by the trapezoid rule over the recorded states with its
//! Euler–Maclaurin end correction (O(dt⁴), finer than any of the integrators); it is 0
//! for exact motion under time-independent constraints (their forces do no work), so
//! max |E| / max T measures the integrator. A constraint that depends on t does work, and
//! the figure is then not reported.
//!
//! Not here: files, text, printing (the observer does that), the λ solve.

use super::dynamics::{Dynamics, SimError, slot_name};
use super::integrate::{Integrator, Stepper, Vectors, add_scaled, copy_slots};
use super::rescale::{Shown, Unit};
use super::rotation::{fold, kick};
use super::rows::Rows;
use super::solve::{CONTACT_TOLERANCE, FactorId};
use super::stabilize::{
    Inequalities, ShakeHistory, Stabilize, StabilizeError, distance, project_positions, rattle_one_row,
    rattle_one_row_plain, shake_positions, update_rates, velocity_step,
};
use super::vector::{dot, length_scale, not_finite_bit, safe_norm};
use crate::expr::eval::{Env, Value};
use crate::model::system::System;
use std::time::Instant;

/// Samples kept for plots by default: 4000 points draw a smooth curve on any screen and keep
/// the SVG small.
pub const SAMPLES: usize = 4000;
/// Bodies whose trajectories are plotted (the first ones): more lines would not be readable.
const PLOTTED_BODIES: usize = 8;
/// A closing contact bounces only when faster than what `BOUNCE_STEPS` steps of the external
/// forces build up, plus `BOUNCE_SPEED_SHARE` of the initial top speed: a body at rest on a
/// floor (or a taut rope) gains one step's worth per step and must not bounce on it.
const BOUNCE_STEPS: f64 = 10.0;
const BOUNCE_SPEED_SHARE: f64 = 1e-6;

/// How a run goes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub integrator: Integrator,
    pub stabilize: Stabilize,
    pub dt: f64,
    pub steps: u64,
    /// Coefficient of restitution of closing contacts, in [0, 1].
    pub restitution: f64,
    /// The run stops when a constraint is farther than `blowup` × the scene's length from
    /// its surface.
    pub blowup: f64,
    /// Samples kept for plots (trajectory, |C|, energy); the CSV sees every step.
    pub samples: usize,
    /// What the run measures besides its steps and the checks that stop it: everything
    /// `lagrange simulate` reports ([`Measure::Everything`], the default), or the checks
    /// alone ([`Measure::Checks`]).
    pub measure: Measure,
    /// Whether the rows' tapes run as machine code ([`Compile`]): never by default.
    pub compile: Compile,
}

/// What a run measures besides its steps ([`Settings::measure`]): the figures of the summary
/// and the frames, which cost a run of a few rows a fifth of its step.
///
/// The checks are made under either: a state or a row that is not finite and a constraint
/// farther than `blowup` × the scene's length from its surface stop the run
/// ([`SimError`]), projections short of their tolerance are counted
/// ([`Summary::unconverged`]). The trajectory is the same bit for bit: nothing left out
/// feeds a step.
///
/// ```
/// use lagrange::numeric::simulate::{Measure, Settings};
/// let mut settings = Settings::new(1e-3, 1.0);
/// assert_eq!(settings.measure, Measure::Everything);
/// settings.measure = Measure::Checks; // the steps, without the energy balance and samples
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Measure {
    /// Everything `lagrange simulate` reports: the largest |C/κ| and |Ċ/κ|, the energy
    /// balance (in the summary and in every [`Frame`]) and the plot samples.
    #[default]
    Everything,
    /// The steps and their checks only. The summary says so ([`Summary::measured`]) and
    /// leaves the figures out: `max_abs_c`, `max_abs_c_dot`, `final_energy_error` and
    /// `max_kinetic` are not measured (0), `energy_rel_drift` is `None` and `samples` empty;
    /// a [`Frame`]'s `energy_error` is `None`. `steps`, `duration`, `evaluations`,
    /// `unconverged` and the final state are as under [`Measure::Everything`].
    Checks,
}

/// Whether a run compiles its rows' tapes to machine code before its first step
/// (`RowProgram::compile`, the `jit` feature): the steps are the same bit for bit either
/// way, and only their speed and the time at load differ. Without the `jit` feature every
/// choice means [`Compile::Never`], so a caller's settings work with either build.
///
/// [`Auto`](Compile::Auto) compiles when the run is long enough to pay the compilation
/// back ([`Compile::pays`]); a program that cannot be compiled (a host without a code
/// generator, a tape too big) keeps the interpreter, under any choice.
///
/// ```
/// use lagrange::numeric::simulate::{Compile, Settings};
/// let mut settings = Settings::new(1e-3, 100.0);
/// assert_eq!(settings.compile, Compile::Never);
/// settings.compile = Compile::Auto; // 100 000 steps: compiled, with the `jit` feature
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Compile {
    /// When the run's evaluations save more time than compiling costs ([`Compile::pays`]).
    Auto,
    /// Always, whatever the run's length.
    Always,
    /// Never: the interpreter runs the tapes (the library's default).
    #[default]
    Never,
}

/// Compiling a tape with Cranelift costs a fixed time per tape (its module and function),
/// about 90 µs, and about 7 µs per instruction of the tape ([`Tape::instructions`]); a
/// compiled evaluation then saves about 2 ns per instruction against the interpreter. This
/// machine's figures (2 cores, x86-64 with AVX2), measured on the pendulum, the double
/// pendulum and the 5- and 10-link chains: `docs/speed.md` (jit35). They set where
/// [`Compile::Auto`] turns, not any result.
///
/// [`Tape::instructions`]: crate::numeric::tape::Tape::instructions
pub const COMPILE_NS_PER_TAPE: f64 = 90_000.0;
/// The cost per tape instruction of compiling (see [`COMPILE_NS_PER_TAPE`]).
pub const COMPILE_NS_PER_INSTRUCTION: f64 = 7_000.0;
/// What an evaluation of a compiled tape saves per instruction (see [`COMPILE_NS_PER_TAPE`]).
pub const SAVED_NS_PER_INSTRUCTION: f64 = 2.0;

impl Compile {
    /// Whether a run that evaluates a program's tapes `evaluations` times is worth compiling
    /// them for, the rule of [`Compile::Auto`]: with `tapes` tapes of `instructions`
    /// instructions in all, compiling costs
    ///
    /// `COMPILE_NS_PER_TAPE · tapes + COMPILE_NS_PER_INSTRUCTION · instructions`
    ///
    /// and each evaluation, which runs one tape (of `instructions / tapes` on average),
    /// saves `SAVED_NS_PER_INSTRUCTION · instructions / tapes`; the run compiles when the
    /// savings reach the cost. The figures are this machine's (`docs/speed.md`, jit35); a
    /// wrong guess costs at most the compile time or the savings, never a result.
    ///
    /// ```
    /// use lagrange::numeric::simulate::Compile;
    /// // The pendulum's three tapes, 14 instructions in all: 0.37 ms to compile, 9 ns
    /// // saved an evaluation, so some 40 000 evaluations (20 000 steps) to pay back.
    /// assert!(!Compile::pays(3, 14, 2 * 10_000));
    /// assert!(Compile::pays(3, 14, 2 * 25_000));
    /// // The 10-link chain's, 232: 1.9 ms, 155 ns an evaluation, some 6 000 steps.
    /// assert!(!Compile::pays(3, 232, 2 * 5_000));
    /// assert!(Compile::pays(3, 232, 2 * 7_000));
    /// ```
    pub fn pays(tapes: usize, instructions: usize, evaluations: u64) -> bool {
        if tapes == 0 || instructions == 0 {
            return false;
        }
        let cost = COMPILE_NS_PER_TAPE * tapes as f64 + COMPILE_NS_PER_INSTRUCTION * instructions as f64;
        let saved = SAVED_NS_PER_INSTRUCTION * instructions as f64 / tapes as f64;
        evaluations as f64 * saved >= cost
    }

    /// Whether a run of `evaluations` row evaluations compiles under this choice: the rule
    /// of [`pays`](Compile::pays) for [`Auto`](Compile::Auto), with `tapes` and
    /// `instructions` those a compilation would compile; always `false` without the `jit`
    /// feature.
    pub fn wanted(self, tapes: usize, instructions: usize, evaluations: u64) -> bool {
        cfg!(feature = "jit")
            && match self {
                Compile::Never => false,
                Compile::Always => true,
                Compile::Auto => Compile::pays(tapes, instructions, evaluations),
            }
    }
}

/// Row evaluations a step of [`Simulation`] makes, for [`Compile::Auto`]'s estimate: the
/// start's rows (only those the velocities change, when the last step's end rows are
/// carried) and SHAKE's end rows (C and J) — 2.0 a step on the pendulum and the chains
/// (`Summary::evaluations`).
pub const EVALUATIONS_PER_STEP: u64 = 2;

impl Settings {
    pub fn new(dt: f64, duration: f64) -> Settings {
        Settings {
            integrator: Integrator::Verlet,
            stabilize: Stabilize::PROJECTION,
            dt,
            steps: steps_for(duration, dt),
            restitution: 0.0,
            blowup: 1.0,
            samples: SAMPLES,
            measure: Measure::Everything,
            compile: Compile::Never,
        }
    }

    /// Bad settings, before any loop runs.
    pub fn validate(&self) -> Result<(), SettingsError> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(SettingsError::Step(self.dt));
        }
        if !(0.0..=1.0).contains(&self.restitution) {
            return Err(SettingsError::Restitution(self.restitution));
        }
        if !(self.blowup.is_finite() && self.blowup > 0.0) {
            return Err(SettingsError::Blowup(self.blowup));
        }
        if self.steps > MAX_STEPS {
            return Err(SettingsError::TooManySteps { steps: self.steps as f64 });
        }
        Ok(self.stabilize.validate()?)
    }
}

/// A run setting out of range (`Settings::validate`).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum SettingsError {
    /// The step dt is not a finite positive number.
    #[error("the step must be finite and positive, found {0}")]
    Step(f64),
    /// The simulated time is not a finite positive number.
    #[error("the duration must be finite and positive, found {0}")]
    Duration(f64),
    /// The duration is shorter than half a step: the run would take no step.
    #[error("the step dt = {dt:e} is longer than twice the duration {duration:e}: the run would take no step")]
    NoStep { dt: f64, duration: f64 },
    /// More steps than [`MAX_STEPS`].
    #[error(
        "the run would take {steps:.3e} steps, more than the maximum of {} (numeric::simulate::MAX_STEPS); use a larger --dt or a shorter --duration",
        MAX_STEPS
    )]
    TooManySteps { steps: f64 },
    /// The restitution is outside [0, 1].
    #[error("the restitution must lie in [0, 1], found {0}")]
    Restitution(f64),
    /// The blow-up bound is not a finite positive number.
    #[error("the blow-up bound must be positive, found {0}")]
    Blowup(f64),
    /// A drift-control setting is out of range.
    #[error(transparent)]
    Stabilize(#[from] StabilizeError),
    /// A velocity-level run with no substeps.
    #[error("--substeps must be at least 1, found 0")]
    Substeps,
    /// A velocity-level run with zero iterations per substep.
    #[error("--iterations must be at least 1, found 0")]
    Iterations,
    /// A velocity-level run of more substeps (steps × substeps) than [`MAX_STEPS`].
    #[error(
        "the run would take {substeps:.3e} substeps (steps × --substeps), more than the maximum of {} (numeric::simulate::MAX_STEPS); use fewer --substeps, a larger --dt or a shorter --duration",
        MAX_STEPS
    )]
    TooManySubsteps { substeps: f64 },
    /// More iterations a substep than [`MAX_ITERATIONS`].
    #[error("--iterations must be at most {max}, found {found}")]
    TooManyIterations { found: usize, max: usize },
    /// The soft step's stiffness is not a finite positive frequency.
    #[error("--hertz must be finite and positive, found {0}")]
    Hertz(f64),
    /// The soft step's damping ratio is negative or not finite.
    #[error("--damping-ratio must be finite and at least 0, found {0}")]
    DampingRatio(f64),
    /// XPBD's compliance is negative or not finite.
    #[error("--compliance must be finite and at least 0, found {0}")]
    Compliance(f64),
    /// PGS's Baumgarte factor is outside [0, 1].
    #[error("the Baumgarte factor must lie in [0, 1], found {0}")]
    Baumgarte(f64),
}

/// The most iterations a substep of a velocity-level run may take (PGS's default is 8;
/// Box2D v2.4's velocity iterations 8): a larger count is a typo, not a setting.
pub const MAX_ITERATIONS: usize = 10_000;

/// The most steps one run takes (`simulate`, and each run of `bench`): a run asked for more
/// (`--duration inf`, a scene `dt = 1e-320`) is refused before it starts, never run for
/// ever. 10⁸ steps of a pendulum take about a minute.
pub const MAX_STEPS: u64 = 100_000_000;

/// The number of steps of `dt` that cover `duration` (rounded; 0 for a negative duration,
/// saturating for a huge one, which [`Settings::validate`] then refuses).
pub fn steps_for(duration: f64, dt: f64) -> u64 {
    (duration / dt).round().max(0.0) as u64
}

/// As [`steps_for`], refusing what cannot be a run: a step or a duration that is not a
/// finite number (a NaN duration would run 0 steps), a duration that rounds to 0 steps
/// (`--dt 1e300`), and more than [`MAX_STEPS`].
pub fn checked_steps(duration: f64, dt: f64) -> Result<u64, SettingsError> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(SettingsError::Step(dt));
    }
    if !(duration.is_finite() && duration > 0.0) {
        return Err(SettingsError::Duration(duration));
    }
    let steps = (duration / dt).round();
    if steps < 1.0 {
        return Err(SettingsError::NoStep { dt, duration });
    }
    if steps > MAX_STEPS as f64 {
        return Err(SettingsError::TooManySteps { steps });
    }
    Ok(steps as u64)
}

/// One recorded state, as the observer sees it.
pub struct Frame<'a> {
    pub step: u64,
    pub time: f64,
    pub position: &'a Vectors,
    pub velocity: &'a Vectors,
    /// Each 3D rigid body's orientation q = [w, x, y, z], in the order of the rigid bodies
    /// (their rotation-vector slots in `position` are zero at a recorded state); empty
    /// without 3D rigid bodies.
    pub orientations: &'a [[f64; 4]],
    /// The rows at this state (C/κ, Ċ/κ per constraint).
    pub rows: &'a Rows,
    pub lambda: &'a [f64],
    /// (T − T₀) − W; `None` when the run keeps no energy balance ([`Measure::Checks`]).
    pub energy_error: Option<f64>,
}

impl<'a> Frame<'a> {
    /// This frame, its numbers in the run's unit, in the caller's: itself when the run works
    /// in the scene's own unit, else converted through `shown` (buffers reused from step to
    /// step; a run in another unit has no 3D rigid body).
    pub fn shown(self, unit: Option<&Unit>, shown: &'a mut Shown) -> Frame<'a> {
        let Some(u) = unit else { return self };
        shown.convert(u, self.position, self.velocity, self.rows, self.lambda);
        Frame {
            position: &shown.q,
            velocity: &shown.v,
            orientations: &[],
            rows: &shown.rows,
            lambda: &shown.lambda,
            ..self
        }
    }
}

/// A sample for plots.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub time: f64,
    pub max_abs_c: f64,
    pub energy_error: f64,
    /// Positions of the first few bodies.
    pub position: Plotted,
}

/// The positions of the first bodies at a sample (at most `PLOTTED_BODIES`), held in
/// place: a run with the default samples records one at every step of a short run, and a
/// `Vec` each was an allocation a step (a few percent of a pendulum's). Read as a slice;
/// built by `collect`, which keeps the first `PLOTTED_BODIES` positions.
#[derive(Clone, Copy)]
pub struct Plotted {
    len: usize,
    at: [[f64; 3]; PLOTTED_BODIES],
}

impl std::ops::Deref for Plotted {
    type Target = [[f64; 3]];
    fn deref(&self) -> &[[f64; 3]] {
        &self.at[..self.len]
    }
}

impl Plotted {
    /// No position.
    const EMPTY: Plotted = Plotted { len: 0, at: [[0.0; 3]; PLOTTED_BODIES] };

    /// The first `PLOTTED_BODIES` of `positions`, in place of what it held.
    fn fill(&mut self, positions: impl IntoIterator<Item = [f64; 3]>) {
        self.len = 0;
        for (to, x) in self.at.iter_mut().zip(positions) {
            *to = x;
            self.len += 1;
        }
    }
}

impl FromIterator<[f64; 3]> for Plotted {
    fn from_iter<I: IntoIterator<Item = [f64; 3]>>(positions: I) -> Plotted {
        let mut plotted = Plotted::EMPTY;
        plotted.fill(positions);
        plotted
    }
}

impl PartialEq for Plotted {
    fn eq(&self, other: &Plotted) -> bool {
        **self == **other
    }
}

impl std::fmt::Debug for Plotted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

/// What a run measured.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    pub integrator: String,
    /// The stabilisation's name (`projection`, `baumgarte`, `none`); empty for a
    /// velocity-level run, whose settings are in `velocity`.
    pub stabilize: String,
    /// The settings of a velocity-level run (`numeric::velocity`), for its report.
    pub velocity: Option<super::velocity::Settings>,
    pub steps: u64,
    pub dt: f64,
    /// Simulated time.
    pub duration: f64,
    pub wall_seconds: f64,
    /// What the run measured ([`Settings::measure`]): under [`Measure::Checks`] the
    /// figures below that say so were not measured, and hold 0, `None` or nothing.
    pub measured: Measure,
    /// max over steps and constraints of |C/κ| (inequalities: their violation only); not
    /// measured under [`Measure::Checks`].
    pub max_abs_c: f64,
    /// max of |Ċ/κ| (inequalities: only while touching and closing); not measured under
    /// [`Measure::Checks`].
    pub max_abs_c_dot: f64,
    /// max |E| / max(max T, `work_scale` at step 0) (max |E| where both are 0); None
    /// when a constraint depends on time, or under [`Measure::Checks`].
    pub energy_rel_drift: Option<f64>,
    /// The energy balance E at the end, and max T (±∞ when outside the f64 range in the
    /// scene's unit; the ratio above is always finite); not measured under
    /// [`Measure::Checks`].
    pub final_energy_error: f64,
    pub max_kinetic: f64,
    /// Row evaluations (the cost unit).
    pub evaluations: u64,
    /// Whether some of the rows' tapes ran as machine code ([`Settings::compile`]); the
    /// numbers are the same either way.
    pub compiled: bool,
    /// Steps whose projection onto C = 0 (`--stabilize projection`, or the exact velocity
    /// solve's after each substep) ended farther from it than its tolerance, and how far;
    /// `None` when every projection reached it or the run does not project.
    pub unconverged: Option<Unconverged>,
    /// k when the run worked in a length unit of 2ᵏ (the scene's lengths were beyond
    /// 2^±[`NATURAL_RANGE`](super::dynamics::NATURAL_RANGE)); 0 when it ran in the scene's own. Every figure here is in the scene's unit.
    pub unit_exponent: i64,
    /// Symbol name → final value (positions and velocities).
    pub final_state: Vec<(String, Value)>,
    pub final_position: Vec<[f64; 3]>,
    pub final_velocity: Vec<[f64; 3]>,
    /// Samples for plots (at most [`Settings::samples`], and the last step); none under
    /// [`Measure::Checks`].
    pub samples: Vec<Sample>,
}

/// Projections that did not reach their tolerance: iterations spent or diverging, as
/// where C = 0 has a vanishing gradient (`dot(r, r) = 0`) or a step too large for the
/// quasi-Newton iteration. The run goes on from the positions reached (the drift check
/// stops it when they are out of reach); the summary says how far they were.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Unconverged {
    /// How many steps.
    pub steps: u64,
    /// The first one.
    pub first: u64,
    /// The largest distance |C|/‖∇C‖ left (in the scene's unit), and the tolerance's bound.
    pub distance: f64,
    pub bound: f64,
}

impl Unconverged {
    /// Counts step `step`, whose projection ended `distance` from C = 0 against `bound`
    /// (both in the scene's unit), into `unconverged`.
    pub fn count(unconverged: &mut Option<Unconverged>, step: u64, distance: f64, bound: f64) {
        let u = unconverged.get_or_insert(Unconverged { steps: 0, first: step, distance, bound });
        u.steps += 1;
        u.distance = u.distance.max(distance);
    }
}

/// A run that stopped early: why, and what it measured until then.
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    pub error: SimError,
    pub summary: Summary,
}

/// The positions and velocities that `env` gives the bodies.
///
/// A rigid body's angular slots come after every body (`numeric::rows`): in 2D component 0
/// of `[θ, 0, 0]` and `[ω, 0, 0]`; in 3D three slots, the first holding the rotation vector
/// φ = 0 (the orientation itself is the dynamics', `Dynamics::orientations`) and the world
/// ω, the other two zero (`numeric::rotation`).
pub fn initial_state(system: &System, env: &Env) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, f64) {
    let get = |s| env.get(s).and_then(Value::vector).unwrap_or([0.0; 3]);
    let angle = |s| [env.get(s).and_then(Value::scalar).unwrap_or(0.0), 0.0, 0.0];
    let mut q: Vec<[f64; 3]> = system.bodies.iter().map(|b| get(b.position)).collect();
    let mut v: Vec<[f64; 3]> = system.bodies.iter().map(|b| get(b.velocity)).collect();
    for rigid in system.bodies.iter().filter_map(|b| b.rigid.as_ref()) {
        if rigid.nodes.axes.is_some() {
            q.extend([[0.0; 3]; 3]);
            v.extend([get(rigid.angular_velocity), [0.0; 3], [0.0; 3]]);
        } else {
            q.push(angle(rigid.orientation));
            v.push(angle(rigid.angular_velocity));
        }
    }
    let t = env.get(system.time).and_then(Value::scalar).unwrap_or(0.0);
    (q, v, t)
}

/// The length scale of the state `env` gives (`numeric::vector::length_scale` of the bodies'
/// positions; a rigid body's angle is no length): what contact distances, drift and
/// off-constraint distances count against.
pub fn scene_length(system: &System, env: &Env) -> f64 {
    let (q, _, _) = initial_state(system, env);
    length_scale(&q[..system.bodies.len()])
}

/// The state at the end of a run by symbol name, for the summary: each body's position and
/// velocity, then each rigid body's angle and angular velocity from its slot after the bodies
/// (3D: its orientation from `orientations`, in the order of the 3D rigid bodies, and the
/// world ω; the state's rotation vector must have been folded in, `Dynamics::rebase`).
pub fn final_state(system: &System, q: &[[f64; 3]], v: &[[f64; 3]], orientations: &[[f64; 4]]) -> Vec<(String, Value)> {
    let name = |s| system.graph.symbol(s).name.clone();
    let mut state = Vec::new();
    for (i, body) in system.bodies.iter().enumerate() {
        state.push((name(body.position), Value::Vector(q[i])));
        state.push((name(body.velocity), Value::Vector(v[i])));
    }
    let mut slot = system.bodies.len();
    let mut turned = orientations.iter();
    for rigid in system.bodies.iter().filter_map(|b| b.rigid.as_ref()) {
        match (rigid.nodes.axes, turned.next()) {
            (Some(_), Some(&q0)) => {
                state.push((name(rigid.orientation), Value::Quaternion(q0)));
                state.push((name(rigid.angular_velocity), Value::Vector(v[slot])));
                slot += 3;
            }
            _ => {
                state.push((name(rigid.orientation), Value::Scalar(q[slot][0])));
                state.push((name(rigid.angular_velocity), Value::Scalar(v[slot][0])));
                slot += 1;
            }
        }
    }
    state
}

/// Whether some constraint depends on t (its force then does work).
pub fn time_dependent(system: &System) -> bool {
    system.constraints.iter().any(|c| system.graph.free_symbols(c.c).contains(&system.time))
}

/// A simulation in progress: the state and its scratch.
pub struct Simulation<'s> {
    dynamics: Dynamics<'s>,
    settings: Settings,
    stepper: Stepper,
    t0: f64,
    q: Vec<[f64; 3]>,
    v: Vec<[f64; 3]>,
    a: Vec<[f64; 3]>,
    /// v½ of a RATTLE step.
    half: Vec<[f64; 3]>,
    /// Verlet's predicted velocity v½ + dt/2 a₀ (3D rigid bodies' second kick).
    predicted: Vec<[f64; 3]>,
    /// Whether some body is a 3D rigid body: Euler and Verlet then kick with the implicit
    /// gyroscopic term (`numeric::rotation::kick`).
    three_d: bool,
    /// The length unit the run works in, when not the scene's own (see [`Dynamics::choose_unit`]).
    unit: Option<Unit>,
    /// What the observer sees when the run works in another unit: the state, rows and λ
    /// converted back (buffers reused from step to step).
    shown: Shown,
    /// The rows of the step's start, and of its end (after the step: at the positions and
    /// time the next step starts from, C/κ and J; the rest was spent by the velocity step).
    /// Kept here and swapped, never moved by value: a `Rows` moved through a `Result` is a
    /// copy each time, a few of them a step. Boxed, so that the swap at every step's start
    /// exchanges two pointers, not the two headers' sixteen words.
    start: Box<Rows>,
    end: Box<Rows>,
    /// Whether `end` serves the next step's start, which then evaluates only what the
    /// velocities change (`Dynamics::rows_moved_into`); else every row is evaluated.
    carried: bool,
    /// The marks of the kept factors the last solves of `start` and `end` went through
    /// (`Dynamics::made`, `solve::FactorId`), while their J is unchanged: SHAKE's iterations
    /// solve along the start's J, and the next start's solve has the end rows' J.
    start_made: Option<FactorId>,
    end_made: Option<FactorId>,
    /// C/κ of the end rows, kept across the velocity step that overwrites it.
    values: Vec<f64>,
    /// Whether some constraint is an inequality (found once, not at every step).
    has_inequalities: bool,
    /// SHAKE's multipliers of the last steps, for its prediction (`stabilize::ShakeHistory`;
    /// not used with inequalities or 3D rigid bodies).
    shake: ShakeHistory,
    /// Whether some of the rows' tapes run as machine code ([`Settings::compile`]).
    compiled: bool,
    /// Whether RATTLE's steps may take the one-row step (`stabilize::rattle_one_row`) and the
    /// start's solve its closed form on one slot (`Dynamics::solve_one_slot`): a scene of one
    /// slot and one constraint, unless told otherwise ([`Simulation::set_one_row`]); each
    /// declines rows of another shape. And how many steps took the one-row step.
    one_row: bool,
    one_row_steps: u64,
    /// Whether those runs' solves go without the scaling where its guard allows
    /// (`single::unscaled_multiplier`; [`Simulation::set_unscaled`]).
    unscaled: bool,
}

impl<'s> Simulation<'s> {
    pub fn new(mut dynamics: Dynamics<'s>, env: &Env, settings: Settings) -> Result<Simulation<'s>, SimError> {
        settings.validate().map_err(SimError::Settings)?;
        // The gyroscopic term −ω × Iω depends on ω: Verlet's second kick needs its own solve.
        if !dynamics.orientations().is_empty() {
            dynamics.velocity_dependent_forces = true;
        }
        let unit = dynamics.choose_unit(env)?;
        let (q, v, t0) = match &unit {
            Some(unit) => initial_state(dynamics.system(), &unit.to_unit(env)),
            None => initial_state(dynamics.system(), env),
        };
        dynamics.baumgarte = settings.stabilize.baumgarte_terms(settings.dt);
        let compiled = dynamics.compile_rows(settings.compile, settings.steps.saturating_mul(EVALUATIONS_PER_STEP));
        let n = q.len();
        let three_d = !dynamics.orientations().is_empty();
        let has_inequalities = dynamics.system().constraints.iter().any(|c| c.inequality);
        let one_constraint = dynamics.system().constraints.len() == 1;
        Ok(Simulation {
            dynamics,
            settings,
            stepper: Stepper::new(settings.integrator, n),
            t0,
            q,
            v,
            a: vec![[0.0; 3]; n],
            half: vec![[0.0; 3]; n],
            predicted: vec![[0.0; 3]; n],
            three_d,
            unit,
            shown: Shown::default(),
            start: Box::default(),
            end: Box::default(),
            carried: false,
            start_made: None,
            end_made: None,
            values: Vec::new(),
            has_inequalities,
            shake: ShakeHistory::default(),
            compiled,
            one_row: n == 1 && one_constraint,
            one_row_steps: 0,
            unscaled: true,
        })
    }

    /// Whether RATTLE's steps (Verlet with projection) on a scene of one equality row on one
    /// slot (the pendulum, a bead) take the step written for that shape
    /// (`stabilize::rattle_one_row`), as they do unless told otherwise: the same numbers bit
    /// for bit as the general step, which `false` forces (for tests that compare the two).
    pub fn set_one_row(&mut self, on: bool) {
        self.one_row = on && self.q.len() == 1 && self.dynamics.system().constraints.len() == 1;
    }

    /// Whether RATTLE's one-row runs (the plain step, `stabilize::rattle_one_row_plain`, and
    /// each step's start before it) solve their one row without the scaling where the
    /// magnitudes allow (`single::unscaled_multiplier`: one division where the scaled solve
    /// chains three square roots and seven divisions; the same numbers to a few roundings), as
    /// they do unless told otherwise; `false` keeps the scaled solve, whose numbers are the
    /// general step's bit for bit (for tests that compare the two).
    pub fn set_unscaled(&mut self, on: bool) {
        self.unscaled = on;
    }

    /// How many steps of the runs so far took the one-row step ([`set_one_row`](Simulation::set_one_row)).
    pub fn one_row_steps(&self) -> u64 {
        self.one_row_steps
    }

    /// Runs all steps, calling `observe` at every recorded state (step 0 … steps).
    pub fn run(&mut self, observe: &mut dyn FnMut(&Frame) -> Result<(), String>) -> Result<Summary, Box<Failure>> {
        let start = Instant::now();
        let system = self.dynamics.system();
        let s = self.settings;
        self.carried = false;
        self.shake = ShakeHistory::default();
        let mut summary = Summary {
            integrator: s.integrator.name().into(),
            stabilize: s.stabilize.name().into(),
            dt: s.dt,
            measured: s.measure,
            compiled: self.compiled,
            unit_exponent: self.unit.as_ref().map_or(0, |u| u.exponent),
            ..Summary::default()
        };
        let result = self.run_inner(s, &mut summary, observe);
        summary.wall_seconds = start.elapsed().as_secs_f64();
        summary.evaluations = self.dynamics.evaluations;
        // 3D rigid bodies: the last step's rotation vectors into the orientations reported.
        self.dynamics.rebase(&mut self.q);
        let back = |x: &[f64; 3]| self.unit.as_ref().map_or(*x, |u| u.vector(*x));
        summary.final_position = self.q.iter().map(back).collect();
        summary.final_velocity = self.v.iter().map(back).collect();
        // Angles are no lengths: the unit converts the bodies' slots only.
        let n = system.bodies.len();
        let (mut q, mut v) = (summary.final_position.clone(), summary.final_velocity.clone());
        q[n..].copy_from_slice(&self.q[n..]);
        v[n..].copy_from_slice(&self.v[n..]);
        summary.final_state = final_state(system, &q, &v, self.dynamics.orientations());
        match result {
            Ok(()) => Ok(summary),
            Err(error) => Err(Box::new(Failure { error, summary })),
        }
    }

    /// A NaN or infinity in the state stops the run, naming the body.
    #[inline(always)]
    fn check_finite(&self, step: u64, time: f64) -> Result<(), SimError> {
        // One slot (a pendulum, a bead): its six numbers in one test, the loop only to name it.
        if let ([q], [v]) = (self.q.as_slice(), self.v.as_slice())
            && [q[0], q[1], q[2], v[0], v[1], v[2]].iter().fold(0u64, |bad, x| bad | not_finite_bit(*x)) >> 63 == 0
        {
            return Ok(());
        }
        self.check_slots(step, time)
    }

    /// [`check_finite`](Simulation::check_finite) slot by slot.
    #[inline(never)]
    fn check_slots(&self, step: u64, time: f64) -> Result<(), SimError> {
        for (i, (q, v)) in self.q.iter().zip(&self.v).enumerate() {
            if !(q.iter().chain(v).all(|x| x.is_finite())) {
                let body = slot_name(self.dynamics.system(), i);
                return Err(SimError::NonFinite { step, time, body });
            }
        }
        Ok(())
    }

    /// With 3D rigid bodies, the first part of Euler's and Verlet's step: the kick v += h a₀
    /// with the gyroscopic term at the implicit midpoint (`rotation::kick` at the start's
    /// rows; h = dt for Euler, dt/2 for Verlet), then the drift q += dt v.
    fn first_kick(&mut self, h: f64) {
        self.half.copy_from_slice(&self.v);
        kick(&self.start, h, &self.a, &self.half, &mut self.v);
        add_scaled(&mut self.q, self.settings.dt, &self.v);
    }

    /// With 3D rigid bodies, Verlet's second kick at t⁺: v⁺ = v½ + dt/2 a(q⁺, ṽ) at the
    /// predicted ṽ = v½ + dt/2 a₀, the gyroscopic term at the implicit midpoint.
    fn second_kick(&mut self, t1: f64, dt: f64) -> Result<(), SimError> {
        for ((p, v), a) in self.predicted.iter_mut().zip(&self.v).zip(&self.a) {
            for d in 0..3 {
                p[d] = v[d] + 0.5 * dt * a[d];
            }
        }
        self.dynamics.kick_at(t1, &self.q, &self.predicted, 0.5 * dt, &mut self.v)
    }

    /// Newton onto C = 0 at `t` (`stabilize::project_positions`): the rows at the result.
    fn project(&mut self, t: f64, length: f64, tolerance: f64, max_iterations: usize) -> Result<Rows, SimError> {
        let (rows, _) = project_positions(
            &mut self.dynamics,
            t,
            &mut self.q,
            &self.v,
            tolerance * length,
            max_iterations,
            Inequalities::Violated,
        )?;
        Ok(rows)
    }

    fn run_inner(
        &mut self,
        s: Settings,
        summary: &mut Summary,
        observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
    ) -> Result<(), SimError> {
        let mut figures = Figures::default();
        let mut balance = EnergyBalance::default();
        // One loop for each measure, the figures' work compiled out of the other's.
        let result = match s.measure {
            Measure::Everything => self.steps::<true>(s, summary, &mut figures, &mut balance, observe),
            Measure::Checks => self.steps::<false>(s, summary, &mut figures, &mut balance, observe),
        };
        // What the steps recorded, whether the run ended or stopped.
        let unit = self.unit.as_ref();
        let energy_back = |x: f64| unit.map_or(x, |u| u.energy(x));
        summary.steps = figures.steps;
        summary.duration = figures.steps as f64 * s.dt;
        if figures.recorded && s.measure == Measure::Everything {
            summary.max_abs_c = figures.max_abs_c;
            summary.max_abs_c_dot = figures.max_abs_c_dot;
            // The ratio is the same in any unit; the energies themselves may leave the f64
            // range in the caller's (a 1e155 m pendulum has T ≈ 1e311 J).
            summary.max_kinetic = energy_back(balance.max_kinetic);
            summary.final_energy_error = figures.energy_error;
            summary.energy_rel_drift = (!self.dynamics.time_dependent()).then(|| {
                let scale = balance.max_kinetic.max(balance.work_scale);
                if scale > 0.0 { balance.max_error / scale } else { energy_back(balance.max_error) }
            });
        }
        result
    }

    /// The steps of [`run_inner`](Simulation::run_inner): the summary's running figures go
    /// to `figures` and `balance`, which it writes into the summary once the steps end.
    /// `MEASURE`: whether the run measures them ([`Measure::Everything`]), else only the
    /// checks are made, the steps counted and the start's largest acceleration taken.
    fn steps<const MEASURE: bool>(
        &mut self,
        s: Settings,
        summary: &mut Summary,
        figures: &mut Figures,
        balance: &mut EnergyBalance,
        observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
    ) -> Result<(), SimError> {
        let system = self.dynamics.system();
        // Numbers of the run (in its unit) → the caller's unit, for everything reported.
        let unit = self.unit.clone();
        let energy_back = |x: f64| unit.as_ref().map_or(x, |u| u.energy(x));
        let length_back = |x: f64| unit.as_ref().map_or(x, |u| u.length(x));
        // The scene's length scale (in the run's unit): positions only, not a rigid body's angle.
        let length = length_scale(&self.q[..system.bodies.len()]);
        let mut reach =
            Reach { length, bound: s.blowup * length, touch: CONTACT_TOLERANCE * length, bounce_speed: 0.0 };
        let stride = (s.steps / s.samples.max(1) as u64).max(1);
        let plotted = system.bodies.len().min(PLOTTED_BODIES);
        // Every sample the run will keep, at once (a step's push never reallocates).
        if MEASURE {
            summary
                .samples
                .reserve((s.steps / stride).saturating_add(2).min(s.samples.saturating_add(2) as u64) as usize);
        }
        // The next sampled step, a multiple of `stride` (counted, rather than a division
        // of n at every step).
        let mut next_sample = 0;
        // Step n's time t₀ + n dt, computed once a step: the last step's t1 (the same
        // formula), and at the start as at n = 0.
        let mut t = self.t0 + 0.0 * s.dt;
        // RATTLE's step for one equality row on the only slot of a steady scene (the plain
        // step's run: `stabilize::rattle_one_row_plain`), whose solves go without the scaling.
        let plain_rattle = matches!((s.integrator, s.stabilize), (Integrator::Verlet, Stabilize::Projection { .. }))
            && self.one_row
            && self.unscaled
            && !self.has_inequalities
            && !self.three_d
            && self.dynamics.steady
            && !self.dynamics.velocity_dependent_forces;
        for n in 0..=s.steps {
            self.dynamics.step = n;
            // 3D rigid bodies: the rotation vectors of the last step into the orientations.
            if self.three_d {
                self.dynamics.rebase(&mut self.q);
            }
            // C and J at these positions came with the last step's end rows, if it kept them:
            // they become the start's, and the start's buffers the end's for the step to come.
            // The end rows' mark goes with them while their J is kept.
            let end_made = self.end_made.take();
            self.start_made = None;
            let mut kept = false;
            if std::mem::take(&mut self.carried) {
                std::mem::swap(&mut self.start, &mut self.end);
                // One row on one point mass: its motion's numbers in line.
                kept = (self.one_row && self.dynamics.rows_moved_one_slot(&self.q, &self.v, &mut self.start))
                    || self.dynamics.rows_moved_into(t, &self.q, &self.v, &mut self.start)?;
                if kept {
                    self.start_made = end_made;
                }
            } else {
                let rows = self.dynamics.rows(t, &self.q, &self.v)?;
                let old = std::mem::replace(&mut *self.start, rows);
                self.dynamics.recycle(old);
            }
            // The rows' distances, when SHAKE measured them at these C and J.
            let known = self.shake.end_distances(kept);
            let (c_max, c_dot_max, left) =
                Self::drift::<MEASURE>(system, self.unit.as_ref(), &self.start, known, n, t, &reach)?;
            let rows = &self.start;
            // Every step's positions were projected to `bound` (the start's are as given).
            if let (Stabilize::Projection { tolerance, .. }, true) = (s.stabilize, n > 0) {
                let bound = tolerance * reach.length;
                if left > bound {
                    Unconverged::count(&mut summary.unconverged, n, length_back(left), length_back(bound));
                }
            }
            // E(t) and, at step 0, the largest |M⁻¹F|, which the steps need (not E) under either.
            let (energy_error, accel) = if MEASURE {
                figures.max_abs_c = figures.max_abs_c.max(c_max);
                figures.max_abs_c_dot = figures.max_abs_c_dot.max(c_dot_max);
                let (energy_error, accel) = balance.record(rows, n, s.dt);
                (energy_back(energy_error), accel)
            } else if n == 0 {
                (f64::NAN, largest_acceleration(rows))
            } else {
                (f64::NAN, 0.0)
            };
            if n == 0 {
                let speed = self.v.iter().map(safe_norm).fold(0.0, f64::max);
                // Approaches slower than what ten steps of the external forces build up do not bounce.
                reach.bounce_speed = BOUNCE_STEPS * s.dt * accel + BOUNCE_SPEED_SHARE * speed;
                // A contact's rate counts as zero against what the forces build in a step
                // too: at rest the bodies' speeds are rounding, and so are the rates.
                // (Not past f64's range: then the bodies' speeds alone, as before.)
                let scale = s.dt * accel;
                self.dynamics.settings.speed_scale = if scale.is_finite() { scale } else { 0.0 };
            }
            figures.energy_error = energy_error;
            figures.recorded = true;
            if MEASURE && n == 0 {
                balance.work_scale = work_scale(&rows.force, system.bodies.len(), length);
            }
            // One row on the only slot: its acceleration in closed form, else the solve's.
            let one_slot = match (self.one_row, plain_rattle) {
                // RATTLE's one-row run: without the scaling where the guard allows.
                (true, true) => self
                    .dynamics
                    .solve_one_slot_unscaled(&self.start)
                    .or_else(|| self.dynamics.solve_one_slot(&mut self.start)),
                (true, false) => self.dynamics.solve_one_slot(&mut self.start),
                _ => None,
            };
            if one_slot.is_none() {
                self.dynamics.solve_known(&mut self.start, self.start_made);
            }
            self.start_made = self.dynamics.made();
            // The active set for the step to come: contacts that push are held (without
            // inequalities nothing is, and the set stays empty).
            if self.has_inequalities {
                self.dynamics.hold_solved(&self.start);
            }
            let sampled = n == next_sample;
            if sampled {
                next_sample += stride;
            }
            if MEASURE && (sampled || n == s.steps) {
                // Written where it is kept: a `Sample` built aside is a copy of its positions' room.
                let position = self.q[..plotted].iter().map(|x| unit.as_ref().map_or(*x, |u| u.vector(*x)));
                summary.samples.push(Sample { time: t, max_abs_c: c_max, energy_error, position: Plotted::EMPTY });
                if let Some(sample) = summary.samples.last_mut() {
                    sample.position.fill(position);
                }
            }
            self.show(n, t, MEASURE.then_some(energy_error), observe)?;
            figures.steps = n;
            if n == s.steps {
                break;
            }
            match (one_slot, self.a.as_mut_slice()) {
                // No 3D rigid body's slot to fold on one slot (`solve_one_slot`'s rows).
                (Some(a), [to]) => *to = a,
                _ => {
                    copy_slots(&mut self.a, &self.dynamics.solution().acceleration);
                    fold(&self.start, &mut self.a);
                }
            }
            self.dynamics.step = n + 1;
            let t1 = self.t0 + (n + 1) as f64 * s.dt;
            self.advance(&s, n, [t, t1], &reach)?;
            t = t1;
        }
        Ok(())
    }

    /// |C| and |Ċ| of what should be zero at step `n` (in the caller's unit; an inequality
    /// counts only its violation and, near its surface, its closing rate), and the largest
    /// distance |C|/‖∇C‖ of the same (in the run's unit); stops the run when a value is not
    /// finite or a surface is out of reach. `known`: each row's distance, when SHAKE measured
    /// it at the same C and J (`ShakeHistory::end_distances`), else computed here.
    /// `FIGURES`: whether |C| and |Ċ| are wanted; else they are 0 and only the checks and the
    /// distance are made.
    fn drift<const FIGURES: bool>(
        system: &System,
        unit: Option<&Unit>,
        rows: &Rows,
        known: Option<&[f64]>,
        n: u64,
        t: f64,
        reach: &Reach,
    ) -> Result<(f64, f64, f64), SimError> {
        let row_back = |q: usize, x: f64| unit.map_or(x, |u| u.row_value(q, x));
        let length_back = |x: f64| unit.map_or(x, |u| u.length(x));
        let (mut c_max, mut c_dot_max, mut left) = (0.0f64, 0.0f64, 0.0f64);
        let known = known.filter(|d| d.len() == rows.rows.len());
        for (k, row) in rows.rows.iter().enumerate() {
            let d = match known {
                Some(d) => d[k],
                None => distance(row),
            };
            if !(row.value.is_finite() && row.rate.is_finite()) {
                let value = if row.value.is_finite() { row.rate } else { row.value };
                let constraint = system.constraints[k].name.clone();
                return Err(SimError::NonFiniteRow { step: n, time: t, constraint, value });
            }
            if d.abs() > reach.bound && (!row.inequality || d < 0.0) {
                let (constraint, value) = (system.constraints[k].name.clone(), row_back(k, row.value));
                let (distance, bound) = (length_back(d), length_back(reach.bound));
                return Err(match n {
                    0 => SimError::FarStart { time: t, constraint, value, distance: distance.abs(), bound },
                    step => SimError::Drift { step, time: t, constraint, value, distance, bound },
                });
            }
            if !FIGURES {
                left = left.max(if row.inequality { -d } else { d.abs() });
                continue;
            }
            let (value, rate) = (row_back(k, row.value), row_back(k, row.rate));
            if row.inequality {
                c_max = c_max.max((-value).max(0.0));
                left = left.max(-d);
                if d <= reach.touch && rate < 0.0 {
                    c_dot_max = c_dot_max.max(-rate);
                }
            } else {
                c_max = c_max.max(value.abs());
                left = left.max(d.abs());
                c_dot_max = c_dot_max.max(rate.abs());
            }
        }
        Ok((c_max, c_dot_max, left))
    }

    /// Hands the state of step `n` to the observer, in the caller's unit (its rows are the
    /// start's, λ of the step's solve, `Dynamics::solution`).
    #[inline(always)]
    fn show(
        &mut self,
        n: u64,
        t: f64,
        energy_error: Option<f64>,
        observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
    ) -> Result<(), SimError> {
        let frame = Frame {
            step: n,
            time: t,
            position: &self.q,
            velocity: &self.v,
            orientations: self.dynamics.orientations(),
            rows: &self.start,
            lambda: &self.dynamics.solution().lambda,
            energy_error,
        };
        // In the scene's own unit the frame as it is (not moved through `Frame::shown`).
        let shown = match &self.unit {
            None => observe(&frame),
            unit => observe(&frame.shown(unit.as_ref(), &mut self.shown)),
        };
        shown.map_err(SimError::Output)
    }

    /// From step `n` at time `t` (its rows in `self.start`, its accelerations in `self.a`)
    /// to step n + 1 at `t1`: integrate, then stabilise and resolve contacts as the
    /// settings `s` (the run's) say; the rows at the end, where there are any, in `self.end`.
    #[inline(always)]
    fn advance(&mut self, s: &Settings, n: u64, [t, t1]: [f64; 2], reach: &Reach) -> Result<(), SimError> {
        let has_inequalities = self.has_inequalities;
        // The end rows' mark, when the velocity step solved them through a kept factor.
        // The end rows' C/κ go to `values` before the step spends them (`Simulation::carry`).
        let velocity_step =
            |dynamics: &mut Dynamics<'_>, end: &mut Rows, v: &mut Vectors, values: &mut Vec<f64>, equalities: bool| {
                let (touch, bounce) = (reach.touch, reach.bounce_speed);
                let applied = velocity_step(end, v, equalities, touch, s.restitution, bounce, dynamics, values);
                if applied { dynamics.made() } else { None }
            };
        // The velocity step spends the end rows' C, Ċ and c but keeps J, and the positions
        // stay where the rows were evaluated: with C put back they serve the next start
        // (not with 3D rigid bodies, whose orientations are rebased there).
        let keep = !self.three_d;
        if let (Integrator::Verlet, Stabilize::Projection { tolerance, max_iterations }) = (s.integrator, s.stabilize) {
            // One equality row on the only slot: the same step written for that shape.
            if self.one_row && !has_inequalities && !self.three_d {
                // The plain step first, from the numbers in hand; else the one-row step's stages.
                let plain = self.dynamics.steady && !self.dynamics.velocity_dependent_forces;
                if let (true, [q], [v], [half], [a]) =
                    (plain, self.q.as_mut_slice(), self.v.as_mut_slice(), self.half.as_mut_slice(), self.a.as_slice())
                    && let Some(made) = rattle_one_row_plain(
                        &mut self.dynamics,
                        s.dt,
                        [q, v, half],
                        a,
                        &self.start,
                        &mut self.end,
                        tolerance * reach.length,
                        &mut self.shake,
                        &mut self.values,
                        self.unscaled,
                    )
                {
                    self.one_row_steps += 1;
                    self.end_made = made;
                    self.carry(keep);
                    return Ok(());
                }
                let made = rattle_one_row(
                    &mut self.dynamics,
                    t1,
                    s.dt,
                    &mut self.q,
                    &mut self.v,
                    &mut self.half,
                    &self.a,
                    &mut self.start,
                    &mut self.end,
                    self.start_made,
                    [reach.length, tolerance],
                    max_iterations,
                    &mut self.shake,
                    [reach.touch, s.restitution, reach.bounce_speed],
                    &mut self.values,
                )?;
                if let Some(made) = made {
                    self.one_row_steps += 1;
                    self.end_made = made;
                    self.carry(keep);
                    return self.check_finite(n + 1, t1);
                }
            }
            // RATTLE: drift, SHAKE along the start's gradients, kick, velocity projection.
            if self.three_d {
                self.first_kick(0.5 * s.dt);
            } else {
                Stepper::verlet_drift(s.dt, &mut self.q, &mut self.v, &self.a);
            }
            shake_positions(
                &mut self.dynamics,
                t1,
                s.dt,
                &mut self.q,
                &mut self.v,
                &mut self.start,
                &mut self.end,
                self.start_made,
                reach.length,
                tolerance,
                max_iterations,
                (!has_inequalities && !self.three_d).then_some(&mut self.shake),
            )?;
            if has_inequalities {
                let projected = self.project(t1, reach.length, tolerance, max_iterations)?;
                self.replace_end(projected);
            }
            copy_slots(&mut self.half, &self.v);
            if self.three_d {
                self.second_kick(t1, s.dt)?;
            } else if self.dynamics.velocity_dependent_forces {
                self.stepper.verlet_kick(&mut self.dynamics, t1, s.dt, &self.q, &mut self.v, &self.a)?;
            } else {
                // v⁺ = v½ + dt/2 M⁻¹F(q⁺): the constraint part of the kick is what the
                // velocity projection below removes anyway, so no solve is needed here.
                for ((v, f), w) in self.v.iter_mut().zip(&self.end.force).zip(&self.end.inverse_mass) {
                    for d in 0..3 {
                        v[d] += 0.5 * s.dt * f[d] * w;
                    }
                }
            }
            update_rates(&mut self.end, &self.half, &self.v);
            self.end_made = velocity_step(&mut self.dynamics, &mut self.end, &mut self.v, &mut self.values, true);
            self.carry(keep);
            return self.check_finite(n + 1, t1);
        }
        match s.integrator {
            Integrator::Euler if self.three_d => self.first_kick(s.dt),
            Integrator::Verlet if self.three_d => {
                self.first_kick(0.5 * s.dt);
                self.second_kick(t1, s.dt)?;
            }
            _ => self.stepper.step(&mut self.dynamics, t, s.dt, &mut self.q, &mut self.v, &self.a)?,
        }
        self.check_finite(n + 1, t1)?;
        match s.stabilize {
            Stabilize::Projection { tolerance, max_iterations } => {
                let projected = self.project(t1, reach.length, tolerance, max_iterations)?;
                self.replace_end(projected);
                self.end_made = velocity_step(&mut self.dynamics, &mut self.end, &mut self.v, &mut self.values, true);
                self.carry(keep);
            }
            _ if has_inequalities => {
                let rows = self.dynamics.rows(t1, &self.q, &self.v)?;
                self.replace_end(rows);
                self.end_made = velocity_step(&mut self.dynamics, &mut self.end, &mut self.v, &mut self.values, false);
                self.carry(keep);
            }
            _ => {}
        }
        Ok(())
    }
}

impl Simulation<'_> {
    /// `rows` become the end rows; the buffers they replace go back to the dynamics.
    fn replace_end(&mut self, rows: Rows) {
        let old = std::mem::replace(&mut *self.end, rows);
        self.dynamics.recycle(old);
    }

    /// The end rows after the velocity step: with their C/κ put back where the step spent
    /// them (`values` holds them then: `stabilize::velocity_step`), the next step's start
    /// (`keep`), else left as scratch.
    fn carry(&mut self, keep: bool) {
        if keep {
            if self.end.rows.len() == self.values.len() {
                for (row, &c) in self.end.rows.iter_mut().zip(&self.values) {
                    row.value = c;
                }
            }
            self.carried = true;
        }
    }
}

/// The summary's figures as a run goes (in the caller's unit), written into it when the run
/// ends or stops (`Simulation::run_inner`): the largest |C| and |Ċ| so far, the energy
/// balance of the last recorded step, whether any step was recorded, and the last step
/// handed to the observer.
#[derive(Default)]
struct Figures {
    max_abs_c: f64,
    max_abs_c_dot: f64,
    energy_error: f64,
    recorded: bool,
    steps: u64,
}

/// The run's lengths (in its unit): the scene's scale, the distance from a surface that
/// stops the run, the distance at which a contact touches, and the slowest approach that
/// bounces.
struct Reach {
    length: f64,
    bound: f64,
    touch: f64,
    bounce_speed: f64,
}

/// The energy a scene's forces can exchange over its size: Σ|Fᵢ|·size over the bodies'
/// slots plus Σ|τᵢ|·1 rad over the rotation slots after them. The energy balance is reported
/// relative to the larger of this and the largest kinetic energy: a scene at rest has no
/// kinetic energy to compare with (its balance over the rounding-level T would read 1e13).
pub(crate) fn work_scale(force: &[[f64; 3]], bodies: usize, size: f64) -> f64 {
    let (forces, torques) = force.split_at(bodies.min(force.len()));
    forces.iter().map(safe_norm).sum::<f64>() * size + torques.iter().map(safe_norm).sum::<f64>()
}

/// The largest |M⁻¹F| over the rows' slots: what the step's start measures for the bounce
/// speed and the contacts' rate scale (`Simulation::steps`).
fn largest_acceleration(rows: &Rows) -> f64 {
    let slots = rows.force.iter().zip(&rows.inverse_mass);
    slots.fold(0.0f64, |accel, (f, w)| accel.max(safe_norm(f) * w))
}

/// The energy balance's running sums: E(t) = T − T₀ − ∫ F·v dt, the integral by the
/// trapezoid with its Euler–Maclaurin end correction.
#[derive(Default)]
struct EnergyBalance {
    kinetic0: f64,
    /// The trapezoid's ∫ P dt so far.
    work: f64,
    max_error: f64,
    max_kinetic: f64,
    /// [`work_scale`] at step 0.
    work_scale: f64,
    /// P at steps n−2 and n−1, and dP/dt at step 0, for the end correction.
    power_2: f64,
    power_1: f64,
    power_rate0: f64,
}

impl EnergyBalance {
    /// Records step `n` from its rows; returns E(t) in the run's unit and, at step 0, the
    /// largest |M⁻¹F| (0 at the other steps).
    fn record(&mut self, rows: &Rows, n: u64, dt: f64) -> (f64, f64) {
        let (mut kinetic, mut power) = (0.0, 0.0);
        // Over the rows' slots: a 3D rigid body's T = ½ Σₖ Iₖ (eₖ·ω)², and its forces
        // τₖ − (ω × Iω)ₖ, whose gyroscopic part does no work.
        for ((u, f), w) in rows.velocity.iter().zip(&rows.force).zip(&rows.inverse_mass) {
            kinetic += 0.5 * dot(u, u) / w;
            power += dot(f, u);
        }
        // The largest acceleration is wanted at step 0 only (the bounce speed).
        let accel = if n == 0 { largest_acceleration(rows) } else { 0.0 };
        if n == 0 {
            self.kinetic0 = kinetic;
        } else {
            self.work += 0.5 * (self.power_1 + power) * dt;
        }
        // Euler–Maclaurin: ∫P dt = trapezoid − dt²/12 (Ṗ(t) − Ṗ(0)) + O(dt⁴), with Ṗ from
        // second-order one-sided differences, so the balance measures the integrator and
        // not the quadrature (the plain trapezoid's O(dt²) would hide RK4's error).
        let mut end_correction = 0.0;
        if n == 2 {
            self.power_rate0 = (-3.0 * self.power_2 + 4.0 * self.power_1 - power) / (2.0 * dt);
        }
        if n >= 2 {
            let power_rate = (3.0 * power - 4.0 * self.power_1 + self.power_2) / (2.0 * dt);
            end_correction = -dt * dt / 12.0 * (power_rate - self.power_rate0);
        }
        (self.power_2, self.power_1) = (self.power_1, power);
        let error = (kinetic - self.kinetic0) - (self.work + end_correction);
        self.max_error = self.max_error.max(error.abs());
        self.max_kinetic = self.max_kinetic.max(kinetic);
        (error, accel)
    }
}
