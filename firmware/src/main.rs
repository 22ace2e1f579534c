//! The firmware binary: boot, validate the embedded image, then serve control steps over UART0 forever
//! (until the host sends `Shutdown`). Panics, HardFaults and unexpected exceptions exit QEMU with a failure
//! code through semihosting, so nothing hangs silently.
#![no_std]
#![no_main]

use core::sync::atomic::{AtomicBool, Ordering};
use cortex_m_rt::{entry, exception, ExceptionFrame};
use defmt::{error, info, Display2Format};
use defmt_semihosting as _;
use firmware::app::{Action, App};
use firmware::cost::{self, SysTickMeter, INSTRUCTIONS_PER_TICK};
use firmware::uart::{Uart, UART0_BASE};
use firmware::{exit_code, BAUD};
use shared_types::protocol::{encode_frame, Reader, MAX_FRAME};

mod build_config {
    include!(concat!(env!("OUT_DIR"), "/build_config.rs"));
}

/// Byte array with the alignment of `f64`, so that the image is stored word-aligned in flash.
#[repr(C, align(8))]
struct Aligned<T: ?Sized>(T);

/// The controller image chosen at build time (see build.rs).
static IMAGE: &Aligned<[u8]> = &Aligned(*include_bytes!(concat!(env!("OUT_DIR"), "/image.bin")));

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

    let (mut app, boot) = App::new(&IMAGE.0, build_config::REJECTED_M);
    match boot {
        Ok(img) => info!(
            "image accepted: {=usize} bytes, n={=usize} m={=usize} trajectories={=usize} steps={=usize}",
            IMAGE.0.len(),
            img.n(),
            img.m(),
            img.n_trajectories(),
            img.total_steps()
        ),
        Err(e) => error!(
            "image rejected: {} ({=usize} bytes); applying the build-time fallback (zero input, m={=usize})",
            Display2Format(&e),
            IMAGE.0.len(),
            build_config::REJECTED_M
        ),
    }

    // SAFETY: UART0 is used by nothing else.
    let mut uart = unsafe { Uart::new(UART0_BASE, BAUD) };
    let mut reader = Reader::new();
    let mut out = [0u8; MAX_FRAME];
    info!("ready");
    loop {
        let byte = uart.read_byte();
        let Some(ev) = reader.push(byte) else {
            continue;
        };
        match app.on_frame(ev, &mut meter) {
            Action::Reply(reply) => match encode_frame(&reply, &mut out) {
                Ok(frame) => uart.write_all(frame),
                // MAX_FRAME is sized for the largest reply; reaching this is a bug, so say so loudly and
                // exit with the panic code, without a panic (no panicking path: `cargo xtask no-panic`).
                Err(_) => {
                    error!("reply does not fit MAX_FRAME");
                    semihosting::process::exit(exit_code::PANIC)
                }
            },
            Action::Shutdown => {
                let s = app.stats();
                info!(
                    "shutdown: ok={=u32} out_of_envelope={=u32} bad_frames={=u32} rejected={=u32} max_cost={=u32} stack_peak={=u32}",
                    s.ok,
                    s.out_of_envelope,
                    s.bad_frames,
                    s.rejected,
                    s.max_cost,
                    firmware::stack::peak_bytes()
                );
                semihosting::process::exit(exit_code::SUCCESS)
            }
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
