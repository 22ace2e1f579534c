//! Controller image format (versioned, CRC-checked, postcard payload) and the evaluator that both the host
//! verifier and the firmware run. `no_std`, no allocation, never panics on bad data (DESIGN §4).
#![no_std]

pub mod protocol;
