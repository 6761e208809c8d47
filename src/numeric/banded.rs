//! Symmetric banded matrices and their Cholesky factor: the linear-time λ solve of chains.
//!
//! A constraint couples to another only through a body they share, so the A of an N-link
//! chain (constraints numbered along the chain) is tridiagonal: bandwidth w = 1. Cholesky
//! of a band matrix keeps the band (no fill outside it), costing O(n w²) time and O(n w)
//! memory instead of O(n³) and O(n²) dense. Design note: the band covers chains, ropes and
//! stacks; grids and meshes, whose band grows with the scene's width, take the sparse
//! L D Lᵀ (`numeric::sparse`), small blocks dense Cholesky (`numeric::solve::plan` picks).
//!
//! Constraints numbered in another order (a shuffled chain, a tree) are renumbered by
//! reverse Cuthill–McKee (Cuthill & McKee 1969; George 1971), which recovers the band of a
//! chain exactly and keeps trees and meshes narrow.
//!
//! Not here: choosing between band, sparse and dense, rank-deficient systems (the caller falls back
//! to a dense SVD when [`Banded::cholesky`] reports a small pivot).

/// A symmetric n×n matrix with Aᵢⱼ = 0 for |i − j| > w, storing the lower band row by row.
#[derive(Clone, Debug, PartialEq)]
pub struct Banded {
    n: usize,
    w: usize,
    /// Row i holds Aᵢ,ᵢ₋w … Aᵢᵢ at `i*(w+1) ..`; entries left of column 0 stay zero.
    data: Vec<f64>,
}

/// The lower Cholesky factor L (A = L Lᵀ) of a [`Banded`] matrix, with the same band.
#[derive(Clone, Debug, PartialEq)]
pub struct BandedCholesky {
    n: usize,
    w: usize,
    l: Vec<f64>,
    /// A tridiagonal's 1/Lᵢᵢ per row (empty for other bandwidths): its substitutions
    /// multiply by them (see [`solve_in_place`](BandedCholesky::solve_in_place)).
    inverse: Vec<f64>,
}

impl Banded {
    /// The zero matrix of size `n` and bandwidth `w`.
    pub fn zeros(n: usize, w: usize) -> Banded {
        Banded { n, w, data: vec![0.0; n * (w + 1)] }
    }

    fn at(&self, i: usize, j: usize) -> usize {
        i * (self.w + 1) + self.w + j - i
    }

    /// Adds `x` to Aᵢⱼ (and so to Aⱼᵢ). Entries outside the band are ignored (debug assert).
    pub fn add(&mut self, i: usize, j: usize, x: f64) {
        let (i, j) = if i >= j { (i, j) } else { (j, i) };
        debug_assert!(i - j <= self.w, "entry ({i}, {j}) outside bandwidth {}", self.w);
        if i - j <= self.w {
            let at = self.at(i, j);
            self.data[at] += x;
        }
    }

    /// y = A x.
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        let (n, w) = (self.n, self.w);
        let (x, y) = (&x[..n], &mut y[..n]);
        if w == 1 {
            tridiagonal_mul(&self.data[..2 * n], x, y);
            return;
        }
        if w == 0 {
            // A diagonal (rows on disjoint bodies: a pendulum): the loop below's sums.
            for ((yi, xi), d) in y.iter_mut().zip(x).zip(&self.data[..n]) {
                *yi = 0.0 + (0.0 + d * xi);
            }
            return;
        }
        self.band_mul(x, y);
    }

    /// y = A x for any bandwidth (`x` and `y` of the matrix's size).
    fn band_mul(&self, x: &[f64], y: &mut [f64]) {
        let (n, w) = (self.n, self.w);
        y.fill(0.0);
        for i in 0..n {
            let lo = i.saturating_sub(w);
            // Row i's entries Aᵢⱼ for j in lo..i, then Aᵢᵢ.
            let row = &self.data[i * (w + 1) + w + lo - i..(i + 1) * (w + 1)];
            let (left, diagonal) = row.split_at(i - lo);
            let xi = x[i];
            let mut s = 0.0;
            for (a, (xj, yj)) in left.iter().zip(x[lo..i].iter().zip(&mut y[lo..i])) {
                s += a * xj;
                *yj += a * xi;
            }
            y[i] += s + diagonal[0] * xi;
        }
    }

    /// The Cholesky factor, or the first row whose pivot (Schur complement) falls to
    /// `pivot_floor` or below: the matrix is then singular or too close to it to trust.
    pub fn cholesky(&self, pivot_floor: f64) -> Result<BandedCholesky, usize> {
        let mut factor = BandedCholesky::empty();
        self.cholesky_into(pivot_floor, &mut factor).map(|()| factor)
    }

    /// [`cholesky`](Banded::cholesky) into `factor`, reusing its storage.
    pub fn cholesky_into(&self, pivot_floor: f64, factor: &mut BandedCholesky) -> Result<(), usize> {
        factor.n = self.n;
        factor.w = self.w;
        factor.l.clear();
        factor.l.resize(self.n * (self.w + 1), 0.0);
        factor.inverse.clear();
        match self.w {
            0 => self.diagonal_factor(pivot_floor, &mut factor.l),
            1 => {
                self.tridiagonal_factor(pivot_floor, &mut factor.l)?;
                // Off the factor's chain of square roots: n independent divisions.
                factor.inverse.resize(self.n, 0.0);
                for (i, r) in factor.inverse.iter_mut().enumerate() {
                    *r = 1.0 / factor.l[2 * i + 1];
                }
                Ok(())
            }
            _ => self.band_factor(pivot_floor, &mut factor.l),
        }
    }

    /// A diagonal's factor (rows on disjoint bodies: a pendulum) into `l` (of the band's
    /// size): Lᵢᵢ = √Aᵢᵢ, as the general loop takes it.
    fn diagonal_factor(&self, pivot_floor: f64, l: &mut [f64]) -> Result<(), usize> {
        for (i, (li, &s)) in l.iter_mut().zip(&self.data[..self.n]).enumerate() {
            if s.is_nan() || s <= pivot_floor {
                return Err(i);
            }
            *li = s.sqrt();
        }
        Ok(())
    }

    /// A tridiagonal's factor (chains) into `l` (zeroed, of the band's size): the general
    /// loop's sums in its order, without its inner loops. Row i's off-diagonal
    /// Lᵢ,ᵢ₋₁ = Aᵢ,ᵢ₋₁/Lᵢ₋₁,ᵢ₋₁ (nothing to subtract: the rows share no earlier column), then
    /// Lᵢᵢ = √(Aᵢᵢ − Lᵢ,ᵢ₋₁²).
    fn tridiagonal_factor(&self, pivot_floor: f64, l: &mut [f64]) -> Result<(), usize> {
        let n = self.n;
        let (a, l) = (&self.data[..2 * n], &mut l[..2 * n]);
        for i in 0..n {
            let above = if i > 0 { l[2 * i - 1] } else { 1.0 };
            let (below, diagonal) = tridiagonal_factor_row(a[2 * i], a[2 * i + 1], above, i > 0, pivot_floor);
            if i > 0 {
                l[2 * i] = below;
            }
            l[2 * i + 1] = diagonal.ok_or(i)?;
        }
        Ok(())
    }

    /// The factor of any bandwidth into `l` (zeroed, of the band's size).
    fn band_factor(&self, pivot_floor: f64, l: &mut [f64]) -> Result<(), usize> {
        let (n, w) = (self.n, self.w);
        for i in 0..n {
            let lo = i.saturating_sub(w);
            for j in lo..=i {
                // Lᵢⱼ = (Aᵢⱼ − Σₖ Lᵢₖ Lⱼₖ) / Lⱼⱼ over the k both rows' bands share.
                let mut s = self.data[i * (w + 1) + w + j - i];
                let from = lo.max(j.saturating_sub(w));
                let li = &l[i * (w + 1) + w + from - i..i * (w + 1) + w + j - i];
                let lj = &l[j * (w + 1) + w + from - j..j * (w + 1) + w];
                for (a, b) in li.iter().zip(lj) {
                    s -= a * b;
                }
                if i == j {
                    if s.is_nan() || s <= pivot_floor {
                        return Err(i);
                    }
                    l[i * (w + 1) + w] = s.sqrt();
                } else {
                    l[i * (w + 1) + w + j - i] = s / l[j * (w + 1) + w];
                }
            }
        }
        Ok(())
    }

    /// The matrix's size and bandwidth.
    pub fn shape(&self) -> (usize, usize) {
        (self.n, self.w)
    }

    /// The band's storage (row i: Aᵢ,ᵢ₋w … Aᵢᵢ at `i (w + 1) ..`), to be filled in place by
    /// a caller that knows where each entry goes ([`Banded::index`]).
    pub fn data_mut(&mut self) -> &mut [f64] {
        &mut self.data
    }

    /// Where Aᵢⱼ (i ≥ j, within the band) lives in [`data_mut`](Banded::data_mut).
    pub fn index(&self, i: usize, j: usize) -> usize {
        self.at(i, j)
    }
}

impl BandedCholesky {
    /// An empty factor, to be filled by [`Banded::cholesky_into`].
    pub fn empty() -> BandedCholesky {
        BandedCholesky { n: 0, w: 0, l: Vec::new(), inverse: Vec::new() }
    }

    /// Overwrites `x` (the right-hand side) with the solution of L Lᵀ y = x.
    pub fn solve_in_place(&self, x: &mut [f64]) {
        let (n, w) = (self.n, self.w);
        let x = &mut x[..n];
        if w == 1 {
            let (l, inverse) = (&self.l[..2 * n], &self.inverse[..n]);
            let mut previous = 0.0;
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = forward_row(l, inverse, i, *xi, previous);
                previous = *xi;
            }
            tridiagonal_backward(l, inverse, x);
            return;
        }
        if w == 0 {
            // A diagonal's factor: the general loop's two divisions, the first after
            // subtracting its empty sum (−0, which turns a −0 right-hand side into +0).
            for (xi, l) in x.iter_mut().zip(&self.l[..n]) {
                *xi = ((*xi - -0.0) / l) / l;
            }
            return;
        }
        self.band_solve(x);
    }

    /// [`solve_in_place`](BandedCholesky::solve_in_place) for any bandwidth (`x` of the
    /// factor's size).
    fn band_solve(&self, x: &mut [f64]) {
        let (n, w) = (self.n, self.w);
        let x = &mut x[..n];
        // Row i of L is `l[i (w + 1) ..][..w + 1]`, entry (i, k) at w + k − i: the same sums
        // in the same order as indexing (i, k), on slices the compiler can keep in registers.
        for i in 0..n {
            let lo = i.saturating_sub(w);
            let row = &self.l[i * (w + 1)..(i + 1) * (w + 1)];
            let s: f64 = row[w + lo - i..w].iter().zip(&x[lo..i]).map(|(l, xk)| l * xk).sum();
            x[i] = (x[i] - s) / row[w];
        }
        for i in (0..n).rev() {
            let row = &self.l[i * (w + 1)..(i + 1) * (w + 1)];
            x[i] /= row[w];
            let (xi, lo) = (x[i], i.saturating_sub(w));
            for (l, xk) in row[w + lo - i..w].iter().zip(&mut x[lo..i]) {
                *xk -= l * xi;
            }
        }
    }
}

/// Row i of a tridiagonal's factor (chains), from Aᵢ,ᵢ₋₁ (`below`, when `has_below`), Aᵢᵢ
/// and Lᵢ₋₁,ᵢ₋₁ (`above`): Lᵢ,ᵢ₋₁ = Aᵢ,ᵢ₋₁/Lᵢ₋₁,ᵢ₋₁ (nothing to subtract: the rows share no
/// earlier column), then Lᵢᵢ = √(Aᵢᵢ − Lᵢ,ᵢ₋₁²): the general loop's sums in its order, without
/// its inner loops. Lᵢᵢ is `None` when the pivot falls to `pivot_floor` or below (or is NaN).
/// The one form of these operations: [`Banded::cholesky_into`] and the chain solve
/// (`numeric::chain`) both run it.
#[inline]
pub(crate) fn tridiagonal_factor_row(
    below: f64,
    diagonal: f64,
    above: f64,
    has_below: bool,
    pivot_floor: f64,
) -> (f64, Option<f64>) {
    let mut s = diagonal;
    let mut l = 0.0;
    if has_below {
        l = below / above;
        s -= l * l;
    }
    if s.is_nan() || s <= pivot_floor {
        return (l, None);
    }
    (l, Some(s.sqrt()))
}

/// Row i of a tridiagonal factor's forward substitution (L y = x, `l` the factor's band as
/// [`BandedCholesky`] stores it, `inverse` its 1/Lᵢᵢ): yᵢ = (xᵢ − Lᵢ,ᵢ₋₁ yᵢ₋₁)/Lᵢᵢ from
/// yᵢ₋₁ = `previous`, multiplied by 1/Lᵢᵢ rather than divided by Lᵢᵢ. Every row waits on the
/// one before, so the loop runs at the latency of its chain: a multiplication is a third of
/// a division's (within an ulp of it; the refinement that follows every solve takes up the
/// difference). The sum starts from −0 as the general loop's `sum()` does (so x − s turns a
/// −0 right-hand side into +0, as it always did).
#[inline]
pub(crate) fn forward_row(l: &[f64], inverse: &[f64], i: usize, x: f64, previous: f64) -> f64 {
    forward_step(l[2 * i], inverse[i], i > 0, x, previous)
}

/// [`forward_row`] from row i's numbers: Lᵢ,ᵢ₋₁ (`below`, read when `has_below`: i > 0) and
/// 1/Lᵢᵢ, for a caller that walks the factor row by row rather than indexing it.
#[inline(always)]
pub(crate) fn forward_step(below: f64, inverse: f64, has_below: bool, x: f64, previous: f64) -> f64 {
    let s = if has_below { -0.0 + below * previous } else { -0.0 };
    (x - s) * inverse
}

/// Row i of the backward substitution Lᵀ x = y of a tridiagonal factor: xᵢ = (yᵢ − `next`)
/// × 1/Lᵢᵢ, and the `next` of row i − 1, Lᵢ,ᵢ₋₁ xᵢ (0 at row 0: `has_below` is i > 0).
#[inline(always)]
pub(crate) fn backward_step(below: f64, inverse: f64, has_below: bool, y: f64, next: f64) -> (f64, f64) {
    let v = (y - next) * inverse;
    (v, if has_below { below * v } else { 0.0 })
}

/// The backward substitution Lᵀ x = y of a tridiagonal factor in place (after
/// [`forward_row`] over every row), multiplying by 1/Lᵢᵢ.
#[inline]
pub(crate) fn tridiagonal_backward(l: &[f64], inverse: &[f64], x: &mut [f64]) {
    let mut next = 0.0;
    for i in (0..x.len()).rev() {
        (x[i], next) = backward_step(l[2 * i], inverse[i], i > 0, x[i], next);
    }
}

/// Row i of y = A x for a tridiagonal A stored as [`Banded`] stores it (`d[2i]` = Aᵢ,ᵢ₋₁,
/// `d[2i + 1]` = Aᵢᵢ): the general loop's sums in its order.
#[inline]
pub(crate) fn tridiagonal_mul_row(d: &[f64], x: &[f64], i: usize) -> f64 {
    let n = x.len();
    let s = if i > 0 { 0.0 + d[2 * i] * x[i - 1] } else { 0.0 };
    let own = 0.0 + (s + d[2 * i + 1] * x[i]);
    if i + 1 < n { own + d[2 * i + 2] * x[i + 1] } else { own }
}

/// y = A x for a tridiagonal A (chains) stored as [`Banded`] stores it, row by row.
fn tridiagonal_mul(d: &[f64], x: &[f64], y: &mut [f64]) {
    for (i, yi) in y.iter_mut().enumerate() {
        *yi = tridiagonal_mul_row(d, x, i);
    }
}

pub fn reverse_cuthill_mckee(n: usize, edges: impl Iterator<Item = (usize, usize)>) -> Vec<usize> {
    let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (i, j) in edges {
        if i != j {
            neighbours[i].push(j);
            neighbours[j].push(i);
        }
    }
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
    }
    let degree: Vec<usize> = neighbours.iter().map(Vec::len).collect();
    let mut by_degree: Vec<usize> = (0..n).collect();
    by_degree.sort_by_key(|&i| degree[i]);
    let mut seen = vec![false; n];
    let mut order = Vec::new();
    for &start in &by_degree {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let mut head = order.len();
        order.push(start);
        while head < order.len() {
            let node = order[head];
            head += 1;
            let mut next: Vec<usize> = neighbours[node].iter().copied().filter(|&j| !seen[j]).collect();
            next.sort_by_key(|&j| degree[j]);
            for j in next {
                seen[j] = true;
                order.push(j);
            }
        }
    }
    order.reverse();
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tridiagonal_solve_matches_a_dense_one() {
        let n = 7;
        let mut a = Banded::zeros(n, 1);
        for i in 0..n {
            a.add(i, i, 2.0 + i as f64 * 0.1);
            if i > 0 {
                a.add(i, i - 1, -0.9);
            }
        }
        let x: Vec<f64> = (0..n).map(|i| (i as f64).sin() + 0.5).collect();
        let mut b = vec![0.0; n];
        a.mul(&x, &mut b);
        // The tridiagonal product is the general band loop's, number for number.
        let mut wide = Banded::zeros(n, 2);
        for i in 0..n {
            for j in i.saturating_sub(1)..=i {
                wide.add(i, j, a.data[a.at(i, j)]);
            }
        }
        let mut general = vec![0.0; n];
        wide.mul(&x, &mut general);
        assert_eq!(b, general);
        let ch = a.cholesky(1e-12).expect("positive definite");
        // A zero right-hand side of −0 solves to +0, as the general loop's sums give it (a
        // λ printed as −0.0 would be news to a user).
        let mut zeros = vec![-0.0; n];
        ch.solve_in_place(&mut zeros);
        assert!(zeros.iter().all(|z| z.to_bits() == 0), "{zeros:?}");
        ch.solve_in_place(&mut b);
        for (got, want) in b.iter().zip(&x) {
            assert!((got - want).abs() < 1e-13, "{got} vs {want}");
        }
    }

    proptest::proptest! {
        /// The tridiagonal factor is the general loop's bit for bit, and fails at the same
        /// row (matrices near singular and indefinite included).
        #[test]
        fn tridiagonal_factor_is_the_general_one(
            entries in proptest::collection::vec((0.0f64..4.0, -2.0f64..2.0), 1..40),
        ) {
            let n = entries.len();
            let mut a = Banded::zeros(n, 1);
            for (i, &(d, e)) in entries.iter().enumerate() {
                a.add(i, i, d);
                if i > 0 {
                    a.add(i, i - 1, e);
                }
            }
            let (mut fast, mut general) = (vec![0.0; 2 * n], vec![0.0; 2 * n]);
            let (got, want) = (a.tridiagonal_factor(1e-10, &mut fast), a.band_factor(1e-10, &mut general));
            proptest::prop_assert_eq!(got, want);
            let bits = |l: &[f64]| l.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            proptest::prop_assert_eq!(bits(&fast), bits(&general));
        }
    }

    proptest::proptest! {
        /// The tridiagonal substitutions (multiplying by 1/Lᵢᵢ) agree with the general
        /// loop's (dividing by Lᵢᵢ) to rounding on well-conditioned matrices (diagonally
        /// dominant: κ below 3), and solve a zero right-hand side to the same signed zeros.
        #[test]
        fn tridiagonal_solve_is_the_general_one_to_rounding(
            entries in proptest::collection::vec((2.0f64..4.0, -1.0f64..1.0, -3.0f64..3.0), 1..40),
            negative_zero in 0usize..40,
        ) {
            let n = entries.len();
            let mut a = Banded::zeros(n, 1);
            for (i, &(d, e, _)) in entries.iter().enumerate() {
                a.add(i, i, d);
                if i > 0 {
                    a.add(i, i - 1, e);
                }
            }
            let mut x: Vec<f64> = entries.iter().map(|&(_, _, x)| x).collect();
            if negative_zero < n {
                x[negative_zero] = -0.0;
            }
            let factor = a.cholesky(1e-10).expect("diagonally dominant");
            let (mut fast, mut general) = (x.clone(), x.clone());
            factor.solve_in_place(&mut fast);
            factor.band_solve(&mut general);
            let size = general.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (f, g) in fast.iter().zip(&general) {
                proptest::prop_assert!((f - g).abs() <= 1e-14 * size, "{} vs {}", f, g);
            }
            // A zero right-hand side (−0 where x has it) gets the general loop's signed zeros.
            let zeros: Vec<f64> = x.iter().map(|v| if v.to_bits() == (-0.0f64).to_bits() { -0.0 } else { 0.0 }).collect();
            let (mut fast, mut general) = (zeros.clone(), zeros);
            factor.solve_in_place(&mut fast);
            factor.band_solve(&mut general);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            proptest::prop_assert_eq!(bits(&fast), bits(&general));
        }
    }

    proptest::proptest! {
        /// A diagonal's product, factor and solve are the general loops' bit for bit (a −0
        /// right-hand side included), and its factor fails at the same row.
        #[test]
        fn diagonal_paths_are_the_general_ones(
            entries in proptest::collection::vec((-0.5f64..4.0, -3.0f64..3.0), 1..20),
            negative_zero in 0usize..20,
        ) {
            let n = entries.len();
            let mut a = Banded::zeros(n, 0);
            for (i, &(d, _)) in entries.iter().enumerate() {
                a.add(i, i, d);
            }
            let mut x: Vec<f64> = entries.iter().map(|&(_, x)| x).collect();
            if negative_zero < n {
                x[negative_zero] = -0.0;
            }
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let (mut fast, mut general) = (vec![1.0; n], vec![2.0; n]);
            a.mul(&x, &mut fast);
            a.band_mul(&x, &mut general);
            proptest::prop_assert_eq!(bits(&fast), bits(&general));
            let (mut fast, mut general) = (vec![0.0; n], vec![0.0; n]);
            let (got, want) = (a.diagonal_factor(1e-10, &mut fast), a.band_factor(1e-10, &mut general));
            proptest::prop_assert_eq!(got, want);
            proptest::prop_assert_eq!(bits(&fast), bits(&general));
            if got.is_ok() {
                let factor = BandedCholesky { n, w: 0, l: fast, inverse: Vec::new() };
                let (mut fast, mut general) = (x.clone(), x.clone());
                factor.solve_in_place(&mut fast);
                factor.band_solve(&mut general);
                proptest::prop_assert_eq!(bits(&fast), bits(&general));
            }
        }
    }

    #[test]
    fn cuthill_mckee_recovers_a_shuffled_path() {
        // The path 0–1–…–9 numbered by a shuffle: bandwidth 1 again after renumbering.
        let label = [7, 2, 9, 0, 5, 3, 8, 1, 6, 4];
        let order = reverse_cuthill_mckee(10, (0..9).map(|k| (label[k], label[k + 1])));
        let mut position = [0; 10];
        for (new, &old) in order.iter().enumerate() {
            position[old] = new;
        }
        let width = (0..9).map(|k| position[label[k]].abs_diff(position[label[k + 1]])).max();
        assert_eq!(width, Some(1));
    }

    #[test]
    fn singular_matrix_reports_the_row() {
        let mut a = Banded::zeros(2, 1);
        a.add(0, 0, 1.0);
        a.add(1, 1, 1.0);
        a.add(1, 0, 1.0);
        assert_eq!(a.cholesky(1e-12), Err(1));
    }
}
