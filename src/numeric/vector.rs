//! Small vector arithmetic on `[f64; 3]` (2D vectors have a zero third component), shared
//! by the solve, the simulation, the checks and the benches: the dot product, the norm
//! without overflow, a row's norm over all its bodies, and the length scale of a scene.
//!
//! Not here: matrices (nalgebra, `numeric::banded`), the compiled evaluation's own
//! overflow-safe `norm2`/`norm3` (`numeric::program`, which the tape and generated code run).

/// a·b.
pub fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
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

/// Magnitudes whose squares, summed over a row, can neither overflow nor lose the row's
/// leading digits to underflow: squares within 1e±288 leave a factor 1e20 to either end of
/// the normal range (a row would need 1e20 parts to overflow).
const PLAIN_SQUARES: std::ops::RangeInclusive<f64> = 1.0e-144..=1.0e144;

/// ‖J‖ of a whole row (all bodies' parts `(body, Jᵢ)`), without overflow: the plain
/// √Σ J² when the largest component is of moderate size (the common case, no division),
/// else part by part with [`safe_norm`].
pub fn row_norm(jacobian: &[(usize, [f64; 3])]) -> f64 {
    // Loops over the parts rather than flattened iterators: the drift check, SHAKE's
    // residual and the solve's scaling run this for every row (the sum's start, ±0, cannot
    // change a sum of squares).
    let mut big = 0.0f64;
    for (_, j) in jacobian {
        big = big.max(j[0].abs()).max(j[1].abs()).max(j[2].abs());
    }
    if PLAIN_SQUARES.contains(&big) {
        let mut sum = 0.0;
        for (_, j) in jacobian {
            sum += dot(j, j);
        }
        return sum.sqrt();
    }
    jacobian.iter().map(|(_, j)| safe_norm(j)).fold(0.0f64, |a, b| safe_norm(&[a, b, 0.0]))
}

/// The length scale of a scene: the largest |rᵢ| of the bodies' positions, or 1 when every
/// body is at the origin (or the largest is not finite). Contact distances count as zero
/// relative to it, and a simulation measures drift and blow-up against it.
pub fn length_scale<'a>(positions: impl IntoIterator<Item = &'a [f64; 3]>) -> f64 {
    let length = positions.into_iter().map(safe_norm).fold(0.0, f64::max);
    if length > 0.0 && length.is_finite() { length } else { 1.0 }
}
