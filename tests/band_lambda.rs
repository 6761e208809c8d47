//! The chain's λ from one program of the derivation's formulas (`numeric::band_lambda`)
//! against the rows' solve it stands in for (`RowProgram::evaluate_into` + `solve_into`):
//! on random states of chains (2D and 3D, masses 2^±20) within a small factor of the rows'
//! solve's error against a double-double reference, and on nearly straight, ill-conditioned
//! chains of 100 to 2 000 links as accurate summed over the cases; its accelerations those
//! of the rows' solve on the benchmark's chain; and the switch: every case the rows' solve
//! answers otherwise (a zero or tiny link, a pivot at the rank tolerance, a NaN, an infinite
//! or zero mass, numbers out of range, the dense and sparse methods, four rows under `Auto`,
//! a missing value) declined, the fallback giving `solve_into`'s answer bit for bit; systems
//! it does not serve (an inequality, rows out of chain order, a rigid body) never made.

mod common;

use common::Rng;
use lagrange::expr::eval::{Env, Value};
use lagrange::model::file::load;
use lagrange::numeric::band_lambda::BandLambda;
use lagrange::numeric::rows::Rows;
use lagrange::numeric::solve::{Method, Settings, Solution, Status, solve_into};
use lagrange::scenario::Scenario;

/// The unit roundoff.
const U: f64 = f64::EPSILON / 2.0;

/// An `n`-link chain in dimension `dim` hanging from the origin, body i of mass `m{i}` (a
/// parameter each, so a state can give every body its own), under gravity, with the links
/// listed in `order` (indices 1..=n; the chain's order when `None`), the last link an
/// inequality (a rope) when `rope`.
fn chain_text(n: usize, dim: usize, order: Option<&[usize]>, rope: bool) -> String {
    let zero = if dim == 2 { "[0.0, 0.0]" } else { "[0.0, 0.0, 0.0]" };
    let g = if dim == 2 { "[0.0, -9.81]" } else { "[0.0, -9.81, 0.0]" };
    let mut s = format!("title = \"chain\"\ndimension = {dim}\n\n[parameters]\nl = 0.5\ng = {g}\n");
    for i in 1..=n {
        s += &format!("m{i} = 1.0\n");
    }
    for i in 1..=n {
        s += &format!(
            "\n[[bodies]]\nname = \"p{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\nmass = \"m{i}\"\nforce = \"F{i}\"\n"
        );
    }
    let chain: Vec<usize> = (1..=n).collect();
    for &i in order.unwrap_or(&chain) {
        let d = if i == 1 { "r1".to_string() } else { format!("(r{i} - r{})", i - 1) };
        let relation = if rope && i == n { "<=" } else { "=" };
        s += &format!("\n[[constraints]]\nname = \"link{i}\"\nexpr = \"dot({d}, {d}) {relation} l^2\"\n");
    }
    let initial: Vec<String> = (1..=n)
        .map(|i| {
            let x = 0.5 * i as f64;
            let r = if dim == 2 { format!("[{x}, 0.0]") } else { format!("[{x}, 0.0, 0.0]") };
            format!("r{i} = {r}, v{i} = {zero}")
        })
        .collect();
    let forces: Vec<String> = (1..=n).map(|i| format!("F{i} = \"m{i}*g\"")).collect();
    s += &format!("\n[scene]\ninitial = {{ {} }}\nforces = {{ {} }}\n", initial.join(", "), forces.join(", "));
    s
}

/// The chain of [`chain_text`], derived, with its band program (`None` when not served).
fn chain(n: usize, dim: usize, order: Option<&[usize]>, rope: bool) -> (Scenario, Option<BandLambda>) {
    let s = Scenario::new(load(&chain_text(n, dim, order, rope)).expect("valid"), &[]).expect("derives");
    let band = BandLambda::new(&s.system, &s.derivation, &s.scene.forces);
    (s, band)
}

/// Sets symbol `name` of `s` in `env` to `value`.
fn set(s: &Scenario, env: &mut Env, name: &str, value: Value) {
    env.set(s.system.graph.symbol_named(name).expect("a symbol of the chain"), value);
}

/// 2^e for an integer e.
fn pow2(e: i32) -> f64 {
    2f64.powi(e)
}

/// A random state of the `n`-link chain `s`: links of random directions (within `bend` of
/// +x) and lengths about l, random velocities, masses 2^±`spread`.
fn random_state(s: &Scenario, rng: &mut Rng, n: usize, dim: usize, bend: f64, spread: f64) -> Env {
    let mut env = s.env.clone();
    let mut r = [0.0; 3];
    for i in 1..=n {
        let mut d = rng.normal_vector(dim, bend);
        d[0] = 1.0;
        let length = 0.5 * rng.uniform(0.5, 2.0) / d.iter().map(|x| x * x).sum::<f64>().sqrt();
        for c in 0..3 {
            r[c] += d[c] * length;
        }
        set(s, &mut env, &format!("r{i}"), Value::Vector(r));
        set(s, &mut env, &format!("v{i}"), Value::Vector(rng.normal_vector(dim, 1.0)));
        set(s, &mut env, &format!("m{i}"), Value::Scalar(pow2(rng.uniform(-spread, spread) as i32)));
    }
    env
}

/// The rows' answer at `env`: the rows evaluated, then `solve_into`.
fn rows_answer(s: &Scenario, env: &Env, settings: &Settings) -> (Rows, Solution) {
    let rows = s.program.evaluate(&s.system, env).expect("rows");
    let mut out = Solution::default();
    solve_into(&rows, settings, &mut out);
    (rows, out)
}

/// The states of [`ill_conditioned_chains_lose_nothing_against_the_rows_solve`]: 12 for each
/// of 3 lengths and 3 mass spreads.
const CASES: usize = 108;

/// ‖λ − reference‖∞ / ‖reference‖∞.
fn error(lambda: &[f64], reference: &[f64]) -> f64 {
    let size = reference.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    lambda.iter().zip(reference).fold(0.0f64, |m, (x, r)| m.max((x - r).abs())) / size
}

/// Random states of chains of 6 to 40 links in 2D and 3D, masses 2^±20, links within 45° of
/// a line: the band path serves each (status `Solved`, no diagnostic, as the rows' solve),
/// and its λ is within 16× the rows' solve's error against the double-double reference plus
/// 16u (the module's analysis: both are backward stable solves of the same A up to a
/// diagonal scaling, so both errors are of order κ(Ã) u; case by case they scatter around
/// each other), summed over the 100 cases within 1.5× of it (measured 1.14×).
#[test]
fn random_states_are_served_and_as_accurate_as_the_rows_solve() {
    let mut rng = Rng::new(36);
    let (mut band_total, mut rows_total) = (0.0, 0.0);
    for (n, dim) in [(6, 2), (17, 2), (40, 2), (12, 3)] {
        let (s, band) = chain(n, dim, None, false);
        let mut band = band.expect("a chain is served");
        assert_eq!(band.len(), n);
        for case in 0..25 {
            let what = format!("n = {n}, dim = {dim}, case {case}");
            let env = random_state(&s, &mut rng, n, dim, 1.0, 20.0);
            let settings = Settings::default();
            let (rows, want) = rows_answer(&s, &env, &settings);
            let mut got = Solution::default();
            assert!(band.solve_into(&env, &settings, &mut got), "{what}: served");
            assert_eq!((got.status, &got.diagnostics), (Status::Solved, &want.diagnostics), "{what}");
            assert_eq!((&got.active, &got.contacts), (&want.active, &want.contacts), "{what}");
            let reference = common::reference_lambda(&rows);
            let (b, r) = (error(&got.lambda, &reference), error(&want.lambda, &reference));
            assert!(b <= 16.0 * r + 16.0 * U, "{what}: band {b:e}, rows {r:e}");
            (band_total, rows_total) = (band_total + b, rows_total + r);
        }
    }
    assert!(band_total <= 1.5 * rows_total, "band {band_total:e}, rows {rows_total:e}");
}

/// Nearly straight chains of 100, 500 and 2 000 links (links within 0.05 rad of +x),
/// masses 2^±0, 2^±10, 2^±20 from body to body: Ã's off-diagonals near ±1, κ(Ã) growing as
/// n² and with the spread; [`CASES`] states in all. The band path's λ against the
/// double-double reference: within 16× the rows' solve's error plus 16u case by case
/// (measured: from about 0.1× to 9×, the two errors scattering around each other, as the
/// module's analysis has it), summed over the cases within 1.5× of it (measured 1.10×), and
/// the ratio of the two errors 1.25 or less in geometric mean (measured 1.01); the chains
/// are ill-conditioned indeed (the worst error above 1e-11). On 27 states the sum was
/// 3.4× from one case (9.9e-11 against 2.4e-11): sums of so few are one case's.
#[test]
fn ill_conditioned_chains_lose_nothing_against_the_rows_solve() {
    let mut rng = Rng::new(2026);
    let (mut band_total, mut rows_total, mut worst) = (0.0, 0.0, 0.0f64);
    let mut log_ratio = 0.0;
    for n in [100, 500, 2000] {
        let (s, band) = chain(n, 2, None, false);
        let mut band = band.expect("a chain is served");
        for spread in [0.0, 10.0, 20.0] {
            for case in 0..CASES / 9 {
                let what = format!("n = {n}, masses 2^±{spread}, case {case}");
                let env = random_state(&s, &mut rng, n, 2, 0.05, spread);
                let settings = Settings { method: Method::Banded, ..Settings::default() };
                let (rows, want) = rows_answer(&s, &env, &settings);
                let mut got = Solution::default();
                assert!(band.solve_into(&env, &settings, &mut got), "{what}: served");
                let reference = common::reference_lambda(&rows);
                let (b, r) = (error(&got.lambda, &reference), error(&want.lambda, &reference));
                assert!(b <= 16.0 * r + 16.0 * U, "{what}: band {b:e}, rows {r:e}");
                (band_total, rows_total) = (band_total + b, rows_total + r);
                log_ratio += (b / r).ln();
                worst = worst.max(r);
            }
        }
    }
    assert!(worst > 1e-11, "the chains are ill-conditioned: worst error {worst:e}");
    assert!(band_total <= 1.5 * rows_total, "band {band_total:e}, rows {rows_total:e}");
    let typical = (log_ratio / CASES as f64).exp();
    assert!(typical <= 1.25, "the band path's error {typical}x the rows' solve's, in geometric mean");
}

/// The benchmark's chain (`scenario::chain`, N = 10 and 100) at its scene state: the band
/// path's accelerations are the rows' solve's to 1e-12 of the largest.
#[test]
fn the_benchmark_chain_accelerates_as_the_rows_solve() {
    for n in [10, 100] {
        let s = Scenario::new(load(&lagrange::scenario::chain(n)).expect("valid"), &[]).expect("derives");
        let mut band = BandLambda::new(&s.system, &s.derivation, &s.scene.forces).expect("a chain");
        let settings = Settings::default();
        let (_, want) = rows_answer(&s, &s.env, &settings);
        let mut got = Solution::default();
        assert!(band.solve_into(&s.env, &settings, &mut got));
        let scale = want.acceleration.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        for (a, w) in got.acceleration.iter().flatten().zip(want.acceleration.iter().flatten()) {
            assert!((a - w).abs() <= 1e-12 * scale, "n = {n}: {a} against {w}");
        }
        for (f, w) in got.constraint_force.iter().flatten().zip(want.constraint_force.iter().flatten()) {
            assert!((f - w).abs() <= 1e-12 * scale, "n = {n}: force {f} against {w}");
        }
    }
}

/// Every case the rows' solve answers with a diagnostic, another method or another unit is
/// declined (`solve_into` false, the answer untouched), and `solve_or_rows_into` then gives
/// `solve_into`'s answer bit for bit; the served case through it is the band path's.
#[test]
fn every_declined_case_falls_back_to_the_rows_solve_exactly() {
    let n = 8;
    let (s, band) = chain(n, 2, None, false);
    let mut band = band.expect("a chain is served");
    let base = random_state(&s, &mut Rng::new(7), n, 2, 0.3, 4.0);
    let with = |changes: &[(&str, Value)]| {
        let mut env = base.clone();
        for (name, value) in changes {
            set(&s, &mut env, name, *value);
        }
        env
    };
    let r3 = match base.get(s.system.graph.symbol_named("r3").expect("r3")) {
        Some(Value::Vector(r)) => r,
        _ => unreachable!("r3 is a vector"),
    };
    let auto = Settings::default();
    let setting = |method| Settings { method, ..Settings::default() };
    let strict = Settings { rank_tolerance: 0.9, ..Settings::default() };
    let huge: Vec<(String, Value)> =
        (1..=n).map(|i| (format!("r{i}"), Value::Vector([1e160 * i as f64, 0.0, 0.0]))).collect();
    let tiny: Vec<(String, Value)> =
        (1..=n).map(|i| (format!("r{i}"), Value::Vector([1e-160 * i as f64, 0.0, 0.0]))).collect();
    let scaled = |scale: f64| -> Vec<(String, Value)> {
        (1..=n).map(|i| (format!("r{i}"), Value::Vector([scale * i as f64, 0.0, 0.0]))).collect()
    };
    // Links 2^-250 long between positions about 2^-200 (inputs in range, d·d = 2^-500), and
    // links 2^231 long on masses 2^-20 (Aₖₖ = 2^483).
    let cancelled: Vec<(String, Value)> =
        (1..=n).map(|i| (format!("r{i}"), Value::Vector([pow2(-200) + i as f64 * pow2(-250), 0.0, 0.0]))).collect();
    let heavy: Vec<(String, Value)> = (1..=n)
        .flat_map(|i| {
            [
                (format!("r{i}"), Value::Vector([i as f64 * pow2(231), 0.0, 0.0])),
                (format!("m{i}"), Value::Scalar(pow2(-20))),
            ]
        })
        .collect();
    let named = |list: &[(String, Value)]| with(&list.iter().map(|(n, v)| (n.as_str(), *v)).collect::<Vec<_>>());
    let cases: Vec<(&str, Env, Settings)> = vec![
        ("a link of zero length", with(&[("r4", Value::Vector(r3))]), auto),
        ("a pivot at the rank tolerance", base.clone(), strict),
        ("a NaN position", with(&[("r5", Value::Vector([f64::NAN, 0.0, 0.0]))]), auto),
        ("a NaN velocity", with(&[("v2", Value::Vector([0.0, f64::NAN, 0.0]))]), auto),
        ("an infinite mass", with(&[("m3", Value::Scalar(f64::INFINITY))]), auto),
        ("a zero mass", with(&[("m3", Value::Scalar(0.0))]), auto),
        ("an infinite gravity", with(&[("g", Value::Vector([0.0, f64::INFINITY, 0.0]))]), auto),
        ("numbers that overflow", named(&huge), auto),
        ("numbers that underflow", named(&tiny), auto),
        ("positions below the input range (1e-100)", named(&scaled(1e-100)), auto),
        ("positions above the input range (1e100)", named(&scaled(1e100)), auto),
        ("A's diagonal below its range (links of 2^-250 at 2^-200)", named(&cancelled), auto),
        ("A's diagonal above its range (links of 2^231, masses 2^-20)", named(&heavy), auto),
        ("the dense method", base.clone(), setting(Method::Dense)),
        ("the sparse method", base.clone(), setting(Method::Sparse)),
    ];
    for (what, env, settings) in &cases {
        let (_, want) = rows_answer(&s, env, settings);
        let mut untouched = Solution { lambda: vec![42.0], ..Solution::default() };
        assert!(!band.solve_into(env, settings, &mut untouched), "{what}: declined");
        assert_eq!(untouched.lambda, [42.0], "{what}: the answer untouched");
        let (mut scratch, mut rows, mut got) = (s.program.scratch(), Rows::default(), Solution::default());
        let served = band.solve_or_rows_into(&s.system, env, settings, &s.program, &mut scratch, &mut rows, &mut got);
        assert_eq!(served, Ok(false), "{what}");
        common::assert_same(&got, &want, what);
    }
    // The band path declines the state the rows' solve calls singular at the rank tolerance,
    // and what that solve says of it.
    let (_, strict_answer) = rows_answer(&s, &base, &strict);
    assert_ne!(strict_answer.status, Status::Solved, "the strict tolerance finds the chain singular");
    // Served, through the helper too: the band path's answer.
    let (mut scratch, mut rows, mut got) = (s.program.scratch(), Rows::default(), Solution::default());
    let served = band.solve_or_rows_into(&s.system, &base, &auto, &s.program, &mut scratch, &mut rows, &mut got);
    assert_eq!(served, Ok(true));
    let mut direct = Solution::default();
    assert!(band.solve_into(&base, &auto, &mut direct));
    common::assert_same(&got, &direct, "served");
    // A missing value: declined, and the rows' evaluation reports it.
    let mut missing = Env::new();
    missing.set(s.system.graph.symbol_named("l").expect("l"), Value::Scalar(0.5));
    assert!(!band.solve_into(&missing, &auto, &mut got));
    let result = band.solve_or_rows_into(&s.system, &missing, &auto, &s.program, &mut scratch, &mut rows, &mut got);
    assert!(result.is_err(), "the rows cannot be evaluated either");
}

/// The answer's vectors are traded with the program's buffers: an answer of another scene
/// (3D, its third components not zero), one spoiled with NaNs and a fresh one get the same
/// answer, bit for bit, the 2D chain's third components zeros.
#[test]
fn an_old_answer_changes_nothing() {
    let n = 7;
    let (s, band) = chain(n, 2, None, false);
    let mut band = band.expect("a chain is served");
    let (s3, band3) = chain(n, 3, None, false);
    let mut band3 = band3.expect("a chain is served");
    let settings = Settings::default();
    let mut rng = Rng::new(38);
    for case in 0..5 {
        let env = random_state(&s, &mut rng, n, 2, 0.5, 3.0);
        let mut fresh = Solution::default();
        assert!(band.solve_into(&env, &settings, &mut fresh), "case {case}");
        let mut old = Solution::default();
        let env3 = random_state(&s3, &mut rng, n, 3, 0.5, 3.0);
        assert!(band3.solve_into(&env3, &settings, &mut old));
        assert!(old.acceleration.iter().any(|a| a[2] != 0.0), "the 3D answer has third components");
        let mut spoiled = Solution {
            lambda: vec![f64::NAN; n],
            acceleration: vec![[f64::NAN; 3]; n],
            constraint_force: vec![[f64::NAN; 3]; n],
            ..Solution::default()
        };
        for (what, answer) in [("a 3D answer", &mut old), ("NaNs", &mut spoiled)] {
            assert!(band.solve_into(&env, &settings, answer), "case {case}, {what}");
            common::assert_same(answer, &fresh, what);
            let third = answer.acceleration.iter().chain(&answer.constraint_force).map(|v| v[2].to_bits());
            assert!(third.into_iter().all(|z| z == 0), "case {case}, {what}: zeros");
        }
    }
}

/// Outputs that are not finite at inputs that are (no finiteness pass looks at the outputs:
/// each reaches a test of the guard): links written `norm(d) = l`, whose J = d/|d| is 0/0
/// at a zero-length link, and forces `m g / s`, infinite and 0/0 at s = 0. Declined,
/// interpreted and compiled, and the fallback gives `solve_into`'s answer bit for bit.
#[test]
fn outputs_that_are_not_finite_are_declined() {
    let n = 6;
    let mut text = chain_text(n, 2, None, false).replace("l = 0.5\n", "l = 0.5\ns = 1.0\n");
    for i in 1..=n {
        let d = if i == 1 { "r1".to_string() } else { format!("(r{i} - r{})", i - 1) };
        text = text.replace(&format!("dot({d}, {d}) = l^2"), &format!("norm({d}) = l"));
        text = text.replace(&format!("F{i} = \"m{i}*g\""), &format!("F{i} = \"m{i}*g/s\""));
    }
    assert!(text.contains("norm((r2 - r1)) = l") && text.contains("m3*g/s"), "{text}");
    let s = Scenario::new(load(&text).expect("valid"), &[]).expect("derives");
    let band = BandLambda::new(&s.system, &s.derivation, &s.scene.forces).expect("a chain is served");
    #[allow(unused_mut)]
    let mut programs = vec![("interpreted", band.clone())];
    #[cfg(feature = "jit")]
    {
        let mut compiled = band;
        compiled.compile(&s.derivation).expect("this host compiles");
        programs.push(("compiled", compiled));
    }
    let base = random_state(&s, &mut Rng::new(11), n, 2, 0.3, 2.0);
    let r2 = base.get(s.system.graph.symbol_named("r2").expect("r2")).expect("r2");
    let mut zero_link = base.clone();
    set(&s, &mut zero_link, "r3", r2);
    let mut no_s = base.clone();
    set(&s, &mut no_s, "s", Value::Scalar(0.0));
    let settings = Settings::default();
    for (name, mut band) in programs {
        let mut served = Solution::default();
        assert!(band.solve_into(&base, &settings, &mut served), "{name}: the state itself is served");
        for (what, env) in [("a zero-length link", &zero_link), ("s = 0", &no_s)] {
            let what = format!("{name}, {what}");
            let (_, want) = rows_answer(&s, env, &settings);
            let mut untouched = Solution { lambda: vec![42.0], ..Solution::default() };
            assert!(!band.solve_into(env, &settings, &mut untouched), "{what}: declined");
            assert_eq!(untouched.lambda, [42.0], "{what}: the answer untouched");
            let (mut scratch, mut rows, mut got) = (s.program.scratch(), Rows::default(), Solution::default());
            let served =
                band.solve_or_rows_into(&s.system, env, &settings, &s.program, &mut scratch, &mut rows, &mut got);
            assert_eq!(served, Ok(false), "{what}");
            common::assert_same(&got, &want, &what);
        }
    }
}

/// `Auto` solves four rows or fewer densely, as the rows' chain path: declined there,
/// served under `Banded`.
#[test]
fn four_rows_go_dense_under_auto_and_band_when_asked() {
    let (s, band) = chain(4, 2, None, false);
    let mut band = band.expect("a chain is served");
    let env = random_state(&s, &mut Rng::new(4), 4, 2, 0.3, 2.0);
    let mut got = Solution::default();
    assert!(!band.solve_into(&env, &Settings::default(), &mut got));
    let banded = Settings { method: Method::Banded, ..Settings::default() };
    assert!(band.solve_into(&env, &banded, &mut got));
    let (rows, want) = rows_answer(&s, &env, &banded);
    let reference = common::reference_lambda(&rows);
    assert!(error(&got.lambda, &reference) <= 16.0 * error(&want.lambda, &reference) + 16.0 * U);
}

/// Systems the band path does not serve are never made: an inequality row, links listed
/// out of chain order (A's band is wider in that order; reversed it is not), a rigid body,
/// and a band only the symbolic A shows: rows two apart that move one body with J's
/// orthogonal by their formulas (`r1.x = 0` and `r1.y = 0` around a link), whose Aₖ,ₖ₊₂
/// the derivation simplified to zero but J's numbers need not give as one.
#[test]
fn systems_it_does_not_serve_get_no_program() {
    assert!(chain(6, 2, None, true).1.is_none(), "a rope");
    assert!(chain(6, 2, Some(&[1, 3, 2, 4, 5, 6]), false).1.is_none(), "out of order");
    assert!(chain(6, 2, Some(&[6, 5, 4, 3, 2, 1]), false).1.is_some(), "reversed: the band kept");
    let mut text = chain_text(2, 2, None, false);
    let at = text.find("\n[[constraints]]").expect("the chain's constraints");
    let rows = "\n[[constraints]]\nname = \"x\"\nexpr = \"r1.x = 0\"\n\n[[constraints]]\nname = \"link\"\n\
                expr = \"dot(r2 - r1, r2 - r1) = l^2\"\n\n[[constraints]]\nname = \"y\"\nexpr = \"r1.y = 0\"\n";
    let end = text.find("\n[scene]").expect("the scene");
    text.replace_range(at..end, rows);
    let s = Scenario::new(load(&text).expect("valid"), &[]).expect("derives");
    assert_eq!(s.derivation.constraints.len(), 3);
    let entries: Vec<(usize, usize)> = s.derivation.a.iter().map(|e| (e.0, e.1)).collect();
    assert!(!entries.contains(&(0, 2)), "A's formulas are tridiagonal: {entries:?}");
    assert!(BandLambda::new(&s.system, &s.derivation, &s.scene.forces).is_none(), "a band J does not keep");
    let text = std::fs::read_to_string("constraints/rigid/atwood_pulley.toml").expect("the file");
    let s = Scenario::new(load(&text).expect("valid"), &[]).expect("derives");
    assert!(s.system.bodies.iter().any(|b| b.rigid.is_some()), "the file has a rigid body");
    assert!(BandLambda::new(&s.system, &s.derivation, &s.scene.forces).is_none(), "a rigid body");
}

/// The compiled program, which takes A's band from the derivation's formulas, gives the
/// interpreted one's λ, which forms A from J, within rounding (to 1e-10 of the largest), and
/// as accurately against the double-double reference (within 16× the rows' solve's error
/// plus 16u): on one tape (10 links: too few of a shape to batch) and shape by shape (40
/// links each of its own mass parameter, whose rows read no mass and share a shape while
/// the bodies do not, and the benchmark's 40-link chain); masses 2^±4 where each body has
/// its own.
#[cfg(feature = "jit")]
#[test]
fn the_compiled_program_answers_as_the_interpreted_one() {
    let benchmark = Scenario::new(load(&lagrange::scenario::chain(40)).expect("valid"), &[]).expect("derives");
    let cases = [(10, chain(10, 2, None, false).0), (40, chain(40, 2, None, false).0), (40, benchmark)];
    for (case, (n, s)) in cases.into_iter().enumerate() {
        let mut interpreted = BandLambda::new(&s.system, &s.derivation, &s.scene.forces).expect("a chain");
        let mut compiled = interpreted.clone();
        compiled.compile(&s.derivation).expect("this host compiles");
        assert!(compiled.is_compiled() && !interpreted.is_compiled());
        assert_eq!(interpreted.is_batched(), case > 0, "case {case}");
        let mut rng = Rng::new(n as u64);
        for _ in 0..10 {
            let mut env = s.env.clone();
            for i in 1..=n {
                set(&s, &mut env, &format!("r{i}"), Value::Vector(rng.normal_vector(2, 1.0)));
                set(&s, &mut env, &format!("v{i}"), Value::Vector(rng.normal_vector(2, 1.0)));
                if case < 2 {
                    set(&s, &mut env, &format!("m{i}"), Value::Scalar(pow2(rng.uniform(-4.0, 4.0) as i32)));
                }
            }
            let (mut a, mut b) = (Solution::default(), Solution::default());
            assert!(interpreted.solve_into(&env, &Settings::default(), &mut a), "case {case}");
            assert!(compiled.solve_into(&env, &Settings::default(), &mut b), "case {case}");
            let size = a.lambda.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for (x, y) in a.lambda.iter().zip(&b.lambda) {
                assert!((x - y).abs() <= 1e-10 * size, "case {case}: {x} against {y}");
            }
            let (rows, want) = rows_answer(&s, &env, &Settings::default());
            let reference = common::reference_lambda(&rows);
            let r = error(&want.lambda, &reference);
            for (what, got) in [("interpreted", &a), ("compiled", &b)] {
                let e = error(&got.lambda, &reference);
                assert!(e <= 16.0 * r + 16.0 * U, "case {case}, {what}: {e:e} against the rows' {r:e}");
            }
        }
    }
}
