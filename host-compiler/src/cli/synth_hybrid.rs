//! `synth` for a hybrid plant (`[[plant.location]]` in the spec): runs across internal edges, certified by
//! `certify::internal`, grown over Init ([`crate::synth::hybrid::synthesize_hybrid`]), verified by Monte
//! Carlo against the exact hybrid flow through the shared evaluator. Writes `controller.img` (only when
//! the verification passed), `certificate.json` and `report.html` ([`crate::report::hybrid`]); exit
//! status as for `synth` ([`super::Exit`]).
//!
//! `--import FILE|DIR` takes recordings (`host-compiler play` writes them): each is replayed on the
//! automaton, split at its events into the path's segments and certified by the same certificate
//! ([`crate::synth::hybrid::import`]); an accepted one joins the runs before the growth, a refused one
//! is named on stderr with its reason (the segment, what binds, by how much) and in `certificate.json`'s
//! `imported`. A file that does not read is bad input, as for `synth`.

use super::synth::write_atomic;
use super::{BadInput, Exit, Failure, Outcome, SynthArgs};
use crate::synth::hybrid::{synthesize_hybrid, HybridOptions, HybridTask};
use crate::synth::Generator;
use miette::IntoDiagnostic;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

pub fn run(a: &SynthArgs, problem: crate::spec::Problem) -> Outcome {
    let imports = super::synth::load_imports(a, &problem)?;
    let task = HybridTask::new(problem)
        .map_err(|e| miette::miette!("{e}"))
        .bad_input()?;
    if a.guard_routes && task.forced {
        return Err(Failure::bad_input(miette::miette!(
            "--guard-routes: {} switches by the controller's choice (forced switching), and its \
             planner already tries every switching schedule; routes through guards are for internal \
             switching",
            a.spec.display()
        )));
    }
    let generator = a.generator.unwrap_or(Generator::Scp);
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        if let Err(e) = ctrlc::set_handler(move || {
            if cancel.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!(
                "\ninterrupt: finishing with the runs certified so far (Ctrl-C again to abort)"
            );
        }) {
            eprintln!("warning: Ctrl-C handler not installed: {e}");
        }
    }
    if !a.quiet {
        eprintln!(
            "hybrid plant: {} locations, {} edges; runs go {}",
            task.plant.modes().len(),
            task.plant.edges().len(),
            task.route()
        );
    }
    let quiet = a.quiet;
    let opts = HybridOptions {
        verify_interior: (a.verify_runs as usize).min(100_000),
        cancel: cancel.clone(),
        on_accept: (!quiet).then(|| {
            Arc::new(|count: usize, delta: f64| eprintln!("certified run {count} (δ = {delta:.4})"))
                as Arc<dyn Fn(usize, f64) + Send + Sync>
        }),
        on_progress: (!quiet).then(super::stage_lines),
        imports,
        generator,
        routes: a.guard_routes,
        ..HybridOptions::default()
    };
    let s = synthesize_hybrid(&task, &opts).map_err(|e| Failure {
        exit: Exit::Failed,
        report: miette::miette!("{e}"),
    })?;
    for (name, r) in &s.imported {
        match r {
            Ok(d) => eprintln!("{name}: imported, δ = {d:.4}"),
            Err(why) => eprintln!("warning: {name}: not used: {why}"),
        }
    }
    let img_path = a.out.join("controller.img");
    let unproved: Vec<&str> = s.recheck.iter().filter_map(|r| r.why.as_deref()).collect();
    let verified = s.verify.violations == 0 && unproved.is_empty();
    let image = super::monitored(a, &s.image)?;
    if verified {
        write_atomic(&img_path, &image)?;
    }
    let cert = serde_json::json!({
        "task": "hybrid",
        "image": super::image_identity(&img_path, &image),
        "spec": a.spec.display().to_string(),
        "seed": task.problem.seed,
        "plant": "hybrid",
        "switching": if task.forced { "forced" } else { "internal" },
        "generator": generator.to_string(),
        "formula": task.problem.mtl,
        "path": task.path.iter().map(|&l| &task.plant.modes()[l].name).collect::<Vec<_>>(),
        "edges": task.edges,
        "stop": s.stop,
        "coverage": s.coverage,
        "verify": s.verify,
        "recheck": s.recheck,
        "seeds_tried": s.seeds_tried,
        "imported": s.imported.iter().map(|(name, r)| match r {
            Ok(d) => serde_json::json!({"file": name, "delta": d}),
            Err(why) => serde_json::json!({"file": name, "why": why}),
        }).collect::<Vec<_>>(),
        "refused": s.refused.iter().map(|(x, why)| serde_json::json!({"seed": x, "why": why})).collect::<Vec<_>>(),
        "locations": task.designs.iter().map(|d| serde_json::json!({
            "K": crate::linalg::to_rows(d.K.as_ref()), "P": crate::linalg::to_rows(d.P.as_ref()),
        })).collect::<Vec<_>>(),
        "runs": s.runs.iter().zip(&s.sources).map(|(r, src)| serde_json::json!({
            "x0": r.nominals[0].x[0], "certificate": r.certificate, "source": src,
            "locations": r.locations.iter().map(|&l| &task.plant.modes()[l].name).collect::<Vec<_>>(),
            "nominal_segments": r.nominals.iter().map(|n| &n.x).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
        "seconds": s.seconds,
    });
    std::fs::write(
        a.out.join("certificate.json"),
        serde_json::to_string_pretty(&cert).into_diagnostic()?,
    )
    .into_diagnostic()?;
    let page = crate::report::hybrid::render(&task, &a.spec.display().to_string(), &s);
    std::fs::write(a.out.join("report.html"), page).into_diagnostic()?;
    let deltas: Vec<f64> = s.runs.iter().map(|r| r.delta()).collect();
    let (dmin, dmax) = deltas
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &d| (a.min(d), b.max(d)));
    println!(
        "runs              {} ({} seeds tried)",
        s.runs.len(),
        s.seeds_tried
    );
    println!("delta range       {dmin:.4} .. {dmax:.4} (CAF metric of the first location)");
    println!(
        "coverage          {:.5} (lower bound {:.5}, upper {:.5} at {} confidence, {} samples)",
        s.coverage.mean,
        s.coverage.lower,
        s.coverage.upper,
        s.coverage.confidence,
        s.coverage.samples
    );
    println!("stop              {}", s.stop);
    print_refusals(&s.refused);
    println!(
        "verification      {} runs ({} switched, at most {} events; {} boundary starts refused by the f32 selection, not run), {} violations",
        s.verify.runs - s.verify.rejected,
        s.verify.switched,
        s.verify.max_events,
        s.verify.rejected,
        s.verify.violations
    );
    println!(
        "re-proved         {} of {} runs from the image bytes",
        s.recheck.iter().filter(|r| r.ok).count(),
        s.recheck.len()
    );
    println!("time              {:.1} s", s.seconds);
    super::synth::refuse_unless_certified(
        &unproved,
        s.verify.violations,
        s.verify.first_violation.as_deref(),
    )?;
    println!("{}", super::synth::image_line(&img_path, image.len()));
    if let Some(w) = super::synth::flash_warning(image.len()) {
        eprintln!("warning: {w}");
    }
    super::synth::coverage_exit(
        cancel.load(Ordering::Relaxed),
        &s.coverage,
        task.problem.synthesis.coverage_target,
        &s.stop,
        "runs",
    )
}

/// The seeds that certified no run, by the kind of their reason, with where in Init they lie: the place a
/// new seed trajectory is needed when the growth stops short ([`crate::synth::refusals`]); the three
/// largest groups.
fn print_refusals(refused: &[(Vec<f64>, String)]) {
    let groups = crate::synth::refusals::groups(refused);
    if groups.is_empty() {
        return;
    }
    println!(
        "refused seeds     {} (by reason; certificate.json lists each)",
        refused.len()
    );
    for g in groups.iter().take(3) {
        let span: Vec<String> =
            g.lo.iter()
                .zip(&g.hi)
                .map(|(l, h)| format!("[{l:.2}, {h:.2}]"))
                .collect();
        println!("  {:>5} × {}", g.count, g.reason);
        println!("          within {}", span.join(" × "));
    }
    if groups.len() > 3 {
        let rest: usize = groups[3..].iter().map(|g| g.count).sum();
        println!("  {rest:>5} × other reasons ({} kinds)", groups.len() - 3);
    }
}
