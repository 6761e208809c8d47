//! Checking a derived formula in your own tests: load a constraint file, derive, and assert
//! that lagrange's constraint force equals the one you worked out, on the constraint manifold.
//!
//! `cargo run --example check_formula`. In a test, the same lines go in a `#[test]` function.

use lagrange::check::{CheckError, Checked};

fn main() -> Result<(), CheckError> {
    // The tension of a pendulum hinged at p, as a mechanics text writes it (l² where lagrange
    // has |r − p|²: equal wherever the rod holds, which is where the check looks).
    Checked::load("constraints/pendulum_pivot.toml")?
        .assert_force("bob", "-(m*dot(v,v) + dot(F, r - p))/l^2 * (r - p)")
        .assert_lambda("rod", "-(m*dot(v,v) + dot(F, r - p))/(2*l^2)");

    // Without panicking: the outcome says how it was judged, or where it differs.
    let mut wire = Checked::load("constraints/bead_on_wire.toml")?;
    let outcome = wire.force("bead", "-(m*dot(v,v) - dot(F,r))/l^2 * r")?;
    println!("{outcome}");
    Ok(())
}
