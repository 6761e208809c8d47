//! `generate --lang c` against `generate --lang rust`, bit for bit: for every file in
//! `constraints/` (and `constraints/hard/`, `constraints/joints/`, `constraints/rigid/` —
//! θ, ω, τ, I and Jʷ too; 3D bodies at random unit quaternions, with q, world ω and τ, the
//! principal axes, the axis slots, world torques and α — and the hostile names of
//! `tests/data`), the C
//! module is compiled with `cc -std=c99 -Wall -Wextra -Werror -ffp-contract=off` (one
//! invocation per file: each module is its own translation unit) and the Rust modules with
//! `rustc -D warnings` (one invocation for all), both print every output at the same
//! random states, and every number must have the same bits (or both be NaN). The step
//! (`--solver soft-step`, `pgs` and `exact`, on every one of those files — each in one solver
//! in turn, and a few in all three: point masses, contacts, 2D and 3D rigid bodies)
//! likewise: 60 steps of 1/60 from random states, the positions,
//! orientations, velocities, angular velocities and impulses bit for bit (measured: every
//! number of every file), compiled unoptimised (`-O0`, `opt-level=0`: the same IEEE
//! operations, a shorter compile).
//!
//! Skipped, saying so, when no C compiler is found (`CC`, else `cc`, else `gcc`) and under
//! `LAGRANGE_QUICK_TESTS`.
//!
//! Not here: the Rust module against the library (`tests/generate.rs`, `tests/generate_step.rs`).

mod common;

use lagrange::codegen::layout::Solver;
use lagrange::codegen::{Lang, Module, Options, module};
use lagrange::expr::Ty;
use lagrange::expr::eval::{Env, Value};
use lagrange::model::file::{Loaded, load};
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Random states per file; the last has its lengths near 1e155 (see [`huge`]).
const STATES: usize = 4;

/// The files compared: `constraints/`, `constraints/hard/`, `constraints/joints/` and
/// `constraints/rigid/`, the hostile names, and two scenes whose A and J are mostly zeros.
fn files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    let dirs = ["constraints", "constraints/hard", "constraints/joints", "constraints/rigid"];
    for dir in dirs {
        let mut here: Vec<PathBuf> = std::fs::read_dir(dir)
            .expect("constraints/")
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        here.sort();
        files.extend(here);
    }
    files.push(PathBuf::from("tests/data/hostile_names.toml"));
    // A's band, A whole and J mostly zeros: written as their formulas over zeroed arrays.
    files.push(PathBuf::from("tests/data/net_8x3.toml"));
    files.push(PathBuf::from("tests/data/chain_20_interleaved.toml"));
    files
}

fn loaded(path: &Path) -> Loaded {
    let text = std::fs::read_to_string(path).expect("readable");
    load(&text).unwrap_or_else(|e| panic!("{}: {e:?}", path.display()))
}

/// A C compiler: `CC`, else the first of `cc`, `gcc` that runs.
fn c_compiler() -> Option<String> {
    let candidates = std::env::var("CC").into_iter().chain(["cc".to_string(), "gcc".to_string()]);
    candidates.into_iter().find(|c| Command::new(c).arg("--version").output().is_ok_and(|o| o.status.success()))
}

/// Random values for every symbol of the file (masses and parameters in [0.5, 2)).
fn random_env(l: &Loaded, rng: &mut common::Rng) -> Env {
    let g = &l.system.graph;
    let mut env = Env::new();
    for (s, info) in g.symbols() {
        if g.is_quaternion(s) {
            // 3D rigid bodies: a random unit quaternion [w, x, y, z].
            env.set(s, Value::Quaternion(common::random_quaternion(rng)));
            continue;
        }
        let value = match info.ty {
            Ty::Scalar
                if matches!(
                    info.role,
                    lagrange::expr::Role::Mass { .. }
                        | lagrange::expr::Role::Inertia { .. }
                        | lagrange::expr::Role::Parameter
                ) =>
            {
                Value::Scalar(rng.uniform(0.5, 2.0))
            }
            Ty::Scalar => Value::Scalar(rng.uniform(-2.0, 2.0)),
            // 3D principal moments, positive.
            Ty::Vector if matches!(info.role, lagrange::expr::Role::Inertia { .. }) => {
                Value::Vector(rng.uniform_vector(g.dim(), 0.5, 2.0))
            }
            Ty::Vector => Value::Vector(rng.uniform_vector(g.dim(), -1.0, 1.0)),
        };
        env.set(s, value);
    }
    env
}

/// `env` with every vector (positions, velocities, forces, vector parameters) times 1e155.
fn huge(l: &Loaded, env: &Env) -> Env {
    let mut out = Env::new();
    for (s, _) in l.system.graph.symbols() {
        match env.get(s) {
            Some(Value::Vector(v)) => out.set(s, Value::Vector(v.map(|x| x * 1e155))),
            Some(other) => out.set(s, other),
            None => {}
        }
    }
    out
}

/// Statements giving `s` the values of `env`, in Rust (`rust`) or C: one per field and component.
fn assignments(l: &Loaded, m: &Module, env: &Env, rust: bool) -> String {
    let dim = l.system.graph.dim();
    let mut out = String::new();
    for (s, field) in &m.fields {
        match env.get(*s) {
            Some(Value::Scalar(x)) => {
                let _ = write!(out, "s.{field} = {x:?}; ");
            }
            Some(Value::Vector(v)) => {
                for (d, x) in v.iter().enumerate().take(dim) {
                    let _ = write!(out, "s.{field}[{d}] = {x:?}; ");
                }
            }
            Some(Value::Quaternion(q)) => {
                for (d, x) in q.iter().enumerate() {
                    let _ = write!(out, "s.{field}[{d}] = {x:?}; ");
                }
            }
            None => {}
        }
    }
    if rust { format!("{{ let mut s = State::default(); {out}s }}") } else { out }
}

/// The outputs both modules have, with how each language flattens them.
struct Output {
    name: &'static str,
    /// The Rust expression of its numbers as a `Vec<f64>`.
    rust: String,
    /// The C array's declaration and its length in numbers.
    c_array: String,
    len: usize,
    /// C statements filling `out_NAME` when it is not one call of `NAME(&s, out_NAME)`.
    c_fill: Option<String>,
}

fn outputs(rust: &str) -> Vec<Output> {
    // The number right after `pattern` in the Rust module (a constant's value, an array's size).
    let count = |pattern: &str| -> usize {
        let at = rust.find(pattern).expect("the output exists") + pattern.len();
        rust[at..].chars().take_while(char::is_ascii_digit).collect::<String>().parse().expect("a size")
    };
    let mut list = Vec::new();
    let mut add = |name: &'static str, rust_expr: String, shape: String, len: usize| {
        list.push(Output { name, rust: rust_expr, c_array: format!("double out_{name}{shape}"), len, c_fill: None });
    };
    let k = count("pub const CONSTRAINTS: usize = ");
    let n = count("pub const BODIES: usize = ");
    let dim = count("pub const DIM: usize = ");
    for name in ["constraints", "constraint_rates", "b_vector", "c_term"] {
        add(name, format!("{name}(&s).to_vec()"), format!("[{}]", k.max(1)), k);
    }
    if rust.contains("pub fn a_band(") {
        let w = count("pub fn a_band(s: &State) -> [[f64; ");
        add("a_band", "a_band(&s).concat()".into(), format!("[{}][{w}]", k.max(1)), k * w);
    } else {
        add("a_matrix", "a_matrix(&s).concat()".into(), format!("[{0}][{0}]", k.max(1)), k * k);
    }
    if rust.contains("pub fn jacobian_blocks(") {
        let blocks = count("pub const JACOBIAN_BLOCKS: usize = ");
        add(
            "jacobian_blocks",
            "jacobian_blocks(&s).iter().flat_map(|b| b.2).collect()".into(),
            format!("[{}][{dim}]", blocks.max(1)),
            blocks * dim,
        );
    } else {
        add("jacobian", "jacobian(&s).concat()".into(), format!("[{}][{}]", k.max(1), (n * dim).max(1)), k * n * dim);
    }
    for name in ["positions", "velocities", "external_forces", "applied_forces"] {
        add(name, format!("{name}(&s).concat()"), format!("[{}][{dim}]", n.max(1)), n * dim);
    }
    add("inverse_masses", "inverse_masses(&s).to_vec()".into(), format!("[{}]", n.max(1)), n);
    // 3D rigid bodies: q as 4 numbers, world vectors, the principal axes, three axis slots each.
    let three = rust.contains("pub const ANGULAR_SLOTS: usize = ");
    if rust.contains("pub const RIGID: usize = ") {
        let r = count("pub const RIGID: usize = ");
        if three {
            add("orientations", "orientations(&s).concat()".into(), format!("[{r}][4]"), 4 * r);
            for name in ["angular_velocities", "external_torques", "applied_torques"] {
                add(name, format!("{name}(&s).concat()"), format!("[{r}][3]"), 3 * r);
            }
            add("body_axes", "body_axes(&s).concat().concat()".into(), format!("[{r}][3][3]"), 9 * r);
            for name in ["axis_inverse_inertias", "axis_angular_velocities", "axis_torques"] {
                add(name, format!("{name}(&s).to_vec()"), format!("[{}]", 3 * r), 3 * r);
            }
        } else {
            for name in
                ["orientations", "angular_velocities", "external_torques", "applied_torques", "inverse_inertias"]
            {
                add(name, format!("{name}(&s).to_vec()"), format!("[{r}]"), r);
            }
        }
        let r = if three { 3 * r } else { r };
        if rust.contains("pub fn angular_jacobian_blocks(") {
            let entries = count("pub const ANGULAR_BLOCKS: usize = ");
            add(
                "angular_jacobian_blocks",
                "angular_jacobian_blocks(&s).iter().map(|b| b.2).collect()".into(),
                format!("[{}]", entries.max(1)),
                entries,
            );
        } else {
            add("angular_jacobian", "angular_jacobian(&s).concat()".into(), format!("[{}][{r}]", k.max(1)), k * r);
        }
    }
    // The λ path: λ, the forces and accelerations (and torques, α), and the rows' solve
    // itself — λ, contact states (-1 for an equality, then Apart .. Penetrating as 0 .. 4),
    // forces and accelerations per slot, the status (Solved .. Failed as 0 .. 5).
    add("lambda", "lambda(&s).to_vec()".into(), format!("[{}]", k.max(1)), k);
    add("forces", "forces(&s).concat()".into(), format!("[{}][{dim}]", n.max(1)), n * dim);
    add("accelerations", "accelerations(&s).concat()".into(), format!("[{}][{dim}]", n.max(1)), n * dim);
    let mut slots = n;
    if rust.contains("pub const RIGID: usize = ") {
        let r = count("pub const RIGID: usize = ");
        if three {
            slots += 3 * r;
            add("torques", "torques(&s).concat()".into(), format!("[{r}][3]"), 3 * r);
            add("angular_accelerations", "angular_accelerations(&s).concat()".into(), format!("[{r}][3]"), 3 * r);
        } else {
            slots += r;
            add("torques", "torques(&s).to_vec()".into(), format!("[{r}]"), r);
            add("angular_accelerations", "angular_accelerations(&s).to_vec()".into(), format!("[{r}]"), r);
        }
    }
    // λ by L D Lᵀ of A's band (systems of equalities): the rows it solves, and whether it
    // answers (1, then λ) or gives up (0, then zeros).
    if rust.contains("pub fn band_system(") {
        let w = count("pub fn band_system(s: &State) -> [[f64; ");
        list.push(Output {
            name: "band_system",
            rust: "band_system(&s).concat()".into(),
            c_array: format!("double out_band_system[{k}][{w}]"),
            len: k * w,
            c_fill: None,
        });
        list.push(Output {
            name: "band_lambda",
            rust: format!("band_lambda(&s).map_or(vec![0.0; {}], |l| [1.0].into_iter().chain(l).collect())", k + 1),
            c_array: format!("double out_band_lambda[{}]", k + 1),
            len: k + 1,
            c_fill: Some(
                "out_band_lambda[0] = band_lambda(&s, out_band_lambda + 1);\n        \
                 if (out_band_lambda[0] == 0.0) { for (int i = 1; i <= CONSTRAINTS; i++) { out_band_lambda[i] = 0.0; } }"
                    .into(),
            ),
        });
    }
    let len = 2 * k + 2 * slots * dim + 1;
    list.push(Output {
        name: "solution",
        rust: "{ let x = solution(&s); x.lambda.iter().copied()\
               .chain(x.contacts.iter().map(|c| c.map_or(-1.0, |c| c as i32 as f64)))\
               .chain(x.force.iter().flatten().copied()).chain(x.acceleration.iter().flatten().copied())\
               .chain([x.status as i32 as f64]).collect() }"
            .into(),
        c_array: format!("double out_solution[{}]", len),
        len,
        c_fill: Some(
            "Solution x;\n        int at = 0;\n        solution(&s, &x);\n        \
             for (int i = 0; i < CONSTRAINTS; i++) { out_solution[at++] = x.lambda[i]; }\n        \
             for (int i = 0; i < CONSTRAINTS; i++) { out_solution[at++] = (double)x.contact[i]; }\n        \
             for (int i = 0; i < SLOTS; i++) { for (int d = 0; d < DIM; d++) { out_solution[at++] = x.force[i][d]; } }\n        \
             for (int i = 0; i < SLOTS; i++) { for (int d = 0; d < DIM; d++) { out_solution[at++] = x.acceleration[i][d]; } }\n        \
             out_solution[at++] = (double)x.status;"
                .into(),
        ),
    });
    list
}

/// The Rust side, compiling: `modules` are each module's declaration and its part of `main`,
/// in the order their lines are compared. They are split into two harnesses whose compiles
/// start here, at the same time, so that the C side compiles beside them (compiling every
/// module is the test's longest step, and one rustc keeps one core busy); [`RustBuild::output`]
/// runs them in turn, so the lines keep the modules' order. Unoptimised: about four times
/// shorter to compile than at opt-level 1, and Rust's floating point is the same IEEE
/// operations at every level (no contraction), so the numbers compared do not change.
struct RustBuild(Vec<(PathBuf, std::process::Child)>);

impl RustBuild {
    fn start(dir: &Path, modules: &[(String, String)]) -> RustBuild {
        let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
        let builds = modules
            .chunks(modules.len().div_ceil(2).max(1))
            .enumerate()
            .map(|(i, part)| {
                let mut code = String::from("// Test harness generated by tests/generate_c.rs.\n");
                part.iter().for_each(|(declaration, _)| code.push_str(declaration));
                code.push_str(SHOW);
                code.push_str("\nfn main() {\n");
                part.iter().for_each(|(_, body)| code.push_str(body));
                code.push_str("}\n");
                let (main_rs, exe) = (dir.join(format!("harness_{i}.rs")), dir.join(format!("harness_{i}")));
                std::fs::write(&main_rs, code).expect("write");
                let child = Command::new(&rustc)
                    .args(["--edition", "2021", "-C", "opt-level=0", "-D", "warnings", "-o"])
                    .arg(&exe)
                    .arg(&main_rs)
                    .stdout(std::process::Stdio::piped())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .expect("rustc runs");
                (exe, child)
            })
            .collect();
        RustBuild(builds)
    }

    /// Waits for the compiles, runs the harnesses in turn and returns their lines.
    fn output(self) -> String {
        let mut stdout = String::new();
        for (exe, child) in self.0 {
            let built = child.wait_with_output().expect("rustc runs");
            let error = String::from_utf8_lossy(&built.stderr);
            assert!(built.status.success(), "the Rust modules do not compile:\n{error}");
            let run = Command::new(&exe).output().expect("runs");
            assert!(run.status.success(), "Rust harness failed: {}", String::from_utf8_lossy(&run.stderr));
            stdout.push_str(&String::from_utf8_lossy(&run.stdout));
        }
        stdout
    }
}

/// Compiles the C harness `main_c` (`-std=c99 -Wall -Wextra -Werror -ffp-contract=off` at
/// `level`, `-O0` or `-O1`) next to it, runs it and returns its lines; `what` names it in a
/// failure.
fn c_output(cc: &str, main_c: &Path, level: &str, what: &str) -> String {
    let exe = main_c.with_extension("exe");
    let built = Command::new(cc)
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-ffp-contract=off", level, "-o"])
        .arg(&exe)
        .arg(main_c)
        .arg("-lm")
        .output()
        .expect("cc runs");
    assert!(built.status.success(), "{what}: the C code does not compile:\n{}", String::from_utf8_lossy(&built.stderr));
    let run = Command::new(&exe).output().expect("runs");
    assert!(run.status.success(), "{what}: C harness failed");
    String::from_utf8_lossy(&run.stdout).into_owned()
}

/// The harnesses' one printing function: every output is a line of its numbers in `{:?}`
/// (the shortest text that reads back to the same bits). One function, not a `println!` per
/// output: `main`'s thousands of closures took most of rustc's time (type checking 26 s of
/// 48 s for half of the modules, measured 2026-12-06).
const SHOW: &str = "
fn show(x: &[f64]) {
    println!(\"{}\", x.iter().map(|y| format!(\"{y:?}\")).collect::<Vec<_>>().join(\" \"));
}
";

fn numbers(line: &str) -> Vec<f64> {
    line.split_whitespace().map(|x| x.parse().unwrap_or_else(|_| panic!("a number: {x}"))).collect()
}

#[test]
fn the_c_module_gives_the_rust_modules_numbers_bit_for_bit() {
    if common::skip_slow("the_c_module_gives_the_rust_modules_numbers_bit_for_bit") {
        return;
    }
    let Some(cc) = c_compiler() else {
        eprintln!(
            "the_c_module_gives_the_rust_modules_numbers_bit_for_bit: skipped (no C compiler: set CC or install cc)"
        );
        return;
    };
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generate_c");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut rng = common::Rng::new(0xc0de_5eed);
    let mut modules = Vec::new();
    let mut c_mains = Vec::new();
    for path in files() {
        let l = loaded(&path);
        let rust = module(&l, &Options::default()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let c = module(&l, &Options { lang: Lang::C, ..Options::default() })
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("file").replace('-', "_");
        let name = format!("m{}_{stem}", c_mains.len());
        let rs = dir.join(format!("{name}.rs"));
        std::fs::write(&rs, &rust.code).expect("write");
        let declaration = format!("#[allow(dead_code)]\npub mod {name} {{\n    include!({rs:?});\n}}\n");
        let mut rust_body = String::new();
        let outs = outputs(&rust.code);
        let mut c_main = format!(
            "#include <stdio.h>\n#include \"{name}.c\"\n\nstatic void show(const double *x, int n) {{\n    for (int i = 0; i < n; i++) {{\n        printf(\"%.17g \", x[i]);\n    }}\n    printf(\"\\n\");\n}}\n\nint main(void) {{\n"
        );
        for state in 0..STATES {
            let mut env = random_env(&l, &mut rng);
            if state == STATES - 1 {
                // Lengths near 1e155: r·r overflows, so `solution` takes its change of length unit.
                env = huge(&l, &env);
            }
            let _ = writeln!(
                rust_body,
                // black_box: LLVM folds a constant `powi` with the host's `pow` (one rounding)
                // where the module at run time multiplies (as C's lg_powi does), so the states
                // must reach the functions as run-time values.
                "    {{\n        use {name}::*;\n        let s = std::hint::black_box({});",
                assignments(&l, &rust, &env, true)
            );
            let _ = writeln!(c_main, "    {{\n        State s = {{0}};\n        {}", assignments(&l, &c, &env, false));
            for o in &outs {
                let _ = writeln!(rust_body, "        let x: Vec<f64> = {};\n        show(&x);", o.rust);
                let fill = o.c_fill.clone().unwrap_or_else(|| format!("{}(&s, out_{});", o.name, o.name));
                let _ = writeln!(
                    c_main,
                    "        {{\n        {};\n        {fill}\n        show(&out_{}[0]{}, {});\n        }}",
                    o.c_array,
                    o.name,
                    "[0]".repeat(o.c_array.matches('[').count() - 1),
                    o.len
                );
            }
            rust_body.push_str("    }\n");
            c_main.push_str("    }\n");
        }
        c_main.push_str("    return 0;\n}\n");
        std::fs::write(dir.join(format!("{name}.c")), &c.code).expect("write");
        let main_c = dir.join(format!("{name}_main.c"));
        std::fs::write(&main_c, c_main).expect("write");
        c_mains.push((path.display().to_string(), outs.len(), main_c));
        modules.push((declaration, rust_body));
    }
    // The C modules compile at -O1 (the warnings GCC finds only when optimising, such as
    // -Wmaybe-uninitialized, are part of "clean") while the Rust harnesses compile.
    let rust = RustBuild::start(&dir, &modules);
    let c_runs: Vec<_> =
        c_mains.into_iter().map(|(file, count, main_c)| (c_output(&cc, &main_c, "-O1", &file), file, count)).collect();
    let stdout = rust.output();
    let mut rust_lines = stdout.lines();
    let mut compared = 0;
    for (c_out, file, count) in &c_runs {
        let mut c_lines = c_out.lines();
        for line in 0..STATES * count {
            let (r, c) = (numbers(rust_lines.next().expect("a Rust line")), numbers(c_lines.next().expect("a C line")));
            assert_eq!(r.len(), c.len(), "{file}: output {line}");
            for (x, y) in r.iter().zip(&c) {
                assert!(
                    x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
                    "{file}: output {line}: Rust {r:?}, C {c:?}"
                );
                compared += 1;
            }
        }
    }
    eprintln!("{compared} numbers equal bit for bit over {} files", c_runs.len());
    assert!(compared > 1000);
}

/// The solvers whose step file `i` of [`files`] is compared in: each file in one, in turn
/// (soft step, PGS, exact), so each solver's text is compiled with a third of the scenes and
/// each scene's rows and state accessors once; and every solver on a file of each kind (a
/// point mass, a contact, a 2D joint with a limit, a 3D hinge, the spinning top). Every pair
/// would be 171 modules and three times the compile. The 100-link chain, whose turn is the
/// exact step's, takes PGS instead: the exact step's rows' solve is dense (O(K³) a substep),
/// and its four runs took 22 s of the unoptimised Rust harness (measured 2026-12-06).
fn step_solvers(i: usize, path: &Path) -> Vec<Solver> {
    let is = |name: &str| path.file_stem().is_some_and(|s| s == name);
    let every = ["pendulum", "floor_rest", "revolute_limit", "hinge_3d", "spinning_top"];
    if every.iter().any(|e| is(e)) {
        vec![Solver::SoftStep, Solver::Pgs, Solver::Exact]
    } else {
        match [Solver::SoftStep, Solver::Pgs, Solver::Exact][i % 3] {
            Solver::Exact if is("chain_100") => vec![Solver::Pgs],
            solver => vec![solver],
        }
    }
}

/// Steps each state takes in the step comparison, of dt = 1/60.
const STEPS: usize = 60;

#[test]
fn the_c_step_gives_the_rust_steps_numbers_bit_for_bit() {
    if common::skip_slow("the_c_step_gives_the_rust_steps_numbers_bit_for_bit") {
        return;
    }
    let Some(cc) = c_compiler() else {
        eprintln!("the_c_step_gives_the_rust_steps_numbers_bit_for_bit: skipped (no C compiler: set CC or install cc)");
        return;
    };
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("generate_c_step");
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut rng = common::Rng::new(0x57e9_c0de);
    let mut modules = Vec::new();
    let mut c_mains = Vec::new();
    for (i, path) in files().into_iter().enumerate() {
        for solver in step_solvers(i, &path) {
            let l = loaded(&path);
            let options = Options { solver: Some(solver), ..Options::default() };
            let rust = module(&l, &options).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let c =
                module(&l, &Options { lang: Lang::C, ..options }).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let name = format!("m{}", c_mains.len());
            let rs = dir.join(format!("{name}.rs"));
            std::fs::write(&rs, &rust.code).expect("write");
            let declaration = format!("#[allow(dead_code)]\npub mod {name} {{\n    include!({rs:?});\n}}\n");
            let mut rust_body = String::new();
            let mut c_main = format!(
                "#include <stdio.h>\n#include \"{name}.c\"\n\nstatic void show(const double *x, int n) {{\n    int i;\n    \
                 for (i = 0; i < n; i++) {{\n        printf(\"%.17g \", x[i]);\n    }}\n}}\n\n\
                 int main(void) {{\n    int n, i;\n    double p[CONSTRAINTS > 0 ? CONSTRAINTS : 1];\n"
            );
            // The rigid bodies' θ and ω (3D: q and the world ω) after the bodies' x and v, as
            // the Rust module's `orientations` and `angular_velocities` give them.
            let (rust_turns, c_turns) = match (l.system.has_rigid_bodies(), l.system.dim()) {
                (false, _) => (("", ""), ("", "", "")),
                (true, 2) => (
                    (".chain(orientations(&s))", ".chain(angular_velocities(&s))"),
                    (
                        "double o[RIGID], w[RIGID];",
                        "orientations(&s, o);\n        show(o, RIGID);",
                        "angular_velocities(&s, w);\n        show(w, RIGID);",
                    ),
                ),
                (true, _) => (
                    (".chain(orientations(&s).concat())", ".chain(angular_velocities(&s).concat())"),
                    (
                        "double o[RIGID][4], w[RIGID][3];",
                        "orientations(&s, o);\n        show(&o[0][0], 4 * RIGID);",
                        "angular_velocities(&s, w);\n        show(&w[0][0], 3 * RIGID);",
                    ),
                ),
            };
            for _ in 0..STATES {
                let env = random_env(&l, &mut rng);
                let _ = writeln!(
                    rust_body,
                    "    {{\n        use {name}::*;\n        let mut s = {};\n        let mut p = [0.0; CONSTRAINTS];\n        \
                     for _ in 0..{STEPS} {{\n            step(&mut s, &mut p, 1.0 / 60.0);\n        }}\n        \
                     show(&positions(&s).concat().into_iter(){}.chain(velocities(&s).concat()){}.chain(p).collect::<Vec<f64>>());\n    }}",
                    assignments(&l, &rust, &env, true),
                    rust_turns.0,
                    rust_turns.1
                );
                let _ = writeln!(
                    c_main,
                    "    {{\n        State s = {{0}};\n        double q[BODIES > 0 ? BODIES : 1][DIM], v[BODIES > 0 ? BODIES : 1][DIM];\n        {}\n        {}\n        \
                     for (i = 0; i < CONSTRAINTS; i++) {{\n            p[i] = 0.0;\n        }}\n        \
                     for (n = 0; n < {STEPS}; n++) {{\n            step(&s, p, 1.0 / 60.0);\n        }}\n        \
                     positions(&s, q);\n        show(&q[0][0], BODIES * DIM);\n        {}\n        \
                     velocities(&s, v);\n        show(&v[0][0], BODIES * DIM);\n        {}\n        \
                     show(p, CONSTRAINTS);\n        printf(\"\\n\");\n    }}",
                    c_turns.0,
                    assignments(&l, &c, &env, false),
                    c_turns.1,
                    c_turns.2
                );
            }
            c_main.push_str("    return 0;\n}\n");
            std::fs::write(dir.join(format!("{name}.c")), &c.code).expect("write");
            let main_c = dir.join(format!("{name}_main.c"));
            std::fs::write(&main_c, c_main).expect("write");
            c_mains.push((format!("{} ({})", path.display(), solver.name()), main_c));
            modules.push((declaration, rust_body));
        }
    }
    let rust = RustBuild::start(&dir, &modules);
    let c_runs: Vec<_> =
        c_mains.into_iter().map(|(case, main_c)| (c_output(&cc, &main_c, "-O0", &case), case)).collect();
    let stdout = rust.output();
    let mut rust_lines = stdout.lines();
    let mut compared = 0;
    for (c_out, case) in &c_runs {
        for (state, c_line) in c_out.lines().enumerate() {
            let (r, c) = (numbers(rust_lines.next().expect("a Rust line")), numbers(c_line));
            assert_eq!(r.len(), c.len(), "{case}: state {state}");
            for (x, y) in r.iter().zip(&c) {
                assert!(
                    x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()),
                    "{case}: state {state}: Rust {r:?}, C {c:?}"
                );
                compared += 1;
            }
        }
    }
    eprintln!("step: {compared} numbers equal bit for bit after {STEPS} steps, {} modules", c_runs.len());
    assert!(compared > 1000);
}

/// Where A's band, A whole or J is mostly zeros (a net's band, a chain listed out of order, a
/// dense J of many bodies), the C module zeroes the array in one loop and writes only its
/// formulas, and the Rust module writes only its formulas over the zeros it starts from: a
/// grid's module stays proportional to its formulas, not to its band. A band with one zero (a
/// chain's) is still written whole. (The numbers are compared in the two tests above and in
/// tests/generate.rs.)
#[test]
fn arrays_of_mostly_zeros_are_written_as_their_formulas() {
    // The body of function `name` (from its signature, which starts with `head`), if written.
    let body = |code: &str, head: &str| {
        let start = code.find(head)?;
        Some(code[start..start + code[start..].find("\n}\n").expect("a function ends")].to_string())
    };
    // The statements `out[i][j] = 0.0;` with literal indices: a zero written in place.
    let zeros_in_place = |body: &str| {
        body.lines()
            .filter(|l| {
                let l = l.trim();
                l.starts_with("out[") && l.ends_with("= 0.0;") && !l.starts_with("out[r]")
            })
            .count()
    };
    let arrays = ["a_band", "band_system", "a_matrix", "jacobian"];
    for file in ["tests/data/net_8x3.toml", "tests/data/chain_20_interleaved.toml"] {
        let l = loaded(Path::new(file));
        let c = module(&l, &Options { lang: Lang::C, ..Options::default() }).expect("generates");
        let rust = module(&l, &Options::default()).expect("generates");
        let (mut written, mut rust_written) = (0, 0);
        for f in arrays {
            if let Some(b) = body(&c.code, &format!("void {f}(")) {
                assert_eq!(zeros_in_place(&b), 0, "{file}: C's {f} writes a zero in place");
                assert!(b.contains("out[r][d] = 0.0;"), "{file}: C's {f} zeroes its array in a loop");
                written += 1;
            }
            if let Some(b) = body(&rust.code, &format!("pub fn {f}(")) {
                assert!(!b.contains(" 0.0,") && !b.contains("[0.0, "), "{file}: Rust's {f} writes zeros:\n{b}");
                rust_written += 1;
            }
        }
        assert!(written >= 2, "{file}: C's A and J are written");
        assert!(rust_written >= 2, "{file}: Rust's A and J are written");
    }
    let l = loaded(Path::new("constraints/chain_5.toml"));
    let c = module(&l, &Options { lang: Lang::C, ..Options::default() }).expect("generates");
    let a = body(&c.code, "void a_matrix(").expect("a small A is dense");
    assert!(zeros_in_place(&a) > 0 && !a.contains("out[r][d] = 0.0;"), "a small A is written whole:\n{a}");
}
