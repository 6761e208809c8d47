//! Polynomials and rational functions over atoms: the simplifier's canonical form.
//!
//! An atom is a graph node the algebra treats as a variable (`m`, `r·v`, `sin(θ)`). A
//! [`Mono`] is a product of atom powers, a [`Poly`] a sum of rational multiples of monomials,
//! and a [`Frac`] a polynomial over a product of polynomial factors. Two expressions that are
//! equal as rational functions of their atoms have equal forms, so collecting like terms,
//! cancelling and comparing are structural.
//!
//! Terms are stored in a graded monomial order over atom ids (total degree, then exponents
//! in id order), which is compatible with multiplication, so exact division works. The order
//! people read is applied only when the form is turned back into a graph (`simplify`).
//!
//! Every operation that can grow the form (products, powers, common denominators) is
//! bounded by [`MAX_TERMS`] and its coefficients by [`MAX_COEFFICIENT_BITS`]: past either the
//! operation returns `None` and the caller keeps that piece unexpanded. Nothing here is
//! exponential, and no coefficient grows to millions of digits (`(x + 2 y)²⁰⁰⁰`).

use super::graph::Id;
use super::num::Rational;
use super::work;
use smallvec::SmallVec;
use std::cmp::Ordering;

/// The most terms a polynomial may reach by expansion before it is kept unexpanded.
pub const MAX_TERMS: usize = 2000;

/// The largest coefficient (numerator and denominator bits together) a product or power
/// may make before it is kept unexpanded: about 1 200 decimal digits, as for literals
/// ([`super::num::MAX_BITS`]).
pub const MAX_COEFFICIENT_BITS: u64 = super::num::MAX_BITS;

/// The most terms [`Poly::sqrt_exact`] looks at: a root costs a product per term, and the
/// squares a layout meets (`((r1 − p)·v1)²`, 3 to 10 terms) are far below.
pub const MAX_SQUARE_ROOT_TERMS: usize = 64;

/// A product of atom powers, sorted by atom id, exponents non-zero.
///
/// Exponents are negative only for radical atoms (`norm(u)`, `sqrt(x)`, which are never
/// zero where a formula is defined): the simplifier keeps `1/|d|` as `|d|⁻¹` in the
/// numerator, so a sum of fractions over different roots is a (Laurent) polynomial and
/// never goes over one common denominator. Every other atom has a positive exponent.
#[derive(Clone, PartialEq, Eq, Hash, Debug, Default)]
pub struct Mono(pub SmallVec<[(Id, i32); 4]>);

impl Mono {
    pub fn one() -> Mono {
        Mono(SmallVec::new())
    }

    pub fn atom(id: Id) -> Mono {
        let mut v = SmallVec::new();
        v.push((id, 1));
        Mono(v)
    }

    pub fn is_one(&self) -> bool {
        self.0.is_empty()
    }

    pub fn degree(&self) -> i64 {
        self.0.iter().map(|&(_, e)| i64::from(e)).sum()
    }

    /// Whether some atom has a negative exponent (a radical in a denominator).
    pub fn has_negative(&self) -> bool {
        self.0.iter().any(|&(_, e)| e < 0)
    }

    /// The part with negative exponents (`|d|⁻³` of `(r·v) |d|⁻³`), and the rest.
    pub fn split_negative(&self) -> (Mono, Mono) {
        let (neg, pos): (SmallVec<_>, SmallVec<_>) = self.0.iter().copied().partition(|&(_, e)| e < 0);
        (Mono(neg), Mono(pos))
    }

    /// `1 / self`.
    pub fn inverse(&self) -> Mono {
        Mono(self.0.iter().map(|&(a, e)| (a, -e)).collect())
    }

    pub fn exponent(&self, atom: Id) -> i32 {
        self.0.iter().find(|&&(a, _)| a == atom).map_or(0, |&(_, e)| e)
    }

    /// The single atom, if this is `x¹`.
    pub fn as_atom(&self) -> Option<Id> {
        match self.0.as_slice() {
            [(a, 1)] => Some(*a),
            _ => None,
        }
    }

    pub fn mul(&self, other: &Mono) -> Mono {
        // Merges: the result's size is bounded by the operands', and growing it was 3 % of the
        // bead's derivation (callgrind).
        let mut out = SmallVec::with_capacity(self.0.len() + other.0.len());
        let (mut i, mut j) = (0, 0);
        let (a, b) = (&self.0, &other.0);
        while i < a.len() && j < b.len() {
            match a[i].0.cmp(&b[j].0) {
                Ordering::Less => {
                    out.push(a[i]);
                    i += 1;
                }
                Ordering::Greater => {
                    out.push(b[j]);
                    j += 1;
                }
                Ordering::Equal => {
                    // A radical's negative power can cancel its positive one.
                    let e = a[i].1 + b[j].1;
                    if e != 0 {
                        out.push((a[i].0, e));
                    }
                    i += 1;
                    j += 1;
                }
            }
        }
        out.extend_from_slice(&a[i..]);
        out.extend_from_slice(&b[j..]);
        Mono(out)
    }

    /// Whether `self` divides `other`.
    pub fn divides(&self, other: &Mono) -> bool {
        self.0.iter().all(|&(a, e)| other.exponent(a) >= e)
    }

    /// `self / other`; `other` must divide `self`.
    pub fn div(&self, other: &Mono) -> Mono {
        self.mul(&other.inverse())
    }

    /// The greatest common divisor: the minimum exponent of each atom, an absent atom
    /// counting as exponent 0 (so a negative exponent common to every term is kept).
    pub fn gcd(&self, other: &Mono) -> Mono {
        let mut out = SmallVec::new();
        let (a, b) = (&self.0, &other.0);
        let (mut i, mut j) = (0, 0);
        while i < a.len() || j < b.len() {
            let (atom, e) = match (a.get(i), b.get(j)) {
                (Some(&(x, ex)), Some(&(y, ey))) => match x.cmp(&y) {
                    Ordering::Less => {
                        i += 1;
                        (x, ex.min(0))
                    }
                    Ordering::Greater => {
                        j += 1;
                        (y, ey.min(0))
                    }
                    Ordering::Equal => {
                        i += 1;
                        j += 1;
                        (x, ex.min(ey))
                    }
                },
                (Some(&(x, ex)), None) => {
                    i += 1;
                    (x, ex.min(0))
                }
                (None, Some(&(y, ey))) => {
                    j += 1;
                    (y, ey.min(0))
                }
                (None, None) => break,
            };
            if e != 0 {
                out.push((atom, e));
            }
        }
        Mono(out)
    }

    /// Replaces the exponent of `atom` (removing it at zero).
    pub fn with_exponent(&self, atom: Id, e: i32) -> Mono {
        let mut v: SmallVec<[(Id, i32); 4]> = self.0.iter().copied().filter(|&(a, _)| a != atom).collect();
        if e != 0 {
            let pos = v.iter().position(|&(a, _)| a > atom).unwrap_or(v.len());
            v.insert(pos, (atom, e));
        }
        Mono(v)
    }
}

/// Graded order: total degree first, then exponents compared atom by atom in id order (an
/// absent atom has exponent 0). With negative exponents this is still a group order
/// (compatible with multiplication), which is what collecting and exact division need.
impl Ord for Mono {
    fn cmp(&self, other: &Self) -> Ordering {
        self.degree().cmp(&other.degree()).then_with(|| {
            let (a, b) = (&self.0, &other.0);
            let (mut i, mut j) = (0, 0);
            loop {
                match (a.get(i), b.get(j)) {
                    (None, None) => return Ordering::Equal,
                    (Some(&(_, ex)), None) => return ex.cmp(&0),
                    (None, Some(&(_, ey))) => return 0.cmp(&ey),
                    (Some(&(x, ex)), Some(&(y, ey))) => match x.cmp(&y) {
                        // `self` has atom x and `other` does not.
                        Ordering::Less => return ex.cmp(&0),
                        Ordering::Greater => return 0.cmp(&ey),
                        Ordering::Equal => match ex.cmp(&ey) {
                            Ordering::Equal => {
                                i += 1;
                                j += 1;
                            }
                            o => return o,
                        },
                    },
                }
            }
        })
    }
}

impl PartialOrd for Mono {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// A polynomial: terms sorted by increasing monomial, no zero coefficients.
#[derive(Clone, PartialEq, Eq, Hash, Debug, Default, PartialOrd, Ord)]
pub struct Poly(pub Vec<(Mono, Rational)>);

impl Poly {
    pub fn zero() -> Poly {
        Poly(Vec::new())
    }

    pub fn constant(q: Rational) -> Poly {
        if q.is_zero() { Poly::zero() } else { Poly(vec![(Mono::one(), q)]) }
    }

    pub fn atom(id: Id) -> Poly {
        Poly(vec![(Mono::atom(id), Rational::ONE)])
    }

    pub fn is_zero(&self) -> bool {
        self.0.is_empty()
    }

    /// The number of terms (no `is_empty`: that is [`Poly::is_zero`]).
    pub(crate) fn len(&self) -> usize {
        self.0.len()
    }

    pub fn as_constant(&self) -> Option<Rational> {
        match self.0.as_slice() {
            [] => Some(Rational::ZERO),
            [(m, q)] if m.is_one() => Some(q.clone()),
            _ => None,
        }
    }

    /// The single atom, if this is exactly `x`.
    pub fn as_atom(&self) -> Option<Id> {
        match self.0.as_slice() {
            [(m, q)] if q.is_one() => m.as_atom(),
            _ => None,
        }
    }

    /// The leading (largest) term.
    pub fn leading(&self) -> Option<&(Mono, Rational)> {
        self.0.last()
    }

    pub fn add(&self, other: &Poly) -> Poly {
        let (a, b) = (&self.0, &other.0);
        // Bounded by the operands: charged, never refused (the callers that loop check).
        work::charge(
            self.weight().saturating_add(other.weight()).saturating_add(self.atoms()).saturating_add(other.atoms()),
        );
        // Merges: the result's size is bounded by the operands', and growing it was 3 % of the
        // bead's derivation (callgrind).
        let mut out = Vec::with_capacity(a.len() + b.len());
        let (mut i, mut j) = (0, 0);
        while i < a.len() && j < b.len() {
            match a[i].0.cmp(&b[j].0) {
                Ordering::Less => {
                    out.push(a[i].clone());
                    i += 1;
                }
                Ordering::Greater => {
                    out.push(b[j].clone());
                    j += 1;
                }
                Ordering::Equal => {
                    let q = a[i].1.add(&b[j].1);
                    if !q.is_zero() {
                        out.push((a[i].0.clone(), q));
                    }
                    i += 1;
                    j += 1;
                }
            }
        }
        out.extend_from_slice(&a[i..]);
        out.extend_from_slice(&b[j..]);
        Poly(out)
    }

    /// The sum of many polynomials at once: every term gathered, sorted and merged, so a
    /// sum of k polynomials of n terms costs O(kn log kn) rather than k passes over the
    /// growing total. Equal to adding them one by one (the representation is canonical).
    pub fn sum<'a>(polys: impl IntoIterator<Item = &'a Poly>) -> Poly {
        let mut terms: Vec<(Mono, Rational)> = polys.into_iter().flat_map(|p| p.0.iter().cloned()).collect();
        work::charge(terms.len() as u64);
        terms.sort_by(|a, b| a.0.cmp(&b.0));
        let mut out: Vec<(Mono, Rational)> = Vec::new();
        for (m, q) in terms {
            match out.last_mut() {
                Some((last, sum)) if *last == m => *sum = sum.add(&q),
                _ => out.push((m, q)),
            }
        }
        out.retain(|(_, q)| !q.is_zero());
        Poly(out)
    }

    pub fn neg(&self) -> Poly {
        Poly(self.0.iter().map(|(m, q)| (m.clone(), q.neg())).collect())
    }

    pub fn scale(&self, k: &Rational) -> Poly {
        if k.is_zero() {
            return Poly::zero();
        }
        Poly(self.0.iter().map(|(m, q)| (m.clone(), q.mul(k))).collect())
    }

    pub fn mul_mono(&self, m: &Mono) -> Poly {
        // Multiplying every term by the same monomial keeps the order.
        Poly(self.0.iter().map(|(t, q)| (t.mul(m), q.clone())).collect())
    }

    /// The product, or `None` when it would pass [`MAX_TERMS`].
    pub fn mul(&self, other: &Poly) -> Option<Poly> {
        if self.len().saturating_mul(other.len()) > 4 * MAX_TERMS {
            return None;
        }
        // A product's coefficient is a sum of at most min(len) products of two coefficients.
        let sum_bits = 64 - (self.len().min(other.len()) as u64).leading_zeros() as u64;
        if self.max_bits().saturating_add(other.max_bits()).saturating_add(sum_bits) > MAX_COEFFICIENT_BITS {
            return None;
        }
        // Every pair of terms, weighted by their coefficients' words (a product of big
        // numbers is quadratic in words) and their monomials' atoms (merged):
        // Σᵢⱼ (1 + wᵢ)(1 + wⱼ) + aᵢ + aⱼ.
        let (la, lb) = (self.len() as u64, other.len() as u64);
        let cost = (self.weight().saturating_mul(other.weight()))
            .saturating_add(self.atoms().saturating_mul(lb))
            .saturating_add(other.atoms().saturating_mul(la));
        if !work::charge(cost) {
            return None;
        }
        let (small, big) = if self.len() <= other.len() { (self, other) } else { (other, self) };
        // One term (often a constant): every product keeps the order, no merging.
        if let [(m, q)] = small.0.as_slice() {
            let row = if m.is_one() {
                big.0.iter().map(|(t, p)| (t.clone(), p.mul(q))).collect()
            } else {
                big.0.iter().map(|(t, p)| (t.mul(m), p.mul(q))).collect()
            };
            return (big.len() <= MAX_TERMS).then_some(Poly(row));
        }
        let mut acc = Poly::zero();
        for (m, q) in &small.0 {
            let mut row = big.mul_mono(m);
            for t in &mut row.0 {
                t.1 = t.1.mul(q);
            }
            acc = acc.add(&row);
        }
        (acc.len() <= MAX_TERMS).then_some(acc)
    }

    pub fn powi(&self, n: u32) -> Option<Poly> {
        if n == 1 {
            return Some(self.clone());
        }
        // The coefficients of p^n have at least n times the bits of p's leading one.
        if self
            .leading()
            .is_some_and(|(_, q)| q.bits().saturating_sub(2).saturating_mul(u64::from(n)) > MAX_COEFFICIENT_BITS)
        {
            return None;
        }
        let mut result = Poly::constant(Rational::ONE);
        let mut base = self.clone();
        let mut n = n;
        while n > 0 {
            if n & 1 == 1 {
                result = result.mul(&base)?;
            }
            n >>= 1;
            if n > 0 {
                base = base.mul(&base)?;
            }
        }
        Some(result)
    }

    /// What visiting every term costs the work meter: a term and its coefficient's words.
    fn weight(&self) -> u64 {
        self.0.iter().map(|(_, q)| 1 + work::words(q.bits())).sum()
    }

    /// The atoms of every monomial together (what merging them visits).
    fn atoms(&self) -> u64 {
        self.0.iter().map(|(m, _)| m.0.len() as u64).sum()
    }

    /// The most bits of any coefficient (0 for zero).
    pub fn max_bits(&self) -> u64 {
        self.0.iter().map(|(_, q)| q.bits()).max().unwrap_or(0)
    }

    /// The positive rational gcd of the coefficients (1 for zero).
    pub fn content(&self) -> Rational {
        let mut it = self.0.iter();
        let Some((_, first)) = it.next() else { return Rational::ONE };
        it.fold(first.abs(), |g, (_, q)| g.gcd(q))
    }

    /// The largest monomial dividing every term (1 for zero or a constant).
    pub fn common_mono(&self) -> Mono {
        let mut it = self.0.iter();
        let Some((first, _)) = it.next() else { return Mono::one() };
        it.fold(first.clone(), |g, (m, _)| g.gcd(m))
    }

    pub fn div_mono(&self, m: &Mono) -> Poly {
        Poly(self.0.iter().map(|(t, q)| (t.div(m), q.clone())).collect())
    }

    /// `self / d` when `d` divides `self` exactly, by multivariate division.
    pub fn div_exact(&self, d: &Poly) -> Option<Poly> {
        let (lm, lq) = d.leading()?;
        if self.is_zero() {
            return Some(Poly::zero());
        }
        let mut r = self.clone();
        let mut quotient = Poly::zero();
        // Each step removes the leading term of r; the bound keeps a non-divisor cheap.
        for _ in 0..(self.len() + 1) * 4 {
            let Some((rm, rq)) = r.leading().cloned() else { return Some(quotient) };
            if !lm.divides(&rm) || work::exhausted() {
                return None;
            }
            let t = Poly(vec![(rm.div(lm), rq.div(lq)?)]);
            quotient = quotient.add(&t);
            r = r.add(&d.mul(&t)?.neg());
            if r.len() > MAX_TERMS {
                return None;
            }
        }
        r.is_zero().then_some(quotient)
    }

    /// The polynomial `q` with `q² = self` and a positive leading coefficient, if there is
    /// one (over the rationals); `None` past [`MAX_SQUARE_ROOT_TERMS`] terms.
    ///
    /// The leading term of `q` is the root of the leading term of `self`; each next term is
    /// the remainder's leading term over twice `q`'s (as for integers, the order being a
    /// monomial order). A non-square fails at the first term that does not divide.
    pub fn sqrt_exact(&self) -> Option<Poly> {
        if self.len() > MAX_SQUARE_ROOT_TERMS {
            return None;
        }
        let (lm, lq) = self.leading()?;
        let half = |m: &Mono| -> Option<Mono> {
            let half: Option<SmallVec<[(Id, i32); 4]>> =
                m.0.iter().map(|&(a, e)| (e % 2 == 0).then_some((a, e / 2))).collect();
            half.map(Mono)
        };
        // The order is a monomial order, so the lowest term of q² is the square of q's
        // lowest term: a lowest term that is no square rejects at once (most sums).
        let (low_m, low_q) = self.0.first()?;
        half(low_m)?;
        low_q.sqrt_exact()?;
        let lead = (half(lm)?, lq.sqrt_exact()?);
        let twice = (lead.0.clone(), lead.1.mul(&Rational::int(2)));
        let mut root = Poly(vec![lead]);
        // self − root², updated by each new term t: (root + t)² = root² + (2 root + t) t.
        let mut remainder = self.add(&root.mul(&root)?.neg());
        for _ in 0..=self.len() {
            let Some((rm, rq)) = remainder.leading() else { return Some(root) };
            if !twice.0.divides(rm) {
                return None;
            }
            let next = (rm.div(&twice.0), rq.div(&twice.1)?);
            if next.0 >= twice.0 {
                return None;
            }
            let t = Poly(vec![next]);
            let grown = root.add(&t);
            // The coefficients' bound of the product `root · root` this replaces.
            let sum_bits = 64 - (grown.len() as u64).leading_zeros() as u64;
            if grown.max_bits().saturating_mul(2).saturating_add(sum_bits) > MAX_COEFFICIENT_BITS {
                return None;
            }
            let change = root.scale(&Rational::int(2)).add(&t).mul(&t)?;
            remainder = remainder.add(&change.neg());
            root = grown;
        }
        None
    }

    /// Splits `self = k · m · P` with `k` rational (the sign of the leading term), `m` the common
    /// monomial and `P` primitive with a positive leading coefficient.
    pub fn split(&self) -> (Rational, Mono, Poly) {
        let m = self.common_mono();
        let mut k = self.content();
        if self.leading().is_some_and(|(_, q)| q.is_negative()) {
            k = k.neg();
        }
        let inv = k.recip().unwrap_or(Rational::ONE);
        (k, m.clone(), self.div_mono(&m).scale(&inv))
    }
}

/// A rational function: `num / Π factorᵢ^eᵢ`, each factor primitive (or a single atom),
/// with a positive leading coefficient, sorted and distinct.
#[derive(Clone, PartialEq, Eq, Hash, Debug, Default)]
pub struct Frac {
    pub num: Poly,
    pub den: Vec<(Poly, u32)>,
}

impl Frac {
    pub fn zero() -> Frac {
        Frac::default()
    }

    pub fn constant(q: Rational) -> Frac {
        Frac { num: Poly::constant(q), den: Vec::new() }
    }

    pub fn atom(id: Id) -> Frac {
        Frac { num: Poly::atom(id), den: Vec::new() }
    }

    pub fn poly(p: Poly) -> Frac {
        Frac { num: p, den: Vec::new() }
    }

    pub fn is_zero(&self) -> bool {
        self.num.is_zero()
    }

    pub fn as_constant(&self) -> Option<Rational> {
        if self.den.is_empty() { self.num.as_constant() } else { None }
    }

    pub fn neg(&self) -> Frac {
        Frac { num: self.num.neg(), den: self.den.clone() }
    }

    pub fn scale(&self, k: &Rational) -> Frac {
        if k.is_zero() {
            return Frac::zero();
        }
        Frac { num: self.num.scale(k), den: self.den.clone() }
    }

    pub fn add(&self, other: &Frac) -> Option<Frac> {
        if self.is_zero() {
            return Some(other.clone());
        }
        if other.is_zero() {
            return Some(self.clone());
        }
        if self.den == other.den {
            return Some(Frac { num: self.num.add(&other.num), den: self.den.clone() }.normalize());
        }
        let lcm = lcm(&self.den, &other.den);
        let a = self.num.mul(&expand(&quotient(&lcm, &self.den))?)?;
        let b = other.num.mul(&expand(&quotient(&lcm, &other.den))?)?;
        Some(Frac { num: a.add(&b), den: lcm }.normalize())
    }

    pub fn sub(&self, other: &Frac) -> Option<Frac> {
        self.add(&other.neg())
    }

    pub fn mul(&self, other: &Frac) -> Option<Frac> {
        if self.is_zero() || other.is_zero() {
            return Some(Frac::zero());
        }
        // A constant factor (the 1 a product starts from): scaling keeps a normal form normal.
        if let Some(c) = self.as_constant() {
            return Some(other.scale(&c));
        }
        if let Some(c) = other.as_constant() {
            return Some(self.scale(&c));
        }
        let num = self.num.mul(&other.num)?;
        let mut den = self.den.clone();
        for (f, e) in &other.den {
            push_factor(&mut den, f.clone(), *e);
        }
        Some(Frac { num, den }.normalize())
    }

    /// `1 / self`, or `None` for zero or when too large.
    pub fn recip(&self) -> Option<Frac> {
        if self.is_zero() {
            return None;
        }
        let (k, m, p) = self.num.split();
        let mut den = Vec::new();
        // A radical's negative power in the numerator comes back up as a positive one.
        let (negative, positive) = m.split_negative();
        for &(a, e) in &positive.0 {
            push_factor(&mut den, Poly::atom(a), e.unsigned_abs());
        }
        if p.as_constant().is_none() {
            push_factor(&mut den, p, 1);
        }
        let mut num = expand(&self.den)?.scale(&k.recip()?);
        if !negative.is_one() {
            num = num.mul_mono(&negative.inverse());
        }
        Some(Frac { num, den }.normalize())
    }

    pub fn powi(&self, n: i64) -> Option<Frac> {
        if n == -1 {
            return self.recip();
        }
        if n < 0 {
            return self.recip()?.powi(n.checked_neg()?);
        }
        let n = u32::try_from(n).ok()?;
        let num = self.num.powi(n)?;
        let den = self.den.iter().map(|(f, e)| (f.clone(), e.saturating_mul(n))).collect();
        Some(Frac { num, den }.normalize())
    }

    /// Cancels common atoms and exactly dividing factors between numerator and denominator.
    pub fn normalize(mut self) -> Frac {
        if self.num.is_zero() {
            self.den.clear();
            return self;
        }
        if self.den.is_empty() {
            return self;
        }
        let common = self.num.common_mono();
        let mut cancel = Mono::one();
        for (f, e) in &mut self.den {
            if let Some(a) = f.as_atom() {
                let k = common.exponent(a).min(i32::try_from(*e).unwrap_or(i32::MAX));
                if k > 0 {
                    *e -= k.unsigned_abs();
                    cancel = cancel.mul(&Mono(smallvec::smallvec![(a, k)]));
                }
            } else {
                while *e > 0 && self.num.len() >= f.len() {
                    match self.num.div_exact(f) {
                        Some(q) => {
                            self.num = q;
                            *e -= 1;
                        }
                        None => break,
                    }
                }
            }
        }
        if !cancel.is_one() {
            self.num = self.num.div_mono(&cancel);
        }
        self.den.retain(|(_, e)| *e > 0);
        self
    }
}

/// Adds `f^e` to a factor list, keeping it sorted and merged.
pub fn push_factor(den: &mut Vec<(Poly, u32)>, f: Poly, e: u32) {
    if e == 0 {
        return;
    }
    match den.binary_search_by(|(g, _)| g.cmp(&f)) {
        Ok(i) => den[i].1 += e,
        Err(i) => den.insert(i, (f, e)),
    }
}

/// The least common multiple of two factor lists (maximum exponents).
fn lcm(a: &[(Poly, u32)], b: &[(Poly, u32)]) -> Vec<(Poly, u32)> {
    let mut out = a.to_vec();
    for (f, e) in b {
        match out.binary_search_by(|(g, _)| g.cmp(f)) {
            Ok(i) => out[i].1 = out[i].1.max(*e),
            Err(i) => out.insert(i, (f.clone(), *e)),
        }
    }
    out
}

/// `big / small` for factor lists where `small` divides `big`.
fn quotient(big: &[(Poly, u32)], small: &[(Poly, u32)]) -> Vec<(Poly, u32)> {
    big.iter()
        .filter_map(|(f, e)| {
            let s = small.iter().find(|(g, _)| g == f).map_or(0, |(_, k)| *k);
            (e > &s).then(|| (f.clone(), e - s))
        })
        .collect()
}

/// The product of a factor list as one polynomial.
pub fn expand(factors: &[(Poly, u32)]) -> Option<Poly> {
    let mut acc = Poly::constant(Rational::ONE);
    for (f, e) in factors {
        acc = acc.mul(&f.powi(*e)?)?;
    }
    Some(acc)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::graph::Graph;

    fn atoms() -> (Id, Id) {
        let mut g = Graph::new(2);
        (g.int(7), g.int(8))
    }

    #[test]
    fn sum_of_many_equals_adding_one_by_one() {
        let (x, y) = atoms();
        let (px, py) = (Poly::atom(x), Poly::atom(y));
        let one = Poly::constant(Rational::ONE);
        let a = px.add(&one).powi(3).expect("small");
        let b = py.add(&px.neg()).powi(2).expect("small");
        let c = a.neg();
        let d = px.mul(&py).expect("small").scale(&Rational::int(5));
        let polys = [a, b, c, d, Poly::zero(), one];
        let pairwise = polys.iter().fold(Poly::zero(), |acc, p| acc.add(p));
        assert_eq!(Poly::sum(&polys), pairwise);
        // Terms that cancel are gone, not kept with a zero coefficient.
        assert!(Poly::sum([&polys[0], &polys[2]]).is_zero());
    }

    #[test]
    fn graded_order_is_a_monomial_order() {
        let (x, y) = atoms();
        let mx = Mono::atom(x);
        let my = Mono::atom(y);
        let ms = [Mono::one(), mx.clone(), my.clone(), mx.mul(&mx), mx.mul(&my), my.mul(&my)];
        for a in &ms {
            for b in &ms {
                for c in &ms {
                    if a < b {
                        assert!(a.mul(c) < b.mul(c), "{a:?} < {b:?} but not after * {c:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn exact_division_and_cancellation() {
        let (x, y) = atoms();
        let px = Poly::atom(x);
        let py = Poly::atom(y);
        let sum = px.add(&py);
        let diff = px.add(&py.neg());
        let prod = sum.mul(&diff).unwrap();
        assert_eq!(prod.div_exact(&sum), Some(diff.clone()));
        assert_eq!(prod.div_exact(&px.add(&Poly::constant(Rational::int(3)))), None);
        // (x² − y²) / (x + y) = x − y
        let f = Frac::poly(prod).mul(&Frac::poly(sum).recip().unwrap()).unwrap();
        assert_eq!(f, Frac::poly(diff));
        // x / x = 1
        let one = Frac::atom(x).mul(&Frac::atom(x).recip().unwrap()).unwrap();
        assert_eq!(one.as_constant(), Some(Rational::ONE));
    }

    #[test]
    fn expansion_is_bounded() {
        let (x, y) = atoms();
        let s = Poly::atom(x).add(&Poly::atom(y));
        assert!(s.powi(10).is_some());
        assert!(s.powi(100_000).is_none());
    }
}
