//! Constraint files and the systems they describe.
//!
//! `system` holds the resolved model (symbols, constraints as graph nodes) and its builder;
//! `file` reads TOML into raw serde structs and validates them into a `System`; `scene`
//! resolves the `[scene]` table and gives a state its numbers.

pub mod expect;
pub mod file;
pub mod keys;
pub mod scene;
pub mod system;
