//! From canonical form back to a graph a person reads easily.
//!
//! The canonical form is fully expanded (`r1·r1 − 2 r1·r2 + r2·r2`); this module lays it out
//! the way a derivation is written by hand, without changing its value:
//! - a fraction is one numerator over one denominator, with the rational content and sign
//!   in front: `−(m v·v + F·r)/(r·r)`;
//! - a common monomial is taken out of a sum: `m (x + y)`;
//! - dot products that factor are factored back: `(r1 − r2)·(v1 − v2)`, found as a rank-one
//!   bilinear form over the vector atoms (this also keeps the formula accurate in f64: no
//!   cancellation between `r1·r1` and `r2·r2` for nearby bodies far from the origin);
//! - a vector groups its atoms by common coefficient: `−(m v·v + F·r)/(r·r) r`,
//!   `2 (r1 − r2)`, unit vectors as one literal `[x, y]`;
//! - terms are ordered by weighted degree, kinematic atoms (positions, velocities, …) before
//!   parameters, so `r·r − l²`, `m v·v + F·r`, `2 v·v + 2 r·a` read as in the article;
//! - a difference of vectors the user wrote (`r2 − r1` in a constraint or a definition) keeps
//!   the user's orientation and order wherever the layout writes that combination or its
//!   negation ([`Simplifier::keep_orientations`]); others start with a positive entry.
//!
//! Whatever is built here simplifies back to the same canonical form (tested), so
//! `simplify` is idempotent.

use super::graph::{FastMap, Graph, Id, Marks, Node, Role, Ty, TypeError};
use super::num::Rational;
use super::poly::{Frac, MAX_SQUARE_ROOT_TERMS, Mono, Poly, push_factor};
use super::simplify::{Canon, Simplifier, VAtom, VecForm};
use super::work;
use smallvec::SmallVec;
use std::cmp::Ordering;

/// Vector combinations as the user wrote them, by their canonical form: the primitive
/// integer combination in atom order with a positive first entry (`r1 − r2`) → the user's
/// primitive combination in the user's order and sign (`r2 − r1`).
pub(crate) type Orientations = FastMap<Vec<(Id, Rational)>, Vec<(Id, Rational)>>;

impl Simplifier {
    /// Remembers every sum of two or more vector atoms with constant coefficients under
    /// `roots` (`r2 - r1` as lowered from a constraint or a definition), so that the
    /// layout writes that combination, or its negation, as the user did: `(r2 − r1)·(v2 − v1)`,
    /// not `(r1 − r2)·(v1 − v2)`. The value is the same either way; only the sign taken out
    /// and the order of the terms change. Call it before simplifying (the layout is
    /// memoised). One walk over the nodes under `roots`, each visited once.
    ///
    /// Positions' differences carry their orientation to the velocities and accelerations
    /// (`r2 − r1` makes `v2 − v1` and `a2 − a1`), and to the bodies' forces (`F2 − F1`),
    /// `forces` being each body's force node by body index.
    pub fn keep_orientations(&mut self, g: &mut Graph, roots: &[Id], forces: &[Id]) {
        let mut seen: Marks = Marks::default();
        seen.clear();
        let mut stack: Vec<Id> = roots.to_vec();
        while let Some(id) = stack.pop() {
            if !seen.insert(id.index()) {
                continue;
            }
            let node = g.node(id);
            if let Node::Add(xs) = node
                && g.ty(id) == Ty::Vector
                && let Some(written) = constant_combination(g, xs)
            {
                let of_forces = forces_combination(g, &written, forces);
                let mut next = Some(written);
                while let Some(written) = next.take() {
                    next = derivative_combination(g, &written);
                    self.remember_orientation(g, written);
                }
                if let Some(written) = of_forces {
                    self.remember_orientation(g, written);
                }
            }
            stack.extend_from_slice(g.node(id).children());
        }
    }

    /// `written` (a combination as the user wrote it) by its canonical form; the first
    /// one written wins.
    fn remember_orientation(&mut self, g: &Graph, written: Vec<(Id, Rational)>) {
        let (written, _) = primitive_keeping_sign(written);
        // The canonical form is the same primitive combination in node order, its first
        // entry positive (what `canonical_primitive` of the sorted combination gives).
        let mut canonical = written.clone();
        canonical.sort_by(|x, y| g.cmp_nodes(x.0, y.0));
        if canonical.first().is_some_and(|(_, q)| q.is_negative()) {
            canonical.iter_mut().for_each(|(_, q)| *q = q.neg());
        }
        self.orientations.entry(canonical).or_insert(written);
    }

    /// The readable graph of a canonical form.
    pub(super) fn build(&mut self, g: &mut Graph, c: &Canon) -> Result<Id, TypeError> {
        match c {
            Canon::S(f) => self.build_frac(g, f),
            Canon::V(v) => self.build_vec(g, v),
        }
    }

    /// A scalar form with every coefficient on its own term and no content in front:
    /// `r.x − 10⁻⁴⁰⁰` rather than `10⁻⁴⁰⁰ (10⁴⁰⁰ r.x − 1)`, whose factors are out of f64's
    /// range apart though the whole is not. For numbers only
    /// ([`DerivedConstraint::over_scale`](crate::derive::DerivedConstraint)); the documents
    /// use `build`. A vector form is built as `build` does.
    pub(super) fn build_distributed(&mut self, g: &mut Graph, c: &Canon) -> Result<Id, TypeError> {
        let Canon::S(f) = c else { return self.build(g, c) };
        if let Some(q) = f.as_constant() {
            return Ok(g.num(q));
        }
        let terms = (f.num.0.iter())
            .map(|(m, q)| {
                let factors = mono_factors(g, m)?;
                term(g, q, factors)
            })
            .collect::<Result<Vec<Id>, TypeError>>()?;
        let sum = g.add(terms)?;
        if f.den.is_empty() {
            return Ok(sum);
        }
        let inverse = self.inverse_denominator(g, &Rational::ONE, &f.den)?;
        g.mul(vec![sum, inverse])
    }

    fn build_frac(&mut self, g: &mut Graph, f: &Frac) -> Result<Id, TypeError> {
        if let Some(q) = f.as_constant() {
            return Ok(g.num(q));
        }
        if f.num.0.iter().any(|(m, _)| m.has_negative()) {
            return self.build_separated(g, f);
        }
        self.build_one_fraction(g, f)
    }

    /// A numerator with radicals' negative powers (`|d|⁻¹`, `|d|⁻³`): one fraction per
    /// power, `x/|d1| + y/|d2|³`, each over its own roots, never one common denominator of
    /// them all (that form multiplies every numerator by every other root, and grows
    /// exponentially in the number of roots). The denominator's other factors stay
    /// outside: `(x/|d1| + y/|d2|)/(m1 m2)`.
    fn build_separated(&mut self, g: &mut Graph, f: &Frac) -> Result<Id, TypeError> {
        let mut groups: Vec<(Mono, Vec<(Mono, Rational)>)> = Vec::new();
        for (m, q) in &f.num.0 {
            let (negative, positive) = m.split_negative();
            match groups.iter_mut().find(|(n, _)| *n == negative) {
                Some((_, terms)) => terms.push((positive, q.clone())),
                None => groups.push((negative, vec![(positive, q.clone())])),
            }
        }
        let mut parts: Vec<(Frac, Id)> = Vec::new();
        let single = groups.len() == 1;
        for (negative, terms) in groups {
            let mut terms = terms;
            terms.sort_by(|a, b| a.0.cmp(&b.0));
            let mut den: Vec<(Poly, u32)> = if single { f.den.clone() } else { Vec::new() };
            for &(a, e) in &negative.0 {
                push_factor(&mut den, Poly::atom(a), e.unsigned_abs());
            }
            let part = Frac { num: Poly(terms), den };
            let node = self.build_one_fraction(g, &part)?;
            parts.push((part, node));
        }
        // Groups by the power of their roots (`x/|d|` before `y/|d|³`, as written by hand),
        // then in reading order of their numerators, then by their roots.
        let power = |f: &Frac| f.den.iter().filter(|(p, _)| p.as_atom().is_some()).map(|(_, e)| *e).sum::<u32>();
        // Each numerator's reading keys are computed once, not at every comparison.
        let mut keyed: Vec<(Vec<ReadingKey>, (Frac, Id))> =
            parts.into_iter().map(|part| (reading_keys(g, &part.0.num), part)).collect();
        keyed.sort_by(|(ka, a), (kb, b)| {
            power(&a.0).cmp(&power(&b.0)).then_with(|| cmp_keys_reading(g, ka, kb)).then_with(|| {
                let roots = |f: &Frac| f.den.iter().filter_map(|(p, _)| p.as_atom()).collect::<Vec<_>>();
                let (ra, rb) = (roots(&a.0), roots(&b.0));
                ra.iter()
                    .zip(&rb)
                    .map(|(x, y)| g.cmp_nodes(*x, *y))
                    .find(|o| o.is_ne())
                    .unwrap_or(ra.len().cmp(&rb.len()))
            })
        });
        let sum = g.add(keyed.into_iter().map(|(_, (_, n))| n).collect())?;
        if single || f.den.is_empty() {
            return Ok(sum);
        }
        let inverse = self.inverse_denominator(g, &Rational::ONE, &f.den)?;
        g.mul(vec![sum, inverse])
    }

    /// One numerator over one denominator.
    fn build_one_fraction(&mut self, g: &mut Graph, f: &Frac) -> Result<Id, TypeError> {
        if let Some(q) = f.as_constant() {
            return Ok(g.num(q));
        }
        // Room up front: this list becomes a node's `Box<[Id]>` (callgrind: 3 % of the
        // bead's derivation without the room here and in the lists below).
        let mut factors = Vec::with_capacity(4);
        let k = if let [(m, _)] = f.num.0.as_slice() {
            factors.extend(mono_factors(g, m)?);
            signed_content(g, &f.num)
        } else {
            let common = f.num.common_mono();
            if common.is_one() {
                // Without a common factor the terms to lay out are the numerator's own
                // monomials: put them in reading order once, for the sign and the sum.
                let ordered = reading_order(g, &f.num);
                let k = with_sign_of(f.num.content(), ordered.first());
                let inv = k.recip().unwrap_or(Rational::ONE);
                let rest: Vec<(Mono, Rational)> = ordered.into_iter().map(|(m, q)| (m, q.mul(&inv))).collect();
                factors.push(self.build_ordered(g, rest)?);
                k
            } else {
                let k = signed_content(g, &f.num);
                let inv = k.recip().unwrap_or(Rational::ONE);
                factors.extend(mono_factors(g, &common)?);
                let rest = f.num.div_mono(&common).scale(&inv);
                factors.push(self.build_poly(g, &rest)?);
                k
            }
        };
        if f.den.is_empty() {
            return term(g, &k, factors);
        }
        // Rational content p/q: p stays in front, q joins the denominator.
        let (p, q) = k.split_parts();
        let numerator = term(g, &p, factors)?;
        let inv_den = self.inverse_denominator(g, &q, &f.den)?;
        let mut all = splice(g, numerator);
        all.push(inv_den);
        g.mul(all)
    }

    /// `1/(q Π fᵢ^eᵢ)` as one node: the factors in reading order, one power alone written
    /// `x/|d|³` rather than `x/(|d|³)`.
    fn inverse_denominator(&mut self, g: &mut Graph, q: &Rational, factors: &[(Poly, u32)]) -> Result<Id, TypeError> {
        let mut den = Vec::new();
        if !q.is_one() {
            den.push(g.num(q.clone()));
        }
        let mut dens: Vec<(Vec<ReadingKey>, &(Poly, u32))> =
            factors.iter().map(|f| (reading_keys(g, &f.0), f)).collect();
        dens.sort_by(|(ka, _), (kb, _)| cmp_keys_reading(g, ka, kb));
        for (_, (factor, e)) in dens {
            let node = match factor.as_atom() {
                Some(a) => a,
                None => self.build_poly(g, factor)?,
            };
            den.push(if *e == 1 { node } else { g.powi(node, i64::from(*e))? });
        }
        match den.as_slice() {
            [one] => match g.node(*one) {
                &Node::Pow([b, e]) if g.as_num(e).and_then(Rational::to_i64).is_some_and(|n| n > 1) => {
                    let n = g.as_num(e).and_then(Rational::to_i64).unwrap_or(1);
                    g.powi(b, -n)
                }
                _ => g.powi(*one, -1),
            },
            _ => {
                let denominator = g.mul(den)?;
                g.powi(denominator, -1)
            }
        }
    }

    /// A primitive polynomial as a sum, with factorable dot products factored.
    fn build_poly(&mut self, g: &mut Graph, p: &Poly) -> Result<Id, TypeError> {
        self.build_ordered(g, reading_order(g, p))
    }

    /// [`Simplifier::build_poly`] of terms already in reading order.
    fn build_ordered(&mut self, g: &mut Graph, terms: Vec<(Mono, Rational)>) -> Result<Id, TypeError> {
        // A perfect square is written as one: `((r1 − p)·v1)²`, not its three expanded terms.
        if terms.len() >= 3 && terms.len() <= MAX_SQUARE_ROOT_TERMS {
            let mut p = Poly(terms.clone());
            p.0.sort_by(|a, b| a.0.cmp(&b.0));
            if let Some(root) = p.sqrt_exact().filter(|r| r.len() >= 2) {
                let root = if signed_content(g, &root).is_negative() { root.neg() } else { root };
                let base = self.build_poly(g, &root)?;
                return g.powi(base, 2);
            }
        }
        let mut replaced: FastMap<usize, Option<(Rational, Mono, Id)>> = FastMap::default();
        for (indices, factored) in bilinear_groups(g, &terms, &self.orientations)? {
            for (n, &i) in indices.iter().enumerate() {
                replaced.insert(i, if n == 0 { Some(factored.clone()) } else { None });
            }
        }
        // Factored groups with the same dot product combine: m1 X + m2 X = (m1 + m2) X.
        let mut by_dot: FastMap<Id, Poly> = FastMap::default();
        for (k, cofactor, dot) in replaced.values().flatten() {
            let part = Poly(vec![(cofactor.clone(), k.clone())]);
            let sum = by_dot.get(dot).map_or(part.clone(), |p| p.add(&part));
            by_dot.insert(*dot, sum);
        }
        // Exact room, as the factors above.
        let mut nodes = Vec::with_capacity(terms.len());
        for (i, (m, q)) in terms.iter().enumerate() {
            match replaced.get(&i) {
                Some(Some((_, _, dot))) => {
                    let Some(cofactors) = by_dot.remove(dot) else { continue };
                    let node = if cofactors.len() == 1 {
                        let (c, k) = &cofactors.0[0];
                        let mut factors = mono_factors(g, c)?;
                        factors.push(*dot);
                        term(g, k, factors)?
                    } else {
                        let (k, common, rest) = cofactors.split();
                        let mut factors = mono_factors(g, &common)?;
                        factors.push(self.build_poly(g, &rest)?);
                        factors.push(*dot);
                        term(g, &k, factors)?
                    };
                    nodes.push(node);
                }
                Some(None) => {}
                None => {
                    let factors = mono_factors(g, m)?;
                    nodes.push(term(g, q, factors)?);
                }
            }
        }
        g.add(nodes)
    }

    fn build_vec(&mut self, g: &mut Graph, v: &VecForm) -> Result<Id, TypeError> {
        if v.0.is_empty() {
            return Ok(g.zero_vector());
        }
        let mut literal: Vec<Option<Id>> = vec![None; g.dim()];
        // Group atoms whose coefficients agree up to a rational factor: shape → [(atom, k)].
        let mut groups: Vec<(Frac, Vec<(Id, Rational)>)> = Vec::new();
        let mut atoms: Vec<(Id, &Frac)> = Vec::new();
        for (u, s) in &v.0 {
            match u {
                VAtom::Basis(axis) => literal[axis.index()] = Some(self.build_frac(g, s)?),
                VAtom::Atom(a) => atoms.push((*a, s)),
            }
        }
        atoms.sort_by(|x, y| g.cmp_nodes(x.0, y.0));
        for (a, s) in atoms {
            let k = signed_content(g, &s.num);
            let shape = s.scale(&k.recip().unwrap_or(Rational::ONE));
            match groups.iter_mut().find(|(sh, _)| *sh == shape) {
                Some((_, members)) => members.push((a, k)),
                None => groups.push((shape, vec![(a, k)])),
            }
        }
        let mut nodes = Vec::new();
        for (shape, members) in groups {
            let mut kk = members[0].1.abs();
            for (_, k) in &members[1..] {
                kk = kk.gcd(k);
            }
            if members[0].1.is_negative() {
                kk = kk.neg();
            }
            let inv = kk.recip().unwrap_or(Rational::ONE);
            let combination: Vec<(Id, Rational)> = members.iter().map(|(a, k)| (*a, k.mul(&inv))).collect();
            // A difference the user wrote keeps the user's orientation: `−(r2 − r1)`.
            let (combination, sign) = if combination.len() >= 2 {
                primitive(combination, &self.orientations)
            } else {
                (combination, Rational::ONE)
            };
            let kk = kk.mul(&sign);
            let vector = vector_sum(g, &combination)?;
            let scalar = self.build_frac(g, &shape.scale(&kk))?;
            nodes.push(times(g, scalar, vector)?);
        }
        if literal.iter().any(Option::is_some) {
            let zero = g.int(0);
            let entries = literal.into_iter().map(|e| e.unwrap_or(zero)).collect();
            nodes.push(g.vector(entries)?);
        }
        g.add(nodes)
    }
}

/// `coef · f₁ ⋯ fₙ` as people write it (and as the parser reads it back): `f₁ f₂` for 1,
/// `−f₁ f₂` (the first factor negated) for −1, `3 f₁ f₂` otherwise.
fn term(g: &mut Graph, coef: &Rational, factors: Vec<Id>) -> Result<Id, TypeError> {
    if factors.is_empty() {
        return Ok(g.num(coef.clone()));
    }
    if coef.is_one() {
        return g.mul(factors);
    }
    let minus_one = Rational::int(-1);
    if *coef == minus_one {
        let mut factors = factors;
        factors[0] = g.neg(factors[0]);
        return g.mul(factors);
    }
    let mut all = vec![g.num(coef.clone())];
    all.extend(factors);
    g.mul(all)
}

/// [`term`] of one factor, without its lists: `x`, `−x` or `3 x`.
fn term1(g: &mut Graph, coef: &Rational, x: Id) -> Result<Id, TypeError> {
    if coef.is_one() {
        return Ok(x);
    }
    if *coef == Rational::int(-1) {
        return Ok(g.neg(x));
    }
    let k = g.num(coef.clone());
    g.mul(vec![k, x])
}

/// `s · v` with `s` scalar: the factors of `s` followed by `v`.
fn times(g: &mut Graph, s: Id, v: Id) -> Result<Id, TypeError> {
    if g.as_num(s).is_some_and(Rational::is_one) {
        return Ok(v);
    }
    let mut factors = splice(g, s);
    factors.push(v);
    g.mul(factors)
}

/// The factors of a product, to be joined into a larger product; a negation `−x` stays whole.
fn splice(g: &Graph, id: Id) -> Vec<Id> {
    match g.node(id) {
        Node::Mul(xs) if !is_negation(g, id) => xs.to_vec(),
        _ => vec![id],
    }
}

/// Whether `id` is `(−1)·x`, the graph's negation.
pub(super) fn is_negation(g: &Graph, id: Id) -> bool {
    match g.node(id) {
        Node::Mul(xs) => xs.len() == 2 && g.as_num(xs[0]).is_some_and(|q| *q == Rational::int(-1)),
        _ => false,
    }
}

/// The atoms of a monomial as factors `x` or `x^e`, in canonical atom order.
fn mono_factors(g: &mut Graph, m: &Mono) -> Result<Vec<Id>, TypeError> {
    let mut atoms: Vec<(Id, i32)> = m.0.to_vec();
    atoms.sort_by(|a, b| g.cmp_nodes(a.0, b.0));
    atoms.into_iter().map(|(a, e)| if e == 1 { Ok(a) } else { g.powi(a, i64::from(e)) }).collect()
}

/// The content of `p` with the sign of its first term in reading order.
fn signed_content(g: &Graph, p: &Poly) -> Rational {
    let k = p.content();
    // The first term in reading order is the first minimum of the order (the sort is stable).
    let first = match p.0.as_slice() {
        [only] => Some(only),
        terms => terms
            .iter()
            .map(|t| (reading_key(g, &t.0), t))
            .min_by(|a, b| cmp_reading_keys(g, &a.0, &b.0))
            .map(|(_, t)| t),
    };
    with_sign_of(k, first)
}

/// `k`, negated when the first term in reading order is negative.
fn with_sign_of(k: Rational, first: Option<&(Mono, Rational)>) -> Rational {
    match first {
        Some((_, q)) if q.is_negative() => k.neg(),
        _ => k,
    }
}

/// The terms of `p` in the order people read: higher weighted degree first, then terms with
/// positions, velocities and forces before those of parameters alone.
fn reading_order(g: &Graph, p: &Poly) -> Vec<(Mono, Rational)> {
    if p.len() < 2 {
        return p.0.clone();
    }
    // Each term's key is computed once, not once per comparison (that allocated and
    // walked the atoms O(n log n) times and was a seventh of a chain's derivation).
    let mut keyed: Vec<(ReadingKey, &(Mono, Rational))> = p.0.iter().map(|t| (reading_key(g, &t.0), t)).collect();
    keyed.sort_by(|a, b| cmp_reading_keys(g, &a.0, &b.0));
    keyed.into_iter().map(|(_, t)| t.clone()).collect()
}

/// A polynomial's reading keys in reading order: what two polynomials are compared by
/// ([`cmp_keys_reading`]), computed once for each polynomial of a list to be sorted.
fn reading_keys(g: &Graph, p: &Poly) -> Vec<ReadingKey> {
    let mut keys: Vec<ReadingKey> = p.0.iter().map(|(m, _)| reading_key(g, m)).collect();
    keys.sort_by(|a, b| cmp_reading_keys(g, a, b));
    keys
}

/// Two polynomials in reading order, term by term, then the shorter first.
fn cmp_keys_reading(g: &Graph, a: &[ReadingKey], b: &[ReadingKey]) -> Ordering {
    for (x, y) in a.iter().zip(b) {
        let o = cmp_reading_keys(g, x, y);
        if o != Ordering::Equal {
            return o;
        }
    }
    a.len().cmp(&b.len())
}

/// What the reading order compares: the weighted degree, then the atoms with kinematic
/// ones (positions, velocities, …) first.
struct ReadingKey {
    degree: i64,
    atoms: SmallVec<[(bool, Id, i32); 4]>,
}

fn reading_key(g: &Graph, m: &Mono) -> ReadingKey {
    let mut atoms: SmallVec<[(bool, Id, i32); 4]> = m.0.iter().map(|&(x, e)| (is_kinematic(g, x), x, e)).collect();
    atoms.sort_by(|p, q| q.0.cmp(&p.0).then_with(|| g.cmp_nodes(p.1, q.1)));
    ReadingKey { degree: weighted_degree(g, m), atoms }
}

fn cmp_reading_keys(g: &Graph, a: &ReadingKey, b: &ReadingKey) -> Ordering {
    b.degree.cmp(&a.degree).then_with(|| {
        for (x, y) in a.atoms.iter().zip(&b.atoms) {
            let o = y.0.cmp(&x.0).then_with(|| g.cmp_nodes(x.1, y.1)).then_with(|| y.2.cmp(&x.2));
            if o != Ordering::Equal {
                return o;
            }
        }
        b.atoms.len().cmp(&a.atoms.len())
    })
}

/// Degree counting a dot product as two factors, a triple product as three.
fn weighted_degree(g: &Graph, m: &Mono) -> i64 {
    m.0.iter()
        .map(|&(a, e)| {
            let w = match g.node(a) {
                Node::Dot([_, b]) if matches!(g.node(*b), Node::Cross(_)) => 3,
                Node::Dot(_) | Node::Cross(_) => 2,
                _ => 1,
            };
            w * i64::from(e)
        })
        .sum()
}

/// An atom with at most this many children, all symbols, is judged by looking at them:
/// the walk of [`is_kinematic`] would visit them all well within [`KINEMATIC_BUDGET`] and
/// give the same answer. Eight covers every atom the simplifier makes of symbols (a dot
/// product, a component, a function of one or two symbols, a 3D triple product).
const DIRECT_CHILDREN: usize = 8;

/// How many nodes [`is_kinematic`] visits before it calls an atom not kinematic. Atoms are
/// small (dot products, components, functions of a few symbols); a larger one is a piece
/// kept unexpanded, and past this budget it is laid out as a parameter would be. The
/// choice moves where such a piece is written, never a value, and bounds the layout's
/// cost per atom.
const KINEMATIC_BUDGET: usize = 64;

/// Whether an atom involves a body's position, velocity, acceleration or force.
fn is_kinematic(g: &Graph, atom: Id) -> bool {
    let kinematic_symbol = |id: Id| match g.node(id) {
        Node::Sym(s) => !matches!(g.symbol(*s).role, Role::Parameter | Role::Mass { .. } | Role::Time),
        _ => false,
    };
    // Most atoms are a symbol or a few symbols under one node (`r·v`, `r.x`): the walk
    // below would visit them all well within its budget, so look at them directly.
    let children = g.node(atom).children();
    if children.len() <= DIRECT_CHILDREN && children.iter().all(|&c| matches!(g.node(c), Node::Sym(_))) {
        return kinematic_symbol(atom) || children.iter().any(|&c| kinematic_symbol(c));
    }
    let mut stack: SmallVec<[Id; 16]> = smallvec::smallvec![atom];
    let mut budget = KINEMATIC_BUDGET;
    let mut found = false;
    while let Some(id) = stack.pop() {
        if let Node::Sym(s) = g.node(id)
            && !matches!(g.symbol(*s).role, Role::Parameter | Role::Mass { .. } | Role::Time)
        {
            found = true;
            break;
        }
        budget -= 1;
        if budget == 0 {
            break;
        }
        stack.extend_from_slice(g.node(id).children());
    }
    // The nodes visited, charged to the formula's work (a layout of many large atoms is work).
    work::charge((KINEMATIC_BUDGET - budget) as u64);
    found
}

/// A term eligible for dot factoring: `cofactor · (u·w)`.
struct DotTerm {
    index: usize,
    u: Id,
    w: Id,
    coef: Rational,
}

/// Groups of terms that factor as `k · cofactor · (Σ aᵢ uᵢ)·(Σ bⱼ wⱼ)`; each with the term
/// indices it replaces and the replacement `(k, cofactor, dot product)`.
#[allow(clippy::type_complexity)]
fn bilinear_groups(
    g: &mut Graph,
    terms: &[(Mono, Rational)],
    orientations: &Orientations,
) -> Result<Vec<(Vec<usize>, (Rational, Mono, Id))>, TypeError> {
    // Group by cofactor: the monomial without its single dot atom (groups in order of first
    // appearance, found through a map: a sum of thousands of dot products stays linear).
    let mut by_cofactor: Vec<(Mono, Vec<DotTerm>)> = Vec::new();
    let mut group_of: FastMap<Mono, usize> = FastMap::default();
    for (index, (m, q)) in terms.iter().enumerate() {
        let dots: SmallVec<[(Id, i32); 4]> =
            m.0.iter().copied().filter(|(a, _)| matches!(g.node(*a), Node::Dot(_)) && !is_triple(g, *a)).collect();
        let [(dot, 1)] = dots.as_slice() else { continue };
        let Node::Dot([u, w]) = *g.node(*dot) else { continue };
        let cofactor = m.with_exponent(*dot, 0);
        let t = DotTerm { index, u, w, coef: q.clone() };
        match group_of.get(&cofactor) {
            Some(&k) => by_cofactor[k].1.push(t),
            None => {
                group_of.insert(cofactor.clone(), by_cofactor.len());
                by_cofactor.push((cofactor, vec![t]));
            }
        }
    }
    let mut out = Vec::new();
    for (cofactor, list) in by_cofactor {
        if list.len() < 2 {
            continue;
        }
        for component in components(&list) {
            if component.len() < 2 {
                continue;
            }
            let members: Vec<&DotTerm> = component.iter().map(|&i| &list[i]).collect();
            if let Some((k, a, b)) = factor_bilinear(g, &members, orientations) {
                let ua = vector_sum(g, &a)?;
                let wb = vector_sum(g, &b)?;
                let (x, y) = if g.cmp_nodes(a[0].0, b[0].0).is_le() { (ua, wb) } else { (wb, ua) };
                let dot = g.dot(x, y)?;
                let indices = members.iter().map(|t| t.index).collect();
                out.push((indices, (k, cofactor.clone(), dot)));
            }
        }
    }
    Ok(out)
}

fn is_triple(g: &Graph, a: Id) -> bool {
    matches!(g.node(a), Node::Dot([_, b]) if matches!(g.node(*b), Node::Cross(_)))
}

/// Connected components of the terms, joined when they share a vector atom: each term is
/// joined to the first term that had each of its atoms (union–find), so the work is linear
/// in the terms. Components come in order of their first term, members in term order.
fn components(list: &[DotTerm]) -> Vec<Vec<usize>> {
    let mut parent: Vec<usize> = (0..list.len()).collect();
    fn find(parent: &mut [usize], i: usize) -> usize {
        let mut r = i;
        while parent[r] != r {
            r = parent[r];
        }
        // Path compression: every node on the way now points at the root.
        let mut i = i;
        while parent[i] != r {
            let next = parent[i];
            parent[i] = r;
            i = next;
        }
        r
    }
    let mut first_with: FastMap<Id, usize> = FastMap::default();
    for (i, t) in list.iter().enumerate() {
        for atom in [t.u, t.w] {
            let j = *first_with.entry(atom).or_insert(i);
            let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
            // The earlier root stays the root.
            let (lo, hi) = if ri < rj { (ri, rj) } else { (rj, ri) };
            parent[hi] = lo;
        }
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut group_of_root: FastMap<usize, usize> = FastMap::default();
    for i in 0..list.len() {
        let r = find(&mut parent, i);
        match group_of_root.get(&r) {
            Some(&k) => groups[k].push(i),
            None => {
                group_of_root.insert(r, groups.len());
                groups.push(vec![i]);
            }
        }
    }
    groups
}

/// Writes `Σ c (u·w)` as `k (Σ aᵢ uᵢ)·(Σ bⱼ wⱼ)` when the bilinear form has rank one, with
/// `a`, `b` primitive integer vectors whose first entry (in reading order) is positive.
#[allow(clippy::type_complexity)]
fn factor_bilinear(
    g: &Graph,
    terms: &[&DotTerm],
    orientations: &Orientations,
) -> Option<(Rational, Vec<(Id, Rational)>, Vec<(Id, Rational)>)> {
    let mut atoms: Vec<Id> = terms.iter().flat_map(|t| [t.u, t.w]).collect();
    atoms.sort_by(|x, y| g.cmp_nodes(*x, *y));
    atoms.dedup();
    let coef = |x: Id, y: Id| -> Rational {
        terms
            .iter()
            .find(|t| (t.u == x && t.w == y) || (t.u == y && t.w == x))
            .map_or(Rational::ZERO, |t| t.coef.clone())
    };
    if let Some(found) = factor_symmetric_or_bipartite(g, terms, &atoms, &coef, orientations) {
        return Some(found);
    }
    // A vector common to every term: u·(Σ cⱼ wⱼ), as in r1·r1 − r1·r2 = r1·(r1 − r2).
    if let Some(common) = atoms.iter().copied().find(|&u| terms.iter().all(|t| t.u == u || t.w == u)) {
        let mut other: Vec<(Id, Rational)> =
            terms.iter().map(|t| (if t.u == common { t.w } else { t.u }, t.coef.clone())).collect();
        other.sort_by(|x, y| g.cmp_nodes(x.0, y.0));
        let (b, sb) = primitive(other, orientations);
        return Some((sb, vec![(common, Rational::ONE)], b));
    }
    // Two different sums, sharing atoms: (r1 − r2)·(r2 − r3).
    let half = Rational::new(1, 2);
    let m = |x: Id, y: Id| if x == y { coef(x, x) } else { coef(x, y).mul(&half) };
    let p = *atoms.iter().find(|&&x| !coef(x, x).is_zero())?;
    let (k, a, b) = rank_two(&atoms, p, &m)?;
    let (a, sa) = primitive(a, orientations);
    let (b, sb) = primitive(b, orientations);
    Some((k.mul(&sa).mul(&sb), a, b))
}

#[allow(clippy::type_complexity)]
fn factor_symmetric_or_bipartite(
    g: &Graph,
    terms: &[&DotTerm],
    atoms: &[Id],
    coef: &dyn Fn(Id, Id) -> Rational,
    orientations: &Orientations,
) -> Option<(Rational, Vec<(Id, Rational)>, Vec<(Id, Rational)>)> {
    let _ = g;
    let (k, a, b) = if terms.iter().any(|t| t.u == t.w) {
        // Symmetric: M = k a aᵀ with M_ii = c_ii and M_ij = c_ij / 2.
        let half = Rational::new(1, 2);
        let m = |x: Id, y: Id| if x == y { coef(x, x) } else { coef(x, y).mul(&half) };
        let p = *atoms.iter().find(|&&x| !coef(x, x).is_zero())?;
        let k = m(p, p);
        let a: Vec<(Id, Rational)> = atoms.iter().map(|&x| (x, m(p, x).div(&k).unwrap_or(Rational::ZERO))).collect();
        for (x, ax) in &a {
            for (y, ay) in &a {
                if m(*x, *y) != k.mul(ax).mul(ay) {
                    return None;
                }
            }
        }
        (k, a.clone(), a)
    } else {
        // Bipartite: the atoms split in two sides with every term across.
        let mut side: FastMap<Id, bool> = FastMap::default();
        side.insert(atoms[0], true);
        let mut changed = true;
        while changed {
            changed = false;
            for t in terms {
                match (side.get(&t.u).copied(), side.get(&t.w).copied()) {
                    (Some(x), None) => {
                        side.insert(t.w, !x);
                        changed = true;
                    }
                    (None, Some(y)) => {
                        side.insert(t.u, !y);
                        changed = true;
                    }
                    (Some(x), Some(y)) if x == y => return None,
                    _ => {}
                }
            }
        }
        let xs: Vec<Id> = atoms.iter().copied().filter(|a| side.get(a) == Some(&true)).collect();
        let ys: Vec<Id> = atoms.iter().copied().filter(|a| side.get(a) == Some(&false)).collect();
        let (x0, y0) = (xs[0], *ys.first()?);
        let k = coef(x0, y0);
        if k.is_zero() {
            return None;
        }
        let a: Vec<(Id, Rational)> = xs.iter().map(|&x| (x, coef(x, y0).div(&k).unwrap_or(Rational::ZERO))).collect();
        let b: Vec<(Id, Rational)> = ys.iter().map(|&y| (y, coef(x0, y).div(&k).unwrap_or(Rational::ZERO))).collect();
        for (x, ax) in &a {
            for (y, by) in &b {
                if coef(*x, *y) != k.mul(ax).mul(by) {
                    return None;
                }
            }
        }
        (k, a, b)
    };
    let (a, sa) = primitive(a, orientations);
    let (b, sb) = primitive(b, orientations);
    let k = k.mul(&sa).mul(&sb);
    Some((k, a, b))
}

/// `Q(x) = Σ Mᵢⱼ xᵢ xⱼ` as `(1/Mₚₚ) (a·x)(b·x)`, when it is such a product (rank two,
/// indefinite, over the rationals): `r1·r2 − r2·r2 − r1·r3 + r2·r3 = (r1 − r2)·(r2 − r3)`,
/// the A entry between two links of a chain.
///
/// Completing the square in `xₚ` (`Mₚₚ ≠ 0`) with `L = Σⱼ Mₚⱼ xⱼ` over the other atoms and
/// `R` their part of `Q`: `Mₚₚ Q = (Mₚₚ xₚ + L)² − D` with `D = L² − Mₚₚ R`. `Q` factors exactly
/// when `D = (d·x)²` for a rational `d`, and then `Mₚₚ Q = (Mₚₚ xₚ + L − d·x)(Mₚₚ xₚ + L + d·x)`.
#[allow(clippy::type_complexity)]
fn rank_two(
    atoms: &[Id],
    p: Id,
    m: &dyn Fn(Id, Id) -> Rational,
) -> Option<(Rational, Vec<(Id, Rational)>, Vec<(Id, Rational)>)> {
    let mpp = m(p, p);
    let rest: Vec<Id> = atoms.iter().copied().filter(|&x| x != p).collect();
    let l: Vec<Rational> = rest.iter().map(|&x| m(p, x)).collect();
    // D's matrix: Nᵢⱼ = Lᵢ Lⱼ − Mₚₚ Mᵢⱼ; it must be d dᵀ.
    let n = |i: usize, j: usize| l[i].mul(&l[j]).sub(&mpp.mul(&m(rest[i], rest[j])));
    let q = (0..rest.len()).find(|&i| !n(i, i).is_zero())?;
    let s = n(q, q).sqrt_exact()?;
    let d: Vec<Rational> = (0..rest.len()).map(|j| n(q, j).div(&s)).collect::<Option<_>>()?;
    let square = (0..rest.len()).all(|i| (0..rest.len()).all(|j| n(i, j) == d[i].mul(&d[j])));
    if !square {
        return None;
    }
    let side = |sign: i64| -> Vec<(Id, Rational)> {
        atoms
            .iter()
            .map(|&x| match rest.iter().position(|&y| y == x) {
                Some(j) => (x, l[j].add(&d[j].mul(&Rational::int(sign)))),
                None => (x, mpp.clone()),
            })
            .collect()
    };
    Some((mpp.recip()?, side(-1), side(1)))
}

/// `Σ qᵢ uᵢ` of a sum's terms when each is a vector atom `u`, `−u` or `q u` with `q` a number,
/// over two or more different atoms.
fn constant_combination(g: &Graph, terms: &[Id]) -> Option<Vec<(Id, Rational)>> {
    let atom = |x: Id| !matches!(g.node(x), Node::Add(_) | Node::Mul(_) | Node::Vector(_) | Node::Num(_));
    let mut out: Vec<(Id, Rational)> = Vec::new();
    for &t in terms {
        let (u, q) = match g.node(t) {
            Node::Mul(xs) if xs.len() == 2 && atom(xs[1]) => (xs[1], g.as_num(xs[0])?.clone()),
            _ if atom(t) => (t, Rational::ONE),
            _ => return None,
        };
        if q.is_zero() || out.iter().any(|(v, _)| *v == u) {
            return None;
        }
        out.push((u, q));
    }
    (out.len() >= 2).then_some(out)
}

/// The same combination of the atoms' time derivatives, when every atom is a symbol that
/// has one (positions → velocities → accelerations).
fn derivative_combination(g: &mut Graph, v: &[(Id, Rational)]) -> Option<Vec<(Id, Rational)>> {
    let mut out = Vec::new();
    for (u, q) in v {
        let Node::Sym(s) = *g.node(*u) else { return None };
        let d = g.symbol(s).derivative?;
        out.push((g.sym(d), q.clone()));
    }
    Some(out)
}

/// The same combination of the bodies' forces, when every atom is a body's position.
fn forces_combination(g: &Graph, v: &[(Id, Rational)], forces: &[Id]) -> Option<Vec<(Id, Rational)>> {
    let mut out = Vec::new();
    for (u, q) in v {
        let Node::Sym(s) = *g.node(*u) else { return None };
        let Role::Position { body } = g.symbol(s).role else { return None };
        out.push((*forces.get(body)?, q.clone()));
    }
    Some(out)
}

/// `v = s · v'` with `v'` integer and gcd 1, `s > 0`: the combination as written, scaled.
fn primitive_keeping_sign(v: Vec<(Id, Rational)>) -> (Vec<(Id, Rational)>, Rational) {
    let (p, s) = canonical_primitive(v);
    if s.is_negative() { (p.into_iter().map(|(x, q)| (x, q.neg())).collect(), s.neg()) } else { (p, s) }
}

/// `v = s · v'` with `v'` integer, gcd 1, first entry positive, zero entries dropped; or,
/// when `±v'` is a combination the user wrote (`orientations`), `v'` as the user wrote it.
fn primitive(v: Vec<(Id, Rational)>, orientations: &Orientations) -> (Vec<(Id, Rational)>, Rational) {
    let (p, s) = canonical_primitive(v);
    match orientations.get(&p) {
        Some(written) if written.len() == p.len() => {
            // The user's sign: the entry of p's first atom in what the user wrote.
            let same = written.iter().find(|(x, _)| *x == p[0].0).is_some_and(|(_, q)| !q.is_negative());
            (written.clone(), if same { s } else { s.neg() })
        }
        _ => (p, s),
    }
}

/// [`primitive`] without the user's orientations.
fn canonical_primitive(v: Vec<(Id, Rational)>) -> (Vec<(Id, Rational)>, Rational) {
    let v: Vec<(Id, Rational)> = v.into_iter().filter(|(_, q)| !q.is_zero()).collect();
    let mut s = v.first().map_or(Rational::ONE, |(_, q)| q.abs());
    for (_, q) in &v[1.min(v.len())..] {
        s = s.gcd(q);
    }
    if v.first().is_some_and(|(_, q)| q.is_negative()) {
        s = s.neg();
    }
    let inv = s.recip().unwrap_or(Rational::ONE);
    (v.into_iter().map(|(x, q)| (x, q.mul(&inv))).collect(), s)
}

/// `Σ aᵢ uᵢ` as a graph: `r1 − r2`.
fn vector_sum(g: &mut Graph, v: &[(Id, Rational)]) -> Result<Id, TypeError> {
    // Exact room, as the factors above.
    let mut parts = Vec::with_capacity(v.len());
    for (u, q) in v {
        parts.push(term1(g, q, *u)?);
    }
    g.add(parts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::graph::{Role, Ty};

    /// Every bilinear form `Σ c (u·w)` that is a dot product `(Σ aᵢ uᵢ)·(Σ bⱼ uⱼ)` of two
    /// integer combinations of three vectors (each coefficient in −2..=2) is found to be one,
    /// and the factors found multiply back to the same form: rank one (`a ∥ b`), across two
    /// sides, with a vector in common, and rank two (`(r1 − r2)·(r2 − r3)`).
    #[test]
    fn every_dot_product_of_two_sums_is_factored_back_exactly() {
        let mut g = Graph::new(2);
        let atoms: Vec<Id> = (0..3)
            .map(|body| {
                let s = g.declare(&format!("r{body}"), Ty::Vector, Role::Position { body });
                g.sym(s)
            })
            .collect();
        let combos: Vec<[i64; 3]> = (0..125).map(|n| [n % 5 - 2, (n / 5) % 5 - 2, n / 25 - 2]).collect();
        let form = |a: &[i64; 3], b: &[i64; 3]| -> Vec<DotTerm> {
            let mut terms = Vec::new();
            for i in 0..3 {
                for j in i..3 {
                    let c = if i == j { a[i] * b[i] } else { a[i] * b[j] + a[j] * b[i] };
                    if c != 0 {
                        terms.push(DotTerm { index: terms.len(), u: atoms[i], w: atoms[j], coef: Rational::int(c) });
                    }
                }
            }
            terms
        };
        let mut rank_two = 0;
        for a in &combos {
            for b in &combos {
                let terms = form(a, b);
                if terms.is_empty() {
                    continue;
                }
                let refs: Vec<&DotTerm> = terms.iter().collect();
                let Some((k, x, y)) = factor_bilinear(&g, &refs, &Orientations::default()) else {
                    panic!("{a:?}·{b:?} was not factored");
                };
                // k (Σ xᵢ uᵢ)·(Σ yⱼ uⱼ), expanded, is the form again.
                let coefficient =
                    |v: &[(Id, Rational)], u: Id| v.iter().find(|e| e.0 == u).map_or(Rational::ZERO, |e| e.1.clone());
                let (x, y): (Vec<Rational>, Vec<Rational>) =
                    atoms.iter().map(|&u| (coefficient(&x, u), coefficient(&y, u))).unzip();
                for i in 0..3 {
                    for j in i..3 {
                        let product = if i == j { x[i].mul(&y[i]) } else { x[i].mul(&y[j]).add(&x[j].mul(&y[i])) };
                        let expected = terms
                            .iter()
                            .find(|t| t.u == atoms[i] && t.w == atoms[j])
                            .map_or(Rational::ZERO, |t| t.coef.clone());
                        assert_eq!(k.mul(&product), expected, "{a:?}·{b:?}: entry ({i}, {j})");
                    }
                }
                if x != y
                    && x.iter().zip(&y).any(|(p, q)| !p.is_zero() && !q.is_zero())
                    && terms.iter().any(|t| t.u == t.w)
                {
                    rank_two += 1;
                }
            }
        }
        assert!(rank_two > 1000, "only {rank_two} forms of rank two with shared vectors");
    }
}
