//! Lowering: graph expressions → one scalar SSA program, shared by the tape and by codegen.
//!
//! Vectors are split into their components, so the program only holds scalar operations
//! (`+ − × ÷`, powers, functions, an overflow-safe norm). While lowering, constants are
//! folded, a few identities are applied (`x + (−y)` → `x − y`, `x · 1` → `x`, `x^2` → `x·x`,
//! `x · y^−1` → `x / y`) and every operation is hash-consed at the scalar level, so a
//! component computed twice (say `r.x·r.x` in `r·r` and in `|r|`) is computed once. Dead
//! operations (left over by the identities) are dropped at the end.
//!
//! Design note: the [`Tape`](super::tape::Tape) and the Rust generator both start from this
//! [`Program`], so the lowering is written once; the tape allocates registers for it, the
//! generator names its values. Lowering walks the reachable nodes in id order (children
//! first), so it never recurses.
//!
//! Not here: register allocation and evaluation (`tape.rs`), text of any kind (`codegen`).

use crate::expr::eval;
use crate::expr::func::MAX_ARITY;
use crate::expr::graph::FastMap;
use crate::expr::{Func, Graph, Id, Node, Symbol, Ty};
use std::ops::Range;

/// A value of the program: the index of the operation that computes it.
pub type Val = u32;

/// One scalar operation. Operands are earlier values.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Op {
    /// Input slot `j`.
    Input(u32),
    /// A constant, stored as its bits so that operations can be hashed.
    Const(u64),
    Add(Val, Val),
    Sub(Val, Val),
    Mul(Val, Val),
    Div(Val, Val),
    Neg(Val),
    /// `x^n` for an integer `n` with |n| ≥ 3 (smaller powers become products).
    Powi(Val, i32),
    /// `b^e` with the semantics of [`eval::pow`] (integer exponents by `powi`).
    Powf(Val, Val),
    /// A function of the table over its arguments (the first `arity` slots; the others
    /// repeat the first, so equal calls hash equal).
    Call(Func, [Val; MAX_ARITY]),
    /// `|(x, y)|`, overflow-safe ([`norm2`]).
    Norm2(Val, Val),
    /// `|(x, y, z)|`, overflow-safe ([`norm3`]).
    Norm3(Val, Val, Val),
}

impl Op {
    /// The value of a `Const`.
    pub fn constant(self) -> Option<f64> {
        match self {
            Op::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        }
    }

    /// The operands, in order.
    pub fn operands(self) -> impl Iterator<Item = Val> {
        let (list, n): ([Val; 3], usize) = match self {
            Op::Input(_) | Op::Const(_) => ([0; 3], 0),
            Op::Neg(a) | Op::Powi(a, _) => ([a, 0, 0], 1),
            Op::Call(f, [a, b]) => ([a, b, 0], f.arity()),
            Op::Add(a, b) | Op::Sub(a, b) | Op::Mul(a, b) | Op::Div(a, b) | Op::Powf(a, b) | Op::Norm2(a, b) => {
                ([a, b, 0], 2)
            }
            Op::Norm3(a, b, c) => ([a, b, c], 3),
        };
        list.into_iter().take(n)
    }
}

/// `|(x, y)|`: [`eval::norm`], the one overflow-safe norm.
#[inline]
pub fn norm2(x: f64, y: f64) -> f64 {
    eval::norm([x, y])
}

/// `|(x, y, z)|`: [`eval::norm`], the one overflow-safe norm.
#[inline]
pub fn norm3(x: f64, y: f64, z: f64) -> f64 {
    eval::norm([x, y, z])
}

/// Why expressions could not be lowered.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LowerError {
    #[error("the expression uses `{0}`, which is not among the inputs: add it to the input layout")]
    MissingInput(String),
    #[error("an input symbol is listed twice: `{0}`")]
    DuplicateInput(String),
    /// `rot` in 3D over something other than an orientation symbol (the lowering of the
    /// language allows only those).
    #[error("`rot` in 3D turns by an orientation symbol's quaternion only")]
    NotAQuaternion,
}

/// A scalar SSA program: `ops[i]` computes value `i` from earlier values.
#[derive(Clone, Debug)]
pub struct Program {
    pub ops: Vec<Op>,
    /// Number of input slots (a vector symbol takes `dim` slots).
    pub n_inputs: usize,
    /// The slots of each input symbol, in the order given, then of each angle's sine and
    /// cosine ([`Inputs::with_trig`]).
    pub input_ranges: Vec<Range<usize>>,
    /// The components of every root, concatenated.
    pub outputs: Vec<Val>,
    /// The range of `outputs` that belongs to each root.
    pub output_ranges: Vec<Range<usize>>,
}

/// The input layout of programs: the slots of each input symbol (1, or `dim` for a vector),
/// in the order given. Built once for many lowerings over the same inputs (`codegen` lowers
/// every function of a module over one layout), so a lowering costs the size of its
/// expressions, not of the inputs.
#[derive(Clone, Debug)]
pub struct Inputs {
    /// Symbol → (first slot, width).
    slots: FastMap<Symbol, (u32, usize)>,
    /// Angle → the slot of its sine, its cosine in the next ([`Inputs::with_trig`]).
    trig: FastMap<Symbol, u32>,
    ranges: Vec<Range<usize>>,
    n: usize,
}

impl Inputs {
    pub fn new(g: &Graph, inputs: &[Symbol]) -> Result<Inputs, LowerError> {
        Inputs::with_trig(g, inputs, &[])
    }

    /// [`new`](Inputs::new), then two slots for each scalar of `trig`: its sine and cosine,
    /// which the lowering reads wherever it would compute them (a 2D rotation R(θ), a call
    /// `sin(θ)`, `cos(θ)`), so a caller whose many roots turn by one body's angle computes
    /// them once per body rather than once per root. Their ranges follow the symbols':
    /// range `inputs.len() + k` is `trig[k]`'s (sine, cosine).
    pub fn with_trig(g: &Graph, inputs: &[Symbol], trig: &[Symbol]) -> Result<Inputs, LowerError> {
        let mut slots = FastMap::default();
        let mut ranges = Vec::new();
        let mut n = 0usize;
        for &s in inputs {
            let width = if g.is_quaternion(s) {
                4
            } else if g.symbol(s).ty == Ty::Vector {
                g.dim()
            } else {
                1
            };
            if slots.insert(s, (n as u32, width)).is_some() {
                return Err(LowerError::DuplicateInput(g.symbol(s).name.clone()));
            }
            ranges.push(n..n + width);
            n += width;
        }
        let mut pairs = FastMap::default();
        for &s in trig {
            if pairs.insert(s, n as u32).is_some() {
                return Err(LowerError::DuplicateInput(g.symbol(s).name.clone()));
            }
            ranges.push(n..n + 2);
            n += 2;
        }
        Ok(Inputs { slots, trig: pairs, ranges, n })
    }

    /// The slots of each input symbol, in the order given, then of each angle's sine and
    /// cosine: a program's [`input_ranges`](Program::input_ranges) over this layout.
    pub fn ranges(&self) -> &[Range<usize>] {
        &self.ranges
    }

    /// The input slot of `f(x)` when `f` is sin or cos and `x` an angle whose sine and
    /// cosine are inputs ([`with_trig`](Inputs::with_trig)).
    fn trig_slot(&self, g: &Graph, f: Func, x: Id) -> Option<u32> {
        let Node::Sym(s) = g.node(x) else { return None };
        let sine = *self.trig.get(s)?;
        match f {
            Func::Sin => Some(sine),
            Func::Cos => Some(sine + 1),
            _ => None,
        }
    }
}

impl Program {
    /// Lowers `roots` over the input layout `inputs` (each symbol takes 1 or `dim` slots).
    pub fn lower(g: &Graph, roots: &[Id], inputs: &[Symbol]) -> Result<Program, LowerError> {
        Program::lower_in(g, roots, &Inputs::new(g, inputs)?)
    }

    /// [`Program::lower`] over a layout built once. Only the inputs the roots use get an
    /// operation (`Op::Input`), at their first use.
    pub fn lower_in(g: &Graph, roots: &[Id], inputs: &Inputs) -> Result<Program, LowerError> {
        let mut b = Builder::default();
        // The input symbols met so far → their slot values.
        let mut slots: FastMap<Symbol, [Val; 3]> = FastMap::default();
        // A 3D orientation takes four slots, [w, x, y, z], read only by `rot`.
        let mut quaternions: FastMap<Symbol, [Val; 4]> = FastMap::default();
        // Node → its component values (a scalar uses entry 0).
        let mut vals: FastMap<Id, [Val; 3]> = FastMap::default();
        let dim = g.dim();
        for id in g.reachable(roots) {
            let width = if g.ty(id) == Ty::Vector { dim } else { 1 };
            let get = |x: &Id| vals[x];
            let v: [Val; 3] = match g.node(id) {
                Node::Num(q) => [b.constant(q.to_f64()), 0, 0],
                Node::Sym(s) => match (slots.get(s), inputs.slots.get(s)) {
                    (Some(v), _) => *v,
                    (None, Some(&(first, width))) => {
                        let mut v = [0; 4];
                        for (k, slot) in v.iter_mut().enumerate().take(width) {
                            *slot = b.push(Op::Input(first + k as u32));
                        }
                        if width == 4 {
                            quaternions.insert(*s, v);
                        }
                        let v = [v[0], v[1], v[2]];
                        slots.insert(*s, v);
                        v
                    }
                    (None, None) => return Err(LowerError::MissingInput(g.symbol(*s).name.clone())),
                },
                Node::Vector(xs) => {
                    let mut v = [0; 3];
                    for (o, x) in v.iter_mut().zip(xs.iter()) {
                        *o = get(x)[0];
                    }
                    v
                }
                Node::Add(xs) => {
                    let mut acc = get(&xs[0]);
                    for x in &xs[1..] {
                        let t = get(x);
                        for k in 0..width {
                            acc[k] = b.add(acc[k], t[k]);
                        }
                    }
                    acc
                }
                Node::Mul(xs) => b.product(g, xs, &vals, width),
                Node::Pow([base, e]) => match g.as_num(*e) {
                    Some(q) => [b.pow_const(get(base)[0], q.to_f64()), 0, 0],
                    None => [b.powf(get(base)[0], get(e)[0]), 0, 0],
                },
                Node::Dot([x, y]) => {
                    let (x, y) = (get(x), get(y));
                    let mut acc = b.mul(x[0], y[0]);
                    for k in 1..dim {
                        let p = b.mul(x[k], y[k]);
                        acc = b.add(acc, p);
                    }
                    [acc, 0, 0]
                }
                Node::Cross([x, y]) => {
                    let (x, y) = (get(x), get(y));
                    // (a × b)ᵢ = a_{i+1} b_{i+2} − a_{i+2} b_{i+1}; in 2D only the z-part.
                    let part = |b: &mut Builder, i: usize, j: usize| {
                        let p = b.mul(x[i], y[j]);
                        let q = b.mul(x[j], y[i]);
                        b.sub(p, q)
                    };
                    if dim == 2 {
                        [part(&mut b, 0, 1), 0, 0]
                    } else {
                        [part(&mut b, 1, 2), part(&mut b, 2, 0), part(&mut b, 0, 1)]
                    }
                }
                Node::Norm(x) => {
                    let x = get(x);
                    [b.norm(&x[..dim]), 0, 0]
                }
                Node::Comp(x, axis) => [get(x)[axis.index()], 0, 0],
                Node::Call(f, args) => match inputs.trig_slot(g, *f, args[0]) {
                    Some(slot) => [b.push(Op::Input(slot)), 0, 0],
                    None => {
                        let args: Vec<Val> = args[..f.arity()].iter().map(|a| get(a)[0]).collect();
                        [b.call(*f, &args), 0, 0]
                    }
                },
                // R(q) s, the matrix of `eval::rotate` in its order of operations (3D).
                Node::Rot([q, u]) if dim == 3 => {
                    let q = match g.node(*q) {
                        Node::Sym(s) => quaternions.get(s).copied(),
                        _ => None,
                    };
                    let Some(q) = q else { return Err(LowerError::NotAQuaternion) };
                    b.rotate(q, get(u))
                }
                // R(θ) s = [cos θ s.x − sin θ s.y, sin θ s.x + cos θ s.y] (2D only).
                Node::Rot([theta, u]) => {
                    let (th, u) = (get(theta)[0], get(u));
                    let trig = |b: &mut Builder, f: Func| match inputs.trig_slot(g, f, *theta) {
                        Some(slot) => b.push(Op::Input(slot)),
                        None => b.call(f, &[th]),
                    };
                    let (sin, cos) = (trig(&mut b, Func::Sin), trig(&mut b, Func::Cos));
                    let (cx, sy) = (b.mul(cos, u[0]), b.mul(sin, u[1]));
                    let (sx, cy) = (b.mul(sin, u[0]), b.mul(cos, u[1]));
                    [b.sub(cx, sy), b.add(sx, cy), 0]
                }
                // perp(u) = [−u.y, u.x]
                Node::Perp(x) => {
                    let x = get(x);
                    [b.neg(x[1]), x[0], 0]
                }
            };
            vals.insert(id, v);
        }
        let mut outputs = Vec::new();
        let mut output_ranges = Vec::new();
        for r in roots {
            let width = if g.ty(*r) == Ty::Vector { dim } else { 1 };
            let start = outputs.len();
            outputs.extend_from_slice(&vals[r][..width]);
            output_ranges.push(start..outputs.len());
        }
        let (n_inputs, input_ranges) = (inputs.n, inputs.ranges.clone());
        let mut p = Program { ops: b.ops, n_inputs, input_ranges, outputs, output_ranges };
        p.drop_dead();
        p.share_reciprocals();
        Ok(p)
    }

    /// Divisions by a value that divides twice or more become products with its reciprocal,
    /// computed once (`x/m, y/m` → `k = 1/m; x·k, y·k`): one division instead of many, the
    /// rounding the interpreter has (it computes `x · m⁻¹`).
    fn share_reciprocals(&mut self) {
        let mut divisions = vec![0u32; self.ops.len()];
        for op in &self.ops {
            if let Op::Div(_, d) = op {
                divisions[*d as usize] += 1;
            }
        }
        if divisions.iter().all(|&k| k < 2) {
            return;
        }
        let mut b = Builder::default();
        let mut map: Vec<Val> = Vec::new();
        for op in &self.ops {
            let m = |v: Val| map[v as usize];
            let v = match *op {
                Op::Div(x, d) if divisions[d as usize] >= 2 => {
                    let one = b.constant(1.0);
                    let k = b.push(Op::Div(one, m(d)));
                    b.mul(m(x), k)
                }
                other => b.push(renumber(other, &map)),
            };
            map.push(v);
        }
        for o in &mut self.outputs {
            *o = map[*o as usize];
        }
        self.ops = b.ops;
        self.drop_dead();
    }

    /// Removes operations no output depends on (inputs stay) and renumbers the rest.
    fn drop_dead(&mut self) {
        let mut live = vec![false; self.ops.len()];
        for &o in &self.outputs {
            live[o as usize] = true;
        }
        for i in (0..self.ops.len()).rev() {
            if live[i] || matches!(self.ops[i], Op::Input(_)) {
                live[i] = true;
                for a in self.ops[i].operands() {
                    live[a as usize] = true;
                }
            }
        }
        let mut new_index = vec![0; self.ops.len()];
        let mut ops = Vec::new();
        for (i, op) in self.ops.iter().enumerate() {
            if live[i] {
                new_index[i] = ops.len() as Val;
                ops.push(renumber(*op, &new_index));
            }
        }
        for o in &mut self.outputs {
            *o = new_index[*o as usize];
        }
        self.ops = ops;
    }

    /// How many times each value is used (by operations and outputs).
    pub fn use_counts(&self) -> Vec<u32> {
        let mut uses = vec![0; self.ops.len()];
        for op in &self.ops {
            for a in op.operands() {
                uses[a as usize] += 1;
            }
        }
        for &o in &self.outputs {
            uses[o as usize] += 1;
        }
        uses
    }
}

fn renumber(op: Op, m: &[Val]) -> Op {
    let r = |v: Val| m[v as usize];
    match op {
        Op::Input(_) | Op::Const(_) => op,
        Op::Add(a, b) => Op::Add(r(a), r(b)),
        Op::Sub(a, b) => Op::Sub(r(a), r(b)),
        Op::Mul(a, b) => Op::Mul(r(a), r(b)),
        Op::Div(a, b) => Op::Div(r(a), r(b)),
        Op::Neg(a) => Op::Neg(r(a)),
        Op::Powi(a, n) => Op::Powi(r(a), n),
        Op::Powf(a, b) => Op::Powf(r(a), r(b)),
        Op::Call(f, args) => Op::Call(f, args.map(r)),
        Op::Norm2(a, b) => Op::Norm2(r(a), r(b)),
        Op::Norm3(a, b, c) => Op::Norm3(r(a), r(b), r(c)),
    }
}

/// Builds operations with constant folding, identities and scalar-level CSE.
#[derive(Default)]
struct Builder {
    ops: Vec<Op>,
    index: FastMap<Op, Val>,
}

impl Builder {
    fn push(&mut self, op: Op) -> Val {
        if let Some(&v) = self.index.get(&op) {
            return v;
        }
        let v = self.ops.len() as Val;
        self.ops.push(op);
        self.index.insert(op, v);
        v
    }

    fn constant(&mut self, x: f64) -> Val {
        // One representation per value: -0 is kept (it matters for 1/x), NaNs are one NaN.
        let x = if x.is_nan() { f64::NAN } else { x };
        self.push(Op::Const(x.to_bits()))
    }

    fn k(&self, v: Val) -> Option<f64> {
        self.ops[v as usize].constant()
    }

    fn negated(&self, v: Val) -> Option<Val> {
        match self.ops[v as usize] {
            Op::Neg(x) => Some(x),
            _ => None,
        }
    }

    fn add(&mut self, a: Val, b: Val) -> Val {
        match (self.k(a), self.k(b)) {
            (Some(x), Some(y)) => return self.constant(x + y),
            (Some(0.0), _) => return b,
            (_, Some(0.0)) => return a,
            _ => {}
        }
        if let Some(y) = self.negated(b) {
            return self.sub(a, y);
        }
        if let Some(x) = self.negated(a) {
            return self.sub(b, x);
        }
        // x + (−c) = x − c, exactly.
        if let Some(y) = self.k(b).filter(|y| *y < 0.0) {
            let c = self.constant(-y);
            return self.sub(a, c);
        }
        if let Some(x) = self.k(a).filter(|x| *x < 0.0) {
            let c = self.constant(-x);
            return self.sub(b, c);
        }
        self.push(Op::Add(a.min(b), a.max(b)))
    }

    fn sub(&mut self, a: Val, b: Val) -> Val {
        match (self.k(a), self.k(b)) {
            (Some(x), Some(y)) => return self.constant(x - y),
            (Some(0.0), _) => return self.neg(b),
            (_, Some(0.0)) => return a,
            _ => {}
        }
        if let Some(y) = self.negated(b) {
            return self.add(a, y);
        }
        self.push(Op::Sub(a, b))
    }

    fn neg(&mut self, a: Val) -> Val {
        if let Some(x) = self.k(a) {
            return self.constant(-x);
        }
        match self.ops[a as usize] {
            Op::Neg(x) => x,
            // −(x − y) = y − x exactly.
            Op::Sub(x, y) => self.sub(y, x),
            _ => self.push(Op::Neg(a)),
        }
    }

    fn mul(&mut self, a: Val, b: Val) -> Val {
        match (self.k(a), self.k(b)) {
            (Some(x), Some(y)) => return self.constant(x * y),
            (Some(1.0), _) => return b,
            (_, Some(1.0)) => return a,
            (Some(-1.0), _) => return self.neg(b),
            (_, Some(-1.0)) => return self.neg(a),
            _ => {}
        }
        // Signs move outwards, where sums turn them into subtractions.
        if let Some(y) = self.k(b).filter(|y| *y < 0.0) {
            let c = self.constant(-y);
            let p = self.mul(a, c);
            return self.neg(p);
        }
        if let Some(x) = self.k(a).filter(|x| *x < 0.0) {
            let c = self.constant(-x);
            let p = self.mul(c, b);
            return self.neg(p);
        }
        if let Some(x) = self.negated(a) {
            let p = self.mul(x, b);
            return self.neg(p);
        }
        if let Some(y) = self.negated(b) {
            let p = self.mul(a, y);
            return self.neg(p);
        }
        self.push(Op::Mul(a.min(b), a.max(b)))
    }

    /// R(q) u, as [`eval::rotate`] computes it (the same products in the same order).
    fn rotate(&mut self, q: [Val; 4], u: [Val; 3]) -> [Val; 3] {
        let [w, x, y, z] = q;
        let (one, two) = (self.constant(1.0), self.constant(2.0));
        let (xx, yy, zz) = (self.mul(x, x), self.mul(y, y), self.mul(z, z));
        let (xy, xz, yz) = (self.mul(x, y), self.mul(x, z), self.mul(y, z));
        let (wx, wy, wz) = (self.mul(w, x), self.mul(w, y), self.mul(w, z));
        let diagonal = |b: &mut Builder, p: Val, r: Val| {
            let s = b.add(p, r);
            let t = b.mul(two, s);
            b.sub(one, t)
        };
        let off = |b: &mut Builder, p: Val, r: Val, plus: bool| {
            let s = if plus { b.add(p, r) } else { b.sub(p, r) };
            b.mul(two, s)
        };
        let m = [
            [diagonal(self, yy, zz), off(self, xy, wz, false), off(self, xz, wy, true)],
            [off(self, xy, wz, true), diagonal(self, xx, zz), off(self, yz, wx, false)],
            [off(self, xz, wy, false), off(self, yz, wx, true), diagonal(self, xx, yy)],
        ];
        m.map(|row| {
            let (a, b, c) = (self.mul(row[0], u[0]), self.mul(row[1], u[1]), self.mul(row[2], u[2]));
            let ab = self.add(a, b);
            self.add(ab, c)
        })
    }

    fn div(&mut self, a: Val, b: Val) -> Val {
        match (self.k(a), self.k(b)) {
            (Some(x), Some(y)) => return self.constant(x / y),
            (_, Some(1.0)) => return a,
            (_, Some(-1.0)) => return self.neg(a),
            _ => {}
        }
        if let Some(x) = self.negated(a) {
            let q = self.div(x, b);
            return self.neg(q);
        }
        if let Some(y) = self.negated(b) {
            let q = self.div(a, y);
            return self.neg(q);
        }
        self.push(Op::Div(a, b))
    }

    /// `a^e` for a constant exponent.
    fn pow_const(&mut self, a: Val, e: f64) -> Val {
        if let Some(x) = self.k(a) {
            return self.constant(eval::pow(x, e));
        }
        if e == e.trunc() && e.abs() <= i32::MAX as f64 {
            let n = e as i32;
            return match n {
                0 => self.constant(1.0),
                1 => a,
                2 => self.mul(a, a),
                _ if n < 0 => {
                    let one = self.constant(1.0);
                    let p = self.pow_const(a, -e);
                    self.div(one, p)
                }
                _ => self.push(Op::Powi(a, n)),
            };
        }
        if e == 0.5 {
            return self.call(Func::Sqrt, &[a]);
        }
        if e == -0.5 {
            let one = self.constant(1.0);
            let r = self.call(Func::Sqrt, &[a]);
            return self.div(one, r);
        }
        let e = self.constant(e);
        self.push(Op::Powf(a, e))
    }

    fn powf(&mut self, a: Val, e: Val) -> Val {
        match self.k(e) {
            Some(x) => self.pow_const(a, x),
            None => self.push(Op::Powf(a, e)),
        }
    }

    /// `f(args)`, folded when every argument is a constant.
    fn call(&mut self, f: Func, args: &[Val]) -> Val {
        let constants: Option<Vec<f64>> = args.iter().map(|&a| self.k(a)).collect();
        match constants {
            Some(xs) => self.constant(f.apply(&xs)),
            None => self.push(Op::Call(f, f.slots(args, 0))),
        }
    }

    fn norm(&mut self, xs: &[Val]) -> Val {
        let ks: Vec<Option<f64>> = xs.iter().map(|&x| self.k(x)).collect();
        match (xs, ks.as_slice()) {
            (_, [Some(x), Some(y)]) => self.constant(norm2(*x, *y)),
            (_, [Some(x), Some(y), Some(z)]) => self.constant(norm3(*x, *y, *z)),
            (&[x, y], _) => self.push(Op::Norm2(x, y)),
            (&[x, y, z], _) => self.push(Op::Norm3(x, y, z)),
            // Vectors have 2 or 3 components; anything else is the sum of squares' root.
            _ => {
                let mut acc = self.constant(0.0);
                for &x in xs {
                    let sq = self.mul(x, x);
                    acc = self.add(acc, sq);
                }
                self.call(Func::Sqrt, &[acc])
            }
        }
    }

    /// A product node: constant factors first, factors `y^−n` as divisions, the vector
    /// factor (last, if any) scaled component by component.
    fn product(&mut self, g: &Graph, xs: &[Id], vals: &FastMap<Id, [Val; 3]>, width: usize) -> [Val; 3] {
        let mut numerator = self.constant(1.0);
        let mut denominator = self.constant(1.0);
        let mut vector = None;
        for x in xs {
            if g.ty(*x) == Ty::Vector {
                vector = Some(vals[x]);
                continue;
            }
            if let Node::Pow([base, e]) = g.node(*x)
                && let Some(q) = g.as_num(*e)
                && q.is_negative()
            {
                let d = self.pow_const(vals[base][0], -q.to_f64());
                denominator = self.mul(denominator, d);
            } else {
                numerator = self.mul(numerator, vals[x][0]);
            }
        }
        let scale = self.div(numerator, denominator);
        match vector {
            None => [scale, 0, 0],
            Some(v) => {
                let mut out = [0; 3];
                for k in 0..width {
                    // s·vₖ, or vₖ/d when the numerator is 1: keep one rounding where we can.
                    out[k] = if self.k(numerator) == Some(1.0) && self.k(denominator) != Some(1.0) {
                        self.div(v[k], denominator)
                    } else {
                        self.mul(scale, v[k])
                    };
                }
                out
            }
        }
    }
}
