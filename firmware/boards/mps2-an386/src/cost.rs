//! The mps2-an386 board's step-cost meter: the cost of a control step in guest instructions, measured with
//! SysTick.
//!
//! # Conversion
//! Under `qemu-system-arm -icount shift=0` every guest instruction advances QEMU's virtual clock by
//! 2^0 = 1 ns, whatever the host's speed. SysTick, clocked from the core clock (`CLKSOURCE = 1`), counts
//! at the mps2-an386 system clock of 25 MHz, one tick per 40 ns of virtual time, so
//!
//! ```text
//! instructions = ticks × 1e9 / (25e6 × 2^shift) = ticks × 40      (shift = 0)
//! ```
//!
//! The resolution is one tick, 40 instructions: a step reported as `40 t` executed between `40 (t − 1)`
//! and `40 (t + 1)` instructions. The two reads of the counter themselves add a few instructions, well
//! under one tick. [`calibrate`] checks the factor at boot against a loop of known length, and the HIL
//! tests assert it. On real silicon the same ticks are CPU cycles, not instructions.
//!
//! SysTick is 24 bits wide and free-running here (reload `0xFF_FFFF`): a measurement is exact for steps
//! shorter than 2^24 ticks (≈ 671 million instructions), far beyond any bounded control step.

use control_loop::board::Meter;
use core::sync::atomic::{compiler_fence, Ordering};
use cortex_m::peripheral::{syst::SystClkSource, SYST};

/// Core (and SysTick) clock of mps2-an386 in QEMU.
pub const SYSCLK_HZ: u32 = 25_000_000;
/// Virtual nanoseconds per instruction under `-icount shift=0`.
pub const NS_PER_INSTRUCTION: u32 = 1;
/// Instructions per SysTick tick: 1e9 / (SYSCLK_HZ · NS_PER_INSTRUCTION).
pub const INSTRUCTIONS_PER_TICK: u32 = 1_000_000_000 / SYSCLK_HZ / NS_PER_INSTRUCTION;

const MASK: u32 = 0x00FF_FFFF;

/// SysTick as a free-running 24-bit down-counter at the core clock.
pub struct SysTickMeter {
    _syst: SYST,
}

impl SysTickMeter {
    /// Takes SysTick and starts it free-running from the core clock, without interrupts.
    pub fn new(mut syst: SYST) -> Self {
        syst.disable_interrupt();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(MASK);
        syst.clear_current();
        syst.enable_counter();
        Self { _syst: syst }
    }

    /// Ticks elapsed while running `f`.
    pub fn ticks<R>(&mut self, f: impl FnOnce() -> R) -> (R, u32) {
        compiler_fence(Ordering::SeqCst);
        let start = SYST::get_current();
        compiler_fence(Ordering::SeqCst);
        let r = core::hint::black_box(f());
        compiler_fence(Ordering::SeqCst);
        let end = SYST::get_current();
        compiler_fence(Ordering::SeqCst);
        // Down-counter: elapsed = start - end, modulo 2^24.
        (r, start.wrapping_sub(end) & MASK)
    }
}

impl Meter for SysTickMeter {
    fn measure<R>(&mut self, f: impl FnOnce() -> R) -> (R, u32) {
        let (r, t) = self.ticks(f);
        (r, t.saturating_mul(INSTRUCTIONS_PER_TICK))
    }
}

/// Runs a loop of exactly `2 × iterations` instructions (`subs` + `bne`, `iterations` ≥ 1) and returns the
/// ticks it took, so that `ticks × INSTRUCTIONS_PER_TICK ≈ 2 × iterations` can be checked.
pub fn calibrate(meter: &mut SysTickMeter, iterations: u32) -> u32 {
    let n = iterations.max(1);
    let ((), ticks) = meter.ticks(|| {
        // SAFETY: register-only loop; no memory, no stack.
        unsafe {
            core::arch::asm!(
                "2:",
                "subs {0}, #1",
                "bne 2b",
                inout(reg) n => _,
                options(nomem, nostack),
            );
        }
    });
    ticks
}
