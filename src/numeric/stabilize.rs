//! Drift control and contacts after a step: projection onto C = 0 and Ċ = 0, Baumgarte
//! settings, and impulses for closing contacts.
//!
//! Methods. Baumgarte (J. Baumgarte, "Stabilization of constraints and integrals of motion
//! in dynamical systems", Comput. Methods Appl. Mech. Eng. 1, 1972) replaces C̈ = 0 by
//! C̈ + 2αĊ + β²C = 0. Post-stabilisation by projection (U. Ascher, H. Chin, L. Petzold,
//! S. Reich, "Stabilization of constrained mechanical systems with DAEs and invariant
//! manifolds", Mech. Struct. Mach. 23, 1995; U. Ascher, "Stabilization of invariants of
//! discretized differential systems", Numer. Algorithms 14, 1997) moves the state back onto
//! the manifold after each step with the mass-weighted minimum-norm correction:
//!
//!   positions  (Newton):  Δr = M⁻¹Jᵀμ,  (J M⁻¹ Jᵀ) μ = −C,  repeated until |C| is small;
//!   velocities (linear):  Δv = M⁻¹Jᵀμ,  (J M⁻¹ Jᵀ) μ = −Ċ.
//!
//! Design note. Both are the λ solve of `numeric::solve` in disguise: with the external
//! forces set to zero and the bias c set to C (or Ċ), `solve` returns μ and the
//! "accelerations" M⁻¹Jᵀμ are exactly Δr (or Δv). Reusing it means the sparse solve and the
//! QP for inequalities serve projection and contacts too, with one set of diagnostics.
//! Inequality rows take part only where they are violated (C < 0) or closing (Ċ < 0 while
//! touching); `solve`'s active set keeps their μ ≥ 0, so a contact only ever pushes. Held
//! contacts (the run's active set, `Dynamics::hold`) are equalities here: the projection
//! and SHAKE hold them at C = 0 from both sides, and the velocity step at Ċ = 0.
//!
//! Contacts. A closing contact gets the impulse P = −(1+e)(J v)/(J M⁻¹ Jᵀ) (DESIGN.md step
//! 6): the same velocity solve with c = (1+e)Ċ, so Ċ⁺ = −eĊ. Approaches slower than a
//! threshold get e = 0, so a resting body or a taut rope does not bounce on round-off.
//! `numeric::contact::impulses` is the same QP on velocities, but not the same step: it
//! acts only when some contact is closing, holds every touching contact (resting ones too)
//! and always sets the equalities' Ċ to 0, with no bounce threshold; the run loop needs the
//! projection of Ċ = 0 at every step, contacts measured against the scene's size, and the
//! threshold, so it keeps [`velocity_step`].
//!
//! 3D rigid bodies are corrected in the generalised coordinates: the solve's per-axis
//! Δφₖ, Δωₖ along the principal axes are folded into a world rotation vector and ω
//! (`rotation::fold`), and the rotation vector turns the orientation (q = exp(φ) ⊗ q₀).
//!
//! Not here: the integrators, the run loop.

use super::dynamics::{BaumgarteTerms, Dynamics, SimError};
use super::integrate::Vectors;
use super::rotation::{first_angular, fold, unfold};
use super::rows::{Row, Rows};
use super::single::{correction_unscaled, correction_with_norm};
use super::solve::{FactorId, positive_finite, solve, zero_vectors};
use super::vector::{dot, not_finite_bit, row_norm};

/// The projection's default relative tolerance: |C|/‖J‖ within 1e-13 of the scene's size is
/// a few ulps of positions of that size, so a projected run keeps |C| at round-off.
pub const PROJECTION_TOLERANCE: f64 = 1e-13;
/// The projection's default iteration limit: Newton from one step's drift converges in two or
/// three iterations; 20 leaves room for a large step and still bounds a step's cost.
pub const PROJECTION_ITERATIONS: usize = 20;
/// SHAKE stops when the residual more than doubles from one iteration to the next: the step
/// was too large for the quasi-Newton iteration, which then diverges.
const DIVERGENCE: f64 = 2.0;

/// How drift is controlled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Stabilize {
    None,
    /// C̈ + 2ζωĊ + ω²C = 0 with ω = `omega_dt` / dt.
    Baumgarte {
        zeta: f64,
        omega_dt: f64,
    },
    /// Newton onto C = 0 to the relative `tolerance`, then velocities onto Ċ = 0.
    Projection {
        tolerance: f64,
        max_iterations: usize,
    },
}

impl Stabilize {
    pub const BAUMGARTE: Stabilize = Stabilize::Baumgarte { zeta: 1.0, omega_dt: 0.1 };
    pub const PROJECTION: Stabilize =
        Stabilize::Projection { tolerance: PROJECTION_TOLERANCE, max_iterations: PROJECTION_ITERATIONS };

    pub fn name(self) -> &'static str {
        match self {
            Stabilize::None => "none",
            Stabilize::Baumgarte { .. } => "baumgarte",
            Stabilize::Projection { .. } => "projection",
        }
    }

    /// The Baumgarte terms for step `dt`: ω = omega_dt/dt, α = ζω, β = ω.
    pub fn baumgarte_terms(self, dt: f64) -> Option<BaumgarteTerms> {
        match self {
            Stabilize::Baumgarte { zeta, omega_dt } => {
                let omega = omega_dt / dt;
                Some(BaumgarteTerms { two_alpha: 2.0 * zeta * omega, beta_squared: omega * omega })
            }
            _ => None,
        }
    }

    /// Bad settings, before any loop runs.
    pub fn validate(self) -> Result<(), StabilizeError> {
        match self {
            Stabilize::None => Ok(()),
            Stabilize::Baumgarte { zeta, omega_dt } => {
                if !(zeta.is_finite() && zeta >= 0.0) {
                    return Err(StabilizeError::Damping(zeta));
                }
                if !(omega_dt.is_finite() && omega_dt > 0.0 && omega_dt <= 1.0) {
                    return Err(StabilizeError::Frequency(omega_dt));
                }
                Ok(())
            }
            Stabilize::Projection { tolerance, max_iterations } => {
                if !(tolerance.is_finite() && tolerance > 0.0) {
                    return Err(StabilizeError::Tolerance(tolerance));
                }
                if max_iterations == 0 {
                    return Err(StabilizeError::NoIterations);
                }
                Ok(())
            }
        }
    }
}

/// A drift-control setting out of range.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum StabilizeError {
    /// Baumgarte's ζ is negative or not finite.
    #[error("the Baumgarte damping ratio ζ (--zeta) must be finite and at least 0, found {0}")]
    Damping(f64),
    /// Baumgarte's ω·dt is outside (0, 1].
    #[error("the Baumgarte frequency ω·dt (--omega-dt) must lie in (0, 1], found {0}")]
    Frequency(f64),
    /// The projection tolerance is not a finite positive number.
    #[error("the projection tolerance (--tolerance) must be finite and positive, found {0}")]
    Tolerance(f64),
    /// The projection may take no Newton iteration.
    #[error("the projection needs at least one iteration")]
    NoIterations,
}

/// The first-order distance of a row to its surface, C/‖J‖ (signed). Where J = 0 (a
/// singular configuration) it is 0 on the surface and ±∞ off it: no step along J reaches it.
pub fn distance(row: &Row) -> f64 {
    distance_of(row.value, &row.jacobian)
}

/// [`distance`] of a row's C/κ `value` and J `jacobian`.
#[inline(always)]
fn distance_of(value: f64, jacobian: &[(usize, [f64; 3])]) -> f64 {
    distance_at_norm(value, row_norm(jacobian))
}

/// [`distance_of`] with the row's norm ‖J‖ `n` (`vector::row_norm`).
#[inline(always)]
fn distance_at_norm(value: f64, n: f64) -> f64 {
    if positive_finite(n) {
        value / n
    } else if value == 0.0 {
        0.0
    } else {
        f64::INFINITY.copysign(value)
    }
}

/// The normal speed of a row, Ċ/‖J‖ (signed; 0 when J = 0).
pub fn normal_speed(row: &Row) -> f64 {
    let n = row_norm(&row.jacobian);
    if positive_finite(n) { row.rate / n } else { 0.0 }
}

/// Marks a row as left out of a correction solve: an inactive inequality (λ = 0).
fn leave_out(row: &mut Row) {
    row.inequality = true;
    row.value = f64::MAX;
    row.rate = f64::MAX;
    row.bias = 0.0;
}

/// Marks a row as enforced with target ΔX = −`bias` (X = C or Ċ).
fn enforce(row: &mut Row, bias: f64) {
    row.value = 0.0;
    row.rate = 0.0;
    row.bias = bias;
}

/// Adds M⁻¹Jᵀμ for the rows to `x`; the solve goes through the run's cache when `dynamics`
/// is given.
fn apply_correction(rows: &mut Rows, x: &mut Vectors, dynamics: Option<&mut Dynamics<'_>>) {
    rows.force.iter_mut().for_each(|f| *f = [0.0; 3]);
    let mut owned;
    let step = match dynamics {
        Some(dynamics) => dynamics.correct_step(rows, None),
        None => {
            owned = solve(rows).acceleration;
            &mut owned
        }
    };
    fold(rows, step);
    add_finite(x, step);
}

/// x += Δx slot by slot over the slots `step` has, the components that are finite: chosen
/// per component, not branched to (as [`shake_update`]).
fn add_finite(x: &mut Vectors, step: &Vectors) {
    for (x, dx) in x.iter_mut().zip(step) {
        let sum = add3(*x, *dx);
        for d in 0..3 {
            x[d] = if dx[d].is_finite() { sum[d] } else { x[d] };
        }
    }
}

/// SHAKE's update q += Δq, v½ += Δq/dt slot by slot over the slots `step` has, the
/// components that are finite. Every component is divided (a zero Δq, as a 2D scene's
/// third components, is its own quotient: ±0/dt = ±0 for the run's dt > 0) and the sums
/// are chosen, not branched to, per component: the slot's three components then go as one
/// vector operation rather than a test, a branch and a scalar division each.
fn shake_update(q: &mut Vectors, v_half: &mut Vectors, step: &Vectors, dt: f64) {
    for ((q, v), dq) in q.iter_mut().zip(v_half.iter_mut()).zip(step) {
        let (sum, rate) = (add3(*q, *dq), add3(*v, dq.map(|x| x / dt)));
        for d in 0..3 {
            let finite = dq[d].is_finite();
            q[d] = if finite { sum[d] } else { q[d] };
            v[d] = if finite { rate[d] } else { v[d] };
        }
    }
}

/// x + y component by component.
#[inline(always)]
fn add3(x: [f64; 3], y: [f64; 3]) -> [f64; 3] {
    [x[0] + y[0], x[1] + y[1], x[2] + y[2]]
}

/// Which inequality rows a projection holds on their surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Inequalities {
    /// Only violated ones (C < 0), with μ ≥ 0 so a contact only pushes: a simulation.
    Violated,
    /// Every one, as an equality (μ of either sign): states on every constraint's surface,
    /// as `check` needs to judge formulas that hold only there.
    AsEqualities,
}

/// Newton onto C = 0 (equalities, and the inequalities `inequalities` says) at time t, until
/// every enforced row's distance |C|/‖J‖ is at most `bound` (the relative tolerance times the
/// scene's length scale) or `max_iterations` are spent. Returns the rows at the final
/// positions and the iterations taken.
pub fn project_positions(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &mut Vectors,
    v: &Vectors,
    bound: f64,
    max_iterations: usize,
    inequalities: Inequalities,
) -> Result<(Rows, usize), SimError> {
    let mut iterations = 0;
    loop {
        let mut rows = dynamics.rows(t, q, v)?;
        // Residual: the largest first-order distance to a surface that is to be enforced.
        let all = inequalities == Inequalities::AsEqualities;
        // Held contacts (the active set) are equalities for the step: held at C = 0 from
        // both sides, so the drift of a step on a curved surface cannot lift them off.
        let as_equality = |k: usize, row: &Row| !row.inequality || all || dynamics.is_held(k);
        let enforced = |k: usize, row: &Row, s: f64| as_equality(k, row) || s < 0.0;
        let mut residual = 0.0f64;
        for (k, row) in rows.rows.iter().enumerate() {
            let s = distance(row);
            if enforced(k, row, s) {
                residual = residual.max(s.abs());
            }
        }
        if residual <= bound || iterations >= max_iterations {
            return Ok((rows, iterations));
        }
        // Contacts within reach of this correction (closer than twice the largest distance
        // it closes) take part as inequalities, J Δq ≥ −C with μ ≥ 0, violated or not: left
        // out, the correction of one contact pushes its neighbour through its surface (a
        // stack: the iteration would ping-pong between them without converging).
        let within = |k: usize, row: &Row, s: f64| enforced(k, row, s) || s <= 2.0 * residual;
        for (k, row) in rows.rows.iter_mut().enumerate() {
            if within(k, row, distance(row)) {
                // (J M⁻¹ Jᵀ) μ = −C: c = C (μ ≥ 0 on violated contacts that are not held).
                row.inequality &= !as_equality(k, row);
                enforce(row, row.value);
            } else {
                leave_out(row);
            }
        }
        apply_correction(&mut rows, q, Some(dynamics));
        dynamics.recycle(rows);
        iterations += 1;
    }
}

/// The steps of [`ShakeHistory`]: μ is predicted by the quadratic through the last three
/// steps' (its error is a third difference of μ, O(dt³) relatively).
const ORDER: usize = 3;

/// SHAKE's multipliers of a run's last steps, from which [`shake_positions`] predicts the
/// step's. The correction μ (Δq = M⁻¹Jₙᵀμ beyond the drift along the start's acceleration)
/// is O(dt³) and smooth in time but for one part: the residual C that the last step left at
/// its positions (within the tolerance, as rounding falls), which this step's correction
/// takes back, −(Jₙ M⁻¹ Jₙᵀ)⁻¹C (by the diagonal for one row or after an iteration, where it
/// is rounding; by a solve with the start's factor where rows couple). So the history keeps
/// the smooth part, μ less what the next step takes back of its own residual plus what it
/// took back of the last one's, extrapolates it, and adds what this step must take back:
/// extrapolated with the residuals in, they would be amplified from step to step up to the
/// tolerance. The predicted positions then usually meet the tolerance at once (a
/// pendulum's one iteration becomes none; a 10-link chain's two, none on most steps). The
/// prediction is along the start's J, as every SHAKE iteration is:
/// the iteration that follows converges to the same solution, to its tolerance. Only for
/// scenes without inequalities or 3D rigid bodies (a contact's impulse or a held set that
/// changes breaks the smoothness; a rotation vector would need folding).
#[derive(Clone, Debug, Default)]
pub struct ShakeHistory {
    /// Per row, what the last steps kept.
    rows: Vec<RowHistory>,
    /// How many steps `rows` holds, in a row of converged steps that corrected their
    /// positions (at most [`ORDER`]; 0: nothing known, and no prediction).
    known: usize,
    /// This step's μ so far (the prediction's, then each iteration's added).
    total: Vec<f64>,
    /// The prediction's step M⁻¹Jₙᵀμ on the slots (scratch).
    step: Vec<[f64; 3]>,
    /// Each row's distance |C|/‖J‖ (signed, [`distance`]) at the last step's final
    /// positions, as SHAKE's residual measured it.
    distances: Vec<f64>,
    /// Whether `distances` are those of the end rows the last SHAKE left (their C/κ and J
    /// the positions' own, bit for bit), not yet taken by
    /// [`end_distances`](ShakeHistory::end_distances).
    ends: bool,
}

/// One row's part of a [`ShakeHistory`].
#[derive(Clone, Copy, Debug, Default)]
struct RowHistory {
    /// The smooth part of μ of the last steps, the latest first.
    past: [f64; ORDER],
    /// C/(Jₙ M⁻¹ Jₙᵀ) at the last step's final positions: what this step's μ takes back
    /// (with the sign of −μ).
    left: f64,
}

impl ShakeHistory {
    /// The distances of every row of the end rows the last [`shake_positions`] with this
    /// history left, when those rows became the next step's start with their C/κ and J
    /// unchanged (`kept`: `Dynamics::rows_moved_into` said so, and nothing wrote them in
    /// between, as a run's RATTLE step writes none of them for good): the next start's drift
    /// check need not compute them again (the same function of the same numbers). Once:
    /// the mark is taken, so a step without SHAKE leaves none behind.
    pub fn end_distances(&mut self, kept: bool) -> Option<&[f64]> {
        (std::mem::take(&mut self.ends) && kept).then_some(self.distances.as_slice())
    }

    /// This step's prediction from the start's rows (J and 1/m) and its step on the slots,
    /// returned when there is one (after a converged step that corrected its positions) and
    /// every number of it is finite.
    fn predict(&mut self, start: &Rows) -> Option<&Vectors> {
        let rows = start.rows.len();
        // μ so far, one a row: written in place when the last step had these rows (a run's
        // every step but its first), not cleared and refilled.
        if self.total.len() != rows {
            self.total.clear();
            self.total.resize(rows, 0.0);
        }
        if self.known == 0 || self.rows.len() != rows {
            self.total.fill(0.0);
            return None;
        }
        // The polynomial through the last `known` steps' smooth part, at this step.
        let [a, b, c] = match self.known {
            1 => [1.0, 0.0, 0.0],
            2 => [2.0, -1.0, 0.0],
            _ => [3.0, -3.0, 1.0],
        };
        // One row on one slot (a pendulum, a bead): the numbers of the loops below, without them.
        if let ([row], [h], [mu], [w]) =
            (start.rows.as_slice(), self.rows.as_slice(), self.total.as_mut_slice(), start.inverse_mass.as_slice())
            && let [(0, j)] = row.jacobian.as_slice()
        {
            *mu = a * h.past[0] + b * h.past[1] + c * h.past[2] - h.left;
            let (m, w) = (*mu, *w);
            // 0 + J μ w: the loop's sum into a zeroed slot.
            let x = [0.0 + j[0] * m * w, 0.0 + j[1] * m * w, 0.0 + j[2] * m * w];
            if !(x[0].is_finite() & x[1].is_finite() & x[2].is_finite()) {
                *mu = 0.0;
                return None;
            }
            match self.step.as_mut_slice() {
                [slot] => *slot = x,
                _ => {
                    self.step.clear();
                    self.step.push(x);
                }
            }
            return Some(&self.step);
        }
        for (mu, h) in self.total.iter_mut().zip(&self.rows) {
            *mu = a * h.past[0] + b * h.past[1] + c * h.past[2] - h.left;
        }
        let slots = start.inverse_mass.len();
        if self.step.len() == slots {
            for x in &mut self.step {
                *x = [0.0; 3];
            }
        } else {
            zero_vectors(&mut self.step, slots);
        }
        for (row, &mu) in start.rows.iter().zip(&self.total) {
            for &(b, j) in &row.jacobian {
                let (x, w) = (&mut self.step[b], start.inverse_mass[b]);
                for d in 0..3 {
                    x[d] += j[d] * mu * w;
                }
            }
        }
        // Every component finite, in one branch-free pass.
        let finite = self.step.iter().fold(true, |ok, x| ok & x[0].is_finite() & x[1].is_finite() & x[2].is_finite());
        if !finite {
            self.total.fill(0.0);
            return None;
        }
        Some(&self.step)
    }

    /// Adds an iteration's μ to the step's.
    fn add(&mut self, mu: &[f64]) {
        for (total, mu) in self.total.iter_mut().zip(mu) {
            *total += mu;
        }
    }

    /// The step's end (`kept`: SHAKE converged and corrected the positions, by a prediction
    /// or an iteration): its smooth part kept, with the residual C left at the final
    /// positions (`end`) over the diagonal of Jₙ M⁻¹ Jₙᵀ (`start`'s J and 1/m); else the
    /// history forgotten (a step that needed no correction has no μ to go on from, and a
    /// scene at rest none to predict).
    fn finish(&mut self, kept: bool, end: &[Row], start: &Rows, exact: Option<&[f64]>) {
        let rows = end.len();
        if !kept || self.total.len() != rows {
            self.known = 0;
            return;
        }
        let had_left = self.known > 0 && self.rows.len() == rows;
        // One row (a pendulum, a bead) after the first steps: the loop below's numbers, in line.
        if let (true, None, [h], [mu], [row], [new]) =
            (had_left, exact, self.rows.as_mut_slice(), self.total.as_slice(), start.rows.as_slice(), end)
        {
            let delta = new.value / row.jacobian.iter().map(|(b, j)| dot(j, j) * start.inverse_mass[*b]).sum::<f64>();
            let delta = if delta.is_finite() { delta } else { 0.0 };
            h.past = [mu + h.left - delta, h.past[0], h.past[1]];
            h.left = delta;
            self.known = (self.known + 1).min(ORDER);
            return;
        }
        if !had_left {
            self.rows.clear();
            self.rows.resize(rows, RowHistory::default());
        }
        for (k, (((h, mu), row), new)) in self.rows.iter_mut().zip(&self.total).zip(&start.rows).zip(end).enumerate() {
            let delta = match exact {
                Some(lambda) => -lambda[k],
                None => new.value / row.jacobian.iter().map(|(b, j)| dot(j, j) * start.inverse_mass[*b]).sum::<f64>(),
            };
            let delta = if delta.is_finite() { delta } else { 0.0 };
            // μ = smooth − (the last step's left); the μ that would meet C = 0 is μ − δ.
            h.past = [mu + h.left - delta, h.past[0], h.past[1]];
            h.left = delta;
        }
        self.known = (self.known + 1).min(ORDER);
    }
}

/// SHAKE (Ryckaert, Ciccotti, Berendsen 1977; with the velocity step below it is RATTLE,
/// Andersen 1983): corrects Verlet's drift q⁺ = q + dt v½ along the gradients at the
/// *start* of the step, Δq = M⁻¹Jₙᵀμ with (Jₙ M⁻¹ Jₙᵀ) μ = −C(q⁺) (a quasi-Newton
/// iteration), and folds the correction into v½ += Δq/dt. Along Jₙ rather than J(q⁺), the
/// step stays symplectic, so the energy error of a long run stays bounded. Equalities only:
/// a contact's correction must not turn into a velocity (that would pre-empt its impulse
/// and restitution), so violated inequalities are left to [`project_positions`]. `start` holds
/// the rows at the start of the step (its C, Ċ and c may be overwritten; its J is kept).
/// An iteration reads C and J alone (`Dynamics::positions`), and its solve has the start's
/// J, so the run's solve cache serves it with the start's factor; at the final positions
/// the rows are completed from the last iteration's C and J
/// (`Dynamics::rows_after_positions_into`) into `end` (whatever it held: its buffers are
/// reused); for a steady program (`RowProgram::steady`: constant forces and masses, no C
/// reading t) without the motion tape, from the start's slots and Ċ = J·v½
/// (`Dynamics::rows_after_positions_steady_into`), the same quantities. `made`: the mark of the factor the start's solve went through
/// (`Dynamics::made`, `solve::FactorId`), so that the iterations' solves do not compare the
/// start's J with it again. `history`: the run's [`ShakeHistory`], when its prediction is
/// to start the iteration (`None`: from the drifted positions, as for a scene with contacts).
/// Returns the iterations taken.
#[allow(clippy::too_many_arguments)]
pub fn shake_positions(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    dt: f64,
    q: &mut Vectors,
    v_half: &mut Vectors,
    start: &mut Rows,
    end: &mut Rows,
    made: Option<FactorId>,
    length: f64,
    tolerance: f64,
    max_iterations: usize,
    mut history: Option<&mut ShakeHistory>,
) -> Result<usize, SimError> {
    let mut made = made;
    let system = dynamics.system();
    // A steady program's end rows need no motion tape: their slots' numbers are the
    // start's, taken before the iterations zero its forces.
    let steady = dynamics.steady;
    if steady {
        end.take_slots(start);
    }
    // The correction predicted from the last steps', along the start's J.
    let mut predicted = false;
    if let Some(step) = history.as_deref_mut().and_then(|h| h.predict(start)) {
        shake_update(q, v_half, step, dt);
        predicted = true;
    }
    let bound = tolerance * length;
    let mut iterations = 0;
    let mut previous = f64::INFINITY;
    let mut zeroed = false;
    if let Some(history) = history.as_deref_mut() {
        history.ends = false;
    }
    loop {
        // C and J only (the iteration reads nothing else); the full rows once, at the end.
        dynamics.positions(t, q, v_half)?;
        let mut residual = 0.0f64;
        match history.as_deref_mut() {
            // Every row's distance kept, for the next start's drift check (`end_distances`).
            Some(history) => {
                let rows = dynamics.position_rows();
                if history.distances.len() != rows.len() {
                    history.distances.resize(rows.len(), 0.0);
                }
                for (k, (row, kept)) in rows.iter().zip(&mut history.distances).enumerate() {
                    *kept = distance(row);
                    if !row.inequality || dynamics.is_held(k) {
                        residual = residual.max(kept.abs());
                    }
                }
            }
            None => {
                for (k, row) in dynamics.position_rows().iter().enumerate() {
                    if !row.inequality || dynamics.is_held(k) {
                        residual = residual.max(distance(row).abs());
                    }
                }
            }
        }
        // Stop when converged, out of iterations, or diverging (the step was too large for
        // the quasi-Newton iteration; the run's drift check then reports it).
        if residual <= bound || iterations >= max_iterations || residual > DIVERGENCE * previous {
            if let Some(history) = history.as_deref_mut() {
                let kept = residual <= bound && (predicted || iterations > 0);
                // The residual a prediction left alone, taken back exactly where rows couple
                // (a chain's Jₙ M⁻¹ Jₙᵀ is far from its diagonal): a solve with the start's
                // factor. After an iteration it is rounding, and the diagonal serves.
                let exact = kept && iterations == 0 && start.rows.len() > 1;
                if exact {
                    for (old, new) in start.rows.iter_mut().zip(dynamics.position_rows()) {
                        enforce(old, new.value);
                    }
                    start.force.iter_mut().for_each(|f| *f = [0.0; 3]);
                    dynamics.correct_known(start, made);
                }
                let exact = exact.then(|| dynamics.correction().lambda.as_slice());
                history.finish(kept, dynamics.position_rows(), start, exact);
            }
            // C and J are those just evaluated: Ċ, c and the bodies' numbers are added.
            let kept = (steady && dynamics.rows_after_positions_steady_into(v_half, end))
                || dynamics.rows_after_positions_into(t, q, v_half, end)?;
            if let Some(history) = history {
                // The distances just measured are the end rows'.
                history.ends = kept;
            }
            return Ok(iterations);
        }
        previous = residual;
        // One constraint on the scene's only slot (a pendulum, a bead), an equality for the
        // step: its correction in closed form, with `start` as it is.
        let single = match (dynamics.position_rows(), system.constraints.as_slice()) {
            ([new], [constraint]) if !constraint.inequality || dynamics.is_held(0) => Some(new.value),
            _ => None,
        };
        if let Some((dq, mu)) = single.and_then(|c| dynamics.correct_single_multiplier(start, c)) {
            if let Some(history) = history.as_deref_mut() {
                history.add(&[mu]);
            }
            shake_update(q, v_half, std::slice::from_ref(&dq), dt);
            iterations += 1;
            continue;
        }
        made = shake_correction(dynamics, dt, q, v_half, start, made, &mut zeroed, history.as_deref_mut());
        iterations += 1;
    }
}

/// One of SHAKE's iterations through the solve ([`shake_positions`]' general correction): the
/// start's rows set to take back C at the positions just evaluated (equalities and held
/// contacts; the other inequalities left out), their forces zeroed once (`zeroed`), the
/// correction M⁻¹Jₙᵀμ solved with the start's J (`made`: the mark of its factor), added to
/// q and, over dt, to v½, and μ added to `history`'s. Returns the mark of the factor the
/// solve went through.
#[allow(clippy::too_many_arguments)]
fn shake_correction(
    dynamics: &mut Dynamics<'_>,
    dt: f64,
    q: &mut Vectors,
    v_half: &mut Vectors,
    start: &mut Rows,
    made: Option<FactorId>,
    zeroed: &mut bool,
    history: Option<&mut ShakeHistory>,
) -> Option<FactorId> {
    let system = dynamics.system();
    for (k, ((old, new), constraint)) in
        start.rows.iter_mut().zip(dynamics.position_rows()).zip(&system.constraints).enumerate()
    {
        let equality = !constraint.inequality || dynamics.is_held(k);
        old.inequality = !equality;
        if equality {
            // (Jₙ M⁻¹ Jₙᵀ) μ = −C(q⁺): c = C(q⁺).
            enforce(old, new.value);
        } else {
            leave_out(old);
        }
    }
    // The forces once: nothing writes them between the iterations.
    if !*zeroed {
        start.force.iter_mut().for_each(|f| *f = [0.0; 3]);
        *zeroed = true;
    }
    // The start's J is kept (only C, Ċ, c and the forces are written above).
    let step = match history {
        Some(history) => {
            let solution = dynamics.correct_known(start, made);
            history.add(&solution.lambda);
            &mut solution.acceleration
        }
        None => dynamics.correct_step(start, made),
    };
    fold(start, step);
    shake_update(q, v_half, step, dt);
    dynamics.made()
}

/// RATTLE's step for one equality row on a scene's only slot (a pendulum, a bead on a
/// curve or surface), with a steady program (`Dynamics::steady`) and no force reading a
/// velocity: Verlet's drift v½ = v + dt/2 a, q⁺ = q + dt v½; SHAKE from its prediction
/// ([`shake_positions`] with `history`); the kick v⁺ = v½ + dt/2 M⁻¹F(q⁺) into `v` (v½ kept
/// in `half`); Ċ of the end rows brought to v⁺ ([`update_rates`]); the velocity projection
/// ([`velocity_step`] with projection; `touch`, `restitution` and `bounce_speed` are its
/// contacts' settings, for the general step). The same operations in the same order as those
/// functions for this shape, so every number is theirs bit for bit, without their loops
/// over rows and slots, their checks of the shape at every stage and their calls.
///
/// Returns `None`, with nothing touched, when the scene is not of that shape (the caller
/// then takes the general step); else the mark of the factor the velocity projection went
/// through (`Dynamics::made`, as `Simulation` keeps it). Where a stage's closed form
/// declines (an iteration's one-row correction, the velocity projection's) the general
/// stage answers, as it does inside those functions; errors are theirs.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn rattle_one_row(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    dt: f64,
    q: &mut Vectors,
    v: &mut Vectors,
    half: &mut Vectors,
    a: &Vectors,
    start: &mut Rows,
    end: &mut Rows,
    made: Option<FactorId>,
    [length, tolerance]: [f64; 2],
    max_iterations: usize,
    history: &mut ShakeHistory,
    [touch, restitution, bounce_speed]: [f64; 3],
    values: &mut Vec<f64>,
) -> Result<Option<Option<FactorId>>, SimError> {
    let one_slot = q.len() == 1 && v.len() == 1 && half.len() == 1 && a.len() == 1;
    let one_row = matches!(
        (start.rows.as_slice(), start.inverse_mass.len(), start.force.len(), dynamics.system().constraints.as_slice()),
        ([row], 1, 1, [constraint]) if !row.inequality && !constraint.inequality && matches!(row.jacobian.as_slice(), [(0, _)])
    );
    if !(one_slot && one_row && start.axes.is_empty() && dynamics.steady && !dynamics.velocity_dependent_forces) {
        return Ok(None);
    }
    // Verlet's drift (`Stepper::verlet_drift`): v½ = v + (dt/2) a; q⁺ = q + dt v½.
    let h = 0.5 * dt;
    for d in 0..3 {
        v[0][d] += h * a[0][d];
    }
    for d in 0..3 {
        q[0][d] += dt * v[0][d];
    }
    // SHAKE (`shake_positions`, steady, with the history): the end rows' slots are the
    // start's (`Rows::take_slots`), the prediction along the start's J first.
    end.dim = start.dim;
    end.axes.clear();
    match (end.inverse_mass.as_mut_slice(), end.force.as_mut_slice()) {
        ([w], [f]) => (*w, *f) = (start.inverse_mass[0], start.force[0]),
        _ => end.take_slots(start),
    }
    let (j, w) = (start.rows[0].jacobian[0].1, start.inverse_mass[0]);
    let predicted = match predict_one_row(history, start, &j, w) {
        Some(x) => {
            // `shake_update` of a finite step: q += Δq, v½ += Δq/dt.
            for d in 0..3 {
                q[0][d] += x[d];
                v[0][d] += x[d] / dt;
            }
            true
        }
        None => false,
    };
    let bound = tolerance * length;
    let (mut iterations, mut previous, mut zeroed, mut made) = (0, f64::INFINITY, false, made);
    history.ends = false;
    loop {
        dynamics.positions(t, q, v)?;
        // The row's distance, kept for the next start's drift check; the residual from 0.
        let mut residual = 0.0f64;
        let rows = dynamics.position_rows();
        match (rows, history.distances.as_mut_slice()) {
            ([row], [kept]) => {
                *kept = distance(row);
                if !row.inequality || dynamics.is_held(0) {
                    residual = residual.max(kept.abs());
                }
            }
            _ => {
                history.distances.resize(rows.len(), 0.0);
                for (k, (row, kept)) in rows.iter().zip(&mut history.distances).enumerate() {
                    *kept = distance(row);
                    if !row.inequality || dynamics.is_held(k) {
                        residual = residual.max(kept.abs());
                    }
                }
            }
        }
        if residual <= bound || iterations >= max_iterations || residual > DIVERGENCE * previous {
            let kept = residual <= bound && (predicted || iterations > 0);
            // One row: the prediction's residual is taken back by the diagonal (no exact solve).
            finish_one_row(history, kept, dynamics.position_rows(), start);
            let kept = dynamics.rows_after_positions_one_slot(&v[0], end)
                || dynamics.rows_after_positions_into(t, q, v, end)?;
            history.ends = kept;
            break;
        }
        previous = residual;
        let c = match dynamics.position_rows() {
            [new] => Some(new.value),
            _ => None,
        };
        if let Some((dq, mu)) = c.and_then(|c| dynamics.correct_single_multiplier(start, c)) {
            history.add(&[mu]);
            shake_update(q, v, std::slice::from_ref(&dq), dt);
        } else {
            made = shake_correction(dynamics, dt, q, v, start, made, &mut zeroed, Some(&mut *history));
        }
        iterations += 1;
    }
    // The kick with F(q⁺) alone: its constraint part is what the projection below removes.
    half[0] = v[0];
    for ((v, f), w) in v.iter_mut().zip(&end.force).zip(&end.inverse_mass) {
        for d in 0..3 {
            v[d] += 0.5 * dt * f[d] * w;
        }
    }
    // Ċ brought from v½ to v⁺ (`update_rates`; no 3D rigid body's slot to unfold).
    match end.rows.as_mut_slice() {
        [row] if end.axes.is_empty() && matches!(row.jacobian.as_slice(), [(0, _)]) => {
            let (j, x, y) = (row.jacobian[0].1, half[0], v[0]);
            row.rate += j[0] * (y[0] - x[0]) + j[1] * (y[1] - x[1]) + j[2] * (y[2] - x[2]);
        }
        _ => update_rates(end, half, v),
    }
    // The velocity projection onto Ċ = 0 (`velocity_step`'s one-row path, else the step).
    values.clear();
    let rate = match end.rows.as_slice() {
        [row] if !row.inequality => Some(row.rate),
        _ => None,
    };
    if let Some(dv) = rate.and_then(|rate| dynamics.correct_single(end, rate)) {
        // `add_finite` on the one slot: v += Δv, the components that are finite.
        for d in 0..3 {
            let sum = v[0][d] + dv[d];
            v[0][d] = if dv[d].is_finite() { sum } else { v[0][d] };
        }
        return Ok(Some(dynamics.made()));
    }
    let applied = velocity_step(end, v, true, touch, restitution, bounce_speed, dynamics, values);
    Ok(Some(if applied { dynamics.made() } else { None }))
}

/// [`rattle_one_row`]'s step when it goes the plain way — SHAKE's prediction meets the
/// tolerance without an iteration, every number is finite, the velocity projection's
/// closed form answers —, computed from the numbers in hand into locals and written only
/// once the step is known to be plain: the same operations in the same order, so the same
/// numbers bit for bit, without the stages' tests of the rows' shape, their `Rows` and their
/// calls (the positions' tape at the fixed places of `Dynamics::one_slot_positions`) — but
/// for the velocity projection with `unscaled`: without the scaling where its guard allows
/// (`single::correction_unscaled`, the same Δv to a few roundings), else the scaled one.
///
/// Returns `None`, with nothing written (the tapes' scratch and the one-row solve's kept
/// scaling aside, which hold no state of the run), where the step is not plain or the rows
/// are not of that shape: the caller then takes [`rattle_one_row`], which computes the step
/// again and answers for whatever made it other (an iteration, a number not finite, an
/// error). Else the mark of the factor the velocity projection went through, as
/// [`rattle_one_row`] returns it. `q`, `v` (and `half`, `a`) must hold one slot, and the
/// scene must be as [`rattle_one_row`] requires (the caller's test, once a run).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn rattle_one_row_plain(
    dynamics: &mut Dynamics<'_>,
    dt: f64,
    [q, v, half]: [&mut [f64; 3]; 3],
    a: &[f64; 3],
    start: &Rows,
    end: &mut Rows,
    bound: f64,
    history: &mut ShakeHistory,
    values: &mut Vec<f64>,
    unscaled: bool,
) -> Option<Option<FactorId>> {
    // The shapes the step writes in place, and the history's room for one row after a
    // converged step (a prediction to start from).
    let ([row], [w], [f]) = (start.rows.as_slice(), start.inverse_mass.as_slice(), start.force.as_slice()) else {
        return None;
    };
    let ([(0, j)], false, true) = (row.jacobian.as_slice(), row.inequality, start.axes.is_empty()) else {
        return None;
    };
    let ([h], [_], [_], 1..) =
        (history.rows.as_slice(), history.total.as_slice(), history.distances.as_slice(), history.known)
    else {
        return None;
    };
    let (j, w, f, h) = (*j, *w, *f, *h);
    // Verlet's drift: v½ = v + (dt/2) a; q⁺ = q + dt v½.
    let step = 0.5 * dt;
    let mut u = *v;
    for d in 0..3 {
        u[d] += step * a[d];
    }
    let mut x = *q;
    for d in 0..3 {
        x[d] += dt * u[d];
    }
    // SHAKE's prediction (`predict_one_row`): μ from the last steps', Δq = 0 + J μ w.
    let [pa, pb, pc] = match history.known {
        1 => [1.0, 0.0, 0.0],
        2 => [2.0, -1.0, 0.0],
        _ => [3.0, -3.0, 1.0],
    };
    let mu = pa * h.past[0] + pb * h.past[1] + pc * h.past[2] - h.left;
    let dq = [0.0 + j[0] * mu * w, 0.0 + j[1] * mu * w, 0.0 + j[2] * mu * w];
    if (not_finite_bit(dq[0]) | not_finite_bit(dq[1]) | not_finite_bit(dq[2])) >> 63 != 0 {
        return None;
    }
    for d in 0..3 {
        x[d] += dq[d];
        u[d] += dq[d] / dt;
    }
    // C/κ and J at q⁺, every number finite; the row's distance within the tolerance.
    let (value, jn, true) = dynamics.one_slot_positions(&x, &u)? else {
        return None;
    };
    let norm = row_norm(&[(0, jn)]);
    let distance = distance_at_norm(value, norm);
    if 0.0f64.max(distance.abs()) > bound {
        return None;
    }
    // `finish_one_row`: the μ that would meet C = 0 is μ − δ, δ = C/(Jₙ M⁻¹ Jₙᵀ).
    let delta = value / std::iter::once(dot(&j, &j) * w).sum::<f64>();
    let delta = if delta.is_finite() { delta } else { 0.0 };
    // The end rows' Ċ at v½ (`rows_after_positions_one_slot`); the kick with F(q⁺) = F;
    // Ċ brought to v⁺ (`update_rates`).
    let rate = jn[0] * u[0] + jn[1] * u[1] + jn[2] * u[2];
    let mut y = u;
    for d in 0..3 {
        y[d] += 0.5 * dt * f[d] * w;
    }
    let rate = rate + (jn[0] * (y[0] - u[0]) + jn[1] * (y[1] - u[1]) + jn[2] * (y[2] - u[2]));
    // The velocity projection onto Ċ = 0 (`correction_single`'s tests: v½, Ċ, 1/m and J
    // finite, 1/m ≥ 0; J and 1/m are, from the tape and the start's checked rows).
    if (not_finite_bit(u[0]) | not_finite_bit(u[1]) | not_finite_bit(u[2]) | not_finite_bit(rate)) >> 63 != 0
        || w < 0.0
        || !w.is_finite()
    {
        return None;
    }
    // Without the scaling where the magnitudes allow (`single::correction_unscaled`), else
    // with J's scaling (when J is not the kept one's) from the norm the distance took.
    let dv = match unscaled.then(|| correction_unscaled(&jn, w, rate)).flatten() {
        Some(dv) => dv,
        None => correction_with_norm(&jn, w, rate, || norm, dynamics.single_scaling())?.0,
    };
    for d in 0..3 {
        let sum = y[d] + dv[d];
        y[d] = if dv[d].is_finite() { sum } else { y[d] };
    }
    // The state the run checks next (`Simulation::check_finite`): else the general step says.
    let state = [x[0], x[1], x[2], y[0], y[1], y[2]];
    if state.iter().fold(0u64, |bad, x| bad | not_finite_bit(*x)) >> 63 != 0 {
        return None;
    }
    // The step is plain: written.
    let (end_row, end_w, end_u, end_f) = end.one_slot_mut()?;
    let [(slot, end_j)] = end_row.jacobian.as_mut_slice() else {
        return None;
    };
    (*slot, *end_j) = (0, jn);
    (end_row.value, end_row.rate, end_row.bias, end_row.inequality) = (value, rate, 0.0, false);
    (*end_w, *end_u, *end_f) = (w, u, f);
    end.dim = start.dim;
    end.axes.clear();
    (*q, *half, *v) = (x, u, y);
    let known = history.known;
    if let ([h], [total], [kept]) =
        (history.rows.as_mut_slice(), history.total.as_mut_slice(), history.distances.as_mut_slice())
    {
        *total = mu;
        *kept = distance;
        h.past = [mu + h.left - delta, h.past[0], h.past[1]];
        h.left = delta;
    }
    history.known = (known + 1).min(ORDER);
    history.ends = true;
    dynamics.count_positions();
    values.clear();
    Some(dynamics.made())
}

/// [`ShakeHistory::predict`] for one row on one slot (`start` holds it, J `j` and 1/m `w`):
/// the prediction's step on the slot, every component finite, or `None` (the history's μ
/// then as `predict` leaves it); in line where the history has the row's room.
#[inline(always)]
fn predict_one_row(history: &mut ShakeHistory, start: &Rows, j: &[f64; 3], w: f64) -> Option<[f64; 3]> {
    let known = history.known;
    let ([h], [mu]) = (history.rows.as_slice(), history.total.as_mut_slice()) else {
        return history.predict(start).and_then(|step| step.first().copied());
    };
    if known == 0 {
        *mu = 0.0;
        return None;
    }
    let [a, b, c] = match known {
        1 => [1.0, 0.0, 0.0],
        2 => [2.0, -1.0, 0.0],
        _ => [3.0, -3.0, 1.0],
    };
    *mu = a * h.past[0] + b * h.past[1] + c * h.past[2] - h.left;
    let m = *mu;
    // 0 + J μ w: the loop's sum into a zeroed slot.
    let x = [0.0 + j[0] * m * w, 0.0 + j[1] * m * w, 0.0 + j[2] * m * w];
    // Every component finite: the OR of their `not_finite_bit`s, one test.
    if (not_finite_bit(x[0]) | not_finite_bit(x[1]) | not_finite_bit(x[2])) >> 63 != 0 {
        *mu = 0.0;
        return None;
    }
    Some(x)
}

/// [`ShakeHistory::finish`] for one row on one slot (`start` holds it, `end` the row at
/// the final positions): the same numbers, in line where the history has the row's room.
#[inline(always)]
fn finish_one_row(history: &mut ShakeHistory, kept: bool, end: &[Row], start: &Rows) {
    if let (true, true, [h], [mu], [row], [new]) =
        (kept, history.known > 0, history.rows.as_mut_slice(), history.total.as_slice(), start.rows.as_slice(), end)
    {
        let delta = new.value / row.jacobian.iter().map(|(b, j)| dot(j, j) * start.inverse_mass[*b]).sum::<f64>();
        let delta = if delta.is_finite() { delta } else { 0.0 };
        h.past = [mu + h.left - delta, h.past[0], h.past[1]];
        h.left = delta;
        history.known = (history.known + 1).min(ORDER);
        return;
    }
    history.finish(kept, end, start, None);
}

/// [`project_positions_along`] hands over to Newton when an iteration does not at least halve
/// the residual: the quasi-Newton iteration contracts by about ‖ΔJ‖/‖J‖ (J's change over the
/// substep), and a slower one costs more substitutions than Newton's factorisations.
const CONTRACTION: f64 = 0.5;

/// Quasi-Newton onto C = 0 along the rows `along` (their J, at the start of a substep, whose
/// factor the run's solve cache holds from the velocity solve): Δq = M⁻¹Jₙᵀμ with
/// (Jₙ M⁻¹ Jₙᵀ) μ = −C(q), positions only, until every row's distance |C|/‖J‖ at q is at
/// most `bound`, as [`project_positions`] measures it. Its solves are substitutions with the
/// cached factor. The full rows are evaluated at the starting q (returned as they are when
/// it is on the surface already, as at rest); the iterations read C and J alone
/// (`Dynamics::positions`), and at the final positions the rows are completed from the last
/// one's (`Dynamics::rows_after_positions`). Returns the rows at the final positions and
/// the iterations taken. Equalities only: with an inequality constraint in the system it
/// returns `None` at once. It also returns `None`, with `q` put back exactly where it was
/// (kept in `start`), when the iteration is not converging fast: an iteration does not
/// halve the residual, the residual is not finite, `max_iterations` are spent, or the rows
/// cannot be evaluated past the starting q; the caller then takes [`project_positions`] from
/// the same q. An evaluation error at the starting q is returned as [`project_positions`]
/// would return it. `along`'s C, Ċ and c are overwritten; its J is kept.
#[allow(clippy::too_many_arguments)]
pub fn project_positions_along(
    dynamics: &mut Dynamics<'_>,
    t: f64,
    q: &mut Vectors,
    v: &Vectors,
    along: &mut Rows,
    bound: f64,
    max_iterations: usize,
    start: &mut Vec<[f64; 3]>,
) -> Result<Option<(Rows, usize)>, SimError> {
    if dynamics.system().constraints.iter().any(|c| c.inequality) || along.rows.iter().any(|r| r.inequality) {
        return Ok(None);
    }
    // The largest distance to a surface; a NaN counts as infinitely far (f64::max drops it).
    let residual_of = |rows: &[Row]| {
        rows.iter()
            .map(|row| distance(row).abs())
            .fold(0.0f64, |r, s| if s.is_nan() { f64::INFINITY } else { r.max(s) })
    };
    let rows = dynamics.rows(t, q, v)?;
    let mut previous = residual_of(&rows.rows);
    if previous <= bound {
        return Ok(Some((rows, 0)));
    }
    let go_on = previous.is_finite() && max_iterations > 0;
    if go_on {
        start.clear();
        start.extend_from_slice(q);
        for (old, new) in along.rows.iter_mut().zip(&rows.rows) {
            // (Jₙ M⁻¹ Jₙᵀ) μ = −C(q): c = C(q).
            enforce(old, new.value);
        }
    }
    dynamics.recycle(rows);
    if !go_on {
        return Ok(None);
    }
    step_along(dynamics, q, along);
    let mut iterations = 1;
    loop {
        // Past the starting q an evaluation error hands over to Newton from there.
        let restore = |q: &mut Vectors| {
            q.copy_from_slice(start);
            Ok(None)
        };
        if dynamics.positions(t, q, v).is_err() {
            return restore(q);
        }
        let residual = residual_of(dynamics.position_rows());
        if residual <= bound {
            // C and J are those just evaluated: Ċ, c and the bodies' numbers are added.
            return match dynamics.rows_after_positions(t, q, v) {
                Ok(rows) => Ok(Some((rows, iterations))),
                Err(_) => restore(q),
            };
        }
        if !(residual.is_finite() && residual <= CONTRACTION * previous) || iterations >= max_iterations {
            return restore(q);
        }
        previous = residual;
        for (old, new) in along.rows.iter_mut().zip(dynamics.position_rows()) {
            enforce(old, new.value);
        }
        step_along(dynamics, q, along);
        iterations += 1;
    }
}

/// q += M⁻¹Jᵀμ with (J M⁻¹ Jᵀ) μ = −c for the rows `along` (c set), through the run's cache.
fn step_along(dynamics: &mut Dynamics<'_>, q: &mut Vectors, along: &mut Rows) {
    along.force.iter_mut().for_each(|f| *f = [0.0; 3]);
    let step = dynamics.correct_step(along, None);
    fold(along, step);
    for (x, dx) in q.iter_mut().zip(step.iter()) {
        for d in 0..3 {
            if dx[d].is_finite() {
                x[d] += dx[d];
            }
        }
    }
}

/// Ċ of `rows` after the velocities changed from `before` to `after` (Ċ is affine in v:
/// Ċ = Σᵢ Jᵢ·vᵢ + ∂C/∂t), without evaluating again.
pub fn update_rates(rows: &mut Rows, before: &Vectors, after: &Vectors) {
    let first = first_angular(rows);
    for k in 0..rows.rows.len() {
        let row = &rows.rows[k];
        let mut rate = row.rate;
        for &(b, j) in &row.jacobian {
            // A 3D rigid body's slot k reads eₖ·ω of the state's world ω.
            let (x, y) = (unfold(rows, first, before, b), unfold(rows, first, after, b));
            rate += j[0] * (y[0] - x[0]) + j[1] * (y[1] - x[1]) + j[2] * (y[2] - x[2]);
        }
        rows.rows[k].rate = rate;
    }
}

/// Velocities onto Ċ = 0 for every row, inequalities as equalities, in one step (Ċ is
/// affine in v: Δv = M⁻¹Jᵀμ with (J M⁻¹ Jᵀ) μ = −Ċ). `rows` is spent.
pub fn project_velocities(rows: &mut Rows, v: &mut Vectors) {
    for row in &mut rows.rows {
        row.inequality = false;
        enforce(row, row.rate);
    }
    apply_correction(rows, v, None);
}

/// The velocity solve at the rows of the current positions: closing contacts (touching
/// within `touch` or `held`, approaching) take Ċ⁺ = −eĊ (e = 0 below `bounce_speed`), the
/// other touching ones Ċ⁺ ≥ 0 (they may take an impulse, never pull); with
/// `project` the equalities and the held contacts that are not closing go onto Ċ = 0 too,
/// else they keep their Ċ; `dynamics` says which contacts are held and serves the solve.
/// Returns whether anything was applied. `rows` is spent (its C, Ċ and c may be
/// overwritten; their C/κ are first saved in `values`, for a caller that puts them back),
/// but for one equality row on the scene's only slot (a pendulum, a bead), projected in
/// closed form from the rows as they are (`Dynamics::correct_single`; `values` is then left
/// empty: nothing was spent).
#[allow(clippy::too_many_arguments)]
pub fn velocity_step(
    rows: &mut Rows,
    v: &mut Vectors,
    project: bool,
    touch: f64,
    restitution: f64,
    bounce_speed: f64,
    dynamics: &mut Dynamics<'_>,
    values: &mut Vec<f64>,
) -> bool {
    values.clear();
    if let (true, [row]) = (project, rows.rows.as_slice())
        && !row.inequality
        && let Some(dv) = dynamics.correct_single(rows, row.rate)
    {
        // ΔĊ = −Ċ, as below.
        add_finite(v, std::slice::from_ref(&dv));
        return true;
    }
    values.extend(rows.rows.iter().map(|row| row.value));
    let mut any = false;
    for (k, row) in rows.rows.iter_mut().enumerate() {
        let is_held = dynamics.is_held(k);
        if row.inequality && is_held && normal_speed(row) >= 0.0 {
            // A held contact not closing is an equality for the step: onto Ċ = 0 with
            // projection (so round-off cannot make it separate), else its rate is kept.
            row.inequality = false;
            enforce(row, if project { row.rate } else { 0.0 });
            any |= project;
        } else if row.inequality {
            let (s, u) = (distance(row), normal_speed(row));
            if (s <= touch || is_held) && u < 0.0 {
                let e = if -u > bounce_speed { restitution } else { 0.0 };
                // ΔĊ = −(1+e)Ċ: c = (1+e)Ċ.
                enforce(row, (1.0 + e) * row.rate);
                any = true;
            } else if s <= touch {
                // Touching, not closing: Ċ⁺ ≥ 0 (μ ≥ 0), so that the impulses of its
                // closing neighbours cannot drive it through its surface (a stack).
                enforce(row, row.rate);
            } else {
                leave_out(row);
            }
        } else if project {
            // ΔĊ = −Ċ.
            enforce(row, row.rate);
            any = true;
        } else {
            // Equalities keep their rate (the impulse must not tear the rods).
            enforce(row, 0.0);
        }
    }
    if any {
        apply_correction(rows, v, Some(dynamics));
    }
    any
}
