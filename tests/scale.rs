//! Scale: a 1 000-body, 1 000-constraint chain simulates for a simulated second (1 000
//! steps; 2 in debug builds), its links held to 1e-9 (`benches/simulate.rs` measures the
//! cost per step against N: linear, through the compiled tape and the band solve).

mod common;

use lagrange::model::file::load;
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::stabilize::Stabilize;
use lagrange::scenario::{Scenario, chain};

#[test]
fn a_thousand_body_chain_simulates() {
    if common::skip_slow("a_thousand_body_chain_simulates") {
        return;
    }
    let loaded = load(&chain(1000)).expect("valid");
    let s = Scenario::new(loaded, &[]).expect("derives");
    assert_eq!((s.system.bodies.len(), s.system.constraints.len()), (1000, 1000));
    let steps = if cfg!(debug_assertions) { 2 } else { 1_000 };
    let settings = common::settings(&s, Integrator::Verlet, Stabilize::PROJECTION, 1e-3, steps);
    let summary = s.simulate(settings, &mut |_| Ok(())).expect("runs");
    assert_eq!(summary.steps, steps);
    assert!(summary.max_abs_c <= 1e-9, "{}", summary.max_abs_c);
    assert!(summary.final_position.iter().flatten().all(|x| x.is_finite()));
}
