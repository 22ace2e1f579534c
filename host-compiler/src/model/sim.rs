//! Closed-loop simulation of the sampled loop under the feedback law u(κ) = K x(κ) + v(κ) (+ ε(κ)), (3.63)
//! and (3.74), and the reference inputs v of (3.6) that make the loop reproduce a nominal trajectory.

use super::{check_finite, check_len, DiscretePlant, ModelError};
use faer::MatRef;

/// States x(0..=N) and applied inputs u(0..N) of one closed-loop run.
#[derive(Clone, Debug, PartialEq)]
pub struct ClosedLoopRun {
    pub x: Vec<Vec<f64>>,
    pub u: Vec<Vec<f64>>,
}

fn check_K(K: MatRef<'_, f64>, n: usize, m: usize) -> Result<(), ModelError> {
    if K.nrows() != m || K.ncols() != n {
        return Err(ModelError::Dimension {
            what: "K",
            expected: format!("{m}×{n}"),
            got: format!("{}×{}", K.nrows(), K.ncols()),
        });
    }
    check_finite("K", K)
}

/// Run x(κ+1) = A x(κ) + B u(κ) + g with u(κ) = K x(κ) + v(κ) + ε(κ) for κ = 0..v.len(); `eps` (the bounded
/// disturbance of Notation 3.20) is optional and, when given, must have the same length as `v`.
pub fn simulate_closed_loop(
    plant: &DiscretePlant,
    K: MatRef<'_, f64>,
    x0: &[f64],
    v: &[Vec<f64>],
    eps: Option<&[Vec<f64>]>,
) -> Result<ClosedLoopRun, ModelError> {
    let (n, m) = (plant.n(), plant.m());
    check_K(K, n, m)?;
    check_len("x0", x0, n)?;
    if let Some(e) = eps {
        if e.len() != v.len() {
            return Err(ModelError::Dimension {
                what: "eps",
                expected: format!("{} steps", v.len()),
                got: format!("{} steps", e.len()),
            });
        }
    }
    let mut x = vec![x0.to_vec()];
    let mut u = Vec::with_capacity(v.len());
    for (k, vk) in v.iter().enumerate() {
        check_len("v(κ)", vk, m)?;
        let xk = &x[k];
        let mut uk: Vec<f64> = (0..m)
            .map(|i| (0..n).map(|j| K[(i, j)] * xk[j]).sum::<f64>() + vk[i])
            .collect();
        if let Some(e) = eps {
            check_len("eps(κ)", &e[k], m)?;
            uk.iter_mut().zip(&e[k]).for_each(|(a, b)| *a += b);
        }
        let next = plant.step(xk, &uk);
        u.push(uk);
        x.push(next);
    }
    Ok(ClosedLoopRun { x, u })
}

/// v(κ) = ũ(κ) − K x̃(κ), the discrete counterpart of (3.6): with it the closed loop started at x̃(0)
/// reproduces the nominal trajectory (x̃, ũ) exactly, whatever K is.
pub fn reference_inputs(
    K: MatRef<'_, f64>,
    x_nom: &[Vec<f64>],
    u_nom: &[Vec<f64>],
) -> Result<Vec<Vec<f64>>, ModelError> {
    let (m, n) = (K.nrows(), K.ncols());
    check_finite("K", K)?;
    if x_nom.len() < u_nom.len() {
        return Err(ModelError::Dimension {
            what: "x_nom",
            expected: format!("at least {} states", u_nom.len()),
            got: format!("{}", x_nom.len()),
        });
    }
    u_nom
        .iter()
        .zip(x_nom)
        .map(|(u, x)| {
            check_len("u_nom(κ)", u, m)?;
            check_len("x_nom(κ)", x, n)?;
            Ok((0..m)
                .map(|i| u[i] - (0..n).map(|j| K[(i, j)] * x[j]).sum::<f64>())
                .collect())
        })
        .collect()
}
