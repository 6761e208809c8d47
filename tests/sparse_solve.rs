//! The sparse Cholesky of the λ solve (`numeric::sparse`, chosen by `solve::plan` for blocks
//! that are not banded): its λ agrees with the dense Cholesky's to round-off (relative to
//! the largest λ) on random sparse systems and on joint grids, a singular block falls back
//! to the minimum-norm solve as the band and dense ones do, the plan takes the sparse factor
//! for a grid and the band for a chain, and the run's cache reuses the sparse analysis with
//! the general solve's answer bit for bit.

use lagrange::numeric::random::Rng;
use lagrange::numeric::rows::{Row, Rows};
use lagrange::numeric::solve::{
    Diagnostic, Factorisation, Method, Settings, Solution, SolveCache, SolvePath, Status, solve_cached, solve_holding,
    solve_with,
};
use proptest::prelude::*;

/// A joint grid after Solver2D's (`constraints/solvers/joint_grid_*.toml`): `k − 1` rows of
/// `k` point masses below a fixed top row, each joined by a distance row to its right and
/// lower neighbours (the top row to its anchors), positions jittered and masses, velocities,
/// forces and c terms drawn from `seed`, so every entry of Ã is non-trivial.
fn grid(k: usize, seed: u64) -> Rows {
    let mut mix = Rng::new(seed);
    let at = |i: usize, j: usize| i * k + j;
    let bodies = (k - 1) * k;
    let position: Vec<[f64; 2]> = (0..bodies)
        .map(|b| {
            let (i, j) = (b / k, b % k);
            [j as f64 + mix.uniform(-0.2, 0.2), -(i as f64 + 1.0) + mix.uniform(-0.2, 0.2)]
        })
        .collect();
    // A distance row from `a` (a body, or an anchor when `ia` is `None`) to body `ib`.
    let row = |a: [f64; 2], ia: Option<usize>, b: [f64; 2], ib: usize, mix: &mut Rng| {
        let d = [b[0] - a[0], b[1] - a[1], 0.0];
        let mut jacobian = Vec::new();
        if let Some(ia) = ia {
            jacobian.push((ia, [-d[0], -d[1], 0.0]));
        }
        jacobian.push((ib, d));
        Row { value: 0.0, rate: 0.0, bias: mix.uniform(-1.0, 1.0), inequality: false, jacobian }
    };
    let mut rows = Vec::new();
    for i in 0..k - 1 {
        for j in 0..k {
            // Down from the body above (the anchor for the first row), then right.
            if i == 0 {
                rows.push(row([j as f64, 0.0], None, position[at(0, j)], at(0, j), &mut mix));
            } else {
                rows.push(row(position[at(i - 1, j)], Some(at(i - 1, j)), position[at(i, j)], at(i, j), &mut mix));
            }
            if j + 1 < k {
                rows.push(row(position[at(i, j)], Some(at(i, j)), position[at(i, j + 1)], at(i, j + 1), &mut mix));
            }
        }
    }
    Rows {
        dim: 2,
        inverse_mass: (0..bodies).map(|_| 1.0 / mix.uniform(0.5, 2.0)).collect(),
        velocity: (0..bodies).map(|_| [mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0), 0.0]).collect(),
        force: vec![[0.0, -10.0, 0.0]; bodies],
        rows,
        axes: Vec::new(),
    }
}

/// An N-link chain of point masses in 2D, links in order.
fn chain(n: usize, seed: u64) -> Rows {
    let mut mix = Rng::new(seed);
    let mut at = [0.0f64, 0.0];
    let mut position = Vec::new();
    for _ in 0..n {
        let angle: f64 = mix.uniform(-1.5, 1.5);
        at = [at[0] + angle.cos(), at[1] + angle.sin()];
        position.push(at);
    }
    let rows = (0..n)
        .map(|k| {
            let prev = if k == 0 { [0.0, 0.0] } else { position[k - 1] };
            let d = [position[k][0] - prev[0], position[k][1] - prev[1], 0.0];
            let mut jacobian = vec![(k, d)];
            if k > 0 {
                jacobian.insert(0, (k - 1, [-d[0], -d[1], 0.0]));
            }
            Row { value: 0.0, rate: 0.0, bias: mix.uniform(-1.0, 1.0), inequality: false, jacobian }
        })
        .collect();
    Rows {
        dim: 2,
        inverse_mass: vec![1.0; n],
        velocity: vec![[0.0; 3]; n],
        force: vec![[0.0, -9.81, 0.0]; n],
        rows,
        axes: Vec::new(),
    }
}

/// `rows` random rows in 3D on `bodies` bodies, each acting on one to three bodies with a
/// random gradient: fewer rows than the bodies' 3 × `bodies` coordinates, so Ã is positive
/// definite (almost surely) and sparse, in no banded order.
fn scattered(bodies: usize, rows: usize, seed: u64) -> Rows {
    let mut mix = Rng::new(seed);
    let rows = (0..rows)
        .map(|_| {
            let count = 1 + (mix.uniform(0.0, 1.0) * 3.0) as usize;
            let mut on: Vec<usize> =
                (0..count).map(|_| (mix.uniform(0.0, 1.0) * bodies as f64) as usize % bodies).collect();
            on.sort_unstable();
            on.dedup();
            let jacobian = on
                .into_iter()
                .map(|b| (b, [mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0)]))
                .collect();
            Row { value: 0.0, rate: 0.0, bias: mix.uniform(-1.0, 1.0), inequality: false, jacobian }
        })
        .collect();
    Rows {
        dim: 3,
        inverse_mass: (0..bodies).map(|_| 1.0 / mix.uniform(0.1, 10.0)).collect(),
        velocity: vec![[0.0; 3]; bodies],
        force: (0..bodies).map(|_| [mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0)]).collect(),
        rows,
        axes: Vec::new(),
    }
}

fn with(method: Method) -> Settings {
    Settings { method, ..Settings::default() }
}

/// The largest difference of λ between two solutions, relative to the largest |λ| (1 when all
/// are below 1).
fn lambda_gap(a: &Solution, b: &Solution) -> f64 {
    let scale = a.lambda.iter().fold(1.0f64, |m, x| m.max(x.abs()));
    a.lambda.iter().zip(&b.lambda).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / scale
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Random sparse positive definite systems: the sparse λ is the dense one to round-off.
    #[test]
    fn sparse_lambda_is_the_dense_lambda_on_random_systems(bodies in 8usize..60, fill in 0.2f64..0.9, seed in any::<u64>()) {
        let rows = scattered(bodies, ((bodies as f64) * fill).max(2.0) as usize, seed);
        let dense = solve_with(&rows, &with(Method::Dense));
        let sparse = solve_with(&rows, &with(Method::Sparse));
        prop_assert_eq!(sparse.status, dense.status);
        if dense.status == Status::Solved {
            prop_assert!(lambda_gap(&sparse, &dense) < 1e-9, "gap {}", lambda_gap(&sparse, &dense));
        }
    }
}

#[test]
fn sparse_lambda_is_the_dense_lambda_on_joint_grids() {
    for (k, seed) in [(5, 1), (12, 2), (20, 3)] {
        let rows = grid(k, seed);
        let dense = solve_with(&rows, &with(Method::Dense));
        assert_eq!(dense.status, Status::Solved, "k = {k}");
        for method in [Method::Sparse, Method::Auto, Method::Banded] {
            let other = solve_with(&rows, &with(method));
            assert_eq!(other.status, Status::Solved, "k = {k}, {method:?}");
            let gap = lambda_gap(&other, &dense);
            assert!(gap < 1e-11, "k = {k}, {method:?}: λ differs by {gap:e} of the largest");
        }
    }
}

#[test]
fn a_singular_grid_falls_back_to_the_minimum_norm_solve_as_the_dense_one_does() {
    // A row repeated: Ã is singular, every factorisation's pivot falls to the rank
    // tolerance, and the answer is the minimum-norm λ with the rows named.
    let mut rows = grid(8, 4);
    let copy = rows.rows[30].clone();
    rows.rows.push(copy);
    let dense = solve_with(&rows, &with(Method::Dense));
    assert_eq!(dense.status, Status::MinimumNorm);
    for method in [Method::Sparse, Method::Auto] {
        let other = solve_with(&rows, &with(method));
        assert_eq!(other.status, Status::MinimumNorm, "{method:?}");
        assert!(
            other.diagnostics.iter().any(|d| matches!(d, Diagnostic::Redundant { constraints, .. }
                if constraints.contains(&30) && constraints.contains(&(rows.rows.len() - 1)))),
            "{method:?}: {:?}",
            other.diagnostics
        );
        assert!(lambda_gap(&other, &dense) < 1e-9, "{method:?}");
    }
    // Through the cache: the general path, the same answer.
    let mut cache = SolveCache::default();
    let cached = solve_cached(&rows, &Settings::default(), &[], &mut cache);
    assert_eq!(cache.last_path(), SolvePath::General);
    assert_eq!(cached, solve_holding(&rows, &Settings::default(), &[]));
}

#[test]
fn the_plan_takes_the_sparse_factor_for_a_grid_and_the_band_for_a_chain() {
    let plan = |rows: &Rows| {
        let mut cache = SolveCache::default();
        solve_cached(rows, &Settings::default(), &[], &mut cache);
        cache.factorisation()
    };
    // The 30 × 30 grid of `constraints/solvers/joint_grid_30.toml` (1 711 rows).
    assert_eq!(plan(&grid(30, 5)), Some(Factorisation::Sparse));
    assert_eq!(plan(&grid(12, 5)), Some(Factorisation::Sparse));
    for n in [20, 300, 3000] {
        assert_eq!(plan(&chain(n, 6)), Some(Factorisation::Band), "n = {n}");
    }
    // Small blocks stay dense (the pendulum's, a two-link chain's).
    assert_eq!(plan(&chain(2, 6)), Some(Factorisation::Dense));
    assert_eq!(plan(&scattered(6, 5, 7)), Some(Factorisation::Dense));
}

#[test]
fn the_cache_reuses_the_sparse_analysis_with_the_general_answer() {
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    let bits = |s: &Solution| s.lambda.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for seed in 0..4 {
        // Another state of the same grid: the same pattern, other numbers.
        let rows = grid(16, 10 + seed);
        let cached = solve_cached(&rows, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Factored);
        assert_eq!(cache.factorisation(), Some(Factorisation::Sparse));
        let general = solve_holding(&rows, &settings, &[]);
        assert_eq!(bits(&cached), bits(&general), "seed {seed}");
        assert_eq!((cached.status, &cached.diagnostics), (general.status, &general.diagnostics));
        // The same J with another right-hand side: the factor serves as it is.
        let mut other = rows.clone();
        other.force.iter_mut().for_each(|f| f[0] += 1.0);
        let again = solve_cached(&other, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Reused);
        assert_eq!(bits(&again), bits(&solve_holding(&other, &settings, &[])));
    }
}

#[test]
fn the_joint_grid_file_solves_alike_with_the_sparse_factor_and_the_band() {
    // `constraints/solvers/joint_grid_30.toml` at its initial state with random velocities
    // and forces (the rows' c terms then carry every entry): 1 711 rows, past the dense
    // bound, so the band (what `Auto` took before) is the reference.
    let text = std::fs::read_to_string("constraints/solvers/joint_grid_30.toml").expect("the file");
    let s =
        lagrange::scenario::Scenario::new(lagrange::model::file::load(&text).expect("valid"), &[]).expect("derives");
    let mut rows = s.program.evaluate(&s.system, &s.env).expect("rows");
    let mut mix = Rng::new(9);
    rows.velocity.iter_mut().for_each(|v| *v = [mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0), 0.0]);
    for row in &mut rows.rows {
        row.bias += mix.uniform(-1.0, 1.0);
    }
    assert_eq!(rows.rows.len(), 1711);
    let band = solve_with(&rows, &with(Method::Banded));
    let auto = solve_with(&rows, &with(Method::Auto));
    assert_eq!((band.status, auto.status), (Status::Solved, Status::Solved));
    let gap = lambda_gap(&auto, &band);
    assert!(gap < 1e-11, "λ differs by {gap:e} of the largest");
    let mut cache = SolveCache::default();
    solve_cached(&rows, &Settings::default(), &[], &mut cache);
    assert_eq!(cache.factorisation(), Some(Factorisation::Sparse));
}
