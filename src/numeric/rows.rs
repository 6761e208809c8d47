//! The numbers of the constraint rows at one state: C, Ċ, J, c per constraint, with the
//! bodies' inverse masses, velocities and external forces — everything the λ solve, the
//! contact logic and the integrators read.
//!
//! Every row refers to C/κ, as the derivation does (κ the constant content taken out of ∇C):
//! `value` = C/κ, `rate` = Ċ/κ, `jacobian` = ∇C/κ, `bias` = c, so C̈/κ = Σᵢ Jᵢ·aᵢ + c and a
//! Newton step on `value` along `jacobian` is consistent.
//!
//! Evaluation goes through one compiled [`Tape`] of every root (`evaluate`, `evaluate_into`);
//! the interpreter (`expr::eval`, the reference semantics) stays available as
//! `evaluate_interpreted`, and a test holds the two together on every constraint file.
//!
//! Not here: files or text (the state arrives as an [`Env`]); solving (`numeric::solve`).

use crate::derive::Derivation;
use crate::expr::eval::{Env, EvalError, Value, eval};
use crate::expr::graph::SymbolWalk;
use crate::expr::{Id, Rational, Symbol};
use crate::model::system::System;
use crate::numeric::tape::{Scratch, Tape};

/// One constraint row at a state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Row {
    /// C/κ.
    pub value: f64,
    /// Ċ/κ.
    pub rate: f64,
    /// c: C̈/κ with every acceleration zero.
    pub bias: f64,
    /// `C ≥ 0` rather than `C = 0`.
    pub inequality: bool,
    /// `(body, Jᵢ = ∇ᵢC/κ)`, components past the dimension zero.
    pub jacobian: Vec<(usize, [f64; 3])>,
}

/// All rows of a system at one state, with the bodies' numbers.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Rows {
    pub dim: usize,
    pub inverse_mass: Vec<f64>,
    pub velocity: Vec<[f64; 3]>,
    /// External force per body.
    pub force: Vec<[f64; 3]>,
    pub rows: Vec<Row>,
}

/// The expressions to evaluate for a system's rows, gathered once and compiled to a
/// [`Tape`] (the interpreter of `expr::eval` is the reference semantics, not the hot path).
#[derive(Clone, Debug)]
pub struct RowProgram {
    /// Roots in this order: per body mass, velocity, force; then per constraint C, Ċ, c, J….
    roots: Vec<Id>,
    /// 1/κ per constraint.
    inverse_scale: Vec<f64>,
    shape: Vec<(bool, Vec<usize>)>,
    /// Every root, compiled over `inputs`.
    tape: Tape,
    /// The free symbols of the roots, in the tape's input order.
    inputs: Vec<Symbol>,
}

/// Input and output buffers of [`RowProgram::evaluate_into`], reused across evaluations.
#[derive(Clone, Debug)]
pub struct RowScratch {
    inputs: Vec<f64>,
    outputs: Vec<f64>,
    tape: Scratch,
}

impl RowProgram {
    /// Gathers the rows of `derivation`. The external force on body i is `forces`' expression
    /// for i when it has one (so a simulation re-evaluates `F = m*g - k*v` at every state),
    /// else the body's force symbol, whose value the state gives.
    pub fn new(system: &mut System, derivation: &Derivation, forces: &[(usize, Id)]) -> RowProgram {
        let mut roots = Vec::new();
        for (i, body) in system.bodies.iter().enumerate() {
            let v = system.graph.sym(body.velocity);
            let f = match forces.iter().find(|(b, _)| *b == i) {
                Some(&(_, expr)) => expr,
                None => system.graph.sym(body.force),
            };
            roots.extend([body.mass, v, f]);
        }
        let mut inverse_scale = Vec::new();
        let mut shape = Vec::new();
        for (k, d) in derivation.constraints.iter().enumerate() {
            roots.extend([d.c, d.c_dot, d.c_term]);
            roots.extend(d.direction.iter().map(|&(_, j)| j));
            inverse_scale.push(d.scale.recip().unwrap_or(Rational::ONE).to_f64());
            shape.push((system.constraints[k].inequality, d.direction.iter().map(|&(b, _)| b).collect()));
        }
        let inputs: Vec<Symbol> = SymbolWalk::default().free_symbols_of(&system.graph, &roots).to_vec();
        // Every symbol a root reads is an input and each is listed once, so lowering cannot fail.
        let tape = Tape::compile(&system.graph, &roots, &inputs).expect("the inputs are the roots' free symbols");
        RowProgram { roots, inverse_scale, shape, tape, inputs }
    }

    /// [`new`](RowProgram::new) for a state that gives some forces itself (`solve --at`,
    /// `--set F=…`): a body whose force symbol is named in `given` keeps that symbol, so the
    /// state's value replaces the scene's expression.
    pub fn with_given_forces(
        system: &mut System,
        derivation: &Derivation,
        forces: &[(usize, Id)],
        given: &[&str],
    ) -> RowProgram {
        let named = |b: usize| given.contains(&system.graph.symbol(system.bodies[b].force).name.as_str());
        let forces: Vec<(usize, Id)> = forces.iter().copied().filter(|&(b, _)| !named(b)).collect();
        RowProgram::new(system, derivation, &forces)
    }

    /// Buffers for [`evaluate_into`](RowProgram::evaluate_into).
    pub fn scratch(&self) -> RowScratch {
        RowScratch {
            inputs: vec![0.0; self.tape.input_len()],
            outputs: vec![0.0; self.tape.output_len()],
            tape: self.tape.scratch(),
        }
    }

    /// The rows at `env` (which must give every position, velocity, mass, force, parameter and `t`).
    pub fn evaluate(&self, system: &System, env: &Env) -> Result<Rows, EvalError> {
        let mut rows = Rows::default();
        self.evaluate_into(system, env, &mut self.scratch(), &mut rows)?;
        Ok(rows)
    }

    /// [`evaluate`](RowProgram::evaluate) into `rows`, reusing its buffers and `scratch`: no
    /// allocation once `rows` has the system's shape (the simulation's hot path).
    pub fn evaluate_into(
        &self,
        system: &System,
        env: &Env,
        scratch: &mut RowScratch,
        rows: &mut Rows,
    ) -> Result<(), EvalError> {
        for (i, &s) in self.inputs.iter().enumerate() {
            let slots = self.tape.input_range(i);
            match env.get(s) {
                Some(Value::Scalar(x)) => scratch.inputs[slots].fill(x),
                Some(Value::Vector(v)) => {
                    let n = slots.len();
                    scratch.inputs[slots].copy_from_slice(&v[..n]);
                }
                None => return Err(EvalError::Missing(system.graph.symbol(s).name.clone())),
            }
        }
        self.tape.eval(&scratch.inputs, &mut scratch.tape, &mut scratch.outputs);
        let out = &scratch.outputs;
        let tape = &self.tape;
        let scalar = |root: usize| out[tape.output_range(root).start];
        let vector = |root: usize| {
            let mut x = [0.0; 3];
            let range = tape.output_range(root);
            let n = range.len();
            x[..n].copy_from_slice(&out[range]);
            x
        };
        let n = system.bodies.len();
        rows.dim = system.dim();
        rows.inverse_mass.clear();
        rows.inverse_mass.extend((0..n).map(|i| 1.0 / scalar(3 * i)));
        rows.velocity.clear();
        rows.velocity.extend((0..n).map(|i| vector(3 * i + 1)));
        rows.force.clear();
        rows.force.extend((0..n).map(|i| vector(3 * i + 2)));
        rows.rows.resize_with(self.shape.len(), Row::default);
        let mut at = 3 * n;
        for (((inequality, bodies), &s), row) in self.shape.iter().zip(&self.inverse_scale).zip(&mut rows.rows) {
            row.value = scalar(at) * s;
            row.rate = scalar(at + 1) * s;
            row.bias = scalar(at + 2);
            row.inequality = *inequality;
            row.jacobian.clear();
            row.jacobian.extend(bodies.iter().enumerate().map(|(q, &b)| (b, vector(at + 3 + q))));
            at += 3 + bodies.len();
        }
        Ok(())
    }

    /// The interpreter's rows at `env` (`expr::eval`, the reference semantics), for tests of
    /// the compiled path.
    pub fn evaluate_interpreted(&self, system: &System, env: &Env) -> Result<Rows, EvalError> {
        let values = eval(&system.graph, &self.roots, env)?;
        let n = system.bodies.len();
        let vector = |v: Value| v.vector().unwrap_or([f64::NAN; 3]);
        let scalar = |v: Value| v.scalar().unwrap_or(f64::NAN);
        let mut rows = Rows {
            dim: system.dim(),
            inverse_mass: (0..n).map(|i| 1.0 / scalar(values[3 * i])).collect(),
            velocity: (0..n).map(|i| vector(values[3 * i + 1])).collect(),
            force: (0..n).map(|i| vector(values[3 * i + 2])).collect(),
            rows: Vec::with_capacity(self.shape.len()),
        };
        let mut at = 3 * n;
        for ((inequality, bodies), &s) in self.shape.iter().zip(&self.inverse_scale) {
            let jacobian = bodies.iter().enumerate().map(|(q, &b)| (b, vector(values[at + 3 + q]))).collect();
            rows.rows.push(Row {
                value: scalar(values[at]) * s,
                rate: scalar(values[at + 1]) * s,
                bias: scalar(values[at + 2]),
                inequality: *inequality,
                jacobian,
            });
            at += 3 + bodies.len();
        }
        Ok(rows)
    }
}
