//! Two constraints and two bodies, against mechanics done independently in this file.
//!
//! lagrange's derivation is evaluated at a state, A λ = −b is solved with plain Rust and
//! the constraint forces are Σₖ λₖ Jₖᵢ. The reference works in minimal coordinates instead
//! and never sees a multiplier: the double pendulum through its angles θ1, θ2 and Lagrange's
//! equations of motion, the rod between two free masses through its centre of mass and the
//! relative vector. The constraint force on each body is then mᵢ r̈ᵢ − Fᵢ. The two must agree
//! to 1e-9 at random (consistent) states with random masses, lengths and external forces.

mod common;

use common::{Rng, add3, close_vec, dot3, scale3, solve};
use lagrange::derive::{Derivation, derive};
use lagrange::expr::Id;
use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::model::file::load;
use lagrange::model::system::System;

const TOL: f64 = 1e-9;

/// The constraint force on each body from lagrange's derivation at `env`.
fn lagrange_forces(system: &System, d: &Derivation, env: &Env) -> Vec<[f64; 3]> {
    let n = d.constraints.len();
    let mut a = vec![vec![0.0; n]; n];
    for (k, row) in a.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = d.a_entry(k, j).map_or(0.0, |id| scalar(d, id, env));
        }
    }
    let minus_b: Vec<f64> = d.b.iter().map(|&id| -scalar(d, id, env)).collect();
    let lambda = solve(a, minus_b);
    let mut forces = vec![[0.0; 3]; system.bodies.len()];
    for (k, dc) in d.constraints.iter().enumerate() {
        for &(body, j) in &dc.jacobian {
            forces[body] = add3(forces[body], scale3(lambda[k], vector(d, j, env)));
        }
    }
    forces
}

fn scalar(d: &Derivation, id: Id, env: &Env) -> f64 {
    eval_one(&d.graph, id, env).expect("evaluates").scalar().expect("a scalar")
}

fn vector(d: &Derivation, id: Id, env: &Env) -> [f64; 3] {
    eval_one(&d.graph, id, env).expect("evaluates").vector().expect("a vector")
}

fn set(system: &System, env: &mut Env, name: &str, value: Value) {
    let s = system.graph.symbol_named(name).unwrap_or_else(|| panic!("no symbol `{name}`"));
    env.set(s, value);
}

fn assert_forces(label: &str, got: &[[f64; 3]], expected: &[[f64; 3]]) {
    for (i, (g, e)) in got.iter().zip(expected).enumerate() {
        assert!(close_vec(*g, *e, TOL), "{label}: body {i}: lagrange {g:?}, minimal coordinates {e:?}");
    }
}

#[test]
fn double_pendulum_matches_lagranges_equations_in_angles() {
    let text = include_str!("../constraints/double_pendulum.toml");
    let system = load(text).expect("the double pendulum loads").system;
    let d = derive(&system).expect("derives");
    assert_eq!(d.constraints.len(), 2);
    let mut rng = Rng::new(2024);
    for case in 0..200 {
        let (l1, l2) = (rng.uniform(0.3, 2.0), rng.uniform(0.3, 2.0));
        let (m1, m2) = (rng.uniform(0.2, 5.0), rng.uniform(0.2, 5.0));
        let (t1, t2) = (rng.uniform(-3.2, 3.2), rng.uniform(-3.2, 3.2));
        let (w1, w2) = (rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0));
        let (f1, f2) = (scale3(10.0, rng.uniform_vector(2, -1.0, 1.0)), scale3(10.0, rng.uniform_vector(2, -1.0, 1.0)));

        // Minimal coordinates: r1 = l1 n(θ1), r2 = r1 + l2 n(θ2), n(θ) = (sin θ, −cos θ),
        // e(θ) = dn/dθ = (cos θ, sin θ), de/dθ = −n.
        let n = |t: f64| [t.sin(), -t.cos(), 0.0];
        let e = |t: f64| [t.cos(), t.sin(), 0.0];
        let r1 = scale3(l1, n(t1));
        let r2 = add3(r1, scale3(l2, n(t2)));
        let v1 = scale3(l1 * w1, e(t1));
        let v2 = add3(v1, scale3(l2 * w2, e(t2)));
        // T = ½(m1+m2) l1² ω1² + m2 l1 l2 cos(θ1−θ2) ω1 ω2 + ½ m2 l2² ω2², and the generalised
        // forces Qⱼ = Σᵢ Fᵢ·∂rᵢ/∂θⱼ. Lagrange's equations M θ̈ = Q − (velocity terms):
        let (c, s) = ((t1 - t2).cos(), (t1 - t2).sin());
        let mass = vec![vec![(m1 + m2) * l1 * l1, m2 * l1 * l2 * c], vec![m2 * l1 * l2 * c, m2 * l2 * l2]];
        let q1 = dot3(add3(f1, f2), scale3(l1, e(t1)));
        let q2 = dot3(f2, scale3(l2, e(t2)));
        let rhs = vec![q1 - m2 * l1 * l2 * s * w2 * w2, q2 + m2 * l1 * l2 * s * w1 * w1];
        let alpha = solve(mass, rhs);
        // r̈1 = l1 (θ̈1 e1 − ω1² n1), r̈2 = r̈1 + l2 (θ̈2 e2 − ω2² n2).
        let acc1 = scale3(l1, add3(scale3(alpha[0], e(t1)), scale3(-w1 * w1, n(t1))));
        let acc2 = add3(acc1, scale3(l2, add3(scale3(alpha[1], e(t2)), scale3(-w2 * w2, n(t2)))));
        let expected = [add3(scale3(m1, acc1), scale3(-1.0, f1)), add3(scale3(m2, acc2), scale3(-1.0, f2))];

        let mut env = Env::new();
        for (name, x) in [("l1", l1), ("l2", l2), ("m1", m1), ("m2", m2)] {
            set(&system, &mut env, name, Value::Scalar(x));
        }
        for (name, v) in [("r1", r1), ("r2", r2), ("v1", v1), ("v2", v2), ("F1", f1), ("F2", f2)] {
            set(&system, &mut env, name, Value::Vector(v));
        }
        set(&system, &mut env, "g", Value::Vector([0.0, -9.81, 0.0]));
        let got = lagrange_forces(&system, &d, &env);
        assert_forces(&format!("double pendulum, case {case}"), &got, &expected);
    }
}

#[test]
fn rod_between_two_free_masses_matches_centre_of_mass_and_relative_motion() {
    for dim in [2, 3] {
        let system = common::two_bodies(dim, &["l"], &[("rod", "dot(r1 - r2, r1 - r2) = l^2")]);
        let d = derive(&system).expect("derives");
        let mut rng = Rng::new(99 + dim as u64);
        let dim = dim as usize;
        for case in 0..200 {
            let l = rng.uniform(0.3, 3.0);
            let (m1, m2) = (rng.uniform(0.2, 5.0), rng.uniform(0.2, 5.0));
            let total = m1 + m2;
            let (f1, f2) =
                (scale3(10.0, rng.uniform_vector(dim, -1.0, 1.0)), scale3(10.0, rng.uniform_vector(dim, -1.0, 1.0)));
            // Centre of mass R, relative vector d = r1 − r2 with |d| = l, ḋ ⟂ d.
            let centre = rng.uniform_vector(dim, -1.0, 1.0);
            let centre_velocity = rng.uniform_vector(dim, -1.0, 1.0);
            let mut rel = rng.uniform_vector(dim, -1.0, 1.0);
            while dot3(rel, rel) < 0.01 {
                rel = rng.uniform_vector(dim, -1.0, 1.0);
            }
            let rel = scale3(l / dot3(rel, rel).sqrt(), rel);
            let u = rng.uniform_vector(dim, -1.0, 1.0);
            let rel_velocity = scale3(2.0, add3(u, scale3(-dot3(u, rel) / (l * l), rel)));
            let r1 = add3(centre, scale3(m2 / total, rel));
            let r2 = add3(centre, scale3(-m1 / total, rel));
            let v1 = add3(centre_velocity, scale3(m2 / total, rel_velocity));
            let v2 = add3(centre_velocity, scale3(-m1 / total, rel_velocity));
            // M R̈ = F1 + F2 (internal forces cancel). The rod only allows d to turn:
            // d̈ = P (F1/m1 − F2/m2) − |ḋ|²/l² d, P the projection orthogonal to d,
            // since d·d = l² gives d·d̈ = −ḋ·ḋ.
            let centre_acc = scale3(1.0 / total, add3(f1, f2));
            let free = add3(scale3(1.0 / m1, f1), scale3(-1.0 / m2, f2));
            let tangential = add3(free, scale3(-dot3(free, rel) / (l * l), rel));
            let rel_acc = add3(tangential, scale3(-dot3(rel_velocity, rel_velocity) / (l * l), rel));
            let acc1 = add3(centre_acc, scale3(m2 / total, rel_acc));
            let acc2 = add3(centre_acc, scale3(-m1 / total, rel_acc));
            let expected = [add3(scale3(m1, acc1), scale3(-1.0, f1)), add3(scale3(m2, acc2), scale3(-1.0, f2))];
            // Newton's third law along the rod, as a sanity check of the reference itself.
            assert!(close_vec(expected[0], scale3(-1.0, expected[1]), TOL));

            let mut env = Env::new();
            for (name, x) in [("l", l), ("m1", m1), ("m2", m2)] {
                set(&system, &mut env, name, Value::Scalar(x));
            }
            for (name, v) in [("r1", r1), ("r2", r2), ("v1", v1), ("v2", v2), ("F1", f1), ("F2", f2)] {
                set(&system, &mut env, name, Value::Vector(v));
            }
            let got = lagrange_forces(&system, &d, &env);
            assert_forces(&format!("rod {dim}D, case {case}"), &got, &expected);
            // The closed form that `derive` gives for one constraint agrees too.
            let closed: Vec<[f64; 3]> =
                d.forces.as_ref().expect("closed form").iter().map(|&(_, f)| vector(&d, f, &env)).collect();
            assert_forces(&format!("rod {dim}D closed form, case {case}"), &closed, &expected);
        }
    }
}
