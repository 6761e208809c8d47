//! Roots of the same shape evaluated together: the rows of a chain, a rope or a grid as one
//! batched tape per shape, instead of one long tape with every link's instructions.
//!
//! A scene repeats a few constraints over many bodies, and `expr::shape` says which: the
//! roots of link k (C, Ċ, c, J) are those of link 2 with the bodies renamed. So the roots
//! are taken in *units* (a row's roots, a body's mass, velocity and force), units of equal
//! shape become the *members* of one batch — the first member's roots compiled once,
//! each member's symbols gathered into its lane — and [`Tape::eval_batch_serial`] runs every
//! instruction over all members at once (structure of arrays, vectorised). Dispatch then
//! costs once per instruction of the shape rather than once per instruction of the scene,
//! which is what made one long tape several times slower than handwritten code. Units whose
//! shape is rare go to one ordinary tape (`rest`).
//!
//! Renaming symbols one-to-one preserves value, so a member's numbers are those of its own
//! roots; they are the one long tape's to rounding (a lowering shares a reciprocal among the
//! roots it compiles together, so a quotient may round differently: tested against the
//! interpreter on chains, `tests/solve_cache.rs`).
//!
//! Not here: what the roots mean (`numeric::rows`), the tape itself (`numeric::tape`).

use super::tape::{BatchScratch, LANES, Scratch, Tape};
use crate::expr::graph::{FastMap, SymbolWalk};
use crate::expr::shape::Shaper;
use crate::expr::{Graph, Id, Symbol, Ty};
use std::ops::Range;

/// Units of one shape are batched when there are at least this many: below, one tape of
/// them costs less than a batch (whose register file of `tape::LANES` values per register is
/// mostly idle). On chains' `simulate` steps the two cross between 9 and 15 units (the
/// measurements are in docs/speed.md, "Small shapes as one tape").
pub const BATCH_MIN: usize = 12;

/// Roots evaluated shape by shape, each left where the batch's lanes write it.
///
/// The outputs are one buffer: each batch's chunks of `LANES` members in turn, each chunk
/// its tape's output rows (component k of the chunk's member s at `k · len + s`, `len` the
/// chunk's members), then the `rest` tape's outputs. A root's components are then `stride`
/// apart ([`place`](Batched::place)), and the caller reads them there: no scatter into
/// another layout.
#[derive(Clone, Debug)]
pub struct Batched {
    batches: Vec<Batch>,
    /// The units in no batch, on one tape over their own symbols, and where each of its
    /// input slots is in the caller's flat inputs.
    rest: Tape,
    rest_source: Vec<usize>,
    /// Per root (an index into the roots `new` was given), its first output and the
    /// distance between its components; `(0, 0)` for a root in no unit.
    places: Vec<(usize, usize)>,
    /// One past the largest index of any `source`: the least length of the caller's
    /// inputs, checked once per evaluation so the gathers need no check per number.
    inputs_len: usize,
    /// The outputs' length: every batch's members' outputs, then `rest`'s.
    outputs_len: usize,
}

/// The members of one shape.
#[derive(Clone, Debug)]
struct Batch {
    /// The first member's roots over its free symbols.
    tape: Tape,
    members: usize,
    /// Where each member's input slots are in the caller's flat inputs, chunk by chunk of
    /// `LANES` members: in a chunk of `len` members from member c, slot j of member c + s
    /// at `j · len + s` (structure of arrays within the chunk).
    source: Vec<usize>,
}

/// `table` (slot j of member s at `j · members + s`) rearranged chunk by chunk of `LANES`
/// members, structure of arrays within each chunk.
fn chunked(table: &[usize], members: usize) -> Vec<usize> {
    let slots = table.len() / members;
    let mut out = Vec::with_capacity(table.len());
    for first in (0..members).step_by(LANES) {
        let len = LANES.min(members - first);
        for j in 0..slots {
            out.extend_from_slice(&table[j * members + first..j * members + first + len]);
        }
    }
    out
}

/// A tape of `ids` over their free symbols and the sine and cosine of those angles among
/// them whose pair `trig` places ([`Tape::compile_with_trig`]), with what each of its input
/// ranges holds: a symbol (`false`) or that symbol's pair (`true`).
fn compile(
    graph: &Graph,
    walk: &mut SymbolWalk,
    ids: &[Id],
    trig: impl Fn(Symbol) -> Option<Range<usize>>,
) -> (Tape, Vec<(Symbol, bool)>) {
    let symbols = walk.free_symbols_of(graph, ids).to_vec();
    let angles: Vec<Symbol> = symbols.iter().copied().filter(|&s| trig(s).is_some()).collect();
    // The roots' free symbols are the inputs, so lowering cannot fail.
    let tape = Tape::compile_with_trig(graph, ids, &symbols, &angles).expect("the inputs are the roots' free symbols");
    let inputs = symbols.into_iter().map(|s| (s, false)).chain(angles.into_iter().map(|s| (s, true))).collect();
    (tape, inputs)
}

/// Buffers of [`Batched::eval`], reused across evaluations.
#[derive(Clone, Debug)]
pub struct BatchedScratch {
    /// Per batch: a chunk's inputs in structure of arrays, and the lanes' registers.
    inputs: Vec<Vec<f64>>,
    lanes: Vec<BatchScratch>,
    rest_inputs: Vec<f64>,
    rest: Scratch,
}

impl Batched {
    /// Batches the `units` of `roots` (each a list of indices into `roots`, root r of
    /// `width(r)` components, as the caller reads it); the inputs are read from a flat
    /// buffer where symbol s occupies `source(s)` (a tape's input layout over every symbol
    /// the roots read), and root r's outputs are at [`place(r)`](Batched::place). `None`
    /// when no shape has [`BATCH_MIN`] units: one tape serves as well.
    ///
    /// `trig(s)`, when it is some, is where the buffer holds the sine and cosine of the
    /// angle s (two slots): the tapes read them there rather than compute them, so an angle
    /// many units turn by (a body's, in each of its joints' rows) has them computed once,
    /// by the caller, with the tapes' own function ([`Func::apply`](crate::expr::Func::apply)).
    pub fn new(
        graph: &Graph,
        roots: &[Id],
        units: &[Vec<usize>],
        width: impl Fn(usize) -> usize,
        source: impl Fn(Symbol) -> Range<usize>,
        trig: impl Fn(Symbol) -> Option<Range<usize>>,
    ) -> Option<Batched> {
        // Where a tape's input range is in the buffer: a symbol's, or an angle's pair.
        let at = |(sym, pair): (Symbol, bool)| if pair { trig(sym).unwrap_or(0..0) } else { source(sym) };
        let mut shaper = Shaper::default();
        let mut walk = SymbolWalk::default();
        // Units by shape, in order of first appearance (deterministic batches).
        let mut by_key: FastMap<Vec<u32>, usize> = FastMap::default();
        let mut groups: Vec<Vec<(usize, Vec<Symbol>)>> = Vec::new();
        for (u, unit) in units.iter().enumerate() {
            let ids: Vec<Id> = unit.iter().map(|&r| roots[r]).collect();
            let mut shape = shaper.shape(graph, &ids);
            // A shape records each slot's role, not its type (a body's velocity and a rigid
            // body's ω share a role's rank): the types too, so members read alike.
            shape.key.push(u32::MAX);
            shape.key.extend(shape.symbols.iter().map(|&s| u32::from(graph.symbol(s).ty == Ty::Vector)));
            let g = *by_key.entry(shape.key).or_insert_with(|| {
                groups.push(Vec::new());
                groups.len() - 1
            });
            groups[g].push((u, shape.symbols));
        }
        if groups.iter().all(|g| g.len() < BATCH_MIN) {
            return None;
        }
        let mut batches = Vec::new();
        let mut rest_roots: Vec<usize> = Vec::new();
        let mut places = vec![(0, 0); roots.len()];
        // The first output of the next batch's members.
        let mut base = 0;
        for group in &groups {
            if group.len() < BATCH_MIN {
                rest_roots.extend(group.iter().flat_map(|(u, _)| units[*u].iter().copied()));
                continue;
            }
            let (first, template) = &group[0];
            let ids: Vec<Id> = units[*first].iter().map(|&r| roots[r]).collect();
            let (tape, inputs) = compile(graph, &mut walk, &ids, &trig);
            let renamed = |theirs: &[Symbol], (sym, pair): (Symbol, bool)| {
                (template.iter().position(|t| *t == sym).map_or(sym, |p| theirs[p]), pair)
            };
            // Every member reads and writes as many numbers as the template: a guard, as the
            // types are in the key.
            let (group, odd): (Vec<_>, Vec<_>) = group.iter().partition(|(u, theirs)| {
                inputs
                    .iter()
                    .enumerate()
                    .all(|(i, &input)| at(renamed(theirs, input)).len() == tape.input_range(i).len())
                    && units[*u].iter().enumerate().all(|(j, &r)| width(r) == tape.output_range(j).len())
            });
            rest_roots.extend(odd.iter().flat_map(|(u, _)| units[*u].iter().copied()));
            if group.len() < BATCH_MIN {
                rest_roots.extend(group.iter().flat_map(|(u, _)| units[*u].iter().copied()));
                continue;
            }
            let members = group.len();
            // A symbol in a slot of the template's shape is renamed to the member's symbol
            // in that slot; the others (parameters, t) are shared.
            let mut from = vec![0; tape.input_len() * members];
            for (s, (_, theirs)) in group.iter().enumerate() {
                for (i, &input) in inputs.iter().enumerate() {
                    for (j, at) in tape.input_range(i).zip(at(renamed(theirs, input))) {
                        from[j * members + s] = at;
                    }
                }
            }
            // Member s is number s − first of the chunk from `first` (every chunk before
            // the last is `LANES` long), whose outputs start at `base + first · n_out`.
            let n_out = tape.output_len();
            for (s, (u, _)) in group.iter().enumerate() {
                let first = s - s % LANES;
                let len = LANES.min(members - first);
                let chunk = base + first * n_out;
                for (j, &r) in units[*u].iter().enumerate() {
                    places[r] = (chunk + tape.output_range(j).start * len + (s - first), len);
                }
            }
            base += members * n_out;
            // Chunk by chunk of `LANES` members (`chunked`), so a chunk's inputs and lanes
            // stay in cache from gather to evaluation.
            let source = chunked(&from, members);
            batches.push(Batch { tape, members, source });
        }
        let ids: Vec<Id> = rest_roots.iter().map(|&r| roots[r]).collect();
        let (rest, rest_inputs) = compile(graph, &mut walk, &ids, &trig);
        let mut rest_source = vec![0; rest.input_len()];
        for (i, &input) in rest_inputs.iter().enumerate() {
            for (j, at) in rest.input_range(i).zip(at(input)) {
                rest_source[j] = at;
            }
        }
        for (j, &r) in rest_roots.iter().enumerate() {
            places[r] = (base + rest.output_range(j).start, 1);
        }
        let outputs_len = base + rest.output_len();
        let past = |table: &[usize]| table.iter().max().map_or(0, |&m| m + 1);
        let inputs_len = batches.iter().map(|b| past(&b.source)).chain([past(&rest_source)]).max().unwrap_or(0);
        Some(Batched { batches, rest, rest_source, places, inputs_len, outputs_len })
    }

    /// Where root `r`'s outputs are in [`eval`](Batched::eval)'s: its first component and
    /// the distance between two.
    pub fn place(&self, r: usize) -> (usize, usize) {
        self.places[r]
    }

    /// How many numbers [`eval`](Batched::eval) writes.
    pub fn output_len(&self) -> usize {
        self.outputs_len
    }

    /// Buffers for [`eval`](Batched::eval).
    pub fn scratch(&self) -> BatchedScratch {
        BatchedScratch {
            inputs: self.batches.iter().map(|b| vec![0.0; b.tape.input_len() * b.members.min(LANES)]).collect(),
            lanes: self.batches.iter().map(|b| b.tape.batch_scratch()).collect(),
            rest_inputs: vec![0.0; self.rest.input_len()],
            rest: self.rest.scratch(),
        }
    }

    /// Every root, from the flat `inputs` (laid out as `source` said), into `out` (of
    /// [`output_len`](Batched::output_len); root r at [`place(r)`](Batched::place)).
    ///
    /// # Panics
    /// If `inputs` is shorter than the layout [`new`](Batched::new) was given, or `out` is
    /// not [`output_len`](Batched::output_len) long.
    pub fn eval(&self, inputs: &[f64], scratch: &mut BatchedScratch, out: &mut [f64]) {
        assert!(inputs.len() >= self.inputs_len, "input length");
        assert_eq!(out.len(), self.outputs_len, "output length");
        let mut out = out;
        for (b, batch) in self.batches.iter().enumerate() {
            let (n_in, n_out) = (batch.tape.input_len(), batch.tape.output_len());
            let mut source = batch.source.as_slice();
            for first in (0..batch.members).step_by(LANES) {
                let len = LANES.min(batch.members - first);
                let lanes = &mut scratch.inputs[b][..n_in * len];
                let (here, rest) = source.split_at(n_in * len);
                for (x, &at) in lanes.iter_mut().zip(here) {
                    // SAFETY: every index of a `source` is below `inputs_len` (asserted).
                    *x = unsafe { *inputs.get_unchecked(at) };
                }
                source = rest;
                let (chunk, rest) = out.split_at_mut(n_out * len);
                batch.tape.eval_batch_serial(len, lanes, &mut scratch.lanes[b], chunk);
                out = rest;
            }
        }
        for (x, &at) in scratch.rest_inputs.iter_mut().zip(&self.rest_source) {
            *x = inputs[at];
        }
        self.rest.eval(&scratch.rest_inputs, &mut scratch.rest, out);
    }
}
