//! `hil-bench`: the HIL measurement for `cargo xtask bench`. Builds the firmware with the double-integrator
//! test image, runs closed loops from inside each ball and from outside every ball, and writes the rows
//! `firmware_step_instructions_max`, `firmware_fallback_instructions_max`, `firmware_flash_bytes` and
//! `firmware_ram_bytes`, `firmware_stack_bytes_max` to `target/bench/rows/hil.json`.
//!
//! `pwa_step_instructions_max`: the largest cost of one control step of a PWA-feedback image (Ch. 6) — tree
//! walk, envelope test against the leaf's balls, law — over closed loops from states in the envelope F and
//! from outside it (where every ball of the leaf is tested before "out of envelope"), measured with
//! `-icount`, from ball centres and from the costliest starts the host evaluator finds just outside the
//! balls. The row is measured on the Example 6.4 image (examples/planar-vehicle-pwa-4.toml);
//! `pwa_step_instructions_max_double_integrator` is the same measurement on the double-integrator image.
//!
//! Flash and RAM come from the ELF's allocated sections ([`qemu_tests::elf_size`]); RAM is the static part
//! (`.data`, `.bss`, `.uninit`) and does not include the stack, whose high-water mark (painted stack,
//! reported by the firmware at shutdown) is the separate `firmware_stack_bytes_max`.
//!
//! `nonlinear_step_instructions_max`: the largest cost of one control step of an image with model maps
//! (a feedback-linearizable plant: ξ = coords(x), the feedforward law, u = input_map(x, w)), over the
//! closed loops of the certified Example 4.9 image (`qemu_tests::images::fl_4_9_certified`, synthesised
//! here: the selection over all its balls at κ = 0, the input map λ(x)w with its sin and cos of θ) and of
//! the certified flat quadrotor image (`qemu_tests::images::flat_quadrotor_certified`: q from the plant
//! state and the controller's thrust and its rate, with atan2 and a square root; u and the next
//! controller states from the snap), from 12 seeded starts in Init each over the task's horizon, against
//! the nonlinear plant integrated on the host; `nonlinear_step_instructions_max_fl_4_9` and
//! `_flat_quadrotor` are the two parts, `model_program_bytes_flat_quadrotor` the quadrotor's programs.
//! `nonlinear_step_instructions_max_one_ball` is the same on the hand-built one-ball image of
//! `qemu_tests::images::fl_4_9` (u = R(θ)w) from its five starts; `model_program_bytes` is the size of
//! that image's two programs.
//!
//! `monitor_step_instructions_max`: the largest cost of the task monitor's update alone (issue 46; the
//! reply's own monitor cost, measured apart from the step) on `examples/planar-vehicle-waypoints.toml`'s
//! formula, over closed loops of its one-ball image (`synth::temporal::single_ball`) with the monitor
//! attached, from 8 seeded starts in Init, each over the horizon (samples 0..=N, the last one deciding
//! every pending value); `monitor_step_instructions_before_last_max` the same over the samples before N. `monitor_mismatches_target`: samples of those runs where the firmware's bounds
//! or verdict differ from the host's f32 reference (target 0). `monitor_ram_bytes` and
//! `monitor_flash_bytes`: the firmware's static RAM and flash with the monitor less without it (same
//! image otherwise).
//!
//! `firmware_stack_bytes_bound`: the worst-case stack of the control loop, as the measured high-water mark
//! of the painted stack over every run of every image mode here (the feedforward double-integrator image
//! and the two PWA images, from inside and outside the envelope, so the law, the envelope test and the
//! fallback all run). The mark covers everything since reset, boot and image validation included, so it
//! bounds the loop's share from above for these runs. No static tool gives a bound for this toolchain (stable Rust has no
//! `-Z emit-stack-sizes`); the figure is measured, not proved.

#![allow(non_snake_case)]

use host_compiler::benchkit::{write_rows, Row};
use qemu_tests::closed_loop::{self, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::images;
use qemu_tests::qemu::Qemu;
use shared_types::eval::Status;
use shared_types::image::decode;
use std::process::ExitCode;
use std::time::Duration;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hil-bench: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    // `HIL_BENCH_ONLY=monitor`: the monitor's rows alone, in their own rows file.
    if std::env::var("HIL_BENCH_ONLY").is_ok_and(|v| v == "monitor") {
        let mon = monitor_step_max()?;
        write_rows("hil_monitor", &monitor_rows(&mon))?;
        return Ok(());
    }
    let img = images::double_integrator()?;
    let elf = firmware_with("double_integrator", &img.bytes)?;
    let plant = img.discrete_plant();
    let image = decode(&img.bytes).map_err(qemu_tests::HilError::Image)?;
    let mut starts: Vec<Vec<f64>> = Vec::new();
    for c in &img.centres {
        for (dx, dy) in [(0.0, 0.0), (0.1, -0.05), (-0.2, 0.1)] {
            starts.push(vec![c[0] as f64 + dx, c[1] as f64 + dy]);
        }
    }
    let outside = vec![vec![10.0, 10.0], vec![-5.0, 3.0]];
    let (mut step_max, mut fallback_max, mut stack_max) = (0u32, 0u32, 0u64);
    for x0 in starts.iter().chain(&outside) {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120))?;
        let mut host = HostEvaluator::new(image);
        let trace = closed_loop::run(&mut q, &plant, &mut host, x0, 0, 100)?;
        step_max = step_max.max(trace.max_cost(Status::Ok).unwrap_or(0));
        fallback_max = fallback_max.max(trace.max_cost(Status::OutOfEnvelope).unwrap_or(0));
        let exit = q.shutdown()?;
        if exit.code != Some(0) {
            return Err(format!("firmware exited with {:?}", exit.code).into());
        }
        let peak =
            qemu_tests::logs::stack_peak(&exit.logs).ok_or("no stack_peak in the shutdown log")?;
        stack_max = stack_max.max(peak);
    }
    let (pwa_max, _, pwa_stack) = pwa_step_max(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/planar-vehicle-pwa-4.toml"
        ),
        "pwa_example_6_4",
    )?;
    let (pwa_di_max, _, pwa_di_stack) = pwa_step_max(
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/double-integrator.toml"
        ),
        "pwa_double_integrator",
    )?;
    let (hybrid_max, hybrid_stack) = hybrid_step_max()?;
    let nl = nonlinear_step_max()?;
    let mon = monitor_step_max()?;
    let size = qemu_tests::elf_size(&std::fs::read(&elf)?)?;
    let rows = [
        Row::new(
            "hybrid_step_instructions_max",
            hybrid_max as f64,
            "instructions (Ex 4.25, guard test included)",
        ),
        Row::new(
            "nonlinear_step_instructions_max",
            nl.certified_fl_4_9.max(nl.certified_flat_quadrotor) as f64,
            "instructions (certified Ex 4.9 and flat quadrotor images, programs included)",
        ),
        Row::new(
            "nonlinear_step_instructions_max_fl_4_9",
            nl.certified_fl_4_9 as f64,
            "instructions (certified Ex 4.9 image)",
        ),
        Row::new(
            "nonlinear_step_instructions_max_flat_quadrotor",
            nl.certified_flat_quadrotor as f64,
            "instructions (certified flat quadrotor image, controller states kept)",
        ),
        Row::new(
            "nonlinear_step_instructions_max_one_ball",
            nl.hand_built as f64,
            "instructions (hand-built one-ball Ex 4.9 image)",
        ),
        Row::new(
            "model_program_bytes",
            nl.program_bytes as f64,
            "bytes (Ex 4.9)",
        ),
        Row::new(
            "model_program_bytes_flat_quadrotor",
            nl.flat_program_bytes as f64,
            "bytes (flat quadrotor: q from (x, T, Ṫ); u and ζ⁺ from (x, T, Ṫ, w))",
        ),
        Row::new("pwa_step_instructions_max", pwa_max as f64, "instructions"),
        Row::new(
            "pwa_step_instructions_max_double_integrator",
            pwa_di_max as f64,
            "instructions",
        ),
        Row::new(
            "firmware_step_instructions_max",
            step_max as f64,
            "instructions",
        ),
        Row::new(
            "firmware_fallback_instructions_max",
            fallback_max as f64,
            "instructions",
        ),
        Row::new("firmware_flash_bytes", size.flash as f64, "bytes"),
        Row::new("firmware_ram_bytes", size.ram as f64, "bytes"),
        Row::new("firmware_stack_bytes_max", stack_max as f64, "bytes"),
        Row::new(
            "firmware_stack_bytes_bound",
            stack_max
                .max(pwa_stack)
                .max(pwa_di_stack)
                .max(hybrid_stack)
                .max(nl.stack)
                .max(mon.stack) as f64,
            "bytes (measured: painted-stack high-water mark, every image mode)",
        ),
    ];
    let rows: Vec<Row> = rows.into_iter().chain(monitor_rows(&mon)).collect();
    write_rows("hil", &rows)?;
    Ok(())
}

/// The monitor's rows (module doc).
fn monitor_rows(mon: &MonitorCosts) -> Vec<Row> {
    vec![
        Row::new(
            "monitor_step_instructions_max",
            mon.max as f64,
            "instructions (planar-vehicle-waypoints' formula, update alone)",
        ),
        Row::new(
            "monitor_step_instructions_before_last_max",
            mon.steady as f64,
            "instructions (the same, samples before N)",
        ),
        Row::new(
            "monitor_mismatches_target",
            mon.mismatches as f64,
            "samples (firmware vs host f32 reference)",
        ),
        Row::new(
            "monitor_ram_bytes",
            mon.ram as f64,
            "bytes (planar-vehicle-waypoints; with the monitor less without)",
        ),
        Row::new(
            "monitor_flash_bytes",
            mon.flash as f64,
            "bytes (with the monitor less without)",
        ),
    ]
}

/// One PWA row (module doc): the largest cost of any reply, `Ok` and out-of-envelope alike, over closed
/// loops from a spread of ball centres and from the states the host evaluator finds most expensive: points
/// just outside a ball (1.02 ρ in the ball's metric, several directions per ball), ranked by how many ball
/// tests the evaluator makes there (all of the leaf's balls for an out-of-envelope state, else the position
/// of the accepting ball in the leaf's list). Returns the maximum, a one-line summary and the largest stack
/// high-water mark of these runs.
fn pwa_step_max(spec: &str, tag: &str) -> Result<(u32, String, u64), Box<dyn std::error::Error>> {
    use host_compiler::pwa::{learn_pwa, PwaSettings};
    use host_compiler::synth::{synthesize, SynthOptions};
    use rand::{Rng, SeedableRng};
    use shared_types::pwa::Region;
    let problem = host_compiler::spec::load(spec).map_err(|e| format!("{e:?}"))?;
    let opts = SynthOptions {
        verify_interior: 200,
        verify_per_ball: 2,
        progress: false,
        ..SynthOptions::default()
    };
    let task = host_compiler::task::Task::new(problem)?;
    let problem = &task.problem;
    let s = synthesize(&task, &opts)?;
    let pwa = learn_pwa(&task, &s, &PwaSettings::default())?;
    let elf = firmware_with(tag, &pwa.image)?;
    let image = decode(&pwa.image).map_err(qemu_tests::HilError::Image)?;
    let plant = task.plant.error_dynamics(0);
    let n = image.n();
    let centre =
        |b: usize| -> Vec<f64> { (0..n).map(|i| image.ball_centre(b, i) as f64).collect() };
    let mut starts: Vec<Vec<f64>> = (0..image.n_balls())
        .step_by((image.n_balls() / 12).max(1))
        .map(centre)
        .collect();
    // Ball tests the evaluator makes at x (module doc).
    let tests = |x: &[f64]| -> usize {
        let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        match image.locate(&xf) {
            Some(Region::OutsideBalls { leaf, .. }) => image.leaf_refs(leaf as usize).1,
            Some(Region::Inside { leaf, ball, .. }) => {
                let len = image.leaf_refs(leaf as usize).1;
                (0..len)
                    .position(|k| image.leaf_ball(leaf as usize, k) == Some(ball as usize))
                    .map_or(len, |k| k + 1)
            }
            _ => 0,
        }
    };
    let P = faer::Mat::from_fn(n, n, |i, j| image.P(0, i, j) as f64);
    let Pis = host_compiler::linalg::sym_fn(P.as_ref(), |l| 1.0 / l.sqrt())
        .ok_or("P is not symmetric")?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(problem.seed ^ 0xb0b);
    let mut ranked: Vec<(usize, Vec<f64>)> = Vec::new();
    for b in 0..image.n_balls() {
        let c = centre(b);
        for _ in 0..4 {
            let mut d: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
            d.iter_mut().for_each(|v| *v /= norm);
            let r = 1.02 * (image.ball_threshold(b) as f64).sqrt();
            let x: Vec<f64> = (0..n)
                .map(|i| c[i] + r * (0..n).map(|j| Pis[(i, j)] * d[j]).sum::<f64>())
                .collect();
            ranked.push((tests(&x), x));
        }
    }
    ranked.sort_by(|a, b| b.0.cmp(&a.0));
    let worst_tests = ranked.first().map_or(0, |r| r.0);
    starts.extend(ranked.into_iter().take(8).map(|r| r.1));
    starts.push(vec![10.0; n]);
    let (mut max, mut stack) = (0u32, 0u64);
    for x0 in &starts {
        let (m, s) = session(&elf, image, x0, task.steps, |x, u| Ok(plant.step(x, u)))?;
        max = max.max(m);
        stack = stack.max(s);
    }
    let summary = format!(
        "pwa ({tag}): {} partitions, tree depth {}, at most {} balls per leaf, {} runs (the 8 costliest starts found on the host make {worst_tests} ball tests), max step {max} instructions",
        pwa.stats.partitions,
        pwa.stats.depth,
        pwa.stats.max_leaf_balls,
        starts.len()
    );
    println!("{summary}");
    Ok((max, summary, stack))
}

/// The hybrid row: Example 4.25's run from the text's x0 in an image with a guard exit; closed loops from
/// 8 starts in its ball (the centre and points towards its boundary), against the automaton's exact flow,
/// over the horizon; the largest cost of any reply (every step tests the guard until the switch is seen)
/// and the stack high-water mark.
fn hybrid_step_max() -> Result<(u32, u64), Box<dyn std::error::Error>> {
    use host_compiler::synth::hybrid::{ball_starts, image, plan_run, HybridTask};
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-internal-4-25.toml"
    );
    let problem = host_compiler::spec::load(spec).map_err(|e| format!("{e:?}"))?;
    let task = HybridTask::new(problem)?;
    let run = plan_run(&task, &[-5.0, 1.0, 2.0])?;
    let bytes = image(&task, std::slice::from_ref(&run))?;
    let elf = firmware_with("hybrid_bench", &bytes)?;
    let img = decode(&bytes).map_err(qemu_tests::HilError::Image)?;
    let mut starts = vec![run.nominals[0].x[0].clone()];
    starts.extend(ball_starts(&task, &run, 3, 4, task.problem.seed ^ 0xbe4c));
    let (mut max, mut stack) = (0u32, 0u64);
    for x0 in &starts {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120))?;
        let mut host = HostEvaluator::new(img);
        let (mut x, mut loc) = (x0.clone(), task.initial);
        for k in 0..task.steps {
            let reply = closed_loop::exchange(&mut q, k as u32, &x, |xf| host.step(xf))?;
            max = max.max(reply.cost);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            let step = task.plant.flow(loc, &x, &u)?;
            x = step.x;
            loc = step.loc;
        }
        let exit = q.shutdown()?;
        if exit.code != Some(0) {
            return Err(format!("hybrid firmware exited with {:?}", exit.code).into());
        }
        let peak =
            qemu_tests::logs::stack_peak(&exit.logs).ok_or("no stack_peak in the shutdown log")?;
        stack = stack.max(peak);
    }
    println!(
        "hybrid (Ex 4.25): δ = {:.4}, {} runs of {} steps, max step {max} instructions",
        run.delta(),
        starts.len(),
        task.steps
    );
    Ok((max, stack))
}

/// The nonlinear rows (module doc): the largest cost of any reply over the closed loops of the certified
/// Example 4.9 and flat quadrotor images from 12 seeded starts in Init each (over the task's horizon) and
/// of the hand-built one-ball image from its five starts, the stack high-water mark, and the bytes of the
/// model programs.
fn nonlinear_step_max() -> Result<NonlinearCosts, Box<dyn std::error::Error>> {
    use qemu_tests::nonlinear::PlantFlow;
    let (task, s) = images::fl_4_9_certified()?;
    let (certified, mut stack, _) = certified_runs("fl_4_9_certified_bench", &task, &s, 4_9)?;
    println!(
        "nonlinear (Ex 4.9 certified, model maps): {} balls, 12 runs of {} steps, max step {certified} instructions",
        s.trajectories.len(),
        task.steps
    );
    let (task, s) = images::flat_quadrotor_certified()?;
    let (flat, st, flat_program_bytes) =
        certified_runs("flat_quadrotor_certified_bench", &task, &s, 3_15)?;
    stack = stack.max(st);
    println!(
        "nonlinear (flat quadrotor certified, controller states T and Ṫ): {} balls, 12 runs of {} steps, \
         programs {flat_program_bytes} bytes, max step {flat} instructions",
        s.trajectories.len(),
        task.steps
    );

    let t = images::fl_4_9()?;
    let elf = firmware_with("fl_4_9_bench", &t.bytes)?;
    let img = decode(&t.bytes).map_err(qemu_tests::HilError::Image)?;
    let mut hand = 0u32;
    let starts = t.starts();
    let steps = t.table_len + 100;
    for x0 in &starts {
        let (m, st) = session(&elf, img, x0, steps, |x, u| {
            PlantFlow::flow(&t.plant, x, u, t.h)
        })?;
        hand = hand.max(m);
        stack = stack.max(st);
    }
    println!(
        "nonlinear (Ex 4.9 hand-built, one ball): {} runs of {steps} steps, programs {} bytes, max step {hand} instructions",
        starts.len(),
        t.program_bytes
    );
    Ok(NonlinearCosts {
        certified_fl_4_9: certified,
        certified_flat_quadrotor: flat,
        hand_built: hand,
        stack,
        program_bytes: t.program_bytes,
        flat_program_bytes,
    })
}

/// A certified image of a linearised task run on the firmware from 12 seeded starts in Init that it
/// accepts, each over the task's horizon against the plant's flow: the largest step cost, the stack
/// high-water mark and the bytes of its two model programs.
fn certified_runs(
    tag: &str,
    task: &host_compiler::task::Task,
    s: &host_compiler::synth::Synthesis,
    seed: u64,
) -> Result<(u32, u64, usize), Box<dyn std::error::Error>> {
    use qemu_tests::nonlinear::PlantFlow;
    let maps = task
        .plant
        .linearization()
        .ok_or("the task is linearised (feedback linearizable or flat)")?;
    let elf = firmware_with(tag, &s.image)?;
    let img = decode(&s.image).map_err(qemu_tests::HilError::Image)?;
    let h = maps.plant.period();
    let (mut max, mut stack) = (0u32, 0u64);
    for x0 in &images::accepted_starts(task, img, 12, seed)? {
        let (m, st) = session(&elf, img, x0, task.steps, |x, u| {
            PlantFlow::flow(&maps.plant, x, u, h)
        })?;
        max = max.max(m);
        stack = stack.max(st);
    }
    Ok((
        max,
        stack,
        maps.coords.bytes.len() + maps.input_map.bytes.len(),
    ))
}

/// What [`monitor_step_max`] measures (module doc).
struct MonitorCosts {
    max: u32,
    /// The largest before the last sample N (which decides every pending value).
    steady: u32,
    mismatches: usize,
    ram: i64,
    flash: i64,
    stack: u64,
}

/// The monitor rows (module doc).
fn monitor_step_max() -> Result<MonitorCosts, Box<dyn std::error::Error>> {
    use host_compiler::monitor::{reference, Program};
    use rand::{Rng, SeedableRng};
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle-waypoints.toml"
    );
    let problem = host_compiler::spec::load(spec)?;
    let tt = host_compiler::property::TemporalTask::from_problem(&problem)?;
    let prog = Program::for_problem(&problem)?;
    let body = prog.encode();
    let task = host_compiler::task::Task::new(problem.clone())?;
    let centre: Vec<f64> = task
        .init()
        .lo
        .iter()
        .zip(&task.init().hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect();
    let (_, bytes) = host_compiler::synth::temporal::single_ball(&task, &tt, &centre)?;
    let with = host_compiler::monitor::attach(&bytes, &body)?;
    let elf = firmware_with("monitor_waypoints_bench", &with)?;
    let plain = firmware_with("monitor_waypoints_plain_bench", &bytes)?;
    let (a, b) = (
        qemu_tests::elf_size(&std::fs::read(&elf)?)?,
        qemu_tests::elf_size(&std::fs::read(&plain)?)?,
    );
    let img = decode(&with).map_err(qemu_tests::HilError::Image)?;
    let section = shared_types::monitor::MonitorProgram::decode(&body, task.plant.n())
        .map_err(|e| format!("{e}"))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(problem.seed ^ 0x46);
    let (mut max, mut steady, mut mismatches, mut stack) = (0u32, 0u32, 0usize, 0u64);
    for run in 0..8 {
        let x0: Vec<f64> = if run == 0 {
            centre.clone()
        } else {
            task.init()
                .lo
                .iter()
                .zip(&task.init().hi)
                .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
                .collect()
        };
        let mut q = Qemu::launch(&elf, Duration::from_secs(300))?;
        let mut host = HostEvaluator::new(img);
        let (mut x, mut trace, mut got) = (x0, Vec::new(), Vec::new());
        for k in 0..=prog.horizon {
            let reply = closed_loop::exchange(&mut q, k as u32, &x, |xf| host.step(xf))?;
            let m = reply.monitor.ok_or("a reply without the monitor")?;
            max = max.max(m.cost);
            if k < prog.horizon {
                steady = steady.max(m.cost);
            }
            trace.push(x.iter().map(|&v| v as f32).collect::<Vec<f32>>());
            got.push(m);
            let u: Vec<f64> = reply.u.as_slice().iter().map(|&v| v as f64).collect();
            x = task.plant.step(0, &x, &u);
        }
        let want = reference::reports(&prog, &section, &trace);
        mismatches += got
            .iter()
            .zip(&want)
            .filter(|(m, w)| {
                m.lo != w.lo.to_bits() || m.hi != w.hi.to_bits() || m.verdict != w.verdict as u8
            })
            .count();
        let exit = q.shutdown()?;
        if exit.code != Some(0) {
            return Err(format!("firmware exited with {:?}", exit.code).into());
        }
        let peak =
            qemu_tests::logs::stack_peak(&exit.logs).ok_or("no stack_peak in the shutdown log")?;
        stack = stack.max(peak);
    }
    let (ram, flash) = (a.ram as i64 - b.ram as i64, a.flash as i64 - b.flash as i64);
    println!(
        "monitor (planar-vehicle-waypoints' formula: {} atoms, {} nodes, N = {}): 8 runs, max update          {max} instructions (before the last sample {steady}), {mismatches} mismatching samples; RAM \
         +{ram} bytes, flash +{flash} bytes",
        prog.atoms.len(),
        prog.nodes.len(),
        prog.horizon
    );
    Ok(MonitorCosts {
        max,
        steady,
        mismatches,
        ram,
        flash,
        stack,
    })
}

/// What [`nonlinear_step_max`] measures (module doc).
struct NonlinearCosts {
    /// The largest step cost over the certified Example 4.9 image's runs.
    certified_fl_4_9: u32,
    /// The same over the certified flat quadrotor image's runs.
    certified_flat_quadrotor: u32,
    /// The same over the hand-built one-ball Example 4.9 image's runs.
    hand_built: u32,
    /// The stack high-water mark over all of them.
    stack: u64,
    /// The hand-built Example 4.9 image's two programs, in bytes.
    program_bytes: usize,
    /// The flat quadrotor image's two programs, in bytes.
    flat_program_bytes: usize,
}

/// The firmware built with `bytes` as its image; `tag` names the image file and the ELF copy.
fn firmware_with(
    tag: &str,
    bytes: &[u8],
) -> Result<std::path::PathBuf, Box<dyn std::error::Error>> {
    let path = firmware::write_image(tag, bytes)?;
    Ok(firmware::build(
        tag,
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )?)
}

/// One closed-loop session: the firmware `elf` booted in QEMU, `steps` periods from `x0` against the host
/// evaluator of `image` (bit for bit) with `plant` the one-period step, the firmware's exit checked.
/// Returns the largest cost of a reply (`Ok` or out of the envelope) and the stack high-water mark.
fn session(
    elf: &std::path::Path,
    image: shared_types::image::Image<'_>,
    x0: &[f64],
    steps: usize,
    plant: impl FnMut(&[f64], &[f64]) -> Result<Vec<f64>, String>,
) -> Result<(u32, u64), Box<dyn std::error::Error>> {
    let mut q = Qemu::launch(elf, Duration::from_secs(120))?;
    let mut host = HostEvaluator::new(image);
    let trace = closed_loop::run_with(&mut q, &mut host, x0, 0, steps, plant)?;
    let max = [Status::Ok, Status::OutOfEnvelope]
        .iter()
        .filter_map(|&st| trace.max_cost(st))
        .max()
        .unwrap_or(0);
    let exit = q.shutdown()?;
    if exit.code != Some(0) {
        return Err(format!("firmware {} exited with {:?}", elf.display(), exit.code).into());
    }
    let peak =
        qemu_tests::logs::stack_peak(&exit.logs).ok_or("no stack_peak in the shutdown log")?;
    Ok((max, peak))
}
