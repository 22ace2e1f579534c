//! Controller image format (versioned, CRC-checked, postcard payload) and the evaluator that both the host
//! verifier and the firmware run. `no_std`, no allocation, never panics on bad data (DESIGN §4).
//!
//! * [`capacity`]: compile-time capacities bounding every image and every runtime loop;
//! * [`image`]: the byte layout, [`image::encode`] and the validating zero-copy [`image::decode`];
//! * [`pwa`]: the PWA-feedback tables (Ch. 6), their validation and bounded-depth point location;
//! * [`eval`]: the f32 evaluator ([`eval::Controller`]), [`eval::Status`] and [`eval::Input`];
//! * [`protocol`]: the UART protocol between plant and firmware.
#![no_std]

pub mod capacity;
pub mod eval;
pub mod image;
pub mod protocol;
pub mod pwa;
