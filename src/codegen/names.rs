//! Names and comment text for generated code: identifiers that are always valid snake_case
//! and never keywords, distinct names, and one-line comment text that no file can end early
//! or turn around (control and bidirectional characters escaped).
//!
//! Not here: which names a module uses ([`super::rust`]).

use crate::expr::graph::NameSet;
use std::fmt::Write;

/// Text safe inside a `//` or `///` comment: one line, no control or bidirectional
/// characters (those are written as `\u{…}`).
pub fn comment_text(s: &str) -> String {
    let mut out = String::new();
    for ch in s.chars() {
        let bidi = matches!(ch, '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}');
        if ch.is_control() || bidi || ch == '\u{2028}' || ch == '\u{2029}' || ch == '\u{feff}' {
            let _ = write!(out, "\\u{{{:x}}}", ch as u32);
        } else {
            out.push(ch);
        }
    }
    out
}

/// Rust's keywords (strict, reserved and weak ones that cannot name a field or function).
const KEYWORDS: &[&str] = &[
    "as", "break", "const", "continue", "crate", "else", "enum", "extern", "false", "fn", "for", "if", "impl", "in",
    "let", "loop", "match", "mod", "move", "mut", "pub", "ref", "return", "self", "static", "struct", "super", "trait",
    "true", "type", "unsafe", "use", "where", "while", "async", "await", "dyn", "abstract", "become", "box", "do",
    "final", "macro", "override", "priv", "typeof", "unsized", "virtual", "yield", "try", "gen", "union", "static",
    "raw", "safe",
];

/// A snake_case identifier for `name`: ASCII letters and digits kept (camel case split with
/// `_`), other characters as `_` or their code point (`λ` → `u3bb`), never a keyword, never
/// starting with a digit, never empty.
pub fn snake(name: &str) -> String {
    let mut out = String::new();
    let mut after_lower = false;
    for ch in name.chars() {
        if ch.is_ascii_alphanumeric() {
            if ch.is_ascii_uppercase() && after_lower {
                out.push('_');
            }
            out.push(ch.to_ascii_lowercase());
            after_lower = ch.is_ascii_lowercase() || ch.is_ascii_digit();
        } else if ch.is_alphanumeric() {
            if !out.is_empty() && !out.ends_with('_') {
                out.push('_');
            }
            let _ = write!(out, "u{:x}_", ch as u32);
            after_lower = false;
        } else {
            if !out.ends_with('_') {
                out.push('_');
            }
            after_lower = false;
        }
    }
    let mut out = out.trim_matches('_').to_string();
    while out.contains("__") {
        out = out.replace("__", "_");
    }
    if out.is_empty() {
        out.push('x');
    }
    if out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert_str(0, "n_");
    }
    if KEYWORDS.contains(&out.as_str()) {
        out.push('_');
    }
    out
}

/// The name itself when it can be a Rust field as written: ASCII letters, digits and `_`,
/// not starting with a digit, not `_` alone and not a keyword. Otherwise `None` (the
/// field's name is then [`snake`] of it).
pub fn as_written(name: &str) -> Option<&str> {
    let ok = !name.is_empty()
        && name != "_"
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !name.starts_with(|c: char| c.is_ascii_digit())
        && !KEYWORDS.contains(&name)
        && !matches!(name, "Self" | "super" | "crate");
    ok.then_some(name)
}

/// C's keywords (C99 and later) and the object-like macros `<math.h>` defines: a name among
/// them, or one C reserves everywhere (`_` and a capital, or `__` anywhere), cannot be a C
/// field.
const C_RESERVED: &[&str] = &[
    "auto",
    "break",
    "case",
    "char",
    "const",
    "continue",
    "default",
    "do",
    "double",
    "else",
    "enum",
    "extern",
    "float",
    "for",
    "goto",
    "if",
    "inline",
    "int",
    "long",
    "register",
    "restrict",
    "return",
    "short",
    "signed",
    "sizeof",
    "static",
    "struct",
    "switch",
    "typedef",
    "union",
    "unsigned",
    "void",
    "volatile",
    "while",
    "_Bool",
    "_Complex",
    "_Imaginary",
    "bool",
    "true",
    "false",
    "alignas",
    "alignof",
    "nullptr",
    "static_assert",
    "thread_local",
    "typeof",
    "constexpr",
    "INFINITY",
    "NAN",
    "HUGE_VAL",
    "HUGE_VALF",
    "HUGE_VALL",
    "FP_NAN",
    "FP_INFINITE",
    "FP_ZERO",
    "FP_SUBNORMAL",
    "FP_NORMAL",
    "FP_ILOGB0",
    "FP_ILOGBNAN",
    "MATH_ERRNO",
    "MATH_ERREXCEPT",
    "math_errhandling",
    "FP_FAST_FMA",
    "FP_FAST_FMAF",
    "FP_FAST_FMAL",
    "DIM",
    "BODIES",
    "CONSTRAINTS",
    "errno",
    "NULL",
    "EOF",
];

/// Whether a Rust identifier cannot be a C field as it is (a keyword, a macro of
/// `<math.h>` or of the module, or a reserved identifier).
pub fn c_reserved(name: &str) -> bool {
    let mut chars = name.chars();
    let reserved_form =
        name.contains("__") || (chars.next() == Some('_') && chars.next().is_some_and(|c| c.is_ascii_uppercase()));
    reserved_form || C_RESERVED.contains(&name)
}

/// Hands out distinct identifiers: a clash gets `_2`, `_3`, ….
pub(super) struct Namer {
    used: NameSet<String>,
}

impl Namer {
    pub(super) fn new(taken: &[&str]) -> Namer {
        Namer { used: taken.iter().map(|s| s.to_string()).collect() }
    }

    pub(super) fn name(&mut self, wanted: &str) -> String {
        let mut name = wanted.to_string();
        let mut k = 2;
        while !self.used.insert(name.clone()) {
            // `self_` + `_2` would be `self__2`, which is not snake_case.
            name = format!("{}_{k}", wanted.trim_end_matches('_'));
            k += 1;
        }
        name
    }
}

#[cfg(test)]
mod tests {
    use super::c_reserved;

    #[test]
    fn c_keywords_macros_and_reserved_forms_are_not_c_fields() {
        for name in ["int", "double", "restrict", "INFINITY", "NAN", "DIM", "_Bool", "_X", "a__b"] {
            assert!(c_reserved(name), "{name}");
        }
        for name in ["r1", "v", "F_1", "_x", "theta", "position"] {
            assert!(!c_reserved(name), "{name}");
        }
    }
}
