//! Fuzz target `image_decode`: `host_compiler::fuzz::image` on every input (the replay test runs the same function
//! on the committed corpus).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| host_compiler::fuzz::image(data));
