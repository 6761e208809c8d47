//! Writes the constraint file of an N-link chain hanging from the origin to stdout.
//!
//! `cargo run --example chain -- 50 > chain_50.toml`; the links have length `l` and the
//! bodies mass `m`; the chain starts straight along +x.

fn main() {
    let n: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(5);
    print!("{}", lagrange::scenario::chain(n));
}
