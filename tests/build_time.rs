//! `lagrange::build` (a user's `build.rs`): the module it writes is `lagrange generate`'s,
//! under the file's stem; a bad file's error reads as `lagrange generate`'s diagnostic; and
//! the example crate `examples/build-time/` (lagrange as a build-dependency, the pendulum
//! module `include!`d) passes its own `cargo test` — run here, skipped under
//! `LAGRANGE_QUICK_TESTS`, in `target/build-time` (its own directory: the outer cargo holds
//! the lock of `target/release`, and a build-dependency is compiled with other settings
//! than lagrange's release build anyway, so nothing could be shared).
//!
//! Not here: what the module computes (`tests/generate.rs`, the example's own test).

mod common;

use lagrange::build::{BuildError, Module, module};
use lagrange::codegen::layout::Solver;
use std::path::{Path, PathBuf};
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("build_time").join(name);
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

/// `lagrange generate ARGS` → (exit code, stdout, stderr).
fn generate(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("generate").args(args).output().expect("runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_module_written_is_lagrange_generates_under_the_files_stem() {
    let dir = scratch("written");
    for (file, flags, name) in [
        ("constraints/pendulum.toml", &[][..], "pendulum.rs"),
        ("constraints/chain_5.toml", &["--specialize"][..], "chain_5.rs"),
        ("constraints/bead_on_wire.toml", &["--solver", "soft-step"][..], "bead_on_wire.rs"),
        ("constraints/solvers/two_particles.toml", &["--solver", "soft-step", "--step-only"][..], "two_particles.rs"),
    ] {
        let mut m = Module::new(file).out_dir(&dir);
        if flags.contains(&"--specialize") {
            m = m.specialize(true);
        }
        if flags.contains(&"soft-step") {
            m = m.solver(Solver::SoftStep);
        }
        if flags.contains(&"--step-only") {
            m = m.step_only(true);
        }
        assert_eq!(m.file_name(), name);
        let path = m.write().unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(path, dir.join(name));
        let (code, stdout, _) = generate(&[&[file][..], flags].concat());
        assert_eq!(code, 0, "{file}");
        assert_eq!(std::fs::read_to_string(&path).expect("written"), stdout, "{file} {flags:?}");
    }
    // A stem that is not a Rust identifier is snake_cased; a given name wins.
    assert_eq!(Module::new("scenes/Chain-5.toml").file_name(), "chain_5.rs");
    assert_eq!(Module::new("x.toml").name("y.rs").file_name(), "y.rs");
}

#[test]
fn a_bad_file_reads_as_lagrange_generates_diagnostic() {
    let dir = scratch("bad");
    for file in ["constraints/invalid/file_types.toml", "constraints/invalid/unknown_symbol.toml"] {
        let e = Module::new(file).out_dir(&dir).write().expect_err("a bad file");
        assert!(matches!(e, BuildError::Invalid { .. }), "{file}: {e:?}");
        let (code, _, stderr) = generate(&[file]);
        assert_eq!(code, 1);
        assert_eq!(format!("{e}\n"), stderr, "{file}");
    }
    // A 3D rigid body with the velocity-level step is written, as `generate` writes it.
    let path = Module::new("constraints/joints/ball_3d.toml")
        .solver(Solver::SoftStep)
        .out_dir(&dir)
        .write()
        .expect("a rigid body's step is written");
    let written = std::fs::read_to_string(&path).expect("written");
    assert!(written.contains("pub fn step("), "no step in {}", path.display());
    assert_eq!(written, generate(&["constraints/joints/ball_3d.toml", "--solver", "soft-step"]).1);
    let e = Module::new("constraints/no_such_file.toml").out_dir(&dir).write().expect_err("missing");
    assert!(matches!(e, BuildError::Read(_)), "{e:?}");
    assert_eq!(format!("{e}\n"), generate(&["constraints/no_such_file.toml"]).2);
}

#[test]
fn outside_a_build_script_it_says_out_dir_is_missing() {
    // Cargo sets OUT_DIR for build scripts only (not for integration tests).
    assert!(std::env::var_os("OUT_DIR").is_none());
    assert!(matches!(module("constraints/pendulum.toml"), Err(BuildError::NoOutDir)));
}

#[test]
fn the_example_crate_passes_its_cargo_test() {
    if common::skip_slow("the_example_crate_passes_its_cargo_test") {
        return;
    }
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).parent().expect("target/").join("build-time");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(["test", "--release"])
        .current_dir("examples/build-time")
        .env("CARGO_TARGET_DIR", &target)
        .env_remove("RUSTFLAGS")
        .output()
        .expect("cargo runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "examples/build-time: cargo test failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("test the_generated_lambda_and_force_are_the_rod_tension ... ok"), "{stdout}");
}
