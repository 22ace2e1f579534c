//! The nucleo-f446re board: ST's NUCLEO-F446RE (STM32F446RE, Cortex-M4F), through stm32f4xx-hal, on the
//! clock it resets to: the internal 16 MHz oscillator ([`SYSCLK_HZ`]). The plant talks to USART2 on PA2 (TX) / PA3 (RX), which the
//! board routes to the on-board ST-LINK's virtual COM port (the USB cable is the only wire), at [`BAUD`]
//! 8N1. The step cost is measured in CPU cycles with the DWT cycle counter ([`CycleMeter`]). Logs go out
//! as defmt over RTT, which `probe-rs run` (the runner in `.cargo/config.toml`) prints.
//!
//! After a `Shutdown` request the board logs the session's counters and starts a new session (sequence
//! numbers from 0 again). A panic, HardFault or unexpected exception is logged and halts the core
//! ([`halt`]): the board stops answering, so the host's timeout sees it.
//!
//! ```text
//! cd firmware/boards/nucleo-f446re
//! CONTROLLER_IMAGE=/path/to/controller.img cargo run --release   # builds, flashes, prints the log
//! ```
#![no_std]
#![no_main]

use control_loop::board::{Link, Meter, StackMeter};
use control_loop::serve::{serve, End};
use control_loop::stack::PaintedStack;
use core::sync::atomic::{compiler_fence, AtomicBool, Ordering};
use cortex_m::peripheral::DWT;
use cortex_m_rt::{entry, exception, ExceptionFrame};
use defmt::{error, info, Display2Format};
use defmt_rtt as _;
use stm32f4xx_hal::pac::{self, USART2};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{self, Serial};

/// USART2 baud rate (8 data bits, no parity, one stop bit), the ST-LINK virtual COM port's.
pub const BAUD: u32 = 115_200;
/// Core clock: the 16 MHz HSI the chip resets to (no dependence on the ST-LINK's MCO or a crystal).
///
/// Not the PLL's 180 MHz: stm32f4xx-hal's clock-tree solver (`Rcc::freeze`) brings 26 panicking paths
/// (asserts, `expect`, divisions) into the image, which the no-panic check refuses. A step's cost in cycles
/// does not depend on the clock (no flash wait states at 16 MHz); its duration is cycles / 16 µs.
pub const SYSCLK_HZ: u32 = 16_000_000;

/// USART2, polled.
struct Vcp(Serial<USART2>);

impl Link for Vcp {
    fn read_byte(&mut self) -> u8 {
        loop {
            match self.0.read() {
                Ok(b) => return b,
                // An overrun, framing or noise error loses a byte: the frame it was in fails to decode.
                Err(nb::Error::WouldBlock) | Err(nb::Error::Other(_)) => {}
            }
        }
    }

    fn write_all(&mut self, bytes: &[u8]) {
        for &b in bytes {
            while self.0.write(b).is_err() {}
        }
    }
}

/// The DWT cycle counter: the cost of a step in CPU cycles. The counter is 32 bits wide and free-running,
/// so a measurement is exact for steps shorter than 2^32 cycles (≈ 268 s at 16 MHz).
struct CycleMeter;

impl Meter for CycleMeter {
    fn measure<R>(&mut self, f: impl FnOnce() -> R) -> (R, u32) {
        compiler_fence(Ordering::SeqCst);
        let start = DWT::cycle_count();
        compiler_fence(Ordering::SeqCst);
        let r = core::hint::black_box(f());
        compiler_fence(Ordering::SeqCst);
        let end = DWT::cycle_count();
        compiler_fence(Ordering::SeqCst);
        (r, end.wrapping_sub(start))
    }
}

#[entry]
fn main() -> ! {
    let (Some(mut cp), Some(dp)) = (cortex_m::Peripherals::take(), pac::Peripherals::take()) else {
        error!("boot: peripherals already taken");
        halt()
    };
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    // The reset clocks (HSI for SYSCLK, AHB, APB1 and APB2), as the HAL's `Clocks::default()` records them.
    let mut rcc = dp.RCC.constrain();
    let gpioa = dp.GPIOA.split(&mut rcc);
    let config = serial::Config::default().baudrate(BAUD.bps());
    let Ok(usart) = dp.USART2.serial((gpioa.pa2, gpioa.pa3), config, &mut rcc) else {
        error!("boot: USART2 refuses {=u32} baud", BAUD);
        halt()
    };
    let mut vcp = Vcp(usart);
    let mut meter = CycleMeter;
    info!(
        "nucleo-f446re: sysclk {=u32} Hz, USART2 {=u32} baud",
        rcc.clocks.sysclk().raw(),
        BAUD
    );
    loop {
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
        info!("ready");
        match serve(&mut app, &mut vcp, &mut meter) {
            End::Shutdown(s) => info!(
                "shutdown: ok={=u32} out_of_envelope={=u32} bad_frames={=u32} rejected={=u32} max_cost={=u32} cycles stack_peak={=u32}",
                s.ok,
                s.out_of_envelope,
                s.bad_frames,
                s.rejected,
                s.max_cost,
                PaintedStack.peak_bytes()
            ),
            End::ReplyTooLarge => {
                error!("reply does not fit MAX_FRAME");
                halt()
            }
        }
    }
}

static FAULTED: AtomicBool = AtomicBool::new(false);

/// Stops the board: a breakpoint (probe-rs stops there and prints the backtrace), then sleep forever.
fn halt() -> ! {
    cortex_m::asm::bkpt();
    loop {
        cortex_m::asm::wfi();
    }
}

#[cfg(not(feature = "panic-never"))]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // Log once; a panic while logging goes straight to the halt.
    if !FAULTED.swap(true, Ordering::SeqCst) {
        error!("panic: {}", Display2Format(info));
    }
    halt()
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
    if !FAULTED.swap(true, Ordering::SeqCst) {
        error!(
            "HardFault at pc={=u32:#010x} lr={=u32:#010x}",
            ef.pc(),
            ef.lr()
        );
    }
    halt()
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if !FAULTED.swap(true, Ordering::SeqCst) {
        error!("unexpected exception {=i16}", irqn);
    }
    halt()
}
