//! The equations of motion at a state: rows → λ → accelerations, behind one function.
//!
//! [`Dynamics::rows`] is where a simulation turns a state (t, q, v) into numbers:
//! [`RowProgram::evaluate_into`] runs the compiled tape into rows recycled from earlier
//! evaluations ([`Dynamics::recycle`]), so a warm step allocates nothing there. Beside it,
//! [`Dynamics::positions`] evaluates C and J alone, and [`Dynamics::rows_moved`] completes
//! rows whose C and J are those of the state (only Ċ, c and the bodies' numbers again).
//! [`Dynamics`] is a [`Field`] for the integrators, with the Baumgarte terms (when chosen)
//! added to the bias c before the solve. [`Dynamics::choose_unit`] moves a scene whose
//! lengths are far from 1 (|r| ≈ 1e155 or 1e-150) to a verified power-of-two unit
//! (`numeric::rescale::Unit`); the run loop converts what it reports back.
//!
//! The dynamics also keep the run's active set of contacts ([`Dynamics::hold`]): a contact
//! that pushes at the start of a step is an equality for the whole step (every integrator
//! stage, SHAKE, the projections), and is released only at the start of a step whose solve
//! gives it λ = 0 (λ would turn negative) or finds it opening. Without it a resting contact
//! on a curved surface drifts off by O(dt³) in a step, counts as apart, falls for a step
//! and is caught again: λ = 0 on some frames, energy lost, RK4's stages disagreeing.
//!
//! A state's slots are the bodies' positions and velocities, then each rigid body's angular
//! slots in the order of `numeric::rows`: in 2D its angle and angular velocity (`[θ, 0, 0]`,
//! `[ω, 0, 0]`), in 3D three slots whose first holds the world rotation vector φ since the
//! start of the step and the world ω (`numeric::rotation`; the orientation is
//! exp(φ) ⊗ q₀, q₀ kept here in [`Dynamics::orientations`]) and whose other two are zero.
//! So the integrators and the projections advance θ or φ and ω as they advance x and v; the
//! solve's per-axis accelerations and corrections are folded into world vectors
//! (`rotation::fold`) before they reach the state.
//!
//! Not here: the run loop, projection, contacts (`numeric::stabilize`), files or text.

use super::contact::ContactState;
use super::integrate::{Field, Vectors, copy_slots};
use super::rescale::{Unit, spread};
use super::rotation::{dexp_inv, fold, kick, rebase, turned};
use super::rows::{OneSlot, Row, RowProgram, RowScratch, Rows, State, angular_bodies, angular_width};
use super::simulate::{Compile, SettingsError};
use super::single::{
    SingleScaling, correction_single, correction_single_multiplier, solve_one_slot, solve_one_slot_unscaled,
    solve_single_with,
};
use super::solve::{Answer, Diagnostic, FactorId, MAX_DENSE_ROWS, Settings, Solution, SolveCache, Status, cached_into};
use crate::expr::eval::{Env, EvalError, Value};
use crate::model::problem::shown;
use crate::model::system::System;
use std::borrow::Cow;

/// Why a simulation stopped.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("cannot evaluate the rows at t = {t}: {error}", t = shown(*.time))]
    Eval { time: f64, error: EvalError },
    #[error("step {step} (t = {t}): the state or force of body `{body}` is not finite", t = shown(*.time))]
    NonFinite { step: u64, time: f64, body: String },
    #[error(
        "step {step} (t = {t}): constraint `{constraint}` evaluates to {value} — its formula overflows or is undefined at this state (check the scene's scale and the singular points of C)",
        t = shown(*.time)
    )]
    NonFiniteRow { step: u64, time: f64, constraint: String, value: f64 },
    #[error(
        "step {step} (t = {t}): constraint `{constraint}` drifted to C = {value:.3e} (distance {distance:.3e}, bound {bound:.3e}); the run blew up — try a smaller --dt (and --stabilize projection if it is off)",
        t = shown(*.time)
    )]
    Drift { step: u64, time: f64, constraint: String, value: f64, distance: f64, bound: f64 },
    /// A constraint out of reach at the initial state: no step has run, so no step size or
    /// solver setting is the cause.
    #[error(
        "at the initial state (t = {t}) constraint `{constraint}` is C = {value:.3e}, a distance |C|/‖∇C‖ of {distance:.3e} from where it holds, beyond the bound {bound:.3e} (the scene's size): no step can start from there — check the initial state ([scene] initial, --set, --at); a gradient that nearly vanishes there, as near a singular point of C, makes this distance large too",
        t = shown(*.time)
    )]
    FarStart { time: f64, constraint: String, value: f64, distance: f64, bound: f64 },
    #[error(
        "step {step} (t = {t}): the {solver} step diverged at constraint `{constraint}` (C = {value:.3e}, distance {distance:.3e}, bound {bound:.3e}){remedy}",
        t = shown(*.time)
    )]
    Diverged {
        step: u64,
        time: f64,
        solver: String,
        constraint: String,
        value: f64,
        distance: f64,
        bound: f64,
        /// What would have helped.
        remedy: Remedy,
    },
    #[error(
        "the scene's independent parts differ in size beyond what one length unit can serve (about 2^{small} and 2^{large}): a run in a unit near the larger would lose the smaller below f64's range; simulate them as separate files"
    )]
    MixedScales { small: i64, large: i64 },
    #[error(
        "step {step}: {rows} coupled rows could not be solved — they are redundant and contradict each other, or no sparse factor serves them, and a dense solve is limited to {limit} rows; the run stops rather than step on without those constraints (check the file for a duplicated or conflicting constraint)"
    )]
    TooLarge { step: u64, rows: usize, limit: usize },
    #[error("cannot write the output: {0}")]
    Output(String),
    #[error("invalid settings: {0}")]
    Settings(#[from] SettingsError),
}

/// What would have kept a diverged velocity-level run stable ([`SimError::Diverged`]); its
/// message is the end of the error's.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum Remedy {
    /// The soft step's largest stable hertz at the initial state (`velocity::stability`), below
    /// the stiffness it ran at.
    #[error("; at the initial state the soft step is stable up to {hertz:.3} Hz (--hertz), it ran at {ran_at} Hz")]
    StableUpTo { hertz: f64, ran_at: f64 },
    /// A soft step the stability analysis could not place (too large a scene, no limit found).
    #[error("; try more --substeps or a lower --hertz")]
    SubstepsOrHertz,
    /// XPBD or the exact velocity solve.
    #[error("; try more --substeps or a smaller --dt")]
    SubstepsOrDt,
    /// PGS: its sweeps left part of the impulses unsolved, and the part of the Baumgarte
    /// bias β·C/h they leave in the velocities adds up over the substeps, so more substeps
    /// make it worse (Catto's two particles diverge sooner at 100 substeps than at 4, and
    /// hold at 32 iterations: `tests/velocity_solvers.rs`).
    #[error(
        "; try more --iterations: Gauss–Seidel converges slowly across a large mass ratio, and the Baumgarte bias it leaves unsolved adds up (more --substeps do not help)"
    )]
    Iterations,
}

/// Baumgarte's terms b += 2αĊ + β²C, stored as (2α, β²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaumgarteTerms {
    pub two_alpha: f64,
    pub beta_squared: f64,
}

/// Scenes whose lengths lie within 2^±32 of 1 run in their own unit: squares and products of
/// a few such numbers stay far from the ends of the f64 range, and the solve's absolute
/// thresholds (a contact's `length_scale` of 1) still mean something.
pub const NATURAL_RANGE: i64 = 32;

/// Rows kept for reuse: a step holds at most three at once (RATTLE's start, SHAKE's end and
/// the projection's), so a fourth spare is never short and memory stays bounded.
const SPARE_ROWS: usize = 4;

/// The equations of motion of a system at any state.
pub struct Dynamics<'s> {
    system: &'s System,
    /// The rows' program: owned, or borrowed from a `Scenario` that runs it many times (a
    /// copy of its tapes per run is a visible part of a short run's cost).
    program: Cow<'s, RowProgram>,
    scratch: RowScratch,
    /// Rows handed back by [`recycle`](Dynamics::recycle), refilled by the next evaluation
    /// so that a step allocates nothing once the pool is warm.
    spare: Vec<Rows>,
    env: Env,
    /// Whether the system has rigid bodies, whose angles [`set_state`](Dynamics::set_state)
    /// writes into `env` at every evaluation (without, it has nothing to do).
    rigid: bool,
    /// Added to the bias of every row before the acceleration solve (None: no Baumgarte).
    pub baumgarte: Option<BaumgarteTerms>,
    /// Whether an external force depends on a velocity (damping, drag). When not, Verlet's
    /// second half needs no evaluation of its own (RATTLE takes F(q⁺) from the rows it has).
    /// `true` is always safe.
    pub velocity_dependent_forces: bool,
    /// Whether RATTLE's SHAKE completes its end rows without the motion tape
    /// ([`rows_after_positions_steady_into`](Dynamics::rows_after_positions_steady_into)):
    /// the program's `RowProgram::steady` at the start. `false` is always safe (the
    /// general path, one evaluation a step more); `true` only for a steady program.
    pub steady: bool,
    /// Row evaluations so far (the cost unit).
    pub evaluations: u64,
    /// The solves' settings: the defaults, with the speed scale of contacts
    /// (`solve::Settings::speed_scale`) a simulation sets at its start.
    pub settings: Settings,
    /// The step being computed, for diagnostics.
    pub step: u64,
    /// The active set kept between steps, per constraint: inequality rows that pushed
    /// (λ > 0) at the start of the step. Within a step they are equalities (every stage of
    /// an integrator, the projections, SHAKE), so a pressed contact moves as its equality
    /// twin does; they are released only at the start of a step whose solve gives them
    /// λ = 0 (λ would turn negative) or finds them opening. Empty: nothing held.
    held: Vec<bool>,
    /// The factorisation shared by solves with the same J (`solve::SolveCache`): the step's
    /// acceleration solve, SHAKE's iterations, the velocity projection and the next start.
    solver: SolveCache,
    /// The mark of the kept factor the last [`solve_known`](Dynamics::solve_known) or
    /// [`correct_step`](Dynamics::correct_step) went through (`solve::FactorId`), `None` when
    /// it went another way (the one-row solve, the general solve).
    made: Option<FactorId>,
    /// The rows of the last [`positions`](Dynamics::positions), and whether all their
    /// numbers were finite.
    position_rows: Vec<Row>,
    positions_finite: bool,
    /// Per 3D rigid body (in the order of its angular slots), the orientation q₀ at the start
    /// of the step; the state's rotation vector φ turns it (`numeric::rotation`).
    orientations: Vec<[f64; 4]>,
    /// The solve's accelerations folded into state slots (scratch of [`Dynamics::kick_at`]).
    folded: Vec<[f64; 3]>,
    /// The answers of the last [`correct`](Dynamics::correct) and the last
    /// [`solve`](Dynamics::solve): buffers the solves fill in place, read where they are
    /// (a solution is seven vectors: moving one in and out of the dynamics at every solve
    /// was a visible part of a pendulum's step).
    correction: Solution,
    solution: Solution,
    /// The one-row solve's last scaling (`numeric::single`), reused at the same J and 1/m.
    single: SingleScaling,
    /// Where the tapes of a scene of one row on one point mass read q and v and leave their
    /// numbers (`RowProgram::one_slot`): its evaluations at a step write and read there.
    one_slot: Option<OneSlot>,
    /// A solve that left a block unsolved ([`Diagnostic::TooLarge`]): the step and its rows.
    /// The next evaluation stops the run with [`SimError::TooLarge`] instead of stepping on
    /// with λ = 0 on them, as if those constraints were not there.
    refused: Option<(u64, usize)>,
}

/// The rows of a block `solution` left unsolved as too large ([`Diagnostic::TooLarge`]).
fn refused_rows(solution: &Solution) -> Option<usize> {
    if solution.status != Status::Failed {
        return None;
    }
    solution.diagnostics.iter().find_map(|d| match d {
        Diagnostic::TooLarge { rows, .. } => Some(*rows),
        _ => None,
    })
}

/// The state slot of each rigid body's angle or rotation vector (and angular velocity), in
/// the order of the rigid bodies.
fn angular_state_slots(system: &System) -> impl Iterator<Item = usize> + use<> {
    let (n, w) = (system.bodies.len(), angular_width(system));
    let count = system.bodies.iter().filter(|b| b.rigid.is_some()).count();
    (0..count).map(move |r| n + r * w)
}

/// The orientations `env` gives the 3D rigid bodies of `system`, in the order of their slots.
fn orientations_of(system: &System, env: &Env) -> Vec<[f64; 4]> {
    let rigid = system.bodies.iter().filter_map(|b| b.rigid.as_ref()).filter(|r| r.nodes.axes.is_some());
    rigid.map(|r| env.get(r.orientation).and_then(Value::quaternion).unwrap_or([1.0, 0.0, 0.0, 0.0])).collect()
}

impl<'s> Dynamics<'s> {
    /// `env` gives every parameter and mass (e.g. [`crate::model::scene::environment`]);
    /// positions, velocities and `t` are overwritten at each evaluation.
    pub fn new(system: &'s System, program: RowProgram, env: Env) -> Dynamics<'s> {
        Dynamics::with_program(system, Cow::Owned(program), env)
    }

    /// [`new`](Dynamics::new) with a program the caller keeps (`Scenario::simulate`: every
    /// run of a scenario reads its one program).
    pub fn borrowing(system: &'s System, program: &'s RowProgram, env: Env) -> Dynamics<'s> {
        Dynamics::with_program(system, Cow::Borrowed(program), env)
    }

    /// [`new`](Dynamics::new) and [`borrowing`](Dynamics::borrowing)'s one body.
    fn with_program(system: &'s System, program: Cow<'s, RowProgram>, env: Env) -> Dynamics<'s> {
        let mut scratch = program.scratch();
        // `env`'s parameters and masses stay until `reset` or `choose_unit` replaces them:
        // loaded at the first evaluation, not at every one.
        scratch.hold_constants();
        let orientations = orientations_of(system, &env);
        let steady = program.steady();
        let one_slot = program.one_slot();
        Dynamics {
            system,
            program,
            scratch,
            spare: Vec::new(),
            env,
            rigid: system.has_rigid_bodies(),
            baumgarte: None,
            velocity_dependent_forces: true,
            steady,
            evaluations: 0,
            settings: Settings::default(),
            step: 0,
            held: Vec::new(),
            solver: SolveCache::default(),
            made: None,
            position_rows: Vec::new(),
            positions_finite: false,
            orientations,
            folded: Vec::new(),
            correction: Solution::default(),
            solution: Solution::default(),
            single: SingleScaling::default(),
            one_slot,
            refused: None,
        }
    }

    /// Starts again from `env` (every parameter and mass) in the scene's own unit; the
    /// evaluation count and scratch are kept.
    pub fn reset(&mut self, env: Env) {
        self.orientations = orientations_of(self.system, &env);
        self.env = env;
        self.scratch.hold_constants();
        self.held.clear();
    }

    /// The 3D rigid bodies' orientations q₀ at the start of the step (after [`rebase`](Dynamics::rebase)
    /// the bodies' orientations), in the order of their angular slots.
    pub fn orientations(&self) -> &[[f64; 4]] {
        &self.orientations
    }

    /// Puts back orientations q₀ that [`orientations`](Dynamics::orientations) gave: the
    /// stability analysis steps many states from the same orientation.
    pub fn set_orientations(&mut self, orientations: &[[f64; 4]]) {
        self.orientations.clear();
        self.orientations.extend_from_slice(orientations);
    }

    /// The start of a step: each 3D rigid body's rotation vector φ in `q` is folded into its
    /// orientation q₀ ← exp(φ) ⊗ q₀, renormalised, and φ set to zero.
    pub fn rebase(&mut self, q: &mut Vectors) {
        if !self.orientations.is_empty() {
            rebase(&mut self.orientations, angular_state_slots(self.system), q);
        }
    }

    /// Whether constraint `k` is a held contact (see [`Dynamics::hold`]).
    pub fn is_held(&self, k: usize) -> bool {
        self.held.get(k).copied().unwrap_or(false)
    }

    /// The held contacts, per constraint (possibly shorter than the constraints: the rest
    /// are not held).
    pub fn held(&self) -> &[bool] {
        &self.held
    }

    /// Updates the active set from the solve at the start of a step ([`Dynamics::solve`] at
    /// `rows`): an inequality row is held for the step when it pushes (λ > 0) and is
    /// resting or penetrating, or was held and is still touching and not opening. A closing
    /// contact that was not held is left to its impulse (holding it as an equality would
    /// fold its correction into the velocity before the bounce).
    pub fn hold(&mut self, rows: &Rows, solution: &Solution) {
        update_held(&mut self.held, rows, solution);
    }

    /// [`hold`](Dynamics::hold) with the answer of the last [`solve`](Dynamics::solve), which
    /// must have been at `rows`.
    pub fn hold_solved(&mut self, rows: &Rows) {
        update_held(&mut self.held, rows, &self.solution);
    }

    /// Releases every held contact (a new run, or a caller that keeps no active set).
    pub fn release(&mut self) {
        self.held.clear();
    }

    /// Compiles the rows' tapes to machine code when `compile` says that a run of
    /// `evaluations` row evaluations should (`simulate::Compile::wanted`,
    /// `RowProgram::compile`); a borrowed program is copied first, the copy's compiled code
    /// shared by its later copies. Returns whether some tape runs compiled now. A tape that
    /// cannot be compiled keeps the interpreter; the numbers are the same either way.
    pub fn compile_rows(&mut self, compile: Compile, evaluations: u64) -> bool {
        let (tapes, instructions) = self.program.uncompiled();
        if tapes > 0 && compile.wanted(tapes, instructions, evaluations) {
            #[cfg(feature = "jit")]
            let _ = self.program.to_mut().compile();
        }
        self.program.compiled_kernels() > 0
    }

    pub fn system(&self) -> &'s System {
        self.system
    }

    /// Whether some constraint's C reads t (`RowProgram::time_dependent`, found when the
    /// program was built).
    pub fn time_dependent(&self) -> bool {
        self.program.time_dependent()
    }

    /// Moves to a length unit near the scene's size when `env`'s lengths are beyond 2^±[`NATURAL_RANGE`]
    /// and the rows are verifiably homogeneous (`numeric::rescale::Unit`): from then on
    /// [`rows`](Dynamics::rows) expects and returns numbers in that unit. Returns the unit,
    /// or `None` when the numbers stay as they are.
    pub fn choose_unit(&mut self, env: &Env) -> Result<Option<Unit>, SimError> {
        // An angle is no length: a scene with rigid bodies runs in its own unit.
        if self.system.has_rigid_bodies() {
            return Ok(None);
        }
        let Some(k) = Unit::exponent_at(self.system, env).filter(|k| k.abs() > NATURAL_RANGE) else {
            return Ok(None);
        };
        let eval_error = |error| SimError::Eval { time: 0.0, error };
        // One unit serves a run: a block nearer the caller's unit than 2ᵏ would be lost in it.
        if let Some((small, large)) = spread(&self.program, self.system, env).map_err(eval_error)?
            && [small, large].iter().any(|e| e.abs() < (e - k).abs())
        {
            return Err(SimError::MixedScales { small, large });
        }
        let unit = Unit::verified(&self.program, self.system, env, k).map_err(eval_error)?;
        if let Some(unit) = &unit {
            self.env = unit.to_unit(&self.env);
            self.scratch.hold_constants();
        }
        Ok(unit)
    }

    /// Puts the rigid bodies' part of (t, q, v) into the environment the tapes read (the
    /// time and the bodies' positions and velocities go to the tapes from the arrays:
    /// `rows::State`).
    #[inline(always)]
    fn set_state(&mut self, q: &Vectors, v: &Vectors) {
        if self.rigid {
            self.set_angles(q, v);
        }
    }

    /// [`set_state`](Dynamics::set_state)'s work, with rigid bodies.
    #[inline(never)]
    fn set_angles(&mut self, q: &Vectors, v: &Vectors) {
        // Rigid bodies' angles (3D: q = exp(φ) ⊗ q₀) and angular velocities, from their
        // angular slots after the bodies.
        let rigid = self.system.bodies.iter().filter_map(|b| b.rigid.as_ref());
        for (r, (slot, rigid)) in angular_state_slots(self.system).zip(rigid).enumerate() {
            match self.orientations.get(r) {
                Some(&q0) => {
                    self.env.set(rigid.orientation, Value::Quaternion(turned(q[slot], q0)));
                    self.env.set(rigid.angular_velocity, Value::Vector(v[slot]));
                }
                None => {
                    self.env.set(rigid.orientation, Value::Scalar(q[slot][0]));
                    self.env.set(rigid.angular_velocity, Value::Scalar(v[slot][0]));
                }
            }
        }
    }

    /// C/κ and J of every row at (t, q) (`RowProgram::evaluate_positions_into`: a tape of C
    /// and J only), read back with [`position_rows`](Dynamics::position_rows): what an
    /// iteration onto C = 0 needs. A number that is not finite is reported as
    /// [`rows`](Dynamics::rows) reports it (the full rows at the same state are evaluated
    /// for the error). In line: an iteration calls it on a scene of a row or two, where the
    /// call's own instructions are a visible part of the evaluation.
    #[inline]
    pub fn positions(&mut self, t: f64, q: &Vectors, v: &Vectors) -> Result<(), SimError> {
        self.evaluations += 1;
        self.set_state(q, v);
        self.program
            .evaluate_positions_state_into(
                self.system,
                &self.env,
                State { t, q, v },
                &mut self.scratch,
                &mut self.position_rows,
            )
            .map_err(|error| SimError::Eval { time: t, error })?;
        // Found as the rows were filled: C/κ and every component of J.
        let finite = self.scratch.finite();
        self.positions_finite = finite;
        if !finite {
            return self.report_positions(t, q, v);
        }
        Ok(())
    }

    /// C/κ and J of a scene of one row on one point mass at the slot's `q` (and `v`) by the
    /// positions' tape (`RowProgram::positions_one_slot`), with whether they are finite:
    /// neither counted nor written into [`position_rows`](Dynamics::position_rows) (a
    /// caller that keeps them counts the evaluation with
    /// [`count_positions`](Dynamics::count_positions)). `None` for another scene, or before
    /// the run's constants are loaded.
    #[inline(always)]
    pub(crate) fn one_slot_positions(&mut self, q: &[f64; 3], v: &[f64; 3]) -> Option<(f64, [f64; 3], bool)> {
        let one = self.one_slot.as_ref()?;
        self.program.positions_one_slot(one, q, v, &mut self.scratch)
    }

    /// Counts an evaluation of [`one_slot_positions`](Dynamics::one_slot_positions) whose
    /// numbers a step kept, as [`positions`](Dynamics::positions) counts its own (and
    /// leaves no positions' rows to be taken).
    #[inline(always)]
    pub(crate) fn count_positions(&mut self) {
        self.evaluations += 1;
        self.positions_finite = false;
    }

    /// The one-row solve's kept scaling (`numeric::single`), for a correction computed
    /// from the numbers in hand (`single::correction_checked`).
    #[inline(always)]
    pub(crate) fn single_scaling(&mut self) -> &mut SingleScaling {
        &mut self.single
    }

    /// [`positions`](Dynamics::positions) at a state where C or J is not finite: the full
    /// rows at the same state, evaluated for the error they report.
    #[inline(never)]
    fn report_positions(&mut self, t: f64, q: &Vectors, v: &Vectors) -> Result<(), SimError> {
        let rows = self.rows(t, q, v)?;
        self.recycle(rows);
        Ok(())
    }

    /// The rows of the last [`positions`](Dynamics::positions) (C/κ and J; Ċ and c are 0),
    /// until [`rows_after_positions`](Dynamics::rows_after_positions) takes them.
    pub fn position_rows(&self) -> &[Row] {
        &self.position_rows
    }

    /// The rows at (t, q, v): the one place states become numbers.
    pub fn rows(&mut self, t: f64, q: &Vectors, v: &Vectors) -> Result<Rows, SimError> {
        self.refusal()?;
        self.evaluations += 1;
        self.set_state(q, v);
        let mut rows = self.spare.pop().unwrap_or_default();
        self.program
            .evaluate_state_into(self.system, &self.env, State { t, q, v }, &mut self.scratch, &mut rows)
            .map_err(|error| SimError::Eval { time: t, error })?;
        let finite = self.scratch.finite();
        self.checked(rows, t, finite)
    }

    /// The rows at (t, q, v) from `rows`, whose C/κ and J are already those at (t, q) (an
    /// evaluation at the same t and q, before a velocity step changed v): only Ċ, c and the
    /// slots' numbers are evaluated (`RowProgram::evaluate_motion_state_into`), as
    /// [`rows`](Dynamics::rows) would give them to rounding. `rows`' other numbers may have
    /// been spent (a correction's C, Ċ and c) but for its `value`, which must be C/κ.
    pub fn rows_moved(&mut self, t: f64, q: &Vectors, v: &Vectors, mut rows: Rows) -> Result<Rows, SimError> {
        self.moved(t, q, v, &mut rows, true)?;
        Ok(rows)
    }

    /// [`rows_moved`](Dynamics::rows_moved) in place: `rows` becomes the rows at (t, q, v)
    /// (what a run loop that keeps its rows in its own buffers calls: a `Rows` moved by
    /// value through a `Result` is a copy of its header each time). Returns whether C and J
    /// are `rows`' own, bit for bit (else every row was evaluated again, J too).
    pub fn rows_moved_into(&mut self, t: f64, q: &Vectors, v: &Vectors, rows: &mut Rows) -> Result<bool, SimError> {
        self.moved(t, q, v, rows, true)
    }

    /// [`rows_moved_into`](Dynamics::rows_moved_into) of a scene of one row on one point
    /// mass, in line where the run's start calls it (`moved_one_slot`): whether it was done,
    /// C and J kept and every number written finite. Else nothing is counted and the caller
    /// takes [`rows_moved_into`](Dynamics::rows_moved_into), which says why (an error, a
    /// number not finite, rows of another shape).
    #[inline(always)]
    pub(crate) fn rows_moved_one_slot(&mut self, q: &Vectors, v: &Vectors, rows: &mut Rows) -> bool {
        self.refused.is_none() && self.moved_one_slot(q, v, rows)
    }

    /// [`rows_moved_into`](Dynamics::rows_moved_into); `checked`: C and J are known to be
    /// finite. In line (always: the run loop's start calls it once a step, and its call
    /// was a fifth of its own cost), as [`positions`](Dynamics::positions), its checks apart.
    #[inline(always)]
    fn moved(&mut self, t: f64, q: &Vectors, v: &Vectors, rows: &mut Rows, checked: bool) -> Result<bool, SimError> {
        self.refusal()?;
        self.evaluations += 1;
        self.set_state(q, v);
        let kept = self
            .program
            .evaluate_motion_state_into(self.system, &self.env, State { t, q, v }, &mut self.scratch, rows)
            .map_err(|error| SimError::Eval { time: t, error })?;
        // C and J were checked when they were evaluated: the new numbers alone (found as
        // they were filled), and all of them again only to name what is not finite.
        let finite = self.scratch.finite();
        if kept && checked && finite {
            return Ok(true);
        }
        self.check_moved(rows, t, kept, finite)?;
        Ok(kept)
    }

    /// [`moved`](Dynamics::moved) of a scene of one row on one point mass whose C and J are
    /// known to be finite (`RowProgram::motion_one_slot`): the same numbers into `rows`,
    /// without the general evaluation's fill. Whether it was done and every number written
    /// is finite; else nothing is counted or written but what the general path, which the
    /// caller then takes, writes over again (the rows of another shape, a number that is
    /// not finite, the constants not loaded yet).
    #[inline(always)]
    fn moved_one_slot(&mut self, q: &Vectors, v: &Vectors, rows: &mut Rows) -> bool {
        let (Some(one), [x], [u]) = (&self.one_slot, q, v) else {
            return false;
        };
        let Some((row, w, velocity, f)) = rows.one_slot_mut() else {
            return false;
        };
        let Some(motion) = self.program.motion_one_slot(one, x, u, &mut self.scratch) else {
            return false;
        };
        if !motion.finite {
            return false;
        }
        self.evaluations += 1;
        (*w, *velocity, *f) = (motion.inverse_mass, motion.velocity, motion.force);
        (row.rate, row.bias, row.inequality) = (motion.rate, motion.bias, one.inequality());
        rows.dim = self.system.dim();
        rows.axes.clear();
        true
    }

    /// [`moved`](Dynamics::moved)'s check of rows whose C and J were kept unchecked (`kept`:
    /// every number is looked at) or evaluated afresh (`finite` says).
    #[inline(never)]
    fn check_moved(&self, rows: &Rows, t: f64, kept: bool, finite: bool) -> Result<(), SimError> {
        let finite = if kept { all_finite(rows) } else { finite };
        self.check(rows, t, finite)
    }

    /// The rows at (t, q, v) after a [`positions`](Dynamics::positions) at the same t and q:
    /// its C/κ and J are taken over and the rest evaluated ([`rows_moved`](Dynamics::rows_moved)).
    pub fn rows_after_positions(&mut self, t: f64, q: &Vectors, v: &Vectors) -> Result<Rows, SimError> {
        let mut rows = self.spare.pop().unwrap_or_default();
        self.rows_after_positions_into(t, q, v, &mut rows)?;
        Ok(rows)
    }

    /// [`rows_after_positions`](Dynamics::rows_after_positions) into `rows` (whatever it
    /// held: its buffers are reused). Returns whether `rows`' C/κ and J are the positions'
    /// own, bit for bit (else every row was evaluated again, as
    /// [`rows_moved_into`](Dynamics::rows_moved_into) says).
    pub fn rows_after_positions_into(
        &mut self,
        t: f64,
        q: &Vectors,
        v: &Vectors,
        rows: &mut Rows,
    ) -> Result<bool, SimError> {
        std::mem::swap(&mut rows.rows, &mut self.position_rows);
        // `positions` reports a C or J that is not finite through a full evaluation, which
        // may round differently and pass: then they are checked again, as `rows` would.
        let finite = std::mem::replace(&mut self.positions_finite, false);
        self.moved(t, q, v, rows, finite)
    }

    /// [`rows_after_positions_into`](Dynamics::rows_after_positions_into) without an
    /// evaluation, for a steady program (`RowProgram::steady`): `rows` keeps its slots' 1/m
    /// and F, which the caller took from rows evaluated earlier in the run (constants of the
    /// run, so the same numbers bit for bit), and takes the last positions' C/κ and J, `v`
    /// as its velocities, and Ċ/κ = Σᵢ Jᵢ·vᵢ: with no C reading t, Ċ = Σᵢ ∇ᵢC·vᵢ, the
    /// quantity the motion tape evaluates from its own expression (so equal to rounding).
    /// c is not evaluated (it stays 0): RATTLE's velocity step sets every row's c itself,
    /// and the next start evaluates the rows' motion part again. Returns false, with
    /// nothing done, when the positions' numbers were not all finite (the general path
    /// then checks them).
    pub fn rows_after_positions_steady_into(&mut self, v: &Vectors, rows: &mut Rows) -> bool {
        if !self.positions_finite {
            return false;
        }
        self.positions_finite = false;
        std::mem::swap(&mut rows.rows, &mut self.position_rows);
        if rows.velocity.len() != v.len() {
            rows.velocity.resize(v.len(), [0.0; 3]);
        }
        copy_slots(&mut rows.velocity, v);
        for row in &mut rows.rows {
            row.rate = row.jacobian.iter().map(|(b, j)| j[0] * v[*b][0] + j[1] * v[*b][1] + j[2] * v[*b][2]).sum();
        }
        true
    }

    /// [`rows_after_positions_steady_into`](Dynamics::rows_after_positions_steady_into) for
    /// rows of one slot (`v` its velocity): the same numbers, without the loops. In line:
    /// RATTLE's one-row step (`stabilize::rattle_one_row`) calls it at every step.
    #[inline(always)]
    pub fn rows_after_positions_one_slot(&mut self, v: &[f64; 3], rows: &mut Rows) -> bool {
        let (true, [velocity], [_]) =
            (self.positions_finite, rows.velocity.as_mut_slice(), self.position_rows.as_slice())
        else {
            return self.rows_after_positions_steady_into(std::slice::from_ref(v), rows);
        };
        *velocity = *v;
        self.positions_finite = false;
        std::mem::swap(&mut rows.rows, &mut self.position_rows);
        for row in &mut rows.rows {
            if let [(0, j)] = row.jacobian.as_slice() {
                // The sum of one term, from −0: the term itself.
                row.rate = j[0] * v[0] + j[1] * v[1] + j[2] * v[2];
            } else {
                let v = std::slice::from_ref(v);
                row.rate = row.jacobian.iter().map(|(b, j)| j[0] * v[*b][0] + j[1] * v[*b][1] + j[2] * v[*b][2]).sum();
            }
        }
        true
    }

    /// `rows` at time `t`, or the error that names the first number that is not finite
    /// (`finite`: whether every number of `rows` is, as `all_finite` says).
    fn checked(&self, rows: Rows, t: f64, finite: bool) -> Result<Rows, SimError> {
        self.check(&rows, t, finite)?;
        Ok(rows)
    }

    /// [`checked`](Dynamics::checked) without taking the rows.
    fn check(&self, rows: &Rows, t: f64, finite: bool) -> Result<(), SimError> {
        // Nothing non-finite reaches the solve (an SVD of NaNs need not even terminate).
        if !finite {
            for (k, row) in rows.rows.iter().enumerate() {
                let bad = [row.value, row.rate, row.bias]
                    .into_iter()
                    .chain(row.jacobian.iter().flat_map(|(_, j)| j.iter().copied()))
                    .find(|x| !x.is_finite());
                if let Some(value) = bad {
                    let constraint = self.system.constraints[k].name.clone();
                    return Err(SimError::NonFiniteRow { step: self.step, time: t, constraint, value });
                }
            }
            for (i, ((f, v), w)) in rows.force.iter().zip(&rows.velocity).zip(&rows.inverse_mass).enumerate() {
                if !(f.iter().chain(v).all(|x| x.is_finite()) && w.is_finite()) {
                    let body = slot_name(self.system, i);
                    return Err(SimError::NonFinite { step: self.step, time: t, body });
                }
            }
        }
        Ok(())
    }

    /// Gives rows back for reuse by the next [`rows`](Dynamics::rows) (optional: dropping
    /// them is correct, only slower).
    pub fn recycle(&mut self, rows: Rows) {
        if self.spare.len() < SPARE_ROWS {
            self.spare.push(rows);
        }
    }

    /// Solves for λ at `rows` (Baumgarte terms added first when set), the held contacts
    /// touching whatever their distance (`solve::solve_holding`): the solve at the start of
    /// a step, which decides what stays held ([`Dynamics::hold`]).
    pub fn solve(&mut self, rows: &mut Rows) -> &Solution {
        self.solve_known(rows, None)
    }

    /// [`solve`](Dynamics::solve) of rows whose J has not changed since the solve that gave
    /// [`made`](Dynamics::made) = `known` (a run's next start, whose J is the velocity
    /// projection's): the kept factor serves them without comparing J again
    /// (`solve::FactorId`).
    pub fn solve_known(&mut self, rows: &mut Rows, known: Option<FactorId>) -> &Solution {
        if let Some(BaumgarteTerms { two_alpha, beta_squared }) = self.baumgarte {
            for (k, row) in rows.rows.iter_mut().enumerate() {
                // A closing contact that is not held is the impulse's (Ċ⁺ = −eĊ at the step's
                // end): a spring on it would brake the approach inside the step, and a bounce
                // with e = 1 came back at 0.9 of its speed. Held contacts (equalities in the
                // stages) and contacts not closing keep the terms.
                if row.inequality && !self.is_held(k) && row.rate < 0.0 {
                    continue;
                }
                // C̈ + 2αĊ + β²C = 0 ⇒ the bias c gains 2αĊ + β²C.
                row.bias += two_alpha * row.rate + beta_squared * row.value;
            }
        }
        let solution = &mut self.solution;
        self.made = None;
        // One row on one body: the same numbers in closed form (`numeric::single`).
        if !solve_single_with(rows, &self.settings, &mut self.single, solution) {
            let held = &self.held;
            cached_into(rows, &self.settings, held, &mut self.solver, solution, Answer::Solution, known);
            self.made = self.solver.made();
            if self.refused.is_none() {
                self.refused = refused_rows(solution).map(|rows| (self.step, rows));
            }
        }
        &self.solution
    }

    /// The mark of the kept factor the last [`solve_known`](Dynamics::solve_known) or
    /// [`correct_step`](Dynamics::correct_step) went through, for a later solve of rows
    /// with the same J (`solve::FactorId`); `None` when it went another way.
    pub fn made(&self) -> Option<FactorId> {
        self.made
    }

    /// [`solve_known`](Dynamics::solve_known) of rows of one slot with one row on it (a
    /// pendulum, a bead), in closed form (`single::solve_one_slot`): the same answer
    /// ([`solution`](Dynamics::solution)) and the slot's acceleration, or `None`, with
    /// nothing done, where that path declines (the caller then takes `solve_known`).
    /// `rows` must be as [`rows`](Dynamics::rows) or
    /// [`rows_moved_into`](Dynamics::rows_moved_into) returned them, every number finite
    /// (they report any other as an error): they are not tested again.
    #[inline(always)]
    pub(crate) fn solve_one_slot(&mut self, rows: &mut Rows) -> Option<[f64; 3]> {
        // Baumgarte's terms change c first: `solve_known` adds them.
        if self.baumgarte.is_some() {
            return None;
        }
        let a = solve_one_slot(rows, &self.settings, &mut self.single, &mut self.solution, true)?;
        self.made = None;
        Some(a)
    }

    /// [`solve_one_slot`](Dynamics::solve_one_slot) without the scaling
    /// (`single::solve_one_slot_unscaled`, under its guard), for RATTLE's one-row runs:
    /// `None`, with nothing done, where it declines (the caller then takes
    /// `solve_one_slot`, which answers as ever).
    #[inline(always)]
    pub(crate) fn solve_one_slot_unscaled(&mut self, rows: &Rows) -> Option<[f64; 3]> {
        if self.baumgarte.is_some() {
            return None;
        }
        let a = solve_one_slot_unscaled(rows, &self.settings, &mut self.solution)?;
        self.made = None;
        Some(a)
    }

    /// The answer of the last [`solve`](Dynamics::solve) (empty before the first).
    pub fn solution(&self) -> &Solution {
        &self.solution
    }

    /// The solve of a correction (projection, SHAKE, velocity step: forces zeroed, c set to
    /// the target), with no contact held: `solve::solve` through the run's cache, into a
    /// buffer the dynamics keep (the caller may change it: it is scratch until the next
    /// correction).
    pub fn correct(&mut self, rows: &Rows) -> &mut Solution {
        self.correct_answering(rows, Answer::Solution, None)
    }

    /// [`correct`](Dynamics::correct)'s step alone, M⁻¹Jᵀμ (the solution's accelerations,
    /// the same numbers), for a caller that reads nothing else (SHAKE, the projections, the
    /// velocity step): a chain's solve then computes no λ (`solve::Answer::Step`). `known`
    /// as in [`solve_known`](Dynamics::solve_known): SHAKE's iterations along the start's J.
    pub fn correct_step(&mut self, rows: &Rows, known: Option<FactorId>) -> &mut Vectors {
        &mut self.correct_answering(rows, Answer::Step, known).acceleration
    }

    /// Whether the corrections' steps ([`correct_step`](Dynamics::correct_step)) on a block
    /// the body-space factor serves take the velocity change alone
    /// (`solve::SolveCache::set_velocity_space`: the same step to rounding, not bit for
    /// bit): the exact velocity step's run.
    pub fn set_velocity_space(&mut self, on: bool) {
        self.solver.set_velocity_space(on);
    }

    /// [`correct`](Dynamics::correct) writing what `answer` asks.
    fn correct_answering(&mut self, rows: &Rows, answer: Answer, known: Option<FactorId>) -> &mut Solution {
        self.made = None;
        if !solve_single_with(rows, &self.settings, &mut self.single, &mut self.correction) {
            let out = &mut self.correction;
            cached_into(rows, &self.settings, &[], &mut self.solver, out, answer, known);
            self.made = self.solver.made();
            if self.refused.is_none() {
                self.refused = refused_rows(&self.correction).map(|rows| (self.step, rows));
            }
        }
        &mut self.correction
    }

    /// [`correct`](Dynamics::correct) of a scene's one row on its only slot, with the row's
    /// c set to `bias`, taken as an equality, and the forces zero — in closed form from the
    /// rows as they are, which are neither written nor spent (`single::correction_single`).
    /// Returns the step on the slot, bit for bit what `correct` would add; `None` where the
    /// one-row solve declines, and the caller takes `correct`.
    pub fn correct_single(&mut self, rows: &Rows, bias: f64) -> Option<[f64; 3]> {
        correction_single(rows, bias, &mut self.single)
    }

    /// [`correct_single`](Dynamics::correct_single) with the correction's multiplier μ (the
    /// step is M⁻¹Jᵀμ): SHAKE's, which a run keeps to predict the next step's.
    pub fn correct_single_multiplier(&mut self, rows: &Rows, bias: f64) -> Option<([f64; 3], f64)> {
        correction_single_multiplier(rows, bias, &mut self.single)
    }

    /// The answer of the last correction ([`correct`](Dynamics::correct),
    /// [`correct_known`](Dynamics::correct_known); after [`correct_step`](Dynamics::correct_step)
    /// its accelerations alone).
    pub fn correction(&self) -> &Solution {
        &self.correction
    }

    /// [`correct`](Dynamics::correct) with `known` as in [`correct_step`](Dynamics::correct_step):
    /// the step and the multipliers μ (`lambda`) of SHAKE's iterations along the start's J,
    /// when a run keeps them to predict the next step's.
    pub fn correct_known(&mut self, rows: &Rows, known: Option<FactorId>) -> &mut Solution {
        self.correct_answering(rows, Answer::Solution, known)
    }

    /// [`SimError::TooLarge`] once a solve has left a block unsolved.
    fn refusal(&self) -> Result<(), SimError> {
        match self.refused {
            Some((step, rows)) => Err(SimError::TooLarge { step, rows, limit: MAX_DENSE_ROWS }),
            None => Ok(()),
        }
    }

    /// The way the last solve through the cache went (`solve::SolvePath`; a one-row solve,
    /// `numeric::single`, does not go through it).
    pub fn last_solve_path(&self) -> super::solve::SolvePath {
        self.solver.last_path()
    }

    /// The solve at (t, q, `at`) with the held contacts as equalities, its accelerations
    /// folded into state slots in `a`; returns the rows for reuse.
    fn accelerations(&mut self, t: f64, q: &Vectors, at: &Vectors, a: &mut Vectors) -> Result<Rows, SimError> {
        let mut rows = self.rows(t, q, at)?;
        // Within a step the held contacts are equalities: every stage sees the same smooth
        // field, so a pressed contact keeps the integrator's order.
        for (k, row) in rows.rows.iter_mut().enumerate() {
            if self.is_held(k) {
                row.inequality = false;
            }
        }
        a.copy_from_slice(&self.solve(&mut rows).acceleration);
        fold(&rows, a);
        Ok(rows)
    }

    /// Verlet's second kick for 3D rigid bodies: v += h a(t, q, `at`), the gyroscopic term at
    /// the implicit midpoint (`rotation::kick`).
    pub fn kick_at(&mut self, t: f64, q: &Vectors, at: &Vectors, h: f64, v: &mut Vectors) -> Result<(), SimError> {
        let mut a = std::mem::take(&mut self.folded);
        a.resize(v.len(), [0.0; 3]);
        let rows = self.accelerations(t, q, at, &mut a)?;
        kick(&rows, h, &a, at, v);
        self.recycle(rows);
        self.folded = a;
        Ok(())
    }
}

/// The active set after the solve `solution` at `rows` (see [`Dynamics::hold`]).
fn update_held(held: &mut Vec<bool>, rows: &Rows, solution: &Solution) {
    held.resize(rows.rows.len(), false);
    for (k, row) in rows.rows.iter().enumerate() {
        let pushing = row.inequality && solution.lambda[k] > 0.0;
        held[k] = pushing
            && match solution.contacts[k] {
                Some(ContactState::Resting | ContactState::Penetrating) => true,
                Some(ContactState::Closing) => held[k],
                _ => false,
            };
    }
}

/// Whether every component of a row's J is finite.
fn parts_finite(row: &Row) -> bool {
    row.jacobian.iter().fold(true, |ok, (_, j)| ok & j[0].is_finite() & j[1].is_finite() & j[2].is_finite())
}

/// Whether every slot's 1/m, velocity and force is finite.
fn slots_finite(rows: &Rows) -> bool {
    let three = |ok: bool, x: &[f64; 3]| ok & x[0].is_finite() & x[1].is_finite() & x[2].is_finite();
    let vectors = rows.force.iter().chain(&rows.velocity).fold(true, three);
    rows.inverse_mass.iter().fold(vectors, |ok, w| ok & w.is_finite())
}

/// Whether every number of `rows` is finite, in one branch-free pass. The tests are
/// combined with `&`, not summed (x·0 is 0 exactly when x is finite, but a sum of them is one
/// chain of dependent additions, which made these checks a visible part of a chain's step).
fn all_finite(rows: &Rows) -> bool {
    let finite = rows.rows.iter().fold(true, |ok, row| {
        ok & row.value.is_finite() & row.rate.is_finite() & row.bias.is_finite() & parts_finite(row)
    });
    finite & slots_finite(rows)
}

/// The body a slot of the rows belongs to: a body, or a rigid body's angular slot.
pub(crate) fn slot_name(system: &System, slot: usize) -> String {
    let n = system.bodies.len();
    let body = if slot < n { Some(slot) } else { angular_bodies(system).nth((slot - n) / angular_width(system)) };
    body.and_then(|b| system.bodies.get(b)).map_or_else(|| slot.to_string(), |b| b.name.clone())
}

impl Field for Dynamics<'_> {
    type Error = SimError;

    fn acceleration(&mut self, t: f64, q: &Vectors, v: &Vectors, a: &mut Vectors) -> Result<(), SimError> {
        let rows = self.accelerations(t, q, v, a)?;
        self.recycle(rows);
        Ok(())
    }

    /// v, but φ̇ = dexp⁻¹(φ) ω for each 3D rigid body's rotation vector (`rotation::dexp_inv`).
    fn rate(&self, q: &Vectors, v: &Vectors, out: &mut Vectors) {
        out.copy_from_slice(v);
        if !self.orientations.is_empty() {
            for slot in angular_state_slots(self.system) {
                out[slot] = dexp_inv(q[slot], v[slot]);
            }
        }
    }
}
