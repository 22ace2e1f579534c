//! Synthesis settings (the `[synthesis]` table of a task spec): a plain struct with documented defaults
//! and a builder that checks ranges, in the style of clarabel's `DefaultSettingsBuilder`.
//!
//! Every key of `[synthesis]` is optional; an absent key takes the default below.

use std::fmt;

/// Which controller the image carries (DESIGN §4, "Modes").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum ControllerMode {
    /// Alg 2: pick the robust neighbourhood that holds x(0), then `u = K x + v_i(κ)`. TOML: `"feedforward"`.
    #[default]
    Feedforward,
    /// Ch. 6: piecewise affine feedback `u = (K + θ_j) x + θ0_j` over partitions. TOML: `"pwa"`.
    Pwa,
}

impl ControllerMode {
    /// Parse the TOML spelling.
    pub fn from_name(s: &str) -> Option<Self> {
        match s {
            "feedforward" => Some(ControllerMode::Feedforward),
            "pwa" => Some(ControllerMode::Pwa),
            _ => None,
        }
    }

    /// The TOML spelling.
    pub fn name(self) -> &'static str {
        match self {
            ControllerMode::Feedforward => "feedforward",
            ControllerMode::Pwa => "pwa",
        }
    }
}

/// What the controller does after the task (issue 17): the `terminal` key of `[synthesis]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TerminalChoice {
    /// A certified terminal law with its invariant ellipsoid in Goal where one exists
    /// ([`crate::terminal`]), else `Hold`, said at synthesis and in the report. TOML: `"auto"`.
    #[default]
    Auto,
    /// The certified terminal law, required: synthesis fails (exit 2) when none exists. TOML:
    /// `"invariant"`.
    Invariant,
    /// No terminal law; a feedforward image keeps its last row's law past the table. TOML: `"hold"`.
    Hold,
    /// No terminal law; a feedforward image applies its fallback past the table. TOML: `"fallback"`.
    Fallback,
}

impl TerminalChoice {
    /// Parse the TOML spelling.
    pub fn from_name(s: &str) -> Option<Self> {
        match s {
            "auto" => Some(TerminalChoice::Auto),
            "invariant" => Some(TerminalChoice::Invariant),
            "hold" => Some(TerminalChoice::Hold),
            "fallback" => Some(TerminalChoice::Fallback),
            _ => None,
        }
    }

    /// The TOML spelling.
    pub fn name(self) -> &'static str {
        match self {
            TerminalChoice::Auto => "auto",
            TerminalChoice::Invariant => "invariant",
            TerminalChoice::Hold => "hold",
            TerminalChoice::Fallback => "fallback",
        }
    }
}

/// Settings of the synthesis loop (Alg 1 with the coverage test of §2.5.2 and the automatic trajectory
/// generation of Alg 4). Build with [`SynthesisSettings::builder`] or take [`Default`].
#[derive(Clone, Debug, PartialEq)]
pub struct SynthesisSettings {
    /// Controller kind in the image. Default [`ControllerMode::Feedforward`].
    pub mode: ControllerMode,
    /// Confidence 1 − β with which the coverage claim holds: the Chernoff bound of §2.5.2 is made
    /// ≤ β. In (0, 1). Default 0.99.
    pub confidence: f64,
    /// Required fraction of Init (by volume) covered by the robust neighbourhoods. In (0, 1].
    /// Default 0.99.
    pub coverage_target: f64,
    /// Half-width ε of the coverage estimate: the loop stops when (covered fraction of the samples) − ε ≥
    /// `coverage_target`. In (0, 1) and `coverage_target + coverage_tolerance ≤ 1`. Default 0.01.
    /// With the defaults every sample must be covered, as in the termination rule of §5.4.
    pub coverage_tolerance: f64,
    /// Budget of nominal trajectories (iterations of Alg 1). ≥ 1. Default 64.
    pub max_trajectories: usize,
    /// Iteration cap of the robustness optimiser for one trajectory (§5.2–5.3). ≥ 1. Default 200.
    pub max_iterations: usize,
    /// σ-margin: the lower bound σmin imposed on the smallest singular value of P − ÃᵀPÃ when solving for
    /// the CAF (Remark 3.22; §6.4 uses 0.1). Finite, > 0. Default 0.1.
    pub sigma_margin: f64,
    /// δε of §5.4: robust neighbourhoods with radius below this are not worth growing from; their seeds are
    /// discarded and a new trajectory is requested. Finite, ≥ 0. Default 1e-3.
    pub min_robustness: f64,
    /// Reference hold L in samples: generated and optimised reference sequences ṽ are constant over
    /// blocks of L samples (move blocking, [`crate::trajectory::hold`]). A PWA law (Ch. 6) then needs
    /// about one partition per block instead of nearly one per sample (§6.2). Recorded (CSV) trajectories
    /// are used as recorded. ≥ 1. Default 1 (every sample free).
    pub reference_hold: usize,
    /// After the task: a certified terminal law where one exists, or the image's behaviour past the table
    /// ([`TerminalChoice`]). Default [`TerminalChoice::Auto`].
    pub terminal: TerminalChoice,
}

impl Default for SynthesisSettings {
    fn default() -> Self {
        Self {
            mode: ControllerMode::Feedforward,
            confidence: 0.99,
            coverage_target: 0.99,
            coverage_tolerance: 0.01,
            max_trajectories: 64,
            max_iterations: 200,
            sigma_margin: 0.1,
            min_robustness: 1e-3,
            reference_hold: 1,
            terminal: TerminalChoice::Auto,
        }
    }
}

impl SynthesisSettings {
    /// A builder starting from the defaults.
    pub fn builder() -> SynthesisSettingsBuilder {
        SynthesisSettingsBuilder { s: Self::default() }
    }

    /// Number N of uniform samples of Init so that the lower Chernoff tail of §2.5.2,
    /// P[E[D] ≤ D̄ − ε] ≤ exp(−ε²N/(2+ε)), is at most 1 − `confidence` (ε = `coverage_tolerance`).
    pub fn coverage_samples(&self) -> usize {
        let eps = self.coverage_tolerance;
        let beta = 1.0 - self.confidence;
        let n = (2.0 + eps) * (1.0 / beta).ln() / (eps * eps);
        n.ceil() as usize
    }

    /// Check every range documented on the fields; the first violation is returned.
    pub fn validate(&self) -> Result<(), SettingsError> {
        let open01 = |v: f64| v.is_finite() && v > 0.0 && v < 1.0;
        if !open01(self.confidence) {
            return Err(SettingsError::new(
                "confidence",
                self.confidence,
                "must lie in (0, 1)",
            ));
        }
        if !(self.coverage_target.is_finite()
            && self.coverage_target > 0.0
            && self.coverage_target <= 1.0)
        {
            return Err(SettingsError::new(
                "coverage_target",
                self.coverage_target,
                "must lie in (0, 1]",
            ));
        }
        if !open01(self.coverage_tolerance) {
            return Err(SettingsError::new(
                "coverage_tolerance",
                self.coverage_tolerance,
                "must lie in (0, 1)",
            ));
        }
        // A small slack so that e.g. 0.99 + 0.01 (which rounds above 1) is accepted.
        if self.coverage_target + self.coverage_tolerance > 1.0 + 1e-12 {
            return Err(SettingsError::new(
                "coverage_tolerance",
                self.coverage_tolerance,
                "coverage_target + coverage_tolerance exceeds 1, so the target can never be certified",
            ));
        }
        if self.max_trajectories == 0 {
            return Err(SettingsError::new(
                "max_trajectories",
                0.0,
                "must be at least 1",
            ));
        }
        if self.max_iterations == 0 {
            return Err(SettingsError::new(
                "max_iterations",
                0.0,
                "must be at least 1",
            ));
        }
        if self.reference_hold == 0 {
            return Err(SettingsError::new(
                "reference_hold",
                0.0,
                "must be at least 1",
            ));
        }
        if !(self.sigma_margin.is_finite() && self.sigma_margin > 0.0) {
            return Err(SettingsError::new(
                "sigma_margin",
                self.sigma_margin,
                "must be finite and > 0",
            ));
        }
        if !(self.min_robustness.is_finite() && self.min_robustness >= 0.0) {
            return Err(SettingsError::new(
                "min_robustness",
                self.min_robustness,
                "must be finite and ≥ 0",
            ));
        }
        Ok(())
    }
}

/// A setting outside its documented range.
#[derive(Clone, Debug, PartialEq)]
pub struct SettingsError {
    /// The TOML key / field name.
    pub field: &'static str,
    /// The offending value.
    pub value: f64,
    /// Why it is rejected.
    pub reason: &'static str,
}

impl SettingsError {
    fn new(field: &'static str, value: f64, reason: &'static str) -> Self {
        Self {
            field,
            value,
            reason,
        }
    }
}

impl fmt::Display for SettingsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "synthesis.{} = {}: {}",
            self.field, self.value, self.reason
        )
    }
}

impl std::error::Error for SettingsError {}

/// Builder for [`SynthesisSettings`]; [`SynthesisSettingsBuilder::build`] validates.
#[derive(Clone, Debug)]
pub struct SynthesisSettingsBuilder {
    s: SynthesisSettings,
}

impl SynthesisSettingsBuilder {
    /// See [`SynthesisSettings::mode`].
    pub fn mode(mut self, v: ControllerMode) -> Self {
        self.s.mode = v;
        self
    }
    /// See [`SynthesisSettings::confidence`].
    pub fn confidence(mut self, v: f64) -> Self {
        self.s.confidence = v;
        self
    }
    /// See [`SynthesisSettings::coverage_target`].
    pub fn coverage_target(mut self, v: f64) -> Self {
        self.s.coverage_target = v;
        self
    }
    /// See [`SynthesisSettings::coverage_tolerance`].
    pub fn coverage_tolerance(mut self, v: f64) -> Self {
        self.s.coverage_tolerance = v;
        self
    }
    /// See [`SynthesisSettings::max_trajectories`].
    pub fn max_trajectories(mut self, v: usize) -> Self {
        self.s.max_trajectories = v;
        self
    }
    /// See [`SynthesisSettings::max_iterations`].
    pub fn max_iterations(mut self, v: usize) -> Self {
        self.s.max_iterations = v;
        self
    }
    /// See [`SynthesisSettings::sigma_margin`].
    pub fn sigma_margin(mut self, v: f64) -> Self {
        self.s.sigma_margin = v;
        self
    }
    /// See [`SynthesisSettings::reference_hold`].
    pub fn reference_hold(mut self, v: usize) -> Self {
        self.s.reference_hold = v;
        self
    }
    /// See [`SynthesisSettings::min_robustness`].
    pub fn min_robustness(mut self, v: f64) -> Self {
        self.s.min_robustness = v;
        self
    }
    /// Validate and return the settings.
    pub fn build(self) -> Result<SynthesisSettings, SettingsError> {
        self.s.validate()?;
        Ok(self.s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_documented_values() {
        let s = SynthesisSettings::default();
        assert!(s.validate().is_ok());
        assert_eq!(s.confidence, 0.99);
        assert_eq!(s.mode, ControllerMode::Feedforward);
    }

    #[test]
    fn builder_rejects_out_of_range() {
        assert_eq!(
            SynthesisSettings::builder()
                .confidence(1.0)
                .build()
                .unwrap_err()
                .field,
            "confidence"
        );
        assert_eq!(
            SynthesisSettings::builder()
                .confidence(0.0)
                .build()
                .unwrap_err()
                .field,
            "confidence"
        );
        assert_eq!(
            SynthesisSettings::builder()
                .coverage_target(0.995)
                .build()
                .unwrap_err()
                .field,
            "coverage_tolerance"
        );
        assert_eq!(
            SynthesisSettings::builder()
                .max_trajectories(0)
                .build()
                .unwrap_err()
                .field,
            "max_trajectories"
        );
        assert_eq!(
            SynthesisSettings::builder()
                .sigma_margin(f64::NAN)
                .build()
                .unwrap_err()
                .field,
            "sigma_margin"
        );
        let ok = SynthesisSettings::builder()
            .confidence(0.9)
            .mode(ControllerMode::Pwa)
            .build()
            .unwrap();
        assert_eq!(ok.confidence, 0.9);
        assert_eq!(ok.mode, ControllerMode::Pwa);
    }

    #[test]
    fn coverage_samples_meet_the_chernoff_bound() {
        let s = SynthesisSettings::default();
        let n = s.coverage_samples() as f64;
        let eps = s.coverage_tolerance;
        let tail = |n: f64| (-eps * eps * n / (2.0 + eps)).exp();
        assert!(tail(n) <= 1.0 - s.confidence + 1e-15);
        // One sample fewer would not do: N is the smallest such integer.
        assert!(tail(n - 1.0) > 1.0 - s.confidence);
    }
}
