//! Random states that satisfy the constraints, for judging formulas that are equal only on
//! the constraint manifold (`l^2` where lagrange writes `dot(r,r)`).
//!
//! A state starts at the scene's initial positions (or the origin) plus Gaussian noise, then:
//! 1. positions: Newton on C = 0 for every constraint (equalities and inequalities, all
//!    taken as active), each step the mass-weighted minimum-norm correction
//!    Δq = −M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁺ C, until |Cₖ|/‖Jₖ‖ is at rounding level;
//! 2. velocities: random, then projected onto Ċ = 0 in one exact step (Ċ is affine in v):
//!    Δv = −M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁺ Ċ, so J v = −∂C/∂t.
//!
//!    Both are the simulation's projection (`numeric::stabilize::project_positions` with
//!    [`Inequalities::AsEqualities`], `project_velocities`), so J M⁻¹ Jᵀ is assembled and
//!    factored by `numeric::solve` and nowhere else;
//! 3. forces and accelerations: random; `t` uniform in [0, 2]; parameters from the file;
//!    masses (and inertias) from the file, or uniform in [0.5, 2] when the file gives none.
//!
//! A rigid body starts at a random angle on the whole circle with random ω, τ and α; its
//! angle and ω are slots of the projection like positions and velocities (generalised
//! coordinates, the angle weighted by the inertia), so they end on C = 0 and Ċ = 0 too.
//!
//! States where Newton does not converge, or where J M⁻¹ Jᵀ is ill-conditioned (a singular
//! configuration, e.g. the bead at the wire's centre), are thrown away and drawn again.
//!
//! The generator is a fixed-seed SplitMix64, so a check gives the same states every run.
//!
//! Not here: comparing values (`check`), a projection or linear algebra of its own, files or
//! text.

use crate::derive::Derivation;
use crate::expr::eval::{Env, Value};
use crate::expr::{Role, Symbol, Ty};
use crate::model::scene::Scene;
use crate::model::system::System;
use crate::numeric::dynamics::Dynamics;
use crate::numeric::random::Rng;
use crate::numeric::rows::{RowProgram, Rows};
use crate::numeric::simulate::initial_state;
use crate::numeric::solve::{Settings, Status, solve_with};
use crate::numeric::stabilize::{Inequalities, distance, project_positions, project_velocities};
use crate::numeric::vector::{row_norm, safe_norm};

/// Newton iterations per attempt: from a start half the scene's size away, Newton takes a
/// handful of steps once quadratic; 60 leaves room for slow first steps near a fold.
const NEWTON_STEPS: usize = 60;
/// Newton stops when every |Cₖ|/‖Jₖ‖ is within this times the scene's size: rounding level
/// of positions of that size, so formulas equal only on the surface agree to ~1e-13.
const NEWTON_TOLERANCE: f64 = 1e-13;
/// After the velocity projection every |Ċₖ|/‖Jₖ‖ must be within this times the fastest
/// speed (rounding level of one linear solve).
const RATE_TOLERANCE: f64 = 1e-12;
/// Attempts per wanted state before giving up.
const ATTEMPTS_PER_STATE: usize = 20;
/// Smallest accepted squared pivot of the unit-diagonal J M⁻¹ Jᵀ (about σ_min/σ_max): states
/// closer to a singular configuration make the formulas' 1/det terms amplify rounding past
/// the check's relative 1e-9.
const MIN_CONDITION: f64 = 1e-6;

/// `count` states on the constraint manifold, or why they could not be found.
pub fn sample(
    system: &System,
    derivation: &Derivation,
    parameters: &[(Symbol, Value)],
    scene: &Scene,
    count: usize,
) -> Result<Vec<Env>, String> {
    let program = RowProgram::new(system, derivation, &[]);
    let mut dynamics = Dynamics::new(system, program, Env::new());
    let dim = system.dim();
    let mut base = Env::new();
    for &(s, v) in parameters {
        base.set(s, v);
    }
    let mut start = vec![[0.0; 3]; system.bodies.len()];
    for &(s, v) in &scene.initial {
        match system.graph.symbol(s).role {
            Role::Position { body } => start[body] = v.vector().unwrap_or([0.0; 3]),
            Role::Mass { .. } | Role::Inertia { .. } => base.set(s, v),
            _ => {}
        }
    }
    let size = start.iter().map(safe_norm).fold(1.0f64, f64::max);
    let masses: Vec<Symbol> = system
        .graph
        .symbols()
        .filter(|(s, info)| matches!(info.role, Role::Mass { .. } | Role::Inertia { .. }) && base.get(*s).is_none())
        .map(|(s, _)| s)
        .collect();
    let three_d_rigid = dim == 3 && system.has_rigid_bodies();
    let mut rng = Rng::new(0x5eed_1a94_a27e);
    let mut states = Vec::new();
    let mut attempts = 0;
    while states.len() < count {
        attempts += 1;
        if attempts > count * ATTEMPTS_PER_STATE {
            return Err(format!(
                "found only {} of {count} states that satisfy the constraints in {} attempts \
                 (Newton did not converge or the configurations were singular)",
                states.len(),
                attempts - 1
            ));
        }
        let mut env = base.clone();
        env.set(system.time, Value::Scalar(rng.uniform(0.0, 2.0)));
        for &m in &masses {
            // A 3D inertia is three principal moments.
            let moment = if system.graph.symbol(m).ty == Ty::Vector {
                Value::Vector([rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0)])
            } else {
                Value::Scalar(rng.uniform(0.5, 2.0))
            };
            env.set(m, moment);
        }
        for (i, body) in system.bodies.iter().enumerate() {
            let mut r = rng.normal_vector(dim, 0.5 * size);
            for (c, s) in r.iter_mut().zip(start[i]) {
                *c += s;
            }
            env.set(body.position, Value::Vector(r));
            env.set(body.velocity, Value::Vector(rng.normal_vector(dim, size)));
            env.set(body.force, Value::Vector(rng.normal_vector(dim, 10.0)));
            env.set(body.acceleration, Value::Vector(rng.normal_vector(dim, 10.0)));
            // A rigid body: an angle anywhere on the circle, ω, τ and α random like v, F and a.
            if let Some(rigid) = &body.rigid
                && rigid.nodes.axes.is_some()
            {
                // 3D: a uniformly random unit quaternion (a normal 4-vector normalised), and
                // world-frame vectors ω, τ and α.
                let q = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
                let n = crate::expr::eval::norm(q);
                env.set(rigid.orientation, Value::Quaternion(q.map(|x| x / n)));
                env.set(rigid.angular_velocity, Value::Vector(rng.normal_vector(3, 1.0)));
                env.set(rigid.torque, Value::Vector(rng.normal_vector(3, 10.0)));
                env.set(rigid.angular_acceleration, Value::Vector(rng.normal_vector(3, 10.0)));
            } else if let Some(rigid) = &body.rigid {
                let angle = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
                env.set(rigid.orientation, Value::Scalar(angle));
                env.set(rigid.angular_velocity, Value::Scalar(rng.normal()));
                env.set(rigid.torque, Value::Scalar(10.0 * rng.normal()));
                env.set(rigid.angular_acceleration, Value::Scalar(10.0 * rng.normal()));
            }
        }
        // 3D rigid bodies are not projected (positions in generalised coordinates with a
        // quaternion are the simulation's, not written yet): their expectations are
        // identities in the state, checked at states that need not satisfy C = 0.
        if three_d_rigid || project(&mut dynamics, &mut env, size).is_some() {
            states.push(env);
        }
    }
    Ok(states)
}

/// Projects `env`'s positions onto C = 0 and velocities onto Ċ = 0 with the simulation's
/// projection (`numeric::stabilize`, every inequality held as an equality); `None` if Newton
/// does not converge or J M⁻¹ Jᵀ is ill-conditioned at the result.
fn project(dynamics: &mut Dynamics<'_>, env: &mut Env, size: f64) -> Option<()> {
    let system = dynamics.system();
    let (mut q, mut v, t) = initial_state(system, env);
    dynamics.reset(env.clone());
    let bound = NEWTON_TOLERANCE * size;
    let (mut rows, _) =
        project_positions(dynamics, t, &mut q, &v, bound, NEWTON_STEPS, Inequalities::AsEqualities).ok()?;
    let residual = rows.rows.iter().map(|r| distance(r).abs()).fold(0.0f64, f64::max);
    let converged = residual <= bound;
    if !converged || !well_conditioned(&rows) {
        return None;
    }
    // Ċ = J v + ∂C/∂t is affine in v: one minimum-norm step makes it zero.
    project_velocities(&mut rows, &mut v);
    let rows = dynamics.rows(t, &q, &v).ok()?;
    let speed = v.iter().map(safe_norm).fold(1.0, f64::max);
    if !rows.rows.iter().all(|r| (r.rate / row_norm(&r.jacobian)).abs() <= RATE_TOLERANCE * speed) {
        return None;
    }
    // Angles and angular velocities sit in the slots after the bodies (`numeric::rows`).
    let n = system.bodies.len();
    for (slot, rigid) in (n..).zip(system.bodies.iter().filter_map(|b| b.rigid.as_ref())) {
        env.set(rigid.orientation, Value::Scalar(q[slot][0]));
        env.set(rigid.angular_velocity, Value::Scalar(v[slot][0]));
    }
    for (body, (q, v)) in system.bodies.iter().zip(q.into_iter().zip(v)) {
        env.set(body.position, Value::Vector(q));
        env.set(body.velocity, Value::Vector(v));
    }
    Some(())
}

/// Whether J M⁻¹ Jᵀ at `rows`, scaled to a unit diagonal as the solve scales it, factors with
/// every pivot above [`MIN_CONDITION`] (all rows taken as equalities): the solve's own test
/// of a singular configuration, with a stricter threshold.
fn well_conditioned(rows: &Rows) -> bool {
    let mut rows = rows.clone();
    rows.rows.iter_mut().for_each(|r| r.inequality = false);
    solve_with(&rows, &Settings { rank_tolerance: MIN_CONDITION, ..Settings::default() }).status == Status::Solved
}
