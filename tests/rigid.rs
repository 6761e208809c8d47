//! 2D rigid bodies: the language (`rot`, `perp`, vector constraints, the body keys), the
//! canonical forms of `rot` and `perp`, and the derivation's velocity and acceleration
//! identities at random states.
//!
//! The identities (DESIGN.md, "Rigid bodies"): with uᵢ = (vᵢ, ωᵢ),
//! Ċ = κ Σᵢ (Jᵛᵢ·vᵢ + Jʷᵢ ωᵢ) + ∂C/∂t and C̈ = κ (Σᵢ (Jᵛᵢ·aᵢ + Jʷᵢ αᵢ) + c), and both Ċ and C̈
//! agree with central differences of C and Ċ along a trajectory
//! x(t) = x0 + v0 t + ½ a0 t², θ(t) = θ0 + ω0 t + ½ α0 t², for random joint-like constraints
//! (pin, distance between body points, point on a line, weld angle, gear, time-driven).

mod common;

use common::Rng;
use lagrange::derive::derive;
use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::expr::grad::gradient;
use lagrange::expr::print::{Style, print};
use lagrange::expr::{Graph, Id, Role, Simplifier, Ty};
use lagrange::model::file::load;
use lagrange::model::system::{MassSpec, RigidSpec, System, SystemBuilder};

/// Two rigid bodies `b1` (`x1 v1 a1 F1 m1`, `th1 w1 al1 T1 I1`) and `b2`, scalar
/// parameters `k`, `l`, `c`, a vector parameter `n`, and the constraints `(name, text)`.
fn two_rigid(constraints: &[(&str, &str)]) -> Result<System, String> {
    rigid_bodies(2, 2, constraints)
}

/// [`two_rigid`] in `dim` dimensions with `count` bodies `b1` … (3D: `th` is a quaternion,
/// `w`, `al`, `T` and `I` vectors).
fn rigid_bodies(dim: i64, count: usize, constraints: &[(&str, &str)]) -> Result<System, String> {
    let mut b = SystemBuilder::new("rigid bodies", dim).map_err(|e| e.to_string())?;
    for p in ["k", "l", "c"] {
        b.parameter(p, Ty::Scalar).map_err(|e| e.to_string())?;
    }
    b.parameter("n", Ty::Vector).map_err(|e| e.to_string())?;
    for i in 1..=count {
        let names: Vec<String> =
            ["x", "v", "a", "F", "m", "th", "w", "al", "T", "I"].iter().map(|s| format!("{s}{i}")).collect();
        let name = format!("b{i}");
        let body = b
            .body(&common::body(&name, &names[0], &names[1], &names[2], &names[3], &names[4]))
            .map_err(|e| e.to_string())?;
        let spec = RigidSpec {
            orientation: &names[5],
            angular_velocity: &names[6],
            angular_acceleration: &names[7],
            torque: &names[8],
            inertia: MassSpec::Symbol(&names[9]),
        };
        b.rigid(body, &spec).map_err(|e| e.to_string())?;
    }
    for (name, text) in constraints {
        b.constraint(name, text).map_err(|e| e.to_string())?;
    }
    Ok(b.finish())
}

fn num(g: &Graph, id: Id, env: &Env) -> Vec<f64> {
    match eval_one(g, id, env) {
        Ok(Value::Scalar(x)) => vec![x],
        Ok(Value::Vector(v)) => v[..g.dim()].to_vec(),
        Ok(Value::Quaternion(q)) => q.to_vec(),
        Err(e) => panic!("evaluation failed: {e}"),
    }
}

fn scalar(g: &Graph, id: Id, env: &Env) -> f64 {
    num(g, id, env)[0]
}

/// A random state: vectors in [-1, 1)², scalars (angles, rates, parameters, masses) in
/// [0.5, 2), `t` in [-1, 1).
fn random_state(system: &System, rng: &mut Rng) -> Env {
    common::random_env(system, rng)
}

/// `env` moved along the trajectory by `h`: positions and angles by their second-order
/// Taylor step, velocities and angular velocities by their first, `t` by `h`.
fn along(system: &System, env: &Env, h: f64) -> Env {
    let g = &system.graph;
    let mut out = env.clone();
    for b in &system.bodies {
        let pairs = [(b.position, b.velocity, b.acceleration)];
        let rigid = b.rigid.as_ref().map(|r| (r.orientation, r.angular_velocity, r.angular_acceleration));
        for (x, v, a) in pairs.into_iter().chain(rigid) {
            let (Some(x0), Some(v0), Some(a0)) = (env.get(x), env.get(v), env.get(a)) else { continue };
            let step = |x: f64, v: f64, a: f64| (x + v * h + 0.5 * a * h * h, v + a * h);
            match (x0, v0, a0) {
                (Value::Scalar(x0), Value::Scalar(v0), Value::Scalar(a0)) => {
                    let (x1, v1) = step(x0, v0, a0);
                    out.set(x, Value::Scalar(x1));
                    out.set(v, Value::Scalar(v1));
                }
                (Value::Vector(x0), Value::Vector(v0), Value::Vector(a0)) => {
                    let (mut x1, mut v1) = ([0.0; 3], [0.0; 3]);
                    for k in 0..g.dim() {
                        (x1[k], v1[k]) = step(x0[k], v0[k], a0[k]);
                    }
                    out.set(x, Value::Vector(x1));
                    out.set(v, Value::Vector(v1));
                }
                _ => panic!("mixed types"),
            }
        }
    }
    let t = env.get(system.time).and_then(Value::scalar).unwrap_or(0.0);
    out.set(system.time, Value::Scalar(t + h));
    out
}

fn close(x: f64, y: f64, tol: f64) -> bool {
    (x - y).abs() <= tol * x.abs().max(y.abs()).max(1.0)
}

/// Joint-like constraints between the two bodies, with body-frame vectors written as
/// literals (random numbers) and parameters.
fn joints(rng: &mut Rng) -> Vec<String> {
    let mut p = || format!("{:.3}", rng.uniform(-1.0, 1.0));
    let (s1, s2) = (format!("[{}, {}]", p(), p()), format!("[{}, {}]", p(), p()));
    let (d1, d2) = (format!("[{}, {}]", p(), p()), format!("[{}*k, {}]", p(), p()));
    let a1 = format!("x1 + rot(th1, {s1})");
    let a2 = format!("x2 + rot(th2, {s2})");
    vec![
        // revolute (a vector constraint: two rows)
        format!("{a1} = {a2}"),
        // distance between body points
        format!("dot({a2} - ({a1}), {a2} - ({a1})) = l^2"),
        // point on a line fixed in body 1 (prismatic / wheel)
        format!("dot({a2} - ({a1}), rot(th1, {d1})) = 0"),
        format!("cross(rot(th1, {d2}), {a2} - ({a1})) = 0"),
        // weld angle, gear
        "th2 - th1 = c".to_string(),
        "k*th1 + l*th2 = 0".to_string(),
        // a body point driven in time, and perp of a body vector
        format!("({a1}).y = c*sin(k*t)"),
        format!("dot(perp(rot(th2, {s2})), x1 - x2) = l + n.x*t"),
    ]
}

#[test]
fn derived_rigid_constraints_satisfy_the_velocity_and_acceleration_identities() {
    let mut rng = Rng::new(0x005e_ed2d);
    let mut checked = 0;
    for round in 0..6 {
        for (i, text) in joints(&mut rng).into_iter().enumerate() {
            let name = format!("j{round}_{i}");
            let system = two_rigid(&[(&name, &text)]).unwrap_or_else(|e| panic!("{text}: {e}"));
            let mut d = derive(&system).unwrap_or_else(|e| panic!("{text}: {e}"));
            for (k, c) in system.constraints.iter().enumerate() {
                let dc = d.constraints[k].clone();
                let g = &mut d.graph;
                // ∂C/∂t, for Ċ = κ Σ (J·v + Jʷ ω) + ∂C/∂t.
                let dt = gradient(g, dc.c, system.time).expect("gradient in t");
                let kappa = dc.scale.to_f64();
                for _ in 0..20 {
                    let env = random_state(&system, &mut rng);
                    let g = &d.graph;
                    let mut rate = scalar(g, dt, &env);
                    let mut accel = scalar(g, dc.bias, &env);
                    for &(body, j) in &dc.jacobian {
                        let b = &system.bodies[body];
                        let jv = num(g, j, &env);
                        let (v, a) = (num(g, b.nodes.velocity, &env), num(g, b.nodes.acceleration, &env));
                        rate += kappa * (jv[0] * v[0] + jv[1] * v[1]);
                        accel += jv[0] * a[0] + jv[1] * a[1];
                    }
                    for &(body, j) in &dc.angular {
                        let r = system.bodies[body].rigid.as_ref().expect("a rigid body");
                        let jw = scalar(g, j, &env);
                        rate += kappa * jw * scalar(g, r.nodes.angular_velocity, &env);
                        accel += jw * scalar(g, r.nodes.angular_acceleration, &env);
                    }
                    let c_dot = scalar(g, dc.c_dot, &env);
                    let c_ddot = scalar(g, dc.c_ddot, &env);
                    assert!(close(rate, c_dot, 1e-10), "{}: Ċ = {c_dot}, J·u + ∂C/∂t = {rate}", c.name);
                    assert!(
                        close(kappa * accel, c_ddot, 1e-10),
                        "{}: C̈ = {c_ddot}, κ(J·u̇ + c) = {}",
                        c.name,
                        kappa * accel
                    );
                    // Central differences along the trajectory.
                    let h = 1e-5;
                    let (ahead, behind) = (along(&system, &env, h), along(&system, &env, -h));
                    let fd_rate = (scalar(g, dc.c, &ahead) - scalar(g, dc.c, &behind)) / (2.0 * h);
                    let fd_accel = (scalar(g, dc.c_dot, &ahead) - scalar(g, dc.c_dot, &behind)) / (2.0 * h);
                    assert!(
                        close(fd_rate, c_dot, 1e-6),
                        "{} ({text}): Ċ = {c_dot}, finite difference {fd_rate}",
                        c.name
                    );
                    assert!(
                        close(fd_accel, c_ddot, 1e-6),
                        "{} ({text}): C̈ = {c_ddot}, finite difference {fd_accel}",
                        c.name
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked >= 6 * 9 * 20, "checked {checked} states");
}

/// A constraint that repeats another on other bodies (the next joint of a chain or grid)
/// is derived by renaming the earlier derivation (`expr::shape`), its turning parts
/// included: what comes out must be what deriving it alone gives, printed the same, for the
/// joints above in 2D and joints through `rot(q, s)` in 3D, whether the renaming keeps the
/// bodies' order (`b1, b2` → `b3, b4`) or reverses it (→ `b4, b3`).
#[test]
fn a_repeated_rigid_joint_derives_as_if_it_were_alone() {
    let mut rng = Rng::new(0x0005_a3e5);
    let mut p = || format!("{:.3}", rng.uniform(-1.0, 1.0));
    let three = |p: &mut dyn FnMut() -> String| format!("[{}, {}, {}]", p(), p(), p());
    let (s1, s2, d1) = (three(&mut p), three(&mut p), three(&mut p));
    let mut cases: Vec<(i64, String)> = joints(&mut Rng::new(0x0005_a3e6)).into_iter().map(|j| (2, j)).collect();
    cases.extend(
        [
            // ball joint, a distance between body points, a hinge's axis kept normal
            format!("x1 + rot(th1, {s1}) = x2 + rot(th2, {s2})"),
            format!("dot(x2 + rot(th2, {s2}) - x1, x2 + rot(th2, {s2}) - x1) = l^2"),
            format!("dot(rot(th1, {d1}), rot(th2, [0, 0, 1])) = 0"),
        ]
        .map(|j| (3, j)),
    );
    let show = |d: &lagrange::derive::Derivation, id: Id| print(&d.graph, id, Style::Source).unwrap_or_default();
    // Everything derived for constraint `first`.. of `d`, printed, with the bodies' names.
    let fields = |d: &lagrange::derive::Derivation, system: &System, first: usize| {
        let mut out = Vec::new();
        for k in first..d.constraints.len() {
            let dc = &d.constraints[k];
            for id in [dc.c, dc.c_dot_raw, dc.c_dot, dc.c_ddot_raw, dc.c_ddot, dc.bias, d.b[k]] {
                out.push(show(d, id));
            }
            out.push(dc.scale.to_string());
            out.push(d.a_entry(k, k).map(|a| show(d, a)).unwrap_or_default());
            for parts in [&dc.gradient, &dc.jacobian, &dc.angular_gradient, &dc.angular] {
                for &(body, e) in parts {
                    out.push(format!("{}: {}", system.bodies[body].name, show(d, e)));
                }
            }
        }
        out
    };
    let mut compared = 0;
    for (dim, text) in &cases {
        for (x, y) in [("3", "4"), ("4", "3")] {
            let renamed = renamed_bodies(text, x, y);
            let alone = rigid_bodies(*dim, 4, &[("j", &renamed)]).unwrap_or_else(|e| panic!("{renamed}: {e}"));
            let one = derive(&alone).unwrap_or_else(|e| panic!("{renamed}: {e}"));
            let together = rigid_bodies(*dim, 4, &[("i", text), ("j", &renamed)]).expect("two joints");
            let both = derive(&together).unwrap_or_else(|e| panic!("{text}: {e}"));
            let rows = one.constraints.len();
            assert_eq!(both.constraints.len(), 2 * rows, "{text}");
            assert_eq!(fields(&both, &together, rows), fields(&one, &alone, 0), "{text} then {renamed}");
            compared += 1;
        }
    }
    assert_eq!(compared, 2 * cases.len());
}

/// `text` with body 1's symbols renamed to body `x`'s and body 2's to body `y`'s (a digit
/// after a letter of a body symbol: `x1`, `th2`, …).
fn renamed_bodies(text: &str, x: &str, y: &str) -> String {
    let mut out = String::new();
    let mut previous = ' ';
    for ch in text.chars() {
        let renamed = match ch {
            '1' if previous.is_ascii_alphabetic() => x,
            '2' if previous.is_ascii_alphabetic() => y,
            _ => {
                out.push(ch);
                previous = ch;
                continue;
            }
        };
        out.push_str(renamed);
        previous = ch;
    }
    out
}

/// The simplified form of `text` in the two-body system, printed.
fn simplified(text: &str) -> String {
    let mut system = two_rigid(&[]).expect("system");
    let id = system.expression(text).unwrap_or_else(|e| panic!("{text}: {e}"));
    let mut s = Simplifier::new();
    let id = s.simplify(&mut system.graph, id).expect("simplify");
    print(&system.graph, id, Style::Text).expect("print")
}

/// Whether `a` and `b` have one canonical form.
fn equivalent(a: &str, b: &str) -> bool {
    let mut system = two_rigid(&[]).expect("system");
    let (x, y) = (system.expression(a).expect("a"), system.expression(b).expect("b"));
    let mut s = Simplifier::new();
    s.equivalent(&mut system.graph, x, y).expect("equivalent")
}

#[test]
fn rot_and_perp_have_the_engines_identities_as_canonical_forms() {
    // perp(perp(u)) = −u, u·perp(u) = 0
    assert!(equivalent("perp(perp(x1))", "-x1"));
    assert_eq!(simplified("dot(x1, perp(x1))"), "0");
    assert_eq!(simplified("dot(rot(th1, n), perp(rot(th1, n)))"), "0");
    // rot(θ,u)·rot(θ,w) = u·w, and a rotation keeps lengths
    assert!(equivalent("dot(rot(th1, n), rot(th1, [k, 1]))", "dot(n, [k, 1])"));
    assert!(equivalent("dot(rot(th1, n), rot(th1, n))", "dot(n, n)"));
    // cross of rotated vectors: rot(θ,u) × rot(θ,w) = u × w
    assert!(equivalent("cross(rot(th1, n), rot(th1, [0, l]))", "l*n.x"));
    // perp(p)·q = p × q and p × perp(q) = p·q (Box2D's b2Cross, b2LeftPerp)
    assert!(equivalent("dot(perp(x1), x2)", "cross(x1, x2)"));
    assert!(equivalent("cross(x1, perp(x2))", "dot(x1, x2)"));
    // rot is linear in its body-frame vector, and rot(θ, e_y) = perp(rot(θ, e_x))
    assert!(equivalent("rot(th1, [k, l])", "k*rot(th1, [1, 0]) + l*perp(rot(th1, [1, 0]))"));
    assert!(equivalent("rot(th1, perp(n))", "perp(rot(th1, n))"));
    // components are the rotation matrix's rows
    assert!(equivalent("rot(th1, [1, 0]).x", "cos(th1)"));
    assert!(equivalent("rot(th1, n).y", "n.x*sin(th1) + n.y*cos(th1)"));
    // different angles do not cancel
    assert!(!equivalent("dot(rot(th1, n), rot(th2, n))", "dot(n, n)"));
}

#[test]
fn d_dt_of_a_body_point_is_omega_perp() {
    let system = two_rigid(&[("p", "dot(x1 + rot(th1, n), x1 + rot(th1, n)) = l^2")]).expect("system");
    let d = derive(&system).expect("derive");
    let text = |id: Id| print(&d.graph, id, Style::Text).expect("print");
    // Ċ = 2 (x + r)·(v + ω perp(r)), r = rot(th1, n), collected: (x + r)·perp(r) = x·perp(r)
    // = r × x (r·perp(r) = 0), the lever arm's cross product.
    assert_eq!(text(d.constraints[0].c_dot), "−2 (w1 x1×rot(th1, n) − (x1 + rot(th1, n))·v1)");
    // Jʷ = ∂C/∂θ / κ (κ = 2): the same cross product, the coefficient of w1.
    assert_eq!(text(d.constraints[0].angular[0].1), "−x1×rot(th1, n)");
}

#[test]
fn a_vector_constraint_is_one_equality_per_component() {
    let system = two_rigid(&[("pin", "x1 + rot(th1, n) = x2")]).expect("system");
    let names: Vec<&str> = system.constraints.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["pin.x", "pin.y"]);
    assert!(system.constraints.iter().all(|c| !c.inequality && c.bodies == [0, 1]));
    // Only `=` between vectors.
    let err = two_rigid(&[("pin", "x1 + rot(th1, n) <= x2")]).expect_err("a vector inequality");
    assert!(err.contains("only `=` relates vectors"), "{err}");
}

/// The rod pinned at one end: A is the revolute joint's 2×2 K (Box2D v3
/// `revolute_joint.c`: K = [[1/m + r_y²/I, −r_x r_y/I], [−r_x r_y/I, 1/m + r_x²/I]] with
/// r = rot(th, s) the pin's lever arm from the centre of mass), and the torque on the rod
/// is r × F_c = r.x F_c.y − r.y F_c.x.
#[test]
fn the_pinned_rod_derives_the_revolute_k_and_the_torque_r_cross_f() {
    let text = std::fs::read_to_string("constraints/rigid/rod_pinned.toml").expect("rod_pinned.toml");
    let loaded = load(&text).unwrap_or_else(|p| panic!("{p:?}"));
    let system = loaded.system;
    let options = lagrange::derive::Options { document: true, steps: false };
    let d = lagrange::derive::derive_with(&system, options).expect("derive");
    let (mut g, mut s) = (d.graph, d.simplifier);
    let mut scope = system.scope.clone();
    for name in ["lambda_pin_x", "lambda_pin_y"] {
        let symbol = g.symbol_named(name).expect("the multiplier symbols");
        scope.insert(name, g.sym(symbol));
    }
    let parse = |g: &mut Graph, t: &str| {
        let syntax = lagrange::expr::parse::parse_expr(t).expect("parse");
        lagrange::expr::lower::lower(&syntax, &scope, g).expect("lower")
    };
    for (k, j, text) in
        [(0, 0, "1/m + (rot(th, s).y)^2/I"), (0, 1, "-rot(th, s).x*rot(th, s).y/I"), (1, 1, "1/m + (rot(th, s).x)^2/I")]
    {
        let entry = d.a.iter().find(|e| e.0 == k && e.1 == j).map(|e| e.2).expect("an entry of A");
        let expected = parse(&mut g, text);
        assert!(s.equivalent(&mut g, entry, expected).expect("equivalent"), "A[{k},{j}] is not {text}");
    }
    let sums = d.torque_sums.expect("torque sums");
    assert_eq!(sums.len(), 1);
    let expected = parse(&mut g, "rot(th, s).x*lambda_pin_y - rot(th, s).y*lambda_pin_x");
    assert!(s.equivalent(&mut g, sums[0].1, expected).expect("equivalent"), "the torque is not r × F_c");
    let rigid = system.bodies[0].rigid.as_ref().expect("rigid");
    assert!(matches!(g.symbol(rigid.orientation).role, Role::Orientation { body: 0 }));
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

/// `derive` of every file in `constraints/joints/` and `constraints/rigid/`, in every format with and without
/// `--steps`, pinned as snapshots (the outputs of `tests/outputs.rs`, for files the other
/// commands do not handle yet). LaTeX is ASCII, so it compiles.
#[test]
fn every_rigid_file_derives_in_every_format() {
    let files = common::rigid_files();
    assert!(!files.is_empty());
    for rel in &files {
        let stem = rel.rsplit('/').next().unwrap_or(rel).trim_end_matches(".toml");
        for format in ["text", "latex", "markdown", "json"] {
            for steps in [false, true] {
                if steps && format == "json" {
                    continue;
                }
                let mut args = vec!["derive", rel.as_str(), "--format", format];
                if steps {
                    args.push("--steps");
                }
                let (code, out, err) = lagrange(&args);
                assert_eq!(code, Some(0), "lagrange {args:?} failed:\n{err}");
                if format == "latex" {
                    assert!(out.is_ascii(), "{rel}: LaTeX is not ASCII");
                }
                if format == "json" {
                    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
                    let constraints = v["constraints"].as_array().expect("constraints");
                    let turning = constraints.iter().any(|c| c["angular_gradient"].is_object());
                    assert!(turning, "{rel}: no constraint has an angular_gradient");
                }
                let name = format!("{stem}__derive_{format}{}", if steps { "_steps" } else { "" });
                insta::assert_snapshot!(name, out);
            }
        }
    }
}

/// `generate --solver` writes the velocity-level step for rigid bodies too, in Rust and C,
/// with their angular slots in the step's rows (`tests/generate_step.rs` and
/// `tests/generate_c.rs` hold its numbers to the library's and to each other).
#[test]
fn generate_writes_the_step_of_rigid_bodies() {
    let rel = "constraints/rigid/rod_pinned.toml";
    for lang in ["rust", "c"] {
        for solver in ["soft-step", "pgs", "exact"] {
            let args = ["generate", rel, "--lang", lang, "--solver", solver];
            let (code, out, err) = lagrange(&args);
            assert_eq!(code, Some(0), "lagrange {args:?}:\n{err}");
            assert!(out.contains("step_with(") && out.contains("SLOTS"), "lagrange {args:?}: no step");
        }
    }
}

/// Evaluates `expected` (parsed into the derivation's graph) and `derived` at random
/// states of `system` and asserts they agree.
fn agrees_at_random_states(system: &System, g: &mut Graph, derived: Id, expected: &str, what: &str) {
    let syntax = lagrange::expr::parse::parse_expr(expected).expect("parse");
    let expected_id = lagrange::expr::lower::lower(&syntax, &system.scope, g).expect("lower");
    let mut rng = Rng::new(0x00d1_57a7);
    for _ in 0..50 {
        let env = random_state(system, &mut rng);
        let (x, y) = (num(g, derived, &env), num(g, expected_id, &env));
        for (a, b) in x.iter().zip(&y) {
            assert!(close(*a, *b, 1e-10), "{what}: derived {a}, expected {b} ({expected})");
        }
    }
}

/// The distance joint between two body points (Box2D v3 `distance_joint.c`, its comment:
/// u = (p2 − p1)/|p2 − p1|, J = [−u, −cross(r1, u), u, cross(r2, u)],
/// K = 1/m1 + 1/I1 cross(r1, u)² + 1/m2 + 1/I2 cross(r2, u)²): Jʷ and A are the engine's.
#[test]
fn the_distance_joint_derives_box2d_s_j_and_k() {
    let pa = "x1 + rot(th1, n)";
    let pb = "x2 + rot(th2, [k, c])";
    let text = format!("norm({pb} - ({pa})) = l");
    let system = two_rigid(&[("rope", &text)]).expect("system");
    let d = derive(&system).expect("derive");
    let dc = d.constraints[0].clone();
    let mut g = d.graph;
    let u = format!("({pb} - ({pa}))/norm({pb} - ({pa}))");
    let (r1, r2) = ("rot(th1, n)", "rot(th2, [k, c])");
    assert!(dc.scale.is_one());
    let jw = |body: usize| dc.angular.iter().find(|e| e.0 == body).map(|e| e.1).expect("an angular part");
    agrees_at_random_states(&system, &mut g, jw(0), &format!("-cross({r1}, {u})"), "Jʷ of body 1");
    agrees_at_random_states(&system, &mut g, jw(1), &format!("cross({r2}, {u})"), "Jʷ of body 2");
    let k = format!("1/m1 + cross({r1}, {u})^2/I1 + 1/m2 + cross({r2}, {u})^2/I2");
    agrees_at_random_states(&system, &mut g, d.a[0].2, &k, "K");
}
