//! `lagrange generate --lang rust`: a self-contained Rust module for a constraint file.
//!
//! The module has a `State` struct (time, positions, velocities, external forces, masses and
//! parameters as fields, vectors as `[f64; D]`) and plain functions of it: the constraint
//! values C (as written) and rates Ċ, A, b, the directions J (∇C over its constant content
//! κ, exported as `SCALE`) and c, the bodies' numbers, and `solution`: the solve of
//! `lagrange solve` on the module's rows (`support/rows.rs`: scaled rows, contact states,
//! λ ≥ 0 on inequalities, the minimum-norm λ of redundant constraints), with `lambda`,
//! `forces`, `force_<body>` and `accelerations` beside it. One equality keeps its closed
//! forms, guarded: where their numbers leave f64's range the scaled solve answers.
//! A big `State` (past `layout::MAX_STATE_FIELDS` inputs) holds the bodies' symbols in role
//! arrays (`ROLE_ARRAYS`): `position[i]`, `velocity[i]`, `force[i]` by body, `mass[j]` by
//! mass symbol, and the 2D rigid bodies' `angle[r]`, `angular_velocity[r]`, `torque[r]` by
//! rigid body (the r-th in file order, its angular slot) and `inertia[j]` by inertia symbol.
//! Rigid bodies (2D) add their θ, ω, τ (and I) to `State`, Jʷ (`angular_jacobian`), the
//! constraint torques and α: the rows' solve runs over the library's slots (bodies, then one
//! angular slot per rigid body), so its numbers are `lagrange solve`'s. 3D rigid bodies add
//! q (`[f64; 4]`), world ω and τ and the principal moments; the solve runs over three
//! slots per body, one per principal axis (`axis_slot`), and the torques and α come back as
//! world vectors.
//! With `--solver` the module also carries the velocity-level step an engine runs
//! (`step(state, impulses, h)`, `step_with`, `StepSettings`), for point masses and 2D and 3D
//! rigid bodies: the scene's `prepare` (the library's row roots in one function, so the
//! library's numbers, over its slots — the bodies, then the angular slots — written into the
//! step's fixed arrays; the exact step's `step_rows`), the state's slots (`get`, `put`) and
//! the helper text of `support/step.rs`, `motion.rs` (or `motion_3d.rs`) and the solver's
//! file. With `--step-only` the module is the step alone, its rows by shape (`shapes.rs`).
//!
//! The layout — dense or banded A, on the stack or the heap, dense J or its blocks, outputs
//! in parts of at most `MAX_PART` formulas — is decided by [`super::layout`] before any text
//! is written; this file writes the text it decides. The entries of A are computed from the
//! directions as assembled (Σᵢ Jₖᵢ·Jⱼᵢ / mᵢ), not from the canonical, bilinearly expanded
//! form the doc comments show: fewer operations and no cancellation. The solves a module
//! carries are helper files of `codegen::support`, included as they are written.
//!
//! Each function body is the scalar [`Program`] of its formulas: values used more than once
//! become `let` bindings, values used once are written inline. `--specialize` substitutes
//! the file's parameter values first and simplifies again, so terms that vanish for this
//! scene vanish from the code.
//!
//! Nothing a file contains can break the module: names become snake_case identifiers
//! (keywords get a trailing `_`, clashes a numeric suffix), and text in comments is one line
//! per comment with control and bidirectional characters escaped.
//!
//! Not here: layout decisions (`codegen::layout`), the helpers' text (`codegen::support`),
//! files or stdout (`main.rs`), evaluation (`numeric`).

use super::layout::Solver;
use super::layout::{self, AStorage, JStorage, Lambda, Layout, MAX_PART, MAX_ROW_KINDS, StateStorage};
use super::names::Namer;
pub use super::names::{comment_text, snake};
use super::support::{
    EXACT, HELPERS, MOTION, MOTION_3D, PGS, ROWS, SOFT_STEP, SOLVE_BAND, SOLVE_DENSE, SOLVE_TRIDIAGONAL, STEP, SWEEP,
};
use crate::derive::{Derivation, DeriveError, derive};
use crate::expr::eval::Value;
use crate::expr::graph::{FastMap, FastSet};
use crate::expr::print::{Style, print};
use crate::expr::{Graph, Id, Rational, Role, Symbol, Ty, TypeError};
use crate::model::file::Loaded;
use crate::numeric::program::{Inputs, LowerError, Op, Program};
use std::cell::Cell;

use std::fmt::Write;

/// What to generate.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// Substitute the file's parameter values (and numeric masses) before generating.
    pub specialize: bool,
    /// Write the velocity-level step of this solver too (`generate --solver`).
    pub solver: Option<Solver>,
    /// The language written.
    pub lang: Lang,
    /// Write the step and nothing else, each repeated row shape once over a table of its
    /// instances (`generate --step-only`; Rust, with `solver` soft step or PGS).
    pub step_only: bool,
}

/// The language of a generated module.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Lang {
    /// A self-contained Rust module.
    #[default]
    Rust,
    /// C99 without dependencies (`<math.h>` only).
    C,
}

/// Why code could not be generated.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum GenerateError {
    #[error(transparent)]
    Derive(#[from] DeriveError),
    #[error("internal type error: {0}")]
    Type(#[from] TypeError),
    #[error(transparent)]
    Lower(#[from] LowerError),
    #[error("parameter `{0}` has a value that cannot be written exactly (not finite, or too large)")]
    BadValue(String),
    #[error(
        "--step-only writes the soft step or PGS (--solver soft-step|pgs) in Rust; the exact step and C need the whole module"
    )]
    StepOnly,
    /// The formulas' code passed [`code_budget`] bytes.
    #[error(
        "the generated code is too large: its formulas pass {0} bytes (64 MiB, and 8 KiB more per body and \
         per constraint; docs/commands.md, \"generate\")"
    )]
    CodeTooLarge(usize),
}

/// The most bytes of formula code (`let` bindings and output expressions) one generated
/// module may hold: 64 MiB, and 8 KiB more per body and per constraint, so a module grows
/// linearly with its scene (a chain's is a few hundred bytes per link) but one formula
/// repeated in every body's force cannot make it quadratic. Charged while the code is
/// written, so a module past it stops there.
pub fn code_budget(system: &crate::model::system::System) -> usize {
    (64 << 20) + 8192 * (system.bodies.len() + system.constraints.len())
}

/// Longest formula quoted in a doc comment, in characters.
const MAX_DOC_FORMULA: usize = 400;
/// Deepest expression written inline; deeper values get a `let`, so rustc never sees a
/// pathologically nested expression.
const MAX_INLINE_DEPTH: u32 = 24;

/// Every formula the module needs, as graph nodes.
pub(super) struct Formulas {
    pub(super) c: Vec<Id>,
    /// Ċ per constraint (with ∂C/∂t).
    pub(super) c_dot: Vec<Id>,
    /// `(k, j, Aₖⱼ)`, upper triangle.
    pub(super) a: Vec<(usize, usize, Id)>,
    pub(super) b: Vec<Id>,
    pub(super) jacobian: Vec<Vec<(usize, Id)>>,
    pub(super) bias: Vec<Id>,
    pub(super) lambda: Option<Id>,
    pub(super) forces: Option<Vec<(usize, Id)>>,
    /// `(body, Jʷ)` per constraint: the angular part of J on each rigid body it turns.
    pub(super) angular: Vec<Vec<(usize, Id)>>,
    /// `(body, torque λ Jʷ)` in closed form (one constraint), on each rigid body it turns.
    pub(super) torques: Option<Vec<(usize, Id)>>,
}

impl Formulas {
    fn map(self, mut f: impl FnMut(Id) -> Result<Id, GenerateError>) -> Result<Formulas, GenerateError> {
        let mut each = |xs: Vec<Id>| xs.into_iter().map(&mut f).collect::<Result<Vec<_>, _>>();
        let c = each(self.c)?;
        let c_dot = each(self.c_dot)?;
        let b = each(self.b)?;
        let bias = each(self.bias)?;
        let a = self.a.into_iter().map(|(k, j, x)| Ok((k, j, f(x)?))).collect::<Result<_, GenerateError>>()?;
        let jacobian = self
            .jacobian
            .into_iter()
            .map(|d| d.into_iter().map(|(i, x)| Ok((i, f(x)?))).collect::<Result<Vec<_>, GenerateError>>())
            .collect::<Result<_, _>>()?;
        let angular = self
            .angular
            .into_iter()
            .map(|d| d.into_iter().map(|(i, x)| Ok((i, f(x)?))).collect::<Result<Vec<_>, GenerateError>>())
            .collect::<Result<_, _>>()?;
        let lambda = self.lambda.map(&mut f).transpose()?;
        let mut pairs = |list: Option<Vec<(usize, Id)>>| match list {
            Some(fs) => {
                fs.into_iter().map(|(i, x)| Ok((i, f(x)?))).collect::<Result<Vec<_>, GenerateError>>().map(Some)
            }
            None => Ok(None),
        };
        let forces = pairs(self.forces)?;
        let torques = pairs(self.torques)?;
        Ok(Formulas { c, c_dot, a, b, jacobian, bias, lambda, forces, angular, torques })
    }
}

/// A field of `State`.
pub(super) struct Field {
    pub(super) symbol: Symbol,
    /// The field's name, or `array[index]` for a symbol held in a role array.
    pub(super) ident: String,
    pub(super) doc: String,
    /// The role array ([`ROLE_ARRAYS`]) that holds it, with its index, when the layout puts
    /// bodies' symbols in arrays.
    pub(super) array: Option<(&'static str, usize)>,
}

/// A generated module and the `State` field that holds each input symbol.
#[derive(Clone, Debug)]
pub struct Module {
    pub code: String,
    pub fields: Vec<(Symbol, String)>,
    /// What the user should know about the code (also written as notes in its header):
    /// constants that do not fit in f64.
    pub warnings: Vec<String>,
}

/// Generates the Rust module for a loaded file (the source text).
pub fn generate(loaded: &Loaded, options: &Options) -> Result<String, GenerateError> {
    Ok(module(loaded, options)?.code)
}

/// Generates the Rust module for a loaded file, with its `State` layout: the module's own
/// derivation, specialised where asked, the scene's numbers as graph nodes, the plan (the
/// state's fields and the layout), then the text in the chosen language.
pub fn module(loaded: &Loaded, options: &Options) -> Result<Module, GenerateError> {
    if options.step_only && (options.lang != Lang::Rust || !options.solver.is_some_and(Solver::sweeps)) {
        return Err(GenerateError::StepOnly);
    }
    // The module's own derivation: `--specialize` extends its graph.
    let mut d = derive(&loaded.system)?;
    let specialised = specialise(loaded, &mut d, options.specialize)?;
    let scene = scene_numbers(loaded, &mut d.graph, &specialised)?;
    let plan = Plan::of(loaded, &d, &specialised);
    let formulas = &specialised.formulas;
    match (options.lang, options.step_only) {
        (Lang::Rust, true) => step_module(loaded, options, &d, formulas, &scene, &plan),
        (Lang::C, _) => c_module(loaded, options, &d, formulas, &scene, &plan),
        (Lang::Rust, false) => rust_module(loaded, options, &d, formulas, &scene, &plan),
    }
}

/// The formulas a module is written from, with the parameters `--specialize` substituted.
struct Specialised {
    formulas: Formulas,
    /// The symbols replaced by their values (not fields of `State`).
    substituted: FastSet<Symbol>,
    /// Each substituted symbol's node → its value's node.
    map: FastMap<Id, Id>,
}

/// The derivation's formulas; with `specialize`, each parameter's value substituted and the
/// formulas simplified again (kept as substituted where that leaves f64's range).
fn specialise(loaded: &Loaded, d: &mut Derivation, specialize: bool) -> Result<Specialised, GenerateError> {
    let mut formulas = Formulas {
        c: d.constraints.iter().map(|c| c.c).collect(),
        c_dot: d.constraints.iter().map(|c| c.c_dot).collect(),
        a: d.a.clone(),
        b: d.b.clone(),
        jacobian: d.constraints.iter().map(|c| c.jacobian.clone()).collect(),
        bias: d.constraints.iter().map(|c| c.bias).collect(),
        lambda: d.lambda,
        forces: d.forces.clone(),
        angular: d.constraints.iter().map(|c| c.angular.clone()).collect(),
        torques: d.torques.clone(),
    };
    let mut substituted = FastSet::default();
    let mut map = FastMap::default();
    if specialize {
        let g = &mut d.graph;
        let dim = g.dim();
        for &(s, value) in &loaded.values {
            let name = g.symbol(s).name.clone();
            let bad = || GenerateError::BadValue(name.clone());
            let node = match value {
                Value::Scalar(x) => {
                    let q = exact(x).ok_or_else(bad)?;
                    g.num(q)
                }
                // A quaternion is never a parameter (an orientation is part of the state).
                Value::Quaternion(_) => return Err(bad()),
                Value::Vector(_) => {
                    let mut entries = Vec::new();
                    for &x in value.components(dim).iter() {
                        let q = exact(x).ok_or_else(bad)?;
                        entries.push(g.num(q));
                    }
                    g.vector(entries)?
                }
            };
            if g.ty(node) != g.symbol(s).ty {
                return Err(bad());
            }
            let sym = g.sym(s);
            map.insert(sym, node);
            substituted.insert(s);
        }
        let simplifier = &mut d.simplifier;
        // One memo for every formula: they share most of their nodes (λ in each force).
        let mut memo = FastMap::default();
        formulas = formulas.map(|id| {
            let replaced = g.substitute_memo(id, &map, &mut memo)?;
            let simplified = simplifier.simplify(g, replaced)?;
            // Collecting over a common denominator can build constants past f64's range
            // (l = 1e-200 gives 1e400 l²-free forms); then keep the formula as substituted.
            Ok(if out_of_range(g, simplified) && !out_of_range(g, replaced) { replaced } else { simplified })
        })?;
    }
    Ok(Specialised { formulas, substituted, map })
}

/// The scene's numbers as graph nodes: masses, A and b as assembled, the bodies' and the
/// rigid bodies' inputs of the rows' solve.
struct SceneNumbers {
    masses: Vec<Id>,
    a_code: Vec<Id>,
    b_code: Vec<Id>,
    bodies: Bodies,
    turns: Turns,
}

fn scene_numbers(loaded: &Loaded, g: &mut Graph, sp: &Specialised) -> Result<SceneNumbers, GenerateError> {
    let (system, formulas, map) = (&loaded.system, &sp.formulas, &sp.map);
    // The code computes A from the directions, Σᵢ Jₖᵢ·Jⱼᵢ / mᵢ, as assembled: the derivation's
    // canonical Aₖⱼ expands each dot bilinearly (a chain's (r₁ − r₂)·(r₂ − r₃) becomes four dot
    // products), which costs more operations and loses digits to cancellation. The doc
    // comments keep the canonical form.
    let masses = system.bodies.iter().map(|b| g.substitute(b.mass, map)).collect::<Result<Vec<_>, _>>()?;
    let inertias = system
        .bodies
        .iter()
        .map(|b| b.rigid.as_ref().map(|r| g.substitute(r.inertia, map)).transpose())
        .collect::<Result<Vec<_>, _>>()?;
    let a_code = assembled_a(g, formulas, system, &masses, &inertias)?;
    let b_code = assembled_b(g, formulas, system, &masses, &inertias)?;
    let inverse_masses = masses.iter().map(|&m| g.powi(m, -1)).collect::<Result<Vec<_>, _>>()?;
    // The scene's force expressions (`[scene] forces`); a body not listed feels none.
    let zero = g.num(Rational::int(0));
    let zero = g.vector(vec![zero; g.dim()])?;
    let given_force = system.by_body(&loaded.scene.forces);
    let given_torque = system.by_body(&loaded.scene.torques);
    let mut applied = Vec::with_capacity(system.bodies.len());
    for given in &given_force {
        applied.push(match given {
            Some(id) => g.substitute(*id, map)?,
            None => zero,
        });
    }
    let bodies = Bodies {
        applied,
        position: system.bodies.iter().map(|b| b.nodes.position).collect(),
        velocity: system.bodies.iter().map(|b| b.nodes.velocity).collect(),
        force: system.bodies.iter().map(|b| b.nodes.force).collect(),
        inverse_mass: inverse_masses,
    };
    // The rigid bodies, in the order of their angular slots (`numeric::rows::angular_bodies`).
    let mut turns = Turns::default();
    for (i, body) in system.bodies.iter().enumerate() {
        let (Some(rigid), Some(inertia)) = (&body.rigid, inertias[i]) else { continue };
        if let Some(axes) = rigid.nodes.axes {
            // 3D: three slots, one per principal axis eₖ = R(q) eₖ (`numeric::rows`).
            let applied = match given_torque[i] {
                Some(id) => g.substitute(id, map)?,
                None => zero,
            };
            turns.three.push(Turn3 {
                body: i,
                first_slot: turns.body.len(),
                orientation: body_symbol(g, rigid.nodes.orientation),
                angular_velocity: rigid.nodes.angular_velocity,
                torque: rigid.nodes.torque,
                applied,
                axes,
            });
            for k in 0..3 {
                let w = axis_slot(g, axes, rigid.nodes.angular_velocity, rigid.nodes.torque, inertia, k)?;
                turns.body.push(i);
                turns.orientation.push(rigid.nodes.orientation);
                turns.angular_velocity.push(w.omega);
                turns.torque.push(w.torque);
                turns.applied.push(applied);
                turns.inverse_inertia.push(w.inverse_inertia);
                turns.inertia.push(inertia);
            }
            continue;
        }
        let scalar_zero = g.num(Rational::int(0));
        turns.body.push(i);
        turns.orientation.push(rigid.nodes.orientation);
        turns.angular_velocity.push(rigid.nodes.angular_velocity);
        turns.torque.push(rigid.nodes.torque);
        turns.applied.push(match given_torque[i] {
            Some(id) => g.substitute(id, map)?,
            None => scalar_zero,
        });
        turns.inverse_inertia.push(g.powi(inertia, -1)?);
        turns.inertia.push(inertia);
    }
    // 3D: Jʷ projected on each principal axis, the entry of the axis' slot.
    if !turns.three.is_empty() {
        for (k, dirs) in formulas.angular.iter().enumerate() {
            for &(b, jw) in dirs {
                let Some(t) = turns.three.iter().find(|t| t.body == b) else { continue };
                let (first, axes) = (t.first_slot, t.axes);
                for (a, &e) in axes.iter().enumerate() {
                    let p = g.dot(jw, e)?;
                    turns.projected.push((k, first + a, p));
                }
            }
        }
    }
    Ok(SceneNumbers { masses, a_code, b_code, bodies, turns })
}

/// The symbol of a symbol's node (a rigid body's orientation).
fn body_symbol(g: &Graph, node: Id) -> Symbol {
    match g.node(node) {
        crate::expr::Node::Sym(s) => *s,
        _ => unreachable!("a rigid body's orientation is its symbol's node"),
    }
}

/// One principal-axis slot of a 3D rigid body, as `numeric::rows` evaluates it.
struct AxisSlot {
    /// 1/Iₖ.
    inverse_inertia: Id,
    /// ωₖ = eₖ·ω.
    omega: Id,
    /// eₖ·τ − (ω_b × I ω_b)ₖ, the gyroscopic term of Euler's equations in the body frame.
    torque: Id,
}

/// Axis `k`'s slot of a 3D rigid body with principal axes `axes`, angular velocity `omega`,
/// torque `tau` and principal moments `moments` (a vector node): with ω_b = (eⱼ·ω)ⱼ and
/// (i, j) = (k + 1, k + 2) mod 3, (ω_b × I ω_b)ₖ = ω_b,i (I_j ω_b,j) − ω_b,j (I_i ω_b,i).
fn axis_slot(g: &mut Graph, axes: [Id; 3], omega: Id, tau: Id, moments: Id, k: usize) -> Result<AxisSlot, TypeError> {
    use crate::expr::Axis;
    let wb: Vec<Id> = axes.iter().map(|&e| g.dot(e, omega)).collect::<Result<_, _>>()?;
    let m: Vec<Id> = Axis::ALL.iter().map(|&a| g.comp(moments, a)).collect::<Result<_, _>>()?;
    let (i, j) = ((k + 1) % 3, (k + 2) % 3);
    let iw_j = g.mul(vec![m[j], wb[j]])?;
    let iw_i = g.mul(vec![m[i], wb[i]])?;
    let first = g.mul(vec![wb[i], iw_j])?;
    let second = g.mul(vec![wb[j], iw_i])?;
    let gyroscopic = g.sub(first, second)?;
    let along = g.dot(axes[k], tau)?;
    let torque = g.sub(along, gyroscopic)?;
    Ok(AxisSlot { inverse_inertia: g.powi(m[k], -1)?, omega: wb[k], torque })
}

/// What both languages lay out the same way: names, the state's fields, the layout, κ and
/// the inequality flags per row.
struct Plan<'a> {
    title: &'a str,
    body_names: Vec<&'a str>,
    constraint_names: Vec<&'a str>,
    fields: Vec<Field>,
    layout: Layout,
    scales: Vec<f64>,
    inequalities: Vec<bool>,
}

impl<'a> Plan<'a> {
    fn of(loaded: &'a Loaded, d: &Derivation, sp: &Specialised) -> Plan<'a> {
        let (system, formulas, g) = (&loaded.system, &sp.formulas, &d.graph);
        let body_names: Vec<&str> = system.bodies.iter().map(|b| b.name.as_str()).collect();
        let constraint_names: Vec<&str> = system.constraints.iter().map(|c| c.name.as_str()).collect();
        // The state holds the file's symbols, not those the derivation declared (the multipliers).
        let field_count = system
            .graph
            .symbols()
            .filter(|(s, i)| !sp.substituted.contains(s) && !matches!(i.role, Role::Acceleration { .. }))
            .count();
        let arrays = layout::state_storage(field_count) == StateStorage::Arrays;
        let fields = state_fields(&system.graph, &body_names, &sp.substituted, arrays);
        let a_entries: Vec<(usize, usize)> = formulas.a.iter().map(|&(r, c, _)| (r, c)).collect();
        let blocks = formulas.jacobian.iter().map(Vec::len).sum::<usize>();
        let closed_form = formulas.lambda.is_some() && formulas.forces.is_some();
        let layout = Layout::of(
            g.dim(),
            system.bodies.len(),
            system.constraints.len(),
            &a_entries,
            blocks,
            closed_form,
            // 3D rigid bodies: λ from the rows' solve over the axis slots only (no closed form
            // or dense path writes the world inertia yet).
            system.constraints.iter().any(|c| c.inequality) || system.dim() == 3 && system.has_rigid_bodies(),
        );
        Plan {
            title: if system.title.is_empty() { "untitled scene" } else { system.title.as_str() },
            body_names,
            constraint_names,
            fields,
            layout,
            scales: d.constraints.iter().map(|c| c.scale.to_f64()).collect(),
            inequalities: system.constraints.iter().map(|c| c.inequality).collect(),
        }
    }

    fn names(&self) -> Names<'_> {
        Names { bodies: &self.body_names, constraints: &self.constraint_names }
    }

    fn inputs(&self) -> Vec<Symbol> {
        self.fields.iter().map(|f| f.symbol).collect()
    }
}

/// 1/κ per row, as `numeric::rows` multiplies by it (the step's rows).
fn inverse_scales(d: &Derivation) -> Vec<f64> {
    d.constraints.iter().map(|c| c.scale.recip().unwrap_or(Rational::ONE).to_f64()).collect()
}

/// The symbols the masses depend on (never length-like).
fn mass_symbols(system: &crate::model::system::System) -> FastSet<Symbol> {
    system.bodies.iter().flat_map(|b| system.graph.free_symbols(b.mass)).collect()
}

/// `generate --lang c`: the same plan written by `codegen::c`.
fn c_module(
    loaded: &Loaded,
    options: &Options,
    d: &Derivation,
    formulas: &Formulas,
    scene: &SceneNumbers,
    plan: &Plan<'_>,
) -> Result<Module, GenerateError> {
    let (system, g, fields) = (&loaded.system, &d.graph, &plan.fields);
    let c_names = super::c::field_names(fields);
    let c_slots = super::c::slots(g, fields, &c_names);
    let input_layout = Inputs::new(g, &plan.inputs())?;
    let budget = code_budget(system);
    let room = Cell::new(budget);
    let ctx = Ctx { g, inputs: &input_layout, slots: &c_slots, non_finite: Cell::new(0), c: true, room, budget };
    let names = plan.names();
    let parts = super::c::Parts {
        title: plan.title,
        specialize: options.specialize,
        fields,
        c_names: &c_names,
        formulas,
        a_code: &scene.a_code,
        bodies: &scene.bodies,
        turns: &scene.turns,
        names: &names,
        layout: &plan.layout,
        scales: &plan.scales,
        inequalities: &plan.inequalities,
        b_code: &scene.b_code,
        length_places: if scene.turns.body.is_empty() {
            length_places(g, fields, &mass_symbols(system))
        } else {
            Vec::new()
        },
        step: options.solver.map(|solver| super::c::StepParts {
            solver,
            inverse_scales: inverse_scales(d),
            time: system.time,
            bodies: system.bodies.iter().map(|b| (b.position, b.velocity)).collect(),
            turns: scene
                .turns
                .rigid_bodies()
                .into_iter()
                .filter_map(|b| system.bodies[b].rigid.as_ref().map(|r| (r.orientation, r.angular_velocity)))
                .collect(),
            roots: StepRoots::of(&loaded.system, g, &plan.layout, &scene.masses, &scene.bodies, &scene.turns, formulas),
        }),
    };
    let code = super::c::emit(&ctx, &parts)?;
    let mut warnings = Vec::new();
    if ctx.non_finite.get() > 0 {
        warnings.push(format!(
            "constants of the formulas do not fit in f64 (written as INFINITY or NAN; {} place(s) in the code)",
            ctx.non_finite.get()
        ));
    }
    let fields = fields.iter().zip(c_names).map(|(f, n)| (f.symbol, n)).collect();
    Ok(Module { code, fields, warnings })
}

/// `generate --lang rust`, section by section as the module reads: the header (comment,
/// field list, `State`, row constants), the formulas' functions, the solve (rows, change of
/// unit, λ and forces), the step (`--solver`), the helpers, and a note on non-finite
/// constants.
fn rust_module(
    loaded: &Loaded,
    options: &Options,
    d: &Derivation,
    formulas: &Formulas,
    scene: &SceneNumbers,
    plan: &Plan<'_>,
) -> Result<Module, GenerateError> {
    let (system, g, fields, layout) = (&loaded.system, &d.graph, &plan.fields, &plan.layout);
    let mut out = String::new();
    header(
        &mut out,
        plan.title,
        (options.specialize, options.solver),
        layout,
        (scene.turns.rigid_bodies().len(), !scene.turns.three.is_empty()),
    );
    field_names(&mut out, g, fields);
    state(&mut out, g, fields, layout);
    row_constants(&mut out, &plan.scales, &plan.inequalities, &names_of(&plan.constraint_names));
    let header_end = out.len();
    let slots = slot_exprs(g, fields);
    let input_layout = Inputs::new(g, &plan.inputs())?;
    let budget = code_budget(system);
    let room = Cell::new(budget);
    let ctx = Ctx { g, inputs: &input_layout, slots: &slots, non_finite: Cell::new(0), c: false, room, budget };
    let names = plan.names();
    formula_fns(&mut out, &ctx, formulas, scene, plan)?;
    rows_fn(&mut out, formulas, layout, &scene.turns);
    // A change of length unit scales no angle, inertia or torque: a module with rigid bodies
    // solves in the file's unit, as `numeric::rescale` finds such rows not homogeneous.
    if scene.turns.body.is_empty() {
        scaling_fns(&mut out, g, fields, &mass_symbols(system));
    }
    ctx.solution(&mut out, formulas, (&scene.a_code, &scene.b_code), &names, layout, &scene.turns)?;
    if let Some(solver) = options.solver {
        let step = StepRoots::of(&loaded.system, g, layout, &scene.masses, &scene.bodies, &scene.turns, formulas);
        let places = StepPlaces::of(system, fields, &scene.turns);
        step_fns(&mut out, &ctx, solver, &inverse_scales(d), &places, &step, formulas, &names, layout)?;
    }
    helper_texts(&mut out, options.solver, !scene.turns.three.is_empty());
    let mut warnings = Vec::new();
    if ctx.non_finite.get() > 0 {
        let warning = format!(
            "constants of the formulas do not fit in f64 (past ±1.8e308: written as f64::INFINITY, or NaN; {} \
             place(s) in the code); the outputs that use them are not finite",
            ctx.non_finite.get()
        );
        let note = format!("// Warning: {}.\n\n", comment_text(&warning));
        // After the header's paragraph (its blank line), before the field list.
        let at = out[..header_end].rfind("\n\n// State fields").map_or(header_end, |i| i + 2);
        out.insert_str(at, &note);
        warnings.push(warning);
    }
    Ok(Module { code: out, fields: fields.iter().map(|f| (f.symbol, f.ident.clone())).collect(), warnings })
}

/// The formulas' functions, in the module's order: C, Ċ, A, b, J, c, the bodies' numbers and
/// the rigid bodies'.
fn formula_fns(
    out: &mut String,
    ctx: &Ctx<'_>,
    formulas: &Formulas,
    scene: &SceneNumbers,
    plan: &Plan<'_>,
) -> Result<(), GenerateError> {
    let (names, layout) = (plan.names(), &plan.layout);
    ctx.constraints(out, formulas, &names)?;
    ctx.rates(out, formulas, &names)?;
    ctx.a(out, formulas, &scene.a_code, layout)?;
    ctx.b(out, formulas)?;
    ctx.jacobian(out, formulas, &names, layout)?;
    ctx.c_term(out, formulas)?;
    ctx.bodies(out, &scene.bodies, &names)?;
    ctx.rigid(out, &scene.turns, formulas, &names, (layout, &plan.fields))
}

/// The helpers every module carries (the rows' solve, the norms), then the step's with
/// `--solver` (its motion of 3D rigid bodies where the module has them).
fn helper_texts(out: &mut String, solver: Option<Solver>, three: bool) {
    out.push_str(ROWS);
    out.push('\n');
    out.push_str(HELPERS);
    if let Some(solver) = solver {
        out.push('\n');
        out.push_str(STEP);
        out.push('\n');
        out.push_str(if three { MOTION_3D } else { MOTION });
        if solver.sweeps() {
            out.push('\n');
            out.push_str(SWEEP);
        }
        out.push('\n');
        out.push_str(match solver {
            Solver::SoftStep => SOFT_STEP,
            Solver::Pgs => PGS,
            Solver::Exact => EXACT,
        });
    }
}

/// The `State` field of a symbol (every body's position and velocity has one).
fn ident_of(fields: &[Field], symbol: Symbol) -> &str {
    fields.iter().find(|f| f.symbol == symbol).map_or("t", |f| f.ident.as_str())
}

/// Where the step reads and writes the state: the time field (none when the file has no
/// `t` in its state), each body's position and velocity fields, in file order, and each
/// rigid body's orientation and angular velocity fields, in the order of their slots.
pub(super) struct StepPlaces<'a> {
    time: Option<&'a str>,
    position: Vec<&'a str>,
    velocity: Vec<&'a str>,
    /// Per rigid body: its orientation (θ, or q in 3D) and ω fields.
    turn: Vec<(&'a str, &'a str)>,
    /// What `same_inputs` compares: per field but the time and the velocities (a role array
    /// once), its numbers as a slice of `a` and of `b`.
    inputs: Vec<(String, String)>,
}

impl<'a> StepPlaces<'a> {
    /// The places of the step's state in `fields`.
    fn of(system: &crate::model::system::System, fields: &'a [Field], turns: &Turns) -> StepPlaces<'a> {
        let turn = |body: usize| {
            let rigid = system.bodies[body].rigid.as_ref();
            rigid.map_or(("", ""), |r| (ident_of(fields, r.orientation), ident_of(fields, r.angular_velocity)))
        };
        let g = &system.graph;
        let mut inputs = Vec::new();
        let mut arrays = Vec::new();
        for f in fields {
            let slice = |x: &str| match f.array {
                Some((name, _)) if scalar_role(name) => format!("&{x}.{name}"),
                Some((name, _)) => format!("{x}.{name}.as_flattened()"),
                None if g.symbol(f.symbol).ty == Ty::Scalar && !g.is_quaternion(f.symbol) => {
                    format!("&[{x}.{}]", f.ident)
                }
                None => format!("&{x}.{}", f.ident),
            };
            match f.array {
                Some(("velocity" | "angular_velocity", _)) => continue,
                Some((name, _)) if arrays.contains(&name) => continue,
                Some((name, _)) => arrays.push(name),
                None if matches!(
                    g.symbol(f.symbol).role,
                    Role::Time | Role::Velocity { .. } | Role::AngularVelocity { .. }
                ) =>
                {
                    continue;
                }
                None => {}
            }
            inputs.push((slice("a"), slice("b")));
        }
        StepPlaces {
            inputs,
            time: fields.iter().find(|f| f.symbol == system.time).map(|f| f.ident.as_str()),
            position: system.bodies.iter().map(|b| ident_of(fields, b.position)).collect(),
            velocity: system.bodies.iter().map(|b| ident_of(fields, b.velocity)).collect(),
            turn: turns.rigid_bodies().into_iter().map(turn).collect(),
        }
    }
}

/// The roots of the step's rows, in the order of the library's `numeric::rows::RowProgram`
/// (per body m, v, F; per rigid body I, ω, τ, and in 3D its principal axes; per row C, Ċ, c,
/// J per body, then Jʷ per rigid body it turns, once per angular slot), with where each
/// row's angular entries go. Rust and C write the step's rows from the same list.
pub(super) struct StepRoots {
    pub(super) roots: Vec<Id>,
    /// Per root, whether the soft step and PGS read it: all but each row's c (a root so that
    /// the shared values are the library's, but only the exact step reads it).
    pub(super) swept: Vec<bool>,
    /// Per row, the slot of each angular entry (after its linear ones), in root order.
    pub(super) angular_slots: Vec<Vec<usize>>,
    /// Per rigid body: its first slot and whether it is 3D (three slots, one per axis).
    pub(super) turns: Vec<(usize, bool)>,
    /// Per row, whether its C reads no time (`numeric::velocity::steady_rows`): ∂C/∂t = 0,
    /// so the soft step and PGS leave its Ċ out (`swept`).
    pub(super) steady: Vec<bool>,
    /// Whether the rows read neither the velocities nor the time (every row steady, no 3D
    /// rigid body, each body's m and F and each rigid body's I and τ free of velocities and
    /// time): then the rows a step leaves are the rows of the next step's start, bit for bit,
    /// while the other inputs are unchanged (`KEEP`, `Stepper`).
    pub(super) keep: bool,
    /// Whether the bodies' m and F (and the rigid bodies' I and τ) read neither positions,
    /// orientations, velocities nor the time, so a step's positions leave them unchanged
    /// (`--step-only`'s `prepare_moved` leaves them out).
    pub(super) still: bool,
    /// Whether a row's evaluation reads the velocities (a row's ∂C/∂t, or a 3D body's
    /// gyroscopic term): not when every row is steady and no body is 3D.
    pub(super) velocities: bool,
    /// The structural zeros of each row's J (`numeric::velocity::pattern`, the library's).
    pub(super) pattern: crate::numeric::velocity::pattern::Pattern,
    /// Per entry in the derivation's order, its components that are the constant ±1 (two
    /// bits per component, as `ENTRY_CODE`: 2 for +1, 3 for −1, 0 otherwise): a pin's
    /// linear entry [±1, 0], whose products the step writes without the multiplication.
    pub(super) units: Vec<u8>,
}

impl StepRoots {
    pub(super) fn of(
        system: &crate::model::system::System,
        g: &Graph,
        layout: &Layout,
        masses: &[Id],
        bodies: &Bodies,
        turns: &Turns,
        formulas: &Formulas,
    ) -> StepRoots {
        let n = layout.bodies;
        let steady = crate::numeric::velocity::steady_rows(system);
        let mut roots = Vec::new();
        for ((&m, &v), &f) in masses.iter().zip(&bodies.velocity).zip(&bodies.applied).take(n) {
            roots.extend([m, v, f]);
        }
        let three = !turns.three.is_empty();
        let width = if three { 3 } else { 1 };
        let mut rigid = Vec::new();
        for (r, body) in turns.rigid_bodies().into_iter().enumerate() {
            let slot = r * width;
            rigid.push((body, n + slot, three));
            if three {
                // The moments, the world ω and τ, and the principal axes.
                let t = &turns.three[r];
                roots.extend([turns.inertia[slot], t.angular_velocity, t.applied]);
                roots.extend(t.axes);
            } else {
                roots.extend([turns.inertia[slot], turns.angular_velocity[slot], turns.applied[slot]]);
            }
        }
        // The bodies' m, v, F (and I, ω, τ): all but the velocities must be free of velocities
        // and time for the rows to be kept.
        let mut walk = crate::expr::graph::SymbolWalk::default();
        let moving = |role: Role| matches!(role, Role::Velocity { .. } | Role::AngularVelocity { .. } | Role::Time);
        let velocities = three || steady.len() != layout.constraints || !steady.iter().all(|&s| s);
        let mut reads = |roles: &dyn Fn(Role) -> bool| {
            roots.chunks_exact(3).any(|c| {
                [c[0], c[2]].iter().any(|&id| walk.free_symbols(g, id).iter().any(|&s| roles(g.symbol(s).role)))
            })
        };
        let keep = !velocities && !reads(&moving);
        let still =
            !three && !reads(&|role| moving(role) || matches!(role, Role::Position { .. } | Role::Orientation { .. }));
        let mut swept = vec![true; roots.len()];
        let mut angular_slots = Vec::with_capacity(layout.constraints);
        let mut units = Vec::new();
        // Component d of J the constant ±1 (a vector literal's entry; an angular slot's Jʷ).
        let unit = |id: Id| match g.as_num(id) {
            Some(q) if *q == Rational::ONE => 2,
            Some(q) if *q == Rational::int(-1) => 3,
            _ => 0,
        };
        for r in 0..layout.constraints {
            for &(_, j) in &formulas.jacobian[r] {
                let mut code = 0u8;
                if let crate::expr::Node::Vector(xs) = g.node(j) {
                    for (d, &x) in xs.iter().enumerate().take(layout.dim) {
                        code |= unit(x) << (2 * d);
                    }
                }
                units.push(code);
            }
            for &(b, jw) in &formulas.angular[r] {
                if rigid.iter().any(|t| t.0 == b) {
                    units.extend(std::iter::repeat_n(if three { 0 } else { unit(jw) }, width));
                }
            }
        }
        for r in 0..layout.constraints {
            roots.extend([formulas.c[r], formulas.c_dot[r], formulas.bias[r]]);
            swept.extend([true, !steady.get(r).copied().unwrap_or(false), false]);
            roots.extend(formulas.jacobian[r].iter().map(|&(_, j)| j));
            let mut slots = Vec::new();
            for &(b, jw) in &formulas.angular[r] {
                let Some(&(_, first, _)) = rigid.iter().find(|t| t.0 == b) else { continue };
                for k in 0..width {
                    roots.push(jw);
                    slots.push(first + k);
                }
            }
            swept.resize(roots.len(), true);
            angular_slots.push(slots);
        }
        StepRoots {
            roots,
            swept,
            angular_slots,
            turns: rigid.into_iter().map(|(_, first, three)| (first, three)).collect(),
            steady: (0..layout.constraints).map(|r| steady.get(r).copied().unwrap_or(false)).collect(),
            keep,
            still,
            velocities,
            pattern: crate::numeric::velocity::pattern::Pattern::of(system),
            units,
        }
    }

    /// The step's slots: the bodies, then the rigid bodies' angular slots.
    pub(super) fn slots(&self, bodies: usize) -> usize {
        bodies + self.turns.iter().map(|&(_, three)| if three { 3 } else { 1 }).sum::<usize>()
    }

    /// The 3D rigid bodies (their slots' principal axes and orientations).
    pub(super) fn three(&self) -> usize {
        self.turns.iter().filter(|t| t.1).count()
    }

    /// Each row's Jacobian entries as the step keeps them: `ROW_START` (one more than the
    /// rows), the slot of each in the step's order (`ROW_BODY`: the library's
    /// `velocity::entry_orders` of the derivation's order, a row's bodies, then its angular
    /// slots) and, per entry in the derivation's order, its place in the step's (`ENTRY_AT`).
    pub(super) fn entries(&self, formulas: &Formulas) -> (Vec<usize>, Vec<usize>, Vec<usize>) {
        let mut starts = vec![0];
        let mut slots = Vec::new();
        for (dirs, angular) in formulas.jacobian.iter().zip(&self.angular_slots) {
            slots.extend(dirs.iter().map(|&(body, _)| body));
            slots.extend(angular);
            starts.push(slots.len());
        }
        let order = crate::numeric::velocity::entry_orders(&starts, &slots);
        let mut at = vec![0; order.len()];
        for (place, &e) in order.iter().enumerate() {
            at[e] = place;
        }
        (starts, order.iter().map(|&e| slots[e]).collect(), at)
    }

    /// Per entry in the step's order (`entries`' `ROW_START`, `ROW_BODY` and `ENTRY_AT`), its
    /// components in two bits each (`ENTRY_CODE`): 0 a structural zero (the library's
    /// `velocity::pattern`, as its `Prepared` keeps it), 2 the constant +1, 3 the constant
    /// −1, 1 any other number. `entry_mask` turns a code into the library's mask.
    pub(super) fn codes(&self, starts: &[usize], slots: &[usize], at: &[usize]) -> Vec<u8> {
        let mut codes = vec![0; slots.len()];
        for (k, w) in starts.windows(2).enumerate() {
            for (e, &place) in at.iter().enumerate().take(w[1]).skip(w[0]) {
                let mask = self.pattern.mask(k, slots[place]);
                let units = self.units.get(e).copied().unwrap_or(0);
                for d in 0..3 {
                    if mask >> d & 1 != 0 {
                        let unit = units >> (2 * d) & 3;
                        codes[place] |= (if unit == 0 { 1 } else { unit }) << (2 * d);
                    }
                }
            }
        }
        codes
    }

    /// The rigid body (its index among `turns`) and the axis of an angular slot.
    fn axis_of(&self, slot: usize) -> (usize, usize) {
        let rigid = self.turns.iter().rposition(|t| t.0 <= slot).unwrap_or(0);
        (rigid, slot - self.turns.get(rigid).map_or(slot, |t| t.0))
    }
}

/// The scene's part of the step (`--solver`): its constants, the derivation of each row as
/// comments, `prepare` (the soft step and PGS: the rows written into the step's arrays;
/// `step_rows` for the exact step) and the state's accessors the step's helper text calls
/// (`time`, `get`, `put`).
#[allow(clippy::too_many_arguments)]
fn step_fns(
    out: &mut String,
    ctx: &Ctx<'_>,
    solver: Solver,
    inverse_scales: &[f64],
    places: &StepPlaces<'_>,
    step: &StepRoots,
    formulas: &Formulas,
    names: &Names<'_>,
    layout: &Layout,
) -> Result<(), GenerateError> {
    let g = ctx.g;
    let k = layout.constraints;
    let n = layout.bodies;
    let slots = step.slots(n);
    let three = step.three() > 0;
    let (starts, entry_at) = step_constants(out, solver, inverse_scales, step, formulas, layout);
    // The derivation, row by row: what the step's helper text computes from these numbers.
    let mut doc = vec![
        "The rows the step solves, at a state: per slot 1/m, v and F (the scene's, `applied_forces`; a rigid body's angular slot 1/I, ω, τ), per row C/κ, Ċ/κ, c and J = ∇C/κ per slot (Jʷ in an angular slot). Per row k".to_string(),
        "of the step: effective mass m_eff = 1/(J M⁻¹ Jᵀ) = 1/A[k][k] (Σᵢ |Jᵢ|²/mᵢ, from these J), ∂C/∂t = Ċ − J·v,"
            .to_string(),
        "and the impulse ΔP the solver gives (see `step_with`); ΔP moves slot i by Δuᵢ = Jᵢ ΔP / mᵢ.".to_string(),
    ];
    let mut diagonal: FastMap<usize, Id> = FastMap::default();
    for &(r, c, a) in &formulas.a {
        if r == c {
            diagonal.entry(r).or_insert(a);
        }
    }
    for (r, dirs) in formulas.jacobian.iter().enumerate() {
        doc.push(format!("- row {r}, `{}`: C = {}", comment_text(names.constraints[r]), formula(g, formulas.c[r])));
        for &(body, id) in dirs {
            doc.push(format!("  J, body `{}`: {}", comment_text(names.bodies[body]), formula(g, id)));
        }
        for &(body, id) in &formulas.angular[r] {
            doc.push(format!("  Jʷ, body `{}`: {}", comment_text(names.bodies[body]), formula(g, id)));
        }
        if let Some(&a) = diagonal.get(&r) {
            doc.push(format!("  J M⁻¹ Jᵀ = A[{r}][{r}] = {}", formula(g, a)));
        }
    }
    for line in &doc {
        let _ = writeln!(out, "/// {line}");
    }
    // One function over the roots of the library's row program, in its order, so the shared
    // values (one reciprocal for a value divided twice or more) are the library's and the
    // rows its numbers, bit for bit. The acceleration-level term c is a root but only the
    // exact step reads it: the soft step's and PGS's code leaves it out.
    let exact = solver == Solver::Exact;
    // Where the bodies' 1/m and F cannot change with the positions and no row reads the
    // velocities, `prepare_moved` (the rows after a substep's drift) is the rows alone, as a
    // `--step-only` module's: `prepare` writes the bodies' numbers and each `UNIT` row's m_eff
    // (`unit_masses`), then calls it.
    let split = !exact && step.still && !step.velocities;
    if split {
        split_prepare(out, ctx, step, formulas, &starts, &entry_at, layout)?;
        step_accessors(out, places, step);
        return Ok(());
    }
    let (lets, exprs) = if exact { ctx.body(&step.roots)? } else { ctx.body_of(&step.roots, &step.swept)? };
    let dim = layout.dim;
    let mut at = 0;
    let mut next = |n: usize| {
        let part = exprs[at..at + n].to_vec();
        at += n;
        part
    };
    if exact {
        let _ = writeln!(out, "fn step_rows(s: &State) -> StepRows<DIM> {{");
    } else {
        let _ = writeln!(
            out,
            "/// The rows after the positions moved within a step: `prepare` (a `--step-only` module leaves out there\n\
             /// the bodies' 1/m and F where they read neither positions, velocities nor the time).\n\
             #[inline(always)]\n\
             fn prepare_moved(s: &State, p: &mut Prepared<DIM>) {{\n    prepare(s, p);\n}}\n\n\
             /// The rows at the state, flattened for the step into `p` (nothing allocated), with the scene's forces (`applied_forces`).\n\
             fn prepare(s: &State, p: &mut Prepared<DIM>) {{"
        );
    }
    for l in &lets {
        let _ = writeln!(out, "    {l}");
    }
    if exact {
        let _ = writeln!(
            out,
            "    let mut r = StepRows {{ rows: Vec::with_capacity({k}), inverse_mass: Vec::with_capacity({slots}), velocity: Vec::with_capacity({slots}), force: Vec::with_capacity({slots}), axes: Vec::new() }};",
        );
    } else {
        // The velocities the rows are evaluated at (∂C/∂t = Ċ − J·v), per slot.
        let _ = writeln!(out, "    let mut v = [[0.0; DIM]; SLOTS];");
    }
    for i in 0..n {
        let m = next(1);
        let (v, f) = (next(dim), next(dim));
        if exact {
            let _ = writeln!(out, "    r.inverse_mass.push(1.0 / {});", operand(&m[0]));
            let _ = writeln!(out, "    r.velocity.push({});\n    r.force.push({});", array(&v), array(&f));
            if three {
                let _ = writeln!(out, "    r.axes.push([0.0; DIM]);");
            }
        } else {
            let _ = writeln!(out, "    p.inverse_mass[{i}] = 1.0 / {};", operand(&m[0]));
            let _ = writeln!(out, "    v[{i}] = {};\n    p.force[{i}] = {};", array(&v), array(&f));
        }
    }
    for (r, &(first, is_3d)) in step.turns.iter().enumerate() {
        if is_3d {
            // I, ω, τ and the axes of the body, then its three axis slots (`axis_slots`).
            let (i, w, t) = (next(3), next(3), next(3));
            let e = [next(3), next(3), next(3)];
            let axes = array(&e.iter().map(|x| array(x)).collect::<Vec<_>>());
            let (i, w, t) = (array(&i), array(&w), array(&t));
            if exact {
                let _ =
                    writeln!(out, "    let axes_{r} = {axes};\n    push_axis_slots(&mut r, {i}, {w}, {t}, axes_{r});");
            } else {
                let _ = writeln!(
                    out,
                    "    let axes_{r} = {axes};\n    p.axis_slots(&mut v, {first}, {i}, {w}, {t}, axes_{r});"
                );
            }
        } else {
            let (i, w, t) = (next(1), next(1), next(1));
            if exact {
                let _ = writeln!(out, "    r.inverse_mass.push(1.0 / {});", operand(&i[0]));
                let _ = writeln!(out, "    r.velocity.push([{}, 0.0]);\n    r.force.push([{}, 0.0]);", w[0], t[0]);
            } else {
                let _ = writeln!(out, "    p.inverse_mass[{first}] = 1.0 / {};", operand(&i[0]));
                let _ = writeln!(out, "    v[{first}] = [{}, 0.0];\n    p.force[{first}] = [{}, 0.0];", w[0], t[0]);
            }
        }
    }
    for (r, (angular, start)) in step.angular_slots.iter().zip(&starts).enumerate() {
        let scalars = next(3);
        let mut js: Vec<String> =
            formulas.jacobian[r].iter().map(|&(body, _)| format!("({body}, {})", array(&next(dim)))).collect();
        for &slot in angular {
            if three {
                // Jʷ·eₖ: the axis' part of the world vector Jʷ (the library's `fill_jacobian`).
                let (rigid, axis) = step.axis_of(slot);
                js.push(format!("({slot}, [dot3(&axes_{rigid}[{axis}], &{}), 0.0, 0.0])", array(&next(dim))));
            } else {
                js.push(format!("({slot}, [{}, 0.0])", next(1)[0]));
            }
        }
        if exact {
            let _ = writeln!(
                out,
                "    r.rows.push(Row {{ value: {} * INVERSE_SCALE[{r}], rate: {} * INVERSE_SCALE[{r}], bias: {}, inequality: INEQUALITY[{r}], jacobian: vec!{} }});",
                operand(&scalars[0]),
                operand(&scalars[1]),
                scalars[2],
                array(&js)
            );
        } else {
            // The entries in the step's order (`ENTRY_AT`), as `p.row` stores and sums them.
            let mut kept = vec![String::new(); js.len()];
            for (e, j) in js.into_iter().enumerate() {
                kept[entry_at[start + e] - start] = j;
            }
            // A steady row's Ċ is not read (its code is left out: `swept`).
            let rate = if scalars[1].is_empty() {
                "0.0".to_string()
            } else {
                format!("{} * INVERSE_SCALE[{r}]", operand(&scalars[1]))
            };
            let _ = writeln!(
                out,
                "    p.row({r}, ({} * INVERSE_SCALE[{r}], {rate}), {start}, {}, &v);",
                operand(&scalars[0]),
                array(&kept)
            );
        }
    }
    if exact {
        let _ = writeln!(out, "    r\n}}\n");
    } else {
        if three {
            // The body-frame ω the gyroscopic terms were taken at, for the kick.
            let _ = writeln!(out, "    p.velocity = v;\n    p.first = first_angular(&p.axes);");
        }
        let _ = writeln!(out, "}}\n");
    }
    step_accessors(out, places, step);
    Ok(())
}

/// `prepare` and `prepare_moved` of a written-out module whose bodies' 1/m and F stay while
/// the positions move and whose rows read no velocity (`step_fns`): `prepare` writes the
/// bodies' numbers and each `UNIT` row's m_eff (`unit_masses`), then calls `prepare_moved`,
/// the rows alone (a `UNIT` row's m_eff by `unit_row`: no sum and no division). Each is
/// lowered over all the roots (so its shared values, and its numbers, are the library's) with
/// code for its part only.
fn split_prepare(
    out: &mut String,
    ctx: &Ctx<'_>,
    step: &StepRoots,
    formulas: &Formulas,
    starts: &[usize],
    entry_at: &[usize],
    layout: &Layout,
) -> Result<(), GenerateError> {
    let (n, dim) = (layout.bodies, layout.dim);
    // Per body m, v, F and per rigid body I, ω, τ: three roots each, then the rows'.
    let rows_from = 3 * (n + step.turns.len());
    let bodies: Vec<bool> = step.swept.iter().enumerate().map(|(i, &w)| w && i < rows_from && i % 3 != 1).collect();
    let rows: Vec<bool> = step.swept.iter().enumerate().map(|(i, &w)| w && i >= rows_from).collect();
    // A function's text, `s` marked used where its code reads no field.
    let function = |out: &mut String, head: &str, lets: &[String], body: &str| {
        let mut text: String = lets.iter().map(|l| format!("    {l}\n")).collect();
        text.push_str(body);
        let unused = if text.contains("s.") { "" } else { "    let _ = s;\n" };
        let _ = writeln!(out, "{head}\n{unused}{text}}}\n");
    };
    let (lets, exprs) = ctx.body_of(&step.roots, &bodies)?;
    let mut body = String::new();
    let mut at = 0;
    for i in 0..n {
        let _ = writeln!(body, "    p.inverse_mass[{i}] = 1.0 / {};", operand(&exprs[at]));
        let _ = writeln!(body, "    p.force[{i}] = {};", array(&exprs[at + 1 + dim..at + 1 + 2 * dim]));
        at += 1 + 2 * dim;
    }
    for &(first, _) in &step.turns {
        let _ = writeln!(body, "    p.inverse_mass[{first}] = 1.0 / {};", operand(&exprs[at]));
        let _ = writeln!(body, "    p.force[{first}] = [{}, 0.0];", exprs[at + 2]);
        at += 3;
    }
    if (0..layout.constraints).any(|r| step.pattern.is_unit(r)) {
        body.push_str("    p.unit_masses();\n");
    }
    body.push_str("    prepare_moved(s, p);\n");
    function(
        out,
        "/// The rows at the state, flattened for the step into `p` (nothing allocated): the bodies' 1/m and F (the\n\
         /// scene's, `applied_forces`) and each `UNIT` row's m_eff, then the rows (`prepare_moved`).\n\
         fn prepare(s: &State, p: &mut Prepared<DIM>) {",
        &lets,
        &body,
    );
    let (lets, exprs) = ctx.body_of(&step.roots, &rows)?;
    let mut body = String::new();
    for (r, (angular, &start)) in step.angular_slots.iter().zip(starts).enumerate() {
        let scalars = &exprs[at..at + 3];
        at += 3;
        let mut js = Vec::new();
        for &(b, _) in &formulas.jacobian[r] {
            js.push((b, array(&exprs[at..at + dim])));
            at += dim;
        }
        for &slot in angular {
            js.push((slot, format!("[{}, 0.0]", exprs[at])));
            at += 1;
        }
        // The entries in the step's order (`ENTRY_AT`).
        let mut kept = vec![(0, String::new()); js.len()];
        for (e, j) in js.into_iter().enumerate() {
            kept[entry_at[start + e] - start] = j;
        }
        let value = format!("{} * INVERSE_SCALE[{r}]", operand(&scalars[0]));
        if step.pattern.is_unit(r) {
            let js: Vec<String> = kept.into_iter().map(|(_, j)| j).collect();
            let _ = writeln!(body, "    p.value[{r}] = {value};");
            let _ = writeln!(body, "    p.effective_mass[{r}] = p.unit_row({r}, {start}, {});", array(&js));
        } else {
            let js: Vec<String> = kept.into_iter().map(|(b, j)| format!("({b}, {j})")).collect();
            let _ = writeln!(body, "    p.row({r}, ({value}, 0.0), {start}, {}, &[]);", array(&js));
        }
    }
    function(
        out,
        "/// The rows after the positions moved within a step: the rows alone (the bodies' 1/m and F read neither\n\
         /// positions, velocities nor the time).\n\
         fn prepare_moved(s: &State, p: &mut Prepared<DIM>) {",
        &lets,
        &body,
    );
    Ok(())
}

/// `--step-only`: the state, the step's constants, `positions` and `velocities`, the rows
/// by shape (`shapes::step_by_shape`) and the step's helpers; none of the formulas' functions.
/// With rigid bodies also `orientations` and `angular_velocities`, as the full module's.
fn step_module(
    loaded: &Loaded,
    options: &Options,
    d: &Derivation,
    formulas: &Formulas,
    scene: &SceneNumbers,
    plan: &Plan<'_>,
) -> Result<Module, GenerateError> {
    let (system, g, fields, layout) = (&loaded.system, &d.graph, &plan.fields, &plan.layout);
    let solver = options.solver.ok_or(GenerateError::StepOnly)?;
    let (dim, n) = (layout.dim, layout.bodies);
    let mut out = String::new();
    let flags = super::flags(options.specialize, Some(solver)) + " --step-only";
    opening(&mut out, plan.title, &flags);
    let _ = writeln!(
        out,
        "// {dim}D, {n} bodies, {} constraints; vectors are [f64; {dim}]. The velocity-level step only (`step`, \
         `step_with`): each repeated row shape is written once, over a table of its instances.\n",
        layout.constraints
    );
    let arrays = fields.iter().any(|f| f.array.is_some());
    if arrays {
        let _ = writeln!(
            out,
            "// State fields: time and parameters under their names; the bodies' positions, velocities, forces \
             and masses in the arrays `position`, `velocity`, `force`, `mass`, in file order{}.\n",
            if fields.iter().any(|f| f.array.is_some_and(|a| a.0 == "angle")) {
                "; the 2D rigid bodies' θ, ω, τ and inertias in `angle`, `angular_velocity`, `torque`, `inertia`, \
                 in the rigid bodies' file order"
            } else {
                ""
            }
        );
    } else {
        field_names(&mut out, g, fields);
    }
    state(&mut out, g, fields, layout);
    let listed: Vec<String> = plan.inequalities.iter().map(|b| b.to_string()).collect();
    let _ = writeln!(
        out,
        "/// Which constraints are inequalities `C ≥ 0`, in file order.\npub const INEQUALITY: [bool; {}] = {};\n",
        listed.len(),
        array(&listed)
    );
    let slots = slot_exprs(g, fields);
    let input_layout = Inputs::new(g, &plan.inputs())?;
    let budget = code_budget(system);
    let ctx = Ctx {
        g,
        inputs: &input_layout,
        slots: &slots,
        non_finite: Cell::new(0),
        c: false,
        room: Cell::new(budget),
        budget,
    };
    let places = StepPlaces::of(system, fields, &scene.turns);
    // Positions and velocities per body, as the full module's functions give them.
    for (name, what, idents) in
        [("positions", "position", &places.position), ("velocities", "velocity", &places.velocity)]
    {
        let _ = writeln!(
            out,
            "/// The {what} of each body, in file order.\npub fn {name}(s: &State) -> [[f64; {dim}]; {n}] {{"
        );
        if arrays {
            let _ = writeln!(out, "    s.{what}\n}}\n");
        } else {
            let items: Vec<String> = idents.iter().map(|i| format!("s.{i}")).collect();
            let _ = writeln!(out, "    {}\n}}\n", array(&items));
        }
    }
    // The rigid bodies' orientations and ω, in the order of their slots, as the full module's
    // functions give them (2D: θ and ω; 3D: q and the world ω).
    if !places.turn.is_empty() {
        let three = !scene.turns.three.is_empty();
        let (q, w) = if three { ("[f64; 4]", "[f64; 3]") } else { ("f64", "f64") };
        let r = places.turn.len();
        for (name, what, ty, at) in [("orientations", "orientation", q, 0), ("angular_velocities", "ω", w, 1)] {
            let items: Vec<String> =
                places.turn.iter().map(|t| format!("s.{}", if at == 0 { t.0 } else { t.1 })).collect();
            // A role array in the order of the rigid bodies is returned whole.
            let role = if at == 0 { "angle" } else { "angular_velocity" };
            let whole = items.iter().enumerate().all(|(i, x)| *x == format!("s.{role}[{i}]"));
            let value = if whole { format!("s.{role}") } else { array(&items) };
            let _ = writeln!(
                out,
                "/// The {what} of each rigid body, in file order.\npub fn {name}(s: &State) -> [{ty}; {r}] {{\n    {value}\n}}\n"
            );
        }
    }
    let step = StepRoots::of(&loaded.system, g, layout, &scene.masses, &scene.bodies, &scene.turns, formulas);
    super::shapes::step_by_shape(
        &mut out,
        &ctx,
        system,
        fields,
        solver,
        &inverse_scales(d),
        &places,
        formulas,
        layout,
        &step,
        arrays,
    )?;
    helper_texts(&mut out, Some(solver), !scene.turns.three.is_empty());
    let mut warnings = Vec::new();
    if ctx.non_finite.get() > 0 {
        warnings.push(format!(
            "constants of the formulas do not fit in f64 (written as f64::INFINITY, or NaN; {} place(s) in the code)",
            ctx.non_finite.get()
        ));
    }
    Ok(Module { code: out, fields: fields.iter().map(|f| (f.symbol, f.ident.clone())).collect(), warnings })
}

/// The step's constants: `SOLVER`, `DEFAULT_ITERATIONS`, `INVERSE_SCALE`, the slots
/// (`SLOTS`, `ORIENTATIONS`, `AXES`), and where each row's Jacobian entries are (`ENTRIES`,
/// `ROW_START`, `ROW_BODY`, over the slots, and `ENTRY_AT`); returns `ROW_START` and `ENTRY_AT`.
pub(super) fn step_constants(
    out: &mut String,
    solver: Solver,
    inverse_scales: &[f64],
    step: &StepRoots,
    formulas: &Formulas,
    layout: &Layout,
) -> (Vec<usize>, Vec<usize>) {
    let k = layout.constraints;
    let slots = step.slots(layout.bodies);
    let three = step.three();
    let _ = writeln!(
        out,
        "/// The velocity-level solver of `step` (`lagrange generate --solver {0}`).\n\
         pub const SOLVER: &str = \"{0}\";\n\
         /// Iterations per substep of `StepSettings::default()` for this solver.\n\
         pub const DEFAULT_ITERATIONS: usize = {1};\n\
         /// 1/κ of each constraint, as the rows of the step scale C and Ċ (C/κ = C·INVERSE_SCALE[k]).\n\
         pub const INVERSE_SCALE: [f64; {k}] = {2};\n\
         /// The step's slots: {3}.\n\
         pub const SLOTS: usize = {slots};\n\
         /// The 3D rigid bodies, whose orientations q₀ the step turns from.\n\
         const ORIENTATIONS: usize = {three};\n\
         /// The slots whose principal axes the rows carry (all of them with 3D rigid bodies, else none).\n\
         const AXES: usize = {4};\n",
        solver.name(),
        solver.default_iterations(),
        array(&inverse_scales.iter().map(|x| format!("{x:?}")).collect::<Vec<_>>()),
        if three > 0 {
            "the bodies, then three per rigid body, one per principal axis eₖ = R(q) eₖ (1/Iₖ, eₖ·ω, eₖ·τ − (ω_b × I ω_b)ₖ, Jʷ·eₖ)"
        } else if !step.turns.is_empty() {
            "the bodies, then one per rigid body (1/I, ω, τ and Jʷ in component 0)"
        } else {
            "the bodies (no rigid body here)"
        },
        if three > 0 { slots } else { 0 }
    );
    // Where each row's entries are, as `Prepared` reads them.
    let (starts, bodies, at) = step.entries(formulas);
    let list = |xs: &[usize]| array(&xs.iter().map(usize::to_string).collect::<Vec<_>>());
    let _ = writeln!(
        out,
        "/// Jacobian entries of all rows; row k's are `ROW_START[k]..ROW_START[k + 1]`, entry e on slot `ROW_BODY[e]`, in the\n\
         /// step's order (the last term of a row's Ċ the velocity the row before wrote last: `velocity::entry_order`).\n\
         const ENTRIES: usize = {};\n\
         const ROW_START: [usize; {}] = {};\n\
         const ROW_BODY: [usize; {}] = {};\n\
         /// Per entry in the derivation's order (a row's bodies, then its angular slots), its place in the step's.\n\
         #[allow(dead_code)]\n\
         const ENTRY_AT: [usize; {}] = {};\n\
         /// Per row, whether its C reads no time: ∂C/∂t = 0 exactly (`numeric::velocity::steady_rows`).\n\
         #[allow(dead_code)]\n\
         const STEADY: [bool; {k}] = {};\n\
         /// Per row, whether every entry of its J is a unit vector, ±e/|e| (`numeric::velocity::pattern`): its |Jᵢ|² is\n\
         /// taken as exactly 1 (`unit_square`), so its m_eff is 1/Σᵢ 1/mᵢ, a constant of the masses.\n\
         #[allow(dead_code)]\n\
         const UNIT: [bool; {k}] = {};\n",
        bodies.len(),
        k + 1,
        list(&starts),
        bodies.len(),
        list(&bodies),
        at.len(),
        list(&at),
        array(&step.steady.iter().map(bool::to_string).collect::<Vec<_>>()),
        array(&(0..k).map(|r| step.pattern.is_unit(r).to_string()).collect::<Vec<_>>())
    );
    let axis: Vec<bool> = (0..k).map(|r| step.pattern.is_axis(r)).collect();
    row_kinds(out, &step.codes(&starts, &bodies, &at), &starts, &axis, layout.dim);
    (starts, at)
}

/// A component code's mask (`ENTRY_CODE` → `ENTRY_MASK`): bit d where component d is not a
/// structural zero.
pub(super) fn entry_mask(code: u8) -> u8 {
    (0..3).filter(|d| code >> (2 * d) & 3 != 0).fold(0, |m, d| m | 1 << d)
}

/// Each row's kind, the codes of its entries (`ROW_KIND`, at most `MAX_ROW_KINDS` of them;
/// the others read `ENTRY_CODE` as they run), and `Prepared::rate` and `Prepared::apply` by
/// kind: each kind's call takes its codes as constants, so its products are written for its
/// pattern — no branch on a component, no product by a structural zero or by ±1 (x·1 = x
/// and x·(−1) = −x exactly: the same bits without the multiplication). A kind whose every
/// component is some other number keeps the loop over the row's entries (`rate_dense`:
/// unrolled, the compiler packs two entries' products into one vector and lengthens the
/// path from the row before's impulse), but for an axis row (`axis`, `velocity::pattern`:
/// two entries J and −J, bit for bit), whose Ċ and impulse read one axis (`rate_axis`,
/// `apply_axis`), as a handwritten distance joint keeps one.
fn row_kinds(out: &mut String, codes: &[u8], starts: &[usize], axis: &[bool], dim: usize) {
    let dense = (0..dim).fold(0u8, |c, d| c | 1 << (2 * d));
    let mut kinds: Vec<(&[u8], bool)> = Vec::new();
    let mut row_kind = Vec::with_capacity(starts.len().saturating_sub(1));
    for (r, w) in starts.windows(2).enumerate() {
        let c = &codes[w[0]..w[1]];
        let c = (c, axis.get(r).copied().unwrap_or(false) && c.len() == 2 && c.iter().all(|&x| x == dense));
        let kind = match kinds.iter().position(|k| *k == c) {
            Some(i) => i,
            None if kinds.len() < MAX_ROW_KINDS => {
                kinds.push(c);
                kinds.len() - 1
            }
            None => MAX_ROW_KINDS,
        };
        row_kind.push(kind);
    }
    let list = |xs: &mut dyn Iterator<Item = String>| array(&xs.collect::<Vec<_>>());
    let _ = writeln!(
        out,
        "/// Per entry (in the step's order), two bits per component of its J: 0 a structural zero of the rows as written\n\
         /// (`numeric::velocity::pattern`, left out of Ċ and an impulse), 2 the constant +1, 3 the constant −1, 1 any other.\n\
         #[allow(dead_code)]\n\
         const ENTRY_CODE: [u8; {}] = {};\n\
         /// Per row, its kind: the `ENTRY_CODE` of its entries and whether it is an axis row (two entries J and −J), one\n\
         /// pattern per kind (`Prepared::rate`, `Prepared::apply`){}.\n\
         #[allow(dead_code)]\n\
         const ROW_KIND: [u8; {}] = {};\n",
        codes.len(),
        list(&mut codes.iter().map(u8::to_string)),
        if row_kind.contains(&MAX_ROW_KINDS) {
            format!("; {MAX_ROW_KINDS}: a row past the kinds written, its codes read from `ENTRY_CODE`")
        } else {
            String::new()
        },
        row_kind.len(),
        list(&mut row_kind.iter().map(usize::to_string)),
    );
    // The arms: each kind's codes; the last kind takes every other value when no row is past
    // the kinds written (one kind: no branch).
    let overflow = row_kind.contains(&MAX_ROW_KINDS);
    let arms = |coded: &str, loop_: &str, axis: &str| {
        let call = |&(k, one_axis): &(&[u8], bool)| {
            if one_axis {
                axis.to_string()
            } else if k.iter().all(|&c| c == dense) {
                loop_.to_string()
            } else if k.len() <= 16 {
                // The codes as one constant, a byte each from the lowest (`rate_of`).
                let bytes = k.iter().rev().map(|c| format!("{c:02x}")).collect::<Vec<_>>().join("_");
                coded.replace("_in(k, CODES", &format!("_of::<{}, 0x{bytes}>(k", k.len()))
            } else {
                coded.replace("CODES", &format!("&{}", list(&mut k.iter().map(u8::to_string))))
            }
        };
        // Without rows past the kinds, the last kind's arm is `_` and takes every kind with
        // the same call (all dense kinds: the loop, no branch).
        let last = (!overflow).then(|| kinds.last().map(&call)).flatten();
        let mut arms = Vec::new();
        for (i, k) in kinds.iter().enumerate() {
            let call = call(k);
            if i + 1 == kinds.len() && !overflow {
                arms.push(format!("_ => {call}"));
            } else if last.as_ref() != Some(&call) {
                arms.push(format!("{i} => {call}"));
            }
        }
        if overflow || kinds.is_empty() {
            arms.push(format!("_ => {}", coded.replace("CODES", "&ENTRY_CODE[ROW_START[k]..ROW_START[k + 1]]")));
        }
        // One arm: the call itself.
        match &arms[..] {
            [one] => format!("{}\n", one.trim_start_matches("_ => ")),
            _ => format!(
                "match ROW_KIND[k] {{\n{}        }}\n",
                arms.iter().map(|a| format!("            {a},\n")).collect::<String>()
            ),
        }
    };
    let _ = writeln!(
        out,
        "#[allow(dead_code)]\n\
         impl Prepared<DIM> {{\n    \
         /// Ċₖ at velocities `u` (`rate_in`), with row k's codes as its kind's constants.\n    \
         #[inline(always)]\n    \
         fn rate(&self, k: usize, u: &[[f64; DIM]]) -> f64 {{\n        \
         {}    \
         }}\n\n    \
         /// Applies an impulse `p` of row k (`apply_in`), with its codes as its kind's constants.\n    \
         #[inline(always)]\n    \
         fn apply(&self, k: usize, u: &mut [[f64; DIM]], p: f64) {{\n        \
         {}    \
         }}\n\n    \
         /// Σᵢ |Jᵢ|²/mᵢ of row k (`mass_in`), with its codes as its kind's constants.\n    \
         #[inline(always)]\n    \
         fn mass(&self, k: usize) -> f64 {{\n        \
         {}    \
         }}\n\
         }}\n",
        arms("self.rate_in(k, CODES, u)", "self.rate_dense(k, u)", "self.rate_axis(k, u)"),
        arms("self.apply_in(k, CODES, u, p)", "self.apply_dense(k, u, p)", "self.apply_axis(k, u, p)"),
        arms("self.mass_in(k, CODES)", "self.mass_dense(k)", "self.mass_dense(k)")
    );
}

/// Past this many comparisons `same_inputs` is a list of statements, not one expression:
/// rustc parses a chain of `&&` by recursion, and 20 000 of them (a 100 × 100 grid of rigid
/// discs, one per angle and torque field) overflow its default stack.
const SAME_CHAIN_MAX: usize = 64;

/// The body of `same_inputs` from its comparisons.
fn same_body(same: &[String]) -> String {
    match same.len() {
        0 => "let _ = (a, b);\n    true".to_string(),
        n if n <= SAME_CHAIN_MAX => same.join("\n        && "),
        _ => {
            let each: Vec<String> = same.iter().map(|s| format!("all &= {s};")).collect();
            format!("let mut all = true;\n    {}\n    all", each.join("\n    "))
        }
    }
}

/// The state's accessors the step's text calls: `time`, `get` (the state's slots) and `put`.
pub(super) fn step_accessors(out: &mut String, places: &StepPlaces<'_>, step: &StepRoots) {
    let same: Vec<String> = places.inputs.iter().map(|(a, b)| format!("same({a}, {b})")).collect();
    let _ = writeln!(
        out,
        "/// Whether the rows read neither the velocities nor the time, so that the rows a step leaves serve the next\n\
         /// step's start while the state's other fields are unchanged (`Stepper`).\n\
         #[allow(dead_code)]\n\
         const KEEP: bool = {};\n\n\
         /// Whether the fields of `a` the rows read are those of `b` bit for bit: every field but the time and the\n\
         /// velocities.\n\
         #[allow(dead_code)]\n\
         fn same_inputs(a: &State, b: &State) -> bool {{\n    {}\n}}\n\n\
         /// The same bits in `a` and `b`, compared without a branch per number.\n\
         #[allow(dead_code)]\n\
         fn same(a: &[f64], b: &[f64]) -> bool {{\n    \
         a.iter().zip(b).fold(true, |same, (x, y)| same & (x.to_bits() == y.to_bits()))\n}}\n",
        step.keep,
        same_body(&same)
    );
    let time = places.time.map_or("0.0".to_string(), |t| format!("s.{t}"));
    let _ = writeln!(out, "/// The state's time (0 when the file's state has none).\nfn time(s: &State) -> f64 {{");
    let _ = writeln!(out, "    {}{time}\n}}\n", if places.time.is_none() { "let _ = s;\n    " } else { "" });
    // The state's slots: per body x and v; per 2D rigid body [θ, 0] and [ω, 0]; per 3D one the
    // rotation vector φ since the orientation q₀ (zero) and the world ω, then two empty slots.
    let (mut q, mut v, mut put) = (Vec::new(), Vec::new(), Vec::new());
    for (p, w) in places.position.iter().zip(&places.velocity) {
        q.push(format!("s.{p}"));
        v.push(format!("s.{w}"));
    }
    let mut orientations = Vec::new();
    for (r, (&(first, is_3d), &(o, w))) in step.turns.iter().zip(&places.turn).enumerate() {
        if is_3d {
            q.extend(["[0.0; 3]".to_string(), "[0.0; 3]".to_string(), "[0.0; 3]".to_string()]);
            v.extend([format!("s.{w}"), "[0.0; 3]".to_string(), "[0.0; 3]".to_string()]);
            put.push((format!("s.{o} = turned(q[{first}], q0[{r}]);"), format!("s.{w} = v[{first}];")));
            orientations.push(format!("s.{o}"));
        } else {
            q.push(format!("[s.{o}, 0.0]"));
            v.push(format!("[s.{w}, 0.0]"));
            put.push((format!("s.{o} = q[{first}][0];"), format!("s.{w} = v[{first}][0];")));
        }
    }
    let n = places.position.len();
    // Bodies and 2D rigid bodies in role arrays, the r-th rigid body at slot n + r: `get` and
    // `put` copy the arrays.
    let arrays = places.position.iter().enumerate().all(|(i, p)| *p == format!("position[{i}]"))
        && places.velocity.iter().enumerate().all(|(i, v)| *v == format!("velocity[{i}]"));
    let rigid_arrays = arrays
        && !step.turns.is_empty()
        && step.turns.iter().zip(&places.turn).enumerate().all(|(r, (&(first, is_3d), &(o, w)))| {
            !is_3d && first == n + r && o == format!("angle[{r}]") && w == format!("angular_velocity[{r}]")
        });
    // Point masses: the slots are the positions and velocities as the module gives them.
    let slots = if step.turns.is_empty() {
        format!("(positions(s), velocities(s), {})", array(&orientations))
    } else if rigid_arrays {
        format!(
            "let (mut q, mut v) = ([[0.0; DIM]; SLOTS], [[0.0; DIM]; SLOTS]);\n    \
             q[..{n}].copy_from_slice(&s.position);\n    v[..{n}].copy_from_slice(&s.velocity);\n    \
             for (x, a) in q[{n}..].iter_mut().zip(&s.angle) {{\n        *x = [*a, 0.0];\n    }}\n    \
             for (x, w) in v[{n}..].iter_mut().zip(&s.angular_velocity) {{\n        *x = [*w, 0.0];\n    }}\n    \
             (q, v, [])"
        )
    } else {
        format!("({}, {}, {})", array(&q), array(&v), array(&orientations))
    };
    let _ = writeln!(
        out,
        "/// The state's slots as the step moves them (the library's `numeric::simulate::initial_state`): per body x and v,\n\
         /// then per rigid body [θ, 0] and [ω, 0] (3D: the rotation vector φ = 0 since its orientation q₀ and the world ω,\n\
         /// then two empty slots), and the 3D rigid bodies' orientations q₀.\n\
         #[allow(clippy::type_complexity)]\n\
         fn get(s: &State) -> ([[f64; DIM]; SLOTS], [[f64; DIM]; SLOTS], [[f64; 4]; ORIENTATIONS]) {{\n    \
         {slots}\n}}\n"
    );
    // `put_moved`'s lines (the time, the positions with the orientations), then `put`'s own (the
    // velocities).
    let mut time_line = match places.time {
        Some(field) => format!("    s.{field} = t;\n"),
        None => "    let _ = t;\n".to_string(),
    };
    if orientations.is_empty() {
        time_line.push_str("    let _ = q0;\n");
    }
    let (mut positions, mut velocities) = (String::new(), String::new());
    if arrays && step.turns.is_empty() {
        positions.push_str("    s.position.copy_from_slice(q);\n");
        velocities.push_str("    s.velocity.copy_from_slice(v);\n");
    } else if arrays {
        let _ = writeln!(positions, "    s.position.copy_from_slice(&q[..{n}]);");
        let _ = writeln!(velocities, "    s.velocity.copy_from_slice(&v[..{n}]);");
    } else {
        for (i, (p, v)) in places.position.iter().zip(&places.velocity).enumerate() {
            let _ = writeln!(positions, "    s.{p} = q[{i}];");
            let _ = writeln!(velocities, "    s.{v} = v[{i}];");
        }
    }
    if rigid_arrays {
        let _ =
            writeln!(positions, "    for (a, x) in s.angle.iter_mut().zip(&q[{n}..]) {{\n        *a = x[0];\n    }}");
        let _ = writeln!(
            velocities,
            "    for (w, x) in s.angular_velocity.iter_mut().zip(&v[{n}..]) {{\n        *w = x[0];\n    }}"
        );
    } else {
        for (o, w) in &put {
            let _ = writeln!(positions, "    {o}");
            let _ = writeln!(velocities, "    {w}");
        }
    }
    let _ = writeln!(
        out,
        "/// Writes the time and the slots into the state (3D: the orientation exp(φ) ⊗ q₀).\n\
         fn put(s: &mut State, t: f64, q: &[[f64; DIM]; SLOTS], v: &[[f64; DIM]; SLOTS], q0: &[[f64; 4]; ORIENTATIONS]) {{\n    \
         put_moved(s, t, q, q0);\n\
         {velocities}}}\n\n\
         /// `put` but for the velocities: the time and the positions (and orientations) after a substep's drift, all\n\
         /// where the rows read no velocity (`KEEP`) need; the step writes the velocities once, after its last substep.\n\
         fn put_moved(s: &mut State, t: f64, q: &[[f64; DIM]; SLOTS], q0: &[[f64; 4]; ORIENTATIONS]) {{\n\
         {time_line}{positions}}}\n"
    );
}

/// An expression as the operand of `*` or `/`: parenthesised unless it is a name, a field,
/// an index or a number.
fn operand(e: &str) -> String {
    if e.chars().all(|c| c.is_alphanumeric() || matches!(c, '_' | '.' | '[' | ']')) {
        e.to_string()
    } else {
        format!("({e})")
    }
}

/// The loop that fills `rows[k].jacobian` from J as the layout stores it.
fn row_jacobians(out: &mut String, layout: &Layout) {
    match layout.j {
        JStorage::Blocks { .. } => {
            let _ = writeln!(
                out,
                "    for (k, i, d) in jacobian_blocks(s) {{\n        rows[k].jacobian.push((i, d));\n    }}"
            );
        }
        JStorage::Dense => {
            let _ = writeln!(out, "    let j = jacobian(s);");
            let _ = writeln!(out, "    for (k, i) in JACOBIAN_BODIES {{");
            let _ = writeln!(
                out,
                "        rows[k].jacobian.push((i, std::array::from_fn(|d| j[k][i * DIM + d])));\n    }}"
            );
        }
    }
}

/// The names of the file's bodies and constraints, in file order.
pub(super) struct Names<'a> {
    pub(super) bodies: &'a [&'a str],
    pub(super) constraints: &'a [&'a str],
}

/// Each body's numbers as graph nodes, in file order: what the rows' solve reads.
pub(super) struct Bodies {
    /// The scene's force expression per body (zero where it gives none).
    pub(super) applied: Vec<Id>,
    pub(super) position: Vec<Id>,
    pub(super) velocity: Vec<Id>,
    pub(super) force: Vec<Id>,
    pub(super) inverse_mass: Vec<Id>,
}

/// The rigid bodies' numbers as graph nodes, in the order of their angular slots (the file's
/// order of the rigid bodies): what the rows' solve reads beside [`Bodies`].
#[derive(Default)]
pub(super) struct Turns {
    /// The body index of each rigid body.
    pub(super) body: Vec<usize>,
    pub(super) orientation: Vec<Id>,
    pub(super) angular_velocity: Vec<Id>,
    /// The state's torque symbol.
    pub(super) torque: Vec<Id>,
    /// The scene's torque expression (zero where it gives none).
    pub(super) applied: Vec<Id>,
    pub(super) inverse_inertia: Vec<Id>,
    /// I (3D: the principal moments, a vector), the root the library's rows invert.
    pub(super) inertia: Vec<Id>,
    /// 3D rigid bodies (empty in 2D): each one's three slots are axis slots, and the
    /// entries of Jʷ are `projected`.
    pub(super) three: Vec<Turn3>,
    /// 3D: `(constraint, slot, Jʷ·eₖ)` for every slot a row turns.
    pub(super) projected: Vec<(usize, usize, Id)>,
}

/// A 3D rigid body: three angular slots from `first_slot`, one per principal axis.
pub(super) struct Turn3 {
    pub(super) body: usize,
    pub(super) first_slot: usize,
    /// The quaternion [w, x, y, z].
    pub(super) orientation: Symbol,
    /// ω, τ (world frame), the scene's τ expression (zero where it gives none).
    pub(super) angular_velocity: Id,
    pub(super) torque: Id,
    pub(super) applied: Id,
    /// The principal axes R(q) eₖ.
    pub(super) axes: [Id; 3],
}

impl Turns {
    /// The rigid bodies, each once (a 3D body has three slots).
    pub(super) fn rigid_bodies(&self) -> Vec<usize> {
        let mut out: Vec<usize> = Vec::new();
        for &b in &self.body {
            if out.last() != Some(&b) {
                out.push(b);
            }
        }
        out
    }

    /// The angular slot (index among the rigid bodies) of body `body`, if it is rigid.
    pub(super) fn slot(&self, body: usize) -> Option<usize> {
        self.body.iter().position(|&b| b == body)
    }

    /// `(constraint, slot, Jʷ)` for every angular entry of J, by constraint.
    pub(super) fn entries(&self, formulas: &Formulas) -> Vec<(usize, usize, Id)> {
        if !self.three.is_empty() {
            return self.projected.clone();
        }
        let mut out = Vec::new();
        for (k, dirs) in formulas.angular.iter().enumerate() {
            out.extend(dirs.iter().filter_map(|&(b, id)| self.slot(b).map(|r| (k, r, id))));
        }
        out
    }
}

/// `rows`: the constraint rows at a state (C/κ, Ċ/κ, c, J per body), as `lagrange solve`
/// reads them. The bodies of each row are the derivation's, listed in `JACOBIAN_BODIES`
/// for a dense J; a sparse J lists them itself. A rigid body's Jʷ follows in its angular
/// slot `BODIES + r` (component 0), as `numeric::rows` places it.
fn rows_fn(out: &mut String, formulas: &Formulas, layout: &Layout, turns: &Turns) {
    let _ = writeln!(
        out,
        "/// The constraint rows at a state, as `lagrange solve` reads them: C/κ, Ċ/κ, c and J = ∇C/κ per body{}.",
        if turns.body.is_empty() {
            ""
        } else if !turns.three.is_empty() {
            " (then Jʷ·eₖ of rigid body r's principal axis k in slot BODIES + 3r + k, component 0)"
        } else {
            " (then Jʷ of rigid body r in slot BODIES + r, component 0)"
        }
    );
    let _ = writeln!(out, "pub fn rows(s: &State) -> Vec<Row<DIM>> {{");
    let _ = writeln!(out, "    let (c, rate, bias) = (constraints(s), constraint_rates(s), c_term(s));");
    let _ = writeln!(
        out,
        "    let mut rows: Vec<Row<DIM>> = (0..CONSTRAINTS)\n        \
         .map(|k| Row {{ value: c[k] / SCALE[k], rate: rate[k] / SCALE[k], bias: bias[k], inequality: INEQUALITY[k], jacobian: Vec::new() }})\n        \
         .collect();"
    );
    row_jacobians(out, layout);
    if !turns.body.is_empty() {
        let (call, pattern, value) = match layout.j {
            JStorage::Blocks { .. } => ("angular_jacobian_blocks(s)", "(k, r, w)", "w"),
            JStorage::Dense => ("ANGULAR_ENTRIES", "(k, r)", "jw[k][r]"),
        };
        if layout.j == JStorage::Dense {
            let _ = writeln!(out, "    let jw = angular_jacobian(s);");
        }
        let _ = writeln!(
            out,
            "    for {pattern} in {call} {{\n        let mut x = [0.0; DIM];\n        x[0] = {value};\n        \
             rows[k].jacobian.push((BODIES + r, x));\n    }}"
        );
    }
    let _ = writeln!(out, "    rows\n}}\n");
    if layout.j == JStorage::Dense {
        let pairs: Vec<String> = formulas
            .jacobian
            .iter()
            .enumerate()
            .flat_map(|(k, dirs)| dirs.iter().map(move |&(i, _)| format!("({k}, {i})")))
            .collect();
        let _ = writeln!(
            out,
            "/// The (constraint, body) pairs of J's structure: body i appears in constraint k's C.\n\
             const JACOBIAN_BODIES: [(usize, usize); {}] = {};\n",
            pairs.len(),
            array(&pairs)
        );
        if !turns.body.is_empty() {
            let pairs: Vec<String> = turns.entries(formulas).iter().map(|&(k, r, _)| format!("({k}, {r})")).collect();
            let _ = writeln!(
                out,
                "/// The (constraint, rigid body) pairs of Jʷ's structure: rigid body r's angle appears in constraint k's C.\n\
                 const ANGULAR_ENTRIES: [(usize, usize); {}] = {};\n",
                pairs.len(),
                array(&pairs)
            );
        }
    }
    if !turns.three.is_empty() {
        let _ = writeln!(
            out,
            "/// λ, the constraint forces and torques and the accelerations at a state, with each inequality's contact\n\
             /// state and the status: what `lagrange solve` gives (see `solve_rows`). The solve runs over slots: the\n\
             /// bodies (1/m, v, F), then three per rigid body r, one per principal axis eₖ = R(q) eₖ at BODIES + 3r + k\n\
             /// (1/Iₖ, eₖ·ω and eₖ·τ − (ω_b × I ω_b)ₖ in component 0), so M stays diagonal; `force` and `acceleration`\n\
             /// there hold the axis' part of the constraint torque and of α (`torques`, `angular_accelerations` turn\n\
             /// them back into the world). Rigid bodies are solved in the file's length unit.\n\
             pub fn solution(s: &State) -> Solution<DIM> {{\n    \
             let slot = |x: f64| {{\n        let mut v = [0.0; DIM];\n        v[0] = x;\n        v\n    }};\n    \
             let mut w = inverse_masses(s).to_vec();\n    \
             w.extend(axis_inverse_inertias(s));\n    \
             let mut v = velocities(s).to_vec();\n    \
             v.extend(axis_angular_velocities(s).map(slot));\n    \
             let mut f = external_forces(s).to_vec();\n    \
             f.extend(axis_torques(s).map(slot));\n    \
             solve_rows(&rows(s), &w, &v, &f, length_scale(&positions(s)))\n}}\n"
        );
        return;
    }
    if !turns.body.is_empty() {
        let _ = writeln!(
            out,
            "/// λ, the constraint forces and torques and the accelerations at a state, with each inequality's contact\n\
             /// state and the status: what `lagrange solve` gives (see `solve_rows`). The solve runs over slots: the\n\
             /// bodies (1/m, v, F), then one angular slot per rigid body (1/I, ω, τ in component 0), so `force` and\n\
             /// `acceleration` hold the constraint torque and α of rigid body r at `BODIES + r`, component 0. Rigid\n\
             /// bodies are solved in the file's length unit (an angle does not scale with it).\n\
             pub fn solution(s: &State) -> Solution<DIM> {{\n    \
             let slot = |x: f64| {{\n        let mut v = [0.0; DIM];\n        v[0] = x;\n        v\n    }};\n    \
             let mut w = inverse_masses(s).to_vec();\n    \
             w.extend(inverse_inertias(s));\n    \
             let mut v = velocities(s).to_vec();\n    \
             v.extend(angular_velocities(s).map(slot));\n    \
             let mut f = external_forces(s).to_vec();\n    \
             f.extend(external_torques(s).map(slot));\n    \
             solve_rows(&rows(s), &w, &v, &f, length_scale(&positions(s)))\n}}\n"
        );
        return;
    }
    let _ = writeln!(
        out,
        "/// λ, the constraint forces and the accelerations at a state, with each inequality's contact state and\n\
         /// the status: what `lagrange solve` gives (see `solve_rows`). Where the numbers overflow, it solves in a\n\
         /// length unit 2ᵏ that brings the largest length-like number near 1, verified homogeneous, and scales back.\n\
         pub fn solution(s: &State) -> Solution<DIM> {{\n    \
         let (r, w, v, f) = (rows(s), inverse_masses(s), velocities(s), external_forces(s));\n    \
         let raw = solve_rows(&r, &w, &v, &f, length_scale(&positions(s)));\n    \
         let big = length_like(s);\n    \
         if rows_finite(&r, &w, &v, &f) || !(big > 0.0 && big.is_finite()) {{\n        return raw;\n    }}\n    \
         let k = big.log2().floor() as i64;\n    \
         let (at, half) = (scaled_state(s, -k), scaled_state(s, -k - 1));\n    \
         let (r, w, v, f) = (rows(&at), inverse_masses(&at), velocities(&at), external_forces(&at));\n    \
         let r_half = rows(&half);\n    \
         if !rows_finite(&r, &w, &v, &f) || !rows_finite(&r_half, &w, &v, &f) {{\n        return raw;\n    }}\n    \
         let Some(p) = degrees(&r, &r_half) else {{\n        return raw;\n    }};\n    \
         let mut x = solve_rows(&r, &w, &v, &f, length_scale(&positions(&at)));\n    \
         for y in x.force.iter_mut().chain(x.acceleration.iter_mut()) {{\n        *y = y.map(|c| pow2(c, k));\n    }}\n    \
         for (q, l) in x.lambda.iter_mut().enumerate() {{\n        *l = pow2(*l, -k * (p[q] - 2));\n    }}\n    \
         x\n}}\n"
    );
}

/// A length-like place of `State`: a field (`vector` when it is one), or a whole role array
/// of vectors (`array`, named by its first field) where the layout holds bodies in arrays.
pub(super) struct LengthPlace {
    pub(super) field: usize,
    pub(super) vector: bool,
    pub(super) array: Option<&'static str>,
}

/// The state's length-like places (positions, velocities, forces, and the parameters no mass
/// depends on), as `numeric::rescale` chooses them, in field order (a role array once).
pub(super) fn length_places(g: &Graph, fields: &[Field], mass_symbols: &FastSet<Symbol>) -> Vec<LengthPlace> {
    let mut places = Vec::new();
    let mut arrays = FastSet::default();
    for (i, f) in fields.iter().enumerate() {
        let info = g.symbol(f.symbol);
        let length = match info.role {
            Role::Position { .. } | Role::Velocity { .. } | Role::Force { .. } => true,
            Role::Parameter => !mass_symbols.contains(&f.symbol),
            _ => false,
        };
        if !length {
            continue;
        }
        match f.array {
            Some((name, _)) => {
                if arrays.insert(name) {
                    places.push(LengthPlace { field: i, vector: true, array: Some(name) });
                }
            }
            None => places.push(LengthPlace { field: i, vector: info.ty == Ty::Vector, array: None }),
        }
    }
    places
}

/// `scaled_state` and `length_like`: the state's length-like fields (positions,
/// velocities, forces, and the parameters no mass depends on), as `numeric::rescale`
/// chooses them.
fn scaling_fns(out: &mut String, g: &Graph, fields: &[Field], mass_symbols: &FastSet<Symbol>) {
    let places: Vec<(String, bool, bool)> = length_places(g, fields, mass_symbols)
        .into_iter()
        .map(|p| match p.array {
            Some(name) => (name.to_string(), true, true),
            None => (fields[p.field].ident.clone(), p.vector, false),
        })
        .collect();
    let _ = writeln!(
        out,
        "/// The state with its length-like fields (positions, velocities, forces, parameters no mass depends on) × 2ᵉ."
    );
    let _ = writeln!(out, "pub fn scaled_state(s: &State, e: i64) -> State {{\n    let mut x = *s;");
    for (place, vector, array) in &places {
        let _ = match (vector, array) {
            (_, true) => writeln!(out, "    x.{place} = x.{place}.map(|r| r.map(|y| pow2(y, e)));"),
            (true, false) => writeln!(out, "    x.{place} = x.{place}.map(|y| pow2(y, e));"),
            (false, false) => writeln!(out, "    x.{place} = pow2(x.{place}, e);"),
        };
    }
    if places.is_empty() {
        let _ = writeln!(out, "    let _ = e;");
    }
    let _ = writeln!(out, "    x\n}}\n");
    let _ =
        writeln!(out, "/// The largest |x| of the state's length-like numbers.\nfn length_like(s: &State) -> f64 {{");
    let _ = writeln!(out, "    let mut big = 0.0f64;");
    for (place, vector, array) in &places {
        let _ = match (vector, array) {
            (_, true) => {
                writeln!(out, "    for y in s.{place}.iter().flatten() {{\n        big = big.max(y.abs());\n    }}")
            }
            (true, false) => writeln!(out, "    for y in s.{place} {{\n        big = big.max(y.abs());\n    }}"),
            (false, false) => writeln!(out, "    big = big.max(s.{place}.abs());"),
        };
    }
    if places.is_empty() {
        let _ = writeln!(out, "    let _ = s;");
    }
    let _ = writeln!(out, "    big\n}}\n");
}

/// The header's list of `State` fields: the rule, then each file name and its field.
fn field_names(out: &mut String, g: &Graph, fields: &[Field]) {
    let _ = writeln!(
        out,
        "// State fields: each symbol of the file under its own name where that is a Rust identifier \
         (ASCII letters, digits, `_`; not a keyword), else its snake_case form (other letters as their \
         code point, `λ` → `u3bb`; a keyword gets `_`; `_2`, `_3`, … where taken). Accelerations are \
         not inputs. In the file → in `State`:"
    );
    for f in fields {
        let _ = writeln!(out, "//   `{}` → `{}`", comment_text(&g.symbol(f.symbol).name), f.ident);
    }
    let _ = writeln!(out);
}

/// The first lines of every Rust module: the command that writes it (`flags` after
/// `--lang rust`), the scene, and that it stands alone.
fn opening(out: &mut String, title: &str, flags: &str) {
    let _ = writeln!(out, "// Generated by `lagrange generate --lang rust{flags}`.");
    let _ = writeln!(out, "// Scene: {}", comment_text(title));
    let _ = writeln!(out, "// Do not edit: regenerate. Self-contained: no dependency on lagrange or any crate.");
}

/// The module's opening comment: what it is and how it is laid out.
fn header(
    out: &mut String,
    title: &str,
    (specialize, solver): (bool, Option<Solver>),
    layout: &Layout,
    (rigid, three): (usize, bool),
) {
    let (dim, n, k) = (layout.dim, layout.bodies, layout.constraints);
    opening(out, title, &super::flags(specialize, solver));
    let _ = writeln!(
        out,
        "// {dim}D, {n} bod{}, {k} constraint{}; vectors are [f64; {dim}].",
        if n == 1 { "y" } else { "ies" },
        if k == 1 { "" } else { "s" }
    );
    if specialize {
        let _ = writeln!(out, "// Specialised: the file's parameter values are written into the formulas.");
    }
    let _ = writeln!(
        out,
        "// Convention: `constraints` is C as written (`lhs = rhs` and `lhs >= rhs` give C = lhs − rhs, \
         `lhs <= rhs` gives C = rhs − lhs). `jacobian` is J = ∇C/κ, with κ = SCALE[k] the constant content \
         of ∇C, and `c_term` and λ refer to C/κ, as `lagrange solve` and `derive --format json` do; \
         the forces do not depend on κ."
    );
    if three {
        let _ = writeln!(
            out,
            "// Rigid bodies ({rigid}, 3D): `State` holds each one's unit quaternion q = [w, x, y, z] (Hamilton), angular \
             velocity ω and torque τ (world frame) beside its position, velocity and force (and its principal moments \
             [I1, I2, I3] as the file declares them). The solve runs over three angular slots per rigid body, one per \
             principal axis eₖ = R(q) eₖ (`body_axes`), so M = blockdiag(m E, diag(I1, I2, I3)) stays diagonal: \
             A = Σ Jᵢ·Jᵢ/mᵢ + Σₖ (Jʷ·eₖ)²/Iₖ, b = Σ Jᵢ·Fᵢ/mᵢ + Σₖ (Jʷ·eₖ)(eₖ·τ − (ω_b × I ω_b)ₖ)/Iₖ + c, the world \
             I⁻¹(τ − ω × I ω) with its gyroscopic term; `torques` and `angular_accelerations` are world vectors."
        );
    } else if rigid > 0 {
        let _ = writeln!(
            out,
            "// Rigid bodies ({rigid}): `State` holds each one's angle θ, angular velocity ω and torque τ beside its \
             position, velocity and force (and its inertia I as the file declares it); `angular_jacobian` is Jʷ, \
             `torques` and `angular_accelerations` the constraint torque and α. M = blockdiag(m E, I): \
             A = Σ (Jᵢ·Jᵢ/mᵢ + Jʷ Jʷ/I), b = Σ (Jᵢ·Fᵢ/mᵢ + Jʷ τ/I) + c (2D: no gyroscopic term)."
        );
    }
    // How a big system is laid out, so that none of its functions needs a big stack.
    match layout.a {
        AStorage::Band { bandwidth } => {
            let _ = writeln!(
                out,
                "// A is banded: `a_band(s)[k][d]` = A[k][k + d] for d ≤ A_BANDWIDTH = {bandwidth}; λ by L D Lᵀ on the band."
            );
        }
        AStorage::Heap => {
            let _ = writeln!(out, "// A is dense and not banded: `a_matrix` returns its {k} rows on the heap (Vec).");
        }
        AStorage::Dense => {}
    }
    if matches!(layout.j, JStorage::Blocks { .. }) {
        let _ = writeln!(
            out,
            "// J is sparse: `jacobian_blocks(s)` is a Vec of its JACOBIAN_BLOCKS non-zero blocks (k, i, d): \
             constraint k's direction d on body i, sorted by k. Σₖ λₖ·d over the blocks of body i is its force."
        );
    }
    if layout.parted {
        let _ = writeln!(
            out,
            "// Outputs of more than {MAX_PART} formulas are filled by private parts of at most {MAX_PART}: no function's \
             stack grows with the system's size beyond its own O(K) arrays."
        );
    }
    let _ = writeln!(out);
}

/// The constraint names as comment text.
fn names_of(names: &[&str]) -> Vec<String> {
    names.iter().map(|n| comment_text(n)).collect()
}

/// `SCALE` (κ of each row: ∇C = κ·J) and `INEQUALITY` (which rows are `C ≥ 0`).
fn row_constants(out: &mut String, scales: &[f64], inequalities: &[bool], names: &[String]) {
    let k = scales.len();
    let _ =
        writeln!(out, "/// κ of each constraint (in file order): the constant taken out of ∇C, so ∇C = SCALE[k]·J[k]");
    let _ =
        writeln!(out, "/// (`jacobian`) and C/SCALE[k] is the value whose gradient is J[k]. A Newton projection on");
    let _ = writeln!(out, "/// C as written steps −C·SCALE[k]·J[k] / |SCALE[k]·J[k]|² (mass-weighted: divide by mᵢ).");
    let listed: Vec<String> = scales.iter().map(|x| format!("{x:?}")).collect();
    let _ = writeln!(out, "pub const SCALE: [f64; {k}] = {};", array(&listed));
    let _ =
        writeln!(out, "/// Which constraints are inequalities `C ≥ 0` (λ ≥ 0, zero unless touching), in file order:");
    for (name, &ineq) in names.iter().zip(inequalities) {
        let _ = writeln!(out, "/// - `{name}`: {}", if ineq { "inequality, C ≥ 0" } else { "equality, C = 0" });
    }
    let listed: Vec<String> = inequalities.iter().map(|b| b.to_string()).collect();
    let _ = writeln!(out, "pub const INEQUALITY: [bool; {k}] = {};\n", array(&listed));
}

/// The `State` struct and the size constants.
fn state(out: &mut String, g: &Graph, fields: &[Field], layout: &Layout) {
    let (dim, n, k) = (layout.dim, layout.bodies, layout.constraints);
    let _ = writeln!(out, "/// A state of the scene: every input of the formulas below.");
    let _ = writeln!(out, "/// Fields are the file's names as written where Rust allows (see the module's header).");
    let _ = writeln!(out, "#[allow(non_snake_case)]");
    let arrays = fields.iter().any(|f| f.array.is_some());
    // `Default` is derived only for arrays of at most 32 entries: role arrays get an impl.
    let _ = writeln!(out, "#[derive(Clone, Copy, Debug, {}PartialEq)]", if arrays { "" } else { "Default, " });
    let _ = writeln!(out, "pub struct State {{");
    let mut defaults = Vec::new();
    for f in fields.iter().filter(|f| f.array.is_none()) {
        let ty = if g.is_quaternion(f.symbol) {
            "[f64; 4]".to_string()
        } else if g.symbol(f.symbol).ty == Ty::Vector {
            format!("[f64; {dim}]")
        } else {
            "f64".into()
        };
        let _ = writeln!(out, "    /// {}", f.doc);
        let _ = writeln!(out, "    pub {}: {ty},", f.ident);
        defaults.push(format!("{}: Default::default()", f.ident));
    }
    for (name, what) in ROLE_ARRAYS {
        let len = fields.iter().filter(|f| f.array.is_some_and(|a| a.0 == name)).count();
        if len == 0 {
            continue;
        }
        let (ty, zero) = if scalar_role(name) {
            (format!("[f64; {len}]"), format!("[0.0; {len}]"))
        } else {
            (format!("[[f64; {dim}]; {len}]"), format!("[[0.0; {dim}]; {len}]"))
        };
        let _ = writeln!(out, "    /// {what} (the header lists which symbol each entry holds).");
        let _ = writeln!(out, "    pub {name}: {ty},");
        defaults.push(format!("{name}: {zero}"));
    }
    let _ = writeln!(out, "}}\n");
    if arrays {
        let _ = writeln!(
            out,
            "impl Default for State {{\n    fn default() -> State {{\n        State {{ {} }}\n    }}\n}}\n",
            defaults.join(", ")
        );
    }
    let _ = writeln!(out, "/// Space dimension.\npub const DIM: usize = {dim};");
    let _ = writeln!(out, "/// Number of bodies (in file order).\npub const BODIES: usize = {n};");
    let _ = writeln!(out, "/// Number of constraints (in file order).\npub const CONSTRAINTS: usize = {k};\n");
}

impl Ctx<'_> {
    /// `constraints`: the values C.
    fn constraints(&self, out: &mut String, formulas: &Formulas, names: &Names<'_>) -> Result<(), GenerateError> {
        let g = self.g;
        let mut doc = vec!["The constraint values C (zero on the constraint):".to_string()];
        for (i, &c) in formulas.c.iter().enumerate() {
            doc.push(format!("- `{}`: {}", comment_text(names.constraints[i]), formula(g, c)));
        }
        self.emit_scalars(out, &doc, "constraints", &formulas.c)
    }

    /// `constraint_rates`: Ċ, with ∂C/∂t (C as written).
    fn rates(&self, out: &mut String, formulas: &Formulas, names: &Names<'_>) -> Result<(), GenerateError> {
        let g = self.g;
        let mut doc = vec!["The rates Ċ = Σᵢ ∇ᵢC·vᵢ + ∂C/∂t of C as written:".to_string()];
        for (i, &c) in formulas.c_dot.iter().enumerate() {
            doc.push(format!("- `{}`: {}", comment_text(names.constraints[i]), formula(g, c)));
        }
        self.emit_scalars(out, &doc, "constraint_rates", &formulas.c_dot)
    }

    /// `positions`, `velocities`, `external_forces` and `inverse_masses`: each body's numbers.
    fn bodies(&self, out: &mut String, bodies: &Bodies, names: &Names<'_>) -> Result<(), GenerateError> {
        let listed = names.bodies.iter().map(|b| format!("`{}`", comment_text(b))).collect::<Vec<_>>().join(", ");
        let order = format!("Per body, in file order ({listed}).");
        let vectors = [
            ("positions", "The position of each body.", &bodies.position),
            ("velocities", "The velocity of each body.", &bodies.velocity),
            ("external_forces", "The external force on each body (the state's force fields).", &bodies.force),
            (
                "applied_forces",
                "The scene's forces (`[scene] forces`) at this state, zero for a body it does not list: an engine's \
                 loop writes them into the state's force fields before asking for λ or the accelerations.",
                &bodies.applied,
            ),
        ];
        for (name, what, roots) in vectors {
            self.emit_vectors(out, &[what.to_string(), order.clone()], name, roots)?;
        }
        let doc = ["1/m of each body.".to_string(), order];
        self.emit_scalars(out, &doc, "inverse_masses", &bodies.inverse_mass)
    }

    /// The rigid bodies' numbers and Jʷ (nothing for a scene of point masses): `RIGID_BODIES`,
    /// `orientations`, `angular_velocities`, `external_torques`, `applied_torques`,
    /// `inverse_inertias`, and `angular_jacobian` (dense, `[[f64; RIGID]; K]`) or
    /// `angular_jacobian_blocks` as the layout stores J.
    fn rigid(
        &self,
        out: &mut String,
        turns: &Turns,
        formulas: &Formulas,
        names: &Names<'_>,
        (layout, fields): (&Layout, &[Field]),
    ) -> Result<(), GenerateError> {
        let r = turns.body.len();
        if r == 0 {
            return Ok(());
        }
        let g = self.g;
        if !turns.three.is_empty() {
            self.rigid_3d(out, turns, names, fields)?;
        } else {
            self.rigid_2d(out, turns, names)?;
        }
        let entries = turns.entries(formulas);
        let mut doc = vec![if turns.three.is_empty() {
            format!(
                "Jʷ: the angular part of J (∂C/∂θ over the same constant κ as J), so Ċ/κ = Σᵢ Jᵢ·vᵢ + Σ_r Jʷ_r ω_r + ∂C/∂t/κ \
                 and the constraint torque on rigid body r is Σₖ λₖ Jʷₖ_r. {}",
                match layout.j {
                    JStorage::Dense => "Row k, column r: rigid body r (`RIGID_BODIES`).",
                    JStorage::Blocks { .. } => "Sparse: every non-zero entry `(k, r, Jʷ)`, sorted by k.",
                }
            )
        } else {
            format!(
                "Jʷ·eₖ: the angular part of J (∂Ċ/∂ω over the same constant κ as J, a world vector) on each principal \
                 axis eₖ = R(q) eₖ, so Ċ/κ = Σᵢ Jᵢ·vᵢ + Σ_slots (Jʷ·eₖ)(eₖ·ω) + ∂C/∂t/κ and the constraint torque on \
                 rigid body r is Σₖ λₖ Jʷₖ_r = Σ_axes eₖ Σₖ λₖ (Jʷₖ_r·eₖ). {}",
                match layout.j {
                    JStorage::Dense => "Row k, column 3r + a: rigid body r's axis a (`RIGID_BODIES`).",
                    JStorage::Blocks { .. } => "Sparse: every non-zero entry `(k, 3r + a, Jʷ·eₐ)`, sorted by k.",
                }
            )
        }];
        for &(k, slot, id) in &entries {
            doc.push(format!("- Jʷ[{k}], body `{}`: {}", comment_text(names.bodies[turns.body[slot]]), formula(g, id)));
        }
        self.angular_jacobian(out, &entries, doc, layout, r)
    }

    /// A 2D module's rigid bodies: `RIGID`, `RIGID_BODIES`, and θ, ω, τ, the scene's τ and 1/I
    /// per rigid body.
    fn rigid_2d(&self, out: &mut String, turns: &Turns, names: &Names<'_>) -> Result<(), GenerateError> {
        let r = turns.body.len();
        let listed: Vec<String> = turns.body.iter().map(|&b| b.to_string()).collect();
        let rigid_names =
            turns.body.iter().map(|&b| format!("`{}`", comment_text(names.bodies[b]))).collect::<Vec<_>>().join(", ");
        let _ = writeln!(
            out,
            "/// Number of rigid bodies (2D: an angle θ, ω = θ̇, the inertia I about the centre of mass, a torque τ).\n\
             pub const RIGID: usize = {r};\n\
             /// The body (index into the bodies) of each rigid body, in file order ({rigid_names}): rigid body r is\n\
             /// body RIGID_BODIES[r], and its angular slot in `rows` and `solution` is BODIES + r.\n\
             pub const RIGID_BODIES: [usize; {r}] = {};\n",
            array(&listed)
        );
        let order = format!("Per rigid body, in file order ({rigid_names}).");
        let scalars = [
            ("orientations", "The angle θ of each rigid body (counter-clockwise).", &turns.orientation),
            ("angular_velocities", "The angular velocity ω of each rigid body.", &turns.angular_velocity),
            ("external_torques", "The external torque on each rigid body (the state's torque fields).", &turns.torque),
            (
                "applied_torques",
                "The scene's torques (`[scene] forces` on a torque symbol) at this state, zero for a rigid body it \
                 does not list: an engine's loop writes them into the state's torque fields.",
                &turns.applied,
            ),
            ("inverse_inertias", "1/I of each rigid body.", &turns.inverse_inertia),
        ];
        for (name, what, roots) in scalars {
            self.emit_scalars(out, &[what.to_string(), order.clone()], name, roots)?;
        }
        Ok(())
    }

    /// A 3D module's rigid bodies: `RIGID`, `RIGID_BODIES`, `ANGULAR_SLOTS`; per rigid body q,
    /// ω, τ, the scene's τ and the principal axes (`body_axes`); per axis slot 1/Iₖ, eₖ·ω and
    /// eₖ·τ − (ω_b × I ω_b)ₖ, what the rows' solve reads.
    fn rigid_3d(
        &self,
        out: &mut String,
        turns: &Turns,
        names: &Names<'_>,
        fields: &[Field],
    ) -> Result<(), GenerateError> {
        let r = turns.three.len();
        let listed: Vec<String> = turns.three.iter().map(|t| t.body.to_string()).collect();
        let rigid_names = turns
            .three
            .iter()
            .map(|t| format!("`{}`", comment_text(names.bodies[t.body])))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            out,
            "/// Number of rigid bodies (3D: a unit quaternion q = [w, x, y, z], ω and τ in the world frame, the\n\
             /// principal moments [I1, I2, I3] in the body frame).\n\
             pub const RIGID: usize = {r};\n\
             /// The body (index into the bodies) of each rigid body, in file order ({rigid_names}): rigid body r is\n\
             /// body RIGID_BODIES[r], and its principal axis k has the angular slot BODIES + 3r + k in `rows` and `solution`.\n\
             pub const RIGID_BODIES: [usize; {r}] = {};\n\
             /// Number of angular slots: three per rigid body, one per principal axis.\n\
             pub const ANGULAR_SLOTS: usize = {};\n",
            array(&listed),
            3 * r
        );
        let order = format!("Per rigid body, in file order ({rigid_names}).");
        let quaternions: Vec<String> =
            turns.three.iter().map(|t| format!("s.{}", ident_of(fields, t.orientation))).collect();
        emit_fn(
            out,
            &["The orientation q = [w, x, y, z] (Hamilton, unit) of each rigid body.".to_string(), order.clone()],
            "orientations",
            &format!("[[f64; 4]; {r}]"),
            &[],
            &array(&quaternions),
        );
        let vectors: [(&str, &str, Vec<Id>); 3] = [
            (
                "angular_velocities",
                "The angular velocity ω (world frame) of each rigid body.",
                turns.three.iter().map(|t| t.angular_velocity).collect(),
            ),
            (
                "external_torques",
                "The external torque τ (world frame) on each rigid body (the state's torque fields).",
                turns.three.iter().map(|t| t.torque).collect(),
            ),
            (
                "applied_torques",
                "The scene's torques (`[scene] forces` on a torque symbol, world frame) at this state, zero for a rigid \
                 body it does not list: an engine's loop writes them into the state's torque fields.",
                turns.three.iter().map(|t| t.applied).collect(),
            ),
        ];
        for (name, what, roots) in vectors {
            self.emit_vectors(out, &[what.to_string(), order.clone()], name, &roots)?;
        }
        let items: Vec<Vec<Id>> = turns.three.iter().map(|t| t.axes.to_vec()).collect();
        let store = |i: usize, e: &[String]| {
            let rows: Vec<String> = e.chunks(3).map(array).collect();
            format!("out[{i}] = {};", array(&rows))
        };
        let doc = [
            "The principal axes R(q) eₖ (k = 1, 2, 3; the columns of R(q)) of each rigid body, in the world."
                .to_string(),
            order,
        ];
        let (ret, init) = (format!("[[[f64; 3]; 3]; {r}]"), format!("[[[0.0; 3]; 3]; {r}]"));
        self.emit_items(out, &doc, "body_axes", &ret, &init, "[[f64; 3]; 3]", &items, store)?;
        let slots = format!("Per angular slot: rigid body r's principal axis k at 3r + k ({rigid_names}).");
        let scalars = [
            ("axis_inverse_inertias", "1/Iₖ of each axis slot.", &turns.inverse_inertia),
            ("axis_angular_velocities", "ωₖ = eₖ·ω of each axis slot.", &turns.angular_velocity),
            (
                "axis_torques",
                "eₖ·τ − (ω_b × I ω_b)ₖ of each axis slot: the external torque with the gyroscopic term of Euler's \
                 equations in the body frame (ω_b = (eⱼ·ω)ⱼ), from the state's torque fields.",
                &turns.torque,
            ),
        ];
        for (name, what, roots) in scalars {
            self.emit_scalars(out, &[what.to_string(), slots.clone()], name, roots)?;
        }
        Ok(())
    }

    /// `angular_jacobian` (dense, `[[f64; R]; K]` over the `r` angular slots) or
    /// `angular_jacobian_blocks`, as the layout stores J.
    fn angular_jacobian(
        &self,
        out: &mut String,
        entries: &[(usize, usize, Id)],
        doc: Vec<String>,
        layout: &Layout,
        r: usize,
    ) -> Result<(), GenerateError> {
        let roots: Vec<Id> = entries.iter().map(|e| e.2).collect();
        if let JStorage::Blocks { .. } = layout.j {
            let count = entries.len();
            let items: Vec<Vec<Id>> = roots.iter().map(|&id| vec![id]).collect();
            let store =
                |i: usize, exprs: &[String]| format!("out[{i}] = ({}, {}, {});", entries[i].0, entries[i].1, exprs[0]);
            let _ = writeln!(
                out,
                "/// Number of non-zero entries of Jʷ: the entries `angular_jacobian_blocks` returns.\n\
                 pub const ANGULAR_BLOCKS: usize = {count};\n"
            );
            let ret = "Vec<(usize, usize, f64)>".to_string();
            let init = format!("vec![(0, 0, 0.0); {count}]");
            return self.emit_items(
                out,
                &doc,
                "angular_jacobian_blocks",
                &ret,
                &init,
                "(usize, usize, f64)",
                &items,
                store,
            );
        }
        let (lets, exprs) = self.body(&roots)?;
        let k = layout.constraints;
        let rows: Vec<String> = (0..k)
            .map(|row| {
                let cells: Vec<String> = (0..r)
                    .map(|slot| {
                        entries
                            .iter()
                            .position(|e| e.0 == row && e.1 == slot)
                            .map_or("0.0".into(), |i| exprs[i].clone())
                    })
                    .collect();
                array(&cells)
            })
            .collect();
        emit_fn(out, &doc, "angular_jacobian", &format!("[[f64; {r}]; {k}]"), &lets, &array(&rows));
        Ok(())
    }

    /// `a_matrix` or `a_band`: A, as the layout stores it, from the assembled entries
    /// `a_code` (the doc comments show the canonical ones, `formulas.a`).
    fn a(&self, out: &mut String, formulas: &Formulas, a_code: &[Id], layout: &Layout) -> Result<(), GenerateError> {
        let (g, k) = (self.g, layout.constraints);
        let mut doc = vec![
            "A of A λ + b = 0: Aₖⱼ = Σᵢ Jₖᵢ·Jⱼᵢ / mᵢ (symmetric, positive semidefinite). Non-zero entries:".to_string(),
        ];
        let mut roots = Vec::new();
        let mut where_: FastMap<(usize, usize), usize> = FastMap::default();
        for (&(r, c, shown), &id) in formulas.a.iter().zip(a_code) {
            doc.push(format!("- A[{r}][{c}] = {}", formula(g, shown)));
            // Off the diagonal the entry is used twice (A is symmetric): listing it twice makes
            // its value a `let`.
            where_.insert((r, c), roots.len());
            roots.push(id);
            if r != c {
                where_.insert((c, r), roots.len());
                roots.push(id);
            }
        }
        match layout.a {
            AStorage::Band { bandwidth } if layout::parted(formulas.a.len()) || layout.sparse_band => {
                // One item per band row, each entry once: the parts need no shared `let`s.
                // A row is written whole, or (mostly zeros: a grid's band) only its non-zero
                // entries over the zeros `out` starts with.
                band_header(out, &mut doc, bandwidth);
                let sparse = layout.sparse_band;
                let present =
                    |r: usize| (r..=r + bandwidth).filter(|c| where_.contains_key(&(r, *c))).collect::<Vec<_>>();
                let items: Vec<Vec<Id>> =
                    (0..k).map(|r| present(r).iter().map(|&c| roots[where_[&(r, c)]]).collect()).collect();
                let store = |r: usize, exprs: &[String]| {
                    if sparse {
                        let stores: Vec<String> = present(r)
                            .into_iter()
                            .zip(exprs)
                            .map(|(c, e)| format!("out[{r}][{}] = {e};", c - r))
                            .collect();
                        return stores.join("\n    ");
                    }
                    let mut values = vec!["0.0".to_string(); bandwidth + 1];
                    for (c, e) in present(r).into_iter().zip(exprs) {
                        values[c - r] = e.clone();
                    }
                    format!("out[{r}] = {};", array(&values))
                };
                let ret = format!("[[f64; {}]; {k}]", bandwidth + 1);
                let init = format!("[[0.0; {}]; {k}]", bandwidth + 1);
                let elem = format!("[f64; {}]", bandwidth + 1);
                self.emit_items(out, &doc, "a_band", &ret, &init, &elem, &items, store)
            }
            AStorage::Heap => {
                // K² numbers: on the heap, written entry by entry (an array literal would be
                // built on the stack first). Only the non-zero entries are stored, row by row.
                let row = |r: usize| (0..k).filter(|c| where_.contains_key(&(r, *c))).collect::<Vec<_>>();
                let items: Vec<Vec<Id>> =
                    (0..k).map(|r| row(r).iter().map(|&c| roots[where_[&(r, c)]]).collect()).collect();
                let store = |r: usize, exprs: &[String]| {
                    let stores: Vec<String> =
                        row(r).into_iter().zip(exprs).map(|(c, e)| format!("out[{r}][{c}] = {e};")).collect();
                    stores.join("\n    ")
                };
                doc.push(String::new());
                doc.push(format!("On the heap ({k} rows of {k}): A is not banded and too big for the stack."));
                let ret = format!("Vec<[f64; {k}]>");
                let init = format!("vec![[0.0; {k}]; {k}]");
                self.emit_items(out, &doc, "a_matrix", &ret, &init, &format!("[f64; {k}]"), &items, store)
            }
            AStorage::Band { bandwidth } => {
                let (lets, exprs) = self.body(&roots)?;
                // Only the band: row r holds A[r][r], A[r][r + 1], …, A[r][r + w] (zeros past the end).
                let rows: Vec<String> = (0..k)
                    .map(|r| {
                        let band: Vec<String> = (r..=r + bandwidth)
                            .map(|c| where_.get(&(r, c)).map_or("0.0".to_string(), |&i| exprs[i].clone()))
                            .collect();
                        array(&band)
                    })
                    .collect();
                band_header(out, &mut doc, bandwidth);
                emit_fn(out, &doc, "a_band", &format!("[[f64; {}]; {k}]", bandwidth + 1), &lets, &array(&rows));
                Ok(())
            }
            AStorage::Dense => {
                let (lets, exprs) = self.body(&roots)?;
                let rows: Vec<String> = (0..k)
                    .map(|r| {
                        array(
                            &(0..k)
                                .map(|c| where_.get(&(r, c)).map_or("0.0".to_string(), |&i| exprs[i].clone()))
                                .collect::<Vec<_>>(),
                        )
                    })
                    .collect();
                emit_fn(out, &doc, "a_matrix", &format!("[[f64; {k}]; {k}]"), &lets, &array(&rows));
                Ok(())
            }
        }
    }

    /// `b_vector`: b.
    fn b(&self, out: &mut String, formulas: &Formulas) -> Result<(), GenerateError> {
        let mut doc = vec!["b of A λ + b = 0: bₖ = Σᵢ Jₖᵢ·Fᵢ / mᵢ + cₖ.".to_string()];
        for (i, &b) in formulas.b.iter().enumerate() {
            doc.push(format!("- b[{i}] = {}", formula(self.g, b)));
        }
        self.emit_scalars(out, &doc, "b_vector", &formulas.b)
    }

    /// `jacobian` or `jacobian_blocks`: J, as the layout stores it.
    fn jacobian(
        &self,
        out: &mut String,
        formulas: &Formulas,
        names: &Names<'_>,
        layout: &Layout,
    ) -> Result<(), GenerateError> {
        let (g, dim, n, k) = (self.g, layout.dim, layout.bodies, layout.constraints);
        let mut doc = vec![format!(
            "J: row k is the force direction of constraint k (∇C over its constant content), body i's \
             components at columns i·{dim} .. i·{dim} + {dim}."
        )];
        let mut roots = Vec::new();
        let mut at: FastMap<(usize, usize), usize> = FastMap::default();
        for (r, dirs) in formulas.jacobian.iter().enumerate() {
            for &(body, id) in dirs {
                doc.push(format!("- J[{r}], body `{}`: {}", comment_text(names.bodies[body]), formula(g, id)));
                at.insert((r, body), roots.len());
                roots.push(id);
            }
        }
        if let JStorage::Blocks { count } = layout.j {
            // Block triplets by constraint, each constraint's bodies as the derivation lists them.
            let blocks: Vec<(usize, usize, Id)> = formulas
                .jacobian
                .iter()
                .enumerate()
                .flat_map(|(r, dirs)| dirs.iter().map(move |&(body, id)| (r, body, id)))
                .collect();
            let _ = writeln!(
                out,
                "/// Number of non-zero blocks of J: the entries `jacobian_blocks` returns.\n\
                 pub const JACOBIAN_BLOCKS: usize = {count};\n"
            );
            doc[0] = format!(
                "J, sparse: every non-zero block `(k, i, d)`, where d is the force direction of constraint k \
                 (∇C over its constant content) on body i, so Jₖ at columns i·{dim} .. i·{dim} + {dim} is d. \
                 Sorted by k; a body a constraint does not involve has no block in its row."
            );
            let items: Vec<Vec<Id>> = blocks.iter().map(|b| vec![b.2]).collect();
            let store = |i: usize, exprs: &[String]| {
                format!("out[{i}] = ({}, {}, {});", blocks[i].0, blocks[i].1, array(exprs))
            };
            // On the heap: a block is 2 + DIM words, and an unoptimised build copies a returned
            // array several times on its way out.
            let ret = format!("Vec<(usize, usize, [f64; {dim}])>");
            let init = format!("vec![(0, 0, [0.0; {dim}]); {count}]");
            let elem = format!("(usize, usize, [f64; {dim}])");
            return self.emit_items(out, &doc, "jacobian_blocks", &ret, &init, &elem, &items, store);
        }
        let (mut lets, exprs) = self.body(&roots)?;
        if layout::mostly_zero(k * n * dim, roots.len() * dim) {
            // The blocks written one by one over a zeroed J.
            lets.push(format!("let mut out = [[0.0; {}]; {k}];", n * dim));
            for (r, dirs) in formulas.jacobian.iter().enumerate() {
                for &(body, _) in dirs {
                    let i = at[&(r, body)];
                    lets.extend((0..dim).map(|d| format!("out[{r}][{}] = {};", body * dim + d, exprs[i * dim + d])));
                }
            }
            emit_fn(out, &doc, "jacobian", &format!("[[f64; {}]; {k}]", n * dim), &lets, "out");
            return Ok(());
        }
        let rows: Vec<String> = (0..k)
            .map(|r| {
                let mut row = Vec::new();
                for body in 0..n {
                    for axis in 0..dim {
                        row.push(match at.get(&(r, body)) {
                            Some(&i) => exprs[i * dim + axis].clone(),
                            None => "0.0".into(),
                        });
                    }
                }
                array(&row)
            })
            .collect();
        emit_fn(out, &doc, "jacobian", &format!("[[f64; {}]; {k}]", n * dim), &lets, &array(&rows));
        Ok(())
    }

    /// `c_term`: c.
    fn c_term(&self, out: &mut String, formulas: &Formulas) -> Result<(), GenerateError> {
        let mut doc = vec!["c: the part of C̈ (over the same constant) without accelerations, C̈ = J·a + c.".to_string()];
        for (i, &c) in formulas.bias.iter().enumerate() {
            doc.push(format!("- c[{i}] = {}", formula(self.g, c)));
        }
        self.emit_scalars(out, &doc, "c_term", &formulas.bias)
    }

    /// `lambda`, `forces`, `force_<body>` and `accelerations`: closed formulas for one
    /// equality (where their numbers are in range); for other systems of equalities λ by
    /// L D Lᵀ on A's band (`band_lambda`) and the forces from it, or from `dense_solution`
    /// for a small dense A; else the rows' solve. The solves' helpers the layout needs.
    #[allow(clippy::too_many_arguments)]
    fn solution(
        &self,
        out: &mut String,
        formulas: &Formulas,
        (a_code, b_code): (&[Id], &[Id]),
        names: &Names<'_>,
        layout: &Layout,
        turns: &Turns,
    ) -> Result<(), GenerateError> {
        let (dim, n, k) = (layout.dim, layout.bodies, layout.constraints);
        let rigid = turns.body.len();
        // The solution's slots past the bodies are the rigid bodies' angles.
        let bodies_only = if rigid > 0 { "[..BODIES]" } else { "" };
        let (force_fns, torque_fns) = per_body_fns(names, turns);
        let _ = writeln!(
            out,
            "/// The accelerations (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ of every body (in file order), from the rows' solve.\n\
             pub fn accelerations(s: &State) -> [[f64; {dim}]; {n}] {{\n    \
             let mut a = [[0.0; {dim}]; {n}];\n    a.copy_from_slice(&solution(s).acceleration{bodies_only});\n    a\n}}\n"
        );
        if !turns.three.is_empty() {
            let r = turns.three.len();
            let _ = writeln!(
                out,
                "/// The angular accelerations α (world frame) of every rigid body (`RIGID_BODIES`), from the rows' solve:\n\
                 /// Σₖ eₖ αₖ over the principal axes eₖ = R(q) eₖ, with Iₖ αₖ = eₖ·τ − (ω_b × I ω_b)ₖ + Σ λ Jʷ·eₖ.\n\
                 pub fn angular_accelerations(s: &State) -> [[f64; 3]; {r}] {{\n    \
                 let (x, e) = (solution(s), body_axes(s));\n    \
                 std::array::from_fn(|r| world(&e[r], |k| x.acceleration[BODIES + 3 * r + k][0]))\n}}\n"
            );
            let _ = writeln!(
                out,
                "/// The multipliers λ (for C/κ), as `lagrange solve` gives them: 0 on an inequality that is apart,\n\
                 /// separating or would pull, and the minimum-norm λ where A is singular (see `solution`).\n\
                 pub fn lambda(s: &State) -> [f64; {k}] {{\n    \
                 let mut l = [0.0; {k}];\n    l.copy_from_slice(&solution(s).lambda);\n    l\n}}\n"
            );
            let _ = writeln!(
                out,
                "/// The constraint force Σₖ λₖ Jₖᵢ on every body (in file order), from the rows' solve.\n\
                 pub fn forces(s: &State) -> [[f64; {dim}]; {n}] {{\n    \
                 let mut f = [[0.0; {dim}]; {n}];\n    f.copy_from_slice(&solution(s).force[..BODIES]);\n    f\n}}\n"
            );
            let _ = writeln!(
                out,
                "/// The constraint torque Σₖ λₖ Jʷₖ (world frame, about the centre of mass) on every rigid body\n\
                 /// (`RIGID_BODIES`), from the rows' solve: Σₖ eₖ (its axis slots' parts).\n\
                 pub fn torques(s: &State) -> [[f64; 3]; {r}] {{\n    \
                 let (x, e) = (solution(s), body_axes(s));\n    \
                 std::array::from_fn(|r| world(&e[r], |k| x.force[BODIES + 3 * r + k][0]))\n}}\n"
            );
            let _ = writeln!(
                out,
                "/// Σₖ eₖ xₖ: a vector given by its parts on the axes `e`, in the world (`numeric::rows::world_angular`'s order).\n\
                 fn world(e: &[[f64; 3]; 3], x: impl Fn(usize) -> f64) -> [f64; 3] {{\n    \
                 let mut out = [0.0; 3];\n    \
                 for (k, axis) in e.iter().enumerate() {{\n        \
                 for (o, a) in out.iter_mut().zip(axis) {{\n            *o += x(k) * a;\n        }}\n    }}\n    out\n}}\n"
            );
            for (slot, name) in torque_fns.iter().enumerate() {
                let _ = writeln!(
                    out,
                    "/// The constraint torque on rigid body `{}` (world frame, about its centre of mass).\npub fn {name}(s: &State) -> [f64; 3] {{\n    torques(s)[{slot}]\n}}\n",
                    comment_text(names.bodies[turns.three[slot].body])
                );
            }
            for (body, name) in force_fns.iter().enumerate() {
                let _ = writeln!(
                    out,
                    "/// The constraint force on body `{}`.\npub fn {name}(s: &State) -> [f64; {dim}] {{\n    forces(s)[{body}]\n}}\n",
                    comment_text(names.bodies[body])
                );
            }
            return Ok(());
        }
        if rigid > 0 {
            let _ = writeln!(
                out,
                "/// The angular accelerations α = (τ + Σₖ λₖ Jʷₖ)/I of every rigid body (`RIGID_BODIES`), from the rows' solve.\n\
                 pub fn angular_accelerations(s: &State) -> [f64; {rigid}] {{\n    \
                 let x = solution(s);\n    std::array::from_fn(|r| x.acceleration[BODIES + r][0])\n}}\n"
            );
        }
        match (layout.lambda, formulas.lambda, &formulas.forces) {
            (Lambda::ClosedForm, Some(lambda), Some(forces)) => {
                return self.closed_form_fns(
                    out,
                    formulas,
                    (lambda, forces),
                    names,
                    layout,
                    turns,
                    (&force_fns, &torque_fns),
                );
            }
            (Lambda::Band, _, _) => {
                self.band_lambda(out, formulas, (a_code, b_code), layout)?;
                band_fns(out, layout, rigid);
            }
            (Lambda::Dense, _, _) => {
                self.band_lambda(out, formulas, (a_code, b_code), layout)?;
                self.dense_solution(out, formulas, (a_code, b_code), layout, turns)?;
            }
            _ => {
                let _ = writeln!(
                    out,
                    "/// The multipliers λ (for C/κ), as `lagrange solve` gives them: 0 on an inequality that is apart,\n\
                     /// separating or would pull, and the minimum-norm λ where A is singular (see `solution`).\n\
                     pub fn lambda(s: &State) -> [f64; {k}] {{\n    \
                     let mut l = [0.0; {k}];\n    l.copy_from_slice(&solution(s).lambda);\n    l\n}}\n"
                );
                let _ = writeln!(
                    out,
                    "/// The constraint force Σₖ λₖ Jₖᵢ on every body (in file order), from the rows' solve.\n\
                     pub fn forces(s: &State) -> [[f64; {dim}]; {n}] {{\n    \
                     let mut f = [[0.0; {dim}]; {n}];\n    f.copy_from_slice(&solution(s).force{bodies_only});\n    f\n}}\n"
                );
                if rigid > 0 {
                    let _ = writeln!(
                        out,
                        "/// The constraint torque Σₖ λₖ Jʷₖ on every rigid body (`RIGID_BODIES`), from the rows' solve.\n\
                         pub fn torques(s: &State) -> [f64; {rigid}] {{\n    \
                         let x = solution(s);\n    std::array::from_fn(|r| x.force[BODIES + r][0])\n}}\n"
                    );
                }
            }
        }
        for (slot, name) in torque_fns.iter().enumerate() {
            let _ = writeln!(
                out,
                "/// The constraint torque on rigid body `{}` (about its centre of mass).\npub fn {name}(s: &State) -> f64 {{\n    torques(s)[{slot}]\n}}\n",
                comment_text(names.bodies[turns.body[slot]])
            );
        }
        for (body, name) in force_fns.iter().enumerate() {
            let _ = writeln!(
                out,
                "/// The constraint force on body `{}`.\npub fn {name}(s: &State) -> [f64; {dim}] {{\n    forces(s)[{body}]\n}}\n",
                comment_text(names.bodies[body])
            );
        }
        if matches!(layout.lambda, Lambda::Band | Lambda::Dense) {
            // Each helper file ends its last item with `}`; a blank line follows it.
            out.push_str(if layout.bandwidth == 1 { SOLVE_TRIDIAGONAL } else { SOLVE_BAND });
            out.push('\n');
        }
        if layout.lambda == Lambda::Dense {
            out.push_str(SOLVE_DENSE);
            out.push('\n');
        }
        Ok(())
    }

    /// One equality's closed forms: `closed_form_holds`, `lambda`, `force_<body>`, `forces`
    /// (and `torque_<body>`, `torques`), each guarded, the scaled `solution` where they are not.
    #[allow(clippy::too_many_arguments)]
    fn closed_form_fns(
        &self,
        out: &mut String,
        formulas: &Formulas,
        (lambda, forces): (Id, &[(usize, Id)]),
        names: &Names<'_>,
        layout: &Layout,
        turns: &Turns,
        (force_fns, torque_fns): (&[String], &[String]),
    ) -> Result<(), GenerateError> {
        let (g, dim, n, rigid) = (self.g, layout.dim, layout.bodies, turns.body.len());
        let _ = writeln!(
            out,
            "/// Whether the closed forms' numbers are in range here (A normal, b finite); where they are not\n\
                     /// (|r| ≈ 1e155 overflows r·r), `lambda` and the forces come from the scaled `solution`.\n\
                     fn closed_form_holds(s: &State) -> bool {{\n    \
                     a_matrix(s)[0][0].is_normal() && b_vector(s)[0].is_finite()\n}}\n"
        );
        let doc = vec![
            "The multiplier λ, in closed form (the scaled `solution` where its numbers leave f64's range):".to_string(),
            format!("λ = {}", formula(g, lambda)),
        ];
        let (lets, exprs) = self.body(&[lambda])?;
        let value = format!(
            "let x = {};\n    if closed_form_holds(s) && x[0].is_finite() {{ x }} else {{ [solution(s).lambda[0]] }}",
            array(&exprs)
        );
        emit_fn(out, &doc, "lambda", "[f64; 1]", &lets, &value);
        for (body, name) in force_fns.iter().enumerate() {
            let found = forces.iter().find(|f| f.0 == body).map(|f| f.1);
            let mut doc = vec![format!("The constraint force on body `{}`:", comment_text(names.bodies[body]))];
            match found {
                Some(id) => {
                    doc.push(formula(g, id));
                    let (lets, exprs) = self.body(&[id])?;
                    let value = format!(
                        "let f = {};\n    \
                                 if closed_form_holds(s) && f.iter().all(|x| x.is_finite()) {{ f }} else {{ solution(s).force[{body}] }}",
                        array(&exprs)
                    );
                    emit_fn(out, &doc, name, &format!("[f64; {dim}]"), &lets, &value);
                }
                None => {
                    doc.push("zero: no constraint involves this body.".into());
                    emit_fn(out, &doc, name, &format!("[f64; {dim}]"), &[], &array(&vec!["0.0".into(); dim]));
                }
            }
        }
        let calls: Vec<String> = force_fns.iter().map(|f| format!("{f}(s)")).collect();
        let doc = vec!["The constraint force on every body (in file order).".to_string()];
        emit_fn(out, &doc, "forces", &format!("[[f64; {dim}]; {n}]"), &[], &array(&calls));
        if rigid > 0 {
            let torques = formulas.torques.as_deref().unwrap_or(&[]);
            for (slot, name) in torque_fns.iter().enumerate() {
                let body = turns.body[slot];
                let found = torques.iter().find(|t| t.0 == body).map(|t| t.1);
                let mut doc = vec![format!(
                    "The constraint torque λ Jʷ on rigid body `{}` (about its centre of mass):",
                    comment_text(names.bodies[body])
                )];
                match found {
                    Some(id) => {
                        doc.push(formula(g, id));
                        let (lets, exprs) = self.body(&[id])?;
                        let value = format!(
                            "let x = {};\n    \
                                     if closed_form_holds(s) && x.is_finite() {{ x }} else {{ solution(s).force[BODIES + {slot}][0] }}",
                            exprs[0]
                        );
                        emit_fn(out, &doc, name, "f64", &lets, &value);
                    }
                    None => {
                        doc.push("zero: the constraint does not turn this body.".into());
                        emit_fn(out, &doc, name, "f64", &[], "0.0");
                    }
                }
            }
            let calls: Vec<String> = torque_fns.iter().map(|f| format!("{f}(s)")).collect();
            let doc = vec!["The constraint torque on every rigid body (`RIGID_BODIES`).".to_string()];
            emit_fn(out, &doc, "torques", &format!("[f64; {rigid}]"), &[], &array(&calls));
        }
        Ok(())
    }

    /// `band_system`, `band_lambda` and `lambda` of a system of equalities (`Lambda::Band` and
    /// `Lambda::Dense`): A λ = −b written row by row as the solve reads it — A's band of the
    /// layout's bandwidth w and −b, one program of A and b as assembled, straight into the
    /// rows (in parts where the layout parts outputs) — and λ by L D Lᵀ written for that band:
    /// `solve_tridiagonal` when w = 1 (no loop over a zero), else `solve_band`. `lambda` is
    /// `band_lambda`, and `solution` (the rows' solve) where it gives up: A singular to the
    /// rows' rank tolerance, or its numbers out of f64's range.
    fn band_lambda(
        &self,
        out: &mut String,
        formulas: &Formulas,
        (a_code, b_code): (&[Id], &[Id]),
        layout: &Layout,
    ) -> Result<(), GenerateError> {
        let (k, w) = (layout.constraints, layout.bandwidth);
        let mut entry: FastMap<(usize, usize), Id> = FastMap::default();
        for (&(r, c, _), &id) in formulas.a.iter().zip(a_code) {
            entry.insert((r.min(c), r.max(c)), id);
        }
        // Row r: the columns of its non-zero band entries, their values, then b[r].
        let columns = |r: usize| (r..=(r + w).min(k - 1)).filter(|c| entry.contains_key(&(r, *c))).collect::<Vec<_>>();
        let items: Vec<Vec<Id>> =
            (0..k).map(|r| columns(r).iter().map(|c| entry[&(r, *c)]).chain([b_code[r]]).collect()).collect();
        // A row written whole, or (where the band is mostly zeros: a grid's) only
        // its non-zero entries over the zeros `out` starts with.
        let sparse = layout.sparse_band;
        let store = |r: usize, exprs: &[String]| {
            let cols = columns(r);
            let minus_b = format!("-{}", operand(&exprs[cols.len()]));
            if sparse {
                let mut stores: Vec<String> =
                    cols.iter().zip(exprs).map(|(c, e)| format!("out[{r}][{}] = {e};", c - r)).collect();
                stores.push(format!("out[{r}][{}] = {minus_b};", w + 1));
                return stores.join("\n    ");
            }
            let mut values = vec!["0.0".to_string(); w + 2];
            for (c, e) in cols.iter().zip(exprs) {
                values[c - r] = e.clone();
            }
            values[w + 1] = minus_b;
            format!("out[{r}] = {};", array(&values))
        };
        let band = match w {
            0 => "A[k][k]".to_string(),
            1 => "A[k][k], A[k][k + 1]".to_string(),
            _ => format!("A[k][k], A[k][k + 1], …, A[k][k + {w}]"),
        };
        let doc = [
            format!("A λ = −b as `band_lambda` solves it: row k holds {band}"),
            "(A's band, zeros past the last column) and −b[k], from one program of A and b as assembled".to_string(),
            "(the numbers of A's entries and of `b_vector`).".to_string(),
        ];
        let width = w + 2;
        self.emit_items(
            out,
            &doc,
            "band_system",
            &format!("[[f64; {width}]; {k}]"),
            &format!("[[0.0; {width}]; {k}]"),
            &format!("[f64; {width}]"),
            &items,
            store,
        )?;
        let (solve, how) = if w == 1 {
            ("solve_tridiagonal(&band_system(s))", "A is tridiagonal, `solve_tridiagonal`, O(K)")
        } else {
            ("solve_band(band_system(s))", "`solve_band` on A's band, O(K w²)")
        };
        let _ = writeln!(
            out,
            "/// The multipliers λ (for C/κ) by L D Lᵀ of `band_system`: {how}.\n\
             /// `None` where A is singular (a pivot at or below 1e-10 of its diagonal entry: redundant\n\
             /// constraints) or its numbers leave f64's range.\n\
             pub fn band_lambda(s: &State) -> Option<[f64; {k}]> {{\n    {solve}\n}}\n\n\
             /// The multipliers λ (for C/κ): `band_lambda`, else the rows' solve (`solution`: the minimum-norm λ where\n\
             /// A is singular, the change of length unit where its numbers overflow).\n\
             pub fn lambda(s: &State) -> [f64; {k}] {{\n    \
             if let Some(l) = band_lambda(s) {{\n        return l;\n    }}\n    \
             let mut l = [0.0; {k}];\n    l.copy_from_slice(&solution(s).lambda);\n    l\n}}\n"
        );
        Ok(())
    }

    /// `dense_solution`, `forces` (and `torques`) of a small system of equalities:
    /// one program computes A and b (as assembled), J and Jʷ with their shared values, Cholesky
    /// solves A λ = −b, and the forces Σₖ λₖ Jₖᵢ and torques Σₖ λₖ Jʷₖ follow; where Cholesky
    /// gives up (A singular: redundant constraints; numbers out of range) the rows' solve answers.
    fn dense_solution(
        &self,
        out: &mut String,
        formulas: &Formulas,
        (a_code, b_code): (&[Id], &[Id]),
        layout: &Layout,
        turns: &Turns,
    ) -> Result<(), GenerateError> {
        let (dim, n, k, rigid) = (layout.dim, layout.bodies, layout.constraints, turns.body.len());
        let blocks: Vec<(usize, usize, Id)> = formulas
            .jacobian
            .iter()
            .enumerate()
            .flat_map(|(r, dirs)| dirs.iter().map(move |&(b, id)| (r, b, id)))
            .collect();
        let angular = turns.entries(formulas);
        let mut roots: Vec<Id> = a_code.to_vec();
        roots.extend(b_code);
        roots.extend(blocks.iter().map(|b| b.2));
        roots.extend(angular.iter().map(|e| e.2));
        let (lets, exprs) = self.body(&roots)?;
        let mut next = exprs.into_iter();
        let mut lines = lets;
        lines.push(format!("let mut a = [[0.0; {k}]; {k}];"));
        for &(r, c, _) in &formulas.a {
            lines.push(format!("a[{r}][{c}] = {};", next.next().unwrap_or_default()));
            if r != c {
                lines.push(format!("a[{c}][{r}] = a[{r}][{c}];"));
            }
        }
        let b: Vec<String> = (0..k).map(|_| format!("-{}", operand(&next.next().unwrap_or_default()))).collect();
        lines.push(format!("let l = solve_dense(a, {})?;", array(&b)));
        // Each force and torque entry as one sum over its rows, the constant 0 entries left out.
        let mut force: Vec<Vec<(usize, String)>> = vec![Vec::new(); n * dim];
        for &(r, body, _) in &blocks {
            for d in 0..dim {
                force[body * dim + d].push((r, next.next().unwrap_or_default()));
            }
        }
        lines.push(format!("let mut f = [[0.0; {dim}]; {n}];"));
        for (i, terms) in force.into_iter().enumerate() {
            if let Some(sum) = lambda_sum(terms, operand) {
                lines.push(format!("f[{}][{}] = {sum};", i / dim, i % dim));
            }
        }
        let result = if rigid > 0 {
            let mut torque: Vec<Vec<(usize, String)>> = vec![Vec::new(); rigid];
            for &(r, slot, _) in &angular {
                torque[slot].push((r, next.next().unwrap_or_default()));
            }
            lines.push(format!("let mut t = [0.0; {rigid}];"));
            for (slot, terms) in torque.into_iter().enumerate() {
                if let Some(sum) = lambda_sum(terms, operand) {
                    lines.push(format!("t[{slot}] = {sum};"));
                }
            }
            "Some((l, f, t))"
        } else {
            "Some((l, f))"
        };
        let ty = if rigid > 0 {
            format!("([f64; {k}], [[f64; {dim}]; {n}], [f64; {rigid}])")
        } else {
            format!("([f64; {k}], [[f64; {dim}]; {n}])")
        };
        let _ = writeln!(
            out,
            "/// λ, the constraint forces Σₖ λₖ Jₖᵢ{} of these equalities, from one program of A and b (as assembled)\n\
             /// and J, and A λ = −b by L D Lᵀ (`solve_dense`); `None` where A is singular (redundant constraints) or its\n\
             /// numbers leave f64's range: there `solution` (the rows' solve of `lagrange solve`) answers.\n\
             pub fn dense_solution(s: &State) -> Option<{ty}> {{",
            if rigid > 0 { " and torques Σₖ λₖ Jʷₖ" } else { "" }
        );
        for l in &lines {
            let _ = writeln!(out, "    {l}");
        }
        let _ = writeln!(out, "    {result}\n}}\n");
        let bodies_only = if rigid > 0 { "[..BODIES]" } else { "" };
        let _ = writeln!(
            out,
            "/// The constraint force Σₖ λₖ Jₖᵢ on every body (in file order): `dense_solution`, else `solution`.\n\
             pub fn forces(s: &State) -> [[f64; {dim}]; {n}] {{\n    \
             if let Some(x) = dense_solution(s) {{\n        return x.1;\n    }}\n    \
             let mut f = [[0.0; {dim}]; {n}];\n    f.copy_from_slice(&solution(s).force{bodies_only});\n    f\n}}\n"
        );
        if rigid > 0 {
            let _ = writeln!(
                out,
                "/// The constraint torque Σₖ λₖ Jʷₖ on every rigid body (`RIGID_BODIES`): `dense_solution`, else `solution`.\n\
                 pub fn torques(s: &State) -> [f64; {rigid}] {{\n    \
                 if let Some(x) = dense_solution(s) {{\n        return x.2;\n    }}\n    \
                 let x = solution(s);\n    std::array::from_fn(|r| x.force[BODIES + r][0])\n}}\n"
            );
        }
        Ok(())
    }
}

/// Σₖ λₖ eₖ, one entry of the forces or torques of `dense_solution` in either language, from
/// its rows' (k, eₖ) in row order: `l[k]` where eₖ is the constant 1, `-l[k]` (`- l[k]` after
/// the first term) where it is −1, `l[k] * eₖ` otherwise (`operand` parenthesises eₖ), and
/// nothing where it is the constant 0; `None` where every eₖ is. Exact but for the sign of a
/// zero: λ is finite by then, so a left-out λₖ·0 is ±0, as is the 0 the sum no longer starts
/// from, and x·1 = x, x·(−1) = −x, y + x·(−1) = y − x bit for bit.
pub(super) fn lambda_sum(terms: Vec<(usize, String)>, operand: fn(&str) -> String) -> Option<String> {
    let mut sum = String::new();
    for (k, e) in terms {
        let term = match e.as_str() {
            "0.0" | "-0.0" => continue,
            "1.0" => format!("l[{k}]"),
            "-1.0" if sum.is_empty() => format!("-l[{k}]"),
            "-1.0" => {
                sum.push_str(&format!(" - l[{k}]"));
                continue;
            }
            _ => format!("l[{k}] * {}", operand(&e)),
        };
        if !sum.is_empty() {
            sum.push_str(" + ");
        }
        sum.push_str(&term);
    }
    if sum.is_empty() { None } else { Some(sum) }
}

/// The names of `force_<body>` (every body) and `torque_<body>` (every rigid body), clear of
/// the module's other functions.
pub(super) fn per_body_fns(names: &Names<'_>, turns: &Turns) -> (Vec<String>, Vec<String>) {
    let mut namer = Namer::new(&[
        "constraints",
        "a_matrix",
        "a_band",
        "b_vector",
        "jacobian",
        "jacobian_blocks",
        "c_term",
        "lambda",
        "forces",
        "torques",
    ]);
    let force_fns: Vec<String> = names.bodies.iter().map(|b| namer.name(&format!("force_{}", snake(b)))).collect();
    let torque_fns: Vec<String> =
        turns.rigid_bodies().iter().map(|&b| namer.name(&format!("torque_{}", snake(names.bodies[b])))).collect();
    (force_fns, torque_fns)
}

/// A banded system of equalities: `forces` (and `torques`) Σₖ λₖ Jₖᵢ of `lambda` over J as the
/// layout stores it.
fn band_fns(out: &mut String, layout: &Layout, rigid: usize) {
    let (dim, n) = (layout.dim, layout.bodies);
    if matches!(layout.j, JStorage::Blocks { .. }) {
        let _ = writeln!(
            out,
            "/// The constraint force on every body (in file order): Σₖ λₖ Jₖᵢ.\n\
                         pub fn forces(s: &State) -> [[f64; {dim}]; {n}] {{\n    \
                         let (l, j) = (lambda(s), jacobian_blocks(s));\n    \
                         let mut f = [[0.0; {dim}]; {n}];\n    \
                         for (k, i, d) in j {{\n        \
                         for (x, y) in f[i].iter_mut().zip(d) {{\n            *x += l[k] * y;\n        }}\n    }}\n    \
                         f\n}}\n"
        );
    } else {
        let _ = writeln!(
            out,
            "/// The constraint force on every body (in file order): Σₖ λₖ Jₖᵢ.\n\
                         pub fn forces(s: &State) -> [[f64; {dim}]; {n}] {{\n    \
                         let (l, j) = (lambda(s), jacobian(s));\n    \
                         let mut f = [[0.0; {dim}]; {n}];\n    \
                         for (lk, jk) in l.iter().zip(j.iter()) {{\n        \
                         for (fi, ji) in f.iter_mut().zip(jk.chunks({dim})) {{\n            \
                         for (x, y) in fi.iter_mut().zip(ji) {{\n                *x += lk * y;\n            }}\n        }}\n    }}\n    \
                         f\n}}\n"
        );
    }
    if rigid > 0 {
        let (call, each) = match layout.j {
            JStorage::Blocks { .. } => {
                ("angular_jacobian_blocks(s)", "for (k, r, w) in jw {\n        t[r] += l[k] * w;\n    }")
            }
            JStorage::Dense => (
                "angular_jacobian(s)",
                "for (lk, wk) in l.iter().zip(jw.iter()) {\n        \
                             for (x, y) in t.iter_mut().zip(wk) {\n            *x += lk * y;\n        }\n    }",
            ),
        };
        let _ = writeln!(
            out,
            "/// The constraint torque on every rigid body (`RIGID_BODIES`): Σₖ λₖ Jʷₖ.\n\
                         pub fn torques(s: &State) -> [f64; {rigid}] {{\n    \
                         let (l, jw) = (lambda(s), {call});\n    \
                         let mut t = [0.0; {rigid}];\n    {each}\n    t\n}}\n"
        );
    }
}

/// Aₖⱼ = Σᵢ [Jₖᵢ·Jⱼᵢ / mᵢ + Jʷₖᵢ Jʷⱼᵢ / Iᵢ] for every non-zero entry of `f.a`, unsimplified:
/// the sum over the bodies both constraints act on, terms with the same mass summed before
/// one division, then the rigid bodies both turn (`inertias`: I of each rigid body).
fn assembled_a(
    g: &mut Graph,
    f: &Formulas,
    system: &crate::model::system::System,
    masses: &[Id],
    inertias: &[Option<Id>],
) -> Result<Vec<Id>, GenerateError> {
    let mut entries = Vec::new();
    for &(k, j, _) in &f.a {
        // (mass, dots over the bodies of that mass), in body order.
        let mut by_mass: Vec<(Id, Vec<Id>)> = Vec::new();
        for &(body, jk) in &f.jacobian[k] {
            let Some(&(_, jj)) = f.jacobian[j].iter().find(|d| d.0 == body) else { continue };
            // Signs out of the dot: (−u)·w = −(u·w) exactly, and u is then shared with the
            // other constraint on this body (a chain's link k − 1 and k both see r₍ₖ₋₁₎ − rₖ).
            let ((nk, uk), (nj, uj)) = (split_sign(g, jk), split_sign(g, jj));
            let Some(dot) = sparse_dot(g, uk, uj)? else { continue };
            let dot = if nk != nj { g.neg(dot) } else { dot };
            match by_mass.iter_mut().find(|e| e.0 == masses[body]) {
                Some(e) => e.1.push(dot),
                None => by_mass.push((masses[body], vec![dot])),
            }
        }
        let mut terms = Vec::new();
        for (m, dots) in by_mass {
            let sum = g.add(dots)?;
            let inv = g.powi(m, -1)?;
            terms.push(g.mul(vec![sum, inv])?);
        }
        for &(body, wk) in &f.angular[k] {
            let (Some(&(_, wj)), Some(inertia)) = (f.angular[j].iter().find(|d| d.0 == body), inertias[body]) else {
                continue;
            };
            // 3D: Σₐ (Jʷₖ·eₐ)(Jʷⱼ·eₐ)/Iₐ over the principal axes, as the axis slots solve it.
            if let Some(axes) = system.bodies[body].rigid.as_ref().and_then(|r| r.nodes.axes) {
                for (a, &e) in crate::expr::Axis::ALL.iter().zip(&axes) {
                    let (pk, pj) = (g.dot(wk, e)?, g.dot(wj, e)?);
                    let moment = g.comp(inertia, *a)?;
                    let inv = g.powi(moment, -1)?;
                    terms.push(g.mul(vec![pk, pj, inv])?);
                }
                continue;
            }
            if g.is_zero(wk) || g.is_zero(wj) {
                continue;
            }
            let inv = g.powi(inertia, -1)?;
            terms.push(g.mul(vec![wk, wj, inv])?);
        }
        entries.push(g.add(terms)?);
    }
    Ok(entries)
}

/// bₖ = Σᵢ Jₖᵢ·Fᵢ / mᵢ + Σ Jʷₖ τ / I + cₖ as assembled from the directions (the state's forces
/// and torques), unsimplified: it shares J, Jʷ and c with the rest of a program, where the
/// canonical bₖ is over a common denominator.
fn assembled_b(
    g: &mut Graph,
    f: &Formulas,
    system: &crate::model::system::System,
    masses: &[Id],
    inertias: &[Option<Id>],
) -> Result<Vec<Id>, GenerateError> {
    let mut out = Vec::with_capacity(f.bias.len());
    for k in 0..f.bias.len() {
        let mut terms = Vec::new();
        for &(body, j) in &f.jacobian[k] {
            let Some(dot) = sparse_dot(g, j, system.bodies[body].nodes.force)? else { continue };
            let inv = g.powi(masses[body], -1)?;
            terms.push(g.mul(vec![dot, inv])?);
        }
        for &(body, w) in &f.angular[k] {
            let (Some(rigid), Some(inertia)) = (&system.bodies[body].rigid, inertias[body]) else { continue };
            // 3D: Σₐ (Jʷ·eₐ)(eₐ·τ − (ω_b × I ω_b)ₐ)/Iₐ, the world I⁻¹(τ − ω × I ω) in the body's axes.
            if let Some(axes) = rigid.nodes.axes {
                for (a, &e) in axes.iter().enumerate() {
                    let slot = axis_slot(g, axes, rigid.nodes.angular_velocity, rigid.nodes.torque, inertia, a)?;
                    let p = g.dot(w, e)?;
                    terms.push(g.mul(vec![p, slot.torque, slot.inverse_inertia])?);
                }
                continue;
            }
            if g.is_zero(w) {
                continue;
            }
            let inv = g.powi(inertia, -1)?;
            terms.push(g.mul(vec![w, rigid.nodes.torque, inv])?);
        }
        terms.push(f.bias[k]);
        out.push(g.add(terms)?);
    }
    Ok(out)
}

/// u·w over the components that are not structurally 0, where u or w is a vector literal
/// with a 0 entry (a unit axis of a vector constraint): a 0 entry lowers to the constant 0,
/// and x·0 stays in the code (IEEE does not fold it: x may be ∞), so `0.0 * x` terms
/// survived in A and b. `None` where every component is 0 (orthogonal unit axes); u·w as
/// it was otherwise. Only the value at a non-finite x changes: that x shows in another term
/// or the result does not depend on it.
fn sparse_dot(g: &mut Graph, u: Id, w: Id) -> Result<Option<Id>, TypeError> {
    let entries = |g: &Graph, v: Id| match g.node(v) {
        crate::expr::Node::Vector(xs) if xs.len() == g.dim() => Some(xs.to_vec()),
        _ => None,
    };
    let (eu, ew) = (entries(g, u), entries(g, w));
    let zero_in = |g: &Graph, e: &Option<Vec<Id>>| e.as_ref().is_some_and(|xs| xs.iter().any(|&x| g.is_zero(x)));
    if !zero_in(g, &eu) && !zero_in(g, &ew) {
        return Ok(Some(g.dot(u, w)?));
    }
    let mut terms = Vec::new();
    for (d, &axis) in crate::expr::Axis::ALL.iter().enumerate().take(g.dim()) {
        let part = |g: &mut Graph, e: &Option<Vec<Id>>, v: Id| match e {
            Some(xs) => Ok(xs[d]),
            None => g.comp(v, axis),
        };
        let (a, b) = (part(g, &eu, u)?, part(g, &ew, w)?);
        if g.is_zero(a) || g.is_zero(b) {
            continue;
        }
        terms.push(g.mul(vec![a, b])?);
    }
    Ok(if terms.is_empty() { None } else { Some(g.add(terms)?) })
}

/// `(true, u)` when `id` is `−u`, else `(false, id)`.
fn split_sign(g: &Graph, id: Id) -> (bool, Id) {
    if let crate::expr::Node::Mul(xs) = g.node(id)
        && let [first, u] = xs[..]
        && g.as_num(first).is_some_and(|q| *q == Rational::int(-1))
    {
        return (true, u);
    }
    (false, id)
}

/// Whether a constant of `id` is non-zero but rounds to 0, ∞ or near the edges of f64.
fn out_of_range(g: &Graph, id: Id) -> bool {
    g.reachable(&[id]).into_iter().any(|x| match g.as_num(x) {
        Some(q) if !q.is_zero() => {
            let v = q.to_f64().abs();
            !(1e-280..=1e280).contains(&v)
        }
        _ => false,
    })
}

/// An `f64` as an exact rational (the decimal it prints as), if finite and not huge.
fn exact(x: f64) -> Option<Rational> {
    if !x.is_finite() {
        return None;
    }
    let q = Rational::parse_decimal(&format!("{:e}", x.abs()))?;
    Some(if x < 0.0 { q.neg() } else { q })
}

/// The fields of `State`: every symbol but accelerations and substituted ones. A name that
/// is a Rust identifier as written keeps it (`R`, `F`, `r`); any other becomes [`snake`] of
/// it, with `_2`, `_3`, … in file order where that is taken (names kept as written first).
/// With `arrays`, the bodies' positions, velocities, forces and mass symbols, and the 2D
/// rigid bodies' θ, ω, τ and inertia symbols, are entries of the role arrays [`ROLE_ARRAYS`]
/// instead (whose names no field takes; the rigid ones only where there are 2D rigid bodies).
fn state_fields(g: &Graph, bodies: &[&str], substituted: &FastSet<Symbol>, arrays: bool) -> Vec<Field> {
    // 2D rigid bodies' θ, ω, τ sit at their rigid body's place among the rigid bodies (the
    // order of the angular slots: body order); 3D ones (q, world ω, τ) keep their fields.
    let mut rigid: Vec<usize> = g
        .symbols()
        .filter_map(|(_, info)| match info.role {
            Role::Orientation { body } if arrays && g.dim() == 2 => Some(body),
            _ => None,
        })
        .collect();
    rigid.sort_unstable();
    rigid.dedup();
    let turn = |body: usize| rigid.binary_search(&body).ok();
    // The rigid roles' names are taken only where there are 2D rigid bodies.
    let reserved: Vec<&str> = match arrays {
        true => {
            ROLE_ARRAYS.iter().map(|r| r.0).filter(|r| !rigid.is_empty() || !scalar_role(r) || *r == "mass").collect()
        }
        false => Vec::new(),
    };
    let keep = |name: &str| super::names::as_written(name).filter(|n| !reserved.contains(n)).map(str::to_string);
    let mut kept: Vec<String> = g
        .symbols()
        .filter(|(s, info)| !substituted.contains(s) && !matches!(info.role, Role::Acceleration { .. }))
        .filter_map(|(_, info)| keep(&info.name))
        .collect();
    kept.extend(reserved.iter().map(|r| r.to_string()));
    let kept: Vec<&str> = kept.iter().map(String::as_str).collect();
    let mut namer = Namer::new(&kept);
    let mut fields = Vec::new();
    let (mut masses, mut inertias) = (0, 0);
    for (symbol, info) in g.symbols() {
        if substituted.contains(&symbol) {
            continue;
        }
        let name = comment_text(&info.name);
        let body = |i: usize| comment_text(bodies.get(i).copied().unwrap_or("?"));
        let doc = match info.role {
            Role::Acceleration { .. } | Role::AngularAcceleration { .. } => continue,
            Role::Orientation { body: i } => format!("Orientation `{name}` of body `{}`.", body(i)),
            Role::AngularVelocity { body: i } => format!("Angular velocity `{name}` of body `{}`.", body(i)),
            Role::Torque { body: i } => format!("External torque `{name}` on body `{}`.", body(i)),
            Role::Inertia { body: i } => format!("Inertia `{name}` (of body `{}`).", body(i)),
            Role::Time => format!("The time `{name}`."),
            Role::Parameter => format!("Parameter `{name}`."),
            Role::Position { body: i } => format!("Position `{name}` of body `{}`.", body(i)),
            Role::Velocity { body: i } => format!("Velocity `{name}` of body `{}`.", body(i)),
            Role::Force { body: i } => format!("External force `{name}` on body `{}`.", body(i)),
            Role::Mass { body: i } => format!("Mass `{name}` (of body `{}`).", body(i)),
        };
        let array = match info.role {
            _ if !arrays => None,
            Role::Position { body } => Some(("position", body)),
            Role::Velocity { body } => Some(("velocity", body)),
            Role::Force { body } => Some(("force", body)),
            Role::Mass { .. } => {
                masses += 1;
                Some(("mass", masses - 1))
            }
            Role::Orientation { body } => turn(body).map(|r| ("angle", r)),
            Role::AngularVelocity { body } => turn(body).map(|r| ("angular_velocity", r)),
            Role::Torque { body } => turn(body).map(|r| ("torque", r)),
            Role::Inertia { .. } if !rigid.is_empty() => {
                inertias += 1;
                Some(("inertia", inertias - 1))
            }
            _ => None,
        };
        let ident = match (array, keep(&info.name)) {
            (Some((name, i)), _) => format!("{name}[{i}]"),
            (None, Some(name)) => name,
            (None, None) => namer.name(&snake(&info.name)),
        };
        fields.push(Field { symbol, ident, doc, array });
    }
    fields
}

/// The role arrays of a big `State`, with their doc: body i's symbol of that role is entry i
/// (masses: the mass symbols in file order); the r-th 2D rigid body in file order (its
/// angular slot `BODIES + r`) has its θ, ω, τ at entry r (inertias: the inertia symbols in
/// file order).
pub(super) const ROLE_ARRAYS: [(&str, &str); 8] = [
    ("position", "The bodies' positions, body i at entry i"),
    ("velocity", "The bodies' velocities, body i at entry i"),
    ("force", "The external forces on the bodies, body i at entry i"),
    ("mass", "The mass symbols, in file order"),
    ("angle", "The 2D rigid bodies' angles θ, the r-th rigid body (in file order) at entry r"),
    ("angular_velocity", "The 2D rigid bodies' angular velocities ω, the r-th rigid body at entry r"),
    ("torque", "The external torques on the 2D rigid bodies, the r-th rigid body at entry r"),
    ("inertia", "The 2D rigid bodies' inertia symbols, in file order"),
];

/// Whether a role array holds scalars (one `f64` per entry) rather than vectors.
pub(super) fn scalar_role(name: &str) -> bool {
    matches!(name, "mass" | "angle" | "angular_velocity" | "torque" | "inertia")
}

/// The Rust expression of every input slot, in slot order.
fn slot_exprs(g: &Graph, fields: &[Field]) -> Vec<String> {
    let mut slots = Vec::new();
    for f in fields {
        if g.is_quaternion(f.symbol) {
            slots.extend((0..4).map(|k| format!("s.{}[{k}]", f.ident)));
        } else if g.symbol(f.symbol).ty == Ty::Vector {
            slots.extend((0..g.dim()).map(|k| format!("s.{}[{k}]", f.ident)));
        } else {
            slots.push(format!("s.{}", f.ident));
        }
    }
    slots
}

/// Lowers formulas to Rust statements and expressions.
pub(super) struct Ctx<'a> {
    pub(super) g: &'a Graph,
    /// The module's input layout, built once for all its functions.
    pub(super) inputs: &'a Inputs,
    pub(super) slots: &'a [String],
    /// Constants written that are not finite f64 (each occurrence in a function body).
    pub(super) non_finite: Cell<usize>,
    /// Write C (`const double` bindings, `<math.h>` calls, the module's `lg_` helpers).
    pub(super) c: bool,
    /// Bytes of formula code the module may still write, of its [`code_budget`].
    pub(super) room: Cell<usize>,
    pub(super) budget: usize,
}

/// Operator precedence of a rendered expression: what it may appear inside unparenthesised.
#[derive(Clone, Copy, PartialEq, PartialOrd)]
pub(super) enum Prec {
    Sum,
    Product,
    Unary,
    Atom,
}

impl Ctx<'_> {
    /// `pub fn name(s: &State) -> [f64; K]` for one scalar formula per entry: an array literal,
    /// or entry by entry ([`Ctx::emit_items`]) past [`MAX_PART`] entries.
    fn emit_scalars(&self, out: &mut String, doc: &[String], name: &str, roots: &[Id]) -> Result<(), GenerateError> {
        let k = roots.len();
        if layout::parted(k) {
            let items: Vec<Vec<Id>> = roots.iter().map(|&r| vec![r]).collect();
            let store = |i: usize, e: &[String]| format!("out[{i}] = {};", e[0]);
            self.emit_items(out, doc, name, &format!("[f64; {k}]"), &format!("[0.0; {k}]"), "f64", &items, store)
        } else {
            let (lets, exprs) = self.body(roots)?;
            emit_fn(out, doc, name, &format!("[f64; {k}]"), &lets, &array(&exprs));
            Ok(())
        }
    }

    /// `pub fn name(s: &State) -> [[f64; DIM]; N]` for one vector formula per entry.
    fn emit_vectors(&self, out: &mut String, doc: &[String], name: &str, roots: &[Id]) -> Result<(), GenerateError> {
        let (n, dim) = (roots.len(), self.g.dim());
        let items: Vec<Vec<Id>> = roots.iter().map(|&r| vec![r]).collect();
        let store = |i: usize, e: &[String]| format!("out[{i}] = {};", array(e));
        let (ret, init) = (format!("[[f64; {dim}]; {n}]"), format!("[[0.0; {dim}]; {n}]"));
        self.emit_items(out, doc, name, &ret, &init, &format!("[f64; {dim}]"), &items, store)
    }

    /// `pub fn name(s: &State) -> ret` that starts from `init` and stores every item:
    /// `store(i, exprs)` is the statement storing item i from the expressions of its roots'
    /// components. Past [`MAX_PART`] formulas (roots) the work is split into private
    /// `#[inline(never)]` functions of consecutive items, at most [`MAX_PART`] formulas each
    /// unless one item has more, called in turn on `&mut out` (a slice of `elem`):
    /// an unoptimised build gives every value of a function its own stack slot, so one
    /// function for a whole chain of thousands of links would need megabytes of stack. Values
    /// shared across two parts are computed in both.
    #[allow(clippy::too_many_arguments)]
    fn emit_items(
        &self,
        out: &mut String,
        doc: &[String],
        name: &str,
        ret: &str,
        init: &str,
        elem: &str,
        items: &[Vec<Id>],
        store: impl Fn(usize, &[String]) -> String,
    ) -> Result<(), GenerateError> {
        // The statements of items lo..hi: `let`s first, then one store per item.
        let statements = |lo: usize, hi: usize| -> Result<Vec<String>, GenerateError> {
            let roots: Vec<Id> = items[lo..hi].iter().flatten().copied().collect();
            let (mut lines, exprs) = self.body(&roots)?;
            let per_root = exprs.len() / roots.len().max(1);
            let mut at = 0;
            for (i, item) in items[lo..hi].iter().enumerate() {
                let n = item.len() * per_root;
                lines.push(store(lo + i, &exprs[at..at + n]));
                at += n;
            }
            Ok(lines)
        };
        for line in doc {
            let _ = writeln!(out, "/// {line}");
        }
        let _ = writeln!(out, "pub fn {name}(s: &State) -> {ret} {{");
        let _ = writeln!(out, "    let mut out = {init};");
        if !layout::parted(items.iter().map(Vec::len).sum::<usize>()) {
            let lines = statements(0, items.len())?;
            if !lines.iter().any(|l| l.contains("s.")) {
                let _ = writeln!(out, "    let _ = s;");
            }
            for l in lines {
                let _ = writeln!(out, "    {l}");
            }
            let _ = writeln!(out, "    out\n}}\n");
            return Ok(());
        }
        // Consecutive items up to MAX_PART formulas a part (at least one item each).
        let parts = layout::parts(items.iter().map(Vec::len));
        for part in &parts {
            let _ = writeln!(out, "    {name}_from_{}(s, &mut out);", part.start);
        }
        let _ = writeln!(out, "    out\n}}\n");
        for part in parts {
            let (lo, hi) = (part.start, part.end);
            let lines = statements(lo, hi)?;
            let _ = writeln!(out, "/// Items {lo}..{hi} of [`{name}`].\n#[inline(never)]");
            let _ = writeln!(out, "fn {name}_from_{lo}(s: &State, out: &mut [{elem}]) {{");
            if !lines.iter().any(|l| l.contains("s.")) {
                let _ = writeln!(out, "    let _ = s;");
            }
            for l in lines {
                let _ = writeln!(out, "    {l}");
            }
            let _ = writeln!(out, "}}\n");
        }
        Ok(())
    }

    /// `let` statements and one expression per output component of `roots`.
    pub(super) fn body(&self, roots: &[Id]) -> Result<(Vec<String>, Vec<String>), GenerateError> {
        self.body_of(roots, &vec![true; roots.len()])
    }

    /// [`Ctx::body`] lowered over all of `roots` (so its shared values, and its numbers, are
    /// those of the whole program) with code only for the roots `wanted` marks: the others'
    /// expressions are empty and no `let` is written that only they use.
    pub(super) fn body_of(&self, roots: &[Id], wanted: &[bool]) -> Result<(Vec<String>, Vec<String>), GenerateError> {
        let p = Program::lower_in(self.g, roots, self.inputs)?;
        self.render(&p, wanted)
    }

    /// The text of a lowered program: `let` statements and one expression per output
    /// component of the roots `wanted` marks (one flag per root, `p.output_ranges`), inputs
    /// written as `self.slots` names them.
    pub(super) fn render(&self, p: &Program, wanted: &[bool]) -> Result<(Vec<String>, Vec<String>), GenerateError> {
        let uses = p.use_counts();
        // The operations a wanted output depends on.
        let mut live = vec![false; p.ops.len()];
        for (range, _) in p.output_ranges.iter().zip(wanted).filter(|(_, w)| **w) {
            for &o in &p.outputs[range.clone()] {
                live[o as usize] = true;
            }
        }
        for i in (0..p.ops.len()).rev() {
            if live[i] {
                for a in p.ops[i].operands() {
                    live[a as usize] = true;
                }
            }
        }
        // Each value: its text, precedence and inline depth.
        let mut text: Vec<(String, Prec, u32)> = Vec::new();
        let mut lets = Vec::new();
        for (i, op) in p.ops.iter().enumerate() {
            let arg = |v: u32, min: Prec| -> (String, u32) {
                let (t, prec, depth) = &text[v as usize];
                if *prec >= min { (t.clone(), *depth) } else { (format!("({t})"), *depth) }
            };
            let receiver = |v: u32| -> (String, u32) {
                match p.ops[v as usize] {
                    // Folding leaves no constant receivers; should one appear, type it.
                    Op::Const(bits) if f64::from_bits(bits).is_finite() && !self.c => {
                        (format!("({:?}_f64)", f64::from_bits(bits)), 0)
                    }
                    _ => arg(v, Prec::Atom),
                }
            };
            let bin = |a: u32, b: u32, sym: &str, prec: Prec| {
                let (x, dx) = arg(a, prec);
                // The right operand binds tighter: floating-point sums are not associative.
                let (y, dy) = arg(b, if prec == Prec::Sum { Prec::Product } else { Prec::Unary });
                (format!("{x} {sym} {y}"), prec, dx.max(dy) + 1)
            };
            let (t, prec, depth) = match *op {
                Op::Input(j) => (self.slots[j as usize].clone(), Prec::Atom, 0),
                Op::Const(bits) => {
                    if !f64::from_bits(bits).is_finite() {
                        self.non_finite.set(self.non_finite.get() + 1);
                    }
                    let (t, prec) =
                        if self.c { super::c::literal(f64::from_bits(bits)) } else { literal(f64::from_bits(bits)) };
                    (t, prec, 0)
                }
                Op::Add(a, b) => bin(a, b, "+", Prec::Sum),
                Op::Sub(a, b) => bin(a, b, "-", Prec::Sum),
                Op::Mul(a, b) => bin(a, b, "*", Prec::Product),
                Op::Div(a, b) => bin(a, b, "/", Prec::Product),
                Op::Neg(a) => {
                    let (x, d) = arg(a, Prec::Atom);
                    (format!("-{x}"), Prec::Unary, d + 1)
                }
                Op::Powi(a, n) if self.c => {
                    let (x, d) = arg(a, Prec::Sum);
                    (format!("lg_powi({x}, {n})"), Prec::Atom, d + 1)
                }
                Op::Powi(a, n) => {
                    let (x, d) = receiver(a);
                    (format!("{x}.powi({n})"), Prec::Atom, d + 1)
                }
                // `<math.h>`'s function of the name: `sin(x)`, `atan2(y, x)`, `log(x)` for ln.
                Op::Call(f, args) if self.c => {
                    let all: Vec<(String, u32)> = args[..f.arity()].iter().map(|&a| arg(a, Prec::Sum)).collect();
                    let list = all.iter().map(|(t, _)| t.as_str()).collect::<Vec<_>>().join(", ");
                    let depth = all.iter().map(|(_, d)| *d).fold(0, u32::max);
                    let name = if f.name() == "ln" { "log" } else { f.name() };
                    (format!("{name}({list})"), Prec::Atom, depth + 1)
                }
                // `f64`'s method of the function's name: `x.sin()`, `y.atan2(x)`.
                Op::Call(f, args) => {
                    let (x, d) = receiver(args[0]);
                    let rest: Vec<(String, u32)> = args[1..f.arity()].iter().map(|&a| arg(a, Prec::Sum)).collect();
                    let list = rest.iter().map(|(t, _)| t.as_str()).collect::<Vec<_>>().join(", ");
                    let depth = rest.iter().map(|(_, d)| *d).fold(d, u32::max);
                    (format!("{x}.{}({list})", f.name()), Prec::Atom, depth + 1)
                }
                Op::Powf(a, b) | Op::Norm2(a, b) => {
                    let name = match (matches!(op, Op::Powf(..)), self.c) {
                        (true, false) => "powf",
                        (false, false) => "norm2",
                        (true, true) => "lg_powf",
                        (false, true) => "lg_norm2",
                    };
                    let ((x, dx), (y, dy)) = (arg(a, Prec::Sum), arg(b, Prec::Sum));
                    (format!("{name}({x}, {y})"), Prec::Atom, dx.max(dy) + 1)
                }
                Op::Norm3(a, b, c) => {
                    let ((x, dx), (y, dy), (z, dz)) = (arg(a, Prec::Sum), arg(b, Prec::Sum), arg(c, Prec::Sum));
                    let name = if self.c { "lg_norm3" } else { "norm3" };
                    (format!("{name}({x}, {y}, {z})"), Prec::Atom, dx.max(dy).max(dz) + 1)
                }
            };
            let simple = matches!(op, Op::Input(_) | Op::Const(_));
            if !live[i] {
                text.push((String::new(), Prec::Atom, 0));
            } else if !simple && (uses[i] > 1 || depth > MAX_INLINE_DEPTH) {
                self.spend(t.len())?;
                let name = format!("x{}", lets.len());
                lets.push(if self.c { format!("const double {name} = {t};") } else { format!("let {name} = {t};") });
                text.push((name, Prec::Atom, 0));
            } else {
                text.push((t, prec, depth));
            }
        }
        let mut exprs = Vec::with_capacity(p.outputs.len());
        for (range, &w) in p.output_ranges.iter().zip(wanted) {
            exprs.extend(
                p.outputs[range.clone()].iter().map(|&o| if w { text[o as usize].0.clone() } else { String::new() }),
            );
        }
        self.spend(exprs.iter().map(String::len).sum())?;
        Ok((lets, exprs))
    }

    /// Takes `bytes` of code from the module's [`code_budget`].
    fn spend(&self, bytes: usize) -> Result<(), GenerateError> {
        let left = self.room.get().checked_sub(bytes).ok_or(GenerateError::CodeTooLarge(self.budget))?;
        self.room.set(left);
        Ok(())
    }
}

/// A float literal and its precedence (a negative literal is a unary minus).
pub(super) fn literal(x: f64) -> (String, Prec) {
    if x.is_nan() {
        ("f64::NAN".into(), Prec::Atom)
    } else if x == f64::INFINITY {
        ("f64::INFINITY".into(), Prec::Atom)
    } else if x == f64::NEG_INFINITY {
        ("f64::NEG_INFINITY".into(), Prec::Atom)
    } else {
        // `{:?}` writes the shortest text that reads back as the same f64, with a `.` or `e`.
        let t = format!("{x:?}");
        if x.is_sign_negative() { (t, Prec::Unary) } else { (t, Prec::Atom) }
    }
}

pub(super) fn array(items: &[String]) -> String {
    format!("[{}]", items.join(", "))
}

fn emit_fn(out: &mut String, doc: &[String], name: &str, ret: &str, lets: &[String], value: &str) {
    for line in doc {
        let _ = writeln!(out, "/// {line}");
    }
    let _ = writeln!(out, "pub fn {name}(s: &State) -> {ret} {{");
    let reads = |t: &str| t.contains("s.") || t.contains("(s)");
    if !lets.iter().any(|l| reads(l)) && !reads(value) {
        // Keep the parameter used in name only: the value does not depend on the state.
        let _ = writeln!(out, "    let _ = s;");
    }
    for l in lets {
        let _ = writeln!(out, "    {l}");
    }
    let _ = writeln!(out, "    {value}\n}}\n");
}

/// A formula for a doc comment: Unicode text, one line, escaped, shortened if long.
pub(super) fn formula(g: &Graph, id: Id) -> String {
    match print(g, id, Style::Text) {
        Ok(t) if t.chars().count() > MAX_DOC_FORMULA => {
            let short: String = t.chars().take(MAX_DOC_FORMULA).collect();
            format!("{} …", comment_text(&short))
        }
        Ok(t) => comment_text(&t),
        Err(e) => format!("({})", comment_text(&e.to_string())),
    }
}

/// The `A_BANDWIDTH` constant and the doc lines that say how a banded A is stored.
fn band_header(out: &mut String, doc: &mut Vec<String>, bandwidth: usize) {
    let _ = writeln!(
        out,
        "/// Half-bandwidth of A: Aₖⱼ = 0 when |k − j| > A_BANDWIDTH.\npub const A_BANDWIDTH: usize = {bandwidth};\n"
    );
    doc.push(String::new());
    doc.push(format!(
        "Stored as a band (A is symmetric): row k holds A[k][k], A[k][k + 1], …, A[k][k + {bandwidth}], \
         zeros past the last column."
    ));
}
