//! Writes into OUT_DIR the step-only soft-step module of the 100 x 100 joint grid
//! (`lagrange generate --solver soft-step --step-only`) and its initial state (`initial.rs`:
//! the parameters, positions and velocities of the file's `[scene]`).

use lagrange::codegen::layout::Solver;
use lagrange::codegen::{Options, module};
use lagrange::expr::eval::Value;
use lagrange::model::file::load;
use lagrange::scenario::Scenario;
use std::fmt::Write;
use std::path::PathBuf;

const FILE: &str = "../../constraints/solvers/joint_grid_100.toml";

fn main() {
    println!("cargo:rerun-if-changed={FILE}");
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let text = std::fs::read_to_string(FILE).expect("the grid's file");
    let options = Options { solver: Some(Solver::SoftStep), step_only: true, ..Options::default() };
    let m = module(&load(&text).expect("valid"), &options).expect("generates");
    std::fs::write(out.join("joint_grid_100.rs"), &m.code).expect("writes the module");
    // The initial state: every field the file's scene gives a value, one assignment each
    // (the bodies' arrays as constants).
    let s = Scenario::new(load(&text).expect("valid"), &[]).expect("derives");
    let (q, v, _) = lagrange::numeric::simulate::initial_state(&s.system, &s.env);
    let two = |x: &[[f64; 3]]| x.iter().map(|p| format!("[{:?}, {:?}]", p[0], p[1])).collect::<Vec<_>>().join(", ");
    let mut init =
        String::from("/// The file's initial state.\npub fn initial() -> State {\n    let mut s = State::default();\n");
    for (symbol, field) in &m.fields {
        if field.contains('[') {
            continue;
        }
        match s.env.get(*symbol) {
            Some(Value::Scalar(x)) => {
                let _ = writeln!(init, "    s.{field} = {x:?};");
            }
            Some(Value::Vector(x)) => {
                let _ = writeln!(init, "    s.{field} = [{:?}, {:?}];", x[0], x[1]);
            }
            _ => {}
        }
    }
    let _ = writeln!(init, "    s.position = [{}];\n    s.velocity = [{}];\n    s\n}}", two(&q), two(&v));
    std::fs::write(out.join("initial.rs"), init).expect("writes the state");
}
