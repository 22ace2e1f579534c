//! The hardware-in-the-loop tests of qemu-tests, as one test binary (DESIGN §7): the real firmware in QEMU
//! (mps2-an386), the plant on the host. They need qemu-system-arm and the thumbv7em-none-eabihf target
//! (`cargo xtask test` installs both); without them each test fails and says so.
//!
//! With the feature `skip-hil` the binary is empty (`cargo xtask test`'s host step; see Cargo.toml).
#![cfg(not(feature = "skip-hil"))]

mod board;
mod feedforward;
mod hybrid;
mod monitor;
mod mtl;
mod nonlinear;
mod pwa;
