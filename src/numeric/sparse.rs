//! Sparse Cholesky L Lᵀ of a symmetric positive definite matrix with a fill-reducing order:
//! the λ solve of blocks that are not banded (grids, meshes), where the band of reverse
//! Cuthill–McKee grows with the width of the scene.
//!
//! Design note. The analysis is Clarabel's QDLDL (`clarabel::qdldl`, Davis's LDL over an
//! elimination tree) run symbolically, with the approximate minimum degree order of the
//! `amd` crate (Amestoy, Davis & Duff 1996), both already in the build through the contact
//! QP: no dependency is added. It gives the order and the pattern of L; columns whose
//! patterns nest (column j's parent in the elimination tree is j + 1 and its pattern is
//! j + 1's and j + 1 itself) are grouped into supernodes, whose columns are stored as one
//! dense block (rows × columns, by columns). The analysis is made once per pattern
//! ([`SparseFactor::analyse`]); a new matrix of the same pattern costs the numeric
//! factorisation alone ([`SparseFactor::factor`]). That is the left-looking supernodal
//! Cholesky (Ng & Peyton 1993; Davis, *Direct Methods for Sparse Linear Systems*, 2006, and
//! CHOLMOD's supernodal factor): each supernode gathers the updates of the supernodes below
//! it in the tree as dense products, then factors its block in place, so the inner loops
//! run over contiguous columns and vectorise where QDLDL's up-looking loop scatters one
//! entry at a time. A pivot (the Schur complement a square root is taken of, QDLDL's D) at
//! or below the caller's floor means the matrix is singular to that tolerance and the
//! factor is refused, so the caller falls back as it does for the band.
//! The substitutions run supernode by supernode over the same blocks, gathering each one's
//! rows into a contiguous buffer, so a solve reads the factor without its scratch and
//! repeats with any right-hand side.
//!
//! Not here: choosing between band, sparse and dense, scaling (`numeric::solve`).

use clarabel::algebra::CscMatrix;
use clarabel::qdldl::{QDLDLFactorisation, QDLDLSettings};

/// No supernode (the end of a list).
const NONE: usize = usize::MAX;

/// A pattern's analysis and, once [`factor`](SparseFactor::factor) succeeded, its numeric
/// L Lᵀ. The matrix is kept (upper triangle, compressed columns, the caller's order) for
/// products A x.
#[derive(Clone, Debug)]
pub struct SparseFactor {
    n: usize,
    /// Upper triangle of A by columns in the caller's order: column j's rows are
    /// `rowval[colptr[j]..colptr[j + 1]]`, ascending, the diagonal last.
    colptr: Vec<usize>,
    rowval: Vec<usize>,
    values: Vec<f64>,
    /// The order, the supernodes and their blocks (boxed: many vectors, moved with the
    /// plan).
    blocks: Box<Blocks>,
    /// Whether `lx` holds the factor of the current values.
    factored: bool,
    /// The entries of L below its diagonal.
    entries: usize,
    /// Σⱼ (entries of column j of L)²: the multiplications of a factorisation, give or take.
    flops: f64,
}

/// A [`SparseFactor`]'s order, supernodes and blocks of L.
#[derive(Clone, Debug)]
struct Blocks {
    /// perm[new] = old: the fill-reducing order.
    perm: Vec<usize>,
    /// Supernode s is the columns `first[s]..first[s + 1]` (in the new order).
    first: Vec<usize>,
    /// Its rows `rows[rowptr[s]..rowptr[s + 1]]`, ascending: its own columns, then the rows
    /// below them.
    rowptr: Vec<usize>,
    rows: Vec<usize>,
    /// Its block of L, rows × columns by columns, at `lx[lxptr[s]..lxptr[s + 1]]` (the
    /// entries above the diagonal of its first columns unused).
    lxptr: Vec<usize>,
    lx: Vec<f64>,
    /// The supernode of each column (new order).
    of: Vec<usize>,
    /// The entries of A each supernode's block starts from, grouped by supernode
    /// (`assembly[assembly_ptr[s]..assembly_ptr[s + 1]]`, in `values`' order within a group):
    /// (index in `values`, place in `lx` it is summed into). A block is zeroed and filled
    /// just before it is factored, while it is about to be in cache anyway.
    assembly: Vec<(usize, usize)>,
    assembly_ptr: Vec<usize>,
    /// The entries of each row of A (both triangles), for the residual's rounding.
    row_entries: Vec<usize>,
    scratch: Scratch,
}

/// The factorisation's buffers (sized by the analysis).
#[derive(Clone, Debug, Default)]
struct Scratch {
    /// relative[row] = its place among the rows of the supernode being factored.
    relative: Vec<usize>,
    /// The places, among those rows, of a descendant's rows.
    places: Vec<usize>,
    /// A descendant's update, rows × columns by columns.
    update: Vec<f64>,
    /// head[s]: the first descendant whose next update goes to s; next[d]: the one after d.
    head: Vec<usize>,
    next: Vec<usize>,
    /// The first row of descendant d not yet used by an update.
    position: Vec<usize>,
}

/// Buffers of [`SparseFactor::solve_into`].
#[derive(Clone, Debug, Default)]
pub struct SparseWork {
    permuted: Vec<f64>,
    ax: Vec<f64>,
    bound: Vec<f64>,
    r: Vec<f64>,
    gathered: Vec<f64>,
}

impl SparseFactor {
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
        // The pattern with a unit diagonal: the symbolic factorisation reads only the
        // structure, and gives the order and the pattern of L (each column's rows
        // ascending, the first its parent in the elimination tree).
        let mut shape = vec![0.0; nnz];
        for j in 0..n {
            shape[colptr[j + 1] - 1] = 1.0;
        }
        let a = CscMatrix::new(n, n, colptr.clone(), rowval.clone(), shape);
        let settings = QDLDLSettings { logical: true, regularize_enable: false, ..QDLDLSettings::default() };
        let ldl = QDLDLFactorisation::new(&a, Some(settings)).ok()?;
        let (lp, li) = (&ldl.L.colptr, &ldl.L.rowval);
        let count = |j: usize| lp[j + 1] - lp[j];
        let flops = (0..n).map(|j| (count(j) as f64).powi(2)).sum::<f64>() + n as f64;
        // Fundamental supernodes: column j joins j − 1's when j − 1's pattern is j and j's
        // pattern.
        let mut fundamental = vec![0];
        for j in 1..n {
            let nests = count(j - 1) == count(j) + 1 && li.get(lp[j - 1]) == Some(&j);
            if !nests {
                fundamental.push(j);
            }
        }
        if n > 0 {
            fundamental.push(n);
        }
        // Relaxed: a run of supernodes joins the next when that is its parent and the
        // zeros its columns then store are few (CHOLMOD's default rule: up to 4 columns
        // always, 16 with under 80 % zeros, 48 with under 10 %, any with under 5 %).
        // Fewer, wider blocks: the small ones near the leaves cost more in bookkeeping
        // than in arithmetic.
        let mut first = vec![0];
        for t in 1..fundamental.len().saturating_sub(1) {
            let (gf, gl, tl) = (*first.last().unwrap_or(&0), fundamental[t], fundamental[t + 1]);
            let parent = (count(gl - 1) > 0).then(|| li[lp[gl - 1]]);
            let joins = parent.is_some_and(|p| p < tl) && {
                let below = count(tl - 1);
                let zeros: usize = (gf..gl).map(|k| (tl - 1 - k) + below - count(k)).sum();
                let total: usize = (gf..tl).map(|k| tl - k + below).sum();
                let (columns, fraction) = (tl - gf, zeros as f64 / total as f64);
                columns <= 4
                    || (columns <= 16 && fraction < 0.8)
                    || (columns <= 48 && fraction < 0.1)
                    || fraction < 0.05
            };
            if !joins {
                first.push(gl);
            }
        }
        if n > 0 {
            first.push(n);
        }
        let supernodes = first.len() - 1;
        let (mut rowptr, mut rows, mut lxptr, mut of) = (vec![0], Vec::new(), vec![0], vec![0; n]);
        for s in 0..supernodes {
            let (f, l) = (first[s], first[s + 1]);
            rows.extend(f..l);
            rows.extend_from_slice(&li[lp[l - 1]..lp[l]]);
            rowptr.push(rows.len());
            let m = rowptr[s + 1] - rowptr[s];
            lxptr.push(lxptr[s] + m * (l - f));
            of[f..l].fill(s);
        }
        // Where each entry of A (upper triangle, caller's order) goes: row max(i, j),
        // column min(i, j) of the permuted matrix, in its supernode's block.
        let mut inverse = vec![0; n];
        for (new, &old) in ldl.perm.iter().enumerate() {
            inverse[old] = new;
        }
        let mut row_entries = vec![0; n];
        for j in 0..n {
            for &i in &rowval[colptr[j]..colptr[j + 1]] {
                row_entries[i] += 1;
                if i != j {
                    row_entries[j] += 1;
                }
            }
        }
        let mut assembly = Vec::with_capacity(nnz);
        let mut assembly_ptr = vec![0; supernodes + 1];
        for j in 0..n {
            for (e, &i) in rowval[colptr[j]..colptr[j + 1]].iter().enumerate() {
                let (a, b) = (inverse[i], inverse[j]);
                let (r, c) = (a.max(b), a.min(b));
                let s = of[c];
                let mine = &rows[rowptr[s]..rowptr[s + 1]];
                // Present: r is in the pattern of L's column c, so in its supernode's rows.
                let k = mine.binary_search(&r).ok()?;
                assembly.push((s, colptr[j] + e, lxptr[s] + k + (c - first[s]) * mine.len()));
                assembly_ptr[s + 1] += 1;
            }
        }
        // Grouped by supernode, `values`' order kept within each (a stable sort): every
        // place receives its entries in the same order as summing over `values` would.
        assembly.sort_by_key(|&(s, _, _)| s);
        for s in 0..supernodes {
            assembly_ptr[s + 1] += assembly_ptr[s];
        }
        let assembly: Vec<(usize, usize)> = assembly.into_iter().map(|(_, e, at)| (e, at)).collect();
        // The largest update: a descendant's rows below a supernode's first column by the
        // supernode's columns among them.
        let (mut tallest, mut widest) = (0, 0);
        for s in 0..supernodes {
            tallest = tallest.max(rowptr[s + 1] - rowptr[s]);
            widest = widest.max(first[s + 1] - first[s]);
        }
        let scratch = Scratch {
            relative: vec![0; n],
            places: vec![0; tallest],
            update: vec![0.0; tallest * widest],
            head: vec![NONE; supernodes],
            next: vec![NONE; supernodes],
            position: vec![0; supernodes],
        };
        let factor = SparseFactor {
            n,
            colptr,
            rowval,
            values,
            blocks: Box::new(Blocks {
                perm: ldl.perm.clone(),
                first,
                rowptr,
                rows,
                lx: vec![0.0; lxptr[supernodes]],
                lxptr,
                of,
                assembly,
                assembly_ptr,
                row_entries,
                scratch,
            }),
            factored: false,
            entries: ldl.nnzL(),
            flops,
        };
        Some((factor, targets))
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

    /// The entries of L below its diagonal.
    pub fn factor_entries(&self) -> usize {
        self.entries
    }

    /// The number of supernodes (groups of columns of L with one pattern).
    pub fn supernodes(&self) -> usize {
        self.blocks.first.len() - 1
    }

    /// The values of A's upper triangle, at the places [`analyse`](SparseFactor::analyse)
    /// gave: the caller zeroes and sums into them, then calls [`factor`](SparseFactor::factor).
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// Factors the current values: false when a pivot falls to `pivot_floor` or below (or
    /// is not a number), the matrix then being singular to that tolerance; the factor must
    /// not be used then.
    pub fn factor(&mut self, pivot_floor: f64) -> bool {
        self.factored = self.factor_widest(pivot_floor);
        self.factored
    }

    /// [`factor_supernodes`](SparseFactor::factor_supernodes) with the widest vector
    /// instructions the processor has (AVX2 on x86-64 when present: the same IEEE
    /// operations four at a time, no FMA, so the factor is bitwise the same either way).
    fn factor_widest(&mut self, pivot_floor: f64) -> bool {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked).
            return unsafe { self.factor_avx2(pivot_floor) };
        }
        self.factor_supernodes(pivot_floor)
    }

    /// [`factor_supernodes`](SparseFactor::factor_supernodes) compiled for AVX2.
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn factor_avx2(&mut self, pivot_floor: f64) -> bool {
        self.factor_supernodes(pivot_floor)
    }

    /// The left-looking supernodal factorisation of `values` into `lx`.
    #[inline(always)]
    fn factor_supernodes(&mut self, pivot_floor: f64) -> bool {
        let values = &self.values;
        let Blocks { first, rowptr, rows, lxptr, lx, of, assembly, assembly_ptr, scratch, .. } = &mut *self.blocks;
        let Scratch { relative, places, update, head, next, position } = scratch;
        head.fill(NONE);
        for s in 0..first.len() - 1 {
            // Its block of A, permuted (nothing else writes to it before this supernode).
            lx[lxptr[s]..lxptr[s + 1]].fill(0.0);
            for &(e, at) in &assembly[assembly_ptr[s]..assembly_ptr[s + 1]] {
                lx[at] += values[e];
            }
            let (f, l) = (first[s], first[s + 1]);
            let w = l - f;
            let mine = &rows[rowptr[s]..rowptr[s + 1]];
            let m = mine.len();
            for (k, &r) in mine.iter().enumerate() {
                relative[r] = k;
            }
            // Every descendant d with rows among s's columns: L_s −= L_d[rows ≥ f] L_d[f..l]ᵀ.
            let mut d = std::mem::replace(&mut head[s], NONE);
            while d != NONE {
                let after = next[d];
                let theirs = &rows[rowptr[d]..rowptr[d + 1]];
                let md = theirs.len();
                let p = position[d];
                let q = p + theirs[p..].iter().take_while(|&&r| r < l).count();
                let (height, width) = (md - p, q - p);
                let (below, block) = lx.split_at_mut(lxptr[s]);
                let ld = &below[lxptr[d]..lxptr[d + 1]];
                let c = &mut update[..height * width];
                product(ld, md, p, height, width, c);
                for (k, &r) in theirs[p..].iter().enumerate() {
                    places[k] = relative[r];
                }
                let ls = &mut block[..m * w];
                for j in 0..width {
                    let column = &mut ls[places[j] * m..];
                    let cj = &c[j * height + j..(j + 1) * height];
                    let (top, bottom) = (places[j], places[height - 1]);
                    if bottom - top == height - 1 - j {
                        // The rows are consecutive in s: one contiguous subtraction.
                        for (t, &v) in column[top..=bottom].iter_mut().zip(cj) {
                            *t -= v;
                        }
                    } else {
                        for (&k, &v) in places[j..height].iter().zip(cj) {
                            column[k] -= v;
                        }
                    }
                }
                position[d] = q;
                if q < md {
                    let t = of[theirs[q]];
                    next[d] = head[t];
                    head[t] = d;
                }
                d = after;
            }
            // The block itself, column by column.
            let ls = &mut lx[lxptr[s]..lxptr[s + 1]];
            for j in 0..w {
                let (left, right) = ls.split_at_mut(j * m);
                let column = &mut right[j..m];
                subtract_columns(left, m, j, column);
                let pivot = column[0];
                if !(pivot > pivot_floor && pivot.is_finite()) {
                    return false;
                }
                let root = pivot.sqrt();
                column[0] = root;
                let inverse = 1.0 / root;
                for x in &mut column[1..] {
                    *x *= inverse;
                }
            }
            if m > w {
                position[s] = w;
                let t = of[mine[w]];
                next[s] = head[t];
                head[t] = s;
            }
        }
        true
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

    /// [`substitute_any`](SparseFactor::substitute_any) with AVX2 when present (bitwise
    /// the same, as [`factor_widest`](SparseFactor::factor_widest)).
    fn substitute(&self, x: &mut [f64], gathered: &mut Vec<f64>) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked).
            return unsafe { self.substitute_avx2(x, gathered) };
        }
        self.substitute_any(x, gathered)
    }

    /// [`substitute_any`](SparseFactor::substitute_any) compiled for AVX2.
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn substitute_avx2(&self, x: &mut [f64], gathered: &mut Vec<f64>) {
        self.substitute_any(x, gathered)
    }

    /// Overwrites `x` with the solution of L Lᵀ y = x in the permuted order, with
    /// `gathered` for one supernode's rows below its columns.
    #[inline(always)]
    fn substitute_any(&self, x: &mut [f64], gathered: &mut Vec<f64>) {
        // L z = x: each supernode solves its columns (contiguous in x), then passes their
        // products to the rows below.
        for s in 0..self.blocks.first.len() - 1 {
            let (mine, ls, w) = self.supernode(s);
            let (f, m) = (self.blocks.first[s], mine.len());
            for j in 0..w {
                let column = &ls[j * m + j..j * m + w];
                let zj = x[f + j] / column[0];
                x[f + j] = zj;
                for (xi, &a) in x[f + j + 1..f + w].iter_mut().zip(&column[1..]) {
                    *xi -= a * zj;
                }
            }
            if m == w {
                continue;
            }
            if w == 1 {
                let z = x[f];
                for (&r, &a) in mine[1..].iter().zip(&ls[1..]) {
                    x[r] -= a * z;
                }
                continue;
            }
            gathered.clear();
            gathered.resize(m - w, 0.0);
            for j in 0..w {
                let zj = x[f + j];
                for (g, &a) in gathered.iter_mut().zip(&ls[j * m + w..(j + 1) * m]) {
                    *g += a * zj;
                }
            }
            for (&r, &g) in mine[w..].iter().zip(gathered.iter()) {
                x[r] -= g;
            }
        }
        // Lᵀ y = z, the supernodes in reverse, each column a dot product with the rows
        // below it (already solved).
        for s in (0..self.blocks.first.len() - 1).rev() {
            let (mine, ls, w) = self.supernode(s);
            let (f, m) = (self.blocks.first[s], mine.len());
            gathered.clear();
            gathered.extend(mine[w..].iter().map(|&r| x[r]));
            for j in (0..w).rev() {
                let column = &ls[j * m..(j + 1) * m];
                let dot = dot(&column[j + 1..w], &x[f + j + 1..f + w]) + dot(&column[w..], gathered);
                x[f + j] = (x[f + j] - dot) / column[j];
            }
        }
    }

    /// Supernode s's rows, block and number of columns.
    fn supernode(&self, s: usize) -> (&[usize], &[f64], usize) {
        (
            &self.blocks.rows[self.blocks.rowptr[s]..self.blocks.rowptr[s + 1]],
            &self.blocks.lx[self.blocks.lxptr[s]..self.blocks.lxptr[s + 1]],
            self.blocks.first[s + 1] - self.blocks.first[s],
        )
    }

    /// A x = `rhs` (in the caller's order) into `x`, with one step of iterative refinement
    /// unless the residual is within the rounding of its own evaluation, with `work`'s
    /// buffers (no allocation once they have the size).
    pub fn solve_into(&self, rhs: &[f64], work: &mut SparseWork, x: &mut Vec<f64>) {
        let n = self.n;
        x.clear();
        x.resize(n, 0.0);
        if !self.factored {
            return;
        }
        let perm = &self.blocks.perm;
        let SparseWork { permuted, ax, bound, r, gathered } = work;
        // perm[new] = old.
        permuted.clear();
        permuted.extend(perm.iter().map(|&old| rhs[old]));
        self.substitute(permuted, gathered);
        for (&old, &value) in perm.iter().zip(permuted.iter()) {
            x[old] = value;
        }
        // The residual r = rhs − A x, and for each row the bound on the rounding of its
        // own evaluation, γ_{k+1} (|A| |x| + |rhs|)ᵢ with k the row's entries (Higham,
        // *Accuracy and Stability of Numerical Algorithms*, 2002, §3.5 and ch. 12): where
        // every |rᵢ| is within it, r is noise and a step of refinement would correct
        // noise, so the answer stands; otherwise one step: x += A⁻¹ r.
        self.mul_bounded(x, ax, bound);
        let unit = f64::EPSILON / 2.0;
        let noise = (0..n).all(|i| {
            let k = (self.blocks.row_entries[i] + 1) as f64;
            (rhs[i] - ax[i]).abs() <= k * unit * (bound[i] + rhs[i].abs())
        });
        if noise {
            return;
        }
        r.clear();
        r.extend(perm.iter().map(|&old| rhs[old] - ax[old]));
        self.substitute(r, gathered);
        for (&old, &dx) in perm.iter().zip(r.iter()) {
            x[old] += dx;
        }
    }

    /// y = A x and bound = |A| |x| (A symmetric, from its upper triangle).
    fn mul_bounded(&self, x: &[f64], y: &mut Vec<f64>, bound: &mut Vec<f64>) {
        y.clear();
        y.resize(self.n, 0.0);
        bound.clear();
        bound.resize(self.n, 0.0);
        for j in 0..self.n {
            let (from, to) = (self.colptr[j], self.colptr[j + 1]);
            let xj = x[j];
            let (mut s, mut t) = (0.0, 0.0);
            // Every entry above the diagonal, then the diagonal (last in the column).
            for (&i, &a) in self.rowval[from..to - 1].iter().zip(&self.values[from..to - 1]) {
                s += a * x[i];
                t += (a * x[i]).abs();
                y[i] += a * xj;
                bound[i] += (a * xj).abs();
            }
            let d = self.values[to - 1] * xj;
            y[j] += s + d;
            bound[j] += t + d.abs();
        }
    }

    /// A x = `rhs` by the two substitutions alone, without refinement (for a caller that
    /// iterates on its own residuals), into `x`, with `work`'s buffers.
    pub fn substitute_into(&self, rhs: &[f64], work: &mut SparseWork, x: &mut Vec<f64>) {
        x.clear();
        x.resize(self.n, 0.0);
        if !self.factored {
            return;
        }
        let perm = &self.blocks.perm;
        let mut permuted = std::mem::take(&mut work.permuted);
        permuted.clear();
        permuted.extend(perm.iter().map(|&old| rhs[old]));
        self.substitute_in_order(&mut permuted, work);
        for (&old, &value) in perm.iter().zip(permuted.iter()) {
            x[old] = value;
        }
        work.permuted = permuted;
    }

    /// The fill-reducing order the factor is in: `order()[new] = old`.
    pub fn order(&self) -> &[usize] {
        &self.blocks.perm
    }

    /// [`substitute_into`](SparseFactor::substitute_into) in place, with the right-hand side
    /// and the answer in the factor's own [`order`](SparseFactor::order): a caller that keeps
    /// its vectors in that order permutes neither way (the same numbers as the permuted
    /// vectors of `substitute_into`, bit for bit). Zero when there is no factor.
    pub fn substitute_in_order(&self, x: &mut [f64], work: &mut SparseWork) {
        if self.factored {
            self.substitute(x, &mut work.gathered);
        } else {
            x.fill(0.0);
        }
    }

    /// [`solve_into`](SparseFactor::solve_into) into a new vector.
    pub fn solve(&self, rhs: &[f64]) -> Vec<f64> {
        let mut x = Vec::new();
        self.solve_into(rhs, &mut SparseWork::default(), &mut x);
        x
    }
}

/// Σ aᵢ bᵢ in four partial sums (one sum in order waits on each addition).
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (mut s0, mut s1, mut s2, mut s3) = (0.0, 0.0, 0.0, 0.0);
    let (ac, bc) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ar, br) = (ac.remainder(), bc.remainder());
    for (x, y) in ac.zip(bc) {
        s0 += x[0] * y[0];
        s1 += x[1] * y[1];
        s2 += x[2] * y[2];
        s3 += x[3] * y[3];
    }
    for (x, y) in ar.iter().zip(br) {
        s0 += x * y;
    }
    (s0 + s1) + (s2 + s3)
}

/// c = L_d[p.., ..] L_d[p..p + width, ..]ᵀ on and below the diagonal of its first `width`
/// rows: `ld` is a block of `md` rows by columns, c has `height` = md − p rows by `width`
/// columns, by columns. Four of L_d's columns at a time, so each pass over c's column
/// carries four multiply–adds an entry.
#[inline(always)]
fn product(ld: &[f64], md: usize, p: usize, height: usize, width: usize, c: &mut [f64]) {
    let wd = ld.len() / md;
    for j in 0..width {
        let cj = &mut c[j * height + j..(j + 1) * height];
        cj.fill(0.0);
        let mut k = 0;
        while k + 4 <= wd {
            let at = |t: usize| (k + t) * md + p + j;
            four(cj, [&ld[at(0)..], &ld[at(1)..], &ld[at(2)..], &ld[at(3)..]], 1.0);
            k += 4;
        }
        while k < wd {
            let a = &ld[k * md + p + j..(k + 1) * md];
            one(cj, a, 1.0);
            k += 1;
        }
    }
}

/// column −= Σ_{k < j} left[j.., k] left[j, k]: `left` is the first j columns of a block of
/// m rows, `column` the rows j.. of its column j.
#[inline(always)]
fn subtract_columns(left: &[f64], m: usize, j: usize, column: &mut [f64]) {
    let mut k = 0;
    while k + 4 <= j {
        let at = |t: usize| (k + t) * m + j;
        four(column, [&left[at(0)..], &left[at(1)..], &left[at(2)..], &left[at(3)..]], -1.0);
        k += 4;
    }
    while k < j {
        one(column, &left[k * m + j..(k + 1) * m], -1.0);
        k += 1;
    }
}

/// c += sign (a₀ a₀[0] + a₁ a₁[0] + a₂ a₂[0] + a₃ a₃[0]) over c's length (each aₜ at least
/// as long): four columns a pass, indexed over one length so the loop vectorises.
#[inline(always)]
fn four(c: &mut [f64], a: [&[f64]; 4], sign: f64) {
    let len = c.len();
    let (a0, a1, a2, a3) = (&a[0][..len], &a[1][..len], &a[2][..len], &a[3][..len]);
    let (b0, b1, b2, b3) = (sign * a0[0], sign * a1[0], sign * a2[0], sign * a3[0]);
    for i in 0..len {
        c[i] += (a0[i] * b0 + a1[i] * b1) + (a2[i] * b2 + a3[i] * b3);
    }
}

/// c += sign a a[0] over c's length.
#[inline(always)]
fn one(c: &mut [f64], a: &[f64], sign: f64) {
    let len = c.len();
    let a = &a[..len];
    let b = sign * a[0];
    for i in 0..len {
        c[i] += a[i] * b;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric, strictly diagonally dominant (so positive definite) matrix on the
    /// edges of an `a` × `b` grid plus `extra` random couplings, as (i, j, value) entries of
    /// its upper triangle and the diagonal, from `seed` (SplitMix64).
    fn grid_matrix(a: usize, b: usize, extra: usize, seed: u64) -> (usize, Vec<(usize, usize, f64)>) {
        let mut state = seed;
        let mut next = move || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        };
        let n = a * b;
        let mut off = Vec::new();
        for i in 0..a {
            for j in 0..b {
                let k = i * b + j;
                if j + 1 < b {
                    off.push((k, k + 1));
                }
                if i + 1 < a {
                    off.push((k, k + b));
                }
            }
        }
        for _ in 0..extra {
            let (p, q) = ((next() * n as f64) as usize % n, (next() * n as f64) as usize % n);
            if p != q {
                off.push((p.min(q), p.max(q)));
            }
        }
        let mut diagonal = vec![0.0; n];
        let mut entries = Vec::new();
        for (p, q) in off {
            let v = 2.0 * next() - 1.0;
            diagonal[p] += v.abs();
            diagonal[q] += v.abs();
            entries.push((p, q, v));
        }
        for (k, d) in diagonal.iter().enumerate() {
            entries.push((k, k, d + 0.01 + next()));
        }
        (n, entries)
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]

        /// The supernodal factor solves as QDLDL's numeric L D Lᵀ (the factor it replaced)
        /// does, to round-off, on grids of any shape with random couplings, and a second
        /// factorisation of the same pattern with other values does too.
        #[test]
        fn supernodes_solve_as_qdldl(a in 1usize..30, b in 1usize..30, extra in 0usize..40, seed in 0u64..1000) {
            let (n, entries) = grid_matrix(a, b, extra, seed);
            let (mut f, targets) = SparseFactor::analyse(n, entries.iter().map(|&(i, j, _)| (i, j))).expect("a valid pattern");
            for round in 0..2 {
                let scale = 1.0 + round as f64;
                f.values_mut().fill(0.0);
                for (&t, &(i, j, v)) in targets.iter().zip(&entries) {
                    f.values_mut()[t] += if i == j { v * scale * scale } else { v * scale };
                }
                proptest::prop_assert!(f.factor(1e-12));
                let rhs: Vec<f64> = (0..n).map(|k| ((k * 7 + 3) % 11) as f64 - 5.0).collect();
                let got = f.solve(&rhs);
                // QDLDL on the same upper triangle, regularisation off.
                let a = CscMatrix::new(n, n, f.colptr.clone(), f.rowval.clone(), f.values.clone());
                let settings = QDLDLSettings { regularize_enable: false, ..QDLDLSettings::default() };
                let mut ldl = QDLDLFactorisation::new(&a, Some(settings)).expect("positive definite");
                let mut want = rhs.clone();
                ldl.solve(&mut want);
                let size = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                for (g, w) in got.iter().zip(&want) {
                    proptest::prop_assert!((g - w).abs() <= 1e-13 * size, "{} vs {}", g, w);
                }
            }
            proptest::prop_assert!(f.supernodes() <= n);
            proptest::prop_assert_eq!(f.factor_entries(), {
                let a = CscMatrix::new(n, n, f.colptr.clone(), f.rowval.clone(), f.values.clone());
                QDLDLFactorisation::new(&a, None).expect("positive definite").nnzL()
            });
        }
    }

    /// The factor and the substitutions give the same bits with the widest instructions
    /// (AVX2 where present) as compiled for any x86-64, and the grid's columns are grouped.
    #[test]
    fn the_widest_instructions_give_the_same_bits() {
        let (n, entries) = grid_matrix(25, 20, 30, 7);
        let (mut f, targets) =
            SparseFactor::analyse(n, entries.iter().map(|&(i, j, _)| (i, j))).expect("a valid pattern");
        for (&t, &(_, _, v)) in targets.iter().zip(&entries) {
            f.values_mut()[t] += v;
        }
        assert!(f.factor(1e-12));
        assert!(f.supernodes() < n / 2, "{} supernodes for {n} columns", f.supernodes());
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let widest = bits(&f.blocks.lx);
        assert!(f.factor_supernodes(1e-12));
        assert_eq!(bits(&f.blocks.lx), widest);
        let rhs: Vec<f64> = (0..n).map(|k| (k % 13) as f64 - 6.0).collect();
        let (mut a, mut b, mut gathered) = (rhs.clone(), rhs, Vec::new());
        f.substitute(&mut a, &mut gathered);
        f.substitute_any(&mut b, &mut gathered);
        assert_eq!(bits(&a), bits(&b));
    }

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
