//! The symbolic core: expression graph, parser, type checker, simplifier, d/dt, ∇, printers.
//!
//! Text goes in through [`parse`] and [`lower`]; derivatives come out of [`diff`] and
//! [`grad`]; [`simplify`] brings any expression to its readable canonical form; [`print`](mod@print)
//! writes it back as the expression language, Unicode text or LaTeX.
//!
//! This module knows nothing of files, serde, nalgebra or the terminal (a test checks it).

pub mod diff;
pub mod eval;
pub mod func;
pub mod grad;
pub mod graph;
pub mod lower;
pub mod num;
pub mod parse;
pub mod poly;
mod present;
pub mod print;
mod rigid;
pub mod shape;
pub mod simplify;
pub mod syntax;
pub mod work;

pub use func::Func;
pub use graph::{Axis, Graph, Id, Node, Role, Symbol, Ty, TypeError};
pub use num::Rational;
pub use print::Style;
pub use simplify::Simplifier;
