//! Stability limits of the velocity-level step: at a state the step is a map
//! x = (q, v, P) ↦ x⁺ (P the warm-start impulses, when warm starting; q and v with a rigid
//! body's angle and angular velocity), and for point masses under rows of fixed direction it
//! is affine, x⁺ = M x + c; it is stable when the spectral
//! radius ρ(M) ≤ 1. M is built column by column by central differences of the step
//! (exact for an affine map up to round-off; the linearisation otherwise), its eigenvalues
//! come from nalgebra (real Schur form), and the largest stable hertz is found by bisection
//! on the joint stiffness with the quarter-substep-rate cap lifted.
//!
//! A 3D rigid body enters x as its world rotation vector φ and world ω (three components
//! each, the first of its angular slots, `numeric::rows`), φ measured from the orientation
//! the analysis starts at: the step folds φ into the dynamics' orientation at every substep
//! (`Dynamics::rebase`), so each evaluation starts from that orientation again and turns
//! its result back into a rotation vector from it. Without that the columns were taken at
//! orientations that drifted from one evaluation to the next.
//!
//! The Schur iteration is bounded: nalgebra's `complex_eigenvalues` iterates until it
//! converges, and on some matrices it never does (`bench --solvers` on a 3D ball joint ran
//! for over ten minutes in it). A matrix that is not finite, or whose iteration does not
//! converge, has no radius here, and the limit is then [`Limit::NoRadius`], said so in the
//! reports, never a number.
//!
//! Not for 3D rigid bodies ([`Limit::Rigid3d`]): their step is nonlinear in φ and ω (the
//! turn, the gyroscopic kick), so central differences leave an error in M, and the neutral
//! modes of a free turn are defective eigenvalues at 1, which an error ε moves by about √ε:
//! on the ball joint's scene ρ came out 1 + 2.6e-6 at 10⁻³ Hz where the Schur iteration
//! converged at all (allowed a hundred times the sweeps), far past the tolerance. A body spinning about its
//! intermediate axis is also unstable in itself, which ρ would count against the solver.
//! The 3D state is still right here (`step_jacobian`), for anyone who looks at M.
//!
//! Catto's two-particle test (inverse masses 0.167 and 0.000995 hanging in a line, h = 1/60,
//! ζ = 0, one substep, one iteration, rows in file order; `constraints/solvers/two_particles.toml`)
//! gives 13.565 Hz without relax and 20.943 Hz with it; he found 13.5 and 20.5 by running
//! the simulation, which overstates both (slow growth looks stable for 10⁴ steps).
//!
//! Only at a state of rest in equilibrium ([`at_rest_in_equilibrium`]): there the step's
//! linearisation is the solver's own stability (Lyapunov's first method at a fixed point),
//! and a stable stiffness keeps ρ ≤ 1. At a state in motion ρ also carries the growth of
//! the motion itself — nearby trajectories of a pendulum released from the horizontal part
//! by up to 3.6·10⁻⁴ a step: ρ − 1 from 5·10⁻⁹ at 10⁻³ Hz to 3.6·10⁻⁴ at 1 Hz with h = 1/60,
//! one substep and relax —, so a bound found there would be a number
//! about the motion, not about the solver (it gave the pendulum "0.007 Hz" while every run
//! at 60 Hz holds): [`Limit::Moving`] says so instead. Nor with inequality rows
//! ([`Limit::Contacts`]): at rest a contact touches, where the clamp P ≥ 0 makes the step
//! not differentiable, and the central differences straddle it (ρ came out 19 on the stack
//! of three discs at every stiffness).
//!
//! Not here: the steps themselves (one file per solver), reports.

use super::{Settings, Solver, Stepper};
use crate::model::system::System;
use crate::numeric::dynamics::{Dynamics, SimError};
use crate::numeric::rotation::{between_orientations, turned};
use crate::numeric::rows::{angular_bodies, angular_width};
use crate::numeric::vector::safe_norm;
use nalgebra::DMatrix;

/// Spectral radii up to 1 + this count as stable (round-off of a neutral mode).
pub const STABLE_TOLERANCE: f64 = 1e-9;

/// Whether the warm-start impulses are part of the step's state.
fn carries_impulses(s: &Settings) -> bool {
    s.warm_start && matches!(s.solver, Solver::SoftStep | Solver::Pgs)
}

/// The components of each slot in the state, one entry per slot of `numeric::rows`: `dim`
/// for a body's position; a 2D rigid body's angle 1; a 3D rigid body's rotation vector 3 in
/// its first angular slot and 0 in the other two (they hold nothing in a state).
fn slot_components(system: &System) -> Vec<usize> {
    let dim = system.dim();
    let rigid = angular_bodies(system).count();
    let angular: &[usize] = if angular_width(system) == 3 { &[3, 0, 0] } else { &[1] };
    let bodies = std::iter::repeat_n(dim, system.bodies.len());
    bodies.chain(std::iter::repeat_n(angular, rigid).flatten().copied()).collect()
}

/// Whether `system` has a 3D rigid body (whose stability is not analysed, [`Limit::Rigid3d`]).
pub fn has_rigid_3d(system: &System) -> bool {
    angular_width(system) == 3 && angular_bodies(system).next().is_some()
}

/// Whether `system` has an inequality row (a contact, a rope).
pub fn has_inequalities(system: &System) -> bool {
    system.constraints.iter().any(|c| c.inequality)
}

/// The length of the state vector x = (q, v[, P]) of `system`.
pub fn state_len(system: &System, s: &Settings) -> usize {
    let rows = system.constraints.len();
    2 * slot_components(system).iter().sum::<usize>() + if carries_impulses(s) { rows } else { 0 }
}

/// The step's linear part at (t, q, v) with warm-start impulses `impulse`: the matrix
/// ∂x⁺/∂x over x = (q, v[, P]) (a body's components up to the system's dimension, a 2D rigid
/// body's angle and angular velocity one each, a 3D one's rotation vector from the
/// dynamics' orientation at the call and its ω three each). The dynamics' orientations are
/// as they were when it returns.
pub fn step_jacobian(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &[[f64; 3]],
    v: &[[f64; 3]],
    impulse: &[f64],
    s: &Settings,
) -> Result<DMatrix<f64>, SimError> {
    let components = slot_components(dynamics.system());
    let (slots, rows) = (q.len(), impulse.len());
    let settings = Settings { restitution: 0.0, ..*s };
    let n = state_len(dynamics.system(), &settings);
    // The slots' components, in the order of x: the positions, then the velocities.
    let flat = |x: &[[f64; 3]], out: &mut Vec<f64>| {
        out.extend(x.iter().zip(&components).flat_map(|(x, &c)| x[..c].iter().copied()));
    };
    let half: usize = components.iter().sum();
    let mut x0 = Vec::with_capacity(n);
    flat(q, &mut x0);
    flat(v, &mut x0);
    if carries_impulses(&settings) {
        x0.extend_from_slice(impulse);
    }
    let mut stepper = Stepper::new(settings, rows, slots);
    let (mut qs, mut vs) = (vec![[0.0; 3]; slots], vec![[0.0; 3]; slots]);
    // Each 3D rigid body's orientation at the call and its rotation vector's slot.
    let base = dynamics.orientations().to_vec();
    let width = angular_width(dynamics.system());
    let turning: Vec<usize> = (0..base.len()).map(|r| dynamics.system().bodies.len() + r * width).collect();
    let mut image = |x: &[f64], out: &mut Vec<f64>| -> Result<(), SimError> {
        let mut at = 0;
        for (i, &c) in components.iter().enumerate() {
            qs[i][..c].copy_from_slice(&x[at..at + c]);
            vs[i][..c].copy_from_slice(&x[half + at..half + at + c]);
            at += c;
        }
        if carries_impulses(&settings) {
            stepper.impulse.copy_from_slice(&x[2 * half..]);
        } else {
            stepper.impulse.iter_mut().for_each(|p| *p = 0.0);
        }
        let r = dynamics.rows(t, &qs, &vs);
        let stepped = r.and_then(|r| stepper.step(dynamics, t, &mut qs, &mut vs, r));
        // The step rebased each 3D body: its φ is from the last substep's orientation. As a
        // rotation vector from the base again, and the base restored for the next image.
        for (r, &slot) in turning.iter().enumerate() {
            let now = turned(qs[slot], dynamics.orientations()[r]);
            qs[slot] = between_orientations(base[r], now);
        }
        dynamics.set_orientations(&base);
        stepped?;
        out.clear();
        flat(&qs, out);
        flat(&vs, out);
        if carries_impulses(&settings) {
            out.extend_from_slice(&stepper.impulse);
        }
        Ok(())
    };
    let mut m = DMatrix::zeros(n, n);
    let (mut plus, mut minus, mut x) = (Vec::new(), Vec::new(), x0.clone());
    for col in 0..n {
        let eps = 1e-6 * x0[col].abs().max(1.0);
        x[col] = x0[col] + eps;
        image(&x, &mut plus)?;
        x[col] = x0[col] - eps;
        image(&x, &mut minus)?;
        x[col] = x0[col];
        for row in 0..n {
            m[(row, col)] = (plus[row] - minus[row]) / (2.0 * eps);
        }
    }
    Ok(m)
}

/// ρ(M): the largest modulus of the eigenvalues; `None` where an entry of M is not finite or
/// the Schur iteration does not converge within [`SCHUR_SWEEPS`] sweeps per row (nalgebra's
/// own `complex_eigenvalues` would iterate for ever).
pub fn spectral_radius(m: &DMatrix<f64>) -> Option<f64> {
    if !m.iter().all(|x| x.is_finite()) {
        return None;
    }
    let schur = nalgebra::Schur::try_new(m.clone(), f64::EPSILON, SCHUR_SWEEPS * m.nrows().max(1))?;
    let radius = schur.complex_eigenvalues().iter().map(|z| z.norm()).fold(0.0, f64::max);
    radius.is_finite().then_some(radius)
}

/// QR sweeps allowed per row of M: LAPACK's `dhseqr` allows 30; a matrix that needs more
/// is one the shifts cannot split, not one that is nearly there.
pub const SCHUR_SWEEPS: usize = 30;

/// ρ of the soft step (or whichever solver `s` names) at (t, q, v) with zero warm-start
/// impulses, at stiffness `hertz` uncapped; `None` where it has none ([`spectral_radius`]).
pub fn radius_at(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &[[f64; 3]],
    v: &[[f64; 3]],
    s: &Settings,
    hertz: f64,
) -> Result<Option<f64>, SimError> {
    let settings = Settings { hertz, cap_hertz: false, ..*s };
    let impulse = vec![0.0; dynamics.system().constraints.len()];
    Ok(spectral_radius(&step_jacobian(dynamics, t, q, v, &impulse, &settings)?))
}

/// The soft step's stability limit at a state ([`largest_stable_hertz`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Limit {
    /// Stable up to this stiffness (Hz, to 1e-6 relative), unstable just above it.
    Hertz(f64),
    /// Unstable already at the softest stiffness searched, 10⁻³ Hz.
    UnstableAtAll,
    /// Still stable at [`MAX_HERTZ`].
    StableThroughout,
    /// The state is not at rest in equilibrium ([`at_rest_in_equilibrium`]): not analysed.
    Moving,
    /// The scene has inequality rows: not analysed (the module's note says why).
    Contacts,
    /// At some stiffness of the search the radius could not be computed
    /// ([`spectral_radius`]: a step that is not finite, or a Schur iteration that did not
    /// converge within its bound, as on `constraints/solvers/hanging_chain.toml`'s 500
    /// numbers at every stiffness).
    NoRadius,
    /// The scene has 3D rigid bodies: not analysed (the module's note says why).
    Rigid3d,
}

impl Limit {
    /// The stiffness of [`Limit::Hertz`].
    pub fn hertz(self) -> Option<f64> {
        match self {
            Limit::Hertz(h) => Some(h),
            Limit::UnstableAtAll
            | Limit::StableThroughout
            | Limit::Moving
            | Limit::Contacts
            | Limit::NoRadius
            | Limit::Rigid3d => None,
        }
    }
}

/// Accelerations up to this fraction of the largest free acceleration |M⁻¹F| count as
/// equilibrium: the exact solve balances the forces to round-off, some 10⁻¹⁵ of them.
pub const EQUILIBRIUM_TOLERANCE: f64 = 1e-9;

/// Whether (t, q, v) is at rest in equilibrium: every velocity zero, and the exact
/// acceleration-level solve's accelerations within [`EQUILIBRIUM_TOLERANCE`] of the largest
/// free acceleration |M⁻¹F| (zero where no force acts). Catto's two particles hanging in
/// their line are; a pendulum released from the horizontal is not.
pub fn at_rest_in_equilibrium(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &[[f64; 3]],
    v: &[[f64; 3]],
) -> Result<bool, SimError> {
    if v.iter().flatten().any(|&x| x != 0.0) {
        return Ok(false);
    }
    let mut rows = dynamics.rows(t, q, v)?;
    let free = rows.force.iter().zip(&rows.inverse_mass).map(|(f, w)| safe_norm(f) * w).fold(0.0, f64::max);
    let largest = dynamics.solve(&mut rows).acceleration.iter().map(safe_norm).fold(0.0, f64::max);
    dynamics.recycle(rows);
    // A NaN (a failed solve) is no equilibrium.
    Ok(largest <= EQUILIBRIUM_TOLERANCE * free)
}

/// Stiffnesses searched up to this (Hz): far beyond any substep rate an engine runs.
pub const MAX_HERTZ: f64 = 1e4;

/// The largest stiffness (Hz, uncapped) at which the step of `s` is stable at (t, q, v), to
/// 1e-6 relative ([`Limit`]).
pub fn largest_stable_hertz(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &[[f64; 3]],
    v: &[[f64; 3]],
    s: &Settings,
) -> Result<Limit, SimError> {
    if has_rigid_3d(dynamics.system()) {
        return Ok(Limit::Rigid3d);
    }
    if has_inequalities(dynamics.system()) {
        return Ok(Limit::Contacts);
    }
    if !at_rest_in_equilibrium(dynamics, t, q, v)? {
        return Ok(Limit::Moving);
    }
    // Some(stable) at stiffness h, None where the step has no radius there.
    let stable = |h: f64, d: &mut Dynamics<'_>| -> Result<Option<bool>, SimError> {
        Ok(radius_at(d, t, q, v, s, h)?.map(|rho| rho <= 1.0 + STABLE_TOLERANCE))
    };
    let (mut lo, mut hi) = (1e-3, 1.0);
    match stable(lo, dynamics)? {
        None => return Ok(Limit::NoRadius),
        Some(false) => return Ok(Limit::UnstableAtAll),
        Some(true) => {}
    }
    // Bracket by doubling, then bisect.
    loop {
        match stable(hi, dynamics)? {
            None => return Ok(Limit::NoRadius),
            Some(false) => break,
            Some(true) => {}
        }
        lo = hi;
        hi *= 2.0;
        if hi > MAX_HERTZ {
            return Ok(Limit::StableThroughout);
        }
    }
    while hi - lo > 1e-6 * hi {
        let mid = 0.5 * (lo + hi);
        match stable(mid, dynamics)? {
            None => return Ok(Limit::NoRadius),
            Some(true) => lo = mid,
            Some(false) => hi = mid,
        }
    }
    Ok(Limit::Hertz(lo))
}
