//! Trajectory optimisation for the certified loop (Ch. 5): potential-function descent with an adjoint
//! gradient (§5.2, Algorithm 3, time-optimal bisection of §5.2.3) and direct maximisation of the
//! certified robustness δ(0) by a proximal bundle method (§5.3, subgradients (5.26)–(5.31)).
//!
//! Everything this module returns as *certified* went through [`crate::certify::shipped`]: v rounded to
//! f32, simulated with the f32 gain, certified with the inter-sample and rounding margins.
//!
//! * [`pieces`]: the pieces of δ(0) with gradients, the adjoint sweep, the subgradient of (5.28)–(5.29).
//! * [`potential`]: the potentials of §5.2.3, Algorithm 3, `argmin`'s L-BFGS, the time-optimal bisection.
//! * `bundle` (behind [`maximize_delta`]): the proximal bundle method of §5.3.
//!
//! API changes for callers (newest first):
//! * `BundleSettings::hold` and `PotentialSettings::hold` (default 1): keep v block-constant
//!   ([`crate::trajectory::hold`]).
//! * `BundleSettings::repair_delta` (default 1e-3): an uncertified start is first repaired by the §5.2
//!   descent, then maximised. `try_maximize_delta` and [`OptimizeError`] for unchecked input.
//! * `BundleSettings::time_search_every: usize` is now `terminal_time: bool` (builder `terminal_time`); the
//!   terminal step is searched between bundle runs instead of interrupting them. `initial_step` is the RMS
//!   size of the first move per input component.
//! * `setup::OwnedLoop` is now [`crate::certify::OwnedLoop`] (a task with its designed CAF).
//! * New modules `pieces`, `potential`, `setup` (additive).

mod bundle;
pub mod pieces;
pub mod potential;
pub mod temporal;

use crate::certify::{Certificate, Loop, LoopConstants};
use crate::settings::{settings_builder, Check, SettingError};
use crate::trajectory::Nominal;
use std::sync::atomic::AtomicBool;

/// Settings of the bundle method for [`maximize_delta`], with documented defaults. Build with
/// [`BundleSettings::builder`] (validated; `to_builder` starts from existing settings) or take
/// [`Default`]. Every entry point checks them again.
#[derive(Clone, Debug)]
pub struct BundleSettings {
    /// Outer iterations (serious + null steps) at most. Default 200. 0 turns §5.3's iterations (and the
    /// repair) off: the start is returned re-certified, cut at k* when `terminal_time` is set.
    pub max_iterations: usize,
    /// Stop when the predicted increase of δ is below this (absolute). Finite, ≥ 0. Default 1e-7.
    pub tolerance: f64,
    /// Smallest proximal step parameter t; below it the method stops with `NoProgress`. Finite, > 0.
    /// Default 1e-8.
    pub min_step: f64,
    /// Largest proximal step parameter t. Finite and ≥ `min_step`. Default 1e2.
    pub max_step: f64,
    /// Size of the first move, as the RMS change per input component; sets the first proximal parameter
    /// t. Finite, > 0. Default 1e-2.
    pub initial_step: f64,
    /// Serious-step test: accept when the certified gain is at least this fraction of the predicted
    /// gain. In (0, 1). Default 0.1.
    pub serious_fraction: f64,
    /// Bundle size at most, before aggregation. ≥ 1. Default 30.
    pub bundle_size: usize,
    /// Optimise the terminal step too (default true): cut the sequence at k* before the first run, and
    /// whenever the bundle method stops converged, try a tenth more steps (holding the last input, up to
    /// `steps_max`) and restart from it if it certifies better.
    pub terminal_time: bool,
    /// When the start is not certified (some piece of δ(0) is not positive), first repair it with the
    /// potential descent of §5.2 (L-BFGS) to this δ, one iteration of the count. Finite, ≥ 0; 0 turns
    /// the repair off. Default 1e-3. The min of many violated pieces gives the bundle method one sample at a time; the
    /// potentials' sum moves all of them at once.
    pub repair_delta: f64,
    /// Reference hold L ([`crate::trajectory::hold`]): v is kept constant over blocks of L samples (the
    /// start is projected, every subgradient is projected). ≥ 1. Default 1 (no blocks).
    pub hold: usize,
}

impl Default for BundleSettings {
    fn default() -> Self {
        Self {
            max_iterations: 200,
            tolerance: 1e-7,
            min_step: 1e-8,
            max_step: 1e2,
            initial_step: 1e-2,
            serious_fraction: 0.1,
            bundle_size: 30,
            terminal_time: true,
            repair_delta: 1e-3,
            hold: 1,
        }
    }
}

impl BundleSettings {
    /// Checks the ranges documented on the fields; the first violation is returned.
    pub fn validate(&self) -> Result<(), SettingError> {
        let c = Check("BundleSettings");
        c.non_negative("tolerance", self.tolerance)?;
        c.positive("min_step", self.min_step)?;
        c.rule(
            "max_step",
            self.max_step,
            self.max_step.is_finite() && self.max_step >= self.min_step,
            "must be finite and ≥ min_step",
        )?;
        c.positive("initial_step", self.initial_step)?;
        c.open_unit("serious_fraction", self.serious_fraction)?;
        c.at_least_one("bundle_size", self.bundle_size)?;
        c.non_negative("repair_delta", self.repair_delta)?;
        c.at_least_one("hold", self.hold)
    }
}

settings_builder!(
    BundleSettings,
    BundleSettingsBuilder {
        max_iterations: usize,
        tolerance: f64,
        min_step: f64,
        max_step: f64,
        initial_step: f64,
        serious_fraction: f64,
        bundle_size: usize,
        terminal_time: bool,
        repair_delta: f64,
        hold: usize,
    }
);

/// Why [`maximize_delta`] stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum OptStop {
    /// The predicted gain fell below the tolerance.
    Converged,
    /// `max_iterations` reached.
    IterationLimit,
    /// The cancel flag was set.
    Cancelled,
    /// The step parameter collapsed without a certified improvement.
    NoProgress,
}

/// The result of [`maximize_delta`].
#[derive(Clone, Debug)]
pub struct Optimized {
    /// What ships (f32-rounded v), from the same x0.
    pub nominal: Nominal,
    /// [`certify::shipped`] of it; δ never below the start's.
    pub certificate: Certificate,
    /// Certified δ per iteration; `history[0]` is δ of the start.
    pub history: Vec<f64>,
    /// Terminal time in steps before and after.
    pub steps_before: usize,
    pub steps_after: usize,
    pub iterations: usize,
    pub stop: OptStop,
}

/// Why an optimiser refused its input.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum OptimizeError {
    #[error("x0 has {got} components, but the plant has n = {n}")]
    StateDimension { got: usize, n: usize },
    #[error("v({k}) has {got} components, but the plant has m = {m}")]
    InputDimension { k: usize, got: usize, m: usize },
    #[error("the reference sequence v is empty")]
    Empty,
    #[error("x0 or v has a non-finite entry")]
    NotFinite,
    #[error("the desired robustness δ = {0} is not a positive finite number")]
    BadDelta(f64),
    #[error(transparent)]
    Settings(#[from] SettingError),
}

/// Check that x0 and v fit the loop (dimensions, finiteness, at least one step).
pub fn check_inputs(lp: &Loop<'_>, x0: &[f64], v: &[Vec<f64>]) -> Result<(), OptimizeError> {
    let (n, m) = (lp.plant.n(), lp.plant.m());
    if x0.len() != n {
        return Err(OptimizeError::StateDimension { got: x0.len(), n });
    }
    if v.is_empty() {
        return Err(OptimizeError::Empty);
    }
    if let Some((k, r)) = v.iter().enumerate().find(|(_, r)| r.len() != m) {
        return Err(OptimizeError::InputDimension { k, got: r.len(), m });
    }
    if x0.iter().chain(v.iter().flatten()).any(|a| !a.is_finite()) {
        return Err(OptimizeError::NotFinite);
    }
    Ok(())
}

/// [`maximize_delta`] on untrusted input: the inputs are checked first ([`check_inputs`]).
pub fn try_maximize_delta(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    v0: &[Vec<f64>],
    steps_max: usize,
    settings: &BundleSettings,
    cancel: &AtomicBool,
) -> Result<Optimized, OptimizeError> {
    check_inputs(lp, x0, v0)?;
    settings.validate()?;
    Ok(bundle::maximize(
        lp, lc, x0, v0, steps_max, settings, cancel,
    ))
}

/// §5.3: maximise the certified robustness δ(0) of the nominal from x0 over v and the terminal time
/// (len(v) ≤ steps_max). Returns the best certified iterate (never worse than the start).
///
/// The pipeline calls this with inputs it built itself; x0 and v must fit the loop (n and m components,
/// finite). An empty v starts from one zero input. For inputs from outside use [`try_maximize_delta`].
pub fn maximize_delta(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    v0: &[Vec<f64>],
    steps_max: usize,
    settings: &BundleSettings,
    cancel: &AtomicBool,
) -> Optimized {
    bundle::maximize(lp, lc, x0, v0, steps_max, settings, cancel)
}

#[cfg(test)]
mod tests {
    use super::BundleSettings;

    #[test]
    fn the_bundle_builder_refuses_a_serious_fraction_outside_the_unit_interval() {
        let e = BundleSettings::builder()
            .serious_fraction(1.5)
            .build()
            .unwrap_err();
        assert_eq!((e.field, e.value), ("serious_fraction", 1.5));
        assert_eq!(
            e.to_string(),
            "BundleSettings.serious_fraction = 1.5: must lie in (0, 1)"
        );
        let e = BundleSettings::builder()
            .max_step(1e-9)
            .build()
            .unwrap_err();
        assert_eq!(e.field, "max_step");
        assert!(BundleSettings::builder().hold(0).build().is_err());
        assert_eq!(BundleSettings::builder().hold(20).build().unwrap().hold, 20);
    }
}
