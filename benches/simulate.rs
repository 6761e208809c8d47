//! Cost of a simulation step against the size of a chain (N = 10, 100, 1000, 10 000 links,
//! `lagrange::scenario::chain`), and a handwritten pendulum step as the baseline of what a
//! step can cost.
//!
//! `cargo bench --bench simulate`. Each sample is one `simulate` call of one step (setting
//! up the run, the recorded state at step 0 plus one Verlet + projection step). Rows come
//! from the compiled tape and the λ solve is a band Cholesky (a chain's A is tridiagonal),
//! so the cost per step grows linearly in N. Deriving the 10 000-link chain takes ~20 s
//! before its samples start.
//!
//! With the `jit` feature the pendulum and the chains also run with their rows' tapes
//! compiled to machine code (`*_jit`: `RowProgram::compile` before the samples), and
//! `rows_compile` measures what that compilation costs a scene at load.

/// The same allocator as the `lagrange` binary (mimalloc: a symbolic derivation allocates
/// many small forms).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use lagrange::model::file::load;
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::simulate::Measure;
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

/// Steps per sample of the per-step benchmarks: a `simulate` call's setup (cloning the
/// program and the state) is spread over them, as it is over a real run.
const STEPS: u64 = 100;

/// The pendulum for `steps` steps through `simulate` (Verlet + projection, as
/// `lagrange simulate` runs it), beside [`handwritten_pendulum_steps`]: divide both by
/// `steps` for the cost of a step. At [`STEPS`] the setting up of the run
/// ([`lagrange_pendulum_step`]) is a few percent of a sample; at 1 000 it is below one.
#[divan::bench(args = [STEPS, 1000], sample_count = 20)]
fn pendulum_steps(bencher: divan::Bencher, steps: u64) {
    rattle(bencher, &pendulum(), steps, Measure::Everything);
}

/// [`pendulum_steps`] asking for the steps alone (`Measure::Checks`: no energy balance,
/// no samples, no largest |C| and |Ċ|; the checks that stop a run made as ever), as a
/// library caller that wants the trajectory runs it: the same trajectory bit for bit.
#[divan::bench(args = [STEPS, 1000], sample_count = 20)]
fn pendulum_steps_lean(bencher: divan::Bencher, steps: u64) {
    rattle(bencher, &pendulum(), steps, Measure::Checks);
}

/// `constraints/pendulum.toml`, derived.
fn pendulum() -> Scenario {
    let text = std::fs::read_to_string("constraints/pendulum.toml").expect("file");
    Scenario::new(load(&text).expect("valid"), &[]).expect("derives")
}

/// Samples of `simulate` of `s` for `steps` Verlet + projection steps (RATTLE) under `measure`.
fn rattle(bencher: divan::Bencher, s: &Scenario, steps: u64, measure: Measure) {
    let mut settings = s.settings();
    settings.integrator = Integrator::Verlet;
    settings.stabilize = Stabilize::PROJECTION;
    settings.steps = steps;
    settings.measure = measure;
    bencher.bench_local(|| s.simulate(settings, &mut |_| Ok(())).expect("runs").steps);
}

/// [`pendulum_steps`] with the rows' tapes compiled to machine code before the samples
/// (`RowProgram::compile`, the `jit` feature): what a long run pays a step once the compile
/// time at its start is spread over it (`rows_compile` measures that).
#[cfg(feature = "jit")]
#[divan::bench(args = [STEPS, 1000], sample_count = 20)]
fn pendulum_steps_jit(bencher: divan::Bencher, steps: u64) {
    rattle(bencher, &compiled(pendulum()), steps, Measure::Everything);
}

/// [`pendulum_steps_lean`] compiled, as [`pendulum_steps_jit`].
#[cfg(feature = "jit")]
#[divan::bench(args = [STEPS, 1000], sample_count = 20)]
fn pendulum_steps_lean_jit(bencher: divan::Bencher, steps: u64) {
    rattle(bencher, &compiled(pendulum()), steps, Measure::Checks);
}

/// `s` with its rows' tapes compiled (`RowProgram::compile`; its batched shapes stay
/// interpreted): every run of it then runs them as machine code.
#[cfg(feature = "jit")]
fn compiled(mut s: Scenario) -> Scenario {
    s.program.compile().expect("this host compiles tapes");
    s
}

/// What compiling the rows' tapes costs a scene at load (`RowProgram::compile` of a fresh
/// copy of its program): the pendulum, the 10- and 100-link chains (the 100's rows are
/// batched: nothing to compile) and `constraints/solvers/rigid_grid_10.toml` (batched too).
#[cfg(feature = "jit")]
#[divan::bench(args = ["pendulum", "chain_10", "chain_100", "rigid_grid_10"], sample_count = 20)]
fn rows_compile(bencher: divan::Bencher, scene: &str) {
    let s = match scene {
        "pendulum" => pendulum(),
        "chain_10" => chain(10),
        "chain_100" => chain(100),
        _ => {
            let text = std::fs::read_to_string("constraints/solvers/rigid_grid_10.toml").expect("file");
            Scenario::new(load(&text).expect("valid"), &[]).expect("derives")
        }
    };
    bencher.with_inputs(|| s.program.clone()).bench_local_values(|mut program| {
        program.compile().expect("this host compiles tapes");
        program
    });
}

/// The baseline of [`pendulum_steps`]: `steps` steps of [`handwritten_pendulum_step`]'s
/// Verlet step with the closed-form λ and projection.
#[divan::bench(args = [STEPS, 1000], sample_count = 20)]
fn handwritten_pendulum_steps(bencher: divan::Bencher, steps: u64) {
    let (l, m, g) = (1.0f64, 1.0f64, -9.81f64);
    let dt = 1e-3;
    let accel = |r: [f64; 2], v: [f64; 2]| {
        let lambda = -(m * (v[0] * v[0] + v[1] * v[1]) + m * g * r[1]) / (r[0] * r[0] + r[1] * r[1]);
        [lambda * r[0] / m, g + lambda * r[1] / m]
    };
    bencher.bench_local(|| {
        let (mut r, mut v) = (divan::black_box([l, 0.0]), divan::black_box([0.0, 0.0]));
        let mut a = accel(r, v);
        for _ in 0..steps {
            for d in 0..2 {
                v[d] += 0.5 * dt * a[d];
                r[d] += dt * v[d];
            }
            let k = l / (r[0] * r[0] + r[1] * r[1]).sqrt();
            r = [r[0] * k, r[1] * k];
            for d in 0..2 {
                v[d] += 0.5 * dt * [0.0, g][d];
            }
            let along = (v[0] * r[0] + v[1] * r[1]) / (r[0] * r[0] + r[1] * r[1]);
            v = [v[0] - along * r[0], v[1] - along * r[1]];
            a = accel(r, v);
        }
        (r, v)
    });
}

/// `simulate` of an N-link chain for [`STEPS`] Verlet + projection steps (RATTLE: the
/// acceleration solve, drift, SHAKE, kick, velocity projection), beside
/// [`handwritten_chain_steps`] doing the same work by hand: divide both by `STEPS` for the
/// cost of a step; their ratio is the overhead of the general path.
#[divan::bench(args = [10, 100, 1000, 10000], sample_count = 5, sample_size = 1)]
fn chain_steps(bencher: divan::Bencher, n: usize) {
    rattle(bencher, &chain(n), STEPS, Measure::Everything);
}

/// [`chain_steps`] asking for the steps alone (`Measure::Checks`, as
/// [`pendulum_steps_lean`]).
#[divan::bench(args = [10, 100, 1000], sample_count = 5, sample_size = 1)]
fn chain_steps_lean(bencher: divan::Bencher, n: usize) {
    rattle(bencher, &chain(n), STEPS, Measure::Checks);
}

/// [`chain_steps`] with the rows' tapes compiled before the samples (as
/// [`pendulum_steps_jit`]; from N = 12 links a chain's rows are batched, and stay
/// interpreted).
#[cfg(feature = "jit")]
#[divan::bench(args = [10, 100], sample_count = 5, sample_size = 1)]
fn chain_steps_jit(bencher: divan::Bencher, n: usize) {
    rattle(bencher, &compiled(chain(n)), STEPS, Measure::Everything);
}

/// The baseline of [`chain_steps`]: the same chain (`lagrange::scenario::chain`: links of
/// l = 0.5, masses 1, g = [0, −9.81], straight along +x at rest, dt = 1e-3) stepped by a
/// handwritten RATTLE with its tridiagonal solves, as an engine programmer would write it.
#[divan::bench(args = [10, 100, 1000, 10000], sample_count = 5, sample_size = 1)]
fn handwritten_chain_steps(bencher: divan::Bencher, n: usize) {
    bencher.bench_local(|| {
        let mut chain = HandChain::new(n);
        for _ in 0..STEPS {
            chain.step();
        }
        divan::black_box(chain.q[n - 1])
    });
}

/// The step of issue 16's first aim, without integrating: at the chain's scene state,
/// assemble A and b of the tridiagonal by hand and solve them (Thomas, [`HandChain`]'s
/// `accelerations`), to the accelerations.
#[divan::bench(name = "chain_solve_1_handwritten", args = [10, 100, 1000, 10000])]
fn chain_solve_handwritten(bencher: divan::Bencher, n: usize) {
    let mut chain = HandChain::new(n);
    bencher.bench_local(|| {
        chain.accelerations();
        divan::black_box(chain.a[n - 1])
    });
}

/// The same through the library, as an engine calls it: the rows by the tape
/// (`RowProgram::evaluate_into`, interpreted) and the solve into an answer kept outside the
/// loop (`solve_into`: scaling, assembly, tridiagonal Cholesky, the refinement where the
/// residual asks, the answer's vectors reused), to the accelerations.
#[divan::bench(name = "chain_solve_2_library", args = [10, 100, 1000, 10000])]
fn chain_solve_library(bencher: divan::Bencher, n: usize) {
    library_step(bencher, chain(n), n);
}

/// [`chain_solve_library`] with a fresh answer each call (`solve_with`: its five vectors
/// allocated every time).
#[divan::bench(name = "chain_solve_2_library_fresh", args = [10, 100, 1000, 10000])]
fn chain_solve_library_fresh(bencher: divan::Bencher, n: usize) {
    let s = chain(n);
    let mut scratch = s.program.scratch();
    let mut rows = lagrange::numeric::rows::Rows::default();
    let settings = lagrange::numeric::solve::Settings::default();
    bencher.bench_local(|| {
        s.program.evaluate_into(&s.system, &s.env, &mut scratch, &mut rows).expect("rows");
        lagrange::numeric::solve::solve_with(&rows, &settings).acceleration[n - 1]
    });
}

/// [`chain_solve_library`] with the rows' tapes compiled (as [`pendulum_steps_jit`]).
#[cfg(feature = "jit")]
#[divan::bench(name = "chain_solve_2_library_jit", args = [10, 100])]
fn chain_solve_library_jit(bencher: divan::Bencher, n: usize) {
    library_step(bencher, compiled(chain(n)), n);
}

/// The library's step of [`chain_solve_library`] on `s`, an `n`-link chain: its rows, then
/// the solve into one answer.
fn library_step(bencher: divan::Bencher, s: Scenario, n: usize) {
    let mut scratch = s.program.scratch();
    let mut rows = lagrange::numeric::rows::Rows::default();
    let mut answer = lagrange::numeric::solve::Solution::default();
    let settings = lagrange::numeric::solve::Settings::default();
    bencher.bench_local(|| {
        s.program.evaluate_into(&s.system, &s.env, &mut scratch, &mut rows).expect("rows");
        lagrange::numeric::solve::solve_into(&rows, &settings, &mut answer);
        answer.acceleration[n - 1]
    });
}

/// The library's λ from one program of the derivation's formulas (`BandLambda`): c, J, the
/// masses and forces, interpreted (one tape at N = 10, shape by shape from N = 100:
/// `numeric::batch`), A's band formed from J, then L D Lᵀ of the tridiagonal under its pivot
/// guard, to the accelerations. Its accelerations are asserted equal to
/// [`chain_solve_library`]'s to 1e-12 of the largest before the samples.
#[divan::bench(name = "chain_solve_2_band", args = [10, 100, 1000, 10000])]
fn chain_solve_band(bencher: divan::Bencher, n: usize) {
    band_step(bencher, chain(n), n, false);
}

/// [`chain_solve_band`] with the band program's tape compiled, A's band from its formulas
/// (`BandLambda::compile`); not at N = 10 000, whose one tape is too large for compiled
/// code's stack frame (`JitError::TooLarge`).
#[cfg(feature = "jit")]
#[divan::bench(name = "chain_solve_2_band_jit", args = [10, 100, 1000])]
fn chain_solve_band_jit(bencher: divan::Bencher, n: usize) {
    band_step(bencher, chain(n), n, true);
}

/// The band program's step on `s`, an `n`-link chain (compiled first when `compile`), after
/// checking its accelerations against the rows' solve.
fn band_step(bencher: divan::Bencher, s: Scenario, n: usize, compile: bool) {
    use lagrange::numeric::band_lambda::BandLambda;
    use lagrange::numeric::solve::{Settings, Solution, solve_into};
    let mut band = BandLambda::new(&s.system, &s.derivation, &s.scene.forces).expect("a chain");
    #[cfg(feature = "jit")]
    if compile {
        band.compile(&s.derivation).expect("this host compiles tapes");
    }
    assert!(!compile || band.is_compiled());
    let settings = Settings::default();
    let mut answer = Solution::default();
    assert!(band.solve_into(&s.env, &settings, &mut answer), "the guard passes on the chain");
    let rows = s.program.evaluate(&s.system, &s.env).expect("rows");
    let mut want = Solution::default();
    solve_into(&rows, &settings, &mut want);
    let scale = want.acceleration.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for (a, w) in answer.acceleration.iter().zip(&want.acceleration) {
        for (a, w) in a.iter().zip(w) {
            assert!((a - w).abs() <= 1e-12 * scale, "band {a} against rows {w}");
        }
    }
    bencher.bench_local(|| {
        band.solve_into(&s.env, &settings, &mut answer);
        answer.acceleration[n - 1]
    });
}

/// As [`chain_solve_library`] with the run's solve (`solve_cached`) warm at the same J: what
/// a SHAKE iteration or the next step's start pays for its solve.
#[divan::bench(name = "chain_solve_3_library_reused", args = [10, 100, 1000, 10000])]
fn chain_solve_library_reused(bencher: divan::Bencher, n: usize) {
    use lagrange::numeric::solve::{Settings, SolveCache, solve_cached};
    let s = chain(n);
    let mut scratch = s.program.scratch();
    let mut rows = lagrange::numeric::rows::Rows::default();
    let mut cache = SolveCache::default();
    bencher.bench_local(|| {
        s.program.evaluate_into(&s.system, &s.env, &mut scratch, &mut rows).expect("rows");
        solve_cached(&rows, &Settings::default(), &[], &mut cache).acceleration[n - 1]
    });
}

/// An N-link chain pinned at the origin, C_k = |d_k|² − l² with d_k = q_k − q_{k−1}
/// (q_{−1} = 0), J_k = ±d_k (κ = 2), unit masses: A is tridiagonal.
struct HandChain {
    q: Vec<[f64; 2]>,
    v: Vec<[f64; 2]>,
    a: Vec<[f64; 2]>,
    /// Scratch: d_k at the step's start (SHAKE's gradients), the tridiagonal's bands and
    /// right-hand side, the multipliers.
    d0: Vec<[f64; 2]>,
    lower: Vec<f64>,
    diag: Vec<f64>,
    upper: Vec<f64>,
    rhs: Vec<f64>,
    mu: Vec<f64>,
}

const L: f64 = 0.5;
const G: f64 = -9.81;
const DT: f64 = 1e-3;

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

impl HandChain {
    fn new(n: usize) -> HandChain {
        let q = (1..=n).map(|i| [0.5 * i as f64, 0.0]).collect();
        let z = || vec![0.0; n];
        let mut c = HandChain {
            q,
            v: vec![[0.0; 2]; n],
            a: vec![[0.0; 2]; n],
            d0: vec![[0.0; 2]; n],
            lower: z(),
            diag: z(),
            upper: z(),
            rhs: z(),
            mu: z(),
        };
        c.accelerations();
        c
    }

    fn link(x: &[[f64; 2]], k: usize) -> [f64; 2] {
        if k == 0 { x[0] } else { sub(x[k], x[k - 1]) }
    }

    /// Solves the tridiagonal system in `lower`, `diag`, `upper`, `rhs` into `mu` (Thomas;
    /// the bands are overwritten).
    fn solve(&mut self) {
        let n = self.diag.len();
        for k in 1..n {
            let w = self.lower[k] / self.diag[k - 1];
            self.diag[k] -= w * self.upper[k - 1];
            self.rhs[k] -= w * self.rhs[k - 1];
        }
        self.mu[n - 1] = self.rhs[n - 1] / self.diag[n - 1];
        for k in (0..n - 1).rev() {
            self.mu[k] = (self.rhs[k] - self.upper[k] * self.mu[k + 1]) / self.diag[k];
        }
    }

    /// The bands of Σᵢ Jₖᵢ·Hⱼᵢ (unit masses) for rows J = ±e_k at q and columns H = ±h_k.
    fn bands(&mut self, e: impl Fn(&HandChain, usize) -> [f64; 2], h: impl Fn(&HandChain, usize) -> [f64; 2]) {
        let n = self.q.len();
        for k in 0..n {
            let (ek, hk) = (e(self, k), h(self, k));
            self.diag[k] = if k == 0 { dot(ek, hk) } else { 2.0 * dot(ek, hk) };
            self.lower[k] = if k > 0 { -dot(ek, h(self, k - 1)) } else { 0.0 };
            self.upper[k] = if k + 1 < n { -dot(ek, h(self, k + 1)) } else { 0.0 };
        }
    }

    /// a = g + Σ λ J: A λ = −b with b_k = |ḋ_k|² (+ d_0·g for the pinned link).
    fn accelerations(&mut self) {
        let n = self.q.len();
        self.bands(|c, k| Self::link(&c.q, k), |c, k| Self::link(&c.q, k));
        for k in 0..n {
            let dv = Self::link(&self.v, k);
            let gravity = if k == 0 { G * self.q[0][1] } else { 0.0 };
            self.rhs[k] = -(dot(dv, dv) + gravity);
        }
        self.solve();
        for i in 0..n {
            let mut f = [0.0, G];
            let di = Self::link(&self.q, i);
            for d in 0..2 {
                f[d] += self.mu[i] * di[d];
            }
            if i + 1 < n {
                let dn = Self::link(&self.q, i + 1);
                for d in 0..2 {
                    f[d] -= self.mu[i + 1] * dn[d];
                }
            }
            self.a[i] = f;
        }
    }

    fn step(&mut self) {
        let n = self.q.len();
        for k in 0..n {
            self.d0[k] = Self::link(&self.q, k);
        }
        // Drift: v½ = v + h/2 a, q⁺ = q + h v½.
        for i in 0..n {
            for d in 0..2 {
                self.v[i][d] += 0.5 * DT * self.a[i][d];
                self.q[i][d] += DT * self.v[i][d];
            }
        }
        // SHAKE along the start's gradients: Δqᵢ = −Σₖ μₖ J⁰ₖᵢ until every distance
        // |C/κ|/|J| is within 1e-13 of the scene's size (its largest |qᵢ|), as `simulate`'s.
        let length = self.q.iter().map(|q| dot(*q, *q)).fold(0.0, f64::max).sqrt();
        for _ in 0..20 {
            let mut worst = 0.0f64;
            for k in 0..n {
                let dk = Self::link(&self.q, k);
                self.rhs[k] = 0.5 * (dot(dk, dk) - L * L);
                worst = worst.max(self.rhs[k].abs());
            }
            if worst / L <= 1e-13 * length {
                break;
            }
            self.bands(|c, k| Self::link(&c.q, k), |c, k| c.d0[k]);
            self.solve();
            for i in 0..n {
                for d in 0..2 {
                    let mut dq = -self.mu[i] * self.d0[i][d];
                    if i + 1 < n {
                        dq += self.mu[i + 1] * self.d0[i + 1][d];
                    }
                    self.q[i][d] += dq;
                    self.v[i][d] += dq / DT;
                }
            }
        }
        // Kick by the external force, then project the velocities onto J v = 0.
        for v in &mut self.v {
            v[1] += 0.5 * DT * G;
        }
        self.bands(|c, k| Self::link(&c.q, k), |c, k| Self::link(&c.q, k));
        for k in 0..n {
            self.rhs[k] = dot(Self::link(&self.q, k), Self::link(&self.v, k));
        }
        self.solve();
        for i in 0..n {
            let di = Self::link(&self.q, i);
            let next = if i + 1 < n { Self::link(&self.q, i + 1) } else { [0.0; 2] };
            let mu_next = if i + 1 < n { self.mu[i + 1] } else { 0.0 };
            for (d, v) in self.v[i].iter_mut().enumerate() {
                *v += -self.mu[i] * di[d] + mu_next * next[d];
            }
        }
        // The next step's accelerations at the new state (what the run records).
        self.accelerations();
    }
}
