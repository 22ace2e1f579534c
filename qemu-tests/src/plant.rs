//! The plant the firmware controls, simulated on the host: a continuous linear affine system
//! `ẋ = A x + B u + c`, sampled with the exact zero-order hold of `host_compiler::model` (DESIGN §5), so the
//! HIL loop and synthesis share one discretisation.

use faer::Mat;
pub use host_compiler::model::{ContinuousPlant, DiscretePlant};

/// The double integrator `ẍ = u`: state (position, velocity), one input.
pub fn double_integrator() -> ContinuousPlant {
    let A = Mat::from_fn(2, 2, |i, j| if (i, j) == (0, 1) { 1.0 } else { 0.0 });
    let B = Mat::from_fn(2, 1, |i, _| if i == 1 { 1.0 } else { 0.0 });
    ContinuousPlant::new(A, B, vec![0.0, 0.0]).expect("the double integrator is a valid plant")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn double_integrator_zoh_matches_closed_form() {
        let h = 0.1;
        let d = double_integrator().zoh(h).unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15;
        assert!(close(d.A[(0, 0)], 1.0) && close(d.A[(0, 1)], h));
        assert!(close(d.A[(1, 0)], 0.0) && close(d.A[(1, 1)], 1.0));
        assert!(close(d.B[(0, 0)], h * h / 2.0) && close(d.B[(1, 0)], h));
        assert_eq!(d.g, vec![0.0, 0.0]);
        // One step from (1, 2) under u = 3: x = 1 + 2h + 3h²/2, v = 2 + 3h.
        let x = d.step(&[1.0, 2.0], &[3.0]);
        assert!(close(x[0], 1.0 + 0.2 + 0.015) && close(x[1], 2.3));
    }
}
