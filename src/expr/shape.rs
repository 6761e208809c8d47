//! Expressions that are the same up to a renaming of symbols.
//!
//! The links of a chain, the springs of a cloth, the walls of a box: a scene repeats a few
//! constraints over many bodies. `|r₃ − r₂|² − l²` is `|r₂ − r₁|² − l²` with the bodies
//! renamed, and so is everything derived from it. A [`Shape`] is an expression with its
//! symbols replaced by numbered slots, so such expressions have equal shapes; work done on
//! one (simplifying, deriving) is reused for the others by renaming its result
//! ([`Graph::substitute_all`] with the map of [`renaming`]).
//!
//! Renaming symbols one-to-one preserves value, so a reused result is always correct. It
//! is also the result the work would have given: the shape records the order in which the
//! slots' symbols sort ([`Graph::cmp_symbols`], by role and body), the only thing about a
//! symbol the simplifier's layout looks at besides its type and role, which the shape
//! records too. Parameters and `t` are not renamed: they keep their identity in the shape.
//!
//! Not here: what is reused (`derive`, [`super::Simplifier::simplify_alike`]).

use super::graph::{FastMap, Graph, Id, Node, Role, Symbol};

/// An expression with its renameable symbols numbered by first appearance.
#[derive(Clone, Debug)]
pub struct Shape {
    /// The expression's structure, slots, and the slots' sort order; equal keys mean equal
    /// expressions up to renaming.
    pub key: Vec<u32>,
    /// The symbol in each slot.
    pub symbols: Vec<Symbol>,
}

// Tags of the key's node records.
const NUM: u32 = 0;
const FIXED: u32 = 1;
const SLOT: u32 = 2;
const VECTOR: u32 = 3;
const ADD: u32 = 4;
const MUL: u32 = 5;
const POW: u32 = 6;
const DOT: u32 = 7;
const CROSS: u32 = 8;
const NORM: u32 = 9;
const COMP: u32 = 10;
const CALL: u32 = 11;
const ATAN2: u32 = 12;

/// Whether a symbol keeps its identity in a shape (parameters and time are shared by the
/// whole scene; bodies' symbols are renamed).
fn fixed(role: Role) -> bool {
    matches!(role, Role::Parameter | Role::Time)
}

impl Shape {
    /// The shape of the expressions `roots` taken together.
    ///
    /// Linear in the number of distinct nodes: shared subexpressions are recorded once and
    /// referred to by their index, so a deeply shared graph cannot blow the key up.
    pub fn of(g: &Graph, roots: &[Id]) -> Shape {
        let mut key = Vec::new();
        let mut symbols = Vec::new();
        let mut slot_of: FastMap<Symbol, u32> = FastMap::default();
        // Nodes are numbered in the order their records are written (children first).
        let mut index: FastMap<Id, u32> = FastMap::default();
        let mut stack: Vec<(Id, bool)> = roots.iter().rev().map(|&r| (r, false)).collect();
        while let Some((id, expanded)) = stack.pop() {
            if index.contains_key(&id) {
                continue;
            }
            let node = g.node(id);
            if !expanded {
                stack.push((id, true));
                stack.extend(node.children().iter().rev().map(|&c| (c, false)));
                continue;
            }
            let kid = |c: &Id| index[c];
            match node {
                // Equal numbers are one node of the graph (hash-consing), so the id is the value.
                Node::Num(_) => key.extend([NUM, id.index() as u32]),
                Node::Sym(s) if fixed(g.symbol(*s).role) => key.extend([FIXED, s.index() as u32]),
                Node::Sym(s) => {
                    let next = symbols.len() as u32;
                    let slot = *slot_of.entry(*s).or_insert(next);
                    if slot == next {
                        symbols.push(*s);
                    }
                    key.extend([SLOT, slot]);
                }
                Node::Vector(xs) | Node::Add(xs) | Node::Mul(xs) => {
                    let tag = match node {
                        Node::Vector(_) => VECTOR,
                        Node::Add(_) => ADD,
                        _ => MUL,
                    };
                    key.extend([tag, xs.len() as u32]);
                    key.extend(xs.iter().map(kid));
                }
                Node::Pow([a, b]) => key.extend([POW, kid(a), kid(b)]),
                Node::Dot([a, b]) => key.extend([DOT, kid(a), kid(b)]),
                Node::Cross([a, b]) => key.extend([CROSS, kid(a), kid(b)]),
                Node::Atan2([a, b]) => key.extend([ATAN2, kid(a), kid(b)]),
                Node::Norm(a) => key.extend([NORM, kid(a)]),
                Node::Comp(a, axis) => key.extend([COMP, axis.index() as u32, kid(a)]),
                Node::Call(f, a) => key.extend([CALL, *f as u32, kid(a)]),
            }
            index.insert(id, index.len() as u32);
        }
        // Which root is which record.
        key.push(u32::MAX);
        key.extend(roots.iter().map(|r| index[r]));
        // What each slot is, and the order the slots' symbols sort in.
        for &s in &symbols {
            key.push(role_code(g.symbol(s).role));
        }
        let mut order: Vec<u32> = (0..symbols.len() as u32).collect();
        order.sort_by(|&a, &b| g.cmp_symbols(symbols[a as usize], symbols[b as usize]));
        key.extend(order);
        Shape { key, symbols }
    }
}

fn role_code(role: Role) -> u32 {
    match role {
        Role::Time => 0,
        Role::Parameter => 1,
        Role::Position { .. } => 2,
        Role::Velocity { .. } => 3,
        Role::Acceleration { .. } => 4,
        Role::Force { .. } => 5,
        Role::Mass { .. } => 6,
    }
}

/// The map from the symbol nodes of `from` to those of `to` (the symbols of two shapes with
/// equal keys).
///
/// With `along_derivatives`, renaming a position renames its velocity and acceleration too,
/// so what is derived from an expression renames with it; the slots themselves come first
/// (an expression with `r₁` and `v₂` may be renamed to one with `r₃` and `v₃`).
pub fn renaming(g: &mut Graph, from: &[Symbol], to: &[Symbol], along_derivatives: bool) -> FastMap<Id, Id> {
    let mut map = FastMap::default();
    for (&a, &b) in from.iter().zip(to) {
        let (na, nb) = (g.sym(a), g.sym(b));
        map.insert(na, nb);
    }
    if along_derivatives {
        for (&a, &b) in from.iter().zip(to) {
            let (mut a, mut b) = (g.symbol(a).derivative, g.symbol(b).derivative);
            while let (Some(x), Some(y)) = (a, b) {
                let (nx, ny) = (g.sym(x), g.sym(y));
                map.entry(nx).or_insert(ny);
                a = g.symbol(x).derivative;
                b = g.symbol(y).derivative;
            }
        }
    }
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::graph::Ty;

    /// A graph with bodies 0..n (positions `r{i}` with velocities `v{i}`) and parameters.
    fn graph(n: usize) -> (Graph, Vec<Id>, Id, Id) {
        let mut g = Graph::new(2);
        let mut r = Vec::new();
        for body in 0..n {
            let p = g.declare(&format!("r{body}"), Ty::Vector, Role::Position { body });
            let v = g.declare(&format!("v{body}"), Ty::Vector, Role::Velocity { body });
            g.set_derivative(p, v);
            r.push(g.sym(p));
        }
        let k = g.declare("k", Ty::Scalar, Role::Parameter);
        let c = g.declare("c", Ty::Scalar, Role::Parameter);
        let (k, c) = (g.sym(k), g.sym(c));
        (g, r, k, c)
    }

    /// `p · |a − b|²`
    fn link(g: &mut Graph, a: Id, b: Id, p: Id) -> Id {
        let d = g.sub(a, b).expect("vectors");
        let dd = g.dot(d, d).expect("vectors");
        g.mul(vec![p, dd]).expect("scalars")
    }

    #[test]
    fn renamed_bodies_have_the_same_shape_and_rename_back() {
        let (mut g, r, k, _) = graph(4);
        let (first, second) = (link(&mut g, r[1], r[0], k), link(&mut g, r[3], r[2], k));
        let (a, b) = (Shape::of(&g, &[first]), Shape::of(&g, &[second]));
        assert_eq!(a.key, b.key);
        let map = renaming(&mut g, &a.symbols, &b.symbols, false);
        assert_eq!(g.substitute(first, &map).expect("renames"), second);
        // Along derivatives, the velocities are renamed with the positions.
        let map = renaming(&mut g, &a.symbols, &b.symbols, true);
        let (v0, v2) = (g.symbol_named("v0").expect("v0"), g.symbol_named("v2").expect("v2"));
        let (v0, v2) = (g.sym(v0), g.sym(v2));
        assert_eq!(map.get(&v0), Some(&v2));
    }

    #[test]
    fn shapes_differ_in_body_order_parameters_and_numbers() {
        let (mut g, r, k, c) = graph(3);
        let base = link(&mut g, r[1], r[0], k);
        let shape = |g: &Graph, id| Shape::of(g, &[id]).key;
        // The bodies in the other order sort the other way: not the same layout.
        let reversed = link(&mut g, r[0], r[1], k);
        assert_ne!(shape(&g, base), shape(&g, reversed));
        // Parameters are not renamed.
        let other_parameter = link(&mut g, r[2], r[1], c);
        assert_ne!(shape(&g, base), shape(&g, other_parameter));
        // Numbers count by value.
        let two = g.int(2);
        let three = g.int(3);
        let (x, y) = (link(&mut g, r[1], r[0], two), link(&mut g, r[2], r[1], three));
        assert_ne!(shape(&g, x), shape(&g, y));
        let y2 = link(&mut g, r[2], r[1], two);
        assert_eq!(shape(&g, x), shape(&g, y2));
    }

    #[test]
    fn a_deeply_shared_graph_has_a_linear_key() {
        // x₀ = r·r, xₙ₊₁ = xₙ · xₙ: 2⁶⁰ leaves as a tree, 61 nodes as a graph.
        let (mut g, r, _, _) = graph(1);
        let mut x = g.dot(r[0], r[0]).expect("vectors");
        for _ in 0..60 {
            x = g.mul(vec![x, x]).expect("scalars");
        }
        let shape = Shape::of(&g, &[x]);
        assert!(shape.key.len() < 400, "key of {} words", shape.key.len());
        assert_eq!(shape.symbols.len(), 1);
    }
}
