//! The bounded-error PWA fit of §6.2: a greedy maximum-feasible-subsystem search in the spirit of
//! Bemporad et al. [190], with the three modifications of §6.2.
//!
//! Each cluster is grown from a seed data point s among the points not yet mapped:
//! 1. start from θ_j = 0, θ0_j = ṽ_s (modification 3): A + BK + Bθ_j = A + BK satisfies (6.6)–(6.7) by the
//!    design of K, and the seed is fitted exactly, so every search maps at least one point and the whole
//!    procedure terminates;
//! 2. repeatedly take the unmapped point nearest (in the P-metric) to the cluster; if the current law
//!    already fits it within ε_fit and passes [`super::check_point`], add it; otherwise solve the
//!    bounded-error fit `min ‖θ P^{-1/2}‖²_F  s.t. |θ x̃ + θ0 − ṽ|_∞ ≤ ε_fit` over the cluster and the
//!    candidate, with the LMI (6.6) at the design contraction as a constraint ([`fit`], an SDP in clarabel),
//!    and accept the new law only if every member still passes [`super::check_point`] (modification 2:
//!    every candidate that fits more points is verified with (6.6) and (6.7), recomputed with faer);
//! 3. stop after `max_failures` consecutive rejected candidates.
//!
//! ε_fit is chosen by [`super::PwaContext::new`] so that the disturbance keeps r_crit below the balls'
//! radii (modification 1). Several seeds are tried (multi-start) and the largest verified cluster is kept,
//! which is the maximum-feasible-subsystem criterion of [190] applied to one cluster at a time.
//!
//! From every seed a second search runs: the thermal relaxation of [190] ([`thermal`]). Starting from the
//! same θ_j = 0, θ0_j = ṽ_s, it sweeps the free points in a seeded random order and, for a point whose fit
//! error exceeds ε_fit by d, moves (θ_j, θ0_j) towards it by a step that decays as exp(−d/T) while the
//! temperature T is lowered cycle by cycle, so far-away points (other clusters) stop pulling the law. The
//! law that fits the most free points is verified on them (modification 2) whenever it beats the best
//! verified count, and the largest verified set wins against the greedy cluster of the same seed.

use super::{check_point, PwaContext, StoredLaw};
use crate::caf::sdp::Sdp;
use crate::linalg::mat_vec;
use clarabel::solver::{DefaultSettingsBuilder, SolverStatus};
use faer::Mat;
use rayon::prelude::*;

/// One learned affine law with its cluster of data points.
#[derive(Clone, Debug)]
pub struct LearnedLaw {
    /// θ_j (m×n) and θ0_j as fitted (f64).
    pub theta: Mat<f64>,
    pub theta0: Vec<f64>,
    /// The law as stored, with its (6.6) margin and critical radius.
    pub stored: StoredLaw,
    /// Indices of the data points of the cluster.
    pub members: Vec<usize>,
}

/// Solves the bounded-error fit over `members` (module doc, step 2) as a small SDP: minimise ‖θ‖²_F subject to
/// `|θ x̃_k + θ0 − ṽ_k|_∞ ≤ eps` for every member and the LMI (6.6) with the contraction the learner needs,
/// written in P^{1/2} coordinates: `[[(1 − s)I, Mᵀ], [M, I]] ⪰ 0` with `M = P^{1/2}(A + BK + Bθ)P^{-1/2}`,
/// i.e. `‖Ã_j‖_P ≤ √(1 − s)` (s = `ctx.s_req`). Constraining the search to laws that satisfy (6.6) with
/// margin, instead of fitting first and verifying after, is what lets a law follow a ramping reference
/// (a least-norm fit alone makes Ã_j unstable there). The answer is still verified afterwards
/// ([`super::check_point`]). `None` if infeasible or the solver fails.
pub fn fit(ctx: &PwaContext, members: &[usize], eps: f64) -> Option<(Mat<f64>, Vec<f64>)> {
    let (n, m) = (ctx.n, ctx.m);
    // Well-scaled variables: θ = Θ P^{1/2} and the law's value at the first member x̄,
    // θ x + θ0 = Θ z + w with z = P^{1/2}(x − x̄), w = θ x̄ + θ0. ‖Θ‖ is the input change per unit of P-distance,
    // the quantity the input bound sees.
    let nv = m * (n + 1) + 1; // Θ (row-major), then w, then the contraction s
    let sv = nv - 1;
    let th = |i: usize, j: usize| i * n + j;
    let t0 = |i: usize| m * n + i;
    let xbar = &ctx.points[*members.first()?].x;
    let mut sdp = Sdp::new(nv);
    for v in 0..m * (n + 1) {
        sdp.add_square_cost(v, if v < m * n { 2.0 } else { 1e-6 });
    }
    sdp.add_lower_bound(sv, ctx.s_req);
    sdp.add_linear_cost(sv, -1e-6);
    for &k in members {
        let p = &ctx.points[k];
        let d: Vec<f64> = (0..n).map(|j| p.x[j] - xbar[j]).collect();
        let z = mat_vec(ctx.roots.sqrt.as_ref(), &d);
        for i in 0..m {
            // ±(Θ_i z + w_i − v_i) ≤ eps
            for sgn in [1.0, -1.0] {
                let mut terms: Vec<(usize, f64)> = (0..n).map(|j| (th(i, j), sgn * z[j])).collect();
                terms.push((t0(i), sgn));
                sdp.add_linear_le(&terms, eps + sgn * p.v[i]);
            }
        }
    }
    add_contraction_lmi(&mut sdp, ctx, sv);
    let z = &solve(sdp)?;
    let Theta = Mat::from_fn(m, n, |i, j| z[th(i, j)]);
    let theta = &Theta * &ctx.roots.sqrt;
    let tx = mat_vec(theta.as_ref(), xbar);
    let theta0 = (0..m).map(|i| z[t0(i)] - tx[i]).collect();
    Some((theta, theta0))
}

/// Whether the stored law fits data point `k` within ε_fit and passes [`check_point`] on its ball.
fn verified_at(ctx: &PwaContext, law: &StoredLaw, k: usize) -> bool {
    let c = check_point(ctx, law, k);
    c.ok && c.fit_err <= ctx.eps_fit
}

/// Whether the stored law satisfies (6.6) strictly and [`verified_at`] holds for every member.
fn verified(ctx: &PwaContext, law: &StoredLaw, members: &[usize]) -> bool {
    law.sigma > 0.0 && members.iter().all(|&k| verified_at(ctx, law, k))
}

/// Grows one cluster from `seed` over the points with `free[k]` (module doc).
fn grow(ctx: &PwaContext, free: &[bool], seed: usize) -> LearnedLaw {
    let (n, m) = (ctx.n, ctx.m);
    let mut theta = Mat::<f64>::zeros(m, n);
    let mut theta0 = ctx.points[seed].v.clone();
    let mut stored = StoredLaw::new(ctx, &theta, &theta0);
    let mut members = vec![seed];
    let np = ctx.points.len();
    let dist = |a: usize, b: usize| {
        let d: Vec<f64> = (0..n)
            .map(|j| ctx.points[a].x[j] - ctx.points[b].x[j])
            .collect();
        crate::linalg::p_norm(ctx.P.as_ref(), &d)
    };
    // Distance of every free point to the cluster; excluded once taken or rejected.
    let mut d: Vec<f64> = (0..np)
        .map(|k| {
            if free[k] && k != seed {
                dist(k, seed)
            } else {
                f64::INFINITY
            }
        })
        .collect();
    // Slightly tighter tolerance in the QP, so f32 rounding of the law keeps the fit within ε_fit.
    let eps_qp = ctx.eps_fit * (1.0 - 1e-3);
    let mut failures = 0;
    while failures < ctx.settings.max_failures {
        let Some((c, &dc)) = d.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)) else {
            break;
        };
        if !dc.is_finite() {
            break;
        }
        d[c] = f64::INFINITY;
        let mut trial = members.clone();
        trial.push(c);
        let accepted = if verified(ctx, &stored, &[c]) {
            true
        } else if let Some((t, t0)) = fit(ctx, &trial, eps_qp) {
            let s = StoredLaw::new(ctx, &t, &t0);
            if verified(ctx, &s, &trial) {
                theta = t;
                theta0 = t0;
                stored = s;
                true
            } else {
                false
            }
        } else {
            false
        };
        if accepted {
            members = trial;
            failures = 0;
            for k in 0..np {
                if d[k].is_finite() {
                    d[k] = d[k].min(dist(k, c));
                }
            }
        } else {
            failures += 1;
        }
    }
    members.sort_unstable();
    LearnedLaw {
        theta,
        theta0,
        stored,
        members,
    }
}

/// The thermal-relaxation search of [190] from `seed` over the free points (module doc). Works in the
/// scaled coordinates of [`fit`]: the law's value at x is Θ z + w with z = P^{1/2}(x − x̃_s), so a step
/// along z moves the input by the same amount per unit of P-distance in every direction. Returns the
/// verified law with the most members found, if it has more than the seed alone. Deterministic
/// (`rng_seed`).
fn thermal(ctx: &PwaContext, free: &[bool], seed: usize, rng_seed: u64) -> Option<LearnedLaw> {
    use rand::seq::SliceRandom;
    use rand::SeedableRng;
    let (n, m) = (ctx.n, ctx.m);
    let xbar = &ctx.points[seed].x;
    let pts: Vec<usize> = (0..ctx.points.len()).filter(|&k| free[k]).collect();
    let z: Vec<Vec<f64>> = pts
        .iter()
        .map(|&k| {
            let d: Vec<f64> = (0..n).map(|j| ctx.points[k].x[j] - xbar[j]).collect();
            mat_vec(ctx.roots.sqrt.as_ref(), &d)
        })
        .collect();
    let eps = ctx.eps_fit * (1.0 - 1e-3);
    let mut Theta = vec![vec![0.0f64; n]; m];
    let mut w = ctx.points[seed].v.clone();
    // Initial temperature: the spread of the references around the seed's.
    let t0 = pts
        .iter()
        .map(|&k| {
            (0..m)
                .map(|i| (ctx.points[k].v[i] - w[i]).abs())
                .fold(0.0f64, f64::max)
        })
        .fold(0.0f64, f64::max)
        .max(eps);
    let residual = |Theta: &[Vec<f64>], w: &[f64], q: usize, i: usize| -> f64 {
        let k = pts[q];
        (0..n).map(|j| Theta[i][j] * z[q][j]).sum::<f64>() + w[i] - ctx.points[k].v[i]
    };
    let fitted = |Theta: &[Vec<f64>], w: &[f64]| -> Vec<usize> {
        (0..pts.len())
            .filter(|&q| (0..m).all(|i| residual(Theta, w, q, i).abs() <= eps))
            .map(|q| pts[q])
            .collect()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(rng_seed);
    let mut order: Vec<usize> = (0..pts.len()).collect();
    let mut best: Option<LearnedLaw> = None;
    let mut best_count = 1usize;
    let cycles = ctx.settings.thermal_cycles;
    for c in 0..cycles {
        let temp = t0 * (1.0 - c as f64 / cycles as f64);
        order.shuffle(&mut rng);
        for &q in &order {
            let zn2: f64 = 1.0 + z[q].iter().map(|v| v * v).sum::<f64>();
            for i in 0..m {
                let r = residual(&Theta, &w, q, i);
                let d = r.abs() - eps;
                if d <= 0.0 {
                    continue;
                }
                // Move the law a fraction exp(−d/T) of the way that would fit this point.
                let eta = (-d / temp).exp() * d / zn2;
                let sg = r.signum();
                for j in 0..n {
                    Theta[i][j] -= eta * sg * z[q][j];
                }
                w[i] -= eta * sg;
            }
        }
        let members = fitted(&Theta, &w);
        if members.len() <= best_count {
            continue;
        }
        // The relaxation ignores (6.6); the points it fits are handed to the constrained fit of [`fit`]
        // (the LMI at the design contraction), whose law is then verified on them (modification 2).
        let Some((theta, theta0)) = fit(ctx, &members, eps) else {
            continue;
        };
        let stored = StoredLaw::new(ctx, &theta, &theta0);
        let ok: Vec<usize> = members
            .iter()
            .copied()
            .filter(|&k| verified_at(ctx, &stored, k))
            .collect();
        if stored.sigma > 0.0 && ok.len() > best_count {
            best_count = ok.len();
            best = Some(LearnedLaw {
                theta,
                theta0,
                stored,
                members: ok,
            });
        }
    }
    best
}

/// Learns laws until every data point is mapped (§6.2). Returns the laws (index = partition) and the law of
/// each data point. Deterministic.
pub fn learn_laws(ctx: &PwaContext) -> (Vec<LearnedLaw>, Vec<usize>) {
    let np = ctx.points.len();
    let mut free = vec![true; np];
    let mut assignment = vec![usize::MAX; np];
    let mut laws = Vec::new();
    let bar = if ctx.settings.progress {
        indicatif::ProgressBar::new(np as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    loop {
        let unmapped: Vec<usize> = (0..np).filter(|&k| free[k]).collect();
        if unmapped.is_empty() {
            break;
        }
        // Seeds spread evenly over the unmapped points (data order: trajectory, then time).
        // The seeds' searches are independent and run in parallel; their results are compared in seed
        // order, so the laws do not depend on the thread count.
        let s = ctx.settings.seeds.max(1).min(unmapped.len());
        let found: Vec<(LearnedLaw, Option<LearnedLaw>)> = (0..s)
            .into_par_iter()
            .map(|q| {
                let seed = unmapped[q * unmapped.len() / s];
                let greedy = grow(ctx, &free, seed);
                let relaxed = (ctx.settings.thermal_cycles > 0)
                    .then(|| thermal(ctx, &free, seed, laws.len() as u64 * 1_000 + q as u64))
                    .flatten();
                (greedy, relaxed)
            })
            .collect();
        let mut best: Option<LearnedLaw> = None;
        for (greedy, relaxed) in found {
            for c in std::iter::once(greedy).chain(relaxed) {
                if best
                    .as_ref()
                    .is_none_or(|b| c.members.len() > b.members.len())
                {
                    best = Some(c);
                }
            }
        }
        let Some(best) = best else { break };
        for &k in &best.members {
            free[k] = false;
            assignment[k] = laws.len();
        }
        bar.inc(best.members.len() as u64);
        laws.push(best);
    }
    bar.finish_and_clear();
    (laws, assignment)
}

/// The largest contraction s any law can have in the CAF metric: max s s.t. ‖A + BK + Bθ‖_P ≤ √(1 − s) over
/// all θ (the LMI of [`fit`] without data). Bounds how large the fitting tolerance of modification 1 can be.
pub fn max_contraction(ctx: &PwaContext) -> Option<f64> {
    let (n, m) = (ctx.n, ctx.m);
    let nv = m * n + 1;
    let sv = m * n;
    let mut sdp = Sdp::new(nv);
    sdp.add_linear_cost(sv, -1.0);
    for v in 0..m * n {
        sdp.add_square_cost(v, 1e-6);
    }
    add_contraction_lmi(&mut sdp, ctx, sv);
    Some(solve(sdp)?[sv])
}

/// The LMI (6.6) with margin s in P^{1/2} coordinates, `[[(1 − s)I, Mᵀ], [M, I]] ⪰ 0` with
/// `M = P^{1/2}(A + BK)P^{-1/2} + P^{1/2}BΘ`, for Θ stored row-major in variables 0..m·n and s in `sv`.
fn add_contraction_lmi(sdp: &mut Sdp, ctx: &PwaContext, sv: usize) {
    let (n, m) = (ctx.n, ctx.m);
    let Ms = &ctx.roots.sqrt * (&ctx.A + &ctx.B * &ctx.K) * &ctx.roots.inv_sqrt;
    let SB = &ctx.roots.sqrt * &ctx.B;
    let F0 = Mat::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
        (true, true) | (false, false) => (i == j) as u8 as f64,
        (false, true) => Ms[(i - n, j)],
        (true, false) => Ms[(j - n, i)],
    });
    sdp.add_lmi(&F0, |x| {
        let Theta = Mat::from_fn(m, n, |i, j| x[i * n + j]);
        let D = &SB * Theta;
        Mat::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
            (true, true) => -((i == j) as u8 as f64) * x[sv],
            (false, true) => D[(i - n, j)],
            (true, false) => D[(j - n, i)],
            _ => 0.0,
        })
    });
}

/// Solves with clarabel; the primal solution when solved (or almost), else `None`.
fn solve(sdp: Sdp) -> Option<Vec<f64>> {
    let st = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(200)
        .build()
        .ok()?;
    let r = sdp.solve(st).ok()?;
    match r.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => Some(r.x),
        _ => None,
    }
}
