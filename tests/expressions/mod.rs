//! Random expression trees over a 3D playground system, shared by `tests/tape.rs` (the
//! tape against the reference interpreter) and `tests/jit.rs` (the compiled tape against
//! the tape), with the deterministic generator that picks them.

#![allow(dead_code)] // each test crate uses its own part of it

use lagrange::expr::Ty;
use lagrange::model::system::{BodySpec, MassSpec, SystemBuilder};

/// A small deterministic generator (xorshift), so failures reproduce.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// A 3D system with every kind of symbol, for random expressions.
pub fn playground() -> lagrange::model::system::System {
    let mut b = SystemBuilder::new("play", 3).expect("3D");
    b.parameter("l", Ty::Scalar).expect("l");
    b.parameter("k", Ty::Scalar).expect("k");
    b.parameter("u", Ty::Vector).expect("u");
    b.body(&BodySpec {
        name: "p",
        position: "r",
        velocity: "v",
        acceleration: "a",
        force: "F",
        mass: MassSpec::Symbol("m"),
    })
    .expect("body");
    b.constraint("c", "dot(r, r) = l^2").expect("constraint");
    b.finish()
}

/// A random scalar expression of at most `depth` levels.
pub fn scalar(rng: &mut Rng, depth: u32) -> String {
    if depth == 0 || rng.below(4) == 0 {
        return ["l", "k", "m", "t", "2", "0.5", "3", "r.x", "v.z"][rng.below(9)].to_string();
    }
    let d = depth - 1;
    match rng.below(16) {
        0 => format!("({} + {})", scalar(rng, d), scalar(rng, d)),
        1 => format!("({} - {})", scalar(rng, d), scalar(rng, d)),
        2 => format!("({}) * ({})", scalar(rng, d), scalar(rng, d)),
        3 => format!("({}) / ({})", scalar(rng, d), scalar(rng, d)),
        4 => format!("({})^{}", scalar(rng, d), ["2", "3", "-1", "-2", "5"][rng.below(5)]),
        // Non-integer powers of a positive base: a base that is zero in exact arithmetic
        // (say `cross(F, r)·r`) rounds to ±tiny, and a negative base has no real power.
        15 => format!("(1 + ({})^2)^{}", scalar(rng, d), ["0.5", "1.5", "-0.5"][rng.below(3)]),
        5 => format!("dot({}, {})", vector(rng, d), vector(rng, d)),
        6 => format!("norm({})", vector(rng, d)),
        7 => format!("{}({})", ["sin", "cos", "tan", "atan", "exp", "sqrt", "ln"][rng.below(7)], scalar(rng, d)),
        8 => format!("atan2({}, {})", scalar(rng, d), scalar(rng, d)),
        9 => format!("({}).{}", vector(rng, d), ["x", "y", "z"][rng.below(3)]),
        10 => format!("-({})", scalar(rng, d)),
        11 => format!("(1 + ({})^2)^(sin({}))", scalar(rng, d), scalar(rng, d)),
        12 => format!("{}(sin({}) / 2)", ["asin", "acos"][rng.below(2)], scalar(rng, d)),
        _ => format!("({}) * ({}) - ({})", scalar(rng, d), scalar(rng, d), scalar(rng, d)),
    }
}

/// A random vector expression of at most `depth` levels.
pub fn vector(rng: &mut Rng, depth: u32) -> String {
    if depth == 0 || rng.below(4) == 0 {
        return ["r", "v", "F", "u", "[1, 0, 0]"][rng.below(5)].to_string();
    }
    let d = depth - 1;
    match rng.below(6) {
        0 => format!("({} + {})", vector(rng, d), vector(rng, d)),
        1 => format!("({} - {})", vector(rng, d), vector(rng, d)),
        2 => format!("({}) * ({})", scalar(rng, d), vector(rng, d)),
        3 => format!("cross({}, {})", vector(rng, d), vector(rng, d)),
        4 => format!("({}) / ({})", vector(rng, d), scalar(rng, d)),
        _ => format!("[{}, {}, {}]", scalar(rng, d), scalar(rng, d), scalar(rng, d)),
    }
}
