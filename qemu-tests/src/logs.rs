//! Decodes the firmware's defmt log stream (semihosting output) with the table in its ELF, and records each
//! session's stack high-water mark for the boards' RAM budget (`cargo xtask test`).

use crate::HilError;
use defmt_decoder::{DecodeError, Table};

/// One decoded log line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogLine {
    /// `TRACE` … `ERROR`, or empty for `println`.
    pub level: String,
    /// The formatted message.
    pub message: String,
}

impl std::fmt::Display for LogLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:<5} {}", self.level, self.message)
    }
}

/// Decodes every complete frame in `stream` (the bytes the firmware wrote through semihosting).
/// Malformed frames are skipped when the encoding can resynchronise (rzcobs), else decoding stops there.
pub fn decode(elf: &[u8], stream: &[u8]) -> Result<Vec<LogLine>, HilError> {
    let table = Table::parse(elf)
        .map_err(|e| HilError::Defmt(format!("reading the defmt table: {e}")))?
        .ok_or_else(|| HilError::Defmt("the ELF has no .defmt section".into()))?;
    let can_recover = table.encoding().can_recover();
    let mut decoder = table.new_stream_decoder();
    decoder.received(stream);
    let mut lines = Vec::new();
    loop {
        match decoder.decode() {
            Ok(frame) => lines.push(LogLine {
                level: frame
                    .level()
                    .map(|l| l.as_str().to_uppercase())
                    .unwrap_or_default(),
                message: frame.display_message().to_string(),
            }),
            Err(DecodeError::UnexpectedEof) => break,
            Err(DecodeError::Malformed) if can_recover => continue,
            Err(DecodeError::Malformed) => {
                return Err(HilError::Defmt(
                    "malformed frame in a stream that cannot resynchronise".into(),
                ))
            }
        }
    }
    Ok(lines)
}

/// The `stack_peak=` value of the firmware's shutdown line, in bytes.
pub fn stack_peak(logs: &[LogLine]) -> Option<u64> {
    logs.iter()
        .filter(|l| l.message.starts_with("shutdown:"))
        .find_map(|l| {
            l.message
                .split_whitespace()
                .find_map(|w| w.strip_prefix("stack_peak="))
        })
        .and_then(|v| v.parse().ok())
}

/// The file every session's stack high-water mark is appended to (`<elf> <bytes>` per line):
/// `<target>/hil/stack-peaks.txt`. `cargo xtask test` empties it before the HIL suite and takes the
/// largest figure as the loop's stack for the boards' RAM budget.
pub fn stack_peaks_file() -> std::path::PathBuf {
    crate::hil_dir().join("stack-peaks.txt")
}

/// Appends one session's stack high-water mark to [`stack_peaks_file`]. Best effort: a record that cannot
/// be written is reported on stderr, and the budget check then fails for want of figures, not this test.
pub fn record_stack_peak(elf: &std::path::Path, peak: u64) {
    use std::io::Write as _;
    let path = stack_peaks_file();
    let name = elf.file_name().unwrap_or_default().to_string_lossy();
    let written = std::fs::create_dir_all(crate::hil_dir()).and_then(|()| {
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)?;
        // One write per line (O_APPEND): lines of concurrent tests do not interleave.
        f.write_all(format!("{name} {peak}\n").as_bytes())
    });
    if let Err(e) = written {
        eprintln!(
            "qemu-tests: recording the stack peak in {}: {e}",
            path.display()
        );
    }
}
