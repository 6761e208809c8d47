//! Layouts of a derivation for people and programs: text, LaTeX, Markdown, JSON.
//!
//! `derive` prints C, Ċ, C̈, ∇C per body, the λ equation (A, b), and λ and the force on each
//! body where a closed form exists; `--steps` walks through the derivation as the article
//! does, one step at a time, with the file's own expressions. Every function here returns
//! a `String` or a JSON value; the caller decides where it goes.
//!
//! With several constraints there is no closed form for λ: the entries of A and b are
//! printed one by one, named by constraints (`A[rod1, rod2]`), the force on each body as
//! Σₖ λₖ Jₖᵢ, and `--steps` adds each Jₖᵢ and cₖ and the system A λ = −b row by row. The
//! JSON then carries `multipliers` (constraint → symbol) and `force_sums` (body → Σ λ J).
//!
//! Everything shown is a node the derivation owns (its graph extends the system's: the force
//! sums, the multiplier symbols and the Newton step of `--steps` are built by `derive`), so
//! this module reads `&System` and `&Derivation` and builds no node.
//!
//! Not here: deriving (`derive`), expression printing rules (`expr::print`).

use crate::derive::Definition;
use crate::derive::Derivation;
use crate::expr::graph::FastSet;
use crate::expr::print::{Names, PrintError, Style, print, print_named, rational_operand, symbol_name};
use crate::expr::{Graph, Id, TypeError};
use crate::model::system::System;
use serde_json::{Value, json};
use std::cell::RefCell;
use std::fmt::Write;

/// The document formats of `derive`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Text,
    Latex,
    Markdown,
    Json,
}

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error(transparent)]
    Print(#[from] PrintError),
    #[error(transparent)]
    Type(#[from] TypeError),
    /// A document needs what the derivation was made without
    /// ([`derive_with`](crate::derive::derive_with) with `Options { document, steps }`).
    #[error("the derivation was made without {0} (derive_with and Options)")]
    NotDerived(&'static str),
    /// The document's formulas together passed [`document_budget`].
    #[error(
        "the document is too large to print: its formulas pass {0} bytes (16 MiB, and 4 KiB more \
         per body and per constraint; docs/file-format.md, \"Limits\"); `lagrange solve` and \
         `generate` need no document"
    )]
    DocumentTooLarge(usize),
}

/// The most bytes of formulas one document of `derive` prints: 16 MiB, and 4 KiB more per
/// body and per constraint, so a scene's document may grow linearly with it (a chain of
/// 10⁵ links prints about 1 KiB per link) but one formula repeated in every body's force
/// cannot make it quadratic.
pub fn document_budget(system: &System) -> usize {
    (16 << 20) + 4096 * (system.bodies.len() + system.constraints.len())
}

/// How expressions look in one document format.
struct Doc {
    style: Style,
    format: Format,
    /// The file's definitions, printed as their names (text, LaTeX and Markdown only).
    names: Names,
    /// The nodes of `names` printed so far.
    used: RefCell<FastSet<Id>>,
    /// Bytes of formulas this document may still print ([`document_budget`]).
    room: std::cell::Cell<usize>,
    budget: usize,
}

impl Doc {
    fn new(format: Format) -> Doc {
        let style = match format {
            Format::Text => Style::Text,
            Format::Latex | Format::Markdown => Style::Latex,
            Format::Json => Style::Source,
        };
        Doc {
            style,
            format,
            names: Names::default(),
            used: RefCell::default(),
            room: usize::MAX.into(),
            budget: usize::MAX,
        }
    }

    /// A document that prints each of `d`'s definitions as its name (none in JSON, whose
    /// expressions stand alone).
    fn naming(format: Format, d: &Derivation, budget: usize) -> Doc {
        let mut doc = Doc::new(format);
        doc.room.set(budget);
        doc.budget = budget;
        if format != Format::Json {
            for def in d.definitions.iter().flatten() {
                for id in [def.written, def.simplified] {
                    doc.names.entry(id).or_insert_with(|| def.name.clone());
                }
            }
            // One constraint's multiplier is the λ printed once above its forces (`λ r`).
            if let (Some(_), Some([only])) = (d.lambda, d.multipliers.as_deref()) {
                doc.names.insert(*only, "lambda".to_string());
            }
        }
        doc
    }

    fn expr(&self, g: &Graph, id: Id) -> Result<String, ReportError> {
        let text = print_named(g, id, self.style, &self.names, &mut self.used.borrow_mut())?;
        let room = self.room.get().checked_sub(text.len()).ok_or(ReportError::DocumentTooLarge(self.budget))?;
        self.room.set(room);
        Ok(text)
    }

    /// The definitions the document printed by name, each once: `d = r2 − r1`.
    fn definitions(&self, g: &Graph, d: &Derivation, out: &mut String) -> Result<(), ReportError> {
        let used = self.used.borrow();
        let defs: Vec<&Definition> = d
            .definitions
            .iter()
            .flatten()
            .filter(|def| {
                // The name printed for a node is the first definition's of that node (an
                // alias `d2 = "d1"` of an earlier definition is printed as `d1`).
                [def.written, def.simplified]
                    .iter()
                    .any(|id| used.contains(id) && self.names.get(id).is_some_and(|n| *n == def.name))
            })
            .collect();
        if defs.is_empty() {
            return Ok(());
        }
        self.heading(out, "Definitions (printed by name below)");
        for def in defs {
            let vector = g.ty(def.simplified) == crate::expr::Ty::Vector;
            self.line(out, &symbol_name(&def.name, vector, self.style), &print(g, def.simplified, self.style)?);
        }
        Ok(())
    }

    /// An equation `lhs = rhs` as a display line.
    fn line(&self, out: &mut String, lhs: &str, rhs: &str) {
        match self.format {
            Format::Text => {
                let _ = writeln!(out, "  {lhs} = {rhs}");
            }
            Format::Latex => {
                let _ = writeln!(out, "\\[ {lhs} = {rhs} \\]");
            }
            _ => {
                let _ = writeln!(out, "$$ {lhs} = {rhs} $$\n");
            }
        }
    }

    fn heading(&self, out: &mut String, text: &str) {
        let text = &one_line(text);
        match self.format {
            Format::Text => {
                let _ = writeln!(out, "\n{text}");
            }
            Format::Latex => {
                let _ = writeln!(out, "\n\\subsection*{{{}}}", latex_escape(text));
            }
            _ => {
                let _ = writeln!(out, "\n## {}\n", markdown_text(text));
            }
        }
    }

    fn para(&self, out: &mut String, text: &str) {
        match self.format {
            Format::Text => {
                let _ = writeln!(out, "  {text}");
            }
            Format::Latex => {
                let _ = writeln!(out, "{}\n", latex_escape(text));
            }
            _ => {
                let _ = writeln!(out, "{text}\n");
            }
        }
    }

    /// A displayed name with a note in words: `∇C (∇ wrt r, body bead)`; in LaTeX the note
    /// is set as text beside the mathematics (`\quad \text{…}`, amsmath).
    fn label(&self, math: &str, note: &str) -> String {
        if self.style == Style::Latex {
            format!("{math} \\quad \\text{{({})}}", latex_escape(note))
        } else {
            format!("{math} ({note})")
        }
    }

    /// The names `C`, `Ċ`, `C̈`, `∇C`, `λ` in this format, with a subscript.
    fn sym(&self, which: &str, sub: &str) -> String {
        let latex = self.style == Style::Latex;
        let base = match (which, latex) {
            ("C", _) => "C".to_string(),
            ("Cdot", false) => "Ċ".into(),
            ("Cdot", true) => "\\dot{C}".into(),
            ("Cddot", false) => "C̈".into(),
            ("Cddot", true) => "\\ddot{C}".into(),
            ("grad", false) => "∇C".into(),
            ("grad", true) => "\\nabla C".into(),
            ("lambda", false) => "λ".into(),
            ("lambda", true) => "\\lambda".into(),
            ("force", false) => "F_c".into(),
            ("force", true) => "\\vec{F}_c".into(),
            ("angular", false) => "∂C/∂θ".into(),
            ("angular", true) => "\\partial C / \\partial \\theta".into(),
            // 3D: the coefficient of ω in Ċ (q has no derivative of its own in the formulas).
            ("angular3", false) => "∂Ċ/∂ω".into(),
            ("angular3", true) => "\\partial \\dot{C} / \\partial \\omega".into(),
            ("torque", false) => "τ_c".into(),
            ("torque", true) => "\\tau_c".into(),
            (other, _) => other.to_string(),
        };
        if which == "force" && latex && !sub.is_empty() {
            return format!("\\vec{{F}}_{{c,\\mathrm{{{}}}}}", latex_escape(sub));
        }
        if which == "torque" && latex && !sub.is_empty() {
            return format!("\\tau_{{c,\\mathrm{{{}}}}}", latex_escape(sub));
        }
        match (sub.is_empty(), latex) {
            (true, _) => base,
            (false, false) => format!("{base}[{sub}]"),
            (false, true) => format!("{base}_{{\\mathrm{{{}}}}}", latex_escape(sub)),
        }
    }
}

impl Doc {
    /// A named entry of a matrix or vector, `A[rod1, rod2]` (`A_{\mathrm{rod1},\mathrm{rod2}}`
    /// in LaTeX): entries of A, b, J and c are named by constraints (and bodies), not numbered.
    fn entry(&self, base: &str, names: &[&str]) -> String {
        if self.style == Style::Latex {
            let names: Vec<String> = names.iter().map(|n| format!("\\mathrm{{{}}}", latex_escape(n))).collect();
            format!("{base}_{{{}}}", names.join(","))
        } else {
            format!("{base}[{}]", names.join(", "))
        }
    }
}

/// A title or heading from the file on one line: line breaks and other control characters
/// become spaces, so a title cannot start a new Markdown block or break `\section*{…}`.
fn one_line(s: &str) -> String {
    s.chars().map(|c| if c.is_control() { ' ' } else { c }).collect()
}

/// Text for a Markdown heading: a `<` that could open an HTML tag or comment (`<b`, `</`,
/// `<!`, `<?`) as `&lt;`, so no raw HTML passes; `<=` in a constraint stays as written.
fn markdown_text(s: &str) -> String {
    let mut out = String::new();
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        let tag = c == '<' && chars.peek().is_some_and(|n| n.is_ascii_alphabetic() || matches!(n, '/' | '!' | '?'));
        if tag { out.push_str("&lt;") } else { out.push(c) }
    }
    out
}

/// Text (a title, a heading, a sentence) as LaTeX text: the characters LaTeX treats as
/// commands escaped, and the mathematical ones this report writes (λ, ∇, Ċ, C̈, ·, ≥, ₖ, ²…)
/// turned into inline math, consecutive ones in one `$…$`. The result is ASCII for every
/// sentence lagrange writes; other characters of a user's title pass through as UTF-8.
fn latex_escape(s: &str) -> String {
    enum Piece {
        Text(String),
        Math(String),
    }
    fn push(pieces: &mut Vec<Piece>, piece: Piece) {
        match (pieces.last_mut(), piece) {
            (Some(Piece::Math(m)), Piece::Math(x)) => m.push_str(&x),
            (Some(Piece::Text(t)), Piece::Text(x)) => t.push_str(&x),
            (_, piece) => pieces.push(piece),
        }
    }
    let mut pieces: Vec<Piece> = Vec::new();
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        // A combining dot or diaeresis puts its accent on this character: `C̈`.
        let accent = match chars.peek() {
            Some('\u{307}') => Some("dot"),
            Some('\u{308}') => Some("ddot"),
            _ => None,
        };
        if let Some(accent) = accent {
            chars.next();
            push(&mut pieces, Piece::Math(format!("\\{accent}{{{c}}}")));
            continue;
        }
        // Sub- and superscripts gather into one script on the letter before them: `Jₖᵢ`, `l²`.
        let script = |c: char| match c {
            'ₖ' => Some(('_', 'k')),
            'ᵢ' => Some(('_', 'i')),
            'ⱼ' => Some(('_', 'j')),
            '²' => Some(('^', '2')),
            _ => None,
        };
        if let Some((kind, first)) = script(c) {
            let mut run = String::from(first);
            while let Some((k, x)) = chars.peek().copied().and_then(script) {
                if k != kind {
                    break;
                }
                run.push(x);
                chars.next();
            }
            // The base: a letter just before (taken into the math), the math just before
            // (unless it ends in a script of the same kind), or an empty group.
            let base = match pieces.last_mut() {
                Some(Piece::Text(t)) if t.ends_with(|b: char| b.is_ascii_alphabetic()) => {
                    t.pop().map(String::from).unwrap_or_default()
                }
                Some(Piece::Math(m)) if !(m.ends_with('}') && m.rfind('{').is_some_and(|i| m[..i].ends_with(kind))) => {
                    String::new()
                }
                _ => "{}".into(),
            };
            if matches!(pieces.last(), Some(Piece::Text(t)) if t.is_empty()) {
                pieces.pop();
            }
            push(&mut pieces, Piece::Math(format!("{base}{kind}{{{run}}}")));
            continue;
        }
        let math = match c {
            'λ' => "\\lambda ",
            'κ' => "\\kappa ",
            'Σ' => "\\sum ",
            '∇' => "\\nabla ",
            '·' => "\\cdot ",
            '×' => "\\times ",
            '≥' => "\\geq ",
            '≤' => "\\leq ",
            '→' => "\\to ",
            '−' => "-",
            'Ċ' => "\\dot{C}",
            'ȧ' => "\\dot{a}",
            'ḃ' => "\\dot{b}",
            _ => "",
        };
        if !math.is_empty() {
            push(&mut pieces, Piece::Math(math.to_string()));
            continue;
        }
        let text = match c {
            '\\' => "\\textbackslash{}".to_string(),
            '^' => "\\textasciicircum{}".to_string(),
            '~' => "\\textasciitilde{}".to_string(),
            '_' | '&' | '%' | '#' | '$' | '{' | '}' => format!("\\{c}"),
            _ => c.to_string(),
        };
        push(&mut pieces, Piece::Text(text));
    }
    let mut out = String::new();
    for piece in pieces {
        match piece {
            Piece::Text(t) => out.push_str(&t),
            Piece::Math(m) => {
                out.push('$');
                out.push_str(m.trim_end());
                out.push('$');
            }
        }
    }
    out
}

/// The derivation as a document (text, LaTeX or Markdown).
pub fn document(system: &System, d: &Derivation, format: Format, steps: bool) -> Result<String, ReportError> {
    let doc = Doc::naming(format, d, document_budget(system));
    let mut out = String::new();
    let title = if system.title.is_empty() { "Constraint forces".to_string() } else { one_line(&system.title) };
    match format {
        Format::Text => {
            let _ = writeln!(out, "{title} ({}D)", system.dim());
        }
        Format::Latex => {
            let _ = writeln!(out, "\\section*{{{} ({}D)}}", latex_escape(&title), system.dim());
        }
        _ => {
            let _ = writeln!(out, "# {} ({}D)", markdown_text(&title), system.dim());
        }
    }
    // The body first: the definitions shown are those it printed by name.
    let mut body = String::new();
    if steps {
        steps_document(system, d, &doc, &mut body)?;
    } else {
        summary(system, d, &doc, &mut body)?;
    }
    doc.definitions(&d.graph, d, &mut out)?;
    out.push_str(&body);
    Ok(out)
}

fn kind(system: &System, k: usize) -> &'static str {
    if system.constraints[k].inequality { "inequality C ≥ 0" } else { "equality C = 0" }
}

fn summary(system: &System, d: &Derivation, doc: &Doc, out: &mut String) -> Result<(), ReportError> {
    let g = &d.graph;
    let many = d.constraints.len() > 1;
    for (k, dc) in d.constraints.iter().enumerate() {
        let c = &system.constraints[k];
        doc.heading(out, &format!("Constraint {}: {}  ({})", c.name, c.text, kind(system, k)));
        let sub = if many { c.name.as_str() } else { "" };
        doc.line(out, &doc.sym("C", sub), &doc.expr(g, dc.c)?);
        doc.line(out, &doc.sym("Cdot", sub), &doc.expr(g, dc.c_dot)?);
        doc.line(out, &doc.sym("Cddot", sub), &doc.expr(g, dc.c_ddot)?);
        for (&(body, grad), &(_, dir)) in dc.gradient.iter().zip(&dc.jacobian) {
            let name = &system.bodies[body].name;
            let r = &g.symbol(system.bodies[body].position).name;
            doc.line(out, &doc.label(&doc.sym("grad", sub), &format!("∇ wrt {r}, body {name}")), &doc.expr(g, grad)?);
            if !dc.scale.is_one() {
                doc.line(
                    out,
                    &doc.label("J", &format!("direction, ∇C/{}, body {name}", rational_operand(&dc.scale))),
                    &doc.expr(g, dir)?,
                );
            }
        }
        angular_lines(system, d, doc, out, k, sub)?;
        let at_rest = if dc.angular.is_empty() { "a = 0" } else { "a = 0 and alpha = 0" };
        let note = format!("C̈ at {at_rest}{}", scale_note(dc.scale.is_one(), &dc.scale));
        doc.line(out, &doc.label("c", &note), &doc.expr(g, dc.bias)?);
    }
    doc.heading(out, "The multiplier equation  A λ + b = 0");
    a_and_b(system, d, doc, out)?;
    if let Some(lambda) = d.lambda {
        doc.heading(out, "Multiplier and constraint force");
        doc.line(out, &doc.sym("lambda", ""), &doc.expr(g, lambda)?);
        wrench_lines(system, d, doc, out)
    } else {
        forces_as_sums(system, d, doc, out)
    }
}

/// The angular part of constraint `k`'s direction on each rigid body it turns: ∂C/∂θ and,
/// when κ ≠ 1, Jʷ = ∂C/∂θ / κ (the coefficient of ω in Ċ/κ and of α in C̈/κ).
fn angular_lines(
    system: &System,
    d: &Derivation,
    doc: &Doc,
    out: &mut String,
    k: usize,
    sub: &str,
) -> Result<(), ReportError> {
    let (g, dc) = (&d.graph, &d.constraints[k]);
    for (&(body, grad), &(_, dir)) in dc.angular_gradient.iter().zip(&dc.angular) {
        let name = &system.bodies[body].name;
        let Some(rigid) = &system.bodies[body].rigid else { continue };
        let (which, wrt) = match rigid.nodes.axes {
            Some(_) => ("angular3", &g.symbol(rigid.angular_velocity).name),
            None => ("angular", &g.symbol(rigid.orientation).name),
        };
        doc.line(out, &doc.label(&doc.sym(which, sub), &format!("wrt {wrt}, body {name}")), &doc.expr(g, grad)?);
        if !dc.scale.is_one() {
            let jw = if doc.style == Style::Latex { "J^{\\omega}" } else { "Jʷ" };
            let note = format!("angular direction, over {}, body {name}", dc.scale);
            doc.line(out, &doc.label(jw, &note), &doc.expr(g, dir)?);
        }
    }
    Ok(())
}

/// The entries of A (upper triangle, non-zero) and b, named by constraints when several.
fn a_and_b(system: &System, d: &Derivation, doc: &Doc, out: &mut String) -> Result<(), ReportError> {
    let g = &d.graph;
    let many = d.constraints.len() > 1;
    let name = |k: usize| system.constraints[k].name.as_str();
    for &(k, j, a) in &d.a {
        let lhs = if many { doc.entry("A", &[name(k), name(j)]) } else { "A".into() };
        doc.line(out, &lhs, &doc.expr(g, a)?);
    }
    if many {
        doc.para(out, "(A is symmetric, A[k, j] = A[j, k]; entries not listed are 0.)");
    }
    for (k, &b) in d.b.iter().enumerate() {
        let lhs = if many { doc.entry("b", &[name(k)]) } else { "b".into() };
        doc.line(out, &lhs, &doc.expr(g, b)?);
    }
    Ok(())
}

/// For several constraints, the system A λ = −b row by row, with the entries by name:
/// `A[rod1, rod1] λ[rod1] + A[rod1, rod2] λ[rod2] = −b[rod1]`.
fn system_rows(system: &System, d: &Derivation, doc: &Doc, out: &mut String) {
    let name = |k: usize| system.constraints[k].name.as_str();
    let lambda = if doc.style == Style::Latex { "\\lambda" } else { "λ" };
    let minus = if doc.style == Style::Latex { "-" } else { "−" };
    for k in 0..d.constraints.len() {
        let terms: Vec<String> = (0..d.constraints.len())
            .filter(|&j| d.a_entry(k, j).is_some())
            .map(|j| {
                // The multipliers as the force lines print them: λ_rod1, \lambda_{\mathrm{rod1}}.
                let l =
                    if doc.style == Style::Latex { doc.entry(lambda, &[name(j)]) } else { format!("λ_{}", name(j)) };
                format!("{} {l}", doc.entry("A", &[name(k), name(j)]))
            })
            .collect();
        let lhs = if terms.is_empty() { "0".to_string() } else { terms.join(" + ") };
        doc.line(out, &lhs, &format!("{minus}{}", doc.entry("b", &[name(k)])));
    }
}

fn scale_note(one: bool, scale: &crate::expr::Rational) -> String {
    if one { String::new() } else { format!(", over {}", rational_operand(scale)) }
}

/// For several constraints: the force on each body as Σₖ λₖ Jₖᵢ, with named multipliers.
fn forces_as_sums(system: &System, d: &Derivation, doc: &Doc, out: &mut String) -> Result<(), ReportError> {
    doc.heading(out, "Constraint forces (λ solves A λ = −b at a state: lagrange solve)");
    wrench_lines(system, d, doc, out)
}

/// The force Σₖ λₖ Jₖᵢ on each body and the torque Σₖ λₖ Jʷₖᵢ on each rigid body, in the
/// multiplier symbols: one constraint's is `λ J`, λ's closed form printed once before, so
/// the document grows with each direction, never with λ repeated on every body.
fn wrench_lines(system: &System, d: &Derivation, doc: &Doc, out: &mut String) -> Result<(), ReportError> {
    let sums = d.force_sums.as_ref().ok_or(ReportError::NotDerived("force sums"))?;
    for &(body, sum) in sums {
        doc.line(out, &doc.sym("force", &system.bodies[body].name), &doc.expr(&d.graph, sum)?);
    }
    for &(body, sum) in d.torque_sums.iter().flatten() {
        doc.line(out, &doc.sym("torque", &system.bodies[body].name), &doc.expr(&d.graph, sum)?);
    }
    Ok(())
}

fn steps_document(system: &System, d: &Derivation, doc: &Doc, out: &mut String) -> Result<(), ReportError> {
    let newton = d.newton.as_ref().ok_or(ReportError::NotDerived("steps"))?;
    let many = d.constraints.len() > 1;
    for (k, dc) in d.constraints.iter().enumerate() {
        let (name, text) = (&system.constraints[k].name, &system.constraints[k].text);
        let sub = if many { name.as_str() } else { "" };
        let g = &d.graph;
        doc.heading(out, &format!("Constraint {name}: {text}"));
        doc.para(out, &format!("Step 1. The position constraint, written as C = 0 ({}):", kind(system, k)));
        doc.line(out, &doc.sym("C", sub), &doc.expr(g, dc.c)?);
        doc.para(out, "Step 2. Differentiate in time. d(a·b)/dt = ȧ·b + a·ḃ (product rule), dr/dt = v:");
        let (raw, done) = (doc.expr(g, dc.c_dot_raw)?, doc.expr(g, dc.c_dot)?);
        doc.line(out, &doc.sym("Cdot", sub), &chain(&raw, &done));
        doc.para(out, "Step 3. Differentiate again, dv/dt = a:");
        let (raw, done) = (doc.expr(g, dc.c_ddot_raw)?, doc.expr(g, dc.c_ddot)?);
        doc.line(out, &doc.sym("Cddot", sub), &chain(&raw, &done));
    }
    // Newton: aᵢ = (Fᵢ + F_c,ᵢ)/mᵢ, substituted into each C̈.
    doc.heading(out, "Newton's law");
    doc.para(out, "Step 4. Each body obeys m a = F + F_c, so a = (F + F_c)/m. Substituted into C̈ = 0:");
    if system.has_rigid_bodies() && system.dim() == 3 {
        doc.para(
            out,
            "A rigid body also obeys Euler's law I alpha = T + T_c - w x (I w) (3D, about the centre \
             of mass, I = R(q) diag(I1, I2, I3) R(q)^T the world inertia), so alpha = I^-1 (T + T_c - w x (I w)), \
             with d(w)/dt = alpha and d rot(q, s)/dt = w x rot(q, s):",
        );
    } else if system.has_rigid_bodies() {
        doc.para(
            out,
            "A rigid body also obeys Euler's law I alpha = T + T_c (2D, about the centre of mass), \
             so alpha = (T + T_c)/I, with its angle's rates d(th)/dt = w, d(w)/dt = alpha and \
             d rot(th, s)/dt = w perp(rot(th, s)):",
        );
    }
    for (k, &substituted) in newton.iter().enumerate() {
        let sub = if many { system.constraints[k].name.as_str() } else { "" };
        doc.line(out, &doc.sym("Cddot", sub), &format!("{} = 0", doc.expr(&d.graph, substituted)?));
    }
    doc.heading(out, "The direction of the force");
    doc.para(
        out,
        "Step 5. Constraint forces do no work on any motion the constraint allows (D'Alembert): \
         F_c·v = 0 whenever Ċ = ∇C·v = 0, so F_c is parallel to ∇C: F_c = λ ∇C. \
         Constant factors of ∇C go into λ:",
    );
    for (k, dc) in d.constraints.iter().enumerate() {
        let sub = if many { system.constraints[k].name.clone() } else { String::new() };
        for (&(body, grad), &(_, dir)) in dc.gradient.iter().zip(&dc.jacobian) {
            let g = &d.graph;
            let name = &system.bodies[body].name;
            let lhs = doc.label(&doc.sym("grad", &sub), &format!("on {name}"));
            let rhs = if dc.scale.is_one() {
                doc.expr(g, grad)?
            } else {
                let times = if doc.style == Style::Latex { "\\cdot" } else { "·" };
                format!("{} = {} {times} ({})", doc.expr(g, grad)?, rational_operand(&dc.scale), doc.expr(g, dir)?)
            };
            doc.line(out, &lhs, &rhs);
            if many {
                let k_name = system.constraints[k].name.as_str();
                doc.line(out, &doc.entry("J", &[k_name, name]), &doc.expr(g, dir)?);
            }
        }
        if !dc.angular.is_empty() {
            doc.para(
                out,
                "On a rigid body the constraint also turns it: the torque is λ times the \
                 coefficient of its angular velocity w in Ċ (of alpha in C̈), the angular part of J:",
            );
            angular_lines(system, d, doc, out, k, &sub)?;
        }
    }
    doc.heading(out, "The multiplier");
    if many {
        // DESIGN step 3 made visible: the part of each C̈ that does not involve a.
        doc.para(
            out,
            "Step 6. Each C̈ₖ (over the factor κₖ taken out of ∇Cₖ) is affine in the accelerations: \
             C̈ₖ/κₖ = Σᵢ Jₖᵢ·aᵢ + cₖ, with cₖ = C̈ₖ/κₖ at a = 0:",
        );
        for (k, dc) in d.constraints.iter().enumerate() {
            doc.line(out, &doc.entry("c", &[system.constraints[k].name.as_str()]), &doc.expr(&d.graph, dc.bias)?);
        }
        doc.para(
            out,
            "With aᵢ = (Fᵢ + Σⱼ λⱼ Jⱼᵢ)/mᵢ the conditions C̈ = 0 are linear in λ: A λ + b = 0, where \
             Aₖⱼ = Σᵢ Jₖᵢ·Jⱼᵢ/mᵢ and bₖ = Σᵢ Jₖᵢ·Fᵢ/mᵢ + cₖ:",
        );
    } else {
        doc.para(out, "Step 6. With F_c = Σ λ J, the conditions C̈ = 0 are linear in λ: A λ + b = 0, where");
    }
    if system.has_rigid_bodies() {
        doc.para(
            out,
            "With rigid bodies c is also taken at alpha = 0, and, with Jw the angular part of \
             each direction, A gains Σ Jw Jw/I and b gains Σ Jw T/I over the rigid bodies \
             (Euler's law in 2D: no gyroscopic term):",
        );
    }
    let g = &d.graph;
    a_and_b(system, d, doc, out)?;
    if let Some(lambda) = d.lambda {
        doc.para(out, "so λ = −b/A:");
        doc.line(out, &doc.sym("lambda", ""), &doc.expr(g, lambda)?);
        doc.heading(out, "The constraint force");
        doc.para(out, "Step 7. Magnitude λ times direction J:");
        wrench_lines(system, d, doc, out)
    } else {
        doc.para(
            out,
            "Step 7. The system A λ = −b, one row per constraint; λ solves it at each state (lagrange solve):",
        );
        system_rows(system, d, doc, out);
        doc.para(out, "The force on each body is Σₖ λₖ Jₖᵢ:");
        forces_as_sums(system, d, doc, out)
    }
}

/// `raw = done`, or just `done` when the rule gave the collected form already.
fn chain(raw: &str, done: &str) -> String {
    if raw == done { done.to_string() } else { format!("{raw} = {done}") }
}

/// The derivation as JSON ([`json`](fn@json)): one value, `A` in it as the list of its
/// non-zero entries over the upper triangle, `[{"row": k, "col": j, "expr": "…"}]` with
/// `k ≤ j`, sorted by row then column (A is symmetric: the entry `(j, k)` is the same
/// expression). Its size is linear in the scene's: a chain's A has 2N − 1 such entries,
/// where the dense N × N array of earlier versions held N² strings, nearly all `"0"`.
#[derive(Debug)]
pub struct JsonDerivation {
    value: Value,
}

impl serde::Serialize for JsonDerivation {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.value.serialize(serializer)
    }
}

/// The derivation as JSON: every expression a string in the expression language.
pub fn json(system: &System, d: &Derivation) -> Result<JsonDerivation, ReportError> {
    let e = &JsonText::new(system, &d.graph);
    let constraints = json_constraints(system, d, e)?;
    let mut entries: Vec<(usize, usize, Id)> =
        d.a.iter().map(|&(k, j, id)| if k <= j { (k, j, id) } else { (j, k, id) }).collect();
    entries.sort_by_key(|&(k, j, _)| (k, j));
    let mut a = Vec::new();
    for (k, j, id) in entries {
        a.push(json!({ "row": k, "col": j, "expr": e.text(id)? }));
    }
    let b: Result<Vec<String>, ReportError> = d.b.iter().map(|&id| e.text(id)).collect();
    let mut out = json!({
        "title": system.title,
        "dimension": system.dim(),
        "bodies": json_bodies(system, e),
        "constraints": constraints,
        "A": a,
        "b": b?,
    });
    // One constraint: λ in closed form once, and the forces and torques in its symbol.
    let closed = d.lambda.is_some();
    if let Some(lambda) = d.lambda {
        out["lambda"] = json!({ system.constraints[0].name.clone(): e.text(lambda)? });
    }
    json_sums(system, d, e, &mut out, closed)?;
    Ok(JsonDerivation { value: out })
}

/// Expressions printed for JSON within the document's budget (`document_budget`).
struct JsonText<'a> {
    system: &'a System,
    graph: &'a crate::expr::graph::Graph,
    budget: usize,
    room: std::cell::Cell<usize>,
}

impl<'a> JsonText<'a> {
    fn new(system: &'a System, graph: &'a crate::expr::graph::Graph) -> JsonText<'a> {
        let budget = document_budget(system);
        JsonText { system, graph, budget, room: std::cell::Cell::new(budget) }
    }

    /// `id` in the expression language; an error once the document passes its budget.
    fn text(&self, id: Id) -> Result<String, ReportError> {
        let text = print(self.graph, id, Style::Source)?;
        let left = self.room.get().checked_sub(text.len()).ok_or(ReportError::DocumentTooLarge(self.budget))?;
        self.room.set(left);
        Ok(text)
    }

    /// `{ body name: expression }` for (body, expression) pairs.
    fn by_body(&self, pairs: &[(usize, Id)]) -> Result<Value, ReportError> {
        let mut map = serde_json::Map::new();
        for &(body, id) in pairs {
            map.insert(self.system.bodies[body].name.clone(), json!(self.text(id)?));
        }
        Ok(Value::Object(map))
    }
}

/// Each body's symbols, mass and (rigid bodies) orientation, angular symbols and inertia.
fn json_bodies(system: &System, e: &JsonText<'_>) -> Vec<Value> {
    let g = e.graph;
    let mut bodies = Vec::new();
    for b in &system.bodies {
        let mut body = json!({
            "name": b.name,
            "position": g.symbol(b.position).name,
            "velocity": g.symbol(b.velocity).name,
            "acceleration": g.symbol(b.acceleration).name,
            "force": g.symbol(b.force).name,
            "mass": e.text(b.mass).unwrap_or_default(),
        });
        if let Some(r) = &b.rigid {
            body["orientation"] = json!(g.symbol(r.orientation).name);
            body["angular_velocity"] = json!(g.symbol(r.angular_velocity).name);
            body["angular_acceleration"] = json!(g.symbol(r.angular_acceleration).name);
            body["torque"] = json!(g.symbol(r.torque).name);
            body["inertia"] = json!(e.text(r.inertia).unwrap_or_default());
        }
        bodies.push(body);
    }
    bodies
}

/// Each constraint: C, Ċ, C̈, κ, J by body (`gradient`), c, and Jʷ on rigid bodies.
fn json_constraints(system: &System, d: &Derivation, e: &JsonText<'_>) -> Result<Vec<Value>, ReportError> {
    let mut constraints = Vec::new();
    for (k, dc) in d.constraints.iter().enumerate() {
        let c = &system.constraints[k];
        let mut entry = json!({
            "name": c.name,
            "kind": if c.inequality { "inequality" } else { "equality" },
            "C": e.text(dc.c)?,
            "C_dot": e.text(dc.c_dot)?,
            "C_ddot": e.text(dc.c_ddot)?,
            "scale": dc.scale.to_string(),
            "gradient": e.by_body(&dc.jacobian)?,
            "c": e.text(dc.bias)?,
        });
        // Rigid bodies: Jʷ = ∂C/∂θ / κ by body (absent for point masses).
        if !dc.angular.is_empty() {
            entry["angular_gradient"] = e.by_body(&dc.angular)?;
        }
        constraints.push(entry);
    }
    Ok(constraints)
}

/// The multipliers as named symbols (`multipliers`: constraint → symbol), and the force on
/// each body as Σₖ λₖ Jₖᵢ in them (as `derive` prints it), so the JSON parses again once
/// the multiplier names are declared as scalars; likewise the torques on rigid bodies. With
/// several constraints they are `force_sums` and `torque_sums` (λ solves A λ = −b at a
/// state); with one (`closed`) `forces` and `torques`, λ's closed form being `lambda`, so
/// a consumer evaluates λ once and each force from it: the document is self-contained and
/// λ is not repeated on every body.
fn json_sums(
    system: &System,
    d: &Derivation,
    e: &JsonText<'_>,
    out: &mut Value,
    closed: bool,
) -> Result<(), ReportError> {
    let names: Vec<String> = system.constraints.iter().map(|c| multiplier_name(&c.name)).collect();
    // Each body's terms from its own constraints' directions, gathered in one pass over the
    // constraints (a body's first direction in a constraint counts).
    let mut terms: Vec<Vec<String>> = vec![Vec::new(); system.bodies.len()];
    let mut last: Vec<Option<usize>> = vec![None; system.bodies.len()];
    for (k, dc) in d.constraints.iter().enumerate() {
        for &(body, j) in &dc.jacobian {
            if body >= terms.len() || last[body] == Some(k) {
                continue;
            }
            last[body] = Some(k);
            terms[body].push(times(&names[k], e.text(j)?));
        }
    }
    let multipliers: serde_json::Map<String, Value> =
        system.constraints.iter().zip(&names).map(|(c, n)| (c.name.clone(), json!(n))).collect();
    let (forces, torques) = if closed { ("forces", "torques") } else { ("force_sums", "torque_sums") };
    out["multipliers"] = Value::Object(multipliers);
    out[forces] = sums_by_body(system, terms);
    // Rigid bodies: the torque on each as Σₖ λₖ Jʷₖᵢ (absent without rigid bodies).
    let mut terms: Vec<Vec<String>> = vec![Vec::new(); system.bodies.len()];
    for (k, dc) in d.constraints.iter().enumerate() {
        for &(body, j) in &dc.angular {
            if let Some(list) = terms.get_mut(body) {
                list.push(times(&names[k], e.text(j)?));
            }
        }
    }
    let torque_sums = sums_by_body(system, terms);
    if torque_sums.as_object().is_some_and(|m| !m.is_empty()) {
        out[torques] = torque_sums;
    }
    Ok(())
}

/// `lambda*j`, with `j` in parentheses unless it is a name.
fn times(lambda: &str, j: String) -> String {
    let atomic = j.chars().all(|ch| ch.is_alphanumeric() || ch == '_');
    if atomic { format!("{lambda}*{j}") } else { format!("{lambda}*({j})") }
}

/// `{ body name: "t₁ + t₂ + …" }` over the bodies with terms.
fn sums_by_body(system: &System, terms: Vec<Vec<String>>) -> Value {
    let mut sums = serde_json::Map::new();
    for (b, list) in system.bodies.iter().zip(terms) {
        if !list.is_empty() {
            sums.insert(b.name.clone(), json!(list.join(" + ")));
        }
    }
    Value::Object(sums)
}

/// The symbol of constraint `name`'s multiplier in JSON: `lambda_<name>`, with every
/// character that cannot be part of a name replaced by `_` (constraint names are free text).
pub fn multiplier_name(name: &str) -> String {
    let clean: String = name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    format!("lambda_{clean}")
}
