//! CSV of a simulation: one line per recorded step — t, every position and velocity
//! component, then each rigid body's angle and angular velocity (3D: its quaternion as
//! `q.w, q.x, q.y, q.z` and its world ω as `w.x, w.y, w.z`), then λ, C/κ and Ċ/κ per
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
            let name = |s| system.graph.symbol(s).name.clone();
            if rigid.nodes.axes.is_some() {
                for c in ["w", "x", "y", "z"] {
                    header.push(',');
                    header.push_str(&field(&format!("{}.{c}", name(rigid.orientation))));
                }
                for axis in AXES {
                    header.push(',');
                    header.push_str(&field(&format!("{}.{axis}", name(rigid.angular_velocity))));
                }
            } else {
                for s in [rigid.orientation, rigid.angular_velocity] {
                    let _ = write!(header, ",{}", name(s));
                }
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
        for (q, v) in frame.position.iter().zip(frame.velocity).take(self.bodies) {
            for &x in q[..dim].iter().chain(&v[..dim]) {
                self.line.push(',');
                number(&mut self.line, x);
            }
        }
        // A rigid body's angle and angular velocity (component 0 of its slot); in 3D its
        // orientation and the world ω of the first of its three slots.
        if frame.orientations.is_empty() {
            for (q, v) in frame.position.iter().zip(frame.velocity).skip(self.bodies) {
                for x in [q[0], v[0]] {
                    self.line.push(',');
                    number(&mut self.line, x);
                }
            }
        } else {
            for (q, v) in frame.orientations.iter().zip(frame.velocity[self.bodies..].iter().step_by(3)) {
                for &x in q.iter().chain(v) {
                    self.line.push(',');
                    number(&mut self.line, x);
                }
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
