//! `host-compiler simulate SPEC IMAGE --x0 …`: one closed-loop run through the shared f32 evaluator,
//! written as CSV in the tools' dialect ([`crate::csv`]: the `# x0` line, then t, x…, u…, the references
//! v = u − K̂ x of the image's gain, status; a trace `mtl` reads and a recording `synth --import` reads),
//! and a verdict on standard error: when Goal was first reached,
//! the least distance to Unsafe before it, the steps out of the certified envelope, the inputs outside
//! the input set, and the run's reach-avoid robustness ([`crate::property::Property`], Euclidean).
//!
//! A feedback-linearizable plant (§3.1.2) runs as `verify` runs it: the plant's state through the
//! image's maps (`step_plant`), the plant flowed by Dop853, the verdict judged in ξ; its CSV has the
//! plant's states and inputs and no reference columns (the law's w is not the plant's input).

use super::{
    decode_image, image_matches_spec, maps_match, read_image, task_of, BadInput, Exit, Failure,
    Outcome,
};
use miette::IntoDiagnostic;
use shared_types::eval::Controller;
use std::io::Write;
use std::path::PathBuf;

/// Largest `--steps`: the run is written row by row, but each step is simulated and printed.
pub const MAX_STEPS: u64 = 1_000_000;

/// Arguments of `simulate`.
#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// Task spec (TOML).
    pub spec: PathBuf,
    /// Controller image.
    pub image: PathBuf,
    /// Initial state, comma separated (n values).
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        required = true
    )]
    pub x0: Vec<f64>,
    /// Number of steps (default: the spec's horizon); at most 1000000 ([`MAX_STEPS`]).
    #[arg(long, value_parser = clap::value_parser!(u64).range(..=MAX_STEPS))]
    pub steps: Option<u64>,
    /// Write the CSV here instead of standard output.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(a: &SimulateArgs) -> Outcome {
    let problem = crate::spec::load(&a.spec).bad_input()?;
    let bytes = read_image(&a.image)?;
    let img = decode_image(&bytes, &a.image)?;
    image_matches_spec(&problem, &img, &a.image, &a.spec)?;
    let task = task_of(problem)?;
    let problem = &task.problem;
    // Within MAX_STEPS (clap checked), so the conversion is exact.
    let steps = a.steps.map_or(problem.horizon_steps(), |s| s as usize);
    let mut out: Box<dyn Write> = match &a.out {
        Some(p) => Box::new(
            std::fs::File::create(p)
                .into_diagnostic()
                .map_err(|e| e.wrap_err(format!("cannot create {}", p.display())))
                .bad_input()?,
        ),
        None => Box::new(std::io::stdout().lock()),
    };
    let run = match task.plant.linearization() {
        None => {
            let n = task.plant.n();
            check_x0(&a.x0, n)?;
            // Per row the reference v = u − K̂ x of the image's gain (location 0): the file is then a
            // recording `synth --import` reads as it is (`trajectory::csv`).
            let K: Vec<Vec<f64>> = (0..task.plant.m())
                .map(|j| (0..n).map(|i| img.K(0, j, i) as f64).collect())
                .collect();
            let plant = task.plant.as_ref();
            write_run(
                &mut *out,
                &img,
                &a.x0,
                steps,
                problem.plant.period,
                Some(&K),
                &task.property.input,
                false,
                &mut |x, u| Ok(plant.step(0, x, u)),
                &|x, _| x.to_vec(),
            )?
        }
        Some(maps) => {
            // A feedback-linearizable plant: the image's maps around the law (`step_plant`), the plant
            // flowed by Dop853, judged in ξ; no reference column (the law's w is not the plant's input).
            maps_match(maps, &img, &a.image, &a.spec)?;
            check_x0(&a.x0, maps.n_plant)?;
            let input = crate::property::input_bound(&maps.input);
            let h = maps.plant.period();
            write_run(
                &mut *out,
                &img,
                &a.x0,
                steps,
                h,
                None,
                &input,
                true,
                &mut |x, u| {
                    maps.plant
                        .flow(x, u, h, 1, &mut |_| {})
                        .map_err(|e| e.to_string())
                },
                &|x, zeta| maps.xi_at(x, zeta),
            )?
        }
    };
    out.flush().into_diagnostic()?;
    eprintln!(
        "{}",
        verdict(&task, &run.judged, run.outside, run.bad_inputs)
    );
    if let Some(e) = run.stopped {
        return Err(miette::miette!(
            "the plant's integration failed after {} steps: {e}",
            run.judged.len() - 1
        )
        .into());
    }
    Ok(Exit::Success)
}

fn check_x0(x0: &[f64], n: usize) -> Result<(), Failure> {
    if x0.len() != n {
        return Err(Failure::bad_input(miette::miette!(
            "--x0 has {} values; the plant has n = {n}",
            x0.len()
        )));
    }
    Ok(())
}

/// What [`write_run`] saw: the states in the task's coordinates (ξ for a feedback-linearizable plant),
/// the steps out of the envelope, the inputs outside the input set, and why the run stopped early.
struct Run {
    judged: Vec<Vec<f64>>,
    outside: usize,
    bad_inputs: usize,
    stopped: Option<String>,
}

/// The closed loop for `steps` steps from `x0`, one CSV row per sample (module doc): the evaluator's
/// One period of the plant from (x, u).
type Advance<'a> = dyn FnMut(&[f64], &[f64]) -> Result<Vec<f64>, String> + 'a;
/// A state in the task's coordinates from (x, the controller's own states ζ).
type Judged<'a> = dyn Fn(&[f64], &[f64]) -> Vec<f64> + 'a;

/// `step_plant` for a plant with model maps (`plant_step`), else `step`; `advance` the plant over one period, `judged` the state in the
/// task's coordinates; `K` gives the reference columns when the plant's input is the law's.
#[allow(clippy::too_many_arguments)]
fn write_run(
    out: &mut dyn Write,
    img: &shared_types::image::Image<'_>,
    x0: &[f64],
    steps: usize,
    period: f64,
    K: Option<&Vec<Vec<f64>>>,
    input: &crate::property::InputBound,
    plant_step: bool,
    advance: &mut Advance<'_>,
    judged: &Judged<'_>,
) -> Result<Run, Failure> {
    let (n, m) = (x0.len(), img.plant_m());
    let mut ctl = Controller::new(*img);
    let names: Vec<String> = x0.iter().map(|v| format!("{v}")).collect();
    writeln!(out, "# x0 = {}", names.join(", ")).into_diagnostic()?;
    let head: Vec<String> = std::iter::once("t".to_string())
        .chain((1..=n).map(|i| format!("x{i}")))
        .chain((1..=m).map(|i| format!("u{i}")))
        .chain(K.into_iter().flat_map(|_| (1..=m).map(|i| format!("v{i}"))))
        .chain(std::iter::once(crate::csv::STATUS.to_string()))
        .collect();
    writeln!(out, "{}", head.join(",")).into_diagnostic()?;
    let mut x = x0.to_vec();
    let mut last = shared_types::eval::Input::zero(m);
    let mut run = Run {
        judged: Vec::with_capacity(steps + 1),
        outside: 0,
        bad_inputs: 0,
        stopped: None,
    };
    for k in 0..=steps {
        // The state in the task's coordinates, read with the controller's own states (a flat plant's).
        let zeta: Vec<f64> = ctl.extension().iter().map(|&v| v as f64).collect();
        run.judged.push(judged(&x, &zeta));
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let answer = if plant_step {
            ctl.step_plant(&xf)
        } else {
            ctl.step(&xf)
        };
        let (u, status) = match answer {
            Ok(u) => (u, "ok".to_string()),
            Err(s) => {
                run.outside += 1;
                (ctl.fallback(&xf, &last), format!("{s}"))
            }
        };
        last = u;
        let uf: Vec<f64> = u.as_slice().iter().map(|&v| v as f64).collect();
        if crate::verify::input_slack(input, &uf) < 0.0 {
            run.bad_inputs += 1;
        }
        let refs: Vec<String> = K
            .map(|K| {
                K.iter()
                    .zip(&uf)
                    .map(|(k, u)| {
                        let kx: f64 = k.iter().zip(&x).map(|(a, b)| a * b).sum();
                        format!("{}", u - kx)
                    })
                    .collect()
            })
            .unwrap_or_default();
        let row: Vec<String> = std::iter::once(format!("{}", k as f64 * period))
            .chain(x.iter().map(|v| format!("{v}")))
            .chain(uf.iter().map(|v| format!("{v}")))
            .chain(refs)
            .chain(std::iter::once(status))
            .collect();
        writeln!(out, "{}", row.join(",")).into_diagnostic()?;
        if k == steps {
            break;
        }
        match advance(&x, &uf) {
            Ok(next) => x = next,
            Err(e) => {
                run.stopped = Some(e);
                break;
            }
        }
    }
    Ok(run)
}

/// The run's verdict, for people (module doc). Distances are Euclidean.
fn verdict(
    task: &crate::task::Task,
    states: &[Vec<f64>],
    outside: usize,
    bad_inputs: usize,
) -> String {
    use crate::property::Property;
    let h = task.plant.period();
    let prop = &task.property;
    let metric = crate::geometry::Metric::euclidean(task.plant.n());
    let goal_step = states
        .iter()
        .take(task.steps + 1)
        .position(|x| prop.goal.contains(x));
    let judged = goal_step.map_or(states.len(), |k| k + 1);
    let goal = match goal_step {
        Some(k) => format!("Goal reached at step {k} (t = {:.4} s)", k as f64 * h),
        None => format!("Goal not reached within T = {} s", prop.horizon),
    };
    let unsafe_ = match prop.unsafe_region() {
        None => "no Unsafe set".to_string(),
        Some(us) => {
            let (k, d) = states[..judged]
                .iter()
                .enumerate()
                .map(|(k, x)| (k, -us.signed_dist(x, &metric).value))
                .fold((0, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b });
            format!(
                "least distance to Unsafe {d:.4e} at step {k}{}",
                if d < 0.0 { " (INSIDE)" } else { "" }
            )
        }
    };
    let names: Vec<String> = (1..=task.plant.n()).map(|i| format!("x{i}")).collect();
    let times: Vec<f64> = (0..states.len()).map(|k| k as f64 * h).collect();
    let columns: Vec<Vec<f64>> = (0..task.plant.n())
        .map(|i| states.iter().map(|x| x[i]).collect())
        .collect();
    let rho = crate::robustness::mtl::Trace::new(times, names, columns)
        .ok()
        .and_then(|t| prop.trace_robustness(&t).ok());
    format!(
        "verdict: {goal}; {unsafe_}; {outside} steps out of the certified envelope (fallback applied); \
         {bad_inputs} inputs outside the input set; reach-avoid robustness of the samples {}",
        rho.map_or("not defined (the run left the finite numbers)".to_string(), |r| format!("{r:.4e}"))
    )
}
