//! The pieces of δ(0) (Theorem 4.7 as [`crate::certify::certify`] evaluates them) per sample, with their
//! gradients with respect to the nominal state and reference input, and the adjoint sweep that turns
//! them into gradients with respect to the whole reference sequence v (§5.2.1 under the a priori
//! discretisation remark: the loop is already sampled, so the functional derivative is the sensitivity
//! of a discrete recursion).
//!
//! For the loop x̃(κ+1) = Ã x̃(κ) + B v(κ) + g (Ã = A + BK̂) the sensitivity is ∂x̃(κ)/∂v(j) = Ã^{κ−1−j}B
//! for j < κ. A cost J(x̃(0..N), v(0..N−1)) has ∂J/∂v(j) = ∂J/∂v(j)|direct + Bᵀ λ(j+1) with the adjoint
//! λ(N) = ∂J/∂x̃(N), λ(κ) = ∂J/∂x̃(κ) + Ãᵀ λ(κ+1): one backward sweep instead of N forward sensitivities.
//!
//! Signed distances come with their witness point y* (the nearest point of the boundary); by the envelope
//! theorem ∇ₓ ‖x − y*‖_P = P(x − y*)/‖x − y*‖_P, with the sign of the signed distance. These are the
//! gradients at the critical points of (5.27)–(5.28).

use crate::certify::{input_distance, Loop, LoopConstants};
use crate::geometry::{Metric, Region};
use crate::linalg::{mat_vec, p_norm};
use crate::trajectory::generate::InputBound;
use crate::trajectory::Nominal;
use faer::MatRef;

/// Which piece of δ(0) (4.11).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PieceKind {
    /// Depth in Goal at a sample (4.12)–(4.13).
    Goal,
    /// Distance from Unsafe with the inter-sample margin (4.14).
    Unsafe,
    /// Distance to input violation with the rounding margin (4.15).
    Input,
}

/// A piece's gradient at one sample: with respect to x̃(κ) and (when κ < N) v(κ).
#[derive(Clone, Debug)]
pub struct LocalGrad {
    pub k: usize,
    pub gx: Vec<f64>,
    pub gv: Vec<f64>,
}

/// Evaluates pieces of δ on nominal trajectories of one loop.
pub struct Pieces<'a, 'b> {
    pub lp: &'a Loop<'b>,
    pub lc: &'a LoopConstants,
    metric: Metric,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn mat_t_vec(M: MatRef<'_, f64>, y: &[f64]) -> Vec<f64> {
    (0..M.ncols())
        .map(|j| (0..M.nrows()).map(|i| M[(i, j)] * y[i]).sum())
        .collect()
}

impl<'a, 'b> Pieces<'a, 'b> {
    pub fn new(lp: &'a Loop<'b>, lc: &'a LoopConstants) -> Self {
        Self {
            lp,
            lc,
            metric: Metric {
                n: lp.P.nrows(),
                R: crate::linalg::to_row_major(lp.P),
            },
        }
    }

    /// Signed distance (2.8) in the P-metric and its gradient (envelope theorem at the witness).
    fn signed(&self, region: &dyn Region, x: &[f64]) -> (f64, Vec<f64>) {
        let w = region.signed_dist(x, &self.metric);
        let n = x.len();
        if w.point.len() != n {
            return (w.value, vec![0.0; n]);
        }
        let e: Vec<f64> = x.iter().zip(&w.point).map(|(a, b)| a - b).collect();
        let r = p_norm(self.lp.P, &e);
        if !(r > 0.0) {
            return (w.value, vec![0.0; n]);
        }
        let s = if w.value < 0.0 { -1.0 } else { 1.0 };
        let pe = mat_vec(self.lp.P, &e);
        (w.value, pe.iter().map(|v| s * v / r).collect())
    }

    /// Goal depth (signed) at every sample.
    pub fn goal_values(&self, nom: &Nominal) -> Vec<f64> {
        nom.x
            .iter()
            .map(|x| self.lp.goal().signed_dist(x, &self.metric).value)
            .collect()
    }

    /// Goal piece and its gradient at sample k.
    pub fn goal_grad(&self, nom: &Nominal, k: usize) -> (f64, LocalGrad) {
        let (v, gx) = self.signed(self.lp.goal(), &nom.x[k]);
        let m = self.lp.K.nrows();
        (
            v,
            LocalGrad {
                k,
                gx,
                gv: vec![0.0; m],
            },
        )
    }

    /// The inter-sample excursion vector f = A_c x + B_c u + c of (certify doc, item 2) at sample k < N.
    fn excursion(&self, nom: &Nominal, k: usize) -> Option<Vec<f64>> {
        if k >= nom.steps() {
            return None;
        }
        self.lp.plant.vector_field(0, &nom.x[k], &nom.u[k])
    }

    /// Unsafe piece at every sample: (dist − φ‖f‖_P − φβε̄)/γ between samples, dist at the last sample
    /// (+∞ without Unsafe), as in [`crate::certify::certify`].
    pub fn unsafe_values(&self, nom: &Nominal, eps_f32: f64) -> Vec<f64> {
        let Some(us) = self.lp.unsafe_set() else {
            return vec![f64::INFINITY; nom.x.len()];
        };
        (0..nom.x.len())
            .map(|k| {
                let d = -us.signed_dist(&nom.x[k], &self.metric).value;
                match self.excursion(nom, k) {
                    Some(f) => {
                        let rho = self.lc.phi * p_norm(self.lp.P, &f);
                        (d - rho - self.lc.phi * self.lc.beta * eps_f32) / self.lc.gamma
                    }
                    None => d,
                }
            })
            .collect()
    }

    /// Unsafe piece and its gradient at sample k (ε̄ held fixed).
    pub fn unsafe_grad(&self, nom: &Nominal, k: usize, eps_f32: f64) -> (f64, LocalGrad) {
        let (n, m) = (self.lp.P.nrows(), self.lp.K.nrows());
        let Some(us) = self.lp.unsafe_set() else {
            return (
                f64::INFINITY,
                LocalGrad {
                    k,
                    gx: vec![0.0; n],
                    gv: vec![0.0; m],
                },
            );
        };
        let (s, gs) = self.signed(us, &nom.x[k]);
        let d = -s;
        let mut gx: Vec<f64> = gs.iter().map(|v| -v).collect();
        let mut gv = vec![0.0; m];
        let Some(f) = self.excursion(nom, k) else {
            return (d, LocalGrad { k, gx, gv });
        };
        let Some(cp) = self.lp.plant.continuous(0) else {
            return (d, LocalGrad { k, gx, gv });
        };
        let fn_ = p_norm(self.lp.P, &f);
        let rho = self.lc.phi * fn_;
        let val = (d - rho - self.lc.phi * self.lc.beta * eps_f32) / self.lc.gamma;
        if fn_ > 0.0 {
            // ∇_f ‖f‖_P = P f/‖f‖_P; f = A_c x + B_c (K̂x + v).
            let pf: Vec<f64> = mat_vec(self.lp.P, &f).iter().map(|v| v / fn_).collect();
            let bt = mat_t_vec(cp.B.as_ref(), &pf);
            let at = mat_t_vec(cp.A.as_ref(), &pf);
            let kt = mat_t_vec(self.lp.K, &bt);
            for i in 0..n {
                gx[i] -= self.lc.phi * (at[i] + kt[i]);
            }
            for i in 0..m {
                gv[i] -= self.lc.phi * bt[i];
            }
        }
        for g in gx.iter_mut().chain(gv.iter_mut()) {
            *g /= self.lc.gamma;
        }
        (val, LocalGrad { k, gx, gv })
    }

    /// Input piece at every step κ < N (with the componentwise rounding bound `eps`).
    pub fn input_values(&self, nom: &Nominal, eps: &[f64]) -> Vec<f64> {
        (0..nom.steps())
            .map(|k| input_distance(self.lp.K, &self.lc.roots, &nom.u[k], self.lp.input(), eps))
            .collect()
    }

    /// Input piece and its gradient at step k: through ũ = K̂x̃ + v, ∂/∂x = K̂ᵀ∂/∂ũ and ∂/∂v = ∂/∂ũ.
    pub fn input_grad(&self, nom: &Nominal, k: usize, eps: &[f64]) -> (f64, LocalGrad) {
        let K = self.lp.K;
        let (m, n) = (K.nrows(), K.ncols());
        let u = &nom.u[k];
        let val = input_distance(K, &self.lc.roots, u, self.lp.input(), eps);
        let mut gu = vec![0.0; m];
        match self.lp.input() {
            InputBound::Box { lo, hi } => {
                // The active face: the component and side of the smallest scaled slack.
                let mut best = (f64::INFINITY, 0usize, 0.0f64);
                for i in 0..m {
                    let Ki: Vec<f64> = (0..n).map(|j| K[(i, j)]).collect();
                    let s = self.lc.roots.dual_norm(&Ki);
                    let s = if s > 0.0 { s } else { 1.0 };
                    let up = (hi[i] - eps[i] - u[i]) / s;
                    let dn = (u[i] - lo[i] - eps[i]) / s;
                    if up < best.0 {
                        best = (up, i, -1.0 / s);
                    }
                    if dn < best.0 {
                        best = (dn, i, 1.0 / s);
                    }
                }
                gu[best.1] = best.2;
            }
            InputBound::Norm2 { center, .. } => {
                let s = self.lc.roots.norm_from(K);
                let s = if s > 0.0 { s } else { 1.0 };
                let e: Vec<f64> = u.iter().zip(center).map(|(a, c)| a - c).collect();
                let r = dot(&e, &e).sqrt();
                if r > 0.0 {
                    for i in 0..m {
                        gu[i] = -e[i] / (r * s);
                    }
                }
            }
        }
        let gx = mat_t_vec(K, &gu);
        (val, LocalGrad { k, gx, gv: gu })
    }

    /// Adjoint sweep (module doc): gradient with respect to v(0..N) of a cost whose partial derivatives
    /// are the given local gradients (several may share a sample; they add).
    pub fn adjoint(&self, steps: usize, local: &[(f64, &LocalGrad)]) -> Vec<Vec<f64>> {
        let (n, m) = (self.lp.P.nrows(), self.lp.K.nrows());
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
        adjoint_sweep(self.lc.At.as_ref(), self.lc.B.as_ref(), &gx, gv)
    }
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
        let g = pc.adjoint(N, &[(1.0, c)]);
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
