//! Build-time use from a user's `build.rs`: a constraint file becomes the generated Rust
//! module in cargo's `OUT_DIR`, regenerated when the file changes.
//!
//! ```no_run
//! // The `fn main` of build.rs, in a crate with `lagrange` as a build-dependency:
//! if let Err(e) = lagrange::build::module("constraints/pendulum.toml") {
//!     eprintln!("{e}"); // the diagnostic `lagrange generate` prints, located in the file
//!     std::process::exit(1);
//! }
//! // src/lib.rs: include!(concat!(env!("OUT_DIR"), "/pendulum.rs"));
//! ```
//!
//! [`module`] writes `OUT_DIR/<stem>.rs` (the file's stem in snake_case: `chain-5.toml` →
//! `chain_5.rs`) and prints `cargo:rerun-if-changed=<file>`; [`Module`] takes the options of
//! `lagrange generate` (`specialize`, `solver`) and another output name or directory. A file
//! that does not load or derive is a [`BuildError`] whose `Display` is the located message
//! `lagrange generate` prints (every problem with its line, column and caret).
//!
//! This is the one place besides `main.rs` that writes a file and prints: cargo's build
//! script protocol is a line on stdout, and the module is a file in `OUT_DIR`.
//!
//! Not here: the code itself (`codegen`), the wording of file problems (`model::problem`,
//! drawn by `report::diagnostic`).

use crate::check::{CheckError, read_text};
use crate::codegen::rust::{Lang, Options, module as generate_module, snake};
use crate::codegen::{GenerateError, layout::Solver};
use crate::model::file::{Problem, load};
use crate::report::diagnostic::{render, render_constraint};
use std::path::{Path, PathBuf};

/// Why a module could not be built; `Display` is the message `lagrange generate` prints.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// Not run by cargo as a build script (and no [`Module::out_dir`] given).
    #[error("OUT_DIR is not set: lagrange::build runs in a build script (build.rs), where cargo sets it")]
    NoOutDir,
    /// The constraint file could not be read.
    #[error("error: {0}")]
    Read(CheckError),
    /// The file is invalid: every problem, located in it.
    #[error("{}{} problem{} in {}", render(&path.display().to_string(), text, problems), problems.len(),
            if problems.len() == 1 { "" } else { "s" }, path.display())]
    Invalid { path: PathBuf, text: String, problems: Vec<Problem> },
    /// Its derivation failed on constraint `constraint` (a formula past the work budget):
    /// located at that constraint's `expr`.
    #[error("{}", render_constraint(&path.display().to_string(), text, *constraint, &source.to_string()))]
    Located { path: PathBuf, text: String, constraint: usize, source: GenerateError },
    /// The code could not be generated (a parameter value that cannot be written, a module
    /// past the code budget).
    #[error("error: {}: {source}", path.display())]
    Generate { path: PathBuf, source: GenerateError },
    /// The module could not be written.
    #[error("error: cannot write {}: {source}", path.display())]
    Write { path: PathBuf, source: std::io::Error },
}

/// Generates the Rust module of `file` into `OUT_DIR/<stem>.rs` with `lagrange generate`'s
/// defaults, prints `cargo:rerun-if-changed=<file>`, and returns the path written.
pub fn module(file: impl AsRef<Path>) -> Result<PathBuf, BuildError> {
    Module::new(file).write()
}

/// A module to generate at build time, with `lagrange generate`'s options.
#[derive(Clone, Debug)]
pub struct Module {
    file: PathBuf,
    specialize: bool,
    solver: Option<Solver>,
    step_only: bool,
    name: Option<String>,
    out_dir: Option<PathBuf>,
}

impl Module {
    /// The module of a constraint file (a path relative to the crate's root, where cargo runs
    /// build scripts).
    pub fn new(file: impl AsRef<Path>) -> Module {
        Module {
            file: file.as_ref().to_path_buf(),
            specialize: false,
            solver: None,
            step_only: false,
            name: None,
            out_dir: None,
        }
    }

    /// Substitute the file's parameter values before generating (`--specialize`).
    pub fn specialize(mut self, yes: bool) -> Module {
        self.specialize = yes;
        self
    }

    /// Write the velocity-level step of this solver too (`--solver`).
    pub fn solver(mut self, solver: Solver) -> Module {
        self.solver = Some(solver);
        self
    }

    /// Write the step only, each repeated row shape once over a table of its instances
    /// (`--step-only`; with `solver` the soft step or PGS).
    pub fn step_only(mut self, yes: bool) -> Module {
        self.step_only = yes;
        self
    }

    /// The output's file name (default: the constraint file's stem in snake_case, `.rs`).
    pub fn name(mut self, name: impl Into<String>) -> Module {
        self.name = Some(name.into());
        self
    }

    /// The directory written into (default: `OUT_DIR`).
    pub fn out_dir(mut self, dir: impl AsRef<Path>) -> Module {
        self.out_dir = Some(dir.as_ref().to_path_buf());
        self
    }

    /// The output's file name: the given one, else `<stem>.rs` with the stem in snake_case.
    pub fn file_name(&self) -> String {
        self.name.clone().unwrap_or_else(|| {
            let stem = self.file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            format!("{}.rs", snake(&stem))
        })
    }

    /// The module's source, as `lagrange generate` writes it (no file written, nothing printed).
    pub fn code(&self) -> Result<String, BuildError> {
        self.generated().map(|m| m.code)
    }

    fn generated(&self) -> Result<crate::codegen::Module, BuildError> {
        let path = &self.file;
        let text = read_text(path).map_err(BuildError::Read)?;
        let loaded =
            load(&text).map_err(|problems| BuildError::Invalid { path: path.clone(), text: text.clone(), problems })?;
        let options =
            Options { specialize: self.specialize, solver: self.solver, lang: Lang::Rust, step_only: self.step_only };
        generate_module(&loaded, &options).map_err(|source| match &source {
            GenerateError::Derive(e) if e.constraint().is_some() => {
                BuildError::Located { path: path.clone(), constraint: e.constraint().unwrap_or_default(), text, source }
            }
            _ => BuildError::Generate { path: path.clone(), source },
        })
    }

    /// Generates the module into the output directory, prints `cargo:rerun-if-changed=` for
    /// the constraint file (also when it is bad, so fixing it re-runs the build script), and
    /// returns the path written; the module's warnings (constants past f64's range) become
    /// `cargo:warning=` lines. The file is rewritten only when its text changes.
    pub fn write(&self) -> Result<PathBuf, BuildError> {
        println!("cargo:rerun-if-changed={}", self.file.display());
        let dir = match &self.out_dir {
            Some(dir) => dir.clone(),
            None => std::env::var_os("OUT_DIR").map(PathBuf::from).ok_or(BuildError::NoOutDir)?,
        };
        let generated = self.generated()?;
        for warning in &generated.warnings {
            println!("cargo:warning={}: {warning}", self.file.display());
        }
        let code = generated.code;
        let out = dir.join(self.file_name());
        if std::fs::read_to_string(&out).is_ok_and(|old| old == code) {
            return Ok(out);
        }
        std::fs::write(&out, code).map_err(|source| BuildError::Write { path: out.clone(), source })?;
        Ok(out)
    }
}
