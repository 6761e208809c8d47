//! lagrange: derive constraint forces from constraints written as text, and compute them.
//!
//! The pipeline: a constraint file ([`load`]) becomes a [`System`] of graph nodes
//! ([`expr`]); [`derive`](fn@derive) takes Ċ, C̈, ∇C, A and b and, for one constraint, λ and
//! the forces in closed form, into a [`Derivation`]; [`report`] lays the results out for
//! people and programs; [`numeric`] compiles formulas to a flat tape for numbers (one state
//! or a batch), solves for λ and simulates a [`Scenario`]; [`codegen`] writes the formulas
//! as source code ([`generate`]), from the same scalar lowering; [`Checked`] runs a file's
//! `[[expect]]` entries, or a user's own assertions, as tests.
//!
//! The names below are the surface a user starts from. The stage modules stay public: the
//! command line, the benchmarks and the tests drive each stage (the tape, the solver, the
//! printers) directly, and a user building an engine on lagrange may too.
//!
//! The article's bead, from text to formula to number (`examples/derive_bead.rs`):
//!
//! ```
#![doc = include_str!("../examples/derive_bead.rs")]
//! ```

pub mod build;
pub mod check;
pub mod codegen;
pub mod derive;
pub mod expr;
pub mod model;
pub mod numeric;
pub mod precision;
pub mod report;
pub mod scenario;

pub use check::{CheckError, Checked, Outcome};
pub use codegen::{GenerateError, Options as GenerateOptions, generate};
pub use derive::{Derivation, DeriveError, Options as DeriveOptions, derive, derive_with};
pub use model::file::{Loaded, Problem, load};
pub use model::system::{System, SystemBuilder};
pub use scenario::Scenario;
