//! The numbers of the constraint rows at one state: C, Ċ, J, c per constraint, with the
//! bodies' inverse masses, velocities and external forces — everything the λ solve, the
//! contact logic and the integrators read.
//!
//! Every row refers to C/κ, as the derivation does (κ the constant content taken out of ∇C):
//! `value` = C/κ, `rate` = Ċ/κ, `jacobian` = ∇C/κ, `bias` = c, so C̈/κ = Σᵢ Jᵢ·aᵢ + c and a
//! Newton step on `value` along `jacobian` is consistent.
//!
//! The roots are nodes of the derivation's graph, gathered from `&System` and `&Derivation`
//! without adding any (the bodies' velocity and force nodes are `Body::nodes`). Where each
//! body's and each row's numbers sit among them is recorded as they are gathered
//! (`BodySlots`, `RowLayout`), so adding a quantity (an angular J, a torque) means adding
//! a slot, not recounting offsets.
//!
//! Rigid bodies enter in generalised coordinates: after the n bodies' linear slots (1/m, v,
//! F, and J per body) come one angular slot per rigid body (2D: 1/I, ω, τ and Jʷ, scalars
//! in component 0 of the slot's `[f64; 3]`), in the order [`angular_bodies`] gives; a 3D
//! rigid body has three, one per principal axis eₖ = R(q) eₖ (1/Iₖ, eₖ·ω,
//! eₖ·τ − (ω_b × I ω_b)ₖ with ω_b = (eⱼ·ω)ⱼ, and Jʷ·eₖ), so M⁻¹ stays diagonal with the world
//! inertia R diag(I) Rᵀ; [`world_angular`] turns per-axis results back into world vectors. So u = (v, ω),
//! M = blockdiag(mᵢE, Iᵢ) and A = J M⁻¹ Jᵀ, b = J M⁻¹ (F, τ) + c are what the solve, the
//! contact logic and the projections already compute over slots: none of them needs to know
//! which slot is an angle (DESIGN.md, "Rigid bodies"; 2D has no gyroscopic term).
//!
//! Evaluation goes through one compiled [`Tape`] of every root (`evaluate`, `evaluate_into`),
//! run as machine code once `RowProgram::compile` has made it so (the `jit` feature);
//! the interpreter (`expr::eval`, the reference semantics) stays available as
//! `evaluate_interpreted`, and a test holds the two together on every constraint file.
//!
//! Not here: files or text (the state arrives as an [`Env`]); solving (`numeric::solve`).

use crate::derive::Derivation;
use crate::expr::eval::{Env, EvalError, Value, eval};
use crate::expr::graph::{FastMap, FastSet, SymbolWalk};
use crate::expr::{Func, Id, Rational, Symbol, Ty};
use crate::model::system::System;
use crate::numeric::batch::{Batched, BatchedScratch};
use crate::numeric::integrate::copy_slots;
use crate::numeric::program::{Inputs, Program};
use crate::numeric::tape::{Scratch, Tape};
use crate::numeric::vector::{all_finite, dot, not_finite_bit, not_finite_bits};
use std::ops::Range;

/// One constraint row at a state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Row {
    /// C/κ.
    pub value: f64,
    /// Ċ/κ.
    pub rate: f64,
    /// c: C̈/κ with every acceleration zero.
    pub bias: f64,
    /// `C ≥ 0` rather than `C = 0`.
    pub inequality: bool,
    /// `(body, Jᵢ = ∇ᵢC/κ)`, components past the dimension zero.
    pub jacobian: Vec<(usize, [f64; 3])>,
}

/// All rows of a system at one state, with the bodies' numbers.
///
/// Indexed by slot: the system's bodies `0..n` (their linear part), then one angular slot per
/// rigid body ([`angular_slot`]: 1/I, ω, τ in component 0). Without rigid bodies the slots
/// are the bodies.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Rows {
    pub dim: usize,
    /// 1/m per body, then 1/I per angular slot.
    pub inverse_mass: Vec<f64>,
    /// v per body, then `[ω, 0, 0]` per angular slot.
    pub velocity: Vec<[f64; 3]>,
    /// External force per body, then `[τ, 0, 0]` per angular slot.
    pub force: Vec<[f64; 3]>,
    pub rows: Vec<Row>,
    /// 3D: per slot, the world direction an angular slot's component 0 is along (the
    /// body's principal axis R(q) eₖ; zero for linear slots). Empty in 2D.
    pub axes: Vec<[f64; 3]>,
}

impl Rows {
    /// The slots' 1/m and F (and the dimension) of `from`, whose velocities and rows are
    /// left as they are: for rows whose slots are constants of a run
    /// (`RowProgram::steady`). In line: SHAKE takes them at every step of a steady run, and
    /// for a one-slot scene the call's own instructions were a third of the copy.
    #[inline]
    pub fn take_slots(&mut self, from: &Rows) {
        self.dim = from.dim;
        self.axes.clear();
        let n = from.inverse_mass.len();
        if self.inverse_mass.len() != n || self.force.len() != n {
            self.inverse_mass.resize(n, 0.0);
            self.force.resize(n, [0.0; 3]);
        }
        copy_slots(&mut self.inverse_mass, &from.inverse_mass);
        copy_slots(&mut self.force, &from.force);
    }

    /// The one row and the one slot's 1/m, v and F of rows of that shape (a pendulum, a
    /// bead), else `None`.
    #[inline(always)]
    pub fn one_slot(&self) -> Option<(&Row, f64, &[f64; 3], &[f64; 3])> {
        match (self.rows.as_slice(), self.inverse_mass.as_slice(), self.velocity.as_slice(), self.force.as_slice()) {
            ([row], [w], [v], [f]) => Some((row, *w, v, f)),
            _ => None,
        }
    }

    /// [`one_slot`](Rows::one_slot), to write in place.
    #[inline(always)]
    pub fn one_slot_mut(&mut self) -> Option<(&mut Row, &mut f64, &mut [f64; 3], &mut [f64; 3])> {
        match (
            self.rows.as_mut_slice(),
            self.inverse_mass.as_mut_slice(),
            self.velocity.as_mut_slice(),
            self.force.as_mut_slice(),
        ) {
            ([row], [w], [v], [f]) => Some((row, w, v, f)),
            _ => None,
        }
    }
}

/// The rigid bodies of `system` in the order of their angular slots: the r-th body this
/// yields has the slots `system.bodies.len() + r·w ..` of [`angular_width`] w.
pub fn angular_bodies(system: &System) -> impl Iterator<Item = usize> + '_ {
    system.bodies.iter().enumerate().filter(|(_, b)| b.rigid.is_some()).map(|(i, _)| i)
}

/// How many angular slots a rigid body has: 1 in 2D (the angle), 3 in 3D (one per
/// principal axis, so M = blockdiag(mE, diag(I1, I2, I3)) in the body's axes stays
/// diagonal and the solve needs no 3×3 block).
pub fn angular_width(system: &System) -> usize {
    if system.dim() == 3 { 3 } else { 1 }
}

/// The first angular slot of body `body` of `system`, if it is rigid (2D: its only one).
pub fn angular_slot(system: &System, body: usize) -> Option<usize> {
    angular_slots(system, body).map(|r| r.start)
}

/// The angular slots of body `body` of `system`, if it is rigid.
pub fn angular_slots(system: &System, body: usize) -> Option<Range<usize>> {
    let w = angular_width(system);
    angular_bodies(system)
        .position(|b| b == body)
        .map(|r| system.bodies.len() + r * w..system.bodies.len() + (r + 1) * w)
}

/// The world vector Σₖ xₖ R(q) eₖ of a 3D rigid body's angular slots `slots`, from the
/// number `x(slot)` of each (a constraint torque, an angular acceleration); 2D:
/// `[x(slot), 0, 0]`.
pub fn world_angular(rows: &Rows, x: impl Fn(usize) -> f64, slots: Range<usize>) -> [f64; 3] {
    if rows.axes.is_empty() {
        return [x(slots.start), 0.0, 0.0];
    }
    let mut out = [0.0; 3];
    for slot in slots {
        for (o, e) in out.iter_mut().zip(rows.axes[slot]) {
            *o += x(slot) * e;
        }
    }
    out
}

/// The expressions to evaluate for a system's rows, gathered once and compiled to a
/// [`Tape`] (the interpreter of `expr::eval` is the reference semantics, not the hot path).
#[derive(Clone, Debug)]
pub struct RowProgram {
    /// Every root, in the order the slots of `bodies` and `rows` say.
    roots: Vec<Id>,
    /// Where each body's numbers are among the roots, then each angular slot's.
    bodies: Vec<BodySlots>,
    /// What each constraint row is and where its numbers are among the roots.
    rows: Vec<RowLayout>,
    /// Every root, compiled over their free symbols (and, when the scene repeats a shape,
    /// shape by shape: `numeric::batch`): what [`evaluate_into`](RowProgram::evaluate_into)
    /// runs. Its root r is the program's root r.
    all: Subprogram,
    /// C and J alone (with the principal axes they are projected on): what an iteration
    /// onto C = 0 reads ([`RowProgram::evaluate_positions_into`]).
    positions: Subprogram,
    /// Everything but C and J: each row's Ċ and c, each slot's mass, velocity and force —
    /// what changes when only the velocities do ([`RowProgram::evaluate_motion_state_into`]).
    /// `None` with 3D rigid bodies, whose slots read the principal axes too.
    motion: Option<Subprogram>,
    /// Whether some constraint's C reads t (`simulate::time_dependent`), found once here:
    /// a run asks at its start, and a run of a few steps of a long chain spent about a step
    /// collecting each constraint's free symbols.
    time_dependent: bool,
    /// [`steady`](RowProgram::steady), found once here.
    steady: bool,
}

/// How a [`Subprogram`] computes its roots.
#[derive(Clone, Debug)]
enum Kernel {
    /// One tape of the roots over their free symbols, in its own layout, and the tape
    /// compiled to machine code once `RowProgram::compile` has made it (the same numbers,
    /// bit for bit, without the interpreter's dispatch).
    Tape(Tape, Option<Compiled>),
    /// The same roots shape by shape (`numeric::batch`), reading their inputs as `Flat`
    /// lays them out. No tape of all of them is compiled then: on a big scene it would cost
    /// as much as the batches' lowering many times over and never run.
    Batched(Box<Batched>, Flat),
}

/// A tape compiled to machine code ([`Tape::jit`]), shared by the clones of its program
/// (a simulation that borrows a scenario's program and one that owns a copy run one code).
#[cfg(feature = "jit")]
type Compiled = std::sync::Arc<crate::numeric::jit::JitTape>;

/// Without the `jit` feature no tape is compiled: this type has no value, so a
/// `Kernel::Tape`'s twin is always `None` and its test folds away.
#[cfg(not(feature = "jit"))]
#[derive(Clone, Debug)]
enum Compiled {}

/// The roots from `inputs` into `outputs` by the compiled twin of a tape.
#[cfg(feature = "jit")]
#[inline]
fn run_compiled(compiled: &Compiled, inputs: &[f64], outputs: &mut [f64]) {
    compiled.eval(inputs, outputs);
}

/// Never called: there is no value of [`Compiled`] without the `jit` feature.
#[cfg(not(feature = "jit"))]
#[inline]
fn run_compiled(compiled: &Compiled, _: &[f64], _: &mut [f64]) {
    match *compiled {}
}

/// Some of a [`RowProgram`]'s roots, and how they are evaluated.
#[derive(Clone, Debug)]
struct Subprogram {
    kernel: Kernel,
    inputs: Vec<Symbol>,
    /// Per program root, where its components are among the outputs (`len` 0: not in
    /// them): in the tape's layout, or the batches'.
    place: Vec<Place>,
    sources: Vec<Source>,
    /// The inputs that are not constants of a run (`Source::Env`), with their slots: what
    /// a state evaluation loads once the constants are held ([`RowScratch::hold_constants`]).
    varying: Vec<Load>,
    /// `varying` as copies from the state's arrays, when every one of them comes from there
    /// (no rigid body's angle, which the environment gives) and a tape reads them in its own
    /// layout (no batches): a state evaluation with the constants held is then
    /// [`StateCopies::load`] alone.
    copies: Option<StateCopies>,
    /// Where `tape` leaves each number `Rows` reads, in the order they are filled (`None`
    /// with 3D rigid bodies, whose slots are projected on their axes by `fill`).
    places: Option<Places>,
}

/// Where a [`Subprogram`]'s outputs hold the numbers of the rows and slots, listed in the
/// order `Rows` is filled (each row's C, Ċ, c; every row's J entries in turn; each slot's
/// 1/m, v, F), so one pass down these lists fills `Rows` with no lookup through the
/// program's roots and no test of a slot's kind. Only for scenes without 3D rigid bodies,
/// whose every slot is a plain (1/m, v, F) and every J entry its root's value.
#[derive(Clone, Debug, Default)]
struct Places {
    /// Per row: where its numbers are and what the fill needs of its layout, in one
    /// record (a fill's loop over the rows then walks two lists, these and the rows).
    rows: Vec<RowPlaces>,
    /// Every row's J entries in turn (`RowPlaces::entries` a row).
    jacobian: Vec<Entry>,
    /// Per slot: the output of 1/m's m, and the places of v and F.
    mass: Vec<u32>,
    velocity: Vec<Place>,
    force: Vec<Place>,
    /// The width every J entry has (the dimension, for point masses alone), or 0 when
    /// they differ (2D rigid bodies' Jʷ is one number): the fill then reads each entry
    /// without testing its width.
    width: u32,
    /// The same of every slot's v and F.
    slot_width: u32,
    /// The outputs' length: every place of `jacobian`, `velocity` and `force` lies below it
    /// (checked when they are listed), so a fill that has checked its outputs' length
    /// ([`Places::outputs`]) reads them without a check per number.
    outputs: usize,
}

/// One row's part of [`Places`].
#[derive(Clone, Copy, Debug)]
struct RowPlaces {
    /// The output of C, Ċ, c (`ABSENT`: not a root of this tape).
    value: u32,
    rate: u32,
    bias: u32,
    /// How many J entries the row has (`RowLayout::bodies.len()`).
    entries: u32,
    /// `RowLayout::inverse_scale` and `inequality`.
    inverse_scale: f64,
    inequality: bool,
}

/// One J entry of a row in [`Places`]: where it is among the outputs, and its slot.
#[derive(Clone, Copy, Debug)]
struct Entry {
    place: Place,
    slot: u32,
}

/// A subprogram's outputs, checked to be as long as its [`Places`] say
/// ([`Places::outputs`]).
#[derive(Clone, Copy)]
struct Outputs<'a>(&'a [f64]);

/// Where a root's components are among a subprogram's outputs: the first, how many (one
/// to three; 0: the root is not there), and the distance between two — 1 in a tape's own
/// layout; a batch's members, evaluated in lanes, have their components a chunk's members
/// apart (`numeric::batch`), and are read there rather than copied into the tape's layout.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Place {
    start: u32,
    len: u32,
    stride: u32,
}

impl Place {
    /// The root's components in `out` (zero past `len`).
    #[inline]
    fn read(self, out: &[f64]) -> [f64; 3] {
        let (s, d) = (self.start as usize, self.stride as usize);
        match self.len {
            2 => [out[s], out[s + d], 0.0],
            3 => [out[s], out[s + d], out[s + 2 * d]],
            1 => [out[s], 0.0, 0.0],
            _ => [0.0; 3],
        }
    }

    /// [`read`](Place::read) of a root known to be `W` (2 or 3) wide, from outputs whose
    /// length is checked: no test of the width, no bounds check (the fills' reads of J, v
    /// and F, where a check per component cost about as much as the copy).
    ///
    /// # Safety
    /// `self` is `W` wide and one of the places listed in the [`Places`] whose
    /// [`outputs`](Places::outputs) made `out`.
    #[inline(always)]
    unsafe fn read_of<const W: usize>(self, out: Outputs<'_>) -> [f64; 3] {
        let (s, d) = (self.start as usize, self.stride as usize);
        let mut v = [0.0; 3];
        for (k, x) in v.iter_mut().enumerate().take(W) {
            // SAFETY: `Places::new` checked that each of its places' `len` components lies
            // below its `outputs`, and `Places::outputs` that `out` is that long.
            *x = unsafe { *out.0.get_unchecked(s + k * d) };
        }
        v
    }

    /// [`read_of`](Place::read_of) of a root `W` (2 or 3) wide, or, for `W` = 0, of any
    /// width (a test of its `len`, still no bounds check: the fills of a 2D rigid body's
    /// rows, whose linear J and v are 2 wide and angular ones 1).
    ///
    /// # Safety
    /// As [`read_of`](Place::read_of); for `W` ≠ 0, `self` is `W` wide.
    #[inline(always)]
    unsafe fn read_width<const W: usize>(self, out: Outputs<'_>) -> [f64; 3] {
        // SAFETY: the caller's: `self` is one of the places that made `out`, of the width read.
        unsafe {
            match (W, self.len) {
                (0, 1) => self.read_of::<1>(out),
                (0, 2) => self.read_of::<2>(out),
                (0, 3) => self.read_of::<3>(out),
                (0, _) => [0.0; 3],
                _ => self.read_of::<W>(out),
            }
        }
    }
}

/// The width every one of `places` has, or 0 when they differ (or there are none).
fn common_width(places: &[Place]) -> u32 {
    match places.first() {
        Some(p) if places.iter().all(|x| x.len == p.len) => p.len,
        _ => 0,
    }
}

/// The panic of [`Places::outputs`] given another subprogram's outputs: out of line.
#[cold]
#[inline(never)]
fn outputs_misused(len: usize, expected: usize) -> ! {
    panic!("outputs of length {len} read along places of {expected}")
}

/// A root a tape does not compute, in [`Places`].
const ABSENT: u32 = u32::MAX;

impl Places {
    /// `out`, checked to be these places' outputs.
    #[inline]
    fn outputs<'a>(&self, out: &'a [f64]) -> Outputs<'a> {
        if out.len() != self.outputs {
            outputs_misused(out.len(), self.outputs);
        }
        Outputs(out)
    }

    /// The places of `sub`'s outputs for `rows` and `bodies` (none of them a principal axis).
    fn new(sub: &Subprogram, bodies: &[BodySlots], rows: &[RowLayout]) -> Places {
        let scalar = |root: usize| match sub.place[root] {
            Place { len: 0, .. } => ABSENT,
            Place { start, .. } => start,
        };
        let entry = |(&slot, root): (&usize, usize)| Entry { place: sub.place[root], slot: slot as u32 };
        let jacobian: Vec<Entry> =
            rows.iter().flat_map(|r| r.bodies.iter().zip(r.jacobian.clone()).map(entry)).collect();
        let velocity: Vec<Place> = bodies.iter().map(|b| sub.place[b.velocity]).collect();
        let force: Vec<Place> = bodies.iter().map(|b| sub.place[b.force]).collect();
        let slot_width = match (common_width(&velocity), common_width(&force)) {
            (v, f) if v == f => v,
            _ => 0,
        };
        let outputs = sub.output_len();
        let inside = |p: &Place| p.len == 0 || (p.start as usize + (p.len as usize - 1) * p.stride as usize) < outputs;
        let places: Vec<Place> = jacobian.iter().map(|e| e.place).collect();
        assert!(places.iter().chain(&velocity).chain(&force).all(inside), "a root's place lies past the outputs");
        let row = |r: &RowLayout| RowPlaces {
            value: scalar(r.value),
            rate: scalar(r.rate),
            bias: scalar(r.bias),
            entries: r.bodies.len() as u32,
            inverse_scale: r.inverse_scale,
            inequality: r.inequality,
        };
        Places {
            outputs,
            rows: rows.iter().map(row).collect(),
            width: common_width(&places),
            jacobian,
            mass: bodies.iter().map(|b| scalar(b.mass)).collect(),
            velocity,
            force,
            slot_width,
        }
    }
}

/// Whether the three components are finite (combined with `&`: no branch).
#[inline]
fn finite3(x: &[f64; 3]) -> bool {
    x[0].is_finite() & x[1].is_finite() & x[2].is_finite()
}

impl Subprogram {
    /// The input buffer: the tape's own layout, or the batches' (`Flat`).
    fn input_len(&self) -> usize {
        match &self.kernel {
            Kernel::Tape(tape, _) => tape.input_len(),
            Kernel::Batched(_, flat) => flat.len,
        }
    }

    /// The inputs from `env` into `buffer` (of [`input_len`](Subprogram::input_len)).
    fn load(&self, system: &System, env: &Env, buffer: &mut [f64]) -> Result<(), EvalError> {
        match &self.kernel {
            Kernel::Batched(_, flat) => flat.load(system, env, &self.inputs, buffer),
            Kernel::Tape(tape, _) => load(system, env, tape, &self.inputs, buffer),
        }
    }

    /// The inputs from `state` and `env` into `scratch`'s buffer; the constants of a run
    /// (`Source::Env`) only when they are not held there already (`hold`: they are to be
    /// kept, see [`RowScratch::hold_constants`]).
    ///
    /// In line, its common case apart: with the constants held and every other input from
    /// the state's arrays (a scene of point masses, once a run has started), only the state's
    /// numbers are copied, by [`load_from_state`] (a copy of a few numbers, where the general
    /// load — the environment, its errors, the batches — costs about a hundred instructions
    /// a call for a one-body scene).
    #[inline(always)]
    fn load_state(
        &self,
        system: &System,
        env: &Env,
        state: State<'_>,
        hold: bool,
        scratch: &mut SubScratch,
    ) -> Result<(), EvalError> {
        if let Some(copies) = &self.copies
            && hold
            && scratch.constants
        {
            copies.load(state, &mut scratch.inputs);
            return Ok(());
        }
        self.load_state_any(system, env, state, hold, scratch)
    }

    /// [`load_state`](Subprogram::load_state) in every case.
    #[inline(never)]
    fn load_state_any(
        &self,
        system: &System,
        env: &Env,
        state: State<'_>,
        hold: bool,
        scratch: &mut SubScratch,
    ) -> Result<(), EvalError> {
        let buffer = &mut scratch.inputs;
        let held = hold && scratch.constants;
        match &self.kernel {
            Kernel::Batched(_, flat) => flat.load_state(system, env, state, &self.inputs, held, buffer)?,
            Kernel::Tape(..) if held => load_varying(system, env, state, &self.inputs, &self.varying, buffer)?,
            Kernel::Tape(tape, _) => {
                let all = 0..self.inputs.len();
                load_state(system, env, state, tape, &self.inputs, &self.sources, all, buffer)?
            }
        }
        scratch.constants = hold;
        Ok(())
    }

    /// The outputs' length: the tape's, or the batches'.
    fn output_len(&self) -> usize {
        match &self.kernel {
            Kernel::Tape(tape, _) => tape.output_len(),
            Kernel::Batched(batched, _) => batched.output_len(),
        }
    }

    /// Every root from the loaded `inputs` into `outputs` (laid out as `place` says): by
    /// the compiled tape when there is one, else by the interpreter. In line (its callers
    /// are few, and a call of it was a visible part of a small evaluation).
    #[inline(always)]
    fn run(&self, inputs: &[f64], tape: &mut Scratch, batched: Option<&mut BatchedScratch>, outputs: &mut [f64]) {
        match (&self.kernel, batched) {
            (Kernel::Batched(b, _), Some(buffers)) => b.eval(inputs, buffers, outputs),
            (Kernel::Batched(b, _), None) => evaluate_batched_without_scratch(b, inputs, outputs),
            (Kernel::Tape(_, Some(compiled)), _) => run_compiled(compiled, inputs, outputs),
            (Kernel::Tape(t, None), _) => t.eval(inputs, tape, outputs),
        }
    }

    /// The roots `wanted` of `roots` (indices) over their own free symbols: batched by the
    /// `units` of `roots` (`numeric::batch`) where some shape repeats, else one tape.
    fn new(
        system: &System,
        graph: &crate::expr::Graph,
        roots: &[Id],
        wanted: impl IntoIterator<Item = usize>,
        units: &[Vec<usize>],
    ) -> Subprogram {
        let mut root = vec![usize::MAX; roots.len()];
        let mut ids = Vec::new();
        for r in wanted {
            if root[r] == usize::MAX {
                root[r] = ids.len();
                ids.push(roots[r]);
            }
        }
        let inputs: Vec<Symbol> = SymbolWalk::default().free_symbols_of(graph, &ids).to_vec();
        // The layout a tape of `ids` over `inputs` has: each input symbol's slots, and each
        // root's components one after the other.
        let layout = Inputs::new(graph, &inputs).expect("the free symbols are distinct");
        let ranges = layout.ranges();
        let width = |id: Id| if graph.ty(id) == Ty::Vector { graph.dim() } else { 1 };
        let mut first = Vec::with_capacity(ids.len());
        ids.iter().fold(0, |at, &id| {
            first.push(at);
            at + width(id)
        });
        let sources = sources(system, &inputs);
        let varying: Vec<Load> = (0..inputs.len())
            .filter(|&i| !matches!(sources[i], Source::Env))
            .map(|i| Load { input: i, source: sources[i], start: ranges[i].start, len: ranges[i].len() })
            .collect();
        let mut place: Vec<Place> = root
            .iter()
            .map(|&r| match r {
                usize::MAX => Place::default(),
                r => Place { start: first[r] as u32, len: width(ids[r]) as u32, stride: 1 },
            })
            .collect();
        let flat = Flat::new(system, ranges, &inputs, &sources);
        let len = |r: usize| place[r].len as usize;
        let batched = Batched::new(graph, roots, units, len, flat.slots(&inputs), flat.trig_slots(&inputs));
        let (kernel, copies) = match batched {
            Some(batched) => {
                // The roots are read where the batches leave them.
                for (r, place) in place.iter_mut().enumerate() {
                    if place.len > 0 {
                        let (start, stride) = batched.place(r);
                        (place.start, place.stride) = (start as u32, stride as u32);
                    }
                }
                (Kernel::Batched(Box::new(batched), flat), None)
            }
            None => {
                // As for the whole program: the inputs are the roots' free symbols.
                let program = Program::lower_in(graph, &ids, &layout).expect("the inputs are the roots' free symbols");
                let tape = Tape::from_program(&program);
                // The roots are read where the tape writes them (the layout above, which a
                // tape of `ids` has, taken from the tape itself rather than assumed).
                for (&r, place) in root.iter().zip(&mut place) {
                    if r != usize::MAX {
                        let range = tape.output_range(r);
                        (place.start, place.len) = (range.start as u32, range.len() as u32);
                    }
                }
                (Kernel::Tape(tape, None), StateCopies::new(&varying, system.dim()))
            }
        };
        Subprogram { kernel, inputs, place, sources, varying, copies, places: None }
    }
}

/// [`Subprogram::run`] with batches but a scratch without their buffers: never with a
/// scratch of the subprogram (which has them), so out of line, with buffers of its own.
#[cold]
#[inline(never)]
fn evaluate_batched_without_scratch(batched: &Batched, inputs: &[f64], outputs: &mut [f64]) {
    batched.eval(inputs, &mut batched.scratch(), outputs);
}

/// Where a batched evaluation reads its inputs (`numeric::batch` gathers them by index
/// from one buffer): every body's position, then every body's velocity, three numbers a
/// body as a simulation keeps them, so a state arrives in two block copies rather than
/// symbol by symbol; then t; then the other input symbols (parameters, masses, rigid
/// bodies' angles) one after the other, a 2D rigid body's angle θ followed by sin θ and
/// cos θ, which the load computes once for the batches' tapes to read (`Batched::new`'s
/// `trig`: a body's angle is turned by in each row of each of its joints).
#[derive(Clone, Debug)]
struct Flat {
    bodies: usize,
    /// Per input symbol of the tape, its slots in the buffer.
    places: Vec<Range<usize>>,
    /// The input symbols that are constants of a run (`Source::Env`: indices into `places`).
    env: Vec<usize>,
    /// The rigid bodies' angles and angular velocities among the inputs (`Source::Angle`),
    /// which the environment gives per state.
    angles: Vec<usize>,
    /// The slot of each 2D rigid body's angle among the inputs: its sine and cosine follow.
    trig: Vec<usize>,
    /// Whether some input is a position, a velocity (else that block is not copied).
    positions: bool,
    velocities: bool,
    len: usize,
}

impl Flat {
    /// `ranges`: each input symbol's slots in a tape's own layout (their widths count here).
    fn new(system: &System, ranges: &[Range<usize>], inputs: &[Symbol], sources: &[Source]) -> Flat {
        let n = system.bodies.len();
        let mut len = 6 * n + 1;
        let (mut env, mut angles, mut trig) = (Vec::new(), Vec::new(), Vec::new());
        let orientations: FastSet<Symbol> = match system.dim() {
            2 => system.bodies.iter().filter_map(|b| b.rigid.as_ref()).map(|r| r.orientation).collect(),
            _ => Default::default(),
        };
        let places = sources
            .iter()
            .enumerate()
            .map(|(i, source)| {
                let w = ranges[i].len();
                match *source {
                    Source::Position(b) => 3 * b..3 * b + w,
                    Source::Velocity(b) => 3 * (n + b)..3 * (n + b) + w,
                    Source::Time => 6 * n..6 * n + 1,
                    Source::Env | Source::Angle => {
                        match source {
                            Source::Env => env.push(i),
                            _ => angles.push(i),
                        }
                        let at = len;
                        len += w;
                        if w == 1 && orientations.contains(&inputs[i]) {
                            trig.push(at);
                            len += 2;
                        }
                        at..at + w
                    }
                }
            })
            .collect();
        let positions = sources.iter().any(|s| matches!(s, Source::Position(_)));
        let velocities = sources.iter().any(|s| matches!(s, Source::Velocity(_)));
        Flat { bodies: n, places, env, angles, trig, positions, velocities, len }
    }

    /// Symbol → the slots of its sine and cosine in the buffer, for the 2D rigid bodies'
    /// angles (`inputs` are the tape's input symbols).
    fn trig_slots<'f>(&'f self, inputs: &[Symbol]) -> impl Fn(Symbol) -> Option<Range<usize>> + 'f {
        let slots = self.slots(inputs);
        let angles: FastSet<usize> = self.trig.iter().copied().collect();
        move |s| {
            let at = slots(s);
            (at.len() == 1 && angles.contains(&at.start)).then(|| at.start + 1..at.start + 3)
        }
    }

    /// The sine and cosine of each 2D rigid body's angle in `buffer`, from the angle there:
    /// the tapes' own [`Func::apply`], so a tape reading them has the bits it would compute.
    fn fill_trig(&self, buffer: &mut [f64]) {
        for &at in &self.trig {
            let theta = [buffer[at]];
            buffer[at + 1] = Func::Sin.apply(&theta);
            buffer[at + 2] = Func::Cos.apply(&theta);
        }
    }

    /// Symbol → its slots in the buffer (`inputs` are the tape's input symbols).
    fn slots<'f>(&'f self, inputs: &[Symbol]) -> impl Fn(Symbol) -> Range<usize> + 'f {
        let at: FastMap<Symbol, usize> = inputs.iter().enumerate().map(|(i, &s)| (s, i)).collect();
        move |s| at.get(&s).map_or(0..0, |&i| self.places[i].clone())
    }

    /// The buffer from `env` alone (`inputs` the tape's input symbols).
    fn load(&self, system: &System, env: &Env, inputs: &[Symbol], buffer: &mut [f64]) -> Result<(), EvalError> {
        for (&s, at) in inputs.iter().zip(&self.places) {
            from_env(system, env, s, &mut buffer[at.clone()])?;
        }
        self.fill_trig(buffer);
        Ok(())
    }

    /// The buffer from `state` (positions, velocities, t) and `env` (the rest; not the
    /// constants of a run when they are `held` in `buffer` already).
    fn load_state(
        &self,
        system: &System,
        env: &Env,
        state: State<'_>,
        inputs: &[Symbol],
        held: bool,
        buffer: &mut [f64],
    ) -> Result<(), EvalError> {
        let n = self.bodies;
        if self.positions {
            buffer[..3 * n].copy_from_slice(state.q[..n].as_flattened());
        }
        if self.velocities {
            buffer[3 * n..6 * n].copy_from_slice(state.v[..n].as_flattened());
        }
        buffer[6 * n] = state.t;
        let constants = if held { &[][..] } else { &self.env[..] };
        for &i in constants.iter().chain(&self.angles) {
            from_env(system, env, inputs[i], &mut buffer[self.places[i].clone()])?;
        }
        self.fill_trig(buffer);
        Ok(())
    }
}

/// `slots` from symbol `s`'s value in `env`, element by element (a copy of one to four
/// numbers is cheaper inline than a call).
#[inline(always)]
fn from_env(system: &System, env: &Env, s: Symbol, slots: &mut [f64]) -> Result<(), EvalError> {
    match env.get(s) {
        Some(Value::Scalar(x)) => slots.fill(x),
        Some(Value::Vector(v)) => copy_prefix(slots, &v),
        Some(Value::Quaternion(q)) => copy_prefix(slots, &q),
        None => return Err(EvalError::Missing(system.graph.symbol(s).name.clone())),
    }
    Ok(())
}

/// The first numbers of `from` into `slots`, as many as both have: at an input's usual
/// widths (one to three) a copy of fixed length each, where a copy of the length at hand
/// was a call of `memcpy` (about 10 instructions of the load's 35 a link of the chain).
#[inline(always)]
fn copy_prefix(slots: &mut [f64], from: &[f64]) {
    match (slots, from) {
        ([a, b], [x, y, ..]) => (*a, *b) = (*x, *y),
        ([a, b, c], [x, y, z, ..]) => (*a, *b, *c) = (*x, *y, *z),
        ([a], [x, ..]) => *a = *x,
        (slots, from) => slots.iter_mut().zip(from).for_each(|(d, x)| *d = *x),
    }
}

/// Which roots of a [`RowProgram`] a tape computes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Part {
    /// Every root.
    All,
    /// Each row's C and J, and the principal axes.
    Positions,
    /// Each row's Ċ and c, each slot's mass, velocity and force (no 3D rigid body).
    Motion,
}

/// The roots of a [`RowProgram`] in units of one shape each (`numeric::batch`): each body's
/// mass, velocity and force, each rigid body's angular roots, each row's C, Ċ, c and J (or
/// the roots of `part` alone: C and J then each principal axis; Ċ and c then the slots'),
/// every root once.
fn units(bodies: &[BodySlots], rows: &[RowLayout], n_roots: usize, part: Part) -> Vec<Vec<usize>> {
    let positions = part == Part::Positions;
    let mut covered = vec![false; n_roots];
    let mut units = Vec::new();
    let mut take = |unit: Vec<usize>, units: &mut Vec<Vec<usize>>| {
        let unit: Vec<usize> = unit.into_iter().filter(|&r| !std::mem::replace(&mut covered[r], true)).collect();
        if !unit.is_empty() {
            units.push(unit);
        }
    };
    for layout in rows {
        let unit = match part {
            Part::All => [layout.value, layout.rate, layout.bias].into_iter().chain(layout.jacobian.clone()).collect(),
            Part::Positions => std::iter::once(layout.value).chain(layout.jacobian.clone()).collect(),
            Part::Motion => vec![layout.rate, layout.bias],
        };
        take(unit, &mut units);
    }
    for b in bodies {
        let axes = b.principal.map(|(_, axes)| axes.to_vec()).unwrap_or_default();
        if positions {
            for a in axes {
                take(vec![a], &mut units);
            }
        } else {
            take([b.mass, b.velocity, b.force].into_iter().chain(axes).collect(), &mut units);
        }
    }
    units
}

/// Where one slot's numbers are among a [`RowProgram`]'s roots (and the tape's outputs): a
/// body's mass, velocity and force, or an angular slot's inertia, ω and τ.
#[derive(Clone, Copy, Debug)]
struct BodySlots {
    mass: usize,
    velocity: usize,
    force: usize,
    /// 3D: this slot is axis `k` of a rigid body whose principal axes R(q) eⱼ are the
    /// roots `axes` (`mass`, `velocity` and `force` are then the vectors I, ω and τ).
    principal: Option<(usize, [usize; 3])>,
}

/// Whether every slot's mass and force (torque) of `bodies` reads only constants of a run
/// (parameters, masses, inertias, the force and torque symbols the environment gives): no
/// position, velocity, angle or time.
fn constant_slots(graph: &crate::expr::graph::Graph, roots: &[Id], bodies: &[BodySlots]) -> bool {
    use crate::expr::graph::Role;
    let slots: Vec<Id> = bodies.iter().flat_map(|b| [roots[b.mass], roots[b.force]]).collect();
    SymbolWalk::default().free_symbols_of(graph, &slots).iter().all(|&s| {
        matches!(
            graph.symbol(s).role,
            Role::Parameter | Role::Mass { .. } | Role::Inertia { .. } | Role::Force { .. } | Role::Torque { .. }
        )
    })
}

/// One constraint row of a [`RowProgram`]: its kind, its bodies, 1/κ, and where its
/// numbers are among the roots.
#[derive(Clone, Debug)]
struct RowLayout {
    inequality: bool,
    inverse_scale: f64,
    /// The slots of J (bodies, then angular slots for Jʷ), in the order of `jacobian`'s roots.
    bodies: Vec<usize>,
    value: usize,
    rate: usize,
    bias: usize,
    /// J of `bodies[q]` is root `jacobian.start + q`.
    jacobian: Range<usize>,
}

/// Adds `id` to `roots`; returns its slot.
fn push(roots: &mut Vec<Id>, id: Id) -> usize {
    roots.push(id);
    roots.len() - 1
}

/// `tape`'s inputs (the symbols `inputs`) from `env` into `buffer`.
fn load(system: &System, env: &Env, tape: &Tape, inputs: &[Symbol], buffer: &mut [f64]) -> Result<(), EvalError> {
    for (&s, at) in inputs.iter().zip(tape.input_ranges()) {
        from_env(system, env, s, &mut buffer[at.clone()])?;
    }
    Ok(())
}

/// Where a tape's input symbol comes from when the state is given as arrays
/// ([`RowProgram::evaluate_state_into`]): a body's position or velocity (slot i of the
/// state), the time, or the environment: a rigid body's angle (orientation) or angular
/// velocity, which the environment gives per state, or a constant of a run (parameters,
/// masses, given forces), which a scratch may hold between evaluations.
#[derive(Clone, Copy, Debug)]
enum Source {
    Position(usize),
    Velocity(usize),
    Time,
    Angle,
    Env,
}

/// The [`Source`] of each of `inputs`.
fn sources(system: &System, inputs: &[Symbol]) -> Vec<Source> {
    let mut of = FastMap::default();
    for (i, body) in system.bodies.iter().enumerate() {
        of.insert(body.position, Source::Position(i));
        of.insert(body.velocity, Source::Velocity(i));
    }
    for rigid in system.bodies.iter().filter_map(|b| b.rigid.as_ref()) {
        of.insert(rigid.orientation, Source::Angle);
        of.insert(rigid.angular_velocity, Source::Angle);
    }
    of.insert(system.time, Source::Time);
    inputs.iter().map(|s| of.get(s).copied().unwrap_or(Source::Env)).collect()
}

/// A state given as arrays: time, and each body's position and velocity (slot i for body i,
/// as a simulation keeps them; rigid bodies' angles are read from the environment).
#[derive(Clone, Copy, Debug)]
pub struct State<'a> {
    pub t: f64,
    pub q: &'a [[f64; 3]],
    pub v: &'a [[f64; 3]],
}

/// `tape`'s inputs `which` (indices) from `state` where `sources` says so, else from `env`.
#[allow(clippy::too_many_arguments)]
fn load_state(
    system: &System,
    env: &Env,
    state: State<'_>,
    tape: &Tape,
    inputs: &[Symbol],
    sources: &[Source],
    which: impl IntoIterator<Item = usize>,
    buffer: &mut [f64],
) -> Result<(), EvalError> {
    // One to three components, copied by hand (a copy of a variable length is a call).
    let copy = |slots: &mut [f64], x: &[f64; 3]| {
        for (k, d) in slots.iter_mut().enumerate().take(3) {
            *d = x[k];
        }
    };
    for i in which {
        let slots = &mut buffer[tape.input_range(i)];
        match sources[i] {
            Source::Position(b) => copy(slots, &state.q[b]),
            Source::Velocity(b) => copy(slots, &state.v[b]),
            Source::Time => slots.fill(state.t),
            Source::Angle | Source::Env => match env.get(inputs[i]) {
                Some(Value::Scalar(x)) => slots.fill(x),
                Some(Value::Vector(v)) => slots.iter_mut().zip(v).for_each(|(d, x)| *d = x),
                Some(Value::Quaternion(q)) => slots.iter_mut().zip(q).for_each(|(d, x)| *d = x),
                None => return Err(EvalError::Missing(system.graph.symbol(inputs[i]).name.clone())),
            },
        }
    }
    Ok(())
}

/// One input a state evaluation loads: `input` (an index into the tape's inputs), where it
/// comes from, and its slots `start..start + len` in the input buffer.
#[derive(Clone, Copy, Debug)]
struct Load {
    input: usize,
    source: Source,
    start: usize,
    len: usize,
}

/// The inputs `loads` from `state`, or `env` for the rigid bodies' angles (`inputs`: the
/// tape's input symbols), as [`load_state`] loads them.
fn load_varying(
    system: &System,
    env: &Env,
    state: State<'_>,
    inputs: &[Symbol],
    loads: &[Load],
    buffer: &mut [f64],
) -> Result<(), EvalError> {
    // One to three components, copied by hand (a copy of a variable length is a call).
    let copy = |slots: &mut [f64], x: &[f64; 3]| {
        for (d, x) in slots.iter_mut().zip(x) {
            *d = *x;
        }
    };
    for load in loads {
        let slots = &mut buffer[load.start..load.start + load.len];
        match load.source {
            Source::Position(b) => copy(slots, &state.q[b]),
            Source::Velocity(b) => copy(slots, &state.v[b]),
            Source::Time => slots.fill(state.t),
            Source::Angle | Source::Env => from_env(system, env, inputs[load.input], slots)?,
        }
    }
    Ok(())
}

/// A [`Subprogram`]'s inputs that change from state to state, when all of them come from
/// the state's arrays: each body position's and velocity's first input slot (`dim` slots
/// each) and t's slot, so a load copies fixed-width blocks with no test of where each comes
/// from (a copy of a variable length is a call).
#[derive(Clone, Debug)]
struct StateCopies {
    /// `(body, first slot)`.
    positions: Vec<(usize, usize)>,
    velocities: Vec<(usize, usize)>,
    time: Vec<usize>,
    /// The dimension: every position and velocity is that many slots.
    dim: usize,
}

impl StateCopies {
    /// The copies of `loads` in a scene of dimension `dim` (2 or 3), or `None` when one of
    /// them is read from the environment (a rigid body's angle) or is not `dim` slots wide.
    fn new(loads: &[Load], dim: usize) -> Option<StateCopies> {
        if !matches!(dim, 2 | 3) {
            return None;
        }
        let mut copies = StateCopies { positions: Vec::new(), velocities: Vec::new(), time: Vec::new(), dim };
        for load in loads {
            match load.source {
                Source::Position(b) if load.len == dim => copies.positions.push((b, load.start)),
                Source::Velocity(b) if load.len == dim => copies.velocities.push((b, load.start)),
                Source::Time if load.len == 1 => copies.time.push(load.start),
                _ => return None,
            }
        }
        Some(copies)
    }

    /// The inputs from `state` into `buffer` (the tape's input layout).
    #[inline(always)]
    fn load(&self, state: State<'_>, buffer: &mut [f64]) {
        if self.dim == 2 {
            self.load_of::<2>(state, buffer);
        } else {
            self.load_of::<3>(state, buffer);
        }
        for &at in &self.time {
            buffer[at] = state.t;
        }
    }

    /// [`load`](StateCopies::load)'s positions and velocities, `W` = `dim` slots each.
    #[inline(always)]
    fn load_of<const W: usize>(&self, state: State<'_>, buffer: &mut [f64]) {
        for (copies, from) in [(&self.positions, state.q), (&self.velocities, state.v)] {
            for &(b, at) in copies {
                buffer[at..at + W].copy_from_slice(&from[b][..W]);
            }
        }
    }
}

/// Row `row`'s J `entries` from `out` (all of width `width` when it is not 0), in place
/// when the row has that many already. The common case
/// (in place) is compiled into each fill's loop over the rows (a call per row cost more
/// than the copy it makes), the entries read without a bounds check and, when they are all
/// 2 or 3 wide, without a test of their width; the rest is [`fill_entries_any`].
///
/// `entries` are some of the [`Places`] that made `out`, `width` their `width`.
#[inline(always)]
fn fill_entries(row: &mut Row, entries: &[Entry], width: u32, out: Outputs<'_>) {
    if row.jacobian.len() != entries.len() {
        return fill_entries_any(row, entries, out.0);
    }
    match width {
        2 => entries_of_width::<2>(row, entries, out),
        3 => entries_of_width::<3>(row, entries, out),
        _ => entries_of_width::<0>(row, entries, out),
    }
}

/// [`fill_entries`] into a row of another length (the first fill of a scratch's rows).
#[cold]
#[inline(never)]
fn fill_entries_any(row: &mut Row, entries: &[Entry], out: &[f64]) {
    row.jacobian.clear();
    row.jacobian.extend(entries.iter().map(|e| (e.slot as usize, e.place.read(out))));
}

/// [`fill_entries`] in place, every entry `W` wide (`W` = 0: of any width, see
/// [`Place::read_width`]): each read without a bounds check.
#[inline(always)]
fn entries_of_width<const W: usize>(row: &mut Row, entries: &[Entry], out: Outputs<'_>) {
    for (j, e) in row.jacobian.iter_mut().zip(entries) {
        // SAFETY: `e` is one of the entries of the places that made `out`, `W` wide when
        // `W` ≠ 0 (`fill_entries`).
        *j = (e.slot as usize, unsafe { e.place.read_width::<W>(out) });
    }
}

/// [`RowProgram::fill_slots`] when every slot's v and F are `W` wide (`W` = 0: of any
/// width, see [`Place::read_width`]): each read without a bounds check. Whether every 1/m
/// is finite (v and F are outputs as they are: see [`finite_fill`]).
#[inline(always)]
fn slots_of_width<const W: usize>(places: &Places, out: &[f64], rows: &mut Rows) -> bool {
    let checked = places.outputs(out);
    let slots = rows.inverse_mass.iter_mut().zip(&mut rows.velocity).zip(&mut rows.force);
    let at = places.mass.iter().zip(&places.velocity).zip(&places.force);
    let mut finite = true;
    for (((w, u), f), ((&m, &v), &force)) in slots.zip(at) {
        *w = 1.0 / out[m as usize];
        // SAFETY: `places` made `checked`, and every v and F of theirs is `W` wide when
        // `W` ≠ 0 (the caller's `slot_width`).
        (*u, *f) = unsafe { (v.read_width::<W>(checked), force.read_width::<W>(checked)) };
        finite &= w.is_finite();
    }
    finite
}

/// Whether every number a fill along [`Places`] wrote is finite, from `out` (the tape's
/// outputs it read), `computed` (whether the numbers it computed from them — C/κ, Ċ/κ,
/// 1/m — are finite) and `written` (a test of every number written, run only when some
/// output is not finite). Every other number a fill writes is an output as it is, or a
/// zero past a root's width; and every output is some root's component the fill reads. So
/// with finite outputs `computed` decides, and otherwise `written` (a non-finite output
/// may still give a finite number: 1/∞ = 0).
#[inline]
fn finite_fill(out: &[f64], computed: bool, written: impl FnOnce() -> bool) -> bool {
    if all_finite(out) { computed } else { written() }
}

/// Whether every one of `xs` is finite, by their exponent bits ([`not_finite_bits`]: a few
/// integer operations a number, no branch): the single-row fills' test of the numbers they
/// wrote, which is what [`finite_fill`] decides (every number such a fill writes is an
/// output or computed from one, and every output is read), without a pass over the outputs.
#[inline(always)]
fn finite_all(parts: &[&[f64]]) -> bool {
    parts.iter().fold(0u64, |all, xs| all | not_finite_bits(xs)) >> 63 == 0
}

/// Whether every one of `xs` is finite: the OR of their exponent bits
/// (`vector::not_finite_bit`), over an array of fixed length (no loop over slices).
#[inline(always)]
fn all_finite_bits<const N: usize>(xs: [f64; N]) -> bool {
    xs.iter().fold(0u64, |bad, x| bad | not_finite_bit(*x)) >> 63 == 0
}

/// [`RowProgram::evaluate_motion_state_into`]'s fill for one row on one slot whose J, v and
/// F are `W` (2 or 3) wide (a pendulum, a bead), in place in rows of that shape: the loops'
/// set-up and the outputs' sweep cost more than the numbers written (about 180 instructions
/// of a pendulum's step in two fills, callgrind). `None`, with nothing written, for any
/// other shape; else whether every number written is finite.
#[inline(always)]
fn motion_one<const W: usize>(places: &Places, out: Outputs<'_>, rows: &mut Rows) -> Option<bool> {
    let ([at], [m], [velocity], [force]) =
        (places.rows.as_slice(), places.mass.as_slice(), places.velocity.as_slice(), places.force.as_slice())
    else {
        return None;
    };
    let (row, w, u, f) = rows.one_slot_mut()?;
    *w = 1.0 / out.0[*m as usize];
    // SAFETY: `places` made `out`, and its v and F are `W` wide (the caller's `slot_width`).
    (*u, *f) = unsafe { (velocity.read_of::<W>(out), force.read_of::<W>(out)) };
    row.rate = out.0[at.rate as usize] * at.inverse_scale;
    row.bias = out.0[at.bias as usize];
    row.inequality = at.inequality;
    // The components past `W` are zeros.
    Some(finite_all(&[&[*w, row.rate, row.bias], &u[..W], &f[..W]]))
}

/// [`RowProgram::evaluate_positions_state_into`]'s fill for one row with one J entry `W`
/// (2 or 3) wide, in place in rows of that shape, as [`motion_one`]: `None`, with nothing
/// written, for any other shape; else whether C/κ and J are finite.
#[inline(always)]
fn positions_one<const W: usize>(places: &Places, out: Outputs<'_>, rows: &mut [Row]) -> Option<bool> {
    let ([at], [entry], [row]) = (places.rows.as_slice(), places.jacobian.as_slice(), rows) else {
        return None;
    };
    let [(slot, j)] = row.jacobian.as_mut_slice() else {
        return None;
    };
    row.value = out.0[at.value as usize] * at.inverse_scale;
    row.rate = 0.0;
    row.bias = 0.0;
    row.inequality = at.inequality;
    // SAFETY: `places` made `out`, and its J entries are `W` wide (the caller's `width`).
    (*slot, *j) = (entry.slot as usize, unsafe { entry.place.read_of::<W>(out) });
    Some(finite_all(&[&[row.value], &j[..W]]))
}

/// Whether every number of `rows`' slots (1/m, v, F) is finite.
fn slots_finite(rows: &Rows) -> bool {
    rows.inverse_mass.iter().all(|w| w.is_finite()) && rows.velocity.iter().chain(&rows.force).all(finite3)
}

/// Whether every number of `rows` is finite: each row's C/κ, Ċ/κ, c and J, each slot's.
fn all_written_finite(rows: &Rows) -> bool {
    rows.rows
        .iter()
        .all(|row| row.value.is_finite() & row.rate.is_finite() & row.bias.is_finite() & entries_finite(row))
        && slots_finite(rows)
}

/// Whether every row's C/κ and J is finite (what a positions evaluation writes, with zeros).
fn positions_finite(rows: &[Row]) -> bool {
    rows.iter().all(|row| row.value.is_finite() & entries_finite(row))
}

/// Whether every component of a row's J is finite.
fn entries_finite(row: &Row) -> bool {
    row.jacobian.iter().fold(true, |ok, (_, j)| ok & finite3(j))
}

/// Where the positions' and the motion's tapes of a program of one row on one slot (a
/// pendulum, a bead: a point mass, its C reading no t) read the slot's q and v and leave
/// the row's and the slot's numbers: found once ([`RowProgram::one_slot`]), so an
/// evaluation at a step of such a scene writes two or four inputs and reads its outputs at
/// these places, without the general fill's walk down its `Places` and tests of the
/// shape (about a hundred instructions of an evaluation, callgrind). The numbers are the
/// fills' bit for bit: the same tapes, the same inputs, the same outputs read, the same
/// products.
#[derive(Clone, Copy, Debug)]
pub struct OneSlot {
    /// The dimension: q, v, J and F are this many (2 or 3) components wide.
    width: usize,
    /// The first input slot of q and of v in the positions' tape and in the motion's
    /// (`usize::MAX`: the tape does not read it).
    positions_q: usize,
    positions_v: usize,
    motion_q: usize,
    motion_v: usize,
    /// The outputs of C and J (positions' tape), of Ċ, c, m, v and F (motion's).
    value: usize,
    jacobian: Place,
    rate: usize,
    bias: usize,
    mass: usize,
    velocity: Place,
    force: Place,
    /// `RowLayout::inverse_scale` and `inequality` of the row.
    inverse_scale: f64,
    inequality: bool,
}

/// The motion's numbers of a one-slot scene at a state ([`RowProgram::motion_one_slot`]):
/// Ċ/κ, c, 1/m, v and F, as [`RowProgram::evaluate_motion_state_into`] writes them.
#[derive(Clone, Copy, Debug)]
pub struct OneSlotMotion {
    pub rate: f64,
    pub bias: f64,
    pub inverse_mass: f64,
    pub velocity: [f64; 3],
    pub force: [f64; 3],
    /// Whether every one of them is finite (as [`RowScratch::finite`] says of a fill).
    pub finite: bool,
}

impl OneSlot {
    /// Whether the row is an inequality (`RowLayout::inequality`).
    pub fn inequality(&self) -> bool {
        self.inequality
    }

    /// q and v into a tape's inputs at `q_at` and `v_at` (`usize::MAX`: not read); `None`
    /// when the inputs are shorter than the places say (never, for the program's own scratch).
    #[inline(always)]
    fn load(&self, q: &[f64; 3], v: &[f64; 3], [q_at, v_at]: [usize; 2], inputs: &mut [f64]) -> Option<()> {
        for (at, x) in [(q_at, q), (v_at, v)] {
            if at == usize::MAX {
                continue;
            }
            // Two or three components: stores of arrays of a known length (a slice's copy
            // was a call of `memcpy`).
            if self.width == 3 {
                let to: &mut [f64; 3] = inputs.get_mut(at..at + 3)?.try_into().ok()?;
                *to = *x;
            } else {
                let to: &mut [f64; 2] = inputs.get_mut(at..at + 2)?.try_into().ok()?;
                *to = [x[0], x[1]];
            }
        }
        Some(())
    }

    /// A root's components at `place` (zeros past the width), or `None` past `out`.
    #[inline(always)]
    fn read(&self, place: Place, out: &[f64]) -> Option<[f64; 3]> {
        let (s, d) = (place.start as usize, place.stride as usize);
        Some(if self.width == 3 {
            [*out.get(s)?, *out.get(s + d)?, *out.get(s + 2 * d)?]
        } else {
            [*out.get(s)?, *out.get(s + d)?, 0.0]
        })
    }
}

/// Input and output buffers of [`RowProgram::evaluate_into`], reused across evaluations.
#[derive(Clone, Debug)]
pub struct RowScratch {
    /// Every root's, the positions' and the motion's (none without its subprogram).
    all: SubScratch,
    positions: SubScratch,
    motion: Option<SubScratch>,
    /// Whether the state evaluations keep the constants of a run in the input buffers
    /// ([`hold_constants`](RowScratch::hold_constants)).
    hold: bool,
    /// Whether every number the last evaluation wrote is finite ([`finite`](RowScratch::finite)).
    finite: bool,
}

impl RowScratch {
    /// From now on the evaluations at a state given as arrays
    /// ([`RowProgram::evaluate_state_into`] and its `positions` and `motion` kin) load the
    /// constants of a run — every input the environment gives but the rigid bodies' angles
    /// and angular velocities: parameters, masses, given forces — at their first evaluation
    /// with this scratch and keep them, rather than reading them from the environment at
    /// every evaluation. The caller's environment must give the same constants until it calls
    /// this again (which loads them afresh at the next evaluation). An evaluation from an
    /// environment alone ([`RowProgram::evaluate_into`]) loads everything, as without this.
    pub fn hold_constants(&mut self) {
        self.hold = true;
        for s in std::iter::once(&mut self.all).chain(Some(&mut self.positions)).chain(self.motion.as_mut()) {
            s.constants = false;
        }
    }

    /// Whether every number the last evaluation with this scratch wrote into its rows is
    /// finite: all of them, or for an
    /// [`evaluate_motion_state_into`](RowProgram::evaluate_motion_state_into) that kept C
    /// and J, the numbers it wrote (Ċ, c, each slot's 1/m, v and F). Found as the rows are
    /// filled, so a caller that must not pass a NaN on needs no second pass over them.
    pub fn finite(&self) -> bool {
        self.finite
    }
}

/// The buffers of one [`Subprogram`].
#[derive(Clone, Debug)]
struct SubScratch {
    inputs: Vec<f64>,
    outputs: Vec<f64>,
    tape: Scratch,
    /// The batches' buffers (none without batches).
    batched: Option<BatchedScratch>,
    /// Whether `inputs` holds the constants of a run, loaded by a state evaluation that
    /// keeps them ([`RowScratch::hold_constants`]).
    constants: bool,
}

impl Subprogram {
    fn scratch(&self) -> SubScratch {
        SubScratch {
            inputs: vec![0.0; self.input_len()],
            outputs: vec![0.0; self.output_len()],
            tape: match &self.kernel {
                Kernel::Tape(tape, _) => tape.scratch(),
                Kernel::Batched(..) => Scratch::default(),
            },
            batched: match &self.kernel {
                Kernel::Batched(batched, _) => Some(batched.scratch()),
                Kernel::Tape(..) => None,
            },
            constants: false,
        }
    }

    /// [`run_loaded`](Subprogram::run_loaded) with the compiled tape's call in line (the
    /// one-slot evaluations': [`run`](Subprogram::run)'s own call and dispatch were a tenth
    /// of such an evaluation).
    #[inline(always)]
    fn run_one(&self, scratch: &mut SubScratch) {
        match &self.kernel {
            Kernel::Tape(_, Some(compiled)) => run_compiled(compiled, &scratch.inputs, &mut scratch.outputs),
            _ => self.run_loaded(scratch),
        }
    }

    /// Every root from the inputs loaded in `scratch` into its outputs (laid out as `place`
    /// says).
    #[inline]
    fn run_loaded(&self, scratch: &mut SubScratch) {
        self.run(&scratch.inputs, &mut scratch.tape, scratch.batched.as_mut(), &mut scratch.outputs);
    }
}

impl RowProgram {
    /// Gathers the rows of `derivation`. The external force on body i is `forces`' expression
    /// for i when it has one (so a simulation re-evaluates `F = m*g - k*v` at every state),
    /// else the body's force symbol, whose value the state gives. A rigid body's torque is
    /// its torque symbol (`torques` gives expressions the same way).
    pub fn new(system: &System, derivation: &Derivation, forces: &[(usize, Id)]) -> RowProgram {
        RowProgram::with_torques(system, derivation, forces, &[])
    }

    /// [`new`](RowProgram::new) with expressions for some rigid bodies' external torques
    /// (`(body, torque expression)`); the others are their torque symbols.
    pub fn with_torques(
        system: &System,
        derivation: &Derivation,
        forces: &[(usize, Id)],
        torques: &[(usize, Id)],
    ) -> RowProgram {
        let graph = &derivation.graph;
        let mut roots = Vec::new();
        let mut bodies = Vec::with_capacity(system.bodies.len());
        let given_force = system.by_body(forces);
        let given_torque = system.by_body(torques);
        for (body, given) in system.bodies.iter().zip(&given_force) {
            let f = given.unwrap_or(body.nodes.force);
            bodies.push(BodySlots {
                mass: push(&mut roots, body.mass),
                velocity: push(&mut roots, body.nodes.velocity),
                force: push(&mut roots, f),
                principal: None,
            });
        }
        // One angular slot per rigid body, after every body: inertia, ω, τ.
        let mut slot_of = vec![None; system.bodies.len()];
        for i in angular_bodies(system) {
            slot_of[i] = Some(bodies.len());
            let Some(rigid) = &system.bodies[i].rigid else { continue };
            let tau = given_torque[i].unwrap_or(rigid.nodes.torque);
            let (mass, velocity, force) = (
                push(&mut roots, rigid.inertia),
                push(&mut roots, rigid.nodes.angular_velocity),
                push(&mut roots, tau),
            );
            match rigid.nodes.axes {
                // 3D: one slot per principal axis, each reading I, ω, τ and the axes.
                Some(axes) => {
                    let axes = axes.map(|e| push(&mut roots, e));
                    for k in 0..3 {
                        bodies.push(BodySlots { mass, velocity, force, principal: Some((k, axes)) });
                    }
                }
                None => bodies.push(BodySlots { mass, velocity, force, principal: None }),
            }
        }
        let mut rows = Vec::with_capacity(derivation.constraints.len());
        for (k, d) in derivation.constraints.iter().enumerate() {
            // C and Ċ, multiplied by 1/κ when evaluated; or C/κ and Ċ/κ themselves where
            // κ is out of f64's range (`DerivedConstraint::over_scale`).
            let ((c, c_dot), inverse_scale) = match d.over_scale {
                Some(scaled) => (scaled, 1.0),
                None => ((d.c, d.c_dot), d.scale.recip().unwrap_or(Rational::ONE).to_f64()),
            };
            let (value, rate, bias) = (push(&mut roots, c), push(&mut roots, c_dot), push(&mut roots, d.bias));
            let start = roots.len();
            roots.extend(d.jacobian.iter().map(|&(_, j)| j));
            let mut slots: Vec<usize> = d.jacobian.iter().map(|&(b, _)| b).collect();
            // Jʷ of each rigid body the row turns, in its angular slot (3D: the vector Jʷ
            // once per principal slot, projected on that axis when evaluated).
            for &(b, jw) in &d.angular {
                if let Some(slot) = slot_of[b] {
                    for k in 0..angular_width(system) {
                        roots.push(jw);
                        slots.push(slot + k);
                    }
                }
            }
            rows.push(RowLayout {
                inequality: system.constraints[k].inequality,
                inverse_scale,
                bodies: slots,
                value,
                rate,
                bias,
                jacobian: start..roots.len(),
            });
        }
        let mut all =
            Subprogram::new(system, graph, &roots, 0..roots.len(), &units(&bodies, &rows, roots.len(), Part::All));
        let axes = bodies.iter().filter_map(|b| b.principal).flat_map(|(_, axes)| axes);
        let c_and_j = rows.iter().flat_map(|r| std::iter::once(r.value).chain(r.jacobian.clone()));
        let units_of = |part| units(&bodies, &rows, roots.len(), part);
        let mut positions = Subprogram::new(system, graph, &roots, c_and_j.chain(axes), &units_of(Part::Positions));
        let motion = bodies.iter().all(|b| b.principal.is_none()).then(|| {
            let rates = rows.iter().flat_map(|r| [r.rate, r.bias]);
            let slots = bodies.iter().flat_map(|b| [b.mass, b.velocity, b.force]);
            Subprogram::new(system, graph, &roots, rates.chain(slots), &units_of(Part::Motion))
        });
        let mut motion = motion;
        if bodies.iter().all(|b| b.principal.is_none()) {
            for sub in [&mut all, &mut positions].into_iter().chain(motion.as_mut()) {
                sub.places = Some(Places::new(sub, &bodies, &rows));
            }
        }
        let time_dependent = super::simulate::time_dependent(system);
        let steady = motion.is_some()
            && !time_dependent
            && rows.iter().all(|r| !r.inequality)
            && constant_slots(graph, &roots, &bodies);
        RowProgram { roots, bodies, rows, all, positions, motion, time_dependent, steady }
    }

    /// Whether some constraint's C reads t (`simulate::time_dependent` of the system the
    /// program was built for).
    pub fn time_dependent(&self) -> bool {
        self.time_dependent
    }

    /// Whether what the motion tape gives after a positions evaluation follows from C and J
    /// alone: every slot's 1/m and F (torque) reads no position, velocity or time (gravity
    /// `F = m*g`), so they are constants of a run; no C reads t, so Ċ = Σᵢ Jᵢ·vᵢ; no row is
    /// an inequality and there is a motion tape (no 3D rigid body). RATTLE's SHAKE then
    /// completes its end rows without a tape (`Dynamics::rows_after_positions_steady_into`).
    pub fn steady(&self) -> bool {
        self.steady
    }

    /// The subprograms' kernels: every root's, the positions', and the motion's when there is one.
    fn subprograms(&self) -> impl Iterator<Item = &Subprogram> {
        [&self.all, &self.positions].into_iter().chain(self.motion.as_ref())
    }

    /// The single tapes not compiled yet (of every root, of C and J, of the motion): what
    /// `compile` (the `jit` feature) would compile. Shapes batched by `numeric::batch` are
    /// not among them (they stay interpreted, in lanes).
    fn interpreted_tapes(&self) -> impl Iterator<Item = &Tape> {
        self.subprograms().filter_map(|sub| match &sub.kernel {
            Kernel::Tape(tape, None) => Some(tape),
            _ => None,
        })
    }

    /// How many tapes `compile` (the `jit` feature) would compile, and how many instructions
    /// they hold in all ([`Tape::instructions`]): what compiling costs
    /// (`numeric::simulate::Compile::pays`). `(0, 0)` once compiled, or when every kernel is
    /// batched; a tape `compile` could not compile is still counted.
    pub fn uncompiled(&self) -> (usize, usize) {
        self.interpreted_tapes().fold((0, 0), |(n, i), tape| (n + 1, i + tape.instructions()))
    }

    /// How many of the program's kernels run as machine code (`compile` made them); 0
    /// without the `jit` feature.
    pub fn compiled_kernels(&self) -> usize {
        self.subprograms().filter(|sub| matches!(sub.kernel, Kernel::Tape(_, Some(_)))).count()
    }

    /// Compiles the program's single tapes to machine code ([`Tape::jit`]): the evaluations
    /// then run them, with the same results bit for bit (but for the sign of a NaN, which
    /// stops a run anyway: `Tape::jit`'s contract). Never done unless asked: compiling
    /// costs time at load (`numeric::simulate::Compile` weighs it against a run's length).
    ///
    /// A tape that cannot be compiled keeps the interpreter, and the others are compiled
    /// still; the first failure is returned ([`JitError::Host`]: this processor has no code
    /// generator, and nothing was compiled; [`JitError::TooLarge`]: a tape too big for
    /// compiled code's stack frame). Either way the program evaluates as before. Batched
    /// shapes (`numeric::batch`) stay interpreted; a tape compiled already is kept.
    ///
    /// [`JitError::Host`]: crate::numeric::jit::JitError::Host
    /// [`JitError::TooLarge`]: crate::numeric::jit::JitError::TooLarge
    #[cfg(feature = "jit")]
    pub fn compile(&mut self) -> Result<(), crate::numeric::jit::JitError> {
        use crate::numeric::jit::JitError;
        let mut first = None;
        for sub in [&mut self.all, &mut self.positions].into_iter().chain(self.motion.as_mut()) {
            if let Kernel::Tape(tape, compiled @ None) = &mut sub.kernel {
                match tape.jit() {
                    Ok(jit) => *compiled = Some(std::sync::Arc::new(jit)),
                    // No tape compiles on this host: do not try the others.
                    Err(e @ JitError::Host(_)) => return Err(e),
                    Err(e) => first = first.or(Some(e)),
                }
            }
        }
        first.map_or(Ok(()), Err)
    }

    /// [`new`](RowProgram::new) for a state that gives some forces itself (`solve --at`,
    /// `--set F=…`): a body whose force symbol is named in `given` keeps that symbol, so the
    /// state's value replaces the scene's expression.
    pub fn with_given_forces(
        system: &System,
        derivation: &Derivation,
        forces: &[(usize, Id)],
        given: &[&str],
    ) -> RowProgram {
        let named = |b: usize| given.contains(&derivation.graph.symbol(system.bodies[b].force).name.as_str());
        let forces: Vec<(usize, Id)> = forces.iter().copied().filter(|&(b, _)| !named(b)).collect();
        RowProgram::new(system, derivation, &forces)
    }

    /// Buffers for [`evaluate_into`](RowProgram::evaluate_into).
    pub fn scratch(&self) -> RowScratch {
        RowScratch {
            all: self.all.scratch(),
            positions: self.positions.scratch(),
            motion: self.motion.as_ref().map(Subprogram::scratch),
            hold: false,
            finite: false,
        }
    }

    /// The rows at `env` (which must give every position, velocity, mass, force, parameter and `t`).
    pub fn evaluate(&self, system: &System, env: &Env) -> Result<Rows, EvalError> {
        let mut rows = Rows::default();
        self.evaluate_into(system, env, &mut self.scratch(), &mut rows)?;
        Ok(rows)
    }

    /// [`evaluate`](RowProgram::evaluate) into `rows`, reusing its buffers and `scratch`: no
    /// allocation once `rows` has the system's shape (the simulation's hot path).
    pub fn evaluate_into(
        &self,
        system: &System,
        env: &Env,
        scratch: &mut RowScratch,
        rows: &mut Rows,
    ) -> Result<(), EvalError> {
        scratch.all.constants = false;
        self.all.load(system, env, &mut scratch.all.inputs)?;
        self.run_loaded(system, scratch, rows);
        Ok(())
    }

    /// [`evaluate_into`](RowProgram::evaluate_into) at a state given as arrays (time,
    /// bodies' positions and velocities; everything else from `env`): what a simulation
    /// evaluates, without writing its state into an environment first.
    pub fn evaluate_state_into(
        &self,
        system: &System,
        env: &Env,
        state: State<'_>,
        scratch: &mut RowScratch,
        rows: &mut Rows,
    ) -> Result<(), EvalError> {
        self.all.load_state(system, env, state, scratch.hold, &mut scratch.all)?;
        self.run_loaded(system, scratch, rows);
        Ok(())
    }

    /// [`evaluate_state_into`](RowProgram::evaluate_state_into) for rows whose C/κ and J
    /// are already those at `state`'s time and positions (the rows of an evaluation at the
    /// same t and q, or [`evaluate_positions_state_into`](RowProgram::evaluate_positions_state_into)'s
    /// rows with `rows.rows` swapped in): only what depends on the velocities is evaluated —
    /// each row's Ċ and c, each slot's 1/m, v and F — and `value` and `jacobian` are kept.
    /// The result is the full evaluation's, to rounding (C and J of the positions' tape, Ċ
    /// and c of a tape of their own: see
    /// [`evaluate_positions_into`](RowProgram::evaluate_positions_into)). Evaluates every
    /// root when the program has no such tape (3D rigid bodies) or `rows` does not have
    /// the system's rows; returns whether C and J were kept.
    ///
    /// Out of line, with the load and the fill in it: one call per evaluation besides the
    /// tape's (a simulation step of a small scene makes several).
    #[inline(never)]
    pub fn evaluate_motion_state_into(
        &self,
        system: &System,
        env: &Env,
        state: State<'_>,
        scratch: &mut RowScratch,
        rows: &mut Rows,
    ) -> Result<bool, EvalError> {
        let (Some(m), Some(buffers)) = (&self.motion, &mut scratch.motion) else {
            return self.evaluate_state_into(system, env, state, scratch, rows).map(|()| false);
        };
        if rows.rows.len() != self.rows.len() {
            return self.evaluate_state_into(system, env, state, scratch, rows).map(|()| false);
        }
        // A motion tape exists only without 3D rigid bodies, so its places are known.
        let Some(places) = &m.places else {
            return self.evaluate_state_into(system, env, state, scratch, rows).map(|()| false);
        };
        m.load_state(system, env, state, scratch.hold, buffers)?;
        m.run_loaded(buffers);
        let out = &buffers.outputs;
        // As `fill` without 3D rigid bodies (so no principal axes); in place when `rows`
        // has the slots already (the rows of the last evaluation).
        rows.dim = system.dim();
        rows.axes.clear();
        let one = match places.slot_width {
            2 => motion_one::<2>(places, places.outputs(out), rows),
            3 => motion_one::<3>(places, places.outputs(out), rows),
            _ => None,
        };
        if let Some(finite) = one {
            scratch.finite = finite;
            return Ok(true);
        }
        let mut computed = self.fill_slots(places, out, rows);
        for (row, at) in rows.rows.iter_mut().zip(&places.rows) {
            row.rate = out[at.rate as usize] * at.inverse_scale;
            row.bias = out[at.bias as usize];
            row.inequality = at.inequality;
            computed &= row.rate.is_finite();
        }
        scratch.finite = finite_fill(out, computed, || {
            slots_finite(rows) && rows.rows.iter().all(|row| row.rate.is_finite() & row.bias.is_finite())
        });
        Ok(true)
    }

    /// Each slot's 1/m, v and F from a tape's outputs along its [`Places`], in place when
    /// `rows` has the slots already; whether every 1/m is finite (see [`finite_fill`]).
    #[inline(always)]
    fn fill_slots(&self, places: &Places, out: &[f64], rows: &mut Rows) -> bool {
        let n = self.bodies.len();
        if rows.inverse_mass.len() != n || rows.velocity.len() != n || rows.force.len() != n {
            rows.inverse_mass.resize(n, 0.0);
            rows.velocity.resize(n, [0.0; 3]);
            rows.force.resize(n, [0.0; 3]);
        }
        match places.slot_width {
            2 => slots_of_width::<2>(places, out, rows),
            3 => slots_of_width::<3>(places, out, rows),
            _ => slots_of_width::<0>(places, out, rows),
        }
    }

    /// Every row's C, Ċ, c and J and every slot's numbers from the full tape's outputs along
    /// its [`Places`] (no 3D rigid body): `fill`'s numbers in one pass, in place where
    /// `rows` has the shape already; whether every number is finite.
    fn fill_plain(&self, system: &System, places: &Places, out: &[f64], rows: &mut Rows) -> bool {
        rows.dim = system.dim();
        rows.axes.clear();
        let mut computed = self.fill_slots(places, out, rows);
        rows.rows.resize_with(self.rows.len(), Row::default);
        let checked = places.outputs(out);
        let mut entries = places.jacobian.as_slice();
        for (row, at) in rows.rows.iter_mut().zip(&places.rows) {
            row.value = out[at.value as usize] * at.inverse_scale;
            row.rate = out[at.rate as usize] * at.inverse_scale;
            row.bias = out[at.bias as usize];
            row.inequality = at.inequality;
            computed &= row.value.is_finite() & row.rate.is_finite();
            let (here, rest) = entries.split_at(at.entries as usize);
            entries = rest;
            fill_entries(row, here, places.width, checked);
        }
        finite_fill(out, computed, || all_written_finite(rows))
    }

    /// The rows from the inputs loaded in `scratch`.
    fn run_loaded(&self, system: &System, scratch: &mut RowScratch, rows: &mut Rows) {
        self.all.run_loaded(&mut scratch.all);
        let out = &scratch.all.outputs;
        if let Some(places) = &self.all.places {
            scratch.finite = self.fill_plain(system, places, out, rows);
            return;
        }
        let place = &self.all.place;
        let scalar = |root: usize| out[place[root].start as usize];
        let vector = |root: usize| place[root].read(out);
        self.fill(system, rows, scalar, vector);
        scratch.finite = all_written_finite(rows);
    }

    /// `rows` from the roots' values (`scalar`, `vector` by root): the one assembly of the
    /// compiled and the interpreted paths.
    fn fill(
        &self,
        system: &System,
        rows: &mut Rows,
        scalar: impl Fn(usize) -> f64,
        vector: impl Fn(usize) -> [f64; 3],
    ) {
        rows.dim = system.dim();
        rows.inverse_mass.clear();
        rows.velocity.clear();
        rows.force.clear();
        rows.axes.clear();
        let three = angular_width(system) == 3 && system.has_rigid_bodies();
        for b in &self.bodies {
            let Some((k, axes)) = b.principal else {
                rows.inverse_mass.push(1.0 / scalar(b.mass));
                rows.velocity.push(vector(b.velocity));
                rows.force.push(vector(b.force));
                if three {
                    rows.axes.push([0.0; 3]);
                }
                continue;
            };
            // Axis k of a 3D rigid body, in its principal frame eⱼ = R(q) eⱼ:
            // 1/Iₖ, ωₖ = eₖ·ω, and τₖ − (ω_b × I ω_b)ₖ, the gyroscopic term of Euler's
            // equations in the body frame (ω_b = (eⱼ·ω)ⱼ).
            let (moments, w, tau) = (vector(b.mass), vector(b.velocity), vector(b.force));
            let e = axes.map(&vector);
            let wb = e.map(|ej| dot(&ej, &w));
            let iw = [moments[0] * wb[0], moments[1] * wb[1], moments[2] * wb[2]];
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let gyroscopic = wb[i] * iw[j] - wb[j] * iw[i];
            rows.inverse_mass.push(1.0 / moments[k]);
            rows.velocity.push([wb[k], 0.0, 0.0]);
            rows.force.push([dot(&e[k], &tau) - gyroscopic, 0.0, 0.0]);
            rows.axes.push(e[k]);
        }
        rows.rows.resize_with(self.rows.len(), Row::default);
        for (layout, row) in self.rows.iter().zip(&mut rows.rows) {
            row.value = scalar(layout.value) * layout.inverse_scale;
            row.rate = scalar(layout.rate) * layout.inverse_scale;
            row.bias = scalar(layout.bias);
            row.inequality = layout.inequality;
            self.fill_jacobian(layout, row, &vector);
        }
    }

    /// Row `layout`'s J from the roots' values.
    fn fill_jacobian(&self, layout: &RowLayout, row: &mut Row, vector: &impl Fn(usize) -> [f64; 3]) {
        row.jacobian.clear();
        for (&slot, at) in layout.bodies.iter().zip(layout.jacobian.clone()) {
            let j = vector(at);
            // A 3D angular slot holds Jʷ·eₖ, its axis' part of the vector Jʷ.
            let j = match self.bodies[slot].principal {
                Some((k, axes)) => [dot(&vector(axes[k]), &j), 0.0, 0.0],
                None => j,
            };
            row.jacobian.push((slot, j));
        }
    }

    /// C/κ and J of every row at `env` (positions, parameters and `t`), into `rows`: `value`,
    /// `jacobian` and `inequality` as [`evaluate_into`](RowProgram::evaluate_into) gives
    /// them, to rounding (the same nodes, lowered without the others, may share a
    /// subexpression differently: an ulp apart); `rate` and `bias` are 0. A tape of C and J
    /// only, for iterations onto C = 0 that read nothing else.
    pub fn evaluate_positions_into(
        &self,
        system: &System,
        env: &Env,
        scratch: &mut RowScratch,
        rows: &mut Vec<Row>,
    ) -> Result<(), EvalError> {
        let p = &self.positions;
        scratch.positions.constants = false;
        p.load(system, env, &mut scratch.positions.inputs)?;
        self.positions_loaded(scratch, rows);
        Ok(())
    }

    /// [`evaluate_positions_into`](RowProgram::evaluate_positions_into) at a state given as
    /// arrays (see [`evaluate_state_into`](RowProgram::evaluate_state_into)).
    ///
    /// Out of line, with the load and the fill in it, as
    /// [`evaluate_motion_state_into`](RowProgram::evaluate_motion_state_into).
    #[inline(never)]
    pub fn evaluate_positions_state_into(
        &self,
        system: &System,
        env: &Env,
        state: State<'_>,
        scratch: &mut RowScratch,
        rows: &mut Vec<Row>,
    ) -> Result<(), EvalError> {
        let p = &self.positions;
        p.load_state(system, env, state, scratch.hold, &mut scratch.positions)?;
        self.positions_loaded(scratch, rows);
        Ok(())
    }

    /// C/κ and J from the positions' inputs loaded in `scratch`.
    #[inline(always)]
    fn positions_loaded(&self, scratch: &mut RowScratch, rows: &mut Vec<Row>) {
        let p = &self.positions;
        p.run_loaded(&mut scratch.positions);
        let out = &scratch.positions.outputs;
        if let Some(places) = &p.places {
            let one = match places.width {
                2 => positions_one::<2>(places, places.outputs(out), rows),
                3 => positions_one::<3>(places, places.outputs(out), rows),
                _ => None,
            };
            if let Some(finite) = one {
                scratch.finite = finite;
                return;
            }
        }
        rows.resize_with(self.rows.len(), Row::default);
        if let Some(places) = &p.places {
            // Without 3D rigid bodies J is its roots as they are (no projection on an axis).
            let checked = places.outputs(out);
            let mut computed = true;
            let mut entries = places.jacobian.as_slice();
            for (row, at) in rows.iter_mut().zip(&places.rows) {
                row.value = out[at.value as usize] * at.inverse_scale;
                row.rate = 0.0;
                row.bias = 0.0;
                row.inequality = at.inequality;
                computed &= row.value.is_finite();
                let (here, rest) = entries.split_at(at.entries as usize);
                entries = rest;
                fill_entries(row, here, places.width, checked);
            }
            scratch.finite = finite_fill(out, computed, || positions_finite(rows));
            return;
        }
        let vector = |root: usize| p.place[root].read(out);
        let plain = self.motion.is_some();
        for (layout, row) in self.rows.iter().zip(rows.iter_mut()) {
            row.value = out[p.place[layout.value].start as usize] * layout.inverse_scale;
            row.rate = 0.0;
            row.bias = 0.0;
            row.inequality = layout.inequality;
            if plain && row.jacobian.len() == layout.bodies.len() {
                // In place: the rows of the last evaluation have the same bodies.
                for ((j, &slot), at) in row.jacobian.iter_mut().zip(&layout.bodies).zip(layout.jacobian.clone()) {
                    *j = (slot, vector(at));
                }
            } else {
                self.fill_jacobian(layout, row, &vector);
            }
        }
        scratch.finite = positions_finite(rows);
    }

    /// The places of a program of one row with one J entry on one slot, a point mass whose
    /// tapes of the positions and the motion read only its q and v from the state (no t,
    /// no angle: `StateCopies`), every root 2 or 3 wide as the dimension: what
    /// [`positions_one_slot`](RowProgram::positions_one_slot) and
    /// [`motion_one_slot`](RowProgram::motion_one_slot) read. `None` for any other program.
    pub fn one_slot(&self) -> Option<OneSlot> {
        let ([row], [_], Some(motion)) = (self.rows.as_slice(), self.bodies.as_slice(), &self.motion) else {
            return None;
        };
        let (Some(p), Some(m)) = (&self.positions.places, &motion.places) else {
            return None;
        };
        let ([p_row], [m_row], [entry], [mass], [velocity], [force]) = (
            p.rows.as_slice(),
            m.rows.as_slice(),
            p.jacobian.as_slice(),
            m.mass.as_slice(),
            m.velocity.as_slice(),
            m.force.as_slice(),
        ) else {
            return None;
        };
        let width = p.width as usize;
        let wide = |place: &Place| place.len as usize == width && place.stride == 1;
        if !(matches!(width, 2 | 3) && wide(&entry.place) && wide(velocity) && wide(force) && entry.slot == 0) {
            return None;
        }
        if [p_row.value, m_row.rate, m_row.bias, *mass].contains(&ABSENT) {
            return None;
        }
        // Each tape's inputs from the slot's q and v alone, `width` wide.
        let slots = |sub: &Subprogram| -> Option<[usize; 2]> {
            let copies = sub.copies.as_ref()?;
            if copies.dim != width || !copies.time.is_empty() {
                return None;
            }
            let at = |list: &[(usize, usize)]| match list {
                [] => Some(usize::MAX),
                [(0, at)] => Some(*at),
                _ => None,
            };
            Some([at(&copies.positions)?, at(&copies.velocities)?])
        };
        let ([positions_q, positions_v], [motion_q, motion_v]) = (slots(&self.positions)?, slots(motion)?);
        Some(OneSlot {
            width,
            positions_q,
            positions_v,
            motion_q,
            motion_v,
            value: p_row.value as usize,
            jacobian: entry.place,
            rate: m_row.rate as usize,
            bias: m_row.bias as usize,
            mass: *mass as usize,
            velocity: *velocity,
            force: *force,
            inverse_scale: row.inverse_scale,
            inequality: row.inequality,
        })
    }

    /// C/κ and J of the one row at the slot's `q` (and `v`, should the tape read it), by the
    /// positions' tape at `one`'s places ([`one_slot`](RowProgram::one_slot) of this
    /// program): the numbers [`evaluate_positions_state_into`](RowProgram::evaluate_positions_state_into)
    /// writes into the row (its Ċ and c 0, its flag the row's), bit for bit, and whether they
    /// are finite (also left in `scratch`, as the fill leaves it). `None`, with nothing
    /// evaluated, until an evaluation with `scratch` has loaded the run's constants (the
    /// caller then takes the general evaluation, which loads them).
    #[inline(always)]
    pub fn positions_one_slot(
        &self,
        one: &OneSlot,
        q: &[f64; 3],
        v: &[f64; 3],
        scratch: &mut RowScratch,
    ) -> Option<(f64, [f64; 3], bool)> {
        let buffers = &mut scratch.positions;
        if !(scratch.hold && buffers.constants) {
            return None;
        }
        one.load(q, v, [one.positions_q, one.positions_v], &mut buffers.inputs)?;
        self.positions.run_one(buffers);
        let out = &buffers.outputs;
        let value = *out.get(one.value)? * one.inverse_scale;
        let j = one.read(one.jacobian, out)?;
        // As `positions_one`: C/κ and the components of J written (those past the width
        // are zeros, finite: tested with them, one OR of fixed length).
        let finite = all_finite_bits([value, j[0], j[1], j[2]]);
        scratch.finite = finite;
        Some((value, j, finite))
    }

    /// Ċ/κ, c, 1/m, v and F of the one slot at its `q` and `v`, by the motion's tape at
    /// `one`'s places: the numbers [`evaluate_motion_state_into`](RowProgram::evaluate_motion_state_into)
    /// writes, bit for bit, with whether they are finite (also left in `scratch`). `None`, as
    /// [`positions_one_slot`](RowProgram::positions_one_slot), until the constants are loaded.
    #[inline(always)]
    pub fn motion_one_slot(
        &self,
        one: &OneSlot,
        q: &[f64; 3],
        v: &[f64; 3],
        scratch: &mut RowScratch,
    ) -> Option<OneSlotMotion> {
        let (Some(m), Some(buffers)) = (&self.motion, &mut scratch.motion) else {
            return None;
        };
        if !(scratch.hold && buffers.constants) {
            return None;
        }
        one.load(q, v, [one.motion_q, one.motion_v], &mut buffers.inputs)?;
        m.run_one(buffers);
        let out = &buffers.outputs;
        let inverse_mass = 1.0 / *out.get(one.mass)?;
        let (velocity, force) = (one.read(one.velocity, out)?, one.read(one.force, out)?);
        let rate = *out.get(one.rate)? * one.inverse_scale;
        let bias = *out.get(one.bias)?;
        // As `motion_one`: every number written (the components past the width are zeros,
        // finite: tested with them).
        let [u, f] = [velocity, force];
        let finite = all_finite_bits([inverse_mass, rate, bias, u[0], u[1], u[2], f[0], f[1], f[2]]);
        scratch.finite = finite;
        Some(OneSlotMotion { rate, bias, inverse_mass, velocity, force, finite })
    }

    /// The interpreter's rows at `env` (`expr::eval`, the reference semantics), for tests of
    /// the compiled path; `derivation` is the one the program was gathered from.
    pub fn evaluate_interpreted(&self, system: &System, derivation: &Derivation, env: &Env) -> Result<Rows, EvalError> {
        let values = eval(&derivation.graph, &self.roots, env)?;
        // A scalar root read as a slot's vector (a 2D rigid body's ω, τ, Jʷ) is component 0,
        // as the compiled path reads its one output.
        let vector = |at: usize| match values[at] {
            Value::Scalar(x) => [x, 0.0, 0.0],
            other => other.vector().unwrap_or([f64::NAN; 3]),
        };
        let scalar = |at: usize| values[at].scalar().unwrap_or(f64::NAN);
        let mut rows = Rows::default();
        self.fill(system, &mut rows, scalar, vector);
        Ok(rows)
    }
}
