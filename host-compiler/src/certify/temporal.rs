//! Theorem 4.2 for the sampled f32 loop: the certified radius of a nominal trajectory for an MTL task
//! (Problem 2.28), with the formula's atoms measured in the CAF metric (2.14).
//!
//! Every run from the ball B_P(x̃(0), r) stays in the tube ‖x(κ) − x̃(κ)‖_P ≤ r at the samples (Theorem
//! 3.21: the rounding of the evaluator is a bounded disturbance and r ≥ r_crit) and, between samples,
//! within e_κ(r) = γr + φ‖f_κ‖_P + φβε̄ of x̃(κ) (the inter-sample bound of [`super`], item 2). The formula
//! holds for every such run when
//!
//! 1. **at the samples**: the nominal's robustness in the CAF metric, ρ(0) = ⟦φ⟧(x̃, 0), exceeds r. Every
//!    atom is a signed distance in ‖·‖_P, 1-Lipschitz, and the semantics passes values through min, max
//!    and negation, so a run within r of the nominal at every sample has robustness ≥ ρ(0) − r: the
//!    discrete-time semantics the `mtl` monitor computes on the samples;
//! 2. **in continuous time**: the lower bound of [`crate::robustness::mtl::tube`] with margins (r, e_κ(r))
//!    is positive; it is non-increasing in r, and its root is found by bisection. An atom whose set is a
//!    union of known convex pieces also gets its directional clearance over each interval,
//!    min_j (base_j − slope_j·(γr + φβ(ε̄ + D))) ([`super::pieces`]' module doc, "Between samples along a
//!    direction"), the bound Theorem 4.7's Unsafe piece takes, so Remark 2.29's embedding certifies the
//!    same δ;
//! 3. **inputs**: δ_Input of Theorem 4.7 (4.15) over the whole table, with the rounding margin;
//! 4. r_crit < r (Theorem 3.21).
//!
//! δ_φ is the least of 1–3 (times 1 − 10⁻⁹ for the strict inequalities), stored through the f32
//! selection radius as for reach-avoid. For a discrete-time plant there is nothing between samples and
//! part 2 is skipped.
//!
//! **A plant's sampled-loop mismatch D** (a feedback-linearizable plant's w-channel disturbance,
//! `model::feedback_linearizable`, Theorem 3.21 with a second disturbance). It enters r_crit and the
//! inter-sample margin (`LoopConstants::r_crit`, `held_disturbance`), as for reach-avoid; and, as
//! Theorem 4.7's certificate does, the radius may instead be the tube bound less what the disturbances
//! can add over the table: a run from the δ-ball stays within δ + S_N·(‖P^{1/2}B‖ε̄ + φβD) of the nominal
//! at every sample (‖Ã^j‖_P ≤ 1, `LoopConstants::accumulation`), and parts 1–3 are bounds on that sample
//! deviation (part 2 takes it as its r), so every part holds for δ = min(1–3) − S_N·(…), without r_crit.
//! δ_φ is the larger of the two.

use super::pieces::PieceClearance;
use super::{rounding_over_table, selection_radius, Loop, LoopConstants, Pieces};
use crate::geometry::Metric;
use crate::linalg::p_norm;
use crate::property::{state_signals, TemporalError, TemporalTask};
use crate::robustness::mtl::{Margins, MtlError, NamedSet, Trace, TubeError, TubeFormula};
use crate::trajectory::Nominal;

/// Bisection steps for the continuous-time root (relative precision 2⁻⁶⁰ of ρ(0)).
const BISECTION_STEPS: usize = 60;

/// The formula of a task bound in the CAF metric of a loop.
pub struct TemporalLoop {
    sets: Vec<NamedSet>,
    task_formula: crate::robustness::mtl::Formula,
    signals: Vec<String>,
}

impl TemporalLoop {
    /// The formula bound to the state signals and the sets in the CAF metric.
    pub fn monitor(&self) -> Result<crate::robustness::mtl::Monitor<'_>, TemporalCertifyError> {
        self.task_formula
            .bind(&self.signals, &self.sets)
            .map_err(|e| TemporalCertifyError::Bind(e.to_string()))
    }
    /// The state signal names.
    pub fn signals(&self) -> &[String] {
        &self.signals
    }
    /// The task's sets measured in the loop's CAF metric P.
    pub fn new(task: &TemporalTask, lp: &Loop<'_>) -> Result<Self, TemporalError> {
        let metric = Metric {
            n: lp.P.nrows(),
            R: crate::linalg::to_row_major(lp.P),
        };
        Ok(Self {
            sets: task.sets(&metric)?,
            task_formula: task.formula().clone(),
            signals: state_signals(task.n()),
        })
    }
}

/// The certificate of one trajectory for an MTL task.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TemporalCertificate {
    /// ρ(0) of the nominal in the CAF metric, at the samples (part 1).
    pub delta_samples: f64,
    /// The continuous-time root (part 2; equal to `delta_samples`' bound for discrete-time plants).
    pub delta_continuous: f64,
    /// δ_Input (part 3) and its step.
    pub delta_input: f64,
    pub k_input: usize,
    pub eps_components: Vec<f64>,
    pub eps_f32: f64,
    pub r_crit: f64,
    /// With a sampled-loop mismatch D > 0: S_N·(‖P^{1/2}B‖ε̄ + φβD), how far the disturbances can move a
    /// run from the undisturbed tube over the table (module doc); 0 otherwise.
    pub accumulated: f64,
    /// The certified radius (0 if none) and the radius stored in the image.
    pub delta: f64,
    pub delta_stored: f32,
    /// The nominal's robustness signal ρ(κ) in the CAF metric, at every sample.
    pub signal: Vec<f64>,
    /// Where ρ(0) comes from: the set, the sample, and whether the atom is negated there (the first of
    /// equals).
    pub critical: Option<(String, usize, bool)>,
}

impl TemporalCertificate {
    pub fn is_certified(&self) -> bool {
        self.delta > 0.0 && self.delta_stored > 0.0
    }
    /// A certificate of nothing (the nominal could not be evaluated).
    fn none(m: usize) -> Self {
        Self {
            delta_samples: f64::NAN,
            delta_continuous: f64::NAN,
            delta_input: f64::NAN,
            k_input: 0,
            eps_components: vec![f64::NAN; m],
            eps_f32: f64::NAN,
            r_crit: f64::NAN,
            accumulated: 0.0,
            delta: 0.0,
            delta_stored: 0.0,
            signal: Vec::new(),
            critical: None,
        }
    }
}

/// Why a nominal could not be scored.
#[derive(Debug, thiserror::Error)]
pub enum TemporalCertifyError {
    #[error(transparent)]
    Tube(#[from] TubeError),
    #[error(transparent)]
    Mtl(#[from] Box<MtlError>),
    #[error("the formula does not bind: {0}")]
    Bind(String),
}

/// The nominal as a trace x1 … xn at t = κh.
pub fn nominal_trace(nom: &Nominal, h: f64, signals: &[String]) -> Result<Trace, Box<MtlError>> {
    let n = signals.len();
    let times = (0..nom.x.len()).map(|k| k as f64 * h).collect();
    let cols = (0..n)
        .map(|i| nom.x.iter().map(|x| x[i]).collect())
        .collect();
    Trace::new(times, signals.to_vec(), cols).map_err(|e| Box::new(MtlError::Trace(e)))
}

/// Certify one nominal trajectory (simulated with the shipped K̂, v̂) for the formula (module doc). A
/// nominal that cannot be scored certifies nothing.
pub fn certify_temporal(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    tl: &TemporalLoop,
    nom: &Nominal,
) -> TemporalCertificate {
    try_certify(lp, lc, tl, nom).unwrap_or_else(|_| TemporalCertificate::none(lp.K.nrows()))
}

/// [`certify_temporal`], saying why a nominal could not be scored.
pub fn try_certify(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    tl: &TemporalLoop,
    nom: &Nominal,
) -> Result<TemporalCertificate, TemporalCertifyError> {
    let N = nom.steps();
    let h = lp.plant.period();
    let trace = nominal_trace(nom, h, &tl.signals)?;
    let monitor = tl.monitor()?;
    // The samples' semantics is the monitor's own (the verifier's), on the trace's f64 times; the tube
    // converts window bounds to sample counts to 10⁻⁹ of a period, which can differ from it when a window
    // ends within rounding of a sample.
    let signal = monitor.robustness(&trace).map_err(Box::new)?;
    let tube = TubeFormula::new(&monitor, &trace)?;
    let rho0 = signal[0];
    let critical = tube
        .critical(rho0)
        .first()
        .map(|(s, k, neg)| (s.name.clone(), *k, *neg));
    // Rounding over the table with the tube at its largest possible radius ρ(0).
    let (eps_components, eps_f32) = rounding_over_table(lp, lc, nom, rho0);
    // Inputs (4.15).
    let pc = Pieces::new(lp, lc);
    let (k_input, delta_input) = pc
        .input_values(nom, &eps_components)
        .into_iter()
        .enumerate()
        .fold(
            (0, f64::INFINITY),
            |b, (k, v)| if v < b.1 { (k, v) } else { b },
        );
    // Continuous time: the root of the tube's lower bound in r.
    let delta_continuous = match lp.continuous() {
        None => rho0,
        Some(_) => {
            let c: Vec<f64> = (0..N)
                .map(|k| {
                    let f = lp
                        .plant
                        .vector_field(lp.loc, &nom.x[k], &nom.u[k])
                        .unwrap_or_else(|| vec![f64::INFINITY; nom.x[k].len()]);
                    lc.phi * p_norm(lp.P, &f) + lc.held_disturbance(eps_f32)
                })
                .collect();
            // Each set atom's convex pieces between samples (the directional bound of
            // `certify::pieces`' module doc), where its set is a union of known convex pieces.
            let held = lc.held_disturbance(eps_f32);
            let pieces: Vec<Option<Vec<Option<Vec<PieceClearance>>>>> = tube
                .atom_sets()
                .into_iter()
                .map(|set| {
                    let set = set?;
                    set.region.convex_pieces()?;
                    Some(
                        (0..N)
                            .map(|k| pc.clearances(set.region.as_ref(), nom, k))
                            .collect(),
                    )
                })
                .collect();
            let mut between = vec![0.0; N];
            let mut clear: Vec<Option<Vec<f64>>> = vec![None; pieces.len()];
            let mut positive = |r: f64| {
                for (b, ck) in between.iter_mut().zip(&c) {
                    *b = lc.gamma * r + ck;
                }
                // A run deviates from the nominal's held flow by at most w = γr + held.
                let w = lc.gamma * r + held;
                for (cl, p) in clear.iter_mut().zip(&pieces) {
                    *cl = p
                        .as_ref()
                        .map(|per_k| super::pieces::least_clearances(per_k, std::iter::repeat(w)));
                }
                tube.lower_at_start_with(
                    &Margins {
                        r,
                        between: &between,
                    },
                    &clear,
                ) > 0.0
            };
            if !(rho0 > 0.0) || !positive(0.0) {
                0.0
            } else {
                let (mut lo, mut hi) = (0.0, rho0);
                for _ in 0..BISECTION_STEPS {
                    let mid = 0.5 * (lo + hi);
                    if positive(mid) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                lo
            }
        }
    };
    let r_crit = lc.r_crit(eps_f32);
    let d = rho0.min(delta_continuous).min(delta_input);
    let mut delta = if d > 0.0 && r_crit < d {
        d * (1.0 - 1e-9)
    } else {
        0.0
    };
    // The disturbances summed over the table (module doc): every part bounds the sample deviation, which
    // stays below δ + `accumulated`.
    let mut accumulated = 0.0;
    if lc.mismatch_step() > 0.0 && d > 0.0 {
        let per_step = lc.roots.norm_into(lc.B.as_ref()) * eps_f32 + lc.mismatch_step();
        accumulated = lc.accumulation(N) * per_step * (1.0 + 1e-9);
        delta = delta.max((d - accumulated) * (1.0 - 1e-9));
    }
    Ok(TemporalCertificate {
        delta_samples: rho0,
        delta_continuous,
        delta_input,
        k_input,
        delta_stored: selection_radius(lp.P, &nom.x[0], delta),
        eps_components,
        eps_f32,
        r_crit,
        accumulated,
        delta,
        signal,
        critical,
    })
}
