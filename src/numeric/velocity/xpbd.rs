//! XPBD: extended position-based dynamics with compliance (M. Macklin, M. Müller,
//! N. Chentanez, "XPBD: Position-Based Simulation of Compliant Constrained Dynamics",
//! Motion in Games 2016), with small steps (M. Macklin et al., "Small Steps in Physics
//! Simulation", SCA 2019): substeps of one iteration by default.
//!
//! Per substep of h = dt/substeps:
//!
//!   predict     u ← v + h M⁻¹F;  x ← q + h u;  λ ← 0
//!   iterate     per row, in file order (eq. 18 of the paper, α̃ = α/h²):
//!               Δλ = (−C(x) − α̃ λ) / (J M⁻¹ Jᵀ + α̃),  x ← x + M⁻¹Jᵀ Δλ
//!   update      v ← (x − q)/h,  q ← x
//!
//! An inequality row clamps its accumulated λ at λ ≥ 0 (so it only pushes, and lets go once
//! C ≥ 0). The rows are evaluated once per iteration at x; within a sweep C(x) of a row is
//! its value there plus J·(x − x_evaluated) for the moves earlier rows made (first order;
//! the next iteration or substep evaluates again). The compliance α refers to C/κ, as the rows
//! do; α = 0 is a rigid row. λ/h² is the force the row applied.
//!
//! Not here: the run loop (`velocity::run`).

use super::Stepper;
use crate::numeric::dynamics::{Dynamics, SimError};
use crate::numeric::integrate::Vectors;
use crate::numeric::rotation;
use crate::numeric::rows::Rows;

/// One XPBD step (see the file's note).
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
    let alpha = settings.compliance / (h * h);
    s.prepared.load(&rows);
    for sub in 0..settings.substeps {
        // 3D rigid bodies: φ = 0 from here, the substep's turn exact (`Prepared::drift`).
        dynamics.rebase(q);
        let t1 = t + (sub + 1) as f64 * h;
        // Predict: the previous positions are kept, the new ones are x.
        s.prepared.to_axes(v);
        s.prepared.kick(v, h);
        s.prepared.to_world(v);
        s.saved.copy_from_slice(q);
        s.prepared.drift(q, v, h);
        s.impulse.iter_mut().for_each(|l| *l = 0.0);
        for _ in 0..settings.iterations() {
            dynamics.recycle(rows);
            rows = dynamics.rows(t1, q, v)?;
            s.prepared.load(&rows);
            let p = &s.prepared;
            // Positions in the rows' slots: a 3D body's rotation vector along its axes.
            p.to_axes(q);
            s.evaluated.copy_from_slice(q);
            for k in 0..p.len() {
                let m = p.effective_mass[k];
                if m == 0.0 {
                    continue;
                }
                // C(x) to first order from where the rows were evaluated.
                let mut c = p.value[k];
                for e in p.start[k]..p.start[k + 1] {
                    let b = p.body[e];
                    let (x, x0, j) = (&q[b], &s.evaluated[b], &p.jacobian[e]);
                    c += j[0] * (x[0] - x0[0]) + j[1] * (x[1] - x0[1]) + j[2] * (x[2] - x0[2]);
                }
                let old = s.impulse[k];
                let mut delta = (-c - alpha * old) / (1.0 / m + alpha);
                if p.inequality[k] {
                    delta = (old + delta).max(0.0) - old;
                }
                s.impulse[k] = old + delta;
                p.apply(k, q, delta);
            }
            p.to_world(q);
        }
        // v = (x − q)/h; a 3D body's ω is its turn over the substep over h.
        for ((v, x), x0) in v.iter_mut().zip(q.iter()).zip(&s.saved) {
            for d in 0..3 {
                v[d] = (x[d] - x0[d]) / h;
            }
        }
        if let Some(first) = s.prepared.first {
            for g in (first..q.len()).step_by(3) {
                v[g] = rotation::between(s.saved[g], q[g]).map(|x| x / h);
            }
        }
        if sub + 1 < settings.substeps {
            // The next substep's forces at the new state.
            dynamics.recycle(rows);
            rows = dynamics.rows(t1, q, v)?;
            s.prepared.load(&rows);
        }
    }
    dynamics.recycle(rows);
    Ok(())
}
