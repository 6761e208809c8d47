//! The velocity-level step an engine runs: impulses on velocities, one solver per file —
//! Box2D v3's soft step ([`soft_step`]), sequential impulses with Baumgarte bias ([`pgs`]),
//! XPBD ([`xpbd`]) and the exact velocity solve A P = −(J u + bias) ([`exact`]) — with the
//! run loop that records the same [`Frame`](super::simulate::Frame)s and
//! [`Summary`](super::simulate::Summary) as the acceleration-level simulation ([`run`]) and
//! the stability analysis of the soft step ([`stability`]).
//!
//! Every solver reads the rows of `numeric::rows` through [`Dynamics::rows`]: per constraint
//! C/κ, Ċ/κ and J = ∇C/κ per slot, per slot 1/m, v and F. The rows are evaluated at the
//! positions each substep starts from and held fixed within the substep, as Box2D holds a
//! joint's anchors between position updates. Ċ at any velocity u is J·u + ∂C/∂t, with
//! ∂C/∂t = Ċ − J·v taken from the rows (so moving constraints work), and 0 exactly for a row
//! whose C reads no time ([`steady_rows`]). A row's impulse P acts
//! as Δvᵢ = (1/mᵢ) Jᵢ P; with J = ∇C/κ, P refers to C/κ as λ does, and P/h ≈ λ.
//!
//! Rigid bodies (2D) need nothing of their own: a state's slots are the bodies, then one
//! angular slot per rigid body (`numeric::rows`: 1/I, ω, τ and the row's Jʷ in component 0,
//! θ in the position's). So a row's entries are its linear and angular parts per body,
//! u = (v, ω), M⁻¹ = blockdiag(1/m E, 1/I), m_eff = 1/(Σ Jᵛ·Jᵛ/m + Σ (Jʷ)²/I) (for a pin,
//! Jʷ = (r × n): Box2D's (r × n)²/I terms), an impulse changes v by Jᵛ P/m and ω by Jʷ P/I,
//! and θ += h ω with x += h v (symplectic Euler, as for point masses; in 2D the turn is
//! exact, so XPBD's position update θ += Jʷ Δλ/I is its angular generalised inverse mass).
//! Lengths (the scene's size, the blow-up bound, the bench's deviation) come from the bodies'
//! positions only, never an angle.
//!
//! 3D rigid bodies. The state holds a 3D body's world rotation vector φ and world ω in its
//! first angular slot (`numeric::rotation`), the rows three slots along the principal axes
//! eₖ (1/Iₖ, eₖ·ω, eₖ·τ − gyroscopic, Jʷ·eₖ). Each substep rebases (φ = 0, the orientation
//! into `Dynamics`), [`Prepared::to_axes`] turns the state's ω into the rows' slots, where
//! the kick ([`Prepared::kick`]: τ and the gyroscopic term at the implicit midpoint,
//! `rotation::kick_axes`, so a free body keeps T and |L|) and the sweeps or the solve act
//! with no change; [`Prepared::to_world`] folds ω back and [`Prepared::drift`] turns the body
//! exactly, φ ← log(exp(h ω) ⊗ exp(φ)). XPBD does the same with positions: its correction
//! (1/Iₖ)(Jʷ·eₖ)Δλ per axis is I⁻¹Jʷ Δλ in the world, added to φ (first order, as its
//! linear correction), and ω = log(exp(φ⁺) ⊗ exp(−φ))/h is the substep's turn. Without 3D
//! bodies these conversions do nothing.
//!
//! Row by row, not in blocks: a vector constraint (a revolute pin, `NAME.x` and `NAME.y`) is
//! two rows swept one after the other, where Box2D v3 solves a point joint's two rows as one
//! 2×2 block (`revolute_joint.c`: ΔP = −s_m K⁻¹(Ċ + bias) − s_i P). Converged, both give the
//! exact velocity solve −K⁻¹Ċ (PGS, and the soft step's relax pass); with softness the
//! sweep's fixed point is (A + (s_i/s_m) diag A) P = −Ċ, Box2D's (A + (s_i/s_m) K) P = −Ċ,
//! and one iteration differs (`tests/velocity_rigid.rs`). A generated step that follows the
//! library must sweep the same rows in the same order.
//!
//! Design note. [`Stepper`] holds the solver's state between steps (accumulated impulses
//! for warm starting) and its scratch (the rows flattened into [`Prepared`]), so a step of
//! the iterative solvers allocates nothing once warm. The soft step and PGS share the
//! sequential-impulse loop ([`Prepared::sweep`]); they differ in the bias, the softness and
//! the relax pass. The exact velocity solve goes through `numeric::solve` (banded or dense,
//! Clarabel for inequality rows), like the projections of `numeric::stabilize`.
//!
//! Not here: files or text; the acceleration-level run (`numeric::simulate`, the default
//! `exact` of the command line); quaternion arithmetic (`numeric::rotation`).

pub mod bench;
pub mod exact;
pub mod pattern;
pub mod pgs;
pub mod run;
pub mod soft_step;
pub mod stability;
pub mod xpbd;

use super::dynamics::{Dynamics, SimError};
use super::integrate::Vectors;
use super::rotation;
use super::rows::Rows;
use super::simulate::{MAX_ITERATIONS, MAX_STEPS, SettingsError};
use crate::expr::graph::SymbolWalk;
use crate::model::system::System;
use pattern::{Pattern, full, unit_square};

/// Which velocity-level solver a run uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Solver {
    /// Box2D v3's soft step: substeps, soft bias, warm start, relax, restitution.
    SoftStep,
    /// Sequential impulses (projected Gauss–Seidel) with Baumgarte bias.
    Pgs,
    /// Extended position-based dynamics with compliance (Macklin et al. 2016).
    Xpbd,
    /// The exact velocity solve A P = −(J u + C/h) per substep, through `numeric::solve`.
    Exact,
}

impl Solver {
    pub const ALL: [Solver; 4] = [Solver::SoftStep, Solver::Pgs, Solver::Xpbd, Solver::Exact];

    pub fn name(self) -> &'static str {
        match self {
            Solver::SoftStep => "soft-step",
            Solver::Pgs => "pgs",
            Solver::Xpbd => "xpbd",
            Solver::Exact => "exact-velocity",
        }
    }

    /// Iterations per substep when none are asked for: Box2D v3 runs one per substep; PGS
    /// without substeps needs more to converge on a chain; XPBD with small steps one.
    pub fn default_iterations(self) -> usize {
        match self {
            Solver::SoftStep | Solver::Xpbd | Solver::Exact => 1,
            Solver::Pgs => 8,
        }
    }
}

/// Box2D's `b2Softness`: the soft constraint of stiffness `hertz` and damping ratio ζ at step
/// h, as a bias rate on C, a scale on the effective mass and a scale on the accumulated impulse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Softness {
    pub bias_rate: f64,
    pub mass_scale: f64,
    pub impulse_scale: f64,
}

impl Softness {
    /// A rigid row without bias (the relax pass, Box2D's `useBias = false`).
    pub const RIGID: Softness = Softness { bias_rate: 0.0, mass_scale: 1.0, impulse_scale: 0.0 };

    /// `b2MakeSoft` (Box2D v3 `src/solver.h`; Catto, "Solver2D", 2024): ω = 2π·hertz,
    /// a₁ = 2ζ + hω, a₂ = hω·a₁, a₃ = 1/(1 + a₂); bias rate ω/a₁, mass scale a₂a₃, impulse
    /// scale a₃. Zero hertz is a rigid row.
    pub fn new(hertz: f64, zeta: f64, h: f64) -> Softness {
        if hertz == 0.0 {
            return Softness::RIGID;
        }
        let omega = 2.0 * std::f64::consts::PI * hertz;
        let a1 = 2.0 * zeta + h * omega;
        let a2 = h * omega * a1;
        let a3 = 1.0 / (1.0 + a2);
        Softness { bias_rate: omega / a1, mass_scale: a2 * a3, impulse_scale: a3 }
    }
}

/// How a velocity-level run goes. Build with [`Settings::new`] and field updates, then
/// [`Settings::validate`] (the run does it before any step).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub solver: Solver,
    pub dt: f64,
    pub steps: u64,
    /// Substeps per step (Box2D v3: 4).
    pub substeps: usize,
    /// Iterations per substep (None: [`Solver::default_iterations`]).
    pub iterations: Option<usize>,
    /// Stiffness of the soft step's equality rows (Box2D `jointHertz`: 60 Hz).
    pub hertz: f64,
    /// Damping ratio of the soft step's equality rows (Box2D `jointDampingRatio`: 2).
    pub damping_ratio: f64,
    /// Cap `hertz` at a quarter of the substep rate, as Box2D does (the stability analysis
    /// turns it off to search beyond it).
    pub cap_hertz: bool,
    /// The soft step's relax pass (a rigid pass without bias after the positions move).
    pub relax: bool,
    /// Start each step from the last step's impulses.
    pub warm_start: bool,
    /// Coefficient of restitution of closing contacts, in [0, 1].
    pub restitution: f64,
    /// Approaches slower than this (in Ċ/κ units) do not bounce (Box2D's
    /// `restitutionThreshold`, 1 m/s).
    pub restitution_threshold: f64,
    /// PGS's Baumgarte factor β: bias β·C/h (Box2D v2.4's `b2_baumgarte`, 0.2).
    pub baumgarte: f64,
    /// XPBD's compliance α (inverse stiffness of C/κ; 0 is a rigid row).
    pub compliance: f64,
    /// The run stops when a constraint is farther than `blowup` × the scene's length from
    /// its surface.
    pub blowup: f64,
    /// Samples kept for plots.
    pub samples: usize,
    /// At which recorded states a frame carries λ: every `lambda_every`-th step and the last
    /// (1, the default: every step; 0: none), as `--csv --every` writes them. Only the exact
    /// solve saves work by it (on a redundant block the last substep of a step whose λ is not
    /// wanted takes the velocity change alone, as its other substeps do); the other solvers
    /// have λ for free and report it at every step ([`Settings::lambda_at`]).
    pub lambda_every: u64,
    /// Whether the rows' tapes run as machine code (`simulate::Compile`): never by default.
    pub compile: crate::numeric::simulate::Compile,
}

/// Box2D v3's contact softness: 30 Hz (capped like the joints), ζ = 10, and the push-out
/// speed limit of penetrating contacts (`contactSpeed`, 3 m/s).
const CONTACT_HERTZ: f64 = 30.0;
const CONTACT_DAMPING_RATIO: f64 = 10.0;
const CONTACT_SPEED: f64 = 3.0;

impl Settings {
    /// Box2D's defaults: 4 substeps, joints at 60 Hz with ζ = 2, relax and warm start on.
    pub fn new(solver: Solver, dt: f64, duration: f64) -> Settings {
        Settings {
            solver,
            dt,
            steps: (duration / dt).round().max(0.0) as u64,
            substeps: 4,
            iterations: None,
            hertz: 60.0,
            damping_ratio: 2.0,
            cap_hertz: true,
            relax: true,
            warm_start: true,
            restitution: 0.0,
            restitution_threshold: 1.0,
            baumgarte: 0.2,
            compliance: 0.0,
            blowup: 1.0,
            samples: 4000,
            lambda_every: 1,
            compile: crate::numeric::simulate::Compile::Never,
        }
    }

    /// Whether the frame of step `n` carries λ (`lambda_every`; always, but for the exact
    /// solve). A frame without it has an empty `Frame::lambda`, never stale numbers.
    pub fn lambda_at(&self, n: u64) -> bool {
        self.solver != Solver::Exact
            || (self.lambda_every > 0 && (n.is_multiple_of(self.lambda_every) || n == self.steps))
    }

    /// Bad settings, before any step runs.
    pub fn validate(&self) -> Result<(), SimError> {
        use SettingsError as E;
        let bad = |e: SettingsError| Err(SimError::Settings(e));
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad(E::Step(self.dt));
        }
        if self.substeps == 0 {
            return bad(E::Substeps);
        }
        if self.iterations == Some(0) {
            return bad(E::Iterations);
        }
        if self.iterations() > MAX_ITERATIONS {
            return bad(E::TooManyIterations { found: self.iterations(), max: MAX_ITERATIONS });
        }
        let substeps = self.steps as f64 * self.substeps as f64;
        if substeps > MAX_STEPS as f64 {
            return bad(E::TooManySubsteps { substeps });
        }
        if !(self.hertz.is_finite() && self.hertz > 0.0) {
            return bad(E::Hertz(self.hertz));
        }
        if !(self.damping_ratio.is_finite() && self.damping_ratio >= 0.0) {
            return bad(E::DampingRatio(self.damping_ratio));
        }
        if !(0.0..=1.0).contains(&self.restitution) {
            return bad(E::Restitution(self.restitution));
        }
        if !(self.compliance.is_finite() && self.compliance >= 0.0) {
            return bad(E::Compliance(self.compliance));
        }
        if !(self.baumgarte.is_finite() && (0.0..=1.0).contains(&self.baumgarte)) {
            return bad(E::Baumgarte(self.baumgarte));
        }
        if !(self.blowup.is_finite() && self.blowup > 0.0) {
            return bad(E::Blowup(self.blowup));
        }
        Ok(())
    }

    /// The substep h = dt / substeps.
    pub fn substep(&self) -> f64 {
        self.dt / self.substeps as f64
    }

    pub fn iterations(&self) -> usize {
        self.iterations.unwrap_or(self.solver.default_iterations())
    }

    /// The stiffness the equality rows get: `hertz`, capped at a quarter of the substep rate.
    pub fn joint_hertz(&self) -> f64 {
        if self.cap_hertz { self.hertz.min(0.25 / self.substep()) } else { self.hertz }
    }

    /// The soft step's softness of equality rows.
    pub fn joint_softness(&self) -> Softness {
        Softness::new(self.joint_hertz(), self.damping_ratio, self.substep())
    }

    /// The soft step's softness of penetrating inequality rows (Box2D's contact softness).
    pub fn contact_softness(&self) -> Softness {
        let hertz = if self.cap_hertz { CONTACT_HERTZ.min(0.25 / self.substep()) } else { CONTACT_HERTZ };
        Softness::new(hertz, CONTACT_DAMPING_RATIO, self.substep())
    }
}

/// The rows of one substep, flattened for the sequential-impulse loops: per row its C/κ,
/// ∂C/∂t, effective mass 1/(J M⁻¹ Jᵀ) and its Jacobian entries (slot, Jᵢ: a body's Jᵛ or an
/// angular slot's Jʷ) in the order of [`entry_order`], each with the components that can be
/// nonzero ([`Pattern`]); per slot 1/m (1/I) and F (τ).
#[derive(Clone, Debug, Default)]
pub struct Prepared {
    /// The scene's dimension: an effective mass sums this many squares per entry ([`dot_in`]).
    pub dim: usize,
    /// Entries of row k: `start[k]..start[k + 1]`.
    pub start: Vec<usize>,
    pub body: Vec<usize>,
    pub jacobian: Vec<[f64; 3]>,
    /// Per entry, the components of its J that can be nonzero (bit d: component d; the
    /// [`Pattern`]'s, every component of the dimension for rows it does not describe): the
    /// products Ċ and an impulse take ([`dot_masked`], [`Prepared::apply`]).
    pub mask: Vec<u8>,
    pub value: Vec<f64>,
    /// ∂C/∂t = Ċ − J·v at the evaluated state (0 on a steady row).
    pub time_rate: Vec<f64>,
    /// m_eff = 1/(J M⁻¹ Jᵀ); 0 where J = 0 (a singular configuration: the row does nothing).
    pub effective_mass: Vec<f64>,
    pub inequality: Vec<bool>,
    pub inverse_mass: Vec<f64>,
    pub force: Vec<[f64; 3]>,
    /// Per slot its principal axis (`Rows::axes`: empty without 3D rigid bodies).
    pub axes: Vec<[f64; 3]>,
    /// Per slot the velocity the rows were evaluated at (3D rigid bodies: the body-frame ω
    /// their gyroscopic term was taken at; empty without 3D rigid bodies).
    pub velocity: Vec<[f64; 3]>,
    /// The first 3D rigid body's first slot (`None` without 3D rigid bodies).
    pub first: Option<usize>,
    /// Per row, whether its C reads no time ([`steady_rows`]): its ∂C/∂t is 0 exactly, taken
    /// as 0 rather than as Ċ − J·v (round-off that reads the velocities). Empty, or not one
    /// per row: none. Set with the pattern ([`Prepared::set_system`]).
    steady: Vec<bool>,
    /// The system's structural zeros of J ([`Pattern::of`]; [`Prepared::set_system`]).
    /// Empty, or not one row per row: every component.
    pattern: Pattern,
    /// Per entry, its index in its row's `Row::jacobian`. With `start`, `body` and `mask` it is
    /// the layout of the entries, a function of the rows' slots (in the derivation's order),
    /// the dimension and the pattern alone: [`Prepared::load`] keeps it while the rows' slots
    /// are those it was made for (every substep of a run, J's pattern being fixed) and fills
    /// only the numbers.
    source: Vec<usize>,
    /// Scratch: one row's entries in [`entry_order`].
    order: Vec<usize>,
    /// Scratch: the rows' Ċ of [`Prepared::rates`].
    rates: Vec<f64>,
}

/// Per constraint of `system` (one row each), whether its C reads no time, so that
/// ∂C/∂t = 0 exactly ([`Prepared::set_system`]; a generated module's `STEADY`, which leaves such
/// a row's Ċ out of its code).
pub fn steady_rows(system: &System) -> Vec<bool> {
    let mut walk = SymbolWalk::default();
    system.constraints.iter().map(|c| !walk.free_symbols(&system.graph, c.c).contains(&system.time)).collect()
}

/// a·b over the first `dim` components, summed from the first product (no leading zero): the
/// sum a generated module of that dimension writes (its `dot`), zero's sign included.
#[inline(always)]
pub fn dot_in(dim: usize, a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let mut s = a[0] * b[0];
    for d in 1..dim.min(3) {
        s += a[d] * b[d];
    }
    s
}

/// a·b over the components in `mask` (bit d: component d), summed from the first of them:
/// [`dot_in`]'s sum without the products of the components left out (a structural zero of
/// J: see [`pattern`] for what that changes, the sign of an exact zero at most, for finite
/// numbers); what a generated module's `dot_masked` writes.
#[inline(always)]
pub fn dot_masked(mask: u8, a: &[f64; 3], b: &[f64; 3]) -> f64 {
    match mask {
        0b011 => a[0] * b[0] + a[1] * b[1],
        0b111 => a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
        0b001 => a[0] * b[0],
        0b010 => a[1] * b[1],
        0b100 => a[2] * b[2],
        _ => {
            let mut s = 0.0;
            let mut first = true;
            for d in (0..3).filter(|d| mask >> d & 1 != 0) {
                s = if first { a[d] * b[d] } else { s + a[d] * b[d] };
                first = false;
            }
            s
        }
    }
}

/// The order in which the step keeps a row's Jacobian entries (in [`Prepared`] and a generated
/// module's `ROW_BODY`), so that a Gauss–Seidel sweep's Ċ = ∂C/∂t + Σᵢ Jᵢ·uᵢ, summed in that
/// order, adds the velocity the previous row wrote last as its last term: after a row whose
/// entries are on the slots `previous` (in its order), first the row's entries on slots the
/// previous row does not touch, in the derivation's order, then those it does, in the order
/// the previous row applied them. Pushes onto `order` the indices `0..len` of the row's
/// entries (entry e on slot `slot(e)`). A chain's row k (bodies k − 1 and k, after a row that
/// wrote k − 1 last) sums its body k first: the path from one row's impulse to the next row's
/// is one product and two additions, as a handwritten n·(v_b − v_a) (Box2D
/// `b2SolveDistanceJoint`) has it.
pub fn entry_order(previous: &[usize], len: usize, slot: impl Fn(usize) -> usize, order: &mut Vec<usize>) {
    order.extend((0..len).filter(|&e| !previous.contains(&slot(e))));
    for (i, p) in previous.iter().enumerate() {
        if !previous[..i].contains(p) {
            order.extend((0..len).filter(|&e| slot(e) == *p));
        }
    }
}

/// [`entry_order`] over all rows, each after the one before it (row 0 after none): rows k's
/// entries are `starts[k]..starts[k + 1]` on the slots `slots`; returns per place of the
/// step's order the index of the entry there in the derivation's order.
pub fn entry_orders(starts: &[usize], slots: &[usize]) -> Vec<usize> {
    let mut order = Vec::with_capacity(slots.len());
    let mut kept: Vec<usize> = Vec::new();
    for k in 0..starts.len().saturating_sub(1) {
        let (a, b) = (starts[k], starts[k + 1]);
        let at = order.len();
        let previous = std::mem::take(&mut kept);
        entry_order(&previous, b - a, |e| slots[a + e], &mut order);
        for e in &mut order[at..] {
            *e += a;
        }
        kept = order[at..].iter().map(|&e| slots[e]).collect();
    }
    order
}

impl Prepared {
    /// Sets what is known of `system`'s rows before any number (which rows are steady, J's
    /// structural zeros), once per run; the layout made without them goes.
    pub fn set_system(&mut self, system: &System) {
        self.steady = steady_rows(system);
        self.pattern = Pattern::of(system);
        self.start.clear();
    }

    /// Fills from `rows`, reusing the buffers: the layout of the
    /// entries (`Prepared::lay_out`) only when the rows' slots are not those of the last
    /// call, then per entry its J and per row its numbers.
    pub fn load(&mut self, rows: &Rows) {
        if !self.fits(rows) {
            self.lay_out(rows);
        }
        // Every entry's J is written below (the buffer keeps its length between substeps).
        self.jacobian.resize(self.body.len(), [0.0; 3]);
        self.value.clear();
        self.time_rate.clear();
        self.effective_mass.clear();
        self.inequality.clear();
        self.inverse_mass.clone_from(&rows.inverse_mass);
        self.force.clone_from(&rows.force);
        self.axes.clone_from(&rows.axes);
        self.first = rotation::first_angular(rows);
        if self.first.is_some() {
            self.velocity.clone_from(&rows.velocity);
        }
        let dim = rows.dim;
        // The pattern is the system's, one per row; rows of another count take none.
        let known = self.pattern.len() == rows.rows.len();
        for (r, row) in rows.rows.iter().enumerate() {
            // A distance row's |J_b|² is 1 exactly where J is a number (`unit_square`).
            let unit = known && self.pattern.is_unit(r);
            let mut k = 0.0;
            let entries = self.start[r]..self.start[r + 1];
            for (&e, kept) in self.source[entries.clone()].iter().zip(&mut self.jacobian[entries]) {
                let (b, j) = (&row.jacobian[e].0, &row.jacobian[e].1);
                *kept = *j;
                // Every component: the squares of the structural zeros add +0 to a sum ≥ +0,
                // so the mask would give the same bits.
                k += rows.inverse_mass[*b] * if unit { unit_square(dim, j) } else { dot_in(dim, j, j) };
            }
            self.value.push(row.value);
            self.time_rate.push(self.time_rate_of(rows, r));
            self.effective_mass.push(if k > 0.0 && k.is_finite() { 1.0 / k } else { 0.0 });
            self.inequality.push(row.inequality);
        }
    }

    /// ∂Cₖ/∂t of row k of `rows`, whose length is that of its entries in the layout: 0 on
    /// a steady row, else Ċₖ − Σᵢ Jₖᵢ·vᵢ at the velocities the rows were evaluated at,
    /// summed from 0 over the entries in [`entry_order`] (the [`Prepared::rate`] of its
    /// `time_rate`). Each entry's velocity is that of its slot in the row, the layout's slot
    /// where the layout is the row's.
    #[inline(always)]
    fn time_rate_of(&self, rows: &Rows, k: usize) -> f64 {
        if self.steady.len() == rows.rows.len() && self.steady[k] {
            return 0.0;
        }
        let row = &rows.rows[k];
        let mut jv = 0.0;
        let entries = self.start[k]..self.start[k + 1];
        for (&e, &mask) in self.source[entries.clone()].iter().zip(&self.mask[entries]) {
            let (b, j) = &row.jacobian[e];
            jv += dot_masked(mask, j, &rows.velocity[*b]);
        }
        row.rate - jv
    }

    /// Ċ of every row of `rows` at velocities `u` (in the rows' slots), read from the rows
    /// themselves: [`Prepared::load`] then [`Prepared::rate`] give the same numbers bit for
    /// bit, but copy J and ∂C/∂t first and take the effective masses, which the exact solve
    /// (each row read once a substep) does not need. The layout is checked in the same pass
    /// (each row's length and each entry's slot against those it was made for) and made
    /// again, and the rates taken again, where it is not `rows`'.
    pub fn rates(&mut self, rows: &Rows, u: &Vectors) -> &[f64] {
        let mut rates = std::mem::take(&mut self.rates);
        rates.clear();
        let fits = self.dim == rows.dim
            && self.start.len() == rows.rows.len() + 1
            && (0..rows.rows.len()).all(|k| {
                let (rate, fits) = self.rate_checked(rows, k, u);
                rates.push(rate);
                fits
            });
        if !fits {
            self.lay_out(rows);
            rates.clear();
            rates.extend((0..rows.rows.len()).map(|k| self.rate_checked(rows, k, u).0));
        }
        self.rates = rates;
        &self.rates
    }

    /// Ċₖ at `u` from row k of `rows` through the layout, and whether the layout is row k's
    /// (its length, and each entry's slot): where it is not, the number is not to be read.
    /// A layout of another length is found before any entry is read, and every entry reads
    /// the velocities of its slot in the row, so no index leaves its slice.
    #[inline(always)]
    fn rate_checked(&self, rows: &Rows, k: usize, u: &Vectors) -> (f64, bool) {
        let row = &rows.rows[k];
        let entries = self.start[k]..self.start[k + 1];
        if row.jacobian.len() != entries.len() {
            return (0.0, false);
        }
        let (mut c, mut fits) = (self.time_rate_of(rows, k), true);
        let layout = self.source[entries.clone()].iter().zip(&self.mask[entries.clone()]).zip(&self.body[entries]);
        for ((&e, &mask), &slot) in layout {
            let (b, j) = &row.jacobian[e];
            fits &= *b == slot;
            c += dot_masked(mask, j, &u[*b]);
        }
        (c, fits)
    }

    /// Whether the layout (`start`, `body`, `mask`, `source`) is that of `rows`: the same
    /// dimension, row count and, per row, the same slots in the same places of its J.
    fn fits(&self, rows: &Rows) -> bool {
        self.dim == rows.dim
            && self.start.len() == rows.rows.len() + 1
            && rows.rows.iter().zip(self.start.windows(2)).all(|(row, s)| {
                row.jacobian.len() == s[1] - s[0]
                    && self.source[s[0]..s[1]].iter().zip(&self.body[s[0]..s[1]]).all(|(&e, &b)| row.jacobian[e].0 == b)
            })
    }

    /// The layout of `rows`' entries: per row its entries in [`entry_order`], each with its
    /// slot, its mask (the pattern's, every component of the dimension for rows it does not
    /// describe) and its index in the row's J.
    fn lay_out(&mut self, rows: &Rows) {
        self.start.clear();
        self.body.clear();
        self.mask.clear();
        self.source.clear();
        self.dim = rows.dim;
        let dim = rows.dim;
        let mut previous = 0;
        // The pattern is the system's, one per row; rows of another count take none.
        // A dense pattern's masks are all `full(dim)`: no lookup per entry.
        let pattern = self.pattern.len() == rows.rows.len() && !self.pattern.is_dense();
        for (r, row) in rows.rows.iter().enumerate() {
            let at = self.body.len();
            self.start.push(at);
            self.order.clear();
            entry_order(&self.body[previous..at], row.jacobian.len(), |e| row.jacobian[e].0, &mut self.order);
            previous = at;
            for &e in &self.order {
                let b = row.jacobian[e].0;
                self.body.push(b);
                self.mask.push(if pattern { self.pattern.mask(r, b) } else { full(dim) });
                self.source.push(e);
            }
        }
        self.start.push(self.body.len());
    }

    pub fn len(&self) -> usize {
        self.value.len()
    }

    pub fn is_empty(&self) -> bool {
        self.value.is_empty()
    }

    /// Ċₖ at velocities `u`: ∂Cₖ/∂t + Σᵢ Jₖᵢ·uᵢ, summed in that order over the entries in
    /// [`entry_order`], each product over its entry's components that can be nonzero
    /// ([`dot_masked`]).
    #[inline(always)]
    pub fn rate(&self, k: usize, u: &Vectors) -> f64 {
        let mut c = self.time_rate[k];
        for e in self.start[k]..self.start[k + 1] {
            c += dot_masked(self.mask[e], &self.jacobian[e], &u[self.body[e]]);
        }
        c
    }

    /// Applies an impulse `p` of row k: uᵢ += (1/mᵢ) Jₖᵢ p, on the components of Jₖᵢ that can
    /// be nonzero (adding s·0 would leave uᵢ as it is, but for the sign of a zero).
    #[inline(always)]
    pub fn apply(&self, k: usize, u: &mut Vectors, p: f64) {
        for e in self.start[k]..self.start[k + 1] {
            let (b, j, mask) = (self.body[e], &self.jacobian[e], self.mask[e]);
            let (s, u) = (self.inverse_mass[b] * p, &mut u[b]);
            // The common masks written out (one predictable branch an entry), as `dot_masked`.
            match mask {
                0b011 => {
                    u[0] += s * j[0];
                    u[1] += s * j[1];
                }
                0b111 => {
                    u[0] += s * j[0];
                    u[1] += s * j[1];
                    u[2] += s * j[2];
                }
                _ => {
                    for d in (0..3).filter(|d| mask >> d & 1 != 0) {
                        u[d] += s * j[d];
                    }
                }
            }
        }
    }

    /// u += h M⁻¹ F: the external forces over one substep, u in the rows' slots
    /// ([`Prepared::to_axes`]). A 3D rigid body's torque and gyroscopic term go through the
    /// implicit-midpoint kick in its principal frame (`rotation::kick_axes`).
    pub fn kick(&self, u: &mut Vectors, h: f64) {
        kick(u, h, self.first, &self.inverse_mass, &self.force, &self.velocity);
    }

    /// State slots (a 3D rigid body's world ω or rotation vector in its first slot) into the
    /// rows' slots (its components along the principal axes of these rows), in place; nothing
    /// changes without 3D rigid bodies.
    pub fn to_axes(&self, x: &mut Vectors) {
        rotation::to_axes(&self.axes, x);
    }

    /// The inverse of [`Prepared::to_axes`].
    pub fn to_world(&self, x: &mut Vectors) {
        rotation::to_world(&self.axes, x);
    }

    /// q += h u over state slots, a 3D rigid body's rotation vector (since the step's start)
    /// turned exactly by h ω: φ ← log(exp(h ω) ⊗ exp(φ)) (`rotation::compose`).
    pub fn drift(&self, q: &mut Vectors, u: &Vectors, h: f64) {
        drift_turning(q, u, h, self.first);
    }

    /// Warm start: every row's accumulated impulse applied again.
    pub fn warm_start(&self, u: &mut Vectors, impulse: &[f64]) {
        for (k, &p) in impulse.iter().enumerate() {
            if p != 0.0 {
                self.apply(k, u, p);
            }
        }
    }

    /// One Gauss–Seidel sweep over the rows in file order: row k of value C, with the bias b
    /// and softness s that `law(k, C)` gives, takes ΔP = −s_m·m_eff·(Ċ + bias) − s_i·P (Box2D
    /// `b2SolveDistanceJoint`), an inequality row clamping the accumulated impulse at P ≥ 0
    /// (Box2D `b2SolveContact`; Catto, "Iterative Dynamics with Temporal Coherence", 2005).
    pub fn sweep(&self, u: &mut Vectors, impulse: &mut [f64], mut law: impl FnMut(usize, f64) -> (f64, Softness)) {
        for (k, impulse) in impulse.iter_mut().enumerate() {
            let m = self.effective_mass[k];
            if m == 0.0 {
                continue;
            }
            let (bias, soft) = law(k, self.value[k]);
            let rate = self.rate(k, u);
            let old = *impulse;
            let mut delta = -soft.mass_scale * m * (rate + bias) - soft.impulse_scale * old;
            if self.inequality[k] {
                delta = (old + delta).max(0.0) - old;
            }
            *impulse = old + delta;
            self.apply(k, u, delta);
        }
    }
}

/// [`Prepared::kick`] with the slots' 1/m (1/I), F (τ) and velocities (3D rigid bodies:
/// the rows' evaluated ω) given, from the slot `first` of the first 3D rigid body on.
pub fn kick(
    u: &mut Vectors,
    h: f64,
    first: Option<usize>,
    inverse_mass: &[f64],
    force: &[[f64; 3]],
    velocity: &[[f64; 3]],
) {
    let first = first.unwrap_or(u.len());
    for ((u, f), w) in u[..first].iter_mut().zip(force).zip(inverse_mass) {
        for d in 0..3 {
            u[d] += h * w * f[d];
        }
    }
    for g in (first..u.len()).step_by(3) {
        let axis = |x: &[[f64; 3]]| [x[g][0], x[g + 1][0], x[g + 2][0]];
        let w = [inverse_mass[g], inverse_mass[g + 1], inverse_mass[g + 2]];
        let w1 = rotation::kick_axes(w, axis(force), axis(velocity), h, axis(u));
        for k in 0..3 {
            u[g + k] = [w1[k], 0.0, 0.0];
        }
    }
}

/// [`Prepared::drift`] with the slot `first` of the first 3D rigid body given.
pub fn drift_turning(q: &mut Vectors, u: &Vectors, h: f64, first: Option<usize>) {
    let Some(first) = first else { return drift(q, u, h) };
    drift(&mut q[..first], &u[..first], h);
    for g in (first..q.len()).step_by(3) {
        q[g] = rotation::compose(u[g].map(|x| h * x), q[g]);
    }
}

/// q += h u.
pub fn drift(q: &mut [[f64; 3]], u: &[[f64; 3]], h: f64) {
    for (q, u) in q.iter_mut().zip(u) {
        for d in 0..3 {
            q[d] += h * u[d];
        }
    }
}

/// A velocity-level solver with its state between steps and its scratch.
pub struct Stepper {
    pub settings: Settings,
    /// Accumulated impulse per row (the warm-start storage); XPBD: its λ of the last substep.
    pub impulse: Vec<f64>,
    prepared: Prepared,
    /// The velocities at the start of the step (restitution), the positions before a
    /// substep (XPBD) or before its projection (the exact solve's, to fall back from).
    saved: Vec<[f64; 3]>,
    /// The positions the rows were evaluated at (XPBD).
    evaluated: Vec<[f64; 3]>,
    /// Ċ per row at the start of the step (restitution's relative velocity).
    start_rate: Vec<f64>,
    /// Whether the step to come must leave its impulses in `impulse` (true from
    /// [`Stepper::new`]; the run loop sets it from [`Settings::lambda_at`]). Only the exact
    /// solve reads it: without, `impulse` keeps an older step's and [`Stepper::lambda`] is
    /// not to be read.
    pub wants_impulse: bool,
    /// The exact solve's bound on the distance |C|/‖∇C‖ its last projection aimed for (the
    /// last step's, in the run's unit); `None` for the solvers that do not project. The run
    /// loop takes it to report a step whose positions stayed farther (`Summary::unconverged`).
    pub projection_bound: Option<f64>,
}

impl Stepper {
    pub fn new(settings: Settings, rows: usize, bodies: usize) -> Stepper {
        Stepper {
            settings,
            impulse: vec![0.0; rows],
            prepared: Prepared::default(),
            saved: vec![[0.0; 3]; bodies],
            evaluated: vec![[0.0; 3]; bodies],
            start_rate: vec![0.0; rows],
            wants_impulse: true,
            projection_bound: None,
        }
    }

    /// The constraint force per row that the last step applied, P/h (XPBD: λ/h²): what the
    /// CSV shows as λ.
    pub fn lambda(&self, out: &mut Vec<f64>) {
        let h = self.settings.substep();
        let scale = match self.settings.solver {
            Solver::Xpbd => 1.0 / (h * h),
            _ => 1.0 / h,
        };
        out.clear();
        out.extend(self.impulse.iter().map(|p| p * scale));
    }

    /// One step of `settings.dt` from (t, q, v), whose rows `rows` are (the run loop has them
    /// from recording the state; they are recycled). 3D rigid bodies: every substep starts
    /// with `Dynamics::rebase` (the orientation is unchanged, so the rows still hold), so a
    /// rotation vector in `q` is the turn since the substep's start.
    pub fn step(
        &mut self,
        dynamics: &mut Dynamics<'_>,
        t: f64,
        q: &mut Vectors,
        v: &mut Vectors,
        rows: Rows,
    ) -> Result<(), SimError> {
        // Once per stepper: which rows have ∂C/∂t = 0 exactly, and J's structural zeros.
        if self.prepared.steady.is_empty() {
            self.prepared.set_system(dynamics.system());
        }
        match self.settings.solver {
            Solver::SoftStep => soft_step::step(self, dynamics, t, q, v, rows),
            Solver::Pgs => pgs::step(self, dynamics, t, q, v, rows),
            Solver::Xpbd => xpbd::step(self, dynamics, t, q, v, rows),
            Solver::Exact => exact::step(self, dynamics, t, q, v, rows),
        }
    }
}
