//! Stability limits of the velocity-level step: at a state the step is a map
//! x = (q, v, P) ↦ x⁺ (P the warm-start impulses, when warm starting; q and v with a rigid
//! body's angle and angular velocity), and for point masses under rows of fixed direction it
//! is affine, x⁺ = M x + c; it is stable when the spectral
//! radius ρ(M) ≤ 1. M is built column by column by central differences of the step
//! (exact for an affine map up to round-off; the linearisation otherwise), its eigenvalues
//! come from nalgebra (real Schur form), and the largest stable hertz is found by bisection
//! on the joint stiffness with the quarter-substep-rate cap lifted.
//!
//! Catto's two-particle test (inverse masses 0.167 and 0.000995 hanging in a line, h = 1/60,
//! ζ = 0, one substep, one iteration, rows in file order; `constraints/solvers/two_particles.toml`)
//! gives 13.565 Hz without relax and 20.943 Hz with it; he found 13.5 and 20.5 by running
//! the simulation, which overstates both (slow growth looks stable for 10⁴ steps).
//!
//! Not here: the steps themselves (one file per solver), reports.

use super::{Settings, Solver, Stepper};
use crate::model::system::System;
use crate::numeric::dynamics::{Dynamics, SimError};
use nalgebra::DMatrix;

/// Spectral radii up to 1 + this count as stable (round-off of a neutral mode).
pub const STABLE_TOLERANCE: f64 = 1e-9;

/// Whether the warm-start impulses are part of the step's state.
fn carries_impulses(s: &Settings) -> bool {
    s.warm_start && matches!(s.solver, Solver::SoftStep | Solver::Pgs)
}

/// The components of each slot in the state: `dim` for a body's position, 1 for a rigid
/// body's angle (component 0 of its angular slot, `numeric::rows`).
fn slot_components(system: &System) -> Vec<usize> {
    let dim = system.dim();
    let angles = system.bodies.iter().filter(|b| b.rigid.is_some()).count();
    std::iter::repeat_n(dim, system.bodies.len()).chain(std::iter::repeat_n(1, angles)).collect()
}

/// The length of the state vector x = (q, v[, P]) of `system`.
pub fn state_len(system: &System, s: &Settings) -> usize {
    let rows = system.constraints.len();
    2 * slot_components(system).iter().sum::<usize>() + if carries_impulses(s) { rows } else { 0 }
}

/// The step's linear part at (t, q, v) with warm-start impulses `impulse`: the matrix
/// ∂x⁺/∂x over x = (q, v[, P]) (a body's components up to the system's dimension, a rigid
/// body's angle and angular velocity one each).
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
        let r = dynamics.rows(t, &qs, &vs)?;
        stepper.step(dynamics, t, &mut qs, &mut vs, r)?;
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

/// ρ(M): the largest modulus of the eigenvalues.
pub fn spectral_radius(m: &DMatrix<f64>) -> f64 {
    m.complex_eigenvalues().iter().map(|z| z.norm()).fold(0.0, f64::max)
}

/// ρ of the soft step (or whichever solver `s` names) at (t, q, v) with zero warm-start
/// impulses, at stiffness `hertz` uncapped.
pub fn radius_at(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &[[f64; 3]],
    v: &[[f64; 3]],
    s: &Settings,
    hertz: f64,
) -> Result<f64, SimError> {
    let settings = Settings { hertz, cap_hertz: false, ..*s };
    let impulse = vec![0.0; dynamics.system().constraints.len()];
    Ok(spectral_radius(&step_jacobian(dynamics, t, q, v, &impulse, &settings)?))
}

/// Stiffnesses searched up to this (Hz): far beyond any substep rate an engine runs.
pub const MAX_HERTZ: f64 = 1e4;

/// The largest stiffness (Hz, uncapped) at which the step of `s` is stable at (t, q, v), to
/// 1e-6 relative: `None` when it is unstable already at 10⁻³ Hz or still stable at
/// [`MAX_HERTZ`].
pub fn largest_stable_hertz(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &[[f64; 3]],
    v: &[[f64; 3]],
    s: &Settings,
) -> Result<Option<f64>, SimError> {
    let stable = |h: f64, d: &mut Dynamics<'_>| -> Result<bool, SimError> {
        Ok(radius_at(d, t, q, v, s, h)? <= 1.0 + STABLE_TOLERANCE)
    };
    let (mut lo, mut hi) = (1e-3, 1.0);
    if !stable(lo, dynamics)? {
        return Ok(None);
    }
    // Bracket by doubling, then bisect.
    while stable(hi, dynamics)? {
        lo = hi;
        hi *= 2.0;
        if hi > MAX_HERTZ {
            return Ok(None);
        }
    }
    while hi - lo > 1e-6 * hi {
        let mid = 0.5 * (lo + hi);
        if stable(mid, dynamics)? {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(Some(lo))
}
