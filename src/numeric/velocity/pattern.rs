//! Which components of each row's J can be nonzero, known from the constraints as written,
//! before any number: the structural zeros the step's loops leave out. A revolute pin's row
//! `NAME.x` reads only the x components of its bodies' positions, so its linear entries are
//! [±1, 0] and its Ċ reads no v_y; an angular slot holds Jʷ in component 0 only. A
//! Gauss–Seidel row that multiplies by such a 0 waits on the velocities the rows before it
//! moved by 0 (u_y += (w·ΔP)·0), where a handwritten row (Box2D's
//! Ċₓ = (v_bx − ω_b r_By) − (v_ax − ω_a r_Ay)) reads no v_y; so the library's sweep and a
//! generated step (`codegen`: Rust's `ENTRY_CODE` and `ROW_KIND`, C's `ENTRY_MASK`) take the
//! same products over the same components.
//!
//! What leaving a component out changes, exactly: a product 0·u is ±0 for a finite u, and
//! s + (±0) is s except that −0 + (+0) is +0; so a sum without it is the sum with it but
//! for the sign of an exact zero, and for a u that is ±∞ or NaN (which the product would
//! make NaN). An effective mass Σ wᵢ|Jᵢ|² does not change at all (each square is ≥ +0).
//! The library and the generated Rust and C leave out the same components, so they stay
//! one computation, bit for bit.
//!
//! The analysis is over C as the system holds it (definitions substituted, before
//! simplification), conservative: component d of body b's J is a structural zero when C
//! reads no path to component d of b's position — through a component `r.y`, a vector
//! literal's entry, a sum's or a product's vector part, `perp`; a norm, a dot or cross
//! product, `rot`, a power or a function reads every component of what it is given. The
//! derivation's J = ∇C/κ cannot be nonzero where C does not read. A row evaluated from
//! another system (other rows) takes every component.
//!
//! The same reading of C finds the rows whose every entry is a unit vector: C = ±|e| + k,
//! e = Σ ±r_b + a (each body's position once, with coefficient ±1; k and a read no body), a
//! distance row. Each J_b = ±e/|e| then has |J_b|² = 1 identically (κ = 1: the ±1 in ∇C
//! leaves no content to take out), so m_eff = 1/Σ_b (1/m_b) does not depend on the
//! positions; the library and the generated step take |J_b|² as exactly 1 there
//! ([`unit_square`]), where Σ |J_b|²/m_b from the numbers would round differently each step.
//!
//! Among those, a row of two bodies, one with coefficient +1 in e and the other −1 (e = r_b −
//! r_a + a), is an axis row ([`Pattern::is_axis`]): ∇_a C = −∇_b C, so J_a = −J_b, and the
//! derivation's code gives the same products with one factor negated (J_b = e·(1/|e|), J_a =
//! e·(−1/|e|)), which round to the negated numbers, bit for bit (`tests/generate_step.rs`
//! checks it on every such row of every file). A sweep may then read one axis n = J_b and take
//! −n for the other entry: (−n)·u = −(n·u) and s·(−n) = −(s·n) exactly (round to nearest is
//! symmetric), so c + J_a·u_a = c − n·u_a and u_a + s·J_a = u_a − s·n, the same bits.
//!
//! Not here: the loops that use the masks (`Prepared`, the generated step), numbers.

use crate::expr::graph::{FastSet, SymbolWalk};
use crate::expr::{Graph, Id, Node, Role, Ty};
use crate::model::system::System;

/// Every component of a `dim`-dimensional entry: bits 0..dim.
pub fn full(dim: usize) -> u8 {
    ((1u32 << dim.min(3)) - 1) as u8
}

/// The structurally nonzero components of each row's Jacobian entries: per constraint, per
/// body whose position its C reads, a mask (bit d: component d may be nonzero); an angular
/// slot (a rigid body's Jʷ, or Jʷ·eₖ in 3D) is component 0 alone.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Pattern {
    dim: usize,
    bodies: usize,
    /// Per row, `(body, mask)` for each body its C reads, by body.
    rows: Vec<Vec<(usize, u8)>>,
    /// No structural zero anywhere and no angular slot: [`mask`](Pattern::mask) is every
    /// component throughout (point masses on distance rows), so a caller may skip it.
    dense: bool,
    /// Per row, whether every entry of its J is a unit vector, structurally (the module's
    /// note: a distance row).
    unit: Vec<bool>,
    /// Per row, whether it is a unit row between two bodies of opposite signs (J_a = −J_b: an
    /// axis row, the module's note).
    axis: Vec<bool>,
}

/// |J_b|² of an entry of a row whose entries are unit vectors ([`Pattern::is_unit`]) over
/// its first `dim` components: exactly 1 where J_b is a number, NaN where a component is not
/// (J = d/|d| at d = 0), so that the effective mass 1/Σ |J_b|²/m_b is 0 there, as from the
/// numbers (the row does nothing). Without a branch: 1 + 0·J₀ + 0·J₁ …, each 0·x ±0 for a
/// finite x and NaN otherwise.
#[inline(always)]
pub fn unit_square(dim: usize, j: &[f64; 3]) -> f64 {
    j[..dim.min(3)].iter().fold(1.0, |s, x| s + 0.0 * x)
}

impl Pattern {
    /// The pattern of `system`'s constraints (one row each, in order).
    pub fn of(system: &System) -> Pattern {
        let g = &system.graph;
        let mut walk = Walk::default();
        let rows: Vec<Vec<(usize, u8)>> = system.constraints.iter().map(|c| walk.reads(g, c.c)).collect();
        let all = full(g.dim());
        let dense = !system.has_rigid_bodies() && rows.iter().flatten().all(|&(_, m)| m & all == all);
        let mut symbols = SymbolWalk::default();
        let signs: Vec<Option<Vec<bool>>> = system.constraints.iter().map(|c| unit_row(g, &mut symbols, c.c)).collect();
        let unit = signs.iter().map(Option::is_some).collect();
        let axis = signs.iter().map(|s| matches!(s.as_deref(), Some([a, b]) if a != b)).collect();
        Pattern { dim: g.dim(), bodies: system.bodies.len(), rows, dense, unit, axis }
    }

    /// Whether row `row` is an axis row: a unit row whose two entries are J and −J, bit for
    /// bit (the module's note); false where the pattern does not know the row.
    pub fn is_axis(&self, row: usize) -> bool {
        self.axis.get(row).copied().unwrap_or(false)
    }

    /// Whether every entry of row `row`'s J is a unit vector (a distance row, the module's
    /// note), so that |J_b|² is [`unit_square`]; false where the pattern does not know the row.
    pub fn is_unit(&self, row: usize) -> bool {
        self.unit.get(row).copied().unwrap_or(false)
    }

    /// Whether [`mask`](Pattern::mask) is every component of the dimension for every row and
    /// slot: no structural zero and no rigid body's angular slot.
    pub fn is_dense(&self) -> bool {
        self.dense
    }

    /// Rows of this pattern.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The components of row `row`'s entry on slot `slot` (a body, or past the bodies an
    /// angular slot) that can be nonzero; every component where the pattern does not know
    /// the row or the body (never 0: an entry the derivation keeps is read by its C).
    pub fn mask(&self, row: usize, slot: usize) -> u8 {
        let all = full(self.dim);
        if slot >= self.bodies {
            return 1;
        }
        let Some(bodies) = self.rows.get(row) else { return all };
        match bodies.iter().find(|e| e.0 == slot) {
            Some(&(_, m)) if m & all != 0 => m & all,
            _ => all,
        }
    }
}

/// Whether C (`c`) is ±|e| + k with e = Σ ±r_b + a, each body's position once in e with
/// coefficient ±1, and k, a and everything else reading no body (only parameters and the
/// time): then ∇_b C = ±e/|e|, a unit vector, for every body C reads. `Some` of each body's
/// sign in e (true for −1), in the order e sums them, where it is; `None` where it is not.
fn unit_row(g: &Graph, symbols: &mut SymbolWalk, c: Id) -> Option<Vec<bool>> {
    let mut free =
        |id: Id| symbols.free_symbols(g, id).iter().all(|&s| matches!(g.symbol(s).role, Role::Time | Role::Parameter));
    // The one term of C that reads a body.
    let term = match g.node(c) {
        Node::Add(xs) => {
            let mut reading = xs.iter().filter(|&&x| !free(x));
            match (reading.next(), reading.next()) {
                (Some(&x), None) => x,
                _ => return None,
            }
        }
        _ => c,
    };
    let norm = signed(g, term).unwrap_or(term);
    let Node::Norm(e) = g.node(norm) else { return None };
    let terms = match g.node(*e) {
        Node::Add(xs) => &xs[..],
        _ => std::slice::from_ref(e),
    };
    let (mut bodies, mut signs) = (Vec::new(), Vec::new());
    for &t in terms {
        let negative = signed(g, t);
        match g.node(negative.unwrap_or(t)) {
            Node::Sym(s) if matches!(g.symbol(*s).role, Role::Position { .. }) => {
                if bodies.contains(s) {
                    return None;
                }
                bodies.push(*s);
                signs.push(negative.is_some());
            }
            _ if free(t) => {}
            _ => return None,
        }
    }
    (!bodies.is_empty()).then_some(signs)
}

/// `x` where `id` is −x (the product −1·x).
fn signed(g: &Graph, id: Id) -> Option<Id> {
    match g.node(id) {
        Node::Mul(xs) if xs.len() == 2 && g.as_num(xs[0]).is_some_and(|q| q.neg().is_one()) => Some(xs[1]),
        _ => None,
    }
}

/// Which components of which bodies' positions an expression reads (scratch reused over
/// the constraints).
#[derive(Default)]
struct Walk {
    /// `(node, component)`: component d of a vector node, or `u8::MAX` for all of it (a
    /// scalar node, or every component of a vector).
    seen: FastSet<(Id, u8)>,
    stack: Vec<(Id, u8)>,
}

const ALL: u8 = u8::MAX;

impl Walk {
    /// `(body, mask)` by body: the components of each body's position `root` reads.
    fn reads(&mut self, g: &Graph, root: Id) -> Vec<(usize, u8)> {
        self.seen.clear();
        self.stack.clear();
        self.stack.push((root, ALL));
        let mut out: Vec<(usize, u8)> = Vec::new();
        while let Some((id, which)) = self.stack.pop() {
            if !self.seen.insert((id, which)) {
                continue;
            }
            let node = g.node(id);
            match node {
                Node::Num(_) => {}
                Node::Sym(s) => {
                    if let Role::Position { body } = g.symbol(*s).role {
                        let bits = if which == ALL { ALL } else { 1u8 << which };
                        match out.iter_mut().find(|e| e.0 == body) {
                            Some(e) => e.1 |= bits,
                            None => out.push((body, bits)),
                        }
                    }
                }
                Node::Vector(xs) => {
                    if which == ALL {
                        self.stack.extend(xs.iter().map(|&x| (x, ALL)));
                    } else if let Some(&x) = xs.get(which as usize) {
                        self.stack.push((x, ALL));
                    }
                }
                // A sum of vectors: its component d is the terms' component d.
                Node::Add(xs) => self.stack.extend(xs.iter().map(|&x| (x, which))),
                // A product: every scalar factor, and the vector factor's component d.
                Node::Mul(xs) => {
                    for &x in xs.iter() {
                        let w = if g.ty(x) == Ty::Vector { which } else { ALL };
                        self.stack.push((x, w));
                    }
                }
                Node::Comp(a, axis) => self.stack.push((*a, axis.index() as u8)),
                // perp([x, y]) = [−y, x].
                Node::Perp(u) => self.stack.push((*u, if which < 2 { which ^ 1 } else { ALL })),
                Node::Pow(_) | Node::Dot(_) | Node::Cross(_) | Node::Norm(_) | Node::Call(..) | Node::Rot(_) => {
                    self.stack.extend(node.children().iter().map(|&x| (x, ALL)));
                }
            }
        }
        out.sort_unstable();
        out
    }
}
