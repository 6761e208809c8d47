//! A loaded file made ready to run: derived, its rows gathered, its state given numbers.
//!
//! [`Scenario`] is what `simulate` and `bench` share: one derivation, then as many runs as
//! needed with different [`Settings`], each starting from the scene's initial state.
//!
//! Not here: reading files (the caller passes a [`Loaded`]), printing.

use crate::derive::{Derivation, DeriveError, derive};
use crate::expr::Role;
use crate::expr::eval::Env;
use crate::model::file::{Loaded, RawValue};
use crate::model::scene::{Scene, StateError, environment};
use crate::model::system::System;
use crate::numeric::dynamics::Dynamics;
use crate::numeric::rows::RowProgram;
use crate::numeric::simulate::{Failure, Frame, Settings, Simulation, Summary};
use std::collections::BTreeMap;

/// Why a file cannot be run.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error(transparent)]
    Derive(#[from] DeriveError),
    #[error("initial state: {0}")]
    State(#[from] StateError),
}

/// A derived system with its numbers.
pub struct Scenario {
    pub system: System,
    pub derivation: Derivation,
    pub program: RowProgram,
    /// The initial state (parameters, masses, positions, velocities, t).
    pub env: Env,
    pub scene: Scene,
    pub values: BTreeMap<String, RawValue>,
}

impl Scenario {
    /// Derives `loaded` and evaluates its initial state, with `overrides` (`NAME = value`).
    pub fn new(mut loaded: Loaded, overrides: &[(String, RawValue)]) -> Result<Scenario, ScenarioError> {
        let derivation = derive(&mut loaded.system)?;
        let program = RowProgram::new(&mut loaded.system, &derivation, &loaded.scene.forces);
        let env = environment(&loaded.system, &loaded.values, &loaded.scene, overrides)?;
        Ok(Scenario { system: loaded.system, derivation, program, env, scene: loaded.scene, values: loaded.values })
    }

    /// The scene's own settings (dt, duration, restitution) with the defaults for the rest.
    pub fn settings(&self) -> Settings {
        let mut s = Settings::new(self.scene.dt, self.scene.duration);
        s.restitution = self.scene.restitution;
        s
    }

    /// Runs from the initial state.
    pub fn simulate(
        &self,
        settings: Settings,
        observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
    ) -> Result<Summary, Box<Failure>> {
        let mut dynamics = Dynamics::new(&self.system, self.program.clone(), self.env.clone());
        dynamics.velocity_dependent_forces = self.scene.forces.iter().any(|&(_, f)| {
            let graph = &self.system.graph;
            graph.free_symbols(f).into_iter().any(|s| matches!(graph.symbol(s).role, Role::Velocity { .. }))
        });
        let mut simulation = Simulation::new(dynamics, &self.env, settings)
            .map_err(|error| Box::new(Failure { error, summary: Summary::default() }))?;
        simulation.run(observe)
    }
}
