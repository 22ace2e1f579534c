//! `host-compiler verify SPEC IMAGE`: an image against its spec: refused unless its dimensions and sample
//! period are the spec's, its certificate re-proved from the bytes ([`crate::verify::feedforward`],
//! [`crate::verify::pwa`]), then closed-loop Monte Carlo through the shared f32 evaluator, and with
//! `--attack` the falsifier ([`crate::verify::attack`]) for every image mode.

use super::{
    decode_image, image_matches_spec, read_image, task_of, BadInput, Exit, Failure, Outcome,
};
use crate::verify::attack::{AttackError, AttackReport, AttackSettings};
use crate::verify::{monte_carlo, Judge};
use miette::IntoDiagnostic;
use std::path::PathBuf;

/// Arguments of `verify`.
#[derive(clap::Args, Debug)]
pub struct VerifyArgs {
    /// Task spec (TOML).
    pub spec: PathBuf,
    /// Controller image.
    pub image: PathBuf,
    /// Initial states drawn uniformly in the certified cover (the part of Init the image accepts); at
    /// most 1000000 (`verify::MAX_RUNS`: each start is held in memory).
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u64).range(..=crate::verify::MAX_RUNS))]
    pub runs: u64,
    /// Initial states on the boundary of each ball; at most 4096 (`verify::MAX_PER_BALL`).
    #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u64).range(..=crate::verify::MAX_PER_BALL))]
    pub per_ball: u64,
    /// Seed of the Monte Carlo draw (default: the spec's seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
    /// Also run the falsifier (every image mode): multi-start Nelder–Mead over each ball, its shell and
    /// its f32 neighbourhood for the start whose run has the least robustness against the task (the
    /// formula's for MTL tasks; on the automaton's flow for hybrid images, on the plant itself for
    /// feedback-linearizable plants; [`crate::verify::attack`]); any violation it finds fails the
    /// verification.
    #[arg(long)]
    pub attack: bool,
    /// Closed-loop runs per Nelder–Mead start of the falsifier (two starts per ball); at least n + 2, at
    /// most 100000.
    #[arg(long, default_value_t = 120, requires = "attack", value_parser = clap::value_parser!(u64).range(3..=100_000))]
    pub attack_evals: u64,
}

pub fn run(a: &VerifyArgs) -> Outcome {
    // Within `verify::MAX_RUNS` and `MAX_PER_BALL` (clap checked), so the conversions are exact.
    let (runs, per_ball) = (a.runs as usize, a.per_ball as usize);
    let problem = crate::spec::load(&a.spec).bad_input()?;
    let bytes = read_image(&a.image)?;
    let img = decode_image(&bytes, &a.image)?;
    image_matches_spec(&problem, &img, &a.image, &a.spec)?;
    let pwa = img.mode() == shared_types::image::Mode::PwaFeedback;
    // Nothing would be simulated: the Monte Carlo part would pass vacuously.
    if runs == 0 && (pwa || per_ball == 0) {
        return Err(Failure::bad_input(miette::miette!(
            "--runs 0{}: no closed-loop run would be checked; ask for at least one run",
            if pwa { "" } else { " --per-ball 0" }
        )));
    }
    if problem.hybrid.is_some() {
        return run_hybrid(a, runs, per_ball, problem, &bytes);
    }
    if problem.mtl.is_some() {
        return run_temporal(a, runs, per_ball, problem, &bytes);
    }
    let task = task_of(problem)?;
    let problem = &task.problem;
    let judge = Judge::new(&task);
    if pwa {
        return run_pwa(a, runs, &task, &judge, &img, problem.seed);
    }
    let linearized = task.plant.linearization().is_some();
    if let Some(maps) = task.plant.linearization() {
        super::maps_match(maps, &img, &a.image, &a.spec)?;
    }
    let rc = crate::verify::feedforward::recheck(&judge, &img)
        .map_err(|e| miette::miette!("{}: {e}", a.image.display()))?;
    let terminal = terminal_recheck(&task, &img, &a.image, !a.json)?;
    let seed = a.seed.unwrap_or(problem.seed ^ 0x7e51f1);
    let r = if linearized {
        crate::verify::nonlinear::monte_carlo_fl(&task, &img, runs, per_ball, seed)
    } else {
        monte_carlo(&judge, &img, runs, per_ball, seed)
    }
    .into_diagnostic()?;
    let attack = match attack_settings(a, problem.seed)? {
        Some(s) if linearized => {
            Some(crate::verify::attack::attack_fl(&task, &img, &s).bad_input()?)
        }
        Some(s) => Some(crate::verify::attack::attack(&judge, &img, &s).bad_input()?),
        None => None,
    };
    if a.json {
        let j = serde_json::json!({
            "recheck": rc, "terminal": terminal, "monte_carlo": r, "attack": attack,
        });
        println!("{}", serde_json::to_string_pretty(&j).into_diagnostic()?);
    } else {
        println!(
            "radii re-proved from the bytes: {} trajectories, {} failing (worst stored/certified {:.9}, \
             tolerance 1 + {:.1e}; σ_min {:.4e})",
            rc.trajectories.len(),
            rc.failures,
            rc.worst_ratio,
            rc.tolerance,
            rc.sigma_min
        );
        let whitened: Vec<f64> = rc
            .trajectories
            .iter()
            .filter_map(|c| c.selection_test.map(|r| r / c.delta))
            .collect();
        if !whitened.is_empty() {
            println!(
                "selection test re-proved from the bytes: {} thresholds (accepted states within {:.9} × the certified radius at most)",
                whitened.len(),
                whitened.iter().copied().fold(0.0f64, f64::max)
            );
        }
        for c in &rc.trajectories {
            if let Some(why) = c.failure(rc.horizon) {
                println!("certificate failure: {why}");
            }
        }
        println!(
            "runs {} interior + {} boundary ({} boundary points not accepted by the f32 selection)",
            r.interior_runs, r.boundary_runs, r.boundary_rejected
        );
        println!(
            "worst margins: goal depth {}, unsafe distance {}, input slack {}",
            margin(r.worst_goal_margin),
            if judge.unsafe_set().is_none() {
                "none (no Unsafe set)".to_string()
            } else {
                margin(r.worst_unsafe_margin)
            },
            margin(r.worst_input_margin)
        );
        for v in &r.first_violations {
            println!("violation from x0 = {:?}: {v:?}", v.x0);
        }
        print_after_goal(&r);
        println!("violations {}", r.violations);
        print_attack(attack.as_ref());
    }
    if rc.failures > 0 {
        let first = rc
            .trajectories
            .iter()
            .find_map(|c| c.failure(rc.horizon))
            .unwrap_or_default();
        return Err(miette::miette!(
            "{}: {} of {} stored radii are not certified by the image's own bytes; first: {first}",
            a.image.display(),
            rc.failures,
            rc.trajectories.len()
        )
        .into());
    }
    if r.violations > 0 {
        return Err(miette::miette!("{} violations", r.violations).into());
    }
    attack_verdict(attack.as_ref())?;
    if r.interior_runs < runs {
        return Err(miette::miette!(
            "only {} of {} initial states could be drawn in the certified cover",
            r.interior_runs,
            runs
        )
        .into());
    }
    Ok(Exit::Success)
}

/// The image's terminal law re-proved from its bytes, printed when `print` (not with `--json`, whose
/// object holds it); a law the bytes do not certify is a failed check (exit 1) naming the condition.
fn terminal_recheck(
    task: &crate::task::Task,
    img: &shared_types::image::Image<'_>,
    path: &std::path::Path,
    print: bool,
) -> Result<Option<crate::certify::terminal::TerminalCertificate>, Failure> {
    match crate::verify::recheck_terminal(task, img) {
        None => {
            if print {
                println!("terminal law: none in the image");
            }
            Ok(None)
        }
        Some(Ok(c)) if !print => Ok(Some(c)),
        Some(Ok(c)) => {
            println!(
                "terminal law re-proved from the bytes: contraction {:.4}, next sample within {:.6} of the accepted {:.6}; Goal depth {:.4} ≥ {:.4}, Unsafe distance {:.4}, input distance {:.4} (ellipsoid metric)",
                c.contraction, c.theta, c.acceptance_floor, c.goal_depth, c.between_samples, c.unsafe_distance, c.input_distance
            );
            Ok(Some(c))
        }
        Some(Err(e)) => Err(miette::miette!(
            "{}: the terminal law is not certified by the image's own bytes: {e}",
            path.display()
        )
        .into()),
    }
}

/// What the runs did after Goal: under a terminal law this is judged (its violations are counted);
/// without one it is reported only.
fn print_after_goal(r: &crate::verify::VerifyReport) {
    println!(
        "after Goal: {} runs were outside Goal again within {} samples, {} were handed over to the terminal law; {} left the input set, {} entered Unsafe (judged only under the terminal law)",
        r.runs_leaving_goal, r.run_steps, r.handed_over, r.after_goal_input_excursions, r.after_goal_unsafe
    );
}

/// The falsifier's settings from the flags (`None` without `--attack`), seeded by `--seed` or the spec's.
fn attack_settings(a: &VerifyArgs, spec_seed: u64) -> Result<Option<AttackSettings>, Failure> {
    if !a.attack {
        return Ok(None);
    }
    let s = AttackSettings::builder()
        .evaluations_per_start(a.attack_evals as usize)
        .seed(a.seed.unwrap_or(spec_seed ^ 0xa77ac))
        .build()
        .map_err(AttackError::from)
        .bad_input()?;
    Ok(Some(s))
}

/// The falsifier's line (and its violations, each with its start), when it ran.
fn print_attack(attack: Option<&AttackReport>) {
    let Some(at) = attack else { return };
    println!(
        "attack: {} runs in {:.2} s ({:.0} runs/s); least robustness {} from x0 = {:?}; violations {}",
        at.evaluations,
        at.seconds,
        at.evaluations as f64 / at.seconds.max(1e-9),
        margin(at.worst_robustness),
        at.worst_start,
        at.violations
    );
    for v in &at.first_violations {
        println!("attack violation from x0 = {:?}: {}", v.x0, v.what);
    }
}

/// A failed check when the falsifier found a violating run (named with its start).
fn attack_verdict(attack: Option<&AttackReport>) -> Result<(), Failure> {
    match attack {
        Some(at) if at.violations > 0 => {
            let first = at
                .first_violations
                .first()
                .map(|v| format!(" (first from x0 = {:?}: {})", v.x0, v.what))
                .unwrap_or_default();
            Err(miette::miette!(
                "the falsifier found {} violating runs{first}",
                at.violations
            )
            .into())
        }
        _ => Ok(()),
    }
}

/// A worst margin for people: its value, or that no run recorded one (never `inf` as if it were a
/// result).
fn margin(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4e}")
    } else {
        "none recorded (no run reached this check)".to_string()
    }
}

/// PWA images (Ch. 6): the independent certificate recheck and closed-loop Monte Carlo from F
/// ([`crate::verify::pwa`]); runs terminate upon entering Goal (Theorem 6.5).
fn run_pwa(
    a: &VerifyArgs,
    runs: usize,
    task: &crate::task::Task,
    judge: &Judge<'_>,
    img: &shared_types::image::Image<'_>,
    spec_seed: u64,
) -> Outcome {
    let rc = crate::verify::pwa::recheck(judge, img).map_err(|e| miette::miette!(e))?;
    let terminal = terminal_recheck(task, img, &a.image, !a.json)?;
    // The image does not mark which balls start a trajectory: all runs start anywhere in F.
    let mc =
        crate::verify::pwa::monte_carlo_pwa(judge, img, &[], runs, a.seed.unwrap_or(0x7e51f1), 0)
            .into_diagnostic()?;
    let attack = match attack_settings(a, spec_seed)? {
        Some(s) => Some(crate::verify::attack::attack_pwa(judge, img, &s).bad_input()?),
        None => None,
    };
    if a.json {
        let j = serde_json::json!({
            "recheck": rc, "terminal": terminal, "monte_carlo": mc, "attack": attack,
        });
        println!("{}", serde_json::to_string_pretty(&j).into_diagnostic()?);
    } else {
        println!(
            "partitions {}, tree depth {}, containment across boundaries: {} leaf visits, {} failing balls",
            rc.partitions.len(),
            rc.depth,
            rc.containment_checks,
            rc.containment_failures
        );
        for p in rc.partitions.iter().filter(|p| !p.ok) {
            println!("partition {} fails its certificate: {p:?}", p.partition);
        }
        println!("goal within T: {}", rc.liveness.describe());
        println!(
            "runs {} from F ({} drawn starts not accepted), at most {} steps to Goal",
            mc.runs, mc.rejected, mc.max_steps_to_goal
        );
        if img.terminal_law().is_some() {
            println!(
                "after Goal (judged under the terminal law, to {} samples): {} runs were outside Goal again, {} were handed over",
                crate::verify::run_steps(judge, img),
                mc.runs_leaving_goal,
                mc.handed_over
            );
        }
        for v in &mc.first_violations {
            println!("violation from x0 = {:?}: {v:?}", v.x0);
        }
        println!("violations {}", mc.violations);
        print_attack(attack.as_ref());
    }
    if rc.failures > 0 || mc.violations > 0 {
        return Err(miette::miette!(
            "{} certificate failures, {} violations",
            rc.failures,
            mc.violations
        )
        .into());
    }
    attack_verdict(attack.as_ref())?;
    if mc.runs < runs {
        return Err(miette::miette!(
            "only {} of {} initial states could be drawn in F",
            mc.runs,
            runs
        )
        .into());
    }
    Ok(Exit::Success)
}

/// `verify` of an image for an MTL task: every ball re-proved from the bytes for the formula
/// ([`crate::verify::temporal::recheck`]), then Monte Carlo from Init (states the image accepts) and from
/// the boundary of every ball, each run judged by the formula as written.
fn run_temporal(
    a: &VerifyArgs,
    runs: usize,
    per_ball: usize,
    problem: crate::spec::Problem,
    bytes: &[u8],
) -> Outcome {
    use crate::verify::temporal::{monte_carlo_temporal, recheck};
    let img = decode_image(bytes, &a.image)?;
    if img.mode() != shared_types::image::Mode::Feedforward || problem.hybrid.is_some() {
        return Err(Failure::bad_input(miette::miette!(
            "{}: MTL tasks are certified for feedforward images of one-location plants",
            a.image.display()
        )));
    }
    let ts = super::synth_temporal::temporal_task(problem)?;
    let (tt, task) = (&ts.tt, &ts.task);
    if let Some(maps) = task.plant.linearization() {
        super::maps_match(maps, &img, &a.image, &a.spec)?;
    }
    let rc = recheck(task, tt, &img)
        .map_err(|e| miette::miette!("{}: {e}", a.image.display()))
        .bad_input()?;
    let init = crate::cover::estimate::SampleBox {
        lo: task.problem.init.lo.clone(),
        hi: task.problem.init.hi.clone(),
    };
    let seed = a.seed.unwrap_or(task.problem.seed ^ 0x7e51f1);
    let starts = crate::verify::hybrid::starts_from_image(bytes, &init, runs, per_ball, seed)
        .map_err(|e| miette::miette!("{e}"))
        .bad_input()?;
    let linearized = task.plant.linearization().is_some();
    let r = if linearized {
        // On the nonlinear plant, the zero states drawn in Init.
        crate::verify::temporal::monte_carlo_temporal_fl(task, tt, &img, &starts, seed ^ 0x2e10)
            .map_err(|e| miette::miette!("{}: {e}", a.image.display()))
            .bad_input()?
    } else {
        monte_carlo_temporal(task, tt, &img, &starts).map_err(miette::Report::new)?
    };
    let attack = match attack_settings(a, task.problem.seed)? {
        // On the nonlinear plant too.
        Some(s) if linearized => {
            Some(crate::verify::attack::attack_temporal_fl(task, tt, &img, &s).bad_input()?)
        }
        Some(s) => Some(crate::verify::attack::attack_temporal(task, tt, &img, &s).bad_input()?),
        None => None,
    };
    let unproved: Vec<usize> = rc.iter().filter(|c| !c.ok).map(|c| c.trajectory).collect();
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"recheck": rc, "monte_carlo": r, "attack": attack})
            )
            .into_diagnostic()?
        );
    } else {
        println!(
            "re-proved         {} of {} balls from the image bytes, for `{}`{}",
            rc.len() - unproved.len(),
            rc.len(),
            ts.written,
            ts.rewritten()
                .map_or(String::new(), |xi| format!(" (in ξ: `{xi}`)"))
        );
        println!(
            "monte carlo       {} runs judged by the formula at the samples and sampled 8× finer ({} starts refused by the f32 selection, not run), {} violations",
            r.runs, r.rejected, r.violations
        );
        print_attack(attack.as_ref());
    }
    if let Some(c) = rc.iter().find(|c| !c.ok) {
        // The stored radius within the certified one: what failed is the selection test's threshold.
        let what = if c.selection_test.is_some() && c.stored <= c.certified {
            "its whitened selection test accepts states beyond"
        } else {
            "its stored radius exceeds"
        };
        return Err(miette::miette!(
            "{}: ball {} is not re-proved: {what} what its table certifies for the formula",
            a.image.display(),
            c.trajectory
        )
        .into());
    }
    if r.violations > 0 {
        return Err(miette::miette!(
            "{} violations (first: {})",
            r.violations,
            r.first_violation.as_deref().unwrap_or("?")
        )
        .into());
    }
    attack_verdict(attack.as_ref())?;
    Ok(Exit::Success)
}

/// `verify` of a hybrid image: every run re-proved from the bytes ([`crate::verify::hybrid::recheck`]),
/// then Monte Carlo against the automaton's exact flow from Init (states the image accepts) and from the
/// boundary of every ball.
fn run_hybrid(
    a: &VerifyArgs,
    runs: usize,
    per_ball: usize,
    problem: crate::spec::Problem,
    bytes: &[u8],
) -> Outcome {
    use crate::verify::hybrid::{monte_carlo_hybrid, recheck, starts_from_image, HybridReport};
    use rayon::prelude::*;
    let task = crate::synth::hybrid::HybridTask::new(problem)
        .map_err(|e| miette::miette!("{e}"))
        .bad_input()?;
    let rc = recheck(
        &task.plant,
        &task.property,
        task.formula.as_ref(),
        task.steps,
        bytes,
    )
    .map_err(|e| miette::miette!("{}: {e}", a.image.display()))
    .bad_input()?;
    let init = crate::cover::estimate::SampleBox {
        lo: task.problem.init.lo.clone(),
        hi: task.problem.init.hi.clone(),
    };
    let seed = a.seed.unwrap_or(task.problem.seed ^ 0x7e51f1);
    let starts = starts_from_image(bytes, &init, runs, per_ball, seed)
        .map_err(|e| miette::miette!("{e}"))
        .bad_input()?;
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
        r.merge(p.map_err(|e| miette::miette!("{e}"))?);
    }
    let attack = match attack_settings(a, task.problem.seed)? {
        Some(s) => {
            let runs = crate::verify::attack::HybridRuns {
                plant: &task.plant,
                property: &task.property,
                formula: task.formula.as_ref(),
                initial: task.initial,
                steps: task.steps,
            };
            Some(crate::verify::attack::attack_hybrid(runs, bytes, &s).bad_input()?)
        }
        None => None,
    };
    let unproved: Vec<&str> = rc.iter().filter_map(|c| c.why.as_deref()).collect();
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"recheck": rc, "monte_carlo": r, "attack": attack})
            )
            .into_diagnostic()?
        );
    } else {
        println!(
            "re-proved         {} of {} runs from the image bytes",
            rc.len() - unproved.len(),
            rc.len()
        );
        println!(
            "monte carlo       {} runs ({} switched, at most {} events; {} starts refused by the f32 selection, not run), {} violations",
            r.runs - r.rejected,
            r.switched,
            r.max_events,
            r.rejected,
            r.violations
        );
        print_attack(attack.as_ref());
    }
    if let Some(why) = unproved.first() {
        return Err(miette::miette!("{}: not re-proved: {why}", a.image.display()).into());
    }
    if r.violations > 0 {
        return Err(miette::miette!(
            "{} violations (first: {})",
            r.violations,
            r.first_violation.as_deref().unwrap_or("?")
        )
        .into());
    }
    attack_verdict(attack.as_ref())?;
    Ok(Exit::Success)
}
