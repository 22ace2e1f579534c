//! `export --c`: the self-contained C99 evaluator and the image as a `const` array.
//!
//! Writes four files into the output directory:
//! * `controller.h`, `controller.c`: the evaluator (templates `export/c/controller.{h,c}`, with the
//!   capacities of `shared_types::capacity` and the format version filled in, so they cannot drift);
//! * `controller_image.h`, `controller_image.c`: `sc_image_bytes` (the image bytes, unchanged),
//!   `sc_image_len`, and `SC_IMAGE_MONITOR_WORDS`, the arena the image's monitor needs (section 14,
//!   `MonitorProgram::words`; 0 without one), so that a C firmware sizes it statically.
//!
//! The image is decoded before anything is written, so a rejected image writes nothing; an image with a
//! section the C evaluator does not implement ([`C_SECTION_KINDS`]) is refused too, since the C would
//! refuse it at `sc_init`.

use std::path::{Path, PathBuf};

use shared_types::image::{decode, directory, ImageError, Mode, FORMAT_VERSION};
use shared_types::{capacity, monitor};

/// The evaluator's header template.
pub const CONTROLLER_H: &str = include_str!("c/controller.h");
/// The evaluator's source template.
pub const CONTROLLER_C: &str = include_str!("c/controller.c");

/// The section kinds `controller.c` decodes and evaluates (tags 1–11: locations, fallback, trajectories,
/// segments, steps, PWA laws, tree and balls, segment exits, model maps, terminal law; 12: the spec
/// fingerprint, whose length it checks and which it does not evaluate; 13: the selection test; 14: the
/// task's monitor, validated by `sc_init` and evaluated by `sc_monitor_update`). A section kind added to
/// the format must be added to the C (decoder and evaluator, and the harness's images) before it is added
/// here.
pub const C_SECTION_KINDS: [u16; 14] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14];

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The bytes are not a valid image.
    #[error("the image is rejected: {0}")]
    Rejected(ImageError),
    /// The image has a section the C evaluator does not implement.
    #[error(
        "the image has a section of kind {kind}, which the C evaluator does not implement (it knows kinds 1 to 14)"
    )]
    UnsupportedSection {
        /// The section's kind tag.
        kind: u16,
    },
    /// A file could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file or directory.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// One generated file: its name and content.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CFile {
    /// File name (no directory).
    pub name: &'static str,
    /// Content.
    pub text: String,
}

/// The template with every `@NAME@` placeholder replaced.
fn fill(template: &str) -> String {
    let values: [(&str, usize); 30] = [
        ("FORMAT_VERSION", FORMAT_VERSION as usize),
        ("MAX_N", capacity::MAX_N),
        ("MAX_M", capacity::MAX_M),
        ("MAX_LOCATIONS", capacity::MAX_LOCATIONS),
        ("MAX_TRAJECTORIES", capacity::MAX_TRAJECTORIES),
        ("MAX_STEPS", capacity::MAX_STEPS),
        ("MAX_TABLE_VALUES", capacity::MAX_TABLE_VALUES),
        ("MAX_SEGMENTS", capacity::MAX_SEGMENTS),
        ("MAX_SECTIONS", capacity::MAX_SECTIONS),
        ("MAX_PARTITIONS", capacity::MAX_PARTITIONS),
        ("MAX_TREE_DEPTH", capacity::MAX_TREE_DEPTH),
        ("MAX_TREE_NODES", capacity::MAX_TREE_NODES),
        ("MAX_LEAVES", capacity::MAX_LEAVES),
        ("MAX_BALLS", capacity::MAX_BALLS),
        ("MAX_BALL_REFS", capacity::MAX_BALL_REFS),
        ("MAX_LEAF_BALLS", capacity::MAX_LEAF_BALLS),
        (
            "SPEC_FINGERPRINT_LEN",
            shared_types::image::SPEC_FINGERPRINT_LEN,
        ),
        ("MAX_PROGRAM_LEN", capacity::MAX_PROGRAM_LEN),
        ("MAX_PROGRAM_CONSTS", capacity::MAX_PROGRAM_CONSTS),
        ("MAX_PROGRAM_INPUTS", capacity::MAX_PROGRAM_INPUTS),
        ("MAX_PROGRAM_OUTPUTS", capacity::MAX_PROGRAM_OUTPUTS),
        ("MAX_PROGRAM_STACK", capacity::MAX_PROGRAM_STACK),
        ("MAX_PROGRAM_REGS", capacity::MAX_PROGRAM_REGS),
        ("MAX_EXT", capacity::MAX_EXT),
        (
            "MAX_PROGRAM_POWI",
            capacity::MAX_PROGRAM_POWI.unsigned_abs() as usize,
        ),
        ("MAX_MONITOR_ATOMS", monitor::MAX_MONITOR_ATOMS),
        ("MAX_MONITOR_NODES", monitor::MAX_MONITOR_NODES),
        ("MAX_MONITOR_SAMPLES", monitor::MAX_MONITOR_SAMPLES),
        ("MAX_MONITOR_ROWS", monitor::MAX_MONITOR_ROWS),
        ("MAX_MONITOR_WORDS", monitor::MAX_MONITOR_WORDS),
    ];
    let mut out = template.to_string();
    for (name, v) in values {
        out = out.replace(&format!("@{name}@"), &v.to_string());
    }
    out
}

/// The files of the C export of `image` (validated first with the firmware's decoder).
pub fn files(image: &[u8]) -> Result<Vec<CFile>, ExportError> {
    let img = decode(image).map_err(ExportError::Rejected)?;
    let dir = directory(image).map_err(ExportError::Rejected)?;
    for i in 0..dir.len() {
        if let Some(e) = dir.entry(i) {
            if !C_SECTION_KINDS.contains(&e.kind) {
                return Err(ExportError::UnsupportedSection { kind: e.kind });
            }
        }
    }
    let mode = match img.mode() {
        Mode::Feedforward => "feedforward",
        Mode::PwaFeedback => "PWA feedback",
        _ => "unknown",
    };
    let maps = match img.model_maps() {
        Some(mm) => format!(
            ", model maps (plant n = {}, m = {}{})",
            mm.n_plant(),
            mm.m_plant(),
            match mm.n_ext() {
                0 => String::new(),
                k => format!(", {k} controller state(s)"),
            }
        ),
        None => String::new(),
    };
    let monitor_words = img.monitor().map_or(0, |p| p.words());
    let monitor_note = match img.monitor() {
        Some(p) => format!(
            ", a monitor ({} atom(s), {} node(s), N = {}, arena {monitor_words} words)",
            p.atoms(),
            p.nodes(),
            p.horizon()
        ),
        None => String::new(),
    };
    let summary = format!(
        "{} bytes, {mode}, n = {}, m = {}{maps}{monitor_note}, {} location(s), CRC-32 {:#010x}",
        image.len(),
        img.n(),
        img.m(),
        img.n_locations(),
        u32::from_le_bytes([image[28], image[29], image[30], image[31]]),
    );
    let image_h = format!(
        "/* controller_image.h: the controller image (generated by `host-compiler export --c`).\n \
         * {summary}. */\n\
         #ifndef SC_CONTROLLER_IMAGE_H\n#define SC_CONTROLLER_IMAGE_H\n\n#include <stdint.h>\n\n\
         /* The image bytes, exactly as the Rust toolchain wrote them; pass them to sc_init. */\n\
         extern const uint8_t sc_image_bytes[{len}];\n\
         extern const uint32_t sc_image_len;\n\n\
         /* The arena the image's monitor needs, in 32-bit words (sc_monitor_words; 0: no monitor). */\n\
         #define SC_IMAGE_MONITOR_WORDS {monitor_words}u\n\n#endif /* SC_CONTROLLER_IMAGE_H */\n",
        len = image.len()
    );
    let mut image_c = format!(
        "/* controller_image.c: the controller image (generated by `host-compiler export --c`).\n \
         * {summary}. sc_init checks its CRC and everything else before use. */\n\
         #include \"controller_image.h\"\n\n\
         const uint32_t sc_image_len = {len}u;\n\n\
         const uint8_t sc_image_bytes[{len}] = {{\n",
        len = image.len()
    );
    for chunk in image.chunks(16) {
        image_c.push_str("   ");
        for b in chunk {
            image_c.push_str(&format!(" 0x{b:02x},"));
        }
        image_c.push('\n');
    }
    image_c.push_str("};\n");
    Ok(vec![
        CFile {
            name: "controller.h",
            text: fill(CONTROLLER_H),
        },
        CFile {
            name: "controller.c",
            text: fill(CONTROLLER_C),
        },
        CFile {
            name: "controller_image.h",
            text: image_h,
        },
        CFile {
            name: "controller_image.c",
            text: image_c,
        },
    ])
}

/// Writes the C export of `image` into `dir` (created if missing); returns the paths written.
pub fn write(image: &[u8], dir: &Path) -> Result<Vec<PathBuf>, ExportError> {
    let files = files(image)?;
    std::fs::create_dir_all(dir).map_err(|source| ExportError::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::with_capacity(files.len());
    for f in files {
        let path = dir.join(f.name);
        std::fs::write(&path, f.text).map_err(|source| ExportError::Write {
            path: path.clone(),
            source,
        })?;
        written.push(path);
    }
    Ok(written)
}
