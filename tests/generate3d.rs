//! `lagrange generate --lang rust` for 3D rigid bodies: every 3D file of
//! `constraints/joints/` and `constraints/rigid/`, plain and specialised, compiled in one
//! crate (rustc, warnings denied) and run at random states with random unit quaternions;
//! λ, the forces, accelerations, the world-frame torques and angular accelerations must be
//! `lagrange solve`'s (`numeric::rescale::solve_at`, `numeric::rows::world_angular`), and C,
//! Ċ, A and b the derivation's (the interpreter), to 1e-12 relative.
//!
//! Not here: the 2D modules (`tests/generate.rs`), the C target (it refuses 3D rigid
//! bodies, `tests/rigid3d.rs`).

mod common;

use common::{Rng, random_quaternion};
use lagrange::codegen::{Module, Options, module};
use lagrange::derive::{Derivation, derive};
use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::expr::{Role, Ty};
use lagrange::model::file::{Loaded, load};
use lagrange::numeric::rescale::solve_at;
use lagrange::numeric::rows::{RowProgram, angular_bodies, angular_slots, world_angular};
use lagrange::numeric::solve::Settings;
use std::fmt::Write;
use std::path::Path;
use std::process::Command;

/// States per module.
const STATES: usize = 4;

/// The outputs compared, each printed flattened.
const OUTPUTS: [&str; 9] = [
    "constraints",
    "constraint_rates",
    "b_vector",
    "lambda",
    "a_matrix",
    "forces",
    "accelerations",
    "torques",
    "angular_accelerations",
];

/// Relative agreement asked of every output (of its largest entry, at least 1).
const TOLERANCE: f64 = 1e-12;

fn loaded(rel: &str) -> Loaded {
    let text = std::fs::read_to_string(rel).expect("readable");
    load(&text).unwrap_or_else(|e| panic!("{rel}: {e:?}"))
}

/// A random state: unit quaternions, positive masses and principal moments, the file's
/// parameter values, everything else in [-2, 2].
fn random_state(l: &Loaded, rng: &mut Rng) -> Env {
    let g = &l.system.graph;
    let mut env = Env::new();
    for (s, info) in g.symbols() {
        let value = if g.is_quaternion(s) {
            Value::Quaternion(random_quaternion(rng))
        } else {
            match (info.ty, info.role) {
                (Ty::Scalar, Role::Mass { .. } | Role::Inertia { .. }) => Value::Scalar(rng.uniform(0.5, 2.0)),
                (Ty::Vector, Role::Inertia { .. }) => Value::Vector(rng.uniform_vector(3, 0.5, 2.0)),
                (Ty::Scalar, _) => Value::Scalar(rng.uniform(-2.0, 2.0)),
                (Ty::Vector, _) => Value::Vector(rng.uniform_vector(3, -2.0, 2.0)),
            }
        };
        env.set(s, value);
    }
    for &(s, v) in &l.values {
        env.set(s, v);
    }
    env
}

/// The generated `State` of `env`, as a block expression assigning each field.
fn state_literal(m: &Module, env: &Env) -> String {
    let mut literal = String::from("{ let mut s = State::default(); ");
    for (s, field) in &m.fields {
        let _ = match env.get(*s) {
            Some(Value::Scalar(x)) => write!(literal, "s.{field} = {x:?}; "),
            Some(Value::Vector(v)) => write!(literal, "s.{field} = {v:?}; "),
            Some(Value::Quaternion(q)) => write!(literal, "s.{field} = {q:?}; "),
            None => panic!("no value for field {field}"),
        };
    }
    literal.push_str("s }");
    literal
}

/// The outputs at `env`: the interpreter's C, Ċ, A, b and `lagrange solve`'s numbers.
fn expected(l: &Loaded, d: &Derivation, env: &Env) -> Vec<Vec<f64>> {
    let (system, g) = (&l.system, &d.graph);
    let scalar = |id| eval_one(g, id, env).expect("evaluates").scalar().expect("a scalar");
    let k = d.constraints.len();
    let mut a = vec![0.0; k * k];
    for &(r, c, id) in &d.a {
        a[r * k + c] = scalar(id);
        a[c * k + r] = scalar(id);
    }
    let program = RowProgram::new(system, d, &[]);
    let (rows, solution) = solve_at(&program, system, env, &Settings::default()).expect("evaluates");
    let n = system.bodies.len();
    let world = |of: &dyn Fn(usize) -> f64| -> Vec<f64> {
        angular_bodies(system)
            .flat_map(|i| world_angular(&rows, of, angular_slots(system, i).expect("rigid")))
            .collect()
    };
    vec![
        d.constraints.iter().map(|c| scalar(c.c)).collect(),
        d.constraints.iter().map(|c| scalar(c.c_dot)).collect(),
        d.b.iter().map(|&id| scalar(id)).collect(),
        solution.lambda.clone(),
        a,
        solution.constraint_force[..n].iter().flatten().copied().collect(),
        solution.acceleration[..n].iter().flatten().copied().collect(),
        world(&|s| solution.constraint_force[s][0]),
        world(&|s| solution.acceleration[s][0]),
    ]
}

#[test]
fn generated_3d_rigid_modules_compile_and_agree_with_solve() {
    // One rustc run of 14 modules: ~14 s on 2 cores, so not in the quick pass.
    if common::skip_slow("generated_3d_rigid_modules_compile_and_agree_with_solve") {
        return;
    }
    let files: Vec<String> = common::rigid_files().into_iter().filter(|rel| common::is_3d(Path::new(rel))).collect();
    assert!(files.len() >= 7, "the 3D joints and scenes: {files:?}");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generate3d");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut rng = Rng::new(0x3d_9e7e_4a7e);
    let mut main = String::from("// Test harness generated by tests/generate3d.rs.\n");
    let mut body = String::new();
    let mut cases = Vec::new();
    for rel in &files {
        for specialize in [false, true] {
            let l = loaded(rel);
            let m = module(&l, &Options { specialize, ..Options::default() }).unwrap_or_else(|e| panic!("{rel}: {e}"));
            let reference = loaded(rel);
            let d = derive(&reference.system).expect("derives");
            let stem = Path::new(rel).file_stem().and_then(|s| s.to_str()).expect("a name");
            let name = format!("{stem}{}", if specialize { "_specialized" } else { "" });
            let file = dir.join(format!("{name}.rs"));
            std::fs::write(&file, &m.code).expect("write module");
            let _ = writeln!(main, "#[allow(dead_code)]\nmod {name} {{\n    include!({file:?});\n}}");
            for i in 0..STATES {
                let env = random_state(&reference, &mut rng);
                let _ = writeln!(body, "    {{\n        use {name}::*;\n        let s = {};", state_literal(&m, &env));
                for f in ["constraints", "constraint_rates", "b_vector", "lambda"] {
                    let _ = writeln!(body, "        show(\"{name} {i} {f}\", &{f}(&s));");
                }
                for f in ["a_matrix", "forces", "accelerations", "torques", "angular_accelerations"] {
                    let _ = writeln!(body, "        show(\"{name} {i} {f}\", &{f}(&s).concat());");
                }
                body.push_str("    }\n");
                cases.push((format!("{name} {i}"), expected(&reference, &d, &env)));
            }
        }
    }
    main.push_str("\nfn show(label: &str, xs: &[f64]) {\n    println!(\"{label} {xs:?}\");\n}\n\nfn main() {\n");
    main.push_str(&body);
    main.push_str("}\n");
    let main_path = dir.join("harness.rs");
    std::fs::write(&main_path, &main).expect("write harness");
    let exe = dir.join("harness");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let out = Command::new(rustc)
        .args(["--edition", "2021", "-C", "opt-level=0", "-D", "warnings", "-o"])
        .arg(&exe)
        .arg(&main_path)
        .output()
        .expect("rustc runs (set RUSTC or put rustc on PATH)");
    assert!(out.status.success(), "generated code does not compile:\n{}", String::from_utf8_lossy(&out.stderr));
    let run = Command::new(&exe).output().expect("harness runs");
    assert!(run.status.success(), "harness failed: {}", String::from_utf8_lossy(&run.stderr));
    let stdout = String::from_utf8_lossy(&run.stdout);
    let mut lines = stdout.lines();
    let mut checked = 0;
    for (case, want) in &cases {
        for (f, want) in OUTPUTS.iter().zip(want) {
            let line = lines.next().expect("one line per output");
            let (label, values) = line.split_once(" [").expect("label [values]");
            assert_eq!(label, format!("{case} {f}"));
            let got: Vec<f64> = values
                .trim_end_matches(']')
                .split(", ")
                .filter(|x| !x.is_empty())
                .map(|x| x.parse().expect("a number"))
                .collect();
            assert_eq!(got.len(), want.len(), "{label}");
            let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            for (x, y) in got.iter().zip(want) {
                assert!((x - y).abs() <= TOLERANCE * scale, "{label}: generated {got:?}, solve {want:?}");
            }
            checked += 1;
        }
    }
    assert_eq!(checked, cases.len() * OUTPUTS.len());
}
