//! Box2D v3's soft step (E. Catto, "Solver2D", 2024; Box2D v3 `src/solver.c`
//! `b2SolverStage_*`, `src/joint.c`, `src/distance_joint.c`, `src/contact_solver.c`), for
//! the rows of any derived constraint.
//!
//! One step of dt is `substeps` substeps of h = dt/substeps, each (as `b2SolverStep` orders
//! its stages):
//!
//!   integrate velocities   u ← v + h M⁻¹F
//!   warm start             u ← u + M⁻¹Jᵀ P   (P: the accumulated impulses, kept across substeps and steps)
//!   solve (with bias)      per row, in file order: ΔP = −s_m·m_eff·(J u + ∂C/∂t + b) − s_i·P
//!   integrate positions    q ← q + h u
//!   relax (without bias)   per row: ΔP = −m_eff·(J u + ∂C/∂t)
//!
//! and after the last substep, restitution for contacts that closed faster than the
//! threshold (`b2ApplyRestitution`: ΔP = −m_eff·(Ċ + e·Ċ₀), P ≥ 0). Softness from
//! `b2MakeSoft` ([`Softness::new`]): equality rows use the joint softness (`--hertz`,
//! `--damping-ratio`, capped at a quarter of the substep rate: Box2D's `jointSoftness`),
//! b = biasRate·C. Inequality rows follow `b2SolveContact`: apart (C > 0) they are rigid and
//! speculative, b = C/h; penetrating they use the contact softness (30 Hz, ζ = 10) with
//! b = max(biasRate·C, −3 m/s); the relax pass keeps the speculative bias only. Every
//! inequality row clamps its accumulated impulse at P ≥ 0.
//!
//! The rows are evaluated at the positions each substep starts from, and again after the
//! positions move (for the relax pass and the next substep): one evaluation per substep, as
//! Box2D recomputes a joint's separation from the bodies' current positions.
//!
//! Not here: the run loop (`velocity::run`), the stability analysis (`velocity::stability`).

use super::{CONTACT_SPEED, Softness, Stepper};
use crate::numeric::dynamics::{Dynamics, SimError};
use crate::numeric::integrate::Vectors;
use crate::numeric::rows::Rows;

/// One soft step (see the file's note).
pub fn step(
    s: &mut Stepper,
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &mut Vectors,
    v: &mut Vectors,
    mut rows: Rows,
) -> Result<(), SimError> {
    let settings = s.settings;
    let h = settings.substep();
    let iterations = settings.iterations();
    let joint = settings.joint_softness();
    let contact = settings.contact_softness();
    if !settings.warm_start {
        s.impulse.iter_mut().for_each(|p| *p = 0.0);
    }
    s.prepared.load(&rows);
    s.prepared.to_axes(v);
    for k in 0..s.prepared.len() {
        s.start_rate[k] = s.prepared.rate(k, v);
    }
    for sub in 0..settings.substeps {
        // 3D rigid bodies: φ = 0 from here, the substep's turn exact (`Prepared::drift`).
        dynamics.rebase(q);
        let p = &s.prepared;
        // v is in the rows' slots here (a 3D body's ω along its principal axes).
        p.kick(v, h);
        p.warm_start(v, &s.impulse);
        for _ in 0..iterations {
            // Box2D's `useBias = true`.
            p.sweep(v, &mut s.impulse, |k, c| {
                if !p.inequality[k] {
                    (joint.bias_rate * c, joint)
                } else if c > 0.0 {
                    (c / h, Softness::RIGID)
                } else {
                    ((contact.bias_rate * c).max(-CONTACT_SPEED), contact)
                }
            });
        }
        p.to_world(v);
        p.drift(q, v, h);
        let t1 = t + (sub + 1) as f64 * h;
        dynamics.recycle(rows);
        rows = dynamics.rows(t1, q, v)?;
        s.prepared.load(&rows);
        let p = &s.prepared;
        p.to_axes(v);
        if settings.relax {
            for _ in 0..iterations {
                p.sweep(v, &mut s.impulse, |k, c| {
                    if p.inequality[k] && c > 0.0 { (c / h, Softness::RIGID) } else { (0.0, Softness::RIGID) }
                });
            }
        }
    }
    if settings.restitution > 0.0 {
        let p = &s.prepared;
        for k in 0..p.len() {
            let m = p.effective_mass[k];
            let closing = s.start_rate[k];
            if !p.inequality[k] || m == 0.0 || closing > -settings.restitution_threshold || s.impulse[k] <= 0.0 {
                continue;
            }
            let old = s.impulse[k];
            let delta = (old - m * (p.rate(k, v) + settings.restitution * closing)).max(0.0) - old;
            s.impulse[k] = old + delta;
            p.apply(k, v, delta);
        }
    }
    s.prepared.to_world(v);
    dynamics.recycle(rows);
    Ok(())
}
