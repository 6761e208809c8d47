//! Written into modules generated with `--solver` that have no 3D rigid body: how the step
//! moves the slots — the kick of the external forces u += h M⁻¹F and the drift q += h u, over
//! every slot alike (a 2D rigid body's angular slot holds θ, ω, 1/I and τ, so θ += h ω and
//! ω += h τ/I come from the same loops), as the library's `numeric::velocity::Prepared::kick`
//! and `drift` run them without 3D bodies. The state's slots are the rows' slots here, so
//! the changes between them do nothing, and there is no orientation to rebase.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as
//! part of every generated module of `tests/generate_step.rs`. Not here: 3D rigid bodies
//! (`motion_3d.rs`), the rows (`step.rs`).

#[allow(dead_code)]
impl<const D: usize> Prepared<D> {
    /// u += h M⁻¹ F: the external forces (and torques) over one substep.
    fn kick(&self, u: &mut [[f64; D]], h: f64) {
        for ((u, f), w) in u.iter_mut().zip(&self.force).zip(&self.inverse_mass) {
            for d in 0..D {
                u[d] += h * w * f[d];
            }
        }
    }

    /// State slots into the rows' slots: the same slots without 3D rigid bodies.
    fn to_axes(&self, _x: &mut [[f64; D]]) {}

    /// The rows' slots into state slots: the same slots without 3D rigid bodies.
    fn to_world(&self, _x: &mut [[f64; D]]) {}

    /// q += h u.
    fn drift(&self, q: &mut [[f64; D]], u: &[[f64; D]], h: f64) {
        for (q, u) in q.iter_mut().zip(u) {
            for d in 0..D {
                q[d] += h * u[d];
            }
        }
    }
}

/// A correction over the rows' slots into state slots (the rows' `axes`): nothing to turn
/// without 3D rigid bodies.
#[allow(dead_code)]
fn fold<const D: usize>(_axes: &[[f64; D]], _x: &mut [[f64; D]]) {}

/// The start of a substep: no orientation to fold in without 3D rigid bodies.
#[allow(dead_code)]
fn rebase<const D: usize>(_orientations: &mut [[f64; 4]], _q: &mut [[f64; D]], _fresh: bool) {}
