//! An owned certified loop built from a spec, the same way the pipeline builds it (sampled plant, discrete
//! CAF with the spec's σ-margin, f32 gain K̂): for the optimiser's tests, benches and callers outside the
//! pipeline that need a [`Loop`] without running a synthesis.

use crate::certify::{CertifyError, Loop, LoopConstants};
use crate::geometry::Region;
use crate::spec::Problem;
use crate::synth::{round32, sampled_plant, SampledPlant};
use crate::trajectory::generate::InputBound;
use faer::Mat;

/// Why a loop could not be built from a spec.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    #[error("plant: {0}")]
    Plant(String),
    #[error("no CAF and feedback: {0}")]
    Caf(String),
    #[error("sets: {0}")]
    Sets(String),
    #[error(transparent)]
    Certify(#[from] CertifyError),
}

/// Everything a [`Loop`] borrows, owned.
pub struct OwnedLoop {
    pub plant: SampledPlant,
    /// The gain as shipped (f32 values widened exactly).
    pub K: Mat<f64>,
    /// The CAF metric (exactly symmetric).
    pub P: Mat<f64>,
    pub goal: Box<dyn Region>,
    pub unsafe_set: Option<Box<dyn Region>>,
    pub input: InputBound,
    /// The spec's horizon in steps.
    pub steps: usize,
    /// Sample period h.
    pub period: f64,
}

impl OwnedLoop {
    /// The sampled plant, CAF (3.66)–(3.67) with the spec's σ-margin and the f32 gain, as `synth` builds them.
    pub fn from_problem(problem: &Problem) -> Result<Self, SetupError> {
        let n = problem.plant.n();
        let m = problem.plant.m();
        let plant = sampled_plant(problem).map_err(|e| SetupError::Plant(e.to_string()))?;
        let dp = crate::model::DiscretePlant::new(
            plant.A.clone(),
            plant.B.clone(),
            plant.g.clone(),
            problem.plant.period,
        )
        .map_err(|e| SetupError::Plant(e.to_string()))?;
        let st = crate::caf::CafSettings {
            sigma: problem.synthesis.sigma_margin,
            ..Default::default()
        };
        let caf = match crate::caf::synthesize_discrete(&dp, &st)
            .map_err(|e| SetupError::Caf(e.to_string()))?
        {
            crate::caf::CafOutcome::Solved(c) => c,
            other => return Err(SetupError::Caf(format!("{other:?}"))),
        };
        let P = crate::linalg::sym(caf.P.as_ref());
        let K = Mat::from_fn(m, n, |i, j| round32(caf.K[(i, j)]));
        let goal = problem
            .goal_region()
            .map_err(|e| SetupError::Sets(e.to_string()))?;
        let unsafe_set = problem
            .unsafe_region()
            .map_err(|e| SetupError::Sets(e.to_string()))?;
        let input = crate::synth::input_bound(&problem.input);
        Ok(Self {
            plant,
            K,
            P,
            goal,
            unsafe_set,
            input,
            steps: problem.horizon_steps(),
            period: problem.plant.period,
        })
    }

    /// The borrowed view the certifier and the optimiser take.
    pub fn lp(&self) -> Loop<'_> {
        Loop {
            A: self.plant.A.as_ref(),
            B: self.plant.B.as_ref(),
            g: &self.plant.g,
            K: self.K.as_ref(),
            P: self.P.as_ref(),
            continuous: self.plant.continuous.as_ref(),
            goal: self.goal.as_ref(),
            unsafe_set: self.unsafe_set.as_deref(),
            input: &self.input,
        }
    }

    /// Its trajectory-independent constants.
    pub fn constants(&self) -> Result<LoopConstants, SetupError> {
        Ok(LoopConstants::new(&self.lp())?)
    }
}
