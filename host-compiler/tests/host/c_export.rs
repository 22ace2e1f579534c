//! The C export (`host-compiler export --c`): the exported C99 evaluator, compiled with the system `cc`
//! under the header's flags, against the Rust evaluator, status and every input bit, on ≥ 10⁵ seeded
//! states per image mode (feedforward with one and several locations, both terminal behaviours and every
//! fallback law; PWA with one and several locations); corrupted arrays refused exactly when the Rust
//! decoder refuses them; and the subcommand's exit codes.

use std::path::PathBuf;
use std::process::Command;

use host_compiler::export::harness::{
    feedforward_image, pwa_image, scenario, CHarness, Comparison, Op,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::image::{compute_crc, decode, Terminal};

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("c_export_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// Builds the harness for `image`, runs `states` seeded states and returns the comparison.
fn compare(name: &str, image: &[u8], seed: u64, states: usize) -> Comparison {
    let dir = scratch(name);
    let h = CHarness::build(image, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
    let img = decode(image).expect("valid image");
    let ops = scenario(&img, seed, states);
    let c = h.compare(&ops).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(c.inits, 1, "{name}");
    assert_eq!(
        c.init_mismatches, 0,
        "{name}: the exported array is refused"
    );
    c
}

/// Adds up comparisons and checks that no step differed.
fn check_all(mode: &str, results: &[(&str, Comparison)]) -> usize {
    let mut states = 0;
    for (name, c) in results {
        eprintln!(
            "{mode} {name}: {} states, {} mismatches, by status (ok, out of envelope, bad frame) {:?}",
            c.states,
            c.mismatches,
            &c.by_status[..3]
        );
        assert_eq!(c.mismatches, 0, "{mode} {name}: {:?}", c.first);
        // The scenario must reach every answer, or the comparison proves less than it claims.
        assert!(c.by_status[0] > c.states / 10, "{mode} {name}: too few Ok");
        assert!(c.by_status[1] > 0, "{mode} {name}: no out-of-envelope step");
        assert!(c.by_status[2] > 0, "{mode} {name}: no bad frame");
        states += c.states;
    }
    states
}

#[test]
fn feedforward_matches_the_rust_evaluator_bit_for_bit() {
    let cases = [
        (
            "one_location_hold_last_hold",
            4,
            2,
            1,
            12,
            Terminal::HoldLast,
            0,
        ),
        (
            "three_locations_fallback_linear",
            5,
            2,
            3,
            20,
            Terminal::Fallback,
            2,
        ),
        (
            "two_locations_fallback_constant",
            3,
            1,
            2,
            8,
            Terminal::Fallback,
            3,
        ),
        (
            "one_location_fallback_zero_n12_m6",
            12,
            6,
            1,
            6,
            Terminal::Fallback,
            1,
        ),
        (
            "eight_locations_hold_last_hold",
            2,
            1,
            8,
            30,
            Terminal::HoldLast,
            0,
        ),
    ];
    let mut results = Vec::new();
    for (i, &(name, n, m, locs, trajs, terminal, fb)) in cases.iter().enumerate() {
        let image = feedforward_image(100 + i as u64, n, m, locs, trajs, terminal, fb);
        results.push((name, compare(name, &image, 7 + i as u64, 22_000)));
    }
    let states = check_all("feedforward", &results);
    assert!(states >= 100_000, "{states}");
}

#[test]
fn pwa_matches_the_rust_evaluator_bit_for_bit() {
    let cases = [
        ("one_location_zero", 2, 1, 1, 3, 40, 1),
        ("three_locations_linear", 4, 2, 3, 5, 80, 2),
        ("two_locations_hold", 6, 3, 2, 4, 60, 0),
        ("one_location_constant_n12", 12, 6, 1, 2, 30, 3),
    ];
    let mut results = Vec::new();
    for (i, &(name, n, m, locs, parts, balls, fb)) in cases.iter().enumerate() {
        let image = pwa_image(200 + i as u64, n, m, locs, parts, balls, fb);
        results.push((name, compare(name, &image, 17 + i as u64, 27_000)));
    }
    let states = check_all("PWA", &results);
    assert!(states >= 100_000, "{states}");
}

/// Random byte changes with the CRC repaired (so the content checks decide), byte flips without it, and
/// truncations: the C init accepts exactly what `decode` accepts, and an accepted variant steps alike.
#[test]
fn corrupted_arrays_are_refused_as_the_rust_decoder_refuses_them() {
    let images = [
        (
            "feedforward",
            feedforward_image(300, 3, 2, 3, 6, Terminal::Fallback, 2),
        ),
        ("pwa", pwa_image(301, 3, 2, 2, 3, 20, 3)),
    ];
    for (name, image) in images {
        let dir = scratch(&format!("corrupt_{name}"));
        let h = CHarness::build(&image, &dir).expect("harness");
        let img = decode(&image).expect("valid");
        let probe: Vec<Op> = scenario(&img, 5, 40)
            .into_iter()
            .filter(|op| matches!(op, Op::Step(_) | Op::Reset))
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        let mut ops = Vec::new();
        let mut refused_crc = 0usize;
        let mut repaired = 0usize;
        for k in 0..1500 {
            let mut bytes = image.clone();
            match k % 3 {
                // One byte changed, CRC left stale: always refused.
                0 => {
                    let i = rng.random_range(0..bytes.len());
                    bytes[i] ^= 1 << rng.random_range(0..8);
                    refused_crc += 1;
                }
                // One to three bytes changed, CRC repaired: the content checks decide.
                1 => {
                    for _ in 0..rng.random_range(1..=3) {
                        let i = rng.random_range(0..bytes.len());
                        bytes[i] = rng.random();
                    }
                    if let Ok(crc) = compute_crc(&bytes) {
                        bytes[28..32].copy_from_slice(&crc.to_le_bytes());
                    }
                    repaired += 1;
                }
                // Truncated or extended.
                _ => {
                    if rng.random::<bool>() {
                        bytes.truncate(rng.random_range(0..bytes.len()));
                    } else {
                        bytes.push(rng.random());
                    }
                }
            }
            ops.push(Op::InitBytes(bytes));
            ops.extend(probe.iter().cloned());
        }
        ops.push(Op::InitEmbedded);
        ops.extend(probe.iter().cloned());
        let c = h.compare(&ops).expect("driver");
        let accepted_rust = h
            .run_rust(&ops)
            .iter()
            .filter(|a| matches!(a, host_compiler::export::harness::Answer::Init(true)))
            .count();
        eprintln!(
            "{name}: {} inits ({refused_crc} stale CRC, {repaired} repaired), {accepted_rust} accepted, \
             {} states, {} init mismatches, {} step mismatches",
            c.inits, c.states, c.init_mismatches, c.mismatches
        );
        assert_eq!(c.init_mismatches, 0, "{name}: {:?}", c.first);
        assert_eq!(c.mismatches, 0, "{name}: {:?}", c.first);
        // Both outcomes occur: the check is not vacuous.
        assert!(
            accepted_rust > 1 && accepted_rust < c.inits / 2,
            "{accepted_rust}"
        );
    }
}

fn host_compiler() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

#[test]
fn export_writes_the_files_and_refuses_bad_input_with_exit_2() {
    let dir = scratch("cli");
    let image = feedforward_image(400, 2, 1, 1, 3, Terminal::HoldLast, 1);
    let img_path = dir.join("controller.img");
    std::fs::write(&img_path, &image).unwrap();
    let out = dir.join("c");
    let ok = host_compiler()
        .args(["export", "--c"])
        .arg(&img_path)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(ok.status.code(), Some(0), "{ok:?}");
    for f in [
        "controller.h",
        "controller.c",
        "controller_image.h",
        "controller_image.c",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let header = std::fs::read_to_string(out.join("controller.h")).unwrap();
    assert!(header.contains("-ffp-contract=off") && !header.contains('@'));

    // Unreadable, corrupted, and an output path that is a file.
    let mut bad = image.clone();
    let last = bad.len() - 1;
    bad[last] ^= 0xFF;
    let bad_path = dir.join("bad.img");
    std::fs::write(&bad_path, &bad).unwrap();
    for (img, out_dir, what) in [
        (dir.join("missing.img"), dir.join("c1"), "cannot read"),
        (bad_path.clone(), dir.join("c2"), "rejected"),
        (img_path.clone(), img_path.clone(), "cannot write"),
    ] {
        let r = host_compiler()
            .args(["export", "--c"])
            .arg(&img)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{what}: {stderr}");
        assert!(stderr.contains(what), "{what}: {stderr}");
    }
    assert!(!dir.join("c2").exists(), "a rejected image wrote files");
}
