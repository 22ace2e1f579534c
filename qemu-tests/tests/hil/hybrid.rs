//! Example 4.25 on the target (§4.2.2): a run across the internal edge x₁ = 0, certified by
//! `certify::internal`, in an image with a guard exit; the emulated Cortex-M4F runs it from 50 initial
//! states in the run's ball, against the hybrid plant simulated on the host with its exact flow (events
//! found between samples, [`host_compiler::model::hybrid::Hybrid::flow`]). Every run must switch once,
//! reach Goal within T, never enter Unsafe (at every sample and at 8 sub-samples of each period) and
//! apply only inputs in [−3, 3], with the firmware's inputs equal to the host evaluator's bit for bit.

use host_compiler::synth::hybrid::{ball_starts, image, plan_run, HybridTask};
use qemu_tests::closed_loop::{exchange, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::qemu::Qemu;
use shared_types::eval::Status;
use std::time::Duration;

const RUNS: usize = 50;
const SUBSTEPS: usize = 8;

#[test]
fn hybrid_example_4_25_meets_the_spec_on_the_target_from_50_initial_states() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-internal-4-25.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let task = HybridTask::new(problem).expect("the example is a hybrid task");
    let run = plan_run(&task, &[-5.0, 1.0, 2.0]).expect("a run from Example 4.25's x0");
    assert!(run.certificate.is_certified(), "{:?}", run.certificate);
    let bytes = image(&task, std::slice::from_ref(&run)).expect("image");
    let path = firmware::write_image("hybrid_4_25", &bytes).expect("image written");
    let elf = firmware::build(
        "hybrid_4_25",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let img = shared_types::image::decode(&bytes).expect("the image decodes");
    let h = task.plant.period();
    let fine = task
        .plant
        .resampled(h / SUBSTEPS as f64)
        .expect("the automaton at a finer period");
    let goal = &task.property.goal;
    let unsafe_set = task.property.unsafe_region().expect("Unsafe");
    let starts = ball_starts(
        &task,
        &run,
        RUNS / 2,
        RUNS - RUNS / 2,
        task.problem.seed ^ 0x425,
    );
    let mut worst_cost = 0u32;
    let mut latest_goal = 0usize;
    for (r, x0) in starts.iter().enumerate() {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(img);
        let (mut x, mut loc) = (x0.clone(), task.initial);
        let mut events = 0usize;
        let mut reached = None;
        for k in 0..=task.steps {
            if goal.contains(&x) {
                reached = Some(k);
                break;
            }
            if k == task.steps {
                break;
            }
            let reply = exchange(&mut q, k as u32, &x, |xf| host.step(xf))
                .unwrap_or_else(|e| panic!("run {r}: {e}"));
            assert_eq!(
                reply.status,
                Status::Ok,
                "run {r} from {x0:?}: step {k} not Ok"
            );
            worst_cost = worst_cost.max(reply.cost);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            assert!(u[0].abs() <= 3.0, "run {r}: |u| = {} > 3 at step {k}", u[0]);
            for _ in 0..SUBSTEPS {
                let step = fine
                    .flow(loc, &x, &u)
                    .unwrap_or_else(|e| panic!("run {r}: {e}"));
                events += step.events.len();
                x = step.x;
                loc = step.loc;
                assert!(
                    !unsafe_set.contains(&x),
                    "run {r}: in Unsafe after step {k}: {x:?}"
                );
            }
        }
        let k = reached
            .unwrap_or_else(|| panic!("run {r} from {x0:?} never reached Goal; ends at {x:?}"));
        latest_goal = latest_goal.max(k);
        assert_eq!(events, 1, "run {r} from {x0:?}: {events} events");
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {r}: firmware exit");
    }
    println!(
        "HIL hybrid 4.25: {RUNS} runs switched once and met the spec (Goal by sample {latest_goal} of {}); δ = {:.4}, image {} bytes, worst step cost {worst_cost} instructions",
        task.steps,
        run.delta(),
        bytes.len()
    );
}
