//! `lagrange solve` end to end: the JSON shape, its consistency with `derive --format json`,
//! states from `--at` and `--set`, and the errors for missing and non-finite values.

use serde_json::Value;
use std::process::{Command, Output};

fn lagrange(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_lagrange")).args(args).output().expect("runs")
}

fn stdout_json(out: &Output) -> Value {
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(|x| x.as_f64().expect("number")).collect()
}

fn temp_file(name: &str, text: &str) -> std::path::PathBuf {
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-cli-solve-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write");
    path
}

#[test]
fn json_has_the_documented_shape_and_matches_derive() {
    let out = lagrange(&[
        "solve",
        "constraints/bead_on_wire.toml",
        "--set",
        "r=[1.2,-1.6]",
        "--set",
        "v=[1.6, 1.2]",
        "--format",
        "json",
    ]);
    let v = stdout_json(&out);
    assert_eq!(v["t"].as_f64(), Some(0.0));
    assert_eq!(v["status"], "solved");
    let c = &v["constraints"][0];
    for key in ["name", "kind", "value", "rate", "lambda", "active"] {
        assert!(c.get(key).is_some(), "missing {key}");
    }
    assert_eq!(
        (c["name"].as_str(), c["kind"].as_str(), c["active"].as_bool()),
        (Some("wire"), Some("equality"), Some(true))
    );
    assert!(v["diagnostics"].as_array().expect("array").is_empty());
    // λ refers to C/κ like derive's gradient: force = λ·gradient, and derive's gradient is r.
    let derived = stdout_json(&lagrange(&["derive", "constraints/bead_on_wire.toml", "--format", "json"]));
    assert_eq!(derived["constraints"][0]["gradient"]["bead"], "r");
    let lambda = c["lambda"].as_f64().expect("number");
    let force = numbers(&v["forces"]["bead"]);
    let (r, vel, m, g) = ([1.2, -1.6], [1.6, 1.2], 1.0, -9.81);
    for d in 0..2 {
        assert!((force[d] - lambda * r[d]).abs() <= 1e-12 * force[d].abs().max(1.0));
    }
    // The article: λ = −(m v·v + F·r)/(r·r).
    let want = -(m * (vel[0] * vel[0] + vel[1] * vel[1]) + m * g * r[1]) / (r[0] * r[0] + r[1] * r[1]);
    assert!((lambda - want).abs() <= 1e-12 * want.abs(), "{lambda} vs {want}");
    let a = numbers(&v["accelerations"]["bead"]);
    assert!((a[1] - (force[1] + m * g) / m).abs() <= 1e-12 * 10.0);
}

#[test]
fn state_files_in_toml_and_json() {
    let toml = temp_file("state.toml", "r = [0.0, -2.0]\nv = [3.0, 0.0]\nt = 1.5\n");
    let json = temp_file("state.json", r#"{"r": [0.0, -2.0], "v": [3.0, 0.0], "t": 1.5}"#);
    for path in [&toml, &json] {
        let v = stdout_json(&lagrange(&[
            "solve",
            "constraints/bead_on_wire.toml",
            "--at",
            path.to_str().expect("utf-8"),
            "--format",
            "json",
        ]));
        assert_eq!(v["t"].as_f64(), Some(1.5));
        // At the bottom: tension m v²/l + m g = 4.5 + 9.81 upwards.
        let f = numbers(&v["forces"]["bead"]);
        assert!((f[1] - 14.31).abs() <= 1e-12 * 14.31 && f[0] == 0.0, "{f:?}");
    }
    // --set wins over --at.
    let v = stdout_json(&lagrange(&[
        "solve",
        "constraints/bead_on_wire.toml",
        "--at",
        toml.to_str().expect("utf-8"),
        "--set",
        "v=[0,0]",
        "--format",
        "json",
    ]));
    let f = numbers(&v["forces"]["bead"]);
    assert!((f[1] - 9.81).abs() <= 1e-12 * 9.81, "{f:?}");
}

#[test]
fn bad_state_files_report_the_location() {
    let bad = temp_file("bad.toml", "r = [0.0, -2.0]\nv = [3.0, \n");
    let out = lagrange(&["solve", "constraints/bead_on_wire.toml", "--at", bad.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.toml") && err.contains("line 2"), "{err}");
    let bad = temp_file("bad.json", "{\"r\": [0.0, -2.0],\n \"v\": }");
    let out = lagrange(&["solve", "constraints/bead_on_wire.toml", "--at", bad.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 2"), "{err}");
}

#[test]
fn a_missing_value_is_an_error_naming_the_symbol() {
    let text = std::fs::read_to_string("constraints/bead_on_wire.toml").expect("file");
    let cut = text.find("[scene]").expect("scene");
    let path = temp_file("no_scene.toml", &text[..cut]);
    let out = lagrange(&["solve", path.to_str().expect("utf-8")]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no value for `r`"), "{err}");
    assert!(out.stdout.is_empty());
}

#[test]
fn non_finite_values_are_rejected() {
    for set in ["v=nan", "v=[NaN, 1]", "m=inf", "l=1e999", "v=[1,"] {
        let out = lagrange(&["solve", "constraints/bead_on_wire.toml", "--set", set]);
        assert_eq!(out.status.code(), Some(1), "{set}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("--set") && err.contains(set.split('=').next().expect("name")), "{set}: {err}");
    }
    let out = lagrange(&["solve", "constraints/bead_on_wire.toml", "--set", "m=-1"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("mass must be positive"));
}

#[test]
fn text_table_and_diagnostics_for_a_singular_state() {
    // At the centre with v ≠ 0, C̈ = 0 cannot hold: no answer, exit 4 (the table is printed).
    let out = lagrange(&["solve", "constraints/bead_on_wire.toml", "--set", "r=[0,0]"]);
    assert_eq!(out.status.code(), Some(4), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("status: singular") && text.contains("wire") && text.contains("gradient"), "{text}");
    // The diagnostic names the constraint, not its index.
    assert!(text.contains("- [wire] singular configuration: the gradient of constraint `wire` is zero here"), "{text}");
    let out = lagrange(&["solve", "constraints/floor_rest.toml", "--format", "json"]);
    let v = stdout_json(&out);
    assert_eq!(v["constraints"][0]["contact"], "resting");
    assert!((v["constraints"][0]["lambda"].as_f64().expect("number") - 19.62).abs() < 1e-12);
}

#[test]
fn long_help_documents_every_exit_code() {
    let out = lagrange(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    let table = text.split("Exit codes:").nth(1).expect("an exit-code table in --help");
    for code in ["0  success", "1  bad input", "2  bad settings", "3  internal failure", "4  no answer"] {
        assert!(table.contains(code), "{code} missing from {table}");
    }
}

/// `--help`'s exit codes say what the README's table says, code by code (the same words,
/// once backticks, line breaks and the README's typography — `10⁸`, `100 000` — are set
/// aside), and each claim checked here holds: `--steps 0` runs and exits 0, a duration
/// that gives no step and an output that is the input file exit 2.
#[test]
fn help_and_readme_give_the_same_exit_codes() {
    let normal = |s: &str| {
        let s = s.replace('`', "").replace("10⁸", "10^8").replace("100 000", "100000").replace("\\|", "|");
        s.split_whitespace().collect::<Vec<_>>().join(" ")
    };
    let help = String::from_utf8_lossy(&lagrange(&["--help"]).stdout).into_owned();
    let help = help.split("Exit codes:").nth(1).expect("an exit-code table in --help");
    let mut from_help = Vec::new();
    for line in help.lines().filter(|l| !l.trim().is_empty()) {
        match line.strip_prefix("  ").and_then(|l| l.split_once("  ")) {
            Some((code, text)) if code.len() == 1 => from_help.push((code.to_string(), text.to_string())),
            _ => from_help.last_mut().expect("a code first").1.push_str(line),
        }
    }
    let readme = std::fs::read_to_string("README.md").expect("the README");
    let table = readme.split("Exit codes (also in `lagrange --help`):").nth(1).expect("the README's table");
    let from_readme: Vec<(String, String)> = table
        .lines()
        .skip_while(|l| !l.starts_with("| 0"))
        .take_while(|l| l.starts_with('|'))
        .filter_map(|l| {
            let (code, text) = l.trim_matches('|').split_once('|')?;
            Some((code.trim().to_string(), text.trim().to_string()))
        })
        .collect();
    assert_eq!(from_help.len(), 5, "{from_help:#?}");
    assert_eq!(from_readme.len(), from_help.len(), "{from_readme:#?}");
    for ((code, help), (readme_code, readme)) in from_help.iter().zip(&from_readme) {
        assert_eq!(code, readme_code);
        assert_eq!(normal(help), normal(readme), "exit code {code}");
    }
    let code = |args: &[&str]| lagrange(args).status.code();
    assert_eq!(code(&["simulate", "constraints/pendulum.toml", "--steps", "0"]), Some(0));
    assert_eq!(code(&["simulate", "constraints/pendulum.toml", "--duration", "1e-9"]), Some(2));
    let input =
        temp_file("exit_codes_input.toml", &std::fs::read_to_string("constraints/pendulum.toml").expect("file"));
    let input = input.to_str().expect("utf-8");
    assert_eq!(code(&["generate", input, "-o", input]), Some(2));
}

/// `--set`'s help names every form of value it takes, and each form it names is taken: a
/// number, a 2D and a 3D vector, a 3D orientation's quaternion.
#[test]
fn set_help_names_the_forms_it_takes() {
    for command in ["solve", "simulate", "bench"] {
        let help = String::from_utf8_lossy(&lagrange(&[command, "--help"]).stdout).into_owned();
        let set = help.split("--set <NAME=VALUE>").nth(1).expect("--set in the help");
        let set = set.split("\n\n").next().unwrap_or("").split_whitespace().collect::<Vec<_>>().join(" ");
        for form in ["NAME=NUMBER", "NAME=[x,y]", "[x,y,z]", "NAME=[w,x,y,z]"] {
            assert!(set.contains(form), "{command}: {form} not in {set}");
        }
    }
    let ok = |args: &[&str]| {
        let out = lagrange(args);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    };
    ok(&["solve", "constraints/pendulum.toml", "--set", "r=[0,-1]", "--set", "m=2"]);
    ok(&["solve", "constraints/joints/ball_3d.toml", "--set", "x1=[0,0,0]", "--set", "q1=[0,1,0,0]"]);
}

/// The bead of `bead_on_wire.toml` with its constraint replaced by `expr`.
fn bead_with(name: &str, expr: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string("constraints/bead_on_wire.toml").expect("file");
    let start = text.find("expr = ").expect("an expr line");
    let end = start + text[start..].find('\n').expect("end of line");
    temp_file(name, &format!("{}expr = '{expr}'{}", &text[..start], &text[end..]))
}

/// `solve` on `path` (with `extra` arguments) as text and as JSON: both exit 4, the text
/// says `null` where the JSON has null (never NaN), and every sentence in `expect` is among
/// the diagnostics of both.
fn no_answer(path: &std::path::Path, extra: &[&str], status: &str, expect: &[&str]) {
    let file = path.to_str().expect("utf-8");
    let text = lagrange(&[&["solve", file][..], extra].concat());
    assert_eq!(text.status.code(), Some(4), "{file}: {}", String::from_utf8_lossy(&text.stderr));
    let table = String::from_utf8_lossy(&text.stdout);
    assert!(table.contains(&format!("(status: {status})")), "{table}");
    let numbers = table.split("\ndiagnostics").next().expect("the table");
    assert!(!numbers.contains("NaN") && !numbers.contains("inf"), "{table}");
    assert_eq!(numbers.contains("null"), status == "failed", "{table}");
    let json = lagrange(&[&["solve", file, "--format", "json"][..], extra].concat());
    assert_eq!(json.status.code(), Some(4));
    let v: Value = serde_json::from_slice(&json.stdout).expect("JSON on stdout");
    assert_eq!(v["status"], status);
    let messages: Vec<String> = v["diagnostics"]
        .as_array()
        .expect("diagnostics")
        .iter()
        .map(|d| d["message"].as_str().expect("a message").to_string())
        .collect();
    for e in expect {
        assert!(messages.iter().any(|m| m.contains(e)), "{e:?} not in {messages:#?}");
        assert!(table.contains(e), "{e:?} not in {table}");
    }
    assert!(messages.iter().all(|m| !m.contains("(overflow)")), "{messages:#?}");
}

#[test]
fn atwood_at_the_peg_is_undefined_not_an_overflow() {
    // r1 exactly at the pulley: ∇|r1 − p| = (r1 − p)/|r1 − p| is 0/0.
    let peg = ["--set", "r1=[0,0]", "--set", "r2=[0,-3]"];
    no_answer(
        std::path::Path::new("constraints/atwood.toml"),
        &peg,
        "failed",
        &["its gradient is undefined (NaN: 0/0", "Ċ/κ of `string` is undefined (NaN: 0/0"],
    );
}

#[test]
fn failed_statuses_exit_4_and_name_the_cause() {
    for (tag, expr, expect) in [
        ("exp", "exp(1000)*r.x = 1", "its gradient is beyond f64's range"),
        ("div0", "r.x/0 = 1", "its gradient is beyond f64's range"),
        ("ln0", "ln(0)*r.x = 1", "its gradient is beyond f64's range"),
        ("sqrt", "sqrt(-1 - r.x^2) = 1", "its gradient is undefined (NaN"),
    ] {
        let path = bead_with(&format!("{tag}.toml"), expr);
        no_answer(&path, &[], "failed", &[expect, "left out"]);
    }
    // At the centre the gradient 2r vanishes and C̈ = 0 cannot hold with v ≠ 0.
    no_answer(
        std::path::Path::new("constraints/hard/bead_near_centre.toml"),
        &["--set", "r=[0,0]"],
        "singular",
        &["singular configuration", "cannot hold"],
    );
}

/// κ beyond f64's range either way (1e400 or 1e-400): C/κ and Ċ/κ are numbers (C and 1/κ
/// are not, and C · (1/κ) was NaN), λ and J as usual, κ printed from its digits.
#[test]
fn a_scale_beyond_f64_still_gives_c_over_kappa() {
    // The scene's state: r = [2, 0], v = [0, 1]; C/κ is r.x − 10⁻⁴⁰⁰ (= 2 in f64) or r.x − 1, Ċ/κ = v.x.
    for (name, expr, kappa, value) in [
        ("huge_scale.toml", "r.x*1e400 = 1", "1.000e400", 2.0),
        ("tiny_scale.toml", "r.x*1e-400 = 1e-400", "1.000e-400", 1.0),
    ] {
        let path = bead_with(name, expr);
        let file = path.to_str().expect("utf-8");
        let out = lagrange(&["solve", file]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let table = String::from_utf8_lossy(&out.stdout);
        assert!(!table.contains("NaN") && !table.contains("null") && table.contains(kappa), "{table}");
        let v = stdout_json(&lagrange(&["solve", file, "--format", "json"]));
        let row = &v["constraints"][0];
        assert_eq!(row["value"].as_f64(), Some(value), "{expr}: {row}");
        assert_eq!(row["rate"].as_f64(), Some(0.0), "{expr}: {row}");
        assert_eq!(row["lambda"].as_f64(), Some(0.0), "{expr}: {row}");
    }
}

#[test]
fn a_zero_gradient_that_can_hold_is_an_answer() {
    // At the centre at rest the c term v·v is 0: λ = 0 is exact (status singular, exit 0).
    let out = lagrange(&["solve", "constraints/bead_on_wire.toml", "--set", "r=[0,0]", "--set", "v=[0,0]"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stdout));
    assert!(String::from_utf8_lossy(&out.stdout).contains("status: singular"));
}

/// Two independent pendulums, one of size 1e200 and one of size 1 moving at 1: the unit
/// that holds the big one (2^664) put the small one below f64's range and `solve` said
/// "solved" with its force [0, 0]. Each block is now solved in a unit that fits it.
const TWO_SCALES: &str = r#"title = "Two pendulums far apart in size"
dimension = 2
[parameters]
L = 1e200
l = 1.0
m = 1.0
[[bodies]]
name = "big"
position = "R"
velocity = "V"
acceleration = "A"
mass = "m"
force = "G"
[[bodies]]
name = "small"
position = "r"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"
[[constraints]]
name = "big_rod"
expr = "dot(R,R) = L^2"
[[constraints]]
name = "small_rod"
expr = "dot(r,r) = l^2"
[scene]
initial = { R = [1e200, 0.0], V = [0.0, 1e199], r = [1.0, 0.0], v = [0.0, 1.0] }
forces = { G = "[0, 0]", F = "[0, 0]" }
dt = 1e-3
duration = 1.0
"#;

#[test]
fn independent_parts_of_very_different_size_keep_their_forces() {
    let path = temp_file("two_scales.toml", TWO_SCALES);
    let v = stdout_json(&lagrange(&["solve", path.to_str().expect("utf-8"), "--format", "json"]));
    assert_eq!(v["status"], "solved");
    // Centripetal m v²/l toward the pivot: [−1, 0] for the small bob, [−1e198, 0] for the big.
    let small = numbers(&v["forces"]["small"]);
    assert!((small[0] + 1.0).abs() <= 1e-12 && small[1] == 0.0, "{small:?}");
    let big = numbers(&v["forces"]["big"]);
    assert!((big[0] / 1e198 + 1.0).abs() <= 1e-12 && big[1] == 0.0, "{big:?}");
    let text = v["diagnostics"].to_string();
    assert!(text.contains("the rescaled unit does not fit `small_rod`"), "{text}");
}

#[test]
fn a_huge_parameter_does_not_erase_the_bodies() {
    // --set l=1e200 makes C = r·r − l² overflow, but the force −(m v·v + F·r)/(r·r) r does
    // not depend on l: it is the force at the scene's l (it was [0, 0]).
    let at_scene = stdout_json(&lagrange(&["solve", "constraints/bead_on_wire.toml", "--format", "json"]));
    let huge =
        stdout_json(&lagrange(&["solve", "constraints/bead_on_wire.toml", "--set", "l=1e200", "--format", "json"]));
    assert_eq!(huge["status"], "solved");
    assert_eq!(huge["forces"], at_scene["forces"]);
    assert!(numbers(&huge["forces"]["bead"]).iter().any(|x| *x != 0.0));
    assert!(huge["constraints"][0]["value"].is_null());
}

/// A bead on the wire without `[scene] forces`: its force F is zero, and `solve` says so on
/// stderr (DESIGN: "solve and simulate say which symbols were taken as zero"); a force given
/// in the state, or by the scene, is not mentioned.
#[test]
fn forces_nobody_set_are_said_to_be_zero() {
    let bead = std::fs::read_to_string("constraints/bead_on_wire.toml").expect("file");
    let unforced = temp_file("unforced.toml", &bead.replace("forces = { F = \"m*g\" }", ""));
    let path = unforced.to_str().expect("utf-8");
    let note = "note: the force `F` of `bead` has no value and no [scene] forces expression: taken as zero";
    let out = lagrange(&["solve", path, "--format", "json"]);
    let v = stdout_json(&out);
    assert!(String::from_utf8_lossy(&out.stderr).contains(note), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(numbers(&v["forces"]["bead"])[1], 0.0, "no gravity: the pull is centripetal only");
    let given = lagrange(&["solve", path, "--set", "F=[0,-1]", "--format", "json"]);
    stdout_json(&given);
    assert!(!String::from_utf8_lossy(&given.stderr).contains("taken as zero"));
    let scene = lagrange(&["solve", "constraints/bead_on_wire.toml"]);
    assert!(scene.status.success() && !String::from_utf8_lossy(&scene.stderr).contains("taken as zero"));
}

/// `solve` at a state off the wire names the constraint with |C|/‖∇C‖ (r = [3, 0] on l = 2:
/// C/κ = 5/2, ∇C/κ = r, so 2.5/3) and still answers (exit 0, status solved): the force at
/// that state.
#[test]
fn a_state_off_the_constraint_is_a_diagnostic_with_its_distance() {
    let out = lagrange(&["solve", "constraints/bead_on_wire.toml", "--set", "r=[3,0]", "--format", "json"]);
    let v = stdout_json(&out);
    assert_eq!(v["status"], "solved");
    let d = v["diagnostics"].as_array().expect("array");
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0]["constraints"][0], "wire");
    let message = d[0]["message"].as_str().expect("message");
    assert!(message.contains("off constraint `wire`: distance |C|/‖∇C‖ = 8.333e-1"), "{message}");
}
