//! Simulation: drift and energy of the pendulum, determinism, the integrators' orders.

mod common;

use common::{run, run_observed, scenario, settings};
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::stabilize::Stabilize;
use lagrange::report::csv::CsvWriter;
use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};

#[test]
fn pendulum_verlet_projection_1e5_steps_keeps_drift_and_energy() {
    let s = run("constraints/pendulum.toml", Some(100_000)).expect("runs");
    assert_eq!(s.steps, 100_000);
    assert!(s.max_abs_c <= 1e-9, "max |C| = {}", s.max_abs_c);
    assert!(s.max_abs_c_dot <= 1e-9, "max |Ċ| = {}", s.max_abs_c_dot);
    assert!(s.energy_rel_drift.expect("time-independent") <= 1e-3, "energy {:?}", s.energy_rel_drift);
}

/// The CSV bytes and final state of one run.
fn csv_of(path: &str, integrator: Integrator, stabilize: Stabilize) -> (Vec<u8>, Vec<[f64; 3]>) {
    let s = scenario(path);
    let settings = settings(&s, integrator, stabilize, 1e-3, 1000);
    let mut writer = CsvWriter::new(&s.system, Vec::new(), 7, 1000).expect("header");
    let summary = s.simulate(settings, &mut |f| writer.frame(f).map_err(|e| e.to_string())).expect("runs");
    let mut out = summary.final_position;
    out.extend(summary.final_velocity);
    (writer.into_inner(), out)
}

fn hash(bytes: &[u8]) -> u64 {
    let mut h = DefaultHasher::new();
    bytes.hash(&mut h);
    h.finish()
}

#[test]
fn same_file_and_options_give_bit_identical_runs() {
    for (path, integrator, stabilize) in [
        ("constraints/chain_5.toml", Integrator::Rk4, Stabilize::PROJECTION),
        ("constraints/chain_5.toml", Integrator::Verlet, Stabilize::PROJECTION),
        ("constraints/double_pendulum.toml", Integrator::Euler, Stabilize::BAUMGARTE),
        ("constraints/hard/rope.toml", Integrator::Verlet, Stabilize::PROJECTION),
    ] {
        let (a, qa) = csv_of(path, integrator, stabilize);
        let (b, qb) = csv_of(path, integrator, stabilize);
        assert_eq!(hash(&a), hash(&b), "{path}");
        assert_eq!(a, b);
        let bits = |q: &[[f64; 3]]| q.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&qa), bits(&qb));
        assert!(a.len() > 1000);
    }
}

/// The pendulum's final position error after 1 s at step `dt` against a fine RK4 run.
fn error_at(integrator: Integrator, dt: f64, reference: &[f64; 3]) -> f64 {
    let steps = (1.0 / dt).round() as u64;
    let s = run_observed(
        "constraints/pendulum.toml",
        integrator,
        Stabilize::PROJECTION,
        Some(dt),
        Some(steps),
        &mut |_| {},
    )
    .expect("runs");
    let q = s.final_position[0];
    ((q[0] - reference[0]).powi(2) + (q[1] - reference[1]).powi(2)).sqrt()
}

#[test]
fn integrators_converge_at_their_orders() {
    let reference = run_observed(
        "constraints/pendulum.toml",
        Integrator::Rk4,
        Stabilize::PROJECTION,
        Some(1e-4),
        Some(10_000),
        &mut |_| {},
    )
    .expect("runs")
    .final_position[0];
    for (integrator, order) in [(Integrator::Euler, 1.0), (Integrator::Verlet, 2.0), (Integrator::Rk4, 4.0)] {
        let (e1, e2) = (error_at(integrator, 0.01, &reference), error_at(integrator, 0.005, &reference));
        let observed = (e1 / e2).log2();
        assert!((observed - order).abs() <= 0.5, "{integrator:?}: order {observed} ({e1:e}, {e2:e})");
    }
}

#[test]
fn baumgarte_keeps_drift_small_and_none_lets_it_grow() {
    let path = "constraints/double_pendulum.toml";
    let go = |stabilize| {
        run_observed(path, Integrator::Euler, stabilize, Some(2e-3), Some(2000), &mut |_| {}).expect("runs").max_abs_c
    };
    let (none, baumgarte) = (go(Stabilize::None), go(Stabilize::BAUMGARTE));
    assert!(baumgarte < none / 10.0, "baumgarte {baumgarte:e}, none {none:e}");
}

#[test]
fn energy_balance_counts_the_work_of_velocity_dependent_forces() {
    // Drag takes most of the energy out, yet ΔT − W stays at the integrator's error.
    let s = run("constraints/damped_pendulum.toml", None).expect("runs");
    let v = s.final_velocity[0];
    assert!(0.5 * (v[0] * v[0] + v[1] * v[1]) < 0.5 * s.max_kinetic, "drag took energy out");
    assert!(s.energy_rel_drift.expect("reported") <= 1e-4, "{:?}", s.energy_rel_drift);
    assert!(s.max_abs_c <= 1e-9);
}

#[test]
fn time_dependent_constraints_keep_drift_small_and_do_not_report_energy() {
    for integrator in Integrator::ALL {
        let s = run_observed(
            "constraints/driven_pendulum.toml",
            integrator,
            Stabilize::PROJECTION,
            None,
            None,
            &mut |_| {},
        )
        .expect("runs");
        assert_eq!(s.energy_rel_drift, None);
        assert!(s.max_abs_c <= 1e-9 && s.max_abs_c_dot <= 1e-9, "{integrator:?}: {} {}", s.max_abs_c, s.max_abs_c_dot);
    }
}

#[test]
fn energy_balance_resolves_rk4s_fourth_order() {
    // The work integral carries an Euler–Maclaurin end correction, so the balance falls
    // as dt⁴ with RK4 instead of stalling at the trapezoid's dt².
    let energy = |dt: f64| {
        let steps = (2.0 / dt).round() as u64;
        run_observed(
            "constraints/pendulum.toml",
            Integrator::Rk4,
            Stabilize::PROJECTION,
            Some(dt),
            Some(steps),
            &mut |_| {},
        )
        .expect("runs")
        .energy_rel_drift
        .expect("reported")
    };
    let (coarse, fine) = (energy(4e-3), energy(2e-3));
    assert!(coarse / fine > 10.0, "{coarse:e} → {fine:e}");
}

#[test]
fn compiled_rows_agree_with_the_interpreter_on_every_file() {
    // The simulation's rows come from the compiled tape; the interpreter is the reference
    // semantics. They may round differently (x·y⁻¹ is lowered to x/y), never by more than a
    // few ulps: relative 1e-12 at 20 random states of every file with a scene.
    let mut files: Vec<_> = ["constraints", "constraints/hard"]
        .iter()
        .flat_map(|d| std::fs::read_dir(d).expect("dir").map(|e| e.expect("entry").path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    let mut checked = 0;
    for path in files {
        let text = std::fs::read_to_string(&path).expect("file");
        let Ok(loaded) = lagrange::model::file::load(&text) else { continue };
        let Ok(s) = lagrange::scenario::Scenario::new(loaded, &[]) else { continue };
        let mut rng = common::Rng::new(7);
        for _ in 0..20 {
            let env = common::random_env(&s.system, &mut rng);
            let compiled = s.program.evaluate(&s.system, &env).expect("rows");
            let reference = s.program.evaluate_interpreted(&s.system, &s.derivation, &env).expect("rows");
            let close =
                |a: f64, b: f64| a == b || (a - b).abs() <= 1e-12 * a.abs().max(b.abs()) || (a.is_nan() && b.is_nan());
            let close3 = |a: &[f64; 3], b: &[f64; 3]| (0..3).all(|d| close(a[d], b[d]));
            let at = path.display();
            assert!(compiled.inverse_mass.iter().zip(&reference.inverse_mass).all(|(a, b)| close(*a, *b)), "{at}");
            assert!(compiled.force.iter().zip(&reference.force).all(|(a, b)| close3(a, b)), "{at}: forces");
            assert!(compiled.velocity.iter().zip(&reference.velocity).all(|(a, b)| close3(a, b)), "{at}");
            for (a, b) in compiled.rows.iter().zip(&reference.rows) {
                let ok = close(a.value, b.value)
                    && close(a.rate, b.rate)
                    && close(a.bias, b.bias)
                    && a.inequality == b.inequality
                    && a.jacobian.iter().zip(&b.jacobian).all(|((p, x), (q, y))| p == q && close3(x, y));
                assert!(ok, "{at}: {a:?} vs {b:?}");
            }
        }
        checked += 1;
    }
    assert!(checked >= 20, "only {checked} files checked");
}

#[test]
fn bad_settings_are_refused_by_cause_before_any_step() {
    use lagrange::numeric::simulate::{Settings, SettingsError};
    use lagrange::numeric::stabilize::StabilizeError;
    let good = Settings::new(1e-3, 1.0);
    assert_eq!(good.validate(), Ok(()));
    let refused = |change: fn(&mut Settings)| {
        let mut s = good;
        change(&mut s);
        s.validate().expect_err("refused")
    };
    assert_eq!(refused(|s| s.dt = -1.0), SettingsError::Step(-1.0));
    assert_eq!(refused(|s| s.restitution = 1.5), SettingsError::Restitution(1.5));
    assert_eq!(refused(|s| s.blowup = 0.0), SettingsError::Blowup(0.0));
    assert_eq!(
        refused(|s| s.stabilize = Stabilize::Baumgarte { zeta: -1.0, omega_dt: 0.1 }),
        SettingsError::Stabilize(StabilizeError::Damping(-1.0))
    );
    assert_eq!(
        refused(|s| s.stabilize = Stabilize::Baumgarte { zeta: 1.0, omega_dt: 2.0 }),
        SettingsError::Stabilize(StabilizeError::Frequency(2.0))
    );
    assert_eq!(
        refused(|s| s.stabilize = Stabilize::Projection { tolerance: 0.0, max_iterations: 20 }),
        SettingsError::Stabilize(StabilizeError::Tolerance(0.0))
    );
    assert_eq!(
        refused(|s| s.stabilize = Stabilize::Projection { tolerance: 1e-13, max_iterations: 0 }),
        SettingsError::Stabilize(StabilizeError::NoIterations)
    );
}
