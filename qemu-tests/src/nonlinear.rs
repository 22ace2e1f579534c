//! Nonlinear plants on the host for the HIL loop (issue 13 item 7): a plant is anything that can flow its
//! state over one sample period with the input held ([`PlantFlow`]). The plant `ẋ = f(x) + g(x)u` of a
//! spec written as expressions is the host compiler's own `model::nonlinear::NonlinearPlant`, integrated
//! by `ode_solvers`' Dop853 at rtol 10⁻¹⁰ (the same flow `verify` judges images with).

use host_compiler::model::nonlinear::NonlinearPlant;

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

impl PlantFlow for NonlinearPlant {
    fn n(&self) -> usize {
        NonlinearPlant::n(self)
    }

    fn m(&self) -> usize {
        NonlinearPlant::m(self)
    }

    fn flow(&self, x: &[f64], u: &[f64], h: f64) -> Result<Vec<f64>, String> {
        NonlinearPlant::flow(self, x, u, h, 1, &mut |_| {}).map_err(|e| e.to_string())
    }
}
