//! A loaded file made ready to run: derived, its rows gathered, its state given numbers.
//!
//! [`Scenario`] is what `simulate` and `bench` share: one derivation, then as many runs as
//! needed with different [`Settings`], each starting from the scene's initial state.
//!
//! [`chain`] writes the text of the N-link chain that the scale tests, the simulate
//! benchmark and `examples/chain.rs` all run (`constraints/hard/chain_100.toml` is its
//! N = 100).
//!
//! Not here: reading files (the caller passes a [`Loaded`]), printing.

use crate::derive::{Derivation, DeriveError, derive};
use crate::expr::eval::{Env, Value};
use crate::expr::{Role, Symbol};
use crate::model::file::Loaded;
use crate::model::scene::{Scene, StateError, environment};
use crate::model::system::System;
use crate::numeric::dynamics::Dynamics;
use crate::numeric::rows::RowProgram;
use crate::numeric::simulate::{Failure, Frame, Settings, Simulation, Summary, scene_length};
use crate::numeric::solve::{self, Diagnostic, off_constraint};
use std::fmt::Write;

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
    /// The `[parameters]` values, by symbol.
    pub values: Vec<(Symbol, Value)>,
}

impl Scenario {
    /// Derives `loaded` and evaluates its initial state, with `overrides` (values checked
    /// by `model::state`). The scene's `[scene] forces` expressions are compiled into the
    /// rows, except for a force or torque symbol `overrides` gives: that body takes the
    /// given value for the whole run (as `lagrange solve --set` takes it at one state), and
    /// [`Scenario::scene`] no longer lists its expression.
    pub fn new(mut loaded: Loaded, overrides: &[(Symbol, Value)]) -> Result<Scenario, ScenarioError> {
        let derivation = derive(&loaded.system)?;
        let (system, scene) = (&loaded.system, &mut loaded.scene);
        let given = |s: Symbol| overrides.iter().any(|&(g, _)| g == s);
        scene.forces.retain(|&(b, _)| !given(system.bodies[b].force));
        scene.torques.retain(|&(b, _)| !system.bodies[b].rigid.as_ref().is_some_and(|r| given(r.torque)));
        let program = RowProgram::with_torques(system, &derivation, &scene.forces, &scene.torques);
        let env = environment(&loaded.system, &loaded.values, &loaded.scene, overrides)?;
        Ok(Scenario { system: loaded.system, derivation, program, env, scene: loaded.scene, values: loaded.values })
    }

    /// The scene's own settings (dt, duration, restitution) with the defaults for the rest.
    pub fn settings(&self) -> Settings {
        let mut s = Settings::new(self.scene.dt, self.scene.duration);
        s.restitution = self.scene.restitution;
        s
    }

    /// The equality rows the initial state is off, and by how much
    /// (`numeric::solve::off_constraint`), for a note before a run projects it onto them. A
    /// state where the rows cannot be evaluated gives none: the run reports that itself.
    pub fn initial_offsets(&self) -> Vec<Diagnostic> {
        let Ok(rows) = self.program.evaluate(&self.system, &self.env) else { return Vec::new() };
        let settings = solve::Settings { length_scale: scene_length(&self.system, &self.env), ..Default::default() };
        off_constraint(&rows, &settings)
    }

    /// Runs from the initial state.
    pub fn simulate(
        &self,
        settings: Settings,
        observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
    ) -> Result<Summary, Box<Failure>> {
        let mut dynamics = Dynamics::borrowing(&self.system, &self.program, self.env.clone());
        // Each distinct expression once (a chain's bodies share one `m*g`).
        let mut forces: Vec<_> = self.scene.forces.iter().chain(&self.scene.torques).map(|&(_, f)| f).collect();
        forces.sort_unstable();
        forces.dedup();
        dynamics.velocity_dependent_forces = forces.into_iter().any(|f| {
            let graph = &self.system.graph;
            graph
                .free_symbols(f)
                .into_iter()
                .any(|s| matches!(graph.symbol(s).role, Role::Velocity { .. } | Role::AngularVelocity { .. }))
        });
        let mut simulation = Simulation::new(dynamics, &self.env, settings)
            .map_err(|error| Box::new(Failure { error, summary: Summary::default() }))?;
        simulation.run(observe)
    }

    /// Runs from the initial state with a velocity-level solver (`numeric::velocity`).
    pub fn simulate_velocity(
        &self,
        settings: crate::numeric::velocity::Settings,
        observe: &mut dyn FnMut(&Frame) -> Result<(), String>,
    ) -> Result<Summary, Box<Failure>> {
        let dynamics = Dynamics::new(&self.system, self.program.clone(), self.env.clone());
        crate::numeric::velocity::run::run(dynamics, &self.env, settings, observe)
    }
}

/// The TOML text of an `n`-link chain hanging from the origin: point masses `p1…pn` of mass
/// `m`, joined by rods of length `l` (`link1` pins `p1` to the origin), starting straight
/// along +x at rest, under gravity `g`; dt = 1e-3, 5 s.
///
/// ```
/// let loaded = lagrange::model::file::load(&lagrange::scenario::chain(3)).unwrap();
/// assert_eq!(loaded.system.constraints.len(), 3);
/// ```
pub fn chain(n: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# A chain of {n} point masses joined by rods of length l, hanging from the origin.");
    let _ = writeln!(s, "# Generated by `cargo run --example chain -- {n}`.");
    let _ = writeln!(s, "title = \"Chain of {n} links\"\ndimension = 2\n");
    let _ = writeln!(s, "[parameters]\nl = 0.5\nm = 1.0\ng = [0.0, -9.81]\n");
    for i in 1..=n {
        let _ = writeln!(
            s,
            "[[bodies]]\nname = \"p{i}\"\nposition = \"r{i}\"\nvelocity = \"v{i}\"\nacceleration = \"a{i}\"\nmass = \"m\"\nforce = \"F{i}\"\n"
        );
    }
    let _ = writeln!(s, "[[constraints]]\nname = \"link1\"\nexpr = \"dot(r1, r1) = l^2\"\n");
    for i in 2..=n {
        let _ = writeln!(
            s,
            "[[constraints]]\nname = \"link{i}\"\nexpr = \"dot(r{i} - r{j}, r{i} - r{j}) = l^2\"\n",
            j = i - 1
        );
    }
    let initial: Vec<String> =
        (1..=n).map(|i| format!("r{i} = [{:.1}, 0.0], v{i} = [0.0, 0.0]", 0.5 * i as f64)).collect();
    let forces: Vec<String> = (1..=n).map(|i| format!("F{i} = \"m*g\"")).collect();
    let _ = writeln!(s, "[scene]\ninitial = {{ {} }}", initial.join(", "));
    let _ = writeln!(s, "forces = {{ {} }}\ndt = 1e-3\nduration = 5.0", forces.join(", "));
    s
}
