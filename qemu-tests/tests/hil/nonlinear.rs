//! A feedback-linearizable plant on the target (issue 13 item 7): the Example 4.9 image with model maps
//! (`qemu_tests::images::fl_4_9`: ξ = coords(x), u = input_map(x, w) = R(θ)w) runs on the emulated
//! Cortex-M4F against the plant's nonlinear equations integrated on the host with an adaptive
//! Dormand–Prince solver (`qemu_tests::nonlinear`). Five runs of 400 steps from Init's corners and
//! centre (`NonlinearImage::starts`, some with θ and θ̇ off zero): every reply is `Ok`,
//! its input equals the host evaluator's `step_plant` bit for bit, and each run ends near the goal.
//!
//! Then the certified image as `synth` makes it from `examples/fl-4-9.toml` (its maps derived by
//! `model::feedback_linearizable`), from 50 seeded initial states in Init: every run meets the spec on the
//! plant (Goal within T; Unsafe never entered and every input in ‖F‖ ≤ 2 before Goal; each run ends at
//! Goal), bit for bit with the host, and the worst step cost is printed. The same for the torque-driven pendulum
//! (`examples/fl-pendulum.toml`, a law that depends on ξ, bounded over its operating region), whose runs
//! must also stay inside that region. And the differentially flat planar quadrotor
//! (`examples/flat-quadrotor.toml`): the firmware keeps the thrust and its rate as states of its own, the
//! host evaluator keeps them in step, and each sample's ξ is the flat state q read with them (its
//! operating region, over q, is part of Unsafe).
//!
//! Last, an MTL task on a feedback-linearizable plant (issue #14; Theorem 4.2 on the model in ξ with the
//! mismatch D): the pendulum's swing-up profile (`examples/fl-pendulum-mtl.toml`), one ball certified for
//! the formula from Init's centre; the firmware runs it from 50 states of the ball (25 on its boundary,
//! 25 inside) against the plant's flow, and every run must satisfy the formula (as rewritten into ξ, with
//! the region's conjunct) at the samples and sampled 8 times per period, stay inside the operating region,
//! apply only inputs in the plant's input set, bit for bit with the host evaluator. The same for the
//! flat quadrotor's speed rule (`examples/flat-quadrotor-speed.toml`, Example 4.3's kind), its runs
//! drawn in Init where the one ball's image accepts them.

use host_compiler::property::input_bound;
use host_compiler::verify::input_slack;
use qemu_tests::closed_loop::{run_until, run_with, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::images::{
    accepted_starts, fl_4_9, fl_4_9_certified, fl_pendulum_certified, flat_quadrotor_certified,
    FL_TABLE_LEN,
};
use qemu_tests::nonlinear::PlantFlow;
use qemu_tests::qemu::Qemu;
use shared_types::eval::Status;
use std::time::Duration;

const STEPS: usize = FL_TABLE_LEN + 100;

#[test]
fn fl_4_9_model_maps_run_on_the_target_bit_for_bit() {
    let t = fl_4_9().unwrap_or_else(|e| panic!("{e}"));
    let path = firmware::write_image("fl_4_9", &t.bytes).expect("image written");
    let elf = firmware::build(
        "fl_4_9",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let img = shared_types::image::decode(&t.bytes).expect("the image decodes");
    let starts = t.starts();
    let mut worst = 0u32;
    for (r, x0) in starts.iter().enumerate() {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(img);
        let trace = run_with(&mut q, &mut host, x0, 0, STEPS, |x, u| {
            PlantFlow::flow(&t.plant, x, u, t.h)
        })
        .unwrap_or_else(|e| panic!("run {r} from {x0:?}: {e}"));
        assert_eq!(trace.replies.len(), STEPS);
        for (k, reply) in trace.replies.iter().enumerate() {
            assert_eq!(reply.status, Status::Ok, "run {r}: step {k}");
            assert_eq!(reply.u.len(), 2, "run {r}: step {k}");
        }
        worst = worst.max(trace.max_cost(Status::Ok).unwrap_or(0));
        let end = trace.last_state();
        assert!(
            (end[0] - 2.0).abs() < 0.02 && end[2].abs() < 0.02,
            "run {r} from {x0:?} ends at {end:?}"
        );
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {r}: firmware exit");
    }
    assert!(worst > 0);
    println!(
        "HIL fl-4-9 (model maps): {} runs of {STEPS} steps bit for bit; image {} bytes, model programs {} bytes, worst step cost {worst} instructions",
        starts.len(),
        t.bytes.len(),
        t.program_bytes
    );
}

#[test]
fn fl_4_9_certified_image_meets_the_spec_from_50_starts() {
    let (task, s) = fl_4_9_certified().unwrap_or_else(|e| panic!("{e}"));
    assert!(
        task.property.unsafe_region().is_some(),
        "Ex 4.9 has an obstacle"
    );
    certified_image_meets_the_spec_from_50_starts("fl_4_9_certified", &task, &s, 4_9);
}

/// The torque-driven pendulum (`examples/fl-pendulum.toml`): its law cancels (g/l) sin θ, a term in ξ
/// bounded over the spec's operating region, whose complement is Unsafe.
#[test]
fn fl_pendulum_certified_image_meets_the_spec_from_50_starts() {
    let (task, s) = fl_pendulum_certified().unwrap_or_else(|e| panic!("{e}"));
    let maps = task.plant.linearization().expect("a linearised plant");
    assert!(
        maps.region.is_some(),
        "the pendulum declares an operating region"
    );
    certified_image_meets_the_spec_from_50_starts("fl_pendulum_certified", &task, &s, 2026);
}

#[test]
fn flat_quadrotor_certified_image_meets_the_spec_from_50_starts() {
    let (task, s) = flat_quadrotor_certified().unwrap_or_else(|e| panic!("{e}"));
    assert!(
        s.coverage.lower >= 0.99,
        "coverage lower bound {}",
        s.coverage.lower
    );
    certified_image_meets_the_spec_from_50_starts("flat_quadrotor_certified", &task, &s, 3_15);
}

/// 50 seeded starts in Init that the image accepts, each run on the firmware against the plant's flow:
/// Goal within T; before it, no sample in Unsafe or outside the operating region, every reply `Ok`
/// with its input in the plant's input set, bit for bit with the host evaluator; each run ends at the
/// first sample in Goal (`run_until`).
fn certified_image_meets_the_spec_from_50_starts(
    name: &str,
    task: &host_compiler::task::Task,
    s: &host_compiler::synth::Synthesis,
    seed: u64,
) {
    assert_eq!(s.verify.violations, 0);
    let maps = task.plant.linearization().expect("a linearised plant");
    let img = shared_types::image::decode(&s.image).expect("the image decodes");
    let path = firmware::write_image(name, &s.image).expect("image written");
    let elf = firmware::build(
        name,
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    // 50 starts drawn in Init whose ξ the image's selection accepts.
    let starts = accepted_starts(task, img, 50, seed).unwrap_or_else(|e| panic!("{e}"));
    let goal = task.property.goal.as_ref();
    let unsafe_set = task.property.unsafe_region();
    let in_region = |x: &[f64]| {
        maps.region.as_ref().is_none_or(|r| {
            x.iter()
                .zip(r.lo.iter().zip(&r.hi))
                .all(|(v, (l, h))| l < v && v < h)
        })
    };
    let input = input_bound(&maps.input);
    let h = maps.plant.period();
    let mut worst = 0u32;
    for (r, x0) in starts.iter().enumerate() {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(img);
        // The run is judged up to Goal (below), so it ends there.
        let trace = run_until(
            &mut q,
            &mut host,
            x0,
            0,
            task.steps,
            |x, u| PlantFlow::flow(&maps.plant, x, u, h),
            |x, z| goal.contains(&maps.xi_at(x, z)),
        )
        .unwrap_or_else(|e| panic!("{name} run {r} from {x0:?}: {e}"));
        // ξ of each sample, read with the controller's states there (a flat plant's thrust and its rate).
        let xi: Vec<Vec<f64>> = trace
            .states
            .iter()
            .zip(&trace.controller_states)
            .map(|(x, z)| maps.xi_at(x, z))
            .collect();
        let goal_at = xi
            .iter()
            .position(|xi| goal.contains(xi))
            .unwrap_or_else(|| panic!("{name} run {r} from {x0:?} never reaches Goal"));
        for (k, x) in trace.states.iter().enumerate().take(goal_at + 1) {
            assert!(
                unsafe_set.is_none_or(|us| !us.contains(&xi[k])),
                "{name} run {r}: Unsafe at sample {k}"
            );
            assert!(
                in_region(x),
                "{name} run {r}: outside the operating region at sample {k}: {x:?}"
            );
        }
        for (k, reply) in trace.replies.iter().enumerate().take(goal_at) {
            assert_eq!(reply.status, Status::Ok, "{name} run {r}: step {k}");
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            assert!(
                input_slack(&input, &u) >= 0.0,
                "{name} run {r}: input {u:?} at step {k}"
            );
        }
        worst = worst.max(trace.max_cost(Status::Ok).unwrap_or(0));
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "{name} run {r}: firmware exit");
    }
    assert!(worst > 0);
    println!(
        "HIL {name}: 50 runs of {} steps met the spec, bit for bit; {} trajectories, image {} bytes, \
         worst step cost {worst} instructions",
        task.steps,
        s.trajectories.len(),
        s.image.len()
    );
}

#[test]
fn fl_pendulum_mtl_holds_on_the_target_from_50_initial_states() {
    use host_compiler::geometry::Metric;
    use host_compiler::linalg::PdRoots;
    use host_compiler::property::TemporalTask;
    use host_compiler::synth::temporal::single_ball;
    use rand::{Rng, SeedableRng};
    const RUNS: usize = 50;
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/fl-pendulum-mtl.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let task = host_compiler::task::Task::new(problem).expect("the task in ξ");
    let tt = TemporalTask::from_problem(&task.problem).expect("the formula in ξ");
    let maps = task.plant.linearization().expect("a linearised plant");
    let centre: Vec<f64> = task.init().centre();
    let (ball, bytes) = single_ball(&task, &tt, &centre).unwrap_or_else(|e| panic!("{e}"));
    assert!(ball.certificate.is_certified(), "{:?}", ball.certificate);
    let path = firmware::write_image("fl_pendulum_mtl", &bytes).expect("image written");
    let elf = firmware::build(
        "fl_pendulum_mtl",
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
    // A hair inside the radius the image's selection accepts whole.
    let d = host_compiler::verify::boundary_radius(&img, 0);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(task.problem.seed ^ 0x2_31);
    // Plant states whose ξ lies in the ball (the zero states, if any, at Init's centre), every other one
    // on its boundary, kept when the image's f32 selection accepts them (a point within rounding of the
    // boundary may be refused there: such a start is out of the certified envelope, not run).
    let selector = shared_types::eval::Controller::new(img);
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let mut draws = 0usize;
    while starts.len() < RUNS && draws < 100 * RUNS {
        draws += 1;
        let radius = if starts.len().is_multiple_of(2) {
            d
        } else {
            d * rng.random::<f64>().powf(1.0 / n as f64)
        };
        let xi = host_compiler::verify::hybrid::point_on_sphere(&mut rng, &roots, c, radius);
        let xi32: Vec<f32> = xi.iter().map(|&v| v as f32).collect();
        if selector.select_maps(&xi32).is_none() {
            continue;
        }
        let mut x = maps.init.centre();
        for (j, &s) in maps.xi_states.iter().enumerate() {
            x[s] = xi[j];
        }
        starts.push(x);
    }
    assert_eq!(starts.len(), RUNS, "{draws} draws");
    let sets = tt.sets(&Metric::euclidean(n)).expect("the sets");
    let region = maps
        .region
        .as_ref()
        .expect("the pendulum's operating region");
    let inside = |x: &[f64]| {
        x.iter()
            .zip(region.lo.iter().zip(&region.hi))
            .all(|(v, (l, h))| l < v && v < h)
    };
    let (least, worst_cost) = mtl_runs_on_target(&task, &tt, &sets, &elf, img, &starts, &inside);
    println!(
        "HIL fl-pendulum MTL: {RUNS} runs of {} steps satisfied `{}` on the plant (least robustness \
         {least:.4e}, Euclidean, in ξ), bit for bit; δ = {:.4}, image {} bytes, worst step cost \
         {worst_cost} instructions",
        task.steps,
        tt.written.source(),
        ball.certificate.delta,
        bytes.len()
    );
}

/// An MTL task on the differentially flat quadrotor (issue #14, `examples/flat-quadrotor-speed.toml`):
/// one ball certified for the speed rule from Init's centre in q; the firmware (keeping the thrust and
/// its rate) runs it from 50 plant states in Init whose q the image accepts, against the plant's flow;
/// every run must satisfy the formula as rewritten into q (with the region's conjunct) at the samples and
/// sampled 8 times per period (q read with the controller's states, and between samples with their
/// model), apply only inputs in the plant's input set, bit for bit with the host evaluator.
#[test]
fn flat_quadrotor_speed_rule_holds_on_the_target_from_50_initial_states() {
    use host_compiler::geometry::Metric;
    use host_compiler::property::TemporalTask;
    use host_compiler::synth::temporal::single_ball;
    const RUNS: usize = 50;
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/flat-quadrotor-speed.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the example parses");
    let task = host_compiler::task::Task::new(problem).expect("the task in q");
    let tt = TemporalTask::from_problem(&task.problem).expect("the formula in q");
    let maps = task.plant.linearization().expect("a linearised plant");
    assert!(maps.flat.is_some(), "a flat plant");
    let centre: Vec<f64> = task.init().centre();
    let (ball, bytes) = single_ball(&task, &tt, &centre).unwrap_or_else(|e| panic!("{e}"));
    assert!(ball.certificate.is_certified(), "{:?}", ball.certificate);
    let path = firmware::write_image("flat_quadrotor_speed", &bytes).expect("image written");
    let elf = firmware::build(
        "flat_quadrotor_speed",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let img = shared_types::image::decode(&bytes).expect("the image decodes");
    let starts = accepted_starts(&task, img, RUNS, 4_3).unwrap_or_else(|e| panic!("{e}"));
    let sets = tt
        .sets(&Metric::euclidean(task.plant.n()))
        .expect("the sets");
    // The operating region over q is a conjunct of the rewritten formula.
    let (least, worst_cost) = mtl_runs_on_target(&task, &tt, &sets, &elf, img, &starts, &|_| true);
    println!(
        "HIL flat quadrotor MTL: {RUNS} runs of {} steps satisfied `{}` on the plant (least robustness \
         {least:.4e}, Euclidean, in q), bit for bit; δ = {:.4}, image {} bytes, worst step cost \
         {worst_cost} instructions",
        task.steps,
        tt.written.source(),
        ball.certificate.delta,
        bytes.len()
    );
}

/// Each start run on the firmware `elf` (image `img`) against the plant's flow with 8 states recorded per
/// period: every reply `Ok` and bit for bit with the host evaluator, every input in the plant's input
/// set, every plant state `inside` (at the samples and between them), and the formula as rewritten into
/// ξ true on the samples and on the finer record (ξ read with the controller's states, between samples
/// with their model: a flat plant's thrust and its rate). Returns the least robustness (Euclidean) and
/// the worst step cost.
fn mtl_runs_on_target(
    task: &host_compiler::task::Task,
    tt: &host_compiler::property::TemporalTask,
    sets: &[host_compiler::robustness::mtl::sets::NamedSet],
    elf: &std::path::Path,
    img: shared_types::image::Image<'_>,
    starts: &[Vec<f64>],
    inside: &dyn Fn(&[f64]) -> bool,
) -> (f64, u32) {
    use host_compiler::verify::temporal::{formula_value, RunRecord};
    use qemu_tests::closed_loop::exchange;
    const SUB: usize = 8;
    let maps = task.plant.linearization().expect("a linearised plant");
    let input = input_bound(&maps.input);
    let h = maps.plant.period();
    let (mut worst_cost, mut least) = (0u32, f64::INFINITY);
    for (r, x0) in starts.iter().enumerate() {
        let mut q = Qemu::launch(elf, Duration::from_secs(120)).unwrap_or_else(|e| panic!("{e}"));
        let mut host = HostEvaluator::new(img);
        let mut x = x0.clone();
        let mut z = host.extension();
        let mut rec = RunRecord::new(&maps.xi_at(x0, &z), h);
        for k in 0..task.steps {
            let reply = exchange(&mut q, k as u32, &x, |xf| host.step(xf))
                .unwrap_or_else(|e| panic!("run {r}: {e}"));
            assert_eq!(reply.status, Status::Ok, "run {r} from {x0:?}: step {k}");
            worst_cost = worst_cost.max(reply.cost);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            assert!(
                input_slack(&input, &u) >= 0.0,
                "run {r}: input {u:?} outside the plant's input set at step {k}"
            );
            let z1 = host.extension();
            let mut i = 0usize;
            x = maps
                .plant
                .flow(&x, &u, h, SUB, &mut |xs| {
                    i += 1;
                    assert!(
                        inside(xs),
                        "run {r}: outside the region in period {k}: {xs:?}"
                    );
                    let tau = i as f64 * h / SUB as f64;
                    let zs = match &maps.flat {
                        Some(fc) => fc.zeta_within(&z, &z1, h, tau),
                        None => Vec::new(),
                    };
                    rec.push_between(tau, &maps.xi_at(xs, &zs));
                })
                .unwrap_or_else(|e| panic!("run {r}: the flow in period {k}: {e}"));
            assert!(
                inside(&x),
                "run {r}: outside the region at sample {}: {x:?}",
                k + 1
            );
            z = z1;
            rec.push_sample(&maps.xi_at(&x, &z));
        }
        let exit = q.shutdown().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(exit.code, Some(0), "run {r}: firmware exit");
        let (tc, tf) = rec.traces().expect("the run's traces");
        let rho = formula_value(tt, sets, &tc).expect("the formula at the samples");
        let rho_fine = formula_value(tt, sets, &tf).expect("the formula sampled finer");
        assert!(
            rho > 0.0 && rho_fine > 0.0,
            "run {r} from {x0:?}: robustness {rho} at the samples, {rho_fine} sampled finer"
        );
        least = least.min(rho).min(rho_fine);
    }
    (least, worst_cost)
}
