//! Written into every generated module: what the formulas may call, `norm2`, `norm3`
//! (range-safe norms, the same as `numeric::program`'s) and `powf` (integer exponents by
//! `powi`, so that negative bases work).
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled
//! by the crate's tests. Not here: the solves (`solve.rs`, `solve_heap.rs`, `solve_band.rs`).

/// |(x, y)| without overflow or underflow (the plain formula unless it would lose range).
#[allow(dead_code)]
#[inline]
fn norm2(x: f64, y: f64) -> f64 {
    let s = x * x + y * y;
    if s.is_finite() && s >= f64::MIN_POSITIVE { s.sqrt() } else { x.hypot(y) }
}

/// |(x, y, z)| without overflow or underflow.
#[allow(dead_code)]
#[inline]
fn norm3(x: f64, y: f64, z: f64) -> f64 {
    let s = x * x + y * y + z * z;
    if s.is_finite() && s >= f64::MIN_POSITIVE { s.sqrt() } else { x.hypot(y).hypot(z) }
}

/// `b^e`, integer exponents by `powi` so that negative bases work.
#[allow(dead_code)]
#[inline]
fn powf(b: f64, e: f64) -> f64 {
    if e == e.trunc() && e.abs() <= i32::MAX as f64 { b.powi(e as i32) } else { b.powf(e) }
}
