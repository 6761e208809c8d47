//! The numbers of the constraint rows at one state: C, Ċ, J, c per constraint, with the
//! bodies' inverse masses, velocities and external forces — everything the λ solve, the
//! contact logic and the integrators read.
//!
//! Every row refers to C/κ, as the derivation does (κ the constant content taken out of ∇C):
//! `value` = C/κ, `rate` = Ċ/κ, `jacobian` = ∇C/κ, `bias` = c, so C̈/κ = Σᵢ Jᵢ·aᵢ + c and a
//! Newton step on `value` along `jacobian` is consistent.
//!
//! Not here: files or text (the state arrives as an [`Env`]); solving (`numeric::solve`).

use crate::derive::Derivation;
use crate::expr::eval::{Env, EvalError, Value, eval};
use crate::expr::{Id, Rational};
use crate::model::system::System;

/// One constraint row at a state.
#[derive(Clone, Debug, PartialEq)]
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
#[derive(Clone, Debug, PartialEq)]
pub struct Rows {
    pub dim: usize,
    pub inverse_mass: Vec<f64>,
    pub velocity: Vec<[f64; 3]>,
    /// External force per body.
    pub force: Vec<[f64; 3]>,
    pub rows: Vec<Row>,
}

/// The expressions to evaluate for a system's rows, gathered once.
#[derive(Clone, Debug)]
pub struct RowProgram {
    /// Roots in this order: per body mass, velocity, force; then per constraint C, Ċ, c, J….
    roots: Vec<Id>,
    /// 1/κ per constraint.
    inverse_scale: Vec<f64>,
    shape: Vec<(bool, Vec<usize>)>,
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
        RowProgram { roots, inverse_scale, shape }
    }

    /// The rows at `env` (which must give every position, velocity, mass, force, parameter and `t`).
    pub fn evaluate(&self, system: &System, env: &Env) -> Result<Rows, EvalError> {
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
