//! The synthesis pipeline for linear affine plants (Algorithm 1 with Algorithm 2's controller):
//! spec → sampled plant → CAF and feedback → trajectories grown until Init is covered → certified,
//! f32-exact image → independent Monte Carlo verification → report.
//!
//! The cover grows by Algorithm 4 (§5.4) by default: the first trajectory from the SCP generator (or
//! imports), each later one from the boundary of the ball closest to the nearest uncovered sample, with δ
//! maximised by §5.3 ([`crate::optimize::maximize_delta`]) and re-certified through
//! [`certify::shipped`]; [`Generator::Scp`] keeps Algorithm 1 with the SCP generator per seed. The run
//! stops when Init is covered, the budget is spent, no local variation reaches the rest ("needs a new seed
//! trajectory"), or on [`SynthOptions::cancel`] (Ctrl-C), always with a verified image of what is certified.
//!
//! Everything random is drawn from ChaCha streams seeded by the spec's seed, and parallel work is
//! collected in a fixed order, so the same spec and seed give a byte-identical image.

pub mod alg4;

use crate::certify::{self, Certificate, Loop, LoopConstants};
use crate::coverage::{CoverageEstimate, SampleBox};
use crate::emit::{FallbackLaw, ImageBuilder, TrajectoryEntry};
use crate::linalg::round32;
use crate::optimize::{maximize_delta, BundleSettings, OptStop, Optimized};
use crate::property::input_scale;
use crate::task::Task;
use crate::trajectory::generate::{generate, GenProblem, GenSettings};
use crate::trajectory::Nominal;
use crate::verify::{monte_carlo, Judge, VerifyReport};
use faer::Mat;
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// How the cover grows after its first trajectory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
pub enum Generator {
    /// Algorithm 4 (§5.4): the nearest uncovered sample projected onto the closest ball, that ball's
    /// feedback law simulated from there, δ maximised by §5.3 and re-certified (the default).
    #[default]
    #[value(name = "algorithm4")]
    Algorithm4,
    /// Algorithm 1 with the SCP generator from each uncovered seed, without §5.3 (the earlier pipeline).
    Scp,
}

impl std::fmt::Display for Generator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Generator::Algorithm4 => "algorithm4",
            Generator::Scp => "scp",
        })
    }
}

/// Called with the number of trajectories after each one is accepted (e.g. to interrupt a run).
#[derive(Clone)]
pub struct AcceptHook(pub Arc<dyn Fn(usize) + Send + Sync>);

impl std::fmt::Debug for AcceptHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("AcceptHook(..)")
    }
}

/// Options of one run that are not part of the task (defaults documented per field).
#[derive(Clone, Debug)]
pub struct SynthOptions {
    /// Monte Carlo runs from the certified cover in the verification (default 10 000).
    pub verify_interior: usize,
    /// Runs from the boundary of each ball (default 32).
    pub verify_per_ball: usize,
    /// Uniform samples of Init used to choose seeds (default 4 000).
    pub working_samples: usize,
    /// Show progress bars (default true).
    pub progress: bool,
    /// Recorded trajectories (e.g. from a person) to certify and use before generating any.
    pub imports: Vec<(String, crate::trajectory::csv::Recording)>,
    /// How trajectories after the first are made (default [`Generator::Algorithm4`]).
    pub generator: Generator,
    /// Seeds tried per round, in parallel (default 4). Fixed, so results do not depend on the thread count.
    pub batch: usize,
    /// Settings of §5.3's bundle method (default: `BundleSettings::default()` with the spec's
    /// `max_iterations`).
    pub optimizer: Option<BundleSettings>,
    /// Set to stop cleanly (Ctrl-C): the run ends with what is certified so far, verified and reported
    /// (default: a fresh, unset flag).
    pub cancel: Arc<AtomicBool>,
    /// Called after each accepted trajectory (default none).
    pub on_accept: Option<AcceptHook>,
}

impl Default for SynthOptions {
    fn default() -> Self {
        Self {
            verify_interior: 10_000,
            verify_per_ball: 32,
            working_samples: 4_000,
            progress: true,
            imports: vec![],
            generator: Generator::default(),
            batch: 4,
            optimizer: None,
            cancel: Arc::new(AtomicBool::new(false)),
            on_accept: None,
        }
    }
}

/// Why the growth loop stopped.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum StopReason {
    /// The coverage lower bound met the target at the requested confidence.
    Covered,
    /// The trajectory budget ran out first.
    Budget { trajectories: usize },
    /// No uncovered sample admits a certifiable trajectory.
    Stuck { failed_seeds: usize },
    /// Algorithm 4's second rule: no uncovered sample is reachable by local variation of the cover (and
    /// a new SCP seed did not help either); `region` says where they lie.
    NeedsSeed {
        region: alg4::UncoveredRegion,
        description: String,
    },
    /// Stopped on request (Ctrl-C) with this many certified trajectories.
    Interrupted { trajectories: usize },
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::Covered => write!(f, "Init covered at the requested confidence"),
            StopReason::Budget { trajectories } => {
                write!(f, "trajectory budget ({trajectories}) ran out before Init was covered")
            }
            StopReason::Stuck { failed_seeds } => write!(
                f,
                "stopped: {failed_seeds} uncovered seed states admit no certifiable trajectory (needs a new seed trajectory)"
            ),
            StopReason::NeedsSeed { description, .. } => write!(
                f,
                "no uncovered sample is reachable by local variation of the cover: needs a new seed trajectory ({description})"
            ),
            StopReason::Interrupted { trajectories } => write!(
                f,
                "interrupted: the image holds the {trajectories} trajectories certified so far"
            ),
        }
    }
}

/// One certified trajectory of the cover.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CoverTrajectory {
    pub source: String,
    pub nominal: Nominal,
    pub certificate: Certificate,
}

/// A coverage estimate through the image's f32 selection: the estimate, the uncovered fresh samples, the image.
type Estimate = (CoverageEstimate, Vec<Vec<f64>>, Vec<u8>);

/// One §5.3 optimisation of the growth loop (accepted or not).
#[derive(Clone, Debug, serde::Serialize)]
pub struct OptRecord {
    /// Growth round it belongs to.
    pub round: usize,
    /// The ball whose boundary it starts on (Algorithm 4), or `None` for an SCP seed.
    pub origin: Option<usize>,
    pub x0: Vec<f64>,
    /// The shipped nominal before optimisation and its certified δ (0 when not certified).
    #[serde(skip)]
    pub before: Nominal,
    pub delta_before: f64,
    /// Certified δ of the re-certified result.
    pub delta_after: f64,
    /// Certified δ per iteration ([0] = start).
    pub history: Vec<f64>,
    pub iterations: usize,
    pub stop: OptStop,
    /// Its index among the trajectories when accepted.
    pub accepted: Option<usize>,
}

impl OptRecord {
    fn new(
        round: usize,
        origin: Option<usize>,
        x0: &[f64],
        before: (Nominal, Certificate),
        after: &Certificate,
        opt: &Optimized,
        accepted: Option<usize>,
    ) -> Self {
        Self {
            round,
            origin,
            x0: x0.to_vec(),
            delta_before: before.1.delta.max(0.0),
            before: before.0,
            delta_after: after.delta.max(0.0),
            history: opt.history.clone(),
            iterations: opt.iterations,
            stop: opt.stop,
            accepted,
        }
    }

    /// δ after ÷ δ before (∞ when the start was not certified).
    pub fn gain(&self) -> f64 {
        if self.delta_before > 0.0 {
            self.delta_after / self.delta_before
        } else {
            f64::INFINITY
        }
    }
}

/// The cover after one growth round.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CoverSnapshot {
    pub round: usize,
    /// Trajectories (the first `trajectories` of the final list).
    pub trajectories: usize,
    /// Working samples still uncovered (full states), discarded ones included.
    #[serde(skip)]
    pub uncovered: Vec<Vec<f64>>,
}

impl CoverSnapshot {
    /// The cover `trajs` and the working samples (`work`, `discarded`) it does not cover yet.
    fn new(
        round: usize,
        P: faer::MatRef<'_, f64>,
        trajs: &[CoverTrajectory],
        work: &[Vec<f64>],
        discarded: &[Vec<f64>],
    ) -> Self {
        Self {
            round,
            trajectories: trajs.len(),
            uncovered: work
                .iter()
                .chain(discarded)
                .filter(|x| alg4::gap(P, x, trajs).is_none_or(|(d, _)| d > 0.0))
                .cloned()
                .collect(),
        }
    }
}

/// Progress bars of the growth loop: accepted trajectories, and the seeds of the current round.
struct Bars {
    trajectories: ProgressBar,
    batch: ProgressBar,
}

impl Bars {
    fn new(progress: bool, budget: u64) -> Self {
        if !progress {
            return Self {
                trajectories: ProgressBar::hidden(),
                batch: ProgressBar::hidden(),
            };
        }
        let mp = indicatif::MultiProgress::new();
        let trajectories = mp.add(bar(true, budget, "trajectories"));
        let batch = mp.add(bar(true, 0, "round"));
        Self {
            trajectories,
            batch,
        }
    }
    fn set_round(&self, round: usize, what: &str) {
        self.batch.set_message(format!("round {round}: {what}"));
    }
    fn clear(&self) {
        self.trajectories.finish_and_clear();
        self.batch.finish_and_clear();
    }
}

/// Everything a run produced.
pub struct Synthesis {
    /// The shipped gain K̂ and the CAF metric P.
    pub K: Mat<f64>,
    pub P: Mat<f64>,
    /// The continuous-time (K, P) of LMI (3.8) for continuous plants (reported, not used by the image).
    pub continuous_caf: Option<(Mat<f64>, Mat<f64>)>,
    pub constants: LoopConstants,
    pub trajectories: Vec<CoverTrajectory>,
    pub image: Vec<u8>,
    pub coverage: CoverageEstimate,
    /// Final coverage samples not covered (full state vectors).
    pub uncovered: Vec<Vec<f64>>,
    pub stop: StopReason,
    /// How the cover grew, every §5.3 optimisation it ran, and the cover after each round.
    pub generator: Generator,
    pub optimization: Vec<OptRecord>,
    pub snapshots: Vec<CoverSnapshot>,
    /// Working samples drawn (the denominator of the snapshots).
    pub working_samples: usize,
    pub verify: VerifyReport,
    pub timings: Vec<(String, f64)>,
    pub warnings: Vec<String>,
}

/// Errors that end a run.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("no CAF and feedback: {0}")]
    Caf(#[from] crate::caf::DesignError),
    #[error(transparent)]
    Certify(#[from] certify::CertifyError),
    #[error("{name}: the recording does not fit n = {n}, m = {m}")]
    Recording { name: String, n: usize, m: usize },
    #[error("image: {0}")]
    Emit(#[from] crate::emit::EmitError),
    #[error("no certified trajectory at all: {0}")]
    Nothing(String),
}

fn bar(progress: bool, len: u64, msg: &str) -> ProgressBar {
    if !progress {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(len);
    b.set_style(
        ProgressStyle::with_template("{msg:>28} [{bar:30}] {pos}/{len} {elapsed}")
            .unwrap_or(ProgressStyle::default_bar()),
    );
    b.set_message(msg.to_string());
    b
}

/// Run the whole pipeline.
pub fn synthesize(task: &Task, opts: &SynthOptions) -> Result<Synthesis, SynthError> {
    let problem = &task.problem;
    let mut timings = Vec::new();
    let t0 = Instant::now();
    let (n, m) = (task.plant.n(), task.plant.m());
    // CAF and feedback for the sampled loop (LMIs (3.66)–(3.67) with the σ-margin of Remark 3.22); what
    // ships, and everything below is certified for, is the f32 gain K̂.
    let design = crate::caf::design(task)?;
    let mut warnings = design.warnings.clone();
    let (Khat, P) = (&design.K, &design.P);
    timings.push(("CAF (SDP)".to_string(), t0.elapsed().as_secs_f64()));

    let lp = Loop::new(task, &design);
    let lc = LoopConstants::new(&lp)?;
    let steps = task.steps;

    // Trajectory generator: the tube conditions of Theorem 4.7 with the inter-sample and rounding margins.
    let gp = GenProblem {
        plant: &*task.plant,
        K: Khat.as_ref(),
        P: P.as_ref(),
        property: &task.property,
        convex: &task.convex,
        steps,
        gamma: lc.gamma,
        phi: lc.phi,
        beta: lc.beta,
        input_margin: 1e-5 * input_scale(&task.property.input),
    };
    let gs = GenSettings::default();
    let shipped = |x0: &[f64], v: &[Vec<f64>]| -> (Nominal, Certificate) {
        certify::shipped(&lp, &lc, x0, v)
    };
    let delta_eps = problem.synthesis.min_robustness;
    let accept = |c: &Certificate| c.is_certified() && c.delta >= delta_eps;
    // Generated references are held over blocks of `reference_hold` samples (move blocking); recorded
    // ones are used as recorded. Algorithm 4's seeds reuse a held reference, and §5.3 keeps it held.
    let hold = problem.synthesis.reference_hold;
    let generated = |x0: &[f64]| -> Option<Vec<Vec<f64>>> {
        let mut v = generate(&gp, x0, &gs).ok()?.nominal.v;
        crate::trajectory::hold::project(&mut v, hold);
        Some(v)
    };
    let make = |x0: &[f64]| -> Option<CoverTrajectory> {
        let v = generated(x0)?;
        let (nominal, certificate) = shipped(x0, &v);
        accept(&certificate).then(|| CoverTrajectory {
            source: "generated".into(),
            nominal,
            certificate,
        })
    };
    let bundle = opts
        .optimizer
        .clone()
        .unwrap_or_else(|| {
            BundleSettings::default().max_iterations(problem.synthesis.max_iterations)
        })
        .hold(hold);
    let cancel: &AtomicBool = &opts.cancel;
    let cancelled = || cancel.load(Ordering::Relaxed);
    // §5.3 on a start (x0, v): maximise the certified δ, then re-certify what the optimiser returns through
    // the shipping path (its answer is never trusted as is). Returns (before, after, optimiser result).
    let optimise = |x0: &[f64], v: &[Vec<f64>]| {
        let before = shipped(x0, v);
        let opt = maximize_delta(&lp, &lc, x0, v, steps, &bundle, cancel);
        let after = shipped(x0, &opt.nominal.v);
        (before, after, opt)
    };
    // A new seed trajectory from the SCP generator, then §5.3 (Algorithm 4's start and its fallback).
    let seed_scp = |x0: &[f64]| {
        let v = generated(x0)?;
        Some(optimise(x0, &v))
    };

    let t1 = Instant::now();
    let init = SampleBox {
        lo: problem.init.lo.clone(),
        hi: problem.init.hi.clone(),
    };
    let mut work_rng = ChaCha8Rng::seed_from_u64(problem.seed);
    let mut work = init.samples(opts.working_samples, &mut work_rng);
    let mut trajs: Vec<CoverTrajectory> = Vec::new();
    // Recorded trajectories first: the nominal of the shipped loop from the recorded x0 and v, certified as is.
    for (name, rec) in &opts.imports {
        if rec.x0.len() != n || rec.v.iter().any(|r| r.len() != m) {
            return Err(SynthError::Recording {
                name: name.clone(),
                n,
                m,
            });
        }
        let x0: Vec<f64> = rec.x0.iter().map(|&v| round32(v)).collect();
        let (nom, cert) = shipped(&x0, &rec.v);
        if cert.is_certified() {
            trajs.push(CoverTrajectory {
                source: format!("csv:{name}"),
                nominal: nom,
                certificate: cert,
            });
        } else {
            warnings.push(format!(
                "{name}: not used, its certified robustness is not positive (δ_Goal {:.3e}, δ_Unsafe {:.3e}, δ_Input {:.3e}, r_crit {:.3e})",
                cert.delta_goal, cert.delta_unsafe_intersample, cert.delta_input, cert.r_crit
            ));
        }
    }
    let mut failed = 0usize;
    let budget = problem.synthesis.max_trajectories;
    // A fixed batch size: the seeds of a round, and so the result, must not depend on the thread count.
    let batch = opts.batch.max(1);
    let bars = Bars::new(opts.progress, budget as u64);
    let on_accept = |count: usize| {
        bars.trajectories.inc(1);
        if let Some(h) = &opts.on_accept {
            (h.0)(count);
        }
    };
    // Enough fresh samples that a fully covered sample proves the target (and the spec's tolerance).
    let n_final =
        problem
            .synthesis
            .coverage_samples()
            .max(if problem.synthesis.coverage_target < 1.0 {
                crate::coverage::samples_needed(
                    problem.synthesis.coverage_target,
                    problem.synthesis.confidence,
                )
            } else {
                0 // a finite sample never proves 100 %: the loop stops on its budget and says so
            });
    // Final, independent estimate on fresh samples through the f32 selection of the image.
    let estimate = |trajs: &[CoverTrajectory], round: u64| -> Result<Estimate, SynthError> {
        let image = build_image(task, Khat, P, trajs)?;
        let img = shared_types::image::decode(&image)
            .map_err(|e| SynthError::Nothing(format!("{e:?}")))?;
        let ctl = shared_types::eval::Controller::new(img);
        let mut frng =
            ChaCha8Rng::seed_from_u64(problem.seed ^ 0x5eed_c0fe_u64.wrapping_add(round));
        let pts = init.samples(n_final, &mut frng);
        let unc: Vec<Vec<f64>> = pts
            .par_iter()
            .filter(|x| {
                let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
                ctl.select(&xf).is_none()
            })
            .cloned()
            .collect();
        let est = CoverageEstimate::from_counts(
            n_final,
            n_final - unc.len(),
            problem.synthesis.confidence,
        );
        Ok((est, unc, image))
    };
    let free = problem.init.free_coords();
    let mut final_round = 0u64;
    let mut round = 0usize;
    let mut records: Vec<OptRecord> = Vec::new();
    let mut snapshots: Vec<CoverSnapshot> = Vec::new();
    // Algorithm 4: uncovered samples whose projection no local variation certifies (δ < δε or nothing new).
    let mut discarded: Vec<Vec<f64>> = Vec::new();
    let outside = |trajs: &[CoverTrajectory], x: &[f64]| {
        alg4::gap(P.as_ref(), x, trajs).is_none_or(|(d, _)| d > 0.0)
    };
    let (stop, coverage, uncovered, image) = loop {
        work.retain(|x| outside(&trajs, x));
        discarded.retain(|x| outside(&trajs, x));
        if !trajs.is_empty() && cancelled() {
            let (est, unc, image) = estimate(&trajs, final_round)?;
            break (
                StopReason::Interrupted {
                    trajectories: trajs.len(),
                },
                est,
                unc,
                image,
            );
        }
        if cancelled() {
            bars.clear();
            return Err(SynthError::Nothing(
                "interrupted before any trajectory was certified".into(),
            ));
        }
        // Algorithm 4's second stopping rule: every uncovered sample left was discarded. One new seed
        // trajectory from the SCP generator (where the most distant of them lies) before giving up.
        if opts.generator == Generator::Algorithm4
            && work.is_empty()
            && !discarded.is_empty()
            && trajs.len() < budget
        {
            round += 1;
            let far = discarded
                .iter()
                .enumerate()
                .map(|(i, x)| {
                    (
                        i,
                        alg4::gap(P.as_ref(), x, &trajs).map_or(f64::INFINITY, |g| g.0),
                    )
                })
                .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a })
                .0;
            let x0: Vec<f64> = discarded[far].iter().map(|&v| round32(v)).collect();
            bars.set_round(round, "new seed trajectory (SCP)");
            let made = seed_scp(&x0);
            let mut ok = false;
            if let Some((before, (nominal, certificate), opt)) = made {
                ok = accept(&certificate)
                    && !outside(
                        std::slice::from_ref(&CoverTrajectory {
                            source: String::new(),
                            nominal: nominal.clone(),
                            certificate: certificate.clone(),
                        }),
                        &discarded[far],
                    );
                records.push(OptRecord::new(
                    round,
                    None,
                    &x0,
                    before,
                    &certificate,
                    &opt,
                    ok.then_some(trajs.len()),
                ));
                if ok {
                    trajs.push(CoverTrajectory {
                        source: "generated (SCP) + §5.3".into(),
                        nominal,
                        certificate,
                    });
                    on_accept(trajs.len());
                }
            }
            if ok {
                // The new seed may make the discarded samples reachable again.
                work.append(&mut discarded);
                snapshots.push(CoverSnapshot::new(
                    round,
                    P.as_ref(),
                    &trajs,
                    &work,
                    &discarded,
                ));
                continue;
            }
            let mut rest = discarded.clone();
            let (est, unc, image) = estimate(&trajs, final_round)?;
            rest.extend(unc.iter().cloned());
            let typical =
                median(trajs.iter().map(|t| t.certificate.delta_stored as f64)).unwrap_or(0.05);
            let region = alg4::UncoveredRegion::of(P.as_ref(), &rest, 4.0 * typical)
                .expect("discarded is not empty");
            let description = region.describe(&free);
            snapshots.push(CoverSnapshot::new(
                round,
                P.as_ref(),
                &trajs,
                &work,
                &discarded,
            ));
            break (
                StopReason::NeedsSeed {
                    region,
                    description,
                },
                est,
                unc,
                image,
            );
        }
        if work.is_empty() || trajs.len() >= budget {
            let (est, unc, image) = estimate(&trajs, final_round)?;
            final_round += 1;
            let target = problem.synthesis.coverage_target;
            if est.lower >= target {
                break (StopReason::Covered, est, unc, image);
            }
            if trajs.len() >= budget {
                break (
                    StopReason::Budget {
                        trajectories: budget,
                    },
                    est,
                    unc,
                    image,
                );
            }
            if unc.is_empty() || final_round > 8 {
                break (
                    StopReason::Stuck {
                        failed_seeds: failed,
                    },
                    est,
                    unc,
                    image,
                );
            }
            // Not yet: the fresh sample found holes; use them as seeds and estimate again afterwards.
            work = unc;
            continue;
        }
        round += 1;
        let room = budget - trajs.len();
        if opts.generator == Generator::Algorithm4 && trajs.is_empty() {
            // The first seed: the SCP generator from the centre of Init (then from working samples in
            // order), optimised by §5.3 like every later one.
            bars.set_round(round, "first seed (SCP + §5.3)");
            let centre: Vec<f64> = init
                .lo
                .iter()
                .zip(&init.hi)
                .map(|(l, h)| round32(0.5 * (l + h)))
                .collect();
            let seeds: Vec<Vec<f64>> = std::iter::once(centre)
                .chain(
                    work.iter()
                        .take(batch - 1)
                        .map(|x| x.iter().map(|&v| round32(v)).collect()),
                )
                .collect();
            let made: Vec<_> = seeds.par_iter().map(|s| seed_scp(s)).collect();
            let mut got = false;
            for (s, r) in seeds.iter().zip(made) {
                match r {
                    Some((before, (nominal, certificate), opt)) if !got && accept(&certificate) => {
                        records.push(OptRecord::new(
                            round,
                            None,
                            s,
                            before,
                            &certificate,
                            &opt,
                            Some(0),
                        ));
                        trajs.push(CoverTrajectory {
                            source: "generated (SCP) + §5.3".into(),
                            nominal,
                            certificate,
                        });
                        on_accept(trajs.len());
                        got = true;
                    }
                    Some(_) if got => {}
                    _ => {
                        failed += 1;
                        work.retain(|x| alg4::dist(P.as_ref(), x, s) > 0.0125);
                    }
                }
            }
            if !got && work.is_empty() {
                bars.clear();
                return Err(SynthError::Nothing(format!(
                    "{failed} seeds from Init gave no certifiable trajectory"
                )));
            }
            snapshots.push(CoverSnapshot::new(
                round,
                P.as_ref(),
                &trajs,
                &work,
                &discarded,
            ));
            continue;
        }
        let typical =
            median(trajs.iter().map(|t| t.certificate.delta_stored as f64)).unwrap_or(0.05);
        match opts.generator {
            Generator::Algorithm4 => {
                // (5.32) for every uncovered sample; nearest first (ties: sample order).
                let mut pool: Vec<(f64, usize, usize)> = work
                    .iter()
                    .enumerate()
                    .filter_map(|(i, y)| alg4::gap(P.as_ref(), y, &trajs).map(|(d, m)| (d, m, i)))
                    .collect();
                pool.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
                let mut items: Vec<(usize, usize, Vec<f64>)> = Vec::new(); // (sample, ball m, ŷ)
                let mut drop: Vec<usize> = Vec::new();
                for &(_, mi, i) in &pool {
                    if items.len() >= batch.min(room) {
                        break;
                    }
                    let tm = &trajs[mi];
                    // The δε floor: a ball below it is not grown further.
                    if (tm.certificate.delta_stored as f64) < delta_eps {
                        drop.push(i);
                        continue;
                    }
                    let Some(yh) = alg4::project_onto_boundary(
                        P.as_ref(),
                        &work[i],
                        &tm.nominal.x[0],
                        tm.certificate.delta_stored as f64,
                    ) else {
                        drop.push(i);
                        continue;
                    };
                    // Spread a batch: one seed per neighbourhood of the typical radius.
                    if items
                        .iter()
                        .any(|(_, _, z)| alg4::dist(P.as_ref(), z, &yh) < typical)
                    {
                        continue;
                    }
                    items.push((i, mi, yh));
                }
                bars.set_round(round, "optimising (Algorithm 4, §5.3)");
                bars.batch.set_length(items.len() as u64);
                bars.batch.set_position(0);
                let made: Vec<_> = items
                    .par_iter()
                    .map(|(_, mi, yh)| {
                        let v = alg4::feedback_law_reference(&trajs[*mi]);
                        let r = optimise(yh, &v);
                        bars.batch.inc(1);
                        r
                    })
                    .collect();
                for ((i, mi, yh), (before, (nominal, certificate), opt)) in items.iter().zip(made) {
                    let cand = CoverTrajectory {
                        source: format!("Algorithm 4 from #{mi} + §5.3"),
                        nominal,
                        certificate,
                    };
                    // Accept when certified at the δε floor and it covers its target or some sample
                    // still uncovered (earlier acceptances of this round included).
                    let ok = accept(&cand.certificate)
                        && (alg4::covers(P.as_ref(), &cand, &work[*i])
                            || work
                                .iter()
                                .any(|x| alg4::covers(P.as_ref(), &cand, x) && outside(&trajs, x)));
                    records.push(OptRecord::new(
                        round,
                        Some(*mi),
                        yh,
                        before,
                        &cand.certificate,
                        &opt,
                        ok.then_some(trajs.len()),
                    ));
                    if ok {
                        trajs.push(cand);
                        on_accept(trajs.len());
                    } else {
                        failed += 1;
                        drop.push(*i);
                        // Samples that project onto the same ball within half the typical radius of ŷ
                        // start the same reference sequence from nearly the same state, and δ depends
                        // continuously on the start: discard them with it rather than retry each one.
                        let tm = &trajs[*mi];
                        for &(_, m2, j) in &pool {
                            if m2 == *mi && j != *i {
                                let close = alg4::project_onto_boundary(
                                    P.as_ref(),
                                    &work[j],
                                    &tm.nominal.x[0],
                                    tm.certificate.delta_stored as f64,
                                )
                                .is_some_and(|z| alg4::dist(P.as_ref(), &z, yh) < 0.5 * typical);
                                if close {
                                    drop.push(j);
                                }
                            }
                        }
                    }
                }
                drop.sort_unstable();
                drop.dedup();
                for &i in drop.iter().rev() {
                    discarded.push(work.swap_remove(i));
                }
            }
            Generator::Scp => {
                // Algorithm 1: seeds are uncovered working samples, farthest first (greedy, spread by the
                // typical radius).
                let outside_by = |x: &[f64], extra: &[Vec<f64>]| -> f64 {
                    let mut d = alg4::gap(P.as_ref(), x, &trajs).map_or(f64::INFINITY, |g| g.0);
                    for c in extra {
                        d = d.min(alg4::dist(P.as_ref(), x, c) - typical);
                    }
                    d
                };
                let mut seeds: Vec<Vec<f64>> = Vec::new();
                let mut cand = work.clone();
                while seeds.len() < batch.min(room) && !cand.is_empty() {
                    let (best, _) = cand
                        .iter()
                        .enumerate()
                        .map(|(i, x)| (i, outside_by(x, &seeds)))
                        .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
                    let s: Vec<f64> = cand.swap_remove(best).iter().map(|&v| round32(v)).collect();
                    cand.retain(|x| alg4::dist(P.as_ref(), x, &s) > typical);
                    seeds.push(s);
                }
                bars.set_round(round, "generating (SCP, Algorithm 1)");
                let made: Vec<Option<CoverTrajectory>> =
                    seeds.par_iter().map(|s| make(s)).collect();
                let mut progress = false;
                for (s, t) in seeds.iter().zip(made) {
                    match t {
                        Some(t) => {
                            trajs.push(t);
                            progress = true;
                            on_accept(trajs.len());
                        }
                        None => {
                            failed += 1;
                            // Drop the seed and its close neighbours from the working set so the loop moves
                            // on; the final fresh sample will find any hole this leaves.
                            work.retain(|x| alg4::dist(P.as_ref(), x, s) > 0.25 * typical);
                        }
                    }
                }
                if !progress && work.is_empty() && trajs.is_empty() {
                    bars.clear();
                    return Err(SynthError::Nothing(format!(
                        "{failed} seeds from Init gave no certifiable trajectory"
                    )));
                }
            }
        }
        snapshots.push(CoverSnapshot::new(
            round,
            P.as_ref(),
            &trajs,
            &work,
            &discarded,
        ));
    };
    bars.clear();
    if trajs.is_empty() {
        return Err(SynthError::Nothing(
            "no trajectory could be certified".into(),
        ));
    }
    timings.push((
        match opts.generator {
            Generator::Algorithm4 => "cover (Algorithm 4 + §5.3)",
            Generator::Scp => "cover (Algorithm 1, SCP)",
        }
        .to_string(),
        t1.elapsed().as_secs_f64(),
    ));
    if stop != StopReason::Covered {
        warnings.push(stop.to_string());
    }

    // Independent verification through the shared evaluator.
    let t2 = Instant::now();
    let img =
        shared_types::image::decode(&image).map_err(|e| SynthError::Nothing(format!("{e:?}")))?;
    let judge = Judge::new(task);
    let verify = monte_carlo(
        &judge,
        &img,
        opts.verify_interior,
        opts.verify_per_ball,
        problem.seed ^ 0x7e51f1,
    );
    timings.push(("verification".to_string(), t2.elapsed().as_secs_f64()));
    if verify.violations > 0 {
        warnings.push(format!(
            "verification found {} violations: the image is NOT certified",
            verify.violations
        ));
    }
    Ok(Synthesis {
        K: design.K.clone(),
        P: design.P.clone(),
        continuous_caf: design.continuous.clone(),
        constants: lc,
        trajectories: trajs,
        image,
        coverage,
        uncovered,
        stop,
        generator: opts.generator,
        optimization: records,
        snapshots,
        working_samples: opts.working_samples,
        verify,
        timings,
        warnings,
    })
}

fn median(it: impl Iterator<Item = f64>) -> Option<f64> {
    let mut v: Vec<f64> = it.collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    Some(v[v.len() / 2])
}

/// The feedforward image of a cover (Algorithm 2): the f32 gain and metric, each ball with its stored
/// radius, and each reference table; terminal behaviour keeps the last law; fallback per the input set.
pub fn build_image(
    task: &Task,
    Khat: &Mat<f64>,
    P: &Mat<f64>,
    trajs: &[CoverTrajectory],
) -> Result<Vec<u8>, SynthError> {
    let plant = &*task.plant;
    let mut b = ImageBuilder::new(plant.n(), plant.m(), plant.period());
    b.add_location(
        crate::linalg::to_row_major(Khat.as_ref()),
        crate::linalg::to_row_major(P.as_ref()),
    );
    for t in trajs {
        b.add_trajectory(TrajectoryEntry {
            x0: t.nominal.x[0].clone(),
            delta: t.certificate.delta_stored as f64,
            v: t.nominal.v.concat(),
            location: vec![0; t.nominal.v.len()],
        });
    }
    if let crate::spec::InputSet::Box { lo, hi } = &task.problem.input {
        b.input_box = Some((lo.clone(), hi.clone()));
    }
    b.fallback = FallbackLaw::Zero;
    Ok(b.to_bytes()?)
}
