//! The derivation pipeline (DESIGN.md steps 1–5): C → Ċ → C̈ → J, c → A, b → λ, forces.
//!
//! For each constraint: Ċ and C̈ by the product rule at the vector level, Jᵢ = ∇ᵣᵢC for the
//! bodies it involves, and c = C̈ with the accelerations set to zero. Each ∇C is divided by
//! its positive constant content κ (∇(r·r − l²) = 2r → direction r): the multiplier then
//! belongs to the direction people write (the article's λ), and J, c, A, b and λ all refer
//! to C/κ, so A λ + b = 0 holds among them exactly. The force on each body, Σₖ λₖ Jₖᵢ, does
//! not depend on κ.
//!
//! A is sparse: Aₖⱼ = Σᵢ Jₖᵢ·Jⱼᵢ / mᵢ over the bodies the two constraints share, so an
//! N-link chain has O(N) entries and the derivation is linear in N.
//!
//! Scenes repeat themselves: a constraint of the same shape as an earlier one (equal up to
//! renaming bodies, `expr::shape`) is the earlier derivation renamed, and so are A and b
//! entries of a shape seen before (`Simplifier::simplify_alike`). What comes out is what
//! deriving it alone gives; a chain's link costs a renaming, not a derivation.
//!
//! The model stays as it was loaded: [`derive()`] reads a `&System` and the [`Derivation`]
//! owns everything it adds. Its graph is the system's graph, copied once and extended
//! (nodes are appended, never changed), so every id of the system — constraints, masses,
//! the bodies' symbol nodes, expectations — means the same node in the derivation's graph,
//! and one graph answers every lookup afterwards. The copy costs one pass over the system's
//! nodes and symbols per derivation; a graph layered over the system's (its nodes below,
//! the derivation's above) would avoid it, at the price of every lookup asking which layer,
//! and belongs to `expr`. Beside the formulas the derivation owns what the documents show
//! that is not a number, built only when asked ([`Options`]): the multiplier symbols
//! `lambda_<name>` and the force sums Σₖ λₖ Jₖᵢ in them (one constraint too: its documents
//! print λ once and each force as λ J, so their size is linear in the bodies), and each C̈
//! with Newton's law substituted (`--steps`).
//!
//! Names: ∇C is `gradient`, J = ∇C/κ is `jacobian` and c is `bias` here and in
//! `numeric::rows`; the user-facing names stay (`derive --format json` calls J `"gradient"`
//! and c `"c"`, the generated Rust has `jacobian` and `c_term`; ARCHITECTURE.md has the
//! table). A renamed derivation comes back as one list whose layout is named once
//! (`Scalars`, then ∇C and J per body).
//!
//! Not here: numbers (`numeric`), layouts of the derivation for people (`report`).

use crate::expr::diff::{DiffError, time_derivative};
use crate::expr::grad::gradient;
use crate::expr::graph::FastMap;
use crate::expr::print::{Style, print};
use crate::expr::shape::{Reuse, Shaper};
use crate::expr::{Graph, Id, Node, Rational, Role, Simplifier, Symbol, Ty, TypeError};
use crate::model::system::{BuildError, System};
use std::collections::HashMap;

/// Everything derived for one constraint.
#[derive(Clone, Debug)]
pub struct DerivedConstraint {
    /// `C`, simplified.
    pub c: Id,
    /// `d/dt C` as the product rule gives it, before collecting.
    pub c_dot_raw: Id,
    pub c_dot: Id,
    /// `d/dt Ċ` as the product rule gives it, before collecting.
    pub c_ddot_raw: Id,
    pub c_ddot: Id,
    /// `(body, ∇C)` for each body involved, simplified.
    pub gradient: Vec<(usize, Id)>,
    /// κ: the positive constant content taken out of ∇C.
    pub scale: Rational,
    /// `(body, J = ∇C / κ)`.
    pub jacobian: Vec<(usize, Id)>,
    /// `c = C̈|ₐ₌₀ / κ`, so that C̈/κ = Σᵢ Jᵢ·aᵢ + c (rigid bodies: also α = 0, and
    /// C̈/κ = Σᵢ (Jᵢ·aᵢ + Jʷᵢ αᵢ) + c).
    pub bias: Id,
    /// `(body, ∂C/∂θ)` for each rigid body whose orientation C involves, simplified (3D:
    /// ∂Ċ/∂ω, a vector: the quaternion is never differentiated).
    pub angular_gradient: Vec<(usize, Id)>,
    /// `(body, Jʷ = ∂C/∂θ / κ)`: the coefficient of α in C̈/κ, and of ω in Ċ/κ (2D: a scalar;
    /// 3D: a vector).
    pub angular: Vec<(usize, Id)>,
    /// `(C/κ, Ċ/κ)` as formulas, only when κ or 1/κ is outside f64's normal range: there C
    /// or 1/κ is ±∞ or 0 in f64, and C · (1/κ) would be NaN or 0 where C/κ is a number
    /// (`r.x*1e400 = 1`). Otherwise the rows multiply C and Ċ by 1/κ.
    pub over_scale: Option<(Id, Id)>,
}

/// The derivation of a whole system.
#[derive(Debug)]
pub struct Derivation {
    /// The system's graph with every node the derivation built: each id of the system is
    /// valid here and means the same node.
    pub graph: Graph,
    /// The simplifier of `graph`, with what it remembers of the derivation.
    pub simplifier: Simplifier,
    pub constraints: Vec<DerivedConstraint>,
    /// Non-zero entries `(k, j, Aₖⱼ)` with `k ≤ j` (A is symmetric).
    pub a: Vec<(usize, usize, Id)>,
    pub b: Vec<Id>,
    /// λ in closed form, when there is a single constraint.
    pub lambda: Option<Id>,
    /// `(body, force λ J)` in closed form, when there is a single constraint: simplified, except
    /// where λ is kept separated or with [`Options::document`] (then the product λ J as it
    /// stands, the same function).
    pub forces: Option<Vec<(usize, Id)>>,
    /// `(body, torque λ Jʷ)` on each rigid body in closed form, when there is a single constraint.
    pub torques: Option<Vec<(usize, Id)>>,
    /// With [`Options::document`]: each constraint's multiplier λₖ, the node of the scalar
    /// symbol `lambda_<name>`, by constraint (one constraint has λ in closed form too, in
    /// [`lambda`](Self::lambda): the documents print that once, and the forces in the symbol).
    pub multipliers: Option<Vec<Id>>,
    /// With [`Options::document`]: `(body, Σₖ λₖ Jₖᵢ)` in the multiplier symbols, for each
    /// body some constraint acts on, in body order (one constraint: λ J, not simplified).
    pub force_sums: Option<Vec<(usize, Id)>>,
    /// With [`Options::document`]: `(body, Σₖ λₖ Jʷₖᵢ)`, the torque on each rigid body some
    /// constraint turns, in body order.
    pub torque_sums: Option<Vec<(usize, Id)>>,
    /// With [`Options::steps`]: each C̈ with Newton's law aᵢ = (Fᵢ + F_c,ᵢ)/mᵢ substituted
    /// for the accelerations, in the vector symbols `F_c` (one body) or `F_c_<body>`, and
    /// αᵢ = (τᵢ + τ_c,ᵢ)/Iᵢ for rigid bodies' angular accelerations (`T_c`, `T_c_<body>`).
    pub newton: Option<Vec<Id>>,
    /// With [`Options::document`]: the file's definitions the documents print as names.
    pub definitions: Option<Vec<Definition>>,
}

/// A `[definitions]` entry as the documents show it: `d` for `r2 − r1`.
#[derive(Clone, Debug)]
pub struct Definition {
    pub name: String,
    /// The definition as lowered (what each use of the name is in the file's formulas).
    pub written: Id,
    /// Its simplified form, as the derived formulas contain it.
    pub simplified: Id,
}

/// What [`derive_with`] derives beyond the formulas (the numbers need none of it).
#[derive(Clone, Copy, Debug, Default)]
pub struct Options {
    /// The multiplier symbols and force sums Σₖ λₖ Jₖᵢ (the text, LaTeX and Markdown
    /// documents show them, for one constraint as λ J beside λ's closed form).
    pub document: bool,
    /// Newton's law substituted into each C̈ (`derive --steps` shows it).
    pub steps: bool,
}

impl Derivation {
    /// Parses and type-checks `text` in `system`'s scope into the derivation's graph (an
    /// expected formula to compare with a derived one).
    pub fn expression(&mut self, system: &System, text: &str) -> Result<Id, BuildError> {
        let syntax = crate::expr::parse::parse_expr(text)
            .map_err(|error| BuildError::Parse { context: String::new(), error })?;
        crate::expr::lower::lower(&syntax, &system.scope, &mut self.graph)
            .map_err(|error| BuildError::Lower { context: String::new(), error })
    }

    /// `Aₖⱼ` (either order), if non-zero.
    pub fn a_entry(&self, k: usize, j: usize) -> Option<Id> {
        let (k, j) = if k <= j { (k, j) } else { (j, k) };
        self.a.iter().find(|e| e.0 == k && e.1 == j).map(|e| e.2)
    }
}

/// Why a system could not be derived.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DeriveError {
    #[error("constraint `{name}`: {error}")]
    Diff { name: String, error: DiffError },
    #[error("constraint `{0}` has a zero gradient everywhere: it does not constrain any position")]
    ZeroGradient(String),
    #[error("internal type error: {0}")]
    Type(#[from] TypeError),
    /// A formula passed the simplifier's work budget (`expr::simplify::MAX_FORM_WORK`).
    /// `constraint`: the index of the constraint whose formula it is, when it is one's (the
    /// report points at its `expr` in the file).
    #[error(
        "{what} is too large to derive: one of its formulas needs more than {work} term operations \
         to simplify (the limit of docs/file-format.md, \"Limits\"); write it in a smaller form, \
         or split it with [definitions] and more constraints"
    )]
    TooLarge { what: String, work: u64, constraint: Option<usize> },
}

impl DeriveError {
    /// The index of the constraint the error is about, when it names one by position.
    pub fn constraint(&self) -> Option<usize> {
        match self {
            DeriveError::TooLarge { constraint, .. } => *constraint,
            _ => None,
        }
    }
}

/// `e`, with a budget error said of `what` (a constraint, the multiplier equation), and of
/// constraint `k` when it is one's.
fn located(e: DeriveError, k: Option<usize>, what: impl FnOnce() -> String) -> DeriveError {
    match e {
        DeriveError::Type(TypeError::TooLarge(work)) => DeriveError::TooLarge { what: what(), work, constraint: k },
        DeriveError::Diff { error: DiffError::Type(TypeError::TooLarge(work)), name } => {
            DeriveError::TooLarge { what: format!("constraint `{name}`"), work, constraint: k }
        }
        e => e,
    }
}

/// Runs DESIGN.md steps 1–5 on every constraint of `system`.
pub fn derive(system: &System) -> Result<Derivation, DeriveError> {
    derive_with(system, Options::default())
}

/// [`derive()`], and what `options` asks for beyond the formulas.
pub fn derive_with(system: &System, options: Options) -> Result<Derivation, DeriveError> {
    let mut graph = system.graph.clone();
    let mut simplifier = Simplifier::new();
    let (g, s) = (&mut graph, &mut simplifier);
    // Differences keep the orientation the file wrote them in (`r2 − r1`).
    let written: Vec<Id> =
        system.constraints.iter().map(|c| c.c).chain(system.definitions.iter().map(|d| d.1)).collect();
    let forces: Vec<Id> = system.bodies.iter().map(|b| b.nodes.force).collect();
    s.keep_orientations(g, &written, &forces);
    let mut constraints: Vec<DerivedConstraint> = Vec::new();
    // Constraints already derived, by shape: a repeat (the next link of a chain) is the
    // earlier derivation with the bodies renamed.
    let mut derived: FastMap<Vec<u32>, (usize, Reuse)> = FastMap::default();
    let mut shaper = Shaper::default();
    // With one constraint nothing repeats: shapes would be work for nothing.
    let repeats = system.constraints.len() > 1;
    let name = |k: usize| move || format!("constraint `{}`", system.constraints[k].name);
    for k in 0..system.constraints.len() {
        if !repeats {
            constraints.push(derive_constraint(system, g, s, k).map_err(|e| located(e, Some(k), name(k)))?);
            continue;
        }
        let shape = shaper.shape(g, &[system.constraints[k].c]);
        let repeat = match derived.get_mut(&shape.key) {
            Some((earlier, reuse)) => renamed(system, g, s, &constraints[*earlier], reuse, &shape.symbols, k),
            None => None,
        };
        let dc = match repeat {
            Some(dc) => dc,
            None => {
                let dc = derive_constraint(system, g, s, k).map_err(|e| located(e, Some(k), name(k)))?;
                derived.insert(shape.key, (k, Reuse::new(Roots::of(&dc), shape.symbols, true)));
                dc
            }
        };
        constraints.push(dc);
    }
    let (a, b) = assemble(system, g, s, &constraints, repeats)
        .map_err(|e| located(e.into(), None, || "the multiplier equation A λ + b = 0".to_string()))?;
    let (mut lambda, mut forces, mut torques) = (None, None, None);
    if let [only] = constraints.as_slice() {
        // λ = −b / A
        let a00 = a.first().map(|e| e.2).ok_or(DeriveError::ZeroGradient(system.constraints[0].name.clone()))?;
        let closed_form = || format!("λ and the forces of constraint `{}`", system.constraints[0].name);
        let (l, separated) = closed_form_lambda(g, s, b[0], a00).map_err(|e| located(e, Some(0), closed_form))?;
        // A separated λ stays a factor of each force and torque as written (λ J): simplified,
        // the product would be put over λ's combined denominator again. The documents print
        // λ J with λ as its symbol, so for them the product is not expanded either (the
        // same function: `check` compares canonical forms).
        let mut wrench = |j: Id| -> Result<Id, DeriveError> {
            let product = g.mul(vec![l, j])?;
            if separated || options.document {
                s.adopt(product);
                return Ok(product);
            }
            s.simplify(g, product).map_err(|e| located(e.into(), Some(0), closed_form))
        };
        let mut f = Vec::new();
        for &(body, j) in &only.jacobian {
            f.push((body, wrench(j)?));
        }
        let mut t = Vec::new();
        for &(body, j) in &only.angular {
            t.push((body, wrench(j)?));
        }
        lambda = Some(l);
        forces = Some(f);
        torques = Some(t);
    }
    let newton = if options.steps { Some(newton(system, g, &constraints)?) } else { None };
    let definitions = if options.document { Some(definitions(system, g, s)?) } else { None };
    let (multipliers, force_sums, torque_sums) = if options.document {
        let (multipliers, sums, torque_sums) = force_sums(system, g, s, &constraints)?;
        (Some(multipliers), Some(sums), Some(torque_sums))
    } else {
        (None, None, None)
    };
    Ok(Derivation {
        graph,
        simplifier,
        constraints,
        a,
        b,
        lambda,
        forces,
        torques,
        multipliers,
        force_sums,
        torque_sums,
        newton,
        definitions,
    })
}

/// The file's definitions as the documents name them: each with its node as lowered and as
/// laid out (both are printed as the name), those that are more than a symbol or a number.
fn definitions(system: &System, g: &mut Graph, s: &mut Simplifier) -> Result<Vec<Definition>, TypeError> {
    let mut out = Vec::new();
    for (name, id) in &system.definitions {
        let trivial = |g: &Graph, x: Id| matches!(g.node(x), Node::Sym(_) | Node::Num(_));
        if trivial(g, *id) {
            continue;
        }
        let simplified = s.simplify(g, *id)?;
        if trivial(g, simplified) {
            continue;
        }
        out.push(Definition { name: name.clone(), written: *id, simplified });
    }
    Ok(out)
}

/// Each C̈ with aᵢ = (Fᵢ + F_c,ᵢ)/mᵢ for every body it involves, in new vector symbols F_c,ᵢ.
fn newton(system: &System, g: &mut Graph, constraints: &[DerivedConstraint]) -> Result<Vec<Id>, TypeError> {
    let single = system.bodies.len() == 1;
    let fc_nodes: Vec<Id> = (system.bodies.iter())
        .map(|body| {
            let name = if single { "F_c".to_string() } else { format!("F_c_{}", body.name) };
            let s = g.declare(&name, Ty::Vector, Role::Parameter);
            g.sym(s)
        })
        .collect();
    // The constraint torques, for rigid bodies: T_c or T_c_<body>.
    let mut tc_nodes = Vec::new();
    for body in &system.bodies {
        let name = if system.bodies.len() == 1 { "T_c".to_string() } else { format!("T_c_{}", body.name) };
        tc_nodes.push(match &body.rigid {
            Some(rigid) => {
                let ty = if rigid.nodes.axes.is_some() { Ty::Vector } else { Ty::Scalar };
                let s = g.declare(&name, ty, Role::Parameter);
                Some(g.sym(s))
            }
            None => None,
        });
    }
    let mut out = Vec::new();
    for (k, dc) in constraints.iter().enumerate() {
        let mut map = HashMap::new();
        for &body in &system.constraints[k].bodies {
            let b = &system.bodies[body];
            let total = g.add(vec![b.nodes.force, fc_nodes[body]])?;
            let inv_m = g.powi(b.mass, -1)?;
            let accel = g.mul(vec![inv_m, total])?;
            map.insert(b.nodes.acceleration, accel);
            if let (Some(rigid), Some(tc)) = (&b.rigid, tc_nodes[body]) {
                // Euler's law: I α = τ + τ_c (2D); I α = τ + τ_c − ω × (I ω) (3D, I the
                // world inertia).
                let alpha = match rigid.nodes.axes {
                    Some(axes) => {
                        let spin = gyroscopic(g, rigid, axes)?;
                        let minus_spin = g.neg(spin);
                        let total = g.add(vec![rigid.nodes.torque, tc, minus_spin])?;
                        inverse_inertia_times(g, rigid, axes, total)?
                    }
                    None => {
                        let total = g.add(vec![rigid.nodes.torque, tc])?;
                        let inv_i = g.powi(rigid.inertia, -1)?;
                        g.mul(vec![inv_i, total])?
                    }
                };
                map.insert(rigid.nodes.angular_acceleration, alpha);
            }
        }
        out.push(g.substitute(dc.c_ddot, &map)?);
    }
    Ok(out)
}

/// λ = −b/A of one constraint in the shorter of its two forms: combined over one
/// denominator ([`Simplifier::negated_quotient`], the form of every polynomial A), or, where
/// A is a sum of fractions over different roots, the quotient of the two sums as they read
/// ([`Simplifier::separated_quotient`]); `true` when the separated one is kept. Both are
/// the same function; the length compared is the expression language's. Over two or more
/// different roots the combined form is not built: its numerator carries the product of
/// the other roots in every term, so it grows as their number squared (a rope through k
/// segments) where the separated one grows linearly; in every file here it was the longer
/// (the pulley joint's λ 15 699 characters against 989, the rope's 3 222 against 1 218 at
/// k = 8), and building it made deriving the rope grow as k².
fn closed_form_lambda(g: &mut Graph, s: &mut Simplifier, b: Id, a: Id) -> Result<(Id, bool), DeriveError> {
    /// From this many different roots in A's denominators the separated form is kept unseen.
    const ALWAYS_SEPARATED: usize = 2;
    let separated = s.separated_quotient(g, b, a)?;
    if let Some((separated, roots)) = separated
        && roots >= ALWAYS_SEPARATED
    {
        return Ok((separated, true));
    }
    let combined = s.negated_quotient(g, b, a)?;
    let Some((separated, _)) = separated else { return Ok((combined, false)) };
    let length = |id: Id| print(g, id, Style::Source).map_or(usize::MAX, |text| text.len());
    Ok(if length(separated) < length(combined) { (separated, true) } else { (combined, false) })
}

/// The multiplier symbols `lambda_<name>` of the constraints, and the force on each body
/// as Σₖ λₖ Jₖᵢ in them (and the torque Σₖ λₖ Jʷₖᵢ on each rigid body). A component of a
/// vector constraint `pin.x` has the multiplier `lambda_pin_x` (a name the language reads).
#[allow(clippy::type_complexity)]
fn force_sums(
    system: &System,
    g: &mut Graph,
    s: &mut Simplifier,
    constraints: &[DerivedConstraint],
) -> Result<(Vec<Id>, Vec<(usize, Id)>, Vec<(usize, Id)>), TypeError> {
    let multipliers: Vec<Id> = (system.constraints.iter())
        .map(|c| {
            let s = g.declare(&format!("lambda_{}", c.name.replace('.', "_")), Ty::Scalar, Role::Parameter);
            g.sym(s)
        })
        .collect();
    // Each body's terms gathered from its own constraints' directions, in one pass over
    // the constraints (not every constraint searched for every body: that was quadratic).
    // A body's first direction in a constraint counts, as a search would find it.
    let n = system.bodies.len();
    let mut torque_terms: Vec<Vec<Id>> = vec![Vec::new(); n];
    let mut last: Vec<Option<usize>> = vec![None; n];
    for (k, dc) in constraints.iter().enumerate() {
        for &(body, j) in &dc.angular {
            if body >= n || last[body] == Some(k) {
                continue;
            }
            last[body] = Some(k);
            // Simplified term by term, so a negative lever arm reads `−λ L cos(th)`.
            let term = g.mul(vec![multipliers[k], j])?;
            torque_terms[body].push(s.simplify(g, term)?);
        }
    }
    let mut torque_sums = Vec::new();
    for (body, list) in torque_terms.into_iter().enumerate() {
        if !list.is_empty() {
            torque_sums.push((body, g.add(list)?));
        }
    }
    let mut terms: Vec<Vec<Id>> = vec![Vec::new(); n];
    let mut last: Vec<Option<usize>> = vec![None; n];
    for (k, dc) in constraints.iter().enumerate() {
        for &(body, j) in &dc.jacobian {
            if body >= n || last[body] == Some(k) {
                continue;
            }
            last[body] = Some(k);
            terms[body].push(g.mul(vec![multipliers[k], j])?);
        }
    }
    let mut sums = Vec::new();
    for (body, list) in terms.into_iter().enumerate() {
        if !list.is_empty() {
            sums.push((body, g.add(list)?));
        }
    }
    Ok((multipliers, sums, torque_sums))
}

fn derive_constraint(
    system: &System,
    g: &mut Graph,
    s: &mut Simplifier,
    k: usize,
) -> Result<DerivedConstraint, DeriveError> {
    let name = &system.constraints[k].name;
    let diff_error = |error| DeriveError::Diff { name: name.clone(), error };
    let c_raw = system.constraints[k].c;
    let involved = &system.constraints[k].bodies;
    let c = s.simplify(g, c_raw)?;
    let c_dot_raw = time_derivative(g, c).map_err(diff_error)?;
    let c_dot = s.simplify(g, c_dot_raw)?;
    let c_ddot_raw = time_derivative(g, c_dot).map_err(diff_error)?;
    let c_ddot = s.simplify(g, c_ddot_raw)?;
    let mut gradient_parts = Vec::new();
    let mut scale: Option<Rational> = None;
    for &body in involved {
        let r = system.bodies[body].position;
        let grad = gradient(g, c, r)?;
        let grad = s.simplify(g, grad)?;
        if s.is_zero(g, grad)? {
            continue;
        }
        let content = s.content(g, grad)?;
        scale = Some(match scale {
            None => content,
            Some(k) => k.gcd(&content),
        });
        gradient_parts.push((body, grad));
    }
    // Rigid bodies: ∂C/∂θ, the angular part of the direction (Jʷ before κ). κ is the
    // linear parts' content (as for point masses, so a pin's J is [1, 0] and its Jʷ a lever
    // arm); only a constraint on angles alone (a gear) takes it from the angular parts.
    let linear_scale = scale.is_some();
    let mut angular_parts = Vec::new();
    for &body in involved {
        let Some(rigid) = &system.bodies[body].rigid else { continue };
        // 3D: the coefficient of ω in Ċ (= that of α in C̈), a vector: q is never
        // differentiated, only `rot(q, s)` is (d/dt = ω × rot(q, s)).
        let grad = if rigid.nodes.axes.is_some() {
            gradient(g, c_dot, rigid.angular_velocity)?
        } else {
            gradient(g, c, rigid.orientation)?
        };
        let grad = s.simplify(g, grad)?;
        if s.is_zero(g, grad)? {
            continue;
        }
        if !linear_scale {
            let content = s.content(g, grad)?;
            scale = Some(match scale {
                None => content,
                Some(k) => k.gcd(&content),
            });
        }
        angular_parts.push((body, grad));
    }
    let scale = scale.ok_or_else(|| DeriveError::ZeroGradient(name.clone()))?;
    let inv = scale.recip().unwrap_or(Rational::ONE);
    let mut scaled = |parts: &[(usize, Id)]| -> Result<Vec<(usize, Id)>, TypeError> {
        parts.iter().map(|&(body, grad)| Ok((body, s.scaled(g, grad, &inv)?))).collect()
    };
    let jacobian = scaled(&gradient_parts)?;
    let angular = scaled(&angular_parts)?;
    // c = C̈ with every acceleration (and angular acceleration) set to zero, over κ.
    let zero = g.zero_vector();
    let scalar_zero = g.int(0);
    let mut to_zero = FastMap::default();
    for &(body, _) in &gradient_parts {
        to_zero.insert(system.bodies[body].nodes.acceleration, zero);
    }
    for &(body, _) in &angular_parts {
        if let Some(rigid) = &system.bodies[body].rigid {
            let zero = if rigid.nodes.axes.is_some() { zero } else { scalar_zero };
            to_zero.insert(rigid.nodes.angular_acceleration, zero);
        }
    }
    let at_rest = g.substitute(c_ddot, &to_zero)?;
    let bias = s.scaled(g, at_rest, &inv)?;
    let over_scale = if scale.to_f64().is_normal() && inv.to_f64().is_normal() {
        None
    } else {
        Some((s.scaled_for_numbers(g, c, &inv)?, s.scaled_for_numbers(g, c_dot, &inv)?))
    };
    Ok(DerivedConstraint {
        c,
        c_dot_raw,
        c_dot,
        c_ddot_raw,
        c_ddot,
        gradient: gradient_parts,
        scale,
        jacobian,
        bias,
        angular_gradient: angular_parts,
        angular,
        over_scale,
    })
}

/// The expressions of a derived constraint that do not depend on the bodies it acts on.
#[derive(Clone, Copy)]
struct Scalars {
    c: Id,
    c_dot_raw: Id,
    c_dot: Id,
    c_ddot_raw: Id,
    c_ddot: Id,
    bias: Id,
}

impl Scalars {
    const LEN: usize = 6;

    fn of(dc: &DerivedConstraint) -> Scalars {
        let DerivedConstraint { c, c_dot_raw, c_dot, c_ddot_raw, c_ddot, bias, .. } = *dc;
        Scalars { c, c_dot_raw, c_dot, c_ddot_raw, c_ddot, bias }
    }

    fn ids(self) -> [Id; Scalars::LEN] {
        [self.c, self.c_dot_raw, self.c_dot, self.c_ddot_raw, self.c_ddot, self.bias]
    }

    fn from_ids(ids: [Id; Scalars::LEN]) -> Scalars {
        let [c, c_dot_raw, c_dot, c_ddot_raw, c_ddot, bias] = ids;
        Scalars { c, c_dot_raw, c_dot, c_ddot_raw, c_ddot, bias }
    }

    /// The simplified ones, which the simplifier may take as canonical when renamed (the
    /// product rule's raw forms are not).
    fn simplified(self) -> [Id; 4] {
        [self.c, self.c_dot, self.c_ddot, self.bias]
    }
}

/// A derived constraint's expressions as one list, as a [`Reuse`] keeps and renames them:
/// the [`Scalars`], then ∇C of each of its bodies, then J of each, in its body order, then
/// ∂C/∂θ and Jʷ of each rigid body it turns.
struct Roots {
    /// How many bodies ∇C and J have.
    bodies: usize,
    /// How many rigid bodies ∂C/∂θ and Jʷ have.
    turning: usize,
}

/// A derived constraint's per-body expressions, split out of a renamed [`Roots`] list.
struct PerBody<'a> {
    gradient: &'a [Id],
    jacobian: &'a [Id],
    angular_gradient: &'a [Id],
    angular: &'a [Id],
}

impl Roots {
    fn of(dc: &DerivedConstraint) -> Vec<Id> {
        let mut roots = Scalars::of(dc).ids().to_vec();
        for parts in [&dc.gradient, &dc.jacobian, &dc.angular_gradient, &dc.angular] {
            roots.extend(parts.iter().map(|e| e.1));
        }
        roots
    }

    /// The scalars and the per-body expressions of `ids`; `None` if it is not of this layout.
    fn split<'a>(&self, ids: &'a [Id]) -> Option<(Scalars, PerBody<'a>)> {
        let (scalars, per_body) = ids.split_first_chunk::<{ Scalars::LEN }>()?;
        if per_body.len() != 2 * (self.bodies + self.turning) {
            return None;
        }
        let (linear, turning) = per_body.split_at(2 * self.bodies);
        let (gradient, jacobian) = linear.split_at(self.bodies);
        let (angular_gradient, angular) = turning.split_at(self.turning);
        Some((Scalars::from_ids(*scalars), PerBody { gradient, jacobian, angular_gradient, angular }))
    }
}

/// `earlier`'s derivation (kept in `reuse`) renamed to constraint `k`, of the same shape,
/// whose symbols are `to`; `None` if the bodies do not correspond.
fn renamed(
    system: &System,
    g: &mut Graph,
    s: &mut Simplifier,
    earlier: &DerivedConstraint,
    reuse: &mut Reuse,
    to: &[Symbol],
    k: usize,
) -> Option<DerivedConstraint> {
    // C/κ and Ċ/κ as formulas are not among the renamed roots: such a constraint is
    // derived alone.
    if earlier.over_scale.is_some() {
        return None;
    }
    let new = reuse.renamed(g, to)?;
    let roots = Roots { bodies: earlier.gradient.len(), turning: earlier.angular.len() };
    let (scalars, per_body) = roots.split(&new)?;
    let from = reuse.slots();
    let involved = &system.constraints[k].bodies;
    // Bodies correspond through the slots of their positions (a rigid body's turning
    // parts: of its orientation, which C holds wherever it has them); a slot renames a
    // symbol to one of the same role.
    let counterpart = |symbol: Symbol| -> Option<(usize, usize)> {
        let slot = from.iter().position(|&s| s == symbol)?;
        let body = match (g.symbol(symbol).role, g.symbol(*to.get(slot)?).role) {
            (Role::Position { .. }, Role::Position { body }) => body,
            (Role::Orientation { .. }, Role::Orientation { body }) => body,
            _ => return None,
        };
        Some((involved.iter().position(|&b| b == body)?, body))
    };
    let mut linear = Vec::new();
    for ((&(body, _), &grad), &j) in earlier.gradient.iter().zip(per_body.gradient).zip(per_body.jacobian) {
        let (place, body) = counterpart(system.bodies[body].position)?;
        linear.push((place, body, grad, j));
    }
    let mut turning = Vec::new();
    let angular = earlier.angular_gradient.iter().zip(per_body.angular_gradient).zip(per_body.angular);
    for ((&(body, _), &grad), &j) in angular {
        let (place, body) = counterpart(system.bodies[body].rigid.as_ref()?.orientation)?;
        turning.push((place, body, grad, j));
    }
    // In the constraint's body order, as `derive_constraint` lists them.
    linear.sort_by_key(|e| e.0);
    turning.sort_by_key(|e| e.0);
    let PerBody { gradient, jacobian, angular_gradient, angular } = per_body;
    for &id in scalars.simplified().iter().chain(gradient).chain(jacobian).chain(angular_gradient).chain(angular) {
        s.adopt(id);
    }
    let Scalars { c, c_dot_raw, c_dot, c_ddot_raw, c_ddot, bias } = scalars;
    Some(DerivedConstraint {
        c,
        c_dot_raw,
        c_dot,
        c_ddot_raw,
        c_ddot,
        gradient: linear.iter().map(|e| (e.1, e.2)).collect(),
        scale: earlier.scale.clone(),
        jacobian: linear.iter().map(|e| (e.1, e.3)).collect(),
        bias,
        angular_gradient: turning.iter().map(|e| (e.1, e.2)).collect(),
        angular: turning.iter().map(|e| (e.1, e.3)).collect(),
        over_scale: None,
    })
}

/// A (sparse, upper triangle) and b from the constraints' directions; with `repeats`,
/// entries of the same shape as earlier ones are renamed from them.
#[allow(clippy::type_complexity)]
fn assemble(
    system: &System,
    g: &mut Graph,
    s: &mut Simplifier,
    constraints: &[DerivedConstraint],
    repeats: bool,
) -> Result<(Vec<(usize, usize, Id)>, Vec<Id>), TypeError> {
    // Which constraints act on each body.
    let mut on_body: Vec<Vec<(usize, Id)>> = vec![Vec::new(); system.bodies.len()];
    for (k, dc) in constraints.iter().enumerate() {
        for &(body, j) in &dc.jacobian {
            on_body[body].push((k, j));
        }
    }
    let inv_mass = (system.bodies.iter()).map(|body| g.powi(body.mass, -1)).collect::<Result<Vec<Id>, _>>()?;
    // Which constraints turn each rigid body, and the bodies' inverse inertias.
    let mut turning: Vec<Vec<(usize, Id)>> = vec![Vec::new(); system.bodies.len()];
    for (k, dc) in constraints.iter().enumerate() {
        for &(body, j) in &dc.angular {
            turning[body].push((k, j));
        }
    }
    let mut inv_inertia = Vec::new();
    for body in &system.bodies {
        inv_inertia.push(match &body.rigid {
            // 3D: I⁻¹ is applied through the body's axes (`inverse_inertia_times`).
            Some(rigid) if rigid.nodes.axes.is_none() => Some(g.powi(rigid.inertia, -1)?),
            _ => None,
        });
    }
    // Aₖⱼ = Σᵢ [Jₖᵢ·Jⱼᵢ / mᵢ + Jʷₖᵢ Jʷⱼᵢ / Iᵢ], collected per pair (k ≤ j) over shared bodies.
    let mut pairs: Vec<((usize, usize), Vec<Id>)> = Vec::new();
    let mut index: HashMap<(usize, usize), usize> = HashMap::new();
    for (body, acting) in on_body.iter().enumerate() {
        for (x, &(k, jk)) in acting.iter().enumerate() {
            for &(j, jj) in &acting[x..] {
                let dot = g.dot(jk, jj)?;
                let term = g.mul(vec![dot, inv_mass[body]])?;
                let key = (k.min(j), k.max(j));
                let slot = *index.entry(key).or_insert_with(|| {
                    pairs.push((key, Vec::new()));
                    pairs.len() - 1
                });
                pairs[slot].1.push(term);
            }
        }
    }
    for (body, acting) in turning.iter().enumerate() {
        let Some(rigid) = &system.bodies[body].rigid else { continue };
        for (x, &(k, jk)) in acting.iter().enumerate() {
            for &(j, jj) in &acting[x..] {
                // 2D: Jʷₖ Jʷⱼ / I; 3D: Jʷₖ·I⁻¹ Jʷⱼ with the world inertia.
                let term = match (inv_inertia[body], rigid.nodes.axes) {
                    (Some(inv_i), _) => g.mul(vec![jk, jj, inv_i])?,
                    (None, Some(axes)) => {
                        let turned = inverse_inertia_times(g, rigid, axes, jj)?;
                        g.dot(jk, turned)?
                    }
                    (None, None) => continue,
                };
                let key = (k.min(j), k.max(j));
                let slot = *index.entry(key).or_insert_with(|| {
                    pairs.push((key, Vec::new()));
                    pairs.len() - 1
                });
                pairs[slot].1.push(term);
            }
        }
    }
    pairs.sort_by_key(|(key, _)| *key);
    let mut a = Vec::new();
    for ((k, j), terms) in pairs {
        let sum = g.add(terms)?;
        let entry = if repeats { s.simplify_alike(g, sum)? } else { s.simplify(g, sum)? };
        // A simplified zero is the number 0.
        if !g.is_zero(entry) {
            a.push((k, j, entry));
        }
    }
    // bₖ = Σᵢ [Jₖᵢ·Fᵢ / mᵢ + Jʷₖᵢ τᵢ / Iᵢ] + cₖ (2D: no gyroscopic term; 3D:
    // Jʷₖᵢ·Iᵢ⁻¹ (τᵢ − ωᵢ × Iᵢ ωᵢ))
    let mut b = Vec::new();
    for dc in constraints {
        let mut terms = Vec::new();
        for &(body, j) in &dc.jacobian {
            let dot = g.dot(j, system.bodies[body].nodes.force)?;
            terms.push(g.mul(vec![dot, inv_mass[body]])?);
        }
        for &(body, j) in &dc.angular {
            let Some(rigid) = &system.bodies[body].rigid else { continue };
            match (inv_inertia[body], rigid.nodes.axes) {
                (Some(inv_i), _) => terms.push(g.mul(vec![j, rigid.nodes.torque, inv_i])?),
                // 3D: Jʷ·I⁻¹ (τ − ω × I ω)
                (None, Some(axes)) => {
                    let spin = gyroscopic(g, rigid, axes)?;
                    let minus_spin = g.neg(spin);
                    let net = g.add(vec![rigid.nodes.torque, minus_spin])?;
                    let turned = inverse_inertia_times(g, rigid, axes, net)?;
                    terms.push(g.dot(j, turned)?);
                }
                (None, None) => {}
            }
        }
        terms.push(dc.bias);
        let sum = g.add(terms)?;
        b.push(if repeats { s.simplify_alike(g, sum)? } else { s.simplify(g, sum)? });
    }
    Ok((a, b))
}

/// I⁻¹ u for a 3D rigid body, with the world inertia I = R diag(I1, I2, I3) Rᵀ written
/// through the body's axes eₖ = rot(q, eₖ) (the columns of R): Σₖ eₖ (eₖ·u) / Iₖ.
fn inverse_inertia_times(
    g: &mut Graph,
    rigid: &crate::model::system::Rigid,
    axes: [Id; 3],
    u: Id,
) -> Result<Id, TypeError> {
    let mut terms = Vec::new();
    for (axis, e) in crate::expr::Axis::ALL.into_iter().zip(axes) {
        let moment = g.comp(rigid.inertia, axis)?;
        let inv = g.powi(moment, -1)?;
        let along = g.dot(e, u)?;
        terms.push(g.mul(vec![along, inv, e])?);
    }
    g.add(terms)
}

/// ω × (I ω) for a 3D rigid body, with I ω = Σₖ Iₖ eₖ (eₖ·ω) (see [`inverse_inertia_times`]):
/// the gyroscopic term of Euler's equations in the world frame.
fn gyroscopic(g: &mut Graph, rigid: &crate::model::system::Rigid, axes: [Id; 3]) -> Result<Id, TypeError> {
    let w = rigid.nodes.angular_velocity;
    let mut terms = Vec::new();
    for (axis, e) in crate::expr::Axis::ALL.into_iter().zip(axes) {
        let moment = g.comp(rigid.inertia, axis)?;
        let along = g.dot(e, w)?;
        terms.push(g.mul(vec![along, moment, e])?);
    }
    let momentum = g.add(terms)?;
    g.cross(w, momentum)
}
