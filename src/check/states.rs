//! Random states that satisfy the constraints, for judging formulas that are equal only on
//! the constraint manifold (`l^2` where lagrange writes `dot(r,r)`).
//!
//! A state starts at the scene's initial positions (or the origin) plus Gaussian noise, then:
//! 1. positions: Newton on C = 0 for every constraint (equalities and inequalities, all
//!    taken as active), each step the mass-weighted minimum-norm correction
//!    Δq = −M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁺ C, until |Cₖ|/‖Jₖ‖ is at rounding level;
//! 2. velocities: random, then projected onto Ċ = 0 in one exact step (Ċ is affine in v):
//!    Δv = −M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁺ Ċ, so J v = −∂C/∂t;
//! 3. forces and accelerations: random; `t` uniform in [0, 2]; parameters from the file;
//!    masses from the file, or uniform in [0.5, 2] when the file gives none.
//!
//! States where Newton does not converge, or where J M⁻¹ Jᵀ is ill-conditioned (a singular
//! configuration, e.g. the bead at the wire's centre), are thrown away and drawn again.
//!
//! The generator is a fixed-seed SplitMix64, so a check gives the same states every run.
//!
//! Not here: comparing values (`check`), files or text.

use crate::derive::Derivation;
use crate::expr::eval::{Env, Value};
use crate::expr::{Role, Symbol};
use crate::model::file::RawValue;
use crate::model::scene::Scene;
use crate::model::system::System;
use crate::numeric::random::Rng;
use crate::numeric::rows::{RowProgram, Rows};
use nalgebra::{DMatrix, DVector};
use std::collections::BTreeMap;

/// Newton iterations per attempt.
const NEWTON_STEPS: usize = 60;
/// Attempts per wanted state before giving up.
const ATTEMPTS_PER_STATE: usize = 20;
/// Smallest accepted σ_min/σ_max of J M⁻¹ Jᵀ.
const MIN_CONDITION: f64 = 1e-6;

/// `count` states on the constraint manifold, or why they could not be found.
pub fn sample(
    system: &mut System,
    derivation: &Derivation,
    parameters: &BTreeMap<String, RawValue>,
    scene: &Scene,
    count: usize,
) -> Result<Vec<Env>, String> {
    let program = RowProgram::new(system, derivation, &[]);
    let system: &System = system;
    let dim = system.dim();
    let mut base = Env::new();
    for (name, value) in parameters {
        let (s, v) = crate::model::scene::value_for(system, name, value, dim)?;
        base.set(s, v);
    }
    let mut start = vec![[0.0; 3]; system.bodies.len()];
    for &(s, v) in &scene.initial {
        match system.graph.symbol(s).role {
            Role::Position { body } => start[body] = v.vector().unwrap_or([0.0; 3]),
            Role::Mass { .. } => base.set(s, v),
            _ => {}
        }
    }
    let size = start.iter().map(norm).fold(1.0f64, f64::max);
    let masses: Vec<Symbol> = system
        .graph
        .symbols()
        .filter(|(s, info)| matches!(info.role, Role::Mass { .. }) && base.get(*s).is_none())
        .map(|(s, _)| s)
        .collect();
    let mut rng = Rng::new(0x5eed_1a94_a27e);
    let mut states = Vec::with_capacity(count);
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
            env.set(m, Value::Scalar(rng.uniform(0.5, 2.0)));
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
        }
        if project(system, &program, &mut env, size).is_some() {
            states.push(env);
        }
    }
    Ok(states)
}

/// Projects `env`'s positions onto C = 0 and velocities onto Ċ = 0; `None` if it fails.
fn project(system: &System, program: &RowProgram, env: &mut Env, size: f64) -> Option<()> {
    let mut converged = false;
    for _ in 0..NEWTON_STEPS {
        let rows = program.evaluate(system, env).ok()?;
        let residual = rows.rows.iter().map(|r| r.value.abs() / row_norm(r)).fold(0.0f64, f64::max);
        if !residual.is_finite() {
            return None;
        }
        if residual <= 1e-13 * size {
            converged = true;
            break;
        }
        let c: Vec<f64> = rows.rows.iter().map(|r| r.value).collect();
        let step = correction(&rows, &c)?;
        for (body, dq) in system.bodies.iter().zip(step) {
            let r = env.get(body.position)?.vector()?;
            env.set(body.position, Value::Vector([r[0] - dq[0], r[1] - dq[1], r[2] - dq[2]]));
        }
    }
    if !converged {
        return None;
    }
    // Ċ = J v + ∂C/∂t is affine in v: one minimum-norm step makes it zero.
    let rows = program.evaluate(system, env).ok()?;
    let rate: Vec<f64> = rows.rows.iter().map(|r| r.rate).collect();
    let step = correction(&rows, &rate)?;
    for (body, dv) in system.bodies.iter().zip(step) {
        let v = env.get(body.velocity)?.vector()?;
        env.set(body.velocity, Value::Vector([v[0] - dv[0], v[1] - dv[1], v[2] - dv[2]]));
    }
    let rows = program.evaluate(system, env).ok()?;
    let speed =
        system.bodies.iter().filter_map(|b| env.get(b.velocity)?.vector()).map(|v| norm(&v)).fold(1.0, f64::max);
    rows.rows.iter().all(|r| r.rate.abs() / row_norm(r) <= 1e-12 * speed).then_some(())
}

/// Δ per body = M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁺ e, or `None` when J M⁻¹ Jᵀ is ill-conditioned.
fn correction(rows: &Rows, e: &[f64]) -> Option<Vec<[f64; 3]>> {
    let k = rows.rows.len();
    let mut g = DMatrix::<f64>::zeros(k, k);
    for (p, rp) in rows.rows.iter().enumerate() {
        for (q, rq) in rows.rows.iter().enumerate() {
            for (bp, jp) in &rp.jacobian {
                for (bq, jq) in &rq.jacobian {
                    if bp == bq {
                        g[(p, q)] += dot(jp, jq) * rows.inverse_mass[*bp];
                    }
                }
            }
        }
    }
    let svd = g.svd(true, true);
    let largest = svd.singular_values.max();
    let smallest = svd.singular_values.min();
    if !(largest > 0.0 && smallest >= MIN_CONDITION * largest) {
        return None;
    }
    let mu = svd.solve(&DVector::from_column_slice(e), 0.0).ok()?;
    let mut delta = vec![[0.0; 3]; rows.inverse_mass.len()];
    for (p, row) in rows.rows.iter().enumerate() {
        for (b, j) in &row.jacobian {
            for d in 0..3 {
                delta[*b][d] += rows.inverse_mass[*b] * mu[p] * j[d];
            }
        }
    }
    Some(delta)
}

fn row_norm(r: &crate::numeric::rows::Row) -> f64 {
    r.jacobian.iter().map(|(_, j)| dot(j, j)).sum::<f64>().sqrt().max(f64::MIN_POSITIVE)
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: &[f64; 3]) -> f64 {
    dot(a, a).sqrt()
}
