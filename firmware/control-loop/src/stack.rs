//! Stack high-water mark on a Cortex-M board ([`PaintedStack`]). With cortex-m-rt's `paint-stack` feature,
//! the reset handler fills the whole stack region (`_stack_end` .. `_stack_start`, i.e. all RAM after the
//! static data) with [`cortex_m_rt::STACK_PAINT_VALUE`]; the deepest word that no longer holds it bounds
//! the stack used so far. It is a lower bound in principle (a frame slot never written keeps the paint),
//! exact in practice. Reads memory only (linker symbols), no registers, so every board shares it.

use crate::board::StackMeter;
use cortex_m_rt::STACK_PAINT_VALUE;

extern "C" {
    static _stack_start: u32;
    static _stack_end: u32;
}

/// The painted stack of cortex-m-rt's `link.x`.
#[derive(Clone, Copy, Debug, Default)]
pub struct PaintedStack;

/// Bytes of stack used so far (deepest overwritten word to the top of the stack).
pub fn peak_bytes() -> u32 {
    // Only the addresses of the linker symbols are taken (defined by cortex-m-rt's link.x).
    let (bottom, top) = (
        &raw const _stack_end as usize,
        &raw const _stack_start as usize,
    );
    let mut p = bottom;
    while p < top {
        // SAFETY: [bottom, top) is RAM reserved for the stack, word-aligned (link.x asserts it).
        if unsafe { core::ptr::read_volatile(p as *const u32) } != STACK_PAINT_VALUE {
            break;
        }
        p += 4;
    }
    (top - p) as u32
}

impl StackMeter for PaintedStack {
    fn peak_bytes(&self) -> u32 {
        peak_bytes()
    }
}
