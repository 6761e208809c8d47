//! Written into modules generated with `--solver soft-step` or `--solver pgs`: warm starting
//! and the sequential-impulse sweep both solvers run, as the library's `Prepared::warm_start`
//! and `Prepared::sweep` (`numeric::velocity`) run them.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as part of every
//! generated module of `tests/generate_step.rs` (it uses the module's items, so it is not a
//! module of its own). Not here: the bias and softness of each row (each solver's step).

/// A step that keeps what the next step starts from: the accumulated impulses (the
/// warm-start storage) and the rows at the state the last step left, so a step evaluates the
/// rows once per substep (where `step` evaluates them once more, at its start), as an engine
/// keeps its joints' prepared rows. The rows are kept only where they read neither the
/// velocities nor the time (`KEEP`), and serve only while every other field of the state is
/// what the last step left, bit for bit (`same_inputs`): move a body or change a parameter
/// between steps and the next step evaluates them again. So `Stepper::step` gives `step`'s
/// numbers bit for bit. Large scenes: `Box::new(Stepper::new())` keeps it off the stack.
#[allow(dead_code)]
pub struct Stepper {
    /// The accumulated impulse of each row (for C/κ; P/h ≈ λ), as `step`'s `impulses`.
    pub impulses: [f64; CONSTRAINTS],
    /// The rows at `left`, when `kept`.
    rows: Prepared<DIM>,
    /// The state as the last step left it.
    left: State,
    kept: bool,
}

#[allow(dead_code)]
impl Stepper {
    /// No impulses and no rows yet.
    pub fn new() -> Stepper {
        Stepper { impulses: [0.0; CONSTRAINTS], rows: Prepared::zeroed(), left: State::default(), kept: false }
    }

    /// One step of `dt` with the defaults (`StepSettings::default()`), as `step`.
    pub fn step(&mut self, s: &mut State, dt: f64) {
        self.step_with(s, dt, &StepSettings::default());
    }

    /// One step of `dt` with `settings`, as `step_with`.
    pub fn step_with(&mut self, s: &mut State, dt: f64, settings: &StepSettings) {
        if !(self.kept && same_inputs(s, &self.left)) {
            prepare(s, &mut self.rows);
        }
        steps(s, &mut self.impulses, &mut self.rows, dt, settings);
        self.kept = KEEP;
        if KEEP {
            self.left = *s;
        }
    }
}

impl Default for Stepper {
    fn default() -> Stepper {
        Stepper::new()
    }
}

impl Prepared<DIM> {
    /// Warm start: every row's accumulated impulse applied again.
    fn warm_start(&self, u: &mut [[f64; DIM]], impulse: &[f64]) {
        for (k, &p) in impulse.iter().enumerate() {
            if p != 0.0 {
                self.apply(k, u, p);
            }
        }
    }

    /// One Gauss–Seidel sweep over the rows in file order: row k of value C/κ, with the bias
    /// b and softness s that `law(k, C/κ)` gives, takes ΔP = −s_m·m_eff·(Ċ + b) − s_i·P
    /// (Box2D `b2SolveDistanceJoint`); an inequality row clamps its accumulated impulse at
    /// P ≥ 0 (Box2D `b2SolveContact`).
    fn sweep(&self, u: &mut [[f64; DIM]], impulse: &mut [f64], mut law: impl FnMut(usize, f64) -> (f64, Softness)) {
        for (k, impulse) in impulse.iter_mut().enumerate() {
            let m = self.effective_mass[k];
            if m == 0.0 {
                continue;
            }
            let (bias, soft) = law(k, self.value[k]);
            let rate = self.rate(k, u);
            let old = *impulse;
            let mut delta = -soft.mass_scale * m * (rate + bias) - soft.impulse_scale * old;
            if INEQUALITY[k] {
                delta = (old + delta).max(0.0) - old;
            }
            *impulse = old + delta;
            self.apply(k, u, delta);
        }
    }
}
