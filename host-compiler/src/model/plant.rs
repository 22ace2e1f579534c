//! The one interface every plant class implements (DESIGN §3): what synthesis, certification,
//! verification and the QEMU harness ask of a plant, whatever its class.
//!
//! A plant is sampled: the firmware reads the state every `period` seconds and holds its input until the
//! next sample (zero-order hold). What the pipeline needs of it:
//! * **the sampled step** ([`Plant::step`]): where the plant is one period later, for simulation and
//!   verification;
//! * **the flow between samples** ([`Plant::vector_field`], [`Plant::between_samples`]): the vector
//!   field for the inter-sample bound of the certificate, and states inside the period for the
//!   verifier's check between samples;
//! * **locations** ([`Plant::locations`]): one for a plain plant; a hybrid automaton (§3.2) has several,
//!   with guards and resets between them, and each trait method takes the location it is asked about;
//! * **the coordinates the CAF lives in** ([`Plant::error_dynamics`]): per location, the sampled linear
//!   model x⁺ = A x + B u + g whose error dynamics e⁺ = (A + BK) e the CAF (3.66)–(3.67) certifies. For a
//!   linear affine plant these are the plant's own coordinates; a feedback-linearizable or flat plant
//!   (§3.1.2–3.1.3) gives its linear model in ξ or the flat state, with the maps to and from it;
//! * **the continuous model** ([`Plant::continuous`]) behind the samples, when the plant is given in
//!   continuous time, from which the certificate's inter-sample constants come.
//!
//! A new plant class is a new module implementing this trait (and, for the firmware, an image section);
//! nothing in the pipeline's middle matches on the class.

use super::{ContinuousPlant, DiscretePlant};

/// Index of a discrete location (mode) of a plant: 0 for a plant with one location.
pub type Location = usize;

/// A sampled plant of any class (module doc).
pub trait Plant: Send + Sync + std::fmt::Debug {
    /// State dimension n.
    fn n(&self) -> usize;
    /// Input dimension m.
    fn m(&self) -> usize;
    /// Sample period h in seconds.
    fn period(&self) -> f64;
    /// Number of locations (1 for a plant without discrete modes).
    fn locations(&self) -> usize {
        1
    }
    /// The sampled linear model of location `loc` in the coordinates the CAF lives in: its error dynamics
    /// are what the CAF and the feedback are designed for, and the nominal of the tracking loop is
    /// simulated with it.
    fn error_dynamics(&self, loc: Location) -> &DiscretePlant;
    /// The continuous-time model of location `loc` behind the samples, if the plant is in continuous time.
    fn continuous(&self, loc: Location) -> Option<&ContinuousPlant>;
    /// One sample period from `x` with `u` held: the state at the next sample.
    fn step(&self, loc: Location, x: &[f64], u: &[f64]) -> Vec<f64>;
    /// [`Plant::step`] into `out` (n values, the same ones), for loops that step every run's every
    /// sample.
    fn step_into(&self, loc: Location, x: &[f64], u: &[f64], out: &mut [f64]) {
        out.copy_from_slice(&self.step(loc, x, u));
    }
    /// The vector field at the sample, ẋ(κh) with the held input, for continuous-time plants (`None` for a
    /// plant given in discrete time, which has no motion between samples).
    fn vector_field(&self, loc: Location, x: &[f64], u: &[f64]) -> Option<Vec<f64>> {
        self.continuous(loc).map(|c| c.f(x, u))
    }
    /// Visits the states strictly inside the period after `x` with `u` held, at equally spaced instants
    /// in time order, for the verifier's check between samples (none for a discrete-time plant). A visitor
    /// rather than a list: the verifier calls this every step of every Monte Carlo run.
    fn between_samples(&self, loc: Location, x: &[f64], u: &[f64], visit: &mut dyn FnMut(&[f64]));
    /// An upper bound on how far the plant moves from `x` within the period with `u` held,
    /// sup over τ ∈ [0, h] of ‖x(κh + τ) − x‖₂ (`model::intersample`), which bounds every state
    /// [`Plant::between_samples`] visits: a check those states provably pass (the sample's clearance
    /// from a set above it) may then be skipped. `None` when the class has no such bound.
    fn excursion(&self, _loc: Location, _x: &[f64], _u: &[f64]) -> Option<f64> {
        None
    }
    /// A bound on a disturbance in the input channel of the linear model, varying within the period, by
    /// which the sampled loop departs from that model (2-norm, input units): 0 when the sampled model is
    /// exact (linear affine plants); a feedback-linearizable plant's held input drifts from the
    /// linearising one between samples (`feedback_linearizable`, module doc item 3).
    fn model_mismatch(&self) -> f64 {
        0.0
    }
    /// The maps between the plant's own coordinates and those of the linear model, when they differ.
    fn linearization(&self) -> Option<&super::feedback_linearizable::FlMaps> {
        None
    }
}
