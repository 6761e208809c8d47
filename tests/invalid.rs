//! Every file in `constraints/invalid/` is refused by `lagrange derive` with located
//! messages: `file:line:col`, the source line, and a caret under the fault. The
//! expression-level files (one per error class of the expression language) have a test
//! below and a snapshot each; a new one needs a new test. The file-level files
//! (`file_*.toml`, several problems each) are snapshot-tested by `constraint_files.rs` and
//! run through the binary here.

use std::path::Path;
use std::process::Command;

/// Runs `lagrange derive REL` from the crate root and returns stderr, after checking that the
/// file was refused: exit code 1 and nothing on stdout.
fn refused(rel: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["derive", rel])
        .output()
        .expect("the lagrange binary runs");
    let stderr = String::from_utf8(out.stderr).expect("stderr is UTF-8");
    assert_eq!(out.status.code(), Some(1), "{rel}: expected exit code 1, got {:?}\n{stderr}", out.status);
    assert!(out.stdout.is_empty(), "{rel}: nothing should be printed on stdout");
    stderr
}

/// Runs `lagrange derive constraints/invalid/NAME.toml` from the crate root (so the path in
/// the message is relative and the snapshot machine-independent); returns stderr.
fn derive_invalid(name: &str) -> String {
    let root = env!("CARGO_MANIFEST_DIR");
    let rel = format!("constraints/invalid/{name}.toml");
    assert!(Path::new(root).join(&rel).is_file(), "{rel} is missing");
    let stderr = refused(&rel);
    // The shape every snapshot must have, checked here too so a bad snapshot cannot be
    // accepted by eye: a located header, the offending source line, a caret.
    let location = format!("{rel}:");
    let header = stderr.lines().find(|l| l.contains(&location)).unwrap_or_else(|| panic!("no location in\n{stderr}"));
    let numbers: Vec<&str> = header.rsplit(&location).next().unwrap_or("").split(':').collect();
    assert!(
        numbers.len() == 2 && numbers.iter().all(|n| n.trim().parse::<usize>().is_ok()),
        "expected `{rel}:line:col` in {header:?}"
    );
    assert!(stderr.lines().any(|l| l.contains("expr = ")), "no source line in\n{stderr}");
    assert!(stderr.lines().any(|l| l.trim_start().trim_start_matches(['│', '|']).trim_start().starts_with('^')));
    assert!(!stderr.contains("panicked"), "{rel}: panic\n{stderr}");
    stderr
}

macro_rules! invalid {
    ($($name:ident: $needle:literal,)*) => {$(
        #[test]
        fn $name() {
            let stderr = derive_invalid(stringify!($name));
            assert!(stderr.contains($needle), "expected {:?} in\n{stderr}", $needle);
            insta::assert_snapshot!(stderr);
        }
    )*};
}

invalid! {
    unknown_symbol: "unknown symbol `L` (did you mean `l`?)",
    unknown_function: "unknown function `dott`",
    wrong_arity: "takes 2 arguments, found 1",
    dot_of_scalar: "needs a vector here, found a scalar",
    vector_times_vector: "cannot multiply a vector by a vector",
    literal_length: "needs 2 entries, found 3",
    vector_vs_scalar: "cannot compare a vector with a scalar",
    syntax_error: "expected an expression",
    norm_bars: "write the norm |r| as `norm(r)`",
    printed_notation: "write `dot(r, r)`",
    vector_power: "write |r|² as `dot(r, r)`",
    double_star: "write powers with `^`",
    missing_times: "a product needs `*`",
    missing_relation: "a constraint is a relation",
    strict_inequality: "write `>=` or `<=`",
    pi_constant: "`pi` is not built in",
    rot_not_orientation: "`phi` is not an orientation",
    rot_time_varying: "must be constant in time",
    vector_inequality: "only `=` relates vectors",
}

/// The file-level invalid files (`file_*.toml`, snapshot-tested through the library by
/// `constraint_files.rs`) through the binary: exit code 1, nothing on stdout, and on stderr
/// exactly the library's rendering — the same messages whichever way a file is loaded —
/// followed by the count.
#[test]
fn file_level_files_through_the_binary() {
    let root = env!("CARGO_MANIFEST_DIR");
    let mut count = 0;
    for stem in stems().into_iter().filter(|s| s.starts_with("file_")) {
        let rel = format!("constraints/invalid/{stem}.toml");
        let stderr = refused(&rel);
        let text = std::fs::read_to_string(Path::new(root).join(&rel)).expect("readable");
        let Err(lagrange::check::CheckError::Invalid { rendered, count: problems, .. }) =
            lagrange::check::Checked::from_text(&rel, &text)
        else {
            panic!("{rel}: the library accepted an invalid file");
        };
        assert_eq!(stderr, format!("{rendered}{problems} problems in {rel}\n"), "{rel}");
        count += 1;
    }
    assert!(count >= 9, "expected the file-level invalid files, found {count}");
}

/// The stems of the `.toml` files in `constraints/invalid/`, sorted.
fn stems() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/invalid");
    let mut out: Vec<String> = std::fs::read_dir(dir)
        .expect("constraints/invalid exists")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .filter_map(|p| p.file_stem().and_then(|s| s.to_str()).map(str::to_string))
        .collect();
    out.sort();
    out
}

/// Every file in `constraints/invalid/` is snapshot-tested (adding a file adds a test): the
/// expression-level ones by a test above, the file-level ones (`file_*.toml`) by the loop in
/// `constraint_files.rs`; each has its snapshot in `tests/snapshots/`.
#[test]
fn every_invalid_file_is_tested() {
    let source = include_str!("invalid.rs");
    let snapshots = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/snapshots");
    let all = stems();
    for stem in &all {
        let snapshot = if stem.starts_with("file_") {
            format!("constraint_files__{stem}.snap")
        } else {
            assert!(source.contains(&format!("    {stem}: \"")), "constraints/invalid/{stem}.toml has no test");
            format!("invalid__{stem}.snap")
        };
        assert!(snapshots.join(&snapshot).is_file(), "constraints/invalid/{stem}.toml has no snapshot {snapshot}");
    }
    let expression_level = all.iter().filter(|s| !s.starts_with("file_")).count();
    assert!(expression_level >= 8, "expected at least 8 expression-level invalid files, found {expression_level}");
}
