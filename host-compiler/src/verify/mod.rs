//! Independent re-check of a controller image: the certificate re-proved from the bytes
//! ([`feedforward::recheck`], [`pwa::recheck`]) and closed-loop Monte Carlo through the shared-types evaluator
//! in f32, on the exact discretised plant, from initial states drawn in the certified cover and on the
//! boundary of every ball. Every run must reach Goal within the horizon, never enter Unsafe (also checked
//! at sub-sample instants for continuous-time plants) and apply only inputs inside the input set.
//!
//! # When the task ends
//! The task is the reach-avoid problem of Theorem 4.7: it is met at the first sample in Goal, provided
//! Unsafe was avoided and every input was admissible up to then. That is exactly what a certificate
//! proves (the ball reaches Goal at k* and the tube is checked up to the end of its table), so only that
//! part of a run is judged. A run is still simulated to the horizon, and what the image does after Goal
//! (inputs outside the set, entering Unsafe) is counted and reported separately, not as a violation:
//! a trajectory whose table the optimiser cut at k* (§5.3) certifies nothing after it.
//!
//! # After Goal, with a terminal law (issue 42, item 4)
//! An image with a terminal law (section 11) is certified for the whole run: its cover reaches the law's
//! handover region inside Goal, so every run is handed over within the horizon and the law keeps it in
//! Goal for ever (`certify::terminal`'s module doc). Its runs last 2T, and after the first sample in Goal
//! each of these is a violation ([`RunOutcome::terminal_violation`]): outside Goal again (at a sample or
//! between samples), in Unsafe, an input outside the set, a refusal by the evaluator, or no handover
//! within the horizon.

pub mod attack;
pub mod coverage;
pub mod feedforward;
pub mod hybrid;
pub mod nonlinear;
pub mod pwa;
pub mod stored;
pub mod temporal;

/// Largest number of Monte Carlo runs from the cover one check may ask for (`verify --runs`,
/// `synth --verify-runs`): every start is held in memory (8n + 24 bytes) and simulated over the horizon,
/// so 10⁶ runs take at most about 120 MB and minutes, not the 24 GB a 10⁹ request would.
pub const MAX_RUNS: u64 = 1_000_000;

/// Largest number of runs from the boundary of each ball (`verify --per-ball`): with at most 1 024 balls
/// (`shared_types::capacity::MAX_TRAJECTORIES`), at most 4 194 304 boundary runs.
pub const MAX_PER_BALL: u64 = 4_096;

use crate::certify::terminal::{TerminalCertificate, TerminalRefusal};
use crate::geometry::Region;
use crate::linalg::mat_vec;
use crate::model::{DiscretePlant, Plant};
use crate::property::{InputBound, ReachAvoid};
use crate::spec::InitBox;
use crate::task::Task;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use shared_types::eval::Controller;
use shared_types::image::Image;

/// The image's metric P (decoded, so finite and positive definite in f32) has no f64
/// eigendecomposition: the boundaries of its balls cannot be sampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("the image's metric P has no eigendecomposition: its balls cannot be sampled")]
pub struct MetricError;

/// Why a Monte Carlo campaign did not run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum MonteCarloError {
    #[error(transparent)]
    Metric(#[from] MetricError),
    /// More runs than [`MAX_RUNS`] or [`MAX_PER_BALL`] allow (checked before any is drawn).
    #[error("{what} = {got} runs; at most {max}")]
    TooManyRuns {
        what: &'static str,
        got: usize,
        max: u64,
    },
}

/// `count` against `max`, before any run is drawn.
fn check_runs(what: &'static str, count: usize, max: u64) -> Result<(), MonteCarloError> {
    if count as u64 > max {
        return Err(MonteCarloError::TooManyRuns {
            what,
            got: count,
            max,
        });
    }
    Ok(())
}

/// P^{-1/2} of the image's metric (location 0), for drawing states in and on its balls.
pub(crate) fn inverse_sqrt_metric(image: &Image<'_>) -> Result<faer::Mat<f64>, MetricError> {
    let n = image.n();
    let P = crate::linalg::sym(faer::Mat::from_fn(n, n, |i, j| image.P(0, i, j) as f64).as_ref());
    crate::linalg::sym_fn(P.as_ref(), |l| 1.0 / l.max(1e-300).sqrt()).ok_or(MetricError)
}

/// Why an image does not belong to a spec: it was made for another plant or sample period, so nothing
/// it was certified for says anything about this spec.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Mismatch {
    #[error("the image is for n = {image} states but the spec's plant has n = {spec} (plant.A)")]
    States { image: usize, spec: usize },
    #[error("the image is for m = {image} inputs but the spec's plant has m = {spec} (plant.B)")]
    Inputs { image: usize, spec: usize },
    #[error(
        "the image's sample period is {image} s but the spec's plant.period is {spec} s \
         (the image was certified for another sampled loop)"
    )]
    Period { image: f32, spec: f64 },
    #[error("{}", spec_changed(.changed))]
    Spec { changed: Vec<&'static str> },
}

/// "the spec's [goal] and horizon changed since this image was synthesised": the parts that changed,
/// without the whole-spec hash (which changes with any of them).
fn spec_changed(changed: &[&str]) -> String {
    let parts: Vec<&str> = changed.iter().copied().filter(|&p| p != "spec").collect();
    let list = match parts.as_slice() {
        [] => return "the spec changed since this image was synthesised".into(),
        [one] => (*one).to_string(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    };
    format!(
        "the spec's {list} changed since this image was synthesised (synthesise it again from the \
         spec as it is now)"
    )
}

/// Refuses an image whose dimensions (n, m) or sample period differ from the spec's, or whose spec
/// fingerprint (if it stores one) is not the spec's ([`Mismatch::Spec`] names the parts that changed).
/// The period is compared as the f32 the image stores: exactly the value `emit` writes for the spec's
/// period.
pub fn check_matches(problem: &crate::spec::Problem, image: &Image<'_>) -> Result<(), Mismatch> {
    let p = &problem.plant;
    // A feedback-linearizable plant's image works in ξ, of dimension Σ r_i.
    let n = problem
        .nonlinear
        .as_ref()
        .map_or(p.n(), |d| d.relative_degree().iter().sum());
    if image.n() != n {
        return Err(Mismatch::States {
            image: image.n(),
            spec: n,
        });
    }
    if image.m() != p.m() {
        return Err(Mismatch::Inputs {
            image: image.m(),
            spec: p.m(),
        });
    }
    if image.period() != p.period as f32 {
        return Err(Mismatch::Period {
            image: image.period(),
            spec: p.period,
        });
    }
    // An image without a fingerprint (written before it existed) is accepted; the CLI warns.
    if let Some(stored) = image
        .fingerprint()
        .and_then(crate::spec::SpecFingerprint::from_bytes)
    {
        let changed = problem.fingerprint.changed(&stored);
        if !changed.is_empty() {
            return Err(Mismatch::Spec { changed });
        }
    }
    Ok(())
}

/// The plant and spec a run is judged against: the task's plant, property, horizon and Init.
#[derive(Clone, Copy)]
pub struct Judge<'a> {
    pub plant: &'a dyn Plant,
    pub property: &'a ReachAvoid,
    /// Steps in the horizon.
    pub steps: usize,
    /// Init, to draw initial states from.
    pub init: &'a InitBox,
}

impl<'a> Judge<'a> {
    /// The judge of a task.
    pub fn new(task: &'a Task) -> Self {
        Self {
            plant: &*task.plant,
            property: &task.property,
            steps: task.steps,
            init: task.init(),
        }
    }
    /// The sampled model x⁺ = A x + B u + g.
    pub fn model(&self) -> &'a DiscretePlant {
        self.plant.error_dynamics(0)
    }
    pub fn goal(&self) -> &'a dyn Region {
        self.property.goal.as_ref()
    }
    pub fn unsafe_set(&self) -> Option<&'a dyn Region> {
        self.property.unsafe_region()
    }
    pub fn input(&self) -> &'a InputBound {
        &self.property.input
    }
}

/// How one run ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RunOutcome {
    pub x0: Vec<f64>,
    pub reached_goal: bool,
    pub entered_unsafe: bool,
    pub input_violation: bool,
    /// The evaluator refused the state (out of envelope) at κ = 0.
    pub rejected: bool,
    /// The evaluator refused a later state of an accepted run.
    pub evaluator_error: bool,
    /// Largest Goal depth reached (Euclidean), smallest Unsafe distance, smallest input slack.
    pub goal_margin: f64,
    pub unsafe_margin: f64,
    pub input_margin: f64,
    /// First sample in Goal (the task ends there; the rest of the run is not judged).
    pub goal_step: Option<usize>,
    /// After Goal, the terminal law applied an input outside the set (reported, not a violation).
    pub after_goal_input_excursion: bool,
    /// After Goal, the run entered Unsafe (reported, not a violation).
    pub after_goal_unsafe: bool,
    /// After first reaching Goal, the run was outside Goal at a sample or between samples (within the
    /// run's length: 2T for an image with a terminal law, else T).
    pub left_goal: bool,
    /// The terminal law took over (images with one).
    pub handed_over: bool,
    /// The run reached Goal but the terminal law had not taken over by the end of the horizon (images
    /// with one; a violation).
    pub not_handed_over: bool,
    /// With a terminal law in the image, after the run's first sample in Goal: it left Goal, entered
    /// Unsafe, applied an input outside the set, was refused by the evaluator or was not handed over
    /// within the horizon. The certificate covers the whole run (module doc): a violation.
    pub terminal_violation: bool,
}

impl RunOutcome {
    /// A run from `x0` before its first step: nothing reached, nothing violated, margins at their
    /// neutral values.
    pub fn new(x0: &[f64]) -> Self {
        Self {
            x0: x0.to_vec(),
            reached_goal: false,
            entered_unsafe: false,
            input_violation: false,
            rejected: false,
            evaluator_error: false,
            goal_margin: f64::NEG_INFINITY,
            unsafe_margin: f64::INFINITY,
            input_margin: f64::INFINITY,
            goal_step: None,
            after_goal_input_excursion: false,
            after_goal_unsafe: false,
            left_goal: false,
            handed_over: false,
            not_handed_over: false,
            terminal_violation: false,
        }
    }

    /// Records that the evaluator refused the state at sample `k`: at k = 0 the start lies outside the
    /// cover (not a violation); before Goal an evaluator error; after Goal a violation when the run is
    /// judged after Goal (`terminal`: the image has a terminal law, module doc), else nothing (the task
    /// has ended).
    pub fn refused(&mut self, k: usize, terminal: bool) {
        if k == 0 {
            self.rejected = true;
        } else if self.goal_step.is_none() {
            self.evaluator_error = true;
        } else {
            self.terminal_violation |= terminal;
        }
    }

    pub fn violated(&self) -> bool {
        !self.rejected
            && (!self.reached_goal
                || self.entered_unsafe
                || self.input_violation
                || self.evaluator_error
                || self.terminal_violation)
    }
}

/// Every how many runs the (costly) signed-distance margins are recorded.
pub const MARGIN_EVERY: usize = 16;

/// Result of a verification campaign.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct VerifyReport {
    pub interior_runs: usize,
    pub boundary_runs: usize,
    /// Boundary points the evaluator refused at κ = 0 (part of `refused`).
    pub boundary_rejected: usize,
    /// Starts the evaluator refused at κ = 0 although the certificate covers them: every start is drawn
    /// where the image's f32 selection provably accepts (interior starts by that selection itself,
    /// boundary starts within [`boundary_radius`]; with model maps, ξ by the spec's coords program at the
    /// spec's ζ0). Any is a failed verification, never "0 violations".
    pub refused: usize,
    /// With model maps: boundary points whose ξ (the spec's coords program in f32) the image's selection
    /// does not accept (the program's rounding, or a ball whose centre no plant state reaches); not run.
    pub boundary_outside: usize,
    pub violations: usize,
    pub first_violations: Vec<RunOutcome>,
    /// Worst margins over the runs that recorded them (every [`MARGIN_EVERY`]-th): Goal depth (max over
    /// time, min over runs), Unsafe distance and input slack (min over both), Euclidean.
    pub worst_goal_margin: f64,
    pub worst_unsafe_margin: f64,
    pub worst_input_margin: f64,
    /// Runs whose terminal law, after the task ended in Goal, left the input set / entered Unsafe (not
    /// judged: see the module doc).
    pub after_goal_input_excursions: usize,
    pub after_goal_unsafe: usize,
    /// Runs that reached Goal and were outside it again before the end of the run (2T with a terminal
    /// law, else T), and runs the terminal law took over (counted among the accepted runs).
    pub runs_leaving_goal: usize,
    pub handed_over: usize,
    /// Runs that reached Goal and were not handed over within the horizon (images with a terminal law).
    pub not_handed_over: usize,
    /// Whether what runs do after Goal is judged (the image has a terminal law, module doc): then every
    /// run counted above, and every run entering Unsafe or leaving the input set after Goal, is among
    /// the violations.
    pub after_goal_judged: bool,
    /// Samples each run lasts: the horizon, or twice it with a terminal law.
    pub run_steps: usize,
}

/// The radius (in the image's metric P̂, about the stored centre) within which every state the image's
/// whitened selection test (section 13, `shared_types::selection`) accepts for trajectory `t` lies,
/// recomputed from the stored factor, whitened centre and threshold
/// ([`crate::certify::pwa_accept_radius`]); `None` for an image without the section. The ball's metric
/// is that of the trajectory's first location; `P` is it, widened from the image.
pub fn selection_test_radius(image: &Image<'_>, P: faer::MatRef<'_, f64>, t: usize) -> Option<f64> {
    selection_test_data(image, t)
        .map(|(Rh, c, cz, s)| crate::certify::pwa_accept_radius(P, &Rh, &c, &cz, s))
}

/// The radius at which a Monte Carlo places trajectory `t`'s boundary starts, in the image's metric about
/// the stored centre: a hair (one part in 10⁶) inside the radius within which the image's f32 selection
/// test provably accepts every state (the P-metric test with the stored radius,
/// [`crate::certify::selection_floor`]; a whitened selection test, [`crate::certify::pwa_complete_radius`]),
/// so that every boundary start is a state the certificate covers and the evaluator must run: a refused
/// one fails the verification.
pub fn boundary_radius(image: &Image<'_>, t: usize) -> f64 {
    let stored = image.delta(t) as f64;
    let n = image.n();
    let l = image.location(t, 0);
    let P: Vec<f64> = (0..n * n)
        .map(|i| image.P(l, i / n, i % n) as f64)
        .collect();
    let P = crate::linalg::from_row_major(n, n, &P);
    let r = match selection_test_data(image, t) {
        Some((Rh, c, cz, s)) => stored.min(crate::certify::pwa_complete_radius(
            P.as_ref(),
            &Rh,
            &c,
            &cz,
            s,
        )),
        None => {
            let c: Vec<f64> = (0..n).map(|i| image.centre(t, i) as f64).collect();
            stored.min(crate::certify::selection_floor(
                P.as_ref(),
                &c,
                image.delta(t),
                stored,
            ))
        }
    };
    r * (1.0 - 1e-6)
}

/// Trajectory `t`'s record of the image's selection test, widened: the factor of its location, its
/// stored centre, whitened centre and threshold; `None` without the section.
#[allow(clippy::type_complexity)]
fn selection_test_data(image: &Image<'_>, t: usize) -> Option<(Vec<f64>, Vec<f64>, Vec<f64>, f32)> {
    let test = image.selection_test()?;
    let n = image.n();
    let l = image.location(t, 0);
    let Rh: Vec<f64> = (0..n * n)
        .map(|i| test.factor(n, l, i / n, i % n) as f64)
        .collect();
    let c: Vec<f64> = (0..n).map(|i| image.centre(t, i) as f64).collect();
    let cz: Vec<f64> = (0..n).map(|i| test.centre_z(n, t, i) as f64).collect();
    Some((Rh, c, cz, test.threshold(n, t)))
}

/// How far `u` lies inside the input set (negative outside): the distance to the nearest box face, or
/// `max − ‖u − center‖₂`.
pub fn input_slack(input: &InputBound, u: &[f64]) -> f64 {
    match input {
        InputBound::Box { lo, hi } => u
            .iter()
            .zip(lo.iter().zip(hi))
            .map(|(&x, (&l, &h))| (h - x).min(x - l))
            .fold(f64::INFINITY, f64::min),
        InputBound::Norm2 { center, max } => {
            max - u
                .iter()
                .zip(center)
                .map(|(a, c)| (a - c) * (a - c))
                .sum::<f64>()
                .sqrt()
        }
    }
}

/// Run the closed loop from `x0` with the image's evaluator. Violations are decided by set membership at every
/// sample and sub-sample; with `margins` the signed distances at the samples are recorded too (costlier).
pub fn run(judge: &Judge<'_>, image: &Image<'_>, x0: &[f64], margins: bool) -> RunOutcome {
    run_visiting(judge, image, x0, margins, &mut |_| {})
}

/// [`run`], showing `visit` the state at every sample the run reaches (x0 first), in order.
pub fn run_visiting(
    judge: &Judge<'_>,
    image: &Image<'_>,
    x0: &[f64],
    margins: bool,
    visit: &mut dyn FnMut(&[f64]),
) -> RunOutcome {
    run_until(judge, image, x0, margins, visit, run_steps(judge, image))
}

/// [`run`] for `last` samples (at least the horizon's): what a run does after the task, with or without
/// a terminal law (the `terminal` bench's baseline runs an image without one to 2T).
pub fn run_to(judge: &Judge<'_>, image: &Image<'_>, x0: &[f64], last: usize) -> RunOutcome {
    run_until(judge, image, x0, false, &mut |_| {}, last.max(judge.steps))
}

fn run_until(
    judge: &Judge<'_>,
    image: &Image<'_>,
    x0: &[f64],
    margins: bool,
    visit: &mut dyn FnMut(&[f64]),
    last: usize,
) -> RunOutcome {
    let metric = crate::geometry::Metric::euclidean(x0.len());
    let mut ctl = Controller::new(*image);
    let mut x = x0.to_vec();
    // The loop's buffers, reused every step (a run is hundreds of steps, the Monte Carlo 10⁴ runs).
    let (mut next, mut xf, mut u) = (x0.to_vec(), vec![0.0f32; x0.len()], Vec::new());
    let mut out = RunOutcome::new(x0);
    // Judged until the first sample in Goal (module doc); after it, only recorded, except with a
    // terminal law, whose certificate covers the rest of the run.
    let judged = image.terminal_law().is_some();
    let mut goal_dist = SignedDistances::new(judge.goal(), &metric);
    let mut unsafe_dist = judge
        .unsafe_set()
        .map(|us| SignedDistances::new(us, &metric));
    let mut check = |x: &[f64], out: &mut RunOutcome, sample: bool| {
        if out.goal_step.is_some() && !judge.goal().contains(x) {
            out.left_goal = true;
            out.terminal_violation |= judged;
        }
        if let Some(us) = judge.unsafe_set() {
            let inside = us.contains(x);
            if out.goal_step.is_some() {
                out.after_goal_unsafe |= inside;
                out.terminal_violation |= inside && judged;
                return;
            }
            out.entered_unsafe |= inside;
            if let (true, true, Some(d)) = (margins, sample, unsafe_dist.as_mut()) {
                out.unsafe_margin = out.unsafe_margin.min(-d.at(x));
            }
        }
    };
    check(&x, &mut out, true);
    for k in 0..=last {
        visit(&x);
        // Only samples within the horizon get here before Goal (the loop ends at T without it).
        if out.goal_step.is_none() && judge.goal().contains(&x) {
            out.reached_goal = true;
            out.goal_step = Some(k);
        }
        if margins && k <= judge.steps {
            out.goal_margin = out.goal_margin.max(goal_dist.at(&x));
        }
        if k == last || (k >= judge.steps && out.goal_step.is_none()) {
            break;
        }
        for (f, v) in xf.iter_mut().zip(&x) {
            *f = *v as f32;
        }
        match ctl.step(&xf) {
            Ok(v) => {
                u.clear();
                u.extend(v.as_slice().iter().map(|&v| v as f64));
            }
            Err(_) => {
                out.refused(k, judged);
                return out;
            }
        }
        out.handed_over |= ctl.in_terminal_phase();
        // The handover happens at the step of sample κ* ≤ N ≤ T at the latest.
        if judged && k == judge.steps && out.goal_step.is_some() && !out.handed_over {
            out.not_handed_over = true;
            out.terminal_violation = true;
        }
        let s = input_slack(judge.input(), &u);
        if out.goal_step.is_some() {
            out.after_goal_input_excursion |= s < 0.0;
            out.terminal_violation |= judged && s < 0.0;
        } else {
            out.input_margin = out.input_margin.min(s);
            if s < 0.0 {
                out.input_violation = true;
            }
        }
        if !between_clear(judge, &x, &u, out.goal_step.is_some()) {
            judge
                .plant
                .between_samples(0, &x, &u, &mut |xs| check(xs, &mut out, false));
        }
        judge.plant.step_into(0, &x, &u, &mut next);
        std::mem::swap(&mut x, &mut next);
        check(&x, &mut out, true);
    }
    out
}

/// Whether every state of the period after the sample `x` with `u` held provably passes the checks a
/// run makes between samples: outside Unsafe, and inside Goal once the run has reached it (`in_goal`).
/// The plant's bound on its motion within the period ([`Plant::excursion`], grown by a relative 10⁻⁹
/// and an absolute 10⁻¹² of the state's size for the rounding of the states it visits) lies below the
/// sets' sure radii at the sample ([`Region::sure_radius`]). Then the visit would find nothing, and
/// skipping it leaves the run's outcome as it was; `false` (visit them) whenever either is unknown.
pub(crate) fn between_clear(judge: &Judge<'_>, x: &[f64], u: &[f64], in_goal: bool) -> bool {
    let Some(e) = judge.plant.excursion(0, x, u) else {
        return false;
    };
    let size = x.iter().fold(1.0f64, |a, v| a.max(v.abs()));
    let reach = e * (1.0 + 1e-9) + 1e-12 * size;
    if !reach.is_finite() {
        return false;
    }
    let clear = |set: &dyn Region, inside: bool| match set.sure_radius(x) {
        Some((side, r)) => side == inside && r > reach,
        None => false,
    };
    if let Some(us) = judge.unsafe_set() {
        if !clear(us, false) {
            return false;
        }
    }
    !in_goal || clear(judge.goal(), true)
}

/// A set's signed distance in one metric at the points of a run (the margins the report gives), compiled
/// for the metric once, when first asked ([`Region::compile`]: the same values, bit for bit, without a
/// witness point per point); a set without a compiled form answers through [`Region::signed_dist`].
pub(crate) struct SignedDistances<'a> {
    set: &'a dyn Region,
    metric: &'a crate::geometry::Metric,
    compiled: Option<Option<Box<dyn crate::geometry::SignedDistanceFn + 'a>>>,
}

impl<'a> SignedDistances<'a> {
    pub(crate) fn new(set: &'a dyn Region, metric: &'a crate::geometry::Metric) -> Self {
        Self {
            set,
            metric,
            compiled: None,
        }
    }

    /// The signed distance of `x` (positive inside).
    pub(crate) fn at(&mut self, x: &[f64]) -> f64 {
        let (set, metric) = (self.set, self.metric);
        match self.compiled.get_or_insert_with(|| set.compile(metric)) {
            Some(f) => f.eval(x).signed(),
            None => set.signed_dist(x, metric).value,
        }
    }
}

/// The terminal law of `image` (section 11) re-proved from its bytes against the task
/// ([`crate::certify::terminal`]); `None` for an image without one.
pub fn recheck_terminal(
    task: &crate::task::Task,
    image: &Image<'_>,
) -> Option<Result<TerminalCertificate, TerminalRefusal>> {
    let law = image.terminal_law()?;
    let stored = crate::emit::stored_terminal(&law, image.n(), image.m());
    Some(crate::certify::terminal::certify(
        task.plant.as_ref(),
        &task.property,
        &stored,
    ))
}

/// Where the image's runs are certified to end: with a terminal law, its handover region H inside Goal,
/// from the section's own bytes ([`crate::certify::terminal::handover_region`]; the empty set when the
/// f32 test is proved to accept nothing); `None` without a terminal law (the task's Goal).
pub fn handover_target(image: &Image<'_>) -> Option<Box<dyn Region>> {
    let law = image.terminal_law()?;
    let (n, m) = (image.n(), image.m());
    let stored = crate::emit::stored_terminal(&law, n, m);
    Some(
        crate::certify::terminal::handover_region(&stored).map_or_else(
            || Box::new(crate::geometry::Empty(n)) as Box<dyn Region>,
            |(_, h)| h,
        ),
    )
}

/// Samples a run of `image` lasts: the horizon, or twice it when the image has a terminal law (whose
/// certificate covers what comes after the task).
pub fn run_steps(judge: &Judge<'_>, image: &Image<'_>) -> usize {
    if image.terminal_law().is_some() {
        2 * judge.steps
    } else {
        judge.steps
    }
}

/// Monte Carlo over the certified cover: `interior` initial states drawn uniformly in Init and accepted by
/// the evaluator's ball selection (rejection sampling, at most 50× as many draws), plus `per_ball` points on
/// the boundary of every ball (in all state directions, at the stored radius less one part in 10⁶). Deterministic for a
/// seed; runs in parallel.
pub fn monte_carlo(
    judge: &Judge<'_>,
    image: &Image<'_>,
    interior: usize,
    per_ball: usize,
    seed: u64,
) -> Result<VerifyReport, MonteCarloError> {
    check_runs("interior", interior, MAX_RUNS)?;
    check_runs("per_ball", per_ball, MAX_PER_BALL)?;
    let Pis = inverse_sqrt_metric(image)?;
    let ctl = Controller::new(*image);
    // Interior: rejection sampling against the evaluator's own selection.
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Grown as needed: `interior` comes from a flag and may be far more than memory holds.
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let mut draws = 0usize;
    while starts.len() < interior && draws < interior.saturating_mul(50) {
        draws += 1;
        let x: Vec<f64> = judge
            .init
            .lo
            .iter()
            .zip(&judge.init.hi)
            .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
            .collect();
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        if ctl.select(&xf).is_some() {
            starts.push(x);
        }
    }
    let interior_runs = starts.len();
    // Boundary: x = c + δ·P^{-1/2}w/‖w‖ for random directions w.
    let mut boundary: Vec<Vec<f64>> = Vec::new();
    for t in 0..image.n_trajectories() {
        for _ in 0..per_ball {
            boundary.push(ball_boundary_point(image, Pis.as_ref(), t, &mut rng));
        }
    }
    let boundary_runs = boundary.len();
    let all: Vec<Vec<f64>> = starts.into_iter().chain(boundary).collect();
    // Margins (signed distances, for the report) on every MARGIN_EVERY-th run; violations on all of them.
    let outcomes: Vec<RunOutcome> = all
        .par_iter()
        .enumerate()
        .map(|(i, x0)| run(judge, image, x0, i % MARGIN_EVERY == 0))
        .collect();
    let mut report = summarize(&outcomes, interior_runs, boundary_runs);
    report.run_steps = run_steps(judge, image);
    report.after_goal_judged = image.terminal_law().is_some();
    Ok(report)
}

/// A point on the boundary of trajectory `t`'s ball, c + r·P^{-1/2}w/‖w‖ for a random direction w, at
/// the [`boundary_radius`] r, so that the f32 selection accepts nearly all of them (`Pis` = P^{-1/2}).
pub(crate) fn ball_boundary_point(
    image: &Image<'_>,
    Pis: faer::MatRef<'_, f64>,
    t: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<f64> {
    let n = image.n();
    let d = boundary_radius(image, t);
    let w: Vec<f64> = (0..n)
        .map(|_| rng.sample::<f64, _>(rand_distr::StandardNormal))
        .collect();
    let wn = w.iter().map(|a| a * a).sum::<f64>().sqrt().max(1e-300);
    let e = mat_vec(Pis, &w);
    (0..n)
        .map(|i| image.centre(t, i) as f64 + d * e[i] / wn)
        .collect()
}

/// The report of a Monte Carlo's runs: the first `interior_runs` drawn inside, the next `boundary_runs` on
/// the balls' boundaries; margins from every [`MARGIN_EVERY`]-th run.
pub fn summarize(
    outcomes: &[RunOutcome],
    interior_runs: usize,
    boundary_runs: usize,
) -> VerifyReport {
    let boundary_rejected = outcomes[interior_runs..]
        .iter()
        .filter(|o| o.rejected)
        .count();
    let refused = outcomes.iter().filter(|o| o.rejected).count();
    let bad: Vec<&RunOutcome> = outcomes.iter().filter(|o| o.violated()).collect();
    let ok = outcomes
        .iter()
        .step_by(MARGIN_EVERY)
        .filter(|o| !o.rejected);
    let (mut wg, mut wu, mut wi) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    for o in ok {
        wg = wg.min(o.goal_margin);
        wu = wu.min(o.unsafe_margin);
        wi = wi.min(o.input_margin);
    }
    VerifyReport {
        interior_runs,
        boundary_runs,
        boundary_rejected,
        refused,
        boundary_outside: 0,
        violations: bad.len(),
        first_violations: bad.into_iter().take(10).cloned().collect(),
        worst_goal_margin: wg,
        worst_unsafe_margin: wu,
        worst_input_margin: wi,
        after_goal_input_excursions: outcomes
            .iter()
            .filter(|o| o.after_goal_input_excursion)
            .count(),
        after_goal_unsafe: outcomes.iter().filter(|o| o.after_goal_unsafe).count(),
        runs_leaving_goal: outcomes.iter().filter(|o| o.left_goal).count(),
        handed_over: outcomes.iter().filter(|o| o.handed_over).count(),
        not_handed_over: outcomes.iter().filter(|o| o.not_handed_over).count(),
        after_goal_judged: false,
        run_steps: 0,
    }
}
