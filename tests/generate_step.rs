//! The generated step (`generate --solver soft-step|pgs|exact`) against the library's on
//! every file in `constraints/` and `constraints/hard/`, and on the rigid bodies' files
//! (`constraints/joints/` — the 2D joints from a random state off the joint —,
//! `constraints/rigid/`, the rigid scenes of `constraints/solvers/`): each module is
//! compiled (all of one solver in one rustc invocation, unoptimised but for the
//! `--step-only` one: [`runs_of`]), runs 1 000 steps of the scene's dt from its initial
//! state, and its positions, orientations (θ; a 3D body's q), velocities, angular
//! velocities (ω) and impulses are compared with the library's at steps 1, 10, 100 and
//! 1 000.
//!
//! The library's step is `numeric::velocity::Stepper` with its default settings, on the
//! library's own rows (`numeric::dynamics`, the compiled tape); a 3D body's orientation there
//! is exp(φ) ⊗ q₀ of its state's rotation vector and `Dynamics::orientations`.
//!
//! What holds (measured 2026-12-05): the soft step and PGS agree **bitwise** on every file at
//! every checkpoint (232 of them, 58 files: point masses, 2D and 3D rigid bodies) — the
//! module's rows are one function over the library's row roots in their order, so the tape's
//! numbers, and the step does the library's operations in its order (for 3D bodies the
//! rebase, the per-axis slots, the implicit-midpoint kick and the exact turn too). The exact
//! step agrees **within round-off**: its solve is the module's port of `numeric::solve`
//! (`solve_rows`), not the library's factorisations; 17 of its 56 files stay bitwise (`hard/huge`
//! leaves f64's range at the library's first step), the others part by at most 5.2e-11 of the
//! scene's scale after 1 000 steps (measured 2026-12-06 04:25 UTC, the 2D joints from random
//! states under their scenes' forces: the pulley; the rigid 20-link chain 8.1e-12, the ball
//! joint 4.8e-13, the 5-link chain 3.8e-13, the hinge 2.9e-13, the rest below 2.4e-13),
//! asserted at 1e-9, with two files apart (see the test). The count was 47 in an earlier
//! measurement, 16 of 55 on 2026-12-05. The exact comparison leaves out three big scenes for time ([`left_out`]).
//! The soft step's `--step-only` modules (rows by shape) are held to the library the same
//! way on eleven files, point masses and 2D and 3D rigid bodies, bit for bit (the eleventh a
//! 13 × 13 rigid grid, past `layout::MAX_STATE_FIELDS` inputs: its θ, ω, τ in role arrays). The harness
//! counts its allocations: the soft step and PGS allocate nothing in any of their 1 000
//! steps, rigid bodies included. The soft step and PGS run through the module's `Stepper`
//! (the rows the last step left kept where `KEEP`), and after the checkpoints each module
//! checks `Stepper` against `step` bit for bit over three steps with its first body moved
//! between them.
//!
//! Not here: the default module (`tests/generate.rs`), the snapshots (`tests/outputs.rs`).

mod common;

use lagrange::codegen::layout::Solver;
use lagrange::codegen::{Module, Options, module};
use lagrange::expr::eval::{Env, Value};
use lagrange::expr::{Role, Ty};
use lagrange::model::file::{Loaded, load};
use lagrange::numeric::dynamics::Dynamics;
use lagrange::numeric::rotation::turned;
use lagrange::scenario::Scenario;
use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Steps run, and the steps after which both runs are compared.
const STEPS: usize = 1000;
const CHECKPOINTS: [usize; 4] = [1, 10, 100, 1000];

/// Every file of `constraints/` and `constraints/hard/`, and the rigid bodies' files:
/// `constraints/joints/` (the 2D joints from a random state off the joint: [`scenario`]),
/// `constraints/rigid/` and `constraints/solvers/rigid_*`; gathered once.
fn files() -> Vec<PathBuf> {
    static FILES: std::sync::OnceLock<Vec<PathBuf>> = std::sync::OnceLock::new();
    FILES.get_or_init(gather).clone()
}

fn gather() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in ["constraints", "constraints/hard", "constraints/joints", "constraints/rigid", "constraints/solvers"] {
        let mut here: Vec<PathBuf> = std::fs::read_dir(dir)
            .expect("constraints/")
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .filter(|p| {
                let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("");
                dir != "constraints/solvers" || stem.starts_with("rigid_")
            })
            .filter(|p| scenario(p).is_some())
            .collect();
        here.sort();
        files.extend(here);
    }
    files
}

/// A file's scenario: its scene, or for a 2D joint of `constraints/joints/` a seeded random
/// state in place of the scene's initial one: positions, velocities, angles and ω in
/// [−1, 1), masses, inertias and the parameters without a value in [0.5, 2), the scene's
/// forces and torques (the generated module's `applied_forces`). Such a state is off the
/// joint, so the step pulls it together with large impulses: a harder case for agreeing bit
/// for bit than the joint files' own scenes (at rest, closed, gently driven).
fn scenario(path: &Path) -> Option<Scenario> {
    let mut l = loaded(path);
    if !path.starts_with("constraints/joints") || l.system.dim() != 2 {
        return Scenario::new(l, &[]).ok();
    }
    l.scene.initial.clear();
    let g = &l.system.graph;
    let mut rng = common::Rng::new(0x57e9_1015);
    let mut overrides = Vec::new();
    for (s, info) in g.symbols() {
        if l.values.iter().any(|v| v.0 == s) || g.is_quaternion(s) {
            continue;
        }
        let (low, high) = match info.role {
            Role::Position { .. } | Role::Velocity { .. } | Role::Orientation { .. } | Role::AngularVelocity { .. } => {
                (-1.0, 1.0)
            }
            Role::Mass { .. } | Role::Inertia { .. } | Role::Parameter => (0.5, 2.0),
            _ => continue,
        };
        let value = match info.ty {
            Ty::Scalar => Value::Scalar(rng.uniform(low, high)),
            Ty::Vector => Value::Vector(rng.uniform_vector(g.dim(), low, high)),
        };
        overrides.push((s, value));
    }
    Scenario::new(l, &overrides).ok()
}

fn loaded(path: &Path) -> Loaded {
    let text = std::fs::read_to_string(path).expect("readable");
    load(&text).unwrap_or_else(|e| panic!("{}: {e:?}", path.display()))
}

/// The generated `State` of `env`, as a block assigning each field. A 3D rigid body's q is
/// the orientation the library's rows are evaluated at, exp(0) ⊗ q₀ (`rotation::turned`).
fn state_literal(l: &Loaded, m: &Module, env: &Env) -> String {
    let dim = l.system.graph.dim();
    let mut literal = String::from("{ let mut s = State::default(); ");
    for (s, field) in &m.fields {
        match env.get(*s) {
            Some(Value::Scalar(x)) => {
                let _ = write!(literal, "s.{field} = {x:?}; ");
            }
            Some(Value::Vector(v)) => {
                let _ = write!(literal, "s.{field} = {:?}; ", &v[..dim]);
            }
            Some(Value::Quaternion(q)) => {
                let _ = write!(literal, "s.{field} = {:?}; ", turned([0.0; 3], q));
            }
            None => {}
        }
    }
    literal.push_str("s }");
    literal
}

/// One scene's run: its numbers at each checkpoint (positions, velocities, impulses).
type Run = Vec<Vec<f64>>;

/// The library's run of `solver` on `scenario`: `STEPS` steps of the scene's dt, by
/// `numeric::velocity::Stepper` with its default settings.
fn library_run(s: &Scenario, solver: Solver) -> Run {
    use lagrange::numeric::velocity::{Settings, Solver as Library, Stepper};
    let dim = s.system.graph.dim();
    let mut dynamics = Dynamics::new(&s.system, s.program.clone(), s.env.clone());
    let (mut q, mut v, t0) = lagrange::numeric::simulate::initial_state(&s.system, &s.env);
    let dt = s.scene.dt;
    let library = match solver {
        Solver::SoftStep => Library::SoftStep,
        Solver::Pgs => Library::Pgs,
        Solver::Exact => Library::Exact,
    };
    let mut stepper = Stepper::new(Settings::new(library, dt, STEPS as f64 * dt), s.system.constraints.len(), q.len());
    let mut out = Vec::new();
    for n in 0..STEPS {
        let t = t0 + n as f64 * dt;
        // The library stops where its rows leave f64's range; the comparison stops there too.
        let Ok(rows) = dynamics.rows(t, &q, &v) else { break };
        if stepper.step(&mut dynamics, t, &mut q, &mut v, rows).is_err() {
            break;
        }
        if CHECKPOINTS.contains(&(n + 1)) {
            // Positions, orientations (θ; a 3D body's exp(φ) ⊗ q₀), velocities, angular
            // velocities (ω; a 3D body's world ω), impulses: the module's order.
            let bodies = s.system.bodies.len();
            let three = dynamics.orientations().to_vec();
            let mut numbers: Vec<f64> = q[..bodies].iter().flat_map(|x| x[..dim].iter().copied()).collect();
            let slots = |x: &[[f64; 3]]| -> Vec<f64> {
                if three.is_empty() {
                    x[bodies..].iter().map(|x| x[0]).collect()
                } else {
                    x[bodies..].iter().step_by(3).flat_map(|w| *w).collect()
                }
            };
            if three.is_empty() {
                numbers.extend(slots(&q));
            } else {
                numbers.extend(q[bodies..].iter().step_by(3).zip(&three).flat_map(|(phi, q0)| turned(*phi, *q0)));
            }
            numbers.extend(v[..bodies].iter().flat_map(|x| x[..dim].iter().copied()));
            numbers.extend(slots(&v));
            numbers.extend(&stepper.impulse);
            out.push(numbers);
        }
    }
    out
}

/// The harness lines that run one module's step and print its checkpoints. The soft step and
/// PGS run by the module's `Stepper` (the rows the last step left kept); after the
/// checkpoints they print whether `Stepper` and `step` then agree bit for bit over three
/// steps with the first body moved by 1 mm before the second (the kept rows dropped).
fn harness_case(name: &str, l: &Loaded, m: &Module, s: &Scenario, sweeps: bool) -> String {
    let literal = state_literal(l, m, &s.env);
    let time = m.fields.iter().find(|f| f.0 == l.system.time).map(|f| f.1.clone());
    let t0 = lagrange::numeric::simulate::initial_state(&s.system, &s.env).2;
    let mut h = String::new();
    let impulses = if sweeps { "let mut w = Stepper::new();" } else { "let mut p = [0.0; CONSTRAINTS];" };
    let _ = writeln!(
        h,
        "    {{\n        use {name}::*;\n        let mut s = {literal};\n        {impulses}\n        \
         let mut allocations = 0;"
    );
    let _ = writeln!(h, "        for n in 0..{STEPS}usize {{");
    if let Some(t) = time {
        let _ = writeln!(h, "            s.{t} = {t0:?} + n as f64 * {:?};", s.scene.dt);
    }
    // The step's allocations, counted by the harness's allocator (`ALLOCATIONS`).
    let _ = writeln!(
        h,
        "            let before = ALLOCATIONS.load(Relaxed);\n            {};\n            \
         allocations += ALLOCATIONS.load(Relaxed) - before;",
        if sweeps {
            format!("w.step(&mut s, {:?})", s.scene.dt)
        } else {
            format!("step(&mut s, &mut p, {:?})", s.scene.dt)
        }
    );
    // The rigid bodies' θ and ω (3D: q and the world ω) after the bodies' x and v.
    let (orientations, angular) = match (l.system.has_rigid_bodies(), l.system.dim()) {
        (false, _) => ("", ""),
        (true, 2) => ("x.extend(orientations(&s));", "x.extend(angular_velocities(&s));"),
        (true, _) => ("x.extend(orientations(&s).concat());", "x.extend(angular_velocities(&s).concat());"),
    };
    let _ = writeln!(
        h,
        "            if {CHECKPOINTS:?}.contains(&(n + 1)) {{\n                \
         let mut x: Vec<f64> = positions(&s).concat();\n                {orientations}\n                \
         x.extend(velocities(&s).concat());\n                {angular}\n                \
         x.extend({});\n                println!(\"{name} {{x:?}}\");\n            }}\n        }}\n        \
         println!(\"{name} allocations {{allocations}}\");",
        if sweeps { "w.impulses" } else { "p" }
    );
    if sweeps {
        let body = m.fields.iter().find(|f| f.0 == l.system.bodies[0].position).map(|f| f.1.clone());
        let nudge = body.map_or(String::new(), |b| format!("a.{b}[0] += 1e-3;\n                s.{b}[0] += 1e-3;"));
        let _ = writeln!(
            h,
            "        let (mut a, mut p) = (s, w.impulses);\n        \
             for n in 0..3 {{\n            if n == 1 {{\n                {nudge}\n            }}\n            \
             step(&mut a, &mut p, {dt:?});\n            w.step(&mut s, {dt:?});\n        }}\n        \
             let bits = |x: Vec<f64>| x.iter().map(|x| x.to_bits()).collect::<Vec<_>>();\n        \
             let same = bits(positions(&a).concat()) == bits(positions(&s).concat())\n            \
             && bits(velocities(&a).concat()) == bits(velocities(&s).concat())\n            \
             && bits(p.to_vec()) == bits(w.impulses.to_vec());\n        \
             println!(\"{name} kept {{same}}\");",
            dt = s.scene.dt
        );
    }
    h.push_str("    }\n");
    h
}

/// The harness's global allocator: the system's, counting allocations (`ALLOCATIONS`) so
/// each case can say whether its steps allocated.
const COUNTING_ALLOCATOR: &str = "use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);
struct Counting;
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Relaxed);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}
#[global_allocator]
static COUNTING: Counting = Counting;
";

fn numbers(line: &str) -> Vec<f64> {
    let (_, values) = line.split_once(" [").expect("label [values]");
    values.trim_end_matches(']').split(", ").filter(|x| !x.is_empty()).map(|x| x.parse().expect("a number")).collect()
}

/// The scenes a solver's comparison leaves out for time: the exact step's rows' solve in the
/// module is dense (O(K³) per substep and projection), and unoptimised, so the 100-link
/// chain (53 s of the harness), the rigid ball and chain (82 rows) and the 10 × 10 rigid grid
/// (342 rows) would take minutes of the suite's 15.
fn left_out(solver: Solver, path: &Path) -> bool {
    let big = ["chain_100", "rigid_ball_and_chain", "rigid_grid_10"];
    solver == Solver::Exact && big.iter().any(|b| path.file_stem().is_some_and(|s| s == *b))
}

/// How many files `solver`'s comparison runs.
fn compared_files(solver: Solver) -> usize {
    files().iter().filter(|p| !left_out(solver, p)).count()
}

/// Compiles every file's module for `solver` in one crate, runs it, and returns per file
/// (name, library run, generated run).
fn both_runs(solver: Solver) -> Vec<(String, Run, Run)> {
    runs_of(solver, false, &files())
}

/// [`both_runs`] over `files`, their modules written with `--step-only` where asked.
fn runs_of(solver: Solver, step_only: bool, files: &[PathBuf]) -> Vec<(String, Run, Run)> {
    let which = format!("{}{}", solver.name().replace('-', "_"), if step_only { "_step_only" } else { "" });
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("generate_step_{which}"));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let mut main = String::from("// Test harness generated by tests/generate_step.rs.\n");
    main.push_str(COUNTING_ALLOCATOR);
    let mut body = String::new();
    let mut cases = Vec::new();
    for path in files {
        if left_out(solver, path) {
            continue;
        }
        let l = loaded(path);
        let m = module(&l, &Options { solver: Some(solver), step_only, ..Options::default() })
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let s = scenario(path).expect("a scenario");
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("file").replace('-', "_");
        let parent = path.parent().and_then(|p| p.file_name()).and_then(|p| p.to_str()).unwrap_or("");
        let name = if parent == "constraints" { stem } else { format!("{parent}_{stem}") };
        let file = dir.join(format!("{name}.rs"));
        std::fs::write(&file, &m.code).expect("write module");
        let _ = writeln!(main, "pub mod {name} {{\n    include!({file:?});\n}}");
        body.push_str(&harness_case(&name, &l, &m, &s, solver.sweeps()));
        cases.push((name, library_run(&s, solver)));
    }
    let _ = write!(main, "\nfn main() {{\n{body}}}\n");
    let main_path = dir.join("harness.rs");
    std::fs::write(&main_path, main).expect("write harness");
    let exe = dir.join("harness");
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    // Rust's floating point is the same IEEE operations at every level (no contraction, no
    // reassociation), so the level only trades compile time for run time. Unoptimised, the
    // harness of every module compiles in half the time and runs in 4–19 s; the
    // `--step-only` harness is small to compile but steps the 30 × 30 grid and the 13 × 13
    // rigid grid, 90 s unoptimised against 0.3 s at opt-level 1 (6 s to compile, measured
    // 2026-12-06).
    let level = if step_only { "opt-level=1" } else { "opt-level=0" };
    let out = Command::new(rustc)
        .args(["--edition", "2021", "-C", level, "-D", "warnings", "-o"])
        .arg(&exe)
        .arg(&main_path)
        .output()
        .expect("rustc runs (set RUSTC or put rustc on PATH)");
    assert!(out.status.success(), "generated code does not compile:\n{}", String::from_utf8_lossy(&out.stderr));
    let run = Command::new(&exe).output().expect("harness runs");
    assert!(run.status.success(), "harness failed: {}", String::from_utf8_lossy(&run.stderr));
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    let mut lines = stdout.lines();
    cases
        .into_iter()
        .map(|(name, library)| {
            let generated: Run = (0..CHECKPOINTS.len())
                .map(|_| {
                    let line = lines.next().expect("one line per checkpoint");
                    assert!(line.starts_with(&format!("{name} [")), "{line}");
                    numbers(line)
                })
                .collect();
            let line = lines.next().expect("the allocations line");
            let count = line.strip_prefix(&format!("{name} allocations ")).expect("allocations");
            // The soft step and PGS allocate nothing (`Prepared` and the slots in fixed arrays).
            // The exact step's rows are `Vec`s for `solve_rows`: its count shows the counter counts.
            if solver.sweeps() {
                assert_eq!(count, "0", "{name}: the {} step allocated over {STEPS} steps", solver.name());
                // `Stepper` and `step` the same bits, the kept rows dropped where a body moved.
                let line = lines.next().expect("the kept line");
                assert_eq!(line, format!("{name} kept true"), "{name}: `Stepper` and `step` part");
            } else {
                assert_ne!(count, "0", "{name}: no allocation counted in the exact step");
            }
            (name, library, generated)
        })
        .collect()
}

/// Same bits, or both NaN.
fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

fn bitwise(solver: Solver) {
    bitwise_runs(solver, both_runs(solver), compared_files(solver));
}

/// Every checkpoint of `runs` the same bits in both; at least three checkpoints per file.
fn bitwise_runs(solver: Solver, runs: Vec<(String, Run, Run)>, files: usize) {
    let mut compared = 0;
    for (name, library, generated) in runs {
        for (c, (want, got)) in library.iter().zip(&generated).enumerate() {
            assert_eq!(want.len(), got.len(), "{name}");
            compared += 1;
            for (i, (x, y)) in want.iter().zip(got).enumerate() {
                assert!(
                    same(*x, *y),
                    "{name}, {}: after step {}, number {i}: library {x:?}, generated {y:?}",
                    solver.name(),
                    CHECKPOINTS[c]
                );
            }
        }
    }
    eprintln!("{}: {compared} checkpoints equal bit for bit", solver.name());
    // Most files run all 1 000 steps in the library (a few hard ones leave f64's range).
    assert!(compared >= 3 * files, "only {compared} checkpoints compared");
}

/// `--step-only` modules write each repeated row shape once over a table of its instances;
/// their rows are cut out of the same program, so the soft step stays the library's bit for
/// bit: on Solver2D's point-mass scenes (the 30 × 30 grid's 1 711 rows and 870 bodies are a
/// few shapes, its anchors per-instance parameters; the stack's contacts are inequality
/// rows), on files whose rows read the time and parameters, and on rigid bodies (the 2D
/// rigid chain, a 2D revolute joint from a random state and the 3D ball joint: angular
/// slots, Jʷ projected on a 3D body's axes; the 20-link chain's links are one shape), and on
/// a rigid scene big enough for role arrays ([`big_rigid_grid`]).
#[test]
fn the_step_only_soft_step_is_the_librarys_bit_for_bit() {
    if common::skip_slow("the_step_only_soft_step_is_the_librarys_bit_for_bit") {
        return;
    }
    let files: Vec<PathBuf> = [
        "constraints/solvers/two_particles.toml",
        "constraints/solvers/ball_and_chain.toml",
        "constraints/solvers/stack.toml",
        "constraints/solvers/joint_grid_30.toml",
        "constraints/moving_circle.toml",
        "constraints/driven_pendulum.toml",
        "constraints/hard/bounce.toml",
        "constraints/rigid/chain_20.toml",
        "constraints/joints/revolute.toml",
        "constraints/joints/ball_3d.toml",
    ]
    .iter()
    .map(PathBuf::from)
    .chain([big_rigid_grid()])
    .collect();
    let n = files.len();
    bitwise_runs(Solver::SoftStep, runs_of(Solver::SoftStep, true, &files), n);
}

/// `examples/solver_scenes.rs`, for its `rigid_grid` (its other scenes and its `main` unused).
#[allow(dead_code)]
#[path = "../examples/solver_scenes.rs"]
mod scenes;

/// Box2D's joint grid as rigid discs, 13 × 13 (156 bodies, 600 revolute rows), written into
/// the test's temporary directory: past `layout::MAX_STATE_FIELDS` inputs, so its `State`
/// holds the bodies' x, v, F and the rigid bodies' θ, ω, τ in role arrays.
fn big_rigid_grid() -> PathBuf {
    let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join("rigid_grid_13.toml");
    std::fs::write(&path, scenes::rigid_grid(13)).expect("writes the scene");
    path
}

/// A big scene of 2D rigid bodies keeps their θ, ω and τ in role arrays indexed by the rigid
/// bodies' order, in the Rust step-only module and in the C module alike; its step is the
/// library's bit for bit (the step-only test above runs it 1 000 steps).
#[test]
fn a_big_rigid_scene_keeps_its_angles_in_role_arrays() {
    use lagrange::codegen::Lang;
    let l = loaded(&big_rigid_grid());
    let rigid = l.system.bodies.iter().filter(|b| b.rigid.is_some()).count();
    assert_eq!(rigid, 156);
    let options = Options { solver: Some(Solver::SoftStep), step_only: true, ..Options::default() };
    let m = module(&l, &options).expect("generates");
    for role in ["angle", "angular_velocity", "torque"] {
        assert!(m.code.contains(&format!("    pub {role}: [f64; {rigid}],")), "{role}");
    }
    // Body i's θ is the entry of its place among the rigid bodies (here every body is rigid).
    for (i, b) in l.system.bodies.iter().enumerate() {
        let r = b.rigid.as_ref().expect("rigid");
        let field = |s| m.fields.iter().find(|f| f.0 == s).map(|f| f.1.as_str());
        assert_eq!(field(r.orientation), Some(format!("angle[{i}]").as_str()));
        assert_eq!(field(r.angular_velocity), Some(format!("angular_velocity[{i}]").as_str()));
    }
    assert!(!m.code.contains("pub th_"), "no named angle fields");
    let c = module(&l, &Options { solver: Some(Solver::SoftStep), lang: Lang::C, ..Options::default() })
        .expect("generates C");
    for role in ["angle", "angular_velocity", "torque"] {
        assert!(c.code.contains(&format!("    double {role}[{rigid}];")), "C {role}");
    }
}

#[test]
fn the_generated_soft_step_is_the_librarys_bit_for_bit() {
    if common::skip_slow("the_generated_soft_step_is_the_librarys_bit_for_bit") {
        return;
    }
    bitwise(Solver::SoftStep);
}

#[test]
fn the_generated_pgs_step_is_the_librarys_bit_for_bit() {
    if common::skip_slow("the_generated_pgs_step_is_the_librarys_bit_for_bit") {
        return;
    }
    bitwise(Solver::Pgs);
}

#[test]
fn the_generated_exact_step_agrees_with_the_librarys_within_round_off() {
    if common::skip_slow("the_generated_exact_step_agrees_with_the_librarys_within_round_off") {
        return;
    }
    let mut report = Vec::new();
    for (name, library, generated) in both_runs(Solver::Exact) {
        // Per checkpoint: the largest difference relative to the run's largest number.
        let differences: Vec<f64> = library
            .iter()
            .zip(&generated)
            .map(|(want, got)| {
                let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
                want.iter()
                    .zip(got)
                    .fold(0.0f64, |m, (x, y)| if same(*x, *y) { m } else { m.max((x - y).abs() / scale) })
            })
            .collect();
        eprintln!("exact step: {name}: {differences:?}");
        report.push((name, differences));
    }
    assert!(
        report.len() == compared_files(Solver::Exact)
            && report.iter().filter(|r| r.1.len() == CHECKPOINTS.len()).count() >= report.len() - 1
    );
    for (name, differences) in &report {
        // Two files where the runs part, measured: the bead 1e-12 from the centre of its
        // circle (J ≈ 1e-12, C = −4: the module's `solve_rows` and `numeric::solve` give
        // different impulses for that nearly singular row, 49× the scene's scale apart
        // after one step), and the stiff mass ratio (1e9 : 1, unstable at this dt), where
        // the runs agree bit for bit through step 100 and a 1e-16 difference has grown to
        // the scene's scale by step 1 000.
        let checked = match name.as_str() {
            "hard_bead_near_centre" => 0,
            "hard_mass_ratio_stiff" => 3,
            _ => CHECKPOINTS.len(),
        };
        for (c, d) in differences.iter().enumerate().take(checked) {
            assert!(
                *d <= 1e-9,
                "{name}: after step {}, generated and library differ by {d:e} of the scale",
                CHECKPOINTS[c]
            );
        }
    }
}

/// A step-only module writes each repeated shape once: the 30 × 30 grid's 1 711 rows and 870
/// bodies are a handful of shape functions and its module a small fraction of the row-by-row
/// one (9.5 MB). The bound, `SMALL`, leaves room for the support code and the per-row tables
/// (`ROW_KIND`, `ROW_START`, `ROW_BODY`) to grow by a quarter; a module written row by row is
/// five times it and more.
#[test]
fn a_step_only_module_writes_each_shape_once() {
    const SMALL: usize = 250_000;
    let l = loaded(Path::new("constraints/solvers/joint_grid_30.toml"));
    let options = Options { solver: Some(Solver::SoftStep), step_only: true, ..Options::default() };
    let code = module(&l, &options).expect("generates").code;
    let shapes = code.matches("\nfn shape_").count();
    assert!((4..=8).contains(&shapes), "{shapes} shapes");
    assert!(code.len() < SMALL, "{} bytes", code.len());
    assert!(!code.contains("pub fn lambda(") && code.contains("pub fn step("));
    // Rigid bodies: the 10 × 10 rigid grid's 342 revolute rows and 90 bodies are a few dozen
    // shapes (bodies, rigid bodies and rows by where they sit), an eighth of the 1.6 MB module.
    let l = loaded(Path::new("constraints/solvers/rigid_grid_10.toml"));
    let code = module(&l, &options).expect("generates").code;
    let shapes = code.matches("\nfn shape_").count();
    assert!((3..=30).contains(&shapes), "{shapes} shapes");
    assert!(code.len() < SMALL, "{} bytes", code.len());
    assert!(code.contains("pub fn orientations(") && code.contains("pub fn angular_velocities("));
}

/// `--step-only` writes the soft step or PGS in Rust: without a solver, with the exact step
/// or in C it is refused before anything is written.
#[test]
fn step_only_needs_the_soft_step_or_pgs_in_rust() {
    use lagrange::codegen::{GenerateError, Lang};
    let l = loaded(Path::new("constraints/solvers/two_particles.toml"));
    let step_only = Options { step_only: true, ..Options::default() };
    for options in [
        step_only.clone(),
        Options { solver: Some(Solver::Exact), ..step_only.clone() },
        Options { solver: Some(Solver::SoftStep), lang: Lang::C, ..step_only },
    ] {
        assert_eq!(module(&l, &options).err(), Some(GenerateError::StepOnly), "{options:?}");
    }
}

/// `--step-only` takes a rigid body's sin θ and cos θ once per state (in `others`), not once
/// per row that reads them: the 20-link chain's module calls each once per link, where its
/// 40 rows called them for their bodies, 78 calls of each per `prepare` (same bits: the
/// step-only test above).
#[test]
fn the_step_only_module_takes_each_angles_sine_and_cosine_once() {
    let l = loaded(Path::new("constraints/rigid/chain_20.toml"));
    let options = Options { solver: Some(Solver::SoftStep), step_only: true, ..Options::default() };
    let code = lagrange::codegen::generate(&l, &options).expect("generates");
    let rigid = l.system.bodies.iter().filter(|b| b.rigid.is_some()).count();
    assert_eq!(rigid, 20);
    assert_eq!(code.matches(".sin()").count(), rigid, "{code}");
    assert_eq!(code.matches(".cos()").count(), rigid, "{code}");
}

/// `Stepper` keeps the rows where they read neither velocities nor time, and only there: on
/// Solver2D's scenes of point masses and 2D rigid bodies (`KEEP`), not on a moving
/// constraint (the driven pendulum's C reads t), a 3D body (its gyroscopic term reads ω) or
/// a force that reads a velocity. What it compares before using them is every field but the
/// time and the velocities: the parameters and positions, never `v`.
#[test]
fn the_stepper_keeps_rows_that_read_neither_velocities_nor_time() {
    let keep = |file: &str| {
        let l = loaded(Path::new(file));
        let options = Options { solver: Some(Solver::SoftStep), ..Options::default() };
        let code = lagrange::codegen::generate(&l, &options).expect("generates");
        assert!(code.contains("pub struct Stepper"), "{file}");
        (code.contains("const KEEP: bool = true;"), code)
    };
    for file in ["constraints/solvers/two_particles.toml", "constraints/solvers/rigid_ball_and_chain.toml"] {
        assert!(keep(file).0, "{file}");
    }
    // C reads t; a 3D body; a drag force F = m g − c v.
    for file in
        ["constraints/driven_pendulum.toml", "constraints/joints/ball_3d.toml", "constraints/damped_pendulum.toml"]
    {
        assert!(!keep(file).0, "{file}");
    }
    let (_, code) = keep("constraints/solvers/two_particles.toml");
    assert!(code.contains("same(&a.g, &b.g)") && code.contains("same(&a.r_p1, &b.r_p1)"));
    assert!(!code.contains("same(&a.v_p1"));
}

/// The rows the step takes as distance rows (`velocity::pattern`'s unit rows: |Jᵢ|² exactly
/// 1, so m_eff = 1/Σᵢ 1/mᵢ) are rows whose derivation gives it: κ = 1, no angular entry, and
/// each Jᵢ·Jᵢ simplifies to 1. Solver2D's point-mass scenes are all such rows; a pin of the
/// rigid grid is not one.
#[test]
fn the_unit_rows_are_those_whose_derivation_gives_unit_entries() {
    use lagrange::numeric::velocity::pattern::Pattern;
    let mut units = 0;
    for dir in ["constraints", "constraints/hard", "constraints/joints", "constraints/rigid", "constraints/solvers"] {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
            .expect("constraints/")
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml") && !p.ends_with("joint_grid_100.toml"))
            .collect();
        paths.sort();
        for path in paths {
            let Ok(l) = load(&std::fs::read_to_string(&path).expect("readable")) else { continue };
            let Ok(mut d) = lagrange::derive(&l.system) else { continue };
            let pattern = Pattern::of(&l.system);
            for (k, c) in d.constraints.clone().iter().enumerate().filter(|&(k, _)| pattern.is_unit(k)) {
                units += 1;
                let at = format!("{} row {k}", path.display());
                assert!(c.scale.is_one() && c.angular.is_empty(), "{at}");
                for &(_, j) in &c.jacobian {
                    let square = d.graph.dot(j, j).expect("a vector");
                    let square = d.simplifier.simplify(&mut d.graph, square).expect("simplifies");
                    assert!(d.graph.as_num(square).is_some_and(|q| q.is_one()), "{at}");
                }
            }
        }
    }
    assert!(units > 1711, "{units}");
    for (file, every) in
        [("two_particles", true), ("ball_and_chain", true), ("joint_grid_30", true), ("rigid_grid_10", false)]
    {
        let l = loaded(Path::new(&format!("constraints/solvers/{file}.toml")));
        let pattern = Pattern::of(&l.system);
        let rows = l.system.constraints.len();
        assert_eq!((0..rows).filter(|&k| pattern.is_unit(k)).count(), if every { rows } else { 0 }, "{file}");
    }
}

/// The axis rows (`velocity::pattern`: a distance row between two bodies of opposite signs,
/// whose sweep in a generated step reads one axis n and takes −n for the other entry) are
/// rows whose two entries the library evaluates as J and −J bit for bit: on every file with a
/// scene and on Solver2D's point-mass scenes, at the initial state and after each of 100
/// library soft steps. Solver2D's point-mass scenes are all axis rows but for those on an
/// anchor (one body); no rigid row is one.
#[test]
fn the_axis_rows_have_entries_j_and_minus_j_bit_for_bit() {
    use lagrange::numeric::velocity::pattern::Pattern;
    use lagrange::numeric::velocity::{Settings, Solver as Library, Stepper};
    let solvers = ["two_particles", "ball_and_chain", "joint_grid_30", "hanging_chain", "stretched_chain", "stack"];
    let mut axes = 0;
    for path in
        files().into_iter().chain(solvers.iter().map(|f| PathBuf::from(format!("constraints/solvers/{f}.toml"))))
    {
        let Some(s) = scenario(&path) else { continue };
        let dim = s.system.dim();
        let pattern = Pattern::of(&s.system);
        let marked: Vec<usize> = (0..s.system.constraints.len()).filter(|&k| pattern.is_axis(k)).collect();
        if marked.is_empty() {
            continue;
        }
        let mut dynamics = Dynamics::new(&s.system, s.program.clone(), s.env.clone());
        let (mut q, mut v, t0) = lagrange::numeric::simulate::initial_state(&s.system, &s.env);
        let dt = s.scene.dt;
        let settings = Settings::new(Library::SoftStep, dt, 100.0 * dt);
        let mut stepper = Stepper::new(settings, s.system.constraints.len(), q.len());
        for n in 0..=100 {
            let t = t0 + n as f64 * dt;
            let Ok(rows) = dynamics.rows(t, &q, &v) else { break };
            for &k in &marked {
                let j = &rows.rows[k].jacobian;
                assert_eq!(j.len(), 2, "{} row {k}", path.display());
                let bits = |x: &[f64; 3], sign: f64| x[..dim].iter().map(|x| (sign * x).to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&j[0].1, 1.0), bits(&j[1].1, -1.0), "{} row {k} step {n}", path.display());
                axes += 1;
            }
            if n == 100 || stepper.step(&mut dynamics, t, &mut q, &mut v, rows).is_err() {
                break;
            }
        }
    }
    assert!(axes > 100 * 1711, "{axes}");
    for (file, anchored) in [("two_particles", 1), ("ball_and_chain", 1), ("joint_grid_30", 30), ("rigid_grid_10", 342)]
    {
        let l = loaded(Path::new(&format!("constraints/solvers/{file}.toml")));
        let pattern = Pattern::of(&l.system);
        let rows = l.system.constraints.len();
        assert_eq!((0..rows).filter(|&k| !pattern.is_axis(k)).count(), anchored, "{file}");
    }
}
