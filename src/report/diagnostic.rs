//! Renders file problems as `file:line:col: message` with the source line and a caret.
//!
//! codespan-reporting draws the rustc-style `^^^` under the fault. Plain text, no colour,
//! so the same bytes go to a terminal, a pipe and a snapshot.

use crate::model::file::Problem;
use codespan_reporting::diagnostic::{Diagnostic, Label};
use codespan_reporting::files::SimpleFile;
use codespan_reporting::term::{self, Config};

/// Renders every problem of one file, in order.
pub fn render(path: &str, text: &str, problems: &[Problem]) -> String {
    let file = SimpleFile::new(path, text);
    let config = Config::default();
    let mut out = String::new();
    for p in problems {
        let mut d = Diagnostic::error().with_message(&p.message);
        match &p.span {
            Some(span) => {
                let start = floor_char(text, span.start.min(text.len()));
                let end = floor_char(text, span.end.clamp(start, text.len()));
                d = d.with_labels(vec![Label::primary((), start..end)]);
            }
            None => d = d.with_notes(vec![format!("in {path}")]),
        }
        match term::emit_into_string(&config, &file, &d) {
            Ok(s) => out.push_str(&s),
            Err(_) => out.push_str(&format!("error: {path}: {}\n", p.message)),
        }
    }
    out
}

/// The nearest char boundary at or before `i`.
pub fn floor_char(text: &str, mut i: usize) -> usize {
    while i > 0 && !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}
