//! Documents for people and programs: derivations, diagnostics, (later) tables and plots.
//!
//! Everything here returns strings or JSON values; only `main.rs` writes them out.

pub mod csv;
pub mod derivation;
pub mod diagnostic;
pub mod plot;
pub mod precision;
pub mod simulation;
pub mod solution;
pub mod solvers;
