//! Helpers shared by the integration tests: small systems, random states, evaluation, and
//! running a file's scene with chosen settings.
//!
//! Each test binary uses a different subset, hence the `dead_code` allowance.
#![allow(dead_code)]

use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::expr::{Id, Role, Ty};
use lagrange::model::file::load;
use lagrange::model::system::{BodySpec, MassSpec, System, SystemBuilder};
use lagrange::numeric::dynamics::{Dynamics, SimError};
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::rows::Rows;
use lagrange::numeric::simulate::initial_state;
use lagrange::numeric::simulate::{Failure, Frame, Settings, Summary};
use lagrange::numeric::stabilize::Stabilize;
use lagrange::numeric::velocity::{Settings as VelocitySettings, Stepper};
use lagrange::scenario::Scenario;
use nalgebra::{DMatrix, DVector};

/// The environment variable that makes the slow tests (the 10⁵-step chain, the 10⁶-step
/// pendulum, the rustc compiles of generated modules, the 1000-body chain) return at once:
/// `LAGRANGE_QUICK_TESTS=1 cargo test --release` is the fast suite for a developer. The
/// README's `cargo test --release`, and CI (which unsets it), run everything.
pub const QUICK: &str = "LAGRANGE_QUICK_TESTS";

/// Whether the slow test `name` is to be skipped (see [`QUICK`]); says so on stderr.
pub fn skip_slow(name: &str) -> bool {
    let skip = std::env::var_os(QUICK).is_some();
    if skip {
        eprintln!("{name}: skipped ({QUICK} is set)");
    }
    skip
}

/// The crate's deterministic generator (SplitMix64): tests must be reproducible.
pub use lagrange::numeric::random::Rng;

/// A body named `name` with symbols `r{i} v{i} a{i} F{i}` and mass `m{i}` (or without the
/// suffix when `i` is empty).
pub fn body<'a>(name: &'a str, r: &'a str, v: &'a str, a: &'a str, f: &'a str, m: &'a str) -> BodySpec<'a> {
    BodySpec { name, position: r, velocity: v, acceleration: a, force: f, mass: MassSpec::Symbol(m) }
}

/// The article's bead: one body `r v a F m`, parameter `l`, constraint `dot(r,r) = l^2`.
pub fn bead(dim: i64) -> System {
    let mut b = SystemBuilder::new("bead", dim).expect("dimension");
    b.parameter("l", Ty::Scalar).expect("l");
    b.body(&body("bead", "r", "v", "a", "F", "m")).expect("bead");
    b.constraint("wire", "dot(r,r) = l^2").expect("wire");
    b.finish()
}

/// Two bodies `p1` (`r1 v1 a1 F1 m1`) and `p2` (`r2 v2 a2 F2 m2`), scalar parameters
/// `params`, and the given constraints `(name, text)`.
pub fn two_bodies(dim: i64, params: &[&str], constraints: &[(&str, &str)]) -> System {
    let mut b = SystemBuilder::new("two bodies", dim).expect("dimension");
    for p in params {
        b.parameter(p, Ty::Scalar).expect("parameter");
    }
    b.body(&body("p1", "r1", "v1", "a1", "F1", "m1")).expect("p1");
    b.body(&body("p2", "r2", "v2", "a2", "F2", "m2")).expect("p2");
    for (name, text) in constraints {
        b.constraint(name, text).expect("constraint");
    }
    b.finish()
}

/// The `.toml` files of `dirs`, sorted.
pub fn constraint_files(dirs: &[&str]) -> Vec<std::path::PathBuf> {
    let mut files: Vec<_> = dirs
        .iter()
        .flat_map(|d| std::fs::read_dir(d).expect("dir").map(|e| e.expect("entry").path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

/// Every file of `dirs` (sorted) that loads and has a scene to run, with its path; files
/// without a scene (no initial state) or that do not load are left out.
pub fn scenarios(dirs: &[&str]) -> impl Iterator<Item = (std::path::PathBuf, Scenario)> {
    constraint_files(dirs).into_iter().filter_map(|path| {
        let text = std::fs::read_to_string(&path).expect("file");
        let s = Scenario::new(load(&text).ok()?, &[]).ok()?;
        Some((path, s))
    })
}

/// A random state for every symbol of `system`: vectors in `[-1, 1)ᵈ`, masses and scalar
/// parameters in `[0.5, 2)`, `t` in `[-1, 1)`.
pub fn random_env(system: &System, rng: &mut Rng) -> Env {
    let dim = system.dim();
    let mut env = Env::new();
    for (s, info) in system.graph.symbols() {
        let value = match (info.ty, info.role) {
            (Ty::Vector, _) => Value::Vector(rng.uniform_vector(dim, -1.0, 1.0)),
            (Ty::Scalar, Role::Time) => Value::Scalar(rng.uniform(-1.0, 1.0)),
            (Ty::Scalar, _) => Value::Scalar(rng.uniform(0.5, 2.0)),
        };
        env.set(s, value);
    }
    env
}

pub fn scalar(system: &System, id: Id, env: &Env) -> f64 {
    eval_one(&system.graph, id, env).expect("evaluates").scalar().expect("a scalar")
}

pub fn vector(system: &System, id: Id, env: &Env) -> [f64; 3] {
    eval_one(&system.graph, id, env).expect("evaluates").vector().expect("a vector")
}

/// `|a − b| ≤ rel · max(1, |a|, |b|)`.
pub fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * 1f64.max(a.abs()).max(b.abs())
}

/// Component-wise [`close`], with the scale taken from the larger vector.
pub fn close_vec(a: [f64; 3], b: [f64; 3], rel: f64) -> bool {
    let scale = a.iter().chain(&b).fold(1f64, |m, x| m.max(x.abs()));
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() <= rel * scale)
}

pub fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn scale3(k: f64, a: [f64; 3]) -> [f64; 3] {
    [k * a[0], k * a[1], k * a[2]]
}

pub fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Solves the small dense system `M x = y` by Gaussian elimination with partial pivoting.
pub fn solve(mut m: Vec<Vec<f64>>, mut y: Vec<f64>) -> Vec<f64> {
    let n = y.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs())).unwrap_or(col);
        m.swap(col, pivot);
        y.swap(col, pivot);
        let pivot_row = m[col].clone();
        for row in col + 1..n {
            let f = m[row][col] / pivot_row[col];
            for (x, p) in m[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            y[row] -= f * y[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let s: f64 = (row + 1..n).map(|k| m[row][k] * x[k]).sum();
        x[row] = (y[row] - s) / m[row][row];
    }
    x
}

pub fn scenario(path: &str) -> Scenario {
    let text = std::fs::read_to_string(path).expect("file");
    let loaded = load(&text).expect("valid file");
    Scenario::new(loaded, &[]).expect("derives and has an initial state")
}

pub fn settings(s: &Scenario, integrator: Integrator, stabilize: Stabilize, dt: f64, steps: u64) -> Settings {
    let mut settings = s.settings();
    settings.integrator = integrator;
    settings.stabilize = stabilize;
    settings.dt = dt;
    settings.steps = steps;
    settings
}

/// Runs `path` and calls `observe` on every frame.
pub fn run_observed(
    path: &str,
    integrator: Integrator,
    stabilize: Stabilize,
    dt: Option<f64>,
    steps: Option<u64>,
    observe: &mut dyn FnMut(&Frame),
) -> Result<Summary, Box<Failure>> {
    let s = scenario(path);
    let dt = dt.unwrap_or(s.scene.dt);
    let steps = steps.unwrap_or((s.scene.duration / dt).round() as u64);
    let settings = settings(&s, integrator, stabilize, dt, steps);
    s.simulate(settings, &mut |f| {
        observe(f);
        Ok(())
    })
}

/// Runs `path` with Verlet + projection at the scene's step.
pub fn run(path: &str, steps: Option<u64>) -> Result<Summary, Box<Failure>> {
    run_observed(path, Integrator::Verlet, Stabilize::PROJECTION, None, steps, &mut |_| {})
}

/// Runs `steps` steps of the velocity-level `settings` on `s` by hand, calling `each` with
/// the stepper and the rows after every step.
pub fn velocity_steps(
    s: &Scenario,
    settings: VelocitySettings,
    steps: u64,
    mut each: impl FnMut(&Stepper, &Rows),
) -> Result<(), SimError> {
    let mut dynamics = Dynamics::new(&s.system, s.program.clone(), s.env.clone());
    let (mut q, mut v, t0) = initial_state(&s.system, &s.env);
    let mut stepper = Stepper::new(settings, s.system.constraints.len(), q.len());
    for n in 0..steps {
        let t = t0 + n as f64 * settings.dt;
        let rows = dynamics.rows(t, &q, &v)?;
        stepper.step(&mut dynamics, t, &mut q, &mut v, rows)?;
        let after = dynamics.rows(t + settings.dt, &q, &v)?;
        each(&stepper, &after);
    }
    Ok(())
}

/// A = J M⁻¹ Jᵀ, J u and the effective masses 1/Aₖₖ for the rows at a state, over the
/// rows' slots (a rigid body's angular slot carries 1/I and Jʷ).
pub fn impulse_system(rows: &Rows, u: &[[f64; 3]]) -> (DMatrix<f64>, DVector<f64>, Vec<f64>) {
    let k = rows.rows.len();
    let mut a = DMatrix::zeros(k, k);
    let mut ju = DVector::zeros(k);
    let mut meff = vec![0.0; k];
    for (p, rp) in rows.rows.iter().enumerate() {
        for (b, j) in &rp.jacobian {
            ju[p] += j[0] * u[*b][0] + j[1] * u[*b][1] + j[2] * u[*b][2];
        }
        for (q, rq) in rows.rows.iter().enumerate() {
            for (bp, jp) in &rp.jacobian {
                for (bq, jq) in &rq.jacobian {
                    if bp == bq {
                        a[(p, q)] += rows.inverse_mass[*bp] * (jp[0] * jq[0] + jp[1] * jq[1] + jp[2] * jq[2]);
                    }
                }
            }
        }
        meff[p] = 1.0 / a[(p, p)];
    }
    (a, ju, meff)
}

/// The folders of rigid-body files: the joint library (`constraints/joints/`) and the rigid
/// scenes with closed forms (`constraints/rigid/`).
pub const RIGID_DIRS: [&str; 2] = ["constraints/joints", "constraints/rigid"];

/// The `.toml` files of [`RIGID_DIRS`], relative to the crate root: the joints, then the
/// scenes, each folder sorted.
pub fn rigid_files() -> Vec<String> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut out = Vec::new();
    for dir in RIGID_DIRS {
        let mut here: Vec<String> = std::fs::read_dir(root.join(dir))
            .unwrap_or_else(|e| panic!("{dir}: {e}"))
            .filter_map(|e| e.ok()?.file_name().into_string().ok())
            .filter(|n| n.ends_with(".toml"))
            .map(|n| format!("{dir}/{n}"))
            .collect();
        here.sort();
        out.extend(here);
    }
    out
}

/// Whether a path is in one of the [`RIGID_DIRS`].
pub fn in_rigid_dirs(path: &std::path::Path) -> bool {
    RIGID_DIRS.iter().any(|d| path.starts_with(d))
}

/// Whether a constraint file is 3D (in [`RIGID_DIRS`]: quaternion orientations, which
/// `generate` and `bench` do not handle yet).
pub fn is_3d(path: &std::path::Path) -> bool {
    std::fs::read_to_string(path).is_ok_and(|t| t.lines().any(|l| l.trim() == "dimension = 3"))
}

/// A uniformly random unit quaternion [w, x, y, z] (a normalised 4D normal sample).
pub fn random_quaternion(rng: &mut Rng) -> [f64; 4] {
    let q = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    q.map(|x| x / n)
}

/// exp(½ n φ) ⊗ q₀: q₀ turned by φ about the world axis n (unit), Hamilton's product.
pub fn turned(q0: [f64; 4], n: [f64; 3], phi: f64) -> [f64; 4] {
    let (s, c) = (0.5 * phi).sin_cos();
    let p = [c, s * n[0], s * n[1], s * n[2]];
    [
        p[0] * q0[0] - p[1] * q0[1] - p[2] * q0[2] - p[3] * q0[3],
        p[0] * q0[1] + p[1] * q0[0] + p[2] * q0[3] - p[3] * q0[2],
        p[0] * q0[2] - p[1] * q0[3] + p[2] * q0[0] + p[3] * q0[1],
        p[0] * q0[3] + p[1] * q0[2] - p[2] * q0[1] + p[3] * q0[0],
    ]
}

/// λ of `rows` (a chain: row k on slots k − 1 and k, row 0 on slot 0) in double-double:
/// A λ = −b with A = J M⁻¹ Jᵀ and b = J M⁻¹ F + c from the rows' f64 numbers (their products
/// exact in double-double), by the tridiagonal's elimination (A is positive definite: no
/// pivoting). About 32 digits: the reference the f64 solves are measured against.
pub fn reference_lambda(rows: &Rows) -> Vec<f64> {
    use twofloat::TwoFloat;
    let n = rows.rows.len();
    let dd = TwoFloat::from;
    let w = |s: usize| dd(rows.inverse_mass[s]);
    let dot = |a: &[f64; 3], b: &[f64; 3]| (0..3).fold(dd(0.0), |sum, c| sum + TwoFloat::new_mul(a[c], b[c]));
    let entry = |k: usize, l: usize| {
        let mut sum = dd(0.0);
        for (s, j) in &rows.rows[k].jacobian {
            for (t, i) in &rows.rows[l].jacobian {
                if s == t {
                    sum += dot(j, i) * w(*s);
                }
            }
        }
        sum
    };
    let mut diagonal: Vec<TwoFloat> = (0..n).map(|k| entry(k, k)).collect();
    let below: Vec<TwoFloat> = (0..n).map(|k| if k > 0 { entry(k, k - 1) } else { dd(0.0) }).collect();
    let mut rhs: Vec<TwoFloat> = (0..n)
        .map(|k| {
            let row = &rows.rows[k];
            -(row.jacobian.iter().fold(dd(0.0), |sum, (s, j)| sum + dot(j, &rows.force[*s]) * w(*s)) + dd(row.bias))
        })
        .collect();
    for k in 1..n {
        let m = below[k] / diagonal[k - 1];
        diagonal[k] -= m * below[k];
        let r = rhs[k - 1];
        rhs[k] -= m * r;
    }
    let mut lambda = vec![dd(0.0); n];
    for k in (0..n).rev() {
        let next = if k + 1 < n { below[k + 1] * lambda[k + 1] } else { dd(0.0) };
        lambda[k] = (rhs[k] - next) / diagonal[k];
    }
    lambda.into_iter().map(f64::from).collect()
}

/// Equal number for number (bits, so a −0 for a +0 counts too), diagnostics and status too.
pub fn assert_same(a: &lagrange::numeric::solve::Solution, b: &lagrange::numeric::solve::Solution, what: &str) {
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let bits3 = |x: &[[f64; 3]]| x.iter().flat_map(|v| v.map(f64::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&a.lambda), bits(&b.lambda), "{what}: λ");
    assert_eq!(bits3(&a.acceleration), bits3(&b.acceleration), "{what}: accelerations");
    assert_eq!(bits3(&a.constraint_force), bits3(&b.constraint_force), "{what}: forces");
    assert_eq!(
        (&a.active, &a.diagnostics, a.status, &a.contacts),
        (&b.active, &b.diagnostics, b.status, &b.contacts),
        "{what}"
    );
}
