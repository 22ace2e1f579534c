//! Feedforward images (Alg 2) on the target, as `host-compiler synth` makes them from two examples:
//! Example 4.8's planar vehicle (`examples/planar-vehicle.toml`) and the SCOTS maze with a point mass
//! (`examples/maze-scots-pointmass.toml`, whose nominal trajectories come from the global route search,
//! issue 48). Each runs on the emulated Cortex-M4F from 50 initial states drawn uniformly in Init. Every
//! run must get `Ok` at every step until it enters Goal, reach Goal within T, never enter Unsafe (checked
//! at every sample and at sub-samples of each period of the continuous plant), and apply only inputs in
//! the input set, with the firmware's inputs equal to the host evaluator's bit for bit. Where the image
//! carries a terminal law, each run goes on to twice the horizon and must stay in Goal under it.

#![allow(non_snake_case)]

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
fn planar_vehicle_meets_the_spec_on_the_target_from_50_initial_states() {
    on_target(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/planar-vehicle.toml"
        ),
        "planar_vehicle",
        0x4111,
        true,
    );
}

#[test]
fn maze_scots_pointmass_meets_the_spec_on_the_target_from_50_initial_states() {
    on_target(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/maze-scots-pointmass.toml"
        ),
        "maze_scots_pointmass",
        0x3a2e,
        // Its fifteen walls and the outside of the field compile to 39 monitor nodes, past the
        // firmware's 32 (`synth --monitor` refuses it so): no image with its monitor.
        false,
    );
}

/// Synthesise `spec`, embed its image in the firmware (named `tag`) and run it from [`RUNS`] starts
/// drawn uniformly in Init (seeded by the spec's seed and `salt`). With `monitor`, also write the image
/// with the task's monitor attached (`<tag>_monitor`).
fn on_target(spec: &str, tag: &str, salt: u64, monitor: bool) {
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let opts = SynthOptions {
        verify_interior: 1_000,
        verify_per_ball: 4,
        progress: false,
        ..SynthOptions::default()
    };
    let task = Task::new(problem).expect("the example is a task");
    let problem = &task.problem;
    let s = synthesize(&task, &opts).expect("synthesis succeeds");
    assert_eq!(s.verify.violations, 0);
    let path = firmware::write_image(tag, &s.image).expect("image written");
    // The same image with the task's monitor (what `synth --monitor` writes), for the boards' budgets
    // (`cargo xtask budgets` builds the longest image of each configuration).
    if monitor {
        let program =
            host_compiler::monitor::Program::for_problem(problem).expect("a monitorable task");
        let with_monitor = host_compiler::monitor::attach(&s.image, &program.encode())
            .expect("the monitor attaches");
        firmware::write_image(&format!("{tag}_monitor"), &with_monitor).expect("image written");
    }
    let elf = firmware::build(
        tag,
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let image = shared_types::image::decode(&s.image).expect("the image decodes");
    let judge = Judge::new(&task);
    let (goal, unsafe_set, input) = (judge.goal(), judge.unsafe_set(), judge.input());
    let plant = &*task.plant;
    let steps = task.steps;
    let terminal = image.terminal_law().is_some();
    let last = if terminal { 2 * steps } else { steps };
    let mut rng = ChaCha8Rng::seed_from_u64(problem.seed ^ salt);
    let mut worst_cost = 0u32;
    let mut longest = 0usize;
    for run in 0..RUNS {
        let x0: Vec<f64> = problem
            .init
            .lo
            .iter()
            .zip(&problem.init.hi)
            .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
            .collect();
        let mut q = Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(image);
        let mut x = x0.clone();
        let mut reached = None;
        for k in 0..=last {
            assert!(
                !unsafe_set.as_ref().is_some_and(|u| u.contains(&x)),
                "run {run} from {x0:?}: in Unsafe at step {k}: {x:?}"
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
            worst_cost = worst_cost.max(reply.cost);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            let slack = host_compiler::verify::input_slack(input, &u);
            assert!(
                slack >= 0.0,
                "run {run}: u = {u:?} outside the input set at step {k}"
            );
            let mut between = 0;
            plant.between_samples(0, &x, &u, &mut |xs| {
                between += 1;
                assert!(
                    !unsafe_set.as_ref().is_some_and(|u| u.contains(xs)),
                    "run {run}: in Unsafe between samples after step {k}"
                );
            });
            assert!(between > 0, "a continuous plant is checked between samples");
            x = plant.step(0, &x, &u);
        }
        let k = reached
            .unwrap_or_else(|| panic!("run {run} from {x0:?} never reached Goal; ends at {x:?}"));
        assert!(k as f64 * problem.plant.period <= problem.horizon + 1e-9);
        longest = longest.max(k);
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {run}: firmware exit");
    }
    println!(
        "HIL {tag}: {RUNS} runs met the spec (Goal within {longest} of {steps} steps; terminal law: {terminal}); {} trajectories, image {} bytes, worst step cost {worst_cost} instructions",
        s.trajectories.len(),
        s.image.len()
    );
}
