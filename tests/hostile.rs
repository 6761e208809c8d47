//! Hostile input through the real binary: whatever the file holds, `lagrange derive` ends
//! with a short message on stderr and exit code 1 — never a panic (101), a stack overflow
//! or another signal, never a wall of text. Options that ask for unbounded work
//! (`simulate --duration inf`, `bench --states 100000000`) are refused before any work with
//! exit 2, and `check` ends on constraints that are undefined near its sampled states.

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
        let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
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
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lagrange-hostile-{}-does-not-exist.toml", std::process::id()));
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

    // A 3 GiB file (sparse: no byte of it is written) is refused by its length, unread.
    let sparse = TempFile::new("sparse3g", b"");
    std::fs::OpenOptions::new().write(true).open(&sparse.0).and_then(|f| f.set_len(3 << 30)).expect("a sparse file");
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("derive").arg(&sparse.0).output().expect("binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("too large") && out.stdout.is_empty(), "{stderr}");
}

// ---- files and injection ---------------------------------------------------------------

/// Runs the binary with `args`; returns (exit code, stdout, stderr).
fn run(args: &[&std::ffi::OsStr]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).args(args).output().expect("binary runs");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
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

fn bead_scene() -> String {
    bead_with("dot(r, r) = l^2") + "[scene]\ninitial = { r = [1.0, 0.0], v = [0.0, 1.0] }\n"
}

/// `simulate x.toml --csv x.toml` (or `--plot`, or through a symlink to it) is refused
/// before anything runs, and the constraint file is left as it was.
#[test]
fn outputs_never_overwrite_the_input() {
    let text = bead_scene();
    let file = TempFile::new("overwrite", text.as_bytes());
    let path = file.0.as_os_str();
    for flag in ["--csv", "--plot"] {
        let (code, stdout, stderr) =
            run(&["simulate".as_ref(), path, "--steps".as_ref(), "10".as_ref(), flag.as_ref(), path]);
        assert_eq!(code, Some(2), "{flag}: {stderr}");
        assert!(stderr.contains("is the input file"), "{flag}: {stderr}");
        assert!(stdout.is_empty(), "{flag}: nothing runs: {stdout}");
        assert_eq!(std::fs::read_to_string(&file.0).expect("still there"), text, "{flag}: the input was changed");
    }
    #[cfg(unix)]
    {
        let link = file.0.with_extension("link.csv");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&file.0, &link).expect("a symlink");
        let (code, _, stderr) =
            run(&["simulate".as_ref(), path, "--steps".as_ref(), "10".as_ref(), "--csv".as_ref(), link.as_os_str()]);
        let _ = std::fs::remove_file(&link);
        assert_eq!(code, Some(2), "{stderr}");
        assert_eq!(
            std::fs::read_to_string(&file.0).expect("still there"),
            text,
            "the input was changed through a symlink"
        );
    }
    let (code, _, stderr) = run(&["bench".as_ref(), path, "--plot".as_ref(), path]);
    assert_eq!(code, Some(2), "bench --plot: {stderr}");
    assert_eq!(std::fs::read_to_string(&file.0).expect("still there"), text);
}

/// A CSV that cannot be written is a failed write: exit 1, not 0, and one message, whether
/// the buffer meets the failure when the file is closed (10 steps) or during the run (100 000
/// steps, which stops there), under the exact and a velocity-level solver.
#[test]
fn a_csv_that_cannot_be_written_fails_the_command() {
    if !std::path::Path::new("/dev/full").exists() {
        return;
    }
    let file = TempFile::new("full", bead_scene().as_bytes());
    for steps in ["10", "100000"] {
        for solver in ["exact", "soft-step"] {
            let (code, _, stderr) = run(&[
                "simulate".as_ref(),
                file.0.as_os_str(),
                "--steps".as_ref(),
                steps.as_ref(),
                "--solver".as_ref(),
                solver.as_ref(),
                "--csv".as_ref(),
                "/dev/full".as_ref(),
            ]);
            assert_eq!(code, Some(1), "{steps} steps, {solver}: {stderr}");
            let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
            assert_eq!(errors.len(), 1, "{steps} steps, {solver}: {stderr}");
            assert!(errors[0].starts_with("error: cannot write the CSV /dev/full: "), "{stderr}");
        }
    }
}

/// Names and titles never reach the terminal raw: an ANSI escape and a line break in a
/// constraint's name cannot erase `check`'s FAILED line or print a fake `ok` line.
#[test]
fn names_reach_the_terminal_escaped() {
    let name = "wire\\u001b[2K\\r\\nok     fake.toml:1:1: all fine";
    let text = bead_with("dot(r, r) = l^2").replace("name = \"wire\"", &format!("name = \"{name}\""))
        + &format!("[[expect]]\nlambda = {{ \"{name}\" = \"42\" }}\n");
    let file = TempFile::new("escape", text.as_bytes());
    let (code, stdout, stderr) = run(&["check".as_ref(), file.0.as_os_str()]);
    assert_eq!(code, Some(1), "{stdout}{stderr}");
    assert!(!stdout.contains('\u{1b}') && !stderr.contains('\u{1b}'), "{stdout:?}");
    assert!(!stdout.lines().any(|l| l.starts_with("ok")), "a fake ok line:\n{stdout}");
    assert!(stdout.lines().any(|l| l.starts_with("FAILED") && l.contains("\\u{1b}")), "{stdout}");
    // The derivation's documents too.
    let (code, stdout, _) = run(&["derive".as_ref(), file.0.as_os_str()]);
    assert_eq!(code, Some(0));
    assert!(!stdout.contains('\u{1b}'), "{stdout:?}");
}

/// A title with line breaks and HTML stays one heading: no new Markdown block, no raw HTML,
/// and LaTeX's `\section*{…}` on one line.
#[test]
fn a_title_stays_one_heading() {
    let text = bead_with("dot(r, r) = l^2")
        .replace("title = \"hostile\"", "title = \"Bead\\n\\n<script>alert(1)</script>\\n# Not a heading\"");
    let file = TempFile::new("title", text.as_bytes());
    let (code, md, _) = run(&["derive".as_ref(), file.0.as_os_str(), "--format".as_ref(), "markdown".as_ref()]);
    assert_eq!(code, Some(0));
    assert_eq!(md.lines().filter(|l| l.starts_with("# ")).count(), 1, "{md}");
    assert!(md.lines().next().is_some_and(|l| l.contains("Bead") && l.contains("Not a heading")), "{md}");
    assert!(!md.contains("<script"), "{md}");
    let (code, tex, _) = run(&["derive".as_ref(), file.0.as_os_str(), "--format".as_ref(), "latex".as_ref()]);
    assert_eq!(code, Some(0));
    let section = tex.lines().find(|l| l.starts_with("\\section*{")).expect("a section");
    assert!(section.ends_with('}') && section.contains("Not a heading"), "{tex}");
}

/// CSV headers built from names are one record: a `,`, a quote or a line break in a
/// constraint's name is quoted, and a field a spreadsheet would run as a formula is defused.
#[test]
fn csv_headers_quote_and_defuse_names() {
    use lagrange::report::csv::field;
    assert_eq!(field("r.x"), "r.x");
    assert_eq!(field("a,b"), "\"a,b\"");
    assert_eq!(field("say \"hi\"\nthere"), "\"say \"\"hi\"\"\nthere\"");
    for formula in ["=1+2", "+1", "-1", "@SUM(A1)"] {
        assert_eq!(field(formula), format!("'{formula}"), "{formula}");
    }
    let text = bead_scene().replace("name = \"wire\"", "name = \"a,b\\nc\"");
    let file = TempFile::new("csvname", text.as_bytes());
    let csv = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lagrange-hostile-{}-names.csv", std::process::id()));
    let (code, _, stderr) = run(&[
        "simulate".as_ref(),
        file.0.as_os_str(),
        "--steps".as_ref(),
        "2".as_ref(),
        "--csv".as_ref(),
        csv.as_os_str(),
    ]);
    let written = std::fs::read_to_string(&csv).unwrap_or_default();
    let _ = std::fs::remove_file(&csv);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(written.starts_with("t,r.x,r.y,v.x,v.y,\"lambda_a,b\nc\",\"C_a,b\nc\",\"Cdot_a,b\nc\"\n"), "{written}");
}

/// Runs `lagrange args…` from the crate root, killed if it is still running after
/// `seconds`: (exit code, stdout, stderr). A run that had to be killed fails the test.
fn bounded(args: &[&str], seconds: u64) -> (Option<i32>, String, String) {
    use std::io::Read;
    let mut child = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("binary runs");
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if started.elapsed().as_secs() >= seconds {
            let _ = child.kill();
            let _ = child.wait();
            panic!("lagrange {args:?} still running after {seconds} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let (mut out, mut err) = (String::new(), String::new());
    child.stdout.take().expect("stdout").read_to_string(&mut out).expect("UTF-8 stdout");
    child.stderr.take().expect("stderr").read_to_string(&mut err).expect("UTF-8 stderr");
    (status.code(), out, err)
}

/// Step counts that cannot be a run are refused before it starts, with exit 2 and a message
/// saying why: never a run for ever (the count saturating at u64::MAX), never 0 steps with
/// exit 0.
#[test]
fn simulate_refuses_runs_without_a_bounded_step_count() {
    let pendulum = "constraints/pendulum.toml";
    for (flags, expect) in [
        (&["--duration", "inf"][..], "the duration must be finite and positive, found inf"),
        (&["--duration", "nan"], "the duration must be finite and positive, found NaN"),
        (&["--duration", "1e300"], "more than the maximum of 100000000"),
        (&["--dt", "1e-320"], "more than the maximum of 100000000"),
        (&["--steps", "1000000000"], "more than the maximum of 100000000"),
        (&["--dt", "1e300"], "the run would take no step"),
        (&["--solver", "pgs", "--duration", "inf"], "the duration must be finite and positive"),
    ] {
        let (code, out, err) = bounded(&[&["simulate", pendulum][..], flags].concat(), 10);
        assert_eq!(code, Some(2), "{flags:?}: {err}");
        assert!(err.contains(expect), "{flags:?}: {err}");
        assert!(out.is_empty(), "{flags:?}: no summary of a run that never started: {out}");
    }
    // The same for a scene's own dt.
    let text = std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(pendulum)).expect("file");
    let tiny = regex_free_replace(&text, "dt = ", "dt = 1e-320 #");
    let file = TempFile::new("tiny-dt", tiny.as_bytes());
    let (code, _, err) = bounded(&["simulate", file.0.to_str().expect("utf-8")], 10);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("more than the maximum of 100000000"), "{err}");
}

/// `text` with the first line starting with `key` given `replacement` as its start.
fn regex_free_replace(text: &str, key: &str, replacement: &str) -> String {
    text.lines()
        .map(|l| if l.starts_with(key) { l.replacen(key, replacement, 1) } else { l.to_string() })
        .collect::<Vec<_>>()
        .join("\n")
}

/// `bench` likewise: a sweep whose reference run has no bounded step count, a NaN duration
/// and a state count that would exhaust memory are refused at once.
#[test]
fn bench_refuses_unbounded_work() {
    let pendulum = "constraints/pendulum.toml";
    for (flags, expect) in [
        (&["--duration", "1e300"][..], "the reference run would take 3.200e304 steps"),
        (&["--dt", "1e-300"], "the reference run would take 3.200e302 steps"),
        (&["--duration", "nan"], "the duration must be positive, found NaN"),
        (&["--states", "100000000"], "--states must be at most 100000"),
        (&["--solvers", "--duration", "1e300"], "more than the maximum of 100000000"),
    ] {
        let (code, out, err) = bounded(&[&["bench", pendulum][..], flags].concat(), 10);
        assert_eq!(code, Some(2), "{flags:?}: {err}");
        assert!(err.contains(expect), "{flags:?}: {err}");
        assert!(!out.contains("18446744073709551615"), "{flags:?}: {out}");
    }
}

/// `check` at sampled states of constraints that are NaN or whose gradient is infinite
/// somewhere near (`acos`, `sqrt`, `ln`, `asin`): each ends at once with its verdict (exit
/// 1, the expectations are wrong or cannot be judged) — once a panic inside nalgebra's
/// SVD ("Singular value was NaN") and, with three constraints, a run that never returned.
#[test]
fn check_at_sampled_states_of_partly_undefined_constraints_ends() {
    let body = |name: &str, at: &str| {
        format!(
            "[[bodies]]\nname = \"{name}\"\nposition = \"r{at}\"\nvelocity = \"v{at}\"\nacceleration = \"a{at}\"\nmass = \"m\"\nforce = \"F{at}\"\n"
        )
    };
    let constraint = |k: usize, expr: &str| format!("[[constraints]]\nname = \"c{k}\"\nexpr = '{expr}'\n");
    let cases: [(&str, &[&str]); 4] = [
        ("one", &["r.x = 0", "acos(r.y) = 0"]),
        ("one", &["sqrt(r.y) - 1 = 0"]),
        ("one", &["ln(r.x) = 0"]),
        ("two", &["r1.x = 0", "r0.y = 0", "asin(r0.x) = 0"]),
    ];
    for (bodies, exprs) in cases {
        let mut file = String::from("title = \"undefined nearby\"\ndimension = 2\n[parameters]\nm = 1.0\n");
        if bodies == "one" {
            file += &body("b", "");
        } else {
            file += &body("b0", "0");
            file += &body("b1", "1");
        }
        for (k, e) in exprs.iter().enumerate() {
            file += &constraint(k, e);
        }
        let target = if bodies == "one" { "b" } else { "b0" };
        file += &format!("[[expect]]\nforce = {{ {target} = \"[1, 2]\" }}\n");
        let temp = TempFile::new("undefined-nearby", file.as_bytes());
        let (code, out, err) = bounded(&["check", temp.0.to_str().expect("utf-8")], 20);
        assert_eq!(code, Some(1), "{exprs:?}: {out}{err}");
        assert!(!err.contains("panicked") && out.contains("0 passed, 1 failed"), "{exprs:?}: {out}{err}");
    }
}

/// `check` compares values past ~1.4e154 (whose squares overflow) as any others: wrong
/// expectations fail, right ones pass. The bead at r = [2, 0] at rest pushed by F =
/// [−1e200, 0]: λ (C/κ, κ = 2) = −F·r/(r·r) = 5e199, so λ for C as written is 2.5e199 and
/// the force on the bead λ r = [1e200, 0].
#[test]
fn check_compares_huge_values_without_overflow() {
    let state = "at = { r = [2.0, 0.0], v = [0.0, 0.0], F = [-1e200, 0.0] }";
    let entries = [
        ("force = { bead = [1e200, 0.0] }", true),
        ("lambda = { wire = 2.5e199 }", true),
        ("force = { bead = [2e200, 0.0] }", false),
        ("force = { bead = [1e200, 1e199] }", false),
        ("lambda = { wire = -1e300 }", false),
        ("force = { bead = \"1e200*r\" }", false),
        ("force = { bead = \"1e300*r\" }", false),
    ];
    for (entry, right) in entries {
        let file = format!("{}[[expect]]\n{state}\n{entry}\n", bead_with("dot(r, r) = l^2"));
        let temp = TempFile::new("huge-check", file.as_bytes());
        let (code, out, err) = bounded(&["check", temp.0.to_str().expect("utf-8")], 20);
        let verdict = if right { "1 passed, 0 failed" } else { "0 passed, 1 failed" };
        assert!(out.contains(verdict), "{entry}: expected {verdict}:\n{out}{err}");
        assert_eq!(code, Some(if right { 0 } else { 1 }), "{entry}: {out}{err}");
    }
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
    assert!(stderr.contains("\"Limits\"") && stderr.lines().count() <= 8, "{stderr}");
    // Located as file problems are: at the constraint's `expr`, line 29 of the file.
    assert!(stderr.contains(".toml:29:8") && stderr.contains("expr = 'd12 = 0'"), "{stderr}");
}

#[test]
fn a_document_past_its_budget_is_refused_not_written() {
    // A hundred beads, each on its own curve (rᵢ.x + rᵢ.y + 1)²⁴ = 0: every C, Ċ, C̈, A and b
    // is an expanded polynomial of ≈ 170 kB, 17.6 MB in all; the document's budget is
    // 16 MiB + 4 KiB per body and per constraint.
    let mut text = bodies_with(100, "(r1.x + r1.y + 1)^24 = 0");
    for i in 2..=100 {
        text += &format!("[[constraints]]\nname = \"c{i}\"\nexpr = \"(r{i}.x + r{i}.y + 1)^24 = 0\"\n");
    }
    for format in ["text", "json"] {
        let (code, stdout, stderr) = run_on("curves100", &text, &["derive", "--format", format]);
        assert_eq!(code, Some(1), "{format}: {stderr}");
        assert!(stdout.is_empty(), "{format}: no half document");
        assert!(stderr.contains("the document is too large to print"), "{format}: {stderr}");
    }
}

#[test]
fn one_multiplier_shared_by_many_bodies_is_printed_once() {
    // One constraint summing 2 000 dot(rᵢ, rᵢ): each body's force is `λ rᵢ` beside λ's
    // closed form printed once (when each force repeated λ the text was 175 MB, refused by
    // the budget above; now 0.57 MB): the document grows with the bodies, not with their
    // product with λ's size.
    let sum: Vec<String> = (1..=2000).map(|i| format!("dot(r{i}, r{i})")).collect();
    let text = bodies_with(2000, &format!("{} = 1", sum.join(" + ")));
    for format in ["text", "json"] {
        let (code, stdout, stderr) = run_on("dots2000", &text, &["derive", "--format", format]);
        assert_eq!(code, Some(0), "{format}: {stderr}");
        assert!(stdout.len() < 1000 * 2000, "{format}: {} bytes, more than 1 000 a body", stdout.len());
        let force = if format == "text" { "F_c[b2000] = λ r2000\n" } else { "\"b2000\": \"lambda_all*r2000\"" };
        assert!(stdout.contains(force), "{format}: the force on b2000 is not {force:?}");
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

/// Formulas whose work was not bounded by the size of their forms alone: exact divisions of
/// forms far below any size limit (a 3D power of a quotient, nested `atan2`), products of
/// thousands of factors, a power tower whose layout compared ever deeper graphs. Each is
/// now refused by the work meter (term operations charged by the arithmetic and the
/// layout, `expr::work`), naming its constraint, or derived; none runs for seconds more.
#[test]
fn work_inside_the_arithmetic_is_budgeted() {
    let atan2 = (0..6).fold("r.x".to_string(), |e, _| format!("atan2({e}, r.y)"));
    let atan2_8 = (0..8).fold("r.x".to_string(), |e, _| format!("atan2({e}, r.y)"));
    let binomials: Vec<String> = (1..=2000).map(|i| format!("(r.x + {i})")).collect();
    let xs: Vec<String> = (1..=300).map(|i| format!("r{i}.x")).collect();
    let tower = vec!["r.x"; 64].join("^");
    let cases = [
        // > 20 s and 18 MB of output before.
        ("atan2_6", bead_with(&format!("{atan2} = 0")), "wire"),
        // Depth 8: 35 s before.
        ("atan2_8", bead_with(&format!("{atan2_8} = 0")), "wire"),
        // > 30 s in Poly::div_exact before.
        (
            "poly3d",
            bead_with("(r.z + r.y + atan(r.x)/(2 + sin(r.z - r.z^2)))^4 = 0").replace("dimension = 2", "dimension = 3"),
            "wire",
        ),
        // > 120 s before (coefficients of thousands of bits, multiplied term by term).
        ("binomials2000", bead_with(&format!("{} = 1", binomials.join("*"))), "wire"),
        // 2.7 GB before.
        ("product300", bodies_with(300, &format!("{} = 1", xs.join("*"))), "all"),
        // > 30 s before (the layout's comparisons of deep graphs).
        ("tower64", bead_with(&format!("{tower} = 1")), "wire"),
    ];
    for (tag, text, name) in cases {
        let (code, stdout, stderr) = run_on(tag, &text, &["derive"]);
        assert_eq!(code, Some(1), "{tag}: {stderr}");
        assert!(stdout.is_empty(), "{tag}: no half document");
        assert!(stderr.contains(&format!("constraint `{name}` is too large to derive")), "{tag}: {stderr}");
        assert!(!stderr.contains("panicked") && stderr.lines().count() <= 8, "{tag}: {stderr}");
        // At the constraint's `expr` in the file (a long line shown as a window).
        assert!(stderr.contains(".toml:") && stderr.contains("expr = "), "{tag}: {stderr}");
    }
    // `solve` derives first, so it is refused the same way (the 3D power: 17 s before).
    let poly3d =
        bead_with("(r.z + r.y + atan(r.x)/(2 + sin(r.z - r.z^2)))^4 = 0").replace("dimension = 2", "dimension = 3");
    let at = TempFile::new("poly3d-state", b"r = [0.1, 0.2, 0.3]\nv = [0.0, 0.0, 0.0]\nF = [0.0, 0.0, 0.0]\n");
    let (code, stdout, stderr) = run_on("poly3d_solve", &poly3d, &["solve", "--at", at.0.to_str().expect("utf-8")]);
    assert_eq!(code, Some(1), "{stdout}{stderr}");
    assert!(stdout.is_empty() && stderr.contains("constraint `wire` is too large to derive"), "{stderr}");
    // Below the budget the same shapes are derived: 5 nested atan2, 300 binomials.
    let atan2_5 = (0..5).fold("r.x".to_string(), |e, _| format!("atan2({e}, r.y)"));
    let (code, stdout, stderr) = run_on("atan2_5", &bead_with(&format!("{atan2_5} = 0")), &["derive"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stdout.contains("atan2"), "{stdout}");
    let b300: Vec<String> = (1..=300).map(|i| format!("(r.x + {i})")).collect();
    let (code, _, stderr) = run_on("binomials300", &bead_with(&format!("{} = 1", b300.join("*"))), &["derive"]);
    assert_eq!(code, Some(0), "{stderr}");
}

/// `generate` on one constraint summing 2 000 `dot(rᵢ, rᵢ)`: every body's closed-form force
/// in the Rust module repeats λ, so it grew quadratically (665 MB of Rust, > 60 s, 840 MB
/// before). The code's budget (64 MiB and 8 KiB per body and constraint) stops it while it
/// is written. The C module carries the same closed forms (its λ path is the Rust module's,
/// bit for bit), so it is refused the same way.
#[test]
fn generated_code_past_its_budget_is_refused() {
    let sum: Vec<String> = (1..=2000).map(|i| format!("dot(r{i}, r{i})")).collect();
    let text = bodies_with(2000, &format!("{} = 1", sum.join(" + ")));
    let (code, stdout, stderr) = run_on("dots2000gen", &text, &["generate"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stdout.is_empty(), "no half module");
    assert!(stderr.contains("the generated code is too large"), "{stderr}");
    let (code, stdout, stderr) = run_on("dots2000gen_c", &text, &["generate", "--lang", "c"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stdout.is_empty(), "no half module");
    assert!(stderr.contains("the generated code is too large"), "{stderr}");
}

/// 80 bodies with all 3 160 pairwise distances: a coupled block of 3 160 rows over 160
/// unknowns, singular, whose minimum-norm solve is dense (an n³ eigendecomposition, > 60 s
/// before). Past `MAX_DENSE_ROWS` it is refused: status failed, exit 4, saying why.
#[test]
fn a_dense_solve_past_its_size_is_refused() {
    let n = 80;
    let mut text = String::from("title = \"all pairs\"\ndimension = 2\n[parameters]\nm = 1.0\n");
    let mut state = Vec::new();
    for i in 1..=n {
        text += &format!(
            "[[bodies]]\nname = \"b{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\nmass = \"m\"\nforce = \"F{i}\"\n"
        );
        // Bodies on a spiral, at rest, under gravity.
        let (a, radius) = (i as f64 * 0.7, 1.0 + i as f64 * 0.1);
        state.push(format!(
            "r{i} = [{}, {}]\nv{i} = [0.0, 0.0]\nF{i} = [0.0, -9.81]\n",
            radius * a.cos(),
            radius * a.sin()
        ));
    }
    for i in 1..=n {
        for j in i + 1..=n {
            text += &format!("[[constraints]]\nname = \"d{i}_{j}\"\nexpr = \"norm(r{i} - r{j}) = 1\"\n");
        }
    }
    let at = TempFile::new("pairs-state", state.concat().as_bytes());
    let (code, stdout, stderr) = run_on("pairs80", &text, &["solve", "--at", at.0.to_str().expect("utf-8")]);
    assert_eq!(code, Some(4), "{stdout}{stderr}");
    assert!(stdout.contains("status: failed"), "{stdout}");
    assert!(stdout.contains("too large to solve: 3160 coupled rows"), "{stdout}");
    // The diagnostic names the first rows and the count, not 3 160 names.
    let line = stdout.lines().find(|l| l.contains("too large to solve")).unwrap_or_default();
    assert!(line.len() < 400 && line.contains("… (3160 in all)"), "{line}");
}
