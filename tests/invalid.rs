//! Every file in `constraints/invalid/` is refused by `lagrange derive` with a located
//! message: `file:line:col`, the source line, and a caret under the fault. The rendered
//! messages are snapshots (`tests/snapshots/`), one per error class of the expression
//! language; a new file there needs a new test below.

use std::path::Path;
use std::process::Command;

/// Runs `lagrange derive constraints/invalid/NAME.toml` from the crate root (so the path in
/// the message is relative and the snapshot machine-independent); returns stderr.
fn derive_invalid(name: &str) -> String {
    let root = env!("CARGO_MANIFEST_DIR");
    let rel = format!("constraints/invalid/{name}.toml");
    assert!(Path::new(root).join(&rel).is_file(), "{rel} is missing");
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .current_dir(root)
        .args(["derive", &rel])
        .output()
        .expect("the lagrange binary runs");
    let stderr = String::from_utf8(out.stderr).expect("stderr is UTF-8");
    assert_eq!(out.status.code(), Some(1), "{rel}: expected exit code 1, got {:?}\n{stderr}", out.status);
    assert!(out.stdout.is_empty(), "{rel}: nothing should be printed on stdout");
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
}

/// Every expression-level file in `constraints/invalid/` has a test above (adding a file adds
/// a test); the file-level ones (`file_*.toml`) are snapshot-tested by `constraint_files.rs`.
#[test]
fn every_invalid_file_is_tested() {
    let source = include_str!("invalid.rs");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/invalid");
    let mut count = 0;
    for entry in std::fs::read_dir(dir).expect("constraints/invalid exists").flatten() {
        let path = entry.path();
        if path.extension().is_some_and(|e| e == "toml") {
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_string();
            if stem.starts_with("file_") {
                continue;
            }
            assert!(source.contains(&format!("    {stem}: \"")), "constraints/invalid/{stem}.toml has no test");
            count += 1;
        }
    }
    assert!(count >= 8, "expected at least 8 invalid files, found {count}");
}
