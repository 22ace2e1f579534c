//! The synthesis pipeline for an MTL task (Problem 2.28) on a one-location plant: Algorithm 1 with the
//! formula's certified robustness (Theorem 4.2 for the sampled f32 loop, [`crate::certify::temporal`]) in
//! place of Theorem 4.7.
//!
//! Each seed x0 (the centre of Init first, then uncovered working samples, a fixed batch per round in
//! parallel) gets a nominal from two starts, the first that certifies: (1) the table of the nearest ball
//! of the cover, replayed from x0 (Algorithm 4's local variation), (2) the SCP generator's reach-avoid
//! trajectory for the spec's Goal and Unsafe. From either, the critical-atom ascent of §5.3
//! ([`crate::optimize::temporal`]) climbs the formula's robustness; the result is re-certified from the
//! f32 table. The image is Algorithm 2's feedforward image, the firmware runs it unchanged; it is
//! re-proved from its bytes and verified by Monte Carlo against the formula as written
//! ([`crate::verify::temporal`]; a feedback-linearizable task's image on the nonlinear plant,
//! `monte_carlo_temporal_fl`).
//!
//! Everything random is drawn from a ChaCha stream seeded by the spec's seed, and each round's seeds are
//! collected in order, so the image does not depend on the number of threads.

use crate::certify::temporal::{TemporalCertificate, TemporalLoop};
use crate::certify::{Loop, LoopConstants};
use crate::cover::estimate::{estimate, CoverageEstimate, SampleBox};
use crate::cover::seeds::{Generators, Proposal, Seed, Source, Sources};
use crate::optimize::temporal::{maximize_temporal, AscentSettings};
use crate::property::{input_scale, TemporalTask};
use crate::task::Task;
use crate::trajectory::csv::Recording;
use crate::trajectory::generate::GenProblem;
use crate::trajectory::Nominal;
use crate::verify::temporal::{
    monte_carlo_temporal, monte_carlo_temporal_fl, recheck, TemporalCheck, TemporalReport,
};
use faer::Mat;
use rand::SeedableRng;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Rounds in a row that certify nothing before the growth stops.
const MAX_EMPTY_ROUNDS: usize = 6;

/// Options of one run (defaults documented per field).
#[derive(Clone)]
pub struct TemporalOptions {
    /// Monte Carlo runs from covered samples of Init (default 10 000).
    pub verify_interior: usize,
    /// Runs from the boundary of each ball (default 32).
    pub verify_per_ball: usize,
    /// Uniform samples of Init the seeds are chosen from (default 2 000).
    pub working_samples: usize,
    /// Seeds per round, in parallel (default 4).
    pub batch: usize,
    /// The ascent's iterations per seed (default: the spec's `max_iterations`).
    pub iterations: Option<usize>,
    pub cancel: Arc<AtomicBool>,
    /// Called with the number of balls and the new ball's δ after each acceptance.
    pub on_accept: Option<Arc<dyn Fn(usize, f64) + Send + Sync>>,
    /// Told a line at each stage after the growth (the image and its re-proof, the coverage, the Monte
    /// Carlo), as the hybrid synthesis tells its own (default none).
    pub on_progress: Option<crate::cover::StageHook>,
    /// Recordings (name, recording) certified first ([`certify_recording`]); those certified at least
    /// `min_robustness` join the balls before any seed is planned (default none).
    pub imports: Vec<(String, Recording)>,
}

impl Default for TemporalOptions {
    fn default() -> Self {
        Self {
            verify_interior: 10_000,
            verify_per_ball: 32,
            working_samples: 2_000,
            batch: 4,
            iterations: None,
            cancel: Arc::new(AtomicBool::new(false)),
            on_accept: None,
            on_progress: None,
            imports: Vec::new(),
        }
    }
}

/// One certified ball of the cover.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TemporalTrajectory {
    /// Where it came from: Algorithm 4 from a ball (its table replayed), the generator, a recording.
    pub source: crate::cover::Source,
    pub nominal: Nominal,
    pub certificate: TemporalCertificate,
}

/// Everything a run produced.
pub struct TemporalSynthesis {
    pub K: Mat<f64>,
    pub P: Mat<f64>,
    pub trajectories: Vec<TemporalTrajectory>,
    pub seeds_tried: usize,
    /// Seeds that gave no certified ball, and why.
    pub refused: Vec<(Vec<f64>, String)>,
    pub coverage: CoverageEstimate,
    pub image: Vec<u8>,
    pub recheck: Vec<TemporalCheck>,
    pub verify: TemporalReport,
    pub stop: String,
    pub seconds: f64,
    /// Each import: its name and δ, or why it was not used.
    pub imported: Vec<(String, Result<f64, String>)>,
    /// Wall time per stage (growth, re-proof, coverage, Monte Carlo), seconds.
    pub timings: Vec<(String, f64)>,
}

/// A person's recording (`synth --import`, `host-compiler play`) certified for the formula: the nominal
/// of the shipped loop from the recorded x0 and reference inputs, both as f32 (what the image stores),
/// and Theorem 4.2's certificate of it. The formula is judged over the whole horizon of `steps` samples,
/// so a recording must have that many rows: a shorter one would leave windows judged on nothing.
pub fn certify_recording(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    tl: &TemporalLoop,
    steps: usize,
    rec: &Recording,
) -> Result<(Nominal, TemporalCertificate), String> {
    let (n, m) = (lp.P.nrows(), lp.K.nrows());
    if rec.x0.len() != n || rec.v.iter().any(|r| r.len() != m) {
        return Err(format!(
            "the recording's x0 has {} values and its rows {} inputs; the plant has n = {n}, m = {m}",
            rec.x0.len(),
            rec.v.first().map_or(0, Vec::len)
        ));
    }
    if rec.steps() != steps {
        return Err(format!(
            "the task is a formula, judged over the whole horizon of {steps} samples; the recording \
             has {} rows",
            rec.steps()
        ));
    }
    let f32s = |r: &[f64]| -> Vec<f64> { r.iter().map(|&a| a as f32 as f64).collect() };
    // As recorded, or derived from the applied inputs or the states (`trajectory::track`).
    let x0 = f32s(&rec.x0);
    let v = crate::trajectory::track::references(lp.model(), lp.K, lp.input, &x0, rec)
        .map_err(|e| e.to_string())?;
    let v: Vec<Vec<f64>> = v.iter().map(|r| f32s(r)).collect();
    let nominal = lp.simulate(&x0, &v);
    let certificate = crate::certify::temporal::certify_temporal(lp, lc, tl, &nominal);
    Ok((nominal, certificate))
}

/// What limits a temporal certificate, or why it certifies nothing (for messages).
pub fn certificate_text(c: &TemporalCertificate, h: f64) -> String {
    let critical = c.critical.as_ref().map_or(String::new(), |(set, k, neg)| {
        format!(
            ", critical atom {}{set} at t = {:.2} s",
            if *neg { "¬" } else { "" },
            *k as f64 * h
        )
    });
    format!(
        "ρ(0) = {:.3e} at the samples{critical}, {:.3e} between them, δ_Input = {:.3e} at t = {:.2} s, \
         r_crit = {:.3e}",
        c.delta_samples,
        c.delta_continuous,
        c.delta_input,
        c.k_input as f64 * h,
        c.r_crit
    )
}

/// How the reason a seed gives starts when the formula is vacuous ([`vacuous`]).
pub const VACUOUS: &str = "the formula is (nearly) always true";

/// Ratio of ρ(0) to the input margin it costs past which a failed certificate is put down to the
/// formula's margin: the f32 rounding over the tube (taken at radius ρ(0)) grows with ρ(0) at the rate of
/// f32 rounding times the loop's gains, far below this ratio's inverse for a formula that constrains the
/// runs.
const VACUOUS_RATIO: f64 = 1e3;

/// The reason a run's certificate fails when the formula holds by a margin no tube can use: ρ(0) = +∞
/// (`true`), or so large that the f32 rounding over a tube that wide leaves no input margin
/// (δ_Input < 0 by far less than ρ(0)). Every run fails the same way, so the growth stops at the first.
fn vacuous(c: &TemporalCertificate) -> Option<String> {
    let rho = c.delta_samples;
    let unusable = rho.is_infinite()
        || c.delta_input.is_nan()
        || c.delta_input == f64::NEG_INFINITY
        || (c.delta_input < 0.0 && rho > VACUOUS_RATIO * -c.delta_input);
    (rho > 0.0 && unusable).then(|| {
        format!(
            "{VACUOUS}: it holds on this run with robustness ρ(0) = {rho:.3e}, a margin no tube of the \
             controller can use, so there is nothing to certify; write a formula that constrains the \
             runs (e.g. reach Goal: `F[0,T] goal`), and check its predicates' constants against the \
             states' range"
        )
    })
}

/// What planning a seed borrows from the run.
struct Planner<'a> {
    lp: &'a Loop<'a>,
    lc: &'a LoopConstants,
    tl: &'a TemporalLoop,
    /// The seed sources: the SCP generator alone (no routes; its references are not held, as the ascent
    /// does not keep a hold).
    gens: Generators<'a>,
    ascent: AscentSettings,
    cancel: &'a AtomicBool,
}

/// A seed's best attempt: certified, or the reason it is not. The candidates are the seed's sources in
/// order ([`crate::cover::seeds`]): the nearest ball's table replayed from the seed itself (Algorithm 4's
/// local variation) when `nearest` names one, then the generator; each climbed by the ascent.
fn plan(
    p: &Planner<'_>,
    x0: &[f64],
    nearest: Option<(usize, &[Vec<f64>])>,
) -> Result<TemporalTrajectory, String> {
    let Planner {
        lp,
        lc,
        tl,
        gens,
        ascent,
        cancel,
    } = p;
    let mut why = Vec::new();
    let seed = Seed {
        x: x0.to_vec(),
        grow: nearest.map(|(i, _)| (i, x0.to_vec())),
    };
    // The nearest ball's table stands at its index; the others are not asked for.
    let mut tables: Vec<&[Vec<f64>]> = Vec::new();
    if let Some((i, v)) = nearest {
        tables.resize(i + 1, &[]);
        tables[i] = v;
    }
    let src = gens.over(tables);
    for Proposal { origin, candidate } in src.proposals(&seed) {
        let source = Source::new(origin, false);
        let v = match candidate {
            Ok(v) => v,
            Err(e) => {
                why.push(format!("generator: {e}"));
                continue;
            }
        };
        let o = maximize_temporal(lp, lc, tl, x0, &v, ascent, cancel);
        if o.certificate.is_certified() {
            return Ok(TemporalTrajectory {
                source,
                nominal: o.nominal,
                certificate: o.certificate,
            });
        }
        if let Some(v) = vacuous(&o.certificate) {
            return Err(v);
        }
        why.push(format!(
            "{source}: ρ(0) = {:.3e}, continuous {:.3e}, δ_Input = {:.3e} after {} ascent steps",
            o.certificate.delta_samples,
            o.certificate.delta_continuous,
            o.certificate.delta_input,
            o.iterations
        ));
    }
    Err(why.join("; "))
}

/// One ball from one seed, without a cover: the CAF, the nominal from the SCP generator climbed by the
/// ascent and certified, and its one-ball feedforward image (for the HIL tests and examples).
pub fn single_ball(
    task: &Task,
    tt: &TemporalTask,
    x0: &[f64],
) -> Result<(TemporalTrajectory, Vec<u8>), String> {
    let s = task.settings();
    let design = crate::caf::design(task).map_err(|e| format!("no CAF and feedback: {e}"))?;
    let lp = Loop::new(task, &design);
    let lc = LoopConstants::new(&lp).map_err(|e| e.to_string())?;
    let tl = TemporalLoop::new(tt, &lp).map_err(|e| e.to_string())?;
    let gp = gen_problem(task, &lp, &lc);
    let cancel = AtomicBool::new(false);
    let planner = Planner {
        lp: &lp,
        lc: &lc,
        tl: &tl,
        gens: Generators::new(&gp, 1),
        ascent: ascent_settings(task, s.max_iterations),
        cancel: &cancel,
    };
    let x0: Vec<f64> = x0.iter().map(|&a| a as f32 as f64).collect();
    let ball = plan(&planner, &x0, None)?;
    let image = crate::cover::feedforward_image_of(
        task,
        &lp.K.to_owned(),
        &lp.P.to_owned(),
        [(&ball.nominal, ball.certificate.delta_stored)],
    )
    .map_err(|e| format!("image: {e}"))?;
    Ok((ball, image))
}

/// The generator's problem: the spec's Goal and Unsafe with the loop's tube constants.
pub fn gen_problem<'a>(task: &'a Task, lp: &Loop<'a>, lc: &LoopConstants) -> GenProblem<'a> {
    GenProblem {
        loc: 0,
        plant: &*task.plant,
        K: lp.K,
        P: lp.P,
        property: &task.property,
        convex: &task.convex,
        steps: task.steps,
        gamma: lc.gamma,
        phi: lc.phi,
        beta: lc.beta,
        input_margin: 1e-5 * input_scale(&task.property.input),
        schedule: None,
    }
}

/// The ascent's settings, scaled to the input set.
fn ascent_settings(task: &Task, iterations: usize) -> AscentSettings {
    let scale = input_scale(&task.property.input);
    AscentSettings {
        iterations,
        initial_step: 0.05 * scale,
        min_step: 1e-6 * scale,
    }
}

/// Algorithm 1 for the formula (module doc).
pub fn synthesize_temporal(
    task: &Task,
    tt: &TemporalTask,
    opts: &TemporalOptions,
) -> Result<TemporalSynthesis, String> {
    let t0 = std::time::Instant::now();
    let s = task.settings();
    let design = crate::caf::design(task).map_err(|e| format!("no CAF and feedback: {e}"))?;
    let lp = Loop::new(task, &design);
    let lc = LoopConstants::new(&lp).map_err(|e| e.to_string())?;
    let tl = TemporalLoop::new(tt, &lp).map_err(|e| e.to_string())?;
    let gp = gen_problem(task, &lp, &lc);
    let ascent = ascent_settings(task, opts.iterations.unwrap_or(s.max_iterations));
    let planner = Planner {
        lp: &lp,
        lc: &lc,
        tl: &tl,
        gens: Generators::new(&gp, 1),
        ascent,
        cancel: &opts.cancel,
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(task.problem.seed);
    let init = SampleBox {
        lo: task.init().lo.clone(),
        hi: task.init().hi.clone(),
    };
    let working = init.samples(opts.working_samples.max(1), &mut rng);
    let round32 = |x: &[f64]| -> Vec<f64> { x.iter().map(|&a| a as f32 as f64).collect() };
    let centre: Vec<f64> = init
        .lo
        .iter()
        .zip(&init.hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect();
    let mut balls: Vec<TemporalTrajectory> = Vec::new();
    let mut refused = Vec::new();
    let mut tried = vec![false; working.len()];
    let (mut seeds_tried, mut empty_rounds, mut first) = (0usize, 0usize, true);
    let target = (s.coverage_target + s.coverage_tolerance).min(1.0);
    let budget = s.max_trajectories;
    let P = lp.P.to_owned();
    let inside = |balls: &[TemporalTrajectory], x: &[f64]| -> Option<(usize, f64)> {
        // The nearest ball in the CAF metric, and whether x lies in it (the f64 test; the image's f32
        // selection decides coverage at the end).
        balls
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let e: Vec<f64> = x.iter().zip(&b.nominal.x[0]).map(|(a, c)| a - c).collect();
                (
                    i,
                    crate::linalg::p_norm(P.as_ref(), &e) - b.certificate.delta_stored as f64,
                )
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
    };
    // Recorded trajectories first, through the same accept test as planned ones.
    let mut imported = Vec::with_capacity(opts.imports.len());
    for (name, rec) in &opts.imports {
        let r = certify_recording(&lp, &lc, &tl, task.steps, rec).and_then(|(nominal, c)| {
            if !c.is_certified() {
                Err(format!(
                    "not certified: {}",
                    certificate_text(&c, task.plant.period())
                ))
            } else if c.delta < s.min_robustness {
                Err(format!(
                    "δ = {:.3e} below min_robustness {:.3e}",
                    c.delta, s.min_robustness
                ))
            } else if balls.len() >= budget {
                Err(format!("the budget of {budget} trajectories is spent"))
            } else {
                let d = c.delta;
                balls.push(TemporalTrajectory {
                    source: Source::import(name),
                    nominal,
                    certificate: c,
                });
                if let Some(f) = &opts.on_accept {
                    f(balls.len(), d);
                }
                Ok(d)
            }
        });
        imported.push((name.clone(), r));
    }
    let stop = loop {
        if opts.cancel.load(Ordering::Relaxed) {
            break "interrupted".to_string();
        }
        let covered = working
            .iter()
            .filter(|x| inside(&balls, x).is_some_and(|(_, g)| g <= 0.0))
            .count();
        let frac = covered as f64 / working.len() as f64;
        if frac >= target {
            break format!("the working samples are covered ({:.1} %)", 100.0 * frac);
        }
        if balls.len() >= budget {
            break format!("the budget of {budget} trajectories is spent");
        }
        if empty_rounds >= MAX_EMPTY_ROUNDS {
            break format!(
                "{MAX_EMPTY_ROUNDS} rounds in a row certified no ball: a new seed trajectory is needed"
            );
        }
        let seeds: Vec<Vec<f64>> = if first {
            first = false;
            vec![round32(&centre)]
        } else {
            let mut out = Vec::new();
            for (i, x) in working.iter().enumerate() {
                if out.len() == opts.batch.max(1) {
                    break;
                }
                if !tried[i] && inside(&balls, x).is_none_or(|(_, g)| g > 0.0) {
                    tried[i] = true;
                    out.push(round32(x));
                }
            }
            out
        };
        if seeds.is_empty() {
            break "every uncovered working sample was tried: a new seed trajectory is needed"
                .to_string();
        }
        seeds_tried += seeds.len();
        let nearest: Vec<Option<usize>> = seeds
            .iter()
            .map(|x| inside(&balls, x).map(|(i, _)| i))
            .collect();
        let planned: Vec<Result<TemporalTrajectory, String>> = seeds
            .par_iter()
            .zip(&nearest)
            .map(|(x, near)| {
                let near = near.map(|i| (i, balls[i].nominal.v.as_slice()));
                plan(&planner, x, near)
            })
            .collect();
        let before = balls.len();
        for (x, r) in seeds.into_iter().zip(planned) {
            match r {
                Ok(t) if t.certificate.delta >= s.min_robustness && balls.len() < budget => {
                    balls.push(t);
                    if let Some(f) = &opts.on_accept {
                        f(
                            balls.len(),
                            balls.last().map_or(0.0, |b| b.certificate.delta),
                        );
                    }
                }
                Ok(t) => refused.push((
                    x,
                    format!(
                        "δ = {:.3e} below min_robustness {:.3e}",
                        t.certificate.delta, s.min_robustness
                    ),
                )),
                Err(e) => refused.push((x, e)),
            }
        }
        // A vacuous formula fails every run alike: said at the first.
        if let (true, Some((_, why))) = (balls.is_empty(), refused.last()) {
            if why.starts_with(VACUOUS) {
                return Err(why.clone());
            }
        }
        empty_rounds = if balls.len() > before {
            0
        } else {
            empty_rounds + 1
        };
    };
    let mut timings = vec![("growth".to_string(), t0.elapsed().as_secs_f64())];
    let mut lap = std::time::Instant::now();
    let mut mark = |what: &str, timings: &mut Vec<(String, f64)>| {
        timings.push((what.to_string(), lap.elapsed().as_secs_f64()));
        lap = std::time::Instant::now();
    };
    if balls.is_empty() {
        return Err(format!(
            "no trajectory was certified for the formula ({seeds_tried} seeds tried; first reason: {})",
            refused.first().map_or("none", |r| r.1.as_str())
        ));
    }
    let K = lp.K.to_owned();
    let image = crate::cover::feedforward_image_of(
        task,
        &K,
        &P,
        balls
            .iter()
            .map(|b| (&b.nominal, b.certificate.delta_stored)),
    )
    .map_err(|e| format!("image: {e}"))?;
    let decoded = shared_types::image::decode(&image).map_err(|e| format!("image: {e}"))?;
    mark("image", &mut timings);
    let progress = |line: String| {
        if let Some(f) = &opts.on_progress {
            f.stage(&line);
        }
    };
    progress(format!(
        "image: {} bytes; re-proving {} balls from its bytes",
        image.len(),
        balls.len()
    ));
    let recheck = recheck(task, tt, &decoded).map_err(|e| e.to_string())?;
    mark("re-proof", &mut timings);
    // Coverage (§2.5.2) on fresh samples through the image's own f32 selection.
    let ctl = shared_types::eval::Controller::new(decoded);
    let accepted = |x: &[f64]| {
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        ctl.select_maps(&x32).is_some()
    };
    progress(format!(
        "coverage from {} samples of Init",
        s.coverage_samples()
    ));
    let coverage = estimate(&init, s.coverage_samples(), s.confidence, &mut rng, |x| {
        accepted(x)
    });
    mark("coverage", &mut timings);
    // Monte Carlo: covered samples of Init, and the boundary of every ball.
    let starts = crate::verify::hybrid::starts_from_image(
        &image,
        &init,
        opts.verify_interior,
        opts.verify_per_ball,
        task.problem.seed ^ 0x7e51f1,
    )?;
    progress(format!(
        "Monte Carlo: {} closed-loop runs judged by the formula",
        starts.len()
    ));
    // A feedback-linearizable task's image runs on the nonlinear plant (its zero states drawn in Init).
    let verify = if task.plant.linearization().is_some() {
        monte_carlo_temporal_fl(task, tt, &decoded, &starts, task.problem.seed ^ 0x2e10)?
    } else {
        monte_carlo_temporal(task, tt, &decoded, &starts).map_err(|e| e.to_string())?
    };
    mark("monte carlo", &mut timings);
    Ok(TemporalSynthesis {
        K,
        P,
        trajectories: balls,
        seeds_tried,
        refused,
        imported,
        coverage,
        image,
        recheck,
        verify,
        stop,
        seconds: t0.elapsed().as_secs_f64(),
        timings,
    })
}
