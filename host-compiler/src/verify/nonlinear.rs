//! Monte Carlo of a feedback-linearizable task's image against the nonlinear plant itself (§3.1.2): every
//! run starts from a plant state in Init, the controller measures the full state, maps it to ξ, runs the
//! linear law and maps w back to u through the model programs in f32, exactly as the firmware does; the
//! plant is flowed over each held period by the adaptive integrator (`model::nonlinear`, Dop853 at
//! rtol 10⁻¹⁰), with Unsafe also checked at [`SUBSTEPS`] − 1 instants inside every period. Runs are
//! judged as the linear Monte Carlo judges them (Goal reached within T, Unsafe never entered, every
//! applied input in the *plant's* input set, until the first sample in Goal), independently of how the
//! certificate bounded the zero dynamics and the sampled-loop mismatch.

use super::{check_runs, MonteCarloError, MAX_PER_BALL, MAX_RUNS};
use super::{input_slack, inverse_sqrt_metric, summarize, RunOutcome, VerifyReport, MARGIN_EVERY};
use crate::linalg::mat_vec;
use crate::model::feedback_linearizable::FlMaps;
use crate::property::input_bound;
use crate::task::Task;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use shared_types::eval::{Controller, Status};
use shared_types::image::Image;

/// Sub-intervals per period at which Unsafe is checked between samples.
pub const SUBSTEPS: usize = 8;

/// One control period of the firmware on the plant's measured state: ξ = coords(x̂), w from the linear
/// law on ξ, u = input_map(x̂, w), all in f32.
pub fn plant_step(ctl: &mut Controller<'_>, maps: &FlMaps, x: &[f32]) -> Result<Vec<f32>, Status> {
    let coords = maps.coords.program();
    let mut xi = vec![0.0f32; coords.n_outputs()];
    coords.eval(x, &mut xi).map_err(|_| Status::BadFrame)?;
    if !xi.iter().all(|v| v.is_finite()) {
        return Err(Status::OutOfEnvelope);
    }
    let w = ctl.step(&xi)?;
    let map = maps.input_map.program();
    let inputs: Vec<f32> = x.iter().chain(w.as_slice()).copied().collect();
    let mut u = vec![0.0f32; map.n_outputs()];
    map.eval(&inputs, &mut u).map_err(|_| Status::BadFrame)?;
    if !u.iter().all(|v| v.is_finite()) {
        return Err(Status::OutOfEnvelope);
    }
    Ok(u)
}

/// One closed-loop run from the plant state `x0` (module doc); margins recorded when asked.
pub fn run_fl(
    task: &Task,
    maps: &FlMaps,
    image: &Image<'_>,
    x0: &[f64],
    margins: bool,
) -> RunOutcome {
    let metric = crate::geometry::Metric::euclidean(maps.xi_states.len());
    let goal = task.property.goal.as_ref();
    let unsafe_set = task.property.unsafe_region();
    let input = input_bound(&maps.input);
    let h = maps.plant.period();
    let mut ctl = Controller::new(*image);
    let mut x = x0.to_vec();
    let mut out = RunOutcome::new(x0);
    let check = |x: &[f64], out: &mut RunOutcome, sample: bool| {
        if let Some(us) = unsafe_set {
            let xi = maps.xi_of(x);
            let inside = us.contains(&xi);
            if out.goal_step.is_some() {
                out.after_goal_unsafe |= inside;
                return;
            }
            out.entered_unsafe |= inside;
            if margins && sample {
                out.unsafe_margin = out.unsafe_margin.min(-us.signed_dist(&xi, &metric).value);
            }
        }
    };
    check(&x, &mut out, true);
    for k in 0..=task.steps {
        let xi = maps.xi_of(&x);
        if out.goal_step.is_none() && goal.contains(&xi) {
            out.reached_goal = true;
            out.goal_step = Some(k);
        }
        if margins {
            out.goal_margin = out.goal_margin.max(goal.signed_dist(&xi, &metric).value);
        }
        if k == task.steps {
            break;
        }
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let u: Vec<f64> = match plant_step(&mut ctl, maps, &xf) {
            Ok(u) => u.iter().map(|&v| v as f64).collect(),
            Err(_) => {
                if k == 0 {
                    out.rejected = true;
                } else if out.goal_step.is_none() {
                    out.evaluator_error = true;
                }
                return out;
            }
        };
        let s = input_slack(&input, &u);
        if out.goal_step.is_some() {
            out.after_goal_input_excursion |= s < 0.0;
        } else {
            out.input_margin = out.input_margin.min(s);
            out.input_violation |= s < 0.0;
        }
        match maps
            .plant
            .flow(&x, &u, h, SUBSTEPS, &mut |xs| check(xs, &mut out, false))
        {
            Ok(next) => x = next,
            Err(_) => {
                // The integrator failed: nothing is known about the run, so it counts against the image.
                if out.goal_step.is_none() {
                    out.evaluator_error = true;
                }
                return out;
            }
        }
        check(&x, &mut out, true);
    }
    out
}

/// Monte Carlo over the certified cover of a feedback-linearizable task: `interior` plant states drawn
/// uniformly in Init whose ξ the evaluator's selection accepts (at most 50× as many draws), plus
/// `per_ball` states per ball whose ξ lies on the ball's boundary (the stored radius less one part in 10⁶)
/// and whose zero-dynamics states are drawn in Init. Deterministic for a seed; runs in parallel.
pub fn monte_carlo_fl(
    task: &Task,
    image: &Image<'_>,
    interior: usize,
    per_ball: usize,
    seed: u64,
) -> Result<VerifyReport, MonteCarloError> {
    check_runs("interior", interior, MAX_RUNS)?;
    check_runs("per_ball", per_ball, MAX_PER_BALL)?;
    let maps = task
        .plant
        .linearization()
        .expect("monte_carlo_fl is called on a linearised task");
    let init = &maps.init;
    let n = image.n();
    let Pis = inverse_sqrt_metric(image)?;
    let ctl = Controller::new(*image);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let draw = |rng: &mut ChaCha8Rng| -> Vec<f64> {
        init.lo
            .iter()
            .zip(&init.hi)
            .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
            .collect()
    };
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let mut draws = 0usize;
    while starts.len() < interior && draws < interior.saturating_mul(50) {
        draws += 1;
        let x = draw(&mut rng);
        let xi: Vec<f32> = maps.xi_of(&x).iter().map(|&v| v as f32).collect();
        if ctl.select(&xi).is_some() {
            starts.push(x);
        }
    }
    let interior_runs = starts.len();
    let mut boundary: Vec<Vec<f64>> = Vec::new();
    for t in 0..image.n_trajectories() {
        let c: Vec<f64> = (0..n).map(|i| image.centre(t, i) as f64).collect();
        let d = image.delta(t) as f64 * (1.0 - 1e-6);
        for _ in 0..per_ball {
            let w: Vec<f64> = (0..n)
                .map(|_| rng.sample::<f64, _>(rand_distr::StandardNormal))
                .collect();
            let wn = w.iter().map(|a| a * a).sum::<f64>().sqrt().max(1e-300);
            let e = mat_vec(Pis.as_ref(), &w);
            let mut x = draw(&mut rng);
            for (j, &s) in maps.xi_states.iter().enumerate() {
                x[s] = c[j] + d * e[j] / wn;
            }
            boundary.push(x);
        }
    }
    let boundary_runs = boundary.len();
    let all: Vec<Vec<f64>> = starts.into_iter().chain(boundary).collect();
    let outcomes: Vec<RunOutcome> = all
        .par_iter()
        .enumerate()
        .map(|(i, x0)| run_fl(task, maps, image, x0, i % MARGIN_EVERY == 0))
        .collect();
    Ok(summarize(&outcomes, interior_runs, boundary_runs))
}
