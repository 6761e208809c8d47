//! The canonical forms of `rot(θ, s)` and `perp(u)` (2D rigid bodies), as rules of the
//! simplifier.
//!
//! `rot(θ, ·)` and `perp` are linear, so they distribute over a vector form `Σ sⱼ uⱼ`, and
//! their atoms are few: `rot(θ, u)` for a constant vector symbol `u` or the unit vector eₓ
//! (`rot(θ, e_y) = perp(rot(θ, eₓ))`), and `perp(a)` of a non-unit atom. The rules, so that
//! results read like the engines' comments (Box2D's `b2LeftPerp`, `b2Cross`):
//!
//! | rule                                                     | why                      |
//! |----------------------------------------------------------|--------------------------|
//! | `perp(eₓ) = e_y`, `perp(e_y) = −eₓ`, `perp(perp(u)) = −u` | a quarter turn, twice     |
//! | `rot(θ, perp(u)) = perp(rot(θ, u))`                      | rotations commute in 2D  |
//! | `perp(p)·q = p×q`, so `u·perp(u) = 0`                    | the 2D cross product     |
//! | `perp(p)×q = −p·q`, `p×perp(q) = p·q`                     | likewise                 |
//! | `rot(θ,u)·rot(θ,w) = u·w`, `rot(θ,u)×rot(θ,w) = u×w`     | R(θ) is a rotation       |
//! | `rot(θ,u).x = u.x cos θ − u.y sin θ`, `.y = u.x sin θ + u.y cos θ` | components     |
//!
//! In 3D (`q` a quaternion) `rot(q, ·)` is linear with atoms `rot(q, u)` for a constant
//! vector symbol `u` or a unit vector eₖ, and the rules are those of a rotation:
//! `rot(q,u)·rot(q,w) = u·w` and `rot(q,u)×rot(q,w) = rot(q, u×w)`, so a triple product
//! of one body's vectors is its body-frame triple product, in the simplifier's one sorted
//! form (`[u, w, z]` with a sign); a component `rot(q, u).x` is an atom.
//!
//! Not here: the simplifier's other rules (`simplify`), d/dt and ∇ of `rot` and `perp`
//! (`diff`, `grad`).

use super::func::Func;
use super::graph::{Axis, Graph, Id, Node, TypeError};
use super::num::Rational;
use super::poly::Frac;
use super::simplify::{Simplifier, VAtom, VecForm};

impl Simplifier {
    /// The form of `rot(θ, v)`: `Σ sⱼ rot(θ, uⱼ)` over `v`'s form; `None` (kept as written)
    /// when θ is not a single symbol.
    pub(super) fn rot_form(&mut self, g: &mut Graph, theta: Id, v: Id) -> Result<Option<VecForm>, TypeError> {
        let angle = self.scalar_of(theta);
        let Some(theta) = angle.num.as_atom().filter(|&a| angle.den.is_empty() && matches!(g.node(a), Node::Sym(_)))
        else {
            return Ok(None);
        };
        let mut acc = VecForm::default();
        for (u, s) in self.vector_of(v).0 {
            let Some(term) = self.rot_atom(g, theta, u)?.scale(&s) else { return Ok(None) };
            let Some(sum) = acc.add(&term) else { return Ok(None) };
            acc = sum;
        }
        Ok(Some(acc))
    }

    /// `rot(θ, u)` of one atom of a constant vector.
    fn rot_atom(&mut self, g: &mut Graph, theta: Id, u: VAtom) -> Result<VecForm, TypeError> {
        let one = || Frac::constant(Rational::ONE);
        if g.dim() == 3 {
            // 3D: every atom stays `rot(q, u)`, a unit vector as its literal.
            let u = match u {
                VAtom::Basis(axis) => unit(g, axis)?,
                VAtom::Atom(a) => a,
            };
            return Ok(VecForm(vec![(VAtom::Atom(g.rot(theta, u)?), one())]));
        }
        Ok(match u {
            VAtom::Basis(Axis::X) => {
                let ex = unit_x(g)?;
                VecForm(vec![(VAtom::Atom(g.rot(theta, ex)?), one())])
            }
            // rot(θ, e_y) = perp(rot(θ, eₓ))
            VAtom::Basis(_) => {
                let ex = unit_x(g)?;
                let turned = g.rot(theta, ex)?;
                VecForm(vec![(VAtom::Atom(g.perp(turned)?), one())])
            }
            VAtom::Atom(a) => match g.node(a).clone() {
                Node::Perp(b) => {
                    let inner = self.rot_atom(g, theta, VAtom::Atom(b))?;
                    self.perp_of(g, &inner)?
                }
                _ => VecForm(vec![(VAtom::Atom(g.rot(theta, a)?), one())]),
            },
        })
    }

    /// The form of `perp(v)`.
    pub(super) fn perp_form(&mut self, g: &mut Graph, v: Id) -> Result<VecForm, TypeError> {
        let form = self.vector_of(v);
        self.perp_of(g, &form)
    }

    fn perp_of(&mut self, g: &mut Graph, form: &VecForm) -> Result<VecForm, TypeError> {
        let mut terms = Vec::new();
        for (u, s) in &form.0 {
            let (atom, sign) = match *u {
                VAtom::Basis(Axis::X) => (VAtom::Basis(Axis::Y), 1),
                VAtom::Basis(_) => (VAtom::Basis(Axis::X), -1),
                VAtom::Atom(a) => match *g.node(a) {
                    Node::Perp(b) => (VAtom::Atom(b), -1),
                    _ => (VAtom::Atom(g.perp(a)?), 1),
                },
            };
            terms.push((atom, s.scale(&Rational::int(sign))));
        }
        // The atoms changed, so their order may have: merged one by one into a sorted form.
        let mut out = VecForm::default();
        for (u, s) in terms {
            out = out.add(&VecForm(vec![(u, s)])).unwrap_or(out);
        }
        Ok(out)
    }

    /// `a·b` of two vector atoms when a rule of this file applies (`Some`; its value `None`
    /// when too large to expand), `None` when none does.
    pub(super) fn rigid_dot(&mut self, g: &mut Graph, a: Id, b: Id) -> Result<Option<Option<Frac>>, TypeError> {
        Ok(match (g.node(a).clone(), g.node(b).clone()) {
            // perp(p)·perp(q) = p·q
            (Node::Perp(p), Node::Perp(q)) => Some(self.dot_atoms(g, VAtom::Atom(p), VAtom::Atom(q))?),
            // perp(p)·q = p×q
            (Node::Perp(p), _) => Some(self.cross_of_atoms(g, VAtom::Atom(p), VAtom::Atom(b))?),
            (_, Node::Perp(q)) => Some(self.cross_of_atoms(g, VAtom::Atom(q), VAtom::Atom(a))?),
            // rot(θ,u)·rot(θ,w) = u·w
            (Node::Rot([t1, u]), Node::Rot([t2, w])) if t1 == t2 => {
                let (u, w) = (constant_atom(g, u), constant_atom(g, w));
                Some(self.dot_atoms(g, u, w)?)
            }
            _ => None,
        })
    }

    /// `p×q` (2D) of two vector atoms when a rule of this file applies; see [`Self::rigid_dot`].
    pub(super) fn rigid_cross(&mut self, g: &mut Graph, p: Id, q: Id) -> Result<Option<Option<Frac>>, TypeError> {
        Ok(match (g.node(p).clone(), g.node(q).clone()) {
            // perp(a)×q = −a·q
            (Node::Perp(a), _) => self.dot_atoms(g, VAtom::Atom(a), VAtom::Atom(q))?.map(|f| Some(f.neg())),
            // p×perp(b) = p·b
            (_, Node::Perp(b)) => Some(self.dot_atoms(g, VAtom::Atom(p), VAtom::Atom(b))?),
            // rot(θ,u)×rot(θ,w) = u×w
            (Node::Rot([t1, u]), Node::Rot([t2, w])) if t1 == t2 => {
                let (u, w) = (constant_atom(g, u), constant_atom(g, w));
                Some(self.cross_of_atoms(g, u, w)?)
            }
            _ => None,
        })
    }

    /// `p×q` (3D) of two vector atoms when a rule of this file applies (`Some`; its value
    /// `None` when too large to expand): `rot(q,u)×rot(q,w) = rot(q, u×w)`.
    pub(super) fn rigid_cross3(&mut self, g: &mut Graph, p: Id, q: Id) -> Result<Option<Option<VecForm>>, TypeError> {
        let (Node::Rot([t1, u]), Node::Rot([t2, w])) = (g.node(p).clone(), g.node(q).clone()) else { return Ok(None) };
        if t1 != t2 {
            return Ok(None);
        }
        let one = || Frac::constant(Rational::ONE);
        let (u, w) = (VecForm(vec![(constant_atom(g, u), one())]), VecForm(vec![(constant_atom(g, w), one())]));
        let Some(body_frame) = self.cross3(g, &u, &w)? else { return Ok(Some(None)) };
        let mut acc = VecForm::default();
        for (atom, s) in body_frame.0 {
            let Some(term) = self.rot_atom(g, t1, atom)?.scale(&s) else { return Ok(Some(None)) };
            let Some(sum) = acc.add(&term) else { return Ok(Some(None)) };
            acc = sum;
        }
        Ok(Some(Some(acc)))
    }

    /// `x·(p×q)` (3D) when two of the three turn with one quaternion: the cyclic order puts
    /// them in the cross product, `rot(q,u)×rot(q,w) = rot(q, u×w)`, and the dot product is
    /// taken of the result (`Some`; its value `None` when too large), else `None`.
    pub(super) fn rigid_triple(
        &mut self,
        g: &mut Graph,
        x: Id,
        p: Id,
        q: Id,
    ) -> Result<Option<Option<Frac>>, TypeError> {
        if g.dim() != 3 {
            return Ok(None);
        }
        // x·(p×q) = p·(q×x) = q·(x×p)
        for (a, b, c) in [(x, p, q), (p, q, x), (q, x, p)] {
            let Some(turned) = self.rigid_cross3(g, b, c)? else { continue };
            let Some(turned) = turned else { return Ok(Some(None)) };
            let mut acc = Frac::zero();
            for (atom, s) in turned.0 {
                let Some(d) = self.dot_atoms(g, VAtom::Atom(a), atom)? else { return Ok(Some(None)) };
                let Some(sum) = d.mul(&s).and_then(|t| acc.add(&t)) else { return Ok(Some(None)) };
                acc = sum;
            }
            return Ok(Some(Some(acc)));
        }
        Ok(None)
    }

    /// `u×w` (2D) of two atoms, through the simplifier's bilinear cross product.
    fn cross_of_atoms(&mut self, g: &mut Graph, u: VAtom, w: VAtom) -> Result<Option<Frac>, TypeError> {
        let one = || Frac::constant(Rational::ONE);
        self.cross2(g, &VecForm(vec![(u, one())]), &VecForm(vec![(w, one())]))
    }

    /// The component `axis` of a `rot` or `perp` atom; `None` when `a` is neither (outer) or
    /// too large to expand (inner).
    pub(super) fn rigid_component(
        &mut self,
        g: &mut Graph,
        a: Id,
        axis: Axis,
    ) -> Result<Option<Option<Frac>>, TypeError> {
        Ok(match g.node(a).clone() {
            // perp(b) = [−b.y, b.x]
            Node::Perp(b) => Some(match axis {
                Axis::X => self.component(g, b, Axis::Y)?.map(|f| f.neg()),
                _ => self.component(g, b, Axis::X)?,
            }),
            // 3D: a component of `rot(q, u)` is an atom of its own.
            Node::Rot(_) if g.dim() == 3 => None,
            Node::Rot([theta, u]) => {
                let cos = Frac::atom(g.call(Func::Cos, &[theta])?);
                let sin = Frac::atom(g.call(Func::Sin, &[theta])?);
                let (ux, uy) = match constant_atom(g, u) {
                    VAtom::Basis(Axis::X) => (Some(Frac::constant(Rational::ONE)), Some(Frac::zero())),
                    VAtom::Basis(_) => (Some(Frac::zero()), Some(Frac::constant(Rational::ONE))),
                    VAtom::Atom(s) => (self.component(g, s, Axis::X)?, self.component(g, s, Axis::Y)?),
                };
                let (Some(ux), Some(uy)) = (ux, uy) else { return Ok(Some(None)) };
                // x: u.x cos θ − u.y sin θ; y: u.x sin θ + u.y cos θ
                let value = match axis {
                    Axis::X => ux.mul(&cos).zip(uy.mul(&sin)).and_then(|(p, q)| p.sub(&q)),
                    _ => ux.mul(&sin).zip(uy.mul(&cos)).and_then(|(p, q)| p.add(&q)),
                };
                Some(value)
            }
            _ => None,
        })
    }
}

/// The unit vector eₓ as a literal.
fn unit_x(g: &mut Graph) -> Result<Id, TypeError> {
    let (one, zero) = (g.int(1), g.int(0));
    g.vector(vec![one, zero])
}

/// The unit vector along `axis` as a literal (3D).
fn unit(g: &mut Graph, axis: Axis) -> Result<Id, TypeError> {
    let entries = Axis::ALL.map(|a| g.int(i64::from(a == axis)));
    g.vector(entries.to_vec())
}

/// The second argument of a `rot` atom (a constant vector symbol or the literal eₓ; in 3D
/// any unit literal) as an atom of a vector form.
fn constant_atom(g: &Graph, u: Id) -> VAtom {
    if g.dim() == 3 {
        if let Node::Vector(xs) = g.node(u) {
            let ones: Vec<usize> = (0..3).filter(|&k| g.as_num(xs[k]).is_some_and(Rational::is_one)).collect();
            if let [k] = ones[..]
                && (0..3).all(|j| j == k || g.is_zero(xs[j]))
            {
                return VAtom::Basis(Axis::ALL[k]);
            }
        }
        return VAtom::Atom(u);
    }
    match g.node(u) {
        Node::Vector(xs) if g.as_num(xs[0]).is_some_and(Rational::is_one) && g.is_zero(xs[1]) => VAtom::Basis(Axis::X),
        Node::Vector(xs) if g.as_num(xs[1]).is_some_and(Rational::is_one) && g.is_zero(xs[0]) => VAtom::Basis(Axis::Y),
        _ => VAtom::Atom(u),
    }
}
