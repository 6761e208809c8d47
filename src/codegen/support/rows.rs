//! Written into every generated module: `solve_rows`, the multiplier solve of `lagrange
//! solve` (`numeric::solve`) on the rows a module computes — the same scaling, contact
//! states, tolerances and minimum-norm convention, so a module gives what `solve` gives.
//!
//! Each row is scaled as `numeric::solve` scales it: Ĵ = J/‖J‖ (‖J‖ without overflow), then
//! J̃ = Ĵ/√Âₖₖ, so Ã = J̃ M⁻¹ J̃ᵀ has a unit diagonal and no product of two raw J is formed
//! (|r| ≈ 1e155 solves as |r| ≈ 1 does). Inequality rows are classified like
//! `numeric::contact` (apart, separating, resting, closing, penetrating; tolerance 1e-9
//! relative to the scene's length and the fastest body of the row); apart and separating
//! rows carry λ = 0. The touching rows are solved as equalities; if an inequality row would
//! pull, Murty's least-index principal pivoting finds the active set (λ ≥ 0 and C̈ ≥ 0 with
//! complementarity — the LCP `solve`'s QP solves, whose answer is unique for a regular Ã).
//! A singular Ã (redundant constraints) gets the λ of least norm √(Σ λ²) for C/κ (the
//! pseudo-inverse's, as `solve` gives), from a symmetric eigendecomposition (cyclic Jacobi)
//! with `solve`'s rank threshold (1e-10 of the largest eigenvalue) and the null-space part
//! chosen in λ; `Status` says so. Where the raw numbers overflow
//! (|r| ≈ 1e155 makes C = r·r − l² ∞ − ∞), the module solves in a length unit scaled by a
//! power of two, verified homogeneous (`degrees`), and scales back, as `solve` does
//! (`numeric::rescale`).
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled
//! by the crate's tests. Not here: the formulas (generated), the closed form of one
//! equality (generated), the band fast path (`solve_band.rs`).

/// Where an inequality row stands (the contact states of `lagrange solve`).
#[allow(dead_code)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contact {
    /// C > 0 beyond the tolerance: no force.
    Apart,
    /// Touching and opening (Ċ > 0): no force.
    Separating,
    /// Touching with Ċ ≈ 0: λ ≥ 0 by complementarity.
    Resting,
    /// Touching and closing (Ċ < 0): it needs an impulse; the force holds it as if resting.
    Closing,
    /// C < 0 beyond the tolerance: treated as touching.
    Penetrating,
}

/// How a solve went, from best to worst (the statuses of `lagrange solve`).
#[allow(dead_code)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Status {
    /// Every condition holds.
    Solved,
    /// Redundant constraints with consistent data: the minimum-norm λ (in the scaled
    /// multipliers λₖ·‖Jₖ‖·√Aₖₖ, which do not depend on how C is written).
    MinimumNorm,
    /// A constraint has a zero gradient here: it carries no force.
    Singular,
    /// The active-set search did not settle: the last λ, clamped.
    Inaccurate,
    /// The constraints contradict each other: the least-squares minimum-norm λ.
    Inconsistent,
    /// Non-finite numbers: λ is 0 on the rows involved.
    Failed,
}

/// One constraint row at a state: C/κ, Ċ/κ, c, and J = ∇C/κ per body it involves.
#[allow(dead_code)]
#[derive(Clone, Debug, PartialEq)]
pub struct Row<const D: usize> {
    pub value: f64,
    pub rate: f64,
    pub bias: f64,
    pub inequality: bool,
    pub jacobian: Vec<(usize, [f64; D])>,
}

/// The answer at one state, as `lagrange solve` gives it.
#[allow(dead_code)]
#[derive(Clone, Debug, PartialEq)]
pub struct Solution<const D: usize> {
    /// λ per constraint, for C/κ (0 for an inequality that is not pushing).
    pub lambda: Vec<f64>,
    /// The contact state of each inequality row (`None` for equalities).
    pub contacts: Vec<Option<Contact>>,
    /// The constraint force Σₖ λₖ Jₖᵢ on each body.
    pub force: Vec<[f64; D]>,
    /// (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ per body.
    pub acceleration: Vec<[f64; D]>,
    pub status: Status,
}

/// Relative tolerance of "touching" and "resting" (`numeric::solve::Settings`).
const CONTACT_TOLERANCE: f64 = 1e-9;
/// Pivots and eigenvalues of the unit-diagonal Ã at or below this are zero.
const RANK_TOLERANCE: f64 = 1e-10;

/// ‖x‖ without overflow or underflow.
#[allow(dead_code)]
fn safe_norm(x: &[f64]) -> f64 {
    let big = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if big == 0.0 || !big.is_finite() {
        return big;
    }
    let s: f64 = x.iter().map(|v| (v / big) * (v / big)).sum();
    big * s.sqrt()
}

/// The contact length of a scene at a state: the largest |rᵢ| (1 when there is none).
#[allow(dead_code)]
fn length_scale<const D: usize>(positions: &[[f64; D]]) -> f64 {
    let length = positions.iter().map(|r| safe_norm(r)).fold(0.0, f64::max);
    if length > 0.0 && length.is_finite() { length } else { 1.0 }
}

/// λ, the forces and the accelerations at a state (see the note at the top of this part).
#[allow(dead_code, clippy::needless_range_loop)]
fn solve_rows<const D: usize>(
    rows: &[Row<D>],
    inverse_mass: &[f64],
    velocity: &[[f64; D]],
    force: &[[f64; D]],
    length: f64,
) -> Solution<D> {
    let (k, n) = (rows.len(), inverse_mass.len());
    let mut status = Status::Solved;
    let bad_body: Vec<bool> = (0..n)
        .map(|i| {
            let w = inverse_mass[i];
            !(w.is_finite() && w >= 0.0) || force[i].iter().chain(&velocity[i]).any(|x| !x.is_finite())
        })
        .collect();
    // Scaling: ‖Jₖ‖, 1/√Âₖₖ and J̃ₖ per usable row.
    let mut norm = vec![0.0; k];
    let mut jacobi = vec![0.0; k];
    let mut scaled: Vec<Vec<(usize, [f64; D])>> = vec![Vec::new(); k];
    let mut contacts = vec![None; k];
    for (q, row) in rows.iter().enumerate() {
        let nq = row.jacobian.iter().map(|(_, j)| safe_norm(j)).fold(0.0, |a, b| safe_norm(&[a, b]));
        // The contact state, as `numeric::contact::classify` gives it.
        if row.inequality {
            let speed = row.jacobian.iter().map(|(b, _)| safe_norm(&velocity[*b])).fold(0.0, f64::max);
            let tol = CONTACT_TOLERANCE;
            contacts[q] = Some(if !(nq > 0.0 && nq.is_finite()) {
                if row.value >= 0.0 { Contact::Apart } else { Contact::Penetrating }
            } else {
                let (distance, rate) = (row.value / nq, row.rate / nq);
                if distance > tol * length {
                    Contact::Apart
                } else if distance.is_nan() || distance < -tol * length {
                    Contact::Penetrating
                } else if rate > tol * speed {
                    Contact::Separating
                } else if rate < -tol * speed {
                    Contact::Closing
                } else {
                    Contact::Resting
                }
            });
        }
        let finite = nq.is_finite()
            && row.bias.is_finite()
            && !row.jacobian.iter().any(|(b, _)| bad_body[*b])
            && (!row.inequality || (row.value.is_finite() && row.rate.is_finite()));
        if !finite {
            status = status.max(Status::Failed);
            continue;
        }
        if nq == 0.0 {
            status = status.max(Status::Singular);
            continue;
        }
        let unit = |j: &[f64; D]| j.map(|x| x / nq);
        let a_kk: f64 =
            row.jacobian.iter().map(|(b, j)| unit(j).iter().map(|x| x * x).sum::<f64>() * inverse_mass[*b]).sum();
        if !(a_kk > 0.0 && a_kk.is_finite()) {
            status = status.max(Status::Singular);
            continue;
        }
        let d = 1.0 / a_kk.sqrt();
        norm[q] = nq;
        jacobi[q] = d;
        scaled[q] = row.jacobian.iter().map(|(b, j)| (*b, unit(j).map(|x| x * d))).collect();
    }
    // Candidates: usable equalities, and inequality rows touching without separating.
    let index: Vec<usize> = (0..k)
        .filter(|&q| norm[q] > 0.0 && !matches!(contacts[q], Some(Contact::Apart) | Some(Contact::Separating)))
        .collect();
    let m = index.len();
    // b̃ₚ = Σᵢ J̃ₚᵢ·Fᵢ wᵢ + c̃ₚ, and Ãₚq = Σᵢ J̃ₚᵢ·J̃qᵢ wᵢ over shared bodies.
    let dot = |a: &[f64; D], b: &[f64; D]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let b: Vec<f64> = index
        .iter()
        .map(|&q| {
            let ext: f64 = scaled[q].iter().map(|(i, j)| dot(j, &force[*i]) * inverse_mass[*i]).sum();
            ext + (rows[q].bias / norm[q]) * jacobi[q]
        })
        .collect();
    let mut a = vec![vec![0.0; m]; m];
    for p in 0..m {
        for r in p..m {
            let mut x = 0.0;
            for (i, jp) in &scaled[index[p]] {
                if let Some((_, jr)) = scaled[index[r]].iter().find(|(j, _)| j == i) {
                    x += dot(jp, jr) * inverse_mass[*i];
                }
            }
            a[p][r] = x;
            a[r][p] = x;
        }
    }
    let nonnegative: Vec<bool> = index.iter().map(|&q| rows[q].inequality).collect();
    // λ_q/μ_p: the minimum norm is taken in λ (for C/κ), as `solve` takes it.
    let weight: Vec<f64> = index.iter().map(|&q| jacobi[q] / norm[q]).collect();
    let mu = multipliers(&a, &b, &weight, &nonnegative, &mut status);
    let mut lambda = vec![0.0; k];
    let mut constraint_force = vec![[0.0; D]; n];
    for (p, &q) in index.iter().enumerate() {
        lambda[q] = (mu[p] * jacobi[q]) / norm[q];
        for (i, j) in &scaled[q] {
            for c in 0..D {
                constraint_force[*i][c] += mu[p] * j[c];
            }
        }
    }
    let acceleration =
        (0..n).map(|i| std::array::from_fn(|c| (force[i][c] + constraint_force[i][c]) * inverse_mass[i])).collect();
    Solution { lambda, contacts, force: constraint_force, acceleration, status }
}

/// The scaled multipliers: the equality solve when no row is `nonnegative`, else the LCP.
#[allow(dead_code)]
fn multipliers(a: &[Vec<f64>], b: &[f64], weight: &[f64], nonnegative: &[bool], status: &mut Status) -> Vec<f64> {
    let n = b.len();
    let clamp = |x: Vec<f64>| -> Vec<f64> {
        x.into_iter().zip(nonnegative).map(|(v, &nn)| if nn { v.max(0.0) } else { v }).collect()
    };
    let everything = vec![true; n];
    if !nonnegative.contains(&true) {
        return subset(a, b, weight, &everything, status);
    }
    let tol = CONTACT_TOLERANCE;
    // Every touching inequality as an equality first: if they all push, that is the answer.
    let mut first = Status::Solved;
    let x = subset(a, b, weight, &everything, &mut first);
    let scale = x.iter().fold(1.0f64, |m, v| m.max(v.abs()));
    if first == Status::Solved && x.iter().zip(nonnegative).all(|(v, &nn)| !nn || *v >= -tol * scale) {
        return clamp(x);
    }
    // Murty's least-index principal pivoting (Murty 1974), from the rows that pushed.
    let mut in_set: Vec<bool> = (0..n).map(|p| !nonnegative[p] || x[p] > 0.0).collect();
    let mut last = x;
    for _ in 0..(200 * n + 1000) {
        let mut s = Status::Solved;
        let x = subset(a, b, weight, &in_set, &mut s);
        let scale = b.iter().chain(&x).fold(1.0f64, |m, v| m.max(v.abs()));
        let w: Vec<f64> = (0..n).map(|p| (0..n).map(|q| a[p][q] * x[q]).sum::<f64>() + b[p]).collect();
        let flip = (0..n)
            .find(|&p| nonnegative[p] && ((in_set[p] && x[p] < -tol * scale) || (!in_set[p] && w[p] < -tol * scale)));
        last = x;
        match flip {
            None => {
                *status = (*status).max(s);
                return clamp(last);
            }
            Some(p) => in_set[p] = !in_set[p],
        }
    }
    *status = (*status).max(Status::Inaccurate);
    clamp(last)
}

/// Solves Ã μ = −b̃ on the rows marked in `keep` (the others get μ = 0): Cholesky with one
/// step of iterative refinement; the minimum-norm solution when Ã is singular there.
#[allow(dead_code, clippy::needless_range_loop)]
fn subset(a: &[Vec<f64>], b: &[f64], weight: &[f64], keep: &[bool], status: &mut Status) -> Vec<f64> {
    let rows: Vec<usize> = (0..b.len()).filter(|&p| keep[p]).collect();
    let m = rows.len();
    let sub: Vec<Vec<f64>> = rows.iter().map(|&p| rows.iter().map(|&q| a[p][q]).collect()).collect();
    let rhs: Vec<f64> = rows.iter().map(|&p| -b[p]).collect();
    let w: Vec<f64> = rows.iter().map(|&p| weight[p]).collect();
    let y = match cholesky(&sub) {
        Some(l) => {
            let mut y = cholesky_solve(&l, &rhs);
            let r: Vec<f64> = (0..m).map(|p| rhs[p] - (0..m).map(|q| sub[p][q] * y[q]).sum::<f64>()).collect();
            let dy = cholesky_solve(&l, &r);
            for p in 0..m {
                y[p] += dy[p];
            }
            y
        }
        None => minimum_norm(&sub, &rhs, &w, status),
    };
    let mut x = vec![0.0; b.len()];
    for (i, &p) in rows.iter().enumerate() {
        x[p] = if y[i].is_finite() {
            y[i]
        } else {
            *status = (*status).max(Status::Failed);
            0.0
        };
    }
    x
}

/// L of A = L Lᵀ, or `None` when a pivot L[i][i]² is at or below the rank tolerance.
#[allow(dead_code, clippy::needless_range_loop)]
fn cholesky(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let mut acc = a[i][j];
            for p in 0..j {
                acc -= l[i][p] * l[j][p];
            }
            if i == j {
                if !(acc > RANK_TOLERANCE && acc.is_finite()) {
                    return None;
                }
                l[i][i] = acc.sqrt();
            } else {
                l[i][j] = acc / l[j][j];
            }
        }
    }
    Some(l)
}

/// x with L Lᵀ x = b.
#[allow(dead_code, clippy::needless_range_loop)]
fn cholesky_solve(l: &[Vec<f64>], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut x = b.to_vec();
    for i in 0..n {
        for p in 0..i {
            x[i] -= l[i][p] * x[p];
        }
        x[i] /= l[i][i];
    }
    for i in (0..n).rev() {
        for p in i + 1..n {
            x[i] -= l[p][i] * x[p];
        }
        x[i] /= l[i][i];
    }
    x
}

/// The minimum-norm (least-squares if inconsistent) solution of a singular symmetric
/// `a x = rhs`: Σ over eigenvalues above the rank threshold of vᵢ (vᵢ·rhs)/σᵢ, from a cyclic
/// Jacobi eigendecomposition (for a symmetric matrix its singular values are |σᵢ|). Of the
/// solutions x₀ + N z (N the null eigenvectors) it returns the one of least ‖W x‖, W the
/// `weight`s λ/μ, so that λ has the least norm, as `solve` gives (when the weights' ratios
/// leave the normal range, x₀ stands).
#[allow(dead_code, clippy::needless_range_loop)]
fn minimum_norm(a: &[Vec<f64>], rhs: &[f64], weight: &[f64], status: &mut Status) -> Vec<f64> {
    let n = rhs.len();
    let mut s: Vec<Vec<f64>> = a.to_vec();
    let mut v: Vec<Vec<f64>> = (0..n).map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect()).collect();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| s[i][j] * s[i][j])
            .sum();
        let diag: f64 = (0..n).map(|i| s[i][i] * s[i][i]).sum();
        if off.is_nan() || off <= 1e-32 * diag {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if s[p][q] == 0.0 {
                    continue;
                }
                // The rotation that zeroes s[p][q] (Golub & Van Loan, §8.5).
                let theta = (s[q][q] - s[p][p]) / (2.0 * s[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let sn = t * c;
                for r in 0..n {
                    let (x, y) = (s[r][p], s[r][q]);
                    s[r][p] = c * x - sn * y;
                    s[r][q] = sn * x + c * y;
                }
                for r in 0..n {
                    let (x, y) = (s[p][r], s[q][r]);
                    s[p][r] = c * x - sn * y;
                    s[q][r] = sn * x + c * y;
                }
                for r in 0..n {
                    let (x, y) = (v[r][p], v[r][q]);
                    v[r][p] = c * x - sn * y;
                    v[r][q] = sn * x + c * y;
                }
            }
        }
    }
    let largest = (0..n).map(|i| s[i][i].abs()).fold(0.0, f64::max);
    let threshold = RANK_TOLERANCE * largest.max(f64::MIN_POSITIVE);
    let mut x = vec![0.0; n];
    for e in 0..n {
        let sigma = s[e][e];
        if sigma.abs() > threshold {
            let along = (0..n).map(|r| v[r][e] * rhs[r]).sum::<f64>() / sigma;
            for r in 0..n {
                x[r] += v[r][e] * along;
            }
        }
    }
    let null: Vec<usize> = (0..n).filter(|&e| s[e][e].abs() <= threshold || s[e][e].is_nan()).collect();
    let top = weight.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let w: Vec<f64> = weight.iter().map(|x| x / top).collect();
    if !null.is_empty() && w.len() == n && w.iter().all(|x| x.is_normal()) {
        // min over z of ‖W (x₀ + N z)‖: (Nᵀ W² N) z = −Nᵀ W² x₀, scaled to a unit diagonal.
        let m = null.len();
        let g: Vec<Vec<f64>> = (0..m)
            .map(|i| (0..m).map(|j| (0..n).map(|r| w[r] * w[r] * v[r][null[i]] * v[r][null[j]]).sum()).collect())
            .collect();
        let h: Vec<f64> = (0..m).map(|i| -(0..n).map(|r| w[r] * w[r] * v[r][null[i]] * x[r]).sum::<f64>()).collect();
        let d: Vec<f64> = (0..m).map(|i| 1.0 / g[i][i].sqrt()).collect();
        let unit: Vec<Vec<f64>> = (0..m).map(|i| (0..m).map(|j| g[i][j] * d[i] * d[j]).collect()).collect();
        if let Some(l) = cholesky(&unit) {
            let z = cholesky_solve(&l, &h.iter().zip(&d).map(|(y, e)| y * e).collect::<Vec<f64>>());
            let moved: Vec<f64> =
                (0..n).map(|r| x[r] + (0..m).map(|i| v[r][null[i]] * z[i] * d[i]).sum::<f64>()).collect();
            if moved.iter().all(|y| y.is_finite()) {
                x = moved;
            }
        }
    }
    let amax = |xs: &mut dyn Iterator<Item = f64>| xs.fold(0.0f64, |m, y| m.max(y.abs()));
    let residual = amax(&mut (0..n).map(|p| (0..n).map(|q| a[p][q] * x[q]).sum::<f64>() - rhs[p]));
    let size = amax(&mut rhs.iter().copied()) + amax(&mut a.iter().flatten().copied()) * amax(&mut x.iter().copied());
    let consistent = size == 0.0 || residual <= CONTACT_TOLERANCE.sqrt() * 1e-2 * size;
    *status = (*status).max(if consistent { Status::MinimumNorm } else { Status::Inconsistent });
    x
}

/// x · 2ᵉ without an intermediate overflow or underflow of the factor; once x is 0, ∞ or
/// NaN it stays so and the chunks stop (a row that underflowed to 0 at half the scale
/// gives the degree `i64::MAX`).
///
/// Never inlined: `scaled_state` calls it once per number of the state, and rustc at
/// opt-level 3 overflows its own stack (LLVM's scalar evolution recursing over the chained
/// loops) on a 100-link chain's module when each call carries its two loops inline.
#[allow(dead_code)]
#[inline(never)]
fn pow2(mut x: f64, mut e: i64) -> f64 {
    while e > 1000 && x.is_finite() && x != 0.0 {
        x *= 2f64.powi(1000);
        e -= 1000;
    }
    while e < -1000 && x.is_finite() && x != 0.0 {
        x *= 2f64.powi(-1000);
        e += 1000;
    }
    if !(-1000..=1000).contains(&e) {
        return x;
    }
    x * 2f64.powi(e as i32)
}

/// Whether every number the solve reads is finite.
#[allow(dead_code)]
fn rows_finite<const D: usize>(
    rows: &[Row<D>],
    inverse_mass: &[f64],
    velocity: &[[f64; D]],
    force: &[[f64; D]],
) -> bool {
    inverse_mass.iter().all(|x| x.is_finite())
        && velocity.iter().chain(force).flatten().all(|x| x.is_finite())
        && rows.iter().all(|r| {
            r.value.is_finite()
                && r.rate.is_finite()
                && r.bias.is_finite()
                && r.jacobian.iter().all(|(_, j)| j.iter().all(|x| x.is_finite()))
        })
}

/// The degree p of each row if `at` (a state scaled by 2ᵉ) and `half` (by 2ᵉ⁻¹) differ
/// exactly as a homogeneous row would (C, Ċ, c by 2ᵖ, J by 2ᵖ⁻¹), else `None`.
#[allow(dead_code)]
fn degrees<const D: usize>(at: &[Row<D>], half: &[Row<D>]) -> Option<Vec<i64>> {
    let exact = |a: f64, b: f64, p: i64| a == pow2(b, p);
    let mut out = Vec::with_capacity(at.len());
    for (a, b) in at.iter().zip(half) {
        let scalars = [(a.value, b.value), (a.rate, b.rate), (a.bias, b.bias)];
        let from_scalar = scalars.iter().find(|(x, _)| *x != 0.0).map(|&(x, y)| (x / y).log2().round() as i64);
        let from_j = a
            .jacobian
            .iter()
            .zip(&b.jacobian)
            .flat_map(|((_, x), (_, y))| x.iter().zip(y).map(|(x, y)| (*x, *y)))
            .find(|(x, _)| *x != 0.0)
            .map(|(x, y)| ((x / y).log2().round() as i64).saturating_add(1));
        let p = from_scalar.or(from_j).unwrap_or(0);
        let ok = scalars.iter().all(|&(x, y)| exact(x, y, p))
            && a.jacobian
                .iter()
                .zip(&b.jacobian)
                .all(|((_, x), (_, y))| x.iter().zip(y).all(|(x, y)| exact(*x, *y, p.saturating_sub(1))));
        if !ok {
            return None;
        }
        out.push(p);
    }
    Some(out)
}
