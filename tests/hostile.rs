//! Hostile input through the real binary: whatever the file holds, `lagrange derive` ends
//! with a short message on stderr and exit code 1 — never a panic (101), a stack overflow
//! or another signal, never a wall of text.

use std::path::PathBuf;
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A temporary file with a unique name, removed when dropped.
struct TempFile(PathBuf);

impl TempFile {
    fn new(tag: &str, bytes: &[u8]) -> TempFile {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let name = format!("lagrange-hostile-{}-{n}-{tag}.toml", std::process::id());
        let path = std::env::temp_dir().join(name);
        std::fs::write(&path, bytes).expect("temp file written");
        TempFile(path)
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// A bead file whose constraint is `expr` (written as a TOML literal string).
fn bead_with(expr: &str) -> String {
    format!(
        "title = \"hostile\"\ndimension = 2\n[parameters]\nl = 1.0\nm = 1.0\n[[bodies]]\nname = \"bead\"\n\
         position = \"r\"\nvelocity = \"v\"\nacceleration = \"a\"\nmass = \"m\"\nforce = \"F\"\n\
         [[constraints]]\nname = \"wire\"\nexpr = '{expr}'\n"
    )
}

/// Runs `lagrange derive FILE` and checks the outcome: exit 1, a message on stderr that is
/// short and contains `expect`, no panic. Returns stderr.
fn refused(tag: &str, bytes: &[u8], expect: &str) -> String {
    let file = TempFile::new(tag, bytes);
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("derive").arg(&file.0).output().expect("binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{tag}: expected exit code 1 (a refusal), got {:?} (101 is a panic, None a signal)\n{}",
        out.status,
        &stderr[..stderr.len().min(2000)]
    );
    assert!(!stderr.contains("panicked"), "{tag}: panic\n{stderr}");
    assert!(stderr.contains(expect), "{tag}: expected {expect:?} in\n{}", &stderr[..stderr.len().min(2000)]);
    assert!(stderr.len() < 2000 && stderr.lines().count() <= 12, "{tag}: message too long:\n{}", &stderr[..2000]);
    assert!(out.stdout.is_empty(), "{tag}: nothing belongs on stdout");
    stderr
}

#[test]
fn deeply_nested_parentheses() {
    let n = 100_000;
    let expr = format!("{}dot(r, r){} = l^2", "(".repeat(n), ")".repeat(n));
    refused("parens", bead_with(&expr).as_bytes(), "nest");
}

#[test]
fn deeply_nested_unary_minus_and_calls() {
    let minus = format!("{}dot(r, r) = l^2", "-".repeat(100_000));
    refused("minus", bead_with(&minus).as_bytes(), "nest");
    let calls = format!("{}dot(r, r){} = l^2", "sin(".repeat(50_000), ")".repeat(50_000));
    refused("calls", bead_with(&calls).as_bytes(), "nest");
}

#[test]
fn ten_megabyte_expression() {
    // 10 MB of `r.x + r.x + …`: valid syntax, far past the expression length limit.
    let term = "r.x + ";
    let expr = format!("{}dot(r, r) = l^2", term.repeat(10_000_000 / term.len()));
    assert!(expr.len() >= 10_000_000);
    refused("huge", bead_with(&expr).as_bytes(), "too long");
}

#[test]
fn empty_file() {
    refused("empty", b"", "dimension");
}

#[test]
fn not_toml() {
    refused("not-toml", b"this is { not toml ]]\n\x20= =\n", "error");
}

#[test]
fn invalid_utf8() {
    let mut bytes = bead_with("dot(r, r) = l^2").into_bytes();
    bytes.splice(0..0, [0xff, 0xfe, 0xc3, 0x28]);
    refused("utf8", &bytes, "not valid UTF-8");
}

#[test]
fn missing_file() {
    let path = std::env::temp_dir().join(format!("lagrange-hostile-{}-does-not-exist.toml", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("derive").arg(&path).output().expect("binary runs");
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot read"));
}
