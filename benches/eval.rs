//! Evaluation speed, always against a handwritten baseline from the same run.
//!
//! The article's bead force F_c = −(m v·v + F·r)/(r·r) r, a 10-link chain's A and b, and the
//! 2D revolute joint's wrench (λ of its two rows, the force and torque on both bodies), each
//! computed by: handwritten Rust (the revolute joint Box2D-style), the code `lagrange generate` writes (checked in under
//! `benches/generated/`, kept current by `tests/generate.rs`), the compiled tape for one
//! state, and the tape batched over many states (structure of arrays).
//!
//! With the `jit` feature, the bead and the chain also run as the tape compiled to machine
//! code (`bead_4_jit`, `chain10_ab_4_jit`: `Tape::jit`, one state a call), and `jit_compile`
//! times the compilation itself (what loading a tape would cost).
//!
//! The bead also runs over a few states at once (`bead_few_*`: 1 to 8): the handwritten loop,
//! `eval_batch_serial`, and `Tape::eval_few`, whose registers hold all the states' values.
//!
//! The bead's batch also runs on one core (calls below `PARALLEL_MIN`), so the tape's own
//! speed can be told from what rayon adds or, on a busy machine, costs.
//!
//! Run: `cargo bench --bench eval`. Per-state figures of batches are the time divided by
//! the batch size (divan also prints the throughput).

/// The same allocator as the `lagrange` binary (mimalloc: a symbolic derivation allocates
/// many small forms).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use divan::{Bencher, black_box, counter::ItemsCount};
use lagrange::derive::derive;
use lagrange::expr::{Id, Symbol};
use lagrange::model::file::load;
use lagrange::numeric::Tape;
use lagrange::numeric::tape::PARALLEL_MIN;

#[allow(dead_code, clippy::all)]
mod bead {
    include!("generated/bead_on_wire.rs");
}

#[allow(dead_code, clippy::all)]
mod chain {
    include!("generated/chain_10.rs");
}

#[allow(dead_code, clippy::all)]
mod revolute {
    include!("generated/revolute.rs");
}

fn main() {
    divan::main();
}

const BATCHES: [usize; 2] = [1024, 65536];

// ---- the bead -----------------------------------------------------------------------------

/// A bead state for the handwritten function, passed by reference like the generated one.
struct BeadState {
    r: [f64; 2],
    v: [f64; 2],
    f: [f64; 2],
    m: f64,
}

/// The article's formula by hand: λ = −(m v·v + F·r)/(r·r), F_c = λ r.
#[inline(never)]
fn bead_by_hand(s: &BeadState) -> [f64; 2] {
    let BeadState { r, v, f, m } = *s;
    let lambda = -(m * (v[0] * v[0] + v[1] * v[1]) + (f[0] * r[0] + f[1] * r[1])) / (r[0] * r[0] + r[1] * r[1]);
    [lambda * r[0], lambda * r[1]]
}

#[inline(never)]
fn bead_generated(s: &bead::State) -> [f64; 2] {
    bead::force_bead(s)
}

/// The bead's force as a tape over the inputs [r, v, F, m] (7 slots).
fn bead_tape() -> Tape {
    let l = load(include_str!("../constraints/bead_on_wire.toml")).expect("bead file");
    let d = derive(&l.system).expect("derives");
    let force = d.forces.as_ref().expect("one constraint")[0].1;
    let b = &l.system.bodies[0];
    let m = l.system.graph.symbol_named("m").expect("m");
    Tape::compile(&d.graph, &[force], &[b.position, b.velocity, b.force, m]).expect("compiles")
}

const R: [f64; 2] = [1.2, -1.6];
const V: [f64; 2] = [0.3, 0.9];
const F: [f64; 2] = [0.0, -9.81];
const M: f64 = 1.5;

#[divan::bench(name = "bead_1_handwritten")]
fn bead_handwritten(b: Bencher) {
    let s = BeadState { r: R, v: V, f: F, m: M };
    b.bench_local(|| bead_by_hand(black_box(&s)));
}

#[divan::bench(name = "bead_2_generated")]
fn bead_generated_bench(b: Bencher) {
    let s = bead::State { r: R, v: V, F, m: M, ..Default::default() };
    b.bench_local(|| bead_generated(black_box(&s)));
}

#[divan::bench(name = "bead_3_tape")]
fn bead_tape_bench(b: Bencher) {
    let tape = bead_tape();
    let mut scratch = tape.scratch();
    let inputs = [R[0], R[1], V[0], V[1], F[0], F[1], M];
    let mut out = [0.0; 2];
    b.bench_local(|| {
        tape.eval(black_box(&inputs), &mut scratch, &mut out);
        black_box(out)
    });
}

#[cfg(feature = "jit")]
#[divan::bench(name = "bead_4_jit")]
fn bead_jit_bench(b: Bencher) {
    let tape = bead_tape();
    let jit = tape.jit().expect("this host compiles tapes");
    let inputs = [R[0], R[1], V[0], V[1], F[0], F[1], M];
    let mut out = [0.0; 2];
    b.bench_local(|| {
        jit.eval(black_box(&inputs), &mut out);
        black_box(out)
    });
}

#[cfg(feature = "jit")]
#[divan::bench(name = "bead_5_jit_read_in_place")]
fn bead_jit_in_place_bench(b: Bencher) {
    let tape = bead_tape();
    let jit = tape.jit().expect("this host compiles tapes");
    let inputs = [R[0], R[1], V[0], V[1], F[0], F[1], M];
    let mut out = [0.0; 2];
    b.bench_local(|| {
        jit.eval(black_box(&inputs), &mut out);
        black_box(&out);
    });
}

#[divan::bench(name = "bead_3_tape_read_in_place")]
fn bead_tape_in_place_bench(b: Bencher) {
    let tape = bead_tape();
    let mut scratch = tape.scratch();
    let inputs = [R[0], R[1], V[0], V[1], F[0], F[1], M];
    let mut out = [0.0; 2];
    b.bench_local(|| {
        tape.eval(black_box(&inputs), &mut scratch, &mut out);
        black_box(&out);
    });
}

/// Compiling a tape to machine code: the bead's force, the chain's A and b.
#[cfg(feature = "jit")]
#[divan::bench(name = "jit_compile", args = ["bead", "chain10_ab"], sample_count = 30)]
fn jit_compile(b: Bencher, what: &str) {
    let tape = if what == "bead" { bead_tape() } else { chain_tape() };
    b.bench_local(|| tape.jit().expect("this host compiles tapes"));
}

/// Random bead states, structure of arrays: rows rx, ry, vx, vy, Fx, Fy, m.
fn bead_states(n: usize) -> Vec<f64> {
    let mut x = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut soa = Vec::with_capacity(7 * n);
    for row in 0..7 {
        for _ in 0..n {
            soa.push(if row == 6 { 0.5 + next() } else { 4.0 * next() - 2.0 });
        }
    }
    soa
}

/// The handwritten batch loop over the same layout.
#[inline(never)]
fn bead_batch_by_hand(n: usize, inputs: &[f64], out: &mut [f64]) {
    let (rx, rest) = inputs.split_at(n);
    let (ry, rest) = rest.split_at(n);
    let (vx, rest) = rest.split_at(n);
    let (vy, rest) = rest.split_at(n);
    let (fx, rest) = rest.split_at(n);
    let (fy, m) = rest.split_at(n);
    let (ox, oy) = out.split_at_mut(n);
    for s in 0..n.min(m.len()).min(ox.len()).min(oy.len()) {
        let lambda = -(m[s] * (vx[s] * vx[s] + vy[s] * vy[s]) + (fx[s] * rx[s] + fy[s] * ry[s]))
            / (rx[s] * rx[s] + ry[s] * ry[s]);
        ox[s] = lambda * rx[s];
        oy[s] = lambda * ry[s];
    }
}

#[divan::bench(name = "bead_batch_1_handwritten", args = BATCHES)]
fn bead_batch_handwritten(b: Bencher, n: usize) {
    let inputs = bead_states(n);
    let mut out = vec![0.0; 2 * n];
    b.counter(ItemsCount::new(n)).bench_local(|| bead_batch_by_hand(n, black_box(&inputs), &mut out));
}

#[divan::bench(name = "bead_batch_2_tape", args = BATCHES)]
fn bead_batch_tape(b: Bencher, n: usize) {
    let tape = bead_tape();
    let inputs = bead_states(n);
    let mut out = vec![0.0; 2 * n];
    let mut scratch = tape.batch_scratch();
    b.counter(ItemsCount::new(n)).bench_local(|| tape.eval_batch(n, black_box(&inputs), &mut scratch, &mut out));
}

/// The same batch on one core: calls of fewer than `PARALLEL_MIN` states each (the rows of a
/// call are slices of the big rows, so this copies the inputs once per call, outside timing).
#[divan::bench(name = "bead_batch_3_tape_one_core", args = BATCHES)]
fn bead_batch_tape_one_core(b: Bencher, n: usize) {
    let tape = bead_tape();
    let inputs = bead_states(n);
    let piece = (PARALLEL_MIN / 2).min(n);
    // Structure of arrays per piece: the rows of states s..s + piece.
    let pieces: Vec<Vec<f64>> = (0..n)
        .step_by(piece)
        .map(|s| (0..7).flat_map(|row| inputs[row * n + s..row * n + s + piece].iter().copied()).collect())
        .collect();
    let mut out = vec![0.0; 2 * piece];
    let mut scratch = tape.batch_scratch();
    b.counter(ItemsCount::new(n)).bench_local(|| {
        for p in &pieces {
            tape.eval_batch(piece, black_box(p), &mut scratch, &mut out);
        }
    });
}

/// A few states at once (`FEW`: what a caller with a handful of bodies or candidate states
/// has), beside the handwritten loop over the same layout: per state, the tape's call and
/// dispatch are shared by the states and their divisions overlap, as the handwritten
/// loop's do.
const FEW: [usize; 4] = [1, 2, 4, 8];

#[divan::bench(name = "bead_few_1_handwritten", args = FEW)]
fn bead_few_handwritten(b: Bencher, n: usize) {
    let inputs = bead_states(n);
    let mut out = vec![0.0; 2 * n];
    b.counter(ItemsCount::new(n)).bench_local(|| bead_batch_by_hand(n, black_box(&inputs), &mut out));
}

#[divan::bench(name = "bead_few_2_tape", args = FEW)]
fn bead_few_tape(b: Bencher, n: usize) {
    let tape = bead_tape();
    let inputs = bead_states(n);
    let mut out = vec![0.0; 2 * n];
    let mut scratch = tape.batch_scratch();
    b.counter(ItemsCount::new(n)).bench_local(|| tape.eval_batch_serial(n, black_box(&inputs), &mut scratch, &mut out));
}

/// The same few states through [`Tape::eval_few`]: every register holds the `K` states'
/// values, one call and one dispatch per instruction for all of them.
#[divan::bench(name = "bead_few_3_tape_few", consts = [2, 4, 8])]
fn bead_few_tape_few<const K: usize>(b: Bencher) {
    let tape = bead_tape();
    let soa = bead_states(K);
    let inputs: Vec<[f64; K]> = (0..7).map(|j| std::array::from_fn(|s| soa[j * K + s])).collect();
    let mut out = [[0.0; K]; 2];
    let mut scratch = tape.few_scratch::<K>();
    b.counter(ItemsCount::new(K)).bench_local(|| {
        tape.eval_few(black_box(&inputs), &mut scratch, &mut out);
        black_box(out)
    });
}

// ---- the 10-link chain: A and b -----------------------------------------------------------

const LINKS: usize = 10;

/// One vector per body.
type PerBody = [[f64; 2]; LINKS];

/// A chain state: positions along a zig-zag, some velocities and forces.
fn chain_state() -> (PerBody, PerBody, PerBody, f64) {
    let mut r = [[0.0; 2]; LINKS];
    let mut v = [[0.0; 2]; LINKS];
    let mut f = [[0.0; 2]; LINKS];
    for i in 0..LINKS {
        let x = i as f64;
        r[i] = [0.5 * (x + 1.0), if i % 2 == 0 { 0.1 } else { -0.1 }];
        v[i] = [0.1 * x, -0.05 * x];
        f[i] = [0.0, -9.81];
    }
    (r, v, f, 1.0)
}

/// A and b of the chain by hand: dₖ = rₖ − rₖ₋₁ (r₀ = 0), Aₖₖ = dₖ·dₖ (1/mₖ₋₁ + 1/mₖ),
/// Aₖ,ₖ₊₁ = −dₖ·dₖ₊₁ / mₖ, bₖ = dₖ·(Fₖ/mₖ − Fₖ₋₁/mₖ₋₁) + |vₖ − vₖ₋₁|², in the generated layout.
#[inline(never)]
fn chain_by_hand(r: &PerBody, v: &PerBody, f: &PerBody, m: f64) -> ([[f64; LINKS]; LINKS], [f64; LINKS]) {
    let inv_m = 1.0 / m;
    let mut d = [[0.0; 2]; LINKS];
    let mut u = [[0.0; 2]; LINKS];
    let mut g = [[0.0; 2]; LINKS];
    for k in 0..LINKS {
        let (rp, vp, fp) = if k == 0 { ([0.0; 2], [0.0; 2], [0.0; 2]) } else { (r[k - 1], v[k - 1], f[k - 1]) };
        d[k] = [r[k][0] - rp[0], r[k][1] - rp[1]];
        u[k] = [v[k][0] - vp[0], v[k][1] - vp[1]];
        g[k] = [f[k][0] - fp[0], f[k][1] - fp[1]];
    }
    let mut a = [[0.0; LINKS]; LINKS];
    let mut b = [0.0; LINKS];
    for k in 0..LINKS {
        let dd = d[k][0] * d[k][0] + d[k][1] * d[k][1];
        a[k][k] = if k == 0 { dd * inv_m } else { 2.0 * dd * inv_m };
        if k + 1 < LINKS {
            let off = -(d[k][0] * d[k + 1][0] + d[k][1] * d[k + 1][1]) * inv_m;
            a[k][k + 1] = off;
            a[k + 1][k] = off;
        }
        b[k] = (d[k][0] * g[k][0] + d[k][1] * g[k][1]) * inv_m + u[k][0] * u[k][0] + u[k][1] * u[k][1];
    }
    (a, b)
}

#[inline(never)]
fn chain_generated(s: &chain::State) -> ([[f64; LINKS]; LINKS], [f64; LINKS]) {
    (chain::a_matrix(s), chain::b_vector(s))
}

fn chain_generated_state() -> chain::State {
    let (r, v, f, m) = chain_state();
    chain::State {
        r1: r[0],
        r2: r[1],
        r3: r[2],
        r4: r[3],
        r5: r[4],
        r6: r[5],
        r7: r[6],
        r8: r[7],
        r9: r[8],
        r10: r[9],
        v1: v[0],
        v2: v[1],
        v3: v[2],
        v4: v[3],
        v5: v[4],
        v6: v[5],
        v7: v[6],
        v8: v[7],
        v9: v[8],
        v10: v[9],
        F1: f[0],
        F2: f[1],
        F3: f[2],
        F4: f[3],
        F5: f[4],
        F6: f[5],
        F7: f[6],
        F8: f[7],
        F9: f[8],
        F10: f[9],
        m,
        ..Default::default()
    }
}

/// A tape of the chain's non-zero A entries and b over the inputs [r₁…r₁₀, v₁…v₁₀, F₁…F₁₀, m].
fn chain_tape() -> Tape {
    let l = load(include_str!("data/chain_10.toml")).expect("chain file");
    let d = derive(&l.system).expect("derives");
    let mut roots: Vec<Id> = d.a.iter().map(|e| e.2).collect();
    roots.extend(&d.b);
    let s = &l.system;
    let mut inputs: Vec<Symbol> = s.bodies.iter().map(|b| b.position).collect();
    inputs.extend(s.bodies.iter().map(|b| b.velocity));
    inputs.extend(s.bodies.iter().map(|b| b.force));
    inputs.push(s.graph.symbol_named("m").expect("m"));
    Tape::compile(&d.graph, &roots, &inputs).expect("compiles")
}

fn chain_inputs() -> Vec<f64> {
    let (r, v, f, m) = chain_state();
    let mut x: Vec<f64> = r.iter().chain(&v).chain(&f).flatten().copied().collect();
    x.push(m);
    x
}

#[divan::bench(name = "chain10_ab_1_handwritten")]
fn chain_handwritten(b: Bencher) {
    let (r, v, f, m) = chain_state();
    // The baseline must compute what the generated code computes.
    let (hand, generated) = (chain_by_hand(&r, &v, &f, m), chain_generated(&chain_generated_state()));
    for (x, y) in hand.0.iter().flatten().chain(&hand.1).zip(generated.0.iter().flatten().chain(&generated.1)) {
        assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "handwritten chain differs: {x} vs {y}");
    }
    b.bench_local(|| chain_by_hand(black_box(&r), black_box(&v), black_box(&f), black_box(m)));
}

#[divan::bench(name = "chain10_ab_2_generated")]
fn chain_generated_bench(b: Bencher) {
    let s = chain_generated_state();
    b.bench_local(|| chain_generated(black_box(&s)));
}

#[divan::bench(name = "chain10_ab_3_tape")]
fn chain_tape_bench(b: Bencher) {
    let tape = chain_tape();
    let mut scratch = tape.scratch();
    let inputs = chain_inputs();
    let mut out = vec![0.0; tape.output_len()];
    b.bench_local(|| tape.eval(black_box(&inputs), &mut scratch, &mut out));
}

#[cfg(feature = "jit")]
#[divan::bench(name = "chain10_ab_4_jit")]
fn chain_jit_bench(b: Bencher) {
    let tape = chain_tape();
    let jit = tape.jit().expect("this host compiles tapes");
    let inputs = chain_inputs();
    let mut out = vec![0.0; tape.output_len()];
    b.bench_local(|| jit.eval(black_box(&inputs), &mut out));
}

#[divan::bench(name = "chain10_ab_batch_tape", args = BATCHES)]
fn chain_batch_tape(b: Bencher, n: usize) {
    let tape = chain_tape();
    let one = chain_inputs();
    let inputs: Vec<f64> = one.iter().flat_map(|&x| std::iter::repeat_n(x, n)).collect();
    let mut out = vec![0.0; tape.output_len() * n];
    let mut scratch = tape.batch_scratch();
    b.counter(ItemsCount::new(n)).bench_local(|| tape.eval_batch(n, black_box(&inputs), &mut scratch, &mut out));
}

// ---- the 2D revolute joint ----------------------------------------------------------------

/// Two rigid bodies' numbers for the handwritten revolute joint (`constraints/joints/revolute.toml`).
struct Rigid2 {
    x: [f64; 2],
    v: [f64; 2],
    f: [f64; 2],
    m: f64,
    th: f64,
    w: f64,
    t: f64,
    i: f64,
}

const ANCHOR_A: [f64; 2] = [0.5, 0.0];
const ANCHOR_B: [f64; 2] = [-0.5, 0.0];

fn revolute_bodies() -> (Rigid2, Rigid2) {
    let a = Rigid2 { x: [0.1, 0.2], v: [0.3, -0.4], f: [0.5, -9.81], m: 1.5, th: 0.3, w: 1.2, t: 0.2, i: 0.4 };
    let b = Rigid2 { x: [1.05, 0.35], v: [-0.2, 0.6], f: [-0.3, -4.9], m: 0.8, th: -0.7, w: -0.5, t: -0.1, i: 0.25 };
    (a, b)
}

/// The pin's wrench by hand, as Box2D v3's `revolute_joint.c` lays it out (rA, rB the anchors
/// from the centres, K its 2×2 effective mass), at the acceleration level: C = pA − pB, so
/// J = [E, perp(rA), −E, −perp(rB)], K = J M⁻¹ Jᵀ, b = J M⁻¹ (F, τ) + c with c = −ωA² rA + ωB² rB,
/// λ = −K⁻¹ b (Cramer), and the wrench (λ, rA × λ) on A and (−λ, −rB × λ) on B.
#[inline(never)]
fn revolute_by_hand(a: &Rigid2, b: &Rigid2) -> ([[f64; 2]; 2], [f64; 2]) {
    let (ca, sa) = (a.th.cos(), a.th.sin());
    let (cb, sb) = (b.th.cos(), b.th.sin());
    let ra = [ca * ANCHOR_A[0] - sa * ANCHOR_A[1], sa * ANCHOR_A[0] + ca * ANCHOR_A[1]];
    let rb = [cb * ANCHOR_B[0] - sb * ANCHOR_B[1], sb * ANCHOR_B[0] + cb * ANCHOR_B[1]];
    let (ma, mb, ia, ib) = (1.0 / a.m, 1.0 / b.m, 1.0 / a.i, 1.0 / b.i);
    let k11 = ma + mb + ra[1] * ra[1] * ia + rb[1] * rb[1] * ib;
    let k12 = -ra[1] * ra[0] * ia - rb[1] * rb[0] * ib;
    let k22 = ma + mb + ra[0] * ra[0] * ia + rb[0] * rb[0] * ib;
    // perp(r) = [−r.y, r.x]
    let b1 = a.f[0] * ma - ra[1] * a.t * ia - b.f[0] * mb + rb[1] * b.t * ib - a.w * a.w * ra[0] + b.w * b.w * rb[0];
    let b2 = a.f[1] * ma + ra[0] * a.t * ia - b.f[1] * mb - rb[0] * b.t * ib - a.w * a.w * ra[1] + b.w * b.w * rb[1];
    let det = k11 * k22 - k12 * k12;
    let l = [-(k22 * b1 - k12 * b2) / det, -(k11 * b2 - k12 * b1) / det];
    let torque_a = ra[0] * l[1] - ra[1] * l[0];
    let torque_b = -(rb[0] * l[1] - rb[1] * l[0]);
    ([l, [-l[0], -l[1]]], [torque_a, torque_b])
}

/// The generated module's wrench: `dense_solution` (one program of A, b, J, Jʷ and the 2×2
/// A λ = −b by Cramer's rule under L D Lᵀ's pivot rule), the forces and the torques from one
/// solve; its rows' solve (`solution`, what `lagrange solve` gives) where that gives up,
/// which this state never needs.
#[inline(never)]
fn revolute_generated(s: &revolute::State) -> ([[f64; 2]; 2], [f64; 2]) {
    match revolute::dense_solution(s) {
        Some((_, f, t)) => (f, t),
        None => {
            let x = revolute::solution(s);
            ([x.force[0], x.force[1]], [x.force[2][0], x.force[3][0]])
        }
    }
}

/// The same wrench through the rows' solve (`solution`): the general path (row scaling,
/// contact states, rows on the heap), for comparison.
#[divan::bench(name = "revolute_wrench_3_rows_solve")]
fn revolute_rows_bench(bencher: Bencher) {
    let s = revolute_state();
    bencher.bench_local(|| {
        let x = revolute::solution(black_box(&s));
        ([x.force[0], x.force[1]], [x.force[2][0], x.force[3][0]])
    });
}

fn revolute_state() -> revolute::State {
    let (a, b) = revolute_bodies();
    revolute::State {
        x1: a.x,
        v1: a.v,
        F1: a.f,
        m1: a.m,
        th1: a.th,
        w1: a.w,
        T1: a.t,
        I1: a.i,
        x2: b.x,
        v2: b.v,
        F2: b.f,
        m2: b.m,
        th2: b.th,
        w2: b.w,
        T2: b.t,
        I2: b.i,
        sA: ANCHOR_A,
        sB: ANCHOR_B,
        ..Default::default()
    }
}

#[divan::bench(name = "revolute_wrench_1_handwritten")]
fn revolute_handwritten(bencher: Bencher) {
    let (a, b) = revolute_bodies();
    // The baseline does the generated module's work: the same wrench (checked once, untimed).
    let (hand, generated) = (revolute_by_hand(&a, &b), revolute_generated(&revolute_state()));
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0);
    assert!(
        hand.0.iter().flatten().zip(generated.0.iter().flatten()).all(|(x, y)| close(*x, *y)),
        "{hand:?} {generated:?}"
    );
    assert!(hand.1.iter().zip(&generated.1).all(|(x, y)| close(*x, *y)), "{hand:?} {generated:?}");
    bencher.bench_local(|| revolute_by_hand(black_box(&a), black_box(&b)));
}

#[divan::bench(name = "revolute_wrench_2_generated")]
fn revolute_generated_bench(bencher: Bencher) {
    let s = revolute_state();
    bencher.bench_local(|| revolute_generated(black_box(&s)));
}
