//! The multiplier solve (DESIGN.md steps 4–6): A λ = −b at one state, the constraint force
//! on each body Σₖ λₖ Jₖᵢ and the accelerations aᵢ = (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ.
//!
//! Design note. Rows are scaled first, Ĵₖ = Jₖ/‖Jₖ‖, so A's diagonal is made of inverse
//! masses and every threshold can be relative; λ is scaled back at the end. The fast path is
//! Cholesky of the scaled A; when it fails (redundant constraints, a singular configuration)
//! an SVD gives the minimum-norm λ, and the diagnostics say which constraints are involved
//! and whether the system is consistent. Active inequality rows are kept by a small active
//! set loop (drop rows whose λ < 0); the Clarabel QP replaces it for large contact sets.
//!
//! Not here: evaluating rows (`numeric::rows`), files, text.

use super::rows::Rows;
use nalgebra::{DMatrix, DVector};

/// Relative tolerance under which a row counts as touching (C ≈ 0) or resting (Ċ ≈ 0).
pub const CONTACT_TOLERANCE: f64 = 1e-9;
/// Singular values below this fraction of the largest are treated as zero.
pub const RANK_TOLERANCE: f64 = 1e-10;

/// Something the caller should know about a solve.
#[derive(Clone, Debug, PartialEq)]
pub struct Diagnostic {
    /// The constraints involved (indices).
    pub constraints: Vec<usize>,
    pub message: String,
}

/// The answer at one state.
#[derive(Clone, Debug, PartialEq)]
pub struct Solution {
    /// λ per constraint (0 for inactive inequalities), referring to C/κ like the rows.
    pub lambda: Vec<f64>,
    /// Whether each constraint takes part (equalities always; inequalities when active).
    pub active: Vec<bool>,
    /// Σₖ λₖ Jₖᵢ per body.
    pub constraint_force: Vec<[f64; 3]>,
    /// (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ per body.
    pub acceleration: Vec<[f64; 3]>,
    pub diagnostics: Vec<Diagnostic>,
}

/// ‖x‖ without overflow or underflow for any finite components.
pub fn safe_norm(x: &[f64; 3]) -> f64 {
    let big = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if big == 0.0 || !big.is_finite() {
        return big;
    }
    let s: f64 = x.iter().map(|v| (v / big) * (v / big)).sum();
    big * s.sqrt()
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Solves for λ at `rows`.
pub fn solve(rows: &Rows) -> Solution {
    let n_bodies = rows.inverse_mass.len();
    let k = rows.rows.len();
    let mut diagnostics = Vec::new();
    // Row scales 1/‖Jₖ‖; a zero gradient leaves the row out (it can carry no force).
    let mut scale = vec![0.0; k];
    for (q, row) in rows.rows.iter().enumerate() {
        let norm = row.jacobian.iter().map(|(_, j)| safe_norm(j)).fold(0.0f64, |a, b| safe_norm(&[a, b, 0.0]));
        if norm > 0.0 && norm.is_finite() {
            scale[q] = 1.0 / norm;
        } else {
            diagnostics.push(Diagnostic {
                constraints: vec![q],
                message: format!(
                    "singular configuration: the gradient of constraint {q} is {} here, so it carries no force",
                    if norm == 0.0 { "zero" } else { "not finite" }
                ),
            });
        }
    }
    let mut active: Vec<bool> = rows
        .rows
        .iter()
        .enumerate()
        .map(|(q, r)| {
            scale[q] > 0.0
                && (!r.inequality || {
                    let (c, rate) = (r.value * scale[q], r.rate * scale[q]);
                    c <= CONTACT_TOLERANCE && rate <= CONTACT_TOLERANCE
                })
        })
        .collect();
    let mut lambda = vec![0.0; k];
    // Active set: solve, drop inequality rows that would pull, repeat (at most k times).
    for _ in 0..=k {
        lambda.iter_mut().for_each(|l| *l = 0.0);
        let index: Vec<usize> = (0..k).filter(|&q| active[q]).collect();
        solve_equalities(rows, &scale, &index, &mut lambda, &mut diagnostics);
        let pulling: Vec<usize> =
            index.iter().copied().filter(|&q| rows.rows[q].inequality && lambda[q] < 0.0).collect();
        if pulling.is_empty() {
            break;
        }
        for q in pulling {
            active[q] = false;
        }
    }
    let mut constraint_force = vec![[0.0; 3]; n_bodies];
    for (q, row) in rows.rows.iter().enumerate() {
        for (b, j) in &row.jacobian {
            for d in 0..3 {
                constraint_force[*b][d] += lambda[q] * j[d];
            }
        }
    }
    let acceleration = (0..n_bodies)
        .map(|i| {
            let (f, fc, w) = (rows.force[i], constraint_force[i], rows.inverse_mass[i]);
            [(f[0] + fc[0]) * w, (f[1] + fc[1]) * w, (f[2] + fc[2]) * w]
        })
        .collect();
    Solution { lambda, active, constraint_force, acceleration, diagnostics }
}

/// Solves the scaled equations of the rows in `index` and writes their λ.
fn solve_equalities(
    rows: &Rows,
    scale: &[f64],
    index: &[usize],
    lambda: &mut [f64],
    diagnostics: &mut Vec<Diagnostic>,
) {
    let n = index.len();
    if n == 0 {
        return;
    }
    // Âₚq = Σᵢ Ĵₚᵢ·Ĵqᵢ/mᵢ and b̂ₚ = Σᵢ Ĵₚᵢ·Fᵢ/mᵢ + ĉₚ, with Ĵ = J/‖J‖.
    let mut a = DMatrix::<f64>::zeros(n, n);
    let mut b = DVector::<f64>::zeros(n);
    for (p, &kp) in index.iter().enumerate() {
        let rp = &rows.rows[kp];
        for &(body, ref j) in &rp.jacobian {
            let w = rows.inverse_mass[body] * scale[kp];
            b[p] += dot(j, &rows.force[body]) * w;
            for (q, &kq) in index.iter().enumerate() {
                for &(other, ref jq) in &rows.rows[kq].jacobian {
                    if other == body {
                        a[(p, q)] += dot(j, jq) * w * scale[kq];
                    }
                }
            }
        }
        b[p] += rp.bias * scale[kp];
    }
    let rhs = -&b;
    let mu = match a.clone().cholesky() {
        Some(ch) if ch.l().diagonal().iter().all(|d| *d > RANK_TOLERANCE.sqrt() * a.diagonal().amax().sqrt()) => {
            ch.solve(&rhs)
        }
        _ => minimum_norm(&a, &rhs, index, diagnostics),
    };
    for (p, &kp) in index.iter().enumerate() {
        lambda[kp] = mu[p] * scale[kp];
        if !lambda[kp].is_finite() {
            diagnostics.push(Diagnostic {
                constraints: vec![kp],
                message: format!("λ of constraint {kp} is not finite; it is set to 0"),
            });
            lambda[kp] = 0.0;
        }
    }
}

/// The minimum-norm solution of a singular `a μ = rhs` by SVD, with a diagnostic.
fn minimum_norm(
    a: &DMatrix<f64>,
    rhs: &DVector<f64>,
    index: &[usize],
    diagnostics: &mut Vec<Diagnostic>,
) -> DVector<f64> {
    let svd = a.clone().svd(true, true);
    let largest = svd.singular_values.amax();
    let threshold = RANK_TOLERANCE * largest;
    let rank = svd.singular_values.iter().filter(|s| **s > threshold).count();
    let mu = svd.solve(rhs, threshold).unwrap_or_else(|_| DVector::zeros(rhs.len()));
    let residual = (a * &mu - rhs).amax();
    let consistent = residual <= 1e-8 * (rhs.amax() + a.amax() * mu.amax()).max(f64::MIN_POSITIVE);
    let smallest = svd.singular_values.iter().copied().filter(|s| *s > threshold).fold(f64::INFINITY, f64::min);
    diagnostics.push(Diagnostic {
        constraints: index.to_vec(),
        message: format!(
            "redundant or singular constraints: rank {rank} of {} (condition of the rest ≈ {:.1e}); {}",
            index.len(),
            largest / smallest,
            if consistent {
                "consistent, minimum-norm λ".to_string()
            } else {
                format!("inconsistent (residual {residual:.2e}), least-squares minimum-norm λ")
            }
        ),
    });
    mu
}
