//! Writes into OUT_DIR the step-only soft-step modules (`lagrange generate --solver soft-step
//! --step-only`) of two 100 x 100 grids and their initial states:
//!
//! - `joint_grid_100.rs` and `initial_points.rs`: the point masses of
//!   `constraints/solvers/joint_grid_100.toml` (distance rows);
//! - `rigid_grid.rs` and `initial_rigid.rs`: Box2D's `joint_grid` as rigid discs on revolute
//!   joints, the scene `cargo run --example solver_scenes -- rigid_grid N` writes (its text
//!   comes from that example's `rigid_grid`, included below), N = 30 or the environment's
//!   `RIGID_GRID` (100 for Box2D's grid).
//!
//! An initial state is `State::default()` with every nonzero value of the file's `[scene]`
//! assigned (parameters, orientations, angular velocities) and, in a big scene, the bodies'
//! positions and velocities as arrays.

use lagrange::codegen::layout::Solver;
use lagrange::codegen::{Options, module};
use lagrange::expr::eval::Value;
use lagrange::model::file::load;
use lagrange::scenario::Scenario;
use std::fmt::Write;
use std::path::Path;

/// `examples/solver_scenes.rs`, for its `rigid_grid` (its other scenes and its `main` unused).
#[allow(dead_code)]
#[path = "../solver_scenes.rs"]
mod scenes;

const POINTS: &str = "../../constraints/solvers/joint_grid_100.toml";

fn main() {
    println!("cargo:rerun-if-changed={POINTS}");
    println!("cargo:rerun-if-changed=../solver_scenes.rs");
    println!("cargo:rerun-if-env-changed=RIGID_GRID");
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let points = std::fs::read_to_string(POINTS).expect("the grid's file");
    write(&points, &out, "joint_grid_100.rs", "initial_points.rs", "");
    let n: usize = match std::env::var("RIGID_GRID") {
        Ok(n) => n.parse().ok().filter(|&n| n >= 2).expect("RIGID_GRID is a grid size of at least 2"),
        // 30 builds in about a minute; Box2D's 100's module takes about 2 minutes of rustc.
        Err(_) => 30,
    };
    let rigid = scenes::rigid_grid(n);
    write(
        &rigid,
        &out,
        "rigid_grid.rs",
        "initial_rigid.rs",
        &format!("/// The grid's columns.\npub const COLUMNS: usize = {n};\n"),
    );
}

/// Writes the step-only soft-step module of the scene `text` into `out/name` and its initial
/// state (`initial()`, after `extra`) into `out/initial`.
fn write(text: &str, out: &Path, name: &str, initial: &str, extra: &str) {
    let options = Options { solver: Some(Solver::SoftStep), step_only: true, ..Options::default() };
    let m = module(&load(text).expect("valid"), &options).expect("generates");
    std::fs::write(out.join(name), &m.code).expect("writes the module");
    let s = Scenario::new(load(text).expect("valid"), &[]).expect("derives");
    // A scene of more than 1 024 inputs keeps its bodies' x and v in arrays (a smaller one as
    // fields, set above): the slots' first entries (then a rigid body's [θ, 0] and [ω, 0]).
    let (q, v, _) = lagrange::numeric::simulate::initial_state(&s.system, &s.env);
    let bodies = m.fields.iter().filter(|(_, field)| field.starts_with("position[")).count();
    let (q, v) = (&q[..bodies], &v[..bodies]);
    let two = |x: &[[f64; 3]]| x.iter().map(|p| format!("[{:?}, {:?}]", p[0], p[1])).collect::<Vec<_>>().join(", ");
    let mut init = format!(
        "{extra}/// The file's initial state.\npub fn initial() -> State {{\n    let mut s = State::default();\n"
    );
    // One assignment per scalar or vector field or role array entry (a rigid body's
    // `angle[r]`) the scene gives a nonzero value (the bodies' positions and velocities as
    // constants below): a rigid grid's 2 x 9 900 zero angles and rates stay default.
    for (symbol, field) in &m.fields {
        if field.starts_with("position[") || field.starts_with("velocity[") {
            continue;
        }
        match s.env.get(*symbol) {
            Some(Value::Scalar(x)) if x != 0.0 => {
                let _ = writeln!(init, "    s.{field} = {x:?};");
            }
            Some(Value::Vector(x)) if x.iter().any(|&c| c != 0.0) => {
                let _ = writeln!(init, "    s.{field} = [{:?}, {:?}];", x[0], x[1]);
            }
            _ => {}
        }
    }
    if bodies > 0 {
        let _ = writeln!(init, "    s.position = [{}];\n    s.velocity = [{}];", two(q), two(v));
    }
    let _ = writeln!(init, "    s\n}}");
    std::fs::write(out.join(initial), init).expect("writes the state");
}
