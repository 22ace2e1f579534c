//! §5.3 for an MTL task: the formula's robustness climbed through its critical atom. The robustness of a
//! nominal at the samples is one atom's signed distance at one sample (the semantics passes values through
//! min, max and negation), so the gradient of that atom at that sample, carried back to v by the adjoint
//! of the loop ([`super::pieces::adjoint`]), is a subgradient of the robustness (the selection (5.29) of
//! §5.3 with the formula's critical time and atom in place of Theorem 4.7's pieces). The input piece
//! (4.15) takes part as for reach-avoid.
//!
//! The ascent is a normalised subgradient method with a step that grows on success and halves on
//! failure; a step is kept only when it raises the objective, and what it returns is re-certified by
//! [`crate::certify::temporal`] from the f32-rounded table, never trusted.

use super::pieces::{adjoint, LocalGrad, Pieces};
use crate::certify::temporal::{
    certify_temporal, nominal_trace, TemporalCertificate, TemporalLoop,
};
use crate::certify::{Loop, LoopConstants};
use crate::robustness::mtl::TubeFormula;
use crate::trajectory::Nominal;
use std::sync::atomic::{AtomicBool, Ordering};

/// The objective the ascent climbs, min(ρ(0), δ_Input) at the samples in the CAF metric (negative for a
/// nominal that violates the formula), and a subgradient with respect to v (module doc): of the atoms
/// that attain the value, the one whose gradient is largest.
pub fn objective_subgradient(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    tl: &TemporalLoop,
    nom: &Nominal,
    eps: &[f64],
) -> Option<(f64, Vec<Vec<f64>>)> {
    let N = nom.steps();
    let trace = nominal_trace(nom, lp.plant.period(), tl.signals()).ok()?;
    let monitor = tl.monitor().ok()?;
    let rho0 = monitor.robustness(&trace).ok()?[0];
    let pc = Pieces::new(lp, lc);
    let di = pc
        .input_values(nom, eps)
        .into_iter()
        .fold(f64::INFINITY, f64::min);
    let m = lp.K.nrows();
    let value = rho0.min(di);
    if !value.is_finite() {
        return None;
    }
    // The pieces active at the value (to a relative 10⁻³): the input piece at its nearest steps, the
    // formula's critical atoms.
    let tol = 1e-3 * value.abs().max(1e-3);
    let mut cands: Vec<LocalGrad> = Vec::new();
    if di <= value + tol {
        let inputs = pc.input_values(nom, eps);
        let mut near: Vec<usize> = (0..inputs.len())
            .filter(|&k| inputs[k] <= value + tol)
            .collect();
        near.sort_by(|&a, &b| inputs[a].total_cmp(&inputs[b]));
        near.truncate(MAX_ACTIVE);
        for k in near {
            cands.push(pc.input_grad(nom, k, eps).1);
        }
    }
    if rho0 <= value + tol {
        let tube = TubeFormula::new(&monitor, &trace).ok()?;
        for (set, k, neg) in tube.critical(rho0).into_iter().take(MAX_ACTIVE) {
            let (_, g) = pc.signed(set.region.as_ref(), &nom.x[k]);
            let s = if neg { -1.0 } else { 1.0 };
            cands.push(LocalGrad {
                k,
                gx: g.iter().map(|v| s * v).collect(),
                gv: vec![0.0; m],
            });
        }
    }
    let grads: Vec<Vec<f64>> = cands
        .iter()
        .map(|c| adjoint(&pc, N, &[(1.0, c)]).concat())
        .collect();
    if grads.is_empty() {
        return None;
    }
    let g = min_norm_combination(&grads);
    Some((value, g.chunks(m).map(|c| c.to_vec()).collect()))
}

/// Active pieces taken into the ascent direction, at most.
const MAX_ACTIVE: usize = 8;

/// The least-norm point of the convex hull of the gradients (Gilbert's algorithm): the steepest ascent
/// direction of a minimum of the pieces they belong to (the Clarke subdifferential's least element).
fn min_norm_combination(g: &[Vec<f64>]) -> Vec<f64> {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut w = g[0].clone();
    for _ in 0..100 {
        // The vertex least aligned with w; stop when none improves.
        let (i, best) = g
            .iter()
            .enumerate()
            .map(|(i, gi)| (i, dot(&w, gi)))
            .fold((0, f64::INFINITY), |b, x| if x.1 < b.1 { x } else { b });
        let ww = dot(&w, &w);
        if ww - best <= 1e-12 * ww.max(1e-300) {
            break;
        }
        // Minimise ‖w + t(g_i − w)‖ over t ∈ [0, 1].
        let d: Vec<f64> = g[i].iter().zip(&w).map(|(a, b)| a - b).collect();
        let dd = dot(&d, &d);
        if !(dd > 0.0) {
            break;
        }
        let t = (-dot(&w, &d) / dd).clamp(0.0, 1.0);
        w.iter_mut().zip(&d).for_each(|(a, b)| *a += t * b);
    }
    w
}

/// The result of [`maximize_temporal`].
#[derive(Clone, Debug)]
pub struct TemporalOptimized {
    /// What ships (f32-rounded v) and its certificate.
    pub nominal: Nominal,
    pub certificate: TemporalCertificate,
    /// The objective min(ρ(0), δ_Input) per accepted step; `[0]` is the start's.
    pub history: Vec<f64>,
    pub iterations: usize,
}

/// Ascent settings: iterations, the first step (RMS change per input component) and the smallest step.
#[derive(Clone, Copy, Debug)]
pub struct AscentSettings {
    pub iterations: usize,
    pub initial_step: f64,
    pub min_step: f64,
}

fn shipped(lp: &Loop<'_>, x0: &[f64], v: &[Vec<f64>]) -> (Vec<Vec<f64>>, Nominal) {
    let v32: Vec<Vec<f64>> = v
        .iter()
        .map(|r| r.iter().map(|&a| a as f32 as f64).collect())
        .collect();
    let nom = lp.simulate(x0, &v32);
    (v32, nom)
}

/// Climb min(ρ(0), δ_Input) over v from `v0` (module doc), then certify the best table.
pub fn maximize_temporal(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    tl: &TemporalLoop,
    x0: &[f64],
    v0: &[Vec<f64>],
    settings: &AscentSettings,
    cancel: &AtomicBool,
) -> TemporalOptimized {
    let (mut v, mut nom) = shipped(lp, x0, v0);
    let mut cert = certify_temporal(lp, lc, tl, &nom);
    let eps = |c: &TemporalCertificate| -> Vec<f64> {
        if c.eps_components.iter().all(|e| e.is_finite()) {
            c.eps_components.clone()
        } else {
            vec![0.0; lp.K.nrows()]
        }
    };
    let mut e = eps(&cert);
    let Some((mut value, mut grad)) = objective_subgradient(lp, lc, tl, &nom, &e) else {
        return TemporalOptimized {
            nominal: nom,
            certificate: cert,
            history: vec![],
            iterations: 0,
        };
    };
    let mut history = vec![value];
    let mut step = settings.initial_step;
    let mut iterations = 0;
    let count = (v.len() * lp.K.nrows()).max(1) as f64;
    while iterations < settings.iterations && step >= settings.min_step {
        if cancel.load(Ordering::Relaxed) {
            break;
        }
        iterations += 1;
        let gn = grad.iter().flatten().map(|g| g * g).sum::<f64>().sqrt();
        if !(gn > 0.0) || !gn.is_finite() {
            break;
        }
        // A move of RMS size `step` per component along the subgradient.
        let scale = step * count.sqrt() / gn;
        let trial: Vec<Vec<f64>> = v
            .iter()
            .zip(&grad)
            .map(|(r, g)| r.iter().zip(g).map(|(a, b)| a + scale * b).collect())
            .collect();
        let (tv, tnom) = shipped(lp, x0, &trial);
        match objective_subgradient(lp, lc, tl, &tnom, &e) {
            Some((tval, tgrad)) if tval > value => {
                v = tv;
                nom = tnom;
                value = tval;
                grad = tgrad;
                history.push(value);
                step *= 1.5;
            }
            _ => step *= 0.5,
        }
        // Refresh the rounding margins now and then (they grow with the tube's radius).
        if iterations % 16 == 0 {
            cert = certify_temporal(lp, lc, tl, &nom);
            e = eps(&cert);
        }
    }
    cert = certify_temporal(lp, lc, tl, &nom);
    TemporalOptimized {
        nominal: nom,
        certificate: cert,
        history,
        iterations,
    }
}
