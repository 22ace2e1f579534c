//! Hardware-in-the-loop harness: builds the firmware, boots it in QEMU, and closes the loop over UART.
