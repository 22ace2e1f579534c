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

/// Forced switching on the target (§4.2.1): the cart example's run switches from `forward` to
/// `backward` by its table. The firmware's reply carries the location of its row, and the host plant
/// takes the forced edge when that location changes (identity reset, guard the whole space). 50 initial
/// states in the run's ball; every run switches once at the sample the image says, reaches Goal within
/// T, never reaches the wall (at every sample and 8 sub-samples), applies only |u| ≤ 0.5, and the
/// firmware's inputs and locations equal the host evaluator's bit for bit.
#[test]
fn hybrid_forced_cart_meets_the_spec_on_the_target_from_50_initial_states() {
    use host_compiler::model::hybrid::EdgeKind;
    use host_compiler::synth::hybrid::forced::plan_forced;
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-forced-cart.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let task = HybridTask::new(problem).expect("the example is a hybrid task");
    let run = plan_forced(&task, &[0.0, 0.0]).expect("a run from Init's centre");
    assert!(run.certificate.is_certified(), "{:?}", run.certificate);
    assert_eq!(run.locations.len(), 2, "the run switches once");
    let switch_at = run.nominals[0].steps();
    let bytes = image(&task, std::slice::from_ref(&run)).expect("image");
    let path = firmware::write_image("hybrid_forced_cart", &bytes).expect("image written");
    let elf = firmware::build(
        "hybrid_forced_cart",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let img = shared_types::image::decode(&bytes).expect("the image decodes");
    let fine = task
        .plant
        .resampled(task.plant.period() / SUBSTEPS as f64)
        .expect("the automaton at a finer period");
    let goal = &task.property.goal;
    let unsafe_set = task.property.unsafe_region().expect("Unsafe");
    let starts = ball_starts(
        &task,
        &run,
        RUNS / 2,
        RUNS - RUNS / 2,
        task.problem.seed ^ 0x420,
    );
    let mut latest_goal = 0usize;
    for (r, x0) in starts.iter().enumerate() {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(img);
        let (mut x, mut loc) = (x0.clone(), task.initial);
        let mut switched = Vec::new();
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
            assert_eq!(
                reply.location,
                host.location(),
                "run {r}: step {k}'s location"
            );
            let want = reply.location as usize;
            if want != loc {
                let edge = task
                    .plant
                    .edges()
                    .iter()
                    .find(|e| e.from == loc && e.to == want && e.kind == EdgeKind::Forced)
                    .unwrap_or_else(|| panic!("run {r}: no forced edge {loc} → {want}"));
                assert!(
                    edge.guard.contains(&x),
                    "run {r}: step {k} outside the guard"
                );
                x = edge.reset.apply(&x);
                loc = want;
                switched.push(k);
            }
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            assert!(
                u[0].abs() <= 0.5,
                "run {r}: |u| = {} > 0.5 at step {k}",
                u[0]
            );
            for _ in 0..SUBSTEPS {
                let step = fine
                    .flow(loc, &x, &u)
                    .unwrap_or_else(|e| panic!("run {r}: {e}"));
                assert!(
                    step.events.is_empty(),
                    "run {r}: an event the automaton took itself"
                );
                x = step.x;
                assert!(
                    !unsafe_set.contains(&x),
                    "run {r}: in Unsafe after step {k}: {x:?}"
                );
            }
        }
        let k = reached
            .unwrap_or_else(|| panic!("run {r} from {x0:?} never reached Goal; ends at {x:?}"));
        latest_goal = latest_goal.max(k);
        assert_eq!(switched, vec![switch_at], "run {r} from {x0:?}: switches");
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {r}: firmware exit");
    }
    println!(
        "HIL forced cart: {RUNS} runs switched at sample {switch_at} and met the spec (Goal by sample {latest_goal} of {}); δ = {:.4}, image {} bytes",
        task.steps,
        run.delta(),
        bytes.len()
    );
}
