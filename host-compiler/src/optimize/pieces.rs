//! The adjoint sweep that turns the per-sample gradients of δ(0)'s pieces ([`crate::certify::pieces`],
//! Theorem 4.7 as certification evaluates it) into gradients with respect to the whole reference
//! sequence v (§5.2.1 under the a priori
//! discretisation remark: the loop is already sampled, so the functional derivative is the sensitivity
//! of a discrete recursion).
//!
//! For the loop x̃(κ+1) = Ã x̃(κ) + B v(κ) + g (Ã = A + BK̂) the sensitivity is ∂x̃(κ)/∂v(j) = Ã^{κ−1−j}B
//! for j < κ. A cost J(x̃(0..N), v(0..N−1)) has ∂J/∂v(j) = ∂J/∂v(j)|direct + Bᵀ λ(j+1) with the adjoint
//! λ(N) = ∂J/∂x̃(N), λ(κ) = ∂J/∂x̃(κ) + Ãᵀ λ(κ+1): one backward sweep instead of N forward sensitivities.

pub use crate::certify::pieces::{LocalGrad, PieceKind, Pieces};

use crate::linalg::mat_t_vec;
use crate::trajectory::Nominal;
use faer::MatRef;

/// Adjoint sweep (module doc): gradient with respect to v(0..N) of a cost whose partial derivatives are
/// the given local gradients (several may share a sample; they add).
pub fn adjoint(pc: &Pieces<'_, '_>, steps: usize, local: &[(f64, &LocalGrad)]) -> Vec<Vec<f64>> {
    let (n, m) = (pc.lp.P.nrows(), pc.lp.K.nrows());
    let mut gx = vec![vec![0.0; n]; steps + 1];
    let mut gv = vec![vec![0.0; m]; steps];
    for (w, lg) in local {
        for (a, b) in gx[lg.k].iter_mut().zip(&lg.gx) {
            *a += w * b;
        }
        if lg.k < steps {
            for (a, b) in gv[lg.k].iter_mut().zip(&lg.gv) {
                *a += w * b;
            }
        }
    }
    adjoint_sweep(pc.lc.At.as_ref(), pc.lc.B.as_ref(), &gx, gv)
}

/// λ(N) = gx(N), λ(κ) = gx(κ) + Ãᵀλ(κ+1); returns gv(κ) + Bᵀλ(κ+1) for κ < N.
pub fn adjoint_sweep(
    At: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    gx: &[Vec<f64>],
    mut gv: Vec<Vec<f64>>,
) -> Vec<Vec<f64>> {
    let steps = gv.len();
    let mut lam = gx[steps].clone();
    for k in (0..steps).rev() {
        let bl = mat_t_vec(B, &lam);
        for (g, b) in gv[k].iter_mut().zip(&bl) {
            *g += b;
        }
        let al = mat_t_vec(At, &lam);
        lam = al.iter().zip(&gx[k]).map(|(a, b)| a + b).collect();
    }
    gv
}

/// The certified value of (4.11) before margins, min(δ_Goal, δ_Unsafe between samples, δ_Input), and a
/// subgradient of it with respect to v chosen by (5.29): of the pieces that attain it (to a relative 1e-12)
/// at their critical samples, the one with the largest gradient norm ((5.30)–(5.31) show it lies in the
/// Clarke subdifferential (5.26)).
pub fn delta_subgradient(
    pc: &Pieces<'_, '_>,
    nom: &Nominal,
    eps: &[f64],
    eps_f32: f64,
) -> (f64, Vec<Vec<f64>>) {
    let N = nom.steps();
    let goal = pc.goal_values(nom);
    let uns = pc.unsafe_values(nom, eps_f32);
    let inp = pc.input_values(nom, eps);
    let dg = goal.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let du = uns.iter().cloned().fold(f64::INFINITY, f64::min);
    let di = inp.iter().cloned().fold(f64::INFINITY, f64::min);
    let d = dg.min(du).min(di);
    let tol = 1e-12 * d.abs().max(1e-3);
    let mut cands: Vec<LocalGrad> = Vec::new();
    if dg <= d + tol {
        for (k, &g) in goal.iter().enumerate() {
            if g >= dg - tol {
                cands.push(pc.goal_grad(nom, k).1);
            }
        }
    }
    if du <= d + tol {
        for (k, &u) in uns.iter().enumerate() {
            if u <= du + tol {
                cands.push(pc.unsafe_grad(nom, k, eps_f32).1);
            }
        }
    }
    if di <= d + tol {
        for (k, &u) in inp.iter().enumerate() {
            if u <= di + tol {
                cands.push(pc.input_grad(nom, k, eps).1);
            }
        }
    }
    let mut best: Option<(f64, Vec<Vec<f64>>)> = None;
    for c in &cands {
        let g = adjoint(pc, N, &[(1.0, c)]);
        let nn: f64 = g.iter().flatten().map(|v| v * v).sum();
        if best.as_ref().is_none_or(|(b, _)| nn > *b) {
            best = Some((nn, g));
        }
    }
    let m = pc.lp.K.nrows();
    (
        d,
        best.map(|b| b.1).unwrap_or_else(|| vec![vec![0.0; m]; N]),
    )
}
