//! The synthesis pipeline (Algorithm 1 with Algorithm 2's controller), a short sequence of stages:
//! task → CAF and shipped gain ([`crate::caf::design`]) → cover grown until Init is covered
//! ([`crate::cover::grow`]) → certified, f32-exact image → independent Monte Carlo verification
//! ([`crate::verify`]) → outcome (the report is written from it by the CLI).
//!
//! The cover grows by Algorithm 4 (§5.4) by default: the first trajectory from the SCP generator (or
//! imports), each later one from the boundary of the ball closest to the nearest uncovered sample, with δ
//! maximised by §5.3 ([`crate::optimize::maximize_delta`]) and re-certified through
//! [`certify::shipped`]; [`Generator::Scp`] keeps Algorithm 1 with the SCP generator per seed. The run
//! stops when Init is covered, the budget is spent, no local variation reaches the rest ("needs a new seed
//! trajectory"), or on [`SynthOptions::cancel`] (Ctrl-C), always with a verified image of what is certified.
//!
//! Where a terminal law is certified (designed before the cover, [`terminal_for`]), the cover is grown for
//! the task whose Goal is the law's handover region ([`handover_task`]), so that every certified run is
//! handed over within the horizon, before it can leave Goal (the argument: `certify::terminal`'s module
//! doc); the verification judges the spec's own task, to twice the horizon.
//!
//! Everything random is drawn from ChaCha streams seeded by the spec's seed, and parallel work is
//! collected in a fixed order, so the same spec and seed give a byte-identical image.

pub mod hybrid;
pub mod refusals;
pub mod temporal;

use crate::certify::{self, Loop, LoopConstants};
use crate::cover::{grow, Cover, CoverageEstimate, GrowError, GrowOptions};
use crate::optimize::BundleSettings;
use crate::task::Task;
use crate::terminal::{design_terminal, NoTerminal, TerminalDesign};
use crate::verify::attack::{attack, AttackError, AttackReport, AttackSettings};
use crate::verify::{monte_carlo, Judge, VerifyReport};
use faer::Mat;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

pub use crate::cover::{
    alg4, feedforward_image, AcceptHook, CoverSnapshot, CoverTrajectory, Generator, OptRecord,
    StopReason,
};

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
    /// The falsifier run on the feedforward image after the Monte Carlo, on the plant itself for a
    /// feedback-linearizable one (default: one start of at most 40 runs per ball, seeded by the spec's
    /// seed); `None` skips it.
    pub attack: Option<AttackSettings>,
    /// Told a line as the verification and the falsifier start (default none).
    pub on_stage: Option<crate::cover::StageHook>,
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
            attack: Some(AttackSettings {
                starts_per_ball: 1,
                evaluations_per_start: 40,
                seed: 0,
            }),
            on_stage: None,
        }
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
    /// The route searches the growth ran (the routes the report draws).
    pub routes: Vec<crate::cover::RouteSearch>,
    /// Working samples drawn (the denominator of the snapshots).
    pub working_samples: usize,
    pub verify: VerifyReport,
    /// What the falsifier found on the image (when [`SynthOptions::attack`] asked for it).
    pub attack: Option<AttackReport>,
    pub timings: Vec<(String, f64)>,
    pub warnings: Vec<String>,
    /// The terminal law in the image, or why there is none (issue 17).
    pub terminal: TerminalOutcome,
    /// With a certified terminal law: ρ_h, the radius (in the law's metric) of the handover region the
    /// cover's runs are certified to reach ([`handover_task`]).
    pub handover_radius: Option<f64>,
}

impl Synthesis {
    /// The initial states x̃_i(0) of the certified trajectories: the centres of the cover's balls over Init,
    /// from which a PWA image's Monte Carlo draws half its runs.
    pub fn init_centres(&self) -> Vec<Vec<f64>> {
        self.trajectories
            .iter()
            .filter(|t| t.certificate.is_certified())
            .map(|t| t.nominal.x[0].clone())
            .collect()
    }
}

/// What the image does after the task (the spec's `[synthesis] terminal`).
#[derive(Clone, Debug)]
pub enum TerminalOutcome {
    /// A certified terminal law, stored in the image.
    Certified(Box<TerminalDesign>),
    /// None exists (the reason); the image keeps its behaviour past the table.
    None(NoTerminal),
    /// The spec asked for none (`"hold"` or `"fallback"`).
    NotAsked,
}

impl TerminalOutcome {
    /// The design, when certified.
    pub fn design(&self) -> Option<&TerminalDesign> {
        match self {
            TerminalOutcome::Certified(d) => Some(d),
            _ => None,
        }
    }
}

/// The terminal law the spec asks for: designed and certified where `auto` or `invariant` asks
/// ([`crate::terminal`]); `invariant` without one is an error, before any growth.
pub fn terminal_for(task: &Task) -> Result<TerminalOutcome, SynthError> {
    use crate::spec::TerminalChoice;
    match task.settings().terminal {
        TerminalChoice::Hold | TerminalChoice::Fallback => Ok(TerminalOutcome::NotAsked),
        choice => match design_terminal(task) {
            Ok(d) => Ok(TerminalOutcome::Certified(Box::new(d))),
            Err(e) if choice == TerminalChoice::Invariant => Err(SynthError::Terminal(e)),
            Err(e) => Ok(TerminalOutcome::None(e)),
        },
    }
}

/// A feedforward image's bytes with the terminal behaviour the spec chose: the certified law stored as
/// section 11, and past the table `fallback` when the spec says so (else the last row's law).
fn with_terminal(image: Vec<u8>, task: &Task, t: &TerminalOutcome) -> Result<Vec<u8>, SynthError> {
    let fallback = task.settings().terminal == crate::spec::TerminalChoice::Fallback;
    if t.design().is_none() && !fallback {
        return Ok(image);
    }
    let img = shared_types::image::decode(&image).map_err(SynthError::ImageRejected)?;
    let mut b = crate::emit::ImageBuilder::from_image(&img);
    b.terminal_law = t.design().map(|d| d.stored.clone());
    if fallback {
        b.terminal = shared_types::image::Terminal::Fallback;
    }
    b.to_bytes()
        .map_err(|e| SynthError::Cover(GrowError::Emit(e)))
}

/// Errors that end a run.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error("no CAF and feedback: {0}")]
    Caf(#[from] crate::caf::DesignError),
    #[error(transparent)]
    Certify(#[from] certify::CertifyError),
    #[error(transparent)]
    Cover(#[from] GrowError),
    #[error("the emitted image is rejected by the decoder: {0}")]
    ImageRejected(shared_types::image::ImageError),
    #[error(transparent)]
    Verify(#[from] crate::verify::MonteCarloError),
    #[error(transparent)]
    Attack(#[from] AttackError),
    #[error("[synthesis] terminal = \"invariant\": {0}")]
    Terminal(NoTerminal),
    #[error("the terminal law's handover region: {0}")]
    Handover(String),
    /// Goal cannot be reached from Init in the free space at all (`trajectory::route`): bad input.
    #[error(
        "no route: Goal cannot be reached from any state of Init without entering Unsafe; {pieces} \
         close it off (a search of the free space in the coordinates {coords}, {cells} cells)"
    )]
    NoRoute {
        /// The spec's names of the pieces, e.g. `unsafe[3], unsafe[4]`.
        pieces: String,
        coords: String,
        cells: usize,
    },
}

/// Refuses, before any other work, a task whose Goal no continuous path from Init reaches in the free
/// space ([`crate::trajectory::route::RouteMap::closed_off`]), naming the Unsafe pieces that close it
/// off. Only for a continuous-time plant: a sampled one may jump a wall between samples.
pub fn refuse_without_route(task: &Task) -> Result<(), SynthError> {
    use crate::trajectory::route::{RouteMap, RouteSettings};
    if task.convex.unsafe_pieces.is_empty() || task.plant.continuous(0).is_none() {
        return Ok(());
    }
    let init = task.init();
    let Some(map) = RouteMap::new(&task.convex, &init.lo, &init.hi, &RouteSettings::default())
    else {
        return Ok(());
    };
    let Some(closed) = map.closed_off(&init.lo, &init.hi) else {
        return Ok(());
    };
    let named = task.problem.unsafe_sets.len();
    let pieces: Vec<String> = closed
        .pieces
        .iter()
        .map(|&i| {
            if i < named {
                format!("unsafe[{i}]")
            } else {
                format!("the complement of the operating region (piece {i})")
            }
        })
        .collect();
    let coords: Vec<String> = closed
        .coords
        .iter()
        .map(|j| format!("x{}", j + 1))
        .collect();
    Err(SynthError::NoRoute {
        pieces: if pieces.is_empty() {
            "the region's bounds".into()
        } else {
            pieces.join(", ")
        },
        coords: coords.join(", "),
        cells: closed.cells,
    })
}

/// Run the whole pipeline.
pub fn synthesize(task: &Task, opts: &SynthOptions) -> Result<Synthesis, SynthError> {
    let problem = &task.problem;
    let mut timings = Vec::new();
    let t0 = Instant::now();
    // At once: a Goal walled off from Init is said before any design or seed work (issue 48, item 6).
    refuse_without_route(task)?;
    // CAF and feedback for the sampled loop (LMIs (3.66)–(3.67) with the σ-margin of Remark 3.22); what
    // ships, and everything below is certified for, is the f32 gain K̂.
    let design = crate::caf::design(task)?;
    let mut warnings = design.warnings.clone();
    timings.push(("CAF (SDP)".to_string(), t0.elapsed().as_secs_f64()));

    // The terminal law first: it does not depend on the cover, a spec that requires one that does not
    // exist fails here rather than after the growth, and where one is certified the cover is grown for
    // its handover region (below).
    let t_terminal = Instant::now();
    let terminal = terminal_for(task)?;
    timings.push((
        "terminal law".to_string(),
        t_terminal.elapsed().as_secs_f64(),
    ));
    match &terminal {
        TerminalOutcome::None(e) => warnings.push(format!("no terminal law: {e}")),
        TerminalOutcome::Certified(_) | TerminalOutcome::NotAsked => {}
    }
    // With a certified terminal law, every run must be handed over before it can leave Goal (issue 42,
    // item 4; the argument is certify::terminal's module doc): the cover's Goal is the handover region
    // H ⊂ Goal, and its tubes stay in the task's Goal from the first sample wholly in it until H.
    let handover = match terminal.design() {
        Some(d) => Some(handover_task(task, d)?),
        None => None,
    };
    let cover_task = handover.as_ref().map_or(task, |(t, _)| t);
    let lp = Loop::new(cover_task, &design);
    let mut lc = LoopConstants::new(&lp)?;
    if handover.is_some() {
        let goal = task
            .problem
            .goal_region()
            .map_err(|e| SynthError::Handover(e.to_string()))?;
        lc = lc.with_stay_in(Arc::from(goal));
    }

    let t1 = Instant::now();
    let grown = grow(
        cover_task,
        &lp,
        &lc,
        &GrowOptions {
            working_samples: opts.working_samples,
            progress: opts.progress,
            imports: &opts.imports,
            generator: opts.generator,
            batch: opts.batch,
            optimizer: opts.optimizer.as_ref(),
            cancel: &opts.cancel,
            on_accept: opts.on_accept.as_ref(),
        },
    )?;
    warnings.extend(grown.warnings);
    let (stop, coverage, uncovered) = (grown.stop, grown.coverage, grown.uncovered);
    let image = if task.settings().mode == crate::spec::ControllerMode::Feedforward {
        with_terminal(grown.image, task, &terminal)?
    } else {
        grown.image
    };
    let Cover {
        trajectories: trajs,
        records,
        snapshots,
        routes,
        ..
    } = grown.cover;
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
    let img = shared_types::image::decode(&image).map_err(SynthError::ImageRejected)?;
    let judge = Judge::new(task);
    let linearized = task.plant.linearization().is_some();
    let stage = |line: String| {
        if let Some(h) = &opts.on_stage {
            h.stage(&line);
        }
    };
    stage(format!(
        "verification: Monte Carlo of {} runs from the cover, {} on each of {} balls' boundary",
        opts.verify_interior,
        opts.verify_per_ball,
        img.n_trajectories()
    ));
    // A linearised plant is verified against the plant itself, not its linear model.
    let verify = if linearized {
        crate::verify::nonlinear::monte_carlo_fl(
            task,
            &img,
            opts.verify_interior,
            opts.verify_per_ball,
            problem.seed ^ 0x7e51f1,
        )?
    } else {
        monte_carlo(
            &judge,
            &img,
            opts.verify_interior,
            opts.verify_per_ball,
            problem.seed ^ 0x7e51f1,
        )?
    };
    timings.push(("verification".to_string(), t2.elapsed().as_secs_f64()));
    if verify.violations > 0 {
        warnings.push(format!(
            "verification found {} violations: the image is NOT certified",
            verify.violations
        ));
    }
    let attack = match &opts.attack {
        Some(a) => {
            stage("falsifier: a search for the least robust run over every ball".into());
            let t3 = Instant::now();
            let settings = AttackSettings {
                seed: a.seed ^ problem.seed,
                ..a.clone()
            };
            // A linearised plant is attacked on the plant itself, as it is verified.
            let r = if linearized {
                crate::verify::attack::attack_fl(task, &img, &settings)?
            } else {
                attack(&judge, &img, &settings)?
            };
            timings.push(("falsifier".to_string(), t3.elapsed().as_secs_f64()));
            if r.violations > 0 {
                warnings.push(format!(
                    "the falsifier found {} violating runs: the image is NOT certified",
                    r.violations
                ));
            }
            Some(r)
        }
        None => None,
    };
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
        routes,
        working_samples: opts.working_samples,
        verify,
        attack,
        timings,
        warnings,
        terminal,
        handover_radius: handover.map(|(_, rho)| rho),
    })
}

/// The task a cover is grown for under a certified terminal law `d`: the task with the law's handover
/// region H as its Goal ([`crate::certify::terminal::handover_region`]), and H's radius ρ_h in the
/// law's metric.
pub fn handover_task(task: &Task, d: &TerminalDesign) -> Result<(Task, f64), SynthError> {
    let (piece, region) = crate::certify::terminal::handover_region(&d.stored).ok_or_else(|| {
        SynthError::Handover(
            "the f32 handover test is not proved to accept any state (its rounding analysis does not \
             apply)"
                .into(),
        )
    })?;
    let t = task
        .with_goal(piece, region)
        .map_err(|e| SynthError::Handover(e.to_string()))?;
    Ok((t, crate::certify::terminal::handover_radius(&d.stored)))
}
