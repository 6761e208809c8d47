//! `lagrange generate --lang c`: the formulas of the Rust module as C99 without dependencies
//! (`<math.h>` only), clean under `-std=c99 -Wall -Wextra -Werror -ffp-contract=off`, and
//! bit for bit the Rust module's numbers: every function body is the same scalar program
//! (`Ctx::body` of `codegen::rust` in its C form), the helpers (`lg_norm2`, `lg_norm3`,
//! `lg_powf`, `lg_powi`) do the Rust helpers' operations, and `-ffp-contract=off` keeps the
//! compiler from fusing a product into a sum (Rust never does).
//!
//! The module has a `State` struct (the Rust module's fields; a name C cannot have — a C
//! keyword, a macro of `<math.h>`, a reserved identifier — gets `_`, then a suffix where
//! taken), the constants `DIM`, `BODIES`, `CONSTRAINTS`, `SCALE`, `INEQUALITY`, and one
//! function per output writing into an array the caller passes: `constraints`,
//! `constraint_rates`, `a_matrix` (or `a_band`), `b_vector`, `jacobian` (or
//! `jacobian_blocks`), `c_term`, `positions`, `velocities`, `external_forces`,
//! `applied_forces`, `inverse_masses`; with rigid bodies also `orientations`,
//! `angular_velocities`, `external_torques`, `applied_torques`, `inverse_inertias` and
//! `angular_jacobian` (Jʷ), as the Rust module has them. 3D rigid bodies likewise: q as
//! `double[4]` ([w, x, y, z]) in `State`, `ANGULAR_SLOTS`, `orientations`, world-vector
//! `angular_velocities`, `external_torques`, `applied_torques`, `body_axes`, and per axis
//! slot `axis_inverse_inertias`, `axis_angular_velocities`, `axis_torques` and Jʷ·eₖ.
//!
//! With `--solver soft-step|pgs|exact` the module also has the step (`step`, `step_with`,
//! `step_settings_default`), for point masses and 2D and 3D rigid bodies: the scene's
//! `step_rows` over the Rust module's roots (`StepRoots`, those of its `prepare` or
//! `step_rows`), its state accessors, and the text of `support/motion.c` (or `motion_3d.c`),
//! `support/step.c` and `sweep.c` or `exact.c`, the Rust step's operations in its order.
//!
//! Not here: layout decisions (`codegen::layout`, shared with the Rust emitter), the λ path
//! (`codegen::c_solve`), files or stdout.

use super::layout::{self, AStorage, JStorage, Layout, Solver};
use super::names::{Namer, c_reserved, comment_text};
use super::rust::{
    Bodies, Ctx, Field, Formulas, GenerateError, LengthPlace, Names, Prec, ROLE_ARRAYS, StepRoots, Turns, formula,
    scalar_role,
};
use crate::expr::graph::FastMap;
use crate::expr::{Graph, Id, Symbol, Ty};
use std::fmt::Write;

/// What the C text is written from (the Rust emitter's formulas and layout).
pub(super) struct Parts<'a> {
    pub title: &'a str,
    pub specialize: bool,
    pub fields: &'a [Field],
    /// The C name of each field (same order).
    pub c_names: &'a [String],
    pub formulas: &'a Formulas,
    pub a_code: &'a [Id],
    pub bodies: &'a Bodies,
    /// The rigid bodies (none for point masses).
    pub turns: &'a Turns,
    pub names: &'a Names<'a>,
    pub layout: &'a Layout,
    pub scales: &'a [f64],
    pub inequalities: &'a [bool],
    /// b as assembled (the dense λ path's program).
    pub b_code: &'a [Id],
    /// The state's length-like places (`solution`'s change of unit; point masses).
    pub length_places: Vec<LengthPlace>,
    /// The step, with `--solver`.
    pub step: Option<StepParts>,
}

/// What the step's C needs beyond the formulas.
pub(super) struct StepParts {
    pub solver: Solver,
    /// 1/κ as the library's rows multiply by it.
    pub inverse_scales: Vec<f64>,
    pub time: Symbol,
    /// Each body's position and velocity symbols.
    pub bodies: Vec<(Symbol, Symbol)>,
    /// Each rigid body's orientation and angular velocity symbols, in the order of its slots.
    pub turns: Vec<(Symbol, Symbol)>,
    /// The rows' roots in the library's order (as the Rust module's `step_rows`).
    pub roots: StepRoots,
}

/// The step's shared C (`support/step.c`): the Rust step's operations in its order.
const STEP_C: &str = include_str!("support/step.c");
/// The kick and drift over the slots (`support/motion.c`, no 3D rigid body).
const MOTION_C: &str = include_str!("support/motion.c");
/// The same with 3D rigid bodies (`support/motion_3d.c`).
const MOTION_3D_C: &str = include_str!("support/motion_3d.c");
/// The soft step and PGS (`support/sweep.c`).
const SWEEP_C: &str = include_str!("support/sweep.c");
/// The exact step (`support/exact.c`).
const EXACT_C: &str = include_str!("support/exact.c");

/// The C name of each field: the Rust one, unless C cannot have it (then `_`, and a suffix
/// where taken). A role array's entry (`position[3]`) keeps its form.
pub(super) fn field_names(fields: &[Field]) -> Vec<String> {
    let taken: Vec<&str> = fields.iter().map(|f| f.ident.as_str()).collect();
    let mut namer = Namer::new(&taken);
    fields
        .iter()
        .map(|f| {
            if f.array.is_none() && c_reserved(&f.ident) {
                namer.name(&format!("{}_", f.ident))
            } else {
                f.ident.clone()
            }
        })
        .collect()
}

/// The C expression of every input slot, in slot order (`s->r1[0]`).
pub(super) fn slots(g: &Graph, fields: &[Field], c_names: &[String]) -> Vec<String> {
    let mut slots = Vec::new();
    for (f, name) in fields.iter().zip(c_names) {
        if g.is_quaternion(f.symbol) {
            slots.extend((0..4).map(|k| format!("s->{name}[{k}]")));
        } else if g.symbol(f.symbol).ty == Ty::Vector {
            slots.extend((0..g.dim()).map(|k| format!("s->{name}[{k}]")));
        } else {
            slots.push(format!("s->{name}"));
        }
    }
    slots
}

/// A C literal of `x`, exact (the shortest decimal that reads back as `x`); `<math.h>`'s
/// `INFINITY` and `NAN` for the non-finite.
pub(super) fn literal(x: f64) -> (String, Prec) {
    if x.is_nan() {
        ("NAN".into(), Prec::Atom)
    } else if x == f64::INFINITY {
        ("INFINITY".into(), Prec::Atom)
    } else if x == f64::NEG_INFINITY {
        ("-INFINITY".into(), Prec::Unary)
    } else {
        let t = format!("{x:?}");
        if x.is_sign_negative() { (t, Prec::Unary) } else { (t, Prec::Atom) }
    }
}

/// The helpers the formulas call: the Rust module's `norm2`, `norm3`, `powf` and f64's
/// `powi` (binary powers, as LLVM expands a constant exponent), with their operations.
const HELPERS: &str = "\
/* |(x, y)| without overflow or underflow (the plain formula unless it would lose range). */
static inline double lg_norm2(double x, double y) {
    const double s = x * x + y * y;
    return (isfinite(s) && s >= DBL_MIN) ? sqrt(s) : hypot(x, y);
}

/* |(x, y, z)| without overflow or underflow. */
static inline double lg_norm3(double x, double y, double z) {
    const double s = x * x + y * y + z * z;
    return (isfinite(s) && s >= DBL_MIN) ? sqrt(s) : hypot(hypot(x, y), z);
}

/* x^n for an integer n by binary powers: the result starts at the lowest set bit's power. */
static inline double lg_powi(double x, int n) {
    const int reciprocal = n < 0;
    double r = 1.0;
    for (;;) {
        if (n & 1) {
            r *= x;
        }
        n /= 2;
        if (n == 0) {
            break;
        }
        x *= x;
    }
    return reciprocal ? 1.0 / r : r;
}

/* b^e, integer exponents by lg_powi so that negative bases work. */
static inline double lg_powf(double b, double e) {
    if (e == trunc(e) && fabs(e) <= 2147483647.0) {
        return lg_powi(b, (int)e);
    }
    return pow(b, e);
}
";

/// The C module's text.
pub(super) fn emit(ctx: &Ctx<'_>, p: &Parts<'_>) -> Result<String, GenerateError> {
    let (g, l) = (ctx.g, p.layout);
    let (dim, n, k) = (l.dim, l.bodies, l.constraints);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "/* Generated by `lagrange generate --lang c{}`. */",
        super::flags(p.specialize, p.step.as_ref().map(|s| s.solver))
    );
    let _ = writeln!(out, "/* Scene: {} */", c_comment(p.title));
    let _ = writeln!(
        out,
        "/* Do not edit: regenerate. C99 without dependencies (<math.h>, link with -lm); compile with\n   \
         -ffp-contract=off to get the Rust module's numbers bit for bit. */"
    );
    let _ = writeln!(
        out,
        "/* {dim}D, {n} bod{}, {k} constraint{}; vectors are double[{dim}]. Convention: `constraints` is C as\n   \
         written, `jacobian` J = grad C / SCALE[k], and `c_term` and lambda refer to C/SCALE[k]. */\n",
        if n == 1 { "y" } else { "ies" },
        if k == 1 { "" } else { "s" }
    );
    out.push_str("#include <float.h>\n#include <limits.h>\n#include <math.h>\n#include <stdlib.h>\n\n");
    let _ = writeln!(out, "enum {{ DIM = {dim}, BODIES = {n}, CONSTRAINTS = {k} }};\n");
    // The state.
    let _ = writeln!(out, "/* A state of the scene: every input of the formulas (the Rust module's fields). */");
    let _ = writeln!(out, "typedef struct State {{");
    for (f, name) in p.fields.iter().zip(p.c_names).filter(|(f, _)| f.array.is_none()) {
        let ty = if g.is_quaternion(f.symbol) {
            "[4]".to_string()
        } else if g.symbol(f.symbol).ty == Ty::Vector {
            format!("[{dim}]")
        } else {
            String::new()
        };
        let _ = writeln!(out, "    /* {} */\n    double {name}{ty};", c_comment(&f.doc));
    }
    for (role, _) in ROLE_ARRAYS {
        let len = p.fields.iter().filter(|f| f.array.is_some_and(|a| a.0 == role)).count();
        if len > 0 {
            let shape = if scalar_role(role) { format!("[{len}]") } else { format!("[{len}][{dim}]") };
            let _ = writeln!(out, "    double {role}{shape};");
        }
    }
    if p.fields.is_empty() {
        let _ = writeln!(out, "    double unused;");
    }
    let _ = writeln!(out, "}} State;\n");
    let scales: Vec<String> = p.scales.iter().map(|x| literal(*x).0).collect();
    let _ = writeln!(out, "/* kappa of each constraint: grad C = SCALE[k] J[k]. */");
    let _ = writeln!(out, "const double SCALE[{}] = {{{}}};", k.max(1), list(&scales, k));
    let flags: Vec<String> = p.inequalities.iter().map(|b| if *b { "1".into() } else { "0".into() }).collect();
    let _ = writeln!(out, "/* Which constraints are inequalities C >= 0. */");
    let _ = writeln!(out, "const int INEQUALITY[{}] = {{{}}};\n", k.max(1), list(&flags, k));
    out.push_str(HELPERS);
    out.push('\n');
    let f = p.formulas;
    let doc_list = |what: &str, ids: &[Id]| {
        let mut d = vec![what.to_string()];
        for (i, &id) in ids.iter().enumerate() {
            d.push(format!("- `{}`: {}", comment_text(p.names.constraints[i]), formula(g, id)));
        }
        d
    };
    scalars(ctx, &mut out, &doc_list("The constraint values C:", &f.c), "constraints", &f.c, k)?;
    scalars(ctx, &mut out, &doc_list("The rates of C (with dC/dt):", &f.c_dot), "constraint_rates", &f.c_dot, k)?;
    a(ctx, &mut out, p)?;
    scalars(ctx, &mut out, &["b of A lambda + b = 0.".to_string()], "b_vector", &f.b, k)?;
    jacobian(ctx, &mut out, p)?;
    scalars(
        ctx,
        &mut out,
        &["c: the part of the second derivative of C/SCALE without accelerations.".to_string()],
        "c_term",
        &f.bias,
        k,
    )?;
    let b = p.bodies;
    for (name, what, roots) in [
        ("positions", "The position of each body.", &b.position),
        ("velocities", "The velocity of each body.", &b.velocity),
        ("external_forces", "The external force on each body (the state's force fields).", &b.force),
        ("applied_forces", "The scene's forces at this state (zero for a body it does not list).", &b.applied),
    ] {
        let (lets, exprs) = ctx.body(roots)?;
        let stores: Vec<String> = (0..n)
            .flat_map(|i| (0..dim).map(move |d| (i, d)))
            .map(|(i, d)| format!("out[{i}][{d}] = {};", exprs[i * dim + d]))
            .collect();
        function(&mut out, &[what.to_string()], name, &format!("double out[{}][{dim}]", n.max(1)), &lets, &stores);
    }
    let (lets, exprs) = ctx.body(&b.inverse_mass)?;
    let stores: Vec<String> = exprs.iter().enumerate().map(|(i, e)| format!("out[{i}] = {e};")).collect();
    function(
        &mut out,
        &["1/m of each body.".to_string()],
        "inverse_masses",
        &format!("double out[{}]", n.max(1)),
        &lets,
        &stores,
    );
    rigid(ctx, &mut out, p)?;
    super::c_solve::emit(ctx, &mut out, p)?;
    if let Some(step) = &p.step {
        step_c(ctx, &mut out, p, step)?;
    }
    Ok(out)
}

/// The rigid bodies' numbers and Jʷ, as the Rust module has them (nothing for point masses):
/// 2D ([`rigid_2d`]) or 3D ([`rigid_3d`]), then [`angular_jacobian`].
fn rigid(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let t = p.turns;
    let r = t.body.len();
    if r == 0 {
        return Ok(());
    }
    if t.three.is_empty() {
        rigid_2d(ctx, out, p)?;
    } else {
        rigid_3d(ctx, out, p)?;
    }
    angular_jacobian(ctx, out, p)
}

/// A 2D module's rigid bodies: `RIGID`, `RIGID_BODIES`, and θ, ω, τ, the scene's τ and 1/I
/// per rigid body.
fn rigid_2d(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let t = p.turns;
    let r = t.body.len();
    let bodies: Vec<String> = t.body.iter().map(usize::to_string).collect();
    let _ = writeln!(
        out,
        "/* The rigid bodies: rigid body r is body RIGID_BODIES[r] (2D: angle, angular velocity, inertia, torque). */
         enum {{ RIGID = {r} }};
const int RIGID_BODIES[{r}] = {{{}}};
",
        bodies.join(", ")
    );
    for (name, what, roots) in [
        ("orientations", "The angle of each rigid body (counter-clockwise).", &t.orientation),
        ("angular_velocities", "The angular velocity of each rigid body.", &t.angular_velocity),
        ("external_torques", "The external torque on each rigid body (the state's torque fields).", &t.torque),
        ("applied_torques", "The scene's torques at this state (zero for a rigid body it does not list).", &t.applied),
        ("inverse_inertias", "1/I of each rigid body.", &t.inverse_inertia),
    ] {
        scalars(ctx, out, &[what.to_string()], name, roots, r)?;
    }
    Ok(())
}

/// A 3D module's rigid bodies, as the Rust module's: `RIGID`, `RIGID_BODIES`,
/// `ANGULAR_SLOTS`; per rigid body q (4 doubles, [w, x, y, z]), ω, τ, the scene's τ (world
/// vectors) and the principal axes (`body_axes`); per axis slot 1/Iₖ, eₖ·ω and
/// eₖ·τ − (ω_b × I ω_b)ₖ, what the rows' solve reads.
fn rigid_3d(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let t = p.turns;
    let r = t.three.len();
    let bodies: Vec<String> = t.three.iter().map(|x| x.body.to_string()).collect();
    let _ = writeln!(
        out,
        "/* The rigid bodies (3D): rigid body r is body RIGID_BODIES[r] (unit quaternion q = [w, x, y, z], omega and
   tau in the world frame, principal moments [I1, I2, I3]); its principal axis k has the angular slot
   BODIES + 3r + k of the rows' solve. */
enum {{ RIGID = {r}, ANGULAR_SLOTS = {} }};
const int RIGID_BODIES[{r}] = {{{}}};
",
        3 * r,
        bodies.join(", ")
    );
    let name_of = |sym: Symbol| p.fields.iter().position(|f| f.symbol == sym).map(|i| p.c_names[i].clone());
    let mut stores = Vec::new();
    for (i, x) in t.three.iter().enumerate() {
        let q = name_of(x.orientation).unwrap_or_default();
        stores.extend((0..4).map(|c| format!("out[{i}][{c}] = s->{q}[{c}];")));
    }
    function(
        out,
        &["The orientation q = [w, x, y, z] (Hamilton, unit) of each rigid body.".to_string()],
        "orientations",
        &format!("double out[{r}][4]"),
        &[],
        &stores,
    );
    let vectors: [(&str, &str, Vec<Id>); 3] = [
        (
            "angular_velocities",
            "The angular velocity omega (world frame) of each rigid body.",
            t.three.iter().map(|x| x.angular_velocity).collect(),
        ),
        (
            "external_torques",
            "The external torque tau (world frame) on each rigid body (the state's torque fields).",
            t.three.iter().map(|x| x.torque).collect(),
        ),
        (
            "applied_torques",
            "The scene's torques (world frame) at this state (zero for a rigid body it does not list).",
            t.three.iter().map(|x| x.applied).collect(),
        ),
    ];
    for (name, what, roots) in vectors {
        let (lets, exprs) = ctx.body(&roots)?;
        let stores: Vec<String> = (0..r)
            .flat_map(|i| (0..3).map(move |d| (i, d)))
            .map(|(i, d)| format!("out[{i}][{d}] = {};", exprs[i * 3 + d]))
            .collect();
        function(out, &[what.to_string()], name, &format!("double out[{r}][3]"), &lets, &stores);
    }
    let roots: Vec<Id> = t.three.iter().flat_map(|x| x.axes).collect();
    let (lets, exprs) = ctx.body(&roots)?;
    let mut stores = Vec::new();
    for i in 0..r {
        for a in 0..3 {
            for d in 0..3 {
                stores.push(format!("out[{i}][{a}][{d}] = {};", exprs[(i * 3 + a) * 3 + d]));
            }
        }
    }
    function(
        out,
        &["The principal axes R(q) e_k (out[r][k], the columns of R(q)) of each rigid body, in the world.".to_string()],
        "body_axes",
        &format!("double out[{r}][3][3]"),
        &lets,
        &stores,
    );
    let slots = 3 * r;
    for (name, what, roots) in [
        ("axis_inverse_inertias", "1/I_k of each axis slot (rigid body r's axis k at 3r + k).", &t.inverse_inertia),
        ("axis_angular_velocities", "omega_k = e_k.omega of each axis slot.", &t.angular_velocity),
        (
            "axis_torques",
            "e_k.tau - (omega_b x I omega_b)_k of each axis slot: the external torque with the gyroscopic term of Euler's equations in the body frame (omega_b = (e_j.omega)_j), from the state's torque fields.",
            &t.torque,
        ),
    ] {
        scalars(ctx, out, &[what.to_string()], name, roots, slots)?;
    }
    Ok(())
}

/// `angular_jacobian` (dense, K × angular slots) or `angular_jacobian_blocks` (with
/// `ANGULAR_ROW` and `ANGULAR_SLOT`): Jʷ in 2D, Jʷ·eₖ per axis slot in 3D.
fn angular_jacobian(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let t = p.turns;
    let (r, k) = (t.body.len(), p.layout.constraints);
    let entries = t.entries(p.formulas);
    let roots: Vec<Id> = entries.iter().map(|e| e.2).collect();
    let (lets, exprs) = ctx.body(&roots)?;
    let mut stores = Vec::new();
    match p.layout.j {
        JStorage::Blocks { .. } => {
            let count = entries.len();
            let rows: Vec<String> = entries.iter().map(|e| e.0.to_string()).collect();
            let slots: Vec<String> = entries.iter().map(|e| e.1.to_string()).collect();
            let _ =
                writeln!(out, "/* The constraint and the rigid body of each entry of `angular_jacobian_blocks`. */");
            let _ = writeln!(out, "const int ANGULAR_ROW[{}] = {{{}}};", count.max(1), list(&rows, count));
            let _ = writeln!(out, "const int ANGULAR_SLOT[{}] = {{{}}};\n", count.max(1), list(&slots, count));
            stores.extend(exprs.iter().enumerate().map(|(i, e)| format!("out[{i}] = {e};")));
            let doc =
                ["The angular part of J, sparse: entry i is constraint ANGULAR_ROW[i] on rigid body ANGULAR_SLOT[i]."
                    .to_string()];
            function(out, &doc, "angular_jacobian_blocks", &format!("double out[{}]", count.max(1)), &lets, &stores);
        }
        JStorage::Dense => {
            for row in 0..k {
                for slot in 0..r {
                    let at = entries.iter().position(|e| e.0 == row && e.1 == slot);
                    stores
                        .push(format!("out[{row}][{slot}] = {};", at.map_or("0.0".to_string(), |i| exprs[i].clone())));
                }
            }
            let doc = if t.three.is_empty() {
                ["The angular part of J (dC/dtheta over SCALE[k]): row k, column r is rigid body r.".to_string()]
            } else {
                ["The angular part of J on each principal axis (Jw.e_k): row k, column 3r + a is rigid body r's axis a."
                    .to_string()]
            };
            function(out, &doc, "angular_jacobian", &format!("double out[{}][{r}]", k.max(1)), &lets, &stores);
        }
    }
    Ok(())
}

/// The scene's part of the step in C (`step_rows`, the state's accessors, the row
/// structure) and the shared text: `support/step.c`, the motion of the slots
/// (`support/motion.c`, or `motion_3d.c`), then the solver's (`sweep.c` or `exact.c`).
fn step_c(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>, step: &StepParts) -> Result<(), GenerateError> {
    let (dim, n, k) = (p.layout.dim, p.layout.bodies, p.layout.constraints);
    let f = p.formulas;
    let roots = &step.roots;
    let slots = roots.slots(n);
    let rigid_3d = roots.three();
    let (starts, bodies, entry_at) = roots.entries(f);
    let masks: Vec<String> =
        roots.codes(&starts, &bodies, &entry_at).iter().map(|&c| super::rust::entry_mask(c).to_string()).collect();
    let (starts, bodies): (Vec<String>, Vec<String>) =
        (starts.iter().map(usize::to_string).collect(), bodies.iter().map(usize::to_string).collect());
    let at: Vec<String> = entry_at.iter().map(usize::to_string).collect();
    let entries = bodies.len();
    let _ = writeln!(
        out,
        "/* The velocity-level step: `lagrange generate --lang c --solver {}`. */\n\
         enum {{ SOLVER_PGS = {}, DEFAULT_ITERATIONS = {}, RIGID_3D = {rigid_3d} }};\n",
        step.solver.name(),
        i32::from(step.solver == Solver::Pgs),
        step.solver.default_iterations()
    );
    let inv: Vec<String> = step.inverse_scales.iter().map(|x| literal(*x).0).collect();
    let _ = writeln!(
        out,
        "/* 1/kappa of each constraint. */\nconst double INVERSE_SCALE[{}] = {{{}}};",
        k.max(1),
        list(&inv, k)
    );
    let _ = writeln!(
        out,
        "/* Row k's Jacobian entries are ROW_START[k] .. ROW_START[k + 1], on slots ROW_BODY[e] (the bodies, then\n   \
         the rigid bodies' angular slots). */"
    );
    let _ = writeln!(out, "static const int ROW_START[{}] = {{{}}};", k + 1, starts.join(", "));
    let _ = writeln!(out, "static const int ROW_BODY[{}] = {{{}}};", entries.max(1), list(&bodies, entries));
    let _ = writeln!(
        out,
        "/* In the step's order: the last term of a row's rate is the velocity the row before wrote last (the\n   \
         library's velocity::entry_order). Per entry in the derivation's order, its place in the step's. */"
    );
    let _ = writeln!(out, "const int ENTRY_AT[{}] = {{{}}};", entries.max(1), list(&at, entries));
    let _ = writeln!(
        out,
        "/* Per entry in the step's order, the components of its J that can be nonzero (bit d: component d): the\n   \
         structural zeros of the rows as written (velocity::pattern), which the rate and an impulse leave out. */"
    );
    let _ = writeln!(out, "static const unsigned char ENTRY_MASK[{}] = {{{}}};", entries.max(1), list(&masks, entries));
    let steady: Vec<String> = roots.steady.iter().map(|&b| i32::from(b).to_string()).collect();
    let _ = writeln!(
        out,
        "/* Per row, whether its C reads no time: dC/dt = 0 exactly (velocity::steady_rows). */\n\
         static const int STEADY[{}] = {{{}}};\n",
        k.max(1),
        list(&steady, k)
    );
    let unit: Vec<String> = (0..k).map(|r| i32::from(roots.pattern.is_unit(r)).to_string()).collect();
    let _ = writeln!(
        out,
        "/* Per row, whether every entry of its J is a unit vector, +-e/|e| (velocity::pattern): its |J_i|^2 is\n   \
         taken as exactly 1 (lg_unit_square), as the library and the Rust module take it. */\n\
         static const int UNIT[{}] = {{{}}};\n",
        k.max(1),
        list(&unit, k)
    );
    let _ = writeln!(
        out,
        "/* The rows of a state as the step reads them: per row C/kappa, its rate, c, J per entry; per slot\n   \
         1/m, v and the scene's force (a rigid body's 1/I, omega, tau), its principal axis (3D rigid bodies); and\n   \
         the step's effective masses, dC/dt and first 3D slot. */\n\
         typedef struct Prepared {{\n    double value[{k1}], rate[{k1}], bias[{k1}], time_rate[{k1}], effective_mass[{k1}];\n    \
         double inverse_mass[{slots}], velocity[{slots}][{dim}], force[{slots}][{dim}], axes[{slots}][{dim}];\n    \
         double jacobian[{e1}][{dim}];\n    int first;\n}} Prepared;\n",
        k1 = k.max(1),
        e1 = entries.max(1)
    );
    out.push_str(if rigid_3d > 0 { MOTION_3D_C } else { MOTION_C });
    out.push('\n');
    // The rows' roots in the library's order (as the Rust module's `prepare`): c, read by the
    // exact step alone, is left out of the others' code.
    let (lets, exprs) =
        if step.solver == Solver::Exact { ctx.body(&roots.roots)? } else { ctx.body_of(&roots.roots, &roots.swept)? };
    let mut values = exprs.into_iter();
    let mut next = || values.next().unwrap_or_default();
    let mut stores = Vec::new();
    for i in 0..n {
        stores.push(format!("r->inverse_mass[{i}] = 1.0 / {};", paren(&next())));
        for d in 0..dim {
            stores.push(format!("r->velocity[{i}][{d}] = {};", next()));
        }
        for d in 0..dim {
            stores.push(format!("r->force[{i}][{d}] = {};", next()));
        }
        if rigid_3d > 0 {
            stores.push(format!("r->axes[{i}][0] = 0.0;\n    r->axes[{i}][1] = 0.0;\n    r->axes[{i}][2] = 0.0;"));
        }
    }
    let vector = |next: &mut dyn FnMut() -> String| (0..3).map(|_| next()).collect::<Vec<_>>().join(", ");
    for &(first, three) in &roots.turns {
        if three {
            // I, ω, τ and the axes, then the body's three axis slots.
            let (i, w, t) = (vector(&mut next), vector(&mut next), vector(&mut next));
            let e = [vector(&mut next), vector(&mut next), vector(&mut next)];
            stores.push(format!(
                "{{\n        const double m[3] = {{{i}}}, w[3] = {{{w}}}, tau[3] = {{{t}}};\n        \
                 const double e[3][3] = {{{{{}}}, {{{}}}, {{{}}}}};\n        axis_slots(r, {first}, m, w, tau, e);\n    }}",
                e[0], e[1], e[2]
            ));
        } else {
            stores.push(format!("r->inverse_mass[{first}] = 1.0 / {};", paren(&next())));
            stores.push(format!("r->velocity[{first}][0] = {};\n    r->velocity[{first}][1] = 0.0;", next()));
            stores.push(format!("r->force[{first}][0] = {};\n    r->force[{first}][1] = 0.0;", next()));
        }
    }
    // Entry e_at in the derivation's order is kept at ENTRY_AT[e_at] (the step's order).
    let mut e_at = 0;
    for (r, angular) in roots.angular_slots.iter().enumerate() {
        stores.push(format!("r->value[{r}] = {} * INVERSE_SCALE[{r}];", paren(&next())));
        // A steady row's rate is not read by the soft step and PGS (its code is left out).
        let rate = next();
        if rate.is_empty() {
            stores.push(format!("r->rate[{r}] = 0.0;"));
        } else {
            stores.push(format!("r->rate[{r}] = {} * INVERSE_SCALE[{r}];", paren(&rate)));
        }
        let bias = next();
        if !bias.is_empty() {
            stores.push(format!("r->bias[{r}] = {bias};"));
        }
        for _ in &f.jacobian[r] {
            let e = entry_at[e_at];
            for d in 0..dim {
                stores.push(format!("r->jacobian[{e}][{d}] = {};", next()));
            }
            e_at += 1;
        }
        for &slot in angular {
            let e = entry_at[e_at];
            if rigid_3d > 0 {
                // Jʷ·eₖ: the axis' part of the world vector Jʷ.
                let jw = vector(&mut next);
                stores.push(format!(
                    "{{\n        const double jw[3] = {{{jw}}};\n        r->jacobian[{e}][0] = lg_dot3(r->axes[{slot}], jw);\n        \
                     r->jacobian[{e}][1] = 0.0;\n        r->jacobian[{e}][2] = 0.0;\n    }}"
                ));
            } else {
                stores.push(format!("r->jacobian[{e}][0] = {};\n    r->jacobian[{e}][1] = 0.0;", next()));
            }
            e_at += 1;
        }
    }
    let _ = writeln!(out, "/* The rows at a state (the Rust module's step_rows, one program over the same roots). */");
    let _ = writeln!(out, "static void step_rows(const State *s, Prepared *r) {{");
    if !lets.iter().chain(&stores).any(|t| t.contains("s->")) {
        let _ = writeln!(out, "    (void)s;");
    }
    for l in lets.iter().chain(&stores) {
        let _ = writeln!(out, "    {l}");
    }
    let _ = writeln!(out, "}}\n");
    let name_of = |sym: Symbol| p.fields.iter().position(|f| f.symbol == sym).map(|i| p.c_names[i].clone());
    let _ = writeln!(out, "static double state_time(const State *s) {{");
    match name_of(step.time) {
        Some(t) => {
            let _ = writeln!(out, "    return s->{t};\n}}\n");
        }
        None => {
            let _ = writeln!(out, "    (void)s;\n    return 0.0;\n}}\n");
        }
    }
    // The state's slots as the Rust module's `get` and `put` have them.
    let mut get = Vec::new();
    let mut put = Vec::new();
    for (i, &(q, v)) in step.bodies.iter().enumerate() {
        let (q, v) = (name_of(q).unwrap_or_default(), name_of(v).unwrap_or_default());
        for d in 0..dim {
            get.push(format!("q[{i}][{d}] = s->{q}[{d}];\n    v[{i}][{d}] = s->{v}[{d}];"));
            put.push(format!("s->{q}[{d}] = q[{i}][{d}];\n    s->{v}[{d}] = v[{i}][{d}];"));
        }
    }
    let mut r3 = 0;
    for (&(first, three), &(o, w)) in roots.turns.iter().zip(&step.turns) {
        let (o, w) = (name_of(o).unwrap_or_default(), name_of(w).unwrap_or_default());
        if three {
            for slot in first..first + 3 {
                for d in 0..3 {
                    get.push(format!("q[{slot}][{d}] = 0.0;"));
                    let value = if slot == first { format!("s->{w}[{d}]") } else { "0.0".to_string() };
                    get.push(format!("v[{slot}][{d}] = {value};"));
                }
            }
            for d in 0..4 {
                get.push(format!("q0[{r3}][{d}] = s->{o}[{d}];"));
            }
            put.push(format!("turned(q[{first}], q0[{r3}], s->{o});"));
            for d in 0..3 {
                put.push(format!("s->{w}[{d}] = v[{first}][{d}];"));
            }
            r3 += 1;
        } else {
            get.push(format!(
                "q[{first}][0] = s->{o};\n    q[{first}][1] = 0.0;\n    v[{first}][0] = s->{w};\n    v[{first}][1] = 0.0;"
            ));
            put.push(format!("s->{o} = q[{first}][0];\n    s->{w} = v[{first}][0];"));
        }
    }
    if rigid_3d == 0 {
        get.push("(void)q0;".to_string());
        put.push("(void)q0;".to_string());
    }
    let _ = writeln!(
        out,
        "/* The state's slots: per body x and v, per rigid body [theta, 0] and [omega, 0] (3D: the rotation vector\n   \
         phi = 0 since its orientation q0 and the world omega, then two empty slots), and the 3D bodies' q0. */\n\
         static void state_get(const State *s, double q[][DIM], double v[][DIM], double q0[][4]) {{\n    {}\n}}\n",
        get.join("\n    ")
    );
    let time = name_of(step.time).map_or("(void)t;".to_string(), |t| format!("s->{t} = t;"));
    let _ = writeln!(
        out,
        "/* Writes the time and the slots into the state (3D: the orientation exp(phi) (x) q0). */\n\
         static void state_put(State *s, double t, double q[][DIM], double v[][DIM], double q0[][4]) {{\n    {time}\n    {}\n}}\n",
        put.join("\n    ")
    );
    out.push_str(STEP_C);
    out.push('\n');
    out.push_str(if step.solver == Solver::Exact { EXACT_C } else { SWEEP_C });
    Ok(())
}

/// An expression as the operand of `*` or `/`: parenthesised unless it is a name, a
/// field, an index or an unsigned number.
pub(super) fn paren(e: &str) -> String {
    let simple = e.chars().all(|c| c.is_alphanumeric() || matches!(c, '_' | '.' | '[' | ']'))
        || (e.starts_with("s->") && !e.contains(' '));
    if simple { e.to_string() } else { format!("({e})") }
}

/// `a_matrix` (dense K×K, or the caller's array for a big unbanded A) or `a_band`.
fn a(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let k = p.layout.constraints;
    let (lets, exprs) = ctx.body(p.a_code)?;
    let mut stores = Vec::new();
    let doc = ["A of A lambda + b = 0: A[k][j] = sum_i J[k][i].J[j][i] / m_i.".to_string()];
    // Each entry's formula by its row and column (the first written, as a search would find).
    let mut written: FastMap<(usize, usize), usize> = FastMap::default();
    for (i, &(r, c, _)) in p.formulas.a.iter().enumerate() {
        written.entry((r, c)).or_insert(i);
    }
    match p.layout.a {
        AStorage::Band { bandwidth } => {
            let sparse = p.layout.sparse_band;
            if sparse {
                stores.push(zero_fill(k, bandwidth + 1));
            }
            for r in 0..k {
                for d in 0..=bandwidth {
                    match written.get(&(r, r + d)) {
                        Some(&i) => stores.push(format!("out[{r}][{d}] = {};", exprs[i])),
                        None if !sparse => stores.push(format!("out[{r}][{d}] = 0.0;")),
                        None => {}
                    }
                }
            }
            let _ = writeln!(
                out,
                "/* Half-bandwidth of A: A[k][j] = 0 when |k - j| > A_BANDWIDTH. */\nenum {{ A_BANDWIDTH = {bandwidth} }};\n"
            );
            let doc = [format!("A as its band: out[k][d] = A[k][k + d] for d <= {bandwidth}.")];
            function(out, &doc, "a_band", &format!("double out[{}][{}]", k.max(1), bandwidth + 1), &lets, &stores);
        }
        AStorage::Dense | AStorage::Heap => {
            let entry = |r: usize, c: usize| [written.get(&(r, c)), written.get(&(c, r))].into_iter().flatten().min();
            let nonzero = (0..k).flat_map(|r| (0..k).map(move |c| (r, c))).filter(|&(r, c)| entry(r, c).is_some());
            let sparse = layout::mostly_zero(k * k, nonzero.count());
            if sparse {
                stores.push(zero_fill(k, k));
            }
            for r in 0..k {
                for c in 0..k {
                    match entry(r, c) {
                        Some(&i) => stores.push(format!("out[{r}][{c}] = {};", exprs[i])),
                        None if !sparse => stores.push(format!("out[{r}][{c}] = 0.0;")),
                        None => {}
                    }
                }
            }
            function(out, &doc, "a_matrix", &format!("double out[{0}][{0}]", k.max(1)), &lets, &stores);
        }
    }
    Ok(())
}

/// `jacobian` (dense K × N·DIM) or `jacobian_blocks` (the non-zero blocks, with their
/// constraint and body in `JACOBIAN_ROW` and `JACOBIAN_BODY`).
fn jacobian(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let (dim, n, k) = (p.layout.dim, p.layout.bodies, p.layout.constraints);
    let blocks: Vec<(usize, usize, Id)> = p
        .formulas
        .jacobian
        .iter()
        .enumerate()
        .flat_map(|(r, dirs)| dirs.iter().map(move |&(b, id)| (r, b, id)))
        .collect();
    let roots: Vec<Id> = blocks.iter().map(|b| b.2).collect();
    let (lets, exprs) = ctx.body(&roots)?;
    let mut stores = Vec::new();
    match p.layout.j {
        JStorage::Blocks { count } => {
            let rows: Vec<String> = blocks.iter().map(|b| b.0.to_string()).collect();
            let bodies: Vec<String> = blocks.iter().map(|b| b.1.to_string()).collect();
            let _ = writeln!(out, "/* The constraint and the body of each block of `jacobian_blocks`. */");
            let _ = writeln!(out, "const int JACOBIAN_ROW[{}] = {{{}}};", count.max(1), list(&rows, count));
            let _ = writeln!(out, "const int JACOBIAN_BODY[{}] = {{{}}};\n", count.max(1), list(&bodies, count));
            for (i, _) in blocks.iter().enumerate() {
                for d in 0..dim {
                    stores.push(format!("out[{i}][{d}] = {};", exprs[i * dim + d]));
                }
            }
            let doc =
                ["J, sparse: block i is constraint JACOBIAN_ROW[i]'s direction on body JACOBIAN_BODY[i].".to_string()];
            function(out, &doc, "jacobian_blocks", &format!("double out[{}][{dim}]", count.max(1)), &lets, &stores);
        }
        JStorage::Dense => {
            let sparse = layout::mostly_zero(k * n * dim, blocks.len() * dim);
            if sparse {
                stores.push(zero_fill(k, n * dim));
            }
            for r in 0..k {
                for body in 0..n {
                    let at = blocks.iter().position(|b| b.0 == r && b.1 == body);
                    for d in 0..dim {
                        match at {
                            Some(i) => stores.push(format!("out[{r}][{}] = {};", body * dim + d, exprs[i * dim + d])),
                            None if !sparse => stores.push(format!("out[{r}][{}] = 0.0;", body * dim + d)),
                            None => {}
                        }
                    }
                }
            }
            let doc = [format!("J: row k is constraint k's direction, body i's components at columns i*{dim} ..")];
            function(out, &doc, "jacobian", &format!("double out[{}][{}]", k.max(1), (n * dim).max(1)), &lets, &stores);
        }
    }
    Ok(())
}

/// A function writing one scalar formula per entry of `out`.
fn scalars(
    ctx: &Ctx<'_>,
    out: &mut String,
    doc: &[String],
    name: &str,
    roots: &[Id],
    k: usize,
) -> Result<(), GenerateError> {
    let (lets, exprs) = ctx.body(roots)?;
    let stores: Vec<String> = exprs.iter().enumerate().map(|(i, e)| format!("out[{i}] = {e};")).collect();
    function(out, doc, name, &format!("double out[{}]", k.max(1)), &lets, &stores);
    Ok(())
}

/// The loop that sets every number of `out[rows][width]` to 0 (before a block's non-zero
/// entries are stored: [`layout::mostly_zero`]).
pub(super) fn zero_fill(rows: usize, width: usize) -> String {
    format!(
        "for (int r = 0; r < {rows}; r++) {{\n        for (int d = 0; d < {width}; d++) {{\n            \
         out[r][d] = 0.0;\n        }}\n    }}"
    )
}

/// `void name(const State *s, OUT) { lets; stores }`, its doc as a comment.
pub(super) fn function(out: &mut String, doc: &[String], name: &str, param: &str, lets: &[String], stores: &[String]) {
    let _ = writeln!(out, "/* {}", c_comment(&doc[0]));
    for line in &doc[1..] {
        let _ = writeln!(out, "   {}", c_comment(line));
    }
    let _ = writeln!(out, "*/\nvoid {name}(const State *s, {param}) {{");
    let uses_state = lets.iter().chain(stores).any(|t| t.contains("s->"));
    if !uses_state {
        let _ = writeln!(out, "    (void)s;");
    }
    if stores.is_empty() {
        let _ = writeln!(out, "    (void)out;");
    }
    for l in lets.iter().chain(stores) {
        let _ = writeln!(out, "    {l}");
    }
    let _ = writeln!(out, "}}\n");
}

/// An initialiser list of `k` entries (one `0` when there are none: C has no empty arrays).
pub(super) fn list(items: &[String], k: usize) -> String {
    if k == 0 { "0".into() } else { items.join(", ") }
}

/// Text safe inside a C `/* */` comment: one line (as [`comment_text`]), no `*/` or `/*`,
/// and no trigraph (`??`, which C99 reads before comments end).
pub(super) fn c_comment(s: &str) -> String {
    comment_text(s).replace("*/", "* /").replace("/*", "/ *").replace("??", "? ?")
}
