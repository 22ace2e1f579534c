//! Robustness of sampled trajectories (DESIGN §3, "trajectory ──robustness──▶ δ").
//!
//! This module owns two computations on a nominal trajectory, both linear in the number of samples:
//!
//! * [`safety`]: the safety robustness δ of Theorem 4.7 (reach Goal by time T while avoiding Unsafe and
//!   keeping the feedback input admissible), with the critical time and the critical set point of each
//!   part, which the optimiser needs for subgradients (§5.3). Its three scans ([`goal_part`],
//!   [`unsafe_part`], [`input_part`]) are the one implementation of the theorem's extrema: the
//!   certifier of the sampled f32 loop (`crate::certify`) runs them on its per-sample terms.
//! * [`mtl`]: the robust semantics of metric temporal logic (Def 2.16, Def 2.17) on discrete-time
//!   traces: a formula parser, a streaming evaluator (sliding-window min/max with monotone deques and a
//!   two-stack window for bounded until), a direct reference evaluator used as the test oracle and
//!   bench baseline, and the CSV trace reader behind `host-compiler mtl`.
//!
//! Sign convention, shared with `geometry` (Def 2.16, (2.8)): a positive robustness is a margin by
//! which the property holds, a negative one the margin by which it fails.

pub mod mtl;
pub mod safety;

pub use safety::{
    goal_at, goal_part, input_part, safety_robustness, safety_robustness_joint, unsafe_part,
    Binding, Critical, FnInput, InputSets, SafetyError, SafetyRobustness, SafetySet, SafetySpec,
    SampledTrajectory, UnsafePart,
};
