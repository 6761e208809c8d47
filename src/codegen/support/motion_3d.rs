//! Written into modules generated with `--solver` that have 3D rigid bodies: how the step
//! moves the slots, as the library's `numeric::velocity::Prepared` and `numeric::rotation`
//! do it, the same operations in the same order. A 3D rigid body has three slots, one per
//! principal axis eₖ = R(q) eₖ (1/Iₖ, eₖ·ω, eₖ·τ − (ω_b × I ω_b)ₖ, Jʷ·eₖ: `axis_slots`); the
//! state keeps the world ω and, in the first slot, the rotation vector φ of the body since
//! its orientation q₀ at the substep's start (`rebase`: q₀ ← exp(φ) ⊗ q₀ renormalised, φ = 0;
//! the state's q is exp(φ) ⊗ q₀, `turned`). The sweeps and the solve act on ω along the axes
//! (`to_axes`, back with `to_world`); the kick takes the torque and the gyroscopic term at the
//! implicit midpoint in the body frame (`kick_axes`, Newton on a 3×3: a free body keeps its
//! energy and |L|), and the drift turns the body exactly, φ ← log(exp(h ω) ⊗ exp(φ)).
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as
//! part of the generated 3D modules of `tests/generate_step.rs`. Not here: point masses and
//! 2D rigid bodies (`motion.rs`), the rows (`step.rs`).

/// The Hamilton product a ⊗ b of quaternions [w, x, y, z].
fn product(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// a·b of world vectors, as the library's `numeric::vector::dot` sums it.
fn dot3(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The unit quaternion exp(½ [0, φ]) of the rotation by |φ| about φ/|φ|.
fn exp(phi: [f64; 3]) -> [f64; 4] {
    let angle = dot3(&phi, &phi).sqrt();
    let half = 0.5 * angle;
    // sin(|φ|/2)/|φ|, by its series near 0 (relative error below 1e-16 for |φ| < 1e-4).
    let s = if angle < 1e-4 { 0.5 - angle * angle / 48.0 } else { half.sin() / angle };
    [half.cos(), s * phi[0], s * phi[1], s * phi[2]]
}

/// q / |q| (q unchanged when it is zero or not finite).
fn normalise(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    if n > 0.0 && n.is_finite() { q.map(|x| x / n) } else { q }
}

/// The orientation exp(φ) ⊗ q₀ of a body turned by the world rotation vector φ from q₀.
fn turned(phi: [f64; 3], q0: [f64; 4]) -> [f64; 4] {
    product(exp(phi), q0)
}

/// The rotation vector φ of the unit quaternion q = exp(φ), the shorter turn.
fn log(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = if q[0] < 0.0 { q.map(|c| -c) } else { q };
    let n = (x * x + y * y + z * z).sqrt();
    // |φ| = 2 atan2(|v|, w); |φ|/|v| → 2/w as |v| → 0.
    let s = if n > 0.0 { 2.0 * n.atan2(w) / n } else { 2.0 };
    [s * x, s * y, s * z]
}

/// The rotation vector of exp(`turn`) ⊗ exp(φ).
fn compose(turn: [f64; 3], phi: [f64; 3]) -> [f64; 3] {
    log(product(exp(turn), exp(phi)))
}

/// The start of a substep: each 3D rigid body's rotation vector φ (its first slot of `q`)
/// folded into its orientation, q₀ ← exp(φ) ⊗ q₀ renormalised, and φ set to zero. `fresh`:
/// the first substep of a step, where q₀ is the state's q, already exp(φ) ⊗ q₀ of the last
/// step (the library's product), so it is only renormalised.
fn rebase(orientations: &mut [[f64; 4]], q: &mut [[f64; 3]], fresh: bool) {
    let first = q.len() - 3 * orientations.len();
    for (r, q0) in orientations.iter_mut().enumerate() {
        let slot = first + 3 * r;
        *q0 = if fresh { normalise(*q0) } else { normalise(turned(q[slot], *q0)) };
        q[slot] = [0.0; 3];
    }
}

/// The three slots of a 3D rigid body with principal moments `moments`, world ω `w` and
/// torque `tau`, and principal axes `e` (the library's `RowProgram::fill`): per axis k,
/// 1/Iₖ, ωₖ = eₖ·ω, and eₖ·τ − (ω_b × I ω_b)ₖ with ω_b = (eⱼ·ω)ⱼ.
fn axis_slots(moments: [f64; 3], w: [f64; 3], tau: [f64; 3], e: [[f64; 3]; 3]) -> [(f64, [f64; 3], [f64; 3]); 3] {
    let wb = e.map(|ej| dot3(&ej, &w));
    let iw = [moments[0] * wb[0], moments[1] * wb[1], moments[2] * wb[2]];
    [0, 1, 2].map(|k| {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let gyroscopic = wb[i] * iw[j] - wb[j] * iw[i];
        (1.0 / moments[k], [wb[k], 0.0, 0.0], [dot3(&e[k], &tau) - gyroscopic, 0.0, 0.0])
    })
}

/// `axis_slots` appended to the exact step's rows (`step_rows`).
#[allow(dead_code)]
fn push_axis_slots(r: &mut StepRows<3>, moments: [f64; 3], w: [f64; 3], tau: [f64; 3], e: [[f64; 3]; 3]) {
    for (k, (inverse, velocity, force)) in axis_slots(moments, w, tau, e).into_iter().enumerate() {
        r.inverse_mass.push(inverse);
        r.velocity.push(velocity);
        r.force.push(force);
        r.axes.push(e[k]);
    }
}

/// The first slot of the 3D rigid bodies (the linear slots have no axis).
fn first_angular(axes: &[[f64; 3]]) -> Option<usize> {
    axes.iter().position(|e| *e != [0.0; 3])
}

/// State slots into the rows' slots, in place: a 3D body's world vector x in its first slot
/// becomes [eₖ·x, 0, 0] in its slot k.
fn to_axes(axes: &[[f64; 3]], x: &mut [[f64; 3]]) {
    let Some(first) = first_angular(axes) else { return };
    for g in (first..x.len()).step_by(3) {
        let w = x[g];
        for k in 0..3 {
            x[g + k] = [dot3(&axes[g + k], &w), 0.0, 0.0];
        }
    }
}

/// The rows' slots into state slots, in place: Σₖ xₖ eₖ in a 3D body's first slot, zero in
/// the other two (a correction of the solve, or ω).
fn fold(axes: &[[f64; 3]], x: &mut [[f64; 3]]) {
    let Some(first) = first_angular(axes) else { return };
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

/// I⁻¹(ω × Iω) in the body frame: component k is (Iⱼ − Iᵢ) ωᵢ ωⱼ / Iₖ, (i, j) = (k+1, k+2).
fn gyroscopic(inertia: [f64; 3], w: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        (inertia[j] - inertia[i]) * w[i] * w[j] / inertia[k]
    })
}

/// Newton iterations of the implicit midpoint (two or three reach rounding for ω h up to 1).
const KICK_ITERATIONS: usize = 50;

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

/// The implicit-midpoint kick of one 3D rigid body over `h` in its principal frame: from the
/// body-frame ω `w`, with the rows' per-axis 1/Iₖ and force fₖ = τₖ − (ω_at × Iω_at)ₖ taken at
/// the body-frame velocity `at`, whose explicit gyroscopic part is replaced by the midpoint's.
fn kick_axes(inverse_inertia: [f64; 3], force: [f64; 3], at: [f64; 3], h: f64, w: [f64; 3]) -> [f64; 3] {
    let inertia = inverse_inertia.map(|x| 1.0 / x);
    let g_at = gyroscopic(inertia, at);
    let applied = [0, 1, 2].map(|k| inverse_inertia[k] * force[k] + g_at[k]);
    implicit_midpoint(inertia, h, w, applied)
}

#[allow(dead_code)]
impl Prepared<3> {
    /// `axis_slots` written into the prepared rows from slot `first` on (`prepare`), the
    /// body-frame ω into the evaluated velocities `v`.
    #[allow(clippy::too_many_arguments)]
    fn axis_slots(
        &mut self,
        v: &mut [[f64; 3]; SLOTS],
        first: usize,
        moments: [f64; 3],
        w: [f64; 3],
        tau: [f64; 3],
        e: [[f64; 3]; 3],
    ) {
        for (k, (inverse, velocity, force)) in axis_slots(moments, w, tau, e).into_iter().enumerate() {
            self.inverse_mass[first + k] = inverse;
            v[first + k] = velocity;
            self.force[first + k] = force;
            self.axes[first + k] = e[k];
        }
    }

    /// u += h M⁻¹ F over the rows' slots; a 3D rigid body's torque and gyroscopic term go
    /// through the implicit-midpoint kick in its principal frame (`kick_axes`).
    fn kick(&self, u: &mut [[f64; 3]], h: f64) {
        let first = self.first.unwrap_or(u.len());
        for ((u, f), w) in u[..first].iter_mut().zip(&self.force).zip(&self.inverse_mass) {
            for d in 0..3 {
                u[d] += h * w * f[d];
            }
        }
        for g in (first..u.len()).step_by(3) {
            let axis = |x: &[[f64; 3]]| [x[g][0], x[g + 1][0], x[g + 2][0]];
            let w = [self.inverse_mass[g], self.inverse_mass[g + 1], self.inverse_mass[g + 2]];
            let w1 = kick_axes(w, axis(&self.force), axis(&self.velocity), h, axis(u));
            for k in 0..3 {
                u[g + k] = [w1[k], 0.0, 0.0];
            }
        }
    }

    /// State slots into the rows' slots (a 3D body's world ω along its principal axes).
    fn to_axes(&self, x: &mut [[f64; 3]]) {
        to_axes(&self.axes, x);
    }

    /// The inverse of `to_axes`.
    fn to_world(&self, x: &mut [[f64; 3]]) {
        fold(&self.axes, x);
    }

    /// q += h u over state slots, a 3D rigid body's rotation vector turned exactly by h ω:
    /// φ ← log(exp(h ω) ⊗ exp(φ)).
    fn drift(&self, q: &mut [[f64; 3]], u: &[[f64; 3]], h: f64) {
        let first = self.first.unwrap_or(q.len());
        for (q, u) in q[..first].iter_mut().zip(&u[..first]) {
            for d in 0..3 {
                q[d] += h * u[d];
            }
        }
        for g in (first..q.len()).step_by(3) {
            q[g] = compose(u[g].map(|x| h * x), q[g]);
        }
    }
}
