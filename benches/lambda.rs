//! The generated module's `lambda()` of an N-link chain against a handwritten tridiagonal
//! step of the same chain, in the same run (issue 16: generated λ ≤ 1.2× handwritten).
//!
//! `cargo bench --bench lambda`. The chains are `cargo run --example chain -- N` (unit-free
//! links `l`, one mass symbol `m`, hanging from the origin), their modules `lagrange
//! generate` writes, checked in under `benches/generated/` and kept current by
//! `tests/generate.rs`: N = 10 (A dense, `Lambda::Dense`) and N = 100 (A as its band,
//! `Lambda::Band`). N = 1 000 is not checked in: its module is over 2 MB.
//!
//! The handwritten step is what an engine programmer writes for this chain: one pass over
//! the links for dₖ = rₖ − rₖ₋₁ (r₀ = 0), uₖ = vₖ − vₖ₋₁, the tridiagonal A and b
//! (`chain_by_hand` in `benches/eval.rs`), then L D Lᵀ of the tridiagonal (Thomas), no
//! checks. Both sides are asserted to give the same λ before any sample.

/// The same allocator as the `lagrange` binary (mimalloc), as the other benchmarks.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use divan::{Bencher, black_box};

#[allow(dead_code, clippy::all)]
mod chain10 {
    include!("generated/chain_10.rs");
}

#[allow(dead_code, clippy::all)]
mod chain100 {
    include!("generated/chain_100.rs");
}

fn main() {
    divan::main();
}

/// One vector per body.
type PerBody<const N: usize> = [[f64; 2]; N];

/// A chain state: positions along a zig-zag, moving, under a force that is not gravity's
/// alone, and a mass that is not 1, so every term of A and b is a non-trivial number.
fn chain_state<const N: usize>() -> (PerBody<N>, PerBody<N>, PerBody<N>, f64) {
    let mut r = [[0.0; 2]; N];
    let mut v = [[0.0; 2]; N];
    let mut f = [[0.0; 2]; N];
    for i in 0..N {
        let x = i as f64;
        r[i] = [0.5 * (x + 1.0), if i % 2 == 0 { 0.1 } else { -0.1 }];
        v[i] = [0.1 * x.sin(), -0.05 * x.cos()];
        f[i] = [0.3 * (0.7 * x).cos(), -9.81];
    }
    (r, v, f, 1.3)
}

/// λ of the chain by hand: the tridiagonal A (diagonal `diag`, above it `off`) and −b, one
/// pass over the links, then Thomas on A λ = −b. Aₖₖ = dₖ·dₖ (1/mₖ₋₁ + 1/mₖ) (the pinned
/// link: dₖ·dₖ/m), Aₖ,ₖ₊₁ = −dₖ·dₖ₊₁/m, bₖ = dₖ·(Fₖ − Fₖ₋₁)/m + uₖ·uₖ (F₀ = 0), for C/κ
/// with κ = 2 as the generated module's λ.
#[inline(never)]
fn lambda_by_hand<const N: usize>(r: &PerBody<N>, v: &PerBody<N>, f: &PerBody<N>, m: f64) -> [f64; N] {
    let w = 1.0 / m;
    let mut diag = [0.0; N];
    let mut off = [0.0; N];
    let mut x = [0.0; N];
    let (mut rp, mut vp, mut fp) = ([0.0; 2], [0.0; 2], [0.0; 2]);
    let mut dp = [0.0; 2];
    for k in 0..N {
        let d = [r[k][0] - rp[0], r[k][1] - rp[1]];
        let u = [v[k][0] - vp[0], v[k][1] - vp[1]];
        let dd = d[0] * d[0] + d[1] * d[1];
        diag[k] = if k == 0 { dd * w } else { 2.0 * dd * w };
        if k > 0 {
            off[k - 1] = -(dp[0] * d[0] + dp[1] * d[1]) * w;
        }
        x[k] = -((d[0] * (f[k][0] - fp[0]) + d[1] * (f[k][1] - fp[1])) * w + u[0] * u[0] + u[1] * u[1]);
        (rp, vp, fp, dp) = (r[k], v[k], f[k], d);
    }
    // L D Lᵀ of the tridiagonal: forward elimination, then back substitution.
    for k in 1..N {
        let l = off[k - 1] / diag[k - 1];
        diag[k] -= l * off[k - 1];
        x[k] -= l * x[k - 1];
    }
    x[N - 1] /= diag[N - 1];
    for k in (0..N - 1).rev() {
        x[k] = (x[k] - off[k] * x[k + 1]) / diag[k];
    }
    x
}

/// Fills a generated module's `State` from per-body arrays: `$rk $vk $Fk` names body k's
/// fields, in order.
macro_rules! state {
    ($module:ident, $r:expr, $v:expr, $f:expr, $m:expr; $($rn:ident $vn:ident $fname:ident),* $(,)?) => {{
        let (r, v, f) = ($r, $v, $f);
        let mut s = $module::State { m: $m, ..Default::default() };
        let mut k = 0;
        $(
            s.$rn = r[k];
            s.$vn = v[k];
            s.$fname = f[k];
            k += 1;
        )*
        assert_eq!(k, $module::BODIES);
        s
    }};
}

fn state10() -> chain10::State {
    let (r, v, f, m) = chain_state::<10>();
    state!(chain10, r, v, f, m;
        r1 v1 F1, r2 v2 F2, r3 v3 F3, r4 v4 F4, r5 v5 F5, r6 v6 F6, r7 v7 F7, r8 v8 F8, r9 v9 F9, r10 v10 F10)
}

fn state100() -> chain100::State {
    let (r, v, f, m) = chain_state::<100>();
    state!(chain100, r, v, f, m;
        r1 v1 F1, r2 v2 F2, r3 v3 F3, r4 v4 F4, r5 v5 F5, r6 v6 F6, r7 v7 F7, r8 v8 F8, r9 v9 F9, r10 v10 F10,
        r11 v11 F11, r12 v12 F12, r13 v13 F13, r14 v14 F14, r15 v15 F15, r16 v16 F16, r17 v17 F17, r18 v18 F18,
        r19 v19 F19, r20 v20 F20, r21 v21 F21, r22 v22 F22, r23 v23 F23, r24 v24 F24, r25 v25 F25, r26 v26 F26,
        r27 v27 F27, r28 v28 F28, r29 v29 F29, r30 v30 F30, r31 v31 F31, r32 v32 F32, r33 v33 F33, r34 v34 F34,
        r35 v35 F35, r36 v36 F36, r37 v37 F37, r38 v38 F38, r39 v39 F39, r40 v40 F40, r41 v41 F41, r42 v42 F42,
        r43 v43 F43, r44 v44 F44, r45 v45 F45, r46 v46 F46, r47 v47 F47, r48 v48 F48, r49 v49 F49, r50 v50 F50,
        r51 v51 F51, r52 v52 F52, r53 v53 F53, r54 v54 F54, r55 v55 F55, r56 v56 F56, r57 v57 F57, r58 v58 F58,
        r59 v59 F59, r60 v60 F60, r61 v61 F61, r62 v62 F62, r63 v63 F63, r64 v64 F64, r65 v65 F65, r66 v66 F66,
        r67 v67 F67, r68 v68 F68, r69 v69 F69, r70 v70 F70, r71 v71 F71, r72 v72 F72, r73 v73 F73, r74 v74 F74,
        r75 v75 F75, r76 v76 F76, r77 v77 F77, r78 v78 F78, r79 v79 F79, r80 v80 F80, r81 v81 F81, r82 v82 F82,
        r83 v83 F83, r84 v84 F84, r85 v85 F85, r86 v86 F86, r87 v87 F87, r88 v88 F88, r89 v89 F89, r90 v90 F90,
        r91 v91 F91, r92 v92 F92, r93 v93 F93, r94 v94 F94, r95 v95 F95, r96 v96 F96, r97 v97 F97, r98 v98 F98,
        r99 v99 F99, r100 v100 F100)
}

/// The baseline must compute what the generated code computes: the same λ to round-off
/// (relative to the largest |λ|: the two factorisations differ in their rounding).
fn assert_same(hand: &[f64], generated: &[f64]) {
    let scale = hand.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(scale > 0.0 && hand.iter().all(|x| x.is_finite()), "handwritten λ: {hand:?}");
    for (k, (x, y)) in hand.iter().zip(generated).enumerate() {
        assert!((x - y).abs() <= 1e-12 * scale, "λ[{k}]: handwritten {x}, generated {y}");
    }
}

#[divan::bench(name = "chain10_lambda_1_handwritten")]
fn chain10_handwritten(b: Bencher) {
    let (r, v, f, m) = chain_state::<10>();
    assert_same(&lambda_by_hand(&r, &v, &f, m), &chain10::lambda(&state10()));
    b.bench_local(|| lambda_by_hand(black_box(&r), black_box(&v), black_box(&f), black_box(m)));
}

#[divan::bench(name = "chain10_lambda_2_generated")]
fn chain10_generated(b: Bencher) {
    let s = state10();
    b.bench_local(|| chain10::lambda(black_box(&s)));
}

#[divan::bench(name = "chain100_lambda_1_handwritten")]
fn chain100_handwritten(b: Bencher) {
    let (r, v, f, m) = chain_state::<100>();
    assert_same(&lambda_by_hand(&r, &v, &f, m), &chain100::lambda(&state100()));
    b.bench_local(|| lambda_by_hand(black_box(&r), black_box(&v), black_box(&f), black_box(m)));
}

#[divan::bench(name = "chain100_lambda_2_generated")]
fn chain100_generated(b: Bencher) {
    let s = state100();
    b.bench_local(|| chain100::lambda(black_box(&s)));
}
