//! `hil-bench`: the HIL measurement for `cargo xtask bench`. Builds the firmware with the double-integrator
//! test image, runs closed loops from inside each ball and from outside every ball, and writes the rows
//! `firmware_step_instructions_max`, `firmware_fallback_instructions_max`, `firmware_flash_bytes` and
//! `firmware_ram_bytes`, `firmware_stack_bytes_max` to `target/bench/rows/hil.json`.
//!
//! `pwa_step_instructions_max`: the largest cost of one control step of a PWA-feedback image (Ch. 6) — tree
//! walk, envelope test against the leaf's balls, law — over closed loops from states in the envelope F and
//! from outside it (where every ball of the leaf is tested before "out of envelope"), measured with
//! `-icount`. The image is learned from the double-integrator cover (the Example 6.4 setting does not yet
//! give an image within the capacities).
//!
//! Flash and RAM come from the ELF's allocated sections ([`qemu_tests::elf_size`]); RAM is the static part
//! (`.data`, `.bss`, `.uninit`) and does not include the stack, whose high-water mark (painted stack,
//! reported by the firmware at shutdown) is the separate `firmware_stack_bytes_max`.

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
    let img = images::double_integrator()?;
    let path = firmware::write_image("double_integrator", &img.bytes)?;
    let elf = firmware::build(
        "double_integrator",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )?;
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
    let pwa_max = pwa_step_max()?;
    let size = qemu_tests::elf_size(&std::fs::read(&elf)?)?;
    let rows = [
        Row::new("pwa_step_instructions_max", pwa_max as f64, "instructions"),
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
    ];
    write_rows("hil", &rows)?;
    Ok(())
}

/// The PWA row (module doc): every reply's cost, `Ok` and out-of-envelope alike.
fn pwa_step_max() -> Result<u32, Box<dyn std::error::Error>> {
    use host_compiler::pwa::{learn_pwa, PwaSettings};
    use host_compiler::synth::{synthesize, SynthOptions};
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    );
    let problem = host_compiler::spec::load(spec).map_err(|e| format!("{e:?}"))?;
    let opts = SynthOptions {
        verify_interior: 200,
        verify_per_ball: 2,
        progress: false,
        ..SynthOptions::default()
    };
    let s = synthesize(&problem, &opts)?;
    let pwa = learn_pwa(&problem, &s, &PwaSettings::default())?;
    let path = firmware::write_image("pwa_double_integrator", &pwa.image)?;
    let elf = firmware::build(
        "pwa_double_integrator",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )?;
    let image = decode(&pwa.image).map_err(qemu_tests::HilError::Image)?;
    let plant = host_compiler::model::DiscretePlant::new(
        s.plant.A.clone(),
        s.plant.B.clone(),
        s.plant.g.clone(),
        problem.plant.period,
    )?;
    let n = image.n();
    let mut starts: Vec<Vec<f64>> = (0..image.n_balls())
        .step_by((image.n_balls() / 12).max(1))
        .map(|b| (0..n).map(|i| image.ball_centre(b, i) as f64).collect())
        .collect();
    starts.push(vec![10.0; n]);
    let mut max = 0u32;
    for x0 in &starts {
        let mut q = Qemu::launch(&elf, Duration::from_secs(120))?;
        let mut host = HostEvaluator::new(image);
        let trace = closed_loop::run(&mut q, &plant, &mut host, x0, 0, problem.horizon_steps())?;
        for st in [Status::Ok, Status::OutOfEnvelope] {
            max = max.max(trace.max_cost(st).unwrap_or(0));
        }
        let exit = q.shutdown()?;
        if exit.code != Some(0) {
            return Err(format!("PWA firmware exited with {:?}", exit.code).into());
        }
    }
    println!(
        "pwa: {} partitions, tree depth {}, at most {} balls per leaf, {} runs, max step {max} instructions",
        pwa.stats.partitions,
        pwa.stats.depth,
        pwa.stats.max_leaf_balls,
        starts.len()
    );
    Ok(max)
}
