//! `lagrange derive` for several constraints (DESIGN step 5: no closed form for λ): the
//! entries of A and b named by constraints, the force on each body as Σₖ λₖ Jₖᵢ, and with
//! `--steps` C, Ċ, C̈ of each constraint, each Jₖᵢ and cₖ, and the system A λ = −b row by
//! row — in text, LaTeX, Markdown and JSON alike. The JSON's force sums parse again.

use lagrange::expr::{Role, Ty};
use lagrange::model::file::load;
use std::process::Command;

const DOUBLE: &str = "constraints/double_pendulum.toml";
const CHAIN: &str = "constraints/chain_5.toml";

/// `lagrange derive FILE ARGS…` from the crate root; stdout, after checking success.
fn derive(path: &str, args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .arg("derive")
        .arg(path)
        .args(args)
        .output()
        .expect("the binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{path} {args:?}: {stderr}");
    assert!(stderr.is_empty(), "{path} {args:?}: nothing on stderr, found {stderr}");
    String::from_utf8(out.stdout).expect("UTF-8")
}

fn assert_all(output: &str, needles: &[&str], what: &str) {
    for needle in needles {
        assert!(output.contains(needle), "{what}: {needle:?} missing in\n{output}");
    }
}

#[test]
fn text_names_every_entry_and_sums_the_forces() {
    let text = derive(DOUBLE, &[]);
    assert_all(
        &text,
        &[
            "A[rod1, rod1] = (r1·r1)/m1",
            "A[rod1, rod2] = −(r1·(r2 − r1))/m1",
            "A[rod2, rod2] = ",
            "b[rod1] = (m1 v1·v1 + F1·r1)/m1",
            "b[rod2] = ",
            "F_c[upper] = λ_rod1 r1 − λ_rod2 (r2 − r1)",
            "F_c[lower] = λ_rod2 (r2 − r1)",
        ],
        "derive",
    );
    // No closed form is claimed for several constraints.
    assert!(!text.lines().any(|l| l.trim_start().starts_with("λ = ")), "{text}");
}

/// Neighbouring links of a chain share a body: their A entry is the dot product of the two
/// link vectors as the file writes them (`(r2 − r1)·(r3 − r2)`, a bilinear form of rank two), not expanded
/// into four dot products that cancel in floating point when the links are short and far from
/// the origin. The later links are the first ones renamed (`expr::shape`) and read the same.
#[test]
fn a_chain_couples_neighbouring_links_by_one_dot_product() {
    let text = derive(CHAIN, &[]);
    assert_all(
        &text,
        &[
            "A[link1, link2] = −(r1·(r2 − r1))/m",
            "A[link2, link3] = −((r2 − r1)·(r3 − r2))/m",
            "A[link3, link4] = −((r3 − r2)·(r4 − r3))/m",
            "A[link4, link5] = −((r4 − r3)·(r5 − r4))/m",
            "A[link5, link5] = 2 ((r5 − r4)·(r5 − r4))/m",
        ],
        "chain",
    );
}

#[test]
fn steps_show_each_constraint_then_the_system() {
    let text = derive(DOUBLE, &["--steps"]);
    let needles = [
        "C[rod1] = r1·r1 − l1²",
        "Ċ[rod1] = v1·r1 + r1·v1 = 2 r1·v1",
        "C̈[rod1] = 2 (v1·v1 + r1·a1)",
        "C[rod2] = ",
        "Ċ[rod2] = ",
        "C̈[rod2] = ",
        "J[rod1, upper] = r1",
        "J[rod2, upper] = −(r2 − r1)",
        "J[rod2, lower] = r2 − r1",
        "c[rod1] = v1·v1",
        "c[rod2] = (v2 − v1)·(v2 − v1)",
        "A[rod1, rod2] = ",
        "b[rod2] = ",
        "A[rod1, rod1] λ_rod1 + A[rod1, rod2] λ_rod2 = −b[rod1]",
        "A[rod2, rod1] λ_rod1 + A[rod2, rod2] λ_rod2 = −b[rod2]",
        "F_c[upper] = λ_rod1 r1 − λ_rod2 (r2 − r1)",
    ];
    assert_all(&text, &needles, "derive --steps");
    // The steps come in the article's order.
    let at = |needle: &str| text.find(needle).unwrap_or_else(|| panic!("{needle:?} missing"));
    let order = ["Step 1.", "Step 2.", "Step 3.", "Step 4.", "Step 5.", "Step 6.", "Step 7.", "F_c[upper]"];
    assert!(order.windows(2).all(|w| at(w[0]) < at(w[1])), "steps out of order:\n{text}");

    // A chain: one row per link, each with its neighbours only (A is tridiagonal).
    let chain = derive(CHAIN, &["--steps"]);
    let rows: Vec<&str> = chain.lines().filter(|l| l.contains("= −b[link")).collect();
    assert_eq!(rows.len(), 5, "{chain}");
    assert!(rows[0].trim_start().starts_with("A[link1, link1] λ_link1 + A[link1, link2] λ_link2 = −b[link1]"));
    assert!(rows[2].contains("A[link3, link2] λ_link2 + A[link3, link3] λ_link3 + A[link3, link4] λ_link4"));
    for k in 1..=5 {
        assert_all(&chain, &[&format!("C̈[link{k}] = "), &format!("c[link{k}] = "), &format!("b[link{k}] = ")], CHAIN);
    }
}

#[test]
fn latex_and_markdown_carry_the_same_entries() {
    for format in ["latex", "markdown"] {
        let summary = derive(DOUBLE, &["--format", format]);
        let steps = derive(DOUBLE, &["--format", format, "--steps"]);
        let entries = [
            "A_{\\mathrm{rod1},\\mathrm{rod1}} = ",
            "A_{\\mathrm{rod1},\\mathrm{rod2}} = ",
            "A_{\\mathrm{rod2},\\mathrm{rod2}} = ",
            "b_{\\mathrm{rod1}} = ",
            "b_{\\mathrm{rod2}} = ",
            "\\vec{F}_{c,\\mathrm{upper}} = \\lambda_{\\mathrm{rod1}}",
            "\\vec{F}_{c,\\mathrm{lower}} = \\lambda_{\\mathrm{rod2}}",
        ];
        assert_all(&summary, &entries, format);
        assert_all(&steps, &entries, format);
        assert_all(
            &steps,
            &[
                "J_{\\mathrm{rod2},\\mathrm{lower}} = ",
                "c_{\\mathrm{rod2}} = ",
                "A_{\\mathrm{rod2},\\mathrm{rod1}} \\lambda_{\\mathrm{rod1}} + A_{\\mathrm{rod2},\\mathrm{rod2}} \\lambda_{\\mathrm{rod2}} = -b_{\\mathrm{rod2}}",
            ],
            format,
        );
        // Every display line is balanced (no half-written formula).
        let open = steps.matches('{').count();
        assert_eq!(open, steps.matches('}').count(), "{format}: unbalanced braces");
    }
    for format in ["text", "latex", "markdown", "json"] {
        derive(CHAIN, &["--format", format]);
        derive(CHAIN, &["--format", format, "--steps"]);
    }
}

#[test]
fn json_force_sums_parse_again() {
    let json: serde_json::Value = serde_json::from_str(&derive(DOUBLE, &["--format", "json"])).expect("JSON");
    assert!(json.get("lambda").is_none() && json.get("forces").is_none(), "no closed form for several constraints");
    let text = std::fs::read_to_string(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(DOUBLE)).expect("file");
    let mut system = load(&text).expect("valid").system;
    // The multipliers, declared as scalars so the sums parse in the file's scope.
    let multipliers = json["multipliers"].as_object().expect("multipliers");
    assert_eq!(multipliers.len(), 2);
    for (constraint, symbol) in multipliers {
        let symbol = symbol.as_str().expect("a name");
        assert_eq!(symbol, format!("lambda_{constraint}"));
        let s = system.graph.declare(symbol, Ty::Scalar, Role::Parameter);
        let id = system.graph.sym(s);
        system.scope.insert(symbol, id);
    }
    let sums = json["force_sums"].as_object().expect("force_sums");
    // Independent of the printer: the double pendulum's constraint forces by hand.
    let by_hand = [("upper", "lambda_rod1*r1 + lambda_rod2*(r1 - r2)"), ("lower", "lambda_rod2*(r2 - r1)")];
    assert_eq!(sums.len(), by_hand.len());
    for (body, expected) in by_hand {
        let printed = sums[body].as_str().expect("a string");
        let got = system.expression(printed).unwrap_or_else(|e| panic!("{body}: {printed:?} does not parse: {e}"));
        let want = system.expression(expected).expect("parses");
        let same = system.simplifier.equivalent(&mut system.graph, got, want).expect("well typed");
        assert!(same, "force on {body}: {printed} ≠ {expected}");
    }
}

/// A long chain's JSON: `A` is the list of its non-zero entries over the upper triangle,
/// `{"row": k, "col": j, "expr": …}` sorted by row then column: for a chain the diagonal
/// and the band above it, 2N − 1 entries, none of them `"0"`.
#[test]
fn a_long_chains_json_lists_the_sparse_upper_triangle_of_a() {
    let n = 300;
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("lagrange_json_chain_{}.toml", std::process::id()));
    std::fs::write(&path, lagrange::scenario::chain(n)).expect("temporary file");
    let out = derive(path.to_str().expect("UTF-8 path"), &["--format", "json"]);
    let _ = std::fs::remove_file(&path);
    let json: serde_json::Value = serde_json::from_str(&out).expect("valid JSON");
    let a = json["A"].as_array().expect("A");
    assert_eq!(a.len(), 2 * n - 1);
    let mut previous = None;
    for entry in a {
        let (k, j) = (entry["row"].as_u64().expect("row"), entry["col"].as_u64().expect("col"));
        let expr = entry["expr"].as_str().expect("a string");
        assert!(j == k || j == k + 1, "A[{k}][{j}] = {expr} is off the band or below the diagonal");
        assert_ne!(expr, "0", "A[{k}][{j}] is listed but zero");
        assert!(previous < Some((k, j)), "A's entries are not sorted at ({k}, {j})");
        previous = Some((k, j));
    }
}
