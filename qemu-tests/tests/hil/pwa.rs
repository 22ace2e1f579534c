//! The PWA-feedback image (Ch. 6) on the target, for two covers: the double integrator
//! (examples/double-integrator.toml) and the setting of Example 6.4 (examples/planar-vehicle-pwa-4.toml, the
//! planar vehicle of Example 4.8). Each controller is learned from its certified feedforward cover,
//! re-checked with `verify::pwa::recheck`, embedded in the firmware, and run on the emulated Cortex-M4F from
//! 50 initial states drawn uniformly in balls of the certified envelope F (half of them in the balls over
//! Init). Every run must get `Ok` at every step until it enters Goal, within T, stay out of Unsafe at the
//! samples, apply inputs inside the input set, and the firmware's inputs must equal the host evaluator's
//! bit for bit. Where the image carries a terminal law (the double integrator's; issue 17), each run goes
//! on to twice the horizon: every step `Ok`, every sample in Goal, every input in the input set.

#![allow(non_snake_case)]

use host_compiler::pwa::{learn_pwa, PwaSettings};
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use host_compiler::verify::Judge;
use qemu_tests::closed_loop::{exchange, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::qemu::Qemu;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::eval::Status;
use std::time::Duration;

const RUNS: usize = 50;

#[test]
fn pwa_controller_meets_the_spec_on_the_target_from_50_initial_states() {
    run(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/double-integrator.toml"
        ),
        "pwa_double_integrator",
        "double integrator",
    );
}

#[test]
fn pwa_controller_of_example_6_4_meets_the_spec_on_the_target_from_50_initial_states() {
    run(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/planar-vehicle-pwa-4.toml"
        ),
        "pwa_example_6_4",
        "Example 6.4",
    );
}

fn run(spec: &str, tag: &str, label: &str) {
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let opts = SynthOptions {
        verify_interior: 500,
        verify_per_ball: 4,
        progress: false,
        ..SynthOptions::default()
    };
    let task = Task::new(problem).expect("the example is a task");
    let problem = &task.problem;
    let s = synthesize(&task, &opts).expect("synthesis succeeds");
    let pwa = learn_pwa(&task, &s, &PwaSettings::default()).expect("PWA learning succeeds");
    let image = shared_types::image::decode(&pwa.image).expect("the image decodes");
    let judge = Judge::new(&task);
    let (goal, unsafe_set, input) = (judge.goal(), judge.unsafe_set(), judge.input());
    let rc = host_compiler::verify::pwa::recheck(&judge, &image).expect("recheck runs");
    assert_eq!(
        rc.failures, 0,
        "the image's certificate must recheck: {rc:?}"
    );
    let path = firmware::write_image(tag, &pwa.image).expect("image written");
    let elf = firmware::build(
        tag,
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    // Starts: uniform in a uniformly chosen ball of F; the first half in balls centred at some x̃_i(0).
    let n = image.n();
    let P = faer::Mat::from_fn(n, n, |i, j| image.P(0, i, j) as f64);
    let Pis = host_compiler::linalg::sym_fn(P.as_ref(), |l| 1.0 / l.sqrt()).expect("P symmetric");
    let nb = image.n_balls();
    let centre =
        |b: usize| -> Vec<f64> { (0..n).map(|i| image.ball_centre(b, i) as f64).collect() };
    let init_balls: Vec<usize> = (0..nb)
        .filter(|&b| {
            let c = centre(b);
            s.trajectories.iter().any(|t| {
                t.nominal.x[0]
                    .iter()
                    .zip(&c)
                    .all(|(a, b)| (*a as f32) as f64 == *b)
            })
        })
        .collect();
    assert!(!init_balls.is_empty());
    let mut rng = ChaCha8Rng::seed_from_u64(problem.seed ^ 0x6a4);
    let steps = problem.horizon_steps();
    let proved = rc
        .liveness
        .max_steps_to_goal
        .expect("a recheck without failures proves a steps-to-Goal bound");
    let mut worst_cost = 0u32;
    let mut longest = 0usize;
    let terminal = image.terminal_law().is_some();
    let mut handed_over = 0usize;
    for run in 0..RUNS {
        let b = if run < RUNS / 2 {
            init_balls[rng.random_range(0..init_balls.len())]
        } else {
            rng.random_range(0..nb)
        };
        let x0 = host_compiler::verify::pwa::draw_in_ball(
            &mut rng,
            &Pis,
            &centre(b),
            (image.ball_threshold(b) as f64).sqrt() * (1.0 - 1e-6),
        );
        let mut q = Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(image);
        let mut x = x0.clone();
        let mut reached = None;
        let last = if terminal { 2 * steps } else { steps };
        for k in 0..=last {
            assert!(
                !unsafe_set.as_ref().is_some_and(|u| u.contains(&x)),
                "run {run} from {x0:?}: in Unsafe at step {k}"
            );
            if reached.is_none() && goal.contains(&x) {
                reached = Some(k);
                if !terminal {
                    break;
                }
            } else if reached.is_some() {
                assert!(
                    goal.contains(&x),
                    "run {run} from {x0:?}: left Goal at step {k} ({x:?}) under the terminal law"
                );
            }
            if k == last || (reached.is_none() && k == steps) {
                break;
            }
            let reply = exchange(&mut q, k as u32, &x, |xf| host.step(xf))
                .unwrap_or_else(|e| panic!("run {run}: {e}"));
            assert_eq!(
                reply.status,
                Status::Ok,
                "run {run} from {x0:?}: step {k} at {x:?} not Ok"
            );
            handed_over += usize::from(reached.is_some() && host.in_terminal_phase());
            worst_cost = worst_cost.max(reply.cost);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            let slack = host_compiler::verify::input_slack(input, &u);
            assert!(
                slack >= 0.0,
                "run {run}: u = {u:?} outside the input set at step {k}"
            );
            x = task.plant.step(0, &x, &u);
        }
        let k = reached
            .unwrap_or_else(|| panic!("run {run} from {x0:?} never reached Goal; ends at {x:?}"));
        longest = longest.max(k);
        // The recheck proved a bound on the steps to Goal from the bytes; the firmware must honour it.
        assert!(
            k <= proved,
            "run {run} from {x0:?}: Goal after {k} steps, beyond the proved {proved}"
        );
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {run}: firmware exit");
    }
    if terminal {
        assert!(handed_over > 0, "no step ran under the terminal law");
    }
    println!(
        "HIL PWA ({label}): {RUNS} runs met the spec (Goal within {longest} ≤ {proved} proved ≤ {steps} steps; terminal law: {terminal}, {handed_over} steps after Goal under it, in Goal to {} steps); {} partitions, tree depth {}, image {} bytes, worst step cost {worst_cost} instructions",
        if terminal { 2 * steps } else { steps },
        pwa.stats.partitions,
        pwa.stats.depth,
        pwa.image.len()
    );
}
