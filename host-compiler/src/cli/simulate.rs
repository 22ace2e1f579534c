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
//!
//! A hybrid plant (§4.2) runs as [`crate::verify::hybrid`]'s Monte Carlo runs it, through its own
//! functions ([`crate::verify::hybrid::take_forced`], [`crate::verify::hybrid::flow_period`]): from x0
//! in the automaton's initial location, the evaluator's input held over each period on the automaton's
//! exact flow (internal events found between samples, resets applied), and with forced switching the
//! location of the evaluator's row taken at the sample as the discrete input (§4.2.1). Its CSV has a
//! [`crate::trajectory::csv::LOCATION`] column: the name of the location the plant flows in from that
//! sample on (after a forced switch taken there), and v = u − K̂_ℓ x with that location's gain, so the
//! file is a recording `synth --import` reads for either kind of switching (and `mtl` skips the column).
//! The states are those at the samples (after any events in the period before, as the plant is measured);
//! each event is a comment line `# event t = … s: edge e (a → b), …` after the row of the period it falls
//! in, with its time and, for an internal event, the state reaching the guard. The verdict also gives
//! the least distance to Unsafe between samples ([`crate::verify::hybrid::SUBSTEPS`] per period, up to
//! Goal) and the events taken. Unlike the Monte Carlo, the run goes on for `--steps` samples after
//! Goal, a refused state or an input outside the set (as a one-location run does); a forced switch
//! whose guard does not hold the state, or a flow the automaton cannot continue, ends it (exit 1).

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
#[command(after_long_help = "\
The CSV (standard output or --out): `# x0 = …`, a header, a row per sample:
  t         the sample time (s)
  x1…xn     the plant's state at the sample
  u1…um     the input applied over the period that follows (the evaluator's,
            or the fallback's)
  v1…vm     the reference v = u − K̂x of the image's gain (for a hybrid image,
            the gain of the row's location); none for a feedback-linearizable
            or flat plant, whose law is not in the plant's input
  location  hybrid images only: the location the plant flows in from that
            sample on (after a forced switch the controller takes there)
  status    `ok`, or why the evaluator refused the state (fallback applied)
A hybrid image runs on the automaton's exact flow, as `verify` runs it; each
event is a comment line `# event t = … s: edge e (a → b), …` after the row of
its period, and the rows hold the states at the samples.
The file is a trace `mtl` reads and a recording `synth --import` reads (the
last row, the final state, is not an input). The verdict goes to standard
error; exit 1 when the run cannot go on (a flow the plant cannot continue, a
forced switch outside its guard).")]
pub struct SimulateArgs {
    /// Task spec (TOML).
    pub spec: PathBuf,
    /// Controller image.
    pub image: PathBuf,
    /// Initial state, comma separated (n finite values).
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
    // Within MAX_STEPS (clap checked), so the conversion is exact.
    let steps = a.steps.map_or(problem.horizon_steps(), |s| s as usize);
    if problem.hybrid.is_some() {
        return run_hybrid(a, &problem, &img, steps);
    }
    let task = task_of(problem)?;
    let problem = &task.problem;
    let mut out = open_out(a)?;
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
    let judge = Verdict {
        property: &task.property,
        period: task.plant.period(),
        steps: task.steps,
    };
    eprintln!(
        "{}",
        judge.text(&run.judged, run.outside, run.bad_inputs, None)
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

/// `--x0` must give n finite values; a bad one is bad input naming its entry.
fn check_x0(x0: &[f64], n: usize) -> Result<(), Failure> {
    if x0.len() != n {
        return Err(Failure::bad_input(miette::miette!(
            "--x0 has {} values; the plant has n = {n}",
            x0.len()
        )));
    }
    if let Some(i) = x0.iter().position(|v| !v.is_finite()) {
        return Err(Failure::bad_input(miette::miette!(
            "--x0 entry {} (x{}) is {}: the initial state must be finite numbers",
            i + 1,
            i + 1,
            x0[i]
        )));
    }
    Ok(())
}

/// Where the CSV goes: `--out`, or standard output.
fn open_out(a: &SimulateArgs) -> Result<Box<dyn Write>, Failure> {
    Ok(match &a.out {
        Some(p) => Box::new(
            std::fs::File::create(p)
                .into_diagnostic()
                .map_err(|e| e.wrap_err(format!("cannot create {}", p.display())))
                .bad_input()?,
        ),
        None => Box::new(std::io::stdout().lock()),
    })
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

/// What a run is judged against: the task's reach-avoid property over its horizon of `steps` samples.
struct Verdict<'a> {
    property: &'a crate::property::ReachAvoid,
    period: f64,
    steps: usize,
}

impl Verdict<'_> {
    /// The run's verdict on its samples, for people (module doc). Distances are Euclidean. `between`:
    /// the least distance to Unsafe between samples up to the first sample in Goal and its time, where
    /// the run was also looked at there (a hybrid run's sub-samples).
    fn text(
        &self,
        states: &[Vec<f64>],
        outside: usize,
        bad_inputs: usize,
        between: Option<(f64, f64)>,
    ) -> String {
        use crate::property::Property;
        let h = self.period;
        let prop = self.property;
        let n = states.first().map_or(0, Vec::len);
        let metric = crate::geometry::Metric::euclidean(n);
        let goal_step = states
            .iter()
            .take(self.steps + 1)
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
                let between = between.map_or(String::new(), |(d, t)| {
                    format!(
                        " ({d:.4e} between samples, at t = {t:.4} s{})",
                        if d <= 0.0 { ", INSIDE" } else { "" }
                    )
                });
                format!(
                    "least distance to Unsafe {d:.4e} at step {k}{}{between}",
                    if d < 0.0 { " (INSIDE)" } else { "" }
                )
            }
        };
        let names: Vec<String> = (1..=n).map(|i| format!("x{i}")).collect();
        let times: Vec<f64> = (0..states.len()).map(|k| k as f64 * h).collect();
        let columns: Vec<Vec<f64>> = (0..n)
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
}

/// `simulate` of a hybrid image (module doc): the run [`crate::verify::hybrid`]'s Monte Carlo makes,
/// from x0 in the automaton's initial location, written with each row's location and the events as
/// comment lines, for `steps` samples whatever the run meets on the way.
fn run_hybrid(
    a: &SimulateArgs,
    problem: &crate::spec::Problem,
    img: &shared_types::image::Image<'_>,
    steps: usize,
) -> Outcome {
    use crate::verify::hybrid::{flow_period, take_forced, PeriodStop, SUBSTEPS};
    let desc = problem.hybrid.as_ref().expect("called for a hybrid spec");
    let h = problem.plant.period;
    let plant = crate::model::hybrid::Hybrid::from_spec(desc, h)
        .map_err(|e| miette::miette!("{}: {e}", a.spec.display()))
        .bad_input()?;
    let property = crate::property::ReachAvoid::from_problem(problem)
        .map_err(|e| miette::miette!("{}: {e}", a.spec.display()))
        .bad_input()?;
    let modes = plant.modes();
    if img.n_locations() != modes.len() {
        return Err(Failure::bad_input(miette::miette!(
            "{} does not belong to {}: the image has {} locations, the automaton {}",
            a.image.display(),
            a.spec.display(),
            img.n_locations(),
            modes.len()
        )));
    }
    let (n, m) = (img.n(), img.m());
    check_x0(&a.x0, n)?;
    // The flow verify's Monte Carlo takes: the automaton resampled at SUBSTEPS sub-periods per period.
    let fine = plant
        .resampled(h / SUBSTEPS as f64)
        .map_err(|e| miette::miette!("{}: {e}", a.spec.display()))
        .bad_input()?;
    let edge_name = |e: usize| {
        let edge = &plant.edges()[e];
        format!(
            "edge {e} ({} → {})",
            modes[edge.from].name, modes[edge.to].name
        )
    };
    let list = |x: &[f64]| {
        x.iter()
            .map(|v| format!("{v}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut out = open_out(a)?;
    let io = |e: std::io::Error| Failure::from(miette::miette!("cannot write the run: {e}"));
    writeln!(out, "# x0 = {}", list(&a.x0)).map_err(io)?;
    writeln!(
        out,
        "# a run of a hybrid image: `{}` is the location the plant flows in from each sample on (after \
         a forced switch the controller takes there); events between samples are the `# event` lines",
        crate::trajectory::csv::LOCATION
    )
    .map_err(io)?;
    let head: Vec<String> = std::iter::once("t".to_string())
        .chain((1..=n).map(|i| format!("x{i}")))
        .chain((1..=m).map(|i| format!("u{i}")))
        .chain((1..=m).map(|i| format!("v{i}")))
        .chain([
            crate::trajectory::csv::LOCATION.to_string(),
            crate::csv::STATUS.to_string(),
        ])
        .collect();
    writeln!(out, "{}", head.join(",")).map_err(io)?;
    let mut ctl = Controller::new(*img);
    let (mut x, mut loc) = (a.x0.clone(), desc.initial);
    let mut last = shared_types::eval::Input::zero(m);
    let (mut outside, mut bad_inputs, mut events) = (0usize, 0usize, 0usize);
    let mut samples: Vec<Vec<f64>> = Vec::with_capacity(steps + 1);
    // The least distance to Unsafe between samples up to the first sample in Goal, and when.
    let mut between = (f64::INFINITY, 0.0f64);
    let mut in_goal = false;
    let euclid = crate::geometry::Metric::euclidean(n);
    let mut stopped: Option<String> = None;
    let horizon = problem.horizon_steps();
    for k in 0..=steps {
        let t = k as f64 * h;
        samples.push(x.clone());
        in_goal = in_goal || (k <= horizon && property.goal.contains(&x));
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let (u, status, accepted) = match ctl.step(&xf) {
            Ok(u) => (u, "ok".to_string(), true),
            Err(s) => {
                outside += 1;
                (ctl.fallback(&xf, &last), format!("{s}"), false)
            }
        };
        last = u;
        let uf: Vec<f64> = u.as_slice().iter().map(|&v| v as f64).collect();
        if crate::verify::input_slack(&property.input, &uf) < 0.0 {
            bad_inputs += 1;
        }
        // Forced switching (§4.2.1): the location of the evaluator's row is the discrete input, taken
        // at the sample; under the fallback the table chooses nothing and the plant stays.
        let measured = x.clone();
        let switch = if accepted {
            take_forced(&fine, &mut loc, &mut x, ctl.location())
        } else {
            Ok(None)
        };
        // The reference of the row's location's gain: u = K̂_ℓ x + v, as a recording gives it.
        let refs = (0..m).map(|j| {
            let kx: f64 = (0..n).map(|i| img.K(loc, j, i) as f64 * measured[i]).sum();
            format!("{}", uf[j] - kx)
        });
        let row: Vec<String> = std::iter::once(format!("{t}"))
            .chain(measured.iter().map(|v| format!("{v}")))
            .chain(uf.iter().map(|v| format!("{v}")))
            .chain(refs)
            .chain([modes[loc].name.clone(), status])
            .collect();
        writeln!(out, "{}", row.join(",")).map_err(io)?;
        match switch {
            Ok(Some(e)) => {
                events += 1;
                writeln!(
                    out,
                    "# event t = {t} s: forced {}, at the sample",
                    edge_name(e)
                )
                .map_err(io)?;
            }
            Ok(None) => {}
            Err(want) => {
                stopped = Some(format!(
                    "at step {k} (t = {t} s) the controller switches from {} to {}, but the state is \
                     not in that forced edge's guard: the run stops there",
                    modes[loc].name, modes[want].name
                ));
                break;
            }
        }
        if k == steps {
            break;
        }
        let mut lines: Vec<String> = Vec::new();
        let sub_h = fine.period();
        let flowed = flow_period(&fine, &mut loc, &mut x, &uf, &mut |s| {
            let start = t + (s.index - 1) as f64 * sub_h;
            for ev in s.events {
                lines.push(format!(
                    "# event t = {} s: {}, reaching its guard at x = {}",
                    start + ev.time,
                    edge_name(ev.edge),
                    list(&ev.before)
                ));
            }
            events += s.events.len();
            if !in_goal {
                if let Some(us) = property.unsafe_region() {
                    let d = -us.signed_dist(s.x, &euclid).value;
                    if d < between.0 {
                        between = (d, t + s.index as f64 * sub_h);
                    }
                }
            }
            Ok(())
        });
        for l in &lines {
            writeln!(out, "{l}").map_err(io)?;
        }
        match flowed {
            Ok(()) => {}
            // `sub` never stops the period.
            Err(PeriodStop::Stopped(why)) => stopped = Some(why),
            Err(PeriodStop::Flow { from, error }) => {
                stopped = Some(format!(
                    "the automaton's flow failed in the period from step {k} (t = {t} s), at x = {}: \
                     {error}",
                    list(&from)
                ));
            }
        }
        if stopped.is_some() {
            break;
        }
    }
    out.flush().map_err(io)?;
    let judge = Verdict {
        property: &property,
        period: h,
        steps: problem.horizon_steps(),
    };
    let between = property
        .unsafe_region()
        .and(between.0.is_finite().then_some(between));
    eprintln!(
        "{}; events taken: {events}",
        judge.text(&samples, outside, bad_inputs, between)
    );
    if let Some(why) = stopped {
        return Err(miette::miette!("{why}").into());
    }
    Ok(Exit::Success)
}
