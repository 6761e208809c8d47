//! Exact rational constants for the expression graph.
//!
//! Every constant in a formula is an exact rational: `1.5e-3` is `3/2000`, `9.81` is
//! `981/100`, and folding `2/4` gives `1/2`, so printed formulas carry no rounding. Small
//! values live in an `i64` pair (the common case, no allocation); anything that overflows
//! moves to a big rational. Both forms are canonical, so `Eq` and `Hash` are structural
//! (a big rational hashes its numerator and denominator as they are: `num_rational`'s own
//! `Hash` expands the value as a continued fraction, so that unreduced ratios hash alike,
//! 3 % of deriving a grid of bodies with 16-digit masses).
//!
//! Not here: floating point. Converting to `f64` happens only in [`Rational::to_f64`].

use num_bigint::BigInt;
use num_integer::Integer;
use num_rational::BigRational;
use num_traits::{One, Signed, ToPrimitive, Zero};
use std::cmp::Ordering;
use std::fmt;
use std::hash::{Hash, Hasher};

/// An exact rational number in lowest terms with a positive denominator.
#[derive(Clone, PartialEq, Eq)]
pub enum Rational {
    /// `num / den` with `den > 0` and `gcd(num, den) = 1`.
    Small(i64, i64),
    /// Used only when the value does not fit `Small`.
    Big(Box<BigRational>),
}

impl Hash for Rational {
    fn hash<H: Hasher>(&self, state: &mut H) {
        match self {
            Rational::Small(n, d) => (0u8, n, d).hash(state),
            // In lowest terms with a positive denominator (`from_big`'s inputs come from
            // `BigRational`'s reducing constructors and arithmetic), so equal values have
            // equal parts.
            Rational::Big(b) => (1u8, b.numer(), b.denom()).hash(state),
        }
    }
}

/// Literals and folded powers larger than this many bits are refused rather than built.
pub const MAX_BITS: u64 = 4096;

impl Rational {
    pub const ZERO: Rational = Rational::Small(0, 1);
    pub const ONE: Rational = Rational::Small(1, 1);

    pub fn int(n: i64) -> Rational {
        Rational::Small(n, 1)
    }

    /// `num / den`, reduced. `den` must be non-zero.
    pub fn new(num: i64, den: i64) -> Rational {
        debug_assert!(den != 0);
        if num != i64::MIN && den != i64::MIN && den != 0 {
            return Rational::reduce_small(num, den);
        }
        Rational::from_big(BigRational::new(BigInt::from(num), BigInt::from(den)))
    }

    fn from_big(r: BigRational) -> Rational {
        match (r.numer().to_i64(), r.denom().to_i64()) {
            (Some(n), Some(d)) if n != i64::MIN && d != i64::MIN => Rational::Small(n, d),
            _ => Rational::Big(Box::new(r)),
        }
    }

    fn to_big(&self) -> BigRational {
        match self {
            Rational::Small(n, d) => BigRational::new_raw(BigInt::from(*n), BigInt::from(*d)),
            Rational::Big(b) => (**b).clone(),
        }
    }

    /// Parses a decimal literal such as `12`, `1.5`, `2.5e-3` exactly.
    ///
    /// Returns `None` when the text is not a decimal literal or its size passes [`MAX_BITS`].
    pub fn parse_decimal(text: &str) -> Option<Rational> {
        let (mantissa, exponent) = match text.find(['e', 'E']) {
            Some(i) => (&text[..i], text[i + 1..].parse::<i64>().ok()?),
            None => (text, 0),
        };
        let (int_part, frac_part) = match mantissa.find('.') {
            Some(i) => (&mantissa[..i], &mantissa[i + 1..]),
            None => (mantissa, ""),
        };
        if int_part.is_empty() && frac_part.is_empty() {
            return None;
        }
        if !int_part.bytes().chain(frac_part.bytes()).all(|b| b.is_ascii_digit()) {
            return None;
        }
        let scale = exponent.checked_sub(frac_part.len() as i64)?;
        // Nearly every literal is an i64 over a power of ten below 10¹⁹: no big integers,
        // no digit string (the same reduced value as the general path below).
        if scale.unsigned_abs() <= 18 {
            let mut digits = int_part.bytes().chain(frac_part.bytes());
            let n = digits.try_fold(0i64, |n, b| n.checked_mul(10)?.checked_add(i64::from(b - b'0')));
            let power = 10i64.pow(scale.unsigned_abs() as u32);
            match n {
                Some(n) if scale < 0 => return Some(Rational::new(n, power)),
                Some(n) => {
                    if let Some(v) = n.checked_mul(power) {
                        return Some(Rational::int(v));
                    }
                }
                None => {}
            }
        }
        let digits = format!("{int_part}{frac_part}");
        let digits = digits.trim_start_matches('0');
        // 10^k needs about 3.33 k bits: refuse literals whose exact value would be huge.
        let size_bits = (digits.len() as i64 + scale.abs()) * 4;
        if size_bits > MAX_BITS as i64 {
            return None;
        }
        let mantissa: BigInt = if digits.is_empty() { BigInt::zero() } else { digits.parse().ok()? };
        let ten = BigInt::from(10);
        let power = num_traits::pow(ten, scale.unsigned_abs() as usize);
        let value =
            if scale >= 0 { BigRational::from_integer(mantissa * power) } else { BigRational::new(mantissa, power) };
        Some(Rational::from_big(value))
    }

    pub fn is_zero(&self) -> bool {
        matches!(self, Rational::Small(0, _))
    }

    pub fn is_one(&self) -> bool {
        matches!(self, Rational::Small(1, 1))
    }

    pub fn is_negative(&self) -> bool {
        match self {
            Rational::Small(n, _) => *n < 0,
            Rational::Big(b) => b.is_negative(),
        }
    }

    pub fn is_integer(&self) -> bool {
        match self {
            Rational::Small(_, d) => *d == 1,
            Rational::Big(b) => b.is_integer(),
        }
    }

    /// The value as an `i64` when it is an integer that fits.
    pub fn to_i64(&self) -> Option<i64> {
        match self {
            Rational::Small(n, 1) => Some(*n),
            _ => None,
        }
    }

    /// Numerator and denominator as small integers, when they fit.
    pub fn as_small(&self) -> Option<(i64, i64)> {
        match self {
            Rational::Small(n, d) => Some((*n, *d)),
            Rational::Big(_) => None,
        }
    }

    /// The nearest `f64` (correctly rounded for small values, within an ulp for big ones).
    pub fn to_f64(&self) -> f64 {
        match self {
            Rational::Small(n, d) => *n as f64 / *d as f64,
            Rational::Big(b) => b.to_f64().unwrap_or(f64::NAN),
        }
    }

    pub fn neg(&self) -> Rational {
        match self {
            Rational::Small(n, d) if *n != i64::MIN => Rational::Small(-n, *d),
            _ => Rational::from_big(-self.to_big()),
        }
    }

    pub fn abs(&self) -> Rational {
        if self.is_negative() { self.neg() } else { self.clone() }
    }

    pub fn add(&self, other: &Rational) -> Rational {
        if let (Rational::Small(a, b), Rational::Small(c, d)) = (self, other) {
            // Integers (most coefficients): no gcd needed.
            if *b == 1
                && *d == 1
                && let Some(n) = a.checked_add(*c)
                && n != i64::MIN
            {
                return Rational::Small(n, 1);
            }
            if b == d {
                if let Some(n) = a.checked_add(*c) {
                    return Rational::reduce_small(n, *b);
                }
            } else if let (Some(ad), Some(cb), Some(bd)) = (a.checked_mul(*d), c.checked_mul(*b), b.checked_mul(*d))
                && let Some(n) = ad.checked_add(cb)
            {
                return Rational::reduce_small(n, bd);
            }
        }
        let (x, y) = (self.to_big(), other.to_big());
        if x.is_integer() && y.is_integer() {
            // No reduction: num-rational's gcd with a denominator of one is a binary gcd that
            // takes a shift per bit of the numerator (a 4 096-bit sum: ~100 µs, callgrind).
            return Rational::from_big(BigRational::from_integer(x.numer() + y.numer()));
        }
        Rational::from_big(x + y)
    }

    pub fn sub(&self, other: &Rational) -> Rational {
        self.add(&other.neg())
    }

    pub fn mul(&self, other: &Rational) -> Rational {
        // A product's coefficient starts at 1: a big factor is then taken as it is, not
        // multiplied and reduced by a big gcd again.
        match (self, other) {
            (Rational::Small(1, 1), x) | (x, Rational::Small(1, 1)) => return x.clone(),
            _ => {}
        }
        if let (Rational::Small(a, b), Rational::Small(c, d)) = (self, other) {
            if *b == 1
                && *d == 1
                && let Some(n) = a.checked_mul(*c)
                && n != i64::MIN
            {
                return Rational::Small(n, 1);
            }
            // Cross-reduce first so the products stay small.
            let g1 = a.gcd(d).max(1);
            let g2 = c.gcd(b).max(1);
            if let (Some(n), Some(m)) = ((a / g1).checked_mul(c / g2), (b / g2).checked_mul(d / g1)) {
                return Rational::reduce_small(n, m);
            }
        }
        let (x, y) = (self.to_big(), other.to_big());
        if x.is_integer() && y.is_integer() {
            // No reduction, as in `add`.
            return Rational::from_big(BigRational::from_integer(x.numer() * y.numer()));
        }
        Rational::from_big(x * y)
    }

    /// `1 / self`; `None` for zero.
    pub fn recip(&self) -> Option<Rational> {
        if self.is_zero() {
            return None;
        }
        match self {
            Rational::Small(n, d) if *n != i64::MIN => {
                Some(if *n < 0 { Rational::Small(-d, -n) } else { Rational::Small(*d, *n) })
            }
            _ => Some(Rational::from_big(self.to_big().recip())),
        }
    }

    pub fn div(&self, other: &Rational) -> Option<Rational> {
        other.recip().map(|r| self.mul(&r))
    }

    /// `self^n` for an integer `n`, or `None` when it is undefined (0^-1) or too large.
    pub fn pow(&self, n: i64) -> Option<Rational> {
        if n < 0 {
            return self.recip()?.pow(n.checked_neg()?);
        }
        let bits = self.bits().saturating_mul(n.unsigned_abs());
        if bits > MAX_BITS {
            return None;
        }
        let mut result = Rational::ONE;
        for _ in 0..n {
            result = result.mul(self);
        }
        Some(result)
    }

    /// An upper bound on the bits of numerator and denominator together.
    pub fn bits(&self) -> u64 {
        match self {
            Rational::Small(n, d) => (64 - n.unsigned_abs().leading_zeros() as u64) + (64 - d.leading_zeros() as u64),
            Rational::Big(b) => b.numer().bits() + b.denom().bits(),
        }
    }

    /// The exact square root when `self` is the square of a rational.
    pub fn sqrt_exact(&self) -> Option<Rational> {
        if self.is_negative() {
            return None;
        }
        let b = self.to_big();
        let n = b.numer().sqrt();
        let d = b.denom().sqrt();
        (&n * &n == *b.numer() && &d * &d == *b.denom()).then(|| Rational::from_big(BigRational::new(n, d)))
    }

    /// The numerator and the denominator as integer rationals: `p/q → (p, q)`.
    pub fn split_parts(&self) -> (Rational, Rational) {
        match self {
            Rational::Small(n, d) => (Rational::Small(*n, 1), Rational::Small(*d, 1)),
            Rational::Big(_) => {
                let (p, q) = self.parts();
                (Rational::from_parts(p, 1.into()), Rational::from_parts(q, 1.into()))
            }
        }
    }

    /// Numerator and denominator as big integers.
    pub fn parts(&self) -> (BigInt, BigInt) {
        let b = self.to_big();
        (b.numer().clone(), b.denom().clone())
    }

    /// The rational `n / d` from big parts.
    pub fn from_parts(n: BigInt, d: BigInt) -> Rational {
        if d.is_one() {
            // An integer: no gcd (a big one's binary gcd with 1 walks all its bits).
            return Rational::from_big(BigRational::from_integer(n));
        }
        Rational::from_big(BigRational::new(n, d))
    }

    fn reduce_small(n: i64, d: i64) -> Rational {
        if n == i64::MIN || d == i64::MIN {
            // `Small` never holds i64::MIN, so negation is always safe and the form unique.
            return Rational::from_big(BigRational::new(BigInt::from(n), BigInt::from(d)));
        }
        let g = n.gcd(&d).max(1);
        let (n, d) = (n / g, d / g);
        if d < 0 { Rational::Small(-n, -d) } else { Rational::Small(n, d) }
    }

    /// The greatest common divisor of two rationals: `gcd(a/b, c/d) = gcd(a,c)/lcm(b,d)`, positive.
    pub fn gcd(&self, other: &Rational) -> Rational {
        // Small values (nearly all of them) need no big integers: gcd(a, c) and lcm(b, d)
        // in i64, when the lcm fits.
        if let (Rational::Small(a, b), Rational::Small(c, d)) = (self, other) {
            let n = a.unsigned_abs().gcd(&c.unsigned_abs());
            if n == 0 {
                return Rational::ONE;
            }
            let g = b.gcd(d);
            if let (Ok(n), Some(l)) = (i64::try_from(n), (b / g).checked_mul(*d)) {
                // n divides a and c, l is a multiple of b and d: gcd(n, l) = 1 already.
                return Rational::reduce_small(n, l);
            }
        }
        let (a, b) = self.parts();
        let (c, d) = other.parts();
        let n = a.gcd(&c);
        if n.is_zero() {
            return Rational::ONE;
        }
        Rational::from_parts(n, b.lcm(&d))
    }
}

impl Ord for Rational {
    fn cmp(&self, other: &Self) -> Ordering {
        if let (Rational::Small(a, b), Rational::Small(c, d)) = (self, other) {
            return (*a as i128 * *d as i128).cmp(&(*c as i128 * *b as i128));
        }
        self.to_big().cmp(&other.to_big())
    }
}

impl PartialOrd for Rational {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl fmt::Debug for Rational {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// Prints `n` or `n/d`.
impl fmt::Display for Rational {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Rational::Small(n, 1) => write!(f, "{n}"),
            Rational::Small(n, d) => write!(f, "{n}/{d}"),
            Rational::Big(b) if b.denom().is_one() => write!(f, "{}", b.numer()),
            Rational::Big(b) => write!(f, "{}/{}", b.numer(), b.denom()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two 16-digit masses multiply to a big rational: products with 1, integers built from
    /// parts and hashes all give the reduced value's, whatever the route to it.
    #[test]
    fn big_values_multiply_hash_and_build_as_their_reduced_form() {
        use std::hash::DefaultHasher;
        let decimal = |s: &str| Rational::parse_decimal(s).expect("a decimal");
        let big = decimal("0.5026548245743669").mul(&decimal("0.040212385965949365"));
        assert!(matches!(big, Rational::Big(_)));
        assert_eq!(Rational::ONE.mul(&big), big);
        assert_eq!(big.mul(&Rational::ONE), big);
        let around = big.mul(&Rational::int(6)).mul(&Rational::new(1, 6));
        assert_eq!(around, big);
        let hash = |r: &Rational| {
            let mut h = DefaultHasher::new();
            r.hash(&mut h);
            h.finish()
        };
        assert_eq!(hash(&around), hash(&big));
        let (n, d) = big.parts();
        assert_eq!(Rational::from_parts(n.clone(), d), big);
        assert_eq!(Rational::from_parts(n.clone() * 3, 3.into()), Rational::from_parts(n, 1.into()));
    }

    #[test]
    fn decimals_are_exact() {
        assert_eq!(Rational::parse_decimal("1.5e-3"), Some(Rational::new(3, 2000)));
        assert_eq!(Rational::parse_decimal("9.81"), Some(Rational::new(981, 100)));
        assert_eq!(Rational::parse_decimal("007"), Some(Rational::int(7)));
        assert_eq!(Rational::parse_decimal(".5"), Some(Rational::new(1, 2)));
        assert_eq!(Rational::parse_decimal("1e400").map(|r| r.is_integer()), Some(true));
        assert_eq!(Rational::parse_decimal("1e100000"), None);
        assert_eq!(Rational::parse_decimal("nan"), None);
    }

    /// The i64 fast path and the big-integer path agree where they meet.
    #[test]
    fn decimals_at_the_edge_of_i64() {
        let ten = |k: u32| Rational::from_big(BigRational::from_integer(num_traits::pow(BigInt::from(10), k as usize)));
        assert_eq!(Rational::parse_decimal("1e18"), Some(ten(18)));
        assert_eq!(Rational::parse_decimal("1e19"), Some(ten(19)));
        assert_eq!(Rational::parse_decimal("10e18"), Some(ten(19)));
        assert_eq!(Rational::parse_decimal("1e-18"), ten(18).recip());
        assert_eq!(Rational::parse_decimal("1e-19"), ten(19).recip());
        assert_eq!(Rational::parse_decimal("9223372036854775807"), Some(Rational::int(i64::MAX)));
        assert!(matches!(Rational::parse_decimal("9223372036854775808"), Some(Rational::Big(_))));
        assert_eq!(Rational::parse_decimal("0.000"), Some(Rational::ZERO));
        assert_eq!(Rational::parse_decimal("2.50"), Some(Rational::new(5, 2)));
        assert_eq!(Rational::parse_decimal("0.1e1"), Some(Rational::ONE));
    }

    #[test]
    fn overflow_moves_to_big_and_back() {
        let big = Rational::int(i64::MAX).mul(&Rational::int(4));
        assert!(matches!(big, Rational::Big(_)));
        let back = big.div(&Rational::int(4)).unwrap();
        assert_eq!(back, Rational::int(i64::MAX));
        assert_eq!(Rational::new(2, -4), Rational::new(-1, 2));
        assert_eq!(Rational::new(1, 3).gcd(&Rational::new(1, 2)), Rational::new(1, 6));
    }
}
