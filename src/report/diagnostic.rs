//! Renders file problems (and budget errors of a constraint) as `file:line:col: message`
//! with the source line and a caret.
//!
//! codespan-reporting draws the rustc-style `^^^` under the fault. Plain text, no colour,
//! so the same bytes go to a terminal, a pipe and a snapshot. The message is the problem's
//! `Display` (`model::problem`); this file adds only the layout.
//!
//! Not here: the wording of messages (`model::problem`), choosing where output goes.

use crate::model::file::Problem;
use codespan_reporting::diagnostic::{Diagnostic, Label};
use codespan_reporting::files::SimpleFile;
use codespan_reporting::term::{self, Config};

/// Renders every problem of one file, in order.
pub fn render(path: &str, text: &str, problems: &[Problem]) -> String {
    problems.iter().map(|p| render_message(path, text, &p.to_string(), p.span())).collect()
}

/// Renders an error about constraint `k` of the file (a formula past the work budget) at
/// that constraint's `expr`, as file problems are: `file:line:col`, the line, a caret.
/// Without a place to show (the text does not parse as it did), `error: file: message`.
pub fn render_constraint(path: &str, text: &str, k: usize, message: &str) -> String {
    render_message(path, text, message, constraint_expr_span(text, k))
}

/// The span of the `expr` of the `k`-th `[[constraints]]` table (its table when it has none).
fn constraint_expr_span(text: &str, k: usize) -> Option<std::ops::Range<usize>> {
    use toml::de::{DeTable, DeValue};
    let root = DeTable::parse(text).ok()?;
    let DeValue::Array(tables) = root.get_ref().get("constraints")?.get_ref() else { return None };
    let table = tables.get(k)?;
    match table.get_ref() {
        DeValue::Table(t) => Some(t.get("expr").map_or(table.span(), |e| e.span())),
        _ => None,
    }
}

fn render_message(path: &str, text: &str, message: &str, span: Option<std::ops::Range<usize>>) -> String {
    let file = SimpleFile::new(path, text);
    let config = Config::default();
    // A name in a message (`in constraint `…``) never reaches the terminal raw.
    let message = escape_controls(message, false).into_owned();
    if let Some(span) = &span
        && let Some(clipped) = render_long_line(path, text, &message, span)
    {
        return clipped;
    }
    let mut d = Diagnostic::error().with_message(&message);
    match &span {
        Some(span) => {
            let start = floor_char(text, span.start.min(text.len()));
            let end = floor_char(text, span.end.clamp(start, text.len()));
            d = d.with_labels(vec![Label::primary((), start..end)]);
        }
        None => d = d.with_notes(vec![format!("in {path}")]),
    }
    match term::emit_into_string(&config, &file, &d) {
        Ok(s) => s,
        Err(_) => format!("error: {path}: {message}\n"),
    }
}

/// Source lines longer than this are shown as a window around the fault.
const MAX_LINE_CHARS: usize = 160;

/// The same layout as codespan's, for a problem on a source line too long to echo whole
/// (a 10 MB expression must not become a 10 MB message): the line is cut to a window of
/// the fault, marked with `…`. `None` when the line is short enough to show as it is.
fn render_long_line(path: &str, text: &str, message: &str, span: &std::ops::Range<usize>) -> Option<String> {
    let start = floor_char(text, span.start.min(text.len()));
    let end = floor_char(text, span.end.clamp(start, text.len()));
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let line_end = text[start..].find('\n').map_or(text.len(), |i| start + i);
    let line = &text[line_start..line_end];
    if line.chars().count() <= MAX_LINE_CHARS {
        return None;
    }
    let number = text[..start].matches('\n').count() + 1;
    let before: Vec<char> = text[line_start..start].chars().collect();
    let column = before.len() + 1;
    let shown_before = before.len().min(MAX_LINE_CHARS / 3);
    let after: String = text[start..line_end].chars().take(MAX_LINE_CHARS - shown_before).collect();
    let clipped_left = shown_before < before.len();
    let clipped_right = start + after.len() < line_end;
    let mut excerpt = String::new();
    if clipped_left {
        excerpt.push('…');
    }
    excerpt.extend(&before[before.len() - shown_before..]);
    excerpt.push_str(&after);
    if clipped_right {
        excerpt.push('…');
    }
    let caret_at = shown_before + usize::from(clipped_left);
    let carets = text[start..end.min(start + after.len())].chars().count().max(1);
    let gutter = " ".repeat(number.to_string().len());
    Some(format!(
        "error: {message}\n{gutter} ┌─ {path}:{number}:{column}\n{gutter} │\n{number} │ {excerpt}\n{gutter} │ {}{}\n\n",
        " ".repeat(caret_at),
        "^".repeat(carets)
    ))
}

/// The nearest char boundary at or before `i`.
pub fn floor_char(text: &str, mut i: usize) -> usize {
    while i > 0 && !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// `s` with every control character (and the bidirectional overrides, which reorder what a
/// terminal shows) written as an escape, `\u{1b}`: a name or title never reaches a
/// terminal raw, so it cannot move the cursor, erase a line or fake one. Line breaks are
/// kept when `keep_newlines` (multi-line text), escaped otherwise (one line).
pub fn escape_controls(s: &str, keep_newlines: bool) -> std::borrow::Cow<'_, str> {
    let unsafe_char = |c: char| {
        (c.is_control() && !(keep_newlines && (c == '\n' || c == '\t')))
            || matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
    };
    if !s.contains(unsafe_char) {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut out = String::new();
    for c in s.chars() {
        match c {
            '\n' if !keep_newlines => out.push_str("\\n"),
            c if unsafe_char(c) => out.extend(c.escape_unicode()),
            c => out.push(c),
        }
    }
    std::borrow::Cow::Owned(out)
}
