//! Example 4.8 on the target: the planar-vehicle image that `host-compiler synth` makes runs on the
//! emulated Cortex-M4F from 50 initial states drawn uniformly in Init. Every run must reach Goal within T,
//! never enter Unsafe (checked at every sample and at 8 sub-samples of each period of the continuous plant),
//! and apply only inputs with ‖u‖₂ ≤ 1 — with the firmware's inputs equal to the host evaluator's bit for bit.

#![allow(non_snake_case)]

use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
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
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    );
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
    let path = firmware::write_image("planar_vehicle", &s.image).expect("image written");
    let elf = firmware::build(
        "planar_vehicle",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let image = shared_types::image::decode(&s.image).expect("the image decodes");
    let plant = &*task.plant;
    let goal = &task.property.goal;
    let unsafe_set = task
        .property
        .unsafe_region()
        .expect("the example has an obstacle");
    let steps = task.steps;
    let mut rng = ChaCha8Rng::seed_from_u64(problem.seed ^ 0x4111);
    let mut worst_cost = 0u32;
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
        for k in 0..=steps {
            assert!(
                !unsafe_set.contains(&x),
                "run {run} from {x0:?}: in Unsafe at step {k}: {x:?}"
            );
            if reached.is_none() && goal.contains(&x) {
                reached = Some(k);
            }
            if k == steps {
                break;
            }
            let reply = exchange(&mut q, k as u32, &x, |xf| host.step(xf))
                .unwrap_or_else(|e| panic!("run {run}: {e}"));
            assert_eq!(
                reply.status,
                Status::Ok,
                "run {run} from {x0:?}: step {k} not Ok"
            );
            worst_cost = worst_cost.max(reply.cost);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            let un = u.iter().map(|a| a * a).sum::<f64>().sqrt();
            assert!(un <= 1.0, "run {run}: ‖u‖ = {un} > 1 at step {k}");
            let mut between = 0;
            plant.between_samples(0, &x, &u, &mut |xs| {
                between += 1;
                assert!(
                    !unsafe_set.contains(xs),
                    "run {run}: in Unsafe between samples after step {k}"
                );
            });
            assert!(between > 0, "a continuous plant is checked between samples");
            x = plant.step(0, &x, &u);
        }
        let k = reached
            .unwrap_or_else(|| panic!("run {run} from {x0:?} never reached Goal; ends at {x:?}"));
        assert!(k as f64 * problem.plant.period <= problem.horizon + 1e-9);
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {run}: firmware exit");
    }
    println!(
        "HIL planar vehicle: {RUNS} runs of {steps} steps met the spec; {} trajectories, image {} bytes, worst step cost {worst_cost} instructions",
        s.trajectories.len(),
        s.image.len()
    );
}
