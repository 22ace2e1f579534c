//! Build script of the mps2-an386 board:
//! 1. copies the board's memory map `memory.x` into `OUT_DIR` (cortex-m-rt's `link.x` includes it);
//! 2. `FIRMWARE_FAULT_INJECTION=panic|hardfault` builds a test firmware that faults on purpose at boot
//!    (the HIL suite checks that faults exit QEMU with failure).
//!
//! The controller image is embedded by the control loop's build script (`CONTROLLER_IMAGE`).

use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let memory_x = manifest.join("memory.x");
    std::fs::copy(&memory_x, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=FIRMWARE_FAULT_INJECTION");

    println!("cargo::rustc-check-cfg=cfg(fault_injection, values(\"panic\", \"hardfault\"))");
    match std::env::var("FIRMWARE_FAULT_INJECTION").as_deref() {
        Ok(kind @ ("panic" | "hardfault")) => {
            println!("cargo:rustc-cfg=fault_injection=\"{kind}\"")
        }
        Ok("") | Err(_) => {}
        Ok(other) => panic!("FIRMWARE_FAULT_INJECTION={other:?}: expected panic or hardfault"),
    }
}
