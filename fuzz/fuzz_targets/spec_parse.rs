//! Fuzz target `spec_parse`: `host_compiler::fuzz::spec` on every input (the replay test runs the same function
//! on the committed corpus).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| host_compiler::fuzz::spec(data));
