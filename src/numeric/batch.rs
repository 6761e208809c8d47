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
use crate::expr::graph::SymbolWalk;
use crate::expr::shape::Shaper;
use crate::expr::{Graph, Id, Symbol, Ty};
use std::collections::HashMap;
use std::ops::Range;

/// Units of one shape are batched when there are at least this many: below, one tape of
/// them costs about what a batch does, and a batch's register file (lanes of
/// `tape::LANES` values per register) would be mostly idle.
pub const BATCH_MIN: usize = 4;

/// Roots evaluated shape by shape, into the places a caller's output layout gives them.
#[derive(Clone, Debug)]
pub struct Batched {
    batches: Vec<Batch>,
    /// The units in no batch, on one tape over their own symbols, and where each of its
    /// input slots is in the caller's flat inputs.
    rest: Tape,
    rest_source: Vec<usize>,
    /// Where each of `rest`'s output components goes.
    rest_dest: Vec<usize>,
    /// One past the largest index of any `source` and any `dest`: the least lengths of the
    /// caller's inputs and outputs, checked once per evaluation so the gathers and
    /// scatters need no check per number.
    inputs_len: usize,
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
    /// Where each member's output components go, laid out as `source`.
    dest: Vec<usize>,
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

/// Buffers of [`Batched::eval`], reused across evaluations.
#[derive(Clone, Debug)]
pub struct BatchedScratch {
    /// Per batch: inputs and outputs in structure of arrays, and the lanes' registers.
    inputs: Vec<Vec<f64>>,
    outputs: Vec<Vec<f64>>,
    lanes: Vec<BatchScratch>,
    rest_inputs: Vec<f64>,
    rest_outputs: Vec<f64>,
    rest: Scratch,
}

impl Batched {
    /// Batches the `units` of `roots` (each a list of indices into `roots`); the output
    /// components of root r go to `dest(r)` (as many as the root has), and the inputs
    /// are read from a flat buffer where symbol s occupies `source(s)` (a tape's input
    /// layout over every symbol the roots read). `None` when no shape has [`BATCH_MIN`]
    /// units: one tape serves as well.
    pub fn new(
        graph: &Graph,
        roots: &[Id],
        units: &[Vec<usize>],
        dest: impl Fn(usize) -> Range<usize>,
        source: impl Fn(Symbol) -> Range<usize>,
    ) -> Option<Batched> {
        let mut shaper = Shaper::default();
        let mut walk = SymbolWalk::default();
        // Units by shape, in order of first appearance (deterministic batches).
        let mut by_key: HashMap<Vec<u32>, usize> = HashMap::new();
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
        for group in &groups {
            if group.len() < BATCH_MIN {
                rest_roots.extend(group.iter().flat_map(|(u, _)| units[*u].iter().copied()));
                continue;
            }
            let (first, template) = &group[0];
            let ids: Vec<Id> = units[*first].iter().map(|&r| roots[r]).collect();
            let inputs = walk.free_symbols_of(graph, &ids).to_vec();
            // The roots' free symbols are the inputs, so lowering cannot fail.
            let tape = Tape::compile(graph, &ids, &inputs).expect("the inputs are the roots' free symbols");
            let renamed =
                |theirs: &[Symbol], sym: &Symbol| template.iter().position(|t| t == sym).map_or(*sym, |p| theirs[p]);
            // Every member reads and writes as many numbers as the template: a guard, as the
            // types are in the key.
            let (group, odd): (Vec<_>, Vec<_>) = group.iter().partition(|(u, theirs)| {
                inputs
                    .iter()
                    .enumerate()
                    .all(|(i, sym)| source(renamed(theirs, sym)).len() == tape.input_range(i).len())
                    && units[*u].iter().enumerate().all(|(j, &r)| dest(r).len() == tape.output_range(j).len())
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
                for (i, sym) in inputs.iter().enumerate() {
                    for (j, at) in tape.input_range(i).zip(source(renamed(theirs, sym))) {
                        from[j * members + s] = at;
                    }
                }
            }
            let mut out = vec![0; tape.output_len() * members];
            for (s, (u, _)) in group.iter().enumerate() {
                for (j, &r) in units[*u].iter().enumerate() {
                    let range = tape.output_range(j);
                    for (k, c) in range.clone().enumerate() {
                        out[c * members + s] = dest(r).start + k;
                    }
                }
            }
            // Chunk by chunk of `LANES` members (`chunked`), so a chunk's inputs, lanes and
            // outputs stay in cache from gather to scatter.
            let (source, dest) = (chunked(&from, members), chunked(&out, members));
            batches.push(Batch { tape, members, source, dest });
        }
        let ids: Vec<Id> = rest_roots.iter().map(|&r| roots[r]).collect();
        let rest_inputs = walk.free_symbols_of(graph, &ids).to_vec();
        let rest = Tape::compile(graph, &ids, &rest_inputs).expect("the inputs are the roots' free symbols");
        let mut rest_source = vec![0; rest.input_len()];
        for (i, &sym) in rest_inputs.iter().enumerate() {
            for (j, at) in rest.input_range(i).zip(source(sym)) {
                rest_source[j] = at;
            }
        }
        let mut rest_dest = vec![0; rest.output_len()];
        for (j, &r) in rest_roots.iter().enumerate() {
            for (k, c) in rest.output_range(j).enumerate() {
                rest_dest[c] = dest(r).start + k;
            }
        }
        let past = |table: &[usize]| table.iter().max().map_or(0, |&m| m + 1);
        let inputs_len = batches.iter().map(|b| past(&b.source)).chain([past(&rest_source)]).max().unwrap_or(0);
        let outputs_len = batches.iter().map(|b| past(&b.dest)).chain([past(&rest_dest)]).max().unwrap_or(0);
        Some(Batched { batches, rest, rest_source, rest_dest, inputs_len, outputs_len })
    }

    /// Buffers for [`eval`](Batched::eval).
    pub fn scratch(&self) -> BatchedScratch {
        BatchedScratch {
            inputs: self.batches.iter().map(|b| vec![0.0; b.tape.input_len() * b.members.min(LANES)]).collect(),
            outputs: self.batches.iter().map(|b| vec![0.0; b.tape.output_len() * b.members.min(LANES)]).collect(),
            lanes: self.batches.iter().map(|b| b.tape.batch_scratch()).collect(),
            rest_inputs: vec![0.0; self.rest.input_len()],
            rest_outputs: vec![0.0; self.rest.output_len()],
            rest: self.rest.scratch(),
        }
    }

    /// Every root, from the flat `inputs` (laid out as `source` said), each written to its
    /// place in `out`.
    ///
    /// # Panics
    /// If `inputs` or `out` is shorter than the layouts [`new`](Batched::new) was given.
    pub fn eval(&self, inputs: &[f64], scratch: &mut BatchedScratch, out: &mut [f64]) {
        assert!(inputs.len() >= self.inputs_len, "input length");
        assert!(out.len() >= self.outputs_len, "output length");
        for (b, batch) in self.batches.iter().enumerate() {
            let (n_in, n_out) = (batch.tape.input_len(), batch.tape.output_len());
            let (mut source, mut dest) = (batch.source.as_slice(), batch.dest.as_slice());
            for first in (0..batch.members).step_by(LANES) {
                let len = LANES.min(batch.members - first);
                let (lanes, outputs) = (&mut scratch.inputs[b][..n_in * len], &mut scratch.outputs[b][..n_out * len]);
                let (here, rest) = source.split_at(n_in * len);
                for (x, &at) in lanes.iter_mut().zip(here) {
                    // SAFETY: every index of a `source` is below `inputs_len` (asserted).
                    *x = unsafe { *inputs.get_unchecked(at) };
                }
                source = rest;
                batch.tape.eval_batch_serial(len, lanes, &mut scratch.lanes[b], outputs);
                let (here, rest) = dest.split_at(n_out * len);
                for (&d, &x) in here.iter().zip(outputs.iter()) {
                    // SAFETY: every index of a `dest` is below `outputs_len` (asserted).
                    unsafe { *out.get_unchecked_mut(d) = x };
                }
                dest = rest;
            }
        }
        for (x, &at) in scratch.rest_inputs.iter_mut().zip(&self.rest_source) {
            *x = inputs[at];
        }
        self.rest.eval(&scratch.rest_inputs, &mut scratch.rest, &mut scratch.rest_outputs);
        for (&d, &x) in self.rest_dest.iter().zip(&scratch.rest_outputs) {
            out[d] = x;
        }
    }
}
