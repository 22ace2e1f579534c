//! The critical radius of Theorem 3.21: robustness of the sampled loop to a bounded disturbance ε in the
//! reference input, u = K x + v + ε (3.74).
//!
//! With e = x̃ − x̂′ the deviation from the undisturbed run, one step gives e⁺ = Ã e − E ε ((3.79), E = B for
//! an input disturbance) and, for ‖ε‖₂ ≤ δ,
//!
//!   ‖e⁺‖²_ψ − ‖e‖²_ψ ≤ −σ ‖e‖² + 2 a δ ‖e‖ + b δ²   (3.82),  a = ‖ÃᵀPE‖₂,  b = ‖EᵀPE‖₂,
//!
//! σ = σ_min(P − ÃᵀPÃ). The right side is ≤ 0 once ‖e‖ ≥ ρ_crit = δ (a + √(a² + σ b))/σ (3.83); ‖e‖_ψ ≥ r̃ =
//! ρ_crit √λ_max(P) (3.85) implies that (3.86); below r̃ the right side is at most (a²/σ + b) δ², so
//! r_crit = √(r̃² + (a²/σ + b) δ²) (3.87) and every ψ-ball of radius r ≥ r_crit around the undisturbed
//! trajectory keeps the disturbed one (3.88).
//!
//! δ bounds the Euclidean norm of the disturbance vector at every step (the ℓ∞-in-time norm of (3.76)).
//! All quantities are computed conservatively: σ from the validated lower bound of
//! [`super::validate::certify`], the norms inflated by a relative 64 n ε.

use super::validate::certify;
use super::{CafError, TimeKind};
use faer::{Mat, MatRef, Side};

/// The quantities of Theorem 3.21 for one (Ã, P, E, δ).
#[derive(Clone, Debug, PartialEq)]
pub struct RCrit {
    /// δ: bound on ‖ε(κ)‖₂.
    pub delta: f64,
    /// σ_min(P − ÃᵀPÃ), validated lower bound.
    pub sigma_min: f64,
    /// ‖ÃᵀPE‖₂ (upper bound).
    pub norm_AtPE: f64,
    /// ‖EᵀPE‖₂ (upper bound).
    pub norm_EtPE: f64,
    /// λ_max(P) (upper bound).
    pub lambda_max: f64,
    /// ρ_crit (3.83), Euclidean.
    pub rho_crit: f64,
    /// r̃ (3.85), ψ units.
    pub r_tilde: f64,
    /// r_crit (3.87), ψ units.
    pub r_crit: f64,
}

impl RCrit {
    /// The ψ-radius that stays invariant for a disturbed run started within ψ-distance `r0` of the nominal:
    /// max(r0, r_crit) (Theorem 3.21 applied with r = max(r0, r_crit)).
    pub fn invariant_radius(&self, r0: f64) -> f64 {
        r0.max(self.r_crit)
    }
}

fn spectral_norm(M: &Mat<f64>) -> Option<f64> {
    if M.nrows() == 0 || M.ncols() == 0 {
        return Some(0.0);
    }
    M.singular_values().ok().map(|s| s[0])
}

/// Theorem 3.21 for the closed loop Ã with metric P and disturbance matrix E (E = B for a disturbance in the
/// reference input). Fails if the shapes disagree, δ is not finite and ≥ 0, or P − ÃᵀPÃ is not validated
/// positive definite (then no critical radius exists).
pub fn r_crit(
    At: MatRef<'_, f64>,
    P: MatRef<'_, f64>,
    E: MatRef<'_, f64>,
    delta: f64,
) -> Result<RCrit, CafError> {
    r_crit_mixed(At, P, E, delta, 0.0)
}

/// Theorem 3.21 with a second disturbance z added to the step, known only by ‖z‖_P ≤ `z`: e⁺ = Ãe − Eε − z.
/// The proof of (3.82) goes through with 2aδ replaced by 2(aδ + a_z z), a_z = ‖P^{1/2}Ã‖₂ (since
/// |2eᵀÃᵀPz| ≤ 2‖P^{1/2}Ãe‖‖z‖_P), and bδ² by (√b δ + z)²; (3.83)–(3.87) follow unchanged in those two
/// terms. A feedback-linearizable plant's sampled-loop mismatch, which varies within the period, enters
/// this way (`certify::LoopConstants::mismatch`).
pub fn r_crit_mixed(
    At: MatRef<'_, f64>,
    P: MatRef<'_, f64>,
    E: MatRef<'_, f64>,
    delta: f64,
    z: f64,
) -> Result<RCrit, CafError> {
    if !(z.is_finite() && z >= 0.0) {
        return Err(CafError::Disturbance(z));
    }
    let n = At.nrows();
    if At.ncols() != n || P.nrows() != n || P.ncols() != n || E.nrows() != n {
        return Err(CafError::Dimension {
            what: "r_crit arguments",
            expected: format!("Ã {n}×{n}, P {n}×{n}, E with {n} rows"),
            got: format!(
                "Ã {}×{}, P {}×{}, E {}×{}",
                At.nrows(),
                At.ncols(),
                P.nrows(),
                P.ncols(),
                E.nrows(),
                E.ncols()
            ),
        });
    }
    if !(delta.is_finite() && delta >= 0.0) {
        return Err(CafError::Disturbance(delta));
    }
    // Validate P − ÃᵀPÃ with the same guarded computation as the synthesis (K = I, B = Ã: Ã = 0 + Ã·I).
    let zero = Mat::<f64>::zeros(n, n);
    let eye = Mat::<f64>::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 });
    let cert = certify(TimeKind::Discrete, zero.as_ref(), At, eye.as_ref(), P)
        .ok_or(CafError::NonFinite { what: "Ã or P" })?;
    if !(cert.margin > 0.0) {
        return Err(CafError::NoMargin {
            margin: cert.margin,
        });
    }
    let inflate = 1.0 + 64.0 * n as f64 * f64::EPSILON;
    let P = P.to_owned();
    let PE = &P * E;
    let a = spectral_norm(&(At.transpose() * &PE))
        .ok_or(CafError::NonFinite { what: "ÃᵀPE" })?
        * inflate;
    let EtPE = E.transpose() * &PE;
    let b = if EtPE.nrows() == 0 {
        0.0
    } else {
        EtPE.self_adjoint_eigenvalues(Side::Lower)
            .map_err(|_| CafError::NonFinite { what: "EᵀPE" })?
            .last()
            .copied()
            .unwrap_or(0.0)
            .max(0.0)
            * inflate
    };
    let sigma = cert.margin;
    let lambda_max = cert.lambda_max_P;
    let (rho_crit, r_crit_sq_rest) = if z > 0.0 {
        // The linear and quadratic disturbance terms of (3.82) with the second disturbance.
        let roots = crate::linalg::PdRoots::new(P.as_ref())
            .ok_or(CafError::NonFinite { what: "P^{1/2}" })?;
        let a_z = spectral_norm(&(&roots.sqrt * At))
            .ok_or(CafError::NonFinite { what: "P^{1/2}Ã" })?
            * inflate;
        let lin = a * delta + a_z * z;
        let quad = (b.sqrt() * delta + z).powi(2) * inflate;
        (
            (lin + (lin * lin + sigma * quad).sqrt()) / sigma,
            lin * lin / sigma + quad,
        )
    } else {
        (
            delta * (a + (a * a + sigma * b).sqrt()) / sigma,
            (a * a / sigma + b) * delta * delta,
        )
    };
    let r_tilde = rho_crit * lambda_max.sqrt();
    let r_crit = (r_tilde * r_tilde + r_crit_sq_rest).sqrt();
    Ok(RCrit {
        delta,
        sigma_min: sigma,
        norm_AtPE: a,
        norm_EtPE: b,
        lambda_max,
        rho_crit,
        r_tilde,
        r_crit,
    })
}
