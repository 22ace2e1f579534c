//! What a board gives the loop: a byte link to the plant, a step-cost meter and a stack high-water mark.
//! Each board's folder implements these over its own peripherals; the host tests implement them over
//! buffers.

/// The byte link to the plant: the board's UART, polled.
pub trait Link {
    /// Blocks until a byte arrives. A byte the hardware lost (overrun, framing or noise error) is not
    /// delivered: the frame it belonged to then fails to decode and is answered `BadFrame`.
    fn read_byte(&mut self) -> u8;
    /// Sends all bytes, blocking until each is accepted by the transmitter.
    fn write_all(&mut self, bytes: &[u8]);
}

/// Something that can run a closure and say what it cost. The unit is the board's: guest instructions
/// under QEMU `-icount` (mps2-an386), CPU cycles on silicon (nucleo-f446re); it is what `Reply::cost`
/// carries.
pub trait Meter {
    /// Runs `f`, returning its result and its cost.
    fn measure<R>(&mut self, f: impl FnOnce() -> R) -> (R, u32);
}

/// The stack used so far.
pub trait StackMeter {
    /// Bytes of stack used since reset (the high-water mark).
    fn peak_bytes(&self) -> u32;
}
