//! `synth` for a spec with `mode = "pwa"`: learns the piecewise-affine feedback (Ch. 6) from the certified
//! feedforward cover, re-checks the emitted image independently ([`crate::verify::pwa`]) and writes
//! `controller.img` (the PWA image), `feedforward.img` (the cover it was learned from, the size baseline),
//! `report.html` with its PWA section and `certificate.json`.

use super::synth::{short_of_target, write_atomic};
use super::{Exit, Outcome, SynthArgs};
use crate::pwa::{learn_pwa, PwaSettings};
use crate::report::pwa::PwaSummary;
use crate::report::report_data;
use crate::synth::Synthesis;
use crate::task::Task;
use crate::verify::pwa::{monte_carlo_pwa, recheck};
use crate::verify::Judge;
use miette::{IntoDiagnostic, WrapErr};

/// Learns, checks and writes the PWA controller (module doc). Fails when any check fails.
pub fn run(a: &SynthArgs, task: &Task, s: &Synthesis) -> Outcome {
    let problem = &task.problem;
    let settings = PwaSettings::builder()
        .progress(!a.quiet)
        .build()
        .into_diagnostic()?;
    let pwa = learn_pwa(task, s, &settings).map_err(|e| miette::miette!("PWA learning: {e}"))?;
    let img = shared_types::image::decode(&pwa.image)
        .map_err(|e| miette::miette!("the emitted PWA image is rejected: {e}"))?;
    let judge = Judge::new(task);
    let rc = recheck(&judge, &img).map_err(|e| miette::miette!(e))?;
    let init_centres = s.init_centres();
    let mc = monte_carlo_pwa(
        &judge,
        &img,
        &init_centres,
        a.verify_runs as usize,
        problem.seed ^ 0x7e51f1,
        64,
    )
    .into_diagnostic()?;
    let summary = PwaSummary {
        data_points: pwa.ctx.points.len(),
        trajectories: init_centres.len(),
        eps_fit: pwa.ctx.eps_fit,
        stats: pwa.stats.clone(),
        learn_seconds: pwa.learn_seconds,
        partition_seconds: pwa.partition_seconds,
        image_bytes: pwa.image.len(),
        feedforward_image_bytes: s.image.len(),
        recheck: rc,
        monte_carlo: mc,
        coverage: crate::pwa::coverage(&img, problem),
    };
    let img_path = a.out.join("controller.img");
    // Only a certified image is written (`synth` module doc); the report says why one is not.
    let certified = summary.recheck.failures == 0
        && summary.monte_carlo.violations == 0
        && summary.stats.dropped == 0;
    let image = super::monitored(a, &pwa.image)?;
    if certified {
        write_atomic(&img_path, &image)?;
    }
    if s.verify.violations == 0 {
        write_atomic(&a.out.join("feedforward.img"), &s.image)?;
    }
    let mut data = report_data(
        problem,
        &a.spec.display().to_string(),
        s,
        &img_path.display().to_string(),
    );
    data.image_bytes = image.len();
    data.pwa = Some(crate::report::pwa::pwa_report(&pwa, &img, &summary));
    let report = crate::report::write_report(&data, &a.out)
        .into_diagnostic()
        .wrap_err("writing the report")?;
    let cert = serde_json::json!({
        "task": "pwa",
        "image": super::image_identity(&img_path, &image),
        "spec": a.spec.display().to_string(),
        "seed": problem.seed,
        "mode": "pwa",
        "sigma_min": s.constants.sigma_min,
        "K": crate::linalg::to_rows(s.K.as_ref()),
        "P": crate::linalg::to_rows(s.P.as_ref()),
        "coverage": s.coverage,
        "feedforward_verify": s.verify,
        "pwa": summary,
        "trajectories": s.trajectories.iter().map(|t| serde_json::json!({
            "source": t.source, "x0": t.nominal.x[0], "certificate": t.certificate,
            "nominal": t.nominal.x,
        })).collect::<Vec<_>>(),
        "balls": ball_provenance(&pwa, &img),
        "timings": s.timings,
    });
    std::fs::write(
        a.out.join("certificate.json"),
        serde_json::to_string_pretty(&cert).into_diagnostic()?,
    )
    .into_diagnostic()?;
    let st = &summary.stats;
    println!(
        "cover             {} trajectories, {} data points, coverage of Init {:.5} (lower bound {:.5})",
        summary.trajectories, summary.data_points, s.coverage.mean, s.coverage.lower
    );
    println!(
        "PWA coverage      of Init by the image's envelope {:.5} (lower bound {:.5} at {} confidence, {} samples)",
        summary.coverage.mean,
        summary.coverage.lower,
        summary.coverage.confidence,
        summary.coverage.samples
    );
    println!(
        "partitions        {} (ratio to the dissertation's 110: {:.3})",
        st.partitions,
        st.partitions as f64 / 110.0
    );
    println!(
        "tree              {} nodes, {} leaves, worst-case depth {} hyperplane tests, at most {} balls per leaf, {} balls, {} references, {} dropped",
        st.nodes, st.leaves, st.depth, st.max_leaf_balls, st.balls, st.ball_refs, st.dropped
    );
    println!(
        "learning          {:.3} s (partition {:.3} s), eps_fit {:.3e}",
        summary.learn_seconds, summary.partition_seconds, summary.eps_fit
    );
    println!(
        "image             {} ({} bytes; feedforward image of the same cover {} bytes)",
        img_path.display(),
        summary.image_bytes,
        summary.feedforward_image_bytes
    );
    if let Some(w) = super::synth::flash_warning(summary.image_bytes) {
        eprintln!("warning: {w}");
    }
    let bad_parts = summary.recheck.partitions.iter().filter(|p| !p.ok).count();
    println!(
        "recheck           {} partitions, {} failing; containment across boundaries {} leaf visits, {} failing balls",
        summary.recheck.partitions.len(),
        bad_parts,
        summary.recheck.containment_checks,
        summary.recheck.containment_failures
    );
    println!("goal within T      {}", summary.recheck.liveness.describe());
    let mc = &summary.monte_carlo;
    println!(
        "verification      {} runs from F ({} from the balls over Init), {} starts not accepted, {} violations, at most {} steps to Goal",
        mc.runs, mc.init_runs, mc.rejected, mc.violations, mc.max_steps_to_goal
    );
    for v in &mc.first_violations {
        println!(
            "violation from x0 = {:?}: {}",
            v.x0,
            crate::verify::attack::describe(v)
        );
    }
    match &s.terminal {
        crate::synth::TerminalOutcome::Certified(_) => println!(
            "terminal law      in the PWA image too; after Goal, {}",
            super::after_goal_judged(
                mc.max_steps,
                mc.runs_leaving_goal,
                mc.after_goal_unsafe,
                mc.after_goal_input_excursions,
                mc.not_handed_over,
                mc.handed_over
            )
        ),
        crate::synth::TerminalOutcome::None(e) => println!("terminal law      none: {e}"),
        crate::synth::TerminalOutcome::NotAsked => {
            println!("terminal law      none (the spec's [synthesis] terminal)")
        }
    }
    println!("{}", crate::report::after_goal_line(&img));
    println!("report            {}", report.display());
    if !certified {
        return Err(miette::miette!(
            "the PWA image is NOT certified and was not written: {} recheck failures, {} violations, \
             {} dropped balls",
            summary.recheck.failures,
            mc.violations,
            st.dropped
        )
        .into());
    }
    if (mc.runs as u64) < a.verify_runs {
        return Err(miette::miette!(
            "only {} of {} initial states could be drawn in F",
            mc.runs,
            a.verify_runs
        )
        .into());
    }
    if let crate::synth::StopReason::Interrupted { trajectories } = s.stop {
        return Err(super::Failure {
            exit: Exit::Interrupted,
            report: miette::miette!(
                "interrupted: the PWA law was learned from the {trajectories} trajectories certified so far; \
                 the run did not finish"
            ),
        });
    }
    let target = problem.synthesis.coverage_target;
    if s.stop == crate::synth::StopReason::Covered && summary.coverage.lower < target {
        // The cover met the target but the PWA image's envelope (its balls' f32 tests) does not prove it.
        eprintln!(
            "coverage target NOT met by the PWA image: its envelope covers Init at least {:.5} at {} \
             confidence, short of the target {target}; the image is certified for its envelope only \
             (exit status 3)",
            summary.coverage.lower, summary.coverage.confidence
        );
        return Ok(Exit::ShortOfTarget);
    }
    Ok(short_of_target(s, target))
}

/// Each ball of the PWA image with its provenance, for independent checkers (`inspect --json`): the data
/// point whose ball it stores (trajectory i and step κ of the cover, found by its f32 centre) and its
/// successor: the image's ball of (i, κ + 1), or `"goal"` when κ + 1 = κ*_i (that ball lies in Goal,
/// where the run ends), or `null` when the successor's ball is not in the image. A ball no data point
/// has (none, by construction) has `null` provenance.
fn ball_provenance(
    pwa: &crate::pwa::PwaController,
    img: &shared_types::image::Image<'_>,
) -> Vec<serde_json::Value> {
    use std::collections::HashMap;
    let n = img.n();
    let key = |x: &mut dyn Iterator<Item = f32>| -> Vec<u32> { x.map(f32::to_bits).collect() };
    let by_centre: HashMap<Vec<u32>, usize> = pwa
        .ctx
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| (key(&mut p.x.iter().map(|&v| v as f32)), i))
        .collect();
    let point_of: Vec<Option<usize>> = (0..img.n_balls())
        .map(|b| {
            by_centre
                .get(&key(&mut (0..n).map(|i| img.ball_centre(b, i))))
                .copied()
        })
        .collect();
    let ball_of: HashMap<(usize, usize), usize> = point_of
        .iter()
        .enumerate()
        .filter_map(|(b, p)| p.map(|i| ((pwa.ctx.points[i].traj, pwa.ctx.points[i].kappa), b)))
        .collect();
    point_of
        .iter()
        .enumerate()
        .map(|(b, p)| match p {
            None => serde_json::json!({ "ball": b, "trajectory": null, "kappa": null, "successor": null }),
            Some(i) => {
                let d = &pwa.ctx.points[*i];
                let successor = if d.to_go <= 1 {
                    serde_json::json!("goal")
                } else {
                    serde_json::json!(ball_of.get(&(d.traj, d.kappa + 1)))
                };
                serde_json::json!({
                    "ball": b,
                    "trajectory": d.traj,
                    "kappa": d.kappa,
                    "to_go": d.to_go,
                    "successor": successor,
                })
            }
        })
        .collect()
}
