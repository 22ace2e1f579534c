//! Polled driver for the Arm CMSDK APB UART, as on the MPS2 boards (UART0 of AN385/AN386 at
//! `0x4000_4000`). Five registers: DATA, STATE, CTRL, INTSTATUS, BAUDDIV.
//!
//! Hand-written: there is no maintained crate for this IP block (no PAC covers the MPS2 FPGA images), and
//! the whole driver is a few volatile register accesses.

use control_loop::board::Link;
use core::ptr::{read_volatile, write_volatile};

/// Base address of UART0 on mps2-an386.
pub const UART0_BASE: usize = 0x4000_4000;

const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const BAUDDIV: usize = 0x10;

const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;

/// Clock of the APB peripherals on the MPS2 (same as the CPU clock in QEMU's model).
pub const PCLK_HZ: u32 = 25_000_000;

/// One CMSDK UART, polled (no interrupts).
pub struct Uart {
    base: usize,
}

impl Uart {
    /// Enables transmitter and receiver at `baud`.
    ///
    /// # Safety
    /// `base` must be the address of a CMSDK APB UART that nothing else uses.
    pub unsafe fn new(base: usize, baud: u32) -> Self {
        let uart = Self { base };
        // The divisor must be at least 16 (QEMU's model refuses to run below that, like the hardware).
        let div = (PCLK_HZ / baud.max(1)).max(16);
        unsafe {
            uart.write(BAUDDIV, div);
            uart.write(CTRL, CTRL_TX_EN | CTRL_RX_EN);
        }
        uart
    }

    unsafe fn read(&self, off: usize) -> u32 {
        unsafe { read_volatile((self.base + off) as *const u32) }
    }

    unsafe fn write(&self, off: usize, v: u32) {
        unsafe { write_volatile((self.base + off) as *mut u32, v) }
    }

    /// Blocks until a byte arrives.
    pub fn read_byte(&mut self) -> u8 {
        // SAFETY: `new`'s contract: the registers of a UART we own.
        unsafe {
            while self.read(STATE) & STATE_RX_FULL == 0 {}
            self.read(DATA) as u8
        }
    }

    /// Sends all bytes, blocking while the transmit buffer is full.
    pub fn write_all(&mut self, bytes: &[u8]) {
        for &b in bytes {
            // SAFETY: as above.
            unsafe {
                while self.read(STATE) & STATE_TX_FULL != 0 {}
                self.write(DATA, b as u32);
            }
        }
    }
}

impl Link for Uart {
    fn read_byte(&mut self) -> u8 {
        Uart::read_byte(self)
    }
    fn write_all(&mut self, bytes: &[u8]) {
        Uart::write_all(self, bytes)
    }
}
