//! The hardware-in-the-loop tests of qemu-tests, as one test binary (DESIGN §7): the real firmware in QEMU
//! (mps2-an386), the plant on the host. They need qemu-system-arm and the thumbv7em-none-eabihf target
//! (`cargo xtask test` installs both); without them each test fails and says so.

mod board;
mod feedforward;
mod hybrid;
mod mtl;
mod nonlinear;
mod pwa;
