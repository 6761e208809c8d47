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
//! - The slider-crank's simulated piston on its closed-form position.
//! - Ċ = J·u + ∂C/∂t, and Ċ the central-difference rate of C along the state's own motion,
//!   for every constraint of every joint and scene file, 2D and 3D.

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
    for rel in ["joints/revolute", "joints/weld", "joints/prismatic", "joints/gear", "rigid/rod_pinned"] {
        let rel = format!("constraints/{rel}.toml");
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
    // The scene: horizontal, at rest, I = m L²/12, F = m g.
    let (code, out, err) = lagrange(&["solve", "constraints/rigid/rod_pinned.toml", "--format", "json"]);
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
    use lagrange::model::scene::StateError;
    let rel = "constraints/rigid/rod_pinned.toml";
    // The file without its scene: nothing gives th.
    let text = read(rel);
    let without_scene = text.split("[scene]").next().expect("the file's head");
    let loaded = load(without_scene).expect("valid file");
    let system = &loaded.system;
    let sym = |name: &str| system.graph.symbol_named(name).expect("a symbol of the file");
    let mut state = vec![
        (sym("x"), Value::Vector([1.0, 0.0, 0.0])),
        (sym("v"), Value::Vector([0.0; 3])),
        (sym("F"), Value::Vector([0.0; 3])),
        (sym("I"), Value::Scalar(1.0)),
    ];
    let missing = environment(system, &loaded.values, &loaded.scene, &state).map(|_| ());
    assert!(matches!(&missing, Err(StateError::Missing(name)) if name == "th"), "{missing:?}");
    state.push((sym("th"), Value::Scalar(0.0)));
    let env = environment(system, &loaded.values, &loaded.scene, &state).expect("ω and τ default to 0");
    assert_eq!(env.get(sym("w")), Some(Value::Scalar(0.0)));
    assert_eq!(env.get(sym("T")), Some(Value::Scalar(0.0)));
    // Through the binary: a zero inertia names the body.
    let (code, _, err) = lagrange(&["solve", rel, "--set", "I=0"]);
    assert_eq!(code, Some(1));
    assert!(err.contains("a moment of inertia must be positive and finite: body `rod` has 0"), "{err}");
}

/// `check` on every file of `constraints/joints/` and `constraints/rigid/`: each `[[expect]]` (forces and torques from
/// closed forms or the engines' formulas) holds at random states with θ and ω on the
/// constraints, and at the states the entries give.
#[test]
fn every_rigid_file_passes_check() {
    let mut passed = 0;
    for rel in common::rigid_files() {
        let mut checked = lagrange::check::Checked::from_text(&rel, &read(&rel)).unwrap_or_else(|e| panic!("{e}"));
        let outcomes = checked.run();
        // A joint of the library states the engine's formula it reproduces.
        assert!(!rel.starts_with("constraints/joints/") || !outcomes.is_empty(), "{rel}: no [[expect]]");
        for outcome in outcomes {
            assert!(outcome.passed, "{rel}: {outcome}");
            passed += 1;
        }
    }
    assert!(passed >= 80, "only {passed} checks ran");
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

/// θ(t) of the physical pendulum θ'' = −(3g/2L) cos θ (the uniform rod pinned at one end,
/// θ from the horizontal), by RK4 with a step 100 times finer than the simulation's.
fn physical_pendulum(duration: f64) -> (f64, f64) {
    let k = 1.5 * 9.81 / 2.0;
    let f = |y: [f64; 2]| [y[1], -k * y[0].cos()];
    let (mut y, h) = ([0.0, 0.0], 1e-5);
    for _ in 0..(duration / h).round() as usize {
        let a = f(y);
        let b = f([y[0] + h / 2.0 * a[0], y[1] + h / 2.0 * a[1]]);
        let c = f([y[0] + h / 2.0 * b[0], y[1] + h / 2.0 * b[1]]);
        let d = f([y[0] + h * c[0], y[1] + h * c[1]]);
        for i in 0..2 {
            y[i] += h / 6.0 * (a[i] + 2.0 * b[i] + 2.0 * c[i] + d[i]);
        }
    }
    (y[0], y[1])
}

fn final_number(summary: &serde_json::Value, name: &str) -> f64 {
    summary["final"][name].as_f64().unwrap_or_else(|| panic!("no final {name}: {summary}"))
}

/// `simulate` integrates θ and ω with x and v: the pinned rod released horizontal swings as
/// the physical pendulum (RK4 + projection against the ODE's own RK4 to 1e-9), keeps its
/// pin to rounding, and Verlet + projection holds the energy (translation and rotation).
#[test]
fn simulate_swings_the_pinned_rod_as_a_physical_pendulum() {
    let rel = "constraints/rigid/rod_pinned.toml";
    let (code, out, err) = lagrange(&["simulate", rel, "--integrator", "rk4", "--duration", "1", "--format", "json"]);
    assert_eq!(code, Some(0), "{err}");
    let summary: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let (th, w) = physical_pendulum(1.0);
    assert!((final_number(&summary, "th") - th).abs() < 1e-9, "θ {} against {th}", final_number(&summary, "th"));
    assert!((final_number(&summary, "w") - w).abs() < 1e-9, "ω {} against {w}", final_number(&summary, "w"));
    // The centre stays L/2 from the pin along the rod.
    let x = [summary["final"]["x"][0].as_f64().expect("x"), summary["final"]["x"][1].as_f64().expect("x")];
    assert!((x[0] - th.cos()).abs() < 1e-9 && (x[1] - th.sin()).abs() < 1e-9, "x = {x:?}");
    assert!(summary["max_abs_C"].as_f64().expect("a number") < 1e-12);
    let (code, out, err) = lagrange(&["simulate", rel, "--format", "json"]);
    assert_eq!(code, Some(0), "{err}");
    let summary: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let drift = summary["energy_rel_drift"].as_f64().expect("reported");
    assert!(drift < 1e-5, "Verlet's energy balance {drift}");
    assert!(summary["max_abs_C"].as_f64().expect("a number") < 1e-12);
}

/// The CSV carries each rigid body's angle and angular velocity after the positions and
/// velocities, one number each.
#[test]
fn the_csv_has_the_angle_and_the_angular_velocity() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-rigid-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    let csv = dir.join("rod.csv");
    let path = csv.to_str().expect("UTF-8");
    let (code, _, err) =
        lagrange(&["simulate", "constraints/rigid/rod_pinned.toml", "--duration", "0.01", "--csv", path]);
    assert_eq!(code, Some(0), "{err}");
    let text = std::fs::read_to_string(&csv).expect("the CSV");
    let _ = std::fs::remove_dir_all(&dir);
    let mut lines = text.lines();
    let header = lines.next().expect("a header");
    assert!(header.starts_with("t,x.x,x.y,v.x,v.y,th,w,lambda_pin.x,"), "{header}");
    let columns = header.split(',').count();
    let first = lines.next().expect("step 0");
    assert_eq!(first.split(',').count(), columns);
    assert!(first.starts_with("0,1,0,0,0,0,0,"), "{first}");
}

/// One Newton step of the projection in generalised coordinates: the pin's error is shared
/// between x and θ in the ratio of 1/m to 1/I (the mass-weighted minimum-norm step).
#[test]
fn the_projection_weights_the_angle_by_the_inertia() {
    use lagrange::numeric::dynamics::Dynamics;
    use lagrange::numeric::simulate::initial_state;
    use lagrange::numeric::stabilize::{Inequalities, project_positions};
    let loaded = load(&read("constraints/rigid/rod_pinned.toml")).expect("valid file");
    let system = &loaded.system;
    let d = derive(system).expect("derive");
    let program = RowProgram::new(system, &d, &loaded.scene.forces);
    let sym = |name: &str| system.graph.symbol_named(name).expect("a symbol of the file");
    // The centre 0.1 above where the pin allows (θ = 0 puts it at [1, 0]); I = m/3.
    let overrides = [(sym("x"), Value::Vector([1.0, 0.1, 0.0]))];
    let env = environment(system, &loaded.values, &loaded.scene, &overrides).expect("a full state");
    let (mut q, v, t) = initial_state(system, &env);
    assert_eq!(q.len(), 2, "one body and one angular slot");
    let mut dynamics = Dynamics::new(system, program, env);
    project_positions(&mut dynamics, t, &mut q, &v, 0.0, 1, Inequalities::Violated).expect("projects");
    // J = [E, perp(rot(0, [-1, 0]))] = [E, [0, -1]]: Δy − Δθ = −0.1 with weights m = 1,
    // I = 1/3 gives Δy = −0.1 (1/m)/(1/m + 1/I) = −0.025 and Δθ = 0.075.
    assert!((q[0][1] - 0.075).abs() < 1e-12, "y = {}", q[0][1]);
    assert!((q[1][0] - 0.075).abs() < 1e-12, "θ = {}", q[1][0]);
    assert!(q[0][0] == 1.0, "x = {}", q[0][0]);
}

/// Ċ = κ Σᵢ (Jᵛᵢ·vᵢ + Jʷᵢ·ωᵢ) + ∂C/∂t for every constraint of every joint and scene file
/// (`constraints/joints/`, `constraints/rigid/`, 2D and 3D), at random states with angles on
/// the whole circle and uniformly random unit quaternions; and Ċ is the rate of C along the
/// motion the state gives, x + v s, θ + ω s in 2D or exp(½ ω s) ⊗ q in 3D (ω in the world
/// frame), t + s, by fourth-order central differences: the derivation's J against numbers,
/// not only against its own Ċ.
#[test]
fn c_dot_is_j_times_u_for_every_joint_and_scene_file() {
    use lagrange::expr::grad::gradient;
    let (mut checked, mut files_3d) = (0, 0);
    for rel in common::rigid_files() {
        let loaded = load(&read(&rel)).expect("valid file");
        let system = &loaded.system;
        let dim = system.dim();
        files_3d += usize::from(dim == 3);
        let mut d = derive(system).expect("derive");
        let partials: Vec<_> = d
            .constraints
            .iter()
            .map(|c| c.c)
            .collect::<Vec<_>>()
            .into_iter()
            .map(|c| gradient(&mut d.graph, c, system.time).expect("∂C/∂t"))
            .collect();
        let mut rng = Rng::new(0x0b0d_0003);
        for _ in 0..100 {
            let mut env: Env = common::random_env(system, &mut rng);
            for (s, info) in system.graph.symbols() {
                match (info.role, dim) {
                    (Role::Orientation { .. }, 2) => env.set(s, Value::Scalar(rng.uniform(-3.2, 3.2))),
                    (Role::Orientation { .. }, _) => env.set(s, Value::Quaternion(common::random_quaternion(&mut rng))),
                    (Role::AngularVelocity { .. }, 2) => env.set(s, Value::Scalar(rng.uniform(-2.0, 2.0))),
                    (Role::AngularVelocity { .. }, _) => env.set(s, Value::Vector(rng.uniform_vector(3, -2.0, 2.0))),
                    _ => {}
                }
            }
            // The state moved along its own velocities by s.
            let moved = |s: f64| {
                let mut e = env.clone();
                let t = env.get(system.time).and_then(Value::scalar).expect("t");
                e.set(system.time, Value::Scalar(t + s));
                for body in &system.bodies {
                    let x = env.get(body.position).expect("x").components(dim);
                    let v = env.get(body.velocity).expect("v").components(dim);
                    let mut moved = [0.0; 3];
                    for c in 0..dim {
                        moved[c] = x[c] + v[c] * s;
                    }
                    e.set(body.position, Value::Vector(moved));
                    let Some(rigid) = body.rigid.as_ref() else { continue };
                    let w = env.get(rigid.angular_velocity).expect("ω");
                    match (env.get(rigid.orientation).expect("orientation"), w) {
                        (Value::Scalar(th), Value::Scalar(w)) => e.set(rigid.orientation, Value::Scalar(th + w * s)),
                        (Value::Quaternion(q), Value::Vector(w)) => {
                            let speed = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
                            let axis = w.map(|c| c / speed);
                            e.set(rigid.orientation, Value::Quaternion(common::turned(q, axis, speed * s)));
                        }
                        other => panic!("{rel}: orientation and ω {other:?}"),
                    }
                }
                e
            };
            let h = 1e-3;
            let around = [moved(-2.0 * h), moved(-h), moved(h), moved(2.0 * h)];
            let value = |id, env: &Env| eval_one(&d.graph, id, env).expect("evaluates");
            for (k, c) in d.constraints.iter().enumerate() {
                let mut u = value(partials[k], &env).scalar().expect("a scalar");
                let kappa = c.scale.to_f64();
                for &(b, j) in &c.jacobian {
                    let j = value(j, &env).components(dim);
                    let v = env.get(system.bodies[b].velocity).expect("v").components(dim);
                    u += kappa * (0..dim).map(|i| j[i] * v[i]).sum::<f64>();
                }
                for &(b, jw) in &c.angular {
                    let rigid = system.bodies[b].rigid.as_ref().expect("a rigid body");
                    let w = env.get(rigid.angular_velocity).expect("ω").components(dim);
                    let jw = value(jw, &env).components(dim);
                    u += kappa * jw.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>();
                }
                let name = &system.constraints[k].name;
                let c_dot = value(c.c_dot, &env).scalar().expect("a scalar");
                assert!(common::close(c_dot, u, 1e-11), "{rel}, {name}: Ċ = {c_dot}, J·u + ∂C/∂t = {u}");
                let [c2m, cm, cp, c2p] = [0, 1, 2, 3].map(|i| value(c.c, &around[i]).scalar().expect("a scalar"));
                let rate = (-c2p + 8.0 * cp - 8.0 * cm + c2m) / (12.0 * h);
                assert!(common::close(c_dot, rate, 1e-7), "{rel}, {name}: Ċ = {c_dot}, dC/ds = {rate}");
                checked += 1;
            }
        }
    }
    assert!(files_3d >= 6, "the 3D joints: {files_3d} files");
    assert!(checked >= 10_000, "{checked} rows checked");
}

/// `[scene] forces` takes a rigid body's torque by its symbol (`T = "…"`, a scalar): the
/// state's torque is the expression's value, and `simulate` re-evaluates it at every
/// state, so a damping torque −c ω takes energy out of the swinging rod.
#[test]
fn scene_torques_are_expressions_evaluated_at_each_state() {
    use lagrange::scenario::Scenario;
    let text = read("constraints/rigid/rod_pinned.toml");
    let scene_forces = "forces = { F = \"[0, -m*g]\" }";
    assert!(text.contains(scene_forces));
    let with =
        |torque: &str| text.replace(scene_forces, &format!("forces = {{ F = \"[0, -m*g]\", T = \"{torque}\" }}"));
    // At the scene's state (th = 0, w = 0) the torque 2 + 3 cos(th) is 5.
    let loaded = load(&with("2 + 3*cos(th)")).expect("valid file");
    let system = &loaded.system;
    let env = environment(system, &loaded.values, &loaded.scene, &[]).expect("a full state");
    let t = system.graph.symbol_named("T").expect("the torque symbol");
    assert_eq!(env.get(t), Some(Value::Scalar(5.0)));
    // The energy ½ m |v|² + ½ I ω² + m g y after a second, from rest at y = 0.
    let energy = |torque: &str| {
        let scenario = Scenario::new(load(&with(torque)).expect("valid file"), &[]).expect("runnable");
        let mut settings = scenario.settings();
        settings.steps = 1000;
        let summary = scenario.simulate(settings, &mut |_| Ok(())).map_err(|f| f.error.to_string()).expect("runs");
        let get = |name: &str| summary.final_state.iter().find(|(n, _)| n == name).map(|(_, v)| *v).expect(name);
        let (x, v) = (get("x").components(2), get("v").components(2));
        let w = get("w").scalar().expect("ω");
        0.5 * (v[0] * v[0] + v[1] * v[1]) + 0.5 * w * w / 3.0 + 9.81 * x[1]
    };
    let free = energy("0");
    let damped = energy("-0.5*w");
    assert!(free.abs() < 1e-4, "the free rod keeps its energy: {free}");
    assert!(damped < -0.1, "the damped rod loses energy: {damped}");
}

/// A chain of 20 rigid rods on revolute joints, pinned at the top and released horizontal
/// (`constraints/rigid/chain_20.toml`, 40 rows): `simulate`'s default run (Verlet and the
/// projection, dt = 1e-3) holds every joint within |C| ≤ 1e-9 over 10⁴ steps while the chain
/// falls and whips (measured: max |C| 3.0e-12). The chain must have moved for this to mean
/// anything: its tip falls below the pin by more than half the chain's length.
#[test]
fn a_chain_of_twenty_rigid_rods_keeps_its_joints_over_ten_thousand_steps() {
    let scenario = common::scenario("constraints/rigid/chain_20.toml");
    assert_eq!(scenario.system.bodies.len(), 20);
    assert_eq!(scenario.system.constraints.len(), 40, "20 joints, one row per component of each");
    let mut settings = scenario.settings();
    settings.steps = 10_000;
    let summary = scenario.simulate(settings, &mut |_| Ok(())).map_err(|f| f.error.to_string()).expect("runs");
    assert_eq!(summary.steps, 10_000);
    assert!(summary.max_abs_c <= 1e-9, "max |C| = {:e}", summary.max_abs_c);
    let tip = summary.final_state.iter().find(|(n, _)| n == "x20").map(|(_, v)| v.components(2)).expect("x20");
    assert!(tip[1] < -10.0, "the chain fell: its last rod's centre is at {tip:?}");
}

/// `lagrange bench` on rigid bodies: the work-precision sweep runs every method on the pinned
/// rod, and the formula accuracy has a row for the rod's force and one for its constraint
/// torque (`rod (torque)`), each at f64's precision on random states (the solve of the rows
/// against the double-double reference over the same angular slots).
#[test]
fn bench_measures_the_rigid_bodies_forces_and_torques() {
    let (code, out, err) =
        lagrange(&["bench", "constraints/rigid/rod_pinned.toml", "--duration", "0.05", "--format", "json"]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let rows = v["rows"].as_array().expect("rows");
    assert!(rows.len() >= 36 && rows.iter().all(|r| r["status"] == "ok"), "{rows:?}");
    for file in ["rod_pinned", "atwood_pulley", "cylinder_incline", "chain_20"] {
        let scenario = common::scenario(&format!("constraints/rigid/{file}.toml"));
        let rows = lagrange::precision::accuracy::formula_accuracy(&scenario, 50, 7);
        let rigid = scenario.system.bodies.iter().filter(|b| b.rigid.is_some()).count();
        assert_eq!(rows.len(), 2 * (scenario.system.bodies.len() + rigid), "{file}: a row per force and torque");
        for r in rows.iter().filter(|r| r.states == "random") {
            assert_eq!(r.count, 50, "{file} {}", r.body);
            assert!(r.median_rel_error < 1e-12, "{file} {}: median {:e}", r.body, r.median_rel_error);
        }
        let torques = rows.iter().filter(|r| r.torque).count();
        assert_eq!(torques, 2 * rigid, "{file}");
    }
}

/// The slider-crank (`constraints/rigid/slider_crank.toml`: the crank driven at W, eight rows
/// for eight coordinates, so the motion is the kinematics alone): `simulate`'s default run
/// (Verlet and the projection, 10³ steps of 1 ms, 2 rad of crank) keeps the piston on the
/// closed form x_p = r cos(W t) + sqrt(l² − r² sin²(W t)) and on the cylinder at every step
/// within 1e-10 (measured: 4.0e-13 at most).
#[test]
fn the_slider_cranks_piston_follows_its_closed_form() {
    let s = common::scenario("constraints/rigid/slider_crank.toml");
    let param = |name: &str| {
        let sym = s.system.graph.symbol_named(name).expect(name);
        s.env.get(sym).and_then(Value::scalar).expect(name)
    };
    let (r, l, w) = (param("r"), param("l"), param("W"));
    let piston = s.system.bodies.iter().position(|b| b.rigid.is_none()).expect("the piston");
    let (mut worst, mut frames) = (0f64, 0);
    let summary = s
        .simulate(s.settings(), &mut |f| {
            let phi = w * f.time;
            let x = r * phi.cos() + (l * l - r * r * phi.sin().powi(2)).sqrt();
            worst = worst.max((f.position[piston][0] - x).abs()).max(f.position[piston][1].abs());
            frames += 1;
            Ok(())
        })
        .map_err(|f| f.error.to_string())
        .expect("runs");
    assert_eq!(summary.steps, 1000);
    assert!(frames >= 1000, "{frames} frames");
    assert!(worst <= 1e-10, "the piston is {worst:e} off its closed form");
}
