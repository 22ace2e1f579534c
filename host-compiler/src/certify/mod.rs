//! Certification of what actually runs (DESIGN §5): the certified radius of a nominal trajectory for the
//! sampled loop evaluated in f32 with the exact tables shipped.
//!
//! For one nominal trajectory x̃ of the loop x⁺ = A x + B (K̂ x + v̂(κ)) + g (K̂, v̂ the f32 values shipped):
//!
//! 1. **Theorem 4.7 at the samples.** δ_Goal = max_κ depth_P(x̃(κ), Goal) at κ* (4.12–4.13);
//!    δ_Unsafe = min_κ dist_P(x̃(κ), Unsafe) (4.14); δ_Input = min_κ dist_P(x̃(κ), {x : K̂x + v̂(κ) ∉ Input'})
//!    (4.15), with Input' the input set shrunk by the f32 rounding bound (so the input the firmware applies,
//!    not only the ideal one, is in Input). Unsafe and Input are checked over the whole table (κ = 0..N),
//!    which is stronger than the [0, t*] of the theorem.
//! 2. **Between samples** (continuous-time plants under zero-order hold). With u held, d(s) = x(κh+s) − x(κh)
//!    solves ḋ = A_c d + f with f = A_c x(κh) + B_c u(κ) + c, so d(s) = ∫₀ˢ e^{A_c τ}dτ f. The logarithmic
//!    norm μ = λ_max(sym(P^{1/2}A_cP^{-1/2})) bounds ‖e^{A_c τ}‖_P ≤ e^{μτ}, hence with
//!    φ(h) = (e^{μh} − 1)/μ (h when μ = 0): ‖x(κh+s) − x(κh)‖_P ≤ φ(h)‖f‖_P for all s ∈ [0, h] (the
//!    Euclidean version of this bound is `model::InterSampleBound`; here it is taken in the CAF metric). With x(κh) = x̃(κ) + e, ‖e‖_P ≤ r, and
//!    u = ũ + K̂e + ε this is at most γr + ρ_κ + φ(h)β ε̄ after the sample, where γ = 1 + φ(h)‖A_c + B_cK̂‖_P,
//!    ρ_κ = φ(h)‖A_c x̃(κ) + B_c ũ(κ) + c‖_P and β = ‖P^{1/2}B_c‖₂. So the tube clears Unsafe between
//!    samples when r < (dist_P(x̃(κ), Unsafe) − ρ_κ − φβε̄)/γ.
//! 3. **f32 arithmetic as a bounded input disturbance** (Theorem 3.21). The evaluator computes
//!    u_i = (Σ_j K̂_ij x̂_j) + v̂_i in f32 by recursive summation, with x̂ = fl32(x). Its error against
//!    K̂x + v̂ is at most u|K̂||x| + γ_{n+1}(|K̂||x̂| + |v̂|) componentwise (u = 2⁻²⁴, γ_k = ku/(1−ku);
//!    Higham, *Accuracy and Stability of Numerical Algorithms*, §3.1), evaluated with the largest |x_j| in
//!    the tube. ε̄ is the largest 2-norm of that bound. r_crit (3.83–3.87) must stay below the radius.
//! 4. **Ball selection in f32.** The firmware accepts x when fl32((x̂−c)ᵀP̂(x̂−c)) ≤ fl32(δ̂²); the stored δ̂
//!    is shrunk so that every accepted x lies in the certified ball (bound derived in [`selection_radius`]).
//! 5. **PWA balls in f32.** The PWA evaluator's whitened ball test (`shared_types::pwa`) gets its own
//!    per-ball stored squared threshold, [`pwa_ball_threshold`] (from the radius [`pwa_ball_radius`], in
//!    [`pwa_ball`]).

pub mod ceiling;
pub mod forced;
pub mod internal;
pub mod pieces;
pub mod pwa_ball;
pub mod temporal;
pub mod terminal;

pub use ceiling::Ceiling;
pub use forced::{certify_forced, ForcedCertificate, ForcedError, ForcedSegment};
pub use pieces::Pieces;
pub use pwa_ball::{
    cholesky_upper, metric_factor_f32, pwa_accept_radius, pwa_ball_complete_radius,
    pwa_ball_radius, pwa_ball_threshold, pwa_complete_radius, threshold_of_radius, whitened_centre,
};

use crate::caf::Design;
use crate::geometry::{Metric, Region, Witness};
use crate::linalg::{sym_eigenvalues, PdRoots};
use crate::model::{ContinuousPlant, DiscretePlant, Location, Plant};
use crate::property::{InputBound, ReachAvoid};
use crate::robustness::safety::{self, InputSets, SafetySet, SampledTrajectory};
use crate::spec::Problem;
use crate::task::Task;
use crate::trajectory::Nominal;
use faer::{Mat, MatRef};

/// Unit roundoff of f32 (round to nearest).
pub const U32: f64 = 5.960_464_477_539_063e-8; // 2^-24
/// Smallest positive normal f32: below it rounding is absolute (at most half the subnormal spacing).
const F32_ABS: f64 = 1.0e-45;

/// γ_k = k u / (1 − k u).
pub(crate) fn gamma_k(k: usize) -> f64 {
    let ku = k as f64 * U32;
    ku / (1.0 - ku)
}

/// How far the PWA evaluator's routing value `fl(aᵀx̂) − b` can lie from `aᵀc − b` for an f32 state x̂ in
/// `B_P(c, r)` (`a`, `b` the f32 values a tree node stores): `‖a‖_{P⁻¹} r` for the ball, plus the rounding
/// of the n-term dot product, `γ_n Σ_j |a_j||x̂_j|` (Higham §3.1), with `|x̂_j| ≤ |c_j| + r·axis_j`,
/// `axis_j = sqrt((P⁻¹)_jj)`. A ball can be routed left only if `aᵀc − b ≤` this, right only if `≥ −`it.
/// The partitioner lists balls and the verifier re-checks containment with this one bound.
pub fn hyperplane_reach(roots: &PdRoots, axis: &[f64], a: &[f64], c: &[f64], r: f64) -> f64 {
    let n = a.len();
    let round: f64 = gamma_k(n)
        * (0..n)
            .map(|j| a[j].abs() * (c[j].abs() + r * axis[j]))
            .sum::<f64>();
    roots.dual_norm(a) * r + round
}

/// The loop being certified: one location of the task's plant under the shipped gain K̂ and the CAF metric
/// P, with the sets its nominal is judged against. For a plant with one location and a reach-avoid task
/// the sets are the task's; a segment of a hybrid run (§4.2) has its own target (the safe transition
/// into the next segment) and the task's Unsafe and input set.
#[derive(Clone, Copy)]
pub struct Loop<'a> {
    pub plant: &'a dyn Plant,
    /// The location whose error dynamics the loop runs in.
    pub loc: Location,
    /// The gain as shipped (f32 values widened exactly to f64).
    pub K: MatRef<'a, f64>,
    /// The CAF metric.
    pub P: MatRef<'a, f64>,
    /// Where the nominal must be at its critical sample (Goal, or the segment's safe transition).
    pub goal: &'a dyn Region,
    pub unsafe_set: Option<&'a dyn Region>,
    pub input: &'a InputBound,
}

impl<'a> Loop<'a> {
    /// The loop of a task with its designed CAF.
    pub fn new(task: &'a Task, design: &'a Design) -> Self {
        Self::reach_avoid(&*task.plant, 0, design, &task.property)
    }
    /// The loop of location `loc` of `plant` with a designed CAF and a reach-avoid property's sets.
    pub fn reach_avoid(
        plant: &'a dyn Plant,
        loc: Location,
        design: &'a Design,
        property: &'a ReachAvoid,
    ) -> Self {
        Self {
            plant,
            loc,
            K: design.K.as_ref(),
            P: design.P.as_ref(),
            goal: property.goal.as_ref(),
            unsafe_set: property.unsafe_region(),
            input: &property.input,
        }
    }
    /// The sampled model x⁺ = A x + B u + g the CAF lives in.
    pub fn model(&self) -> &'a DiscretePlant {
        self.plant.error_dynamics(self.loc)
    }
    /// The continuous model of the loop's location, if the plant is in continuous time.
    pub fn continuous(&self) -> Option<&'a ContinuousPlant> {
        self.plant.continuous(self.loc)
    }
    pub fn A(&self) -> MatRef<'a, f64> {
        self.model().A.as_ref()
    }
    pub fn B(&self) -> MatRef<'a, f64> {
        self.model().B.as_ref()
    }
    pub fn goal(&self) -> &'a dyn Region {
        self.goal
    }
    pub fn unsafe_set(&self) -> Option<&'a dyn Region> {
        self.unsafe_set
    }
    pub fn input(&self) -> &'a InputBound {
        self.input
    }
    /// The nominal of this loop from `x0` under the reference sequence `v`.
    pub fn simulate(&self, x0: &[f64], v: &[Vec<f64>]) -> Nominal {
        crate::trajectory::simulate(self.model(), self.K, x0, v)
    }
}

/// A task with its designed CAF: everything a [`Loop`] borrows, owned (for the optimiser's tests, benches
/// and callers outside the synthesis pipeline).
pub struct OwnedLoop {
    pub task: Task,
    pub design: Design,
}

/// Why a loop could not be built from a spec.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    #[error(transparent)]
    Task(#[from] crate::task::TaskError),
    #[error("no CAF and feedback: {0}")]
    Caf(#[from] crate::caf::DesignError),
    #[error(transparent)]
    Certify(#[from] CertifyError),
}

impl OwnedLoop {
    /// The task of a validated spec and its CAF, as `synth` builds them.
    pub fn from_problem(problem: &Problem) -> Result<Self, SetupError> {
        let task = Task::new(problem.clone())?;
        let design = crate::caf::design(&task)?;
        Ok(Self { task, design })
    }
    /// The borrowed view the certifier and the optimiser take.
    pub fn lp(&self) -> Loop<'_> {
        Loop::new(&self.task, &self.design)
    }
    /// Its trajectory-independent constants.
    pub fn constants(&self) -> Result<LoopConstants, SetupError> {
        Ok(LoopConstants::new(&self.lp())?)
    }
}

/// Constants of a loop that do not depend on the trajectory.
#[derive(Clone, Debug)]
pub struct LoopConstants {
    pub roots: PdRoots,
    /// σ_min(P − ÃᵀPÃ) for Ã = A + B K̂ (Theorem 3.21 needs it > 0).
    pub sigma_min: f64,
    /// Ã = A + B K̂ and B, for r_crit.
    pub At: Mat<f64>,
    pub B: Mat<f64>,
    pub P: Mat<f64>,
    /// Inter-sample constants: φ(h), γ, β (1, 0, 0 for discrete-time plants).
    pub phi: f64,
    pub gamma: f64,
    pub beta: f64,
    /// sqrt((P⁻¹)_jj): the largest |e_j| over ‖e‖_P ≤ 1.
    pub axis: Vec<f64>,
    /// The plant's sampled-loop mismatch D ([`Plant::model_mismatch`]): an input-channel disturbance
    /// that varies within the period, 0 for linear affine plants. Each step it moves the state by at most
    /// φβD in the P-metric (the inter-sample bound's own argument), which r_crit and the inter-sample
    /// margin take with the rounding ([`LoopConstants::held_disturbance`]).
    pub mismatch: f64,
    /// A differentially flat plant's disturbances outside the w channel (`model::flat`, items 3–4): how
    /// far they move the state per period in the P-metric, φ Σ_j b_j √P_jj + Σ_j J_j √P_jj (a
    /// disturbance d_j e_j has P-norm |d_j|√P_jj); 0 for every other plant.
    pub state_step: f64,
    /// ‖A_c‖_P, the P-induced norm of the continuous plant's A (0 for discrete-time plants): the
    /// third-order term of the drift along a direction ([`crate::model::drift_against`]) that the Unsafe
    /// margin between samples takes against each convex piece of Unsafe ([`Pieces::unsafe_margin`], for
    /// every loop).
    pub a_norm: f64,
    /// A set every run must stay in, at the samples and between them, from the first sample at which the
    /// whole tube lies in it until the critical sample κ*: the task's Goal, where the loop's own goal is a
    /// terminal law's handover region inside it (`certify::terminal`'s module doc, issue 42 item 4);
    /// `None` otherwise ([`LoopConstants::with_stay_in`]).
    pub stay_in: Option<StayIn>,
    /// ‖Ã^j‖_P ([`LoopConstants::power_norms`]), computed once when first asked.
    power_norms: std::sync::OnceLock<Vec<f64>>,
}

/// The set of [`LoopConstants::stay_in`], shared by every clone of the constants.
#[derive(Clone)]
pub struct StayIn(pub std::sync::Arc<dyn Region>);

impl std::fmt::Debug for StayIn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "StayIn(a region in dimension {})", self.0.dim())
    }
}

/// Why a loop cannot be certified at all.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum CertifyError {
    #[error("the CAF matrix P is not positive definite")]
    MetricNotPd,
    #[error("with the shipped (f32) gain, P − ÃᵀPÃ is not positive definite (σ_min = {0:.3e}): no robustness to rounding (Theorem 3.21)")]
    NotContracting(f64),
}

/// The inter-sample constants in the CAF metric for a plant held over one period h: φ = (e^{μh} − 1)/μ
/// (= h as μh → 0) with μ the logarithmic norm of A_c in the P-metric, so that ‖x(κh+τ) − x_κ‖_P ≤ φ‖f_κ‖_P
/// for τ ∈ [0, h] (the P-metric version of `model::InterSampleBound`), and β = ‖B_c‖ into the P-metric.
pub fn intersample_phi_beta(roots: &PdRoots, cp: &ContinuousPlant, h: f64) -> (f64, f64) {
    let As = &roots.sqrt * &cp.A * &roots.inv_sqrt;
    let mu = sym_eigenvalues(As.as_ref())
        .and_then(|e| e.last().copied())
        .unwrap_or(f64::INFINITY);
    let phi = if (mu * h).abs() < 1e-12 {
        h
    } else {
        (mu * h).exp_m1() / mu
    };
    (phi, roots.norm_into(cp.B.as_ref()))
}

impl LoopConstants {
    pub fn new(lp: &Loop<'_>) -> Result<Self, CertifyError> {
        let roots = PdRoots::new(lp.P).ok_or(CertifyError::MetricNotPd)?;
        let At = lp.A() + lp.B() * lp.K;
        let M = lp.P - At.transpose() * lp.P * &At;
        let sigma_min = sym_eigenvalues(M.as_ref())
            .and_then(|e| e.first().copied())
            .unwrap_or(f64::NAN);
        if !(sigma_min > 0.0) {
            return Err(CertifyError::NotContracting(sigma_min));
        }
        let (phi, gamma, beta) = match lp.continuous() {
            None => (0.0, 1.0, 0.0),
            Some(cp) => {
                let (phi, beta) = intersample_phi_beta(&roots, cp, lp.plant.period());
                let Acl = &cp.A + &cp.B * lp.K;
                (phi, 1.0 + phi * roots.induced_norm(Acl.as_ref()), beta)
            }
        };
        let a_norm = lp
            .continuous()
            .map_or(0.0, |cp| roots.induced_norm(cp.A.as_ref()) * (1.0 + 1e-9));
        let n = lp.P.nrows();
        let axis = (0..n).map(|j| roots.inv[(j, j)].max(0.0).sqrt()).collect();
        let mismatch = lp.plant.model_mismatch();
        let state_step = match lp.plant.linearization().and_then(|m| m.flat.as_ref()) {
            None => 0.0,
            Some(fc) => {
                let sq = |j: usize| lp.P[(j, j)].max(0.0).sqrt();
                let rate: f64 = fc
                    .state_rate
                    .iter()
                    .enumerate()
                    .map(|(j, b)| b * sq(j))
                    .sum();
                let jump: f64 = fc.jump.iter().enumerate().map(|(j, b)| b * sq(j)).sum();
                (phi * rate + jump) * (1.0 + 1e-9)
            }
        };
        Ok(Self {
            roots,
            sigma_min,
            At,
            B: lp.B().to_owned(),
            P: lp.P.to_owned(),
            phi,
            gamma,
            beta,
            axis,
            mismatch,
            state_step,
            a_norm,
            stay_in: None,
            power_norms: std::sync::OnceLock::new(),
        })
    }

    /// These constants with a set the runs must stay in from the first sample at which the whole tube
    /// lies in it until κ* ([`LoopConstants::stay_in`]).
    pub fn with_stay_in(self, region: std::sync::Arc<dyn Region>) -> Self {
        Self {
            stay_in: Some(StayIn(region)),
            ..self
        }
    }

    /// ‖Ã^j‖_P for j < k (the P-induced norms of the closed loop's powers, each rounded up by a relative
    /// 10⁻⁹), computed once for the first k asked.
    pub fn power_norms(&self, k: usize) -> Vec<f64> {
        let norms = |k: usize| {
            let At = &self.roots.sqrt * &self.At * &self.roots.inv_sqrt;
            let n = At.nrows();
            let mut pw = Mat::<f64>::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 });
            let mut out = Vec::with_capacity(k);
            for _ in 0..k {
                out.push(crate::linalg::spectral_norm(pw.as_ref()) * (1.0 + 1e-9));
                pw = &At * &pw;
            }
            out
        };
        let pre = self.power_norms.get_or_init(|| norms(k));
        if pre.len() >= k {
            pre[..k].to_vec()
        } else {
            norms(k)
        }
    }

    /// S_k = Σ_{j<k} ‖Ã^j‖_P ([`LoopConstants::power_norms`]): a disturbance of P-norm ≤ z every step
    /// moves a run at most S_k·z from where the undisturbed loop would take it within k steps, by the
    /// variation-of-constants sum.
    pub fn accumulation(&self, k: usize) -> f64 {
        self.power_norms(k).iter().sum()
    }

    /// How far the held input's disturbances move the state within one period, in the P-metric: φβ(ε̄ + D)
    /// for the evaluator's rounding ε̄ and the plant's mismatch D (0 for discrete-time plants).
    pub fn held_disturbance(&self, eps_f32: f64) -> f64 {
        self.phi * self.beta * (eps_f32 + self.mismatch) + self.state_step
    }

    /// How far the plant's mismatch moves the state per period in the P-metric: φβD, plus a flat plant's
    /// state-channel disturbances ([`LoopConstants::state_step`]).
    pub fn mismatch_step(&self) -> f64 {
        self.phi * self.beta * self.mismatch + self.state_step
    }

    /// r_crit of Theorem 3.21, (3.83)–(3.87), for a disturbance bound ε̄ (2-norm per step) entering through B
    /// and the plant's mismatch φβD on the state ([`crate::caf::r_crit_mixed`], with its validated,
    /// rounding-guarded norms); ∞ when it does not exist.
    pub fn r_crit(&self, eps: f64) -> f64 {
        let z = self.mismatch_step();
        crate::caf::r_crit_mixed(self.At.as_ref(), self.P.as_ref(), self.B.as_ref(), eps, z)
            .map(|r| r.r_crit)
            .unwrap_or(f64::INFINITY)
    }
}

/// The certificate of one trajectory.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Certificate {
    /// Theorem 4.7 at the samples, before margins.
    pub delta_goal: f64,
    pub k_star: usize,
    pub delta_unsafe: f64,
    pub k_unsafe: usize,
    pub delta_input: f64,
    pub k_input: usize,
    /// Unsafe after the inter-sample bound.
    pub delta_unsafe_intersample: f64,
    /// Componentwise f32 rounding bound (max over the table) and its 2-norm ε̄.
    pub eps_components: Vec<f64>,
    pub eps_f32: f64,
    pub r_crit: f64,
    /// The certified radius of the ball of initial states (0 if none).
    pub delta: f64,
    /// The radius to store in the image (f32, rounded down), accounting for selection in f32.
    pub delta_stored: f32,
    /// When the plant has a sampled-loop mismatch: how far the disturbances (rounding and mismatch) can
    /// move a run from the undisturbed tube over the table, S_N·(‖P^{1/2}B‖ε̄ + φβD); δ may then be the
    /// parts' minimum less this (the tube of radius δ + it then satisfies every part), where that beats
    /// r_crit. 0 otherwise.
    #[serde(skip_serializing_if = "is_zero")]
    pub accumulated: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Certificate {
    pub fn is_certified(&self) -> bool {
        self.delta > 0.0 && self.delta_stored > 0.0
    }

    /// min(δ_Goal, δ_Unsafe between samples, δ_Input): the radius Theorem 4.7 allows before r_crit;
    /// NaN when a part could not be computed.
    pub fn parts_min(&self) -> f64 {
        let p = [
            self.delta_goal,
            self.delta_unsafe_intersample,
            self.delta_input,
        ];
        if p.iter().any(|v| v.is_nan()) {
            return f64::NAN;
        }
        p.into_iter().fold(f64::INFINITY, f64::min)
    }

    /// The part that limits δ: the smallest of δ_Goal, δ_Unsafe (between samples) and δ_Input, or
    /// r_crit when those are positive but r_crit is not below their minimum (ties: Goal, Unsafe, Input).
    pub fn binding(&self) -> Binding {
        let d = self.parts_min();
        if d.is_nan() {
            return Binding::NotComputed;
        }
        // With a sampled-loop mismatch, δ = d − `accumulated` stands in for r_crit when it is positive.
        let by_sum = self.accumulated > 0.0 && d > self.accumulated;
        if d > 0.0 && (self.r_crit >= d || self.r_crit.is_nan()) && !by_sum {
            return Binding::RCrit {
                r_crit: self.r_crit,
                parts_min: d,
                accumulated: self.accumulated,
            };
        }
        if self.delta_goal == d {
            Binding::Goal(d)
        } else if self.delta_unsafe_intersample == d {
            Binding::Unsafe(d)
        } else {
            Binding::Input(d)
        }
    }
}

/// The part of a [`Certificate`] that limits its δ ([`Certificate::binding`]), with its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Binding {
    /// δ_Goal (4.13): the ball reaches Goal within the table (T) only if it is > 0.
    Goal(f64),
    /// δ_Unsafe (4.14) after the inter-sample and rounding margins.
    Unsafe(f64),
    /// δ_Input (4.15) with the rounding margin.
    Input(f64),
    /// The three parts are positive, but the critical radius r_crit (3.83) is not below their minimum,
    /// nor (with a sampled-loop mismatch) is the disturbance accumulated over the table
    /// ([`Certificate::accumulated`], 0 without one).
    RCrit {
        r_crit: f64,
        parts_min: f64,
        accumulated: f64,
    },
    /// A part could not be computed (a non-finite distance on the nominal).
    NotComputed,
}

impl std::fmt::Display for Binding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Binding::Goal(v) => write!(f, "δ_Goal = {v:.3e}"),
            Binding::Unsafe(v) => write!(f, "δ_Unsafe = {v:.3e} (between samples)"),
            Binding::Input(v) => write!(f, "δ_Input = {v:.3e}"),
            Binding::RCrit {
                r_crit,
                parts_min,
                accumulated,
            } if *accumulated > 0.0 => write!(
                f,
                "min(δ_Goal, δ_Unsafe, δ_Input) = {parts_min:.3e} is not above the disturbance the \
                 sampled loop accumulates over the table, {accumulated:.3e}, nor above r_crit = \
                 {r_crit:.3e}"
            ),
            Binding::RCrit {
                r_crit, parts_min, ..
            } => write!(
                f,
                "r_crit = {r_crit:.3e}, not below min(δ_Goal, δ_Unsafe, δ_Input) = {parts_min:.3e}"
            ),
            Binding::NotComputed => write!(f, "a δ part that could not be computed (non-finite)"),
        }
    }
}

/// Largest absolute state components over the tube of radius r around x̃(κ).
pub(crate) fn tube_abs(x: &[f64], r: f64, axis: &[f64]) -> Vec<f64> {
    x.iter()
        .zip(axis)
        .map(|(&xi, &a)| xi.abs() + r * a)
        .collect()
}

/// Componentwise bound on the f32 evaluator's error for states with |x_j| ≤ X_j (module doc, item 3).
pub fn evaluator_error_bound(K: MatRef<'_, f64>, v: &[f64], X: &[f64]) -> Vec<f64> {
    let (m, n) = (K.nrows(), K.ncols());
    let g = gamma_k(n + 1);
    (0..m)
        .map(|i| {
            let kx: f64 = (0..n).map(|j| K[(i, j)].abs() * X[j]).sum();
            let quant: f64 = (0..n)
                .map(|j| K[(i, j)].abs() * (U32 * X[j] + F32_ABS))
                .sum();
            quant + g * (kx * (1.0 + U32) + v[i].abs()) + F32_ABS
        })
        .collect()
}

/// Distance in the P-metric from x̃ to {x : K x + v ∉ Input'} — exact for a box (the nearest violated face),
/// and the lower bound (ρ − ‖ũ‖)/‖K P^{-1/2}‖₂ for a 2-norm ball. `eps` is the componentwise rounding
/// bound by which Input is shrunk. Negative when ũ itself violates Input'.
pub fn input_distance(
    K: MatRef<'_, f64>,
    roots: &PdRoots,
    u: &[f64],
    input: &InputBound,
    eps: &[f64],
) -> f64 {
    input_distance_scaled(&InputScale::new(K, roots, input), u, input, eps)
}

/// What [`input_distance`] divides the input slack by, for one gain K in one CAF metric: per row of K its
/// dual norm ‖K_i‖_{P⁻¹} for a box, ‖K P^{-1/2}‖₂ for a 2-norm ball. It depends on the loop alone, so a
/// caller measuring every step of a nominal computes it once.
#[derive(Clone, Debug, PartialEq)]
pub enum InputScale {
    /// ‖K_i‖_{P⁻¹} per input component.
    Rows(Vec<f64>),
    /// ‖K P^{-1/2}‖₂.
    Norm(f64),
}

impl InputScale {
    /// The scale of gain `K` in the metric of `roots` for `input`'s kind.
    pub fn new(K: MatRef<'_, f64>, roots: &PdRoots, input: &InputBound) -> Self {
        match input {
            InputBound::Box { .. } => InputScale::Rows(
                (0..K.nrows())
                    .map(|i| {
                        let Ki: Vec<f64> = (0..K.ncols()).map(|j| K[(i, j)]).collect();
                        roots.dual_norm(&Ki)
                    })
                    .collect(),
            ),
            InputBound::Norm2 { .. } => InputScale::Norm(roots.norm_from(K)),
        }
    }
}

/// [`input_distance`] with the loop's [`InputScale`] computed beforehand (the same value, bit for bit).
pub fn input_distance_scaled(
    scale: &InputScale,
    u: &[f64],
    input: &InputBound,
    eps: &[f64],
) -> f64 {
    let over = |slack: f64, s: f64| {
        if s > 0.0 {
            slack / s
        } else if slack >= 0.0 {
            f64::INFINITY
        } else {
            slack
        }
    };
    match (input, scale) {
        (InputBound::Box { lo, hi }, InputScale::Rows(rows)) => {
            let mut d = f64::INFINITY;
            for (i, &s) in rows.iter().enumerate() {
                let slack = (hi[i] - eps[i] - u[i]).min(u[i] - lo[i] - eps[i]);
                d = d.min(over(slack, s));
            }
            d
        }
        (InputBound::Norm2 { center, max }, InputScale::Norm(s)) => {
            let e2 = eps.iter().map(|e| e * e).sum::<f64>().sqrt();
            let un = u
                .iter()
                .zip(center)
                .map(|(a, c)| (a - c) * (a - c))
                .sum::<f64>()
                .sqrt();
            over(max - e2 - un, *s)
        }
        // A scale made for the other kind of input set is the caller's error: NaN, which the robustness
        // scans refuse (a NaN distance is an error, never skipped).
        _ => {
            debug_assert!(false, "an input scale of the other kind of input set");
            f64::NAN
        }
    }
}

/// The radius to store so that every state the f32 selection test accepts lies in the certified ball of
/// radius `delta` (module doc, item 4). The test computes e = fl(x̂ − c) and d² = Σ_i e_i fl(Σ_j P̂_ij e_j) in
/// f32. Each e_i carries a relative error ≤ u from the subtraction plus the quantisation of x (≤ u|x_i|);
/// P̂_ij = P_ij(1 + θ) with |θ| ≤ u. The inner sum `Σ_j P̂_ij e_j` is an n-term dot product (each term
/// within γ_n, Higham §3.1), and the outer `Σ_i e_i·s_i` another, so each term `e_i P̂_ij e_j` of the
/// computed d² carries a factor within γ_{2n} of 1. Hence
/// |fl(d²) − eᵀPe| ≤ γ_{2n+4}·|e|ᵀ|P||e| + terms in u|x|, and |e|ᵀ|P||e| ≤ ‖|P|‖₂/λ_min(P)·‖e‖²_P.
/// Shrinking δ² by the factor (1 − γ_{2n+4}κ)(1 − 2u) and subtracting the quantisation term keeps
/// acceptance inside the ball. Returns the f32 value, rounded down.
pub fn selection_radius(P: MatRef<'_, f64>, center: &[f64], delta: f64) -> f32 {
    let Some((rel, quant)) = selection_rounding(P, center, delta) else {
        return 0.0;
    };
    let d = (delta * ((1.0 - rel) * (1.0 - 2.0 * U32)).sqrt() - 2.0 * quant).max(0.0);
    round_down_f32(d)
}

/// The other side of [`selection_radius`]: a radius ρ such that the f32 test with the stored radius `r̂`
/// accepts every state within ρ of `center` in the P-metric, for states within `delta` of it (the
/// quantisation term is taken at `delta`). The computed d² is at most (1 + rel)(‖e‖_P + quant)² and the
/// f32 square of r̂ at least r̂²(1 − u), so ρ = r̂·sqrt((1 − 2u)/(1 + rel)) − 2·quant. 0 when the
/// rounding analysis does not apply.
pub fn selection_floor(P: MatRef<'_, f64>, center: &[f64], r_hat: f32, delta: f64) -> f64 {
    let Some((rel, quant)) = selection_rounding(P, center, delta) else {
        return 0.0;
    };
    (r_hat as f64 * ((1.0 - 2.0 * U32) / (1.0 + rel)).sqrt() - 2.0 * quant).max(0.0)
}

/// The two error terms of the f32 selection test for states within `delta` of `center` (see
/// [`selection_radius`]): the relative error `γ_{2n+4}·‖|P|‖₂/λ_min(P)` of the computed d² and the
/// P-norm of the quantisation of x. `None` when P is not positive definite, `delta` not positive, or the
/// relative error not below 1/2.
fn selection_rounding(P: MatRef<'_, f64>, center: &[f64], delta: f64) -> Option<(f64, f64)> {
    let n = P.nrows();
    let absP = Mat::from_fn(n, n, |i, j| P[(i, j)].abs());
    let ev = sym_eigenvalues(P).unwrap_or_default();
    let (lmin, lmax) = (
        ev.first().copied().unwrap_or(0.0),
        ev.last().copied().unwrap_or(f64::INFINITY),
    );
    if !(lmin > 0.0) || !(delta > 0.0) {
        return None;
    }
    let kappa = crate::linalg::spectral_norm(absP.as_ref()) / lmin;
    let rel = gamma_k(2 * n + 4) * kappa;
    if rel >= 0.5 {
        return None;
    }
    // Quantisation of x: ‖x − x̂‖_P ≤ sqrt(λ_max)·u·(‖c‖∞ + δ·max axis) (per component bound, n of them).
    let xmax = center.iter().fold(0.0f64, |a, c| a.max(c.abs())) + delta / lmin.sqrt();
    let quant = lmax.sqrt() * (n as f64).sqrt() * (U32 * xmax + F32_ABS);
    Some((rel, quant))
}

/// The largest f32 not above x (x ≥ 0).
pub fn round_down_f32(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) > x {
        f32::from_bits(f.to_bits() - 1)
    } else {
        f
    }
}

/// Where the nominal's target (the loop's `goal`) is judged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GoalAt {
    /// At the sample of greatest depth, κ* of (4.12): the task ends when Goal is reached.
    Best,
    /// At the last sample of the table: a forced switch (§4.2.1) happens when the segment's table ends.
    Last,
    /// Nowhere: the segment ends where the plant switches by itself (§4.2.2, [`internal`]), and the
    /// caller bounds the radius by the given value instead (the rounding bound is taken at that radius;
    /// the Goal part reads it, at the last sample).
    Free(f64),
}

/// The evaluator's rounding bound over a nominal's table (module doc, item 3) for runs within the tube of
/// radius `r_max` (negative counts as 0): the componentwise bound (max over the table) and its 2-norm ε̄.
pub fn rounding_over_table(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    nom: &Nominal,
    r_max: f64,
) -> (Vec<f64>, f64) {
    let r_max = r_max.max(0.0);
    let mut eps_components = vec![0.0f64; lp.K.nrows()];
    for k in 0..nom.steps() {
        let X = tube_abs(&nom.x[k], r_max, &lc.axis);
        for (e, b) in eps_components
            .iter_mut()
            .zip(evaluator_error_bound(lp.K, &nom.v[k], &X))
        {
            *e = e.max(b);
        }
    }
    let eps_f32 = eps_components.iter().map(|e| e * e).sum::<f64>().sqrt();
    (eps_components, eps_f32)
}

/// Certify one nominal trajectory (simulated with the shipped K̂, v̂) for the loop, with the target
/// judged at its best sample ([`certify_at`] with [`GoalAt::Best`]).
pub fn certify(lp: &Loop<'_>, lc: &LoopConstants, nom: &Nominal) -> Certificate {
    certify_at(lp, lc, nom, GoalAt::Best)
}

/// Certify one nominal trajectory (simulated with the shipped K̂, v̂) for the loop: the critical samples
/// of Theorem 4.7's pieces ([`Pieces`], scanned by [`crate::robustness::safety`]'s shared scans over the
/// whole table; the target at the sample `at` says), the f32 rounding bound, r_crit and the stored radius.
/// A nominal that is not finite, or a NaN distance, certifies nothing (δ = 0, the parts NaN).
pub fn certify_at(lp: &Loop<'_>, lc: &LoopConstants, nom: &Nominal, at: GoalAt) -> Certificate {
    let pc = Pieces::new(lp, lc);
    let m = lp.K.nrows();
    let N = nom.steps();
    let n = lp.P.nrows();
    let times: Vec<f64> = (0..nom.x.len()).map(|k| k as f64).collect();
    let states: Vec<f64> = nom.x.iter().flatten().copied().collect();
    let parts = SampledTrajectory::new(&times, &states, n).and_then(|traj| {
        let metric = pc.metric();
        // 1. Goal (4.12)–(4.13): the sample of greatest depth (the earliest of equals), or the last one.
        let goal = match at {
            GoalAt::Best => {
                safety::goal_part(&traj, SafetySet::Region(lp.goal()), metric, traj.len())?
            }
            GoalAt::Last => safety::goal_at(&traj, SafetySet::Region(lp.goal()), metric, N)?,
            GoalAt::Free(r_max) => safety::Critical {
                value: r_max,
                index: N,
                time: N as f64,
                point: Vec::new(),
            },
        };
        // 2. Unsafe (4.14) at samples and between them, over the whole table (stronger than 0..=κ*). The
        // margins need the rounding bound over the table, taken with the tube at its largest possible
        // radius, min(δ_Goal, δ_Unsafe at the samples); without Unsafe, δ_Goal.
        let rounding = std::cell::OnceCell::new();
        let margin = |k: usize, d: f64, d_min: f64| {
            let (_, eps_f32) =
                rounding.get_or_init(|| rounding_over_table(lp, lc, nom, goal.value.min(d_min)));
            pc.unsafe_margin(nom, k, d, *eps_f32)
        };
        let unsafe_ = safety::unsafe_part(
            &traj,
            lp.unsafe_set().map(SafetySet::Region),
            metric,
            traj.len(),
            Some(&margin),
        )?;
        let (eps_components, eps_f32) = rounding
            .into_inner()
            .unwrap_or_else(|| rounding_over_table(lp, lc, nom, goal.value));
        // 3. Input (4.15) with the rounding margin, at every step that applies an input.
        let input = LoopInput {
            pc: &pc,
            nom,
            eps: &eps_components,
        };
        let input = safety::input_part(&traj, &input, metric, N)?;
        Ok((goal, unsafe_, input, eps_components, eps_f32))
    });
    let Ok((goal, unsafe_, input, eps_components, eps_f32)) = parts else {
        return Certificate {
            delta_goal: f64::NAN,
            k_star: 0,
            delta_unsafe: f64::NAN,
            k_unsafe: 0,
            delta_input: f64::NAN,
            k_input: 0,
            delta_unsafe_intersample: f64::NAN,
            eps_components: vec![f64::NAN; m],
            eps_f32: f64::NAN,
            r_crit: f64::NAN,
            delta: 0.0,
            delta_stored: 0.0,
            accumulated: 0.0,
        };
    };
    let delta_unsafe_is = unsafe_
        .margined
        .as_ref()
        .map_or(unsafe_.at_samples.value, |c| c.value);
    let (k_input, delta_input) = input.map_or((0, f64::INFINITY), |c| (c.index, c.value));
    let r_crit = lc.r_crit(eps_f32);
    let d47 = goal.value.min(delta_unsafe_is).min(delta_input);
    // Staying in the task's Goal until κ* (LoopConstants::stay_in): the largest radius up to d47 for which
    // the tube, once wholly in it, stays in it.
    let stay = lc
        .stay_in
        .as_ref()
        .map(|s| StayMargins::new(lp, lc, nom, s.0.as_ref(), goal.index, eps_f32));
    let d47 = stay.as_ref().map_or(d47, |s| s.largest(d47));
    // Theorem 3.21: any r in [r_crit, d47) works; the strict inequalities of Lemma 4.4 need r < d47.
    let mut delta = if d47 > 0.0 && r_crit < d47 {
        d47 * (1.0 - 1e-9)
    } else {
        0.0
    };
    // With a sampled-loop mismatch, r_crit (a one-step Lyapunov argument) is far more conservative than
    // summing the disturbances over the table: a run from the δ-ball stays within δ + `accumulated` of
    // the nominal at every sample (‖Ã^j‖_P ≤ 1), so every part holds for δ = d47 − `accumulated`.
    let mut accumulated = 0.0;
    if lc.mismatch_step() > 0.0 && d47 > 0.0 {
        let per_step = lc.roots.norm_into(lc.B.as_ref()) * eps_f32 + lc.mismatch_step();
        accumulated = lc.accumulation(N) * per_step * (1.0 + 1e-9);
        delta = delta.max((d47 - accumulated) * (1.0 - 1e-9));
    }
    if let Some(s) = &stay {
        // The tube's radius lies between δ and δ + accumulated at every sample.
        if delta > 0.0 && !s.holds(delta, delta + accumulated) {
            delta = 0.0;
        }
    }
    let delta_stored = selection_radius(lp.P, &nom.x[0], delta);
    Certificate {
        delta_goal: goal.value,
        k_star: goal.index,
        delta_unsafe: unsafe_.at_samples.value,
        k_unsafe: unsafe_.at_samples.index,
        delta_input,
        k_input,
        delta_unsafe_intersample: delta_unsafe_is,
        eps_components,
        eps_f32,
        r_crit,
        delta,
        delta_stored,
        accumulated,
    }
}

/// The figures of the stay-in condition ([`LoopConstants::stay_in`]) over samples 0..=κ*: the tube of
/// radius r about x̃(κ) lies in the set at sample κ when its P-depth g_κ ≥ r, and between κ and κ + 1
/// (κ < κ*) when r ≤ (g_κ − φ‖f_κ‖_P − φβ(ε̄ + D))/γ, the isotropic inter-sample bound of the module doc
/// (item 2) taken against the set's complement. From κ* on the run is handed over to the terminal law,
/// whose certificate covers the rest.
struct StayMargins {
    /// g_κ for κ ≤ κ*.
    depth: Vec<f64>,
    /// min(g_κ, the inter-sample margin) for κ < κ*, g_κ* at κ*.
    margin: Vec<f64>,
}

impl StayMargins {
    fn new(
        lp: &Loop<'_>,
        lc: &LoopConstants,
        nom: &Nominal,
        set: &dyn Region,
        k_star: usize,
        eps_f32: f64,
    ) -> Self {
        let metric = Metric {
            n: lp.P.nrows(),
            R: crate::linalg::to_row_major(lp.P),
        };
        let last = k_star.min(nom.x.len().saturating_sub(1));
        let held = lc.held_disturbance(eps_f32);
        let depth: Vec<f64> = nom.x[..=last]
            .iter()
            .map(|x| {
                let v = set.signed_dist(x, &metric).value;
                if v.is_nan() {
                    f64::NEG_INFINITY
                } else {
                    v
                }
            })
            .collect();
        let margin = depth
            .iter()
            .enumerate()
            .map(|(k, &g)| {
                if k == last || k >= nom.steps() {
                    return g;
                }
                match lp.plant.vector_field(lp.loc, &nom.x[k], &nom.u[k]) {
                    Some(f) => {
                        let between =
                            (g - lc.phi * crate::linalg::p_norm(lp.P, &f) - held) / lc.gamma;
                        if between.is_nan() {
                            f64::NEG_INFINITY
                        } else {
                            g.min(between)
                        }
                    }
                    None => g,
                }
            })
            .collect();
        Self { depth, margin }
    }

    /// Whether tubes of radius between `lo` and `hi` stay in the set: from the first sample with depth ≥ lo
    /// (the earliest the whole tube can lie in it) to κ*, every margin ≥ hi. True when no sample has
    /// depth ≥ lo (the tube is never wholly in the set before κ*: nothing to keep).
    fn holds(&self, lo: f64, hi: f64) -> bool {
        match self.depth.iter().position(|&g| g >= lo) {
            None => true,
            Some(j) => self.margin[j..].iter().all(|&m| m >= hi),
        }
    }

    /// The largest r ≤ `bound` (less a relative 10⁻⁹) for which [`StayMargins::holds`]`(r, r)`, or 0. With
    /// j the first sample whose depth reaches r, r must exceed every earlier depth and be at most the least
    /// margin from j on: each j gives one candidate, min(suffix minimum at j, bound).
    fn largest(&self, bound: f64) -> f64 {
        if bound.is_nan() || bound <= 0.0 {
            return bound;
        }
        let n = self.margin.len();
        let mut suffix = vec![f64::INFINITY; n + 1];
        for k in (0..n).rev() {
            suffix[k] = suffix[k + 1].min(self.margin[k]);
        }
        let mut before = f64::NEG_INFINITY;
        let mut best = 0.0f64;
        for (&s, &g) in suffix.iter().zip(&self.depth) {
            let r = s.min(bound);
            // δ is taken a relative 10⁻⁹ below its bound: the first sample at depth ≥ δ must still be
            // this one.
            if r * (1.0 - 1e-9) > before && r > best {
                best = r;
            }
            before = before.max(g);
        }
        // No sample wholly in the set below the bound: nothing to keep.
        if before < bound * (1.0 - 1e-9) {
            best = best.max(bound);
        }
        best
    }
}

/// The Input piece as the shared scan queries it: the closed-form P-distance of [`input_distance`] at
/// the nominal input of each step (it has no witness point; certification needs none).
struct LoopInput<'p, 'a, 'b> {
    pc: &'p Pieces<'a, 'b>,
    nom: &'p Nominal,
    eps: &'p [f64],
}

impl InputSets for LoopInput<'_, '_, '_> {
    fn samples(&self) -> Option<usize> {
        Some(self.nom.steps())
    }
    fn signed_dist(&self, kappa: usize, x: &[f64], metric: &Metric) -> Witness {
        Witness {
            value: self.signed_value(kappa, x, metric),
            point: Vec::new(),
        }
    }
    fn signed_value(&self, kappa: usize, _x: &[f64], _metric: &Metric) -> f64 {
        self.pc.input_value(self.nom, kappa, self.eps)
    }
}

/// The one path from a reference sequence to what ships: `v` rounded to f32, the nominal of the loop
/// with the shipped gain `lp.K` from `x0` (which the caller keeps f32-representable), and its certificate.
pub fn shipped(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    v: &[Vec<f64>],
) -> (Nominal, Certificate) {
    let v32: Vec<Vec<f64>> = v
        .iter()
        .map(|r| r.iter().map(|&a| a as f32 as f64).collect())
        .collect();
    let nom = lp.simulate(x0, &v32);
    let cert = certify(lp, lc, &nom);
    (nom, cert)
}

#[cfg(test)]
mod tests {
    use super::StayMargins;

    fn stay(depth: &[f64], margin: &[f64]) -> StayMargins {
        StayMargins {
            depth: depth.to_vec(),
            margin: margin.to_vec(),
        }
    }

    /// A nominal that enters the set, leaves it and comes back: a tube of radius r is wholly in it first
    /// at the first sample of depth ≥ r and must stay from there, so a large r (first wholly inside
    /// after the dip) passes, a middle one (inside before the dip) fails, and the largest passing r up to
    /// the bound is found.
    #[test]
    fn the_stay_condition_starts_where_the_tube_is_first_wholly_inside() {
        // Depths: outside, inside 0.2, dips out to −0.1, deep inside 0.5 and 0.6 (κ* = 4).
        let s = stay(&[-1.0, 0.2, -0.1, 0.5, 0.6], &[-1.0, 0.2, -0.1, 0.5, 0.6]);
        assert!(s.holds(0.4, 0.4), "wholly inside first at κ = 3, and stays");
        assert!(
            !s.holds(0.1, 0.1),
            "wholly inside at κ = 1, then out at κ = 2"
        );
        assert!((s.largest(0.55) - 0.55).abs() < 1e-12);
        assert!((s.largest(0.45) - 0.45).abs() < 1e-12);
        // A bound below the first visit's depth: every radius up to it meets the dip.
        assert_eq!(s.largest(0.15), 0.0);
        // The inter-sample margin counts between κ and κ + 1.
        let s = stay(&[-1.0, 0.5, 0.6], &[-1.0, 0.3, 0.6]);
        assert!((s.largest(0.5) - 0.3).abs() < 1e-12);
        assert!(s.holds(0.3, 0.3) && !s.holds(0.31, 0.31));
    }
}
