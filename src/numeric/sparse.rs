//! Sparse L D Lᵀ of a symmetric positive definite matrix with a fill-reducing order: the λ
//! solve of blocks that are not banded (grids, meshes), where the band of reverse
//! Cuthill–McKee grows with the width of the scene.
//!
//! Design note. The factorisation is Clarabel's QDLDL (`clarabel::qdldl`, the up-looking
//! L D Lᵀ of Davis's LDL over an elimination tree) with the approximate minimum degree
//! order of the `amd` crate (Amestoy, Davis & Duff 1996), both already in the build through
//! the contact QP: no dependency is added. The analysis — the order, the elimination tree,
//! the column counts of L and where each entry of A goes in the permuted matrix — is made
//! once per pattern ([`SparseFactor::analyse`]); a new matrix of the same pattern costs the
//! numeric factorisation alone ([`SparseFactor::factor`]). QDLDL's regularisation is off: a
//! pivot at or below the caller's floor means the matrix is singular to that tolerance and
//! the factor is refused, so the caller falls back as it does for the band (the pivots of
//! L D Lᵀ are the squares of Cholesky's, the Schur complements the band compares).
//! The substitutions are written here over QDLDL's L, so a solve reads the factor without
//! its scratch and repeats with any right-hand side.
//!
//! Not here: choosing between band, sparse and dense, scaling, refinement's policy
//! (`numeric::solve`).

use clarabel::algebra::CscMatrix;
use clarabel::qdldl::{QDLDLFactorisation, QDLDLSettings};

/// A pattern's analysis and, once [`factor`](SparseFactor::factor) succeeded, its numeric
/// L D Lᵀ. The matrix is kept (upper triangle, compressed columns, the caller's order) for
/// products A x.
#[derive(Debug)]
pub struct SparseFactor {
    n: usize,
    /// Upper triangle of A by columns in the caller's order: column j's rows are
    /// `rowval[colptr[j]..colptr[j + 1]]`, ascending, the diagonal last.
    colptr: Vec<usize>,
    rowval: Vec<usize>,
    values: Vec<f64>,
    /// 0..nnz, QDLDL's indices of every entry for its value update.
    every: Vec<usize>,
    /// Boxed: QDLDL's factorisation and workspace are many vectors, moved with the plan.
    /// `None` only in a clone whose analysis QDLDL refused (it never does: see `analyse`),
    /// which then never factors.
    ldl: Option<Box<QDLDLFactorisation<f64>>>,
    /// Σⱼ (entries of column j of L)²: the multiplications of a factorisation, give or take.
    flops: f64,
}

impl Clone for SparseFactor {
    fn clone(&self) -> SparseFactor {
        // QDLDL's factorisation is not `Clone`: analyse the pattern again and carry the
        // numbers over (a clone is rare: a cache copied whole).
        let entries =
            (0..self.n).flat_map(|j| self.rowval[self.colptr[j]..self.colptr[j + 1]].iter().map(move |&i| (i, j)));
        let Some((mut copy, _)) = SparseFactor::analyse(self.n, entries) else {
            return SparseFactor { ldl: None, ..self.shallow() };
        };
        copy.values.copy_from_slice(&self.values);
        if let Some(ldl) = &mut copy.ldl {
            ldl.update_values(&copy.every, &copy.values);
            // A refused factor stays refused in the copy: callers use only factors that
            // succeeded.
            let _ = ldl.refactor();
        }
        copy
    }
}

/// Buffers of [`SparseFactor::solve_into`].
#[derive(Clone, Debug, Default)]
pub struct SparseWork {
    permuted: Vec<f64>,
    ax: Vec<f64>,
    r: Vec<f64>,
    y: Vec<f64>,
}

impl SparseFactor {
    /// Everything but the factorisation.
    fn shallow(&self) -> SparseFactor {
        SparseFactor {
            n: self.n,
            colptr: self.colptr.clone(),
            rowval: self.rowval.clone(),
            values: self.values.clone(),
            every: self.every.clone(),
            ldl: None,
            flops: self.flops,
        }
    }

    /// The analysis of the symmetric pattern whose entries are `entries` ((i, j) pairs of
    /// either triangle, repeats allowed; the diagonal is always included), with, for each
    /// entry in the order given, the place its value is summed into
    /// ([`values_mut`](SparseFactor::values_mut)). The values start at zero. `None` when
    /// QDLDL refuses the pattern (it checks that it is square, upper triangular and has an
    /// entry in every column, which this one always is) or an entry is out of range.
    pub fn analyse(n: usize, entries: impl Iterator<Item = (usize, usize)>) -> Option<(SparseFactor, Vec<usize>)> {
        let pairs: Vec<(usize, usize)> = entries.map(|(i, j)| (i.min(j), i.max(j))).collect();
        if pairs.iter().any(|&(_, j)| j >= n) {
            return None;
        }
        // Column j holds the rows i ≤ j: count, then fill, then sort and deduplicate each.
        let mut rows_of: Vec<Vec<usize>> = (0..n).map(|j| vec![j]).collect();
        for &(i, j) in &pairs {
            if i != j {
                rows_of[j].push(i);
            }
        }
        let mut colptr = Vec::with_capacity(n + 1);
        let mut rowval = Vec::new();
        colptr.push(0);
        for rows in &mut rows_of {
            rows.sort_unstable();
            rows.dedup();
            rowval.extend_from_slice(rows);
            colptr.push(rowval.len());
        }
        let targets = pairs
            .iter()
            .map(|&(i, j)| {
                let column = &rowval[colptr[j]..colptr[j + 1]];
                // Present by construction.
                colptr[j] + column.binary_search(&i).unwrap_or(0)
            })
            .collect();
        let nnz = rowval.len();
        let values = vec![0.0; nnz];
        // The pattern with a unit diagonal: the analysis reads only the structure.
        let mut shape = vec![0.0; nnz];
        for j in 0..n {
            shape[colptr[j + 1] - 1] = 1.0;
        }
        let a = CscMatrix::new(n, n, colptr.clone(), rowval.clone(), shape);
        let settings = QDLDLSettings { logical: true, regularize_enable: false, ..QDLDLSettings::default() };
        let ldl = Box::new(QDLDLFactorisation::new(&a, Some(settings)).ok()?);
        let flops = ldl.L.colptr.windows(2).map(|w| ((w[1] - w[0]) as f64).powi(2)).sum::<f64>() + n as f64;
        let every = (0..nnz).collect();
        Some((SparseFactor { n, colptr, rowval, values, every, ldl: Some(ldl), flops }, targets))
    }

    /// The size n.
    pub fn size(&self) -> usize {
        self.n
    }

    /// About how many multiply–adds a factorisation costs (Σⱼ of the square of the entries
    /// of L's column j), for the caller's choice between factorisations.
    pub fn flops(&self) -> f64 {
        self.flops
    }

    /// The entries of L below its unit diagonal.
    pub fn factor_entries(&self) -> usize {
        self.ldl.as_ref().map_or(0, |ldl| ldl.nnzL())
    }

    /// The values of A's upper triangle, at the places [`analyse`](SparseFactor::analyse)
    /// gave: the caller zeroes and sums into them, then calls [`factor`](SparseFactor::factor).
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// Factors the current values: false when a pivot of D falls to `pivot_floor` or below
    /// (or is not a number), the matrix then being singular to that tolerance; the factor
    /// must not be used then.
    pub fn factor(&mut self, pivot_floor: f64) -> bool {
        let Some(ldl) = &mut self.ldl else { return false };
        ldl.update_values(&self.every, &self.values);
        ldl.refactor().is_ok() && ldl.D.iter().all(|&d| d > pivot_floor && d.is_finite())
    }

    /// y = A x (A symmetric, from its upper triangle).
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        y[..self.n].fill(0.0);
        for j in 0..self.n {
            let (from, to) = (self.colptr[j], self.colptr[j + 1]);
            let xj = x[j];
            let mut s = 0.0;
            // Every entry above the diagonal, then the diagonal (last in the column).
            for (&i, &a) in self.rowval[from..to - 1].iter().zip(&self.values[from..to - 1]) {
                s += a * x[i];
                y[i] += a * xj;
            }
            y[j] += s + self.values[to - 1] * xj;
        }
    }

    /// Overwrites `x` with the solution of L D Lᵀ y = x in the permuted order.
    fn substitute(&self, x: &mut [f64]) {
        let Some(ldl) = &self.ldl else { return };
        let l = &ldl.L;
        let (p, i, v) = (&l.colptr, &l.rowval, &l.nzval);
        for j in 0..self.n {
            let xj = x[j];
            for (&r, &a) in i[p[j]..p[j + 1]].iter().zip(&v[p[j]..p[j + 1]]) {
                x[r] -= a * xj;
            }
        }
        for (xj, &d) in x.iter_mut().zip(&ldl.Dinv) {
            *xj *= d;
        }
        for j in (0..self.n).rev() {
            let mut s = x[j];
            for (&r, &a) in i[p[j]..p[j + 1]].iter().zip(&v[p[j]..p[j + 1]]) {
                s -= a * x[r];
            }
            x[j] = s;
        }
    }

    /// A x = `rhs` (in the caller's order) into `x`, with one step of iterative refinement,
    /// with `work`'s buffers (no allocation once they have the size).
    pub fn solve_into(&self, rhs: &[f64], work: &mut SparseWork, x: &mut Vec<f64>) {
        let n = self.n;
        let Some(ldl) = &self.ldl else {
            x.clear();
            x.resize(n, 0.0);
            return;
        };
        let perm = &ldl.perm;
        let SparseWork { permuted, ax, r, y } = work;
        // perm[new] = old.
        permuted.clear();
        permuted.extend(perm.iter().map(|&old| rhs[old]));
        self.substitute(permuted);
        x.clear();
        x.resize(n, 0.0);
        for (&old, &value) in perm.iter().zip(permuted.iter()) {
            x[old] = value;
        }
        // One step of iterative refinement: x += A⁻¹ (rhs − A x).
        ax.clear();
        ax.resize(n, 0.0);
        self.mul(x, ax);
        r.clear();
        r.extend(perm.iter().map(|&old| rhs[old] - ax[old]));
        self.substitute(r);
        y.clear();
        y.extend_from_slice(r);
        for (&old, &dx) in perm.iter().zip(y.iter()) {
            x[old] += dx;
        }
    }

    /// [`solve_into`](SparseFactor::solve_into) into a new vector.
    pub fn solve(&self, rhs: &[f64]) -> Vec<f64> {
        let mut x = Vec::new();
        self.solve_into(rhs, &mut SparseWork::default(), &mut x);
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_system_solves() {
        // The 1-D Laplacian plus a corner coupling (not banded in this order).
        let n = 6;
        let mut entries = Vec::new();
        let mut values = Vec::new();
        for i in 0..n {
            entries.push((i, i));
            values.push(4.0);
            if i > 0 {
                entries.push((i - 1, i));
                values.push(-1.0);
            }
        }
        entries.push((n - 1, 0));
        values.push(-1.0);
        let (mut f, targets) = SparseFactor::analyse(n, entries.iter().copied()).expect("a valid pattern");
        for (&t, &v) in targets.iter().zip(&values) {
            f.values_mut()[t] += v;
        }
        assert!(f.factor(1e-10));
        let want: Vec<f64> = (0..n).map(|i| i as f64 - 2.5).collect();
        let mut b = vec![0.0; n];
        f.mul(&want, &mut b);
        let got = f.solve(&b);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-14, "{g} vs {w}");
        }
        // A clone (analysed again) factors and solves alike.
        let copy = f.clone();
        assert_eq!(copy.solve(&b), got);
        assert_eq!(copy.factor_entries(), f.factor_entries());
        // A singular matrix is refused.
        f.values_mut().fill(0.0);
        for (&t, &(i, j)) in targets.iter().zip(&entries) {
            f.values_mut()[t] += if i == j { 1.0 } else { 0.0 };
        }
        f.values_mut()[targets[0]] = 0.0;
        assert!(!f.factor(1e-10));
    }
}
