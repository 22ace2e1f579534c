//! Exports of a controller image for other toolchains. Owns [`c`]: the C99 evaluator (a port of
//! `shared_types::eval::Controller` with the validating decoder of `shared_types::image::decode`, kept as
//! template files under `export/c/`) and the image bytes as a `const` array, written for a C firmware to
//! include; it covers every image mode: feedforward (with or without the optional segment exits of
//! section 9, the guard test and segment cursor of `Controller::step_exits`) and PWA feedback. And
//! [`harness`]: the differential check that compiles the exported C with the system compiler and
//! compares it, status and input bit for bit, with the Rust evaluator, on synthetic images of every mode
//! and seeded scenarios (used by the tests and the `c_export` bench).
//!
//! Invariant: the exported C decides exactly what the Rust evaluator decides, on the same image bytes; the
//! bytes (not tables derived from them) are what the C reads, and it refuses whatever `decode` refuses.

pub mod c;
pub mod harness;
