//! Cost of a simulation step against the size of a chain (N = 10, 100, 1000, 10 000 links,
//! `lagrange::scenario::chain`), and a handwritten pendulum step as the baseline of what a
//! step can cost.
//!
//! `cargo bench --bench simulate`. Each sample is one `simulate` call of one step (setting
//! up the run, the recorded state at step 0 plus one Verlet + projection step). Rows come
//! from the compiled tape and the λ solve is a band Cholesky (a chain's A is tridiagonal),
//! so the cost per step grows linearly in N. Deriving the 10 000-link chain takes ~20 s
//! before its samples start.

/// The same allocator as the `lagrange` binary (mimalloc: a symbolic derivation allocates
/// many small forms).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use lagrange::model::file::load;
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::stabilize::Stabilize;
use lagrange::scenario::Scenario;

fn main() {
    divan::main();
}

fn chain(n: usize) -> Scenario {
    Scenario::new(load(&lagrange::scenario::chain(n)).expect("valid"), &[]).expect("derives")
}

#[divan::bench(args = [10, 100, 1000, 10000], sample_count = 5, sample_size = 1)]
fn chain_step(bencher: divan::Bencher, n: usize) {
    let s = chain(n);
    let mut settings = s.settings();
    settings.integrator = Integrator::Verlet;
    settings.stabilize = Stabilize::PROJECTION;
    settings.steps = 1;
    bencher.bench_local(|| s.simulate(settings, &mut |_| Ok(())).expect("runs").steps);
}

/// The baseline: one Verlet step of the pendulum with λ = −(m v·v + F·r)/(r·r) written by
/// hand, and a projection back onto |r| = l.
#[divan::bench]
fn handwritten_pendulum_step(bencher: divan::Bencher) {
    let (l, m, g) = (1.0f64, 1.0f64, -9.81f64);
    let dt = 1e-3;
    let accel = |r: [f64; 2], v: [f64; 2]| {
        let lambda = -(m * (v[0] * v[0] + v[1] * v[1]) + m * g * r[1]) / (r[0] * r[0] + r[1] * r[1]);
        [lambda * r[0] / m, g + lambda * r[1] / m]
    };
    bencher.bench_local(|| {
        let (mut r, mut v) = (divan::black_box([l, 0.0]), divan::black_box([0.0, 0.0]));
        let a = accel(r, v);
        for d in 0..2 {
            v[d] += 0.5 * dt * a[d];
            r[d] += dt * v[d];
        }
        let a1 = accel(r, [v[0] + 0.5 * dt * a[0], v[1] + 0.5 * dt * a[1]]);
        for d in 0..2 {
            v[d] += 0.5 * dt * a1[d];
        }
        let k = l / (r[0] * r[0] + r[1] * r[1]).sqrt();
        let along = (v[0] * r[0] + v[1] * r[1]) / (r[0] * r[0] + r[1] * r[1]);
        ([r[0] * k, r[1] * k], [v[0] - along * r[0], v[1] - along * r[1]])
    });
}

/// The same pendulum step through lagrange (rows by the compiled tape, the λ solve).
#[divan::bench(sample_count = 20)]
fn lagrange_pendulum_step(bencher: divan::Bencher) {
    let text = std::fs::read_to_string("constraints/pendulum.toml").expect("file");
    let s = Scenario::new(load(&text).expect("valid"), &[]).expect("derives");
    let mut settings = s.settings();
    settings.steps = 1;
    bencher.bench_local(|| s.simulate(settings, &mut |_| Ok(())).expect("runs").steps);
}
