//! What `derive` prints reads as what it means: a negative factor of a product keeps its
//! parentheses (`r.y (−sin(w t) w)`, never `r.y −sin(w t) w`, which reads as a
//! difference), in the Unicode text and in LaTeX, and a fractional κ is written `∇C/(2/3)`,
//! never `∇C/2/3` (which reads as ∇C/6). The round trips of the printers over random
//! expressions are property tests in `properties.rs`.
//!
//! Not here: the snapshots of every document (`outputs.rs`), LaTeX's syntax (`latex.rs`).

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
