//! The pendulum of `constraints/pendulum.toml` as a generated module (`lagrange::build`):
//! `pendulum::State`, `pendulum::lambda`, `pendulum::forces`, … exactly as
//! `lagrange generate constraints/pendulum.toml` writes them.

/// The generated module (`OUT_DIR/pendulum.rs`).
pub mod pendulum {
    include!(concat!(env!("OUT_DIR"), "/pendulum.rs"));
}
