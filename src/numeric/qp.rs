//! The contact QP (DESIGN.md step 6): min ½λᵀAλ + bᵀλ subject to λₖ ≥ 0 on inequality rows
//! (equality rows free), solved with Clarabel (Goulart & Chen 2024, an interior-point method
//! for conic programs), and its KKT check.
//!
//! With A = J M⁻¹ Jᵀ positive semidefinite, the KKT conditions of this QP are exactly the
//! contact conditions: w = Aλ + b is C̈ (or, with velocity data, the post-impulse rate), and
//! λ ≥ 0, w ≥ 0, λ·w = 0 on inequality rows, w = 0 on equality rows. Clarabel's form is
//! min ½xᵀPx + qᵀx s.t. A x + s = b, s ∈ K: P = A (upper triangle, sparse), q = b, and one
//! row −eₖ with bound 0 in the nonnegative cone per inequality row (so sₖ = λₖ ≥ 0).
//!
//! Interior-point answers are accurate to ~1e-8; `numeric::solve` polishes them with the
//! equality solve on the rows Clarabel finds active. Not here: choosing the rows, scaling.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus, SupportedConeT};

/// What the QP solve came to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QpStatus {
    /// Solved to Clarabel's default tolerances.
    Solved,
    /// Solved to reduced accuracy.
    AlmostSolved,
    /// No λ satisfies the conditions: the contacts and equalities contradict each other.
    Infeasible,
    /// The objective is unbounded below: b has a part A cannot balance (inconsistent rows).
    Unbounded,
    /// The iteration or time limit was reached.
    MaxIterations,
    /// Clarabel stopped on a numerical error or lack of progress.
    NumericalError,
    /// Clarabel refused the problem (a bug in the caller: dimensions or settings).
    Rejected,
}

/// The QP's answer with its optimality residuals.
#[derive(Clone, Debug, PartialEq)]
pub struct QpSolution {
    pub status: QpStatus,
    pub lambda: Vec<f64>,
    pub iterations: u32,
    pub residuals: Kkt,
}

/// KKT residuals of λ for the QP, each relative to max(1, ‖b‖∞) (A should be scaled to a
/// unit diagonal for these to mean something).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Kkt {
    /// max |wₖ| over equality rows, w = Aλ + b.
    pub stationarity: f64,
    /// max of −λₖ and −wₖ over inequality rows (0 when both are nonnegative).
    pub feasibility: f64,
    /// max |λₖ wₖ| / max(1, |λₖ|) over inequality rows.
    pub complementarity: f64,
}

impl Kkt {
    /// The largest of the three residuals.
    pub fn worst(&self) -> f64 {
        self.stationarity.max(self.feasibility).max(self.complementarity)
    }
}

/// A symmetric matrix given by its upper-triangle entries `(i, j, Aᵢⱼ)` with i ≤ j
/// (repeated entries add up).
pub type Triplets = [(usize, usize, f64)];

/// y = A x for a symmetric matrix given by upper-triangle triplets.
pub fn sym_mul(n: usize, a: &Triplets, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; n];
    for &(i, j, v) in a {
        y[i] += v * x[j];
        if i != j {
            y[j] += v * x[i];
        }
    }
    y
}

/// The KKT residuals of `lambda` for min ½λᵀAλ + bᵀλ, λₖ ≥ 0 where `nonnegative[k]`.
pub fn kkt(a: &Triplets, b: &[f64], nonnegative: &[bool], lambda: &[f64]) -> Kkt {
    let n = b.len();
    let w: Vec<f64> = sym_mul(n, a, lambda).iter().zip(b).map(|(x, y)| x + y).collect();
    let scale = b.iter().fold(1.0f64, |m, x| m.max(x.abs()));
    let mut r = Kkt::default();
    for k in 0..n {
        if nonnegative[k] {
            r.feasibility = r.feasibility.max(-lambda[k]).max(-w[k]);
            r.complementarity = r.complementarity.max((lambda[k] * w[k]).abs() / lambda[k].abs().max(1.0));
        } else {
            r.stationarity = r.stationarity.max(w[k].abs());
        }
    }
    r.stationarity /= scale;
    r.feasibility /= scale;
    r.complementarity /= scale;
    r
}

/// Solves min ½λᵀAλ + bᵀλ s.t. λₖ ≥ 0 where `nonnegative[k]`, with Clarabel (quiet).
pub fn solve_qp(a: &Triplets, b: &[f64], nonnegative: &[bool]) -> QpSolution {
    let n = b.len();
    let (mut rows, mut cols, mut vals) = (Vec::new(), Vec::new(), Vec::new());
    for &(i, j, v) in a {
        let (i, j) = if i <= j { (i, j) } else { (j, i) };
        rows.push(i);
        cols.push(j);
        vals.push(v);
    }
    let p = CscMatrix::new_from_triplets(n, n, rows, cols, vals);
    // One row −eₖ per nonnegative variable: −λₖ + sₖ = 0 with sₖ ≥ 0.
    let bounded: Vec<usize> = (0..n).filter(|&k| nonnegative[k]).collect();
    let m = bounded.len();
    let g = CscMatrix::new_from_triplets(m, n, (0..m).collect(), bounded.clone(), vec![-1.0; m]);
    let h = vec![0.0; m];
    let cones = if m > 0 { vec![NonnegativeConeT(m)] } else { Vec::new() };
    let settings = DefaultSettings { verbose: false, ..DefaultSettings::default() };
    let Some(mut solver) = clarabel_solve(&p, b, &g, &h, &cones, settings.clone()) else {
        return QpSolution {
            status: QpStatus::Rejected,
            lambda: vec![0.0; n],
            iterations: 0,
            residuals: Kkt::default(),
        };
    };
    let mut status = qp_status(solver.solution.status);
    if status == QpStatus::NumericalError {
        // Clarabel's equilibration can stall it on a QP that is unbounded (contacts no
        // acceleration satisfies): it stops without a verdict where the unscaled problem
        // gives one (a 2D body held by four contacts that leave it no room, a case found by
        // `tests/numeric_solve.rs`'s `contacts_are_complementary`). Once more without it; a
        // verdict there is kept, else the first answer stands.
        let again = DefaultSettings { equilibrate_enable: false, ..settings };
        if let Some(retry) = clarabel_solve(&p, b, &g, &h, &cones, again) {
            let verdict = qp_status(retry.solution.status);
            if verdict != QpStatus::NumericalError {
                (solver, status) = (retry, verdict);
            }
        }
    }
    let mut lambda = solver.solution.x.clone();
    if !matches!(status, QpStatus::Solved | QpStatus::AlmostSolved) || lambda.iter().any(|x| !x.is_finite()) {
        // Certificates are not answers: report zeros with the status.
        lambda = vec![0.0; n];
    }
    let residuals = kkt(a, b, nonnegative, &lambda);
    QpSolution { status, lambda, iterations: solver.solution.iterations, residuals }
}

/// Clarabel's solver for the QP, solved; `None` when Clarabel refuses the problem.
fn clarabel_solve(
    p: &CscMatrix<f64>,
    q: &[f64],
    g: &CscMatrix<f64>,
    h: &[f64],
    cones: &[SupportedConeT<f64>],
    settings: DefaultSettings<f64>,
) -> Option<DefaultSolver<f64>> {
    let mut solver = DefaultSolver::new(p, q, g, h, cones, settings).ok()?;
    solver.solve();
    Some(solver)
}

/// What Clarabel's status says of the QP.
fn qp_status(status: SolverStatus) -> QpStatus {
    match status {
        SolverStatus::Solved => QpStatus::Solved,
        SolverStatus::AlmostSolved => QpStatus::AlmostSolved,
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => QpStatus::Infeasible,
        SolverStatus::DualInfeasible | SolverStatus::AlmostDualInfeasible => QpStatus::Unbounded,
        SolverStatus::MaxIterations | SolverStatus::MaxTime => QpStatus::MaxIterations,
        SolverStatus::NumericalError
        | SolverStatus::InsufficientProgress
        | SolverStatus::Unsolved
        | SolverStatus::CallbackTerminated => QpStatus::NumericalError,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four contacts on one 2D body (and one on a second) that no acceleration satisfies: the
    /// QP is unbounded. Clarabel with its equilibration stalls ("insufficient progress");
    /// the retry without it finds the ray (the scaled Ã and b̃ of a case
    /// `tests/numeric_solve.rs`'s `contacts_are_complementary` found).
    #[test]
    fn contacts_that_leave_no_room_are_unbounded_not_a_numerical_error() {
        let a = [
            (0, 0, 1.0),
            (0, 1, -0.22181819579198353),
            (0, 2, -0.4609347847105865),
            (0, 3, -0.5762643121190506),
            (1, 1, 0.15264734016268328),
            (1, 1, 0.8473526598373166),
            (1, 2, -0.6905827646367897),
            (1, 3, 0.8579625188148635),
            (2, 2, 1.0000000000000002),
            (2, 3, -0.45964705846772874),
            (3, 3, 1.0),
        ];
        let b = [9.477932665563854, -4.079051392407083, 4.937874387565541, -14.068890331778551];
        let s = solve_qp(&a, &b, &[true; 4]);
        assert_eq!(s.status, QpStatus::Unbounded);
        assert!(s.lambda.iter().all(|x| *x == 0.0), "a certificate is not an answer: {:?}", s.lambda);
    }

    #[test]
    fn one_pushing_and_one_pulling_contact() {
        // Uncoupled rows: λ₀ = 2 (pushes), λ₁ would be −3 so it is 0 with w₁ = 3.
        let a = [(0, 0, 1.0), (1, 1, 1.0)];
        let b = [-2.0, 3.0];
        let s = solve_qp(&a, &b, &[true, true]);
        assert_eq!(s.status, QpStatus::Solved);
        assert!((s.lambda[0] - 2.0).abs() < 1e-7 && s.lambda[1].abs() < 1e-7, "{:?}", s.lambda);
        assert!(s.residuals.worst() < 1e-7, "{:?}", s.residuals);
    }

    #[test]
    fn inconsistent_equality_is_unbounded() {
        // A = 0 on a free row with b ≠ 0: no stationary point.
        let a = [(0, 0, 0.0), (1, 1, 1.0)];
        let s = solve_qp(&a, &[1.0, -1.0], &[false, true]);
        assert_eq!(s.status, QpStatus::Unbounded);
    }
}
