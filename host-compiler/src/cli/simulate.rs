//! `host-compiler simulate SPEC IMAGE --x0 …`: one closed-loop run through the shared f32 evaluator,
//! written as CSV (t, x…, u…, status).

use super::{decode_image, read_image, task_of, BadInput, Exit, Failure, Outcome};
use crate::verify::check_matches;
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
    check_matches(&problem, &img)
        .map_err(|e| {
            miette::miette!(
                "{} does not belong to {}: {e}",
                a.image.display(),
                a.spec.display()
            )
        })
        .bad_input()?;
    let n = problem.plant.n();
    if a.x0.len() != n {
        return Err(Failure::bad_input(miette::miette!(
            "--x0 has {} values; the spec has n = {n}",
            a.x0.len()
        )));
    }
    let task = task_of(problem)?;
    let problem = &task.problem;
    // Within MAX_STEPS (clap checked), so the conversion is exact.
    let steps = a.steps.map_or(problem.horizon_steps(), |s| s as usize);
    let mut ctl = Controller::new(img);
    let mut out: Box<dyn Write> = match &a.out {
        Some(p) => Box::new(
            std::fs::File::create(p)
                .into_diagnostic()
                .map_err(|e| e.wrap_err(format!("cannot create {}", p.display())))
                .bad_input()?,
        ),
        None => Box::new(std::io::stdout().lock()),
    };
    let m = problem.plant.m();
    let head: Vec<String> = std::iter::once("t".to_string())
        .chain((1..=n).map(|i| format!("x{i}")))
        .chain((1..=m).map(|i| format!("u{i}")))
        .chain(std::iter::once("status".to_string()))
        .collect();
    writeln!(out, "{}", head.join(",")).into_diagnostic()?;
    let mut x = a.x0.clone();
    let mut last = shared_types::eval::Input::zero(m);
    for k in 0..=steps {
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let (u, status) = match ctl.step(&xf) {
            Ok(u) => (u, "ok".to_string()),
            Err(s) => (ctl.fallback(&xf, &last), format!("{s}")),
        };
        last = u;
        let uf: Vec<f64> = u.as_slice().iter().map(|&v| v as f64).collect();
        let row: Vec<String> = std::iter::once(format!("{}", k as f64 * problem.plant.period))
            .chain(x.iter().map(|v| format!("{v}")))
            .chain(uf.iter().map(|v| format!("{v}")))
            .chain(std::iter::once(status))
            .collect();
        writeln!(out, "{}", row.join(",")).into_diagnostic()?;
        x = task.plant.step(0, &x, &uf);
    }
    Ok(Exit::Success)
}
