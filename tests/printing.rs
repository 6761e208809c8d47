//! What `derive` prints reads as what it means: a negative factor of a product keeps its
//! parentheses (`r.y (−sin(w t) w)`, never `r.y −sin(w t) w`, which reads as a
//! difference), in the Unicode text and in LaTeX, and a fractional κ is written `∇C/(2/3)`,
//! never `∇C/2/3` (which reads as ∇C/6). The round trips of the printers over random
//! expressions are property tests in `properties.rs`.
//!
//! Not here: the snapshots of every document (`outputs.rs`), LaTeX's syntax (`latex.rs`).

mod common;

use lagrange::derive::{Options, derive_with};
use lagrange::model::file::load;
use lagrange::report::derivation::{Format, document};

fn doc(text: &str, format: Format, steps: bool) -> String {
    let loaded = load(text).unwrap_or_else(|p| panic!("loads: {p:?}"));
    let d = derive_with(&loaded.system, Options { document: true, steps }).expect("derives");
    document(&loaded.system, &d, format, steps).expect("document builds")
}

fn spinning_hoop() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/constraints/spinning_hoop.toml")).expect("reads")
}

#[test]
fn a_negative_factor_keeps_its_parentheses_in_text() {
    let text = doc(&spinning_hoop(), Format::Text, true);
    let line = text.lines().find(|l| l.trim_start().starts_with("Ċ[plane]")).expect("a Ċ[plane] line");
    // A factor juxtaposed after another piece never starts with a minus.
    assert!(!line.contains(" −sin"), "{line}");
    assert!(line.contains("r.y (−sin(w t) w)"), "{line}");
}

#[test]
fn a_negative_factor_keeps_its_parentheses_in_latex() {
    let text = doc(&spinning_hoop(), Format::Latex, true);
    let line = text.lines().find(|l| l.contains("\\dot{C}_{\\mathrm{plane}} =")).expect("a Ċ[plane] line");
    assert!(!line.contains("\\, -\\sin"), "{line}");
    assert!(line.contains("\\vec{r}_{y} \\, \\left(-\\sin\\left(w \\, t\\right) \\, w\\right)"), "{line}");
}

/// A bead on a circle written with C scaled by 1/3: ∇C = (2/3) r, so κ = 2/3.
const THIRD: &str = r#"
title = "Scaled bead"
dimension = 2
[parameters]
l = 1.0
m = 1.0
[[bodies]]
name = "bead"
position = "r"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"
[[constraints]]
name = "circle"
expr = "dot(r, r)/3 = l^2"
"#;

#[test]
fn a_fractional_scale_is_written_in_parentheses() {
    let text = doc(THIRD, Format::Text, false);
    assert!(text.contains("∇C/(2/3)"), "{text}");
    assert!(!text.contains("∇C/2/3"), "{text}");
    assert!(text.contains("over (2/3)"), "{text}");
    let steps = doc(THIRD, Format::Text, true);
    assert!(steps.contains("= (2/3) · (r)"), "{steps}");
}

/// A vector over a scalar denominator is one fraction in LaTeX, as a person writes the unit
/// vector of a spherical pendulum, `\frac{\vec r - \vec p}{\lVert \vec r - \vec p \rVert}`, and
/// Newton's `\frac{\vec F + \vec F_c}{m}` — not `\frac{1}{…} \, (…)`; the text keeps
/// `(r − p)/|r − p|`.
#[test]
fn a_vector_over_a_denominator_is_one_fraction_in_latex() {
    let pendulum = r#"
dimension = 3
[parameters]
l = 1.0
m = 1.0
p = [0.0, 0.0, 1.0]
[[bodies]]
name = "bob"
position = "r"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"
[[constraints]]
name = "rod"
expr = "norm(r - p) = l"
"#;
    let latex = doc(pendulum, Format::Latex, true);
    let gradient = latex.lines().find(|l| l.contains("\\nabla C \\quad")).expect("a ∇C line");
    assert!(
        gradient.ends_with("= \\frac{\\vec{r} - \\vec{p}}{\\left\\lVert \\vec{r} - \\vec{p} \\right\\rVert} \\]"),
        "{gradient}"
    );
    assert!(latex.contains("\\frac{\\vec{F} + \\vec{F}_{c}}{m}"), "Newton's step: {latex}");
    assert!(!latex.contains("\\frac{1}{\\left\\lVert"), "no reciprocal in front of a vector: {latex}");
    let text = doc(pendulum, Format::Text, false);
    assert!(text.contains("(r − p)/|r − p|"), "{text}");
}

/// A rope over pulleys through `k` segments (`norm(r1 - p1) + norm(r2 - p1) + norm(r2 - p2) + …
/// = L`, a body between each two pulleys), as the benches' rope writes it.
fn rope(k: usize) -> String {
    let body = |s: usize| s / 2 + 1 + s % 2;
    let pulley = |s: usize| s.div_ceil(2) + usize::from(s.is_multiple_of(2));
    let mut text = String::from("title = \"rope\"\ndimension = 2\n\n[parameters]\nL = 10.0\n");
    for p in 1..=pulley(k - 1) {
        text += &format!("p{p} = [{p}.0, 0.0]\n");
    }
    for b in 1..=body(k - 1) {
        text += &format!("m{b} = 1.0\n");
    }
    for b in 1..=body(k - 1) {
        text += &format!(
            "[[bodies]]\nname = \"b{b}\"\nposition = \"r{b}\"\nvelocity = \"v{b}\"\nacceleration = \"a{b}\"\n\
             mass = \"m{b}\"\nforce = \"F{b}\"\n"
        );
    }
    let terms: Vec<String> = (0..k).map(|s| format!("norm(r{} - p{})", body(s), pulley(s))).collect();
    text + &format!("[[constraints]]\nname = \"rope\"\nexpr = \"{} = L\"\n", terms.join(" + "))
}

/// Where two segments meet at a body, A is a sum of fractions over their lengths
/// (`2 m1 + m2 + 2 m1 ((r2 − p1)·(r2 − p2))/(|r2 − p1| |r2 − p2|)` over `m1 m2`), and
/// λ = −b/A over one common denominator would repeat the product of the other lengths in
/// every term (1 261 characters at k = 5, growing faster than k). It is printed as the
/// quotient of the two sums, as by hand: linear in k, shorter than the combined form from
/// k = 3 on, and the same function.
#[test]
fn a_rope_over_pulleys_prints_lambda_as_the_quotient_of_b_and_a() {
    use lagrange::expr::print::{Style, print};
    for k in 2..=6 {
        let loaded = load(&rope(k)).unwrap_or_else(|p| panic!("loads: {p:?}"));
        let mut d = derive_with(&loaded.system, Options::default()).expect("derives");
        let lambda = d.lambda.expect("one constraint has a closed form");
        let text = print(&d.graph, lambda, Style::Source).expect("prints");
        assert!(text.len() <= 200 * k, "k = {k}: λ is {} characters: {text}", text.len());
        let (b, a) = (d.b[0], d.a[0].2);
        let combined = d.simplifier.negated_quotient(&mut d.graph, b, a).expect("the combined form");
        let combined_text = print(&d.graph, combined, Style::Source).expect("prints");
        if k >= 3 {
            assert!(text.len() < combined_text.len(), "k = {k}: {text} against {combined_text}");
        }
        assert!(d.simplifier.equivalent(&mut d.graph, lambda, combined).expect("compares"), "k = {k}");
        // Where the quotient is kept, the force on the first body is λ times its direction
        // (r1 − p1)/|r1 − p1|, λ as printed.
        if k >= 3 {
            let force = d.forces.as_ref().expect("forces")[0].1;
            let force_text = print(&d.graph, force, Style::Source).expect("prints");
            assert!(force_text.starts_with(&format!("({text})")), "k = {k}: {force_text}");
        }
    }
}

/// The rope's documents grow linearly in the segments k = 1…8: λ's closed form is printed
/// once and each body's force as `λ J` (JSON: `lambda_rope*(J)`, with `lambda` and
/// `multipliers` beside it), not λ's formula again on every body. Before, the JSON was
/// 1.1 kB at k = 1 and 12.1 kB at k = 8, more than 8 times as much, and its last segment
/// added 2.8 kB where the second added 1.0 kB. Asserted: bytes at k = 8 ≤ 8 × bytes at
/// k = 1 (c = 1: the document's fixed part pays for the growth), and the eighth segment adds at most
/// 1.5 times what the second added (a quadratic term would make it grow with k). And each
/// force read back from the JSON, its multiplier bound to the JSON's λ, is the derivation's
/// closed form λ J at random states.
#[test]
fn a_ropes_documents_grow_linearly_and_each_force_is_lambda_times_its_direction() {
    use lagrange::expr::eval::{Value, eval_one};
    use lagrange::expr::{Role, Ty};
    use lagrange::report::derivation::json;
    let mut rng = common::Rng::new(12);
    let (mut json_bytes, mut text_bytes) = (Vec::new(), Vec::new());
    for k in 1..=8 {
        let loaded = load(&rope(k)).unwrap_or_else(|p| panic!("loads: {p:?}"));
        let d = derive_with(&loaded.system, Options { document: true, steps: false }).expect("derives");
        let value = serde_json::to_value(json(&loaded.system, &d).expect("JSON builds")).expect("a JSON value");
        json_bytes.push(serde_json::to_string_pretty(&value).expect("prints").len());
        text_bytes.push(document(&loaded.system, &d, Format::Text, false).expect("document builds").len());
        let mut system = loaded.system;
        let symbol = value["multipliers"]["rope"].as_str().expect("the rope's multiplier symbol");
        let s = system.graph.declare(symbol, Ty::Scalar, Role::Parameter);
        let id = system.graph.sym(s);
        system.scope.insert(symbol, id);
        let parse = |system: &mut lagrange::model::system::System, v: &serde_json::Value| {
            let text = v.as_str().expect("a string");
            system.expression(text).unwrap_or_else(|e| panic!("k = {k}: {text:?} does not parse: {e}"))
        };
        let lambda = parse(&mut system, &value["lambda"]["rope"]);
        let forces = value["forces"].as_object().expect("forces");
        assert_eq!(forces.len(), system.bodies.len(), "k = {k}: a force on every body");
        let closed = d.forces.as_ref().expect("one constraint's closed forms");
        let parsed: Vec<_> = closed
            .iter()
            .map(|&(body, f)| {
                let text = forces[&system.bodies[body].name].as_str().expect("a string").to_string();
                assert!(text.starts_with(&format!("{symbol}*")), "k = {k}: {text}");
                (parse(&mut system, &serde_json::Value::String(text)), f)
            })
            .collect();
        for _ in 0..10 {
            let mut env = common::random_env(&system, &mut rng);
            let l = eval_one(&system.graph, lambda, &env).expect("λ evaluates").scalar().expect("a scalar");
            env.set(s, Value::Scalar(l));
            for &(from_json, f) in &parsed {
                let got = eval_one(&system.graph, from_json, &env).expect("evaluates").vector().expect("a vector");
                let want = eval_one(&d.graph, f, &env).expect("evaluates").vector().expect("a vector");
                assert!(common::close_vec(got, want, 1e-12), "k = {k}: {got:?} against the closed form {want:?}");
            }
        }
    }
    for (what, bytes) in [("JSON", &json_bytes), ("text", &text_bytes)] {
        assert!(bytes[7] <= 8 * bytes[0], "{what} bytes for k = 1…8: {bytes:?}");
        assert!(2 * (bytes[7] - bytes[6]) <= 3 * (bytes[1] - bytes[0]), "{what} bytes for k = 1…8: {bytes:?}");
    }
}
