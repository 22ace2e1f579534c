//! The mps2-an386 board: the Arm MPS2 with the AN386 FPGA image (Cortex-M4F), as emulated by
//! `qemu-system-arm -machine mps2-an386`. Boot, validate the embedded image, then serve control steps over
//! UART0 ([`uart`]) until the host sends `Shutdown`, with SysTick under `-icount` as the cost meter
//! ([`cost`]). Logs go out as defmt over semihosting, apart from the UART. Panics, HardFaults and
//! unexpected exceptions exit QEMU with a failure code through semihosting, so nothing hangs silently.
//!
//! # Building and running
//! Build from this folder, so that cargo reads `.cargo/config.toml` here (the QEMU runner) and in
//! `firmware/` (target, linker scripts):
//!
//! ```text
//! cd firmware/boards/mps2-an386
//! CONTROLLER_IMAGE=/path/to/controller.img cargo build --release   # without it: the default test image
//! cargo run --release                                                # boots it in qemu-system-arm
//! ```
//!
//! `cargo run` puts UART0 on the terminal; the HIL harness (`qemu-tests`) connects it to a socket instead
//! and decodes the defmt log.
#![no_std]
#![no_main]

mod cost;
mod uart;

use control_loop::board::StackMeter;
use control_loop::serve::{serve, End};
use control_loop::stack::PaintedStack;
use core::sync::atomic::{AtomicBool, Ordering};
use cortex_m_rt::{entry, exception, ExceptionFrame};
use cost::{SysTickMeter, INSTRUCTIONS_PER_TICK};
use defmt::{error, info, Display2Format};
use defmt_semihosting as _;
use uart::{Uart, UART0_BASE};

/// Exit codes reported to QEMU through semihosting (`SYS_EXIT_EXTENDED`); QEMU exits with the same status.
mod exit_code {
    /// The host asked for shutdown.
    pub const SUCCESS: i32 = 0;
    /// A panic (there should be none: bad data is handled without panicking).
    pub const PANIC: i32 = 101;
    /// A HardFault.
    pub const HARD_FAULT: i32 = 102;
    /// An interrupt or exception that has no handler.
    pub const UNEXPECTED_EXCEPTION: i32 = 103;
    /// Boot failed before the loop (core peripherals already taken).
    pub const BOOT: i32 = 104;
}

/// UART baud rate. QEMU ignores it (bytes move at socket speed), but the divisor must be valid.
const BAUD: u32 = 115_200;

/// Iterations of the boot calibration loop (2 instructions each).
const CALIBRATION_ITERATIONS: u32 = 100_000;

#[entry]
fn main() -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        semihosting::process::exit(exit_code::BOOT)
    };
    let mut meter = SysTickMeter::new(cp.SYST);
    let ticks = cost::calibrate(&mut meter, CALIBRATION_ITERATIONS);
    info!(
        "calibration: {=u32} instructions took {=u32} SysTick ticks ({=u32} instructions per tick assumed)",
        2 * CALIBRATION_ITERATIONS,
        ticks,
        INSTRUCTIONS_PER_TICK
    );

    #[cfg(fault_injection = "panic")]
    fault_injection_panic();
    #[cfg(fault_injection = "hardfault")]
    fault_injection_hardfault();

    let image = control_loop::image::image();
    let (mut app, boot) = control_loop::boot();
    match boot {
        Ok(img) => info!(
            "image accepted: {=usize} bytes, n={=usize} m={=usize} trajectories={=usize} steps={=usize}",
            image.len(),
            img.n(),
            img.m(),
            img.n_trajectories(),
            img.total_steps()
        ),
        Err(e) => error!(
            "image rejected: {} ({=usize} bytes); applying the build-time fallback (zero input, m={=usize})",
            e,
            image.len(),
            control_loop::image::REJECTED_M
        ),
    }

    // SAFETY: UART0 is used by nothing else.
    let mut uart = unsafe { Uart::new(UART0_BASE, BAUD) };
    info!("ready");
    match serve(&mut app, &mut uart, &mut meter) {
        End::Shutdown(s) => {
            info!(
                "shutdown: ok={=u32} out_of_envelope={=u32} bad_frames={=u32} rejected={=u32} max_cost={=u32} stack_peak={=u32}",
                s.ok,
                s.out_of_envelope,
                s.bad_frames,
                s.rejected,
                s.max_cost,
                PaintedStack.peak_bytes()
            );
            semihosting::process::exit(exit_code::SUCCESS)
        }
        // MAX_FRAME is sized for the largest reply; reaching this is a bug, so say so loudly and exit with
        // the panic code, without a panic (no panicking path: `cargo xtask no-panic`).
        End::ReplyTooLarge => {
            error!("reply does not fit MAX_FRAME");
            semihosting::process::exit(exit_code::PANIC)
        }
    }
}

#[cfg(fault_injection = "panic")]
fn fault_injection_panic() {
    // Built only with FIRMWARE_FAULT_INJECTION=panic, to test that a panic exits QEMU with failure.
    let v = core::hint::black_box(&[1u8, 2, 3][..]);
    let i = core::hint::black_box(7usize);
    info!("fault injection: indexing out of bounds");
    let _ = v[i];
}

#[cfg(fault_injection = "hardfault")]
fn fault_injection_hardfault() {
    // Built only with FIRMWARE_FAULT_INJECTION=hardfault: a read from unmapped memory.
    info!("fault injection: reading unmapped memory");
    // SAFETY: deliberately faults; the HardFault handler exits QEMU.
    let _ = unsafe { core::ptr::read_volatile(0xF000_0000 as *const u32) };
}

static PANICKING: AtomicBool = AtomicBool::new(false);

#[cfg(not(feature = "panic-never"))]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // Log once; a panic while logging (e.g. inside the defmt logger) goes straight to exit.
    if !PANICKING.swap(true, Ordering::SeqCst) {
        error!("panic: {}", Display2Format(info));
    }
    semihosting::process::exit(exit_code::PANIC)
}

/// The panic handler of the `panic-never` build (the no-panic check of `cargo xtask test`): it calls a
/// function that is defined nowhere, so the link fails, naming this symbol, if any panicking path is still
/// reachable after optimisation; xtask then names the functions that call into the panic machinery.
#[cfg(feature = "panic-never")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    extern "C" {
        /// Never defined: see above.
        fn firmware_panic_path_is_reachable() -> !;
    }
    // SAFETY: never runs; a build that could reach this does not link.
    unsafe { firmware_panic_path_is_reachable() }
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    if !PANICKING.swap(true, Ordering::SeqCst) {
        error!(
            "HardFault at pc={=u32:#010x} lr={=u32:#010x}",
            ef.pc(),
            ef.lr()
        );
    }
    semihosting::process::exit(exit_code::HARD_FAULT)
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if !PANICKING.swap(true, Ordering::SeqCst) {
        error!("unexpected exception {=i16}", irqn);
    }
    semihosting::process::exit(exit_code::UNEXPECTED_EXCEPTION)
}
