//! `lagrange bench` on every scene file (the `precision` module): a table of 12+ rows, an
//! SVG, and formula accuracy.

mod common;

use lagrange::precision::accuracy::formula_accuracy;
use lagrange::precision::{Sweep, work_precision};
use lagrange::report::{plot, precision};

fn scene_files() -> Vec<String> {
    let mut files = Vec::new();
    for dir in ["constraints", "constraints/hard"] {
        for entry in std::fs::read_dir(dir).expect("dir") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                files.push(path.display().to_string());
            }
        }
    }
    files.sort();
    files
}

#[test]
fn bench_writes_a_table_and_a_plot_for_every_scene_file() {
    let mut benched = 0;
    for path in scene_files() {
        // Files without a runnable scene (no initial state) are not scene files.
        let text = std::fs::read_to_string(&path).expect("file");
        let Ok(loaded) = lagrange::model::file::load(&text) else { continue };
        let Ok(s) = lagrange::scenario::Scenario::new(loaded, &[]) else { continue };
        benched += 1;
        // A short sweep (10 steps at the coarsest) keeps this fast; the table's shape is the point.
        let mut sweep = Sweep::new(s.scene.dt, 40.0 * s.scene.dt);
        if path.contains("chain_100") {
            sweep.duration = 8.0 * s.scene.dt;
            sweep.refinement = 2.0;
        }
        let wp = work_precision(&s, &sweep).expect("sweep");
        assert!(wp.rows.len() >= 12, "{path}: {} rows", wp.rows.len());
        let accuracy = formula_accuracy(&s, 8, 7);
        assert!(!accuracy.is_empty(), "{path}");
        let json = precision::json(&wp, &accuracy);
        assert_eq!(json["rows"].as_array().map(Vec::len), Some(wp.rows.len()));
        assert!(precision::text(&wp, &accuracy).lines().count() >= 12);
        assert!(precision::csv(&wp, &accuracy).lines().count() >= 13);
        let svg = plot::work_precision(&path, "time", "error", &precision::lines(&wp)).expect("svg");
        assert!(svg.starts_with("<svg") && svg.contains("</svg>"), "{path}");
    }
    assert!(benched >= 15, "only {benched} scene files");
}

#[test]
fn pendulum_work_precision_ranks_the_methods() {
    let s = common::scenario("constraints/pendulum.toml");
    let wp = work_precision(&s, &Sweep::new(1e-3, 2.0)).expect("sweep");
    let error = |integrator: &str, dt: f64| {
        wp.rows
            .iter()
            .find(|r| r.integrator == integrator && r.stabilize == "projection" && (r.dt - dt).abs() < 1e-12)
            .and_then(|r| r.final_error)
            .expect("row")
    };
    // At every step size RK4 beats Verlet beats Euler, and every error falls as dt does.
    for dt in [4e-3, 2e-3, 1e-3, 5e-4] {
        assert!(error("rk4", dt) < error("verlet", dt) && error("verlet", dt) < error("euler", dt), "dt {dt}");
    }
    assert!(error("verlet", 5e-4) < error("verlet", 4e-3) / 16.0);
    let accuracy = formula_accuracy(&s, 100, 3);
    assert!(accuracy.iter().all(|a| a.median_rel_error <= 1e-15 && a.max_rel_error <= 1e-13), "{accuracy:?}");
}

#[test]
fn a_sweep_that_cannot_run_is_refused_by_cause() {
    use lagrange::precision::SweepError;
    let s = common::scenario("constraints/pendulum.toml");
    let mut sweep = Sweep::new(1e-3, 1.0);
    sweep.steps.truncate(3);
    assert_eq!(work_precision(&s, &sweep).err(), Some(SweepError::TooFewSteps(3)));
    let mut sweep = Sweep::new(1e-3, 1.0);
    sweep.steps[0] = f64::NAN;
    assert_eq!(sweep.validate(), Err(SweepError::Step));
    assert_eq!(Sweep::new(1e-3, -1.0).validate(), Err(SweepError::Duration(-1.0)));
    let mut sweep = Sweep::new(1e-3, 1.0);
    sweep.integrators.clear();
    assert_eq!(sweep.validate(), Err(SweepError::Empty));
}

/// A rigid body on a fixed axle through its centre, in 2D (a constant torque) and in 3D
/// (spinning torque-free about no principal axis): its position never moves, so only its
/// orientation tells the methods apart. The final-state error counts the turn from the
/// reference orientation: every Euler run is off by more than 1e-6 rad and less at each
/// smaller step (it counted positions only, and was 0 for every run).
#[test]
fn the_final_state_error_counts_orientations() {
    let body = |dim: usize| {
        let inertia = if dim == 2 { "0.5" } else { "[1.0, 2.0, 3.0]" };
        let (zero, orientation, omega) =
            if dim == 2 { ("[0, 0]", "0.0", "2.0") } else { ("[0, 0, 0]", "[1.0, 0.0, 0.0, 0.0]", "[1.0, 2.0, 0.5]") };
        let torque = if dim == 2 { "\nforces = { T = \"0.3\" }" } else { "" };
        format!(
            "title = \"Axle\"\ndimension = {dim}\n\n[[bodies]]\nname = \"wheel\"\nposition = \"x\"\nvelocity = \"v\"\n\
             acceleration = \"a\"\nmass = \"m\"\nforce = \"F\"\norientation = \"q\"\nangular_velocity = \"w\"\n\
             angular_acceleration = \"alpha\"\ninertia = \"I\"\ntorque = \"T\"\n\n[[constraints]]\nname = \"axle\"\n\
             expr = \"x = {zero}\"\n\n[scene]\ninitial = {{ x = {zero}, v = {zero}, m = 1.0, I = {inertia}, q = {orientation}, w = {omega} }}{torque}\n"
        )
    };
    for dim in [2, 3] {
        let text = body(dim);
        let loaded = lagrange::model::file::load(&text).unwrap_or_else(|e| panic!("{e:?}\n{text}"));
        let s = lagrange::scenario::Scenario::new(loaded, &[]).unwrap_or_else(|e| panic!("{e:?}"));
        let wp = work_precision(&s, &Sweep::new(1e-2, 0.2)).expect("sweep");
        let euler: Vec<f64> = wp
            .rows
            .iter()
            .filter(|r| r.integrator == "euler" && r.stabilize == "projection")
            .map(|r| r.final_error.expect("a final error"))
            .collect();
        assert_eq!(euler.len(), 4, "{dim}D");
        assert!(euler.iter().all(|e| *e > 1e-6), "{dim}D: {euler:?}");
        assert!(euler.windows(2).all(|w| w[1] < w[0]), "{dim}D: the error falls with the step: {euler:?}");
    }
}
