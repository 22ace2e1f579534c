//! Theorem 4.7 per sample for the sampled f32 loop: the pieces of δ(0) (4.11) at every sample, each with
//! its gradient with respect to the nominal state and reference input. This is the one implementation of
//! the reach-avoid robustness's terms: [`super::certify`] takes the critical samples of the values, and
//! the optimiser (§5.2–5.3, [`crate::optimize`]) the gradients at them.
//!
//! * **Goal** (4.12)–(4.13): the signed depth in Goal in the CAF metric.
//! * **Unsafe** (4.14): the distance from Unsafe; between samples (continuous-time plants) reduced by the
//!   inter-sample excursion and the rounding disturbance, (dist − φ‖f‖_P − φβε̄)/γ ([`super`] doc, item 2),
//!   or, where larger, by the drift against each convex piece of Unsafe (below), for every loop: one
//!   location or a hybrid run's segment, and the same bound in the MTL tube ([`super::temporal`]) and the
//!   PWA check ([`crate::pwa`]).
//! * **Input** (4.15): the P-distance to inputs outside the input set shrunk by the rounding bound.
//!
//! Certification takes the extrema of these terms through the shared scans of Theorem 4.7
//! ([`crate::robustness::safety`]); the optimiser takes every sample near the extremum (its subgradient
//! selection (5.29)) and the gradients there.
//!
//! **Between samples along a direction.** The isotropic bound charges the whole excursion φ‖f‖_P against
//! Unsafe, also along a wall the run moves parallel to. Per convex piece j of Unsafe at P-distance d_j from
//! x̃ = x̃(κ), with witness p and the unit (‖n‖_{P⁻¹} = 1) normal n = P(x̃ − p)/‖P(x̃ − p)‖_{P⁻¹}:
//!
//! 1. *The piece lies behind a half-space.* If q is the piece's P-nearest point to x̃ and
//!    n_q = P(x̃ − q)/‖x̃ − q‖_P (‖n_q‖_{P⁻¹} = 1), the projection's optimality in the P inner product
//!    gives n_qᵀ(y − q) ≤ 0 for every y of the piece, so the piece lies in {y : n_qᵀ(y − x̃) ≤ −d_j} and
//!    dist_P(z, piece) ≥ d_j + n_qᵀ(z − x̃) for every z.
//! 2. *A run's motion.* Over τ ∈ [0, h] a run is z(τ) = x̃ + Φ(τ)f + e(τ), with Φ(τ) = ∫₀^τ e^{A_c s} ds, f the
//!    nominal's held vector field and e(τ) its deviation from the nominal's held flow; ‖e(τ)‖_P ≤ w with
//!    w = γr + φβ(ε̄ + D) (+ a flat plant's state step) for runs from the r-ball (the isotropic bound's own
//!    argument: e(τ) = e_κ + Φ(τ)((A_c + B_cK̂)e_κ + B_c·disturbance), ‖Φ(τ)‖_P ≤ φ). Then
//!    −nᵀ(z(τ) − x̃) ≤ drift_n + ‖n‖_{P⁻¹}w, drift_n = [`crate::model::drift_against`] of f (its proof in
//!    `model::intersample`), and ‖z(τ) − x̃‖_P ≤ φ‖f‖_P + w.
//! 3. *A witness that is not exactly the nearest point* (a QP's answer) tilts n: with p′ the point of the
//!    piece nearest p (ε_p from p), Pythagoras for the projection on a convex set gives
//!    ‖q − p′‖_P² ≤ ‖x̃ − p′‖_P² − d_j², so ‖n − n_q‖_{P⁻¹} ≤ c_w = 2(√((g + ε_p)² − d_j²) + ε_p)/min(g, d_j),
//!    g = ‖x̃ − p‖_P, and |(n − n_q)ᵀ(z − x̃)| ≤ c_w‖z − x̃‖_P.
//!
//! Together: dist_P(z(τ), piece) ≥ base_j − slope_j·w for every τ ∈ [0, h], with
//! base_j = d_j − drift_n − c_w φ‖f‖_P and slope_j = max(‖n‖_{P⁻¹}, 1) + c_w ([`PieceClearance`]). The Unsafe
//! piece between samples is the largest r with base_j − slope_j(γr + held) > 0 for every piece, when that
//! beats the isotropic one ([`Pieces::directional_margin`]); the optimiser's gradient there is the binding
//! piece's, with n and c_w held fixed (a subgradient of the value with the normal frozen: it only steers
//! the ascent, the value is what is certified). Every figure is rounded toward the safe side by a
//! relative 10⁻⁹.
//!
//! Signed distances come with their witness point y* (the nearest point of the boundary); by the envelope
//! theorem ∇ₓ ‖x − y*‖_P = P(x − y*)/‖x − y*‖_P, with the sign of the signed distance. These are the
//! gradients at the critical points of (5.27)–(5.28).

use super::{input_distance_scaled, InputScale, Loop, LoopConstants};
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
    /// The input piece's divisor for the loop's gain, computed once ([`InputScale`]).
    input_scale: InputScale,
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
            input_scale: InputScale::new(lp.K, &lc.roots, lp.input()),
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
                let held = self.lc.held_disturbance(eps_f32);
                let isotropic = self.isotropic_margin(d, f_p, held);
                match self.directional_margin(nom, k, held) {
                    Some((m, _)) if m > isotropic => m,
                    _ => isotropic,
                }
            }
            None => d,
        }
    }

    /// Lower bounds on dist_P(z(τ), Unsafe) over the period after sample k < N, for every run z whose
    /// sample lies within r of x̃(k) and whose input carries the rounding ε̄: the isotropic one,
    /// d − (γr + φ‖f‖_P + held) ([`super`] doc, item 2), and the directional one,
    /// min_j (base_j − slope_j(γr + held)) (module doc), where known. `None` at the last sample, without
    /// Unsafe, and for discrete-time plants. The Unsafe piece between samples is the largest r at which
    /// the larger of the two stays positive.
    pub fn unsafe_clearance(
        &self,
        nom: &Nominal,
        k: usize,
        r: f64,
        eps_f32: f64,
    ) -> Option<(f64, Option<f64>)> {
        let us = self.lp.unsafe_set()?;
        let f = self.excursion(nom, k)?;
        self.lp.continuous()?;
        let d = -us.signed_dist(&nom.x[k], &self.metric).value;
        let held = self.lc.held_disturbance(eps_f32);
        let w = self.lc.gamma * r + held;
        let isotropic = d - (w + self.lc.phi * p_norm(self.lp.P, &f));
        let directional = self.clearances(us, nom, k).map(|v| least_clearance(&v, w));
        Some((isotropic, directional))
    }

    /// The isotropic Unsafe margin between samples, (d − φ‖f‖_P − held)/γ ([`super`] doc, item 2), for the
    /// distance d at the sample, ‖f‖_P and the held disturbances' step `held`.
    pub fn isotropic_margin(&self, d: f64, f_p: f64, held: f64) -> f64 {
        (d - self.lc.phi * f_p - held) / self.lc.gamma
    }

    /// The convex pieces of `set` as seen between samples κ and κ+1 of the nominal
    /// ([`piece_clearances`]); `None` at the last sample, for discrete-time plants, when the set is not
    /// known as a union of convex pieces, or when the sample touches one.
    pub fn clearances(
        &self,
        set: &dyn Region,
        nom: &Nominal,
        k: usize,
    ) -> Option<Vec<PieceClearance>> {
        let f = self.excursion(nom, k)?;
        let cp = self.lp.continuous()?;
        piece_clearances(
            set,
            &self.metric,
            self.lp.P,
            &self.lc.roots,
            cp.A.as_ref(),
            self.lc.a_norm,
            self.lp.plant.period(),
            self.lc.phi,
            &nom.x[k],
            &f,
        )
    }

    /// The Unsafe piece between samples κ and κ+1 by the drift against each convex piece of Unsafe, with
    /// the index of the piece that binds (`None` where [`Pieces::clearances`] is). A run from the r-ball
    /// deviates from the nominal's held flow by at most w = γr + held over the period (module doc,
    /// "Between samples along a direction"), so it misses piece j while base_j − slope_j·w > 0:
    ///   r < (base_j − slope_j·held) / (γ·slope_j),
    /// and Unsafe for r below the least of these over its pieces.
    pub fn directional_margin(&self, nom: &Nominal, k: usize, held: f64) -> Option<(f64, usize)> {
        let cl = self.clearances(self.lp.unsafe_set()?, nom, k)?;
        let (j, least) = cl
            .iter()
            .map(|c| (c.base - c.slope * held) / (self.lc.gamma * c.slope))
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |b, (j, m)| if m < b.1 { (j, m) } else { b },
            );
        if least.is_nan() {
            return None;
        }
        // base and slope are rounded toward the safe side already (`piece_clearances`).
        Some((least, j))
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
        let held = self.lc.held_disturbance(eps_f32);
        let isotropic = self.isotropic_margin(d, fn_, held);
        let pf: Vec<f64> = if fn_ > 0.0 {
            mat_vec(self.lp.P, &f).iter().map(|v| v / fn_).collect()
        } else {
            vec![0.0; n]
        };
        // The margin's gradient with respect to f, and the factor it is divided by; then f = A_c x + B_c
        // (K̂x + v) carries it to x and v.
        let (val, gf, scale) = match self.directional_margin(nom, k, held) {
            Some((dm, j)) if dm > isotropic => {
                // The directional margin (module doc, "Between samples along a direction"): the
                // binding piece's base with its normal and tilt held fixed (they only steer).
                let cl = self
                    .clearances(self.lp.unsafe_set().expect("checked above"), nom, k)
                    .expect("the margin was computed from them");
                let c = &cl[j];
                gx = c.dist_grad.clone();
                let gf = c.base_grad_f(
                    self.lp.P,
                    &f,
                    cp.A.as_ref(),
                    self.lc.a_norm,
                    self.lp.plant.period(),
                    self.lc.phi,
                    &pf,
                );
                (dm, gf, self.lc.gamma * c.slope)
            }
            _ => {
                let gf: Vec<f64> = pf.iter().map(|v| -self.lc.phi * v).collect();
                (isotropic, gf, self.lc.gamma)
            }
        };
        let bt = mat_t_vec(cp.B.as_ref(), &gf);
        let at = mat_t_vec(cp.A.as_ref(), &gf);
        let kt = mat_t_vec(self.lp.K, &bt);
        for i in 0..n {
            gx[i] += at[i] + kt[i];
        }
        for i in 0..m {
            gv[i] += bt[i];
        }
        for g in gx.iter_mut().chain(gv.iter_mut()) {
            *g /= scale;
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
        input_distance_scaled(&self.input_scale, &nom.u[k], self.lp.input(), eps)
    }

    /// The CAF metric the pieces are measured in.
    pub fn metric(&self) -> &Metric {
        &self.metric
    }

    /// Input piece and its gradient at step k: through ũ = K̂x̃ + v, ∂/∂x = K̂ᵀ∂/∂ũ and ∂/∂v = ∂/∂ũ.
    pub fn input_grad(&self, nom: &Nominal, k: usize, eps: &[f64]) -> (f64, LocalGrad) {
        let K = self.lp.K;
        let m = K.nrows();
        let u = &nom.u[k];
        let val = input_distance_scaled(&self.input_scale, u, self.lp.input(), eps);
        let mut gu = vec![0.0; m];
        match self.lp.input() {
            InputBound::Box { lo, hi } => {
                // The active face: the component and side of the smallest scaled slack.
                let mut best = (f64::INFINITY, 0usize, 0.0f64);
                for i in 0..m {
                    // The scale was built from this input set (`Pieces::new`): the other arm is
                    // never taken.
                    let s = match &self.input_scale {
                        InputScale::Rows(rows) => rows[i],
                        InputScale::Norm(_) => f64::NAN,
                    };
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
                // Built from this input set, as above.
                let s = match self.input_scale {
                    InputScale::Norm(s) => s,
                    InputScale::Rows(_) => f64::NAN,
                };
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

/// One convex piece of a set as seen between two samples (module doc, "Between samples along a
/// direction"): every point of a run over the period whose deviation from the nominal's held flow stays
/// within w in the P-metric is at least `base − slope·w` from the piece (P-metric).
#[derive(Clone, Debug)]
pub struct PieceClearance {
    /// d_j − drift_n − c_w·φ‖f‖_P.
    pub base: f64,
    /// max(‖n‖_{P⁻¹}, 1) + c_w.
    pub slope: f64,
    /// ∇ₓ d_j at the witness (the P-distance's gradient, envelope theorem).
    pub dist_grad: Vec<f64>,
    /// The unit normal n = P(x̃ − p)/‖P(x̃ − p)‖_{P⁻¹} and ‖n‖_{P⁻¹} as computed.
    normal: Vec<f64>,
    n_dual: f64,
    /// The tilt constant c_w.
    c_w: f64,
}

impl PieceClearance {
    /// ∂base/∂f with the normal and the tilt held fixed: −∇_f drift_n − c_w·φ·P f/‖f‖_P (`pf` = P f/‖f‖_P,
    /// zeros at f = 0). The optimiser's ascent direction only; the value is what is certified.
    #[allow(clippy::too_many_arguments)]
    pub fn base_grad_f(
        &self,
        P: faer::MatRef<'_, f64>,
        f: &[f64],
        a: faer::MatRef<'_, f64>,
        a_p: f64,
        h: f64,
        phi: f64,
        pf: &[f64],
    ) -> Vec<f64> {
        let a_f = mat_vec(a, f);
        let a_rows = crate::linalg::to_row_major(a);
        // The gradient of the remainder's weight ([`remainder_weight`]): of ‖f‖_P, or of ‖A²f‖_P/a²
        // where that is the smaller.
        let f_p = p_norm(P, f);
        let a2f = mat_vec(a, &a_f);
        let a2f_p = p_norm(P, &a2f);
        let gw: Vec<f64> = if a_p > 0.0 && a2f_p / (a_p * a_p) < f_p {
            if a2f_p > 0.0 {
                // ∇ ‖A²f‖_P = (A²)ᵀ P A²f / ‖A²f‖_P.
                let pa = mat_vec(P, &a2f);
                let t = mat_t_vec(a, &mat_t_vec(a, &pa));
                t.iter().map(|v| v / (a2f_p * a_p * a_p)).collect()
            } else {
                vec![0.0; f.len()]
            }
        } else {
            pf.to_vec()
        };
        let gd = crate::model::drift_against_grad(
            &self.normal,
            f,
            &a_f,
            &a_rows,
            h,
            self.n_dual,
            &gw,
            a_p,
        );
        gd.iter()
            .zip(pf)
            .map(|(g, p)| -g - self.c_w * phi * p)
            .collect()
    }
}

/// The least clearance over the convex pieces `pieces` for a run whose deviation from the nominal's
/// held flow is at most `w` (each piece stays at least base − slope·w away; +∞ without pieces).
pub fn least_clearance(pieces: &[PieceClearance], w: f64) -> f64 {
    pieces
        .iter()
        .map(|c| c.base - c.slope * w)
        .fold(f64::INFINITY, f64::min)
}

/// [`least_clearance`] at each sample with its deviation bound from `ws` (paired in order, the shorter
/// one ending it); NaN where the sample's pieces are unknown.
pub fn least_clearances(
    per_k: &[Option<Vec<PieceClearance>>],
    ws: impl IntoIterator<Item = f64>,
) -> Vec<f64> {
    per_k
        .iter()
        .zip(ws)
        .map(|(pk, w)| pk.as_ref().map_or(f64::NAN, |v| least_clearance(v, w)))
        .collect()
}

/// The weight of the third-order remainder in the drift along a direction
/// ([`crate::model::drift_against`]'s `f_p`): ‖f‖_P, or ‖A²f‖_P/a² where smaller (`a_f` = A f, `a_p` = a ≥
/// ‖A‖_P). The remainder is R₃(τ)f = Σ_{i≥0} A^i(A²f) τ^{i+3}/(i+3)!, so ‖R₃(τ)f‖_P ≤ ‖A²f‖_P·χ₃(τ)/a²
/// as well as ‖f‖_P·χ₃(τ) (`model::intersample`'s module doc); χ₃(τ)/a² = τ³ Σ_i (aτ)^i/(i+3)! grows with
/// a, so a rounded up stays an upper bound. For a chain of integrators (A² f = 0 on a double integrator)
/// the remainder vanishes and the drift is exact to second order.
fn remainder_weight(
    P: faer::MatRef<'_, f64>,
    a: faer::MatRef<'_, f64>,
    a_f: &[f64],
    f_p: f64,
    a_p: f64,
) -> f64 {
    if a_p > 0.0 {
        let a2f_p = p_norm(P, &mat_vec(a, a_f));
        f_p.min(a2f_p / (a_p * a_p) * (1.0 + 1e-12))
    } else {
        f_p
    }
}

/// The convex pieces of `set` at the sample x̃ with the held vector field f (module doc, "Between samples
/// along a direction"), in the metric `metric` = ‖·‖_P: each piece's [`PieceClearance`]. `a` is the
/// continuous plant's A, `a_p` = ‖A‖_P, `h` the period and `phi` = φ(h). `None` when the set is not known
/// as a union of convex pieces, a distance is not finite, or x̃ touches a piece.
#[allow(clippy::too_many_arguments)]
pub fn piece_clearances(
    set: &dyn Region,
    metric: &Metric,
    P: faer::MatRef<'_, f64>,
    roots: &crate::linalg::PdRoots,
    a: faer::MatRef<'_, f64>,
    a_p: f64,
    h: f64,
    phi: f64,
    x: &[f64],
    f: &[f64],
) -> Option<Vec<PieceClearance>> {
    let pieces = set.convex_pieces()?;
    let a_f = mat_vec(a, f);
    let f_p = p_norm(P, f);
    let weight = remainder_weight(P, a, &a_f, f_p, a_p);
    let mut out = Vec::with_capacity(pieces.len());
    for piece in pieces {
        let w = piece.try_dist(x, metric).ok()?;
        let dj = w.value;
        if !(dj > 0.0 && dj.is_finite()) || w.point.len() != x.len() {
            return None;
        }
        let e: Vec<f64> = x.iter().zip(&w.point).map(|(a, b)| a - b).collect();
        let g = p_norm(P, &e);
        let pe = mat_vec(P, &e);
        let dn = roots.dual_norm(&pe);
        if !(g > 0.0 && dn > 0.0) {
            return None;
        }
        let normal: Vec<f64> = pe.iter().map(|v| v / dn).collect();
        let eps_p = if piece.contains(&w.point) {
            0.0
        } else {
            piece.try_dist(&w.point, metric).ok()?.value
        };
        if !eps_p.is_finite() {
            return None;
        }
        let tilt = ((g + eps_p).powi(2) - dj * dj).max(0.0).sqrt();
        let c_w = 2.0 * (tilt + eps_p) / g.min(dj) * (1.0 + 1e-9);
        let n_dual = roots.dual_norm(&normal);
        let drift = crate::model::drift_against(&normal, f, &a_f, h, n_dual, weight, a_p);
        let base = dj - drift - c_w * phi * f_p * (1.0 + 1e-9);
        if !base.is_finite() {
            return None;
        }
        out.push(PieceClearance {
            base: base - base.abs() * 1e-9,
            slope: (n_dual.max(1.0) + c_w) * (1.0 + 1e-9),
            dist_grad: pe.iter().map(|v| v / g).collect(),
            normal,
            n_dual,
            c_w,
        });
    }
    Some(out)
}
