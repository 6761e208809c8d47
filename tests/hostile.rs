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
    let stderr = refused_at_length(tag, bytes, expect);
    assert!(stderr.len() < 2000 && stderr.lines().count() <= 12, "{tag}: message too long:\n{}", clip(&stderr));
    stderr
}

/// [`refused`] without the length limit (for files with several problems).
fn refused_at_length(tag: &str, bytes: &[u8], expect: &str) -> String {
    let file = TempFile::new(tag, bytes);
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("derive").arg(&file.0).output().expect("binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{tag}: expected exit code 1 (a refusal), got {:?} (101 is a panic, None a signal)\n{}",
        out.status,
        clip(&stderr)
    );
    assert!(!stderr.contains("panicked"), "{tag}: panic\n{}", clip(&stderr));
    assert!(stderr.contains(expect), "{tag}: expected {expect:?} in\n{}", clip(&stderr));
    assert!(out.stdout.is_empty(), "{tag}: nothing belongs on stdout");
    stderr
}

/// The first 2000 bytes (or fewer, at a char boundary) of a message, for assertion output.
fn clip(s: &str) -> &str {
    let mut end = s.len().min(2000);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
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

/// A bead file with `extra` appended at the top level (before any table header).
fn bead_with_top(extra: &str) -> String {
    format!("{extra}\n{}", bead_with("dot(r, r) = l^2"))
}

#[test]
fn deeply_nested_arrays_and_tables() {
    let n = 100_000;
    let arrays = format!("x = {}{}", "[".repeat(n), "]".repeat(n));
    refused("arrays", bead_with_top(&arrays).as_bytes(), "nests arrays or tables too deeply");
    let inline = format!("x = {}1{}", "{a = ".repeat(n), "}".repeat(n));
    refused("inline-tables", bead_with_top(&inline).as_bytes(), "nests arrays or tables too deeply");
    // The same depth where a value is expected: a parameter, a mass, an `at` state.
    let parameter = bead_with("dot(r, r) = l^2").replace("l = 1.0", &format!("l = {}{}", "[".repeat(n), "]".repeat(n)));
    refused("parameter", parameter.as_bytes(), "too deeply");
}

#[test]
fn deeply_nested_keys() {
    let n = 100_000;
    let dotted = format!("x.{}b = 1", "a.".repeat(n));
    refused("dotted", bead_with_top(&dotted).as_bytes(), "too deeply");
    let header = format!("{}\n[{}b]\nc = 1\n", bead_with("dot(r, r) = l^2"), "a.".repeat(n));
    refused("header", header.as_bytes(), "too deeply");
}

#[test]
fn wide_arrays_are_not_deep() {
    // 200 000 small arrays side by side: wide, not deep; an unknown key, said once.
    let wide = format!("x = [{}]", "[1],".repeat(200_000));
    refused("wide", bead_with_top(&wide).as_bytes(), "unknown key `x` at the top level");
}

#[test]
fn non_finite_and_mistyped_values() {
    let file = bead_with("dot(r, r) = l^2").replace("l = 1.0", "l = nan").replace("m = 1.0", "m = \"one\"");
    let stderr = refused_at_length("nan", file.as_bytes(), "must be a finite number, found nan");
    assert!(stderr.contains("found a string") && stderr.contains("2 problems"), "{stderr}");
}

#[test]
fn empty_file() {
    refused("empty", b"", "dimension");
}

#[test]
fn not_toml() {
    // Every syntax error is reported (here two), each located.
    let stderr = refused_at_length("not-toml", b"this is { not toml ]]\n\x20= =\n", "error");
    assert!(stderr.contains("2 problems") && stderr.contains(":1:6") && stderr.contains(":2:4"), "{stderr}");
}

#[test]
fn many_syntax_errors_are_capped() {
    // A thousand broken lines: a handful of located messages, not a thousand.
    let garbage = "x = = 1\n".repeat(1000);
    let stderr = refused_at_length("garbage", garbage.as_bytes(), "extra `=`");
    let errors = stderr.matches("error: ").count();
    assert!((2..=8).contains(&errors), "{errors} errors shown:\n{}", clip(&stderr));
    assert!(stderr.len() < 4000, "{}", clip(&stderr));
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

/// The library, not only the binary (which runs on a large stack): a user's test calls
/// `Checked::from_text` on an ordinary test thread, and deep input is refused there too.
#[test]
fn deep_input_through_the_library_on_a_small_stack() {
    let n = 100_000;
    let inputs = [
        bead_with_top(&format!("x = {}{}", "[".repeat(n), "]".repeat(n))),
        bead_with_top(&format!("x = {}1{}", "{a = ".repeat(n), "}".repeat(n))),
        bead_with_top(&format!("x.{}b = 1", "a.".repeat(n))),
        bead_with(&format!("{}dot(r, r){} = l^2", "(".repeat(n), ")".repeat(n))),
    ];
    let worker = std::thread::Builder::new()
        .stack_size(1 << 20)
        .spawn(move || {
            inputs
                .iter()
                .map(|text| match lagrange::check::Checked::from_text("deep.toml", text) {
                    Err(lagrange::check::CheckError::Invalid { rendered, .. }) => rendered,
                    Err(other) => panic!("expected validation problems, got {other}"),
                    Ok(_) => panic!("deep input accepted"),
                })
                .collect::<Vec<String>>()
        })
        .expect("thread starts");
    let rendered = worker.join().expect("no stack overflow or panic on a 1 MiB stack");
    for r in &rendered {
        assert!(r.contains("too deeply") || r.contains("nest"), "{}", clip(r));
    }
}

/// Deep expressions wherever the file holds one — a scene force, an expected formula, a
/// definition — are each refused with their place, all in one run.
#[test]
fn deep_expressions_in_every_expression_field() {
    let n = 100_000;
    let file = format!(
        "{}[definitions]\nc = '{}t{}'\n[scene]\nforces = {{ F = '{}r{}' }}\n[[expect]]\nC_dot = {{ wire = '{}1' }}\n",
        bead_with("dot(r, r) = l^2"),
        "sin(".repeat(n / 2),
        ")".repeat(n / 2),
        "(".repeat(n),
        ")".repeat(n),
        "-".repeat(n),
    );
    let stderr = refused_at_length("deep-fields", file.as_bytes(), "3 problems");
    for place in ["in definition `c`", "in the force on `F`", "in the expected `C_dot`"] {
        assert!(stderr.contains(&format!("{place}: expression nested too deeply")), "{place}:\n{}", clip(&stderr));
    }
}

/// `lagrange … | head`: the reader goes away before the output is written. That is not an
/// internal failure; the command finishes with its own exit code.
#[test]
fn closed_standard_output_is_not_a_failure() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .args(["derive", "--steps"])
        .arg(root.join("constraints/chain_5.toml"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("binary runs");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("binary finishes");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "exit {:?}, stderr: {stderr}", out.status.code());
    assert!(stderr.is_empty(), "a closed pipe printed: {stderr}");
}

/// An endless input (`/dev/zero`) and a file past the size limit are refused after reading
/// at most one byte more than the limit: at once, with a bounded amount of memory (before,
/// `/dev/zero` was read until memory ran out).
#[test]
fn endless_and_oversized_inputs_are_refused_while_reading() {
    let started = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).args(["derive", "/dev/zero"]).output().expect("binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("too large"), "{stderr}");
    // Generous: reading 64 MiB takes milliseconds; what this excludes is reading forever.
    assert!(started.elapsed().as_secs() < 30, "took {:?}", started.elapsed());

    let big = vec![b'#'; lagrange::model::file::MAX_FILE_BYTES + 1];
    refused("oversized", &big, "too large");
}

// ---- Work that is not bounded (issue 17): budgets on work, not timers -----------------------
// Each file below is generated here; each run ends because a count runs out (terms of
// canonical forms, bits of coefficients, bytes of a document), never because of a clock.

/// `lagrange ARGS… FILE` on `text`: exit code, stdout, stderr.
fn run_on(tag: &str, text: &str, args: &[&str]) -> (Option<i32>, String, String) {
    let file = TempFile::new(tag, text.as_bytes());
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).args(args).arg(&file.0).output().expect("binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A bead file with `[definitions]` `defs` and the constraint `expr`.
fn bead_with_definitions(defs: &[(String, String)], expr: &str) -> String {
    let mut text = bead_with(expr);
    let table: String = defs.iter().map(|(k, v)| format!("{k} = \"{v}\"\n")).collect();
    text = text.replacen("[[bodies]]", &format!("[definitions]\n{table}[[bodies]]"), 1);
    text
}

/// `n` bodies `b1…bn` (positions `r1…rn`) and one constraint `expr`.
fn bodies_with(n: usize, expr: &str) -> String {
    let mut text = String::from("title = \"many\"\ndimension = 2\n[parameters]\nm = 1.0\n");
    for i in 1..=n {
        text += &format!(
            "[[bodies]]\nname = \"b{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\nmass = \"m\"\nforce = \"F{i}\"\n"
        );
    }
    text + &format!("[[constraints]]\nname = \"all\"\nexpr = \"{expr}\"\n")
}

#[test]
fn a_formula_past_the_work_budget_is_refused_by_its_constraint() {
    // d_i = sin(d_{i-1}) d_{i-1} + d_{i-1}², twelve deep: C̈ passes 200 000 terms of work
    // (it used to take > 20 s and 2 GB).
    let mut defs = vec![("d0".to_string(), "r.x".to_string())];
    for i in 1..=12 {
        defs.push((format!("d{i}"), format!("sin(d{j})*d{j} + d{j}^2", j = i - 1)));
    }
    let (code, stdout, stderr) = run_on("definitions12", &bead_with_definitions(&defs, "d12 = 0"), &["derive"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stdout.is_empty());
    assert!(stderr.contains("constraint `wire` is too large to derive"), "{stderr}");
    assert!(stderr.contains("\"Limits\"") && stderr.lines().count() <= 3, "{stderr}");
}

#[test]
fn a_document_past_its_budget_is_refused_not_written() {
    // One constraint summing 2 000 dot(rᵢ, rᵢ): each body's closed-form force repeats λ
    // (175 MB of text before); the document's budget is 16 MiB + 4 KiB per body.
    let sum: Vec<String> = (1..=2000).map(|i| format!("dot(r{i}, r{i})")).collect();
    let text = bodies_with(2000, &format!("{} = 1", sum.join(" + ")));
    for format in ["text", "json"] {
        let (code, stdout, stderr) = run_on("dots2000", &text, &["derive", "--format", format]);
        assert_eq!(code, Some(1), "{format}: {stderr}");
        assert!(stdout.is_empty(), "{format}: no half document");
        assert!(stderr.contains("the document is too large to print"), "{format}: {stderr}");
    }
}

#[test]
fn exact_powers_and_long_chains_end_with_a_result() {
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        // Powers past 4 096 bits stay powers: nothing computes 3^1000000.
        ("pow3", bead_with("r.x - 3^1000000 = 0"), vec!["derive"]),
        ("pow23", bead_with("r.x - (2/3)^100000 = 0"), vec!["derive"]),
        // (r.y + 1.827 r.x)^-100000: no 1.827^100000 is expanded (> 60 s before).
        ("negpow", bead_with("(r.y + 1.827*r.x)^-100000 = 1"), vec!["derive"]),
        ("negpow_gen", bead_with("(r.y + 1.827*r.x)^-100000 = 1"), vec!["generate", "--specialize"]),
        // 60 nested square roots.
        ("sqrt60", bead_with(&format!("{}r.x^2 + 1{} = 2", "sqrt(".repeat(60), ")".repeat(60))), vec!["derive"]),
    ];
    for (tag, text, args) in cases {
        let (code, stdout, stderr) = run_on(tag, &text, &args);
        assert_eq!(code, Some(0), "{tag}: {stderr}");
        assert!(!stdout.is_empty() && stdout.len() < 4 << 20, "{tag}: {} bytes", stdout.len());
    }
    let (_, stdout, _) = run_on("pow3_doc", &bead_with("r.x - 3^1000000 = 0"), &["derive"]);
    assert!(stdout.contains("C = r.x − 3¹⁰⁰⁰⁰⁰⁰"), "{stdout}");
    // 3 000 chained aliases d_i = d_{i-1}, unused: linear, and the document lists none of them.
    let mut defs = vec![("d0".to_string(), "r.x".to_string())];
    for i in 1..=3000 {
        defs.push((format!("d{i}"), format!("d{}", i - 1)));
    }
    let (code, stdout, stderr) = run_on("aliases", &bead_with_definitions(&defs, "dot(r, r) = l^2"), &["derive"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(!stdout.contains("d1 =") && stdout.len() < 2000, "{stdout}");
}
