//! Shared helpers for the simulation tests: load a file, run it with chosen settings.
#![allow(dead_code)]

use lagrange::model::file::load;
use lagrange::numeric::integrate::Integrator;
use lagrange::numeric::simulate::{Failure, Frame, Settings, Summary};
use lagrange::numeric::stabilize::Stabilize;
use lagrange::scenario::Scenario;

pub fn scenario(path: &str) -> Scenario {
    let text = std::fs::read_to_string(path).expect("file");
    let loaded = load(&text).expect("valid file");
    Scenario::new(loaded, &[]).expect("derives and has an initial state")
}

pub fn settings(s: &Scenario, integrator: Integrator, stabilize: Stabilize, dt: f64, steps: u64) -> Settings {
    let mut settings = s.settings();
    settings.integrator = integrator;
    settings.stabilize = stabilize;
    settings.dt = dt;
    settings.steps = steps;
    settings
}

/// Runs `path` and calls `observe` on every frame.
pub fn run_observed(
    path: &str,
    integrator: Integrator,
    stabilize: Stabilize,
    dt: Option<f64>,
    steps: Option<u64>,
    observe: &mut dyn FnMut(&Frame),
) -> Result<Summary, Box<Failure>> {
    let s = scenario(path);
    let dt = dt.unwrap_or(s.scene.dt);
    let steps = steps.unwrap_or((s.scene.duration / dt).round() as u64);
    let settings = settings(&s, integrator, stabilize, dt, steps);
    s.simulate(settings, &mut |f| {
        observe(f);
        Ok(())
    })
}

/// Runs `path` with Verlet + projection at the scene's step.
pub fn run(path: &str, steps: Option<u64>) -> Result<Summary, Box<Failure>> {
    run_observed(path, Integrator::Verlet, Stabilize::PROJECTION, None, steps, &mut |_| {})
}
