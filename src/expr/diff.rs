//! d/dt at the vector level: forward mode over the graph, with the product and chain rules.
//!
//! d(a·b)/dt = ȧ·b + a·ḃ, d(a×b)/dt = ȧ×b + a×ḃ, d|a|/dt = a·ȧ/|a|, d f(u)/dt = Σ ∂f/∂uᵢ u̇ᵢ
//! (the partials are the function table's, [`Func::partial`]);
//! d rot(θ, s)/dt = θ̇ perp(rot(θ, s)) in 2D and ω × rot(q, s) in 3D, d perp(u)/dt = perp(u̇);
//! a position's derivative is its body's velocity symbol, a velocity's is the acceleration
//! (an orientation's the angular velocity, whose derivative is the angular acceleration),
//! `t` has derivative 1 and parameters are constant. The result is written the way a person
//! applies the rules (`d(r·r)/dt = v·r + r·v`): only zero terms and unit factors are
//! dropped here; collecting is the simplifier's job.
//!
//! The walk is iterative in id order (children first), so deep graphs cannot overflow the
//! stack, and each shared subexpression is differentiated once.

use super::func::Func;
use super::graph::FastMap;
use super::graph::{Graph, Id, Node, Role, Ty, TypeError};
use super::num::Rational;

/// Why a derivative could not be taken.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DiffError {
    #[error("the time derivative of `{0}` is not defined: constraints may use positions, parameters and t")]
    NoDerivative(String),
    #[error("internal type error while differentiating: {0}")]
    Type(#[from] TypeError),
}

/// d/dt of `root`.
pub fn time_derivative(graph: &mut Graph, root: Id) -> Result<Id, DiffError> {
    let order = graph.reachable(&[root]);
    let mut d: FastMap<Id, Id> = FastMap::default();
    // Sized once: growing a hash map rehashes it (measured with `reachable`'s set).
    d.reserve(order.len());
    for id in order {
        let node = graph.node(id).clone();
        let di = derive_node(graph, id, &node, &d)?;
        d.insert(id, di);
    }
    Ok(d[&root])
}

fn derive_node(g: &mut Graph, id: Id, node: &Node, d: &FastMap<Id, Id>) -> Result<Id, DiffError> {
    let ty = g.ty(id);
    Ok(match node {
        Node::Num(_) => g.int(0),
        Node::Sym(s) => {
            let info = g.symbol(*s);
            match (info.role, info.derivative) {
                (Role::Time, _) => g.int(1),
                (Role::Parameter | Role::Mass { .. } | Role::Inertia { .. }, _) => zero(g, ty),
                (_, Some(next)) => g.sym(next),
                (_, None) => return Err(DiffError::NoDerivative(info.name.clone())),
            }
        }
        Node::Vector(xs) => {
            let ds: Vec<Id> = xs.iter().map(|x| d[x]).collect();
            if ds.iter().all(|&x| g.is_zero(x)) { g.zero_vector() } else { g.vector(ds)? }
        }
        Node::Add(xs) => {
            let ds: Vec<Id> = xs.iter().map(|x| d[x]).collect();
            add(g, ds, ty)?
        }
        Node::Mul(xs) => {
            // Product rule: Σᵢ x₁ ⋯ ẋᵢ ⋯ xₙ.
            let mut terms = Vec::new();
            for (i, x) in xs.iter().enumerate() {
                if g.is_zero(d[x]) {
                    continue;
                }
                let mut factors = xs.to_vec();
                factors[i] = d[x];
                terms.push(mul(g, factors, ty)?);
            }
            add(g, terms, ty)?
        }
        Node::Pow([b, e]) => {
            let (db, de) = (d[b], d[e]);
            let mut terms = Vec::new();
            if !g.is_zero(db) {
                // d(b^e) = e b^(e-1) ḃ for constant e.
                let e_minus_one = match g.as_num(*e) {
                    Some(q) => {
                        let q = q.sub(&Rational::ONE);
                        g.num(q)
                    }
                    None => {
                        let minus_one = g.int(-1);
                        g.add(vec![*e, minus_one])?
                    }
                };
                let power = pow(g, *b, e_minus_one)?;
                terms.push(mul(g, vec![*e, power, db], Ty::Scalar)?);
            }
            if !g.is_zero(de) {
                // d(b^e) = b^e ln(b) ė for the exponent's part.
                let ln_b = g.call(Func::Ln, &[*b])?;
                terms.push(mul(g, vec![id, ln_b, de], Ty::Scalar)?);
            }
            add(g, terms, Ty::Scalar)?
        }
        Node::Dot([a, b]) => {
            let mut terms = Vec::new();
            if !g.is_zero(d[a]) {
                terms.push(g.dot(d[a], *b)?);
            }
            if !g.is_zero(d[b]) {
                terms.push(g.dot(*a, d[b])?);
            }
            add(g, terms, ty)?
        }
        Node::Cross([a, b]) => {
            let mut terms = Vec::new();
            if !g.is_zero(d[a]) {
                terms.push(g.cross(d[a], *b)?);
            }
            if !g.is_zero(d[b]) {
                terms.push(g.cross(*a, d[b])?);
            }
            add(g, terms, ty)?
        }
        Node::Norm(a) => {
            if g.is_zero(d[a]) {
                return Ok(g.int(0));
            }
            // d|a|/dt = a·ȧ / |a|
            let num = g.dot(*a, d[a])?;
            g.div(num, id)?
        }
        Node::Comp(a, axis) => {
            if g.is_zero(d[a]) {
                g.int(0)
            } else {
                g.comp(d[a], *axis)?
            }
        }
        Node::Call(f, _) => {
            // Chain rule: Σᵢ ∂f/∂uᵢ u̇ᵢ over the arguments that move.
            let args = node.children();
            let mut terms = Vec::new();
            for (i, u) in args.iter().enumerate() {
                if g.is_zero(d[u]) {
                    continue;
                }
                let outer = f.partial(g, i, args, id)?;
                terms.push(mul(g, vec![outer, d[u]], Ty::Scalar)?);
            }
            add(g, terms, Ty::Scalar)?
        }
        Node::Rot([theta, v]) => {
            // d/dt R(θ) s = θ̇ perp(R(θ) s) + R(θ) ṡ (ṡ = 0 for the constant `s` the
            // language allows; kept for any other). 3D: d/dt R(q) s = ω × R(q) s, where
            // `d[q]` is ω (the orientation symbol's derivative symbol): q̇ itself is never
            // written, since q appears only inside `rot`.
            let mut terms = Vec::new();
            if !g.is_zero(d[theta]) && g.dim() == 3 {
                terms.push(g.cross(d[theta], id)?);
            } else if !g.is_zero(d[theta]) {
                let turned = g.perp(id)?;
                terms.push(mul(g, vec![d[theta], turned], Ty::Vector)?);
            }
            if !g.is_zero(d[v]) {
                terms.push(g.rot(*theta, d[v])?);
            }
            add(g, terms, Ty::Vector)?
        }
        Node::Perp(a) => {
            if g.is_zero(d[a]) {
                g.zero_vector()
            } else {
                g.perp(d[a])?
            }
        }
    })
}

/// The zero of a type.
pub(super) fn zero(g: &mut Graph, ty: Ty) -> Id {
    match ty {
        Ty::Scalar => g.int(0),
        Ty::Vector => g.zero_vector(),
    }
}

/// A sum without its zero terms.
pub(super) fn add(g: &mut Graph, terms: Vec<Id>, ty: Ty) -> Result<Id, TypeError> {
    let terms: Vec<Id> = terms.into_iter().filter(|&t| !g.is_zero(t)).collect();
    if terms.is_empty() { Ok(zero(g, ty)) } else { g.add(terms) }
}

/// A product without unit factors; zero if any factor is zero.
pub(super) fn mul(g: &mut Graph, factors: Vec<Id>, ty: Ty) -> Result<Id, TypeError> {
    if factors.iter().any(|&f| g.is_zero(f)) {
        return Ok(zero(g, ty));
    }
    let factors: Vec<Id> = factors.into_iter().filter(|&f| !g.as_num(f).is_some_and(Rational::is_one)).collect();
    if factors.is_empty() { Ok(g.int(1)) } else { g.mul(factors) }
}

/// `b^e`, without the trivial powers 0 and 1.
pub(super) fn pow(g: &mut Graph, b: Id, e: Id) -> Result<Id, TypeError> {
    match g.as_num(e) {
        Some(q) if q.is_zero() => Ok(g.int(1)),
        Some(q) if q.is_one() => Ok(b),
        _ => g.pow(b, e),
    }
}
