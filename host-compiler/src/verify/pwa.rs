//! Independent re-check of a PWA-feedback image (Ch. 6) from the image bytes and the spec alone: the
//! certificate of every partition recomputed from the stored f32 tables, and closed-loop Monte Carlo from
//! states drawn in the certified envelope F (6.2) through the shared f32 evaluator.
//!
//! # What a PWA run must do (Theorem 6.5)
//! A run starts in a certified ball of F and *terminates upon entering Goal*. It meets the spec when it
//! enters Goal within the horizon, never enters Unsafe (at the samples and at the sub-sample instants of a
//! continuous-time plant), applies only inputs inside the input set, and the evaluator never answers
//! "out of envelope" before Goal. After Goal the run is over: the firmware may then report out of envelope.
//!
//! # The certificate, recomputed (nothing from the learner is trusted)
//! With P the image's metric, K_j, θ0_j the stored law of partition j and (A, B, g) the spec's sampled plant:
//! * **(6.6)** for every partition: σ_j = λ_min(P − Ã_jᵀPÃ_j) > 0 with Ã_j = A + B K_j.
//! * **The f32 ball test**: a ball is (c, ρ) with ρ = √ŝ, ŝ its stored squared threshold; the states the
//!   evaluator accepts in it lie within r = [`crate::certify::pwa_accept_radius`] of c, recomputed from the
//!   stored factor R̂, whitened centre and ŝ (slightly above ρ); r, not ρ, is the radius of the states a law
//!   is applied to below.
//! * **Containment across boundaries** (the hypothesis of Theorem 6.6, what Algorithm 5 repairs): every
//!   stored ball is sent down the tree with the conservative ball–hyperplane test of §6.3, widened by the
//!   rounding of the evaluator's f32 dot product ([`crate::certify::hyperplane_reach`] h: `aᵀc − b ≤ h`
//!   goes left, `≥ −h` goes right); every leaf it reaches must list a ball of the same geometry (centre,
//!   threshold and location), and no branch may reach "outside".
//! * **(6.7) and (6.5)** for every (leaf, ball) pair (c, ρ, law j) and every candidate successor ball b:
//!   the input u* that maps c onto the centre c_b in one step (least squares, residual
//!   res = Ac + g + Bu* − c_b) is the nominal input; the law's deviation from it, ε = ‖K_j c + θ0_j − u*‖
//!   plus the f32 rounding bound, is the bounded disturbance of Theorem 3.21. b is a *successor* when
//!   r̃_crit(Ã_j, ε) < ρ_b (3.83)–(3.87) and ‖Ã_j‖_P r + ‖P^{1/2}B‖ε + ‖res‖_P ≤ r_in,b, the radius within
//!   which ball b's f32 test provably accepts ([`crate::certify::pwa_complete_radius`]): the whole one-step
//!   image is then recognised in b. Alternatively the whole image lies in Goal. Each pair needs one of the
//!   two.
//! * **Goal within T** ([`time_to_go_ranks`]). Invariance alone allows a run to circle in F. The evaluator
//!   applies the law of the first listed ball containing the state, so the recheck looks for ranks τ with
//!   τ = 0 where the image lies in Goal, τ(b) ≥ 1 + τ(some successor), and τ nondecreasing along every
//!   leaf's list. Then if x is handled by b, x⁺ lies in a successor b', the leaf of x⁺ lists b'
//!   (containment), and the first listed ball containing x⁺ has rank ≤ τ(b') ≤ τ(b) − 1: Goal is reached
//!   after at most τ(b) + 1 steps. The least ranks must give at most the horizon's steps. The learner's
//!   order (increasing κ*_i − κ) is one such ranking; the recheck derives its own from the bytes.
//!   With a terminal law (section 11), "Goal" here is the law's handover region H inside Goal, derived
//!   from the section's own bytes ([`crate::certify::terminal::handover_region`]): every run then reaches
//!   a state the f32 handover test accepts within T, and the law (its certificate rechecked apart) keeps
//!   it in Goal from there; the Monte Carlo judges the whole run of 2T ([`super`]'s module doc).
//! * **Input** over every listed ball, and **Unsafe between samples** for continuous plants (the bound of
//!   [`crate::certify`] item 2 with the law's gain, or, where larger, the drift against each convex piece
//!   of Unsafe of `certify::pieces`' module doc, for the centre's held flow and a deviation from it of at
//!   most γ_j r + φβε̄).

use super::{input_slack, Judge, RunOutcome};
use crate::certify::{evaluator_error_bound, input_distance, intersample_phi_beta};
use crate::linalg::{mat_vec, p_norm, sym, sym_eigenvalues, PdRoots};
use faer::Mat;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use shared_types::eval::Controller;
use shared_types::image::Image;
use shared_types::pwa::{Child, Region as Located};

/// The recomputed certificate of one partition (law).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PartitionCheck {
    pub partition: usize,
    /// λ_min(P − Ã_jᵀPÃ_j) of (6.6).
    pub sigma: f64,
    /// Balls listed for this law (over all leaves).
    pub balls: usize,
    /// Largest r̃_crit / ρ_b over its balls (< 1 required, (6.7)).
    pub worst_rcrit_ratio: f64,
    /// Largest one-step reach / ρ_b over its balls (≤ 1 required, (6.5)); 0 when every image lies in Goal.
    pub worst_reach_ratio: f64,
    /// Smallest input-set distance minus ρ over its balls (≥ 0 required).
    pub worst_input_slack: f64,
    /// Smallest Unsafe clearance between samples over its balls (> 0 required).
    pub worst_unsafe_clearance: f64,
    pub ok: bool,
}

/// Everything [`recheck`] found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PwaRecheck {
    pub partitions: Vec<PartitionCheck>,
    /// Stored balls whose descent reached a leaf that does not list them, or "outside".
    pub containment_failures: usize,
    /// Leaf visits checked by the descent.
    pub containment_checks: usize,
    /// Worst-case hyperplane tests of the tree (recomputed by walking it).
    pub depth: usize,
    /// Goal within the horizon, from the time-to-go ranking ([`time_to_go_ranks`]).
    pub liveness: Liveness,
    pub failures: usize,
}

/// Whether every run from F provably reaches Goal within the horizon (module doc, "Goal within T").
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Liveness {
    /// Largest number of steps to Goal the ranking proves, over the listed balls; `None` on failure.
    pub max_steps_to_goal: Option<usize>,
    /// Steps in the spec's horizon.
    pub horizon: usize,
    /// Why no ranking within the horizon exists.
    pub failure: Option<NoRanking>,
}

/// Why the stored balls have no time-to-go ranking within the horizon ([`time_to_go_ranks`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NoRanking {
    /// The ball's one-step image has neither of the two ways to make progress.
    #[error(
        "ball {ball}: its law's one-step image neither lies in Goal nor provably lands in a listed ball"
    )]
    NoSuccessor { ball: usize },
    /// The least ranking exceeds `cap` (the horizon's steps less one) at this ball.
    #[error(
        "ball {ball}: no time-to-go ranking within {cap} steps: its successors and the order of \
         the leaves that list it give no bound on the steps to Goal within the horizon"
    )]
    BeyondHorizon { ball: usize, cap: usize },
}

// The JSON output (`verify --json`, the report) keeps the sentence people read.
impl serde::Serialize for NoRanking {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// Why an image cannot be rechecked at all (bad input, as opposed to a failed check).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RecheckError {
    #[error("the image's P is not positive definite")]
    MetricNotPd,
    #[error("BᵀB is singular: B has no full column rank")]
    InputMatrixRankDeficient,
}

impl Liveness {
    /// One line for people: the proved bound against the horizon, or why there is none.
    pub fn describe(&self) -> String {
        match (&self.failure, self.max_steps_to_goal) {
            (None, Some(k)) => format!(
                "proved: at most {k} of the horizon's {} steps",
                self.horizon
            ),
            (Some(e), _) => format!("NOT proved: {e}"),
            (None, None) => "NOT proved: no ball is listed".to_string(),
        }
    }
}

/// The least time-to-go ranking τ of the stored balls (module doc, "Goal within T"), or why none is at
/// most `cap`. `goal[b]`: the one-step image of ball b under its law lies in Goal; `succ[b]`: the balls
/// that image provably lands in; `class[b]`: the first ball of b's geometry (centre, threshold, location),
/// since a leaf may list another ball of the same geometry; `leaves`: each leaf's ball list in the order
/// the evaluator scans it. The constraints are τ(b) = 0 if `goal[b]`, else
/// τ(b) ≥ 1 + min over successors b' of max{τ(b'') : b'' listed, class(b'') = class(b')}, and τ
/// nondecreasing along every leaf's list. Kleene iteration from τ = 0 of this monotone system reaches its
/// least solution, or exceeds `cap`.
pub fn time_to_go_ranks(
    goal: &[bool],
    succ: &[Vec<usize>],
    class: &[usize],
    leaves: &[Vec<usize>],
    cap: usize,
) -> Result<Vec<usize>, NoRanking> {
    let nb = goal.len();
    let mut listed = vec![false; nb];
    for &b in leaves.iter().flatten() {
        listed[b] = true;
    }
    let members: Vec<Vec<usize>> = (0..nb)
        .map(|g| (0..nb).filter(|&b| class[b] == g && listed[b]).collect())
        .collect();
    let listed_balls: Vec<usize> = (0..nb).filter(|&b| listed[b]).collect();
    if let Some(&b) = listed_balls
        .iter()
        .find(|&&b| !goal[b] && succ[b].iter().all(|&s| members[class[s]].is_empty()))
    {
        return Err(NoRanking::NoSuccessor { ball: b });
    }
    let mut tau = vec![0usize; nb];
    loop {
        let mut changed = false;
        for &b in &listed_balls {
            let base = if goal[b] {
                0
            } else {
                1 + succ[b]
                    .iter()
                    .filter_map(|&s| members[class[s]].iter().map(|&m| tau[m]).max())
                    .min()
                    .unwrap_or(usize::MAX - 1)
            };
            if base > tau[b] {
                tau[b] = base;
                changed = true;
            }
        }
        for leaf in leaves {
            for w in leaf.windows(2) {
                if tau[w[1]] < tau[w[0]] {
                    tau[w[1]] = tau[w[0]];
                    changed = true;
                }
            }
        }
        if let Some(&b) = listed_balls.iter().find(|&&b| tau[b] > cap) {
            return Err(NoRanking::BeyondHorizon { ball: b, cap });
        }
        if !changed {
            return Ok(tau);
        }
    }
}

/// Recomputes the certificate of every partition of a PWA image (module doc). `judge` gives the plant
/// (its sampled model, and its continuous model for the inter-sample check) and the sets.
pub fn recheck(judge: &Judge<'_>, image: &Image<'_>) -> Result<PwaRecheck, RecheckError> {
    let (n, m) = (image.n(), image.m());
    let model = judge.model();
    let (A, B) = (model.A.as_ref(), model.B.as_ref());
    let continuous = judge.plant.continuous(0);
    let P = sym(Mat::from_fn(n, n, |i, j| image.P(0, i, j) as f64).as_ref());
    let roots = PdRoots::new(P.as_ref()).ok_or(RecheckError::MetricNotPd)?;
    let np = image.n_partitions();
    let nb = image.n_balls();
    let metric = crate::geometry::Metric {
        n,
        R: crate::linalg::to_row_major(P.as_ref()),
    };
    let centre =
        |b: usize| -> Vec<f64> { (0..n).map(|i| image.ball_centre(b, i) as f64).collect() };
    // ρ = √ŝ: the radius of the stored squared threshold.
    let rho = |b: usize| (image.ball_threshold(b) as f64).sqrt();
    let centres: Vec<Vec<f64>> = (0..nb).map(centre).collect();
    // The radius within which every state the f32 ball test accepts lies (about the stored centre, in the
    // image's metric), recomputed from the stored factor, whitened centre and radius: the states the law
    // is applied to. A ball whose data admit no bound makes every check of it fail (∞).
    // Likewise the radius within which every state is accepted (completeness): where a step must land.
    let (r_acc, r_in): (Vec<f64>, Vec<f64>) = (0..nb)
        .map(|b| {
            let l = image.ball_location(b);
            let Pl: Vec<f64> = (0..n * n)
                .map(|i| image.P(l, i / n, i % n) as f64)
                .collect();
            let Pl = crate::linalg::from_row_major(n, n, &Pl);
            let Rh: Vec<f64> = (0..n * n)
                .map(|i| image.factor(l, i / n, i % n) as f64)
                .collect();
            let cz: Vec<f64> = (0..n).map(|i| image.ball_centre_z(b, i) as f64).collect();
            let s = image.ball_threshold(b);
            (
                crate::certify::pwa_accept_radius(Pl.as_ref(), &Rh, &centres[b], &cz, s),
                crate::certify::pwa_complete_radius(Pl.as_ref(), &Rh, &centres[b], &cz, s),
            )
        })
        .unzip();
    let axis: Vec<f64> = (0..n).map(|j| roots.inv[(j, j)].max(0.0).sqrt()).collect();
    let normB = roots.norm_into(B);
    // B⁺ for the nominal input between two centres.
    let BtB = B.transpose() * B;
    let BtB_inv = crate::linalg::sym_fn(sym(BtB.as_ref()).as_ref(), |l| 1.0 / l)
        .ok_or(RecheckError::InputMatrixRankDeficient)?;
    let Bpinv = &BtB_inv * B.transpose();
    let (phi, beta) = continuous.map_or((0.0, 0.0), |cp| {
        intersample_phi_beta(&roots, cp, judge.plant.period())
    });
    let a_norm = continuous.map_or(0.0, |cp| roots.induced_norm(cp.A.as_ref()) * (1.0 + 1e-9));
    // Per law: gain, offset, Ã_j, σ_j, ‖Ã_j‖_P, r̃_crit(ε = 1), γ_j.
    struct Law {
        K: Mat<f64>,
        off: Vec<f64>,
        sigma: f64,
        norm: f64,
        rc1: f64,
        gamma: f64,
    }
    let laws: Vec<Law> = (0..np)
        .map(|j| {
            let K = Mat::from_fn(m, n, |r, c| image.law_gain(j, r, c) as f64);
            let off: Vec<f64> = (0..m).map(|r| image.law_offset(j, r) as f64).collect();
            let At = A + B * &K;
            let M = &P - At.transpose() * &P * &At;
            let sigma = sym_eigenvalues(sym(M.as_ref()).as_ref())
                .and_then(|e| e.first().copied())
                .unwrap_or(f64::NAN);
            let rc1 = crate::caf::r_crit(At.as_ref(), P.as_ref(), B, 1.0)
                .map(|r| r.r_crit)
                .unwrap_or(f64::INFINITY);
            let gamma = continuous.map_or(1.0, |cp| {
                1.0 + phi * roots.induced_norm((&cp.A + &cp.B * &K).as_ref())
            });
            Law {
                norm: roots.induced_norm(At.as_ref()),
                K,
                off,
                sigma,
                rc1,
                gamma,
            }
        })
        .collect();
    // Where a run ends: Goal, or with a terminal law its handover region (module doc).
    let handover = super::handover_target(image);
    let target = handover.as_deref().unwrap_or(judge.goal());
    // (ball, law) pairs, once each. The evaluator applies the law of the ball that holds the state (the
    // ball's partition, not the leaf's: a leaf may list balls of several laws), so that is the law checked.
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for l in 0..image.n_leaves() {
        let (_, len) = image.leaf_refs(l);
        for k in 0..len {
            if let Some(b) = image.leaf_ball(l, k) {
                pairs.push((b, image.ball_partition(b)));
            }
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    struct PairCheck {
        ball: usize,
        law: usize,
        rcrit_ratio: f64,
        reach_ratio: f64,
        input_slack: f64,
        clearance: f64,
        /// The whole one-step image lies in Goal.
        in_goal: bool,
        /// Balls the whole one-step image provably lands in (reach ≤ r_in and r̃_crit < ρ).
        succ: Vec<usize>,
    }
    let checks: Vec<PairCheck> = pairs
        .par_iter()
        .map(|&(b, j)| {
            let L = &laws[j];
            let c = &centres[b];
            let r = r_acc[b];
            let X: Vec<f64> = c.iter().zip(&axis).map(|(x, a)| x.abs() + r * a).collect();
            let round = evaluator_error_bound(L.K.as_ref(), &L.off, &X);
            let eps_round = round.iter().map(|e| e * e).sum::<f64>().sqrt();
            let u: Vec<f64> = mat_vec(L.K.as_ref(), c)
                .iter()
                .zip(&L.off)
                .map(|(a, o)| a + o)
                .collect();
            let free = model.step(c, &vec![0.0; m]);
            // Image of the ball lies in Goal (the handover region with a terminal law)?
            let cplus = model.step(c, &u);
            let r_plus = L.norm * r + normB * eps_round;
            let in_goal = target.signed_dist(&cplus, &metric).value > r_plus;
            let (mut rcrit_ratio, mut reach_ratio) = (f64::INFINITY, f64::INFINITY);
            let mut succ = Vec::new();
            let mut best_valid = false;
            if in_goal {
                rcrit_ratio = 0.0;
                reach_ratio = 0.0;
            } else {
                for (bb, cb) in centres.iter().enumerate() {
                    let rb = rho(bb);
                    // Quick reject: centres farther apart than the budget allows.
                    let d: Vec<f64> = (0..n).map(|i| cplus[i] - cb[i]).collect();
                    if p_norm(P.as_ref(), &d) > 2.0 * rb + r_plus {
                        continue;
                    }
                    let target: Vec<f64> = (0..n).map(|i| cb[i] - free[i]).collect();
                    let ustar = mat_vec(Bpinv.as_ref(), &target);
                    let bu = mat_vec(B, &ustar);
                    let res: Vec<f64> = (0..n).map(|i| bu[i] - target[i]).collect();
                    let fit = u
                        .iter()
                        .zip(&ustar)
                        .map(|(a, s)| (a - s) * (a - s))
                        .sum::<f64>()
                        .sqrt();
                    let eps = fit + eps_round;
                    let reach = L.norm * r + normB * eps + p_norm(P.as_ref(), &res);
                    // The step must land where ball bb provably accepts (r_in, a hair below ρ).
                    let rr = reach / r_in[bb];
                    let rc = L.rc1 * eps / rb;
                    let valid = rr <= 1.0 && rc < 1.0;
                    if valid {
                        succ.push(bb);
                    }
                    // Report the best successor: valid ones first, then the smallest reach.
                    if (valid, -rr) > (best_valid, -reach_ratio) {
                        best_valid = valid;
                        reach_ratio = rr;
                        rcrit_ratio = rc;
                    }
                }
            }
            let input_slack = input_distance(L.K.as_ref(), &roots, &u, judge.input(), &round) - r;
            let clearance = match judge.unsafe_set() {
                None => f64::INFINITY,
                Some(us) => {
                    let d = -us.signed_dist(c, &metric).value;
                    let field = judge.plant.vector_field(0, c, &u);
                    let exc = field.as_ref().map_or(0.0, |f| phi * p_norm(P.as_ref(), f));
                    // A run deviates from the centre's held flow by at most w over the period.
                    let w = L.gamma * r + phi * beta * eps_round;
                    let directional = match (&field, continuous) {
                        (Some(f), Some(cp)) => crate::certify::pieces::piece_clearances(
                            us,
                            &metric,
                            P.as_ref(),
                            &roots,
                            cp.A.as_ref(),
                            a_norm,
                            judge.plant.period(),
                            phi,
                            c,
                            f,
                        )
                        .map_or(f64::NEG_INFINITY, |v| {
                            crate::certify::pieces::least_clearance(&v, w)
                        }),
                        _ => f64::NEG_INFINITY,
                    };
                    (d - (w + exc)).max(directional)
                }
            };
            PairCheck {
                ball: b,
                law: j,
                rcrit_ratio,
                reach_ratio,
                input_slack,
                clearance,
                in_goal,
                succ,
            }
        })
        .collect();
    let mut partitions: Vec<PartitionCheck> = laws
        .iter()
        .enumerate()
        .map(|(j, L)| PartitionCheck {
            partition: j,
            sigma: L.sigma,
            balls: 0,
            worst_rcrit_ratio: 0.0,
            worst_reach_ratio: 0.0,
            worst_input_slack: f64::INFINITY,
            worst_unsafe_clearance: f64::INFINITY,
            ok: true,
        })
        .collect();
    for c in &checks {
        let p = &mut partitions[c.law];
        p.balls += 1;
        p.worst_rcrit_ratio = p.worst_rcrit_ratio.max(c.rcrit_ratio);
        p.worst_reach_ratio = p.worst_reach_ratio.max(c.reach_ratio);
        p.worst_input_slack = p.worst_input_slack.min(c.input_slack);
        p.worst_unsafe_clearance = p.worst_unsafe_clearance.min(c.clearance);
    }
    for p in &mut partitions {
        p.ok = p.sigma > 0.0
            && p.worst_rcrit_ratio < 1.0
            && p.worst_reach_ratio <= 1.0
            && p.worst_input_slack >= 0.0
            && p.worst_unsafe_clearance > 0.0;
    }
    // Balls of one geometry (centre, threshold, location) accept the same states: a leaf that lists any
    // of them lists that ball. `class[b]` is the first ball of b's geometry.
    let same_geometry = |a: usize, b: usize| {
        centres[a] == centres[b]
            && image.ball_threshold(a).to_bits() == image.ball_threshold(b).to_bits()
            && image.ball_location(a) == image.ball_location(b)
    };
    let class: Vec<usize> = (0..nb)
        .map(|b| (0..=b).find(|&a| same_geometry(a, b)).unwrap_or(b))
        .collect();
    // Reaching Goal within the horizon: rank the balls by time to go.
    let mut goal = vec![false; nb];
    let mut succ = vec![Vec::new(); nb];
    for c in &checks {
        goal[c.ball] = c.in_goal;
        succ[c.ball] = c.succ.clone();
    }
    let leaves: Vec<Vec<usize>> = (0..image.n_leaves())
        .map(|l| {
            let (_, len) = image.leaf_refs(l);
            (0..len).filter_map(|k| image.leaf_ball(l, k)).collect()
        })
        .collect();
    let cap = judge.steps.saturating_sub(1);
    let liveness = match time_to_go_ranks(&goal, &succ, &class, &leaves, cap) {
        Ok(tau) => Liveness {
            max_steps_to_goal: checks.iter().map(|c| tau[c.ball] + 1).max(),
            horizon: judge.steps,
            failure: None,
        },
        Err(e) => Liveness {
            max_steps_to_goal: None,
            horizon: judge.steps,
            failure: Some(e),
        },
    };
    // Containment across boundaries: descend every ball.
    let mut containment_failures = 0;
    let mut containment_checks = 0;
    let mut depth = 0;
    for b in 0..nb {
        let c = &centres[b];
        let r = r_acc[b];
        let mut stack = vec![(
            if image.n_nodes() == 0 {
                Child::Leaf(0)
            } else {
                Child::Node(0)
            },
            0usize,
        )];
        let mut failed = false;
        while let Some((ch, d)) = stack.pop() {
            match ch {
                Child::Outside => failed = true,
                Child::Leaf(l) => {
                    containment_checks += 1;
                    depth = depth.max(d);
                    let (_, len) = image.leaf_refs(l as usize);
                    let listed = (0..len)
                        .filter_map(|k| image.leaf_ball(l as usize, k))
                        .any(|bb| class[bb] == class[b]);
                    if !listed {
                        failed = true;
                    }
                }
                Child::Node(i) => {
                    let i = i as usize;
                    let a: Vec<f64> = (0..n).map(|q| image.node_normal(i, q) as f64).collect();
                    let s = a.iter().zip(c).map(|(a, x)| a * x).sum::<f64>()
                        - image.node_offset(i) as f64;
                    let w = crate::certify::hyperplane_reach(&roots, &axis, &a, c, r);
                    let Some((left, right)) = image.node_children(i) else {
                        failed = true;
                        continue;
                    };
                    if s <= w {
                        stack.push((left, d + 1));
                    }
                    if s >= -w {
                        stack.push((right, d + 1));
                    }
                }
            }
        }
        if failed {
            containment_failures += 1;
        }
    }
    let failures = partitions.iter().filter(|p| !p.ok).count()
        + containment_failures
        + liveness.failure.is_some() as usize;
    Ok(PwaRecheck {
        partitions,
        containment_failures,
        containment_checks,
        liveness,
        depth: depth.max(image.tree_depth()),
        failures,
    })
}

/// One closed-loop run of a PWA image from `x0`, terminating upon entering Goal (module doc); with a
/// terminal law it goes on to twice the horizon, and what the run does under that law is judged
/// ([`super::RunOutcome::terminal_violation`]).
pub fn run_pwa(judge: &Judge<'_>, image: &Image<'_>, x0: &[f64]) -> (RunOutcome, Vec<Vec<f64>>) {
    let mut ctl = Controller::new(*image);
    let mut x = x0.to_vec();
    let mut path = vec![x.clone()];
    let mut out = RunOutcome::new(x0);
    let hit = |x: &[f64]| judge.unsafe_set().is_some_and(|us| us.contains(x));
    // After Goal (terminal law only): outside Goal or in Unsafe, a violation (super's module doc).
    let judged = image.terminal_law().is_some();
    let after = |x: &[f64], out: &mut RunOutcome| {
        let outside = !judge.goal().contains(x);
        let unsafe_ = hit(x);
        out.left_goal |= outside;
        out.after_goal_unsafe |= unsafe_;
        out.terminal_violation |= judged && (outside || unsafe_);
    };
    let last = super::run_steps(judge, image);
    out.entered_unsafe |= hit(&x);
    for k in 0..=last {
        if out.goal_step.is_none() && judge.goal().contains(&x) {
            out.reached_goal = true;
            out.goal_step = Some(k);
            if image.terminal_law().is_none() {
                break;
            }
        }
        if k == last || (k >= judge.steps && out.goal_step.is_none()) {
            break;
        }
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let u: Vec<f64> = match ctl.step(&xf) {
            Ok(u) => u.as_slice().iter().map(|&v| v as f64).collect(),
            Err(_) => {
                out.refused(k, judged);
                break;
            }
        };
        out.handed_over |= ctl.in_terminal_phase();
        // The handover happens within the horizon (module doc, "Goal within T").
        if judged && k == judge.steps && out.goal_step.is_some() && !out.handed_over {
            out.not_handed_over = true;
            out.terminal_violation = true;
        }
        let s = input_slack(judge.input(), &u);
        if out.goal_step.is_some() {
            out.after_goal_input_excursion |= s < 0.0;
            out.terminal_violation |= judged && s < 0.0;
            if !super::between_clear(judge, &x, &u, true) {
                judge
                    .plant
                    .between_samples(0, &x, &u, &mut |xs| after(xs, &mut out));
            }
            x = judge.plant.step(0, &x, &u);
            after(&x, &mut out);
        } else {
            out.input_margin = out.input_margin.min(s);
            out.input_violation |= s < 0.0;
            if !super::between_clear(judge, &x, &u, false) {
                judge
                    .plant
                    .between_samples(0, &x, &u, &mut |xs| out.entered_unsafe |= hit(xs));
            }
            x = judge.plant.step(0, &x, &u);
            out.entered_unsafe |= hit(&x);
        }
        path.push(x.clone());
    }
    (out, path)
}

/// Result of a PWA Monte Carlo campaign.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PwaMonteCarlo {
    /// Runs from states drawn uniformly in a uniformly chosen stored ball of F.
    pub runs: usize,
    /// Of them, starts in a ball at κ = 0 (the cover of Init) — drawn first, half of the runs.
    pub init_runs: usize,
    /// Drawn starts the evaluator did not accept (at the ball's edge, f32); not counted as runs.
    pub rejected: usize,
    pub violations: usize,
    pub first_violations: Vec<RunOutcome>,
    /// Largest number of steps a run lasted (to Goal; with a terminal law, to twice the horizon).
    pub max_steps: usize,
    /// Largest number of steps a run took to reach Goal.
    pub max_steps_to_goal: usize,
    /// Runs outside Goal again after reaching it, and runs the terminal law took over (images with one;
    /// runs last [`super::run_steps`] samples).
    pub runs_leaving_goal: usize,
    pub handed_over: usize,
    /// After Goal (images with a terminal law, judged: each is a violation): runs that entered Unsafe,
    /// left the input set, or were not handed over within the horizon.
    pub after_goal_unsafe: usize,
    pub after_goal_input_excursions: usize,
    pub not_handed_over: usize,
    /// A few runs (sample paths), for the report.
    pub sample_paths: Vec<Vec<Vec<f64>>>,
}

/// Draws a point uniformly in the P-ball (c, r).
pub fn draw_in_ball(rng: &mut ChaCha8Rng, Pis: &Mat<f64>, c: &[f64], r: f64) -> Vec<f64> {
    let n = c.len();
    let w: Vec<f64> = (0..n)
        .map(|_| rng.sample::<f64, _>(rand_distr::StandardNormal))
        .collect();
    let wn = w.iter().map(|a| a * a).sum::<f64>().sqrt().max(1e-300);
    let rad = r * rng.random::<f64>().powf(1.0 / n as f64);
    let e = mat_vec(Pis.as_ref(), &w);
    (0..n).map(|i| c[i] + rad * e[i] / wn).collect()
}

/// Closed-loop Monte Carlo of a PWA image: `runs` starts, half in the balls whose centre starts a
/// trajectory (`init_centres`: the image does not mark them, the caller passes the cover's x̃_i(0)), half
/// anywhere in F; each drawn uniformly in a uniformly chosen ball (radius less one part in 10⁶).
/// Deterministic for a seed; runs in parallel, collected in order.
pub fn monte_carlo_pwa(
    judge: &Judge<'_>,
    image: &Image<'_>,
    init_centres: &[Vec<f64>],
    runs: usize,
    seed: u64,
    keep_paths: usize,
) -> Result<PwaMonteCarlo, super::MonteCarloError> {
    super::check_runs("runs", runs, super::MAX_RUNS)?;
    let n = image.n();
    let nb = image.n_balls();
    let Pis = super::inverse_sqrt_metric(image)?;
    let centre =
        |b: usize| -> Vec<f64> { (0..n).map(|i| image.ball_centre(b, i) as f64).collect() };
    let init_balls: Vec<usize> = (0..nb)
        .filter(|&b| {
            let c = centre(b);
            init_centres
                .iter()
                .any(|x| x.iter().zip(&c).all(|(a, b)| (*a as f32) as f64 == *b))
        })
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let ctl = Controller::new(*image);
    // Grown as needed: `runs` comes from a flag and may be far more than memory holds.
    let mut starts = Vec::new();
    let mut rejected = 0;
    let mut init_runs = 0;
    let mut draws = 0usize;
    // An image without balls has nothing to draw from (every run would be "not drawn").
    while nb > 0 && starts.len() < runs && draws < runs.saturating_mul(10) {
        draws += 1;
        let from_init = starts.len() < runs / 2 && !init_balls.is_empty();
        let b = if from_init {
            init_balls[rng.random_range(0..init_balls.len())]
        } else {
            rng.random_range(0..nb)
        };
        let x = draw_in_ball(
            &mut rng,
            &Pis,
            &centre(b),
            (image.ball_threshold(b) as f64).sqrt() * (1.0 - 1e-6),
        );
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        match ctl.locate(&xf) {
            Some(Located::Inside { .. }) => {
                init_runs += from_init as usize;
                starts.push(x);
            }
            _ => rejected += 1,
        }
    }
    let outcomes: Vec<(RunOutcome, Vec<Vec<f64>>, usize)> = starts
        .par_iter()
        .enumerate()
        .map(|(i, x0)| {
            let (o, p) = run_pwa(judge, image, x0);
            let steps = p.len() - 1;
            (o, if i < keep_paths { p } else { vec![] }, steps)
        })
        .collect();
    let bad: Vec<&RunOutcome> = outcomes
        .iter()
        .map(|o| &o.0)
        .filter(|o| o.violated() || o.rejected)
        .collect();
    let max_steps = outcomes.iter().map(|o| o.2).max().unwrap_or(0);
    let max_steps_to_goal = outcomes
        .iter()
        .filter_map(|o| o.0.goal_step)
        .max()
        .unwrap_or(0);
    let runs_leaving_goal = outcomes.iter().filter(|o| o.0.left_goal).count();
    let handed_over = outcomes.iter().filter(|o| o.0.handed_over).count();
    let count = |f: fn(&RunOutcome) -> bool| outcomes.iter().filter(|o| f(&o.0)).count();
    Ok(PwaMonteCarlo {
        after_goal_unsafe: count(|o| o.after_goal_unsafe),
        after_goal_input_excursions: count(|o| o.after_goal_input_excursion),
        not_handed_over: count(|o| o.not_handed_over),
        max_steps_to_goal,
        runs_leaving_goal,
        handed_over,
        runs: starts.len(),
        init_runs,
        rejected,
        violations: bad.len(),
        first_violations: bad.into_iter().take(10).cloned().collect(),
        max_steps,
        sample_paths: outcomes.into_iter().take(keep_paths).map(|o| o.1).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::{time_to_go_ranks, NoRanking};

    fn classes(n: usize) -> Vec<usize> {
        (0..n).collect()
    }

    #[test]
    fn a_chain_is_ranked_by_its_steps_to_goal() {
        // 0 → 1 → 2 → Goal, one leaf listing them nearest-Goal first.
        let succ = vec![vec![1], vec![2], vec![]];
        let goal = [false, false, true];
        let leaves = vec![vec![2, 1, 0]];
        let tau = time_to_go_ranks(&goal, &succ, &classes(3), &leaves, 2).unwrap();
        assert_eq!(tau, vec![2, 1, 0]);
        // Three steps do not fit a horizon of two.
        assert!(time_to_go_ranks(&goal, &succ, &classes(3), &leaves, 1).is_err());
    }

    #[test]
    fn the_shortest_successor_counts_and_leaf_order_raises_ranks() {
        // 0 may land in 1 (two steps from Goal) or in 2 (in Goal next): rank 1.
        let succ = vec![vec![1, 2], vec![3], vec![], vec![]];
        let goal = [false, false, true, true];
        let tau = time_to_go_ranks(&goal, &succ, &classes(4), &[vec![2, 0, 3, 1]], 9).unwrap();
        // The leaf lists 0 before 3, so 3 is ranked at least as 0, and 1, which lands in 3, one above.
        assert_eq!(tau, vec![1, 2, 0, 1]);
    }

    #[test]
    fn a_leaf_that_hands_states_back_up_the_chain_has_no_ranking() {
        // 0 → 1 → 2 → Goal, but a leaf lists 0 before 2: a state in both is run with 0's law, so the chain
        // can start over and no bound on the steps to Goal exists.
        let succ = vec![vec![1], vec![2], vec![]];
        let goal = [false, false, true];
        let leaves = vec![vec![0, 2], vec![1]];
        let err = time_to_go_ranks(&goal, &succ, &classes(3), &leaves, 50).unwrap_err();
        assert!(
            matches!(err, NoRanking::BeyondHorizon { cap: 50, .. }),
            "{err:?}"
        );
        assert!(
            err.to_string()
                .contains("no time-to-go ranking within 50 steps"),
            "{err}"
        );
    }

    #[test]
    fn a_successor_of_the_same_geometry_is_ranked_by_its_worst_listed_copy() {
        // Balls 1 and 2 have the same geometry; a leaf may list either, so 0's successor counts as the
        // larger of their ranks.
        let succ = vec![vec![1], vec![], vec![3], vec![]];
        let goal = [false, true, false, true];
        let class = vec![0, 1, 1, 3];
        let leaves = vec![vec![1, 0], vec![3, 2]];
        let tau = time_to_go_ranks(&goal, &succ, &class, &leaves, 9).unwrap();
        assert_eq!(tau, vec![2, 0, 1, 0]);
    }

    #[test]
    fn a_ball_without_successor_or_goal_is_named() {
        let err = time_to_go_ranks(
            &[false, true],
            &[vec![], vec![]],
            &classes(2),
            &[vec![1, 0]],
            9,
        )
        .unwrap_err();
        assert_eq!(err, NoRanking::NoSuccessor { ball: 0 });
        assert!(err.to_string().starts_with("ball 0:"), "{err}");
    }
}
