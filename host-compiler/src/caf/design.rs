//! The CAF and feedback of a task's plant, designed once per run (§3.2, Remark 3.22): the discrete LMIs
//! (3.66)–(3.67) on each location's sampled model with the spec's σ-margin, the exactly symmetric metric
//! P, and the gain K̂ as the image ships it (f32). Everything downstream is certified for K̂, not K.
//! For a continuous-time plant the CAF of (3.8) is designed too, for the report only.

use super::{synthesize_continuous, synthesize_discrete, CafError, CafOutcome, CafSettings};
use crate::linalg::round32;
use crate::model::{Location, Plant};
use crate::task::Task;
use faer::Mat;

/// The designed CAF of a task (one location).
#[derive(Clone, Debug)]
pub struct Design {
    /// The gain as shipped: the f32 values of the LMI's K, widened exactly.
    pub K: Mat<f64>,
    /// The CAF metric, exactly symmetric (so that its f32 image is too).
    pub P: Mat<f64>,
    /// The continuous-time (K, P) of LMI (3.8) for continuous plants (reported, not used by the image).
    pub continuous: Option<(Mat<f64>, Mat<f64>)>,
    /// Why the continuous-time CAF (reported only) is missing, if it is.
    pub warnings: Vec<String>,
}

/// Why no CAF was designed: bad input to the solver, or the solver's outcome (kept as data).
#[derive(Debug, thiserror::Error)]
pub enum DesignError {
    #[error(transparent)]
    Input(#[from] CafError),
    #[error("{}", outcome_message(.0))]
    Outcome(Box<CafOutcome>),
}

/// Designs the CAF and the shipped gain of the task's plant (module doc): of its one location.
pub fn design(task: &Task) -> Result<Design, DesignError> {
    design_location(&*task.plant, 0, task.settings().sigma_margin)
}

/// The CAF of every location of a plant (§3.2: a CAF ψ_ℓ and gain per location, the feedback (3.69)),
/// or the first location that has none, with the reason.
pub fn design_locations(
    plant: &dyn Plant,
    sigma: f64,
) -> Result<Vec<Design>, (Location, DesignError)> {
    (0..plant.locations())
        .map(|loc| design_location(plant, loc, sigma).map_err(|e| (loc, e)))
        .collect()
}

/// The CAF and shipped gain of location `loc` of a plant, with the σ-margin `sigma` (module doc).
pub fn design_location(
    plant: &dyn Plant,
    loc: Location,
    sigma: f64,
) -> Result<Design, DesignError> {
    let (n, m) = (plant.n(), plant.m());
    let settings = CafSettings {
        sigma,
        ..Default::default()
    };
    let caf = match synthesize_discrete(plant.error_dynamics(loc), &settings)? {
        CafOutcome::Solved(c) => c,
        other => return Err(DesignError::Outcome(Box::new(other))),
    };
    let mut warnings = Vec::new();
    // What the loop would certify with continuous feedback (Example 3.3 gives K = −0.1·[0 I] and P = I for
    // the planar vehicle).
    let continuous = plant.continuous(loc).and_then(|c| {
        let st = CafSettings {
            sigma: 0.0,
            ..Default::default()
        };
        match synthesize_continuous(c, &st) {
            Ok(CafOutcome::Solved(caf)) => Some((caf.K, caf.P)),
            Ok(other) => {
                warnings.push(format!(
                    "continuous-time CAF (3.8), reported only: {}",
                    outcome_message(&other)
                ));
                None
            }
            Err(e) => {
                warnings.push(format!("continuous-time CAF (3.8), reported only: {e}"));
                None
            }
        }
    });
    Ok(Design {
        K: Mat::from_fn(m, n, |i, j| round32(caf.K[(i, j)])),
        P: crate::linalg::sym(caf.P.as_ref()),
        continuous,
        warnings,
    })
}

/// A control engineer's reading of a CAF synthesis that did not produce a certificate.
pub fn outcome_message(o: &CafOutcome) -> String {
    use CafOutcome::*;
    match o {
        Solved(_) => "solved".into(),
        NotStabilizable { mode } => {
            format!("the sampled plant is not stabilizable: {mode}")
        }
        MarginUnachievable { mode, max_sigma } => format!(
            "the σ-margin cannot be met: {mode}; it allows at most σ = {max_sigma:.4} \
             (lower [synthesis] sigma_margin)"
        ),
        Infeasible { stage, status } => {
            format!("the LMIs are infeasible at stage {stage} ({status})")
        }
        SolverFailed { stage, status } => format!("clarabel failed at stage {stage} ({status})"),
        ValidationFailed { reason } => {
            format!("the solver's answer failed the independent check: {reason}")
        }
    }
}
