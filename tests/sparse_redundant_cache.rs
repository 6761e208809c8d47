//! The run's solve cache on a redundant block past the dense decomposition
//! (`solve::MAX_DENSE_ROWS`), as a rigid joint grid is: it keeps the factor its minimum norm
//! iterates with (and its analysis), so a solve with the same J only iterates on it and a
//! new J of the same pattern only refactors it, with the general solve's answer bit for bit;
//! rows that contradict each other are refused by the kept factor and answered by the
//! general solve (which refuses them as too large). Within the dense bound a block that is
//! singular whatever its numbers takes the sparse factor in the cache too (the general
//! solve keeps the eigendecomposition, for its rank and condition).
//!
//! The braced grid holds every point mass, so the cache (and the general solve past the
//! dense bound) take the minimum norm in the bodies' velocity space (`numeric::gram`), and
//! keep its factor for a J that moved in its last bits (a grid at rest): both sides of those
//! switches are tested here, with a pendulum hung from the grid (a body the rows do not hold)
//! for the regularised factor.
//!
//! A correction's step through a cache whose velocity space is on
//! (`SolveCache::set_velocity_space`, the exact velocity step's runs) takes the velocity
//! change alone on the body-space factor, without λ: the same step as the minimum-norm λ's
//! M⁻¹(F + Jᵀλ) to rounding, fresh and with a stale factor, and rows that contradict each
//! other still go to the general solve.
//!
//! The block is a braced grid of point masses: each joined by distance rows to its right
//! and lower neighbours and across both diagonals of each cell (the top row to fixed
//! anchors), about four rows per body on its two velocity components, so Ã is singular
//! whatever the numbers. Consistent c terms are J w for a random w (in the range of J, so
//! A λ = −(J M⁻¹ F + c) has a solution); random ones contradict.

use lagrange::numeric::random::Rng;
use lagrange::numeric::rows::{Row, Rows};
use lagrange::numeric::solve::{
    Diagnostic, Factorisation, MAX_DENSE_ROWS, Settings, Solution, SolveCache, SolvePath, Status, solve_cached,
    solve_cached_step_into, solve_holding,
};
use proptest::prelude::*;

/// The braced grid: `k − 1` rows of `k` point masses below fixed anchors, positions
/// jittered, masses, velocities and forces drawn from `seed`, c terms consistent (J w).
fn braced(k: usize, seed: u64) -> Rows {
    let mut mix = Rng::new(seed);
    let bodies = (k - 1) * k;
    let at = |i: usize, j: usize| i * k + j;
    let position: Vec<[f64; 2]> = (0..bodies)
        .map(|b| [(b % k) as f64 + mix.uniform(-0.1, 0.1), -((b / k) as f64 + 1.0) + mix.uniform(-0.1, 0.1)])
        .collect();
    // The point of (i, j), i = −1 being the anchors' row.
    let point = |i: isize, j: usize| if i < 0 { [j as f64, 0.0] } else { position[at(i as usize, j)] };
    let body = |i: isize, j: usize| (i >= 0).then(|| at(i as usize, j));
    let mut pairs = Vec::new();
    for i in 0..(k - 1) as isize {
        for j in 0..k {
            pairs.push(((i - 1, j), (i, j)));
            if j + 1 < k {
                pairs.push(((i, j), (i, j + 1)));
                pairs.push(((i - 1, j), (i, j + 1)));
                pairs.push(((i - 1, j + 1), (i, j)));
            }
        }
    }
    let w: Vec<[f64; 3]> = (0..bodies).map(|_| [mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0), 0.0]).collect();
    let rows = pairs
        .iter()
        .map(|&((ia, ja), (ib, jb))| {
            let (a, b) = (point(ia, ja), point(ib, jb));
            let d = [b[0] - a[0], b[1] - a[1], 0.0];
            let mut jacobian = Vec::new();
            if let Some(a) = body(ia, ja) {
                jacobian.push((a, [-d[0], -d[1], 0.0]));
            }
            jacobian.push((body(ib, jb).expect("a body"), d));
            let bias = jacobian.iter().map(|(s, j)| j[0] * w[*s][0] + j[1] * w[*s][1]).sum();
            Row { value: 0.0, rate: 0.0, bias, inequality: false, jacobian }
        })
        .collect();
    Rows {
        dim: 2,
        inverse_mass: (0..bodies).map(|_| 1.0 / mix.uniform(0.5, 2.0)).collect(),
        velocity: (0..bodies).map(|_| [mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0), 0.0]).collect(),
        force: vec![[0.0, -10.0, 0.0]; bodies],
        rows,
        axes: Vec::new(),
    }
}

fn bits(s: &Solution) -> Vec<u64> {
    s.lambda.iter().chain(s.acceleration.iter().flatten()).map(|x| x.to_bits()).collect()
}

/// The cached solve is the general one: λ and accelerations bit for bit, status and
/// diagnostics equal.
fn assert_general(cached: &Solution, rows: &Rows, what: &str) {
    let general = solve_holding(rows, &Settings::default(), &[]);
    assert_eq!(bits(cached), bits(&general), "{what}");
    assert_eq!((cached.status, &cached.diagnostics), (general.status, &general.diagnostics), "{what}");
}

#[test]
fn the_cache_keeps_the_factor_of_a_redundant_block_with_the_general_answer() {
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    for seed in 0..3 {
        // Another state of the same grid: the same pattern, other numbers.
        let rows = braced(17, 20 + seed);
        assert!(rows.rows.len() > MAX_DENSE_ROWS && rows.rows.len() > 2 * rows.inverse_mass.len());
        let cached = solve_cached(&rows, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Factored, "seed {seed}");
        assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
        assert_eq!(cached.status, Status::MinimumNorm, "{:?}", cached.diagnostics);
        assert!(
            cached
                .diagnostics
                .iter()
                .any(|d| matches!(d, Diagnostic::RedundantSparse { size, .. } if *size == rows.rows.len())),
            "{:?}",
            cached.diagnostics
        );
        assert_general(&cached, &rows, &format!("seed {seed}, factored"));
        // The same J with other forces and c terms (still consistent): the kept factor serves.
        let mut other = rows.clone();
        other.force.iter_mut().for_each(|f| f[0] += 1.0);
        for row in &mut other.rows {
            row.bias *= -0.5;
        }
        let again = solve_cached(&other, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Reused, "seed {seed}");
        assert_general(&again, &other, &format!("seed {seed}, reused"));
    }
}

#[test]
fn rows_that_contradict_each_other_are_refused_by_the_kept_factor() {
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    let rows = braced(17, 7);
    solve_cached(&rows, &settings, &[], &mut cache);
    assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
    // The same J with c terms drawn at random: no λ satisfies them all; the kept factor's
    // residual shows it and the general solve answers (too large for its least squares).
    let mut clash = rows.clone();
    let mut mix = Rng::new(99);
    for row in &mut clash.rows {
        row.bias = mix.uniform(-1.0, 1.0);
    }
    let refused = solve_cached(&clash, &settings, &[], &mut cache);
    assert_eq!(cache.last_path(), SolvePath::General);
    assert_eq!(refused.status, Status::Failed);
    assert!(
        refused.diagnostics.iter().any(|d| matches!(d, Diagnostic::TooLarge { rows, .. } if *rows == clash.rows.len())),
        "{:?}",
        refused.diagnostics
    );
    assert_general(&refused, &clash, "contradicting rows");
    // Consistent again with the same J: the factor is still there and serves.
    let served = solve_cached(&rows, &settings, &[], &mut cache);
    assert_eq!(cache.last_path(), SolvePath::Reused);
    assert_general(&served, &rows, "consistent again");
}

/// The largest |a − b| over the largest |b|.
fn gap(a: &[f64], b: &[f64]) -> f64 {
    let top = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f64, f64::max) / top
}

#[test]
fn a_block_within_the_dense_bound_singular_whatever_its_numbers_takes_the_sparse_factor_too() {
    // 9 × 10 bodies, 333 rows on 180 velocity components: the general solve takes the
    // eigendecomposition (rank and condition, what `lagrange solve` shows), a run's cache
    // the body-space sparse factor: the same minimum-norm λ and accelerations to rounding.
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    for seed in 0..3 {
        let rows = braced(10, 3 + seed);
        assert!(rows.rows.len() <= MAX_DENSE_ROWS && rows.rows.len() > 2 * rows.inverse_mass.len());
        let cached = solve_cached(&rows, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Factored, "seed {seed}");
        assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
        assert_eq!(cached.status, Status::MinimumNorm);
        assert!(
            cached.diagnostics.iter().any(|d| matches!(d, Diagnostic::RedundantSparse { .. })),
            "{:?}",
            cached.diagnostics
        );
        let general = solve_holding(&rows, &settings, &[]);
        assert_eq!(general.status, Status::MinimumNorm);
        assert!(
            general.diagnostics.iter().any(|d| matches!(d, Diagnostic::Redundant { rank, size, .. }
                if *rank < *size && *size == rows.rows.len())),
            "{:?}",
            general.diagnostics
        );
        let lambda = gap(&cached.lambda, &general.lambda);
        assert!(lambda < 1e-6, "seed {seed}: λ apart by {lambda:e} of the largest");
        let flat = |s: &Solution| s.acceleration.iter().flatten().copied().collect::<Vec<f64>>();
        let acceleration = gap(&flat(&cached), &flat(&general));
        assert!(acceleration < 1e-9, "seed {seed}: accelerations apart by {acceleration:e} of the largest");
        // The same J: the kept factor serves.
        let mut other = rows.clone();
        other.force.iter_mut().for_each(|f| f[1] -= 2.0);
        solve_cached(&other, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Reused);
    }
}

/// The braced grid with a pendulum: one more point mass hung by one slanted distance row
/// from the last body, so of its two velocity components the rows move, one is held by no
/// row and G lacks full column rank.
fn with_pendulum(mut rows: Rows) -> Rows {
    let last = rows.inverse_mass.len() - 1;
    rows.inverse_mass.push(1.0);
    rows.velocity.push([0.0, 0.0, 0.0]);
    rows.force.push([0.0, -10.0, 0.0]);
    rows.rows.push(Row {
        value: 0.0,
        rate: 0.0,
        bias: 0.0,
        inequality: false,
        jacobian: vec![(last, [0.6, 0.8, 0.0]), (last + 1, [-0.6, -0.8, 0.0])],
    });
    rows
}

#[test]
fn a_body_no_row_holds_takes_the_regularised_factor() {
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    // Held: the body-space factor, in the cache and in the general solve (bit for bit).
    let rows = braced(17, 5);
    let held = solve_cached(&rows, &settings, &[], &mut cache);
    assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
    assert_general(&held, &rows, "held");
    // Not held: the regularised factor, the same answer as the general solve's, and the
    // minimum norm of the two agree on the grid's rows.
    let hung = with_pendulum(rows.clone());
    let loose = solve_cached(&hung, &settings, &[], &mut cache);
    assert_eq!(cache.last_path(), SolvePath::Factored);
    assert_eq!(cache.factorisation(), Some(Factorisation::RegularisedSparse));
    assert_eq!(loose.status, Status::MinimumNorm, "{:?}", loose.diagnostics);
    assert_general(&loose, &hung, "hung");
    // Held again: the body-space factor is made anew.
    solve_cached(&rows, &settings, &[], &mut cache);
    assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
}

/// Every J entry of `rows` times (1 + `relative`·u) for u from `seed` in [−1, 1].
fn nudged(rows: &Rows, relative: f64, seed: u64) -> Rows {
    let mut mix = Rng::new(seed);
    let mut out = rows.clone();
    for row in &mut out.rows {
        for (_, j) in &mut row.jacobian {
            for x in j.iter_mut().take(2) {
                *x *= 1.0 + relative * mix.uniform(-1.0, 1.0);
            }
        }
    }
    out
}

#[test]
fn a_stale_body_space_factor_serves_a_j_that_moved_in_its_last_bits() {
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    let rows = braced(17, 11);
    solve_cached(&rows, &settings, &[], &mut cache);
    assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
    let flat = |s: &Solution| s.acceleration.iter().flatten().copied().collect::<Vec<f64>>();
    for (round, relative) in [1e-15, 1e-14, 1e-13].into_iter().enumerate() {
        // J moved by rounding (a grid at rest): the kept factor iterates to this J's
        // answer, the general solve's to rounding times the condition (the same minimum
        // norm: no ε; two fresh solves of J apart by 1e-15 differ as much).
        let moved = nudged(&rows, relative, round as u64);
        let stale = solve_cached(&moved, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Stale, "{relative:e}");
        let general = solve_holding(&moved, &settings, &[]);
        assert_eq!(stale.status, general.status);
        let lambda = gap(&stale.lambda, &general.lambda);
        assert!(lambda < 1e-10, "{relative:e}: λ apart by {lambda:e} of the largest");
        let acceleration = gap(&flat(&stale), &flat(&general));
        assert!(acceleration < 1e-10, "{relative:e}: accelerations apart by {acceleration:e}");
    }
    // J moved by more than `STALE_CHANGE`: factored, the general answer bit for bit.
    let far = nudged(&rows, 1e-6, 9);
    let fresh = solve_cached(&far, &settings, &[], &mut cache);
    assert_eq!(cache.last_path(), SolvePath::Factored);
    assert_general(&fresh, &far, "moved by 1e-6");
}

#[test]
fn the_body_space_minimum_norm_is_the_eigendecomposition_s() {
    // Within the dense bound the general solve takes the eigendecomposition: the body-space
    // minimum norm has no regularisation's share, so λ agrees to rounding times the
    // condition.
    let settings = Settings::default();
    for seed in 0..3 {
        let rows = braced(8, 40 + seed);
        let mut cache = SolveCache::default();
        let cached = solve_cached(&rows, &settings, &[], &mut cache);
        assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
        let general = solve_holding(&rows, &settings, &[]);
        let lambda = gap(&cached.lambda, &general.lambda);
        assert!(lambda < 1e-10, "seed {seed}: λ apart by {lambda:e} of the largest");
    }
}

/// `rows` with body `b`'s x components zero in every row (that component is no column of
/// G), the c terms J u for the rows' velocities u (consistent).
fn without_x_of(rows: &Rows, b: usize) -> Rows {
    consistent(rows, Some(b))
}

/// `rows` with the c terms J u for the rows' velocities u, body `b`'s x components zeroed
/// first when given.
fn consistent(rows: &Rows, b: Option<usize>) -> Rows {
    let mut out = rows.clone();
    for row in &mut out.rows {
        for (slot, j) in &mut row.jacobian {
            if Some(*slot) == b {
                j[0] = 0.0;
            }
        }
        row.bias = row.jacobian.iter().map(|(s, j)| j[0] * rows.velocity[*s][0] + j[1] * rows.velocity[*s][1]).sum();
    }
    out
}

#[test]
fn a_component_that_starts_or_stops_moving_makes_the_factor_anew() {
    // The same slots in the same order (the cache refactors in place when it can), but the
    // set of moved components changes: a new column (a component no row moved before) and
    // a vanished one (no row moves it any more) each need G and its factor made anew; a J
    // that keeps the set (the nudged grid) is refactored in place. Each answer is the
    // general solve's, bit for bit.
    let settings = Settings::default();
    let mut cache = SolveCache::default();
    let rows = braced(17, 13);
    let b = rows.inverse_mass.len() / 2;
    let fewer = without_x_of(&rows, b);
    let solved = solve_cached(&fewer, &settings, &[], &mut cache);
    assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
    assert_general(&solved, &fewer, "without a column");
    for (what, next) in [
        ("a new column", consistent(&rows, None)),
        ("a vanished column", fewer.clone()),
        ("the same columns", without_x_of(&nudged(&rows, 1e-6, 3), b)),
    ] {
        let solved = solve_cached(&next, &settings, &[], &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Factored, "{what}");
        assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace), "{what}");
        assert_eq!(solved.status, Status::MinimumNorm, "{what}: {:?}", solved.diagnostics);
        assert_general(&solved, &next, what);
    }
}

/// The accelerations of a solution, flattened.
fn flat(s: &Solution) -> Vec<f64> {
    s.acceleration.iter().flatten().copied().collect()
}

/// The step alone through `cache` with its velocity space on.
fn velocity_step(rows: &Rows, cache: &mut SolveCache) -> Solution {
    let mut out = Solution::default();
    cache.set_velocity_space(true);
    solve_cached_step_into(rows, &Settings::default(), cache, &mut out);
    out
}

/// The minimum-norm λ's accelerations M⁻¹(F + Jᵀλ) through a fresh cache (the body-space
/// minimum norm, to rounding).
fn minimum_norm_step(rows: &Rows) -> Solution {
    let mut cache = SolveCache::default();
    let out = solve_cached(rows, &Settings::default(), &[], &mut cache);
    assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
    out
}

#[test]
fn the_velocity_space_step_is_the_minimum_norm_s_fresh_stale_and_refactored() {
    let mut cache = SolveCache::default();
    let rows = braced(17, 31);
    let fresh = velocity_step(&rows, &mut cache);
    assert_eq!(cache.last_path(), SolvePath::Factored);
    assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
    assert_eq!(fresh.status, Status::MinimumNorm);
    assert!(fresh.lambda.is_empty() && fresh.diagnostics.is_empty());
    let gap_fresh = gap(&flat(&fresh), &flat(&minimum_norm_step(&rows)));
    assert!(gap_fresh < 1e-11, "fresh: apart by {gap_fresh:e} of the largest");
    // The general solve (past the dense bound: the body-space minimum norm too).
    let general = gap(&flat(&fresh), &flat(&solve_holding(&rows, &Settings::default(), &[])));
    assert!(general < 1e-11, "fresh against the general solve: {general:e}");
    for (round, relative) in [1e-15, 1e-14, 1e-13].into_iter().enumerate() {
        let moved = nudged(&rows, relative, 50 + round as u64);
        let stale = velocity_step(&moved, &mut cache);
        assert_eq!(cache.last_path(), SolvePath::Stale, "{relative:e}");
        let apart = gap(&flat(&stale), &flat(&minimum_norm_step(&moved)));
        assert!(apart < 1e-11, "{relative:e}: apart by {apart:e} of the largest");
    }
    // Past `STALE_CHANGE`: factored, the same step.
    let far = nudged(&rows, 1e-6, 60);
    let refactored = velocity_step(&far, &mut cache);
    assert_eq!(cache.last_path(), SolvePath::Factored);
    let apart = gap(&flat(&refactored), &flat(&minimum_norm_step(&far)));
    assert!(apart < 1e-11, "refactored: apart by {apart:e} of the largest");
    // Off again: the minimum norm's own numbers, bit for bit the general solve's.
    cache.set_velocity_space(false);
    let mut off = Solution::default();
    solve_cached_step_into(&far, &Settings::default(), &mut cache, &mut off);
    assert_general(&off, &far, "velocity space off");
}

#[test]
fn rows_that_contradict_each_other_are_refused_by_the_velocity_space_step() {
    let mut cache = SolveCache::default();
    let rows = braced(17, 37);
    velocity_step(&rows, &mut cache);
    // A J moved in its last bits: the entry is stale, and the next step tries the kept
    // factor as it is (no refill) first.
    velocity_step(&nudged(&rows, 1e-15, 38), &mut cache);
    assert_eq!(cache.last_path(), SolvePath::Stale);
    let mut clash = rows.clone();
    let mut mix = Rng::new(101);
    for row in &mut clash.rows {
        row.bias = mix.uniform(-1.0, 1.0);
    }
    let refused = velocity_step(&clash, &mut cache);
    assert_eq!(cache.last_path(), SolvePath::General);
    assert_eq!(refused.status, Status::Failed);
    assert_general(&refused, &clash, "contradicting rows");
    // The factor is kept (made anew for this J when the stale one did not converge) and
    // serves consistent rows again.
    let served = velocity_step(&rows, &mut cache);
    assert_eq!(cache.last_path(), SolvePath::Reused);
    let apart = gap(&flat(&served), &flat(&minimum_norm_step(&rows)));
    assert!(apart < 1e-11, "consistent again: apart by {apart:e} of the largest");
}

/// One row's J: (slot, component per axis) per part.
type Parts = Vec<(usize, [f64; 3])>;

/// A rigid joint grid as the exact velocity step's rows: `k − 1` rows of `k` discs below a
/// fixed top row, each pinned by a revolute joint (two rows) to its right and lower
/// neighbours at the midpoint (the top row's joints to world points; J does not depend on
/// where the discs are), angles, masses and inertias drawn from `seed`; slots 0..n the discs' positions, n..2n
/// their angles (in the first component). c terms consistent (J w) unless `clash`.
fn rigid_grid(k: usize, seed: u64, clash: bool) -> Rows {
    let mut mix = Rng::new(seed);
    let n = (k - 1) * k;
    let at = |i: usize, j: usize| i * k + j;
    let angle: Vec<f64> = (0..n).map(|_| mix.uniform(-0.3, 0.3)).collect();
    // The lever from disc b's centre to the point at `offset` in its frame.
    let lever = |b: usize, offset: [f64; 2]| {
        let (s, c) = angle[b].sin_cos();
        [c * offset[0] - s * offset[1], s * offset[0] + c * offset[1]]
    };
    // A joint's parts on one disc, the sign +1 for the first body, −1 for the second.
    let parts = |b: usize, offset: [f64; 2], sign: f64| {
        let r = lever(b, offset);
        [
            [(b, [sign, 0.0, 0.0]), (n + b, [-sign * r[1], 0.0, 0.0])],
            [(b, [0.0, sign, 0.0]), (n + b, [sign * r[0], 0.0, 0.0])],
        ]
    };
    let mut joints: Vec<[Parts; 2]> = Vec::new();
    for i in 0..k - 1 {
        for j in 0..k {
            // Up: to the world point above (the top row) or the disc above.
            let below = parts(at(i, j), [0.0, 0.5], -1.0);
            let mut up = [below[0].to_vec(), below[1].to_vec()];
            if i > 0 {
                let above = parts(at(i - 1, j), [0.0, -0.5], 1.0);
                for (u, a) in up.iter_mut().zip(above) {
                    u.splice(0..0, a);
                }
            }
            joints.push(up);
            if j + 1 < k {
                let (left, right) = (parts(at(i, j), [0.5, 0.0], 1.0), parts(at(i, j + 1), [-0.5, 0.0], -1.0));
                joints.push([
                    left[0].iter().chain(&right[0]).copied().collect(),
                    left[1].iter().chain(&right[1]).copied().collect(),
                ]);
            }
        }
    }
    let w: Vec<f64> = (0..2 * n).flat_map(|_| [mix.uniform(-1.0, 1.0), mix.uniform(-1.0, 1.0)]).collect();
    let rows = joints
        .into_iter()
        .flatten()
        .map(|jacobian| {
            let bias = if clash {
                mix.uniform(-1.0, 1.0)
            } else {
                jacobian.iter().map(|(s, j)| j[0] * w[2 * s] + j[1] * w[2 * s + 1]).sum()
            };
            Row { value: 0.0, rate: 0.0, bias, inequality: false, jacobian }
        })
        .collect();
    let mass: Vec<f64> = (0..n).map(|_| 1.0 / mix.uniform(0.3, 3.0)).collect();
    let inertia: Vec<f64> = (0..n).map(|_| 1.0 / mix.uniform(0.02, 0.2)).collect();
    Rows {
        dim: 2,
        inverse_mass: mass.into_iter().chain(inertia).collect(),
        velocity: vec![[0.0; 3]; 2 * n],
        force: (0..n).map(|_| [0.0, -10.0, 0.0]).chain((0..n).map(|_| [0.0; 3])).collect(),
        rows,
        axes: Vec::new(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// On a redundant rigid grid the velocity-space step is the minimum-norm λ's
    /// M⁻¹(F + Jᵀλ) to 1e-11 of the largest (round-off times the condition: measured up to
    /// 2.3e-12), fresh and with a stale factor (J moved in its
    /// last bits), and an inconsistent right-hand side is still the general solve's answer.
    #[test]
    fn the_velocity_space_step_of_a_rigid_grid_is_the_minimum_norm_s(k in 3usize..7, seed in any::<u64>()) {
        let rows = rigid_grid(k, seed, false);
        prop_assert!(rows.rows.len() > 3 * (k - 1) * k);
        let mut cache = SolveCache::default();
        let fresh = velocity_step(&rows, &mut cache);
        prop_assert_eq!(cache.factorisation(), Some(Factorisation::BodySpace));
        prop_assert_eq!(fresh.status, Status::MinimumNorm);
        let apart = gap(&flat(&fresh), &flat(&minimum_norm_step(&rows)));
        prop_assert!(apart < 1e-11, "fresh: apart by {:e}", apart);
        let moved = nudged(&rows, 1e-15, seed ^ 1);
        let stale = velocity_step(&moved, &mut cache);
        prop_assert_eq!(cache.last_path(), SolvePath::Stale);
        let apart = gap(&flat(&stale), &flat(&minimum_norm_step(&moved)));
        prop_assert!(apart < 1e-11, "stale: apart by {:e}", apart);
        let clash = rigid_grid(k, seed, true);
        let refused = velocity_step(&clash, &mut cache);
        prop_assert_eq!(cache.last_path(), SolvePath::General);
        let general = solve_holding(&clash, &Settings::default(), &[]);
        prop_assert_eq!((refused.status, &refused.diagnostics), (general.status, &general.diagnostics));
        prop_assert!(!refused.is_answer());
    }
}
