//! Compiled evaluation: expressions → a flat tape of register instructions, run as one loop.
//!
//! [`Tape::compile`] lowers a set of root expressions to the scalar [`Program`] (vectors in
//! components, constants folded, shared subexpressions computed once) and allocates
//! registers for it: inputs first, then constants, then temporaries, which are reused as
//! soon as their last reader has run. Products read by a single sum or negation are fused
//! into it (`a·b + c·d`, `−(a·b)`: same roundings, no FMA), which halves the instruction count
//! of dot products. Before registers are allocated, a value read by one instruction only is
//! moved to just before its reader, the operand with the longest chain of operations last
//! (`tree_order`: the same operations in another order).
//!
//! [`Tape::eval`] runs its own form of the instructions (`steps`), one forward loop —
//! no recursion, no allocation (the registers live in a [`Scratch`], which keeps the
//! constants between calls). Per state, time goes to dispatch and to chains of dependent
//! operations, so the steps cut both: two independent sums, differences or products of
//! adjacent instructions are one step, and an operand that is the previous step's result is
//! read from the accumulator, a local the compiler keeps in a machine register, rather
//! than through a store and a load (each result is still stored for later readers). The
//! sequences of steps frequent in row tapes (a chain's `d·d`, `−(dₖ·dₖ₊₁)/m`, joint rows'
//! alternating multiply-adds, a dot product of three terms, a vector scaled by the previous
//! result as a force is λ ∇C) are merged into superinstructions, one dispatch each. A step's
//! register numbers are read two at a time (one load for two). A tape of at most
//! `IN_PLACE_MAX` input slots reads its inputs where the caller has them rather than
//! copying them into the registers first: the copy is a fixed cost of every call, large
//! beside a short tape's few steps. The steps perform the instructions' operations on the
//! same operands in the same order (a commutative one may take them swapped): results are
//! bitwise those of the lanes below.
//!
//! [`Tape::eval_batch`] evaluates many states at once, stored as structure of arrays
//! (input slot `j` of state `s` at `inputs[j * n + s]`, outputs alike). It runs each
//! instruction over a lane of up to [`LANES`] states, an inner loop the compiler vectorises
//! (with AVX2 when the processor has it, chosen at run time), and splits batches of more
//! than [`PARALLEL_MIN`] states over the cores with rayon. Memory traffic is what a lane
//! costs, so: inputs are read in place and outputs written in place (never copied through
//! registers), and squares read their operand once (`x·x + y·y`).
//!
//! Design note: a tape interpreter rather than a JIT. Dispatch costs 1–3 ns an instruction
//! for one state and amortises to almost nothing over a lane of states, where each
//! instruction is a streaming pass over L1 (about a cycle a state); code
//! that must be as fast as handwritten is what `lagrange generate` is for, and it is
//! generated from the same [`Program`], so the two cannot disagree on the lowering.
//!
//! Not here: the lowering itself (`program.rs`), text, files.

use super::program::{Inputs, LowerError, Op, Program, Val, norm2, norm3};
use crate::expr::eval;
use crate::expr::{Func, Graph, Id, Symbol};
use rayon::prelude::*;
use std::ops::Range;

/// States per lane in batched evaluation: 2 KiB a register, and dispatch costs little next
/// to 256 operations. (Narrower lanes that keep a big tape's register file in L1 were
/// measured: a 10-link chain's A and b, 60 live temporaries, ran no faster at 32 lanes.)
pub const LANES: usize = 256;
/// Single-state evaluation reads the inputs in place (rather than copying them into the
/// registers first) for tapes of at most this many input slots: the copy is a fixed cost of
/// every call, large beside a short tape's few steps.
const IN_PLACE_MAX: usize = 16;
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
pub(crate) enum Code {
    Add,
    Sub,
    Mul,
    Div,
    Neg,
    /// `a^imm`.
    Powi,
    Powf,
    /// `sqrt(a)`: the one function with a machine instruction (and the commonest, from
    /// norms and half powers), so it gets its own code and vectorises in lanes.
    Sqrt,
    /// `f(a, b)`, a function of the table ([`Func::apply`]; `b` is read by binary ones).
    Call(Func),
    Norm2,
    Norm3,
    /// `a·a`.
    Sq,
    /// `a·a + c·c` (a vector's squared length, `d·d` in 2D).
    SqAddSq,
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

/// `r[d] = code(r[a], r[b], r[c], r[e])`. Unused operands repeat `a`; `d` is never an operand.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Inst {
    pub(crate) code: Code,
    pub(crate) imm: i32,
    pub(crate) d: u32,
    pub(crate) a: u32,
    pub(crate) b: u32,
    pub(crate) c: u32,
    pub(crate) e: u32,
}

/// What a single-state [`Step`] computes. `A`, `B`, `C` variants read that operand from the
/// accumulator — the previous step's result, still in a machine register — instead of the
/// register file: a chain of dependent steps then waits for each operation, not for each
/// operation and a store-to-load round trip through memory. The `2` variants are two
/// independent operations of one kind in one dispatch. One flat `u8` list: one jump table,
/// no payload to decode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
enum S {
    Add,
    AddA,
    Sub,
    SubA,
    SubB,
    Mul,
    MulA,
    Div,
    DivA,
    DivB,
    Neg,
    NegA,
    Powi,
    PowiA,
    Powf,
    Sqrt,
    SqrtA,
    Call,
    Norm2,
    Norm3,
    Sq,
    SqA,
    SqAddSq,
    SqAddSqA,
    MulMulAdd,
    MulMulAddA,
    MulMulSub,
    MulMulSubA,
    MulAdd,
    MulAddA,
    MulAddC,
    MulSub,
    MulSubA,
    SubMul,
    SubMulA,
    SubMulB,
    NegMul,
    NegMulA,
    NegDiv,
    NegDivA,
    NegDivB,
    /// `r[d2] = a + b`, then `r[d] = c + e`.
    Add2,
    /// `r[d2] = a − b`, then `r[d] = c − e`.
    Sub2,
    /// `r[d2] = a·b`, then `r[d] = c·e`.
    Mul2,
    /// `r[d2] = a·a + b·b`, then `r[d] = c·c + e·e` (two squared lengths).
    SqAddSq2,
    // Superinstructions: two or three steps that follow each other often in row tapes, the
    // later ones reading the earlier's result as their accumulator. Each part is computed
    // and stored in turn, as the separate steps would.
    /// `MulA`, `MulA`: `r[d2] = acc·b`, then `r[d] = r[d2]·c`.
    MulAMulA,
    /// `MulMulAdd`, `NegMulA`: `r[d2] = a·b + c·e`, then `r[d] = −(r[d2]·g)`.
    MulMulAddNegMulA,
    /// `MulMulAddA`, `NegMulA`: `r[d2] = acc·b + c·e`, then `r[d] = −(r[d2]·g)`.
    MulMulAddANegMulA,
    /// `Sub2`, `SqAddSqA` (the two differences squared): `r[d3] = a − b`, `r[d2] = c − e`,
    /// then `r[d] = r[d2]·r[d2] + r[d3]·r[d3]`.
    Sub2SqAddSqA,
    /// `MulMulAddA`, `MulAddC`, `MulA`: `r[d3] = acc·b + c·e`, `r[d2] = g·h + r[d3]`, then
    /// `r[d] = r[d2]·k`.
    MulMulAddAMulAddCMulA,
    /// `SubMulA`, `MulAddC`: `r[d2] = acc − b·c`, then `r[d] = g·h + r[d2]`.
    SubMulAMulAddC,
    /// `MulAddC`, `SubMulA`: `r[d2] = a·b + acc`, then `r[d] = r[d2] − g·h`.
    MulAddCSubMulA,
    /// `MulMulAdd`, `MulAddC` (a dot product of three terms): `r[d2] = a·b + c·e`, then
    /// `r[d] = g·h + r[d2]`.
    MulMulAddMulAddC,
    /// `MulMulAddA`, `MulAddC`: `r[d2] = acc·b + c·e`, then `r[d] = g·h + r[d2]`.
    MulMulAddAMulAddC,
    /// `MulA` and a product of the same accumulator (a vector scaled by the previous
    /// result, as a force is λ times a gradient): `r[d2] = acc·b`, then `r[d] = acc·c`.
    MulA2,
    /// `NegMulA` and a negated product of the same accumulator: `r[d2] = −(acc·b)`, then
    /// `r[d] = −(acc·c)`.
    NegMulA2,
    // Superinstructions that run on into the next slot: its step (a `Sub2`, with its own
    // operands and results) follows in the same dispatch, after this one's stores.
    /// `Sub2`, then the next slot's `Sub2` (four differences: a chain's links).
    Sub2Sub2,
    /// `Sub2SqAddSqA`, then the next slot's `Sub2` (a chain's row: ḋ, c = ḋ·ḋ, then a J).
    Sub2SqAddSqASub2,
}

/// One instruction of single-state evaluation: `r[d] = op(a, b, c, e)` (operands as in
/// [`Inst`], or the accumulator where `op` says so), and the result becomes the accumulator.
#[derive(Clone, Copy, Debug)]
struct Step {
    op: S,
    /// The function of `S::Call`.
    f: Func,
    imm: i32,
    d: u32,
    a: u32,
    b: u32,
    c: u32,
    e: u32,
    /// The first result of a `2` step, the second-last of a superinstruction; `d` otherwise.
    d2: u32,
    /// The first result of a three-part superinstruction; `d` otherwise.
    d3: u32,
    /// Operands of a superinstruction's later parts; `a` otherwise.
    g: u32,
    h: u32,
    k: u32,
}

/// A [`Step`] as [`Tape::eval`] reads it: register numbers in pairs, each pair one load
/// (single-state evaluation issues more loads than anything else: a step's register numbers,
/// then its operands).
#[derive(Clone, Copy, Debug)]
struct Packed {
    op: S,
    f: Func,
    imm: i32,
    d: u32,
    k: u32,
    /// `a` in the low half, `b` in the high half; and so on.
    ab: u64,
    ce: u64,
    gh: u64,
    d23: u64,
}

impl From<&Step> for Packed {
    fn from(s: &Step) -> Packed {
        let pair = |lo: u32, hi: u32| u64::from(lo) | (u64::from(hi) << 32);
        // A square sum reads `a` and `c` only: both in one pair, one load.
        let (ab, ce) = match s.op {
            S::SqAddSq | S::SqAddSqA => (pair(s.a, s.c), pair(s.c, s.e)),
            _ => (pair(s.a, s.b), pair(s.c, s.e)),
        };
        Packed { op: s.op, f: s.f, imm: s.imm, d: s.d, k: s.k, ab, ce, gh: pair(s.g, s.h), d23: pair(s.d2, s.d3) }
    }
}

/// The single-state steps of `code`: adjacent independent sums, differences and products
/// paired, then each operand that is the previous step's result read from the accumulator.
/// Operations are those of `code`, operand for operand, except that an accumulator operand
/// of a commutative operation may be swapped into the first place (`x + y` and `y + x` are
/// the same number, bit for bit; only which NaN payload is returned may differ, which Rust
/// leaves unspecified).
fn steps(code: &[Inst]) -> Vec<Step> {
    // `i` and `j` both read `prev`'s result.
    let scale2 = |prev: &Inst, i: &Inst, j: &Inst| [i.a, i.b].contains(&prev.d) && [j.a, j.b].contains(&prev.d);
    let plain = |i: &Inst| {
        let (op, f) = match i.code {
            Code::Add => (S::Add, Func::Sqrt),
            Code::Sub => (S::Sub, Func::Sqrt),
            Code::Mul => (S::Mul, Func::Sqrt),
            Code::Div => (S::Div, Func::Sqrt),
            Code::Neg => (S::Neg, Func::Sqrt),
            Code::Powi => (S::Powi, Func::Sqrt),
            Code::Powf => (S::Powf, Func::Sqrt),
            Code::Sqrt => (S::Sqrt, Func::Sqrt),
            Code::Call(f) => (S::Call, f),
            Code::Norm2 => (S::Norm2, Func::Sqrt),
            Code::Norm3 => (S::Norm3, Func::Sqrt),
            Code::Sq => (S::Sq, Func::Sqrt),
            Code::SqAddSq => (S::SqAddSq, Func::Sqrt),
            Code::MulMulAdd => (S::MulMulAdd, Func::Sqrt),
            Code::MulMulSub => (S::MulMulSub, Func::Sqrt),
            Code::MulAdd => (S::MulAdd, Func::Sqrt),
            Code::MulSub => (S::MulSub, Func::Sqrt),
            Code::SubMul => (S::SubMul, Func::Sqrt),
            Code::NegMul => (S::NegMul, Func::Sqrt),
            Code::NegDiv => (S::NegDiv, Func::Sqrt),
        };
        Step { op, f, imm: i.imm, d: i.d, a: i.a, b: i.b, c: i.c, e: i.e, d2: i.d, d3: i.d, g: i.a, h: i.a, k: i.a }
    };
    let mut out: Vec<Step> = Vec::with_capacity(code.len());
    let mut k = 0;
    while k < code.len() {
        let (i, j) = (code[k], code.get(k + 1));
        let pair = match (i.code, j) {
            (Code::Add, Some(j)) if j.code == Code::Add => Some((S::Add2, j)),
            (Code::Sub, Some(j)) if j.code == Code::Sub => Some((S::Sub2, j)),
            // Two products of the previous result stay apart: as `MulA2` (below, `fuse`) both
            // read it from the accumulator.
            (Code::Mul, Some(j)) if j.code == Code::Mul && !(k > 0 && scale2(&code[k - 1], &i, j)) => {
                Some((S::Mul2, j))
            }
            (Code::SqAddSq, Some(j)) if j.code == Code::SqAddSq => Some((S::SqAddSq2, j)),
            _ => None,
        };
        // The second operands of a square sum are its `c` (its `b` and `e` repeat `a`, `c`).
        let second = |x: &Inst| if x.code == Code::SqAddSq { x.c } else { x.b };
        // The second must not read the first's result: both are computed before either is
        // stored.
        match pair {
            Some((op, j)) if j.a != i.d && second(j) != i.d => {
                out.push(Step {
                    op,
                    f: Func::Sqrt,
                    imm: 0,
                    d: j.d,
                    a: i.a,
                    b: second(&i),
                    c: j.a,
                    e: second(j),
                    d2: i.d,
                    d3: j.d,
                    g: i.a,
                    h: i.a,
                    k: i.a,
                });
                k += 2;
            }
            _ => {
                out.push(plain(&i));
                k += 1;
            }
        }
    }
    // The accumulator holds the previous step's result, stored at its `d`.
    for k in 1..out.len() {
        let acc = out[k - 1].d;
        let s = &mut out[k];
        let op = s.op;
        let (a, b, c, e) = (s.a == acc, s.b == acc, s.c == acc, s.e == acc);
        let swap_ab = |s: &mut Step| std::mem::swap(&mut s.a, &mut s.b);
        s.op = match op {
            // A commutative first pair (a + b, a·b, −a·b, a·b ± …): the accumulator goes to `a`.
            S::Add | S::Mul | S::NegMul | S::MulMulSub | S::MulAdd | S::MulSub if a || b => {
                if !a {
                    swap_ab(s);
                }
                match op {
                    S::Add => S::AddA,
                    S::Mul => S::MulA,
                    S::NegMul => S::NegMulA,
                    S::MulMulSub => S::MulMulSubA,
                    S::MulAdd => S::MulAddA,
                    _ => S::MulSubA,
                }
            }
            S::Sub if a => S::SubA,
            S::Sub if b => S::SubB,
            S::Div if a => S::DivA,
            S::Div if b => S::DivB,
            S::NegDiv if a => S::NegDivA,
            S::NegDiv if b => S::NegDivB,
            S::Neg if a => S::NegA,
            S::Powi if a => S::PowiA,
            S::Sqrt if a => S::SqrtA,
            S::Sq if a => S::SqA,
            S::SqAddSq if a || c => {
                if !a {
                    std::mem::swap(&mut s.a, &mut s.c);
                    s.b = s.a;
                    s.e = s.c;
                }
                S::SqAddSqA
            }
            S::MulMulAdd if a || b || c || e => {
                if !(a || b) {
                    std::mem::swap(&mut s.a, &mut s.c);
                    std::mem::swap(&mut s.b, &mut s.e);
                }
                if s.a != acc {
                    swap_ab(s);
                }
                S::MulMulAddA
            }
            S::MulAdd if c => S::MulAddC,
            S::SubMul if a => S::SubMulA,
            S::SubMul if b || c => {
                if !b {
                    std::mem::swap(&mut s.b, &mut s.c);
                }
                S::SubMulB
            }
            op => op,
        };
    }
    fuse(out)
}

/// `steps` with the frequent sequences of row tapes merged into superinstructions: one
/// dispatch for two or three steps. Each part still reads its operands and stores its result
/// in turn, so the operations, their operands and their order are those of the steps merged.
fn fuse(steps: Vec<Step>) -> Vec<Step> {
    let mut out = Vec::with_capacity(steps.len());
    let mut k = 0;
    while k < steps.len() {
        let s = steps[k];
        let (t, u) = (steps.get(k + 1), steps.get(k + 2));
        let ops = (s.op, t.map(|t| t.op), u.map(|u| u.op));
        // The two that run on into the next slot push their own step here and leave the
        // `Sub2` they run on into as the next slot's step (pushed below). Two differences
        // before a square sum are left to pair with it (`Sub2SqAddSqASub2`).
        let (step, n) = match (ops, t, u) {
            ((S::Sub2, Some(S::SqAddSqA), Some(S::Sub2)), Some(t), Some(u)) if t.c == s.d2 => {
                out.push(Step { op: S::Sub2SqAddSqASub2, d3: s.d2, d2: s.d, d: t.d, ..s });
                (*u, 3)
            }
            ((S::Sub2, Some(S::Sub2), u), Some(t), _) if u != Some(S::SqAddSqA) => {
                out.push(Step { op: S::Sub2Sub2, ..s });
                (*t, 2)
            }
            ((S::MulMulAddA, Some(S::MulAddC), Some(S::MulA)), Some(t), Some(u)) => {
                let op = S::MulMulAddAMulAddCMulA;
                (Step { op, d3: s.d, d2: t.d, d: u.d, g: t.a, h: t.b, k: u.b, ..s }, 3)
            }
            ((S::MulA, Some(S::MulA), _), Some(t), _) => (Step { op: S::MulAMulA, d2: s.d, d: t.d, c: t.b, ..s }, 2),
            // The second product reads the accumulator `s` read (its `a`, the result of the
            // step before; `s.d` is never an operand of `s`, so that register still holds
            // it), not `s`'s own result.
            ((S::MulA, Some(S::Mul), _) | (S::NegMulA, Some(S::NegMul), _), Some(t), _)
                if t.a != s.d && t.b != s.d && (t.a == s.a || t.b == s.a) =>
            {
                let op = if s.op == S::MulA { S::MulA2 } else { S::NegMulA2 };
                // A product commutes: the other operand of `t` goes to `c`.
                let c = if t.a == s.a { t.b } else { t.a };
                (Step { op, d2: s.d, d: t.d, c, ..s }, 2)
            }
            ((S::MulMulAdd | S::MulMulAddA, Some(S::MulAddC), _), Some(t), _) => {
                let op = if s.op == S::MulMulAdd { S::MulMulAddMulAddC } else { S::MulMulAddAMulAddC };
                (Step { op, d2: s.d, d: t.d, g: t.a, h: t.b, ..s }, 2)
            }
            ((S::MulMulAdd | S::MulMulAddA, Some(S::NegMulA), _), Some(t), _) => {
                let op = if s.op == S::MulMulAdd { S::MulMulAddNegMulA } else { S::MulMulAddANegMulA };
                (Step { op, d2: s.d, d: t.d, g: t.b, ..s }, 2)
            }
            // The square sum must read both differences: the second as its accumulator.
            ((S::Sub2, Some(S::SqAddSqA), _), Some(t), _) if t.c == s.d2 => {
                (Step { op: S::Sub2SqAddSqA, d3: s.d2, d2: s.d, d: t.d, ..s }, 2)
            }
            ((S::SubMulA, Some(S::MulAddC), _), Some(t), _) => {
                (Step { op: S::SubMulAMulAddC, d2: s.d, d: t.d, g: t.a, h: t.b, ..s }, 2)
            }
            ((S::MulAddC, Some(S::SubMulA), _), Some(t), _) => {
                (Step { op: S::MulAddCSubMulA, d2: s.d, d: t.d, g: t.b, h: t.c, ..s }, 2)
            }
            _ => (s, 1),
        };
        out.push(step);
        k += n;
    }
    out
}

/// `virt` (instructions over values, producers first) reordered so that a value read by one
/// instruction only is computed just before it, its operands' in operand order: the last
/// one computed is then the previous step's result, which single-state evaluation keeps in
/// a machine register ([`steps`]). A reordering of the same operations: no result changes.
/// Only producers that already come before their reader move, so a malformed program stays
/// malformed (and is refused).
fn tree_order(virt: Vec<(usize, Code, i32, [Val; 4])>, n: usize, outputs: &[Val]) -> Vec<(usize, Code, i32, [Val; 4])> {
    // The instruction computing each value, and how many instructions read it.
    let mut at = vec![usize::MAX; n];
    for (k, (i, ..)) in virt.iter().enumerate() {
        at[*i] = k;
    }
    let operands = |args: &[Val; 4]| {
        let mut seen: Vec<Val> = Vec::with_capacity(4);
        for &a in args {
            if !seen.contains(&a) {
                seen.push(a);
            }
        }
        seen
    };
    let mut readers = vec![0u32; n];
    let mut reader = vec![usize::MAX; n];
    for (k, (_, _, _, args)) in virt.iter().enumerate() {
        for a in operands(args) {
            readers[a as usize] += 1;
            reader[a as usize] = k;
        }
    }
    for &o in outputs {
        readers[o as usize] += 1;
    }
    let deferred: Vec<bool> = virt
        .iter()
        .enumerate()
        .map(|(k, (i, ..))| readers[*i] == 1 && reader[*i] != usize::MAX && reader[*i] > k)
        .collect();
    // The longest chain of operations ending at each instruction (a division or a function
    // counting as several): the longest operand is computed last, so the accumulator carries
    // the critical path and shorter ones have their values stored in time.
    let mut height = vec![0u32; virt.len()];
    for k in 0..virt.len() {
        let own = match virt[k].1 {
            Code::Div | Code::NegDiv | Code::Sqrt | Code::Norm2 | Code::Norm3 => 4,
            Code::Call(_) | Code::Powf | Code::Powi => 8,
            _ => 1,
        };
        let below = operands(&virt[k].3)
            .into_iter()
            .filter(|&a| at[a as usize] < k)
            .map(|a| height[at[a as usize]])
            .max()
            .unwrap_or(0);
        height[k] = below + own;
    }
    let mut order: Vec<usize> = Vec::with_capacity(virt.len());
    let mut taken = vec![false; virt.len()];
    // Post-order with an explicit stack: deep expressions must not overflow the call stack.
    let mut stack: Vec<(usize, bool)> = Vec::new();
    for k in 0..virt.len() {
        if deferred[k] {
            continue;
        }
        taken[k] = true;
        stack.push((k, false));
        while let Some((x, expanded)) = stack.pop() {
            if expanded {
                order.push(x);
                continue;
            }
            stack.push((x, true));
            let mut pulled: Vec<usize> = operands(&virt[x].3)
                .into_iter()
                .map(|a| at[a as usize])
                .filter(|&q| q != usize::MAX && q < x && deferred[q] && !taken[q])
                .collect();
            // Highest last (stable: ties in operand order); pushed in reverse, so they run
            // in that order.
            pulled.sort_by_key(|&q| height[q]);
            for &q in pulled.iter().rev() {
                taken[q] = true;
                stack.push((q, false));
            }
        }
    }
    // Deferred instructions whose reader comes first (a malformed program) keep their place
    // at the end, where register allocation finds the forward reference.
    order.extend((0..virt.len()).filter(|&k| !taken[k]));
    let mut virt: Vec<Option<_>> = virt.into_iter().map(Some).collect();
    order.into_iter().filter_map(|k| virt[k].take()).collect()
}

/// A compiled set of expressions. Immutable; share it between threads freely.
#[derive(Clone, Debug)]
pub struct Tape {
    /// The instructions of batched evaluation.
    code: Vec<Inst>,
    /// The same instructions for single-state evaluation ([`steps`]).
    steps: Vec<Packed>,
    n_inputs: usize,
    /// Values of registers `n_inputs .. n_inputs + consts.len()`.
    consts: Vec<f64>,
    n_regs: usize,
    /// The register of each output component.
    outputs: Vec<u32>,
    output_ranges: Vec<Range<usize>>,
    input_ranges: Vec<Range<usize>>,
    /// Where each register lives in batched evaluation.
    homes: Vec<Home>,
    /// Unique to the compilation (clones share it: they hold the same constants).
    id: u64,
}

/// No tape's [`Tape::id`].
const NO_TAPE: u64 = 0;

/// The next [`Tape::id`].
static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(NO_TAPE + 1);

/// Registers for single-state evaluation; make one with [`Tape::scratch`] and reuse it.
#[derive(Clone, Debug)]
pub struct Scratch {
    regs: Vec<f64>,
    /// The [`Tape::id`] whose constants the registers hold.
    tape: u64,
}

/// Registers of no tape: a placeholder for a caller whose evaluation has no tape of its own
/// (a tape refuses it as the scratch of another tape, unless it has no registers either).
impl Default for Scratch {
    fn default() -> Scratch {
        Scratch { regs: Vec::new(), tape: NO_TAPE }
    }
}

/// Registers for one lane of batched evaluation; make one with [`Tape::batch_scratch`].
#[derive(Clone, Debug)]
pub struct BatchScratch {
    regs: Vec<f64>,
}

/// Registers for [`Tape::eval_few`]: `K` states in each; make one with [`Tape::few_scratch`].
#[derive(Clone, Debug)]
pub struct FewScratch<const K: usize> {
    regs: Vec<[f64; K]>,
    /// The [`Tape::id`] whose constants the registers hold.
    tape: u64,
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
        Tape::compile_with_trig(graph, roots, inputs, &[])
    }

    /// [`compile`](Tape::compile) over `inputs` and then, two slots each, the sine and cosine
    /// of each angle of `trig` (scalars among `inputs`; [`Inputs::with_trig`]): input range
    /// `inputs.len() + k` is `trig[k]`'s pair, which the caller fills, and the tape computes
    /// no sine or cosine of those angles.
    pub fn compile_with_trig(
        graph: &Graph,
        roots: &[Id],
        inputs: &[Symbol],
        trig: &[Symbol],
    ) -> Result<Tape, TapeError> {
        let p = Program::lower_in(graph, roots, &Inputs::with_trig(graph, inputs, trig)?)?;
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
        let mut virt: Vec<(usize, Code, i32, [Val; 4])> = Vec::new();
        for (i, op) in p.ops.iter().enumerate() {
            let (code, imm, args) = match *op {
                Op::Input(_) | Op::Const(_) => continue,
                Op::Add(a, b) | Op::Sub(a, b) => {
                    let sub = matches!(op, Op::Sub(..));
                    match (single_mul(a), single_mul(b)) {
                        (Some((p, q)), Some((r, t))) => {
                            absorbed[a as usize] = true;
                            absorbed[b as usize] = true;
                            // Squares read each operand once: half the loads of a batched lane.
                            let code = match (sub, p == q && r == t) {
                                (false, true) => Code::SqAddSq,
                                (false, false) => Code::MulMulAdd,
                                (true, _) => Code::MulMulSub,
                            };
                            (code, 0, [p, q, r, t])
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
                Op::Mul(a, b) if a == b => (Code::Sq, 0, [a; 4]),
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
                Op::Call(Func::Sqrt, [a, _]) => (Code::Sqrt, 0, [a; 4]),
                // Unary calls' second slot repeats `a`, as unused operands do.
                Op::Call(f, [a, b]) => (Code::Call(f), 0, [a, b, a, a]),
                Op::Norm2(a, b) => (Code::Norm2, 0, [a, b, a, a]),
                Op::Norm3(a, b, c) => (Code::Norm3, 0, [a, b, c, a]),
            };
            virt.push((i, code, imm, args));
        }
        // Sums come after their products, so a product is absorbed before it would be emitted
        // only if we look ahead: drop absorbed products now.
        virt.retain(|(i, ..)| !absorbed[*i]);
        let virt = tree_order(virt, n, &p.outputs);
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
        let mut code = Vec::new();
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
        let steps = steps(&code);
        // The single-state steps use `code`'s register numbers, regrouped.
        assert!(steps.iter().all(|s| [s.d, s.a, s.b, s.c, s.e, s.d2, s.d3, s.g, s.h, s.k].into_iter().all(valid)));
        let steps = steps.iter().map(Packed::from).collect();
        let outputs: Vec<u32> = p.outputs.iter().map(|&o| reg[o as usize]).collect();
        // Batched homes: inputs stay in the caller's rows; a computed output is written
        // straight into its output row (its register is never reused: outputs are read "at
        // the end"); constants and the other temporaries live in the register file.
        let mut homes: Vec<Home> =
            (0..n_regs).map(|r| if r < p.n_inputs { Home::Input(r as u32) } else { Home::Temp }).collect();
        for (k, &r) in outputs.iter().enumerate() {
            if r >= first_temp && homes[r as usize] == Home::Temp {
                homes[r as usize] = Home::Output(k as u32);
            }
        }
        Tape {
            steps,
            code,
            n_inputs: p.n_inputs,
            consts,
            n_regs,
            outputs,
            output_ranges: p.output_ranges.clone(),
            input_ranges: p.input_ranges.clone(),
            homes,
            id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
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

    /// The input slots of every input symbol, in order ([`input_range`](Tape::input_range)
    /// of each).
    pub fn input_ranges(&self) -> &[Range<usize>] {
        &self.input_ranges
    }

    /// The output components of the `i`-th root (one for a scalar, `dim` for a vector).
    pub fn output_range(&self, i: usize) -> Range<usize> {
        self.output_ranges[i].clone()
    }

    /// Number of instructions run per state.
    pub fn instructions(&self) -> usize {
        self.code.len()
    }

    /// The instructions in order (those of batched evaluation), for the `jit` feature.
    #[cfg(feature = "jit")]
    pub(crate) fn jit_code(&self) -> &[Inst] {
        &self.code
    }

    /// The constants: register `input_len() + k` holds `jit_consts()[k]`.
    #[cfg(feature = "jit")]
    pub(crate) fn jit_consts(&self) -> &[f64] {
        &self.consts
    }

    /// The register of each output component.
    #[cfg(feature = "jit")]
    pub(crate) fn jit_outputs(&self) -> &[u32] {
        &self.outputs
    }

    /// Number of registers (inputs, constants, temporaries); every register number is below.
    #[cfg(feature = "jit")]
    pub(crate) fn jit_registers(&self) -> usize {
        self.n_regs
    }

    /// Registers for [`eval`](Tape::eval).
    pub fn scratch(&self) -> Scratch {
        Scratch { regs: vec![0.0; self.n_regs], tape: NO_TAPE }
    }

    /// Registers for [`eval_few`](Tape::eval_few) over `K` states.
    pub fn few_scratch<const K: usize>(&self) -> FewScratch<K> {
        FewScratch { regs: vec![[0.0; K]; self.n_regs], tape: NO_TAPE }
    }

    /// Registers for the serial part of [`eval_batch`](Tape::eval_batch).
    pub fn batch_scratch(&self) -> BatchScratch {
        BatchScratch { regs: vec![0.0; self.n_regs * LANES] }
    }

    /// Evaluates every root at one state.
    ///
    /// # Panics
    /// If `inputs` is not [`input_len`](Tape::input_len) long, `outputs` not
    /// [`output_len`](Tape::output_len) long, or `scratch` was made by a tape with another
    /// number of registers (one scratch may serve tapes of one size in turn).
    pub fn eval(&self, inputs: &[f64], scratch: &mut Scratch, outputs: &mut [f64]) {
        if inputs.len() != self.n_inputs || outputs.len() != self.outputs.len() || scratch.regs.len() != self.n_regs {
            self.misuse(inputs.len(), outputs.len(), scratch.regs.len());
        }
        // The constants stay in the registers from one call to the next (no step writes
        // them): loaded when the scratch last served another tape.
        if scratch.tape != self.id {
            scratch.regs[self.n_inputs..self.n_inputs + self.consts.len()].copy_from_slice(&self.consts);
            scratch.tape = self.id;
        }
        if self.n_inputs <= IN_PLACE_MAX {
            // SAFETY: the lengths are checked above.
            unsafe { self.run_steps::<true, true>(inputs, &mut scratch.regs, outputs) }
        } else {
            scratch.regs[..self.n_inputs].copy_from_slice(inputs);
            // SAFETY: as above.
            unsafe { self.run_steps::<false, true>(inputs, &mut scratch.regs, outputs) }
        }
    }

    /// The registers of the input slots, where [`eval_in_registers`](Tape::eval_in_registers)
    /// reads its inputs: the caller writes them here, slot by slot.
    ///
    /// # Panics
    /// If `scratch` was made by a tape with another number of registers.
    pub fn input_registers<'a>(&self, scratch: &'a mut Scratch) -> &'a mut [f64] {
        if scratch.regs.len() != self.n_regs {
            self.misuse(self.n_inputs, self.outputs.len(), scratch.regs.len());
        }
        &mut scratch.regs[..self.n_inputs]
    }

    /// [`eval`](Tape::eval) at the inputs in `scratch`'s input registers
    /// ([`input_registers`](Tape::input_registers)), every output component left in its
    /// register ([`output_register`](Tape::output_register), read with
    /// [`registers`](Tape::registers)) rather than copied out: the same steps, the same
    /// numbers, for a caller that reads each output once and would pay the copy for
    /// nothing. An output that is an input or a constant is in that input's or constant's
    /// register; the registers of the other outputs are written by no other step.
    ///
    /// # Panics
    /// If `scratch` was made by a tape with another number of registers.
    pub fn eval_in_registers(&self, scratch: &mut Scratch) {
        if scratch.regs.len() != self.n_regs {
            self.misuse(self.n_inputs, self.outputs.len(), scratch.regs.len());
        }
        if scratch.tape != self.id {
            scratch.regs[self.n_inputs..self.n_inputs + self.consts.len()].copy_from_slice(&self.consts);
            scratch.tape = self.id;
        }
        // SAFETY: the registers' length is checked above; with neither `IN_PLACE` nor the
        // outputs' copy, `run_steps` reads neither `inputs` nor `outputs`.
        unsafe { self.run_steps::<false, false>(&[], &mut scratch.regs, &mut []) }
    }

    /// The register that holds output component `k` after
    /// [`eval_in_registers`](Tape::eval_in_registers): below the number of registers.
    pub fn output_register(&self, k: usize) -> usize {
        self.outputs[k] as usize
    }

    /// The registers of `scratch` (every one, input slots first), as
    /// [`eval_in_registers`](Tape::eval_in_registers) left them.
    pub fn registers<'a>(&self, scratch: &'a Scratch) -> &'a [f64] {
        &scratch.regs
    }

    /// The panic of a call of [`eval`](Tape::eval) with slices of the wrong lengths: out of
    /// line, so the call's common path keeps nothing in memory for it.
    #[cold]
    #[inline(never)]
    fn misuse(&self, inputs: usize, outputs: usize, regs: usize) -> ! {
        assert_eq!(inputs, self.n_inputs, "input length");
        assert_eq!(outputs, self.outputs.len(), "output length");
        assert_eq!(regs, self.n_regs, "scratch made by another tape");
        unreachable!("eval called with the right lengths")
    }

    /// The steps of [`eval`](Tape::eval) over the registers `r`, then, with `COPY_OUT`, the
    /// outputs. With `IN_PLACE`, an operand that is an input slot is read from `inputs` (the
    /// registers of the input slots are not written); otherwise the caller has copied
    /// `inputs` into `r`.
    ///
    /// # Safety
    /// `inputs` must be [`input_len`](Tape::input_len) long with `IN_PLACE` or `COPY_OUT`,
    /// `r` [`n_regs`](Tape::scratch) long with the constants in place, `outputs`
    /// [`output_len`](Tape::output_len) long with `COPY_OUT`.
    #[inline(always)]
    unsafe fn run_steps<const IN_PLACE: bool, const COPY_OUT: bool>(
        &self,
        inputs: &[f64],
        r: &mut [f64],
        outputs: &mut [f64],
    ) {
        let n_inputs = self.n_inputs;
        let at = inputs.as_ptr();
        // The previous step's result (`A`, `B`, `C` steps read it here rather than from `r`).
        let mut acc = 0.0;
        // Every register access of the loop goes through `regs`, so reads and stores of one
        // step may interleave.
        let regs = r.as_mut_ptr();
        let mut steps = self.steps.iter();
        while let Some(mut s) = steps.next() {
            // SAFETY: `from_program` only writes register numbers below `n_regs` into `steps`
            // (asserted there), and `r` has exactly `n_regs` registers (the caller's); an
            // input slot `k < n_inputs` is an element of `inputs`.
            let reg = |k: u32| unsafe {
                let k = k as usize;
                if IN_PLACE && k < n_inputs { *at.add(k) } else { *regs.add(k) }
            };
            // SAFETY: as above.
            let set = |k: u32, x: f64| unsafe { *regs.add(k as usize) = x };
            // One load for two register numbers: volatile, so it is not split back into two.
            // SAFETY: a plain read of a field of `s`.
            let pair = |p: &u64| {
                let x = unsafe { std::ptr::read_volatile(p) };
                (x as u32, (x >> 32) as u32)
            };
            let x = match s.op {
                S::Add => {
                    let (a, b) = pair(&s.ab);
                    reg(a) + reg(b)
                }
                S::AddA => {
                    let (_, b) = pair(&s.ab);
                    acc + reg(b)
                }
                S::Sub => {
                    let (a, b) = pair(&s.ab);
                    reg(a) - reg(b)
                }
                S::SubA => {
                    let (_, b) = pair(&s.ab);
                    acc - reg(b)
                }
                S::SubB => {
                    let (a, _) = pair(&s.ab);
                    reg(a) - acc
                }
                S::Mul => {
                    let (a, b) = pair(&s.ab);
                    reg(a) * reg(b)
                }
                S::MulA => {
                    let (_, b) = pair(&s.ab);
                    acc * reg(b)
                }
                S::Div => {
                    let (a, b) = pair(&s.ab);
                    reg(a) / reg(b)
                }
                S::DivA => {
                    let (_, b) = pair(&s.ab);
                    acc / reg(b)
                }
                S::DivB => {
                    let (a, _) = pair(&s.ab);
                    reg(a) / acc
                }
                S::Neg => {
                    let (a, _) = pair(&s.ab);
                    -reg(a)
                }
                S::NegA => -acc,
                S::Powi => {
                    let (a, _) = pair(&s.ab);
                    reg(a).powi(s.imm)
                }
                S::PowiA => acc.powi(s.imm),
                S::Powf => {
                    let (a, b) = pair(&s.ab);
                    eval::pow(reg(a), reg(b))
                }
                S::Sqrt => {
                    let (a, _) = pair(&s.ab);
                    reg(a).sqrt()
                }
                S::SqrtA => acc.sqrt(),
                S::Call => {
                    let (a, b) = pair(&s.ab);
                    s.f.apply(&[reg(a), reg(b)])
                }
                S::Norm2 => {
                    let (a, b) = pair(&s.ab);
                    norm2(reg(a), reg(b))
                }
                S::Norm3 => {
                    let (a, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    norm3(reg(a), reg(b), reg(c))
                }
                S::Sq => {
                    let (a, _) = pair(&s.ab);
                    let a = reg(a);
                    a * a
                }
                S::SqA => acc * acc,
                // A square sum's `a` and `c` are one pair (`Packed::from`).
                S::SqAddSq => {
                    let (a, c) = pair(&s.ab);
                    let (a, c) = (reg(a), reg(c));
                    a * a + c * c
                }
                S::SqAddSqA => {
                    let (_, c) = pair(&s.ab);
                    let c = reg(c);
                    acc * acc + c * c
                }
                S::MulMulAdd => {
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    reg(a) * reg(b) + reg(c) * reg(e)
                }
                S::MulMulAddA => {
                    let (_, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    acc * reg(b) + reg(c) * reg(e)
                }
                S::MulMulSub => {
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    reg(a) * reg(b) - reg(c) * reg(e)
                }
                S::MulMulSubA => {
                    let (_, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    acc * reg(b) - reg(c) * reg(e)
                }
                S::MulAdd => {
                    let (a, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    reg(a) * reg(b) + reg(c)
                }
                S::MulAddA => {
                    let (_, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    acc * reg(b) + reg(c)
                }
                S::MulAddC => {
                    let (a, b) = pair(&s.ab);
                    reg(a) * reg(b) + acc
                }
                S::MulSub => {
                    let (a, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    reg(a) * reg(b) - reg(c)
                }
                S::MulSubA => {
                    let (_, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    acc * reg(b) - reg(c)
                }
                S::SubMul => {
                    let (a, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    reg(a) - reg(b) * reg(c)
                }
                S::SubMulA => {
                    let (_, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    acc - reg(b) * reg(c)
                }
                S::SubMulB => {
                    let (a, _) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    reg(a) - acc * reg(c)
                }
                S::NegMul => {
                    let (a, b) = pair(&s.ab);
                    -(reg(a) * reg(b))
                }
                S::NegMulA => {
                    let (_, b) = pair(&s.ab);
                    -(acc * reg(b))
                }
                S::NegDiv => {
                    let (a, b) = pair(&s.ab);
                    -(reg(a) / reg(b))
                }
                S::NegDivA => {
                    let (_, b) = pair(&s.ab);
                    -(acc / reg(b))
                }
                S::NegDivB => {
                    let (a, _) = pair(&s.ab);
                    -(reg(a) / acc)
                }
                S::Add2 | S::Sub2 | S::Mul2 | S::SqAddSq2 => {
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    let (d2, _) = pair(&s.d23);
                    let (a, b, c, e) = (reg(a), reg(b), reg(c), reg(e));
                    let (first, second) = match s.op {
                        S::Add2 => (a + b, c + e),
                        S::Sub2 => (a - b, c - e),
                        S::Mul2 => (a * b, c * e),
                        _ => (a * a + b * b, c * c + e * e),
                    };
                    set(d2, first);
                    second
                }
                // Superinstructions: each part computed, then stored, in turn; a later part
                // reads registers only after the earlier parts' stores.
                S::MulAMulA => {
                    let (_, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    let (d2, _) = pair(&s.d23);
                    let x = acc * reg(b);
                    set(d2, x);
                    x * reg(c)
                }
                S::MulMulAddNegMulA | S::MulMulAddANegMulA => {
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    let (g, _) = pair(&s.gh);
                    let (d2, _) = pair(&s.d23);
                    let first = if s.op == S::MulMulAddNegMulA { reg(a) } else { acc };
                    let x = first * reg(b) + reg(c) * reg(e);
                    set(d2, x);
                    -(x * reg(g))
                }
                S::Sub2SqAddSqA => {
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    let (d2, d3) = pair(&s.d23);
                    let (x, y) = (reg(a) - reg(b), reg(c) - reg(e));
                    set(d3, x);
                    set(d2, y);
                    y * y + x * x
                }
                S::MulMulAddAMulAddCMulA => {
                    let (_, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    let (g, h) = pair(&s.gh);
                    let (d2, d3) = pair(&s.d23);
                    let x = acc * reg(b) + reg(c) * reg(e);
                    set(d3, x);
                    let y = reg(g) * reg(h) + x;
                    set(d2, y);
                    y * reg(s.k)
                }
                S::SubMulAMulAddC => {
                    let (_, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    let (g, h) = pair(&s.gh);
                    let (d2, _) = pair(&s.d23);
                    let x = acc - reg(b) * reg(c);
                    set(d2, x);
                    reg(g) * reg(h) + x
                }
                S::MulAddCSubMulA => {
                    let (a, b) = pair(&s.ab);
                    let (g, h) = pair(&s.gh);
                    let (d2, _) = pair(&s.d23);
                    let x = reg(a) * reg(b) + acc;
                    set(d2, x);
                    x - reg(g) * reg(h)
                }
                S::MulMulAddMulAddC | S::MulMulAddAMulAddC => {
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    let (g, h) = pair(&s.gh);
                    let (d2, _) = pair(&s.d23);
                    let first = if s.op == S::MulMulAddMulAddC { reg(a) } else { acc };
                    let x = first * reg(b) + reg(c) * reg(e);
                    set(d2, x);
                    reg(g) * reg(h) + x
                }
                S::MulA2 => {
                    let (_, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    let (d2, _) = pair(&s.d23);
                    let (b, c) = (reg(b), reg(c));
                    set(d2, acc * b);
                    acc * c
                }
                S::NegMulA2 => {
                    let (_, b) = pair(&s.ab);
                    let (c, _) = pair(&s.ce);
                    let (d2, _) = pair(&s.d23);
                    let (b, c) = (reg(b), reg(c));
                    set(d2, -(acc * b));
                    -(acc * c)
                }
                S::Sub2Sub2 | S::Sub2SqAddSqASub2 => {
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    let (d2, d3) = pair(&s.d23);
                    let (x, y) = (reg(a) - reg(b), reg(c) - reg(e));
                    if s.op == S::Sub2Sub2 {
                        set(d2, x);
                        set(s.d, y);
                    } else {
                        set(d3, x);
                        set(d2, y);
                        set(s.d, y * y + x * x);
                    }
                    // The next slot's `Sub2` (`fuse` put one there), read after these stores.
                    let Some(next) = steps.next() else {
                        break;
                    };
                    s = next;
                    let (a, b) = pair(&s.ab);
                    let (c, e) = pair(&s.ce);
                    let (d2, _) = pair(&s.d23);
                    let (a, b, c, e) = (reg(a), reg(b), reg(c), reg(e));
                    set(d2, a - b);
                    c - e
                }
            };
            set(s.d, x);
            acc = x;
        }
        if !COPY_OUT {
            return;
        }
        for (o, &k) in outputs.iter_mut().zip(&self.outputs) {
            let k = k as usize;
            // SAFETY: `from_program` asserts every output register is below `n_regs`, and
            // `r` has that many (the caller's).
            *o = if IN_PLACE && k < n_inputs { inputs[k] } else { unsafe { *r.get_unchecked(k) } };
        }
    }

    /// Evaluates every root at `n` states stored as structure of arrays: input slot `j` of
    /// state `s` is `inputs[j * n + s]`, output component `k` of state `s` goes to
    /// `outputs[k * n + s]`. Batches of [`PARALLEL_MIN`] states or more run in parallel;
    /// that path allocates a register file per worker, the serial path never allocates.
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
        let out = OutPtr(outputs.as_mut_ptr());
        if n < PARALLEL_MIN || rayon::current_num_threads() < 2 {
            // SAFETY: `outputs` is `output_len · n` long (asserted) and borrowed mutably for
            // the whole call; `inputs` is `input_len · n` long.
            unsafe { self.run_range(&mut scratch.regs, inputs, out, n, 0..n) };
            return;
        }
        let blocks = n.div_ceil(BLOCK);
        (0..blocks).into_par_iter().for_each_init(
            || vec![0.0; self.n_regs * LANES],
            |regs, block| {
                let range = block * BLOCK..((block + 1) * BLOCK).min(n);
                // SAFETY: as above; each block writes only its own states `range` of every
                // output row, and the blocks are disjoint.
                unsafe { self.run_range(regs, inputs, out, n, range) };
            },
        );
    }

    /// [`eval_batch`](Tape::eval_batch) on the calling thread whatever `n`: for batches
    /// evaluated many times a second (a simulation's rows), where handing work to other
    /// threads would cost more than it saves and the caller's thread is the one measured.
    pub fn eval_batch_serial(&self, n: usize, inputs: &[f64], scratch: &mut BatchScratch, outputs: &mut [f64]) {
        assert_eq!(inputs.len(), self.n_inputs * n, "input length");
        assert_eq!(outputs.len(), self.outputs.len() * n, "output length");
        assert_eq!(scratch.regs.len(), self.n_regs * LANES, "scratch made by another tape");
        // SAFETY: `outputs` is `output_len · n` long (asserted) and borrowed mutably for the
        // whole call; `inputs` is `input_len · n` long.
        unsafe { self.run_range(&mut scratch.regs, inputs, OutPtr(outputs.as_mut_ptr()), n, 0..n) };
    }

    /// Evaluates every root at `K` states at once (a few: 2 to 8), each register holding the
    /// `K` states' values: `inputs[j][s]` is input slot `j` of state `s`, `outputs[k][s]`
    /// output component `k` of state `s`. The results are bitwise those of
    /// [`eval`](Tape::eval) at each state (the lanes' instructions, `K` at a time).
    ///
    /// For callers with a handful of states (a few bodies, candidate states of a search):
    /// one call and one dispatch per instruction serve all `K`, and their divisions and
    /// square roots, independent, overlap in the processor, where `K` calls of
    /// [`eval`](Tape::eval) would each wait on their own. Nothing is allocated; the
    /// constants stay in the scratch between calls, as [`eval`](Tape::eval)'s do.
    ///
    /// # Panics
    /// If `inputs` is not [`input_len`](Tape::input_len) long, `outputs` not
    /// [`output_len`](Tape::output_len) long, or `scratch` was made by a tape with another
    /// number of registers.
    pub fn eval_few<const K: usize>(&self, inputs: &[[f64; K]], scratch: &mut FewScratch<K>, outputs: &mut [[f64; K]]) {
        assert_eq!(inputs.len(), self.n_inputs, "input length");
        assert_eq!(outputs.len(), self.outputs.len(), "output length");
        assert_eq!(scratch.regs.len(), self.n_regs, "scratch made by another tape");
        let r = scratch.regs.as_mut_slice();
        if scratch.tape != self.id {
            for (x, &c) in r[self.n_inputs..].iter_mut().zip(&self.consts) {
                *x = [c; K];
            }
            scratch.tape = self.id;
        }
        r[..self.n_inputs].copy_from_slice(inputs);
        let regs = r.as_mut_ptr();
        // SAFETY: `from_program` asserts every register number of `code` is below `n_regs`,
        // and the scratch has exactly `n_regs` registers (asserted above).
        let reg = |k: u32| unsafe { *regs.add(k as usize) };
        for i in &self.code {
            // Operands by value (the destination is never an operand), then one store.
            let (a, b) = (reg(i.a), reg(i.b));
            let x: [f64; K] = match i.code {
                Code::Add => std::array::from_fn(|s| a[s] + b[s]),
                Code::Sub => std::array::from_fn(|s| a[s] - b[s]),
                Code::Mul => std::array::from_fn(|s| a[s] * b[s]),
                Code::Div => std::array::from_fn(|s| a[s] / b[s]),
                Code::Neg => std::array::from_fn(|s| -a[s]),
                Code::Sq => std::array::from_fn(|s| a[s] * a[s]),
                Code::SqAddSq => {
                    let c = reg(i.c);
                    std::array::from_fn(|s| a[s] * a[s] + c[s] * c[s])
                }
                Code::Powi => std::array::from_fn(|s| a[s].powi(i.imm)),
                Code::Powf => std::array::from_fn(|s| eval::pow(a[s], b[s])),
                Code::Sqrt => std::array::from_fn(|s| a[s].sqrt()),
                Code::Call(f) => std::array::from_fn(|s| f.apply(&[a[s], b[s]])),
                Code::MulMulAdd => {
                    let (c, e) = (reg(i.c), reg(i.e));
                    std::array::from_fn(|s| a[s] * b[s] + c[s] * e[s])
                }
                Code::MulMulSub => {
                    let (c, e) = (reg(i.c), reg(i.e));
                    std::array::from_fn(|s| a[s] * b[s] - c[s] * e[s])
                }
                Code::MulAdd => {
                    let c = reg(i.c);
                    std::array::from_fn(|s| a[s] * b[s] + c[s])
                }
                Code::MulSub => {
                    let c = reg(i.c);
                    std::array::from_fn(|s| a[s] * b[s] - c[s])
                }
                Code::SubMul => {
                    let c = reg(i.c);
                    std::array::from_fn(|s| a[s] - b[s] * c[s])
                }
                Code::NegMul => std::array::from_fn(|s| -(a[s] * b[s])),
                Code::NegDiv => std::array::from_fn(|s| -(a[s] / b[s])),
                // As the lanes: the plain formula, then the rare overflow cases again.
                Code::Norm2 => std::array::from_fn(|s| {
                    let o = (a[s] * a[s] + b[s] * b[s]).sqrt();
                    if o.is_finite() && o >= 1e-150 { o } else { norm2(a[s], b[s]) }
                }),
                Code::Norm3 => {
                    let c = reg(i.c);
                    std::array::from_fn(|s| {
                        let o = (a[s] * a[s] + b[s] * b[s] + c[s] * c[s]).sqrt();
                        if o.is_finite() && o >= 1e-150 { o } else { norm3(a[s], b[s], c[s]) }
                    })
                }
            };
            // SAFETY: as `reg`.
            unsafe { *regs.add(i.d as usize) = x };
        }
        for (o, &k) in outputs.iter_mut().zip(&self.outputs) {
            *o = reg(k);
        }
    }

    /// Runs the states `range` lane by lane, writing their outputs into the rows at `out`.
    ///
    /// # Safety
    /// `out` must point to `output_len · n` writable values that nothing else reads or
    /// writes in the states `range` during the call; `inputs` must be `input_len · n` long
    /// and `regs` `n_regs · LANES` long.
    unsafe fn run_range(&self, regs: &mut [f64], inputs: &[f64], out: OutPtr, n: usize, range: Range<usize>) {
        let mut s = range.start;
        while s < range.end {
            let len = LANES.min(range.end - s);
            for (k, &x) in self.consts.iter().enumerate() {
                let r = (self.n_inputs + k) * LANES;
                regs[r..r + len].fill(x);
            }
            let at = Lane { inputs: inputs.as_ptr(), outputs: out.0, regs: regs.as_mut_ptr(), n, start: s, len };
            // SAFETY: the caller's contract, and `Lane::at` stays inside the three buffers.
            unsafe {
                self.run_lane(at);
                // Outputs computed elsewhere (an input, a constant, a value output twice).
                for (k, &reg) in self.outputs.iter().enumerate() {
                    if self.homes[reg as usize] != Home::Output(k as u32) {
                        let from = at.get(self.homes[reg as usize], reg);
                        let to = at.get(Home::Output(k as u32), reg);
                        std::ptr::copy_nonoverlapping(from, to, len);
                    }
                }
            }
            s += len;
        }
    }

    /// One pass of the tape over one lane of states, with the widest vector instructions
    /// the processor has (AVX2 on x86-64 when present: the same IEEE operations four at a
    /// time, no FMA, so results are bitwise those of [`eval`](Tape::eval)).
    ///
    /// # Safety
    /// As [`run_range`](Tape::run_range), for the lane `at`.
    unsafe fn run_lane(&self, at: Lane) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked); the rest is the caller's contract.
            return unsafe { self.run_lane_avx2(at) };
        }
        // SAFETY: the caller's contract.
        unsafe { self.run_lane_any(at) }
    }

    /// [`run_lane_any`](Tape::run_lane_any) compiled for AVX2.
    ///
    /// # Safety
    /// The processor must have AVX2; otherwise as [`run_range`](Tape::run_range).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_lane_avx2(&self, at: Lane) {
        // SAFETY: the caller's contract.
        unsafe { self.run_lane_any(at) }
    }

    /// One pass of the tape over one lane of states. Operands are read where they live
    /// (input rows, output rows, or the register file) and results written where they live.
    ///
    /// # Safety
    /// As [`run_range`](Tape::run_range), for the lane `at`.
    #[inline(always)]
    unsafe fn run_lane_any(&self, at: Lane) {
        let len = at.len;
        for i in &self.code {
            // SAFETY: every register has its own home (inputs, outputs and temporaries are
            // disjoint memory), and `d` is never an operand, so the destination lane does not
            // overlap any operand lane; each lane is `len` values inside its buffer.
            let (out, [a, b, c, e]) = unsafe {
                let lane = |k: u32| std::slice::from_raw_parts(at.get(*self.homes.get_unchecked(k as usize), k), len);
                let out = std::slice::from_raw_parts_mut(at.get(*self.homes.get_unchecked(i.d as usize), i.d), len);
                (out, [lane(i.a), lane(i.b), lane(i.c), lane(i.e)])
            };
            match i.code {
                Code::Add => zip2(out, a, b, |x, y| x + y),
                Code::Sub => zip2(out, a, b, |x, y| x - y),
                Code::Mul => zip2(out, a, b, |x, y| x * y),
                Code::Div => zip2(out, a, b, |x, y| x / y),
                Code::Neg => zip1(out, a, |x| -x),
                Code::Sq => zip1(out, a, |x| x * x),
                Code::SqAddSq => zip2(out, a, c, |x, y| x * x + y * y),
                Code::Powi => zip1(out, a, |x| x.powi(i.imm)),
                Code::Powf => zip2(out, a, b, eval::pow),
                Code::Sqrt => zip1(out, a, f64::sqrt),
                Code::Call(f) => zip2(out, a, b, |x, y| f.apply(&[x, y])),
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

/// Where a register's lane lives in batched evaluation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Home {
    /// Row `j` of the caller's inputs (read in place, never copied).
    Input(u32),
    /// Row `k` of the caller's outputs: an output value is computed where it is returned.
    Output(u32),
    /// The register file: register `r` at `r · LANES`.
    Temp,
}

/// The output buffer of a batch, shared by the parallel tasks (each writes its own states).
#[derive(Clone, Copy)]
struct OutPtr(*mut f64);
// SAFETY: tasks write disjoint state ranges of the buffer (see `eval_batch`).
unsafe impl Send for OutPtr {}
// SAFETY: as above.
unsafe impl Sync for OutPtr {}

/// One lane of a batch: the states `start..start + len` of `n`.
#[derive(Clone, Copy)]
struct Lane {
    inputs: *const f64,
    outputs: *mut f64,
    regs: *mut f64,
    n: usize,
    start: usize,
    len: usize,
}

impl Lane {
    /// The first value of register `reg`'s lane, living at `home`.
    ///
    /// # Safety
    /// The row or register must exist in its buffer (`Tape::homes` guarantees it).
    #[inline(always)]
    unsafe fn get(self, home: Home, reg: u32) -> *mut f64 {
        // SAFETY: the caller's; rows are `n` long and `start + len ≤ n`.
        unsafe {
            match home {
                Home::Input(j) => self.inputs.add(j as usize * self.n + self.start) as *mut f64,
                Home::Output(k) => self.outputs.add(k as usize * self.n + self.start),
                Home::Temp => self.regs.add(reg as usize * LANES),
            }
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    use crate::numeric::random::Rng;

    /// A draw below `n`.
    fn below(rng: &mut Rng, n: usize) -> usize {
        (rng.next_u64() % n as u64) as usize
    }

    /// A random program over `n_inputs` slots: a few constants, then sums, differences,
    /// products (squares among them, and products read once: fused), quotients, negations and
    /// powers of earlier values; its outputs any values, inputs and constants among them,
    /// some repeated.
    fn random_program(rng: &mut Rng, n_inputs: usize) -> Program {
        let mut ops: Vec<Op> = (0..n_inputs as u32).map(Op::Input).collect();
        for _ in 0..1 + below(rng, 3) {
            ops.push(Op::Const(rng.uniform(-2.0, 2.0).to_bits()));
        }
        for _ in 0..5 + below(rng, 40) {
            let n = ops.len();
            let (a, b) = (below(rng, n) as Val, below(rng, n) as Val);
            ops.push(match below(rng, 7) {
                0 => Op::Add(a, b),
                1 => Op::Sub(a, b),
                2 => Op::Mul(a, b),
                3 => Op::Mul(a, a),
                4 => Op::Div(a, b),
                5 => Op::Neg(a),
                _ => Op::Powi(a, 3),
            });
        }
        let outputs: Vec<Val> = (0..1 + below(rng, 12)).map(|_| below(rng, ops.len()) as Val).collect();
        scalar_program(ops, n_inputs, outputs)
    }

    /// The program of `ops` whose `n_inputs` inputs and `outputs` are one number each.
    fn scalar_program(ops: Vec<Op>, n_inputs: usize, outputs: Vec<Val>) -> Program {
        Program {
            ops,
            n_inputs,
            input_ranges: (0..n_inputs).map(|j| j..j + 1).collect(),
            output_ranges: (0..outputs.len()).map(|k| k..k + 1).collect(),
            outputs,
        }
    }

    /// `eval_in_registers` leaves in each output's register the bits `eval` writes to the
    /// output, on random tapes (inputs in place and copied, outputs that are inputs or
    /// constants), at random states, with one scratch serving the tapes in turn.
    #[test]
    fn outputs_in_registers_are_evals_outputs() {
        let mut rng = Rng::new(0x9e37_79b9_7f4a_7c15);
        for case in 0..300 {
            let n_inputs = 1 + below(&mut rng, 2 * IN_PLACE_MAX);
            let tape = Tape::from_program(&random_program(&mut rng, n_inputs));
            let (mut scratch, mut theirs) = (tape.scratch(), tape.scratch());
            let mut out = vec![0.0; tape.output_len()];
            for _ in 0..4 {
                let inputs: Vec<f64> = (0..n_inputs).map(|_| rng.uniform(-2.0, 2.0)).collect();
                tape.eval(&inputs, &mut theirs, &mut out);
                tape.input_registers(&mut scratch).copy_from_slice(&inputs);
                tape.eval_in_registers(&mut scratch);
                let registers = tape.registers(&scratch);
                for (k, x) in out.iter().enumerate() {
                    let got = registers[tape.output_register(k)];
                    assert_eq!(got.to_bits(), x.to_bits(), "case {case} output {k}");
                }
                // The scratch serves `eval` in turn, as one of another tape would.
                tape.eval(&inputs, &mut scratch, &mut out);
            }
        }
    }

    /// Random programs of the shapes the steps that run on into the next slot merge (four
    /// differences; two differences, their square sum and two more differences: a chain's
    /// links and rows), among other operations, the operands inputs or earlier values (the
    /// previous differences among them, read after they are stored): single-state
    /// evaluation, copied out and left in the registers, gives the lanes' bits, and the
    /// tapes run both kinds of step.
    #[test]
    fn steps_that_run_on_compute_the_lanes_numbers() {
        // A difference of two earlier values, an output.
        fn sub(rng: &mut Rng, ops: &mut Vec<Op>, outputs: &mut Vec<Val>) -> Val {
            let (a, b) = (below(rng, ops.len()) as Val, below(rng, ops.len()) as Val);
            ops.push(Op::Sub(a, b));
            outputs.push(ops.len() as Val - 1);
            ops.len() as Val - 1
        }
        let mut rng = Rng::new(0x2545_f491_4f6c_dd1d);
        let (mut fours, mut rows) = (0, 0);
        for case in 0..300 {
            let n_inputs = 1 + below(&mut rng, 2 * IN_PLACE_MAX);
            let mut ops: Vec<Op> = (0..n_inputs as u32).map(Op::Input).collect();
            let mut outputs: Vec<Val> = Vec::new();
            for _ in 0..1 + below(&mut rng, 10) {
                match below(&mut rng, 3) {
                    0 => {
                        for _ in 0..4 {
                            sub(&mut rng, &mut ops, &mut outputs);
                        }
                    }
                    1 => {
                        let (x, y) = (sub(&mut rng, &mut ops, &mut outputs), sub(&mut rng, &mut ops, &mut outputs));
                        ops.push(Op::Mul(x, x));
                        ops.push(Op::Mul(y, y));
                        let n = ops.len() as Val;
                        ops.push(Op::Add(n - 2, n - 1));
                        outputs.push(n);
                        sub(&mut rng, &mut ops, &mut outputs);
                        sub(&mut rng, &mut ops, &mut outputs);
                    }
                    _ => {
                        let (a, b) = (below(&mut rng, ops.len()) as Val, below(&mut rng, ops.len()) as Val);
                        ops.push(if below(&mut rng, 2) == 0 { Op::Mul(a, b) } else { Op::Div(a, b) });
                        outputs.push(ops.len() as Val - 1);
                    }
                }
            }
            let tape = Tape::from_program(&scalar_program(ops, n_inputs, outputs));
            fours += usize::from(tape.steps.iter().any(|s| s.op == S::Sub2Sub2));
            rows += usize::from(tape.steps.iter().any(|s| s.op == S::Sub2SqAddSqASub2));
            let (mut scratch, mut lanes) = (tape.scratch(), tape.batch_scratch());
            let (mut out, mut want) = (vec![0.0; tape.output_len()], vec![0.0; tape.output_len()]);
            for _ in 0..4 {
                let inputs: Vec<f64> = (0..n_inputs).map(|_| rng.uniform(-2.0, 2.0)).collect();
                tape.eval_batch(1, &inputs, &mut lanes, &mut want);
                tape.eval(&inputs, &mut scratch, &mut out);
                for (k, (x, w)) in out.iter().zip(&want).enumerate() {
                    assert_eq!(x.to_bits(), w.to_bits(), "case {case} output {k}: eval against the lanes");
                }
                tape.input_registers(&mut scratch).copy_from_slice(&inputs);
                tape.eval_in_registers(&mut scratch);
                let registers = tape.registers(&scratch);
                for (k, w) in want.iter().enumerate() {
                    let got = registers[tape.output_register(k)];
                    assert_eq!(got.to_bits(), w.to_bits(), "case {case} output {k}: in registers against the lanes");
                }
            }
        }
        assert!(fours > 30 && rows > 30, "tapes with Sub2Sub2 {fours}, with Sub2SqAddSqASub2 {rows}, of 300");
    }
}
