//! Build script of the nucleo-f446re board: copies the board's memory map `memory.x` into `OUT_DIR`
//! (cortex-m-rt's `link.x` includes it). The controller image is embedded by the control loop's build
//! script (`CONTROLLER_IMAGE`).

use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let memory_x = manifest.join("memory.x");
    std::fs::copy(&memory_x, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
}
