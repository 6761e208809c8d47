//! The hard cases of `constraints/hard/`: each file states an expectation, checked here.

mod common;

use common::{run, run_observed, scenario};
use lagrange::numeric::dynamics::SimError;
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::solve::{Diagnostic, solve};
use lagrange::numeric::stabilize::Stabilize;
use lagrange::numeric::velocity::{Settings, Solver};

/// Runs `path` for `steps` Verlet + projection steps: the summary and the largest |energy
/// error| in the first and in the last tenth of the run.
fn verlet_energy_tenths(path: &str, steps: u64) -> (lagrange::numeric::simulate::Summary, f64, f64) {
    let (mut early, mut late) = (0.0f64, 0.0f64);
    let s = run_observed(path, Integrator::Verlet, Stabilize::PROJECTION, None, Some(steps), &mut |f| {
        if f.step < steps / 10 {
            early = early.max(f.energy_error.expect("a full run keeps its energy balance").abs());
        } else if f.step >= steps / 10 * 9 {
            late = late.max(f.energy_error.expect("a full run keeps its energy balance").abs());
        }
    })
    .expect("runs");
    (s, early, late)
}

fn finite(xs: &[[f64; 3]]) -> bool {
    xs.iter().flatten().all(|x| x.is_finite())
}

#[test]
fn bead_near_the_singular_centre_stops_with_a_diagnostic() {
    let path = "constraints/hard/bead_near_centre.toml";
    let s = scenario(path);
    // The solve near the centre is finite; at the centre it reports the singularity.
    let mut dynamics = lagrange::numeric::dynamics::Dynamics::new(&s.system, s.program.clone(), s.env.clone());
    for r in [[1e-12, 0.0, 0.0], [0.0, 0.0, 0.0]] {
        let rows = dynamics.rows(0.0, &[r], &[[0.0, 1.0, 0.0]]).expect("rows");
        let solution = solve(&rows);
        assert!(solution.lambda.iter().all(|l| l.is_finite()), "{:?}", solution.lambda);
        assert!(finite(&solution.acceleration));
        if r[0] == 0.0 {
            assert_eq!(solution.lambda, vec![0.0]);
            assert!(
                solution.diagnostics.iter().any(|d| matches!(d, Diagnostic::ZeroGradient { constraint: 0, .. })),
                "{:?}",
                solution.diagnostics
            );
        }
    }
    // The run cannot reach the wire along a vanishing gradient: it stops before its first
    // step, naming `wire` and the initial state (not the step size) as the cause.
    let failure = run(path, None).expect_err("must stop");
    match &failure.error {
        SimError::FarStart { constraint, .. } => assert_eq!(constraint, "wire"),
        other => panic!("unexpected error {other}"),
    }
    let message = failure.error.to_string();
    assert!(message.contains("initial state") && !message.contains("--dt"), "{message}");
    // So do the velocity-level solvers, rather than blame their substeps or stiffness.
    for solver in Solver::ALL {
        let failure = s.simulate_velocity(Settings::new(solver, 1e-3, 0.01), &mut |_| Ok(())).expect_err("must stop");
        assert!(matches!(&failure.error, SimError::FarStart { constraint, .. } if constraint == "wire"), "{solver:?}");
    }
    assert!(finite(&failure.summary.final_position) && finite(&failure.summary.final_velocity));
}

#[test]
fn redundant_rod_gives_the_single_rod_motion() {
    let s = scenario("constraints/hard/redundant.toml");
    let mut dynamics = lagrange::numeric::dynamics::Dynamics::new(&s.system, s.program.clone(), s.env.clone());
    let rows = dynamics.rows(0.0, &[[0.6, -0.8, 0.0]], &[[0.8, 0.6, 0.0]]).expect("rows");
    let solution = solve(&rows);
    assert!(
        solution.diagnostics.iter().any(|d| matches!(d, Diagnostic::Redundant { .. })),
        "{:?}",
        solution.diagnostics
    );
    let twice = run("constraints/hard/redundant.toml", None).expect("runs");
    let once = run("constraints/pendulum.toml", Some(twice.steps)).expect("runs");
    assert!(twice.max_abs_c <= 1e-9, "{}", twice.max_abs_c);
    for (a, b) in twice.final_position.iter().zip(&once.final_position) {
        for d in 0..2 {
            assert!((a[d] - b[d]).abs() <= 1e-9, "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn mass_ratio_1e9_chain_keeps_its_links() {
    let s = run("constraints/hard/mass_ratio.toml", None).expect("runs");
    assert_eq!(s.steps, 2000);
    assert!(s.max_abs_c <= 1e-9, "{}", s.max_abs_c);
    assert!(s.energy_rel_drift.expect("reported") <= 1e-3, "{:?}", s.energy_rel_drift);
    assert!(finite(&s.final_position) && finite(&s.final_velocity));
}

#[test]
fn stiff_mass_ratio_chain_stops_with_a_diagnostic() {
    let failure = run("constraints/hard/mass_ratio_stiff.toml", None).expect_err("too stiff for explicit steps");
    match &failure.error {
        SimError::Drift { step, constraint, .. } => {
            assert!(constraint.starts_with("link"), "{constraint}");
            assert!(*step > 0 && *step < 2000, "{step}");
        }
        SimError::NonFiniteRow { constraint, .. } => assert!(constraint.starts_with("link")),
        other => panic!("unexpected error {other}"),
    }
    assert!(finite(&failure.summary.final_position) && finite(&failure.summary.final_velocity));
}

/// The pendulum of `constraints/pendulum.toml` with every length scaled by `l` (a file of
/// `constraints/hard/`) must be the unit pendulum's run, scaled: the run works in a length
/// unit near l (a power of two, so converting back is exact) and reports in the scene's.
fn is_the_unit_pendulum_scaled(path: &str, l: f64) {
    let s = run(path, None).expect("runs: the lengths are rescaled, not overflowing");
    assert_eq!(s.steps, 1000);
    assert_ne!(s.unit_exponent, 0, "ran in a unit near l");
    let unit = run("constraints/pendulum.toml", Some(s.steps)).expect("runs");
    assert_eq!(unit.unit_exponent, 0);
    // Drift: C/κ = (r·r − l²)/2 has degree 2, so |C|/l² is the relative drift; the bound of
    // the unit pendulum (1e-9), and the unit run's own figure to 1 % or to a few roundings
    // of l² (SHAKE's predicted positions leave |C|/l² at some 50 of them, where the two
    // runs' roundings, l not being a power of two, differ by one or two).
    let relative = s.max_abs_c / l / l;
    assert!(relative <= 1e-9, "|C|/l² = {relative:e}");
    let near = 1e-2 * unit.max_abs_c + 4.0 * f64::EPSILON;
    assert!((relative - unit.max_abs_c).abs() <= near, "{relative:e} vs {:e}", unit.max_abs_c);
    // Energy: the balance relative to the largest kinetic energy is unit-free.
    let (e, e_unit) = (s.energy_rel_drift.expect("reported"), unit.energy_rel_drift.expect("reported"));
    assert!(e <= 1e-5, "{e:e}");
    assert!((e - e_unit).abs() <= 1e-6 * e_unit, "{e:e} vs {e_unit:e}");
    // The state: r/l and v/l are the unit pendulum's (to rounding: l is not a power of two).
    for (x, u) in s.final_position[0]
        .iter()
        .chain(&s.final_velocity[0])
        .zip(unit.final_position[0].iter().chain(&unit.final_velocity[0]))
    {
        let scaled = x / l;
        assert!((scaled - u).abs() <= 1e-9, "{scaled} vs {u}");
    }
    assert!(finite(&s.final_position) && finite(&s.final_velocity));
}

#[test]
fn huge_pendulum_is_the_unit_pendulum_scaled() {
    // |r| ≈ 1e155: in metres r·r = 1e310 overflows f64 (C = ∞ − ∞), so the run works in a
    // unit of 2^518 m; the kinetic energy itself (≈ 1e311) is outside f64, its ratio is not.
    is_the_unit_pendulum_scaled("constraints/hard/huge.toml", 1e155);
}

#[test]
fn tiny_pendulum_is_the_unit_pendulum_scaled() {
    // |r| ≈ 1e-150: r·r = 1e-300 is still normal, but C's drift (1e-313) would be subnormal.
    is_the_unit_pendulum_scaled("constraints/hard/tiny.toml", 1e-150);
}

#[test]
fn bead_at_speed_1e8_keeps_the_wire_and_its_speed() {
    let s = run("constraints/hard/fast.toml", None).expect("runs");
    assert_eq!(s.steps, 10_000);
    assert!(s.max_abs_c <= 1e-9, "{}", s.max_abs_c);
    let v = s.final_velocity[0];
    let speed = (v[0] * v[0] + v[1] * v[1]).sqrt();
    // Projection methods are not exactly energy-preserving: the speed error is O((ω dt)²) = 1e-4.
    assert!((speed - 1e8).abs() <= 1e-4 * 1e8, "speed {speed}");
}

#[test]
fn chain_of_100_links_keeps_bounded_drift_for_1e5_steps() {
    if common::skip_slow("chain_of_100_links_keeps_bounded_drift_for_1e5_steps") {
        return;
    }
    // 1e5 steps (100 s, 20 times the scene's 5 s; 2 000 in debug builds): with the compiled
    // tape and the band solve a step costs O(N), ~0.2 ms here. Measured in release:
    // max |C| 3.5e-12, max |Ċ| 1.1e-14, energy balance 6.2e-3 of the largest kinetic energy.
    let steps: u64 = if cfg!(debug_assertions) { 2_000 } else { 100_000 };
    let (s, early, late) = verlet_energy_tenths("constraints/hard/chain_100.toml", steps);
    assert_eq!(s.steps, steps);
    // Drift: every link within 1e-9 (C/κ = (|rᵢ − rᵢ₋₁|² − l²)/2, l = 0.5) at every step.
    assert!(s.max_abs_c <= 1e-9, "{}", s.max_abs_c);
    assert!(s.max_abs_c_dot <= 1e-9, "{}", s.max_abs_c_dot);
    // Energy: RATTLE's error stays bounded — no larger in the last tenth than in the first.
    assert!(s.energy_rel_drift.expect("reported") <= 2e-2, "{:?}", s.energy_rel_drift);
    // Measured: max |E| 1.5e2 in the first tenth, 3.6e1 in the last.
    assert!(late <= 2.0 * early, "early {early:e}, late {late:e}");
    assert!(finite(&s.final_position) && finite(&s.final_velocity));
}

#[test]
fn rope_switches_between_slack_and_taut() {
    let (mut slack, mut taut, mut switches, mut was_taut) = (0, 0, 0, None);
    let mut worst_c = 0.0f64;
    let mut worst_lambda = 0.0f64;
    let s =
        run_observed("constraints/hard/rope.toml", Integrator::Verlet, Stabilize::PROJECTION, None, None, &mut |f| {
            let row = &f.rows.rows[0];
            let is_taut = f.lambda[0] > 0.0;
            if is_taut {
                taut += 1;
            } else if row.value > 1e-9 {
                slack += 1;
            }
            if was_taut.is_some_and(|w| w != is_taut) {
                switches += 1;
            }
            was_taut = Some(is_taut);
            worst_c = worst_c.min(row.value);
            worst_lambda = worst_lambda.min(f.lambda[0]);
        })
        .expect("runs");
    assert_eq!(s.steps, 4000);
    assert!(slack > 100 && taut > 100, "slack {slack}, taut {taut}");
    assert!(switches >= 2, "{switches} switches");
    assert!(worst_c >= -1e-9, "stretched to {worst_c}");
    assert!(worst_lambda >= 0.0, "pushed with λ = {worst_lambda}");
}

#[test]
fn box_rests_on_the_floor_without_jitter_or_sinking() {
    let mut worst = 0.0f64;
    let mut lambda = Vec::new();
    let s =
        run_observed("constraints/hard/floor.toml", Integrator::Verlet, Stabilize::PROJECTION, None, None, &mut |f| {
            let (q, v) = (f.position[0], f.velocity[0]);
            worst = worst.max(q[1].abs()).max(v[0].abs()).max(v[1].abs());
            lambda.push(f.lambda[0]);
        })
        .expect("runs");
    assert_eq!(s.steps, 10_000);
    assert!(worst <= 1e-12, "moved by {worst}");
    // The floor carries the weight m g = 2 × 9.81 (J = ∇(r.y) = [0, 1], so λ is the force).
    assert!(lambda.iter().all(|l| (l - 2.0 * 9.81).abs() <= 1e-9), "{:?}", &lambda[..3]);
}

#[test]
fn ball_bounces_with_restitution() {
    let (mut lowest, mut landed, mut apex_after) = (f64::INFINITY, false, 0.0f64);
    let mut landing_speed = 0.0f64;
    let mut leaving_speed = 0.0f64;
    run_observed("constraints/hard/bounce.toml", Integrator::Verlet, Stabilize::PROJECTION, None, None, &mut |f| {
        let (y, vy) = (f.position[0][1], f.velocity[0][1]);
        lowest = lowest.min(y);
        if !landed && vy < 0.0 {
            landing_speed = -vy;
        }
        if !landed && vy > 0.0 {
            landed = true;
            leaving_speed = vy;
        }
        if landed {
            apex_after = apex_after.max(y);
        }
    })
    .expect("runs");
    assert!(landed);
    assert!(lowest >= -1e-12, "sank to {lowest}");
    assert!((leaving_speed / landing_speed - 0.5).abs() <= 2e-2, "{leaving_speed} / {landing_speed}");
    assert!((apex_after - 0.25).abs() <= 1e-2, "apex {apex_after}");
}

#[test]
fn pendulum_1e6_verlet_steps_have_bounded_energy_error() {
    if common::skip_slow("pendulum_1e6_verlet_steps_have_bounded_energy_error") {
        return;
    }
    // A million steps (1 000 s, ~450 periods; 1e5 in debug builds): RATTLE keeps the energy
    // error bounded — the same size in the last tenth as in the first.
    let steps: u64 = if cfg!(debug_assertions) { 100_000 } else { 1_000_000 };
    let (s, early, late) = verlet_energy_tenths("constraints/pendulum.toml", steps);
    assert!(s.energy_rel_drift.expect("reported") <= 1e-3, "{:?}", s.energy_rel_drift);
    assert!(late <= 2.0 * early + 1e-12, "early {early:e}, late {late:e}");
    assert!(s.max_abs_c <= 1e-9);
}
