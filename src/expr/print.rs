//! Printers: the expression language (parses back to the same graph), Unicode text, LaTeX.
//!
//! `Style::Source` is exact: for every graph the lowering or the simplifier builds,
//! `lower(parse(print(e)))` is `e` itself (a property test checks it), so formulas in JSON
//! can be read back by lagrange or any evaluator. `Style::Text` and `Style::Latex` are for
//! people: `−(m v·v + F·r)/(r·r) r`, `\frac{…}{…}`, `\vec{r}`.
//!
//! Text and LaTeX can print given nodes as names ([`print_named`]): a document prints a
//! file's definition `d = r2 − r1` as `d` wherever that node occurs.
//!
//! Printing expands the graph into a tree, so a graph with heavy sharing could print to an
//! enormous string; [`MAX_OUTPUT`] bounds that and [`MAX_PRINT_DEPTH`] bounds recursion.
//!
//! Not here: documents (derivation layouts live in `report`), numbers' evaluation.

use super::func::Notation;
use super::graph::{FastMap, FastSet, Graph, Id, Node, Ty};
use super::num::Rational;
use super::parse::{STACK_GROWTH, STACK_RED_ZONE};
use super::present::is_negation;
use std::borrow::Cow;

/// Which notation to print in.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Style {
    /// The expression language of constraint files.
    Source,
    /// Unicode for terminals: `·`, `×`, `²`, `−`.
    Text,
    /// LaTeX math.
    Latex,
}

/// The longest printed expression, in bytes.
pub const MAX_OUTPUT: usize = 16 << 20;
/// The deepest expression printed.
pub const MAX_PRINT_DEPTH: u32 = 4000;

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PrintError {
    #[error("expression too deep to print ({0} levels)")]
    TooDeep(u32),
    #[error("expression too large to print (more than {MAX_OUTPUT} bytes)")]
    TooLarge,
}

/// Nodes to print as a name in text and LaTeX (a definition's name for its expression).
pub type Names = FastMap<Id, String>;

/// Prints `id` in `style`.
pub fn print(g: &Graph, id: Id, style: Style) -> Result<String, PrintError> {
    print_named(g, id, style, &Names::default(), &mut FastSet::default())
}

/// Prints `id` in `style`, each node of `names` as its name in text and LaTeX (as a symbol
/// of the node's type: `d`, `\vec{d}`), adding the nodes it printed so to `used`; the
/// expression language ignores `names`, so what it prints still stands alone and parses back.
pub fn print_named(
    g: &Graph,
    id: Id,
    style: Style,
    names: &Names,
    used: &mut FastSet<Id>,
) -> Result<String, PrintError> {
    if g.depth(id) > MAX_PRINT_DEPTH {
        return Err(PrintError::TooDeep(g.depth(id)));
    }
    let names = Some(names).filter(|n| !n.is_empty() && style != Style::Source);
    let mut p = Printer { g, out: String::new(), names, used };
    match style {
        Style::Source => p.source(id)?,
        Style::Text | Style::Latex => p.human(id, style, 0)?,
    }
    Ok(p.out)
}

/// A symbol's name as `style` writes it: `θ2`, `\\vec{d}`, `lambda_rod1`.
pub fn symbol_name(name: &str, vector: bool, style: Style) -> String {
    match style {
        Style::Source => name.to_string(),
        Style::Text => text_name(name).into_owned(),
        Style::Latex => latex_name(name, vector),
    }
}

struct Printer<'g> {
    g: &'g Graph,
    out: String,
    names: Option<&'g Names>,
    used: &'g mut FastSet<Id>,
}

const MINUS: &str = "−";

fn is_fraction_or_negative(q: &Rational) -> bool {
    q.is_negative() || !q.is_integer()
}

impl<'g> Printer<'g> {
    fn push(&mut self, s: &str) -> Result<(), PrintError> {
        if self.out.len() + s.len() > MAX_OUTPUT {
            return Err(PrintError::TooLarge);
        }
        self.out.push_str(s);
        Ok(())
    }

    fn node(&self, id: Id) -> &Node {
        self.g.node(id)
    }

    /// The name `id` prints as, if it is one of the printer's names.
    fn name_of(&self, id: Id) -> Option<&'g str> {
        self.names.and_then(|n| n.get(&id)).map(String::as_str)
    }

    // ---- the expression language -------------------------------------------------------

    fn source(&mut self, id: Id) -> Result<(), PrintError> {
        stacker::maybe_grow(STACK_RED_ZONE, STACK_GROWTH, || self.source_inner(id))
    }

    fn source_inner(&mut self, id: Id) -> Result<(), PrintError> {
        match self.node(id).clone() {
            Node::Num(q) => self.push(&q.to_string()),
            Node::Sym(s) => {
                let name = self.g.symbol(s).name.clone();
                self.push(&name)
            }
            Node::Vector(xs) => self.call_source("", &xs, "[", "]"),
            Node::Add(xs) => {
                self.source_wrapped(xs[0], matches!(self.node(xs[0]), Node::Add(_)))?;
                for &x in &xs[1..] {
                    self.source_term(x)?;
                }
                Ok(())
            }
            Node::Mul(xs) if is_negation(self.g, id) => {
                self.push("-")?;
                self.source_unary_operand(xs[1])
            }
            Node::Mul(xs) => self.source_product(&xs, 0),
            Node::Pow([b, e]) => {
                let plain_base = match self.node(b) {
                    Node::Num(q) => !is_fraction_or_negative(q),
                    Node::Add(_) | Node::Mul(_) | Node::Pow(_) => false,
                    _ => true,
                };
                self.source_wrapped(b, !plain_base)?;
                self.push("^")?;
                let plain_exponent = match self.node(e) {
                    Node::Num(q) => q.is_integer(),
                    Node::Add(_) => false,
                    Node::Mul(_) => is_negation(self.g, e),
                    _ => true,
                };
                self.source_wrapped(e, !plain_exponent)
            }
            Node::Dot([a, b]) => self.call_source("dot", &[a, b], "(", ")"),
            Node::Cross([a, b]) => self.call_source("cross", &[a, b], "(", ")"),
            Node::Norm(a) => self.call_source("norm", &[a], "(", ")"),
            Node::Call(f, args) => self.call_source(f.name(), &args[..f.arity()], "(", ")"),
            Node::Rot([a, b]) => self.call_source("rot", &[a, b], "(", ")"),
            Node::Perp(a) => self.call_source("perp", &[a], "(", ")"),
            Node::Comp(a, axis) => {
                let plain = matches!(
                    self.node(a),
                    Node::Sym(_) | Node::Vector(_) | Node::Call(..) | Node::Rot(_) | Node::Perp(_)
                );
                self.source_wrapped(a, !plain)?;
                self.push(".")?;
                self.push(axis.name())
            }
        }
    }

    fn source_wrapped(&mut self, id: Id, wrap: bool) -> Result<(), PrintError> {
        if wrap {
            self.push("(")?;
        }
        self.source(id)?;
        if wrap {
            self.push(")")?;
        }
        Ok(())
    }

    fn call_source(&mut self, name: &str, args: &[Id], open: &str, close: &str) -> Result<(), PrintError> {
        self.push(name)?;
        self.push(open)?;
        for (i, &a) in args.iter().enumerate() {
            if i > 0 {
                self.push(", ")?;
            }
            self.source(a)?;
        }
        self.push(close)
    }

    /// The operand of a unary minus: numbers, products and sums in parentheses.
    fn source_unary_operand(&mut self, y: Id) -> Result<(), PrintError> {
        let wrap = matches!(self.node(y), Node::Num(_) | Node::Mul(_) | Node::Add(_));
        self.source_wrapped(y, wrap)
    }

    /// A term after the first of a sum, with its sign: the lowering reads `a - 2*x` as
    /// `a + (-2)·x` and `a - m*x` as `a + (−m)·x`, so those print with `-`.
    fn source_term(&mut self, x: Id) -> Result<(), PrintError> {
        match self.node(x).clone() {
            Node::Num(q) if q.is_negative() => {
                self.push(" - ")?;
                self.push(&q.neg().to_string())
            }
            Node::Mul(fs) if is_negation(self.g, x) => {
                self.push(" - ")?;
                let y = fs[1];
                let wrap = matches!(self.node(y), Node::Num(_) | Node::Mul(_) | Node::Add(_));
                self.source_wrapped(y, wrap)
            }
            Node::Mul(fs) => match self.node(fs[0]).clone() {
                Node::Num(q) if q.is_negative() && !self.folds_with_next(&fs) => {
                    self.push(" - ")?;
                    self.push(&q.neg().to_string())?;
                    self.source_factors(&fs, 1)
                }
                Node::Mul(inner) if is_negation(self.g, fs[0]) && !matches!(self.node(inner[1]), Node::Num(_)) => {
                    self.push(" - ")?;
                    self.source_first_factor(inner[1], &fs)?;
                    self.source_factors(&fs, 1)
                }
                _ => {
                    self.push(" + ")?;
                    self.source(x)
                }
            },
            Node::Add(_) => {
                self.push(" + ")?;
                self.source_wrapped(x, true)
            }
            _ => {
                self.push(" + ")?;
                self.source(x)
            }
        }
    }

    /// Whether `fs[0]` (a number) followed by `/fs[1]` (a number) would be read as one rational.
    fn folds_with_next(&self, fs: &[Id]) -> bool {
        matches!(self.node(fs[0]), Node::Num(_))
            && fs.get(1).is_some_and(|&f| match self.node(f) {
                Node::Pow([b, e]) => {
                    matches!(self.node(*b), Node::Num(_)) && self.g.as_num(*e).is_some_and(|q| *q == Rational::int(-1))
                }
                _ => false,
            })
    }

    fn source_product(&mut self, fs: &[Id], _: usize) -> Result<(), PrintError> {
        let first = fs[0];
        match self.node(first).clone() {
            Node::Num(q) if !self.folds_with_next(fs) => self.push(&q.to_string())?,
            Node::Num(_) => self.source_wrapped(first, true)?,
            Node::Mul(inner) if is_negation(self.g, first) => {
                self.push("-")?;
                self.source_unary_operand(inner[1])?;
            }
            _ => self.source_first_factor(first, fs)?,
        }
        self.source_factors(fs, 1)
    }

    /// A product's first factor, not a number or a negation.
    fn source_first_factor(&mut self, f: Id, _fs: &[Id]) -> Result<(), PrintError> {
        let wrap = matches!(self.node(f), Node::Add(_) | Node::Mul(_));
        self.source_wrapped(f, wrap)
    }

    /// Factors `fs[from..]`, each as `*f` or `/d` for `d^-1`.
    fn source_factors(&mut self, fs: &[Id], from: usize) -> Result<(), PrintError> {
        for &f in &fs[from..] {
            if let Node::Pow([b, e]) = *self.node(f)
                && self.g.as_num(e).is_some_and(|q| *q == Rational::int(-1))
            {
                self.push("/")?;
                let wrap = match self.node(b) {
                    Node::Num(q) => is_fraction_or_negative(q),
                    Node::Add(_) | Node::Mul(_) => true,
                    _ => false,
                };
                self.source_wrapped(b, wrap)?;
                continue;
            }
            self.push("*")?;
            let wrap = match self.node(f) {
                Node::Num(q) => is_fraction_or_negative(q),
                Node::Add(_) | Node::Mul(_) => true,
                _ => false,
            };
            self.source_wrapped(f, wrap)?;
        }
        Ok(())
    }

    // ---- text and LaTeX ------------------------------------------------------------------

    /// Prints at a context of precedence `ctx` (0 top, 1 sum, 2 product, 3 unary, 4 power).
    fn human(&mut self, id: Id, style: Style, ctx: u8) -> Result<(), PrintError> {
        stacker::maybe_grow(STACK_RED_ZONE, STACK_GROWTH, || self.human_at(id, style, ctx))
    }

    fn human_at(&mut self, id: Id, style: Style, ctx: u8) -> Result<(), PrintError> {
        if let Some(name) = self.name_of(id) {
            self.used.insert(id);
            let vector = self.g.ty(id) == Ty::Vector;
            let name = if style == Style::Latex { Cow::Owned(latex_name(name, vector)) } else { text_name(name) };
            return self.push(&name);
        }
        let prec = self.human_prec(id);
        let wrap = prec < ctx;
        if wrap {
            self.push(if style == Style::Latex { "\\left(" } else { "(" })?;
        }
        self.human_inner(id, style)?;
        if wrap {
            self.push(if style == Style::Latex { "\\right)" } else { ")" })?;
        }
        Ok(())
    }

    fn human_prec(&self, id: Id) -> u8 {
        if self.name_of(id).is_some() {
            return 5;
        }
        match self.node(id) {
            Node::Add(_) => 1,
            Node::Mul(_) if is_negation(self.g, id) => 3,
            Node::Mul(_) => 2,
            Node::Dot(_) | Node::Cross(_) => 2,
            Node::Num(q) if q.is_negative() => 3,
            Node::Num(q) if !q.is_integer() => 2,
            Node::Pow(_) => 4,
            _ => 5,
        }
    }

    fn human_inner(&mut self, id: Id, style: Style) -> Result<(), PrintError> {
        let latex = style == Style::Latex;
        // The graph outlives the printer: its nodes are read in place, not cloned.
        let g = self.g;
        match g.node(id) {
            Node::Num(q) => {
                // Small values (nearly all) without big integers.
                let (n, d) = match q.as_small() {
                    Some((n, d)) => (n.unsigned_abs().to_string(), d.to_string()),
                    None => {
                        let (n, d) = q.parts();
                        (n.magnitude().to_string(), d.to_string())
                    }
                };
                let sign = if q.is_negative() { if latex { "-" } else { MINUS } } else { "" };
                if q.is_integer() {
                    self.push(&format!("{sign}{n}"))
                } else if latex {
                    self.push(&format!("{sign}\\frac{{{n}}}{{{d}}}"))
                } else {
                    self.push(&format!("{sign}{n}/{d}"))
                }
            }
            &Node::Sym(s) => {
                let info = self.g.symbol(s);
                let name = if latex {
                    Cow::Owned(latex_name(&info.name, info.ty == Ty::Vector))
                } else {
                    text_name(&info.name)
                };
                self.push(&name)
            }
            Node::Vector(xs) => {
                self.push(if latex { "\\begin{bmatrix}" } else { "[" })?;
                for (i, &x) in xs.iter().enumerate() {
                    if i > 0 {
                        self.push(if latex { " \\\\ " } else { ", " })?;
                    }
                    self.human(x, style, 0)?;
                }
                self.push(if latex { "\\end{bmatrix}" } else { "]" })
            }
            Node::Add(xs) => {
                for (i, &x) in xs.iter().enumerate() {
                    let start = self.out.len();
                    self.human(x, style, 1)?;
                    if i == 0 {
                        continue;
                    }
                    // Turn `+ −x` into `− x`, in place.
                    let minus = if latex { "-" } else { MINUS };
                    let joint = if self.out[start..].starts_with(minus) {
                        self.out.replace_range(start..start + minus.len(), "");
                        if latex { " - " } else { " − " }
                    } else {
                        " + "
                    };
                    if self.out.len() + joint.len() > MAX_OUTPUT {
                        return Err(PrintError::TooLarge);
                    }
                    self.out.insert_str(start, joint);
                }
                Ok(())
            }
            Node::Mul(xs) if is_negation(self.g, id) => {
                self.push(if latex { "-" } else { MINUS })?;
                // −r·v is −(r·v) whichever way it is read.
                let ctx = if matches!(self.node(xs[1]), Node::Dot(_) | Node::Cross(_)) { 2 } else { 3 };
                self.human(xs[1], style, ctx)
            }
            Node::Mul(xs) => self.human_product(xs, style),
            &Node::Pow([b, e]) => {
                self.human(b, style, 5)?;
                match self.g.as_num(e).and_then(Rational::to_i64) {
                    Some(n) if !latex => self.push(&superscript(n)),
                    _ if latex => {
                        self.push("^{")?;
                        self.human(e, style, 0)?;
                        self.push("}")
                    }
                    _ => {
                        self.push("^")?;
                        self.human(e, style, 5)
                    }
                }
            }
            &Node::Dot([a, b]) => {
                self.human(a, style, 3)?;
                self.push(if latex { " \\cdot " } else { "·" })?;
                self.human(b, style, 3)
            }
            &Node::Cross([a, b]) => {
                self.human(a, style, 3)?;
                self.push(if latex { " \\times " } else { "×" })?;
                self.human(b, style, 3)
            }
            &Node::Norm(a) => {
                self.push(if latex { "\\left\\lVert " } else { "|" })?;
                // |−u| is |u|: a named difference prints as its name, not its negation.
                let a = match self.node(a) {
                    Node::Mul(xs) if is_negation(self.g, a) => xs[1],
                    _ => a,
                };
                self.human(a, style, 0)?;
                self.push(if latex { " \\right\\rVert" } else { "|" })
            }
            &Node::Comp(a, axis) => {
                self.human(a, style, 5)?;
                if latex {
                    self.push(&format!("_{{{}}}", axis.name()))
                } else {
                    self.push(&format!(".{}", axis.name()))
                }
            }
            &Node::Rot([theta, v]) => {
                self.push(if latex { "\\operatorname{rot}\\left(" } else { "rot(" })?;
                self.human(theta, style, 0)?;
                self.push(", ")?;
                self.human(v, style, 0)?;
                self.push(if latex { "\\right)" } else { ")" })
            }
            &Node::Perp(a) => {
                self.push(if latex { "\\operatorname{perp}\\left(" } else { "perp(" })?;
                self.human(a, style, 0)?;
                self.push(if latex { "\\right)" } else { ")" })
            }
            Node::Call(f, args) => match f.notation() {
                Notation::Radical if latex => {
                    self.push("\\sqrt{")?;
                    self.human(args[0], style, 0)?;
                    self.push("}")
                }
                Notation::Radical => {
                    self.push("√")?;
                    self.human(args[0], style, 5)
                }
                Notation::Call { latex: command } => {
                    self.push(if latex { command } else { f.name() })?;
                    self.push(if latex { "\\left(" } else { "(" })?;
                    for (k, &a) in args[..f.arity()].iter().enumerate() {
                        if k > 0 {
                            self.push(", ")?;
                        }
                        self.human(a, style, 0)?;
                    }
                    self.push(if latex { "\\right)" } else { ")" })
                }
            },
        }
    }

    /// A product as `sign numerator / denominator vector`.
    fn human_product(&mut self, xs: &[Id], style: Style) -> Result<(), PrintError> {
        let latex = style == Style::Latex;
        let mut numerator: Vec<Id> = Vec::new();
        let mut denominator: Vec<(Id, i64)> = Vec::new();
        let mut coefficient = Rational::ONE;
        let mut vector = None;
        let mut negative = false;
        for (i, &x) in xs.iter().enumerate() {
            match self.node(x) {
                // A name is one factor, whatever it stands for.
                _ if self.name_of(x).is_some() => {
                    if i == xs.len() - 1 && self.g.ty(x) == Ty::Vector {
                        vector = Some(x);
                    } else {
                        numerator.push(x);
                    }
                }
                Node::Num(q) => coefficient = coefficient.mul(q),
                Node::Pow([b, e]) if self.g.as_num(*e).is_some_and(|q| q.is_negative() && q.is_integer()) => {
                    let n = self.g.as_num(*e).and_then(Rational::to_i64).unwrap_or(-1);
                    denominator.push((*b, -n));
                }
                // A negated factor anywhere: the sign goes in front.
                Node::Mul(inner) if is_negation(self.g, x) => {
                    negative = !negative;
                    let y = inner[1];
                    // `−|d|⁻¹ d` reads `−d/|d|`.
                    if self.name_of(y).is_none()
                        && let Node::Pow([b, e]) = self.node(y)
                        && let Some(n) = self.g.as_num(*e).filter(|q| q.is_negative() && q.is_integer())
                    {
                        denominator.push((*b, -n.to_i64().unwrap_or(-1)));
                    } else if i == xs.len() - 1 && self.g.ty(y) == Ty::Vector {
                        vector = Some(y);
                    } else {
                        numerator.push(y);
                    }
                }
                _ if i == xs.len() - 1 && self.g.ty(x) == Ty::Vector => vector = Some(x),
                _ => numerator.push(x),
            }
        }
        if coefficient.is_negative() {
            negative = !negative;
            coefficient = coefficient.neg();
        }
        let (p, q) = coefficient.parts();
        let (p, q) = (Rational::from_parts(p, 1.into()), Rational::from_parts(q, 1.into()));
        if negative {
            self.push(if latex { "-" } else { MINUS })?;
        }
        let has_den = !denominator.is_empty() || !q.is_one();
        let mut pieces = 0;
        // `(F + F_c)/m` rather than `1/m (F + F_c)`; in LaTeX `\frac{\vec F + …}{m}`.
        if let Some(v) = vector.filter(|_| has_den && numerator.is_empty() && p.is_one()) {
            if latex {
                numerator.push(v);
            } else {
                self.juxtaposed(v, style, 3, negative)?;
                pieces += 1;
            }
            vector = None;
        }
        if has_den && latex {
            self.push("\\frac{")?;
        }
        // Numerator: the integer coefficient and the factors.
        if !p.is_one() || (numerator.is_empty() && pieces == 0 && (has_den || vector.is_none())) {
            self.push(&p.to_string())?;
            pieces += 1;
        }
        let single = numerator.len() == 1 && pieces == 0;
        for (i, &f) in numerator.iter().enumerate() {
            if pieces > 0 {
                self.push(if latex { " \\, " } else { " " })?;
            }
            let last = i + 1 == numerator.len() && vector.is_none();
            let ctx = match (latex && has_den, single) {
                // Inside \frac{…} the braces group a lone numerator.
                (true, true) => 0,
                // A lone numerator: `(a + b)/c`, `−(a + b)`, `2 r·v`.
                (_, true) if has_den || negative => 3,
                (_, true) => 2,
                // A dot product reads unambiguously as the last factor: `m v·v`.
                _ if last && !has_den => 2,
                _ => 3,
            };
            self.juxtaposed(f, style, ctx, pieces > 0 || negative)?;
            pieces += 1;
        }
        if has_den {
            if latex {
                self.push("}{")?;
            } else {
                self.push("/")?;
            }
            let mut parts = 0;
            let many = denominator.len() + usize::from(!q.is_one()) > 1;
            if many && !latex {
                self.push("(")?;
            }
            if !q.is_one() {
                self.push(&q.to_string())?;
                parts += 1;
            }
            for (b, n) in &denominator {
                if parts > 0 {
                    self.push(if latex { " \\, " } else { " " })?;
                }
                let ctx = if latex && !many {
                    0
                } else if latex || many {
                    3
                } else {
                    5
                };
                self.juxtaposed(*b, style, if *n == 1 { ctx } else { 5 }, parts > 0)?;
                if *n != 1 {
                    if latex { self.push(&format!("^{{{n}}}"))? } else { self.push(&superscript(*n))? }
                }
                parts += 1;
            }
            if many && !latex {
                self.push(")")?;
            }
            if latex {
                self.push("}")?;
            }
        }
        if let Some(v) = vector {
            if pieces > 0 || has_den {
                self.push(if latex { " \\, " } else { " " })?;
            }
            self.juxtaposed(v, style, 3, pieces > 0 || has_den || negative)?;
        }
        Ok(())
    }

    /// A factor of a product printed after another piece (`after`): one whose text would
    /// begin with a minus is put in parentheses, so `r.y (−sin(w t) w)` never reads as
    /// `r.y − sin(w t) w` and `−(−x)` never as `−−x`.
    fn juxtaposed(&mut self, f: Id, style: Style, ctx: u8, after: bool) -> Result<(), PrintError> {
        let start = self.out.len();
        self.human(f, style, ctx)?;
        let minus = if style == Style::Latex { "-" } else { MINUS };
        if after && self.out[start..].starts_with(minus) {
            let (open, close) = if style == Style::Latex { ("\\left(", "\\right)") } else { ("(", ")") };
            if self.out.len() + open.len() + close.len() > MAX_OUTPUT {
                return Err(PrintError::TooLarge);
            }
            self.out.insert_str(start, open);
            self.out.push_str(close);
        }
        Ok(())
    }
}

/// A rational written as an operand of `/` or `·` in a label (`∇C/κ`, `over κ`): a
/// fraction or a negative number in parentheses, so `∇C/(2/3)` never reads as `∇C/6`.
pub fn rational_operand(q: &Rational) -> String {
    if is_fraction_or_negative(q) { format!("({q})") } else { q.to_string() }
}

fn superscript(n: i64) -> String {
    n.to_string()
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            '0' => '⁰',
            '1' => '¹',
            '2' => '²',
            '3' => '³',
            '4' => '⁴',
            '5' => '⁵',
            '6' => '⁶',
            '7' => '⁷',
            '8' => '⁸',
            _ => '⁹',
        })
        .collect()
}

const GREEK: [&str; 24] = [
    "alpha", "beta", "gamma", "delta", "epsilon", "zeta", "eta", "theta", "iota", "kappa", "lambda", "mu", "nu", "xi",
    "omicron", "pi", "rho", "sigma", "tau", "upsilon", "phi", "chi", "psi", "omega",
];
const GREEK_TEXT: [&str; 24] = [
    "α", "β", "γ", "δ", "ε", "ζ", "η", "θ", "ι", "κ", "λ", "μ", "ν", "ξ", "ο", "π", "ρ", "σ", "τ", "υ", "φ", "χ", "ψ",
    "ω",
];

/// `name` split as letters and a trailing digit run: `theta12` → (`theta`, `12`).
fn split_index(name: &str) -> (&str, &str) {
    let cut = name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    if cut == 0 { (name, "") } else { name.split_at(cut) }
}

/// A name as text writes it; borrowed when it has no Greek letter to spell (most names:
/// the documents print a symbol at every occurrence).
fn text_name(name: &str) -> Cow<'_, str> {
    // `lambda_rod1` → `λ_rod1`, `theta2` → `θ2`.
    if let Some((head, tail)) = name.split_once('_')
        && let Some(i) = GREEK.iter().position(|g| *g == head)
    {
        return Cow::Owned(format!("{}_{tail}", GREEK_TEXT[i]));
    }
    let (stem, index) = split_index(name);
    match GREEK.iter().position(|g| *g == stem) {
        Some(i) => Cow::Owned(format!("{}{index}", GREEK_TEXT[i])),
        None => Cow::Borrowed(name),
    }
}

fn latex_name(name: &str, vector: bool) -> String {
    // `lambda_rod1` → `\lambda_{\mathrm{rod1}}`, `F_c` → `F_{c}`.
    if let Some((head, tail)) = name.split_once('_')
        && !head.is_empty()
        && !tail.is_empty()
    {
        let base = latex_name(head, vector);
        let tail = if tail.chars().count() == 1 {
            tail.to_string()
        } else {
            format!("\\mathrm{{{}}}", tail.replace('_', "\\_"))
        };
        return format!("{base}_{{{tail}}}");
    }
    let (stem, index) = split_index(name);
    let base = if GREEK.contains(&stem) {
        format!("\\{stem}")
    } else if stem.chars().count() == 1 {
        stem.to_string()
    } else {
        format!("\\mathrm{{{}}}", stem.replace('_', "\\_"))
    };
    let base = if vector { format!("\\vec{{{base}}}") } else { base };
    if index.is_empty() { base } else { format!("{base}_{{{index}}}") }
}
