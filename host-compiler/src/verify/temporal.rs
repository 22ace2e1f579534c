//! Verification of a feedforward image for an MTL task (Problem 2.28), independent of how it was made:
//!
//! * [`recheck`]: every stored ball radius re-proved from the image bytes and the spec alone — the
//!   nominal re-simulated from the stored centre and table under the stored gain, certified by
//!   [`crate::certify::temporal`] in the stored metric, the radius the bytes certify compared with the
//!   stored one (to [`super::feedforward::tolerance`], the change of metric from P to its f32 rounding);
//! * [`monte_carlo_temporal`]: runs of the closed loop through the shared f32 evaluator on the exact
//!   sampled plant, each judged by the formula *as written* (Euclidean sets, the monitor's semantics)
//!   on its samples and again on the run sampled eight times finer (the plant's states between samples),
//!   and by the input set at every step. A run violates the task when the formula is false on either
//!   sampling (its Boolean semantics: each atom ±1 by set membership, closed sets, so a run on a set's
//!   boundary is in it), an input leaves the input set, or the evaluator refuses a state after accepting
//!   the first. The robustness itself (signed Euclidean distances) is computed on the samples of every
//!   [`super::MARGIN_EVERY`]-th run, for the report;
//! * [`monte_carlo_temporal_fl`]: the same judgement for a feedback-linearizable task's image, run on the
//!   nonlinear plant itself (the image's model programs, the adaptive integrator of `verify::nonlinear`),
//!   leaving the operating region counted as a violation.

use crate::certify::temporal::{certify_temporal, TemporalLoop};
use crate::certify::{selection_radius, CertifyError, Loop, LoopConstants};
use crate::linalg::sym;
use crate::property::{state_signals, TemporalTask};
use crate::robustness::mtl::{NamedSet, Trace};
use crate::task::Task;
use faer::Mat;
use rayon::prelude::*;
use shared_types::eval::Controller;
use shared_types::image::Image;

/// The recomputed certificate of one stored ball.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TemporalCheck {
    pub trajectory: usize,
    pub stored: f32,
    /// The radius the bytes certify.
    pub certified: f32,
    /// With a whitened selection test (section 13): the radius its acceptance is proved within, from the
    /// bytes ([`super::selection_test_radius`]); it must not exceed the certified radius.
    pub selection_test: Option<f64>,
    pub ok: bool,
}

/// Why an image cannot be re-proved at all.
#[derive(Debug, thiserror::Error)]
pub enum TemporalRecheckError {
    #[error(transparent)]
    Certify(#[from] CertifyError),
    #[error("the formula's sets: {0}")]
    Sets(#[from] crate::property::TemporalError),
}

/// Re-proves every stored ball radius of the image (module doc).
pub fn recheck(
    task: &Task,
    tt: &TemporalTask,
    image: &Image<'_>,
) -> Result<Vec<TemporalCheck>, TemporalRecheckError> {
    let (n, m) = (image.n(), image.m());
    let K = Mat::from_fn(m, n, |i, j| image.K(0, i, j) as f64);
    let P = sym(Mat::from_fn(n, n, |i, j| image.P(0, i, j) as f64).as_ref());
    let lp = Loop {
        plant: &*task.plant,
        loc: 0,
        K: K.as_ref(),
        P: P.as_ref(),
        goal: task.property.goal.as_ref(),
        unsafe_set: task.property.unsafe_region(),
        input: &task.property.input,
    };
    let lc = LoopConstants::new(&lp)?;
    let tl = TemporalLoop::new(tt, &lp)?;
    let tol = super::feedforward::tolerance(P.as_ref());
    Ok((0..image.n_trajectories())
        .into_par_iter()
        .map(|t| {
            let x0: Vec<f64> = (0..n).map(|i| image.centre(t, i) as f64).collect();
            let v: Vec<Vec<f64>> = (0..image.trajectory_len(t))
                .map(|k| (0..m).map(|j| image.v(t, k, j) as f64).collect())
                .collect();
            let nom = lp.simulate(&x0, &v);
            let cert = certify_temporal(&lp, &lc, &tl, &nom);
            let stored = image.delta(t);
            let certified = selection_radius(P.as_ref(), &x0, cert.delta);
            let whitened = super::selection_test_radius(image, P.as_ref(), t);
            TemporalCheck {
                trajectory: t,
                stored,
                certified,
                selection_test: whitened,
                ok: cert.delta > 0.0
                    && (stored as f64) <= (certified as f64) * (1.0 + tol)
                    && whitened.is_none_or(|r| r <= cert.delta),
            }
        })
        .collect())
}

/// What the Monte Carlo runs found.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct TemporalReport {
    /// Runs started (the evaluator accepted x(0)).
    pub runs: usize,
    /// Starts the evaluator refused (boundary points outside the f32 selection; not run).
    pub rejected: usize,
    pub violations: usize,
    /// The least robustness (Euclidean signed distances) at the samples over every
    /// [`super::MARGIN_EVERY`]-th run.
    pub min_robustness: f64,
    /// The least input slack over the runs (negative: outside the input set).
    pub min_input_slack: f64,
    pub first_violation: Option<String>,
}

impl TemporalReport {
    fn empty() -> Self {
        Self {
            min_robustness: f64::INFINITY,
            min_input_slack: f64::INFINITY,
            ..Self::default()
        }
    }
    fn merge(&mut self, o: TemporalReport) {
        self.runs += o.runs;
        self.rejected += o.rejected;
        self.violations += o.violations;
        self.min_robustness = self.min_robustness.min(o.min_robustness);
        self.min_input_slack = self.min_input_slack.min(o.min_input_slack);
        if self.first_violation.is_none() {
            self.first_violation = o.first_violation;
        }
    }
}

/// A run's states at the samples and sampled finer (the plant's own states between samples), as it is
/// simulated step by step.
pub struct RunRecord {
    h: f64,
    n: usize,
    /// The states at the samples, row after row (n values each).
    coarse: Vec<f64>,
    /// The instants of the finer trace and its states, row after row: one flat buffer per run rather
    /// than a vector per state (a run at 8× is thousands of states).
    fine_t: Vec<f64>,
    fine: Vec<f64>,
}

impl RunRecord {
    /// A run from `x0` at sample period `h`.
    pub fn new(x0: &[f64], h: f64) -> Self {
        Self {
            h,
            n: x0.len(),
            coarse: x0.to_vec(),
            fine_t: vec![0.0],
            fine: x0.to_vec(),
        }
    }
    /// The sample index of the current period.
    fn period(&self) -> usize {
        self.coarse.len() / self.n.max(1) - 1
    }
    /// One period of the one-location `plant` from `x` under the held input `u`: records the states
    /// between the samples and the next sample, and returns it.
    pub fn step(&mut self, plant: &dyn crate::model::Plant, x: &[f64], u: &[f64]) -> Vec<f64> {
        let k = self.period();
        let first = self.fine_t.len();
        let fine = &mut self.fine;
        let fine_t = &mut self.fine_t;
        plant.between_samples(0, x, u, &mut |xs| {
            fine.extend_from_slice(xs);
            fine_t.push(0.0);
        });
        let parts = self.fine_t.len() - first + 1;
        for (s, t) in self.fine_t[first..].iter_mut().enumerate() {
            *t = (k as f64 + (s + 1) as f64 / parts as f64) * self.h;
        }
        let next = plant.step(0, x, u);
        self.push_sample(&next);
        next
    }
    /// Records a state between samples, `tau` into the current period (a run stepped elsewhere, as
    /// [`super::hybrid`] steps an automaton's flow).
    pub fn push_between(&mut self, tau: f64, x: &[f64]) {
        let k = self.period();
        self.fine_t.push(k as f64 * self.h + tau);
        self.fine.extend_from_slice(x);
    }
    /// Records the next sample's state.
    pub fn push_sample(&mut self, x: &[f64]) {
        let k = self.period() + 1;
        self.coarse.extend_from_slice(x);
        self.fine_t.push(k as f64 * self.h);
        self.fine.extend_from_slice(x);
    }
    /// The run as traces over x1 … xn: at the samples, and sampled finer.
    pub fn traces(&self) -> Result<(Trace, Trace), crate::robustness::mtl::TraceError> {
        let n = self.n;
        let trace = |t: Vec<f64>, rows: &[f64]| {
            let cols = (0..n)
                .map(|i| rows.chunks_exact(n).map(|x| x[i]).collect())
                .collect();
            Trace::new(t, state_signals(n), cols)
        };
        let samples = self.coarse.len() / n.max(1);
        Ok((
            trace(
                (0..samples).map(|k| k as f64 * self.h).collect(),
                &self.coarse,
            )?,
            trace(self.fine_t.clone(), &self.fine)?,
        ))
    }
}

/// The formula as written, over `sets`, at the start of `trace`.
pub fn formula_value(tt: &TemporalTask, sets: &[NamedSet], trace: &Trace) -> Result<f64, String> {
    let m = tt
        .written
        .bind(trace.names(), sets)
        .map_err(|e| e.to_string())?;
    m.robustness(trace).map(|r| r[0]).map_err(|e| e.to_string())
}

/// A set judged by membership alone: its "signed distance" is +1 inside (boundary included), −1 outside,
/// so the robust semantics over such atoms is the formula's Boolean semantics (±1, or ±∞ for constants).
struct Membership(Box<dyn crate::geometry::Region>);

impl crate::geometry::Region for Membership {
    fn dim(&self) -> usize {
        self.0.dim()
    }
    fn contains(&self, x: &[f64]) -> bool {
        self.0.contains(x)
    }
    fn dist(&self, x: &[f64], _: &crate::geometry::Metric) -> crate::geometry::Witness {
        let value = if self.0.contains(x) { 0.0 } else { 1.0 };
        crate::geometry::Witness {
            value,
            point: Vec::new(),
        }
    }
    fn depth(&self, x: &[f64], _: &crate::geometry::Metric) -> crate::geometry::Witness {
        let value = if self.0.contains(x) { 1.0 } else { 0.0 };
        crate::geometry::Witness {
            value,
            point: Vec::new(),
        }
    }
    /// ±1 from one membership test (the default asks `contains` twice: once to choose, once in `depth`).
    fn signed_dist(&self, x: &[f64], _: &crate::geometry::Metric) -> crate::geometry::Witness {
        crate::geometry::Witness {
            value: if self.0.contains(x) { 1.0 } else { -1.0 },
            point: Vec::new(),
        }
    }
    /// The same ±1 for a whole trace, without a witness per sample.
    fn compile(
        &self,
        _: &crate::geometry::Metric,
    ) -> Option<Box<dyn crate::geometry::SignedDistanceFn + '_>> {
        Some(Box::new(MembershipFn(
            self.0.as_ref(),
            crate::geometry::NearbyMembership::new(),
        )))
    }
}

/// [`Membership`] compiled: one membership per point, in trace order, by
/// [`crate::geometry::NearbyMembership`] (no test within the sure radius of an earlier point).
struct MembershipFn<'a>(
    &'a dyn crate::geometry::Region,
    crate::geometry::NearbyMembership,
);

impl crate::geometry::SignedDistanceFn for MembershipFn<'_> {
    fn eval(&mut self, x: &[f64]) -> crate::geometry::Signed {
        crate::geometry::Signed {
            inside: self.1.contains(self.0, x),
            value: 1.0,
        }
    }
}

/// The sets a run is judged with: by membership (every run) and by Euclidean signed distance (reported).
pub struct Judges {
    boolean: Vec<NamedSet>,
    robust: Vec<NamedSet>,
}

/// What one run gave: Boolean verdicts at the samples and sampled finer, the robustness at the samples
/// when it was asked for, the least input slack.
struct Verdict {
    holds: bool,
    holds_fine: bool,
    robustness: Option<f64>,
    slack: f64,
}

/// Which robustness a run computes besides its Boolean verdicts.
#[derive(Clone, Copy)]
enum Robust {
    No,
    /// At the samples (the Monte Carlo's report).
    Samples,
    /// On the run sampled finer (the falsifier's objective).
    Fine,
}

/// One closed-loop run from `x0` judged by the formula (module doc). `None` when the evaluator refuses
/// x0 (the state is outside the certified cover).
fn run(
    task: &Task,
    judges: &Judges,
    tt: &TemporalTask,
    image: &Image<'_>,
    x0: &[f64],
    robust: Robust,
) -> Option<Result<Verdict, String>> {
    let mut rec = RunRecord::new(x0, task.plant.period());
    let mut x = x0.to_vec();
    let mut ctl = Controller::new(*image);
    let mut slack = f64::INFINITY;
    for k in 0..task.steps {
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let u: Vec<f64> = match ctl.step(&xf) {
            Ok(u) => u.as_slice().iter().map(|&v| v as f64).collect(),
            Err(_) if k == 0 => return None,
            Err(e) => {
                return Some(Err(format!(
                    "x0 = {x0:?}: the evaluator refused the state at step {k}: {e}"
                )))
            }
        };
        slack = slack.min(super::input_slack(&task.property.input, &u));
        x = rec.step(&*task.plant, &x, &u);
    }
    let (tc, tf) = match rec.traces() {
        Ok(t) => t,
        Err(e) => return Some(Err(format!("x0 = {x0:?}: {e}"))),
    };
    let judge = |tr: &Trace, sets: &[NamedSet]| formula_value(tt, sets, tr);
    let verdict = (|| -> Result<Verdict, String> {
        Ok(Verdict {
            holds: judge(&tc, &judges.boolean)? > 0.0,
            holds_fine: judge(&tf, &judges.boolean)? > 0.0,
            robustness: match robust {
                Robust::No => None,
                Robust::Samples => Some(judge(&tc, &judges.robust)?),
                Robust::Fine => Some(judge(&tf, &judges.robust)?),
            },
            slack,
        })
    })();
    Some(verdict.map_err(|e| format!("x0 = {x0:?}: {e}")))
}

impl Verdict {
    /// Why the run fails the task, when it does: the formula false on either sampling, or an input
    /// outside the input set.
    fn violation(&self) -> Option<String> {
        (!self.holds || !self.holds_fine || self.slack < 0.0).then(|| {
            format!(
                "the formula is {} at the samples and {} sampled finer; least input slack {:.3e}",
                if self.holds { "true" } else { "FALSE" },
                if self.holds_fine { "true" } else { "FALSE" },
                self.slack
            )
        })
    }
}

impl Judges {
    /// A recorded run judged by the formula as written: whether it holds at the samples and sampled
    /// finer (Boolean semantics), and, when `robust`, its robustness sampled finer (Euclidean signed
    /// distances).
    pub fn judge(
        &self,
        tt: &TemporalTask,
        rec: &RunRecord,
        robust: bool,
    ) -> Result<(bool, bool, Option<f64>), String> {
        let (tc, tf) = rec.traces().map_err(|e| e.to_string())?;
        Ok((
            formula_value(tt, &self.boolean, &tc)? > 0.0,
            formula_value(tt, &self.boolean, &tf)? > 0.0,
            if robust {
                Some(formula_value(tt, &self.robust, &tf)?)
            } else {
                None
            },
        ))
    }

    /// The formula's sets in the Euclidean metric of `n` states, by membership and by distance.
    pub fn new(tt: &TemporalTask, n: usize) -> Result<Self, crate::property::TemporalError> {
        let euclidean = crate::geometry::Metric::euclidean(n);
        Ok(Self {
            boolean: tt
                .sets(&euclidean)?
                .into_iter()
                .map(|s| NamedSet {
                    region: Box::new(Membership(s.region)),
                    ..s
                })
                .collect(),
            robust: tt.sets(&euclidean)?,
        })
    }
}

/// The judge of single runs for the falsifier ([`super::attack::attack_temporal`]): each run is judged
/// exactly as [`monte_carlo_temporal`] judges it, and scored by the formula's robustness (Euclidean
/// signed distances) on the run sampled finer.
pub struct TemporalJudge<'a> {
    task: &'a Task,
    tt: &'a TemporalTask,
    judges: Judges,
}

impl<'a> TemporalJudge<'a> {
    pub fn new(
        task: &'a Task,
        tt: &'a TemporalTask,
    ) -> Result<Self, crate::property::TemporalError> {
        Ok(Self {
            task,
            tt,
            judges: Judges::new(tt, task.plant.n())?,
        })
    }

    /// The run from `x0`: `None` when the evaluator refuses x0, else its robustness sampled finer (−∞
    /// when it cannot be scored) and why it fails the task, when it does.
    pub fn attack_run(&self, image: &Image<'_>, x0: &[f64]) -> Option<(f64, Option<String>)> {
        Some(
            match run(self.task, &self.judges, self.tt, image, x0, Robust::Fine)? {
                Err(why) => (f64::NEG_INFINITY, Some(why)),
                Ok(v) => (v.robustness.unwrap_or(f64::NEG_INFINITY), v.violation()),
            },
        )
    }
}

impl TemporalJudge<'_> {
    /// [`Self::attack_run`] for a feedback-linearizable task: the run from the *plant* state `x0` on the
    /// nonlinear plant, judged as [`monte_carlo_temporal_fl`] judges it, scored by the formula's
    /// robustness on the run sampled finer (ξ, Euclidean). `None` when the evaluator refuses x0.
    pub fn attack_run_fl(&self, image: &Image<'_>, x0: &[f64]) -> Option<(f64, Option<String>)> {
        let Some(maps) = self.task.plant.linearization() else {
            return Some((
                f64::NEG_INFINITY,
                Some("the task's plant is not feedback-linearizable".into()),
            ));
        };
        Some(
            match run_fl(
                self.task,
                maps,
                &self.judges,
                self.tt,
                image,
                x0,
                Robust::Fine,
            )? {
                Err(why) => (f64::NEG_INFINITY, Some(why)),
                Ok(v) => (v.robustness.unwrap_or(f64::NEG_INFINITY), v.violation()),
            },
        )
    }
}

/// Runs from every start (module doc), in parallel, in a fixed order.
pub fn monte_carlo_temporal(
    task: &Task,
    tt: &TemporalTask,
    image: &Image<'_>,
    starts: &[Vec<f64>],
) -> Result<TemporalReport, crate::property::TemporalError> {
    let judges = Judges::new(tt, task.plant.n())?;
    Ok(judge_runs(starts, &|x0, robust| {
        run(task, &judges, tt, image, x0, robust)
    }))
}

/// One closed-loop run of a feedback-linearizable task's image on the nonlinear plant from the plant
/// state `x0` (module doc of [`monte_carlo_temporal_fl`]). `None` when the evaluator refuses x0's ξ.
fn run_fl(
    task: &Task,
    maps: &crate::model::feedback_linearizable::FlMaps,
    judges: &Judges,
    tt: &TemporalTask,
    image: &Image<'_>,
    x0: &[f64],
    robust: Robust,
) -> Option<Result<Verdict, String>> {
    use super::nonlinear::SUBSTEPS;
    let h = maps.plant.period();
    let input = crate::property::input_bound(&maps.input);
    let outside = |x: &[f64]| {
        maps.region.as_ref().is_some_and(|r| {
            x.iter()
                .zip(r.lo.iter().zip(&r.hi))
                .any(|(v, (l, h))| !(l < v && v < h))
        })
    };
    let mut ctl = Controller::new(*image);
    // The controller's own states ζ (a flat plant's dynamic extension; empty otherwise), as the evaluator
    // keeps them: ξ of a plant state is read with them, and between samples with their model
    // (`FlatCoords::zeta_within`), as `verify::nonlinear` reads them.
    let zeta =
        |ctl: &Controller<'_>| -> Vec<f64> { ctl.extension().iter().map(|&v| v as f64).collect() };
    let mut z = zeta(&ctl);
    let mut rec = RunRecord::new(&maps.xi_at(x0, &z), h);
    let mut x = x0.to_vec();
    let mut slack = f64::INFINITY;
    let mut left: Option<(usize, Vec<f64>)> = outside(x0).then(|| (0, x0.to_vec()));
    for k in 0..task.steps {
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let u: Vec<f64> = match ctl.step_plant(&xf) {
            Ok(u) => u.as_slice().iter().map(|&v| v as f64).collect(),
            Err(_) if k == 0 => return None,
            Err(e) => {
                return Some(Err(format!(
                    "x0 = {x0:?}: the evaluator refused the state at step {k}: {e}"
                )))
            }
        };
        slack = slack.min(super::input_slack(&input, &u));
        let z1 = zeta(&ctl);
        let mut i = 0usize;
        let next = maps.plant.flow(&x, &u, h, SUBSTEPS, &mut |xs| {
            i += 1;
            if left.is_none() && outside(xs) {
                left = Some((k, xs.to_vec()));
            }
            let tau = i as f64 * h / SUBSTEPS as f64;
            let zs = match &maps.flat {
                Some(fc) => fc.zeta_within(&z, &z1, h, tau),
                None => Vec::new(),
            };
            rec.push_between(tau, &maps.xi_at(xs, &zs));
        });
        x = match next {
            Ok(x) => x,
            Err(e) => {
                return Some(Err(format!(
                    "x0 = {x0:?}: the plant's flow failed in period {k} ({e})"
                )))
            }
        };
        if left.is_none() && outside(&x) {
            left = Some((k + 1, x.clone()));
        }
        z = z1;
        rec.push_sample(&maps.xi_at(&x, &z));
    }
    if let Some((k, xs)) = left {
        return Some(Err(format!(
            "x0 = {x0:?}: the run leaves the operating region in period {k} (at {xs:?})"
        )));
    }
    Some(
        judges
            .judge(tt, &rec, false)
            .and_then(|(holds, holds_fine, _)| {
                let robustness = match robust {
                    Robust::No => None,
                    Robust::Samples => {
                        let (tc, _) = rec.traces().map_err(|e| e.to_string())?;
                        Some(formula_value(tt, &judges.robust, &tc)?)
                    }
                    Robust::Fine => {
                        let (_, tf) = rec.traces().map_err(|e| e.to_string())?;
                        Some(formula_value(tt, &judges.robust, &tf)?)
                    }
                };
                Ok(Verdict {
                    holds,
                    holds_fine,
                    robustness,
                    slack,
                })
            })
            .map_err(|e| format!("x0 = {x0:?}: {e}")),
    )
}

/// Monte Carlo of a feedback-linearizable task's image for its MTL formula on the nonlinear plant itself
/// (§3.1.2, Theorem 4.2 with the mismatch D; `model::feedback_linearizable`, *MTL tasks*): each start in
/// ξ (`starts`, as [`crate::verify::hybrid::starts_from_image`] draws them) is lifted to a plant state
/// with its zero-dynamics states drawn uniformly in Init (seeded by `seed`; for a flat plant the states
/// that are flat coordinates come from ξ and the others from Init, and the run reads q with ζ0, so its
/// first sample is that plant state's q, whatever ξ it was lifted from); the shared evaluator's
/// `step_plant` maps the state to ξ and w back to u through the image's model programs in f32, the plant
/// is flowed by the adaptive integrator (Dop853, `model::nonlinear`) with
/// [`super::nonlinear::SUBSTEPS`] − 1 states recorded inside every period. A run violates the task when
/// the formula as rewritten into ξ is false on the samples or on the finer sampling (Boolean semantics,
/// as [`monte_carlo_temporal`]), an input leaves the *plant's* input set, the run leaves the operating
/// region (the plant's whole state, zero states included, at the samples and between them), the
/// evaluator refuses a state after accepting the first, or the integrator fails.
pub fn monte_carlo_temporal_fl(
    task: &Task,
    tt: &TemporalTask,
    image: &Image<'_>,
    starts: &[Vec<f64>],
    seed: u64,
) -> Result<TemporalReport, String> {
    use rand::{Rng, SeedableRng};
    let maps = task
        .plant
        .linearization()
        .ok_or("monte_carlo_temporal_fl takes a feedback-linearizable task")?;
    super::nonlinear::check_maps(maps, image)?;
    let judges = Judges::new(tt, task.plant.n()).map_err(|e| e.to_string())?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let init = &maps.init;
    let lifted: Vec<Vec<f64>> = starts
        .iter()
        .map(|xi| {
            let mut x: Vec<f64> = init
                .lo
                .iter()
                .zip(&init.hi)
                .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
                .collect();
            for (j, s) in maps.state_coords() {
                x[s] = xi[j];
            }
            x
        })
        .collect();
    Ok(judge_runs(&lifted, &|x0, robust| {
        run_fl(task, maps, &judges, tt, image, x0, robust)
    }))
}

/// One judged run from a start at the robustness asked (`None`: the evaluator refused the start).
type RunFrom<'a> = dyn Fn(&[f64], Robust) -> Option<Result<Verdict, String>> + Sync + 'a;

/// Every start run by `run` (`None`: the evaluator refused it) in parallel chunks of a fixed order,
/// the robustness recorded on every [`super::MARGIN_EVERY`]th run, merged into one report.
fn judge_runs(starts: &[Vec<f64>], run: &RunFrom<'_>) -> TemporalReport {
    let reports: Vec<TemporalReport> = starts
        .par_chunks(64)
        .enumerate()
        .map(|(c, chunk)| {
            let mut r = TemporalReport::empty();
            for (i, x0) in chunk.iter().enumerate() {
                let robust = if (c * 64 + i) % super::MARGIN_EVERY == 0 {
                    Robust::Samples
                } else {
                    Robust::No
                };
                match run(x0, robust) {
                    None => r.rejected += 1,
                    Some(Err(e)) => {
                        r.runs += 1;
                        r.violations += 1;
                        r.first_violation.get_or_insert(e);
                    }
                    Some(Ok(v)) => {
                        r.runs += 1;
                        if let Some(rho) = v.robustness {
                            r.min_robustness = r.min_robustness.min(rho);
                        }
                        r.min_input_slack = r.min_input_slack.min(v.slack);
                        if let Some(why) = v.violation() {
                            r.violations += 1;
                            r.first_violation
                                .get_or_insert(format!("x0 = {x0:?}: {why}"));
                        }
                    }
                }
            }
            r
        })
        .collect();
    let mut out = TemporalReport::empty();
    for r in reports {
        out.merge(r);
    }
    out
}
