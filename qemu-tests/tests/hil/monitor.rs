//! The task's monitor on the target (issue 46): the double integrator's image (`examples/double-integrator.toml`,
//! reach-avoid, so the monitor's formula is `!Unsafe U[0,T] Goal`) with the monitor section, on the
//! emulated Cortex-M4F. On the model plant, 30 runs from Init: the firmware's bounds and verdict equal
//! the host's reference (`host_compiler::monitor::reference`) bit for bit at every sample, no run is ever
//! reported violated, and every run is satisfied by the horizon. On a plant perturbed past the
//! certificate's assumptions (its input gain tripled), the reports still equal the reference at every
//! sample, and every run whose task is violated (a sample in Unsafe, or Goal never reached by T) is
//! reported violated no later than that.

use host_compiler::monitor::{reference, Program};
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use qemu_tests::closed_loop::{exchange, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::plant::DiscretePlant;
use qemu_tests::qemu::Qemu;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::monitor::{MonitorProgram, Verdict};
use std::time::Duration;

const RUNS: usize = 30;

fn verdict(code: u8) -> Verdict {
    match code {
        1 => Verdict::Satisfied,
        2 => Verdict::Violated,
        3 => Verdict::Boundary,
        _ => Verdict::Pending,
    }
}

#[test]
fn the_monitor_on_the_target_equals_the_reference_and_flags_only_the_perturbed_plant() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let prog = Program::for_problem(&problem).expect("the example is monitorable");
    let body = prog.encode();
    let task = Task::new(problem.clone()).expect("a task");
    let opts = SynthOptions {
        verify_interior: 500,
        progress: false,
        ..SynthOptions::default()
    };
    let s = synthesize(&task, &opts).expect("synthesis succeeds");
    assert_eq!(s.verify.violations, 0);
    let bytes = host_compiler::monitor::attach(&s.image, &body).expect("the monitor attaches");
    let path = firmware::write_image("monitor_double_integrator", &bytes).expect("image written");
    let elf = firmware::build(
        "monitor_double_integrator",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let image = shared_types::image::decode(&bytes).expect("the image decodes");
    let section = MonitorProgram::decode(&body, 2).expect("the section decodes");
    let model = task.plant.as_ref();
    let dp = DiscretePlant::new(
        faer::Mat::from_fn(2, 2, |i, j| [[1.0, 0.1], [0.0, 1.0]][i][j]),
        faer::Mat::from_fn(2, 1, |i, _| 3.0 * [0.005, 0.1][i]),
        vec![0.0, 0.0],
        0.1,
    )
    .expect("the perturbed plant");
    let n_samples = prog.horizon; // samples 0..=N
    let (lo, hi) = (&problem.init.lo, &problem.init.hi);
    let mut rng = ChaCha8Rng::seed_from_u64(problem.seed ^ 0x46);
    let (mut worst_cost, mut violated_runs) = (0u32, 0usize);
    for perturbed in [false, true] {
        for run in 0..RUNS {
            let x0: Vec<f64> = lo
                .iter()
                .zip(hi)
                .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
                .collect();
            let mut q =
                Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
            let mut host = HostEvaluator::new(image);
            let (mut x, mut trace, mut got) = (x0.clone(), Vec::new(), Vec::new());
            for k in 0..=n_samples {
                let reply = exchange(&mut q, k as u32, &x, |xf| host.step(xf))
                    .unwrap_or_else(|e| panic!("run {run}: {e}"));
                let m = reply
                    .monitor
                    .unwrap_or_else(|| panic!("run {run}, step {k}: no monitor in the reply"));
                worst_cost = worst_cost.max(m.cost);
                trace.push(x.iter().map(|&v| v as f32).collect::<Vec<f32>>());
                got.push(m);
                let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
                x = if perturbed {
                    dp.step(&x, &u)
                } else {
                    model.step(0, &x, &u)
                };
            }
            let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(exit.code, Some(0), "run {run}: firmware exit");
            let want = reference::reports(&prog, &section, &trace);
            for (k, (m, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    m.lo == w.lo.to_bits() && m.hi == w.hi.to_bits() && verdict(m.verdict) == w.verdict,
                    "run {run} (perturbed: {perturbed}), step {k}: firmware ({}, {}, {:?}), reference {w:?}",
                    m.lo(),
                    m.hi(),
                    verdict(m.verdict)
                );
            }
            // When the task is actually violated: the first sample in Unsafe (v ≥ 1.5), or N if Goal
            // (0.95 ≤ p ≤ 1.05) is never reached before it.
            let in_goal = |x: &[f32]| (0.95..=1.05).contains(&x[0]);
            let first_goal = trace.iter().position(|x| in_goal(x));
            let first_unsafe = trace.iter().position(|x| x[1] >= 1.5);
            let violated_at = match (first_goal, first_unsafe) {
                (Some(g), Some(u)) if u < g => Some(u),
                (None, Some(u)) => Some(u),
                (None, None) => Some(n_samples),
                _ => None,
            };
            let flagged = got
                .iter()
                .position(|m| verdict(m.verdict) == Verdict::Violated);
            if perturbed {
                if let Some(at) = violated_at {
                    violated_runs += 1;
                    let f = flagged.unwrap_or_else(|| {
                        panic!("run {run}: violated at sample {at}, never reported")
                    });
                    assert!(f <= at, "run {run}: reported at {f}, violated at {at}");
                }
            } else {
                assert_eq!(
                    flagged, None,
                    "run {run}: a certified run reported violated"
                );
                assert_eq!(
                    violated_at, None,
                    "run {run}: the model run violates the task"
                );
                assert_eq!(
                    verdict(got[n_samples].verdict),
                    Verdict::Satisfied,
                    "run {run}: not satisfied by N"
                );
            }
        }
    }
    assert!(
        violated_runs >= RUNS / 2,
        "the perturbation violates the task in {violated_runs} of {RUNS} runs: too few to test the verdict"
    );
    println!(
        "HIL monitor: {RUNS} model runs satisfied, {violated_runs} of {RUNS} perturbed runs violated and reported; \
         the firmware's reports equal the reference at every sample; worst monitor update {worst_cost} instructions"
    );
}
