//! The boundaries of ARCHITECTURE.md, checked by reading the source text.
//!
//! Each rule is a folder (or file) and the words that must not appear in its code. Comments
//! and string literals are blanked out first, so a doc comment saying "knows nothing of
//! serde" is not a violation; everything else is. A failure names the file, the line and
//! the rule, so the fix is obvious.

use std::path::{Path, PathBuf};

/// One boundary: files under `scope` (a folder or a file, relative to the crate root),
/// except those under `exempt`, must not contain any of `forbidden`.
struct Rule {
    scope: &'static str,
    exempt: &'static [&'static str],
    forbidden: &'static [&'static str],
    why: &'static str,
}

const PRINTING: &[&str] = &["println!", "print!", "eprintln!", "eprint!", "dbg!", "stdout(", "stderr("];
const FILES: &[&str] = &["std::fs", "fs::", "File::", "OpenOptions"];
/// Ways to hold a loaded model mutably: the type, and the places a `System` lives.
const MUT_SYSTEM: &[&str] = &[
    "&mut System",
    "&mut loaded.system",
    "&mut self.loaded.system",
    "&mut self.system",
    "&mut scenario.system",
    "&mut l.system",
    "&mut s.system",
];

fn rules() -> Vec<Rule> {
    vec![
        Rule {
            scope: "src/expr",
            exempt: &[],
            forbidden: &["serde", "nalgebra", "clarabel", "toml", "std::fs", "fs::", "File::"],
            why: "the symbolic core knows nothing of files, serde or numerics crates",
        },
        Rule { scope: "src/expr", exempt: &[], forbidden: PRINTING, why: "the symbolic core never prints" },
        Rule {
            scope: "src/expr/parse.rs",
            exempt: &[],
            forbidden: &["to_f64", "parse::<f64>", "parse::<f32>", "f64::from", "as f64", ": f64"],
            why: "the parser only builds syntax; it never evaluates numbers",
        },
        Rule {
            scope: "src/numeric",
            exempt: &[],
            forbidden: &[
                "toml",
                "serde",
                "println!",
                "print!",
                "eprintln!",
                "eprint!",
                "std::fs",
                "fs::",
                "model::file",
                "model::scene",
                "expr::print",
                "report",
            ],
            why: "numeric knows nothing of TOML, files or text: it sees the resolved System, never the file",
        },
        Rule {
            scope: "src/numeric",
            exempt: &[],
            forbidden: &["format!", "write!", "writeln!", "impl fmt::Display", "impl std::fmt::Display"],
            why: "numeric writes no prose: outcomes are typed (enums with indices and numbers); \
                  report and main.rs make the sentences, and the only words in numeric are the \
                  #[error] messages of its typed errors",
        },
        Rule {
            scope: "src/precision",
            exempt: &[],
            forbidden: &["format!", "write!", "writeln!", "impl fmt::Display", "impl std::fmt::Display"],
            why: "precision measures; report::precision words it (failures are SimError values, \
                  labels are names and flags)",
        },
        Rule {
            scope: "src",
            exempt: &["src/main.rs", "src/build.rs"],
            forbidden: PRINTING,
            why: "only main.rs prints: report writers build strings and values, main.rs writes them \
                  (and build.rs, whose cargo:rerun-if-changed lines are cargo's build-script protocol)",
        },
        Rule {
            scope: "src",
            exempt: &["src/main.rs", "src/check/read.rs", "src/build.rs"],
            forbidden: FILES,
            why: "only main.rs touches files (and check/read.rs, the one size-limited read that \
                  users' tests share with the command line, and build.rs, which writes a user's \
                  generated module into OUT_DIR)",
        },
        Rule {
            scope: "src",
            exempt: &["src/model", "src/derive.rs"],
            forbidden: MUT_SYSTEM,
            why: "the model is frozen after load: only model builds a System and derive reads it; \
                  what derive adds lives in the Derivation",
        },
    ]
}

/// The code of a Rust source with comments and the contents of string and char literals
/// replaced by spaces (line structure kept, so line numbers stay right).
fn code_only(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < chars.len() {
                if chars[i] == '/' && chars.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if chars[i] == '*' && chars.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(chars[i]));
                    i += 1;
                }
            }
        } else if c == 'r' && (next == Some('"') || next == Some('#')) && !ident_before(&chars, i) {
            // Raw string r"…" or r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while chars.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if chars.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            for _ in i..=j {
                out.push(' ');
            }
            i = j + 1;
            while i < chars.len() {
                if chars[i] == '"' && (0..hashes).all(|h| chars.get(i + 1 + h) == Some(&'#')) {
                    for _ in 0..=hashes {
                        out.push(' ');
                    }
                    i += 1 + hashes;
                    break;
                }
                out.push(blank(chars[i]));
                i += 1;
            }
        } else if c == '"' {
            out.push(' ');
            i += 1;
            while i < chars.len() && chars[i] != '"' {
                if chars[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < chars.len() {
                    out.push(blank(chars[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c == '\'' && is_char_literal(&chars, i) {
            // 'x', '\n', '\'' — but not lifetimes ('a).
            let end = chars[i + 1..].iter().position(|&d| d == '\'').map(|p| p + i + 1);
            let end = if chars.get(i + 1) == Some(&'\\') {
                chars[i + 3..].iter().position(|&d| d == '\'').map(|p| p + i + 3)
            } else {
                end
            };
            let end = end.unwrap_or(i);
            for _ in i..=end {
                out.push(' ');
            }
            i = end + 1;
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

fn ident_before(chars: &[char], i: usize) -> bool {
    i > 0 && (chars[i - 1].is_alphanumeric() || chars[i - 1] == '_')
}

fn is_char_literal(chars: &[char], i: usize) -> bool {
    matches!((chars.get(i + 1), chars.get(i + 2)), (Some('\\'), _) | (Some(_), Some('\'')))
}

/// Whether `word` occurs in `line` as a whole token (identifier characters do not continue
/// it on either side where the word itself starts or ends with one).
fn contains_token(line: &str, word: &str) -> bool {
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut from = 0;
    while let Some(p) = line[from..].find(word) {
        let start = from + p;
        let end = start + word.len();
        let before_ok = !word.starts_with(is_ident) || !line[..start].ends_with(is_ident);
        let after_ok = !word.ends_with(is_ident) || !line[end..].starts_with(is_ident);
        if before_ok && after_ok {
            return true;
        }
        from = start + 1;
    }
    false
}

/// `(line number, word)` of every forbidden word in the code of `text`.
fn violations(text: &str, forbidden: &[&str]) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in code_only(text).lines().enumerate() {
        for word in forbidden {
            if contains_token(line, word) {
                found.push((n + 1, (*word).to_string()));
            }
        }
    }
    found
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    if dir.is_file() {
        out.push(dir.to_path_buf());
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn module_boundaries_hold() {
    let root = root();
    let mut failures = Vec::new();
    let mut scanned = 0;
    for rule in rules() {
        let mut files = Vec::new();
        rust_files(&root.join(rule.scope), &mut files);
        files.sort();
        for file in files {
            let rel = file.strip_prefix(&root).unwrap_or(&file).to_string_lossy().replace('\\', "/");
            if rule.exempt.iter().any(|e| rel == *e || rel.starts_with(&format!("{e}/"))) {
                continue;
            }
            let text = std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("cannot read {rel}: {e}"));
            scanned += 1;
            for (line, word) in violations(&text, rule.forbidden) {
                let source = text.lines().nth(line - 1).unwrap_or("").trim();
                failures.push(format!("{rel}:{line}: `{word}` is forbidden here ({})\n    {source}", rule.why));
            }
        }
    }
    assert!(scanned >= 20, "expected to scan the source tree, scanned only {scanned} files");
    assert!(failures.is_empty(), "architecture boundaries broken:\n{}", failures.join("\n"));
}

#[test]
fn the_core_exists_where_the_rules_look() {
    // If a folder is renamed, the rules above would silently check nothing.
    for path in ["src/expr", "src/expr/parse.rs", "src/main.rs", "src/report"] {
        assert!(root().join(path).exists(), "{path} is gone: update tests/architecture.rs and ARCHITECTURE.md");
    }
}

#[test]
fn the_frozen_model_rule_sees_a_mutable_system() {
    let text = "fn f(s: &mut System) {}\nlet d = derive(&mut loaded.system);\n// &mut System in a comment\nfn g(s: &System) {}";
    let found: Vec<usize> = violations(text, MUT_SYSTEM).into_iter().map(|(line, _)| line).collect();
    assert_eq!(found, [1, 2]);
}

#[test]
fn the_scanner_sees_code_and_ignores_comments_and_strings() {
    let text = "//! knows nothing of serde\nuse serde::Deserialize;\nlet s = \"println!\";\n    println!(\"x\");\n/* toml */ let t = r#\"toml\"#;\nlet c = '\"'; use toml;\nfn f<'a>(x: &'a str) { eprint!(\"{x}\") }\nlet reprint = 1;";
    let found = violations(text, &["serde", "println!", "toml", "eprint!", "print!"]);
    assert_eq!(
        found,
        vec![
            (2, "serde".to_string()),
            (4, "println!".to_string()),
            (6, "toml".to_string()),
            (7, "eprint!".to_string()),
        ]
    );
    // Parser rule: number evaluation is caught, `f64` inside a word is not a false alarm.
    assert_eq!(violations("let x = q.to_f64();", &["to_f64"]), vec![(1, "to_f64".to_string())]);
    assert!(violations("let my_to_f64x = 1;", &["to_f64"]).is_empty());
}
