//! Property tests over random well-typed expressions (proptest).
//!
//! Expressions are generated as text in the expression language over a small 2D or 3D
//! system — two bodies (`r1 v1`, `r2 v2`), scalar parameters `k`, `c`, the masses, a vector
//! parameter `u`, the time `t` — with `+ − * / ^`, `dot`, `cross`, `norm`, `sqrt sin cos
//! exp atan ln atan2`, components and vector literals. Properties:
//!
//! - d/dt agrees with a central difference along a smooth trajectory
//!   r(t) = r0 + v0 t + ½ a0 t², v(t) = v0 + a0 t (so Ċ and C̈ are both covered);
//! - ∇ with respect to a position agrees with central differences;
//! - `simplify(e)` evaluates to the value of `e`, and simplifying again changes nothing;
//! - printing (`Style::Source`) and parsing again gives the very same node (hash-consing
//!   makes "same graph" an `Id` comparison);
//! - on derived constraints, Ċ = Σᵢ ∇ᵢC·vᵢ + ∂C/∂t and C̈/κ = Σᵢ Jᵢ·aᵢ + c.
//!
//! Numeric checks skip states where a value is not finite or where the finite difference
//! is itself unreliable (it changes with the step size), and count what they checked: a
//! property that skips almost everything fails.
//!
//! Runs are deterministic (fixed seed); `PROPTEST_CASES` raises the number of cases.

mod common;

use common::{Rng, random_env};
use lagrange::derive::{DeriveError, derive};
use lagrange::expr::diff::time_derivative;
use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::expr::grad::gradient;
use lagrange::expr::print::{Style, print};
use lagrange::expr::{Graph, Id, Role, Simplifier, Ty};
use lagrange::model::system::{System, SystemBuilder};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRng, TestRunner};
use std::cell::Cell;

// ---- the system and the generator ------------------------------------------------------

/// Two bodies, parameters `k`, `c` (scalars) and `u` (a vector), and optionally a constraint.
fn system(dim: usize, constraint: Option<&str>) -> Result<System, String> {
    let mut b = SystemBuilder::new("random", dim as i64).map_err(|e| e.to_string())?;
    for p in ["k", "c"] {
        b.parameter(p, Ty::Scalar).map_err(|e| e.to_string())?;
    }
    b.parameter("u", Ty::Vector).map_err(|e| e.to_string())?;
    b.body(&common::body("p1", "r1", "v1", "a1", "F1", "m1")).map_err(|e| e.to_string())?;
    b.body(&common::body("p2", "r2", "v2", "a2", "F2", "m2")).map_err(|e| e.to_string())?;
    if let Some(text) = constraint {
        b.constraint("random", text).map_err(|e| e.to_string())?;
    }
    Ok(b.finish())
}

type Text = BoxedStrategy<String>;

/// Which symbols the leaves may use.
#[derive(Clone, Copy)]
enum Leaves {
    /// Positions, parameters, `t`: what a constraint may depend on.
    Positional,
    /// Also velocities: what d/dt can differentiate (Ċ depends on them).
    Kinematic,
    /// Every symbol, forces and accelerations included.
    All,
}

fn leaves(dim: usize, which: Leaves) -> (Text, Text) {
    let mut scalars = vec!["k", "c", "t", "2", "3", "0.5", "1"];
    let mut vectors = vec!["r1", "r2", "u"];
    match which {
        Leaves::Positional => {}
        Leaves::Kinematic => vectors.extend(["v1", "v2"]),
        Leaves::All => {
            vectors.extend(["v1", "v2", "a1", "F2"]);
            scalars.extend(["m1", "m2"]);
        }
    }
    let _ = dim;
    let s = proptest::sample::select(scalars).prop_map(str::to_string).boxed();
    let v = proptest::sample::select(vectors).prop_map(str::to_string).boxed();
    (s, v)
}

/// One more level of operators over the scalar and vector expressions `s`, `v`.
fn level(dim: usize, s: Text, v: Text) -> (Text, Text) {
    let ss = (s.clone(), s.clone());
    let vv = (v.clone(), v.clone());
    let mut scalar: Vec<(u32, Text)> = vec![
        (3, s.clone()),
        (2, ss.clone().prop_map(|(a, b)| format!("({a} + {b})")).boxed()),
        (2, ss.clone().prop_map(|(a, b)| format!("({a} - {b})")).boxed()),
        (2, ss.clone().prop_map(|(a, b)| format!("{a}*{b}")).boxed()),
        (1, ss.clone().prop_map(|(a, b)| format!("{a}/(1 + {b}^2)")).boxed()),
        (1, ss.clone().prop_map(|(a, b)| format!("{a}/{b}")).boxed()),
        (1, s.clone().prop_map(|a| format!("({a})^2")).boxed()),
        (1, s.clone().prop_map(|a| format!("({a})^3")).boxed()),
        (1, s.clone().prop_map(|a| format!("({a})^-1")).boxed()),
        (1, s.clone().prop_map(|a| format!("-({a})")).boxed()),
        (3, vv.clone().prop_map(|(a, b)| format!("dot({a}, {b})")).boxed()),
        (1, v.clone().prop_map(|a| format!("norm({a})")).boxed()),
        (1, v.clone().prop_map(|a| format!("({a}).x")).boxed()),
        (1, v.clone().prop_map(|a| format!("({a}).y")).boxed()),
        (1, s.clone().prop_map(|a| format!("sqrt(1 + ({a})^2)")).boxed()),
        (1, s.clone().prop_map(|a| format!("sqrt({a})")).boxed()),
        (1, s.clone().prop_map(|a| format!("sin({a})")).boxed()),
        (1, s.clone().prop_map(|a| format!("cos({a})")).boxed()),
        (1, s.clone().prop_map(|a| format!("exp(({a})/4)")).boxed()),
        (1, s.clone().prop_map(|a| format!("atan({a})")).boxed()),
        (1, s.clone().prop_map(|a| format!("ln(1 + ({a})^2)")).boxed()),
        (1, ss.clone().prop_map(|(a, b)| format!("atan2({a}, {b})")).boxed()),
    ];
    let mut vector: Vec<(u32, Text)> = vec![
        (3, v.clone()),
        (2, vv.clone().prop_map(|(a, b)| format!("({a} + {b})")).boxed()),
        (2, vv.clone().prop_map(|(a, b)| format!("({a} - {b})")).boxed()),
        (2, (s.clone(), v.clone()).prop_map(|(a, b)| format!("{a}*{b}")).boxed()),
        (1, (s.clone(), v.clone()).prop_map(|(a, b)| format!("{b}/(1 + ({a})^2)")).boxed()),
        (1, v.clone().prop_map(|a| format!("-{a}")).boxed()),
    ];
    if dim == 2 {
        scalar.push((1, vv.clone().prop_map(|(a, b)| format!("cross({a}, {b})")).boxed()));
        vector.push((1, ss.prop_map(|(a, b)| format!("[{a}, {b}]")).boxed()));
    } else {
        scalar.push((1, v.clone().prop_map(|a| format!("({a}).z")).boxed()));
        vector.push((2, vv.prop_map(|(a, b)| format!("cross({a}, {b})")).boxed()));
        vector.push((1, (s.clone(), s.clone(), s).prop_map(|(a, b, c)| format!("[{a}, {b}, {c}]")).boxed()));
    }
    (proptest::strategy::Union::new_weighted(scalar).boxed(), proptest::strategy::Union::new_weighted(vector).boxed())
}

/// Scalar and vector expressions up to `depth` operator levels.
fn expressions(dim: usize, which: Leaves, depth: usize) -> (Text, Text) {
    let (mut s, mut v) = leaves(dim, which);
    for _ in 0..depth {
        (s, v) = level(dim, s, v);
    }
    (s, v)
}

/// A dimension, a scalar or vector expression, and a seed for random states.
fn cases(which: Leaves, depth: usize, vectors: bool) -> impl Strategy<Value = (usize, String, u64)> {
    let per_dim = move |dim: usize| {
        let (s, v) = expressions(dim, which, depth);
        let e = if vectors { prop_oneof![2 => s, 1 => v].boxed() } else { s };
        (Just(dim), e, any::<u64>())
    };
    prop_oneof![per_dim(2), per_dim(3)]
}

fn runner(cases: u32) -> TestRunner {
    let cases = std::env::var("PROPTEST_CASES").ok().and_then(|c| c.parse().ok()).unwrap_or(cases);
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    TestRunner::new_with_rng(config, TestRng::deterministic_rng(config_algorithm()))
}

fn config_algorithm() -> proptest::test_runner::RngAlgorithm {
    Config::default().rng_algorithm
}

/// Runs `property` over `strategy`; panics with proptest's minimal failing input.
fn check<S: Strategy>(name: &str, cases: u32, strategy: S, property: impl Fn(S::Value) -> Result<(), TestCaseError>)
where
    S::Value: std::fmt::Debug,
{
    if let Err(e) = runner(cases).run(&strategy, property) {
        panic!("{name}: {e}");
    }
}

// ---- numeric helpers --------------------------------------------------------------------

fn components(v: Value, dim: usize) -> Vec<f64> {
    v.components(dim)
}

fn value(system: &System, id: Id, env: &Env) -> Option<Vec<f64>> {
    value_in(&system.graph, id, env)
}

/// [`value`] for an id of `g` (a derivation's graph).
fn value_in(g: &Graph, id: Id, env: &Env) -> Option<Vec<f64>> {
    let v = eval_one(g, id, env).ok()?;
    v.is_finite().then(|| components(v, g.dim()))
}

/// The state at time `t0 + h` of the trajectory through `env` (r0, v0, a0, t0).
fn along(system: &System, env: &Env, h: f64) -> Env {
    let mut out = env.clone();
    for (s, info) in system.graph.symbols() {
        let (Some(d1), true) = (info.derivative, matches!(info.role, Role::Position { .. } | Role::Velocity { .. }))
        else {
            if info.role == Role::Time {
                let t = env.get(s).and_then(Value::scalar).unwrap_or(0.0);
                out.set(s, Value::Scalar(t + h));
            }
            continue;
        };
        let x = env.get(s).and_then(Value::vector).unwrap_or_default();
        let v = env.get(d1).and_then(Value::vector).unwrap_or_default();
        let a = match system.graph.symbol(d1).derivative {
            Some(d2) => env.get(d2).and_then(Value::vector).unwrap_or_default(),
            None => [0.0; 3],
        };
        let mut y = [0.0; 3];
        for k in 0..3 {
            y[k] = x[k] + v[k] * h + 0.5 * a[k] * h * h;
        }
        out.set(s, Value::Vector(y));
    }
    out
}

/// Whether every root's value is stable under relative perturbations of 1e-9 of every
/// input. Expressions like `dot(cross(u, r1), r1)/dot(r1, cross(r1, r2))` are 0/0 in exact
/// arithmetic and rounding noise in f64: such states say nothing about the rules.
fn well_conditioned(system: &System, roots: &[Id], env: &Env, rng: &mut Rng) -> bool {
    let base: Vec<Option<Vec<f64>>> = roots.iter().map(|&id| value(system, id, env)).collect();
    for _ in 0..4 {
        let mut moved = env.clone();
        for (sym, _) in system.graph.symbols() {
            let wiggle = |x: f64, rng: &mut Rng| x * (1.0 + 1e-9 * rng.uniform(-1.0, 1.0));
            match env.get(sym) {
                Some(Value::Scalar(x)) => moved.set(sym, Value::Scalar(wiggle(x, rng))),
                Some(Value::Vector(v)) => moved.set(sym, Value::Vector(v.map(|x| wiggle(x, rng)))),
                // A quaternion stays unit (none of these systems has one).
                Some(Value::Quaternion(_)) | None => {}
            }
        }
        for (&id, b) in roots.iter().zip(&base) {
            let (Some(b), Some(m)) = (b, value(system, id, &moved)) else { return false };
            let scale = b.iter().fold(1f64, |acc, x| acc.max(x.abs()));
            if b.iter().zip(&m).any(|(x, y)| (x - y).abs() > 1e-5 * scale) {
                return false;
            }
        }
    }
    true
}

/// What a numeric comparison concluded.
enum Verdict {
    Agree,
    /// The state is unusable (non-finite, or the finite difference is unreliable).
    Skip,
}

/// Compares an exact derivative with central differences of `f` at steps `h` and `h/2`.
fn compare_fd(
    exact: &[f64],
    f0: &[f64],
    f: impl Fn(f64) -> Option<Vec<f64>>,
    h: f64,
    what: &str,
) -> Result<Verdict, TestCaseError> {
    let diff = |h: f64| -> Option<Vec<f64>> {
        let (plus, minus) = (f(h)?, f(-h)?);
        Some(plus.iter().zip(&minus).map(|(p, m)| (p - m) / (2.0 * h)).collect())
    };
    let (Some(d1), Some(d2)) = (diff(h), diff(h / 2.0)) else { return Ok(Verdict::Skip) };
    // The scale comes from the function and its difference quotient, never from the value
    // under test: a wrong, huge derivative must not widen its own tolerance.
    let scale = f0.iter().chain(&d2).fold(1f64, |m, x| m.max(x.abs()));
    let spread = d1.iter().zip(&d2).fold(0f64, |m, (a, b)| m.max((a - b).abs()));
    // Huge values come from dividing by a quantity that is zero in exact arithmetic
    // (`1/dot(cross(r2, r1), r2)`): rounding noise, not a function to differentiate.
    if spread > 1e-4 * scale || scale > 1e8 {
        return Ok(Verdict::Skip);
    }
    for (i, (e, d)) in exact.iter().zip(&d2).enumerate() {
        let err = (e - d).abs();
        prop_assert!(
            err <= 1e-6 * scale + 2.0 * spread,
            "{what}: component {i}: exact {e}, finite difference {d} (spread {spread}, scale {scale})"
        );
    }
    Ok(Verdict::Agree)
}

/// Counts checked and skipped states for a property, and asserts enough were checked.
struct Tally {
    checked: Cell<usize>,
    skipped: Cell<usize>,
}

impl Tally {
    fn new() -> Tally {
        Tally { checked: Cell::new(0), skipped: Cell::new(0) }
    }

    fn record(&self, v: Verdict) {
        match v {
            Verdict::Agree => self.checked.set(self.checked.get() + 1),
            Verdict::Skip => self.skipped.set(self.skipped.get() + 1),
        }
    }

    fn assert_enough(&self, name: &str, at_least: usize) {
        let (c, s) = (self.checked.get(), self.skipped.get());
        eprintln!("{name}: {c} states checked, {s} skipped");
        assert!(c >= at_least && c >= s, "{name}: only {c} states checked ({s} skipped)");
    }
}

const STATES: usize = 4;

fn lowered(dim: usize, text: &str, constraint: Option<&str>) -> Result<(System, Id), TestCaseError> {
    let mut system = system(dim, constraint).map_err(TestCaseError::fail)?;
    let id = system.expression(text).map_err(|e| TestCaseError::fail(format!("{text}: {e}")))?;
    Ok((system, id))
}

// ---- the properties ---------------------------------------------------------------------

#[test]
fn time_derivative_matches_finite_differences() {
    let tally = Tally::new();
    check("d/dt", 200, cases(Leaves::Kinematic, 4, true), |(dim, text, seed)| {
        let (mut system, e) = lowered(dim, &text, None)?;
        let de = time_derivative(&mut system.graph, e).map_err(|err| TestCaseError::fail(err.to_string()))?;
        let mut rng = Rng::new(seed);
        for _ in 0..STATES {
            let env = random_env(&system, &mut rng);
            if !well_conditioned(&system, &[e, de], &env, &mut rng) {
                tally.record(Verdict::Skip);
                continue;
            }
            let (Some(exact), Some(f0)) = (value(&system, de, &env), value(&system, e, &env)) else {
                tally.record(Verdict::Skip);
                continue;
            };
            let f = |h: f64| value(&system, e, &along(&system, &env, h));
            tally.record(compare_fd(&exact, &f0, f, 1e-3, &format!("d/dt {text}"))?);
        }
        Ok(())
    });
    tally.assert_enough("d/dt", 300);
}

#[test]
fn gradient_matches_finite_differences() {
    let tally = Tally::new();
    check("∇", 200, cases(Leaves::Positional, 4, false), |(dim, text, seed)| {
        let (mut system, e) = lowered(dim, &text, None)?;
        let r1 = system.graph.symbol_named("r1").expect("r1");
        let grad = gradient(&mut system.graph, e, r1).map_err(|err| TestCaseError::fail(err.to_string()))?;
        let mut rng = Rng::new(seed);
        for _ in 0..STATES {
            let env = random_env(&system, &mut rng);
            if !well_conditioned(&system, &[e, grad], &env, &mut rng) {
                tally.record(Verdict::Skip);
                continue;
            }
            let (Some(exact), Some(f0)) = (value(&system, grad, &env), value(&system, e, &env)) else {
                tally.record(Verdict::Skip);
                continue;
            };
            let x0 = env.get(r1).and_then(Value::vector).expect("r1 set");
            let mut verdict = Verdict::Agree;
            for (axis, &exact_k) in exact.iter().enumerate() {
                let f = |h: f64| {
                    let mut moved = env.clone();
                    let mut x = x0;
                    x[axis] += h;
                    moved.set(r1, Value::Vector(x));
                    value(&system, e, &moved)
                };
                if let Verdict::Skip = compare_fd(&[exact_k], &f0, f, 1e-3, &format!("∇r1 {text}, axis {axis}"))? {
                    verdict = Verdict::Skip;
                }
            }
            tally.record(verdict);
        }
        Ok(())
    });
    tally.assert_enough("∇", 300);
}

#[test]
fn simplify_keeps_the_value_and_is_a_fixpoint() {
    let tally = Tally::new();
    check("simplify", 300, cases(Leaves::All, 4, true), |(dim, text, seed)| {
        let (mut system, e) = lowered(dim, &text, None)?;
        let s = system.simplifier.simplify(&mut system.graph, e).map_err(|err| TestCaseError::fail(err.to_string()))?;
        // A fresh simplifier (no memo) leaves the simplified form as it is.
        let again =
            Simplifier::new().simplify(&mut system.graph, s).map_err(|err| TestCaseError::fail(err.to_string()))?;
        prop_assert_eq!(
            again,
            s,
            "simplify is not idempotent on {}: {} then {}",
            text,
            print(&system.graph, s, Style::Source).unwrap_or_default(),
            print(&system.graph, again, Style::Source).unwrap_or_default()
        );
        let mut rng = Rng::new(seed);
        for _ in 0..STATES {
            let env = random_env(&system, &mut rng);
            if !well_conditioned(&system, &[e, s], &env, &mut rng) {
                tally.record(Verdict::Skip);
                continue;
            }
            let (Some(x), Some(y)) = (value(&system, e, &env), value(&system, s, &env)) else {
                tally.record(Verdict::Skip);
                continue;
            };
            let scale = x.iter().chain(&y).fold(1f64, |m, v| m.max(v.abs()));
            // atan2 jumps by 2π across its cut (y = 0, x < 0); when y is zero in exact
            // arithmetic (a vanishing triple product) rounding noise picks the side.
            let on_cut = |a: f64, b: f64| {
                let turns = (a - b) / std::f64::consts::TAU;
                text.contains("atan2") && turns.round() != 0.0 && (turns - turns.round()).abs() < 1e-9
            };
            if x.iter().zip(&y).any(|(a, b)| on_cut(*a, *b)) {
                tally.record(Verdict::Skip);
                continue;
            }
            for (a, b) in x.iter().zip(&y) {
                // 1e-6: sqrt of a rounding-noise zero (1e-16) is already 1e-8, and a wrong
                // rule is off by far more.
                prop_assert!(
                    (a - b).abs() <= 1e-6 * scale,
                    "simplify changed the value of {}: {} vs {} (simplified: {})",
                    text,
                    a,
                    b,
                    print(&system.graph, s, Style::Source).unwrap_or_default()
                );
            }
            tally.record(Verdict::Agree);
        }
        Ok(())
    });
    tally.assert_enough("simplify", 600);
}

#[test]
fn printing_then_parsing_gives_the_same_node() {
    check("print → parse", 300, cases(Leaves::All, 4, true), |(dim, text, _)| {
        let (mut system, e) = lowered(dim, &text, None)?;
        let s = system.simplifier.simplify(&mut system.graph, e).map_err(|err| TestCaseError::fail(err.to_string()))?;
        // Forces and accelerations have no time derivative: no d/dt form then.
        let de = time_derivative(&mut system.graph, e).ok();
        for (what, id) in [("lowered", Some(e)), ("simplified", Some(s)), ("d/dt", de)] {
            let Some(id) = id else { continue };
            let printed =
                print(&system.graph, id, Style::Source).map_err(|err| TestCaseError::fail(err.to_string()))?;
            let back = system
                .expression(&printed)
                .map_err(|err| TestCaseError::fail(format!("{what} form of {text} printed as {printed}: {err}")))?;
            prop_assert_eq!(back, id, "{} form of {} printed as {} parses to another node", what, text, printed);
        }
        Ok(())
    });
}

#[test]
fn derived_constraints_satisfy_the_velocity_and_acceleration_identities() {
    let strategy = cases(Leaves::Positional, 3, false).prop_map(|(dim, text, seed)| {
        // Make sure the constraint involves a position (a random one may not).
        (dim, format!("{text} + k*dot(r1, r2)"), seed)
    });
    velocity_and_acceleration_identities("derive", 150, strategy, 300);
}

/// The same identities on sums of norms and roots over both bodies.
#[test]
fn derived_norm_constraints_satisfy_the_velocity_and_acceleration_identities() {
    velocity_and_acceleration_identities("derive norms", 100, norm_sums(&["r1", "r2", "u"]), 250);
}

/// Ċ = Σᵢ ∇ᵢC·vᵢ + ∂C/∂t and C̈/κ = Σᵢ Jᵢ·aᵢ + c on constraints drawn from `strategy`, at
/// least `at_least` states compared.
fn velocity_and_acceleration_identities(
    name: &str,
    cases: u32,
    strategy: impl Strategy<Value = (usize, String, u64)>,
    at_least: usize,
) {
    let tally = Tally::new();
    check(name, cases, strategy, |(dim, text, seed)| {
        let system = system(dim, Some(&text)).map_err(TestCaseError::fail)?;
        let mut d = match derive(&system) {
            Ok(d) => d,
            // `dot(-r2, k*r1) + k*dot(r1, r2)` is zero: refusing it is the right answer.
            Err(DeriveError::ZeroGradient(_)) => {
                tally.record(Verdict::Skip);
                return Ok(());
            }
            Err(err) => return Err(TestCaseError::fail(format!("{text}: {err}"))),
        };
        let dc = d.constraints[0].clone();
        let g = &mut d.graph;
        let t = g.symbol_named("t").expect("t");
        let dc_dt = gradient(g, dc.c, t).map_err(|err| TestCaseError::fail(err.to_string()))?;
        let kappa = dc.scale.to_f64();
        let mut rng = Rng::new(seed);
        for _ in 0..STATES {
            let env = random_env(&system, &mut rng);
            let (Some(c_dot), Some(c_ddot), Some(partial_t), Some(c_term)) = (
                value_in(&d.graph, dc.c_dot, &env),
                value_in(&d.graph, dc.c_ddot, &env),
                value_in(&d.graph, dc_dt, &env),
                value_in(&d.graph, dc.bias, &env),
            ) else {
                tally.record(Verdict::Skip);
                continue;
            };
            // Ċ = Σᵢ ∇ᵢC·vᵢ + ∂C/∂t, and C̈/κ = Σᵢ Jᵢ·aᵢ + c.
            let (mut velocity_sum, mut accel_sum) = (partial_t[0], c_term[0]);
            let mut scale = c_dot[0].abs().max(c_ddot[0].abs() / kappa).max(1.0);
            let mut finite = true;
            for (&(body, grad), &(_, j)) in dc.gradient.iter().zip(&dc.jacobian) {
                let (Some(grad), Some(j)) = (value_in(&d.graph, grad, &env), value_in(&d.graph, j, &env)) else {
                    finite = false;
                    break;
                };
                let v = env.get(system.bodies[body].velocity).and_then(Value::vector).expect("v");
                let a = env.get(system.bodies[body].acceleration).and_then(Value::vector).expect("a");
                for k in 0..dim {
                    velocity_sum += grad[k] * v[k];
                    accel_sum += j[k] * a[k];
                    scale = scale.max((grad[k] * v[k]).abs()).max((j[k] * a[k]).abs());
                }
            }
            if !finite {
                tally.record(Verdict::Skip);
                continue;
            }
            prop_assert!((c_dot[0] - velocity_sum).abs() <= 1e-8 * scale, "{}: Ċ ≠ Σ ∇C·v + ∂C/∂t", text);
            prop_assert!((c_ddot[0] / kappa - accel_sum).abs() <= 1e-8 * scale, "{}: C̈/κ ≠ Σ J·a + c", text);
            tally.record(Verdict::Agree);
        }
        Ok(())
    });
    tally.assert_enough(name, at_least);
}

/// A constraint that repeats another with the bodies renamed (the next link of a chain) is
/// derived by renaming the earlier derivation (`expr::shape`). What comes out must be what
/// deriving it alone gives, printed the same, whether the renaming keeps the bodies' order
/// (`r1, r2` → `r3, r4`, reused) or reverses it (→ `r4, r3`, derived afresh).
#[test]
fn a_repeated_constraint_derives_as_if_it_were_alone() {
    let reused = Cell::new(0);
    let strategy =
        cases(Leaves::Positional, 3, false).prop_map(|(dim, text, _)| (dim, format!("{text} + k*dot(r1, r2)")));
    check("repeats", 120, strategy, |(dim, text)| {
        let four = |constraints: &[&str]| -> Result<System, TestCaseError> {
            let mut b = SystemBuilder::new("repeats", dim as i64).map_err(|e| TestCaseError::fail(e.to_string()))?;
            for p in ["k", "c"] {
                b.parameter(p, Ty::Scalar).map_err(|e| TestCaseError::fail(e.to_string()))?;
            }
            b.parameter("u", Ty::Vector).map_err(|e| TestCaseError::fail(e.to_string()))?;
            for i in 1..=4 {
                let names = [
                    format!("p{i}"),
                    format!("r{i}"),
                    format!("v{i}"),
                    format!("a{i}"),
                    format!("F{i}"),
                    format!("m{i}"),
                ];
                b.body(&common::body(&names[0], &names[1], &names[2], &names[3], &names[4], &names[5]))
                    .map_err(|e| TestCaseError::fail(e.to_string()))?;
            }
            for (k, c) in constraints.iter().enumerate() {
                b.constraint(&format!("c{k}"), c).map_err(|e| TestCaseError::fail(e.to_string()))?;
            }
            Ok(b.finish())
        };
        for (x, y) in [("r3", "r4"), ("r4", "r3")] {
            let renamed = text.replace("r1", "X").replace("r2", y).replace('X', x);
            let alone = four(&[&renamed])?;
            let Ok(one) = derive(&alone) else { return Ok(()) };
            let together = four(&[&text, &renamed])?;
            let both = derive(&together).map_err(|e| TestCaseError::fail(format!("{text}: {e}")))?;
            let show =
                |d: &lagrange::derive::Derivation, id: Id| print(&d.graph, id, Style::Source).unwrap_or_default();
            let fields = |d: &lagrange::derive::Derivation, k: usize| {
                let dc = &d.constraints[k];
                let mut out = vec![
                    show(d, dc.c),
                    show(d, dc.c_dot_raw),
                    show(d, dc.c_dot),
                    show(d, dc.c_ddot_raw),
                    show(d, dc.c_ddot),
                    show(d, dc.bias),
                    dc.scale.to_string(),
                    d.a_entry(k, k).map(|a| show(d, a)).unwrap_or_default(),
                    show(d, d.b[k]),
                ];
                for (&(body, grad), &(_, j)) in dc.gradient.iter().zip(&dc.jacobian) {
                    out.push(format!("{body}: {} / {}", show(d, grad), show(d, j)));
                }
                out
            };
            prop_assert_eq!(fields(&both, 1), fields(&one, 0), "{} then {}", text, renamed);
            if x == "r3" {
                reused.set(reused.get() + 1);
            }
        }
        Ok(())
    });
    assert!(reused.get() >= 60, "only {} repeats were compared", reused.get());
}

/// Sums of norms and roots of differences over several bodies (a rope over pulleys, a
/// distance joint, `sqrt(dot(d, d) + c²)`): the terms the simplifier keeps as separate
/// fractions over different roots (`x/|d1| + y/|d2|³`) rather than over one common
/// denominator.
fn norm_sums(vectors: &[&'static str]) -> impl Strategy<Value = (usize, String, u64)> {
    let vector = proptest::sample::select(vectors.to_vec());
    let position = proptest::sample::select(vec!["r1", "r2"]);
    let coefficient = proptest::sample::select(vec!["1", "k", "2", "c", "-1"]);
    let term = (coefficient, position, vector, 0..4usize).prop_map(|(k, a, b, form)| match form {
        0 => format!("{k}*norm({a} - {b})"),
        1 => format!("{k}*sqrt(dot({a} - {b}, {a} - {b}) + c^2)"),
        2 => format!("{k}*dot({a}, {b})/norm({a} - {b})"),
        _ => format!("{k}*norm({a} + {b})^3"),
    });
    (2..4usize, proptest::collection::vec(term, 1..5), any::<u64>())
        .prop_map(|(dim, terms, seed)| (dim, terms.join(" + "), seed))
}

#[test]
fn norms_and_roots_over_several_bodies_simplify_and_differentiate_exactly() {
    let tally = Tally::new();
    check("norms", 200, norm_sums(&["r1", "r2", "u"]), |(dim, text, seed)| {
        let (mut system, e) = lowered(dim, &text, None)?;
        let fail = |err: &dyn std::fmt::Display| TestCaseError::fail(err.to_string());
        let de = time_derivative(&mut system.graph, e).map_err(|e| fail(&e))?;
        let dde = time_derivative(&mut system.graph, de).map_err(|e| fail(&e))?;
        for (what, id) in [("e", e), ("d/dt", de), ("d²/dt²", dde)] {
            let s = system.simplifier.simplify(&mut system.graph, id).map_err(|e| fail(&e))?;
            let again = Simplifier::new().simplify(&mut system.graph, s).map_err(|e| fail(&e))?;
            let printed = print(&system.graph, s, Style::Source).unwrap_or_default();
            prop_assert_eq!(again, s, "simplify is not idempotent on {} of {}: {}", what, text, printed);
            let back = system.expression(&printed).map_err(|err| TestCaseError::fail(format!("{printed}: {err}")))?;
            prop_assert_eq!(back, s, "{} of {} printed as {} parses to another node", what, text, printed);
            let mut rng = Rng::new(seed);
            for _ in 0..STATES {
                let env = random_env(&system, &mut rng);
                let (Some(x), Some(y)) = (value(&system, id, &env), value(&system, s, &env)) else {
                    tally.record(Verdict::Skip);
                    continue;
                };
                let scale = x.iter().chain(&y).fold(1f64, |m, v| m.max(v.abs()));
                for (a, b) in x.iter().zip(&y) {
                    prop_assert!(
                        (a - b).abs() <= 1e-9 * scale,
                        "simplify changed the value of {} of {}: {} vs {} (simplified: {})",
                        what,
                        text,
                        a,
                        b,
                        printed
                    );
                }
                tally.record(Verdict::Agree);
            }
        }
        Ok(())
    });
    tally.assert_enough("norms", 1500);
}

/// What `derive --steps` prints — C, Ċ and C̈ as the product rule gives them and collected,
/// ∇C, J, c, λ and the force of a random constraint — printed in the expression language
/// parses back to the very same node, and printed in Unicode (`Style::Text`) reads back
/// (through [`unicode`]) as an expression of the same value at random states.
#[test]
fn what_steps_prints_reads_back() {
    let tally = Tally::new();
    let strategy = cases(Leaves::Positional, 3, false)
        .prop_map(|(dim, text, seed)| (dim, format!("{text} + k*dot(r1, r2)"), seed));
    check("steps print → parse", 120, strategy, |(dim, text, seed)| {
        let system = system(dim, Some(&text)).map_err(TestCaseError::fail)?;
        let options = lagrange::derive::Options { document: true, steps: true };
        let mut d = match lagrange::derive::derive_with(&system, options) {
            Ok(d) => d,
            Err(DeriveError::ZeroGradient(_)) => return Ok(()),
            Err(err) => return Err(TestCaseError::fail(format!("{text}: {err}"))),
        };
        let dc = d.constraints[0].clone();
        let mut roots = vec![dc.c, dc.c_dot_raw, dc.c_dot, dc.c_ddot_raw, dc.c_ddot, dc.bias];
        roots.extend(dc.gradient.iter().chain(&dc.jacobian).map(|&(_, id)| id));
        roots.extend(d.lambda);
        roots.extend(d.forces.iter().flatten().map(|&(_, id)| id));
        let mut rng = Rng::new(seed);
        let envs: Vec<Env> = (0..4).map(|_| random_env(&system, &mut rng)).collect();
        for id in roots {
            let printed = print(&d.graph, id, Style::Source).map_err(|err| TestCaseError::fail(err.to_string()))?;
            let back = d
                .expression(&system, &printed)
                .map_err(|err| TestCaseError::fail(format!("{text}: {printed} does not parse: {err}")))?;
            prop_assert_eq!(back, id, "{}: {} parses to another node", text, printed);
            let human = print(&d.graph, id, Style::Text).map_err(|err| TestCaseError::fail(err.to_string()))?;
            let source = unicode::to_source(&human)
                .map_err(|err| TestCaseError::fail(format!("{text}: Unicode {human} does not read: {err}")))?;
            let again = d
                .expression(&system, &source)
                .map_err(|err| TestCaseError::fail(format!("{text}: Unicode {human} read as {source}: {err}")))?;
            for env in &envs {
                let (Some(x), Some(y)) = (value_in(&d.graph, id, env), value_in(&d.graph, again, env)) else {
                    tally.record(Verdict::Skip);
                    continue;
                };
                let scale = x.iter().chain(&y).fold(1.0_f64, |m, v| m.max(v.abs()));
                let close = x.len() == y.len() && x.iter().zip(&y).all(|(a, b)| (a - b).abs() <= 1e-9 * scale);
                prop_assert!(close, "{}: Unicode {} (read as {}) is {:?}, not {:?}", text, human, source, y, x);
                tally.record(Verdict::Agree);
            }
        }
        Ok(())
    });
    tally.assert_enough("steps print → parse", 1000);
}

/// The Unicode notation read back for the test above, by the rules people read it with:
/// a sum's `+` and `−` have a space on each side; a leading `−` negates what follows up to
/// the next sum operator; juxtaposition (a space), `·`, `×` and `/` are products read left
/// to right; `/` takes one operand (an atom or a parenthesised group); superscripts and
/// `^` bind tighter, components (`.x`) tightest; `|a|` is a norm and `√a` a root.
mod unicode {
    pub fn to_source(text: &str) -> Result<String, String> {
        let mut r = Reader { s: text.chars().collect(), i: 0 };
        let e = r.sum()?;
        if r.i != r.s.len() {
            return Err(format!("unread text at {}: {:?}", r.i, r.s[r.i..].iter().collect::<String>()));
        }
        Ok(e)
    }

    struct Reader {
        s: Vec<char>,
        i: usize,
    }

    impl Reader {
        fn peek(&self) -> Option<char> {
            self.s.get(self.i).copied()
        }
        fn at(&self, k: usize) -> Option<char> {
            self.s.get(self.i + k).copied()
        }
        fn eat(&mut self, c: char) -> Result<(), String> {
            if self.peek() == Some(c) {
                self.i += 1;
                Ok(())
            } else {
                Err(format!("expected {c:?} at {}", self.i))
            }
        }
        /// ` + ` or ` − ` here.
        fn sum_operator(&self) -> Option<char> {
            match (self.at(0), self.at(1), self.at(2)) {
                (Some(' '), Some(op @ ('+' | '−')), Some(' ')) => Some(op),
                _ => None,
            }
        }
        fn sum(&mut self) -> Result<String, String> {
            let mut e = self.signed()?;
            while let Some(op) = self.sum_operator() {
                self.i += 3;
                let t = self.signed()?;
                e = format!("({e}) {} ({t})", if op == '+' { '+' } else { '-' });
            }
            Ok(e)
        }
        fn signed(&mut self) -> Result<String, String> {
            if self.peek() == Some('−') {
                self.i += 1;
                return Ok(format!("-({})", self.signed()?));
            }
            self.product()
        }
        fn product(&mut self) -> Result<String, String> {
            let mut e = self.power()?;
            loop {
                match self.peek() {
                    Some(' ') if self.sum_operator().is_none() => {
                        self.i += 1;
                        e = format!("({e})*({})", self.power()?);
                    }
                    Some('·') => {
                        self.i += 1;
                        e = format!("dot({e}, {})", self.operand()?);
                    }
                    Some('×') => {
                        self.i += 1;
                        e = format!("cross({e}, {})", self.operand()?);
                    }
                    Some('/') => {
                        self.i += 1;
                        e = format!("({e})/({})", self.power()?);
                    }
                    _ => return Ok(e),
                }
            }
        }
        /// An operand of `·` or `×`, which may be negated.
        fn operand(&mut self) -> Result<String, String> {
            if self.peek() == Some('−') {
                self.i += 1;
                return Ok(format!("-({})", self.operand()?));
            }
            self.power()
        }
        fn power(&mut self) -> Result<String, String> {
            let mut e = self.atom()?;
            loop {
                match self.peek() {
                    Some('.') => {
                        self.i += 1;
                        let axis = self.peek().ok_or("a component")?;
                        self.i += 1;
                        e = format!("({e}).{axis}");
                    }
                    Some('^') => {
                        self.i += 1;
                        e = format!("({e})^({})", self.atom()?);
                    }
                    Some(c) if superscript(c).is_some() => {
                        let mut n = String::new();
                        while let Some(d) = self.peek().and_then(superscript) {
                            n.push(d);
                            self.i += 1;
                        }
                        e = format!("({e})^({n})");
                    }
                    _ => return Ok(e),
                }
            }
        }
        fn list(&mut self, close: char) -> Result<String, String> {
            let mut items = vec![self.sum()?];
            while self.peek() == Some(',') {
                self.eat(',')?;
                self.eat(' ')?;
                items.push(self.sum()?);
            }
            self.eat(close)?;
            Ok(items.join(", "))
        }
        fn atom(&mut self) -> Result<String, String> {
            match self.peek().ok_or("an atom at the end")? {
                '(' => {
                    self.i += 1;
                    let e = self.sum()?;
                    self.eat(')')?;
                    Ok(format!("({e})"))
                }
                '[' => {
                    self.i += 1;
                    Ok(format!("[{}]", self.list(']')?))
                }
                '|' => {
                    self.i += 1;
                    let e = self.sum()?;
                    self.eat('|')?;
                    Ok(format!("norm({e})"))
                }
                '√' => {
                    self.i += 1;
                    Ok(format!("sqrt({})", self.power()?))
                }
                c if c.is_ascii_digit() => {
                    let start = self.i;
                    while self.peek().is_some_and(|c| c.is_ascii_digit()) {
                        self.i += 1;
                    }
                    Ok(self.s[start..self.i].iter().collect())
                }
                c if c.is_alphabetic() || c == '_' => {
                    let start = self.i;
                    while self.peek().is_some_and(|c| c.is_alphabetic() || c.is_ascii_digit() || c == '_') {
                        self.i += 1;
                    }
                    let name: String = self.s[start..self.i].iter().collect();
                    if self.peek() == Some('(') {
                        self.i += 1;
                        return Ok(format!("{name}({})", self.list(')')?));
                    }
                    Ok(name)
                }
                c => Err(format!("unexpected {c:?} at {}", self.i)),
            }
        }
    }

    fn superscript(c: char) -> Option<char> {
        let digits = "⁰¹²³⁴⁵⁶⁷⁸⁹";
        if c == '⁻' {
            return Some('-');
        }
        digits.chars().position(|d| d == c).and_then(|k| char::from_digit(k as u32, 10))
    }
}
