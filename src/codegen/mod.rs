//! Source code for the derived formulas, for people who want the numbers in their own program.
//!
//! [`rust`] writes a self-contained Rust module (no dependency on lagrange or any crate).
//! The code is generated from the same scalar program the tape evaluates
//! ([`crate::numeric::program`]), so codegen and the tape share one lowering.
//!
//! Codegen may print text (it writes source), but it never touches files or stdout:
//! `main.rs` decides where the text goes.

mod names;
pub mod rust;
mod support;

pub use rust::{GenerateError, Module, Options, generate, module};
