//! The robust semantics of a property on one sampled trace (Def 2.16–2.17): the common interface through
//! which a run is scored, whether the task is reach-avoid (Problem 2.26) or a temporal-logic formula
//! (Problem 2.28).
//!
//! * [`ReachAvoid`] scores a trace by the until embedding of Remark 2.29,
//!   `¬Unsafe ∧ (¬Unsafe U[0,T] (Goal ∧ ¬Unsafe))`, computed by the shared Theorem 4.7 scans
//!   ([`crate::robustness::safety::safety_robustness_joint`]) without the input part (a trace of states
//!   does not carry the feedback law the input part is measured through).
//! * [`Temporal`] scores it by an MTL formula over named sets ([`crate::robustness::mtl`]).
//!
//! Both take the trace's signals in state order and the Euclidean metric of the sets; a positive value
//! is the margin by which the trace satisfies the property. The two agree on the embedding formula (a
//! test holds them to it), which is what lets MTL synthesis reuse the reach-avoid machinery.

use super::ReachAvoid;
use crate::geometry::{Empty, Metric};
use crate::robustness::mtl::{Formula, MtlError, NamedSet, Trace};
use crate::robustness::safety::{
    safety_robustness_joint, SafetyError, SafetySet, SafetySpec, SampledTrajectory,
};

/// A property with a robust semantics on sampled traces of the state.
pub trait Property {
    /// The robustness of the trace at its first sample: > 0 when the property holds with that margin,
    /// < 0 when it fails by that margin.
    fn trace_robustness(&self, trace: &Trace) -> Result<f64, SemanticsError>;
}

/// Why a trace could not be scored.
#[derive(Debug, thiserror::Error)]
pub enum SemanticsError {
    #[error("the trace has {found} signals but the property is over {n} states")]
    Signals { found: usize, n: usize },
    #[error(transparent)]
    Safety(#[from] SafetyError),
    /// Boxed: a formula error carries its source text.
    #[error(transparent)]
    Mtl(Box<MtlError>),
}

impl Property for ReachAvoid {
    fn trace_robustness(&self, trace: &Trace) -> Result<f64, SemanticsError> {
        let n = self.goal.dim();
        let found = trace.names().len();
        if found != n {
            return Err(SemanticsError::Signals { found, n });
        }
        let cols = trace.columns();
        let states: Vec<f64> = (0..trace.len())
            .flat_map(|k| cols.iter().map(move |c| c[k]))
            .collect();
        let traj = SampledTrajectory::new(trace.times(), &states, n)?;
        let nowhere = Empty(n);
        let metric = Metric::euclidean(n);
        let spec = SafetySpec {
            goal: SafetySet::Region(self.goal.as_ref()),
            unsafe_set: SafetySet::Region(self.unsafe_region().unwrap_or(&nowhere)),
            input: None,
            metric: &metric,
            T: trace.times()[0] + self.horizon,
        };
        Ok(safety_robustness_joint(&traj, &spec)?.delta)
    }
}

/// An MTL task: a formula over named sets (Problem 2.28).
pub struct Temporal {
    pub formula: Formula,
    pub sets: Vec<NamedSet>,
}

impl Property for Temporal {
    fn trace_robustness(&self, trace: &Trace) -> Result<f64, SemanticsError> {
        let boxed = |e: MtlError| SemanticsError::Mtl(Box::new(e));
        let monitor = self
            .formula
            .bind(trace.names(), &self.sets)
            .map_err(|e| boxed(e.into()))?;
        Ok(monitor.robustness(trace).map_err(boxed)?[0])
    }
}
