//! Hybrid runs on the target. Example 4.25 (§4.2.2): a run across the internal edge x₁ = 0, certified
//! by `certify::internal`, in an image with a guard exit. The forced cart (§4.2.1): a run that switches
//! from `forward` to `backward` by its table, certified by `certify::forced`, and the same cart with an
//! MTL task (Def 4.18, `certify::forced::certify_forced_formula`); Example 4.20's eight locations and
//! three discs the same way. The emulated Cortex-M4F
//! runs each from 50 initial states in the run's ball, against the hybrid plant simulated on the host
//! with its exact flow (events found between samples, [`host_compiler::model::hybrid::Hybrid::flow`]).
//! Every run must switch where its run does, reach Goal within T, never enter Unsafe (at every sample and at 8
//! sub-samples of each period) and apply only inputs within the bound, with the firmware's inputs (and
//! the location its reply carries) equal to the host evaluator's bit for bit.

use host_compiler::synth::hybrid::forced::plan_forced;
use host_compiler::synth::hybrid::{ball_starts, image, plan_run, HybridRun, HybridTask};
use qemu_tests::closed_loop::{exchange, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::qemu::Qemu;
use shared_types::eval::Status;
use shared_types::protocol::Reply;
use std::time::Duration;

const RUNS: usize = 50;
const SUBSTEPS: usize = 8;

/// What one run on the target did.
struct TargetRun {
    /// The sample at which it was first in Goal.
    goal: usize,
    /// Events the automaton took by itself (internal edges).
    events: usize,
    /// The worst step cost the firmware reported.
    cost: u32,
}

/// The example's task, the run `plan` makes, its image and a firmware built with it (as `tag`).
fn setup(
    example: &str,
    tag: &str,
    plan: impl FnOnce(&HybridTask) -> HybridRun,
) -> (HybridTask, HybridRun, Vec<u8>, std::path::PathBuf) {
    let spec = format!("{}/../examples/{example}", env!("CARGO_MANIFEST_DIR"));
    let problem = host_compiler::spec::load(&spec).expect("the example parses");
    let task = HybridTask::new(problem).expect("the example is a hybrid task");
    let run = plan(&task);
    assert!(run.certificate.is_certified(), "{:?}", run.certificate);
    let bytes = image(&task, std::slice::from_ref(&run)).expect("image");
    let path = firmware::write_image(tag, &bytes).expect("image written");
    let elf = firmware::build(
        tag,
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    (task, run, bytes, elf)
}

/// Runs the image on the target from each of 50 starts in the run's ball (seeded by `salt`): per
/// sample Goal first (for a reach-avoid task; an MTL task's runs go the whole horizon and are judged by
/// the formula as written at the end, at the samples and the sub-samples), then the exchange (status Ok, inputs bit for bit with the host evaluator, the
/// reply's location the host evaluator's), `switch` with the reply (a forced switch it applies to the
/// state and location), |u| ≤ `u_max`, and the exact flow over [`SUBSTEPS`] sub-periods with Unsafe
/// checked. `switch` gets the run index and sample.
fn run_on_target(
    task: &HybridTask,
    run: &HybridRun,
    bytes: &[u8],
    elf: &std::path::Path,
    salt: u64,
    u_max: f64,
    mut switch: impl FnMut(usize, usize, &Reply, &mut Vec<f64>, &mut usize),
) -> Vec<TargetRun> {
    let img = shared_types::image::decode(bytes).expect("the image decodes");
    let fine = task
        .plant
        .resampled(task.plant.period() / SUBSTEPS as f64)
        .expect("the automaton at a finer period");
    let goal = &task.property.goal;
    let unsafe_set = task.property.unsafe_region().expect("Unsafe");
    let formula = task.formula.as_ref();
    let judges = formula.map(|tt| {
        host_compiler::verify::temporal::Judges::new(tt, x0_dim(task)).expect("the formula's sets")
    });
    let starts = ball_starts(
        task,
        run,
        RUNS / 2,
        RUNS - RUNS / 2,
        task.problem.seed ^ salt,
    );
    let mut out = Vec::with_capacity(starts.len());
    for (r, x0) in starts.iter().enumerate() {
        let mut q = Qemu::launch(elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(img);
        let (mut x, mut loc) = (x0.clone(), task.initial);
        let (mut events, mut cost, mut reached) = (0usize, 0u32, None);
        let mut record = host_compiler::verify::temporal::RunRecord::new(x0, task.plant.period());
        for k in 0..=task.steps {
            if formula.is_none() && goal.contains(&x) {
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
            cost = cost.max(reply.cost);
            switch(r, k, &reply, &mut x, &mut loc);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            assert!(
                u.iter().all(|v| v.abs() <= u_max),
                "run {r}: u = {u:?} beyond {u_max} at step {k}"
            );
            for sub in 0..SUBSTEPS {
                let step = fine
                    .flow(loc, &x, &u)
                    .unwrap_or_else(|e| panic!("run {r}: {e}"));
                events += step.events.len();
                x = step.x;
                loc = step.loc;
                if formula.is_some() {
                    if sub + 1 < SUBSTEPS {
                        record.push_between((sub + 1) as f64 * fine.period(), &x);
                    } else {
                        record.push_sample(&x);
                    }
                    continue;
                }
                assert!(
                    !unsafe_set.contains(&x),
                    "run {r}: in Unsafe after step {k}: {x:?}"
                );
            }
        }
        let goal = match (formula, &judges) {
            (Some(tt), Some(j)) => {
                let (holds, holds_fine, _) =
                    j.judge(tt, &record, false).expect("the run is judged");
                assert!(
                    holds && holds_fine,
                    "run {r} from {x0:?}: the formula is {holds} at the samples and {holds_fine} sampled finer"
                );
                task.steps
            }
            _ => reached
                .unwrap_or_else(|| panic!("run {r} from {x0:?} never reached Goal; ends at {x:?}")),
        };
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {r}: firmware exit");
        out.push(TargetRun { goal, events, cost });
    }
    out
}

/// The state dimension of the task's automaton.
fn x0_dim(task: &HybridTask) -> usize {
    host_compiler::model::Plant::n(&task.plant)
}

#[test]
fn hybrid_example_4_25_meets_the_spec_on_the_target_from_50_initial_states() {
    let (task, run, bytes, elf) = setup("hybrid-internal-4-25.toml", "hybrid_4_25", |task| {
        plan_run(task, &[-5.0, 1.0, 2.0]).expect("a run from Example 4.25's x0")
    });
    // The plant switches by itself: the firmware's location is not a discrete input here.
    let runs = run_on_target(&task, &run, &bytes, &elf, 0x425, 3.0, |_, _, _, _, _| {});
    for (r, t) in runs.iter().enumerate() {
        assert_eq!(t.events, 1, "run {r}: {} events", t.events);
    }
    println!(
        "HIL hybrid 4.25: {RUNS} runs switched once and met the spec (Goal by sample {} of {}); δ = {:.4}, image {} bytes, worst step cost {} instructions",
        runs.iter().map(|t| t.goal).max().unwrap_or(0),
        task.steps,
        run.delta(),
        bytes.len(),
        runs.iter().map(|t| t.cost).max().unwrap_or(0)
    );
}

/// Forced switching on the target (§4.2.1): the firmware's reply carries the location of its row, and
/// the host plant takes the forced edge when that location changes (identity reset, guard the whole
/// space). Every run switches exactly once, at the sample the image says, and the automaton takes no
/// event by itself.
#[test]
fn hybrid_forced_cart_meets_the_spec_on_the_target_from_50_initial_states() {
    forced_on_target(
        "hybrid-forced-cart.toml",
        "hybrid_forced_cart",
        0x420,
        &[0.0, 0.0],
        0.5,
    );
}

/// The same cart with its task an MTL formula (Def 4.18): every run is judged by the formula as
/// written over the whole horizon, at the samples and the sub-samples.
#[test]
fn hybrid_forced_cart_mtl_meets_the_formula_on_the_target_from_50_initial_states() {
    forced_on_target(
        "hybrid-forced-cart-mtl.toml",
        "hybrid_forced_cart_mtl",
        0x418,
        &[0.0, 0.0],
        0.5,
    );
}

/// Example 4.20 (8 locations, forced switching, three discs to avoid): a run planned from Init's centre,
/// its segments certified with the drift against each disc between samples, run on the target from 50
/// starts in its ball with |u_i| ≤ 2 (the input ball's radius).
#[test]
fn hybrid_example_4_20_meets_the_spec_on_the_target_from_50_initial_states() {
    forced_on_target(
        "hybrid-forced-4-20.toml",
        "hybrid_4_20",
        0x4020,
        &[3.5, -6.0, 0.0, 0.0],
        2.0,
    );
}

/// A forced-switching example planned from `x0` and run on the target from 50 starts, with inputs
/// within `u_max` componentwise. Every run switches exactly where the planned run's segments end.
fn forced_on_target(example: &str, tag: &str, salt: u64, x0: &[f64], u_max: f64) {
    let (task, run, bytes, elf) = setup(example, tag, |task| {
        plan_forced(task, x0).unwrap_or_else(|why| panic!("no run from {x0:?}: {why}"))
    });
    let switch_at: Vec<usize> = run
        .nominals
        .iter()
        .scan(0, |k, nom| {
            *k += nom.steps();
            Some(*k)
        })
        .take(run.nominals.len() - 1)
        .collect();
    let mut switched: Vec<Vec<usize>> = vec![Vec::new(); RUNS];
    let runs = run_on_target(
        &task,
        &run,
        &bytes,
        &elf,
        salt,
        u_max,
        |r, k, reply, x, loc| {
            let want = reply.location as usize;
            if want == *loc {
                return;
            }
            let edge = task
                .plant
                .forced_edge(*loc, want)
                .unwrap_or_else(|| panic!("run {r}: no forced edge {loc} → {want}"));
            assert!(
                edge.guard.contains(x),
                "run {r}: step {k} outside the guard"
            );
            *x = edge.reset.apply(x);
            *loc = want;
            switched[r].push(k);
        },
    );
    for (r, t) in runs.iter().enumerate() {
        assert_eq!(
            t.events, 0,
            "run {r}: an event the automaton took by itself"
        );
        // A reach-avoid run stops in Goal, possibly before a later switch of its table.
        let expected: Vec<usize> = switch_at.iter().copied().filter(|&k| k < t.goal).collect();
        assert_eq!(switched[r], expected, "run {r}: switches");
    }
    let names: Vec<&str> = run
        .locations
        .iter()
        .map(|&l| task.plant.modes()[l].name.as_str())
        .collect();
    println!(
        "HIL {tag}: {RUNS} runs through {} switched at samples {switch_at:?} and met the task ({}); δ = {:.4}, image {} bytes, worst step cost {} instructions",
        names.join(" → "),
        if task.formula.is_some() {
            format!("the formula over all {} samples", task.steps)
        } else {
            format!(
                "Goal by sample {} of {}",
                runs.iter().map(|t| t.goal).max().unwrap_or(0),
                task.steps
            )
        },
        run.delta(),
        bytes.len(),
        runs.iter().map(|t| t.cost).max().unwrap_or(0)
    );
}
