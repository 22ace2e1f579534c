//! Nominal trajectories of the closed loop u = K x + v(κ): the common form every trajectory source
//! produces (CSV import of a recorded run, its references derived by `track` when it gives applied inputs
//! or states, or the automatic generator), and their simulation.

pub mod csv;
pub mod generate;
pub mod hold;
pub mod route;
pub mod track;

use crate::model::DiscretePlant;
use faer::MatRef;

/// A sampled nominal trajectory of the closed loop x(κ+1) = A x + B (K x + v(κ)) + g.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Nominal {
    /// States x̃(0..=N) (N+1 samples).
    pub x: Vec<Vec<f64>>,
    /// Reference inputs ṽ(0..N) (N samples).
    pub v: Vec<Vec<f64>>,
    /// Applied inputs ũ(κ) = K x̃(κ) + ṽ(κ).
    pub u: Vec<Vec<f64>>,
}

impl Nominal {
    /// Number of steps N.
    pub fn steps(&self) -> usize {
        self.v.len()
    }
}

/// Simulate the discrete closed loop x⁺ = A x + B (K x + v(κ)) + g of `model` from x0 with the reference
/// inputs `v`.
pub fn simulate(model: &DiscretePlant, K: MatRef<'_, f64>, x0: &[f64], v: &[Vec<f64>]) -> Nominal {
    let (A, B, g) = (model.A.as_ref(), model.B.as_ref(), &model.g);
    let n = A.nrows();
    let m = B.ncols();
    let mut x = Vec::with_capacity(v.len() + 1);
    let mut u = Vec::with_capacity(v.len());
    x.push(x0.to_vec());
    for vk in v {
        let xk = x.last().expect("x holds x0");
        let uk: Vec<f64> = (0..m)
            .map(|i| (0..n).map(|j| K[(i, j)] * xk[j]).sum::<f64>() + vk[i])
            .collect();
        let xn: Vec<f64> = (0..n)
            .map(|i| {
                (0..n).map(|j| A[(i, j)] * xk[j]).sum::<f64>()
                    + (0..m).map(|j| B[(i, j)] * uk[j]).sum::<f64>()
                    + g[i]
            })
            .collect();
        u.push(uk);
        x.push(xn);
    }
    Nominal {
        x,
        v: v.to_vec(),
        u,
    }
}
