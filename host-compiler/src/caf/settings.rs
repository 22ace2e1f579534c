//! Settings of the CAF/feedback synthesis: a plain struct with documented defaults and a checking builder in
//! the style of clarabel's `DefaultSettingsBuilder`.

use super::CafError;

/// Which convex program produces (K, P); both give the same metric P (see the `caf` module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Formulation {
    /// Default. Stage 1 eliminates the gain from the LMI (projection lemma), leaving an LMI in Q = P⁻¹ alone of
    /// size n − rank B; stage 2 picks the smallest-norm gain K certifying the σ-margin for that P (an LMI of
    /// size n + rank B). Fast: the PSD cones stay small.
    #[default]
    Reduced,
    /// The joint LMI in (Q, Y = K Q) as the dissertation writes it, (3.66)–(3.67) resp. (3.8), with K = Y Q⁻¹.
    /// Its PSD cone has size 2n in discrete time, which makes it slow for n ≳ 10; kept as a cross-check.
    Joint,
}

/// Settings of [`super::synthesize_discrete`] and [`super::synthesize_continuous`]. Build with
/// [`CafSettings::builder`] or take [`Default`].
#[derive(Clone, Debug, PartialEq)]
pub struct CafSettings {
    /// σ: the required margin, `σ_min(P − ÃᵀPÃ) ≥ σ` in discrete time (Remark 3.22) or
    /// `σ_min(−(ÃᵀP + PÃ)) ≥ σ` in continuous time, with P normalised to `P ⪰ I` (3.62). Finite, ≥ 0, and < 1
    /// in discrete time (P − ÃᵀPÃ ⪯ P). Zero asks only for the non-strict (3.65)/(3.7). Default 0.1 (the value
    /// of §6.4).
    pub sigma: f64,
    /// η: the metric stage asks for the decay `(1 + η)σ` so that the gain stage has room to pick a small gain
    /// (and a strictly feasible problem). Finite, ≥ 0. Default 0.25.
    pub stage_slack: f64,
    /// Which program to solve. Default [`Formulation::Reduced`].
    pub formulation: Formulation,
    /// Largest acceptable condition number of P; a problem needing more is reported infeasible. > 1.
    /// Default 1e8.
    pub max_condition: f64,
    /// Relative tolerance of the PBH test: a mode is uncontrollable when
    /// `σ_min([λI − A, B]) ≤ pbh_tol · max(1, ‖[A B]‖_F)`. In (0, 1). Default 1e-9.
    pub pbh_tol: f64,
    /// With σ = 0, a validated margin down to `−nonstrict_tol · λ_max(P)` is accepted as the non-strict
    /// certificate (interior-point solutions of a problem without a strictly feasible point sit on the
    /// boundary). Ignored when σ > 0 (then the margin must be ≥ σ). In [0, 1). Default 1e-7.
    pub nonstrict_tol: f64,
    /// Clarabel's gap and feasibility tolerances (`tol_gap_abs`, `tol_gap_rel`, `tol_feas`). In (0, 1).
    /// Default 1e-9.
    pub solver_tol: f64,
    /// Clarabel's iteration cap. ≥ 1. Default 200.
    pub max_iter: u32,
    /// Clarabel's time limit per solve, seconds, > 0 (may be infinite). Default ∞.
    pub time_limit: f64,
}

impl Default for CafSettings {
    fn default() -> Self {
        Self {
            sigma: 0.1,
            stage_slack: 0.25,
            formulation: Formulation::Reduced,
            max_condition: 1e8,
            pbh_tol: 1e-9,
            nonstrict_tol: 1e-7,
            solver_tol: 1e-9,
            max_iter: 200,
            time_limit: f64::INFINITY,
        }
    }
}

impl CafSettings {
    /// A builder starting from the defaults.
    pub fn builder() -> CafSettingsBuilder {
        CafSettingsBuilder { s: Self::default() }
    }

    /// Check every documented range (the discrete-time bound σ < 1 is checked by the discrete synthesis).
    pub fn validate(&self) -> Result<(), CafError> {
        let bad = |field: &'static str, value: f64, rule: &'static str| {
            Err(CafError::Settings { field, value, rule })
        };
        if !(self.sigma.is_finite() && self.sigma >= 0.0) {
            return bad("sigma", self.sigma, "must be finite and ≥ 0");
        }
        if !(self.stage_slack.is_finite() && self.stage_slack >= 0.0) {
            return bad("stage_slack", self.stage_slack, "must be finite and ≥ 0");
        }
        if !(self.max_condition.is_finite() && self.max_condition > 1.0) {
            return bad(
                "max_condition",
                self.max_condition,
                "must be finite and > 1",
            );
        }
        if !(self.pbh_tol > 0.0 && self.pbh_tol < 1.0) {
            return bad("pbh_tol", self.pbh_tol, "must lie in (0, 1)");
        }
        if !(self.nonstrict_tol >= 0.0 && self.nonstrict_tol < 1.0) {
            return bad("nonstrict_tol", self.nonstrict_tol, "must lie in [0, 1)");
        }
        if !(self.solver_tol > 0.0 && self.solver_tol < 1.0) {
            return bad("solver_tol", self.solver_tol, "must lie in (0, 1)");
        }
        if self.max_iter == 0 {
            return bad("max_iter", 0.0, "must be at least 1");
        }
        if !(self.time_limit > 0.0) {
            return bad("time_limit", self.time_limit, "must be > 0");
        }
        Ok(())
    }
}

/// Builder for [`CafSettings`]; [`CafSettingsBuilder::build`] checks the ranges.
#[derive(Clone, Debug)]
pub struct CafSettingsBuilder {
    s: CafSettings,
}

impl CafSettingsBuilder {
    /// See [`CafSettings::sigma`].
    pub fn sigma(mut self, v: f64) -> Self {
        self.s.sigma = v;
        self
    }
    /// See [`CafSettings::stage_slack`].
    pub fn stage_slack(mut self, v: f64) -> Self {
        self.s.stage_slack = v;
        self
    }
    /// See [`CafSettings::formulation`].
    pub fn formulation(mut self, v: Formulation) -> Self {
        self.s.formulation = v;
        self
    }
    /// See [`CafSettings::max_condition`].
    pub fn max_condition(mut self, v: f64) -> Self {
        self.s.max_condition = v;
        self
    }
    /// See [`CafSettings::pbh_tol`].
    pub fn pbh_tol(mut self, v: f64) -> Self {
        self.s.pbh_tol = v;
        self
    }
    /// See [`CafSettings::nonstrict_tol`].
    pub fn nonstrict_tol(mut self, v: f64) -> Self {
        self.s.nonstrict_tol = v;
        self
    }
    /// See [`CafSettings::solver_tol`].
    pub fn solver_tol(mut self, v: f64) -> Self {
        self.s.solver_tol = v;
        self
    }
    /// See [`CafSettings::max_iter`].
    pub fn max_iter(mut self, v: u32) -> Self {
        self.s.max_iter = v;
        self
    }
    /// See [`CafSettings::time_limit`].
    pub fn time_limit(mut self, v: f64) -> Self {
        self.s.time_limit = v;
        self
    }
    /// The settings, if every field is in range.
    pub fn build(self) -> Result<CafSettings, CafError> {
        self.s.validate()?;
        Ok(self.s)
    }
}

#[cfg(test)]
mod tests {
    use super::CafSettings;
    use crate::caf::CafError;

    #[test]
    fn the_builder_refuses_a_condition_cap_of_one() {
        let e = CafSettings::builder()
            .max_condition(1.0)
            .build()
            .unwrap_err();
        assert_eq!(
            e,
            CafError::Settings {
                field: "max_condition",
                value: 1.0,
                rule: "must be finite and > 1",
            }
        );
        assert!(CafSettings::builder().max_iter(0).build().is_err());
        assert_eq!(
            CafSettings::builder().build().unwrap(),
            CafSettings::default()
        );
    }
}
