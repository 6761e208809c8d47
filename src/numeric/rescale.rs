//! Solving where the raw rows overflow: evaluate at a state rescaled by a power of two, solve
//! there, and scale the answer back.
//!
//! At |r| ≈ 1e155, C = r·r − l² is ∞ − ∞ and at |v| ≈ 1e155 the c term v·v is ∞, although
//! the force is finite. Changing the length unit by s = 2⁻ᵏ multiplies positions,
//! velocities, forces and length-like parameters by s, and a row homogeneous of degree p
//! in them gives C → sᵖC, Ċ → sᵖĊ, c → sᵖc, J → sᵖ⁻¹J; the forces then come out times s and
//! λ (for C/κ) times s²⁻ᵖ. Masses and t are not scaled. Which parameters are lengths is not
//! known, so every parameter outside the masses is scaled, and the scaling is *verified*:
//! the rows are evaluated at s and at s/2, and every number must change by the exact power
//! of two its degree predicts (powers of two scale floating-point results exactly). A row
//! that is not homogeneous (sin(ω t) with ω scaled, `l^2 + 1`) fails the check, and the raw
//! answer, with its diagnostics, stands.
//!
//! [`Unit`] is that change of unit as a value: [`solve_at`] uses it for one state when the
//! raw rows overflow; a simulation (`numeric::dynamics::Dynamics::choose_unit`) uses it for
//! a whole run when the scene's lengths are far from 1, integrating in the new unit and
//! converting what it reports back (exactly: the factors are powers of two).
//!
//! One unit for a whole scene can erase a part of it: two independent pendulums at 1e200
//! and at 1, in a unit of 2^664, put the small one's numbers below f64's range (its force
//! came out [0, 0]). [`solve_at`] therefore works per independent block (constraints that
//! share bodies, transitively): a block whose own size is nearer the caller's unit than the
//! new one, and whose raw numbers the solve needs are finite, keeps its raw solution
//! (`Diagnostic::MixedScales` names it). A simulation integrates in one unit, so it refuses
//! such a scene instead (`Dynamics::choose_unit`, [`spread`]).
//!
//! Not here: the solve itself (`numeric::solve`), files or text.

use super::rows::{RowProgram, Rows};
use super::solve::{Diagnostic, Settings, Solution, solve_with};
use crate::expr::Symbol;
use crate::expr::eval::{Env, EvalError, Value};
use crate::model::system::System;

/// `pow2` applies its factor in chunks of 2^±`POW2_CHUNK`: a normal f64 (the range ends near
/// 2^±1022), so every partial product is exact and none overflows on the way.
const POW2_CHUNK: i64 = 1000;

/// x · 2ᵉ without an intermediate overflow or underflow of the factor. Once x is 0,
/// infinite or NaN it stays so, and the chunks stop: a degree read from a row whose number
/// underflowed to 0 at half the scale is log₂(x/0) = ∞, i.e. `i64::MAX`, which would
/// otherwise loop 10¹⁶ times.
pub fn pow2(mut x: f64, mut e: i64) -> f64 {
    while e > POW2_CHUNK && x.is_finite() && x != 0.0 {
        x *= 2f64.powi(POW2_CHUNK as i32);
        e -= POW2_CHUNK;
    }
    while e < -POW2_CHUNK && x.is_finite() && x != 0.0 {
        x *= 2f64.powi(-POW2_CHUNK as i32);
        e += POW2_CHUNK;
    }
    if !(-POW2_CHUNK..=POW2_CHUNK).contains(&e) {
        return x;
    }
    x * 2f64.powi(e as i32)
}

fn rows_finite(rows: &Rows) -> bool {
    let v3 = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
    rows.inverse_mass.iter().all(|x| x.is_finite())
        && rows.velocity.iter().all(v3)
        && rows.force.iter().all(v3)
        && rows.rows.iter().all(|r| {
            r.value.is_finite() && r.rate.is_finite() && r.bias.is_finite() && r.jacobian.iter().all(|(_, j)| v3(j))
        })
}

/// The symbols a change of length unit scales: positions, velocities, forces and the
/// parameters that no mass depends on.
fn length_symbols(system: &System) -> Vec<Symbol> {
    // Each distinct mass expression once (a chain's bodies share one `m`): a run asks this
    // at its start, and a long chain's bodies collected the same free symbols each.
    let mut masses: Vec<_> = system.bodies.iter().map(|b| b.mass).collect();
    masses.sort_unstable();
    masses.dedup();
    let mass_symbols: Vec<Symbol> = masses.into_iter().flat_map(|m| system.graph.free_symbols(m)).collect();
    let mut out: Vec<Symbol> = system.bodies.iter().flat_map(|b| [b.position, b.velocity, b.force]).collect();
    out.extend(system.parameters.iter().map(|&(_, s)| s).filter(|s| !mass_symbols.contains(s)));
    out
}

fn scaled_env(env: &Env, symbols: &[Symbol], e: i64) -> Env {
    let mut out = env.clone();
    for &s in symbols {
        match env.get(s) {
            Some(Value::Scalar(x)) => out.set(s, Value::Scalar(pow2(x, e))),
            Some(Value::Vector(v)) => out.set(s, Value::Vector(v.map(|x| pow2(x, e)))),
            // An orientation has no length.
            Some(Value::Quaternion(_)) | None => {}
        }
    }
    out
}

/// The degree p of each row if `at` (scaled by 2ᵉ) and `half` (by 2ᵉ⁻¹) differ exactly as a
/// homogeneous row would, else `None`.
fn degrees(at: &Rows, half: &Rows) -> Option<Vec<i64>> {
    let exact = |a: f64, b: f64, p: i64| a == pow2(b, p);
    let body_ok = at.inverse_mass == half.inverse_mass
        && at.velocity.iter().zip(&half.velocity).all(|(a, b)| (0..3).all(|d| exact(a[d], b[d], 1)))
        && at.force.iter().zip(&half.force).all(|(a, b)| (0..3).all(|d| exact(a[d], b[d], 1)));
    if !body_ok {
        return None;
    }
    let mut out = Vec::new();
    for (a, b) in at.rows.iter().zip(&half.rows) {
        // The degree from the first non-zero number: scalars have degree p, J has p − 1.
        let scalars = [(a.value, b.value), (a.rate, b.rate), (a.bias, b.bias)];
        let from_scalar = scalars.iter().find(|(x, _)| *x != 0.0).map(|&(x, y)| (x / y).log2().round() as i64);
        let from_j = a
            .jacobian
            .iter()
            .zip(&b.jacobian)
            .flat_map(|((_, x), (_, y))| (0..3).map(move |d| (x[d], y[d])))
            .find(|(x, _)| *x != 0.0)
            .map(|(x, y)| ((x / y).log2().round() as i64).saturating_add(1));
        let p = from_scalar.or(from_j).unwrap_or(0);
        let ok = scalars.iter().all(|&(x, y)| exact(x, y, p))
            && a.jacobian
                .iter()
                .zip(&b.jacobian)
                .all(|((_, x), (_, y))| (0..3).all(|d| exact(x[d], y[d], p.saturating_sub(1))));
        if !ok {
            return None;
        }
        out.push(p);
    }
    Some(out)
}

/// A change of length unit to 2ᵏ (one new unit is 2ᵏ old ones), verified homogeneous for a
/// program at a state: positions, velocities, forces and the length-like parameters are
/// multiplied by 2⁻ᵏ, and row q's numbers change by the exact power of two of its degree.
/// Converting with powers of two is exact, so a run in the new unit is the run in the old
/// one, scaled — with every intermediate number near 1 instead of near the ends of the
/// f64 range.
#[derive(Clone, Debug, PartialEq)]
pub struct Unit {
    /// k.
    pub exponent: i64,
    /// The degree p of each row: C, Ċ and c scale by 2^{kp}, J by 2^{k(p−1)}.
    pub degrees: Vec<i64>,
    symbols: Vec<Symbol>,
}

impl Unit {
    /// The exponent k that brings the largest length-like number of `env` (a position,
    /// velocity, force or parameter outside the masses) into [1, 2); `None` when there is
    /// none, or it is not finite.
    pub fn exponent_at(system: &System, env: &Env) -> Option<i64> {
        let big = length_symbols(system)
            .iter()
            .filter_map(|&s| env.get(s))
            .flat_map(|v| match v {
                Value::Scalar(x) => [x, 0.0, 0.0],
                Value::Vector(v) => v,
                Value::Quaternion(_) => [0.0; 3],
            })
            .fold(0.0f64, |m, x| m.max(x.abs()));
        (big.is_finite() && big > 0.0).then(|| big.log2().floor() as i64)
    }

    /// The unit 2ᵏ for `program` at `env`, if its rows are finite there at 2⁻ᵏ and 2⁻ᵏ⁻¹ and
    /// every number changes by the exact power of two its degree predicts; `None` when a row
    /// is not homogeneous (`sin(ω t)` with ω scaled, `l^2 + 1`).
    pub fn verified(
        program: &RowProgram,
        system: &System,
        env: &Env,
        exponent: i64,
    ) -> Result<Option<Unit>, EvalError> {
        let symbols = length_symbols(system);
        let at = program.evaluate(system, &scaled_env(env, &symbols, -exponent))?;
        let half = program.evaluate(system, &scaled_env(env, &symbols, -exponent - 1))?;
        let degrees = (rows_finite(&at) && rows_finite(&half)).then(|| degrees(&at, &half)).flatten();
        Ok(degrees.map(|degrees| Unit { exponent, degrees, symbols }))
    }

    /// `env` in the new unit (its length-like values × 2⁻ᵏ).
    pub fn to_unit(&self, env: &Env) -> Env {
        scaled_env(env, &self.symbols, -self.exponent)
    }

    /// A length (position, velocity, force, acceleration) back in the old unit: x · 2ᵏ.
    pub fn length(&self, x: f64) -> f64 {
        pow2(x, self.exponent)
    }

    /// A vector of lengths back in the old unit.
    pub fn vector(&self, x: [f64; 3]) -> [f64; 3] {
        x.map(|x| self.length(x))
    }

    /// C, Ċ or c of row q back in the old unit: x · 2^{kp}.
    pub fn row_value(&self, q: usize, x: f64) -> f64 {
        pow2(x, self.exponent * self.degrees[q])
    }

    /// λ of row q back in the old unit: λ · 2^{−k(p−2)} (forces scale by 2ᵏ, J by 2^{k(p−1)}).
    pub fn lambda(&self, q: usize, x: f64) -> f64 {
        pow2(x, -self.exponent * (self.degrees[q] - 2))
    }

    /// An energy (mass × length²/time²) back in the old unit: x · 2^{2k}.
    pub fn energy(&self, x: f64) -> f64 {
        pow2(x, 2 * self.exponent)
    }

    /// Rows evaluated in the new unit, back in the old one (∞ where the true number
    /// overflows f64).
    pub fn rows(&self, rows: &mut Rows) {
        for (q, row) in rows.rows.iter_mut().enumerate() {
            row.value = self.row_value(q, row.value);
            row.rate = self.row_value(q, row.rate);
            row.bias = self.row_value(q, row.bias);
            let p = self.degrees[q];
            for (_, j) in row.jacobian.iter_mut() {
                *j = j.map(|x| pow2(x, self.exponent * (p - 1)));
            }
        }
        for v in rows.velocity.iter_mut().chain(rows.force.iter_mut()) {
            *v = self.vector(*v);
        }
    }
}

/// A recorded state of a run in another unit, converted back to the caller's for an
/// observer: positions, velocities (the bodies' slots; a run with rigid bodies keeps the
/// scene's unit), rows and λ. The buffers are reused from step to step.
#[derive(Default)]
pub struct Shown {
    pub q: Vec<[f64; 3]>,
    pub v: Vec<[f64; 3]>,
    pub rows: Rows,
    pub lambda: Vec<f64>,
}

impl Shown {
    /// `q`, `v`, `rows` and `lambda` (in `unit`) into the caller's unit.
    pub fn convert(&mut self, unit: &Unit, q: &[[f64; 3]], v: &[[f64; 3]], rows: &Rows, lambda: &[f64]) {
        self.q.clear();
        self.q.extend(q.iter().map(|x| unit.vector(*x)));
        self.v.clear();
        self.v.extend(v.iter().map(|x| unit.vector(*x)));
        self.rows.clone_from(rows);
        unit.rows(&mut self.rows);
        self.lambda.clear();
        self.lambda.extend(lambda.iter().enumerate().map(|(k, l)| unit.lambda(k, *l)));
    }
}

/// The independent blocks of a scene: per body and per row the index of its block (bodies
/// joined, transitively, by the rows acting on both; a body no row acts on is a block of its
/// own). Rows with no body get `usize::MAX`.
pub fn blocks(rows: &Rows) -> (Vec<usize>, Vec<usize>) {
    let n = rows.inverse_mass.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for row in &rows.rows {
        if let Some(&(first, _)) = row.jacobian.first() {
            for &(b, _) in &row.jacobian[1..] {
                let (x, y) = (root(&mut parent, first), root(&mut parent, b));
                parent[x] = y;
            }
        }
    }
    let body: Vec<usize> = (0..n).map(|i| root(&mut parent, i)).collect();
    let row = rows.rows.iter().map(|r| r.jacobian.first().map_or(usize::MAX, |&(b, _)| body[b])).collect();
    (body, row)
}

/// Per block of [`blocks`] (indexed by its root body), the exponent of its largest
/// position, velocity or force component (`None` when all are zero or one is not finite).
fn block_exponents(rows: &Rows, env: &Env, system: &System, body_block: &[usize]) -> Vec<Option<i64>> {
    let mut big = vec![0.0f64; body_block.len()];
    for (i, b) in system.bodies.iter().enumerate() {
        let get = |s| env.get(s).and_then(Value::vector).unwrap_or([0.0; 3]);
        let m = [get(b.position), get(b.velocity), rows.force[i]].iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        big[body_block[i]] = big[body_block[i]].max(m);
    }
    big.iter().map(|&x| (x.is_finite() && x > 0.0).then(|| x.log2().floor() as i64)).collect()
}

/// The spread of length scales over the scene's independent blocks: (smallest, largest)
/// exponent of the blocks' sizes at `env`, `None` with fewer than two sized blocks. A
/// simulation in one unit refuses a scene whose spread passes what f64 can hold for both.
pub fn spread(program: &RowProgram, system: &System, env: &Env) -> Result<Option<(i64, i64)>, EvalError> {
    let rows = program.evaluate(system, env)?;
    let (body_block, _) = blocks(&rows);
    let sized: Vec<i64> = block_exponents(&rows, env, system, &body_block).into_iter().flatten().collect();
    Ok((sized.len() >= 2).then(|| (sized.iter().copied().min().unwrap_or(0), sized.iter().copied().max().unwrap_or(0))))
}

/// Whether the raw solve of block `block` is usable: none of its rows has non-finite numbers
/// or λ.
fn raw_usable(solution: &Solution, row_block: &[usize], block: usize) -> bool {
    !solution.diagnostics.iter().any(|d| {
        matches!(d, Diagnostic::NonFiniteRow { .. } | Diagnostic::NonFiniteLambda { .. })
            && d.constraints().iter().any(|&q| row_block.get(q) == Some(&block))
    })
}

/// The rows at `env` and their solution; when the raw rows are not finite, the verified
/// rescaled solve (see the module note), with a diagnostic saying so. The rows returned are
/// the raw ones scaled back from the rescaled state (∞ where the true number overflows).
pub fn solve_at(
    program: &RowProgram,
    system: &System,
    env: &Env,
    settings: &Settings,
) -> Result<(Rows, Solution), EvalError> {
    let raw = program.evaluate(system, env)?;
    if rows_finite(&raw) {
        let solution = solve_with(&raw, settings);
        return Ok((raw, solution));
    }
    // 2⁻ᵏ brings the largest length-like number near 1.
    let unit = match Unit::exponent_at(system, env) {
        Some(k) => Unit::verified(program, system, env, k)?,
        None => None,
    };
    let Some(unit) = unit else {
        let solution = solve_with(&raw, settings);
        return Ok((raw, solution));
    };
    let k = unit.exponent;
    let mut rows = program.evaluate(system, &unit.to_unit(env))?;
    let scaled_settings = Settings { length_scale: pow2(settings.length_scale, -k), ..*settings };
    let mut solution = solve_with(&rows, &scaled_settings);
    // Back to the caller's units: forces and accelerations × 2ᵏ = 1/s, λ = λ'·s^{p−2}.
    for f in solution.constraint_force.iter_mut().chain(solution.acceleration.iter_mut()) {
        *f = unit.vector(*f);
    }
    for (q, l) in solution.lambda.iter_mut().enumerate() {
        let scaled = *l;
        *l = unit.lambda(q, scaled);
        if scaled != 0.0 && !l.is_normal() {
            solution.diagnostics.push(Diagnostic::LambdaOutOfRange { constraint: q, lambda: *l });
        }
    }
    solution.diagnostics.push(Diagnostic::Rescaled { exponent: -k });
    unit.rows(&mut rows);
    keep_raw_blocks(system, env, settings, &raw, k, &mut rows, &mut solution);
    Ok((rows, solution))
}

/// The blocks whose own size is nearer the caller's unit (2⁰) than the new one (2ᵏ) take
/// their raw solution where it is usable: the rescaled one has lost them below f64's range.
fn keep_raw_blocks(
    system: &System,
    env: &Env,
    settings: &Settings,
    raw: &Rows,
    k: i64,
    rows: &mut Rows,
    solution: &mut Solution,
) {
    let (body_block, row_block) = blocks(raw);
    let exponents = block_exponents(raw, env, system, &body_block);
    let raw_solution = solve_with(raw, settings);
    let keep: Vec<bool> = (0..body_block.len())
        .map(|b| exponents[b].is_some_and(|e| e.abs() < (e - k).abs()) && raw_usable(&raw_solution, &row_block, b))
        .collect();
    let kept_row = |q: usize| row_block.get(q).is_some_and(|&b| b != usize::MAX && keep[b]);
    let kept: Vec<usize> = (0..raw.rows.len()).filter(|&q| kept_row(q)).collect();
    if kept.is_empty() {
        return;
    }
    for (i, &b) in body_block.iter().enumerate() {
        if keep[b] {
            solution.constraint_force[i] = raw_solution.constraint_force[i];
            solution.acceleration[i] = raw_solution.acceleration[i];
            rows.velocity[i] = raw.velocity[i];
            rows.force[i] = raw.force[i];
        }
    }
    for &q in &kept {
        solution.lambda[q] = raw_solution.lambda[q];
        solution.active[q] = raw_solution.active[q];
        solution.contacts[q] = raw_solution.contacts[q];
        rows.rows[q] = raw.rows[q].clone();
    }
    // Diagnostics of the kept rows come from the raw solve, the others' from the rescaled.
    let about_kept = |d: &Diagnostic| !d.constraints().is_empty() && d.constraints().iter().all(|&q| kept_row(q));
    solution.diagnostics.retain(|d| !about_kept(d));
    solution.diagnostics.extend(raw_solution.diagnostics.iter().filter(|d| about_kept(d)).cloned());
    solution.diagnostics.push(Diagnostic::MixedScales { raw: kept });
    solution.status = solution.diagnostics.iter().map(Diagnostic::status).max().unwrap_or_default();
}

#[cfg(test)]
mod tests {
    use super::pow2;

    /// `pow2` is exact multiplication by 2ᵉ across the whole range, and returns at once for
    /// the saturated degrees a row that underflowed at half the scale gives (log₂(x/0) as
    /// `i64::MAX`): before, those looped about 10¹⁶ times.
    #[test]
    fn pow2_is_exact_and_returns_at_once_at_saturated_exponents() {
        for e in [-2000, -1074, -1000, -1, 0, 1, 1000, 1023, 2000] {
            let x = 1.5f64;
            let expected =
                if e >= -1000 { x * 2f64.powi(e as i32) } else { x * 2f64.powi(-1000) * 2f64.powi(e as i32 + 1000) };
            assert_eq!(pow2(x, e), expected, "e = {e}");
        }
        assert_eq!(pow2(f64::MIN_POSITIVE, 2044), 2f64.powi(1022));
        assert_eq!(pow2(2f64.powi(1000), -2000), 2f64.powi(-1000));
        assert_eq!(pow2(0.0, i64::MAX), 0.0);
        assert_eq!(pow2(0.0, i64::MIN), 0.0);
        assert_eq!(pow2(1.0, i64::MAX), f64::INFINITY);
        assert_eq!(pow2(-1.0, i64::MAX), f64::NEG_INFINITY);
        assert_eq!(pow2(1.0, i64::MIN), 0.0);
        assert_eq!(pow2(f64::INFINITY, i64::MIN), f64::INFINITY);
        assert!(pow2(f64::NAN, i64::MAX).is_nan());
    }
}
