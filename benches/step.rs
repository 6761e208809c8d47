//! The generated soft step against a handwritten Box2D-style step, in the same run.
//!
//! Three scenes of point masses joined by distance constraints (`constraints/solvers/`):
//! Catto's two particles (2 bodies, 2 rows), Solver2D's ball and chain (40 links and a
//! 4 021 kg ball, 41 rows) and its joint grid of 30 × 30 (870 bodies below a fixed row,
//! 1 711 rows; its module written with `--step-only`, the rows by shape). Each is stepped by:
//! - `handwritten`: the soft step written by hand the way Box2D v3 writes it
//!   (`src/solver.c` stages `b2IntegrateVelocitiesTask`, `b2WarmStartJointsTask`,
//!   `b2SolveJointsTask`, `b2IntegratePositionsTask`, relax; `src/distance_joint.c`'s
//!   rigid row with `b2MakeSoft`'s softness): bodies as arrays, each joint two body indices
//!   (an anchor is a static body of inverse mass 0), its length and its accumulated
//!   impulse. It runs the algorithm of lagrange's soft step — the rows (axis, C, effective
//!   mass) evaluated where each substep starts and again after the positions move — where
//!   Box2D re-normalises the axis in every warm start, solve and relax; so it is the
//!   baseline for the same work, and it agrees with the generated step to round-off
//!   (checked before the samples: `agree`).
//! - `generated`: `lagrange generate FILE --solver soft-step`'s module, checked in under
//!   `benches/generated/` (kept current by `tests/generate.rs`), stepped by its `Stepper`
//!   (the impulses and the rows the last step left, as the handwritten world keeps them:
//!   the rows evaluated once per substep; `step(state, impulses, dt)` evaluates them once
//!   more, at its start).
//! - `library`: `lagrange simulate --solver soft-step`'s step (`numeric::velocity::Stepper`
//!   over the compiled tape's rows), for scale.
//!
//! Two scenes of 2D rigid bodies joined by revolute joints: the rigid ball and chain (40
//! capsule links and a disc of 4 021 kg, 41 joints, 82 rows) and the 10 × 10 rigid joint
//! grid (90 discs below a fixed row, 171 joints, 342 rows; `--step-only`). Their
//! `handwritten` step is Box2D v3's revolute joint written by hand (`src/revolute_joint.c`'s
//! prepare, warm start and point-to-point solve: lever arms rA, rB, the separation, the 2×2
//! K = [[mA + mB + iA rAy² + iB rBy², −iA rAx rAy − iB rBx rBy], [·, mA + mB + iA rAx² +
//! iB rBx²]] and `b2MakeSoft`; no spring, motor or limit, no restitution), with lagrange's
//! algorithm where the two differ, so that it agrees with the generated step (`agree_rigid`):
//! the rows evaluated once per substep and after the positions move (Box2D rotates the
//! prepared anchors by each body's turn since the step's start in every pass), θ += hω
//! (Box2D integrates a rotation), and a pin's two rows solved one after the other with
//! their diagonal masses 1/K₁₁, 1/K₂₂, as lagrange sweeps rows (Box2D solves the 2×2 block:
//! its fixed point differs with softness, `numeric::velocity`'s note). `handwritten_block`
//! is the same step with Box2D's block ΔP = −s_m K⁻¹(Ċ + biasRate·C) − s_i P (K⁻¹ once per
//! substep): a different iteration, measured and not compared.
//!
//! Every sample is one step of 1/60 s with Box2D's defaults (4 substeps, one iteration,
//! joints at 60 Hz capped at a quarter of the substep rate, ζ = 2, relax, warm start), from
//! the state 100 steps after the scene's start and going on from there.
//!
//! Run: `cargo bench --bench step`.

/// The same allocator as the `lagrange` binary.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

use divan::{Bencher, black_box};
use lagrange::model::file::load;
use lagrange::numeric::dynamics::Dynamics;
use lagrange::numeric::integrate::Vectors;
use lagrange::numeric::velocity::{Settings, Solver, Stepper};
use lagrange::scenario::Scenario;

/// The generated module of a scene, with a constructor of its state from positions (inside
/// the module, so it may use the module's private `put`).
macro_rules! generated {
    ($name:ident, $file:literal) => {
        #[allow(dead_code, clippy::all)]
        mod $name {
            include!($file);

            /// The state at rest at positions `q`, under g = (0, −10), anchored at the origin.
            pub fn at_rest(q: &[[f64; 2]]) -> State {
                let mut s = State::default();
                s.g = [0.0, -10.0];
                s.a1 = [0.0, 0.0];
                let q: &[[f64; 2]; SLOTS] = q.try_into().expect("one position per body");
                put(&mut s, 0.0, q, &[[0.0; 2]; SLOTS], &[]);
                s
            }
        }
    };
}

generated!(two_particles, "generated/two_particles_step.rs");
generated!(ball_and_chain, "generated/ball_and_chain_step.rs");

/// The 30 × 30 grid's step-only module (`--step-only`: its rows by shape).
#[allow(dead_code, clippy::all)]
mod joint_grid_30 {
    include!("generated/joint_grid_30_step.rs");

    /// The file's initial state: at rest at `q`, under g = (0, −10), anchors a1…a30 at (c, 0).
    pub fn at_rest(q: &[[f64; 2]]) -> State {
        let mut s = State::default();
        s.g = [0.0, -10.0];
        macro_rules! anchors {
            ($($a:ident = $x:literal),*) => { $(s.$a = [$x, 0.0];)* };
        }
        anchors!(a1 = 0.0, a2 = 1.0, a3 = 2.0, a4 = 3.0, a5 = 4.0, a6 = 5.0, a7 = 6.0, a8 = 7.0, a9 = 8.0, a10 = 9.0);
        anchors!(a11 = 10.0, a12 = 11.0, a13 = 12.0, a14 = 13.0, a15 = 14.0, a16 = 15.0, a17 = 16.0, a18 = 17.0);
        anchors!(a19 = 18.0, a20 = 19.0, a21 = 20.0, a22 = 21.0, a23 = 22.0, a24 = 23.0, a25 = 24.0, a26 = 25.0);
        anchors!(a27 = 26.0, a28 = 27.0, a29 = 28.0, a30 = 29.0);
        let q: &[[f64; 2]; SLOTS] = q.try_into().expect("one position per body");
        put(&mut s, 0.0, q, &[[0.0; 2]; SLOTS], &[]);
        s
    }
}

/// A rigid scene's generated module (its bodies 2D rigid bodies), with a constructor of its
/// state from the handwritten world's.
macro_rules! generated_rigid {
    ($name:ident, $file:literal) => {
        #[allow(dead_code, clippy::all)]
        mod $name {
            include!($file);

            /// The state at rest at positions `x` and angles `theta`, under g = (0, −10): the
            /// slots are the bodies' positions, then per rigid body [θ, 0].
            pub fn at_rest(x: &[[f64; 2]], theta: &[f64]) -> State {
                let mut s = State::default();
                s.g = [0.0, -10.0];
                let mut q = [[0.0; 2]; SLOTS];
                for (i, (x, th)) in x.iter().zip(theta).enumerate() {
                    q[i] = *x;
                    q[BODIES + i] = [*th, 0.0];
                }
                put(&mut s, 0.0, &q, &[[0.0; 2]; SLOTS], &[]);
                s
            }
        }
    };
}

generated_rigid!(rigid_ball_and_chain, "generated/rigid_ball_and_chain_step.rs");
generated_rigid!(rigid_grid_10, "generated/rigid_grid_10_step.rs");

fn main() {
    divan::main();
}

const DT: f64 = 1.0 / 60.0;
/// Steps run before the samples start (and compared between the steps, `agree`).
const WARM: usize = 100;

// ---- the handwritten step -------------------------------------------------------------

/// A distance joint between bodies `a` and `b`: |q_b − q_a| = length.
#[derive(Clone, Copy)]
struct Joint {
    a: usize,
    b: usize,
    length: f64,
    /// The accumulated impulse (the warm-start storage).
    impulse: f64,
}

/// Box2D's `b2Softness` (`b2MakeSoft`).
#[derive(Clone, Copy)]
struct Soft {
    bias_rate: f64,
    mass_scale: f64,
    impulse_scale: f64,
}

fn make_soft(hertz: f64, zeta: f64, h: f64) -> Soft {
    let omega = 2.0 * std::f64::consts::PI * hertz;
    let a1 = 2.0 * zeta + h * omega;
    let a2 = h * omega * a1;
    let a3 = 1.0 / (1.0 + a2);
    Soft { bias_rate: omega / a1, mass_scale: a2 * a3, impulse_scale: a3 }
}

/// Point masses and distance joints, laid out as Box2D lays out a world: the first
/// `dynamic` bodies move, the others are static (inverse mass 0, never integrated).
struct World {
    dynamic: usize,
    q: Vec<[f64; 2]>,
    v: Vec<[f64; 2]>,
    inverse_mass: Vec<f64>,
    /// External force per body (gravity times mass).
    force: Vec<[f64; 2]>,
    joints: Vec<Joint>,
    /// Per joint, where the substep's rows were evaluated: the unit axis from a to b, C and
    /// the effective mass 1/(1/m_a + 1/m_b).
    axis: Vec<[f64; 2]>,
    c: Vec<f64>,
    mass: Vec<f64>,
}

impl World {
    /// Bodies at `q` of mass `mass` at rest under g = (0, −10), static anchors at `anchors`
    /// (body `q.len() + j` is anchor j), and unit-length joints between the bodies `pairs`.
    fn new(q: &[[f64; 2]], mass: &[f64], anchors: &[[f64; 2]], pairs: &[(usize, usize)]) -> World {
        let (n, k) = (q.len(), pairs.len());
        let statics = anchors.len();
        let mut w = World {
            dynamic: n,
            q: q.iter().chain(anchors).copied().collect(),
            v: vec![[0.0; 2]; n + statics],
            inverse_mass: mass.iter().map(|m| 1.0 / m).chain(vec![0.0; statics]).collect(),
            force: mass.iter().map(|m| [0.0, -10.0 * m]).chain(vec![[0.0; 2]; statics]).collect(),
            joints: pairs.iter().map(|&(a, b)| Joint { a, b, length: 1.0, impulse: 0.0 }).collect(),
            axis: vec![[0.0; 2]; k],
            c: vec![0.0; k],
            mass: vec![0.0; k],
        };
        w.prepare();
        w
    }

    /// A chain hanging from an anchor at the origin: body i at `q[i]` of mass `mass[i]`,
    /// joined to the one before (the first to the anchor) at unit length.
    fn chain(q: &[[f64; 2]], mass: &[f64]) -> World {
        let n = q.len();
        let pairs: Vec<(usize, usize)> = (0..n).map(|i| (if i == 0 { n } else { i - 1 }, i)).collect();
        World::new(q, mass, &[[0.0, 0.0]], &pairs)
    }

    /// Solver2D's joint grid as `joint_grid_30.toml` writes it: `rows` × `columns` points of
    /// 1 kg at (c, −r) below anchors at (c, 0), each joined to the one above and the one on
    /// its left, in the file's order (per point: up, then left).
    fn grid(rows: usize, columns: usize) -> World {
        let at = |r: usize, c: usize| (r - 1) * columns + c;
        let mut q = Vec::new();
        let mut pairs = Vec::new();
        for r in 1..=rows {
            for c in 0..columns {
                q.push([c as f64, -(r as f64)]);
                pairs.push((if r == 1 { rows * columns + c } else { at(r - 1, c) }, at(r, c)));
                if c > 0 {
                    pairs.push((at(r, c - 1), at(r, c)));
                }
            }
        }
        let anchors: Vec<[f64; 2]> = (0..columns).map(|c| [c as f64, 0.0]).collect();
        World::new(&q, &vec![1.0; q.len()], &anchors, &pairs)
    }

    /// The rows at the current positions (Box2D's prepare, here once per substep).
    fn prepare(&mut self) {
        for (j, joint) in self.joints.iter().enumerate() {
            let (qa, qb) = (self.q[joint.a], self.q[joint.b]);
            let d = [qb[0] - qa[0], qb[1] - qa[1]];
            let length = (d[0] * d[0] + d[1] * d[1]).sqrt();
            let inv = 1.0 / length;
            self.axis[j] = [d[0] * inv, d[1] * inv];
            self.c[j] = length - joint.length;
            let k = self.inverse_mass[joint.a] + self.inverse_mass[joint.b];
            self.mass[j] = if k > 0.0 { 1.0 / k } else { 0.0 };
        }
    }

    /// Applies impulse `p` along joint j's axis: v_a −= p n/m_a, v_b += p n/m_b.
    #[inline(always)]
    fn apply(v: &mut [[f64; 2]], inverse_mass: &[f64], joint: &Joint, n: [f64; 2], p: f64) {
        let (wa, wb) = (inverse_mass[joint.a] * p, inverse_mass[joint.b] * p);
        v[joint.a][0] -= wa * n[0];
        v[joint.a][1] -= wa * n[1];
        v[joint.b][0] += wb * n[0];
        v[joint.b][1] += wb * n[1];
    }

    /// One Gauss–Seidel pass over the joints with softness `soft` (`b2SolveDistanceJoint`'s
    /// rigid row: ΔP = −s_m·m·(Ċ + biasRate·C) − s_i·P).
    fn solve(&mut self, soft: Soft) {
        let (v, w) = (&mut self.v, &self.inverse_mass);
        for (j, joint) in self.joints.iter_mut().enumerate() {
            let n = self.axis[j];
            let (va, vb) = (v[joint.a], v[joint.b]);
            let cdot = n[0] * (vb[0] - va[0]) + n[1] * (vb[1] - va[1]);
            let impulse = -soft.mass_scale * self.mass[j] * (cdot + soft.bias_rate * self.c[j])
                - soft.impulse_scale * joint.impulse;
            joint.impulse += impulse;
            World::apply(v, w, joint, n, impulse);
        }
    }

    /// One step of `dt` in 4 substeps (Box2D v3's `b2SolverStage_*` order).
    fn step(&mut self, dt: f64) {
        let substeps = 4;
        let h = dt / substeps as f64;
        let joint_soft = make_soft(60.0f64.min(0.25 / h), 2.0, h);
        let rigid = Soft { bias_rate: 0.0, mass_scale: 1.0, impulse_scale: 0.0 };
        for _ in 0..substeps {
            // Integrate velocities.
            for i in 0..self.dynamic {
                let s = h * self.inverse_mass[i];
                self.v[i][0] += s * self.force[i][0];
                self.v[i][1] += s * self.force[i][1];
            }
            // Warm start.
            for (j, joint) in self.joints.iter().enumerate() {
                World::apply(&mut self.v, &self.inverse_mass, joint, self.axis[j], joint.impulse);
            }
            // Solve, with the soft bias.
            self.solve(joint_soft);
            // Integrate positions.
            for i in 0..self.dynamic {
                self.q[i][0] += h * self.v[i][0];
                self.q[i][1] += h * self.v[i][1];
            }
            self.prepare();
            // Relax: rigid, no bias.
            self.solve(rigid);
        }
    }

    fn impulses(&self) -> Vec<f64> {
        self.joints.iter().map(|j| j.impulse).collect()
    }
}

// ---- the handwritten step for rigid bodies and revolute joints ------------------------

/// A revolute (point) joint: body a's point at `la` in a's frame on body b's point at `lb`
/// (Box2D v3 `src/revolute_joint.c`'s point-to-point part; no spring, motor or limit).
#[derive(Clone, Copy)]
struct Pin {
    a: usize,
    b: usize,
    la: [f64; 2],
    lb: [f64; 2],
    /// The accumulated linear impulse on b (Box2D's `linearImpulse`; −a's).
    impulse: [f64; 2],
}

/// How a pin's two rows are solved: one after the other as lagrange sweeps them (`Rows`),
/// or as Box2D's 2×2 block (`Block`).
#[derive(Clone, Copy, PartialEq)]
enum Pins {
    Rows,
    Block,
}

/// 2D rigid bodies and revolute joints, laid out as Box2D lays out a world: the first
/// `dynamic` bodies move, the others are static (inverse mass and inertia 0, never
/// integrated); an anchor in the world is a static body at the point.
struct RigidWorld {
    dynamic: usize,
    x: Vec<[f64; 2]>,
    theta: Vec<f64>,
    v: Vec<[f64; 2]>,
    w: Vec<f64>,
    inverse_mass: Vec<f64>,
    inverse_inertia: Vec<f64>,
    /// External force per body (gravity times mass); no torque.
    force: Vec<[f64; 2]>,
    pins: Vec<Pin>,
    pin_solve: Pins,
    /// Per body (cos θ, sin θ) where the rows were evaluated (scratch of `prepare`).
    rotation: Vec<[f64; 2]>,
    /// Per pin, where the substep's rows were evaluated: the lever arms rA = R(θa) la and
    /// rB = R(θb) lb, the separation C = (xb + rB) − (xa + rA), and either the two rows'
    /// effective masses 1/K₁₁ and 1/K₂₂ (`Rows`) or K⁻¹ as [a, b, d] of [[a, b], [b, d]]
    /// (`Block`).
    ra: Vec<[f64; 2]>,
    rb: Vec<[f64; 2]>,
    c: Vec<[f64; 2]>,
    mass: Vec<[f64; 3]>,
}

impl RigidWorld {
    /// Bodies at `x` (angle 0, at rest) of masses `mass` and inertias `inertia` under
    /// g = (0, −10), static anchors at `anchors` (body `x.len() + j` is anchor j), and `pins`.
    fn new(x: &[[f64; 2]], mass: &[f64], inertia: &[f64], anchors: &[[f64; 2]], pins: Vec<Pin>) -> RigidWorld {
        let (n, k) = (x.len(), pins.len());
        let bodies = n + anchors.len();
        let statics = vec![0.0; anchors.len()];
        let mut w = RigidWorld {
            dynamic: n,
            x: x.iter().chain(anchors).copied().collect(),
            theta: vec![0.0; bodies],
            v: vec![[0.0; 2]; bodies],
            w: vec![0.0; bodies],
            inverse_mass: mass.iter().map(|m| 1.0 / m).chain(statics.clone()).collect(),
            inverse_inertia: inertia.iter().map(|i| 1.0 / i).chain(statics).collect(),
            force: mass.iter().map(|m| [0.0, -10.0 * m]).chain(vec![[0.0; 2]; anchors.len()]).collect(),
            pins,
            pin_solve: Pins::Rows,
            rotation: vec![[1.0, 0.0]; bodies],
            ra: vec![[0.0; 2]; k],
            rb: vec![[0.0; 2]; k],
            c: vec![[0.0; 2]; k],
            mass: vec![[0.0; 3]; k],
        };
        w.prepare();
        w
    }

    /// Solver2D's ball and chain as `rigid_ball_and_chain.toml` writes it: 40 capsule links
    /// of length 1 along +x from an anchor at the origin, end to end, and a disc of radius 8
    /// pinned at its rim to the last link's end.
    fn ball_and_chain() -> RigidWorld {
        let (link, link_inertia) = (5.981747704246811, 0.7478984966677974);
        let (ball, ball_inertia) = (4021.238596594935, 128679.63509103793);
        let mut x: Vec<[f64; 2]> = (0..40).map(|i| [i as f64 + 0.5, 0.0]).collect();
        x.push([48.0, 0.0]);
        let mut mass = vec![link; 40];
        mass.push(ball);
        let mut inertia = vec![link_inertia; 40];
        inertia.push(ball_inertia);
        let pin = |a, la, b, lb| Pin { a, b, la, lb, impulse: [0.0; 2] };
        let mut pins = vec![pin(41, [0.0, 0.0], 0, [-0.5, 0.0])];
        pins.extend((1..40).map(|i| pin(i - 1, [0.5, 0.0], i, [-0.5, 0.0])));
        pins.push(pin(39, [0.5, 0.0], 40, [-8.0, 0.0]));
        RigidWorld::new(&x, &mass, &inertia, &[[0.0, 0.0]], pins)
    }

    /// Box2D's joint grid as `rigid_grid_10.toml` writes it: discs of radius 0.4 (density 1)
    /// at (c, −r) for r = 1…9, c = 0…9, each pinned at the midpoints to the one above (the
    /// first row to world points at (c, −0.5)) and the one on its left, in the file's order
    /// (per disc: up, then left).
    fn grid() -> RigidWorld {
        let (rows, columns) = (9, 10);
        let at = |r: usize, c: usize| (r - 1) * columns + c;
        let pin = |a, la, b, lb| Pin { a, b, la, lb, impulse: [0.0; 2] };
        let (mut x, mut pins) = (Vec::new(), Vec::new());
        for r in 1..=rows {
            for c in 0..columns {
                x.push([c as f64, -(r as f64)]);
                pins.push(if r == 1 {
                    pin(rows * columns + c, [0.0, 0.0], at(r, c), [0.0, 0.5])
                } else {
                    pin(at(r - 1, c), [0.0, -0.5], at(r, c), [0.0, 0.5])
                });
                if c > 0 {
                    pins.push(pin(at(r, c - 1), [0.5, 0.0], at(r, c), [-0.5, 0.0]));
                }
            }
        }
        let anchors: Vec<[f64; 2]> = (0..columns).map(|c| [c as f64, -0.5]).collect();
        let n = x.len();
        RigidWorld::new(&x, &vec![0.5026548245743669; n], &vec![0.040212385965949365; n], &anchors, pins)
    }

    /// The rows at the current positions (Box2D's prepare, here once per substep): per pin
    /// the lever arms, the separation and K = [[mA + mB + iA rAy² + iB rBy², −iA rAx rAy −
    /// iB rBx rBy], [·, mA + mB + iA rAx² + iB rBx²]] (`b2SolveRevoluteJoint`'s K).
    fn prepare(&mut self) {
        for (r, &theta) in self.rotation.iter_mut().zip(&self.theta) {
            let (s, c) = theta.sin_cos();
            *r = [c, s];
        }
        let turn = |r: [f64; 2], l: [f64; 2]| [r[0] * l[0] - r[1] * l[1], r[1] * l[0] + r[0] * l[1]];
        for (j, pin) in self.pins.iter().enumerate() {
            let (a, b) = (pin.a, pin.b);
            let ra = turn(self.rotation[a], pin.la);
            let rb = turn(self.rotation[b], pin.lb);
            let (xa, xb) = (self.x[a], self.x[b]);
            self.c[j] = [xb[0] + rb[0] - (xa[0] + ra[0]), xb[1] + rb[1] - (xa[1] + ra[1])];
            let (ma, mb, ia, ib) =
                (self.inverse_mass[a], self.inverse_mass[b], self.inverse_inertia[a], self.inverse_inertia[b]);
            let k11 = ma + mb + ia * ra[1] * ra[1] + ib * rb[1] * rb[1];
            let k12 = -ia * ra[0] * ra[1] - ib * rb[0] * rb[1];
            let k22 = ma + mb + ia * ra[0] * ra[0] + ib * rb[0] * rb[0];
            self.mass[j] = match self.pin_solve {
                Pins::Rows => [1.0 / k11, 0.0, 1.0 / k22],
                Pins::Block => {
                    let inv = 1.0 / (k11 * k22 - k12 * k12);
                    [k22 * inv, -k12 * inv, k11 * inv]
                }
            };
            self.ra[j] = ra;
            self.rb[j] = rb;
        }
    }

    /// Applies impulse `p` of pin j to its bodies: b gets p at rB, a gets −p at rA.
    #[inline(always)]
    fn apply(&mut self, j: usize, p: [f64; 2]) {
        let (pin, ra, rb) = (self.pins[j], self.ra[j], self.rb[j]);
        let (ma, ia) = (self.inverse_mass[pin.a], self.inverse_inertia[pin.a]);
        let (mb, ib) = (self.inverse_mass[pin.b], self.inverse_inertia[pin.b]);
        self.v[pin.a][0] -= ma * p[0];
        self.v[pin.a][1] -= ma * p[1];
        self.w[pin.a] -= ia * (ra[0] * p[1] - ra[1] * p[0]);
        self.v[pin.b][0] += mb * p[0];
        self.v[pin.b][1] += mb * p[1];
        self.w[pin.b] += ib * (rb[0] * p[1] - rb[1] * p[0]);
    }

    /// One Gauss–Seidel pass over the pins with softness `soft`: Ċ = (vB + ωB × rB) −
    /// (vA + ωA × rA); `Rows`: row x, then row y with the velocities row x left,
    /// ΔPᵢ = −s_m·(Ċᵢ + biasRate·Cᵢ)/Kᵢᵢ − s_i·Pᵢ; `Block`: ΔP = −s_m·K⁻¹(Ċ + biasRate·C) −
    /// s_i·P (`b2SolveRevoluteJoint`'s point-to-point block).
    fn solve(&mut self, soft: Soft) {
        for j in 0..self.pins.len() {
            let pin = self.pins[j];
            let (ra, rb, c, k) = (self.ra[j], self.rb[j], self.c[j], self.mass[j]);
            let rate = |w: &RigidWorld, d: usize| {
                let (va, vb, wa, wb) = (w.v[pin.a][d], w.v[pin.b][d], w.w[pin.a], w.w[pin.b]);
                if d == 0 { vb - wb * rb[1] - (va - wa * ra[1]) } else { vb + wb * rb[0] - (va + wa * ra[0]) }
            };
            let old = self.pins[j].impulse;
            match self.pin_solve {
                Pins::Rows => {
                    let px =
                        -soft.mass_scale * k[0] * (rate(self, 0) + soft.bias_rate * c[0]) - soft.impulse_scale * old[0];
                    self.apply(j, [px, 0.0]);
                    let py =
                        -soft.mass_scale * k[2] * (rate(self, 1) + soft.bias_rate * c[1]) - soft.impulse_scale * old[1];
                    self.apply(j, [0.0, py]);
                    self.pins[j].impulse = [old[0] + px, old[1] + py];
                }
                Pins::Block => {
                    let (bx, by) = (rate(self, 0) + soft.bias_rate * c[0], rate(self, 1) + soft.bias_rate * c[1]);
                    let p = [
                        -soft.mass_scale * (k[0] * bx + k[1] * by) - soft.impulse_scale * old[0],
                        -soft.mass_scale * (k[1] * bx + k[2] * by) - soft.impulse_scale * old[1],
                    ];
                    self.apply(j, p);
                    self.pins[j].impulse = [old[0] + p[0], old[1] + p[1]];
                }
            }
        }
    }

    /// One step of `dt` in 4 substeps (Box2D v3's `b2SolverStage_*` order).
    fn step(&mut self, dt: f64) {
        let substeps = 4;
        let h = dt / substeps as f64;
        let joint_soft = make_soft(60.0f64.min(0.25 / h), 2.0, h);
        let rigid = Soft { bias_rate: 0.0, mass_scale: 1.0, impulse_scale: 0.0 };
        for _ in 0..substeps {
            // Integrate velocities (no torque).
            for i in 0..self.dynamic {
                let s = h * self.inverse_mass[i];
                self.v[i][0] += s * self.force[i][0];
                self.v[i][1] += s * self.force[i][1];
            }
            // Warm start.
            for j in 0..self.pins.len() {
                self.apply(j, self.pins[j].impulse);
            }
            // Solve, with the soft bias.
            self.solve(joint_soft);
            // Integrate positions: x += h v, θ += h ω (lagrange's; Box2D turns a rotation).
            for i in 0..self.dynamic {
                self.x[i][0] += h * self.v[i][0];
                self.x[i][1] += h * self.v[i][1];
                self.theta[i] += h * self.w[i];
            }
            self.prepare();
            // Relax: rigid, no bias.
            self.solve(rigid);
        }
    }

    /// The impulses per row as lagrange's rows count them: its C is the file's lhs − rhs,
    /// (xa + rA) − (xb + rB), the opposite of the separation, so its impulses are −P.
    fn impulses(&self) -> Vec<f64> {
        self.pins.iter().flat_map(|p| [-p.impulse[0], -p.impulse[1]]).collect()
    }
}

// ---- the scenes -----------------------------------------------------------------------

/// Catto's two particles: inverse masses 0.167 and 0.000995 hanging 1 m apart below the origin.
fn two_particles_start() -> (Vec<[f64; 2]>, Vec<f64>) {
    (vec![[0.0, -1.0], [0.0, -2.0]], vec![5.988023952095808, 1005.0251256281407])
}

/// The ball and chain: 40 links of 6 kg and a 4 021 kg ball, 1 m apart along +x from the origin.
fn ball_and_chain_start() -> (Vec<[f64; 2]>, Vec<f64>) {
    let q: Vec<[f64; 2]> = (1..=41).map(|i| [i as f64, 0.0]).collect();
    let mut m = vec![6.0; 41];
    m[40] = 4021.0;
    (q, m)
}

/// The library's stepper on a scene file, with the rows it steps from.
struct Library {
    scenario: Scenario,
    q: Vec<[f64; 3]>,
    v: Vec<[f64; 3]>,
    t: f64,
}

impl Library {
    fn new(text: &str) -> Library {
        let scenario = Scenario::new(load(text).expect("scene file"), &[]).expect("derives");
        let (q, v, t) = lagrange::numeric::simulate::initial_state(&scenario.system, &scenario.env);
        Library { scenario, q, v, t }
    }

    /// Runs `f` with a stepper and the dynamics it steps.
    fn with<R>(
        &mut self,
        f: impl FnOnce(&mut Stepper, &mut Dynamics<'_>, &mut Vectors, &mut Vectors, &mut f64) -> R,
    ) -> R {
        let s = &self.scenario;
        let mut dynamics = Dynamics::new(&s.system, s.program.clone(), s.env.clone());
        let settings = Settings::new(Solver::SoftStep, DT, 1e9 * DT);
        let mut stepper = Stepper::new(settings, s.system.constraints.len(), self.q.len());
        f(&mut stepper, &mut dynamics, &mut self.q, &mut self.v, &mut self.t)
    }
}

fn library_step(stepper: &mut Stepper, dynamics: &mut Dynamics<'_>, q: &mut Vectors, v: &mut Vectors, t: &mut f64) {
    let rows = dynamics.rows(*t, q, v).expect("rows");
    stepper.step(dynamics, *t, q, v, rows).expect("steps");
    *t += DT;
}

/// The handwritten and the generated step agree to round-off after `WARM` steps: positions
/// within 1e-9 m, impulses within 1e-9 of the largest.
fn agree(name: &str, hand: &World, q: &[[f64; 2]], impulses: &[f64]) {
    let dq = hand.q.iter().zip(q).map(|(a, b)| (a[0] - b[0]).abs().max((a[1] - b[1]).abs())).fold(0.0, f64::max);
    let scale = impulses.iter().fold(1.0f64, |m, p| m.max(p.abs()));
    let dp = hand.impulses().iter().zip(impulses).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max) / scale;
    assert!(dq <= 1e-9 && dp <= 1e-9, "{name}: handwritten and generated steps part: {dq:e} m, {dp:e} of the impulses");
}

/// The handwritten rigid step and the generated one agree to round-off after `WARM` steps:
/// positions within 1e-9 m, angles within 1e-9 rad, impulses within 1e-9 of the largest.
fn agree_rigid(name: &str, hand: &RigidWorld, x: &[[f64; 2]], theta: &[f64], impulses: &[f64]) {
    let n = hand.dynamic;
    let dx = hand.x[..n].iter().zip(x).map(|(a, b)| (a[0] - b[0]).abs().max((a[1] - b[1]).abs())).fold(0.0, f64::max);
    let dth = hand.theta[..n].iter().zip(theta).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    let scale = impulses.iter().fold(1.0f64, |m, p| m.max(p.abs()));
    let dp = hand.impulses().iter().zip(impulses).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max) / scale;
    assert!(
        dx <= 1e-9 && dth <= 1e-9 && dp <= 1e-9,
        "{name}: handwritten and generated steps part: {dx:e} m, {dth:e} rad, {dp:e} of the impulses"
    );
}

// ---- the benchmarks -------------------------------------------------------------------

mod two {
    use super::*;

    #[divan::bench]
    fn handwritten(bencher: Bencher) {
        let (q, m) = two_particles_start();
        let mut w = World::chain(&q, &m);
        (0..WARM).for_each(|_| w.step(DT));
        bencher.bench_local(|| w.step(black_box(DT)));
    }

    #[divan::bench]
    fn generated(bencher: Bencher) {
        use super::two_particles as g;
        let (q, m) = two_particles_start();
        let mut s = g::at_rest(&q);
        let mut p = g::Stepper::new();
        (0..WARM).for_each(|_| p.step(&mut s, DT));
        let mut w = World::chain(&q, &m);
        (0..WARM).for_each(|_| w.step(DT));
        agree("two particles", &w, &g::positions(&s), &p.impulses);
        bencher.bench_local(|| p.step(&mut s, black_box(DT)));
    }

    #[divan::bench]
    fn library(bencher: Bencher) {
        let mut l = Library::new(include_str!("../constraints/solvers/two_particles.toml"));
        l.with(|stepper, dynamics, q, v, t| {
            (0..WARM).for_each(|_| library_step(stepper, dynamics, q, v, t));
            bencher.bench_local(|| library_step(stepper, dynamics, q, v, t));
        });
    }
}

mod chain {
    use super::*;

    #[divan::bench]
    fn handwritten(bencher: Bencher) {
        let (q, m) = ball_and_chain_start();
        let mut w = World::chain(&q, &m);
        (0..WARM).for_each(|_| w.step(DT));
        bencher.bench_local(|| w.step(black_box(DT)));
    }

    #[divan::bench]
    fn generated(bencher: Bencher) {
        use super::ball_and_chain as g;
        let (q, m) = ball_and_chain_start();
        let mut s = g::at_rest(&q);
        let mut p = g::Stepper::new();
        (0..WARM).for_each(|_| p.step(&mut s, DT));
        let mut w = World::chain(&q, &m);
        (0..WARM).for_each(|_| w.step(DT));
        agree("ball and chain", &w, &g::positions(&s), &p.impulses);
        bencher.bench_local(|| p.step(&mut s, black_box(DT)));
    }

    #[divan::bench]
    fn library(bencher: Bencher) {
        let mut l = Library::new(include_str!("../constraints/solvers/ball_and_chain.toml"));
        l.with(|stepper, dynamics, q, v, t| {
            (0..WARM).for_each(|_| library_step(stepper, dynamics, q, v, t));
            bencher.bench_local(|| library_step(stepper, dynamics, q, v, t));
        });
    }
}

mod grid_30 {
    use super::*;

    #[divan::bench]
    fn handwritten(bencher: Bencher) {
        let mut w = World::grid(29, 30);
        (0..WARM).for_each(|_| w.step(DT));
        bencher.bench_local(|| w.step(black_box(DT)));
    }

    #[divan::bench]
    fn generated(bencher: Bencher) {
        use super::joint_grid_30 as g;
        let mut w = World::grid(29, 30);
        let mut s = Box::new(g::at_rest(&w.q[..w.dynamic]));
        let mut p = Box::new(g::Stepper::new());
        (0..WARM).for_each(|_| p.step(&mut s, DT));
        (0..WARM).for_each(|_| w.step(DT));
        agree("30 x 30 grid", &w, &g::positions(&s), &p.impulses[..]);
        bencher.bench_local(|| p.step(&mut s, black_box(DT)));
    }

    #[divan::bench(sample_count = 20)]
    fn library(bencher: Bencher) {
        let mut l = Library::new(include_str!("../constraints/solvers/joint_grid_30.toml"));
        l.with(|stepper, dynamics, q, v, t| {
            (0..WARM).for_each(|_| library_step(stepper, dynamics, q, v, t));
            bencher.bench_local(|| library_step(stepper, dynamics, q, v, t));
        });
    }
}

/// The rigid scenes' benchmarks: `handwritten` (the pins' rows one after the other, as
/// lagrange sweeps them; checked against `generated`), `handwritten_block` (Box2D's 2×2
/// block per pin: a different iteration, not compared), `generated` and `library`.
macro_rules! rigid_benches {
    ($name:ident, $module:ident, $world:expr, $file:literal, $label:literal) => {
        mod $name {
            use super::*;

            #[divan::bench]
            fn handwritten(bencher: Bencher) {
                let mut w = $world;
                (0..WARM).for_each(|_| w.step(DT));
                bencher.bench_local(|| w.step(black_box(DT)));
            }

            #[divan::bench]
            fn handwritten_block(bencher: Bencher) {
                let mut w = $world;
                w.pin_solve = Pins::Block;
                w.prepare();
                (0..WARM).for_each(|_| w.step(DT));
                bencher.bench_local(|| w.step(black_box(DT)));
            }

            #[divan::bench]
            fn generated(bencher: Bencher) {
                use super::$module as g;
                let mut w = $world;
                let mut s = Box::new(g::at_rest(&w.x[..w.dynamic], &w.theta[..w.dynamic]));
                let mut p = Box::new(g::Stepper::new());
                (0..WARM).for_each(|_| p.step(&mut s, DT));
                (0..WARM).for_each(|_| w.step(DT));
                agree_rigid($label, &w, &g::positions(&s), &g::orientations(&s), &p.impulses[..]);
                bencher.bench_local(|| p.step(&mut s, black_box(DT)));
            }

            #[divan::bench(sample_count = 20)]
            fn library(bencher: Bencher) {
                let mut l = Library::new(include_str!($file));
                l.with(|stepper, dynamics, q, v, t| {
                    (0..WARM).for_each(|_| library_step(stepper, dynamics, q, v, t));
                    bencher.bench_local(|| library_step(stepper, dynamics, q, v, t));
                });
            }
        }
    };
}

rigid_benches!(
    rigid_chain,
    rigid_ball_and_chain,
    RigidWorld::ball_and_chain(),
    "../constraints/solvers/rigid_ball_and_chain.toml",
    "rigid ball and chain"
);
rigid_benches!(
    rigid_grid,
    rigid_grid_10,
    RigidWorld::grid(),
    "../constraints/solvers/rigid_grid_10.toml",
    "rigid grid 10 x 10"
);
