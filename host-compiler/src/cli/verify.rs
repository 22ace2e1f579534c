//! `host-compiler verify SPEC IMAGE`: an image against its spec, by [`crate::verification::verify`]
//! (refused unless its dimensions, sample period and fingerprint are the spec's; its stored values the
//! spec gives, its certificate re-proved from the bytes, its coverage of the spec's Init estimated, then
//! closed-loop Monte Carlo through the shared f32 evaluator, and with `--attack` the falsifier for every
//! image mode). This file parses the flags, prints the result and maps it to the exit status: 1 for a
//! failed check, 3 when every check passed but the coverage of the spec's Init is short of its target.

use super::{decode_image, image_matches_spec, read_image, Exit, Failure, Outcome};
use crate::verification::{Options, Refusal, Report, Verification};
use crate::verify::attack::AttackReport;
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
    let problem = crate::spec::load(&a.spec).map_err(Failure::bad_input)?;
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
    let o = Options {
        runs,
        per_ball,
        seed: a.seed,
        attack_evals: a.attack.then_some(a.attack_evals as usize),
        coverage: true,
        stop_early: false,
        progress: Some(super::stage_lines()),
    };
    let v = crate::verification::verify(problem, &bytes, &o).map_err(|r| refusal(r, a))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v).into_diagnostic()?);
    } else {
        print_report(&v, &img);
    }
    exit_of(&v, a)
}

/// A verification that could not run: bad input naming the files.
fn refusal(r: Refusal, a: &VerifyArgs) -> Failure {
    Failure::bad_input(match r {
        Refusal::Rejected(e) => {
            miette::miette!("{}: the image is rejected: {e}", a.image.display())
        }
        Refusal::Mismatch(e) => miette::miette!(
            "{} does not belong to {}: {e}",
            a.image.display(),
            a.spec.display()
        ),
        Refusal::BadInput(e) => e.wrap_err(format!("{}", a.image.display())),
    })
}

/// The exit status of a verification: a failed check (1, naming it), short of the spec's coverage
/// target (3, said on standard error), or success.
fn exit_of(v: &Verification, a: &VerifyArgs) -> Outcome {
    if let Some(f) = &v.failure {
        return Err(if f.about_image {
            miette::miette!("{}: {}", a.image.display(), f.message)
        } else {
            miette::miette!("{}", f.message)
        }
        .into());
    }
    if let Some(c) = v.coverage.as_ref().filter(|c| !c.met) {
        eprintln!(
            "coverage target NOT met: the image covers the spec's Init at least {:.5} at {} confidence ({} of {} samples), short of the target {}; it is verified for its cover only (exit status 3)",
            c.estimate.lower, c.estimate.confidence, c.estimate.covered, c.estimate.samples, c.target
        );
        return Ok(Exit::ShortOfTarget);
    }
    Ok(Exit::Success)
}

/// The report for people: each mode's lines, then the coverage line.
fn print_report(v: &Verification, img: &shared_types::image::Image<'_>) {
    match &v.report {
        Report::Feedforward {
            recheck,
            terminal,
            monte_carlo,
            attack,
            has_unsafe,
        } => {
            print_terminal(terminal.as_ref(), img);
            print_feedforward(recheck, monte_carlo.as_ref(), *has_unsafe, attack.as_ref());
        }
        Report::Pwa {
            recheck: rc,
            terminal,
            monte_carlo,
            attack,
            run_steps,
        } => {
            print_terminal(terminal.as_ref(), img);
            println!(
                "partitions {}, tree depth {}, containment across boundaries: {} leaf visits, {} failing balls",
                rc.partitions.len(),
                rc.depth,
                rc.containment_checks,
                rc.containment_failures
            );
            for p in rc.partitions.iter().filter(|p| !p.ok) {
                println!(
                    "partition {} fails its certificate: {}",
                    p.partition,
                    serde_json::to_string(p).unwrap_or_default()
                );
            }
            println!("goal within T: {}", rc.liveness.describe());
            if let Some(mc) = monte_carlo {
                println!(
                    "runs {} from F ({} drawn starts not accepted), at most {} steps to Goal",
                    mc.runs, mc.rejected, mc.max_steps_to_goal
                );
                if img.terminal_law().is_some() {
                    println!(
                        "after Goal: {}",
                        super::after_goal_judged(
                            *run_steps,
                            mc.runs_leaving_goal,
                            mc.after_goal_unsafe,
                            mc.after_goal_input_excursions,
                            mc.not_handed_over,
                            mc.handed_over
                        )
                    );
                }
                for v in &mc.first_violations {
                    println!(
                        "violation from x0 = {:?}: {}",
                        v.x0,
                        crate::verify::attack::describe(v)
                    );
                }
                println!("violations {}", mc.violations);
            }
            print_attack(attack.as_ref());
        }
        Report::Temporal {
            recheck: rc,
            monte_carlo,
            attack,
            written,
            in_xi,
        } => {
            let unproved = rc.iter().filter(|c| !c.ok).count();
            println!(
                "re-proved         {} of {} balls from the image bytes, for `{written}`{}",
                rc.len() - unproved,
                rc.len(),
                in_xi
                    .as_deref()
                    .map_or(String::new(), |xi| format!(" (in ξ: `{xi}`)"))
            );
            if let Some(r) = monte_carlo {
                println!(
                    "monte carlo       {} runs judged by the formula at the samples and sampled 8× finer ({} starts refused by the f32 selection, not run), {} violations",
                    r.runs, r.rejected, r.violations
                );
            }
            print_attack(attack.as_ref());
        }
        Report::Hybrid {
            recheck: rc,
            monte_carlo,
            attack,
        } => {
            let unproved = rc.iter().filter(|c| !c.ok).count();
            println!(
                "re-proved         {} of {} runs from the image bytes",
                rc.len() - unproved,
                rc.len()
            );
            if let Some(r) = monte_carlo {
                println!(
                    "monte carlo       {} runs ({} switched, at most {} events; {} starts refused by the f32 selection, not run), {} violations",
                    r.runs - r.rejected,
                    r.switched,
                    r.max_events,
                    r.rejected,
                    r.violations
                );
            }
            print_attack(attack.as_ref());
        }
    }
    if let Some(c) = &v.coverage {
        println!(
            "coverage of the spec's Init {:.5} (lower bound {:.5}, upper {:.5} at {} confidence, {} samples; target {}{})",
            c.estimate.mean,
            c.estimate.lower,
            c.estimate.upper,
            c.estimate.confidence,
            c.estimate.samples,
            c.target,
            if c.met { ", met" } else { ", NOT met" }
        );
    }
}

/// The terminal law's line (none, or re-proved with its figures; a refused one is the failure).
fn print_terminal(
    terminal: Option<&crate::certify::terminal::TerminalCertificate>,
    img: &shared_types::image::Image<'_>,
) {
    match terminal {
        Some(c) => println!(
            "terminal law re-proved from the bytes: contraction {:.4}, next sample within {:.6} of the accepted {:.6}; Goal depth {:.4} ≥ {:.4}, Unsafe distance {:.4}, input distance {:.4} (ellipsoid metric)",
            c.contraction, c.theta, c.acceptance_floor, c.goal_depth, c.between_samples, c.unsafe_distance, c.input_distance
        ),
        None if img.terminal_law().is_none() => println!("terminal law: none in the image"),
        // Not re-proved: the failure says why.
        None => {}
    }
}

fn print_feedforward(
    rc: &crate::verify::feedforward::FeedforwardRecheck,
    r: Option<&crate::verify::VerifyReport>,
    has_unsafe: bool,
    attack: Option<&AttackReport>,
) {
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
    if let Some(r) = r {
        println!(
            "runs {} interior + {} boundary ({} refused by the evaluator although its certificate covers them{})",
            r.interior_runs,
            r.boundary_runs,
            r.refused,
            if r.boundary_outside > 0 {
                format!(
                    "; {} boundary points outside the image's selection on the spec's maps, not run",
                    r.boundary_outside
                )
            } else {
                String::new()
            }
        );
        println!(
            "worst margins: goal depth {}, unsafe distance {}, input slack {}",
            margin(r.worst_goal_margin),
            if has_unsafe {
                margin(r.worst_unsafe_margin)
            } else {
                "none (no Unsafe set)".to_string()
            },
            margin(r.worst_input_margin)
        );
        for v in &r.first_violations {
            println!(
                "violation from x0 = {:?}: {}",
                v.x0,
                crate::verify::attack::describe(v)
            );
        }
        print_after_goal(r);
        println!("violations {}", r.violations);
    }
    print_attack(attack);
}

/// What the runs did after Goal: under a terminal law this is judged (its violations are counted);
/// without one it is reported only.
fn print_after_goal(r: &crate::verify::VerifyReport) {
    let line = if r.after_goal_judged {
        super::after_goal_judged(
            r.run_steps,
            r.runs_leaving_goal,
            r.after_goal_unsafe,
            r.after_goal_input_excursions,
            r.not_handed_over,
            r.handed_over,
        )
    } else {
        super::after_goal_unjudged(
            r.run_steps,
            r.runs_leaving_goal,
            r.after_goal_unsafe,
            r.after_goal_input_excursions,
        )
    };
    println!("after Goal: {line}");
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

/// A worst margin for people: its value, or that no run recorded one (never `inf` as if it were a
/// result).
fn margin(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4e}")
    } else {
        "none recorded (no run reached this check)".to_string()
    }
}
