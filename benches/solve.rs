//! The λ solve of an N-link chain, dense Cholesky against the band Cholesky, and of a k × k
//! joint grid, the sparse Cholesky against the band and dense Cholesky, with divan.
//!
//! `cargo bench --bench solve`. The rows are built directly (no derivation): a chain of N
//! unit masses in a zig-zag, moving, under gravity, so A is tridiagonal and full of
//! non-trivial numbers. Both sides include the same scaling and assembly, so the
//! difference is the factorisation: O(N³) dense against O(N) banded. Dense stops at
//! N = 1000 (N = 10 000 would need 800 MB and minutes). `auto_scrambled` lists the links
//! out of order, so the band has to be found by renumbering.
//!
//! `chain_*` is the solve alone of the same chain's rows against a handwritten tridiagonal
//! solve of them (`chain_1_handwritten`: A = J M⁻¹ Jᵀ and b = J M⁻¹ F + c assembled from the
//! rows' J, Thomas's algorithm, the accelerations): the library's `solve_with` (the fast
//! path for chains, `numeric::chain`) and `solve_into` (the same into a kept answer), the general solve it stands in for (`solve_general`),
//! and a run's cache with J kept (reused) or changing at every solve (refactored).

/// The same allocator as the `lagrange` binary (mimalloc: a symbolic derivation allocates
/// many small forms).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use divan::{Bencher, black_box};
use lagrange::numeric::rows::{Row, Rows};
use lagrange::numeric::solve::{
    Method, Settings, Solution, SolveCache, solve_cached, solve_general, solve_into, solve_with,
};

fn main() {
    divan::main();
}

/// An N-link chain from the origin: link k joins body k−1 (or the origin) to body k.
fn chain(n: usize) -> Rows {
    let mut position = Vec::with_capacity(n);
    let mut velocity = Vec::with_capacity(n);
    let mut at = [0.0f64, 0.0];
    for k in 0..n {
        let angle = -1.2 + 0.4 * ((k % 7) as f64);
        at = [at[0] + 0.5 * angle.cos(), at[1] + 0.5 * angle.sin()];
        position.push(at);
        velocity.push([0.1 * (k as f64).sin(), 0.2 * (k as f64).cos(), 0.0]);
    }
    let rows = (0..n)
        .map(|k| {
            let prev = if k == 0 { [0.0, 0.0] } else { position[k - 1] };
            let vprev = if k == 0 { [0.0; 3] } else { velocity[k - 1] };
            let d = [position[k][0] - prev[0], position[k][1] - prev[1], 0.0];
            let u = [velocity[k][0] - vprev[0], velocity[k][1] - vprev[1], 0.0];
            let mut jacobian = vec![(k, d)];
            if k > 0 {
                jacobian.insert(0, (k - 1, [-d[0], -d[1], 0.0]));
            }
            Row { value: 0.0, rate: 0.0, bias: u[0] * u[0] + u[1] * u[1], inequality: false, jacobian }
        })
        .collect();
    Rows { dim: 2, inverse_mass: vec![1.0; n], velocity, force: vec![[0.0, -9.81, 0.0]; n], rows, axes: Vec::new() }
}

#[divan::bench(args = [10, 100, 1000])]
fn dense(bencher: Bencher, n: usize) {
    let rows = chain(n);
    let settings = Settings { method: Method::Dense, ..Settings::default() };
    bencher.bench(|| solve_with(black_box(&rows), &settings));
}

#[divan::bench(args = [10, 100, 1000, 10000])]
fn banded(bencher: Bencher, n: usize) {
    let rows = chain(n);
    let settings = Settings { method: Method::Banded, ..Settings::default() };
    bencher.bench(|| solve_with(black_box(&rows), &settings));
}

/// The chain with its links listed in a scrambled order: `Auto` renumbers it (reverse
/// Cuthill–McKee) back into a band, so this stays linear too.
#[divan::bench(args = [1000, 10000])]
fn auto_scrambled(bencher: Bencher, n: usize) {
    let mut rows = chain(n);
    let mut scrambled = vec![None; n];
    for (k, row) in rows.rows.drain(..).enumerate() {
        scrambled[(k * 7919) % n] = Some(row);
    }
    rows.rows = scrambled.into_iter().flatten().collect();
    let settings = Settings::default();
    bencher.bench(|| solve_with(black_box(&rows), &settings));
}

/// The joint grid of `constraints/solvers/joint_grid_K.toml` as rows: `k − 1` rows of `k`
/// unit masses below a fixed top row, each joined to its right and lower neighbours (the
/// top row to its anchors), positions bent by `phase` and moving, so every entry of Ã is
/// non-trivial; Ã is not banded (its band after reverse Cuthill–McKee is about 2k wide).
fn grid(k: usize, phase: f64) -> Rows {
    let bodies = (k - 1) * k;
    let at = |i: usize, j: usize| i * k + j;
    let position: Vec<[f64; 2]> = (0..bodies)
        .map(|b| {
            let (i, j) = ((b / k) as f64, (b % k) as f64);
            [j + 0.2 * (0.7 * i + phase).sin(), -(i + 1.0) + 0.2 * (0.9 * j + phase).cos()]
        })
        .collect();
    let row = |a: [f64; 2], ia: Option<usize>, b: [f64; 2], ib: usize| {
        let d = [b[0] - a[0], b[1] - a[1], 0.0];
        let mut jacobian = Vec::new();
        if let Some(ia) = ia {
            jacobian.push((ia, [-d[0], -d[1], 0.0]));
        }
        jacobian.push((ib, d));
        Row { value: 0.0, rate: 0.0, bias: 0.1 * (ib as f64).sin(), inequality: false, jacobian }
    };
    let mut rows = Vec::new();
    for i in 0..k - 1 {
        for j in 0..k {
            if i == 0 {
                rows.push(row([j as f64, 0.0], None, position[at(0, j)], at(0, j)));
            } else {
                rows.push(row(position[at(i - 1, j)], Some(at(i - 1, j)), position[at(i, j)], at(i, j)));
            }
            if j + 1 < k {
                rows.push(row(position[at(i, j)], Some(at(i, j)), position[at(i, j + 1)], at(i, j + 1)));
            }
        }
    }
    let velocity = (0..bodies).map(|b| [0.1 * (b as f64).sin(), 0.1 * (b as f64).cos(), 0.0]).collect();
    Rows {
        dim: 2,
        inverse_mass: vec![1.0; bodies],
        velocity,
        force: vec![[0.0, -10.0, 0.0]; bodies],
        rows,
        axes: Vec::new(),
    }
}

/// The grid's solve with the sparse factor, analysis included (k = 30, 100: the files'
/// 1 711 and 19 701 rows).
#[divan::bench(args = [10, 20, 30, 100])]
fn grid_sparse(bencher: Bencher, k: usize) {
    let rows = grid(k, 0.3);
    let settings = Settings { method: Method::Sparse, ..Settings::default() };
    bencher.bench(|| solve_with(black_box(&rows), &settings));
}

/// The grid's solve with the band Cholesky after reverse Cuthill–McKee (what `Auto` took
/// before the sparse factor).
#[divan::bench(args = [10, 20, 30, 100], sample_count = 10, sample_size = 1)]
fn grid_band(bencher: Bencher, k: usize) {
    let rows = grid(k, 0.3);
    let settings = Settings { method: Method::Banded, ..Settings::default() };
    bencher.bench(|| solve_with(black_box(&rows), &settings));
}

/// The grid's solve with dense Cholesky, up to `MAX_DENSE_ROWS` rows (k = 20: 741 rows).
#[divan::bench(args = [10, 20], sample_count = 10, sample_size = 1)]
fn grid_dense(bencher: Bencher, k: usize) {
    let rows = grid(k, 0.3);
    let settings = Settings { method: Method::Dense, ..Settings::default() };
    bencher.bench(|| solve_with(black_box(&rows), &settings));
}

/// What a simulation's step pays per solve on the grid: the run's cache with two states of
/// the same grid in turn, so every solve is scaled, assembled and factored anew on the kept
/// analysis (the sparse order and pattern of L, chosen by `Auto`).
#[divan::bench(args = [10, 30, 100])]
fn grid_cached_refactor(bencher: Bencher, k: usize) {
    let states = [grid(k, 0.3), grid(k, 0.4)];
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    let mut turn = 0;
    bencher.bench_local(|| {
        turn ^= 1;
        solve_cached(black_box(&states[turn]), &settings, &[], &mut cache)
    });
}

/// A step at rest: the run's cache with J unchanged, so every solve substitutes (twice,
/// with the refinement) on the kept factor.
#[divan::bench(args = [10, 30, 100])]
fn grid_cached_reuse(bencher: Bencher, k: usize) {
    let rows = grid(k, 0.3);
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    solve_cached(&rows, &settings, &[], &mut cache);
    bencher.bench_local(|| solve_cached(black_box(&rows), &settings, &[], &mut cache));
}

/// The baseline of the `chain_*` benchmarks: the chain's rows solved by hand, as an engine
/// programmer would for a chain known to be one: Aₖₖ = Σᵢ Jₖᵢ·Jₖᵢ wᵢ, Aₖ,ₖ₋₁ = Jₖ₋₁,ₖ₋₁·Jₖ,ₖ₋₁ wₖ₋₁
/// (the body the two links share), bₖ = Σᵢ Jₖᵢ·Fᵢ wᵢ + cₖ, Thomas's algorithm for A λ = −b,
/// then aᵢ = (Fᵢ + Σₖ λₖ Jₖᵢ) wᵢ. No scaling, no checks, no refinement.
#[divan::bench(name = "chain_1_handwritten", args = [10, 100, 1000, 10000])]
fn chain_handwritten(bencher: Bencher, n: usize) {
    let rows = chain(n);
    let dot = |a: &[f64; 3], b: &[f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (mut lower, mut diag, mut rhs, mut lambda) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut acceleration = vec![[0.0; 3]; n];
    bencher.bench_local(|| {
        let rows = black_box(&rows);
        let w = &rows.inverse_mass;
        for (k, row) in rows.rows.iter().enumerate() {
            let (mut a, mut b) = (0.0, row.bias);
            for (i, j) in &row.jacobian {
                a += dot(j, j) * w[*i];
                b += dot(j, &rows.force[*i]) * w[*i];
            }
            diag[k] = a;
            rhs[k] = -b;
            lower[k] = if k > 0 {
                // Row k's first entry and row k − 1's last are on the body they share.
                let ((i, j), (_, p)) =
                    (row.jacobian[0], rows.rows[k - 1].jacobian[rows.rows[k - 1].jacobian.len() - 1]);
                dot(&p, &j) * w[i]
            } else {
                0.0
            };
        }
        for k in 1..n {
            let m = lower[k] / diag[k - 1];
            diag[k] -= m * lower[k];
            rhs[k] -= m * rhs[k - 1];
        }
        lambda[n - 1] = rhs[n - 1] / diag[n - 1];
        for k in (0..n - 1).rev() {
            lambda[k] = (rhs[k] - lower[k + 1] * lambda[k + 1]) / diag[k];
        }
        for (a, f) in acceleration.iter_mut().zip(&rows.force) {
            *a = *f;
        }
        for (row, l) in rows.rows.iter().zip(&lambda) {
            for (i, j) in &row.jacobian {
                for d in 0..3 {
                    acceleration[*i][d] += l * j[d] * w[*i];
                }
            }
        }
        acceleration[n - 1]
    });
}

/// `solve_with` of the chain's rows: the fast path for chains (`numeric::chain`).
#[divan::bench(name = "chain_2_solve_with", args = [10, 100, 1000, 10000])]
fn chain_solve_with(bencher: Bencher, n: usize) {
    let rows = chain(n);
    let settings = Settings::default();
    bencher.bench(|| solve_with(black_box(&rows), &settings).acceleration[n - 1]);
}

/// [`chain_solve_with`] into an answer kept outside the loop (`solve_into`): what an engine
/// that solves every frame calls, the answer's vectors reused.
#[divan::bench(name = "chain_2_solve_into", args = [10, 100, 1000, 10000])]
fn chain_solve_into(bencher: Bencher, n: usize) {
    let rows = chain(n);
    let settings = Settings::default();
    let mut answer = Solution::default();
    bencher.bench_local(|| {
        solve_into(black_box(&rows), &settings, &mut answer);
        answer.acceleration[n - 1]
    });
}

/// The general solve the fast path stands in for (`solve_general`: scaling buffers, terms of
/// Ã, the plan, the band factor, its refinement): the same numbers bit for bit.
#[divan::bench(name = "chain_3_general", args = [10, 100, 1000, 10000])]
fn chain_general(bencher: Bencher, n: usize) {
    let rows = chain(n);
    let settings = Settings::default();
    bencher.bench(|| solve_general(black_box(&rows), &settings, &[]).acceleration[n - 1]);
}

/// A run's cache with J kept (a SHAKE iteration, a step's start): the substitutions alone.
#[divan::bench(name = "chain_4_cached_reused", args = [10, 100, 1000, 10000])]
fn chain_cached_reused(bencher: Bencher, n: usize) {
    let rows = chain(n);
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    solve_cached(&rows, &settings, &[], &mut cache);
    bencher.bench_local(|| solve_cached(black_box(&rows), &settings, &[], &mut cache).acceleration[n - 1]);
}

/// A run's cache with J changing at every solve (two states in turn, J differing from the
/// first row): scaled, assembled and factored anew each time.
#[divan::bench(name = "chain_5_cached_refactored", args = [10, 100, 1000, 10000])]
fn chain_cached_refactored(bencher: Bencher, n: usize) {
    let first = chain(n);
    let mut second = first.clone();
    for row in &mut second.rows {
        for (_, j) in &mut row.jacobian {
            j[0] *= 1.0 + 1e-9;
        }
    }
    let states = [first, second];
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    let mut turn = 0;
    bencher.bench_local(|| {
        turn ^= 1;
        solve_cached(black_box(&states[turn]), &settings, &[], &mut cache).acceleration[n - 1]
    });
}
