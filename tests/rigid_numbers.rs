//! 2D rigid bodies in numbers: the rows' angular slots (Jʷ, 1/I, ω, τ), the λ solve with
//! the angular terms in A, and `lagrange solve`'s torques, angular accelerations and
//! per-constraint reactions.
//!
//! - The pinned uniform rod against its closed form: the pivot force along the rod
//!   m g cos φ + m ω² L/2, across it ¼ m g sin φ, α = −(3g/2L) sin φ, and the constraint
//!   torque r × F_c about the centre of mass.
//! - The numeric λ (rows → `numeric::solve`) against the symbolic A and b of the derivation
//!   evaluated at the same random states and solved densely, for every joint file.
//! - A door on two hinges (redundant revolute joints): the diagnostic names the rows.

mod common;

use common::Rng;
use lagrange::derive::derive;
use lagrange::expr::Role;
use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::model::file::load;
use lagrange::model::scene::environment;
use lagrange::numeric::rows::{RowProgram, angular_slot};
use lagrange::numeric::solve::{Status, solve};
use nalgebra::{DMatrix, DVector};

fn read(rel: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// Runs the binary from the crate root with `args`: (exit code, stdout, stderr).
fn lagrange(args: &[&str]) -> (Option<i32>, String, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .expect("the lagrange binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The pinned rod of `constraints/rigid/rod_pinned.toml` at angle φ from the downward
/// vertical, spinning at ω, under gravity: the solve gives the textbook pivot force.
#[test]
fn the_pinned_rod_solves_to_its_closed_form() {
    let loaded = load(&read("constraints/rigid/rod_pinned.toml")).expect("valid file");
    let system = &loaded.system;
    let d = derive(system).expect("derive");
    let program = RowProgram::new(system, &d, &[]);
    let (m, l, g) = (1.0, 2.0, 9.81);
    let sym = |name: &str| system.graph.symbol_named(name).expect("a symbol of the file");
    let mut rng = Rng::new(0x0b0d_0001);
    for _ in 0..100 {
        let phi = rng.uniform(-3.0, 3.0);
        let omega = rng.uniform(-4.0, 4.0);
        // θ is the rod's direction from the pin (p = 0) to its centre: hanging down is −π/2.
        let th = phi - std::f64::consts::FRAC_PI_2;
        let e = [th.cos(), th.sin()];
        let tangent = [-e[1], e[0]];
        let x = [e[0] * l / 2.0, e[1] * l / 2.0, 0.0];
        let v = [tangent[0] * omega * l / 2.0, tangent[1] * omega * l / 2.0, 0.0];
        let overrides = [
            (sym("th"), Value::Scalar(th)),
            (sym("w"), Value::Scalar(omega)),
            (sym("x"), Value::Vector(x)),
            (sym("v"), Value::Vector(v)),
            (sym("I"), Value::Scalar(m * l * l / 12.0)),
            (sym("F"), Value::Vector([0.0, -m * g, 0.0])),
        ];
        let env = environment(system, &loaded.values, &loaded.scene, &overrides).expect("a full state");
        let rows = program.evaluate(system, &env).expect("rows");
        let s = solve(&rows);
        assert_eq!(s.status, Status::Solved, "{:?}", s.diagnostics);
        let f = s.constraint_force[0];
        let towards_pin = -(f[0] * e[0] + f[1] * e[1]);
        let across = f[0] * tangent[0] + f[1] * tangent[1];
        let along_expected = m * g * phi.cos() + m * omega * omega * l / 2.0;
        let across_expected = 0.25 * m * g * phi.sin();
        assert!(common::close(towards_pin, along_expected, 1e-12), "φ {phi} ω {omega}: along {towards_pin}");
        assert!(common::close(across, across_expected, 1e-12), "φ {phi} ω {omega}: across {across}");
        let slot = angular_slot(system, 0).expect("the rod is rigid");
        let alpha = s.acceleration[slot][0];
        assert!(common::close(alpha, -1.5 * g / l * phi.sin(), 1e-12), "α {alpha}");
        // The constraint torque about the centre of mass: r × F_c with r from the centre to the pin.
        let r = [-x[0], -x[1]];
        let torque = r[0] * f[1] - r[1] * f[0];
        assert!(common::close(s.constraint_force[slot][0], torque, 1e-12), "torque");
    }
}

/// Every joint file whose rows are independent: the solve's λ equals the one from the
/// derivation's symbolic A and b (with the Jʷ Jʷ/I and Jʷ τ/I terms) at random states.
#[test]
fn the_numeric_lambda_agrees_with_the_symbolic_a_and_b() {
    let mut checked = 0;
    for rel in ["revolute", "weld", "prismatic", "gear", "rod_pinned"] {
        let rel = format!("constraints/rigid/{rel}.toml");
        let loaded = load(&read(&rel)).expect("valid file");
        let system = &loaded.system;
        let d = derive(system).expect("derive");
        let program = RowProgram::new(system, &d, &[]);
        let mut rng = Rng::new(0x0b0d_0002);
        for _ in 0..200 {
            let mut env: Env = common::random_env(system, &mut rng);
            // Angles over the whole circle, rates of either sign.
            for (s, info) in system.graph.symbols() {
                match info.role {
                    Role::Orientation { .. } => env.set(s, Value::Scalar(rng.uniform(-3.2, 3.2))),
                    Role::AngularVelocity { .. } | Role::Torque { .. } => {
                        env.set(s, Value::Scalar(rng.uniform(-2.0, 2.0)))
                    }
                    _ => {}
                }
            }
            let n = d.b.len();
            let value = |id| eval_one(&d.graph, id, &env).expect("evaluates").scalar().expect("a scalar");
            let mut a = DMatrix::zeros(n, n);
            for &(k, j, id) in &d.a {
                a[(k, j)] = value(id);
                a[(j, k)] = value(id);
            }
            let b = DVector::from_iterator(n, d.b.iter().map(|&id| value(id)));
            let Some(ch) = a.clone().cholesky() else { panic!("{rel}: A is not positive definite") };
            let lambda = ch.solve(&(-&b));
            let rows = program.evaluate(system, &env).expect("rows");
            let s = solve(&rows);
            assert_eq!(s.status, Status::Solved, "{rel}: {:?}", s.diagnostics);
            let cond = a.clone().svd(false, false).singular_values;
            let cond = cond.max() / cond.min();
            for k in 0..n {
                let tol = 1e-13 * cond.max(1.0) * lambda.amax().max(1.0);
                assert!(
                    (s.lambda[k] - lambda[k]).abs() <= tol.max(1e-11),
                    "{rel}, row {k}: numeric {} symbolic {}",
                    s.lambda[k],
                    lambda[k]
                );
            }
            checked += 1;
        }
    }
    assert_eq!(checked, 1000);
}

/// Two hinges on one door are redundant (rank 3 of 4): `solve` says so, naming the rows,
/// and the minimum-norm answer still holds the door (zero accelerations).
#[test]
fn a_door_on_two_hinges_is_diagnosed_redundant_by_name() {
    let (code, out, err) = lagrange(&["solve", "constraints/rigid/door_two_hinges.toml", "--format", "json"]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    assert_eq!(v["status"], "minimum-norm");
    let diagnostics = v["diagnostics"].as_array().expect("diagnostics");
    assert_eq!(diagnostics.len(), 1, "{diagnostics:?}");
    let names: Vec<&str> =
        diagnostics[0]["constraints"].as_array().expect("names").iter().filter_map(|n| n.as_str()).collect();
    assert_eq!(names, ["upper.x", "lower.x"]);
    assert!(diagnostics[0]["message"].as_str().expect("a message").contains("rank 3 of 4"));
    let a = &v["accelerations"]["door"];
    assert!(a[0].as_f64().expect("a number").abs() < 1e-12 && a[1].as_f64().expect("a number").abs() < 1e-12);
    assert!(v["angular_accelerations"]["door"].as_f64().expect("a number").abs() < 1e-12);
    // The two hinges share the weight, each with its torque about the centre.
    let reactions = v["reactions"].as_array().expect("reactions");
    assert_eq!(reactions.len(), 4);
    let weight: f64 = reactions.iter().map(|r| r["force"][1].as_f64().expect("a number")).sum();
    assert!((weight - 98.1).abs() < 1e-9, "the hinges carry {weight}");
    let torque: f64 = reactions.iter().map(|r| r["torque"].as_f64().expect("a number")).sum();
    assert!(torque.abs() < 1e-9);
}

/// `solve --format json` on a rigid body: torques and angular accelerations are numbers
/// keyed by the rigid bodies only; each reaction names its constraint and body.
#[test]
fn solve_prints_torques_angular_accelerations_and_reactions() {
    let (code, out, err) = lagrange(&[
        "solve",
        "constraints/rigid/rod_pinned.toml",
        "--set",
        "th=0",
        "--set",
        "x=[1,0]",
        "--set",
        "v=[0,0]",
        "--set",
        "I=0.3333333333333333",
        "--set",
        "F=[0,-9.81]",
        "--format",
        "json",
    ]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    // Horizontal rod released from rest: α = −3g/(2L), the pin carries ¼ m g.
    let alpha = v["angular_accelerations"]["rod"].as_f64().expect("a number");
    assert!((alpha + 1.5 * 9.81 / 2.0).abs() < 1e-12, "α = {alpha}");
    let torque = v["torques"]["rod"].as_f64().expect("a number");
    assert!((torque + 0.25 * 9.81).abs() < 1e-12, "T_c = {torque}");
    let reactions = v["reactions"].as_array().expect("reactions");
    let names: Vec<(&str, &str)> = reactions
        .iter()
        .map(|r| (r["constraint"].as_str().expect("a name"), r["body"].as_str().expect("a name")))
        .collect();
    assert_eq!(names, [("pin.x", "rod"), ("pin.y", "rod")]);
    assert!((reactions[1]["force"][1].as_f64().expect("a number") - 0.25 * 9.81).abs() < 1e-12);
    // A point-mass file keeps its JSON as it was: no rigid keys.
    let (code, out, _) = lagrange(&["solve", "constraints/pendulum.toml", "--format", "json"]);
    assert_eq!(code, Some(0));
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    assert!(v.get("torques").is_none() && v.get("reactions").is_none());
}

/// A rigid body's state needs its orientation; a zero inertia is refused naming the body.
#[test]
fn a_rigid_state_without_an_angle_or_with_zero_inertia_is_an_error() {
    let rel = "constraints/rigid/rod_pinned.toml";
    let base = ["solve", rel, "--set", "x=[1,0]", "--set", "v=[0,0]", "--set", "F=[0,-9.81]"];
    let mut args = base.to_vec();
    args.extend(["--set", "I=1"]);
    let (code, _, err) = lagrange(&args);
    assert_eq!(code, Some(1));
    assert!(err.contains("no value for `th`"), "{err}");
    let mut args = base.to_vec();
    args.extend(["--set", "th=0", "--set", "I=0"]);
    let (code, _, err) = lagrange(&args);
    assert_eq!(code, Some(1));
    assert!(err.contains("a moment of inertia must be positive and finite: body `rod` has 0"), "{err}");
}

/// The rigid-body files, relative to the crate root, sorted.
fn rigid_files() -> Vec<String> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/rigid");
    let mut out: Vec<String> = std::fs::read_dir(dir)
        .expect("constraints/rigid exists")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".toml"))
        .map(|n| format!("constraints/rigid/{n}"))
        .collect();
    out.sort();
    out
}

/// `check` on every file of `constraints/rigid/`: each `[[expect]]` (forces and torques from
/// closed forms or the engines' formulas) holds at random states with θ and ω on the
/// constraints, and at the states the entries give.
#[test]
fn every_rigid_file_passes_check() {
    let mut passed = 0;
    for rel in rigid_files() {
        let mut checked = lagrange::check::Checked::from_text(&rel, &read(&rel)).unwrap_or_else(|e| panic!("{e}"));
        for outcome in checked.run() {
            assert!(outcome.passed, "{rel}: {outcome}");
            passed += 1;
        }
    }
    assert!(passed >= 4, "only {passed} checks ran");
}

/// The user-test API judges torques too, and a wrong torque fails (with the state shown).
#[test]
fn the_check_api_judges_torques() {
    let rel = "constraints/rigid/rod_pinned.toml";
    let mut checked = lagrange::check::Checked::from_text(rel, &read(rel)).expect("valid file");
    let right = "-(L/2)*(2*m*L*T - 4*I*dot(F, perp(rot(th, [1, 0]))))/(4*I + m*L^2)";
    checked.assert_torque("rod", right);
    let wrong = checked.torque("rod", &format!("-({right})")).expect("judged");
    assert!(!wrong.passed && wrong.detail.contains("th = "), "{wrong}");
}
