//! Piecewise-affine feedback learned from a certified feedforward cover (Ch. 6).
//!
//! # What is learned
//! The feedforward controller of Algorithm 2 applies `u = K x + ṽ_i(κ)` along certified nominal runs
//! x̃_i. This module replaces the replayed table by the law (6.1), `u = (K + θ_j) x + θ0_j` on partition
//! X_j, learned from the pairs (x̃_i(κ), ṽ_i(κ)) ([`learn`], §6.2), and a bounded-depth tree that routes a
//! state to its partition ([`partition`], §6.3). The envelope is F of (6.2): the union of the certified
//! balls `B_P(x̃_i(κ), δ_i)`.
//!
//! # Why a law is safe on a ball (Theorem 6.6)
//! For a state x = x̃_i(κ) + e in the ball (‖e‖_P ≤ δ_i) and the law j,
//! `x⁺ − x̃_i(κ+1) = Ã_j e + B ε` with `Ã_j = A + B K + B θ_j` and `ε = θ_j x̃_i(κ) + θ0_j − ṽ_i(κ)` the
//! fitting error at the data point, plus the f32 rounding of the evaluator, which is a further bounded
//! input disturbance (DESIGN §5). This is the setting of Theorem 3.21 with Ã_j in place of Ã. A law is
//! accepted for a ball ([`check_point`]) only when all of the following hold, each recomputed here with
//! faer eigenvalues and norms, independently of the solver that proposed θ_j:
//!
//! * **(6.6)**: `[Q, Ã_j Q; (Ã_j Q)ᵀ, Q] ⪰ 0` with Q = P⁻¹ (the matrix written P in (3.65)–(3.67) and
//!   (6.6) is the LMI variable, the inverse of the CAF metric P used here). By the Schur complement this
//!   is `Q − Ã_j Q Ã_jᵀ ⪰ 0`, i.e. `‖Ã_j‖_P ≤ 1`, i.e. `P − Ã_jᵀ P Ã_j ⪰ 0` (3.64); we require the strict
//!   version `σ_j = λ_min(P − Ã_jᵀPÃ_j) > 0`, the hypothesis of Theorem 3.21.
//! * **(6.7)**: `r̃_crit(Ã_j, ε̄) < ρ_i`, r̃_crit from (3.83)–(3.87) ([`crate::caf::r_crit`]) for the ball's
//!   disturbance bound ε̄ (fitting error plus rounding bound, 2-norm), ρ_i the radius stored in the image.
//! * **(6.5), one step**: `‖Ã_j‖_P δ_i + ‖P^{1/2} B ε̄‖ ≤ (1 − η) ρ_i`: every state the image accepts in
//!   the ball at κ (they lie within the certified δ_i ≥ ρ_i) lands strictly inside the stored ball at κ+1,
//!   with a relative margin η for the f32 ball test.
//! * **Input**: the law's input over the ball stays in the input set shrunk by the rounding bound
//!   ([`crate::certify::input_distance`] with the law's gain).
//!
//! Goal and Unsafe need no new check: the balls are the feedforward certificate's balls (Theorem 4.7).
//!
//! # Limits
//! * Discrete-time loop only: for continuous-time plants the inter-sample bound of the certificate was
//!   computed with K, not K + θ_j; [`learn_pwa`] refuses such plants rather than certify them wrongly.
//! * Theorems 6.5–6.6 give safety (the run stays in F until Goal). Reaching Goal within T is not implied
//!   when a run switches between trajectories' balls; it is checked empirically by the tests.
//! * The f32 ball test is assumed to accept only states within δ_i when ρ_i is the feedforward
//!   certificate's stored radius (its selection shrink uses γ_{n+4}, larger than the γ_{2n} of the PWA test
//!   for n ≤ 4).

pub mod learn;
pub mod partition;

use crate::certify::{evaluator_error_bound, input_distance};
use crate::linalg::{mat_vec, sym_eigenvalues, PdRoots};
use crate::synth::{round32, Synthesis};
use crate::trajectory::generate::InputBound;
use faer::Mat;

pub use learn::{learn_laws, LearnedLaw};
pub use partition::{build_image, PartitionStats};

/// Settings of the learning and partitioning, with documented defaults ([`PwaSettings::default`]).
#[derive(Clone, Debug)]
pub struct PwaSettings {
    /// The fitting tolerance is chosen so that r_crit(A + BK, ε_fit + ε_f32) ≤ `rcrit_fraction` · min_i ρ_i
    /// (Example 6.4 uses one half). Default 0.5.
    pub rcrit_fraction: f64,
    /// Seeds tried per cluster (multi-start of the greedy search; the largest verified cluster wins).
    /// Default 4.
    pub seeds: usize,
    /// Consecutive rejected candidates after which a cluster stops growing. Default 12.
    pub max_failures: usize,
    /// Relative margin η of the one-step inclusion (6.5) for the f32 ball test. Default 1e-4.
    pub eta: f64,
    /// Largest tree depth (hyperplane tests). Default `shared_types::capacity::MAX_TREE_DEPTH`.
    pub max_depth: usize,
}

impl Default for PwaSettings {
    fn default() -> Self {
        Self {
            rcrit_fraction: 0.5,
            seeds: 4,
            max_failures: 12,
            eta: 1e-4,
            max_depth: shared_types::capacity::MAX_TREE_DEPTH,
        }
    }
}

impl PwaSettings {
    pub fn rcrit_fraction(mut self, v: f64) -> Self {
        self.rcrit_fraction = v;
        self
    }
    pub fn seeds(mut self, v: usize) -> Self {
        self.seeds = v;
        self
    }
    pub fn max_failures(mut self, v: usize) -> Self {
        self.max_failures = v;
        self
    }
    pub fn eta(mut self, v: f64) -> Self {
        self.eta = v;
        self
    }
    pub fn max_depth(mut self, v: usize) -> Self {
        self.max_depth = v;
        self
    }
}

/// Why no PWA controller could be built.
#[derive(Debug, thiserror::Error)]
pub enum PwaError {
    #[error("PWA feedback is implemented for discrete-time loops only (inter-sample bound not rechecked)")]
    ContinuousPlant,
    #[error("no certified trajectory with a step before Goal: nothing to learn from")]
    NoData,
    #[error("the CAF metric P is not positive definite")]
    MetricNotPd,
    #[error("no critical radius for A + BK: {0}")]
    RCrit(String),
    #[error("the tree needs more than the image capacities allow: {0}")]
    Capacity(String),
    #[error(transparent)]
    Emit(#[from] crate::emit::EmitError),
}

/// One data point: the step κ of certified trajectory i, with its ball.
#[derive(Clone, Debug)]
pub struct DataPoint {
    pub traj: usize,
    pub kappa: usize,
    /// x̃_i(κ).
    pub x: Vec<f64>,
    /// ṽ_i(κ).
    pub v: Vec<f64>,
    /// ũ_i(κ) = K x̃_i(κ) + ṽ_i(κ), the input of the feedforward law.
    pub u: Vec<f64>,
    /// The certified radius δ_i (accepted states lie within it).
    pub delta: f64,
    /// The stored radius ρ_i (f32, rounded down), the image's ball.
    pub rho: f64,
}

/// The loop and data the learning works on.
#[derive(Clone, Debug)]
pub struct PwaContext {
    pub n: usize,
    pub m: usize,
    pub A: Mat<f64>,
    pub B: Mat<f64>,
    /// The shipped (f32-exact) CAF gain.
    pub K: Mat<f64>,
    pub P: Mat<f64>,
    pub roots: PdRoots,
    /// ‖P^{1/2} B‖₂.
    pub norm_B: f64,
    /// sqrt((P⁻¹)_jj): the largest |e_j| over ‖e‖_P ≤ 1.
    pub axis: Vec<f64>,
    pub input: InputBound,
    pub points: Vec<DataPoint>,
    /// Per-component fitting tolerance ε_fit of the bounded-error fit (modification 1 of §6.2).
    pub eps_fit: f64,
    pub settings: PwaSettings,
}

impl PwaContext {
    /// Collects the data points (κ = 0..κ*_i − 1 of every certified trajectory: the balls from which the
    /// run has not yet been certified inside Goal) and chooses ε_fit (§6.2, modification 1): with ε̄ the
    /// largest rounding bound of the evaluator over the data, ε_fit (2-norm ε_fit·√m) is the largest value
    /// with r_crit(A + BK, ε_fit√m + ε̄) ≤ `rcrit_fraction` · min_i ρ_i, using that r_crit (3.87) is linear
    /// in the disturbance bound.
    pub fn new(
        problem: &crate::spec::Problem,
        syn: &Synthesis,
        settings: PwaSettings,
    ) -> Result<Self, PwaError> {
        if syn.plant.continuous.is_some() {
            return Err(PwaError::ContinuousPlant);
        }
        let (n, m) = (syn.K.ncols(), syn.K.nrows());
        let roots = PdRoots::new(syn.P.as_ref()).ok_or(PwaError::MetricNotPd)?;
        let axis: Vec<f64> = (0..n).map(|j| roots.inv[(j, j)].max(0.0).sqrt()).collect();
        let mut points = Vec::new();
        for (i, t) in syn.trajectories.iter().enumerate() {
            let c = &t.certificate;
            if !c.is_certified() {
                continue;
            }
            for k in 0..c.k_star.min(t.nominal.v.len()) {
                points.push(DataPoint {
                    traj: i,
                    kappa: k,
                    x: t.nominal.x[k].clone(),
                    v: t.nominal.v[k].clone(),
                    u: t.nominal.u[k].clone(),
                    delta: c.delta,
                    rho: c.delta_stored as f64,
                });
            }
        }
        if points.is_empty() {
            return Err(PwaError::NoData);
        }
        let At = &syn.plant.A + &syn.plant.B * &syn.K;
        let rc1 = crate::caf::r_crit(At.as_ref(), syn.P.as_ref(), syn.plant.B.as_ref(), 1.0)
            .map_err(|e| PwaError::RCrit(e.to_string()))?
            .r_crit;
        let rho_min = points.iter().map(|p| p.rho).fold(f64::INFINITY, f64::min);
        let mut eps_round = 0.0f64;
        for p in &points {
            let X: Vec<f64> =
                p.x.iter()
                    .zip(&axis)
                    .map(|(x, a)| x.abs() + p.delta * a)
                    .collect();
            let e = evaluator_error_bound(syn.K.as_ref(), &p.v, &X);
            eps_round = eps_round.max(e.iter().map(|e| e * e).sum::<f64>().sqrt());
        }
        let budget = settings.rcrit_fraction * rho_min / rc1;
        let eps_fit = ((budget - 2.0 * eps_round) / (m as f64).sqrt()).max(0.0);
        let norm_B = roots.norm_into(syn.plant.B.as_ref());
        Ok(Self {
            n,
            m,
            A: syn.plant.A.clone(),
            B: syn.plant.B.clone(),
            K: syn.K.clone(),
            P: syn.P.clone(),
            roots,
            norm_B,
            axis,
            input: crate::synth::input_bound(&problem.input),
            points,
            eps_fit,
            settings,
        })
    }
}

/// A law as the image stores it: the full gain K_j = fl32(K + θ_j) and offset fl32(θ0_j), widened exactly,
/// with its law-level quantities.
#[derive(Clone, Debug)]
pub struct StoredLaw {
    pub gain: Mat<f64>,
    pub offset: Vec<f64>,
    /// Ã_j = A + B K_j.
    pub At: Mat<f64>,
    /// σ_j = λ_min(P − Ã_jᵀPÃ_j) (6.6); must be > 0.
    pub sigma: f64,
    /// ‖Ã_j‖_P.
    pub norm_At: f64,
    /// r̃_crit(Ã_j, ε = 1) (3.87); r̃_crit is linear in ε. ∞ if it does not exist.
    pub rcrit_unit: f64,
}

impl StoredLaw {
    /// Rounds θ_j, θ0_j as the image will and computes the (6.6) margin and the unit critical radius.
    pub fn new(ctx: &PwaContext, theta: &Mat<f64>, theta0: &[f64]) -> Self {
        let gain = Mat::from_fn(ctx.m, ctx.n, |i, j| round32(ctx.K[(i, j)] + theta[(i, j)]));
        let offset: Vec<f64> = theta0.iter().map(|&t| round32(t)).collect();
        let At = &ctx.A + &ctx.B * &gain;
        let M = &ctx.P - At.transpose() * &ctx.P * &At;
        let sigma = sym_eigenvalues(crate::linalg::sym(M.as_ref()).as_ref())
            .and_then(|e| e.first().copied())
            .unwrap_or(f64::NAN);
        let norm_At = ctx.roots.induced_norm(At.as_ref());
        let rcrit_unit = if sigma > 0.0 {
            crate::caf::r_crit(At.as_ref(), ctx.P.as_ref(), ctx.B.as_ref(), 1.0)
                .map(|r| r.r_crit)
                .unwrap_or(f64::INFINITY)
        } else {
            f64::INFINITY
        };
        Self {
            gain,
            offset,
            At,
            sigma,
            norm_At,
            rcrit_unit,
        }
    }

    /// The law's input at x.
    pub fn input(&self, x: &[f64]) -> Vec<f64> {
        mat_vec(self.gain.as_ref(), x)
            .iter()
            .zip(&self.offset)
            .map(|(a, b)| a + b)
            .collect()
    }
}

/// The verdict of [`check_point`] for one law and one ball.
#[derive(Clone, Debug, PartialEq)]
pub struct PointCheck {
    /// Fitting error K_j x̃ + θ0_j − ũ (∞-norm).
    pub fit_err: f64,
    /// Disturbance bound ε̄ (2-norm): fitting error plus the evaluator's rounding bound.
    pub eps: f64,
    /// (6.6) margin σ_j.
    pub sigma: f64,
    /// r̃_crit(Ã_j, ε̄) of (6.7).
    pub r_crit: f64,
    /// Left side of the one-step inclusion (6.5): ‖Ã_j‖_P δ_i + ‖P^{1/2}B‖ ε̄.
    pub reach: f64,
    /// P-distance from the ball centre to inputs outside the (shrunk) input set.
    pub input_dist: f64,
    /// All conditions hold.
    pub ok: bool,
}

/// Checks (6.6), (6.7), the one-step inclusion (6.5) and the input bound for law `law` on the ball of data
/// point `k` (module doc). Independent of how the law was found.
pub fn check_point(ctx: &PwaContext, law: &StoredLaw, k: usize) -> PointCheck {
    let p = &ctx.points[k];
    let uc = law.input(&p.x);
    let fit: Vec<f64> = uc.iter().zip(&p.u).map(|(a, b)| a - b).collect();
    let fit_err = fit.iter().fold(0.0f64, |a, e| a.max(e.abs()));
    let fit2 = fit.iter().map(|e| e * e).sum::<f64>().sqrt();
    let X: Vec<f64> =
        p.x.iter()
            .zip(&ctx.axis)
            .map(|(x, a)| x.abs() + p.delta * a)
            .collect();
    let round = evaluator_error_bound(law.gain.as_ref(), &law.offset, &X);
    let eps = fit2 + round.iter().map(|e| e * e).sum::<f64>().sqrt();
    let r_crit = law.rcrit_unit * eps;
    let reach = law.norm_At * p.delta + ctx.norm_B * eps;
    let input_dist = input_distance(law.gain.as_ref(), &ctx.roots, &uc, &ctx.input, &round);
    let ok = law.sigma > 0.0
        && r_crit < p.rho
        && reach <= (1.0 - ctx.settings.eta) * p.rho
        && input_dist >= p.delta;
    PointCheck {
        fit_err,
        eps,
        sigma: law.sigma,
        r_crit,
        reach,
        input_dist,
        ok,
    }
}

/// Everything [`learn_pwa`] produced.
#[derive(Clone, Debug)]
pub struct PwaController {
    pub ctx: PwaContext,
    /// The laws (index = partition), with their clusters.
    pub laws: Vec<LearnedLaw>,
    /// The cluster (law) each data point was learned into.
    pub assignment: Vec<usize>,
    /// For each data point, every law verified for its ball (always contains its own).
    pub admissible: Vec<Vec<usize>>,
    pub builder: crate::emit::PwaImageBuilder,
    pub image: Vec<u8>,
    pub stats: PartitionStats,
    pub learn_seconds: f64,
    pub partition_seconds: f64,
}

/// Learns the PWA law (§6.2) from a synthesis' certified cover, builds the partition tree (§6.3) and emits
/// the PWA image.
pub fn learn_pwa(
    problem: &crate::spec::Problem,
    syn: &Synthesis,
    settings: &PwaSettings,
) -> Result<PwaController, PwaError> {
    let t0 = std::time::Instant::now();
    let ctx = PwaContext::new(problem, syn, settings.clone())?;
    let (laws, assignment) = learn_laws(&ctx);
    let learn_seconds = t0.elapsed().as_secs_f64();
    let t1 = std::time::Instant::now();
    let stored: Vec<&StoredLaw> = laws.iter().map(|l| &l.stored).collect();
    let admissible: Vec<Vec<usize>> = (0..ctx.points.len())
        .map(|k| {
            (0..laws.len())
                .filter(|&j| j == assignment[k] || check_point(&ctx, stored[j], k).ok)
                .collect()
        })
        .collect();
    let (mut builder, stats) = build_image(&ctx, &laws, &assignment, &admissible)?;
    builder.period = problem.plant.period;
    if let crate::spec::InputSet::Box { lo, hi } = &problem.input {
        builder.input_box = Some((lo.clone(), hi.clone()));
    }
    let image = builder.to_bytes()?;
    let partition_seconds = t1.elapsed().as_secs_f64();
    Ok(PwaController {
        ctx,
        laws,
        assignment,
        admissible,
        builder,
        image,
        stats,
        learn_seconds,
        partition_seconds,
    })
}
