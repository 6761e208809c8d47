//! Constraint files and the systems they describe.
//!
//! `system` holds the resolved model (symbols, constraints as graph nodes) and its builder;
//! `document` reads the spanned TOML tree into raw structs (every type error collected),
//! `keys` reports unknown keys, `file` validates the raw structs into a `System`; `scene`
//! resolves the `[scene]` table and gives a state its numbers.

pub mod document;
pub mod expect;
pub mod file;
pub mod keys;
pub mod scene;
pub mod system;
