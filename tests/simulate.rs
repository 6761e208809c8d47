//! Simulation: drift and energy of the pendulum, determinism, the integrators' orders.

use lagrange::derive::derive;
use lagrange::model::file::load;
use lagrange::model::scene::environment;
use lagrange::numeric::dynamics::Dynamics;
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::rows::RowProgram;
use lagrange::numeric::simulate::{Settings, Simulation, Summary};
use lagrange::numeric::stabilize::Stabilize;

fn run(path: &str, integrator: Integrator, stabilize: Stabilize, dt: f64, steps: u64) -> Summary {
    let text = std::fs::read_to_string(path).expect("file");
    let mut loaded = load(&text).expect("valid file");
    let derivation = derive(&mut loaded.system).expect("derives");
    let program = RowProgram::new(&mut loaded.system, &derivation, &loaded.scene.forces);
    let env = environment(&loaded.system, &loaded.values, &loaded.scene, &[]).expect("state");
    let dynamics = Dynamics::new(&loaded.system, program, env.clone());
    let mut settings = Settings::new(dt, dt * steps as f64);
    settings.integrator = integrator;
    settings.stabilize = stabilize;
    settings.steps = steps;
    let mut sim = Simulation::new(dynamics, &env, settings).expect("settings");
    sim.run(&mut |_| Ok(())).expect("runs")
}

#[test]
fn pendulum_verlet_projection_1e5_steps_keeps_drift_and_energy() {
    let s = run("constraints/pendulum.toml", Integrator::Verlet, Stabilize::PROJECTION, 1e-3, 100_000);
    eprintln!("{s:?}", s = (s.max_abs_c, s.max_abs_c_dot, s.energy_rel_drift, s.wall_seconds, s.evaluations));
    assert!(s.max_abs_c <= 1e-9, "max |C| = {}", s.max_abs_c);
    assert!(s.energy_rel_drift.expect("time-independent") <= 1e-3, "energy {:?}", s.energy_rel_drift);
}
