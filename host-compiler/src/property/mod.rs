//! What a run must satisfy (DESIGN §3): the task's property and the sets it is stated over.
//!
//! Today's property is reach-avoid (Problem 2.26): reach Goal within the horizon, never enter Unsafe
//! before, apply only inputs in the input set. Its robustness for one nominal trajectory is Theorem 4.7,
//! evaluated for the sampled f32 loop by [`crate::certify`] and, piece by piece with gradients, by the
//! optimiser. An MTL task (Problem 2.28, the semantics in [`crate::robustness::mtl`]) is the second
//! property, [`Temporal`]; both score sampled traces through the one interface [`Property`]
//! ([`semantics`]).

pub mod semantics;
mod sets;
pub mod temporal;

pub use semantics::{Property, SemanticsError, Temporal};
pub use sets::{convex_piece, input_bound, input_scale, ConvexPiece, InputBound};
pub use temporal::{state_signals, TemporalError, TemporalTask};

use crate::geometry::Region;
use crate::spec::{Problem, SpecError};

/// The sets of a reach-avoid task as regions with signed distances in any metric (what certification,
/// verification and optimisation evaluate), and the input set.
pub struct ReachAvoid {
    pub goal: Box<dyn Region>,
    /// The union of the Unsafe sets; `None` when the spec has none.
    pub unsafe_set: Option<Box<dyn Region>>,
    pub input: InputBound,
    /// T: Goal must be reached within [0, T] seconds.
    pub horizon: f64,
}

/// Goal and the members of Unsafe as convex pieces: the form the trajectory generator's convex
/// subproblems constrain.
pub struct ConvexSets {
    pub goal: ConvexPiece,
    pub unsafe_pieces: Vec<ConvexPiece>,
}

impl ConvexSets {
    /// The convex pieces of a validated spec's Goal and Unsafe sets, in state coordinates.
    pub fn from_problem(problem: &Problem) -> Result<Self, PropertyError> {
        let n = problem.plant.n();
        Ok(Self {
            goal: convex_piece(&problem.goal, n)?,
            unsafe_pieces: problem
                .unsafe_sets
                .iter()
                .map(|s| convex_piece(s, n))
                .collect::<Result<_, _>>()?,
        })
    }
}

/// Why a spec's sets could not be turned into a property.
#[derive(Debug, thiserror::Error)]
pub enum PropertyError {
    #[error(transparent)]
    Spec(#[from] SpecError),
}

impl ReachAvoid {
    /// The reach-avoid property of a validated spec, in state coordinates.
    pub fn from_problem(problem: &Problem) -> Result<Self, PropertyError> {
        Ok(Self {
            goal: problem.goal_region()?,
            unsafe_set: problem.unsafe_region()?,
            input: input_bound(&problem.input),
            horizon: problem.horizon,
        })
    }

    /// Unsafe as a borrowed region.
    pub fn unsafe_region(&self) -> Option<&dyn Region> {
        self.unsafe_set.as_deref()
    }
}
