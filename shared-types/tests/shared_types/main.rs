//! The integration tests of shared-types, as one test binary (DESIGN §7): the image format and its
//! round trips, the PWA tables, the evaluators of both modes, and decoding of random and mutated bytes.

mod common;
mod decode_fuzz;
mod evaluator;
mod fingerprint;
mod image_format;
mod maps;
mod program;
mod pwa_eval;
mod pwa_format;
mod selection;
mod terminal;
