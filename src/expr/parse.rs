//! The nom parser of the expression language (DESIGN.md), producing a [`Syntax`] tree.
//!
//! Precedence, loosest first: relations `= >= <=` (top level only), `+ -`, `* /`, unary
//! minus, `^` (right associative, so `-x^2` is `-(x^2)` and `x^-1` is allowed), components
//! `e.x`, then atoms: numbers, names, calls `f(a, b)`, `( e )` and vector literals `[a, b]`.
//!
//! Hostile input is bounded: nesting (parentheses, brackets, calls, unary minus, powers) is
//! limited to [`MAX_NESTING`] levels and text to [`MAX_LEN`] bytes, so no input can overflow
//! the stack; sums and products are parsed as flat lists by loops, not recursion.
//!
//! Not here: names' meanings, types, the values of numbers (see `lower`).

use super::graph::Axis;
use super::syntax::{MulOp, RelOp, Relation, Sign, Span, Syntax, SyntaxKind};
use nom::branch::alt;
use nom::bytes::complete::{tag, take_while1};
use nom::character::complete::char;
use nom::combinator::{opt, recognize};
use nom::error::{ErrorKind, ParseError as NomParseError};
use nom::{Err, IResult, Parser};
use std::borrow::Cow;

/// The deepest nesting of parentheses, brackets, calls, unary minus and powers.
pub const MAX_NESTING: u32 = 200;

/// Stack headroom below which recursion continues on a fresh heap-allocated segment.
pub const STACK_RED_ZONE: usize = 128 * 1024;
/// The size of each such segment.
pub const STACK_GROWTH: usize = 2 * 1024 * 1024;

/// The longest expression text accepted, in bytes.
pub const MAX_LEN: usize = 1 << 20;

/// A syntax error: where, and what was expected.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct ParseError {
    pub span: Span,
    pub message: String,
}

/// nom's error type for this parser: the remaining input where it failed and what was expected.
///
/// Alternatives that fail are part of parsing good text (`opt` of a fraction or an exponent
/// of every number), so a fixed message is borrowed, not allocated.
#[derive(Debug)]
struct PErr<'a> {
    at: &'a str,
    message: Cow<'static, str>,
}

impl<'a> NomParseError<&'a str> for PErr<'a> {
    fn from_error_kind(input: &'a str, _kind: ErrorKind) -> Self {
        PErr { at: input, message: Cow::Borrowed("unexpected input") }
    }

    fn append(_: &'a str, _: ErrorKind, other: Self) -> Self {
        other
    }

    /// Of two alternatives that failed, report the one that got further.
    fn or(self, other: Self) -> Self {
        if other.at.len() < self.at.len() { other } else { self }
    }
}

type Res<'a, T> = IResult<&'a str, T, PErr<'a>>;

fn fail<'a, T>(at: &'a str, message: impl Into<Cow<'static, str>>) -> Res<'a, T> {
    Err(Err::Error(PErr { at, message: message.into() }))
}

fn cut<'a, T>(at: &'a str, message: impl Into<Cow<'static, str>>) -> Res<'a, T> {
    Err(Err::Failure(PErr { at, message: message.into() }))
}

/// Parses one expression (no relation).
pub fn parse_expr(text: &str) -> Result<Syntax<'_>, ParseError> {
    let p = Parse::new(text)?;
    let (rest, e) = p.expr(text, 0).map_err(|e| p.error(e))?;
    p.finish(rest, After::Expression)?;
    Ok(e)
}

/// Parses `lhs = rhs`, `lhs >= rhs`, `lhs <= rhs` or a bare `C`.
pub fn parse_relation(text: &str) -> Result<Relation<'_>, ParseError> {
    let p = Parse::new(text)?;
    let (rest, lhs) = p.expr(text, 0).map_err(|e| p.error(e))?;
    let (rest, _) = ws(rest).map_err(|e| p.error(e))?;
    let rel_op = alt((tag(">="), tag("<="), tag("=="), tag("=")));
    let (_, rel) = match opt(rel_op).parse(rest).map_err(|e| p.error(e))? {
        (after, Some(op)) => {
            let op_span = p.span(rest, after);
            let op = match op {
                ">=" => RelOp::Ge,
                "<=" => RelOp::Le,
                _ => RelOp::Eq,
            };
            let (after, rhs) = p.expr(after, 0).map_err(|e| p.error(e))?;
            p.finish(after, After::Rhs)?;
            (after, Some((op, op_span, rhs)))
        }
        (rest, None) => {
            p.finish(rest, After::Lhs)?;
            (rest, None)
        }
    };
    Ok(Relation { lhs, rel })
}

struct Parse<'s> {
    src: &'s str,
}

/// What text left over after an expression follows, for the hint of its message.
#[derive(Clone, Copy, PartialEq, Eq)]
enum After {
    /// A whole expression (a definition, a force).
    Expression,
    /// The left side of a constraint, no relation operator yet.
    Lhs,
    /// The right side of a constraint.
    Rhs,
}

/// A hint for notation the language does not have, written where someone used to
/// mathematics (or to how lagrange prints formulas) writes it: `|r|`, `r·r`, `l²`, `−`,
/// `√`, `**`, and the strict inequalities `>` and `<`.
fn notation_hint(at: &str) -> Option<&'static str> {
    let mut chars = at.chars();
    let first = chars.next()?;
    let second = chars.next();
    Some(match first {
        '|' => ": write the norm |r| as `norm(r)`",
        '·' => ": `·` is how lagrange prints a dot product; write `dot(r, r)`",
        '×' => ": `×` is how lagrange prints a cross product; write `cross(a, b)`",
        '²' | '³' | '⁴' | '⁵' | '⁶' | '⁷' | '⁸' | '⁹' | '⁰' | '¹' | '⁻' => {
            ": write powers with `^`, e.g. `l^2`"
        }
        '−' => ": `−` (the Unicode minus sign) is not `-`; write `-`",
        '√' => ": write roots as `sqrt(x)`",
        '*' if second == Some('*') => ": write powers with `^`, e.g. `l^2`, not `l**2`",
        '>' | '<' if second != Some('=') => {
            ": a strict inequality is not a constraint (a contact holds at equality); write `>=` or `<=`"
        }
        _ => return None,
    })
}

/// Spaces, tabs and line breaks (nom's `multispace0`, as a loop over bytes: it runs
/// between every two tokens).
fn ws(i: &str) -> Res<'_, &str> {
    let n = i.bytes().take_while(|b| matches!(b, b' ' | b'\t' | b'\r' | b'\n')).count();
    Ok((&i[n..], &i[..n]))
}

fn is_ident_start(c: char) -> bool {
    c.is_ascii_alphabetic() || c == '_'
}

fn is_ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// A name: a letter or `_`, then letters, digits and `_` (all ASCII, so bytes suffice).
fn ident(i: &str) -> Res<'_, &str> {
    let bytes = i.as_bytes();
    if !bytes.first().is_some_and(|&b| is_ident_start(b as char)) {
        return fail(i, "unexpected input");
    }
    let n = 1 + bytes[1..].iter().take_while(|&&b| is_ident_char(b as char)).count();
    Ok((&i[n..], &i[..n]))
}

/// `12`, `1.5`, `.5`, `2.`, `1e-3`: digits with an optional fraction and exponent, no sign.
fn number(i: &str) -> Res<'_, &str> {
    let digits = || take_while1(|c: char| c.is_ascii_digit());
    let mantissa = alt((recognize((digits(), opt((char('.'), opt(digits()))))), recognize((char('.'), digits()))));
    let exponent = (alt((char('e'), char('E'))), opt(alt((char('+'), char('-')))), digits());
    recognize((mantissa, opt(exponent))).parse(i)
}

impl<'s> Parse<'s> {
    fn new(src: &'s str) -> Result<Parse<'s>, ParseError> {
        if src.len() > MAX_LEN {
            return Err(ParseError {
                span: Span::new(0, 0),
                message: format!(
                    "expression is too long ({} bytes; the limit is {} bytes): split it into definitions",
                    src.len(),
                    MAX_LEN
                ),
            });
        }
        Ok(Parse { src })
    }

    fn offset(&self, rest: &str) -> usize {
        self.src.len() - rest.len()
    }

    fn span(&self, from: &str, to: &str) -> Span {
        Span::new(self.offset(from), self.offset(to))
    }

    fn error(&self, e: Err<PErr<'s>>) -> ParseError {
        match e {
            Err::Error(e) | Err::Failure(e) => {
                let start = self.offset(e.at);
                let end = (start + e.at.chars().next().map_or(0, char::len_utf8)).min(self.src.len());
                ParseError { span: Span::new(start, end), message: e.message.into_owned() }
            }
            Err::Incomplete(_) => {
                ParseError { span: Span::new(self.src.len(), self.src.len()), message: "unexpected end".into() }
            }
        }
    }

    fn finish(&self, rest: &str, after: After) -> Result<(), ParseError> {
        let rest = rest.trim_start();
        if rest.is_empty() {
            return Ok(());
        }
        let start = self.offset(rest);
        let c = rest.chars().next().unwrap_or(' ');
        let starts_operand = is_ident_start(c) || c.is_ascii_digit() || c == '(' || c == '[';
        let hint = match notation_hint(rest) {
            Some(hint) => hint,
            // `2 dot(r, r) = l^2`: a relation follows, so what is missing is a `*`.
            None if starts_operand && (after != After::Lhs || rest.contains(['=', '<', '>'])) => {
                "; a product needs `*`: write `2*dot(r, r)`, not `2 dot(r, r)`"
            }
            None if starts_operand => {
                "; a constraint is a relation: `lhs = rhs`, `lhs <= rhs` or `lhs >= rhs` (and a product needs `*`)"
            }
            None => "",
        };
        Err(ParseError {
            span: Span::new(start, start + c.len_utf8()),
            message: format!("unexpected `{c}` after the end of the expression{hint}"),
        })
    }

    fn nested(&self, i: &'s str, depth: u32) -> Res<'s, ()> {
        if depth >= MAX_NESTING {
            return cut(i, format!("expression nested too deeply (more than {MAX_NESTING} levels)"));
        }
        Ok((i, ()))
    }

    /// `term (± term)*`
    fn expr(&self, i: &'s str, depth: u32) -> Res<'s, Syntax<'s>> {
        // Nesting recurses through here; grow the stack on the heap when it runs low, so
        // the nesting limit, not the thread's stack size, is what bounds the depth.
        stacker::maybe_grow(STACK_RED_ZONE, STACK_GROWTH, || self.expr_inner(i, depth))
    }

    fn expr_inner(&self, i: &'s str, depth: u32) -> Res<'s, Syntax<'s>> {
        let (i, _) = ws(i)?;
        let start = i;
        let (mut i, first) = self.term(i, depth)?;
        // Most sums are a single term: the list is allocated at the first operator.
        let mut first = Some(first);
        let mut terms = Vec::new();
        loop {
            let (j, _) = ws(i)?;
            let sign = match j.chars().next() {
                Some('+') => Sign::Plus,
                Some('-') => Sign::Minus,
                _ => break,
            };
            let (j, _) = ws(&j[1..])?;
            let (j, t) = self.term(j, depth).or_else(|e| self.expected_operand(e, j))?;
            if let Some(first) = first.take() {
                terms.push((Sign::Plus, first));
            }
            terms.push((sign, t));
            i = j;
        }
        if let Some(first) = first {
            return Ok((i, first));
        }
        Ok((i, Syntax { kind: SyntaxKind::Sum(terms), span: self.span(start, i) }))
    }

    /// After an operator, a missing operand is a hard error with a clear message.
    fn expected_operand<T>(&self, e: Err<PErr<'s>>, at: &'s str) -> Res<'s, T> {
        match e {
            Err::Error(inner) if inner.at.len() >= at.len() => cut(at, "expected an expression after the operator"),
            Err::Error(inner) => Err(Err::Failure(inner)),
            other => Err(other),
        }
    }

    /// `unary (*/ unary)*`
    fn term(&self, i: &'s str, depth: u32) -> Res<'s, Syntax<'s>> {
        let start = i;
        let (mut i, first) = self.unary(i, depth)?;
        let mut first = Some(first);
        let mut factors = Vec::new();
        loop {
            let (j, _) = ws(i)?;
            let op = match j.chars().next() {
                Some('*') if j[1..].starts_with('*') => {
                    return cut(&j[1..], "`**` is not an operator: write powers with `^`, e.g. `l^2`");
                }
                Some('*') => MulOp::Times,
                Some('/') => MulOp::Over,
                _ => break,
            };
            let (j, _) = ws(&j[1..])?;
            let (j, f) = self.unary(j, depth).or_else(|e| self.expected_operand(e, j))?;
            if let Some(first) = first.take() {
                factors.push((MulOp::Times, first));
            }
            factors.push((op, f));
            i = j;
        }
        if let Some(first) = first {
            return Ok((i, first));
        }
        Ok((i, Syntax { kind: SyntaxKind::Product(factors), span: self.span(start, i) }))
    }

    /// `- unary | power`
    fn unary(&self, i: &'s str, depth: u32) -> Res<'s, Syntax<'s>> {
        if let Some(rest) = i.strip_prefix('-') {
            self.nested(i, depth)?;
            let (j, _) = ws(rest)?;
            let (j, e) = stacker::maybe_grow(STACK_RED_ZONE, STACK_GROWTH, || self.unary(j, depth + 1))
                .or_else(|e| self.expected_operand(e, j))?;
            return Ok((j, Syntax { kind: SyntaxKind::Neg(Box::new(e)), span: self.span(i, j) }));
        }
        self.power(i, depth)
    }

    /// `postfix (^ unary)?`
    fn power(&self, i: &'s str, depth: u32) -> Res<'s, Syntax<'s>> {
        let (i2, base) = self.postfix(i, depth)?;
        let (j, _) = ws(i2)?;
        if let Some(rest) = j.strip_prefix('^') {
            self.nested(j, depth)?;
            let (rest, _) = ws(rest)?;
            let (k, exponent) = stacker::maybe_grow(STACK_RED_ZONE, STACK_GROWTH, || self.unary(rest, depth + 1))
                .or_else(|e| self.expected_operand(e, rest))?;
            let span = self.span(i, k);
            return Ok((k, Syntax { kind: SyntaxKind::Pow(Box::new(base), Box::new(exponent)), span }));
        }
        Ok((i2, base))
    }

    /// `atom (.x | .y | .z)*`
    fn postfix(&self, i: &'s str, depth: u32) -> Res<'s, Syntax<'s>> {
        let start = i;
        let (mut i, mut e) = self.atom(i, depth)?;
        while let Some(rest) = i.strip_prefix('.') {
            let (after, name) = ident(rest).or_else(|_| cut(rest, "expected a component `x`, `y` or `z` after `.`"))?;
            let axis = match name {
                "x" => Axis::X,
                "y" => Axis::Y,
                "z" => Axis::Z,
                _ => return cut(rest, format!("unknown component `{name}`: expected `x`, `y` or `z`")),
            };
            let axis_span = self.span(rest, after);
            e = Syntax { kind: SyntaxKind::Component(Box::new(e), axis, axis_span), span: self.span(start, after) };
            i = after;
        }
        Ok((i, e))
    }

    fn atom(&self, i: &'s str, depth: u32) -> Res<'s, Syntax<'s>> {
        match i.chars().next() {
            Some('(') => {
                self.nested(i, depth)?;
                let (j, inner) = self.expr(&i[1..], depth + 1)?;
                let (j, _) = ws(j)?;
                let Some(j) = j.strip_prefix(')') else {
                    return cut(j, "expected `)` to close the parenthesis");
                };
                Ok((j, Syntax { kind: SyntaxKind::Paren(Box::new(inner)), span: self.span(i, j) }))
            }
            Some('[') => {
                self.nested(i, depth)?;
                let (j, items) = self.list(&i[1..], depth + 1, ']')?;
                Ok((j, Syntax { kind: SyntaxKind::Vector(items), span: self.span(i, j) }))
            }
            Some(c) if is_ident_start(c) => {
                let (j, name) = ident(i)?;
                let name_span = self.span(i, j);
                let (k, _) = ws(j)?;
                if let Some(after_paren) = k.strip_prefix('(') {
                    self.nested(i, depth)?;
                    let (k, args) = self.list(after_paren, depth + 1, ')')?;
                    let kind = SyntaxKind::Call { name, name_span, args };
                    return Ok((k, Syntax { kind, span: self.span(i, k) }));
                }
                Ok((j, Syntax { kind: SyntaxKind::Ident(name), span: name_span }))
            }
            Some(c) if c.is_ascii_digit() || c == '.' => {
                let (j, text) = number(i)?;
                Ok((j, Syntax { kind: SyntaxKind::Number(text), span: self.span(i, j) }))
            }
            Some(c) => fail(i, format!("expected an expression, found `{c}`{}", notation_hint(i).unwrap_or(""))),
            None => fail(i, "expected an expression, found the end of the text"),
        }
    }

    /// `e (, e)* close`, at least one entry.
    fn list(&self, i: &'s str, depth: u32, close: char) -> Res<'s, Vec<Syntax<'s>>> {
        let mut items = Vec::new();
        let (mut i, _) = ws(i)?;
        if let Some(rest) = i.strip_prefix(close) {
            return Ok((rest, items));
        }
        loop {
            let (j, e) = self.expr(i, depth).or_else(|e| self.expected_operand(e, i))?;
            items.push(e);
            let (j, _) = ws(j)?;
            if let Some(rest) = j.strip_prefix(',') {
                i = rest;
            } else if let Some(rest) = j.strip_prefix(close) {
                return Ok((rest, items));
            } else {
                return cut(j, format!("expected `,` or `{close}`"));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape(e: &Syntax) -> String {
        match &e.kind {
            SyntaxKind::Number(n) => n.to_string(),
            SyntaxKind::Ident(n) => n.to_string(),
            SyntaxKind::Sum(ts) => {
                let parts: Vec<String> = ts
                    .iter()
                    .map(|(s, t)| format!("{}{}", if *s == Sign::Minus { "-" } else { "+" }, shape(t)))
                    .collect();
                format!("sum({})", parts.join(" "))
            }
            SyntaxKind::Product(fs) => {
                let parts: Vec<String> = fs
                    .iter()
                    .map(|(o, f)| format!("{}{}", if *o == MulOp::Over { "/" } else { "*" }, shape(f)))
                    .collect();
                format!("prod({})", parts.join(" "))
            }
            SyntaxKind::Neg(x) => format!("neg({})", shape(x)),
            SyntaxKind::Pow(a, b) => format!("pow({}, {})", shape(a), shape(b)),
            SyntaxKind::Call { name, args, .. } => {
                format!("{name}({})", args.iter().map(shape).collect::<Vec<_>>().join(", "))
            }
            SyntaxKind::Component(x, a, _) => format!("{}.{}", shape(x), a.name()),
            SyntaxKind::Vector(xs) => format!("[{}]", xs.iter().map(shape).collect::<Vec<_>>().join(", ")),
            SyntaxKind::Paren(x) => format!("({})", shape(x)),
        }
    }

    fn check(text: &str, expected: &str) {
        let e = parse_expr(text).unwrap_or_else(|err| panic!("{text}: {err}"));
        assert_eq!(shape(&e), expected, "{text}");
    }

    #[test]
    fn precedence() {
        check("a + b * c", "sum(+a +prod(*b *c))");
        check("-x^2", "neg(pow(x, 2))");
        check("x^-1", "pow(x, neg(1))");
        check("a^b^c", "pow(a, pow(b, c))");
        check("a - b - c", "sum(+a -b -c)");
        check("a / b * c", "prod(*a /b *c)");
        check("r.x * 2", "prod(*r.x *2)");
        check("dot(r, r) - l^2", "sum(+dot(r, r) -pow(l, 2))");
        check("[1.5e-3, .5]", "[1.5e-3, .5]");
        check("(a + b).y", "(sum(+a +b)).y");
        check("nan + inf", "sum(+nan +inf)");
    }

    #[test]
    fn relations() {
        let r = parse_relation("dot(r,r) <= l^2").unwrap();
        assert_eq!(r.rel.as_ref().map(|(op, _, _)| *op), Some(RelOp::Le));
        assert!(parse_relation("r.y").unwrap().rel.is_none());
    }

    #[test]
    fn errors_have_spans() {
        let e = parse_expr("a + ").unwrap_err();
        assert_eq!(e.message, "expected an expression after the operator");
        assert_eq!(e.span.start, 4);
        let e = parse_expr("(a + b").unwrap_err();
        assert_eq!(e.message, "expected `)` to close the parenthesis");
        let e = parse_expr("a b").unwrap_err();
        assert_eq!(e.span, Span::new(2, 3));
        let e = parse_expr("r.w").unwrap_err();
        assert!(e.message.contains("unknown component"));
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_crash() {
        let text = format!("{}x{}", "(".repeat(100_000), ")".repeat(100_000));
        let e = parse_expr(&text).unwrap_err();
        assert!(e.message.contains("nested too deeply"), "{}", e.message);
        let e = parse_expr(&format!("{}x", "-".repeat(100_000))).unwrap_err();
        assert!(e.message.contains("nested too deeply"));
        let e = parse_expr(&"x^".repeat(100_000)).unwrap_err();
        assert!(e.message.contains("nested too deeply"));
    }

    #[test]
    fn long_flat_sums_parse_without_recursion() {
        let text = "x + ".repeat(50_000) + "x";
        match parse_expr(&text).unwrap().kind {
            SyntaxKind::Sum(ts) => assert_eq!(ts.len(), 50_001),
            other => panic!("{other:?}"),
        }
        let huge = "x+".repeat(6 << 20);
        assert!(parse_expr(&huge).unwrap_err().message.contains("too long"));
    }
}
