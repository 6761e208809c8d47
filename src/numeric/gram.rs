//! The minimum-norm λ of a block that is singular whatever its numbers (more rows than the
//! velocity components they move, a rigid joint grid's redundant loops), solved in the
//! bodies' velocity space instead of the rows' space.
//!
//! Design note. With the rows scaled (`numeric::solve`: J̃, Ã = J̃ M⁻¹ J̃ᵀ with a unit
//! diagonal) and the weights Ŵ that make the least ‖Ŵ μ‖ the least ‖λ‖ for C/κ, the
//! minimum-norm μ of Ã μ = r is μ = Ŵ⁻¹ ν with ν the least-norm solution of B ν = c,
//! B = G Gᵀ, c = Ŵ⁻¹ r, for G = Ŵ⁻¹ J̃ M^{-1/2} (rows × moved velocity components). When G
//! has full column rank (every body held: rank Ã equals the number of components), its
//! Gram matrix H = Gᵀ G is positive definite, of the size of the velocity space, and
//! B⁺ = G H⁻² Gᵀ (the pseudo-inverse of G Gᵀ through G's own; Golub and Van Loan, *Matrix
//! Computations*, §5.5). So
//!
//!   x = H⁻¹ Gᵀ c   (the velocity change, in M^{1/2} units: unique),
//!   z = H⁻¹ x,     ν = G z   (the least-norm split of its impulse among the rows),
//!
//! two substitutions with one sparse factor of H (columns scaled to a unit diagonal, so the
//! rank tolerance is relative) and no regularisation: every iterate μ = Ŵ⁻¹ G (…) lies in
//! the subspace where the minimum norm lies, whatever the accuracy of the factor, so the
//! split among redundant rows is the minimum-norm one to rounding (the regularised factor of
//! `solve::sparse_minimum_norm` carries ε's share into it), and a factor made for another J
//! of the same pattern still iterates to this J's answer where it is close enough (the
//! run's solve cache keeps a stale factor that way). H's pattern is the bodies' adjacency
//! (a grid's five-point stencil of 3 × 3 blocks), narrower than Ã's (every pair of rows
//! sharing a body). Iterative refinement against Ã itself (computed as Ŵ G Gᵀ Ŵ μ, no Ã
//! assembled) polishes the answer and checks consistency, as the regularised iteration does.
//! When G lacks full column rank (a pendulum hanging from a redundant grid, a constraint
//! written twice on point masses) a pivot of H falls to the rank tolerance and the caller
//! takes the regularised factor instead.
//!
//! A caller that needs the velocity change alone (the exact velocity step's velocity solves
//! and projections: `BodySpace::velocity_change`) needs neither ẑ nor the second
//! substitution: x = H⁻¹ Gᵀ c is M^{1/2} Δu, and since G has full column rank Δu is the one
//! vector with J Δu = the rows' target, whatever the split among redundant rows. So it
//! iterates Δu against the rows' own residual, each application one substitution; the
//! factor, the scaling and G then only precondition, and a stale set of them (a nearby J's,
//! not even refilled) still converges to this J's Δu.
//!
//! Not here: which blocks are singular whatever their numbers, diagnostics, the cache
//! (`numeric::solve`).

use super::sparse::{SparseFactor, SparseWork};

/// A component of a row's part is stored in G when its slot moves (inverse mass not zero)
/// and some row of the block has that axis non-zero: the moved components, G's columns.
/// Rows' explicit zeros on a moved component are kept, so G's pattern (and H's) does not
/// change with the numbers of a row whose component passes through zero.
#[derive(Clone, Debug)]
pub(crate) struct Gram {
    /// moved[slot]: one bit per axis that is a column.
    moved: Vec<u8>,
    /// The number of columns.
    columns: usize,
    /// Row p's entries are `start[p]..start[p + 1]` of the vectors below.
    start: Vec<usize>,
    /// Each entry's column (32 bits: the products stream it beside G's values). Numbered slot
    /// by slot, axis by axis, until [`relabel`](Gram::relabel) puts them in a factor's order.
    column: Vec<u32>,
    /// Each entry's source: the place of its part in the scaled rows' buffer, and the axis.
    source: Vec<(usize, usize)>,
    /// G's entries times the column scale s (so G'ᵀ G' has a unit diagonal).
    g: Vec<f64>,
    /// Ŵ per row (relative weights, or ones when their range is too wide).
    weight: Vec<f64>,
    /// s² per column: 1/Hₐₐ.
    scale2: Vec<f64>,
    /// A buffer of [`fill`](Gram::fill): √(1/m) per slot, then s per column (what
    /// [`BodySpace::velocity_change`] reads).
    root: Vec<f64>,
    /// position[old] = the column numbered `old` slot by slot, axis by axis, in the
    /// factor's order once [`relabel`](Gram::relabel) has put them there.
    position: Vec<u32>,
}

/// The moved axes of every slot: `parts` are the scaled rows' parts (slot, J̃ᵢ) of the
/// block's rows, given as ranges of `parts`.
fn moved_axes(parts: &[(usize, [f64; 3])], rows: &[std::ops::Range<usize>], inverse_mass: &[f64]) -> Vec<u8> {
    let mut moved = vec![0u8; inverse_mass.len()];
    for range in rows {
        for (b, j) in &parts[range.clone()] {
            if inverse_mass[*b] != 0.0 {
                moved[*b] |= nonzero_axes(j);
            }
        }
    }
    moved
}

/// One bit per axis of `j` that is not zero.
fn nonzero_axes(j: &[f64; 3]) -> u8 {
    u8::from(j[0] != 0.0) | (u8::from(j[1] != 0.0) << 1) | (u8::from(j[2] != 0.0) << 2)
}

impl Gram {
    /// G of the block rows whose parts are `parts[rows[p]]` (places in the scaled rows'
    /// buffer), with the slots' `inverse_mass` and the rows' weights λₖ/λ̃ₖ; `None` when a
    /// column's scale is not a normal number or a weight is not finite.
    pub(crate) fn new(
        parts: &[(usize, [f64; 3])],
        rows: &[std::ops::Range<usize>],
        inverse_mass: &[f64],
        weight: &[f64],
        weight_range: f64,
    ) -> Option<Gram> {
        let moved = moved_axes(parts, rows, inverse_mass);
        // Columns numbered slot by slot, axis by axis.
        let mut first = Vec::with_capacity(moved.len());
        let mut columns = 0;
        for m in &moved {
            first.push(columns);
            columns += m.count_ones() as usize;
        }
        let mut start = Vec::with_capacity(rows.len() + 1);
        let (mut column, mut source) = (Vec::<u32>::new(), Vec::new());
        // Columns are numbered in 32 bits.
        u32::try_from(columns).ok()?;
        for range in rows {
            start.push(column.len());
            for (place, (b, _)) in range.clone().zip(&parts[range.clone()]) {
                let bits = moved[*b];
                if inverse_mass[*b] == 0.0 {
                    continue;
                }
                let mut at = first[*b];
                for axis in 0..3 {
                    if bits & (1 << axis) != 0 {
                        column.push(at as u32);
                        source.push((place, axis));
                        at += 1;
                    }
                }
            }
        }
        start.push(column.len());
        let mut gram = Gram {
            moved,
            columns,
            start,
            g: vec![0.0; column.len()],
            column,
            source,
            weight: Vec::new(),
            scale2: Vec::new(),
            root: Vec::new(),
            position: (0..columns as u32).collect(),
        };
        gram.fill(parts, inverse_mass, weight, weight_range).then_some(gram)
    }

    /// The number of rows.
    pub(crate) fn rows(&self) -> usize {
        self.start.len() - 1
    }

    /// Whether the rows `rows` of `parts` move no component that is not one of G's columns
    /// (without allocating: this runs at every substep of a run). With [`fill`](Gram::fill)
    /// it says whether they move the same components as those G was made from: a column
    /// that no row moves any more (its components zero, or its slot's inverse mass) leaves a
    /// zero diagonal in H, which `fill` refuses.
    pub(crate) fn same_columns(
        &self,
        parts: &[(usize, [f64; 3])],
        rows: &[std::ops::Range<usize>],
        inverse_mass: &[f64],
    ) -> bool {
        inverse_mass.len() == self.moved.len()
            && rows.iter().all(|range| {
                parts[range.clone()]
                    .iter()
                    .all(|(b, j)| inverse_mass[*b] == 0.0 || nonzero_axes(j) & !self.moved[*b] == 0)
            })
    }

    /// G's values from the rows' parts at the kept places (the same pattern), the masses and
    /// weights; false when a column's scale is not a normal number or a weight not finite.
    pub(crate) fn fill(
        &mut self,
        parts: &[(usize, [f64; 3])],
        inverse_mass: &[f64],
        weight: &[f64],
        weight_range: f64,
    ) -> bool {
        let n = self.rows();
        // Ŵ as `solve::Regularised` weighs the rows: relative to the largest, ones when
        // their range leaves what ε·Ŵ² would see (kept here for the same minimum).
        let top = weight.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        let relative = |p: usize| weight[p] / top;
        let weighted = weight.len() == n && (0..n).all(|p| relative(p).is_finite() && relative(p) >= weight_range);
        self.weight.clear();
        self.weight.extend((0..n).map(|p| if weighted { relative(p) } else { 1.0 }));
        // √(1/m) per slot once, 1/Ŵ per row once: the loop over the entries multiplies only.
        let mut root = std::mem::take(&mut self.root);
        root.clear();
        root.extend(inverse_mass.iter().map(|w| w.sqrt()));
        let mut diagonal = std::mem::take(&mut self.scale2);
        diagonal.clear();
        diagonal.resize(self.columns, 0.0);
        for p in 0..n {
            let inverse = 1.0 / self.weight[p];
            let (from, to) = (self.start[p], self.start[p + 1]);
            for ((g, &(place, axis)), &c) in
                self.g[from..to].iter_mut().zip(&self.source[from..to]).zip(&self.column[from..to])
            {
                let (slot, j) = &parts[place];
                *g = j[axis] * root[*slot] * inverse;
                diagonal[c as usize] += *g * *g;
            }
        }
        // s = 1/√Hₐₐ into `root` (now per column), s² = 1/Hₐₐ kept.
        root.clear();
        root.extend(diagonal.iter().map(|d| 1.0 / d.sqrt()));
        for d in diagonal.iter_mut() {
            *d = 1.0 / *d;
        }
        self.scale2 = diagonal;
        let mut finite = self.scale2.iter().all(|s| s.is_normal());
        for (g, &c) in self.g.iter_mut().zip(&self.column) {
            *g *= root[c as usize];
            finite &= g.is_finite();
        }
        self.root = root;
        finite
    }

    /// Numbers the columns in `order` (`order[new] = old`, a factor's fill-reducing order of
    /// H), so that G'ᵀ x comes out in the order the factor's substitutions take and G' x
    /// reads it there: only where each column's numbers are kept changes, each product and
    /// each sum is the same.
    fn relabel(&mut self, order: &[usize]) {
        let mut new = vec![0u32; order.len()];
        for (n, &old) in order.iter().enumerate() {
            new[old] = n as u32;
        }
        for c in &mut self.column {
            *c = new[*c as usize];
        }
        self.scale2 = order.iter().map(|&old| self.scale2[old]).collect();
        self.root = order.iter().map(|&old| self.root[old]).collect();
        self.position = new;
    }

    /// The pairs of columns whose products H sums, in the order [`assemble`](Gram::assemble)
    /// sums them: row by row, each pair of its entries once.
    fn pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        (0..self.rows()).flat_map(move |p| {
            let (from, to) = (self.start[p], self.start[p + 1]);
            (from..to).flat_map(move |e| (e..to).map(move |f| (self.column[e] as usize, self.column[f] as usize)))
        })
    }

    /// H' = G'ᵀ G' (unit diagonal) into `values` at `targets` (from
    /// [`pairs`](Gram::pairs)'s analysis).
    fn assemble(&self, values: &mut [f64], targets: &[usize]) {
        values.fill(0.0);
        let mut t = 0;
        for p in 0..self.rows() {
            let (from, to) = (self.start[p], self.start[p + 1]);
            for e in from..to {
                let ge = self.g[e];
                for f in e..to {
                    // Two entries of a row on one component: their cross term twice.
                    let twice = if e != f && self.column[e] == self.column[f] { 2.0 } else { 1.0 };
                    values[targets[t]] += twice * ge * self.g[f];
                    t += 1;
                }
            }
        }
    }

    /// y = G'ᵀ x (columns from rows).
    fn transpose_mul(&self, x: &[f64], y: &mut Vec<f64>) {
        self.transpose_mul_by(|p| x[p], y);
    }

    /// y = G'ᵀ x with xₚ = `x(p)`, computed where the product needs it (a caller's row
    /// weights in the same pass: the same numbers as a vector of them first).
    #[inline(always)]
    fn transpose_mul_by(&self, x: impl Fn(usize) -> f64, y: &mut Vec<f64>) {
        y.clear();
        y.resize(self.columns, 0.0);
        for (p, ends) in self.start.windows(2).enumerate() {
            let xp = x(p);
            let (from, to) = (ends[0], ends[1]);
            for (&c, &g) in self.column[from..to].iter().zip(&self.g[from..to]) {
                y[c as usize] += g * xp;
            }
        }
    }

    /// y = G' x (rows from columns).
    fn mul(&self, x: &[f64], y: &mut Vec<f64>) {
        self.mul_then(x, y, |_, s| s);
    }

    /// yₚ = `then(p, (G' x)ₚ)`: [`mul`](Gram::mul) with each row's sum passed through
    /// `then` (a caller's row weights) in the same pass.
    #[inline(always)]
    fn mul_then(&self, x: &[f64], y: &mut Vec<f64>, then: impl Fn(usize, f64) -> f64) {
        y.clear();
        y.extend(self.start.windows(2).enumerate().map(|(p, ends)| {
            let (from, to) = (ends[0], ends[1]);
            let sum = self.g[from..to].iter().zip(&self.column[from..to]).map(|(g, &c)| g * x[c as usize]).sum::<f64>();
            then(p, sum)
        }));
    }
}

/// The factor of H' = G'ᵀ G' of a [`Gram`], and what its solves need.
#[derive(Clone, Debug)]
pub(crate) struct BodySpace {
    gram: Gram,
    factor: SparseFactor,
    /// For each pair of [`Gram::pairs`], the place in `factor` it is summed into.
    targets: Vec<usize>,
    /// The block rows with a visible part in the null space.
    null_rows: Vec<usize>,
    /// G's values the factor was made from (a stale factor serves while G stays near them).
    factored: Vec<f64>,
    /// ẑ of the last minimum norm (μ = Ŵ⁻¹ G' ẑ): a warm start for the next.
    last: Vec<f64>,
}

/// Buffers of [`BodySpace::minimum_norm`].
#[derive(Clone, Debug, Default)]
pub(crate) struct BodySpaceWork {
    residual: Vec<f64>,
    step: Vec<f64>,
    trial: Vec<f64>,
    ax: Vec<f64>,
    columns: Vec<f64>,
    /// ẑ of the last pseudo-inverse application.
    z: Vec<f64>,
    /// [`BodySpace::velocity_change`]'s trial Δu and its residual.
    velocity_trial: Vec<[f64; 3]>,
    residual_trial: Vec<f64>,
    sparse: SparseWork,
}

impl BodySpaceWork {
    /// The buffer of [`BodySpace::velocity_change`]'s residual, for a caller that takes the
    /// residual of its start itself (its `start`).
    pub(crate) fn residual_mut(&mut self) -> &mut Vec<f64> {
        &mut self.residual
    }
}

/// How a [`BodySpace::minimum_norm`] ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Iterated {
    /// The pseudo-inverse applications (two substitutions each).
    pub solves: usize,
    /// Whether the residual reached the rounding of its own evaluation.
    pub converged: bool,
    /// Whether the residual is within the consistency bound.
    pub consistent: bool,
}

/// Thresholds of [`BodySpace::minimum_norm`], from `numeric::solve`'s settings.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Bounds {
    /// The residual allowed beside the rounding, relative to max |rhs|.
    pub consistency: f64,
    /// The rounding allowed, in ulps of max |Ã|·max |μ| (Ã's diagonal is one).
    pub rounding: f64,
    /// The most pseudo-inverse applications.
    pub solves: usize,
}

/// The residual counts as at its rounding within this many ulps of max|μ| + max|rhs| (Ã's
/// entries are at most one): a row of a grid sums a dozen terms, each rounded once.
const CONVERGED_ULPS: f64 = 64.0;
/// A residual within this many ulps (of the same) is at its rounding however the iteration
/// ended: stopped improving there, or a warm start already there.
const ROUNDING_ULPS: f64 = 4.0 * CONVERGED_ULPS;

impl BodySpace {
    /// The factor of `gram`'s H'; `None` when a pivot falls to `pivot_floor` (G lacks full
    /// column rank: some body is not held, the rows' rank is below the components') or its
    /// pattern is refused.
    pub(crate) fn new(mut gram: Gram, pivot_floor: f64, null_share: f64) -> Option<BodySpace> {
        let (factor, targets) = SparseFactor::analyse(gram.columns, gram.pairs())?;
        // From here G's columns are in the factor's order (`assemble` reads only which
        // entries share a column, and `targets`): no permutation around the substitutions.
        gram.relabel(factor.order());
        let mut body =
            BodySpace { gram, factor, targets, null_rows: Vec::new(), factored: Vec::new(), last: Vec::new() };
        body.refactor(pivot_floor, null_share).then_some(body)
    }

    /// The factor's flops (for the caller's cost bounds).
    pub(crate) fn flops(&self) -> f64 {
        self.factor.flops()
    }

    /// G, for refilling in place.
    pub(crate) fn gram_mut(&mut self) -> &mut Gram {
        &mut self.gram
    }

    /// The largest change of G' (unit columns) since the factor was made: a stale factor's
    /// relative error is about twice it, so each application of its pseudo-inverse shrinks
    /// the error by about that times H's condition.
    pub(crate) fn change(&self) -> f64 {
        self.gram.g.iter().zip(&self.factored).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
    }

    /// The block rows with a visible part in the null space (as of the last factorisation).
    pub(crate) fn null_rows(&self) -> &[usize] {
        &self.null_rows
    }

    /// H' from G's current values, factored, and the null space's rows found: false when a
    /// pivot falls to `pivot_floor`.
    pub(crate) fn refactor(&mut self, pivot_floor: f64, null_share: f64) -> bool {
        self.gram.assemble(self.factor.values_mut(), &self.targets);
        if !self.factor.factor(pivot_floor) {
            return false;
        }
        self.factored.clone_from(&self.gram.g);
        // A null vector of Ã in ν = Ŵ μ: y − G' H'⁻¹ G'ᵀ y (the projection onto null G'ᵀ)
        // from a fixed random y; rows with a visible part in it are the redundant ones.
        let n = self.gram.rows();
        let mut rng = super::random::Rng::new(0x5EED_F00D);
        let y: Vec<f64> = (0..n).map(|_| rng.normal()).collect();
        let (mut columns, mut back) = (Vec::new(), Vec::new());
        self.gram.transpose_mul(&y, &mut columns);
        self.factor.substitute_in_order(&mut columns, &mut SparseWork::default());
        self.gram.mul(&columns, &mut back);
        let null: Vec<f64> = y.iter().zip(&back).zip(&self.gram.weight).map(|((y, b), w)| (y - b) / w).collect();
        let peak = null.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        self.null_rows.clear();
        self.null_rows.extend((0..n).filter(|&p| null[p].abs() > null_share * peak));
        true
    }

    /// step = Ŵ⁻¹ G' H'⁻¹ S² H'⁻¹ G'ᵀ Ŵ⁻¹ r: the weighted pseudo-inverse of Ã applied to r
    /// (see the file's note; S² = 1/diag H undoes the column scaling between the solves),
    /// with ẑ = H'⁻¹ S² H'⁻¹ G'ᵀ Ŵ⁻¹ r left in `work.z` (the substitutions in place there, in
    /// the factor's order, which G's columns are in).
    fn pseudo_inverse(&self, r: &[f64], work: &mut BodySpaceWork) {
        let BodySpaceWork { step, z, sparse, .. } = work;
        let weight = &self.gram.weight;
        self.gram.transpose_mul_by(|p| r[p] / weight[p], z);
        self.factor.substitute_in_order(z, sparse);
        for (x, s) in z.iter_mut().zip(&self.gram.scale2) {
            *x *= s;
        }
        self.factor.substitute_in_order(z, sparse);
        self.gram.mul_then(z, step, |p, x| x / weight[p]);
    }

    /// ax = Ã x = Ŵ G' S⁻² G'ᵀ Ŵ x.
    fn a_mul(&self, x: &[f64], ax: &mut Vec<f64>, columns: &mut Vec<f64>) {
        let weight = &self.gram.weight;
        self.gram.transpose_mul_by(|p| x[p] * weight[p], columns);
        for (x, s) in columns.iter_mut().zip(&self.gram.scale2) {
            *x /= s;
        }
        self.gram.mul_then(columns, ax, |p, x| x * weight[p]);
    }

    /// The minimum-norm μ of Ã μ = `rhs` into `mu`: μ₀ = 0, μₖ₊₁ = μₖ + Ã⁺(rhs − Ã μₖ) with
    /// the pseudo-inverse through the factor, until the residual is at its rounding, stops
    /// halving, or `bounds.solves` are spent; with how it ended. With the factor of this
    /// G one application lands within rounding times H's condition, the next at rounding;
    /// with a factor of a nearby G (stale) each application shrinks the error by about
    /// the factor's relative error times that condition. `warm`: start from μ₀ = Ŵ⁻¹ G' ẑ
    /// with the ẑ of the last call instead of 0 (in the subspace of this G's minimum norm
    /// whatever ẑ is, so the limit is the same; a grid at rest starts at its answer).
    pub(crate) fn minimum_norm(
        &mut self,
        rhs: &[f64],
        bounds: &Bounds,
        work: &mut BodySpaceWork,
        mu: &mut Vec<f64>,
        warm: bool,
    ) -> Iterated {
        let n = self.gram.rows();
        let mut residual = std::mem::take(&mut work.residual);
        let mut z = std::mem::take(&mut self.last);
        let size = rhs.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let mut left = f64::INFINITY;
        if warm && z.len() == self.gram.columns {
            let BodySpaceWork { ax, columns, .. } = work;
            let weight = &self.gram.weight;
            self.gram.mul_then(&z, mu, |p, x| x / weight[p]);
            self.a_mul(mu, ax, columns);
            left = rhs.iter().zip(ax.iter()).fold(0.0f64, |m, (r, a)| m.max((r - a).abs()));
            residual.clear();
            residual.extend(rhs.iter().zip(ax.iter()).map(|(r, a)| r - a));
        }
        if !(left.is_finite() && left <= size) {
            // Cold: μ₀ = 0.
            z.clear();
            z.resize(self.gram.columns, 0.0);
            mu.clear();
            mu.resize(n, 0.0);
            residual.clear();
            residual.extend_from_slice(rhs);
            left = size;
        }
        let top = mu.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        // A warm start within the bound the iteration stops at is an answer (cold: only when
        // the right-hand side is zero). Not within the looser bound it may end at: a grid at
        // rest starts a few hundred ulps off (its c terms move by rounding), and one more
        // application takes it to one or two.
        let (mut solves, mut converged) = (0, left <= CONVERGED_ULPS * f64::EPSILON * (top + size));
        while solves < bounds.solves && !converged {
            self.pseudo_inverse(&residual, work);
            let BodySpaceWork { step, trial, ax, columns, .. } = work;
            trial.clear();
            trial.extend(mu.iter().zip(step.iter()).map(|(m, s)| m + s));
            self.a_mul(trial, ax, columns);
            let now = rhs.iter().zip(ax.iter()).fold(0.0f64, |m, (r, a)| m.max((r - a).abs()));
            solves += 1;
            let accept = |z: &mut Vec<f64>, step: &[f64]| z.iter_mut().zip(step).for_each(|(z, s)| *z += s);
            if !now.is_finite() || now > 0.5 * left {
                // No longer halving: the last iterate is at its rounding (or this one worse).
                if now < left && now.is_finite() {
                    std::mem::swap(mu, trial);
                    accept(&mut z, &work.z);
                    left = now;
                }
                break;
            }
            std::mem::swap(mu, trial);
            accept(&mut z, &work.z);
            residual.clear();
            residual.extend(rhs.iter().zip(ax.iter()).map(|(r, a)| r - a));
            left = now;
            let top = mu.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            converged = left <= CONVERGED_ULPS * f64::EPSILON * (top + size);
        }
        work.residual = residual;
        self.last = z;
        let top = mu.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let rounding = bounds.rounding * f64::EPSILON * top;
        let consistent =
            (left <= bounds.consistency * size + rounding || size == 0.0) && mu.iter().all(|x| x.is_finite());
        // Stopped by no longer halving: at the rounding too when within a few times its bound.
        converged |= left <= ROUNDING_ULPS * f64::EPSILON * (top + size);
        Iterated { solves, converged, consistent }
    }

    /// The velocity change Δu of the minimum-norm μ of this block's rows (see the file's
    /// note), without μ, into `du`: the unique Δu on G's columns with J Δu = the rows'
    /// target, since G has full column rank. `residual(Δu, r)` writes the scaled rows'
    /// residual r = rhs − J̃ Δu (the minimum norm's rhs − Ã μ for the μ of that Δu) and
    /// returns max |rₚ| and the rounding scale of its products (max over the rows of
    /// Σ |J̃ₚᵢ Δuᵢ|); `size` is max |rhs|. The iteration Δu ← Δu + M^{-1/2} S H'⁻¹ G'ᵀ Ŵ⁻¹ r
    /// (one substitution an application: the minimum norm's two, with S² between, are for
    /// the split among redundant rows, which Δu does not depend on) runs until the residual
    /// is at the rounding of its own evaluation, stops halving, or `bounds.solves` are
    /// spent, held to the minimum norm's bounds (so rows that contradict each other are
    /// found as there). Its limit is Δu whatever the factor, G and scaling it steps with
    /// (a nearby J's, kept: they only precondition; each application then shrinks the error
    /// by about their relative error times H's condition), as long as the residual is the
    /// current rows'. It starts from `du` as given when that leaves a residual below `size`
    /// (a grid at rest: near its answer), else from 0; `start`, when given, is what
    /// `residual` would return for `du` as given, its residual already in
    /// [`BodySpaceWork::residual_mut`] (a caller that took it in a walk of its own).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn velocity_change(
        &self,
        size: f64,
        start: Option<(f64, f64)>,
        mut residual: impl FnMut(&[[f64; 3]], &mut Vec<f64>) -> (f64, f64),
        inverse_mass: &[f64],
        bounds: &Bounds,
        work: &mut BodySpaceWork,
        du: &mut Vec<[f64; 3]>,
    ) -> Iterated {
        let BodySpaceWork { residual: r, z: step, velocity_trial: trial, residual_trial, sparse, .. } = work;
        let (mut left, mut scale) = (f64::INFINITY, 0.0);
        if let Some(start) = start {
            (left, scale) = start;
        } else if du.len() == inverse_mass.len() {
            (left, scale) = residual(du, r);
        }
        if !(left.is_finite() && left <= size) {
            // Cold: Δu₀ = 0 (also when the last Δu is not finite).
            du.clear();
            du.resize(inverse_mass.len(), [0.0; 3]);
            (left, scale) = residual(du, r);
        }
        let at_rounding = |left: f64, scale: f64, ulps: f64| left <= ulps * f64::EPSILON * (scale + size);
        let (mut solves, mut converged) = (0, at_rounding(left, scale, CONVERGED_ULPS));
        while solves < bounds.solves && !converged {
            let weight = &self.gram.weight;
            self.gram.transpose_mul_by(|p| r[p] / weight[p], step);
            self.factor.substitute_in_order(step, sparse);
            trial.clone_from(du);
            self.add_velocity(step, inverse_mass, trial);
            let (now, now_scale) = residual(trial, residual_trial);
            solves += 1;
            let halved = now <= 0.5 * left;
            if now < left {
                std::mem::swap(du, trial);
                std::mem::swap(r, residual_trial);
                (left, scale) = (now, now_scale);
            }
            if !halved {
                // No longer halving: the last iterate is at its rounding (or this one worse).
                break;
            }
            converged = at_rounding(left, scale, CONVERGED_ULPS);
        }
        let consistent = (left <= bounds.consistency * size + bounds.rounding * f64::EPSILON * scale || size == 0.0)
            && du.iter().flatten().all(|x| x.is_finite());
        // Stopped by no longer halving: at the rounding too when within a few times its bound.
        converged |= at_rounding(left, scale, ROUNDING_ULPS);
        Iterated { solves, converged, consistent }
    }

    /// Adds M^{-1/2} S y (y in G's columns, the factor's order) to `du` slot by slot, with
    /// the slots' `inverse_mass`; the components that are no column of G get nothing.
    fn add_velocity(&self, y: &[f64], inverse_mass: &[f64], du: &mut [[f64; 3]]) {
        let gram = &self.gram;
        let mut old = 0;
        for ((bits, w), d) in gram.moved.iter().zip(inverse_mass).zip(du.iter_mut()) {
            if *bits == 0 {
                continue;
            }
            let root = w.sqrt();
            for (axis, d) in d.iter_mut().enumerate() {
                if bits & (1 << axis) != 0 {
                    let c = gram.position[old] as usize;
                    *d += root * gram.root[c] * y[c];
                    old += 1;
                }
            }
        }
    }
}
