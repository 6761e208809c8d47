//! The generated pendulum against the textbook rod tension, at states on the constraint
//! (|r| = l, v ⊥ r) with random l, m, g, angle and speed.
//!
//! The closed form: the radial part of Newton's law for a point mass on a rod of length l,
//! m (−v²/l) = m g·r̂ + T, gives the rod's force F_c = −m (v²/l + g·r̂) r̂ (e.g. Taylor,
//! Classical Mechanics, §1.7 and problem 1.39; Kleppner & Kolenkow, §2.4). The file writes
//! C = r·r − l², so ∇C = 2r, κ = 2, J = r and λ (for C/κ) = −m (v·v + g·r)/(r·r).

use lagrange_build_time::pendulum::{self, State};

/// A state on the constraint: angle `theta`, speed `u` along the tangent.
fn state(l: f64, m: f64, g: [f64; 2], theta: f64, u: f64) -> State {
    let mut s = State::default();
    s.l = l;
    s.m = m;
    s.g = g;
    s.r = [l * theta.cos(), l * theta.sin()];
    s.v = [-u * theta.sin(), u * theta.cos()];
    s.F = [m * g[0], m * g[1]];
    s
}

/// A small deterministic generator (SplitMix64) for the states.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        lo + (hi - lo) * ((z >> 11) as f64 / (1u64 << 53) as f64)
    }
}

fn close(a: f64, b: f64, scale: f64) -> bool {
    (a - b).abs() <= 1e-12 * scale
}

#[test]
fn the_generated_lambda_and_force_are_the_rod_tension() {
    let mut rng = Rng(0x5eed);
    for _ in 0..200 {
        let (l, m) = (rng.uniform(0.2, 5.0), rng.uniform(0.1, 10.0));
        let g = [rng.uniform(-3.0, 3.0), rng.uniform(-12.0, -1.0)];
        let (theta, u) = (rng.uniform(-3.2, 3.2), rng.uniform(-4.0, 4.0));
        let s = state(l, m, g, theta, u);
        let r_hat = [s.r[0] / l, s.r[1] / l];
        let radial = -m * (u * u / l + g[0] * r_hat[0] + g[1] * r_hat[1]);
        let scale = m * (u * u / l + g[0].abs() + g[1].abs());
        // λ for C/κ with J = r: F_c = λ r, so λ = radial / l.
        let lambda = pendulum::lambda(&s)[0];
        assert!(close(lambda * l, radial, scale), "λ = {lambda}, expected {}", radial / l);
        let f = pendulum::forces(&s)[0];
        for d in 0..2 {
            assert!(close(f[d], radial * r_hat[d], scale), "F_c = {f:?}, expected {:?}", r_hat.map(|x| radial * x));
        }
        // The rows' solve (the numeric path of `lagrange solve`) agrees with the closed form.
        let x = pendulum::solution(&s);
        assert!(close(x.lambda[0] * l, radial, scale), "solution λ = {}, expected {}", x.lambda[0], radial / l);
        // And the acceleration is the centripetal one plus gravity's tangential part.
        let a = pendulum::accelerations(&s)[0];
        let along: f64 = a[0] * r_hat[0] + a[1] * r_hat[1];
        assert!(close(along, -u * u / l, scale / m), "radial acceleration {along}, expected {}", -u * u / l);
    }
}
