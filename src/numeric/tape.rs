//! Compiled evaluation: expressions → a flat tape of register instructions, run as one loop.
//!
//! [`Tape::compile`] lowers a set of root expressions to the scalar [`Program`] (vectors in
//! components, constants folded, shared subexpressions computed once) and allocates
//! registers for it: inputs first, then constants, then temporaries, which are reused as
//! soon as their last reader has run. Products read by a single sum or negation are fused
//! into it (`a·b + c·d`, `−(a·b)`: same roundings, no FMA), which halves the instruction count
//! of dot products. [`Tape::eval`] then runs one forward loop over the instruction slice —
//! no recursion, no allocation (the registers live in a [`Scratch`]).
//!
//! [`Tape::eval_batch`] evaluates many states at once, stored as structure of arrays
//! (input slot `j` of state `s` at `inputs[j * n + s]`, outputs alike). It runs each
//! instruction over a lane of [`LANES`] states, an inner loop the compiler vectorises, and
//! splits batches of more than [`PARALLEL_MIN`] states over the cores with rayon.
//!
//! Design note: a tape interpreter rather than a JIT. Dispatch costs 1–3 ns an instruction
//! for one state and amortises to almost nothing over a lane of states, where each
//! instruction is a streaming pass over L1 (about a cycle a state); code
//! that must be as fast as handwritten is what `lagrange generate` is for, and it is
//! generated from the same [`Program`], so the two cannot disagree on the lowering.
//!
//! Not here: the lowering itself (`program.rs`), text, files.

use super::program::{LowerError, Op, Program, Val, norm2, norm3};
use crate::expr::eval;
use crate::expr::{Func, Graph, Id, Symbol};
use rayon::prelude::*;
use std::ops::Range;

/// States per lane in batched evaluation: 2 KiB a register, so a dozen live registers fit
/// in L1, and dispatch costs little next to 256 operations (64 measured ~20 % slower).
pub const LANES: usize = 256;
/// Batches smaller than this run on the calling thread.
pub const PARALLEL_MIN: usize = 8192;
/// States per parallel task.
const BLOCK: usize = 2048;

/// Why a tape could not be compiled.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TapeError {
    #[error(transparent)]
    Lower(#[from] LowerError),
}

/// What an instruction computes; operands are register numbers in [`Inst`]. A flat list,
/// so dispatch is one jump table.
///
/// The fused codes are products feeding a sum, `a·b + c·d` and friends: the commonest shape
/// of a lowered dot product. They round exactly as the separate operations do (no FMA), so
/// fusing changes the instruction count, never a result.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Code {
    Add,
    Sub,
    Mul,
    Div,
    Neg,
    /// `a^imm`.
    Powi,
    Powf,
    Sqrt,
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Atan,
    Exp,
    Ln,
    Atan2,
    Norm2,
    Norm3,
    /// `a·b + c·e`.
    MulMulAdd,
    /// `a·b − c·e`.
    MulMulSub,
    /// `a·b + c`.
    MulAdd,
    /// `a·b − c`.
    MulSub,
    /// `a − b·c`.
    SubMul,
    /// `−(a·b)`.
    NegMul,
    /// `−(a/b)`.
    NegDiv,
}

impl Code {
    fn call(f: Func) -> Code {
        match f {
            Func::Sqrt => Code::Sqrt,
            Func::Sin => Code::Sin,
            Func::Cos => Code::Cos,
            Func::Tan => Code::Tan,
            Func::Asin => Code::Asin,
            Func::Acos => Code::Acos,
            Func::Atan => Code::Atan,
            Func::Exp => Code::Exp,
            Func::Ln => Code::Ln,
        }
    }
}

/// `r[d] = code(r[a], r[b], r[c], r[e])`. Unused operands repeat `a`; `d` is never an operand.
#[derive(Clone, Copy, Debug)]
struct Inst {
    code: Code,
    imm: i32,
    d: u32,
    a: u32,
    b: u32,
    c: u32,
    e: u32,
}

/// A compiled set of expressions. Immutable; share it between threads freely.
#[derive(Clone, Debug)]
pub struct Tape {
    code: Vec<Inst>,
    n_inputs: usize,
    /// Values of registers `n_inputs .. n_inputs + consts.len()`.
    consts: Vec<f64>,
    n_regs: usize,
    /// The register of each output component.
    outputs: Vec<u32>,
    output_ranges: Vec<Range<usize>>,
    input_ranges: Vec<Range<usize>>,
}

/// Registers for single-state evaluation; make one with [`Tape::scratch`] and reuse it.
#[derive(Clone, Debug)]
pub struct Scratch {
    regs: Vec<f64>,
}

/// Registers for one lane of batched evaluation; make one with [`Tape::batch_scratch`].
#[derive(Clone, Debug)]
pub struct BatchScratch {
    regs: Vec<f64>,
}

impl Tape {
    /// Compiles `roots` over the input layout `inputs`: symbol `inputs[i]` occupies the slots
    /// [`input_range(i)`](Tape::input_range) (one for a scalar, `dim` for a vector).
    ///
    /// Fails, naming the symbol, when a root uses a symbol that is not an input.
    ///
    /// ```
    /// # use lagrange::model::file::load;
    /// # use lagrange::numeric::tape::Tape;
    /// let mut loaded = load("dimension = 2\n[parameters]\nl = 1.0\n[[bodies]]\nname = \"b\"\n\
    ///     position = \"r\"\nvelocity = \"v\"\nacceleration = \"a\"\nmass = 1.0\nforce = \"F\"\n\
    ///     [[constraints]]\nname = \"c\"\nexpr = \"dot(r, r) = l^2\"").unwrap();
    /// let s = &mut loaded.system;
    /// let c = s.constraints[0].c;
    /// let (r, l) = (s.bodies[0].position, s.graph.symbol_named("l").unwrap());
    /// let tape = Tape::compile(&s.graph, &[c], &[r, l]).unwrap();
    /// let mut out = [0.0];
    /// tape.eval(&[3.0, 4.0, 2.0], &mut tape.scratch(), &mut out);
    /// assert_eq!(out[0], 25.0 - 4.0);
    /// ```
    pub fn compile(graph: &Graph, roots: &[Id], inputs: &[Symbol]) -> Result<Tape, TapeError> {
        let p = Program::lower(graph, roots, inputs)?;
        Ok(Tape::from_program(&p))
    }

    /// Fuses products into the sums that use them, then allocates registers.
    ///
    /// # Panics
    /// If `p` is malformed (an operand used before it is computed, an input slot past
    /// `n_inputs`); programs from [`Program::lower`] never are.
    pub fn from_program(p: &Program) -> Tape {
        let n = p.ops.len();
        let uses = p.use_counts();
        let single_mul = |v: Val| match p.ops[v as usize] {
            Op::Mul(x, y) if uses[v as usize] == 1 => Some((x, y)),
            _ => None,
        };
        // Instructions over values: (value, code, imm, operands). Products read only by one
        // sum are absorbed into it.
        let mut absorbed = vec![false; n];
        let mut virt: Vec<(usize, Code, i32, [Val; 4])> = Vec::with_capacity(n);
        for (i, op) in p.ops.iter().enumerate() {
            let (code, imm, args) = match *op {
                Op::Input(_) | Op::Const(_) => continue,
                Op::Add(a, b) | Op::Sub(a, b) => {
                    let sub = matches!(op, Op::Sub(..));
                    match (single_mul(a), single_mul(b)) {
                        (Some((p, q)), Some((r, t))) => {
                            absorbed[a as usize] = true;
                            absorbed[b as usize] = true;
                            (if sub { Code::MulMulSub } else { Code::MulMulAdd }, 0, [p, q, r, t])
                        }
                        (Some((p, q)), None) => {
                            absorbed[a as usize] = true;
                            (if sub { Code::MulSub } else { Code::MulAdd }, 0, [p, q, b, p])
                        }
                        (None, Some((r, t))) => {
                            absorbed[b as usize] = true;
                            if sub { (Code::SubMul, 0, [a, r, t, a]) } else { (Code::MulAdd, 0, [r, t, a, r]) }
                        }
                        (None, None) => (if sub { Code::Sub } else { Code::Add }, 0, [a, b, a, a]),
                    }
                }
                Op::Mul(a, b) => (Code::Mul, 0, [a, b, a, a]),
                Op::Div(a, b) => (Code::Div, 0, [a, b, a, a]),
                Op::Neg(a) => match (single_mul(a), p.ops[a as usize]) {
                    (Some((x, y)), _) => {
                        absorbed[a as usize] = true;
                        (Code::NegMul, 0, [x, y, x, x])
                    }
                    (None, Op::Div(x, y)) if uses[a as usize] == 1 => {
                        absorbed[a as usize] = true;
                        (Code::NegDiv, 0, [x, y, x, x])
                    }
                    _ => (Code::Neg, 0, [a; 4]),
                },
                Op::Powi(a, k) => (Code::Powi, k, [a; 4]),
                Op::Powf(a, b) => (Code::Powf, 0, [a, b, a, a]),
                Op::Call(f, a) => (Code::call(f), 0, [a; 4]),
                Op::Atan2(a, b) => (Code::Atan2, 0, [a, b, a, a]),
                Op::Norm2(a, b) => (Code::Norm2, 0, [a, b, a, a]),
                Op::Norm3(a, b, c) => (Code::Norm3, 0, [a, b, c, a]),
            };
            virt.push((i, code, imm, args));
        }
        // Sums come after their products, so a product is absorbed before it would be emitted
        // only if we look ahead: drop absorbed products now.
        virt.retain(|(i, ..)| !absorbed[*i]);
        // Last reader of each value; outputs are read at the end.
        let mut last = vec![0usize; n];
        for (k, (_, _, _, args)) in virt.iter().enumerate() {
            for &a in args {
                last[a as usize] = k;
            }
        }
        for &o in &p.outputs {
            last[o as usize] = usize::MAX;
        }
        let mut reg = vec![u32::MAX; n];
        let mut consts = Vec::new();
        for (i, op) in p.ops.iter().enumerate() {
            if let Op::Input(j) = op {
                reg[i] = *j;
            }
        }
        for (i, op) in p.ops.iter().enumerate() {
            if let Some(x) = op.constant() {
                reg[i] = (p.n_inputs + consts.len()) as u32;
                consts.push(x);
            }
        }
        let first_temp = (p.n_inputs + consts.len()) as u32;
        let mut n_regs = first_temp;
        let mut free: Vec<u32> = Vec::new();
        let mut code = Vec::with_capacity(virt.len());
        for (k, &(i, kind, imm, args)) in virt.iter().enumerate() {
            // The destination is taken before the operands are freed, so it is never one of them.
            let d = free.pop().unwrap_or_else(|| {
                n_regs += 1;
                n_regs - 1
            });
            reg[i] = d;
            let [a, b, c, e] = args.map(|v| reg[v as usize]);
            code.push(Inst { code: kind, imm, d, a, b, c, e });
            let mut operands = args;
            operands.sort_unstable();
            for (x, &v) in operands.iter().enumerate() {
                let r = reg[v as usize];
                if last[v as usize] == k && r >= first_temp && (x == 0 || operands[x - 1] != v) {
                    free.push(r);
                }
            }
        }
        // `eval` reads registers without bounds checks: every register number must be below
        // `n_regs`. Lowering guarantees it; a hand-made malformed `Program` stops here.
        let n_regs = n_regs as usize;
        let valid = |k: u32| (k as usize) < n_regs;
        assert!(
            code.iter().all(|i| [i.d, i.a, i.b, i.c, i.e].into_iter().all(valid))
                && p.outputs.iter().all(|&o| valid(reg[o as usize])),
            "malformed program: an operand is not computed before it is used"
        );
        Tape {
            code,
            n_inputs: p.n_inputs,
            consts,
            n_regs,
            outputs: p.outputs.iter().map(|&o| reg[o as usize]).collect(),
            output_ranges: p.output_ranges.clone(),
            input_ranges: p.input_ranges.clone(),
        }
    }

    /// Number of input slots.
    pub fn input_len(&self) -> usize {
        self.n_inputs
    }

    /// Number of output components (all roots).
    pub fn output_len(&self) -> usize {
        self.outputs.len()
    }

    /// The input slots of the `i`-th input symbol.
    pub fn input_range(&self, i: usize) -> Range<usize> {
        self.input_ranges[i].clone()
    }

    /// The output components of the `i`-th root (one for a scalar, `dim` for a vector).
    pub fn output_range(&self, i: usize) -> Range<usize> {
        self.output_ranges[i].clone()
    }

    /// Number of instructions run per state.
    pub fn instructions(&self) -> usize {
        self.code.len()
    }

    /// Registers for [`eval`](Tape::eval).
    pub fn scratch(&self) -> Scratch {
        Scratch { regs: vec![0.0; self.n_regs] }
    }

    /// Registers for the serial part of [`eval_batch`](Tape::eval_batch).
    pub fn batch_scratch(&self) -> BatchScratch {
        BatchScratch { regs: vec![0.0; self.n_regs * LANES] }
    }

    /// Evaluates every root at one state.
    ///
    /// # Panics
    /// If `inputs` is not [`input_len`](Tape::input_len) long, `outputs` not
    /// [`output_len`](Tape::output_len) long, or `scratch` was made by a different tape.
    pub fn eval(&self, inputs: &[f64], scratch: &mut Scratch, outputs: &mut [f64]) {
        assert_eq!(inputs.len(), self.n_inputs, "input length");
        assert_eq!(outputs.len(), self.outputs.len(), "output length");
        assert_eq!(scratch.regs.len(), self.n_regs, "scratch made by another tape");
        let r = scratch.regs.as_mut_slice();
        r[..self.n_inputs].copy_from_slice(inputs);
        r[self.n_inputs..self.n_inputs + self.consts.len()].copy_from_slice(&self.consts);
        for i in &self.code {
            // SAFETY: `from_program` only writes register numbers below `n_regs` into `code`, and
            // `r` has exactly `n_regs` registers (asserted above).
            let reg = |k: u32| unsafe { *r.get_unchecked(k as usize) };
            let (a, b) = (reg(i.a), reg(i.b));
            let x = match i.code {
                Code::Add => a + b,
                Code::Sub => a - b,
                Code::Mul => a * b,
                Code::Div => a / b,
                Code::Neg => -a,
                Code::Powi => a.powi(i.imm),
                Code::Powf => eval::pow(a, b),
                Code::Sqrt => a.sqrt(),
                Code::Sin => a.sin(),
                Code::Cos => a.cos(),
                Code::Tan => a.tan(),
                Code::Asin => a.asin(),
                Code::Acos => a.acos(),
                Code::Atan => a.atan(),
                Code::Exp => a.exp(),
                Code::Ln => a.ln(),
                Code::Atan2 => a.atan2(b),
                Code::Norm2 => norm2(a, b),
                Code::Norm3 => norm3(a, b, reg(i.c)),
                Code::MulMulAdd => a * b + reg(i.c) * reg(i.e),
                Code::MulMulSub => a * b - reg(i.c) * reg(i.e),
                Code::MulAdd => a * b + reg(i.c),
                Code::MulSub => a * b - reg(i.c),
                Code::SubMul => a - b * reg(i.c),
                Code::NegMul => -(a * b),
                Code::NegDiv => -(a / b),
            };
            // SAFETY: as above.
            unsafe { *r.get_unchecked_mut(i.d as usize) = x };
        }
        for (o, &reg) in outputs.iter_mut().zip(&self.outputs) {
            *o = r[reg as usize];
        }
    }

    /// Evaluates every root at `n` states stored as structure of arrays: input slot `j` of
    /// state `s` is `inputs[j * n + s]`, output component `k` of state `s` goes to
    /// `outputs[k * n + s]`. Batches of [`PARALLEL_MIN`] states or more run in parallel;
    /// that path allocates once per call (task bookkeeping and a register file per worker),
    /// the serial path never does.
    ///
    /// # Panics
    /// If the slices are not `n` times [`input_len`](Tape::input_len) and
    /// [`output_len`](Tape::output_len) long, or `scratch` was made by a different tape.
    pub fn eval_batch(&self, n: usize, inputs: &[f64], scratch: &mut BatchScratch, outputs: &mut [f64]) {
        assert_eq!(inputs.len(), self.n_inputs * n, "input length");
        assert_eq!(outputs.len(), self.outputs.len() * n, "output length");
        assert_eq!(scratch.regs.len(), self.n_regs * LANES, "scratch made by another tape");
        if n == 0 {
            return;
        }
        if n < PARALLEL_MIN || rayon::current_num_threads() < 2 {
            self.run_range(&mut scratch.regs, inputs, n, 0..n, |k, at, lane| {
                outputs[k * n + at..k * n + at + lane.len()].copy_from_slice(lane);
            });
            return;
        }
        // Each task owns, for every output, the piece of its row that holds its block of states.
        let blocks = n.div_ceil(BLOCK);
        let mut pieces: Vec<Vec<&mut [f64]>> = (0..blocks).map(|_| Vec::with_capacity(self.outputs.len())).collect();
        for row in outputs.chunks_mut(n) {
            for (block, piece) in row.chunks_mut(BLOCK).enumerate() {
                pieces[block].push(piece);
            }
        }
        pieces.into_par_iter().enumerate().for_each_init(
            || vec![0.0; self.n_regs * LANES],
            |regs, (block, mut rows)| {
                let start = block * BLOCK;
                let end = (start + BLOCK).min(n);
                self.run_range(regs, inputs, n, start..end, |k, at, lane| {
                    rows[k][at - start..at - start + lane.len()].copy_from_slice(lane);
                });
            },
        );
    }

    /// Runs the states `range` lane by lane; `store(k, s, values)` receives output `k` of
    /// the states `s..s + values.len()`.
    fn run_range(
        &self,
        regs: &mut [f64],
        inputs: &[f64],
        n: usize,
        range: Range<usize>,
        mut store: impl FnMut(usize, usize, &[f64]),
    ) {
        let mut s = range.start;
        while s < range.end {
            let len = LANES.min(range.end - s);
            // Inputs are read where they are (rows of `inputs`), not copied into registers.
            for (k, &x) in self.consts.iter().enumerate() {
                let r = (self.n_inputs + k) * LANES;
                regs[r..r + len].fill(x);
            }
            self.run_lane(regs, Rows { inputs, n, start: s, count: self.n_inputs }, len);
            for (k, &reg) in self.outputs.iter().enumerate() {
                let r = reg as usize;
                // An output may be an input itself (the direction of `r·r` is `r`).
                let lane = if r < self.n_inputs {
                    &inputs[r * n + s..r * n + s + len]
                } else {
                    &regs[r * LANES..r * LANES + len]
                };
                store(k, s, lane);
            }
            s += len;
        }
    }

    /// One pass of the tape over `len` states: input registers read from `rows`, the others
    /// held in `regs` (register `k` at `k * LANES`).
    fn run_lane(&self, regs: &mut [f64], rows: Rows<'_>, len: usize) {
        for i in &self.code {
            let (out, [a, b, c, e]) = lanes(regs, rows, i, len);
            match i.code {
                Code::Add => zip2(out, a, b, |x, y| x + y),
                Code::Sub => zip2(out, a, b, |x, y| x - y),
                Code::Mul => zip2(out, a, b, |x, y| x * y),
                Code::Div => zip2(out, a, b, |x, y| x / y),
                Code::Neg => zip1(out, a, |x| -x),
                Code::Powi => zip1(out, a, |x| x.powi(i.imm)),
                Code::Powf => zip2(out, a, b, eval::pow),
                Code::Sqrt => zip1(out, a, f64::sqrt),
                Code::Sin => zip1(out, a, f64::sin),
                Code::Cos => zip1(out, a, f64::cos),
                Code::Tan => zip1(out, a, f64::tan),
                Code::Asin => zip1(out, a, f64::asin),
                Code::Acos => zip1(out, a, f64::acos),
                Code::Atan => zip1(out, a, f64::atan),
                Code::Exp => zip1(out, a, f64::exp),
                Code::Ln => zip1(out, a, f64::ln),
                Code::Atan2 => zip2(out, a, b, f64::atan2),
                Code::MulMulAdd => zip4(out, a, b, c, e, |w, x, y, z| w * x + y * z),
                Code::MulMulSub => zip4(out, a, b, c, e, |w, x, y, z| w * x - y * z),
                Code::MulAdd => zip3(out, a, b, c, |x, y, z| x * y + z),
                Code::MulSub => zip3(out, a, b, c, |x, y, z| x * y - z),
                Code::SubMul => zip3(out, a, b, c, |x, y, z| x - y * z),
                Code::NegMul => zip2(out, a, b, |x, y| -(x * y)),
                Code::NegDiv => zip2(out, a, b, |x, y| -(x / y)),
                Code::Norm2 => {
                    // Plain formula over the lane (vectorised), then the rare overflow cases again.
                    zip2(out, a, b, |x, y| (x * x + y * y).sqrt());
                    for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
                        if !(o.is_finite() && *o >= 1e-150) {
                            *o = norm2(x, y);
                        }
                    }
                }
                Code::Norm3 => {
                    zip3(out, a, b, c, |x, y, z| (x * x + y * y + z * z).sqrt());
                    for (((o, &x), &y), &z) in out.iter_mut().zip(a).zip(b).zip(c) {
                        if !(o.is_finite() && *o >= 1e-150) {
                            *o = norm3(x, y, z);
                        }
                    }
                }
            }
        }
    }
}

/// Where the input registers of a lane are: slot `k` of the states `start..` is
/// `inputs[k * n + start..]`.
#[derive(Clone, Copy)]
struct Rows<'a> {
    inputs: &'a [f64],
    n: usize,
    start: usize,
    count: usize,
}

/// The destination lane of `i` (mutable) and its four operand lanes.
fn lanes<'r>(regs: &'r mut [f64], rows: Rows<'r>, i: &Inst, len: usize) -> (&'r mut [f64], [&'r [f64]; 4]) {
    let d = i.d as usize;
    let (below, rest) = regs.split_at_mut(d * LANES);
    let (out, above) = rest.split_at_mut(LANES);
    let (below, above): (&[f64], &[f64]) = (below, above);
    // `d` is never an operand (see `Inst`), so every operand lies below or above it.
    let get = |k: u32| {
        let k = k as usize;
        if k < rows.count {
            &rows.inputs[k * rows.n + rows.start..k * rows.n + rows.start + len]
        } else if k < d {
            &below[k * LANES..k * LANES + len]
        } else {
            &above[(k - d - 1) * LANES..(k - d - 1) * LANES + len]
        }
    };
    (&mut out[..len], [get(i.a), get(i.b), get(i.c), get(i.e)])
}

#[inline(always)]
fn zip1(out: &mut [f64], a: &[f64], f: impl Fn(f64) -> f64) {
    for (o, &x) in out.iter_mut().zip(a) {
        *o = f(x);
    }
}

#[inline(always)]
fn zip2(out: &mut [f64], a: &[f64], b: &[f64], f: impl Fn(f64, f64) -> f64) {
    for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
        *o = f(x, y);
    }
}

#[inline(always)]
fn zip3(out: &mut [f64], a: &[f64], b: &[f64], c: &[f64], f: impl Fn(f64, f64, f64) -> f64) {
    for (((o, &x), &y), &z) in out.iter_mut().zip(a).zip(b).zip(c) {
        *o = f(x, y, z);
    }
}

#[inline(always)]
fn zip4(out: &mut [f64], a: &[f64], b: &[f64], c: &[f64], d: &[f64], f: impl Fn(f64, f64, f64, f64) -> f64) {
    for ((((o, &w), &x), &y), &z) in out.iter_mut().zip(a).zip(b).zip(c).zip(d) {
        *o = f(w, x, y, z);
    }
}
