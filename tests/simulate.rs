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
    let mut checked = 0;
    for (path, s) in common::scenarios(&["constraints", "constraints/hard"]) {
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

// Resting contacts: an inequality that pushes moves as its equality twin does.

/// A 2D ball (mass 1, gravity 9.81) inside a bowl `dot(r,r) <= R^2` of radius 0.5, starting
/// at the bottom at speed 5: fast enough to loop (at the top m v²/R − m g = 0.95 > 0), so the
/// bowl pushes all the way round. `relation` is `<=` (the bowl) or `=` (its equality twin,
/// a bead on a circle).
fn bowl(relation: &str) -> lagrange::scenario::Scenario {
    let text = format!(
        r#"
title = "Ball pressed into a bowl"
dimension = 2
[parameters]
R = 0.5
m = 1.0
g = [0.0, -9.81]
[[bodies]]
name = "ball"
position = "r"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"
[[constraints]]
name = "bowl"
expr = "dot(r, r) {relation} R^2"
[scene]
initial = {{ r = [0.0, -0.5], v = [5.0, 0.0] }}
forces = {{ F = "m*g" }}
"#
    );
    lagrange::scenario::Scenario::new(lagrange::model::file::load(&text).expect("valid"), &[]).expect("derives")
}

/// `rope_pendulum.toml` and its twin with the rope a rod (`<=` → `=`).
fn rope_and_rod() -> (lagrange::scenario::Scenario, lagrange::scenario::Scenario) {
    let text = std::fs::read_to_string("constraints/rope_pendulum.toml").expect("file");
    let rod = text.replace("dot(r, r) <= l^2", "dot(r, r) = l^2");
    assert_ne!(rod, text, "the rope's constraint is where the test expects it");
    let go = |t: &str| {
        lagrange::scenario::Scenario::new(lagrange::model::file::load(t).expect("valid"), &[]).expect("derives")
    };
    (go(&text), go(&rod))
}

/// Runs `s` and returns the summary with the number of frames whose λ is not positive.
fn run_counting_slack(
    s: &lagrange::scenario::Scenario,
    integrator: Integrator,
    dt: f64,
    steps: u64,
) -> (lagrange::numeric::simulate::Summary, usize) {
    let mut slack = 0;
    let summary = s
        .simulate(settings(s, integrator, Stabilize::PROJECTION, dt, steps), &mut |f| {
            slack += usize::from(f.lambda[0] <= 0.0);
            Ok(())
        })
        .expect("runs");
    (summary, slack)
}

#[test]
fn a_taut_rope_holds_like_a_rod() {
    // Before the contacts were held between steps: energy error 1.67e-3 against the rod's
    // 4.1e-7, λ = 0 on 668 of 10 001 rows while the bob stayed taut.
    let (rope, rod) = rope_and_rod();
    for integrator in Integrator::ALL {
        let (a, slack) = run_counting_slack(&rope, integrator, 1e-3, 10_000);
        let (b, _) = run_counting_slack(&rod, integrator, 1e-3, 10_000);
        let (ea, eb) = (a.energy_rel_drift.expect("reported"), b.energy_rel_drift.expect("reported"));
        assert_eq!(slack, 0, "{integrator:?}: λ = 0 on {slack} rows of a taut rope");
        assert!(ea <= 2.0 * eb, "{integrator:?}: energy error {ea:e} against the rod's {eb:e}");
        let apart = (0..2).map(|d| (a.final_position[0][d] - b.final_position[0][d]).abs()).fold(0.0, f64::max);
        assert!(apart <= 1e-9, "{integrator:?}: the rope's bob ends {apart:e} from the rod's");
    }
}

#[test]
fn a_ball_pressed_into_a_bowl_moves_as_a_bead_on_a_circle() {
    // Before: energy error 2.1e-2 against 7.8e-7 for the equality (a bowl of radius 1).
    let (ball, bead) = (bowl("<="), bowl("="));
    for integrator in Integrator::ALL {
        let (a, slack) = run_counting_slack(&ball, integrator, 1e-3, 5000);
        let (b, _) = run_counting_slack(&bead, integrator, 1e-3, 5000);
        let (ea, eb) = (a.energy_rel_drift.expect("reported"), b.energy_rel_drift.expect("reported"));
        assert_eq!(slack, 0, "{integrator:?}: λ = 0 on {slack} rows of a pressed ball");
        assert!(ea <= 2.0 * eb, "{integrator:?}: energy error {ea:e} against the bead's {eb:e}");
        let apart = (0..2).map(|d| (a.final_position[0][d] - b.final_position[0][d]).abs()).fold(0.0, f64::max);
        assert!(apart <= 1e-9, "{integrator:?}: the ball ends {apart:e} from the bead");
    }
}

#[test]
fn rk4_keeps_its_fourth_order_with_a_pressed_contact() {
    // Before: second order only (the contact was dropped and caught again between stages).
    // Now the ball's error is the bead's, step size by step size, and falls at least as dt⁴.
    let error = |s: &lagrange::scenario::Scenario| {
        let at = |dt: f64| {
            let steps = (1.0 / dt).round() as u64;
            let run = s.simulate(settings(s, Integrator::Rk4, Stabilize::PROJECTION, dt, steps), &mut |_| Ok(()));
            run.expect("runs").final_position[0]
        };
        let reference = at(1e-4);
        [0.01, 0.005].map(|dt| {
            let q = at(dt);
            ((q[0] - reference[0]).powi(2) + (q[1] - reference[1]).powi(2)).sqrt()
        })
    };
    let ([e1, e2], [b1, b2]) = (error(&bowl("<=")), error(&bowl("=")));
    let observed = (e1 / e2).log2();
    assert!(observed >= 3.5, "RK4 order {observed} ({e1:e}, {e2:e})");
    assert!((e1 / b1 - 1.0).abs() <= 1e-3 && (e2 / b2 - 1.0).abs() <= 1e-3, "ball {e1:e} {e2:e}, bead {b1:e} {b2:e}");
}

#[test]
fn a_held_contact_is_released_when_it_would_pull() {
    // The bowl at speed 3 cannot loop: the ball leaves the wall where its λ would turn
    // negative (cos θ = −(v₀² − 2gR)/(3gR) from the bottom), flies, and lands again. Held
    // contacts must let it go: some frames slack, λ never negative, never through the wall.
    let text = std::fs::read_to_string("constraints/rope_pendulum.toml").expect("file");
    let fast = text.replace("v = [1.0, 0.0]", "v = [8.0, 0.0]");
    let s = lagrange::scenario::Scenario::new(lagrange::model::file::load(&fast).expect("valid"), &[]).expect("ok");
    let (mut slack, mut worst_lambda, mut outside) = (0, 0.0f64, 0.0f64);
    s.simulate(settings(&s, Integrator::Verlet, Stabilize::PROJECTION, 1e-3, 3000), &mut |f| {
        slack += usize::from(f.lambda[0] == 0.0);
        worst_lambda = worst_lambda.min(f.lambda[0]);
        let r = f.position[0];
        outside = outside.max((r[0] * r[0] + r[1] * r[1]).sqrt() - 2.0);
        Ok(())
    })
    .expect("runs");
    assert!(slack > 100, "the rope never went slack ({slack} frames)");
    assert!(worst_lambda >= 0.0, "the rope pushed: λ = {worst_lambda}");
    assert!(outside <= 1e-9, "the bob went {outside:e} past the rope's length");
}

/// The ball of `hard/bounce.toml` with restitution `e`: the ratio of its upward speed just
/// after its first bounce to its downward speed just before, per stabilisation.
fn bounce_ratio(e: f64, integrator: Integrator, stabilize: Stabilize) -> f64 {
    let text = std::fs::read_to_string("constraints/hard/bounce.toml").expect("file");
    let text = text.replace("restitution = 0.5", &format!("restitution = {e}"));
    let s =
        lagrange::scenario::Scenario::new(lagrange::model::file::load(&text).expect("valid"), &[]).expect("derives");
    let mut settings = settings(&s, integrator, stabilize, 1e-4, 6000);
    settings.restitution = e;
    let (mut before, mut after) = (0.0f64, None);
    s.simulate(settings, &mut |f| {
        let vy = f.velocity[0][1];
        if after.is_none() {
            if vy < 0.0 {
                before = before.min(vy);
            } else if before < 0.0 && vy > 0.0 {
                after = Some(vy);
            }
        }
        Ok(())
    })
    .expect("runs");
    after.expect("the ball bounced") / -before
}

#[test]
fn baumgarte_keeps_restitution() {
    // Before: e = 1 came back at 0.896 of its speed under Baumgarte (its rate term braked
    // the approach inside the step), 1.0 with projection or none.
    for integrator in Integrator::ALL {
        for stabilize in [Stabilize::None, Stabilize::BAUMGARTE, Stabilize::PROJECTION] {
            for e in [1.0, 0.5] {
                let ratio = bounce_ratio(e, integrator, stabilize);
                assert!((ratio - e).abs() <= 1e-3, "{integrator:?} + {stabilize:?}, e = {e}: came back at {ratio}");
            }
        }
    }
}

#[test]
fn a_steps_start_rows_are_the_rows_at_its_state() {
    // From the second step on, a run starts from the last step's end rows (C and J kept,
    // Ċ, c, 1/m, v and F evaluated again: `Dynamics::rows_moved`), not from a full
    // evaluation. What the observer is shown must be the rows at the recorded state
    // whatever path made them: relative 1e-12 (against 1) of a full evaluation there, for
    // RATTLE, RK4 and Euler with projection, a contact, a rope and a driven constraint,
    // 200 steps each (with Baumgarte the shown c holds its terms: not compared).
    use lagrange::numeric::rows::{Rows, State};
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0);
    for (path, integrator, stabilize) in [
        ("constraints/chain_5.toml", Integrator::Verlet, Stabilize::PROJECTION),
        ("constraints/double_pendulum.toml", Integrator::Rk4, Stabilize::PROJECTION),
        ("constraints/hard/bounce.toml", Integrator::Verlet, Stabilize::PROJECTION),
        ("constraints/rope_pendulum.toml", Integrator::Verlet, Stabilize::PROJECTION),
        ("constraints/driven_pendulum.toml", Integrator::Verlet, Stabilize::PROJECTION),
        ("constraints/chain_5.toml", Integrator::Euler, Stabilize::PROJECTION),
    ] {
        let s = scenario(path);
        let settings = settings(&s, integrator, stabilize, 1e-3, 200);
        let mut scratch = s.program.scratch();
        let mut full = Rows::default();
        let mut frames = 0;
        s.simulate(settings, &mut |f| {
            let state = State { t: f.time, q: f.position, v: f.velocity };
            s.program.evaluate_state_into(&s.system, &s.env, state, &mut scratch, &mut full).expect("rows");
            let (a, b) = (f.rows, &full);
            let numbers = |r: &Rows| {
                let rows = r.rows.iter().flat_map(|row| {
                    [row.value, row.rate, row.bias].into_iter().chain(row.jacobian.iter().flat_map(|(_, j)| *j))
                });
                let bodies = r.inverse_mass.iter().copied().chain(r.velocity.iter().chain(&r.force).flatten().copied());
                rows.chain(bodies).collect::<Vec<f64>>()
            };
            let (x, y) = (numbers(a), numbers(b));
            assert_eq!(x.len(), y.len(), "{path} step {}", f.step);
            assert!(x.iter().zip(&y).all(|(p, q)| close(*p, *q)), "{path} step {}: {a:?} vs {b:?}", f.step);
            let flags = |r: &Rows| r.rows.iter().map(|row| row.inequality).collect::<Vec<_>>();
            assert_eq!(flags(a), flags(b), "{path} step {}", f.step);
            frames += 1;
            Ok(())
        })
        .expect("runs");
        assert_eq!(frames, 201, "{path}");
    }
}

/// A number from a wide range of magnitudes and both signs, sometimes 0, ±∞ or NaN
/// (`special`), from 64 random bits.
fn wide(bits: u64, special: bool) -> f64 {
    let (sign, exponent, mantissa) = (bits & 1, (bits >> 1) % 700, (bits >> 11) as f64 / (1u64 << 53) as f64);
    let x = (1.0 + mantissa) * 2f64.powi(exponent as i32 - 350);
    let x = if sign == 1 { -x } else { x };
    match (bits >> 60) % 16 {
        0 => 0.0,
        1 if special => f64::INFINITY,
        2 if special => f64::NAN,
        3..=8 => (1.0 + mantissa) * if sign == 1 { -1.0 } else { 1.0 },
        _ => x,
    }
}

#[test]
fn one_row_on_one_body_is_solved_as_the_general_solve_solves_it() {
    // `numeric::single` (the pendulum's and the bead's solve, in closed form) must give the
    // numbers of the general solve bit for bit wherever it answers, and answer wherever the
    // general solve has nothing to report about rows of its shape: random rows over
    // magnitudes 2^±350 (the scaling's reciprocal and division ranges, overflowing and
    // zero gradients, zero and negative masses, infinite and NaN numbers), one to three
    // slots, the row on any of them.
    use lagrange::numeric::rows::{Row, Rows};
    use lagrange::numeric::single::{SingleScaling, correction_single, is_single, solve_single, solve_single_with};
    use lagrange::numeric::solve::{Settings, Solution, SolveCache, solve_cached, solve_holding};
    let mut rng = common::Rng::new(16);
    // A scaling kept across every case, as a simulation keeps it: reused where J and 1/m
    // repeat bit for bit, the answer must be the fresh one's.
    let mut kept = SingleScaling::default();
    let settings = Settings::default();
    let bits = |s: &Solution| {
        let forces = s.acceleration.iter().chain(&s.constraint_force).flatten();
        s.lambda.iter().chain(forces).map(|x| x.to_bits()).collect::<Vec<_>>()
    };
    // Every field, numbers by their bits (a NaN equals itself).
    let whole = |s: &Solution| {
        let sizes = [s.lambda.len(), s.constraint_force.len(), s.acceleration.len()];
        (bits(s), sizes, s.active.clone(), s.status, s.contacts.clone(), s.diagnostics.clone())
    };
    // One output kept across every case, as `Dynamics` keeps its solutions: it holds the
    // case before's answer, or a general solve's of other shapes with its diagnostics, and
    // the one-row solve writes over it in place where the shape allows.
    let mut reused = Solution::default();
    let (mut taken, mut declined) = (0, 0);
    for case in 0..20_000 {
        let special = case % 4 == 0;
        let slots = 1 + (rng.next_u64() % 3) as usize;
        let body = (rng.next_u64() % slots as u64) as usize;
        let two_d = case % 2 == 0;
        let mut numbers = (0..4 + 7 * slots).map(|_| wide(rng.next_u64(), special));
        let mut next = || numbers.next().unwrap_or(0.0);
        let (value, rate, bias) = (next(), next(), next());
        // Masses ≥ 0 mostly, a negative one now and then.
        let inverse_mass = (0..slots).map(|_| if special { next() } else { next().abs() }).collect();
        let mut vector = || [next(), next(), if two_d { 0.0 } else { next() }];
        let jacobian = vec![(body, vector())];
        let row = Row { value, rate, bias, inequality: false, jacobian };
        let velocity = (0..slots).map(|_| vector()).collect();
        let force = (0..slots).map(|_| vector()).collect();
        let rows =
            Rows { dim: if two_d { 2 } else { 3 }, inverse_mass, velocity, force, rows: vec![row], axes: vec![] };
        assert!(is_single(&rows));
        let general = solve_holding(&rows, &settings, &[]);
        let cached = solve_cached(&rows, &settings, &[], &mut SolveCache::default());
        let mut single = Solution::default();
        let answered = solve_single(&rows, &settings, &mut single);
        let before = whole(&reused);
        assert_eq!(solve_single(&rows, &settings, &mut reused), answered, "case {case}");
        if answered {
            assert_eq!(whole(&reused), whole(&single), "case {case}: an answer over another");
        } else {
            assert_eq!(whole(&reused), before, "case {case}: a declined solve leaves its output");
            reused = general.clone();
        }
        // The same rows with the scaling kept from the case before (a miss), then again (a
        // hit), then with new forces and bias at the same J and masses (a hit).
        for _ in 0..2 {
            let mut with = Solution::default();
            assert_eq!(solve_single_with(&rows, &settings, &mut kept, &mut with), answered, "case {case}");
            assert_eq!((bits(&with), with.status), (bits(&single), single.status), "case {case}");
        }
        // A correction in closed form (`correction_single`, one slot only): the acceleration
        // of the same rows with the forces zeroed and the row an equality, whatever its flag.
        let mut corrected = rows.clone();
        corrected.force.iter_mut().for_each(|f| *f = [0.0; 3]);
        let mut zeroed = Solution::default();
        let want = solve_single(&corrected, &settings, &mut zeroed).then(|| zeroed.acceleration[0].map(f64::to_bits));
        let mut flagged = rows.clone();
        flagged.rows[0].inequality = case % 3 == 0;
        let got = correction_single(&flagged, rows.rows[0].bias, &mut kept).map(|a| a.map(f64::to_bits));
        assert_eq!(got, if slots == 1 { want } else { None }, "case {case}: {rows:?}");
        let mut moved = rows.clone();
        moved.rows[0].bias = wide(rng.next_u64(), special);
        moved.force[body] = [wide(rng.next_u64(), special), wide(rng.next_u64(), special), 0.0];
        let (mut fresh, mut with) = (Solution::default(), Solution::default());
        let fresh_answered = solve_single(&moved, &settings, &mut fresh);
        assert_eq!(solve_single_with(&moved, &settings, &mut kept, &mut with), fresh_answered, "case {case}");
        assert_eq!(bits(&with), bits(&fresh), "case {case}");
        if answered {
            taken += 1;
            assert_eq!(bits(&single), bits(&general), "case {case}: {rows:?}");
            assert_eq!(bits(&single), bits(&cached), "case {case}: {rows:?}");
            let rest = |s: &Solution| (s.active.clone(), s.status, s.contacts.clone(), s.diagnostics.clone());
            assert_eq!(rest(&single), rest(&general), "case {case}: {rows:?}");
            assert!(general.diagnostics.is_empty(), "case {case}: {:?}", general.diagnostics);
        } else {
            declined += 1;
            assert_eq!(single, Solution::default(), "case {case}: a declined solve leaves its output");
            let finite = |x: &[f64; 3]| x.iter().all(|c| c.is_finite());
            let all_finite = rows.velocity.iter().chain(&rows.force).all(finite)
                && rows.inverse_mass.iter().all(|w| w.is_finite())
                && rows.rows[0].bias.is_finite();
            assert!(!general.diagnostics.is_empty() || !all_finite, "case {case} declined: {rows:?}");
        }
    }
    assert!(taken > 5_000 && declined > 1_000, "taken {taken}, declined {declined}");
}

#[test]
fn other_shapes_go_to_the_general_solve() {
    // Two rows, a row on two slots, an inequality, a dense or sparse method: not the
    // closed form's to answer.
    use lagrange::numeric::rows::{Row, Rows};
    use lagrange::numeric::single::{is_single, solve_single};
    use lagrange::numeric::solve::{Method, Settings, Solution};
    let row =
        |jacobian: Vec<(usize, [f64; 3])>, inequality| Row { value: 0.1, rate: 0.2, bias: 0.3, inequality, jacobian };
    let rows = |rows: Vec<Row>| Rows {
        dim: 2,
        inverse_mass: vec![1.0, 0.5],
        velocity: vec![[0.1, 0.2, 0.0], [0.3, 0.4, 0.0]],
        force: vec![[0.0, -9.81, 0.0], [0.0, -4.9, 0.0]],
        rows,
        axes: vec![],
    };
    let one = rows(vec![row(vec![(1, [1.0, 2.0, 0.0])], false)]);
    let default = Settings::default();
    assert!(is_single(&one) && solve_single(&one, &default, &mut Solution::default()));
    assert!(solve_single(&one, &Settings { method: Method::Banded, ..default }, &mut Solution::default()));
    for settings in [Settings { method: Method::Dense, ..default }, Settings { method: Method::Sparse, ..default }] {
        assert!(!solve_single(&one, &settings, &mut Solution::default()), "{:?}", settings.method);
    }
    for other in [
        rows(vec![row(vec![(0, [1.0, 0.0, 0.0])], false), row(vec![(1, [0.0, 1.0, 0.0])], false)]),
        rows(vec![row(vec![(0, [1.0, 0.0, 0.0]), (1, [-1.0, 0.0, 0.0])], false)]),
        rows(vec![row(vec![(1, [1.0, 2.0, 0.0])], true)]),
        rows(vec![]),
    ] {
        assert!(!is_single(&other));
        let mut out = Solution::default();
        assert!(!solve_single(&other, &default, &mut out));
        assert_eq!(out, Solution::default());
    }
}

/// RATTLE on a steady scene (constant forces and masses, no C reading t: the pendulum, a
/// chain) completes SHAKE's end rows without the motion tape (`Dynamics::steady`, one
/// evaluation a step fewer) and runs as the general path does, to round-off; a
/// time-dependent constraint or a velocity-dependent force keeps the general path.
#[test]
fn steady_scenes_skip_a_motion_evaluation_with_the_same_run() {
    use lagrange::numeric::dynamics::Dynamics;
    use lagrange::numeric::simulate::{Simulation, Summary};
    let steps = 2000;
    for path in ["constraints/pendulum.toml", "constraints/chain_5.toml"] {
        let s = scenario(path);
        assert!(s.program.steady(), "{path}");
        let run = |steady: bool| -> Summary {
            let mut dynamics = Dynamics::borrowing(&s.system, &s.program, s.env.clone());
            dynamics.velocity_dependent_forces = false;
            assert!(dynamics.steady);
            dynamics.steady = steady;
            let settings = settings(&s, Integrator::Verlet, Stabilize::PROJECTION, 1e-3, steps);
            Simulation::new(dynamics, &s.env, settings).expect("settings").run(&mut |_| Ok(())).expect("runs")
        };
        let (fast, general) = (run(true), run(false));
        assert_eq!(general.evaluations - fast.evaluations, steps, "{path}: one evaluation a step fewer");
        let states = fast.final_position.iter().chain(&fast.final_velocity);
        let general_states = general.final_position.iter().chain(&general.final_velocity);
        for (a, b) in states.flatten().zip(general_states.flatten()) {
            assert!((a - b).abs() <= 1e-12, "{path}: {a} against {b}");
        }
        assert!((fast.max_abs_c - general.max_abs_c).abs() <= 1e-15, "{path}: max |C|");
        assert!((fast.max_abs_c_dot - general.max_abs_c_dot).abs() <= 1e-15, "{path}: max |Ċ|");
        let (e, g) = (fast.energy_rel_drift.expect("reported"), general.energy_rel_drift.expect("reported"));
        assert!((e - g).abs() <= 1e-12, "{path}: energy {e} against {g}");
    }
    for path in ["constraints/driven_pendulum.toml", "constraints/damped_pendulum.toml"] {
        assert!(!scenario(path).program.steady(), "{path}");
    }
}

#[test]
fn a_state_evaluation_says_whether_every_number_it_wrote_is_finite() {
    // What a run relies on to keep NaN out of its solves: after the positions' evaluation
    // (C/κ and J) and the motion's (Ċ, c and each slot's 1/m, v and F), `finite` says
    // whether every number written is finite. One row on one slot (the pendulum, a 3D bead)
    // is filled without the general loops; the double pendulum takes them. Random states
    // with one number of the state or of a parameter (a mass, the rod's length, g) made
    // 0, huge, infinite or NaN; the rows are those of the last evaluation, as in a run.
    use common::{Rng, random_env};
    use lagrange::expr::eval::Value;
    use lagrange::numeric::rows::{Rows, State};
    use lagrange::numeric::simulate::initial_state;
    let special = [0.0, -0.0, 1e300, -1e300, 1e-320, f64::INFINITY, f64::NEG_INFINITY, f64::NAN];
    let finite3 = |x: &[f64; 3]| x.iter().all(|c| c.is_finite());
    for path in ["constraints/pendulum.toml", "constraints/bead_on_sphere.toml", "constraints/double_pendulum.toml"] {
        let s = scenario(path);
        let mut rng = Rng::new(33);
        let mut scratch = s.program.scratch();
        let mut rows = Rows::default();
        let (mut finite, mut not) = (0, 0);
        let symbols: Vec<_> = s.system.graph.symbols().map(|(symbol, _)| symbol).collect();
        for case in 0..3_000 {
            let mut env = random_env(&s.system, &mut rng);
            let (mut q, mut v, t) = initial_state(&s.system, &env);
            let x = special[rng.next_u64() as usize % special.len()];
            let (body, d) = (rng.next_u64() as usize % q.len(), rng.next_u64() as usize % s.system.dim());
            match case % 4 {
                0 => q[body][d] = x,
                1 => v[body][d] = x,
                2 => {
                    let symbol = symbols[rng.next_u64() as usize % symbols.len()];
                    let value = match env.get(symbol) {
                        Some(Value::Vector(mut u)) => {
                            u[d] = x;
                            Value::Vector(u)
                        }
                        _ => Value::Scalar(x),
                    };
                    env.set(symbol, value);
                }
                _ => {}
            }
            let state = State { t, q: &q, v: &v };
            s.program
                .evaluate_positions_state_into(&s.system, &env, state, &mut scratch, &mut rows.rows)
                .expect("rows");
            let written = rows.rows.iter().all(|r| r.value.is_finite() && r.jacobian.iter().all(|(_, j)| finite3(j)));
            assert_eq!(scratch.finite(), written, "{path} case {case}, positions: {:?}", rows.rows);
            s.program.evaluate_motion_state_into(&s.system, &env, state, &mut scratch, &mut rows).expect("rows");
            let written = rows.rows.iter().all(|r| r.rate.is_finite() && r.bias.is_finite())
                && rows.inverse_mass.iter().all(|w| w.is_finite())
                && rows.velocity.iter().chain(&rows.force).all(finite3);
            assert_eq!(scratch.finite(), written, "{path} case {case}, motion: {rows:?}");
            if written { finite += 1 } else { not += 1 }
        }
        assert!(finite > 1_000 && not > 300, "{path}: finite {finite}, not {not}");
    }
}

/// The bits of what an observer sees of a frame but its energy balance: step, time,
/// positions, velocities, orientations, the rows' C/κ, Ċ/κ and J, λ.
fn frame_bits(f: &lagrange::numeric::simulate::Frame) -> Vec<u64> {
    let mut bits = vec![f.step, f.time.to_bits()];
    let vectors = f.position.iter().chain(f.velocity).flatten();
    bits.extend(vectors.chain(f.orientations.iter().flatten()).map(|x| x.to_bits()));
    for row in &f.rows.rows {
        bits.extend([row.value.to_bits(), row.rate.to_bits()]);
        bits.extend(row.jacobian.iter().flat_map(|(b, j)| [*b as u64, j[0].to_bits(), j[1].to_bits(), j[2].to_bits()]));
    }
    bits.extend(f.lambda.iter().map(|x| x.to_bits()));
    bits
}

#[test]
fn a_run_that_measures_only_its_checks_has_the_same_trajectory_and_says_what_it_left_out() {
    use lagrange::numeric::simulate::{Measure, Summary};
    let bits = |s: &Summary| {
        let states = s.final_position.iter().chain(&s.final_velocity).flatten();
        states.map(|x| x.to_bits()).collect::<Vec<_>>()
    };
    let plans = [
        (Integrator::Verlet, Stabilize::PROJECTION, 1.0),
        (Integrator::Rk4, Stabilize::BAUMGARTE, 1.0),
        (Integrator::Euler, Stabilize::None, 1.0),
        // A bound so close that drift stops the run: the check stays under either measure.
        (Integrator::Euler, Stabilize::None, 1e-9),
    ];
    let mut runs = (0, 0);
    for (path, s) in common::scenarios(&["constraints", "constraints/hard"]) {
        // Contacts through their bounces and rests (the bounce speed and the contacts' rate
        // scale come from the start's accelerations under either measure), the rest briefly.
        let contacts = s.system.constraints.iter().any(|c| c.inequality);
        let steps = if contacts { ((s.scene.duration / s.scene.dt) as u64).min(4000) } else { 60 };
        for (integrator, stabilize, blowup) in plans {
            let mut settings = settings(&s, integrator, stabilize, s.scene.dt, steps);
            settings.blowup = blowup;
            let mut run = |measure| {
                settings.measure = measure;
                let mut frames = Vec::new();
                let mut energies = Vec::new();
                let result = s.simulate(settings, &mut |f| {
                    frames.push(frame_bits(f));
                    energies.push(f.energy_error);
                    Ok(())
                });
                (result, frames, energies)
            };
            let (full, full_frames, full_energies) = run(Measure::Everything);
            let (lean, lean_frames, lean_energies) = run(Measure::Checks);
            let at = format!("{} {integrator:?} {stabilize:?} blowup {blowup}", path.display());
            assert_eq!(lean_frames, full_frames, "{at}: the frames");
            assert!(full_energies.iter().all(|e| e.is_some_and(|e| !e.is_nan())), "{at}: the full run's balance");
            assert!(lean_energies.iter().all(Option::is_none), "{at}: the lean run keeps no balance");
            let (full, lean, stopped) = match (full, lean) {
                (Ok(full), Ok(lean)) => (full, lean, false),
                (Err(full), Err(lean)) => {
                    assert_eq!(lean.error, full.error, "{at}: the same stop");
                    runs.1 += 1;
                    (full.summary, lean.summary, true)
                }
                (full, lean) => panic!("{at}: {:?} against {:?}", full.map(|s| s.steps), lean.map(|s| s.steps)),
            };
            runs.0 += 1;
            assert_eq!(bits(&lean), bits(&full), "{at}: the final state");
            assert_eq!(lean.final_state, full.final_state, "{at}");
            assert_eq!((lean.steps, lean.duration, lean.evaluations), (full.steps, full.duration, full.evaluations));
            assert_eq!(lean.unconverged, full.unconverged, "{at}: unconverged projections are counted");
            // What the lean run says it left out.
            assert_eq!((full.measured, lean.measured), (Measure::Everything, Measure::Checks), "{at}");
            assert!(lean.samples.is_empty() && lean.energy_rel_drift.is_none(), "{at}");
            assert_eq!([lean.max_abs_c, lean.max_abs_c_dot, lean.final_energy_error, lean.max_kinetic], [0.0; 4]);
            // The full run samples every state it records (none when stopped at its start).
            assert!(!full.samples.is_empty() || (stopped && full.steps == 0), "{at}: the full run samples");
        }
    }
    assert!(runs.0 > 100 && runs.1 > 10, "{runs:?} runs, of which stopped");
}

/// A run of `s` from `env` under `settings`, with the one-row step allowed or not
/// (`Simulation::set_one_row`) and its solves scaled (`Simulation::set_unscaled(false)`):
/// every frame's bits, the summary (its wall time zeroed) or the stop, and how many steps
/// took the one-row step. The forces' velocity dependence is found as `Scenario::simulate`
/// finds it.
fn run_one_row(
    s: &lagrange::scenario::Scenario,
    env: &lagrange::expr::eval::Env,
    settings: lagrange::numeric::simulate::Settings,
    one_row: bool,
) -> (Vec<Vec<u64>>, Result<lagrange::numeric::simulate::Summary, String>, u64) {
    run_one_row_solved(s, env, settings, one_row, false)
}

/// [`run_one_row`] with the one-row runs' solves without the scaling or not (`unscaled`:
/// `Simulation::set_unscaled`, as a run takes them unless told otherwise).
fn run_one_row_solved(
    s: &lagrange::scenario::Scenario,
    env: &lagrange::expr::eval::Env,
    settings: lagrange::numeric::simulate::Settings,
    one_row: bool,
    unscaled: bool,
) -> (Vec<Vec<u64>>, Result<lagrange::numeric::simulate::Summary, String>, u64) {
    use lagrange::expr::Role;
    use lagrange::numeric::dynamics::Dynamics;
    use lagrange::numeric::simulate::Simulation;
    let mut dynamics = Dynamics::borrowing(&s.system, &s.program, env.clone());
    let graph = &s.system.graph;
    dynamics.velocity_dependent_forces = s.scene.forces.iter().chain(&s.scene.torques).any(|&(_, f)| {
        let velocity = |r| matches!(r, Role::Velocity { .. } | Role::AngularVelocity { .. });
        graph.free_symbols(f).into_iter().any(|x| velocity(graph.symbol(x).role))
    });
    let mut simulation = match Simulation::new(dynamics, env, settings) {
        Ok(simulation) => simulation,
        Err(error) => return (Vec::new(), Err(format!("{error:?}")), 0),
    };
    simulation.set_one_row(one_row);
    simulation.set_unscaled(unscaled);
    let mut frames = Vec::new();
    let result = simulation.run(&mut |f| {
        frames.push(frame_bits(f));
        Ok(())
    });
    let result = match result {
        Ok(summary) => Ok(lagrange::numeric::simulate::Summary { wall_seconds: 0.0, ..summary }),
        Err(failure) => Err(format!("{:?} after {:?}", failure.error, failure.summary.final_state)),
    };
    (frames, result, simulation.one_row_steps())
}

/// One equality row on the scene's only slot (the pendulum, the beads on a wire, a circle,
/// a sphere, a parabola, an ellipse, a cone): RATTLE takes the step written for that shape
/// (`stabilize::rattle_one_row`, and its plain way, `rattle_one_row_plain`) and every run
/// the start's solve in closed form (`Dynamics::solve_one_slot`), with the scaled solves
/// (`Simulation::set_unscaled(false)`) the general step's numbers bit for bit — every frame
/// (state, C, Ċ, J, λ), the summary, and any stop with its error — under Verlet with
/// projection, RK4 with Baumgarte and Euler without stabilisation, compiled or not, and from
/// hostile parameters (a zero, NaN or infinite rod length, an infinite or zero mass, a NaN
/// g, a length of 1e300) where a run stops or goes on the same way either way.
#[test]
fn one_row_scenes_take_the_one_row_step_with_the_general_steps_numbers() {
    use lagrange::expr::eval::Value;
    use lagrange::numeric::simulate::Compile;
    let plans = [
        (Integrator::Verlet, Stabilize::PROJECTION),
        (Integrator::Rk4, Stabilize::BAUMGARTE),
        (Integrator::Euler, Stabilize::None),
    ];
    let mut taken = Vec::new();
    for (path, s) in common::scenarios(&["constraints", "constraints/hard"]) {
        let steps = 300;
        for (integrator, stabilize) in plans {
            for compile in [Compile::Never, Compile::Always] {
                let mut settings = settings(&s, integrator, stabilize, s.scene.dt, steps);
                settings.compile = compile;
                let at = format!("{} {integrator:?} {stabilize:?} {compile:?}", path.display());
                let (frames, result, one_row_steps) = run_one_row(&s, &s.env, settings, true);
                let (general_frames, general, none) = run_one_row(&s, &s.env, settings, false);
                assert_eq!(none, 0, "{at}: the general step forced");
                assert_eq!(frames, general_frames, "{at}: the frames");
                assert_eq!(result, general, "{at}: the summary");
                if integrator != Integrator::Verlet {
                    assert_eq!(one_row_steps, 0, "{at}: only RATTLE's step");
                } else if one_row_steps > 0 {
                    assert_eq!(Some(one_row_steps), result.as_ref().ok().map(|r| r.steps), "{at}: every step");
                    if compile == Compile::Never {
                        taken.push(path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default());
                    }
                }
            }
        }
    }
    for scene in ["pendulum.toml", "bead_on_wire.toml", "bead_on_sphere.toml", "bead_on_parabola.toml"] {
        assert!(taken.iter().any(|t| t == scene), "{scene} takes the one-row step: {taken:?}");
    }
    assert!(!taken.iter().any(|t| t == "double_pendulum.toml" || t == "chain_5.toml"), "{taken:?}");
    // Hostile parameters of the pendulum: both paths stop, or go on, the same way.
    let s = scenario("constraints/pendulum.toml");
    let symbol = |name| s.system.graph.symbol_named(name).expect(name);
    let hostile = [
        ("l", Value::Scalar(0.0)),
        ("l", Value::Scalar(f64::NAN)),
        ("l", Value::Scalar(f64::INFINITY)),
        ("l", Value::Scalar(1e300)),
        ("l", Value::Scalar(1e-300)),
        ("m", Value::Scalar(f64::INFINITY)),
        ("m", Value::Scalar(0.0)),
        ("m", Value::Scalar(-1.0)),
        ("g", Value::Vector([f64::NAN, -9.81, 0.0])),
        ("g", Value::Vector([0.0, f64::INFINITY, 0.0])),
        ("g", Value::Vector([0.0, 1e308, 0.0])),
    ];
    let mut stopped = 0;
    for (name, value) in hostile {
        let mut env = s.env.clone();
        env.set(symbol(name), value);
        for steps in [1, 50] {
            let settings = settings(&s, Integrator::Verlet, Stabilize::PROJECTION, s.scene.dt, steps);
            let at = format!("pendulum with {name} = {value:?}, {steps} steps");
            let (frames, result, _) = run_one_row(&s, &env, settings, true);
            let (general_frames, general, _) = run_one_row(&s, &env, settings, false);
            assert_eq!(frames, general_frames, "{at}: the frames");
            assert_eq!(result, general, "{at}: the summary or the stop");
            stopped += usize::from(result.is_err());
        }
    }
    assert!(stopped >= 6, "hostile parameters stop runs: {stopped}");
}

/// The numbers of a frame whose bits [`frame_bits`] lists, as numbers (the step, time and
/// slots' indices among them, which must agree exactly).
fn frame_numbers(bits: &[u64]) -> Vec<f64> {
    bits.iter().map(|&b| f64::from_bits(b)).collect()
}

/// The largest difference between two runs' frames ([`frame_bits`]) of one row on one slot,
/// each number against its own size, but C and Ċ, which on the surface are rounding of the
/// sizes they are made of: asserts at most 1e-11 for the state, J and λ, and for C and Ċ
/// the largest of each over the run within 4× of the general run's (the drift the same);
/// the same steps, and frames that differ only in their numbers.
fn frames_close(frames: &[Vec<u64>], general_frames: &[Vec<u64>], at: &str) -> f64 {
    assert_eq!(frames.len(), general_frames.len(), "{at}: the frames");
    let mut worst = 0.0f64;
    // The largest |C| and |Ċ| of each run.
    let (mut drift, mut general_drift) = ([0.0f64; 2], [0.0f64; 2]);
    for (frame, general) in frames.iter().zip(general_frames) {
        assert_eq!((frame.len(), frame[0]), (general.len(), general[0]), "{at}: the frame's shape");
        if frame == general {
            continue;
        }
        // One row on one slot: t, q, v, then C, Ċ, the slot's index and J, then λ.
        let (x, y) = (frame_numbers(frame), frame_numbers(general));
        assert_eq!((frame.len(), frame[10], general[10]), (15, 0, 0), "{at}: one row on one slot");
        let size = |r: std::ops::Range<usize>| y[r].iter().fold(1e-300f64, |m, v| m.max(v.abs()));
        let (q, v, j, lambda) = (size(2..5), size(5..8), size(11..14), size(14..15));
        let scales = [1.0, 1.0, q, q, q, v, v, v, 0.0, 0.0, 1.0, j, j, j, lambda];
        for d in 0..2 {
            drift[d] = drift[d].max(x[8 + d].abs());
            general_drift[d] = general_drift[d].max(y[8 + d].abs());
        }
        for (k, ((a, b), scale)) in x.iter().zip(&y).zip(scales).enumerate().skip(1) {
            if scale == 0.0 {
                continue;
            }
            let off = (a - b).abs() / scale;
            let step = frame[0];
            assert!(off <= 1e-11 || a.to_bits() == b.to_bits(), "{at}: step {step}, number {k}: {a:e} against {b:e}");
            worst = worst.max(if off.is_nan() { 0.0 } else { off });
        }
    }
    for d in 0..2 {
        let (a, b) = (drift[d], general_drift[d]);
        assert!(
            a <= 4.0 * b && b <= 4.0 * a || a == b,
            "{at}: the largest |C| and |Ċ|: {drift:?} against {general_drift:?}"
        );
    }
    worst
}

/// RATTLE's one-row runs solve their row without the scaling where the magnitudes allow
/// (`single::unscaled_multiplier`, as `simulate` runs them): one division where the scaled
/// solve chains three square roots and seven divisions. Against the general step (every
/// solve scaled): the same frames to a few roundings a step — every number of every frame
/// (state, C, Ċ, J, λ) within 1e-11 of its own size (C and Ċ: ‖J‖ times |q| and |v|) over
/// 300 steps, the same steps
/// and the same stops —, every step of the one-row scenes taken the plain way; and from the
/// hostile parameters of [`one_row_scenes_take_the_one_row_step_with_the_general_steps_numbers`]:
/// those outside the guard (infinite and zero masses, g = 1e308 or ∞, a NaN or infinite
/// length) the general step's numbers bit for bit, stops and errors included; lengths of
/// 1e±300, which the run's unit brings inside it, the same steps or stop.
#[test]
fn one_row_rattle_without_the_scaling_keeps_the_general_steps_numbers_to_rounding() {
    use lagrange::expr::eval::Value;
    use lagrange::numeric::simulate::Compile;
    let mut worst = 0.0f64;
    let mut taken = 0;
    for (path, s) in common::scenarios(&["constraints", "constraints/hard"]) {
        for compile in [Compile::Never, Compile::Always] {
            let mut settings = settings(&s, Integrator::Verlet, Stabilize::PROJECTION, s.scene.dt, 300);
            settings.compile = compile;
            let at = format!("{} {compile:?}", path.display());
            let (frames, result, one_row_steps) = run_one_row_solved(&s, &s.env, settings, true, true);
            let (general_frames, general, _) = run_one_row_solved(&s, &s.env, settings, false, false);
            worst = worst.max(frames_close(&frames, &general_frames, &at));
            match (&result, &general) {
                (Ok(a), Ok(b)) => {
                    assert_eq!(a.steps, b.steps, "{at}: the steps");
                    let states = |s: &lagrange::numeric::simulate::Summary| {
                        s.final_position.iter().chain(&s.final_velocity).flatten().copied().collect::<Vec<f64>>()
                    };
                    let (x, y) = (states(a), states(b));
                    let scale = y.iter().fold(1e-300f64, |m, v| m.max(v.abs()));
                    assert!(x.iter().zip(&y).all(|(a, b)| (a - b).abs() <= 1e-9 * scale), "{at}: {x:?} {y:?}");
                }
                (a, b) => assert_eq!(a.is_err(), b.is_err(), "{at}: the stop: {a:?} against {b:?}"),
            }
            if one_row_steps > 0 {
                assert_eq!(Some(one_row_steps), result.as_ref().ok().map(|r| r.steps), "{at}: every step");
                taken += 1;
            }
        }
    }
    assert!(taken >= 20, "one-row scenes compiled and not: {taken}");
    // (6e-14 at worst, the hard/ scenes' C and Ċ on their surfaces.)
    assert!(worst < 1e-11, "largest difference {worst:e}");
    // Outside the guard: the general step's numbers and stops, bit for bit (`exact`); the
    // lengths the run's unit brings inside it, to rounding.
    let s = scenario("constraints/pendulum.toml");
    let symbol = |name| s.system.graph.symbol_named(name).expect(name);
    let hostile = [
        ("l", Value::Scalar(f64::NAN), true),
        ("l", Value::Scalar(f64::INFINITY), true),
        ("l", Value::Scalar(1e300), false),
        ("l", Value::Scalar(1e-300), false),
        ("m", Value::Scalar(f64::INFINITY), true),
        ("m", Value::Scalar(0.0), true),
        ("g", Value::Vector([0.0, f64::INFINITY, 0.0]), true),
        ("g", Value::Vector([0.0, 1e308, 0.0]), true),
    ];
    for (name, value, exact) in hostile {
        let mut env = s.env.clone();
        env.set(symbol(name), value);
        for steps in [1, 50] {
            let settings = settings(&s, Integrator::Verlet, Stabilize::PROJECTION, s.scene.dt, steps);
            let at = format!("pendulum with {name} = {value:?}, {steps} steps");
            let (frames, result, _) = run_one_row_solved(&s, &env, settings, true, true);
            let (general_frames, general, _) = run_one_row_solved(&s, &env, settings, false, false);
            if exact {
                assert_eq!(frames, general_frames, "{at}: the frames");
                assert_eq!(result, general, "{at}: the summary or the stop");
            } else {
                // A rod of 1e±300 swings 1e±150 times a step of the run: its frames are
                // rounding amplified either way; the run goes on or stops the same.
                assert_eq!(frames.len(), general_frames.len(), "{at}: the frames");
                assert_eq!(result.map(|r| r.steps), general.map(|r| r.steps), "{at}: the steps or the stop");
            }
        }
    }
}

/// The one-row solve without the scaling (`single::unscaled_multiplier`, what RATTLE's
/// one-row runs take) against the scaled one (`single::solve_single`, the general solve's
/// numbers): random rows with J, 1/m, F and c over magnitudes 10^±60 — λ within 8 roundings
/// of the scaled λ (relative to the terms of its right-hand side, where they cancel) wherever
/// the guard takes the row, and the guard declining wherever |J|², 1/m or the right-hand
/// side lies outside 10^±100 (a zero gradient, a zero or infinite mass among them).
#[test]
fn one_row_solve_without_the_scaling_is_the_scaled_solves_to_rounding() {
    use lagrange::numeric::rows::{Row, Rows};
    use lagrange::numeric::single::{solve_single, unscaled_multiplier};
    use lagrange::numeric::solve::{Settings, Solution};
    let mut rng = common::Rng::new(38);
    let settings = Settings::default();
    let (mut taken, mut declined, mut worst) = (0, 0, 0.0f64);
    for case in 0..20_000 {
        let magnitude = |rng: &mut common::Rng, spread: f64| 10f64.powf(rng.uniform(-spread, spread));
        let spread = if case % 4 == 0 { 130.0 } else { 60.0 };
        let size = magnitude(&mut rng, spread);
        let j = rng.normal_vector(3, size);
        let w = if case % 97 == 0 { [0.0, f64::INFINITY][case % 2] } else { magnitude(&mut rng, spread) };
        let size = magnitude(&mut rng, spread);
        let f = rng.normal_vector(3, size);
        let c = rng.normal() * magnitude(&mut rng, spread);
        let rows = Rows {
            dim: 3,
            inverse_mass: vec![w],
            velocity: vec![[0.0; 3]],
            force: vec![f],
            rows: vec![Row { value: 0.0, rate: 0.0, bias: c, inequality: false, jacobian: vec![(0, j)] }],
            axes: Vec::new(),
        };
        let dot = |a: &[f64; 3], b: &[f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let (square, b) = (dot(&j, &j), dot(&j, &f) * w + c);
        let inside = |x: f64| (1e-100..=1e100).contains(&x);
        let Some(mu) = unscaled_multiplier(&j, w, &f, c) else {
            declined += 1;
            continue;
        };
        taken += 1;
        assert!(inside(square) && inside(w) && b.abs() <= 1e100, "case {case}: taken outside the guard");
        let mut out = Solution::default();
        if !solve_single(&rows, &settings, &mut out) {
            continue;
        }
        let lambda = out.lambda[0];
        // The right-hand side's terms, where they cancel, bound both answers' error.
        let absolute = |x: &[f64; 3]| x.map(f64::abs);
        let terms = (dot(&absolute(&j), &absolute(&f)) * w + c.abs()) / (square * w);
        let off = (mu - lambda).abs() / terms.max(lambda.abs());
        worst = worst.max(off / f64::EPSILON);
        assert!(
            off <= 8.0 * f64::EPSILON,
            "case {case}: {mu:?} against {lambda:?} ({off:e}): J {j:?}, w {w:?}, F {f:?}, c {c:?}"
        );
    }
    assert!(taken > 5_000 && declined > 1_000, "taken {taken}, declined {declined}");
    // (At this seed: 3.9 roundings at worst.)
    assert!(worst <= 8.0, "worst {worst}");
}
