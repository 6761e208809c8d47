//! Every constraint file in `constraints/` passes its own `[[expect]]` entries (adding a
//! file adds a check), every file-level invalid file in `constraints/invalid/file_*.toml`
//! is refused with located messages (snapshots), and the checker itself fails when it
//! should: a wrong formula or number fails, a formula equal only on the constraint
//! manifold passes.

use lagrange::check::{CheckError, Checked};
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The `.toml` files of `dir` whose names start with `prefix`, sorted, relative to the root.
fn files(dir: &str, prefix: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(root().join(dir))
        .expect("the directory exists")
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(prefix)))
        .map(|p| Path::new(dir).join(p.file_name().unwrap_or_default()))
        .collect();
    out.sort();
    out
}

fn text(rel: &Path) -> String {
    std::fs::read_to_string(root().join(rel)).expect("readable")
}

#[test]
fn every_constraint_file_passes_its_expectations() {
    let all = files("constraints", "");
    assert!(all.len() >= 14, "expected at least 14 constraint files, found {}", all.len());
    let mut failures = Vec::new();
    for rel in &all {
        let name = rel.display().to_string();
        let mut checked = match Checked::from_text(&name, &text(rel)) {
            Ok(c) => c,
            Err(e) => {
                failures.push(format!("{name}: {e}"));
                continue;
            }
        };
        let outcomes = checked.run();
        if outcomes.is_empty() {
            failures.push(format!("{name}: no [[expect]] entries (every file states what it should derive)"));
        }
        for o in outcomes.iter().filter(|o| !o.passed) {
            failures.push(format!("{name}: {o}"));
        }
    }
    assert!(failures.is_empty(), "{} failing checks:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn file_level_invalid_files_report_every_problem_located() {
    let all = files("constraints/invalid", "file_");
    assert!(all.len() >= 4, "expected the file-level invalid files, found {}", all.len());
    for rel in &all {
        let name = rel.display().to_string();
        let rendered = match Checked::from_text(&name, &text(rel)) {
            Err(CheckError::Invalid { rendered, count, .. }) => {
                assert!(count >= 2, "{name}: each file shows several problems at once, found {count}");
                rendered
            }
            Err(other) => panic!("{name}: expected validation problems, got {other}"),
            Ok(_) => panic!("{name}: an invalid file was accepted"),
        };
        // Every problem is located: `file:line:col`, then a caret under the fault.
        let located = rendered.matches(&format!("{name}:")).count();
        let errors = rendered.matches("error: ").count();
        assert_eq!(located, errors, "{name}: every problem has a location\n{rendered}");
        assert!(rendered.contains('^'), "{name}: carets under the faults\n{rendered}");
        let stem = rel.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_string();
        insta::assert_snapshot!(stem, rendered);
    }
}

/// The "mixed problems" file: problems of every stage — a misspelled table, wrong types, a
/// non-finite number, a missing field, an expression error, a bad scene value, unknown names
/// in an expectation, a bad tolerance — are all reported by one load, in file order.
#[test]
fn mixed_problems_are_all_reported_at_once() {
    let rel = Path::new("constraints/invalid/file_mixed_problems.toml");
    let name = rel.display().to_string();
    let Err(CheckError::Invalid { rendered, count, .. }) = Checked::from_text(&name, &text(rel)) else {
        panic!("{name}: expected validation problems");
    };
    let kinds = [
        "unknown key `paramters` at the top level; did you mean `parameters`?",
        "`l` in [parameters] must be a number or a vector of numbers, found a string",
        "`k` in [parameters] must be a finite number, found nan",
        "body `ring` has no `acceleration`",
        "the mass of body `ring` must be a number or a symbol name (a string), found a table",
        "in constraint `axis`: `dot` takes 2 arguments, found 1",
        "`dt` must be a finite positive number",
        "`vel` is not a symbol of this file",
        "`wier` is not a constraint of this file",
        "`tolerance` must be a positive finite number, found 0",
    ];
    for needle in kinds {
        assert!(rendered.contains(needle), "{needle:?} missing in\n{rendered}");
    }
    assert_eq!(count, kinds.len(), "one message per problem, no follow-on noise:\n{rendered}");
    // In file order: line numbers never decrease.
    let lines: Vec<usize> = rendered
        .lines()
        .filter_map(|l| l.split(&format!("{name}:")).nth(1))
        .filter_map(|rest| rest.split(':').next()?.parse().ok())
        .collect();
    assert_eq!(lines.len(), count);
    assert!(lines.windows(2).all(|w| w[0] <= w[1]), "not in file order: {lines:?}");
}

/// A problem found in one part of a file does not hide the others, nor breed follow-on
/// messages: a body whose velocity is a number still declares its position, so the
/// constraint that uses it is not reported as using an unknown symbol.
#[test]
fn an_unreadable_field_does_not_cascade() {
    let original = text(Path::new(WIRE));
    // The velocity's name was never given, so its uses are unknown; the position's is.
    let changed = original.replacen("velocity = \"v\"", "velocity = 7", 1);
    let Err(CheckError::Invalid { rendered, .. }) = Checked::from_text("x.toml", &changed) else {
        panic!("expected a refusal");
    };
    assert!(rendered.contains("`velocity` of body `bead` must be a string, found an integer"), "{rendered}");
    assert!(!rendered.contains("in constraint `wire`"), "the constraint uses only r:\n{rendered}");
    for (from, to, expect) in [
        ("mass = \"m\"", "mass = { kg = 1 }", "the mass of body `bead` must be a number or a symbol name"),
        ("mass = \"m\"", "mass = nan", "a mass must be a positive finite number, found nan"),
        ("l = 2.0", "l = \"two\"", "`l` in [parameters] must be a number or a vector of numbers, found a string"),
        ("l = 2.0", "l = inf", "`l` in [parameters] must be a finite number, found inf"),
        ("expr = \"dot(r,r) = l^2\"", "expr = 5", "`expr` of constraint `wire` must be a string, found an integer"),
        ("expr = \"dot(r,r) = l^2\"", "expr = \"dot(r) = l^2\"", "in constraint `wire`: `dot` takes 2 arguments"),
    ] {
        assert!(original.contains(from), "{from}");
        let changed = original.replacen(from, to, 1);
        let Err(CheckError::Invalid { rendered, count, .. }) = Checked::from_text("x.toml", &changed) else {
            panic!("{to:?}: expected a refusal");
        };
        assert!(rendered.contains(expect), "{expect:?} missing in\n{rendered}");
        assert_eq!(count, 1, "{to:?}: one problem, no follow-on messages:\n{rendered}");
    }
}

const WIRE: &str = "constraints/bead_on_wire.toml";

#[test]
fn a_wrong_formula_fails_with_the_state_and_both_values() {
    let right = "force = { bead = \"-(m*dot(v,v) + dot(F,r))/l^2 * r\" }";
    let wrong = "force = { bead = \"-(m*dot(v,v) - dot(F,r))/l^2 * r\" }";
    let original = text(Path::new(WIRE));
    assert!(original.contains(right));
    let mut checked = Checked::from_text("wrong.toml", &original.replace(right, wrong)).expect("valid");
    let failed: Vec<_> = checked.run().into_iter().filter(|o| !o.passed).collect();
    assert_eq!(failed.len(), 1, "{failed:?}");
    let detail = &failed[0].detail;
    for needle in ["at the state", "r = [", "v = [", "F = [", "derived  = ", "expected = ", "difference"] {
        assert!(detail.contains(needle), "{needle:?} missing in\n{detail}");
    }
}

#[test]
fn a_wrong_number_fails() {
    let original = text(Path::new(WIRE));
    let right = "force = { bead = [0.0, 5.31] }";
    assert!(original.contains(right));
    let mut checked =
        Checked::from_text("wrong.toml", &original.replace(right, "force = { bead = [0.0, 5.3] }")).expect("valid");
    let failed: Vec<_> = checked.run().into_iter().filter(|o| !o.passed).collect();
    assert_eq!(failed.len(), 1, "{failed:?}");
    assert!(failed[0].label.starts_with("force[bead] at "), "{}", failed[0].label);
    assert!(failed[0].detail.contains("5.31") && failed[0].detail.contains("5.3"), "{}", failed[0].detail);
}

#[test]
fn a_formula_equal_only_on_the_manifold_passes_at_states() {
    let mut checked = Checked::load(WIRE).expect("loads");
    // l² for r·r: not the same rational function, equal wherever the bead is on the wire.
    let on_wire = checked.force("bead", "-(m*dot(v,v) + dot(F,r))/l^2 * r").expect("checked");
    assert!(on_wire.passed, "{on_wire}");
    assert!(on_wire.how.contains("100 random states"), "{}", on_wire.how);
    // Off the manifold the same kind of substitution is wrong: 2 l² is not r·r anywhere on it.
    let off = checked.force("bead", "-(m*dot(v,v) + dot(F,r))/(2*l^2) * r").expect("checked");
    assert!(!off.passed, "{off}");
    // Equal in canonical form needs no states.
    let same = checked.force("bead", "-(dot(F,r) + m*dot(v,v))/dot(r,r) * r").expect("checked");
    assert!(same.passed && same.how.contains("canonical"), "{same}");
}

#[test]
fn the_norm_bead_needs_velocities_on_the_manifold_too() {
    // C = |r| − l has a (r·v)² term in C̈ that vanishes only where Ċ = 0.
    let mut checked = Checked::load("constraints/bead_norm.toml").expect("loads");
    checked.assert_force("bead", "-(m*dot(v,v) + dot(F,r))/dot(r,r) * r");
    let also = checked.force("bead", "-(m*dot(v,v) + dot(F,r) + m*dot(r,v))/dot(r,r) * r").expect("checked");
    assert!(also.passed, "r·v = 0 on the manifold, so this is equal there too: {also}");
}

#[test]
fn the_api_asserts_in_a_few_lines() {
    Checked::load("constraints/pendulum_pivot.toml")
        .expect("loads")
        .assert_force("bob", "-(m*dot(v,v) + dot(F, r - p))/l^2 * (r - p)")
        .assert_lambda("rod", "-(m*dot(v,v) + dot(F, r - p))/(2*l^2)")
        .assert_c_dot("rod", "2*dot(r - p, v)")
        .assert_a("rod", "rod", "4*l^2/m");
    let mut several = Checked::load("constraints/double_pendulum.toml").expect("loads");
    several.assert_b("rod1", "2*dot(r1, F1)/m1 + 2*dot(v1, v1)");
    // No closed form with two constraints: the force is judged against the λ solve.
    let wrong = several.force("lower", "[0, 0]").expect("checked");
    assert!(!wrong.passed && wrong.detail.contains("the λ solve"), "{wrong}");
}

#[test]
fn the_api_refuses_unknown_names_and_bad_expressions() {
    let mut checked = Checked::load(WIRE).expect("loads");
    let e = checked.force("beed", "r").expect_err("unknown body");
    assert!(e.to_string().contains("`beed` is not a body"), "{e}");
    let e = checked.lambda("wire", "dot(r,").expect_err("syntax");
    assert!(matches!(e, CheckError::Expected(_)), "{e}");
    let e = checked.force("bead", "dot(r,r)").expect_err("a scalar force");
    assert!(e.to_string().contains("must be a Vector"), "{e}");
    assert!(matches!(Checked::load("constraints/missing.toml"), Err(CheckError::Read { .. })));
}

#[test]
fn the_check_command_reports_and_exits() {
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_lagrange"))
            .current_dir(root())
            .arg("check")
            .args(args)
            .output()
            .expect("runs");
        (out.status.code(), String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let all: Vec<String> = files("constraints", "").iter().map(|p| p.display().to_string()).collect();
    let args: Vec<&str> = all.iter().map(String::as_str).collect();
    let (code, stdout) = run(&args);
    let last = stdout.lines().last().unwrap_or_default();
    assert_eq!(code, Some(0), "{stdout}");
    assert!(last.ends_with(" passed, 0 failed"), "{last}");

    // A deliberately wrong number in a temporary copy: non-zero exit, the failure located.
    let wrong =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-wrong-{}.toml", std::process::id()));
    std::fs::write(&wrong, text(Path::new(WIRE)).replace("lambda = { wire = 1.3275 }", "lambda = { wire = 1.0 }"))
        .expect("writes");
    let path = wrong.display().to_string();
    let (code, stdout) = run(&[&path]);
    let _ = std::fs::remove_file(&wrong);
    assert_eq!(code, Some(1), "{stdout}");
    assert!(stdout.lines().last().unwrap_or_default().ends_with(" passed, 1 failed"), "{stdout}");
    assert!(stdout.contains(&format!("FAILED {path}:")), "{stdout}");
}

/// An `[[expect]]` entry's `note` is printed with each of its failures (every line of it,
/// indented under the failure), and not with a check that passes.
#[test]
fn the_check_command_shows_the_note_of_a_failed_entry() {
    let wrong = text(Path::new(WIRE))
        .replace(
            "lambda = { wire = 1.3275 }",
            "lambda = { wire = 1.0 }\nnote = \"\"\"\nthe wire pushes up with 5.31\nok not a verdict\"\"\"",
        )
        .replace("lambda = { wire = -1.125 }", "lambda = { wire = -1.125 }\nnote = \"passes: not shown\"");
    let path =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-note-{}.toml", std::process::id()));
    std::fs::write(&path, wrong).expect("writes");
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("check").arg(&path).output().expect("runs");
    let _ = std::fs::remove_file(&path);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    let lines: Vec<&str> = stdout.lines().collect();
    let failed = lines.iter().position(|l| l.starts_with("FAILED ")).expect("a failure");
    let note = lines.iter().position(|l| *l == "  note: the wire pushes up with 5.31").expect(&stdout);
    assert!(note > failed && !lines[failed + 1..note].iter().any(|l| l.starts_with("ok ")), "{stdout}");
    assert_eq!(lines[note + 1], "        ok not a verdict", "{stdout}");
    assert!(!stdout.contains("passes: not shown"), "{stdout}");
}
