//! Fuzzing kept in the project (issue 17, "Keep it found"): whole constraint files, made
//! from a grammar of expressions and by mutating real files, run in-process through the
//! loader, `derive` (with its documents), `generate`, `solve` at the file's scene state
//! (what `lagrange solve` does, the change of unit included), and `check` (which derives,
//! samples states and solves at them). Each case must end with a result or a typed error: a panic
//! fails the property, and the work budgets (`expr::work`, the document's and the code's)
//! keep every case short, so the run needs no timer.
//!
//! The seed corpus `tests/fuzz/corpus/` holds the issue's cases (one file each); every file
//! of it runs as a regression test, and the mutation strategy starts from it and from
//! `constraints/`. `PROPTEST_CASES` sets the number of random cases per property (64 by
//! default) and `PROPTEST_RNG_SEED` their seed (fixed by default, so the suite's time does not
//! vary between runs); `docs/fuzzing.md` says how to run it for an hour.

use lagrange::codegen::{Lang, Options as GenerateOptions};
use lagrange::derive::Options as DeriveOptions;
use lagrange::numeric::rescale::solve_at;
use lagrange::numeric::solve::Settings as SolveSettings;
use lagrange::report::derivation::{Format, document};
use lagrange::{Checked, Scenario, derive_with, generate, load};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestRunner};
use std::path::{Path, PathBuf};

/// Runs `text` through every in-process entry point; returns how far it got, for the
/// corpus test's report. Panics (a failed property) only if the library panics.
fn exercise(name: &str, text: &str) -> &'static str {
    let Ok(loaded) = load(text) else { return "refused by the loader" };
    let Ok(d) = derive_with(&loaded.system, DeriveOptions { document: true, steps: true }) else {
        return "refused by derive";
    };
    for format in [Format::Text, Format::Json] {
        let _ = document(&loaded.system, &d, format, true);
    }
    for lang in [Lang::Rust, Lang::C] {
        let _ = generate(&loaded, &GenerateOptions { lang, ..GenerateOptions::default() });
    }
    if let Ok(scenario) = Scenario::new(loaded, &[]) {
        let _ = solve_at(&scenario.program, &scenario.system, &scenario.env, &SolveSettings::default());
    }
    match Checked::from_text(name, text) {
        Ok(mut checked) => {
            let outcomes = checked.run();
            if outcomes.is_empty() { "derived" } else { "checked" }
        }
        Err(_) => "refused by check",
    }
}

/// The runner's settings: `PROPTEST_CASES` random cases per property (64 by default) from
/// `PROPTEST_RNG_SEED` (a fixed seed by default, so every run of the suite, and CI, draws the
/// same cases and takes the same time; set the variable to explore others).
fn config() -> Config {
    let mut config = Config { failure_persistence: None, ..Config::default() };
    config.cases = std::env::var("PROPTEST_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(64);
    if config.rng_seed == RngSeed::Random {
        config.rng_seed = RngSeed::Fixed(0x1a9_2a4e);
    }
    config
}

fn corpus() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz/corpus");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("tests/fuzz/corpus exists")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

/// Every seed of the corpus ends with a result or a typed error (the issue's cases: each
/// once ran for minutes, took gigabytes or panicked).
#[test]
fn every_seed_of_the_corpus_ends() {
    let files = corpus();
    assert!(files.len() >= 10, "the corpus holds the issue's cases");
    for path in files {
        let text = std::fs::read_to_string(&path).expect("UTF-8 seed");
        let name = path.display().to_string();
        let outcome = exercise(&name, &text);
        // The seeds are hard, not broken: each is a valid file.
        assert_ne!(outcome, "refused by the loader", "{name}");
    }
}

/// A scalar expression of the language over the bead's symbols, as text.
fn scalar() -> BoxedStrategy<String> {
    let leaf = prop_oneof![
        Just("r.x".to_string()),
        Just("r.y".to_string()),
        Just("v.x".to_string()),
        Just("l".to_string()),
        Just("m".to_string()),
        Just("t".to_string()),
        Just("dot(r, r)".to_string()),
        Just("dot(r, v)".to_string()),
        Just("norm(r)".to_string()),
        Just("cross(r, v)".to_string()),
        (-3i32..=3).prop_map(|k| k.to_string()),
        prop::sample::select(vec!["0", "0.5", "1e300", "1e-300", "1e400", "2.5e-3", "1827/1000"])
            .prop_map(str::to_string),
    ];
    leaf.prop_recursive(5, 48, 3, |inner| {
        prop_oneof![
            (inner.clone(), prop::sample::select(vec!["+", "-", "*", "/"]), inner.clone())
                .prop_map(|(a, op, b)| format!("({a} {op} {b})")),
            (inner.clone(), prop::sample::select(vec!["2", "3", "-1", "-2", "0.5", "100", "-100000", "r.x"]))
                .prop_map(|(a, n)| format!("({a})^{n}")),
            (prop::sample::select(vec!["sin", "cos", "sqrt", "ln", "exp", "atan", "acos", "asin", "-"]), inner.clone())
                .prop_map(|(f, a)| if f == "-" { format!("-({a})") } else { format!("{f}({a})") }),
            (inner.clone(), inner).prop_map(|(a, b)| format!("atan2({a}, {b})")),
        ]
    })
    .boxed()
}

/// A bead file with the constraints `exprs` (`=` 0, or `>=` 0 for a contact), a scene and an
/// expectation, so `check` samples states and solves at them.
fn bead_file(exprs: &[(String, bool)]) -> String {
    let mut text = String::from(
        "title = \"fuzz\"\ndimension = 2\n[parameters]\nl = 1.5\nm = 2.0\ng = [0.0, -9.81]\n\
         [[bodies]]\nname = \"bead\"\nposition = \"r\"\nvelocity = \"v\"\nacceleration = \"a\"\nmass = \"m\"\nforce = \"F\"\n",
    );
    for (k, (e, contact)) in exprs.iter().enumerate() {
        let relation = if *contact { ">=" } else { "=" };
        text += &format!("[[constraints]]\nname = \"c{k}\"\nexpr = '{e} {relation} 0'\n");
    }
    text += "[scene]\ninitial = { r = [1.0, 0.5], v = [0.0, 1.0] }\nforces = { F = \"m*g\" }\n";
    text += "[[expect]]\nforce = { bead = \"[1, 2]\" }\n";
    text
}

/// Grammar-made files: one to three constraints of random expressions.
#[test]
fn grammar_made_files_end_with_a_result_or_a_typed_error() {
    let mut runner = TestRunner::new(config());
    let strategy = prop::collection::vec((scalar(), any::<bool>()), 1..=3);
    runner
        .run(&strategy, |exprs| {
            exercise("grammar.toml", &bead_file(&exprs));
            Ok(())
        })
        .expect("no panic on a grammar-made file");
}

/// Pieces of TOML and of the expression language that mutations insert.
const TOKENS: &[&str] = &[
    "[[",
    "]]",
    "[",
    "]",
    "{",
    "}",
    "=",
    "\"",
    "'",
    ",",
    "\n",
    "#",
    "nan",
    "inf",
    "-inf",
    "1e999",
    "1e-320",
    "0",
    "-1",
    "dot(",
    "norm(",
    "sqrt(",
    "^",
    "^-100000",
    "*",
    "/0",
    "(",
    ")",
    "r",
    "v",
    "a",
    "m",
    "t",
    "[[bodies]]",
    "[[constraints]]",
    "[[expect]]",
    "[scene]",
    "[definitions]",
    "name = \"x\"",
    "expr = \"r.x\"",
    "\u{202e}",
    "\u{1b}[2K",
    "\u{0}",
    "é",
    "3^1000000",
];

/// One edit of a text: delete a range, duplicate a range, or insert a token.
#[derive(Clone, Debug)]
enum Edit {
    Delete(usize, usize),
    Duplicate(usize, usize),
    Insert(usize, usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 1usize..40).prop_map(|(at, n)| Edit::Delete(at, n)),
        (any::<usize>(), 1usize..80).prop_map(|(at, n)| Edit::Duplicate(at, n)),
        (any::<usize>(), 0..TOKENS.len()).prop_map(|(at, k)| Edit::Insert(at, k)),
    ]
}

/// `text` with `edits` applied, each at a char boundary.
fn mutate(text: &str, edits: &[Edit]) -> String {
    let mut s = text.to_string();
    let boundary = |s: &str, at: usize| {
        let mut i = if s.is_empty() { 0 } else { at % (s.len() + 1) };
        while !s.is_char_boundary(i) {
            i -= 1;
        }
        i
    };
    for e in edits {
        match *e {
            Edit::Delete(at, n) => {
                let i = boundary(&s, at);
                let j = boundary(&s, i + n.min(s.len() - i));
                s.replace_range(i..j, "");
            }
            Edit::Duplicate(at, n) => {
                let i = boundary(&s, at);
                let j = boundary(&s, i + n.min(s.len() - i));
                let piece = s[i..j].to_string();
                s.insert_str(j, &piece);
            }
            Edit::Insert(at, k) => {
                let i = boundary(&s, at);
                s.insert_str(i, TOKENS[k]);
            }
        }
    }
    s
}

/// Mutated files: the shipped constraint files and the corpus, with up to eight edits.
#[test]
fn mutated_files_end_with_a_result_or_a_typed_error() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut seeds: Vec<String> = Vec::new();
    for dir in ["constraints", "constraints/joints", "constraints/rigid", "constraints/solvers"] {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(root.join(dir))
            .expect("constraint directory")
            .map(|e| e.expect("entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        paths.sort();
        seeds.extend(paths.iter().map(|p| std::fs::read_to_string(p).expect("UTF-8")));
    }
    // The corpus's small seeds (the large ones only repeat their budget refusals).
    seeds.extend(corpus().iter().map(|p| std::fs::read_to_string(p).expect("UTF-8")).filter(|t| t.len() < 4096));
    let mut runner = TestRunner::new(config());
    let strategy = (0..seeds.len(), prop::collection::vec(edit(), 1..=8));
    runner
        .run(&strategy, |(k, edits)| {
            exercise("mutated.toml", &mutate(&seeds[k], &edits));
            Ok(())
        })
        .expect("no panic on a mutated file");
}
