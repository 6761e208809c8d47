//! Numbers: the rows of a derived system at a state, and the multiplier solve.
//!
//! This module knows nothing of TOML or text: states arrive as [`crate::expr::eval::Env`],
//! results leave as plain numbers and diagnostics.

pub mod dynamics;
pub mod integrate;
pub mod rows;
pub mod simulate;
pub mod solve;
pub mod stabilize;
