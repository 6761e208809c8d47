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
//! This is the solver of box2d_lite and of Solver2D's `s2Solve_PGS`, where the Baumgarte
//! bias goes into the accumulated impulse. With warm starting that is unstable on the long
//! chain, the joint grid and Catto's two particles, and it is the method, not a slip: the
//! accumulated impulse carries last step's bias impulse β·m_eff·C/h, the warm start applies
//! it again, and a Gauss–Seidel sweep that has not converged does not take it back (the two
//! particles' rows couple with cosine (w₁/(w₁ + w₂))^½ ≈ 0.997: a sweep removes 0.6 % of the
//! error), so the correction is summed over the steps and overshoots. The spectral radius of the step at the two particles' rest state
//! (`velocity::stability`, `tests/velocity.rs`) measures it: 1.21 with warm starting at 4
//! substeps × 8 iterations (1.05 at 1 × 8), exactly 1 (a neutral mode) without warm starting,
//! with β = 0, or with 32 iterations. Box2D v2.4 keeps the bias out of the accumulated impulse
//! (its joints and contacts correct positions in a separate pass, `SolvePositionConstraints`)
//! and v3 softens it and removes it with the relax pass; here `--no-warm-start` or more
//! `--iterations` run those scenes.
//!
//! Not here: the run loop (`velocity::run`).

use super::{Softness, Stepper};
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
        // 3D rigid bodies: φ = 0 from here, the substep's turn exact (`Prepared::drift`).
        dynamics.rebase(q);
        let p = &s.prepared;
        // In the rows' slots (a 3D body's ω along its principal axes) for the sweeps.
        p.to_axes(v);
        p.kick(v, h);
        p.warm_start(v, &s.impulse);
        for _ in 0..settings.iterations() {
            p.sweep(v, &mut s.impulse, |k, c| {
                let bias = if p.inequality[k] && c > 0.0 { c / h } else { beta * c / h };
                (bias, Softness::RIGID)
            });
        }
        p.to_world(v);
        p.drift(q, v, h);
        dynamics.recycle(rows);
        rows = dynamics.rows(t + (sub + 1) as f64 * h, q, v)?;
        s.prepared.load(&rows);
    }
    dynamics.recycle(rows);
    Ok(())
}
