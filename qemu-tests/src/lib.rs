//! Hardware-in-the-loop harness: builds the firmware, boots it in QEMU, and closes the loop over UART.
//!
//! * [`firmware`]: builds the mps2-an386 board's firmware with a given controller image (working
//!   directory `firmware/boards/mps2-an386/`, so that cargo reads the `.cargo/config.toml` files there and
//!   in `firmware/`) and keeps one ELF per configuration;
//! * [`qemu`]: one QEMU `mps2-an386` session: UART0 on a loopback TCP socket, semihosting (defmt) on
//!   QEMU's stdout, kept apart; an overall deadline on every wait, and QEMU killed on drop;
//! * [`logs`]: decodes the defmt stream with the ELF's table (`defmt-decoder`);
//! * [`plant`]: the plant on the host, sampled with `host_compiler::model`'s exact zero-order hold;
//! * [`nonlinear`]: nonlinear plants on the host, flowed over each period by an adaptive ODE solver;
//! * [`closed_loop`]: runs N steps against the plant and the host evaluator, comparing bit for bit;
//! * [`images`]: the test controller images.
//!
//! The integration tests (`tests/hil/`) need `qemu-system-arm` and the `thumbv7em-none-eabihf` target;
//! `cargo xtask test` installs both before it runs them, and without them each test fails saying what is
//! missing.
#![allow(non_snake_case)]

pub mod closed_loop;
pub mod firmware;
pub mod images;
pub mod logs;
pub mod nonlinear;
pub mod plant;
pub mod qemu;

use std::path::PathBuf;
use std::time::Duration;

/// Everything that can go wrong in a HIL session. Messages carry what the person needs to act.
#[derive(Debug, thiserror::Error)]
pub enum HilError {
    #[error("{context}: {source}")]
    Io {
        context: String,
        #[source]
        source: std::io::Error,
    },
    #[error("building the firmware failed ({command}):\n{stderr}")]
    Build { command: String, stderr: String },
    #[error("timed out after {after:?} waiting for {what}")]
    Timeout { what: String, after: Duration },
    #[error("QEMU exited ({status}) while {what}; its stderr:\n{stderr}")]
    QemuExited {
        status: String,
        what: String,
        stderr: String,
    },
    #[error("bad frame from the firmware: {0:?}")]
    Protocol(shared_types::protocol::FrameError),
    #[error("defmt: {0}")]
    Defmt(String),
    #[error("image: {0}")]
    Image(shared_types::image::ImageError),
    #[error("closed loop: {0}")]
    Check(String),
}

impl HilError {
    pub(crate) fn io(context: impl Into<String>) -> impl FnOnce(std::io::Error) -> HilError {
        let context = context.into();
        move |source| HilError::Io { context, source }
    }
}

/// The workspace root (parent of this crate).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Where this harness writes ELF copies and images: `<target>/hil`.
pub fn hil_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"));
    target.join("hil")
}

/// Flash and static RAM of a firmware ELF, in bytes, from its section headers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ElfSize {
    /// Allocated sections with contents (`SHF_ALLOC`, not `SHT_NOBITS`): vector table, code, read-only data
    /// and the initial values of `.data` — what is written to flash.
    pub flash: u64,
    /// Allocated writable sections (`SHF_ALLOC | SHF_WRITE`): `.data`, `.bss`, `.uninit` — static RAM, without
    /// the stack.
    pub ram: u64,
}

/// Sizes the way `size` (Berkeley format) does: flash = text + data, RAM = data + bss.
pub fn elf_size(elf: &[u8]) -> Result<ElfSize, HilError> {
    use object::elf::{SHF_ALLOC, SHF_WRITE};
    use object::{Object, ObjectSection, SectionFlags, SectionKind};
    let file =
        object::File::parse(elf).map_err(|e| HilError::Check(format!("reading the ELF: {e}")))?;
    let mut size = ElfSize { flash: 0, ram: 0 };
    for s in file.sections() {
        let SectionFlags::Elf { sh_flags } = s.flags() else {
            continue;
        };
        if sh_flags & u64::from(SHF_ALLOC) == 0 {
            continue;
        }
        // SHT_NOBITS sections (.bss, .uninit) take no flash.
        let nobits = matches!(
            s.kind(),
            SectionKind::UninitializedData | SectionKind::UninitializedTls
        );
        if !nobits {
            size.flash += s.size();
        }
        if sh_flags & u64::from(SHF_WRITE) != 0 {
            size.ram += s.size();
        }
    }
    Ok(size)
}
