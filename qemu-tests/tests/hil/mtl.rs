//! An MTL task on the target (Problem 2.28, Theorem 4.2 for the sampled f32 loop): the waypoint task of
//! `examples/planar-vehicle-waypoints.toml` (avoid the obstacle; W1, then W2, then Goal, within 5 s). One
//! ball certified for the formula from the centre of Init, in a feedforward image; the emulated
//! Cortex-M4F runs it from 50 initial states of the ball (25 on its boundary, 25 inside) against the plant
//! simulated on the host. Every run must satisfy the formula, judged on its samples and on the run sampled
//! 8 times per period, apply only inputs in the input set, and get from the firmware the host evaluator's
//! inputs bit for bit.

use host_compiler::geometry::Metric;
use host_compiler::linalg::PdRoots;
use host_compiler::property::TemporalTask;
use host_compiler::synth::temporal::single_ball;
use host_compiler::task::Task;
use host_compiler::verify::temporal::{formula_value, RunRecord};
use qemu_tests::closed_loop::{exchange, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::qemu::Qemu;
use rand::{Rng, SeedableRng};
use shared_types::eval::Status;
use std::time::Duration;

const RUNS: usize = 50;

#[test]
fn mtl_waypoints_hold_on_the_target_from_50_initial_states() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle-waypoints.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let tt = TemporalTask::from_problem(&problem).expect("the example has a formula");
    let task = Task::new(problem).expect("a one-location task");
    let centre: Vec<f64> = task
        .init()
        .lo
        .iter()
        .zip(&task.init().hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect();
    let (ball, bytes) = single_ball(&task, &tt, &centre).unwrap_or_else(|e| panic!("{e}"));
    assert!(ball.certificate.is_certified(), "{:?}", ball.certificate);
    let path = firmware::write_image("mtl_waypoints", &bytes).expect("image written");
    let elf = firmware::build(
        "mtl_waypoints",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let img = shared_types::image::decode(&bytes).expect("the image decodes");
    let n = task.plant.n();
    let p_img = faer::Mat::from_fn(n, n, |i, j| img.P(0, i, j) as f64);
    let roots = PdRoots::new(p_img.as_ref()).expect("the stored metric");
    let c = &ball.nominal.x[0];
    let d = ball.certificate.delta_stored as f64 * (1.0 - 1e-6);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(task.problem.seed ^ 0x2_31);
    let starts: Vec<Vec<f64>> = (0..RUNS)
        .map(|r| {
            let radius = if r % 2 == 0 {
                d
            } else {
                d * rng.random::<f64>().powf(1.0 / n as f64)
            };
            host_compiler::verify::hybrid::point_on_sphere(&mut rng, &roots, c, radius)
        })
        .collect();
    let sets = tt.sets(&Metric::euclidean(n)).expect("the sets");
    let h = task.plant.period();
    let mut worst_cost = 0u32;
    let mut least = f64::INFINITY;
    for (r, x0) in starts.iter().enumerate() {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(img);
        let mut x = x0.clone();
        let mut rec = RunRecord::new(x0, h);
        for k in 0..task.steps {
            let reply = exchange(&mut q, k as u32, &x, |xf| host.step(xf))
                .unwrap_or_else(|e| panic!("run {r}: {e}"));
            assert_eq!(reply.status, Status::Ok, "run {r} from {x0:?}: step {k}");
            worst_cost = worst_cost.max(reply.cost);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            assert!(
                host_compiler::verify::input_slack(&task.property.input, &u) >= 0.0,
                "run {r}: input {u:?} outside the input set at step {k}"
            );
            x = rec.step(&*task.plant, &x, &u);
        }
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {r}: firmware exit");
        let (tc, tf) = rec.traces().expect("the run's traces");
        let rho = formula_value(&tt, &sets, &tc).expect("the formula at the samples");
        let rho_fine = formula_value(&tt, &sets, &tf).expect("the formula sampled finer");
        assert!(
            rho > 0.0 && rho_fine > 0.0,
            "run {r} from {x0:?}: robustness {rho} at the samples, {rho_fine} sampled finer"
        );
        least = least.min(rho).min(rho_fine);
    }
    println!(
        "HIL MTL waypoints: {RUNS} runs satisfied `{}` (least robustness {least:.4e}, Euclidean); δ = {:.4}, image {} bytes, worst step cost {worst_cost} instructions",
        tt.written.source(),
        ball.certificate.delta,
        bytes.len()
    );
}
