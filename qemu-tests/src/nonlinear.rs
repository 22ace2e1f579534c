//! Nonlinear plants on the host for the HIL loop (issue 13 item 7): a plant is anything that can flow its
//! state over one sample period with the input held ([`PlantFlow`]); [`ControlAffine`] is the plant
//! `ẋ = f(x) + g(x)u` of a spec written as expressions (`host_compiler::spec::nonlinear`), integrated with
//! the adaptive Dormand–Prince 5(4) method of `ode_solvers` at a tight tolerance ([`RTOL`], [`ATOL`]).
//!
//! The trait is small on purpose: the host compiler's own one-period flow of a nonlinear plant implements
//! it as well, so the closed loop ([`crate::closed_loop::run_with`]) runs either.

use host_compiler::expr::{Expr, Point};
use host_compiler::spec::nonlinear::NonlinearDesc;
use ode_solvers::{DVector, Dopri5, OutputType, System};

/// Relative tolerance of the integration.
pub const RTOL: f64 = 1e-10;
/// Absolute tolerance of the integration.
pub const ATOL: f64 = 1e-10;

/// A continuous-time plant sampled with a zero-order hold: its state after `h` seconds from `x` under
/// the constant input `u`.
pub trait PlantFlow {
    /// State dimension.
    fn n(&self) -> usize;
    /// Input dimension.
    fn m(&self) -> usize;
    /// The state after `h` seconds from `x` with `u` held; an error names why the integration failed.
    fn flow(&self, x: &[f64], u: &[f64], h: f64) -> Result<Vec<f64>, String>;
}

/// `ẋ = f(x) + g(x)u` with f and g as expressions (parameters bound to their values).
#[derive(Clone, Debug)]
pub struct ControlAffine {
    f: Vec<Expr>,
    /// n rows of m entries.
    g: Vec<Vec<Expr>>,
    m: usize,
}

impl ControlAffine {
    /// The plant of a validated spec.
    pub fn from_spec(desc: &NonlinearDesc) -> Self {
        let p = desc.names.param_values();
        ControlAffine {
            f: desc.system.f.iter().map(|e| e.bind_params(&p)).collect(),
            g: desc
                .system
                .g
                .iter()
                .map(|row| row.iter().map(|e| e.bind_params(&p)).collect())
                .collect(),
            m: desc.names.inputs.len(),
        }
    }

    /// The vector field at `x` under `u`.
    pub fn field(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let at = Point { x, u, p: &[] };
        for ((d, f), g) in dx.iter_mut().zip(&self.f).zip(&self.g) {
            *d = f.eval(&at)
                + g.iter()
                    .zip(u)
                    .map(|(gj, uj)| gj.eval(&at) * uj)
                    .sum::<f64>();
        }
    }
}

/// The system `ode_solvers` integrates: the field with the input held.
struct Held<'a> {
    plant: &'a ControlAffine,
    u: &'a [f64],
}

impl System<f64, DVector<f64>> for Held<'_> {
    fn system(&self, _t: f64, y: &DVector<f64>, dy: &mut DVector<f64>) {
        self.plant.field(y.as_slice(), self.u, dy.as_mut_slice());
    }
}

impl PlantFlow for ControlAffine {
    fn n(&self) -> usize {
        self.f.len()
    }

    fn m(&self) -> usize {
        self.m
    }

    fn flow(&self, x: &[f64], u: &[f64], h: f64) -> Result<Vec<f64>, String> {
        if x.len() != self.n() || u.len() != self.m {
            return Err(format!(
                "flow of a plant with n = {}, m = {} from x of {} and u of {} values",
                self.n(),
                self.m,
                x.len(),
                u.len()
            ));
        }
        let held = Held { plant: self, u };
        // Sparse output: the accepted steps themselves, the last of which ends exactly at h.
        let mut solver = Dopri5::from_param(
            held,
            0.0,
            h,
            h,
            DVector::from_column_slice(x),
            RTOL,
            ATOL,
            0.9,
            0.04,
            0.2,
            10.0,
            h,
            0.0,
            100_000,
            1000,
            OutputType::Sparse,
        );
        solver
            .integrate()
            .map_err(|e| format!("Dopri5 from x = {x:?}, u = {u:?}: {e}"))?;
        let (t, y) = solver.results().get();
        match (t.last(), y.last()) {
            (Some(&t), Some(y)) if (t - h).abs() <= 1e-12 * h.max(1.0) => Ok(y.as_slice().to_vec()),
            _ => Err(format!("Dopri5 from x = {x:?} did not reach t = {h}")),
        }
    }
}
