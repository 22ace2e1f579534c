//! Independent re-check of a feedforward image (Algorithm 2) from the image bytes and the spec alone:
//! every stored ball radius is re-proved, as [`super::pwa::recheck`] does for a PWA image's partitions.
//!
//! # What is recomputed (nothing the synthesiser computed is trusted)
//! With K̂ and P̂ the stored f32 gain and metric (widened exactly to f64) and the spec's sampled plant and
//! sets, for every stored trajectory i:
//! * the nominal x̃_i is re-simulated from the stored centre with the stored reference table v̂_i under
//!   K̂ ([`crate::certify::Loop::simulate`]): exactly the loop the firmware runs from the centre;
//! * its certificate is computed by the synthesiser's own code, [`crate::certify::certify`] (Theorem 4.7
//!   at the samples and between them, the f32 rounding of the evaluator as a bounded disturbance,
//!   r_crit), in the metric P̂, with the loop constants ([`crate::certify::LoopConstants`]: the CAF
//!   contraction σ_min(P̂ − ÃᵀP̂Ã) > 0) recomputed from the bytes;
//! * the radius the bytes certify is [`crate::certify::selection_radius`] of that certificate, the
//!   radius whose f32 ball test accepts only states of the certified ball;
//! * with a whitened selection test (section 13, the model-maps step's), the radius its acceptance is
//!   proved within from the stored factor, whitened centre and threshold
//!   ([`crate::certify::pwa_accept_radius`]) must not exceed the recomputed certified radius;
//! * the first sample in Goal, k*, must lie within the spec's horizon.
//!
//! # The metric's rounding
//! The synthesiser certifies in the f64 metric P and stores its f32 rounding P̂, so the recomputed
//! radius differs from the stored one by the change of metric: norms in P and P̂ differ by a factor
//! within √(1 ± u κ) (u = 2⁻²⁴, κ = ‖|P̂|‖₂ / λ_min(P̂)). A stored radius r̂ is accepted up to
//! [`tolerance`] = (n + 2) u κ above the recomputed one r_c = [`crate::certify::selection_radius`] of the
//! recomputed δ, and no further: that is the slack the selection radius keeps below δ. It stores
//! δ·√((1 − γ_{2n+4}κ)(1 − 2u)) less the quantisation term, and √(1 − γ_{2n+4}κ) ≤ 1 − (n + 2)uκ
//! (γ_k = ku/(1 − ku) ≥ ku), so r̂ ≤ r_c·(1 + (n + 2)uκ) ≤ δ·(1 − (n + 2)uκ)(1 + (n + 2)uκ) < δ: an
//! accepted stored radius never exceeds the radius the bytes certify, and the tolerance spends at most
//! the selection radius' own rounding allowance (whose worst case, a relative error of d² near
//! γ_{2n+4}κ in the direction that accepts more, is what it was kept for) on the change of metric,
//! whose effect on δ is of order uκ. Anything more (an image whose radii were enlarged by more than
//! about (n + 2) uκ, a few parts in 10⁶ for the examples' metrics) is refused, naming the trajectory.

use crate::certify::{certify, selection_radius, CertifyError, Loop, LoopConstants, U32};
use crate::linalg::{spectral_norm, sym, sym_eigenvalues};
use faer::Mat;
use rayon::prelude::*;
use shared_types::image::Image;

use super::Judge;

/// The recomputed certificate of one stored trajectory.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TrajectoryCheck {
    pub trajectory: usize,
    /// The radius stored in the image.
    pub stored: f32,
    /// The radius the bytes certify (the stored radius the synthesiser's code gives for them).
    pub certified: f32,
    /// The certified radius before the f32 selection margin (0: the bytes certify no ball at all).
    pub delta: f64,
    /// The sample of greatest Goal depth (Theorem 4.7's k*): the ball is in Goal there.
    pub k_star: usize,
    /// With a whitened selection test (section 13): the radius its acceptance is proved within, from the
    /// bytes ([`super::selection_test_radius`]); it must not exceed `delta`.
    pub selection_test: Option<f64>,
    pub ok: bool,
}

impl TrajectoryCheck {
    /// Why the check failed, for people (`None` when it passed).
    pub fn failure(&self, horizon: usize) -> Option<String> {
        if self.ok {
            return None;
        }
        Some(if self.delta <= 0.0 {
            format!(
                "trajectory {}: its stored table certifies no ball at all (stored radius {:e})",
                self.trajectory, self.stored
            )
        } else if !self.selection_test.is_none_or(|r| r <= self.delta) {
            format!(
                "trajectory {}: its whitened selection test accepts states up to {:e} from the centre, beyond the {:e} its stored table certifies",
                self.trajectory,
                self.selection_test.unwrap_or(f64::NAN),
                self.delta
            )
        } else if self.k_star > horizon {
            format!(
                "trajectory {}: its nominal reaches Goal at step {} (k*), after the horizon's {horizon} steps",
                self.trajectory, self.k_star
            )
        } else {
            format!(
                "trajectory {}: the stored radius {:e} exceeds the {:e} its stored table certifies",
                self.trajectory, self.stored, self.certified
            )
        })
    }
}

/// Everything [`recheck`] found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FeedforwardRecheck {
    /// σ_min(P̂ − ÃᵀP̂Ã) with the stored K̂ and P̂ (Theorem 3.21 needs it > 0).
    pub sigma_min: f64,
    /// Relative excess of a stored radius over the recomputed one still accepted ([`tolerance`]).
    pub tolerance: f64,
    pub trajectories: Vec<TrajectoryCheck>,
    /// Largest stored ÷ certified radius over the trajectories (≤ 1 + tolerance required).
    pub worst_ratio: f64,
    /// Steps in the spec's horizon.
    pub horizon: usize,
    pub failures: usize,
}

/// Why a feedforward image cannot be rechecked at all.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum FeedforwardRecheckError {
    /// The stored K̂ and P̂ do not make a certifiable loop (P̂ not positive definite, or no contraction).
    #[error("the image's gain and metric certify nothing: {0}")]
    Loop(#[from] CertifyError),
    /// A trajectory runs through a location other than 0 (hybrid images are not produced yet).
    #[error(
        "trajectory {trajectory} runs through location {location}; only single-location images are rechecked"
    )]
    Location { trajectory: usize, location: usize },
}

/// The relative tolerance on a stored radius (module doc, "The metric's rounding"): (n + 2) u κ(P̂), the
/// slack [`crate::certify::selection_radius`] keeps below the certified radius.
pub fn tolerance(P: faer::MatRef<'_, f64>) -> f64 {
    let n = P.nrows();
    let absP = Mat::from_fn(n, n, |i, j| P[(i, j)].abs());
    let lmin = sym_eigenvalues(P)
        .and_then(|e| e.first().copied())
        .unwrap_or(0.0);
    if lmin > 0.0 {
        (n as f64 + 2.0) * U32 * spectral_norm(absP.as_ref()) / lmin
    } else {
        0.0
    }
}

/// Re-proves every stored ball radius of a feedforward image (module doc).
pub fn recheck(
    judge: &Judge<'_>,
    image: &Image<'_>,
) -> Result<FeedforwardRecheck, FeedforwardRecheckError> {
    let (n, m) = (image.n(), image.m());
    let K = Mat::from_fn(m, n, |i, j| image.K(0, i, j) as f64);
    let P = sym(Mat::from_fn(n, n, |i, j| image.P(0, i, j) as f64).as_ref());
    // With a terminal law the runs are certified to reach its handover region (verify's module doc).
    let handover = super::handover_target(image);
    let lp = Loop {
        plant: judge.plant,
        loc: 0,
        K: K.as_ref(),
        P: P.as_ref(),
        goal: handover.as_deref().unwrap_or(judge.goal()),
        unsafe_set: judge.property.unsafe_region(),
        input: &judge.property.input,
    };
    for t in 0..image.n_trajectories() {
        let (_, len) = image.trajectory_rows(t);
        if let Some(l) = (0..len).map(|k| image.location(t, k)).find(|&l| l != 0) {
            return Err(FeedforwardRecheckError::Location {
                trajectory: t,
                location: l,
            });
        }
    }
    let lc = LoopConstants::new(&lp)?;
    let tol = tolerance(P.as_ref());
    let horizon = judge.steps;
    let trajectories: Vec<TrajectoryCheck> = (0..image.n_trajectories())
        .into_par_iter()
        .map(|t| {
            let x0: Vec<f64> = (0..n).map(|i| image.centre(t, i) as f64).collect();
            let v: Vec<Vec<f64>> = (0..image.trajectory_len(t))
                .map(|k| (0..m).map(|j| image.v(t, k, j) as f64).collect())
                .collect();
            let nom = lp.simulate(&x0, &v);
            let cert = certify(&lp, &lc, &nom);
            let stored = image.delta(t);
            let certified = selection_radius(P.as_ref(), &x0, cert.delta);
            let whitened = super::selection_test_radius(image, P.as_ref(), t);
            let ok = cert.delta > 0.0
                && cert.k_star <= horizon
                && (stored as f64) <= (certified as f64) * (1.0 + tol)
                && whitened.is_none_or(|r| r <= cert.delta);
            TrajectoryCheck {
                trajectory: t,
                stored,
                certified,
                delta: cert.delta,
                k_star: cert.k_star,
                selection_test: whitened,
                ok,
            }
        })
        .collect();
    let worst_ratio = trajectories
        .iter()
        .map(|c| {
            if c.stored == 0.0 {
                0.0
            } else {
                c.stored as f64 / c.certified as f64
            }
        })
        .fold(0.0, f64::max);
    Ok(FeedforwardRecheck {
        sigma_min: lc.sigma_min,
        tolerance: tol,
        failures: trajectories.iter().filter(|c| !c.ok).count(),
        trajectories,
        worst_ratio,
        horizon,
    })
}
