//! `synth` for an MTL task (a spec with `[mtl] formula`, Problem 2.28) on a one-location plant: recorded
//! runs (`--import`, e.g. from `play`) certified first, then balls certified for the formula
//! (`certify::temporal`), grown over Init
//! ([`crate::synth::temporal::synthesize_temporal`]), re-proved from the image bytes and verified by
//! Monte Carlo against the formula as written. Writes `controller.img` (only when both passed),
//! `certificate.json` and `report.html` ([`crate::report::temporal`]); exit status as for `synth`
//! ([`super::Exit`]).

use super::synth::write_atomic;
use super::{task_of, BadInput, Exit, Failure, Outcome, SynthArgs};
use crate::property::TemporalTask;
use crate::synth::temporal::{synthesize_temporal, TemporalOptions};
use miette::IntoDiagnostic;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The task of an MTL spec, its formula over the task's coordinates and the formula as written.
pub(crate) struct TemporalSpec {
    /// The formula the task is judged by, over the task's coordinates.
    pub tt: TemporalTask,
    pub task: crate::task::Task,
    /// The formula as the user wrote it (over the plant's states), which the certificate and report
    /// state; for a feedback-linearizable plant `tt` is its rewriting into ξ.
    pub written: String,
}

impl TemporalSpec {
    /// The formula over the task's coordinates when it is not the one written (a feedback-linearizable
    /// plant's, in ξ).
    pub fn rewritten(&self) -> Option<&str> {
        let src = self.tt.written.source();
        (src != self.written).then_some(src)
    }
}

/// The task of an MTL spec and its formula over the task's coordinates. The formula is bound first on
/// the spec as written (so that its errors point into the text); a feedback-linearizable plant's task is
/// in ξ, and so is its formula (rewritten by `model::feedback_linearizable::formula_in_xi`).
pub(crate) fn temporal_task(problem: crate::spec::Problem) -> Result<TemporalSpec, Failure> {
    let tt = TemporalTask::from_problem(&problem)
        .map_err(miette::Report::new)
        .bad_input()?;
    let written = tt.written.source().to_string();
    let linearized = problem.nonlinear.is_some();
    let task = task_of(problem)?;
    let tt = if linearized {
        TemporalTask::from_problem(&task.problem)
            .map_err(miette::Report::new)
            .bad_input()?
    } else {
        tt
    };
    Ok(TemporalSpec { tt, task, written })
}

pub fn run(a: &SynthArgs, problem: crate::spec::Problem) -> Outcome {
    if problem.synthesis.mode == crate::spec::ControllerMode::Pwa {
        return Err(Failure::bad_input(miette::miette!(
            "mode = \"pwa\" is not built for MTL tasks: the PWA law is certified for reach-avoid; use \
             mode = \"feedforward\""
        )));
    }
    let ts = temporal_task(problem)?;
    let (tt, task) = (&ts.tt, &ts.task);
    // Recordings in the task's coordinates, each the whole horizon long (the formula is judged over T).
    let imports = super::synth::load_task_imports(a, task)?;
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        if let Err(e) = ctrlc::set_handler(move || {
            if cancel.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!(
                "\ninterrupt: finishing with the balls certified so far (Ctrl-C again to abort)"
            );
        }) {
            eprintln!("warning: Ctrl-C handler not installed: {e}");
        }
    }
    if !a.quiet {
        eprintln!(
            "MTL task: {} (judged on [0, {}] s, atoms in the CAF metric)",
            ts.written, task.problem.horizon
        );
        if let Some(xi) = ts.rewritten() {
            eprintln!("          in the task's coordinates: {xi}");
        }
    }
    let quiet = a.quiet;
    let opts = TemporalOptions {
        verify_interior: (a.verify_runs as usize).min(100_000),
        cancel: cancel.clone(),
        on_accept: (!quiet).then(|| {
            Arc::new(|count: usize, delta: f64| {
                eprintln!("certified ball {count} (δ = {delta:.4})")
            }) as Arc<dyn Fn(usize, f64) + Send + Sync>
        }),
        on_progress: (!quiet).then(super::stage_lines),
        imports,
        ..TemporalOptions::default()
    };
    let s = synthesize_temporal(task, tt, &opts).map_err(|e| Failure {
        // A vacuous formula is the spec's fault (bad input); anything else a failed search.
        exit: if e.starts_with(crate::synth::temporal::VACUOUS) {
            Exit::BadInput
        } else {
            Exit::Failed
        },
        report: miette::miette!("{e}"),
    })?;
    for (name, r) in &s.imported {
        match r {
            Ok(d) => eprintln!("{name}: imported, δ = {d:.4}"),
            Err(why) => eprintln!("warning: {name}: not used: {why}"),
        }
    }
    let img_path = a.out.join("controller.img");
    let unproved: Vec<String> = s
        .recheck
        .iter()
        .filter(|c| !c.ok)
        .map(|c| {
            format!(
                "ball {}: stored radius {:e}, the bytes certify {:e}",
                c.trajectory, c.stored, c.certified
            )
        })
        .collect();
    let verified = s.verify.violations == 0 && unproved.is_empty();
    let image = super::monitored(a, &s.image)?;
    if verified {
        write_atomic(&img_path, &image)?;
    }
    let cert = serde_json::json!({
        "spec": a.spec.display().to_string(),
        "seed": task.problem.seed,
        "task": "mtl",
        "image": super::image_identity(&img_path, &image),
        "formula": ts.written,
        "formula_in_task_coordinates": ts.rewritten(),
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
        "K": crate::linalg::to_rows(s.K.as_ref()),
        "P": crate::linalg::to_rows(s.P.as_ref()),
        "trajectories": s.trajectories.iter().map(|t| serde_json::json!({
            "source": t.source, "x0": t.nominal.x[0], "certificate": t.certificate,
            "nominal": t.nominal.x,
        })).collect::<Vec<_>>(),
        "seconds": s.seconds,
        "timings": s.timings,
    });
    std::fs::write(
        a.out.join("certificate.json"),
        serde_json::to_string_pretty(&cert).into_diagnostic()?,
    )
    .into_diagnostic()?;
    let page = crate::report::temporal::render(
        &task.problem,
        &a.spec.display().to_string(),
        &ts.written,
        ts.rewritten(),
        &s,
    );
    std::fs::write(a.out.join("report.html"), page).into_diagnostic()?;
    let (dmin, dmax) = s
        .trajectories
        .iter()
        .map(|t| t.certificate.delta)
        .fold((f64::INFINITY, 0.0f64), |(a, b), d| (a.min(d), b.max(d)));
    println!(
        "trajectories      {} ({} seeds tried)",
        s.trajectories.len(),
        s.seeds_tried
    );
    println!("delta range       {dmin:.4} .. {dmax:.4} (CAF metric)");
    println!(
        "coverage          {:.5} (lower bound {:.5}, upper {:.5} at {} confidence, {} samples)",
        s.coverage.mean,
        s.coverage.lower,
        s.coverage.upper,
        s.coverage.confidence,
        s.coverage.samples
    );
    println!("stop              {}", s.stop);
    println!(
        "verification      {} runs judged by the formula at the samples and sampled 8× finer ({} starts refused by the f32 selection, not run), {} violations; least robustness {:.4e} (every {}th run)",
        s.verify.runs,
        s.verify.rejected,
        s.verify.violations,
        s.verify.min_robustness,
        crate::verify::MARGIN_EVERY
    );
    println!(
        "re-proved         {} of {} balls from the image bytes",
        s.recheck.len() - unproved.len(),
        s.recheck.len()
    );
    println!(
        "time              {:.1} s ({})",
        s.seconds,
        s.timings
            .iter()
            .map(|(w, t)| format!("{w} {t:.1} s"))
            .collect::<Vec<_>>()
            .join(", ")
    );
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
        "balls",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(name: &str) -> crate::spec::Problem {
        crate::spec::load(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR")))
            .unwrap_or_else(|e| panic!("{e:?}"))
    }

    /// The certificate and report state the formula as written; a feedback-linearizable plant's rewriting
    /// into ξ (with the operating region's conjunct) is stated beside it, and a linear plant has none.
    #[test]
    fn the_formula_as_written_is_kept_beside_its_rewriting_into_xi() {
        let p = load("fl-pendulum-mtl.toml");
        let src = p.mtl.clone().expect("a formula");
        let ts = temporal_task(p).unwrap_or_else(|e| panic!("{:?}", e.report));
        assert_eq!(ts.written, src);
        let xi = ts.rewritten().expect("rewritten into ξ");
        assert!(xi != src && xi.contains("G[0.0,4.0]"), "{xi}");
        let p = load("planar-vehicle-waypoints.toml");
        let src = p.mtl.clone().expect("a formula");
        let ts = temporal_task(p).unwrap_or_else(|e| panic!("{:?}", e.report));
        assert_eq!((ts.written.as_str(), ts.rewritten()), (src.as_str(), None));
    }
}
