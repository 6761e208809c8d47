//! CSV of a simulation: one line per recorded step — t, every position and velocity
//! component, then each rigid body's angle and angular velocity (3D: its quaternion as
//! `q.w, q.x, q.y, q.z` and its world ω as `w.x, w.y, w.z`), then λ, C/κ and Ċ/κ per
//! constraint.
//!
//! Numbers are written as their shortest round-trip digits (zmij's), laid out as Rust's
//! `{}` and `{:e}` lay them out, so two identical runs give byte-identical files and a file
//! read back gives the same f64s.
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
    line: Vec<u8>,
    buffer: zmij::Buffer,
}

/// Shortest round-trip digits; scientific notation outside [1e-4, 1e15): the layout of
/// Rust's `{}` and `{:e}`, from the digits the `zmij` crate finds, several times faster than
/// the standard library's formatting (a CSV of a big scene is millions of numbers). The
/// digits are the standard library's but where two shortest strings are equally close to
/// the number, which the two break differently in the last digit (both read back as the
/// same f64; a property test holds it to both).
fn number(out: &mut Vec<u8>, x: f64, buffer: &mut zmij::Buffer) {
    if !x.is_finite() {
        let _ = write!(out, "{x}");
        return;
    }
    // zmij writes `[-]int.frac` from 1e-5 to 1e16 (`1.0` for 1) and `[-]d[.ddd]e±exp`
    // outside: the layout wanted but for `.0` and `e+`, except in [1e-5, 1e-4) and
    // [1e15, 1e16), which are laid out again from the digits.
    let printed = buffer.format_finite(x).as_bytes();
    let display = x == 0.0 || (1e-4..1e15).contains(&x.abs());
    let (mantissa, exponent) = match printed.iter().position(|&c| c == b'e') {
        Some(e) => (&printed[..e], Some(&printed[e + 1..])),
        None => (printed, None),
    };
    match (display, exponent) {
        (true, None) => out.extend_from_slice(mantissa.strip_suffix(b".0").unwrap_or(mantissa)),
        (false, Some(exponent)) => {
            out.extend_from_slice(mantissa);
            out.push(b'e');
            out.extend_from_slice(exponent.strip_prefix(b"+").unwrap_or(exponent));
        }
        _ => relaid(out, printed, display),
    }
}

/// zmij's text of a number `printed` laid out again as `{}` (`display`) or `{:e}` write it.
fn relaid(out: &mut Vec<u8>, printed: &[u8], display: bool) {
    // Its digits d₁d₂…dₙ, without leading or trailing zeros, are x = ±0.d₁d₂…dₙ × 10^point.
    let mut digits = [0u8; 24];
    let (mut n, mut point, mut fraction) = (0, 0i32, false);
    for (i, &c) in printed.iter().enumerate() {
        match c {
            b'0' if n == 0 => point -= i32::from(fraction),
            b'0'..=b'9' if n < digits.len() => {
                digits[n] = c;
                n += 1;
                point += i32::from(!fraction);
            }
            b'.' => fraction = true,
            b'e' => {
                point += exponent(&printed[i + 1..]);
                break;
            }
            _ => {}
        }
    }
    while n > 0 && digits[n - 1] == b'0' {
        n -= 1;
    }
    let digits = &digits[..n];
    if printed.first() == Some(&b'-') {
        out.push(b'-');
    }
    let zeros = |out: &mut Vec<u8>, k: i32| out.resize(out.len() + k.max(0) as usize, b'0');
    if digits.is_empty() {
        out.push(b'0');
    } else if display {
        match usize::try_from(point) {
            Ok(0) | Err(_) => {
                out.extend_from_slice(b"0.");
                zeros(out, -point);
                out.extend_from_slice(digits);
            }
            Ok(p) if p >= n => {
                out.extend_from_slice(digits);
                zeros(out, point - n as i32);
            }
            Ok(p) => {
                out.extend_from_slice(&digits[..p]);
                out.push(b'.');
                out.extend_from_slice(&digits[p..]);
            }
        }
    } else {
        out.push(digits[0]);
        if n > 1 {
            out.push(b'.');
            out.extend_from_slice(&digits[1..]);
        }
        out.push(b'e');
        let e = point - 1;
        if e < 0 {
            out.push(b'-');
        }
        let e = e.unsigned_abs();
        for place in [100, 10, 1] {
            if e >= place || place == 1 {
                out.push(b'0' + (e / place % 10) as u8);
            }
        }
    }
}

/// The exponent zmij writes after its `e`: an optional sign, then digits.
fn exponent(text: &[u8]) -> i32 {
    let (sign, digits) = match text {
        [b'-', rest @ ..] => (-1, rest),
        [b'+', rest @ ..] => (1, rest),
        rest => (1, rest),
    };
    sign * digits.iter().fold(0, |e, &d| e * 10 + i32::from(d.wrapping_sub(b'0')))
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
        Ok(CsvWriter {
            out,
            every: every.max(1),
            last,
            bodies: system.bodies.len(),
            line: Vec::new(),
            buffer: zmij::Buffer::new(),
        })
    }

    /// Writes the frame if its step is due.
    pub fn frame(&mut self, frame: &Frame) -> std::io::Result<()> {
        if !frame.step.is_multiple_of(self.every) && frame.step != self.last {
            return Ok(());
        }
        let dim = frame.rows.dim;
        self.line.clear();
        number(&mut self.line, frame.time, &mut self.buffer);
        for (q, v) in frame.position.iter().zip(frame.velocity).take(self.bodies) {
            for &x in q[..dim].iter().chain(&v[..dim]) {
                self.line.push(b',');
                number(&mut self.line, x, &mut self.buffer);
            }
        }
        // A rigid body's angle and angular velocity (component 0 of its slot); in 3D its
        // orientation and the world ω of the first of its three slots.
        if frame.orientations.is_empty() {
            for (q, v) in frame.position.iter().zip(frame.velocity).skip(self.bodies) {
                for x in [q[0], v[0]] {
                    self.line.push(b',');
                    number(&mut self.line, x, &mut self.buffer);
                }
            }
        } else {
            for (q, v) in frame.orientations.iter().zip(frame.velocity[self.bodies..].iter().step_by(3)) {
                for &x in q.iter().chain(v) {
                    self.line.push(b',');
                    number(&mut self.line, x, &mut self.buffer);
                }
            }
        }
        for (row, &lambda) in frame.rows.rows.iter().zip(frame.lambda) {
            for x in [lambda, row.value, row.rate] {
                self.line.push(b',');
                number(&mut self.line, x, &mut self.buffer);
            }
        }
        self.line.push(b'\n');
        self.out.write_all(&self.line)
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// What `number` must write: the standard library's shortest round-trip formatting.
    fn by_std(x: f64) -> String {
        let a = x.abs();
        if x == 0.0 || (1e-4..1e15).contains(&a) { format!("{x}") } else { format!("{x:e}") }
    }

    fn written(x: f64) -> String {
        let mut out = Vec::new();
        number(&mut out, x, &mut zmij::Buffer::new());
        String::from_utf8(out).expect("ASCII")
    }

    #[test]
    fn numbers_at_the_edges_are_written_as_the_standard_library_writes_them() {
        let edges = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            100.0,
            0.5,
            1e-4,
            9.999999999999999e-5,
            1.5e-5,
            1e15,
            999999999999999.9,
            1e16,
            1.234e20,
            123456789012345.0,
            0.1 + 0.2,
            1e-7,
            5e-324,
            -5e-324,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
            1e21,
            1e22,
            1e23,
            -2.5e-300,
            2f64.powi(53),
            2f64.powi(-1074),
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for x in edges {
            assert_eq!(written(x), by_std(x), "{x:?}");
        }
    }

    /// Every text zmij might write for a number is laid out as the standard library does,
    /// whichever of its two forms it chose.
    #[test]
    fn either_form_of_zmij_is_laid_out_again() {
        let cases: [(&str, bool, &str); 8] = [
            ("1.5e+2", true, "150"),
            ("1.5e-3", true, "0.0015"),
            ("-1.25e+0", true, "-1.25"),
            ("0.000015", false, "1.5e-5"),
            ("1000000000000000.0", false, "1e15"),
            ("-1234000000000000.0", false, "-1.234e15"),
            ("1e+300", false, "1e300"),
            ("0.0", true, "0"),
        ];
        for (zmij, display, wanted) in cases {
            let mut out = Vec::new();
            relaid(&mut out, zmij.as_bytes(), display);
            assert_eq!(String::from_utf8_lossy(&out), wanted, "{zmij}");
        }
    }

    /// `number`'s text against the standard library's: the same length (so the same layout
    /// and as many digits), the same but for the last digit by one where the number is
    /// halfway between two shortest strings, and read back as the same f64.
    fn agrees(x: f64) -> Result<(), TestCaseError> {
        let (ours, theirs) = (written(x), by_std(x));
        prop_assert_eq!(ours.len(), theirs.len(), "{:?}: {} against {}", x, ours, theirs);
        if ours != theirs {
            let last = |s: &str| s.split('e').next().and_then(|m| m.bytes().last()).unwrap_or(b'0');
            let differing = ours.bytes().zip(theirs.bytes()).filter(|(a, b)| a != b).count();
            prop_assert!(
                differing == 1 && last(&ours).abs_diff(last(&theirs)) == 1,
                "{:?}: {} against {}",
                x,
                ours,
                theirs
            );
        }
        if x.is_finite() {
            prop_assert_eq!(ours.parse::<f64>().map(f64::to_bits), Ok(x.to_bits()), "{} read back", ours);
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]
        /// Any f64, by its bits: every exponent, subnormals, and values near powers of ten.
        #[test]
        fn any_number_is_written_as_the_standard_library_writes_it(bits in any::<u64>(), k in -330i32..310) {
            agrees(f64::from_bits(bits))?;
            agrees(10f64.powi(k) * (1.0 + (bits % 1000) as f64 * 1e-3))?;
        }
    }
}
