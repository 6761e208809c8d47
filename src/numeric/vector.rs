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

/// Whether every number in `xs` is finite, without a branch per number: the one test of
/// the tape's outputs (`numeric::rows`) and of a solve's slots (`numeric::chain`).
///
/// Short arrays by their exponent bits ([`not_finite_bit`], integer operations the compiler
/// vectorises with the default target), longer ones with the widest vector instructions
/// the processor has (AVX2 on x86-64 when present: sums of x·0, [`all_finite_any`]), whose
/// call and test of the processor cost more than they save below about 32 numbers
/// (callgrind, the chain's solve: its slots' 30 velocity and 30 force numbers at N = 10
/// took 30 instructions more a solve by the sums, its 300 and 300 at N = 100 about 1 200
/// fewer).
#[inline]
pub(crate) fn all_finite(xs: &[f64]) -> bool {
    if xs.len() < SHORT {
        return not_finite_bits(xs) >> 63 == 0;
    }
    all_finite_long(xs)
}

/// [`all_finite`]'s arrays too short for the sums of x·0.
const SHORT: usize = 32;

/// x's exponent bits plus one in their lowest place, whose top bit is set exactly when x is
/// not finite: a number's exponent bits are all ones exactly when it is not (±∞, NaN), and
/// adding one to them then carries into the sign bit, so the OR of these over numbers has
/// its top bit clear exactly when all are finite (integer operations, no branch).
#[inline(always)]
pub(crate) fn not_finite_bit(x: f64) -> u64 {
    const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
    (x.to_bits() & EXPONENT) + (1 << 52)
}

/// The OR of [`not_finite_bit`] over `xs`: its top bit is clear exactly when every number
/// is finite (the short path of [`all_finite`]; callers that test several slices OR these).
#[inline(always)]
pub(crate) fn not_finite_bits(xs: &[f64]) -> u64 {
    xs.iter().fold(0u64, |bad, x| bad | not_finite_bit(*x))
}

/// [`all_finite`] of a long array, with AVX2 when the processor has it.
fn all_finite_long(xs: &[f64]) -> bool {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (checked).
        return unsafe { all_finite_avx2(xs) };
    }
    all_finite_any(xs)
}

/// [`all_finite_any`] compiled for AVX2.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn all_finite_avx2(xs: &[f64]) -> bool {
    all_finite_any(xs)
}

/// [`all_finite`] of a long array: x · 0 is ±0 for a finite x and NaN otherwise, and a NaN stays in a sum, so
/// eight sums of such products (vector operations, no branch) are all 0 exactly when
/// every number is finite.
#[inline(always)]
fn all_finite_any(xs: &[f64]) -> bool {
    let mut sums = [0.0f64; 8];
    let mut chunks = xs.chunks_exact(8);
    for c in &mut chunks {
        for (s, x) in sums.iter_mut().zip(c) {
            *s += x * 0.0;
        }
    }
    let rest = chunks.remainder().iter().fold(0.0, |s, x| s + x * 0.0);
    sums.iter().fold(rest, |s, x| s + x) == 0.0
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

    /// [`all_finite`] answers as `is_finite` number by number, with one special number or two
    /// at every place of arrays of every length up to five chunks of eight (the sums'
    /// chunks and the remainder, both sides of `SHORT`), on the bits, the AVX2 path and the
    /// plain sums.
    #[test]
    fn all_finite_is_is_finite_at_every_place() {
        for len in 0..=40 {
            for &a in &SPECIAL_NUMBERS {
                for at in 0..len {
                    for &b in &[1.0, f64::NAN, -0.0] {
                        let mut xs: Vec<f64> = (0..len).map(|i| i as f64 - 3.5).collect();
                        xs[at] = a;
                        xs[(at * 7 + 3) % len] = b;
                        let want = xs.iter().all(|x| x.is_finite());
                        assert_eq!(all_finite(&xs), want, "{xs:?}");
                        assert_eq!(all_finite_any(&xs), want, "{xs:?}");
                        assert_eq!(all_finite_long(&xs), want, "{xs:?}");
                        let bits = not_finite_bits(&xs) >> 63 == 0;
                        assert_eq!(bits, want, "{xs:?}");
                    }
                }
            }
        }
        assert!(all_finite(&[]));
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
