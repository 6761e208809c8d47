//! Redundant constraints in a coupled block past the dense decomposition's 1 000 rows
//! (`solve::MAX_DENSE_ROWS`): the solve finds the minimum-norm λ by regularised sparse
//! solves, and a block it cannot solve (redundant rows that contradict each other) stops a
//! simulation with an error instead of stepping on as if those constraints were absent.
//!
//! The scene is the 30 × 30 joint grid (1 711 distance rows on point masses, one block) with
//! one constraint written twice. Its minimum-norm λ has a closed form: the two copies share
//! the original row's λ equally (of all splits λ₁ + λ₂ = λ, λ₁ = λ₂ = λ/2 has the least
//! λ₁² + λ₂²), and every other row keeps the λ of the grid without the copy, which is
//! nonsingular and solved by the sparse Cholesky.

use lagrange::model::file::load;
use lagrange::numeric::dynamics::SimError;
use lagrange::numeric::simulate::Summary;
use lagrange::numeric::solve::{Diagnostic, MAX_DENSE_ROWS, Solution, Status, solve};
use lagrange::numeric::velocity::{Settings as VelocitySettings, Solver};
use lagrange::scenario::Scenario;
use std::process::Command;

const GRID: &str = include_str!("../constraints/solvers/joint_grid_30.toml");

/// The grid's text with `h1_1` written again as `h1_1_twin`, of length `length`.
fn twin_text(length: &str) -> String {
    format!("{GRID}\n[[constraints]]\nname = \"h1_1_twin\"\nexpr = \"norm(r_p1_1 - r_p1_0) = {length}\"\n")
}

/// The grid with `h1_1` (the first row's first horizontal link) written again as
/// `h1_1_twin`, of length `length` (1.0 is the same constraint).
fn grid_with_twin(length: &str) -> Scenario {
    Scenario::new(load(&twin_text(length)).expect("valid file"), &[]).expect("derives")
}

fn solve_at_start(s: &Scenario) -> Solution {
    solve(&s.program.evaluate(&s.system, &s.env).expect("rows"))
}

fn index(s: &Scenario, name: &str) -> usize {
    s.system.constraints.iter().position(|c| c.name == name).expect("constraint")
}

#[test]
fn a_constraint_written_twice_shares_its_lambda_equally_and_the_rest_is_unchanged() {
    let plain = Scenario::new(load(GRID).expect("valid"), &[]).expect("derives");
    assert!(plain.system.constraints.len() > MAX_DENSE_ROWS, "the block must be past the dense limit");
    let single = solve_at_start(&plain);
    assert_eq!(single.status, Status::Solved);

    let twin = grid_with_twin("1.0");
    let double = solve_at_start(&twin);
    assert_eq!(double.status, Status::MinimumNorm, "{:?}", double.diagnostics);
    let (h, copy) = (index(&twin, "h1_1"), index(&twin, "h1_1_twin"));
    // The null space is the difference of the two copies: exactly those rows are named.
    assert!(
        double.diagnostics.iter().any(|d| matches!(d, Diagnostic::RedundantSparse { constraints, size, .. }
            if *constraints == [h, copy] && *size == twin.system.constraints.len())),
        "{:?}",
        double.diagnostics
    );
    let largest = single.lambda.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let half = single.lambda[index(&plain, "h1_1")] / 2.0;
    for k in [h, copy] {
        let gap = (double.lambda[k] - half).abs() / largest;
        assert!(
            gap < 1e-9,
            "λ of {} is {:e}, half the single row's is {half:e}",
            twin.system.constraints[k].name,
            double.lambda[k]
        );
    }
    let others = (0..plain.system.constraints.len()).filter(|&k| k != h);
    let gap = others.map(|k| (double.lambda[k] - single.lambda[k]).abs()).fold(0.0f64, f64::max) / largest;
    assert!(gap < 1e-11, "the other rows' λ moved by {gap:e} of the largest");
    // The forces are the grid's: the copies' λ add up to the single row's.
    for (a, b) in double.acceleration.iter().zip(&single.acceleration) {
        for c in 0..3 {
            // Relative to g = 10 m/s².
            assert!((a[c] - b[c]).abs() <= 1e-9 * 10.0, "accelerations differ: {a:?} against {b:?}");
        }
    }
}

#[test]
fn the_grid_with_a_twin_row_simulates_with_its_joints_exact() {
    let twin = grid_with_twin("1.0");
    let steps = 3;
    let exact = {
        let mut settings = twin.settings();
        settings.steps = steps;
        twin.simulate(settings, &mut |_| Ok(())).expect("runs")
    };
    let velocity = {
        let mut settings = VelocitySettings::new(Solver::Exact, 1.0 / 60.0, steps as f64 / 60.0);
        settings.steps = steps;
        twin.simulate_velocity(settings, &mut |_| Ok(())).expect("runs")
    };
    for (name, summary) in [("exact", &exact), ("exact-velocity", &velocity)] {
        let Summary { steps: done, max_abs_c, .. } = summary;
        assert_eq!(*done, steps, "{name}");
        // Joints 1 m long: exact to 1e-9 of a link (free fall would open them by 1e-2).
        assert!(*max_abs_c < 1e-9, "{name}: max |C| = {max_abs_c:e}");
    }
}

#[test]
fn contradicting_rows_past_the_dense_limit_stop_the_run_with_an_error() {
    // The copy asks for 1.5 m where the original asks for 1 m. At rest the two agree on the
    // acceleration (the same gradient, the same C̈ = 0): the first solve is the minimum norm.
    // Onto C = 0 they contradict each other, which only a dense least squares could answer.
    let clash = grid_with_twin("1.5");
    assert_eq!(solve_at_start(&clash).status, Status::MinimumNorm);
    let mut settings = clash.settings();
    settings.steps = 3;
    let failure = clash.simulate(settings, &mut |_| Ok(())).expect_err("stops");
    assert!(
        matches!(failure.error, SimError::TooLarge { rows, .. } if rows == clash.system.constraints.len()),
        "{}",
        failure.error
    );
    let mut settings = VelocitySettings::new(Solver::Exact, 1.0 / 60.0, 0.05);
    settings.steps = 3;
    let failure = clash.simulate_velocity(settings, &mut |_| Ok(())).expect_err("stops");
    assert!(matches!(failure.error, SimError::TooLarge { .. }), "{}", failure.error);
}

/// Runs the command line on the grid with a twin of `length` written to a temporary file:
/// exit code, stdout and stderr.
fn cli(length: &str, args: &[&str]) -> (Option<i32>, String, String) {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lagrange-twin-{length}-{}.toml", std::process::id()));
    std::fs::write(&path, twin_text(length)).expect("writes the file");
    let file = path.to_str().expect("utf-8");
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).args(args).arg(file).output().expect("runs");
    let _ = std::fs::remove_file(&path);
    (out.status.code(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

#[test]
fn the_command_line_names_the_redundant_rows_and_stops_on_the_contradicting_ones() {
    let (code, stdout, stderr) = cli("1.0", &["solve"]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    assert!(stdout.contains("minimum-norm"), "{stdout}");
    let line = stdout.lines().find(|l| l.contains("sparse solves")).unwrap_or_default();
    assert!(line.contains("`h1_1`") && line.contains("`h1_1_twin`") && line.contains("1712 rows"), "{stdout}");
    let (code, stdout, stderr) = cli("1.5", &["simulate", "--steps", "3"]);
    assert_eq!(code, Some(2), "a simulation that stopped: {stdout}{stderr}");
    assert!(stderr.contains("1712 coupled rows could not be solved"), "{stderr}");
}
