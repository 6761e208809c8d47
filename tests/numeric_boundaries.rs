//! `numeric` knows nothing of TOML, files or text (ARCHITECTURE.md): no model, no serde or
//! toml, no printers, no files, no printing.

#[test]
fn numeric_knows_nothing_of_files_or_text() {
    let forbidden = ["toml", "serde", "crate::model", "expr::print", "std::fs", "println!", "print!(", "eprintln!"];
    let mut checked = 0;
    for entry in std::fs::read_dir("src/numeric").expect("src/numeric") {
        let path = entry.expect("entry").path();
        let text = std::fs::read_to_string(&path).expect("readable");
        // Doc examples may load a file to show use; code may not.
        let code: String = text.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n");
        for word in forbidden {
            assert!(!code.contains(word), "{} uses `{word}`", path.display());
        }
        checked += 1;
    }
    assert!(checked >= 2, "expected program.rs and tape.rs");
}
