//! Box2D v3's `joint_grid` benchmark, 100 x 100 with the top row fixed, stepped by the soft
//! step `lagrange generate --solver soft-step --step-only` writes, generated at build time
//! (`build.rs`), in two forms:
//!
//! - point masses (`constraints/solvers/joint_grid_100.toml`: 100 x 99 points of 1 kg 1 m
//!   apart below a fixed top row, 19 701 distance rows);
//! - rigid discs on revolute joints, as Box2D builds it (`solver_scenes -- rigid_grid 100`:
//!   discs of radius 0.4 at density 1, each pinned to its right and lower neighbours at the
//!   midpoints, the top row's joints pinned to world points; 19 701 joints, 39 402 rows), or
//!   the `RIGID_GRID` size it was built with.
//!
//! Each runs 500 steps of 1/60 s through the module's `Stepper` with Box2D's defaults
//! (`StepSettings::default()`: 4 substeps, one iteration, joints soft at 60 Hz with ζ = 2,
//! relax and warm start on) and prints the median time per step (steps 2..500) and, after the
//! last step, how far the joints are apart in units of the spacing, max and mean: a distance
//! joint's | |q_b − q_a| − 1 |, a revolute joint's |p_a − p_b| between its two anchor points
//! (Box2D's joint separation), and where the last body ended (`lagrange simulate FILE
//! --solver soft-step --steps 500` ends at the same bits).
//!
//! Run: `cargo run --release` in this directory (the rigid grid 30 x 30: it builds in about a
//! minute); `RIGID_GRID=100 cargo run --release` builds Box2D's 100 x 100 (its 5.7 MB module about 2 minutes of rustc). `cargo run --release -- points` or `-- rigid`
//! runs one of the two.

#[allow(dead_code, clippy::all)]
mod points {
    include!(concat!(env!("OUT_DIR"), "/joint_grid_100.rs"));
    include!(concat!(env!("OUT_DIR"), "/initial_points.rs"));
}

#[allow(dead_code, clippy::all)]
mod rigid {
    include!(concat!(env!("OUT_DIR"), "/rigid_grid.rs"));
    include!(concat!(env!("OUT_DIR"), "/initial_rigid.rs"));
}

use std::time::Instant;

const STEPS: usize = 500;
const DT: f64 = 1.0 / 60.0;

fn main() {
    let which = std::env::args().nth(1);
    let run = move || {
        if which.as_deref() != Some("rigid") {
            run_points();
        }
        if which.as_deref() != Some("points") {
            run_rigid();
        }
    };
    // The states, the steppers' kept rows and a substep's rows are a few MB each: a thread
    // with room for them.
    let thread = std::thread::Builder::new().stack_size(1 << 30).spawn(run);
    match thread.map(|t| t.join()) {
        Ok(Ok(())) => {}
        _ => {
            eprintln!("the stepping thread failed");
            std::process::exit(1);
        }
    }
}

/// The median of the times of steps 2..STEPS, in ms.
fn median(times: &[f64]) -> f64 {
    let mut later = times[1..].to_vec();
    later.sort_by(f64::total_cmp);
    later[later.len() / 2]
}

/// Runs `STEPS` steps of `step`, returning each step's time in ms.
fn time(mut step: impl FnMut()) -> Vec<f64> {
    (0..STEPS)
        .map(|_| {
            let start = Instant::now();
            step();
            start.elapsed().as_secs_f64() * 1e3
        })
        .collect()
}

/// Max, mean and count of the errors `joints` reports.
fn summary(joints: impl Fn(&mut dyn FnMut(f64))) -> (f64, f64, usize) {
    let (mut max, mut sum, mut count) = (0.0f64, 0.0, 0usize);
    joints(&mut |e| {
        max = max.max(e);
        sum += e;
        count += 1;
    });
    (max, sum / count as f64, count)
}

fn report(what: &str, bodies: usize, times: &[f64], (max, mean, count): (f64, f64, usize), last: [f64; 2]) {
    println!("{what}: {bodies} bodies, {count} joints, {STEPS} steps of 1/60 s");
    println!("  time per step: median {:.3} ms (steps 2..{STEPS})", median(times));
    println!("  joints apart after {STEPS} steps: max {max:.4}, mean {mean:.4} of the spacing");
    println!("  last body at {last:?}");
}

fn run_points() {
    const COLUMNS: usize = 100;
    let mut s = Box::new(points::initial());
    let mut stepper = Box::new(points::Stepper::new());
    let times = time(|| stepper.step(&mut s, DT));
    // Each point to the one above (the top row to its anchor at (c, 0)) and to the one on
    // its left; body (r, c) of row r = 1..99 is number (r − 1)·100 + c.
    let q = points::positions(&s);
    let rows = points::BODIES / COLUMNS;
    let errors = summary(|joint| {
        let mut link = |a: [f64; 2], b: [f64; 2]| joint(((b[0] - a[0]).hypot(b[1] - a[1]) - 1.0).abs());
        for r in 0..rows {
            for c in 0..COLUMNS {
                let here = q[r * COLUMNS + c];
                link(if r == 0 { [c as f64, 0.0] } else { q[(r - 1) * COLUMNS + c] }, here);
                if c > 0 {
                    link(q[r * COLUMNS + c - 1], here);
                }
            }
        }
    });
    report("point masses, distance joints", points::BODIES, &times, errors, q[points::BODIES - 1]);
}

fn run_rigid() {
    let n = rigid::COLUMNS;
    let mut s = Box::new(rigid::initial());
    let mut stepper = Box::new(rigid::Stepper::new());
    let times = time(|| stepper.step(&mut s, DT));
    let (x, th) = (rigid::positions(&s), rigid::orientations(&s));
    // Body i's point at `l` in its frame: x + R(θ) l.
    let at = |i: usize, l: [f64; 2]| {
        let (sin, cos) = th[i].sin_cos();
        [x[i][0] + cos * l[0] - sin * l[1], x[i][1] + sin * l[0] + cos * l[1]]
    };
    // Disc (r, c) of row r = 1..n − 1 is number (r − 1)·n + c: pinned at (0, 0.5) to the
    // one above at (0, −0.5) (the top row to the world point (c, −0.5)) and at (−0.5, 0) to
    // the one on its left at (0.5, 0).
    let errors = summary(|joint| {
        let mut pin = |a: [f64; 2], b: [f64; 2]| joint((b[0] - a[0]).hypot(b[1] - a[1]));
        for r in 1..n {
            for c in 0..n {
                let me = (r - 1) * n + c;
                pin(if r == 1 { [c as f64, -0.5] } else { at(me - n, [0.0, -0.5]) }, at(me, [0.0, 0.5]));
                if c > 0 {
                    pin(at(me - 1, [0.5, 0.0]), at(me, [-0.5, 0.0]));
                }
            }
        }
    });
    report(&format!("rigid discs {n} x {n}, revolute joints"), rigid::BODIES, &times, errors, x[rigid::BODIES - 1]);
}
