//! The expression graph: a hash-consed arena of typed nodes.
//!
//! Every node is stored once (`Graph::intern` returns the existing [`Id`] for an equal node),
//! children before parents, so equal subexpressions are shared and a derivative reuses the
//! structure of the expression it came from. Each node carries its type (scalar or vector
//! of the graph's dimension), fixed when it is built: the constructors here are the type
//! checker's last line of defence and refuse ill-typed nodes.
//!
//! Subtraction is `a + (-1)·b`, division is `a · b^-1` and negation is `(-1)·a`, so there
//! is one way to write each thing; printers turn them back into `-`, `/` and unary minus.
//!
//! Not here: parsing, simplification, printing (see the sibling modules).

use super::func::{Func, MAX_ARITY};
use super::num::Rational;
use super::work;
use smallvec::SmallVec;
use std::cmp::Ordering;
use std::collections::HashMap;
use std::fmt;
use std::hash::BuildHasher;

/// A `HashMap` for keys the file does not choose (node ids, hashes of seeded nodes):
/// foldhash with a fixed seed, the crate's one hash function (names use it seeded per
/// process, [`NameMap`]). Fixed, so a run's map orders do not vary from run to run; fast,
/// because std's SipHash was a tenth of a derivation's time.
pub type FastMap<K, V> = HashMap<K, V, foldhash::fast::FixedState>;

/// A `HashSet` for keys the file does not choose; see [`FastMap`].
pub type FastSet<K> = std::collections::HashSet<K, foldhash::fast::FixedState>;

/// A map keyed by names from the file (symbols, bodies, constraints): foldhash seeded at
/// random per process, not [`FastMap`]'s fixed seed, so a file cannot be crafted to make
/// every name collide and loading quadratic. (std's SipHash would do too, at 2 % of a
/// derivation.)
pub type NameMap<K, V> = HashMap<K, V, foldhash::fast::RandomState>;

/// A set of names from the file; see [`NameMap`].
pub type NameSet<K> = std::collections::HashSet<K, foldhash::fast::RandomState>;

/// A map from node ids to values, stored densely by id: ids are small consecutive
/// integers, so a vector indexed by id beats hashing them (and stays in cache on large
/// graphs, where a hash map's random probes made long chains superlinear in wall time).
#[derive(Clone, Debug)]
pub struct IdMap<V> {
    slots: Vec<Option<V>>,
}

impl<V> Default for IdMap<V> {
    fn default() -> Self {
        IdMap { slots: Vec::new() }
    }
}

impl<V> IdMap<V> {
    pub fn get(&self, id: &Id) -> Option<&V> {
        self.slots.get(id.index()).and_then(Option::as_ref)
    }

    pub fn contains_key(&self, id: &Id) -> bool {
        self.get(id).is_some()
    }

    pub fn insert(&mut self, id: Id, value: V) {
        let i = id.index();
        if i >= self.slots.len() {
            self.slots.resize_with((i + 1).max(2 * self.slots.len()), || None);
        }
        self.slots[i] = Some(value);
    }

    /// Inserts `value` unless `id` already has one.
    pub fn insert_if_absent(&mut self, id: Id, value: V) {
        if !self.contains_key(&id) {
            self.insert(id, value);
        }
    }
}

impl<V> std::ops::Index<&Id> for IdMap<V> {
    type Output = V;

    fn index(&self, id: &Id) -> &V {
        self.get(id).expect("no entry for this id")
    }
}

/// A set of indices (of nodes or symbols) with a value each, emptied in O(1): every entry
/// is stamped with the walk that wrote it, and [`Marks::clear`] starts a new walk. The
/// one mark-per-node implementation of the crate (the simplifier's walk, shapes, symbol
/// walks): a flag per node reused from walk to walk, instead of a fresh set per walk.
#[derive(Clone, Debug, Default)]
pub struct Marks<V = ()> {
    entries: Vec<(u32, V)>,
    /// The current walk; entries of other walks are absent. 0 before the first `clear`.
    stamp: u32,
}

impl<V: Copy + Default> Marks<V> {
    /// Empties the set: the start of a walk.
    pub fn clear(&mut self) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // After 2³² walks the stamps wrap: start them again.
            self.entries.iter_mut().for_each(|e| *e = (0, V::default()));
            self.stamp = 1;
        }
    }

    /// The value at `i`, if `i` was set in this walk.
    #[inline]
    pub fn get(&self, i: usize) -> Option<V> {
        match self.entries.get(i) {
            Some(&(stamp, v)) if stamp == self.stamp && stamp != 0 => Some(v),
            _ => None,
        }
    }

    #[inline]
    pub fn contains(&self, i: usize) -> bool {
        self.get(i).is_some()
    }

    /// Sets `i` to `v` in this walk.
    #[inline]
    pub fn set(&mut self, i: usize, v: V) {
        if i >= self.entries.len() {
            self.entries.resize((i + 1).max(2 * self.entries.len()), (0, V::default()));
        }
        self.entries[i] = (self.stamp, v);
    }

    /// Sets `i` (to the default value) unless it is set; whether it was new.
    #[inline]
    pub fn insert(&mut self, i: usize) -> bool {
        let new = !self.contains(i);
        if new {
            self.set(i, V::default());
        }
        new
    }
}

/// The symbols expressions depend on, with the walk's buffers kept from call to call, so
/// many calls on one graph cost their expressions' sizes and no hashing.
#[derive(Debug, Default)]
pub struct SymbolWalk {
    marks: Marks,
    stack: Vec<Id>,
    symbols: Vec<Symbol>,
}

impl SymbolWalk {
    /// The free symbols of `root`, sorted, each once.
    pub fn free_symbols(&mut self, g: &Graph, root: Id) -> &[Symbol] {
        self.free_symbols_of(g, &[root])
    }

    /// The free symbols of `roots` together, sorted, each once.
    pub fn free_symbols_of(&mut self, g: &Graph, roots: &[Id]) -> &[Symbol] {
        self.marks.clear();
        self.symbols.clear();
        self.stack.clear();
        self.stack.extend_from_slice(roots);
        let marks = &mut self.marks;
        walk_symbols(g, &mut self.stack, |id| marks.insert(id.index()), &mut self.symbols);
        &self.symbols
    }
}

/// The one walk for free symbols: every node reachable from `stack` that `first_visit`
/// lets through (it returns whether the node is new), its symbols into `out`, sorted and
/// each once.
fn walk_symbols(g: &Graph, stack: &mut Vec<Id>, mut first_visit: impl FnMut(Id) -> bool, out: &mut Vec<Symbol>) {
    while let Some(id) = stack.pop() {
        if !first_visit(id) {
            continue;
        }
        match g.node(id) {
            Node::Sym(s) => out.push(*s),
            node => stack.extend_from_slice(node.children()),
        }
    }
    out.sort_unstable();
    out.dedup();
}

/// A handle to a node of a [`Graph`]. Children always have smaller ids than parents.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub struct Id(u32);

impl Id {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// A handle to an interned symbol.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub struct Symbol(u32);

impl Symbol {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// The type of a node.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Ty {
    Scalar,
    Vector,
}

impl fmt::Display for Ty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Ty::Scalar => "a scalar",
            Ty::Vector => "a vector",
        })
    }
}

/// A coordinate axis, for components `a.x` and unit vectors.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        ["x", "y", "z"][self.index()]
    }
}

/// What a symbol stands for; this decides its time derivative and its place in sorted order.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug)]
pub enum Role {
    /// The time `t`: dt/dt = 1.
    Time,
    /// A constant of the scene.
    Parameter,
    /// A body's position; its derivative is the body's velocity symbol.
    Position { body: usize },
    /// A body's velocity; its derivative is the body's acceleration symbol.
    Velocity { body: usize },
    /// A body's acceleration; its time derivative is not defined here.
    Acceleration { body: usize },
    /// A body's external force; appears in forces and multipliers, never differentiated.
    Force { body: usize },
    /// A body's mass: a constant.
    Mass { body: usize },
    /// A rigid body's orientation (2D: the angle θ; 3D: a unit quaternion, typed scalar,
    /// read only by `rot`); its derivative is the angular velocity (in 3D only `rot`'s
    /// d/dt uses it: d rot(q, s)/dt = ω × rot(q, s)).
    Orientation { body: usize },
    /// A rigid body's angular velocity ω; its derivative is the angular acceleration.
    AngularVelocity { body: usize },
    /// A rigid body's angular acceleration α; its time derivative is not defined here.
    AngularAcceleration { body: usize },
    /// A rigid body's external torque; like a force, never differentiated.
    Torque { body: usize },
    /// A rigid body's moment of inertia: a constant.
    Inertia { body: usize },
}

impl Role {
    /// Sort rank: forces, then positions, velocities, accelerations, then the rest, so that
    /// `dot(v, r)` is written `r·v` and `F·r` reads as in the article.
    pub(super) fn rank(self) -> (u8, usize) {
        match self {
            Role::Force { body } | Role::Torque { body } => (0, body),
            Role::Position { body } | Role::Orientation { body } => (1, body),
            Role::Velocity { body } | Role::AngularVelocity { body } => (2, body),
            Role::Acceleration { body } | Role::AngularAcceleration { body } => (3, body),
            Role::Mass { body } | Role::Inertia { body } => (4, body),
            Role::Parameter => (5, 0),
            Role::Time => (6, 0),
        }
    }
}

/// An interned symbol: its name, type and role.
#[derive(Clone, Debug)]
pub struct SymbolInfo {
    pub name: String,
    pub ty: Ty,
    pub role: Role,
    /// The symbol its time derivative is, for positions and velocities (and orientations
    /// and angular velocities).
    pub derivative: Option<Symbol>,
}

/// A node of the graph. Operand lists of `Add` and `Mul` have at least two entries.
#[derive(Clone, PartialEq, Eq, Hash, Debug)]
pub enum Node {
    Num(Rational),
    Sym(Symbol),
    /// A vector literal `[e1, e2]` or `[e1, e2, e3]` (as many entries as the dimension).
    Vector(Box<[Id]>),
    /// A sum of scalars, or of vectors.
    Add(Box<[Id]>),
    /// A product of scalars, with at most one vector factor, which comes last.
    Mul(Box<[Id]>),
    /// `[base, exponent]`, scalars.
    Pow([Id; 2]),
    Dot([Id; 2]),
    /// A vector in 3D; in 2D the scalar z-part `a.x b.y − a.y b.x`.
    Cross([Id; 2]),
    Norm(Id),
    Comp(Id, Axis),
    /// A function of the table in `func` over its arguments: the first `arity` slots; the
    /// others repeat the first argument ([`Func::slots`]), so equal calls are equal nodes.
    Call(Func, [Id; MAX_ARITY]),
    /// `rot(θ, s)`: the body-frame vector `s` (constant in time) turned by the orientation
    /// θ into world coordinates, R(θ) s. 2D: θ is a scalar angle; 3D: θ is a unit
    /// quaternion symbol ([`Graph::is_quaternion`]), whose only use is here.
    Rot([Id; 2]),
    /// `perp(u)` in 2D: `u` turned a quarter turn counter-clockwise, [−u.y, u.x].
    Perp(Id),
}

impl Node {
    /// The direct children, in order.
    #[inline]
    pub fn children(&self) -> &[Id] {
        match self {
            Node::Num(_) | Node::Sym(_) => &[],
            Node::Vector(xs) | Node::Add(xs) | Node::Mul(xs) => xs,
            Node::Pow(ab) | Node::Dot(ab) | Node::Cross(ab) | Node::Rot(ab) => ab,
            Node::Norm(a) | Node::Comp(a, _) | Node::Perp(a) => std::slice::from_ref(a),
            Node::Call(f, args) => &args[..f.arity()],
        }
    }

    /// The same kind of node over the children `f` maps these to (leaves are cloned).
    pub fn map_children(&self, mut f: impl FnMut(Id) -> Id) -> Node {
        match self {
            Node::Num(_) | Node::Sym(_) => self.clone(),
            Node::Vector(xs) => Node::Vector(xs.iter().map(|&x| f(x)).collect()),
            Node::Add(xs) => Node::Add(xs.iter().map(|&x| f(x)).collect()),
            Node::Mul(xs) => Node::Mul(xs.iter().map(|&x| f(x)).collect()),
            Node::Pow([a, b]) => Node::Pow([f(*a), f(*b)]),
            Node::Dot([a, b]) => Node::Dot([f(*a), f(*b)]),
            Node::Cross([a, b]) => Node::Cross([f(*a), f(*b)]),
            Node::Norm(a) => Node::Norm(f(*a)),
            Node::Comp(a, axis) => Node::Comp(f(*a), *axis),
            Node::Rot([a, b]) => Node::Rot([f(*a), f(*b)]),
            Node::Perp(a) => Node::Perp(f(*a)),
            Node::Call(func, args) => {
                let mut mapped = *args;
                for slot in &mut mapped[..func.arity()] {
                    *slot = f(*slot);
                }
                Node::Call(*func, func.slots(&mapped[..func.arity()], NO_ID))
            }
        }
    }

    /// The same kind of node over `kids` (as many as [`Node::children`], in order).
    pub fn with_children(&self, kids: &[Id]) -> Node {
        let mut next = kids.iter().copied();
        self.map_children(|old| next.next().unwrap_or(old))
    }

    /// The node kind's place in the canonical order of nodes ([`Graph::cmp_nodes`]): atoms
    /// people read first (numbers, symbols, components) sort before compound nodes. Also
    /// the kind's tag in a shape's key (`shape`).
    pub fn rank(&self) -> u8 {
        match self {
            Node::Num(_) => 0,
            Node::Sym(_) => 1,
            Node::Comp(..) => 2,
            Node::Dot(..) => 3,
            Node::Cross(..) => 4,
            Node::Norm(_) => 5,
            Node::Call(..) => 6,
            Node::Pow(..) => 7,
            Node::Mul(_) => 8,
            Node::Add(_) => 9,
            Node::Vector(_) => 10,
            Node::Rot(_) => 11,
            Node::Perp(_) => 12,
        }
    }
}

/// The filler of a nullary call's slots (never read: [`Node::children`] is empty).
const NO_ID: Id = Id(0);

/// Why a node could not be built: the type rules of the expression language.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TypeError {
    #[error("expected a scalar here, found a vector")]
    ExpectedScalar,
    #[error("expected a vector here, found a scalar")]
    ExpectedVector,
    #[error("cannot add a scalar and a vector")]
    MixedSum,
    #[error("cannot multiply a vector by a vector: use dot(a, b) or cross(a, b)")]
    VectorProduct,
    #[error("cannot divide by a vector")]
    DivideByVector,
    #[error("a vector literal in a {dim}D file needs {dim} entries, found {found}")]
    VectorLength { dim: usize, found: usize },
    #[error("component `{axis}` does not exist in a 2D file")]
    NoZComponent { axis: &'static str },
    #[error("cannot compare a vector with a scalar")]
    MixedRelation,
    #[error("`{name}` takes {expected} argument(s), found {found}")]
    Arity { name: &'static str, expected: usize, found: usize },
    #[error("`{name}` exists only in 2D files for now")]
    OnlyIn2d { name: &'static str },
    /// Simplifying one formula passed the work budget
    /// ([`MAX_FORM_WORK`](crate::expr::simplify::MAX_FORM_WORK) terms of canonical forms).
    #[error("too large to simplify: more than {0} terms of work on one formula")]
    TooLarge(u64),
}

/// The arena. `dim` is the dimension of every vector in it (2 or 3).
#[derive(Clone, Debug)]
pub struct Graph {
    dim: usize,
    nodes: Vec<Node>,
    tys: Vec<Ty>,
    depths: Vec<u32>,
    /// Hash-consing index: a node's hash → the newest node with that hash; `same_hash`
    /// chains to older ones. Nodes are stored once, in `nodes` (no clone as a map key).
    index: FastMap<u64, Id>,
    same_hash: Vec<Option<Id>>,
    /// Each symbol's node, once made (looked up for every symbol a renaming writes).
    sym_nodes: Vec<Option<Id>>,
    /// Hashes nodes for `index`, seeded per graph: nodes hold numbers from the file, and an
    /// unkeyed hash would let a crafted file make them all collide.
    seed: foldhash::fast::RandomState,
    symbols: Vec<SymbolInfo>,
    by_name: NameMap<String, Symbol>,
}

impl Graph {
    /// An empty graph for vectors of `dim` components (2 or 3).
    pub fn new(dim: usize) -> Graph {
        assert!(dim == 2 || dim == 3, "dimension must be 2 or 3");
        let mut g = Graph {
            dim,
            nodes: Vec::new(),
            tys: Vec::new(),
            depths: Vec::new(),
            index: FastMap::default(),
            same_hash: Vec::new(),
            sym_nodes: Vec::new(),
            seed: foldhash::fast::RandomState::default(),
            symbols: Vec::new(),
            by_name: NameMap::default(),
        };
        // The article's bead derives in about 200 nodes: room for a small scene at once,
        // instead of growing (and rehashing) through every power of two up to it.
        g.reserve(256);
        g
    }

    /// Room for `additional` more nodes, so a graph grown by a known amount (a derivation of
    /// many constraints) is not copied and rehashed on the way.
    pub fn reserve(&mut self, additional: usize) {
        self.nodes.reserve(additional);
        self.tys.reserve(additional);
        self.depths.reserve(additional);
        self.same_hash.reserve(additional);
        self.index.reserve(additional);
    }

    pub fn dim(&self) -> usize {
        self.dim
    }

    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    pub fn node(&self, id: Id) -> &Node {
        &self.nodes[id.index()]
    }

    pub fn ty(&self, id: Id) -> Ty {
        self.tys[id.index()]
    }

    /// Height above the leaves (a leaf is 1).
    pub fn depth(&self, id: Id) -> u32 {
        self.depths[id.index()]
    }

    // ---- symbols ----------------------------------------------------------------------

    /// Declares a symbol, or returns the existing one of that name.
    ///
    /// The name must be new or declared with the same type and role.
    pub fn declare(&mut self, name: &str, ty: Ty, role: Role) -> Symbol {
        if let Some(&s) = self.by_name.get(name) {
            debug_assert_eq!(self.symbols[s.index()].ty, ty);
            return s;
        }
        let s = Symbol(self.symbols.len() as u32);
        self.symbols.push(SymbolInfo { name: name.to_string(), ty, role, derivative: None });
        self.by_name.insert(name.to_string(), s);
        s
    }

    /// Records that `d/dt of` is `derivative` (position → velocity → acceleration).
    pub fn set_derivative(&mut self, of: Symbol, derivative: Symbol) {
        self.symbols[of.index()].derivative = Some(derivative);
    }

    pub fn symbol(&self, s: Symbol) -> &SymbolInfo {
        &self.symbols[s.index()]
    }

    pub fn symbol_named(&self, name: &str) -> Option<Symbol> {
        self.by_name.get(name).copied()
    }

    pub fn symbols(&self) -> impl Iterator<Item = (Symbol, &SymbolInfo)> {
        self.symbols.iter().enumerate().map(|(i, s)| (Symbol(i as u32), s))
    }

    // ---- interning --------------------------------------------------------------------

    /// Stores `node` once and returns its id; `ty` must be the node's type.
    fn intern(&mut self, node: Node, ty: Ty) -> Id {
        let hash = self.seed.hash_one(&node);
        if let Some(id) = self.lookup(hash, &node) {
            return id;
        }
        let depth = node.children().iter().map(|c| self.depths[c.index()]).max().unwrap_or(0) + 1;
        let id = Id(self.nodes.len() as u32);
        self.nodes.push(node);
        self.tys.push(ty);
        self.depths.push(depth);
        self.same_hash.push(self.index.insert(hash, id));
        id
    }

    fn lookup(&self, hash: u64, node: &Node) -> Option<Id> {
        let mut next = self.index.get(&hash).copied();
        while let Some(id) = next {
            if self.nodes[id.index()] == *node {
                return Some(id);
            }
            next = self.same_hash[id.index()];
        }
        None
    }

    // ---- typed constructors ------------------------------------------------------------

    pub fn num(&mut self, q: Rational) -> Id {
        self.intern(Node::Num(q), Ty::Scalar)
    }

    pub fn int(&mut self, n: i64) -> Id {
        self.num(Rational::int(n))
    }

    pub fn sym(&mut self, s: Symbol) -> Id {
        if let Some(&Some(id)) = self.sym_nodes.get(s.index()) {
            return id;
        }
        let ty = self.symbols[s.index()].ty;
        let id = self.intern(Node::Sym(s), ty);
        if self.sym_nodes.len() <= s.index() {
            self.sym_nodes.resize(self.symbols.len().max(s.index() + 1), None);
        }
        self.sym_nodes[s.index()] = Some(id);
        id
    }

    /// The constant as a rational, when `id` is a number node.
    pub fn as_num(&self, id: Id) -> Option<&Rational> {
        match self.node(id) {
            Node::Num(q) => Some(q),
            _ => None,
        }
    }

    /// The zero vector `[0, 0]` or `[0, 0, 0]`.
    pub fn zero_vector(&mut self) -> Id {
        let zero = self.int(0);
        let entries = vec![zero; self.dim];
        self.intern(Node::Vector(entries.into()), Ty::Vector)
    }

    /// Whether `id` is the number 0 or the zero vector literal.
    pub fn is_zero(&self, id: Id) -> bool {
        match self.node(id) {
            Node::Num(q) => q.is_zero(),
            Node::Vector(xs) => xs.iter().all(|&x| self.is_zero(x)),
            _ => false,
        }
    }

    pub fn vector(&mut self, entries: Vec<Id>) -> Result<Id, TypeError> {
        self.make(Node::Vector(entries.into()))
    }

    /// The sum of `terms`, all scalars or all vectors. One term is returned as is.
    pub fn add(&mut self, terms: Vec<Id>) -> Result<Id, TypeError> {
        match terms.len() {
            0 => Ok(self.int(0)),
            1 => Ok(terms[0]),
            _ => self.make(Node::Add(terms.into())),
        }
    }

    /// The product of `factors`: scalars with at most one vector, which is moved last.
    pub fn mul(&mut self, mut factors: Vec<Id>) -> Result<Id, TypeError> {
        let vectors = factors.iter().filter(|&&f| self.ty(f) == Ty::Vector).count();
        if vectors > 1 {
            return Err(TypeError::VectorProduct);
        }
        if vectors == 1 {
            let i = factors.iter().position(|&f| self.ty(f) == Ty::Vector).unwrap_or(0);
            let v = factors.remove(i);
            factors.push(v);
        }
        match factors.len() {
            0 => Ok(self.int(1)),
            1 => Ok(factors[0]),
            // `type_of`'s rule for products, already checked by the count above (products
            // are the commonest node a derivation builds: one pass over them, not two).
            _ => {
                let ty = if vectors == 1 { Ty::Vector } else { Ty::Scalar };
                Ok(self.intern(Node::Mul(factors.into()), ty))
            }
        }
    }

    pub fn neg(&mut self, a: Id) -> Id {
        let minus_one = self.int(-1);
        // Cannot fail: -1 is a scalar and `a` is the only other factor.
        self.mul(vec![minus_one, a]).unwrap_or(a)
    }

    pub fn sub(&mut self, a: Id, b: Id) -> Result<Id, TypeError> {
        let nb = self.neg(b);
        self.add(vec![a, nb])
    }

    pub fn div(&mut self, a: Id, b: Id) -> Result<Id, TypeError> {
        if self.ty(b) == Ty::Vector {
            return Err(TypeError::DivideByVector);
        }
        let minus_one = self.int(-1);
        let inv = self.pow(b, minus_one)?;
        self.mul(vec![a, inv])
    }

    pub fn pow(&mut self, base: Id, exponent: Id) -> Result<Id, TypeError> {
        self.make(Node::Pow([base, exponent]))
    }

    pub fn powi(&mut self, base: Id, n: i64) -> Result<Id, TypeError> {
        let e = self.int(n);
        self.pow(base, e)
    }

    pub fn dot(&mut self, a: Id, b: Id) -> Result<Id, TypeError> {
        self.make(Node::Dot([a, b]))
    }

    pub fn cross(&mut self, a: Id, b: Id) -> Result<Id, TypeError> {
        self.make(Node::Cross([a, b]))
    }

    pub fn norm(&mut self, a: Id) -> Result<Id, TypeError> {
        self.make(Node::Norm(a))
    }

    pub fn comp(&mut self, a: Id, axis: Axis) -> Result<Id, TypeError> {
        self.make(Node::Comp(a, axis))
    }

    /// `rot(θ, s)`: `s` in world coordinates (the checks that θ is an orientation and `s`
    /// constant in time are the lowering's, which knows the spans).
    pub fn rot(&mut self, theta: Id, s: Id) -> Result<Id, TypeError> {
        self.make(Node::Rot([theta, s]))
    }

    /// Whether `s` is a 3D orientation: a unit quaternion [w, x, y, z], four numbers in a
    /// state, which the graph types as a scalar and which only `rot` may read.
    pub fn is_quaternion(&self, s: Symbol) -> bool {
        self.dim == 3 && matches!(self.symbols[s.index()].role, Role::Orientation { .. })
    }

    /// `perp(u)` = [−u.y, u.x] (2D).
    pub fn perp(&mut self, u: Id) -> Result<Id, TypeError> {
        self.make(Node::Perp(u))
    }

    /// `f(args)`, with as many arguments as `f` takes ([`Func::signature`]).
    pub fn call(&mut self, f: Func, args: &[Id]) -> Result<Id, TypeError> {
        if args.len() != f.arity() {
            return Err(TypeError::Arity { name: f.name(), expected: f.arity(), found: args.len() });
        }
        self.make(Node::Call(f, f.slots(args, NO_ID)))
    }

    /// Stores `node` once, if it is well typed.
    fn make(&mut self, node: Node) -> Result<Id, TypeError> {
        let ty = self.type_of(&node)?;
        Ok(self.intern(node, ty))
    }

    /// The type rules of the expression language: the type of `node`, whose children are
    /// in this graph, or why it has none.
    fn type_of(&self, node: &Node) -> Result<Ty, TypeError> {
        let expect = |ids: &[Id], ty: Ty| match ids.iter().find(|&&id| self.ty(id) != ty) {
            None => Ok(()),
            Some(_) if ty == Ty::Scalar => Err(TypeError::ExpectedScalar),
            Some(_) => Err(TypeError::ExpectedVector),
        };
        Ok(match node {
            Node::Num(_) => Ty::Scalar,
            Node::Sym(s) => self.symbols[s.index()].ty,
            Node::Vector(xs) => {
                if xs.len() != self.dim {
                    return Err(TypeError::VectorLength { dim: self.dim, found: xs.len() });
                }
                expect(xs, Ty::Scalar)?;
                Ty::Vector
            }
            Node::Add(xs) => {
                let ty = self.ty(xs[0]);
                if xs.iter().any(|&t| self.ty(t) != ty) {
                    return Err(TypeError::MixedSum);
                }
                ty
            }
            Node::Mul(xs) => match xs.iter().filter(|&&f| self.ty(f) == Ty::Vector).count() {
                0 => Ty::Scalar,
                1 => Ty::Vector,
                _ => return Err(TypeError::VectorProduct),
            },
            Node::Pow(ab) => {
                expect(ab, Ty::Scalar)?;
                Ty::Scalar
            }
            Node::Dot(ab) => {
                expect(ab, Ty::Vector)?;
                Ty::Scalar
            }
            Node::Cross(ab) => {
                expect(ab, Ty::Vector)?;
                if self.dim == 3 { Ty::Vector } else { Ty::Scalar }
            }
            Node::Norm(a) => {
                expect(std::slice::from_ref(a), Ty::Vector)?;
                Ty::Scalar
            }
            Node::Comp(a, axis) => {
                expect(std::slice::from_ref(a), Ty::Vector)?;
                if axis.index() >= self.dim {
                    return Err(TypeError::NoZComponent { axis: axis.name() });
                }
                Ty::Scalar
            }
            Node::Call(f, _) => {
                let (args, result) = f.signature();
                for (&arg, &ty) in node.children().iter().zip(args) {
                    expect(&[arg], ty)?;
                }
                result
            }
            Node::Rot([theta, s]) => {
                // 3D: the quaternion symbol has the scalar type (it is no vector of the
                // file's dimension); the lowering allows it nowhere else.
                expect(&[*theta], Ty::Scalar)?;
                expect(&[*s], Ty::Vector)?;
                Ty::Vector
            }
            Node::Perp(a) => {
                if self.dim != 2 {
                    return Err(TypeError::OnlyIn2d { name: "perp" });
                }
                expect(std::slice::from_ref(a), Ty::Vector)?;
                Ty::Vector
            }
        })
    }

    /// `node` over other children (as many, in order), type-checked (used by rewriters).
    ///
    /// Rewriters only ever map a child to a node of the same type, so this cannot fail for
    /// well-typed input; a mismatch is reported rather than ignored.
    pub fn rebuild(&mut self, node: &Node, kids: &[Id]) -> Result<Id, TypeError> {
        self.make(node.with_children(kids))
    }

    /// The node `like` over other children of the same types (a renaming of its symbols,
    /// `expr::shape`), interned with `like`'s type and no type checks.
    pub fn renamed_node(&mut self, like: Id, kids: &[Id]) -> Id {
        debug_assert!(self.node(like).children().iter().zip(kids).all(|(a, b)| self.ty(*a) == self.ty(*b)));
        if kids.is_empty() {
            return like;
        }
        let node = self.node(like).with_children(kids);
        let ty = self.ty(like);
        self.intern(node, ty)
    }

    // ---- traversal ---------------------------------------------------------------------

    /// Every node reachable from `roots`, in increasing id order (children before parents).
    ///
    /// Iterative, so deep graphs cannot overflow the stack.
    /// The visited set is a hash set, not a flag per node of the graph: its cost is the
    /// size of the answer, not of the graph (a 1000-link chain calls this thousands of
    /// times on a graph of ~10⁵ nodes).
    pub fn reachable(&self, roots: &[Id]) -> Vec<Id> {
        // Room for a small formula's nodes up front: growing the set rehashes it each time
        // (without it, 4 % more instructions in the bead's derivation, callgrind).
        let mut seen: FastSet<Id> = FastSet::with_capacity_and_hasher(64, Default::default());
        let mut stack: Vec<Id> = roots.to_vec();
        let mut out = Vec::with_capacity(64);
        while let Some(id) = stack.pop() {
            if !seen.insert(id) {
                continue;
            }
            out.push(id);
            stack.extend_from_slice(self.node(id).children());
        }
        out.sort_unstable();
        out
    }

    /// The symbols that `root` depends on, sorted, each once.
    ///
    /// The visited set is a hash set, so one call costs the size of the expression, not of
    /// the graph; [`SymbolWalk`] keeps its buffers for many calls.
    pub fn free_symbols(&self, root: Id) -> Vec<Symbol> {
        let mut seen: FastSet<Id> = FastSet::default();
        let mut syms = Vec::new();
        walk_symbols(self, &mut vec![root], |id| seen.insert(id), &mut syms);
        syms
    }

    /// Replaces every occurrence of the nodes in `map` (keys) by their values, bottom-up.
    pub fn substitute<S: BuildHasher>(&mut self, root: Id, map: &HashMap<Id, Id, S>) -> Result<Id, TypeError> {
        self.substitute_memo(root, map, &mut FastMap::default())
    }

    /// [`Graph::substitute`] for many roots under one `map`: `memo` keeps each node's
    /// replacement between calls, so nodes the roots share (λ in every body's force) are
    /// visited once, not once per root. `memo` must only ever be used with the same `map`.
    pub fn substitute_memo<S: BuildHasher>(
        &mut self,
        root: Id,
        map: &HashMap<Id, Id, S>,
        memo: &mut FastMap<Id, Id>,
    ) -> Result<Id, TypeError> {
        // The nodes under `root` not yet replaced; sorted, children come first (a node's
        // children are interned before it).
        let mut seen: FastSet<Id> = FastSet::default();
        let mut stack = vec![root];
        let mut order = Vec::new();
        while let Some(id) = stack.pop() {
            if memo.contains_key(&id) || !seen.insert(id) {
                continue;
            }
            order.push(id);
            stack.extend_from_slice(self.node(id).children());
        }
        order.sort_unstable();
        for id in order {
            let replaced = match map.get(&id) {
                Some(&to) => to,
                None => self.rebuilt(id, memo)?,
            };
            memo.insert(id, replaced);
        }
        Ok(memo[&root])
    }

    /// `id` over the children `new` maps its children to (itself when none changed).
    fn rebuilt(&mut self, id: Id, new: &FastMap<Id, Id>) -> Result<Id, TypeError> {
        let children = self.node(id).children();
        if children.iter().all(|c| new[c] == *c) {
            return Ok(id);
        }
        let kids: SmallVec<[Id; 4]> = children.iter().map(|c| new[c]).collect();
        let node = self.node(id).clone();
        self.rebuild(&node, &kids)
    }

    // ---- canonical order ---------------------------------------------------------------

    /// A total order on nodes that depends only on their structure and symbol names, never
    /// on ids, so that a canonical form is the same whatever order things were built in.
    pub fn cmp_nodes(&self, a: Id, b: Id) -> Ordering {
        // A node is equal to itself (hash-consed): the common case of sorting factors.
        if a == b {
            return Ordering::Equal;
        }
        /// A comparison still to make: two nodes, or an outcome decided once the pairs
        /// pushed above it are equal (a component's axis, a list's length).
        enum Step {
            Pair(Id, Id),
            Then(Ordering),
        }
        // Depth-first in the order the comparison reads them, on a heap stack: the first
        // unequal pair decides, as a recursion would, but no depth overflows the thread's
        // stack, and each pair visited is charged to the simplifier's work meter.
        let mut todo: SmallVec<[Step; 16]> = smallvec::smallvec![Step::Pair(a, b)];
        while let Some(step) = todo.pop() {
            let (a, b) = match step {
                Step::Then(Ordering::Equal) => continue,
                Step::Then(o) => return o,
                Step::Pair(a, b) if a == b => continue,
                Step::Pair(a, b) => (a, b),
            };
            work::charge(1);
            let (na, nb) = (self.node(a), self.node(b));
            let head = na.rank().cmp(&nb.rank()).then_with(|| match (na, nb) {
                (Node::Num(x), Node::Num(y)) => x.cmp(y),
                (Node::Sym(x), Node::Sym(y)) => self.cmp_symbols(*x, *y),
                (Node::Call(f, _), Node::Call(g, _)) => f.cmp(g),
                _ => Ordering::Equal,
            });
            if head != Ordering::Equal {
                return head;
            }
            match (na, nb) {
                (Node::Comp(x, i), Node::Comp(y, j)) => {
                    todo.push(Step::Then(i.cmp(j)));
                    todo.push(Step::Pair(*x, *y));
                }
                // Dot products sort by their later operand first, so `v·v` comes before `r·a`.
                (Node::Dot([x1, x2]), Node::Dot([y1, y2])) => {
                    todo.push(Step::Pair(*x1, *y1));
                    todo.push(Step::Pair(*x2, *y2));
                }
                _ => {
                    let (xs, ys) = (na.children(), nb.children());
                    todo.push(Step::Then(xs.len().cmp(&ys.len())));
                    todo.extend(xs.iter().zip(ys).rev().map(|(x, y)| Step::Pair(*x, *y)));
                }
            }
        }
        Ordering::Equal
    }

    /// Symbols sort by role (forces, positions, velocities, …), then body, then name.
    pub fn cmp_symbols(&self, a: Symbol, b: Symbol) -> Ordering {
        let (sa, sb) = (self.symbol(a), self.symbol(b));
        sa.role.rank().cmp(&sb.role.rank()).then_with(|| natural_cmp(&sa.name, &sb.name))
    }
}

/// Compares names with digit runs as numbers, so `l2 < l10`.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut x, mut y) = (a.as_bytes(), b.as_bytes());
    while let (Some(&cx), Some(&cy)) = (x.first(), y.first()) {
        if cx.is_ascii_digit() && cy.is_ascii_digit() {
            let nx = x.iter().take_while(|c| c.is_ascii_digit()).count();
            let ny = y.iter().take_while(|c| c.is_ascii_digit()).count();
            let (dx, dy) = (trim_zeros(&x[..nx]), trim_zeros(&y[..ny]));
            let o = dx.len().cmp(&dy.len()).then_with(|| dx.cmp(dy));
            if o != Ordering::Equal {
                return o;
            }
            x = &x[nx..];
            y = &y[ny..];
        } else {
            if cx != cy {
                return cx.cmp(&cy);
            }
            x = &x[1..];
            y = &y[1..];
        }
    }
    x.len().cmp(&y.len()).then_with(|| a.cmp(b))
}

fn trim_zeros(d: &[u8]) -> &[u8] {
    let k = d.iter().take_while(|&&c| c == b'0').count();
    &d[k..]
}
