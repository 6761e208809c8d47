//! Every output a user sees, pinned: `derive` in every format with and without `--steps`,
//! `generate`, and `solve --format json` at the scene's state, for every file in
//! `constraints/` and `constraints/hard/`, through the binary; and golden hashes of the CSV of
//! fixed `simulate` runs, so determinism holds across builds and not only within one process.
//!
//! A refactoring keeps these byte-identical. A change that alters an output on purpose
//! updates its snapshot (`INSTA_UPDATE=always cargo test --release --test outputs`, then
//! review the diff) or its hash, and says why in the commit.
//!
//! Outputs longer than [`INLINE_LIMIT`] (the 100-link chain) are pinned by their length and
//! an FNV-1a hash, with their first lines for orientation, so the snapshots stay readable.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// Outputs up to this many bytes are snapshotted whole.
const INLINE_LIMIT: usize = 200_000;

/// Lines of a long output kept in its snapshot beside the hash.
const HEAD_LINES: usize = 40;

/// FNV-1a, 64 bits: a hash that is the same in every build and on every machine (std's
/// `DefaultHasher` promises neither).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3))
}

/// Every constraint file whose outputs are pinned, relative to the crate root, in a fixed order.
fn files() -> Vec<String> {
    let out = files_in(&["constraints", "constraints/hard"]);
    assert!(out.len() >= 30, "expected the shipped constraint files, found {}", out.len());
    out
}

/// The `.toml` files of `dirs`, relative to the crate root, sorted within each folder.
fn files_in(dirs: &[&str]) -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut out = Vec::new();
    for &dir in dirs {
        let mut here: Vec<PathBuf> = std::fs::read_dir(root.join(dir))
            .expect("the constraints folder is readable")
            .map(|e| e.expect("a directory entry").path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        here.sort();
        out.extend(
            here.iter().map(|p| format!("{dir}/{}", p.file_name().and_then(|n| n.to_str()).expect("UTF-8 name"))),
        );
    }
    out
}

/// The snapshot name of `rel` and one output: `bead_on_wire__derive_text`, `hard_rope__…`.
fn snapshot_name(rel: &str, what: &str) -> String {
    let stem = rel.trim_start_matches("constraints/").trim_end_matches(".toml").replace('/', "_");
    format!("{stem}__{what}")
}

/// Runs the binary from the crate root with `args`; the output must succeed and be UTF-8.
fn run(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .expect("the lagrange binary runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "lagrange {args:?} failed ({:?}):\n{stderr}", out.status);
    String::from_utf8(out.stdout).expect("stdout is UTF-8")
}

/// The text a snapshot holds: the output itself, or for a long one its size, hash and head.
fn pinned(output: &str) -> String {
    if output.len() <= INLINE_LIMIT {
        return output.to_string();
    }
    let head: Vec<&str> = output.lines().take(HEAD_LINES).collect();
    format!(
        "bytes: {}\nfnv1a64: {:016x}\nfirst {HEAD_LINES} lines:\n{}\n",
        output.len(),
        fnv1a(output.as_bytes()),
        head.join("\n")
    )
}

/// Snapshots `lagrange ARGS… FILE` for every file, under `what`.
fn pin_every_file(what: &str, args: &[&str]) {
    pin_files(files(), what, args);
}

/// Snapshots `lagrange ARGS… FILE` for each of `files`, under `what`.
fn pin_files(files: Vec<String>, what: &str, args: &[&str]) {
    insta::with_settings!({ snapshot_path => "snapshots/outputs", prepend_module_to_snapshot => false }, {
        for rel in files {
            let mut full = vec![args[0], rel.as_str()];
            full.extend_from_slice(&args[1..]);
            let output = run(&full);
            insta::assert_snapshot!(snapshot_name(&rel, what), pinned(&output));
        }
    });
}

#[test]
fn derive_text() {
    pin_every_file("derive_text", &["derive"]);
}

#[test]
fn derive_text_steps() {
    pin_every_file("derive_text_steps", &["derive", "--steps"]);
}

#[test]
fn derive_latex() {
    pin_every_file("derive_latex", &["derive", "--format", "latex"]);
}

#[test]
fn derive_latex_steps() {
    pin_every_file("derive_latex_steps", &["derive", "--format", "latex", "--steps"]);
}

#[test]
fn derive_markdown() {
    pin_every_file("derive_markdown", &["derive", "--format", "markdown"]);
}

#[test]
fn derive_markdown_steps() {
    pin_every_file("derive_markdown_steps", &["derive", "--format", "markdown", "--steps"]);
}

#[test]
fn derive_json() {
    pin_every_file("derive_json", &["derive", "--format", "json"]);
}

#[test]
fn derive_json_steps() {
    pin_every_file("derive_json_steps", &["derive", "--format", "json", "--steps"]);
}

#[test]
fn generate_rust() {
    pin_every_file("generate_rust", &["generate"]);
}

/// The rigid-body files' modules (their `derive` outputs are pinned by `tests/rigid.rs`).
#[test]
fn generate_rust_rigid() {
    // 3D rigid bodies (quaternions) are not generated yet: `tests/rigid3d.rs` has their refusal.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files: Vec<String> =
        files_in(&common::RIGID_DIRS).into_iter().filter(|f| !common::is_3d(&root.join(f))).collect();
    assert!(files.len() >= 12, "expected the joint library, found {}", files.len());
    pin_files(files, "generate_rust", &["generate"]);
}

#[test]
fn solve_json() {
    pin_every_file("solve_json", &["solve", "--format", "json"]);
}

/// Fixed `simulate` runs and the FNV-1a hash and length of their CSV. The hashes were taken
/// from the binary at the commit that added this test; a change that moves one on purpose
/// says why in its commit.
const GOLDEN_RUNS: [(&str, &[&str], u64, usize); 6] = [
    (
        "constraints/pendulum.toml",
        &["--steps", "2000"],
        // Moved when SHAKE began predicting its correction from the last steps' (2026-12-06):
        // r, v and λ part from the old ones by at most 7e-13 of their largest values, C by
        // 9e-14 (within the projection's tolerance; its values print longer: 281 100 →
        // 282 634 bytes). Moved again when RATTLE's one-row runs began solving their row
        // without the scaling (`single::unscaled_multiplier`, 2026-12-07): r and C the same,
        // v by at most 2.2e-16 (5e-17 of its largest), λ by 1.1e-14 (3.6e-16 of its
        // largest), Ċ by 2.2e-16 (rounding: its largest is 4.4e-16); 282 558 bytes.
        0xa8fc_7d5c_4408_104b,
        282_558,
    ),
    ("constraints/double_pendulum.toml", &["--integrator", "rk4", "--steps", "2000"], 0x053a_931c_f63d_e6ff, 543_871),
    (
        "constraints/chain_5.toml",
        &["--integrator", "euler", "--stabilize", "baumgarte", "--steps", "1000"],
        // Moved when the tridiagonal substitutions began multiplying by 1/Lᵢᵢ (2026-12-05):
        // the run's numbers part from the old ones by at most 1e-13 of their size. Moved
        // again when the chain's solve took its step of refinement only where the residual
        // asks for it (2026-12-07): r, v and λ by at most 1.2e-15, 3.7e-15 and 4.0e-14 of
        // their largest values, C and Ċ by 2.8e-16 and 1.2e-14 (Euler + Baumgarte drifts;
        // 719 173 → 718 937 bytes: shorter last digits).
        0x43e4_afbf_c115_7e1d,
        718_937,
    ),
    ("constraints/hard/bounce.toml", &["--steps", "3000"], 0x8297_fd45_ae5f_4878, 283_483),
    ("constraints/rope_pendulum.toml", &["--steps", "3000", "--every", "3"], 0x6ff3_9566_3d8b_ebd4, 128_679),
    // A 3D rigid body: quaternion columns, the implicit gyroscopic kick, RATTLE in (x, φ).
    ("constraints/rigid/spinning_top.toml", &["--steps", "1000"], 0x02a4_42da_c4b7_7ad4, 463_218),
];

#[test]
fn simulate_csv_matches_its_golden_hash() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("lagrange-golden-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary folder");
    let mut report = Vec::new();
    for (i, (file, options, hash, len)) in GOLDEN_RUNS.iter().enumerate() {
        let csv = dir.join(format!("run{i}.csv"));
        let csv_arg = csv.to_str().expect("UTF-8 temporary path");
        let mut args = vec!["simulate", file, "--csv", csv_arg];
        args.extend_from_slice(options);
        run(&args);
        let bytes = std::fs::read(&csv).expect("the CSV was written");
        assert!(bytes.len() > 10_000, "{file}: a CSV of {} bytes is too short to pin anything", bytes.len());
        report.push(format!("{file} {options:?}: {:#018x}, {}", fnv1a(&bytes), bytes.len()));
        if (fnv1a(&bytes), bytes.len()) != (*hash, *len) {
            report.push(format!("  expected {hash:#018x}, {len}"));
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    let failed = report.iter().any(|l| l.starts_with("  expected"));
    assert!(!failed, "a simulate CSV changed:\n{}", report.join("\n"));
}
