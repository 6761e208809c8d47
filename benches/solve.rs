//! The λ solve of an N-link chain, dense Cholesky against the band Cholesky, with divan.
//!
//! `cargo bench --bench solve`. The rows are built directly (no derivation): a chain of N
//! unit masses in a zig-zag, moving, under gravity, so A is tridiagonal and full of
//! non-trivial numbers. Both sides include the same scaling and assembly, so the
//! difference is the factorisation: O(N³) dense against O(N) banded. Dense stops at
//! N = 1000 (N = 10 000 would need 800 MB and minutes). `auto_scrambled` lists the links
//! out of order, so the band has to be found by renumbering.

/// The same allocator as the `lagrange` binary (mimalloc: a symbolic derivation allocates
/// many small forms).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use divan::{Bencher, black_box};
use lagrange::numeric::rows::{Row, Rows};
use lagrange::numeric::solve::{Method, Settings, solve_with};

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
