//! The resolved system: bodies, parameters and constraints as graph nodes, ready to derive.
//!
//! A [`System`] is built only through [`SystemBuilder`], which declares every symbol with
//! its role (position → velocity → acceleration, force, mass, parameter, `t`), refuses name
//! clashes, and parses and type-checks each constraint in scope. Files are one way to
//! fill a builder (`model::file`); tests and benchmarks fill it directly.
//!
//! Not here: TOML, numbers for solving (`model::file` keeps those), derivation (`derive`).

use crate::expr::graph::{NameSet, SymbolWalk};
use crate::expr::lower::{LowerError, LoweredRelation, Scope, is_function_name, lower, lower_relation};
use crate::expr::parse::{ParseError, parse_expr, parse_relation};
use crate::expr::{Graph, Id, Node, Role, Simplifier, Symbol, Ty};
use std::fmt;
use std::sync::Arc;

/// A point mass.
#[derive(Clone, Debug)]
pub struct Body {
    pub name: String,
    pub position: Symbol,
    pub velocity: Symbol,
    pub acceleration: Symbol,
    pub force: Symbol,
    /// A mass symbol or a number.
    pub mass: Id,
    /// The nodes of the body's symbols, made when they were declared: valid in the system's
    /// graph and in every graph that extends it (a derivation's), so no one needs to make them.
    pub nodes: BodyNodes,
    /// The rotational part of a rigid body (one with an `orientation`); `None` for a point mass.
    pub rigid: Option<Rigid>,
}

/// What a rigid body adds to a point mass (2D: scalar angle, angular velocity and
/// acceleration, inertia and torque; 3D: a quaternion, world-frame vectors ω, α and τ, and
/// the principal moments as a vector).
#[derive(Clone, Debug)]
pub struct Rigid {
    pub orientation: Symbol,
    pub angular_velocity: Symbol,
    pub angular_acceleration: Symbol,
    pub torque: Symbol,
    /// The moment of inertia about the centre of mass: a symbol or a number (3D: the
    /// principal moments, a vector symbol or literal).
    pub inertia: Id,
    pub nodes: RigidNodes,
}

/// The nodes of a rigid body's rotational symbols.
#[derive(Clone, Copy, Debug)]
pub struct RigidNodes {
    pub orientation: Id,
    pub angular_velocity: Id,
    pub angular_acceleration: Id,
    pub torque: Id,
    /// 3D: the body's principal axes in the world, `rot(q, eₖ)` for k = x, y, z (the
    /// columns of R(q)); `None` in 2D.
    pub axes: Option<[Id; 3]>,
}

/// The nodes of a body's symbols.
#[derive(Clone, Copy, Debug)]
pub struct BodyNodes {
    pub position: Id,
    pub velocity: Id,
    pub acceleration: Id,
    pub force: Id,
}

/// A position constraint `C = 0` or `C ≥ 0`.
#[derive(Clone, Debug)]
pub struct Constraint {
    pub name: String,
    /// As written in the file.
    pub text: String,
    /// `C` with definitions substituted, as lowered (not yet simplified).
    pub c: Id,
    pub inequality: bool,
    /// Indices of the bodies whose positions `C` depends on.
    pub bodies: Vec<usize>,
}

/// Bodies and constraints over one expression graph.
#[derive(Debug)]
pub struct System {
    pub title: String,
    pub graph: Graph,
    pub simplifier: Simplifier,
    pub bodies: Vec<Body>,
    pub constraints: Vec<Constraint>,
    /// Parameters in declaration order, with their types.
    pub parameters: Vec<(String, Symbol)>,
    /// `[definitions]` in the order they were declared, each with its lowered node (what
    /// every use of the name is); documents print the name for it (`report::derivation`).
    pub definitions: Vec<(String, Id)>,
    pub time: Symbol,
    pub scope: Scope,
}

impl System {
    /// Per body, the expression `pairs` gives it first — a scene's forces or torques,
    /// `(body, expression)` (`model::scene::Scene`) — found in one pass over them (a search
    /// per body is quadratic in a big scene); `None` where none is given. A body index past
    /// the system's bodies is ignored.
    pub fn by_body(&self, pairs: &[(usize, Id)]) -> Vec<Option<Id>> {
        let mut given = vec![None; self.bodies.len()];
        // Backwards, so that the first pair of a body is the one left.
        for &(body, expr) in pairs.iter().rev() {
            if let Some(slot) = given.get_mut(body) {
                *slot = Some(expr);
            }
        }
        given
    }

    pub fn dim(&self) -> usize {
        self.graph.dim()
    }

    /// Whether some body is rigid (has an orientation).
    pub fn has_rigid_bodies(&self) -> bool {
        self.bodies.iter().any(|b| b.rigid.is_some())
    }

    pub fn body_named(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    pub fn constraint_named(&self, name: &str) -> Option<usize> {
        self.constraints.iter().position(|c| c.name == name)
    }

    /// Parses and type-checks an expression in the system's scope (for expectations, forces).
    pub fn expression(&mut self, text: &str) -> Result<Id, BuildError> {
        let syntax = parse_expr(text).map_err(|e| BuildError::Parse { context: String::new(), error: e })?;
        lower(&syntax, &self.scope, &mut self.graph).map_err(|e| BuildError::Lower { context: String::new(), error: e })
    }
}

/// What the builder refuses.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BuildError {
    #[error("the dimension must be 2 or 3, found {0}")]
    Dimension(i64),
    #[error("`{name}` is declared twice (as {first} and as {second})")]
    Duplicate { name: String, first: String, second: String },
    #[error("`{0}` is reserved (a function or the time `t`)")]
    Reserved(String),
    #[error("`{0}` is not a valid name: use letters, digits and `_`, starting with a letter")]
    BadName(String),
    #[error("{context}{error}")]
    Parse { context: String, error: ParseError },
    #[error("{context}{error}")]
    Lower { context: String, error: LowerError },
    #[error("constraint `{0}` does not involve the position of any body")]
    NoBody(String),
    #[error("constraint `{name}` uses `{symbol}`: constraints may depend on positions, parameters and t only")]
    NotPositional { name: String, symbol: String },
    #[error("body `{0}` is declared rigid twice")]
    RigidTwice(String),
    #[error("the mass of body `{0}` is a number or a scalar symbol, not a vector")]
    VectorMass(String),
    /// A 2D rigid body's inertia written as three principal moments.
    #[error(
        "body `{0}` is in a 2D file, where the inertia is one number (the moment about the centre of mass), not principal moments [I1, I2, I3]"
    )]
    PrincipalInertia2d(String),
    /// A 3D rigid body's inertia written as one number or a scalar symbol.
    #[error(
        "body `{0}` is in a 3D file, where the inertia is the principal moments [I1, I2, I3] in the body frame (a vector literal or a vector symbol), not one number"
    )]
    ScalarInertia3d(String),
}

/// A number of the file as an exact constant node.
fn exact_number(g: &mut crate::expr::Graph, x: f64) -> Result<Id, BuildError> {
    let q =
        crate::expr::Rational::parse_decimal(&format!("{x:e}")).ok_or_else(|| BuildError::BadName(format!("{x}")))?;
    Ok(g.num(q))
}

/// Fills a [`System`] one declaration at a time.
#[derive(Debug)]
pub struct SystemBuilder {
    system: System,
    /// What each symbol was declared as (by the symbol's index), for clash messages and
    /// [`SystemBuilder::is_constant`]. Whether a name is taken is the scope's to say (every
    /// claimed name enters it), so declaring a chain's thousands of names keeps no second
    /// map of them.
    symbol_kinds: Vec<Option<Kind>>,
    /// Names of definitions (whose nodes may be symbols' nodes, so known by name).
    definitions: NameSet<String>,
    /// Names of bodies and constraints declared so far, for duplicate checks.
    body_names: NameSet<String>,
    constraint_names: NameSet<String>,
    /// Scratch of the walk for a constraint's symbols, kept from one constraint to the next.
    walk: SymbolWalk,
    /// Whether some body is rigid so far ([`System::has_rigid_bodies`] walks every body: once
    /// per constraint would make loading a large scene quadratic).
    has_rigid: bool,
}

/// What a name was declared as; written out (`the position of body `bead``) only for a
/// clash message, so declaring a chain's thousands of names formats nothing.
#[derive(Clone, Debug)]
enum Kind {
    Time,
    Parameter,
    Definition,
    /// A symbol of a body: `what` (position, velocity, …) and the body's name, shared by
    /// its symbols.
    OfBody {
        what: &'static str,
        body: Arc<str>,
    },
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Kind::Time => f.write_str("the time"),
            Kind::Parameter => f.write_str("a parameter"),
            Kind::Definition => f.write_str("a definition"),
            Kind::OfBody { what, body } => write!(f, "the {what} of body `{body}`"),
        }
    }
}

/// The symbols of one body, by name.
#[derive(Clone, Debug)]
pub struct BodySpec<'a> {
    pub name: &'a str,
    pub position: &'a str,
    pub velocity: &'a str,
    pub acceleration: &'a str,
    pub force: &'a str,
    /// A symbol name or a number.
    pub mass: MassSpec<'a>,
}

#[derive(Clone, Debug)]
pub enum MassSpec<'a> {
    Symbol(&'a str),
    Number(f64),
    /// Principal moments [I1, I2, I3]: a 3D rigid body's inertia only.
    Principal([f64; 3]),
}

/// The rotational symbols of a rigid body, by name (2D: all scalars).
#[derive(Clone, Debug)]
pub struct RigidSpec<'a> {
    pub orientation: &'a str,
    pub angular_velocity: &'a str,
    pub angular_acceleration: &'a str,
    pub torque: &'a str,
    /// The moment of inertia: a symbol name or a number (like a mass).
    pub inertia: MassSpec<'a>,
}

impl SystemBuilder {
    pub fn new(title: &str, dim: i64) -> Result<SystemBuilder, BuildError> {
        if dim != 2 && dim != 3 {
            return Err(BuildError::Dimension(dim));
        }
        let mut graph = Graph::new(dim as usize);
        let time = graph.declare("t", Ty::Scalar, Role::Time);
        let t_node = graph.sym(time);
        let mut scope = Scope::new();
        scope.insert("t", t_node);
        let system = System {
            title: title.to_string(),
            graph,
            simplifier: Simplifier::new(),
            bodies: Vec::new(),
            constraints: Vec::new(),
            parameters: Vec::new(),
            definitions: Vec::new(),
            time,
            scope,
        };
        let mut symbol_kinds = vec![None; time.index() + 1];
        symbol_kinds[time.index()] = Some(Kind::Time);
        Ok(SystemBuilder {
            system,
            symbol_kinds,
            definitions: NameSet::default(),
            body_names: NameSet::default(),
            constraint_names: NameSet::default(),
            walk: SymbolWalk::default(),
            has_rigid: false,
        })
    }

    /// Binds `name` in the scope to the node `bind` gives (called only when the name may be
    /// declared, with what else it made), refusing bad, reserved and taken names, in that
    /// order. One lookup of the name: the scope is asked whether it is taken and told its
    /// node at once.
    fn claim<T>(&mut self, name: &str, what: &Kind, bind: impl FnOnce(&mut Graph) -> (Id, T)) -> Result<T, BuildError> {
        let valid = name.as_bytes().first().is_some_and(u8::is_ascii_alphabetic)
            && name.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_');
        if !valid {
            return Err(BuildError::BadName(name.to_string()));
        }
        if is_function_name(name) {
            return Err(BuildError::Reserved(name.to_string()));
        }
        let System { scope, graph, .. } = &mut self.system;
        if let Some(made) = scope.insert_new(name, || bind(graph)) {
            return Ok(made);
        }
        if name == "t" {
            return Err(BuildError::Reserved(name.to_string()));
        }
        // Every name in scope was claimed, as a definition or a symbol.
        let first = self.kind(name).map_or_else(String::new, Kind::to_string);
        Err(BuildError::Duplicate { name: name.to_string(), first, second: what.to_string() })
    }

    /// What a declared name was declared as.
    fn kind(&self, name: &str) -> Option<&Kind> {
        if self.definitions.contains(name) {
            return Some(&Kind::Definition);
        }
        let Node::Sym(s) = self.system.graph.node(self.system.scope.get(name)?) else {
            return None;
        };
        self.symbol_kinds.get(s.index())?.as_ref()
    }

    fn symbol(&mut self, name: &str, ty: Ty, role: Role, what: Kind) -> Result<Symbol, BuildError> {
        let s = self.claim(name, &what, |g| {
            let s = g.declare(name, ty, role);
            (g.sym(s), s)
        })?;
        // Symbols are numbered in declaration order, so this is usually a push.
        if self.symbol_kinds.len() <= s.index() {
            self.symbol_kinds.resize_with(s.index() + 1, || None);
        }
        self.symbol_kinds[s.index()] = Some(what);
        Ok(s)
    }

    /// Declares a scalar or vector parameter.
    pub fn parameter(&mut self, name: &str, ty: Ty) -> Result<Symbol, BuildError> {
        let s = self.symbol(name, ty, Role::Parameter, Kind::Parameter)?;
        self.system.parameters.push((name.to_string(), s));
        Ok(s)
    }

    /// Declares a body and its symbols; returns its index.
    pub fn body(&mut self, spec: &BodySpec<'_>) -> Result<usize, BuildError> {
        let body = self.system.bodies.len();
        if self.body_names.contains(spec.name) {
            return Err(BuildError::Duplicate {
                name: spec.name.to_string(),
                first: format!("body `{}`", spec.name),
                second: "another body".into(),
            });
        }
        let body_name: Arc<str> = Arc::from(spec.name);
        let of = |what: &'static str| Kind::OfBody { what, body: body_name.clone() };
        let position = self.symbol(spec.position, Ty::Vector, Role::Position { body }, of("position"))?;
        let velocity = self.symbol(spec.velocity, Ty::Vector, Role::Velocity { body }, of("velocity"))?;
        let acceleration =
            self.symbol(spec.acceleration, Ty::Vector, Role::Acceleration { body }, of("acceleration"))?;
        let force = self.symbol(spec.force, Ty::Vector, Role::Force { body }, of("force"))?;
        let g = &mut self.system.graph;
        g.set_derivative(position, velocity);
        g.set_derivative(velocity, acceleration);
        let mass = match spec.mass {
            MassSpec::Symbol(name) => {
                // Bodies may share a mass symbol (`m` for every link of a chain).
                // A mass may also be a scalar parameter (`m = 1.0` in [parameters]).
                match self.system.scope.get(name) {
                    Some(id) if self.system.graph.ty(id) == Ty::Scalar && self.is_constant(name) => id,
                    _ => {
                        let s = self.symbol(name, Ty::Scalar, Role::Mass { body }, of("mass"))?;
                        self.system.graph.sym(s)
                    }
                }
            }
            MassSpec::Number(x) => exact_number(&mut self.system.graph, x)?,
            MassSpec::Principal(_) => return Err(BuildError::VectorMass(spec.name.to_string())),
        };
        let g = &mut self.system.graph;
        // Each symbol's node exists since it was bound in the scope: these make none.
        let nodes = BodyNodes {
            position: g.sym(position),
            velocity: g.sym(velocity),
            acceleration: g.sym(acceleration),
            force: g.sym(force),
        };
        self.body_names.insert(spec.name.to_string());
        self.system.bodies.push(Body {
            name: spec.name.to_string(),
            position,
            velocity,
            acceleration,
            force,
            mass,
            nodes,
            rigid: None,
        });
        Ok(body)
    }

    /// Makes body `body` (declared by [`SystemBuilder::body`]) rigid: declares its
    /// orientation, angular velocity and acceleration, torque and inertia (2D: scalars).
    pub fn rigid(&mut self, body: usize, spec: &RigidSpec<'_>) -> Result<(), BuildError> {
        let Some(name) = self.system.bodies.get(body).map(|b| b.name.clone()) else {
            return Err(BuildError::BadName(format!("body {body}")));
        };
        if self.system.bodies[body].rigid.is_some() {
            return Err(BuildError::RigidTwice(name));
        }
        // 2D: scalars. 3D: ω, α and τ are world-frame vectors, the orientation a quaternion
        // (typed scalar, read only by `rot`: `Graph::is_quaternion`), the inertia a vector.
        let three = self.system.dim() == 3;
        let turn = if three { Ty::Vector } else { Ty::Scalar };
        match (&spec.inertia, three) {
            (MassSpec::Principal(_), false) => return Err(BuildError::PrincipalInertia2d(name)),
            (MassSpec::Number(_), true) => return Err(BuildError::ScalarInertia3d(name)),
            _ => {}
        }
        let body_name: Arc<str> = Arc::from(name.as_str());
        let of = |what: &'static str| Kind::OfBody { what, body: body_name.clone() };
        let orientation = self.symbol(spec.orientation, Ty::Scalar, Role::Orientation { body }, of("orientation"))?;
        let angular_velocity =
            self.symbol(spec.angular_velocity, turn, Role::AngularVelocity { body }, of("angular velocity"))?;
        let angular_acceleration = self.symbol(
            spec.angular_acceleration,
            turn,
            Role::AngularAcceleration { body },
            of("angular acceleration"),
        )?;
        let torque = self.symbol(spec.torque, turn, Role::Torque { body }, of("torque"))?;
        let g = &mut self.system.graph;
        g.set_derivative(orientation, angular_velocity);
        g.set_derivative(angular_velocity, angular_acceleration);
        let inertia = match spec.inertia {
            MassSpec::Symbol(name) => match self.system.scope.get(name) {
                // Bodies may share an inertia symbol, and it may be a parameter (a scalar
                // in 2D, a vector in 3D).
                Some(id) if self.system.graph.ty(id) == turn && self.is_inertia_or_constant(name) => id,
                _ => {
                    let s = self.symbol(name, turn, Role::Inertia { body }, of("inertia"))?;
                    self.system.graph.sym(s)
                }
            },
            MassSpec::Number(x) => exact_number(&mut self.system.graph, x)?,
            MassSpec::Principal(moments) => {
                let mut entries = Vec::new();
                for x in moments {
                    entries.push(exact_number(&mut self.system.graph, x)?);
                }
                self.system.graph.vector(entries).map_err(|_| BuildError::PrincipalInertia2d(name.clone()))?
            }
        };
        let g = &mut self.system.graph;
        // 3D: the body's axes in the world, rot(q, eₖ), for the world inertia R diag(I) Rᵀ.
        let axes = if three {
            let q = g.sym(orientation);
            let mut axes = [q; 3];
            for (k, axis) in axes.iter_mut().enumerate() {
                let entries: Vec<Id> = (0..3).map(|j| g.int(i64::from(j == k))).collect();
                let unit = g.vector(entries).map_err(|_| BuildError::ScalarInertia3d(name.clone()))?;
                *axis = g.rot(q, unit).map_err(|_| BuildError::ScalarInertia3d(name.clone()))?;
            }
            Some(axes)
        } else {
            None
        };
        let nodes = RigidNodes {
            orientation: g.sym(orientation),
            angular_velocity: g.sym(angular_velocity),
            angular_acceleration: g.sym(angular_acceleration),
            torque: g.sym(torque),
            axes,
        };
        self.system.bodies[body].rigid =
            Some(Rigid { orientation, angular_velocity, angular_acceleration, torque, inertia, nodes });
        self.has_rigid = true;
        Ok(())
    }

    fn is_inertia_or_constant(&self, name: &str) -> bool {
        self.is_constant(name)
            || self.kind(name).is_some_and(|what| matches!(what, Kind::OfBody { what: "inertia", .. }))
    }

    fn is_constant(&self, name: &str) -> bool {
        self.kind(name).is_some_and(|what| matches!(what, Kind::OfBody { what: "mass", .. } | Kind::Parameter))
    }

    /// Declares a named expression, substituted wherever the name is used. Definitions may
    /// use earlier ones; order them (see `model::file` for the dependency sort).
    pub fn definition(&mut self, name: &str, text: &str) -> Result<Id, BuildError> {
        let context = || format!("in definition `{name}`: ");
        let syntax = parse_expr(text).map_err(|error| BuildError::Parse { context: context(), error })?;
        let id = lower(&syntax, &self.system.scope, &mut self.system.graph)
            .map_err(|error| BuildError::Lower { context: context(), error })?;
        self.claim(name, &Kind::Definition, |_| (id, ()))?;
        self.definitions.insert(name.to_string());
        self.system.definitions.push((name.to_string(), id));
        Ok(id)
    }

    /// Declares a constraint `lhs = rhs`, `lhs >= rhs`, `lhs <= rhs` or a bare `C`.
    pub fn constraint(&mut self, name: &str, text: &str) -> Result<usize, BuildError> {
        // The message's context is written only for a message (most constraints have none).
        let context = || format!("in constraint `{name}`: ");
        let relation = parse_relation(text).map_err(|error| BuildError::Parse { context: context(), error })?;
        let LoweredRelation { c, inequality } = lower_relation(&relation, &self.system.scope, &mut self.system.graph)
            .map_err(|error| BuildError::Lower { context: context(), error })?;
        let g = &self.system.graph;
        let mut bodies = Vec::new();
        for &s in self.walk.free_symbols(g, c) {
            let info = g.symbol(s);
            match info.role {
                Role::Position { body } | Role::Orientation { body } => bodies.push(body),
                Role::Velocity { .. }
                | Role::Acceleration { .. }
                | Role::Force { .. }
                | Role::AngularVelocity { .. }
                | Role::AngularAcceleration { .. }
                | Role::Torque { .. } => {
                    return Err(BuildError::NotPositional { name: name.to_string(), symbol: info.name.clone() });
                }
                _ => {}
            }
        }
        if bodies.is_empty() {
            return Err(BuildError::NoBody(name.to_string()));
        }
        // A rigid body is found through its position and its orientation: once, in order.
        if self.has_rigid {
            bodies.sort_unstable();
            bodies.dedup();
        }
        // A vector constraint is one scalar equality per component, `NAME.x`, `NAME.y`(, `NAME.z`).
        let parts: Vec<(String, Id)> = if self.system.graph.ty(c) == Ty::Vector {
            let mut parts = Vec::new();
            for axis in &crate::expr::Axis::ALL[..self.system.dim()] {
                let component = self.system.graph.comp(c, *axis).map_err(|e| BuildError::Lower {
                    context: context(),
                    error: LowerError { span: relation.lhs.span, kind: e.into() },
                })?;
                parts.push((format!("{name}.{}", axis.name()), component));
            }
            parts
        } else {
            vec![(name.to_string(), c)]
        };
        if self.constraint_names.contains(name) || parts.iter().any(|(n, _)| self.constraint_names.contains(n)) {
            return Err(BuildError::Duplicate {
                name: name.to_string(),
                first: "a constraint".into(),
                second: "another constraint".into(),
            });
        }
        let k = self.system.constraints.len();
        self.constraint_names.insert(name.to_string());
        for (part, c) in parts {
            self.constraint_names.insert(part.clone());
            self.system.constraints.push(Constraint {
                name: part,
                text: text.to_string(),
                c,
                inequality,
                bodies: bodies.clone(),
            });
        }
        Ok(k)
    }

    pub fn finish(self) -> System {
        self.system
    }

    /// The system so far (for resolving expressions between declarations).
    pub fn system(&self) -> &System {
        &self.system
    }
}
