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
    problems.iter().map(|p| render_labelled(path, text, &p.to_string(), p.span(), p.also())).collect()
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
    render_labelled(path, text, message, span, None)
}

/// As [`render_message`], with a second place (a span and what is there) labelled under its
/// own line when the problem has one (the message names its line too, for the long-line
/// layout, which shows only the first place).
fn render_labelled(
    path: &str,
    text: &str,
    message: &str,
    span: Option<std::ops::Range<usize>>,
    also: Option<(std::ops::Range<usize>, &str)>,
) -> String {
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
            let mut labels = vec![Label::primary((), start..end)];
            if let Some((also, what)) = also {
                let start = floor_char(text, also.start.min(text.len()));
                let end = floor_char(text, also.end.clamp(start, text.len()));
                labels.push(Label::secondary((), start..end).with_message(what));
            }
            d = d.with_labels(labels);
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
    let number = crate::model::problem::line_of(text, start);
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
    if !has_unsafe_bytes(s.as_bytes(), keep_newlines) {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut out = String::new();
    for c in s.chars() {
        match c {
            '\n' if !keep_newlines => out.push_str("\\n"),
            c if is_unsafe(c, keep_newlines) => out.extend(c.escape_unicode()),
            c => out.push(c),
        }
    }
    std::borrow::Cow::Owned(out)
}

/// Whether [`escape_controls`] escapes `c`.
fn is_unsafe(c: char, keep_newlines: bool) -> bool {
    (c.is_control() && !(keep_newlines && (c == '\n' || c == '\t')))
        || matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
}

/// Whether UTF-8 text holds a character [`escape_controls`] escapes, read byte by byte (a
/// derivation of a big scene is megabytes of text, mostly ASCII, which this passes without
/// decoding): the C0 controls and DEL are bytes below 0x20 and 0x7F; the C1 controls
/// U+0080–U+009F are 0xC2 0x80–0x9F; the bidirectional overrides U+202A–U+202E and
/// U+2066–U+2069 are 0xE2 0x80 0xAA–0xAE and 0xE2 0x81 0xA6–0xA9. No other character's
/// encoding holds these sequences (a lead byte is never a continuation byte).
fn has_unsafe_bytes(bytes: &[u8], keep_newlines: bool) -> bool {
    // Most bytes are none of these: one table lookup each, the rest only at a flagged byte.
    const FLAGGED: [bool; 256] = {
        let mut flagged = [false; 256];
        let mut b = 0;
        while b < 0x20 {
            flagged[b] = true;
            b += 1;
        }
        flagged[0x7f] = true;
        flagged[0xc2] = true;
        flagged[0xe2] = true;
        flagged
    };
    let after = |i: usize| bytes.get(i + 1..).unwrap_or_default();
    bytes.iter().enumerate().filter(|&(_, &b)| FLAGGED[usize::from(b)]).any(|(i, &b)| match (b, after(i)) {
        (b'\n' | b'\t', _) => !keep_newlines,
        (0xc2, [0x80..=0x9f, ..]) => true,
        (0xe2, [0x80, 0xaa..=0xae, ..] | [0x81, 0xa6..=0xa9, ..]) => true,
        (0xc2 | 0xe2, _) => false,
        _ => true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The characters at the edges of what is escaped, and their UTF-8 neighbours.
    const EDGES: [char; 24] = [
        '\0',
        '\t',
        '\n',
        '\r',
        '\u{1f}',
        ' ',
        '~',
        '\u{7f}',
        '\u{80}',
        '\u{9f}',
        '\u{a0}',
        '\u{ff}',
        '\u{2029}',
        '\u{202a}',
        '\u{202e}',
        '\u{202f}',
        '\u{2065}',
        '\u{2066}',
        '\u{2069}',
        '\u{206a}',
        'λ',
        '·',
        '²',
        '\u{1f600}',
    ];

    proptest! {
        /// The byte test finds exactly the characters the escape replaces.
        #[test]
        fn the_byte_test_agrees_with_the_characters(
            chars in prop::collection::vec(prop_oneof![any::<char>(), prop::sample::select(EDGES.to_vec())], 0..12),
            keep_newlines in any::<bool>(),
        ) {
            let s: String = chars.iter().collect();
            let by_char = s.chars().any(|c| is_unsafe(c, keep_newlines));
            prop_assert_eq!(has_unsafe_bytes(s.as_bytes(), keep_newlines), by_char, "{:?}", s);
            prop_assert_eq!(matches!(escape_controls(&s, keep_newlines), std::borrow::Cow::Owned(_)), by_char);
        }
    }
}
