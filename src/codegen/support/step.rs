//! Written into every module generated with `--solver`: the pieces of the velocity-level
//! step that every solver shares — Box2D's softness (`b2MakeSoft`), the step's settings with
//! Box2D v3's defaults, the rows of one substep flattened with their effective masses
//! (`Prepared`, over the slots of `numeric::rows`: the bodies, then the rigid bodies' angular
//! slots; arrays of the module's sizes that its `prepare` fills in place). The same operations in the same order as the library's `numeric::velocity`
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

/// The rows at a state as the exact step reads them (`step_rows`): per row C/κ, Ċ/κ, c, J;
/// per slot (the bodies, then the rigid bodies' angular slots, as `numeric::rows` lays them
/// out) 1/m, v and the scene's force; with 3D rigid bodies each slot's principal axis (zero
/// for a linear slot; empty otherwise).
#[allow(dead_code)]
struct StepRows<const D: usize> {
    rows: Vec<Row<D>>,
    inverse_mass: Vec<f64>,
    velocity: Vec<[f64; D]>,
    force: Vec<[f64; D]>,
    axes: Vec<[f64; D]>,
}

/// The rows of one substep, flattened: per row its C/κ, ∂C/∂t, effective mass
/// 1/(J M⁻¹ Jᵀ) and its Jacobian entries `ROW_START[k]..ROW_START[k + 1]` (entry e on slot
/// `ROW_BODY[e]`: a body's Jᵛ or an angular slot's Jʷ, in the step's order: `ENTRY_AT`);
/// per slot 1/m (1/I) and F (τ). Arrays of the module's sizes, filled in place (`prepare`),
/// so a step allocates nothing.
#[allow(dead_code)]
struct Prepared<const D: usize> {
    jacobian: [[f64; D]; ENTRIES],
    value: [f64; CONSTRAINTS],
    /// ∂C/∂t = Ċ − J·v at the evaluated state (0 on a `STEADY` row).
    time_rate: [f64; CONSTRAINTS],
    /// m_eff = 1/(J M⁻¹ Jᵀ); 0 where J = 0 (a singular configuration: the row does nothing).
    effective_mass: [f64; CONSTRAINTS],
    /// Per `UNIT` row, its m_eff where J is a number: 1/Σᵢ 1/mᵢ, a constant of the masses
    /// (`unit_masses`), which `unit_row` reads where the positions move.
    unit_mass: [f64; CONSTRAINTS],
    inverse_mass: [f64; SLOTS],
    force: [[f64; D]; SLOTS],
    /// Per slot its principal axis (`AXES` is 0 without 3D rigid bodies).
    axes: [[f64; D]; AXES],
    /// Per slot the velocity the rows were evaluated at (3D rigid bodies: the body-frame ω
    /// their gyroscopic term was taken at; none without 3D rigid bodies).
    velocity: [[f64; D]; AXES],
    /// The first 3D rigid body's first slot (`None` without 3D rigid bodies).
    first: Option<usize>,
}

/// a·b, summed from the first product as the library's `velocity::dot_in` sums the scene's
/// components (the same number, zero's sign included).
#[inline(always)]
fn dot<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    let mut s = a[0] * b[0];
    for d in 1..D {
        s += a[d] * b[d];
    }
    s
}

/// m_eff = 1/m from m = Σᵢ |Jᵢ|²/mᵢ, 0 unless m is positive and finite (a singular
/// configuration: the row does nothing).
#[inline(always)]
fn effective_mass(m: f64) -> f64 {
    if m > 0.0 && m.is_finite() { 1.0 / m } else { 0.0 }
}

/// |J_b|² of an entry of a `UNIT` row (every entry a unit vector, ±e/|e|: the library's
/// `velocity::pattern::unit_square`): exactly 1 where J_b is a number, NaN where it is not
/// (e = 0), so that `effective_mass` gives 0 there as from the numbers: 1 + 0·J₀ + 0·J₁ …,
/// without a branch.
#[inline(always)]
fn unit_square<const D: usize>(j: &[f64; D]) -> f64 {
    j.iter().fold(1.0, |s, x| s + 0.0 * x)
}

/// Whether every component of `js` is a number (x − x is +0 for a number, NaN for ±∞ and NaN):
/// a `UNIT` row's test for its m_eff (`unit_square`), without a branch per component.
#[inline(always)]
fn numbers<'a, const D: usize>(js: impl Iterator<Item = &'a [f64; D]>) -> bool {
    js.flatten().fold(0.0, |s, x| s + (x - x)) == 0.0
}

/// |J|² of an entry of row k as its m_eff takes it: `unit_square` on a `UNIT` row, else J·J
/// (`dot`, as the library's `velocity::dot_in`).
#[inline(always)]
fn square<const D: usize>(k: usize, j: &[f64; D]) -> f64 {
    if UNIT[k] { unit_square(j) } else { dot(j, j) }
}

/// Σ_d term(d) over the first D components, the terms `None` left out, summed from the first
/// kept one (0 when none is), written out component by component: `dot_coded`'s and
/// `square_coded`'s sum.
#[inline(always)]
fn sum_kept<const D: usize>(term: impl Fn(usize) -> Option<f64>) -> f64 {
    let add = |s: Option<f64>, x: Option<f64>| match (s, x) {
        (Some(s), Some(x)) => Some(s + x),
        (None, x) => x,
        (s, None) => s,
    };
    let mut s = term(0);
    if D > 1 {
        s = add(s, term(1));
    }
    if D > 2 {
        s = add(s, term(2));
    }
    s.unwrap_or(0.0)
}

/// a·b over the components `c` codes (two bits per component, as `ENTRY_CODE`: 0 a structural
/// zero, left out; 2 a = +1, the product b; 3 a = −1, the product −b; 1 a·b), summed from the
/// first of them, as the library's `velocity::dot_masked` sums them (1·b = b and (−1)·b = −b
/// exactly: the same number, zero's sign included). Written out component by component (no
/// loop), so that with `c` a constant every test folds away.
#[inline(always)]
fn dot_coded<const D: usize>(c: u8, a: &[f64; D], b: &[f64; D]) -> f64 {
    let term = |d: usize| match c >> (2 * d) & 3 {
        0 => None,
        1 => Some(a[d] * b[d]),
        2 => Some(b[d]),
        _ => Some(-b[d]),
    };
    sum_kept::<D>(term)
}

/// |a|² over the components `c` codes (as `dot_coded`; a component ±1 adds 1 exactly), summed
/// from the first of them, written out component by component.
#[inline(always)]
fn square_coded<const D: usize>(c: u8, a: &[f64; D]) -> f64 {
    let term = |d: usize| match c >> (2 * d) & 3 {
        0 => None,
        1 => Some(a[d] * a[d]),
        _ => Some(1.0),
    };
    sum_kept::<D>(term)
}

/// uᵢ += s·Jᵢ over the components `c` codes (as `dot_coded`: none for a structural zero, s for
/// +1, −s for −1), written out component by component.
#[inline(always)]
fn add_coded<const D: usize>(c: u8, u: &mut [f64; D], j: &[f64; D], s: f64) {
    let mut one = |d: usize| match c >> (2 * d) & 3 {
        0 => {}
        1 => u[d] += s * j[d],
        2 => u[d] += s,
        _ => u[d] += -s,
    };
    one(0);
    if D > 1 {
        one(1);
    }
    if D > 2 {
        one(2);
    }
}

#[allow(dead_code)]
impl Prepared<DIM> {
    /// From the rows at a state (`step_rows`), evaluated at the velocities they carry.
    fn new(r: &StepRows<DIM>) -> Prepared<DIM> {
        let mut p = Prepared::zeroed();
        let mut e = 0;
        for (k, row) in r.rows.iter().enumerate() {
            // The derivation's order into the step's (`ENTRY_AT`).
            for (_, j) in &row.jacobian {
                p.jacobian[ENTRY_AT[e]] = *j;
                e += 1;
            }
            p.value[k] = row.value;
            p.time_rate[k] = row.rate;
        }
        p.inverse_mass.copy_from_slice(&r.inverse_mass);
        p.force.copy_from_slice(&r.force);
        if !r.axes.is_empty() {
            p.axes.copy_from_slice(&r.axes);
            p.first = r.axes.iter().position(|e| e.iter().any(|&x| x != 0.0));
            if p.first.is_some() {
                p.velocity.copy_from_slice(&r.velocity);
            }
        }
        p.finish(&r.velocity);
        p
    }

    /// With C/κ, J, 1/m and F in place and Ċ/κ in `time_rate`: each row's effective mass
    /// 1/Σᵢ |Jᵢ|²/mᵢ (`mass`, by the row's kind) and ∂C/∂t = Ċ/κ − J·v at the evaluated
    /// velocities `velocity` (0 on a `STEADY` row, whose C reads no time).
    #[inline(always)]
    fn finish(&mut self, velocity: &[[f64; DIM]]) {
        for k in 0..CONSTRAINTS {
            let m = self.mass(k);
            let mut jv = 0.0;
            if !STEADY[k] {
                for e in ROW_START[k]..ROW_START[k + 1] {
                    jv += dot_coded(ENTRY_CODE[e], &self.jacobian[e], &velocity[ROW_BODY[e]]);
                }
            }
            self.time_rate[k] = if STEADY[k] { 0.0 } else { self.time_rate[k] - jv };
            self.effective_mass[k] = effective_mass(m);
        }
    }
}

#[allow(dead_code)]
impl<const D: usize> Prepared<D> {
    /// Room for the rows, to be filled by `prepare` (or `new`).
    fn zeroed() -> Prepared<D> {
        Prepared {
            jacobian: [[0.0; D]; ENTRIES],
            value: [0.0; CONSTRAINTS],
            time_rate: [0.0; CONSTRAINTS],
            effective_mass: [0.0; CONSTRAINTS],
            unit_mass: [0.0; CONSTRAINTS],
            inverse_mass: [0.0; SLOTS],
            force: [[0.0; D]; SLOTS],
            axes: [[0.0; D]; AXES],
            velocity: [[0.0; D]; AXES],
            first: None,
        }
    }

    /// Row k at a state: C/κ `value`, Ċ/κ `rate` (not read on a `STEADY` row) and its
    /// Jacobian `entries` (body, Jᵢ), stored from entry `first` on, with its effective mass
    /// and ∂C/∂t = Ċ/κ − J·v at the evaluated velocities `velocity`: `finish`'s operations for
    /// one row, its bodies' 1/m in place. A `UNIT` row's m_eff is `effective_mass` of
    /// Σᵢ 1/mᵢ where every entry is a number, else 0 (`mass`'s number: each `unit_square` 1,
    /// or NaN), so it waits on no J but a test: with the masses constants of the module, as
    /// where `prepare` writes them out, the division folds away.
    #[inline(always)]
    fn row<const E: usize>(
        &mut self,
        k: usize,
        (value, rate): (f64, f64),
        first: usize,
        entries: [(usize, [f64; D]); E],
        velocity: &[[f64; D]],
    ) {
        let (mut m, mut jv) = (0.0, 0.0);
        for (e, (b, j)) in entries.iter().enumerate() {
            self.jacobian[first + e] = *j;
            m += self.inverse_mass[*b] * if UNIT[k] { 1.0 } else { dot(j, j) };
            if !STEADY[k] {
                jv += dot_coded(ENTRY_CODE[first + e], j, &velocity[*b]);
            }
        }
        self.value[k] = value;
        self.time_rate[k] = if STEADY[k] { 0.0 } else { rate - jv };
        self.effective_mass[k] = if !UNIT[k] || numbers(entries.iter().map(|(_, j)| j)) { effective_mass(m) } else { 0.0 };
    }

    /// Row k's entries `j` in the step's order, stored from entry `e` on, with `finish`'s
    /// operations for a row whose C reads no time (`STEADY`): ∂C/∂t = 0 (`time_rate`'s 0 from
    /// `zeroed` on: nothing writes another on such a row), and the returned m =
    /// Σᵢ |Jᵢ|²/mᵢ over the entries in the step's order from 0 (over every component: a
    /// structural zero's square is +0 and (±1)² = 1, so `mass`'s number), from the entries as
    /// evaluated rather than read back; m_eff is `effective_mass(m)`.
    #[inline(always)]
    fn steady_row<const N: usize>(&mut self, k: usize, e: usize, j: [[f64; D]; N]) -> f64 {
        let mut m = 0.0;
        for (x, j) in j.iter().enumerate() {
            m += self.inverse_mass[ROW_BODY[e + x]] * square(k, j);
        }
        self.jacobian[e..e + N].copy_from_slice(&j);
        m
    }

    /// Each `UNIT` row's m_eff where its J is a number, from its bodies' 1/m in place:
    /// `effective_mass` of Σᵢ 1/mᵢ over its entries in the step's order from 0 (`mass`'s
    /// number, each |Jᵢ|² exactly 1), once per state of the masses (`prepare`).
    fn unit_masses(&mut self) {
        for k in (0..CONSTRAINTS).filter(|&k| UNIT[k]) {
            let mut m = 0.0;
            for e in ROW_START[k]..ROW_START[k + 1] {
                m += self.inverse_mass[ROW_BODY[e]];
            }
            self.unit_mass[k] = effective_mass(m);
        }
    }

    /// `steady_row` for a `UNIT` row, returning its m_eff: `unit_mass` where every entry is a
    /// number (each `unit_square` 1), else 0 (`effective_mass` of `mass`'s NaN), without a
    /// sum of masses or a division. (A test per component, which a row of numbers passes
    /// predictably: quicker here than `unit_square`'s products.)
    #[inline(always)]
    fn unit_row<const N: usize>(&mut self, k: usize, e: usize, j: [[f64; D]; N]) -> f64 {
        let number = j.iter().all(|j| j.iter().all(|x| x.is_finite()));
        self.jacobian[e..e + N].copy_from_slice(&j);
        if number { self.unit_mass[k] } else { 0.0 }
    }

    /// Row k's m_eff from the m = Σᵢ |Jᵢ|²/mᵢ left in its place (`steady_row`).
    #[inline(always)]
    fn invert_mass(&mut self, k: usize) {
        self.effective_mass[k] = effective_mass(self.effective_mass[k]);
    }

    fn len(&self) -> usize {
        CONSTRAINTS
    }

    /// Ċₖ at velocities `u`: ∂Cₖ/∂t + Σᵢ Jₖᵢ·uᵢ, summed in that order over the row's entries
    /// as they are kept (the library's `velocity::entry_order`: the velocity the row before
    /// wrote last is the last term), each product over its entry's components as `codes`
    /// gives them (`dot_coded`; the row's `ENTRY_CODE`, as constants where `rate` calls it
    /// by the row's kind).
    #[inline(always)]
    fn rate_in(&self, k: usize, codes: &[u8], u: &[[f64; D]]) -> f64 {
        let first = ROW_START[k];
        let mut c = self.time_rate[k];
        for (e, &code) in codes.iter().enumerate() {
            c += dot_coded(code, &self.jacobian[first + e], &u[ROW_BODY[first + e]]);
        }
        c
    }

    /// `rate_in` with the row's `N` codes as one constant, a byte each from the lowest
    /// (`CODES`): each kind's its own function, so the compiler writes each kind's products
    /// for its pattern (with the codes as values, it may merge the kinds' calls into one
    /// that reads them as it runs).
    #[inline(always)]
    fn rate_of<const N: usize, const CODES: u128>(&self, k: usize, u: &[[f64; D]]) -> f64 {
        let first = ROW_START[k];
        let (j, b) = (&self.jacobian[first..first + N], &ROW_BODY[first..first + N]);
        let mut c = self.time_rate[k];
        for e in 0..N {
            c += dot_coded((CODES >> (8 * e)) as u8, &j[e], &u[b[e]]);
        }
        c
    }

    /// Σᵢ |Jᵢ|²/mᵢ of row k over its entries in the step's order, from 0 (`finish`): each
    /// |Jᵢ|² over the components `codes` keeps, a component ±1 adding 1 (`square_coded`; the
    /// structural zeros' squares are +0 and (±1)² = 1, so the same number as over every
    /// component); on a `UNIT` row `unit_square`.
    #[inline(always)]
    fn mass_in(&self, k: usize, codes: &[u8]) -> f64 {
        let first = ROW_START[k];
        let mut m = 0.0;
        for (e, &code) in codes.iter().enumerate() {
            let j = &self.jacobian[first + e];
            m += self.inverse_mass[ROW_BODY[first + e]] * if UNIT[k] { unit_square(j) } else { square_coded(code, j) };
        }
        m
    }

    /// `mass_in` with the row's codes as one constant (as `rate_of`).
    #[inline(always)]
    fn mass_of<const N: usize, const CODES: u128>(&self, k: usize) -> f64 {
        let first = ROW_START[k];
        let (j, b) = (&self.jacobian[first..first + N], &ROW_BODY[first..first + N]);
        let mut m = 0.0;
        for e in 0..N {
            let code = (CODES >> (8 * e)) as u8;
            m += self.inverse_mass[b[e]] * if UNIT[k] { unit_square(&j[e]) } else { square_coded(code, &j[e]) };
        }
        m
    }

    /// `mass_in` for a row none of whose components is a structural zero or ±1.
    #[inline(always)]
    fn mass_dense(&self, k: usize) -> f64 {
        let mut m = 0.0;
        for e in ROW_START[k]..ROW_START[k + 1] {
            m += self.inverse_mass[ROW_BODY[e]] * square(k, &self.jacobian[e]);
        }
        m
    }

    /// `rate_in` for a row none of whose components is a structural zero or ±1: the same sum
    /// as a loop over its entries.
    #[inline(always)]
    fn rate_dense(&self, k: usize, u: &[[f64; D]]) -> f64 {
        let mut c = self.time_rate[k];
        for e in ROW_START[k]..ROW_START[k + 1] {
            c += dot(&self.jacobian[e], &u[ROW_BODY[e]]);
        }
        c
    }

    /// `rate_dense` for an axis row (`ROW_KIND`; `velocity::pattern`: its two entries J and −J,
    /// bit for bit): n = its first entry's J, read once, and (∂C/∂t + n·u_a) − n·u_b, the same
    /// number as the sum with −n ((−n)·u = −(n·u) exactly).
    #[inline(always)]
    fn rate_axis(&self, k: usize, u: &[[f64; D]]) -> f64 {
        let e = ROW_START[k];
        let n = &self.jacobian[e];
        (self.time_rate[k] + dot(n, &u[ROW_BODY[e]])) - dot(n, &u[ROW_BODY[e + 1]])
    }

    /// `apply_dense` for an axis row (`rate_axis`): u_a += (p/m_a) n, u_b −= (p/m_b) n, the
    /// same numbers as adding (p/m_b)·(−n).
    #[inline(always)]
    fn apply_axis(&self, k: usize, u: &mut [[f64; D]], p: f64) {
        let e = ROW_START[k];
        let (n, a, b) = (&self.jacobian[e], ROW_BODY[e], ROW_BODY[e + 1]);
        let s = self.inverse_mass[a] * p;
        for d in 0..D {
            u[a][d] += s * n[d];
        }
        let s = self.inverse_mass[b] * p;
        for d in 0..D {
            u[b][d] -= s * n[d];
        }
    }

    /// Applies an impulse `p` of row k: uᵢ += (1/mᵢ) Jₖᵢ p, on the components `codes` keeps
    /// (as for `rate_in`: s·0 would leave uᵢ as it is but for a zero's sign; s·(±1) is ±s).
    #[inline(always)]
    fn apply_in(&self, k: usize, codes: &[u8], u: &mut [[f64; D]], p: f64) {
        let first = ROW_START[k];
        for (e, &code) in codes.iter().enumerate() {
            let (b, j) = (ROW_BODY[first + e], &self.jacobian[first + e]);
            add_coded(code, &mut u[b], j, self.inverse_mass[b] * p);
        }
    }

    /// `apply_in` with the row's codes as one constant (as `rate_of`).
    #[inline(always)]
    fn apply_of<const N: usize, const CODES: u128>(&self, k: usize, u: &mut [[f64; D]], p: f64) {
        let first = ROW_START[k];
        let (j, b) = (&self.jacobian[first..first + N], &ROW_BODY[first..first + N]);
        for e in 0..N {
            add_coded((CODES >> (8 * e)) as u8, &mut u[b[e]], &j[e], self.inverse_mass[b[e]] * p);
        }
    }

    /// `apply_in` for a row none of whose components is a structural zero or ±1.
    #[inline(always)]
    fn apply_dense(&self, k: usize, u: &mut [[f64; D]], p: f64) {
        for e in ROW_START[k]..ROW_START[k + 1] {
            let (b, j) = (ROW_BODY[e], &self.jacobian[e]);
            let s = self.inverse_mass[b] * p;
            for d in 0..D {
                u[b][d] += s * j[d];
            }
        }
    }
}
