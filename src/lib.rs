//! lagrange: derive constraint forces from constraints written as text, and compute them.
//!
//! The pipeline: a constraint file ([`model::file`]) becomes a [`model::system::System`] of
//! graph nodes ([`expr`]); [`derive`](mod@derive) takes Ċ, C̈, ∇C, A and b and, for one constraint, λ
//! and the forces in closed form; [`report`] lays the results out for people and programs.
//! [`numeric`] compiles formulas to a flat tape for numbers (one state or a batch), and
//! [`codegen`] writes them as source code, both from one scalar lowering.

pub mod check;
pub mod codegen;
pub mod derive;
pub mod expr;
pub mod model;
pub mod numeric;
pub mod precision;
pub mod report;
pub mod scenario;
