//! Written into every module generated with `--solver`: the pieces of the velocity-level
//! step that every solver shares — Box2D's softness (`b2MakeSoft`), the step's settings with
//! Box2D v3's defaults, the rows of one substep flattened with their effective masses
//! (`Prepared`, over the slots of `numeric::rows`: the bodies, then the rigid bodies' angular
//! slots). The same operations in the same order as the library's `numeric::velocity`
//! (`Softness`, `Settings`, `Prepared`), so a module's step gives the library's numbers.
//!
//! Included with `include_str!` from the first item on (this note is left out); compiled as part of every
//! generated module of `tests/generate_step.rs` (it uses the module's items, so it is not a
//! module of its own). Not here: the kick, the drift and the change between the state's and
//! the rows' slots (`motion.rs`, or `motion_3d.rs` with 3D rigid bodies), the
//! sequential-impulse sweep (`sweep.rs`), each solver's step (`soft_step.rs`, `pgs.rs`,
//! `exact.rs`), the rows' formulas (generated).

/// Box2D's `b2Softness`: a soft row of stiffness `hertz` and damping ratio ζ at substep h,
/// as a bias rate on C/κ, a scale on the effective mass and a scale on the accumulated impulse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Softness {
    pub bias_rate: f64,
    pub mass_scale: f64,
    pub impulse_scale: f64,
}

impl Softness {
    /// A rigid row without bias (the relax pass, Box2D's `useBias = false`).
    pub const RIGID: Softness = Softness { bias_rate: 0.0, mass_scale: 1.0, impulse_scale: 0.0 };

    /// `b2MakeSoft`: ω = 2π·hertz, a₁ = 2ζ + hω, a₂ = hω·a₁, a₃ = 1/(1 + a₂); bias rate ω/a₁,
    /// mass scale a₂a₃, impulse scale a₃. Zero hertz is a rigid row.
    pub fn new(hertz: f64, zeta: f64, h: f64) -> Softness {
        if hertz == 0.0 {
            return Softness::RIGID;
        }
        let omega = 2.0 * std::f64::consts::PI * hertz;
        let a1 = 2.0 * zeta + h * omega;
        let a2 = h * omega * a1;
        let a3 = 1.0 / (1.0 + a2);
        Softness { bias_rate: omega / a1, mass_scale: a2 * a3, impulse_scale: a3 }
    }
}

/// Box2D v3's contact softness: 30 Hz (capped like the joints), ζ = 10, and the push-out
/// speed limit of penetrating contacts (`contactSpeed`, 3 m/s).
#[allow(dead_code)]
const CONTACT_HERTZ: f64 = 30.0;
#[allow(dead_code)]
const CONTACT_DAMPING_RATIO: f64 = 10.0;
#[allow(dead_code)]
const CONTACT_SPEED: f64 = 3.0;

/// How `step_with` runs one step. `Default` is Box2D v3's: 4 substeps, joints at 60 Hz with
/// ζ = 2 capped at a quarter of the substep rate, relax and warm start on, no restitution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepSettings {
    /// Substeps per step (Box2D v3: 4).
    pub substeps: usize,
    /// Iterations per substep (`DEFAULT_ITERATIONS` for this module's solver).
    pub iterations: usize,
    /// Stiffness of the soft step's equality rows (Box2D `jointHertz`: 60 Hz).
    pub hertz: f64,
    /// Damping ratio of the soft step's equality rows (Box2D `jointDampingRatio`: 2).
    pub damping_ratio: f64,
    /// Cap `hertz` at a quarter of the substep rate, as Box2D does.
    pub cap_hertz: bool,
    /// The soft step's relax pass (a rigid pass without bias after the positions move).
    pub relax: bool,
    /// Start each step from the last step's impulses.
    pub warm_start: bool,
    /// Coefficient of restitution of closing inequality rows, in [0, 1].
    pub restitution: f64,
    /// Approaches slower than this (in Ċ/κ units) do not bounce (Box2D: 1 m/s).
    pub restitution_threshold: f64,
    /// PGS's Baumgarte factor β: bias β·C/h (Box2D v2.4: 0.2).
    pub baumgarte: f64,
}

impl Default for StepSettings {
    fn default() -> StepSettings {
        StepSettings {
            substeps: 4,
            iterations: DEFAULT_ITERATIONS,
            hertz: 60.0,
            damping_ratio: 2.0,
            cap_hertz: true,
            relax: true,
            warm_start: true,
            restitution: 0.0,
            restitution_threshold: 1.0,
            baumgarte: 0.2,
        }
    }
}

#[allow(dead_code)]
impl StepSettings {
    /// The stiffness equality rows get at substep h: `hertz`, capped at a quarter of 1/h.
    pub fn joint_hertz(&self, h: f64) -> f64 {
        if self.cap_hertz { self.hertz.min(0.25 / h) } else { self.hertz }
    }

    /// The softness of equality rows at substep h.
    pub fn joint_softness(&self, h: f64) -> Softness {
        Softness::new(self.joint_hertz(h), self.damping_ratio, h)
    }

    /// The softness of penetrating inequality rows at substep h (Box2D's contact softness).
    pub fn contact_softness(&self, h: f64) -> Softness {
        let hertz = if self.cap_hertz { CONTACT_HERTZ.min(0.25 / h) } else { CONTACT_HERTZ };
        Softness::new(hertz, CONTACT_DAMPING_RATIO, h)
    }
}

/// The rows at a state as the step reads them (`step_rows`): per row C/κ, Ċ/κ, c, J; per
/// slot (the bodies, then the rigid bodies' angular slots, as `numeric::rows` lays them out)
/// 1/m, v and the scene's force; with 3D rigid bodies each slot's principal axis (zero for a
/// linear slot; empty otherwise).
struct StepRows<const D: usize> {
    rows: Vec<Row<D>>,
    inverse_mass: Vec<f64>,
    velocity: Vec<[f64; D]>,
    force: Vec<[f64; D]>,
    axes: Vec<[f64; D]>,
}

/// The rows of one substep, flattened: per row its C/κ, ∂C/∂t, effective mass
/// 1/(J M⁻¹ Jᵀ) and its Jacobian entries (slot, Jᵢ: a body's Jᵛ or an angular slot's Jʷ);
/// per slot 1/m (1/I) and F (τ).
#[allow(dead_code)]
struct Prepared<const D: usize> {
    /// Entries of row k: `start[k]..start[k + 1]`.
    start: Vec<usize>,
    body: Vec<usize>,
    jacobian: Vec<[f64; D]>,
    value: Vec<f64>,
    /// ∂C/∂t = Ċ − J·v at the evaluated state.
    time_rate: Vec<f64>,
    /// m_eff = 1/(J M⁻¹ Jᵀ); 0 where J = 0 (a singular configuration: the row does nothing).
    effective_mass: Vec<f64>,
    inequality: Vec<bool>,
    inverse_mass: Vec<f64>,
    force: Vec<[f64; D]>,
    /// Per slot its principal axis (empty without 3D rigid bodies).
    axes: Vec<[f64; D]>,
    /// Per slot the velocity the rows were evaluated at (3D rigid bodies: the body-frame ω
    /// their gyroscopic term was taken at; empty without 3D rigid bodies).
    velocity: Vec<[f64; D]>,
    /// The first 3D rigid body's first slot (`None` without 3D rigid bodies).
    first: Option<usize>,
}

/// a·b, summed from 0 as the library sums its three components (the same number, zero's
/// sign included).
fn dot<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    let mut s = 0.0;
    for d in 0..D {
        s += a[d] * b[d];
    }
    s
}

#[allow(dead_code)]
impl<const D: usize> Prepared<D> {
    /// From the rows at a state (`step_rows`), evaluated at the velocities they carry.
    fn new(r: &StepRows<D>) -> Prepared<D> {
        let rows = &r.rows;
        let first = r.axes.iter().position(|e| e.iter().any(|&x| x != 0.0));
        let mut p = Prepared {
            start: Vec::with_capacity(rows.len() + 1),
            body: Vec::new(),
            jacobian: Vec::new(),
            value: Vec::with_capacity(rows.len()),
            time_rate: Vec::with_capacity(rows.len()),
            effective_mass: Vec::with_capacity(rows.len()),
            inequality: Vec::with_capacity(rows.len()),
            inverse_mass: r.inverse_mass.clone(),
            force: r.force.clone(),
            axes: r.axes.clone(),
            velocity: if first.is_some() { r.velocity.clone() } else { Vec::new() },
            first,
        };
        for row in rows {
            p.start.push(p.body.len());
            let (mut k, mut jv) = (0.0, 0.0);
            for (b, j) in &row.jacobian {
                p.body.push(*b);
                p.jacobian.push(*j);
                k += r.inverse_mass[*b] * dot(j, j);
                jv += dot(j, &r.velocity[*b]);
            }
            p.value.push(row.value);
            p.time_rate.push(row.rate - jv);
            p.effective_mass.push(if k > 0.0 && k.is_finite() { 1.0 / k } else { 0.0 });
            p.inequality.push(row.inequality);
        }
        p.start.push(p.body.len());
        p
    }

    fn len(&self) -> usize {
        self.value.len()
    }

    /// Ċₖ at velocities `u`: Σᵢ Jₖᵢ·uᵢ + ∂Cₖ/∂t.
    fn rate(&self, k: usize, u: &[[f64; D]]) -> f64 {
        let mut c = self.time_rate[k];
        for e in self.start[k]..self.start[k + 1] {
            c += dot(&self.jacobian[e], &u[self.body[e]]);
        }
        c
    }

    /// Applies an impulse `p` of row k: uᵢ += (1/mᵢ) Jₖᵢ p.
    fn apply(&self, k: usize, u: &mut [[f64; D]], p: f64) {
        for e in self.start[k]..self.start[k + 1] {
            let (b, j) = (self.body[e], &self.jacobian[e]);
            let s = self.inverse_mass[b] * p;
            for d in 0..D {
                u[b][d] += s * j[d];
            }
        }
    }
}
