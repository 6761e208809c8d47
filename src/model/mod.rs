//! Constraint files and the systems they describe: raw TOML in, a validated model out.
//!
//! `raw` holds every raw type of a file (the TOML as written, with spans); `document` fills
//! them from toml's spanned tree, `keys` reports unknown keys; `file` validates them into a
//! `System` (`system` holds the resolved model and its builder), with `scene` for `[scene]`
//! and `expect` for `[[expect]]`; `state` checks a value against its symbol, for the file
//! and for states given on the command line (`--at`, `--set`); `problem` is what can be
//! wrong, one variant per cause. Each module uses only modules listed above it, so there
//! is no import circle (checked by `tests/model.rs`):
//!
//! ```text
//! raw, system     the raw types; the model and its builder (no other model module)
//! state           raw, system
//! problem         state, system
//! keys            problem
//! scene, expect   problem, raw, state, system
//! document        keys, problem, raw
//! file            document, scene, expect, problem, raw, state, system
//! ```
//!
//! Not here: reading files from disk (the caller passes the text), deriving, numbers.

pub mod document;
pub mod expect;
pub mod file;
pub mod keys;
pub mod problem;
pub mod raw;
pub mod scene;
pub mod state;
pub mod system;
