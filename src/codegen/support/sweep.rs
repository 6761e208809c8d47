//! Written into modules generated with `--solver soft-step` or `--solver pgs`: warm starting
//! and the sequential-impulse sweep both solvers run, as the library's `Prepared::warm_start`
//! and `Prepared::sweep` (`numeric::velocity`) run them.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as part of every
//! generated module of `tests/generate_step.rs` (it uses the module's items, so it is not a
//! module of its own). Not here: the bias and softness of each row (each solver's step).

impl<const D: usize> Prepared<D> {
    /// Warm start: every row's accumulated impulse applied again.
    fn warm_start(&self, u: &mut [[f64; D]], impulse: &[f64]) {
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
    fn sweep(&self, u: &mut [[f64; D]], impulse: &mut [f64], mut law: impl FnMut(usize, f64) -> (f64, Softness)) {
        for (k, impulse) in impulse.iter_mut().enumerate() {
            let m = self.effective_mass[k];
            if m == 0.0 {
                continue;
            }
            let (bias, soft) = law(k, self.value[k]);
            let rate = self.rate(k, u);
            let old = *impulse;
            let mut delta = -soft.mass_scale * m * (rate + bias) - soft.impulse_scale * old;
            if self.inequality[k] {
                delta = (old + delta).max(0.0) - old;
            }
            *impulse = old + delta;
            self.apply(k, u, delta);
        }
    }
}
