//! ∇ with respect to one symbol, at the vector level, by reverse mode over the graph.
//!
//! For a scalar `C` and a vector symbol `r`, `gradient(C, r)` is the vector expression ∇ᵣC
//! (the direction of the constraint force on the body at `r`); for a scalar symbol it is
//! the partial derivative (∂C/∂t for `t`). Adjoints flow from the root to the leaves:
//! a dot product `a·b` with adjoint `w` sends `w b` to `a` and `w a` to `b`, a cross product
//! `a×b` sends `b×w` to `a` and `w×a` to `b`, `rot(θ, s)` sends `w·perp(rot(θ, s))` to θ,
//! `perp(u)` sends `−perp(w)` to `u`, and so on, so the result stays in vector
//! form (∇(r·r) = r + r, which the simplifier collects to 2r) instead of components.
//!
//! Nodes that do not depend on the symbol get no adjoint, so the work is proportional to
//! the part of the expression that involves it.

use super::diff::{add, mul, zero};
use super::graph::FastMap;
use super::graph::{Axis, Graph, Id, Node, Symbol, Ty, TypeError};
use super::num::Rational;

/// ∂root/∂wrt: a vector for a vector symbol, a scalar for a scalar one. `root` is a scalar.
pub fn gradient(graph: &mut Graph, root: Id, wrt: Symbol) -> Result<Id, TypeError> {
    let target = graph.sym(wrt);
    let target_ty = graph.ty(target);
    let order = graph.reachable(&[root]);
    // Which nodes depend on the symbol at all (children come first in `order`).
    let mut depends: FastMap<Id, bool> = FastMap::default();
    // Sized once: growing a hash map rehashes it (measured with `reachable`'s set).
    depends.reserve(order.len());
    for &id in &order {
        let dep = id == target || graph.node(id).children().iter().any(|c| depends[c]);
        depends.insert(id, dep);
    }
    if !depends[&root] {
        return Ok(zero(graph, target_ty));
    }
    let mut parts: FastMap<Id, Vec<Id>> = FastMap::default();
    let one = graph.int(1);
    parts.insert(root, vec![one]);
    for &id in order.iter().rev() {
        if !depends[&id] || id == target {
            continue;
        }
        let Some(contributions) = parts.remove(&id) else { continue };
        let ty = graph.ty(id);
        let w = add(graph, contributions, ty)?;
        if graph.is_zero(w) {
            continue;
        }
        let node = graph.node(id).clone();
        for (child, adjoint) in propagate(graph, id, &node, w)? {
            if depends[&child] {
                parts.entry(child).or_default().push(adjoint);
            }
        }
    }
    match parts.remove(&target) {
        Some(contributions) => add(graph, contributions, target_ty),
        None => Ok(zero(graph, target_ty)),
    }
}

/// The adjoint contributions of node `id` (with adjoint `w`) to its children.
fn propagate(g: &mut Graph, id: Id, node: &Node, w: Id) -> Result<Vec<(Id, Id)>, TypeError> {
    let mut out = Vec::new();
    match node {
        Node::Num(_) | Node::Sym(_) => {}
        Node::Add(xs) => out.extend(xs.iter().map(|&x| (x, w))),
        Node::Vector(xs) => {
            for (k, &x) in xs.iter().enumerate() {
                let c = g.comp(w, Axis::ALL[k])?;
                out.push((x, c));
            }
        }
        Node::Mul(xs) => {
            let result_is_vector = g.ty(id) == Ty::Vector;
            for (i, &x) in xs.iter().enumerate() {
                let others: Vec<Id> = xs.iter().enumerate().filter(|&(j, _)| j != i).map(|(_, &y)| y).collect();
                let adjoint = if result_is_vector && g.ty(x) == Ty::Scalar {
                    // w · (∂(x u)/∂x) = w·u times the other scalars.
                    let rest = mul(g, others, Ty::Vector)?;
                    g.dot(w, rest)?
                } else {
                    let mut factors = others;
                    factors.push(w);
                    mul(g, factors, g.ty(x))?
                };
                out.push((x, adjoint));
            }
        }
        Node::Pow([b, e]) => {
            // ∂(b^e)/∂b = e b^(e−1); ∂(b^e)/∂e = b^e ln b.
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
            let power = super::diff::pow(g, *b, e_minus_one)?;
            let db = mul(g, vec![w, *e, power], Ty::Scalar)?;
            out.push((*b, db));
            let ln_b = g.call(super::func::Func::Ln, &[*b])?;
            let de = mul(g, vec![w, id, ln_b], Ty::Scalar)?;
            out.push((*e, de));
        }
        Node::Dot([a, b]) => {
            let wa = mul(g, vec![w, *b], Ty::Vector)?;
            let wb = mul(g, vec![w, *a], Ty::Vector)?;
            out.push((*a, wa));
            out.push((*b, wb));
        }
        Node::Cross([a, b]) if g.dim() == 3 => {
            // w·(da × b) = da·(b × w);  w·(a × db) = db·(w × a)
            let ga = g.cross(*b, w)?;
            let gb = g.cross(w, *a)?;
            out.push((*a, ga));
            out.push((*b, gb));
        }
        Node::Cross([a, b]) if involves_rotation(g, id) => {
            // 2D, on rigid bodies: ∂(a×b)/∂a = −perp(b), ∂(a×b)/∂b = perp(a), kept as
            // vectors (a lever arm's components would be written in cos θ and sin θ).
            let pb = g.perp(*b)?;
            let pa = g.perp(*a)?;
            let minus_w = g.neg(w);
            let ga = mul(g, vec![minus_w, pb], Ty::Vector)?;
            let gb = mul(g, vec![w, pa], Ty::Vector)?;
            out.push((*a, ga));
            out.push((*b, gb));
        }
        Node::Cross([a, b]) => {
            // 2D: a×b = a.x b.y − a.y b.x, so ∂/∂a = [b.y, −b.x] and ∂/∂b = [−a.y, a.x].
            let perp = |g: &mut Graph, v: Id, sign_x: i64| -> Result<Id, TypeError> {
                let (vx, vy) = (g.comp(v, Axis::X)?, g.comp(v, Axis::Y)?);
                let (first, second) = if sign_x > 0 { (vy, g.neg(vx)) } else { (g.neg(vy), vx) };
                g.vector(vec![first, second])
            };
            let pa = perp(g, *b, 1)?;
            let pb = perp(g, *a, -1)?;
            let ga = mul(g, vec![w, pa], Ty::Vector)?;
            let gb = mul(g, vec![w, pb], Ty::Vector)?;
            out.push((*a, ga));
            out.push((*b, gb));
        }
        Node::Norm(a) => {
            // ∂|a|/∂a = a / |a|
            let inv = g.powi(id, -1)?;
            let ga = mul(g, vec![w, inv, *a], Ty::Vector)?;
            out.push((*a, ga));
        }
        Node::Comp(a, axis) => {
            let zero = g.int(0);
            let mut entries = vec![zero; g.dim()];
            entries[axis.index()] = w;
            let ga = g.vector(entries)?;
            out.push((*a, ga));
        }
        Node::Call(f, _) => {
            let args = node.children();
            for (i, &u) in args.iter().enumerate() {
                let outer = f.partial(g, i, args, id)?;
                let gu = mul(g, vec![w, outer], Ty::Scalar)?;
                out.push((u, gu));
            }
        }
        // 3D: no symbol a gradient is taken for (a position, ω, t) is inside `rot(q, s)`:
        // q is read by `rot` only and `s` is constant in time, so this is never reached.
        Node::Rot(_) if g.dim() == 3 => return Err(TypeError::OnlyIn2d { name: "∂rot/∂q" }),
        Node::Rot([theta, v]) => {
            // ∂(R(θ) s)/∂θ = perp(R(θ) s), so θ gets w·perp(R(θ) s); s gets Rᵀ w, written
            // in components [w.x cos θ + w.y sin θ, −w.x sin θ + w.y cos θ].
            let turned = g.perp(id)?;
            let gt = g.dot(w, turned)?;
            out.push((*theta, gt));
            let (c, s) = (g.call(super::func::Func::Cos, &[*theta])?, g.call(super::func::Func::Sin, &[*theta])?);
            let (wx, wy) = (g.comp(w, Axis::X)?, g.comp(w, Axis::Y)?);
            let (cx, sy) = (mul(g, vec![c, wx], Ty::Scalar)?, mul(g, vec![s, wy], Ty::Scalar)?);
            let first = add(g, vec![cx, sy], Ty::Scalar)?;
            let (sx, cy) = (mul(g, vec![s, wx], Ty::Scalar)?, mul(g, vec![c, wy], Ty::Scalar)?);
            let minus_sx = g.neg(sx);
            let second = add(g, vec![minus_sx, cy], Ty::Scalar)?;
            let gs = g.vector(vec![first, second])?;
            out.push((*v, gs));
        }
        Node::Perp(a) => {
            // w·perp(da) = da·(−perp(w))
            let turned = g.perp(w)?;
            let ga = g.neg(turned);
            out.push((*a, ga));
        }
    }
    Ok(out)
}

/// Whether `id` involves `rot` or `perp` (a rigid body's vectors), so its gradient is
/// written with `perp`; expressions of point masses keep their component form.
fn involves_rotation(g: &Graph, id: Id) -> bool {
    g.reachable(&[id]).iter().any(|&n| matches!(g.node(n), Node::Rot(_) | Node::Perp(_)))
}
