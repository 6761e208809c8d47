//! The λ solve of equality rows that form a chain in their given order (Ã tridiagonal: a
//! slot is acted on by one row or by two consecutive ones), assembled, factored and solved in
//! place in a few passes along the rows, instead of the general solve's scaling buffers,
//! term lists, band matrix and permutations (`numeric::solve`).
//!
//! Design note. The general solve of a chain is correct and linear but walks the rows many
//! times: a finiteness check, the scaling (‖J‖, J/‖J‖, Jacobi), Ã term by term through a list
//! of terms, the band factor, the right-hand side, each substitution, then λ and the forces.
//! Here one pass does, for each row, the check, the scaling, the row's two entries of Ã and
//! b̃'s sum over its entries (one walk of them); a second the row of the factor (the factor
//! of row k needs only rows up to k), −b̃ and the forward substitution; a third the backward
//! substitution with the refinement's residual (a row's once the rows from it down are
//! final) and the norms that decide whether a step of refinement is taken; only when it is,
//! a fourth the residual's forward substitution and a fifth its backward substitution,
//! adding the correction; then λ; and, over the slots, each slot's force from its one or two
//! rows and its acceleration (a fresh answer's accelerations in a pass of their own). No term
//! list, no permutation, no buffer of the general solve's. Every number up to the solution
//! is the general solve's bit for bit: the same operations (`solve::scale_row`, `solve::b_of`,
//! `banded`'s tridiagonal kernels) in the same order — Ã's entries summed over the slots in
//! increasing order from +0, as `solve::assemble`'s terms go. The general solve always takes
//! the step of refinement; this one takes it only when the first solution's residual is
//! above what the backward stable tridiagonal Cholesky leaves ([`REFINE_BOUND`], with the
//! analysis), which it practically never is: the solution is then the general one's before
//! its step, within the same residual bound, and where the step is taken it is the general
//! solve's bit for bit. A property test over random chains holds it to that
//! (`tests/chain_solve.rs`).
//!
//! It serves only what the general solve would answer with the tridiagonal band Cholesky and
//! no diagnostic but a λ out of range: equality rows, every number finite, every row usable
//! (a finite, non-zero ‖J‖ and a positive, finite Âₖₖ), each row's slots in increasing order,
//! the band of width exactly 1 in the given order, [`Method::Banded`] or [`Method::Auto`]
//! with more than four rows (fewer go dense), no pivot at or below the rank tolerance, past
//! [`MAX_DENSE_ROWS`] rows under `Auto` no more rows than the velocity components they move
//! (`solve::structurally_singular`), and every multiplier finite. Anything else declines,
//! leaving the answer to the general solve (with its diagnostics, the renumbering, the
//! eigendecomposition or the regularised factor). Kept in a run's `SolveCache`, it keeps the
//! bits of J and the masses it was made from and refactors from the first row whose J
//! changed: the rows before keep their scaling, Ã and factor rows, which depend on nothing
//! after them; `solve_with`'s chains keep no factor and take no bits, only the last pattern,
//! used again for rows on the same slots in the same order. The pattern check
//! records each entry's partner, the entry of the row before on the same slot, which is
//! all Ãₖ,ₖ₋₁ and the count of moved velocity components need from the pattern.
//!
//! Not here: evaluating rows (`numeric::rows`), inequality rows, other bandwidths.

use super::banded::{backward_step, forward_step, tridiagonal_factor_row};
use super::rows::Rows;
use super::solve::{
    Answer, FactorId, MAX_DENSE_ROWS, Method, Settings, Solution, SolvePath, Status, b_of, normalise_row, out_of_range,
};
use super::vector::{all_finite, dot, not_finite_bit};
use std::cell::RefCell;

/// No row yet, in [`Chain::first`].
const NONE: usize = usize::MAX;

/// The residual's bound under which [`Chain::substitute`] takes no step of refinement:
/// ‖−b̃ − Ã y‖₁ ≤ 16 u (3 ‖y‖₁ + ‖b̃‖₁), u = 2⁻⁵³ the unit roundoff.
///
/// Why a step would not help there (Higham, *Accuracy and Stability of Numerical
/// Algorithms*, 2nd ed. 2002: §9.6 for tridiagonals, ch. 10 for Cholesky, ch. 12 for
/// refinement). The factor of a tridiagonal Ã is bidiagonal with a positive diagonal, so
/// |L||Lᵀ| = |L Lᵀ| entry by entry (the diagonal's l²ᵢ,ᵢ₋₁ + l²ᵢᵢ has no cancellation, the
/// off-diagonal is one product): the factor has no growth. Each factor row (a division, a
/// square, a subtraction, a square root) gives L̂ L̂ᵀ = Ã + ΔÃ with |ΔÃ| ≤ γ₃ |L̂||L̂ᵀ| ≤
/// γ₃ |Ã| (to first order), and each substitution row (a product, a subtraction, the
/// rounded 1/Lᵢᵢ and the multiplication by it) (L̂ + ΔL) y = x with |ΔL| ≤ γ₃ |L̂|; together
/// (Ã + E) ŷ = −b̃ with |E| ≤ 9u |Ã| to first order: the solve is backward stable
/// componentwise, and the true residual is at most 9u |Ã||ŷ|. Its evaluation (three
/// products, their sum, the subtraction) adds γ₄ (|b̃| + |Ã||ŷ|), so the computed residual
/// is within 13u (|Ã||ŷ| + |b̃|) row by row, and summed over the rows within
/// 13u (‖Ã‖₁ ‖ŷ‖₁ + ‖b̃‖₁), where ‖Ã‖₁ ≤ 3 (1 + O(u)): Ã is a Gram matrix J̃ M⁻¹ J̃ᵀ with a
/// unit diagonal to rounding, so |Ãᵢⱼ| ≤ (Ãᵢᵢ Ãⱼⱼ)^½, and a column has three entries.
/// 16u leaves room for the second-order terms and the sums' own rounding (n u, below 1e-10
/// for a million rows). A residual within it is the rounding of a backward stable solve,
/// which one step of fixed-precision refinement improves by no more than a small constant
/// (Higham §12.2: the step brings the componentwise backward error to O(u) when the solver
/// is not stable enough; here it already is, and the forward error is about κ(Ã) u either
/// way — on ill-conditioned chains λ's errors without the step are 1.3× larger summed over
/// cases, from 0.09× to 9× case by case, `tests/chain_solve.rs`): the step is taken only
/// where the analysis does not hold — numbers near the underflow threshold (a subnormal's
/// error is not relative), or a residual that is not finite.
const REFINE_BOUND: f64 = 16.0 * (f64::EPSILON / 2.0);

/// A chain's scaling, Ã and factor, with the J and masses they were made from and the
/// buffers of its substitutions (see the module note).
#[derive(Clone, Debug, Default)]
pub(crate) struct Chain {
    /// Whether the fields below hold the scaling and factor of `bits` and `mass_bits` under
    /// `rank_tolerance` and `method`.
    valid: bool,
    /// How many factors have been begun: the mark of the one kept ([`FactorId`]), counted
    /// up before every factor begun from a row that changed or on a new pattern (0, before
    /// the first and after 2⁶⁴, marks nothing).
    made: u64,
    rank_tolerance: u64,
    method: Method,
    /// Row k's entries are `start[k]..start[k + 1]` of `parts` and `bits`.
    start: Vec<usize>,
    /// J̃ per entry (slot, J/‖J‖/√Âₖₖ), as `solve::Scaled` keeps it.
    parts: Vec<(usize, [f64; 3])>,
    /// Per entry its slot and the bits of its J, and per slot the bits of 1/m, the scaling
    /// was made from (slot and bits side by side: the check of a solve whose J is kept
    /// walks one array).
    bits: Vec<(usize, [u64; 3])>,
    mass_bits: Vec<u64>,
    /// ‖Jₖ‖ and 1/√Âₖₖ per row.
    norm: Vec<f64>,
    jacobi: Vec<f64>,
    /// Ã and its factor L as `banded::Banded` and `BandedCholesky` store a tridiagonal
    /// (row k: entry (k, k − 1) at 2k, (k, k) at 2k + 1), with 1/Lₖₖ.
    a: Vec<f64>,
    l: Vec<f64>,
    inverse: Vec<f64>,
    /// Per row Σᵢ J̃ᵢ·Fᵢ wᵢ, b̃ but its c̃, summed as the row is scaled (rows past the first
    /// that changed; the rows before take it in [`factor_from`](Chain::factor_from)).
    external: Vec<f64>,
    /// Whether the last substitution took the step of refinement ([`REFINE_BOUND`]).
    refined: bool,
    /// −b̃, the solution and the refinement's correction.
    rhs: Vec<f64>,
    y: Vec<f64>,
    r: Vec<f64>,
    /// Per entry, the entry of the row before on the same slot (`NONE`: that row does not
    /// act on it): the pairs whose products make Ãₖ,ₖ₋₁, found once with the pattern.
    partner: Vec<usize>,
    /// Per slot, the first entry on it (the pattern check) and the second (`NONE`: one row
    /// acts on it, or none): what [`finish`](Chain::finish) sums a slot's force from.
    first: Vec<usize>,
    second: Vec<usize>,
    /// Per entry, its row.
    owner: Vec<usize>,
    /// Whether `start`, the slots of `parts`, `partner`, `first`, `second` and `owner` hold
    /// a whole chain's pattern (the last one taken), which a solve of rows on the same slots
    /// in the same order uses again ([`same_pattern`](Chain::same_pattern)).
    pattern: bool,
}

/// Whether every row is an equality with a finite c term and every velocity and force is
/// finite: what `solve_cached_into` checks before anything is cached.
/// (This runs at every solve: the rows' flags and c terms are tested joined by `&`, and the
/// slots' numbers along flat arrays by `vector::all_finite`, without a branch each.)
pub(crate) fn servable(rows: &Rows) -> bool {
    rows.rows.iter().fold(true, |ok, row| ok & !row.inequality & row.bias.is_finite())
        && all_finite(rows.velocity.as_flattened())
        && all_finite(rows.force.as_flattened())
}

/// Whether every number of `xs` is ±0: its bits but the sign's, OR-ed, are none (without
/// a branch each).
fn all_zero(xs: &[f64]) -> bool {
    xs.iter().fold(0u64, |bits, x| bits | (x.to_bits() << 1)) == 0
}

/// `v` cleared, with room for `n` elements: a vector of its own when it has less, allocated
/// at that capacity at once (extending an empty vector took the growth path's two calls
/// more, about 40 instructions a vector: a tenth of a 10-row solve's allocations).
fn emptied<T>(v: &mut Vec<T>, n: usize) {
    v.clear();
    if v.capacity() < n {
        *v = Vec::with_capacity(n);
    }
}

/// Row j's residual −b̃ⱼ − (Ã y)ⱼ from its numbers, as `banded::tridiagonal_mul_row` sums
/// (Ã y)ⱼ: `below` is +0 + Ãⱼ,ⱼ₋₁ yⱼ₋₁ (+0 at row 0), then Ãⱼⱼ yⱼ, then `above`, Ãⱼ₊₁,ⱼ yⱼ₊₁.
/// At the last row, which has no row above, `above` is +0: the sum before it is +0 + (…),
/// never −0, so adding +0 leaves its bits (a NaN stays a NaN) as leaving it out would.
#[inline(always)]
fn residual(rhs: f64, below: f64, diagonal: f64, y: f64, above: f64) -> f64 {
    rhs - ((0.0 + (below + diagonal * y)) + above)
}

thread_local! {
    /// The buffers of [`solve_into`]'s chains, kept between the calls on a thread: their sizes
    /// and the last pattern, not their numbers (every call scales and factors afresh), so a
    /// solve of a chain the size of the last one allocates only its answer (nothing into an
    /// answer that held one of that size, `solve::solve_into`), and one on the same slots
    /// does not look for its pattern again.
    static BUFFERS: RefCell<Chain> = RefCell::new(Chain::default());
}

/// Writes the general solve's answer at `rows` into `out` when they form a chain it serves
/// (module note), reusing `out`'s vectors, and returns true; returns false, `out`
/// untouched, otherwise: `solve_holding_into`'s fast path.
pub(crate) fn solve_into(rows: &Rows, settings: &Settings, out: &mut Solution) -> bool {
    if !servable(rows) || !allowed(settings.method, rows.rows.len()) {
        return false;
    }
    let path = BUFFERS.with(|chain| match chain.try_borrow_mut() {
        // No factor of an earlier call is reused, none is kept: this solve's cost is a fresh one's.
        Ok(mut chain) => chain.solve_fresh(rows, settings, out),
        // Not reached (nothing here solves inside a solve), but a fresh chain would serve.
        Err(_) => Chain::default().solve_fresh(rows, settings, out),
    });
    path.is_some()
}

/// Whether every slot's 1/m is finite and ≥ 0, as `solve::row_sound` asks of the slots a
/// row acts on: checked once a solve here rather than once per entry (a slot no row acts
/// on that fails it sends the rows to the general solve, which answers the same).
///
/// By bits, as [`not_finite_bit`] (which this adds to): w + 0 turns −0 (which is ≥ 0) into +0,
/// so its sign bit is set exactly when w < 0 (or w is a NaN, which the exponent finds).
fn masses_sound(inverse_mass: &[f64]) -> bool {
    inverse_mass.iter().fold(0u64, |bad, w| bad | (w + 0.0).to_bits() | not_finite_bit(*w)) >> 63 == 0
}

/// Whether the general solve takes the tridiagonal band for a chain of `k` rows under
/// `method` (`solve::plan`: `Auto` takes dense Cholesky up to four rows, where the band is
/// not under a quarter of the size).
fn allowed(method: Method, k: usize) -> bool {
    match method {
        Method::Banded => k > 0,
        Method::Auto => k > 4,
        Method::Dense | Method::Sparse => false,
    }
}

impl Chain {
    /// Whether a factor is kept (for `SolveCache::factorisation`).
    pub(crate) fn is_kept(&self) -> bool {
        self.valid
    }

    /// The mark of the kept factor ([`FactorId`]), `None` when none is kept.
    pub(crate) fn made(&self) -> Option<FactorId> {
        std::num::NonZeroU64::new(self.made).filter(|_| self.valid).map(FactorId)
    }

    /// Solves `rows` (already [`servable`]) into `out` when they are a chain this path serves,
    /// reusing the kept scaling and factor up to the first row whose J changed; `None` (the
    /// kept factor dropped, `out` untouched) otherwise. `answer` says what is written;
    /// `known`, when it is the kept factor's mark, says the rows' J is the factor's bit for
    /// bit (the caller's word: it has not changed since the solve that handed the mark out),
    /// so only the masses and settings are compared.
    pub(crate) fn solve_into(
        &mut self,
        rows: &Rows,
        settings: &Settings,
        out: &mut Solution,
        answer: Answer,
        known: Option<FactorId>,
    ) -> Option<SolvePath> {
        self.solve_keeping(rows, settings, out, true, answer, known)
    }

    /// [`solve_into`](Chain::solve_into) from scratch, keeping no factor (the bits of J and
    /// the masses are not taken): `solve_with`'s chains, which are never compared with a
    /// next call's.
    fn solve_fresh(&mut self, rows: &Rows, settings: &Settings, out: &mut Solution) -> Option<SolvePath> {
        self.valid = false;
        self.solve_keeping(rows, settings, out, false, Answer::Solution, None)
    }

    /// [`solve_into`](Chain::solve_into), keeping the factor for the next call when `keep`.
    /// A correction's step (`Answer::Step`) whose forces are all zero (its caller zeroed
    /// them) takes each row's b̃ as its c term where that is not zero ([`factor_from`]).
    fn solve_keeping(
        &mut self,
        rows: &Rows,
        settings: &Settings,
        out: &mut Solution,
        keep: bool,
        answer: Answer,
        known: Option<FactorId>,
    ) -> Option<SolvePath> {
        let k = rows.rows.len();
        if !allowed(settings.method, k) {
            self.valid = false;
            return None;
        }
        let from = match known {
            Some(id) if self.is_made(id, rows, settings) => Some(k),
            _ => self.unchanged_rows(rows, settings),
        };
        let from = match from {
            Some(from) => from,
            None => {
                // A fresh solve (`keep` false: no bits to take) of the last pattern again
                // has nothing to find (a solve that keeps one compares the rows' slots in
                // `unchanged_rows`).
                let reused = !keep && self.same_pattern(rows);
                if !reused && !self.take_pattern(rows, keep) {
                    self.valid = false;
                    return None;
                }
                self.rank_tolerance = settings.rank_tolerance.to_bits();
                self.method = settings.method;
                0
            }
        };
        // Invalid until the factor is whole again, and another factor's from the first row
        // that changed.
        self.valid = false;
        if from < k {
            self.made = self.made.wrapping_add(1);
        }
        let zero_forces = answer == Answer::Step && all_zero(rows.force.as_flattened());
        if !self.factor_and_forward(rows, settings, from, keep, zero_forces) {
            return None;
        }
        if from < k && settings.method == Method::Auto && k > MAX_DENSE_ROWS && k > self.columns(rows) {
            return None;
        }
        self.valid = keep;
        if !self.substitute() {
            // `solve::finite_in_place` has a diagnostic for it.
            return None;
        }
        self.finish(rows, out, answer);
        Some(if from == k { SolvePath::Reused } else { SolvePath::Factored })
    }

    /// Whether `id` marks the kept factor and the rows' masses and the settings are those it
    /// was made from: with the caller's word that J is the factor's ([`FactorId`]), the rows
    /// are the factor's bit for bit. The masses are compared by bits, without a branch each
    /// (a motion evaluation fills them again even where J is kept).
    fn is_made(&self, id: FactorId, rows: &Rows, settings: &Settings) -> bool {
        self.valid
            && id.0.get() == self.made
            && self.start.len() == rows.rows.len() + 1
            && self.rank_tolerance == settings.rank_tolerance.to_bits()
            && self.method == settings.method
            && self.mass_bits.len() == rows.inverse_mass.len()
            && self.mass_bits.iter().zip(&rows.inverse_mass).fold(0, |d, (b, w)| d | (b ^ w.to_bits())) == 0
    }

    /// The first row whose J differs from the kept one's bits (`k` when none does, 0 when a
    /// mass or the settings did), or `None` when no factor is kept or the rows act on other
    /// slots: a new pattern.
    fn unchanged_rows(&mut self, rows: &Rows, settings: &Settings) -> Option<usize> {
        let k = rows.rows.len();
        if !self.valid || self.start.len() != k + 1 || self.mass_bits.len() != rows.inverse_mass.len() {
            return None;
        }
        let mut from = k;
        let mut each = rows.rows.iter().zip(self.start.windows(2)).enumerate();
        // J bit for bit up to the first row that differs (a run's velocity projection: the
        // first), the slots alone after it.
        for (q, (row, bounds)) in each.by_ref() {
            let kept = &self.bits[bounds[0]..bounds[1]];
            if kept.len() != row.jacobian.len() {
                return None;
            }
            let mut same = true;
            for ((s, j), (slot, bits)) in row.jacobian.iter().zip(kept) {
                if slot != s {
                    return None;
                }
                let j = j.map(f64::to_bits);
                same &= ((bits[0] ^ j[0]) | (bits[1] ^ j[1]) | (bits[2] ^ j[2])) == 0;
            }
            if !same {
                from = q;
                break;
            }
        }
        for (_, (row, bounds)) in each {
            let kept = &self.bits[bounds[0]..bounds[1]];
            if kept.len() != row.jacobian.len() || row.jacobian.iter().zip(kept).any(|((s, _), (slot, _))| slot != s) {
                return None;
            }
        }
        let mut masses_same = true;
        for (mine, w) in self.mass_bits.iter_mut().zip(&rows.inverse_mass) {
            let bits = w.to_bits();
            masses_same &= *mine == bits;
            *mine = bits;
        }
        let settings_same = self.rank_tolerance == settings.rank_tolerance.to_bits() && self.method == settings.method;
        if !(masses_same && settings_same) {
            self.rank_tolerance = settings.rank_tolerance.to_bits();
            self.method = settings.method;
            from = 0;
        }
        Some(from)
    }

    /// Whether the rows act on the slots of the kept pattern, row by row and in the same
    /// order: then every pattern this path takes from them is that one.
    fn same_pattern(&self, rows: &Rows) -> bool {
        let k = rows.rows.len();
        if !self.pattern || self.start.len() != k + 1 || self.first.len() != rows.inverse_mass.len() {
            return false;
        }
        rows.rows.iter().zip(self.start.windows(2)).all(|(row, bounds)| {
            let kept = &self.parts[bounds[0]..bounds[1]];
            kept.len() == row.jacobian.len()
                && row.jacobian.iter().zip(kept).fold(true, |same, ((s, _), (slot, _))| same & (s == slot))
        })
    }

    /// Takes the rows' pattern when it is a chain this path serves: each row's slots in
    /// increasing order, every slot acted on by one row or two consecutive ones, and two
    /// consecutive rows sharing a slot somewhere (the band is exactly 1 wide: a band of 0,
    /// rows on disjoint slots, takes the general solve's diagonal kernels). With `keep`, the
    /// slots of the J bits and the masses' bits are taken too.
    fn take_pattern(&mut self, rows: &Rows, keep: bool) -> bool {
        let (k, slots) = (rows.rows.len(), rows.inverse_mass.len());
        self.pattern = false;
        self.first.clear();
        self.first.resize(slots, NONE);
        self.second.clear();
        self.second.resize(slots, NONE);
        self.start.clear();
        self.parts.clear();
        self.partner.clear();
        self.owner.clear();
        // Sized once: pushed one by one, a long chain's buffers were copied as they grew.
        let entries = rows.rows.iter().map(|row| row.jacobian.len()).sum();
        self.start.reserve(k + 1);
        self.parts.reserve(entries);
        self.partner.reserve(entries);
        self.owner.reserve(entries);
        let mut shared = false;
        // The first entry of the row before (entries before it are of earlier rows).
        let mut before = 0;
        for (q, row) in rows.rows.iter().enumerate() {
            let here = self.parts.len();
            self.start.push(here);
            let mut previous = None;
            for &(s, _) in &row.jacobian {
                if s >= slots || previous.is_some_and(|p| p >= s) {
                    return false;
                }
                previous = Some(s);
                // The slot's first entry is of this row only if the slot repeats in it
                // (refused above), so one at or past `before` is of the row before.
                let partner = match self.first[s] {
                    NONE => {
                        self.first[s] = self.parts.len();
                        NONE
                    }
                    entry if entry >= before => {
                        shared = true;
                        self.second[s] = self.parts.len();
                        entry
                    }
                    _ => return false,
                };
                self.parts.push((s, [0.0; 3]));
                self.partner.push(partner);
                self.owner.push(q);
            }
            before = here;
        }
        self.start.push(self.parts.len());
        if !shared {
            return false;
        }
        if keep {
            self.bits.clear();
            self.bits.extend(self.parts.iter().map(|&(slot, _)| (slot, [0; 3])));
            self.mass_bits.clear();
            self.mass_bits.extend(rows.inverse_mass.iter().map(|w| w.to_bits()));
        }
        // Sized, not cleared: a solve from a new pattern writes every entry (from row 0)
        // before reading it, so a chain of the last call's size is not written twice.
        let buffers = [&mut self.norm, &mut self.jacobi, &mut self.inverse, &mut self.rhs, &mut self.y, &mut self.r];
        for v in buffers.into_iter().chain([&mut self.external]) {
            v.resize(k, 0.0);
        }
        for v in [&mut self.a, &mut self.l] {
            v.resize(2 * k, 0.0);
        }
        self.pattern = true;
        true
    }

    /// Rows `from..` scaled and assembled (their J's bits taken), then factored, with every
    /// row's −b̃ and forward substitution. False when a row is not usable or a pivot falls to
    /// the rank tolerance (the general solve has a diagnostic or a fallback).
    ///
    /// Two passes: the scaling's rows are independent (each a chain of two square roots and
    /// two divisions of its own, which overlap from row to row), the factor's rows one chain
    /// through every row (a division and a square root each, then 1/Lₖₖ). Interleaved in one
    /// pass they ran no faster (the `solve` benchmark's `chain_5_cached_refactored`).
    fn factor_and_forward(
        &mut self,
        rows: &Rows,
        settings: &Settings,
        from: usize,
        keep: bool,
        zero_forces: bool,
    ) -> bool {
        (from == rows.rows.len() || masses_sound(&rows.inverse_mass))
            && self.scale_and_assemble(rows, from, keep, !zero_forces)
            && self.factor_from(rows, settings.rank_tolerance, from, zero_forces)
    }

    /// Rows `from..` scaled and their entries of Ã assembled, their J's bits taken when
    /// `keep`; false
    /// when a row is not usable. The rows' c terms are known finite ([`servable`]) and every
    /// slot's 1/m finite and ≥ 0 ([`masses_sound`]), so what `solve::row_sound` would still
    /// check is that J is finite, which a scaled row's is: a component that is not makes
    /// ‖J‖ or Âₖₖ not finite, and `scale_row` refuses the row.
    fn scale_and_assemble(&mut self, rows: &Rows, from: usize, keep: bool, forces: bool) -> bool {
        let (w, applied) = (&rows.inverse_mass, &rows.force);
        let Chain { start, parts, partner, bits, norm, jacobi, a, external, .. } = self;
        for (q, row) in rows.rows.iter().enumerate().skip(from) {
            let (lo, hi) = (start[q], start[q + 1]);
            if keep {
                for ((_, bits), (_, j)) in bits[lo..hi].iter_mut().zip(&row.jacobian) {
                    *bits = j.map(f64::to_bits);
                }
            }
            let (before, mine) = parts[..hi].split_at_mut(lo);
            let Ok((n, d)) = normalise_row(row, w, mine) else {
                return false;
            };
            (norm[q], jacobi[q]) = (n, d);
            // J̃ = Ĵ/√Âₖₖ (`scale_row`'s last step), and at once Ãₖₖ and Ãₖ,ₖ₋₁ as
            // `assemble`'s terms sum them: slot by slot in increasing order, from +0 (the
            // band's zeros); the slots shared with the row before are this row's entries
            // with a partner, in the same increasing order. (Two sums side by side, each in
            // its order, in one walk of the row's entries rather than three.)
            // With `forces`, b̃'s sum Σᵢ J̃ᵢ·Fᵢ wᵢ beside them, from −0 as `solve::b_of`
            // sums it ([`factor_from`](Chain::factor_from) adds c̃).
            let (mut diagonal, mut below, mut applied_sum) = (0.0, 0.0, -0.0);
            for (&p, (s, u)) in partner[lo..hi].iter().zip(mine) {
                *u = u.map(|x| x * d);
                let w = w[*s];
                diagonal += dot(u, u) * w;
                if p != NONE {
                    below += dot(&before[p].1, u) * w;
                }
                if forces {
                    applied_sum += dot(u, &applied[*s]) * w;
                }
            }
            (a[2 * q], a[2 * q + 1]) = (below, diagonal);
            external[q] = applied_sum;
        }
        true
    }

    /// The factor's rows `from..` (`banded`'s tridiagonal factor, row by row) and every
    /// row's −b̃ and forward substitution, in one pass: two chains through the rows side by
    /// side, each row's entries of Ã and L walked beside it (no index, no bounds check).
    /// (One loop after the other ran the fresh solve of `chain_solve_2_library` 4 % slower:
    /// the two chains no longer overlap.)
    ///
    /// With `zero_forces` (every slot's F is ±0) b̃ = Σᵢ J̃ᵢ·Fᵢ wᵢ + c̃ is a sum of zeros
    /// (J̃ and w finite) plus c̃, which is c̃ itself when c̃ is not zero: then the sum is not
    /// taken, and where c̃ is zero it is, for the sign of the zero.
    fn factor_from(&mut self, rows: &Rows, floor: f64, from: usize, zero_forces: bool) -> bool {
        let k = rows.rows.len();
        let Chain { start, parts, norm, jacobi, a, l, inverse, rhs, y, external, .. } = self;
        let band = a[..2 * k].chunks_exact(2).zip(l[..2 * k].chunks_exact_mut(2)).zip(&mut inverse[..k]);
        let scaling = norm.iter().zip(jacobi.iter());
        let each = rows.rows.iter().zip(start.windows(2)).zip(scaling).zip(rhs.iter_mut().zip(y.iter_mut()));
        // Lₖ₋₁,ₖ₋₁ and the forward substitution's yₖ₋₁.
        let (mut above, mut previous) = (1.0, 0.0);
        for (q, ((((row, bounds), (&norm, &jacobi)), (rhs, y)), ((a, l), inverse))) in each.zip(band).enumerate() {
            if q >= from {
                let (l_below, Some(l_diagonal)) = tridiagonal_factor_row(a[0], a[1], above, q > 0, floor) else {
                    return false;
                };
                (l[0], l[1]) = (l_below, l_diagonal);
                *inverse = 1.0 / l_diagonal;
            }
            above = l[1];
            // c̃ as `b_of` adds it (the same division, which `b_of` then shares).
            let c = (row.bias / norm) * jacobi;
            let b = if zero_forces && c != 0.0 {
                -c
            } else if q >= from && !zero_forces {
                // Σᵢ J̃ᵢ·Fᵢ wᵢ from the scaling's pass, then `b_of`'s sum.
                -(external[q] + c)
            } else {
                -b_of(rows, &parts[bounds[0]..bounds[1]], row.bias, norm, jacobi)
            };
            *rhs = b;
            previous = forward_step(l[0], *inverse, q > 0, b, previous);
            *y = previous;
        }
        true
    }

    /// The backward substitution, then one step of iterative refinement, y += Ã⁻¹ (−b̃ − Ã y),
    /// as `solve::BandFactor::solve_into` takes it, when the residual asks for it
    /// ([`REFINE_BOUND`]), in up to three passes: the backward substitution with the residual
    /// of each row once y is known on and around it (rows below it are final by then), and
    /// with it ‖r‖₁, ‖y‖₁ and ‖b̃‖₁; then, only when the test fails, the residual's forward
    /// substitution and its backward substitution adding each correction to y. The same
    /// operations as one pass each (`banded`'s `backward_step`, `forward_step` and
    /// `tridiagonal_mul_row`), each pass over slices of k rows (no bounds check left): the
    /// residual of row i + 1 is computed once yᵢ is ([`residual`]), with yᵢ₊₁ and
    /// Ãᵢ₊₂,ᵢ₊₁ yᵢ₊₂ kept in registers. Whether every μ is finite: by the norms when the
    /// refinement is not taken (a finite ‖y‖₁ has every yᵢ finite), else tested by bits as
    /// each is written ([`not_finite_bit`]: no pass of its own).
    fn substitute(&mut self) -> bool {
        let Chain { a, l, inverse, rhs, y, r, refined, .. } = self;
        let k = y.len();
        let (a, l) = (a[..2 * k].as_chunks::<2>().0, l[..2 * k].as_chunks::<2>().0);
        let (inverse, rhs, r, y) = (&inverse[..k], &rhs[..k], &mut r[..k], &mut y[..k]);
        // yᵢ₊₁ and Ãᵢ₊₁,ᵢ yᵢ₊₁ (row i's `above`; +0 at the last row) while row i is substituted.
        let (mut y_up, mut above) = (0.0, 0.0);
        let mut next = 0.0;
        // ‖r‖₁, ‖y‖₁ and ‖b̃‖₁, three sums beside the substitution's chain (a NaN or an
        // infinity stays in its sum, which the test then fails).
        let (mut r_norm, mut y_norm, mut b_norm) = (0.0f64, 0.0f64, 0.0f64);
        for i in (0..k).rev() {
            let v;
            (v, next) = backward_step(l[i][0], inverse[i], i > 0, y[i], next);
            y[i] = v;
            y_norm += v.abs();
            b_norm += rhs[i].abs();
            if i + 1 < k {
                let j = i + 1;
                r[j] = residual(rhs[j], 0.0 + a[j][0] * v, a[j][1], y_up, above);
                r_norm += r[j].abs();
                above = a[j][0] * y_up;
            }
            y_up = v;
        }
        if k > 0 {
            r[0] = residual(rhs[0], 0.0, a[0][1], y_up, above);
            r_norm += r[0].abs();
        }
        // ‖Ã‖₁ ≤ 3 (below): the bound's scale, finite only when every yᵢ and b̃ᵢ is.
        let scale = 3.0 * y_norm + b_norm;
        *refined = !(r_norm <= REFINE_BOUND * scale && scale < f64::INFINITY);
        if !*refined {
            return true;
        }
        let mut previous = 0.0;
        for i in 0..k {
            previous = forward_step(l[i][0], inverse[i], i > 0, r[i], previous);
            r[i] = previous;
        }
        let mut next = 0.0;
        let mut bad = 0;
        for i in (0..k).rev() {
            let v;
            (v, next) = backward_step(l[i][0], inverse[i], i > 0, r[i], next);
            y[i] += v;
            bad |= not_finite_bit(y[i]);
        }
        bad >> 63 == 0
    }

    /// [`Block::columns`](super::solve) of the kept scaled rows: the velocity components
    /// with a non-zero part of J̃ and a non-zero inverse mass. A slot has one entry or two
    /// (`first`, `second`), so the count is, slot by slot, the components of the union of
    /// their masks: one mask per entry, no scatter into a mask per slot.
    fn columns(&self, rows: &Rows) -> usize {
        // How many bits of a three-bit mask are set.
        const ONES: [usize; 8] = [0, 1, 1, 2, 1, 2, 2, 3];
        // The components of an entry's J̃ that are not ±0 (by bits, without a branch), as bits.
        let mask = |entry: usize| {
            let j = self.parts[entry].1.map(|x| usize::from(x.to_bits() << 1 != 0));
            j[0] | (j[1] << 1) | (j[2] << 2)
        };
        let mut count = 0;
        for ((&first, &second), &w) in self.first.iter().zip(&self.second).zip(&rows.inverse_mass) {
            if first != NONE && w != 0.0 {
                count += ONES[mask(first) | if second != NONE { mask(second) } else { 0 }];
            }
        }
        count
    }

    /// λ, the forces and the accelerations from μ = `y`, as `solve::finish_into` makes them
    /// when every row takes part: λₖ = (μₖ/√Âₖₖ)/‖Jₖ‖ with a diagnostic where it leaves the
    /// normal range, the forces Σₖ μₖ J̃ₖᵢ, (Fᵢ + fᵢ) wᵢ. A step (`Answer::Step`) takes the
    /// forces and accelerations alone: no λ (a division a row), active set or contact states.
    ///
    /// The forces are summed slot by slot, not row by row into zeroed slots: a slot's force
    /// is +0 plus its first row's μJ̃ plus, where a second row acts on it, that row's — the
    /// same two additions in the same order as `solve::add_row_force` row after row (each
    /// row acts on a slot once, and the rows that do are consecutive) — and its
    /// acceleration follows at once, as `solve::accelerations_into` takes it.
    fn finish(&self, rows: &Rows, out: &mut Solution, answer: Answer) {
        let k = rows.rows.len();
        let mut diagnostics = std::mem::take(&mut out.diagnostics);
        diagnostics.clear();
        emptied(&mut out.lambda, 0);
        emptied(&mut out.active, 0);
        emptied(&mut out.contacts, 0);
        if answer == Answer::Solution {
            // Written once each (extended, not zeroed first).
            emptied(&mut out.lambda, k);
            emptied(&mut out.active, k);
            emptied(&mut out.contacts, k);
            let scaling = self.jacobi.iter().zip(&self.norm);
            out.lambda.extend(self.y[..k].iter().zip(scaling).enumerate().map(|(q, (&m, (&jacobi, &norm)))| {
                let l = (m * jacobi) / norm;
                out_of_range(q, m, l, &mut diagnostics);
                l
            }));
            out.active.extend(std::iter::repeat_n(true, k));
            out.contacts.extend(std::iter::repeat_n(None, k));
        }
        let slots = rows.inverse_mass.len();
        let n = rows.force.len().min(slots);
        let (force, acceleration) = (&mut out.constraint_force, &mut out.acceleration);
        // μₖ J̃ₖᵢ of row k's entry, added to `f`.
        let add = |f: [f64; 3], k: usize, entry: usize| {
            let (m, j) = (self.y[k], &self.parts[entry].1);
            [f[0] + m * j[0], f[1] + m * j[1], f[2] + m * j[2]]
        };
        // Slot i's force from its first and second entries.
        let slot_force = |(&first, &second): (&usize, &usize)| {
            let mut f = [0.0; 3];
            if first != NONE {
                let k = self.owner[first];
                f = add(f, k, first);
                // The second entry on a slot is of the row after the first's.
                if second != NONE {
                    f = add(f, k + 1, second);
                }
            }
            f
        };
        // (Fᵢ + fᵢ) wᵢ.
        let accelerate = |f: [f64; 3], applied: [f64; 3], w: f64| {
            [(applied[0] + f[0]) * w, (applied[1] + f[1]) * w, (applied[2] + f[2]) * w]
        };
        // The slots with an applied force (all of them but in a malformed `Rows`) as slices
        // of n: their accelerations are written without a bounds check.
        let (applied, w) = (&rows.force[..n], &rows.inverse_mass[..n]);
        let pairs = self.first.iter().zip(&self.second);
        if force.len() == slots && acceleration.len() == n {
            // The answer of the last solve of these slots (a run's cache): in place, each
            // slot's force and acceleration at once.
            let acceleration = &mut acceleration[..n];
            for (i, (f_out, pair)) in force.iter_mut().zip(pairs).enumerate() {
                let f = slot_force(pair);
                *f_out = f;
                if i < n {
                    acceleration[i] = accelerate(f, applied[i], w[i]);
                }
            }
        } else {
            // A new answer: each vector written once, in a pass of its own, rather than
            // zeroed and then written (the zeroing cost as much as the accelerations).
            emptied(force, slots);
            force.extend(pairs.map(slot_force));
            // (A no-op: the pattern has a first and a second entry per slot.)
            force.resize(slots, [0.0; 3]);
            emptied(acceleration, n);
            let each = force[..n].iter().zip(applied).zip(w);
            acceleration.extend(each.map(|((&f, &applied), &w)| accelerate(f, applied, w)));
        }
        out.diagnostics = diagnostics;
        out.status = Status::Solved;
    }
}

#[cfg(test)]
mod tests {
    use super::{Chain, all_zero, masses_sound};
    use crate::numeric::rows::{Row, Rows};
    use crate::numeric::solve::{Settings, Solution, solve_general};

    /// A zigzag chain of `n` unit masses in 2D, each row's c term `bias` (no velocities or
    /// forces: b̃ is c̃).
    fn zigzag(n: usize, bias: f64) -> Rows {
        let rows = (0..n)
            .map(|k| {
                let d = [1.0, if k % 2 == 0 { 0.3 } else { -0.2 }, 0.0];
                let jacobian = if k > 0 { vec![(k - 1, d.map(|x| -x)), (k, d)] } else { vec![(k, d)] };
                Row { value: 0.0, rate: 0.0, bias: bias * (1.0 + k as f64 / 7.0), inequality: false, jacobian }
            })
            .collect();
        Rows {
            dim: 2,
            inverse_mass: vec![1.0; n],
            velocity: vec![[0.0; 3]; n],
            force: vec![[0.0; 3]; n],
            rows,
            axes: Vec::new(),
        }
    }

    /// λ's bits.
    fn bits(s: &Solution) -> Vec<u64> {
        s.lambda.iter().map(|x| x.to_bits()).collect()
    }

    /// The step of refinement is taken exactly where the residual asks for it, and then
    /// gives the general solve's numbers: not on a chain of ordinary numbers; on the same
    /// chain with its forward solution spoiled in one row (a residual far above the bound),
    /// where the step brings y back to the unspoiled answer; and on a chain whose c terms
    /// (so b̃ and λ) are subnormal, where rounding is not relative and the bound underflows,
    /// solved as the general solve solves it, bit for bit.
    #[test]
    fn the_refinement_is_taken_where_the_residual_asks_for_it() {
        let settings = Settings::default();
        let rows = zigzag(12, 0.7);
        let mut chain = Chain::default();
        let mut out = Solution::default();
        assert!(chain.solve_fresh(&rows, &settings, &mut out).is_some());
        assert!(!chain.refined, "ordinary numbers: no step");
        let plain = chain.y.clone();
        // The forward substitution again, one row of it spoiled, then the substitution.
        assert!(chain.factor_and_forward(&rows, &settings, 0, false, false));
        chain.y[5] *= 1.0 + 1e-6;
        assert!(chain.substitute());
        assert!(chain.refined, "a spoiled solution's residual asks for the step");
        let size = plain.iter().fold(0.0f64, |m, y| m.max(y.abs()));
        for (got, want) in chain.y.iter().zip(&plain) {
            // One step takes a 1e-6 error to about 1e-6 · κ u below the rounding of the
            // answer (κ of a few here): what is left is that rounding.
            assert!((got - want).abs() <= 1e-14 * size, "{got:e} against {want:e}");
        }
        let tiny = zigzag(12, 3e-318);
        let mut chain = Chain::default();
        let mut out = Solution::default();
        assert!(chain.solve_fresh(&tiny, &settings, &mut out).is_some());
        assert!(chain.refined, "subnormal numbers: the step");
        assert_eq!(bits(&out), bits(&solve_general(&tiny, &settings, &[])));
    }

    /// [`masses_sound`]'s and [`all_zero`]'s bit tests answer as `w >= 0.0 && w.is_finite()`
    /// and `x == 0.0` number by number, on every kind of number:
    /// zeros, subnormals, the largest, infinities and NaNs of either sign and other payloads.
    #[test]
    fn the_bit_tests_are_the_tests_number_by_number() {
        let special = crate::numeric::vector::SPECIAL_NUMBERS;
        for &a in &special {
            for &b in &special {
                let xs = [1.0, a, b, 2.0];
                let sound = xs.iter().all(|w| *w >= 0.0 && w.is_finite());
                assert_eq!(masses_sound(&xs), sound, "{a:e} {b:e}");
                assert_eq!(all_zero(&[a, b]), a == 0.0 && b == 0.0, "{a:e} {b:e}");
            }
        }
    }
}
