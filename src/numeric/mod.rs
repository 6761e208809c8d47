//! Numbers from formulas: compiled evaluation, the rows of a derived system at a state, the
//! multiplier solve, and simulation.
//!
//! [`program`] lowers graph expressions to one scalar SSA program (components, folded
//! constants, scalar-level CSE); [`tape`] allocates registers for it and evaluates it at one
//! state or at many (structure of arrays, vectorised lanes, rayon for large batches). The Rust
//! generator (`codegen`) starts from the same program. [`rows`] evaluates a derivation's rows
//! (C, Ċ, J, c) at a state, shape by shape where the scene repeats one ([`batch`]); [`solve`] finds the multipliers ([`single`] for one row on one body, `chain` for rows that form a chain in their order, [`banded`], [`sparse`], [`qp`], [`contact`],
//! [`rescale`]). [`dynamics`], [`integrate`], [`stabilize`] and [`simulate`] step a scene.
//! [`rotation`] moves 3D rigid bodies' quaternions and holds the
//! implicit gyroscopic kick. [`vector`] holds the small vector arithmetic they share, [`random`] the one seeded generator.
//!
//! This module knows nothing of TOML, files or text: states arrive as
//! [`crate::expr::eval::Env`], results leave as plain numbers and diagnostics.

pub mod band_lambda;
pub mod banded;
pub mod batch;
mod chain;
pub mod contact;
pub mod dynamics;
pub(crate) mod gram;
pub mod integrate;
#[cfg(feature = "jit")]
pub mod jit;
pub mod program;
pub mod qp;
pub mod random;
pub mod rescale;
pub mod rotation;
pub mod rows;
pub mod simulate;
pub mod single;
pub mod solve;
pub mod sparse;
pub mod stabilize;
pub mod tape;
pub mod vector;
pub mod velocity;

#[cfg(feature = "jit")]
pub use jit::{JitError, JitTape};
pub use tape::{BatchScratch, FewScratch, Scratch, Tape, TapeError};
