//! Written into modules generated with `--solver pgs`: projected Gauss–Seidel, sequential
//! impulses with Baumgarte bias and accumulated clamping (E. Catto, "Iterative Dynamics with
//! Temporal Coherence", 2005; Box2D v2.4), the operations and their order those of the
//! library's `numeric::velocity::pgs`.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as part of every
//! generated module of `tests/generate_step.rs` (it uses the module's items, so it is not a
//! module of its own). Not here: the rows (generated), the shared pieces (`step.rs`, `sweep.rs`).

/// One PGS step of `dt` with the defaults (`StepSettings::default()`: 4 substeps, 8
/// iterations, β = 0.2); `impulses` is the warm-start storage, the accumulated impulse of
/// each row (for C/κ; P/h ≈ λ), kept by the caller from one step to the next (start from zeros).
pub fn step(s: &mut State, impulses: &mut [f64; CONSTRAINTS], dt: f64) {
    step_with(s, impulses, dt, &StepSettings::default());
}

/// One PGS step of `dt` in `settings.substeps` substeps of h = dt/substeps, each: u ← v +
/// h M⁻¹F (F: `applied_forces`, the scene's); warm start u ← u + M⁻¹Jᵀ P; `iterations`
/// sweeps over the rows in file order, row k taking ΔP = −m_eff·(J u + ∂C/∂t + b) with
/// b = β·C/(κh) (an inequality row apart, C > 0, is speculative: b = C/(κh)), an inequality
/// row clamping its accumulated impulse at P ≥ 0; then q ← q + h u, and the rows evaluated
/// again. Over the slots of `numeric::rows`: a rigid body's angle and ω too (a 3D body's ω
/// along its principal axes, its kick with the gyroscopic term at the implicit midpoint, its
/// turn exact). No softness and no relax pass. The state's time advances by h per substep; its
/// force fields are not read.
pub fn step_with(s: &mut State, impulses: &mut [f64; CONSTRAINTS], dt: f64, settings: &StepSettings) {
    let mut p = Prepared::zeroed();
    prepare(s, &mut p);
    steps(s, impulses, &mut p, dt, settings);
}

/// `step_with` from the rows `p` at the state `s`, leaving in `p` the rows at the state it
/// ends at (its last substep's end).
fn steps(s: &mut State, impulses: &mut [f64; CONSTRAINTS], p: &mut Prepared<DIM>, dt: f64, settings: &StepSettings) {
    let h = dt / settings.substeps as f64;
    let beta = settings.baumgarte;
    if !settings.warm_start {
        impulses.iter_mut().for_each(|p| *p = 0.0);
    }
    let t = time(s);
    let (mut q, mut v, mut q0) = get(s);
    for sub in 0..settings.substeps {
        // 3D rigid bodies: the orientation folded in and renormalised, φ = 0 from here.
        rebase(&mut q0, &mut q, sub == 0);
        // In the rows' slots (a 3D body's ω along its principal axes) for the sweeps.
        p.to_axes(&mut v);
        p.kick(&mut v, h);
        p.warm_start(&mut v, impulses);
        let pr = &*p;
        for _ in 0..settings.iterations {
            pr.sweep(&mut v, impulses, |k, c| {
                let bias = if INEQUALITY[k] && c > 0.0 { c / h } else { beta * c / h };
                (bias, Softness::RIGID)
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
    }
    if KEEP {
        put(s, time(s), &q, &v, &q0);
    }
}
