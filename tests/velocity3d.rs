//! The velocity-level solvers (`numeric::velocity`) on 3D rigid bodies (quaternion
//! orientations, world ω, principal moments): every solver runs the 3D ball and hinge joints
//! and the spinning top for 1 s within its bound with unit quaternions, PGS and the soft step
//! converge to the exact velocity solve on a broken hinge as iterations grow (the exact solve
//! itself equal to −A⁻¹ J u by hand), the resting hung top's impulse is λ·h, a free fast
//! asymmetric spinner keeps T and |L| over 10⁴ soft steps, runs are bitwise deterministic,
//! and the command line steps a 3D file.

mod common;

use common::{impulse_system, velocity_steps};
use lagrange::expr::eval::Value;
use lagrange::model::raw::RawValue;
use lagrange::numeric::rotation::{self, first_angular};
use lagrange::numeric::rows::Rows;
use lagrange::numeric::solve::solve;
use lagrange::numeric::velocity::{Settings, Softness, Solver};
use lagrange::scenario::Scenario;
use nalgebra::DVector;

fn read(rel: &str) -> String {
    std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)).expect("file")
}

/// The file's text with some values given (numbers, vectors or quaternions).
fn scenario_of(text: &str, values: &[(&str, &[f64])]) -> Scenario {
    let loaded = lagrange::model::file::load(text).expect("valid file");
    let raw: Vec<(&str, RawValue)> = values
        .iter()
        .map(|&(n, v)| (n, if v.len() == 1 { RawValue::Number(v[0]) } else { RawValue::Vector(v.to_vec()) }))
        .collect();
    let overrides = lagrange::model::state::values(&loaded.system, &raw).expect("values of the file's symbols");
    Scenario::new(loaded, &overrides).expect("derives")
}

/// The quaternion rotation q s q*.
fn rotate(q: [f64; 4], s: [f64; 3]) -> [f64; 3] {
    let p = rotation::product(rotation::product(q, [0.0, s[0], s[1], s[2]]), [q[0], -q[1], -q[2], -q[3]]);
    [p[1], p[2], p[3]]
}

fn norm4(q: [f64; 4]) -> f64 {
    q.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// The bound on max |C| over 1 s at 60 Hz with Box2D's defaults (4 substeps): the exact
/// velocity solve projects onto C = 0 after every substep (measured: 1.1e-13 at most); the
/// iterative solvers hold the joints to 5 mm, as in 2D (measured: 1.0e-3, 1.5e-3 and
/// 1.2e-3 for the soft step, PGS and XPBD on the spinning top, whose tip carries its weight
/// and the centripetal pull at 100 rad/s of spin, 0.4 rad a substep; 4.3e-5 at most on the
/// joints, which start on their constraints in velocity too).
fn bound(solver: Solver) -> f64 {
    match solver {
        Solver::Exact => 1e-9,
        Solver::SoftStep | Solver::Pgs | Solver::Xpbd => 5e-3,
    }
}

#[test]
fn every_solver_runs_the_3d_joints_and_the_top_for_a_second() {
    for rel in
        ["constraints/joints/ball_3d.toml", "constraints/joints/hinge_3d.toml", "constraints/rigid/spinning_top.toml"]
    {
        let s = scenario_of(&read(rel), &[]);
        for solver in Solver::ALL {
            let settings = Settings::new(solver, 1.0 / 60.0, 1.0);
            let mut norms = 0.0f64;
            let summary = s
                .simulate_velocity(settings, &mut |f| {
                    assert!(!f.orientations.is_empty(), "{rel}: the frame carries the orientations");
                    norms = f.orientations.iter().fold(norms, |m, q| m.max((norm4(*q) - 1.0).abs()));
                    Ok(())
                })
                .unwrap_or_else(|f| panic!("{rel}, {}: {}", solver.name(), f.error));
            let name = solver.name();
            assert_eq!(summary.steps, 60, "{rel}, {name}");
            assert!(summary.max_abs_c <= bound(solver), "{rel}, {name}: max |C| = {:e}", summary.max_abs_c);
            assert!(norms < 1e-14, "{rel}, {name}: |q| − 1 = {norms:e}");
            for (n, value) in &summary.final_state {
                if let Value::Quaternion(q) = value {
                    assert!((norm4(*q) - 1.0).abs() < 1e-14, "{rel}, {name}: final {n} = {q:?}");
                }
            }
            assert!(
                summary.final_state.iter().any(|(_, v)| matches!(v, Value::Quaternion(_))),
                "{rel}, {name}: the final orientations"
            );
        }
    }
}

/// The hinge of `hinge_3d.toml` closed at a turned orientation (both bodies turned by the
/// same q, so the axes stay aligned and the anchors meet) with velocities that break it, no
/// forces and no torques.
fn broken_hinge() -> Scenario {
    let q = rotation::normalise([0.9, 0.2, -0.3, 0.1]);
    let (s1, s2) = ([0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]);
    let (r1, r2) = (rotate(q, s1), rotate(q, s2));
    let x2 = [0, 1, 2].map(|d| r1[d] - r2[d]);
    scenario_of(
        &read("constraints/joints/hinge_3d.toml"),
        &[
            ("x1", &[0.0, 0.0, 0.0]),
            ("x2", &x2),
            ("q1", &q),
            ("q2", &q),
            ("v1", &[0.3, -1.0, 0.2]),
            ("v2", &[1.0, 0.5, -0.4]),
            ("w1", &[0.7, -0.2, 0.5]),
            ("w2", &[-1.1, 0.4, 0.3]),
            ("F1", &[0.0, 0.0, 0.0]),
            ("F2", &[0.0, 0.0, 0.0]),
            ("T1", &[0.0, 0.0, 0.0]),
            ("T2", &[0.0, 0.0, 0.0]),
        ],
    )
}

/// The velocities over the rows' slots after a torque-free kick of h: each 3D body's
/// body-frame ω through the implicit-midpoint gyroscopic kick (`rotation::kick_axes`).
fn kicked(rows: &Rows, h: f64) -> Vec<[f64; 3]> {
    let mut u = rows.velocity.clone();
    let first = first_angular(rows).expect("3D bodies");
    for g in (first..u.len()).step_by(3) {
        let axis = |x: &[[f64; 3]]| [x[g][0], x[g + 1][0], x[g + 2][0]];
        let w = rotation::kick_axes(
            [rows.inverse_mass[g], rows.inverse_mass[g + 1], rows.inverse_mass[g + 2]],
            axis(&rows.force),
            axis(&rows.velocity),
            h,
            axis(&rows.velocity),
        );
        for k in 0..3 {
            u[g + k] = [w[k], 0.0, 0.0];
        }
    }
    u
}

#[test]
fn pgs_and_the_soft_step_converge_to_the_exact_velocity_solve_on_a_3d_hinge() {
    // One step of one substep from velocities that break the hinge (Ċ ≠ 0 at C = 0, no
    // forces). The exact velocity solve is A P = −(J u + C/h) with A = J M⁻¹ Jᵀ over the
    // per-axis slots (M⁻¹ = blockdiag(E/m, R diag(1/I) Rᵀ): the world inverse inertia the
    // engines use, Jolt's `HingeRotationConstraintPart`) and u the velocities after the
    // gyroscopic kick. PGS converges to it as the iterations grow, the soft step without
    // relax to its regularised twin (A + (s_i/s_m) diag A) P = −J u (as in 2D,
    // `tests/velocity_rigid.rs`).
    let s = broken_hinge();
    let rows = s.program.evaluate(&s.system, &s.env).expect("rows");
    assert!(rows.rows.iter().all(|r| r.value.abs() < 1e-15), "the hinge starts closed");
    let h = 1.0 / 60.0;
    let u = kicked(&rows, h);
    let (a, ju, _) = impulse_system(&rows, &u);
    assert!(ju.amax() > 0.3, "the velocities break the hinge: J u = {ju}");
    let c = DVector::from_iterator(rows.rows.len(), rows.rows.iter().map(|r| r.value / h));
    let exact = a.clone().lu().solve(&(-&ju - &c)).expect("A is regular");
    let one = |solver: Solver, iterations: usize| {
        let settings =
            Settings { substeps: 1, iterations: Some(iterations), relax: false, ..Settings::new(solver, h, h) };
        let mut p = vec![];
        velocity_steps(&s, settings, 1, |st, _| p.clone_from(&st.impulse)).expect("runs");
        DVector::from_vec(p)
    };
    let library = one(Solver::Exact, 1);
    assert!((&library - &exact).amax() < 1e-12 * exact.amax(), "exact velocity solve {library} against {exact}");

    let soft = Softness::new(60.0f64.min(0.25 / h), 2.0, h);
    let mut twin = a.clone();
    for i in 0..twin.nrows() {
        twin[(i, i)] += soft.impulse_scale / soft.mass_scale * a[(i, i)];
    }
    let bias = DVector::from_iterator(rows.rows.len(), rows.rows.iter().map(|r| soft.bias_rate * r.value));
    let soft_exact = twin.lu().solve(&(-&ju - &bias)).expect("regular");
    for (solver, target) in [(Solver::Pgs, &exact), (Solver::SoftStep, &soft_exact)] {
        let errors: Vec<f64> = [1, 2, 4, 8, 16, 64, 512].iter().map(|&n| (&one(solver, n) - target).amax()).collect();
        for w in errors.windows(2) {
            assert!(w[1] <= w[0] * 1.0001 + 1e-13 * target.amax(), "{}: errors {errors:?} must fall", solver.name());
        }
        assert!(errors[0] > 1e-3 * target.amax(), "{}: one sweep is not converged yet: {errors:?}", solver.name());
        assert!(errors[6] < 1e-10 * target.amax(), "{}: errors {errors:?}", solver.name());
    }
}

#[test]
fn the_resting_hung_top_takes_lambda_times_h() {
    // The top of `spinning_top.toml` hung below its tip at rest (turned by π about x, so its
    // axis e₃ points down and the centre is at [0, 0, −l]): the tip carries the weight, the
    // acceleration solve's λ of tip.z is m g (C = x + rot(q, [0, 0, −l]), ∇ₓC = E: the force
    // λ holds up m g), of tip.x and tip.y zero, and with the force through the centre no
    // torque. The exact velocity solve's impulse per substep is λ h to round-off; the soft
    // step's and PGS's once they settle.
    let s = scenario_of(
        &read("constraints/rigid/spinning_top.toml"),
        &[("x", &[0.0, 0.0, -0.5]), ("v", &[0.0, 0.0, 0.0]), ("q", &[0.0, 1.0, 0.0, 0.0]), ("w", &[0.0, 0.0, 0.0])],
    );
    let lambda = solve(&s.program.evaluate(&s.system, &s.env).expect("rows")).lambda;
    let (m, g) = (1.0, 9.81);
    assert!((lambda[2] - m * g).abs() < 1e-12 && lambda[0].abs() < 1e-12 && lambda[1].abs() < 1e-12, "λ = {lambda:?}");
    for (solver, tolerance) in [(Solver::Exact, 1e-12), (Solver::SoftStep, 1e-9), (Solver::Pgs, 1e-9)] {
        let settings = Settings::new(solver, 1.0 / 60.0, 1.0);
        let h = settings.substep();
        let mut last = vec![0.0; 3];
        velocity_steps(&s, settings, if solver == Solver::Exact { 3 } else { 600 }, |st, _| {
            last.clone_from(&st.impulse)
        })
        .expect("runs");
        let relative = (last[2] / h - lambda[2]).abs() / lambda[2];
        assert!(
            relative < tolerance,
            "{}: P/h = {} against λ = {} ({relative:e})",
            solver.name(),
            last[2] / h,
            lambda[2]
        );
        for k in 0..2 {
            assert!(last[k].abs() / h < tolerance * lambda[2], "{}: tip P/h = {:?}", solver.name(), last);
        }
    }
}

/// One body held at its centre (x = 0: no torque from the constraint), no force, no
/// torque, its rotation free.
const SPINNER: &str = r#"
title = "A free asymmetric spinner held at its centre"
dimension = 3

[[bodies]]
name = "spinner"
position = "x"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"
orientation = "q"
angular_velocity = "w"
angular_acceleration = "alpha"
inertia = "I"
torque = "T"

[[constraints]]
name = "centre"
expr = "x = [0, 0, 0]"

[scene]
initial = { x = [0.0, 0.0, 0.0], v = [0.0, 0.0, 0.0], q = [1.0, 0.0, 0.0, 0.0], w = [0.3, 20.0, 1.0], m = 1.0, I = [1.0, 2.0, 3.0] }
forces = { F = "[0, 0, 0]", T = "[0, 0, 0]" }
"#;

/// T = ½ Σ Iₖ ωₖ² and |L|² = Σ (Iₖ ωₖ)² from the rows' body-frame slots.
fn energy_and_momentum(rows: &Rows) -> (f64, f64) {
    let first = first_angular(rows).expect("a 3D body");
    let (mut t, mut l2) = (0.0, 0.0);
    for k in first..rows.velocity.len() {
        let (w, i) = (rows.velocity[k][0], 1.0 / rows.inverse_mass[k]);
        t += 0.5 * i * w * w;
        l2 += (i * w).powi(2);
    }
    (t, l2.sqrt())
}

#[test]
fn a_fast_asymmetric_spinner_keeps_its_energy_and_momentum_under_the_soft_step() {
    // ω = [0.3, 20, 1] rad/s about the intermediate axis of I = [1, 2, 3]: it tumbles
    // (Dzhanibekov), 0.33 rad a step at 60 Hz. An explicit gyroscopic kick gains energy at
    // every step (Avian #420, Bullet #357); the implicit-midpoint kick keeps T and |L| of
    // the body-frame ω exactly, and the drift turns the body about ω itself (exp(h ω)), which
    // leaves the body-frame ω as it is. Bound over 10⁴ steps: |T/T₀ − 1| and ||L|/|L₀| − 1|
    // below 1e-9, rounding only (measured 2.0e-11 and 1.0e-11: the per-axis and world
    // conversions of ω at each of the 4·10⁴ substeps).
    let s = scenario_of(SPINNER, &[]);
    let settings = Settings { steps: 10_000, ..Settings::new(Solver::SoftStep, 1.0 / 60.0, 0.0) };
    let (mut first, mut worst_t, mut worst_l, mut turned) = (None, 0.0f64, 0.0f64, 0.0f64);
    s.simulate_velocity(settings, &mut |f| {
        let (t, l) = energy_and_momentum(f.rows);
        let (t0, l0) = *first.get_or_insert((t, l));
        worst_t = worst_t.max((t / t0 - 1.0).abs());
        worst_l = worst_l.max((l / l0 - 1.0).abs());
        // The body axis e₂ (the spin's) leaves its start: it does tumble.
        turned = turned.max(1.0 - rotate(f.orientations[0], [0.0, 1.0, 0.0])[1]);
        Ok(())
    })
    .unwrap_or_else(|f| panic!("{}", f.error));
    assert!(turned > 1.0, "the spinner tumbles (e₂·y fell by {turned})");
    assert!(worst_t < 1e-9 && worst_l < 1e-9, "T drifted by {worst_t:e}, |L| by {worst_l:e}");
}

#[test]
fn runs_with_3d_bodies_are_deterministic() {
    let s = broken_hinge();
    for solver in Solver::ALL {
        let run = || {
            let mut bits = Vec::new();
            let settings = Settings { steps: 30, ..Settings::new(solver, 1.0 / 60.0, 0.0) };
            s.simulate_velocity(settings, &mut |f| {
                bits.extend(f.position.iter().chain(f.velocity).flat_map(|p| p.map(f64::to_bits)));
                bits.extend(f.orientations.iter().flat_map(|q| q.map(f64::to_bits)));
                bits.extend(f.lambda.iter().map(|l| l.to_bits()));
                Ok(())
            })
            .expect("runs");
            bits
        };
        let first = run();
        assert!(!first.is_empty());
        assert_eq!(first, run(), "{}", solver.name());
    }
}

#[test]
fn the_command_line_steps_a_3d_file_with_every_solver() {
    for solver in ["soft-step", "pgs", "xpbd", "exact-velocity"] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_lagrange"))
            .args(["simulate", "constraints/joints/hinge_3d.toml", "--solver", solver, "--format", "json"])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .expect("runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{solver}: {err}");
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        let q = json["final"]["q1"].as_array().unwrap_or_else(|| panic!("{solver}: final q1 in {json}"));
        let q: Vec<f64> = q.iter().filter_map(|x| x.as_f64()).collect();
        assert_eq!(q.len(), 4, "{solver}: {q:?}");
        assert!((q.iter().map(|x| x * x).sum::<f64>().sqrt() - 1.0).abs() < 1e-12, "{solver}: |q1| = {q:?}");
        // The links turned about the hinge's z axis only (w1 = z at the start).
        assert!(q[1].abs() < 1e-9 && q[2].abs() < 1e-9 && q[3].abs() > 0.1, "{solver}: q1 = {q:?}");
    }
}

/// The stability analysis's linearisation of a 3D step (`stability::step_jacobian`): the
/// state holds a 3D body's rotation vector φ (from the orientation at the call) and ω, three
/// numbers each, and the dynamics' orientations are as they were after it (every step folds
/// φ into them; the columns were taken at drifting orientations, and φ⁺ was the last
/// substep's turn only). A body at rest on an axle through its centre, turned, turns freely
/// by dt ω: ∂φ⁺/∂φ = E, ∂φ⁺/∂ω = dt E, ∂ω⁺/∂ω = E, ∂ω⁺/∂φ = 0.
#[test]
fn the_step_jacobian_of_a_3d_body_is_its_free_turn() {
    use lagrange::numeric::dynamics::Dynamics;
    use lagrange::numeric::simulate::initial_state;
    use lagrange::numeric::velocity::stability;
    let q = rotation::normalise([0.9, 0.2, -0.3, 0.1]);
    let text = "title = \"Axle\"\ndimension = 3\n\n[[bodies]]\nname = \"wheel\"\nposition = \"x\"\nvelocity = \"v\"\n\
                acceleration = \"a\"\nmass = \"m\"\nforce = \"F\"\norientation = \"q\"\nangular_velocity = \"w\"\n\
                angular_acceleration = \"alpha\"\ninertia = \"I\"\ntorque = \"T\"\n\n[[constraints]]\nname = \"axle\"\n\
                expr = \"x = [0, 0, 0]\"\n\n[scene]\ninitial = { x = [0, 0, 0], v = [0, 0, 0], m = 1.0, I = [1.0, 2.0, 3.0], \
                w = [0, 0, 0] }\n";
    let s = scenario_of(text, &[("q", &q)]);
    let dt = 1.0 / 60.0;
    let settings = Settings::new(Solver::SoftStep, dt, 1.0);
    // (x, φ) and (v, ω), three numbers each, and the axle's three warm-start impulses.
    assert_eq!(stability::state_len(&s.system, &settings), 15);
    let mut dynamics = Dynamics::new(&s.system, s.program.clone(), s.env.clone());
    let before = dynamics.orientations().to_vec();
    let (q0, v0, t) = initial_state(&s.system, &s.env);
    let m = stability::step_jacobian(&mut dynamics, t, &q0, &v0, &[0.0; 3], &settings).expect("rows");
    assert_eq!(m.shape(), (15, 15));
    assert_eq!(dynamics.orientations(), &before[..], "the orientation is put back");
    let (phi, omega) = (3, 9);
    for i in 0..3 {
        for j in 0..3 {
            let e = if i == j { 1.0 } else { 0.0 };
            for (what, row, col, want) in [
                ("∂φ⁺/∂φ", phi, phi, e),
                ("∂φ⁺/∂ω", phi, omega, dt * e),
                ("∂ω⁺/∂ω", omega, omega, e),
                ("∂ω⁺/∂φ", omega, phi, 0.0),
            ] {
                let got = m[(row + i, col + j)];
                assert!((got - want).abs() < 1e-7, "{what} [{i}][{j}] = {got}, want {want}");
            }
        }
    }
}
