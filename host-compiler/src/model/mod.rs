//! Plant models: the [`Plant`] interface every plant class implements (module `plant`), and its first
//! class, [`LinearAffine`]: linear affine plants in continuous time (ẋ = A x + B u + c, with a sample
//! period) and discrete time (x⁺ = A x + B u + g); the exact zero-order-hold discretisation ([`zoh`], via the matrix
//! exponential [`expm`]); closed-loop simulation with the feedback law u = K x + v(κ) of (3.5)/(3.63); and the
//! inter-sample excursion bound ([`InterSampleBound`]) the certification uses to account for what the
//! continuous plant does between samples.
//!
//! Hybrid automata over linear affine locations, with their exact simulation across events, are in
//! [`hybrid`]; nonlinear input-affine plants written in the spec, flowed by an adaptive integrator, in
//! [`nonlinear`].
//!
//! Matrices are faer `Mat<f64>`, vectors `Vec<f64>` / `&[f64]`.

mod expm;
pub mod feedback_linearizable;
pub mod flat;
pub mod hybrid;
mod intersample;
mod linear;
pub mod nonlinear;
mod plant;
mod sim;

pub use expm::expm;
pub use intersample::{chi3, drift_against, drift_against_grad, InterSampleBound};
pub use linear::{zoh, ContinuousPlant, DiscretePlant, LinearAffine};
pub use plant::{Location, Plant};
pub use sim::{reference_inputs, simulate_closed_loop, ClosedLoopRun};

/// Bad input to a model constructor or helper (dimensions, non-finite numbers, periods).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A matrix or vector has the wrong shape.
    #[error("{what}: expected {expected}, got {got}")]
    Dimension {
        what: &'static str,
        expected: String,
        got: String,
    },
    /// A NaN or infinity where a finite number is required.
    #[error("{what} contains a non-finite entry")]
    NonFinite { what: &'static str },
    /// The sample period must be finite and > 0.
    #[error("sample period must be finite and > 0, got {0}")]
    Period(f64),
    /// e^M of finite M overflows f64.
    #[error("e^M overflows f64 (‖M‖₁ = {norm:.3e})")]
    ExpOverflow { norm: f64 },
    /// The exact zero-order hold of a continuous plant overflows f64: e^{A h} is too large.
    #[error(
        "exp(A·h) overflows f64 for the sample period h = {period} s (‖[A B c]·h‖₁ = {norm:.3e}): the \
         sampled plant cannot be represented; shorten plant.period or rescale plant.A"
    )]
    SampledOverflow { period: f64, norm: f64 },
}

pub(crate) fn check_finite(what: &'static str, m: faer::MatRef<'_, f64>) -> Result<(), ModelError> {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            if !m[(i, j)].is_finite() {
                return Err(ModelError::NonFinite { what });
            }
        }
    }
    Ok(())
}

pub(crate) fn check_len(what: &'static str, v: &[f64], n: usize) -> Result<(), ModelError> {
    if v.len() != n {
        return Err(ModelError::Dimension {
            what,
            expected: format!("length {n}"),
            got: format!("length {}", v.len()),
        });
    }
    if v.iter().any(|x| !x.is_finite()) {
        return Err(ModelError::NonFinite { what });
    }
    Ok(())
}
