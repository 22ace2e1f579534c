//! Controller firmware for the Arm MPS2-AN386 (Cortex-M4F), as emulated by `qemu-system-arm -machine
//! mps2-an386`.
//!
//! The binary (`src/main.rs`) validates the embedded controller image at boot, then loops: read a
//! COBS-framed request from UART0, evaluate the controller ([`app`]), reply with the input, a status and
//! the step's cost in instructions ([`cost`]). Logs go out as defmt over semihosting, apart from the UART.
//! No heap; every buffer is a fixed array sized by `shared_types::capacity`.
//!
//! # Building and running
//! Build from this directory, so that cargo reads `firmware/.cargo/config.toml` (target, linker scripts,
//! QEMU runner):
//!
//! ```text
//! cd firmware
//! CONTROLLER_IMAGE=/path/to/controller.img cargo build --release   # without it: the default test image
//! cargo run --release                                                # boots it in qemu-system-arm
//! ```
//!
//! `cargo run` puts UART0 on the terminal; the HIL harness (`qemu-tests`) connects it to a socket instead
//! and decodes the defmt log. See `build.rs` for the build-time settings.
#![no_std]

pub mod app;
pub mod cost;
pub mod stack;
pub mod uart;

/// Exit codes reported to QEMU through semihosting (`SYS_EXIT_EXTENDED`); QEMU exits with the same status.
pub mod exit_code {
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
pub const BAUD: u32 = 115_200;
