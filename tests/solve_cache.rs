//! The fast paths of the numbers: the solve that reuses a factorisation
//! (`solve::solve_cached`) and the tape of C and J alone
//! (`RowProgram::evaluate_positions_into`). The reused factorisation must give exactly what
//! the general solve gives, the positions tape the full tape's C and J to rounding, and the
//! reused factorisation must be taken only where it is safe: every case that
//! needs the general solve (an inequality, a number that is not finite, a row that carries
//! no force, redundant rows) goes there and is answered as before. The batched rows of a
//! chain (`numeric::batch`) are held to the interpreter.

mod common;

use lagrange::model::file::load;
use lagrange::numeric::rows::Rows;
use lagrange::numeric::solve::{
    Diagnostic, Method, Settings, Solution, SolveCache, SolvePath, Status, solve_cached, solve_holding,
};
use lagrange::scenario::Scenario;

/// The rows of an N-link chain (`lagrange::scenario::chain`) at a random state `seed`: A
/// tridiagonal with every entry non-trivial, other J for another seed.
fn chain(n: usize, seed: u64) -> Rows {
    let s = Scenario::new(load(&lagrange::scenario::chain(n)).expect("valid"), &[]).expect("derives");
    let env = common::random_env(&s.system, &mut common::Rng::new(seed));
    s.program.evaluate(&s.system, &env).expect("rows")
}

/// Equal number for number (bits, so a −0 for a +0 counts too).
fn assert_same(a: &Solution, b: &Solution) {
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let bits3 = |x: &[[f64; 3]]| x.iter().flat_map(|v| v.map(f64::to_bits)).collect::<Vec<_>>();
    assert_eq!(bits(&a.lambda), bits(&b.lambda));
    assert_eq!(bits3(&a.acceleration), bits3(&b.acceleration));
    assert_eq!(bits3(&a.constraint_force), bits3(&b.constraint_force));
    assert_eq!((&a.active, &a.diagnostics, a.status, &a.contacts), (&b.active, &b.diagnostics, b.status, &b.contacts));
}

/// Solves through `cache` and checks the answer against the general solve; returns the path.
fn solve_checked(rows: &Rows, settings: &Settings, cache: &mut SolveCache) -> SolvePath {
    let fast = solve_cached(rows, settings, &[], cache);
    assert_same(&fast, &solve_holding(rows, settings, &[]));
    cache.last_path()
}

#[test]
fn the_reused_factorisation_gives_the_general_answer_and_only_while_j_and_the_masses_stay() {
    let settings = Settings::default();
    for n in [1, 5, 10, 17, 300] {
        let mut cache = SolveCache::default();
        let rows = chain(n, 1);
        assert_eq!(solve_checked(&rows, &settings, &mut cache), SolvePath::Factored, "n = {n}");
        // Other forces, c and velocities with the same J and masses: the factor serves.
        let mut other = rows.clone();
        for (k, row) in other.rows.iter_mut().enumerate() {
            row.bias = (k as f64 * 0.37).sin();
            row.value = 1e-3 * k as f64;
        }
        other.force.iter_mut().for_each(|f| *f = [0.3, -2.0, 0.0]);
        other.velocity.iter_mut().for_each(|v| v[0] += 1.0);
        assert_eq!(solve_checked(&other, &settings, &mut cache), SolvePath::Reused, "n = {n}");
        // One ulp of one J component, one mass, another state: factored anew.
        let mut nudged = rows.clone();
        let j = &mut nudged.rows[n / 2].jacobian[0].1[1];
        *j = f64::from_bits(j.to_bits() + 1);
        assert_eq!(solve_checked(&nudged, &settings, &mut cache), SolvePath::Factored, "n = {n}");
        let mut heavier = nudged.clone();
        heavier.inverse_mass[n - 1] *= 0.5;
        assert_eq!(solve_checked(&heavier, &settings, &mut cache), SolvePath::Factored, "n = {n}");
        assert_eq!(solve_checked(&chain(n, 2), &settings, &mut cache), SolvePath::Factored, "n = {n}");
        // Other settings: the rank tolerance decides the factor's pivots.
        let strict = Settings { rank_tolerance: 1e-3, ..settings };
        assert_ne!(solve_checked(&chain(n, 2), &strict, &mut cache), SolvePath::Reused, "n = {n}");
    }
}

#[test]
fn every_case_the_cache_does_not_serve_goes_to_the_general_solve() {
    let settings = Settings::default();
    let n = 20;
    // Each case starts from a warm cache whose J matches, so only the guard keeps it off.
    let general = |change: &dyn Fn(&mut Rows), settings: &Settings| {
        let mut cache = SolveCache::default();
        let rows = chain(n, 1);
        solve_checked(&rows, &Settings::default(), &mut cache);
        let mut rows = rows;
        change(&mut rows);
        let path = solve_checked(&rows, settings, &mut cache);
        let answer = solve_holding(&rows, settings, &[]);
        (path, answer)
    };
    // An inequality row (a contact: λ ≥ 0, the active set).
    let (path, _) = general(&|r| r.rows[3].inequality = true, &settings);
    assert_eq!(path, SolvePath::General);
    // A c term, a velocity, a force that is not finite: the general solve's diagnostics.
    for change in [
        (|r: &mut Rows| r.rows[4].bias = f64::NAN) as fn(&mut Rows),
        |r| r.velocity[2][0] = f64::INFINITY,
        |r| r.force[5][1] = f64::NAN,
    ] {
        let (path, answer) = general(&change, &settings);
        assert_eq!(path, SolvePath::General);
        assert!(answer.diagnostics.iter().any(|d| matches!(d, Diagnostic::NonFiniteRow { .. })));
    }
    // A row with a zero gradient carries no force.
    let (path, answer) = general(&|r| r.rows[6].jacobian.iter_mut().for_each(|(_, j)| *j = [0.0; 3]), &settings);
    assert_eq!(path, SolvePath::General);
    assert!(answer.diagnostics.iter().any(|d| matches!(d, Diagnostic::ZeroGradient { constraint: 6, .. })));
    // A redundant row (the same link twice): the band pivot fails, the minimum-norm λ.
    let (path, answer) = general(&|r| r.rows[8] = r.rows[7].clone(), &settings);
    assert_eq!(path, SolvePath::General);
    assert_eq!(answer.status, Status::MinimumNorm);
    // A singular dense block (two rows, so dense is chosen; the same link twice).
    let mut cache = SolveCache::default();
    let mut twice = chain(2, 1);
    twice.rows[1] = twice.rows[0].clone();
    assert_eq!(solve_checked(&twice, &settings, &mut cache), SolvePath::General);
}

#[test]
fn dense_blocks_are_served_too_with_the_general_answer() {
    // Asked for, or chosen (a band of a quarter of the size or more: the pendulum, a
    // two-link chain): factored once, then reused while J and the masses stay.
    let dense = Settings { method: Method::Dense, ..Settings::default() };
    for (n, settings) in [(20, dense), (1, Settings::default()), (2, Settings::default())] {
        let mut cache = SolveCache::default();
        let rows = chain(n, 1);
        assert_eq!(solve_checked(&rows, &settings, &mut cache), SolvePath::Factored, "n = {n}");
        let mut other = rows.clone();
        other.rows.iter_mut().for_each(|row| row.bias += 0.25);
        assert_eq!(solve_checked(&other, &settings, &mut cache), SolvePath::Reused, "n = {n}");
        assert_eq!(solve_checked(&chain(n, 2), &settings, &mut cache), SolvePath::Factored, "n = {n}");
    }
}

#[test]
fn batched_rows_are_the_interpreters_on_chains() {
    // A chain's links and bodies are evaluated shape by shape (`numeric::batch`): the same
    // numbers as the reference semantics, to rounding, at random states; so are C and J of
    // the positions tape.
    let close = |a: f64, b: f64| a == b || (a - b).abs() <= 1e-12 * a.abs().max(b.abs());
    let close3 = |a: &[f64; 3], b: &[f64; 3]| (0..3).all(|d| close(a[d], b[d]));
    // The point-mass chains, and a chain of rigid rods (bodies and their angular slots
    // alike in role, not in type: never one batch).
    let rods = std::fs::read_to_string("constraints/rigid/chain_20.toml").expect("file");
    for (n, text) in [(5, lagrange::scenario::chain(5)), (40, lagrange::scenario::chain(40)), (20, rods)] {
        let s = Scenario::new(load(&text).expect("valid"), &[]).expect("derives");
        let mut rng = common::Rng::new(11);
        let mut scratch = s.program.scratch();
        for _ in 0..5 {
            let env = common::random_env(&s.system, &mut rng);
            let compiled = s.program.evaluate(&s.system, &env).expect("rows");
            let reference = s.program.evaluate_interpreted(&s.system, &s.derivation, &env).expect("rows");
            assert!(compiled.inverse_mass.iter().zip(&reference.inverse_mass).all(|(a, b)| close(*a, *b)));
            assert!(compiled.force.iter().zip(&reference.force).all(|(a, b)| close3(a, b)));
            assert!(compiled.velocity.iter().zip(&reference.velocity).all(|(a, b)| close3(a, b)));
            let mut positions = Vec::new();
            s.program.evaluate_positions_into(&s.system, &env, &mut scratch, &mut positions).expect("rows");
            for ((a, b), p) in compiled.rows.iter().zip(&reference.rows).zip(&positions) {
                let same_j = |x: &lagrange::numeric::rows::Row| {
                    a.jacobian.iter().zip(&x.jacobian).all(|((i, u), (k, w))| i == k && close3(u, w))
                };
                assert!(close(a.value, b.value) && close(a.rate, b.rate) && close(a.bias, b.bias), "n = {n}");
                assert!(same_j(b) && same_j(p) && close(a.value, p.value), "n = {n}: {a:?} vs {b:?}, {p:?}");
            }
        }
    }
}

#[test]
fn the_positions_tape_gives_the_rows_c_and_j_on_every_file() {
    // The same nodes, compiled without Ċ, c and the bodies' numbers: the lowering may share
    // a subexpression differently and round an ulp apart (bead_on_ellipse's C did), never
    // more than a few: relative 1e-13 (against 1) at 10 random states of every file.
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-13 * a.abs().max(b.abs()).max(1.0);
    let mut checked = 0;
    for (path, s) in common::scenarios(&["constraints", "constraints/hard", "constraints/rigid"]) {
        let mut rng = common::Rng::new(11);
        let mut scratch = s.program.scratch();
        let mut positions = Vec::new();
        for _ in 0..10 {
            let env = common::random_env(&s.system, &mut rng);
            let full = s.program.evaluate(&s.system, &env).expect("rows");
            s.program.evaluate_positions_into(&s.system, &env, &mut scratch, &mut positions).expect("rows");
            assert_eq!(positions.len(), full.rows.len());
            for (a, b) in positions.iter().zip(&full.rows) {
                let at = path.display();
                assert!(close(a.value, b.value), "{at}: C {a:?} vs {b:?}");
                assert_eq!(a.inequality, b.inequality, "{at}");
                let same = a.jacobian.len() == b.jacobian.len()
                    && a.jacobian
                        .iter()
                        .zip(&b.jacobian)
                        .all(|((p, x), (q, y))| p == q && (0..3).all(|d| close(x[d], y[d])));
                assert!(same, "{at}: J {a:?} vs {b:?}");
                assert_eq!((a.rate, a.bias), (0.0, 0.0), "{at}");
            }
        }
        checked += 1;
    }
    assert!(checked >= 25, "only {checked} files checked");
}

#[test]
fn the_motion_tape_on_the_positions_rows_gives_the_full_rows_on_every_file() {
    // What a simulation's step does at the end of SHAKE and at the next start: C and J of
    // the positions' tape (or of the last evaluation), then Ċ, c and the slots' 1/m, v and F
    // of a tape of their own. The numbers are the full evaluation's to rounding (relative
    // 1e-13 against 1, as above) at 10 random states of every file; with 3D rigid bodies
    // the whole rows are evaluated instead (said by the `false`).
    use lagrange::numeric::rows::{Rows, State};
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-13 * a.abs().max(b.abs()).max(1.0);
    let close3 = |x: &[f64; 3], y: &[f64; 3]| (0..3).all(|d| close(x[d], y[d]));
    let (mut kept, mut whole) = (0, 0);
    for (path, s) in common::scenarios(&["constraints", "constraints/hard", "constraints/rigid"]) {
        let mut rng = common::Rng::new(12);
        let mut scratch = s.program.scratch();
        let mut rows = Rows::default();
        for _ in 0..10 {
            let env = common::random_env(&s.system, &mut rng);
            let full = s.program.evaluate(&s.system, &env).expect("rows");
            let (q, v, t) = lagrange::numeric::simulate::initial_state(&s.system, &env);
            let state = State { t, q: &q, v: &v };
            s.program
                .evaluate_positions_state_into(&s.system, &env, state, &mut scratch, &mut rows.rows)
                .expect("rows");
            let only_motion =
                s.program.evaluate_motion_state_into(&s.system, &env, state, &mut scratch, &mut rows).expect("rows");
            let at = path.display();
            assert_eq!(only_motion, s.system.bodies.iter().all(|b| b.rigid.is_none()) || s.system.dim() == 2, "{at}");
            assert_eq!(rows.dim, full.dim, "{at}");
            assert_eq!(rows.axes, full.axes, "{at}");
            assert_eq!(rows.inverse_mass.len(), full.inverse_mass.len(), "{at}");
            for (a, b) in rows.inverse_mass.iter().zip(&full.inverse_mass) {
                assert!(close(*a, *b), "{at}: 1/m {a} vs {b}");
            }
            for (x, y) in rows.velocity.iter().zip(&full.velocity).chain(rows.force.iter().zip(&full.force)) {
                assert!(close3(x, y), "{at}: v or F {x:?} vs {y:?}");
            }
            assert_eq!(rows.rows.len(), full.rows.len(), "{at}");
            for (a, b) in rows.rows.iter().zip(&full.rows) {
                let numbers = [(a.value, b.value), (a.rate, b.rate), (a.bias, b.bias)];
                assert!(numbers.iter().all(|&(x, y)| close(x, y)), "{at}: {a:?} vs {b:?}");
                assert_eq!(a.inequality, b.inequality, "{at}");
                let same = a.jacobian.len() == b.jacobian.len()
                    && a.jacobian.iter().zip(&b.jacobian).all(|((p, x), (q, y))| p == q && close3(x, y));
                assert!(same, "{at}: J {a:?} vs {b:?}");
            }
            if only_motion { kept += 1 } else { whole += 1 }
        }
    }
    assert!(kept >= 250 && whole >= 10, "{kept} states by the motion's tape, {whole} whole");
}

#[test]
fn held_constants_give_the_rows_of_a_fresh_load_on_every_file() {
    // A simulation's scratch keeps the run's constants (parameters, masses, given forces)
    // loaded once (`RowScratch::hold_constants`) and reads only the state and the rigid
    // bodies' angles at each evaluation. Its rows must be those of a scratch that loads
    // everything every time, bit for bit: at several states with the same constants (the
    // rigid bodies' angles and angular velocities changed through the environment), after
    // an evaluation from an environment alone in between (which overwrites the buffers),
    // and with new constants after `hold_constants` again.
    use lagrange::expr::eval::Env;
    use lagrange::numeric::rows::{Rows, State};
    let bits = |r: &Rows| {
        let rows = r.rows.iter().flat_map(|row| {
            [row.value, row.rate, row.bias].into_iter().chain(row.jacobian.iter().flat_map(|(_, j)| *j))
        });
        let slots =
            r.inverse_mass.iter().copied().chain(r.velocity.iter().chain(&r.force).chain(&r.axes).flatten().copied());
        rows.chain(slots).map(f64::to_bits).collect::<Vec<_>>()
    };
    let mut checked = 0;
    for (path, s) in common::scenarios(&["constraints", "constraints/hard", "constraints/rigid"]) {
        let at = path.display();
        let mut rng = common::Rng::new(16);
        let (mut held, mut fresh) = (s.program.scratch(), s.program.scratch());
        let (mut a, mut b) = (Rows::default(), Rows::default());
        for _ in 0..3 {
            let constants = common::random_env(&s.system, &mut rng);
            held.hold_constants();
            for k in 0..3 {
                // Another state and other angles, the same constants.
                let other = common::random_env(&s.system, &mut rng);
                let mut env: Env = constants.clone();
                for rigid in s.system.bodies.iter().filter_map(|b| b.rigid.as_ref()) {
                    for symbol in [rigid.orientation, rigid.angular_velocity] {
                        if let Some(value) = other.get(symbol) {
                            env.set(symbol, value);
                        }
                    }
                }
                let (q, v, t) = lagrange::numeric::simulate::initial_state(&s.system, &other);
                let state = State { t, q: &q, v: &v };
                if k == 1 {
                    s.program.evaluate_into(&s.system, &other, &mut held, &mut a).expect("rows");
                    s.program.evaluate_positions_into(&s.system, &other, &mut held, &mut a.rows).expect("rows");
                }
                s.program.evaluate_state_into(&s.system, &env, state, &mut held, &mut a).expect("rows");
                s.program.evaluate_state_into(&s.system, &env, state, &mut fresh, &mut b).expect("rows");
                assert_eq!(bits(&a), bits(&b), "{at}: all rows");
                s.program.evaluate_positions_state_into(&s.system, &env, state, &mut held, &mut a.rows).expect("rows");
                s.program.evaluate_positions_state_into(&s.system, &env, state, &mut fresh, &mut b.rows).expect("rows");
                assert_eq!(bits(&a), bits(&b), "{at}: C and J");
                let kept_a =
                    s.program.evaluate_motion_state_into(&s.system, &env, state, &mut held, &mut a).expect("rows");
                let kept_b =
                    s.program.evaluate_motion_state_into(&s.system, &env, state, &mut fresh, &mut b).expect("rows");
                assert_eq!((kept_a, bits(&a)), (kept_b, bits(&b)), "{at}: the motion's rows");
            }
        }
        checked += 1;
    }
    assert!(checked >= 25, "only {checked} files checked");
}

#[test]
fn an_evaluation_says_whether_every_number_it_wrote_is_finite() {
    // `RowScratch::finite` is found as the rows are filled, and a simulation trusts it
    // instead of looking at the rows again (`Dynamics`): it must say what a look at the
    // numbers written says — every number of a full evaluation, C and J of the positions'
    // tape, Ċ, c and the slots' numbers of the motion tape — at ordinary states and at
    // states with a position or velocity made NaN or infinite, on every file.
    use lagrange::numeric::rows::{Row, Rows, State};
    let finite3 = |x: &[f64; 3]| x.iter().all(|c| c.is_finite());
    let entries = |row: &Row| row.jacobian.iter().all(|(_, j)| finite3(j));
    let slots = |rows: &Rows| {
        rows.inverse_mass.iter().all(|w| w.is_finite()) && rows.velocity.iter().chain(&rows.force).all(finite3)
    };
    let (mut checked, mut poisoned) = (0, 0);
    for (path, s) in common::scenarios(&["constraints", "constraints/hard", "constraints/rigid"]) {
        let at = path.display();
        let mut rng = common::Rng::new(18);
        let mut scratch = s.program.scratch();
        let mut rows = Rows::default();
        for case in 0..8 {
            let env = common::random_env(&s.system, &mut rng);
            let (mut q, mut v, t) = lagrange::numeric::simulate::initial_state(&s.system, &env);
            if case % 2 == 1 {
                let bad = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][case % 3];
                let slot = (rng.next_u64() % s.system.bodies.len() as u64) as usize;
                let d = (rng.next_u64() % s.system.dim() as u64) as usize;
                if case % 4 == 1 {
                    q[slot][d] = bad
                } else {
                    v[slot][d] = bad
                }
                poisoned += 1;
            }
            let state = State { t, q: &q, v: &v };
            s.program.evaluate_state_into(&s.system, &env, state, &mut scratch, &mut rows).expect("rows");
            let all =
                rows.rows.iter().all(|r| r.value.is_finite() && r.rate.is_finite() && r.bias.is_finite() && entries(r));
            assert_eq!(scratch.finite(), all && slots(&rows), "{at} case {case}: full");
            s.program
                .evaluate_positions_state_into(&s.system, &env, state, &mut scratch, &mut rows.rows)
                .expect("rows");
            let positions = rows.rows.iter().all(|r| r.value.is_finite() && entries(r));
            assert_eq!(scratch.finite(), positions, "{at} case {case}: positions");
            let kept =
                s.program.evaluate_motion_state_into(&s.system, &env, state, &mut scratch, &mut rows).expect("rows");
            let motion = rows.rows.iter().all(|r| r.rate.is_finite() && r.bias.is_finite()) && slots(&rows);
            let written =
                if kept { motion } else { motion && rows.rows.iter().all(|r| r.value.is_finite() && entries(r)) };
            assert_eq!(scratch.finite(), written, "{at} case {case}: motion");
            checked += 1;
        }
    }
    assert!(checked >= 200 && poisoned >= 100, "checked {checked}, poisoned {poisoned}");
}
