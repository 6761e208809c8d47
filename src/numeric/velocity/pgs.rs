//! Projected Gauss–Seidel: sequential impulses with Baumgarte bias and accumulated clamping
//! (E. Catto, "Iterative Dynamics with Temporal Coherence", GDC 2005; Box2D v2.4
//! `b2_contact_solver.cpp`, `b2_distance_joint.cpp`), the "PGS" of Catto's Solver2D.
//!
//! Per substep of h = dt/substeps: u ← v + h M⁻¹F; warm start u ← u + M⁻¹Jᵀ P; `iterations`
//! sweeps over the rows in file order, each row taking
//!
//!   ΔP = −m_eff·(J u + ∂C/∂t + b),   b = β·C/h   (β = 0.2, Box2D v2.4's `b2_baumgarte`)
//!
//! (an inequality row apart from its surface, C > 0, is speculative: b = C/h), an inequality
//! row clamping its accumulated impulse at P ≥ 0; then q ← q + h u. No softness and no relax
//! pass: the bias velocity stays in the bodies, which is what the soft step's relax removes.
//!
//! Not here: the run loop (`velocity::run`).

use super::{Softness, Stepper, drift};
use crate::numeric::dynamics::{Dynamics, SimError};
use crate::numeric::integrate::Vectors;
use crate::numeric::rows::Rows;

/// One PGS step (see the file's note).
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
    let beta = settings.baumgarte;
    if !settings.warm_start {
        s.impulse.iter_mut().for_each(|p| *p = 0.0);
    }
    s.prepared.load(&rows);
    for sub in 0..settings.substeps {
        let p = &s.prepared;
        p.kick(v, h);
        p.warm_start(v, &s.impulse);
        for _ in 0..settings.iterations() {
            p.sweep(v, &mut s.impulse, |k, c| {
                let bias = if p.inequality[k] && c > 0.0 { c / h } else { beta * c / h };
                (bias, Softness::RIGID)
            });
        }
        drift(q, v, h);
        dynamics.recycle(rows);
        rows = dynamics.rows(t + (sub + 1) as f64 * h, q, v)?;
        s.prepared.load(&rows);
    }
    dynamics.recycle(rows);
    Ok(())
}
