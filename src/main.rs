//! The `lagrange` command line: parse arguments, call the library, print. Nothing else.

use clap::{Parser, Subcommand, ValueEnum};
use lagrange::derive::derive;
use lagrange::model::file::{Problem, load};
use lagrange::report::derivation::{self, Format};
use lagrange::report::diagnostic::render;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

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
    /// Run the scene: integrate, stabilise, report drift and energy.
    Simulate(SimulateArgs),
    /// Speed against error: a work-precision sweep and the formulas' f64 accuracy.
    Bench(BenchArgs),
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Run on a thread with a generous stack: recursion is bounded everywhere, and this is a
    // second line of defence for inputs nobody thought of.
    let worker = std::thread::Builder::new().stack_size(256 << 20).spawn(move || run(cli));
    match worker.map(|h| h.join()) {
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
        Command::Simulate(args) => cmd_simulate(&args),
        Command::Bench(args) => cmd_bench(&args),
    }
}

/// Reads a file as UTF-8 text, with a clear message for the ways that fails.
fn read_text(path: &Path) -> Result<String, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("error: cannot read {}: {e}", path.display()))?;
    if bytes.len() > lagrange::model::file::MAX_FILE_BYTES {
        return Err(format!(
            "error: {} is too large ({} bytes; the limit is {} bytes)",
            path.display(),
            bytes.len(),
            lagrange::model::file::MAX_FILE_BYTES
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        format!(
            "error: {} is not valid UTF-8 (invalid byte at offset {})",
            path.display(),
            e.utf8_error().valid_up_to()
        )
    })
}

fn report_problems(path: &Path, text: &str, problems: &[Problem]) -> ExitCode {
    eprint!("{}", render(&path.display().to_string(), text, problems));
    eprintln!("{} problem{} in {}", problems.len(), if problems.len() == 1 { "" } else { "s" }, path.display());
    ExitCode::from(1)
}

fn cmd_derive(path: &Path, format: FormatArg, steps: bool) -> ExitCode {
    let text = match read_text(path) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(1);
        }
    };
    let mut loaded = match load(&text) {
        Ok(l) => l,
        Err(problems) => return report_problems(path, &text, &problems),
    };
    let derivation = match derive(&mut loaded.system) {
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
    let result = if format == Format::Json {
        derivation::json(&loaded.system, &derivation).map(|v| serde_json::to_string_pretty(&v).unwrap_or_default())
    } else {
        derivation::document(&mut loaded.system, &derivation, format, steps)
    };
    match result {
        Ok(s) => {
            println!("{s}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {}: {e}", path.display());
            ExitCode::from(1)
        }
    }
}

/// Reads, loads and derives a file into a runnable scenario, or reports why not.
fn scenario(path: &Path) -> Result<lagrange::scenario::Scenario, ExitCode> {
    let text = read_text(path).map_err(|e| {
        eprintln!("{e}");
        ExitCode::from(1)
    })?;
    let loaded = load(&text).map_err(|problems| report_problems(path, &text, &problems))?;
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
        println!(
            "{}",
            serde_json::to_string_pretty(&lagrange::report::simulation::json(&summary, dim)).unwrap_or_default()
        );
    } else {
        println!("{}", lagrange::report::simulation::text(&summary, dim));
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
        OutArg::Text => println!("{}", table::text(&wp, &accuracy)),
        OutArg::Json => println!("{}", serde_json::to_string_pretty(&table::json(&wp, &accuracy)).unwrap_or_default()),
        OutArg::Csv => print!("{}", table::csv(&wp, &accuracy)),
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
