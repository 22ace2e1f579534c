//! A fuzz smoke run on the stable toolchain, so `cargo xtask test` (and CI, which has no nightly and no
//! cargo-fuzz) mutates inputs too, not only replays them (`fuzz_corpus.rs`). For each of the five fuzz
//! targets, a seeded (ChaCha8) byte-level mutator (bit flips, byte insertion, deletion and replacement
//! by random or boundary values, chunk duplication, truncation, and splicing two corpus entries) stacks
//! one to four mutations on an entry of the committed corpus (`fuzz/corpus/<target>/`) and runs the result
//! through the function that target's cargo-fuzz harness calls (`host_compiler::fuzz`), for a fixed
//! number of executions per target ([`TARGETS`]). A panic fails the test with the input written to a file
//! and printed in hex.
//!
//! This is a smoke check, not the campaign: a few thousand blind mutations per target find what a
//! change broke in an obvious way; the coverage-guided cargo-fuzz campaigns (`fuzz/CAMPAIGN.md`, ≥ 10⁷
//! executions per target) are what the fuzzing claims rest on.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

/// The largest mutated input tried (bytes): larger ones are cut, so that one input stays cheap.
const MAX_LEN: usize = 64 * 1024;

/// What a fuzz target runs on one input.
type Entry = fn(&[u8]);

/// The targets, the function each runs (the same as `fuzz/fuzz_targets/*.rs`) and the mutated inputs
/// run. The counts keep the whole smoke near 10 s in the test profile on two shared cores (measured on
/// the development machine: 3 to 5 µs per input for the image, CSV, MTL and frame targets, 33 µs for the
/// spec parser); the test prints each target's time.
const TARGETS: [(&str, Entry, usize); 5] = [
    ("image_decode", host_compiler::fuzz::image, 300_000),
    ("spec_parse", host_compiler::fuzz::spec, 150_000),
    ("csv_readers", host_compiler::fuzz::csv, 300_000),
    ("mtl_parse", host_compiler::fuzz::mtl, 300_000),
    ("uart_frame", host_compiler::fuzz::uart, 300_000),
];

/// The committed corpus of `target`, in file-name order (so the run is the same on every machine).
fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
        .iter()
        .map(|p| std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .collect()
}

/// Byte values that sit on boundaries (sign bits, lengths, ASCII delimiters).
const INTERESTING: [u8; 12] = [
    0x00, 0x01, 0x7f, 0x80, 0xff, b'\n', b',', b'"', b'[', b'(', b'-', b'9',
];

/// One to four stacked mutations of `base` (module doc); `other` is the splice partner.
fn mutate(rng: &mut ChaCha8Rng, base: &[u8], other: &[u8]) -> Vec<u8> {
    let mut d = base.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        let len = d.len();
        match rng.random_range(0..8) {
            // Flip one bit.
            0 if len > 0 => {
                let i = rng.random_range(0..len);
                d[i] ^= 1 << rng.random_range(0..8);
            }
            // Replace a byte by a random one.
            1 if len > 0 => {
                let i = rng.random_range(0..len);
                d[i] = rng.random();
            }
            // Replace a byte by a boundary value.
            2 if len > 0 => {
                let i = rng.random_range(0..len);
                d[i] = INTERESTING[rng.random_range(0..INTERESTING.len())];
            }
            // Insert a byte.
            3 => {
                let i = rng.random_range(0..=len);
                d.insert(i, INTERESTING[rng.random_range(0..INTERESTING.len())]);
            }
            // Delete a run of bytes.
            4 if len > 0 => {
                let i = rng.random_range(0..len);
                let k = rng.random_range(1..=(len - i).min(16));
                d.drain(i..i + k);
            }
            // Duplicate a chunk in place.
            5 if len > 0 => {
                let i = rng.random_range(0..len);
                let k = rng.random_range(1..=(len - i).min(64));
                let chunk = d[i..i + k].to_vec();
                d.splice(i..i, chunk);
            }
            // Truncate.
            6 if len > 0 => d.truncate(rng.random_range(0..len)),
            // Splice: this input's head, the other's tail.
            _ => {
                let i = rng.random_range(0..=d.len());
                let j = rng.random_range(0..=other.len());
                d.truncate(i);
                d.extend_from_slice(&other[j..]);
            }
        }
    }
    d.truncate(MAX_LEN);
    d
}

/// Writes a crashing input where the test run keeps its files, and returns the path.
fn keep(target: &str, i: usize, data: &[u8]) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("fuzz-smoke-{target}-{i}.bin"));
    // If even that fails the hex below still shows the input.
    let _ = std::fs::write(&p, data);
    p
}

/// Runs `executions` mutated inputs of `entries` through `run`, seeded by `seed`; a panic panics again
/// with the input kept in a file and printed in hex.
fn smoke(target: &str, run: Entry, executions: usize, entries: &[Vec<u8>], seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for i in 0..executions {
        let a = &entries[rng.random_range(0..entries.len())];
        let b = &entries[rng.random_range(0..entries.len())];
        let data = mutate(&mut rng, a, b);
        if std::panic::catch_unwind(|| run(&data)).is_err() {
            let p = keep(target, i, &data);
            let hex: String = data.iter().map(|b| format!("{b:02x}")).collect();
            panic!(
                "{target}: execution {i} panicked; input ({} bytes) written to {}: {hex}",
                data.len(),
                p.display()
            );
        }
    }
}

#[test]
fn mutated_corpus_inputs_do_not_crash_any_target() {
    for (t, (target, run, executions)) in TARGETS.into_iter().enumerate() {
        let entries = corpus(target);
        assert!(!entries.is_empty(), "fuzz/corpus/{target} is empty");
        let start = std::time::Instant::now();
        smoke(target, run, executions, &entries, 0x5e0c_e000 + t as u64);
        eprintln!(
            "{target}: {executions} mutated inputs from {} corpus entries in {:.2} s, no crash",
            entries.len(),
            start.elapsed().as_secs_f64()
        );
    }
}

/// A target that panics: the smoke fails naming the input's file (which holds the input) and its hex.
#[test]
fn a_crash_is_kept_in_a_file_and_printed() {
    fn crashes(d: &[u8]) {
        assert!(
            d.len() > 1_000_000,
            "deliberate crash of the smoke's self-test"
        );
    }
    let entries = vec![b"seed".to_vec()];
    let err = std::panic::catch_unwind(|| smoke("self_test", crashes, 10, &entries, 1))
        .expect_err("the smoke reports the crash");
    let msg = err.downcast_ref::<String>().cloned().unwrap_or_default();
    assert!(msg.contains("self_test: execution 0 panicked"), "{msg}");
    let path = msg
        .split("written to ")
        .nth(1)
        .and_then(|r| r.split(": ").next())
        .expect("the file is named");
    let kept = std::fs::read(path).expect("the input was kept");
    let hex: String = kept.iter().map(|b| format!("{b:02x}")).collect();
    assert!(msg.ends_with(&hex), "{msg}");
}
