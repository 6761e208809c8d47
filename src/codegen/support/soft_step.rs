//! Written into modules generated with `--solver soft-step`: Box2D v3's soft step (E. Catto,
//! "Solver2D", 2024; Box2D v3 `b2SolverStage_*`) on the module's rows, the operations and
//! their order those of the library's `numeric::velocity::soft_step`.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as part of every
//! generated module of `tests/generate_step.rs` (it uses the module's items, so it is not a
//! module of its own). Not here: the rows (generated), the shared pieces (`step.rs`, `sweep.rs`).

/// One soft step of `dt` with Box2D's defaults (`StepSettings::default()`); `impulses` is the
/// warm-start storage, the accumulated impulse of each row (for C/κ; P/h ≈ λ), kept by the
/// caller from one step to the next (start from zeros).
pub fn step(s: &mut State, impulses: &mut [f64; CONSTRAINTS], dt: f64) {
    step_with(s, impulses, dt, &StepSettings::default());
}

/// One soft step of `dt` in `settings.substeps` substeps of h = dt/substeps, each:
///
///   integrate velocities   u ← v + h M⁻¹F             (F: `applied_forces`, the scene's)
///   warm start             u ← u + M⁻¹Jᵀ P
///   solve (with bias)      per row, in file order: ΔP = −s_m·m_eff·(J u + ∂C/∂t + b) − s_i·P
///   integrate positions    q ← q + h u
///   relax (without bias)   per row: ΔP = −m_eff·(J u + ∂C/∂t)
///
/// over the slots of `numeric::rows` (a rigid body's angle and ω too; a 3D body's ω along its
/// principal axes, its kick with the gyroscopic term at the implicit midpoint, its turn
/// exact), with the rows evaluated where each substep starts; then restitution for inequality rows
/// that closed faster than the threshold. Equality rows: b = biasRate·C/κ with the joint
/// softness. Inequality rows: apart (C > 0) rigid and speculative, b = C/(κh); penetrating
/// the contact softness, b = max(biasRate·C/κ, −3); P ≥ 0 on the accumulated impulse. The
/// state's time advances by h per substep; its force fields are not read.
pub fn step_with(s: &mut State, impulses: &mut [f64; CONSTRAINTS], dt: f64, settings: &StepSettings) {
    let mut p = Prepared::zeroed();
    prepare(s, &mut p);
    steps(s, impulses, &mut p, dt, settings);
}

/// `step_with` from the rows `p` at the state `s`, leaving in `p` the rows at the state it
/// ends at (a substep's end, before its relax pass: where the library's next step starts).
fn steps(s: &mut State, impulses: &mut [f64; CONSTRAINTS], p: &mut Prepared<DIM>, dt: f64, settings: &StepSettings) {
    let h = dt / settings.substeps as f64;
    let iterations = settings.iterations;
    let joint = settings.joint_softness(h);
    let contact = settings.contact_softness(h);
    if !settings.warm_start {
        impulses.iter_mut().for_each(|p| *p = 0.0);
    }
    let t = time(s);
    let (mut q, mut v, mut q0) = get(s);
    // In the rows' slots (a 3D body's ω along its principal axes) for the sweeps.
    p.to_axes(&mut v);
    // Ċ at the step's start, restitution's closing speed (read only with restitution).
    let mut start_rate = [0.0; CONSTRAINTS];
    if settings.restitution > 0.0 {
        for (k, rate) in start_rate.iter_mut().enumerate() {
            *rate = p.rate(k, &v);
        }
    }
    for sub in 0..settings.substeps {
        // 3D rigid bodies: the orientation folded in and renormalised, φ = 0 from here.
        rebase(&mut q0, &mut q, sub == 0);
        p.kick(&mut v, h);
        p.warm_start(&mut v, impulses);
        for _ in 0..iterations {
            // Box2D's `useBias = true`.
            let pr = &*p;
            pr.sweep(&mut v, impulses, |k, c| {
                if !INEQUALITY[k] {
                    (joint.bias_rate * c, joint)
                } else if c > 0.0 {
                    (c / h, Softness::RIGID)
                } else {
                    ((contact.bias_rate * c).max(-CONTACT_SPEED), contact)
                }
            });
        }
        p.to_world(&mut v);
        p.drift(&mut q, &v, h);
        // The rows after the drift read no velocity where `KEEP`: written once, at the end.
        if KEEP {
            put_moved(s, t + (sub + 1) as f64 * h, &q, &q0);
        } else {
            put(s, t + (sub + 1) as f64 * h, &q, &v, &q0);
        }
        prepare_moved(s, p);
        p.to_axes(&mut v);
        if settings.relax {
            let pr = &*p;
            for _ in 0..iterations {
                pr.sweep(&mut v, impulses, |k, c| {
                    if INEQUALITY[k] && c > 0.0 { (c / h, Softness::RIGID) } else { (0.0, Softness::RIGID) }
                });
            }
        }
    }
    if settings.restitution > 0.0 {
        for k in 0..p.len() {
            let m = p.effective_mass[k];
            let closing = start_rate[k];
            if !INEQUALITY[k] || m == 0.0 || closing > -settings.restitution_threshold || impulses[k] <= 0.0 {
                continue;
            }
            let old = impulses[k];
            let delta = (old - m * (p.rate(k, &v) + settings.restitution * closing)).max(0.0) - old;
            impulses[k] = old + delta;
            p.apply(k, &mut v, delta);
        }
    }
    p.to_world(&mut v);
    put(s, time(s), &q, &v, &q0);
}
