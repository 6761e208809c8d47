//! Solver2D's joint grid as point masses (`constraints/solvers/joint_grid_100.toml`: 100 x 99
//! points of 1 kg 1 m apart below a fixed top row, 19 701 distance rows) stepped the way Box2D
//! v3's `joint_grid` benchmark steps its grid: 500 steps of 1/60 s, 4 substeps, one iteration,
//! joints soft at 60 Hz with ζ = 2 (the module's `step`, Box2D's defaults). Prints the median
//! time per step (steps 2..500), and after the last step how far the joints are from their
//! unit length (| |q_b − q_a| − 1 |, in units of the spacing), max and mean, and where the
//! last body ended (`lagrange simulate FILE --solver soft-step --steps 500` prints the same).
//!
//! Run: `cargo run --release` in this directory.

#[allow(dead_code, clippy::all)]
mod grid {
    include!(concat!(env!("OUT_DIR"), "/joint_grid_100.rs"));
    include!(concat!(env!("OUT_DIR"), "/initial.rs"));
}

use std::time::Instant;

const COLUMNS: usize = 100;
const STEPS: usize = 500;

fn main() {
    let mut s = Box::new(grid::initial());
    let mut impulses = Box::new([0.0; grid::CONSTRAINTS]);
    let mut times = Vec::with_capacity(STEPS);
    for _ in 0..STEPS {
        let start = Instant::now();
        grid::step(&mut s, &mut impulses, 1.0 / 60.0);
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let mut later = times[1..].to_vec();
    later.sort_by(f64::total_cmp);
    let median = later[later.len() / 2];
    // The joints: each point to the one above (the top row to its anchor at (c, 0)) and to
    // the one on its left; body (r, c) of row r = 1..99 is number (r − 1)·100 + c.
    let q = grid::positions(&s);
    let rows = grid::BODIES / COLUMNS;
    let (mut max, mut sum, mut count) = (0.0f64, 0.0, 0usize);
    let mut joint = |a: [f64; 2], b: [f64; 2]| {
        let e = ((b[0] - a[0]).hypot(b[1] - a[1]) - 1.0).abs();
        max = max.max(e);
        sum += e;
        count += 1;
    };
    for r in 0..rows {
        for c in 0..COLUMNS {
            let here = q[r * COLUMNS + c];
            joint(if r == 0 { [c as f64, 0.0] } else { q[(r - 1) * COLUMNS + c] }, here);
            if c > 0 {
                joint(q[r * COLUMNS + c - 1], here);
            }
        }
    }
    println!("{} bodies, {} joints, {STEPS} steps of 1/60 s", grid::BODIES, count);
    println!("time per step: median {median:.3} ms (steps 2..{STEPS})");
    println!("joint error after {STEPS} steps: max {max:.4}, mean {:.4} of the spacing", sum / count as f64);
    // The library's `simulate --solver soft-step --steps 500` ends at the same bits.
    println!("last body at {:?}", q[grid::BODIES - 1]);
}
