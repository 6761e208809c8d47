//! `derive --format latex` writes LaTeX that compiles: ASCII only (every symbol lagrange
//! writes in its sentences becomes a LaTeX command), `$` and braces balanced, every display
//! `\[ … \]` closed, and no character LaTeX reserves left bare in text. Checked for every
//! constraint file, with and without `--steps`. (Compiled with pdflatex by hand: every
//! document of `constraints/` and `constraints/hard/`, wrapped in `article` + `amsmath`.)

use lagrange::derive::{Options, derive_with};
use lagrange::model::file::load;
use lagrange::report::derivation::{Format, document};
use std::path::{Path, PathBuf};

fn files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints");
    let mut out = Vec::new();
    for dir in [root.clone(), root.join("hard")] {
        for entry in std::fs::read_dir(dir).expect("constraints/ is readable").flatten() {
            let path = entry.path();
            if path.extension().is_some_and(|e| e == "toml") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

fn latex(path: &Path, steps: bool) -> String {
    let text = std::fs::read_to_string(path).expect("file reads");
    let loaded = load(&text).unwrap_or_else(|_| panic!("{} loads", path.display()));
    let d = derive_with(&loaded.system, Options { document: true, steps }).expect("derives");
    document(&loaded.system, &d, Format::Latex, steps).expect("document builds")
}

/// The problems of one line of LaTeX, outside display math: what would stop pdflatex.
fn problems(line: &str) -> Vec<String> {
    let mut found = Vec::new();
    if !line.is_ascii() {
        found.push("a character that is not ASCII".to_string());
    }
    let mut depth = 0i64;
    let mut in_math = line.starts_with("\\[");
    let mut prev = ' ';
    for c in line.chars() {
        if prev != '\\' {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                '$' => in_math = !in_math,
                '_' | '^' if !in_math => found.push(format!("a bare `{c}` in text")),
                _ => {}
            }
        }
        if depth < 0 {
            found.push("a `}` without its `{`".to_string());
            depth = 0;
        }
        prev = if prev == '\\' && c == '\\' { ' ' } else { c };
    }
    if depth != 0 {
        found.push("unbalanced braces".to_string());
    }
    if in_math != line.starts_with("\\[") {
        found.push("an unclosed `$`".to_string());
    }
    if line.starts_with("\\[") && !line.ends_with("\\]") {
        found.push("an unclosed `\\[`".to_string());
    }
    found
}

#[test]
fn every_latex_document_is_well_formed() {
    let mut checked = 0;
    for path in files() {
        for steps in [false, true] {
            let doc = latex(&path, steps);
            for (n, line) in doc.lines().enumerate() {
                let p = problems(line);
                assert!(p.is_empty(), "{} (steps: {steps}) line {}: {p:?}\n{line}", path.display(), n + 1);
            }
            checked += 1;
        }
    }
    assert!(checked >= 60, "only {checked} documents");
}

#[test]
fn sentences_put_their_symbols_in_math() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = latex(&root.join("constraints/double_pendulum.toml"), true);
    // Step 6's sentence: C̈ₖ/κₖ = Σᵢ Jₖᵢ·aᵢ + cₖ.
    assert!(doc.contains("$\\ddot{C}_{k}$/$\\kappa _{k}$ = $\\sum _{i}$ $J_{ki}\\cdot a_{i}$ + $c_{k}$"), "{doc}");
    // A label beside an equation is text inside the display.
    let bead = latex(&root.join("constraints/bead_on_wire.toml"), false);
    assert!(bead.contains("\\[ \\nabla C \\quad \\text{($\\nabla$ wrt r, body bead)} = 2 \\, \\vec{r} \\]"), "{bead}");
    assert!(bead.contains("dot(r,r) = l\\textasciicircum{}2"), "{bead}");
}
