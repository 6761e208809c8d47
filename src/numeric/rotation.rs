//! Orientations of 3D rigid bodies in a simulation: Hamilton quaternions q = [w, x, y, z]
//! moved by world-frame rotation vectors, the fold of the rows' per-axis angular slots into
//! world vectors, and the implicit gyroscopic kick.
//!
//! A simulation state carries a 3D rigid body in generalised coordinates (DESIGN.md, "Rigid
//! bodies"): its three angular slots (`numeric::rows`) hold, in the first, the rotation
//! vector φ of the body since the start of the step (world frame) and ω (world frame); the
//! other two are zero. The orientation is q = exp(φ) ⊗ q₀ with q₀ the orientation at the
//! start of the step, so q̇ = ½ [0, ω] ⊗ q holds to second order in dt with φ̇ = ω (exact
//! for a fixed axis); at the start of every step φ is folded into q₀ and q₀ renormalised
//! ([`rebase`]). A correction Δφ of a projection is a rotation vector like any other, so
//! the projections work in the generalised coordinates (x, φ) and (v, ω) unchanged.
//!
//! The gyroscopic term. Explicit −ω × Iω makes an explicit integrator gain energy at every
//! step for a fast spinner (Avian #420, Bullet #357: the body spins up until it explodes).
//! Bullet's `btRigidBody::computeGyroscopicImpulseImplicit_Body` and Catto's GDC 2015
//! "Numerical Methods" take one Newton step of *implicit Euler* in the body frame: stable,
//! but it damps the spin (energy leaves at every step). Here a velocity kick of length h
//! takes the gyroscopic term at the *implicit midpoint* ω̄ = (ω + ω⁺)/2 in the body frame,
//! I(ω⁺ − ω)/h = τ + Jʷᵀλ − ω̄ × Iω̄, solved by Newton to rounding ([`kick`]). The implicit
//! midpoint rule keeps every quadratic invariant of the ODE it integrates, and both
//! T = ½ ωᵀIω and |L|² = |Iω|² are quadratic in the body-frame ω: a torque-free kick keeps
//! them exactly, and the drift between kicks (the body turned about ω itself) leaves the
//! body-frame ω unchanged. So a free body's energy and |L| stay at their initial values to
//! rounding over any number of steps, whatever ω dt is; only the direction of L in the world
//! carries the method's O(dt²) error. The kick is symmetric, so velocity Verlet built from
//! two half kicks stays second order and time-reversible.
//!
//! Not here: the rows (`numeric::rows`), the λ solve, the run loop (`numeric::simulate`).

use super::integrate::Vectors;
use super::rows::Rows;
use super::vector::dot;

/// The Hamilton product a ⊗ b of quaternions [w, x, y, z].
pub fn product(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// The unit quaternion exp(½ [0, φ]) of the rotation by |φ| about φ/|φ|.
pub fn exp(phi: [f64; 3]) -> [f64; 4] {
    let angle = dot(&phi, &phi).sqrt();
    let half = 0.5 * angle;
    // sin(|φ|/2)/|φ|, by its series near 0 (relative error below 1e-16 for |φ| < 1e-4).
    let s = if angle < 1e-4 { 0.5 - angle * angle / 48.0 } else { half.sin() / angle };
    [half.cos(), s * phi[0], s * phi[1], s * phi[2]]
}

/// φ̇ of the rotation vector φ of q = exp(φ) ⊗ q₀ turning at the world ω:
/// φ̇ = dexp⁻¹(φ) ω = ω − ½ φ × ω + c φ × (φ × ω), c = (1 − (θ/2) cot(θ/2))/θ², θ = |φ|
/// (the inverse of the left Jacobian of SO(3); c → 1/12 + θ²/720 as θ → 0). With φ̇ = ω
/// instead, RK4 would fall to second order in the orientation.
pub fn dexp_inv(phi: [f64; 3], w: [f64; 3]) -> [f64; 3] {
    let angle = dot(&phi, &phi).sqrt();
    let c = if angle < 1e-3 {
        1.0 / 12.0 + angle * angle / 720.0
    } else {
        let half = 0.5 * angle;
        (1.0 - half / half.tan()) / (angle * angle)
    };
    let pw = cross(phi, w);
    let ppw = cross(phi, pw);
    [0, 1, 2].map(|d| w[d] - 0.5 * pw[d] + c * ppw[d])
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// q / |q| (q unchanged when it is zero or not finite: the run's finiteness check names it).
pub fn normalise(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 && n.is_finite() { q.map(|x| x / n) } else { q }
}

/// The orientation exp(φ) ⊗ q₀ of a body turned by the world rotation vector φ from q₀.
pub fn turned(phi: [f64; 3], q0: [f64; 4]) -> [f64; 4] {
    product(exp(phi), q0)
}

/// Folds each body's rotation vector (slot `slots[r]` of `q`) into its orientation
/// `orientations[r]`, renormalised, and sets the rotation vector to zero: the start of a step.
pub fn rebase(orientations: &mut [[f64; 4]], slots: impl Iterator<Item = usize>, q: &mut Vectors) {
    for (q0, slot) in orientations.iter_mut().zip(slots) {
        *q0 = normalise(turned(q[slot], *q0));
        q[slot] = [0.0; 3];
    }
}

/// The rotation vector φ of the unit quaternion q = exp(φ): the inverse of [`exp`] on the
/// rotations by at most π (q and −q are the same rotation; the shorter turn is taken).
pub fn log(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = if q[0] < 0.0 { q.map(|c| -c) } else { q };
    let n = (x * x + y * y + z * z).sqrt();
    // |φ| = 2 atan2(|v|, w); |φ|/|v| → 2/w as |v| → 0 (atan2 keeps its relative accuracy).
    let s = if n > 0.0 { 2.0 * n.atan2(w) / n } else { 2.0 };
    [s * x, s * y, s * z]
}

/// The rotation vector of exp(`turn`) ⊗ exp(φ): a body at exp(φ) ⊗ q₀ turned by the world
/// rotation vector `turn` (the exact composition, where φ + turn holds to first order).
pub fn compose(turn: [f64; 3], phi: [f64; 3]) -> [f64; 3] {
    log(product(exp(turn), exp(phi)))
}

/// The world rotation vector of exp(`to`) ⊗ exp(−`from`): the turn from exp(`from`) ⊗ q₀ to
/// exp(`to`) ⊗ q₀.
pub fn between(from: [f64; 3], to: [f64; 3]) -> [f64; 3] {
    log(product(exp(to), exp(from.map(|x| -x))))
}

/// The world rotation vector of the turn from orientation `from` to `to`: log(to ⊗ from*).
pub fn between_orientations(from: [f64; 4], to: [f64; 4]) -> [f64; 3] {
    log(product(to, [from[0], -from[1], -from[2], -from[3]]))
}

/// State slots into the rows' slots, in place, with the principal axes `axes` of the rows
/// (`Rows::axes`; empty without 3D rigid bodies, and then nothing changes): a 3D body's
/// world vector x in its first slot becomes [eₖ·x, 0, 0] in its slot k. [`to_world`] is the
/// inverse (the axes are orthonormal).
pub fn to_axes(axes: &[[f64; 3]], x: &mut Vectors) {
    let Some(first) = axes.iter().position(|e| *e != [0.0; 3]) else { return };
    for g in (first..x.len()).step_by(3) {
        let w = x[g];
        for k in 0..3 {
            x[g + k] = [dot(&axes[g + k], &w), 0.0, 0.0];
        }
    }
}

/// The rows' slots into state slots, in place: [`fold`] with the axes given as a slice.
pub fn to_world(axes: &[[f64; 3]], x: &mut Vectors) {
    let Some(first) = axes.iter().position(|e| *e != [0.0; 3]) else { return };
    for g in (first..x.len()).step_by(3) {
        let mut w = [0.0; 3];
        for k in 0..3 {
            let (e, s) = (axes[g + k], x[g + k][0]);
            for d in 0..3 {
                w[d] += s * e[d];
            }
        }
        x[g] = w;
        x[g + 1] = [0.0; 3];
        x[g + 2] = [0.0; 3];
    }
}

/// The implicit-midpoint kick of one 3D rigid body over `h` in its principal frame (see the
/// file's note): from the body-frame ω, with the rows' per-axis 1/Iₖ and force
/// fₖ = τₖ − (ω_at × Iω_at)ₖ evaluated at the body-frame velocity `at`, whose explicit
/// gyroscopic part is replaced by the one at the midpoint. Returns the body-frame ω⁺.
pub fn kick_axes(inverse_inertia: [f64; 3], force: [f64; 3], at: [f64; 3], h: f64, w: [f64; 3]) -> [f64; 3] {
    let inertia = inverse_inertia.map(|x| 1.0 / x);
    let g_at = gyroscopic(inertia, at);
    let applied = [0, 1, 2].map(|k| inverse_inertia[k] * force[k] + g_at[k]);
    implicit_midpoint(inertia, h, w, applied)
}

/// The applied forces of `rows` in state slots: a linear slot's F as it is; a 3D body's
/// world torque τ = Σₖ (fₖ + (ω_b × Iω_b)ₖ) eₖ in its first slot (the rows' per-axis force
/// less its gyroscopic term, which does no work), zero in the other two.
pub fn applied(rows: &Rows, out: &mut Vectors) {
    out.copy_from_slice(&rows.force);
    let Some(first) = first_angular(rows) else { return };
    for g in (first..out.len()).step_by(3) {
        let inertia = [0, 1, 2].map(|k| 1.0 / rows.inverse_mass[g + k]);
        let w = [0, 1, 2].map(|k| rows.velocity[g + k][0]);
        let gyro = gyroscopic(inertia, w);
        let mut tau = [0.0; 3];
        for k in 0..3 {
            let s = rows.force[g + k][0] + inertia[k] * gyro[k];
            for (t, e) in tau.iter_mut().zip(rows.axes[g + k]) {
                *t += s * e;
            }
        }
        out[g] = tau;
        out[g + 1] = [0.0; 3];
        out[g + 2] = [0.0; 3];
    }
}

/// The first angular slot of the 3D rigid bodies in `rows` (the linear slots have no axis):
/// body r's slots are `first + 3r ..`; `None` without 3D rigid bodies.
pub fn first_angular(rows: &Rows) -> Option<usize> {
    rows.axes.iter().position(|e| *e != [0.0; 3])
}

/// Turns `x`, numbers over the rows' slots (an acceleration or a correction of the solve:
/// a 3D body's slot k holds its part along the principal axis eₖ), into state slots: the
/// world vector Σₖ xₖ eₖ in the body's first slot, zero in the other two. Without 3D rigid
/// bodies nothing changes.
pub fn fold(rows: &Rows, x: &mut Vectors) {
    let Some(first) = first_angular(rows) else { return };
    for g in (first..x.len()).step_by(3) {
        let mut w = [0.0; 3];
        for k in 0..3 {
            let (e, s) = (rows.axes[g + k], x[g + k][0]);
            for d in 0..3 {
                w[d] += s * e[d];
            }
        }
        x[g] = w;
        x[g + 1] = [0.0; 3];
        x[g + 2] = [0.0; 3];
    }
}

/// The rows' slot `slot` of the state vector `x` (state slots as [`fold`] writes them): a
/// linear slot as it is; a 3D body's slot k as [eₖ·ω, 0, 0].
pub fn unfold(rows: &Rows, first: Option<usize>, x: &Vectors, slot: usize) -> [f64; 3] {
    match first {
        Some(first) if slot >= first => {
            let g = first + 3 * ((slot - first) / 3);
            [dot(&rows.axes[slot], &x[g]), 0.0, 0.0]
        }
        _ => x[slot],
    }
}

/// Newton iterations of the implicit midpoint: from the explicit guess, two or three reach
/// rounding for ω dt up to about 1; more mean a step far too long to be accurate anyway.
const KICK_ITERATIONS: usize = 50;

/// A velocity kick v += h a over the state slots, with the gyroscopic term of each 3D rigid
/// body taken at the implicit midpoint (see the file's note). `a` is the acceleration from
/// the solve at `rows` (in state slots, [`fold`]), whose gyroscopic part was evaluated at
/// the velocities `at`; `rows` gives the bodies' principal axes and moments.
pub fn kick(rows: &Rows, h: f64, a: &Vectors, at: &Vectors, v: &mut Vectors) {
    let first = first_angular(rows).unwrap_or(v.len());
    for (v, a) in v[..first].iter_mut().zip(&a[..first]) {
        for d in 0..3 {
            v[d] += h * a[d];
        }
    }
    for g in (first..v.len()).step_by(3) {
        let e = [rows.axes[g], rows.axes[g + 1], rows.axes[g + 2]];
        let inertia = [0, 1, 2].map(|k| 1.0 / rows.inverse_mass[g + k]);
        let body = |w: &[f64; 3]| e.map(|ek| dot(&ek, w));
        let (w0, alpha, w_at) = (body(&v[g]), body(&a[g]), body(&at[g]));
        // The solve's α holds −I⁻¹(ω × Iω) at `at`: what is left is I⁻¹(τ + Jʷᵀλ).
        let g_at = gyroscopic(inertia, w_at);
        let applied = [0, 1, 2].map(|k| alpha[k] + g_at[k]);
        let w1 = implicit_midpoint(inertia, h, w0, applied);
        let mut world = [0.0; 3];
        for (k, ek) in e.iter().enumerate() {
            for d in 0..3 {
                world[d] += w1[k] * ek[d];
            }
        }
        v[g] = world;
    }
}

/// I⁻¹(ω × Iω) in the body frame: component k is (Iⱼ − Iᵢ) ωᵢ ωⱼ / Iₖ, (i, j) = (k+1, k+2).
fn gyroscopic(inertia: [f64; 3], w: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        (inertia[j] - inertia[i]) * w[i] * w[j] / inertia[k]
    })
}

/// ω⁺ with ω⁺ = ω + h (`applied` − I⁻¹(ω̄ × Iω̄)), ω̄ = (ω + ω⁺)/2, body frame, by Newton
/// on G(ω⁺) = ω⁺ − ω − h applied + h g(ω̄), G' = E + (h/2) g'(ω̄).
fn implicit_midpoint(inertia: [f64; 3], h: f64, w0: [f64; 3], applied: [f64; 3]) -> [f64; 3] {
    let g0 = gyroscopic(inertia, w0);
    let mut w = [0, 1, 2].map(|k| w0[k] + h * (applied[k] - g0[k]));
    let scale = w0.iter().chain(&w).fold(0.0f64, |m, x| m.max(x.abs()));
    for _ in 0..KICK_ITERATIONS {
        let mid = [0, 1, 2].map(|k| 0.5 * (w0[k] + w[k]));
        let gm = gyroscopic(inertia, mid);
        let residual = [0, 1, 2].map(|k| w[k] - w0[k] - h * (applied[k] - gm[k]));
        // ∂gₖ/∂ωᵢ = cₖ ωⱼ and ∂gₖ/∂ωⱼ = cₖ ωᵢ with cₖ = (Iⱼ − Iᵢ)/Iₖ.
        let mut jac = [[0.0; 3]; 3];
        for k in 0..3 {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let c = (inertia[j] - inertia[i]) / inertia[k];
            jac[k][k] = 1.0;
            jac[k][i] += 0.5 * h * c * mid[j];
            jac[k][j] += 0.5 * h * c * mid[i];
        }
        let Some(step) = solve3(jac, residual) else { break };
        let mut largest = 0.0f64;
        for k in 0..3 {
            w[k] -= step[k];
            largest = largest.max(step[k].abs());
        }
        if largest.is_nan() || largest <= 4.0 * f64::EPSILON * scale.max(f64::MIN_POSITIVE) {
            break;
        }
    }
    w
}

/// x with m x = r by Cramer's rule; `None` when m is singular or not finite.
fn solve3(m: [[f64; 3]; 3], r: [f64; 3]) -> Option<[f64; 3]> {
    let det3 = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let det = det3(m);
    if !(det.is_finite() && det != 0.0) {
        return None;
    }
    let mut x = [0.0; 3];
    for (c, xc) in x.iter_mut().enumerate() {
        let mut mc = m;
        for row in 0..3 {
            mc[row][c] = r[row];
        }
        *xc = det3(mc) / det;
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Property: exp(φ) rotates like Rodrigues' formula, and exp(a n) ⊗ exp(b n) = exp((a+b) n).
    #[test]
    fn exp_composes_about_one_axis() {
        let n = [0.6, -0.48, 0.64];
        let (a, b) = (0.7, -1.9);
        let lhs = product(exp(n.map(|x| a * x)), exp(n.map(|x| b * x)));
        let rhs = exp(n.map(|x| (a + b) * x));
        for k in 0..4 {
            assert!((lhs[k] - rhs[k]).abs() < 1e-15, "{lhs:?} vs {rhs:?}");
        }
        // The series branch meets the closed form at its threshold.
        let small = exp([1e-4, 0.0, 0.0]);
        assert!((small[1] - (0.5e-4f64).sin()).abs() < 1e-20);
    }

    /// Property: log inverts exp up to π, compose(a n, b n) = (a + b) n about one axis, and
    /// to_world undoes to_axes.
    #[test]
    fn log_inverts_exp_and_composes() {
        for phi in [[0.0, 0.0, 0.0], [1e-9, 0.0, -2e-9], [0.4, -1.1, 0.6], [2.0, 1.0, -1.5]] {
            let back = log(exp(phi));
            for d in 0..3 {
                assert!((back[d] - phi[d]).abs() < 1e-14, "{phi:?} → {back:?}");
            }
        }
        let n = [0.6, -0.48, 0.64];
        let c = compose(n.map(|x| 0.3 * x), n.map(|x| 0.9 * x));
        let between = between(n.map(|x| 0.9 * x), c);
        for d in 0..3 {
            assert!((c[d] - 1.2 * n[d]).abs() < 1e-15);
            assert!((between[d] - 0.3 * n[d]).abs() < 1e-15);
        }
        let q0 = normalise([0.3, -0.5, 0.1, 0.8]);
        let e = [0, 1, 2].map(|k| {
            let q = product(
                product(q0, [0.0, (k == 0) as u8 as f64, (k == 1) as u8 as f64, (k == 2) as u8 as f64]),
                [q0[0], -q0[1], -q0[2], -q0[3]],
            );
            [q[1], q[2], q[3]]
        });
        let axes = vec![[0.0; 3], e[0], e[1], e[2]];
        let x = vec![[1.0, 2.0, 3.0], [0.7, -1.3, 2.1], [0.0; 3], [0.0; 3]];
        let mut y = x.clone();
        to_axes(&axes, &mut y);
        assert_eq!(y[0], x[0]);
        to_world(&axes, &mut y);
        for d in 0..3 {
            assert!((y[1][d] - x[1][d]).abs() < 1e-15);
        }
    }

    /// Property: d/dt exp(φ(t)) ⊗ q₀ with φ̇ = dexp⁻¹(φ) ω is ½ [0, ω] ⊗ q (central
    /// differences), at a small and a large rotation vector.
    #[test]
    fn dexp_inv_moves_q_at_the_world_omega() {
        let q0 = normalise([0.3, -0.5, 0.1, 0.8]);
        let w = [0.7, -1.3, 2.1];
        for phi in [[1e-4, -2e-4, 3e-4], [0.4, -1.1, 0.6]] {
            let rate = dexp_inv(phi, w);
            let h = 1e-6;
            let at = |s: f64| turned([0, 1, 2].map(|d| phi[d] + s * rate[d]), q0);
            let (plus, minus) = (at(h), at(-h));
            let q = turned(phi, q0);
            let expected = product([0.0, w[0], w[1], w[2]], q);
            for k in 0..4 {
                let fd = (plus[k] - minus[k]) / (2.0 * h);
                assert!((fd - 0.5 * expected[k]).abs() < 1e-8, "φ = {phi:?}: {fd} vs {}", 0.5 * expected[k]);
            }
        }
    }

    /// Property: a torque-free implicit-midpoint kick keeps T and |L| to rounding, however
    /// long the step (the explicit kick does not).
    #[test]
    fn torque_free_kick_keeps_energy_and_momentum() {
        let inertia = [1.0, 2.0, 3.0];
        let w0 = [0.3, 20.0, 1.0];
        let energy = |w: [f64; 3]| (0..3).map(|k| inertia[k] * w[k] * w[k]).sum::<f64>();
        let momentum = |w: [f64; 3]| (0..3).map(|k| (inertia[k] * w[k]).powi(2)).sum::<f64>();
        for h in [1e-3, 1e-2, 0.05] {
            let w1 = implicit_midpoint(inertia, h, w0, [0.0; 3]);
            assert!((energy(w1) / energy(w0) - 1.0).abs() < 1e-13, "h = {h}: T {} → {}", energy(w0), energy(w1));
            assert!((momentum(w1) / momentum(w0) - 1.0).abs() < 1e-13, "h = {h}");
        }
        let g = gyroscopic(inertia, w0);
        let explicit = [0, 1, 2].map(|k| w0[k] - 0.05 * g[k]);
        assert!(energy(explicit) / energy(w0) - 1.0 > 1e-3);
    }
}
