//! The syntax tree of one expression or relation, exactly as written, with source spans.
//!
//! The parser produces this tree and nothing else; [`super::lower`] resolves names, checks
//! types and turns it into graph nodes. Sums and products are lists, not nested binary
//! nodes, so a ten-megabyte `x + x + … + x` is one wide node rather than a deep chain.
//!
//! Not here: numbers' values (a literal keeps its text), names' meanings, types.

use super::graph::Axis;

/// A half-open byte range `start..end` into the parsed text.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Debug, Default)]
pub struct Span {
    pub start: usize,
    pub end: usize,
}

impl Span {
    pub fn new(start: usize, end: usize) -> Span {
        Span { start, end }
    }

    /// The smallest span covering both.
    pub fn to(self, other: Span) -> Span {
        Span { start: self.start.min(other.start), end: self.end.max(other.end) }
    }
}

/// A node of the syntax tree.
#[derive(Clone, PartialEq, Debug)]
pub struct Syntax<'a> {
    pub kind: SyntaxKind<'a>,
    pub span: Span,
}

/// `+` or `-` before a term of a sum.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Sign {
    Plus,
    Minus,
}

/// `*` or `/` before a factor of a product.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum MulOp {
    Times,
    Over,
}

#[derive(Clone, PartialEq, Debug)]
pub enum SyntaxKind<'a> {
    /// A decimal literal, as written.
    Number(&'a str),
    Ident(&'a str),
    /// `t1 ± t2 ± …`; the first sign is always `Plus` (a leading minus is `Neg`).
    Sum(Vec<(Sign, Syntax<'a>)>),
    /// `f1 */ f2 */ …`; the first operator is always `Times`.
    Product(Vec<(MulOp, Syntax<'a>)>),
    Neg(Box<Syntax<'a>>),
    Pow(Box<Syntax<'a>>, Box<Syntax<'a>>),
    /// `name(args…)`, with the span of the name.
    Call {
        name: &'a str,
        name_span: Span,
        args: Vec<Syntax<'a>>,
    },
    /// `e.x`, with the span of the component letter.
    Component(Box<Syntax<'a>>, Axis, Span),
    /// `[e1, e2, …]`.
    Vector(Vec<Syntax<'a>>),
    /// `( e )`: kept so that printing and parsing again gives the same grouping.
    Paren(Box<Syntax<'a>>),
}

/// The comparison of a constraint.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum RelOp {
    Eq,
    Ge,
    Le,
}

/// `lhs op rhs`, or a bare expression meaning `expr = 0`.
#[derive(Clone, PartialEq, Debug)]
pub struct Relation<'a> {
    pub lhs: Syntax<'a>,
    pub rel: Option<(RelOp, Span, Syntax<'a>)>,
}
