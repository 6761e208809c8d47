//! The multiplier solve (DESIGN.md steps 4–6): A λ + b = 0 at one state, with λₖ ≥ 0 and
//! complementarity on active inequality rows; the constraint force on each body Σₖ λₖ Jₖᵢ
//! and the accelerations aᵢ = (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ.
//!
//! Design note.
//! - Scaling. Each row is scaled twice before anything is multiplied: Ĵ = J/‖J‖ (‖J‖ computed
//!   without overflow), then J̃ = Ĵ/√Âₖₖ (Jacobi), so Ã = J̃ M⁻¹ J̃ᵀ has a unit diagonal and
//!   every threshold below is relative. No product of two raw J is ever formed, so rows
//!   with |J| ≈ 1e155 or 1e-150 solve as well as |J| ≈ 1. λₖ = λ̃ₖ (√Âₖₖ⁻¹)/‖Jₖ‖ and the force
//!   Σ λ̃ₖ J̃ₖᵢ comes straight from the scaled quantities.
//! - Equalities. A is banded when constraints are numbered along a chain; the band Cholesky
//!   (`numeric::banded`) is linear in the number of rows. Grids and meshes have no narrow
//!   band: the sparse Cholesky in an approximate minimum degree order (`numeric::sparse`)
//!   serves them, and dense Cholesky small blocks. `plan` chooses once per pattern, by
//!   counts of multiply–adds; a run's cache keeps the choice and the sparse analysis.
//!   A small pivot (Ã singular within `rank_tolerance`: a redundant constraint, a singular
//!   configuration) falls back to a dense eigendecomposition: the minimum-norm λ when the
//!   system is consistent, least squares when not, always with a diagnostic naming the rows, the
//!   rank and a condition estimate. One step of iterative refinement follows each solve.
//! - Inequalities. Rows are classified by `numeric::contact`. If the equality solve over all
//!   touching rows already pushes on every inequality (λ ≥ 0), it is the answer (the QP's
//!   solution then coincides with it). Otherwise the QP (`numeric::qp`, Clarabel) picks the
//!   active set, and the equality solve on that set polishes it to full precision; KKT
//!   residuals are checked and reported when poor. When Clarabel fails (iteration limit,
//!   numerical error) or its active set does not polish, Murty's least-index principal
//!   pivoting (exact, terminates for positive definite Ã) starts from its guess, for blocks
//!   of up to 64 rows.
//!
//! Singular blocks past the dense decomposition (and, in a run's cache, within it when
//! singular whatever their numbers) take their minimum norm from a sparse factor: of the Gram
//! matrix of the velocity components their rows move when those rows hold every one
//! (`numeric::gram`), of a regularised Ã otherwise (`sparse_minimum_norm`).
//!
//! Minimum norm is that of λ for C/κ (what the pseudo-inverse of the unscaled A gives): the
//! eigendecomposition runs on the scaled Ã, and the null-space part is then chosen to minimise ‖λ‖ with
//! λₖ = λ̃ₖ/(‖Jₖ‖√Âₖₖ) (see `minimum_norm`).
//!
//! Not here: evaluating rows (`numeric::rows`), files, text.

use super::banded::{Banded, BandedCholesky};
use super::contact::{ContactState, classify_holding};
use super::gram::{BodySpace, BodySpaceWork, Bounds, Gram, Iterated};
use super::qp::{Kkt, QpStatus, kkt, solve_qp};
use super::rows::Rows;
use super::sparse::{SparseFactor, SparseWork};
use nalgebra::{DMatrix, DVector};

/// Default of [`Settings::rank_tolerance`]: a pivot of the unit-diagonal Ã at 1e-10 means a
/// row is dependent on the others to about five digits of a double's sixteen, so the rows are
/// redundant rather than merely close, and rounding (≈1e-16 per entry) stays far below it.
pub const RANK_TOLERANCE: f64 = 1e-10;
/// Default of [`Settings::contact_tolerance`]: about 1e7 ulps, so the rounding of C and Ċ at
/// a resting contact is inside it, while a contact 1e-9 of the scene's size apart is apart.
pub const CONTACT_TOLERANCE: f64 = 1e-9;
/// The band solve is used when `BAND_FRACTION` · bandwidth < n: the band factor costs n w²
/// against dense n³/3, and below a quarter of the size the band path wins even against
/// nalgebra's faster dense kernels (the `solve` benchmark's crossover).
const BAND_FRACTION: usize = 4;
/// Blocks smaller than this are not renumbered (reverse Cuthill–McKee) nor ordered for the
/// sparse factor: their dense solve takes microseconds, which an ordering would not win back.
const RENUMBER_MIN_ROWS: usize = 16;
/// A band at most this wide (after renumbering) is taken without analysing the sparse
/// factor: a chain's (1) or a ladder's band costs n (w + 1)² multiply–adds, which no order
/// of a sparse factor beats by enough to pay for finding it.
const NARROW_BAND: usize = 3;
/// The sparse factor's multiply–adds cost about this many of the band's (indirect
/// addressing, an elimination-tree walk per row; the `solve` benchmark's grid), so `Auto`
/// weighs its count by it against the band's n (w + 1)².
const SPARSE_COST: f64 = 2.0;
/// Dense Cholesky's multiply–adds cost about this fraction of the band's (nalgebra's
/// vectorised kernels): the ratio `BAND_FRACTION` was measured at.
const DENSE_COST: f64 = 0.2;
/// The most multiply–adds a sparse factorisation may take (about thirty times a dense one
/// of [`MAX_DENSE_ROWS`] rows, about ten seconds here): past it the block is refused as too
/// large, a deterministic bound rather than a timer.
pub const MAX_SPARSE_FLOPS: f64 = 1e10;
/// Murty's pivoting gives up after `FLIPS_PER_ROW` · n + `FLIPS_BASE` flips: the least-index
/// rule needs a few flips per row on a positive definite Ã, so the bound only stops a cycle
/// that rounding causes on a degenerate block.
const FLIPS_PER_ROW: usize = 200;
const FLIPS_BASE: usize = 1000;
/// Murty's pivoting runs on blocks of at most this many rows (each flip is an equality solve;
/// larger blocks are left to Clarabel's answer).
const PIVOTING_MAX_ROWS: usize = 64;
/// A least-squares λ counts as consistent when its residual is within
/// √`contact_tolerance` · `CONSISTENCY` of the system's size (3e-7 at the default): the
/// rounding of an ill-conditioned but consistent system stays below, rows that contradict
/// each other by more than that are reported inconsistent.
const CONSISTENCY: f64 = 1e-2;
/// A row takes part in a null vector of Ã (it is named as redundant) when its component is
/// above `NULL_SHARE` of the vector's largest: smaller ones are rounding.
const NULL_SHARE: f64 = 1e-6;
/// ε of the regularised factor Ã + ε W² that solves singular blocks past [`MAX_DENSE_ROWS`]
/// ([`sparse_minimum_norm`]), relative to Ã's unit diagonal: each solve shrinks the error
/// along an eigenvalue σ of the weighted Ã by ε/(σ + ε), so the eigenvalues a grid or a
/// chain of joints has (1e-4 and up at ten thousand rows) converge in a few solves, while
/// the residual's rounding in the null space (≈ 1e-16) grows by 1/ε into λ's split among
/// the redundant rows only (1e-8 of λ; the impulse Jᵀλ has no null-space part).
const REGULARISATION: f64 = 1e-8;
/// The rounding of a residual rhs − Ã μ [`sparse_minimum_norm`] allows beside its
/// consistency bound on rhs, in ulps of max|Ã|·max|μ|: a consistent block's iterate stops at
/// a few ulps per entry of a row (tens); rows that contradict each other by r₀ make μ grow by
/// r₀/ε a solve (1e8 r₀), so ITERATE_ROUNDING · 2⁻⁵² · 1e8 r₀ ≈ 1e-4 r₀ per solve, forty solves
/// at most, stays below the r₀ they leave.
const ITERATE_ROUNDING: f64 = 1e4;
/// The most regularised solves [`sparse_minimum_norm`] takes; it stops earlier as soon as a
/// solve no longer halves the residual (it is then at its rounding).
const REGULARISED_SOLVES: usize = 40;
/// Weights of rows (λₖ/λ̃ₖ) below this fraction of the largest would make ε Wₖ² vanish
/// beside rounding: [`sparse_minimum_norm`] then minimises the norm of the scaled λ̃.
const WEIGHT_RANGE: f64 = 1e-4;

/// The most rows a dense equality solve (or the minimum-norm solve of a singular block) may
/// have: both cost n³ (a symmetric eigendecomposition, then a least squares over the null
/// space), about a second here. A coupled block past it that is singular, or that neither
/// the band nor the sparse factor serves, is refused ([`Diagnostic::TooLarge`]), a
/// deterministic bound rather than a timer.
pub const MAX_DENSE_ROWS: usize = 1000;

/// Which factorisation the equality solve uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Method {
    /// A narrow band at once (chains); otherwise the sparse Cholesky in an approximate
    /// minimum degree order when its count of multiply–adds (weighted) is below both band
    /// Cholesky's (after reverse Cuthill–McKee renumbering if that narrows the band; only
    /// when the bandwidth is under a quarter of the size) and dense Cholesky's (up to
    /// [`MAX_DENSE_ROWS`] rows); otherwise band when it fits, dense when not.
    #[default]
    Auto,
    /// Dense Cholesky (nalgebra), whatever the structure.
    Dense,
    /// Band Cholesky (renumbered by reverse Cuthill–McKee if that narrows the band),
    /// whatever the bandwidth.
    Banded,
    /// Sparse L D Lᵀ in an approximate minimum degree order (`numeric::sparse`), whatever
    /// the structure.
    Sparse,
}

/// Tolerances and choices of the solve. Build with `Settings::default()` and field updates,
/// then [`Settings::validate`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Pivots and singular values of the unit-diagonal Ã at or below this are zero.
    pub rank_tolerance: f64,
    /// Relative tolerance of "touching" and "resting" for inequality rows
    /// (`numeric::contact`), of consistency checks and of the QP's KKT residuals.
    pub contact_tolerance: f64,
    /// The length against which a contact distance |C|/‖∇C‖ counts as zero.
    pub length_scale: f64,
    /// A speed against which a contact's normal speed Ċ/‖∇C‖ counts as zero beside the
    /// fastest body it involves (`numeric::contact`): 0 by default, the bodies' speeds
    /// alone. A simulation sets what its forces build up in a step, so that a scene at rest,
    /// whose speeds are rounding, does not take the rounding of Ċ for opening or closing.
    pub speed_scale: f64,
    pub method: Method,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            rank_tolerance: RANK_TOLERANCE,
            contact_tolerance: CONTACT_TOLERANCE,
            length_scale: 1.0,
            speed_scale: 0.0,
            method: Method::Auto,
        }
    }
}

/// A setting out of range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SettingsError {
    #[error("`{name}` must be a finite positive number below 1, found {value}")]
    Tolerance { name: &'static str, value: f64 },
    #[error("`length_scale` must be a finite positive number, found {0}")]
    Length(f64),
    #[error("`speed_scale` must be a finite number, zero or positive, found {0}")]
    Speed(f64),
}

impl Settings {
    pub fn validate(&self) -> Result<(), SettingsError> {
        for (name, value) in [("rank_tolerance", self.rank_tolerance), ("contact_tolerance", self.contact_tolerance)] {
            if !(value > 0.0 && value < 1.0) {
                return Err(SettingsError::Tolerance { name, value });
            }
        }
        if !(self.length_scale > 0.0 && self.length_scale.is_finite()) {
            return Err(SettingsError::Length(self.length_scale));
        }
        if !(self.speed_scale >= 0.0 && self.speed_scale.is_finite()) {
            return Err(SettingsError::Speed(self.speed_scale));
        }
        Ok(())
    }
}

/// How a solve went, from best to worst (`Ord` follows this order).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord)]
pub enum Status {
    /// Every condition holds to the tolerances.
    #[default]
    Solved,
    /// Redundant constraints (A singular) with consistent data: the minimum-norm λ.
    MinimumNorm,
    /// A constraint has a zero gradient here (a singular configuration): it carries no force.
    Singular,
    /// The QP solved to reduced accuracy or with poor KKT residuals.
    Inaccurate,
    /// The constraints contradict each other here: the least-squares minimum-norm λ.
    Inconsistent,
    /// No answer: non-finite input, or the QP failed. λ is 0 on the rows involved.
    Failed,
}

impl Status {
    /// A short name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Status::Solved => "solved",
            Status::MinimumNorm => "minimum-norm",
            Status::Singular => "singular",
            Status::Inaccurate => "inaccurate",
            Status::Inconsistent => "inconsistent",
            Status::Failed => "failed",
        }
    }
}

/// Something the caller should know about a solve: one variant per cause, carrying the
/// constraints involved (indices into the system's constraints) and the numbers that
/// describe it. `report::solution` turns them into sentences with the constraints' names.
#[derive(Clone, Debug, PartialEq)]
pub enum Diagnostic {
    /// The row has non-finite numbers (its gradient or c term, C or Ċ of an inequality, or
    /// the mass, velocity or force of a body it acts on); it is left out (`Failed`). `part`
    /// is the first of them found non-finite, `cause` whether it is NaN or ±∞.
    NonFiniteRow { constraint: usize, part: RowPart, cause: NonFinite },
    /// The gradient is zero here (a singular configuration): the row carries no force.
    /// `unsatisfiable`: its c term is not zero, so its C̈ = 0 cannot hold.
    ZeroGradient { constraint: usize, unsatisfiable: bool },
    /// The row acts only on bodies of infinite mass: it carries no force.
    InfiniteMass { constraint: usize },
    /// An inequality row is closing (Ċ < 0): it needs an impulse; the force holds it as if
    /// resting.
    Closing { constraint: usize },
    /// An inequality row is violated beyond the tolerance; it is treated as touching.
    Penetrating { constraint: usize },
    /// λ is outside the normal f64 range at this scale although the forces are exact.
    LambdaOutOfRange { constraint: usize, lambda: f64 },
    /// λ came out non-finite and was set to 0 (`Failed`).
    NonFiniteLambda { constraint: usize },
    /// Ã is singular on these rows (redundant constraints or a singular configuration) and
    /// the system is consistent: the minimum-norm λ. `rank` of `size` rows; `condition`
    /// estimates σ_max/σ_min of the rest.
    Redundant { constraints: Vec<usize>, rank: usize, size: usize, condition: f64 },
    /// As [`Diagnostic::Redundant`] for a block of `size` rows past [`MAX_DENSE_ROWS`]: the
    /// minimum-norm λ by `solves` sparse solves (`sparse_minimum_norm`: applications of the
    /// body-space pseudo-inverse, or regularised solves); the rank is not computed.
    RedundantSparse { constraints: Vec<usize>, size: usize, solves: usize },
    /// As [`Diagnostic::Redundant`], but the rows contradict each other: the least-squares
    /// minimum-norm λ, with the relative residual left.
    Inconsistent { constraints: Vec<usize>, rank: usize, size: usize, condition: f64, residual: f64 },
    /// The contact QP over these rows gave no answer (`status` is neither solved nor almost
    /// solved); λ is 0 on them.
    QpFailed { constraints: Vec<usize>, status: QpStatus },
    /// The contact QP's answer has poor KKT residuals (`Inaccurate`).
    QpInaccurate { constraints: Vec<usize>, status: QpStatus, iterations: u32, residuals: Kkt },
    /// A restitution outside [0, 1] was asked for; 0 is used.
    Restitution { value: f64 },
    /// The numbers overflow at this state; the solve ran in a length unit of 2^`exponent`
    /// (verified homogeneous) and was scaled back.
    Rescaled { exponent: i64 },
    /// A coupled block of `rows` rows needs a dense solve (it is singular, or neither the
    /// band nor the sparse factor serves it) past [`MAX_DENSE_ROWS`]: it is not solved, λ
    /// is 0 on it (`Failed`).
    TooLarge { constraints: Vec<usize>, rows: usize },
    /// The scene has independent parts at length scales one unit cannot serve: these
    /// constraints (and their bodies) were solved in the caller's unit, the rest in the
    /// rescaled one ([`Diagnostic::Rescaled`]).
    MixedScales { raw: Vec<usize> },
    /// The state is off an equality row ([`off_constraint`]): its first-order distance
    /// |C|/‖∇C‖ is beyond the contact tolerance of `length`, or its normal speed |Ċ|/‖∇C‖
    /// beyond that of `speed`. λ is the force at this state, which is not on the constraint.
    OffConstraint { constraint: usize, distance: f64, length: f64, normal_speed: f64, speed: f64 },
}

/// Which number of a row (or of a body it acts on) is not finite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowPart {
    /// ∇C/κ on some body.
    Gradient,
    /// c, C̈/κ with every acceleration zero.
    CTerm,
    /// C/κ.
    Value,
    /// Ċ/κ.
    Rate,
    /// The inverse mass of this body (a zero, negative or non-finite mass).
    Mass { body: usize },
    /// This body's velocity.
    Velocity { body: usize },
    /// This body's external force.
    Force { body: usize },
}

/// How a number is not finite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NonFinite {
    /// NaN: an undefined operation in the formula (0/0, ∞ − ∞, 0·∞, `sqrt` or `ln` of a
    /// negative number).
    Undefined,
    /// ±∞: the value exceeds f64's range (or a division by zero).
    Overflow,
}

impl NonFinite {
    /// The cause of `x`, `None` when it is finite.
    pub fn of(x: f64) -> Option<NonFinite> {
        if x.is_nan() {
            Some(NonFinite::Undefined)
        } else if x.is_infinite() {
            Some(NonFinite::Overflow)
        } else {
            None
        }
    }

    /// The cause of the first non-finite number among `xs` (NaN wins over ±∞, as the
    /// deeper cause), `None` when all are finite.
    pub fn of_all(xs: impl IntoIterator<Item = f64>) -> Option<NonFinite> {
        xs.into_iter().filter_map(NonFinite::of).max_by_key(|c| matches!(c, NonFinite::Undefined))
    }
}

/// Whether a mass's inverse `w` is unusable: negative, NaN or ±∞ (a mass of zero, negative,
/// or non-finite), with its cause.
fn bad_inverse_mass(w: f64) -> Option<NonFinite> {
    match NonFinite::of(w) {
        Some(c) => Some(c),
        None if w < 0.0 => Some(NonFinite::Undefined),
        None => None,
    }
}

/// Whether `row`'s c term and J, its bodies' inverse masses (finite, ≥ 0), with `motion`
/// their velocities and forces, and with `check_value` its C and Ċ are all finite: the
/// common case of [`non_finite_part`], without branches. Tests combined with `&` (one chain
/// of single-cycle steps, not of additions). Written out rather than as a chain of
/// iterators: this runs for every row of every factorisation.
#[inline]
pub(super) fn row_sound(rows: &Rows, row: &super::rows::Row, check_value: bool, motion: bool) -> bool {
    let finite3 = |x: &[f64; 3]| x[0].is_finite() & x[1].is_finite() & x[2].is_finite();
    let mut ok = row.bias.is_finite();
    for (body, j) in &row.jacobian {
        let w = rows.inverse_mass[*body];
        ok &= (w >= 0.0) & w.is_finite() & finite3(j);
        if motion {
            ok &= finite3(&rows.velocity[*body]) & finite3(&rows.force[*body]);
        }
    }
    if check_value {
        ok &= row.value.is_finite() & row.rate.is_finite();
    }
    ok
}

/// Why a row with finite numbers cannot be scaled ([`scale_row`]).
pub(super) enum Unscalable {
    /// ‖J‖ overflows (finite components).
    Overflow,
    /// ‖J‖ = 0.
    Zero,
    /// Âₖₖ is not positive and finite (every body it acts on has infinite mass).
    InfiniteMass,
}

/// Whether x is positive and finite (`x > 0.0 && x.is_finite()`), tested on its bits as one
/// comparison: those of the positive finite numbers are 1 ..= the largest's, so less one
/// they are below it, and +0 (less one, wrapping: the largest u64), every negative number
/// (the sign bit), ±∞ and the NaNs are not. Written as comparisons, the compiler classified
/// x by its bits in about fifteen instructions: SHAKE's residual runs this for every row's
/// ‖J‖ at every iteration, the scaling for every Âₖₖ.
#[inline(always)]
pub(crate) fn positive_finite(x: f64) -> bool {
    x.to_bits().wrapping_sub(1) < f64::MAX.to_bits()
}

/// Row `row` scaled into `parts` (one per J entry, in order; their slots left as they are):
/// Ĵ = J/‖J‖ (times 1/‖J‖ where that is a normal number), Âₖₖ = Σᵢ ‖Ĵᵢ‖² wᵢ, J̃ = Ĵ/√Âₖₖ;
/// returns ‖J‖ and 1/√Âₖₖ. `parts` holds Ĵ when the row is unscalable at Âₖₖ.
#[inline(always)]
pub(super) fn scale_row(
    row: &super::rows::Row,
    inverse_mass: &[f64],
    parts: &mut [(usize, [f64; 3])],
) -> Result<(f64, f64), Unscalable> {
    let (norm, d) = normalise_row(row, inverse_mass, parts)?;
    for (_, u) in parts.iter_mut() {
        *u = u.map(|x| x * d);
    }
    Ok((norm, d))
}

/// [`scale_row`] but its last step: `parts` hold Ĵ; returns ‖J‖ and 1/√Âₖₖ, by which the
/// caller multiplies each part for J̃ (the chain's solve does, with Ã's entries in the
/// same pass).
#[inline(always)]
pub(super) fn normalise_row(
    row: &super::rows::Row,
    inverse_mass: &[f64],
    parts: &mut [(usize, [f64; 3])],
) -> Result<(f64, f64), Unscalable> {
    let norm = row_norm(&row.jacobian);
    if !norm.is_finite() {
        return Err(Unscalable::Overflow);
    }
    if norm == 0.0 {
        return Err(Unscalable::Zero);
    }
    let inverse = 1.0 / norm;
    let reciprocal = RECIPROCAL_NORMS.contains(&norm);
    let mut a_kk = 0.0;
    for ((_, u), (b, j)) in parts.iter_mut().zip(&row.jacobian) {
        *u = if reciprocal { j.map(|x| x * inverse) } else { j.map(|x| x / norm) };
        a_kk += dot(u, u) * inverse_mass[*b];
    }
    if !positive_finite(a_kk) {
        return Err(Unscalable::InfiniteMass);
    }
    Ok((norm, 1.0 / a_kk.sqrt()))
}

/// The first non-finite number of `row` (and the bodies it acts on), in the order the
/// solve needs them; C and Ċ only for inequalities (`check_value`).
fn non_finite_part(rows: &Rows, row: &super::rows::Row, check_value: bool) -> Option<(RowPart, NonFinite)> {
    // The common case first, without branches.
    if row_sound(rows, row, check_value, true) {
        return None;
    }
    if let Some(c) = NonFinite::of_all(row.jacobian.iter().flat_map(|(_, j)| j.iter().copied())) {
        return Some((RowPart::Gradient, c));
    }
    if let Some(c) = NonFinite::of(row.bias) {
        return Some((RowPart::CTerm, c));
    }
    for &(body, _) in &row.jacobian {
        if let Some(c) = bad_inverse_mass(rows.inverse_mass[body]) {
            return Some((RowPart::Mass { body }, c));
        }
        if let Some(c) = NonFinite::of_all(rows.velocity[body]) {
            return Some((RowPart::Velocity { body }, c));
        }
        if let Some(c) = NonFinite::of_all(rows.force[body]) {
            return Some((RowPart::Force { body }, c));
        }
    }
    if check_value {
        if let Some(c) = NonFinite::of(row.value) {
            return Some((RowPart::Value, c));
        }
        if let Some(c) = NonFinite::of(row.rate) {
            return Some((RowPart::Rate, c));
        }
    }
    None
}

impl Diagnostic {
    /// The status this diagnostic implies on its own (the solve's status is the worst of its
    /// diagnostics'), for callers that merge the diagnostics of two solves.
    pub fn status(&self) -> Status {
        match self {
            Diagnostic::NonFiniteRow { .. } | Diagnostic::NonFiniteLambda { .. } | Diagnostic::TooLarge { .. } => {
                Status::Failed
            }
            Diagnostic::ZeroGradient { .. } | Diagnostic::InfiniteMass { .. } => Status::Singular,
            Diagnostic::Redundant { .. } | Diagnostic::RedundantSparse { .. } => Status::MinimumNorm,
            Diagnostic::Inconsistent { .. } => Status::Inconsistent,
            Diagnostic::QpFailed { status: QpStatus::Infeasible | QpStatus::Unbounded, .. } => Status::Inconsistent,
            Diagnostic::QpFailed { .. } => Status::Failed,
            Diagnostic::QpInaccurate { .. } => Status::Inaccurate,
            Diagnostic::Closing { .. }
            | Diagnostic::Penetrating { .. }
            | Diagnostic::LambdaOutOfRange { .. }
            | Diagnostic::Restitution { .. }
            | Diagnostic::Rescaled { .. }
            | Diagnostic::MixedScales { .. }
            | Diagnostic::OffConstraint { .. } => Status::Solved,
        }
    }

    /// The constraints involved (indices; empty when the whole solve is meant).
    pub fn constraints(&self) -> &[usize] {
        match self {
            Diagnostic::NonFiniteRow { constraint, .. }
            | Diagnostic::ZeroGradient { constraint, .. }
            | Diagnostic::InfiniteMass { constraint }
            | Diagnostic::Closing { constraint }
            | Diagnostic::Penetrating { constraint }
            | Diagnostic::LambdaOutOfRange { constraint, .. }
            | Diagnostic::OffConstraint { constraint, .. }
            | Diagnostic::NonFiniteLambda { constraint } => std::slice::from_ref(constraint),
            Diagnostic::Redundant { constraints, .. }
            | Diagnostic::RedundantSparse { constraints, .. }
            | Diagnostic::Inconsistent { constraints, .. }
            | Diagnostic::QpFailed { constraints, .. }
            | Diagnostic::QpInaccurate { constraints, .. }
            | Diagnostic::TooLarge { constraints, .. } => constraints,
            Diagnostic::MixedScales { raw } => raw,
            Diagnostic::Restitution { .. } | Diagnostic::Rescaled { .. } => &[],
        }
    }
}

/// The equality rows the state is off, as [`Diagnostic::OffConstraint`]: a row whose distance
/// |C|/‖∇C‖ exceeds `contact_tolerance` · `length_scale`, or whose normal speed |Ċ|/‖∇C‖
/// exceeds `contact_tolerance` times its speed scale — the largest speed of the bodies it
/// acts on, or of its own motion ∂C/∂t/‖∇C‖ (a driven constraint at rest). Inequality rows
/// have their contact states instead; a row with a zero or non-finite gradient has its own
/// diagnostics. A solve at any state is an answer for that state: this says only that the
/// state is not one the constraints allow, and by how much.
pub fn off_constraint(rows: &Rows, settings: &Settings) -> Vec<Diagnostic> {
    let tol = settings.contact_tolerance;
    let mut off = Vec::new();
    for (k, row) in rows.rows.iter().enumerate() {
        let norm = row_norm(&row.jacobian);
        if row.inequality || !(norm > 0.0 && norm.is_finite()) {
            continue;
        }
        let (distance, normal_speed) = (row.value / norm, row.rate / norm);
        let along: f64 = row.jacobian.iter().map(|(b, j)| dot(j, &rows.velocity[*b]) / norm).sum();
        let bodies = row.jacobian.iter().map(|(b, _)| safe_norm(&rows.velocity[*b])).fold(0.0, f64::max);
        let speed = bodies.max((normal_speed - along).abs());
        let far = distance.abs() > tol * settings.length_scale;
        let moving = normal_speed.abs() > tol * speed;
        if (far || moving) && distance.is_finite() && normal_speed.is_finite() {
            off.push(Diagnostic::OffConstraint {
                constraint: k,
                distance,
                length: settings.length_scale,
                normal_speed,
                speed,
            });
        }
    }
    off
}

/// The answer at one state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Solution {
    /// λ per constraint (0 for inactive inequalities), referring to C/κ like the rows.
    pub lambda: Vec<f64>,
    /// Equalities: whether the row could take part (a non-zero, finite gradient).
    /// Inequalities: whether the row carries a force (λ > 0).
    pub active: Vec<bool>,
    /// Σₖ λₖ Jₖᵢ per body.
    pub constraint_force: Vec<[f64; 3]>,
    /// (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ per body.
    pub acceleration: Vec<[f64; 3]>,
    pub diagnostics: Vec<Diagnostic>,
    /// The worst outcome of the solve; `Solved` when `diagnostics` holds nothing serious.
    pub status: Status,
    /// Per constraint: the contact state of an inequality row, `None` for equalities.
    pub contacts: Vec<Option<ContactState>>,
}

impl Solution {
    /// Whether the numbers answer the question asked: false when the status is `Failed` or
    /// `Inconsistent` (no λ satisfies every row), or when a row with a zero gradient has a
    /// C̈ = 0 that cannot hold. A zero gradient whose c term is zero is an answer (λ = 0
    /// is exact), as are the minimum-norm λ of consistent redundant rows and an inaccurate
    /// QP's λ (its residuals are in the diagnostic).
    pub fn is_answer(&self) -> bool {
        !matches!(self.status, Status::Failed | Status::Inconsistent)
            && !self.diagnostics.iter().any(|d| matches!(d, Diagnostic::ZeroGradient { unsatisfiable: true, .. }))
    }
}

use super::vector::dot;
/// Re-exported where callers have always found them; they live in `numeric::vector`.
pub use super::vector::{row_norm, safe_norm};

/// The rows rescaled to a unit-diagonal Ã (see the design note).
#[derive(Clone, Debug, Default)]
pub(crate) struct Scaled {
    /// ‖Jₖ‖.
    pub norm: Vec<f64>,
    /// 1/√Âₖₖ.
    pub jacobi: Vec<f64>,
    /// Whether the row has a finite, non-zero gradient and finite numbers.
    pub usable: Vec<bool>,
    /// J̃ₖ = Jₖ/‖Jₖ‖/√Âₖₖ per body, all rows in one buffer: row k is `parts[start[k]..start[k + 1]]`
    /// (empty when not usable).
    parts: Vec<(usize, [f64; 3])>,
    start: Vec<usize>,
}

/// Norms whose reciprocal is a normal number: Ĵ = J·(1/‖J‖) there (a multiplication is
/// cheaper than a division and within an ulp of it); outside, J/‖J‖ by division, so tiny
/// norms stay finite.
const RECIPROCAL_NORMS: std::ops::RangeInclusive<f64> = 1e-300..=1e300;

impl Scaled {
    /// Scales `rows`; rows that cannot carry a force get a diagnostic and `usable = false`.
    pub fn new(rows: &Rows, diagnostics: &mut Vec<Diagnostic>, status: &mut Status) -> Scaled {
        let mut s = Scaled::default();
        s.refill(rows, diagnostics, status);
        s
    }

    /// [`new`](Scaled::new) into `self`'s buffers (no allocation once they have the rows' size).
    fn refill(&mut self, rows: &Rows, diagnostics: &mut Vec<Diagnostic>, status: &mut Status) {
        let k = rows.rows.len();
        for v in [&mut self.norm, &mut self.jacobi] {
            v.clear();
            v.resize(k, 0.0);
        }
        self.usable.clear();
        self.usable.resize(k, false);
        self.parts.clear();
        // Sized up front: 1 % of a chain's simulation (see `assemble`).
        self.parts.reserve(rows.rows.iter().map(|r| r.jacobian.len()).sum());
        self.start.clear();
        self.start.reserve(k + 1);
        for (q, row) in rows.rows.iter().enumerate() {
            self.start.push(self.parts.len());
            // An inequality also needs C and Ċ to be classified.
            if let Some((part, cause)) = non_finite_part(rows, row, row.inequality) {
                diagnostics.push(Diagnostic::NonFiniteRow { constraint: q, part, cause });
                *status = (*status).max(Status::Failed);
                continue;
            }
            let first = self.parts.len();
            self.parts.extend(row.jacobian.iter().map(|&(b, _)| (b, [0.0; 3])));
            let (diagnostic, worst) = match scale_row(row, &rows.inverse_mass, &mut self.parts[first..]) {
                Ok((norm, d)) => {
                    self.norm[q] = norm;
                    self.jacobi[q] = d;
                    self.usable[q] = true;
                    continue;
                }
                // Finite components whose norm overflows (row_norm scales, so this is rare).
                Err(Unscalable::Overflow) => (
                    Diagnostic::NonFiniteRow { constraint: q, part: RowPart::Gradient, cause: NonFinite::Overflow },
                    Status::Failed,
                ),
                Err(Unscalable::Zero) => {
                    (Diagnostic::ZeroGradient { constraint: q, unsatisfiable: row.bias != 0.0 }, Status::Singular)
                }
                Err(Unscalable::InfiniteMass) => (Diagnostic::InfiniteMass { constraint: q }, Status::Singular),
            };
            self.parts.truncate(first);
            diagnostics.push(diagnostic);
            *status = (*status).max(worst);
        }
        self.start.push(self.parts.len());
    }

    /// [`refill`](Scaled::refill) of rows that act on the same slots in the same order as
    /// those `self` was filled from, every row of which was usable, with every velocity and
    /// force finite and no inequality (`SolveCache`'s refactorisation): each row's parts
    /// overwritten in place, the same operations in the same order, so the same bits. False
    /// (`self` then spent) when a row is no longer usable, where `refill` would give a
    /// diagnostic.
    fn rescale_in_place(&mut self, rows: &Rows) -> bool {
        for (q, (row, bounds)) in rows.rows.iter().zip(self.start.windows(2)).enumerate() {
            // The motion is known finite (the cache's entry check).
            if !row_sound(rows, row, false, false) {
                return false;
            }
            match scale_row(row, &rows.inverse_mass, &mut self.parts[bounds[0]..bounds[1]]) {
                Ok((norm, d)) => (self.norm[q], self.jacobi[q]) = (norm, d),
                Err(_) => return false,
            }
        }
        true
    }

    /// Every row's J̃ per body in one buffer (row k at [`range`](Scaled::range)).
    pub(crate) fn parts(&self) -> &[(usize, [f64; 3])] {
        &self.parts
    }

    /// The places of row k's parts in [`parts`](Scaled::parts).
    pub(crate) fn range(&self, k: usize) -> std::ops::Range<usize> {
        self.start[k]..self.start[k + 1]
    }

    /// J̃ₖ per body (empty when row k is not usable).
    pub fn jacobian(&self, k: usize) -> &[(usize, [f64; 3])] {
        &self.parts[self.start[k]..self.start[k + 1]]
    }

    /// λₖ from λ̃ₖ.
    pub fn unscale(&self, k: usize, x: f64) -> f64 {
        if self.usable[k] { (x * self.jacobi[k]) / self.norm[k] } else { 0.0 }
    }

    /// A row quantity of C/κ (a rate, a c term) in the scaled row: x/‖J‖/√Â.
    pub fn scale(&self, k: usize, x: f64) -> f64 {
        scale_by(x, self.norm[k], self.jacobi[k])
    }
}

/// [`Scaled::scale`] with the row's ‖J‖ and 1/√Â given: x/‖J‖/√Â.
#[inline(always)]
fn scale_by(x: f64, norm: f64, jacobi: f64) -> f64 {
    (x / norm) * jacobi
}

/// Ã restricted to some rows: upper-triangle triplets and the bandwidth in that order.
pub(crate) struct Block {
    pub n: usize,
    pub bandwidth: usize,
    pub a: Vec<(usize, usize, f64)>,
    /// Per block row, λₖ/λ̃ₖ = 1/(‖Jₖ‖√Âₖₖ): the weights that make a minimum-norm λ̃ the
    /// minimum-norm λ of C/κ (see [`minimum_norm`]).
    pub weight: Vec<f64>,
    /// The velocity components (slot and axis) with a non-zero part of J̃ and a non-zero
    /// inverse mass: rank Ã ≤ `columns`, so more rows than that are redundant whatever the
    /// numbers ([`structurally_singular`]).
    pub columns: usize,
    /// G = Ŵ⁻¹ J̃ M^{-1/2} of a block singular whatever its numbers, for its minimum norm in
    /// the bodies' velocity space (`numeric::gram`); `None` otherwise.
    pub gram: Option<Gram>,
}

/// Whether `block` has more rows than velocity components its rows move: Ã = J̃ M⁻¹ J̃ᵀ is
/// then singular in exact arithmetic (rank Ã ≤ rank J̃ ≤ `columns`), so a factorisation
/// that does not find it singular found a rounding accident, and the solve goes to the
/// minimum norm without trying one (a rigid grid's redundant loops).
fn structurally_singular(block: &Block) -> bool {
    block.n > block.columns
}

/// Whether `block` is [`structurally_singular`] past the dense decomposition under a method
/// that allows the sparse factor: [`equality`] and the run's cache then take it to the sparse
/// minimum norm (the body-space factor first) without [`plan`]'s analysis of Ã, which only
/// the regularised factor uses (and makes itself where the body space does not serve).
fn singular_past_dense(block: &Block, settings: &Settings) -> bool {
    block.n > MAX_DENSE_ROWS && matches!(settings.method, Method::Auto | Method::Sparse) && structurally_singular(block)
}

/// [`Block::columns`] of the rows `index`.
fn columns(scaled: &Scaled, inverse_mass: &[f64], index: &[usize]) -> usize {
    // One bit per axis of each slot.
    let mut moved = vec![0u8; inverse_mass.len()];
    for &k in index {
        for &(b, j) in scaled.jacobian(k) {
            if inverse_mass[b] != 0.0 {
                moved[b] |= u8::from(j[0] != 0.0) | (u8::from(j[1] != 0.0) << 1) | (u8::from(j[2] != 0.0) << 2);
            }
        }
    }
    moved.iter().map(|m| m.count_ones() as usize).sum()
}

/// One term J̃ₚᵢ·J̃qᵢ wᵢ of Ã: block rows `lo` ≤ `hi`, the two parts' places in
/// `Scaled::parts`, and the body i.
#[derive(Clone, Copy, Debug)]
struct Term {
    lo: usize,
    hi: usize,
    p: usize,
    q: usize,
    body: usize,
}

/// The terms of Ã over the rows `index`, in the order [`assemble`] sums them: body by body,
/// the pairs of rows acting on it. They depend only on which bodies each row acts on, so a
/// solve that keeps its pattern keeps them (`SolveCache`).
fn terms(scaled: &Scaled, n_bodies: usize, index: &[usize]) -> Vec<Term> {
    // The rows acting on each body, bucketed by body (counting sort: one buffer, no Vec per body).
    let mut first = vec![0usize; n_bodies + 1];
    for &k in index {
        for &(b, _) in scaled.jacobian(k) {
            first[b + 1] += 1;
        }
    }
    for b in 0..n_bodies {
        first[b + 1] += first[b];
    }
    let mut fill = first.clone();
    let mut acting_on = vec![(0usize, 0usize); first[n_bodies]];
    for (p, &k) in index.iter().enumerate() {
        for (at, &(b, _)) in (scaled.start[k]..).zip(scaled.jacobian(k)) {
            acting_on[fill[b]] = (p, at);
            fill[b] += 1;
        }
    }
    let mut terms = Vec::with_capacity(acting_on.len() * 2);
    for body in 0..n_bodies {
        let acting = &acting_on[first[body]..first[body + 1]];
        for (x, &(p, jp)) in acting.iter().enumerate() {
            for &(q, jq) in &acting[x..] {
                let (lo, hi) = if p <= q { (p, q) } else { (q, p) };
                terms.push(Term { lo, hi, p: jp, q: jq, body });
            }
        }
    }
    terms
}

/// The value of one term of Ã.
fn term_value(scaled: &Scaled, inverse_mass: &[f64], t: &Term) -> f64 {
    dot(&scaled.parts[t.p].1, &scaled.parts[t.q].1) * inverse_mass[t.body]
}

/// Ãₚq = Σᵢ J̃ₚᵢ·J̃qᵢ wᵢ over the bodies rows p and q of `index` share.
pub(crate) fn assemble(scaled: &Scaled, inverse_mass: &[f64], index: &[usize]) -> Block {
    let terms = terms(scaled, inverse_mass.len(), index);
    let bandwidth = terms.iter().map(|t| t.hi - t.lo).max().unwrap_or(0);
    let a = terms.iter().map(|t| (t.lo, t.hi, term_value(scaled, inverse_mass, t))).collect();
    let weight: Vec<f64> = index.iter().map(|&k| scaled.unscale(k, 1.0)).collect();
    let columns = columns(scaled, inverse_mass, index);
    let n = index.len();
    let gram = (n > columns).then(|| gram(scaled, inverse_mass, index, &weight)).flatten();
    Block { n, bandwidth, a, weight, columns, gram }
}

/// G of the rows `index` with their weights (see `numeric::gram`).
fn gram(scaled: &Scaled, inverse_mass: &[f64], index: &[usize], weight: &[f64]) -> Option<Gram> {
    let ranges: Vec<_> = index.iter().map(|&k| scaled.range(k)).collect();
    Gram::new(scaled.parts(), &ranges, inverse_mass, weight, WEIGHT_RANGE)
}

/// Solves for λ at `rows` with the default settings.
pub fn solve(rows: &Rows) -> Solution {
    solve_with(rows, &Settings::default())
}

/// Solves for λ at `rows`: a fresh [`Solution`] and [`solve_into`].
pub fn solve_with(rows: &Rows, settings: &Settings) -> Solution {
    let mut out = Solution::default();
    solve_into(rows, settings, &mut out);
    out
}

/// [`solve_with`] into `out`, reusing its vectors: every field of `out` (λ, the active set,
/// the contact states, the forces, the accelerations, the diagnostics and the status) is
/// overwritten, and the answer is [`solve_with`]'s bit for bit whatever `out` held before
/// (`tests/solve_into.rs`). What an engine that solves every frame calls, with the answer
/// kept outside its loop: a chain's solve (`numeric::chain`) then allocates nothing once
/// `out` has held an answer of that size; the general solve still allocates its own
/// buffers (the scaling, the block, its factor), but not the vectors of the answer.
///
/// ```
/// use lagrange::numeric::rows::{Row, Rows};
/// use lagrange::numeric::solve::{Settings, Solution, solve_into, solve_with};
///
/// // A bead on a unit circle at rest, under gravity: C = x² + y² − 1, J = (2x, 2y).
/// let rows = Rows {
///     rows: vec![Row { value: 0.0, rate: 0.0, bias: 0.0, inequality: false, jacobian: vec![(0, [0.0, -2.0, 0.0])] }],
///     inverse_mass: vec![1.0],
///     velocity: vec![[0.0; 3]],
///     force: vec![[0.0, -9.81, 0.0]],
///     ..Rows::default()
/// };
/// let settings = Settings::default();
/// let mut out = Solution::default();
/// for _ in 0..3 {
///     // The same answer each frame, in the same buffers.
///     solve_into(&rows, &settings, &mut out);
///     assert_eq!(out, solve_with(&rows, &settings));
/// }
/// ```
pub fn solve_into(rows: &Rows, settings: &Settings, out: &mut Solution) {
    solve_holding_into(rows, settings, &[], out);
}

/// Solves for λ at `rows`, with the inequality rows marked in `held` (a simulation's active
/// set, `numeric::dynamics`) taken as touching whatever their distance
/// (`contact::classify_holding`): they stay candidates, λ ≥ 0, and leave only when λ would
/// turn negative or they open. A fresh [`Solution`] and [`solve_holding_into`].
pub fn solve_holding(rows: &Rows, settings: &Settings, held: &[bool]) -> Solution {
    let mut out = Solution::default();
    solve_holding_into(rows, settings, held, &mut out);
    out
}

/// [`solve_holding`] into `out`, reusing its vectors as [`solve_into`] does: every field is
/// overwritten, the answer [`solve_holding`]'s bit for bit.
pub fn solve_holding_into(rows: &Rows, settings: &Settings, held: &[bool], out: &mut Solution) {
    // Equality rows that form a chain in their order: the same numbers in a few passes
    // (`numeric::chain`), declined (`out` untouched) wherever this solve would say more.
    if !super::chain::solve_into(rows, settings, out) {
        general_into(rows, settings, held, out);
    }
}

/// Whether [`solve_holding`] answers `rows` by its fast path for chains (`numeric::chain`):
/// for the tests of the switch.
#[doc(hidden)]
pub fn chain_serves(rows: &Rows, settings: &Settings) -> bool {
    super::chain::solve_into(rows, settings, &mut Solution::default())
}

/// [`solve_holding`] without its fast path for chains (`numeric::chain`): the reference that
/// path is held to, bit for bit (`tests/chain_solve.rs`).
#[doc(hidden)]
pub fn solve_general(rows: &Rows, settings: &Settings, held: &[bool]) -> Solution {
    let mut out = Solution::default();
    general_into(rows, settings, held, &mut out);
    out
}

/// [`solve_general`] into `out`: its own buffers allocated afresh, the answer written into
/// `out`'s vectors.
fn general_into(rows: &Rows, settings: &Settings, held: &[bool], out: &mut Solution) {
    let k = rows.rows.len();
    let mut diagnostics = std::mem::take(&mut out.diagnostics);
    diagnostics.clear();
    let mut status = Status::Solved;
    let scaled = Scaled::new(rows, &mut diagnostics, &mut status);
    let contacts = classify_holding(rows, settings, held);
    // Candidates: usable equalities, and inequality rows touching without separating.
    let index: Vec<usize> = (0..k)
        .filter(|&q| {
            scaled.usable[q]
                && match contacts[q] {
                    None => true,
                    Some(c) => c.is_candidate(),
                }
        })
        .collect();
    for (q, contact) in contacts.iter().enumerate() {
        if let Some(ContactState::Closing) = contact {
            diagnostics.push(Diagnostic::Closing { constraint: q });
        }
        if let Some(ContactState::Penetrating) = contact {
            diagnostics.push(Diagnostic::Penetrating { constraint: q });
        }
    }
    let b = right_hand_side(rows, &scaled, &index);
    let nonnegative: Vec<bool> = index.iter().map(|&q| rows.rows[q].inequality).collect();
    let block = assemble(&scaled, &rows.inverse_mass, &index);
    let mu = multipliers(&block, &b, &nonnegative, &index, settings, &mut diagnostics, &mut status);
    finish_into(rows, &scaled, &index, &mu, diagnostics, status, out);
    out.contacts.clear();
    out.contacts.extend_from_slice(&contacts);
}

/// Which way a [`solve_cached`] went (for tests of the switch, and for profiles).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SolvePath {
    /// Nothing solved yet.
    #[default]
    None,
    /// The cached scaling and factor served: J and the masses were bit for bit those it
    /// was made from.
    Reused,
    /// J or the masses changed: scaled, assembled and factored anew, and cached (in the
    /// cache's own buffers when the rows act on the same bodies as before).
    Factored,
    /// J changed by less than [`STALE_CHANGE`] on a block the body-space factor serves:
    /// scaled anew, the kept factor iterated to this J's minimum norm (at rounding, or it is
    /// factored after all and the path is [`SolvePath::Factored`]). A velocity change
    /// ([`SolveCache::set_velocity_space`]) near a stale entry's J is not even scaled anew:
    /// the entry as it is preconditions the rows' own residual.
    Stale,
    /// Not a case the cache serves (an inequality row, a number that is not finite, a row
    /// that cannot carry a force, a block within [`MAX_DENSE_ROWS`] singular by its numbers
    /// only, a dense one past it, rows of a singular block that contradict each other):
    /// [`solve_holding`].
    General,
}

/// What repeated solves with the same J and masses share: the scaling of the rows
/// (J/‖J‖ and Jacobi) and the factor of Ã (band, sparse or dense). A run's solves come in
/// such series — the acceleration solve at the start of a step, every SHAKE iteration along
/// the start's gradients, and the next step's start at the positions the velocity
/// projection had — so most of them only substitute a right-hand side. When J changes but
/// acts on the same bodies (every step of a run), the terms of Ã and where each goes in the
/// band or the sparse matrix are kept (with the sparse factor's order, elimination tree and
/// pattern of L), so a new factor costs the arithmetic alone.
///
/// It serves only equality rows whose numbers are all finite and usable, on a block the
/// band, sparse or dense factorisation factors, or a singular one past [`MAX_DENSE_ROWS`]
/// whose minimum norm `sparse_minimum_norm` iterates to: the body-space factor
/// (`numeric::gram`) where the rows hold every component they move, else the regularised
/// factor of Ã + ε W², kept and refactored in place on a new J while the block is singular
/// whatever its numbers (`Block::columns`); each solve checks its residual, leaving rows
/// that contradict each other to the general solve. Anything else goes to
/// [`solve_holding`] unchanged. A solve it serves is the one `solve_holding` would compute,
/// number for number (the same scaling, assembly, factor and refinement, made from inputs
/// equal bit for bit), with two exceptions: a body-space factor kept for a J that moved in
/// its last bits ([`SolvePath::Stale`]) iterates to the same minimum norm to rounding, not
/// bit for bit; and a block within [`MAX_DENSE_ROWS`] singular whatever its numbers (more
/// rows than velocity components, a small rigid grid) takes the sparse minimum norm here,
/// the eigendecomposition there (which reports the rank and condition `lagrange solve`
/// shows): the same minimum-norm λ to rounding (the regularised factor: but for the
/// regularisation's share in the redundant rows' split), [`Diagnostic::RedundantSparse`]
/// instead of [`Diagnostic::Redundant`]. A third, only when asked for
/// ([`SolveCache::set_velocity_space`]): a correction's step on a body-space block is the
/// velocity change alone, the same step to rounding, no λ.
#[derive(Clone, Debug, Default)]
pub struct SolveCache {
    entry: Option<Factored>,
    path: SolvePath,
    /// Buffers of the reused solve: −b̃, μ and the band solve's.
    rhs: Vec<f64>,
    mu: Vec<f64>,
    work: BandWork,
    sparse_work: SparseWork,
    regularised_work: RegularisedWork,
    body_work: BodySpaceWork,
    /// The factor of rows that form a chain in their order (`numeric::chain`), tried first.
    chain: super::chain::Chain,
    /// The kept chain factor the last solve went through, when it went through one
    /// ([`SolveCache::made`]).
    made: Option<FactorId>,
    /// A step (`Answer::Step`) on a body-space block is the velocity change alone
    /// ([`SolveCache::set_velocity_space`]).
    velocity_space: bool,
    /// The rows' targets of that velocity change (`velocity_target`), and the last one, Δu
    /// per slot (the next one's warm start).
    target: Vec<f64>,
    velocity: Vec<[f64; 3]>,
}

/// The mark of one factor a [`SolveCache`] made (of rows that form a chain, `numeric::chain`):
/// a solve through the cache hands it out ([`SolveCache::made`]) when its rows were served
/// by the kept chain factor, and a later solve of rows whose J is still bit for bit those
/// rows' may pass it back, so that the factor's J is not compared with theirs again (the
/// masses and settings still are). The cache marks every factor it begins anew, so a mark
/// whose factor has since been replaced (another J, another pattern, a failed solve) no
/// longer matches and the solve compares J as it would without one. The caller's word is
/// only that J did not change since the solve that handed the mark out: rows evaluated
/// again (even at the same state) do not keep a mark. A mark is of one cache. (Not zero,
/// so that an `Option` of one is a word: the run loop passes them at every step.)
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FactorId(pub(crate) std::num::NonZeroU64);

/// How a solve's rows compare with a cached entry's ([`Factored::compare_taking`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Likeness {
    /// J and the masses bit for bit: the factor serves.
    Same,
    /// The same slots in the same order, other numbers: refactored in place.
    SamePattern,
    /// Another pattern or other settings: a new entry.
    Different,
}

/// One cached factorisation and the inputs it was made from.
#[derive(Clone, Debug)]
struct Factored {
    rank_tolerance: u64,
    method: Method,
    /// 1/m per slot, as bits.
    inverse_mass: Vec<u64>,
    /// Every row's J, concatenated (slot, bits of each component), and each row's length.
    jacobian: Vec<(usize, [u64; 3])>,
    lengths: Vec<usize>,
    scaled: Scaled,
    /// 0..k: every row takes part.
    index: Vec<usize>,
    factor: Factor,
    /// The body-space factor was kept for a J it was not made from ([`SolvePath::Stale`]).
    stale: bool,
    /// Buffers of a body-space refactorisation: the rows' weights and parts' ranges.
    spare: (Vec<f64>, Vec<std::ops::Range<usize>>),
}

/// A cached factor of Ã.
#[derive(Clone, Debug)]
enum Factor {
    /// The band Cholesky, with Ã's terms and the place in the band each is added to.
    Band {
        factor: BandFactor,
        terms: Vec<Term>,
        targets: Vec<usize>,
    },
    /// The sparse Cholesky (its order, supernodes and pattern of L analysed once), with
    /// Ã's terms and the place in its matrix each is added to.
    Sparse {
        factor: SparseFactor,
        terms: Vec<Term>,
        targets: Vec<usize>,
    },
    Dense(DenseFactor),
    /// A singular block past [`MAX_DENSE_ROWS`], or within it when singular whatever its
    /// numbers: the factor of Ã + ε W² its minimum norm iterates with
    /// ([`sparse_minimum_norm`]), with Ã's terms (in the order of its entries and their
    /// places).
    Singular {
        regularised: Regularised,
        terms: Vec<Term>,
    },
    /// A block singular whatever its numbers whose rows hold every component they move:
    /// the factor of the Gram matrix of its velocity components (`numeric::gram`), tried
    /// before [`Factor::Singular`].
    BodySpace {
        body: Box<BodySpace>,
    },
}

impl Factored {
    fn settings_match(&self, rows: &Rows, settings: &Settings) -> bool {
        self.rank_tolerance == settings.rank_tolerance.to_bits()
            && self.method == settings.method
            && self.lengths.len() == rows.rows.len()
            && self.inverse_mass.len() == rows.inverse_mass.len()
            && self.lengths.iter().zip(&rows.rows).all(|(n, row)| *n == row.jacobian.len())
    }

    /// Whether `rows` are near enough the entry's J for its kept body-space factor, scaling
    /// and G to precondition their velocity change (`velocity_near`): the same settings and
    /// slots, the same slots without mass and the same zero components (so the same columns
    /// of G, all still moved), and every component within [`STALE_CHANGE`] of its row's
    /// norm of the kept one (so J keeps G's full column rank). One walk, nothing stored.
    fn near(&self, rows: &Rows, settings: &Settings) -> bool {
        if !self.near_slots(rows, settings) {
            return false;
        }
        let mut kept = self.jacobian.iter();
        rows.rows.iter().zip(&self.scaled.norm).all(|(row, norm)| {
            row.jacobian.iter().fold(true, |near, part| near & part_near(STALE_CHANGE * norm, part, kept.next()))
        })
    }

    /// [`near`](Factored::near)'s test of everything but J's numbers: the same settings and
    /// slots per row, the same slots without mass.
    fn near_slots(&self, rows: &Rows, settings: &Settings) -> bool {
        let massless = |w: f64| w == 0.0;
        let same = |(b, w): (&u64, &f64)| massless(f64::from_bits(*b)) == massless(*w);
        self.settings_match(rows, settings) && self.inverse_mass.iter().zip(&rows.inverse_mass).all(same)
    }

    /// How `rows` compare with the rows the entry was made from, in one walk along J (a run
    /// changes J at every step, and this runs at every solve): [`Likeness::Same`] bit for
    /// bit, [`Likeness::SamePattern`] when they act on the same slots in the same order,
    /// else [`Likeness::Different`]. From the first number that differs on, the walk stores
    /// the rows' bits as the entry's (the masses' too): on `SamePattern` the entry then holds
    /// the rows' J and masses, as [`refactor`](Factored::refactor) needs, and on
    /// `Different` (or a refactorisation that fails) the entry is made anew anyway.
    fn compare_taking(&mut self, rows: &Rows, settings: &Settings) -> Likeness {
        if !self.settings_match(rows, settings) {
            return Likeness::Different;
        }
        let mut same = true;
        for (mine, w) in self.inverse_mass.iter_mut().zip(&rows.inverse_mass) {
            let bits = w.to_bits();
            if *mine != bits {
                *mine = bits;
                same = false;
            }
        }
        // Row by row over plain slices (each row's length already equal, `settings_match`).
        let mut kept = self.jacobian.as_mut_slice();
        for row in &rows.rows {
            let Some((mine, rest)) = kept.split_at_mut_checked(row.jacobian.len()) else {
                return Likeness::Different;
            };
            kept = rest;
            for ((s, a), (t, b)) in mine.iter_mut().zip(&row.jacobian) {
                if s != t {
                    return Likeness::Different;
                }
                let bits = b.map(f64::to_bits);
                if *a != bits {
                    *a = bits;
                    same = false;
                }
            }
        }
        match (kept.is_empty(), same) {
            (false, _) => Likeness::Different,
            (true, true) => Likeness::Same,
            (true, false) => Likeness::SamePattern,
        }
    }

    /// Scales, assembles and factors `rows` (of [`Likeness::SamePattern`], their bits already
    /// taken by [`compare_taking`](Factored::compare_taking))
    /// in place: the numbers of a fresh factorisation, from the kept terms. False when the
    /// rows are no longer a case the cache serves (the entry is then spent).
    fn refactor(&mut self, rows: &Rows, settings: &Settings) -> bool {
        self.stale = false;
        if matches!(self.factor, Factor::Dense(_)) {
            return false;
        }
        // `solve_cached_into` served the rows (every velocity and force finite, no
        // inequality), and every row of the entry is usable.
        if !self.scaled.rescale_in_place(rows) {
            return false;
        }
        // Ã term by term in `assemble`'s order: the same sums as `plan`'s.
        match &mut self.factor {
            Factor::Band { factor, terms, targets } => {
                let data = factor.a.data_mut();
                data.fill(0.0);
                for (t, &at) in terms.iter().zip(targets.iter()) {
                    data[at] += term_value(&self.scaled, &rows.inverse_mass, t);
                }
                factor.a.cholesky_into(settings.rank_tolerance, &mut factor.factor).is_ok()
            }
            Factor::Sparse { factor, terms, targets } => {
                let values = factor.values_mut();
                values.fill(0.0);
                for (t, &at) in terms.iter().zip(targets.iter()) {
                    values[at] += term_value(&self.scaled, &rows.inverse_mass, t);
                }
                factor.factor(settings.rank_tolerance)
            }
            Factor::Dense(_) => false,
            Factor::BodySpace { body } => {
                // As `Factor::Singular`: singular whatever the numbers (the same components
                // moved, `Gram::same_columns`, by the same rows: still more rows than
                // components), G's pattern the same, else the plan is made again.
                if !matches!(settings.method, Method::Auto | Method::Sparse) {
                    return false;
                }
                // In the entry's own buffers: a grid's weights and ranges are large enough that
                // allocating them at every substep pays for fresh pages.
                let (weight, ranges) = &mut self.spare;
                weight.clear();
                weight.extend(self.index.iter().map(|&k| self.scaled.unscale(k, 1.0)));
                ranges.clear();
                ranges.extend(self.index.iter().map(|&k| self.scaled.range(k)));
                let (weight, ranges) = (&*weight, &*ranges);
                let gram = body.gram_mut();
                if !(gram.same_columns(self.scaled.parts(), ranges, &rows.inverse_mass)
                    && gram.fill(self.scaled.parts(), &rows.inverse_mass, weight, WEIGHT_RANGE))
                {
                    return false;
                }
                // G barely moved (a grid at rest, J changing in its last bits): the kept
                // factor serves as the iteration's preconditioner (`solve_cached_into`
                // factors after all if it does not reach rounding).
                self.stale = body.change() <= STALE_CHANGE;
                self.stale || body.refactor(settings.rank_tolerance, NULL_SHARE)
            }
            Factor::Singular { regularised, terms } => {
                // `plan`'s way to the regularised factor without a factorisation that fails:
                // singular whatever the numbers, past the dense decomposition. Otherwise
                // (singular by the numbers alone) the plan is made again.
                let n = self.index.len();
                if !matches!(settings.method, Method::Auto | Method::Sparse)
                    || n <= columns(&self.scaled, &rows.inverse_mass, &self.index)
                {
                    return false;
                }
                for (entry, t) in regularised.a.iter_mut().zip(terms.iter()) {
                    entry.2 = term_value(&self.scaled, &rows.inverse_mass, t);
                }
                let weight: Vec<f64> = self.index.iter().map(|&k| self.scaled.unscale(k, 1.0)).collect();
                regularised.refactor(&weight)
            }
        }
    }

    /// A new entry for `rows`, or `None` when they are not a case the cache serves.
    fn new(rows: &Rows, settings: &Settings) -> Option<Factored> {
        let (mut diagnostics, mut status) = (Vec::new(), Status::Solved);
        let scaled = Scaled::new(rows, &mut diagnostics, &mut status);
        // No diagnostic: every row is usable, so every row takes part.
        if !diagnostics.is_empty() {
            return None;
        }
        let index: Vec<usize> = (0..rows.rows.len()).collect();
        let block = assemble(&scaled, &rows.inverse_mass, &index);
        let sparse_method = matches!(settings.method, Method::Auto | Method::Sparse);
        // A singular block's factor: the body-space one where it serves (as
        // `sparse_minimum_norm` tries it first), the regularised one otherwise.
        let singular = |analysed: Option<SparsePlan>| -> Option<Factor> {
            if let Some(body) = body_space(&block, settings) {
                return Some(Factor::BodySpace { body: Box::new(body) });
            }
            Some(Factor::Singular {
                regularised: Regularised::new(&block, analysed)?,
                terms: terms(&scaled, rows.inverse_mass.len(), &index),
            })
        };
        let planned = if singular_past_dense(&block, settings) { None } else { Some(plan(&block, settings)) };
        let factor = match planned {
            None => singular(None)?,
            Some(planned) => match planned {
                // Singular whatever its numbers within the dense bound (a small rigid grid): the
                // run takes the regularised sparse factor too, where the general solve takes the
                // eigendecomposition (for its rank and condition): the same minimum-norm λ to
                // the regularisation's 1e-8 in the redundant rows' split, the same impulses to
                // rounding, at a sparse factor's cost instead of n³ per solve.
                Plan::Singular(_) | Plan::Band(None) | Plan::Sparse(None) | Plan::Dense
                    if block.n <= MAX_DENSE_ROWS && sparse_method && structurally_singular(&block) =>
                {
                    let analysed = match planned {
                        Plan::Singular(analysed) => Some(analysed),
                        _ => None,
                    };
                    singular(analysed)?
                }
                Plan::Band(Some(factor)) => {
                    let terms = terms(&scaled, rows.inverse_mass.len(), &index);
                    let targets = terms
                        .iter()
                        .map(|t| {
                            let (i, j) = (factor.position[t.hi], factor.position[t.lo]);
                            factor.a.index(i.max(j), i.min(j))
                        })
                        .collect();
                    Factor::Band { factor, terms, targets }
                }
                Plan::Sparse(Some(SparsePlan { factor, targets })) => {
                    // `targets` follow `block.a`, which is `terms` in order.
                    Factor::Sparse { factor, terms: terms(&scaled, rows.inverse_mass.len(), &index), targets }
                }
                Plan::Dense if block.n <= MAX_DENSE_ROWS => Factor::Dense(DenseFactor::new(&block, settings)?),
                // Singular past the dense decomposition: `equality`'s regularised factor.
                Plan::Singular(analysed) if block.n > MAX_DENSE_ROWS => singular(Some(analysed))?,
                Plan::Band(None) | Plan::Sparse(None) if block.n > MAX_DENSE_ROWS => singular(None)?,
                _ => return None,
            },
        };
        Some(Factored {
            rank_tolerance: settings.rank_tolerance.to_bits(),
            method: settings.method,
            inverse_mass: rows.inverse_mass.iter().map(|w| w.to_bits()).collect(),
            jacobian: rows.rows.iter().flat_map(|row| &row.jacobian).map(|(s, j)| (*s, j.map(f64::to_bits))).collect(),
            lengths: rows.rows.iter().map(|row| row.jacobian.len()).collect(),
            scaled,
            index,
            factor,
            stale: false,
            spare: (Vec::new(), Vec::new()),
        })
    }
}

/// Which factorisation a [`SolveCache`] keeps (the plan [`Method::Auto`] made for the
/// block's pattern), for tests of the choice and for profiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Factorisation {
    Band,
    Sparse,
    Dense,
    /// The sparse factor of the regularised Ã of a singular block past [`MAX_DENSE_ROWS`],
    /// or within it when singular whatever its numbers (its minimum norm by iterated solves).
    RegularisedSparse,
    /// The sparse factor of the Gram matrix of the velocity components of a block singular
    /// whatever its numbers whose rows hold every component (`numeric::gram`).
    BodySpace,
}

impl SolveCache {
    /// Whether a correction's step ([`solve_cached_step_into`], `Dynamics::correct_step`) on
    /// a block the body-space factor serves (`numeric::gram`) takes the velocity change
    /// alone, x = H⁻¹ Gᵀ c (one substitution an application), instead of the minimum-norm
    /// λ's M⁻¹Jᵀλ (two): the same velocity change to rounding, not bit for bit, and no λ.
    /// Off by default (every solve the general solve's numbers, as the type says); the
    /// exact velocity step turns it on for its run.
    pub fn set_velocity_space(&mut self, on: bool) {
        self.velocity_space = on;
    }

    /// The way the last solve went.
    pub fn last_path(&self) -> SolvePath {
        self.path
    }

    /// The mark of the kept chain factor the last solve went through ([`FactorId`]); `None`
    /// when it went another way or the factor was not kept.
    pub fn made(&self) -> Option<FactorId> {
        self.made
    }

    /// The factorisation kept, `None` when none is (nothing solved, or the last solve was
    /// not a case the cache serves).
    pub fn factorisation(&self) -> Option<Factorisation> {
        if self.chain.is_kept() {
            return Some(Factorisation::Band);
        }
        self.entry.as_ref().map(|c| match c.factor {
            Factor::Band { .. } => Factorisation::Band,
            Factor::Sparse { .. } => Factorisation::Sparse,
            Factor::Dense(_) => Factorisation::Dense,
            Factor::Singular { .. } => Factorisation::RegularisedSparse,
            Factor::BodySpace { .. } => Factorisation::BodySpace,
        })
    }
}

/// [`solve_holding`], reusing `cache`'s factorisation when J and the masses are those it
/// was made from (see [`SolveCache`]); the answer is the same either way.
pub fn solve_cached(rows: &Rows, settings: &Settings, held: &[bool], cache: &mut SolveCache) -> Solution {
    let mut out = Solution::default();
    solve_cached_into(rows, settings, held, cache, &mut out);
    out
}

/// [`solve_cached`] into `out`, reusing its buffers: a run's solves allocate nothing once
/// warm.
pub fn solve_cached_into(rows: &Rows, settings: &Settings, held: &[bool], cache: &mut SolveCache, out: &mut Solution) {
    cached_into(rows, settings, held, cache, out, Answer::Solution, None);
}

/// [`solve_cached_into`]'s step alone, as a correction reads it (SHAKE's iterations, the
/// projections, the velocity step: forces zeroed, c the target): `out.acceleration` holds
/// M⁻¹(F + Jᵀλ); λ, the active set and the contact states are left empty where the path
/// does not make them (the chain's, and the velocity change of
/// [`SolveCache::set_velocity_space`], which leaves the constraint forces empty too).
pub fn solve_cached_step_into(rows: &Rows, settings: &Settings, cache: &mut SolveCache, out: &mut Solution) {
    cached_into(rows, settings, &[], cache, out, Answer::Step, None);
}

/// What a solve through the cache writes into its [`Solution`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Answer {
    /// All of it: λ, the active set, the forces, the accelerations, the diagnostics, the
    /// status and the contact states.
    Solution,
    /// A correction's step (SHAKE's iterations, the velocity projection: forces zeroed, c
    /// the target), read from the accelerations alone: the chain path (`numeric::chain`)
    /// writes only the forces and the accelerations — the same numbers — leaving λ, the
    /// active set and the contact states empty and no diagnostic; a body-space block with
    /// [`SolveCache::set_velocity_space`] on writes the accelerations alone (the velocity
    /// change, to rounding, [`BodySpace::velocity_change`]), the status and no diagnostic;
    /// every other path writes the whole solution.
    Step,
}

/// [`solve_cached_into`]'s body, the chain path writing what `answer` asks: `known`, the
/// mark of the factor a solve of rows with this J went through ([`FactorId`]), spares the
/// chain's comparison of J while that factor is the one kept. The run's solves
/// (`Dynamics::solve_known`, `Dynamics::correct_step`).
pub(crate) fn cached_into(
    rows: &Rows,
    settings: &Settings,
    held: &[bool],
    cache: &mut SolveCache,
    out: &mut Solution,
    answer: Answer,
    known: Option<FactorId>,
) {
    cache.made = None;
    if !super::chain::servable(rows) {
        cache.path = SolvePath::General;
        solve_holding_into(rows, settings, held, out);
        return;
    }
    // A chain in its order: the tridiagonal in place (`numeric::chain`), the same numbers.
    if let Some(path) = cache.chain.solve_into(rows, settings, out, answer, known) {
        cache.path = path;
        cache.made = cache.chain.made();
        return;
    }
    if answer == Answer::Step && cache.velocity_space && velocity_near(rows, settings, cache, out) {
        return;
    }
    let likeness = cache.entry.as_mut().map_or(Likeness::Different, |c| c.compare_taking(rows, settings));
    if likeness == Likeness::Same {
        cache.path = SolvePath::Reused;
    } else {
        let refactored = match &mut cache.entry {
            Some(c) if likeness == Likeness::SamePattern => c.refactor(rows, settings),
            _ => false,
        };
        if !refactored {
            cache.entry = Factored::new(rows, settings);
        }
        let stale = cache.entry.as_ref().is_some_and(|c| c.stale);
        cache.path = if stale { SolvePath::Stale } else { SolvePath::Factored };
    }
    let Some(c) = &mut cache.entry else {
        cache.path = SolvePath::General;
        solve_holding_into(rows, settings, held, out);
        return;
    };
    let (mut diagnostics, mut status) = (std::mem::take(&mut out.diagnostics), Status::Solved);
    diagnostics.clear();
    cache.mu.clear();
    if !c.index.is_empty() {
        // Every row takes part (`index` is 0..k): b̃ row by row along the scaled parts.
        negated_right_hand_side(rows, &c.scaled, &mut cache.rhs);
        match &mut c.factor {
            Factor::Band { factor, .. } => factor.solve_into(&cache.rhs, &mut cache.work, &mut cache.mu),
            Factor::Sparse { factor, .. } => factor.solve_into(&cache.rhs, &mut cache.sparse_work, &mut cache.mu),
            Factor::Dense(factor) => cache.mu.extend(factor.solve(&cache.rhs)),
            Factor::BodySpace { body } => {
                let velocity = answer == Answer::Step && cache.velocity_space;
                let (rhs, work, mu, bounds) = (&cache.rhs, &mut cache.body_work, &mut cache.mu, body_bounds(settings));
                let (scaled, target, du) = (&c.scaled, &mut cache.target, &mut cache.velocity);
                let size = if velocity { velocity_target(rows, scaled, target) } else { 0.0 };
                let target = &*target;
                // A stale factor starts from the last answer (a grid at rest: at its answer);
                // a fresh minimum norm from 0, as the general solve.
                let done = with_body_space(body, &mut c.stale, &mut cache.path, settings, |body, warm| {
                    if velocity {
                        let residual =
                            |du: &[[f64; 3]], r: &mut Vec<f64>| velocity_residual(rows, scaled, target, du, r);
                        body.velocity_change(size, None, residual, &rows.inverse_mass, &bounds, work, du)
                    } else {
                        body.minimum_norm(rhs, &bounds, work, mu, warm)
                    }
                });
                let Some(done) = done.filter(|done| done.consistent) else {
                    // The factor failed (the entry is spent), or rows that contradict each
                    // other here: the general solve says so.
                    if done.is_none() {
                        cache.entry = None;
                    }
                    cache.path = SolvePath::General;
                    solve_holding_into(rows, settings, held, out);
                    return;
                };
                status = status.max(Status::MinimumNorm);
                if velocity {
                    // The buffer handed back (the step has no diagnostic).
                    out.diagnostics = diagnostics;
                    velocity_step_into(rows, &cache.velocity, status, out);
                    return;
                }
                diagnostics.push(body_diagnostic(body, &c.index, done.solves));
            }
            Factor::Singular { regularised, .. } => {
                match regularised.minimum_norm(&cache.rhs, settings, &mut cache.regularised_work, &mut cache.mu) {
                    Some(solves) => {
                        diagnostics.push(regularised.diagnostic(&c.index, solves));
                        status = status.max(Status::MinimumNorm);
                    }
                    None => {
                        // Rows that contradict each other here: the general solve says so.
                        cache.path = SolvePath::General;
                        solve_holding_into(rows, settings, held, out);
                        return;
                    }
                }
            }
        }
        finite_in_place(&mut cache.mu, &c.index, &mut diagnostics, &mut status);
    }
    finish_into(rows, &c.scaled, &c.index, &cache.mu, diagnostics, status, out);
    out.contacts.clear();
    out.contacts.resize(rows.rows.len(), None);
}

/// Runs `solve` (the kept body-space factor's iteration; its flag: whether a minimum norm
/// may start from the last answer) and, when the factor was stale (kept for another J,
/// `stale`) and the answer did not reach rounding, refactors and runs it again as a fresh
/// factor solves, the path then [`SolvePath::Factored`]; `None` when that factorisation
/// fails.
fn with_body_space(
    body: &mut BodySpace,
    stale: &mut bool,
    path: &mut SolvePath,
    settings: &Settings,
    mut solve: impl FnMut(&mut BodySpace, bool) -> Iterated,
) -> Option<Iterated> {
    let done = solve(body, *stale);
    if !*stale || (done.converged && done.consistent) {
        return Some(done);
    }
    // The kept factor is too far from this J: factored now.
    *stale = false;
    *path = SolvePath::Factored;
    body.refactor(settings.rank_tolerance, NULL_SHARE).then(|| solve(body, false))
}

/// A step of the body-space velocity change `du` into `out`: the accelerations Fᵢ wᵢ + Δuᵢ,
/// no diagnostic, `status`, everything else empty.
fn velocity_step_into(rows: &Rows, du: &[[f64; 3]], status: Status, out: &mut Solution) {
    out.lambda.clear();
    out.active.clear();
    out.contacts.clear();
    out.constraint_force.clear();
    out.diagnostics.clear();
    out.acceleration.clear();
    out.acceleration.extend(
        rows.force
            .iter()
            .zip(&rows.inverse_mass)
            .zip(du)
            .map(|((f, w), d)| [f[0] * w + d[0], f[1] * w + d[1], f[2] * w + d[2]]),
    );
    out.status = status;
}

/// The targets of a velocity change, tₖ = −(Jₖ·F w + cₖ) (J Δu = t is J̃ Δu = −b̃ unscaled),
/// into `target`; returns max |tₖ| in the scaled rows (`scaled`'s, the minimum norm's max
/// |rhs|).
/// Its callers' rows have a finite J (scaled, or near the kept entry's, `Factored::near`)
/// and finite forces (`chain::servable`). Without a force on any slot (a correction's rows)
/// and with finite masses each Jₖ·F w is ±0, which leaves a c that is not 0 as it is, so
/// the products are taken only where c is 0 (for the sign of that zero): the same targets.
fn velocity_target(rows: &Rows, scaled: &Scaled, target: &mut Vec<f64>) -> f64 {
    target.clear();
    let unforced = rows.force.as_flattened().iter().fold(true, |zero, f| zero & (*f == 0.0))
        && rows.inverse_mass.iter().fold(true, |finite, w| finite & w.is_finite());
    let mut size = 0.0f64;
    for (k, row) in rows.rows.iter().enumerate() {
        let t = if unforced && row.bias != 0.0 { -row.bias } else { -(external(rows, &row.jacobian) + row.bias) };
        size = size.max(scaled.scale(k, t).abs());
        target.push(t);
    }
    size
}

/// Σᵢ Jᵢ·Fᵢ wᵢ over a row's parts (slot, Jᵢ), summed from −0 (as `Iterator::sum` of f64
/// does): a row's part of the right-hand side from the external forces.
#[inline(always)]
fn external(rows: &Rows, parts: &[(usize, [f64; 3])]) -> f64 {
    let mut ext = -0.0;
    for (body, j) in parts {
        ext += dot(j, &rows.force[*body]) * rows.inverse_mass[*body];
    }
    ext
}

/// The residual of a velocity change `du` of `rows` in the scaled rows, rₖ = (tₖ − Jₖ Δu)
/// scaled by `scaled` (the kept entry's: a nearby J's, within rounding of these rows'), into
/// `r`, with max |rₖ| (a NaN counting as infinite) and the rounding scale of the products,
/// max Σ |Jₖᵢ Δuᵢ| scaled ([`BodySpace::velocity_change`]). From the rows' own J: the limit
/// of the iteration is their Δu whatever the kept factor.
fn velocity_residual(rows: &Rows, scaled: &Scaled, target: &[f64], du: &[[f64; 3]], r: &mut Vec<f64>) -> (f64, f64) {
    let (left, scale, _) = residual_walk(rows, scaled, target, du, r, |_, _| true);
    (left, scale)
}

/// [`velocity_residual`] with each part (slot, Jᵢ) of row k also passed to `near(‖Jₖ‖, part)`
/// in the same walk along J (a test of the part against a kept J, [`part_near`]): the walk
/// stops at the first row with a part not near, and the third number says whether every
/// part was (the residual is complete only then).
#[inline(always)]
fn residual_walk(
    rows: &Rows,
    scaled: &Scaled,
    target: &[f64],
    du: &[[f64; 3]],
    r: &mut Vec<f64>,
    mut near: impl FnMut(f64, &(usize, [f64; 3])) -> bool,
) -> (f64, f64, bool) {
    let (mut left, mut scale) = (0.0f64, 0.0f64);
    r.clear();
    // A plain loop over the rows beside their scales: the sums stay in registers.
    let scales = scaled.norm.iter().zip(&scaled.jacobi);
    for ((row, t), (&norm, &jacobi)) in rows.rows.iter().zip(target).zip(scales) {
        let (mut sum, mut size, mut all_near) = (0.0, 0.0, true);
        for part in &row.jacobian {
            all_near &= near(norm, part);
            let (j, d) = (&part.1, &du[part.0]);
            let terms = [j[0] * d[0], j[1] * d[1], j[2] * d[2]];
            for term in terms {
                sum += term;
                size += term.abs();
            }
        }
        if !all_near {
            return (left, scale, false);
        }
        let rk = scale_by(t - sum, norm, jacobi);
        left = if rk.is_nan() { f64::INFINITY } else { left.max(rk.abs()) };
        scale = scale.max(scale_by(size, norm, jacobi).abs());
        r.push(rk);
    }
    (left, scale, true)
}

/// Whether a part (slot, Jᵢ) of a row whose kept ‖J‖ is `norm` is near its `kept` one
/// (slot, bits of Jᵢ) for [`Factored::near`]: the same slot, the same zero components and
/// each component within [`STALE_CHANGE`] ‖J‖; false without a kept one. Without a branch
/// per component (`&`, not `&&`: a test and a branch each cost several times the
/// instructions; every part is near at rest).
#[inline(always)]
fn part_near(norm: f64, (s, j): &(usize, [f64; 3]), kept: Option<&(usize, [u64; 3])>) -> bool {
    let Some((t, bits)) = kept else { return false };
    let bound = STALE_CHANGE * norm;
    j.iter().zip(bits).fold(s == t, |near, (x, b)| {
        let y = f64::from_bits(*b);
        near & ((*x == 0.0) == (y == 0.0)) & ((x - y).abs() <= bound)
    })
}

/// A step of the velocity change ([`SolveCache::set_velocity_space`]) with the kept
/// body-space factor, scaling and G as they are, without comparing, rescaling or refilling
/// anything ([`SolvePath::Stale`]): where the entry is stale already (a grid at rest, J
/// moving in its last bits) and `rows` are near its J ([`Factored::near`]); the residual is
/// the rows' own, so the answer is theirs. True when it answered into `out` (converged at
/// rounding and consistent); false leaves the solve to the usual path, which compares,
/// refills and refactors as needed and finds contradicting rows.
fn velocity_near(rows: &Rows, settings: &Settings, cache: &mut SolveCache, out: &mut Solution) -> bool {
    let SolveCache { entry: Some(c), target, velocity, body_work, .. } = cache else {
        return false;
    };
    let Factor::BodySpace { body } = &c.factor else {
        return false;
    };
    if !c.stale {
        return false;
    }
    let scaled = &c.scaled;
    let size = velocity_target(rows, scaled, target);
    // With a last Δu to start from (`BodySpace::velocity_change`'s warm start), J is tested
    // in the walk that takes that start's residual: each row's J read once, not twice.
    let warm = velocity.len() == rows.inverse_mass.len();
    let start = if warm && c.near_slots(rows, settings) {
        let mut kept = c.jacobian.iter();
        let near = |norm, part: &_| part_near(norm, part, kept.next());
        let (left, scale, near) = residual_walk(rows, scaled, target, velocity, body_work.residual_mut(), near);
        near.then_some((left, scale))
    } else {
        None
    };
    if start.is_none() && (warm || !c.near(rows, settings)) {
        return false;
    }
    let residual = |du: &[[f64; 3]], r: &mut Vec<f64>| velocity_residual(rows, scaled, target, du, r);
    let bounds = body_bounds(settings);
    let done = body.velocity_change(size, start, residual, &rows.inverse_mass, &bounds, body_work, velocity);
    if !(done.converged && done.consistent) {
        return false;
    }
    velocity_step_into(rows, velocity, Status::MinimumNorm, out);
    cache.path = SolvePath::Stale;
    true
}

/// b̃ₚ = Σᵢ J̃ₚᵢ·Fᵢ wᵢ + c̃ₚ for the rows `index`.
fn right_hand_side(rows: &Rows, scaled: &Scaled, index: &[usize]) -> Vec<f64> {
    index.iter().map(|&q| b_entry(rows, scaled, q)).collect()
}

/// b̃ of row `q`.
fn b_entry(rows: &Rows, scaled: &Scaled, q: usize) -> f64 {
    b_of(rows, scaled.jacobian(q), rows.rows[q].bias, scaled.norm[q], scaled.jacobi[q])
}

/// b̃ of a row from its scaled parts, its c term, ‖J‖ and 1/√Â: Σᵢ J̃ᵢ·Fᵢ wᵢ summed from −0
/// (as `Iterator::sum` of f64 does), plus c̃ ([`Scaled::scale`]).
pub(super) fn b_of(rows: &Rows, parts: &[(usize, [f64; 3])], bias: f64, norm: f64, jacobi: f64) -> f64 {
    external(rows, parts) + (bias / norm) * jacobi
}

/// −b̃ of every row into `rhs` (the cached solve, where every row takes part): the numbers
/// of [`b_entry`], walking the scaled parts in order.
fn negated_right_hand_side(rows: &Rows, scaled: &Scaled, rhs: &mut Vec<f64>) {
    rhs.clear();
    let mut from = 0;
    for (q, (row, to)) in rows.rows.iter().zip(&scaled.start[1..]).enumerate() {
        let parts = &scaled.parts[from..*to];
        from = *to;
        rhs.push(-b_of(rows, parts, row.bias, scaled.norm[q], scaled.jacobi[q]));
    }
}

/// The diagnostic of row `q` whose λ = λ̃/(‖J‖√Â) left the normal f64 range while its μ
/// did not: λ can leave it when ‖J‖ does (|r| ≈ 1e155 gives λ ≈ 1e-310) although the force
/// λ̃ J̃ is exact, so say so rather than print a wrong 0 or ∞.
pub(super) fn out_of_range(q: usize, m: f64, l: f64, diagnostics: &mut Vec<Diagnostic>) {
    if m != 0.0 && !l.is_normal() {
        diagnostics.push(Diagnostic::LambdaOutOfRange { constraint: q, lambda: l });
    }
}

/// Adds one row's force μ J̃ᵢ to each of its bodies: Σₖ λₖ Jₖᵢ = Σₖ λ̃ₖ J̃ₖᵢ, no raw J, no
/// overflow; called row by row, each row's parts in order.
pub(super) fn add_row_force(constraint_force: &mut [[f64; 3]], m: f64, parts: &[(usize, [f64; 3])]) {
    for (body, j) in parts {
        let f = &mut constraint_force[*body];
        f[0] += m * j[0];
        f[1] += m * j[1];
        f[2] += m * j[2];
    }
}

/// `vectors` as `n` zero vectors: in place when it holds `n` already (a run's answers keep
/// their bodies' count, and a `clear` and `resize` was a call per solve).
pub(super) fn zero_vectors(vectors: &mut Vec<[f64; 3]>, n: usize) {
    if vectors.len() == n {
        vectors.fill([0.0; 3]);
    } else {
        vectors.clear();
        vectors.resize(n, [0.0; 3]);
    }
}

/// Each body's acceleration (Fᵢ + fᵢ) wᵢ from the applied and the constraint forces, written
/// in place when `acceleration` has the bodies' count already (no `clear` and out-of-line
/// `extend` per solve).
pub(super) fn accelerations_into(rows: &Rows, constraint_force: &[[f64; 3]], acceleration: &mut Vec<[f64; 3]>) {
    let n = rows.force.len().min(constraint_force.len()).min(rows.inverse_mass.len());
    if acceleration.len() != n {
        acceleration.resize(n, [0.0; 3]);
    }
    let sources = rows.force.iter().zip(constraint_force).zip(&rows.inverse_mass);
    for (a, ((f, fc), w)) in acceleration.iter_mut().zip(sources) {
        *a = [(f[0] + fc[0]) * w, (f[1] + fc[1]) * w, (f[2] + fc[2]) * w];
    }
}

/// λ, the active set, the forces, the accelerations, the diagnostics and the status of the
/// scaled multipliers `mu` of the rows `index`, into `out`'s buffers (its contacts are left
/// to the caller).
fn finish_into(
    rows: &Rows,
    scaled: &Scaled,
    index: &[usize],
    mu: &[f64],
    mut diagnostics: Vec<Diagnostic>,
    status: Status,
    out: &mut Solution,
) {
    let n_bodies = rows.inverse_mass.len();
    let k = rows.rows.len();
    let lambda = &mut out.lambda;
    lambda.clear();
    lambda.resize(k, 0.0);
    let constraint_force = &mut out.constraint_force;
    zero_vectors(constraint_force, n_bodies);
    debug_assert_eq!(index.len(), mu.len());
    if index.len() == k {
        // Every row takes part (`index` is 0..k, as in every cached solve): one pass along
        // the scaled parts, the same numbers in the same order as the loop below.
        let mut from = 0;
        for (q, ((l, &m), to)) in lambda.iter_mut().zip(mu).zip(&scaled.start[1..]).enumerate() {
            *l = scaled.unscale(q, m);
            out_of_range(q, m, *l, &mut diagnostics);
            add_row_force(constraint_force, m, &scaled.parts[from..*to]);
            from = *to;
        }
    } else {
        for (&q, &m) in index.iter().zip(mu) {
            lambda[q] = scaled.unscale(q, m);
            out_of_range(q, m, lambda[q], &mut diagnostics);
            add_row_force(constraint_force, m, scaled.jacobian(q));
        }
    }
    accelerations_into(rows, constraint_force, &mut out.acceleration);
    out.active.clear();
    out.active.extend(
        scaled
            .usable
            .iter()
            .zip(&rows.rows)
            .zip(lambda.iter())
            .map(|((u, row), l)| *u && (!row.inequality || *l > 0.0)),
    );
    out.diagnostics = diagnostics;
    out.status = status;
}

/// The scaled multipliers of a block: the equality solve when no row is `nonnegative`, else
/// the QP, polished. `index` maps block rows to constraint numbers for diagnostics.
pub(crate) fn multipliers(
    block: &Block,
    b: &[f64],
    nonnegative: &[bool],
    index: &[usize],
    settings: &Settings,
    diagnostics: &mut Vec<Diagnostic>,
    status: &mut Status,
) -> Vec<f64> {
    if !nonnegative.iter().any(|&x| x) {
        return equality(block, b, index, settings, diagnostics, status);
    }
    let tol = settings.contact_tolerance;
    // Every touching inequality as an equality first: if they all push, that is the answer.
    let (mut d0, mut s0) = (Vec::new(), Status::Solved);
    let x = equality(block, b, index, settings, &mut d0, &mut s0);
    let scale = x.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    if s0 == Status::Solved && x.iter().zip(nonnegative).all(|(v, &nn)| !nn || *v >= -tol * scale) {
        return x.into_iter().zip(nonnegative).map(|(v, &nn)| if nn { v.max(0.0) } else { v }).collect();
    }
    let qp = solve_qp(&block.a, b, nonnegative);
    let names = |rows: &[usize]| rows.iter().map(|&p| index[p]).collect::<Vec<_>>();
    let all = names(&(0..block.n).collect::<Vec<_>>());
    let clarabel_ok = matches!(qp.status, QpStatus::Solved | QpStatus::AlmostSolved);
    // Polish: the equality solve on the rows the QP keeps (free rows and λ > 0).
    let big = qp.lambda.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    // Interior-point λ of an inactive row decays towards tol·big, an active one stays O(big):
    // √tol·big lies between the two, so it separates them without knowing the answer.
    let keep: Vec<bool> = (0..block.n).map(|p| !nonnegative[p] || qp.lambda[p] > tol.sqrt() * big).collect();
    let (polished, d1, s1) = solve_subset(block, b, &keep, index, settings);
    let polished: Vec<f64> =
        polished.into_iter().zip(nonnegative).map(|(v, &nn)| if nn { v.max(0.0) } else { v }).collect();
    let r_polished = kkt(&block.a, b, nonnegative, &polished);
    if clarabel_ok && r_polished.worst() <= tol {
        diagnostics.extend(d1);
        *status = (*status).max(s1);
        return polished;
    }
    // Clarabel failed or its active set does not polish: principal pivoting from its guess.
    if let Some((x, d2, s2)) = pivoting(block, b, nonnegative, &keep, index, settings) {
        diagnostics.extend(d2);
        *status = (*status).max(s2);
        return x;
    }
    if !clarabel_ok {
        let worst = match qp.status {
            QpStatus::Infeasible | QpStatus::Unbounded => Status::Inconsistent,
            _ => Status::Failed,
        };
        diagnostics.push(Diagnostic::QpFailed { constraints: all, status: qp.status });
        *status = (*status).max(worst);
        return vec![0.0; block.n];
    }
    let (answer, residuals) = if r_polished.worst() <= qp.residuals.worst() {
        diagnostics.extend(d1);
        *status = (*status).max(s1);
        (polished, r_polished)
    } else {
        (qp.lambda.clone(), qp.residuals)
    };
    // KKT residuals beyond √tol mean λ is good to fewer than half the digits asked for.
    if qp.status == QpStatus::AlmostSolved || residuals.worst() > tol.sqrt() {
        diagnostics.push(Diagnostic::QpInaccurate {
            constraints: all,
            status: qp.status,
            iterations: qp.iterations,
            residuals,
        });
        *status = (*status).max(Status::Inaccurate);
    }
    answer
}

/// The equality solve on the rows of `block` marked in `keep`; the others get λ = 0.
fn solve_subset(
    block: &Block,
    b: &[f64],
    keep: &[bool],
    index: &[usize],
    settings: &Settings,
) -> (Vec<f64>, Vec<Diagnostic>, Status) {
    let rows: Vec<usize> = (0..block.n).filter(|&p| keep[p]).collect();
    let mut position = vec![usize::MAX; block.n];
    for (s, &p) in rows.iter().enumerate() {
        position[p] = s;
    }
    let sub = Block {
        n: rows.len(),
        bandwidth: block.bandwidth,
        a: block
            .a
            .iter()
            .filter(|(p, q, _)| position[*p] != usize::MAX && position[*q] != usize::MAX)
            .map(|&(p, q, v)| (position[p], position[q], v))
            .collect(),
        weight: rows.iter().map(|&p| block.weight[p]).collect(),
        // A subset of the rows moves a subset of the components: still a bound on the rank.
        columns: block.columns,
        // The regularised factor serves a subset (the polish of a QP's active set).
        gram: None,
    };
    let sub_b: Vec<f64> = rows.iter().map(|&p| b[p]).collect();
    let sub_index: Vec<usize> = rows.iter().map(|&p| index[p]).collect();
    let (mut d, mut s) = (Vec::new(), Status::Solved);
    let y = equality(&sub, &sub_b, &sub_index, settings, &mut d, &mut s);
    let mut x = vec![0.0; block.n];
    for (i, &p) in rows.iter().enumerate() {
        x[p] = y[i];
    }
    (x, d, s)
}

/// Murty's least-index principal pivoting (Murty 1974) for the contact LCP, from the set
/// `start`: solve the equalities on the set, then flip the first inequality row that is
/// infeasible (λ < 0 inside, C̈ < 0 outside). It terminates when Ã restricted to the
/// inequality rows' Schur complement is positive definite; otherwise it gives up (`None`)
/// after a bounded number of flips. Only used for small blocks, when Clarabel fails.
fn pivoting(
    block: &Block,
    b: &[f64],
    nonnegative: &[bool],
    start: &[bool],
    index: &[usize],
    settings: &Settings,
) -> Option<(Vec<f64>, Vec<Diagnostic>, Status)> {
    let n = block.n;
    if n > PIVOTING_MAX_ROWS {
        return None;
    }
    let tol = settings.contact_tolerance;
    let mut in_set: Vec<bool> = (0..n).map(|p| !nonnegative[p] || start[p]).collect();
    for _ in 0..(FLIPS_PER_ROW * n + FLIPS_BASE) {
        let (x, d, s) = solve_subset(block, b, &in_set, index, settings);
        if s > Status::MinimumNorm {
            return None;
        }
        let w: Vec<f64> = super::qp::sym_mul(n, &block.a, &x).iter().zip(b).map(|(u, v)| u + v).collect();
        let scale = b.iter().chain(&x).fold(1.0f64, |m, v| m.max(v.abs()));
        let flip = (0..n)
            .find(|&p| nonnegative[p] && ((in_set[p] && x[p] < -tol * scale) || (!in_set[p] && w[p] < -tol * scale)));
        match flip {
            None => {
                let x: Vec<f64> =
                    x.into_iter().zip(nonnegative).map(|(v, &nn)| if nn { v.max(0.0) } else { v }).collect();
                return Some((x, d, s));
            }
            Some(p) => in_set[p] = !in_set[p],
        }
    }
    None
}

/// Solves Ã μ = −b̃ on a block: band Cholesky, sparse Cholesky or dense Cholesky
/// ([`plan`]), an eigendecomposition when singular.
pub(crate) fn equality(
    block: &Block,
    b: &[f64],
    index: &[usize],
    settings: &Settings,
    diagnostics: &mut Vec<Diagnostic>,
    status: &mut Status,
) -> Vec<f64> {
    let n = block.n;
    if n == 0 {
        return Vec::new();
    }
    let rhs: Vec<f64> = b.iter().map(|x| -x).collect();
    let too_large = |diagnostics: &mut Vec<Diagnostic>, status: &mut Status| {
        diagnostics.push(Diagnostic::TooLarge { constraints: index.to_vec(), rows: n });
        *status = (*status).max(Status::Failed);
        vec![0.0; n]
    };
    if singular_past_dense(block, settings) {
        return match sparse_minimum_norm(block, None, &rhs, index, settings, diagnostics, status) {
            Some(x) => finite_or_zero(x, index, diagnostics, status),
            None => too_large(diagnostics, status),
        };
    }
    // The sparse analysis of a block found singular, for its minimum norm.
    let mut sparse = None;
    match plan(block, settings) {
        Plan::Band(Some(factor)) => {
            return finite_or_zero(factor.solve(&rhs), index, diagnostics, status);
        }
        Plan::Sparse(Some(sparse)) => {
            return finite_or_zero(sparse.factor.solve(&rhs), index, diagnostics, status);
        }
        Plan::Band(None) | Plan::Sparse(None) => {}
        Plan::Singular(analysed) => sparse = Some(analysed),
        Plan::Dense => {
            if n > MAX_DENSE_ROWS {
                return too_large(diagnostics, status);
            }
            if let Some(factor) = DenseFactor::new(block, settings) {
                return finite_or_zero(factor.solve(&rhs), index, diagnostics, status);
            }
        }
    }
    if n > MAX_DENSE_ROWS {
        // Singular past the dense decomposition: the minimum norm by the sparse factor of a
        // regularised Ã, when the rows are consistent.
        return match sparse_minimum_norm(block, sparse, &rhs, index, settings, diagnostics, status) {
            Some(x) => finite_or_zero(x, index, diagnostics, status),
            None => too_large(diagnostics, status),
        };
    }
    let x = minimum_norm(&dense(block), &rhs, &block.weight, index, settings, diagnostics, status);
    finite_or_zero(x, index, diagnostics, status)
}

/// How [`equality`] factors a block: the band Cholesky or the sparse Cholesky (`Some` when
/// their pivots all stay above the rank tolerance, `None` when one does not: the block is
/// singular; the sparse one `None` also when it has no analysis), or dense.
pub(crate) enum Plan {
    Band(Option<BandFactor>),
    Sparse(Option<SparsePlan>),
    /// The sparse factor's analysis of a block its pivots found singular, for
    /// [`sparse_minimum_norm`] to factor the regularised Ã with.
    Singular(SparsePlan),
    Dense,
}

/// A block's sparse factor and, for each of its entries (`Block::a`, in order), the place
/// its value is summed into.
pub(crate) struct SparsePlan {
    factor: SparseFactor,
    targets: Vec<usize>,
}

/// The factorisation chosen for `block` ([`Method`]). `Auto` renumbers by reverse
/// Cuthill–McKee when the given order's band is not under a quarter of the size, takes a
/// narrow band at once, and otherwise analyses the sparse factor and takes it when its
/// weighted count of multiply–adds is below both the band's (when under a quarter of the
/// size) and the dense one's (up to [`MAX_DENSE_ROWS`]); otherwise band when it fits, dense
/// when not. A block no factor serves (dense past the bound, sparse past
/// [`MAX_SPARSE_FLOPS`]) is planned dense, which [`equality`] refuses as too large. A block
/// [`singular_past_dense`] is not planned: its callers take it to the minimum norm (no
/// factorisation that can only fail, or pass by a rounding accident).
pub(crate) fn plan(block: &Block, settings: &Settings) -> Plan {
    let n = block.n;
    let mut order: Option<Vec<usize>> = None;
    let mut bandwidth = block.bandwidth;
    let renumber = matches!(settings.method, Method::Banded | Method::Auto);
    if renumber && BAND_FRACTION * bandwidth >= n && n >= RENUMBER_MIN_ROWS {
        let rcm = super::banded::reverse_cuthill_mckee(n, block.a.iter().map(|&(p, q, _)| (p, q)));
        let mut position = vec![0; n];
        for (new, &old) in rcm.iter().enumerate() {
            position[old] = new;
        }
        let width = block.a.iter().map(|&(p, q, _)| position[p].abs_diff(position[q])).max().unwrap_or(0);
        if width < bandwidth {
            bandwidth = width;
            order = Some(rcm);
        }
    }
    let band_fits = BAND_FRACTION * bandwidth < n;
    let banded = match settings.method {
        Method::Banded => true,
        Method::Dense => false,
        Method::Sparse => return sparse_plan(block, settings),
        Method::Auto if band_fits && (bandwidth <= NARROW_BAND || n < RENUMBER_MIN_ROWS) => true,
        Method::Auto if n < RENUMBER_MIN_ROWS => false,
        Method::Auto => match SparseFactor::analyse(n, block.a.iter().map(|&(p, q, _)| (p, q))) {
            None => band_fits,
            Some((mut sparse, targets)) => {
                let cubed = (n as f64).powi(3);
                let band_cost = if band_fits { n as f64 * ((bandwidth + 1) as f64).powi(2) } else { f64::INFINITY };
                let dense_cost = if n <= MAX_DENSE_ROWS { DENSE_COST * cubed / 3.0 } else { f64::INFINITY };
                let sparse_cost =
                    if sparse.flops() <= MAX_SPARSE_FLOPS { SPARSE_COST * sparse.flops() } else { f64::INFINITY };
                if sparse_cost < band_cost && sparse_cost < dense_cost {
                    let factored = fill_sparse(block, settings, &mut sparse, &targets);
                    return sparse_outcome(factored, SparsePlan { factor: sparse, targets });
                }
                // As before the sparse factor: band when it fits, dense otherwise.
                band_fits
            }
        },
    };
    if !banded {
        return Plan::Dense;
    }
    // position[old] = new (the identity without a renumbering).
    let mut position: Vec<usize> = (0..n).collect();
    if let Some(order) = &order {
        for (new, &old) in order.iter().enumerate() {
            position[old] = new;
        }
    }
    let mut a = Banded::zeros(n, bandwidth);
    for &(p, q, v) in &block.a {
        a.add(position[q], position[p], v);
    }
    Plan::Band(a.cholesky(settings.rank_tolerance).ok().map(|factor| BandFactor { position, a, factor }))
}

/// The sparse factor of `block` ([`Method::Sparse`]: whatever its cost), or its analysis
/// when it is singular.
fn sparse_plan(block: &Block, settings: &Settings) -> Plan {
    match SparseFactor::analyse(block.n, block.a.iter().map(|&(p, q, _)| (p, q))) {
        None => Plan::Sparse(None),
        Some((mut factor, targets)) => {
            let factored = fill_sparse(block, settings, &mut factor, &targets);
            sparse_outcome(factored, SparsePlan { factor, targets })
        }
    }
}

/// The sparse factor when it `factored`, its analysis as [`Plan::Singular`] when not.
fn sparse_outcome(factored: bool, plan: SparsePlan) -> Plan {
    if factored { Plan::Sparse(Some(plan)) } else { Plan::Singular(plan) }
}

/// Sums `block`'s entries into `factor` at `targets` (in `Block::a`'s order: the cache's
/// refactorisation sums its terms in the same order) and factors it.
fn fill_sparse(block: &Block, settings: &Settings, factor: &mut SparseFactor, targets: &[usize]) -> bool {
    sum_entries(block, factor.values_mut(), targets);
    factor.factor(settings.rank_tolerance)
}

/// Zeroes `values` and sums `block`'s entries into them at `targets` (in `Block::a`'s order).
fn sum_entries(block: &Block, values: &mut [f64], targets: &[usize]) {
    values.fill(0.0);
    for (&at, &(_, _, v)) in targets.iter().zip(&block.a) {
        values[at] += v;
    }
}

/// A block's band Cholesky, in its (possibly renumbered) order: what a solve needs to be
/// repeated with other right-hand sides.
#[derive(Clone, Debug)]
pub(crate) struct BandFactor {
    /// position[old] = new.
    position: Vec<usize>,
    a: Banded,
    factor: BandedCholesky,
}

impl BandFactor {
    /// Ã x = `rhs` (in the block's order), with one step of iterative refinement.
    fn solve(&self, rhs: &[f64]) -> Vec<f64> {
        let mut x = Vec::new();
        self.solve_into(rhs, &mut BandWork::default(), &mut x);
        x
    }

    /// [`solve`](BandFactor::solve) into `x`, with `work`'s buffers (no allocation once
    /// they have the block's size).
    ///
    /// The refinement always runs: taking it only when the componentwise residual was
    /// above rounding saved a substitution, but moved a contact stack's run (the exact
    /// velocity solve, `constraints/solvers/stack.toml`) from 1.6e-4 to 6.4e-3 of
    /// penetration, so the cheaper rule did not behave as the solve did.
    fn solve_into(&self, rhs: &[f64], work: &mut BandWork, x: &mut Vec<f64>) {
        let n = rhs.len();
        let BandWork { permuted, y, ax, r } = work;
        permuted.resize(n, 0.0);
        for (old, &new) in self.position.iter().enumerate() {
            permuted[new] = rhs[old];
        }
        y.clear();
        y.extend_from_slice(permuted);
        self.factor.solve_in_place(y);
        // One step of iterative refinement: x += A⁻¹ (rhs − A x).
        ax.resize(n, 0.0);
        self.a.mul(y, ax);
        r.clear();
        r.extend(permuted.iter().zip(ax.iter()).map(|(u, v)| u - v));
        self.factor.solve_in_place(r);
        y.iter_mut().zip(r.iter()).for_each(|(u, v)| *u += v);
        x.clear();
        x.extend(self.position.iter().map(|&new| y[new]));
    }
}

/// Buffers of [`BandFactor::solve_into`].
#[derive(Clone, Debug, Default)]
struct BandWork {
    permuted: Vec<f64>,
    y: Vec<f64>,
    ax: Vec<f64>,
    r: Vec<f64>,
}

/// A block's dense Cholesky (nalgebra), with Ã for the refinement.
#[derive(Clone, Debug)]
pub(crate) struct DenseFactor {
    a: DMatrix<f64>,
    factor: nalgebra::Cholesky<f64, nalgebra::Dyn>,
}

impl DenseFactor {
    /// The factor of `block`, or `None` when a pivot falls to the rank tolerance (singular).
    fn new(block: &Block, settings: &Settings) -> Option<DenseFactor> {
        let a = dense(block);
        let factor = a.clone().cholesky()?;
        factor.l().diagonal().iter().all(|d| d * d > settings.rank_tolerance).then_some(DenseFactor { a, factor })
    }

    /// Ã x = `rhs` with one step of iterative refinement.
    fn solve(&self, rhs: &[f64]) -> Vec<f64> {
        let rhs = DVector::from_column_slice(rhs);
        let mut x = self.factor.solve(&rhs);
        let r = &rhs - &self.a * &x;
        x += self.factor.solve(&r);
        x.iter().copied().collect()
    }
}

fn dense(block: &Block) -> DMatrix<f64> {
    let mut a = DMatrix::<f64>::zeros(block.n, block.n);
    for &(p, q, v) in &block.a {
        a[(p, q)] += v;
        if p != q {
            a[(q, p)] += v;
        }
    }
    a
}

fn finite_or_zero(
    mut x: Vec<f64>,
    index: &[usize],
    diagnostics: &mut Vec<Diagnostic>,
    status: &mut Status,
) -> Vec<f64> {
    finite_in_place(&mut x, index, diagnostics, status);
    x
}

/// Sets the non-finite entries of `x` to 0, with a diagnostic each.
fn finite_in_place(x: &mut [f64], index: &[usize], diagnostics: &mut Vec<Diagnostic>, status: &mut Status) {
    for (p, v) in x.iter_mut().enumerate() {
        if !v.is_finite() {
            diagnostics.push(Diagnostic::NonFiniteLambda { constraint: index[p] });
            *status = (*status).max(Status::Failed);
            *v = 0.0;
        }
    }
}

/// The minimum-norm (least-squares if inconsistent) solution of a singular `a μ = rhs`, with
/// a diagnostic naming the rows in the null space.
///
/// `a` is the symmetric, positive semi-definite Ã, so its eigendecomposition Q Λ Qᵀ is its
/// SVD, with eigenvectors orthogonal to rounding (nalgebra's SVD leaves the singular
/// vectors of an exactly rank-deficient matrix inaccurate by 1e-6 on small redundant
/// systems, which showed as residuals and a wrong minimum). Eigenvalues at or below the
/// rank tolerance (relative to the largest) are zero: μ₀ = Σ qᵢ (qᵢ·rhs)/Λᵢ over the rest.
///
/// The norm minimised is that of λ = `weight`·μ (λ of C/κ, what the pseudo-inverse of the
/// unscaled A gives), not of the scaled μ: among μ₀ + N z (N the null eigenvectors), z
/// minimises ‖W (μ₀ + N z)‖ by a small least squares. Weights count relative to the largest;
/// when their ratios leave the normal range, μ₀ stands (then Σ Aₖₖ λₖ² is what is minimised).
fn minimum_norm(
    a: &DMatrix<f64>,
    rhs: &[f64],
    weight: &[f64],
    index: &[usize],
    settings: &Settings,
    diagnostics: &mut Vec<Diagnostic>,
    status: &mut Status,
) -> Vec<f64> {
    let n = rhs.len();
    let rhs = DVector::from_column_slice(rhs);
    let eigen = a.clone().symmetric_eigen();
    let magnitude: Vec<f64> = eigen.eigenvalues.iter().map(|x| x.abs()).collect();
    let largest = magnitude.iter().copied().fold(0.0f64, f64::max);
    let threshold = settings.rank_tolerance * largest.max(f64::MIN_POSITIVE);
    let kept: Vec<usize> = (0..n).filter(|&s| magnitude[s] > threshold && magnitude[s].is_finite()).collect();
    let null: Vec<usize> = (0..n).filter(|&s| !kept.contains(&s)).collect();
    let rank = kept.len();
    let q = &eigen.eigenvectors;
    let mut mu = DVector::zeros(n);
    for &s in &kept {
        let column = q.column(s);
        mu += column * (column.dot(&rhs) / eigen.eigenvalues[s]);
    }
    let top = weight.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let w: Vec<f64> = weight.iter().map(|x| x / top).collect();
    if !null.is_empty() && w.len() == n && w.iter().all(|x| x.is_normal()) {
        // min over z of ‖W μ₀ + (W N) z‖: z = −(W N)⁺ W μ₀.
        let basis = DMatrix::from_fn(n, null.len(), |p, c| q[(p, null[c])]);
        let weighted = DMatrix::from_fn(n, null.len(), |p, c| w[p] * basis[(p, c)]);
        let target = DVector::from_fn(n, |p, _| -w[p] * mu[p]);
        let inner = weighted.svd(true, true);
        let floor = settings.rank_tolerance * inner.singular_values.amax().max(f64::MIN_POSITIVE);
        if let Ok(z) = inner.solve(&target, floor) {
            let moved = &mu + basis * z;
            if moved.iter().all(|x| x.is_finite()) {
                mu = moved;
            }
        }
    }
    let residual = (a * &mu - &rhs).amax();
    let size = rhs.amax() + a.amax() * mu.amax();
    let consistent = residual <= settings.contact_tolerance.sqrt() * CONSISTENCY * size || size == 0.0;
    let smallest = kept.iter().map(|&s| magnitude[s]).fold(f64::INFINITY, f64::min);
    // Rows with a visible part in a null vector are the redundant ones.
    let mut involved = vec![false; n];
    for &s in &null {
        let column = q.column(s);
        let top = column.amax();
        for p in 0..n {
            involved[p] |= column[p].abs() > NULL_SHARE * top;
        }
    }
    let constraints: Vec<usize> = (0..n).filter(|&p| involved[p]).map(|p| index[p]).collect();
    let condition = largest / smallest;
    diagnostics.push(if consistent {
        Diagnostic::Redundant { constraints, rank, size: n, condition }
    } else {
        Diagnostic::Inconsistent { constraints, rank, size: n, condition, residual: residual / size }
    });
    *status = (*status).max(if consistent { Status::MinimumNorm } else { Status::Inconsistent });
    mu.iter().copied().collect()
}

/// The minimum-norm λ of a singular, consistent block too large for the dense
/// eigendecomposition of [`minimum_norm`] (`analysed`: its sparse analysis, when the plan
/// made one): through the body-space factor when the block is singular whatever its numbers
/// and its rows hold every component they move ([`body_space`]), otherwise by iterated
/// Tikhonov regularisation on the
/// sparse factor (the proximal-point iteration; Hanke and Groetsch, "Nonstationary
/// iterated Tikhonov regularization", J. Optim. Theory Appl. 98, 1998):
/// μ₀ = 0, μₖ₊₁ = μₖ + (Ã + ε W²)⁻¹ (rhs − Ã μₖ), with W the rows' weights (see
/// [`minimum_norm`]). In ν = W μ this is νₖ₊₁ = νₖ + (B + ε)⁻¹ (c − B νₖ) for
/// B = W⁻¹ Ã W⁻¹: the iterates stay in the range of B, where the solution of least ‖ν‖ =
/// ‖W μ‖ lies, and converge to it ([`REGULARISATION`] for the rate).
///
/// The rows named are those with a visible part (`NULL_SHARE`) in the null space, found by
/// two inverse iterations of the regularised factor from a fixed random vector (the null
/// part grows by 1/ε² against at most 1/σ² elsewhere); the rank is not computed.
/// `None` when the block has no sparse analysis within [`MAX_SPARSE_FLOPS`] and cheaper than
/// a dense factor (as [`plan`] weighs them), the regularised factor fails, or the residual
/// stays above the consistency bound (rows that contradict each other: their least squares
/// needs the eigendecomposition).
fn sparse_minimum_norm(
    block: &Block,
    analysed: Option<SparsePlan>,
    rhs: &[f64],
    index: &[usize],
    settings: &Settings,
    diagnostics: &mut Vec<Diagnostic>,
    status: &mut Status,
) -> Option<Vec<f64>> {
    let mut mu = Vec::new();
    if let Some(mut body) = body_space(block, settings) {
        let done = body.minimum_norm(rhs, &body_bounds(settings), &mut BodySpaceWork::default(), &mut mu, false);
        if done.consistent {
            diagnostics.push(body_diagnostic(&body, index, done.solves));
            *status = (*status).max(Status::MinimumNorm);
            return Some(mu);
        }
    }
    let regularised = Regularised::new(block, analysed)?;
    let solves = regularised.minimum_norm(rhs, settings, &mut RegularisedWork::default(), &mut mu)?;
    diagnostics.push(regularised.diagnostic(index, solves));
    *status = (*status).max(Status::MinimumNorm);
    Some(mu)
}

/// The most pseudo-inverse applications of a body-space minimum norm
/// ([`BodySpace::minimum_norm`]): with a fresh factor two reach rounding on the grids, a third
/// finds it stopped improving.
const BODY_SPACE_SOLVES: usize = 8;

/// The body-space factor of `block` (`numeric::gram`: the minimum norm through the Gram
/// matrix of the rows' velocity components) when the block is singular whatever its
/// numbers and every component it moves is held (G of full column rank), within
/// [`MAX_SPARSE_FLOPS`]; `None` otherwise, when the regularised factor serves.
fn body_space(block: &Block, settings: &Settings) -> Option<BodySpace> {
    if !matches!(settings.method, Method::Auto | Method::Sparse) {
        return None;
    }
    let gram = block.gram.clone()?;
    let body = BodySpace::new(gram, settings.rank_tolerance, NULL_SHARE)?;
    (body.flops() <= MAX_SPARSE_FLOPS).then_some(body)
}

/// The largest change of the body-space G' (columns of unit norm) for which a run's cache
/// keeps the factor made for another J of the same pattern ([`SolvePath::Stale`]): its
/// pseudo-inverse is then off by about this times H's condition (1e4–1e6 on grids), so
/// each application shrinks the error by that much and two or three reach rounding. A grid
/// at rest changes J in its last bits (1e-16); a swinging one by 1e-3 a substep, and is
/// factored.
pub const STALE_CHANGE: f64 = 1e-11;

/// [`BodySpace::minimum_norm`]'s thresholds: the consistency bound and rounding of
/// [`Regularised::minimum_norm`].
fn body_bounds(settings: &Settings) -> Bounds {
    Bounds {
        consistency: settings.contact_tolerance.sqrt() * CONSISTENCY,
        rounding: ITERATE_ROUNDING,
        solves: BODY_SPACE_SOLVES,
    }
}

/// The diagnostic of a body-space minimum norm of `solves` applications, the rows named by
/// `index`.
fn body_diagnostic(body: &BodySpace, index: &[usize], solves: usize) -> Diagnostic {
    let constraints = body.null_rows().iter().map(|&p| index[p]).collect();
    Diagnostic::RedundantSparse { constraints, size: index.len(), solves }
}

/// The factor of Ã + ε W² of a singular block (see [`sparse_minimum_norm`]) and what its
/// solves need: made once per J and masses, and kept by a run's [`SolveCache`] (its analysis
/// too, while the pattern stays), since the iteration needs no more than it.
#[derive(Clone, Debug)]
pub(crate) struct Regularised {
    factor: SparseFactor,
    /// For each of Ã's entries (`a`, in order), the place in `factor` it is summed into.
    targets: Vec<usize>,
    /// Ã's entries (`Block::a`), for the residuals.
    a: Vec<(usize, usize, f64)>,
    /// The place in `factor` of each row's diagonal entry (the first place an entry (p, p)
    /// was given: they all sum into one).
    diagonal: Vec<usize>,
    /// The block rows with a visible part in the null space (`NULL_SHARE`).
    null_rows: Vec<usize>,
    /// The largest |Ãₚq|, for the rounding of a residual.
    entry: f64,
}

/// Buffers of [`Regularised::minimum_norm`].
#[derive(Clone, Debug, Default)]
struct RegularisedWork {
    residual: Vec<f64>,
    step: Vec<f64>,
    trial: Vec<f64>,
    ax: Vec<f64>,
    sparse: SparseWork,
}

impl Regularised {
    /// The regularised factor of `block` (`analysed`: its sparse analysis, when the plan made
    /// one); `None` as [`sparse_minimum_norm`] says.
    fn new(block: &Block, analysed: Option<SparsePlan>) -> Option<Regularised> {
        let n = block.n;
        let SparsePlan { factor, targets } = match analysed {
            Some(plan) => plan,
            None => {
                let (factor, targets) = SparseFactor::analyse(n, block.a.iter().map(|&(p, q, _)| (p, q)))?;
                SparsePlan { factor, targets }
            }
        };
        // As `plan` weighs them: a block whose sparse factor costs more than a dense one is
        // dense (all pairs of a cluster of bodies), and its n³ is what the size limit refuses.
        let dense_cost = DENSE_COST * (n as f64).powi(3) / 3.0;
        if factor.flops() > MAX_SPARSE_FLOPS || SPARSE_COST * factor.flops() > dense_cost {
            return None;
        }
        let mut diagonal = vec![usize::MAX; n];
        for (&at, &(p, q, _)) in targets.iter().zip(&block.a) {
            if p == q && diagonal[p] == usize::MAX {
                diagonal[p] = at;
            }
        }
        // Ã has a unit diagonal: every row has its entry.
        if diagonal.contains(&usize::MAX) {
            return None;
        }
        let mut regularised =
            Regularised { factor, targets, a: block.a.clone(), diagonal, null_rows: Vec::new(), entry: 0.0 };
        regularised.refactor(&block.weight).then_some(regularised)
    }

    /// Ã + ε W² into the factor from `a` (Ã's entries at their places, then ε Wₚ² on each
    /// diagonal), for the rows' `weight`, factored, and the null space's rows found: false
    /// when the factorisation fails.
    fn refactor(&mut self, weight: &[f64]) -> bool {
        let n = self.diagonal.len();
        let top = weight.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        let values = self.factor.values_mut();
        values.fill(0.0);
        for (&at, &(_, _, v)) in self.targets.iter().zip(&self.a) {
            values[at] += v;
        }
        let w2 = |p: usize| (weight[p] / top) * (weight[p] / top);
        let weighted = weight.len() == n && (0..n).all(|p| w2(p).is_finite() && w2(p).sqrt() >= WEIGHT_RANGE);
        let w2 = |p: usize| if weighted { w2(p) } else { 1.0 };
        for (p, &at) in self.diagonal.iter().enumerate() {
            values[at] += REGULARISATION * w2(p);
        }
        if !self.factor.factor(0.0) {
            return false;
        }
        // The null space's rows: two inverse iterations in the weighted norm from a fixed
        // vector.
        let mut rng = super::random::Rng::new(0x5EED_F00D);
        let mut y: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let mut work = SparseWork::default();
        for _ in 0..2 {
            // The substitutions alone: which rows a null vector shows in needs no refinement.
            let weighted: Vec<f64> = y.iter().enumerate().map(|(p, v)| v * w2(p)).collect();
            self.factor.substitute_into(&weighted, &mut work, &mut y);
        }
        let peak = y.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        self.null_rows.clear();
        self.null_rows.extend((0..n).filter(|&p| y[p].abs() > NULL_SHARE * peak));
        self.entry = self.a.iter().fold(0.0f64, |m, &(_, _, v)| m.max(v.abs()));
        true
    }

    /// The minimum-norm μ of Ã μ = `rhs` into `mu` by the iterated Tikhonov solves (see
    /// [`sparse_minimum_norm`]), and their number; `None` when the residual stays above the
    /// consistency bound (rows that contradict each other) or μ is not finite.
    fn minimum_norm(
        &self,
        rhs: &[f64],
        settings: &Settings,
        work: &mut RegularisedWork,
        mu: &mut Vec<f64>,
    ) -> Option<usize> {
        let n = self.diagonal.len();
        let RegularisedWork { residual, step, trial, ax, sparse } = work;
        mu.clear();
        mu.resize(n, 0.0);
        residual.clear();
        residual.extend_from_slice(rhs);
        let size = rhs.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let mut left = size;
        let mut solves = 0;
        let entry = self.entry;
        while solves < REGULARISED_SOLVES && left > 0.0 {
            // The substitutions alone: the iteration refines against Ã itself.
            self.factor.substitute_into(residual, sparse, step);
            trial.clear();
            trial.extend(mu.iter().zip(step.iter()).map(|(m, s)| m + s));
            // Ã x in `qp::sym_mul`'s order.
            ax.clear();
            ax.resize(n, 0.0);
            for &(i, j, v) in &self.a {
                ax[i] += v * trial[j];
                if i != j {
                    ax[j] += v * trial[i];
                }
            }
            let now = rhs.iter().zip(ax.iter()).fold(0.0f64, |m, (r, a)| m.max((r - a).abs()));
            solves += 1;
            if !now.is_finite() || now > 0.5 * left {
                // No longer halving: the last iterate is at its rounding (or this one is worse).
                if now < left && now.is_finite() {
                    std::mem::swap(mu, trial);
                    left = now;
                }
                break;
            }
            std::mem::swap(mu, trial);
            residual.clear();
            residual.extend(rhs.iter().zip(ax.iter()).map(|(r, a)| r - a));
            left = now;
        }
        // Against the right-hand side as the dense solve weighs it, and against the rounding
        // of Ã μ: not √tolerance of |Ã||μ|, since rows that contradict each other leave their
        // residual's null part r₀ in every step, which adds r₀/ε to μ each time, so that bound
        // would grow past any residual (random c terms on a braced grid passed it).
        let rounding = ITERATE_ROUNDING * f64::EPSILON * entry * mu.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let consistent = left <= settings.contact_tolerance.sqrt() * CONSISTENCY * size + rounding || size == 0.0;
        (consistent && mu.iter().all(|x| x.is_finite())).then_some(solves)
    }

    /// The diagnostic of a solve of `solves` regularised solves, the rows named by `index`.
    fn diagnostic(&self, index: &[usize], solves: usize) -> Diagnostic {
        let constraints = self.null_rows.iter().map(|&p| index[p]).collect();
        Diagnostic::RedundantSparse { constraints, size: self.diagonal.len(), solves }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numeric::rows::Row;
    use proptest::prelude::*;

    /// A chain of `masses.len()` point masses in 2D, the first hung from a fixed point: row 0
    /// acts on body 0, row k on bodies k − 1 and k, with the gradients `dirs`.
    fn chain(masses: &[f64], dirs: &[[f64; 2]]) -> Rows {
        let rows = dirs
            .iter()
            .enumerate()
            .map(|(k, d)| {
                let j = [d[0], d[1], 0.0];
                let jacobian = if k == 0 { vec![(0, j)] } else { vec![(k - 1, j.map(|x| -x)), (k, j)] };
                Row { value: 0.0, rate: 0.0, bias: 0.1 * k as f64, inequality: false, jacobian }
            })
            .collect();
        let n = masses.len();
        Rows {
            dim: 2,
            inverse_mass: masses.to_vec(),
            velocity: vec![[0.5, -0.25, 0.0]; n],
            force: vec![[0.0, -9.81, 0.0]; n],
            rows,
            axes: Vec::new(),
        }
    }

    /// A run of same-pattern rows (a chain of `n`), each state with other numbers, some with
    /// one number the cache cannot serve (an inverse mass zero, NaN, infinite or slightly
    /// negative, which keeps Ã positive definite so only the check on the masses finds it; a
    /// gradient zero, NaN or infinite). Short chains take the dense factor, which is made
    /// anew; longer ones the band or sparse factor, refactored in place.
    fn runs() -> impl Strategy<Value = Vec<Rows>> {
        (2usize..80).prop_flat_map(|n| {
            let component = prop_oneof![0.1..2.0f64, -2.0..-0.1f64];
            let state = (
                prop::collection::vec(0.1..2.0f64, n),
                prop::collection::vec([component.clone(), component], n),
                prop::option::of((0..2 * n, 0..4usize)),
            )
                .prop_map(move |(mut masses, mut dirs, bad)| {
                    if let Some((at, kind)) = bad {
                        if at < n {
                            masses[at] = [0.0, f64::NAN, f64::INFINITY, -1e-3][kind];
                        } else {
                            let d = &mut dirs[at - n];
                            *d = [[0.0, 0.0], [f64::NAN, d[1]], [d[0], f64::INFINITY], [d[0], d[1]]][kind];
                        }
                    }
                    chain(&masses, &dirs)
                });
            prop::collection::vec(state, 1..8)
        })
    }

    proptest! {
        /// Refactored in place along a run whose J changes at every state (the solve cache's
        /// `compare_taking` and `Scaled::rescale_in_place`), with states the cache cannot
        /// serve in between, the answer is the general solve's bit for bit, and a state it
        /// can serve after one it could not is factored again.
        #[test]
        fn a_run_of_same_pattern_rows_gives_the_general_answer(run in runs(), sparse in any::<bool>()) {
            let settings = Settings { method: if sparse { Method::Sparse } else { Method::Auto }, ..Settings::default() };
            let mut cache = SolveCache::default();
            let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            let bits3 = |x: &[[f64; 3]]| x.iter().flat_map(|v| v.map(f64::to_bits)).collect::<Vec<_>>();
            for rows in &run {
                let cached = solve_cached(rows, &settings, &[], &mut cache);
                let general = solve_holding(rows, &settings, &[]);
                prop_assert_eq!(bits(&cached.lambda), bits(&general.lambda));
                prop_assert_eq!(bits3(&cached.constraint_force), bits3(&general.constraint_force));
                prop_assert_eq!(bits3(&cached.acceleration), bits3(&general.acceleration));
                prop_assert_eq!(&cached.active, &general.active);
                prop_assert_eq!(&cached.diagnostics, &general.diagnostics);
                prop_assert_eq!(cached.status, general.status);
                if general.diagnostics.is_empty() {
                    prop_assert_ne!(cache.last_path(), SolvePath::General);
                }
            }
        }
    }

    proptest! {
        /// A mark of a factor ([`FactorId`]) serves only while that factor is kept: along a
        /// run, each state's rows solved with the mark the state before had — its factor
        /// since replaced by the next state's — give the general answer bit for bit; solved
        /// again with the mark their own solve handed out they are `Reused` (J not compared)
        /// with the same answer; and with one mass changed under that mark they are factored
        /// again, the general answer of those masses.
        #[test]
        fn a_mark_serves_only_its_factor_and_masses(run in runs()) {
            let settings = Settings::default();
            let mut cache = SolveCache::default();
            let bits3 = |x: &[[f64; 3]]| x.iter().flat_map(|v| v.map(f64::to_bits)).collect::<Vec<_>>();
            let mut out = Solution::default();
            let mut solve = |rows: &Rows, cache: &mut SolveCache, mark| {
                cached_into(rows, &settings, &[], cache, &mut out, Answer::Solution, mark);
                (bits3(&out.acceleration), out.lambda.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
            };
            let general = |rows: &Rows| {
                let g = solve_holding(rows, &settings, &[]);
                (bits3(&g.acceleration), g.lambda.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
            };
            for pair in run.windows(2) {
                let (before, rows) = (&pair[0], &pair[1]);
                solve(before, &mut cache, None);
                let stale = cache.made();
                solve(rows, &mut cache, None);
                prop_assert_eq!(solve(before, &mut cache, stale), general(before));
                let own = cache.made();
                prop_assert_eq!(solve(before, &mut cache, own), general(before));
                if own.is_some() {
                    prop_assert_eq!(cache.last_path(), SolvePath::Reused);
                }
                let mut heavier = before.clone();
                heavier.inverse_mass[0] *= 0.5;
                prop_assert_eq!(solve(&heavier, &mut cache, own), general(&heavier));
                if own.is_some() && cache.made().is_some() {
                    prop_assert_eq!(cache.last_path(), SolvePath::Factored);
                }
            }
        }
    }

    /// [`positive_finite`]'s bit test answers as `n > 0.0 && n.is_finite()` on every kind of
    /// number: zeros, subnormals, the ends of the normal range, infinities and NaNs of either
    /// sign, and numbers around them.
    #[test]
    fn positive_finite_is_the_comparisons() {
        for x in crate::numeric::vector::SPECIAL_NUMBERS {
            for n in [x, f64::from_bits(x.to_bits().wrapping_add(1)), f64::from_bits(x.to_bits().wrapping_sub(1))] {
                assert_eq!(positive_finite(n), n > 0.0 && n.is_finite(), "{n:e} ({:#x})", n.to_bits());
            }
        }
    }
}
