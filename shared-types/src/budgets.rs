//! What every board must fit (issue 16): flash and RAM for the firmware together with its image, and the
//! loop's worst-case stack. Stated here and nowhere else: `cargo xtask budgets` checks every board's
//! linked firmware against them, and `host-compiler synth` warns when an image alone is larger than the
//! flash budget (it then fits no board with its firmware).

/// Flash: code, read-only data, the image, `.data`'s initial values.
pub const FLASH_BYTES: u64 = 128 * 1024;
/// RAM: static data and the loop's worst-case stack.
pub const RAM_BYTES: u64 = 32 * 1024;
/// The loop's worst-case stack alone (bench row `firmware_stack_bytes_bound`).
pub const STACK_BYTES: u64 = 8 * 1024;
