//! The helper functions a generated module carries: the rows' solve of `lagrange solve`
//! (scaled, with contact states, λ ≥ 0 on inequalities and the minimum-norm λ; every
//! module), L D Lᵀ on A's band (the fast path of λ for equalities: tridiagonal or any
//! band), dense L D Lᵀ (of a small A of equalities, with the forces), the range-safe norms and
//! powers the formulas call, and with `--solver` the velocity-level step (shared pieces, the
//! motion of the slots — `motion_3d.rs` with 3D rigid bodies —, the sequential-impulse sweep,
//! and one file per solver).
//!
//! Each lives in a real Rust file beside this one, included as text with `include_str!`
//! and written into a module as it is: from the file's first item on, its `//!` note left
//! out ([`text`]). The crate's tests compile the same files as modules, so a helper that
//! does not compile fails `cargo test`, not a user's build. They are written into every
//! module that needs them, so the module stays self-contained (no dependency on lagrange or
//! any crate).
//!
//! Not here: anything generated from a formula ([`super::rust`]), choosing which helpers a
//! module needs ([`super::layout`]).

/// The solve of `lagrange solve` on a module's rows: `solve_rows`, its types and helpers.
pub(super) const ROWS: &str = text(include_str!("rows.rs"));

/// A λ = −b as its band rows (`band_system`), A not tridiagonal: L D Lᵀ on the band, O(K w²).
pub(super) const SOLVE_BAND: &str = text(include_str!("solve_band.rs"));

/// A λ = −b as its rows (`band_system`), A tridiagonal (a chain listed in order): L D Lᵀ, O(K).
pub(super) const SOLVE_TRIDIAGONAL: &str = text(include_str!("solve_tridiagonal.rs"));

/// A small dense A λ = −b of equalities: Cholesky on the array, the fast path before `solve_rows`.
pub(super) const SOLVE_DENSE: &str = text(include_str!("solve_dense.rs"));

/// The velocity-level step's shared pieces: softness, settings, the prepared rows (`--solver`).
pub(super) const STEP: &str = text(include_str!("step.rs"));

/// The kick and the drift over the slots (`--solver`, no 3D rigid body).
pub(super) const MOTION: &str = text(include_str!("motion.rs"));

/// The kick with the implicit-midpoint gyroscopic term, the exact turn and the changes
/// between world and principal-axis slots (`--solver` with 3D rigid bodies).
pub(super) const MOTION_3D: &str = text(include_str!("motion_3d.rs"));

/// Warm start and the sequential-impulse sweep (`--solver soft-step` and `pgs`).
pub(super) const SWEEP: &str = text(include_str!("sweep.rs"));

/// Box2D v3's soft step (`--solver soft-step`).
pub(super) const SOFT_STEP: &str = text(include_str!("soft_step.rs"));

/// Projected Gauss–Seidel with Baumgarte bias (`--solver pgs`).
pub(super) const PGS: &str = text(include_str!("pgs.rs"));

/// The exact velocity solve and its projection (`--solver exact`).
pub(super) const EXACT: &str = text(include_str!("exact.rs"));

/// What the formulas may call: `norm2`, `norm3`, `powf`; every module carries them.
pub(super) const HELPERS: &str = text(include_str!("helpers.rs"));

/// A helper file's text from its first item on: the leading `//!` lines and the blank line
/// after them are the file's own note, not part of what a module carries.
const fn text(file: &'static str) -> &'static str {
    let bytes = file.as_bytes();
    let mut at = 0;
    // Skip lines that start with `//!`, then one empty line.
    while at + 3 <= bytes.len() && bytes[at] == b'/' && bytes[at + 1] == b'/' && bytes[at + 2] == b'!' {
        while at < bytes.len() && bytes[at] != b'\n' {
            at += 1;
        }
        at += 1;
    }
    if at < bytes.len() && bytes[at] == b'\n' {
        at += 1;
    }
    match file.split_at_checked(at) {
        Some((_, rest)) => rest,
        None => file,
    }
}

// The helper files, compiled as modules (a helper that does not compile fails here). Their
// functions are private: what they compute is tested through generated modules
// (`tests/generate.rs` compiles and runs them).
#[cfg(test)]
#[allow(dead_code)]
mod helpers;
#[cfg(test)]
#[allow(dead_code)]
mod rows;
#[cfg(test)]
#[allow(dead_code)]
mod solve_band;
#[cfg(test)]
#[allow(dead_code)]
mod solve_dense;
#[cfg(test)]
#[allow(dead_code)]
mod solve_tridiagonal;

#[cfg(test)]
mod tests {
    use super::{
        EXACT, HELPERS, MOTION, MOTION_3D, PGS, ROWS, SOFT_STEP, SOLVE_BAND, SOLVE_DENSE, SOLVE_TRIDIAGONAL, STEP,
        SWEEP,
    };

    #[test]
    fn a_helper_is_its_file_without_the_note() {
        for (text, first) in [
            (ROWS, "/// Where an inequality row stands"),
            (SOLVE_BAND, "/// Solves A x = r for a symmetric positive definite band matrix"),
            (SOLVE_TRIDIAGONAL, "/// Solves A x = r for a symmetric positive definite tridiagonal"),
            (SOLVE_DENSE, "/// Solves `a x = b` for a symmetric positive definite `a` by Cholesky"),
            (HELPERS, "/// |(x, y)|"),
            (STEP, "/// Box2D's `b2Softness`"),
            (SWEEP, "/// A step that keeps what the next step starts from"),
            (MOTION, "#[allow(dead_code)]\nimpl<const D: usize> Prepared<D>"),
            (MOTION_3D, "/// The Hamilton product"),
            (SOFT_STEP, "/// One soft step of `dt`"),
            (PGS, "/// One PGS step of `dt`"),
            (EXACT, "/// Relative tolerance"),
        ] {
            assert!(text.starts_with(first), "{text}");
            assert!(!text.contains("//!") && text.ends_with("}\n"), "{text}");
        }
    }
}
