//! Loading a constraint file: what `lagrange::model` promises a user of the library.
//!
//! Definitions are ordered however long their chain of uses; cycles are reported once and
//! nothing that depends on them is reported again.
//!
//! Not here: the messages of invalid files (snapshots in `tests/constraint_files.rs`).

use lagrange::model::file::load;
use std::fmt::Write;
use std::time::{Duration, Instant};

/// A bead on a wire whose radius is the last of `n` definitions, each using the one before.
fn chain_of_definitions(n: usize, last: &str) -> String {
    let mut text = String::from("dimension = 2\n[definitions]\nd_0 = \"1\"\n");
    for i in 1..n {
        writeln!(text, "d_{i} = \"d_{} + 1\"", i - 1).expect("writes to a string");
    }
    writeln!(text, "d_{n} = \"{last}\"").expect("writes to a string");
    text.push_str(
        "[[bodies]]\nname = \"bead\"\nposition = \"r\"\nvelocity = \"v\"\nacceleration = \"a\"\nmass = 1.0\nforce = \"F\"\n\
         [[constraints]]\nname = \"wire\"\nexpr = \"dot(r, r) = d_0^2\"\n",
    );
    text
}

#[test]
fn a_long_chain_of_definitions_loads_in_linear_time() {
    // Keys sort as text (d_1, d_10, d_100, …), so the file's order is far from the order of
    // use: every definition waits for one written elsewhere.
    let n = 20_000;
    let text = chain_of_definitions(n, &format!("d_{} + 1", n - 1));
    let start = Instant::now();
    let loaded = load(&text).expect("a chain of definitions is a valid file");
    assert!(start.elapsed() < Duration::from_secs(20), "took {:?}", start.elapsed());
    assert!(loaded.system.graph.symbol_named("d_0").is_none(), "a definition is not a symbol");
    assert_eq!(loaded.system.constraints.len(), 1);
}

#[test]
fn a_cycle_at_the_end_of_a_long_chain_is_reported_once() {
    let n = 20_000;
    // d_n uses d_{n-1} (so the whole chain) and itself.
    let text = chain_of_definitions(n, &format!("d_{} + d_{n}", n - 1));
    let problems = load(&text).expect_err("a definition refers to itself");
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(
        problems[0].message.contains(&format!("definition `d_{n}` refers to itself (through d_{n})")),
        "{problems:?}"
    );
}
