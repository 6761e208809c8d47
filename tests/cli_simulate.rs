//! The `simulate` and `bench` commands end to end: outputs, JSON shape, failures.

use std::path::PathBuf;
use std::process::Command;

fn lagrange(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_lagrange")).args(args).output().expect("runs")
}

/// `simulate FILE ARGS… --format json --csv DIR/run.csv --plot DIR/run.svg` in a fresh
/// directory named by `tag`: the output, the directory, the CSV and the SVG paths.
fn simulate_with_files(tag: &str, file: &str, args: &[&str]) -> (std::process::Output, PathBuf, PathBuf, PathBuf) {
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-cli-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let (csv, svg) = (dir.join("run.csv"), dir.join("run.svg"));
    let mut all = vec!["simulate", file];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--format", "json", "--csv", csv.to_str().expect("utf-8")]);
    all.extend_from_slice(&["--plot", svg.to_str().expect("utf-8")]);
    (lagrange(&all), dir, csv, svg)
}

#[test]
fn simulate_prints_the_json_summary_and_writes_csv_and_svg() {
    let (out, dir, csv, svg) =
        simulate_with_files("pendulum", "constraints/pendulum.toml", &["--steps", "1000", "--every", "10"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    for key in ["steps", "duration", "wall_seconds", "max_abs_C", "max_abs_C_dot", "energy_rel_drift", "final"] {
        assert!(json.get(key).is_some(), "missing {key}");
    }
    assert_eq!(json["steps"], 1000);
    assert_eq!(json["final"]["r"].as_array().map(Vec::len), Some(2));
    let text = std::fs::read_to_string(&csv).expect("csv");
    assert_eq!(text.lines().next(), Some("t,r.x,r.y,v.x,v.y,lambda_rod,C_rod,Cdot_rod"));
    assert_eq!(text.lines().count(), 1 + 101);
    assert!(std::fs::read_to_string(&svg).expect("svg").contains("</svg>"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_run_that_blows_up_names_step_and_constraint_and_keeps_its_csv() {
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-cli-fail-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let csv = dir.join("run.csv");
    // Euler without stabilisation at a huge step: the rod stretches past the scene's size.
    let out = lagrange(&[
        "simulate",
        "constraints/pendulum.toml",
        "--integrator",
        "euler",
        "--stabilize",
        "none",
        "--dt",
        "0.2",
        "--steps",
        "1000",
        "--csv",
        csv.to_str().expect("utf-8"),
    ]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("step ") && stderr.contains("`rod`"), "{stderr}");
    let text = std::fs::read_to_string(&csv).expect("csv kept");
    assert!(text.lines().count() >= 2, "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn simulate_rejects_bad_settings_before_running() {
    let out = lagrange(&["simulate", "constraints/pendulum.toml", "--dt=-1"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("step must be finite and positive"));
    // A drift-control flag out of range is refused whichever --stabilize runs: a typo never
    // passes silently (as the velocity-level flags, checked whichever --solver runs).
    for (args, message) in [
        (&["--zeta", "-1"][..], "ζ (--zeta) must be finite and at least 0, found -1"),
        (&["--zeta", "-1", "--stabilize", "baumgarte"][..], "ζ (--zeta) must be finite and at least 0, found -1"),
        (&["--omega-dt", "2"][..], "ω·dt (--omega-dt) must lie in (0, 1], found 2"),
        (&["--tolerance", "0", "--stabilize", "none"][..], "(--tolerance) must be finite and positive, found 0"),
        (&["--tolerance", "inf", "--solver", "pgs"][..], "(--tolerance) must be finite and positive, found inf"),
        // Every 0th step was every step, silently.
        (&["--every", "0", "--csv", "never-written.csv"][..], "invalid value '0' for '--every <EVERY>'"),
    ] {
        let mut all = vec!["simulate", "constraints/pendulum.toml", "--steps", "10"];
        all.extend_from_slice(args);
        let out = lagrange(&all);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(message),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.stdout.is_empty(), "{args:?}: nothing ran");
    }
}

#[test]
fn bench_prints_rows_as_json() {
    let out = lagrange(&[
        "bench",
        "constraints/bead_on_wire.toml",
        "--duration",
        "0.05",
        "--states",
        "10",
        "--format",
        "json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert!(json["rows"].as_array().map_or(0, Vec::len) >= 12);
    assert!(json["accuracy"].as_array().map_or(0, Vec::len) >= 2);
}

/// Each run of the sweep is shown once: step sizes that give the duration the same number of
/// steps are one run (a duration of one step gave four equal rows per method), and a note
/// says so; a duration that separates them still shows all four.
#[test]
fn bench_shows_each_run_once() {
    // dt = 1e-3: the step sizes 4e-3, 2e-3, 1e-3 and 5e-4 give 1, 1, 1, 1 steps in 1e-4,
    // 1, 1, 2, 3 in 1.5e-3, and 1, 2, 3, 6 in 3e-3.
    for (duration, runs) in [("0.0001", 1), ("0.0015", 3), ("0.003", 4)] {
        let out = lagrange(&[
            "bench",
            "constraints/pendulum.toml",
            "--duration",
            duration,
            "--states",
            "10",
            "--format",
            "json",
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{stderr}");
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        let rows = json["rows"].as_array().expect("rows");
        let mut seen = std::collections::HashSet::new();
        for row in rows {
            let key = (row["integrator"].to_string(), row["stabilize"].to_string(), row["steps"].to_string());
            assert!(seen.insert(key.clone()), "duration {duration}: {key:?} twice");
        }
        assert_eq!(rows.len(), 9 * runs, "duration {duration}: {rows:#?}");
        assert_eq!(stderr.contains("each distinct run is shown once"), runs < 4, "{stderr}");
    }
}

#[test]
fn a_pendulum_of_1e155_metres_runs_in_its_own_unit_and_plots() {
    let (out, dir, csv, svg) = simulate_with_files("huge", "constraints/hard/huge.toml", &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(json["steps"], 1000);
    assert_eq!(json["unit_exponent"], 518);
    // The CSV is in metres: the last row's r.x is about −0.986 × 1e155.
    let text = std::fs::read_to_string(&csv).expect("csv");
    let last: Vec<f64> = text.lines().last().expect("rows").split(',').map(|x| x.parse().expect("a number")).collect();
    assert!((last[1] / 1e155 + 0.986).abs() < 1e-3, "{last:?}");
    assert!(std::fs::read_to_string(&svg).expect("svg").contains("</svg>"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two independent pendulums of sizes 1e200 and 1: one unit cannot hold both (the small bob
/// left its rod, |r| = 3.45, while the summary said max |C| = 0). `simulate` refuses the
/// scene before the first step, with exit 2 and no summary.
#[test]
fn simulate_refuses_parts_no_one_unit_can_hold() {
    let scene = r#"title = "Two pendulums far apart in size"
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
initial = { R = [1e200, 0.0], V = [0.0, 0.0], r = [1.0, 0.0], v = [0.0, 1.0] }
forces = { G = "[0, 0]", F = "[0, 0]" }
dt = 1e-3
duration = 1.0
"#;
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lagrange-cli-two-scales-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("two_scales.toml");
    std::fs::write(&path, scene).expect("write");
    let out = lagrange(&["simulate", path.to_str().expect("utf-8")]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("independent parts differ in size") && err.contains("2^0 and 2^664"), "{err}");
    assert!(out.stdout.is_empty(), "{}", String::from_utf8_lossy(&out.stdout));
}

/// `bench`'s ns/eval of a closed form times the interpreter; the table says so, so it is not
/// read as the speed of the compiled tape users run (issue 14: 5 204 ns beside the README's
/// 20–30 ns for the tape).
#[test]
fn bench_says_what_ns_per_eval_times() {
    let out = lagrange(&["bench", "constraints/pendulum.toml", "--duration", "0.05", "--states", "10"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("closed form") && text.contains("ns/eval of `closed form`: the interpreter"), "{text}");
}

/// `simulate` from a state off the constraint says by how much before the run projects it
/// (r = [2.1, 0] on a wire of l = 2, v with a radial part), naming the constraint.
#[test]
fn simulate_says_how_far_off_the_initial_state_is() {
    let bead = std::fs::read_to_string("constraints/bead_on_wire.toml").expect("file");
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-cli-off-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let path = dir.join("off.toml");
    let off =
        bead.replace("initial = { r = [2.0, 0.0], v = [0.0, 1.0] }", "initial = { r = [2.1, 0.0], v = [0.5, 1.0] }");
    assert_ne!(off, bead, "the scene line to replace");
    std::fs::write(&path, off).expect("write");
    let out = lagrange(&["simulate", path.to_str().expect("utf-8"), "--steps", "10"]);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    // |C|/‖∇C‖ = (2.1² − 4)/(2 · 2.1); |Ċ|/‖∇C‖ = |r·v|/|r| = 0.5.
    assert!(
        stderr.contains("note: initially the state is off constraint `wire`: distance |C|/‖∇C‖ = 9.762e-2"),
        "{stderr}"
    );
    assert!(
        stderr.contains("speed off it |Ċ|/‖∇C‖ = 5.000e-1") && stderr.contains("the first step projects it"),
        "{stderr}"
    );
    let on = lagrange(&["simulate", "constraints/bead_on_wire.toml", "--steps", "10"]);
    assert!(on.status.success() && !String::from_utf8_lossy(&on.stderr).contains("off constraint"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scene at rest has a kinetic energy of rounding size: its energy balance is measured
/// against the forces' work scale Σ|F|·size (it read 1.5e15 against the kinetic energy of
/// Catto's two particles hanging still, and 1.0 for the exact velocity solve).
#[test]
fn a_scene_at_rest_reports_its_energy_balance_against_the_work_scale() {
    for solver in [None, Some("exact-velocity")] {
        let mut args = vec!["simulate", "constraints/solvers/two_particles.toml", "--steps", "20"];
        args.extend(solver.iter().flat_map(|s| ["--solver", *s]));
        let out = lagrange(&[&args[..], &["--format", "json"]].concat());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        let drift = json["energy_rel_drift"].as_f64().expect("reported");
        assert!(drift <= 1e-12, "{solver:?}: energy balance {drift:e} of the scale");
        let text = lagrange(&args);
        assert!(String::from_utf8_lossy(&text.stdout).contains("of the energy scale"), "{solver:?}");
    }
}

/// A large scene's text summary names the first symbols of its final state and how many
/// more there are, not a line of every body (the JSON has them all).
#[test]
fn a_large_scene_text_summary_keeps_its_final_line_short() {
    let file = "constraints/solvers/rigid_grid_10.toml";
    let out = lagrange(&["simulate", file, "--solver", "soft-step", "--steps", "2"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    let last = text.lines().last().expect("a final line");
    assert!(last.contains("and 344 more (all of them: --format json or --csv)"), "{last}");
    assert!(last.len() < 2000, "{} bytes", last.len());
    let json = lagrange(&["simulate", file, "--solver", "soft-step", "--steps", "2", "--format", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&json.stdout).expect("json");
    assert_eq!(json["final"].as_object().map(|o| o.len()), Some(360));
}

/// `simulate FILE --steps N --format json ARGS…`: the JSON summary (the run must succeed).
fn summary(file: &str, steps: &str, args: &[&str]) -> serde_json::Value {
    let mut all = vec!["simulate", file, "--steps", steps, "--format", "json"];
    all.extend_from_slice(args);
    let out = lagrange(&all);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("json")
}

#[test]
fn simulate_starts_from_set_and_at_values_as_an_edited_file_would() {
    // `--set` over the file's values runs the scene the edited file describes, bit for bit.
    let text = std::fs::read_to_string("constraints/pendulum.toml").expect("file");
    let edited = text.replace("l = 1.0", "l = 2.0").replace("r = [1.0, 0.0]", "r = [2.0, 0.0]");
    assert_ne!(edited, text);
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-cli-set-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let (file, state) = (dir.join("long.toml"), dir.join("state.json"));
    std::fs::write(&file, edited).expect("write");
    std::fs::write(&state, r#"{"r": [2.0, 0.0]}"#).expect("write");
    let from_file = summary(file.to_str().expect("utf-8"), "500", &[]);
    let from_set = summary("constraints/pendulum.toml", "500", &["--set", "l=2", "--set", "r=[2,0]"]);
    let from_at =
        summary("constraints/pendulum.toml", "500", &["--at", state.to_str().expect("utf-8"), "--set", "l=2"]);
    assert_eq!(from_set["final"], from_file["final"]);
    assert_eq!(from_at["final"], from_file["final"]);
    assert_ne!(from_set["final"], summary("constraints/pendulum.toml", "500", &[])["final"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_force_or_torque_given_by_set_replaces_the_scenes_expression() {
    // The pendulum's scene pulls with F = m g; given F = 0 it stays where it was released.
    let still = summary("constraints/pendulum.toml", "200", &["--set", "F=[0,0]"]);
    assert_eq!(still["final"]["r"], serde_json::json!([1.0, 0.0]));
    assert_eq!(still["final"]["v"], serde_json::json!([0.0, 0.0]));
    // The revolute joint's scene turns body a with T1 = 0.2 N m; given T1 = 0 nothing moves,
    // with the acceleration-level solve and with an engine's step alike.
    for solver in ["exact", "soft-step"] {
        let run = summary("constraints/joints/revolute.toml", "100", &["--solver", solver, "--set", "T1=0"]);
        assert_eq!(run["final"]["w1"], 0.0, "{solver}");
        assert_eq!(run["final"]["x2"], serde_json::json!([1.0, 0.0]), "{solver}");
        let turning = summary("constraints/joints/revolute.toml", "100", &["--solver", solver]);
        assert!(turning["final"]["w1"].as_f64().is_some_and(|w| w > 0.0), "{solver}: {turning}");
    }
}

#[test]
fn simulate_refuses_a_bad_set_or_at_before_running() {
    for (args, says) in [
        (&["--set", "nosuch=1"][..], "`nosuch` is not a symbol"),
        (&["--set", "l"][..], "--set l"),
        (&["--set", "m=-1"][..], "m"),
        // Refused as in the file: 1/m of a subnormal mass overflows (it used to stop the run
        // at step 0 with a body "not finite").
        (&["--set", "m=1e-320"][..], "`bob` = 1e-320 (a subnormal number: 1/m overflows)"),
        (&["--at", "no/such/state.toml"][..], "cannot read"),
    ] {
        let mut all = vec!["simulate", "constraints/pendulum.toml", "--steps", "10"];
        all.extend_from_slice(args);
        let out = lagrange(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(out.stdout.is_empty(), "{args:?}: ran anyway");
    }
}

/// A run that overflows at its first step (dt = 1e300): the error gives the time in
/// scientific notation (not three hundred digits), the JSON summary says why the run
/// stopped beside the final state's `null`, and the text writes that number as `inf` or
/// `NaN` rather than `null`.
#[test]
fn a_run_stopped_by_an_overflow_says_why_its_final_state_is_not_finite() {
    for solver in ["exact", "exact-velocity"] {
        let args = ["simulate", "constraints/pendulum.toml", "--solver", solver, "--dt", "1e300", "--steps", "3"];
        let out = lagrange(&[&args[..], &["--format", "json"]].concat());
        assert_eq!(out.status.code(), Some(2), "{solver}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains("`rod`") && (stderr.contains("e299") || stderr.contains("e300")), "{stderr}");
        assert!(!stderr.contains("000000000000"), "{stderr}");
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        let stopped = json["stopped"].as_str().unwrap_or_default();
        assert!(stopped.contains("`rod`") && stderr.contains(stopped), "{json}");
        let finals: Vec<&serde_json::Value> = json["final"]["r"].as_array().into_iter().flatten().collect();
        assert!(finals.iter().any(|x| x.is_null()), "the overflow is in the final state: {json}");

        let text = lagrange(&args);
        assert_eq!(text.status.code(), Some(2), "{solver}");
        let stdout = String::from_utf8_lossy(&text.stdout);
        let last = stdout.lines().find(|l| l.trim_start().starts_with("final:")).unwrap_or_default();
        assert!(!last.contains("null") && (last.contains("inf") || last.contains("NaN")), "{stdout}");
    }
    // A run that ends well has no "stopped".
    let out = lagrange(&["simulate", "constraints/pendulum.toml", "--steps", "3", "--format", "json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert!(json.get("stopped").is_none(), "{json}");
}

#[test]
fn a_projection_that_cannot_reach_its_tolerance_is_reported() {
    // l = 0 turns the rod into dot(r, r) = 0, whose gradient 2r vanishes where it holds:
    // Newton crawls towards r = 0 and never reaches the tolerance.
    let out = lagrange(&["simulate", "constraints/pendulum.toml", "--set", "l=0", "--steps", "200"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("did not reach its tolerance") && text.contains("in 200 of 200 steps"), "{text}");
    let json = summary("constraints/pendulum.toml", "200", &["--set", "l=0"]);
    let u = &json["unconverged"];
    assert_eq!(u["steps"], 200, "{json}");
    assert_eq!(u["first_step"], 1, "{json}");
    assert!(u["max_distance"].as_f64().expect("a number") > 1e6 * u["tolerance"].as_f64().expect("a number"), "{json}");
    // The exact velocity solve projects after each substep, and says so too.
    let json = summary("constraints/pendulum.toml", "200", &["--set", "l=0", "--solver", "exact-velocity"]);
    let u = &json["unconverged"];
    assert_eq!((&u["steps"], &u["first_step"]), (&200.into(), &1.into()), "{json}");
    assert!(u["max_distance"].as_f64().expect("a number") > u["tolerance"].as_f64().expect("a number"), "{json}");
    // The pendulum as written reaches it at every step: no key, no warning.
    for solver in ["exact", "exact-velocity"] {
        let json = summary("constraints/pendulum.toml", "2000", &["--solver", solver]);
        assert!(json.get("unconverged").is_none(), "{solver}: {json}");
        let out = lagrange(&["simulate", "constraints/pendulum.toml", "--steps", "2000", "--solver", solver]);
        assert!(!String::from_utf8_lossy(&out.stdout).contains("warning"), "{solver}");
    }
}

/// The stack of `constraints/solvers/stack.toml` (floor, then two disc contacts) stays at
/// rest under `simulate`'s RATTLE step: its contacts are on their surfaces to the projection's
/// tolerance at every step, their velocities at rounding, the energy balance at rounding, and
/// each contact carries the weight above it at every step (λ = (mass above)·g = 1020, 1010,
/// 1000 N, by hand). Before: the contact projection corrected one violated contact at a
/// time, pushing its neighbour through (5e-3 m of overlap, a third of the steps
/// unconverged), and the rounding of Ċ at rest counted as opening, so every other step the
/// contacts let go (λ = 0) and the stack fell for a step.
#[test]
fn a_stack_at_rest_stays_on_its_contacts() {
    let (out, dir, csv, _) = simulate_with_files("stack", "constraints/solvers/stack.toml", &["--steps", "600"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert!(json.get("unconverged").is_none(), "{json}");
    assert!(json["max_abs_C"].as_f64().expect("a number") <= 1e-12, "{json}");
    assert!(json["max_abs_C_dot"].as_f64().expect("a number") <= 1e-12, "{json}");
    assert!(json["energy_rel_drift"].as_f64().expect("a number") <= 1e-12, "{json}");
    let text = std::fs::read_to_string(&csv).expect("csv");
    let header: Vec<&str> = text.lines().next().expect("a header").split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let heights = [column("r_bottom.y"), column("r_middle.y"), column("r_top.y")];
    let weights =
        [(column("lambda_floor"), 1020.0), (column("lambda_lower"), 1010.0), (column("lambda_upper"), 1000.0)];
    for line in text.lines().skip(1) {
        let x: Vec<f64> = line.split(',').map(|v| v.parse().expect("a number")).collect();
        for (k, &c) in heights.iter().enumerate() {
            assert!((x[c] - (0.5 + k as f64)).abs() <= 1e-12, "{line}");
        }
        for &(c, weight) in &weights {
            assert!((x[c] - weight).abs() <= 1e-9 * weight, "{line}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The CSV of `path` as its header and its rows of numbers, by time.
fn csv_table(path: &std::path::Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).expect("csv");
    let mut lines = text.lines();
    let header = lines.next().expect("a header").split(',').map(String::from).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().expect("a number")).collect()).collect();
    (header, rows)
}

/// The exact velocity step computes λ only at the steps the CSV writes (`--every`): its
/// rows have λ, the one a run that computes λ at every step writes there. On a chain (no
/// body-space block) the whole row is that run's bit for bit; on the rigid grid, whose
/// other steps take the velocity change alone (`Dynamics::set_velocity_space`), the
/// states part in their last bits and λ agrees to rounding.
#[test]
fn an_exact_velocity_csv_has_lambda_at_its_rows() {
    for (file, bitwise) in
        [("constraints/solvers/hanging_chain.toml", true), ("constraints/solvers/rigid_grid_10.toml", false)]
    {
        let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("lagrange-cli-every-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let run = |every: &str| {
            let csv = dir.join(format!("every{every}.csv"));
            let args = ["simulate", file, "--solver", "exact-velocity", "--steps", "13", "--every", every];
            let out = lagrange(&[&args[..], &["--csv", csv.to_str().expect("utf-8")]].concat());
            assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
            csv_table(&csv)
        };
        let (header, all) = run("1");
        let (header4, some) = run("4");
        assert_eq!(header4, header);
        // Steps 0, 4, 8, 12 and the last, 13.
        assert_eq!(some.len(), 5, "{file}");
        let lambdas: Vec<usize> = (0..header.len()).filter(|&i| header[i].starts_with("lambda_")).collect();
        let largest = all.iter().flat_map(|r| lambdas.iter().map(|&i| r[i].abs())).fold(0.0, f64::max);
        assert!(largest > 0.0, "{file}");
        for (row, step) in some.iter().zip([0, 4, 8, 12, 13]) {
            let full = &all[step];
            assert_eq!(row.len(), full.len(), "{file} step {step}");
            if bitwise {
                assert_eq!(row, full, "{file} step {step}");
            }
            for &i in &lambdas {
                assert!((row[i] - full[i]).abs() <= 1e-12 * largest, "{file} step {step} {}", header[i]);
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
