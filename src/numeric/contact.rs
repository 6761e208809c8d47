//! Inequality rows `C ≥ 0` (DESIGN.md step 6): which are touching, resting, separating or
//! closing, and the velocity-level impulses that stop closing contacts.
//!
//! A row is *touching* when its distance |C|/‖∇C‖ is within `contact_tolerance · length_scale`
//! of zero (`Settings`), and its normal speed Ċ/‖∇C‖ counts as zero within
//! `contact_tolerance` times the fastest body it involves (or `Settings::speed_scale`, when
//! faster: a simulation's speeds at rest are rounding). Apart (C > 0) or separating
//! (Ċ > 0) rows carry λ = 0; resting and closing rows are candidates of the force solve;
//! a closing row (Ċ < 0) also needs an impulse.
//!
//! Impulses solve the velocity-level twin of the force problem (Newton's restitution law,
//! as in Moreau's and Stewart–Trinkle's time stepping): find P with
//! u⁺ = J v + A P (the post-impulse rates), Pₖ ≥ 0, u⁺ₖ + e·min(Ċₖ, 0) ≥ 0 and
//! complementarity on touching inequality rows, u⁺ = 0 on equality rows. That is the same QP
//! as the forces with b = J v + e·min(J v, 0); for one contact it is the closed form
//! P = −(1+e) J v / (J M⁻¹ Jᵀ).
//!
//! Not here: the QP itself (`numeric::qp`), integrating (the simulator applies Δv).

use super::rows::Rows;
use super::solve::{Diagnostic, Scaled, Settings, Status, assemble, multipliers};
use super::vector::{row_norm, safe_norm};

/// Where an inequality row stands at a state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactState {
    /// C > 0 beyond the tolerance: no force.
    Apart,
    /// Touching and opening (Ċ > 0): no force.
    Separating,
    /// Touching with Ċ ≈ 0: λ ≥ 0 by complementarity.
    Resting,
    /// Touching and closing (Ċ < 0): needs an impulse; the force solve treats it as resting.
    Closing,
    /// C < 0 beyond the tolerance (drift or a bad state): treated as touching.
    Penetrating,
}

impl ContactState {
    /// Whether the row takes part in the force solve.
    pub fn is_candidate(self) -> bool {
        matches!(self, ContactState::Resting | ContactState::Closing | ContactState::Penetrating)
    }

    pub fn name(self) -> &'static str {
        match self {
            ContactState::Apart => "apart",
            ContactState::Separating => "separating",
            ContactState::Resting => "resting",
            ContactState::Closing => "closing",
            ContactState::Penetrating => "penetrating",
        }
    }
}

/// The state of every inequality row (`None` for equalities).
pub fn classify(rows: &Rows, settings: &Settings) -> Vec<Option<ContactState>> {
    classify_holding(rows, settings, &[])
}

/// [`classify`], with the rows marked in `held` (an active set kept from an earlier state;
/// missing entries are not held) touching whatever their distance: a held contact is
/// resting or closing by its rate, or separating, never apart or penetrating, so the drift
/// of a step cannot release it — only its λ turning negative (or its opening) can.
pub fn classify_holding(rows: &Rows, settings: &Settings, held: &[bool]) -> Vec<Option<ContactState>> {
    let tol = settings.contact_tolerance;
    rows.rows
        .iter()
        .enumerate()
        .map(|(k, row)| {
            if !row.inequality {
                return None;
            }
            let norm = row_norm(&row.jacobian);
            let speed =
                row.jacobian.iter().map(|(b, _)| safe_norm(&rows.velocity[*b])).fold(settings.speed_scale, f64::max);
            if !(norm > 0.0 && norm.is_finite()) {
                // No direction: the row cannot push; whether it holds is C's business.
                return Some(if row.value >= 0.0 { ContactState::Apart } else { ContactState::Penetrating });
            }
            let distance = if held.get(k).copied().unwrap_or(false) { 0.0 } else { row.value / norm };
            let rate = row.rate / norm;
            if distance > tol * settings.length_scale {
                Some(ContactState::Apart)
            } else if distance.is_nan() || distance < -tol * settings.length_scale {
                Some(ContactState::Penetrating)
            } else if rate > tol * speed {
                Some(ContactState::Separating)
            } else if rate < -tol * speed {
                Some(ContactState::Closing)
            } else {
                Some(ContactState::Resting)
            }
        })
        .collect()
}

/// Impulses for every row at a state (`restitution` e ∈ [0, 1]).
#[derive(Clone, Debug, PartialEq)]
pub struct Impulses {
    /// P per constraint, for C/κ (0 where no impulse acts).
    pub impulse: Vec<f64>,
    /// Δvᵢ = Σₖ Pₖ Jₖᵢ / mᵢ per body.
    pub velocity_change: Vec<[f64; 3]>,
    pub status: Status,
    pub diagnostics: Vec<Diagnostic>,
}

/// The impulses that stop every closing contact at once, keeping equality rows' Ċ = 0 and
/// touching contacts from closing (the velocity-level QP; see the module note). Nothing
/// happens (all zero) when no contact is closing.
pub fn impulses(rows: &Rows, restitution: f64, settings: &Settings) -> Impulses {
    let (k, n) = (rows.rows.len(), rows.inverse_mass.len());
    let mut out = Impulses {
        impulse: vec![0.0; k],
        velocity_change: vec![[0.0; 3]; n],
        status: Status::Solved,
        diagnostics: Vec::new(),
    };
    let e = if (0.0..=1.0).contains(&restitution) {
        restitution
    } else {
        out.diagnostics.push(Diagnostic::Restitution { value: restitution });
        out.status = Status::Failed;
        0.0
    };
    let contacts = classify(rows, settings);
    if !contacts.contains(&Some(ContactState::Closing)) {
        return out;
    }
    let scaled = Scaled::new(rows, &mut out.diagnostics, &mut out.status);
    let touching = |c: Option<ContactState>| match c {
        None => true,
        Some(s) => s != ContactState::Apart,
    };
    let index: Vec<usize> = (0..k).filter(|&q| scaled.usable[q] && touching(contacts[q])).collect();
    // b̃ = J̃ v + e·min(J̃ v, 0) on contacts, J̃ v on equalities (Ċ/κ scaled).
    let b: Vec<f64> = index
        .iter()
        .map(|&q| {
            let u = scaled.scale(q, rows.rows[q].rate);
            if rows.rows[q].inequality { u + e * u.min(0.0) } else { u }
        })
        .collect();
    let nonnegative: Vec<bool> = index.iter().map(|&q| rows.rows[q].inequality).collect();
    let block = assemble(&scaled, &rows.inverse_mass, &index);
    let p = multipliers(&block, &b, &nonnegative, &index, settings, &mut out.diagnostics, &mut out.status);
    for (s, &q) in index.iter().enumerate() {
        out.impulse[q] = scaled.unscale(q, p[s]);
        for (body, j) in scaled.jacobian(q) {
            let w = rows.inverse_mass[*body];
            for (dv, jd) in out.velocity_change[*body].iter_mut().zip(j) {
                *dv += p[s] * jd * w;
            }
        }
    }
    out
}
