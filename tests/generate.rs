//! `lagrange generate --lang rust`: the generated modules compile with rustc (warnings
//! denied) and compute what the reference interpreter computes, for every file in
//! `constraints/`, `constraints/joints/` and `constraints/rigid/` (rigid bodies: θ, ω, τ, I in the state; Jʷ, the
//! torques and α beside J, the forces and a) and for a file of hostile names, plain and
//! specialised.

mod common;

use lagrange::codegen::{Module, Options, module};
use lagrange::derive::{Derivation, derive};
use lagrange::expr::eval::{Env, Value, eval_one};
use lagrange::expr::{Graph, Role, Symbol, Ty};
use lagrange::model::file::{Loaded, load};
use lagrange::numeric::rescale::solve_at;
use lagrange::numeric::rows::{RowProgram, angular_bodies, angular_slot};
use lagrange::numeric::solve::{Settings, Solution, safe_norm};
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// States per module.
const STATES: usize = 4;

/// The outputs compared for every module, in the order the harness prints them.
const OUTPUTS: [&str; 10] = [
    "constraints",
    "b_vector",
    "c_term",
    "lambda",
    "constraint_rates",
    "a_matrix",
    "jacobian",
    "forces",
    "accelerations",
    "applied_forces",
];

/// The outputs compared beside [`OUTPUTS`] for a module with rigid bodies.
const RIGID_OUTPUTS: [&str; 7] = [
    "torques",
    "angular_accelerations",
    "orientations",
    "angular_velocities",
    "inverse_inertias",
    "applied_torques",
    "angular_jacobian",
];

struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
}

/// Named outputs (`lambda`, `forces`, …) and their values, flattened row by row.
type Outputs = Vec<(String, Vec<f64>)>;

/// One generated module to check: its code, and for each state the literal and the
/// expected outputs (name, values) computed by the interpreter.
struct Case {
    name: String,
    module: Module,
    states: Vec<(String, Outputs)>,
    /// The file has rigid bodies: the module's rigid outputs are compared too.
    rigid: bool,
    /// The module's A is banded (`a_band`, no `a_matrix`).
    banded: bool,
}

fn files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in ["constraints", "constraints/joints", "constraints/rigid"] {
        let mut here: Vec<PathBuf> = std::fs::read_dir(dir)
            .expect("constraints/")
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            // 3D rigid bodies (quaternions) are not generated yet (`tests/rigid3d.rs`).
            .filter(|p| !(common::in_rigid_dirs(p) && common::is_3d(p)))
            .collect();
        here.sort();
        files.extend(here);
    }
    files.push(PathBuf::from("tests/data/hostile_names.toml"));
    // A's band and J mostly zeros: written as their formulas over zeroed arrays.
    files.push(PathBuf::from("tests/data/net_8x3.toml"));
    files
}

fn loaded(path: &Path) -> Loaded {
    let text = std::fs::read_to_string(path).expect("readable");
    load(&text).unwrap_or_else(|e| panic!("{}: {e:?}", path.display()))
}

/// A random state of the system: the interpreter's environment (with parameter values from
/// the file when `file_parameters`) and the generated `State` literal.
fn random_state(l: &Loaded, m: &Module, rng: &mut Rng, file_parameters: bool) -> (Env, String) {
    let g = &l.system.graph;
    let mut env = Env::new();
    for (s, info) in g.symbols() {
        let value = match info.ty {
            Ty::Scalar if matches!(info.role, Role::Mass { .. } | Role::Inertia { .. } | Role::Parameter) => {
                Value::Scalar(rng.range(0.5, 2.0))
            }
            Ty::Scalar => Value::Scalar(rng.range(-2.0, 2.0)),
            Ty::Vector => {
                // The interpreter's vectors have zeros past the dimension.
                let mut v = [0.0; 3];
                for x in v.iter_mut().take(g.dim()) {
                    *x = rng.range(-2.0, 2.0);
                }
                Value::Vector(v)
            }
        };
        env.set(s, value);
    }
    if file_parameters {
        for &(s, v) in &l.values {
            env.set(s, v);
        }
    }
    let literal = state_literal(l, m, &env);
    (env, literal)
}

/// The generated `State` of `env`, as a block expression assigning each field (a field of
/// a big state is an entry of a role array, `position[3]`).
fn state_literal(l: &Loaded, m: &Module, env: &Env) -> String {
    let g = &l.system.graph;
    let mut literal = String::from("{ let mut s = State::default(); ");
    for (s, field) in &m.fields {
        match env.get(*s) {
            Some(Value::Scalar(x)) => {
                let _ = write!(literal, "s.{field} = {x:?}; ");
            }
            Some(Value::Vector(v)) => {
                let _ = write!(literal, "s.{field} = {:?}; ", &v[..g.dim()]);
            }
            Some(Value::Quaternion(_)) => panic!("`generate` refuses 3D rigid bodies: field {field}"),
            None => panic!("no value for field {field}"),
        }
    }
    literal.push_str("s }");
    literal
}

fn scalar(g: &Graph, id: lagrange::expr::Id, env: &Env) -> f64 {
    eval_one(g, id, env).expect("evaluates").scalar().expect("scalar")
}

fn vector(g: &Graph, id: lagrange::expr::Id, env: &Env) -> Vec<f64> {
    eval_one(g, id, env).expect("evaluates").components(g.dim())
}

/// What the generated functions must return, from the interpreter.
fn expected(l: &Loaded, d: &Derivation, env: &Env) -> Outputs {
    let g = &d.graph;
    let (dim, n, k) = (g.dim(), l.system.bodies.len(), d.constraints.len());
    let c: Vec<f64> = d.constraints.iter().map(|c| scalar(g, c.c, env)).collect();
    let mut a = vec![0.0; k * k];
    for &(r, col, id) in &d.a {
        let x = scalar(g, id, env);
        a[r * k + col] = x;
        a[col * k + r] = x;
    }
    let b: Vec<f64> = d.b.iter().map(|&id| scalar(g, id, env)).collect();
    let mut j = vec![0.0; k * n * dim];
    for (r, dc) in d.constraints.iter().enumerate() {
        for &(body, id) in &dc.jacobian {
            j[r * n * dim + body * dim..][..dim].copy_from_slice(&vector(g, id, env));
        }
    }
    let c_term: Vec<f64> = d.constraints.iter().map(|c| scalar(g, c.bias, env)).collect();
    // λ, the forces and the accelerations are what `lagrange solve` gives at this state
    // (inequalities by their contact state, the minimum-norm λ of a singular A).
    let solution = solved(l, d, env);
    let lambda = solution.lambda.clone();
    let forces: Vec<f64> = solution.constraint_force[..n].iter().flat_map(|f| f[..dim].to_vec()).collect();
    let accelerations: Vec<f64> = solution.acceleration[..n].iter().flat_map(|a| a[..dim].to_vec()).collect();
    let rates: Vec<f64> = d.constraints.iter().map(|c| scalar(g, c.c_dot, env)).collect();
    let applied: Vec<f64> = (0..n)
        .flat_map(|i| match l.scene.forces.iter().find(|f| f.0 == i) {
            Some(&(_, id)) => vector(g, id, env),
            None => vec![0.0; dim],
        })
        .collect();
    let rigid_outputs = rigid_expected(l, d, env, &solution);
    let mut outputs: Outputs = vec![
        ("constraints".into(), c),
        ("a_matrix".into(), a),
        ("b_vector".into(), b),
        ("jacobian".into(), j),
        ("c_term".into(), c_term),
        ("lambda".into(), lambda),
        ("forces".into(), forces),
        ("accelerations".into(), accelerations),
        ("constraint_rates".into(), rates),
        ("applied_forces".into(), applied),
    ];
    outputs.extend(rigid_outputs);
    outputs
}

/// What a module's rigid-body functions must return (nothing for point masses): the
/// constraint torques and α from `lagrange solve`'s angular slots, the state's θ, ω, 1/I,
/// the scene's torques and Jʷ (constraint by rigid body) from the interpreter.
fn rigid_expected(l: &Loaded, d: &Derivation, env: &Env, solution: &Solution) -> Outputs {
    let g = &d.graph;
    let system = &l.system;
    let rigid: Vec<usize> = angular_bodies(system).collect();
    if rigid.is_empty() {
        return Vec::new();
    }
    let slot = |i: usize| angular_slot(system, i).expect("a rigid body has an angular slot");
    let per_body = |f: &dyn Fn(&lagrange::model::system::Rigid) -> f64| -> Vec<f64> {
        rigid.iter().map(|&i| f(system.bodies[i].rigid.as_ref().expect("rigid"))).collect()
    };
    let (r, k) = (rigid.len(), d.constraints.len());
    let mut jw = vec![0.0; k * r];
    for (row, dc) in d.constraints.iter().enumerate() {
        for &(body, id) in &dc.angular {
            let col = rigid.iter().position(|&b| b == body).expect("Jʷ of a rigid body");
            jw[row * r + col] = scalar(g, id, env);
        }
    }
    vec![
        ("torques".into(), rigid.iter().map(|&i| solution.constraint_force[slot(i)][0]).collect()),
        ("angular_accelerations".into(), rigid.iter().map(|&i| solution.acceleration[slot(i)][0]).collect()),
        ("orientations".into(), per_body(&|b| scalar(g, b.nodes.orientation, env))),
        ("angular_velocities".into(), per_body(&|b| scalar(g, b.nodes.angular_velocity, env))),
        ("inverse_inertias".into(), per_body(&|b| 1.0 / scalar(g, b.inertia, env))),
        (
            "applied_torques".into(),
            rigid
                .iter()
                .map(|&i| l.scene.torques.iter().find(|t| t.0 == i).map_or(0.0, |&(_, id)| scalar(g, id, env)))
                .collect(),
        ),
        ("angular_jacobian".into(), jw),
    ]
}

/// What `lagrange solve` gives at `env`: the rows (the state's forces as given), the contact
/// length of the scene (its largest |r|), and the solve (rescaled where the raw rows overflow).
fn solved(l: &Loaded, d: &Derivation, env: &Env) -> Solution {
    let system = &l.system;
    let program = RowProgram::new(system, d, &[]);
    let length = system
        .bodies
        .iter()
        .filter_map(|b| env.get(b.position).and_then(|v| v.vector()))
        .map(|r| safe_norm(&r))
        .fold(0.0, f64::max);
    let settings =
        Settings { length_scale: if length > 0.0 && length.is_finite() { length } else { 1.0 }, ..Settings::default() };
    solve_at(&program, system, env, &settings).expect("evaluates").1
}

fn rustc() -> String {
    std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into())
}

/// A fresh directory `CARGO_TARGET_TMPDIR/DIR_NAME` holding the generated `code` as
/// `module.rs`, and the start of a harness that includes it and opens `main` (with `show`,
/// which prints a slice of numbers on one line).
fn harness_start(dir_name: impl AsRef<Path>, code: &str) -> (std::path::PathBuf, String) {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(dir_name);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let module_path = dir.join("module.rs");
    std::fs::write(&module_path, code).expect("write module");
    let mut main =
        format!("#[allow(dead_code)]\nmod system {{\n    include!({module_path:?});\n}}\nuse system::*;\n\n");
    main.push_str("fn show(xs: &[f64]) {\n    println!(\"{xs:?}\");\n}\n\nfn main() {\n");
    (dir, main)
}

/// Writes `main` as `dir/harness.rs`, compiles it with `rustc -D warnings` at opt-level 0
/// (compiling is most of these tests' time, 3–5× less than at opt-level 1; the outputs are
/// the same to round-off, `powi` being expanded differently), runs it, and returns its
/// standard output; panics with rustc's or the harness's stderr.
fn compile_and_run(dir: &Path, main: &str) -> String {
    let main_path = dir.join("harness.rs");
    std::fs::write(&main_path, main).expect("write harness");
    let exe = dir.join("harness");
    let out = Command::new(rustc())
        .args(["--edition", "2021", "-C", "opt-level=0", "-D", "warnings", "-o"])
        .arg(&exe)
        .arg(&main_path)
        .output()
        .expect("rustc runs (set RUSTC or put rustc on PATH)");
    assert!(out.status.success(), "generated code does not compile:\n{}", String::from_utf8_lossy(&out.stderr));
    let run = Command::new(&exe).output().expect("harness runs");
    assert!(run.status.success(), "harness failed: {}", String::from_utf8_lossy(&run.stderr));
    String::from_utf8_lossy(&run.stdout).into_owned()
}

#[test]
fn generated_rust_compiles_and_agrees_with_the_interpreter() {
    if common::skip_slow("generated_rust_compiles_and_agrees_with_the_interpreter") {
        return;
    }
    let mut cases = Vec::new();
    let mut rng = Rng(0x5eed_1234_abcd_0001);
    for path in files() {
        for specialize in [false, true] {
            let l = loaded(&path);
            let m = module(&l, &Options { specialize, ..Options::default() })
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            // The reference derivation, on a fresh load (the generator may have grown the graph).
            let reference = loaded(&path);
            let d = derive(&reference.system).expect("derives");
            let mut states = Vec::new();
            for _ in 0..STATES {
                let (env, literal) = random_state(&reference, &m, &mut rng, specialize);
                states.push((literal, expected(&reference, &d, &env)));
            }
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("file").replace('-', "_");
            let folder = if path.starts_with("constraints/joints") {
                "joints_"
            } else if path.starts_with("constraints/rigid") {
                "rigid_"
            } else {
                ""
            };
            let name = format!("{folder}{stem}{}", if specialize { "_specialized" } else { "" });
            let (rigid, banded) = (reference.system.has_rigid_bodies(), m.code.contains("pub fn a_band("));
            cases.push(Case { name, module: m, states, rigid, banded });
        }
    }
    // One crate: each module included in its own `mod`, and a main that prints every output.
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generate");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut main = String::from("// Test harness generated by tests/generate.rs.\n");
    for case in &cases {
        let file = dir.join(format!("{}.rs", case.name));
        std::fs::write(&file, &case.module.code).expect("write module");
        let _ = writeln!(main, "#[allow(dead_code)]\nmod {} {{\n    include!({:?});\n}}", case.name, file);
    }
    main.push_str("\nfn show(label: &str, xs: &[f64]) {\n    println!(\"{label} {xs:?}\");\n}\n\nfn main() {\n");
    for case in &cases {
        for (i, (literal, _)) in case.states.iter().enumerate() {
            let m = &case.name;
            let _ = writeln!(main, "    {{\n        use {m}::*;\n        let s = {literal};");
            for f in ["constraints", "b_vector", "c_term", "lambda", "constraint_rates"] {
                let _ = writeln!(main, "        show(\"{m} {i} {f}\", &{f}(&s));");
            }
            for f in ["a_matrix", "jacobian", "forces", "accelerations", "applied_forces"] {
                // A banded A (the 20-rod chain's 40 rows) is `a_band`: the big-chain tests compare it.
                if f == "a_matrix" && case.banded {
                    continue;
                }
                let _ = writeln!(main, "        show(\"{m} {i} {f}\", &{f}(&s).concat());");
            }
            if case.rigid {
                for f in &RIGID_OUTPUTS[..6] {
                    let _ = writeln!(main, "        show(\"{m} {i} {f}\", &{f}(&s));");
                }
                let _ = writeln!(main, "        show(\"{m} {i} angular_jacobian\", &angular_jacobian(&s).concat());");
            }
            main.push_str("    }\n");
        }
    }
    main.push_str("}\n");
    let stdout = compile_and_run(&dir, &main);
    let mut lines = stdout.lines();
    let (mut checked, mut expected_checks) = (0, 0);
    for case in &cases {
        let outputs: Vec<&str> = OUTPUTS
            .iter()
            .chain(if case.rigid { &RIGID_OUTPUTS[..] } else { &[] })
            .copied()
            .filter(|&f| !(f == "a_matrix" && case.banded))
            .collect();
        expected_checks += STATES * outputs.len();
        for (i, (_, expect)) in case.states.iter().enumerate() {
            for &f in &outputs {
                let line = lines.next().expect("one line per output");
                let (label, values) = line.split_once(" [").expect("label [values]");
                assert_eq!(label, format!("{} {i} {f}", case.name));
                let got: Vec<f64> = values
                    .trim_end_matches(']')
                    .split(", ")
                    .filter(|x| !x.is_empty())
                    .map(|x| x.parse().expect("a number"))
                    .collect();
                let want = &expect.iter().find(|e| e.0 == f).expect("expected output").1;
                assert_eq!(got.len(), want.len(), "{label}");
                let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
                for (x, y) in got.iter().zip(want) {
                    assert!((x - y).abs() <= 1e-9 * scale, "{label}: generated {got:?}, interpreter {want:?}");
                }
                checked += 1;
            }
        }
    }
    assert_eq!(checked, expected_checks);
    let rigid = cases.iter().filter(|c| c.rigid).count();
    assert!(rigid >= 2 * 12, "the rigid files were checked plain and specialised: {rigid} modules");
}

#[test]
fn hostile_names_become_safe_identifiers_and_comments() {
    let l = loaded(Path::new("tests/data/hostile_names.toml"));
    let m = module(&l, &Options::default()).expect("generates");
    let fields: Vec<&str> = m.fields.iter().map(|f| f.1.as_str()).collect();
    // Distinct, valid, not keywords.
    let mut sorted = fields.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(sorted.len(), fields.len(), "{fields:?}");
    for f in &fields {
        assert!(f.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'), "{f}");
        assert!(!f.starts_with(|c: char| c.is_ascii_digit()) && *f != "_", "{f}");
        assert!(!["self", "Self", "type", "mut", "fn", "super", "crate"].contains(f), "{f}");
    }
    // Names that are Rust identifiers stay as written; others follow the documented rule,
    // and the header lists every one.
    let field = |name: &str| {
        let g = &l.system.graph;
        m.fields.iter().find(|(s, _)| g.symbol(*s).name == name).map(|f| f.1.as_str()).expect(name)
    };
    for (name, ident) in [
        ("R", "R"),
        ("r", "r"),
        ("F", "F"),
        ("f_", "f_"),
        ("Self_", "Self_"),
        ("self", "self_"),
        ("type", "type_"),
        ("mut", "mut_"),
    ] {
        assert_eq!(field(name), ident, "{name}");
        assert!(m.code.contains(&format!("//   `{name}` → `{ident}`")), "{name} is listed in the header");
    }
    // No line of the module is a comment that a name could end early, and no raw control
    // or direction-changing characters survive.
    assert!(!m.code.contains('\u{202e}') && !m.code.contains('\r'));
    for line in m.code.lines() {
        let trimmed = line.trim_start();
        if trimmed.contains("panic!") {
            assert!(trimmed.starts_with("//"), "code injected from a name: {line}");
        }
    }
}

#[test]
fn specialised_code_carries_no_parameters() {
    let l = loaded(Path::new("constraints/bead_on_wire.toml"));
    let m = module(&l, &Options { specialize: true, ..Options::default() }).expect("generates");
    let g = &l.system.graph;
    let names: Vec<&str> = m.fields.iter().map(|(s, _)| g.symbol(*s).name.as_str()).collect();
    assert!(!names.contains(&"l") && !names.contains(&"m") && !names.contains(&"g"), "{names:?}");
    assert!(names.contains(&"r") && names.contains(&"v") && names.contains(&"F"), "{names:?}");
    let _: Vec<Symbol> = m.fields.iter().map(|f| f.0).collect();
}

/// The modules the benchmarks include are what the generator writes today.
#[test]
fn checked_in_generated_code_is_current() {
    use lagrange::codegen::layout::Solver;
    let soft = Some(Solver::SoftStep);
    for (n, file) in [(10, "benches/data/chain_10.toml"), (100, "benches/data/chain_100.toml")] {
        let on_disk = std::fs::read_to_string(file).expect("checked-in chain");
        assert!(
            on_disk == lagrange::scenario::chain(n),
            "{file} is stale: run `cargo run --release --example chain -- {n} > {file}`"
        );
    }
    for (file, solver, step_only, generated) in [
        ("constraints/bead_on_wire.toml", None, false, "benches/generated/bead_on_wire.rs"),
        ("benches/data/chain_10.toml", None, false, "benches/generated/chain_10.rs"),
        ("benches/data/chain_100.toml", None, false, "benches/generated/chain_100.rs"),
        ("constraints/joints/revolute.toml", None, false, "benches/generated/revolute.rs"),
        ("constraints/solvers/two_particles.toml", soft, false, "benches/generated/two_particles_step.rs"),
        ("constraints/solvers/ball_and_chain.toml", soft, false, "benches/generated/ball_and_chain_step.rs"),
        ("constraints/solvers/joint_grid_30.toml", soft, true, "benches/generated/joint_grid_30_step.rs"),
        (
            "constraints/solvers/rigid_ball_and_chain.toml",
            soft,
            false,
            "benches/generated/rigid_ball_and_chain_step.rs",
        ),
        ("constraints/solvers/rigid_grid_10.toml", soft, true, "benches/generated/rigid_grid_10_step.rs"),
    ] {
        let l = loaded(Path::new(file));
        let code =
            lagrange::codegen::generate(&l, &Options { solver, step_only, ..Options::default() }).expect("generates");
        let on_disk = std::fs::read_to_string(generated).expect("checked-in module");
        let mut flag = solver.map_or(String::new(), |s| format!(" --solver {}", s.name()));
        if step_only {
            flag.push_str(" --step-only");
        }
        assert!(
            code == on_disk,
            "{generated} is stale: run `cargo run --release -- generate {file}{flag} -o {generated}`"
        );
    }
}

/// Specialising a tiny parameter must not turn a finite formula into ∞·0: collecting over a
/// common denominator would need constants past f64's range.
#[test]
fn specialising_extreme_values_keeps_formulas_finite() {
    let text = std::fs::read_to_string("constraints/bead_on_wire.toml").expect("bead");
    let text = text.replace("l = 2.0", "l = 1e-200");
    assert!(text.contains("l = 1e-200"));
    let l = load(&text).expect("loads");
    let code = lagrange::codegen::generate(&l, &Options { specialize: true, ..Options::default() }).expect("generates");
    assert!(!code.contains("INFINITY") && !code.contains("NAN"), "{code}");
}

/// A chain of `n` links in 2D hanging from the origin, with its own mass per body.
fn chain_file(n: usize) -> String {
    chain_file_in_order(n, 1..=n)
}

/// [`chain_file`] with its constraints (links 1 ..= n) listed in the order given.
fn chain_file_in_order(n: usize, links: impl Iterator<Item = usize>) -> String {
    let mut t = format!("title = \"Chain of {n} links\"\ndimension = 2\n\n[parameters]\nl = 0.5\n");
    for i in 1..=n {
        let _ = write!(
            t,
            "\n[[bodies]]\nname = \"p{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\n\
             mass = \"m{i}\"\nforce = \"F{i}\"\n"
        );
    }
    for i in links {
        let link = if i == 1 { "r1".to_string() } else { format!("r{i} - r{}", i - 1) };
        let _ = write!(t, "\n[[constraints]]\nname = \"link{i}\"\nexpr = \"dot({link}, {link}) = l^2\"\n");
    }
    t
}

/// Past `DENSE_MAX` constraints a chain's A is generated as its band only (`a_band`, no
/// N×N array) and λ solved by band Cholesky; the compiled module agrees with the
/// interpreter at random states: the band entry by entry, b, and λ through the residual
/// of A λ + b = 0 with the interpreter's A.
#[test]
fn big_chains_get_a_banded_a_that_compiles_and_agrees() {
    if common::skip_slow("big_chains_get_a_banded_a_that_compiles_and_agrees") {
        return;
    }
    const LINKS: usize = 40;
    let text = chain_file(LINKS);
    let l = load(&text).expect("chain loads");
    let m = module(&l, &Options::default()).expect("generates");
    assert!(m.code.contains("pub const A_BANDWIDTH: usize = 1;"), "a chain is tridiagonal");
    assert!(m.code.contains("pub fn a_band(s: &State) -> [[f64; 2]; 40]"));
    assert!(!m.code.contains("fn a_matrix") && !m.code.contains("[[f64; 40]; 40]"), "no dense A");
    let reference = load(&text).expect("chain loads");
    let d = derive(&reference.system).expect("derives");
    let mut rng = Rng(0x0c4a_1150_0000_0040);
    let states: Vec<(Env, String)> = (0..STATES).map(|_| random_state(&reference, &m, &mut rng, false)).collect();

    let (dir, mut main) = harness_start("generate_band", &m.code);
    for (_, literal) in &states {
        let _ = writeln!(main, "    let s = {literal};");
        main.push_str("    show(&a_band(&s).concat());\n    show(&b_vector(&s));\n    show(&lambda(&s));\n");
        main.push_str("    show(&forces(&s).concat());\n");
    }
    main.push_str("}\n");
    let stdout = compile_and_run(&dir, &main);
    let mut lines = stdout.lines().map(|line| -> Vec<f64> {
        line.trim_matches(['[', ']']).split(", ").map(|x| x.parse().expect("a number")).collect()
    });
    let close = |x: f64, y: f64, scale: f64| (x - y).abs() <= 1e-9 * scale.max(1.0);
    for (env, _) in &states {
        let want = expected(&reference, &d, env);
        let get = |name: &str| &want.iter().find(|e| e.0 == name).expect(name).1;
        let (a, b, jac) = (get("a_matrix"), get("b_vector"), get("jacobian"));
        let (band, b_got, lambda, forces) =
            (lines.next().unwrap(), lines.next().unwrap(), lines.next().unwrap(), lines.next().unwrap());
        let a_scale = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for r in 0..LINKS {
            for w in 0..2 {
                let want = if r + w < LINKS { a[r * LINKS + r + w] } else { 0.0 };
                assert!(close(band[r * 2 + w], want, a_scale), "A[{r}][{}]: {} vs {want}", r + w, band[r * 2 + w]);
            }
        }
        let b_scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(b_got.iter().zip(b).all(|(x, y)| close(*x, *y, b_scale)), "b: {b_got:?} vs {b:?}");
        // A λ + b = 0 with the interpreter's A and b.
        let l_scale = lambda.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for r in 0..LINKS {
            let residual: f64 = (0..LINKS).map(|c| a[r * LINKS + c] * lambda[c]).sum::<f64>() + b[r];
            assert!(residual.abs() <= 1e-9 * (a_scale * l_scale + b_scale), "row {r}: residual {residual}");
        }
        // Forces = Jᵀ λ with the interpreter's J.
        for (i, f) in forces.iter().enumerate() {
            let want: f64 = (0..LINKS).map(|r| lambda[r] * jac[r * 2 * LINKS + i]).sum();
            assert!(close(*f, want, l_scale), "force component {i}: {f} vs {want}");
        }
    }
    assert!(lines.next().is_none());
}

/// Links of the big chain. Its dense J would be 500 × 1000 f64 = 4 MB, twice a spawned
/// thread's default 2 MiB stack, and the module takes rustc about 2–3 s.
const BIG_LINKS: usize = 500;

/// Parses a harness line `[x, y, …]`.
fn numbers(line: &str) -> Vec<f64> {
    line.trim_matches(['[', ']']).split(", ").filter(|x| !x.is_empty()).map(|x| x.parse().expect("a number")).collect()
}

/// A chain of hundreds of links (`scenario::chain`): J is written as its non-zero blocks on
/// the heap, A as its band, every big output filled in parts; the module compiles with
/// warnings denied and unoptimised (where stack frames are largest), every function runs in
/// a thread with a 2 MiB stack, and agrees with the interpreter at random states: C, the
/// band of A, b, c and the blocks of J entry by entry, λ through the residual of A λ + b = 0
/// with the interpreter's A, and the forces as Σₖ λₖ Jₖᵢ with the interpreter's J.
#[test]
fn a_chain_of_hundreds_of_links_runs_on_a_small_stack_and_agrees() {
    if common::skip_slow("a_chain_of_hundreds_of_links_runs_on_a_small_stack_and_agrees") {
        return;
    }
    const STATES: usize = 2;
    let text = lagrange::scenario::chain(BIG_LINKS);
    let l = load(&text).expect("chain loads");
    let m = module(&l, &Options::default()).expect("generates");
    let code = &m.code;
    assert!(code.contains("pub fn jacobian_blocks(s: &State) -> Vec<(usize, usize, [f64; 2])>"));
    assert!(code.contains(&format!("pub const JACOBIAN_BLOCKS: usize = {};", 2 * BIG_LINKS - 1)));
    assert!(code.contains(&format!("pub fn a_band(s: &State) -> [[f64; 2]; {BIG_LINKS}]")));
    assert!(!code.contains("fn jacobian(") && !code.contains("fn a_matrix"), "no dense J or A");
    // No array on the stack bigger than the state's own O(N) size (6 N numbers; generic
    // lengths skipped): the biggest is `band_system`'s, A's band and −b, 3 a row.
    for (at, _) in code.match_indices("[[f64; ") {
        let inner = code[at + 7..].split(']').next().and_then(|x| x.parse::<usize>().ok());
        let outer = code[at..].split("]; ").nth(1).and_then(|x| x.split(']').next()?.parse::<usize>().ok());
        if let (Some(inner), Some(outer)) = (inner, outer) {
            assert!(inner * outer <= 3 * BIG_LINKS, "an array of {inner} × {outer} f64");
        }
    }

    let reference = load(&text).expect("chain loads");
    let d = derive(&reference.system).expect("derives");
    let mut rng = Rng(0xb16c_4a11_0000_0500);
    let states: Vec<(Env, String)> = (0..STATES).map(|_| random_state(&reference, &m, &mut rng, false)).collect();

    let (dir, mut main) = harness_start("generate_big", code);
    for (_, literal) in &states {
        // The state is built on the main thread; every function runs on a 2 MiB stack.
        let _ = writeln!(main, "    let s = Box::new({literal});");
        main.push_str(
            "    std::thread::Builder::new()\n        .stack_size(2 << 20)\n        .spawn(move || {\n            \
             show(&constraints(&s));\n            show(&a_band(&s).concat());\n            show(&b_vector(&s));\n            \
             show(&c_term(&s));\n            \
             let j: Vec<f64> = jacobian_blocks(&s).iter().flat_map(|&(k, i, d)| [k as f64, i as f64, d[0], d[1]]).collect();\n            \
             show(&j);\n            show(&lambda(&s));\n            show(&forces(&s).concat());\n            \
             show(&force_p1(&s));\n        })\n        .expect(\"spawns\")\n        .join()\n        .expect(\"no overflow\");\n",
        );
    }
    main.push_str("}\n");
    let stdout = compile_and_run(&dir, &main);
    let mut lines = stdout.lines().map(numbers);

    let g = &d.graph;
    let k = BIG_LINKS;
    let close = |x: f64, y: f64, scale: f64| (x - y).abs() <= 1e-9 * scale.max(1.0);
    let max_abs = |xs: &[f64]| xs.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let agree = |what: &str, got: &[f64], want: &[f64]| {
        assert_eq!(got.len(), want.len(), "{what}");
        let scale = max_abs(want);
        for (i, (x, y)) in got.iter().zip(want).enumerate() {
            assert!(close(*x, *y, scale), "{what}[{i}]: generated {x}, interpreter {y}");
        }
    };
    for (env, _) in &states {
        let mut next = || lines.next().expect("one line per output");
        let (c, band, b, c_term, blocks, lambda, forces, force_p1) =
            (next(), next(), next(), next(), next(), next(), next(), next());
        let want = |ids: &mut dyn Iterator<Item = lagrange::expr::Id>| -> Vec<f64> {
            ids.map(|id| scalar(g, id, env)).collect()
        };
        agree("C", &c, &want(&mut d.constraints.iter().map(|c| c.c)));
        let b_want = want(&mut d.b.iter().copied());
        agree("b", &b, &b_want);
        agree("c", &c_term, &want(&mut d.constraints.iter().map(|c| c.bias)));
        // A: the interpreter's upper triangle, as band rows.
        let mut band_want = vec![0.0; 2 * k];
        for &(r, col, id) in &d.a {
            let (r, col) = (r.min(col), r.max(col));
            assert!(col - r <= 1, "a chain's A is tridiagonal");
            band_want[2 * r + col - r] = scalar(g, id, env);
        }
        agree("A band", &band, &band_want);
        // J: (k, i, d) blocks in the derivation's order.
        let mut j_want = Vec::new();
        for (r, dc) in d.constraints.iter().enumerate() {
            for &(body, id) in &dc.jacobian {
                j_want.extend([r as f64, body as f64]);
                j_want.extend(vector(g, id, env));
            }
        }
        agree("J blocks", &blocks, &j_want);
        // A λ + b = 0 with the interpreter's A.
        let a_scale = max_abs(&band_want);
        let (l_scale, b_scale) = (max_abs(&lambda), max_abs(&b_want));
        let mut residual = b_want.clone();
        for r in 0..k {
            residual[r] += band_want[2 * r] * lambda[r];
            if r + 1 < k {
                residual[r] += band_want[2 * r + 1] * lambda[r + 1];
                residual[r + 1] += band_want[2 * r + 1] * lambda[r];
            }
        }
        for (r, x) in residual.iter().enumerate() {
            assert!(x.abs() <= 1e-9 * (a_scale * l_scale + b_scale), "row {r}: residual {x}");
        }
        // Forces = Σₖ λₖ Jₖᵢ with the interpreter's J.
        let mut f_want = vec![0.0; 2 * k];
        for block in j_want.chunks(4) {
            let (r, body) = (block[0] as usize, block[1] as usize);
            f_want[2 * body] += lambda[r] * block[2];
            f_want[2 * body + 1] += lambda[r] * block[3];
        }
        agree("forces", &forces, &f_want);
        agree("force on p1", &force_p1, &f_want[..2]);
    }
    assert!(lines.next().is_none());
}

/// A chain whose constraints are listed odd links first, then even ones: A is not banded,
/// so past 16 constraints it is a dense `a_matrix` on the heap (rows filled in parts), λ by
/// Gaussian elimination on the heap, and J is `jacobian_blocks`.
#[test]
fn a_big_unbanded_system_gets_a_heap_a_that_compiles_and_agrees() {
    if common::skip_slow("a_big_unbanded_system_gets_a_heap_a_that_compiles_and_agrees") {
        return;
    }
    const LINKS: usize = 100;
    let text = chain_file_in_order(LINKS, (1..=LINKS).step_by(2).chain((2..=LINKS).step_by(2)));
    let code = sparse_j_agrees("heap_a", &text, 0x0dd5_e7e0_0000_0100);
    assert!(code.contains(&format!("pub fn a_matrix(s: &State) -> Vec<[f64; {LINKS}]>")), "a heap A");
    assert!(!code.contains("A_BANDWIDTH"));
}

/// Few constraints on many bodies (a 10-link chain, body 11 on a circle, 200 free bodies):
/// A stays a small dense array, but J (11 × 420 entries) is written as its 20 blocks.
#[test]
fn few_constraints_on_many_bodies_get_a_sparse_j() {
    if common::skip_slow("few_constraints_on_many_bodies_get_a_sparse_j") {
        return;
    }
    let mut text = chain_file(10);
    let bodies = text.find("\n[[constraints]]").expect("constraints");
    let free: String = (11..=210)
        .map(|i| {
            format!(
                "\n[[bodies]]\nname = \"p{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\n\
                 mass = \"m{i}\"\nforce = \"F{i}\"\n"
            )
        })
        .collect();
    text.insert_str(bodies, &free);
    text.push_str("\n[[constraints]]\nname = \"circle\"\nexpr = \"dot(r11, r11) = l^2\"\n");
    let code = sparse_j_agrees("many_bodies", &text, 0x0b0d_1e50_0000_0210);
    assert!(code.contains("pub fn a_matrix(s: &State) -> [[f64; 11]; 11]"), "a small dense A");
    assert!(code.contains("pub const JACOBIAN_BLOCKS: usize = 20;"));
}

/// Generates `text`'s module, checks J is `jacobian_blocks`, compiles it with warnings denied
/// and unoptimised, runs every function on a 2 MiB thread at two random states and compares
/// C, b, c, λ, A, J (made dense from its blocks) and the forces with the interpreter, entry by
/// entry. Returns the module's code.
fn sparse_j_agrees(name: &str, text: &str, seed: u64) -> String {
    let l = load(text).expect("loads");
    let m = module(&l, &Options::default()).expect("generates");
    assert!(m.code.contains("pub fn jacobian_blocks") && !m.code.contains("fn jacobian("), "a sparse J");
    let reference = load(text).expect("loads");
    let d = derive(&reference.system).expect("derives");
    let mut rng = Rng(seed);
    let states: Vec<(Env, String)> = (0..2).map(|_| random_state(&reference, &m, &mut rng, false)).collect();

    let (dir, mut main) = harness_start(format!("generate_{name}"), &m.code);
    for (_, literal) in &states {
        let _ = writeln!(main, "    let s = Box::new({literal});");
        main.push_str(
            "    std::thread::Builder::new()\n        .stack_size(2 << 20)\n        .spawn(move || {\n            \
             show(&constraints(&s));\n            show(&b_vector(&s));\n            show(&c_term(&s));\n            \
             show(&lambda(&s));\n            show(&a_matrix(&s).concat());\n            \
             let mut j = vec![0.0; CONSTRAINTS * BODIES * DIM];\n            \
             for (k, i, d) in jacobian_blocks(&s) {\n                \
             j[k * BODIES * DIM + i * DIM..][..DIM].copy_from_slice(&d);\n            }\n            \
             show(&j);\n            show(&forces(&s).concat());\n        })\n        .expect(\"spawns\")\n        \
             .join()\n        .expect(\"no overflow\");\n",
        );
    }
    main.push_str("}\n");
    let stdout = compile_and_run(&dir, &main);
    let mut lines = stdout.lines().map(numbers);
    for (env, _) in &states {
        let want = expected(&reference, &d, env);
        for f in ["constraints", "b_vector", "c_term", "lambda", "a_matrix", "jacobian", "forces"] {
            let got = lines.next().expect("one line per output");
            let want = &want.iter().find(|e| e.0 == f).expect(f).1;
            assert_eq!(got.len(), want.len(), "{f}");
            let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            for (i, (x, y)) in got.iter().zip(want).enumerate() {
                assert!((x - y).abs() <= 1e-9 * scale, "{name} {f}[{i}]: generated {x}, interpreter {y}");
            }
        }
    }
    assert!(lines.next().is_none());
    m.code
}

/// `constraints` is C as written and `jacobian` is ∇C/κ with κ = `SCALE`: a textbook Newton
/// projection on C with ∇C = SCALE·J converges (quadratically) from off the constraint, for
/// the bead (`dot(r,r) = l^2`, κ = 2) and the parabola.
#[test]
fn a_newton_projection_with_scale_converges() {
    if common::skip_slow("a_newton_projection_with_scale_converges") {
        return;
    }
    for (file, start) in
        [("constraints/bead_on_wire.toml", "[3.0, 0.5]"), ("constraints/bead_on_parabola.toml", "[1.5, 0.2]")]
    {
        let l = loaded(Path::new(file));
        let m = module(&l, &Options { specialize: true, ..Options::default() }).expect("generates");
        assert!(m.code.contains("pub const SCALE: [f64; 1]"), "{file}");
        let stem = Path::new(file).file_stem().and_then(|s| s.to_str()).unwrap_or("file");
        let (dir, mut main) = harness_start(format!("generate_newton_{stem}"), &m.code);
        let _ = writeln!(main, "    let mut s = State::default();\n    s.r = {start};");
        main.push_str(
            "    let mut steps = 0;\n    while constraints(&s)[0].abs() > 1e-13 && steps < 50 {\n        \
             let (c, j) = (constraints(&s)[0], jacobian(&s)[0]);\n        \
             let grad = [SCALE[0] * j[0], SCALE[0] * j[1]];\n        \
             let n2 = grad[0] * grad[0] + grad[1] * grad[1];\n        \
             s.r[0] -= c * grad[0] / n2;\n        s.r[1] -= c * grad[1] / n2;\n        steps += 1;\n    }\n    \
             show(&[steps as f64, constraints(&s)[0]]);\n}\n",
        );
        let out = compile_and_run(&dir, &main);
        let got = numbers(out.trim());
        assert!(got[0] < 10.0 && got[1].abs() <= 1e-13, "{file}: Newton took {} steps, |C| = {}", got[0], got[1]);
    }
}

/// A body's position, velocity and external force in 2D.
type BodyState = ([f64; 2], [f64; 2], [f64; 2]);

/// A state of `l` with the file's parameter values, t = 0 and each body's (r, v, F) as given.
fn state_of(l: &Loaded, bodies: &[BodyState]) -> Env {
    let mut env = Env::new();
    for &(s, v) in &l.values {
        env.set(s, v);
    }
    env.set(l.system.time, Value::Scalar(0.0));
    let v3 = |x: [f64; 2]| Value::Vector([x[0], x[1], 0.0]);
    for (b, &(r, v, f)) in l.system.bodies.iter().zip(bodies) {
        env.set(b.position, v3(r));
        env.set(b.velocity, v3(v));
        env.set(b.force, v3(f));
    }
    env
}

/// The code of a contact state in the harness's output (−1 for an equality).
fn contact_code(c: Option<lagrange::numeric::contact::ContactState>) -> f64 {
    use lagrange::numeric::contact::ContactState::*;
    match c {
        None => -1.0,
        Some(Apart) => 0.0,
        Some(Separating) => 1.0,
        Some(Resting) => 2.0,
        Some(Closing) => 3.0,
        Some(Penetrating) => 4.0,
    }
}

/// Compiles `text`'s module, calls `solution` at each state and compares λ, the contact
/// states, the status's being "solved" or not, the forces and the accelerations with what
/// `lagrange solve` gives there; returns the contact codes seen (by state).
fn agrees_with_solve(name: &str, text: &str, states: &[Vec<BodyState>]) -> Vec<Vec<f64>> {
    let l = load(text).expect("loads");
    let m = module(&l, &Options::default()).expect("generates");
    let d = derive(&l.system).expect("derives");
    let envs: Vec<Env> = states.iter().map(|s| state_of(&l, s)).collect();
    let (dir, mut main) = harness_start(format!("generate_solve_{name}"), &m.code);
    main.push_str(
        "    let code = |c: Option<Contact>| match c {\n        None => -1.0,\n        Some(Contact::Apart) => 0.0,\n        \
         Some(Contact::Separating) => 1.0,\n        Some(Contact::Resting) => 2.0,\n        Some(Contact::Closing) => 3.0,\n        \
         Some(Contact::Penetrating) => 4.0,\n    };\n",
    );
    for env in &envs {
        let _ = writeln!(main, "    let s = {};", state_literal(&l, &m, env));
        main.push_str(
            "    let x = solution(&s);\n    show(&x.lambda);\n    show(&x.contacts.iter().map(|c| code(*c)).collect::<Vec<f64>>());\n    \
             show(&[(x.status == Status::Solved) as u8 as f64, (x.status == Status::MinimumNorm) as u8 as f64]);\n    \
             show(&lambda(&s));\n    show(&forces(&s).concat());\n    show(&accelerations(&s).concat());\n",
        );
    }
    main.push_str("}\n");
    let stdout = compile_and_run(&dir, &main);
    let mut lines = stdout.lines().map(numbers);
    let mut seen = Vec::new();
    for (env, state) in envs.iter().zip(states) {
        let want = solved(&l, &d, env);
        let mut next = || lines.next().expect("one line per output");
        let (lambda, contacts, status, lambda_fn, forces, accelerations) =
            (next(), next(), next(), next(), next(), next());
        let close = |x: f64, y: f64, scale: f64| (x - y).abs() <= 1e-9 * scale.max(1.0);
        let scale = want.lambda.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (what, got) in [("solution().lambda", &lambda), ("lambda()", &lambda_fn)] {
            assert_eq!(got.len(), want.lambda.len());
            for (k, (x, y)) in got.iter().zip(&want.lambda).enumerate() {
                assert!(
                    close(*x, *y, scale),
                    "{name} at {state:?}: {what}[{k}] = {x}, solve gives {y} ({:?})",
                    want.status
                );
            }
        }
        let want_contacts: Vec<f64> = want.contacts.iter().map(|c| contact_code(*c)).collect();
        assert_eq!(contacts, want_contacts, "{name} at {state:?}: contact states");
        use lagrange::numeric::solve::Status as S;
        assert_eq!(
            status,
            [(want.status == S::Solved) as u8 as f64, (want.status == S::MinimumNorm) as u8 as f64],
            "{name} at {state:?}: status {:?}",
            want.status
        );
        let flat = |xs: &[[f64; 3]]| xs.iter().flat_map(|x| x[..2].to_vec()).collect::<Vec<f64>>();
        for (what, got, want) in [
            ("forces", &forces, flat(&want.constraint_force)),
            ("accelerations", &accelerations, flat(&want.acceleration)),
        ] {
            let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for (i, (x, y)) in got.iter().zip(&want).enumerate() {
                assert!(close(*x, *y, scale), "{name} at {state:?}: {what}[{i}] = {x}, solve gives {y}");
            }
        }
        seen.push(contacts);
    }
    assert!(lines.next().is_none());
    seen
}

/// `dot(r, r) <= l^2` (the rope pendulum, l = 2): the generated module gives what `solve`
/// gives when the bob is apart (inside), separating (moving in), resting and pushing
/// (at the bottom), resting but pulling (at the top at rest: λ = 0 by complementarity) and
/// closing (moving out); and `lambda`/`forces` are zero where the rope is slack.
#[test]
fn one_inequality_is_honoured_at_every_contact_state() {
    if common::skip_slow("one_inequality_is_honoured_at_every_contact_state") {
        return;
    }
    let text = std::fs::read_to_string("constraints/rope_pendulum.toml").expect("rope");
    let g = [0.0, -9.81];
    let states = vec![
        vec![([1.0, 0.0], [0.0, 1.0], g)],
        vec![([2.0, 0.0], [-1.0, 0.0], g)],
        vec![([0.0, -2.0], [1.0, 0.0], g)],
        vec![([0.0, 2.0], [0.0, 0.0], g)],
        vec![([2.0, 0.0], [1.0, 0.5], g)],
    ];
    let seen = agrees_with_solve("rope", &text, &states);
    assert_eq!(seen, [[0.0], [1.0], [2.0], [2.0], [3.0]], "apart, separating, resting, resting, closing");
}

/// Several rows, equalities and inequalities mixed: two bodies on a floor joined by a rope,
/// the first on a vertical guide. Where the rope or a floor would pull, the module's active
/// set gives `solve`'s λ (0 there) and forces.
#[test]
fn several_inequalities_are_honoured_as_solve_honours_them() {
    if common::skip_slow("several_inequalities_are_honoured_as_solve_honours_them") {
        return;
    }
    let mut text =
        String::from("title = \"Two boxes and a rope\"\ndimension = 2\n\n[parameters]\nl = 1.0\nm1 = 1.0\nm2 = 2.0\n");
    for i in 1..=2 {
        let _ = write!(
            text,
            "\n[[bodies]]\nname = \"box{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\nmass = \"m{i}\"\nforce = \"F{i}\"\n"
        );
    }
    for (name, expr) in [
        ("guide", "r1.x = 0"),
        ("floor1", "r1.y >= 0"),
        ("floor2", "r2.y >= 0"),
        ("rope", "dot(r2 - r1, r2 - r1) <= l^2"),
    ] {
        let _ = write!(text, "\n[[constraints]]\nname = \"{name}\"\nexpr = \"{expr}\"\n");
    }
    let (z, w1, w2) = ([0.0, 0.0], [0.0, -9.81], [0.0, -19.62]);
    let states = vec![
        // Both on the floor at rest, the rope taut but not needed.
        vec![(z, z, w1), ([1.0, 0.0], z, w2)],
        // Box 2 pulled away: the rope holds it, the guide holds box 1.
        vec![(z, z, w1), ([1.0, 0.0], z, [5.0, -19.62])],
        // Box 2 lifted and pulled: floor 2 would pull (λ = 0), the rope holds.
        vec![(z, z, w1), ([1.0, 0.0], z, [5.0, 30.0])],
        // Box 2 separating from the floor, the rope closing.
        vec![(z, z, w1), ([1.0, 0.0], [1.0, 1.0], w2)],
        // Box 1 in the air (apart), the rope slack.
        vec![([0.0, 0.5], z, w1), ([0.5, 0.0], z, w2)],
    ];
    let seen = agrees_with_solve("two_boxes", &text, &states);
    // (guide, floor1, floor2, rope)
    assert_eq!(seen[0], [-1.0, 2.0, 2.0, 2.0]);
    assert_eq!(seen[3], [-1.0, 2.0, 1.0, 3.0]);
    assert_eq!(seen[4], [-1.0, 0.0, 2.0, 0.0]);
}

/// A square of four masses with its four sides and both diagonals (one rod redundant): the
/// generated λ is `solve`'s minimum-norm λ (status "minimum-norm"), not NaN, at a state at
/// rest and at a spinning one.
#[test]
fn a_redundant_system_gives_solves_minimum_norm_lambda() {
    if common::skip_slow("a_redundant_system_gives_solves_minimum_norm_lambda") {
        return;
    }
    let mut text = String::from("title = \"Braced square\"\ndimension = 2\n\n[parameters]\nm = 1.0\n");
    for i in 1..=4 {
        let _ = write!(
            text,
            "\n[[bodies]]\nname = \"p{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\nmass = \"m\"\nforce = \"F{i}\"\n"
        );
    }
    let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    for (i, j) in [(1, 2), (2, 3), (3, 4), (4, 1), (1, 3), (2, 4)] {
        let (a, b) = (corners[i - 1], corners[j - 1]);
        let l2 = (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]);
        let _ = write!(
            text,
            "\n[[constraints]]\nname = \"rod{i}{j}\"\nexpr = \"dot(r{i} - r{j}, r{i} - r{j}) = {l2:?}\"\n"
        );
    }
    let g = [0.0, -9.81];
    let at_rest: Vec<_> = corners.iter().map(|&r| (r, [0.0, 0.0], g)).collect();
    // Spinning about the centre at ω = 2: v = ω × (r − c).
    let spinning: Vec<_> =
        corners.iter().map(|&r| (r, [-2.0 * (r[1] - 0.5), 2.0 * (r[0] - 0.5)], [1.0, -3.0])).collect();
    let l = load(&text).expect("loads");
    let d = derive(&l.system).expect("derives");
    for state in [&at_rest, &spinning] {
        let want = solved(&l, &d, &state_of(&l, state));
        assert_eq!(want.status, lagrange::numeric::solve::Status::MinimumNorm, "the square is redundant");
    }
    agrees_with_solve("braced_square", &text, &[at_rest, spinning]);
}

/// Two equalities (a bead on the unit circle held at x = 1): the 2×2 `dense_solution`
/// (Cramer's rule, the pivot rule multiplied out) answers at a regular state and hands over
/// to `solution` where A is singular (the two gradients parallel at (1, 0)), nearly so
/// (1 − cos² of their angle = 1e-12, below the rows' rank tolerance of 1e-10), or its
/// numbers leave f64's range (|r| = 1e155: A overflows; 1e-170: A₀₀ underflows); λ and the
/// forces are `solve`'s at every state either way.
#[test]
fn the_two_by_two_dense_solve_hands_over_where_a_is_singular_or_out_of_range() {
    if common::skip_slow("the_two_by_two_dense_solve_hands_over_where_a_is_singular_or_out_of_range") {
        return;
    }
    let text = "title = \"Bead on a circle held at x = 1\"\ndimension = 2\n\n[parameters]\nm = 1.5\n\n\
                [[bodies]]\nname = \"p\"\nposition = \"r\"\nvelocity = \"v\"\nacceleration = \"a\"\nmass = \"m\"\nforce = \"F\"\n\n\
                [[constraints]]\nname = \"circle\"\nexpr = \"dot(r, r) = 1\"\n\n[[constraints]]\nname = \"line\"\nexpr = \"r.x = 1\"\n";
    let g = [0.0, -9.81];
    let states: Vec<(bool, Vec<BodyState>)> = vec![
        (true, vec![([0.8, 0.6], [0.3, -0.4], g)]),
        (false, vec![([1.0, 0.0], [0.0, 1.0], g)]),
        (false, vec![([1.0, 1e-6], [0.0, 1.0], g)]),
        (false, vec![([0.6e155, 0.8e155], [0.8e155, -0.6e155], [0.0, -9.81e155])]),
        (false, vec![([0.6e-170, 0.8e-170], [0.8e-170, -0.6e-170], [0.0, -9.81e-170])]),
    ];
    let l = load(text).expect("loads");
    let m = module(&l, &Options::default()).expect("generates");
    assert!(m.code.contains("pub fn dense_solution"), "two equalities take the dense path");
    let d = derive(&l.system).expect("derives");
    let (dir, mut main) = harness_start("generate_dense_2x2", &m.code);
    let envs: Vec<Env> = states.iter().map(|(_, s)| state_of(&l, s)).collect();
    for env in &envs {
        let _ = writeln!(main, "    let s = {};", state_literal(&l, &m, env));
        main.push_str(
            "    show(&[dense_solution(&s).is_some() as u8 as f64]);\n    show(&lambda(&s));\n    show(&forces(&s).concat());\n",
        );
    }
    main.push_str("}\n");
    let stdout = compile_and_run(&dir, &main);
    let mut lines = stdout.lines().map(numbers);
    for ((dense, state), env) in states.iter().zip(&envs) {
        let mut next = || lines.next().expect("one line per output");
        let (flag, lambda, forces) = (next(), next(), next());
        assert_eq!(flag, [f64::from(u8::from(*dense))], "at {state:?}: dense_solution answers: {dense}");
        let want = solved(&l, &d, env);
        let wanted_forces: Vec<f64> = want.constraint_force[..1].iter().flat_map(|f| f[..2].to_vec()).collect();
        for (what, got, want) in [("lambda", &lambda, &want.lambda), ("forces", &forces, &wanted_forces)] {
            let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            assert_eq!(got.len(), want.len(), "{what}");
            for (x, y) in got.iter().zip(want) {
                assert!((x - y).abs() <= 1e-9 * scale, "at {state:?}: {what} {got:?}, solve gives {want:?}");
            }
        }
    }
}

/// A chain's λ by L D Lᵀ of A's band (`band_lambda`, here `solve_tridiagonal`: 5 links with
/// A a dense array, 20 with A its band) answers at a regular state and hands over to
/// `solution` where A is singular (a link of length 0: two bodies at one place) or its
/// numbers leave f64's range (lengths near 1e155: A overflows; 1e-170: its diagonal
/// underflows); λ and the forces are `solve`'s at every state either way.
#[test]
fn the_band_solve_hands_over_where_a_is_singular_or_out_of_range() {
    if common::skip_slow("the_band_solve_hands_over_where_a_is_singular_or_out_of_range") {
        return;
    }
    for links in [5, 20] {
        let l = load(&lagrange::scenario::chain(links)).expect("loads");
        let m = module(&l, &Options::default()).expect("generates");
        assert!(m.code.contains("solve_tridiagonal(&band_system(s))"), "a chain's A is tridiagonal");
        assert_eq!(m.code.contains("pub fn dense_solution"), links <= 16, "A dense up to 16 links");
        let d = derive(&l.system).expect("derives");
        // A zig-zag, moving, under gravity and a sideways push: every entry non-trivial.
        let zigzag = |scale: f64| -> Vec<BodyState> {
            (0..links)
                .map(|i| {
                    let x = i as f64;
                    let r = [0.5 * (x + 1.0) * scale, if i % 2 == 0 { 0.1 } else { -0.1 } * scale];
                    (r, [0.1 * x.sin() * scale, -0.05 * x.cos() * scale], [0.3 * scale, -9.81 * scale])
                })
                .collect()
        };
        let mut coincident = zigzag(1.0);
        coincident[3].0 = coincident[2].0;
        let states: Vec<(bool, Vec<BodyState>)> =
            vec![(true, zigzag(1.0)), (false, coincident), (false, zigzag(1e155)), (false, zigzag(1e-170))];
        let (dir, mut main) = harness_start(format!("generate_band_hand_over_{links}"), &m.code);
        let envs: Vec<Env> = states.iter().map(|(_, s)| state_of(&l, s)).collect();
        for env in &envs {
            let _ = writeln!(main, "    let s = {};", state_literal(&l, &m, env));
            main.push_str(
                "    show(&[band_lambda(&s).is_some() as u8 as f64]);\n    show(&lambda(&s));\n    show(&forces(&s).concat());\n",
            );
        }
        main.push_str("}\n");
        let stdout = compile_and_run(&dir, &main);
        let mut lines = stdout.lines().map(numbers);
        for (i, ((fast, _), env)) in states.iter().zip(&envs).enumerate() {
            let mut next = || lines.next().expect("one line per output");
            let (flag, lambda, forces) = (next(), next(), next());
            assert_eq!(flag, [f64::from(u8::from(*fast))], "{links} links, state {i}: band_lambda answers: {fast}");
            let want = solved(&l, &d, env);
            let wanted_forces: Vec<f64> = want.constraint_force.iter().flat_map(|f| f[..2].to_vec()).collect();
            for (what, got, want) in [("lambda", &lambda, &want.lambda), ("forces", &forces, &wanted_forces)] {
                let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
                assert!(
                    want.iter().all(|x| x.is_finite()) && scale > 0.0,
                    "{links} links, state {i}: solve gives {want:?}"
                );
                assert_eq!(got.len(), want.len(), "{what}");
                for (x, y) in got.iter().zip(want) {
                    assert!(
                        (x - y).abs() <= 1e-9 * scale,
                        "{links} links, state {i}: {what} {got:?}, solve gives {want:?}"
                    );
                }
            }
        }
    }
}

/// A 2 000-link chain: its `State` holds the bodies' symbols in role arrays (8 000 named
/// fields under `derive(PartialEq)` overflowed rustc's stack), the module compiles with
/// warnings denied, unoptimised, and its forces on a 2 MiB thread agree with `solve` at the
/// scene's initial state.
#[test]
fn a_chain_of_two_thousand_links_compiles() {
    if common::skip_slow("a_chain_of_two_thousand_links_compiles") {
        return;
    }
    const LINKS: usize = 2000;
    let text = lagrange::scenario::chain(LINKS);
    let l = load(&text).expect("chain loads");
    let m = module(&l, &Options::default()).expect("generates");
    assert!(m.code.contains(&format!("    pub position: [[f64; 2]; {LINKS}],")), "role arrays");
    assert!(m.code.contains("//   `r7` → `position[6]`"), "the header lists the mapping");
    let d = derive(&l.system).expect("derives");
    let mut env = Env::new();
    for &(s, v) in l.values.iter().chain(&l.scene.initial) {
        env.set(s, v);
    }
    env.set(l.system.time, Value::Scalar(0.0));
    let gravity = Value::Vector([0.0, -9.81, 0.0]);
    for b in &l.system.bodies {
        env.set(b.force, gravity);
    }
    let (dir, mut main) = harness_start("generate_chain_2000", &m.code);
    let _ = writeln!(main, "    let s = Box::new({});", state_literal(&l, &m, &env));
    main.push_str(
        "    std::thread::Builder::new()\n        .stack_size(2 << 20)\n        .spawn(move || show(&forces(&s).concat()))\n        \
         .expect(\"spawns\")\n        .join()\n        .expect(\"no overflow\");\n}\n",
    );
    let got = numbers(compile_and_run(&dir, &main).trim());
    let want = solved(&l, &d, &env);
    let want: Vec<f64> = want.constraint_force.iter().flat_map(|f| f[..2].to_vec()).collect();
    let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
    assert_eq!(got.len(), want.len());
    for (i, (x, y)) in got.iter().zip(&want).enumerate() {
        assert!((x - y).abs() <= 1e-9 * scale, "force component {i}: generated {x}, solve {y}");
    }
}

/// The huge pendulum (every length 1e155): r·r overflows, so the closed form would give
/// [−0, −0]; the generated forces are `solve`'s at a moving state.
#[test]
fn generated_forces_are_overflow_safe_where_solve_is() {
    if common::skip_slow("generated_forces_are_overflow_safe_where_solve_is") {
        return;
    }
    let text = std::fs::read_to_string("constraints/hard/huge.toml").expect("huge");
    let states = vec![
        vec![([0.6e155, -0.8e155], [0.8e155, 0.6e155], [0.0, -9.81e155])],
        vec![([1e155, 0.0], [0.0, 2e155], [0.0, -9.81e155])],
    ];
    agrees_with_solve("huge", &text, &states);
    let l = load(&text).expect("loads");
    let d = derive(&l.system).expect("derives");
    let want = solved(&l, &d, &state_of(&l, &states[0]));
    assert!(want.constraint_force[0][0].abs() > 1e154, "a real force: {:?}", want.constraint_force);
}

/// A constant past f64's range is written as `f64::INFINITY`, with a warning in the module
/// and in `Module::warnings` (which `generate` prints to stderr).
#[test]
fn an_infinite_constant_is_warned_about() {
    let text = std::fs::read_to_string("constraints/bead_on_parabola.toml").expect("parabola");
    let text = text.replace("expr = \"r.y = r.x^2\"", "expr = \"r.x*1e400 = 1\"");
    assert!(text.contains("1e400"));
    let l = load(&text).expect("loads");
    let m = module(&l, &Options::default()).expect("generates");
    assert!(m.code.contains("f64::INFINITY"));
    assert_eq!(m.warnings.len(), 1, "{:?}", m.warnings);
    assert!(m.code.contains("// Warning: constants of the formulas do not fit in f64"), "a note in the module");
    let plain =
        module(&loaded(Path::new("constraints/bead_on_parabola.toml")), &Options::default()).expect("generates");
    assert!(plain.warnings.is_empty() && !plain.code.contains("// Warning"));
}

/// `generate x.toml -o x.toml` (also through a symlink) is refused with a clear error and
/// leaves the input as it was; the warning of an infinite constant reaches stderr.
#[test]
fn generate_refuses_to_overwrite_its_input() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generate_same_file");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let input = dir.join("bead.toml");
    let original = std::fs::read_to_string("constraints/bead_on_wire.toml").expect("bead");
    std::fs::write(&input, &original).expect("write");
    let link = dir.join("link.toml");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&input, &link).expect("symlink");
    for out in [&input, &link] {
        let run = Command::new(env!("CARGO_BIN_EXE_lagrange"))
            .arg("generate")
            .arg(&input)
            .arg("-o")
            .arg(out)
            .output()
            .expect("runs");
        assert_eq!(run.status.code(), Some(2), "refused (bad options, docs/commands.md)");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(stderr.contains("is the input file") && stderr.contains("refusing to overwrite"), "{stderr}");
        assert_eq!(std::fs::read_to_string(&input).expect("still there"), original, "the input is intact");
    }
    let out = dir.join("bead.rs");
    let run = Command::new(env!("CARGO_BIN_EXE_lagrange"))
        .arg("generate")
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("runs");
    assert!(run.status.success() && std::fs::read_to_string(&out).expect("written").contains("pub fn solution"));
    let inf = dir.join("inf.toml");
    std::fs::write(&inf, original.replace("dot(r,r) = l^2", "r.x*1e400 = 1")).expect("write");
    let run = Command::new(env!("CARGO_BIN_EXE_lagrange")).arg("generate").arg(&inf).output().expect("runs");
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success() && stderr.contains("warning:") && stderr.contains("do not fit in f64"), "{stderr}");
}
