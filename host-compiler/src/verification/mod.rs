//! One verification of an image against its spec, without printing (above `verify`, whose checks it
//! runs, and `synth`, whose hybrid task it builds): what `host-compiler verify` runs
//! (the CLI only prints its result and maps it to an exit status) and what the tamper campaign
//! ([`tamper`], `benches/tamper.rs`) runs on every perturbed image, so both run the same checks.
//!
//! In order, for every image mode: the image must decode and belong to the spec
//! ([`crate::verify::check_matches`]; else a [`Refusal`], bad input); its stored values that no re-proof reads
//! must be the ones the spec gives ([`crate::verify::stored`]); its certificate is re-proved from the bytes (the
//! mode's re-proof and the terminal law's); its coverage of the spec's Init is estimated
//! ([`crate::verify::coverage`]); then the Monte Carlo (every start it draws is one the certificate covers, so a
//! refused start is a failure, `refused`) and, when asked, the falsifier. The first check that fails is
//! the [`Failed`] result (exit 1); a coverage short of the spec's target with every check passed is
//! [`Verification::short_of_coverage`] (exit 3).

pub mod tamper;

use crate::certify::terminal::TerminalCertificate;
use crate::cover::estimate::SampleBox;
use crate::verify::attack::{AttackError, AttackReport, AttackSettings};
use crate::verify::coverage::Coverage;
use crate::verify::feedforward::FeedforwardRecheck;
use crate::verify::hybrid::{HybridReport, RunCheck};
use crate::verify::pwa::{PwaMonteCarlo, PwaRecheck};
use crate::verify::temporal::{TemporalCheck, TemporalReport};
use crate::verify::{Judge, VerifyReport};
use shared_types::image::{Image, Mode};

/// What to run.
#[derive(Clone, Debug)]
pub struct Options {
    /// Monte Carlo starts drawn in the certified cover (PWA: in F).
    pub runs: usize,
    /// Starts on the boundary of every ball.
    pub per_ball: usize,
    /// The Monte Carlo's seed (default: derived from the spec's).
    pub seed: Option<u64>,
    /// Closed-loop runs per Nelder–Mead start of the falsifier; `None`: no falsifier.
    pub attack_evals: Option<usize>,
    /// Estimate the coverage of the spec's Init ([`crate::verify::coverage`]).
    pub coverage: bool,
    /// Stop at the first failed check (the campaign), instead of running every part for the report.
    pub stop_early: bool,
    /// Told a line as each stage starts (the re-proof, the coverage, the Monte Carlo, the falsifier);
    /// `None`: nothing is told.
    pub progress: Option<crate::cover::StageHook>,
}

impl Options {
    /// Tell the receiver, if any, that stage `line` starts.
    fn stage(&self, line: impl FnOnce() -> String) {
        if let Some(p) = &self.progress {
            p.stage(&line());
        }
    }
    /// The stage line of the Monte Carlo.
    fn stage_monte_carlo(&self, balls: usize) {
        self.stage(|| {
            format!(
                "Monte Carlo: {} runs from the cover, {} on each of {balls} balls' boundary",
                self.runs, self.per_ball
            )
        });
    }
    /// The stage line of the falsifier, when it runs.
    fn stage_attack(&self, v: &Verdict) {
        if self.attack_evals.is_some() && !v.stop() {
            self.stage(|| "falsifier: a search for the least robust run over every ball".into());
        }
    }
    /// The stage line of the re-proof.
    fn stage_recheck(&self, img: &Image<'_>) {
        self.stage(|| {
            format!(
                "re-proving {} balls from the image's bytes",
                img.n_trajectories()
            )
        });
    }
}

impl Default for Options {
    fn default() -> Self {
        Self {
            runs: 10_000,
            per_ball: 32,
            seed: None,
            attack_evals: None,
            coverage: true,
            stop_early: false,
            progress: None,
        }
    }
}

/// Why an image is not verified at all: bad input.
#[derive(Debug)]
pub enum Refusal {
    /// The decoder rejects the bytes.
    Rejected(String),
    /// The image was made for another spec (dimensions, period, fingerprint).
    Mismatch(String),
    /// Anything else that makes the verification impossible (a spec that makes no task, an image of
    /// the wrong mode for the spec, a re-proof that cannot start, flags).
    BadInput(miette::Report),
}

impl Refusal {
    fn bad(e: impl std::fmt::Display) -> Self {
        Refusal::BadInput(miette::miette!("{e}"))
    }
}

/// The check that failed (the campaign counts refusals by it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum Check {
    /// A stored value no re-proof reads is not the spec's ([`crate::verify::stored`]).
    Stored,
    /// The certificate is not re-proved from the bytes.
    Recheck,
    /// The terminal law is not re-proved from the bytes.
    Terminal,
    /// The evaluator refused Monte Carlo starts the certificate covers.
    Refused,
    /// A Monte Carlo run violated the task.
    Violation,
    /// The falsifier found a violating run.
    Attack,
    /// Fewer starts than asked could be drawn in the cover.
    Draws,
}

impl Check {
    /// For people and the bench's rows.
    pub fn name(self) -> &'static str {
        match self {
            Check::Stored => "stored values",
            Check::Recheck => "re-proof",
            Check::Terminal => "terminal law",
            Check::Refused => "refused starts",
            Check::Violation => "monte carlo",
            Check::Attack => "falsifier",
            Check::Draws => "draws",
        }
    }
}

/// A failed check (exit 1).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Failed {
    pub check: Check,
    pub message: String,
    /// Whether the message is about the image's bytes (the CLI names the file before it).
    pub about_image: bool,
}

/// Each mode's results, for the report.
#[derive(Clone, Debug, serde::Serialize)]
#[serde(untagged)]
pub enum Report {
    Feedforward {
        recheck: FeedforwardRecheck,
        terminal: Option<TerminalCertificate>,
        monte_carlo: Option<VerifyReport>,
        attack: Option<AttackReport>,
        #[serde(skip)]
        has_unsafe: bool,
    },
    Pwa {
        recheck: PwaRecheck,
        terminal: Option<TerminalCertificate>,
        monte_carlo: Option<PwaMonteCarlo>,
        attack: Option<AttackReport>,
        #[serde(skip)]
        run_steps: usize,
    },
    Temporal {
        recheck: Vec<TemporalCheck>,
        monte_carlo: Option<TemporalReport>,
        attack: Option<AttackReport>,
        #[serde(skip)]
        written: String,
        #[serde(skip)]
        in_xi: Option<String>,
    },
    Hybrid {
        recheck: Vec<RunCheck>,
        monte_carlo: Option<HybridReport>,
        attack: Option<AttackReport>,
    },
}

/// The result of a verification that ran.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Verification {
    #[serde(flatten)]
    pub report: Report,
    /// The image's coverage of the spec's Init (when asked and the checks before it passed).
    pub coverage: Option<Coverage>,
    /// The first check that failed, if any.
    pub failure: Option<Failed>,
}

impl Verification {
    /// Every check passed but the coverage of the spec's Init is short of its target (exit 3).
    pub fn short_of_coverage(&self) -> bool {
        self.failure.is_none() && self.coverage.as_ref().is_some_and(|c| !c.met)
    }
    /// Every check passed and the coverage (if estimated) meets the target.
    pub fn passed(&self) -> bool {
        self.failure.is_none() && !self.short_of_coverage()
    }
}

/// The first failure of a list of candidates (in the order of the module doc).
struct Verdict {
    failure: Option<Failed>,
    stop_early: bool,
}

impl Verdict {
    fn fail(&mut self, check: Check, about_image: bool, message: impl FnOnce() -> String) {
        if self.failure.is_none() {
            self.failure = Some(Failed {
                check,
                message: message(),
                about_image,
            });
        }
    }
    /// Whether the next (costly) part should be skipped.
    fn stop(&self) -> bool {
        self.stop_early && self.failure.is_some()
    }
}

fn attack_settings(o: &Options, seed: u64) -> Result<Option<AttackSettings>, Refusal> {
    let Some(e) = o.attack_evals else {
        return Ok(None);
    };
    AttackSettings::builder()
        .evaluations_per_start(e)
        .seed(o.seed.unwrap_or(seed ^ 0xa77ac))
        .build()
        .map(Some)
        .map_err(|e| Refusal::BadInput(AttackError::from(e).into()))
}

/// Verifies `bytes` against `problem` (module doc).
pub fn verify(
    problem: crate::spec::Problem,
    bytes: &[u8],
    o: &Options,
) -> Result<Verification, Refusal> {
    let img = shared_types::image::decode(bytes).map_err(|e| Refusal::Rejected(e.to_string()))?;
    crate::verify::check_matches(&problem, &img).map_err(|e| Refusal::Mismatch(e.to_string()))?;
    if problem.hybrid.is_some() {
        return verify_hybrid(problem, bytes, &img, o);
    }
    if problem.mtl.is_some() {
        return verify_temporal(problem, bytes, &img, o);
    }
    let task = crate::task::Task::new(problem).map_err(Refusal::bad)?;
    if img.mode() == Mode::PwaFeedback {
        return verify_pwa(&task, bytes, &img, o);
    }
    verify_feedforward(&task, bytes, &img, o)
}

fn stored(v: &mut Verdict, bytes: &[u8], expected: &crate::verify::stored::Expected) {
    if let Err(e) = crate::verify::stored::check(bytes, expected) {
        v.fail(Check::Stored, true, || e.to_string());
    }
}

fn init_box(init: &crate::spec::InitBox) -> SampleBox {
    SampleBox {
        lo: init.lo.clone(),
        hi: init.hi.clone(),
    }
}

/// The coverage estimate, unless not asked or a check already failed under `stop_early`.
fn coverage(
    v: &Verdict,
    o: &Options,
    img: &Image<'_>,
    proved: &[bool],
    init: &SampleBox,
    problem: &crate::spec::Problem,
    seed: u64,
) -> Option<Coverage> {
    (o.coverage && !v.stop()).then(|| {
        o.stage(|| "coverage of the spec's Init".into());
        crate::verify::coverage::estimate(
            img,
            proved,
            init,
            &problem.synthesis,
            crate::verify::coverage::seed_of(o.seed.unwrap_or(seed)),
        )
    })
}

fn terminal(
    v: &mut Verdict,
    task: &crate::task::Task,
    img: &Image<'_>,
) -> Option<TerminalCertificate> {
    match crate::verify::recheck_terminal(task, img) {
        None => None,
        Some(Ok(c)) => Some(c),
        Some(Err(e)) => {
            v.fail(Check::Terminal, true, || {
                format!("the terminal law is not certified by the image's own bytes: {e}")
            });
            None
        }
    }
}

fn attack_verdict(v: &mut Verdict, attack: Option<&AttackReport>) {
    if let Some(at) = attack.filter(|a| a.violations > 0) {
        let first = at
            .first_violations
            .first()
            .map(|x| format!(" (first from x0 = {:?}: {})", x.x0, x.what))
            .unwrap_or_default();
        v.fail(Check::Attack, false, || {
            format!(
                "the falsifier found {} violating runs{first}",
                at.violations
            )
        });
    }
}

fn refused_verdict(v: &mut Verdict, refused: usize, runs: usize) {
    if refused > 0 {
        v.fail(Check::Refused, true, || {
            format!(
                "the evaluator refused {refused} of {runs} Monte Carlo starts that its certificate covers \
                 (each inside a ball the image's own f32 selection provably accepts): the image does not \
                 run what it certifies"
            )
        });
    }
}

fn verify_feedforward(
    task: &crate::task::Task,
    bytes: &[u8],
    img: &Image<'_>,
    o: &Options,
) -> Result<Verification, Refusal> {
    let problem = &task.problem;
    let judge = Judge::new(task);
    let linearized = task.plant.linearization().is_some();
    if let Some(maps) = task.plant.linearization() {
        crate::verify::nonlinear::check_maps(maps, img).map_err(Refusal::Mismatch)?;
    }
    let mut v = Verdict {
        failure: None,
        stop_early: o.stop_early,
    };
    stored(
        &mut v,
        bytes,
        &crate::verify::stored::Expected::feedforward(task, false),
    );
    o.stage_recheck(img);
    let rc = crate::verify::feedforward::recheck(&judge, img).map_err(|e| {
        // Not re-provable at all: a failed check about the image.
        Failed {
            check: Check::Recheck,
            message: e.to_string(),
            about_image: true,
        }
    });
    let rc = match rc {
        Ok(rc) => rc,
        Err(f) => {
            let mut v = v;
            v.fail(f.check, true, || f.message);
            return Ok(Verification {
                report: Report::Feedforward {
                    recheck: FeedforwardRecheck {
                        sigma_min: 0.0,
                        tolerance: 0.0,
                        trajectories: Vec::new(),
                        worst_ratio: 0.0,
                        horizon: task.steps,
                        failures: 0,
                    },
                    terminal: None,
                    monte_carlo: None,
                    attack: None,
                    has_unsafe: judge.unsafe_set().is_some(),
                },
                coverage: None,
                failure: v.failure,
            });
        }
    };
    if rc.failures > 0 {
        let first = rc
            .trajectories
            .iter()
            .find_map(|c| c.failure(rc.horizon))
            .unwrap_or_default();
        v.fail(Check::Recheck, true, || {
            format!(
                "{} of {} stored radii are not certified by the image's own bytes; first: {first}",
                rc.failures,
                rc.trajectories.len()
            )
        });
    }
    let terminal = terminal(&mut v, task, img);
    let proved: Vec<bool> = rc.trajectories.iter().map(|c| c.ok).collect();
    let init = match task.plant.linearization() {
        Some(m) => init_box(&m.init),
        None => init_box(task.init()),
    };
    let coverage = coverage(&v, o, img, &proved, &init, problem, problem.seed);
    let seed = o.seed.unwrap_or(problem.seed ^ 0x7e51f1);
    let mc = if v.stop() {
        None
    } else {
        o.stage_monte_carlo(img.n_trajectories());
        let r = if linearized {
            crate::verify::nonlinear::monte_carlo_fl(task, img, o.runs, o.per_ball, seed)
        } else {
            crate::verify::monte_carlo(&judge, img, o.runs, o.per_ball, seed)
        }
        .map_err(Refusal::bad)?;
        refused_verdict(&mut v, r.refused, r.interior_runs + r.boundary_runs);
        if r.violations > 0 {
            v.fail(Check::Violation, false, || {
                format!("{} violations", r.violations)
            });
        }
        Some(r)
    };
    o.stage_attack(&v);
    let attack = match attack_settings(o, problem.seed)? {
        Some(_) if v.stop() => None,
        Some(s) if linearized => Some(
            crate::verify::attack::attack_fl(task, img, &s)
                .map_err(|e| Refusal::BadInput(e.into()))?,
        ),
        Some(s) => Some(
            crate::verify::attack::attack(&judge, img, &s)
                .map_err(|e| Refusal::BadInput(e.into()))?,
        ),
        None => None,
    };
    attack_verdict(&mut v, attack.as_ref());
    if let Some(r) = &mc {
        if r.interior_runs < o.runs {
            v.fail(Check::Draws, false, || {
                format!(
                    "only {} of {} initial states could be drawn in the certified cover",
                    r.interior_runs, o.runs
                )
            });
        }
    }
    Ok(Verification {
        report: Report::Feedforward {
            recheck: rc,
            terminal,
            monte_carlo: mc,
            attack,
            has_unsafe: judge.unsafe_set().is_some(),
        },
        coverage,
        failure: v.failure,
    })
}

fn verify_pwa(
    task: &crate::task::Task,
    bytes: &[u8],
    img: &Image<'_>,
    o: &Options,
) -> Result<Verification, Refusal> {
    let judge = Judge::new(task);
    let problem = &task.problem;
    let mut v = Verdict {
        failure: None,
        stop_early: o.stop_early,
    };
    stored(&mut v, bytes, &crate::verify::stored::Expected::pwa(task));
    o.stage_recheck(img);
    let rc = crate::verify::pwa::recheck(&judge, img).map_err(Refusal::bad)?;
    if rc.failures > 0 {
        v.fail(Check::Recheck, true, || {
            format!("{} certificate failures", rc.failures)
        });
    }
    let terminal = terminal(&mut v, task, img);
    let coverage = coverage(
        &v,
        o,
        img,
        &[],
        &init_box(task.init()),
        problem,
        problem.seed,
    );
    let mc = if v.stop() {
        None
    } else {
        // The image does not mark which balls start a trajectory: all runs start anywhere in F.
        o.stage(|| {
            format!(
                "Monte Carlo: {} runs from F, the PWA law's envelope",
                o.runs
            )
        });
        let mc = crate::verify::pwa::monte_carlo_pwa(
            &judge,
            img,
            &[],
            o.runs,
            o.seed.unwrap_or(0x7e51f1),
            0,
        )
        .map_err(Refusal::bad)?;
        if mc.violations > 0 {
            v.fail(Check::Violation, false, || {
                format!(
                    "{} certificate failures, {} violations",
                    rc.failures, mc.violations
                )
            });
        }
        Some(mc)
    };
    o.stage_attack(&v);
    let attack = match attack_settings(o, problem.seed)? {
        Some(s) if !v.stop() => Some(
            crate::verify::attack::attack_pwa(&judge, img, &s)
                .map_err(|e| Refusal::BadInput(e.into()))?,
        ),
        _ => None,
    };
    attack_verdict(&mut v, attack.as_ref());
    if let Some(mc) = &mc {
        if mc.runs < o.runs {
            v.fail(Check::Draws, false, || {
                format!(
                    "only {} of {} initial states could be drawn in F",
                    mc.runs, o.runs
                )
            });
        }
    }
    Ok(Verification {
        report: Report::Pwa {
            recheck: rc,
            terminal,
            monte_carlo: mc,
            attack,
            run_steps: crate::verify::run_steps(&judge, img),
        },
        coverage,
        failure: v.failure,
    })
}

fn verify_temporal(
    problem: crate::spec::Problem,
    bytes: &[u8],
    img: &Image<'_>,
    o: &Options,
) -> Result<Verification, Refusal> {
    use crate::property::TemporalTask;
    use crate::verify::temporal::{monte_carlo_temporal, monte_carlo_temporal_fl, recheck};
    if img.mode() != Mode::Feedforward {
        return Err(Refusal::bad(
            "MTL tasks are certified for feedforward images of one-location plants",
        ));
    }
    // The formula bound on the spec as written (its errors point into the text), then on the task's
    // coordinates (ξ for a feedback-linearizable plant), as `synth` binds it.
    let tt = TemporalTask::from_problem(&problem).map_err(|e| Refusal::BadInput(e.into()))?;
    let written = tt.written.source().to_string();
    let linearized = problem.nonlinear.is_some();
    let task = crate::task::Task::new(problem).map_err(Refusal::bad)?;
    let tt = if linearized {
        TemporalTask::from_problem(&task.problem).map_err(|e| Refusal::BadInput(e.into()))?
    } else {
        tt
    };
    let in_xi = {
        let src = tt.written.source();
        (src != written).then(|| src.to_string())
    };
    if let Some(maps) = task.plant.linearization() {
        crate::verify::nonlinear::check_maps(maps, img).map_err(Refusal::Mismatch)?;
    }
    let mut v = Verdict {
        failure: None,
        stop_early: o.stop_early,
    };
    stored(
        &mut v,
        bytes,
        &crate::verify::stored::Expected::feedforward(&task, true),
    );
    o.stage_recheck(img);
    let rc = recheck(&task, &tt, img).map_err(Refusal::bad)?;
    if let Some(c) = rc.iter().find(|c| !c.ok) {
        // The stored radius within the certified one: what failed is the selection test's threshold.
        let what = if c.selection_test.is_some() && c.stored <= c.certified {
            "its whitened selection test accepts states beyond"
        } else {
            "its stored radius exceeds"
        };
        v.fail(Check::Recheck, true, || {
            format!(
                "ball {} is not re-proved: {what} what its table certifies for the formula",
                c.trajectory
            )
        });
    }
    let proved: Vec<bool> = rc.iter().map(|c| c.ok).collect();
    let init = init_box(&task.problem.init);
    let cov_init = match task.plant.linearization() {
        Some(m) => init_box(&m.init),
        None => init.clone(),
    };
    let coverage = coverage(
        &v,
        o,
        img,
        &proved,
        &cov_init,
        &task.problem,
        task.problem.seed,
    );
    let seed = o.seed.unwrap_or(task.problem.seed ^ 0x7e51f1);
    let mc = if v.stop() {
        None
    } else {
        o.stage_monte_carlo(img.n_trajectories());
        let starts =
            crate::verify::hybrid::starts_from_image(bytes, &init, o.runs, o.per_ball, seed)
                .map_err(Refusal::bad)?;
        let r = if linearized {
            // On the nonlinear plant, the zero states drawn in Init.
            monte_carlo_temporal_fl(&task, &tt, img, &starts, seed ^ 0x2e10)
                .map_err(Refusal::bad)?
        } else {
            monte_carlo_temporal(&task, &tt, img, &starts).map_err(Refusal::bad)?
        };
        // Every start is one the image's selection accepts (interior) or provably accepts (boundary);
        // on the nonlinear plant the lifted state's ξ is the coords program's, whose rounding may
        // refuse a boundary start, so refusals are judged only on the linear model.
        if !linearized {
            refused_verdict(&mut v, r.rejected, r.runs + r.rejected);
        }
        if r.violations > 0 {
            v.fail(Check::Violation, false, || {
                format!(
                    "{} violations (first: {})",
                    r.violations,
                    r.first_violation.as_deref().unwrap_or("?")
                )
            });
        }
        Some(r)
    };
    o.stage_attack(&v);
    let attack = match attack_settings(o, task.problem.seed)? {
        Some(_) if v.stop() => None,
        Some(s) if linearized => Some(
            crate::verify::attack::attack_temporal_fl(&task, &tt, img, &s)
                .map_err(|e| Refusal::BadInput(e.into()))?,
        ),
        Some(s) => Some(
            crate::verify::attack::attack_temporal(&task, &tt, img, &s)
                .map_err(|e| Refusal::BadInput(e.into()))?,
        ),
        None => None,
    };
    attack_verdict(&mut v, attack.as_ref());
    Ok(Verification {
        report: Report::Temporal {
            recheck: rc,
            monte_carlo: mc,
            attack,
            written,
            in_xi,
        },
        coverage,
        failure: v.failure,
    })
}

fn verify_hybrid(
    problem: crate::spec::Problem,
    bytes: &[u8],
    img: &Image<'_>,
    o: &Options,
) -> Result<Verification, Refusal> {
    use crate::verify::hybrid::{monte_carlo_hybrid, recheck, starts_from_image};
    use rayon::prelude::*;
    let task = crate::synth::hybrid::HybridTask::new(problem).map_err(Refusal::bad)?;
    let mut v = Verdict {
        failure: None,
        stop_early: o.stop_early,
    };
    stored(&mut v, bytes, &crate::verify::stored::Expected::hybrid());
    o.stage_recheck(img);
    let rc = recheck(
        &task.plant,
        &task.property,
        task.formula.as_ref(),
        task.steps,
        bytes,
    )
    .map_err(Refusal::bad)?;
    if let Some(why) = rc.iter().find_map(|c| c.why.as_deref()) {
        v.fail(Check::Recheck, true, || format!("not re-proved: {why}"));
    }
    let init = init_box(&task.problem.init);
    let proved: Vec<bool> = rc.iter().map(|c| c.ok).collect();
    let coverage = coverage(&v, o, img, &proved, &init, &task.problem, task.problem.seed);
    let seed = o.seed.unwrap_or(task.problem.seed ^ 0x7e51f1);
    let mc = if v.stop() {
        None
    } else {
        o.stage_monte_carlo(img.n_trajectories());
        let starts =
            starts_from_image(bytes, &init, o.runs, o.per_ball, seed).map_err(Refusal::bad)?;
        let parts: Vec<Result<HybridReport, String>> = starts
            .par_chunks(64)
            .map(|c| {
                monte_carlo_hybrid(
                    &task.plant,
                    &task.property,
                    task.formula.as_ref(),
                    task.initial,
                    task.steps,
                    bytes,
                    c,
                )
            })
            .collect();
        let mut r = HybridReport {
            min_unsafe_distance: f64::INFINITY,
            ..Default::default()
        };
        for p in parts {
            match p {
                Ok(p) => r.merge(p),
                Err(e) => {
                    v.fail(Check::Violation, false, || e);
                }
            }
        }
        refused_verdict(&mut v, r.rejected, r.runs);
        if r.violations > 0 {
            v.fail(Check::Violation, false, || {
                format!(
                    "{} violations (first: {})",
                    r.violations,
                    r.first_violation.as_deref().unwrap_or("?")
                )
            });
        }
        Some(r)
    };
    o.stage_attack(&v);
    let attack = match attack_settings(o, task.problem.seed)? {
        Some(s) if !v.stop() => {
            let runs = crate::verify::attack::HybridRuns {
                plant: &task.plant,
                property: &task.property,
                formula: task.formula.as_ref(),
                initial: task.initial,
                steps: task.steps,
            };
            Some(
                crate::verify::attack::attack_hybrid(runs, bytes, &s)
                    .map_err(|e| Refusal::BadInput(e.into()))?,
            )
        }
        _ => None,
    };
    attack_verdict(&mut v, attack.as_ref());
    Ok(Verification {
        report: Report::Hybrid {
            recheck: rc,
            monte_carlo: mc,
            attack,
        },
        coverage,
        failure: v.failure,
    })
}
