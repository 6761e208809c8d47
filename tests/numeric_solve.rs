//! The numeric solve against independent answers: closed forms worked out here, at easy and
//! hard states (redundant, singular, tiny, huge, mass ratio 1e9, speed 1e8), floors and
//! ropes, every file of `constraints/`, and random contact sets (complementarity).
//! Solver tests check the status first, then the numbers.

use lagrange::derive::{Derivation, derive};
use lagrange::model::file::{Loaded, load};
use lagrange::model::raw::RawValue;
use lagrange::model::scene::environment;
use lagrange::model::state;
use lagrange::numeric::contact::{ContactState, impulses};
use lagrange::numeric::qp::{QpStatus, solve_qp};
use lagrange::numeric::rows::{Row, RowProgram, Rows};
use lagrange::numeric::solve::{Diagnostic, Settings, Solution, Status, solve, solve_with};
use proptest::prelude::*;

struct Setup {
    loaded: Loaded,
    program: RowProgram,
    _derivation: Derivation,
}

fn setup(text: &str) -> Setup {
    setup_given_forces(text, &[])
}

/// A setup where the bodies with these force symbols take the force from the state, not
/// from `[scene] forces` (as `lagrange solve --set F=…` does).
fn setup_given_forces(text: &str, given: &[&str]) -> Setup {
    let loaded = load(text).expect("valid file");
    let derivation = derive(&loaded.system).expect("derives");
    let system = &loaded.system;
    let forces: Vec<_> = loaded
        .scene
        .forces
        .iter()
        .copied()
        .filter(|&(b, _)| !given.contains(&system.graph.symbol(system.bodies[b].force).name.as_str()))
        .collect();
    let program = RowProgram::new(system, &derivation, &forces);
    Setup { loaded, program, _derivation: derivation }
}

fn v(x: &[f64]) -> RawValue {
    RawValue::Vector(x.to_vec())
}

fn s(x: f64) -> RawValue {
    RawValue::Number(x)
}

impl Setup {
    fn rows(&self, overrides: &[(&str, RawValue)]) -> Rows {
        let o = state::values(&self.loaded.system, overrides).expect("values of the file's symbols");
        let env = environment(&self.loaded.system, &self.loaded.values, &self.loaded.scene, &o).expect("state");
        self.program.evaluate(&self.loaded.system, &env).expect("rows")
    }
}

/// ‖got − want‖ ≤ rel · scale, componentwise over the first `dim` components.
fn assert_close(got: &[f64; 3], want: &[f64], rel: f64, scale: f64, what: &str) {
    let err = want.iter().enumerate().map(|(d, w)| (got[d] - w).abs()).fold(0.0, f64::max);
    assert!(err <= rel * scale, "{what}: got {got:?}, want {want:?} (error {err:e}, allowed {:e})", rel * scale);
}

fn norm(x: &[f64]) -> f64 {
    let big = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if big == 0.0 {
        return 0.0;
    }
    big * x.iter().map(|v| (v / big) * (v / big)).sum::<f64>().sqrt()
}

const BEAD: &str = r#"
dimension = 2
[parameters]
l = 2.0
m = 1.0
g = [0.0, -9.81]
[[bodies]]
name = "bead"
position = "r"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"
[[constraints]]
name = "wire"
expr = "dot(r,r) = l^2"
[scene]
initial = { r = [2.0, 0.0], v = [0.0, 1.0] }
forces = { F = "m*g" }
"#;

/// The article's force, written so it neither overflows nor underflows: with r̂ = r/|r|,
/// F_c = −(m v·v + F·r)/(r·r) r = −(m |v|²/|r| + F·r̂) r̂.
fn article_force(m: f64, r: &[f64; 2], vel: &[f64; 2], f: &[f64; 2]) -> [f64; 2] {
    let len = norm(r);
    let u = [r[0] / len, r[1] / len];
    let speed = norm(vel);
    let magnitude = -(m * (speed / len) * speed + (f[0] * u[0] + f[1] * u[1]));
    [magnitude * u[0], magnitude * u[1]]
}

/// The bead at radius `l` and angle θ with tangential speed `speed`, l given as a parameter.
fn bead_case(l: f64, speed: f64, theta: f64) {
    let setup = setup(BEAD);
    let r = [l * theta.cos(), l * theta.sin()];
    let vel = [-speed * theta.sin(), speed * theta.cos()];
    let rows = setup.rows(&[("l", s(l)), ("r", v(&r)), ("v", v(&vel))]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Solved, "l = {l:e}, speed = {speed:e}: {:?}", sol.diagnostics);
    let want = article_force(1.0, &r, &vel, &[0.0, -9.81]);
    assert_close(&sol.constraint_force[0], &want, 1e-9, norm(&want), &format!("bead l = {l:e}, speed = {speed:e}"));
    for x in sol.constraint_force[0].iter().chain(&sol.acceleration[0]).chain(&sol.lambda) {
        assert!(x.is_finite());
    }
}

#[test]
fn bead_at_ordinary_tiny_and_huge_scales_and_high_speed() {
    for (l, speeds) in [
        (2.0, vec![0.0, 1.0, 3.7, 1e8]),
        (1e-8, vec![0.0, 1e-8, 3e-4]),
        (1e-150, vec![0.0, 1e-150, 2e-76]),
        (1e155, vec![0.0, 1.0, 1e8, 1e80]),
    ] {
        for speed in speeds {
            for theta in [0.0, 0.7, 2.0, 4.1] {
                bead_case(l, speed, theta);
            }
        }
    }
}

#[test]
fn same_constraint_twice_is_redundant_with_the_same_force() {
    let text = BEAD.replace(
        "expr = \"dot(r,r) = l^2\"",
        "expr = \"dot(r,r) = l^2\"\n[[constraints]]\nname = \"again\"\nexpr = \"dot(r,r) = l^2\"",
    );
    let setup = setup(&text);
    let (r, vel) = ([1.2, -1.6], [1.6, 1.2]);
    let rows = setup.rows(&[("r", v(&r)), ("v", v(&vel))]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::MinimumNorm);
    assert!(
        sol.diagnostics.iter().any(
            |d| matches!(d, Diagnostic::Redundant { constraints, rank: 1, size: 2, .. } if *constraints == [0, 1])
        )
    );
    let want = article_force(1.0, &r, &vel, &[0.0, -9.81]);
    assert_close(&sol.constraint_force[0], &want, 1e-9, norm(&want), "redundant bead");
    // Minimum norm splits the load equally.
    assert!((sol.lambda[0] - sol.lambda[1]).abs() <= 1e-9 * sol.lambda[0].abs());
}

#[test]
fn bead_at_the_centre_is_a_singular_configuration() {
    let setup = setup(BEAD);
    let rows = setup.rows(&[("r", v(&[0.0, 0.0])), ("v", v(&[0.0, 1.0]))]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Singular);
    assert!(sol.diagnostics.iter().any(|d| matches!(d, Diagnostic::ZeroGradient { constraint: 0, .. })));
    assert_eq!(sol.lambda, vec![0.0]);
    assert_close(&sol.acceleration[0], &[0.0, -9.81], 1e-15, 9.81, "free fall at the centre");
}

const TRIANGLE: &str = r#"
# An equilateral triangle of rods pinned at p1, p2 on the x axis, and p3's x fixed as well:
# 7 constraints on 6 coordinates, one redundant.
dimension = 2
[parameters]
l = 1.0
m1 = 1.0
m2 = 2.0
m3 = 3.0
g = [0.0, -9.81]
[[bodies]]
name = "p1"
position = "r1"
velocity = "v1"
acceleration = "a1"
mass = "m1"
force = "F1"
[[bodies]]
name = "p2"
position = "r2"
velocity = "v2"
acceleration = "a2"
mass = "m2"
force = "F2"
[[bodies]]
name = "p3"
position = "r3"
velocity = "v3"
acceleration = "a3"
mass = "m3"
force = "F3"
[[constraints]]
name = "pin_x"
expr = "r1.x = 0"
[[constraints]]
name = "pin_y"
expr = "r1.y = 0"
[[constraints]]
name = "roller"
expr = "r2.y = 0"
[[constraints]]
name = "rod12"
expr = "dot(r2 - r1, r2 - r1) = l^2"
[[constraints]]
name = "rod23"
expr = "dot(r3 - r2, r3 - r2) = l^2"
[[constraints]]
name = "rod31"
expr = "dot(r1 - r3, r1 - r3) = l^2"
[[constraints]]
name = "apex"
expr = "r3.x = l/2"
[scene]
initial = { r1 = [0.0, 0.0], v1 = [0.0, 0.0], r2 = [1.0, 0.0], v2 = [0.0, 0.0], r3 = [0.5, 0.8660254037844386], v3 = [0.0, 0.0] }
forces = { F1 = "m1*g", F2 = "m2*g", F3 = "m3*g" }
"#;

#[test]
fn over_constrained_triangle_holds_still_with_minimum_norm_multipliers() {
    let setup = setup(TRIANGLE);
    let rows = setup.rows(&[]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::MinimumNorm, "{:?}", sol.diagnostics);
    assert!(
        sol.diagnostics.iter().any(
            |d| matches!(d, Diagnostic::Redundant { constraints, rank: 6, size: 7, .. } if constraints.contains(&6))
        )
    );
    // Independent answer: the structure cannot move, so every constraint force cancels gravity.
    for (i, m) in [1.0, 2.0, 3.0].iter().enumerate() {
        assert_close(&sol.constraint_force[i], &[0.0, 9.81 * m], 1e-9, 9.81 * m, "triangle force");
        assert_close(&sol.acceleration[i], &[0.0, 0.0], 1e-9, 9.81, "triangle at rest");
    }
}

const DOUBLE: &str = r#"
dimension = 2
[parameters]
l1 = 1.0
l2 = 1.5
m1 = 1.0
m2 = 2.0
g = [0.0, -9.81]
[[bodies]]
name = "upper"
position = "r1"
velocity = "v1"
acceleration = "a1"
mass = "m1"
force = "F1"
[[bodies]]
name = "lower"
position = "r2"
velocity = "v2"
acceleration = "a2"
mass = "m2"
force = "F2"
[[constraints]]
name = "rod1"
expr = "dot(r1, r1) = l1^2"
[[constraints]]
name = "rod2"
expr = "dot(r2 - r1, r2 - r1) = l2^2"
[scene]
forces = { F1 = "m1*g", F2 = "m2*g" }
"#;

/// The double pendulum's forces by Cramer's rule on the 2×2 system written out by hand:
/// J₁ = r₁ on body 1; J₂ = −d on body 1 and d on body 2 (d = r₂ − r₁);
/// A = [[r₁·r₁/m₁, −r₁·d/m₁], [·, d·d (1/m₁ + 1/m₂)]], b = [r₁·g + v₁·v₁, d·(g − g) + u·u].
fn double_pendulum_forces(m1: f64, m2: f64, r1: [f64; 2], r2: [f64; 2], v1: [f64; 2], v2: [f64; 2]) -> [[f64; 2]; 2] {
    let dot = |a: [f64; 2], b: [f64; 2]| a[0] * b[0] + a[1] * b[1];
    let d = [r2[0] - r1[0], r2[1] - r1[1]];
    let u = [v2[0] - v1[0], v2[1] - v1[1]];
    let g = [0.0, -9.81];
    let (a11, a12, a22) = (dot(r1, r1) / m1, -dot(r1, d) / m1, dot(d, d) * (1.0 / m1 + 1.0 / m2));
    let (b1, b2) = (dot(r1, g) + dot(v1, v1), dot(u, u));
    let det = a11 * a22 - a12 * a12;
    let l1 = (-b1 * a22 + b2 * a12) / det;
    let l2 = (-b2 * a11 + b1 * a12) / det;
    [[l1 * r1[0] - l2 * d[0], l1 * r1[1] - l2 * d[1]], [l2 * d[0], l2 * d[1]]]
}

#[test]
fn two_links_with_mass_ratio_1e9_either_way() {
    let setup = setup(DOUBLE);
    // Rods at 60° to each other, both moving.
    let (t1, t2) = (-0.4f64, -0.4f64 + std::f64::consts::FRAC_PI_3);
    let r1 = [t1.cos(), t1.sin()];
    let r2 = [r1[0] + 1.5 * t2.cos(), r1[1] + 1.5 * t2.sin()];
    let (v1, v2) = ([0.3 * -t1.sin(), 0.3 * t1.cos()], [0.3 * -t1.sin() + 0.5, 0.3 * t1.cos() - 0.2]);
    for (m1, m2) in [(1.0, 1e9), (1e9, 1.0), (1.0, 2.0)] {
        let rows =
            setup.rows(&[("m1", s(m1)), ("m2", s(m2)), ("r1", v(&r1)), ("r2", v(&r2)), ("v1", v(&v1)), ("v2", v(&v2))]);
        let sol = solve(&rows);
        assert_eq!(sol.status, Status::Solved, "m1 = {m1:e}, m2 = {m2:e}: {:?}", sol.diagnostics);
        let want = double_pendulum_forces(m1, m2, r1, r2, v1, v2);
        let scale = norm(&want[0]).max(norm(&want[1]));
        for (i, w) in want.iter().enumerate() {
            assert_close(&sol.constraint_force[i], w, 1e-9, scale, &format!("body {i}, m1 = {m1:e}, m2 = {m2:e}"));
        }
    }
}

fn file_setup(path: &std::path::Path) -> Setup {
    let text = std::fs::read_to_string(path).expect("readable");
    setup(&text)
}

/// C̈/κ = Σᵢ Jᵢ·aᵢ + c per row, for the solution's accelerations.
fn c_ddot(rows: &Rows, sol: &Solution) -> Vec<f64> {
    rows.rows
        .iter()
        .map(|row| {
            row.jacobian.iter().map(|(b, j)| (0..3).map(|d| j[d] * sol.acceleration[*b][d]).sum::<f64>()).sum::<f64>()
                + row.bias
        })
        .collect()
}

#[test]
fn every_constraint_file_solves_at_its_scene_state() {
    let mut seen = 0;
    for entry in std::fs::read_dir("constraints").expect("constraints/") {
        let path = entry.expect("entry").path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        seen += 1;
        let setup = file_setup(&path);
        let rows = setup.rows(&[]);
        let sol = solve(&rows);
        assert_eq!(sol.status, Status::Solved, "{}: {:?}", path.display(), sol.diagnostics);
        // C̈ = 0 on equalities and complementarity on inequalities, relative to the row's size.
        for (k, (row, cdd)) in rows.rows.iter().zip(c_ddot(&rows, &sol)).enumerate() {
            let jn = norm(&row.jacobian.iter().flat_map(|(_, j)| j.to_vec()).collect::<Vec<_>>());
            let size = jn * rows.force.iter().map(|f| norm(f)).fold(0.0, f64::max) * 10.0 + row.bias.abs() + 1.0;
            if row.inequality {
                assert!(sol.lambda[k] >= 0.0 && cdd >= -1e-9 * size, "{}: row {k}", path.display());
                assert!((sol.lambda[k] * cdd).abs() <= 1e-9 * size * sol.lambda[k].abs().max(1.0));
            } else {
                assert!(cdd.abs() <= 1e-9 * size, "{}: row {k} C̈ = {cdd}", path.display());
            }
        }
    }
    assert!(seen >= 6);
}

#[test]
fn bead_files_match_the_article_at_their_scene_state() {
    for (file, r, vel) in [
        ("constraints/bead_on_wire.toml", [2.0, 0.0], [0.0, 1.0]),
        ("constraints/rope_pendulum.toml", [0.0, -2.0], [1.0, 0.0]),
    ] {
        let setup = file_setup(std::path::Path::new(file));
        let sol = solve(&setup.rows(&[]));
        assert_eq!(sol.status, Status::Solved);
        let want = article_force(1.0, &r, &vel, &[0.0, -9.81]);
        assert_close(&sol.constraint_force[0], &want, 1e-12, norm(&want), file);
    }
}

#[test]
fn floor_rests_lifts_off_and_reports_closing_contacts() {
    let setup = file_setup(std::path::Path::new("constraints/floor_rest.toml"));
    // Resting: λ = m g, no acceleration.
    let rows = setup.rows(&[("m", s(3.0)), ("r", v(&[0.5, 0.0])), ("v", v(&[2.0, 0.0]))]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Solved);
    assert_eq!(sol.contacts[0], Some(ContactState::Resting));
    assert!((sol.lambda[0] - 3.0 * 9.81).abs() <= 1e-12 * 3.0 * 9.81 && sol.active[0]);
    assert_close(&sol.acceleration[0], &[0.0, 0.0], 1e-12, 9.81, "resting");
    // Pulled up harder than gravity: the floor does not pull back.
    let given = setup_given_forces(&std::fs::read_to_string("constraints/floor_rest.toml").expect("file"), &["F"]);
    let rows = given.rows(&[("r", v(&[0.0, 0.0])), ("v", v(&[0.0, 0.0])), ("F", v(&[1.0, 20.0]))]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Solved);
    assert_eq!((sol.lambda[0], sol.active[0]), (0.0, false));
    // Above the floor, or touching and moving up: no force.
    for (r, vel, state) in
        [([0.0, 0.5], [0.0, -1.0], ContactState::Apart), ([0.0, 0.0], [0.0, 1.0], ContactState::Separating)]
    {
        let sol = solve(&setup.rows(&[("r", v(&r)), ("v", v(&vel))]));
        assert_eq!(sol.status, Status::Solved);
        assert_eq!((sol.contacts[0], sol.lambda[0]), (Some(state), 0.0));
    }
    // Touching and moving down: an impulse is needed, P = −(1+e) J v / (J M⁻¹ Jᵀ) = (1+e) m |v_y|.
    let rows = setup.rows(&[("m", s(2.0)), ("r", v(&[0.0, 0.0])), ("v", v(&[1.0, -4.0]))]);
    let sol = solve(&rows);
    assert_eq!(sol.contacts[0], Some(ContactState::Closing));
    assert!(sol.diagnostics.iter().any(|d| matches!(d, Diagnostic::Closing { constraint: 0 })));
    let p = 1.5 * 2.0 * 4.0;
    let all = impulses(&rows, 0.5, &Settings::default());
    assert_eq!(all.status, Status::Solved);
    assert!((all.impulse[0] - p).abs() <= 1e-9 * p, "P = {} vs {p}", all.impulse[0]);
    assert_close(&all.velocity_change[0], &[0.0, 6.0], 1e-9, 6.0, "bounce Δv = (1+e)|v_y|");
}

#[test]
fn rope_is_slack_inside_and_a_pendulum_when_taut() {
    let setup = file_setup(std::path::Path::new("constraints/rope_pendulum.toml"));
    // Slack: inside the circle.
    let sol = solve(&setup.rows(&[("r", v(&[0.3, -1.0])), ("v", v(&[2.0, 0.0]))]));
    assert_eq!(sol.status, Status::Solved);
    assert_eq!((sol.contacts[0], sol.lambda[0]), (Some(ContactState::Apart), 0.0));
    // Taut and swinging: the pendulum tension (the article's force).
    for theta in [-2.5f64, -1.0, -0.2, 0.4] {
        let (r, vel) = ([2.0 * theta.cos(), 2.0 * theta.sin()], [-5.0 * theta.sin(), 5.0 * theta.cos()]);
        let sol = solve(&setup.rows(&[("r", v(&r)), ("v", v(&vel))]));
        assert_eq!(sol.status, Status::Solved);
        assert!(sol.lambda[0] > 0.0 && sol.active[0]);
        let want = article_force(1.0, &r, &vel, &[0.0, -9.81]);
        assert_close(&sol.constraint_force[0], &want, 1e-9, norm(&want), "taut rope");
    }
    // At the top, too slow to keep the rope taut: it goes slack (λ = 0, C̈ > 0).
    let rows = setup.rows(&[("r", v(&[0.0, 2.0])), ("v", v(&[0.5, 0.0]))]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Solved);
    assert_eq!(sol.lambda[0], 0.0);
    assert!(c_ddot(&rows, &sol)[0] > 0.0);
}

/// Random contact sets: every row touching and resting, on 2–3 bodies in 2D.
fn contact_rows() -> impl Strategy<Value = Rows> {
    (2usize..=3)
        .prop_flat_map(|n| {
            (
                proptest::collection::vec(0.05f64..20.0, n),
                proptest::collection::vec((-10.0f64..10.0, -10.0f64..10.0), n),
                proptest::collection::vec(
                    (0..n, 0..n, (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0), -5.0f64..5.0),
                    1..=2 * n,
                ),
                proptest::sample::select(vec![1e-6, 1.0, 1e6]),
            )
        })
        .prop_map(|(masses, forces, specs, size)| {
            let n = masses.len();
            let rows = specs
                .into_iter()
                .map(|(b1, b2, (x1, y1, x2, y2), c)| {
                    let mut jacobian = vec![(b1, [x1 * size, y1 * size, 0.0])];
                    if b2 != b1 {
                        jacobian.push((b2, [x2 * size, y2 * size, 0.0]));
                    }
                    Row { value: 0.0, rate: 0.0, bias: c * size, inequality: true, jacobian }
                })
                .collect();
            Rows {
                dim: 2,
                inverse_mass: masses.iter().map(|m| 1.0 / m).collect(),
                velocity: vec![[0.0; 3]; n],
                force: forces.iter().map(|&(x, y)| [x, y, 0.0]).collect(),
                axes: Vec::new(),
                rows,
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, max_global_rejects: 10_000, ..ProptestConfig::default() })]

    #[test]
    fn contacts_are_complementary(rows in contact_rows()) {
        let sol = solve(&rows);
        if sol.status == Status::Inconsistent {
            // Opposing contacts can demand C̈ > 0 both ways (c ≠ 0): no answer exists. With
            // c = 0 the QP is bounded (b lies in the range of J), so it must solve.
            let mut at_rest = rows.clone();
            at_rest.rows.iter_mut().for_each(|r| r.bias = 0.0);
            prop_assert!(solve(&at_rest).status <= Status::Inaccurate);
            return Ok(());
        }
        prop_assert!(sol.status <= Status::Inaccurate, "{:?} {:?}", sol.status, sol.diagnostics);
        let tol = if sol.status == Status::Inaccurate { 1e-6 } else { 1e-8 };
        // Scales: accelerations |F|/m and |c|/‖J‖; forces those times the largest mass.
        let accel = rows.force.iter().zip(&rows.inverse_mass).map(|(f, w)| norm(f) * w).fold(0.0, f64::max)
            + rows.rows.iter().filter(|r| r.jacobian.iter().any(|(_, j)| j.iter().any(|x| *x != 0.0))).map(|r| r.bias.abs() / norm(&r.jacobian.iter().flat_map(|(_, j)| j.to_vec()).collect::<Vec<_>>())).fold(0.0, f64::max);
        let heavy = rows.inverse_mass.iter().map(|w| 1.0 / w).fold(0.0, f64::max);
        let cdd = c_ddot(&rows, &sol);
        let mut forces = Vec::new();
        for (k, row) in rows.rows.iter().enumerate() {
            let jn = norm(&row.jacobian.iter().flat_map(|(_, j)| j.to_vec()).collect::<Vec<_>>());
            if jn == 0.0 {
                prop_assert_eq!(sol.lambda[k], 0.0);
                continue;
            }
            forces.push((k, sol.lambda[k] * jn, cdd[k] / jn));
        }
        // Force scale: the largest contact force or the weight-like scale, whichever is larger.
        // Near-parallel contacts need huge opposing forces; C̈ is then only known to the
        // rounding of those forces (ε·F·w), which the tolerance includes.
        let fscale = forces.iter().map(|f| f.1.abs()).fold(heavy * accel, f64::max);
        let wmax = rows.inverse_mass.iter().fold(0.0f64, |m, w| m.max(*w));
        let allowed = tol * accel + 64.0 * f64::EPSILON * fscale * wmax;
        for (k, force, normal) in forces {
            prop_assert!(force >= 0.0, "λ{k} = {}", sol.lambda[k]);
            prop_assert!(normal >= -allowed, "C̈{k}/‖J‖ = {normal:e} (allowed {allowed:e})");
            prop_assert!((force * normal).abs() <= allowed * fscale, "λ·C̈ row {k}: {:e}", force * normal);
        }
    }

    #[test]
    fn pushed_contacts_agree_with_the_equality_solve(rows in contact_rows()) {
        // Solve as equalities, then flip the rows that pull (−J, −c flips λₖ alone): now
        // every contact pushes, and the contact solve must give the same λ.
        let mut as_equalities = rows.clone();
        as_equalities.rows.iter_mut().for_each(|r| r.inequality = false);
        let first = solve(&as_equalities);
        prop_assume!(first.status == Status::Solved && first.lambda.iter().all(|l| *l != 0.0));
        let mut rows = rows;
        for (row, l) in rows.rows.iter_mut().zip(&first.lambda) {
            if *l < 0.0 {
                row.bias = -row.bias;
                row.jacobian.iter_mut().for_each(|(_, j)| j.iter_mut().for_each(|x| *x = -*x));
            }
        }
        let mut as_equalities = rows.clone();
        as_equalities.rows.iter_mut().for_each(|r| r.inequality = false);
        let eq = solve(&as_equalities);
        prop_assert!(eq.lambda.iter().all(|l| *l > 0.0));
        let sol = solve_with(&rows, &Settings::default());
        prop_assert_eq!(sol.status, Status::Solved);
        for (a, b) in sol.lambda.iter().zip(&eq.lambda) {
            prop_assert!((a - b).abs() <= 1e-9 * b.abs(), "{a} vs {b}");
        }
        // Clarabel alone on the raw QP (A = J M⁻¹ Jᵀ, b = J M⁻¹ F + c) lands there too, to
        // interior-point accuracy.
        let n = rows.rows.len();
        let mut a = Vec::new();
        for p in 0..n {
            for q in p..n {
                let mut x = 0.0;
                for (bp, jp) in &rows.rows[p].jacobian {
                    for (bq, jq) in &rows.rows[q].jacobian {
                        if bp == bq {
                            x += (jp[0] * jq[0] + jp[1] * jq[1]) * rows.inverse_mass[*bp];
                        }
                    }
                }
                a.push((p, q, x));
            }
        }
        let b: Vec<f64> = rows.rows.iter().map(|r| {
            r.jacobian.iter().map(|(i, j)| (j[0] * rows.force[*i][0] + j[1] * rows.force[*i][1]) * rows.inverse_mass[*i]).sum::<f64>() + r.bias
        }).collect();
        // Clarabel on the Jacobi-scaled problem (Ã = D A D, b̃ = D b, λ = D λ̃, as the solve
        // does before calling it), where A is well conditioned (κ(Ã) < 1e3): elsewhere λ itself is
        // ill-determined at interior-point tolerances, which is why the solve polishes.
        let mut dense = nalgebra::DMatrix::<f64>::zeros(n, n);
        for &(p, q, x) in &a {
            dense[(p, q)] = x;
            dense[(q, p)] = x;
        }
        let d: Vec<f64> = (0..n).map(|p| 1.0 / dense[(p, p)].sqrt()).collect();
        let scaled = nalgebra::DMatrix::from_fn(n, n, |p, q| dense[(p, q)] * d[p] * d[q]);
        let eig = scaled.clone().symmetric_eigenvalues();
        prop_assume!(eig.min() > 1e-3 * eig.max());
        let a_scaled: Vec<(usize, usize, f64)> = a.iter().map(|&(p, q, _)| (p, q, scaled[(p, q)])).collect();
        let b_scaled: Vec<f64> = b.iter().zip(&d).map(|(x, y)| x * y).collect();
        let qp = solve_qp(&a_scaled, &b_scaled, &vec![true; n]);
        prop_assert!(matches!(qp.status, QpStatus::Solved | QpStatus::AlmostSolved), "{:?}", qp.status);
        // Compared in the scaled multipliers λ̃ = λ/D, the units Clarabel's tolerances apply to.
        let exact: Vec<f64> = eq.lambda.iter().zip(&d).map(|(x, y)| x / y).collect();
        let big = exact.iter().chain(&b_scaled).fold(0.0f64, |m, x| m.max(x.abs()));
        for (x, y) in qp.lambda.iter().zip(&exact) {
            // Interior-point accuracy: relative ~1e-3 on nearly inactive rows, absolute up to
            // √tol ≈ 1e-4 at the unit scale of Ã on rows that are nearly degenerate (λ and the
            // slack both near zero; Clarabel's gap and feasibility tolerances are 1e-8; a
            // random case gave 1.9e-5). The polish in `numeric::solve` recovers full precision.
            prop_assert!((x - y).abs() <= 1e-3 * big + 1e-4, "QP {x} vs {y}");
        }
    }
}

/// Contacts a QP must sort out: a body on two floors, one pushing and one not.
#[test]
fn qp_path_finds_the_active_contact() {
    let rows = Rows {
        dim: 2,
        inverse_mass: vec![0.5],
        velocity: vec![[0.0; 3]],
        force: vec![[3.0, -19.62, 0.0]],
        axes: Vec::new(),
        rows: vec![
            Row { value: 0.0, rate: 0.0, bias: 0.0, inequality: true, jacobian: vec![(0, [0.0, 1.0, 0.0])] },
            Row { value: 0.0, rate: 0.0, bias: 0.0, inequality: true, jacobian: vec![(0, [1.0, 1.0, 0.0])] },
        ],
    };
    // As equalities both rows would fix the body: λ₁ = −3 < 0 (pulls), so the QP drops it.
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Solved, "{:?}", sol.diagnostics);
    assert!((sol.lambda[0] - 19.62).abs() <= 1e-12 * 19.62 && sol.lambda[1] == 0.0, "{:?}", sol.lambda);
    assert_close(&sol.acceleration[0], &[1.5, 0.0], 1e-12, 10.0, "slides along the floor");
}

/// A long chain hanging straight down at rest: band and dense paths agree, and each link
/// carries the weight below it.
#[test]
fn straight_chain_band_and_dense_agree_with_statics() {
    let n = 200;
    let (m, g) = (0.7, 9.81);
    let mut rows = Vec::new();
    for k in 0..n {
        // Link k joins body k−1 (or the origin) to body k, pointing down: J = r_k − r_{k−1} = (0, −l).
        let mut jacobian = vec![(k, [0.0, -0.5, 0.0])];
        if k > 0 {
            jacobian.insert(0, (k - 1, [0.0, 0.5, 0.0]));
        }
        rows.push(Row { value: 0.0, rate: 0.0, bias: 0.0, inequality: false, jacobian });
    }
    let rows = Rows {
        dim: 2,
        inverse_mass: vec![1.0 / m; n],
        velocity: vec![[0.0; 3]; n],
        force: vec![[0.0, -m * g, 0.0]; n],
        axes: Vec::new(),
        rows,
    };
    for method in [lagrange::numeric::solve::Method::Banded, lagrange::numeric::solve::Method::Dense] {
        let sol = solve_with(&rows, &Settings { method, ..Settings::default() });
        assert_eq!(sol.status, Status::Solved);
        for k in 0..n {
            // Link k holds the weight of bodies k..n up: λ·(−0.5) = (n − k) m g.
            let want = -((n - k) as f64) * m * g / 0.5;
            assert!(
                (sol.lambda[k] - want).abs() <= 1e-9 * want.abs(),
                "{method:?} link {k}: {} vs {want}",
                sol.lambda[k]
            );
        }
    }
}

/// A wire and a line through the bead's position with the same normal: C̈ = 0 asks
/// v·v + r·a = 0 and a.x = 0 at once, which cannot both hold when the bead moves.
#[test]
fn contradictory_constraints_are_reported_inconsistent() {
    let text = BEAD.replace(
        "expr = \"dot(r,r) = l^2\"",
        "expr = \"dot(r,r) = l^2\"\n[[constraints]]\nname = \"line\"\nexpr = \"r.x = l\"",
    );
    let setup = setup(&text);
    let rows = setup.rows(&[("r", v(&[2.0, 0.0])), ("v", v(&[0.0, 1.0]))]);
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Inconsistent);
    assert!(
        sol.diagnostics
            .iter()
            .any(|d| matches!(d, Diagnostic::Inconsistent { constraints, .. } if *constraints == [0, 1]))
    );
    assert!(sol.lambda.iter().chain(sol.constraint_force[0].iter()).all(|x| x.is_finite()));
    // At rest the same pair is merely redundant.
    let sol = solve(&setup.rows(&[("r", v(&[2.0, 0.0])), ("v", v(&[0.0, 0.0]))]));
    assert_eq!(sol.status, Status::MinimumNorm);
    assert_close(&sol.acceleration[0], &[0.0, -9.81], 1e-12, 9.81, "slides down the line");
}

/// A body hitting a corner (floor and wall both closing): the two impulses are the
/// single-contact formula each, since the normals are orthogonal.
#[test]
fn simultaneous_impulses_at_a_corner() {
    let rows = Rows {
        dim: 2,
        inverse_mass: vec![0.25],
        velocity: vec![[-3.0, -2.0, 0.0]],
        force: vec![[0.0, -39.24, 0.0]],
        axes: Vec::new(),
        rows: vec![
            Row { value: 0.0, rate: -2.0, bias: 0.0, inequality: true, jacobian: vec![(0, [0.0, 1.0, 0.0])] },
            Row { value: 0.0, rate: -3.0, bias: 0.0, inequality: true, jacobian: vec![(0, [1.0, 0.0, 0.0])] },
        ],
    };
    let e = 0.8;
    let out = impulses(&rows, e, &Settings::default());
    assert_eq!(out.status, Status::Solved, "{:?}", out.diagnostics);
    for (k, speed) in [(0, 2.0), (1, 3.0)] {
        let single = (1.0 + e) * 4.0 * speed;
        assert!((out.impulse[k] - single).abs() <= 1e-9 * single, "{k}: {} vs {single}", out.impulse[k]);
    }
    assert_close(&out.velocity_change[0], &[3.0 * 1.8, 2.0 * 1.8], 1e-9, 6.0, "corner bounce");
}

/// The same straight chain with its links listed in a scrambled order: the band is found
/// again by renumbering, and every link still holds the weight below it.
#[test]
fn scrambled_chain_is_renumbered_into_a_band() {
    let n = 300;
    let (m, g) = (0.7, 9.81);
    // Link k at position (k * 7919) mod n in the list (7919 is prime, so this is a permutation).
    let mut rows = vec![None; n];
    for k in 0..n {
        let mut jacobian = vec![(k, [0.0, -0.5, 0.0])];
        if k > 0 {
            jacobian.insert(0, (k - 1, [0.0, 0.5, 0.0]));
        }
        rows[(k * 7919) % n] = Some((k, Row { value: 0.0, rate: 0.0, bias: 0.0, inequality: false, jacobian }));
    }
    let (links, rows): (Vec<usize>, Vec<Row>) = rows.into_iter().map(|r| r.expect("a permutation")).unzip();
    let rows = Rows {
        dim: 2,
        inverse_mass: vec![1.0 / m; n],
        velocity: vec![[0.0; 3]; n],
        force: vec![[0.0, -m * g, 0.0]; n],
        axes: Vec::new(),
        rows,
    };
    let sol = solve(&rows);
    assert_eq!(sol.status, Status::Solved);
    for (q, &k) in links.iter().enumerate() {
        let want = -((n - k) as f64) * m * g / 0.5;
        assert!((sol.lambda[q] - want).abs() <= 1e-9 * want.abs(), "link {k}: {} vs {want}", sol.lambda[q]);
    }
}

/// Where the raw rows overflow (|v| ≈ 1e155 makes c = v·v infinite, |r| ≈ 1e200 makes
/// r·r infinite), the solve is redone in a length unit scaled by a power of two: exact
/// forces, and C scaled back (its rounding noise ε·l² may itself overflow). A row that is not homogeneous (`l^2 + 1`) is
/// not rescaled: the raw answer stands, with its diagnostic, and no NaN.
#[test]
fn overflowing_rows_are_solved_in_a_rescaled_unit() {
    use lagrange::numeric::rescale::solve_at;
    let setup = setup(BEAD);
    let system = &setup.loaded.system;
    for (l, speed) in [(1e155, 1e155), (1e200, 3e199), (1e300, 1.0), (2.0, 1.0)] {
        let (theta, g) = (0.9f64, [0.0, -9.81]);
        let r = [l * theta.cos(), l * theta.sin()];
        let vel = [-speed * theta.sin(), speed * theta.cos()];
        let o = state::values(system, &[("l", s(l)), ("r", v(&r)), ("v", v(&vel))]).expect("values");
        let env = environment(system, &setup.loaded.values, &setup.loaded.scene, &o).expect("state");
        let (rows, sol) = solve_at(&setup.program, system, &env, &Settings::default()).expect("rows");
        assert_eq!(sol.status, Status::Solved, "l = {l:e}: {:?}", sol.diagnostics);
        let want = article_force(1.0, &r, &vel, &g);
        assert_close(&sol.constraint_force[0], &want, 1e-9, norm(&want), &format!("rescaled bead l = {l:e}"));
        // C/κ is rounding noise of size ε·l², ±∞ where even that is beyond f64, never NaN.
        assert!(!rows.rows[0].value.is_nan() && !rows.rows[0].bias.is_nan());
        assert_eq!(sol.diagnostics.iter().any(|d| matches!(d, Diagnostic::Rescaled { .. })), l > 1e154);
    }
    let text = BEAD.replace("expr = \"dot(r,r) = l^2\"", "expr = \"dot(r,r) = l^2 + 1\"");
    let setup = self::setup(&text);
    let system = &setup.loaded.system;
    let o =
        state::values(system, &[("l", s(1e155)), ("r", v(&[1e155, 0.0])), ("v", v(&[0.0, 1e155]))]).expect("values");
    let env = environment(system, &setup.loaded.values, &setup.loaded.scene, &o).expect("state");
    let (_, sol) = solve_at(&setup.program, system, &env, &Settings::default()).expect("rows");
    assert_eq!(sol.status, Status::Failed);
    assert!(sol.diagnostics.iter().any(|d| matches!(d, Diagnostic::NonFiniteRow { .. })));
    assert!(sol.lambda.iter().chain(&sol.constraint_force[0]).all(|x| x.is_finite()));
}

/// A random redundant system of equalities on `n` bodies in 2D: `independent` random rows,
/// then rows that are combinations of them (J and c alike, so the data stay consistent),
/// each row scaled by a random factor in [0.1, 10] so that ‖Jₖ‖ differs from row to row
/// (not more: the unscaled pseudo-inverse of the reference must still see the rank).
fn redundant_rows(rng: &mut lagrange::numeric::random::Rng, n: usize, independent: usize, extra: usize) -> Rows {
    let mut dense: Vec<(Vec<[f64; 3]>, f64)> = Vec::new();
    for _ in 0..independent {
        let j = (0..n).map(|_| rng.normal_vector(2, 1.0)).collect();
        dense.push((j, rng.normal()));
    }
    for _ in 0..extra {
        let (mut j, mut c) = (vec![[0.0; 3]; n], 0.0);
        for (jk, ck) in &dense[..independent] {
            let alpha = rng.normal();
            for (x, y) in j.iter_mut().zip(jk) {
                for d in 0..2 {
                    x[d] += alpha * y[d];
                }
            }
            c += alpha * ck;
        }
        dense.push((j, c));
    }
    let rows = dense
        .into_iter()
        .map(|(j, c)| {
            let s = 10f64.powf(rng.uniform(-1.0, 1.0));
            let jacobian = j.iter().enumerate().map(|(b, x)| (b, [x[0] * s, x[1] * s, 0.0])).collect();
            Row { value: 0.0, rate: 0.0, bias: c * s, inequality: false, jacobian }
        })
        .collect();
    Rows {
        dim: 2,
        inverse_mass: (0..n).map(|_| 1.0 / rng.uniform(0.1, 10.0)).collect(),
        velocity: vec![[0.0; 3]; n],
        force: (0..n).map(|_| rng.normal_vector(2, 5.0)).collect(),
        axes: Vec::new(),
        rows,
    }
}

#[test]
fn redundant_systems_get_the_pseudo_inverse_multipliers() {
    // "Minimum-norm λ" is the minimum of ‖λ‖ for C/κ: λ = −A⁺ b with A = J M⁻¹ Jᵀ and
    // b = J M⁻¹ F + c as the rows hold them (before: the minimum of Σ Aₖₖ λₖ², which differs
    // whenever the rows' scales differ). nalgebra's pseudo-inverse of the unscaled A is the
    // independent answer.
    let mut rng = lagrange::numeric::random::Rng::new(14);
    let mut checked = 0;
    for case in 0..300 {
        let n = 2 + case % 3;
        let independent = 1 + case % (2 * n - 1);
        let extra = 1 + case % 2;
        let rows = redundant_rows(&mut rng, n, independent, extra);
        let k = rows.rows.len();
        let dense_j = |q: usize| {
            let mut x = vec![0.0; 2 * n];
            for (b, j) in &rows.rows[q].jacobian {
                x[2 * b] = j[0];
                x[2 * b + 1] = j[1];
            }
            x
        };
        let j: Vec<Vec<f64>> = (0..k).map(dense_j).collect();
        let w = |i: usize| rows.inverse_mass[i / 2];
        let a = nalgebra::DMatrix::from_fn(k, k, |p, q| (0..2 * n).map(|i| j[p][i] * j[q][i] * w(i)).sum::<f64>());
        let b = nalgebra::DVector::from_fn(k, |p, _| {
            (0..2 * n).map(|i| j[p][i] * w(i) * rows.force[i / 2][i % 2]).sum::<f64>() + rows.rows[p].bias
        });
        let want = -(a.clone().pseudo_inverse(1e-8 * a.amax()).expect("an SVD") * b.clone());
        let sol = solve(&rows);
        assert_eq!(sol.status, Status::MinimumNorm, "case {case}: {:?}", sol.diagnostics);
        let got = nalgebra::DVector::from_vec(sol.lambda.clone());
        let error = (&got - &want).norm();
        assert!(
            error <= 1e-7 * want.norm(),
            "case {case}: λ = {got} against A⁺: {want} (‖λ‖ {} vs {})",
            got.norm(),
            want.norm()
        );
        checked += 1;
    }
    assert_eq!(checked, 300);
}

/// `off_constraint` (what `solve` and `simulate` say of a state off a constraint): on the wire
/// with a tangent velocity nothing is reported, at any scale; moved off by a relative δ above
/// the contact tolerance, or given a radial speed, the row is named with |C|/‖∇C‖ and
/// |Ċ|/‖∇C‖ as worked out by hand for C = r·r − l² (∇C/κ = r, C/κ = (r·r − l²)/2).
#[test]
fn states_off_the_constraint_are_named_with_distance_and_speed() {
    use lagrange::numeric::solve::off_constraint;
    let setup = setup(BEAD);
    let system = &setup.loaded.system;
    let mut rng = lagrange::numeric::random::Rng::new(17);
    for _ in 0..200 {
        let l = 10f64.powf(rng.uniform(-6.0, 6.0));
        let (theta, speed) = (rng.uniform(-3.1, 3.1), l * rng.uniform(0.0, 3.0));
        let settings = Settings { length_scale: l, ..Settings::default() };
        let offsets = |r: [f64; 2], vel: [f64; 2]| {
            let o = state::values(system, &[("l", s(l)), ("r", v(&r)), ("v", v(&vel))]).expect("values");
            let env = environment(system, &setup.loaded.values, &setup.loaded.scene, &o).expect("state");
            off_constraint(&setup.program.evaluate(system, &env).expect("rows"), &settings)
        };
        let (e, t) = ([theta.cos(), theta.sin()], [-theta.sin(), theta.cos()]);
        let on = offsets([l * e[0], l * e[1]], [speed * t[0], speed * t[1]]);
        assert!(on.is_empty(), "on the wire at l = {l:e}: {on:?}");
        // Off by δ l radially: |C|/‖∇C‖ = ((1+δ)² − 1) l / (2 (1+δ)).
        let delta = 10f64.powf(rng.uniform(-7.0, -1.0));
        let r = [(1.0 + delta) * l * e[0], (1.0 + delta) * l * e[1]];
        let off = offsets(r, [speed * t[0], speed * t[1]]);
        let want = ((1.0 + delta).powi(2) - 1.0) * l / (2.0 * (1.0 + delta));
        match off.as_slice() {
            [Diagnostic::OffConstraint { constraint: 0, distance, normal_speed, .. }] => {
                assert!((distance - want).abs() <= 1e-6 * want, "δ = {delta:e}: distance {distance:e}, want {want:e}");
                assert!(normal_speed.abs() <= 1e-9 * speed.max(l), "tangent speed counted: {normal_speed:e}");
            }
            other => panic!("δ = {delta:e} at l = {l:e}: {other:?}"),
        }
        // On the wire with a radial speed u: |Ċ|/‖∇C‖ = u.
        let u = speed.max(l) * 10f64.powf(rng.uniform(-6.0, 0.0));
        let off = offsets([l * e[0], l * e[1]], [speed * t[0] + u * e[0], speed * t[1] + u * e[1]]);
        match off.as_slice() {
            [Diagnostic::OffConstraint { normal_speed, distance, .. }] => {
                assert!((normal_speed - u).abs() <= 1e-9 * u, "radial speed {normal_speed:e}, want {u:e}");
                assert!(distance.abs() <= 1e-12 * l, "distance on the wire {distance:e}");
            }
            other => panic!("radial speed {u:e} at l = {l:e}: {other:?}"),
        }
    }
    // Inequality rows are the contact states' business, never an offset.
    let rope = self::setup(&BEAD.replace("dot(r,r) = l^2", "dot(r,r) <= l^2"));
    let o = state::values(&rope.loaded.system, &[("r", v(&[0.5, 0.0]))]).expect("values");
    let env = environment(&rope.loaded.system, &rope.loaded.values, &rope.loaded.scene, &o).expect("state");
    let rows = rope.program.evaluate(&rope.loaded.system, &env).expect("rows");
    assert!(off_constraint(&rows, &Settings::default()).is_empty());
}
