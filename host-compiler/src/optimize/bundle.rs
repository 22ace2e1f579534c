//! Direct maximisation of the certified robustness δ(0) (§5.3) by a proximal bundle method for nonconvex,
//! nonsmooth functions, with the terminal step as a discrete outer variable.
//!
//! We minimise f(z) = −min(δ_Goal, δ_Unsafe, δ_Input) of the *shipped* nominal (v rounded to f32, f32 gain,
//! inter-sample and rounding margins: the value [`crate::certify::certify`] takes before r_crit), over
//! z = v(0..N). A subgradient comes from the critical piece, sample and witness point ((5.27)–(5.29),
//! [`super::pieces::delta_subgradient`]) through the adjoint sweep.
//!
//! **Method.** Around the stability centre ẑ the bundle holds cuts f(ẑ) − α_j + g_jᵀd with linearisation
//! errors α_j = max(|f(ẑ) − ℓ_j(ẑ)|, γ s_j²) (s_j a bound on the distance from ẑ to where the cut was taken;
//! the γs² term and the absolute value are the usual safeguards for nonconvex f). The proximal subproblem
//! min_d max_j(−α_j + g_jᵀd) + ‖d‖²/(2t) is solved in its dual form, a QP on the unit simplex of the bundle
//! weights λ: min ½ t‖Σλ_j g_j‖² + Σλ_j α_j — small (one variable per cut), solved by clarabel. Then
//! d = −t Σλ_j g_j and the predicted decrease is t‖ĝ‖² + α̂. A trial point that achieves a fraction of the
//! prediction is a serious step (the centre moves, t may grow); otherwise a null step adds its cut (and t
//! shrinks when the trial reveals nonconvexity or nulls repeat). When the bundle is full the cuts with zero
//! weight are dropped and the rest replaced by their aggregate (Σλ_j g_j, Σλ_j ℓ_j, Σλ_j s_j).
//!
//! The text uses the limited-memory bundle method; the proximal bundle method with a QP subproblem is the
//! other option the issue names, chosen because clarabel (already a dependency) solves its subproblem.
//!
//! Input bounds are not constraints of the subproblem: δ_Input is one of the pieces, so any trial that
//! violates them has a worse f and is never a serious step. Every iterate is the shipped nominal and the
//! returned one is re-certified; only certified improvements are kept.

use super::pieces::{delta_subgradient, Pieces};
use super::potential::{descend, DescentMethod, PotentialSettings};
use super::{BundleSettings, OptStop, Optimized};
use crate::certify::{self, Certificate, Loop, LoopConstants};
use crate::trajectory::hold;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use std::sync::atomic::{AtomicBool, Ordering};

/// One evaluation: the shipped nominal, its certificate, f = −(4.11) before margins, and ∂f.
struct Point {
    v: Vec<Vec<f64>>,
    cert: Certificate,
    f: f64,
    g: Vec<f64>,
}

fn d47(c: &Certificate) -> f64 {
    c.delta_goal
        .min(c.delta_unsafe_intersample)
        .min(c.delta_input)
}

/// Evaluates the shipped nominal of `v`; with `hold` > 1 the subgradient is projected onto block-constant
/// sequences, so steps keep v block-constant.
fn evaluate(lp: &Loop<'_>, lc: &LoopConstants, x0: &[f64], v: Vec<Vec<f64>>, hold: usize) -> Point {
    let (nom, cert) = certify::shipped(lp, lc, x0, &v);
    let pc = Pieces::new(lp, lc);
    let (_, mut gv) = delta_subgradient(&pc, &nom, &cert.eps_components, cert.eps_f32);
    hold::project(&mut gv, hold);
    let f = -d47(&cert);
    let g = gv.into_iter().flatten().map(|x| -x).collect();
    Point {
        v,
        cert,
        f: if f.is_nan() { f64::INFINITY } else { f },
        g,
    }
}

/// A cut: subgradient g, value of its linearisation at the centre ℓ, distance bound s.
struct Cut {
    g: Vec<f64>,
    lin: f64,
    s: f64,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The dual of the proximal subproblem: min ½ t λᵀGGᵀλ + αᵀλ on the simplex. Returns λ.
fn dual_qp(G: &[&[f64]], alpha: &[f64], t: f64) -> Option<Vec<f64>> {
    let b = G.len();
    if b == 1 {
        return Some(vec![1.0]);
    }
    let (mut PI, mut PJ, mut PV) = (vec![], vec![], vec![]);
    for j in 0..b {
        for i in 0..=j {
            PI.push(i);
            PJ.push(j);
            PV.push(t * dot(G[i], G[j]));
        }
    }
    let Pm = CscMatrix::new_from_triplets(b, b, PI, PJ, PV);
    // Rows: 1ᵀλ = 1 (zero cone), −λ ≤ 0 (nonnegative cone).
    let (mut AI, mut AJ, mut AV) = (vec![], vec![], vec![]);
    for j in 0..b {
        AI.push(0);
        AJ.push(j);
        AV.push(1.0);
        AI.push(1 + j);
        AJ.push(j);
        AV.push(-1.0);
    }
    let Am = CscMatrix::new_from_triplets(b + 1, b, AI, AJ, AV);
    let mut rhs = vec![0.0; b + 1];
    rhs[0] = 1.0;
    let cones = [
        SupportedConeT::ZeroConeT(1),
        SupportedConeT::NonnegativeConeT(b),
    ];
    let st = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(100)
        .build()
        .ok()?;
    let mut solver = DefaultSolver::new(&Pm, alpha, &Am, &rhs, &cones, st).ok()?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {}
        _ => return None,
    }
    let mut l: Vec<f64> = solver.solution.x.iter().map(|x| x.max(0.0)).collect();
    let sum: f64 = l.iter().sum();
    if !(sum > 0.0) {
        return None;
    }
    for x in &mut l {
        *x /= sum;
    }
    Some(l)
}

/// Local downshift weight γ of the linearisation errors.
const GAMMA: f64 = 1e-3;

/// The proximal bundle method at a fixed terminal step, from `start`. Returns the best point (by the
/// certified δ, then by f), the iterations used and why it stopped; pushes the best certified δ per
/// iteration onto `history`.
#[allow(clippy::too_many_arguments)]
fn bundle_run(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    start: Point,
    s: &BundleSettings,
    budget: usize,
    t: &mut f64,
    history: &mut Vec<f64>,
    cancel: &AtomicBool,
) -> (Point, usize, OptStop) {
    let m = lp.K.nrows();
    let mut center = start;
    let mut cuts = vec![Cut {
        g: center.g.clone(),
        lin: center.f,
        s: 0.0,
    }];
    let mut nulls = 0usize;
    let mut it = 0usize;
    let best_delta = |h: &Vec<f64>| h.last().copied().unwrap_or(0.0);
    loop {
        if cancel.load(Ordering::Relaxed) {
            return (center, it, OptStop::Cancelled);
        }
        if it >= budget {
            return (center, it, OptStop::IterationLimit);
        }
        if *t < s.min_step {
            return (center, it, OptStop::NoProgress);
        }
        it += 1;
        let alpha: Vec<f64> = cuts
            .iter()
            .map(|c| (center.f - c.lin).abs().max(GAMMA * c.s * c.s))
            .collect();
        let G: Vec<&[f64]> = cuts.iter().map(|c| c.g.as_slice()).collect();
        let Some(lam) = dual_qp(&G, &alpha, *t) else {
            history.push(best_delta(history).max(center.cert.delta));
            *t *= 0.5;
            continue;
        };
        let dim = center.g.len();
        let mut gh = vec![0.0; dim];
        for (l, c) in lam.iter().zip(&cuts) {
            if *l > 0.0 {
                for (a, b) in gh.iter_mut().zip(&c.g) {
                    *a += l * b;
                }
            }
        }
        let ah: f64 = lam.iter().zip(&alpha).map(|(l, a)| l * a).sum();
        let pred = *t * dot(&gh, &gh) + ah;
        if pred <= s.tolerance {
            history.push(best_delta(history).max(center.cert.delta));
            return (center, it, OptStop::Converged);
        }
        let d: Vec<f64> = gh.iter().map(|x| -*t * x).collect();
        let dn = dot(&d, &d).sqrt();
        let zc: Vec<f64> = center.v.iter().flatten().copied().collect();
        let vt: Vec<Vec<f64>> = zc
            .iter()
            .zip(&d)
            .map(|(a, b)| a + b)
            .collect::<Vec<_>>()
            .chunks(m)
            .map(|c| c.to_vec())
            .collect();
        let trial = evaluate(lp, lc, x0, vt, s.hold);
        // Aggregate when full: keep the cuts with weight, fold them into one aggregate cut.
        if cuts.len() + 1 > s.bundle_size.max(2) {
            let agg = Cut {
                g: gh.clone(),
                lin: lam.iter().zip(&cuts).map(|(l, c)| l * c.lin).sum(),
                s: lam.iter().zip(&cuts).map(|(l, c)| l * c.s).sum(),
            };
            cuts = vec![agg];
        }
        if center.f - trial.f >= s.serious_fraction * pred && trial.f < center.f {
            // Serious step: move the centre by d; the cuts' linearisations and distances follow.
            for c in &mut cuts {
                c.lin += dot(&c.g, &d);
                c.s += dn;
            }
            cuts.push(Cut {
                g: trial.g.clone(),
                lin: trial.f,
                s: 0.0,
            });
            if center.f - trial.f >= 0.5 * pred {
                *t = (*t * 2.0).min(s.max_step);
            }
            nulls = 0;
            center = trial;
            let bd = best_delta(history).max(center.cert.delta);
            history.push(bd);
        } else {
            // Null step: the trial's cut, linearised at the centre.
            let lin = trial.f - dot(&trial.g, &d);
            let nonconvex = lin > center.f;
            cuts.push(Cut {
                g: trial.g,
                lin,
                s: dn,
            });
            nulls += 1;
            if nonconvex || nulls >= 2 {
                *t *= 0.5;
            }
            history.push(best_delta(history).max(center.cert.delta));
        }
    }
}

/// See [`super::maximize_delta`].
pub(super) fn maximize(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    v0: &[Vec<f64>],
    steps_max: usize,
    s: &BundleSettings,
    cancel: &AtomicBool,
) -> Optimized {
    let steps_max = steps_max.max(1);
    let n0 = v0.len().min(steps_max).max(1);
    let mut v_start: Vec<Vec<f64>> = v0[..n0.min(v0.len())].to_vec();
    if v_start.is_empty() {
        v_start.push(vec![0.0; lp.K.nrows()]);
    }
    hold::project(&mut v_start, s.hold);
    let start = evaluate(lp, lc, x0, v_start, s.hold);
    let steps_before = start.v.len();
    let mut history = vec![start.cert.delta];
    let start_v = start.v.clone();
    let start_delta = start.cert.delta;
    let finish = |best: Point, mut history: Vec<f64>, iterations: usize, stop: OptStop| {
        // The answer as shipped, re-certified from scratch; never worse than the start, and the start
        // itself when no iteration ran.
        let v = if iterations == 0 { &start_v } else { &best.v };
        let (mut nominal, mut certificate) = certify::shipped(lp, lc, x0, v);
        if certificate.delta < start_delta {
            (nominal, certificate) = certify::shipped(lp, lc, x0, &start_v);
        }
        if iterations > 0 {
            if let Some(h) = history.last_mut() {
                *h = certificate.delta;
            }
        }
        Optimized {
            steps_after: nominal.steps(),
            nominal,
            certificate,
            history,
            steps_before,
            iterations,
            stop,
        }
    };
    if cancel.load(Ordering::Relaxed) {
        return finish(start, history, 0, OptStop::Cancelled);
    }
    let better = |a: &Point, b: &Point| -> bool {
        // a strictly better than b: certified δ first, then the raw value.
        (a.cert.delta, -a.f) > (b.cert.delta, -b.f)
    };
    let mut best = start;
    // Terminal step (a discrete variable, outside the bundle method): cutting at k* never lowers δ
    // (fewer samples to keep clear of Unsafe and the input bound).
    if s.terminal_time {
        let k = best.cert.k_star.max(1);
        if k < best.v.len() {
            let cand = evaluate(lp, lc, x0, best.v[..k].to_vec(), s.hold);
            if !better(&best, &cand) {
                best = cand;
            }
        }
    }
    let mut iterations = 0usize;
    // Repair an uncertified start with the potentials of §5.2 (one iteration of the count).
    if !best.cert.is_certified() && s.repair_delta > 0.0 && s.max_iterations > 0 {
        let ps = PotentialSettings::builder()
            .delta(s.repair_delta)
            .max_iterations(500)
            .max_evaluations(2000)
            .hold(s.hold)
            .build();
        let repaired = ps
            .ok()
            .and_then(|ps| descend(lp, lc, x0, &best.v, &ps, DescentMethod::Lbfgs).ok());
        if let Some(d) = repaired {
            let cand = evaluate(lp, lc, x0, d.v, s.hold);
            if better(&cand, &best) {
                best = cand;
            }
        }
        iterations += 1;
        history.push(best.cert.delta.max(history[0]));
    }
    let mut t = 0.0f64;
    let stop = loop {
        if t < s.min_step {
            // First step (and after a collapse): a move of initial_step (RMS per input component) along
            // the subgradient.
            let gn = dot(&best.g, &best.g).sqrt();
            let dim = best.g.len().max(1) as f64;
            t = if gn > 0.0 {
                (s.initial_step * dim.sqrt() / gn).clamp(s.min_step, s.max_step)
            } else {
                s.max_step
            };
        }
        let budget = s.max_iterations.saturating_sub(iterations);
        let (p, used, why) = bundle_run(lp, lc, x0, best, s, budget, &mut t, &mut history, cancel);
        iterations += used;
        best = p;
        match why {
            OptStop::Converged | OptStop::NoProgress
                if s.terminal_time && iterations < s.max_iterations =>
            {
                // Longer horizon: a tenth more steps holding the last input, kept if it certifies better.
                let N = best.v.len();
                if N >= steps_max {
                    break why;
                }
                let ext = (N / 10).max(1).min(steps_max - N);
                let mut v = best.v.clone();
                let last = v.last().cloned().unwrap_or_else(|| vec![0.0; lp.K.nrows()]);
                v.extend(std::iter::repeat_n(last, ext));
                let cand = evaluate(lp, lc, x0, v, s.hold);
                if better(&cand, &best) {
                    best = cand;
                    t = 0.0;
                } else {
                    break why;
                }
            }
            other => break other,
        }
    };
    finish(best, history, iterations, stop)
}

#[cfg(test)]
mod tests {
    use super::dual_qp;

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-6)
    }

    #[test]
    fn dual_qp_balances_opposite_subgradients() {
        // 0 ∈ conv{g₁, g₂}: the weights that reach it are (½, ½), so the step is zero (a stationary point).
        let l = dual_qp(&[&[1.0, 0.0], &[-1.0, 0.0]], &[0.0, 0.0], 1.0).unwrap();
        assert!(close(&l, &[0.5, 0.5]), "{l:?}");
    }

    #[test]
    fn dual_qp_picks_the_shortest_combination() {
        // Both point the same way: the shorter one alone.
        let l = dual_qp(&[&[1.0, 0.0], &[2.0, 0.0]], &[0.0, 0.0], 1.0).unwrap();
        assert!(close(&l, &[1.0, 0.0]), "{l:?}");
        // ½‖λ₁e₁ + λ₂e₂‖² + 2λ₁: the linearisation error pushes all weight to the second cut.
        let l = dual_qp(&[&[1.0, 0.0], &[0.0, 1.0]], &[2.0, 0.0], 1.0).unwrap();
        assert!(close(&l, &[0.0, 1.0]), "{l:?}");
        // Without the error the two orthogonal cuts share equally.
        let l = dual_qp(&[&[1.0, 0.0], &[0.0, 1.0]], &[0.0, 0.0], 3.0).unwrap();
        assert!(close(&l, &[0.5, 0.5]), "{l:?}");
    }
}
