//! How a generated module lays out a system: dense or banded A, on the stack or the heap,
//! dense J or its blocks, outputs in one function or in parts. Decided once, from the
//! derivation's sizes, before any text is written; every emitter (Rust, C) follows it.
//! How λ is found ([`Lambda`]: a guarded closed form, L D Lᵀ on A's band of the bandwidth
//! known here, or the rows' solve that honours inequalities and redundancy) is decided here
//! too.
//!
//! Big systems must not need a big stack (a 1000-link chain's dense J alone is 16 MB), and
//! code size should grow linearly with a chain's length. So A is a dense K×K array only up
//! to [`MAX_DENSE_A`] constraints; past that a banded A (a chain listed in order) is written
//! as its band, and an A that is not banded lives on the heap.
//! J is a dense array up to [`MAX_DENSE_J`] entries, past that the list of its non-zero
//! blocks. An output of more than [`MAX_PART`] formulas is filled by parts of at most that
//! many ([`parts`]). What stays on the stack is O(K + N).
//!
//! Not here: the text of any language (`codegen::rust`), the formulas themselves.

use std::ops::Range;

/// Most constraints for which A is written as a dense K×K array of formulas: 16² = 256
/// entries (2 KiB of stack). Past this, a banded A (a chain's) is written as its band only,
/// and a dense one as rows on the heap.
pub const MAX_DENSE_A: usize = 16;

/// Most entries (K · N · DIM) of a Jacobian written as a dense array: 4096 numbers, 32 KiB
/// of stack, a fraction of a thread's smallest default stack. Past this J is written as its
/// non-zero blocks `(constraint, body, direction)`, on the heap.
pub const MAX_DENSE_J: usize = 4096;

/// Most formulas an output computes in one function. An unoptimised build gives every value
/// of a function its own stack slot, so one function for a chain of thousands of links would
/// need megabytes of stack; 64 formulas keep a frame to a few KiB while a small system's
/// outputs stay one function each.
pub const MAX_PART: usize = 64;

/// Most fields of a `State` struct with one field per symbol. rustc's derives of
/// `PartialEq` and `Debug` recurse over the fields: a 2 000-link chain's 8 000 fields
/// overflow its stack, 1 700 links' compile; 1 024 keeps far from that edge while every
/// shipped scene keeps named fields. Past it the bodies' symbols (and 2D rigid bodies' θ, ω,
/// τ, I) live in role arrays.
pub const MAX_STATE_FIELDS: usize = 1024;

/// Most row kinds (distinct patterns of structural zeros over a row's entries) a step module
/// writes its rows' products for, each kind's code specialised to its pattern (`ROW_KIND`):
/// a scene of a few joint types has a handful (a pin's x and y rows, with two bodies or one);
/// each kind is one more copy of a row's Ċ and impulse in the sweep, so past 32 the other
/// rows read their masks from `ENTRY_MASK` as they run (the same operations, the same bits).
pub const MAX_ROW_KINDS: usize = 32;

/// How `State` holds the inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StateStorage {
    /// One field per symbol.
    Fields,
    /// Positions, velocities, forces and mass symbols as arrays indexed by body (or mass
    /// symbol), and 2D rigid bodies' θ, ω, τ and inertia symbols as arrays indexed by rigid
    /// body (or inertia symbol); time, parameters and 3D rigid bodies' q, ω, τ stay fields.
    /// Past [`MAX_STATE_FIELDS`] fields.
    Arrays,
}

/// How `State` holds `fields` inputs.
pub fn state_storage(fields: usize) -> StateStorage {
    if fields > MAX_STATE_FIELDS { StateStorage::Arrays } else { StateStorage::Fields }
}

/// How A is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AStorage {
    /// A K×K array on the stack (`a_matrix`), at most [`MAX_DENSE_A`] constraints.
    Dense,
    /// Its band (`a_band`, row k holding A[k][k..=k + bandwidth]), past [`MAX_DENSE_A`]
    /// constraints when A is banded.
    Band { bandwidth: usize },
    /// K rows on the heap (`a_matrix` as a `Vec`), past [`MAX_DENSE_A`] when not banded.
    Heap,
}

/// How J is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JStorage {
    /// A K × N·DIM array (`jacobian`), at most [`MAX_DENSE_J`] entries.
    Dense,
    /// Its non-zero blocks on the heap (`jacobian_blocks`), past [`MAX_DENSE_J`] entries.
    Blocks { count: usize },
}

/// How λ is found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lambda {
    /// One equality: λ and the forces are closed formulas, used where their numbers are in
    /// range (A normal, b finite); elsewhere the rows' solve ([`Lambda::Rows`]) answers.
    ClosedForm,
    /// Equalities only, A banded past [`MAX_DENSE_A`]: λ by L D Lᵀ on A's band
    /// ([`Layout::bandwidth`]: a tridiagonal A gets the tridiagonal solve), and the rows'
    /// solve where it gives up (A singular or its numbers out of range).
    Band,
    /// Equalities only, A dense (at most [`MAX_DENSE_A`] constraints): λ as for
    /// [`Lambda::Band`] (L D Lᵀ on A's band, of half-bandwidth up to K − 1), the forces by
    /// Cholesky on A λ = −b from one program of A, b, J (and Jʷ); the rows' solve where
    /// either gives up.
    Dense,
    /// The rows' solve of every other system: the scaled solve of `lagrange solve`, with
    /// inequality rows (λ ≥ 0, contact states) and the minimum-norm λ of a singular A.
    Rows,
}
/// The velocity-level step a module carries (`generate --solver`), and the helper files
/// it needs beside the rows' solve every module has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// Box2D v3's soft step: substeps, soft bias, warm start, relax, restitution.
    SoftStep,
    /// Sequential impulses with Baumgarte bias and accumulated clamping.
    Pgs,
    /// The exact velocity solve A P = −(J u + bias) per substep, then a projection.
    Exact,
}

impl Solver {
    /// The name `--solver` takes and the module's `SOLVER` says.
    pub fn name(self) -> &'static str {
        match self {
            Solver::SoftStep => "soft-step",
            Solver::Pgs => "pgs",
            Solver::Exact => "exact",
        }
    }

    /// Iterations per substep by default, as the library's solvers run them (Box2D v3: one;
    /// PGS without softness needs more to converge on a chain).
    pub fn default_iterations(self) -> usize {
        match self {
            Solver::SoftStep | Solver::Exact => 1,
            Solver::Pgs => 8,
        }
    }

    /// Whether the step runs the sequential-impulse sweep (warm start and `sweep`).
    pub fn sweeps(self) -> bool {
        matches!(self, Solver::SoftStep | Solver::Pgs)
    }
}

/// The layout of one module.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    pub dim: usize,
    pub bodies: usize,
    pub constraints: usize,
    pub a: AStorage,
    pub j: JStorage,
    pub lambda: Lambda,
    /// A's half-bandwidth: Aₖⱼ = 0 when |k − j| exceeds it (from the non-zero entries, so a
    /// chain listed in order has 1 whatever its storage). The λ solve is written for it.
    pub bandwidth: usize,
    /// Whether some output is filled by parts (said in the module's header).
    pub parted: bool,
    /// Whether A's band (K rows of `bandwidth` + 1 numbers) is mostly zeros
    /// ([`mostly_zero`]): `a_band` and `band_system` then write its formulas over a zeroed
    /// band.
    pub sparse_band: bool,
}

impl Layout {
    /// The layout for `constraints` constraints on `bodies` bodies in `dim` dimensions, with
    /// the non-zero entries `a` (upper triangle, `(k, j)`) and `blocks` non-zero blocks of J;
    /// `closed_form` when the derivation gives λ as a formula, `inequalities` when some row
    /// is `C ≥ 0`.
    pub fn of(
        dim: usize,
        bodies: usize,
        constraints: usize,
        a: &[(usize, usize)],
        blocks: usize,
        closed_form: bool,
        inequalities: bool,
    ) -> Layout {
        let k = constraints;
        let bandwidth = a.iter().map(|&(r, c)| r.abs_diff(c)).max().unwrap_or(0);
        // Banded: the band (w + 1 per row) is at most half of a row.
        let a_storage = if k <= MAX_DENSE_A {
            AStorage::Dense
        } else if 2 * (bandwidth + 1) <= k {
            AStorage::Band { bandwidth }
        } else {
            AStorage::Heap
        };
        let j = if k * bodies * dim > MAX_DENSE_J { JStorage::Blocks { count: blocks } } else { JStorage::Dense };
        let parted = k > MAX_PART
            || (k > MAX_DENSE_A && a.len() > MAX_PART)
            || (matches!(j, JStorage::Blocks { .. }) && blocks > MAX_PART);
        let lambda = match a_storage {
            _ if inequalities => Lambda::Rows,
            _ if closed_form => Lambda::ClosedForm,
            AStorage::Band { .. } => Lambda::Band,
            AStorage::Dense => Lambda::Dense,
            AStorage::Heap => Lambda::Rows,
        };
        let sparse_band = mostly_zero(k * (bandwidth + 1), a.len());
        Layout { dim, bodies, constraints, a: a_storage, j, lambda, bandwidth, parted, sparse_band }
    }
}

/// Whether a block of A (its band, or the whole matrix) of `numbers` numbers, `nonzero` of
/// them formulas, is mostly zeros: more than three in four. Its formulas are then written
/// one by one over a zeroed block rather than every number in place: a grid's band is such a
/// block (the 100 × 100 rigid grid's C file was 31 M lines of `= 0.0;` out of 33 M); a
/// chain's band, one zero in all, is written whole, and so is an array of zeros alone.
pub fn mostly_zero(numbers: usize, nonzero: usize) -> bool {
    nonzero > 0 && numbers.saturating_sub(nonzero) > 3 * nonzero
}

/// Whether an output of `formulas` formulas is filled by parts.
pub fn parted(formulas: usize) -> bool {
    formulas > MAX_PART
}

/// Consecutive items grouped into parts of at most [`MAX_PART`] formulas (an item of more
/// is a part alone): `sizes` gives each item's formula count, the result each part's items.
pub fn parts(sizes: impl IntoIterator<Item = usize>) -> Vec<Range<usize>> {
    let mut parts = Vec::new();
    let (mut lo, mut formulas, mut n) = (0, 0, 0);
    for (i, size) in sizes.into_iter().enumerate() {
        if i > lo && formulas + size > MAX_PART {
            parts.push(lo..i);
            (lo, formulas) = (i, 0);
        }
        formulas += size;
        n = i + 1;
    }
    parts.push(lo..n);
    parts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chain_is_banded_past_the_dense_limit_and_a_full_a_goes_to_the_heap() {
        let chain = |k: usize| (0..k).flat_map(|i| [(i, i), (i, (i + 1).min(k - 1))]).collect::<Vec<_>>();
        assert_eq!(Layout::of(2, 16, 16, &chain(16), 31, false, false).a, AStorage::Dense);
        assert_eq!(Layout::of(2, 17, 17, &chain(17), 33, false, false).a, AStorage::Band { bandwidth: 1 });
        let full: Vec<(usize, usize)> = (0..17).flat_map(|i| (i..17).map(move |j| (i, j))).collect();
        assert_eq!(Layout::of(2, 17, 17, &full, 17, false, false).a, AStorage::Heap);
        // The λ solve's bandwidth is A's, whatever its storage.
        assert_eq!(Layout::of(2, 10, 10, &chain(10), 19, false, false).bandwidth, 1);
        assert_eq!(Layout::of(2, 17, 17, &full, 17, false, false).bandwidth, 16);
    }

    #[test]
    fn inequalities_always_take_the_rows_solve() {
        let chain = |k: usize| (0..k).flat_map(|i| [(i, i), (i, (i + 1).min(k - 1))]).collect::<Vec<_>>();
        assert_eq!(Layout::of(2, 1, 1, &chain(1), 1, true, false).lambda, Lambda::ClosedForm);
        assert_eq!(Layout::of(2, 1, 1, &chain(1), 1, true, true).lambda, Lambda::Rows);
        assert_eq!(Layout::of(2, 17, 17, &chain(17), 33, false, false).lambda, Lambda::Band);
        assert_eq!(Layout::of(2, 17, 17, &chain(17), 33, false, true).lambda, Lambda::Rows);
        assert_eq!(Layout::of(2, 3, 3, &chain(3), 5, false, false).lambda, Lambda::Dense);
        assert_eq!(Layout::of(2, 3, 3, &chain(3), 5, false, true).lambda, Lambda::Rows);
        let full: Vec<(usize, usize)> = (0..17).flat_map(|i| (i..17).map(move |j| (i, j))).collect();
        assert_eq!(Layout::of(2, 17, 17, &full, 17, false, false).lambda, Lambda::Rows);
    }

    #[test]
    fn j_is_blocks_past_its_dense_limit() {
        assert_eq!(Layout::of(2, 32, 64, &[], 10, false, false).j, JStorage::Dense);
        assert_eq!(Layout::of(2, 33, 64, &[], 10, false, false).j, JStorage::Blocks { count: 10 });
    }

    #[test]
    #[allow(clippy::single_range_in_vec_init)] // one part, a range of items
    fn parts_hold_at_most_the_limit_unless_one_item_is_bigger() {
        assert_eq!(parts([1; 64]), vec![0..64]);
        assert_eq!(parts([1; 65]), [0..64, 64..65]);
        assert_eq!(parts([3; 43]), [0..21, 21..42, 42..43]);
        assert_eq!(parts([100, 1]), [0..1, 1..2]);
        assert_eq!(parts([]), vec![0..0]);
    }
}
