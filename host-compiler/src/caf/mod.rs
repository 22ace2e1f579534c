//! Tracking feedback K and quadratic control autobisimulation function (CAF) ψ(x, x′) = ‖x − x′‖_P
//! ((3.2), (3.61)) for linear affine plants: the LMIs of §3.1.1 (3.8) and §3.1.4 (3.66)–(3.67) with the σ-margin
//! of Remark 3.22, solved with clarabel's PSD cone; the stabilizability (PBH) diagnosis; the independent
//! validation of every answer; and the critical radius r_crit of Theorem 3.21 (3.83)–(3.87).
//!
//! # What is certified
//! A [`Caf`] holds (K, P) with P = Pᵀ ⪰ I (3.62), so ψ ≥ ‖·‖₂ (3.58), and, with Ã = A + BK,
//! - discrete time: `P − ÃᵀPÃ ⪰ σ I`, i.e. σ_min(P − ÃᵀPÃ) ≥ σ, the strict form of (3.65) that Remark 3.22
//!   asks for and Theorem 3.21 needs (σ > 0);
//! - continuous time: `ÃᵀP + PÃ ⪯ −σ I`, the strict form of (3.7).
//!
//! These facts are re-measured by [`certify`] with faer (eigenvalues of P and of the decrease matrix, with a
//! rounding guard) after the solver returns; the solver's own claims are never trusted.
//!
//! # The programs
//! In the usual change of variables Q = P⁻¹ (up to scale), Y = K Q:
//! - Ã Q Ãᵀ ⪯ (1 − γ) Q ⇔ ÃᵀPÃ ⪯ (1 − γ) P ⇔ `[[(1−γ)Q, AQ+BY], [(AQ+BY)ᵀ, Q]] ⪰ 0` (Schur complement);
//!   this is (3.67) with a decay margin γ. With the normalisation Q ⪯ I (P ⪰ I, (3.62)) it gives
//!   P − ÃᵀPÃ ⪰ γP ⪰ γI. (Remark 3.22 subtracts σI in the lower-right block instead; read with the LMI
//!   variable as P⁻¹, that bounds P − ÃᵀPÃ below by σP², which is the intended σI only when P = I, so the
//!   relative form is used here.)
//! - continuous time: `AQ + QAᵀ + BY + YᵀBᵀ + γQ ⪯ 0` ⇔ ÃᵀP + PÃ ⪯ −γP, (3.8) with a margin.
//!
//! **Objective (favours large balls in state coordinates).** With P ⪰ I the ψ-ball of radius r contains
//! the Euclidean ball of radius r/√λ_max(P) and lies in the one of radius r, so the robust neighbourhoods are
//! as round as possible when λ_max(P) — here the condition number bound — is small. The metric stage
//! maximises s subject to `s I ⪯ Q ⪯ I` and the margin LMI, i.e. minimises λ_max(P) ≤ 1/s. It asks for the
//! decay γ = (1 + η)σ (η = [`CafSettings::stage_slack`]). The gain stage then fixes P (normalised to
//! λ_min(P) = 1) and picks the gain of smallest Frobenius norm with `P − ÃᵀPÃ ⪰ σI` (resp.
//! `ÃᵀP + PÃ ⪯ −σI`) — small gains spend little input on deviations and amplify f32 rounding little. The
//! slack η guarantees this second problem a strictly feasible point.
//!
//! [`Formulation::Reduced`] (default) solves the metric stage without Y: by the projection (elimination)
//! lemma, ∃Y with the LMI above ⇔ `N_Bᵀ((1−γ)Q − AQAᵀ)N_B ⪰ 0` (discrete) resp.
//! `N_Bᵀ(AQ + QAᵀ + γQ)N_B ⪯ 0` (continuous), N_B a basis of the left null space of B. Its PSD cones have
//! sizes n and n − rank B instead of 2n, which keeps clarabel's dense KKT blocks small; the gain stage has
//! one cone of size n + rank B. [`Formulation::Joint`] solves the LMI in (Q, Y) as written and returns
//! K = Y Q⁻¹ (a cross-check; same metric, different gain).
//!
//! # Outcomes
//! Solver results are statuses ([`CafOutcome`]), not errors: not stabilizable (PBH: an uncontrollable mode
//! with |λ| ≥ 1, resp. Re λ ≥ 0, reported with its left eigenvector), margin unachievable (an uncontrollable
//! mode decays slower than σ requires), infeasible, solver failure, or an answer that failed validation.
//! Bad input (shapes, non-finite numbers, settings out of range) is a [`CafError`].

// Negated comparisons (`!(x > 0.0)`) are deliberate throughout: they reject NaN as well.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod design;
mod pbh;
mod rcrit;
pub(crate) mod sdp;
mod settings;
mod synth;
mod validate;

pub use design::{design, design_location, design_locations, outcome_message, Design, DesignError};
pub use pbh::{uncontrollable_modes, UncontrollableMode};
pub use rcrit::{r_crit, r_crit_mixed, RCrit};
pub use settings::{CafSettings, CafSettingsBuilder, Formulation};
pub use synth::{synthesize, synthesize_continuous, synthesize_discrete};
pub use validate::{certify, Certificate};

use faer::Mat;

/// Which time domain a CAF certifies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeKind {
    /// x⁺ = A x + B u + g; decrease condition (3.65).
    Discrete,
    /// ẋ = A x + B u + c; decrease condition (3.7).
    Continuous,
}

/// A validated feedback gain and CAF metric.
#[derive(Clone, Debug, PartialEq)]
pub struct Caf {
    pub time: TimeKind,
    /// The plant matrices the certificate is about.
    pub A: Mat<f64>,
    pub B: Mat<f64>,
    /// m×n feedback gain of u = K x + v (3.5)/(3.63).
    pub K: Mat<f64>,
    /// n×n metric of ψ (3.61), P ⪰ I.
    pub P: Mat<f64>,
    /// The margin σ that was required (and is certified: `certificate.margin ≥ σ`).
    pub sigma: f64,
    pub formulation: Formulation,
    /// The independently validated facts.
    pub certificate: Certificate,
}

impl Caf {
    /// Ã = A + B K (3.75).
    pub fn A_cl(&self) -> Mat<f64> {
        &self.A + &self.B * &self.K
    }

    /// ψ(x, x′) = √((x − x′)ᵀ P (x − x′)) (3.61). Panics only if the slices are shorter than n.
    pub fn psi(&self, x: &[f64], y: &[f64]) -> f64 {
        let n = self.P.nrows();
        let d: Vec<f64> = (0..n).map(|i| x[i] - y[i]).collect();
        (0..n)
            .map(|i| d[i] * (0..n).map(|j| self.P[(i, j)] * d[j]).sum::<f64>())
            .sum::<f64>()
            .max(0.0)
            .sqrt()
    }

    /// Theorem 3.21 for a disturbance in the reference input (E = B) with ‖ε(κ)‖₂ ≤ δ. Discrete time only.
    pub fn r_crit(&self, delta: f64) -> Result<RCrit, CafError> {
        if self.time != TimeKind::Discrete {
            return Err(CafError::NotDiscrete);
        }
        r_crit(
            self.A_cl().as_ref(),
            self.P.as_ref(),
            self.B.as_ref(),
            delta,
        )
    }
}

/// The result of a synthesis run.
// `Solved` is the common case; boxing it would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub enum CafOutcome {
    /// A validated (K, P).
    Solved(Caf),
    /// An uncontrollable mode in the closed unstable region: no K stabilises the pair (A, B).
    NotStabilizable { mode: UncontrollableMode },
    /// The pair is stabilizable but an uncontrollable (stable) mode decays too slowly for the decay margin
    /// the metric stage needs: ψ along it contracts no faster than the mode, so σ must be below `max_sigma`
    /// (1 − |λ|² in discrete time, −2 Re λ in continuous time).
    MarginUnachievable {
        mode: UncontrollableMode,
        max_sigma: f64,
    },
    /// Clarabel proved the program of `stage` infeasible (e.g. the condition-number cap), or validation found
    /// the condition number above the cap.
    Infeasible { stage: String, status: String },
    /// Clarabel stopped without an answer (iteration/time limit, numerical trouble).
    SolverFailed { stage: String, status: String },
    /// The solver's answer did not survive the independent check.
    ValidationFailed { reason: String },
}

impl CafOutcome {
    /// The CAF, if solved.
    pub fn solved(self) -> Option<Caf> {
        match self {
            CafOutcome::Solved(c) => Some(c),
            _ => None,
        }
    }
}

/// Bad input to the CAF synthesis or to r_crit.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CafError {
    #[error("{what}: expected {expected}, got {got}")]
    Dimension {
        what: &'static str,
        expected: String,
        got: String,
    },
    #[error("{what} is not finite")]
    NonFinite { what: &'static str },
    #[error("setting `{field}` = {value}: {rule}")]
    Settings {
        field: &'static str,
        value: f64,
        rule: &'static str,
    },
    #[error("disturbance bound δ must be finite and ≥ 0, got {0}")]
    Disturbance(f64),
    #[error("P − ÃᵀPÃ is not validated positive definite (margin {margin:.3e}); Theorem 3.21 does not apply")]
    NoMargin { margin: f64 },
    #[error("r_crit is defined for the discrete-time loop only")]
    NotDiscrete,
    #[error("clarabel rejected the problem: {0}")]
    Solver(#[from] crate::solver::SetupError),
}
