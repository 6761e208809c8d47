//! λ of a chain of equality rows from one program of the derivation's formulas: each row's
//! c and J and each body's mass and force, evaluated by one [`Tape`] (or its compiled twin)
//! or shape by shape (`numeric::batch`, where rows repeat a shape); A's band formed from J
//! (Aₖₖ = Σᵢ Jₖᵢ·Jₖᵢ/mᵢ, Aₖ₋₁,ₖ = Σ over the bodies both rows move of Jₖ₋₁,ᵢ·Jₖᵢ/mᵢ) or,
//! compiled, taken from A's own formulas (`Derivation::a`); then L D Lᵀ written for the
//! tridiagonal band under a pivot guard, to λ, the constraint forces and the accelerations.
//! What the generated module's `band_system` and `solve_tridiagonal` do (`codegen::rust`),
//! in the library.
//!
//! Design note. The rows' path (`RowProgram::evaluate_into`, then `solve::solve_into`)
//! evaluates every row's C, Ċ, c and J, fills `Rows`, then scales each row by ‖J‖ and the
//! Jacobi factor, assembles Ã term by term and factors it, with the refinement's residual:
//! general, and about 860 instructions a row of a chain. Here the band's shape is known when
//! the program is made, so A's band comes out as numbers with no `Rows`, no scaling and no
//! assembly; b is c + Σᵢ Jᵢ·Fᵢ/mᵢ from the same outputs (the derivation's b reads the force
//! symbols, where a scene gives forces by expressions, which the program evaluates), and the
//! accelerations Fᵢ/mᵢ + (Σₖ λₖ Jₖᵢ)/mᵢ from the same J. A's entries are formed from J, a
//! few flops a row in Rust, rather than evaluated from their formulas, which an interpreter
//! pays for op by op (about 70 instructions a row of a 10-link chain's tape, against some 35
//! here); compiled code evaluates the formulas for less than that, so
//! [`BandLambda::compile`] adds them to its tape. The factor is of A itself, not of the
//! Jacobi-scaled Ã: no square root, no ‖J‖, and as accurate (the analysis is at the
//! factor). Only what this path can answer as the general solve would is served; everything
//! else is declined, and the caller takes the rows' solve
//! ([`BandLambda::solve_or_rows_into`] does both).
//!
//! Served: point masses only (no rigid body), every row an equality that moves some body,
//! no body moved by two rows further apart than neighbours in the listing order (A = J M⁻¹ Jᵀ
//! is then tridiagonal in that order), no more rows than the velocity components they move.
//! Declined at construction (`None`): rigid bodies, inequality rows, a wider band or a band
//! only a renumbering finds (the rows' solve renumbers by reverse Cuthill–McKee), and a band
//! only A's formulas show: two rows further apart moving one body, whose Aₖⱼ the derivation
//! simplified to zero (J's orthogonal by their formulas) but J's numbers need not give as
//! one. A zero Aₖ,ₖ₊₁ within the band (orthogonal J's of neighbours) is a number like any.
//!
//! The guard, per call ([`BandLambda::solve_into`] returns false, `out` untouched):
//! - the settings' [`Method`] is [`Method::Banded`], or [`Method::Auto`] with more than
//!   four rows (`Auto` solves fewer densely; the same rule as the rows' chain path);
//! - every input (the state, the parameters, the masses) is zero or of magnitude within
//!   [`INPUT_RANGE`], and so is every 1/m (a NaN input is the general solve's `NonFiniteRow`,
//!   an infinite or zero mass its `InfiniteMass`);
//! - every Aₖₖ is within [`DIAGONAL_RANGE`] (a zero one is a zero gradient; one outside is
//!   a state whose numbers the general solve may have to rescale), and every pivot
//!   dₖ > τ Aₖₖ, τ the settings' `rank_tolerance` (the general solve's relative threshold on
//!   the Jacobi-scaled Ã = D A D with D = diag(Aₖₖ)^−½, whose pivots are exactly dₖ/Aₖₖ: the
//!   same test, so a state it calls singular or redundant is declined);
//! - every λₖ is zero or a normal number (the general solve's `LambdaOutOfRange` and
//!   `NonFiniteLambda`), and every acceleration is finite.
//!
//! No test looks at the program's outputs as such: one that is not finite (a J of 0/0 at a
//! zero-length `norm` link, a force over a zero) fails one of these. A non-finite mass fails
//! 1/m's range; a force component makes its body's acceleration not finite; a J component
//! makes its Aₖₖ not finite (formed from J) or its body's Σₖ λₖ Jₖᵢ, hence acceleration, not
//! finite (λₖ finite times ±∞ or NaN, and a sum with one, is not finite); a c makes bₖ, yₖ
//! and λₖ not finite (1/dₖ is finite and positive); from the formulas, an Aₖₖ fails its
//! range and an Aₖ₋₁,ₖ makes dₖ −∞ or NaN, failing the pivot test.
//!
//! Accuracy: λ here and the scaled solve's are equally accurate, to a small constant (the
//! analysis is on the factor's function, `BandLambda::solve`, beside the guard;
//! `tests/band_lambda.rs` measures it against a double-double reference).
//!
//! Not here: the rows' C and Ċ (a projection needs them: `numeric::rows`), inequality rows,
//! wider bands, rigid bodies, diagnostics (a declined state gets them from the rows' solve).

use crate::derive::Derivation;
use crate::expr::eval::{Env, Value};
use crate::expr::graph::SymbolWalk;
use crate::expr::{Id, Symbol};
use crate::model::system::System;
use crate::numeric::batch::{Batched, BatchedScratch};
use crate::numeric::contact::ContactState;
use crate::numeric::program::Inputs;
use crate::numeric::rows::{RowProgram, RowScratch, Rows};
use crate::numeric::solve::{self, Method, Settings, Solution, Status};
use crate::numeric::tape::{Scratch, Tape};

/// Past every output index the program may have (checked when it is made).
const ABSENT: u32 = u32::MAX;

/// The magnitudes of the inputs served (zero aside), and of every 1/m: 2^±240. Products of
/// up to four of them (within 2^±960) neither overflow nor underflow: a chain's J = d is of
/// degree one, c = ḋ·ḋ and F = m g of degree two, the terms formed here of degree three
/// (Jₖᵢ·Jⱼᵢ/mᵢ, A's) and four (Jₖᵢ·Fᵢ/mᵢ, b's), and A's formulas compiled of degree three
/// (Aₖₖ = (d·d)(1/mₖ₋₁ + 1/mₖ)); so the numbers lose no digits to f64's range but where a
/// difference cancels (d = rₖ − rₖ₋₁ tiny), which [`DIAGONAL_RANGE`] catches. A scene
/// outside it (the article's bead at |r| = 1e-150 or 1e155) goes to the rows' solve, which
/// changes its length unit where it must. (The bound on 1/m is the underflow argument's of
/// [`DIAGONAL_RANGE`]; a mass that is an input in range has its 1/m in range.)
pub const INPUT_RANGE: std::ops::RangeInclusive<f64> =
    f64::from_bits(0x30f0_0000_0000_0000)..=f64::from_bits(0x4ef0_0000_0000_0000);

/// The diagonal entries served: 2^±480. There the factor's numbers stay normal, or the
/// guard declines:
/// - Aₖ₋₁,ₖ formed from J is at most (1 + γ)(Aₖₖ Aₖ₋₁,ₖ₋₁)^½, γ a few u (each shared body's
///   term |Jₖ₋₁,ᵢ·Jₖᵢ|/mᵢ is at most the geometric mean of its terms in the two diagonals,
///   Cauchy–Schwarz, and those terms are non-negative), so Aₖ₋₁,ₖ² stays below 2^961; from
///   the formulas (compiled) an Aₖ₋₁,ₖ² that overflowed would make dₖ = −∞, which the pivot
///   test declines. The computed A need not be a Gram matrix exactly: its pivots still lie
///   in (τ Aₖₖ, Aₖₖ] (dₖ = Aₖₖ minus a non-negative number, rounded), so 1/dₖ lies in
///   [2^−480, 2^480/τ) (normal for any τ above 2^−543; the default τ = 1e-10 is about 2^−33);
/// - a product Aₖ₋₁,ₖ² that underflows is below 2^−1022, negligible against u Aₖₖ ≥ 2^−533;
/// - A's terms formed from J: a component product Jₖᵢ Jⱼᵢ that underflows errs by at most
///   2^−1075, times 1/mᵢ ≤ 2^240 ([`INPUT_RANGE`], checked): below 2^−834, negligible
///   against u (Aₖₖ Aⱼⱼ)^½ ≥ 2^−533; a term that overflows makes its Aₖₖ infinite.
///
/// So the rounding is the analysis' alone (`BandLambda::solve`).
pub const DIAGONAL_RANGE: std::ops::RangeInclusive<f64> =
    f64::from_bits(0x21f0_0000_0000_0000)..=f64::from_bits(0x5df0_0000_0000_0000);

/// A chain's λ from one program of A's band, c, J, the masses and forces (see the
/// module's note for what it serves and what its guard declines).
#[derive(Clone, Debug)]
pub struct BandLambda {
    kernel: Kernel,
    /// The program's roots, in units (each row's, then each body's: indices into
    /// `roots`), kept for `BandLambda::compile` (feature `jit`).
    #[cfg(feature = "jit")]
    roots: Vec<Id>,
    #[cfg(feature = "jit")]
    units: Vec<Vec<usize>>,
    /// The input symbols: the vectors', whose components fill the input buffer's first
    /// slots in turn (`dim` each), then the scalars', one slot each after them (checked when
    /// the program is made): the loads are two runs of one width, no width or place to read.
    vectors: Vec<Symbol>,
    scalars: Vec<Symbol>,
    dim: usize,
    /// Per row, where its numbers are among the outputs.
    rows: Vec<RowAt>,
    /// Every row's J entries in turn.
    entries: Vec<EntryAt>,
    /// Per body, where its mass and force are.
    bodies: Vec<BodyAt>,
    // Buffers of one call.
    /// The inputs of the batched and compiled kernels (the interpreted tape's are in its
    /// registers: `Tape::input_registers`).
    input: Vec<f64>,
    /// The batched and compiled kernels' outputs, then one zero (an absent Aₖ₋₁,ₖ's, read
    /// with no test); the interpreted tape leaves its outputs in its registers, where the
    /// places of `rows`, `entries` and `bodies` point (`Tape::eval_in_registers`).
    output: Vec<f64>,
    /// Whether A's band is among the outputs, from the derivation's formulas (compiled code,
    /// where they cost less than forming A from J), rather than formed from J here.
    formulas: bool,
    /// Per body: F/m, then 1/m.
    per_body: Vec<[f64; 4]>,
    /// Per J entry, its components read from the outputs once (the row's Aₖ₋₁,ₖ, and the
    /// forces Σₖ λₖ Jₖᵢ, read them here).
    jacobian: Vec<[f64; 3]>,
    /// Per row: 1/dₖ, Lₖ = Aₖ₋₁,ₖ/dₖ₋₁, y then λ.
    inverse_pivot: Vec<f64>,
    multiplier: Vec<f64>,
    lambda: Vec<f64>,
    /// Per body: Σₖ λₖ Jₖᵢ, and the acceleration (swapped with the answer's vectors when
    /// the guard passes: no copy).
    force: Vec<[f64; 3]>,
    acceleration: Vec<[f64; 3]>,
    /// Per body, the rows that move it and their J entries, in row order (none: the body's
    /// Σₖ λₖ Jₖᵢ is zero).
    movers: Vec<Movers>,
    /// The answer's flags and contact states, one a row: every row active, none a contact.
    active: Vec<bool>,
    contacts: Vec<Option<ContactState>>,
}

/// How the program's roots are computed: one tape of them all (and its compiled twin once
/// [`BandLambda::compile`] has made it), or shape by shape (`numeric::batch`) where rows
/// and bodies repeat a shape often enough, as the rows' program does.
#[derive(Clone, Debug)]
enum Kernel {
    Tape {
        tape: Tape,
        scratch: Scratch,
        #[cfg(feature = "jit")]
        compiled: Option<std::sync::Arc<crate::numeric::jit::JitTape>>,
    },
    Batched(Box<Batched>, BatchedScratch),
}

/// One row's output c and its J entries `entries[start..end]`; where A's band comes from
/// the formulas (compiled code), Aₖₖ and Aₖ₋₁,ₖ among the outputs (the zero past them when
/// the formula is zero or the row the first).
#[derive(Clone, Copy, Debug)]
struct RowAt {
    bias: u32,
    start: u32,
    end: u32,
    diagonal: u32,
    lower: u32,
}

/// A J entry: where its components are among the outputs (the interpreted tape's
/// registers), its body, and the entry of the same body in the row before (an index into
/// `entries`; [`ABSENT`] when that row does not move the body): the pair's term of Aₖ₋₁,ₖ.
#[derive(Clone, Copy, Debug)]
struct EntryAt {
    at: [u32; 3],
    body: u32,
    partner: u32,
}

/// The rows that move a body (at most two, neighbours: the band's condition) and the index
/// of each one's J entry of it in `entries`, in row order; `count` of them are set.
#[derive(Clone, Copy, Debug, Default)]
struct Movers {
    count: u32,
    row: [u32; 2],
    entry: [u32; 2],
}

/// Where a body's mass and its force's components are.
#[derive(Clone, Copy, Debug)]
struct BodyAt {
    mass: u32,
    force: [u32; 3],
}

/// Whether `method` lets a chain of `k` rows be solved by a band factor: the rule of the
/// rows' chain path (`Auto` solves four rows or fewer densely).
fn allowed(method: Method, k: usize) -> bool {
    match method {
        Method::Banded => k > 0,
        Method::Auto => k > 4,
        Method::Dense | Method::Sparse => false,
    }
}

/// Whether `x` is zero or of a magnitude in [`INPUT_RANGE`] (a NaN is not: its comparisons
/// are false). Gathered, not branched on.
#[inline(always)]
fn in_range(x: f64) -> bool {
    let (small, big) = (*INPUT_RANGE.start(), *INPUT_RANGE.end());
    let a = x.abs();
    (a <= big) & ((a >= small) | (a == 0.0))
}

/// `D` components of a root, from where they are.
#[inline(always)]
fn read<const D: usize>(o: &[f64], at: &[u32; 3]) -> [f64; D] {
    std::array::from_fn(|d| o[at[d] as usize])
}

/// Where the solve reads the outputs: the interpreted tape's registers (where it leaves
/// them: `Tape::eval_in_registers`), else `output`.
fn outputs<'a>(kernel: &'a Kernel, output: &'a [f64]) -> &'a [f64] {
    match kernel {
        #[cfg(feature = "jit")]
        Kernel::Tape { compiled: Some(_), .. } => output,
        Kernel::Tape { tape, scratch, .. } => tape.registers(scratch),
        Kernel::Batched(..) => output,
    }
}

impl BandLambda {
    /// The program of `derivation`'s chain, with `forces` the scene's force expressions by
    /// body (the others are the bodies' force symbols, as [`RowProgram::new`] takes them);
    /// `None` for a system it does not serve (see the module's note).
    pub fn new(system: &System, derivation: &Derivation, forces: &[(usize, Id)]) -> Option<BandLambda> {
        let k = derivation.constraints.len();
        let dim = system.dim();
        let point_masses = system.bodies.iter().all(|b| b.rigid.is_none());
        let equalities = system.constraints.iter().all(|c| !c.inequality);
        if k == 0 || !point_masses || !equalities || !matches!(dim, 2 | 3) || k >= ABSENT as usize {
            return None;
        }
        // A = J M⁻¹ Jᵀ is tridiagonal in the listing order when no body is moved by two rows
        // further apart than neighbours: the rows acting on each body, first and last.
        let mut acting: Vec<Option<(usize, usize)>> = vec![None; system.bodies.len()];
        for (r, d) in derivation.constraints.iter().enumerate() {
            if d.jacobian.is_empty() {
                return None;
            }
            for &(b, _) in &d.jacobian {
                let span = acting.get_mut(b)?;
                *span = Some(span.map_or((r, r), |(first, _)| (first, r)));
            }
        }
        if acting.iter().flatten().any(|&(first, last)| last - first > 1) {
            return None;
        }
        // No more rows than the velocity components they move: past that A is singular
        // whatever the state (the general solve's `structurally_singular`).
        if k > dim * acting.iter().flatten().count() {
            return None;
        }
        // The roots in units: per row c, J; per body m, F.
        let mut roots = Vec::new();
        let mut units = Vec::with_capacity(k + system.bodies.len());
        for d in &derivation.constraints {
            let first = roots.len();
            roots.push(d.bias);
            roots.extend(d.jacobian.iter().map(|&(_, j)| j));
            units.push((first..roots.len()).collect::<Vec<_>>());
        }
        // Each body's force expression (the first `forces` gives, as `RowProgram::new`
        // takes it).
        for (body, f) in system.bodies.iter().zip(system.by_body(forces)) {
            let f = f.unwrap_or(body.nodes.force);
            units.push(vec![roots.len(), roots.len() + 1]);
            roots.push(body.mass);
            roots.push(f);
        }
        let graph = &derivation.graph;
        let found = SymbolWalk::default().free_symbols_of(graph, &roots).to_vec();
        // The vectors' symbols first, then the scalars': the input buffer is then `dim`
        // slots a vector from slot 0, one a scalar after them (checked).
        let widths = Inputs::new(graph, &found).ok()?;
        let (vectors, scalars): (Vec<_>, Vec<_>) = found.iter().zip(widths.ranges()).partition(|(_, r)| r.len() > 1);
        let (vectors, scalars): (Vec<Symbol>, Vec<Symbol>) =
            (vectors.iter().map(|v| *v.0).collect(), scalars.iter().map(|s| *s.0).collect());
        let symbols: Vec<Symbol> = vectors.iter().chain(&scalars).copied().collect();
        let layout = Inputs::new(graph, &symbols).ok()?;
        let ranges = layout.ranges();
        let first_scalar = vectors.len() * dim;
        let expected = (0..vectors.len())
            .map(|i| i * dim..(i + 1) * dim)
            .chain((0..scalars.len()).map(|j| first_scalar + j..first_scalar + j + 1));
        if !ranges.iter().cloned().eq(expected) {
            return None;
        }
        let input_len = ranges.last().map_or(0, |r| r.end);
        let position: crate::expr::graph::FastMap<Symbol, usize> =
            symbols.iter().enumerate().map(|(i, &s)| (s, i)).collect();
        // Each root's width as a tape of it alone would give it: a scalar 1, a vector the
        // dimension.
        let width = |r: usize| if graph.ty(roots[r]) == crate::expr::Ty::Vector { dim } else { 1 };
        let source = |s: Symbol| position.get(&s).map_or(0..0, |&i| ranges[i].clone());
        let batched = Batched::new(graph, &roots, &units, width, source, |_| None);
        // Each root's components' places (past its width, the first again), and how many
        // numbers the solve reads them from: the batched outputs, or the interpreted tape's
        // registers, where it leaves its outputs (`Tape::eval_in_registers`).
        let (kernel, output_len, readable, place): (Kernel, usize, usize, Vec<[usize; 3]>) = match batched {
            Some(b) => {
                let place = (0..roots.len())
                    .map(|r| {
                        let (first, stride) = b.place(r);
                        let component = |d: usize| if d < width(r) { first + d * stride } else { first };
                        [component(0), component(1), component(2)]
                    })
                    .collect();
                let len = b.output_len();
                let scratch = b.scratch();
                (Kernel::Batched(Box::new(b), scratch), len, len, place)
            }
            None => {
                let tape = Tape::compile(graph, &roots, &symbols).ok()?;
                let place = (0..roots.len())
                    .map(|r| {
                        let range = tape.output_range(r);
                        let component = |d: usize| tape.output_register(range.start + d.min(range.len().max(1) - 1));
                        [component(0), component(1), component(2)]
                    })
                    .collect();
                let len = tape.output_len();
                let registers = tape.registers(&tape.scratch()).len();
                let scratch = tape.scratch();
                #[cfg(feature = "jit")]
                let kernel = Kernel::Tape { tape, scratch, compiled: None };
                #[cfg(not(feature = "jit"))]
                let kernel = Kernel::Tape { tape, scratch };
                (kernel, len, registers, place)
            }
        };
        // Every place, with its last component, within the outputs, and every root as wide
        // as a point mass's rows read it.
        let fits = |r: usize, w: usize| {
            width(r) == w && place[r].iter().all(|&at| at < readable) && readable < ABSENT as usize
        };
        let at = |r: usize| place[r].map(|at| at as u32);
        let (mut rows, mut entries) = (Vec::with_capacity(k), Vec::<EntryAt>::new());
        for (unit, d) in units.iter().zip(&derivation.constraints) {
            let start = entries.len() as u32;
            // The row before's entries, where a body this row shares with it is found.
            let before = rows.last().map_or(start, |row: &RowAt| row.start);
            for (&r, &(body, _)) in unit[1..].iter().zip(&d.jacobian) {
                if !fits(r, dim) {
                    return None;
                }
                let body = body as u32;
                let partner = (before..start).find(|&b| entries[b as usize].body == body).unwrap_or(ABSENT);
                entries.push(EntryAt { at: at(r), body, partner });
            }
            if !fits(unit[0], 1) {
                return None;
            }
            let (diagonal, lower) = (output_len as u32, output_len as u32);
            rows.push(RowAt { bias: at(unit[0])[0], start, end: entries.len() as u32, diagonal, lower });
        }
        let mut bodies = Vec::with_capacity(system.bodies.len());
        for unit in &units[k..] {
            let (mass, force) = (unit[0], unit[1]);
            if !(fits(mass, 1) && fits(force, dim)) {
                return None;
            }
            bodies.push(BodyAt { mass: at(mass)[0], force: at(force) });
        }
        let n = bodies.len();
        // Each body's rows and entries, in row order (the entries are): at most two rows,
        // neighbours, and one entry of the body each, or the band's condition fails.
        let mut movers = vec![Movers::default(); n];
        for (r, row) in rows.iter().enumerate() {
            for i in row.start..row.end {
                let m = movers.get_mut(entries[i as usize].body as usize)?;
                let slot = m.count as usize;
                if slot >= 2 {
                    return None;
                }
                (m.row[slot], m.entry[slot], m.count) = (r as u32, i, m.count + 1);
            }
        }
        Some(BandLambda {
            kernel,
            #[cfg(feature = "jit")]
            roots,
            #[cfg(feature = "jit")]
            units,
            vectors,
            scalars,
            dim,
            rows,
            jacobian: vec![[0.0; 3]; entries.len()],
            entries,
            bodies,
            input: vec![0.0; input_len],
            output: vec![0.0; output_len + 1],
            formulas: false,
            per_body: vec![[0.0; 4]; n],
            inverse_pivot: vec![0.0; k],
            multiplier: vec![0.0; k],
            lambda: vec![0.0; k],
            force: vec![[0.0; 3]; n],
            acceleration: vec![[0.0; 3]; n],
            movers,
            active: vec![true; k],
            contacts: vec![None; k],
        })
    }

    /// How many rows the program solves.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether the program has no rows (never: [`new`](BandLambda::new) declines them).
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Whether the roots are evaluated shape by shape (`numeric::batch`) rather than by one
    /// tape.
    pub fn is_batched(&self) -> bool {
        matches!(self.kernel, Kernel::Batched(..))
    }

    /// Compiles the program to machine code ([`Tape::jit`]); never done unless asked (as
    /// [`RowProgram::compile`]). The program is lowered again as one tape of every root (from
    /// `derivation`, the one it was made from), with A's band's formulas added
    /// (`Derivation::a`): compiled code has no dispatch to share among the members of a shape,
    /// and evaluates the formulas for less than forming A from J costs (callgrind, the
    /// 10-link chain: 421 instructions a row against 437 from J; 386 against 402 at 100 links).
    /// λ is then the interpreted one's within rounding, not bit for bit (A's entries round
    /// otherwise), and as accurate (`BandLambda::solve`). On failure (a tape too large for
    /// compiled code's frame, a host without a code generator) the program evaluates as
    /// before and the error is returned.
    #[cfg(feature = "jit")]
    pub fn compile(&mut self, derivation: &Derivation) -> Result<(), crate::numeric::jit::JitError> {
        if self.is_compiled() {
            return Ok(());
        }
        // A's band from the formulas (`Derivation::a`): each row's Aₖₖ and Aₖ₋₁,ₖ, when every
        // entry is within the band J's bodies gave (always, A being J M⁻¹ Jᵀ) and every
        // diagonal has one; else A is formed from J as before.
        let k = self.rows.len();
        let (mut diagonal, mut lower) = (vec![None; k], vec![None; k]);
        let mut within = true;
        for &(r, c, id) in &derivation.a {
            match c.checked_sub(r) {
                Some(0) if r < k => diagonal[r] = Some(id),
                Some(1) if c < k => lower[c] = Some(id),
                _ => within = false,
            }
        }
        let mut roots = self.roots.clone();
        let mut band = Vec::with_capacity(k);
        if within && diagonal.iter().all(Option::is_some) {
            for (d, l) in diagonal.iter().flatten().zip(&lower) {
                band.push((roots.len(), l.map(|_| roots.len() + 1)));
                roots.push(*d);
                roots.extend(l);
            }
        }
        let symbols: Vec<Symbol> = self.vectors.iter().chain(&self.scalars).copied().collect();
        let Ok(tape) = Tape::compile(&derivation.graph, &roots, &symbols) else {
            return Err(crate::numeric::jit::JitError::Codegen("the roots do not lower".into()));
        };
        let jit = tape.jit()?;
        // The one tape writes root r at its own place: every place moves.
        let place = |r: usize| tape.output_range(r).start as u32;
        let zero = tape.output_len() as u32;
        for (i, (row, unit)) in self.rows.iter_mut().zip(&self.units).enumerate() {
            row.bias = place(unit[0]);
            for (entry, &j) in self.entries[row.start as usize..row.end as usize].iter_mut().zip(&unit[1..]) {
                entry.at = [place(j), place(j) + 1, place(j) + 2];
            }
            if let Some(&(d, l)) = band.get(i) {
                (row.diagonal, row.lower) = (place(d), l.map_or(zero, place));
            }
        }
        for (body, unit) in self.bodies.iter_mut().zip(&self.units[k..]) {
            (body.mass, body.force) = (place(unit[0]), [place(unit[1]), place(unit[1]) + 1, place(unit[1]) + 2]);
        }
        self.formulas = !band.is_empty();
        self.output = vec![0.0; tape.output_len() + 1];
        let scratch = tape.scratch();
        self.kernel = Kernel::Tape { tape, scratch, compiled: Some(std::sync::Arc::new(jit)) };
        Ok(())
    }

    /// Whether the tape runs as machine code ([`compile`](BandLambda::compile)).
    pub fn is_compiled(&self) -> bool {
        #[cfg(feature = "jit")]
        return matches!(self.kernel, Kernel::Tape { compiled: Some(_), .. });
        #[cfg(not(feature = "jit"))]
        false
    }

    /// λ, the constraint forces and the accelerations at the state `env` (of the system the
    /// program was made from) into `out`, its status `Solved` with no diagnostic, when the
    /// guard passes (see the module's note); false, `out` untouched, when it declines: the
    /// caller then evaluates the rows and takes [`solve::solve_into`], which gives the
    /// answer or the diagnostic this path cannot
    /// ([`solve_or_rows_into`](BandLambda::solve_or_rows_into) does both).
    pub fn solve_into(&mut self, env: &Env, settings: &Settings, out: &mut Solution) -> bool {
        if !allowed(settings.method, self.rows.len()) || !self.evaluate(env) {
            return false;
        }
        let solved = match (self.dim, self.formulas) {
            (2, false) => self.solve::<2, false>(settings),
            (2, true) => self.solve::<2, true>(settings),
            (_, false) => self.solve::<3, false>(settings),
            (_, true) => self.solve::<3, true>(settings),
        };
        if !solved {
            return false;
        }
        let k = self.rows.len();
        // The answer's vectors and ours trade places (ours are the next call's buffers).
        std::mem::swap(&mut out.lambda, &mut self.lambda);
        std::mem::swap(&mut out.constraint_force, &mut self.force);
        std::mem::swap(&mut out.acceleration, &mut self.acceleration);
        let n = self.bodies.len();
        // The answer's old vectors are the next call's buffers: of the size already but on
        // the first call.
        if self.lambda.len() != k {
            self.lambda.resize(k, 0.0);
        }
        for v in [&mut self.force, &mut self.acceleration] {
            if v.len() != n {
                v.resize(n, [0.0; 3]);
            }
        }
        // Every row active, none a contact: copies of ours (a copy of bytes, where a resize
        // writes them one by one).
        out.active.clone_from(&self.active);
        out.diagnostics.clear();
        out.status = Status::Solved;
        out.contacts.clone_from(&self.contacts);
        true
    }

    /// The factor, λ, the forces and the accelerations of the evaluated outputs, in the
    /// dimension `D`, into this program's buffers: false where the guard declines.
    ///
    /// Accuracy: what λ loses against the rows' scaled solve. That solve factors the
    /// Jacobi-scaled Ã = D A D (D = diag(Aₖₖ)^−½, from ‖J‖ and the masses), this one A itself
    /// (dₖ = Aₖₖ − Aₖ₋₁,ₖ²/dₖ₋₁, L D Lᵀ without square roots). Cholesky is invariant
    /// under diagonal scaling, in exact arithmetic and in its rounding error (Higham,
    /// *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §10.1): the computed factor
    /// of A is the exact factor of A + ΔA with |ΔA| ≤ γ₃ |L̂| D̂ |L̂ᵀ| componentwise, a bound
    /// that scales with A — factoring D A D instead multiplies ΔA's bound by D on both sides,
    /// exactly for powers of two and to the rounding of D otherwise — and for an SPD
    /// tridiagonal |L̂| D̂ |L̂ᵀ| = |L̂ D̂ L̂ᵀ| (no growth, §9.6), so |ΔAᵢⱼ| ≤ γ₃' (Aᵢᵢ Aⱼⱼ)^½:
    /// a perturbation of Ã of order u, whichever matrix was factored. The substitutions add
    /// the same componentwise backward error, and b comes from c, J, F and 1/m with a few
    /// roundings a term (relative to the terms of b), again of order u.
    ///
    /// A's entries, formed from J (interpreted; compiled code evaluates their formulas, a few
    /// roundings each, as the rows' solve's assembly does): the computed Aₖₖ = Σᵢ
    /// (Jₖᵢ·Jₖᵢ)/mᵢ sums non-negative terms, each a dot product of D components and one
    /// product, so it is within γ_{D+p} relatively, p the row's bodies (Higham §3.1); the
    /// computed Aₖ₋₁,ₖ = Σ over the shared bodies (Jₖ₋₁,ᵢ·Jₖᵢ)/mᵢ may cancel, and errs by at
    /// most γ_{D+q} Σᵢ |Jₖ₋₁,ᵢ|·|Jₖᵢ|/mᵢ ≤ γ_{D+q} (Aₖ₋₁,ₖ₋₁ Aₖₖ)^½ (Cauchy–Schwarz), q the
    /// shared bodies (underflows add less, `DIAGONAL_RANGE`). Both are perturbations of Ã's
    /// entries of order u, as the formulas' roundings were (where the formula cancels,
    /// −(dₖ·dₖ₊₁)/m, J's dot product cancels alike). The computed A is a Gram matrix only to
    /// within them: where they make it indefinite, some pivot is ≤ 0 (Sylvester's law of
    /// inertia, the factor's own rounding aside) and the guard declines, as the general solve
    /// calls a matrix whose scaled pivot is below τ = 1e-10 ≫ u singular. Hence the forward
    /// error of both is governed by κ₂(Ã) rather than
    /// κ₂(A) (Thm 10.6 and the remark after it; van der Sluis: the Jacobi scaling is within
    /// a factor of the rows' count of non-zeros, 3 here, of the best diagonal scaling):
    /// ‖λ̂ − λ‖/‖λ‖ ≤ c n κ₂(Ã) u for a small c, the bound of the scaled solve. Not taking
    /// the scaled solve's step of refinement loses nothing beyond a constant (`chain.rs`'s
    /// `REFINE_BOUND`: a backward stable solve's error is already κ u). The test holds the
    /// two errors against a double-double reference within 16× of each other case by case
    /// and within 1.5× summed; measured, with A formed from J, 1.14× summed on 100 random
    /// states, 1.10× on 108 ill-conditioned chains (1.01× in geometric mean, from 0.04× to
    /// 9.9× case by case), as with A's formulas (1.14×, 1.10×).
    fn solve<const D: usize, const FORMULAS: bool>(&mut self, settings: &Settings) -> bool {
        let o = outputs(&self.kernel, &self.output);
        // 1/m and F/m per body: 1/m within the inputs' range.
        let mut ok = true;
        for (b, per_body) in self.bodies.iter().zip(&mut self.per_body) {
            let w = 1.0 / o[b.mass as usize];
            ok &= INPUT_RANGE.contains(&w);
            let f: [f64; D] = read(o, &b.force);
            for d in 0..D {
                per_body[d] = f[d] * w;
            }
            per_body[3] = w;
        }
        // Row by row: −bₖ = −(cₖ + Σᵢ Jₖᵢ·Fᵢ/mᵢ), Aₖₖ = Σᵢ (Jₖᵢ·Jₖᵢ)/mᵢ, Aₖ₋₁,ₖ =
        // Σ over the shared bodies (Jₖ₋₁,ᵢ·Jₖᵢ)/mᵢ; dₖ = Aₖₖ − Aₖ₋₁,ₖ²/dₖ₋₁,
        // Lₖ = Aₖ₋₁,ₖ/dₖ₋₁, yₖ = −bₖ − Lₖ yₖ₋₁ (L y = −b); the pivot above τ Aₖₖ.
        let tolerance = settings.rank_tolerance;
        let (mut inverse_prev, mut y_prev) = (0.0, 0.0);
        let per_row = self.rows.iter().zip(&mut self.inverse_pivot).zip(&mut self.multiplier).zip(&mut self.lambda);
        for (((row, inverse_pivot_out), multiplier), y_out) in per_row {
            let (mut b, mut diagonal, mut e) = (o[row.bias as usize], 0.0, 0.0);
            if FORMULAS {
                (diagonal, e) = (o[row.diagonal as usize], o[row.lower as usize]);
            }
            for i in row.start as usize..row.end as usize {
                let entry = self.entries[i];
                let j: [f64; D] = read(o, &entry.at);
                let body = &self.per_body[entry.body as usize];
                let mut square = 0.0;
                for d in 0..D {
                    b += j[d] * body[d];
                    square += j[d] * j[d];
                }
                // The body's terms of Aₖₖ, and of Aₖ₋₁,ₖ when the row before moves it too.
                if !FORMULAS {
                    diagonal += square * body[3];
                    if let Some(before) = self.jacobian.get(entry.partner as usize) {
                        let mut dot = 0.0;
                        for d in 0..D {
                            dot += before[d] * j[d];
                        }
                        e += dot * body[3];
                    }
                }
                self.jacobian[i][..D].copy_from_slice(&j);
            }
            let d = diagonal - e * e * inverse_prev;
            ok &= DIAGONAL_RANGE.contains(&diagonal) & (d > tolerance * diagonal);
            let l = e * inverse_prev;
            let y = -b - l * y_prev;
            // The next row's 1/dₖ from here, not read back from the buffer (a store and a load
            // on the factor's chain of dependent operations).
            let inverse_pivot = 1.0 / d;
            *inverse_pivot_out = inverse_pivot;
            *multiplier = l;
            *y_out = y;
            (inverse_prev, y_prev) = (inverse_pivot, y);
        }
        if !ok {
            return false;
        }
        // D Lᵀ λ = y: λ_{K−1} = y_{K−1}/d_{K−1}, λₖ = yₖ/dₖ − Lₖ₊₁ λₖ₊₁; each λ zero or normal.
        let (mut next, mut next_multiplier) = (0.0, 0.0);
        let per_row = self.lambda.iter_mut().zip(&self.inverse_pivot).zip(&self.multiplier).rev();
        for ((x, inverse_pivot), multiplier) in per_row {
            let lambda = *x * inverse_pivot - next_multiplier * next;
            ok &= (lambda == 0.0) | lambda.is_normal();
            *x = lambda;
            (next, next_multiplier) = (lambda, *multiplier);
        }
        if !ok {
            return false;
        }
        // Per body Σₖ λₖ Jₖᵢ over the rows that move it, in row order (zero where none
        // does), then aᵢ = Fᵢ/mᵢ + (Σₖ λₖ Jₖᵢ)/mᵢ, finite. (In 2D the third components are
        // zeros: the buffers are the caller's old answer's.)
        let (lambda, jacobian) = (&self.lambda, &self.jacobian);
        let term = |movers: &Movers, m: usize| -> [f64; D] {
            let x = lambda[movers.row[m] as usize];
            let j = &jacobian[movers.entry[m] as usize];
            std::array::from_fn(|d| x * j[d])
        };
        let mut not_finite = 0.0;
        let per_body = self.acceleration.iter_mut().zip(&mut self.force).zip(&self.per_body).zip(&self.movers);
        for (((a, fc), body), movers) in per_body {
            let f: [f64; D] = match movers.count {
                0 => [0.0; D],
                1 => term(movers, 0),
                _ => {
                    let (first, second) = (term(movers, 0), term(movers, 1));
                    std::array::from_fn(|d| first[d] + second[d])
                }
            };
            for d in 0..D {
                fc[d] = f[d];
                a[d] = body[d] + f[d] * body[3];
                not_finite += a[d] * 0.0;
            }
            for d in D..3 {
                (a[d], fc[d]) = (0.0, 0.0);
            }
        }
        not_finite == 0.0
    }

    /// [`solve_into`](BandLambda::solve_into), and where it declines the rows of `program`
    /// (the same system's, with the same forces) evaluated into `rows` and
    /// [`solve::solve_into`]: the answer the caller would have had from the rows, with their
    /// diagnostics. Returns whether the band path answered; an error when the rows could not
    /// be evaluated (a symbol without a value).
    #[allow(clippy::too_many_arguments)]
    pub fn solve_or_rows_into(
        &mut self,
        system: &System,
        env: &Env,
        settings: &Settings,
        program: &RowProgram,
        scratch: &mut RowScratch,
        rows: &mut Rows,
        out: &mut Solution,
    ) -> Result<bool, crate::expr::eval::EvalError> {
        if self.solve_into(env, settings, out) {
            return Ok(true);
        }
        program.evaluate_into(system, env, scratch, rows)?;
        solve::solve_into(rows, settings, out);
        Ok(false)
    }

    /// The program's inputs from `env`, then its outputs: false when a symbol has no value
    /// (or one of another kind) or a number is not finite.
    fn evaluate(&mut self, env: &Env) -> bool {
        // The interpreted tape's inputs are written into its registers, where it reads them.
        let input = match &mut self.kernel {
            #[cfg(feature = "jit")]
            Kernel::Tape { compiled: Some(_), .. } => &mut self.input[..],
            Kernel::Tape { tape, scratch, .. } => tape.input_registers(scratch),
            Kernel::Batched(..) => &mut self.input[..],
        };
        let loaded = match self.dim {
            2 => load::<2>(input, &self.vectors, &self.scalars, env),
            _ => load::<3>(input, &self.vectors, &self.scalars, env),
        };
        if !loaded {
            return false;
        }
        let len = self.output.len() - 1;
        let output = &mut self.output[..len];
        match &mut self.kernel {
            Kernel::Batched(batched, scratch) => batched.eval(&self.input, scratch, output),
            #[cfg(feature = "jit")]
            Kernel::Tape { compiled: Some(compiled), .. } => compiled.eval(&self.input, output),
            Kernel::Tape { tape, scratch, .. } => tape.eval_in_registers(scratch),
        }
        true
    }
}

/// The inputs from `env` into `input` (the vectors' `D` components from slot 0, then the
/// scalars: `BandLambda`'s layout), each number checked as it is stored: false when a
/// symbol has no value (or one of another kind), or a number is not zero or of a magnitude
/// within [`INPUT_RANGE`].
fn load<const D: usize>(input: &mut [f64], vectors: &[Symbol], scalars: &[Symbol], env: &Env) -> bool {
    let Some((head, tail)) = input.split_at_mut_checked(vectors.len() * D) else {
        return false;
    };
    let mut all = true;
    for (slot, &s) in head.as_chunks_mut::<D>().0.iter_mut().zip(vectors) {
        let Some(Value::Vector(v)) = env.get(s) else {
            return false;
        };
        for d in 0..D {
            slot[d] = v[d];
            all &= in_range(v[d]);
        }
    }
    for (slot, &s) in tail.iter_mut().zip(scalars) {
        let Some(Value::Scalar(x)) = env.get(s) else {
            return false;
        };
        *slot = x;
        all &= in_range(x);
    }
    all
}
