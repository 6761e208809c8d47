//! λ of a chain of equality rows from one program of the derivation's formulas: A's band
//! entries (`Derivation::a`), each row's c and J and each body's mass and force, evaluated
//! by one [`Tape`] (or its compiled twin), then L D Lᵀ written for the tridiagonal band under
//! a pivot guard, to λ, the constraint forces and the accelerations. What the generated
//! module's `band_system` and `solve_tridiagonal` do (`codegen::rust`), in the library.
//!
//! Design note. The rows' path (`RowProgram::evaluate_into`, then `solve::solve_into`)
//! evaluates every row's C, Ċ, c and J, fills `Rows`, then scales each row by ‖J‖ and the
//! Jacobi factor, assembles Ã term by term and factors it, with the refinement's residual:
//! general, and about 860 instructions a row of a chain. Here the formulas of A's entries
//! are known when the program is made (the derivation assembled them symbolically), so A's
//! band comes out of the tape as numbers, with no `Rows`, no scaling and no assembly; b is
//! c + Σᵢ Jᵢ·Fᵢ/mᵢ from the same outputs (the derivation's b reads the force symbols,
//! where a scene gives forces by expressions, which the program evaluates), and the
//! accelerations (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ from the same J. Only what this path can answer as the
//! general solve would is served; everything else is declined, and the caller takes the
//! rows' solve ([`BandLambda::solve_or_rows_into`] does both).
//!
//! Served: point masses only (no rigid body), every row an equality, A tridiagonal in the
//! rows' listing order (every entry Aₖⱼ with |k − j| ≤ 1, every Aₖₖ a formula), no more
//! rows than the velocity components they move. Declined at construction (`None`): rigid
//! bodies, inequality rows, a wider band or a band only a renumbering finds (the rows' solve
//! renumbers by reverse Cuthill–McKee), a zero diagonal formula.
//!
//! The guard, per call ([`BandLambda::solve_into`] returns false, `out` untouched):
//! - the settings' [`Method`] is [`Method::Banded`], or [`Method::Auto`] with more than
//!   four rows (`Auto` solves fewer densely; the same rule as the rows' chain path);
//! - every input (the state, the parameters, the masses) and every output of the program
//!   is finite, every mass m gives a positive normal 1/m (an infinite or zero mass is the
//!   general solve's `InfiniteMass`, a non-finite number its `NonFiniteRow`);
//! - every Aₖₖ is a positive normal number (a zero or subnormal one is a zero gradient or a
//!   state whose numbers leave f64's range, which the general solve rescales), and every
//!   pivot dₖ > τ Aₖₖ, τ the settings' `rank_tolerance` (the general solve's relative
//!   threshold on the Jacobi-scaled Ã = D A D with D = diag(Aₖₖ)^−½, whose pivots are
//!   exactly dₖ/Aₖₖ: the same test, so a state it calls singular or redundant is declined);
//! - every λₖ is zero or a normal number (the general solve's `LambdaOutOfRange` and
//!   `NonFiniteLambda`), and every acceleration is finite.
//!
//! Accuracy: what λ loses against the scaled solve. The general solve factors the
//! Jacobi-scaled Ã = D A D, this one A itself. Cholesky (and L D Lᵀ, its square-root-free
//! form) is invariant under diagonal scaling in exact arithmetic, and in floating point its
//! backward error is too: the computed factor of A satisfies L̂ D̂ L̂ᵀ = A + ΔA with
//! |ΔA| ≤ γ₃ |L̂| D̂ |L̂ᵀ| componentwise (Higham, *Accuracy and Stability of Numerical
//! Algorithms*, 2nd ed., §10.1, Thm 10.3; for a tridiagonal §9.6: the factor of an SPD
//! tridiagonal has no growth, |L̂| D̂ |L̂ᵀ| = |L̂ D̂ L̂ᵀ| entry by entry), and the bound on ΔA
//! relative to (Aᵢᵢ Aⱼⱼ)^½ is the same whatever diagonal scaling is applied first, because
//! scaling by powers of two commutes with every rounding and any other scaling changes the
//! bound only by the scaling's own rounding (Thm 10.6 and the remark after it: the forward
//! error of the solve is governed by κ₂(D A D) for the best D, whether or not D is applied;
//! van der Sluis: the Jacobi D is within a factor of the band's width, here 3, of the best).
//! So λ here and the scaled solve's λ both carry a relative error of order κ₂(Ã) u, and
//! differ from each other by that much; the general solve also takes a step of refinement
//! when its residual asks, which this path does not (the chain path's analysis, `chain.rs`
//! `REFINE_BOUND`: the step is not needed for a backward stable solve). The forward error
//! bound is then ‖λ̂ − λ‖/‖λ‖ ≲ c κ₂(Ã) u with c a small constant, for both paths;
//! `tests/band_lambda.rs` holds this path's error against a double-double reference to a
//! small factor of the scaled solve's over random and ill-conditioned chains.
//!
//! Not here: the rows' C and Ċ (a projection needs them: `numeric::rows`), inequality rows,
//! wider bands, rigid bodies, diagnostics (a declined state gets them from the rows' solve).

use crate::derive::Derivation;
use crate::expr::eval::{Env, Value};
use crate::expr::graph::SymbolWalk;
use crate::expr::{Id, Symbol};
use crate::model::system::System;
use crate::numeric::rows::{RowProgram, RowScratch, Rows};
use crate::numeric::solve::{self, Method, Settings, Solution, Status};
use crate::numeric::tape::{Scratch, Tape};
use crate::numeric::vector::all_finite;

/// No entry: a row's A[k][k + 1] that is zero (the last row's, or a simplified zero).
const ABSENT: u32 = u32::MAX;

/// A chain's λ from one program of A's band, c, J, the masses and the forces (see the
/// module's note for what it serves and what its guard declines).
#[derive(Clone, Debug)]
pub struct BandLambda {
    tape: Tape,
    /// The tape compiled to machine code, once [`BandLambda::compile`] has made it.
    #[cfg(feature = "jit")]
    compiled: Option<std::sync::Arc<crate::numeric::jit::JitTape>>,
    /// The tape's input symbols, in its layout's order.
    inputs: Vec<Symbol>,
    dim: usize,
    /// Per row, where its numbers are among the outputs.
    rows: Vec<RowAt>,
    /// Every row's J entries in turn: (first output, body).
    entries: Vec<(u32, u32)>,
    /// Per body: the output of its mass, of its force's first component.
    bodies: Vec<(u32, u32)>,
    // Buffers of one call.
    input: Vec<f64>,
    output: Vec<f64>,
    scratch: Scratch,
    /// Per body: 1/m, and F/m.
    inverse_mass: Vec<f64>,
    weighted: Vec<[f64; 3]>,
    /// Per row: 1/dₖ, Lₖ = A[k − 1][k]/dₖ₋₁, y then λ.
    inverse_pivot: Vec<f64>,
    multiplier: Vec<f64>,
    lambda: Vec<f64>,
    /// Per body: Σₖ λₖ Jₖᵢ.
    force: Vec<[f64; 3]>,
}

/// One row's outputs: A[k][k], A[k][k + 1] (`ABSENT`: zero), c, and its J entries
/// `entries[start..end]`.
#[derive(Clone, Copy, Debug)]
struct RowAt {
    diagonal: u32,
    upper: u32,
    bias: u32,
    start: u32,
    end: u32,
}

/// Whether `method` lets a chain of `k` rows be solved by a band factor: the rule of the
/// rows' chain path (`Auto` solves four rows or fewer densely).
fn allowed(method: Method, k: usize) -> bool {
    match method {
        Method::Banded => k > 0,
        Method::Auto => k > 4,
        Method::Dense | Method::Sparse => false,
    }
}

impl BandLambda {
    /// The program of `derivation`'s chain, with `forces` the scene's force expressions by
    /// body (the others are the bodies' force symbols, as [`RowProgram::new`] takes them);
    /// `None` for a system it does not serve (see the module's note).
    pub fn new(system: &System, derivation: &Derivation, forces: &[(usize, Id)]) -> Option<BandLambda> {
        let k = derivation.constraints.len();
        let dim = system.dim();
        let point_masses = system.bodies.iter().all(|b| b.rigid.is_none());
        let equalities = system.constraints.iter().all(|c| !c.inequality);
        if k == 0 || !point_masses || !equalities || !matches!(dim, 2 | 3) || k >= ABSENT as usize {
            return None;
        }
        // A tridiagonal in the listing order, with a formula on every diagonal entry.
        let mut diagonal = vec![None; k];
        let mut upper = vec![None; k];
        for &(r, c, id) in &derivation.a {
            match c.checked_sub(r) {
                Some(0) => diagonal[r] = Some(id),
                Some(1) => upper[r] = Some(id),
                _ => return None,
            }
        }
        // No more rows than the velocity components they move: past that A is singular
        // whatever the state (the general solve's `structurally_singular`).
        let mut moved = vec![false; system.bodies.len()];
        for d in &derivation.constraints {
            for &(b, _) in &d.jacobian {
                moved[b] = true;
            }
        }
        if k > dim * moved.iter().filter(|m| **m).count() {
            return None;
        }
        // The roots: per row A[k][k], A[k][k + 1], c, J; per body m, F.
        let mut roots = Vec::new();
        let mut at_root = Vec::with_capacity(k);
        for (r, d) in derivation.constraints.iter().enumerate() {
            let diagonal = diagonal[r]?;
            let first = roots.len();
            roots.push(diagonal);
            roots.extend(upper[r]);
            roots.push(d.bias);
            roots.extend(d.jacobian.iter().map(|&(_, j)| j));
            at_root.push((first, upper[r].is_some()));
        }
        let body_roots = roots.len();
        for (i, body) in system.bodies.iter().enumerate() {
            let f = forces.iter().find(|(b, _)| *b == i).map_or(body.nodes.force, |&(_, f)| f);
            roots.push(body.mass);
            roots.push(f);
        }
        let graph = &derivation.graph;
        let inputs = SymbolWalk::default().free_symbols_of(graph, &roots).to_vec();
        let tape = Tape::compile(graph, &roots, &inputs).ok()?;
        let out = |root: usize| tape.output_range(root).start as u32;
        let (mut rows, mut entries) = (Vec::with_capacity(k), Vec::new());
        for (d, &(first, has_upper)) in derivation.constraints.iter().zip(&at_root) {
            let bias = first + 1 + usize::from(has_upper);
            let start = entries.len() as u32;
            for (e, &(body, _)) in d.jacobian.iter().enumerate() {
                // A J entry of another width than the dimension is not a point mass's.
                if tape.output_range(bias + 1 + e).len() != dim {
                    return None;
                }
                entries.push((out(bias + 1 + e), body as u32));
            }
            rows.push(RowAt {
                diagonal: out(first),
                upper: if has_upper { out(first + 1) } else { ABSENT },
                bias: out(bias),
                start,
                end: entries.len() as u32,
            });
        }
        let mut bodies = Vec::with_capacity(system.bodies.len());
        for i in 0..system.bodies.len() {
            let (mass, force) = (body_roots + 2 * i, body_roots + 2 * i + 1);
            if tape.output_range(mass).len() != 1 || tape.output_range(force).len() != dim {
                return None;
            }
            bodies.push((out(mass), out(force)));
        }
        let n = bodies.len();
        Some(BandLambda {
            input: vec![0.0; tape.input_len()],
            output: vec![0.0; tape.output_len()],
            scratch: tape.scratch(),
            tape,
            #[cfg(feature = "jit")]
            compiled: None,
            inputs,
            dim,
            rows,
            entries,
            bodies,
            inverse_mass: vec![0.0; n],
            weighted: vec![[0.0; 3]; n],
            inverse_pivot: vec![0.0; k],
            multiplier: vec![0.0; k],
            lambda: vec![0.0; k],
            force: vec![[0.0; 3]; n],
        })
    }

    /// How many rows the program solves.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// Whether the program has no rows (never: [`new`](BandLambda::new) declines them).
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// How many instructions the program's tape holds ([`Tape::instructions`]).
    pub fn instructions(&self) -> usize {
        self.tape.instructions()
    }

    /// Compiles the program's tape to machine code ([`Tape::jit`]), the same numbers bit for
    /// bit; never done unless asked (as [`RowProgram::compile`]). On failure the tape stays
    /// interpreted and the error is returned.
    #[cfg(feature = "jit")]
    pub fn compile(&mut self) -> Result<(), crate::numeric::jit::JitError> {
        if self.compiled.is_none() {
            self.compiled = Some(std::sync::Arc::new(self.tape.jit()?));
        }
        Ok(())
    }

    /// Whether the tape runs as machine code ([`compile`](BandLambda::compile)).
    pub fn is_compiled(&self) -> bool {
        #[cfg(feature = "jit")]
        return self.compiled.is_some();
        #[cfg(not(feature = "jit"))]
        false
    }

    /// λ, the constraint forces and the accelerations at the state `env` (of the system the
    /// program was made from) into `out`, its status `Solved` with no
    /// diagnostic, when the guard passes (see the module's note); false, `out` untouched,
    /// when it declines: the caller then evaluates the rows and takes
    /// [`solve::solve_into`], which gives the answer or the diagnostic this path cannot
    /// ([`solve_or_rows_into`](BandLambda::solve_or_rows_into) does both).
    pub fn solve_into(&mut self, env: &Env, settings: &Settings, out: &mut Solution) -> bool {
        let k = self.rows.len();
        if !allowed(settings.method, k) || !self.evaluate(env) {
            return false;
        }
        let dim = self.dim;
        let o = &self.output[..];
        // 1/m and F/m per body: 1/m a positive normal number.
        let mut ok = true;
        for (i, &(mass, force)) in self.bodies.iter().enumerate() {
            let w = 1.0 / o[mass as usize];
            ok &= w.is_normal() & (w > 0.0);
            let f = &o[force as usize..force as usize + dim];
            let mut weighted = [0.0; 3];
            for (x, f) in weighted.iter_mut().zip(f) {
                *x = f * w;
            }
            self.inverse_mass[i] = w;
            self.weighted[i] = weighted;
        }
        // Row by row: −bₖ = −(cₖ + Σᵢ Jₖᵢ·Fᵢ/mᵢ); dₖ = A[k][k] − A[k − 1][k]² / dₖ₋₁,
        // Lₖ = A[k − 1][k] / dₖ₋₁, yₖ = −bₖ − Lₖ yₖ₋₁ (L y = −b).
        let tolerance = settings.rank_tolerance;
        let (mut e, mut inverse_prev, mut y_prev) = (0.0, 0.0, 0.0);
        for (q, row) in self.rows.iter().enumerate() {
            let mut b = o[row.bias as usize];
            for &(at, body) in &self.entries[row.start as usize..row.end as usize] {
                let (j, w) = (&o[at as usize..at as usize + dim], &self.weighted[body as usize]);
                b += j.iter().zip(w).map(|(j, w)| j * w).sum::<f64>();
            }
            let diagonal = o[row.diagonal as usize];
            let d = diagonal - e * e * inverse_prev;
            ok &= (diagonal >= f64::MIN_POSITIVE) & (d > tolerance * diagonal);
            let l = e * inverse_prev;
            let y = -b - l * y_prev;
            self.inverse_pivot[q] = 1.0 / d;
            self.multiplier[q] = l;
            self.lambda[q] = y;
            e = if row.upper == ABSENT { 0.0 } else { o[row.upper as usize] };
            (inverse_prev, y_prev) = (self.inverse_pivot[q], y);
        }
        if !ok {
            return false;
        }
        // D Lᵀ λ = y: λ_{K−1} = y_{K−1}/d_{K−1}, λₖ = yₖ/dₖ − Lₖ₊₁ λₖ₊₁; each λ zero or normal.
        let mut next = 0.0;
        let mut next_multiplier = 0.0;
        for q in (0..k).rev() {
            let x = self.lambda[q] * self.inverse_pivot[q] - next_multiplier * next;
            ok &= (x == 0.0) | x.is_normal();
            self.lambda[q] = x;
            (next, next_multiplier) = (x, self.multiplier[q]);
        }
        if !ok {
            return false;
        }
        // Σₖ λₖ Jₖᵢ per body, then aᵢ = (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ, finite.
        self.force.fill([0.0; 3]);
        for (row, &x) in self.rows.iter().zip(&self.lambda) {
            for &(at, body) in &self.entries[row.start as usize..row.end as usize] {
                let f = &mut self.force[body as usize];
                for (f, j) in f.iter_mut().zip(&o[at as usize..at as usize + dim]) {
                    *f += x * j;
                }
            }
        }
        let n = self.bodies.len();
        let mut acceleration_bits = 0.0;
        for i in 0..n {
            let (fc, w, force) = (self.force[i], self.inverse_mass[i], self.bodies[i].1 as usize);
            for d in 0..dim {
                acceleration_bits += ((o[force + d] + fc[d]) * w) * 0.0;
            }
        }
        if acceleration_bits != 0.0 {
            return false;
        }
        out.lambda.clear();
        out.lambda.extend_from_slice(&self.lambda);
        out.active.clear();
        out.active.resize(k, true);
        out.constraint_force.clear();
        out.constraint_force.extend_from_slice(&self.force);
        out.acceleration.clear();
        for i in 0..n {
            let (fc, w, force) = (self.force[i], self.inverse_mass[i], self.bodies[i].1 as usize);
            let mut a = [0.0; 3];
            for d in 0..dim {
                a[d] = (o[force + d] + fc[d]) * w;
            }
            out.acceleration.push(a);
        }
        out.diagnostics.clear();
        out.status = Status::Solved;
        out.contacts.clear();
        out.contacts.resize(k, None);
        true
    }

    /// [`solve_into`](BandLambda::solve_into), and where it declines the rows of `program`
    /// (the same system's, with the same forces) evaluated into `rows` and
    /// [`solve::solve_into`]: the answer the caller would have had from the rows, with their
    /// diagnostics. Returns whether the band path answered; an error when the rows could not
    /// be evaluated (a symbol without a value).
    #[allow(clippy::too_many_arguments)]
    pub fn solve_or_rows_into(
        &mut self,
        system: &System,
        env: &Env,
        settings: &Settings,
        program: &RowProgram,
        scratch: &mut RowScratch,
        rows: &mut Rows,
        out: &mut Solution,
    ) -> Result<bool, crate::expr::eval::EvalError> {
        if self.solve_into(env, settings, out) {
            return Ok(true);
        }
        program.evaluate_into(system, env, scratch, rows)?;
        solve::solve_into(rows, settings, out);
        Ok(false)
    }

    /// The program's inputs from `env`, then its outputs: false when a symbol has no value
    /// or a number is not finite.
    fn evaluate(&mut self, env: &Env) -> bool {
        for (&s, at) in self.inputs.iter().zip(self.tape.input_ranges()) {
            let slots = &mut self.input[at.clone()];
            match env.get(s) {
                Some(Value::Scalar(x)) => slots.fill(x),
                Some(Value::Vector(v)) => slots.iter_mut().zip(v).for_each(|(d, x)| *d = x),
                Some(Value::Quaternion(_)) | None => return false,
            }
        }
        #[cfg(feature = "jit")]
        if let Some(compiled) = &self.compiled {
            compiled.eval(&self.input, &mut self.output);
            return all_finite(&self.input) && all_finite(&self.output);
        }
        self.tape.eval(&self.input, &mut self.scratch, &mut self.output);
        all_finite(&self.input) && all_finite(&self.output)
    }
}
