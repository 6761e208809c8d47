//! Scale: a 1 000-body, 1 000-constraint chain simulates (a few steps with the dense solve
//! and the interpreter; `benches/simulate.rs` measures the cost per step against N).

mod common;

use lagrange::model::file::load;
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::stabilize::Stabilize;
use lagrange::scenario::Scenario;

/// The text of an n-link chain (as `examples/chain.rs` writes it).
pub fn chain(n: usize) -> String {
    let mut s = format!("title = \"Chain of {n}\"\ndimension = 2\n[parameters]\nl = 0.5\nm = 1.0\ng = [0.0, -9.81]\n");
    for i in 1..=n {
        s += &format!(
            "[[bodies]]\nname = \"p{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\nmass = \"m\"\nforce = \"F{i}\"\n"
        );
    }
    s += "[[constraints]]\nname = \"link1\"\nexpr = \"dot(r1, r1) = l^2\"\n";
    for i in 2..=n {
        s += &format!(
            "[[constraints]]\nname = \"link{i}\"\nexpr = \"dot(r{i} - r{j}, r{i} - r{j}) = l^2\"\n",
            j = i - 1
        );
    }
    let initial: Vec<String> =
        (1..=n).map(|i| format!("r{i} = [{:.1}, 0.0], v{i} = [0.0, 0.0]", 0.5 * i as f64)).collect();
    let forces: Vec<String> = (1..=n).map(|i| format!("F{i} = \"m*g\"")).collect();
    s += &format!("[scene]\ninitial = {{ {} }}\nforces = {{ {} }}\n", initial.join(", "), forces.join(", "));
    s
}

#[test]
fn a_thousand_body_chain_simulates() {
    let loaded = load(&chain(1000)).expect("valid");
    let s = Scenario::new(loaded, &[]).expect("derives");
    assert_eq!((s.system.bodies.len(), s.system.constraints.len()), (1000, 1000));
    let settings = common::settings(&s, Integrator::Verlet, Stabilize::PROJECTION, 1e-3, 2);
    let summary = s.simulate(settings, &mut |_| Ok(())).expect("runs");
    assert_eq!(summary.steps, 2);
    assert!(summary.max_abs_c <= 1e-9, "{}", summary.max_abs_c);
    assert!(summary.final_position.iter().flatten().all(|x| x.is_finite()));
}
