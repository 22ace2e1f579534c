//! `host-compiler synth SPEC --out DIR`: the whole pipeline, writing the image, the report and the
//! certificate data.
//!
//! # What is in `--out` afterwards
//! The directory is created (and shown writable) before any work, and the files this command writes are
//! removed from it first, so no file there can be mistaken for this run's result. The image is written
//! to a temporary file in the same directory and renamed into place only once it is verified: a run that
//! fails leaves no `controller.img` at all, and one that is killed leaves at most a temporary file.
//!
//! # Exit status ([`super::Exit`])
//! 0 when Init is covered to the target at the requested confidence and the verification found no
//! violation; 3 when the image is certified and verified but its cover is short of the target; 1 when
//! the verification found violations or nothing could be certified; 2 for bad input; 130 when
//! interrupted.

use super::{task_of, BadInput, Exit, Failure, Outcome, SynthArgs};
use crate::report::format::{self as fmt, Round};
use crate::report::report_data;
use crate::synth::{synthesize, StopReason, SynthError, SynthOptions};
use miette::{IntoDiagnostic, WrapErr};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The files `synth` writes into `--out` (removed at the start of every run).
const OUTPUTS: &[&str] = &[
    "controller.img",
    "feedforward.img",
    "certificate.json",
    "report.html",
];

/// Refuses a run whose image the bytes do not re-prove (`unproved`: why, per refused trajectory) or the
/// Monte Carlo refuted; such an image is not written.
pub(crate) fn refuse_unless_certified(
    unproved: &[impl AsRef<str>],
    violations: usize,
    first_violation: Option<&str>,
) -> Result<(), Failure> {
    if let Some(first) = unproved.first() {
        let first = first.as_ref();
        return Err(miette::miette!(
            "the image bytes do not re-prove {} of its trajectories (first: {first}): the image is NOT \
             certified and was not written",
            unproved.len()
        )
        .into());
    }
    if violations > 0 {
        return Err(miette::miette!(
            "verification found {violations} violations (first: {}): the image is NOT certified and was \
             not written",
            first_violation.unwrap_or("?")
        )
        .into());
    }
    Ok(())
}

/// The exit of a run whose image was written: interrupted (130), the coverage target met (0), or short of
/// it (3, said on stderr with the lower bound and why the growth stopped). `what` names the certified
/// units ("runs", "balls").
pub(crate) fn coverage_exit(
    interrupted: bool,
    coverage: &crate::cover::CoverageEstimate,
    target: f64,
    stop: &str,
    what: &str,
) -> Outcome {
    if interrupted {
        return Err(Failure {
            exit: Exit::Interrupted,
            report: miette::miette!("interrupted: the image holds the {what} certified so far"),
        });
    }
    if coverage.lower >= target {
        Ok(Exit::Success)
    } else {
        eprintln!(
            "coverage target NOT met: the coverage of Init is at least {:.5} at {} confidence, short of the \
             target {target} ({stop}); the image is certified for its cover only (exit status 3)",
            coverage.lower, coverage.confidence
        );
        Ok(Exit::ShortOfTarget)
    }
}

/// The recordings `--import` names (a file, or a directory's `*.csv` in sorted order: `host-compiler
/// play` writes its runs there), each at most the horizon long (which `spec::limits` keeps within the
/// table capacity); a file that does not read is bad input. A recording gives the references, the
/// applied inputs or the states alone (`trajectory::csv`), for a feedback-linearizable or flat plant in
/// its linear model's coordinates ([`load_task_imports`]); a hybrid plant's must give the references.
pub(crate) fn load_imports(
    a: &SynthArgs,
    problem: &crate::spec::Problem,
) -> Result<Vec<(String, crate::trajectory::csv::Recording)>, Failure> {
    load_imports_in(a, problem, crate::trajectory::csv::Coordinates::Plant)
}

/// [`load_imports`] for a one-location task: states and inputs in the coordinates of the model its
/// nominals live in (ξ and w for a feedback-linearizable or flat plant, whose `task.problem` is already
/// the model in ξ).
pub(crate) fn load_task_imports(
    a: &SynthArgs,
    task: &crate::task::Task,
) -> Result<Vec<(String, crate::trajectory::csv::Recording)>, Failure> {
    use crate::trajectory::csv::Coordinates;
    let coords = if task.plant.linearization().is_some() {
        Coordinates::Linearized
    } else {
        Coordinates::Plant
    };
    load_imports_in(a, &task.problem, coords)
}

fn load_imports_in(
    a: &SynthArgs,
    problem: &crate::spec::Problem,
    coords: crate::trajectory::csv::Coordinates,
) -> Result<Vec<(String, crate::trajectory::csv::Recording)>, Failure> {
    use crate::trajectory::csv::Given;
    let (n, m, h) = (problem.plant.n(), problem.plant.m(), problem.plant.period);
    let max_rows = problem.horizon_steps();
    let mut imports = Vec::new();
    for dir in &a.imports {
        let files = crate::trajectory::csv::recordings_in(dir)
            .map_err(|e| miette::miette!("{e}"))
            .bad_input()?;
        if files.is_empty() {
            return Err(Failure::bad_input(miette::miette!(
                "--import {}: the directory holds no .csv recording",
                dir.display()
            )));
        }
        for p in files {
            let rec = crate::trajectory::csv::load_import(&p, n, m, h, max_rows, coords)
                .map_err(|e| miette::miette!("{e}"))
                .bad_input()?;
            if problem.hybrid.is_some() && rec.given != Given::References {
                let what = match rec.given {
                    Given::Applied(_) => "applied inputs `u1…um`",
                    _ => "states alone",
                };
                return Err(Failure::bad_input(miette::miette!(
                    "{}: the recording gives {what}, not the references `v1…vm`: a hybrid plant's \
                     recordings must give the references v = u − K̂x of each sample's location (as `play` \
                     and `simulate` write them); deriving them from applied inputs or states is built for \
                     one-location plants only",
                    p.display()
                )));
            }
            imports.push((p.display().to_string(), rec));
        }
    }
    Ok(imports)
}

pub fn run(a: &SynthArgs) -> Outcome {
    // First of all, even before the spec is read: whatever happens next, no earlier result is left.
    prepare_out(&a.out)?;
    let problem = crate::spec::load(&a.spec).bad_input()?;
    // A spec the monitor cannot read is refused before any synthesis.
    super::monitor_section(a, &problem)?;
    // A hybrid plant first: its task takes an [mtl] formula with forced switching (Def 4.18).
    if problem.hybrid.is_some() {
        return crate::cli::synth_hybrid::run(a, problem);
    }
    if a.guard_routes {
        return Err(Failure::bad_input(miette::miette!(
            "--guard-routes: {} has no hybrid automaton, so there is no guard to route through",
            a.spec.display()
        )));
    }
    if problem.mtl.is_some() {
        return crate::cli::synth_temporal::run(a, problem);
    }
    if problem.nonlinear.is_some() {
        let refuse = |what: &str| {
            Err(Failure::bad_input(miette::miette!(
                "{what} is not built for feedback-linearizable plants yet (the feedforward image of \
                 generated trajectories is)"
            )))
        };
        if problem.synthesis.mode == crate::spec::ControllerMode::Pwa {
            return refuse("[synthesis] mode = \"pwa\"");
        }
    }
    // A feedback-linearizable plant's task is the linear model in ξ; its recordings are in the task's
    // coordinates (x0 = ξ(0), rows the reference of w = K ξ + v), which `play` writes.
    let task = task_of(problem)?;
    let imports = load_task_imports(a, &task)?;
    // Ctrl-C: the first stops the growth loop cleanly (what is certified so far is verified, written
    // and reported); a second one ends the process at once.
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        let handler = ctrlc::set_handler(move || {
            if cancel.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!(
                "\ninterrupt: finishing with the trajectories certified so far (Ctrl-C again to abort)"
            );
        });
        if let Err(e) = handler {
            eprintln!("warning: Ctrl-C handler not installed: {e}");
        }
    }
    // Without a terminal the bars are hidden; log each certified trajectory instead.
    let log = !a.quiet && !std::io::IsTerminal::is_terminal(&std::io::stderr());
    // Read again after the search: a Ctrl-C after the growth returned still ends the run as interrupted.
    let interrupt = cancel.clone();
    let opts = SynthOptions {
        verify_interior: a.verify_runs as usize, // ≤ verify::MAX_RUNS (clap)
        progress: !a.quiet,
        imports,
        generator: a.generator.unwrap_or_default(),
        cancel,
        on_accept: log.then(|| {
            crate::synth::AcceptHook(Arc::new(|count| eprintln!("certified trajectory {count}")))
        }),
        // A line per stage after the cover, on a terminal too (the bars are cleared by then).
        on_stage: (!a.quiet).then(super::stage_lines),
        ..SynthOptions::default()
    };
    let problem = &task.problem;
    let s = synthesize(&task, &opts).map_err(synth_failure)?;
    if problem.synthesis.mode == crate::spec::ControllerMode::Pwa {
        let out = crate::cli::synth_pwa::run(a, &task, &s);
        return match late_interrupt(&s.stop, &interrupt) {
            Some(f) if out.is_ok() => Err(f),
            _ => out,
        };
    }
    let img_path = a.out.join("controller.img");
    // An image the verification refutes is not written (the report says why).
    let attack_violations = s.attack.as_ref().map_or(0, |a| a.violations);
    let certified = s.verify.violations == 0 && attack_violations == 0;
    let image = super::monitored(a, &s.image)?;
    if certified {
        write_atomic(&img_path, &image)?;
    }
    let data = report_data(
        problem,
        &a.spec.display().to_string(),
        &s,
        &img_path.display().to_string(),
    );
    let report = crate::report::write_report(&data, &a.out)
        .into_diagnostic()
        .wrap_err("writing the report")?;
    let cert = serde_json::json!({
        "task": "reach_avoid",
        "image": super::image_identity(&img_path, &image),
        "spec": a.spec.display().to_string(),
        "seed": problem.seed,
        "stop": s.stop.to_string(),
        "generator": s.generator.to_string(),
        "optimization": s.optimization,
        "coverage": s.coverage,
        "verify": s.verify,
        "sigma_min": s.constants.sigma_min,
        "K": crate::linalg::to_rows(s.K.as_ref()),
        "P": crate::linalg::to_rows(s.P.as_ref()),
        "continuous_caf_3_8": s.continuous_caf.as_ref().map(|(K, P)| serde_json::json!({
            "K": crate::linalg::to_rows(K.as_ref()), "P": crate::linalg::to_rows(P.as_ref()),
        })),
        "trajectories": s.trajectories.iter().map(|t| serde_json::json!({
            "source": t.source, "x0": t.nominal.x[0], "certificate": t.certificate,
            "nominal": t.nominal.x,
        })).collect::<Vec<_>>(),
        "timings": s.timings,
        "terminal": terminal_json(&s.terminal),
    });
    std::fs::write(
        a.out.join("certificate.json"),
        serde_json::to_string_pretty(&cert).into_diagnostic()?,
    )
    .into_diagnostic()?;
    let deltas: Vec<f64> = s
        .trajectories
        .iter()
        .map(|t| t.certificate.delta_stored as f64)
        .collect();
    let (dmin, dmax) = deltas
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &d| (a.min(d), b.max(d)));
    println!("trajectories      {}", s.trajectories.len());
    println!("delta range       {dmin:.4} .. {dmax:.4} (CAF metric)");
    println!(
        "coverage          {:.5} (lower bound {}, upper {} at {} confidence, {} samples)",
        s.coverage.mean,
        fmt::directed(s.coverage.lower, 5, Round::Down, 1.0),
        fmt::directed(s.coverage.upper, 5, Round::Up, 0.0),
        fmt::pct_down(s.coverage.confidence),
        s.coverage.samples
    );
    println!("stop              {}", s.stop);
    let seeds: Vec<(f64, f64)> = s
        .optimization
        .iter()
        .filter(|r| r.origin.is_some())
        .map(|r| (r.delta_before, r.delta_after))
        .collect();
    if let Some(line) = gain_summary(s.optimization.len(), &seeds) {
        println!("optimisation      {line}");
    }
    println!(
        "verification      {} runs ({} interior, {} boundary), {} violations",
        s.verify.interior_runs + s.verify.boundary_runs - s.verify.boundary_rejected,
        s.verify.interior_runs,
        s.verify.boundary_runs - s.verify.boundary_rejected,
        s.verify.violations
    );
    if let Some(at) = &s.attack {
        println!(
            "falsifier         {} runs, least run robustness {:.4e}, {} violations",
            at.evaluations, at.worst_robustness, at.violations
        );
    }
    print_terminal(&s.terminal, &s.verify, s.handover_radius, &s.image);
    if certified {
        println!("{}", image_line(&img_path, image.len()));
        if let Some(w) = flash_warning(image.len()) {
            eprintln!("warning: {w}");
        }
    } else {
        println!("image             not written: the verification refutes it");
    }
    println!("report            {}", report.display());
    for (k, v) in &s.timings {
        println!("time {k:<20} {v:.3} s");
    }
    println!(
        "time {:<20} {:.3} s",
        "total",
        s.timings.iter().map(|(_, v)| v).sum::<f64>()
    );
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    if s.verify.violations > 0 || attack_violations > 0 {
        return Err(miette::miette!(
            "verification found {} violations (Monte Carlo) and {attack_violations} (falsifier): the image \
             is NOT certified and was not written",
            s.verify.violations
        )
        .into());
    }
    if let StopReason::Interrupted { trajectories } = s.stop {
        return Err(Failure {
            exit: Exit::Interrupted,
            report: miette::miette!(
                "interrupted: {} holds the {trajectories} trajectories certified so far (verified, {} violations); \
                 the run did not finish",
                img_path.display(),
                s.verify.violations
            ),
        });
    }
    if let Some(f) = late_interrupt(&s.stop, &interrupt) {
        return Err(f);
    }
    Ok(short_of_target(&s, problem.synthesis.coverage_target))
}

/// A Ctrl-C that came after the growth returned (during verification or the report): the run is
/// reported as interrupted (exit 130) all the same, never as a success. `None` when there was none, or
/// when the growth itself stopped for it (that exit is reported above).
fn late_interrupt(stop: &StopReason, cancel: &AtomicBool) -> Option<Failure> {
    let late = cancel.load(Ordering::SeqCst) && !matches!(stop, StopReason::Interrupted { .. });
    late.then(|| Failure {
        exit: Exit::Interrupted,
        report: miette::miette!(
            "interrupted after the search had ended: the files written hold its whole result, but the \
             run did not finish"
        ),
    })
}

/// The terminal law for `certificate.json`: the stored values and the certificate, or why there is none.
pub(crate) fn terminal_json(t: &crate::synth::TerminalOutcome) -> serde_json::Value {
    use crate::synth::TerminalOutcome;
    match t {
        TerminalOutcome::Certified(d) => serde_json::json!({
            "law": "invariant",
            "x_e": d.stored.x_e,
            "u_e": d.u_e,
            "K": crate::linalg::to_rows(d.stored.K.as_ref()),
            "v": d.stored.v,
            "P": crate::linalg::to_rows(d.stored.P.as_ref()),
            "acceptance_radius": d.stored.radius,
            "contraction_target": d.rho,
            "certificate": d.certificate,
        }),
        TerminalOutcome::None(e) => serde_json::json!({ "law": "none", "why": e.to_string() }),
        TerminalOutcome::NotAsked => serde_json::json!({ "law": "none", "why": "not asked" }),
    }
}

/// The terminal law's lines of the summary: what was certified (or why nothing was), what the image
/// does after Goal ([`crate::report::after_goal_line`]) and what the Monte Carlo saw after Goal: with a
/// terminal law a judged result (each run counted is among the violations, `verify`'s module doc), else
/// counts that are not judged.
pub(crate) fn print_terminal(
    t: &crate::synth::TerminalOutcome,
    v: &crate::verify::VerifyReport,
    handover_radius: Option<f64>,
    image: &[u8],
) {
    use crate::synth::TerminalOutcome;
    match t {
        TerminalOutcome::Certified(d) => {
            let c = &d.certificate;
            println!(
                "terminal law      certified at x_e = {:?}, u_e = {:?}: invariant ellipsoid (contraction {:.4}, next sample within {:.4} of the accepted {:.4}), Goal depth {:.4} ≥ {:.4} between samples",
                d.stored.x_e, d.u_e, c.contraction, c.theta, c.acceptance_floor, c.goal_depth, c.between_samples
            );
            if let Some(rho) = handover_radius {
                println!(
                    "handover          the cover's runs are certified to reach the handover region (radius {rho:.6} in the law's metric, accepted by the f32 test) within the horizon"
                );
            }
        }
        TerminalOutcome::None(e) => println!("terminal law      none: {e}"),
        TerminalOutcome::NotAsked => {
            println!("terminal law      none (the spec's [synthesis] terminal)")
        }
    }
    if let Ok(img) = shared_types::image::decode(image) {
        println!("{}", crate::report::after_goal_line(&img));
    }
    if v.after_goal_judged {
        println!(
            "after Goal        {}",
            super::after_goal_judged(
                v.run_steps,
                v.runs_leaving_goal,
                v.after_goal_unsafe,
                v.after_goal_input_excursions,
                v.not_handed_over,
                v.handed_over
            )
        );
    } else {
        println!(
            "after Goal        {}",
            super::after_goal_unjudged(
                v.run_steps,
                v.runs_leaving_goal,
                v.after_goal_unsafe,
                v.after_goal_input_excursions
            )
        );
    }
}

/// [`Exit::Success`] when the cover met the coverage target, else [`Exit::ShortOfTarget`] with a line on
/// standard error saying by how much and why the growth stopped.
pub(crate) fn short_of_target(s: &crate::synth::Synthesis, target: f64) -> Exit {
    if s.stop == StopReason::Covered {
        return Exit::Success;
    }
    eprintln!(
        "coverage target NOT met: the coverage of Init is at least {} at {} confidence, short of the \
         target {target} ({}); the image is certified for its cover only (exit status 3)",
        fmt::directed(s.coverage.lower, 5, Round::Down, 1.0),
        fmt::pct_down(s.coverage.confidence),
        s.stop
    );
    Exit::ShortOfTarget
}

/// Creates `--out`, shows it writable, and removes the files this command writes (module doc), before
/// any work: a directory that cannot hold the result is bad input.
fn prepare_out(out: &Path) -> Result<(), Failure> {
    std::fs::create_dir_all(out)
        .into_diagnostic()
        .wrap_err_with(|| format!("cannot create the output directory {}", out.display()))
        .bad_input()?;
    let probe = out.join(format!(".host-compiler-probe-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .into_diagnostic()
        .wrap_err_with(|| format!("the output directory {} is not writable", out.display()))
        .bad_input()?;
    let _ = std::fs::remove_file(&probe);
    for f in OUTPUTS {
        let p = out.join(f);
        match std::fs::remove_file(&p) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(Failure::bad_input(miette::miette!(
                    "cannot remove the previous {}: {e}",
                    p.display()
                )))
            }
            _ => {}
        }
    }
    Ok(())
}

/// Writes `bytes` to a temporary file beside `path` and renames it into place: `path` is either absent
/// or complete.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), Failure> {
    let name = path
        .file_name()
        .map_or_else(|| "image".to_string(), |n| n.to_string_lossy().into_owned());
    let tmp = path.with_file_name(format!(".{name}.tmp-{}", std::process::id()));
    let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(miette::miette!("cannot write {}: {e}", path.display()).into());
    }
    Ok(())
}

/// A synthesis that ended without an image: bad input when the spec is the cause (a plant no feedback
/// stabilises, a recording that does not fit, an image beyond the capacities), else a failure.
fn synth_failure(e: SynthError) -> Failure {
    use crate::caf::{CafOutcome, DesignError};
    use crate::cover::GrowError;
    let exit = match &e {
        SynthError::Caf(DesignError::Input(_)) => Exit::BadInput,
        SynthError::Caf(DesignError::Outcome(o))
            if matches!(
                **o,
                CafOutcome::NotStabilizable { .. } | CafOutcome::MarginUnachievable { .. }
            ) =>
        {
            Exit::BadInput
        }
        SynthError::Cover(
            GrowError::Recording { .. } | GrowError::Emit(_) | GrowError::Ceiling { .. },
        ) => Exit::BadInput,
        SynthError::Cover(GrowError::InterruptedEmpty) => Exit::Interrupted,
        SynthError::Terminal(_) | SynthError::NoRoute { .. } => Exit::BadInput,
        _ => Exit::Failed,
    };
    Failure {
        exit,
        report: miette::miette!("{e}"),
    }
}

/// What §5.3 did over `runs` optimisations to the Algorithm 4 seeds (those started on a ball's boundary),
/// given as (δ before, δ after): the median of δ after ÷ δ before over the seeds that started certified,
/// and how many started uncertified (δ 0), whose gain has no finite ratio; `None` without such seeds.
fn gain_summary(runs: usize, seeds: &[(f64, f64)]) -> Option<String> {
    if seeds.is_empty() {
        return None;
    }
    let mut g: Vec<f64> = seeds
        .iter()
        .filter(|(before, _)| *before > 0.0)
        .map(|(before, after)| after / before)
        .collect();
    g.sort_by(|a, b| a.total_cmp(b));
    let repaired = seeds.len() - g.len();
    let repaired = match repaired {
        0 => String::new(),
        k => format!(
            "; {k} started uncertified (δ 0) and were repaired, a gain without a finite ratio"
        ),
    };
    Some(match g.get(g.len() / 2) {
        Some(median) if g.len() == seeds.len() => {
            format!("{runs} runs (§5.3), median δ gain {median:.3}")
        }
        Some(median) => format!(
            "{runs} runs (§5.3), median δ gain {median:.3} over the {} seeds that started certified{repaired}",
            g.len()
        ),
        None => format!("{runs} runs (§5.3){repaired}"),
    })
}

/// The summary line of a written image: its path and size against the boards' flash budget
/// (`shared_types::budgets`, the firmware and the image together).
pub(super) fn image_line(path: &std::path::Path, bytes: usize) -> String {
    format!(
        "image             {} ({bytes} bytes; the boards' flash budget for firmware and image together is {} bytes)",
        path.display(),
        shared_types::budgets::FLASH_BYTES
    )
}

/// A warning when an image alone is larger than the boards' flash budget: with its firmware it fits no
/// board as the budgets stand (`cargo xtask budgets` checks the linked firmware).
pub(super) fn flash_warning(bytes: usize) -> Option<String> {
    let budget = shared_types::budgets::FLASH_BYTES;
    (bytes as u64 > budget).then(|| {
        format!(
            "the image is {bytes} bytes, more than the flash budget every board must meet with its \
             firmware ({budget} bytes, shared_types::budgets): it fits no board as shipped; a smaller \
             max_trajectories or a shorter horizon shrinks it"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_image_larger_than_the_flash_budget_is_warned_of_and_one_within_it_is_not() {
        let budget = shared_types::budgets::FLASH_BYTES as usize;
        assert!(flash_warning(budget).is_none());
        let w = flash_warning(1_026_635).expect("over the budget");
        assert!(
            w.contains("1026635 bytes") && w.contains(&budget.to_string()),
            "{w}"
        );
        assert!(image_line(std::path::Path::new("c.img"), 10).contains(&budget.to_string()));
    }

    #[test]
    fn the_gain_summary_is_finite_and_counts_the_seeds_that_started_uncertified() {
        let line = gain_summary(4, &[(0.1, 0.2), (0.0, 0.3), (0.2, 0.3)]).expect("seeds");
        assert!(!line.contains("inf"), "{line}");
        assert!(
            line.contains("median δ gain 2.000 over the 2 seeds"),
            "{line}"
        );
        assert!(line.contains("1 started uncertified"), "{line}");
        let line = gain_summary(1, &[(0.0, 0.3)]).unwrap();
        assert!(!line.contains("inf") && !line.contains("median"), "{line}");
        assert_eq!(
            gain_summary(2, &[(0.1, 0.2), (0.2, 0.3)]).unwrap(),
            "2 runs (§5.3), median δ gain 2.000"
        );
        assert!(gain_summary(0, &[]).is_none());
    }

    #[test]
    fn a_ctrl_c_after_the_search_ended_exits_130_and_none_exits_as_before() {
        let pressed = AtomicBool::new(true);
        let f = late_interrupt(&StopReason::Covered, &pressed)
            .expect("a late Ctrl-C is an interruption");
        assert_eq!(f.exit.code(), 130);
        assert!(f.report.to_string().contains("interrupted"), "{}", f.report);
        assert!(late_interrupt(&StopReason::Covered, &AtomicBool::new(false)).is_none());
        // The growth's own interruption is reported where it was before.
        let stop = StopReason::Interrupted { trajectories: 3 };
        assert!(late_interrupt(&stop, &pressed).is_none());
    }
}
