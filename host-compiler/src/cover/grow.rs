//! The growth loop (Algorithms 1 and 4, §5.4): certify the imported recordings, start from a first seed
//! (the SCP generator from the centre of Init, then §5.3), then grow round by round from the uncovered
//! working samples, until Init is covered at the requested confidence (checked on fresh samples through
//! the image's own f32 selection), the budget is spent, no local variation reaches the rest ("needs a
//! new seed trajectory"), or the run is cancelled.
//!
//! Everything random is drawn from ChaCha streams seeded by the task's seed, and the seeds of a round are
//! a fixed batch collected in order, so the cover does not depend on the number of threads.

use super::estimate::{self, CoverageEstimate, SampleBox};
use super::seeds::{
    certify_recording, recording_refusal, Ask, Generators, Origin, Seed, Source, Sources,
};
use super::{
    alg4, feedforward_image, AcceptHook, Cover, CoverTrajectory, Generator, OptStart, StopReason,
};
use crate::certify::{self, Certificate, Loop, LoopConstants};
use crate::emit::EmitError;
use crate::linalg::round32;
use crate::optimize::{maximize_delta, BundleSettings};
use crate::property::input_scale;
use crate::task::Task;
use crate::trajectory::csv::Recording;
use crate::trajectory::generate::{GenError, GenProblem};
use crate::trajectory::Nominal;
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};

/// What the growth takes from the run's options (`synth::SynthOptions` documents the defaults).
pub struct GrowOptions<'a> {
    pub working_samples: usize,
    pub progress: bool,
    pub imports: &'a [(String, Recording)],
    pub generator: Generator,
    pub batch: usize,
    pub optimizer: Option<&'a BundleSettings>,
    pub cancel: &'a AtomicBool,
    pub on_accept: Option<&'a AcceptHook>,
}

/// What the growth produced.
pub struct Grown {
    pub cover: Cover,
    pub stop: StopReason,
    /// The final coverage estimate on fresh samples, the samples it found uncovered, and the image.
    pub coverage: CoverageEstimate,
    pub uncovered: Vec<Vec<f64>>,
    pub image: Vec<u8>,
    /// Recordings refused, and why.
    pub warnings: Vec<String>,
}

/// Why the growth produced no cover.
#[derive(Debug, thiserror::Error)]
pub enum GrowError {
    #[error(transparent)]
    Settings(#[from] crate::settings::SettingError),
    #[error("{name}: the recording does not fit n = {n}, m = {m}")]
    Recording { name: String, n: usize, m: usize },
    #[error("image: {0}")]
    Emit(#[from] EmitError),
    #[error("the emitted image is rejected by the decoder: {0}")]
    ImageRejected(shared_types::image::ImageError),
    #[error("no certified trajectory at all: interrupted before any trajectory was certified")]
    InterruptedEmpty,
    #[error(
        "no certified trajectory at all: {failed} seeds from Init gave no certifiable trajectory; {attempts}"
    )]
    NoSeed {
        failed: usize,
        attempts: Box<Attempts>,
    },
    #[error("no certified trajectory at all: no trajectory could be certified; {attempts}")]
    NothingCertified { attempts: Box<Attempts> },
    #[error(
        "no certified trajectory at all, and none can be, so no seed was tried: {ceiling}, below the \
         admission floor δε = {floor:.3e} (min_robustness, or 0); the loop (its period, its gain, the input \
         set) must change before any nominal trajectory can be certified"
    )]
    Ceiling {
        ceiling: certify::Ceiling,
        floor: f64,
    },
}

/// What the attempts that certified nothing ended with, for the "no certified trajectory" errors: the
/// certificate of the best attempt (largest min(δ_Goal, δ_Unsafe, δ_Input)) and its binding part, whether
/// any trajectory tried reached Goal within T (δ_Goal > 0), and the generator's refusals.
#[derive(Debug, Default)]
pub struct Attempts {
    /// The horizon T in seconds (for the message).
    pub horizon: f64,
    /// Trajectories certified and refused (before and after §5.3 count separately; where the generator
    /// found none, the loop without a reference, v ≡ 0, from that seed).
    pub certified: usize,
    /// The best of them.
    pub best: Option<Certificate>,
    /// The largest δ_Goal over them (−∞ when there is none).
    pub best_goal: f64,
    /// Seeds from which the generator found no trajectory to certify, and its first reason.
    pub not_generated: usize,
    pub first_refusal: Option<GenError>,
    /// The recordings given (`--import`) that were refused, and why.
    pub imports: Vec<(String, String)>,
    /// Set when the search stopped after its first round of seeds because every recording given was
    /// refused ([`grow`]): the seeds that round tried.
    pub stopped_after: Option<usize>,
}

impl Attempts {
    fn new(horizon: f64) -> Self {
        Self {
            horizon,
            best_goal: f64::NEG_INFINITY,
            ..Self::default()
        }
    }

    /// A refused certificate.
    fn certificate(&mut self, c: &Certificate) {
        self.certified += 1;
        if c.delta_goal > self.best_goal {
            self.best_goal = c.delta_goal;
        }
        let score = |c: &Certificate| {
            let d = c.parts_min();
            if d.is_nan() {
                f64::NEG_INFINITY
            } else {
                d
            }
        };
        if self.best.as_ref().is_none_or(|b| score(c) > score(b)) {
            self.best = Some(c.clone());
        }
    }

    /// A seed the generator found no trajectory from.
    fn refusal(&mut self, e: GenError) {
        self.not_generated += 1;
        if self.first_refusal.is_none() {
            self.first_refusal = Some(e);
        }
    }

    /// A recording given that was refused, and why.
    fn import(&mut self, name: &str, why: String) {
        self.imports.push((name.to_string(), why));
    }

    /// The refused recordings, first in the message: the route given is what a user mends.
    fn imports_text(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.imports.is_empty() {
            return Ok(());
        }
        write!(f, "every recording given was refused:")?;
        for (name, why) in &self.imports {
            write!(f, " {name}: {why};")?;
        }
        write!(f, " and from Init: ")
    }

    /// The early stop, last in the message.
    fn stop_text(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.stopped_after {
            Some(seeds) => write!(
                f,
                "; the search stopped after its first round ({seeds} seeds from Init, each through the \
                 local generator and the routes of the global search) rather than try the rest of \
                 Init's samples for minutes: the route given is the one to mend (why it was refused is \
                 above; `play` shows a run's margins as it goes), or run without --import to let the \
                 search go on over Init"
            ),
            None => Ok(()),
        }
    }

    /// Whether some trajectory tried reached Goal within T with a positive margin (δ_Goal > 0).
    pub fn goal_reached(&self) -> bool {
        self.best_goal > 0.0
    }
}

impl std::fmt::Display for Attempts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let t = self.horizon;
        self.imports_text(f)?;
        match &self.best {
            Some(best) => {
                write!(
                    f,
                    "the best of {} trajectories tried is bound by {} (δ_Goal {:.3e}, δ_Unsafe {:.3e} \
                     between samples, δ_Input {:.3e}, r_crit {:.3e}); ",
                    self.certified,
                    best.binding(),
                    best.delta_goal,
                    best.delta_unsafe_intersample,
                    best.delta_input,
                    best.r_crit
                )?;
                if self.goal_reached() {
                    write!(
                        f,
                        "Goal was reached within T = {t} s by some trajectory tried (largest δ_Goal \
                         {:.3e} > 0)",
                        self.best_goal
                    )?;
                } else {
                    write!(
                        f,
                        "Goal was not reached within T = {t} s from any sample tried (largest δ_Goal \
                         {:.3e} ≤ 0)",
                        self.best_goal
                    )?;
                }
                if let Some(e) = &self.first_refusal {
                    write!(
                        f,
                        "; from {} seeds the generator found no trajectory (first: {e}), and the loop \
                         without a reference (v = 0) was certified from them instead",
                        self.not_generated
                    )?;
                }
                self.stop_text(f)
            }
            None => {
                match &self.first_refusal {
                    Some(e) => write!(
                        f,
                        "from every seed ({}) the generator found no trajectory to certify, so Goal was \
                         not reached within T = {t} s from any sample tried (first: {e})",
                        self.not_generated
                    ),
                    None => write!(f, "no trajectory was tried"),
                }?;
                self.stop_text(f)
            }
        }
    }
}

/// A coverage estimate through the image's f32 selection: the estimate, the uncovered fresh samples, the image.
type Estimate = (CoverageEstimate, Vec<Vec<f64>>, Vec<u8>);

/// Progress bars of the growth loop: accepted trajectories, and the seeds of the current round. When
/// stderr is not a terminal (a CI log, `nohup`), indicatif draws nothing, so each round is also printed
/// as a plain line.
struct Bars {
    trajectories: ProgressBar,
    batch: ProgressBar,
    plain: bool,
}

impl Bars {
    fn new(progress: bool, budget: u64) -> Self {
        if !progress {
            return Self {
                trajectories: ProgressBar::hidden(),
                batch: ProgressBar::hidden(),
                plain: false,
            };
        }
        let mp = indicatif::MultiProgress::new();
        let trajectories = mp.add(bar(true, budget, "trajectories"));
        let batch = mp.add(bar(true, 0, "round"));
        Self {
            trajectories,
            batch,
            plain: !std::io::IsTerminal::is_terminal(&std::io::stderr()),
        }
    }
    fn set_round(&self, round: usize, what: &str) {
        let line = format!("round {round}: {what}");
        if self.plain {
            eprintln!("{line}");
        }
        self.batch.set_message(line);
    }
    fn clear(&self) {
        self.trajectories.finish_and_clear();
        self.batch.finish_and_clear();
    }
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

/// Grows the cover of the task's Init for the loop `lp` (module doc).
pub fn grow(
    task: &Task,
    lp: &Loop<'_>,
    lc: &LoopConstants,
    opts: &GrowOptions<'_>,
) -> Result<Grown, GrowError> {
    let problem = &task.problem;
    let (n, m) = (task.plant.n(), task.plant.m());
    let (K, P) = (&lp.K.to_owned(), &lp.P.to_owned());
    let steps = task.steps;
    let mut warnings = Vec::new();
    let mut cover = Cover::new(P.clone());
    // Trajectory generator: the tube conditions of Theorem 4.7 with the inter-sample and rounding margins.
    let gp = GenProblem {
        loc: 0,
        plant: &*task.plant,
        K: K.as_ref(),
        P: P.as_ref(),
        property: &task.property,
        convex: &task.convex,
        steps,
        gamma: lc.gamma,
        phi: lc.phi,
        beta: lc.beta,
        input_margin: 1e-5 * input_scale(&task.property.input),
        schedule: None,
    };
    let shipped =
        |x0: &[f64], v: &[Vec<f64>]| -> (Nominal, Certificate) { certify::shipped(lp, lc, x0, v) };
    let delta_eps = problem.synthesis.min_robustness;
    let accept = |c: &Certificate| c.is_certified() && c.delta >= delta_eps;
    // The seed sources (`super::seeds`): the SCP generator, then the routes of the global search.
    // Generated references are held over blocks of `reference_hold` samples (move blocking); recorded
    // ones are used as recorded. Algorithm 4's seeds reuse a held reference, and §5.3 keeps it held.
    let hold = problem.synthesis.reference_hold;
    let gens =
        Generators::new(&gp, hold).with_routes(&task.convex, &problem.init.lo, &problem.init.hi);
    let bundle = match opts.optimizer {
        Some(b) => b.clone().to_builder(),
        None => BundleSettings::builder().max_iterations(problem.synthesis.max_iterations),
    }
    .hold(hold)
    .build()?;
    let cancel: &AtomicBool = opts.cancel;
    let cancelled = || cancel.load(Ordering::Relaxed);
    // §5.3 on a start (x0, v): maximise the certified δ, then re-certify what the optimiser returns through
    // the shipping path (its answer is never trusted as is). Returns (before, after, optimiser result).
    let optimise = |x0: &[f64], v: &[Vec<f64>]| {
        let before = shipped(x0, v);
        let opt = maximize_delta(lp, lc, x0, v, steps, &bundle, cancel);
        let after = shipped(x0, &opt.nominal.v);
        (before, after, opt)
    };
    // A new seed trajectory from the SCP generator, then §5.3 (Algorithm 4's start and its fallback).
    // Where the generator finds nothing: the certificate of the loop without a reference (v ≡ 0), so that
    // a "no trajectory" error still says which δ part fails and how far Goal is.
    let unforced = |x0: &[f64]| shipped(x0, &vec![vec![0.0; m]; steps]).1;
    let seed_scp = |x0: &[f64]| {
        let v = gens.generated(x0)?;
        Ok::<_, GenError>(optimise(x0, &v))
    };
    // The routes of the global search, where the plain generator found no accepted trajectory from a
    // seed: each route's reference then §5.3; the first accepted result, with its route's index.
    let from_routes = |x0: &[f64]| {
        gens.routed(x0).find_map(|p| {
            let made = optimise(x0, &p.candidate);
            accept(&made.1 .1).then_some((p.origin, made))
        })
    };
    // Algorithm 1's seed: the seed's sources in order, certified without §5.3 (the plain generator, then
    // the routes of the global search where it gives none accepted), or why not (the plain generator's
    // refused certificate, or its reason).
    let make = |x0: &[f64]| -> Result<CoverTrajectory, Result<Certificate, GenError>> {
        let plain = gens.generated(x0).map(|v| shipped(x0, &v));
        if let Ok((nominal, certificate)) = &plain {
            if accept(certificate) {
                return Ok(CoverTrajectory {
                    source: Source::new(Origin::Generator, false),
                    nominal: nominal.clone(),
                    certificate: certificate.clone(),
                });
            }
        }
        let routed = gens.routed(x0).find_map(|p| {
            let (nominal, certificate) = shipped(x0, &p.candidate);
            accept(&certificate).then(|| CoverTrajectory {
                source: Source::new(p.origin, false),
                nominal,
                certificate,
            })
        });
        match (routed, plain) {
            (Some(t), _) => Ok(t),
            (None, Ok((_, c))) => Err(Ok(c)),
            (None, Err(e)) => Err(Err(e)),
        }
    };

    let init = SampleBox {
        lo: problem.init.lo.clone(),
        hi: problem.init.hi.clone(),
    };
    let mut work_rng = ChaCha8Rng::seed_from_u64(problem.seed);
    let mut work = init.samples(opts.working_samples, &mut work_rng);
    let mut attempts = Attempts::new(problem.horizon);
    // Recorded trajectories first: the nominal of the shipped loop from the recorded x0 and v, certified as is.
    for (name, rec) in opts.imports {
        if rec.x0.len() != n || rec.v.iter().any(|r| r.len() != m) {
            return Err(GrowError::Recording {
                name: name.clone(),
                n,
                m,
            });
        }
        match certify_recording(lp, lc, rec) {
            Ok((nom, cert)) if cert.is_certified() => cover.push(
                CoverTrajectory {
                    source: Source::import(name),
                    nominal: nom,
                    certificate: cert,
                },
                None,
            ),
            Ok((_, cert)) => {
                attempts.certificate(&cert);
                let why = recording_refusal(&cert, lp.model().period);
                warnings.push(format!(
                    "{name}: not used, its certified robustness is not positive: {why}"
                ));
                attempts.import(name, why);
            }
            Err(crate::trajectory::track::TrackError::Dimension { .. }) => {
                return Err(GrowError::Recording {
                    name: name.clone(),
                    n,
                    m,
                });
            }
            Err(e) => {
                warnings.push(format!("{name}: not used: {e}"));
                attempts.import(name, e.to_string());
            }
        }
    }
    // Before any seed: a loop whose every certificate of this length is below the floor admits nothing
    // (`certify::ceiling`), whatever the search proposes.
    if cover.trajectories.is_empty() {
        let ceiling = certify::Ceiling::of(lp, lc, steps);
        if ceiling.below(delta_eps) {
            return Err(GrowError::Ceiling {
                ceiling,
                floor: delta_eps,
            });
        }
    }
    // When recordings were given and every one was refused, the route given is the one to mend: the
    // search stops after its first round of seeds if that round certifies nothing either. Its first
    // round is the centre of Init and a batch of working samples, each through the local generator,
    // §5.3 and the routes of the global search; later rounds only move the start across Init, from
    // which the same generator and routes rarely do better, at tens of seconds a seed.
    let imports_refused = !opts.imports.is_empty() && cover.trajectories.is_empty();
    let mut failed = 0usize;
    let budget = problem.synthesis.max_trajectories;
    // A fixed batch size: the seeds of a round, and so the result, must not depend on the thread count.
    let batch = opts.batch.max(1);
    let bars = Bars::new(opts.progress, budget as u64);
    let on_accept = |count: usize| {
        bars.trajectories.inc(1);
        if let Some(h) = opts.on_accept {
            (h.0)(count);
        }
    };
    // Enough fresh samples that a fully covered sample proves the target (and the spec's tolerance); for a
    // target of 1 the loop stops on its budget and says so.
    let n_final = estimate::final_samples(&problem.synthesis);
    // Final, independent estimate on fresh samples through the f32 selection of the image.
    let estimate = |trajs: &[CoverTrajectory], round: u64| -> Result<Estimate, GrowError> {
        let image = feedforward_image(task, K, P, trajs)?;
        let img = shared_types::image::decode(&image).map_err(GrowError::ImageRejected)?;
        let ctl = shared_types::eval::Controller::new(img);
        let mut frng =
            ChaCha8Rng::seed_from_u64(problem.seed ^ 0x5eed_c0fe_u64.wrapping_add(round));
        let pts = init.samples(n_final, &mut frng);
        let unc: Vec<Vec<f64>> = pts
            .par_iter()
            .filter(|x| {
                let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
                ctl.select_maps(&xf).is_none()
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
    let mut centre_tried = false;
    // Algorithm 4: uncovered samples whose projection no local variation certifies (δ < δε or nothing new).
    let mut discarded: Vec<Vec<f64>> = Vec::new();
    let outside = |trajs: &[CoverTrajectory], x: &[f64]| {
        alg4::gap(P.as_ref(), x, trajs).is_none_or(|(d, _)| d > 0.0)
    };
    let (stop, coverage, uncovered, image) = loop {
        work.retain(|x| outside(&cover.trajectories, x));
        discarded.retain(|x| outside(&cover.trajectories, x));
        if !cover.trajectories.is_empty() && cancelled() {
            let (est, unc, image) = estimate(&cover.trajectories, final_round)?;
            break (
                StopReason::Interrupted {
                    trajectories: cover.trajectories.len(),
                },
                est,
                unc,
                image,
            );
        }
        if cancelled() {
            bars.clear();
            return Err(GrowError::InterruptedEmpty);
        }
        // Algorithm 4's second stopping rule: every uncovered sample left was discarded. One new seed
        // trajectory from the SCP generator (where the most distant of them lies) before giving up.
        if opts.generator == Generator::Algorithm4
            && work.is_empty()
            && !discarded.is_empty()
            && cover.trajectories.len() < budget
        {
            round += 1;
            let far = discarded
                .iter()
                .enumerate()
                .map(|(i, x)| {
                    (
                        i,
                        alg4::gap(P.as_ref(), x, &cover.trajectories)
                            .map_or(f64::INFINITY, |g| g.0),
                    )
                })
                .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a })
                .0;
            let x0: Vec<f64> = discarded[far].iter().map(|&v| round32(v)).collect();
            bars.set_round(round, "new seed trajectory (SCP)");
            let covers_far = |nominal: &Nominal, certificate: &Certificate| {
                accept(certificate)
                    && !outside(
                        std::slice::from_ref(&CoverTrajectory {
                            source: Source::new(Origin::Generator, false),
                            nominal: nominal.clone(),
                            certificate: certificate.clone(),
                        }),
                        &discarded[far],
                    )
            };
            // The seed's sources in order, each then §5.3: the plain generator, kept (for the record) unless
            // a route's does cover the sample; of the routes only the first accepted one is looked at.
            let seed = Seed::at(x0.clone());
            let src = gens.over(Vec::new());
            let mut made = None;
            for p in src.proposals(&seed) {
                let Ok(v) = p.candidate else { continue };
                let m = optimise(&x0, &v);
                let plain = p.origin == Origin::Generator;
                let (accepted, far) = (accept(&m.1 .1), covers_far(&m.1 .0, &m.1 .1));
                if plain || far {
                    made = Some((p.origin, m));
                }
                if far || (accepted && !plain) {
                    break;
                }
            }
            let mut ok = false;
            if let Some((origin, (before, (nominal, certificate), opt))) = made {
                ok = covers_far(&nominal, &certificate);
                cover.record(
                    OptStart::new(round, None, &x0, before, opt),
                    CoverTrajectory {
                        source: Source::new(origin, true),
                        nominal,
                        certificate,
                    },
                    ok,
                    &on_accept,
                );
            }
            if ok {
                // The new seed may make the discarded samples reachable again.
                work.append(&mut discarded);
                cover.snapshot(round, &work, &discarded);
                continue;
            }
            let mut rest = discarded.clone();
            let (est, unc, image) = estimate(&cover.trajectories, final_round)?;
            rest.extend(unc.iter().cloned());
            let typical = alg4::median(
                cover
                    .trajectories
                    .iter()
                    .map(|t| t.certificate.delta_stored as f64),
            )
            .unwrap_or(0.05);
            let region = alg4::UncoveredRegion::of(P.as_ref(), &rest, 4.0 * typical)
                .expect("discarded is not empty");
            let description = region.describe(&free);
            cover.snapshot(round, &work, &discarded);
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
        if work.is_empty() || cover.trajectories.len() >= budget {
            let (est, unc, image) = estimate(&cover.trajectories, final_round)?;
            final_round += 1;
            let target = problem.synthesis.coverage_target;
            if est.lower >= target {
                break (StopReason::Covered, est, unc, image);
            }
            if cover.trajectories.len() >= budget {
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
        let room = budget - cover.trajectories.len();
        if opts.generator == Generator::Algorithm4 && cover.trajectories.is_empty() {
            // The first seed: the SCP generator from the centre of Init (then from working samples in
            // order), optimised by §5.3 like every later one.
            bars.set_round(round, "first seed (SCP + §5.3)");
            let centre: Vec<f64> = init
                .lo
                .iter()
                .zip(&init.hi)
                .map(|(l, h)| round32(0.5 * (l + h)))
                .collect();
            // The centre is tried in the first round only: the generator is deterministic, so a centre
            // that failed once fails again, and later rounds give its place to a working sample.
            let with_centre = !centre_tried;
            centre_tried = true;
            let from_work = if with_centre { batch - 1 } else { batch };
            let seeds: Vec<Vec<f64>> = std::iter::once(centre)
                .filter(|_| with_centre)
                .chain(
                    work.iter()
                        .take(from_work)
                        .map(|x| x.iter().map(|&v| round32(v)).collect()),
                )
                .collect();
            let made: Vec<_> = seeds.par_iter().map(|s| seed_scp(s)).collect();
            let mut got = false;
            for (s, r) in seeds.iter().zip(made) {
                match r {
                    Ok((before, (nominal, certificate), opt)) if !got && accept(&certificate) => {
                        cover.record(
                            OptStart::new(round, None, s, before, opt),
                            CoverTrajectory {
                                source: Source::new(Origin::Generator, true),
                                nominal,
                                certificate,
                            },
                            true,
                            &on_accept,
                        );
                        got = true;
                    }
                    Ok(_) if got => {}
                    r => {
                        match r {
                            Ok(((_, before), (_, after), _)) => {
                                attempts.certificate(&before);
                                attempts.certificate(&after);
                            }
                            Err(e) => {
                                attempts.refusal(e);
                                attempts.certificate(&unforced(s));
                            }
                        }
                        failed += 1;
                        work.retain(|x| alg4::dist(P.as_ref(), x, s) > 0.0125);
                    }
                }
            }
            if !got {
                // The plain generator certified nothing from this round's seeds: their routes, in order.
                bars.set_round(round, "first seed (routes, SCP + §5.3)");
                if let Some((s, (origin, (before, (nominal, certificate), opt)))) =
                    seeds.iter().find_map(|s| from_routes(s).map(|m| (s, m)))
                {
                    cover.record(
                        OptStart::new(round, None, s, before, opt),
                        CoverTrajectory {
                            source: Source::new(origin, true),
                            nominal,
                            certificate,
                        },
                        true,
                        &on_accept,
                    );
                    got = true;
                }
            }
            if !got && (work.is_empty() || imports_refused) {
                if imports_refused {
                    attempts.stopped_after = Some(failed);
                }
                bars.clear();
                return Err(GrowError::NoSeed {
                    failed,
                    attempts: Box::new(attempts),
                });
            }
            cover.snapshot(round, &work, &discarded);
            continue;
        }
        let typical = alg4::median(
            cover
                .trajectories
                .iter()
                .map(|t| t.certificate.delta_stored as f64),
        )
        .unwrap_or(0.05);
        match opts.generator {
            Generator::Algorithm4 => {
                // (5.32) for every uncovered sample; nearest first (ties: sample order).
                let mut pool: Vec<(f64, usize, usize)> = work
                    .iter()
                    .enumerate()
                    .filter_map(|(i, y)| {
                        alg4::gap(P.as_ref(), y, &cover.trajectories).map(|(d, m)| (d, m, i))
                    })
                    .collect();
                pool.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
                let mut items: Vec<(usize, usize, Vec<f64>)> = Vec::new(); // (sample, ball m, ŷ)
                let mut drop: Vec<usize> = Vec::new();
                for &(_, mi, i) in &pool {
                    if items.len() >= batch.min(room) {
                        break;
                    }
                    let tm = &cover.trajectories[mi];
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
                // Each item's seed asks Algorithm 4 alone: its ball's feedback law from ŷ.
                let src = gens.over(
                    cover
                        .trajectories
                        .iter()
                        .map(alg4::feedback_law_reference)
                        .collect(),
                );
                let made: Vec<_> = items
                    .par_iter()
                    .map(|(_, mi, yh)| {
                        let seed = Seed {
                            x: yh.clone(),
                            grow: Some((*mi, yh.clone())),
                        };
                        let r = src
                            .answer(&seed, Ask::Grow)
                            .find_map(|p| Some((p.origin, optimise(yh, &p.candidate.ok()?))));
                        bars.batch.inc(1);
                        r
                    })
                    .collect();
                for ((i, mi, yh), made) in items.iter().zip(made) {
                    // (Every item's ball is in the cover, so it has its candidate.)
                    let Some((origin, (before, (nominal, certificate), opt))) = made else {
                        continue;
                    };
                    let cand = CoverTrajectory {
                        source: Source::new(origin, true),
                        nominal,
                        certificate,
                    };
                    // Accept when certified at the δε floor and it covers its target or some sample
                    // still uncovered (earlier acceptances of this round included).
                    let ok = accept(&cand.certificate)
                        && (alg4::covers(P.as_ref(), &cand, &work[*i])
                            || work.iter().any(|x| {
                                alg4::covers(P.as_ref(), &cand, x)
                                    && outside(&cover.trajectories, x)
                            }));
                    cover.record(
                        OptStart::new(round, Some(*mi), yh, before, opt),
                        cand,
                        ok,
                        &on_accept,
                    );
                    if !ok {
                        failed += 1;
                        drop.push(*i);
                        // Samples that project onto the same ball within half the typical radius of ŷ
                        // start the same reference sequence from nearly the same state, and δ depends
                        // continuously on the start: discard them with it rather than retry each one.
                        let tm = &cover.trajectories[*mi];
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
                    let mut d = alg4::gap(P.as_ref(), x, &cover.trajectories)
                        .map_or(f64::INFINITY, |g| g.0);
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
                let made: Vec<_> = seeds.par_iter().map(|s| make(s)).collect();
                let mut progress = false;
                for (s, t) in seeds.iter().zip(made) {
                    match t {
                        Ok(t) => {
                            cover.push(t, Some(&on_accept));
                            progress = true;
                        }
                        Err(why) => {
                            match why {
                                Ok(c) => attempts.certificate(&c),
                                Err(e) => {
                                    attempts.refusal(e);
                                    attempts.certificate(&unforced(s));
                                }
                            }
                            failed += 1;
                            // Drop the seed and its close neighbours from the working set so the loop moves
                            // on; the final fresh sample will find any hole this leaves.
                            work.retain(|x| alg4::dist(P.as_ref(), x, s) > 0.25 * typical);
                        }
                    }
                }
                if !progress
                    && cover.trajectories.is_empty()
                    && (work.is_empty() || imports_refused)
                {
                    if imports_refused {
                        attempts.stopped_after = Some(failed);
                    }
                    bars.clear();
                    return Err(GrowError::NoSeed {
                        failed,
                        attempts: Box::new(attempts),
                    });
                }
            }
        }
        cover.snapshot(round, &work, &discarded);
    };
    bars.clear();
    cover.routes = gens.searches();
    if cover.trajectories.is_empty() {
        return Err(GrowError::NothingCertified {
            attempts: Box::new(attempts),
        });
    }
    Ok(Grown {
        cover,
        stop,
        coverage,
        uncovered,
        image,
        warnings,
    })
}
