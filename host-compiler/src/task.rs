//! The task (DESIGN §3): built once from a validated spec, then lent to every stage.
//!
//! A [`Task`] holds the plant as a [`Plant`] (its class chosen here, from the spec), the property with
//! its sets in the forms the stages compute with, Init, the horizon in samples and the spec's settings.
//! No stage builds any of these again.

use crate::model::feedback_linearizable::{self, FlError};
use crate::model::hybrid::{Hybrid, HybridError};
use crate::model::{LinearAffine, ModelError, Plant};
use crate::property::{ConvexSets, PropertyError, ReachAvoid};
use crate::spec::{InitBox, Problem, SynthesisSettings};

/// One control task, ready for synthesis and verification.
pub struct Task {
    /// The validated spec it was built from (names, sets as written, settings).
    pub problem: Problem,
    pub plant: Box<dyn Plant>,
    pub property: ReachAvoid,
    /// Goal and Unsafe as convex pieces, for the trajectory generator.
    pub convex: ConvexSets,
    /// Samples in the horizon ([`Problem::horizon_steps`]).
    pub steps: usize,
}

/// Why a validated spec does not make a task.
#[derive(Debug, thiserror::Error)]
pub enum TaskError {
    #[error("plant: {0}")]
    Model(#[from] ModelError),
    #[error("sets: {0}")]
    Property(#[from] PropertyError),
    #[error("plant: {0}")]
    Hybrid(#[from] HybridError),
    /// The spec's hybrid automaton is valid, but a one-location `Task` cannot hold it: hybrid tasks are
    /// synthesised and verified through `synth::hybrid::HybridTask` (internal or forced switching).
    #[error(
        "the plant is a hybrid automaton ({locations} locations, {edges} edges); it is valid, but \
         this path takes one-location plants (synth and verify take hybrid specs through synth::hybrid)"
    )]
    HybridNotSupported { locations: usize, edges: usize },
    /// A feedback-linearizable plant outside what this version linearises and bounds.
    #[error("plant: {0}")]
    Linearize(#[from] FlError),
}

impl Task {
    /// The task of a validated spec: the plant's class from the spec (linear affine, in continuous time
    /// sampled by an exact zero-order hold, or in discrete time; feedback linearizable, whose task is the
    /// linear one in ξ with the maps on the plant), and the reach-avoid property.
    pub fn new(problem: Problem) -> Result<Self, TaskError> {
        if let Some(h) = &problem.hybrid {
            // Built (so that every check of the automaton runs), then refused: the pipeline's stages
            // still run location 0 only.
            let hy = Hybrid::from_spec(h, problem.plant.period)?;
            return Err(TaskError::HybridNotSupported {
                locations: hy.modes().len(),
                edges: hy.edges().len(),
            });
        }
        if problem.nonlinear.is_some() {
            // Every stage works on the linear model in ξ; the plant carries the maps and bounds.
            let flat = problem.nonlinear.as_ref().is_some_and(|d| d.flat.is_some());
            if flat {
                // The chain in the flat state q, the maps and their bounds (`model::flat`); the
                // firmware and the Monte Carlo keep the controller's own states ζ.
                let (q, maps) = crate::model::flat::flatten(&problem)?;
                let plant: Box<dyn Plant> = Box::new(feedback_linearizable::plant(&q, maps)?);
                return Self::with_plant(q, plant);
            }
            let (xi, maps) = feedback_linearizable::linearize(&problem)?;
            let plant: Box<dyn Plant> = Box::new(feedback_linearizable::plant(&xi, maps)?);
            return Self::with_plant(xi, plant);
        }
        let plant: Box<dyn Plant> = Box::new(LinearAffine::from_spec(&problem.plant)?);
        Self::with_plant(problem, plant)
    }

    fn with_plant(problem: Problem, plant: Box<dyn Plant>) -> Result<Self, TaskError> {
        let property = ReachAvoid::from_problem(&problem)?;
        let convex = ConvexSets::from_problem(&problem)?;
        let steps = problem.horizon_steps();
        Ok(Self {
            problem,
            plant,
            property,
            convex,
            steps,
        })
    }

    /// The same task with another Goal (the plant rebuilt from the spec; Unsafe, the input set, Init,
    /// the horizon and the settings as they are): the task a cover is grown for when its runs must end in
    /// a terminal law's handover region inside Goal ([`crate::certify::terminal`]'s module doc). The
    /// spec's own Goal stays in [`Task::problem`], for the report and for judging runs.
    pub fn with_goal(
        &self,
        piece: crate::property::ConvexPiece,
        region: Box<dyn crate::geometry::Region>,
    ) -> Result<Task, TaskError> {
        let mut task = Task::new(self.problem.clone())?;
        task.property.goal = region;
        task.convex.goal = piece;
        Ok(task)
    }

    /// Init, a box in state coordinates.
    pub fn init(&self) -> &InitBox {
        &self.problem.init
    }

    /// The spec's `[synthesis]` settings.
    pub fn settings(&self) -> &SynthesisSettings {
        &self.problem.synthesis
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A feedback-linearizable spec (Example 4.9) becomes the task of its linear model in ξ, with the
    /// plant's mismatch bound and maps on the plant.
    #[test]
    fn a_feedback_linearizable_plant_is_a_task_in_xi() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/fl-4-9.toml");
        let problem = crate::spec::load(path).expect("the shipped example");
        let task = Task::new(problem).expect("a task");
        assert_eq!((task.plant.n(), task.plant.m()), (4, 2));
        assert!(task.plant.model_mismatch() > 0.0);
        let maps = task.plant.linearization().expect("maps");
        assert_eq!(maps.n_plant, 6);
    }

    /// A differentially flat spec is the chain in its flat state q (two chains of four for the
    /// quadrotor); with an MTL formula it is refused with the reason.
    #[test]
    fn a_differentially_flat_task_is_its_chain_in_q_and_takes_a_formula() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/flat-quadrotor.toml"
        );
        let problem = crate::spec::load(path).expect("the shipped example");
        let task = Task::new(problem.clone()).expect("a flat task");
        assert_eq!((task.plant.n(), task.plant.m()), (8, 2));
        let maps = task.plant.linearization().expect("maps");
        assert_eq!((maps.n_plant, maps.m_plant), (6, 2));
        assert_eq!(maps.flat.as_ref().expect("flat").ext_orders, vec![2]);
        // A formula becomes the task in q; a set name the spec lacks is reported where the formula is
        // bound, not a panic.
        let mut temporal = problem;
        temporal.mtl = Some("F[0,6] Goal".into());
        let task = Task::new(temporal.clone()).expect("a flat MTL task");
        assert!(crate::property::TemporalTask::from_problem(&task.problem).is_ok());
        temporal.mtl = Some("F[0,6] goal".into());
        let task = Task::new(temporal).expect("the name is bound later");
        let Err(e) = crate::property::TemporalTask::from_problem(&task.problem) else {
            panic!("an unknown set is refused")
        };
        assert!(e.to_string().contains("goal"), "{e}");
    }
}
