//! Expressions that are the same up to a renaming of symbols.
//!
//! The links of a chain, the springs of a cloth, the walls of a box: a scene repeats a few
//! constraints over many bodies. `|r₃ − r₂|² − l²` is `|r₂ − r₁|² − l²` with the bodies
//! renamed, and so is everything derived from it. A [`Shape`] is an expression with its
//! symbols replaced by numbered slots, so such expressions have equal shapes; work done on
//! one (simplifying, deriving) is reused for the others by renaming its result
//! ([`Template`]).
//!
//! Renaming symbols one-to-one preserves value, so a reused result is always correct. It
//! is also the result the work would have given: the shape records the order in which the
//! slots' symbols sort ([`Graph::cmp_symbols`], by role and body), the only thing about a
//! symbol the simplifier's layout looks at besides its type and role, which the shape
//! records too. Parameters and `t` are not renamed: they keep their identity in the shape.
//!
//! Not here: what is reused (`derive`, [`super::Simplifier::simplify_alike`]).

use super::graph::{FastMap, Graph, Id, Marks, Node, Role, Symbol};
use smallvec::SmallVec;

/// An expression with its renameable symbols numbered by first appearance.
#[derive(Clone, Debug)]
pub struct Shape {
    /// The expression's structure, slots, and the slots' sort order; equal keys mean equal
    /// expressions up to renaming.
    pub key: Vec<u32>,
    /// The symbol in each slot.
    pub symbols: Vec<Symbol>,
}

// Tags of the key's records: a node kind's rank ([`Node::rank`]), and for symbols whether
// the symbol is fixed or a slot (a rank is a `u8`, so these do not collide with one).
const FIXED: u32 = 1 << 8;
const SLOT: u32 = FIXED + 1;

/// Whether a symbol keeps its identity in a shape (parameters and time are shared by the
/// whole scene; bodies' symbols are renamed).
fn fixed(role: Role) -> bool {
    matches!(role, Role::Parameter | Role::Time)
}

/// Scratch space for [`Shaper::shape`]: a number per graph node, reused from call to call,
/// so that a shape costs its expression's size and no hashing.
#[derive(Debug, Default)]
pub struct Shaper {
    /// Each node's number in this call's key.
    seen: Marks<u32>,
    /// Each symbol's slot (by symbol index) in this call's shape.
    slot_of: Marks<u32>,
    /// The walk's stack, kept for its room.
    stack: Vec<(Id, bool)>,
    /// The length of the last key, the room the next one starts with: a chain's keys come
    /// one per link and alike, and growing each from empty was 2 % of its derivation
    /// (callgrind, a 50-link chain).
    last_len: usize,
}

impl Shaper {
    /// The shape of the expressions `roots` taken together.
    ///
    /// Linear in the number of distinct nodes: shared subexpressions are recorded once and
    /// referred to by their index, so a deeply shared graph cannot blow the key up.
    pub fn shape(&mut self, g: &Graph, roots: &[Id]) -> Shape {
        self.seen.clear();
        self.slot_of.clear();
        let mut key = Vec::with_capacity(self.last_len.max(16));
        let mut symbols: Vec<Symbol> = Vec::new();
        let mut count = 0u32;
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        stack.extend(roots.iter().rev().map(|&r| (r, false)));
        while let Some((id, expanded)) = stack.pop() {
            if self.seen.contains(id.index()) {
                continue;
            }
            let node = g.node(id);
            if !expanded {
                stack.push((id, true));
                stack.extend(node.children().iter().rev().map(|&c| (c, false)));
                continue;
            }
            let seen = &self.seen;
            let kid = |c: &Id| seen.get(c.index()).unwrap_or(u32::MAX);
            match node {
                // Equal numbers are one node of the graph (hash-consing), so the id is the value.
                Node::Num(_) => key.extend([u32::from(node.rank()), id.index() as u32]),
                Node::Sym(s) if fixed(g.symbol(*s).role) => key.extend([FIXED, s.index() as u32]),
                Node::Sym(s) => {
                    let slot = match self.slot_of.get(s.index()) {
                        Some(slot) => slot,
                        None => {
                            let slot = symbols.len() as u32;
                            self.slot_of.set(s.index(), slot);
                            symbols.push(*s);
                            slot
                        }
                    };
                    key.extend([SLOT, slot]);
                }
                // Any other node: its kind, what it holds besides its children (how many,
                // which axis, which function), and its children's records.
                _ => {
                    let label = match node {
                        Node::Comp(_, axis) => axis.index() as u32,
                        Node::Call(f, _) => *f as u32,
                        _ => node.children().len() as u32,
                    };
                    key.extend([u32::from(node.rank()), label]);
                    key.extend(node.children().iter().map(kid));
                }
            }
            self.seen.set(id.index(), count);
            count += 1;
        }
        self.stack = stack;
        // Which root is which record.
        key.push(u32::MAX);
        key.extend(roots.iter().map(|r| self.seen.get(r.index()).unwrap_or(u32::MAX)));
        // What each slot is, and the order the slots' symbols sort in.
        for &s in &symbols {
            // The kind of role (its sort rank without the body).
            key.push(u32::from(g.symbol(s).role.rank().0));
        }
        let mut order: Vec<u32> = (0..symbols.len() as u32).collect();
        order.sort_by(|&a, &b| g.cmp_symbols(symbols[a as usize], symbols[b as usize]));
        key.extend(order);
        self.last_len = key.len();
        Shape { key, symbols }
    }
}

/// Results kept for reuse by shape: as they are at first, made a [`Template`] when their
/// shape comes again (in a small scene most shapes come once, and a template costs a walk).
#[derive(Clone, Debug)]
pub struct Reuse {
    roots: Vec<Id>,
    slots: Vec<Symbol>,
    along_derivatives: bool,
    template: Option<Template>,
}

impl Reuse {
    /// `roots`, computed from an expression whose shape had the symbols `slots`; see
    /// [`Template::new`] for `along_derivatives`.
    pub fn new(roots: Vec<Id>, slots: Vec<Symbol>, along_derivatives: bool) -> Reuse {
        Reuse { roots, slots, along_derivatives, template: None }
    }

    /// The symbols of the expression the results were computed from.
    pub fn slots(&self) -> &[Symbol] {
        &self.slots
    }

    /// The results renamed to `slots` ([`Template::instantiate`]).
    pub fn renamed(&mut self, g: &mut Graph, slots: &[Symbol]) -> Option<Vec<Id>> {
        let (roots, from, along) = (&self.roots, &self.slots, self.along_derivatives);
        let template = self.template.get_or_insert_with(|| Template::new(g, roots, from, along));
        template.instantiate(g, slots)
    }
}

/// Results to be renamed many times: the nodes of their graph that involve renamed symbols,
/// children first, as a small program over their own numbering.
#[derive(Clone, Debug)]
pub struct Template {
    ops: Vec<Op>,
    roots: Vec<u32>,
    /// The renamed symbols: a slot of the shape, and how many time derivatives down from it.
    symbols: Vec<(u32, u8)>,
}

#[derive(Clone, Debug)]
enum Op {
    /// A node without renamed symbols, used as it is.
    Keep(Id),
    /// The symbol `symbols[i]`, renamed.
    Symbol(usize),
    /// The node `like` over the renamed children at these places.
    Node(Id, SmallVec<[u32; 4]>),
}

impl Template {
    /// The template of `roots`, whose expression had the shape's symbols `slots`.
    ///
    /// With `along_derivatives`, the slots' velocities and accelerations are renamed with
    /// them, so what is derived from an expression renames with it; the slots themselves
    /// come first (an expression with `r₁` and `v₂` may be renamed to one with `r₃` and `v₃`).
    pub fn new(g: &Graph, roots: &[Id], slots: &[Symbol], along_derivatives: bool) -> Template {
        let mut renamed: FastMap<Symbol, usize> = FastMap::default();
        let mut symbols = Vec::new();
        for (i, &s) in slots.iter().enumerate() {
            renamed.insert(s, symbols.len());
            symbols.push((i as u32, 0));
        }
        if along_derivatives {
            for (i, &s) in slots.iter().enumerate() {
                let (mut next, mut depth) = (g.symbol(s).derivative, 1u8);
                while let Some(d) = next {
                    if let std::collections::hash_map::Entry::Vacant(e) = renamed.entry(d) {
                        e.insert(symbols.len());
                        symbols.push((i as u32, depth));
                    }
                    next = g.symbol(d).derivative;
                    depth = depth.saturating_add(1);
                }
            }
        }
        let order = g.reachable(roots);
        let mut place: FastMap<Id, u32> = FastMap::default();
        let mut ops = Vec::new();
        for id in order {
            let node = g.node(id);
            let op = match node {
                Node::Sym(s) => match renamed.get(s) {
                    Some(&i) => Op::Symbol(i),
                    None => Op::Keep(id),
                },
                _ => {
                    let kids: SmallVec<[u32; 4]> = node.children().iter().map(|c| place[c]).collect();
                    if kids.iter().all(|&k| matches!(ops[k as usize], Op::Keep(_))) {
                        Op::Keep(id)
                    } else {
                        Op::Node(id, kids)
                    }
                }
            };
            place.insert(id, ops.len() as u32);
            ops.push(op);
        }
        let roots = roots.iter().map(|r| place[r]).collect();
        Template { ops, roots, symbols }
    }

    /// The roots with the slots renamed to `slots` (the symbols of a shape with the same key
    /// as the template's), or `None` if a renamed symbol has no counterpart (a slot without
    /// the time derivatives the template's has).
    pub fn instantiate(&self, g: &mut Graph, slots: &[Symbol]) -> Option<Vec<Id>> {
        // Sized up front: a chain instantiates a template per link, and growing these
        // vectors was a tenth of the work (callgrind, a 50-link chain).
        let mut symbols = Vec::with_capacity(self.symbols.len());
        for &(slot, depth) in &self.symbols {
            let mut s = *slots.get(slot as usize)?;
            for _ in 0..depth {
                s = g.symbol(s).derivative?;
            }
            symbols.push(g.sym(s));
        }
        let mut made: Vec<Id> = Vec::with_capacity(self.ops.len());
        let mut kids: SmallVec<[Id; 4]> = SmallVec::new();
        for op in &self.ops {
            let id = match op {
                Op::Keep(id) => *id,
                Op::Symbol(i) => symbols[*i],
                Op::Node(like, places) => {
                    kids.clear();
                    kids.extend(places.iter().map(|&k| made[k as usize]));
                    g.renamed_node(*like, &kids)
                }
            };
            made.push(id);
        }
        Some(self.roots.iter().map(|&r| made[r as usize]).collect())
    }
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
        let mut shaper = Shaper::default();
        let (a, b) = (shaper.shape(&g, &[first]), shaper.shape(&g, &[second]));
        assert_eq!(a.key, b.key);
        let template = Template::new(&g, &[first], &a.symbols, false);
        assert_eq!(template.instantiate(&mut g, &b.symbols), Some(vec![second]));
        // Along derivatives, the velocities are renamed with the positions.
        let v = |g: &mut Graph, name: &str| {
            let s = g.symbol_named(name).expect("declared");
            g.sym(s)
        };
        let (v0, v1, v2, v3) = (v(&mut g, "v0"), v(&mut g, "v1"), v(&mut g, "v2"), v(&mut g, "v3"));
        let moving = g.dot(v1, v0).expect("vectors");
        let template = Template::new(&g, &[first, moving], &a.symbols, true);
        let expected = g.dot(v3, v2).expect("vectors");
        assert_eq!(template.instantiate(&mut g, &b.symbols), Some(vec![second, expected]));
    }

    #[test]
    fn shapes_differ_in_body_order_parameters_and_numbers() {
        let (mut g, r, k, c) = graph(3);
        let base = link(&mut g, r[1], r[0], k);
        let mut shaper = Shaper::default();
        let mut shape = |g: &Graph, id| shaper.shape(g, &[id]).key;
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
        let shape = Shaper::default().shape(&g, &[x]);
        assert!(shape.key.len() < 400, "key of {} words", shape.key.len());
        assert_eq!(shape.symbols.len(), 1);
    }
}
