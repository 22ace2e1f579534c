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
//! * **(6.5), one step**: `‖Ã_j‖_P δ_i + ‖P^{1/2} B ε̄‖ ≤ r_in(i, κ+1)`: every state the image accepts in
//!   the ball at κ (they lie within the certified δ_i ≥ ρ_i) lands where the f32 test of the ball at κ+1
//!   provably accepts it, r_in being [`crate::certify::pwa_ball_complete_radius`] (below ρ_i by less than
//!   10⁻⁴ relative for unit-scale data, `tests/host/certify_bounds.rs`); at κ+1 = κ*_i the bound is δ_i,
//!   since that ball lies in Goal.
//! * **Input**: the law's input over the ball stays in the input set shrunk by the rounding bound
//!   ([`crate::certify::input_distance`] with the law's gain).
//! * **Between samples** (continuous-time plants, zero-order hold). The feedforward certificate bounded the
//!   inter-sample excursion with K; under law j the held input is `u = K_j x + θ0_j`, so it is recomputed
//!   per (law, ball) with the same bound as [`crate::certify`] item 2: for x = x̃ + e, ‖e‖_P ≤ δ_i, the
//!   vector field at the sample is `f = f̃ + (A_c + B_c K_j) e + B_c ε` (f̃ = A_c x̃ + B_c ũ + c), hence
//!   `‖x(κh+s) − x̃(κ)‖_P ≤ γ_j δ_i + φ‖f̃‖_P + φβε̄` on [0, h] with γ_j = 1 + φ(h)‖A_c + B_c K_j‖_P,
//!   φ(h) = (e^{μh} − 1)/μ and β = ‖P^{1/2}B_c‖. The law is accepted on the ball only if this stays below
//!   dist_P(x̃_i(κ), Unsafe), or, where Unsafe is a union of known convex pieces, if the run misses each
//!   piece by the drift against its normal: the run deviates from the nominal's held flow by at most
//!   w = γ_j δ_i + φβε̄, and min_j (base_j − slope_j·w) > 0 (`certify::pieces`' module doc, "Between
//!   samples along a direction", the bound the feedforward certificate takes). (For discrete plants
//!   φ = 0, γ_j = 1 and the check is the sample one.)
//!
//! Goal and Unsafe at the samples need no new check: the balls are the feedforward certificate's balls
//! (Theorem 4.7), which lie outside Unsafe, and the ball at κ*_i lies in Goal.
//!
//! # Reaching Goal within T
//! Theorems 6.5–6.6 give invariance of F until Goal. Reaching Goal within T needs one more property of the
//! tree of [`partition`], because a state may lie in several balls and the evaluator applies the law of the
//! first listed ball that contains it. Let τ(i, κ) = κ*_i − κ be a ball's time-to-go. Every ball that meets
//! a leaf's cell is listed by that leaf with a law verified for it (no ball is dropped, else the build
//! fails), and every leaf lists its balls by increasing τ. Suppose x is accepted by ball b = (i, κ). Its law
//! maps x into b⁺ = (i, κ+1), so x⁺ lies in b⁺, which the leaf of x⁺ lists; the first listed ball
//! containing x⁺ therefore has τ ≤ τ(b⁺) = τ(b) − 1. The time-to-go of the accepting ball drops by at least
//! one per step, and a ball with τ = 0 is the ball at κ*_i, which lies in Goal. A run accepted at its
//! first step in a ball with time-to-go τ is in Goal after at most τ ≤ T/h steps.
//!
//! # Limits
//! * How much the law compresses depends on how fast ṽ = ũ − K x̃ changes per sample against the fitting
//!   tolerance, which (6.5) makes proportional to the per-step contraction 1 − ‖A + BK‖_P. Sampled finely
//!   (Example 4.8 at 0.01 s), ṽ moves by up to ~0.05 per step against a tolerance of ~1e-3, and 1 972 data
//!   points need 517 laws (greedy search). Example 6.4's setting is sampled at 0.06 s (examples/planar-vehicle-pwa-4.toml
//!   explains why): 332 data points, 52 laws. A held reference ([`crate::trajectory::hold`], spec key
//!   `reference_hold`) makes the data piecewise constant, which θ_j = 0 laws fit exactly (§6.2's
//!   piecewise-constant case): at 0.01 s with 20-sample blocks, 54 laws for 1 964 points, at a certified
//!   radius of 0.030 instead of 0.109 (the input bound binds at the end of the first block).
//! * How densely the balls overlap bounds the tree, since a leaf lists every ball that meets its cell:
//!   a leaf over a state that k balls contain lists at least k (≤ `MAX_LEAF_BALLS`). Consecutive balls of
//!   a trajectory overlap when δ_i is large against the step x̃_i(κ+1) − x̃_i(κ), and a cover of all of
//!   Init ends many trajectories in the same Goal. The cut by laws ([`TreeSplit::Laws`]) then lists the
//!   overlapping balls on both sides of every cut and outgrows `MAX_TREE_NODES`; the cut on the data alone
//!   ([`TreeSplit::Balanced`]) fits as long as the overlap does (examples/planar-vehicle-pwa.toml).
//! * The f32 ball test accepts only states within δ_i, and accepts every state within r_in: each ball's
//!   stored radius ρ_i is its own [`crate::certify::pwa_ball_radius`] for (x̃_i(κ), δ_i), and r_in its
//!   [`crate::certify::pwa_ball_complete_radius`], both derived from the evaluator's whitened test
//!   (`shared_types::pwa`, "Rounding of the ball test").

pub mod learn;
pub mod partition;

use crate::certify::{evaluator_error_bound, input_distance};
use crate::linalg::round32;
use crate::linalg::{mat_vec, sym_eigenvalues, PdRoots};
use crate::property::InputBound;
use crate::settings::{settings_builder, Check, SettingError};
use crate::synth::Synthesis;
use crate::task::Task;
use faer::Mat;

pub use learn::{learn_laws, LearnedLaw};
pub use partition::{build_image, PartitionStats};

/// Settings of the learning and partitioning, with documented defaults ([`PwaSettings::default`]). Build
/// with [`PwaSettings::builder`] (validated; `to_builder` starts from existing settings). Every entry point
/// checks them again.
#[derive(Clone, Debug)]
pub struct PwaSettings {
    /// The fitting tolerance is chosen so that a law with the design contraction has
    /// r̃_crit(Ã_j, ε_fit + ε_f32) ≤ `rcrit_fraction` · min_i ρ_i (Example 6.4 uses one half). Finite, > 0.
    /// Default 0.5.
    pub rcrit_fraction: f64,
    /// Design contraction s of the fitted laws: the fit (an SDP) asks `‖A + BK_j‖_P ≤ √(1 − s)` ((6.6) with
    /// margin). Larger s allows a larger fitting tolerance (modification 1 of §6.2) at the price of larger
    /// gains. `None`: the contraction of the CAF gain K itself, 1 − ‖A + BK‖²_P. `Some(s)`: s in (0, 1).
    /// Default `None`.
    pub contraction: Option<f64>,
    /// Seeds tried per cluster (multi-start of the greedy search; the largest verified cluster wins).
    /// ≥ 1. Default 4.
    pub seeds: usize,
    /// Consecutive rejected candidates after which a cluster stops growing. Default 12.
    pub max_failures: usize,
    /// Cycles of the thermal-relaxation search run from every seed besides the greedy growth
    /// ([`learn`] module doc); 0 turns it off. On Example 6.4 it finds the larger cluster for 6 of 202
    /// seeds and roughly triples the learning time. Default 40.
    pub thermal_cycles: usize,
    /// Part of the smallest stored radius kept out of the fitting budget (modification 1 of §6.2), so that
    /// laws are not fitted at the very edge of the one-step inclusion (6.5). Not needed for soundness: the
    /// budget already leaves out the proved gap of the f32 ball test (9·10⁻⁶ of ρ on the double integrator),
    /// and every law is verified against the exact condition. With the gap alone the double integrator at
    /// `rcrit_fraction = 0.02` learns laws whose clusters interleave, and its tree needs 7 369 ball
    /// references (the image holds 4 096) instead of 2 260. In [0, 1). Default 1e-4.
    pub fit_reserve: f64,
    /// Largest tree depth (hyperplane tests). In 1..=`shared_types::capacity::MAX_TREE_DEPTH`.
    /// Default `shared_types::capacity::MAX_TREE_DEPTH`.
    pub max_depth: usize,
    /// Show a progress bar over the data points while learning. Default false.
    pub progress: bool,
    /// Target number of balls per leaf of the cut by laws ([`TreeSplit::Laws`]): a node with one verified
    /// law is still split while it holds more and a cut makes progress, since every ball of a leaf may be
    /// tested in one control step (the out-of-envelope answer tests them all). The cut on the data
    /// ([`TreeSplit::Balanced`]) fills its leaves up to `MAX_LEAF_BALLS` instead: below the number of balls
    /// over one state no cut makes progress. ≥ 1. Default 8.
    pub leaf_balls: usize,
    /// How the tree chooses its cuts ([`TreeSplit`]). Default [`TreeSplit::Auto`].
    pub split: TreeSplit,
}

/// How the point-location tree of [`partition`] cuts a node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum TreeSplit {
    /// Separate the node's most frequent law from the others (the robust LP of [192], §6.3), falling back
    /// to the most balanced cut; a node whose balls share no verified law is cut down to small mixed
    /// leaves, and a node with one law down to `leaf_balls` balls.
    Laws,
    /// Cut on the data alone: the most balanced cut until a node holds at most a leaf size of balls
    /// (the smallest of 16, 32 and `MAX_LEAF_BALLS` whose tree fits the capacities), whatever their laws. Every listed ball carries the law verified for it and the evaluator applies
    /// that law, so a mixed leaf is as sound as a pure one; the tree then only routes, and its size follows
    /// how many balls overlap rather than how many law boundaries there are. Where the balls of F overlap
    /// densely (every ball meeting a cell must be listed by its leaf), cutting by laws duplicates the
    /// overlapping balls into both children at every level and the tree outgrows `MAX_TREE_NODES`.
    Balanced,
    /// [`TreeSplit::Laws`], and [`TreeSplit::Balanced`] when that tree exceeds the image capacities.
    #[default]
    Auto,
}

impl Default for PwaSettings {
    fn default() -> Self {
        Self {
            rcrit_fraction: 0.5,
            contraction: None,
            seeds: 4,
            max_failures: 12,
            thermal_cycles: 40,
            fit_reserve: 1e-4,
            max_depth: shared_types::capacity::MAX_TREE_DEPTH,
            progress: false,
            leaf_balls: 8,
            split: TreeSplit::Auto,
        }
    }
}

impl PwaSettings {
    /// Checks the ranges documented on the fields; the first violation is returned.
    pub fn validate(&self) -> Result<(), SettingError> {
        let c = Check("PwaSettings");
        c.positive("rcrit_fraction", self.rcrit_fraction)?;
        if let Some(s) = self.contraction {
            c.open_unit("contraction", s)?;
        }
        c.at_least_one("seeds", self.seeds)?;
        c.rule(
            "fit_reserve",
            self.fit_reserve,
            self.fit_reserve >= 0.0 && self.fit_reserve < 1.0,
            "must lie in [0, 1)",
        )?;
        c.rule(
            "max_depth",
            self.max_depth as f64,
            (1..=shared_types::capacity::MAX_TREE_DEPTH).contains(&self.max_depth),
            "must lie in 1..=MAX_TREE_DEPTH",
        )?;
        c.at_least_one("leaf_balls", self.leaf_balls)
    }
}

settings_builder!(PwaSettings, PwaSettingsBuilder {
    rcrit_fraction: f64,
    contraction: Option<f64>,
    seeds: usize,
    max_failures: usize,
    thermal_cycles: usize,
    fit_reserve: f64,
    max_depth: usize,
    progress: bool,
    leaf_balls: usize,
    split: TreeSplit,
});

/// Why no PWA controller could be built.
#[derive(Debug, thiserror::Error)]
pub enum PwaError {
    #[error(transparent)]
    Settings(#[from] SettingError),
    #[error("no certified trajectory with a step before Goal: nothing to learn from")]
    NoData,
    #[error("the CAF metric P is not positive definite")]
    MetricNotPd,
    #[error("no critical radius for A + BK: {0}")]
    RCrit(#[source] crate::caf::CafError),
    #[error(
        "ball of trajectory {traj} at step {kappa}: the f32 ball test certifies no radius within δ = {delta:e}"
    )]
    BallTest {
        traj: usize,
        kappa: usize,
        delta: f64,
    },
    #[error(
        "the tree needs more than the image capacities allow: {exceeded}{}",
        learned.map_or(String::new(), |l| format!(" ({l})"))
    )]
    Capacity {
        exceeded: CapacityExceeded,
        /// What the tree was built from, when the learner adds it.
        learned: Option<LearnedSummary>,
    },
    #[error(transparent)]
    Emit(#[from] crate::emit::EmitError),
}

/// Which fixed capacity of the image (`shared_types::capacity`) the tree would exceed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CapacityExceeded {
    /// The tree needs a node beyond `max` (`MAX_TREE_NODES`).
    #[error("more than {max} tree nodes")]
    TreeNodes { max: usize },
    /// `dropped` (leaf, ball) pairs did not fit the leaves' `max` balls each (`MAX_LEAF_BALLS`).
    #[error(
        "{dropped} (leaf, ball) pairs exceed MAX_LEAF_BALLS = {max}: part of F would be reported out of \
         envelope, so the certificate would not hold"
    )]
    LeafBalls { dropped: usize, max: usize },
    /// The leaves list `refs` ball references in all, more than `max` (`MAX_BALL_REFS`).
    #[error("{refs} ball references in the leaves, more than MAX_BALL_REFS = {max}")]
    BallRefs { refs: usize, max: usize },
}

/// What a PWA tree was built from, for the capacity message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearnedSummary {
    pub laws: usize,
    pub data_points: usize,
    pub learn_seconds: f64,
    /// The fitting tolerance ε_fit.
    pub eps_fit: f64,
}

impl std::fmt::Display for LearnedSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} laws learned from {} data points in {:.1} s, ε_fit = {:.3e}",
            self.laws, self.data_points, self.learn_seconds, self.eps_fit
        )
    }
}

/// One data point: the step κ of certified trajectory i, with its ball.
#[derive(Clone, Debug)]
pub struct DataPoint {
    pub traj: usize,
    pub kappa: usize,
    /// Time-to-go τ = κ*_i − κ (module doc, "Reaching Goal within T").
    pub to_go: usize,
    /// x̃_i(κ).
    pub x: Vec<f64>,
    /// ṽ_i(κ).
    pub v: Vec<f64>,
    /// ũ_i(κ) = K x̃_i(κ) + ṽ_i(κ), the input of the feedforward law.
    pub u: Vec<f64>,
    /// The certified radius δ_i (accepted states lie within it).
    pub delta: f64,
    /// The stored radius ρ_i of the image's whitened ball test for this ball
    /// ([`crate::certify::pwa_ball_radius`]: accepted states lie within δ_i).
    pub rho: f64,
    /// How far from x̃_i(κ+1) the one-step image of this ball may reach (6.5): the radius within which the
    /// f32 test of the ball at κ+1 provably accepts ([`crate::certify::pwa_ball_complete_radius`]), or δ_i
    /// when κ+1 = κ*_i (that ball lies in Goal, where the run ends).
    pub reach_limit: f64,
    /// dist_P(x̃_i(κ), Unsafe) (∞ without Unsafe).
    pub unsafe_dist: f64,
    /// φ(h)‖A_c x̃ + B_c ũ + c‖_P: the nominal's inter-sample excursion (0 for discrete plants).
    pub excursion: f64,
    /// Unsafe's convex pieces as seen over the period from x̃_i(κ) under the nominal's held input
    /// ([`crate::certify::pieces::piece_clearances`]; module doc, "Between samples"), where known.
    pub pieces: Option<Vec<crate::certify::pieces::PieceClearance>>,
}

/// Inter-sample constants of a continuous-time plant (module doc, "Between samples").
#[derive(Clone, Debug)]
pub struct InterSample {
    pub Ac: Mat<f64>,
    pub Bc: Mat<f64>,
    /// φ(h) = (e^{μh} − 1)/μ, μ the P-logarithmic norm of A_c.
    pub phi: f64,
    /// β = ‖P^{1/2} B_c‖₂.
    pub beta: f64,
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
    /// Continuous-time plants: the inter-sample constants; `None` for discrete-time plants.
    pub intersample: Option<InterSample>,
    pub points: Vec<DataPoint>,
    /// Per-component fitting tolerance ε_fit of the bounded-error fit (modification 1 of §6.2).
    pub eps_fit: f64,
    /// Contraction s asked of fitted laws in the fit's LMI: ‖A + BK_j‖_P ≤ √(1 − s).
    pub s_req: f64,
    pub settings: PwaSettings,
    /// The synthesis's certified terminal law, which the PWA image carries too (section 11).
    pub terminal: Option<crate::certify::terminal::StoredTerminal>,
}

impl PwaContext {
    /// Collects the data points (κ = 0..κ*_i − 1 of every certified trajectory: the balls from which the
    /// run has not yet been certified inside Goal) and chooses ε_fit (§6.2, modification 1): with ε̄ the
    /// largest rounding bound of the evaluator over the data, ε_fit (2-norm ε_fit·√m) is the largest value
    /// with r_crit(A + BK, ε_fit√m + ε̄) ≤ `rcrit_fraction` · min_i ρ_i, using that r_crit (3.87) is linear
    /// in the disturbance bound.
    pub fn new(task: &Task, syn: &Synthesis, settings: PwaSettings) -> Result<Self, PwaError> {
        settings.validate()?;
        let (n, m) = (syn.K.ncols(), syn.K.nrows());
        let roots = PdRoots::new(syn.P.as_ref()).ok_or(PwaError::MetricNotPd)?;
        let axis: Vec<f64> = (0..n).map(|j| roots.inv[(j, j)].max(0.0).sqrt()).collect();
        let unsafe_set = task.property.unsafe_region();
        let model = task.plant.error_dynamics(0);
        let metric = crate::geometry::Metric {
            n,
            R: crate::linalg::to_row_major(syn.P.as_ref()),
        };
        let intersample = task.plant.continuous(0).map(|cp| InterSample {
            Ac: cp.A.clone(),
            Bc: cp.B.clone(),
            phi: syn.constants.phi,
            beta: syn.constants.beta,
        });
        let mut points = Vec::new();
        for (i, t) in syn.trajectories.iter().enumerate() {
            let c = &t.certificate;
            if !c.is_certified() {
                continue;
            }
            for k in 0..c.k_star.min(t.nominal.v.len()) {
                let x = &t.nominal.x[k];
                let unsafe_dist =
                    unsafe_set.map_or(f64::INFINITY, |us| -us.signed_dist(x, &metric).value);
                let field = task.plant.vector_field(0, x, &t.nominal.u[k]);
                let excursion = match (&field, &intersample) {
                    (Some(f), Some(is)) => is.phi * crate::linalg::p_norm(syn.P.as_ref(), f),
                    _ => 0.0,
                };
                let pieces = match (&field, &intersample, unsafe_set) {
                    (Some(f), Some(is), Some(us)) => crate::certify::pieces::piece_clearances(
                        us,
                        &metric,
                        syn.P.as_ref(),
                        &roots,
                        is.Ac.as_ref(),
                        roots.induced_norm(is.Ac.as_ref()) * (1.0 + 1e-9),
                        task.plant.period(),
                        is.phi,
                        x,
                        f,
                    ),
                    _ => None,
                };
                points.push(DataPoint {
                    pieces,
                    unsafe_dist,
                    excursion,
                    traj: i,
                    to_go: c.k_star - k,
                    kappa: k,
                    x: t.nominal.x[k].clone(),
                    v: t.nominal.v[k].clone(),
                    u: t.nominal.u[k].clone(),
                    delta: c.delta,
                    rho: crate::certify::pwa_ball_radius(syn.P.as_ref(), x, c.delta).ok_or(
                        PwaError::BallTest {
                            traj: i,
                            kappa: k,
                            delta: c.delta,
                        },
                    )? as f64,
                    reach_limit: if k + 1 < c.k_star {
                        crate::certify::pwa_ball_complete_radius(
                            syn.P.as_ref(),
                            &t.nominal.x[k + 1],
                            c.delta,
                        )
                    } else {
                        c.delta
                    },
                });
            }
        }
        if points.is_empty() {
            return Err(PwaError::NoData);
        }
        let At = &model.A + &model.B * &syn.K;
        let rc1 = crate::caf::r_crit(At.as_ref(), syn.P.as_ref(), model.B.as_ref(), 1.0)
            .map_err(PwaError::RCrit)?
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
        let norm_B = roots.norm_into(model.B.as_ref());
        // Modification 1 of §6.2. For a law with ‖Ã_j‖_P ≤ q the invariant radius of (3.83)–(3.87) is about
        // ‖P^{1/2}B‖ε/(1 − q); asking it below f·ρ_min with q = √(1 − s) ≤ 1 − s/2 gives
        // ε ≤ f ρ_min s / (2‖P^{1/2}B‖). For K itself (s = s_K) the exact r_crit of (3.87) is used instead.
        let nK = roots.induced_norm(At.as_ref());
        let s_K = 1.0 - nK * nK;
        let f = settings.rcrit_fraction;
        let (eps2, s_req) = match settings.contraction {
            Some(s) if s > s_K => (f * rho_min * s / (2.0 * norm_B), s),
            _ => (f * rho_min / rc1, s_K),
        };
        // Leave out of the budget what the f32 ball test costs the one-step inclusion (6.5), the largest
        // gap between a ball's stored radius and the radius its successor provably accepts, or the
        // reserve of the settings if that is larger.
        let gap = points
            .iter()
            .map(|p| (p.rho - p.reach_limit).max(0.0))
            .fold(0.0f64, f64::max);
        let eps2 = eps2 - gap.max(settings.fit_reserve * rho_min) / norm_B;
        let eps_fit = ((eps2 - 2.0 * eps_round) / (m as f64).sqrt()).max(0.0);
        Ok(Self {
            terminal: syn.terminal.design().map(|d| d.stored.clone()),
            n,
            m,
            A: model.A.clone(),
            B: model.B.clone(),
            K: syn.K.clone(),
            P: syn.P.clone(),
            roots,
            norm_B,
            axis,
            input: task.property.input.clone(),
            intersample,
            points,
            eps_fit,
            s_req,
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
    /// γ_j = 1 + φ(h)‖A_c + B_c K_j‖_P (1 for discrete plants; module doc, "Between samples").
    pub gamma_is: f64,
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
        let gamma_is = match &ctx.intersample {
            None => 1.0,
            Some(is) => {
                let Acl = &is.Ac + &is.Bc * &gain;
                1.0 + is.phi * ctx.roots.induced_norm(Acl.as_ref())
            }
        };
        Self {
            gain,
            offset,
            At,
            sigma,
            norm_At,
            rcrit_unit,
            gamma_is,
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
    /// dist_P(x̃, Unsafe) − (γ_j δ_i + φ‖f̃‖_P + φβε̄): Unsafe clearance between samples (> 0 required).
    pub clearance: f64,
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
    let (phi, beta) = ctx
        .intersample
        .as_ref()
        .map_or((0.0, 0.0), |is| (is.phi, is.beta));
    // A run deviates from the nominal's held flow by at most w = γ_j δ_i + φβε̄ over the period.
    let w = law.gamma_is * p.delta + phi * beta * eps;
    let isotropic = p.unsafe_dist - (w + p.excursion);
    let directional = p.pieces.as_ref().map_or(f64::NEG_INFINITY, |v| {
        crate::certify::pieces::least_clearance(v, w)
    });
    let clearance = isotropic.max(directional);
    let ok = law.sigma > 0.0
        && r_crit < p.rho
        && reach <= p.reach_limit
        && input_dist >= p.delta
        && clearance > 0.0;
    PointCheck {
        fit_err,
        eps,
        sigma: law.sigma,
        r_crit,
        reach,
        input_dist,
        clearance,
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
    task: &Task,
    syn: &Synthesis,
    settings: &PwaSettings,
) -> Result<PwaController, PwaError> {
    let t0 = std::time::Instant::now();
    let ctx = PwaContext::new(task, syn, settings.clone())?;
    let (laws, assignment) = learn_laws(&ctx);
    let learn_seconds = t0.elapsed().as_secs_f64();
    build_pwa(task, ctx, laws, assignment, learn_seconds)
}

/// The second half of [`learn_pwa`]: the admissible laws of every ball, the tree (§6.3) and the image, for
/// laws already learned.
pub fn build_pwa(
    task: &Task,
    ctx: PwaContext,
    laws: Vec<LearnedLaw>,
    assignment: Vec<usize>,
    learn_seconds: f64,
) -> Result<PwaController, PwaError> {
    let t1 = std::time::Instant::now();
    let stored: Vec<&StoredLaw> = laws.iter().map(|l| &l.stored).collect();
    let admissible: Vec<Vec<usize>> = (0..ctx.points.len())
        .map(|k| {
            (0..laws.len())
                .filter(|&j| j == assignment[k] || check_point(&ctx, stored[j], k).ok)
                .collect()
        })
        .collect();
    let (mut builder, stats) =
        build_image(&ctx, &laws, &assignment, &admissible).map_err(|e| match e {
            PwaError::Capacity { exceeded, .. } => PwaError::Capacity {
                exceeded,
                learned: Some(LearnedSummary {
                    laws: laws.len(),
                    data_points: ctx.points.len(),
                    learn_seconds,
                    eps_fit: ctx.eps_fit,
                }),
            },
            e => e,
        })?;
    builder.period = task.plant.period();
    if let crate::spec::InputSet::Box { lo, hi } = &task.problem.input {
        builder.input_box = Some((lo.clone(), hi.clone()));
    }
    builder.fallback = crate::emit::FallbackLaw::constant(&task.problem.fallback_input);
    builder.fingerprint = Some(task.problem.fingerprint.as_bytes().to_vec());
    builder.terminal_law = ctx.terminal.clone();
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

/// Coverage of Init by the PWA image's envelope (§2.5.2): uniform samples of Init, each counted covered
/// when the image's own f32 point location accepts it (a ball of F, through the tree), with the one-sided
/// Chernoff bounds at the spec's confidence. As many samples as the cover's final estimate
/// ([`crate::cover::estimate::final_samples`]), drawn from their own seeded stream, so a fully accepted
/// sample proves the spec's coverage target for the PWA law itself, not only for the feedforward cover it
/// was learned from (whose balls the image stores with radii rounded down to what its f32 test certifies).
pub fn coverage(
    image: &shared_types::image::Image<'_>,
    problem: &crate::spec::Problem,
) -> crate::cover::estimate::CoverageEstimate {
    use crate::cover::estimate::{estimate, final_samples, SampleBox};
    use rand::SeedableRng;
    let init = SampleBox {
        lo: problem.init.lo.clone(),
        hi: problem.init.hi.clone(),
    };
    let ctl = shared_types::eval::Controller::new(*image);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(problem.seed ^ 0x09a0_c0fe);
    let s = &problem.synthesis;
    estimate(&init, final_samples(s), s.confidence, &mut rng, |x| {
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        matches!(
            ctl.locate(&xf),
            Some(shared_types::pwa::Region::Inside { .. })
        )
    })
}

#[cfg(test)]
mod tests {
    use super::PwaSettings;

    #[test]
    fn the_pwa_builder_refuses_a_depth_beyond_the_image_capacity() {
        let too_deep = shared_types::capacity::MAX_TREE_DEPTH + 1;
        let e = PwaSettings::builder()
            .max_depth(too_deep)
            .build()
            .unwrap_err();
        assert_eq!((e.field, e.value), ("max_depth", too_deep as f64));
        assert!(e.to_string().starts_with("PwaSettings.max_depth = "), "{e}");
        let e = PwaSettings::builder()
            .contraction(Some(1.0))
            .build()
            .unwrap_err();
        assert_eq!(e.field, "contraction");
        assert!(PwaSettings::builder().rcrit_fraction(0.0).build().is_err());
        let s = PwaSettings::builder().thermal_cycles(0).build().unwrap();
        assert_eq!((s.thermal_cycles, s.leaf_balls), (0, 8));
    }
}
