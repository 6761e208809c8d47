//! Generates the pendulum's module into OUT_DIR; a bad constraint file fails the build with
//! the located message `lagrange generate` prints.

fn main() {
    if let Err(e) = lagrange::build::module("../../constraints/pendulum.toml") {
        eprintln!("{e}");
        std::process::exit(1);
    }
}
