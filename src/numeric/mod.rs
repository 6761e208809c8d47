//! Numbers from formulas: compiled evaluation of expression graphs.
//!
//! [`program`] lowers graph expressions to one scalar SSA program (components, folded
//! constants, scalar-level CSE); [`tape`] allocates registers for it and evaluates it at one
//! state or at many (structure of arrays, vectorised lanes, rayon for large batches). The Rust
//! generator (`codegen`) starts from the same program.
//!
//! This module knows nothing of TOML, files or text.

pub mod program;
pub mod tape;

pub use tape::{BatchScratch, Scratch, Tape, TapeError};
