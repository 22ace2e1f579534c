//! `host-compiler synth SPEC --out DIR`: the whole pipeline, writing the image, the report and the
//! certificate data.

use super::SynthArgs;
use crate::report::report_data;
use crate::synth::{synthesize, StopReason, SynthOptions};
use crate::task::Task;
use miette::{IntoDiagnostic, WrapErr};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

pub fn run(a: &SynthArgs) -> miette::Result<()> {
    let problem = crate::spec::load(&a.spec)?;
    let (n, m, h) = (problem.plant.n(), problem.plant.m(), problem.plant.period);
    let mut imports = Vec::new();
    for p in &a.imports {
        let rec = crate::trajectory::csv::load_recording(p, n, m, h)
            .map_err(|e| miette::miette!("{e}"))?;
        imports.push((p.display().to_string(), rec));
    }
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
    let opts = SynthOptions {
        verify_interior: a.verify_runs,
        progress: !a.quiet,
        imports,
        generator: a.generator,
        cancel,
        on_accept: log.then(|| {
            crate::synth::AcceptHook(Arc::new(|count| eprintln!("certified trajectory {count}")))
        }),
        ..SynthOptions::default()
    };
    let task = Task::new(problem).map_err(|e| miette::miette!("{e}"))?;
    let problem = &task.problem;
    let s = synthesize(&task, &opts).map_err(|e| miette::miette!("{e}"))?;
    std::fs::create_dir_all(&a.out)
        .into_diagnostic()
        .wrap_err_with(|| format!("creating {}", a.out.display()))?;
    if problem.synthesis.mode == crate::spec::ControllerMode::Pwa {
        return crate::cli::synth_pwa::run(a, &task, &s);
    }
    let img_path = a.out.join("controller.img");
    std::fs::write(&img_path, &s.image)
        .into_diagnostic()
        .wrap_err("writing the image")?;
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
        })).collect::<Vec<_>>(),
        "timings": s.timings,
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
        "coverage          {:.5} (lower bound {:.5}, upper {:.5} at {:.0}% confidence, {} samples)",
        s.coverage.mean,
        s.coverage.lower,
        s.coverage.upper,
        100.0 * s.coverage.confidence,
        s.coverage.samples
    );
    println!("stop              {}", s.stop);
    if let Some(g) = median_gain(&s) {
        println!(
            "optimisation      {} runs (§5.3), median δ gain {g:.3}",
            s.optimization.len()
        );
    }
    println!(
        "verification      {} runs ({} interior, {} boundary), {} violations",
        s.verify.interior_runs + s.verify.boundary_runs - s.verify.boundary_rejected,
        s.verify.interior_runs,
        s.verify.boundary_runs - s.verify.boundary_rejected,
        s.verify.violations
    );
    if s.verify.after_goal_input_excursions + s.verify.after_goal_unsafe > 0 {
        println!(
            "after Goal        {} runs left the input set, {} entered Unsafe under the terminal law (not judged: the task ends in Goal)",
            s.verify.after_goal_input_excursions, s.verify.after_goal_unsafe
        );
    }
    println!(
        "image             {} ({} bytes)",
        img_path.display(),
        s.image.len()
    );
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
    if s.verify.violations > 0 {
        return Err(miette::miette!(
            "verification found {} violations",
            s.verify.violations
        ));
    }
    if let StopReason::Interrupted { trajectories } = s.stop {
        return Err(miette::miette!(
            "interrupted: {} holds the {trajectories} trajectories certified so far (verified, {} violations); \
             the run did not finish",
            img_path.display(),
            s.verify.violations
        ));
    }
    Ok(())
}

/// Median of δ after ÷ δ before over the Algorithm 4 seeds (those started on a ball's boundary).
fn median_gain(s: &crate::synth::Synthesis) -> Option<f64> {
    let mut g: Vec<f64> = s
        .optimization
        .iter()
        .filter(|r| r.origin.is_some())
        .map(|r| r.gain())
        .collect();
    if g.is_empty() {
        return None;
    }
    g.sort_by(|a, b| a.total_cmp(b));
    Some(g[g.len() / 2])
}
