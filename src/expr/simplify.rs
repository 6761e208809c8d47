//! The simplifier: every expression to a canonical form, and back to a readable graph.
//!
//! Design note. A scalar becomes a rational function ([`Frac`]) over *atoms*: scalar
//! symbols, components `r.x`, dot products of vector atoms in canonical order, `cross` in 2D,
//! triple products in 3D, and function applications with simplified arguments. A vector
//! becomes `Σ sⱼ uⱼ`: scalar coefficients times vector atoms (vector symbols, `cross` of
//! atoms in 3D) and unit vectors (from literals `[a, b]`). `dot` and `cross` expand
//! bilinearly over those sums, so `dot(v,r) + dot(r,v)` is `2 r·v`, and −b/A for the bead
//! cancels to the article's form. Equal rational functions of the atoms have equal forms.
//!
//! The alternatives were rewrite rules to a fixpoint (egg-style equality saturation, or
//! SymPy's heuristics): more general, but neither bounded nor canonical for free. A
//! normal form is both, and it is what a person does by hand for these formulas.
//!
//! The rules, grouped:
//!
//! | group         | rule                                                                 |
//! |---------------|----------------------------------------------------------------------|
//! | constants     | exact rational folding; `sqrt(4) = 2`, `sin(0) = 0`, `exp(0) = 1`    |
//! | sums          | flatten, collect like terms, common denominator                      |
//! | products      | expand over sums (bounded), add exponents, cancel common factors     |
//! | dot           | bilinear; `u·w = w·u`; `u·eₓ = u.x`; `(p×q)·w` is a triple product   |
//! | cross         | bilinear; `u×u = 0`; `w×u = −u×w`; `(p×q)×w = q(p·w) − p(q·w)`      |
//! | radicals      | `sqrt(x)² = x`; `norm(u)² = u·u`; `norm(c u) = |c| norm(u)`          |
//! | functions     | `ln(exp x) = x`, `exp(ln x) = x`; `sin²x + cos²x = 1` (when smaller)  |
//! | rot, perp     | linear; `perp(perp(u)) = −u`, `u·perp(u) = 0`, … (`rigid`)          |
//!
//! Work is bounded: every expansion is capped by [`super::poly::MAX_TERMS`]; past it the
//! piece is kept unexpanded as an atom, which is correct, only less simplified. Results are
//! memoised per node, so shared subexpressions are simplified once.
//!
//! Not here: the readable layout of the result (`present`), derivatives (`diff`, `grad`).

use super::func::Func;
use super::graph::{Axis, FastMap, Graph, Id, IdMap, Marks, Node, Ty, TypeError};
use super::num::Rational;
use super::poly::{Frac, Mono, Poly, push_factor};
use super::present::Orientations;
use super::shape::{Reuse, Shaper};
use super::work;
use smallvec::SmallVec;
use std::rc::Rc;

/// A sum of more than two polynomials with more than this many terms in all is merged in
/// one pass ([`Poly::sum`]: one sort of every term) instead of operand by operand. Both give
/// the same polynomial, so the value moves only time: below it a pairwise merge of a few
/// short operands is cheaper than collecting and sorting them; above it, pairwise merging
/// passes over the growing total once per operand (quadratic in a long chain's sums).
const MERGE_MIN_TERMS: usize = 64;
/// Up to this many sine–cosine pairs met, [`Simplifier::reduce_trig`] tests each pair on a
/// numerator instead of looking its atoms up in `trig_index` (a time-dependent scene has one).
const FEW_TRIG_PAIRS: usize = 4;

/// A vector atom of the canonical form: a graph node, or a unit vector.
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Debug)]
pub(super) enum VAtom {
    Atom(Id),
    Basis(Axis),
}

/// `Σ sⱼ uⱼ`, sorted by atom, no zero coefficients.
#[derive(Clone, PartialEq, Eq, Debug, Default)]
pub(super) struct VecForm(pub(super) Vec<(VAtom, Frac)>);

/// The canonical form of a node.
#[derive(Clone, PartialEq, Eq, Debug)]
pub(super) enum Canon {
    S(Frac),
    V(VecForm),
}

impl Canon {
    /// The terms of the form (its numerators' and denominators' factors'), the unit of
    /// [`MAX_FORM_WORK`].
    fn terms(&self) -> u64 {
        let frac = |f: &Frac| f.num.len() as u64 + f.den.iter().map(|(p, _)| p.len() as u64).sum::<u64>();
        match self {
            Canon::S(f) => frac(f),
            Canon::V(v) => v.0.iter().map(|(_, f)| frac(f)).sum(),
        }
    }
}

/// Simplifies nodes of one graph, remembering what it has done.
///
/// Keep one per graph: ids of different graphs mean different things.
/// The most term operations simplifying one formula may spend ([`work`]): the terms of its
/// canonical forms (numerators and denominators' factors, every node's form counted once),
/// and the terms the arithmetic visits computing them (a term of a sum, a pair of terms of
/// a product, one more per 64 bits of their coefficients). A deterministic budget on work,
/// not a timer: past it the formula is refused as too large ([`TypeError::TooLarge`]).
pub const MAX_FORM_WORK: u64 = 100_000_000;

#[derive(Debug, Default)]
pub struct Simplifier {
    pub(super) memo: IdMap<Rc<Canon>>,
    pub(super) built: IdMap<Id>,
    /// For `sqrt(x)` and `norm(u)` atoms: what their square is (`x`, `u·u`).
    pub(super) radicals: FastMap<Id, Rc<Frac>>,
    /// For each `sin(x)` atom, the `cos(x)` atom of the same argument (`sin² + cos² = 1`),
    /// in the order the pairs were met.
    trig: Vec<(Id, Id)>,
    /// Each paired atom (sine or cosine) → its pair's index in `trig`, so a numerator looks
    /// up only the pairs of its own atoms (a scene of N rotating bodies has N pairs).
    trig_index: FastMap<Id, usize>,
    /// The `sin` (`true`) and `cos` atoms met, by argument.
    trig_seen: FastMap<(bool, Id), Id>,
    /// What [`Simplifier::simplify_alike`] did, by shape: the result, to be renamed.
    alike: FastMap<Vec<u32>, Reuse>,
    shaper: Shaper,
    /// `canon`'s marks of the nodes queued in its current walk.
    queued: Marks,
    /// Differences as the user wrote them (`r2 − r1`), by their canonical orientation
    /// (`r1 − r2`): what the layout writes instead ([`Simplifier::keep_orientations`]).
    pub(super) orientations: Orientations,
}

impl Simplifier {
    pub fn new() -> Simplifier {
        Simplifier::default()
    }

    /// The simplified form of `id`: equal in value, collected, cancelled, readable.
    pub fn simplify(&mut self, g: &mut Graph, id: Id) -> Result<Id, TypeError> {
        if let Some(&s) = self.built.get(&id) {
            return Ok(s);
        }
        // One budget for the form and its layout (the layout's comparisons are work too).
        let (s, over) = work::metered(MAX_FORM_WORK, || {
            let c = self.canon(g, id)?;
            self.laid_out(g, c)
        });
        let s = s?;
        if over {
            return Err(TypeError::TooLarge(MAX_FORM_WORK));
        }
        self.built.insert(id, s);
        Ok(s)
    }

    /// [`Simplifier::simplify`], reusing the work done on an expression of the same shape
    /// (equal up to renaming bodies' symbols, [`Shape`](super::shape::Shape)): the earlier result, renamed.
    ///
    /// For the many entries of a scene that repeat one pattern (A and b of a chain); the
    /// cost of a repeat is a walk over the expression and the result.
    pub fn simplify_alike(&mut self, g: &mut Graph, id: Id) -> Result<Id, TypeError> {
        if let Some(&s) = self.built.get(&id) {
            return Ok(s);
        }
        let shape = self.shaper.shape(g, &[id]);
        if let Some(renamed) = self.alike.get_mut(&shape.key).and_then(|r| r.renamed(g, &shape.symbols)) {
            let result = renamed[0];
            self.built.insert(id, result);
            self.adopt(result);
            return Ok(result);
        }
        let result = self.simplify(g, id)?;
        self.alike.insert(shape.key, Reuse::new(vec![result], shape.symbols, false));
        Ok(result)
    }

    /// Records that `id` is in simplified form (it is a renaming of a simplified node), so
    /// simplifying it again returns it as it is.
    pub fn adopt(&mut self, id: Id) {
        self.built.insert_if_absent(id, id);
    }

    /// Whether `a` and `b` are equal as rational functions of their atoms.
    ///
    /// Denominators are kept as lists of factors, not fully factored, so one function can
    /// have two forms (`1/((k²+1)(k⁶+1))` and `1/(k⁸+k⁶+k²+1)`): when the forms differ, the
    /// difference `a − b` is brought to a common denominator and tested for zero.
    pub fn equivalent(&mut self, g: &mut Graph, a: Id, b: Id) -> Result<bool, TypeError> {
        if self.canon(g, a)? == self.canon(g, b)? {
            return Ok(true);
        }
        if g.ty(a) != g.ty(b) {
            return Ok(false);
        }
        let difference = g.sub(a, b)?;
        self.is_zero(g, difference)
    }

    /// Whether `id` simplifies to zero.
    pub fn is_zero(&mut self, g: &mut Graph, id: Id) -> Result<bool, TypeError> {
        Ok(match &*self.canon(g, id)? {
            Canon::S(f) => f.is_zero(),
            Canon::V(v) => v.0.is_empty(),
        })
    }

    /// The positive rational content of an expression: the largest `k` with `e = k · e'` and
    /// `e'` having integer coefficients of gcd 1 (1 for zero).
    pub fn content(&mut self, g: &mut Graph, id: Id) -> Result<Rational, TypeError> {
        Ok(match &*self.canon(g, id)? {
            Canon::S(f) => f.num.content(),
            Canon::V(v) => {
                let mut it = v.0.iter();
                match it.next() {
                    None => Rational::ONE,
                    Some((_, s)) => it.fold(s.num.content(), |k, (_, s)| k.gcd(&s.num.content())),
                }
            }
        })
    }

    /// The simplified `−n / d`, computed from the forms of `n` and `d` (simplified already,
    /// as b and A are when λ = −b/A), without building the quotient as a graph first.
    pub fn negated_quotient(&mut self, g: &mut Graph, n: Id, d: Id) -> Result<Id, TypeError> {
        let cn = self.canon(g, n)?;
        // 1/d with d's factors kept apart, as `power` does for a written `d^-1`.
        let inverse =
            if g.ty(n) == Ty::Scalar && g.ty(d) == Ty::Scalar { self.factored_power(g, d, -1)? } else { None };
        let form = match (&*cn, inverse) {
            (Canon::S(f), Some(r)) => f.mul(&r).map(|q| self.reduce_radicals(q).scale(&Rational::int(-1))),
            _ => None,
        };
        let Some(form) = form else {
            // Too large to expand (or not scalars): the quotient as a graph, simplified.
            let minus_n = g.neg(n);
            let q = g.div(minus_n, d)?;
            return self.simplify(g, q);
        };
        self.laid_out(g, Rc::new(Canon::S(form)))
    }

    /// `−n / d` kept as one quotient of two readable sums, where `d` is a sum of fractions
    /// over different roots (a term with a root's negative power, as A has where two unit
    /// vectors d/|d| meet at one body: `(d₁·d₂)/(|d₁| |d₂|)`). The combined form of
    /// [`Simplifier::negated_quotient`] clears those roots into one denominator, so its
    /// numerator carries the product of the other roots in every term and grows faster than
    /// the scene; this one is `−(n's numerator × d's denominator over n's)/(d's numerator)`,
    /// linear in the terms of `n` and `d`. Equal to the combined form as a function; `None`
    /// where `d` has no such term (nothing to gain) or a form is too large. With it, the
    /// number of different roots in `d`'s denominators. The caller keeps the shorter form
    /// (over two or more roots this one, without building the combined form).
    pub fn separated_quotient(&mut self, g: &mut Graph, n: Id, d: Id) -> Result<Option<(Id, usize)>, TypeError> {
        if self.radicals.is_empty() || g.ty(n) != Ty::Scalar || g.ty(d) != Ty::Scalar {
            return Ok(None);
        }
        let (cn, cd) = (self.canon(g, n)?, self.canon(g, d)?);
        let (Canon::S(fnum), Canon::S(fden)) = (&*cn, &*cd) else { return Ok(None) };
        let mut roots: Vec<Id> =
            (fden.num.0.iter()).flat_map(|(m, _)| m.split_negative().0.0).map(|(atom, _)| atom).collect();
        if roots.is_empty() {
            return Ok(None);
        }
        roots.sort_unstable();
        roots.dedup();
        let top = crate::expr::poly::expand(&fden.den)
            .and_then(|den| fnum.mul(&Frac::poly(den)))
            .map(|top| top.scale(&Rational::int(-1)));
        let Some(top) = top else { return Ok(None) };
        let bottom = Frac::poly(fden.num.clone());
        let top = self.laid_out(g, Rc::new(Canon::S(top)))?;
        let bottom = self.laid_out(g, Rc::new(Canon::S(bottom)))?;
        let quotient = g.div(top, bottom)?;
        self.adopt(quotient);
        Ok(Some((quotient, roots.len())))
    }

    /// The readable graph of the form `c`, remembered as simplified. What `build` lays out
    /// has the canonical form it came from (the round trip is tested), so `is_zero`,
    /// `content` and `scaled` on the result need not redo it.
    fn laid_out(&mut self, g: &mut Graph, c: Rc<Canon>) -> Result<Id, TypeError> {
        let s = self.build(g, &c)?;
        self.built.insert(s, s);
        self.memo.insert_if_absent(s, c);
        Ok(s)
    }

    /// The simplified `k · e`.
    pub fn scaled(&mut self, g: &mut Graph, id: Id, k: &Rational) -> Result<Id, TypeError> {
        let c = self.scaled_form(g, id, k)?;
        self.build(g, &c)
    }

    /// The canonical form of `k · id`.
    fn scaled_form(&mut self, g: &mut Graph, id: Id, k: &Rational) -> Result<Canon, TypeError> {
        Ok(match &*self.canon(g, id)? {
            Canon::S(f) => Canon::S(f.scale(k)),
            Canon::V(v) => Canon::V(VecForm(v.0.iter().map(|(a, s)| (*a, s.scale(k))).collect())),
        })
    }

    /// `k · id` for evaluating in f64: as [`scaled`](Self::scaled), but each term keeps its
    /// own coefficient (no content in front), so a value within f64's range is computed
    /// even where its content and its terms are not.
    pub fn scaled_for_numbers(&mut self, g: &mut Graph, id: Id, k: &Rational) -> Result<Id, TypeError> {
        let c = self.scaled_form(g, id, k)?;
        self.build_distributed(g, &c)
    }

    /// The canonical form of `id`, computing every reachable node's form once, children first.
    pub(super) fn canon(&mut self, g: &mut Graph, id: Id) -> Result<Rc<Canon>, TypeError> {
        if let Some(c) = self.memo.get(&id) {
            return Ok(c.clone());
        }
        // The nodes below `id` without a form yet; the walk stops at memoised nodes, so
        // a new expression over old ones costs the size of what is new.
        // Room for a small walk up front (with the stack's, the room below and the merges'
        // in `poly`: 3 % of the bead's derivation, callgrind).
        let mut todo = Vec::with_capacity(16);
        // Nodes already queued in this walk: a mark per node, reused from walk to walk.
        self.queued.clear();
        let mut stack = Vec::with_capacity(16);
        stack.push(id);
        while let Some(n) = stack.pop() {
            if self.memo.contains_key(&n) || !self.queued.insert(n.index()) {
                continue;
            }
            todo.push(n);
            stack.extend_from_slice(g.node(n).children());
        }
        todo.sort_unstable();
        // The work budget of this formula ([`work`]): the terms of every form computed for
        // it, and what the arithmetic spent computing them. A nested `canon` (a power's
        // exponent) spends from its formula's budget.
        let (done, over) = work::metered(MAX_FORM_WORK, || {
            for n in todo {
                let node = g.node(n).clone();
                let c = self.canon_node(g, n, &node)?;
                if !work::charge(c.terms()) || work::exhausted() {
                    return Err(TypeError::TooLarge(MAX_FORM_WORK));
                }
                self.memo.insert(n, Rc::new(c));
            }
            Ok(())
        });
        done?;
        if over {
            return Err(TypeError::TooLarge(MAX_FORM_WORK));
        }
        Ok(self.memo[&id].clone())
    }

    pub(super) fn scalar_of(&self, id: Id) -> Frac {
        match &*self.memo[&id] {
            Canon::S(f) => f.clone(),
            Canon::V(_) => Frac::zero(),
        }
    }

    pub(super) fn vector_of(&self, id: Id) -> VecForm {
        match &*self.memo[&id] {
            Canon::V(v) => v.clone(),
            Canon::S(_) => VecForm::default(),
        }
    }

    /// Keeps `node` unexpanded, its children simplified, as an atom.
    fn frozen(&mut self, g: &mut Graph, id: Id, node: &Node) -> Result<Canon, TypeError> {
        let mut kids = Vec::new();
        for &c in node.children() {
            let form = self.memo[&c].clone();
            kids.push(self.build(g, &form)?);
        }
        let atom = g.rebuild(node, &kids)?;
        Ok(match g.ty(id) {
            Ty::Scalar => Canon::S(Frac::atom(atom)),
            Ty::Vector => Canon::V(VecForm(vec![(VAtom::Atom(atom), Frac::constant(Rational::ONE))])),
        })
    }

    fn canon_node(&mut self, g: &mut Graph, id: Id, node: &Node) -> Result<Canon, TypeError> {
        let result = match node {
            Node::Num(q) => Some(Canon::S(Frac::constant(q.clone()))),
            Node::Sym(_) => Some(match g.ty(id) {
                Ty::Scalar => Canon::S(Frac::atom(id)),
                Ty::Vector => Canon::V(VecForm(vec![(VAtom::Atom(id), Frac::constant(Rational::ONE))])),
            }),
            Node::Vector(xs) => {
                let mut terms = Vec::new();
                for (k, x) in xs.iter().enumerate() {
                    let s = self.scalar_of(*x);
                    if !s.is_zero() {
                        terms.push((VAtom::Basis(Axis::ALL[k]), s));
                    }
                }
                Some(Canon::V(VecForm(terms)))
            }
            Node::Add(xs) => match g.ty(id) {
                Ty::Scalar => {
                    let scalar = |x: &Id| match &*self.memo[x] {
                        Canon::S(f) => Some(f),
                        Canon::V(_) => None,
                    };
                    let (mut count, mut terms, mut polynomials) = (0usize, 0usize, true);
                    for f in xs.iter().filter_map(scalar) {
                        count += 1;
                        terms += f.num.len();
                        polynomials &= f.den.is_empty();
                    }
                    if count > 2 && terms > MERGE_MIN_TERMS && polynomials {
                        // Large sums of polynomials: one merge of all the terms (pairwise sums
                        // would pass over the growing total once per operand); small ones
                        // are cheaper pairwise.
                        let num = Poly::sum(xs.iter().filter_map(scalar).map(|f| &f.num));
                        Some(Canon::S(Frac { num, den: Vec::new() }.normalize()))
                    } else {
                        let mut acc = Some(Frac::zero());
                        for f in xs.iter().filter_map(scalar) {
                            acc = acc.and_then(|a| a.add(f));
                        }
                        acc.map(Canon::S)
                    }
                }
                Ty::Vector => {
                    let mut acc = Some(VecForm::default());
                    for x in xs.iter() {
                        let form = self.memo[x].clone();
                        if let Canon::V(v) = &*form {
                            acc = acc.and_then(|a| a.add(v));
                        }
                    }
                    acc.map(Canon::V)
                }
            },
            Node::Mul(xs) => {
                let mut k = Some(Frac::constant(Rational::ONE));
                let mut vector = None;
                for x in xs.iter() {
                    match &*self.memo[x] {
                        Canon::S(f) => k = k.and_then(|k| k.mul(f)).map(|k| self.reduce_radicals(k)),
                        Canon::V(v) => vector = Some(v.clone()),
                    }
                }
                match (k, vector) {
                    (Some(k), Some(v)) => v.scale(&k).map(Canon::V),
                    (Some(k), None) => Some(Canon::S(k)),
                    (None, _) => None,
                }
            }
            Node::Pow([b, e]) => self.power(g, *b, *e)?,
            Node::Dot([a, b]) => {
                let (a, b) = (self.memo[a].clone(), self.memo[b].clone());
                match (&*a, &*b) {
                    (Canon::V(a), Canon::V(b)) => self.dot(g, a, b)?.map(Canon::S),
                    _ => Some(Canon::S(Frac::zero())),
                }
            }
            Node::Cross([a, b]) => {
                let (a, b) = (self.vector_of(*a), self.vector_of(*b));
                if g.dim() == 3 { self.cross3(g, &a, &b)?.map(Canon::V) } else { self.cross2(g, &a, &b)?.map(Canon::S) }
            }
            Node::Norm(a) => {
                let a = self.vector_of(*a);
                self.norm(g, &a)?.map(Canon::S)
            }
            Node::Comp(a, axis) => {
                let a = self.vector_of(*a);
                let e = VecForm(vec![(VAtom::Basis(*axis), Frac::constant(Rational::ONE))]);
                self.dot(g, &a, &e)?.map(Canon::S)
            }
            Node::Call(f, _) => self.call(g, *f, node.children())?.map(Canon::S),
            Node::Rot([theta, v]) => self.rot_form(g, *theta, *v)?.map(Canon::V),
            Node::Perp(v) => Some(Canon::V(self.perp_form(g, *v)?)),
        };
        // Sums and products of sums (common denominators, bilinear dot) can create
        // `sqrt(x)²` anew; reduce them in every form, not only after products and powers.
        match result {
            Some(Canon::S(f)) => Ok(Canon::S(self.reduce_trig(self.reduce_radicals(f)))),
            Some(Canon::V(v)) => {
                let terms =
                    v.0.into_iter()
                        .map(|(u, s)| (u, self.reduce_trig(self.reduce_radicals(s))))
                        .filter(|(_, s)| !s.is_zero());
                Ok(Canon::V(VecForm(terms.collect())))
            }
            None => self.frozen(g, id, node),
        }
    }

    fn power(&mut self, g: &mut Graph, b: Id, e: Id) -> Result<Option<Canon>, TypeError> {
        let base = self.scalar_of(b);
        let exponent = self.scalar_of(e);
        let Some(q) = exponent.as_constant() else {
            return self.opaque_power(g, b, e);
        };
        if let Some(n) = q.to_i64() {
            if n == 0 {
                return Ok(Some(Canon::S(Frac::constant(Rational::ONE))));
            }
            if let Some(c) = base.as_constant() {
                return Ok(c.pow(n).map(|c| Canon::S(Frac::constant(c))));
            }
            // A denominator written as a product or a power stays a list of factors
            // instead of being expanded into one polynomial, so simplifying the printed
            // `1/((k^6 + 1)*(k^2 + 1))` again gives the same form (idempotence).
            if n < 0
                && let Some(f) = self.factored_power(g, b, n)?
            {
                return Ok(Some(Canon::S(self.reduce_radicals(f))));
            }
            return Ok(base.powi(n).map(|f| Canon::S(self.reduce_radicals(f))));
        }
        // b^(p/2) = sqrt(b)^p
        if let Some((p, 2)) = q.as_small() {
            let root = self.sqrt(g, &base)?;
            return Ok(root.and_then(|r| r.powi(p)).map(|f| Canon::S(self.reduce_radicals(f))));
        }
        self.opaque_power(g, b, e)
    }

    /// `b^n` for `n < 0` with the factors of `b` kept apart: `(x y)^n = xⁿ yⁿ` and
    /// `(x^m)^n = x^(mn)` for integer `m`. `None` when a factor is zero or too large.
    fn factored_power(&mut self, g: &mut Graph, b: Id, n: i64) -> Result<Option<Frac>, TypeError> {
        // The walk goes below `b`'s direct children, whose forms `canon` may not have
        // needed yet (it stops at memoised nodes): they are computed here on demand.
        match g.node(b).clone() {
            Node::Mul(xs) => {
                let mut acc = Frac::constant(Rational::ONE);
                for x in xs.iter() {
                    let Some(f) = self.factored_power(g, *x, n)? else { return Ok(None) };
                    let Some(product) = acc.mul(&f) else { return Ok(None) };
                    acc = product;
                }
                Ok(Some(acc))
            }
            Node::Pow([x, e]) => {
                let exponent = self.canon(g, e)?;
                match scalar(&exponent).as_constant().and_then(|q| q.to_i64()) {
                    Some(m) if m > 0 => match n.checked_mul(m) {
                        Some(nm) => self.factored_power(g, x, nm),
                        None => Ok(None),
                    },
                    _ => Ok(scalar(&*self.canon(g, b)?).powi(n)),
                }
            }
            _ => Ok(scalar(&*self.canon(g, b)?).powi(n)),
        }
    }

    fn opaque_power(&mut self, g: &mut Graph, b: Id, e: Id) -> Result<Option<Canon>, TypeError> {
        let (cb, ce) = (self.memo[&b].clone(), self.memo[&e].clone());
        let (sb, se) = (self.build(g, &cb)?, self.build(g, &ce)?);
        let atom = g.pow(sb, se)?;
        Ok(Some(Canon::S(Frac::atom(atom))))
    }

    /// `sqrt(f)`: exact for rational squares, with square rational content taken out.
    fn sqrt(&mut self, g: &mut Graph, f: &Frac) -> Result<Option<Frac>, TypeError> {
        if let Some(c) = f.as_constant()
            && let Some(r) = c.sqrt_exact()
        {
            return Ok(Some(Frac::constant(r)));
        }
        let content = f.num.content();
        let (outside, inside) = match content.sqrt_exact() {
            Some(r) if !f.num.leading().is_some_and(|(_, q)| q.is_negative()) => {
                (r, f.scale(&content.recip().unwrap_or(Rational::ONE)))
            }
            _ => (Rational::ONE, f.clone()),
        };
        let arg = self.build(g, &Canon::S(inside.clone()))?;
        let atom = g.call(Func::Sqrt, &[arg])?;
        self.radicals.insert(atom, Rc::new(inside));
        Ok(Some(Frac::atom(atom).scale(&outside)))
    }

    /// `f(args)`: `sqrt` through [`Self::sqrt`]; otherwise the table's exact value at
    /// rational arguments, `f(f⁻¹(x)) = x`, or the call over simplified arguments as an atom.
    fn call(&mut self, g: &mut Graph, f: Func, args: &[Id]) -> Result<Option<Frac>, TypeError> {
        if f == Func::Sqrt {
            let arg = self.scalar_of(args[0]);
            return self.sqrt(g, &arg);
        }
        let constants: Option<Vec<Rational>> = args.iter().map(|&a| self.scalar_of(a).as_constant()).collect();
        if let Some(v) = constants.and_then(|qs| f.exact(&qs)) {
            return Ok(Some(Frac::constant(v)));
        }
        if let (Some(h), [a]) = (f.inverse(), args) {
            let arg = self.scalar_of(*a);
            if let Some(inner) = arg.num.as_atom().filter(|_| arg.den.is_empty())
                && let Node::Call(k, [x, _]) = g.node(inner).clone()
                && k == h
            {
                let c = self.canon(g, x)?;
                if let Canon::S(s) = &*c {
                    return Ok(Some(s.clone()));
                }
            }
        }
        let mut built = Vec::new();
        for a in args {
            let form = self.memo[a].clone();
            built.push(self.build(g, &form)?);
        }
        let atom = g.call(f, &built)?;
        if let (Some(sine), [arg]) = (
            match f {
                Func::Sin => Some(true),
                Func::Cos => Some(false),
                _ => None,
            },
            built.as_slice(),
        ) {
            // Paired when both have been met (no node is made for the other one: a
            // node the formula does not use would move every later id).
            self.trig_seen.insert((sine, *arg), atom);
            if let Some(&other) = self.trig_seen.get(&(!sine, *arg)) {
                let pair = if sine { (atom, other) } else { (other, atom) };
                if !self.trig_index.contains_key(&atom) {
                    self.trig_index.insert(pair.0, self.trig.len());
                    self.trig_index.insert(pair.1, self.trig.len());
                    self.trig.push(pair);
                }
            }
        }
        Ok(Some(Frac::atom(atom)))
    }

    /// `sin²x + cos²x = 1` for every argument met: a numerator with `sin(x)²` or `cos(x)²`
    /// takes `sin² = 1 − cos²` (or `cos² = 1 − sin²`) throughout when that leaves fewer
    /// terms, until neither does. Each step removes terms, so it ends; a form it leaves
    /// alone is left alone again (idempotence).
    fn reduce_trig(&self, f: Frac) -> Frac {
        if self.trig.is_empty() || f.num.len() < 2 {
            return f;
        }
        let mut num = f.num;
        let mut changed = false;
        loop {
            // Each pass rewrites the whole numerator: once the formula's budget is spent, stop
            // (the caller refuses the formula) rather than keep rewriting unmetered.
            if work::exhausted() {
                return Frac { num, den: f.den };
            }
            let mut best: Option<Poly> = None;
            // The pairs whose atoms the numerator has, in the order they were met: with a
            // few pairs (one time-dependent argument) all of them, tested below, without
            // looking every atom up.
            let pairs: SmallVec<[usize; FEW_TRIG_PAIRS]> = if self.trig.len() <= FEW_TRIG_PAIRS {
                (0..self.trig.len()).collect()
            } else {
                let mut pairs: SmallVec<[usize; FEW_TRIG_PAIRS]> = num
                    .0
                    .iter()
                    .flat_map(|(m, _)| m.0.iter().filter_map(|(a, _)| self.trig_index.get(a).copied()))
                    .collect();
                pairs.sort_unstable();
                pairs.dedup();
                pairs
            };
            for &(sin, cos) in pairs.iter().map(|&k| &self.trig[k]) {
                // The highest powers of sin and cos in the numerator, in one pass.
                let (mut s, mut c) = (0, 0);
                for &(a, e) in num.0.iter().flat_map(|(m, _)| m.0.iter()) {
                    if a == sin {
                        s = s.max(e);
                    } else if a == cos {
                        c = c.max(e);
                    }
                }
                if !(s >= 2 && c >= 1 || c >= 2 && s >= 1) {
                    continue;
                }
                for (x, y) in [(sin, cos), (cos, sin)] {
                    if let Some(p) = substitute_square(&num, x, y)
                        && p.len() < best.as_ref().map_or(num.len(), Poly::len)
                    {
                        best = Some(p);
                    }
                }
            }
            match best {
                Some(p) => {
                    num = p;
                    changed = true;
                }
                None => {
                    let out = Frac { num, den: f.den };
                    // Unchanged, `f` is a form the simplifier made, normalised already; with
                    // at most one factor that is not an atom normalising again gives it back
                    // (with two, a division by one can lengthen the numerator past the
                    // other's length test), so that pass is skipped.
                    let factors = out.den.iter().filter(|(p, _)| p.as_atom().is_none()).count();
                    return if changed || factors > 1 { out.normalize() } else { out };
                }
            }
        }
    }

    /// Radicals to their normal form: a root or norm in a denominator moves up as a negative
    /// power (`x/|d|³` is `x |d|⁻³`, so fractions over different roots add without a common
    /// denominator), `sqrt(x)^k` becomes `x^(k div 2) sqrt(x)^(k mod 2)` for `k ≥ 2` (and
    /// `norm(u)^k` likewise), and a negative power cancels against its square where the
    /// square divides exactly (`(u·u) |u|⁻² = 1`).
    pub(super) fn reduce_radicals(&self, f: Frac) -> Frac {
        if self.radicals.is_empty() {
            return f;
        }
        let radical = |a: &Id| self.radicals.contains_key(a);
        let num_heavy = f.num.0.iter().any(|(m, _)| m.0.iter().any(|(a, e)| (*e >= 2 || *e < 0) && radical(a)));
        let den_radical = f.den.iter().any(|(p, _)| p.as_atom().is_some_and(|a| radical(&a)));
        if !num_heavy && !den_radical {
            return f;
        }
        self.reduced(&f).unwrap_or(f)
    }

    /// [`Simplifier::reduce_radicals`]; `None` when a step is too large to expand.
    fn reduced(&self, f: &Frac) -> Option<Frac> {
        // Radical atoms of the denominator move up; the other factors stay factored.
        let mut up = Mono::one();
        let mut kept = Vec::new();
        for (p, e) in &f.den {
            match p.as_atom().filter(|a| self.radicals.contains_key(a)) {
                Some(a) => up = up.mul(&Mono(smallvec::smallvec![(a, -i32::try_from(*e).ok()?)])),
                None => push_factor(&mut kept, p.clone(), *e),
            }
        }
        let moved;
        let num = if up.is_one() {
            &f.num
        } else {
            moved = f.num.mul_mono(&up);
            &moved
        };
        // Terms whose replacement is a polynomial (the square has no denominator, the
        // common case) are summed in one sort; adding them one by one as fractions
        // tried an exact division per term and took 40 s on `sqrt(1 + (r1·r2/(1+t²))²)`.
        let mut poly_terms: Vec<(Mono, Rational)> = Vec::new();
        let mut fractions = Frac::zero();
        for (m, q) in &num.0 {
            if !m.0.iter().any(|(a, e)| *e >= 2 && self.radicals.contains_key(a)) {
                poly_terms.push((m.clone(), q.clone()));
                continue;
            }
            let mut term = Frac::constant(q.clone());
            let mut rest = Mono::one();
            for &(a, e) in &m.0 {
                match self.radicals.get(&a) {
                    Some(square) if e >= 2 => {
                        term = term.mul(&square.powi(i64::from(e / 2))?)?;
                        if e % 2 == 1 {
                            rest = rest.mul(&Mono::atom(a));
                        }
                    }
                    _ => rest = rest.mul(&Mono(smallvec::smallvec![(a, e)])),
                }
            }
            term = term.mul(&Frac::poly(Poly(vec![(rest, Rational::ONE)])))?;
            if term.den.is_empty() {
                poly_terms.extend(term.num.0);
            } else {
                fractions = fractions.add(&term)?;
            }
        }
        let mut num = Frac::poly(self.cancel_negative_powers(sum_terms(poly_terms)));
        if !fractions.is_zero() {
            num = num.add(&fractions)?;
        }
        if kept.is_empty() {
            return Some(num);
        }
        num.mul(&Frac { num: Poly::constant(Rational::ONE), den: kept })
    }

    /// `Σ cᵢ |u|⁻ᵏ` with `u·u` dividing `Σ cᵢ` exactly becomes `Σ (cᵢ/(u·u)) |u|²⁻ᵏ`, for
    /// every radical and power `k ≥ 1`, as long as one applies (`(u·u)/|u| = |u|`). Each step
    /// raises a negative exponent by two, so it ends.
    fn cancel_negative_powers(&self, mut p: Poly) -> Poly {
        let mut tried: Vec<(Id, i32)> = Vec::new();
        loop {
            let next = p.0.iter().find_map(|(m, _)| {
                m.0.iter().copied().find(|&(a, e)| {
                    e < 0
                        && !tried.contains(&(a, e))
                        && self.radicals.get(&a).is_some_and(|s| s.den.is_empty() && !s.num.is_zero())
                })
            });
            let Some((a, e)) = next else { return p };
            tried.push((a, e));
            let square = &self.radicals[&a].num;
            if !may_divide(square, &p, a, e) {
                continue;
            }
            let (group, rest): (Vec<_>, Vec<_>) = p.0.iter().cloned().partition(|(m, _)| m.exponent(a) == e);
            let cofactor = sum_terms(group.into_iter().map(|(m, q)| (m.with_exponent(a, 0), q)).collect());
            if let Some(quotient) = cofactor.div_exact(square) {
                let raised = if e == -2 { quotient } else { quotient.mul_mono(&Mono(smallvec::smallvec![(a, e + 2)])) };
                let mut terms = rest;
                terms.extend(raised.0);
                p = sum_terms(terms);
            }
        }
    }

    // ---- vector algebra ----------------------------------------------------------------

    /// `a·b`, bilinear over the two sums.
    fn dot(&mut self, g: &mut Graph, a: &VecForm, b: &VecForm) -> Result<Option<Frac>, TypeError> {
        // Polynomial coefficients and atoms (the common case): collect every product's
        // terms and sum them once, instead of merging a new sum per pair. Sums of
        // polynomials do not depend on their order, so the result is the same.
        let polynomial = |v: &VecForm| v.0.iter().all(|(_, s)| s.den.is_empty());
        if polynomial(a) && polynomial(b) {
            let mut terms: Vec<(Mono, Rational)> = Vec::new();
            let mut general = false;
            'pairs: for (u, s) in &a.0 {
                for (w, t) in &b.0 {
                    let Some(atom) = self.dot_atoms(g, *u, *w)? else { return Ok(None) };
                    if !atom.den.is_empty() {
                        general = true;
                        break 'pairs;
                    }
                    if let (Some(p), Some(q)) = (s.num.as_constant(), t.num.as_constant()) {
                        // Constant coefficients: the atom's terms times one number.
                        let pq = p.mul(&q);
                        if !pq.is_zero() {
                            terms.extend(atom.num.0.into_iter().map(|(m, c)| (m, c.mul(&pq))));
                        }
                        continue;
                    }
                    let Some(st) = s.num.mul(&t.num) else { return Ok(None) };
                    let Some(product) = st.mul(&atom.num) else { return Ok(None) };
                    terms.extend(product.0);
                }
            }
            if !general {
                return Ok(Some(self.reduce_radicals(Frac::poly(sum_terms(terms)))));
            }
        }
        let mut acc = Frac::zero();
        for (u, s) in &a.0 {
            for (w, t) in &b.0 {
                let Some(atom) = self.dot_atoms(g, *u, *w)? else { return Ok(None) };
                let Some(term) = s.mul(t).and_then(|st| st.mul(&atom)) else { return Ok(None) };
                let Some(sum) = acc.add(&term) else { return Ok(None) };
                acc = sum;
            }
        }
        Ok(Some(self.reduce_radicals(acc)))
    }

    /// `u·w` of two vector atoms; `None` when it is too large to expand ([`super::poly::MAX_TERMS`]).
    pub(super) fn dot_atoms(&mut self, g: &mut Graph, u: VAtom, w: VAtom) -> Result<Option<Frac>, TypeError> {
        Ok(match (u, w) {
            (VAtom::Basis(x), VAtom::Basis(y)) => {
                Some(Frac::constant(if x == y { Rational::ONE } else { Rational::ZERO }))
            }
            (VAtom::Atom(a), VAtom::Basis(x)) | (VAtom::Basis(x), VAtom::Atom(a)) => self.component(g, a, x)?,
            (VAtom::Atom(a), VAtom::Atom(b)) => {
                if let Some(rigid) = self.rigid_dot(g, a, b)? {
                    return Ok(rigid);
                }
                match (g.node(a).clone(), g.node(b).clone()) {
                    // (p×q)·(s×t) = (p·s)(q·t) − (p·t)(q·s)
                    (Node::Cross([p, q]), Node::Cross([s, t])) => {
                        let ps = self.dot_atoms(g, VAtom::Atom(p), VAtom::Atom(s))?;
                        let qt = self.dot_atoms(g, VAtom::Atom(q), VAtom::Atom(t))?;
                        let pt = self.dot_atoms(g, VAtom::Atom(p), VAtom::Atom(t))?;
                        let qs = self.dot_atoms(g, VAtom::Atom(q), VAtom::Atom(s))?;
                        difference_of_products([ps, qt, pt, qs])
                    }
                    (Node::Cross([p, q]), _) => Some(self.triple(g, b, p, q)?),
                    (_, Node::Cross([p, q])) => Some(self.triple(g, a, p, q)?),
                    _ => {
                        let (x, y) = if g.cmp_nodes(a, b).is_le() { (a, b) } else { (b, a) };
                        Some(Frac::atom(g.dot(x, y)?))
                    }
                }
            }
        })
    }

    /// `x·(p×q)` as a signed, sorted triple product; zero when two entries are equal.
    fn triple(&mut self, g: &mut Graph, x: Id, p: Id, q: Id) -> Result<Frac, TypeError> {
        let mut v = [x, p, q];
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            return Ok(Frac::zero());
        }
        if let Some(Some(rigid)) = self.rigid_triple(g, x, p, q)? {
            return Ok(rigid);
        }
        // Sort with a parity count: the triple product is antisymmetric.
        let mut sign = 1;
        for i in 0..3 {
            for j in 0..2 - i {
                if g.cmp_nodes(v[j], v[j + 1]).is_gt() {
                    v.swap(j, j + 1);
                    sign = -sign;
                }
            }
        }
        let c = g.cross(v[1], v[2])?;
        let atom = g.dot(v[0], c)?;
        Ok(Frac::atom(atom).scale(&Rational::int(sign)))
    }

    /// The component `axis` of a vector atom; `None` when it is too large to expand.
    pub(super) fn component(&mut self, g: &mut Graph, a: Id, axis: Axis) -> Result<Option<Frac>, TypeError> {
        if let Some(rigid) = self.rigid_component(g, a, axis)? {
            return Ok(rigid);
        }
        if let Node::Cross([p, q]) = g.node(a).clone() {
            // (p×q)ₓ = p_y q_z − p_z q_y, cyclically.
            let (i, j) = match axis {
                Axis::X => (Axis::Y, Axis::Z),
                Axis::Y => (Axis::Z, Axis::X),
                Axis::Z => (Axis::X, Axis::Y),
            };
            let (pi, pj) = (self.component(g, p, i)?, self.component(g, p, j)?);
            let (qi, qj) = (self.component(g, q, i)?, self.component(g, q, j)?);
            return Ok(difference_of_products([pi, qj, pj, qi]));
        }
        Ok(Some(Frac::atom(g.comp(a, axis)?)))
    }

    /// `a×b` in 3D, bilinear.
    pub(super) fn cross3(&mut self, g: &mut Graph, a: &VecForm, b: &VecForm) -> Result<Option<VecForm>, TypeError> {
        let mut acc = VecForm::default();
        for (u, s) in &a.0 {
            for (w, t) in &b.0 {
                let Some(atom) = self.cross_atoms(g, *u, *w)? else { return Ok(None) };
                let Some(st) = s.mul(t) else { return Ok(None) };
                let Some(term) = atom.scale(&st) else { return Ok(None) };
                let Some(sum) = acc.add(&term) else { return Ok(None) };
                acc = sum;
            }
        }
        Ok(Some(acc))
    }

    /// `u×w` of two vector atoms in 3D; `None` when it is too large to expand.
    fn cross_atoms(&mut self, g: &mut Graph, u: VAtom, w: VAtom) -> Result<Option<VecForm>, TypeError> {
        let one = || Frac::constant(Rational::ONE);
        Ok(Some(match (u, w) {
            (VAtom::Basis(x), VAtom::Basis(y)) => {
                let (i, j) = (x.index(), y.index());
                if i == j {
                    VecForm::default()
                } else {
                    let k = 3 - i - j;
                    let sign = if (j + 3 - i) % 3 == 1 { 1 } else { -1 };
                    VecForm(vec![(VAtom::Basis(Axis::ALL[k]), Frac::constant(Rational::int(sign)))])
                }
            }
            (VAtom::Atom(a), VAtom::Basis(e)) => {
                // a × eₑ through components: Σᵢ εᵢⱼₑ a_j eᵢ
                let mut terms = VecForm::default();
                for i in Axis::ALL {
                    for j in Axis::ALL {
                        let sign = levi_civita(i.index(), j.index(), e.index());
                        if sign != 0 {
                            let Some(aj) = self.component(g, a, j)? else { return Ok(None) };
                            let basis = VecForm::term(VAtom::Basis(i), aj.scale(&Rational::int(sign)));
                            let Some(sum) = terms.add(&basis) else { return Ok(None) };
                            terms = sum;
                        }
                    }
                }
                terms
            }
            (VAtom::Basis(_), VAtom::Atom(_)) => return Ok(self.cross_atoms(g, w, u)?.map(|v| v.negated())),
            (VAtom::Atom(a), VAtom::Atom(b)) => {
                if a == b {
                    return Ok(Some(VecForm::default()));
                }
                if let Some(rigid) = self.rigid_cross3(g, a, b)? {
                    return Ok(rigid);
                }
                match (g.node(a).clone(), g.node(b).clone()) {
                    // (p×q)×w = q(p·w) − p(q·w)
                    (Node::Cross([p, q]), _) => {
                        let pw = self.dot_atoms(g, VAtom::Atom(p), VAtom::Atom(b))?;
                        let qw = self.dot_atoms(g, VAtom::Atom(q), VAtom::Atom(b))?;
                        let (Some(pw), Some(qw)) = (pw, qw) else { return Ok(None) };
                        let first = VecForm::term(VAtom::Atom(q), pw);
                        let second = VecForm::term(VAtom::Atom(p), qw);
                        return Ok(first.add(&second.negated()));
                    }
                    // u×(p×q) = p(u·q) − q(u·p)
                    (_, Node::Cross([p, q])) => {
                        let uq = self.dot_atoms(g, VAtom::Atom(a), VAtom::Atom(q))?;
                        let up = self.dot_atoms(g, VAtom::Atom(a), VAtom::Atom(p))?;
                        let (Some(uq), Some(up)) = (uq, up) else { return Ok(None) };
                        let first = VecForm::term(VAtom::Atom(p), uq);
                        let second = VecForm::term(VAtom::Atom(q), up);
                        return Ok(first.add(&second.negated()));
                    }
                    _ => {
                        let (x, y, sign) = if g.cmp_nodes(a, b).is_lt() { (a, b, 1) } else { (b, a, -1) };
                        let atom = g.cross(x, y)?;
                        VecForm(vec![(VAtom::Atom(atom), one().scale(&Rational::int(sign)))])
                    }
                }
            }
        }))
    }

    /// `a×b` in 2D: the scalar `a.x b.y − a.y b.x`, bilinear.
    pub(super) fn cross2(&mut self, g: &mut Graph, a: &VecForm, b: &VecForm) -> Result<Option<Frac>, TypeError> {
        let mut acc = Frac::zero();
        for (u, s) in &a.0 {
            for (w, t) in &b.0 {
                let atom = match (*u, *w) {
                    (VAtom::Basis(x), VAtom::Basis(y)) => Frac::constant(Rational::int(match (x, y) {
                        (Axis::X, Axis::Y) => 1,
                        (Axis::Y, Axis::X) => -1,
                        _ => 0,
                    })),
                    // u × eₓ = −u.y, u × e_y = u.x
                    (VAtom::Atom(p), VAtom::Basis(x)) => {
                        let (axis, sign) = if x == Axis::X { (Axis::Y, -1) } else { (Axis::X, 1) };
                        let Some(c) = self.component(g, p, axis)? else { return Ok(None) };
                        c.scale(&Rational::int(sign))
                    }
                    (VAtom::Basis(x), VAtom::Atom(p)) => {
                        let (axis, sign) = if x == Axis::X { (Axis::Y, 1) } else { (Axis::X, -1) };
                        let Some(c) = self.component(g, p, axis)? else { return Ok(None) };
                        c.scale(&Rational::int(sign))
                    }
                    (VAtom::Atom(p), VAtom::Atom(q)) if p == q => Frac::zero(),
                    (VAtom::Atom(p), VAtom::Atom(q)) if let Some(rigid) = self.rigid_cross(g, p, q)? => {
                        let Some(f) = rigid else { return Ok(None) };
                        f
                    }
                    (VAtom::Atom(p), VAtom::Atom(q)) => {
                        let (x, y, sign) = if g.cmp_nodes(p, q).is_lt() { (p, q, 1) } else { (q, p, -1) };
                        Frac::atom(g.cross(x, y)?).scale(&Rational::int(sign))
                    }
                };
                let Some(term) = s.mul(t).and_then(|st| st.mul(&atom)) else { return Ok(None) };
                let Some(sum) = acc.add(&term) else { return Ok(None) };
                acc = sum;
            }
        }
        Ok(Some(acc))
    }

    /// `norm(a)`: positive content taken out, sign normalised, `norm(u)² = u·u` remembered.
    fn norm(&mut self, g: &mut Graph, a: &VecForm) -> Result<Option<Frac>, TypeError> {
        if a.0.is_empty() {
            return Ok(Some(Frac::zero()));
        }
        let mut content = a.0[0].1.num.content();
        for (_, s) in &a.0[1..] {
            content = content.gcd(&s.num.content());
        }
        // norm(−u) = norm(u): make the coefficient of the first atom, in the order people
        // read, positive.
        let first =
            a.0.iter()
                .min_by(|x, y| match (x.0, y.0) {
                    (VAtom::Atom(p), VAtom::Atom(q)) => g.cmp_nodes(p, q),
                    (p, q) => p.cmp(&q),
                })
                .map(|(_, s)| s);
        if first.and_then(|s| s.num.leading()).is_some_and(|(_, q)| q.is_negative()) {
            content = content.neg();
        }
        let inv = content.recip().unwrap_or(Rational::ONE);
        let Some(inner) = a.scale(&Frac::constant(inv)) else { return Ok(None) };
        let square = match self.dot(g, &inner, &inner)? {
            Some(s) => s,
            None => return Ok(None),
        };
        if let [(VAtom::Basis(_), s)] = inner.0.as_slice()
            && s.as_constant().is_some()
        {
            return Ok(Some(Frac::constant(content.abs())));
        }
        let arg = self.build(g, &Canon::V(inner))?;
        // The layout may write the argument as the negation of a difference the user wrote
        // (`−(r2 − r1)`, `Simplifier::keep_orientations`): the norm of that difference.
        let arg = match g.node(arg) {
            Node::Mul(xs) if super::present::is_negation(g, arg) => xs[1],
            _ => arg,
        };
        let atom = g.norm(arg)?;
        self.radicals.insert(atom, Rc::new(square));
        Ok(Some(Frac::atom(atom).scale(&content.abs())))
    }
}

/// `p` with `x² = 1 − y²` in every term: `x^e` becomes `x^(e mod 2) (1 − y²)^(e div 2)`;
/// `None` when a power is too large to expand.
fn substitute_square(p: &Poly, x: Id, y: Id) -> Option<Poly> {
    // 1 − y², its terms in order (degree 0, then 2).
    let one_minus = Poly(vec![(Mono::one(), Rational::ONE), (Mono(smallvec::smallvec![(y, 2)]), Rational::int(-1))]);
    let mut terms: Vec<(Mono, Rational)> = Vec::with_capacity(p.len() + 4);
    for (m, q) in &p.0 {
        let e = m.exponent(x);
        if e < 2 {
            terms.push((m.clone(), q.clone()));
            continue;
        }
        let rest = m.with_exponent(x, e % 2);
        let k = e.unsigned_abs() / 2;
        let factor = if k == 1 { None } else { Some(one_minus.powi(k)?) };
        // q rest (1 − y²)^k, term by term.
        terms.extend(factor.as_ref().unwrap_or(&one_minus).0.iter().map(|(t, c)| (t.mul(&rest), c.mul(q))));
    }
    Some(sum_terms(terms))
}

/// The scalar part of a form (zero for a vector).
fn scalar(c: &Canon) -> Frac {
    match c {
        Canon::S(f) => f.clone(),
        Canon::V(_) => Frac::zero(),
    }
}

/// Whether `square` can divide the cofactor of `a^e` in `p` (its terms with that exponent,
/// `a` taken out), decided without building the cofactor: `Poly::div_exact`'s first test,
/// the square's leading monomial dividing the cofactor's, and for a one-term square the
/// whole test (the cofactor's terms are distinct monomials, so every one must be divisible).
/// Most negative powers have no such cofactor; this keeps their test from costing a sort
/// and a division each.
fn may_divide(square: &Poly, p: &Poly, a: Id, e: i32) -> bool {
    let Some((lead, _)) = square.leading() else { return true };
    let mut cofactor = p.0.iter().filter(|(m, _)| m.exponent(a) == e).map(|(m, _)| m.with_exponent(a, 0));
    if square.len() == 1 { cofactor.all(|m| lead.divides(&m)) } else { cofactor.max().is_none_or(|m| lead.divides(&m)) }
}

/// The polynomial `Σ qᵢ mᵢ` of unsorted terms: sorted once, like terms collected.
fn sum_terms(mut terms: Vec<(Mono, Rational)>) -> Poly {
    // The sort makes about n log₂ n comparisons of monomials, each visiting their atoms:
    // charged to the work meter as the arithmetic's term operations are (uncharged, the
    // trigonometric reduction of one large numerator sorted for seconds past its formula's
    // budget: issue 17's twelve definitions, 8 s and 355 MB).
    let n = terms.len() as u64;
    let visited: u64 = terms.iter().map(|(m, _)| m.0.len() as u64 + 1).sum();
    work::charge(visited.saturating_mul(u64::from(u64::BITS - n.leading_zeros())));
    terms.sort_by(|a, b| a.0.cmp(&b.0));
    let mut out: Vec<(Mono, Rational)> = Vec::new();
    for (m, q) in terms {
        match out.last_mut() {
            Some(last) if last.0 == m => last.1 = last.1.add(&q),
            _ => {
                if out.last().is_some_and(|l| l.1.is_zero()) {
                    out.pop();
                }
                out.push((m, q));
            }
        }
    }
    if out.last().is_some_and(|l| l.1.is_zero()) {
        out.pop();
    }
    Poly(out)
}

/// `p q − r s`, or `None` when a factor or a product is too large to expand: the caller
/// then keeps its piece unexpanded (never zero).
fn difference_of_products([p, q, r, s]: [Option<Frac>; 4]) -> Option<Frac> {
    p?.mul(&q?)?.sub(&r?.mul(&s?)?)
}

fn levi_civita(i: usize, j: usize, k: usize) -> i64 {
    match (i, j, k) {
        (0, 1, 2) | (1, 2, 0) | (2, 0, 1) => 1,
        (0, 2, 1) | (2, 1, 0) | (1, 0, 2) => -1,
        _ => 0,
    }
}

impl VecForm {
    /// `s u` alone; empty when `s` is zero (a form never holds a zero coefficient: the
    /// triple product in `(p×q)×w = q(p·w) − p(q·w)` can vanish, as for `w = q×p`).
    fn term(u: VAtom, s: Frac) -> VecForm {
        if s.is_zero() { VecForm::default() } else { VecForm(vec![(u, s)]) }
    }

    pub(super) fn add(&self, other: &VecForm) -> Option<VecForm> {
        // Merges: the result's size is bounded by the operands', and growing it was 3 % of the
        // bead's derivation (callgrind).
        let mut out: Vec<(VAtom, Frac)> = Vec::with_capacity(self.0.len() + other.0.len());
        let (a, b) = (&self.0, &other.0);
        let (mut i, mut j) = (0, 0);
        while i < a.len() || j < b.len() {
            let take = match (a.get(i), b.get(j)) {
                (Some(x), Some(y)) => x.0.cmp(&y.0),
                (Some(_), None) => std::cmp::Ordering::Less,
                _ => std::cmp::Ordering::Greater,
            };
            match take {
                std::cmp::Ordering::Less => {
                    out.push(a[i].clone());
                    i += 1;
                }
                std::cmp::Ordering::Greater => {
                    out.push(b[j].clone());
                    j += 1;
                }
                std::cmp::Ordering::Equal => {
                    let s = a[i].1.add(&b[j].1)?;
                    if !s.is_zero() {
                        out.push((a[i].0, s));
                    }
                    i += 1;
                    j += 1;
                }
            }
        }
        Some(VecForm(out))
    }

    pub(super) fn scale(&self, k: &Frac) -> Option<VecForm> {
        if k.is_zero() {
            return Some(VecForm::default());
        }
        let mut out = Vec::new();
        for (u, s) in &self.0 {
            out.push((*u, s.mul(k)?));
        }
        Some(VecForm(out))
    }

    fn negated(&self) -> VecForm {
        VecForm(self.0.iter().map(|(u, s)| (*u, s.neg())).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::graph::Role;

    /// `sin²x + cos²x = 1` for any common argument, inside larger sums and products
    /// (`k sin²(w t) + k cos²(w t)` is `k`, the tilted plane's `(sin²α + cos²α)/m` is
    /// `1/m`), and a lone `sin²x` is left as it is (`1 − cos²x` is no smaller).
    #[test]
    fn sin_squared_plus_cos_squared_is_one_for_any_argument() {
        let mut g = Graph::new(3);
        let k = g.declare("k", Ty::Scalar, Role::Parameter);
        let w = g.declare("w", Ty::Scalar, Role::Parameter);
        let t = g.declare("t", Ty::Scalar, Role::Time);
        let (k, w, t) = (g.sym(k), g.sym(w), g.sym(t));
        let wt = g.mul(vec![w, t]).expect("scalars");
        let s = g.call(Func::Sin, &[wt]).expect("scalar");
        let c = g.call(Func::Cos, &[wt]).expect("scalar");
        let (s2, c2) = (g.powi(s, 2).expect("scalar"), g.powi(c, 2).expect("scalar"));
        let ks2 = g.mul(vec![k, s2]).expect("scalars");
        let kc2 = g.mul(vec![k, c2]).expect("scalars");
        let sum = g.add(vec![ks2, kc2]).expect("scalars");
        let mut simplifier = Simplifier::new();
        let simplified = simplifier.simplify(&mut g, sum).expect("well typed");
        assert_eq!(simplified, k);
        let alone = simplifier.simplify(&mut g, s2).expect("well typed");
        assert_eq!(alone, s2);
        // sin⁴ + 2 sin² cos² + cos⁴ = (sin² + cos²)² = 1
        let s4 = g.powi(s, 4).expect("scalar");
        let c4 = g.powi(c, 4).expect("scalar");
        let two = g.int(2);
        let cross = g.mul(vec![two, s2, c2]).expect("scalars");
        let square = g.add(vec![s4, cross, c4]).expect("scalars");
        let one = simplifier.simplify(&mut g, square).expect("well typed");
        assert_eq!(g.as_num(one), Some(&Rational::ONE));
    }

    /// A component of `(((a₀×a₁)×a₂)×…)×a₁₂` has 2¹² terms, past `MAX_TERMS`: the form is
    /// too large to expand, which means "keep it unexpanded", never zero.
    #[test]
    fn a_component_too_large_to_expand_is_not_zero() {
        let mut g = Graph::new(3);
        let vectors: Vec<Id> = (0..13)
            .map(|i| {
                let s = g.declare(&format!("a{i}"), Ty::Vector, Role::Parameter);
                g.sym(s)
            })
            .collect();
        let mut nested = vectors[0];
        for &v in &vectors[1..] {
            nested = g.cross(nested, v).expect("vectors");
        }
        let mut simplifier = Simplifier::new();
        let component = simplifier.component(&mut g, nested, Axis::X).expect("well typed");
        assert!(!component.is_some_and(|f| f.is_zero()), "a form too large to expand became zero");
        // One level less fits, and is expanded.
        let Node::Cross([smaller, _]) = g.node(nested).clone() else { panic!("a cross product") };
        let expanded = simplifier.component(&mut g, smaller, Axis::X).expect("well typed");
        assert_eq!(expanded.map(|f| f.num.len()), Some(1 << 11));
    }
}
