//! What the library keeps of clarabel's refusals: [`SetupError`], clarabel's `SolverError` reduced to small
//! `Copy` data, so that the error enums that carry it stay `Clone` and `PartialEq` (clarabel's own type holds
//! I/O and JSON errors and is neither). A solve that runs reports a `clarabel::solver::SolverStatus`, which
//! callers carry as it is.

use clarabel::solver::SolverError;

/// Why clarabel refused to set a problem up (`DefaultSolver::new`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SetupError {
    /// The problem data are inconsistent (shapes, cones, non-finite entries); clarabel names the field.
    #[error("bad input data: {0}")]
    BadInputData(&'static str),
    /// Clarabel refused its settings (clarabel does not export the type that names the field).
    #[error("bad settings")]
    BadSettings,
    /// File or JSON input/output (not used by this crate's problems).
    #[error("I/O or JSON error")]
    Io,
}

impl From<SolverError> for SetupError {
    fn from(e: SolverError) -> Self {
        match e {
            SolverError::BadInputData(f) => SetupError::BadInputData(f),
            SolverError::SettingsError(_) => SetupError::BadSettings,
            SolverError::IoError(_) | SolverError::JsonError(_) => SetupError::Io,
        }
    }
}
