//! The article's bead, from text to formula to number, through the library: load a constraint
//! file, derive it, print λ and the force as a person writes them, and solve at a state.
//! This is also the crate's front-page example (`src/lib.rs` includes it as a doc test).
//!
//! `cargo run --example derive_bead`.

use lagrange::numeric::rescale::solve_at;
use lagrange::numeric::solve::{Settings, Status};
use lagrange::report::derivation::{Format, document};
use lagrange::{DeriveOptions, Scenario, derive_with, load};

/// The bead on a circular wire of radius l, under gravity (`constraints/bead_on_wire.toml`
/// without its comments and checks).
const BEAD: &str = r#"
title = "Bead on a circular wire"
dimension = 2

[parameters]
l = 2.0
m = 1.0
g = [0.0, -9.81]

[[bodies]]
name = "bead"
position = "r"
velocity = "v"
acceleration = "a"
mass = "m"
force = "F"

[[constraints]]
name = "wire"
expr = "dot(r,r) = l^2"

[scene]
initial = { r = [2.0, 0.0], v = [0.0, 3.0] }
forces = { F = "m*g" }
"#;

fn main() {
    let loaded = load(BEAD).expect("a valid file");

    // Symbols: C, Ċ, C̈, ∇C, A, b, λ and the force, in the article's form.
    let derivation = derive_with(&loaded.system, DeriveOptions { document: true, steps: false }).expect("it derives");
    let text = document(&loaded.system, &derivation, Format::Text, false).expect("a document");
    assert!(text.contains("λ = −(m v·v + F·r)/(r·r)"), "{text}");
    println!("{text}");

    // Numbers at the scene's state: at the side of the wire at speed 3 the wire supplies all
    // of m u²/l = 4.5 towards the centre.
    let scenario = Scenario::new(loaded, &[]).expect("a state");
    let (_, solution) =
        solve_at(&scenario.program, &scenario.system, &scenario.env, &Settings::default()).expect("rows at the state");
    assert_eq!(solution.status, Status::Solved);
    let force = solution.constraint_force[0];
    assert!((force[0] + 4.5).abs() < 1e-12 && force[1].abs() < 1e-12, "{force:?}");
    println!("F_c[bead] = [{}, {}]", force[0], force[1]);
}
