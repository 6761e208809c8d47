//! CSV of a simulation: one line per recorded step — t, every position and velocity
//! component, then each rigid body's angle and angular velocity, then λ, C/κ and Ċ/κ per
//! constraint.
//!
//! Numbers are written with Rust's shortest round-trip formatting, so two identical runs
//! give byte-identical files and a file read back gives the same f64s.
//!
//! The header is built from the file's names, so each field is quoted where it needs it
//! and defused where a spreadsheet would read it as a formula ([`field`]).
//!
//! Not here: opening files (the caller passes any `io::Write`), the run loop.

use crate::model::system::System;
use crate::numeric::simulate::Frame;
use std::fmt::Write as _;
use std::io::Write;

/// Writes frames of a run of `system` to `out`, every `every`-th step (and the last).
pub struct CsvWriter<W: Write> {
    out: W,
    every: u64,
    last: u64,
    /// The number of bodies: the frame's slots past them are rigid bodies' angles.
    bodies: usize,
    line: String,
}

/// Shortest round-trip digits; scientific notation outside [1e-4, 1e15).
fn number(out: &mut String, x: f64) {
    let a = x.abs();
    let _ = if x == 0.0 || (1e-4..1e15).contains(&a) { write!(out, "{x}") } else { write!(out, "{x:e}") };
}

const AXES: [&str; 3] = ["x", "y", "z"];

/// A header field made of a file's names, safe in any reader: quoted (RFC 4180, `"`
/// doubled) when it holds a `,`, a quote or a line break, and with a `'` in front when it
/// begins with `=`, `+`, `-` or `@`, which a spreadsheet would run as a formula.
pub fn field(name: &str) -> String {
    let defused = if name.starts_with(['=', '+', '-', '@']) { format!("'{name}") } else { name.to_string() };
    if defused.contains([',', '"', '\n', '\r']) { format!("\"{}\"", defused.replace('"', "\"\"")) } else { defused }
}

impl<W: Write> CsvWriter<W> {
    /// Writes the header. `last` is the final step, always written.
    pub fn new(system: &System, mut out: W, every: u64, last: u64) -> std::io::Result<CsvWriter<W>> {
        let dim = system.dim();
        let mut header = String::from("t");
        for body in &system.bodies {
            for s in [body.position, body.velocity] {
                for axis in &AXES[..dim] {
                    header.push(',');
                    header.push_str(&field(&format!("{}.{axis}", system.graph.symbol(s).name)));
                }
            }
        }
        for rigid in system.bodies.iter().filter_map(|b| b.rigid.as_ref()) {
            for s in [rigid.orientation, rigid.angular_velocity] {
                let _ = write!(header, ",{}", system.graph.symbol(s).name);
            }
        }
        for c in &system.constraints {
            for what in ["lambda", "C", "Cdot"] {
                header.push(',');
                header.push_str(&field(&format!("{what}_{}", c.name)));
            }
        }
        writeln!(out, "{header}")?;
        Ok(CsvWriter { out, every: every.max(1), last, bodies: system.bodies.len(), line: String::new() })
    }

    /// Writes the frame if its step is due.
    pub fn frame(&mut self, frame: &Frame) -> std::io::Result<()> {
        if !frame.step.is_multiple_of(self.every) && frame.step != self.last {
            return Ok(());
        }
        let dim = frame.rows.dim;
        self.line.clear();
        number(&mut self.line, frame.time);
        for (slot, (q, v)) in frame.position.iter().zip(frame.velocity).enumerate() {
            // A body's components, or a rigid body's angle and angular velocity (component 0).
            let n = if slot < self.bodies { dim } else { 1 };
            for &x in q[..n].iter().chain(&v[..n]) {
                self.line.push(',');
                number(&mut self.line, x);
            }
        }
        for (row, &lambda) in frame.rows.rows.iter().zip(frame.lambda) {
            for x in [lambda, row.value, row.rate] {
                self.line.push(',');
                number(&mut self.line, x);
            }
        }
        self.line.push('\n');
        self.out.write_all(self.line.as_bytes())
    }

    /// The underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }

    /// Flushes what was written (also on a failed run).
    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}
