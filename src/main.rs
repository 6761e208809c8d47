//! The `lagrange` command line: parse arguments, call the library, print. Nothing else.

/// mimalloc: a derivation allocates and frees many small forms; with it a derivation takes
/// 15–18 % fewer instructions than with the system allocator (docs/speed.md).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use clap::{Parser, Subcommand, ValueEnum};
use lagrange::codegen::layout::Solver;
use lagrange::codegen::{Lang, Options, module};
use lagrange::derive::{Options as DeriveOptions, derive, derive_with};
use lagrange::expr::Symbol;
use lagrange::expr::eval::Value;
use lagrange::model::file::{Loaded, Problem, load};
use lagrange::model::scene::{environment, unset_forces};
use lagrange::model::state;
use lagrange::model::system::System;
use lagrange::numeric::rescale::solve_at;
use lagrange::numeric::rows::RowProgram;
use lagrange::numeric::simulate::{initial_state, scene_length};
use lagrange::numeric::solve::{Settings, off_constraint};
use lagrange::report::derivation::{self, Format};
use lagrange::report::diagnostic::render;
use lagrange::report::solution;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

/// Derive constraint forces from constraints written as text.
///
/// A constraint file (TOML) declares bodies (point masses, 2D and 3D rigid bodies, joints),
/// parameters and position constraints such as `dot(r,r) = l^2`. lagrange differentiates
/// each constraint twice in time, finds the force directions ∇C, and solves for the Lagrange
/// multipliers λ; it simulates the scene (at the acceleration level, or with the
/// velocity-level solvers an engine runs) and writes the formulas and the step as Rust or C.
#[derive(Parser, Debug)]
#[command(name = "lagrange", version, about, long_about, after_long_help = EXIT_CODES)]
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
        solver: Option<StepArg>,
        /// Write the step only (`--solver soft-step|pgs`, Rust), each repeated row shape once
        /// over a table of its instances: a small module for scenes of thousands of rows.
        #[arg(long)]
        step_only: bool,
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
        #[command(flatten)]
        state: StateArgs,
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
    ///
    /// The run starts from the file's [parameters] and [scene] initial values, then `--at`,
    /// then each `--set` (later wins), as `solve`; a force or torque given there replaces the
    /// scene's expression for that body for the whole run.
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
enum StepArg {
    SoftStep,
    Pgs,
    Exact,
}

impl StepArg {
    fn solver(self) -> Solver {
        match self {
            StepArg::SoftStep => Solver::SoftStep,
            StepArg::Pgs => Solver::Pgs,
            StepArg::Exact => Solver::Exact,
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
    #[command(flatten)]
    state: StateArgs,
    /// The middle step size; the sweep runs 4, 2, 1 and ½ times it (default: the scene's).
    #[arg(long, allow_negative_numbers = true)]
    dt: Option<f64>,
    /// Simulated time per run (default: the scene's).
    #[arg(long, allow_negative_numbers = true)]
    duration: Option<f64>,
    /// Random (and as many hard) states for the formula accuracy, at most 100000.
    #[arg(long, default_value_t = 200)]
    states: usize,
    #[arg(long, value_enum, default_value_t = OutArg::Text)]
    format: OutArg,
    /// Write the work-precision plot (error against time, log-log) to this SVG file.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Bench the velocity-level solvers instead: each solver × substeps 1, 2, 4, 8 (× 15,
    /// 30, 60 Hz for the soft step) against the exact velocity solve, at the scene's dt (or
    /// --dt) for its duration (or --duration), with the soft step's largest stable hertz.
    #[arg(long)]
    solvers: bool,
}

/// The state a command starts from, over the file's [parameters] and [scene] initial values:
/// `--at`, then each `--set` (later wins). A force or torque given here replaces the scene's
/// expression for that body.
#[derive(clap::Args, Debug, Default)]
struct StateArgs {
    /// A state file (.toml or .json): a flat table symbol = number or [x, y(, z)], for
    /// positions, velocities, forces, masses, parameters and `t`.
    #[arg(long, value_name = "STATE")]
    at: Option<PathBuf>,
    /// Override one symbol: NAME=NUMBER, a vector NAME=[x,y] (3D: [x,y,z]), or a 3D
    /// orientation NAME=[w,x,y,z] (a unit quaternion); may repeat.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
}

/// Options of `simulate`.
#[derive(clap::Args, Debug)]
struct SimulateArgs {
    /// The constraint file (TOML) with a [scene].
    file: PathBuf,
    #[command(flatten)]
    state: StateArgs,
    #[arg(long, value_enum, default_value_t = IntegratorArg::Verlet)]
    integrator: IntegratorArg,
    /// Drift control: none, Baumgarte (--zeta, --omega-dt) or projection after each step.
    #[arg(long, value_enum, default_value_t = StabilizeArg::Projection)]
    stabilize: StabilizeArg,
    /// Baumgarte damping ratio ζ (α = ζω).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    zeta: f64,
    /// Baumgarte frequency relative to the step, ω·dt (β = ω).
    #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
    omega_dt: f64,
    /// Projection tolerance, relative to the scene's size.
    #[arg(long, default_value_t = lagrange::numeric::stabilize::PROJECTION_TOLERANCE, allow_negative_numbers = true)]
    tolerance: f64,
    /// Time step (overrides the scene's).
    #[arg(long, allow_negative_numbers = true)]
    dt: Option<f64>,
    /// Simulated time (overrides the scene's).
    #[arg(long, allow_negative_numbers = true)]
    duration: Option<f64>,
    /// Number of steps (overrides --duration).
    #[arg(long)]
    steps: Option<u64>,
    /// Write t, state, λ, C, Ċ per recorded step to this CSV file.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Write every k-th step to the CSV (and the last; k ≥ 1).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    every: u64,
    /// Write trajectory, |C| and energy error to this SVG file.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// The summary as text or as JSON.
    #[arg(long, value_enum, default_value_t = SummaryArg::Text)]
    format: SummaryArg,
    #[command(flatten)]
    velocity: VelocityArgs,
    #[arg(long, value_enum, default_value_t = CompileArg::Auto, help = COMPILE_HELP)]
    compile: CompileArg,
}

/// `simulate --compile`'s help, which says what this build does with it.
const COMPILE_HELP: &str = if cfg!(feature = "jit") {
    "Run the rows' tapes as machine code (Cranelift): auto when the run is long enough to pay the compile time back, always, or never (the same results either way)"
} else {
    "Run the rows' tapes as machine code: this build has no compiler (the `jit` feature), so every choice means never (the same results either way)"
};

/// `simulate --compile`.
#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
enum CompileArg {
    Auto,
    Always,
    Never,
}

/// The velocity-level solver and its settings (`simulate`, `bench --solvers`).
#[derive(clap::Args, Debug)]
struct VelocityArgs {
    /// exact: the acceleration-level solve with --integrator and --stabilize (the default);
    /// soft-step, pgs, xpbd, exact-velocity: impulses on velocities, the step an engine runs.
    #[arg(long, value_enum, default_value_t = SolverArg::Exact)]
    solver: SolverArg,
    /// Substeps per step of the velocity-level solvers.
    #[arg(long, default_value_t = 4)]
    substeps: usize,
    /// Iterations per substep (default: soft-step, xpbd 1; pgs 8).
    #[arg(long)]
    iterations: Option<usize>,
    /// Stiffness of the soft step's joints (Box2D: 60 Hz, capped at a quarter of the substep rate).
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true)]
    hertz: f64,
    /// Damping ratio ζ of the soft step's joints (Box2D: 2).
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    damping_ratio: f64,
    /// XPBD compliance α of every row (0: rigid).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    compliance: f64,
    /// Skip the soft step's relax pass.
    #[arg(long)]
    no_relax: bool,
    /// Start every step from zero impulses.
    #[arg(long)]
    no_warm_start: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
enum SolverArg {
    Exact,
    SoftStep,
    Pgs,
    Xpbd,
    ExactVelocity,
}

impl VelocityArgs {
    /// The velocity-level settings (`None` for the acceleration-level `exact`), validated.
    fn settings(
        &self,
        dt: f64,
        steps: u64,
        restitution: f64,
    ) -> Result<Option<lagrange::numeric::velocity::Settings>, String> {
        use lagrange::numeric::velocity::{Settings, Solver};
        let solver = match self.solver {
            SolverArg::SoftStep => Solver::SoftStep,
            SolverArg::Pgs => Solver::Pgs,
            SolverArg::Xpbd => Solver::Xpbd,
            SolverArg::ExactVelocity | SolverArg::Exact => Solver::Exact,
        };
        let mut s = Settings::new(solver, dt, 0.0);
        s.steps = steps;
        s.substeps = self.substeps;
        s.iterations = self.iterations;
        s.hertz = self.hertz;
        s.damping_ratio = self.damping_ratio;
        s.compliance = self.compliance;
        s.relax = !self.no_relax;
        s.warm_start = !self.no_warm_start;
        s.restitution = restitution;
        // The flags are checked whichever solver runs, so a typo never passes silently.
        s.validate().map_err(|e| e.to_string())?;
        Ok((self.solver != SolverArg::Exact).then_some(s))
    }
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

/// The exit codes, for `--help` (the README's Commands section has the same table).
const EXIT_CODES: &str = "\
Exit codes:
  0  success
  1  bad input or a failed check: an unreadable or invalid file, a bad --at or --set value,
     a derivation or solve that cannot be done, an expectation that failed, or a failure to
     write an output (standard output, -o, --plot, or the --csv file: creating it, a row
     during the run, which stops there with its summary printed, or its last rows when it
     is closed; one message whichever)
  2  bad settings or a run that stopped: simulate's or bench's settings out of range (a run
     of more than 10^8 steps, or a duration and step that give none; --steps 0 runs and
     exits 0; bench --states above 100000), an output (-o, --csv, --plot) that is the input
     file, a simulation or bench sweep that stopped (its summary is still printed), or
     arguments the command line refuses
  3  internal failure (please report it with the input file)
  4  no answer: solve printed its numbers, but its status is failed or inconsistent, or
     a constraint with a zero gradient cannot hold (singular); the diagnostics name the
     cause (an undefined 0/0, an overflow, the constraints at fault)";

/// A run shows a progress bar (on a terminal) once it has taken this long: shorter ones end
/// without one, and a long one shows it whatever its number of steps (a 100 × 100 rigid grid
/// takes seconds a step).
const PROGRESS_AFTER: std::time::Duration = std::time::Duration::from_secs(1);
/// The bar is looked at about this often: the clock is read only every `stride` steps, the
/// stride chosen from the steps' speed so far, so a 3 µs pendulum step pays one comparison.
const PROGRESS_PERIOD: f64 = 0.1;

/// The progress bar of a run of `steps` steps, shown once it has taken [`PROGRESS_AFTER`].
struct Progress {
    steps: u64,
    start: std::time::Instant,
    next: u64,
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    /// None off a terminal (a pipe, a file, a test).
    fn new(steps: u64) -> Option<Progress> {
        use std::io::IsTerminal;
        std::io::stderr().is_terminal().then(|| Progress {
            steps,
            start: std::time::Instant::now(),
            next: 1,
            bar: None,
        })
    }

    /// Step `step` is done.
    fn at(&mut self, step: u64) {
        if step < self.next {
            return;
        }
        let elapsed = self.start.elapsed();
        if self.bar.is_none() && elapsed >= PROGRESS_AFTER {
            self.bar = Some(indicatif::ProgressBar::new(self.steps));
        }
        if let Some(bar) = &self.bar {
            bar.set_position(step);
        }
        // The steps that take about PROGRESS_PERIOD at the speed so far.
        let per_step = elapsed.as_secs_f64() / step.max(1) as f64;
        let stride = if per_step > 0.0 { (PROGRESS_PERIOD / per_step).clamp(1.0, 1e6) as u64 } else { 1000 };
        self.next = step + stride;
    }

    fn finish(self) {
        if let Some(bar) = self.bar {
            bar.finish_and_clear();
        }
    }
}

/// Files with at least this many constraints show a spinner while they derive and print (on
/// a terminal): a 10⁴-link chain takes about a second, so smaller files end before it would
/// draw.
const SPINNER_MIN_CONSTRAINTS: usize = 10_000;

/// A spinner on stderr, with the elapsed time, while `work` runs on a system of `constraints`
/// constraints — only on a terminal and for large files (`SPINNER_MIN_CONSTRAINTS`).
fn with_spinner<T>(what: &str, constraints: usize, work: impl FnOnce() -> T) -> T {
    use std::io::IsTerminal;
    let spinner = (std::io::stderr().is_terminal() && constraints >= SPINNER_MIN_CONSTRAINTS).then(|| {
        let bar = indicatif::ProgressBar::new_spinner();
        bar.set_message(format!("{what} {constraints} constraints"));
        if let Ok(style) = indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
            bar.set_style(style);
        }
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        bar
    });
    let result = work();
    if let Some(bar) = spinner {
        bar.finish_and_clear();
    }
    result
}

/// Set when standard output failed for a reason other than its reader going away.
static STDOUT_FAILED: AtomicBool = AtomicBool::new(false);

/// Writes to standard output. A closed pipe (`lagrange check … | head`) is not an error: the
/// reader has what it wanted, and the command goes on (files it writes are still written).
/// Any other failure is reported once and makes the exit code 1.
fn emit(args: std::fmt::Arguments<'_>) {
    use std::io::Write;
    // Names and titles from a file never reach the terminal raw (escape sequences could
    // erase a line or fake one); line breaks and tabs stay.
    let text = std::fmt::format(args);
    let text = lagrange::report::diagnostic::escape_controls(&text, true);
    if let Err(e) = std::io::stdout().lock().write_all(text.as_bytes()) {
        stdout_failed(&e);
    }
}

/// `eprintln!` with control characters escaped, as [`emit`] does for standard output.
macro_rules! errln {
    ($($arg:tt)*) => {
        eprintln!("{}", lagrange::report::diagnostic::escape_controls(&format!($($arg)*), true))
    };
}

/// Reports a failure to write standard output once, and makes the exit code 1; a closed
/// pipe is not a failure.
fn stdout_failed(e: &std::io::Error) {
    if e.kind() != std::io::ErrorKind::BrokenPipe && !STDOUT_FAILED.swap(true, Ordering::Relaxed) {
        errln!("error: cannot write to standard output: {e}");
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
            errln!("error: internal failure (please report it with the input file)");
            ExitCode::from(3)
        }
    }
}

fn run(cli: Cli) -> ExitCode {
    match cli.command {
        Command::Derive { file, format, steps } => cmd_derive(&file, format, steps),
        Command::Generate { file, lang, output, specialize, solver, step_only } => {
            let lang = match lang {
                LangArg::Rust => Lang::Rust,
                LangArg::C => Lang::C,
            };
            let options = Options { specialize, solver: solver.map(StepArg::solver), lang, step_only };
            cmd_generate(&file, output.as_deref(), &options)
        }
        Command::Solve { file, state, format } => match cmd_solve(&file, &state, format) {
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

/// A derivation's error, printed: at the constraint's `expr` in the file when it is about
/// one (a formula past the work budget), as file problems are; else `error: FILE: message`.
fn report_derive_error(path: &Path, e: &lagrange::DeriveError) {
    if let Some(k) = e.constraint()
        && let Ok(text) = read_text(path)
    {
        let shown = path.display().to_string();
        eprint!("{}", lagrange::report::diagnostic::render_constraint(&shown, &text, k, &e.to_string()));
        return;
    }
    errln!("error: {}: {e}", path.display());
}

fn report_problems(path: &Path, text: &str, problems: &[Problem]) -> ExitCode {
    eprint!("{}", render(&path.display().to_string(), text, problems));
    errln!("{} problem{} in {}", problems.len(), if problems.len() == 1 { "" } else { "s" }, path.display());
    ExitCode::from(1)
}

/// Reads and validates a constraint file, or prints why not (every problem, located) and
/// gives the exit code.
fn load_file(path: &Path) -> Result<Loaded, ExitCode> {
    let text = read_text(path).map_err(|e| {
        errln!("{e}");
        ExitCode::from(1)
    })?;
    load(&text).map_err(|problems| report_problems(path, &text, &problems))
}

fn cmd_derive(path: &Path, format: FormatArg, steps: bool) -> ExitCode {
    let loaded = match load_file(path) {
        Ok(l) => l,
        Err(code) => return code,
    };
    let options = DeriveOptions { document: !matches!(format, FormatArg::Json), steps };
    let constraints = loaded.system.constraints.len();
    let derivation = match with_spinner("deriving", constraints, || derive_with(&loaded.system, options)) {
        Ok(d) => d,
        Err(e) => {
            report_derive_error(path, &e);
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
        // A is sparse (its upper triangle's non-zero entries): linear in the scene's size.
        return match with_spinner("writing", constraints, || derivation::json(&loaded.system, &derivation)) {
            Ok(doc) => {
                emit_json(&doc);
                ExitCode::SUCCESS
            }
            Err(e) => {
                errln!("error: {}: {e}", path.display());
                ExitCode::from(1)
            }
        };
    }
    let result =
        with_spinner("writing", constraints, || derivation::document(&loaded.system, &derivation, format, steps));
    match result {
        Ok(s) => {
            outln!("{s}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            errln!("error: {}: {e}", path.display());
            ExitCode::from(1)
        }
    }
}

/// Whether `a` and `b` name the same existing file (through symlinks or hard links too).
fn cmd_generate(path: &Path, output: Option<&Path>, options: &Options) -> ExitCode {
    if let Err(code) = refuse_overwrite(path, &[("-o", output)]) {
        return code;
    }
    let loaded = match load_file(path) {
        Ok(l) => l,
        Err(code) => return code,
    };
    let module = match module(&loaded, options) {
        Ok(m) => m,
        Err(lagrange::GenerateError::Derive(e)) => {
            report_derive_error(path, &e);
            return ExitCode::from(1);
        }
        Err(e) => {
            errln!("error: {}: {e}", path.display());
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
                errln!("error: cannot write {}: {e}", out.display());
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

/// `NAME=VALUE` with VALUE a finite number, a vector of the file's dimension or a 3D
/// orientation's unit quaternion, checked against `system`.
fn parse_set(system: &System, arg: &str) -> Result<state::Given, String> {
    state::assignment(system, arg).map_err(|e| format!("error: --set {arg}: {e}"))
}

/// The values of `--at` and each `--set` for `system`, in order (later wins); an unreadable
/// state file, a bad `--set` or a value that does not fit its symbol is an error (exit 1).
fn overrides(system: &System, path: &Path, state: &StateArgs) -> Result<Vec<(Symbol, Value)>, ExitCode> {
    let fail = |message: String| {
        errln!("{message}");
        ExitCode::from(1)
    };
    let mut given = match &state.at {
        Some(p) => read_state(system, p).map_err(fail)?,
        None => Vec::new(),
    };
    for arg in &state.set {
        given.push(parse_set(system, arg).map_err(fail)?);
    }
    // A value that does not fit its symbol is said of the constraint file.
    given.into_iter().collect::<Result<_, _>>().map_err(|e| fail(format!("error: {}: {e}", path.display())))
}

fn cmd_solve(path: &Path, state: &StateArgs, format: SolveFormat) -> Result<(), ExitCode> {
    let fail = |message: String| {
        errln!("{message}");
        ExitCode::from(1)
    };
    let loaded = load_file(path)?;
    let derivation = derive(&loaded.system).map_err(|e| {
        report_derive_error(path, &e);
        ExitCode::from(1)
    })?;
    let system = &loaded.system;
    let overrides = overrides(system, path, state)?;
    let env = environment(system, &loaded.values, &loaded.scene, &overrides)
        .map_err(|e| fail(format!("error: {}: {e}", path.display())))?;
    for symbol in unset_forces(system, &loaded.scene, &overrides) {
        errln!("{}", solution::zero_force_note(system, symbol));
    }
    // A force given in the state replaces the scene's expression for that body.
    let given: Vec<String> = overrides.iter().map(|&(s, _)| system.graph.symbol(s).name.clone()).collect();
    let given: Vec<&str> = given.iter().map(String::as_str).collect();
    let program = RowProgram::with_given_forces(system, &derivation, &loaded.scene.forces, &given);

    // Contact distances count as zero relative to the size of the scene.
    let (_, _, t) = initial_state(system, &env);
    let settings = Settings { length_scale: scene_length(system, &env), ..Settings::default() };
    let (rows, mut solution) =
        solve_at(&program, system, &env, &settings).map_err(|e| fail(format!("error: {}: {e}", path.display())))?;
    solution.diagnostics.extend(off_constraint(&rows, &settings));
    match format {
        SolveFormat::Json => {
            emit_json(&solution::json(system, &derivation, &rows, &solution, t));
        }
        SolveFormat::Text => out!("{}", solution::text(system, &derivation, &rows, &solution, t)),
    }
    if solution.is_answer() { Ok(()) } else { Err(ExitCode::from(4)) }
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
                errln!("{e}");
                failed += 1;
                continue;
            }
        };
        let mut checked = match Checked::from_text(&name, &text) {
            Ok(c) => c,
            Err(e) => {
                errln!("{e}");
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
            // One line each: a name with a line break cannot start a fake `ok` line.
            let label = lagrange::report::diagnostic::escape_controls(&o.label, false);
            if o.passed {
                passed += 1;
                outln!("ok     {place}: {label} ({})", o.how);
            } else {
                failed += 1;
                outln!("FAILED {place}: {label} ({})", o.how);
                outln!("{}", o.detail);
                if let Some(note) = &o.note {
                    outln!("{}", lagrange::check::noted(note));
                }
            }
        }
    }
    outln!("{passed} passed, {failed} failed");
    if failed == 0 { ExitCode::SUCCESS } else { ExitCode::from(1) }
}

/// `file:line:col` of a byte offset.
fn location(name: &str, text: &str, offset: usize) -> String {
    let before = &text[..lagrange::report::diagnostic::floor_char(text, offset.min(text.len()))];
    let line = lagrange::model::problem::line_of(text, before.len());
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    format!("{name}:{line}:{col}")
}

/// Reads, loads and derives a file into a runnable scenario starting from its initial state
/// with `state`'s values over it, or reports why not; the values too (for the notes on
/// forces taken as zero).
fn scenario(path: &Path, state: &StateArgs) -> Result<(lagrange::scenario::Scenario, Vec<(Symbol, Value)>), ExitCode> {
    let loaded = load_file(path)?;
    let overrides = overrides(&loaded.system, path, state)?;
    let scenario = lagrange::scenario::Scenario::new(loaded, &overrides).map_err(|e| {
        errln!("error: {}: {e}", path.display());
        ExitCode::from(1)
    })?;
    Ok((scenario, overrides))
}

/// Whether writing `output` would replace `input`: the same file by canonical path, or on
/// Unix by device and inode (a symlink or a hard link to it).
fn same_file(input: &Path, output: &Path) -> bool {
    let (Ok(a), Ok(b)) = (std::fs::canonicalize(input), std::fs::canonicalize(output)) else {
        return false;
    };
    if a == b {
        return true;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(a), Ok(b)) = (std::fs::metadata(&a), std::fs::metadata(&b)) {
            return a.dev() == b.dev() && a.ino() == b.ino();
        }
    }
    false
}

/// Refuses, before anything runs, an output (`--csv`, `--plot`) that is the input file.
fn refuse_overwrite(input: &Path, outputs: &[(&str, Option<&Path>)]) -> Result<(), ExitCode> {
    for (flag, path) in outputs {
        if let Some(path) = path
            && same_file(input, path)
        {
            errln!("error: {flag} {} is the input file: refusing to overwrite it", path.display());
            return Err(ExitCode::from(2));
        }
    }
    Ok(())
}

fn cmd_simulate(args: &SimulateArgs) -> ExitCode {
    use lagrange::numeric::stabilize::Stabilize;
    if let Err(code) = refuse_overwrite(&args.file, &[("--csv", args.csv.as_deref()), ("--plot", args.plot.as_deref())])
    {
        return code;
    }
    let (scenario, overrides) = match scenario(&args.file, &args.state) {
        Ok(s) => s,
        Err(code) => return code,
    };
    let settings = match simulate_settings(args, &scenario) {
        Ok(settings) => settings,
        Err(code) => return code,
    };
    let velocity = match args.velocity.settings(settings.dt, settings.steps, settings.restitution) {
        // λ only at the CSV's rows (the exact solve then skips it elsewhere; none without --csv).
        Ok(v) => v.map(|v| lagrange::numeric::velocity::Settings {
            samples: settings.samples,
            lambda_every: if args.csv.is_some() { args.every.max(1) } else { 0 },
            compile: settings.compile,
            ..v
        }),
        Err(e) => {
            errln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    for symbol in unset_forces(&scenario.system, &scenario.scene, &overrides) {
        errln!("{}", solution::zero_force_note(&scenario.system, symbol));
    }
    let projects = velocity.is_none() && matches!(settings.stabilize, Stabilize::Projection { .. });
    for offset in scenario.initial_offsets() {
        errln!("{}", solution::initial_offset_note(&scenario.system, &offset, projects));
    }
    let mut csv = match args.csv.as_deref().map(|path| csv_writer(path, &scenario.system, args.every, settings.steps)) {
        None => None,
        Some(Ok(w)) => Some(w),
        Some(Err(code)) => return code,
    };
    let mut progress = Progress::new(settings.steps);
    // The CSV's write error, kept here: the run stops at it and it is reported once, below.
    let mut csv_error: Option<String> = None;
    let mut observe = |frame: &lagrange::numeric::simulate::Frame| {
        if let Some(progress) = &mut progress {
            progress.at(frame.step);
        }
        csv.as_mut().map_or(Ok(()), |w| w.frame(frame)).map_err(|e| {
            let e = e.to_string();
            csv_error = Some(e.clone());
            e
        })
    };
    let result = match velocity {
        None => scenario.simulate(settings, &mut observe),
        Some(v) => scenario.simulate_velocity(v, &mut observe),
    };
    if let Some(progress) = progress {
        progress.finish();
    }
    // A CSV that could not be written whole (`--csv /dev/full`, a full disk) is one failed
    // write, one message and exit 1, whether the buffer met it during the run (which stopped
    // there: its summary is of the steps run) or when it was closed.
    if csv_error.is_none()
        && let Some(Err(e)) = csv.as_mut().map(|w| w.flush())
    {
        csv_error = Some(e.to_string());
    }
    if let (Some(e), Some(path)) = (&csv_error, &args.csv) {
        errln!("error: cannot write the CSV {}: {e}", path.display());
    }
    let (summary, code, stopped) = match result {
        Ok(s) if csv_error.is_some() => (s, ExitCode::from(1), None),
        Ok(s) => (s, ExitCode::SUCCESS, None),
        Err(failure) if csv_error.is_some() => (failure.summary, ExitCode::from(1), Some(failure.error.to_string())),
        // Refused before the first step: there is no summary to show.
        Err(failure) if failure.summary.integrator.is_empty() => {
            eprintln!("error: {}: {}", args.file.display(), failure.error);
            return ExitCode::from(2);
        }
        Err(failure) => {
            errln!("error: {}: {}", args.file.display(), failure.error);
            (failure.summary, ExitCode::from(2), Some(failure.error.to_string()))
        }
    };
    if let Err(code) = show_simulation(args, &scenario, &summary, stopped.as_deref()) {
        return code;
    }
    code
}

/// The run's settings: the scene's, overridden by the flags, validated before any step.
fn simulate_settings(
    args: &SimulateArgs,
    scenario: &lagrange::scenario::Scenario,
) -> Result<lagrange::numeric::simulate::Settings, ExitCode> {
    use lagrange::numeric::dynamics::SimError;
    use lagrange::numeric::integrate::Integrator;
    use lagrange::numeric::simulate::Compile;
    use lagrange::numeric::stabilize::Stabilize;
    let mut settings = scenario.settings();
    settings.dt = args.dt.unwrap_or(settings.dt);
    let duration = args.duration.unwrap_or(scenario.scene.duration);
    settings.steps = match args.steps {
        Some(steps) => steps,
        None => lagrange::numeric::simulate::checked_steps(duration, settings.dt).map_err(|e| {
            errln!("error: {}", SimError::Settings(e));
            ExitCode::from(2)
        })?,
    };
    settings.compile = match args.compile {
        CompileArg::Auto => Compile::Auto,
        CompileArg::Always => Compile::Always,
        CompileArg::Never => Compile::Never,
    };
    settings.integrator = match args.integrator {
        IntegratorArg::Euler => Integrator::Euler,
        IntegratorArg::Verlet => Integrator::Verlet,
        IntegratorArg::Rk4 => Integrator::Rk4,
    };
    settings.stabilize = match args.stabilize {
        StabilizeArg::None => Stabilize::None,
        StabilizeArg::Baumgarte => Stabilize::Baumgarte { zeta: args.zeta, omega_dt: args.omega_dt },
        StabilizeArg::Projection => Stabilize::Projection {
            tolerance: args.tolerance,
            max_iterations: lagrange::numeric::stabilize::PROJECTION_ITERATIONS,
        },
    };
    // Every drift-control flag is checked, whichever --stabilize runs (as the velocity-level
    // flags are, whichever --solver), so a typo never passes silently.
    let flags = [
        Stabilize::Baumgarte { zeta: args.zeta, omega_dt: args.omega_dt },
        Stabilize::Projection {
            tolerance: args.tolerance,
            max_iterations: lagrange::numeric::stabilize::PROJECTION_ITERATIONS,
        },
    ];
    for flag in flags {
        flag.validate().map_err(|e| {
            errln!("error: {}", SimError::Settings(e.into()));
            ExitCode::from(2)
        })?;
    }
    // The samples feed the plot alone: without --plot a step keeps none (a Vec a step).
    if args.plot.is_none() {
        settings.samples = 0;
    }
    settings.validate().map_err(|e| {
        errln!("error: {}", SimError::Settings(e));
        ExitCode::from(2)
    })?;
    Ok(settings)
}

/// The `--csv` writer, its header written (exit 1 when the file cannot be written).
fn csv_writer(
    path: &Path,
    system: &lagrange::System,
    every: u64,
    steps: u64,
) -> Result<lagrange::report::csv::CsvWriter<std::io::BufWriter<std::fs::File>>, ExitCode> {
    let file = std::fs::File::create(path).map_err(|e| e.to_string());
    let out = file.and_then(|f| {
        lagrange::report::csv::CsvWriter::new(system, std::io::BufWriter::new(f), every, steps)
            .map_err(|e| e.to_string())
    });
    out.map_err(|e| {
        errln!("error: cannot write {}: {e}", path.display());
        ExitCode::from(1)
    })
}

/// The run's summary (text or JSON) and its `--plot` (exit 1 when the plot cannot be written).
fn show_simulation(
    args: &SimulateArgs,
    scenario: &lagrange::scenario::Scenario,
    summary: &lagrange::numeric::simulate::Summary,
    stopped: Option<&str>,
) -> Result<(), ExitCode> {
    let dim = scenario.system.dim();
    if args.format == SummaryArg::Json {
        emit_json(&lagrange::report::simulation::json(summary, dim, stopped));
    } else {
        outln!("{}", lagrange::report::simulation::text(summary, dim));
    }
    if let Some(path) = &args.plot {
        let title = format!(
            "{} — {} + {}",
            scenario.system.title,
            summary.integrator,
            lagrange::report::simulation::stabilization(summary)
        );
        let written = lagrange::report::plot::simulation(&title, summary)
            .and_then(|svg| std::fs::write(path, svg).map_err(|e| e.to_string()));
        if let Err(e) = written {
            errln!("error: {}: {e}", path.display());
            return Err(ExitCode::from(1));
        }
    }
    Ok(())
}

fn cmd_bench(args: &BenchArgs) -> ExitCode {
    use lagrange::report::precision as table;
    if let Err(code) = refuse_overwrite(&args.file, &[("--plot", args.plot.as_deref())]) {
        return code;
    }
    let (scenario, _) = match scenario(&args.file, &args.state) {
        Ok(s) => s,
        Err(code) => return code,
    };
    if args.solvers {
        return cmd_bench_solvers(args, &scenario);
    }
    let max_states = lagrange::precision::accuracy::MAX_STATES;
    if args.states > max_states {
        eprintln!(
            "error: --states must be at most {max_states} (precision::accuracy::MAX_STATES), found {}",
            args.states
        );
        return ExitCode::from(2);
    }
    let sweep = lagrange::precision::Sweep::new(
        args.dt.unwrap_or(scenario.scene.dt),
        args.duration.unwrap_or(scenario.scene.duration),
    );
    let runs = sweep.distinct_steps().len();
    if runs < sweep.steps.len() && sweep.validate().is_ok() {
        errln!(
            "note: a duration of {} gives several of the {} step sizes (dt × 4, 2, 1, ½ of {}) the same number of steps: each distinct run is shown once ({runs} of them); a longer --duration or a smaller --dt sweeps all",
            sweep.duration,
            sweep.steps.len(),
            args.dt.unwrap_or(scenario.scene.dt),
        );
    }
    let wp = match lagrange::precision::work_precision(&scenario, &sweep) {
        Ok(wp) => wp,
        Err(e) => {
            errln!("error: {}: {e}", args.file.display());
            return ExitCode::from(2);
        }
    };
    let accuracy = lagrange::precision::accuracy::formula_accuracy(&scenario, args.states, 1);
    match args.format {
        OutArg::Text => outln!("{}", table::text(&wp, &accuracy)),
        OutArg::Json => emit_json(&table::json(&wp, &accuracy)),
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
            errln!("error: {}: {e}", path.display());
            return ExitCode::from(1);
        }
    }
    ExitCode::SUCCESS
}

/// `bench --solvers`: the velocity-level solver bench of `numeric::velocity::bench`.
fn cmd_bench_solvers(args: &BenchArgs, scenario: &lagrange::scenario::Scenario) -> ExitCode {
    use lagrange::numeric::velocity::bench::{Plan, Scene, solver_bench};
    use lagrange::report::solvers as table;
    let dt = args.dt.unwrap_or(scenario.scene.dt);
    let duration = args.duration.unwrap_or(scenario.scene.duration);
    let steps = match lagrange::numeric::simulate::checked_steps(duration, dt) {
        Ok(steps) => steps,
        Err(e) => {
            errln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let plan = Plan::new(dt, steps);
    let scene = Scene {
        system: &scenario.system,
        program: &scenario.program,
        env: &scenario.env,
        restitution: scenario.scene.restitution,
    };
    let bench = match solver_bench(scene, &plan) {
        Ok(b) => b,
        Err(e) => {
            errln!("error: {}: {e}", args.file.display());
            return ExitCode::from(2);
        }
    };
    match args.format {
        OutArg::Text => out!("{}", table::text(&bench)),
        OutArg::Json => emit_json(&table::json(&bench)),
        OutArg::Csv => out!("{}", table::csv(&bench)),
    }
    if let Some(path) = &args.plot {
        let title = format!("{}: velocity-level solvers, max |C| against time per step", bench.title);
        let written =
            lagrange::report::plot::work_precision(&title, "seconds per step", "max |C|", &table::lines(&bench))
                .and_then(|svg| std::fs::write(path, svg).map_err(|e| e.to_string()));
        if let Err(e) = written {
            errln!("error: {}: {e}", path.display());
            return ExitCode::from(1);
        }
    }
    ExitCode::SUCCESS
}
