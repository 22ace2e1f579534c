//! Controller image format (versioned, CRC-checked, a header and a directory of typed postcard sections)
//! and the evaluator that both the host verifier and the firmware run. `no_std`, no allocation, never
//! panics on bad data (DESIGN §5).
//!
//! * [`capacity`]: compile-time capacities bounding every image and every runtime loop;
//! * [`layout`]: the format's vocabulary (magic, version, [`layout::Mode`], [`layout::SectionKind`]);
//! * [`error`]: the `Copy` error [`error::ImageError`] every check returns;
//! * [`header`]: the fixed header, the CRC and the section directory (parsing and writing);
//! * [`image`]: the content, [`image::encode`] and the validating zero-copy [`image::decode`];
//! * [`pwa`]: the PWA-feedback tables (Ch. 6), their validation and bounded-depth point location;
//! * [`eval`]: the f32 evaluator ([`eval::Controller`]), [`eval::Status`] and [`eval::Input`];
//! * `linalg`: the evaluator's matrix–vector products on nalgebra views, and their summation order;
//! * [`program`]: model programs, the validated `f32` stack bytecode of a nonlinear plant's maps;
//! * [`trig`]: their sine and cosine in f32 arithmetic only (libm's evaluate in f64);
//! * [`maps`]: the model maps section (`coords: x ↦ ξ`, `input_map: (x, w) ↦ u`) of a
//!   feedback-linearizable plant's image;
//! * [`selection`]: the optional whitened selection test of an image with model maps;
//! * [`monitor`]: the task's bounded MTL formula evaluated online with its robustness bounds and verdict
//!   (the program of the optional monitor section and its streaming evaluator over a sized arena);
//! * [`terminal`]: the optional terminal law, a certified law with its invariant ellipsoid in Goal for
//!   after the task;
//! * [`protocol`]: the UART protocol between plant and firmware.
#![no_std]

pub mod budgets;
pub mod capacity;
pub mod error;
pub mod eval;
pub mod header;
pub mod image;
pub mod layout;
mod linalg;
pub mod maps;
pub mod monitor;
pub mod program;
pub mod protocol;
pub mod pwa;
mod raw;
pub mod selection;
pub mod terminal;
pub mod trig;
