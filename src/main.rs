//! The `lagrange` command line: parse arguments, call the library, print. Nothing else.

/// mimalloc: a derivation allocates and frees many small forms; with it a derivation takes
/// 15–18 % fewer instructions than with the system allocator (README, Speed).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use clap::{Parser, Subcommand, ValueEnum};
use lagrange::codegen::layout::Solver;
use lagrange::codegen::{Lang, Options, module};
use lagrange::derive::{Options as DeriveOptions, derive, derive_with};
use lagrange::expr::Symbol;
use lagrange::expr::eval::Value;
use lagrange::model::file::{Loaded, Problem, load};
use lagrange::model::scene::environment;
use lagrange::model::state;
use lagrange::model::system::System;
use lagrange::numeric::rescale::solve_at;
use lagrange::numeric::rows::RowProgram;
use lagrange::numeric::solve::{Settings, safe_norm};
use lagrange::report::derivation::{self, Format};
use lagrange::report::diagnostic::render;
use lagrange::report::solution;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

/// Derive constraint forces from constraints written as text.
///
/// A constraint file (TOML) declares bodies (point masses), parameters and position
/// constraints such as `dot(r,r) = l^2`. lagrange differentiates each constraint twice in
/// time, finds the force directions ∇C, and solves for the Lagrange multipliers λ.
#[derive(Parser, Debug)]
#[command(name = "lagrange", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print C, Ċ, C̈, ∇C, the λ equation, λ and the force on each body.
    Derive {
        /// The constraint file (TOML).
        file: PathBuf,
        /// Output format; JSON expressions are strings in the expression language.
        #[arg(long, value_enum, default_value_t = FormatArg::Text)]
        format: FormatArg,
        /// Walk through the derivation step by step, as the article does.
        #[arg(long)]
        steps: bool,
    },
    /// Write source code for the formulas: plain functions, no dependency on lagrange.
    Generate {
        /// The constraint file (TOML).
        file: PathBuf,
        /// The language to write.
        #[arg(long, value_enum, default_value_t = LangArg::Rust)]
        lang: LangArg,
        /// Write to this file instead of stdout.
        #[arg(short = 'o', long = "output")]
        output: Option<PathBuf>,
        /// Write the file's parameter values into the formulas (only what the scene needs).
        #[arg(long)]
        specialize: bool,
        /// Also write the velocity-level step an engine runs, `step(state, impulses, h)`,
        /// for this solver (Box2D v3's soft step, PGS, or the exact velocity solve).
        #[arg(long, value_enum)]
        solver: Option<SolverArg>,
    },
    /// Numbers at a state: C, Ċ and λ per constraint, force and acceleration per body.
    ///
    /// The state is the file's [parameters] and [scene] initial values, then `--at`, then
    /// each `--set` (later wins); forces come from [scene] forces unless given. `value`,
    /// `rate` and `lambda` refer to C/κ, like `derive --format json` (whose `gradient` is
    /// ∇C/κ, `scale` κ): the force on a body is Σ λ·gradient. A missing or non-finite value
    /// is an error naming the symbol (exit 1).
    Solve {
        /// The constraint file (TOML).
        file: PathBuf,
        /// A state file (.toml or .json): a flat table symbol = number or [x, y(, z)], for
        /// positions, velocities, forces, masses, parameters and `t`.
        #[arg(long, value_name = "STATE")]
        at: Option<PathBuf>,
        /// Override one symbol: NAME=NUMBER or NAME=[x,y]; may repeat.
        #[arg(long = "set", value_name = "NAME=VALUE")]
        set: Vec<String>,
        /// Output format.
        #[arg(long, value_enum, default_value_t = SolveFormat::Text)]
        format: SolveFormat,
    },
    /// Run the files' [[expect]] entries; exit non-zero on any failure.
    Check {
        /// Constraint files (TOML).
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// Run the scene: integrate, stabilise, report drift and energy.
    Simulate(SimulateArgs),
    /// Speed against error: a work-precision sweep and the formulas' f64 accuracy.
    Bench(BenchArgs),
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum LangArg {
    Rust,
    C,
}

/// The step `generate --solver` writes.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum SolverArg {
    SoftStep,
    Pgs,
    Exact,
}

impl SolverArg {
    fn solver(self) -> Solver {
        match self {
            SolverArg::SoftStep => Solver::SoftStep,
            SolverArg::Pgs => Solver::Pgs,
            SolverArg::Exact => Solver::Exact,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum SolveFormat {
    Text,
    Json,
}

/// Options of `bench`.
#[derive(clap::Args, Debug)]
struct BenchArgs {
    /// The constraint file (TOML) with a [scene].
    file: PathBuf,
    /// The middle step size; the sweep runs 4, 2, 1 and ½ times it (default: the scene's).
    #[arg(long)]
    dt: Option<f64>,
    /// Simulated time per run (default: the scene's).
    #[arg(long)]
    duration: Option<f64>,
    /// Random (and as many hard) states for the formula accuracy.
    #[arg(long, default_value_t = 200)]
    states: usize,
    #[arg(long, value_enum, default_value_t = OutArg::Text)]
    format: OutArg,
    /// Write the work-precision plot (error against time, log-log) to this SVG file.
    #[arg(long)]
    plot: Option<PathBuf>,
}

/// Options of `simulate`.
#[derive(clap::Args, Debug)]
struct SimulateArgs {
    /// The constraint file (TOML) with a [scene].
    file: PathBuf,
    #[arg(long, value_enum, default_value_t = IntegratorArg::Verlet)]
    integrator: IntegratorArg,
    /// Drift control: none, Baumgarte (--zeta, --omega-dt) or projection after each step.
    #[arg(long, value_enum, default_value_t = StabilizeArg::Projection)]
    stabilize: StabilizeArg,
    /// Baumgarte damping ratio ζ (α = ζω).
    #[arg(long, default_value_t = 1.0)]
    zeta: f64,
    /// Baumgarte frequency relative to the step, ω·dt (β = ω).
    #[arg(long, default_value_t = 0.1)]
    omega_dt: f64,
    /// Projection tolerance, relative to the scene's size.
    #[arg(long, default_value_t = 1e-13)]
    tolerance: f64,
    /// Time step (overrides the scene's).
    #[arg(long)]
    dt: Option<f64>,
    /// Simulated time (overrides the scene's).
    #[arg(long)]
    duration: Option<f64>,
    /// Number of steps (overrides --duration).
    #[arg(long)]
    steps: Option<u64>,
    /// Write t, state, λ, C, Ċ per recorded step to this CSV file.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Write every k-th step to the CSV.
    #[arg(long, default_value_t = 1)]
    every: u64,
    /// Write trajectory, |C| and energy error to this SVG file.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// The summary as text or as JSON.
    #[arg(long, value_enum, default_value_t = SummaryArg::Text)]
    format: SummaryArg,
}

#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
enum SummaryArg {
    Text,
    Json,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum IntegratorArg {
    Euler,
    Verlet,
    Rk4,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum StabilizeArg {
    None,
    Baumgarte,
    Projection,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum OutArg {
    Text,
    Json,
    Csv,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum FormatArg {
    Text,
    Latex,
    Markdown,
    Json,
}

/// Set when standard output failed for a reason other than its reader going away.
static STDOUT_FAILED: AtomicBool = AtomicBool::new(false);

/// Writes to standard output. A closed pipe (`lagrange check … | head`) is not an error: the
/// reader has what it wanted, and the command goes on (files it writes are still written).
/// Any other failure is reported once and makes the exit code 1.
fn emit(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    if let Err(e) = std::io::stdout().lock().write_fmt(args) {
        stdout_failed(&e);
    }
}

/// Reports a failure to write standard output once, and makes the exit code 1; a closed
/// pipe is not a failure.
fn stdout_failed(e: &std::io::Error) {
    if e.kind() != std::io::ErrorKind::BrokenPipe && !STDOUT_FAILED.swap(true, Ordering::Relaxed) {
        eprintln!("error: cannot write to standard output: {e}");
    }
}

/// Pretty JSON and a line break to standard output, written as it is serialised; failures as
/// in [`emit`].
fn emit_json(value: &impl serde::Serialize) {
    use std::io::Write;
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let written = serde_json::to_writer_pretty(&mut out, value)
        .map_err(std::io::Error::from)
        .and_then(|()| out.write_all(b"\n"))
        .and_then(|()| out.flush());
    if let Err(e) = written {
        stdout_failed(&e);
    }
}

/// `print!` through [`emit`].
macro_rules! out {
    ($($arg:tt)*) => { emit(format_args!($($arg)*)) };
}

/// `println!` through [`emit`].
macro_rules! outln {
    ($($arg:tt)*) => { emit(format_args!("{}\n", format_args!($($arg)*))) };
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Run on a thread with a generous stack: recursion is bounded everywhere, and this is a
    // second line of defence for inputs nobody thought of.
    let worker = std::thread::Builder::new().stack_size(256 << 20).spawn(move || run(cli));
    match worker.map(|h| h.join()) {
        Ok(Ok(_)) if STDOUT_FAILED.load(Ordering::Relaxed) => ExitCode::from(1),
        Ok(Ok(code)) => code,
        _ => {
            eprintln!("error: internal failure (please report it with the input file)");
            ExitCode::from(3)
        }
    }
}

fn run(cli: Cli) -> ExitCode {
    match cli.command {
        Command::Derive { file, format, steps } => cmd_derive(&file, format, steps),
        Command::Generate { file, lang, output, specialize, solver } => {
            let lang = match lang {
                LangArg::Rust => Lang::Rust,
                LangArg::C => Lang::C,
            };
            let options = Options { specialize, solver: solver.map(SolverArg::solver), lang };
            cmd_generate(&file, output.as_deref(), &options)
        }
        Command::Solve { file, at, set, format } => match cmd_solve(&file, at.as_deref(), &set, format) {
            Ok(()) => ExitCode::SUCCESS,
            Err(code) => code,
        },
        Command::Check { files } => cmd_check(&files),
        Command::Simulate(args) => cmd_simulate(&args),
        Command::Bench(args) => cmd_bench(&args),
    }
}

/// Reads a file as UTF-8 text, with a clear message for the ways that fails.
/// The file's text (size-limited, UTF-8), or the message to print.
fn read_text(path: &Path) -> Result<String, String> {
    lagrange::check::read_text(path).map_err(|e| format!("error: {e}"))
}

fn report_problems(path: &Path, text: &str, problems: &[Problem]) -> ExitCode {
    eprint!("{}", render(&path.display().to_string(), text, problems));
    eprintln!("{} problem{} in {}", problems.len(), if problems.len() == 1 { "" } else { "s" }, path.display());
    ExitCode::from(1)
}

/// Reads and validates a constraint file, or prints why not (every problem, located) and
/// gives the exit code.
fn load_file(path: &Path) -> Result<Loaded, ExitCode> {
    let text = read_text(path).map_err(|e| {
        eprintln!("{e}");
        ExitCode::from(1)
    })?;
    load(&text).map_err(|problems| report_problems(path, &text, &problems))
}

fn cmd_derive(path: &Path, format: FormatArg, steps: bool) -> ExitCode {
    let loaded = match load_file(path) {
        Ok(l) => l,
        Err(code) => return code,
    };
    let derivation =
        match derive_with(&loaded.system, DeriveOptions { document: !matches!(format, FormatArg::Json), steps }) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("error: {}: {e}", path.display());
                return ExitCode::from(1);
            }
        };
    let format = match format {
        FormatArg::Text => Format::Text,
        FormatArg::Latex => Format::Latex,
        FormatArg::Markdown => Format::Markdown,
        FormatArg::Json => Format::Json,
    };
    if format == Format::Json {
        // Written as it is serialised: a long chain's dense A is never held whole.
        return match derivation::json(&loaded.system, &derivation) {
            Ok(doc) => {
                emit_json(&doc);
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {}: {e}", path.display());
                ExitCode::from(1)
            }
        };
    }
    let result = derivation::document(&loaded.system, &derivation, format, steps);
    match result {
        Ok(s) => {
            outln!("{s}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {}: {e}", path.display());
            ExitCode::from(1)
        }
    }
}

/// Whether `a` and `b` name the same existing file (through symlinks or hard links too).
fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) else { return false };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if (x.dev(), x.ino()) == (y.dev(), y.ino()) {
            return true;
        }
    }
    let _ = (x, y);
    matches!((std::fs::canonicalize(a), std::fs::canonicalize(b)), (Ok(p), Ok(q)) if p == q)
}

fn cmd_generate(path: &Path, output: Option<&Path>, options: &Options) -> ExitCode {
    if let Some(out) = output
        && same_file(path, out)
    {
        eprintln!(
            "error: the output {} is the input file {}: refusing to overwrite it (choose another `-o`)",
            out.display(),
            path.display()
        );
        return ExitCode::from(1);
    }
    let loaded = match load_file(path) {
        Ok(l) => l,
        Err(code) => return code,
    };
    let module = match module(&loaded, options) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: {}: {e}", path.display());
            return ExitCode::from(1);
        }
    };
    for warning in &module.warnings {
        eprintln!("warning: {}: {warning}", path.display());
    }
    let code = module.code;
    match output {
        Some(out) => match std::fs::write(out, code) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: cannot write {}: {e}", out.display());
                ExitCode::from(1)
            }
        },
        None => {
            out!("{code}");
            ExitCode::SUCCESS
        }
    }
}

/// The symbol values of a `--at` file: a flat TOML or JSON table, each checked against
/// `system` (a misfit is kept, to be reported after every syntax error).
fn read_state(system: &System, path: &Path) -> Result<Vec<state::Given>, String> {
    let text = read_text(path)?;
    let Some(format) = state::Format::of(path) else {
        return Err(format!("error: {}: a state file must end in .toml or .json", path.display()));
    };
    state::state_file(system, &text, format).map_err(|e| format!("error: {}: {e}", path.display()))
}

/// `NAME=VALUE` with VALUE a finite number or `[x, y]`, checked against `system`.
fn parse_set(system: &System, arg: &str) -> Result<state::Given, String> {
    state::assignment(system, arg).map_err(|e| format!("error: --set {arg}: {e}"))
}

fn cmd_solve(path: &Path, at: Option<&Path>, set: &[String], format: SolveFormat) -> Result<(), ExitCode> {
    let fail = |message: String| {
        eprintln!("{message}");
        ExitCode::from(1)
    };
    let loaded = load_file(path)?;
    let derivation = derive(&loaded.system).map_err(|e| fail(format!("error: {}: {e}", path.display())))?;
    let system = &loaded.system;
    let mut given = match at {
        Some(p) => read_state(system, p).map_err(fail)?,
        None => Vec::new(),
    };
    for arg in set {
        given.push(parse_set(system, arg).map_err(fail)?);
    }
    // A value that does not fit its symbol is said of the constraint file.
    let overrides: Vec<(Symbol, Value)> =
        given.into_iter().collect::<Result<_, _>>().map_err(|e| fail(format!("error: {}: {e}", path.display())))?;
    let env = environment(system, &loaded.values, &loaded.scene, &overrides)
        .map_err(|e| fail(format!("error: {}: {e}", path.display())))?;
    // A force given in the state replaces the scene's expression for that body.
    let given: Vec<String> = overrides.iter().map(|&(s, _)| system.graph.symbol(s).name.clone()).collect();
    let given: Vec<&str> = given.iter().map(String::as_str).collect();
    let program = RowProgram::with_given_forces(system, &derivation, &loaded.scene.forces, &given);

    // Contact distances count as zero relative to the size of the scene.
    let length = system
        .bodies
        .iter()
        .filter_map(|b| env.get(b.position).and_then(|v| v.vector()))
        .map(|r| safe_norm(&r))
        .fold(0.0, f64::max);
    let settings =
        Settings { length_scale: if length > 0.0 && length.is_finite() { length } else { 1.0 }, ..Settings::default() };
    let (rows, solution) =
        solve_at(&program, system, &env, &settings).map_err(|e| fail(format!("error: {}: {e}", path.display())))?;
    let t = env.get(system.time).and_then(|v| v.scalar()).unwrap_or(0.0);
    match format {
        SolveFormat::Json => {
            let v = solution::json(system, &derivation, &rows, &solution, t);
            outln!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
        }
        SolveFormat::Text => out!("{}", solution::text(system, &derivation, &rows, &solution, t)),
    }
    Ok(())
}

/// `check`: each file's expectations, one line per check, failures with their location and
/// details; the last line is `N passed, M failed` (an unreadable or invalid file counts as
/// one failure).
fn cmd_check(files: &[PathBuf]) -> ExitCode {
    use lagrange::check::Checked;
    let (mut passed, mut failed) = (0usize, 0usize);
    for path in files {
        let name = path.display().to_string();
        let text = match read_text(path) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("{e}");
                failed += 1;
                continue;
            }
        };
        let mut checked = match Checked::from_text(&name, &text) {
            Ok(c) => c,
            Err(e) => {
                eprintln!("{e}");
                failed += 1;
                continue;
            }
        };
        let outcomes = checked.run();
        if outcomes.is_empty() {
            outln!("{name}: no [[expect]] entries");
        }
        for o in outcomes {
            let place = o.span.as_ref().map_or(name.clone(), |s| location(&name, &text, s.start));
            if o.passed {
                passed += 1;
                outln!("ok     {place}: {} ({})", o.label, o.how);
            } else {
                failed += 1;
                outln!("FAILED {place}: {} ({})", o.label, o.how);
                outln!("{}", o.detail);
            }
        }
    }
    outln!("{passed} passed, {failed} failed");
    if failed == 0 { ExitCode::SUCCESS } else { ExitCode::from(1) }
}

/// `file:line:col` of a byte offset.
fn location(name: &str, text: &str, offset: usize) -> String {
    let before = &text[..lagrange::report::diagnostic::floor_char(text, offset.min(text.len()))];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    format!("{name}:{line}:{col}")
}

/// Reads, loads and derives a file into a runnable scenario, or reports why not.
fn scenario(path: &Path) -> Result<lagrange::scenario::Scenario, ExitCode> {
    let loaded = load_file(path)?;
    lagrange::scenario::Scenario::new(loaded, &[]).map_err(|e| {
        eprintln!("error: {}: {e}", path.display());
        ExitCode::from(1)
    })
}

fn cmd_simulate(args: &SimulateArgs) -> ExitCode {
    use lagrange::numeric::integrate::Integrator;
    use lagrange::numeric::stabilize::Stabilize;
    let scenario = match scenario(&args.file) {
        Ok(s) => s,
        Err(code) => return code,
    };
    let mut settings = scenario.settings();
    settings.dt = args.dt.unwrap_or(settings.dt);
    let duration = args.duration.unwrap_or(scenario.scene.duration);
    settings.steps = args.steps.unwrap_or((duration / settings.dt).round().max(0.0) as u64);
    settings.integrator = match args.integrator {
        IntegratorArg::Euler => Integrator::Euler,
        IntegratorArg::Verlet => Integrator::Verlet,
        IntegratorArg::Rk4 => Integrator::Rk4,
    };
    settings.stabilize = match args.stabilize {
        StabilizeArg::None => Stabilize::None,
        StabilizeArg::Baumgarte => Stabilize::Baumgarte { zeta: args.zeta, omega_dt: args.omega_dt },
        StabilizeArg::Projection => Stabilize::Projection { tolerance: args.tolerance, max_iterations: 20 },
    };
    if let Err(e) = settings.validate() {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    let mut csv = match &args.csv {
        None => None,
        Some(path) => {
            let file = std::fs::File::create(path).map_err(|e| e.to_string());
            let out = file.and_then(|f| {
                let out = std::io::BufWriter::new(f);
                lagrange::report::csv::CsvWriter::new(&scenario.system, out, args.every, settings.steps)
                    .map_err(|e| e.to_string())
            });
            match out {
                Ok(w) => Some(w),
                Err(e) => {
                    eprintln!("error: cannot write {}: {e}", path.display());
                    return ExitCode::from(1);
                }
            }
        }
    };
    use std::io::IsTerminal;
    let bar = (std::io::stderr().is_terminal() && settings.steps >= 20_000)
        .then(|| indicatif::ProgressBar::new(settings.steps));
    let result = scenario.simulate(settings, &mut |frame| {
        if let Some(bar) = &bar
            && frame.step.is_multiple_of(1000)
        {
            bar.set_position(frame.step);
        }
        csv.as_mut().map_or(Ok(()), |w| w.frame(frame)).map_err(|e| e.to_string())
    });
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    if let Some(Err(e)) = csv.as_mut().map(|w| w.flush()) {
        eprintln!("error: cannot write the CSV: {e}");
    }
    let (summary, code) = match result {
        Ok(s) => (s, ExitCode::SUCCESS),
        Err(failure) => {
            eprintln!("error: {}: {}", args.file.display(), failure.error);
            (failure.summary, ExitCode::from(2))
        }
    };
    let dim = scenario.system.dim();
    if args.format == SummaryArg::Json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&lagrange::report::simulation::json(&summary, dim)).unwrap_or_default()
        );
    } else {
        outln!("{}", lagrange::report::simulation::text(&summary, dim));
    }
    if let Some(path) = &args.plot {
        let title = format!("{} — {} + {}", scenario.system.title, summary.integrator, summary.stabilize);
        let written = lagrange::report::plot::simulation(&title, &summary)
            .and_then(|svg| std::fs::write(path, svg).map_err(|e| e.to_string()));
        if let Err(e) = written {
            eprintln!("error: {}: {e}", path.display());
            return ExitCode::from(1);
        }
    }
    code
}

fn cmd_bench(args: &BenchArgs) -> ExitCode {
    use lagrange::report::bench as table;
    let scenario = match scenario(&args.file) {
        Ok(s) => s,
        Err(code) => return code,
    };
    let sweep = lagrange::bench::Sweep::new(
        args.dt.unwrap_or(scenario.scene.dt),
        args.duration.unwrap_or(scenario.scene.duration),
    );
    let wp = match lagrange::bench::work_precision(&scenario, &sweep) {
        Ok(wp) => wp,
        Err(e) => {
            eprintln!("error: {}: {e}", args.file.display());
            return ExitCode::from(2);
        }
    };
    let accuracy = lagrange::bench::accuracy::formula_accuracy(&scenario, args.states, 1);
    match args.format {
        OutArg::Text => outln!("{}", table::text(&wp, &accuracy)),
        OutArg::Json => outln!("{}", serde_json::to_string_pretty(&table::json(&wp, &accuracy)).unwrap_or_default()),
        OutArg::Csv => out!("{}", table::csv(&wp, &accuracy)),
    }
    if let Some(path) = &args.plot {
        let title = format!("{}: final-state error against time", scenario.system.title);
        let written = lagrange::report::plot::work_precision(
            &title,
            "wall seconds per simulated second",
            "final-state error / scene size",
            &table::lines(&wp),
        )
        .and_then(|svg| std::fs::write(path, svg).map_err(|e| e.to_string()));
        if let Err(e) = written {
            eprintln!("error: {}: {e}", path.display());
            return ExitCode::from(1);
        }
    }
    ExitCode::SUCCESS
}
