//! Inter-sample excursion of the continuous plant under a zero-order hold: what the certified sampled loop
//! does not see between t = κh and t = (κ+1)h.
//!
//! Derivation. With u held at u_κ on [κh, (κ+1)h] and d(τ) = x(κh+τ) − x_κ, the plant gives
//! ḋ = A d + f_κ with d(0) = 0 and f_κ = A x_κ + B u_κ + c (the vector field at the sample), hence
//!
//!   d(τ) = Φ(τ) f_κ,   Φ(τ) = ∫₀^τ e^{As} ds.
//!
//! The logarithmic norm μ = λ_max((A + Aᵀ)/2) bounds ‖e^{As}‖₂ ≤ e^{μs} for s ≥ 0, so
//! ‖Φ(τ)‖₂ ≤ ∫₀^τ e^{μs} ds = (e^{μτ} − 1)/μ (= τ when μ = 0), which increases with τ. Therefore, for every
//! τ ∈ [0, h],
//!
//!   ‖x(κh+τ) − x_κ‖₂ ≤ γ(h) ‖A x_κ + B u_κ + c‖₂,   γ(h) = (e^{μh} − 1)/μ.
//!
//! For two runs under the same reference v with u = K x + v at the samples, e = x − x̃ obeys
//! ė = A e + B K e_κ, so e(τ) = e_κ + Φ(τ)(A + BK) e_κ and ‖e(κh+τ)‖₂ ≤ (1 + γ(h)‖A + BK‖₂) ‖e_κ‖₂.

use super::{check_finite, check_len, ContinuousPlant, ModelError};
use faer::{Mat, MatRef, Side};

/// The bound γ(h) of the module docs for one plant and period, with the plant kept to evaluate f_κ.
#[derive(Clone, Debug, PartialEq)]
pub struct InterSampleBound {
    /// The continuous plant.
    pub plant: ContinuousPlant,
    /// Sample period h.
    pub h: f64,
    /// μ = λ_max((A + Aᵀ)/2).
    pub log_norm: f64,
    /// γ(h) = (e^{μh} − 1)/μ.
    pub gain: f64,
}

impl InterSampleBound {
    /// The bound for `plant` sampled with period `h`.
    pub fn new(plant: &ContinuousPlant, h: f64) -> Result<Self, ModelError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(ModelError::Period(h));
        }
        let A = plant.A.as_ref();
        check_finite("A", A)?;
        let n = plant.n();
        let sym = Mat::from_fn(n, n, |i, j| 0.5 * (A[(i, j)] + A[(j, i)]));
        let mu = if n == 0 {
            0.0
        } else {
            let ev = sym
                .self_adjoint_eigenvalues(Side::Lower)
                .map_err(|_| ModelError::NonFinite { what: "A" })?;
            ev.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        };
        // expm1 keeps γ accurate when μh is tiny; at μ = 0 the limit is h.
        let gain = if mu == 0.0 { h } else { (mu * h).exp_m1() / mu };
        Ok(Self {
            plant: plant.clone(),
            h,
            log_norm: mu,
            gain,
        })
    }

    /// An upper bound on sup_{τ∈[0,h]} ‖x(κh+τ) − x_κ‖₂ given the sample state x_κ and the held input u_κ.
    pub fn excursion(&self, x: &[f64], u: &[f64]) -> Result<f64, ModelError> {
        check_len("x", x, self.plant.n())?;
        check_len("u", u, self.plant.m())?;
        let f = self.plant.f(x, u);
        Ok(self.gain * f.iter().map(|v| v * v).sum::<f64>().sqrt())
    }

    /// The factor 1 + γ(h)‖A + BK‖₂ bounding sup_τ ‖e(κh+τ)‖₂ / ‖e_κ‖₂ for the deviation e between two runs of
    /// the loop u = K x + v under the same reference v.
    pub fn deviation_factor(&self, K: MatRef<'_, f64>) -> Result<f64, ModelError> {
        let (n, m) = (self.plant.n(), self.plant.m());
        if K.nrows() != m || K.ncols() != n {
            return Err(ModelError::Dimension {
                what: "K",
                expected: format!("{m}×{n}"),
                got: format!("{}×{}", K.nrows(), K.ncols()),
            });
        }
        check_finite("K", K)?;
        let Acl = &self.plant.A + &self.plant.B * K;
        let norm = Acl
            .singular_values()
            .map_err(|_| ModelError::NonFinite { what: "A + BK" })?
            .first()
            .copied()
            .unwrap_or(0.0);
        Ok(1.0 + self.gain * norm)
    }
}

impl ContinuousPlant {
    /// The inter-sample excursion bound for period `h`; see [`InterSampleBound`].
    pub fn inter_sample_bound(&self, h: f64) -> Result<InterSampleBound, ModelError> {
        InterSampleBound::new(self, h)
    }
}
