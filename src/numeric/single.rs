//! One row on one body (a pendulum, a bead): the λ solve of `numeric::solve` for a 1 × 1
//! system, in closed form and without its bookkeeping.
//!
//! The general solve (`solve::solve_cached_into`) scales the row to a unit diagonal, keeps
//! a factor cache (the bits of J and 1/m compared at every call), assembles Ã, factors its
//! band, substitutes with one step of refinement and unscales λ: a few dozen operations of
//! arithmetic for one row, inside a few hundred instructions of buffers, loops and checks.
//! [`solve_single`] does the same arithmetic in the same order — row norm, Ĵ = J/‖J‖,
//! Â, J̃ = Ĵ/√Â, Ã = J̃·J̃ w, L = √Ã, the two divisions of each substitution, the refinement
//! x += A⁻¹(b − A x), λ = λ̃/(‖J‖√Â), the forces and accelerations — so its numbers are the
//! general solve's bit for bit (a property test holds it to `solve_holding` and
//! `solve_cached`, `tests/simulate.rs`).
//!
//! It serves only the plain case and declines everything else, which the caller then hands
//! to the general solve: an inequality row, a number that is not finite, a negative mass, a
//! zero or overflowing gradient, a pivot at or below the rank tolerance (singular), λ out of
//! the f64 range, and settings other than the band or automatic method. Every diagnostic is
//! therefore the general solve's; this path never makes one.
//!
//! The scaling (‖J‖, Ĵ, Â, J̃, Ã and its root: three square roots and two divisions in one
//! chain) depends on J and 1/m alone, and a simulation solves at one J several times — the
//! step's start, SHAKE's iterations along the start's gradient, and the velocity projection
//! at q⁺, which is the next start's J — so [`solve_single_with`] keeps the last scaling in a
//! [`SingleScaling`] and reuses it while J and 1/m are the same bit for bit, as the general
//! solve's cache reuses its factor: the same numbers, computed once.
//!
//! A correction (SHAKE's iterations, the velocity projection) on a scene whose only slot the
//! row acts on needs the step on that slot alone: [`correction_single`] gives it from the
//! same multiplier ([`SingleScaling`]'s μ̃ and λ, one function for both) without writing a
//! `Solution` or the rows.
//!
//! RATTLE's one-row runs (`stabilize::rattle_one_row_plain` and each step's start before it)
//! take the row without the scaling where a guard allows ([`unscaled_multiplier`]: μ =
//! −(J·F w + c)/(J·J w), one division where the scaled solve chains three square roots and
//! seven divisions, the step's latency): the same number to a few roundings, not bit for
//! bit; outside the guard (magnitudes past 10^±100, a zero gradient, a zero or infinite
//! mass) the scaled solve answers, with its diagnostics.
//!
//! Not here: more than one row (the general solve), contacts, the decision of when to call
//! it (`Dynamics::solve`, `Dynamics::correct`, `Dynamics::correct_single`: at every solve,
//! as the check is cheaper than any bookkeeping it saves).

use super::rows::{Row, Rows};
use super::solve::{Method, Settings, Solution, Status, positive_finite, row_norm};
use super::vector::{dot, not_finite_bit};

/// Norms whose reciprocal is a normal number: the general solve scales Ĵ = J·(1/‖J‖) there
/// and J/‖J‖ outside (`solve::Scaled`), and so does this one.
const RECIPROCAL_NORMS: std::ops::RangeInclusive<f64> = 1e-300..=1e300;

/// Whether `rows` are one equality row acting on one slot: the shape [`solve_single`] serves
/// (it may still decline such rows for their numbers).
pub fn is_single(rows: &Rows) -> bool {
    matches!(rows.rows.as_slice(), [row] if row.jacobian.len() == 1 && !row.inequality)
}

/// The scaling of the last row [`solve_single_with`] solved, keyed by the bits of its J and
/// 1/m: ‖J‖, 1/√Â, J̃ = Ĵ/√Â and Ã = J̃·J̃ w with its root L.
#[derive(Clone, Debug, Default)]
pub struct SingleScaling {
    /// The bits of J's components and of 1/m the numbers below are for, when `known`.
    key: [u64; 4],
    known: bool,
    norm: f64,
    jacobi: f64,
    jt: [f64; 3],
    a: f64,
    l: f64,
}

impl SingleScaling {
    /// The scaling of J on a slot of inverse mass `w` (finite, w ≥ 0), computed in the
    /// general solve's order, or `None` where it declines (a zero or overflowing gradient, Â
    /// not positive and finite); kept for the next call with the same bits.
    #[inline(always)]
    fn of(&mut self, row: &[(usize, [f64; 3])], j: &[f64; 3], w: f64) -> Option<&SingleScaling> {
        self.of_norm(j, w, || row_norm(row))
    }

    /// [`of`](SingleScaling::of) with the row's norm ‖J‖ (`vector::row_norm` of its J) from
    /// `norm`, called only when the kept scaling is not J's: a caller that has the norm
    /// already (SHAKE's residual measured the row's distance at the same J) hands it over.
    #[inline(always)]
    fn of_norm(&mut self, j: &[f64; 3], w: f64, norm: impl FnOnce() -> f64) -> Option<&SingleScaling> {
        let key = [j[0].to_bits(), j[1].to_bits(), j[2].to_bits(), w.to_bits()];
        // Compared whole, joined by `&`: one test, not four branches.
        if self.known & (self.key == key) {
            return Some(self);
        }
        self.scale(j, w, key, norm())
    }

    /// [`of`](SingleScaling::of) at a J or 1/m other than the kept one's (`key` their bits),
    /// ‖J‖ = `norm`.
    #[inline(never)]
    fn scale(&mut self, j: &[f64; 3], w: f64, key: [u64; 4], norm: f64) -> Option<&SingleScaling> {
        self.known = false;
        // Scaling: Ĵ = J/‖J‖, Â = ‖Ĵ‖² w, J̃ = Ĵ/√Â.
        if !(norm.is_finite() && norm != 0.0) {
            return None;
        }
        let inverse = 1.0 / norm;
        let u = if RECIPROCAL_NORMS.contains(&norm) { j.map(|x| x * inverse) } else { j.map(|x| x / norm) };
        let a_hat = 0.0 + dot(&u, &u) * w;
        if !positive_finite(a_hat) {
            return None;
        }
        let jacobi = 1.0 / a_hat.sqrt();
        let jt = u.map(|x| x * jacobi);
        // Ã = J̃·J̃ w (one term, added to a zero band) and its factor L = √Ã (used only when
        // Ã passes the caller's rank tolerance).
        let a = 0.0 + dot(&jt, &jt) * w;
        *self = SingleScaling { key, known: true, norm, jacobi, jt, a, l: a.sqrt() };
        Some(self)
    }
}

impl SingleScaling {
    /// μ̃ and λ of the scaled row under the force `f` on its slot (of inverse mass `w`) and
    /// the bias `bias`, in the general solve's order; `None` where it declines: the pivot Ã at
    /// or below `rank_tolerance` (singular), μ̃ not finite, λ out of the f64 range.
    #[inline(always)]
    fn multiplier(&self, f: &[f64; 3], w: f64, bias: f64, rank_tolerance: f64) -> Option<(f64, f64)> {
        let &SingleScaling { norm, jacobi, jt, a, l, .. } = self;
        if a.is_nan() || a <= rank_tolerance {
            return None;
        }
        // −b̃ = −(J̃·F w + c/‖J‖/√Â), the sum of the forces' part started from −0.
        let b = (-0.0 + dot(&jt, f) * w) + (bias / norm) * jacobi;
        let rhs = -b;
        // L Lᵀ x = −b̃ (forward and back: a division each, after subtracting the empty sum
        // −0), then one step of refinement x += A⁻¹(−b̃ − A x).
        let mut mu = ((rhs - -0.0) / l) / l;
        let residual = rhs - (0.0 + (0.0 + a * mu));
        mu += ((residual - -0.0) / l) / l;
        if !mu.is_finite() {
            return None;
        }
        // λ = λ̃/(‖J‖√Â); out of the f64 range the general solve says so in a diagnostic.
        let lambda = (mu * jacobi) / norm;
        if mu != 0.0 && !lambda.is_normal() {
            return None;
        }
        Some((mu, lambda))
    }
}

/// Whether every component of `x` is finite (`is_finite` joined by `&`, as
/// `dynamics::all_finite`: no chain of dependent additions).
fn finite3(x: &[f64; 3]) -> bool {
    x[0].is_finite() & x[1].is_finite() & x[2].is_finite()
}

/// Whether every number of `xs` is finite: the OR of their `vector::not_finite_bit`s, one
/// test (where `is_finite` joined by `&` became a branch for each).
#[inline(always)]
fn all_finite<const N: usize>(xs: [f64; N]) -> bool {
    xs.iter().fold(0u64, |bad, x| bad | not_finite_bit(*x)) >> 63 == 0
}

/// A correction on a scene of one slot with one row acting on it (a pendulum, a bead): the
/// step Δx = M⁻¹Jᵀμ with (J M⁻¹ Jᵀ) μ = −`bias`, the forces zero — what SHAKE and the
/// velocity projection ask of `Dynamics::correct` once they have set the row's c to
/// `bias`, marked it an equality and zeroed the forces. The row is taken as an equality
/// whatever its flag says (the caller decides that, as the projections do). Returns the
/// step on the slot, bit for bit the acceleration [`solve_single_with`] gives those rows,
/// or `None` where it declines them (or the scene has more than one slot), and the general
/// solve must answer; `rows` is only read and no `Solution` written, so a step of a run
/// that has one row on one body spends nothing on them.
pub fn correction_single(rows: &Rows, bias: f64, scaling: &mut SingleScaling) -> Option<[f64; 3]> {
    correction_single_multiplier(rows, bias, scaling).map(|(step, _)| step)
}

/// [`correction_single`] with its multiplier μ (the step is M⁻¹Jᵀμ, to rounding): what
/// SHAKE keeps to predict the next step's correction (`stabilize::ShakeHistory`).
pub fn correction_single_multiplier(rows: &Rows, bias: f64, scaling: &mut SingleScaling) -> Option<([f64; 3], f64)> {
    let [row] = rows.rows.as_slice() else { return None };
    let [(0, j)] = row.jacobian.as_slice() else { return None };
    let ([w], [velocity], [_]) = (rows.inverse_mass.as_slice(), rows.velocity.as_slice(), rows.force.as_slice()) else {
        return None;
    };
    let w = *w;
    // As `solve_single_with` checks them, the zeroed force aside.
    if !all_finite([velocity[0], velocity[1], velocity[2], bias, w, j[0], j[1], j[2]]) || w < 0.0 {
        return None;
    }
    correction_checked(j, w, bias, scaling)
}

/// [`correction_single_multiplier`] of a row whose J `j` on the slot of inverse mass `w`
/// (and the slot's velocity) the caller has found finite, with w ≥ 0, and `bias` finite:
/// the same step and multiplier, from the numbers alone (no `Rows`: RATTLE's one-row step,
/// `stabilize::rattle_one_row`, has them in hand).
#[inline(always)]
pub fn correction_checked(j: &[f64; 3], w: f64, bias: f64, scaling: &mut SingleScaling) -> Option<([f64; 3], f64)> {
    correction_with_norm(j, w, bias, || row_norm(&[(0, *j)]), scaling)
}

/// [`correction_checked`] with J's norm from `norm` (`vector::row_norm` of the row's J, the
/// same number), called only when the kept scaling is not J's.
#[inline(always)]
pub fn correction_with_norm(
    j: &[f64; 3],
    w: f64,
    bias: f64,
    norm: impl FnOnce() -> f64,
    scaling: &mut SingleScaling,
) -> Option<([f64; 3], f64)> {
    let settings = Settings::default();
    let scaled = scaling.of_norm(j, w, norm)?;
    let (mu, lambda) = scaled.multiplier(&[0.0; 3], w, bias, settings.rank_tolerance)?;
    // Σ λ J = λ̃ J̃, added to a zero force; a = (0 + Σ λ J) w.
    Some((scaled.jt.map(|x| (0.0 + (0.0 + mu * x)) * w), lambda))
}

/// [`solve_single_with`] without a kept scaling: every call scales its row afresh.
pub fn solve_single(rows: &Rows, settings: &Settings, out: &mut Solution) -> bool {
    solve_single_with(rows, settings, &mut SingleScaling::default(), out)
}

/// λ for one equality row on one slot, into `out` — the numbers of `solve::solve_cached`
/// (and so of `solve::solve_holding`) bit for bit. Returns false, with `out` untouched, where
/// the general solve must answer: rows of another shape ([`is_single`]), a number that is not
/// finite, a negative mass, a zero gradient, a singular pivot, λ out of range, a dense or
/// sparse `settings.method`.
///
/// `scaling` keeps the row's scaling for the next call at the same J and 1/m (bit for bit):
/// the numbers are the same either way.
pub fn solve_single_with(rows: &Rows, settings: &Settings, scaling: &mut SingleScaling, out: &mut Solution) -> bool {
    let [row] = rows.rows.as_slice() else {
        return false;
    };
    let [(body, j)] = row.jacobian.as_slice() else {
        return false;
    };
    if row.inequality || !matches!(settings.method, Method::Auto | Method::Banded) {
        return false;
    }
    let body = *body;
    let n = rows.inverse_mass.len();
    if body >= n || rows.velocity.len() != n || rows.force.len() != n {
        return false;
    }
    let w = rows.inverse_mass[body];
    // Every number finite, every slot's velocity and force included: the general solve's
    // cache serves nothing less (`is_finite` joined by `&`, as `dynamics::all_finite`: no
    // chain of dependent additions).
    let mut slots = true;
    for i in 0..n {
        slots &= finite3(&rows.velocity[i]) & finite3(&rows.force[i]);
    }
    if !(slots & row.bias.is_finite() & w.is_finite() & finite3(j)) || w < 0.0 {
        return false;
    }
    let Some(scaled) = scaling.of(&row.jacobian, j, w) else {
        return false;
    };
    let jt = scaled.jt;
    let Some((mu, lambda)) = scaled.multiplier(&rows.force[body], w, row.bias, settings.rank_tolerance) else {
        return false;
    };
    // The answer in place when `out` has the shape already (the last solve's: a run solves
    // the same system again and again), else sized first.
    if out.lambda.len() != 1 || out.active.len() != 1 || out.contacts.len() != 1 {
        out.lambda.clear();
        out.lambda.push(0.0);
        out.active.clear();
        out.active.push(true);
        out.contacts.clear();
        out.contacts.push(None);
    }
    out.lambda[0] = lambda;
    out.active[0] = true;
    out.contacts[0] = None;
    if out.constraint_force.len() != n || out.acceleration.len() != n {
        out.constraint_force.resize(n, [0.0; 3]);
        out.acceleration.resize(n, [0.0; 3]);
    }
    // Σ λ J = λ̃ J̃ on the row's slot, added to a zero force; a = (F + Σ λ J) w per slot.
    if let ([fc_out], [a_out], [f]) =
        (out.constraint_force.as_mut_slice(), out.acceleration.as_mut_slice(), rows.force.as_slice())
    {
        // One slot (the row's): the loop below's numbers, in line.
        let fc = [0.0 + mu * jt[0], 0.0 + mu * jt[1], 0.0 + mu * jt[2]];
        *fc_out = fc;
        *a_out = [(f[0] + fc[0]) * w, (f[1] + fc[1]) * w, (f[2] + fc[2]) * w];
    } else {
        solution_slots(rows, body, mu, &jt, out);
    }
    if !out.diagnostics.is_empty() {
        out.diagnostics.clear();
    }
    out.status = Status::Solved;
    true
}

/// [`solve_single_with`] for rows of one slot: the same answer in `out`, and the slot's
/// acceleration returned (what a run's step takes from the answer), or `None`, with `out`
/// untouched, where `solve_single_with` would decline or the rows have more than one slot.
/// `finite`: every number of `rows` is known to be finite (a run's rows as
/// `Dynamics::rows` and `Dynamics::rows_moved_into` return them: they report any other),
/// so only the sign of 1/m is tested; else each is, as `solve_single_with` tests them.
/// In line: a run's step calls it once, and the general function's checks of the shape
/// and its loop over the slots were a fifth of it.
#[inline(always)]
pub fn solve_one_slot(
    rows: &Rows,
    settings: &Settings,
    scaling: &mut SingleScaling,
    out: &mut Solution,
    finite: bool,
) -> Option<[f64; 3]> {
    let (row, j, w, velocity, f) = one_slot_equality(rows, settings)?;
    // Every number finite, as `solve_single_with` checks them (unless known).
    let (v, b) = (velocity, row.bias);
    if !(finite || all_finite([v[0], v[1], v[2], f[0], f[1], f[2], b, w, j[0], j[1], j[2]])) || w < 0.0 {
        return None;
    }
    let scaled = scaling.of(&row.jacobian, j, w)?;
    let jt = scaled.jt;
    let (mu, lambda) = scaled.multiplier(f, w, row.bias, settings.rank_tolerance)?;
    // Σ λ J = λ̃ J̃, added to a zero force; a = (F + Σ λ J) w.
    let fc = [0.0 + mu * jt[0], 0.0 + mu * jt[1], 0.0 + mu * jt[2]];
    let a = [(f[0] + fc[0]) * w, (f[1] + fc[1]) * w, (f[2] + fc[2]) * w];
    write_one_slot(out, lambda, fc, a);
    Some(a)
}

/// A one-slot row's numbers: the row, J, 1/m, v and F ([`one_slot_equality`]).
type OneSlotEquality<'a> = (&'a Row, &'a [f64; 3], f64, &'a [f64; 3], &'a [f64; 3]);

/// The one equality row of `rows` with its one J entry on slot 0, that slot's J, 1/m, v
/// and F, where `settings`' method lets the one-row solves answer (`Auto`, `Banded`):
/// what [`solve_one_slot`] and [`solve_one_slot_unscaled`] serve; else `None`.
#[inline(always)]
fn one_slot_equality<'a>(rows: &'a Rows, settings: &Settings) -> Option<OneSlotEquality<'a>> {
    let (row, w, v, f) = rows.one_slot()?;
    let [(0, j)] = row.jacobian.as_slice() else {
        return None;
    };
    if row.inequality || !matches!(settings.method, Method::Auto | Method::Banded) {
        return None;
    }
    Some((row, j, w, v, f))
}

/// [`solve_one_slot`]'s answer into `out`: λ, the constraint force `fc` and the
/// acceleration `a` of the one slot, in place when `out` has that shape already.
#[inline(always)]
fn write_one_slot(out: &mut Solution, lambda: f64, fc: [f64; 3], a: [f64; 3]) {
    match (out.lambda.as_mut_slice(), out.active.as_mut_slice(), out.contacts.as_mut_slice()) {
        ([l], [active], [contact]) => (*l, *active, *contact) = (lambda, true, None),
        _ => {
            out.lambda.clear();
            out.lambda.push(lambda);
            out.active.clear();
            out.active.push(true);
            out.contacts.clear();
            out.contacts.push(None);
        }
    }
    match (out.constraint_force.as_mut_slice(), out.acceleration.as_mut_slice()) {
        ([fc_out], [a_out]) => (*fc_out, *a_out) = (fc, a),
        _ => {
            out.constraint_force.clear();
            out.constraint_force.push(fc);
            out.acceleration.clear();
            out.acceleration.push(a);
        }
    }
    if !out.diagnostics.is_empty() {
        out.diagnostics.clear();
    }
    out.status = Status::Solved;
}

/// The magnitudes within which a one-row solve is taken without the scaling
/// ([`unscaled_multiplier`]): |J|², 1/m, the right-hand side and μ each within 10^±100, so
/// no product of the formula leaves the normal range and each is a few roundings of its
/// value, as the scaled solve's are (the scaling serves the general solve's range and its
/// many rows, not the accuracy of one).
const UNSCALED: std::ops::RangeInclusive<f64> = 1e-100..=1e100;

/// μ of one row on one slot without the scaling, μ = −(J·F w + c)/(J·J w): one division
/// where [`solve_single_with`] takes three square roots and seven divisions in one chain
/// (the scaling, the two substitutions, the refinement's two, the unscaling) — the same
/// number to a few roundings (a 1 × 1 system: the scaled solve's λ is this quotient, each
/// of its steps rounded). `None` outside the guard: J·J, w or |J·F w + c| outside
/// 10^±100 (so also a zero J, an infinite or zero mass), μ neither zero nor a normal number
/// within 10^±100; the caller then takes the scaled solve, which answers as ever. RATTLE's
/// one-row step only (`stabilize::rattle_one_row_plain`, the run's start before it): its
/// step is a chain of the two solves, and their roots and divisions were most of its time.
#[inline(always)]
pub fn unscaled_multiplier(j: &[f64; 3], w: f64, f: &[f64; 3], bias: f64) -> Option<f64> {
    let square = dot(j, j);
    let b = dot(j, f) * w + bias;
    if !(UNSCALED.contains(&square) && UNSCALED.contains(&w) && b.abs() <= *UNSCALED.end()) {
        return None;
    }
    let mu = -b / (square * w);
    (mu == 0.0 || UNSCALED.contains(&mu.abs())).then_some(mu)
}

/// [`solve_one_slot`] without the scaling, for RATTLE's one-row runs: λ =
/// [`unscaled_multiplier`], the constraint force λJ and a = (F + λJ) w, written as
/// [`solve_one_slot`] writes its answer; `None`, with nothing written, where that solve
/// would decline the rows or the guard does (every number finite is the caller's, as for
/// `solve_one_slot` with `finite`).
#[inline(always)]
pub fn solve_one_slot_unscaled(rows: &Rows, settings: &Settings, out: &mut Solution) -> Option<[f64; 3]> {
    let (row, j, w, _, f) = one_slot_equality(rows, settings)?;
    if w < 0.0 {
        return None;
    }
    let lambda = unscaled_multiplier(j, w, f, row.bias)?;
    let fc = [0.0 + lambda * j[0], 0.0 + lambda * j[1], 0.0 + lambda * j[2]];
    let a = [(f[0] + fc[0]) * w, (f[1] + fc[1]) * w, (f[2] + fc[2]) * w];
    if !all_finite([a[0], a[1], a[2], fc[0], fc[1], fc[2]]) {
        return None;
    }
    write_one_slot(out, lambda, fc, a);
    Some(a)
}

/// The velocity projection of one row on one slot without the scaling ([`correction_checked`]'s
/// step: Δv = J μ w with μ = −`bias`/(J·J w), [`unscaled_multiplier`] with the forces zero),
/// every component finite; `None` outside the guard (the caller then takes the scaled one).
#[inline(always)]
pub fn correction_unscaled(j: &[f64; 3], w: f64, bias: f64) -> Option<[f64; 3]> {
    let mu = unscaled_multiplier(j, w, &[0.0; 3], bias)?;
    let dv = [(mu * j[0]) * w, (mu * j[1]) * w, (mu * j[2]) * w];
    all_finite(dv).then_some(dv)
}

/// [`solve_single_with`]'s forces and accelerations over every slot: Σ λ J = λ̃ J̃ on the row's
/// slot `body`, zero elsewhere; a = (F + Σ λ J) w.
fn solution_slots(rows: &Rows, body: usize, mu: f64, jt: &[f64; 3], out: &mut Solution) {
    let slots =
        out.constraint_force.iter_mut().zip(&mut out.acceleration).zip(rows.force.iter().zip(&rows.inverse_mass));
    for (i, ((fc_out, a_out), (f, &w))) in slots.enumerate() {
        let fc = if i == body { [0.0 + mu * jt[0], 0.0 + mu * jt[1], 0.0 + mu * jt[2]] } else { [0.0; 3] };
        *fc_out = fc;
        *a_out = [(f[0] + fc[0]) * w, (f[1] + fc[1]) * w, (f[2] + fc[2]) * w];
    }
}
