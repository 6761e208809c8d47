//! Time steppers for M a = F + Jᵀλ (DESIGN.md step 7): semi-implicit Euler, velocity
//! Verlet and classical RK4, over positions and velocities of point masses.
//!
//! The accelerations come from a [`Field`] (in a simulation: evaluate the rows, solve for λ,
//! aᵢ = (Fᵢ + Σₖ λₖ Jₖᵢ)/mᵢ). Every stepper takes the acceleration at the start of the step
//! from the caller, who already evaluated it to record the state, so no stage is computed
//! twice. Scratch buffers live in the [`Stepper`]: a step allocates nothing here.
//!
//! Design note. Semi-implicit (symplectic) Euler and velocity Verlet keep the energy error
//! of a conservative system bounded over long runs; RK4 is more accurate per step but drifts
//! secularly. The constraint forces depend on the velocities (the centripetal term in c),
//! so Verlet's second stage is evaluated at the predicted velocity v + dt a — it stays second
//! order, and with projection (`numeric::stabilize`) it behaves like RATTLE.
//!
//! Not here: drift control (`numeric::stabilize`), contacts, the run loop (`numeric::simulate`).

/// Positions or velocities or accelerations of all bodies; components past the dimension are 0.
pub type Vectors = [[f64; 3]];

/// `to = from` (of equal lengths): one or two slots (a pendulum, a bead, a double pendulum)
/// by assignment, more as one block copy — a call to `memcpy` costs more than copying one
/// slot, and the compiler makes one of any loop that copies.
#[inline]
pub fn copy_slots<T: Copy>(to: &mut [T], from: &[T]) {
    match (to, from) {
        ([t], [f]) => *t = *f,
        ([t0, t1], [f0, f1]) => (*t0, *t1) = (*f0, *f1),
        (to, from) => to.copy_from_slice(from),
    }
}

/// Accelerations at a state.
pub trait Field {
    type Error;
    /// Writes aᵢ(t, q, v) into `a`.
    fn acceleration(&mut self, t: f64, q: &Vectors, v: &Vectors, a: &mut Vectors) -> Result<(), Self::Error>;

    /// Writes q̇(q, v) into `out`: v itself, unless some coordinate is not the integral of
    /// its velocity slot (a 3D rigid body's rotation vector, φ̇ = dexp⁻¹(φ) ω,
    /// `numeric::rotation`). RK4's stages use it; the other steppers drift from φ = 0,
    /// where q̇ = v holds along the step's straight line.
    fn rate(&self, q: &Vectors, v: &Vectors, out: &mut Vectors) {
        let _ = q;
        out.copy_from_slice(v);
    }
}

/// Which stepper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Integrator {
    /// Semi-implicit Euler: v ← v + dt a(q, v); q ← q + dt v. First order, symplectic.
    Euler,
    /// Velocity Verlet: half kick, drift, half kick. Second order, symplectic.
    Verlet,
    /// Classical Runge–Kutta of order 4 on (q, v).
    Rk4,
}

impl Integrator {
    pub const ALL: [Integrator; 3] = [Integrator::Euler, Integrator::Verlet, Integrator::Rk4];

    pub fn name(self) -> &'static str {
        match self {
            Integrator::Euler => "euler",
            Integrator::Verlet => "verlet",
            Integrator::Rk4 => "rk4",
        }
    }

    /// Accelerations evaluated per step (including the one the caller supplies).
    pub fn stages(self) -> usize {
        match self {
            Integrator::Euler => 1,
            Integrator::Verlet => 2,
            Integrator::Rk4 => 4,
        }
    }
}

/// A stepper with its scratch buffers, sized for `n` bodies.
#[derive(Clone, Debug)]
pub struct Stepper {
    pub integrator: Integrator,
    q: Vec<[f64; 3]>,
    v: Vec<[f64; 3]>,
    dq: Vec<[f64; 3]>,
    /// q̇ of an RK4 stage ([`Field::rate`]).
    r: Vec<[f64; 3]>,
    k: [Vec<[f64; 3]>; 3],
}

/// `out = x + h y`, componentwise.
fn axpy(out: &mut Vectors, x: &Vectors, h: f64, y: &Vectors) {
    for ((o, x), y) in out.iter_mut().zip(x).zip(y) {
        for d in 0..3 {
            o[d] = x[d] + h * y[d];
        }
    }
}

/// `x += h y`, componentwise.
pub fn add_scaled(x: &mut Vectors, h: f64, y: &Vectors) {
    // One slot (a pendulum, a bead): the loop's numbers without its set-up.
    if let ([x], [y]) = (&mut *x, y) {
        for d in 0..3 {
            x[d] += h * y[d];
        }
        return;
    }
    for (x, y) in x.iter_mut().zip(y) {
        for d in 0..3 {
            x[d] += h * y[d];
        }
    }
}

impl Stepper {
    pub fn new(integrator: Integrator, n: usize) -> Stepper {
        let z = vec![[0.0; 3]; n];
        Stepper { integrator, q: z.clone(), v: z.clone(), dq: z.clone(), r: z.clone(), k: [z.clone(), z.clone(), z] }
    }

    /// Verlet's first half: v½ = v + dt/2 a₀ (written into `v`); q⁺ = q + dt v½.
    pub fn verlet_drift(dt: f64, q: &mut Vectors, v: &mut Vectors, a0: &Vectors) {
        add_scaled(v, 0.5 * dt, a0);
        add_scaled(q, dt, v);
    }

    /// Verlet's second half at t⁺ = t + dt: v⁺ = v½ + dt/2 a₁ with a₁ = a(q⁺, ṽ) at the
    /// predicted velocity ṽ = v½ + dt/2 a₀ (= v + dt a₀); `v` holds v½ on entry.
    pub fn verlet_kick<F: Field>(
        &mut self,
        field: &mut F,
        t_next: f64,
        dt: f64,
        q: &Vectors,
        v: &mut Vectors,
        a0: &Vectors,
    ) -> Result<(), F::Error> {
        let [a1, _, _] = &mut self.k;
        axpy(&mut self.v, v, 0.5 * dt, a0);
        field.acceleration(t_next, q, &self.v, a1)?;
        add_scaled(v, 0.5 * dt, a1);
        Ok(())
    }

    /// Advances (q, v) from t to t + dt; `a0` is the acceleration at (t, q, v).
    pub fn step<F: Field>(
        &mut self,
        field: &mut F,
        t: f64,
        dt: f64,
        q: &mut Vectors,
        v: &mut Vectors,
        a0: &Vectors,
    ) -> Result<(), F::Error> {
        match self.integrator {
            Integrator::Euler => {
                // v⁺ = v + dt a(q, v);  q⁺ = q + dt v⁺.
                add_scaled(v, dt, a0);
                add_scaled(q, dt, v);
            }
            Integrator::Verlet => {
                Stepper::verlet_drift(dt, q, v, a0);
                self.verlet_kick(field, t + dt, dt, q, v, a0)?;
            }
            Integrator::Rk4 => {
                // Stages on y = (q, v), y' = (q̇, a) with q̇ = r(q, v) (v itself but for a 3D
                // body's rotation vector, [`Field::rate`]): k₁ = (r₁, a₀) at y; k₂ at
                // y + dt/2 k₁; k₃ at y + dt/2 k₂; k₄ at y + dt k₃;
                // y⁺ = y + dt/6 (k₁ + 2k₂ + 2k₃ + k₄).
                let [a2, a3, a4] = &mut self.k;
                let (sq, sv, dq, r) = (&mut self.q, &mut self.v, &mut self.dq, &mut self.r);
                let h = 0.5 * dt;
                // Stage 2 at q₂ = q + h r₁, v₂ = v + h a₀; dq collects r₁ + 2r₂ + 2r₃ + r₄.
                field.rate(q, v, r);
                axpy(sq, q, h, r);
                axpy(sv, v, h, a0);
                field.acceleration(t + h, sq, sv, a2)?;
                dq.copy_from_slice(r);
                field.rate(sq, sv, r);
                add_scaled(dq, 2.0, r);
                // Stage 3 at q₃ = q + h r₂, v₃ = v + h a₂.
                axpy(sq, q, h, r);
                axpy(sv, v, h, a2);
                field.acceleration(t + h, sq, sv, a3)?;
                field.rate(sq, sv, r);
                add_scaled(dq, 2.0, r);
                // Stage 4 at q₄ = q + dt r₃, v₄ = v + dt a₃.
                axpy(sq, q, dt, r);
                axpy(sv, v, dt, a3);
                field.acceleration(t + dt, sq, sv, a4)?;
                field.rate(sq, sv, r);
                add_scaled(dq, 1.0, r);
                // q⁺ = q + dt/6 dq;  v⁺ = v + dt/6 (a₀ + 2a₂ + 2a₃ + a₄).
                add_scaled(q, dt / 6.0, dq);
                for i in 0..v.len() {
                    for d in 0..3 {
                        v[i][d] += dt / 6.0 * (a0[i][d] + 2.0 * (a2[i][d] + a3[i][d]) + a4[i][d]);
                    }
                }
            }
        }
        Ok(())
    }
}
