//! The C export (`host-compiler export --c`): the exported C99 evaluator, compiled with the system `cc`
//! under the header's flags, against the Rust evaluator, status and every input bit, on ≥ 10⁵ seeded
//! states per image mode (feedforward with one and several locations, both terminal behaviours and every
//! fallback law; feedforward with segment exits, synthetic and a real hybrid image of Example 4.25 along
//! closed-loop runs; PWA with one and several locations); corrupted arrays refused exactly when the Rust
//! decoder refuses them (random corruption, targeted corruption of exit records, and an exits section
//! added by hand: empty, all tables, wrong length, trailing byte, in a PWA image; a spec-fingerprint
//! section added by hand, well-formed and malformed); images with model maps (section 10):
//! arithmetic-only programs bit for bit, programs calling the C library's and the `libm` crate's
//! functions within [`LIBM_ULPS`] ulps, corrupted maps sections refused exactly when Rust refuses them;
//! model maps with controller states (a dynamic extension) bit for bit, ζ carried, reset and left on the
//! fallback and on errors as Rust does, and their corrupted sections refused as Rust refuses them;
//! model maps with the selection test section (tag 13) bit for bit, including states at its whitened
//! balls' boundaries and ties, and its corrupted or misplaced sections refused as Rust refuses them; and
//! the subcommand's exit codes.

use std::path::PathBuf;
use std::process::Command;

use host_compiler::export::harness::{
    exits_image, exits_scenario, ext_image, feedforward_image, maps_image, pwa_image, scenario,
    with_terminal_law, Answer, CHarness, Comparison, ExitCoverage, Op,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::image::{compute_crc, decode, directory, Terminal, SPEC_FINGERPRINT_LEN};
use shared_types::layout::{exit_record_len, SectionKind};

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

/// Synthetic images with segment exits (1 to 3 locations, 2 or 3 segments per trajectory, guard exits with
/// θ = 0 and θ > 0, table exits, both terminal behaviours), on scenarios that cross guards at many
/// samples, run out of guard segments' rows and sit one ulp either side of a threshold.
#[test]
fn exits_match_the_rust_evaluator_bit_for_bit() {
    let cases = [
        (
            "one_location_tables_hold_last_hold",
            3,
            1,
            1,
            5,
            Terminal::HoldLast,
            0,
        ),
        (
            "two_locations_fallback_linear",
            4,
            2,
            2,
            10,
            Terminal::Fallback,
            2,
        ),
        (
            "three_locations_hold_last_constant",
            3,
            2,
            3,
            12,
            Terminal::HoldLast,
            3,
        ),
        (
            "three_locations_fallback_zero",
            5,
            1,
            3,
            8,
            Terminal::Fallback,
            1,
        ),
        (
            "two_locations_hold_last_hold_n12_m6",
            12,
            6,
            2,
            6,
            Terminal::HoldLast,
            0,
        ),
    ];
    let mut results = Vec::new();
    let mut total = ExitCoverage::default();
    for (i, &(name, n, m, locs, trajs, terminal, fb)) in cases.iter().enumerate() {
        let image = exits_image(500 + i as u64, n, m, locs, trajs, terminal, fb);
        let img = decode(&image).expect("valid image");
        assert!(img.has_exits(), "{name}");
        let dir = scratch(name);
        let h = CHarness::build(&image, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
        let (ops, cov) = exits_scenario(&img, 37 + i as u64, 22_000);
        let c = h.compare(&ops).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((c.inits, c.init_mismatches), (1, 0), "{name}");
        eprintln!(
            "exits {name}: {} guard crossings at {} distinct samples, {} table exits, {} run-outs \
             ({} confirmed), {} / {} states one ulp from a threshold (taken / not), {} exactly on it",
            cov.crossings,
            cov.crossing_samples.len(),
            cov.table_moves,
            cov.run_outs,
            cov.run_outs_confirmed,
            cov.at_threshold_taken,
            cov.at_threshold_not_taken,
            cov.at_threshold_exact
        );
        // The scenario's replica of the cursor agrees with the evaluator where it can be seen.
        assert_eq!(cov.run_outs, cov.run_outs_confirmed, "{name}");
        if locs > 1 {
            assert!(cov.crossings > 100, "{name}: {cov:?}");
            assert!(cov.run_outs > 10, "{name}: {cov:?}");
            assert!(
                cov.at_threshold_taken > 10 && cov.at_threshold_not_taken > 10,
                "{name}"
            );
            assert!(cov.at_threshold_exact > 10, "{name}: {cov:?}");
        }
        total.crossings += cov.crossings;
        total.crossing_samples.extend(cov.crossing_samples);
        total.table_moves += cov.table_moves;
        total.run_outs += cov.run_outs;
        results.push((name, c));
    }
    assert!(total.crossing_samples.len() >= 8, "{total:?}");
    assert!(total.table_moves > 0, "{total:?}");
    let states = check_all("exits", &results);
    assert!(states >= 100_000, "{states}");
}

/// A real image with guard exits: Example 4.25's run from (−5, 1, 2) (`synth::hybrid`), stepped along
/// closed-loop runs of the exact hybrid flow from starts in and on its ball, the states fed exactly and
/// with small noise; both evaluators see the same states.
#[test]
fn a_hybrid_image_matches_along_closed_loop_runs() {
    use host_compiler::synth::hybrid::{ball_starts, image, plan_run, HybridTask};
    use shared_types::eval::Controller;
    let path = format!(
        "{}/../examples/hybrid-internal-4-25.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let task = HybridTask::new(host_compiler::spec::load(&path).unwrap()).unwrap();
    let t0 = std::time::Instant::now();
    let run = plan_run(&task, &[-5.0, 1.0, 2.0]).unwrap();
    let bytes = image(&task, std::slice::from_ref(&run)).unwrap();
    let planned = t0.elapsed();
    let img = decode(&bytes).unwrap();
    assert!(img.has_exits());
    let dir = scratch("hybrid_4_25");
    let h = CHarness::build(&bytes, &dir).expect("harness");
    let starts = ball_starts(&task, &run, 40, 20, 11);
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut ops = vec![Op::InitEmbedded];
    let (mut guard_runs, mut goal_runs) = (0usize, 0usize);
    for noise in [0.0, 1e-3, 2e-2] {
        for x0 in &starts {
            ops.push(Op::Reset);
            let mut ctl = Controller::new(img);
            let (mut x, mut loc) = (x0.clone(), task.initial);
            let mut events = 0usize;
            // Each run stops 5 samples after it reaches Goal (or after the horizon plus 5).
            let mut left = task.steps + 5;
            while left > 0 {
                left -= 1;
                let x32: Vec<f32> = x
                    .iter()
                    .map(|&v| (v + noise * (rng.random::<f64>() - 0.5)) as f32)
                    .collect();
                ops.push(Op::Step(x32.clone()));
                let Ok(u) = ctl.step(&x32) else { break };
                let u: Vec<f64> = u.as_slice().iter().map(|&v| v as f64).collect();
                let step = task.plant.flow(loc, &x, &u).unwrap();
                events += step.events.len();
                x = step.x;
                loc = step.loc;
                if left > 5 && task.property.goal.contains(&x) {
                    left = 5;
                    goal_runs += 1;
                }
            }
            if events > 0 {
                guard_runs += 1;
            }
        }
    }
    let simulated = t0.elapsed();
    let c = h.compare(&ops).expect("driver");
    eprintln!(
        "hybrid 4.25: planned in {planned:.1?}, closed loops by {simulated:.1?}, compared by {:.1?}",
        t0.elapsed()
    );
    eprintln!(
        "hybrid 4.25: {} runs ({guard_runs} switched, {goal_runs} reached Goal), {} states, {} \
         mismatches, by status {:?}",
        3 * starts.len(),
        c.states,
        c.mismatches,
        &c.by_status[..3]
    );
    assert_eq!(c.init_mismatches, 0);
    assert_eq!(c.mismatches, 0, "{:?}", c.first);
    assert!(guard_runs > starts.len(), "{guard_runs}");
    assert!(goal_runs > starts.len(), "{goal_runs}");
    assert!(c.by_status[0] > c.states / 2);
}

/// Each exit record of an image corrupted in the ways `decode` refuses (unknown kind, a nonzero value
/// in a table record, a guard with a negative or non-finite θ, NaN or infinite â, b̂ or next start, a
/// guard on a trajectory's last segment) and in ways it accepts (θ = −0, a guard with all zero values),
/// the CRC repaired: the C init refuses exactly what `decode` refuses, and an accepted variant steps alike.
#[test]
fn corrupted_exit_records_are_refused_by_both() {
    let image = exits_image(600, 3, 2, 3, 6, Terminal::Fallback, 2);
    let img = decode(&image).expect("valid");
    let (n, rec) = (img.n(), exit_record_len(img.n()));
    let dir = directory(&image).expect("directory");
    let e = (0..dir.len())
        .filter_map(|i| dir.entry(i))
        .find(|e| e.kind == SectionKind::SegmentExits as u16)
        .expect("an exits section");
    // The section is postcard: a varint length, then the records.
    let mut start = e.offset as usize;
    while image[start] & 0x80 != 0 {
        start += 1;
    }
    start += 1;
    let n_seg = img.n_segments();
    assert_eq!(start + rec * n_seg, (e.offset + e.len) as usize);
    // The last segment of each trajectory.
    let last: Vec<bool> = (0..n_seg)
        .map(|s| {
            (0..img.n_trajectories()).any(|t| {
                let (s0, c) = img.trajectory_segments(t);
                s == s0 + c - 1
            })
        })
        .collect();
    let set_f32 = |b: &mut Vec<u8>, s: usize, k: usize, v: f32| {
        let o = start + s * rec + 4 + 4 * k;
        b[o..o + 4].copy_from_slice(&v.to_le_bytes());
    };
    let set_kind = |b: &mut Vec<u8>, s: usize, kind: u32| {
        let o = start + s * rec;
        b[o..o + 4].copy_from_slice(&kind.to_le_bytes());
    };
    let mut variants: Vec<(String, Vec<u8>)> = Vec::new();
    for (s, &is_last) in last.iter().enumerate() {
        let guard = img.exit(s) != shared_types::image::Exit::Table;
        for kind in [2u32, 7, 0x100, u32::MAX] {
            let mut b = image.clone();
            set_kind(&mut b, s, kind);
            variants.push((format!("segment {s}: kind {kind}"), b));
        }
        if guard {
            for (what, k, v) in [
                ("θ = -1e-3", n + 1, -1e-3f32),
                ("θ = -inf", n + 1, f32::NEG_INFINITY),
                ("θ = NaN", n + 1, f32::NAN),
                ("θ = -0 (accepted)", n + 1, -0.0),
                ("a0 = NaN", 0, f32::NAN),
                ("b = inf", n, f32::INFINITY),
                ("next0 = NaN", n + 2, f32::NAN),
                ("next_last = -inf", 2 * n + 1, f32::NEG_INFINITY),
            ] {
                let mut b = image.clone();
                set_f32(&mut b, s, k, v);
                variants.push((format!("segment {s}: {what}"), b));
            }
            let mut b = image.clone();
            set_kind(&mut b, s, 0);
            variants.push((format!("segment {s}: guard relabelled table"), b));
        } else {
            for k in [0, n, n + 1, 2 * n + 1] {
                for v in [1.0f32, -0.0, f32::NAN] {
                    let mut b = image.clone();
                    set_f32(&mut b, s, k, v);
                    variants.push((format!("segment {s}: table value {k} = {v}"), b));
                }
            }
            // A guard whose values are all zero: valid except on a last segment.
            let mut b = image.clone();
            set_kind(&mut b, s, 1);
            let what = if is_last {
                "guard on the last segment"
            } else {
                "zero guard (accepted)"
            };
            variants.push((format!("segment {s}: {what}"), b));
            if is_last {
                let mut b = image.clone();
                set_kind(&mut b, s, 1);
                set_f32(&mut b, s, 0, 1.0);
                set_f32(&mut b, s, n + 1, 0.1);
                variants.push((format!("segment {s}: finite guard on the last segment"), b));
            }
        }
    }
    let probe: Vec<Op> = exits_scenario(&img, 5, 60)
        .0
        .into_iter()
        .filter(|op| matches!(op, Op::Step(_) | Op::Reset))
        .collect();
    let mut ops = Vec::new();
    for (_, b) in variants.iter_mut() {
        let crc = compute_crc(b).expect("crc");
        b[28..32].copy_from_slice(&crc.to_le_bytes());
        ops.push(Op::InitBytes(b.clone()));
        ops.extend(probe.iter().cloned());
    }
    let sdir = scratch("corrupt_exits");
    let h = CHarness::build(&image, &sdir).expect("harness");
    let c = h.compare(&ops).expect("driver");
    let rust: Vec<bool> = h
        .run_rust(&ops)
        .iter()
        .filter_map(|a| match a {
            Answer::Init(ok) => Some(*ok),
            _ => None,
        })
        .collect();
    let refused = rust.iter().filter(|ok| !**ok).count();
    for ((what, _), ok) in variants.iter().zip(&rust) {
        // A relabelled guard keeps its nonzero values (refused as a table record); a table value of
        // -0 has a nonzero bit (refused).
        let expect_ok = what.contains("(accepted)");
        assert_eq!(*ok, expect_ok, "{what}: decode accepted = {ok}");
    }
    eprintln!(
        "exit records: {} variants, {refused} refused by decode, {} init mismatches, {} states, {} step \
         mismatches",
        c.inits, c.init_mismatches, c.states, c.mismatches
    );
    assert_eq!(c.init_mismatches, 0, "{:?}", c.first);
    assert_eq!(c.mismatches, 0, "{:?}", c.first);
    assert!(
        refused >= 40 && refused < c.inits,
        "{refused} of {}",
        c.inits
    );
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

/// Images with a terminal law (section 11), feedforward and PWA: the handover test, the terminal law
/// and the terminal phase's out-of-envelope answers match bit for bit.
#[test]
fn terminal_laws_match_the_rust_evaluator_bit_for_bit() {
    let cases = [
        (
            "feedforward_terminal",
            with_terminal_law(
                &feedforward_image(500, 3, 2, 2, 6, Terminal::HoldLast, 1),
                1,
            ),
        ),
        (
            "feedforward_terminal_n12",
            with_terminal_law(
                &feedforward_image(501, 12, 6, 1, 4, Terminal::Fallback, 3),
                2,
            ),
        ),
        (
            "pwa_terminal",
            with_terminal_law(&pwa_image(502, 4, 2, 2, 4, 60, 2), 3),
        ),
    ];
    let mut results = Vec::new();
    for (i, (name, image)) in cases.iter().enumerate() {
        let img = decode(image).expect("valid");
        assert!(img.terminal_law().is_some(), "{name}");
        // The scenario with a reset every 10 steps: the terminal phase lasts until a reset, and a PWA
        // scenario resets rarely.
        let mut ops = Vec::new();
        for (k, op) in scenario(&img, 40 + i as u64, 35_000)
            .into_iter()
            .enumerate()
        {
            if k % 10 == 9 {
                ops.push(Op::Reset);
            }
            ops.push(op);
        }
        let dir = scratch(name);
        let h = CHarness::build(image, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
        let c = h.compare(&ops).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!((c.inits, c.init_mismatches), (1, 0), "{name}");
        results.push((*name, c));
        // The scenario must reach the terminal phase, or the comparison says nothing of it.
        let mut ctl = shared_types::eval::Controller::new(img);
        let mut terminal_steps = 0;
        for op in &ops {
            match op {
                Op::Reset => ctl.reset(),
                Op::Step(x) => {
                    let _ = ctl.step(x);
                    terminal_steps += usize::from(ctl.in_terminal_phase());
                }
                _ => {}
            }
        }
        eprintln!("{name}: {terminal_steps} steps in the terminal phase");
        assert!(terminal_steps > 1_000, "{name}: {terminal_steps}");
    }
    let states = check_all("terminal", &results);
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
        ("exits", exits_image(302, 3, 2, 3, 6, Terminal::HoldLast, 0)),
        ("pwa", pwa_image(301, 3, 2, 2, 3, 20, 3)),
        (
            "terminal",
            with_terminal_law(
                &feedforward_image(304, 3, 2, 1, 4, Terminal::HoldLast, 1),
                4,
            ),
        ),
        (
            "fingerprint",
            with_section(
                &feedforward_image(303, 3, 2, 2, 4, Terminal::HoldLast, 1),
                SectionKind::SpecFingerprint as u16,
                &postcard(&fingerprint()),
            ),
        ),
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

/// `image` with one more section of `kind` (a tag above the image's others, so it goes last) and this
/// postcard `body`, the directory, payload length and CRC updated.
fn with_section(image: &[u8], kind: u16, body: &[u8]) -> Vec<u8> {
    let count = u16::from_le_bytes([image[18], image[19]]) as usize;
    let dir_end = 32 + 12 * count;
    let mut out = image[..dir_end].to_vec();
    for i in 0..count {
        let o = 32 + 12 * i + 4;
        let off = u32::from_le_bytes(out[o..o + 4].try_into().unwrap()) + 12;
        out[o..o + 4].copy_from_slice(&off.to_le_bytes());
    }
    out.extend_from_slice(&kind.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(&(image.len() as u32 + 12).to_le_bytes());
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&image[dir_end..]);
    out.extend_from_slice(body);
    out[18..20].copy_from_slice(&(count as u16 + 1).to_le_bytes());
    let payload = out.len() as u32 - 32;
    out[24..28].copy_from_slice(&payload.to_le_bytes());
    let crc = compute_crc(&out).expect("crc");
    out[28..32].copy_from_slice(&crc.to_le_bytes());
    out
}

/// A postcard byte string: its length as a varint, then the bytes.
fn postcard(bytes: &[u8]) -> Vec<u8> {
    let mut b = Vec::new();
    let mut v = bytes.len();
    loop {
        let byte = (v & 0x7F) as u8;
        v >>= 7;
        if v == 0 {
            b.push(byte);
            break;
        }
        b.push(byte | 0x80);
    }
    b.extend_from_slice(bytes);
    b
}

/// Some spec fingerprint hashes (any bytes of the stored length).
fn fingerprint() -> Vec<u8> {
    (0..SPEC_FINGERPRINT_LEN)
        .map(|i| (i * 31 + 5) as u8)
        .collect()
}

/// Runs `cases` (what, bytes, whether `decode` accepts) through the C init with a probe of `img`'s states
/// after each, in a harness built on `embedded`: `decode` decides as stated, the C init decides as `decode`
/// does and accepted images step alike. Returns the probe.
fn check_section_cases(
    name: &str,
    embedded: &[u8],
    img: &shared_types::image::Image<'_>,
    seed: u64,
    cases: &[(&str, Vec<u8>, bool)],
) -> Vec<Op> {
    let probe: Vec<Op> = scenario(img, seed, 300)
        .into_iter()
        .filter(|op| matches!(op, Op::Step(_) | Op::Reset))
        .collect();
    let mut ops = Vec::new();
    for (what, bytes, ok) in cases {
        assert_eq!(
            decode(bytes).is_ok(),
            *ok,
            "{what}: {:?}",
            decode(bytes).err()
        );
        ops.push(Op::InitBytes(bytes.clone()));
        ops.extend(probe.iter().cloned());
    }
    let h = CHarness::build(embedded, &scratch(name)).expect("harness");
    let c = h.compare(&ops).expect("driver");
    eprintln!(
        "{name}: {} inits, {} init mismatches, {} states, {} mismatches",
        c.inits, c.init_mismatches, c.states, c.mismatches
    );
    assert_eq!(c.inits, cases.len(), "{name}");
    assert_eq!(c.init_mismatches, 0, "{name}: {:?}", c.first);
    assert_eq!(c.mismatches, 0, "{name}: {:?}", c.first);
    probe
}

/// A spec-fingerprint section (tag 12) added by hand: of the stored length in a feedforward image, a PWA
/// image and one with segment exits (accepted, same answers as without it); short, long, empty, with a
/// trailing byte or an overlong length prefix, twice, or under the reserved tag 11 (refused). The C init
/// decides as `decode` does, and accepted images step alike.
#[test]
fn a_fingerprint_section_is_admitted_as_the_rust_decoder_admits_it() {
    let ff = feedforward_image(710, 3, 2, 2, 5, Terminal::Fallback, 3);
    let img = decode(&ff).unwrap();
    let pwa = pwa_image(711, 3, 2, 1, 2, 10, 1);
    let tag = SectionKind::SpecFingerprint as u16;
    let fp = fingerprint();
    let mut trailing = postcard(&fp);
    trailing.push(0);
    let mut overlong = vec![0x80 | SPEC_FINGERPRINT_LEN as u8, 0];
    overlong.extend_from_slice(&fp);
    let with_exits = with_section(&ff, 9, &postcard(&[]));
    let cases: Vec<(&str, Vec<u8>, bool)> = vec![
        ("feedforward", with_section(&ff, tag, &postcard(&fp)), true),
        ("PWA", with_section(&pwa, tag, &postcard(&fp)), true),
        (
            "after segment exits",
            with_section(&with_exits, tag, &postcard(&fp)),
            true,
        ),
        (
            "one byte short",
            with_section(&ff, tag, &postcard(&fp[1..])),
            false,
        ),
        (
            "one byte long",
            with_section(&ff, tag, &postcard(&[&fp[..], &[0]].concat())),
            false,
        ),
        ("empty", with_section(&ff, tag, &postcard(&[])), false),
        ("no body", with_section(&ff, tag, &[]), false),
        ("trailing byte", with_section(&ff, tag, &trailing), false),
        ("overlong length", with_section(&ff, tag, &overlong), false),
        (
            "twice",
            with_section(&with_section(&ff, tag, &postcard(&fp)), tag, &postcard(&fp)),
            false,
        ),
        (
            "tag 11 (terminal law) with a fingerprint's body",
            with_section(&ff, 11, &postcard(&fp)),
            false,
        ),
    ];
    let probe = check_section_cases("fingerprint_section", &ff, &img, 10, &cases);
    // The evaluator does not read the fingerprint: the image answers as without it.
    let mut run = vec![Op::InitEmbedded];
    run.extend(probe.iter().cloned());
    let plain = host_compiler::export::harness::reference(&ff, &run);
    let stamped = host_compiler::export::harness::reference(&cases[0].1, &run);
    assert!(
        plain == stamped,
        "the fingerprinted image answers differently"
    );
    // And `export --c` accepts it.
    assert!(host_compiler::export::c::files(&cases[0].1).is_ok());
}

/// A segment-exits section added by hand: empty (no exits) or all table records in a feedforward image
/// (accepted, same answers), one record short or with a trailing byte (refused), in a PWA image (not
/// admitted by the mode: refused). The C init decides as `decode` does, and accepted images step alike.
#[test]
fn an_exits_section_is_admitted_as_the_rust_decoder_admits_it() {
    let ff = feedforward_image(700, 3, 2, 2, 5, Terminal::Fallback, 3);
    let img = decode(&ff).unwrap();
    let rec = exit_record_len(img.n());
    let n_seg = img.n_segments();
    let records = |k: usize| {
        let mut b = Vec::new();
        for _ in 0..k {
            b.extend_from_slice(&0u32.to_le_bytes());
            b.extend(std::iter::repeat_n(0u8, rec - 4));
        }
        b
    };
    let tables = records(n_seg);
    let mut trailing = postcard(&tables);
    trailing.push(0);
    let pwa = pwa_image(701, 3, 2, 1, 2, 10, 1);
    let cases: Vec<(&str, Vec<u8>, bool)> = vec![
        ("empty", with_section(&ff, 9, &postcard(&[])), true),
        ("all tables", with_section(&ff, 9, &postcard(&tables)), true),
        (
            "one record short",
            with_section(&ff, 9, &postcard(&records(n_seg - 1))),
            false,
        ),
        ("trailing byte", with_section(&ff, 9, &trailing), false),
        (
            "in a PWA image",
            with_section(&pwa, 9, &postcard(&[])),
            false,
        ),
        (
            "unknown kind 10",
            with_section(&ff, 10, &postcard(&[])),
            false,
        ),
    ];
    let probe = check_section_cases("exits_section", &ff, &img, 9, &cases);
    // The all-tables image (through the exits path) answers as the image without the section.
    let mut run = vec![Op::InitEmbedded];
    run.extend(probe.iter().cloned());
    let plain = host_compiler::export::harness::reference(&ff, &run);
    let all_tables = host_compiler::export::harness::reference(&cases[1].1, &run);
    assert!(
        plain == all_tables,
        "the all-tables image answers differently"
    );
}

/// The ulps by which the C library's `sinf`, `cosf`, ... and the `libm` crate's may make one input differ,
/// for the transcendental images, whose outputs are one library call times an input: the host's rounding
/// analysis of a model program assumes each call within 4 ulp of the true value
/// (`host_compiler::expr::interval`), so two libraries that both meet it differ by at most 8 ulp in the
/// call, and the product's rounding adds at most 1.
const LIBM_ULPS: u32 = 2 * 4 + 1;

/// Images with model maps (section 10): the C's `sc_step_plant` against Rust's `step_plant`. Arithmetic
/// programs (+ − · /, negation, integer powers, constants) bit for bit; programs with the ten library
/// functions (two images cover them all, with arguments up to 10⁵ in magnitude) statuses exactly and
/// inputs within [`LIBM_ULPS`]; the largest difference seen is printed.
#[test]
fn model_maps_match_the_rust_evaluator() {
    // (name, n_plant, m_plant, n, m, trajectories, terminal, fallback, transcendental, first function)
    let cases = [
        (
            "arith_hold_last_hold",
            4,
            2,
            2,
            2,
            6,
            Terminal::HoldLast,
            0,
            false,
            0,
        ),
        (
            "arith_fallback_constant",
            6,
            3,
            3,
            1,
            8,
            Terminal::Fallback,
            3,
            false,
            0,
        ),
        (
            "arith_fallback_zero_n12",
            12,
            6,
            8,
            3,
            4,
            Terminal::Fallback,
            1,
            false,
            0,
        ),
        ("libm_0_to_4", 7, 5, 2, 2, 6, Terminal::HoldLast, 3, true, 0),
        ("libm_5_to_9", 7, 5, 3, 2, 6, Terminal::Fallback, 0, true, 5),
    ];
    let (mut exact_states, mut libm_states, mut ulp_max, mut inexact) = (0, 0, 0u32, 0usize);
    for (i, &(name, np, mp, n, m, trajs, terminal, fb, libm, first)) in cases.iter().enumerate() {
        let image = maps_image(
            500 + i as u64,
            np,
            mp,
            n,
            m,
            trajs,
            terminal,
            fb,
            libm,
            first,
        );
        let dir = scratch(&format!("maps_{name}"));
        let h = CHarness::build(&image, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
        let img = decode(&image).expect("valid image");
        assert_eq!((img.plant_n(), img.plant_m()), (np, mp));
        let ops = scenario(&img, 40 + i as u64, 20_000);
        let c = h
            .compare_within(&ops, if libm { LIBM_ULPS } else { 0 })
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        eprintln!(
            "maps {name}: {} states, {} mismatches, {} within {} ulp, max {} ulp, by status {:?}",
            c.states,
            c.mismatches,
            c.inexact,
            if libm { LIBM_ULPS } else { 0 },
            c.ulp_max,
            &c.by_status[..3]
        );
        assert_eq!(
            c.init_mismatches, 0,
            "{name}: the exported array is refused"
        );
        assert_eq!(c.mismatches, 0, "{name}: {:?}", c.first);
        assert!(c.by_status[0] > c.states / 10, "{name}: too few Ok");
        assert!(c.by_status[1] > 0, "{name}: no out-of-envelope step");
        assert!(c.by_status[2] > 0, "{name}: no bad frame");
        if libm {
            libm_states += c.states;
            ulp_max = ulp_max.max(c.ulp_max);
            inexact += c.inexact;
        } else {
            assert_eq!(c.ulp_max, 0, "{name}");
            exact_states += c.states;
        }
    }
    eprintln!(
        "maps: {exact_states} arithmetic states bit for bit; {libm_states} states with library calls, \
         {inexact} of them within {LIBM_ULPS} ulp but not bit for bit, largest difference {ulp_max} ulp"
    );
    assert!(exact_states >= 60_000 && libm_states >= 40_000);
}

/// Corrupted model maps sections, CRC repaired: one to three bytes of the section changed (header,
/// program headers, constants, code, padding), the section cut short or lengthened by a byte, or the
/// header's program lengths moved; the C refuses exactly what the Rust decoder refuses, and where both
/// accept, their steps agree.
#[test]
fn corrupted_model_maps_are_refused_by_both() {
    let image = maps_image(600, 5, 2, 3, 2, 4, Terminal::Fallback, 3, false, 0);
    let dir = scratch("corrupt_maps");
    let h = CHarness::build(&image, &dir).expect("harness");
    let img = decode(&image).expect("valid");
    let probe: Vec<Op> = scenario(&img, 6, 40)
        .into_iter()
        .filter(|op| matches!(op, Op::Step(_) | Op::Reset))
        .collect();
    let dir_entries = directory(&image).expect("directory");
    let maps = (0..dir_entries.len())
        .filter_map(|i| dir_entries.entry(i))
        .find(|e| e.kind == SectionKind::ModelMaps as u16)
        .expect("a model maps section");
    let (off, len) = (maps.offset as usize, maps.len as usize);
    let body = image[off..off + len].to_vec();
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    // A corrupted opcode may become a library function's: the C and Rust libraries may then differ in
    // the last place (see `LIBM_ULPS`), so such images are compared within that, the others bit for bit.
    let (mut ops, mut libm_ops) = (Vec::new(), Vec::new());
    for k in 0..1200 {
        let mut b = body.clone();
        match k % 4 {
            0 | 1 => {
                for _ in 0..rng.random_range(1..=3) {
                    let i = rng.random_range(0..b.len());
                    if k % 4 == 0 {
                        b[i] = rng.random();
                    } else {
                        b[i] ^= 1 << rng.random_range(0..8);
                    }
                }
            }
            2 => {
                if rng.random::<bool>() {
                    b.truncate(rng.random_range(0..b.len()));
                } else {
                    b.push(rng.random_range(0..2));
                }
            }
            _ => {
                // A program length moved by a few bytes (the padding then no longer fits).
                let at = if rng.random::<bool>() { 4 } else { 8 };
                let l = u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
                let l = l.wrapping_add(rng.random_range(1..6)).wrapping_sub(3);
                b[at..at + 4].copy_from_slice(&l.to_le_bytes());
            }
        }
        let bytes = with_section_body(&image, off, len, &b);
        let to = if decode(&bytes).is_ok_and(|i| calls_library(&i)) {
            &mut libm_ops
        } else {
            &mut ops
        };
        to.push(Op::InitBytes(bytes));
        to.extend(probe.iter().cloned());
    }
    ops.push(Op::InitEmbedded);
    ops.extend(probe.iter().cloned());
    let c = h.compare(&ops).expect("driver");
    let accepted = h
        .run_rust(&ops)
        .iter()
        .filter(|a| matches!(a, Answer::Init(true)))
        .count();
    eprintln!(
        "corrupted maps: {} inits, {accepted} accepted by Rust, {} states, {} init mismatches, {} step mismatches",
        c.inits, c.states, c.init_mismatches, c.mismatches
    );
    assert_eq!(c.init_mismatches, 0, "{:?}", c.first);
    assert_eq!(c.mismatches, 0, "{:?}", c.first);
    assert!(accepted > 1 && accepted < c.inits / 2, "{accepted}");
    if !libm_ops.is_empty() {
        let c = h.compare_within(&libm_ops, LIBM_ULPS).expect("driver");
        eprintln!(
            "corrupted maps calling a library function: {} inits, {} states, max {} ulp",
            c.inits, c.states, c.ulp_max
        );
        assert_eq!(c.init_mismatches, 0, "{:?}", c.first);
        assert_eq!(c.mismatches, 0, "{:?}", c.first);
    }
}

/// Images with controller states (`ext_image`: a double integrator whose input is a controller state):
/// `sc_step_plant` against `step_plant` bit for bit, over every fallback and both terminal behaviours.
/// The plant's input is ζ0 of the step, so the many distinct inputs show that ζ is carried from step to
/// step (and reset at every run).
#[test]
fn controller_states_match_the_rust_evaluator() {
    let cases = [
        ("hold_holdlast", 4, Terminal::HoldLast, 0),
        ("zero_fallback", 6, Terminal::Fallback, 1),
        ("constant_fallback", 3, Terminal::Fallback, 3),
    ];
    let mut results = Vec::new();
    for (i, &(name, trajs, terminal, fb)) in cases.iter().enumerate() {
        let image = ext_image(700 + i as u64, trajs, terminal, fb);
        let img = decode(&image).expect("valid image");
        let maps = img.model_maps().expect("model maps");
        assert_eq!(
            (img.plant_n(), img.plant_m(), maps.n_ext()),
            (2, 1, 2),
            "{name}"
        );
        let c = compare(&format!("ext_{name}"), &image, 80 + i as u64, 20_000);
        assert_eq!(c.ulp_max, 0, "{name}");
        // Distinct inputs among the Rust side's Ok answers: u = ζ0 of the step.
        let ops = scenario(&img, 80 + i as u64, 20_000);
        let inputs: std::collections::BTreeSet<u32> =
            host_compiler::export::harness::reference(&image, &ops)
                .iter()
                .filter_map(|a| match a {
                    Answer::Step(0, u, _) => Some(u[0]),
                    _ => None,
                })
                .collect();
        assert!(
            inputs.len() > 1000,
            "{name}: {} distinct inputs",
            inputs.len()
        );
        results.push((name, c));
    }
    assert!(check_all("controller states", &results) >= 60_000);
}

/// Corrupted model maps sections with controller states, CRC repaired: n_ext (byte 2) set to every value
/// up to MAX_EXT + 2, the reserved byte 3 set, a ζ0 word made NaN, infinite or another finite value,
/// random bytes of the header and ζ0 or anywhere; the C refuses exactly what the Rust decoder refuses,
/// and where both accept, their steps agree.
#[test]
fn corrupted_controller_states_are_refused_by_both() {
    let image = ext_image(710, 4, Terminal::Fallback, 3);
    let dir = scratch("corrupt_ext");
    let h = CHarness::build(&image, &dir).expect("harness");
    let img = decode(&image).expect("valid");
    let probe: Vec<Op> = scenario(&img, 9, 40)
        .into_iter()
        .filter(|op| matches!(op, Op::Step(_) | Op::Reset))
        .collect();
    let dir_entries = directory(&image).expect("directory");
    let maps = (0..dir_entries.len())
        .filter_map(|i| dir_entries.entry(i))
        .find(|e| e.kind == SectionKind::ModelMaps as u16)
        .expect("a model maps section");
    let (off, len) = (maps.offset as usize, maps.len as usize);
    let body = image[off..off + len].to_vec();
    assert_eq!(body[2], 2);
    let mut rng = ChaCha8Rng::seed_from_u64(78);
    // As for the maps without controller states: an image whose corrupted code calls a library function
    // is compared within `LIBM_ULPS`, the others bit for bit.
    let (mut ops, mut libm_ops) = (Vec::new(), Vec::new());
    let mut push = |b: &[u8], ops: &mut Vec<Op>| {
        let bytes = with_section_body(&image, off, len, b);
        let to = if decode(&bytes).is_ok_and(|i| calls_library(&i)) {
            &mut libm_ops
        } else {
            ops
        };
        to.push(Op::InitBytes(bytes));
        to.extend(probe.iter().cloned());
    };
    for k in 0..=shared_types::capacity::MAX_EXT as u8 + 2 {
        let mut b = body.clone();
        b[2] = k;
        push(&b, &mut ops);
    }
    for v in [1u8, 0x80, 0xff] {
        let mut b = body.clone();
        b[3] = v;
        push(&b, &mut ops);
    }
    for word in 0..2 {
        for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.25, -1e30] {
            let mut b = body.clone();
            let at = 12 + 4 * word;
            b[at..at + 4].copy_from_slice(&v.to_le_bytes());
            push(&b, &mut ops);
        }
    }
    for k in 0..600 {
        let mut b = body.clone();
        for _ in 0..rng.random_range(1..=3) {
            let i = if k % 2 == 0 {
                rng.random_range(0..20)
            } else {
                rng.random_range(0..b.len())
            };
            b[i] = if k % 3 == 0 {
                rng.random()
            } else {
                b[i] ^ (1 << rng.random_range(0..8))
            };
        }
        push(&b, &mut ops);
    }
    ops.push(Op::InitEmbedded);
    ops.extend(probe.iter().cloned());
    let c = h.compare(&ops).expect("driver");
    let accepted = h
        .run_rust(&ops)
        .iter()
        .filter(|a| matches!(a, Answer::Init(true)))
        .count();
    eprintln!(
        "corrupted controller states: {} inits, {accepted} accepted by Rust, {} states, {} init mismatches, {} step mismatches",
        c.inits, c.states, c.init_mismatches, c.mismatches
    );
    assert_eq!(c.init_mismatches, 0, "{:?}", c.first);
    assert_eq!(c.mismatches, 0, "{:?}", c.first);
    assert!(accepted > 10 && accepted < c.inits / 2, "{accepted}");
    if !libm_ops.is_empty() {
        let c = h.compare_within(&libm_ops, LIBM_ULPS).expect("driver");
        assert_eq!(c.init_mismatches, 0, "{:?}", c.first);
        assert_eq!(c.mismatches, 0, "{:?}", c.first);
    }
}

/// Whether an image's model programs call a library function whose C and Rust results may differ
/// (all but `sqrt` and `abs`, which are exact).
fn calls_library(img: &shared_types::image::Image<'_>) -> bool {
    use shared_types::program::{Func, Op as P};
    img.model_maps().is_some_and(|m| {
        [m.coords(), m.input_map()].iter().any(|p| {
            p.ops().any(|(_, op)| match op {
                P::Func(f) => !matches!(f, Func::Sqrt | Func::Abs),
                P::Atan2 => true,
                _ => false,
            })
        })
    })
}

/// `image` with the section body at `off..off + len` replaced by `body` (the last section, as the model
/// maps are), with the directory entry's length, the payload length and the CRC updated.
fn with_section_body(image: &[u8], off: usize, len: usize, body: &[u8]) -> Vec<u8> {
    assert_eq!(off + len, image.len(), "the model maps section is the last");
    let mut out = image[..off].to_vec();
    out.extend_from_slice(body);
    let count = u16::from_le_bytes([out[18], out[19]]) as usize;
    let entry = 32 + 12 * (count - 1);
    out[entry + 8..entry + 12].copy_from_slice(&(body.len() as u32).to_le_bytes());
    let payload = (out.len() - 32) as u32;
    out[24..28].copy_from_slice(&payload.to_le_bytes());
    let crc = compute_crc(&out).expect("a header");
    out[28..32].copy_from_slice(&crc.to_le_bytes());
    out
}

/// The selection test section (tag 13) of the feedforward image `img` with model maps: per location the
/// upper factor R̂ of its metric (`P = RᵀR`, Cholesky in f64 of the stored f32 values, rounded to f32,
/// exactly 0 below the diagonal), per trajectory `[fl32(R̂_ℓ ĉ), ŝ]` with ℓ the location of its first
/// segment and `ŝ = fl32(δ² · scale(t))` (the P-metric ball's squared radius, scaled so that the two
/// tests select differently); with `tie`, trajectory 1's record is trajectory 0's (in a one-location
/// image an exact tie, which goes to the lowest index).
struct SelectionSection {
    factors: Vec<Vec<f32>>,
    records: Vec<f32>,
}

impl SelectionSection {
    fn new(img: &shared_types::image::Image<'_>, scale: impl Fn(usize) -> f64, tie: bool) -> Self {
        let n = img.n();
        let factors: Vec<Vec<f32>> = (0..img.n_locations())
            .map(|l| {
                let mut rh = vec![0.0f64; n * n];
                for i in 0..n {
                    for j in i..n {
                        let mut s = img.P(l, i, j) as f64;
                        for k in 0..i {
                            s -= rh[k * n + i] * rh[k * n + j];
                        }
                        rh[i * n + j] = if i == j { s.sqrt() } else { s / rh[i * n + i] };
                    }
                }
                rh.iter().map(|&v| v as f32).collect()
            })
            .collect();
        let mut records = Vec::new();
        for t in 0..img.n_trajectories() {
            let rh = &factors[first_location(img, t)];
            for i in 0..n {
                let z: f64 = (i..n)
                    .map(|j| rh[i * n + j] as f64 * img.centre(t, j) as f64)
                    .sum();
                records.push(z as f32);
            }
            let d = img.delta(t) as f64;
            records.push((d * d * scale(t)) as f32);
        }
        if tie && img.n_trajectories() > 1 {
            let r0 = records[..n + 1].to_vec();
            records[n + 1..2 * (n + 1)].copy_from_slice(&r0);
        }
        SelectionSection { factors, records }
    }

    /// The section body (raw little-endian f32).
    fn body(&self) -> Vec<u8> {
        self.factors
            .iter()
            .flatten()
            .chain(&self.records)
            .flat_map(|v| v.to_le_bytes())
            .collect()
    }
}

/// The location of trajectory `t`'s first segment.
fn first_location(img: &shared_types::image::Image<'_>, t: usize) -> usize {
    let (s0, _) = img.trajectory_segments(t);
    img.segment(s0).map_or(0, |s| s.location)
}

/// `image` (with model maps) re-encoded with the selection test section `body`, which must be valid.
fn with_selection(image: &[u8], body: &[u8]) -> Vec<u8> {
    let img = decode(image)
        .expect("a valid image")
        .with_selection_test(body)
        .expect("a valid selection test");
    let mut out = vec![0u8; img.encoded_len().expect("encoded length")];
    let len = shared_types::image::encode(&img, &mut out).expect("encode");
    out.truncate(len);
    out
}

/// Runs of two steps from a reset whose first state lies near trajectory t's whitened ball (t at random):
/// ξ = ĉ + √ŝ·ρ·e/|R̂e| (e a random direction, ρ inside, within 10⁻⁶ or 10⁻⁷ of 1, or outside), lifted to a
/// plant state of a [`maps_image`]-like image (coords ξ_i = x_i + h(x_n, ...), so x_i = ξ_i − h with h
/// the coords at x = 0 and the states past n drawn at random).
fn near_whitened_balls(
    img: &shared_types::image::Image<'_>,
    sel: &SelectionSection,
    seed: u64,
    runs: usize,
) -> Vec<Op> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = img.n();
    let maps = img.model_maps().expect("model maps");
    let np = maps.n_plant();
    let mut ops = Vec::new();
    for _ in 0..runs {
        let t = rng.random_range(0..img.n_trajectories());
        let rh = &sel.factors[first_location(img, t)];
        let e: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let q = (0..n)
            .map(|i| {
                let z: f64 = (i..n).map(|j| rh[i * n + j] as f64 * e[j]).sum();
                z * z
            })
            .sum::<f64>()
            .sqrt()
            .max(1e-300);
        let rho = match rng.random_range(0..4) {
            0 => rng.random::<f64>(),
            1 => 1.0 + (rng.random::<f64>() - 0.5) * 1e-6,
            2 => 1.0 + (rng.random::<f64>() - 0.5) * 1e-7,
            _ => 1.0 + rng.random::<f64>(),
        };
        let s = (sel.records[t * (n + 1) + n] as f64).sqrt();
        let xi: Vec<f32> = (0..n)
            .map(|i| (img.centre(t, i) as f64 + s * rho * e[i] / q) as f32)
            .collect();
        let z: Vec<f32> = (n..np).map(|_| rng.random_range(-1.0f32..1.0)).collect();
        let mut probe = vec![0.0f32; np];
        probe[n..].copy_from_slice(&z);
        let mut h = vec![0.0f32; n];
        maps.coords().eval(&probe, &mut h).expect("coords");
        let x: Vec<f32> = xi
            .iter()
            .zip(&h)
            .map(|(&a, &b)| (a as f64 - b as f64) as f32)
            .chain(z)
            .collect();
        ops.push(Op::Reset);
        ops.push(Op::Step(x.clone()));
        ops.push(Op::Step(x));
    }
    ops
}

/// A feedforward image with model maps and `locations` locations: [`feedforward_image`]'s tables with the
/// model maps, fallback and input box of [`maps_image`] (n_plant = n + 2, m_plant = m).
fn multi_location_maps_image(
    seed: u64,
    n: usize,
    m: usize,
    locations: usize,
    trajs: usize,
) -> Vec<u8> {
    use host_compiler::emit::ImageBuilder;
    let tables = feedforward_image(seed, n, m, locations, trajs, Terminal::Fallback, 1);
    let maps = maps_image(seed, n + 2, m, n, m, trajs, Terminal::Fallback, 3, false, 0);
    let mb = ImageBuilder::from_image(&decode(&maps).unwrap());
    let mut b = ImageBuilder::from_image(&decode(&tables).unwrap());
    b.model_maps = mb.model_maps.clone();
    b.fallback = mb.fallback.clone();
    b.input_box = mb.input_box.clone();
    b.to_bytes()
        .expect("a valid multi-location image with model maps")
}

/// Images with model maps and the selection test section (tag 13): `sc_step_plant` against `step_plant`
/// bit for bit, for one location with n = 2 and n = 8 (Rust's unrolled `select_fixed::<8>`) and three
/// locations (z recomputed when the first segment's location changes), thresholds scaled from the
/// P-metric radii (so the whitened test decides the selection), an exact tie in the one-location
/// images; the scenario's states plus runs starting within 10⁻⁶ or 10⁻⁷ of a whitened ball's boundary.
/// The section's image must answer differently from the plain one on some states, or the comparison
/// would not show that the C reads it.
#[test]
fn selection_tests_match_the_rust_evaluator() {
    let cases: [(&str, Vec<u8>, bool); 3] = [
        (
            "n2_one_location",
            maps_image(800, 4, 2, 2, 2, 6, Terminal::HoldLast, 0, false, 0),
            true,
        ),
        (
            "n8_one_location",
            maps_image(801, 12, 6, 8, 3, 5, Terminal::Fallback, 1, false, 0),
            true,
        ),
        (
            "n3_three_locations",
            multi_location_maps_image(802, 3, 2, 3, 10),
            false,
        ),
    ];
    let mut results = Vec::new();
    for (i, (name, plain, tie)) in cases.iter().enumerate() {
        let img = decode(plain).expect("valid");
        assert!(img.model_maps().is_some(), "{name}");
        let mut rng = ChaCha8Rng::seed_from_u64(90 + i as u64);
        let scales: Vec<f64> = (0..img.n_trajectories())
            .map(|_| rng.random_range(0.4..1.6))
            .collect();
        let sel = SelectionSection::new(&img, |t| scales[t], *tie);
        let bytes = with_selection(plain, &sel.body());
        let with = decode(&bytes).expect("the image with its selection test");
        assert!(with.selection_test().is_some(), "{name}");
        // The harness is built on the plain image (the export's embedded array); every run inits from
        // the bytes with the section.
        let h = CHarness::build(plain, &scratch(&format!("selection_{name}")))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut ops: Vec<Op> = scenario(&with, 95 + i as u64, 15_000)
            .into_iter()
            .map(|op| match op {
                Op::InitEmbedded => Op::InitBytes(bytes.clone()),
                op => op,
            })
            .collect();
        ops.extend(near_whitened_balls(&with, &sel, 97 + i as u64, 3_000));
        let c = h.compare(&ops).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(c.inits, 1, "{name}");
        assert_eq!(c.init_mismatches, 0, "{name}: the image is refused");
        // The same runs on the plain image: the selection test must change some answers.
        let plain_ops: Vec<Op> = ops
            .iter()
            .map(|op| match op {
                Op::InitBytes(_) => Op::InitBytes(plain.clone()),
                op => op.clone(),
            })
            .collect();
        let differ = h
            .run_rust(&ops)
            .iter()
            .zip(&h.run_rust(&plain_ops))
            .filter(|(a, b)| a != b)
            .count();
        eprintln!("selection {name}: {differ} answers differ from the plain image's");
        assert!(differ > 100, "{name}: {differ}");
        results.push((*name, c));
    }
    assert!(check_all("selection test", &results) >= 60_000);
}

/// The selection test section corrupted: by hand (accepted: a zero or −0 threshold, −0 below the
/// diagonal, after a fingerprint; refused: a negative, NaN or infinite threshold, a nonzero value below
/// the diagonal, a zero, negative or NaN diagonal, an infinite centre, a value short or long, a trailing
/// byte, empty, twice, before a fingerprint, in an image without model maps, in a PWA image) and one to
/// three random bytes of its body changed; the C init decides as `decode` does, and accepted images step
/// alike.
#[test]
fn corrupted_selection_tests_are_refused_as_the_rust_decoder_refuses_them() {
    let plain = maps_image(810, 5, 2, 3, 2, 4, Terminal::Fallback, 3, false, 0);
    let img = decode(&plain).unwrap();
    let n = img.n();
    let sel = SelectionSection::new(&img, |_| 1.0, false);
    let body = sel.body();
    let nl = img.n_locations();
    let factor_at = |r: usize, c: usize| 4 * (r * n + c);
    let record_at = |t: usize, k: usize| 4 * (nl * n * n + t * (n + 1) + k);
    let set = |at: usize, v: f32| {
        let mut b = body.clone();
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        b
    };
    let tag = SectionKind::SelectionTest as u16;
    let fp = postcard(&fingerprint());
    let no_maps = feedforward_image(810, 3, 2, 1, 4, Terminal::Fallback, 1);
    assert!(decode(&no_maps).unwrap().model_maps().is_none());
    let pwa = pwa_image(811, 3, 2, 1, 2, 10, 1);
    let mut long = body.clone();
    long.extend_from_slice(&0.5f32.to_le_bytes());
    let mut trailing = body.clone();
    trailing.push(0);
    let cases: Vec<(&str, Vec<u8>, bool)> = vec![
        ("valid", with_section(&plain, tag, &body), true),
        (
            "zero threshold",
            with_section(&plain, tag, &set(record_at(1, n), 0.0)),
            true,
        ),
        (
            "-0 threshold",
            with_section(&plain, tag, &set(record_at(2, n), -0.0)),
            true,
        ),
        (
            "-0 below the diagonal",
            with_section(&plain, tag, &set(factor_at(2, 0), -0.0)),
            true,
        ),
        (
            "after a fingerprint",
            with_section(&with_section(&plain, 12, &fp), tag, &body),
            true,
        ),
        (
            "negative threshold",
            with_section(&plain, tag, &set(record_at(3, n), -1e-30)),
            false,
        ),
        (
            "NaN threshold",
            with_section(&plain, tag, &set(record_at(0, n), f32::NAN)),
            false,
        ),
        (
            "infinite threshold",
            with_section(&plain, tag, &set(record_at(0, n), f32::INFINITY)),
            false,
        ),
        (
            "nonzero below the diagonal",
            with_section(&plain, tag, &set(factor_at(1, 0), 1e-30)),
            false,
        ),
        (
            "zero diagonal",
            with_section(&plain, tag, &set(factor_at(2, 2), 0.0)),
            false,
        ),
        (
            "negative diagonal",
            with_section(&plain, tag, &set(factor_at(0, 0), -1.0)),
            false,
        ),
        (
            "NaN diagonal",
            with_section(&plain, tag, &set(factor_at(1, 1), f32::NAN)),
            false,
        ),
        (
            "infinite centre",
            with_section(&plain, tag, &set(record_at(1, 0), f32::NEG_INFINITY)),
            false,
        ),
        (
            "one value short",
            with_section(&plain, tag, &body[..body.len() - 4]),
            false,
        ),
        ("one value long", with_section(&plain, tag, &long), false),
        ("trailing byte", with_section(&plain, tag, &trailing), false),
        ("empty", with_section(&plain, tag, &[]), false),
        (
            "twice",
            with_section(&with_section(&plain, tag, &body), tag, &body),
            false,
        ),
        (
            "before a fingerprint",
            with_section(&with_section(&plain, tag, &body), 12, &fp),
            false,
        ),
        (
            "without model maps",
            with_section(&no_maps, tag, &body),
            false,
        ),
        ("in a PWA image", with_section(&pwa, tag, &body), false),
    ];
    assert!(matches!(
        decode(&cases[cases.len() - 2].1),
        Err(shared_types::image::ImageError::SelectionWithoutModelMaps)
    ));
    let probe = check_section_cases("selection_section", &plain, &img, 11, &cases);
    // Random corruption of the body (the section is the last): the C refuses exactly what Rust refuses.
    let with = &cases[0].1;
    let (off, len) = (with.len() - body.len(), body.len());
    let mut rng = ChaCha8Rng::seed_from_u64(79);
    let mut ops = Vec::new();
    for k in 0..400 {
        let mut b = body.clone();
        for _ in 0..rng.random_range(1..=3) {
            let i = rng.random_range(0..b.len());
            b[i] = if k % 2 == 0 {
                rng.random()
            } else {
                b[i] ^ (1 << rng.random_range(0..8))
            };
        }
        ops.push(Op::InitBytes(with_section_body(with, off, len, &b)));
        ops.extend(probe.iter().cloned());
    }
    let h = CHarness::build(&plain, &scratch("selection_corrupt")).expect("harness");
    let c = h.compare(&ops).expect("driver");
    let accepted = h
        .run_rust(&ops)
        .iter()
        .filter(|a| matches!(a, Answer::Init(true)))
        .count();
    eprintln!(
        "corrupted selection tests: {} inits, {accepted} accepted by Rust, {} states, {} init mismatches, {} step mismatches",
        c.inits, c.states, c.init_mismatches, c.mismatches
    );
    assert_eq!(c.init_mismatches, 0, "{:?}", c.first);
    assert_eq!(c.mismatches, 0, "{:?}", c.first);
    assert!(accepted > 10 && accepted < c.inits, "{accepted}");
}
