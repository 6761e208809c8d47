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
/// else part by part with [`safe_norm`]. In line (the plain path is a few instructions,
/// the call was a visible part of SHAKE's residual), the rest apart.
#[inline]
pub fn row_norm(jacobian: &[(usize, [f64; 3])]) -> f64 {
    // The drift check, SHAKE's residual and the solve's scaling run this for every row, so
    // the plain sum comes first: when it lies well inside the normal range, the largest
    // component is of moderate size (each square is at most the sum, and at least the sum
    // over the number of components, to rounding), the test on it below would take the
    // plain path, and the plain sum is the answer without looking for the largest.
    let mut sum = 0.0;
    for (_, j) in jacobian {
        sum += dot(j, j);
    }
    let components = 3.0 * jacobian.len() as f64;
    if sum < 1e286 && sum > components * 1e-286 {
        return sum.sqrt();
    }
    row_norm_by_largest(jacobian, sum)
}

/// [`row_norm`] past its plain path: `sum` (Σ J²) when the largest component is of
/// moderate size, else part by part with [`safe_norm`].
#[inline(never)]
fn row_norm_by_largest(jacobian: &[(usize, [f64; 3])], sum: f64) -> f64 {
    let mut big = 0.0f64;
    for (_, j) in jacobian {
        big = big.max(j[0].abs()).max(j[1].abs()).max(j[2].abs());
    }
    if PLAIN_SQUARES.contains(&big) {
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

/// The numbers at the edges of f64's classes — zeros of both signs, the smallest subnormals,
/// the smallest normal, ±1, the largest finite, ±∞, NaNs of both signs and a signalling NaN
/// of each sign — for the tests that hold a test by bits against the comparisons it replaces.
#[cfg(test)]
pub(crate) const SPECIAL_NUMBERS: [f64; 16] = [
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    f64::MIN_POSITIVE,
    1.0,
    -1.0,
    -1.5,
    f64::MAX,
    f64::MIN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NAN,
    -f64::NAN,
    f64::from_bits(0x7ff0_0000_0000_0001),
    f64::from_bits(0xfff0_0000_0000_0001),
];

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// `row_norm` as it was before the plain sum came first: the largest component decides
    /// between the plain sum and the part-by-part scaled norm.
    fn by_largest(jacobian: &[(usize, [f64; 3])]) -> f64 {
        let big = jacobian.iter().flat_map(|(_, j)| j).fold(0.0f64, |m, v| m.max(v.abs()));
        if PLAIN_SQUARES.contains(&big) {
            return jacobian.iter().map(|(_, j)| dot(j, j)).sum::<f64>().sqrt();
        }
        jacobian.iter().map(|(_, j)| safe_norm(j)).fold(0.0f64, |a, b| safe_norm(&[a, b, 0.0]))
    }

    proptest! {
        /// The shortcut through the plain sum gives the norm bit for bit, at every magnitude
        /// (both ends of the range, where the scaled norm must take over, and across the
        /// thresholds), for rows of one to four parts and with zero or non-finite components.
        #[test]
        fn row_norm_is_the_norm_by_the_largest_component(
            parts in prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 1..5),
            exponents in prop::collection::vec(-320i32..310, 3),
            special in 0usize..8,
        ) {
            let mut row: Vec<(usize, [f64; 3])> = parts
                .iter()
                .enumerate()
                .map(|(b, j)| (b, [0, 1, 2].map(|d| j[d] * 10f64.powi(exponents[(b + d) % 3]))))
                .collect();
            match special {
                0 => row[0].1[0] = 0.0,
                1 => row[0].1[1] = f64::NAN,
                2 => row[0].1[2] = f64::INFINITY,
                _ => {}
            }
            let (got, want) = (row_norm(&row), by_largest(&row));
            prop_assert!(got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()), "{got:e} against {want:e}");
        }
    }
}
