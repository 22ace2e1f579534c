//! Theorem 4.7 per sample for the sampled f32 loop: the pieces of δ(0) (4.11) at every sample, each with
//! its gradient with respect to the nominal state and reference input. This is the one implementation of
//! the reach-avoid robustness's terms: [`super::certify`] takes the critical samples of the values, and
//! the optimiser (§5.2–5.3, [`crate::optimize`]) the gradients at them.
//!
//! * **Goal** (4.12)–(4.13): the signed depth in Goal in the CAF metric.
//! * **Unsafe** (4.14): the distance from Unsafe; between samples (continuous-time plants) reduced by the
//!   inter-sample excursion and the rounding disturbance, (dist − φ‖f‖_P − φβε̄)/γ ([`super`] doc, item 2).
//! * **Input** (4.15): the P-distance to inputs outside the input set shrunk by the rounding bound.
//!
//! Certification takes the extrema of these terms through the shared scans of Theorem 4.7
//! ([`crate::robustness::safety`]); the optimiser takes every sample near the extremum (its subgradient
//! selection (5.29)) and the gradients there.
//!
//! Signed distances come with their witness point y* (the nearest point of the boundary); by the envelope
//! theorem ∇ₓ ‖x − y*‖_P = P(x − y*)/‖x − y*‖_P, with the sign of the signed distance. These are the
//! gradients at the critical points of (5.27)–(5.28).

use super::{input_distance, Loop, LoopConstants};
use crate::geometry::{Metric, Region};
use crate::linalg::{mat_t_vec, mat_vec, p_norm};
use crate::property::InputBound;
use crate::trajectory::Nominal;

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
    pub fn signed(&self, region: &dyn Region, x: &[f64]) -> (f64, Vec<f64>) {
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
        self.lp
            .plant
            .vector_field(self.lp.loc, &nom.x[k], &nom.u[k])
    }

    /// The distance from Unsafe (−signed distance) at every sample (+∞ without Unsafe).
    pub fn unsafe_distances(&self, nom: &Nominal) -> Vec<f64> {
        let Some(us) = self.lp.unsafe_set() else {
            return vec![f64::INFINITY; nom.x.len()];
        };
        nom.x
            .iter()
            .map(|x| -us.signed_dist(x, &self.metric).value)
            .collect()
    }

    /// Unsafe piece at every sample from its distances `d` ([`Pieces::unsafe_distances`]):
    /// (d − φ‖f‖_P − φβε̄)/γ between samples, d at the last sample and for discrete-time plants.
    pub fn unsafe_between_samples(&self, nom: &Nominal, d: &[f64], eps_f32: f64) -> Vec<f64> {
        if self.lp.unsafe_set().is_none() {
            return d.to_vec();
        }
        d.iter()
            .enumerate()
            .map(|(k, &d)| self.unsafe_margin(nom, k, d, eps_f32))
            .collect()
    }

    /// The Unsafe piece at sample k from its distance d at the sample: (d − φ‖f‖_P − φβ(ε̄ + D))/γ between
    /// samples, or the directional margin ([`Pieces::directional_margin`]) where it is larger; d at the
    /// last sample and for discrete-time plants.
    pub fn unsafe_margin(&self, nom: &Nominal, k: usize, d: f64, eps_f32: f64) -> f64 {
        match self.excursion(nom, k) {
            Some(f) => {
                let f_p = p_norm(self.lp.P, &f);
                let rho = self.lc.phi * f_p;
                let held = self.lc.held_disturbance(eps_f32);
                let isotropic = (d - rho - held) / self.lc.gamma;
                match self.directional_margin(nom, k, &f, f_p, held) {
                    Some(m) if m > isotropic => m,
                    _ => isotropic,
                }
            }
            None => d,
        }
    }

    /// The Unsafe piece between samples κ and κ+1 by the drift against each convex piece of Unsafe
    /// (`None` when the constants leave it off ([`super::LoopConstants::directional_unsafe`]), Unsafe is
    /// not known as a union of convex pieces, or the sample touches one).
    ///
    /// For a piece at P-distance d_j from x̃(κ), with witness p and the unit (‖n‖_{P⁻¹} = 1) normal
    /// n = P(x̃ − p)/‖·‖, the piece lies in {z : nᵀ(z − x̃) ≤ −d_j} when p is its nearest point. A run
    /// from the r-ball moves against n by at most γr + (held disturbances) + drift_n within the period
    /// (drift_n: [`crate::model::drift_against`] of the nominal's f; the deviation and the disturbances
    /// are bounded in norm as in the isotropic margin). A witness that is not exactly the nearest point q
    /// tilts n: with p′ the point of the piece nearest p (ε_p from p), Pythagoras for the projection on a
    /// convex set gives ‖q − p′‖_P² ≤ ‖x̃ − p′‖_P² − d_j², so ‖n − n_q‖_{P⁻¹} ≤ c_w =
    /// 2(√((g + ε_p)² − d_j²) + ε_p)/min(g, d_j), g = ‖x̃ − p‖_P, and that tilt costs at most c_w times the
    /// run's whole excursion ‖z − x̃‖_P ≤ γr + φ‖f‖_P + held. The piece is then missed for
    ///   r < (d_j − drift_n − held − c_w(φ‖f‖_P + held)) / (γ(1 + c_w)),
    /// and Unsafe for r below the least of these over its pieces.
    fn directional_margin(
        &self,
        nom: &Nominal,
        k: usize,
        f: &[f64],
        f_p: f64,
        held: f64,
    ) -> Option<f64> {
        if !self.lc.directional_unsafe {
            return None;
        }
        let pieces = self.lp.unsafe_set()?.convex_pieces()?;
        let cp = self.lp.continuous()?;
        let x = &nom.x[k];
        let a_f = mat_vec(cp.A.as_ref(), f);
        let a_p = self.lc.roots.induced_norm(cp.A.as_ref());
        let h = self.lp.plant.period();
        let mut least = f64::INFINITY;
        for piece in pieces {
            let w = piece.try_dist(x, &self.metric).ok()?;
            let dj = w.value;
            if !(dj > 0.0 && dj.is_finite()) || w.point.len() != x.len() {
                return None;
            }
            let e: Vec<f64> = x.iter().zip(&w.point).map(|(a, b)| a - b).collect();
            let g = p_norm(self.lp.P, &e);
            let pe = mat_vec(self.lp.P, &e);
            let dn = self.lc.roots.dual_norm(&pe);
            if !(g > 0.0 && dn > 0.0) {
                return None;
            }
            let n: Vec<f64> = pe.iter().map(|v| v / dn).collect();
            let eps_p = if piece.contains(&w.point) {
                0.0
            } else {
                piece.try_dist(&w.point, &self.metric).ok()?.value
            };
            if !eps_p.is_finite() {
                return None;
            }
            let tilt = ((g + eps_p).powi(2) - dj * dj).max(0.0).sqrt();
            let c_w = 2.0 * (tilt + eps_p) / g.min(dj) * (1.0 + 1e-9);
            let n_dual = self.lc.roots.dual_norm(&n);
            let drift = crate::model::drift_against(&n, f, &a_f, h, n_dual, f_p, a_p);
            let m = (dj - drift - held - c_w * (self.lc.phi * f_p + held))
                / (self.lc.gamma * (1.0 + c_w) * n_dual.max(1.0));
            least = least.min(m);
        }
        Some(least - least.abs() * 1e-9)
    }

    /// Unsafe piece at every sample (+∞ without Unsafe).
    pub fn unsafe_values(&self, nom: &Nominal, eps_f32: f64) -> Vec<f64> {
        self.unsafe_between_samples(nom, &self.unsafe_distances(nom), eps_f32)
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
        let Some(cp) = self.lp.continuous() else {
            return (d, LocalGrad { k, gx, gv });
        };
        let fn_ = p_norm(self.lp.P, &f);
        let val = self.unsafe_margin(nom, k, d, eps_f32);
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
            .map(|k| self.input_value(nom, k, eps))
            .collect()
    }

    /// Input piece at step k < N.
    pub fn input_value(&self, nom: &Nominal, k: usize, eps: &[f64]) -> f64 {
        input_distance(self.lp.K, &self.lc.roots, &nom.u[k], self.lp.input(), eps)
    }

    /// The CAF metric the pieces are measured in.
    pub fn metric(&self) -> &Metric {
        &self.metric
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
}
