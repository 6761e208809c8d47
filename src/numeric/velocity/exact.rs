//! The exact velocity-level solve, the impulse twin of DESIGN step 6: per substep of
//! h = dt/substeps, with u = v + h M⁻¹F the velocities after the external forces,
//!
//!   A P = −(J u + ∂C/∂t + C/h),   A = J M⁻¹ Jᵀ,   then u ← u + M⁻¹Jᵀ P,  q ← q + h u,
//!
//! so every equality row ends the substep with Ċ = −C/h (a full position correction, the
//! limit of Baumgarte's bias at β = 1) and inequality rows solve the complementarity problem
//! P ≥ 0, J u + C/h ≥ 0, P·(J u + C/h) = 0 (rows already heading apart with the bias are
//! left out). The solve is `numeric::solve`'s (band Cholesky on chains, sparse L D Lᵀ on
//! grids, dense on small blocks, Clarabel and Murty for inequality rows, through the run's
//! solve cache): the rows get F = 0 and the bias c set to the
//! right-hand side, as `numeric::stabilize` does for its projections, so its "accelerations"
//! M⁻¹JᵀP are the velocity changes. Only the last substep's P is reported
//! (`Stepper::lambda`), at the steps whose λ is wanted (`Settings::lambda_at`), so the other
//! substeps (and the last where λ is not wanted) and the projections take the step alone
//! (`Dynamics::correct_step`), and on a redundant block the body-space factor serves (a rigid
//! grid) that step is the velocity change without its split among the rows
//! (`Dynamics::set_velocity_space`, `numeric::gram`: one substitution an application
//! instead of two, the same velocity change to rounding). After each substep the positions are projected onto
//! C = 0 with the mass-weighted minimum-norm step, to 10⁻¹³ of the scene's size: the bias
//! C/h alone leaves the O(h²) curvature error of the linearised step, the projection makes
//! the joints exact. The projection first iterates along the substep's J
//! (`stabilize::project_positions_along`, a quasi-Newton iteration as SHAKE's, positions
//! only), so the cache serves every iteration with the velocity solve's factor; where that
//! is slow or diverges (a large substep), or with inequality rows, Newton from the same
//! positions (`stabilize::project_positions`: J and a factorisation per iteration) does it.
//! Scenes of fewer than a thousand rows take Newton alone: the two land on different
//! points of C = 0 (apart by about |C(q⁺)|·‖ΔJ‖/‖J‖ a substep: below the step's error,
//! not round-off), and small scenes keep the trajectory the generated exact step
//! reproduces.
//!
//! Not here: the iterative solvers; the acceleration-level run (`numeric::simulate`).

use super::{Stepper, drift_turning, kick};
use crate::numeric::dynamics::{Dynamics, SimError};
use crate::numeric::integrate::Vectors;
use crate::numeric::rotation::{first_angular, to_axes, to_world};
use crate::numeric::rows::Rows;
use crate::numeric::stabilize::{Inequalities, project_positions, project_positions_along};
use crate::numeric::vector::length_scale;

/// Relative tolerance and iteration cap of the projection after each substep.
const PROJECTION_TOLERANCE: f64 = 1e-13;
const PROJECTION_ITERATIONS: usize = 20;
/// Iteration cap of the quasi-Newton projection along the substep's J before Newton takes
/// over: it halves the residual at least per iteration, so from a substep's drift it either
/// converges within a few or is slower than Newton.
const ALONG_ITERATIONS: usize = 10;
/// The fewest rows for which the projection iterates along the substep's J first. Its limit
/// is another point of C = 0 than Newton's (they part by about |C(q⁺)|·‖ΔJ‖/‖J‖ a
/// substep, below the step's own error but not round-off), so small scenes keep Newton's
/// trajectory, the one the generated exact step (`generate --solver exact`) reproduces;
/// there a factorisation is cheap next to the row evaluations anyway. Grids and long chains
/// (thousands of rows, where the factorisations dominate a swinging step) take the cheaper
/// path.
const ALONG_MIN_ROWS: usize = 1000;

/// One exact velocity-level step (see the file's note).
pub fn step(
    s: &mut Stepper,
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &mut Vectors,
    v: &mut Vectors,
    mut rows: Rows,
) -> Result<(), SimError> {
    let h = s.settings.substep();
    // Positions only: a rigid body's angle is no length.
    let length = length_scale(&q[..dynamics.system().bodies.len()]);
    // Every substep's projection aims for it; the run loop reports a step that ends farther.
    let bound = PROJECTION_TOLERANCE * length;
    s.projection_bound = Some(bound);
    // The steps of the velocity solves and the projections need no λ: on a redundant block
    // the velocity change alone (one substitution an application instead of two).
    dynamics.set_velocity_space(true);
    for sub in 0..s.settings.substeps {
        // 3D rigid bodies: φ = 0 from here, the substep's turn exact (`Prepared::drift`).
        dynamics.rebase(q);
        let first = first_angular(&rows);
        // In the rows' slots (a 3D body's ω along its principal axes), as the solve's are.
        to_axes(&rows.axes, v);
        kick(v, h, first, &rows.inverse_mass, &rows.force, &rows.velocity);
        // Ċ at u, read from the rows where they are (each row's numbers once, no copy into
        // `Prepared`, which keeps only the entries' layout: Ċ's order of summation).
        let rates = s.prepared.rates(&rows, v);
        for (row, rate) in rows.rows.iter_mut().zip(rates) {
            // Target: ΔĊ = −(J u + ∂C/∂t + C/h), i.e. c = J u + ∂C/∂t + C/h.
            let bias = rate + row.value / h;
            if row.inequality && bias >= 0.0 {
                // Heading apart with the bias: P = 0 (left out of the solve).
                row.value = f64::MAX;
                row.rate = f64::MAX;
                row.bias = 0.0;
            } else {
                row.value = 0.0;
                row.rate = 0.0;
                row.bias = bias;
            }
        }
        rows.force.iter_mut().for_each(|f| *f = [0.0; 3]);
        // Through the run's solve cache (`Dynamics::correct`, the projection's too): rows
        // on the same bodies keep their factor's analysis (band places, or the sparse
        // order and pattern of L), so each substep's solve is a numeric factorisation.
        // Only the last substep's impulses are reported (`Stepper::lambda`), and only when
        // the step's λ is wanted (`Stepper::wants_impulse`): the others take the step alone
        // (on a redundant block the velocity change without its split among the rows,
        // `Dynamics::set_velocity_space`).
        let change = if sub + 1 == s.settings.substeps && s.wants_impulse {
            let solution = dynamics.correct(&rows);
            s.impulse.copy_from_slice(&solution.lambda);
            &solution.acceleration
        } else {
            &*dynamics.correct_step(&rows, None)
        };
        for (u, du) in v.iter_mut().zip(change) {
            for d in 0..3 {
                if du[d].is_finite() {
                    u[d] += du[d];
                }
            }
        }
        to_world(&rows.axes, v);
        drift_turning(q, v, h, first);
        let t1 = t + (sub + 1) as f64 * h;
        // Along the substep's J first: the cache serves each iteration with the velocity
        // solve's factor; Newton (a factorisation per iteration) where that is slow.
        let along = if rows.rows.len() >= ALONG_MIN_ROWS {
            project_positions_along(dynamics, t1, q, v, &mut rows, bound, ALONG_ITERATIONS, &mut s.saved)?
        } else {
            None
        };
        dynamics.recycle(rows);
        rows = match along {
            Some((projected, _)) => projected,
            None => project_positions(dynamics, t1, q, v, bound, PROJECTION_ITERATIONS, Inequalities::Violated)?.0,
        };
    }
    dynamics.recycle(rows);
    Ok(())
}
