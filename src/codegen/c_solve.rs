//! The λ path of `generate --lang c`: the Rust module's `rows`, `solution` (with its change
//! of length unit where the raw numbers overflow), `lambda`, `forces`, `force_<body>`,
//! `accelerations` and, with rigid bodies, `torques`, `torque_<body>` and
//! `angular_accelerations`, each following the same `Lambda` of the layout (the guarded
//! closed form of one equality; for other equalities λ by L D Lᵀ on A's band, tridiagonal
//! or wider, and a small dense A's forces by L D Lᵀ; else the rows' solve) with the same
//! operations in the same order, so with `-ffp-contract=off` the Rust module's numbers bit
//! for bit. The shared text is `support/rows.c` (`solve_rows`, the Rust `solve_rows`
//! re-stated), `support/solve_tridiagonal.c`, `support/solve_band.c` and
//! `support/solve_dense.c`.
//!
//! Not here: the formulas' functions (`codegen::c`), layout decisions (`codegen::layout`),
//! the velocity-level step (`codegen::c`, `support/step.c`).

use super::c::{Parts, function, list, paren, zero_fill};
use super::layout::{JStorage, Lambda};
use super::names::comment_text;
use super::rust::{Ctx, GenerateError, formula, lambda_sum, per_body_fns};
use crate::expr::Id;
use std::fmt::Write;

/// The rows' solve in C (`support/rows.c`).
const ROWS_C: &str = include_str!("support/rows.c");
/// L D Lᵀ on a band in C (`support/solve_band.c`).
const SOLVE_BAND_C: &str = include_str!("support/solve_band.c");
/// L D Lᵀ of a tridiagonal A in C (`support/solve_tridiagonal.c`).
const SOLVE_TRIDIAGONAL_C: &str = include_str!("support/solve_tridiagonal.c");
/// L D Lᵀ in C (`support/solve_dense.c`).
const SOLVE_DENSE_C: &str = include_str!("support/solve_dense.c");

/// Everything of the λ path: the rows' structure, `rows`, the shared solve, `solution`
/// (and its change of unit for point masses), then λ, forces, torques and accelerations.
pub(super) fn emit(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let (n, k) = (p.layout.bodies, p.layout.constraints);
    let rigid = p.turns.body.len();
    let three = !p.turns.three.is_empty();
    // Row k's entries: its bodies' J in the derivation's order, then Jʷ on its rigid bodies
    // (slot BODIES + r), as the Rust module's `rows` pushes them.
    let angular = p.turns.entries(p.formulas);
    let mut starts = vec![0usize];
    let mut slots = Vec::new();
    for (row, dirs) in p.formulas.jacobian.iter().enumerate() {
        slots.extend(dirs.iter().map(|d| d.0));
        slots.extend(angular.iter().filter(|e| e.0 == row).map(|e| n + e.1));
        starts.push(slots.len());
    }
    let entries = slots.len();
    let _ = writeln!(
        out,
        "/* The rows' solve: slots are the bodies, then one angular slot per rigid body (component 0). */\n\
         enum {{ SLOTS = {}, ROW_ENTRIES = {entries} }};\n\
         /* Row k's entries of J are SOLVE_START[k] .. SOLVE_START[k + 1], on slots SOLVE_SLOT[e]. */\n\
         const int SOLVE_START[{}] = {{{}}};\n\
         const int SOLVE_SLOT[{}] = {{{}}};\n",
        n + rigid,
        k + 1,
        starts.iter().map(usize::to_string).collect::<Vec<_>>().join(", "),
        entries.max(1),
        list(&slots.iter().map(usize::to_string).collect::<Vec<_>>(), entries),
    );
    out.push_str(ROWS_C);
    out.push('\n');
    rows_fn(out, p, &angular, entries);
    if three {
        rigid_3d_solution(out);
    } else if rigid > 0 {
        rigid_solution(out);
    } else {
        scaling(out, p);
        point_solution(out);
    }
    let _ = writeln!(
        out,
        "/* The accelerations (F_i + sum_k lambda_k J_ki)/m_i of every body (in file order), from the rows' solve. */\n\
         void accelerations(const State *s, double out[{n1}][DIM]) {{\n    \
         Solution x;\n    solution(s, &x);\n    \
         for (int i = 0; i < BODIES; i++) {{\n        for (int d = 0; d < DIM; d++) {{\n            \
         out[i][d] = x.acceleration[i][d];\n        }}\n    }}\n}}\n",
        n1 = n.max(1)
    );
    if three {
        let _ = writeln!(
            out,
            "/* Sum_k e_k x_k: a vector given by its parts x on the axes e, in the world (the Rust module's world). */\n\
             static void world(const double e[3][3], const double x[3], double out[3]) {{\n    \
             for (int d = 0; d < 3; d++) {{\n        out[d] = 0.0;\n    }}\n    \
             for (int k = 0; k < 3; k++) {{\n        for (int d = 0; d < 3; d++) {{\n            \
             out[d] += x[k] * e[k][d];\n        }}\n    }}\n}}\n\n\
             /* The angular accelerations alpha (world frame) of every rigid body (RIGID_BODIES), from the rows' solve:\n   \
             sum_k e_k alpha_k over the principal axes e_k = R(q) e_k. */\n\
             void angular_accelerations(const State *s, double out[RIGID][3]) {{\n    \
             Solution x;\n    double e[RIGID][3][3];\n    solution(s, &x);\n    body_axes(s, e);\n    \
             for (int r = 0; r < RIGID; r++) {{\n        double a[3];\n        \
             for (int k = 0; k < 3; k++) {{\n            a[k] = x.acceleration[BODIES + 3 * r + k][0];\n        }}\n        \
             world(e[r], a, out[r]);\n    }}\n}}\n"
        );
    } else if rigid > 0 {
        let _ = writeln!(
            out,
            "/* The angular accelerations (tau + sum_k lambda_k Jw_k)/I of every rigid body (RIGID_BODIES), from the rows' solve. */\n\
             void angular_accelerations(const State *s, double out[RIGID]) {{\n    \
             Solution x;\n    solution(s, &x);\n    \
             for (int r = 0; r < RIGID; r++) {{\n        out[r] = x.acceleration[BODIES + r][0];\n    }}\n}}\n"
        );
    }
    let (force_fns, torque_fns) = per_body_fns(p.names, p.turns);
    match (p.layout.lambda, p.formulas.lambda, &p.formulas.forces) {
        (Lambda::ClosedForm, Some(lambda), Some(forces)) => {
            return closed_form(ctx, out, p, lambda, forces, (&force_fns, &torque_fns));
        }
        (Lambda::Band, _, _) => {
            band_lambda(ctx, out, p)?;
            band(out, p);
        }
        (Lambda::Dense, _, _) => {
            band_lambda(ctx, out, p)?;
            dense(ctx, out, p)?;
        }
        _ => {
            let _ = writeln!(
                out,
                "/* The multipliers lambda (for C/SCALE), as lagrange solve gives them: 0 on an inequality that is\n   \
                 apart, separating or would pull, and the minimum-norm lambda where A is singular (see solution). */\n\
                 void lambda(const State *s, double out[{k1}]) {{\n    \
                 Solution x;\n    solution(s, &x);\n    \
                 for (int k = 0; k < CONSTRAINTS; k++) {{\n        out[k] = x.lambda[k];\n    }}\n}}\n\n\
                 /* The constraint force sum_k lambda_k J_ki on every body (in file order), from the rows' solve. */\n\
                 void forces(const State *s, double out[{n1}][DIM]) {{\n    \
                 Solution x;\n    solution(s, &x);\n    \
                 for (int i = 0; i < BODIES; i++) {{\n        for (int d = 0; d < DIM; d++) {{\n            \
                 out[i][d] = x.force[i][d];\n        }}\n    }}\n}}\n",
                k1 = k.max(1),
                n1 = n.max(1)
            );
            if three {
                let _ = writeln!(
                    out,
                    "/* The constraint torque sum_k lambda_k Jw_k (world frame, about the centre of mass) on every rigid\n   \
                     body (RIGID_BODIES), from the rows' solve: sum_k e_k (its axis slots' parts). */\n\
                     void torques(const State *s, double out[RIGID][3]) {{\n    \
                     Solution x;\n    double e[RIGID][3][3];\n    solution(s, &x);\n    body_axes(s, e);\n    \
                     for (int r = 0; r < RIGID; r++) {{\n        double t[3];\n        \
                     for (int k = 0; k < 3; k++) {{\n            t[k] = x.force[BODIES + 3 * r + k][0];\n        }}\n        \
                     world(e[r], t, out[r]);\n    }}\n}}\n"
                );
            } else if rigid > 0 {
                let _ = writeln!(
                    out,
                    "/* The constraint torque sum_k lambda_k Jw_k on every rigid body (RIGID_BODIES), from the rows' solve. */\n\
                     void torques(const State *s, double out[RIGID]) {{\n    \
                     Solution x;\n    solution(s, &x);\n    \
                     for (int r = 0; r < RIGID; r++) {{\n        out[r] = x.force[BODIES + r][0];\n    }}\n}}\n"
                );
            }
        }
    }
    let rigid_bodies = p.turns.rigid_bodies();
    for (slot, name) in torque_fns.iter().enumerate() {
        if three {
            let _ = writeln!(
                out,
                "/* The constraint torque on rigid body `{}` (world frame, about its centre of mass). */\n\
                 void {name}(const State *s, double out[3]) {{\n    double t[RIGID][3];\n    torques(s, t);\n    \
                 for (int d = 0; d < 3; d++) {{\n        out[d] = t[{slot}][d];\n    }}\n}}\n",
                super::c::c_comment(p.names.bodies[rigid_bodies[slot]])
            );
            continue;
        }
        let _ = writeln!(
            out,
            "/* The constraint torque on rigid body `{}` (about its centre of mass). */\n\
             double {name}(const State *s) {{\n    double t[RIGID];\n    torques(s, t);\n    return t[{slot}];\n}}\n",
            super::c::c_comment(p.names.bodies[rigid_bodies[slot]])
        );
    }
    for (body, name) in force_fns.iter().enumerate() {
        let _ = writeln!(
            out,
            "/* The constraint force on body `{}`. */\n\
             void {name}(const State *s, double out[DIM]) {{\n    double f[{}][DIM];\n    forces(s, f);\n    \
             for (int d = 0; d < DIM; d++) {{\n        out[d] = f[{body}][d];\n    }}\n}}\n",
            super::c::c_comment(p.names.bodies[body]),
            n.max(1)
        );
    }
    Ok(())
}

/// `rows`: C/κ, Ċ/κ, c, the inequality flag and J per entry (then Jʷ in component 0 of its
/// angular slot), from the module's own functions, as the Rust module's `rows`.
fn rows_fn(out: &mut String, p: &Parts<'_>, angular: &[(usize, usize, Id)], entries: usize) {
    let (dim, n, k) = (p.layout.dim, p.layout.bodies, p.layout.constraints);
    let k1 = k.max(1);
    let mut body = vec![
        format!("double c[{k1}], rate[{k1}], bias[{k1}];"),
        "constraints(s, c);".to_string(),
        "constraint_rates(s, rate);".to_string(),
        "c_term(s, bias);".to_string(),
    ];
    let blocks = matches!(p.layout.j, JStorage::Blocks { .. });
    let block_count: usize = p.formulas.jacobian.iter().map(Vec::len).sum();
    if entries > 0 {
        if blocks {
            body.push(format!("double j[{}][DIM];", block_count.max(1)));
            body.push("jacobian_blocks(s, j);".into());
        } else {
            body.push(format!("double j[{k1}][{}];", (n * dim).max(1)));
            body.push("jacobian(s, j);".into());
        }
        if !angular.is_empty() {
            if blocks {
                body.push(format!("double jw[{}];", angular.len()));
                body.push("angular_jacobian_blocks(s, jw);".into());
            } else {
                let width = if p.turns.three.is_empty() { "RIGID" } else { "ANGULAR_SLOTS" };
                body.push(format!("double jw[{k1}][{width}];"));
                body.push("angular_jacobian(s, jw);".into());
            }
        }
    }
    body.push(
        "for (int k = 0; k < CONSTRAINTS; k++) {\n        r->value[k] = c[k] / SCALE[k];\n        \
         r->rate[k] = rate[k] / SCALE[k];\n        r->bias[k] = bias[k];\n        r->inequality[k] = INEQUALITY[k];\n    }"
            .into(),
    );
    let (mut e, mut block) = (0, 0);
    for (row, dirs) in p.formulas.jacobian.iter().enumerate() {
        for &(b, _) in dirs {
            for d in 0..dim {
                let from = if blocks { format!("j[{block}][{d}]") } else { format!("j[{row}][{}]", b * dim + d) };
                body.push(format!("r->jacobian[{e}][{d}] = {from};"));
            }
            e += 1;
            block += 1;
        }
        for (at, entry) in angular.iter().enumerate().filter(|(_, x)| x.0 == row) {
            let from = if blocks { format!("jw[{at}]") } else { format!("jw[{row}][{}]", entry.1) };
            body.push(format!("r->jacobian[{e}][0] = {from};"));
            for d in 1..dim {
                body.push(format!("r->jacobian[{e}][{d}] = 0.0;"));
            }
            e += 1;
        }
    }
    let _ = writeln!(
        out,
        "/* The constraint rows at a state, as lagrange solve reads them: C/SCALE, its rate, c and J = grad C/SCALE\n   \
         per entry (a rigid body's Jw in component 0 of its slot). */\nvoid rows(const State *s, Rows *r) {{"
    );
    for line in body {
        let _ = writeln!(out, "    {line}");
    }
    let _ = writeln!(out, "}}\n");
}

/// `scaled_state` and `length_like` over the state's length-like places, as the Rust
/// module's.
fn scaling(out: &mut String, p: &Parts<'_>) {
    let mut scaled = Vec::new();
    let mut like = Vec::new();
    for place in &p.length_places {
        match place.array {
            Some(name) => {
                scaled.push(format!(
                    "for (size_t i = 0; i < sizeof x->{name} / sizeof x->{name}[0]; i++) {{\n        \
                     for (int d = 0; d < DIM; d++) {{\n            x->{name}[i][d] = pow2(x->{name}[i][d], e);\n        }}\n    }}"
                ));
                like.push(format!(
                    "for (size_t i = 0; i < sizeof s->{name} / sizeof s->{name}[0]; i++) {{\n        \
                     for (int d = 0; d < DIM; d++) {{\n            big = lg_max(big, fabs(s->{name}[i][d]));\n        }}\n    }}"
                ));
            }
            None => {
                let name = &p.c_names[place.field];
                if place.vector {
                    scaled.push(format!(
                        "for (int d = 0; d < DIM; d++) {{\n        x->{name}[d] = pow2(x->{name}[d], e);\n    }}"
                    ));
                    like.push(format!(
                        "for (int d = 0; d < DIM; d++) {{\n        big = lg_max(big, fabs(s->{name}[d]));\n    }}"
                    ));
                } else {
                    scaled.push(format!("x->{name} = pow2(x->{name}, e);"));
                    like.push(format!("big = lg_max(big, fabs(s->{name}));"));
                }
            }
        }
    }
    if scaled.is_empty() {
        scaled.push("(void)e;".into());
        like.push("(void)s;".into());
    }
    let _ = writeln!(
        out,
        "/* The state with its length-like fields (positions, velocities, forces, parameters no mass depends on) x 2^e. */\n\
         void scaled_state(const State *s, long long e, State *x) {{\n    *x = *s;\n    {}\n}}\n\n\
         /* The largest |x| of the state's length-like numbers. */\n\
         double length_like(const State *s) {{\n    double big = 0.0;\n    {}\n    return big;\n}}\n",
        scaled.join("\n    "),
        like.join("\n    ")
    );
}

/// `solution` of point masses: the raw solve, and where the raw numbers overflow the solve
/// in a length unit 2ᵏ verified homogeneous, scaled back (the Rust module's `solution`).
fn point_solution(out: &mut String) {
    out.push_str(
        "/* lambda, the constraint forces and the accelerations at a state, with each inequality's contact state and
   the status: what lagrange solve gives (see solve_rows). Where the numbers overflow, it solves in a length
   unit 2^k that brings the largest length-like number near 1, verified homogeneous, and scales back. */
void solution(const State *s, Solution *x) {
    Rows r, r_half;
    double w[SLOTS], v[SLOTS][DIM], f[SLOTS][DIM], q[SLOTS][DIM], big;
    long long k, p[CONSTRAINTS > 0 ? CONSTRAINTS : 1];
    State at, half;
    rows(s, &r);
    inverse_masses(s, w);
    velocities(s, v);
    external_forces(s, f);
    positions(s, q);
    solve_rows(&r, w, v, f, length_scale(q, BODIES), x);
    big = length_like(s);
    if (rows_finite(&r, w, v, f) || !(big > 0.0 && isfinite(big))) {
        return;
    }
    k = (long long)floor(log2(big));
    scaled_state(s, -k, &at);
    scaled_state(s, -k - 1, &half);
    rows(&at, &r);
    inverse_masses(&at, w);
    velocities(&at, v);
    external_forces(&at, f);
    rows(&half, &r_half);
    if (!rows_finite(&r, w, v, f) || !rows_finite(&r_half, w, v, f)) {
        return;
    }
    if (!degrees(&r, &r_half, p)) {
        return;
    }
    positions(&at, q);
    solve_rows(&r, w, v, f, length_scale(q, BODIES), x);
    for (int i = 0; i < SLOTS; i++) {
        for (int d = 0; d < DIM; d++) {
            x->force[i][d] = pow2(x->force[i][d], k);
            x->acceleration[i][d] = pow2(x->acceleration[i][d], k);
        }
    }
    for (int c = 0; c < CONSTRAINTS; c++) {
        x->lambda[c] = pow2(x->lambda[c], -k * (p[c] - 2));
    }
}

",
    );
}

/// `solution` with rigid bodies: the solve over the slots (bodies, then each rigid body's
/// 1/I, ω, τ in component 0), in the file's length unit.
fn rigid_solution(out: &mut String) {
    out.push_str(
        "/* lambda, the constraint forces and torques and the accelerations at a state, with each inequality's contact
   state and the status: what lagrange solve gives (see solve_rows). The solve runs over slots: the bodies
   (1/m, v, F), then one angular slot per rigid body (1/I, omega, tau in component 0), so force and
   acceleration hold the constraint torque and alpha of rigid body r at BODIES + r, component 0. Rigid
   bodies are solved in the file's length unit (an angle does not scale with it). */
void solution(const State *s, Solution *x) {
    Rows r;
    double w[SLOTS], v[SLOTS][DIM], f[SLOTS][DIM], q[BODIES][DIM], omega[RIGID], tau[RIGID];
    rows(s, &r);
    inverse_masses(s, w);
    inverse_inertias(s, w + BODIES);
    velocities(s, v);
    angular_velocities(s, omega);
    external_forces(s, f);
    external_torques(s, tau);
    for (int i = 0; i < RIGID; i++) {
        for (int d = 0; d < DIM; d++) {
            v[BODIES + i][d] = 0.0;
            f[BODIES + i][d] = 0.0;
        }
        v[BODIES + i][0] = omega[i];
        f[BODIES + i][0] = tau[i];
    }
    positions(s, q);
    solve_rows(&r, w, v, f, length_scale(q, BODIES), x);
}

",
    );
}

/// `solution` with 3D rigid bodies: the solve over the slots (bodies, then each rigid body's
/// three axis slots: 1/Iₖ, eₖ·ω, eₖ·τ − (ω_b × I ω_b)ₖ in component 0), in the file's length
/// unit, as the Rust module's.
fn rigid_3d_solution(out: &mut String) {
    out.push_str(
        "/* lambda, the constraint forces and torques and the accelerations at a state, with each inequality's contact
   state and the status: what lagrange solve gives (see solve_rows). The solve runs over slots: the bodies
   (1/m, v, F), then three per rigid body r, one per principal axis e_k = R(q) e_k at BODIES + 3r + k (1/I_k,
   e_k.omega and e_k.tau - (omega_b x I omega_b)_k in component 0), so M stays diagonal; force and acceleration
   there hold the axis' part of the constraint torque and of alpha (torques and angular_accelerations turn
   them back into the world). Rigid bodies are solved in the file's length unit. */
void solution(const State *s, Solution *x) {
    Rows r;
    double w[SLOTS], v[SLOTS][DIM], f[SLOTS][DIM], q[BODIES][DIM], omega[ANGULAR_SLOTS], tau[ANGULAR_SLOTS];
    rows(s, &r);
    inverse_masses(s, w);
    axis_inverse_inertias(s, w + BODIES);
    velocities(s, v);
    axis_angular_velocities(s, omega);
    external_forces(s, f);
    axis_torques(s, tau);
    for (int i = 0; i < ANGULAR_SLOTS; i++) {
        for (int d = 0; d < DIM; d++) {
            v[BODIES + i][d] = 0.0;
            f[BODIES + i][d] = 0.0;
        }
        v[BODIES + i][0] = omega[i];
        f[BODIES + i][0] = tau[i];
    }
    positions(s, q);
    solve_rows(&r, w, v, f, length_scale(q, BODIES), x);
}

",
    );
}

/// One equality: λ, the forces and torques in closed form, each guarded (A normal, b finite,
/// the value finite), `solution` where they are not.
fn closed_form(
    ctx: &Ctx<'_>,
    out: &mut String,
    p: &Parts<'_>,
    lambda: Id,
    forces: &[(usize, Id)],
    (force_fns, torque_fns): (&[String], &[String]),
) -> Result<(), GenerateError> {
    let (g, dim, n) = (ctx.g, p.layout.dim, p.layout.bodies);
    out.push_str(
        "/* Whether the closed forms' numbers are in range here (A normal, b finite); where they are not
   (|r| ~ 1e155 overflows r.r), lambda and the forces come from the scaled solution. */
static int closed_form_holds(const State *s) {
    double a[1][1], b[1];
    a_matrix(s, a);
    b_vector(s, b);
    return isnormal(a[0][0]) && isfinite(b[0]);
}

",
    );
    let (lets, exprs) = ctx.body(&[lambda])?;
    let mut stores = lets;
    stores.push(format!("const double x = {};", exprs[0]));
    stores.push(
        "if (closed_form_holds(s) && isfinite(x)) {\n        out[0] = x;\n        return;\n    }\n    \
         Solution y;\n    solution(s, &y);\n    out[0] = y.lambda[0];"
            .into(),
    );
    let doc = vec![
        "The multiplier lambda, in closed form (the scaled solution where its numbers leave f64's range):".to_string(),
        format!("lambda = {}", formula(g, lambda)),
    ];
    function(out, &doc, "lambda", "double out[1]", &[], &stores);
    for (body, name) in force_fns.iter().enumerate() {
        let mut doc = vec![format!("The constraint force on body `{}`:", comment_text(p.names.bodies[body]))];
        let mut stores = Vec::new();
        match forces.iter().find(|f| f.0 == body).map(|f| f.1) {
            Some(id) => {
                doc.push(formula(g, id));
                let (lets, exprs) = ctx.body(&[id])?;
                stores = lets;
                stores.push(format!("const double f[DIM] = {{{}}};", exprs.join(", ")));
                stores.push(format!(
                    "int finite = 1;\n    for (int d = 0; d < DIM; d++) {{\n        finite = finite && isfinite(f[d]);\n    }}\n    \
                     if (closed_form_holds(s) && finite) {{\n        for (int d = 0; d < DIM; d++) {{\n            out[d] = f[d];\n        }}\n        \
                     return;\n    }}\n    Solution y;\n    solution(s, &y);\n    \
                     for (int d = 0; d < DIM; d++) {{\n        out[d] = y.force[{body}][d];\n    }}"
                ));
            }
            None => {
                doc.push("zero: no constraint involves this body.".into());
                stores.extend((0..dim).map(|d| format!("out[{d}] = 0.0;")));
            }
        }
        function(out, &doc, name, "double out[DIM]", &[], &stores);
    }
    let calls: Vec<String> = force_fns.iter().enumerate().map(|(i, f)| format!("{f}(s, out[{i}]);")).collect();
    function(
        out,
        &["The constraint force on every body (in file order).".to_string()],
        "forces",
        &format!("double out[{}][DIM]", n.max(1)),
        &[],
        &calls,
    );
    if !p.turns.body.is_empty() {
        let torques = p.formulas.torques.as_deref().unwrap_or(&[]);
        for (slot, name) in torque_fns.iter().enumerate() {
            let body = p.turns.body[slot];
            let mut doc = vec![format!(
                "The constraint torque lambda Jw on rigid body `{}` (about its centre of mass):",
                comment_text(p.names.bodies[body])
            )];
            let mut lines = Vec::new();
            match torques.iter().find(|t| t.0 == body).map(|t| t.1) {
                Some(id) => {
                    doc.push(formula(g, id));
                    let (lets, exprs) = ctx.body(&[id])?;
                    lines = lets;
                    lines.push(format!("const double x = {};", exprs[0]));
                    lines.push(format!(
                        "if (closed_form_holds(s) && isfinite(x)) {{\n        return x;\n    }}\n    \
                         Solution y;\n    solution(s, &y);\n    return y.force[BODIES + {slot}][0];"
                    ));
                }
                None => {
                    doc.push("zero: the constraint does not turn this body.".into());
                    lines.push("(void)s;\n    return 0.0;".into());
                }
            }
            let _ = writeln!(out, "/* {}", super::c::c_comment(&doc[0]));
            for line in &doc[1..] {
                let _ = writeln!(out, "   {}", super::c::c_comment(line));
            }
            let _ = writeln!(out, "*/\ndouble {name}(const State *s) {{");
            for l in &lines {
                let _ = writeln!(out, "    {l}");
            }
            let _ = writeln!(out, "}}\n");
        }
        let calls: Vec<String> = torque_fns.iter().enumerate().map(|(i, f)| format!("out[{i}] = {f}(s);")).collect();
        function(
            out,
            &["The constraint torque on every rigid body (RIGID_BODIES).".to_string()],
            "torques",
            "double out[RIGID]",
            &[],
            &calls,
        );
    }
    Ok(())
}

/// The Rust module's `band_system`, `band_lambda` and `lambda` of a system of equalities
/// (`Lambda::Band` and `Lambda::Dense`): A's band of the layout's bandwidth and −b as rows,
/// one program of A and b as assembled, and L D Lᵀ written for that band
/// (`solve_tridiagonal` when it is 1, else `solve_band`); `solution` where it gives up.
fn band_lambda(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let (k, w) = (p.layout.constraints, p.layout.bandwidth);
    let mut roots: Vec<Id> = Vec::new();
    let mut at: Vec<Vec<Option<usize>>> = vec![vec![None; w + 1]; k];
    for (&(r, c, _), &id) in p.formulas.a.iter().zip(p.a_code) {
        let (r, c) = (r.min(c), r.max(c));
        at[r][c - r] = Some(roots.len());
        roots.push(id);
    }
    let b_at = roots.len();
    roots.extend(p.b_code);
    let (lets, exprs) = ctx.body(&roots)?;
    // The band's zeros (past the last column, and a grid's many) stored one by one, or one
    // loop of them before the non-zero entries where the band is mostly zeros.
    let sparse = p.layout.sparse_band;
    let mut stores = Vec::new();
    if sparse {
        stores.push(zero_fill(k, w + 1));
    }
    for (r, row) in at.iter().enumerate() {
        for (d, e) in row.iter().enumerate() {
            match e {
                Some(i) => stores.push(format!("out[{r}][{d}] = {};", exprs[*i])),
                None if !sparse => stores.push(format!("out[{r}][{d}] = 0.0;")),
                None => {}
            }
        }
        stores.push(format!("out[{r}][{}] = -{};", w + 1, paren(&exprs[b_at + r])));
    }
    let (solver, solve, how) = if w == 1 {
        (SOLVE_TRIDIAGONAL_C, "solve_tridiagonal(a, out)", "tridiagonal (solve_tridiagonal, O(K))")
    } else {
        (SOLVE_BAND_C, "solve_band(a, out)", "on A's band (solve_band, O(K w^2))")
    };
    let _ = writeln!(
        out,
        "/* Half-bandwidth of A as the lambda solve reads it: A[k][j] = 0 when |k - j| > LAMBDA_BANDWIDTH. */\n\
         enum {{ LAMBDA_BANDWIDTH = {w} }};\n"
    );
    out.push_str(solver);
    out.push('\n');
    let doc = [
        "A lambda = -b as band_lambda solves it: out[k][d] = A[k][k + d] for d <= LAMBDA_BANDWIDTH (zeros past the"
            .to_string(),
        "last column), out[k][LAMBDA_BANDWIDTH + 1] = -b[k]; one program of A and b as assembled.".to_string(),
    ];
    function(out, &doc, "band_system", &format!("double out[{k}][LAMBDA_BANDWIDTH + 2]"), &lets, &stores);
    let _ = writeln!(
        out,
        "/* The multipliers lambda (for C/SCALE) by L D L^T of band_system, {how}; 0 where A is singular
   (a pivot at or below 1e-10 of its diagonal entry: redundant constraints) or its numbers leave f64's range. */
int band_lambda(const State *s, double out[{k}]) {{
    double a[{k}][LAMBDA_BANDWIDTH + 2];
    band_system(s, a);
    return {solve};
}}

/* The multipliers lambda (for C/SCALE): band_lambda, else the rows' solve (solution: the minimum-norm lambda
   where A is singular, the change of length unit where its numbers overflow). */
void lambda(const State *s, double out[{k}]) {{
    if (!band_lambda(s, out)) {{
        Solution x;
        solution(s, &x);
        for (int i = 0; i < CONSTRAINTS; i++) {{
            out[i] = x.lambda[i];
        }}
    }}
}}
"
    );
    Ok(())
}

/// A banded system of equalities: the forces and torques Σₖ λₖ Jₖᵢ, Σₖ λₖ Jʷₖ of `lambda`
/// over every entry as the Rust module sums them.
fn band(out: &mut String, p: &Parts<'_>) {
    let (dim, n, k) = (p.layout.dim, p.layout.bodies, p.layout.constraints);
    let each = match p.layout.j {
        JStorage::Blocks { count } => format!(
            "double j[{}][DIM];\n    jacobian_blocks(s, j);\n    \
             for (int b = 0; b < {count}; b++) {{\n        for (int d = 0; d < DIM; d++) {{\n            \
             out[JACOBIAN_BODY[b]][d] += l[JACOBIAN_ROW[b]] * j[b][d];\n        }}\n    }}",
            count.max(1)
        ),
        JStorage::Dense => format!(
            "double j[{k}][{}];\n    jacobian(s, j);\n    \
             for (int c = 0; c < CONSTRAINTS; c++) {{\n        for (int i = 0; i < BODIES; i++) {{\n            \
             for (int d = 0; d < DIM; d++) {{\n                out[i][d] += l[c] * j[c][i * DIM + d];\n            }}\n        }}\n    }}",
            (n * dim).max(1)
        ),
    };
    let _ = writeln!(
        out,
        "/* The constraint force on every body (in file order): sum_k lambda_k J_ki. */
void forces(const State *s, double out[{}][DIM]) {{
    double l[{k}];
    lambda(s, l);
    for (int i = 0; i < BODIES; i++) {{
        for (int d = 0; d < DIM; d++) {{
            out[i][d] = 0.0;
        }}
    }}
    {each}
}}
",
        n.max(1)
    );
    if !p.turns.body.is_empty() {
        let each = match p.layout.j {
            JStorage::Blocks { .. } => {
                let count = p.turns.entries(p.formulas).len();
                format!(
                    "double jw[{}];\n    angular_jacobian_blocks(s, jw);\n    \
                     for (int e = 0; e < {count}; e++) {{\n        out[ANGULAR_SLOT[e]] += l[ANGULAR_ROW[e]] * jw[e];\n    }}",
                    count.max(1)
                )
            }
            JStorage::Dense => format!(
                "double jw[{k}][RIGID];\n    angular_jacobian(s, jw);\n    \
                 for (int c = 0; c < CONSTRAINTS; c++) {{\n        for (int r = 0; r < RIGID; r++) {{\n            \
                 out[r] += l[c] * jw[c][r];\n        }}\n    }}"
            ),
        };
        let _ = writeln!(
            out,
            "/* The constraint torque on every rigid body (RIGID_BODIES): sum_k lambda_k Jw_k. */
void torques(const State *s, double out[RIGID]) {{
    double l[{k}];
    lambda(s, l);
    for (int r = 0; r < RIGID; r++) {{
        out[r] = 0.0;
    }}
    {each}
}}
"
        );
    }
}

/// A small system of equalities: `dense_solution` (one program of A and b as assembled, J
/// and Jʷ; L D Lᵀ), `forces` (and `torques`) with `solution` where it gives up.
fn dense(ctx: &Ctx<'_>, out: &mut String, p: &Parts<'_>) -> Result<(), GenerateError> {
    let (dim, k, rigid) = (p.layout.dim, p.layout.constraints, p.turns.body.len());
    let n1 = p.layout.bodies.max(1);
    let f = p.formulas;
    let blocks: Vec<(usize, usize, Id)> =
        f.jacobian.iter().enumerate().flat_map(|(r, dirs)| dirs.iter().map(move |&(b, id)| (r, b, id))).collect();
    let angular = p.turns.entries(f);
    let mut roots: Vec<Id> = p.a_code.to_vec();
    roots.extend(p.b_code);
    roots.extend(blocks.iter().map(|b| b.2));
    roots.extend(angular.iter().map(|e| e.2));
    let (lets, exprs) = ctx.body(&roots)?;
    out.push_str(SOLVE_DENSE_C);
    out.push('\n');
    let mut next = exprs.into_iter();
    let mut lines = lets;
    lines.push(format!("double a[{k}][{k}];"));
    lines.push(format!(
        "for (int i = 0; i < {k}; i++) {{\n        for (int j = 0; j < {k}; j++) {{\n            a[i][j] = 0.0;\n        }}\n    }}"
    ));
    for &(r, c, _) in &f.a {
        lines.push(format!("a[{r}][{c}] = {};", next.next().unwrap_or_default()));
        if r != c {
            lines.push(format!("a[{c}][{r}] = a[{r}][{c}];"));
        }
    }
    for i in 0..k {
        lines.push(format!("l[{i}] = -{};", paren(&next.next().unwrap_or_default())));
    }
    lines.push("if (!solve_dense(a, l)) {\n        return 0;\n    }".into());
    lines.push(format!(
        "for (int i = 0; i < {n1}; i++) {{\n        for (int d = 0; d < DIM; d++) {{\n            f[i][d] = 0.0;\n        }}\n    }}"
    ));
    // Each force and torque entry as one sum over its rows, the constant 0 entries left out.
    let mut force: Vec<Vec<(usize, String)>> = vec![Vec::new(); p.layout.bodies * dim];
    for &(r, body, _) in &blocks {
        for d in 0..dim {
            force[body * dim + d].push((r, next.next().unwrap_or_default()));
        }
    }
    for (i, terms) in force.into_iter().enumerate() {
        if let Some(sum) = lambda_sum(terms, paren) {
            lines.push(format!("f[{}][{}] = {sum};", i / dim, i % dim));
        }
    }
    if rigid > 0 {
        lines.push("for (int r = 0; r < RIGID; r++) {\n        t[r] = 0.0;\n    }".into());
        let mut torque: Vec<Vec<(usize, String)>> = vec![Vec::new(); rigid];
        for &(r, slot, _) in &angular {
            torque[slot].push((r, next.next().unwrap_or_default()));
        }
        for (slot, terms) in torque.into_iter().enumerate() {
            if let Some(sum) = lambda_sum(terms, paren) {
                lines.push(format!("t[{slot}] = {sum};"));
            }
        }
    }
    lines.push("return 1;".into());
    let torque_param = if rigid > 0 { ", double t[RIGID]" } else { "" };
    let _ = writeln!(
        out,
        "/* lambda and the constraint forces sum_k lambda_k J_ki{} of these equalities, from one program of A and b\n   \
         (as assembled) and J, and A lambda = -b by L D L^T (solve_dense); 0 where A is singular (redundant\n   \
         constraints) or its numbers leave f64's range: there solution (the rows' solve) answers. */\n\
         int dense_solution(const State *s, double l[{k}], double f[{n1}][DIM]{torque_param}) {{",
        if rigid > 0 { " and torques sum_k lambda_k Jw_k" } else { "" }
    );
    if !lines.iter().any(|l| l.contains("s->")) {
        let _ = writeln!(out, "    (void)s;");
    }
    for l in &lines {
        let _ = writeln!(out, "    {l}");
    }
    let _ = writeln!(out, "}}\n");
    let (t_decl, t_arg) = if rigid > 0 { ("    double t[RIGID];\n", ", t") } else { ("", "") };
    let _ = writeln!(
        out,
        "/* The constraint force sum_k lambda_k J_ki on every body (in file order): dense_solution, else solution. */
void forces(const State *s, double out[{n1}][DIM]) {{
    double l[{k}];
{t_decl}    if (!dense_solution(s, l, out{t_arg})) {{
        Solution x;
        solution(s, &x);
        for (int i = 0; i < BODIES; i++) {{
            for (int d = 0; d < DIM; d++) {{
                out[i][d] = x.force[i][d];
            }}
        }}
    }}
}}
"
    );
    if rigid > 0 {
        let _ = writeln!(
            out,
            "/* The constraint torque sum_k lambda_k Jw_k on every rigid body (RIGID_BODIES): dense_solution, else solution. */
void torques(const State *s, double out[RIGID]) {{
    double l[{k}], f[{n1}][DIM];
    if (!dense_solution(s, l, f, out)) {{
        Solution x;
        solution(s, &x);
        for (int r = 0; r < RIGID; r++) {{
            out[r] = x.force[BODIES + r][0];
        }}
    }}
}}
"
        );
    }
    Ok(())
}
