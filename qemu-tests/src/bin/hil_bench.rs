//! `hil-bench`: the HIL measurement for `cargo xtask bench`. Builds the firmware with the double-integrator
//! test image, runs closed loops from inside each ball and from outside every ball, and writes the rows
//! `firmware_step_instructions_max`, `firmware_fallback_instructions_max`, `firmware_flash_bytes` and
//! `firmware_ram_bytes`, `firmware_stack_bytes_max` to `target/bench/rows/hil.json`.
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
    let size = qemu_tests::elf_size(&std::fs::read(&elf)?)?;
    let rows = [
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
