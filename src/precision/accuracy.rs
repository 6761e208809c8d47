//! Formula accuracy: every derived constraint force (and constraint torque on a rigid body)
//! evaluated in f64 against a double-double reference of the same graph, over random and
//! hard states, with the f64 evaluation time beside it — speed and error side by side.
//! Rigid bodies enter as `numeric::rows` lays them out: one angular slot per rigid body
//! (1/I, τ, Jʷ in component 0), so the reference solve is the same code over more slots;
//! their states draw θ anywhere on the circle and ω of the scene's angular speed. A 3D rigid
//! body has three slots, one per principal axis eₖ (1/Iₖ, eₖ·τ − (ω_b × I ω_b)ₖ, Jʷ·eₖ, the
//! gyroscopic term in double-double too); its torque row is the world vector Σₖ τₖ eₖ, and
//! its states draw a unit quaternion uniformly and ω per component.
//!
//! The f64 path is what `solve` and `simulate` use: the closed form λ J when the system has
//! one constraint, else the rows and the λ solve. The reference evaluates the same
//! expressions in double-double and solves A λ = −b by Gaussian elimination in
//! double-double. States: *random* ones around the scene's initial state (positions within
//! the scene's size, velocities of its speed scale), and *hard* ones — everything scaled
//! towards the origin (1e-7: near singular gradients such as the bead's centre) or away
//! from it (1e7: large cancelling terms). Formulas are compared as formulas: the states need
//! not satisfy the constraints.
//!
//! Not here: the simulation error (`precision::work_precision`).

use super::reference::{Dd, eval_dd, solve_dense};
use crate::expr::eval::{Env, Value, eval};
use crate::numeric::random::Rng;
use crate::numeric::rows::{angular_bodies, angular_slots, angular_width, world_angular};
use crate::numeric::solve::solve;
use crate::scenario::Scenario;
use std::time::Instant;
use twofloat::TwoFloat;

/// The hard states scale positions and velocities by these (position, velocity) factors in
/// turn: seven decades small or large, alone and together, where cancellation in f64 shows.
const HARD_SCALES: [(f64, f64); 4] = [(1e-7, 1.0), (1.0, 1e7), (1e7, 1e7), (1e-7, 1e-7)];

/// The most states of each class (`bench --states`): each is a whole state held while it is
/// timed, so 10⁸ would exhaust memory; 10⁵ of a chain take seconds and tens of MB.
pub const MAX_STATES: usize = 100_000;

/// The error of one body's force over a class of states.
#[derive(Clone, Debug, PartialEq)]
pub struct AccuracyRow {
    pub body: String,
    /// The row is the body's constraint torque (a rigid body), not its force.
    pub torque: bool,
    /// "closed form" or "solve".
    pub method: String,
    /// "random" or "hard".
    pub states: String,
    pub count: usize,
    pub median_rel_error: f64,
    pub max_rel_error: f64,
    /// f64 evaluation of all forces at one state, in nanoseconds.
    pub nanos_per_eval: f64,
}

use crate::numeric::vector::safe_norm as norm;

/// |q| of a quaternion's four components.
fn norm4(q: &[f64; 4]) -> f64 {
    q.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// A torque value as a world vector: 3D as it is, 2D `[τ, 0, 0]`.
fn torque_vector<S: Copy + crate::expr::eval::Scalar>(v: Value<S>) -> Option<[S; 3]> {
    match v {
        Value::Scalar(t) => Some([t, S::ZERO, S::ZERO]),
        Value::Vector(t) => Some(t),
        Value::Quaternion(_) => None,
    }
}

/// The forces on every body at `env`, in f64, by the path the library uses, then the
/// constraint torque on every rigid body as a world vector (2D `[τ, 0, 0]`), in the order
/// of [`angular_bodies`].
fn forces_f64(s: &Scenario, env: &Env) -> Option<Vec<[f64; 3]>> {
    let n = s.system.bodies.len();
    match (&s.derivation.forces, &s.derivation.torques) {
        (Some(forces), Some(torques)) => {
            let ids: Vec<_> = forces.iter().chain(torques).map(|&(_, id)| id).collect();
            let values = eval(&s.derivation.graph, &ids, env).ok()?;
            let mut out = vec![[0.0; 3]; outputs(s)];
            for (&(b, _), v) in forces.iter().zip(&values) {
                out[b] = v.vector()?;
            }
            for (&(b, _), v) in torques.iter().zip(&values[forces.len()..]) {
                out[torque_index(s, b)?] = torque_vector(*v)?;
            }
            Some(out)
        }
        _ => {
            let mut rows = s.program.evaluate(&s.system, env).ok()?;
            rows.rows.iter_mut().for_each(|r| r.inequality = false);
            let force = solve(&rows).constraint_force;
            let mut out = force.get(..n)?.to_vec();
            for b in angular_bodies(&s.system) {
                let slots = angular_slots(&s.system, b)?;
                out.push(world_angular(&rows, |slot| force.get(slot).map_or(f64::NAN, |f| f[0]), slots));
            }
            Some(out)
        }
    }
}

/// The rows of the result: every body's force, then every rigid body's torque.
fn outputs(s: &Scenario) -> usize {
    s.system.bodies.len() + angular_bodies(&s.system).count()
}

/// Where rigid body `body`'s torque sits among the outputs.
fn torque_index(s: &Scenario, body: usize) -> Option<usize> {
    angular_bodies(&s.system).position(|b| b == body).map(|r| s.system.bodies.len() + r)
}

/// The same forces (and torques) in double-double (None where the reference is undefined there).
fn forces_dd(s: &Scenario, env: &Env) -> Option<Vec<[TwoFloat; 3]>> {
    let graph = &s.derivation.graph;
    let n = s.system.bodies.len();
    let zero = TwoFloat::from(0.0);
    if let (Some(forces), Some(torques)) = (&s.derivation.forces, &s.derivation.torques) {
        let ids: Vec<_> = forces.iter().chain(torques).map(|&(_, id)| id).collect();
        let values = eval_dd(graph, &ids, env).ok()?;
        let mut out = vec![[zero; 3]; outputs(s)];
        for (&(b, _), v) in forces.iter().zip(&values) {
            out[b] = v.vector_or_nan();
        }
        for (&(b, _), v) in torques.iter().zip(&values[forces.len()..]) {
            out[torque_index(s, b)?] = torque_vector(*v).unwrap_or([TwoFloat::NAN; 3]);
        }
        return Some(out);
    }
    // Masses and external forces per body, then per rigid body its inertia, external torque,
    // ω and (3D) principal axes.
    let rigid: Vec<usize> = angular_bodies(&s.system).collect();
    let width = angular_width(&s.system);
    let mut roots: Vec<_> = s.system.bodies.iter().map(|b| b.mass).collect();
    let force_expr = s.system.by_body(&s.scene.forces);
    let given_torque = s.system.by_body(&s.scene.torques);
    roots.extend(force_expr.iter().flatten());
    let rigid_start = roots.len();
    for &i in &rigid {
        let r = s.system.bodies[i].rigid.as_ref()?;
        let tau = given_torque[i].unwrap_or(r.nodes.torque);
        roots.extend([r.inertia, tau, r.nodes.angular_velocity]);
        roots.extend(r.nodes.axes.iter().flatten());
    }
    let constraints_start = roots.len();
    for d in &s.derivation.constraints {
        roots.push(d.bias);
        roots.extend(d.jacobian.iter().map(|&(_, j)| j));
        roots.extend(d.angular.iter().map(|&(_, j)| j));
    }
    // A torque or ω symbol without a value in the state is zero.
    let mut env = env.clone();
    for &i in &rigid {
        let r = s.system.bodies[i].rigid.as_ref()?;
        let zero_value = if width == 3 { Value::Vector([0.0; 3]) } else { Value::Scalar(0.0) };
        for symbol in [r.torque, r.angular_velocity] {
            if env.get(symbol).is_none() {
                env.set(symbol, zero_value);
            }
        }
    }
    let values = eval_dd(graph, &roots, &env).ok()?;
    let one = TwoFloat::from(1.0);
    let mut inverse_mass: Vec<TwoFloat> = values[..n].iter().map(|m| one / m.scalar_or_nan()).collect();
    let mut at = n;
    let mut force = Vec::new();
    for (i, f) in force_expr.iter().enumerate() {
        force.push(match f {
            Some(_) => {
                at += 1;
                values[at - 1].vector_or_nan()
            }
            None => match env.get(s.system.bodies[i].force) {
                Some(Value::Vector(v)) => v.map(TwoFloat::from),
                _ => [zero; 3],
            },
        });
    }
    debug_assert_eq!(at, rigid_start);
    let dot = |a: &[TwoFloat; 3], b: &[TwoFloat; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    // The angular slots as `numeric::rows` lays them out. 2D: 1/I and τ in component 0.
    // 3D, per principal axis eₖ: 1/Iₖ and eₖ·τ − (ω_b × I ω_b)ₖ with ω_b = (eⱼ·ω)ⱼ (Euler's
    // equations in the body frame; DESIGN "Rigid bodies").
    let mut axes: Vec<[[TwoFloat; 3]; 3]> = Vec::new();
    for _ in &rigid {
        let (inertia, tau, omega) = (values[at], values[at + 1], values[at + 2]);
        at += 3;
        if width == 3 {
            let e: [[TwoFloat; 3]; 3] = std::array::from_fn(|k| values[at + k].vector_or_nan());
            at += 3;
            let (moments, tau, w) = (inertia.vector_or_nan(), tau.vector_or_nan(), omega.vector_or_nan());
            let wb: [TwoFloat; 3] = std::array::from_fn(|k| dot(&e[k], &w));
            let iw: [TwoFloat; 3] = std::array::from_fn(|k| moments[k] * wb[k]);
            for k in 0..3 {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let gyroscopic = wb[i] * iw[j] - wb[j] * iw[i];
                inverse_mass.push(one / moments[k]);
                force.push([dot(&e[k], &tau) - gyroscopic, zero, zero]);
            }
            axes.push(e);
        } else {
            inverse_mass.push(one / inertia.scalar_or_nan());
            force.push([tau.scalar_or_nan(), zero, zero]);
        }
    }
    debug_assert_eq!(at, constraints_start);
    let mut c = Vec::new();
    let mut jac: Vec<Vec<(usize, [TwoFloat; 3])>> = Vec::new();
    for d in &s.derivation.constraints {
        c.push(values[at].scalar_or_nan());
        at += 1;
        let mut row: Vec<(usize, [TwoFloat; 3])> =
            d.jacobian.iter().map(|&(b, _)| b).zip(values[at..].iter().map(|v: &Dd| v.vector_or_nan())).collect();
        at += d.jacobian.len();
        for &(b, _) in &d.angular {
            let slots = angular_slots(&s.system, b)?;
            let r = rigid.iter().position(|&i| i == b)?;
            if width == 3 {
                // Jʷ·eₖ in slot k, as `numeric::rows` projects it.
                let jw = values[at].vector_or_nan();
                for (k, slot) in slots.enumerate() {
                    row.push((slot, [dot(&jw, &axes[r][k]), zero, zero]));
                }
            } else {
                row.push((slots.start, [values[at].scalar_or_nan(), zero, zero]));
            }
            at += 1;
        }
        jac.push(row);
    }
    // A λ = −b with Aₖⱼ = Σᵢ Jₖᵢ·Jⱼᵢ/mᵢ, bₖ = Σᵢ Jₖᵢ·Fᵢ/mᵢ + cₖ over the slots (a rigid body's
    // angular slot adds Jʷₖ Jʷⱼ/I and Jʷₖ τ/I: M = blockdiag(m E, I), DESIGN "Rigid bodies").
    let k = c.len();
    let mut a = vec![vec![zero; k]; k];
    let mut b = vec![zero; k];
    for p in 0..k {
        for &(body, ref jp) in &jac[p] {
            b[p] += dot(jp, &force[body]) * inverse_mass[body];
            for q in 0..k {
                for &(other, ref jq) in &jac[q] {
                    if other == body {
                        a[p][q] += dot(jp, jq) * inverse_mass[body];
                    }
                }
            }
        }
        b[p] = -(b[p] + c[p]);
    }
    let lambda = solve_dense(a, b)?;
    let mut per_slot = vec![[zero; 3]; inverse_mass.len()];
    for (p, l) in lambda.iter().enumerate() {
        for &(body, ref j) in &jac[p] {
            for d in 0..3 {
                per_slot[body][d] += *l * j[d];
            }
        }
    }
    // Forces as they are; each rigid body's torque as a world vector (3D: Σₖ τₖ eₖ).
    let mut out = per_slot[..n].to_vec();
    for (r, &i) in rigid.iter().enumerate() {
        let slots = angular_slots(&s.system, i)?;
        if width == 3 {
            let mut t = [zero; 3];
            for (k, slot) in slots.enumerate() {
                for d in 0..3 {
                    t[d] += per_slot[slot][0] * axes[r][k][d];
                }
            }
            out.push(t);
        } else {
            out.push(per_slot[slots.start]);
        }
    }
    Some(out)
}

/// Measures every body's force (and every rigid body's constraint torque, as the row
/// `<body> (torque)`) over `count` random and `count` hard states.
pub fn formula_accuracy(s: &Scenario, count: usize, seed: u64) -> Vec<AccuracyRow> {
    let system = &s.system;
    let n = system.bodies.len();
    let get = |sym| s.env.get(sym).and_then(Value::vector).unwrap_or([0.0; 3]);
    let q0: Vec<[f64; 3]> = system.bodies.iter().map(|b| get(b.position)).collect();
    let v0: Vec<[f64; 3]> = system.bodies.iter().map(|b| get(b.velocity)).collect();
    let length = q0.iter().map(norm).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    let length = if length > f64::MIN_POSITIVE { length } else { 1.0 };
    let speed = v0.iter().map(norm).fold(0.0, f64::max).max(length);
    let dim = system.dim();
    let method = if s.derivation.forces.is_some() { "closed form" } else { "solve" };
    // Rigid bodies: the angle anywhere on the circle around the scene's (3D: a random unit
    // quaternion, any orientation), ω of the scene's angular speed scale (its largest |ω|,
    // at least speed/length; 3D: per component around the scene's ω).
    let rigid: Vec<usize> = angular_bodies(system).collect();
    let scalar = |sym| s.env.get(sym).and_then(Value::scalar).unwrap_or(0.0);
    let angular = |sym| match s.env.get(sym) {
        Some(Value::Vector(w)) => w,
        Some(Value::Scalar(w)) => [w, 0.0, 0.0],
        _ => [0.0; 3],
    };
    let three = angular_width(system) == 3;
    let spin = system
        .bodies
        .iter()
        .filter_map(|b| b.rigid.as_ref())
        .map(|r| norm(&angular(r.angular_velocity)))
        .fold(speed / length, f64::max);
    let slots = outputs(s);
    let mut rng = Rng::new(seed);
    let mut rows = Vec::new();
    for class in ["random", "hard"] {
        let mut errors: Vec<Vec<f64>> = vec![Vec::new(); slots];
        let mut envs = Vec::new();
        for k in 0..count {
            let (qs, vs) = if class == "random" { (1.0, 1.0) } else { HARD_SCALES[k % HARD_SCALES.len()] };
            let mut env = s.env.clone();
            for (i, body) in system.bodies.iter().enumerate() {
                let mut q = [0.0; 3];
                let mut v = [0.0; 3];
                for d in 0..dim {
                    q[d] = qs * (q0[i][d] + length * rng.uniform(-0.5, 0.5));
                    v[d] = vs * (v0[i][d] + speed * rng.uniform(-0.5, 0.5));
                }
                env.set(body.position, Value::Vector(q));
                env.set(body.velocity, Value::Vector(v));
            }
            for &i in &rigid {
                let Some(r) = &system.bodies[i].rigid else { continue };
                if three {
                    // Normalised Gaussian components: uniform over the unit quaternions.
                    let mut q = [0.0; 4];
                    while norm4(&q) <= 1e-3 {
                        q = std::array::from_fn(|_| rng.normal());
                    }
                    let size = norm4(&q);
                    let w0 = angular(r.angular_velocity);
                    let w: [f64; 3] = std::array::from_fn(|d| vs * (w0[d] + spin * rng.uniform(-0.5, 0.5)));
                    env.set(r.orientation, Value::Quaternion(q.map(|x| x / size)));
                    env.set(r.angular_velocity, Value::Vector(w));
                } else {
                    let theta = scalar(r.orientation) + std::f64::consts::PI * rng.uniform(-1.0, 1.0);
                    let omega = vs * (scalar(r.angular_velocity) + spin * rng.uniform(-0.5, 0.5));
                    env.set(r.orientation, Value::Scalar(theta));
                    env.set(r.angular_velocity, Value::Scalar(omega));
                }
            }
            envs.push(env);
        }
        // Time the f64 path alone.
        let repeats = 5;
        let start = Instant::now();
        for _ in 0..repeats {
            for env in &envs {
                std::hint::black_box(forces_f64(s, env));
            }
        }
        let nanos = start.elapsed().as_secs_f64() * 1e9 / (repeats * envs.len().max(1)) as f64;
        for env in &envs {
            let (Some(f), Some(r)) = (forces_f64(s, env), forces_dd(s, env)) else { continue };
            for i in 0..slots {
                let diff: [f64; 3] = std::array::from_fn(|d| (TwoFloat::from(f[i][d]) - r[i][d]).hi());
                let size = norm(&std::array::from_fn(|d| r[i][d].hi()));
                if size > 0.0 && size.is_finite() {
                    let e = norm(&diff) / size;
                    errors[i].push(if e.is_nan() { f64::INFINITY } else { e });
                }
            }
        }
        for (i, mut e) in errors.into_iter().enumerate() {
            e.sort_by(f64::total_cmp);
            let median = if e.is_empty() { f64::NAN } else { e[e.len() / 2] };
            // Slot i past the bodies is rigid body rigid[i − n]'s constraint torque.
            let (body, torque) = match i.checked_sub(n) {
                None => (system.bodies[i].name.clone(), false),
                Some(r) => (system.bodies[rigid[r]].name.clone(), true),
            };
            rows.push(AccuracyRow {
                body,
                torque,
                method: method.into(),
                states: class.into(),
                count: e.len(),
                median_rel_error: median,
                max_rel_error: e.last().copied().unwrap_or(f64::NAN),
                nanos_per_eval: nanos,
            });
        }
    }
    rows
}
