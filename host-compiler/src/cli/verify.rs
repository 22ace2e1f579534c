//! `host-compiler verify SPEC IMAGE`: closed-loop Monte Carlo of an image against its spec through the
//! shared f32 evaluator.

use crate::task::Task;
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
    /// Initial states drawn uniformly in the certified cover (the part of Init the image accepts).
    #[arg(long, default_value_t = 10_000)]
    pub runs: usize,
    /// Initial states on the boundary of each ball.
    #[arg(long, default_value_t = 32)]
    pub per_ball: usize,
    /// Seed of the Monte Carlo draw (default: the spec's seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &VerifyArgs) -> miette::Result<()> {
    let problem = crate::spec::load(&a.spec)?;
    let bytes = std::fs::read(&a.image).into_diagnostic()?;
    let img = shared_types::image::decode(&bytes)
        .map_err(|e| miette::miette!("{}: the image is rejected: {e:?}", a.image.display()))?;
    if img.n() != problem.plant.n() || img.m() != problem.plant.m() {
        return Err(miette::miette!(
            "the image is for n = {}, m = {} but the spec has n = {}, m = {}",
            img.n(),
            img.m(),
            problem.plant.n(),
            problem.plant.m()
        ));
    }
    let task = Task::new(problem).map_err(|e| miette::miette!("{e}"))?;
    let problem = &task.problem;
    let judge = Judge::new(&task);
    if img.mode() == shared_types::image::Mode::PwaFeedback {
        return run_pwa(a, &judge, &img);
    }
    let r = monte_carlo(
        &judge,
        &img,
        a.runs,
        a.per_ball,
        a.seed.unwrap_or(problem.seed ^ 0x7e51f1),
    );
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r).into_diagnostic()?);
    } else {
        println!(
            "runs {} interior + {} boundary ({} boundary points not accepted by the f32 selection)",
            r.interior_runs, r.boundary_runs, r.boundary_rejected
        );
        println!(
            "worst margins: goal depth {:.4e}, unsafe distance {:.4e}, input slack {:.4e}",
            r.worst_goal_margin, r.worst_unsafe_margin, r.worst_input_margin
        );
        for v in &r.first_violations {
            println!("violation from x0 = {:?}: {v:?}", v.x0);
        }
        println!(
            "after Goal (not judged, the task has ended): {} runs left the input set, {} entered Unsafe",
            r.after_goal_input_excursions, r.after_goal_unsafe
        );
        println!("violations {}", r.violations);
    }
    if r.violations > 0 {
        return Err(miette::miette!("{} violations", r.violations));
    }
    if r.interior_runs < a.runs {
        return Err(miette::miette!(
            "only {} of {} initial states could be drawn in the certified cover",
            r.interior_runs,
            a.runs
        ));
    }
    Ok(())
}

/// PWA images (Ch. 6): the independent certificate recheck and closed-loop Monte Carlo from F
/// ([`crate::verify::pwa`]); runs terminate upon entering Goal (Theorem 6.5).
fn run_pwa(
    a: &VerifyArgs,
    judge: &Judge<'_>,
    img: &shared_types::image::Image<'_>,
) -> miette::Result<()> {
    let rc = crate::verify::pwa::recheck(judge, img).map_err(|e| miette::miette!(e))?;
    // The image does not mark which balls start a trajectory: all runs start anywhere in F.
    let mc =
        crate::verify::pwa::monte_carlo_pwa(judge, img, &[], a.runs, a.seed.unwrap_or(0x7e51f1), 0);
    if a.json {
        let j = serde_json::json!({ "recheck": rc, "monte_carlo": mc });
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
            mc.runs, mc.rejected, mc.max_steps
        );
        for v in &mc.first_violations {
            println!("violation from x0 = {:?}: {v:?}", v.x0);
        }
        println!("violations {}", mc.violations);
    }
    if rc.failures > 0 || mc.violations > 0 {
        return Err(miette::miette!(
            "{} certificate failures, {} violations",
            rc.failures,
            mc.violations
        ));
    }
    if mc.runs < a.runs {
        return Err(miette::miette!(
            "only {} of {} initial states could be drawn in F",
            mc.runs,
            a.runs
        ));
    }
    Ok(())
}
