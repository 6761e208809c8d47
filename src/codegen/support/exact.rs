//! Written into modules generated with `--solver exact`: the exact velocity-level solve, the
//! impulse twin of `lagrange solve`'s A λ + b = 0, as the library's
//! `numeric::velocity::exact` runs it — per substep A P = −(J u + ∂C/∂t + C/h) through the
//! module's rows' solve (`solve_rows`: scaled rows, contact states, P ≥ 0 on inequality
//! rows, the minimum-norm P of redundant rows), then a Newton projection of the positions
//! onto C = 0.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as part of every
//! generated module of `tests/generate_step.rs` (it uses the module's items, so it is not a
//! module of its own). Not here: the rows (generated), the shared pieces (`step.rs`), the
//! solve itself (`rows.rs`).

/// Relative tolerance (of the scene's length) and iteration cap of the projection after
/// each substep.
const PROJECTION_TOLERANCE: f64 = 1e-13;
const PROJECTION_ITERATIONS: usize = 20;

/// One exact velocity-level step of `dt` (`StepSettings::default()`: 4 substeps); `impulses`
/// receives the impulse of each row over the last substep (for C/κ; P/h ≈ λ). The exact
/// solve needs no warm start: the impulses are an output.
pub fn step(s: &mut State, impulses: &mut [f64; CONSTRAINTS], dt: f64) {
    step_with(s, impulses, dt, &StepSettings::default());
}

/// One exact step of `dt` in `settings.substeps` substeps of h = dt/substeps, each: u ← v +
/// h M⁻¹F (F: `applied_forces`, the scene's); A P = −(J u + ∂C/∂t + C/(κh)) with A = J M⁻¹ Jᵀ,
/// an inequality row heading apart with its bias left out (P = 0) and the others P ≥ 0 by
/// complementarity; u ← u + M⁻¹JᵀP; q ← q + h u (over the slots of `numeric::rows`: a rigid
/// body's angle and ω too, a 3D body's turn exact); then Newton with the mass-weighted
/// minimum-norm step Δq = M⁻¹Jᵀμ, (J M⁻¹ Jᵀ) μ = −C/κ, on the equalities and the violated
/// inequalities, until every such row is within 10⁻¹³ of the scene's length of its surface
/// (at most 20 iterations). Only `substeps` of the settings is read.
pub fn step_with(s: &mut State, impulses: &mut [f64; CONSTRAINTS], dt: f64, settings: &StepSettings) {
    let h = dt / settings.substeps as f64;
    let t = time(s);
    let (mut q, mut v, mut q0) = get(s);
    // Positions only: a rigid body's angle is no length.
    let length = length_scale(&positions(s));
    let unforced = [[0.0; DIM]; SLOTS];
    for sub in 0..settings.substeps {
        // 3D rigid bodies: the orientation folded in and renormalised, φ = 0 from here.
        rebase(&mut q0, &mut q, sub == 0);
        let r = step_rows(s);
        let p = Prepared::new(&r);
        let StepRows { mut rows, inverse_mass: w, velocity: before, .. } = r;
        // In the rows' slots (a 3D body's ω along its principal axes), as the solve's are.
        p.to_axes(&mut v);
        p.kick(&mut v, h);
        for (k, row) in rows.iter_mut().enumerate() {
            // Target: ΔĊ = −(J u + ∂C/∂t + C/h), i.e. c = J u + ∂C/∂t + C/h.
            let bias = p.rate(k, &v) + p.value[k] / h;
            if row.inequality && bias >= 0.0 {
                leave_out(row);
            } else {
                enforce(row, bias);
            }
        }
        let solution = solve_rows(&rows, &w, &before, &unforced, length);
        for (u, du) in v.iter_mut().zip(&solution.acceleration) {
            for d in 0..DIM {
                if du[d].is_finite() {
                    u[d] += du[d];
                }
            }
        }
        impulses.copy_from_slice(&solution.lambda);
        p.to_world(&mut v);
        p.drift(&mut q, &v, h);
        put(s, t + (sub + 1) as f64 * h, &q, &v, &q0);
        project(s, (&mut q, &v, &q0), PROJECTION_TOLERANCE * length, PROJECTION_ITERATIONS);
    }
}

/// Marks a row as left out of a solve: an inactive inequality (P = 0).
fn leave_out<const D: usize>(row: &mut Row<D>) {
    row.inequality = true;
    row.value = f64::MAX;
    row.rate = f64::MAX;
    row.bias = 0.0;
}

/// Marks a row as enforced with target ΔX = −`bias`.
fn enforce<const D: usize>(row: &mut Row<D>, bias: f64) {
    row.value = 0.0;
    row.rate = 0.0;
    row.bias = bias;
}

/// A row's first-order distance to its surface, (C/κ)/‖J‖ (±∞ where J = 0 and C ≠ 0).
fn distance<const D: usize>(row: &Row<D>) -> f64 {
    let flat: Vec<f64> = row.jacobian.iter().flat_map(|(_, j)| j.iter().copied()).collect();
    let n = safe_norm(&flat);
    if n > 0.0 && n.is_finite() {
        row.value / n
    } else if row.value == 0.0 {
        0.0
    } else {
        f64::INFINITY.copysign(row.value)
    }
}

/// Newton onto C = 0 (equalities and violated inequalities, μ ≥ 0 on those) until every
/// such row is within `bound` of its surface or `max_iterations` are spent; `q` (the state's
/// slots, a 3D body's rotation vector since `q0`) and the state move together, `v` stays.
fn project(
    s: &mut State,
    (q, v, q0): (&mut [[f64; DIM]; SLOTS], &[[f64; DIM]; SLOTS], &[[f64; 4]; ORIENTATIONS]),
    bound: f64,
    max_iterations: usize,
) {
    let unforced = [[0.0; DIM]; SLOTS];
    let mut iterations = 0;
    loop {
        let StepRows { mut rows, inverse_mass: w, velocity: at, axes, .. } = step_rows(s);
        let enforced = |row: &Row<DIM>, d: f64| !row.inequality || d < 0.0;
        let mut residual = 0.0f64;
        for row in &rows {
            let d = distance(row);
            if enforced(row, d) {
                residual = residual.max(d.abs());
            }
        }
        if residual <= bound || iterations >= max_iterations {
            return;
        }
        for row in &mut rows {
            if enforced(row, distance(row)) {
                let value = row.value;
                enforce(row, value);
            } else {
                leave_out(row);
            }
        }
        // Δq = M⁻¹Jᵀμ over the rows' slots, a 3D body's turn folded into a world rotation vector.
        let mut step = solve_rows(&rows, &w, &at, &unforced, length_scale(&positions(s))).acceleration;
        fold(&axes, &mut step);
        for (x, dx) in q.iter_mut().zip(&step) {
            for d in 0..DIM {
                if dx[d].is_finite() {
                    x[d] += dx[d];
                }
            }
        }
        put(s, time(s), q, v, q0);
        iterations += 1;
    }
}
