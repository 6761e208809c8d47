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
    /// Run the files' [[expect]] entries; exit non-zero on any failure.
    Check {
        /// Constraint files (TOML).
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
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
        Command::Check { files } => cmd_check(&files),
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
            println!("{name}: no [[expect]] entries");
        }
        for o in outcomes {
            let place = o.span.as_ref().map_or(name.clone(), |s| location(&name, &text, s.start));
            if o.passed {
                passed += 1;
                println!("ok     {place}: {} ({})", o.label, o.how);
            } else {
                failed += 1;
                println!("FAILED {place}: {} ({})", o.label, o.how);
                println!("{}", o.detail);
            }
        }
    }
    println!("{passed} passed, {failed} failed");
    if failed == 0 { ExitCode::SUCCESS } else { ExitCode::from(1) }
}

/// `file:line:col` of a byte offset.
fn location(name: &str, text: &str, offset: usize) -> String {
    let before = &text[..lagrange::report::diagnostic::floor_char(text, offset.min(text.len()))];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    format!("{name}:{line}:{col}")
}
