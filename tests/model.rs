//! Loading a constraint file: what `lagrange::model` promises a user of the library.
//!
//! Definitions are ordered however long their chain of uses; cycles are reported once and
//! nothing that depends on them is reported again. States given on the command line come
//! out as checked values of the file's symbols. The model's modules import in one order.
//!
//! Not here: the messages of invalid files (snapshots in `tests/constraint_files.rs`).

use lagrange::expr::eval::Value;
use lagrange::model::file::{Problem, load};
use lagrange::model::state::{self, Format, StateInputError, ValueError};
use std::fmt::Write;
use std::path::Path;
use std::time::{Duration, Instant};

/// A bead on a wire whose radius is the last of `n` definitions, each using the one before.
fn chain_of_definitions(n: usize, last: &str) -> String {
    let mut text = String::from("dimension = 2\n[definitions]\nd_0 = \"1\"\n");
    for i in 1..n {
        writeln!(text, "d_{i} = \"d_{} + 1\"", i - 1).expect("writes to a string");
    }
    writeln!(text, "d_{n} = \"{last}\"").expect("writes to a string");
    text.push_str(
        "[[bodies]]\nname = \"bead\"\nposition = \"r\"\nvelocity = \"v\"\nacceleration = \"a\"\nmass = 1.0\nforce = \"F\"\n\
         [[constraints]]\nname = \"wire\"\nexpr = \"dot(r, r) = d_0^2\"\n",
    );
    text
}

#[test]
fn a_long_chain_of_definitions_loads_in_linear_time() {
    // Keys sort as text (d_1, d_10, d_100, …), so the file's order is far from the order of
    // use: every definition waits for one written elsewhere.
    let n = 20_000;
    let text = chain_of_definitions(n, &format!("d_{} + 1", n - 1));
    let start = Instant::now();
    let loaded = load(&text).expect("a chain of definitions is a valid file");
    assert!(start.elapsed() < Duration::from_secs(20), "took {:?}", start.elapsed());
    assert!(loaded.system.graph.symbol_named("d_0").is_none(), "a definition is not a symbol");
    assert_eq!(loaded.system.constraints.len(), 1);
}

#[test]
fn a_cycle_at_the_end_of_a_long_chain_is_reported_once() {
    let n = 20_000;
    // d_n uses d_{n-1} (so the whole chain) and itself.
    let text = chain_of_definitions(n, &format!("d_{} + d_{n}", n - 1));
    let problems = load(&text).expect_err("a definition refers to itself");
    let [Problem::Cycle { name, through, .. }] = problems.as_slice() else {
        panic!("one cycle, found {problems:?}");
    };
    assert_eq!((name.as_str(), through.as_str()), (format!("d_{n}").as_str(), format!("d_{n}").as_str()));
}

#[test]
fn the_model_modules_import_in_one_order() {
    // Each module may use only the modules listed before it (the order drawn in
    // `src/model/mod.rs`), so no two import each other, even through a third.
    let order = ["raw", "system", "state", "problem", "keys", "scene", "expect", "document", "file"];
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/model");
    for (at, module) in order.iter().enumerate() {
        let text = std::fs::read_to_string(dir.join(format!("{module}.rs"))).expect("a model module");
        for line in text.lines().filter(|l| l.trim_start().starts_with("use super::") || l.contains("pub use super::"))
        {
            let used = line.split("super::").nth(1).and_then(|r| r.split([':', ';']).next()).unwrap_or("");
            let before =
                order[..at].contains(&used) && !matches!((*module, used), ("scene", "expect") | ("expect", "scene"));
            assert!(before, "`{module}` uses `{used}`, which is not listed before it: {line}");
        }
    }
}

#[test]
fn states_from_the_command_line_are_validated_values() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/bead_on_wire.toml"))
        .expect("the bead");
    let loaded = load(&text).expect("valid");
    let system = &loaded.system;
    let r = system.graph.symbol_named("r").expect("r");
    let given = state::assignment(system, "r=[1, -2]").expect("a vector of two");
    assert_eq!(given, Ok((r, Value::Vector([1.0, -2.0, 0.0]))));
    let m = system.graph.symbol_named("m").expect("m");
    assert_eq!(state::assignment(system, " m = 2.5 "), Ok(Ok((m, Value::Scalar(2.5)))));
    assert_eq!(state::assignment(system, "m"), Err(StateInputError::NoEquals));
    assert_eq!(state::assignment(system, "m=two"), Err(StateInputError::NotAValue("two".into())));
    assert_eq!(state::assignment(system, "v=[1, inf]"), Err(StateInputError::NotAValue("[1, inf]".into())));
    assert_eq!(state::assignment(system, "l=1e999"), Err(StateInputError::NotFinite("l".into())));
    assert_eq!(
        state::assignment(system, "r=[1, 2, 3]"),
        Ok(Err(ValueError::Components { name: "r".into(), dim: 2, found: 3 }))
    );
    assert_eq!(state::assignment(system, "a=[0, 0]"), Ok(Err(ValueError::Acceleration("a".into()))));
    assert!(matches!(
        state::assignment(system, "R=[1, 0]"),
        Ok(Err(ValueError::NotASymbol { suggestion: Some(s), .. })) if s == "r"
    ));
    let toml = state::state_file(system, "r = [0.0, -2.0]\nt = 1.5\n", Format::Toml).expect("a TOML state");
    let json = state::state_file(system, r#"{"t": 1.5, "r": [0.0, -2.0]}"#, Format::Json).expect("a JSON state");
    assert_eq!(toml, json);
    assert_eq!(toml, vec![Ok((r, Value::Vector([0.0, -2.0, 0.0]))), Ok((system.time, Value::Scalar(1.5)))]);
    assert!(matches!(state::state_file(system, "r = [0.0,", Format::Toml), Err(StateInputError::Syntax(_))));
    assert_eq!(state::state_file(system, "m = nan", Format::Toml), Ok(vec![Err(ValueError::NotFinite("m".into()))]));
}

#[test]
fn solve_reports_every_syntax_error_of_a_state_before_a_value_that_does_not_fit() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let at = dir.join("state.toml");
    std::fs::write(&at, "x = 1.0\n").expect("writes the state");
    let solve = |set: &str| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_lagrange"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["solve", "constraints/bead_on_wire.toml", "--at", at.to_str().expect("utf-8"), "--set", set])
            .output()
            .expect("runs lagrange");
        assert_eq!(out.status.code(), Some(1), "{set}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    // `x` in the state file does not fit (no such symbol), but `--set`'s syntax comes first.
    assert_eq!(solve("v=nan"), "error: --set v=nan: `v` must be finite\n");
    assert_eq!(solve("v=[0, 0]"), "error: constraints/bead_on_wire.toml: `x` is not a symbol of this file\n");
    std::fs::remove_dir_all(&dir).expect("removes the temporary directory");
}

/// A mistake is reported once, where it is written, and nothing that follows from it is
/// reported again or said falsely: a constraint without a name leaves the file with
/// [[constraints]], a refused body's symbols are not "unknown" in `[scene]`, a clash
/// inside a body is located at its second field, a mass in quotes at the mass.
#[test]
fn a_mistake_causes_no_follow_on_messages() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/invalid/file_follow_on.toml");
    let text = std::fs::read_to_string(path).expect("the file reads");
    let Err(problems) = load(&text) else { panic!("the file is refused") };
    let messages: Vec<String> = problems.iter().map(ToString::to_string).collect();
    assert_eq!(problems.len(), 4, "{messages:#?}");
    for m in &messages {
        assert!(
            !m.contains("no [[constraints]]") && !m.contains("declares no bodies") && !m.contains("not a symbol"),
            "{m}"
        );
    }
    let at = |p: &Problem| p.span().map(|s| text[s].to_string());
    let line = |needle: &str| problems.iter().find(|p| p.to_string().contains(needle)).and_then(at);
    assert_eq!(line("declared twice (as the position of body `bead` and as the velocity"), Some("\"r\"".into()));
    let clash = problems.iter().find(|p| p.to_string().contains("`r` is declared twice")).and_then(Problem::span);
    assert!(clash.is_some_and(|s| text[..s.start].ends_with("velocity = ")), "{messages:#?}");
    assert_eq!(line("`g` is declared twice"), Some("\"g\"".into()));
    assert_eq!(line("is a number in quotes"), Some("\"0.5\"".into()));
    assert!(messages.iter().any(|m| m.contains("a constraint has no `name`")), "{messages:#?}");
}

/// A body field that cannot be read leaves a placeholder symbol in the model (so the body
/// stays declared), and no message names it: with each symbol field of a rigid body left out
/// in turn, and a scene that names a force the file lacks, every message names only what
/// the file writes, and the unknown force's message says the body has no force symbol.
#[test]
fn no_message_names_a_placeholder() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/rigid/rod_pinned.toml"))
        .expect("the rod");
    let fields =
        ["position", "velocity", "acceleration", "force", "angular_velocity", "angular_acceleration", "torque"];
    for field in fields {
        let without: String =
            text.lines().filter(|l| !l.starts_with(&format!("{field} = "))).map(|l| format!("{l}\n")).collect();
        let without = without.replace("forces = { F = ", "forces = { Q = \"[1, 0]\", F = ");
        let Err(problems) = load(&without) else { panic!("the rod without `{field}` is refused") };
        let messages: Vec<String> = problems.iter().map(ToString::to_string).collect();
        assert!(messages.iter().all(|m| !m.contains("unread_")), "without `{field}`: {messages:#?}");
        let unknown = messages.iter().find(|m| m.starts_with("`Q` is not a body's force symbol"));
        let unknown = unknown.unwrap_or_else(|| panic!("without `{field}`: {messages:#?}"));
        if field == "force" {
            assert!(unknown.contains("body `rod` has no force symbol"), "{unknown}");
        } else {
            assert!(unknown.contains("force symbols: F"), "{unknown}");
        }
    }
}

/// The message refusing a quantity in an `[[expect]]` with `at` lists what can be checked
/// there, and each quantity it lists is accepted there (the pinned rod at rest, each key in
/// turn); a quantity it does not list is refused there.
#[test]
fn the_quantities_a_state_check_lists_are_the_ones_it_accepts() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/rigid/rod_pinned.toml"))
        .expect("the rod");
    let with = |key: &str, name: &str, value: &str| {
        format!(
            "{text}\n[[expect]]\nat = {{ th = 0.0, w = 0.0, x = [1.0, 0.0], v = [0.0, 0.0], F = [0.0, -9.81], I = 0.3333333333333333 }}\ntolerance = 1e3\n{key} = {{ {name} = {value} }}\n"
        )
    };
    let Err(problems) = load(&with("C_dot", "\"pin.x\"", "0.0")) else { panic!("C_dot at a state is refused") };
    let message = problems.iter().map(ToString::to_string).find(|m| m.starts_with("only ")).expect("the message");
    let listed: Vec<&str> =
        message.split("can be checked").next().unwrap_or("").split('`').skip(1).step_by(2).collect();
    assert_eq!(listed, ["force", "torque", "lambda"], "{message}");
    for key in ["force", "torque", "lambda", "C_dot", "C_ddot", "A", "b"] {
        let (name, value) = match key {
            "force" => ("rod", "[0.0, 0.0]"),
            "torque" => ("rod", "0.0"),
            "A" => ("\"pin.x,pin.x\"", "0.0"),
            _ => ("\"pin.x\"", "0.0"),
        };
        let loaded = load(&with(key, name, value));
        assert_eq!(loaded.is_ok(), listed.contains(&key), "{key}: {:?}", loaded.err());
    }
}

/// A vector constraint's own name in an `[[expect]]` (where a row belongs) is an error at
/// the key naming its rows, not a check left out in silence; its rows are checked.
#[test]
fn an_expectation_naming_a_vector_constraint_names_its_rows() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/rigid/rod_pinned.toml"))
        .expect("the rod");
    for (key, name) in [("lambda", "pin"), ("C_dot", "pin"), ("A", "\"pin,pin.y\"")] {
        let with = format!("{text}\n[[expect]]\n{key} = {{ {name} = \"42\" }}\n");
        let Err(problems) = load(&with) else { panic!("{key} = {{ {name} }} is refused") };
        let messages: Vec<String> = problems.iter().map(ToString::to_string).collect();
        assert_eq!(
            messages,
            ["`pin` is a vector constraint, checked row by row: name its rows, `pin.x` and `pin.y`"],
            "{key}"
        );
        let span = problems[0].span().expect("located");
        assert_eq!(&with[span], name, "{key}");
    }
    let rows = format!("{text}\n[[expect]]\nC_dot = {{ \"pin.x\" = \"42\" }}\n");
    assert!(load(&rows).is_ok());
}

/// A state file that is not a flat table of numbers and vectors is refused with a message
/// naming the key (never serde's "did not match any variant"), and a JSON key written
/// twice is an error naming it, not a silent last value.
#[test]
fn bad_state_files_name_the_key() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("constraints/bead_on_wire.toml"))
        .expect("the bead");
    let loaded = load(&text).expect("valid");
    let system = &loaded.system;
    assert_eq!(
        state::state_file(system, r#"{"r": [1, 0], "v": [0, 0, "x"]}"#, Format::Json),
        Err(StateInputError::NotAComponent { key: "v".into(), index: 3, found: "a string" })
    );
    assert_eq!(
        state::state_file(system, "r = [1.0, 0.0]\nv = \"fast\"\n", Format::Toml),
        Err(StateInputError::NotANumber { key: "v".into(), found: "a string" })
    );
    // A constraint file given to `--at`.
    let Err(err) = state::state_file(system, &text, Format::Toml) else { panic!("a scene file is not a state") };
    let message = err.to_string();
    assert!(message.contains("is this a constraint file?") && !message.contains("variant"), "{message}");
    let Err(StateInputError::Syntax(message)) =
        state::state_file(system, r#"{"r": [1, 0], "r": [0, 1]}"#, Format::Json)
    else {
        panic!("a duplicate key is refused")
    };
    assert!(message.contains("duplicate key `r`"), "{message}");
}
