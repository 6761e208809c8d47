//! `[definitions]` kept as names: a definition prints as its name in the text, LaTeX and
//! Markdown documents of `derive`, shown once at the top; the JSON's expressions stay
//! self-contained (no definition names); differences keep the orientation the file wrote
//! them in (`r2 − r1`, and so `v2 − v1`, `a2 − a1`, `F2 − F1`).

use std::path::PathBuf;
use std::process::Command;

/// A distance joint in 3D between two bodies, written with the definition `d = r2 - r1`.
const JOINT: &str = r#"
title = "Distance joint"
dimension = 3
[parameters]
l = 1.0
m1 = 1.0
m2 = 2.0
[definitions]
d = "r2 - r1"
unused = "[t, 2*t, 0]"
[[bodies]]
name = "a"
position = "r1"
velocity = "v1"
acceleration = "a1"
mass = "m1"
force = "F1"
[[bodies]]
name = "b"
position = "r2"
velocity = "v2"
acceleration = "a2"
mass = "m2"
force = "F2"
[[constraints]]
name = "rod"
expr = "norm(d) = l"
"#;

/// Writes `text` to a file of this test's own and returns its path.
fn file(name: &str, text: &str) -> PathBuf {
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-definitions-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a scratch directory");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("the file is written");
    path
}

/// `lagrange derive PATH ARGS…`: stdout, after checking success.
fn derive(path: &PathBuf, args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("derive").arg(path).args(args).output().expect("runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("UTF-8")
}

#[test]
fn a_definition_prints_as_its_name_once_defined() {
    let path = file("joint.toml", JOINT);
    let text = derive(&path, &[]);
    for needle in [
        "Definitions (printed by name below)\n  d = r2 − r1\n",
        "C = |d| − l",
        "Ċ = (d·(v2 − v1))/|d|",
        "C̈ = ((v2 − v1)·(v2 − v1) + d·(a2 − a1))/|d| − (d·(v2 − v1))²/|d|³",
        "∇C (∇ wrt r1, body a) = −d/|d|",
        "∇C (∇ wrt r2, body b) = d/|d|",
    ] {
        assert!(text.contains(needle), "{needle:?} missing in\n{text}");
    }
    assert_eq!(text.matches("r2 − r1").count(), 1, "the definition is written out once:\n{text}");
    // The user wrote r2 − r1: no formula turns it round.
    for turned in ["r1 − r2", "v1 − v2", "a1 − a2"] {
        assert!(!text.contains(turned), "{turned:?} in\n{text}");
    }
    // A definition no formula prints is not listed.
    assert!(!text.contains("unused"), "{text}");
    for (format, name) in [("latex", "\\vec{d}"), ("markdown", "\\vec{d}")] {
        let doc = derive(&path, &["--format", format]);
        assert!(doc.contains(&format!("{name} = \\vec{{r}}_{{2}} - \\vec{{r}}_{{1}}")), "{format}:\n{doc}");
        assert!(doc.contains(&format!("\\left\\lVert {name} \\right\\rVert - l")), "{format}:\n{doc}");
    }
    let steps = derive(&path, &["--steps"]);
    assert!(steps.contains("  d = r2 − r1\n") && steps.contains("|d|"), "{steps}");
}

#[test]
fn json_stays_self_contained() {
    let path = file("joint_json.toml", JOINT);
    let json: serde_json::Value = serde_json::from_str(&derive(&path, &["--format", "json"])).expect("JSON");
    let c = &json["constraints"][0];
    assert_eq!(c["C"], "norm(r2 - r1) - l", "{json}");
    assert!(json.get("definitions").is_none(), "{json}");
    let all = json.to_string();
    assert!(!all.contains("norm(d)") && !all.contains("dot(d,"), "{all}");
}
