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
//!
//! **Along one direction** ([`drift_against`]). A norm bound counts every coordinate's rate against every
//! constraint: a vehicle's speed against a limit on its acceleration, or a stiff metric's fast coordinates
//! against an obstacle's face. Along a direction n, Φ(τ) = τI + τ²A/2 + R₃(τ) with
//! ‖R₃(τ)‖_P ≤ ∫₀^τ (e^{as} − 1 − as) ds = (e^{aτ} − 1 − aτ − (aτ)²/2)/a =: χ₃(τ), a = ‖A‖_P (the series of
//! e^{As} term by term), so for τ ∈ [0, h]
//!
//!   −nᵀd(τ) ≤ h·max(0, −nᵀf) + (h²/2)·max(0, −nᵀAf) + ‖n‖_{P⁻¹}‖f‖_P·χ₃(h),
//!
//! each term being largest at τ = h. The first two are exact for a chain of integrators' leading terms;
//! the last is third order in h. Since R₃(τ)f = Σ_{i≥0} A^i(A²f)τ^{i+3}/(i+3)!, also
//! ‖R₃(τ)f‖_P ≤ ‖A²f‖_P·χ₃(τ)/a², so ‖f‖_P in the last term may be replaced by min(‖f‖_P, ‖A²f‖_P/a²)
//! (`f_p` of [`drift_against`]): on a double integrator A²f = 0 and the bound is exact to second order.

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

/// The directional bound of the module doc: an upper bound on sup_{τ∈[0,h]} −nᵀd(τ), how far the held
/// plant moves against `n` within one period, for the vector field `f` at the sample and `a_f` = A f.
/// `n_dual` = ‖n‖_{P⁻¹}, `f_p` = ‖f‖_P (or min(‖f‖_P, ‖A²f‖_P/a²), module doc) and `a_p` = a ≥ ‖A‖_P (the
/// induced norm) in the caller's metric. Each
/// term is rounded up by a relative 10⁻⁹.
pub fn drift_against(
    n: &[f64],
    f: &[f64],
    a_f: &[f64],
    h: f64,
    n_dual: f64,
    f_p: f64,
    a_p: f64,
) -> f64 {
    let dot = |x: &[f64]| -> f64 { n.iter().zip(x).map(|(a, b)| a * b).sum() };
    (h * (-dot(f)).max(0.0) + 0.5 * h * h * (-dot(a_f)).max(0.0) + n_dual * f_p * chi3(h, a_p))
        * (1.0 + 1e-9)
}

/// χ₃(h) of the module doc for a = `a_p` = ‖A‖_P: the remainder's weight in [`drift_against`], rounded
/// up (the series' tail is bounded by its next terms' geometric majorant where the subtraction would
/// cancel).
pub fn chi3(h: f64, a_p: f64) -> f64 {
    let t = a_p * h;
    // χ₃(h) = h (e^t − 1 − t − t²/2)/t, by its series where the subtraction would cancel.
    if t < 1e-2 {
        h * t * t / 6.0 * (1.0 + t / 4.0 + t * t / 20.0 + t * t * t / 100.0)
    } else {
        h * (t.exp_m1() - t - 0.5 * t * t) / t
    }
}

/// The gradient of [`drift_against`] with respect to f, the direction n held fixed: its terms are
/// convex in f (a positive part of a linear form, and a norm), and this is the subgradient that takes
/// each positive part's side at f (0 on the tie). `a` is A as a row-major n×n slice, `pf` = P f/‖f‖_P
/// (the gradient of ‖f‖_P; zeros at f = 0).
#[allow(clippy::too_many_arguments)]
pub fn drift_against_grad(
    n: &[f64],
    f: &[f64],
    a_f: &[f64],
    a: &[f64],
    h: f64,
    n_dual: f64,
    pf: &[f64],
    a_p: f64,
) -> Vec<f64> {
    let dim = n.len();
    let dot = |x: &[f64]| -> f64 { n.iter().zip(x).map(|(a, b)| a * b).sum() };
    let c3 = n_dual * chi3(h, a_p);
    let mut g: Vec<f64> = pf.iter().map(|v| c3 * v).collect();
    if dot(f) < 0.0 {
        g.iter_mut().zip(n).for_each(|(g, ni)| *g -= h * ni);
    }
    if dot(a_f) < 0.0 {
        // ∇_f (−nᵀA f) = −Aᵀn.
        for (j, gj) in g.iter_mut().enumerate() {
            let atn: f64 = (0..dim).map(|i| a[i * dim + j] * n[i]).sum();
            *gj -= 0.5 * h * h * atn;
        }
    }
    g.iter().map(|v| v * (1.0 + 1e-9)).collect()
}

#[cfg(test)]
mod directional_tests {
    use super::*;
    use crate::model::expm::expm;

    /// Against the exact excursion of an anti-damped oscillator and a chain, on a fine grid of τ: the
    /// bound holds in every direction tried.
    #[test]
    fn the_directional_drift_bounds_the_exact_excursion() {
        let h = 0.1;
        for A in [
            faer::mat![[0.0, 1.0], [-2.0, 0.1]],
            faer::mat![[0.0, 1.0], [0.0, 0.0]],
        ] {
            let P = faer::mat![[3.0, 0.5], [0.5, 1.0]];
            let roots = crate::linalg::PdRoots::new(P.as_ref()).unwrap();
            let a_p = roots.induced_norm(A.as_ref());
            for (f, n) in [
                ([2.0, -1.0], [1.0, 0.0]),
                ([-3.0, 0.5], [0.3, -1.0]),
                ([0.0, 4.0], [-1.0, 0.2]),
                ([1.0, 1.0], [0.0, -1.0]),
            ] {
                let a_f = [
                    A[(0, 0)] * f[0] + A[(0, 1)] * f[1],
                    A[(1, 0)] * f[0] + A[(1, 1)] * f[1],
                ];
                let bound = drift_against(
                    &n,
                    &f,
                    &a_f,
                    h,
                    roots.dual_norm(&n),
                    crate::linalg::p_norm(P.as_ref(), &f),
                    a_p,
                );
                // The remainder weighted by ‖A²f‖_P/a² where smaller (module doc).
                let a2f = [
                    A[(0, 0)] * a_f[0] + A[(0, 1)] * a_f[1],
                    A[(1, 0)] * a_f[0] + A[(1, 1)] * a_f[1],
                ];
                let weight = crate::linalg::p_norm(P.as_ref(), &f)
                    .min(crate::linalg::p_norm(P.as_ref(), &a2f) / (a_p * a_p));
                let tight = drift_against(&n, &f, &a_f, h, roots.dual_norm(&n), weight, a_p);
                // d(τ) = Φ(τ) f with Φ(τ) the (1,2) block of expm([[A, I], [0, 0]] τ).
                let mut worst = f64::NEG_INFINITY;
                for i in 0..=200 {
                    let tau = h * i as f64 / 200.0;
                    let M = faer::Mat::<f64>::from_fn(4, 4, |r, c| match (r < 2, c < 2) {
                        (true, true) => A[(r, c)] * tau,
                        (true, false) => f64::from(u8::from(r == c - 2)) * tau,
                        _ => 0.0,
                    });
                    let E = expm(M.as_ref()).unwrap();
                    let d: Vec<f64> = (0..2)
                        .map(|r| E[(r, 2)] * f[0] + E[(r, 3)] * f[1])
                        .collect();
                    worst = worst.max(-(n[0] * d[0] + n[1] * d[1]));
                }
                assert!(worst <= bound, "{A:?} f {f:?} n {n:?}: {worst} > {bound}");
                assert!(worst <= tight, "{A:?} f {f:?} n {n:?}: {worst} > {tight}");
            }
        }
    }
}
