//! Builds the firmware of the mps2-an386 board for a given controller image and keeps a copy of each ELF.
//!
//! The build runs `cargo build --release` with its working directory in `firmware/boards/mps2-an386/`
//! (cargo reads the `.cargo/config.toml` there and in `firmware/`: target, linker scripts, runner), passing
//! the image path in
//! `CONTROLLER_IMAGE`. Builds are serialised within the process (they share `firmware/target`), and each
//! configuration is built once per process; the resulting ELF is copied to `<target>/hil/<name>.elf` so
//! that later builds with other images do not overwrite it.

use crate::{hil_dir, workspace_root, HilError};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;

/// How to build one firmware.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct FirmwareConfig {
    /// Controller image file (`CONTROLLER_IMAGE`); `None` for the firmware's default test image.
    pub image: Option<PathBuf>,
    /// Input dimension of the build-time fallback when the image is rejected (`CONTROLLER_REJECTED_M`).
    pub rejected_m: Option<usize>,
    /// `FIRMWARE_FAULT_INJECTION`: `"panic"` or `"hardfault"` to build a firmware that faults at boot.
    pub fault_injection: Option<&'static str>,
}

static BUILDS: Mutex<Option<HashMap<FirmwareConfig, PathBuf>>> = Mutex::new(None);

/// The board the HIL suite runs: the one `qemu-system-arm -machine mps2-an386` emulates.
pub const BOARD: &str = "mps2-an386";

/// The firmware workspace's directory.
pub fn firmware_dir() -> PathBuf {
    workspace_root().join("firmware")
}

/// The board's folder, where the build runs.
pub fn board_dir() -> PathBuf {
    firmware_dir().join("boards").join(BOARD)
}

/// Where cargo puts the board's release ELF (the firmware workspace's target directory).
pub fn built_elf() -> PathBuf {
    firmware_dir()
        .join("target")
        .join("thumbv7em-none-eabihf")
        .join("release")
        .join(BOARD)
}

/// Builds the firmware for `config` (once per process) and returns the path of its ELF copy
/// `<target>/hil/<name>.elf`.
pub fn build(name: &str, config: &FirmwareConfig) -> Result<PathBuf, HilError> {
    // A poisoned lock only means another test panicked mid-build; the map is still consistent.
    let mut guard = BUILDS.lock().unwrap_or_else(|e| e.into_inner());
    let map = guard.get_or_insert_with(HashMap::new);
    if let Some(elf) = map.get(config) {
        return Ok(elf.clone());
    }
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(&cargo);
    cmd.current_dir(board_dir()).args(["build", "--release"]);
    // The outer cargo's settings must not leak into the firmware build.
    for var in [
        "CARGO_TARGET_DIR",
        "CARGO_BUILD_TARGET",
        "CARGO_BUILD_TARGET_DIR",
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "CARGO_BUILD_RUSTFLAGS",
    ] {
        cmd.env_remove(var);
    }
    match &config.image {
        Some(p) => cmd.env("CONTROLLER_IMAGE", absolute(p)?),
        None => cmd.env_remove("CONTROLLER_IMAGE"),
    };
    match config.rejected_m {
        Some(m) => cmd.env("CONTROLLER_REJECTED_M", m.to_string()),
        None => cmd.env_remove("CONTROLLER_REJECTED_M"),
    };
    match config.fault_injection {
        Some(f) => cmd.env("FIRMWARE_FAULT_INJECTION", f),
        None => cmd.env_remove("FIRMWARE_FAULT_INJECTION"),
    };
    let command = format!(
        "cd {} && {:?} build --release",
        board_dir().display(),
        cargo
    );
    let out = cmd
        .output()
        .map_err(HilError::io(format!("running {command}")))?;
    if !out.status.success() {
        return Err(HilError::Build {
            command,
            stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        });
    }
    let dir = hil_dir();
    std::fs::create_dir_all(&dir).map_err(HilError::io(format!("creating {}", dir.display())))?;
    let elf = dir.join(format!("{name}.elf"));
    std::fs::copy(built_elf(), &elf).map_err(HilError::io(format!(
        "copying the ELF to {}",
        elf.display()
    )))?;
    map.insert(config.clone(), elf.clone());
    Ok(elf)
}

fn absolute(p: &Path) -> Result<PathBuf, HilError> {
    std::path::absolute(p).map_err(HilError::io(format!("resolving {}", p.display())))
}

/// Writes `bytes` to `<target>/hil/images/<name>.bin` and returns the path.
pub fn write_image(name: &str, bytes: &[u8]) -> Result<PathBuf, HilError> {
    let dir = hil_dir().join("images");
    std::fs::create_dir_all(&dir).map_err(HilError::io(format!("creating {}", dir.display())))?;
    let path = dir.join(format!("{name}.bin"));
    std::fs::write(&path, bytes).map_err(HilError::io(format!("writing {}", path.display())))?;
    Ok(path)
}
