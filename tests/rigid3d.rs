//! 3D rigid bodies (quaternion orientations, world-frame ω, α, τ, principal moments) in
//! numbers, each against an independent reference:
//!
//! - The ball joint's A against the engines' effective mass K = (1/m₁ + 1/m₂) E
//!   − [r₁]× I₁⁻¹ [r₁]× − [r₂]× I₂⁻¹ [r₂]× (Jolt `PointConstraintPart`), with R(q) from
//!   nalgebra's `UnitQuaternion` (not the crate's `rotate`), numeric and symbolic A alike.
//! - λ of a body hung from a fixed point by a ball joint against the Newton–Euler closed
//!   form (m a = F + λ, I α = τ − ω × I ω + r × λ, a + α × r + ω × (ω × r) = 0), solved with
//!   nalgebra; the reported torque is r × λ.
//! - Ċ and C̈ of joint-like constraints (ball, hinge rows, a distance between body points)
//!   against central differences of C along a trajectory with an exact rotation
//!   q(t) = exp(½ n φ(t)) q₀ about a random fixed axis n, φ = w t + ½ a t² (so ω = n φ̇,
//!   α = n a); and Ċ/κ = Σ J·u over the rows' slots.
//! - Refusals naming the body: a non-unit quaternion; `bench --solvers` runs them (without
//!   a stability limit, saying so) and `generate --solver` writes their step
//!   (`tests/generate_step.rs`).
//! - Every scene of the joint library and the rigid-body files starts on its constraints.
//! - `bench` (the work-precision sweep and formula accuracy) on the ball joint and the
//!   spinning top: every run ok, each force and world torque at f64's precision against the
//!   double-double reference.

mod common;

use common::{Rng, random_quaternion, turned};
use lagrange::derive::derive;
use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::model::file::load;
use lagrange::model::scene::environment;
use lagrange::numeric::rows::{RowProgram, angular_slots, world_angular};
use lagrange::numeric::solve::{Status, solve};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

fn read(rel: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

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

/// R(q) from nalgebra (Hamilton, [w, x, y, z]).
fn rotation(q: [f64; 4]) -> Matrix3<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3])).to_rotation_matrix().into_inner()
}

fn v3(x: [f64; 3]) -> Vector3<f64> {
    Vector3::new(x[0], x[1], x[2])
}

/// The world inverse inertia R diag(1/I) Rᵀ.
fn inverse_inertia(q: [f64; 4], moments: [f64; 3]) -> Matrix3<f64> {
    let r = rotation(q);
    r * Matrix3::from_diagonal(&Vector3::new(1.0 / moments[0], 1.0 / moments[1], 1.0 / moments[2])) * r.transpose()
}

fn skew(r: Vector3<f64>) -> Matrix3<f64> {
    r.cross_matrix()
}

fn sym(system: &lagrange::System, name: &str) -> lagrange::expr::Symbol {
    system.graph.symbol_named(name).unwrap_or_else(|| panic!("no symbol {name}"))
}

#[test]
fn the_ball_joint_a_is_the_engines_effective_mass() {
    let loaded = load(&read("constraints/joints/ball_3d.toml")).expect("valid file");
    let system = &loaded.system;
    let d = derive(system).expect("derive");
    let program = RowProgram::new(system, &d, &[]);
    let s1 = [0.5, 0.2, -0.1];
    let s2 = [-0.3, 0.0, 0.4];
    let mut rng = Rng::new(0x3d_0001);
    for _ in 0..200 {
        let (q1, q2) = (random_quaternion(&mut rng), random_quaternion(&mut rng));
        let (m1, m2) = (rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0));
        let i1 = [rng.uniform(0.1, 2.0), rng.uniform(0.1, 2.0), rng.uniform(0.1, 2.0)];
        let i2 = [rng.uniform(0.1, 2.0), rng.uniform(0.1, 2.0), rng.uniform(0.1, 2.0)];
        let overrides = [
            (sym(system, "q1"), Value::Quaternion(q1)),
            (sym(system, "q2"), Value::Quaternion(q2)),
            (sym(system, "m1"), Value::Scalar(m1)),
            (sym(system, "m2"), Value::Scalar(m2)),
            (sym(system, "I1"), Value::Vector(i1)),
            (sym(system, "I2"), Value::Vector(i2)),
            (sym(system, "w1"), Value::Vector(rng.normal_vector(3, 1.0))),
            (sym(system, "w2"), Value::Vector(rng.normal_vector(3, 1.0))),
        ];
        let env = environment(system, &loaded.values, &loaded.scene, &overrides).expect("a full state");
        // Jolt PointConstraintPart::CalculateConstraintProperties: K = (1/m1 + 1/m2) E
        // − [r1]× I1⁻¹ [r1]× − [r2]× I2⁻¹ [r2]×, r = R(q) s.
        let (r1, r2) = (rotation(q1) * v3(s1), rotation(q2) * v3(s2));
        let k = Matrix3::identity() * (1.0 / m1 + 1.0 / m2)
            - skew(r1) * inverse_inertia(q1, i1) * skew(r1)
            - skew(r2) * inverse_inertia(q2, i2) * skew(r2);
        // The numeric A of the rows (J M⁻¹ Jᵀ over the slots, three principal slots per body).
        let rows = program.evaluate(system, &env).expect("rows");
        for a in 0..3 {
            for b in 0..3 {
                let mut entry = 0.0;
                for &(slot, ja) in &rows.rows[a].jacobian {
                    if let Some((_, jb)) = rows.rows[b].jacobian.iter().find(|(s, _)| *s == slot) {
                        entry += rows.inverse_mass[slot] * (ja[0] * jb[0] + ja[1] * jb[1] + ja[2] * jb[2]);
                    }
                }
                assert!(common::close(entry, k[(a, b)], 1e-12), "rows A[{a},{b}] = {entry}, K = {}", k[(a, b)]);
                // The derivation's symbolic A at the same state.
                let id = d.a_entry(a, b).expect("a non-zero entry");
                let symbolic = eval_one(&d.graph, id, &env).expect("evaluates").scalar().expect("a scalar");
                assert!(
                    common::close(symbolic, k[(a, b)], 1e-12),
                    "derived A[{a},{b}] = {symbolic}, K = {}",
                    k[(a, b)]
                );
            }
        }
    }
}

const PENDULUM: &str = r#"
title = "A body hung from a fixed point by a ball joint"
dimension = 3

[parameters]
s = [0.1, -0.2, 0.6]
p = [0.0, 0.0, 0.0]

[[bodies]]
name = "bob"
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
name = "ball"
expr = "x + rot(q, s) = p"
"#;

#[test]
fn a_hung_body_solves_to_the_newton_euler_closed_form() {
    let loaded = load(PENDULUM).expect("valid file");
    let system = &loaded.system;
    let d = derive(system).expect("derive");
    let program = RowProgram::new(system, &d, &[]);
    let s = [0.1, -0.2, 0.6];
    let mut rng = Rng::new(0x3d_0002);
    for _ in 0..200 {
        let q = random_quaternion(&mut rng);
        let m = rng.uniform(0.5, 3.0);
        let moments = [rng.uniform(0.1, 2.0), rng.uniform(0.1, 2.0), rng.uniform(0.1, 2.0)];
        let (w, tau, f) = (rng.normal_vector(3, 3.0), rng.normal_vector(3, 2.0), rng.normal_vector(3, 10.0));
        let r = rotation(q) * v3(s);
        // The centre where the anchor meets p = 0, moving so that Ċ = 0: v = −ω × r.
        let x = -r;
        let v = -v3(w).cross(&r);
        let overrides = [
            (sym(system, "q"), Value::Quaternion(q)),
            (sym(system, "m"), Value::Scalar(m)),
            (sym(system, "I"), Value::Vector(moments)),
            (sym(system, "w"), Value::Vector(w)),
            (sym(system, "T"), Value::Vector(tau)),
            (sym(system, "F"), Value::Vector(f)),
            (sym(system, "x"), Value::Vector([x[0], x[1], x[2]])),
            (sym(system, "v"), Value::Vector([v[0], v[1], v[2]])),
        ];
        let env = environment(system, &loaded.values, &loaded.scene, &overrides).expect("a full state");
        let rows = program.evaluate(system, &env).expect("rows");
        let solution = solve(&rows);
        assert_eq!(solution.status, Status::Solved, "{:?}", solution.diagnostics);
        // Newton–Euler: a = (F + λ)/m, α = I⁻¹(τ − ω × Iω + r × λ), and the anchor's
        // acceleration a + α × r + ω × (ω × r) = 0, linear in λ:
        // (E/m − [r]× I⁻¹ [r]×) λ = −(F/m + (I⁻¹(τ − ω × Iω)) × r + ω × (ω × r)).
        let inv = inverse_inertia(q, moments);
        let world_i = inv.try_inverse().expect("positive moments");
        let (wv, tv, fv) = (v3(w), v3(tau), v3(f));
        let free_alpha = inv * (tv - wv.cross(&(world_i * wv)));
        let k = Matrix3::identity() / m - skew(r) * inv * skew(r);
        let rhs = -(fv / m + free_alpha.cross(&r) + wv.cross(&wv.cross(&r)));
        let lambda = k.lu().solve(&rhs).expect("K is positive definite");
        for c in 0..3 {
            assert!(
                common::close(solution.lambda[c], lambda[c], 1e-10),
                "λ[{c}] {} vs {}",
                solution.lambda[c],
                lambda[c]
            );
        }
        // The constraint torque about the centre of mass is r × λ, and α the closed form's.
        let slots = angular_slots(system, 0).expect("rigid");
        let torque = world_angular(&rows, |k| solution.constraint_force[k][0], slots.clone());
        let alpha = world_angular(&rows, |k| solution.acceleration[k][0], slots);
        let expected_torque = r.cross(&lambda);
        let expected_alpha = free_alpha + inv * expected_torque;
        for c in 0..3 {
            assert!(common::close(torque[c], expected_torque[c], 1e-10), "torque {torque:?}");
            assert!(common::close(alpha[c], expected_alpha[c], 1e-10), "α {alpha:?} vs {expected_alpha:?}");
        }
    }
}

const JOINTS: &str = r#"
title = "Joint-like constraints between two 3D rigid bodies"
dimension = 3

[parameters]
s1 = [0.5, 0.2, -0.1]
s2 = [-0.3, 0.7, 0.4]
h1 = [0.0, 0.6, 0.8]
b2 = [1.0, 0.0, 0.0]
L = 1.5

[[bodies]]
name = "a"
position = "x1"
velocity = "v1"
acceleration = "a1"
mass = "m1"
force = "F1"
orientation = "q1"
angular_velocity = "w1"
angular_acceleration = "alpha1"
inertia = [0.1, 0.2, 0.3]
torque = "T1"

[[bodies]]
name = "b"
position = "x2"
velocity = "v2"
acceleration = "a2"
mass = "m2"
force = "F2"
orientation = "q2"
angular_velocity = "w2"
angular_acceleration = "alpha2"
inertia = [0.4, 0.5, 0.6]
torque = "T2"

[[constraints]]
name = "ball"
expr = "x1 + rot(q1, s1) = x2 + rot(q2, s2)"

[[constraints]]
name = "align"
expr = "dot(rot(q1, h1), rot(q2, b2)) = 0"

[[constraints]]
name = "rope"
expr = "norm(x2 + rot(q2, s2) - x1 - rot(q1, s1)) = L"

[[constraints]]
name = "twist"
expr = "dot(cross(rot(q1, h1), rot(q2, b2)), rot(q1, s1) + x1 - x2) = t/3"
"#;

#[test]
fn rates_and_accelerations_match_central_differences_along_a_rotation() {
    let loaded = load(JOINTS).expect("valid file");
    let system = &loaded.system;
    let d = derive(system).expect("derive");
    let program = RowProgram::new(system, &d, &[]);
    let mut rng = Rng::new(0x3d_0003);
    let h = 1e-3;
    for _ in 0..100 {
        // Per body: x(t) = x0 + v t + ½ a t², q(t) = exp(½ n φ(t)) q0, φ = w t + ½ α t².
        let mut bodies = Vec::new();
        for _ in 0..2 {
            let n = rng.normal_vector(3, 1.0);
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            bodies.push((
                rng.normal_vector(3, 1.0),
                rng.normal_vector(3, 1.0),
                rng.normal_vector(3, 1.0),
                random_quaternion(&mut rng),
                n.map(|c| c / len),
                rng.uniform(-2.0, 2.0),
                rng.uniform(-2.0, 2.0),
            ));
        }
        let t0 = rng.uniform(0.0, 1.0);
        let state = |t: f64| {
            let mut env = Env::new();
            for (&(s, v), _) in loaded.values.iter().zip(0..) {
                env.set(s, v);
            }
            env.set(system.time, Value::Scalar(t0 + t));
            for (i, &(x0, v0, a0, q0, n, w, alpha)) in bodies.iter().enumerate() {
                let k = i + 1;
                let at =
                    |p: [f64; 3], v: [f64; 3], a: [f64; 3]| [0, 1, 2].map(|c| p[c] + v[c] * t + 0.5 * a[c] * t * t);
                env.set(sym(system, &format!("x{k}")), Value::Vector(at(x0, v0, a0)));
                env.set(sym(system, &format!("v{k}")), Value::Vector([0, 1, 2].map(|c| v0[c] + a0[c] * t)));
                env.set(sym(system, &format!("a{k}")), Value::Vector(a0));
                env.set(sym(system, &format!("q{k}")), Value::Quaternion(turned(q0, n, w * t + 0.5 * alpha * t * t)));
                env.set(sym(system, &format!("w{k}")), Value::Vector(n.map(|c| c * (w + alpha * t))));
                env.set(sym(system, &format!("alpha{k}")), Value::Vector(n.map(|c| c * alpha)));
                env.set(sym(system, &format!("m{k}")), Value::Scalar(1.0));
                for name in ["F", "T"] {
                    env.set(sym(system, &format!("{name}{k}")), Value::Vector([0.0; 3]));
                }
            }
            env
        };
        let value = |id, env: &Env| eval_one(&d.graph, id, env).expect("evaluates").scalar().expect("a scalar");
        let now = state(0.0);
        let around = [state(-2.0 * h), state(-h), state(h), state(2.0 * h)];
        for (k, dc) in d.constraints.iter().enumerate() {
            let name = &system.constraints[k].name;
            let [c2m, cm, cp, c2p] = [0, 1, 2, 3].map(|i| value(dc.c, &around[i]));
            let c0 = value(dc.c, &now);
            // Fourth-order central differences.
            let rate = (-c2p + 8.0 * cp - 8.0 * cm + c2m) / (12.0 * h);
            let second = (-c2p + 16.0 * cp - 30.0 * c0 + 16.0 * cm - c2m) / (12.0 * h * h);
            let c_dot = value(dc.c_dot, &now);
            let c_ddot = value(dc.c_ddot, &now);
            assert!(common::close(c_dot, rate, 1e-7), "{name}: Ċ {c_dot} vs {rate}");
            assert!(common::close(c_ddot, second, 1e-5), "{name}: C̈ {c_ddot} vs {second}");
        }
        // Ċ/κ = Σ J·u + ∂C/∂t over the rows' slots (C = lhs − rhs, so ∂C/∂t = −1/3 for
        // `twist` only).
        let rows = program.evaluate(system, &now).expect("rows");
        for (k, row) in rows.rows.iter().enumerate() {
            let ju: f64 =
                row.jacobian.iter().map(|(slot, j)| (0..3).map(|c| j[c] * rows.velocity[*slot][c]).sum::<f64>()).sum();
            let explicit =
                if system.constraints[k].name == "twist" { -1.0 / 3.0 / d.constraints[k].scale.to_f64() } else { 0.0 };
            assert!(
                common::close(row.rate, ju + explicit, 1e-12),
                "{}: Ċ/κ {} vs J·u {ju}",
                system.constraints[k].name,
                row.rate
            );
        }
    }
}

#[test]
fn a_non_unit_quaternion_is_refused_naming_the_body() {
    let (code, _, err) = lagrange(&["solve", "constraints/joints/ball_3d.toml", "--set", "q1=[1, 0.1, 0, 0]"]);
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("`q1`, the orientation of body `a`, is not a unit quaternion"), "{err}");
    let (code, _, err) = lagrange(&["solve", "constraints/joints/ball_3d.toml", "--set", "q1=[1, 0, 0]"]);
    assert_ne!(code, Some(0), "{err}");
    assert!(err.contains("a unit quaternion [w, x, y, z]: found 3 numbers"), "{err}");
}

#[test]
fn solve_reports_3d_torques_and_angular_accelerations_as_arrays() {
    let (code, out, err) = lagrange(&["solve", "constraints/joints/hinge_3d.toml", "--format", "json"]);
    assert_eq!(code, Some(0), "{err}");
    let json: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    for key in ["torques", "angular_accelerations"] {
        for body in ["a", "b"] {
            let v = &json[key][body];
            assert!(v.as_array().is_some_and(|a| a.len() == 3 && a.iter().all(|x| x.is_f64())), "{key}.{body}: {v}");
        }
    }
    let reactions = json["reactions"].as_array().expect("reactions");
    assert!(reactions.iter().all(|r| r["torque"].as_array().is_some_and(|a| a.len() == 3)), "{reactions:?}");
}

/// `bench --solvers` on 3D rigid bodies (it hung for over ten minutes in the stability
/// analysis's eigenvalues): every solver runs on the ball joint, the hinge and the spinning
/// top, and the stable hertz is not computed, saying why, in text and JSON.
#[test]
fn the_solver_bench_runs_3d_bodies_without_a_stability_limit() {
    for file in
        ["constraints/joints/ball_3d.toml", "constraints/joints/hinge_3d.toml", "constraints/rigid/spinning_top.toml"]
    {
        let (code, out, err) = lagrange(&["bench", file, "--solvers", "--duration", "0.02", "--format", "json"]);
        assert_eq!(code, Some(0), "{file}: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
        let runs = v["runs"].as_array().expect("runs");
        assert!(runs.len() >= 16 && runs.iter().all(|r| r["failure"].is_null()), "{file}: {runs:?}");
        assert_eq!(v["stable_hertz"].as_array().map(Vec::len), Some(0), "{file}");
        assert_eq!(v["stable_hertz_not_computed"], "3D rigid bodies", "{file}");
    }
    let (code, out, err) = lagrange(&["bench", "constraints/joints/ball_3d.toml", "--solvers", "--duration", "0.02"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(out.contains("largest stable hertz: not computed (3D rigid bodies"), "{out}");
}

/// The scenes of the joint library and of the rigid-body files start on their constraints,
/// in position and velocity: a start off them shows in every method's max |Ċ| and energy
/// (the ball and distance joints started turning at ω = 1 with their centres at rest, their
/// anchors apart at 0.8 m/s: `bench` gave every method max |Ċ| = 0.8).
#[test]
fn every_joint_and_rigid_scene_starts_on_its_constraints() {
    let mut scenes = 0;
    for dir in ["constraints/joints", "constraints/rigid"] {
        let mut files: Vec<_> = std::fs::read_dir(dir).expect("dir").map(|e| e.expect("entry").path()).collect();
        files.sort();
        for path in files.iter().filter(|p| p.extension().is_some_and(|e| e == "toml")) {
            let text = std::fs::read_to_string(path).expect("file");
            let Ok(scenario) = lagrange::scenario::Scenario::new(load(&text).expect("valid file"), &[]) else {
                continue;
            };
            scenes += 1;
            let off = scenario.initial_offsets();
            assert!(off.is_empty(), "{}: starts off {off:?}", path.display());
        }
    }
    assert!(scenes >= 10, "only {scenes} scenes");
}

/// 3D torque expectations are world vectors compared component-wise: the ball joint's
/// torques (Jolt's r × P) pass at their state, and the same file with the torque on `a`
/// turned round fails there while the force on it still passes.
#[test]
fn a_wrong_3d_torque_expectation_fails() {
    let rel = "constraints/joints/ball_3d.toml";
    let text = read(rel);
    let right = "torque = { a = \"cross(rot(q1, s1), ";
    assert!(text.contains(right), "{rel} lost its torque expectation");
    let judge = |text: &str| {
        let mut checked = lagrange::check::Checked::from_text(rel, text).unwrap_or_else(|e| panic!("{e}"));
        checked.run()
    };
    let outcomes = judge(&text);
    assert!(outcomes.iter().any(|o| o.label.starts_with("torque[a]")), "no torque checked");
    assert!(outcomes.iter().all(|o| o.passed), "{outcomes:?}");
    let wrong = text.replace(right, "torque = { a = \"-cross(rot(q1, s1), ");
    for o in judge(&wrong) {
        assert_eq!(o.passed, !o.label.starts_with("torque[a]"), "{o}");
    }
}

/// `lagrange bench` on 3D rigid bodies: the work-precision sweep runs every method on the
/// ball joint and the spinning top, and the formula accuracy has a row per body's force and
/// per rigid body's constraint torque (a world vector, `a (torque)`), each at f64's precision
/// on random states against the double-double solve over the same per-axis slots (measured:
/// medians 2e-16 to 7e-16, worst 8e-13 for the top's torque).
#[test]
fn bench_measures_3d_forces_and_world_torques() {
    for file in ["constraints/joints/ball_3d.toml", "constraints/rigid/spinning_top.toml"] {
        let (code, out, err) = lagrange(&["bench", file, "--duration", "0.05", "--format", "json"]);
        assert_eq!(code, Some(0), "{file}: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
        let rows = v["rows"].as_array().expect("rows");
        assert!(rows.len() >= 36 && rows.iter().all(|r| r["status"] == "ok"), "{file}: {rows:?}");
        let scenario = common::scenario(file);
        let rows = lagrange::precision::accuracy::formula_accuracy(&scenario, 50, 7);
        let rigid = scenario.system.bodies.iter().filter(|b| b.rigid.is_some()).count();
        assert_eq!(rows.len(), 2 * (scenario.system.bodies.len() + rigid), "{file}: a row per force and torque");
        assert_eq!(rows.iter().filter(|r| r.torque).count(), 2 * rigid, "{file}");
        for r in &rows {
            assert!(r.count >= 45, "{file} {} {}: {} states graded", r.body, r.states, r.count);
            assert!(r.median_rel_error < 1e-12, "{file} {} {}: median {:e}", r.body, r.states, r.median_rel_error);
            assert!(r.max_rel_error < 1e-9, "{file} {} {}: max {:e}", r.body, r.states, r.max_rel_error);
        }
    }
}
