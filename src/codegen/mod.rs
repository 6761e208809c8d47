//! Source code for the derived formulas, for people who want the numbers in their own program.
//!
//! [`layout`] decides how a system's outputs are laid out (dense or banded A, dense or block
//! J, parts of at most 64 formulas); [`rust`] writes a self-contained Rust module (no
//! dependency on lagrange or any crate) following it, and `c` the formulas as C99 with the
//! Rust module's numbers bit for bit, with the helper functions of
//! `support` (real Rust files, included as text).
//! The code is generated from the same scalar program the tape evaluates
//! ([`crate::numeric::program`]), so codegen and the tape share one lowering.
//!
//! Codegen may print text (it writes source), but it never touches files or stdout:
//! `main.rs` decides where the text goes.
//!
//! Not here: files, stdout, evaluation of the formulas (`numeric`).

mod c;
mod c_solve;
pub mod layout;
mod names;
pub mod rust;
mod shapes;
mod support;

pub use rust::{GenerateError, Lang, Module, Options, generate, module};

/// The flags of `lagrange generate` a module was written with, after `--lang`, for its
/// opening comment: regenerating with them writes the same module.
fn flags(specialize: bool, solver: Option<layout::Solver>) -> String {
    let mut out = String::new();
    if specialize {
        out.push_str(" --specialize");
    }
    if let Some(solver) = solver {
        out.push_str(" --solver ");
        out.push_str(solver.name());
    }
    out
}
