//! The falsifier (`verify --attack`): an optimisation-based search for the start whose closed-loop run
//! comes closest to failing the task, made without the certificate's reasoning.
//!
//! One search ([`falsify`]) serves every image mode through a [`Target`]: the balls to search, how a
//! start is built from a search point, and how the run from a start is scored. For every ball, starts
//! are parametrised by w ∈ ℝⁿ as x0 = c + s(w)·P^{-1/2}w with s(w) = ρ·min(1, 1/‖w‖) and
//! ρ = (1 + 10⁻⁴)·δ̂ (δ̂ the stored radius): the unit ball of w fills the ball, everything beyond it lands
//! on the shell of radius ρ, a hair outside the stored radius, where the f32 selection test decides (the
//! f32 neighbourhood of the ball). A target may add search coordinates beyond the ball's (the
//! zero-dynamics states of a feedback-linearizable plant, swept over Init). Multi-start Nelder–Mead
//! (argmin) from seeded random w minimises the run's robustness; a start the evaluator refuses scores a
//! large constant (it is outside the cover, not a counterexample). Every run is also judged by the
//! mode's own membership checks, so a violation is reported whether or not the robustness noticed it.
//!
//! The targets, each scoring runs with the task's own semantics on the mode's own run function:
//! * [`attack`] (reach-avoid, feedforward): [`super::run_visiting`] on the exact sampled plant, scored by
//!   [`crate::property::Property`] (Goal within T while avoiding Unsafe, Euclidean);
//! * [`attack_temporal`] (MTL tasks): [`super::temporal::TemporalJudge`], scored by the formula's
//!   robustness on the run sampled finer, judged as `verify`'s MTL Monte Carlo judges it;
//! * [`attack_hybrid`] (hybrid images): [`super::hybrid::run_hybrid`] on the automaton's exact flow,
//!   scored by the reach-avoid robustness of its samples;
//! * [`attack_fl`] (feedback-linearizable plants): [`super::nonlinear::run_fl_visiting`] on the
//!   nonlinear plant, scored by the reach-avoid robustness of its ξ samples;
//! * [`attack_temporal_fl`] (MTL tasks on feedback-linearizable plants): the same starts, each run on the
//!   nonlinear plant judged as `verify`'s FL MTL Monte Carlo judges it and scored by the formula's
//!   robustness on the run sampled finer (`TemporalJudge::attack_run_fl`);
//! * [`attack_pwa`] (PWA images): [`super::pwa::run_pwa`] from every ball of F, scored likewise.

use super::{run_visiting, Judge, RunOutcome};
use crate::property::{Property, ReachAvoid};
use crate::robustness::mtl::Trace;
use crate::settings::{settings_builder, Check, SettingError};
use argmin::core::{CostFunction, Error as ArgminError, Executor};
use argmin::solver::neldermead::NelderMead;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use shared_types::image::Image;
use std::cell::RefCell;
use std::time::Instant;

/// Settings of the falsifier, with documented defaults; build with [`AttackSettings::builder`].
#[derive(Clone, Debug)]
pub struct AttackSettings {
    /// Nelder–Mead starts per ball. ≥ 1. Default 2.
    pub starts_per_ball: usize,
    /// Closed-loop runs per start, at most (the initial simplex included). ≥ n + 2. Default 120.
    pub evaluations_per_start: usize,
    /// Seed of the random starts. Default 0xa77ac.
    pub seed: u64,
}

impl Default for AttackSettings {
    fn default() -> Self {
        Self {
            starts_per_ball: 2,
            evaluations_per_start: 120,
            seed: 0xa77ac,
        }
    }
}

impl AttackSettings {
    /// Checks the ranges documented on the fields (`evaluations_per_start` against n when attacking).
    pub fn validate(&self) -> Result<(), SettingError> {
        let c = Check("AttackSettings");
        c.at_least_one("starts_per_ball", self.starts_per_ball)?;
        c.rule(
            "evaluations_per_start",
            self.evaluations_per_start as f64,
            self.evaluations_per_start >= 3,
            "must be at least n + 2 (the simplex and one step)",
        )
    }
}

settings_builder!(
    AttackSettings,
    AttackSettingsBuilder {
        starts_per_ball: usize,
        evaluations_per_start: usize,
        seed: u64,
    }
);

/// A run that failed the task: its start and what went wrong, in words.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Violation {
    pub x0: Vec<f64>,
    pub what: String,
}

/// What the falsifier found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AttackReport {
    /// Closed-loop runs made.
    pub evaluations: usize,
    pub seconds: f64,
    /// The least robustness of an accepted start's run (Euclidean; > 0: every run found meets the task
    /// with that margin), and that start.
    pub worst_robustness: f64,
    pub worst_start: Vec<f64>,
    /// Runs that failed the task (membership), at most 10 listed, and how many there were.
    pub violations: usize,
    pub first_violations: Vec<Violation>,
}

/// Why the falsifier could not run.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum AttackError {
    #[error(transparent)]
    Settings(#[from] SettingError),
    #[error(transparent)]
    Metric(#[from] super::MetricError),
    #[error(
        "AttackSettings.evaluations_per_start = {got}: this image has n = {n}, so at least {need}"
    )]
    Budget { got: usize, n: usize, need: usize },
    /// The mode's judge could not be built (the formula's sets, the automaton's resampled flow).
    #[error("the falsifier's judge: {0}")]
    Judge(String),
}

/// The score of a start the evaluator refuses (outside the cover).
const REFUSED: f64 = 1e6;

/// A ball of the image as the search sees it: its centre, P^{-1/2} of its metric (row-major n×n) and
/// the search radius ρ (module doc).
#[derive(Clone, Debug)]
pub struct Ball {
    pub centre: Vec<f64>,
    pub pis: Vec<f64>,
    pub reach: f64,
}

impl Ball {
    /// The point of the search coordinates `w` (module doc): inside the ball for ‖w‖ ≤ 1, on the shell
    /// of radius ρ beyond.
    pub fn point(&self, w: &[f64]) -> Vec<f64> {
        let n = self.centre.len();
        let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt();
        let s = if norm > 1.0 {
            self.reach / norm
        } else {
            self.reach
        };
        (0..n)
            .map(|i| self.centre[i] + s * (0..n).map(|j| self.pis[i * n + j] * w[j]).sum::<f64>())
            .collect()
    }
}

/// The balls of a feedforward image (trajectory `t`'s ball in the metric of location 0), or of its F
/// for a PWA image (`pwa`), with the search radius (1 + 10⁻⁴) times the stored one.
fn image_balls(image: &Image<'_>, pwa: bool) -> Result<Vec<Ball>, AttackError> {
    let n = image.n();
    let pis = crate::linalg::to_row_major(super::inverse_sqrt_metric(image)?.as_ref());
    let count = if pwa {
        image.n_balls()
    } else {
        image.n_trajectories()
    };
    Ok((0..count)
        .map(|b| {
            let (centre, radius) = if pwa {
                (
                    (0..n).map(|i| image.ball_centre(b, i) as f64).collect(),
                    (image.ball_threshold(b) as f64).max(0.0).sqrt(),
                )
            } else {
                (
                    (0..n).map(|i| image.centre(b, i) as f64).collect(),
                    image.delta(b) as f64,
                )
            };
            Ball {
                centre,
                pis: pis.clone(),
                reach: radius * (1.0 + 1e-4),
            }
        })
        .collect())
}

/// What the run from one start gave.
#[derive(Clone, Debug, PartialEq)]
pub enum Scored {
    /// The evaluator did not accept the start (outside the cover: not a counterexample).
    Refused,
    /// The run's robustness against the task (> 0: met with that margin; −∞ when the run could not be
    /// scored) and, when it failed the task by the mode's membership checks, why.
    Run {
        robustness: f64,
        violation: Option<String>,
    },
}

impl Scored {
    /// A run the formula's judge scored: `None` when the evaluator refused the start, else its
    /// robustness and violation.
    fn of_judged(run: Option<(f64, Option<String>)>) -> Self {
        match run {
            None => Scored::Refused,
            Some((robustness, violation)) => Scored::Run {
                robustness,
                violation,
            },
        }
    }
}

/// One image mode as the falsifier sees it (module doc).
pub trait Target: Sync {
    /// The balls searched.
    fn balls(&self) -> &[Ball];
    /// Search coordinates beyond the ball's n (default none).
    fn extra_dims(&self) -> usize {
        0
    }
    /// The start for the ball point `p` and the extra search coordinates (each in [−1, 1]); default `p`.
    fn start(&self, p: Vec<f64>, _extra: &[f64]) -> Vec<f64> {
        p
    }
    /// Runs the closed loop from `x0` and scores it.
    fn score(&self, x0: &[f64]) -> Scored;
}

/// One ball's search state: what every evaluation saw.
struct Search<'a, T: Target + ?Sized> {
    target: &'a T,
    ball: &'a Ball,
    seen: RefCell<Seen>,
}

#[derive(Default)]
struct Seen {
    evaluations: usize,
    worst: Option<(f64, Vec<f64>)>,
    violations: usize,
    first_violations: Vec<Violation>,
}

impl<T: Target + ?Sized> Search<'_, T> {
    /// The run from the start of `w`: its robustness (or [`REFUSED`]), recording what it saw.
    fn score(&self, w: &[f64]) -> f64 {
        let n = self.ball.centre.len();
        let extra: Vec<f64> = w[n..].iter().map(|v| v.clamp(-1.0, 1.0)).collect();
        let x0 = self.target.start(self.ball.point(&w[..n]), &extra);
        let scored = self.target.score(&x0);
        let mut seen = self.seen.borrow_mut();
        seen.evaluations += 1;
        let Scored::Run {
            robustness,
            violation,
        } = scored
        else {
            return REFUSED;
        };
        if let Some(what) = violation {
            seen.violations += 1;
            if seen.first_violations.len() < 10 {
                seen.first_violations.push(Violation {
                    x0: x0.clone(),
                    what,
                });
            }
        }
        // A run whose trace cannot be scored (it left the finite numbers) is as bad as it gets.
        let rho = if robustness.is_nan() {
            f64::NEG_INFINITY
        } else {
            robustness
        };
        if seen.worst.as_ref().is_none_or(|(b, _)| rho < *b) {
            seen.worst = Some((rho, x0));
        }
        // Nelder–Mead needs finite values.
        rho.clamp(-REFUSED, REFUSED)
    }
}

impl<T: Target + ?Sized> CostFunction for &Search<'_, T> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, w: &Self::Param) -> Result<f64, ArgminError> {
        Ok(self.score(w))
    }
}

/// Searches every ball of `target` (module doc). Deterministic for the settings' seed: each ball's
/// search is seeded by the seed and its index, and the balls run in parallel.
pub fn falsify<T: Target + ?Sized>(
    target: &T,
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    settings.validate()?;
    let balls = target.balls();
    let n = balls.first().map_or(0, |b| b.centre.len());
    let dim = n + target.extra_dims();
    if settings.evaluations_per_start < dim + 2 {
        return Err(AttackError::Budget {
            got: settings.evaluations_per_start,
            n: dim,
            need: dim + 2,
        });
    }
    let t0 = Instant::now();
    let per_ball: Vec<Seen> = balls
        .par_iter()
        .enumerate()
        .map(|(t, ball)| {
            let search = Search {
                target,
                ball,
                seen: RefCell::new(Seen::default()),
            };
            let mut rng =
                ChaCha8Rng::seed_from_u64(settings.seed ^ (t as u64).wrapping_mul(0x9e37_79b9));
            for _ in 0..settings.starts_per_ball {
                let w0: Vec<f64> = (0..dim).map(|_| rng.random_range(-0.9..0.9)).collect();
                let simplex: Vec<Vec<f64>> = std::iter::once(w0.clone())
                    .chain((0..dim).map(|i| {
                        let mut v = w0.clone();
                        v[i] += if v[i] > 0.0 { -0.4 } else { 0.4 };
                        v
                    }))
                    .collect();
                // Each iteration costs one or two runs (a shrink n); the cap keeps the budget.
                let iters = ((settings.evaluations_per_start - (dim + 1)) / 2) as u64;
                if let Ok(nm) = NelderMead::new(simplex).with_sd_tolerance(1e-10) {
                    // A failed search still counted its runs; nothing else to recover.
                    let _ = Executor::new(&search, nm)
                        .configure(|s| s.max_iters(iters))
                        .run();
                }
            }
            search.seen.into_inner()
        })
        .collect();
    let mut report = AttackReport {
        evaluations: 0,
        seconds: 0.0,
        worst_robustness: f64::INFINITY,
        worst_start: Vec::new(),
        violations: 0,
        first_violations: Vec::new(),
    };
    for s in per_ball {
        report.evaluations += s.evaluations;
        report.violations += s.violations;
        for v in s.first_violations {
            if report.first_violations.len() < 10 {
                report.first_violations.push(v);
            }
        }
        if let Some((w, x0)) = s.worst {
            if w < report.worst_robustness {
                report.worst_robustness = w;
                report.worst_start = x0;
            }
        }
    }
    report.seconds = t0.elapsed().as_secs_f64();
    Ok(report)
}

/// The reach-avoid robustness of the states `samples` (one per sample period `h`, from t = 0), or −∞
/// when they cannot be scored.
fn reach_avoid_robustness(property: &ReachAvoid, samples: &[Vec<f64>], h: f64) -> f64 {
    let Some(n) = samples.first().map(Vec::len) else {
        return f64::NEG_INFINITY;
    };
    let times: Vec<f64> = (0..samples.len()).map(|k| k as f64 * h).collect();
    let columns: Vec<Vec<f64>> = (0..n)
        .map(|i| samples.iter().map(|x| x[i]).collect())
        .collect();
    Trace::new(times, crate::property::state_signals(n), columns)
        .ok()
        .and_then(|t| property.trace_robustness(&t).ok())
        .unwrap_or(f64::NEG_INFINITY)
}

/// A failed reach-avoid run in words (what [`RunOutcome::violated`] saw).
pub fn describe(o: &RunOutcome) -> String {
    let mut why = Vec::new();
    if !o.reached_goal {
        why.push("Goal not reached within T".to_string());
    }
    if o.entered_unsafe {
        why.push("entered Unsafe".to_string());
    }
    if o.input_violation {
        why.push(format!(
            "an input left the input set (slack {:.3e})",
            o.input_margin
        ));
    }
    if o.evaluator_error {
        why.push("the evaluator refused a later state".to_string());
    }
    if o.terminal_violation {
        let mut after = Vec::new();
        if o.left_goal {
            after.push("left Goal");
        }
        if o.after_goal_unsafe {
            after.push("entered Unsafe");
        }
        if o.after_goal_input_excursion {
            after.push("an input left the input set");
        }
        if o.not_handed_over {
            after.push("was not handed over to the terminal law within T");
        }
        if after.is_empty() {
            after.push("the evaluator refused a state");
        }
        why.push(format!("after Goal: {}", after.join(", ")));
    }
    why.join("; ")
}

/// A reach-avoid run scored for the search.
fn scored(o: RunOutcome, robustness: f64) -> Scored {
    if o.rejected {
        return Scored::Refused;
    }
    Scored::Run {
        robustness,
        violation: o.violated().then(|| describe(&o)),
    }
}

/// Feedforward images of reach-avoid tasks on the plant's exact sampled model.
struct ReachAvoidTarget<'a> {
    judge: &'a Judge<'a>,
    image: &'a Image<'a>,
    balls: Vec<Ball>,
}

impl Target for ReachAvoidTarget<'_> {
    fn balls(&self) -> &[Ball] {
        &self.balls
    }
    fn score(&self, x0: &[f64]) -> Scored {
        let mut states: Vec<Vec<f64>> = Vec::new();
        let out = run_visiting(self.judge, self.image, x0, false, &mut |x| {
            states.push(x.to_vec())
        });
        let rho = reach_avoid_robustness(self.judge.property, &states, self.judge.plant.period());
        scored(out, rho)
    }
}

/// Attacks every ball of a feedforward image of a reach-avoid task (module doc).
pub fn attack(
    judge: &Judge<'_>,
    image: &Image<'_>,
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    let target = ReachAvoidTarget {
        judge,
        image,
        balls: image_balls(image, false)?,
    };
    falsify(&target, settings)
}

/// PWA images: runs from anywhere in F, terminating upon entering Goal.
struct PwaTarget<'a> {
    judge: &'a Judge<'a>,
    image: &'a Image<'a>,
    balls: Vec<Ball>,
}

impl Target for PwaTarget<'_> {
    fn balls(&self) -> &[Ball] {
        &self.balls
    }
    fn score(&self, x0: &[f64]) -> Scored {
        let (out, path) = super::pwa::run_pwa(self.judge, self.image, x0);
        let rho = reach_avoid_robustness(self.judge.property, &path, self.judge.plant.period());
        scored(out, rho)
    }
}

/// Attacks every ball of F of a PWA image (module doc).
pub fn attack_pwa(
    judge: &Judge<'_>,
    image: &Image<'_>,
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    let target = PwaTarget {
        judge,
        image,
        balls: image_balls(image, true)?,
    };
    falsify(&target, settings)
}

/// Feedforward images of MTL tasks, judged by the formula.
struct TemporalTarget<'a> {
    judge: super::temporal::TemporalJudge<'a>,
    image: &'a Image<'a>,
    balls: Vec<Ball>,
}

impl Target for TemporalTarget<'_> {
    fn balls(&self) -> &[Ball] {
        &self.balls
    }
    fn score(&self, x0: &[f64]) -> Scored {
        Scored::of_judged(self.judge.attack_run(self.image, x0))
    }
}

/// Attacks every ball of a feedforward image of an MTL task (module doc).
pub fn attack_temporal(
    task: &crate::task::Task,
    tt: &crate::property::TemporalTask,
    image: &Image<'_>,
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    let judge = super::temporal::TemporalJudge::new(task, tt)
        .map_err(|e| AttackError::Judge(e.to_string()))?;
    let target = TemporalTarget {
        judge,
        image,
        balls: image_balls(image, false)?,
    };
    falsify(&target, settings)
}

/// What a hybrid run needs of its task: the automaton, the property, the initial location and the
/// horizon in samples (a `synth::hybrid::HybridTask` lends them).
#[derive(Clone, Copy)]
pub struct HybridRuns<'a> {
    pub plant: &'a crate::model::hybrid::Hybrid,
    pub property: &'a crate::property::ReachAvoid,
    /// The MTL formula when the task is one (forced switching, Def 4.18): runs are then scored by its
    /// robustness sampled finer, as [`super::temporal`] scores a one-location run.
    pub formula: Option<&'a crate::property::TemporalTask>,
    pub initial: crate::model::Location,
    pub steps: usize,
}

/// Hybrid images on the automaton's exact flow, from the initial location.
struct HybridTarget<'a> {
    fine: crate::model::hybrid::Hybrid,
    task: HybridRuns<'a>,
    judges: Option<super::temporal::Judges>,
    image: Image<'a>,
    balls: Vec<Ball>,
}

impl Target for HybridTarget<'_> {
    fn balls(&self) -> &[Ball] {
        &self.balls
    }
    fn score(&self, x0: &[f64]) -> Scored {
        let t = &self.task;
        let mut samples = Vec::new();
        let judging = match (t.formula, &self.judges) {
            (Some(task), Some(judges)) => super::hybrid::Judging::Formula {
                task,
                judges,
                robust: true,
            },
            _ => super::hybrid::Judging::ReachAvoid,
        };
        let run = super::hybrid::run_hybrid(
            &self.fine,
            t.property,
            t.initial,
            t.steps,
            &self.image,
            x0,
            judging,
            &mut |x| samples.push(x.to_vec()),
        );
        if run.rejected {
            return Scored::Refused;
        }
        let robustness = match t.formula {
            Some(_) => run.robustness.unwrap_or(f64::NEG_INFINITY),
            None => reach_avoid_robustness(t.property, &samples, t.plant.period()),
        };
        Scored::Run {
            robustness,
            violation: run.violation,
        }
    }
}

/// Attacks every stored run's ball of a hybrid image (module doc); each ball in the metric of its first
/// segment's location.
pub fn attack_hybrid(
    task: HybridRuns<'_>,
    bytes: &[u8],
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    let image = shared_types::image::decode(bytes)
        .map_err(|e| AttackError::Judge(format!("image: {e}")))?;
    let fine = task
        .plant
        .resampled(task.plant.period() / super::hybrid::SUBSTEPS as f64)
        .map_err(|e| AttackError::Judge(e.to_string()))?;
    let n = image.n();
    let mut balls = Vec::new();
    for t in 0..image.n_trajectories() {
        let (s0, _) = image.trajectory_segments(t);
        let l = image.segment(s0).map_or(0, |s| s.location);
        let P =
            crate::linalg::sym(faer::Mat::from_fn(n, n, |i, j| image.P(l, i, j) as f64).as_ref());
        let pis = crate::linalg::sym_fn(P.as_ref(), |v| 1.0 / v.max(1e-300).sqrt())
            .ok_or(super::MetricError)?;
        balls.push(Ball {
            centre: (0..n).map(|i| image.centre(t, i) as f64).collect(),
            pis: crate::linalg::to_row_major(pis.as_ref()),
            reach: image.delta(t) as f64 * (1.0 + 1e-4),
        });
    }
    let judges = task
        .formula
        .map(|tt| super::temporal::Judges::new(tt, n))
        .transpose()
        .map_err(|e| AttackError::Judge(e.to_string()))?;
    let target = HybridTarget {
        fine,
        task,
        judges,
        image,
        balls,
    };
    falsify(&target, settings)
}

/// Feedback-linearizable plants: ξ searched in the ball, the zero-dynamics states over Init, each run on
/// the nonlinear plant.
struct FlTarget<'a> {
    task: &'a crate::task::Task,
    maps: &'a crate::model::feedback_linearizable::FlMaps,
    image: &'a Image<'a>,
    balls: Vec<Ball>,
    /// The zero-dynamics states Init does not pin, with their ranges.
    free: Vec<(usize, f64, f64)>,
}

impl<'a> FlTarget<'a> {
    /// The image's balls, and the zero-dynamics states Init leaves free, of a feedback-linearizable task.
    fn new(task: &'a crate::task::Task, image: &'a Image<'a>) -> Result<Self, AttackError> {
        let maps = task.plant.linearization().ok_or_else(|| {
            AttackError::Judge("the task's plant is not feedback-linearizable".into())
        })?;
        let init = &maps.init;
        let free = maps
            .zero_states
            .iter()
            .filter(|&&s| init.hi[s] > init.lo[s])
            .map(|&s| (s, init.lo[s], init.hi[s]))
            .collect();
        Ok(Self {
            task,
            maps,
            image,
            balls: image_balls(image, false)?,
            free,
        })
    }
}

impl Target for FlTarget<'_> {
    fn balls(&self) -> &[Ball] {
        &self.balls
    }
    fn extra_dims(&self) -> usize {
        self.free.len()
    }
    fn start(&self, xi: Vec<f64>, extra: &[f64]) -> Vec<f64> {
        let init = &self.maps.init;
        // Zero-dynamics states at Init's centre unless searched; ξ from the ball.
        let mut x = init.centre();
        for (&(s, lo, hi), &e) in self.free.iter().zip(extra) {
            x[s] = lo + (hi - lo) * 0.5 * (e + 1.0);
        }
        // A flat plant's flat coordinates that are not plant states follow from Init and the
        // controller's initial states, so only the others are set (a start the selection then refuses
        // scores as refused, never as a violation).
        for (j, s) in self.maps.state_coords() {
            x[s] = xi[j];
        }
        x
    }
    fn score(&self, x0: &[f64]) -> Scored {
        let mut xis = Vec::new();
        let out =
            super::nonlinear::run_fl_visiting(self.task, self.maps, self.image, x0, &mut |xi| {
                xis.push(xi.to_vec())
            });
        let rho = reach_avoid_robustness(&self.task.property, &xis, self.maps.plant.period());
        scored(out, rho)
    }
}

/// Feedback-linearizable plants with an MTL task: the starts as [`FlTarget`]'s (ξ in the ball, the
/// zero-dynamics states over Init), each run on the nonlinear plant judged and scored by the formula
/// ([`super::temporal::TemporalJudge::attack_run_fl`]).
struct FlTemporalTarget<'a> {
    fl: FlTarget<'a>,
    judge: super::temporal::TemporalJudge<'a>,
}

impl Target for FlTemporalTarget<'_> {
    fn balls(&self) -> &[Ball] {
        self.fl.balls()
    }
    fn extra_dims(&self) -> usize {
        self.fl.extra_dims()
    }
    fn start(&self, xi: Vec<f64>, extra: &[f64]) -> Vec<f64> {
        self.fl.start(xi, extra)
    }
    fn score(&self, x0: &[f64]) -> Scored {
        Scored::of_judged(self.judge.attack_run_fl(self.fl.image, x0))
    }
}

/// Attacks every ball of a feedback-linearizable task's image for its MTL formula on the nonlinear plant.
pub fn attack_temporal_fl(
    task: &crate::task::Task,
    tt: &crate::property::TemporalTask,
    image: &Image<'_>,
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    let fl = FlTarget::new(task, image)?;
    let judge = super::temporal::TemporalJudge::new(task, tt)
        .map_err(|e| AttackError::Judge(e.to_string()))?;
    let target = FlTemporalTarget { fl, judge };
    falsify(&target, settings)
}

/// Attacks every ball of a feedback-linearizable task's image on the nonlinear plant (module doc).
pub fn attack_fl(
    task: &crate::task::Task,
    image: &Image<'_>,
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    let target = FlTarget::new(task, image)?;
    falsify(&target, settings)
}
