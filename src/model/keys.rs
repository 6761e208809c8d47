//! Unknown keys of a constraint file, every one of them, each with a "did you mean".
//!
//! serde's `deny_unknown_fields` stops at the first unknown key; a person who misspells
//! three keys wants three messages. So the file is first read as a spanned TOML tree
//! (`toml::de::DeTable`) and walked against the schema below; `model::document` then
//! ignores unknown keys (they have been reported here).
//!
//! Not here: the types of values (`model::document` checks those), meaning (validation in
//! `file`).

use super::problem::Problem;
use crate::expr::lower::suggest;
use toml::Spanned;
use toml::de::{DeTable, DeValue};

/// The keys of each table, by path. `[]` marks an array of tables.
const SCHEMA: &[(&str, &[&str])] = &[
    ("", &["title", "dimension", "parameters", "definitions", "bodies", "constraints", "scene", "expect"]),
    (
        "bodies[]",
        &[
            "name",
            "position",
            "velocity",
            "acceleration",
            "mass",
            "force",
            "orientation",
            "angular_velocity",
            "angular_acceleration",
            "inertia",
            "torque",
        ],
    ),
    ("constraints[]", &["name", "expr"]),
    ("scene", &["initial", "forces", "dt", "duration", "restitution"]),
    ("expect[]", &["force", "torque", "lambda", "C_dot", "C_ddot", "A", "b", "at", "tolerance", "note"]),
];

/// Every unknown key of the file's tree, located.
pub fn unknown_keys(root: &DeTable<'_>) -> Vec<Problem> {
    let mut problems = Vec::new();
    walk("", root, &mut problems);
    problems
}

fn walk(path: &'static str, table: &DeTable<'_>, problems: &mut Vec<Problem>) {
    let Some(&(_, known)) = SCHEMA.iter().find(|(p, _)| *p == path) else {
        return;
    };
    for (key, value) in table.iter() {
        let name: &str = key.get_ref();
        if !known.contains(&name) {
            let suggestion =
                suggest(name, known.iter().copied()).or_else(|| swapped(name, known)).or_else(|| plural(name, known));
            problems.push(Problem::UnknownKey {
                span: key.span(),
                key: name.to_string(),
                table: path,
                suggestion,
                known,
            });
            continue;
        }
        descend(path, name, value, problems);
    }
}

/// Walks a known key's value if the schema describes it: a table at `parent.name`, or the
/// tables of an array at `parent.name[]`. The path is the schema's own string, so no path
/// is built for the many values (strings, numbers, tables without a schema) that have none.
fn descend(parent: &'static str, name: &str, value: &Spanned<DeValue<'_>>, problems: &mut Vec<Problem>) {
    match value.get_ref() {
        DeValue::Table(t) => {
            if let Some(path) = schema_path(parent, name, false) {
                walk(path, t, problems);
            }
        }
        DeValue::Array(items) => {
            if let Some(path) = schema_path(parent, name, true) {
                for item in items.iter() {
                    if let DeValue::Table(t) = item.get_ref() {
                        walk(path, t, problems);
                    }
                }
            }
        }
        _ => {}
    }
}

/// The schema path `parent.name` (`name` at the top level), with `[]` appended for an
/// array, if the schema has it.
fn schema_path(parent: &str, name: &str, array: bool) -> Option<&'static str> {
    SCHEMA.iter().map(|&(path, _)| path).find(|path| {
        let rest =
            if parent.is_empty() { Some(*path) } else { path.strip_prefix(parent).and_then(|r| r.strip_prefix('.')) };
        let rest = if array { rest.and_then(|r| r.strip_suffix("[]")) } else { rest };
        rest == Some(name)
    })
}

/// A known key that `name` spells with two neighbouring letters swapped (`titel` for
/// `title`): one slip of the fingers, though two edits apart.
fn swapped(name: &str, known: &[&str]) -> Option<String> {
    let a: Vec<char> = name.chars().collect();
    known.iter().find_map(|k| {
        let b: Vec<char> = k.chars().collect();
        let differ: Vec<usize> = (0..a.len()).filter(|&i| a.len() == b.len() && a[i] != b[i]).collect();
        let one_swap = a.len() == b.len()
            && differ.len() == 2
            && differ[1] == differ[0] + 1
            && a[differ[0]] == b[differ[1]]
            && a[differ[1]] == b[differ[0]];
        one_swap.then(|| k.to_string())
    })
}

/// The plural a singular key stands for: `[[body]]` → `bodies`, `[[constraint]]` →
/// `constraints`, `parameter` → `parameters`.
fn plural(name: &str, known: &[&str]) -> Option<String> {
    let candidates = [format!("{name}s"), format!("{}ies", name.strip_suffix('y').unwrap_or(name))];
    known.iter().find(|k| candidates.iter().any(|c| c == *k)).map(|k| k.to_string())
}
