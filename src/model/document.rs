//! The spanned TOML document → the raw structs of a file, field by field.
//!
//! Design note: serde's derived `Deserialize` stops at the first value of the wrong type
//! (a string where a number belongs, a mass written as a table), and its messages name Rust
//! types ("data did not match any variant of untagged enum RawMass"). A person fixing a file
//! wants every problem at once, in the file's words. So the text is parsed once into toml's
//! spanned tree ([`DeTable`]), unknown keys are reported by `model::keys`, and the raw
//! structs are filled here by hand: each field that is missing or of the wrong type is one
//! [`Problem`] at its span, and reading goes on. What cannot be read is left out (`None`, or
//! the entry skipped) — except where leaving it out would breed follow-on messages: a bad
//! parameter keeps its name (as a placeholder value of its shape), a body keeps its symbols
//! (placeholders for unreadable ones, see `RawBody`), a constraint without `expr` keeps its
//! name for `[[expect]]`. A file with any problem derives nothing, so placeholders are never
//! used for numbers.
//!
//! Numbers are rejected here when they are not finite (`nan`, `inf` are valid TOML floats,
//! never valid values of a constraint file). Deep nesting is refused by toml's parser (a
//! depth limit, reported with its span), so nothing here recurses on the input's depth.
//!
//! Not here: meaning (symbols, dimensions, expressions — `model::file`, `scene`, `expect`).

use super::keys::unknown_keys;
use super::problem::{Problem, shown};
use super::raw::{
    QUANTITIES, RawBody, RawConstraint, RawExpect, RawExpected, RawFile, RawMass, RawRigid, RawScene, RawValue, Text,
};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt::{self, Display};
use toml::Spanned;
use toml::de::{DeTable, DeValue};

type Value<'i> = Spanned<DeValue<'i>>;

/// Syntax errors shown at most (after a few, the parser's recovery is mostly guessing).
const MAX_SYNTAX_ERRORS: usize = 8;

/// Parses `text` and reads it into a [`RawFile`]; every problem goes to `problems`.
/// `None` when the text is not TOML: then the syntax errors (toml's recovering parser finds
/// them all; the first `MAX_SYNTAX_ERRORS` are kept) are the problems, and nothing else is
/// judged — the tree after a syntax error is the parser's guess, and complaints about it
/// would mislead.
pub fn read<'i>(text: &'i str, problems: &mut Vec<Problem>) -> Option<RawFile<'i>> {
    let (root, errors) = DeTable::parse_recoverable(text);
    if !errors.is_empty() {
        for e in errors.iter().take(MAX_SYNTAX_ERRORS) {
            problems.push(Problem::Syntax { span: e.span(), message: syntax_message(e.message()) });
        }
        return None;
    }
    problems.extend(unknown_keys(root.get_ref()));
    let mut r = Reader { problems, bodies_read: 0 };
    let table = root.get_ref();
    let dimension = match table.get("dimension") {
        Some(v) => r.integer(v, "`dimension`"),
        None => {
            r.problems.push(Problem::NoDimension { span: 0..0 });
            None
        }
    };
    let file = RawFile {
        title: table.get("title").and_then(|v| r.string(v, "`title`")),
        dimension,
        parameters: table.get("parameters").map(|v| r.values(v, "[parameters]", true)).unwrap_or_default(),
        definitions: table.get("definitions").map(|v| r.strings(v, "[definitions]")).unwrap_or_default(),
        bodies: r.array_of_tables(table.get("bodies"), "bodies", Reader::body),
        constraints: r.array_of_tables(table.get("constraints"), "constraints", Reader::constraint),
        constraints_written: table.contains_key("constraints"),
        scene: table.get("scene").and_then(|v| r.scene(v)),
        expect: r.array_of_tables(table.get("expect"), "expect", Reader::expect),
    };
    Some(file)
}

/// toml's messages for its limits, said in the file's terms.
fn syntax_message(message: &str) -> String {
    let message = message.trim_end();
    if message.contains("recurse") || message.contains("recursion") {
        "the file nests arrays or tables too deeply (toml's depth limit)".into()
    } else {
        message.to_string()
    }
}

/// "a string", "an integer", … for messages.
fn kind(v: &DeValue<'_>) -> &'static str {
    match v {
        DeValue::String(_) => "a string",
        DeValue::Integer(_) => "an integer",
        DeValue::Float(_) => "a number",
        DeValue::Boolean(_) => "a boolean",
        DeValue::Datetime(_) => "a date",
        DeValue::Array(_) => "an array",
        DeValue::Table(_) => "a table",
    }
}

/// A key as written (borrowed from the text, like every string read here).
fn spanned_key<'i>(key: &Spanned<Cow<'i, str>>) -> Text<'i> {
    Spanned::new(key.span(), key.get_ref().clone())
}

/// A label for messages, written out only when a message is: reading a good file builds
/// no label text (formatting every field's label was a tenth of loading a small file).
struct Label<F: Fn(&mut fmt::Formatter<'_>) -> fmt::Result>(F);

impl<F: Fn(&mut fmt::Formatter<'_>) -> fmt::Result> Display for Label<F> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        (self.0)(f)
    }
}

struct Reader<'p> {
    problems: &'p mut Vec<Problem>,
    /// Bodies read so far, to name placeholders.
    bodies_read: usize,
}

impl Reader<'_> {
    fn wrong<W: Display + ?Sized>(&mut self, v: &Value<'_>, what: &W, expected: &str) {
        self.problems.push(Problem::WrongType {
            span: v.span(),
            what: what.to_string(),
            expected: expected.to_string(),
            found: kind(v.get_ref()),
        });
    }

    fn missing<W: Display + ?Sized>(&mut self, table: &Value<'_>, what: &W, key: &str, example: &'static str) {
        self.problems.push(Problem::MissingField {
            span: table.span(),
            what: what.to_string(),
            key: key.to_string(),
            example,
        });
    }

    fn string<'i, W: Display + ?Sized>(&mut self, v: &Value<'i>, what: &W) -> Option<Text<'i>> {
        match v.get_ref() {
            DeValue::String(s) => Some(Spanned::new(v.span(), s.clone())),
            _ => {
                self.wrong(v, what, "a string");
                None
            }
        }
    }

    /// A number as written (integers too), not yet checked for finiteness.
    fn raw_number(v: &DeValue<'_>) -> Option<f64> {
        match v {
            DeValue::Integer(i) => i64::from_str_radix(i.as_str(), i.radix()).ok().map(|i| i as f64),
            DeValue::Float(f) => f.as_str().parse().ok(),
            _ => None,
        }
    }

    /// A finite number.
    fn number<W: Display + ?Sized>(&mut self, v: &Value<'_>, what: &W) -> Option<Spanned<f64>> {
        match Self::raw_number(v.get_ref()) {
            Some(x) if x.is_finite() => Some(Spanned::new(v.span(), x)),
            Some(x) => {
                // As TOML spells it (`nan`, `inf`, `-inf`).
                self.problems.push(Problem::NotFinite { span: v.span(), what: what.to_string(), shown: shown(x) });
                None
            }
            None => {
                self.wrong(v, what, "a number");
                None
            }
        }
    }

    fn integer<W: Display + ?Sized>(&mut self, v: &Value<'_>, what: &W) -> Option<Spanned<i64>> {
        match v.get_ref() {
            DeValue::Integer(i) => match i64::from_str_radix(i.as_str(), i.radix()) {
                Ok(n) => Some(Spanned::new(v.span(), n)),
                Err(_) => {
                    self.wrong(v, what, "2 or 3");
                    None
                }
            },
            _ => {
                self.wrong(v, what, "an integer (2 or 3)");
                None
            }
        }
    }

    /// A number or a vector of finite numbers; each bad component is reported.
    fn value<W: Display + ?Sized>(&mut self, v: &Value<'_>, what: &W) -> Option<Spanned<RawValue>> {
        let before = self.problems.len();
        let value = self.value_or_placeholder(v, what)?;
        (self.problems.len() == before).then_some(value)
    }

    /// Like [`Reader::value`], but a number or an array that is reported as bad still gives
    /// a value of its shape (bad numbers as 0), so the name it declares stays declared and
    /// its uses are not reported again as unknown. `None` for other kinds (reported).
    fn value_or_placeholder<W: Display + ?Sized>(&mut self, v: &Value<'_>, what: &W) -> Option<Spanned<RawValue>> {
        match v.get_ref() {
            DeValue::Array(items) => {
                let xs: Vec<f64> = items
                    .iter()
                    .map(|x| self.number(x, &format_args!("each component of {what}")).map_or(0.0, |x| *x.get_ref()))
                    .collect();
                Some(Spanned::new(v.span(), RawValue::Vector(xs)))
            }
            DeValue::Integer(_) | DeValue::Float(_) => {
                let x = self.number(v, what).map_or(0.0, |x| *x.get_ref());
                Some(Spanned::new(v.span(), RawValue::Number(x)))
            }
            _ => {
                self.wrong(v, what, "a number or a vector of numbers");
                None
            }
        }
    }

    fn table<'a, 'i, W: Display + ?Sized>(&mut self, v: &'a Value<'i>, what: &W) -> Option<&'a DeTable<'i>> {
        match v.get_ref() {
            DeValue::Table(t) => Some(t),
            _ => {
                self.wrong(v, what, "a table");
                None
            }
        }
    }

    /// `name = number or vector` entries (parameters, initial values, `at`). A bad value is
    /// reported and kept as a placeholder of its shape (see [`Reader::value_or_placeholder`]);
    /// a bad parameter of no shape (a string, a table) is kept as a scalar, since the name
    /// is declared either way.
    fn values<'i>(&mut self, v: &Value<'i>, what: &str, declares: bool) -> BTreeMap<Text<'i>, Spanned<RawValue>> {
        let Some(t) = self.table(v, what) else {
            return BTreeMap::new();
        };
        t.iter()
            .filter_map(|(k, x)| {
                let name = spanned_key(k);
                let value = self.value_or_placeholder(x, &format_args!("`{}` in {what}", name.get_ref()));
                let value = match value {
                    None if declares => Spanned::new(x.span(), RawValue::Number(0.0)),
                    value => value?,
                };
                Some((name, value))
            })
            .collect()
    }

    /// `name = "text"` entries (definitions, forces).
    fn strings<'i>(&mut self, v: &Value<'i>, what: &str) -> BTreeMap<Text<'i>, Text<'i>> {
        let Some(t) = self.table(v, what) else {
            return BTreeMap::new();
        };
        t.iter()
            .filter_map(|(k, x)| {
                let name = spanned_key(k);
                let text = self.string(x, &format_args!("`{}` in {what}", name.get_ref()))?;
                Some((name, text))
            })
            .collect()
    }

    /// `[[key]]` entries, each read by `item` (which reports its own problems).
    fn array_of_tables<'i, T>(
        &mut self,
        v: Option<&Value<'i>>,
        key: &str,
        item: impl Fn(&mut Self, &Value<'i>, &DeTable<'i>) -> Option<T>,
    ) -> Vec<Spanned<T>> {
        let Some(v) = v else {
            return Vec::new();
        };
        let DeValue::Array(items) = v.get_ref() else {
            self.wrong(v, &format_args!("`{key}`"), &format!("an array of tables (`[[{key}]]` sections)"));
            return Vec::new();
        };
        let mut out = Vec::new();
        for x in items.iter() {
            match x.get_ref() {
                DeValue::Table(t) => {
                    if let Some(value) = item(self, x, t) {
                        out.push(Spanned::new(x.span(), value));
                    }
                }
                _ => self.wrong(x, &format_args!("each entry of `{key}`"), "a table"),
            }
        }
        out
    }

    /// A required string field of a table.
    fn field<'i, W: Display + ?Sized>(
        &mut self,
        at: &Value<'_>,
        t: &DeTable<'i>,
        what: &W,
        key: &str,
        example: &'static str,
    ) -> Option<Text<'i>> {
        match t.get(key) {
            Some(v) => self.string(v, &format_args!("`{key}` of {what}")),
            None => {
                self.missing(at, what, key, example);
                None
            }
        }
    }

    fn body<'i>(&mut self, at: &Value<'i>, t: &DeTable<'i>) -> Option<RawBody<'i>> {
        let label = Label(|f| match t.get("name").map(|v| v.get_ref()) {
            Some(DeValue::String(s)) => write!(f, "body `{s}`"),
            _ => f.write_str("a body"),
        });
        let name = self.field(at, t, "a body", "name", "\"bead\"");
        // Placeholders for unreadable symbols (see `RawBody`): the problem is reported, the
        // body stays declared.
        self.bodies_read += 1;
        let n = self.bodies_read;
        let mut placeholders = Vec::new();
        let mut symbol = |r: &mut Self, key: &str, example: &'static str| {
            r.field(at, t, &label, key, example).unwrap_or_else(|| {
                let placeholder = format!("unread_{key}_{n}");
                placeholders.push(placeholder.clone());
                Spanned::new(at.span(), Cow::Owned(placeholder))
            })
        };
        let position = symbol(self, "position", "\"r\"");
        let velocity = symbol(self, "velocity", "\"v\"");
        let acceleration = symbol(self, "acceleration", "\"a\"");
        let force = symbol(self, "force", "\"F\"");
        let mass = match t.get("mass") {
            None => {
                self.missing(at, &label, "mass", "\"m\"");
                Spanned::new(at.span(), RawMass::Number(1.0))
            }
            Some(v) => self.mass_like(v, &format_args!("the mass of {label}")),
        };
        // A body with an `orientation` is rigid, and then has the rotational keys too.
        let rigid = if t.contains_key("orientation") {
            let orientation = symbol(self, "orientation", "\"th\"");
            let angular_velocity = symbol(self, "angular_velocity", "\"w\"");
            let angular_acceleration = symbol(self, "angular_acceleration", "\"alpha\"");
            let torque = symbol(self, "torque", "\"T\"");
            let inertia = t.get("inertia").map(|v| self.mass_like(v, &format_args!("the inertia of {label}")));
            Some(RawRigid { orientation, angular_velocity, angular_acceleration, torque, inertia })
        } else {
            // The rotational keys mean nothing without an orientation: say so, not ignore them.
            for key in ["angular_velocity", "angular_acceleration", "inertia", "torque"] {
                if let Some(v) = t.get(key) {
                    self.problems.push(Problem::RigidKeyWithoutOrientation {
                        span: v.span(),
                        what: label.to_string(),
                        key,
                    });
                }
            }
            None
        };
        Some(RawBody { name: name?, position, velocity, acceleration, mass, force, rigid, placeholders })
    }

    /// A mass or an inertia: a number or a symbol's name (an inertia also a vector of
    /// numbers, the principal moments). Finiteness and sign are judged in `model::file`
    /// with the other mass checks.
    fn mass_like<'i, W: Display + ?Sized>(&mut self, v: &Value<'i>, what: &W) -> Spanned<RawMass<'i>> {
        match v.get_ref() {
            DeValue::String(s) => Spanned::new(v.span(), RawMass::Symbol(s.clone())),
            DeValue::Array(items) => {
                let xs: Vec<f64> = items
                    .iter()
                    .map(|x| {
                        self.number(x, &format_args!("each component of {what}")).map_or(f64::NAN, |x| *x.get_ref())
                    })
                    .collect();
                Spanned::new(v.span(), RawMass::Vector(xs))
            }
            DeValue::Integer(_) | DeValue::Float(_) => {
                Spanned::new(v.span(), RawMass::Number(Self::raw_number(v.get_ref()).unwrap_or(f64::NAN)))
            }
            _ => {
                self.wrong(v, what, "a number or a symbol name (a string)");
                Spanned::new(v.span(), RawMass::Number(1.0))
            }
        }
    }

    fn constraint<'i>(&mut self, at: &Value<'i>, t: &DeTable<'i>) -> Option<RawConstraint<'i>> {
        let label = Label(|f| match t.get("name").map(|v| v.get_ref()) {
            Some(DeValue::String(s)) => write!(f, "constraint `{s}`"),
            _ => f.write_str("a constraint"),
        });
        let name = self.field(at, t, "a constraint", "name", "\"wire\"");
        let expr = self.field(at, t, &label, "expr", "\"dot(r,r) = l^2\"");
        Some(RawConstraint { name: name?, expr })
    }

    fn scene<'i>(&mut self, v: &Value<'i>) -> Option<Spanned<RawScene<'i>>> {
        let t = self.table(v, "[scene]")?;
        let mut number = |key: &str| t.get(key).and_then(|x| self.number(x, &format_args!("`{key}` in [scene]")));
        let dt = number("dt");
        let duration = number("duration");
        let restitution = number("restitution");
        let scene = RawScene {
            initial: t.get("initial").map(|x| self.values(x, "[scene] initial", false)).unwrap_or_default(),
            forces: t.get("forces").map(|x| self.strings(x, "[scene] forces")).unwrap_or_default(),
            dt,
            duration,
            restitution,
        };
        Some(Spanned::new(v.span(), scene))
    }

    fn expect<'i>(&mut self, _at: &Value<'i>, t: &DeTable<'i>) -> Option<RawExpect<'i>> {
        let mut entries = |key: &str| t.get(key).map(|x| self.expected(x, key)).unwrap_or_default();
        let force = entries("force");
        let torque = entries("torque");
        let lambda = entries("lambda");
        let c_dot = entries("C_dot");
        let c_ddot = entries("C_ddot");
        let a = entries("A");
        let b = entries("b");
        let at = t.get("at").and_then(|x| {
            let values = self.values(x, "`at`", false);
            matches!(x.get_ref(), DeValue::Table(_)).then(|| Spanned::new(x.span(), values))
        });
        let tolerance = t.get("tolerance").and_then(|x| match Self::raw_number(x.get_ref()) {
            // Sign, zero and NaN are judged with the rest of the entry (`model::expect`).
            Some(n) => Some(Spanned::new(x.span(), n)),
            None => {
                self.wrong(x, "`tolerance`", "a number");
                None
            }
        });
        let note = t.get("note").and_then(|x| self.string(x, "`note`")).map(|s| s.into_inner().into_owned());
        let written = QUANTITIES.iter().filter(|k| t.contains_key(**k)).count();
        Some(RawExpect { force, torque, lambda, c_dot, c_ddot, a, b, at, tolerance, written, note })
    }

    /// The `name = expected` entries of one quantity of an `[[expect]]`.
    fn expected<'i>(&mut self, v: &Value<'i>, key: &str) -> BTreeMap<Text<'i>, Spanned<RawExpected<'i>>> {
        let what = Label(|f| write!(f, "`{key}` in [[expect]]"));
        let Some(t) = self.table(v, &what) else {
            return BTreeMap::new();
        };
        let mut out = BTreeMap::new();
        for (k, x) in t.iter() {
            let name = spanned_key(k);
            let label = Label(|f| write!(f, "the expected `{key}` of `{}`", name.get_ref()));
            let value = match x.get_ref() {
                DeValue::String(s) => Some(RawExpected::Formula(s.clone())),
                DeValue::Integer(_) | DeValue::Float(_) | DeValue::Array(_) => {
                    self.value(x, &label).map(|v| match v.into_inner() {
                        RawValue::Number(n) => RawExpected::Number(n),
                        RawValue::Vector(xs) => RawExpected::Vector(xs),
                    })
                }
                _ => {
                    self.wrong(x, &label, "a formula (a string), a number or a vector");
                    None
                }
            };
            if let Some(value) = value {
                out.insert(name, Spanned::new(x.span(), value));
            }
        }
        out
    }
}
