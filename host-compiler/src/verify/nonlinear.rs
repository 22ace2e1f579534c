//! Monte Carlo of a feedback-linearizable task's image against the nonlinear plant itself (§3.1.2): every
//! run starts from a plant state in Init, and the shared evaluator's `step_plant` (what the firmware runs)
//! maps the measured state to ξ, runs the linear law and maps w back to u through the image's model
//! programs in f32; the
//! plant is flowed over each held period by the adaptive integrator (`model::nonlinear`, Dop853 at
//! rtol 10⁻¹⁰), with Unsafe also checked at [`SUBSTEPS`] − 1 instants inside every period. Runs are
//! judged as the linear Monte Carlo judges them (Goal reached within T, Unsafe never entered (with an
//! operating region, leaving it is entering Unsafe, checked on the plant's whole state), every
//! applied input in the *plant's* input set, until the first sample in Goal), independently of how the
//! certificate bounded the zero dynamics and the sampled-loop mismatch.

use super::SignedDistances;
use super::{ball_boundary_point, check_runs, MonteCarloError, MAX_PER_BALL, MAX_RUNS};
use super::{input_slack, inverse_sqrt_metric, summarize, RunOutcome, VerifyReport, MARGIN_EVERY};
use crate::geometry::NearbyMembership;
use crate::model::feedback_linearizable::FlMaps;
use crate::property::input_bound;
use crate::task::Task;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use shared_types::eval::Controller;
use shared_types::image::Image;

/// Sub-intervals per period at which Unsafe is checked between samples.
pub const SUBSTEPS: usize = 8;

/// One closed-loop run from the plant state `x0` (module doc); margins recorded when asked.
pub fn run_fl(
    task: &Task,
    maps: &FlMaps,
    image: &Image<'_>,
    x0: &[f64],
    margins: bool,
) -> RunOutcome {
    run_fl_inner(task, maps, image, x0, margins, &mut |_| {})
}

/// [`run_fl`] without margins, showing `visit` ξ at every sample the run reaches (x0's first), in
/// order (the falsifier scores these: [`super::attack::attack_fl`]).
pub fn run_fl_visiting(
    task: &Task,
    maps: &FlMaps,
    image: &Image<'_>,
    x0: &[f64],
    visit: &mut dyn FnMut(&[f64]),
) -> RunOutcome {
    run_fl_inner(task, maps, image, x0, false, visit)
}

fn run_fl_inner(
    task: &Task,
    maps: &FlMaps,
    image: &Image<'_>,
    x0: &[f64],
    margins: bool,
    visit: &mut dyn FnMut(&[f64]),
) -> RunOutcome {
    let metric = crate::geometry::Metric::euclidean(maps.n_xi());
    let goal = task.property.goal.as_ref();
    let unsafe_set = task.property.unsafe_region();
    let input = input_bound(&maps.input);
    let h = maps.plant.period();
    let mut ctl = Controller::new(*image);
    let mut x = x0.to_vec();
    let mut out = RunOutcome::new(x0);
    // The controller's own states ζ (a flat plant's dynamic extension; empty otherwise), as the evaluator
    // keeps them: ξ of a plant state is read with them.
    let zeta =
        |ctl: &Controller<'_>| -> Vec<f64> { ctl.extension().iter().map(|&v| v as f64).collect() };
    // Unsafe's membership along the run: the same answers as `contains`, without the test where a point
    // lies within the sure radius of an earlier one (most of a period's states between samples).
    let mut near = NearbyMembership::new();
    let check = |x: &[f64], xi: &[f64], out: &mut RunOutcome, near: &mut NearbyMembership| {
        // Outside the operating region (the plant's whole state, zero dynamics included) is Unsafe.
        if let Some(r) = &maps.region {
            let outside = x
                .iter()
                .zip(r.lo.iter().zip(&r.hi))
                .any(|(v, (l, h))| !(l < v && v < h));
            if out.goal_step.is_some() {
                out.after_goal_unsafe |= outside;
            } else {
                out.entered_unsafe |= outside;
            }
        }
        if let Some(us) = unsafe_set {
            let inside = near.contains(us, xi);
            if out.goal_step.is_some() {
                out.after_goal_unsafe |= inside;
                return;
            }
            out.entered_unsafe |= inside;
        }
    };
    // The margins at the samples (every `MARGIN_EVERY`-th run), before Goal for Unsafe.
    let mut goal_dist = SignedDistances::new(goal, &metric);
    let mut unsafe_dist = unsafe_set.map(|us| SignedDistances::new(us, &metric));
    let mut unsafe_margin = |xi: &[f64], out: &mut RunOutcome| {
        if let (true, None, Some(d)) = (margins, out.goal_step, unsafe_dist.as_mut()) {
            out.unsafe_margin = out.unsafe_margin.min(-d.at(xi));
        }
    };
    let mut z = zeta(&ctl);
    let mut xi = maps.xi_at(&x, &z);
    check(&x, &xi, &mut out, &mut near);
    unsafe_margin(&xi, &mut out);
    for k in 0..=task.steps {
        visit(&xi);
        if out.goal_step.is_none() && goal.contains(&xi) {
            out.reached_goal = true;
            out.goal_step = Some(k);
        }
        if margins {
            out.goal_margin = out.goal_margin.max(goal_dist.at(&xi));
        }
        if k == task.steps {
            break;
        }
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let u: Vec<f64> = match ctl.step_plant(&xf) {
            Ok(u) => u.as_slice().iter().map(|&v| v as f64).collect(),
            Err(_) => {
                // An image with model maps carries no terminal law.
                out.refused(k, false);
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
        // Between samples ζ follows its model over the period (`FlatCoords::zeta_within`).
        let z1 = zeta(&ctl);
        let mut i = 0;
        let mut between = |xs: &[f64]| {
            i += 1;
            let zs = match &maps.flat {
                Some(fc) => fc.zeta_within(&z, &z1, h, i as f64 * h / SUBSTEPS as f64),
                None => Vec::new(),
            };
            check(xs, &maps.xi_at(xs, &zs), &mut out, &mut near)
        };
        match maps.plant.flow(&x, &u, h, SUBSTEPS, &mut between) {
            Ok(next) => x = next,
            Err(_) => {
                // The integrator failed: nothing is known about the run, so it counts against the image.
                if out.goal_step.is_none() {
                    out.evaluator_error = true;
                }
                return out;
            }
        }
        z = z1;
        xi = maps.xi_at(&x, &z);
        check(&x, &xi, &mut out, &mut near);
        unsafe_margin(&xi, &mut out);
    }
    out
}

/// A plant state whose ξ (with the controller states at ζ0) lies on the boundary of trajectory `t`'s ball,
/// at [`super::boundary_radius`]: from the plant state x_c whose ξ-states are the ball's centre (the
/// others from `x`, a draw in Init), along a random direction of the plant's state space (of its
/// ξ-states only when `states_only`: no tilt for the quadrotor), by bisection on the ball's metric; `x`
/// itself when x_c is not inside the ball (a centre no plant state at rest reaches).
fn flat_boundary_start(
    image: &Image<'_>,
    maps: &FlMaps,
    ext0: &[f64],
    t: usize,
    mut x: Vec<f64>,
    states_only: bool,
    rng: &mut ChaCha8Rng,
) -> Vec<f64> {
    let n = image.n();
    let centre: Vec<f64> = (0..n).map(|i| image.centre(t, i) as f64).collect();
    let loc = image.location(t, 0);
    let radius = super::boundary_radius(image, t);
    let dist = |y: &[f64]| {
        let q = maps.xi_at(y, ext0);
        let e: Vec<f64> = (0..n).map(|i| q[i] - centre[i]).collect();
        let pe: f64 = (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| e[i] * image.P(loc, i, j) as f64 * e[j])
                    .sum::<f64>()
            })
            .sum();
        pe.max(0.0).sqrt()
    };
    let coords = maps.state_coords();
    for &(j, s) in &coords {
        x[s] = centre[j];
    }
    if !(dist(&x) < radius) {
        return x;
    }
    let dir: Vec<f64> = (0..x.len())
        .map(|s| {
            if states_only && !coords.iter().any(|&(_, c)| c == s) {
                0.0
            } else {
                rng.sample::<f64, _>(rand_distr::StandardNormal)
            }
        })
        .collect();
    let at = |a: f64| -> Vec<f64> { x.iter().zip(&dir).map(|(v, d)| v + a * d).collect() };
    let (mut lo, mut hi) = (0.0f64, 1e-6f64);
    while dist(&at(hi)) < radius && hi < 1e6 {
        (lo, hi) = (hi, 2.0 * hi);
    }
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if dist(&at(mid)) < radius {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    at(lo)
}

/// Whether the image carries the task's model maps, byte for byte, and the plant's dimensions: an image
/// made for another model (or without maps) is refused before any run.
pub fn check_maps(maps: &FlMaps, image: &Image<'_>) -> Result<(), String> {
    let Some(mm) = image.model_maps() else {
        return Err(
            "the image has no model maps section; a feedback-linearizable plant's image needs \
                    its maps x ↦ ξ and (x, w) ↦ u"
                .into(),
        );
    };
    if (mm.n_plant(), mm.m_plant()) != (maps.n_plant, maps.m_plant) {
        return Err(format!(
            "the image's model maps are for a plant with n = {}, m = {}; the spec's has n = {}, m = {}",
            mm.n_plant(),
            mm.m_plant(),
            maps.n_plant,
            maps.m_plant
        ));
    }
    if mm.coords_bytes() != maps.coords.bytes.as_slice() {
        return Err(
            "the image's coords program (x ↦ ξ) is not the one the spec's model gives".into(),
        );
    }
    if mm.input_map_bytes() != maps.input_map.bytes.as_slice() {
        return Err(
            "the image's input map program ((x, w) ↦ u) is not the one the spec's model gives"
                .into(),
        );
    }
    Ok(())
}

/// Monte Carlo over the certified cover of a feedback-linearizable task: `interior` plant states drawn
/// uniformly in Init whose ξ the evaluator's selection accepts (at most 50× as many draws), plus
/// `per_ball` states per ball whose ξ lies on the ball's boundary ([`super::boundary_radius`]) and whose
/// zero-dynamics states are drawn in Init. ξ is the spec's coords program's in f32 at the spec's ζ0, so
/// a start the evaluator then refuses (its own maps or ζ0 differ) counts in `refused`, a failure;
/// boundary points that selection does not accept are counted in `boundary_outside` and not run.
/// Deterministic for a seed; runs in parallel.
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
    // Whether the image's selection accepts a plant state's ξ as the spec's maps give it in f32 (its
    // coords program at its ζ0): such a start is covered by the certificate, and the evaluator must run
    // it (`VerifyReport::refused`).
    let ext0: Vec<f32> = maps
        .flat
        .as_ref()
        .map_or_else(Vec::new, |f| f.ext_init.iter().map(|&z| z as f32).collect());
    let coords = shared_types::program::Program::decode(&maps.coords.bytes).ok();
    let accepted = |x: &[f64]| -> bool {
        let Some(p) = &coords else { return false };
        let inputs: Vec<f32> = x
            .iter()
            .map(|&v| v as f32)
            .chain(ext0.iter().copied())
            .collect();
        let mut xi = vec![0.0f32; image.n()];
        let mut work = shared_types::program::Workspace::new();
        p.eval_with(&inputs, &mut xi, &mut work).is_ok()
            && xi.iter().all(|v| v.is_finite())
            && ctl.select_maps(&xi).is_some()
    };
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let mut draws = 0usize;
    while starts.len() < interior && draws < interior.saturating_mul(50) {
        draws += 1;
        let x = draw(&mut rng);
        if accepted(&x) {
            starts.push(x);
        }
    }
    let interior_runs = starts.len();
    let mut boundary: Vec<Vec<f64>> = Vec::new();
    let mut outside = 0usize;
    for t in 0..image.n_trajectories() {
        for b in 0..per_ball {
            let x = match &maps.flat {
                None => {
                    let xi = ball_boundary_point(image, Pis.as_ref(), t, &mut rng);
                    let mut x = draw(&mut rng);
                    for (j, &s) in maps.xi_states.iter().enumerate() {
                        x[s] = xi[j];
                    }
                    x
                }
                Some(fc) => {
                    // ξ is not a set of plant states: a plant state on the ball's boundary instead, with ζ0.
                    let x = draw(&mut rng);
                    flat_boundary_start(image, maps, &fc.ext_init, t, x, b % 2 == 1, &mut rng)
                }
            };
            if accepted(&x) {
                boundary.push(x);
            } else {
                outside += 1;
            }
        }
    }
    let boundary_runs = boundary.len();
    let all: Vec<Vec<f64>> = starts.into_iter().chain(boundary).collect();
    let outcomes: Vec<RunOutcome> = all
        .par_iter()
        .enumerate()
        .map(|(i, x0)| run_fl(task, maps, image, x0, i % MARGIN_EVERY == 0))
        .collect();
    let mut report = summarize(&outcomes, interior_runs, boundary_runs);
    report.boundary_outside = outside;
    Ok(report)
}
