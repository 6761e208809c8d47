//! Constraint files and the systems they describe.
//!
//! `system` holds the resolved model (symbols, constraints as graph nodes) and its builder;
//! `file` reads TOML into raw serde structs and validates them into a `System`.

pub mod file;
pub mod system;
