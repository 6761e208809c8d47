//! The seed article (`bead-on-a-wire.md`), reproduced by machine in 2D and 3D.
//!
//! The article's results — Ċ = 2 r·v, C̈ = 2 v·v + 2 r·a, λ = −(m v·v + F·r)/(r·r) along r —
//! are written here as text in the expression language and compared with what `derive`
//! finds, as formulas (`Simplifier::equivalent`), as printed text, and through the JSON
//! of the command line, whose every expression must parse again and whose numbers must
//! satisfy the derivation's identities at random states.

mod common;

use common::{Rng, close, close_vec, random_env, scalar, vector};
use lagrange::derive::{Derivation, derive};
use lagrange::expr::eval::Value;
use lagrange::expr::print::{Style, print};
use lagrange::expr::{Id, Rational, Role, Symbol, Ty};
use lagrange::model::file::load;
use lagrange::model::system::System;
use std::process::Command;

/// The bead file of each dimension, as shipped in `constraints/`.
fn bead_file(dim: usize) -> &'static str {
    match dim {
        2 => "constraints/bead_on_wire.toml",
        _ => "constraints/bead_on_sphere.toml",
    }
}

fn loaded(path: &str) -> System {
    let text = std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).expect("file");
    load(&text).unwrap_or_else(|p| panic!("{path}: {p:?}")).system
}

/// Asserts that `id` (of `d`) and the article's `text` are the same formula.
fn assert_equivalent(system: &System, d: &mut Derivation, id: Id, text: &str, what: &str) {
    let expected = d.expression(system, text).unwrap_or_else(|e| panic!("{text}: {e}"));
    let same = d.simplifier.equivalent(&mut d.graph, id, expected).expect("well typed");
    let got = print(&d.graph, id, Style::Source).unwrap_or_default();
    assert!(same, "{what}: lagrange derived `{got}`, the article has `{text}`");
}

fn derived(system: &System) -> Derivation {
    derive(system).expect("the bead derives")
}

#[test]
fn bead_in_2d_and_3d_gives_the_articles_formulas() {
    for dim in [2, 3] {
        for system in [common::bead(dim as i64), loaded(bead_file(dim))] {
            let mut d = derived(&system);
            let system = &system;
            let dc = d.constraints[0].clone();
            assert_equivalent(system, &mut d, dc.c, "dot(r,r) - l^2", "C");
            assert_equivalent(system, &mut d, dc.c_dot, "2*dot(r,v)", "Ċ");
            assert_equivalent(system, &mut d, dc.c_dot_raw, "2*dot(r,v)", "Ċ before collecting");
            assert_equivalent(system, &mut d, dc.c_ddot, "2*dot(v,v) + 2*dot(r,a)", "C̈");
            assert_equivalent(system, &mut d, dc.gradient[0].1, "2*r", "∇C");
            // The direction is ∇C over its constant content: r, not 2r.
            assert_eq!(dc.scale, Rational::int(2), "κ");
            assert_equivalent(system, &mut d, dc.jacobian[0].1, "r", "J");
            assert_equivalent(system, &mut d, dc.bias, "dot(v,v)", "c");
            let (a, b) = (d.a[0].2, d.b[0]);
            assert_equivalent(system, &mut d, a, "dot(r,r)/m", "A");
            assert_equivalent(system, &mut d, b, "dot(v,v) + dot(F,r)/m", "b");
            let lambda = d.lambda.expect("one constraint: λ in closed form");
            assert_equivalent(system, &mut d, lambda, "-(m*dot(v,v) + dot(F,r))/dot(r,r)", "λ");
            let forces = d.forces.clone().expect("one constraint: forces in closed form");
            assert_eq!(forces.len(), 1);
            assert_equivalent(system, &mut d, forces[0].1, "-(m*dot(v,v) + dot(F,r))/dot(r,r) * r", "force");
            // A wrong formula is not accepted: the check can fail.
            let wrong = d.expression(system, "-(m*dot(v,v) - dot(F,r))/dot(r,r) * r").expect("parses");
            assert!(!d.simplifier.equivalent(&mut d.graph, forces[0].1, wrong).expect("typed"));
        }
    }
}

#[test]
fn bead_prints_as_the_article_writes_it() {
    for dim in [2, 3] {
        let system = common::bead(dim);
        let d = derived(&system);
        let g = &d.graph;
        let text = |id| print(g, id, Style::Text).expect("prints");
        let dc = &d.constraints[0];
        assert_eq!(text(dc.c_dot), "2 r·v");
        assert_eq!(text(dc.jacobian[0].1), "r");
        assert_eq!(text(d.lambda.expect("λ")), "−(m v·v + F·r)/(r·r)");
        assert_eq!(text(d.forces.as_ref().expect("forces")[0].1), "−(m v·v + F·r)/(r·r) r");
        let latex = print(g, d.lambda.expect("λ"), Style::Latex).expect("prints");
        assert!(latex.contains("\\frac") && latex.contains("\\vec{r} \\cdot \\vec{r}"), "{latex}");
    }
}

#[test]
fn the_force_does_not_depend_on_how_c_is_scaled() {
    // 3 (r·r − l²) and (r·r − l²)/5 describe the same wire: the same force, another λ.
    for text in ["3*dot(r,r) = 3*l^2", "dot(r,r)/5 - l^2/5", "l^2 = dot(r,r)"] {
        let mut b = lagrange::model::system::SystemBuilder::new("scaled", 2).expect("2D");
        b.parameter("l", lagrange::expr::Ty::Scalar).expect("l");
        b.body(&common::body("bead", "r", "v", "a", "F", "m")).expect("bead");
        b.constraint("wire", text).expect("constraint");
        let system = b.finish();
        let mut d = derived(&system);
        let force = d.forces.as_ref().expect("forces")[0].1;
        assert_equivalent(&system, &mut d, force, "-(m*dot(v,v) + dot(F,r))/dot(r,r) * r", text);
    }
}

/// `lagrange derive FILE --format json`, parsed.
fn json_of(path: &str) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["derive", path, "--format", "json"])
        .output()
        .expect("binary runs");
    assert!(out.status.success(), "{path}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("valid JSON")
}

/// The JSON's multiplier symbols (`"multipliers"`: constraint → symbol), declared as scalars
/// in `system`'s scope so the forces written in them parse; by constraint name.
fn declare_multipliers(system: &mut System, json: &serde_json::Value) -> Vec<(String, Symbol)> {
    let mut out = Vec::new();
    for (constraint, symbol) in json["multipliers"].as_object().expect("multipliers") {
        let name = symbol.as_str().expect("a symbol's name");
        let s = system.graph.declare(name, Ty::Scalar, Role::Parameter);
        let id = system.graph.sym(s);
        system.scope.insert(name, id);
        out.push((constraint.clone(), s));
    }
    out
}

/// Every string in the JSON that is an expression, with a label, parsed in `system`'s scope
/// (the multipliers declared first).
fn json_expressions(system: &mut System, json: &serde_json::Value) -> Vec<(String, Id)> {
    declare_multipliers(system, json);
    let mut parse = |label: String, v: &serde_json::Value| {
        let text = v.as_str().unwrap_or_else(|| panic!("{label} is not a string"));
        let id = system.expression(text).unwrap_or_else(|e| panic!("{label} = {text:?} does not parse again: {e}"));
        (label, id)
    };
    let mut out = Vec::new();
    for (k, c) in json["constraints"].as_array().expect("constraints").iter().enumerate() {
        for key in ["C", "C_dot", "C_ddot", "c"] {
            out.push(parse(format!("constraints[{k}].{key}"), &c[key]));
        }
        for (body, j) in c["gradient"].as_object().expect("gradient") {
            out.push(parse(format!("constraints[{k}].gradient.{body}"), j));
        }
    }
    // A: its non-zero entries over the upper triangle, `{"row": k, "col": j, "expr": …}`.
    for entry in json["A"].as_array().expect("A") {
        let (k, j) = (entry["row"].as_u64().expect("row"), entry["col"].as_u64().expect("col"));
        assert!(k <= j, "A's entry ({k}, {j}) is below the diagonal");
        out.push(parse(format!("A[{k}][{j}]"), &entry["expr"]));
    }
    for (k, e) in json["b"].as_array().expect("b").iter().enumerate() {
        out.push(parse(format!("b[{k}]"), e));
    }
    for key in ["lambda", "forces"] {
        if let Some(map) = json[key].as_object() {
            for (name, e) in map {
                out.push(parse(format!("{key}.{name}"), e));
            }
        }
    }
    out
}

#[test]
fn json_expressions_parse_again_and_satisfy_the_derivation() {
    let mut rng = Rng::new(7);
    let files = [
        "constraints/bead_on_wire.toml",
        "constraints/bead_on_sphere.toml",
        "constraints/double_pendulum.toml",
        "constraints/chain_5.toml",
    ];
    for path in files {
        let json = json_of(path);
        let mut system = loaded(path);
        let parsed = json_expressions(&mut system, &json);
        let multipliers = declare_multipliers(&mut system, &json);
        assert!(parsed.len() >= 8, "{path}: too few expressions in the JSON");
        let get = |label: &str| parsed.iter().find(|(l, _)| l == label).map(|p| p.1);
        let n = json["constraints"].as_array().map_or(0, Vec::len);
        let bodies: Vec<String> = system.bodies.iter().map(|b| b.name.clone()).collect();
        for _ in 0..20 {
            let env = random_env(&system, &mut rng);
            let body_index = |name: &str| bodies.iter().position(|b| b == name).expect("a body");
            // J and κ of each constraint, from the JSON only.
            let mut directions: Vec<Vec<(usize, [f64; 3])>> = Vec::new();
            for k in 0..n {
                let c = &json["constraints"][k];
                let kappa: f64 = c["scale"].as_str().and_then(|s| s.parse().ok()).unwrap_or_else(|| {
                    let q = c["scale"].as_str().expect("scale");
                    let (p, r) = q.split_once('/').expect("a rational");
                    p.parse::<f64>().expect("p") / r.parse::<f64>().expect("q")
                });
                let mut js = Vec::new();
                let mut j_dot_a = 0.0;
                for name in c["gradient"].as_object().expect("gradient").keys() {
                    let i = body_index(name);
                    let j = vector(&system, get(&format!("constraints[{k}].gradient.{name}")).expect("J"), &env);
                    let a = env.get(system.bodies[i].acceleration).and_then(|v| v.vector()).expect("a");
                    j_dot_a += common::dot3(j, a);
                    js.push((i, j));
                }
                // C̈/κ = Σᵢ Jᵢ·aᵢ + c: the κ scaling is consistent.
                let c_ddot = scalar(&system, get(&format!("constraints[{k}].C_ddot")).expect("C̈"), &env);
                let c_term = scalar(&system, get(&format!("constraints[{k}].c")).expect("c"), &env);
                assert!(close(c_ddot / kappa, j_dot_a + c_term, 1e-12), "{path}: C̈/κ ≠ J·a + c for constraint {k}");
                directions.push(js);
            }
            // Aₖⱼ = Σᵢ Jₖᵢ·Jⱼᵢ/mᵢ and bₖ = Σᵢ Jₖᵢ·Fᵢ/mᵢ + cₖ, from the JSON's own J and c.
            let mass = |i: usize| scalar(&system, system.bodies[i].mass, &env);
            let force = |i: usize| env.get(system.bodies[i].force).and_then(|v| v.vector()).expect("F");
            let mut a = vec![vec![0.0; n]; n];
            let mut b = vec![0.0; n];
            for k in 0..n {
                for j in 0..n {
                    let mut expected = 0.0;
                    for &(i, jk) in &directions[k] {
                        for &(i2, jj) in &directions[j] {
                            if i == i2 {
                                expected += common::dot3(jk, jj) / mass(i);
                            }
                        }
                    }
                    // A is symmetric and sparse: an entry not listed is zero.
                    let (row, col) = (k.min(j), k.max(j));
                    a[k][j] = get(&format!("A[{row}][{col}]")).map_or(0.0, |id| scalar(&system, id, &env));
                    assert!(close(a[k][j], expected, 1e-12), "{path}: A[{k}][{j}]");
                }
                let c_term = scalar(&system, get(&format!("constraints[{k}].c")).expect("c"), &env);
                let expected =
                    directions[k].iter().map(|&(i, j)| common::dot3(j, force(i)) / mass(i)).sum::<f64>() + c_term;
                b[k] = scalar(&system, get(&format!("b[{k}]")).expect("b"), &env);
                assert!(close(b[k], expected, 1e-12), "{path}: b[{k}]");
            }
            // Where the JSON gives λ and forces (one constraint): λ = −b/A and force on
            // body i = Σₖ λₖ Jₖᵢ, written in the multiplier's symbol: evaluated from the
            // document alone, with the symbol bound to λ's value.
            if let Some(lambda) = json["lambda"].as_object() {
                let name = lambda.keys().next().expect("one λ");
                let l = scalar(&system, get(&format!("lambda.{name}")).expect("λ"), &env);
                assert!(close(l, -b[0] / a[0][0], 1e-10), "{path}: λ ≠ −b/A");
                let symbol = multipliers.iter().find(|m| m.0 == *name).expect("λ's symbol").1;
                let mut env = env.clone();
                env.set(symbol, Value::Scalar(l));
                for &(i, j) in &directions[0] {
                    let f = vector(&system, get(&format!("forces.{}", bodies[i])).expect("force"), &env);
                    assert!(close_vec(f, common::scale3(l, j), 1e-12), "{path}: force on {} ≠ λ J", bodies[i]);
                }
            }
        }
    }
}
