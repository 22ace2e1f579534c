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
//! balls' boundaries and ties, and its corrupted or misplaced sections refused as Rust refuses them; the
//! task's monitor (section 14): `sc_monitor_update` against `shared_types::monitor::Monitor`, lo, hi
//! (bits) and the verdict at every update, on synthetic programs of every operator and atom kind, on the
//! monitors of `planar-vehicle-waypoints` and `double-integrator`, and on states with NaN and infinite
//! components; corrupted monitor sections refused exactly when Rust refuses them, and `export --c` of an
//! image with a monitor; and the subcommand's exit codes.

use std::path::PathBuf;
use std::process::Command;

use host_compiler::export::harness::{
    double_integrator_run, exits_image, exits_scenario, ext_image, feedforward_image, maps_image,
    monitor_image, monitor_scenario, monitor_sets, planar_waypoints_run, pwa_image, scenario,
    with_terminal_law, Answer, CHarness, Comparison, ExitCoverage, MonitorPath, Op,
    MONITOR_FORMULAS,
};
use host_compiler::monitor::{AtomSet, Program};
use host_compiler::robustness::mtl::parse;
use host_compiler::spec::{Coords, SetDesc, Shape};
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
        let dir = scratch(&format!("corrupt_array_{name}"));
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

// ---------------------------------------------------------------------------------------------------------
// The task's monitor (section 14).

/// `image` with the monitor section of `prog` (section 14).
fn with_program(image: &[u8], prog: &Program) -> Vec<u8> {
    host_compiler::monitor::attach(image, &prog.encode()).expect("the program attaches")
}

/// [`monitor_scenario`] for `image`, initialised from its bytes ([`Op::InitBytes`]) so that one harness
/// runs every image.
fn monitor_ops(image: &[u8], seed: u64, traces: usize, path: Option<MonitorPath<'_>>) -> Vec<Op> {
    let img = decode(image).expect("a valid image");
    let mut ops = monitor_scenario(&img, seed, traces, path);
    assert_eq!(ops[0], Op::InitEmbedded);
    ops[0] = Op::InitBytes(image.to_vec());
    ops
}

/// Monitor updates in `ops` whose state has a NaN or an infinite component, and whose state has not the
/// plant's n values.
fn unusual_states(ops: &[Op], n: usize) -> (usize, usize) {
    let mut non_finite = 0;
    let mut wrong_len = 0;
    for op in ops {
        if let Op::MonitorUpdate(x) = op {
            non_finite += usize::from(x.iter().any(|v| !v.is_finite()));
            wrong_len += usize::from(x.len() != n);
        }
    }
    (non_finite, wrong_len)
}

/// Checks a monitor comparison: something compared, nothing differed.
fn check_monitor(name: &str, c: &Comparison) {
    eprintln!(
        "{name}: {} traces, {} updates, verdicts per update (pending, satisfied, violated, boundary) {:?}, \
         per trace {:?}; {} monitor inits; mismatches: {} updates, {} traces, {} inits",
        c.monitor_traces,
        c.monitor_updates,
        c.monitor_verdicts,
        c.monitor_decided,
        c.monitor_inits,
        c.monitor_mismatches,
        c.monitor_trace_mismatches,
        c.monitor_init_mismatches
    );
    assert!(c.monitor_traces > 0 && c.monitor_updates > 0, "{name}");
    assert_eq!(c.init_mismatches, 0, "{name}: {:?}", c.first);
    assert_eq!(c.monitor_init_mismatches, 0, "{name}: {:?}", c.first);
    assert_eq!(c.monitor_mismatches, 0, "{name}: {:?}", c.first);
    assert_eq!(c.monitor_trace_mismatches, 0, "{name}");
}

/// The exported monitor against `shared_types::monitor::Monitor`, lo and hi bit for bit and the verdict
/// at every update, on the synthetic programs of [`MONITOR_FORMULAS`] (in a feedforward image, and the
/// first ones in a PWA image too), 160 seeded traces each: paths through and across the atoms' sets
/// (waypoints exactly on a box's face among them, so values of exactly 0 and ties occur), half with NaN,
/// ±∞, huge or wrongly sized states mixed in; inits with an arena one word short (refused by both), exact
/// and with spare words.
#[test]
fn monitors_match_the_rust_evaluator_bit_for_bit() {
    let sets = monitor_sets();
    let n = 3;
    let ff = feedforward_image(900, n, 1, 1, 4, Terminal::HoldLast, 1);
    let pwa = pwa_image(901, n, 2, 1, 2, 10, 0);
    let mut images = Vec::new();
    for (i, &(text, horizon)) in MONITOR_FORMULAS.iter().enumerate() {
        let expr = parse(text).unwrap_or_else(|e| panic!("{text}: {e}"));
        let prog = Program::compile(&expr, &sets, n, 1.0, horizon)
            .unwrap_or_else(|e| panic!("{text}: {e}"));
        images.push((text, with_program(&ff, &prog)));
        if i < 4 {
            images.push((text, with_program(&pwa, &prog)));
        }
    }
    // Every operator and atom kind is there.
    let mut ops_seen = std::collections::BTreeSet::new();
    let mut kinds_seen = std::collections::BTreeSet::new();
    for (_, image) in &images {
        let p = decode(image).unwrap().monitor().expect("a monitor");
        let body = p.body();
        let w = |i: usize| u32::from_le_bytes(body[4 * i..4 * i + 4].try_into().unwrap());
        let nodes_at = 5 + w(4) as usize;
        for k in 0..p.nodes() {
            ops_seen.insert(w(nodes_at + 5 * k));
        }
        let mut at = 5;
        while at < nodes_at {
            let (kind, d) = (w(at), w(at + 1) as usize);
            kinds_seen.insert(kind);
            at += match kind {
                1 | 3 => 2 + 2 * d + 1,
                2 => 2 + 3 * d,
                _ => {
                    let rows = w(at + 2 + d) as usize;
                    3 + d + rows * d + rows
                }
            };
        }
    }
    assert_eq!(ops_seen.len(), 9, "operators {ops_seen:?}");
    assert_eq!(kinds_seen.len(), 4, "atom kinds {kinds_seen:?}");
    let h = CHarness::build(&images[0].1, &scratch("monitor_synthetic")).expect("harness");
    let (mut traces, mut updates, mut odd) = (0usize, 0usize, (0usize, 0usize));
    let (mut decided, mut verdicts) = ([0usize; 4], [0usize; 4]);
    for (i, (text, image)) in images.iter().enumerate() {
        let ops = monitor_ops(image, 2000 + i as u64, 160, None);
        let u = unusual_states(&ops, n);
        odd = (odd.0 + u.0, odd.1 + u.1);
        let c = h.compare(&ops).expect("driver");
        check_monitor(text, &c);
        assert_eq!(
            c.monitor_inits,
            ops.iter()
                .filter(|o| matches!(o, Op::MonitorInit(_)))
                .count()
        );
        traces += c.monitor_traces;
        updates += c.monitor_updates;
        for k in 0..4 {
            decided[k] += c.monitor_decided[k];
            verdicts[k] += c.monitor_verdicts[k];
        }
    }
    eprintln!(
        "synthetic monitors: {} images, {traces} traces, {updates} updates bit for bit ({} states with a \
         NaN or infinite component, {} of the wrong length); verdicts per update {verdicts:?}, per trace \
         {decided:?}",
        images.len(),
        odd.0,
        odd.1
    );
    assert!(
        traces >= 3000 && updates >= 50_000,
        "{traces} traces, {updates} updates"
    );
    assert!(odd.0 > 1000 && odd.1 > 300, "{odd:?}");
    // Every verdict occurs, as a trace's decided verdict and at some update.
    assert!(decided[1] > 100 && decided[2] > 100, "{decided:?}");
    assert!(
        decided[3] > 0 && verdicts[0] > 1000,
        "{decided:?} {verdicts:?}"
    );
}

/// A spec of `examples/`.
fn example(name: &str) -> host_compiler::spec::Problem {
    let path = format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"));
    host_compiler::spec::load(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// The monitors of two real examples, compiled by `Program::for_problem` and attached to a synthetic
/// image of the plant's dimensions: the waypoint formula of `planar-vehicle-waypoints` (G !Unsafe ∧ nested
/// F over 200, 250 and 250 samples on a 500-sample horizon, so the end-of-trace flush decides the nested
/// windows) on runs through its waypoints, and the reach-avoid `!Unsafe U[0,T] Goal` of
/// `double-integrator` on closed-loop runs; plus paths through their sets. Bit for bit at every update,
/// with NaN, ±∞, huge or wrongly sized states mixed into half the traces.
#[test]
fn example_monitors_match_the_rust_evaluator_bit_for_bit() {
    let cases: [(&str, MonitorPath<'_>, usize); 2] = [
        ("planar-vehicle-waypoints.toml", &planar_waypoints_run, 200),
        ("double-integrator.toml", &double_integrator_run, 800),
    ];
    let mut harness: Option<CHarness> = None;
    let (mut traces, mut updates) = (0usize, 0usize);
    for (k, (name, path, runs)) in cases.into_iter().enumerate() {
        let problem = example(name);
        let prog = Program::for_problem(&problem).unwrap_or_else(|e| panic!("{name}: {e}"));
        let (n, m) = (problem.plant.n(), problem.plant.m());
        let image = with_program(
            &feedforward_image(910 + k as u64, n, m, 1, 4, Terminal::Fallback, 1),
            &prog,
        );
        let h = harness.get_or_insert_with(|| {
            CHarness::build(&image, &scratch("monitor_examples")).expect("harness")
        });
        for (what, ops) in [
            (
                "runs",
                monitor_ops(&image, 3000 + k as u64, runs, Some(path)),
            ),
            (
                "set paths",
                monitor_ops(&image, 3100 + k as u64, runs / 4, None),
            ),
        ] {
            let c = h.compare(&ops).expect("driver");
            let label = format!("{name} {what} (N = {})", prog.horizon);
            check_monitor(&label, &c);
            if what == "runs" {
                // The runs both satisfy and violate the task.
                assert!(
                    c.monitor_decided[1] > runs / 20 && c.monitor_decided[2] > runs / 20,
                    "{label}: {:?}",
                    c.monitor_decided
                );
            }
            traces += c.monitor_traces;
            updates += c.monitor_updates;
        }
    }
    eprintln!("example monitors: {traces} traces, {updates} updates bit for bit");
    assert!(traces >= 1000 && updates >= 100_000, "{traces} {updates}");
}

/// Word `i` of a section body set to `v`.
fn set_word(body: &[u8], i: usize, v: u32) -> Vec<u8> {
    let mut b = body.to_vec();
    b[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
    b
}

/// Corrupted monitor sections (tag 14, added by hand to a valid image): the header's dimensions and
/// lengths, every atom kind's fields (kind, dimension, coordinates, non-finite values, a box with lo >
/// hi, a negative radius, a polytope's rows), the nodes (operator, children, windows, a node read twice or
/// not at all), an arena over the largest, the section cut, lengthened, empty or twice, in a PWA image and
/// in an image with model maps (the program is over the plant's state); then 1 500 random changes: one to
/// three words (random, small, special floats) or bits, a word replaced by a finite float, the section cut
/// or lengthened. The C init accepts exactly what `decode` accepts, and every accepted program
/// then runs a trace in both, bit for bit.
#[test]
fn corrupted_monitor_sections_are_refused_as_the_rust_decoder_refuses_them() {
    use host_compiler::monitor::Node;
    let sets = monitor_sets();
    let text = "((B U[0,5] S) | (H R[2,7] !P)) & G[1,3] !Unsafe";
    let prog = Program::compile(&parse(text).unwrap(), &sets, 3, 1.0, 15).expect("compiles");
    let body = prog.encode();
    let ff = feedforward_image(920, 3, 2, 1, 4, Terminal::HoldLast, 1);
    let pwa = pwa_image(921, 3, 2, 1, 2, 10, 1);
    let maps = maps_image(922, 5, 2, 3, 2, 4, Terminal::Fallback, 3, false, 0);
    let tag = SectionKind::Monitor as u16;
    // Word offsets: each atom's record, each node's.
    let mut atom_at = Vec::new();
    let mut at = 5;
    for a in &prog.atoms {
        atom_at.push(at);
        at += a.len();
    }
    let nodes_at = at;
    let node = |pred: &dyn Fn(&Node) -> bool| {
        nodes_at + 5 * prog.nodes.iter().position(pred).expect("the node is there")
    };
    let kind_at = |kind: u32| {
        atom_at[prog
            .atoms
            .iter()
            .position(|a| a[0] == kind)
            .expect("the atom kind is there")]
    };
    let (bx, ball, half, poly) = (kind_at(2), kind_at(3), kind_at(1), kind_at(4));
    let until = node(&|x| matches!(x, Node::Until(..)));
    let always = node(&|x| matches!(x, Node::Always(..)));
    let and = node(&|x| matches!(x, Node::And(..)));
    let atom0 = node(&|x| matches!(x, Node::Atom(..)));
    let root = nodes_at + 5 * (prog.nodes.len() - 1);
    let f = |v: f32| v.to_bits();
    let mut long = body.clone();
    long.extend_from_slice(&0u32.to_le_bytes());
    // An arena over MAX_MONITOR_WORDS (a G read at 101 samples keeps 65 002 entries of 2 words), and
    // one under it.
    let big = |outer: usize, inner: usize, horizon: usize| {
        let e = parse(&format!("F[0,{outer}] G[0,{inner}] B")).unwrap();
        Program::compile(&e, &sets, 3, 1.0, horizon)
            .expect("compiles")
            .encode()
    };
    let five = {
        // The same formula over the maps image's plant (5 states).
        let mut s = sets.clone();
        s.retain(|(n, _)| n != "H" && n != "S");
        s.push((
            "S".into(),
            AtomSet::Set(SetDesc {
                shape: Shape::Ball {
                    center: vec![0.5, 0.0, -0.5],
                    radius: 0.75,
                },
                coords: Coords::StateIndices(vec![0, 1, 2]),
            }),
        ));
        s.push((
            "H".into(),
            AtomSet::HalfSpace {
                a: vec![1.0, -1.0, 0.5, 0.0, 0.25],
                b: 0.25,
            },
        ));
        Program::compile(&parse(text).unwrap(), &s, 5, 1.0, 15)
            .expect("compiles")
            .encode()
    };
    let cases: Vec<(&str, Vec<u8>, bool)> = vec![
        ("valid", with_section(&ff, tag, &body), true),
        ("in a PWA image", with_section(&pwa, tag, &body), true),
        (
            "over the plant of a maps image",
            with_section(&maps, tag, &five),
            true,
        ),
        (
            "over ξ of a maps image",
            with_section(&maps, tag, &body),
            false,
        ),
        (
            "after a fingerprint",
            with_section(
                &with_section(&ff, 12, &postcard(&fingerprint())),
                tag,
                &body,
            ),
            true,
        ),
        (
            "twice",
            with_section(&with_section(&ff, tag, &body), tag, &body),
            false,
        ),
        ("empty", with_section(&ff, tag, &[]), false),
        ("header only", with_section(&ff, tag, &body[..20]), false),
        (
            "one word short",
            with_section(&ff, tag, &body[..body.len() - 4]),
            false,
        ),
        (
            "one byte short",
            with_section(&ff, tag, &body[..body.len() - 1]),
            false,
        ),
        ("one word long", with_section(&ff, tag, &long), false),
        (
            "n = 4",
            with_section(&ff, tag, &set_word(&body, 0, 4)),
            false,
        ),
        (
            "n = 0",
            with_section(&ff, tag, &set_word(&body, 0, 0)),
            false,
        ),
        (
            "N = 65536",
            with_section(&ff, tag, &set_word(&body, 1, 65_536)),
            false,
        ),
        (
            "N = 0",
            with_section(&ff, tag, &set_word(&body, 1, 0)),
            true,
        ),
        (
            "N = 65535",
            with_section(&ff, tag, &set_word(&body, 1, 65_535)),
            true,
        ),
        (
            "33 atoms",
            with_section(&ff, tag, &set_word(&body, 2, 33)),
            false,
        ),
        (
            "one atom fewer",
            with_section(&ff, tag, &set_word(&body, 2, prog.atoms.len() as u32 - 1)),
            false,
        ),
        (
            "no nodes",
            with_section(&ff, tag, &set_word(&body, 3, 0)),
            false,
        ),
        (
            "33 nodes",
            with_section(&ff, tag, &set_word(&body, 3, 33)),
            false,
        ),
        (
            "atom words + 1",
            with_section(&ff, tag, &set_word(&body, 4, (nodes_at - 5) as u32 + 1)),
            false,
        ),
        (
            "atom kind 0",
            with_section(&ff, tag, &set_word(&body, bx, 0)),
            false,
        ),
        (
            "atom kind 5",
            with_section(&ff, tag, &set_word(&body, ball, 5)),
            false,
        ),
        (
            "a ball as a half-space",
            with_section(&ff, tag, &set_word(&body, ball, 1)),
            true,
        ),
        (
            "d = 0",
            with_section(&ff, tag, &set_word(&body, half + 1, 0)),
            false,
        ),
        (
            "d = n + 1",
            with_section(&ff, tag, &set_word(&body, ball + 1, 4)),
            false,
        ),
        (
            "coordinate n",
            with_section(&ff, tag, &set_word(&body, bx + 2, 3)),
            false,
        ),
        (
            "coordinate n - 1",
            with_section(&ff, tag, &set_word(&body, bx + 2, 2)),
            true,
        ),
        (
            "a NaN weight",
            with_section(&ff, tag, &set_word(&body, half + 2 + 3, f(f32::NAN))),
            false,
        ),
        (
            "an infinite offset",
            with_section(&ff, tag, &set_word(&body, half + 2 + 6, f(f32::INFINITY))),
            false,
        ),
        (
            "box lo > hi",
            with_section(&ff, tag, &set_word(&body, bx + 4, f(0.75))),
            false,
        ),
        (
            "box lo = hi",
            with_section(&ff, tag, &set_word(&body, bx + 4, f(0.5))),
            true,
        ),
        (
            "ball radius < 0",
            with_section(&ff, tag, &set_word(&body, ball + 2 + 3 + 3, f(-1e-30))),
            false,
        ),
        (
            "ball radius -0",
            with_section(&ff, tag, &set_word(&body, ball + 2 + 3 + 3, f(-0.0))),
            true,
        ),
        (
            "ball radius 0",
            with_section(&ff, tag, &set_word(&body, ball + 2 + 3 + 3, 0)),
            true,
        ),
        (
            "polytope rows 0",
            with_section(&ff, tag, &set_word(&body, poly + 4, 0)),
            false,
        ),
        (
            "polytope rows 65",
            with_section(&ff, tag, &set_word(&body, poly + 4, 65)),
            false,
        ),
        (
            "polytope rows 2",
            with_section(&ff, tag, &set_word(&body, poly + 4, 2)),
            false,
        ),
        (
            "operator 0",
            with_section(&ff, tag, &set_word(&body, until, 0)),
            false,
        ),
        (
            "operator 10",
            with_section(&ff, tag, &set_word(&body, until, 10)),
            false,
        ),
        (
            "U as R",
            with_section(&ff, tag, &set_word(&body, until, 9)),
            true,
        ),
        (
            "G as F",
            with_section(&ff, tag, &set_word(&body, always, 6)),
            true,
        ),
        (
            "∧ as ∨",
            with_section(&ff, tag, &set_word(&body, and, 5)),
            true,
        ),
        (
            "an atom past the atoms",
            with_section(
                &ff,
                tag,
                &set_word(&body, atom0 + 1, prog.atoms.len() as u32),
            ),
            false,
        ),
        (
            "negation 2",
            with_section(&ff, tag, &set_word(&body, atom0 + 2, 2)),
            false,
        ),
        (
            "an atom with a window",
            with_section(&ff, tag, &set_word(&body, atom0 + 4, 1)),
            false,
        ),
        (
            "an unnegated atom as ⊤ (its atom unread)",
            with_section(&ff, tag, &set_word(&body, atom0, 2)),
            true,
        ),
        (
            "∧ of one child twice",
            {
                let c1 = u32::from_le_bytes(body[4 * (and + 1)..4 * (and + 2)].try_into().unwrap());
                with_section(&ff, tag, &set_word(&body, and + 2, c1))
            },
            false,
        ),
        (
            "the root reading itself",
            with_section(
                &ff,
                tag,
                &set_word(&body, root + 1, prog.nodes.len() as u32 - 1),
            ),
            false,
        ),
        (
            "a node read twice, one unread",
            {
                let c1 =
                    u32::from_le_bytes(body[4 * (root + 1)..4 * (root + 2)].try_into().unwrap());
                with_section(&ff, tag, &set_word(&body, root + 2, c1.saturating_sub(1)))
            },
            false,
        ),
        (
            "U with a > b",
            with_section(&ff, tag, &set_word(&body, until + 3, 6)),
            false,
        ),
        (
            "U with b = 65536",
            with_section(&ff, tag, &set_word(&body, until + 4, 65_536)),
            false,
        ),
        (
            "U with b = 65535",
            with_section(&ff, tag, &set_word(&body, until + 4, 65_535)),
            true,
        ),
        (
            "U with a = b = 0",
            with_section(&ff, tag, &set_word(&body, until + 4, 0)),
            true,
        ),
        (
            "G with a second child",
            with_section(&ff, tag, &set_word(&body, always + 2, 1)),
            false,
        ),
        (
            "G with a > b",
            with_section(&ff, tag, &set_word(&body, always + 3, 4)),
            false,
        ),
        (
            "an arena over the largest",
            with_section(&ff, tag, &big(100, 65_000, 65_535)),
            false,
        ),
        (
            "an arena under the largest",
            with_section(&ff, tag, &big(10, 30_000, 40_000)),
            true,
        ),
    ];
    // The probe: a trace of N + 3 updates through the base program's sets (perturbed), run after every
    // init (accepted programs run to their end; after a refusal the updates have no monitor).
    let base = decode(&cases[0].1).unwrap();
    let probe: Vec<Op> = monitor_scenario(&base, 31, 3, None)
        .into_iter()
        .skip_while(|op| !matches!(op, Op::MonitorUpdate(_)))
        .collect();
    assert!(probe.len() >= 20, "{}", probe.len());
    let mut ops = Vec::new();
    for (what, bytes, ok) in &cases {
        assert_eq!(
            decode(bytes).is_ok(),
            *ok,
            "{what}: {:?}",
            decode(bytes).err()
        );
        ops.push(Op::InitBytes(bytes.clone()));
        ops.push(Op::MonitorInit(0));
        ops.extend(probe.iter().cloned());
    }
    let h = CHarness::build(&cases[0].1, &scratch("monitor_corrupt")).expect("harness");
    let c = h.compare(&ops).expect("driver");
    check_monitor("targeted corruptions", &c);
    assert_eq!(c.inits, cases.len());
    let accepted = cases.iter().filter(|c| c.2).count();
    assert!(c.monitor_traces >= 2 * accepted, "{}", c.monitor_traces);
    // Random corruption of the body (the section is the last): the C refuses exactly what Rust refuses.
    let valid = &cases[0].1;
    let (off, len) = (valid.len() - body.len(), body.len());
    let mut rng = ChaCha8Rng::seed_from_u64(1446);
    let mut ops = Vec::new();
    for k in 0..1500 {
        let mut b = body.clone();
        let words = b.len() / 4;
        match k % 6 {
            // One to three words: random, small, or a special float.
            0..=2 => {
                for _ in 0..rng.random_range(1..=3) {
                    let w = rng.random_range(0..words);
                    let v: u32 = match rng.random_range(0..4) {
                        0 => rng.random(),
                        1 | 2 => rng.random_range(0..40),
                        _ => [f32::NAN, f32::INFINITY, -1.0, 0.0][rng.random_range(0..4)].to_bits(),
                    };
                    b[4 * w..4 * w + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
            // One to three bits.
            3 => {
                for _ in 0..rng.random_range(1..=3) {
                    let i = rng.random_range(0..b.len());
                    b[i] ^= 1 << rng.random_range(0..8);
                }
            }
            // A word (a value, most often) replaced by a random finite float.
            4 => {
                let w = rng.random_range(0..words);
                let v = (4.0 * rng.random::<f32>() - 2.0).to_bits();
                b[4 * w..4 * w + 4].copy_from_slice(&v.to_le_bytes());
            }
            // Cut or lengthened.
            _ => {
                if rng.random::<bool>() {
                    b.truncate(rng.random_range(0..b.len()));
                } else {
                    for _ in 0..rng.random_range(1..=8) {
                        b.push(rng.random());
                    }
                }
            }
        }
        ops.push(Op::InitBytes(with_section_body(valid, off, len, &b)));
        ops.push(Op::MonitorInit(0));
        ops.extend(probe.iter().cloned());
    }
    let c = h.compare(&ops).expect("driver");
    let accepted = h
        .run_rust(&ops)
        .iter()
        .filter(|a| matches!(a, Answer::MonitorInit(0, _)))
        .count();
    eprintln!(
        "random corruptions: {accepted} of {} accepted by Rust",
        c.inits
    );
    check_monitor("random corruptions", &c);
    assert!(accepted > 100 && accepted < c.inits - 100, "{accepted}");
}

/// `export --c` on an image with a monitor (tag 14) succeeds, `controller_image.h` states its arena,
/// and the exported array, initialised by `sc_init`, steps the controller as Rust does and as the same
/// image without the monitor does, and runs the monitor bit for bit (`sc_monitor_init` on the embedded
/// image).
#[test]
fn export_of_an_image_with_a_monitor() {
    let sets = monitor_sets();
    let prog = Program::compile(&parse(MONITOR_FORMULAS[3].0).unwrap(), &sets, 3, 1.0, 20).unwrap();
    let plain = feedforward_image(930, 3, 2, 2, 6, Terminal::Fallback, 2);
    let image = with_program(&plain, &prog);
    let img = decode(&image).expect("valid");
    let words = img.monitor().expect("a monitor").words();
    let files = host_compiler::export::c::files(&image).expect("exports");
    let image_h = &files
        .iter()
        .find(|f| f.name == "controller_image.h")
        .unwrap()
        .text;
    assert!(
        image_h.contains(&format!("#define SC_IMAGE_MONITOR_WORDS {words}u")),
        "{image_h}"
    );
    let plain_h = host_compiler::export::c::files(&plain).unwrap();
    assert!(plain_h[2]
        .text
        .contains("#define SC_IMAGE_MONITOR_WORDS 0u"));
    // The subcommand.
    let dir = scratch("monitor_cli");
    let img_path = dir.join("controller.img");
    std::fs::write(&img_path, &image).unwrap();
    let out = host_compiler()
        .args(["export", "--c"])
        .arg(&img_path)
        .arg("--out")
        .arg(dir.join("c"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    assert!(dir.join("c").join("controller.c").is_file());
    // The controller steps alike, with and without the monitor; the monitor runs alike.
    let mut ops = scenario(&img, 77, 3000);
    let steps: Vec<Op> = ops.clone();
    assert!(
        host_compiler::export::harness::reference(&plain, &steps)
            == host_compiler::export::harness::reference(&image, &steps),
        "the monitor changes the controller's answers"
    );
    ops.extend(monitor_scenario(&img, 78, 200, None));
    let h = CHarness::build(&image, &dir.join("harness")).expect("harness");
    let c = h.compare(&ops).expect("driver");
    check_monitor("embedded", &c);
    assert_eq!(c.mismatches, 0, "{:?}", c.first);
    assert!(
        c.states >= 3000 && c.by_status[0] > 300,
        "{:?}",
        c.by_status
    );
}

/// States whose every component is NaN, +∞, −∞, ±3·10³⁸, 0 or an ordinary value, at every sample: the
/// atoms' sums then meet NaNs of both signs (the input's, and inf − inf's or 0·∞'s of the other sign),
/// which the monitor's ∧, ∨, windows and negations then combine. Bit for bit with Rust, NaN signs
/// included, on programs of ∧ and ∨ of such atoms and of windows over them.
#[test]
fn non_finite_states_match_bit_for_bit() {
    let odd = |rng: &mut ChaCha8Rng, len: usize| -> Vec<Vec<f32>> {
        (0..len)
            .map(|_| {
                (0..3)
                    .map(|_| match rng.random_range(0..7) {
                        0 => f32::NAN,
                        1 => f32::INFINITY,
                        2 => f32::NEG_INFINITY,
                        3 => [3.0e38, -3.0e38][rng.random_range(0..2)],
                        4 => 0.0,
                        _ => rng.random_range(-2.0f32..2.0),
                    })
                    .collect()
            })
            .collect()
    };
    let ff = feedforward_image(950, 3, 1, 1, 4, Terminal::HoldLast, 1);
    let formulas = [
        ("(S & H) | (P & !S)", 3),
        ("S & !H", 2),
        ("!P | H", 2),
        ("F[0,3] (S & H) | G[0,2] (!P | S)", 8),
        ("(H U[0,3] S) & (P R[1,4] !S)", 9),
        ("!Unsafe U[0,5] (H & P)", 6),
    ];
    let h = CHarness::build(&ff, &scratch("monitor_non_finite")).expect("harness");
    let (mut updates, mut nan_reports) = (0usize, 0usize);
    for (i, (text, horizon)) in formulas.into_iter().enumerate() {
        let image = monitor_image(&ff, text, horizon);
        let ops = monitor_ops(&image, 4000 + i as u64, 400, Some(&odd));
        let c = h.compare(&ops).expect("driver");
        check_monitor(text, &c);
        updates += c.monitor_updates;
        nan_reports += h
            .run_rust(&ops)
            .iter()
            .filter(|a| matches!(a, Answer::Monitor(lo, _, v) if *v != u8::MAX && f32::from_bits(*lo).is_nan()))
            .count();
    }
    eprintln!(
        "non-finite states: {updates} updates bit for bit, {nan_reports} reporting a NaN bound"
    );
    assert!(
        updates > 10_000 && nan_reports > 100,
        "{updates} {nan_reports}"
    );
}
