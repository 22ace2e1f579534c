//! Hardware-in-the-loop tests: the real firmware in QEMU (mps2-an386), the plant on the host.
//!
//! They need qemu-system-arm and the thumbv7em-none-eabihf target: `cargo xtask test` installs both before
//! it runs them; without them each test fails and says so.
#![allow(non_snake_case)]

use qemu_tests::closed_loop::{self, check, exchange, wire, HostEvaluator};
use qemu_tests::firmware::{self, FirmwareConfig};
use qemu_tests::images::{self, TestImage};
use qemu_tests::logs::LogLine;
use qemu_tests::qemu::Qemu;
use qemu_tests::HilError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::eval::{Input, Status};
use shared_types::image::decode;
use shared_types::protocol::{decode_frame, encode_frame, Request, State, MAX_FRAME};
use std::path::PathBuf;
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_secs(120);

fn good_image() -> (TestImage, PathBuf) {
    let img = images::double_integrator().expect("test image builds");
    let path = firmware::write_image("double_integrator", &img.bytes).expect("image written");
    let elf = firmware::build(
        "double_integrator",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    (img, elf)
}

fn ok<T>(r: Result<T, HilError>) -> T {
    r.unwrap_or_else(|e| panic!("{e}"))
}

fn has_line(logs: &[LogLine], needle: &str) -> bool {
    logs.iter().any(|l| l.message.contains(needle))
}

fn dump(logs: &[LogLine]) -> String {
    logs.iter().map(|l| format!("  {l}\n")).collect()
}

fn norm(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum::<f64>().sqrt()
}

/// The boot calibration line says `2N instructions took T ticks`; T × 40 must be within one tick.
fn check_calibration(logs: &[LogLine]) {
    let line = logs
        .iter()
        .find(|l| l.message.starts_with("calibration:"))
        .expect("calibration line");
    let words: Vec<&str> = line.message.split_whitespace().collect();
    let instructions: u64 = words[1].parse().expect("instruction count");
    let ticks: u64 = words[4].parse().expect("tick count");
    let per_tick = firmware_instructions_per_tick();
    assert!(
        (ticks * per_tick).abs_diff(instructions) <= per_tick,
        "SysTick conversion is off: {instructions} instructions took {ticks} ticks (× {per_tick})"
    );
}

/// The documented conversion (firmware/boards/mps2-an386/src/cost.rs): 1 ns per instruction, SysTick at 25 MHz.
fn firmware_instructions_per_tick() -> u64 {
    1_000_000_000 / 25_000_000
}

#[test]
fn a_table_inputs_match_the_host_evaluator_bit_for_bit_and_the_state_converges() {
    let (img, elf) = good_image();
    let plant = img.discrete_plant();
    let image = decode(&img.bytes).unwrap();
    let mut worst = 0;
    for ball in 0..img.centres.len() {
        let x0: Vec<f64> = img.centres[ball]
            .iter()
            .zip([0.1, -0.05])
            .map(|(&c, o)| c as f64 + o)
            .collect();
        assert!(
            img.dist2(&x0, ball) < (img.deltas[ball] as f64).powi(2),
            "x0 must start inside ball {ball}"
        );
        let mut q = ok(Qemu::launch(&elf, TIMEOUT));
        let mut host = HostEvaluator::new(image);
        let steps = 100;
        let trace = ok(closed_loop::run(&mut q, &plant, &mut host, &x0, 0, steps));
        assert!(trace.replies.iter().all(|r| r.status == Status::Ok));
        let (n0, n1) = (norm(&x0), norm(trace.last_state()));
        assert!(
            n0 > 1.5 && n1 < 1e-3,
            "ball {ball}: |x| went from {n0} to {n1}"
        );
        // The feedforward term matters: the inputs are not those of K x alone.
        let kx = |x: &[f64]| (images::K_TRACK[0] * x[0] + images::K_TRACK[1] * x[1]) as f32;
        assert!(
            (0..10).any(|k| (trace.replies[k].u.as_slice()[0] - kx(&trace.states[k])).abs() > 0.1)
        );
        worst = worst.max(trace.max_cost(Status::Ok).unwrap_or(0));
        let exit = ok(q.shutdown());
        assert_eq!(exit.code, Some(0), "logs:\n{}", dump(&exit.logs));
        assert!(
            has_line(&exit.logs, "image accepted"),
            "logs:\n{}",
            dump(&exit.logs)
        );
        let summary =
            format!("shutdown: ok={steps} out_of_envelope=0 bad_frames=0 rejected=0 max_cost=");
        assert!(
            has_line(&exit.logs, &summary),
            "logs:\n{}",
            dump(&exit.logs)
        );
        check_calibration(&exit.logs);
        let stack =
            qemu_tests::logs::stack_peak(&exit.logs).expect("stack_peak in the shutdown line");
        assert!(
            stack > 0 && stack < 16 * 1024,
            "stack high-water mark {stack} bytes"
        );
    }
    assert!(worst > 0);
    println!("HIL (a): worst-case feedforward step cost {worst} instructions");
}

#[test]
fn b_a_corrupted_image_is_refused_and_every_reply_says_image_rejected() {
    let img = images::double_integrator().unwrap();
    let bad = images::corrupted(&img.bytes);
    assert!(decode(&bad).is_err());
    let path = firmware::write_image("corrupted", &bad).unwrap();
    let elf = ok(firmware::build(
        "corrupted",
        &FirmwareConfig {
            image: Some(path),
            ..Default::default()
        },
    ));
    let plant = img.discrete_plant();
    let mut q = ok(Qemu::launch(&elf, TIMEOUT));
    // The build-time fallback: zero input of the header's m = 1.
    let zero = Input::zero(1);
    let mut x = vec![1.0, 0.0];
    for seq in 0..20u32 {
        let r = ok(exchange(&mut q, seq, &x, |_| (Status::ImageRejected, zero)));
        let u: Vec<f64> = r.u.as_slice().iter().map(|&v| v as f64).collect();
        x = plant.step(&x, &u);
        if seq == 9 {
            // A malformed frame while rejected still says ImageRejected, and does not advance seq.
            ok(q.send_raw(&[7, 7, 7, 0]));
            let r = ok(q.recv());
            assert_eq!(
                (r.seq, r.status, r.u),
                (10, Status::ImageRejected, wire(&zero))
            );
        }
    }
    // Zero input leaves the double integrator at rest where it was.
    assert_eq!(x, vec![1.0, 0.0]);
    let exit = ok(q.shutdown());
    assert_eq!(exit.code, Some(0));
    assert!(
        has_line(&exit.logs, "image rejected: CrcMismatch"),
        "logs:\n{}",
        dump(&exit.logs)
    );
    assert!(
        has_line(&exit.logs, "rejected=20"),
        "logs:\n{}",
        dump(&exit.logs)
    );
}

fn frame(req: &Request) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    encode_frame(req, &mut buf).unwrap().to_vec()
}

#[test]
fn c_malformed_frames_get_bad_frame_and_the_loop_goes_on_correctly() {
    let (img, elf) = good_image();
    let plant = img.discrete_plant();
    let image = decode(&img.bytes).unwrap();
    let mut host = HostEvaluator::new(image);
    let mut q = ok(Qemu::launch(&elf, TIMEOUT));
    let x0 = vec![2.1, 0.05];
    let before = ok(closed_loop::run(&mut q, &plant, &mut host, &x0, 0, 10));
    let mut x = before.last_state().to_vec();
    let next = 10u32;

    let mut rng = ChaCha8Rng::seed_from_u64(0xbad_f7a3e);
    let good = frame(&Request::Step {
        seq: next,
        x: State::from_slice(&[x[0] as f32, x[1] as f32]).unwrap(),
    });
    // (bytes, the seq the reply must carry)
    let mut cases: Vec<(String, Vec<u8>, u32)> = Vec::new();
    for i in 0..5 {
        let len = rng.random_range(8..MAX_FRAME - 1);
        let mut b: Vec<u8> = (0..len).map(|_| rng.random_range(1..=255u8)).collect();
        assert!(
            decode_frame::<Request>(&b).is_err(),
            "random case {i} happens to be valid"
        );
        b.push(0);
        cases.push((format!("random bytes #{i}"), b, next));
    }
    for cut in [1, good.len() / 2, good.len() - 2] {
        let mut b = good[..cut].to_vec();
        b.push(0);
        cases.push((format!("truncated to {cut} bytes"), b, next));
    }
    let mut over = vec![0x41u8; MAX_FRAME + 10];
    over.push(0);
    cases.push(("oversize".into(), over, next));
    let wrong = |seq: u32| {
        frame(&Request::Step {
            seq,
            x: State::from_slice(&[x[0] as f32, x[1] as f32]).unwrap(),
        })
    };
    cases.push(("sequence number ahead".into(), wrong(next + 5), next + 5));
    cases.push(("sequence number replayed".into(), wrong(next - 1), next - 1));
    cases.push((
        "three-component state".into(),
        frame(&Request::Step {
            seq: next,
            x: State::from_slice(&[0.0; 3]).unwrap(),
        }),
        next,
    ));
    cases.push((
        "NaN in the state".into(),
        frame(&Request::Step {
            seq: next,
            x: State::from_slice(&[f32::NAN, 0.0]).unwrap(),
        }),
        next,
    ));
    // Trailing byte after a valid message: re-frame the decoded bytes plus one.
    let mut trailing = good.clone();
    let body_len = trailing.len() - 1;
    trailing[body_len] = 0x33; // replace the delimiter by a data byte …
    trailing.push(0); // … and end the frame after it
    cases.push(("trailing byte".into(), trailing, next));

    let expect_u = wire(&host.bad_frame_input());
    for (what, bytes, seq) in &cases {
        ok(q.send_raw(bytes));
        let r = ok(q.recv());
        assert_eq!(r.status, Status::BadFrame, "{what}");
        assert_eq!(r.seq, *seq, "{what}");
        assert_eq!(
            r.u, expect_u,
            "{what}: BadFrame carries the fallback at the last state"
        );
        assert_eq!(r.cost, 0, "{what}");
    }
    // Empty frames (lone delimiters) are ignored: no reply, and the next step is answered normally.
    ok(q.send_raw(&[0, 0, 0]));

    let after = ok(closed_loop::run(&mut q, &plant, &mut host, &x, next, 90));
    x = after.last_state().to_vec();
    assert!(
        norm(&x) < 1e-3,
        "state did not converge after the bad frames: {x:?}"
    );
    let exit = ok(q.shutdown());
    assert_eq!(exit.code, Some(0));
    let summary = format!(
        "ok=100 out_of_envelope=0 bad_frames={} rejected=0",
        cases.len()
    );
    assert!(
        has_line(&exit.logs, &summary),
        "want {summary}; logs:\n{}",
        dump(&exit.logs)
    );
}

#[test]
fn d_a_state_outside_every_ball_gets_out_of_envelope_and_the_fallback() {
    let (img, elf) = good_image();
    let plant = img.discrete_plant();
    let image = decode(&img.bytes).unwrap();
    let mut host = HostEvaluator::new(image);
    let x0 = vec![10.0, 10.0];
    assert!(img.outside_every_ball(&x0));
    let mut q = ok(Qemu::launch(&elf, TIMEOUT));
    let trace = ok(closed_loop::run(&mut q, &plant, &mut host, &x0, 0, 60));
    assert!(trace
        .replies
        .iter()
        .all(|r| r.status == Status::OutOfEnvelope));
    // The fallback is the saturated linear law: at (10, 10), K x = −78 saturates to −20.
    assert_eq!(trace.replies[0].u.as_slice(), &[-20.0]);
    ok(check(trace.replies.iter().all(|r| r.cost > 0), || {
        "fallback evaluation has a cost".into()
    }));
    let exit = ok(q.shutdown());
    assert_eq!(exit.code, Some(0));
    assert!(
        has_line(&exit.logs, "ok=0 out_of_envelope=60 bad_frames=0"),
        "logs:\n{}",
        dump(&exit.logs)
    );
    println!(
        "HIL (d): worst-case out-of-envelope step cost {} instructions",
        trace.max_cost(Status::OutOfEnvelope).unwrap_or(0)
    );
}

#[test]
fn e_panic_and_hardfault_exit_qemu_with_failure() {
    for (kind, code, needle) in [
        ("panic", 101, "panic:"),
        ("hardfault", 102, "HardFault at pc="),
    ] {
        let elf = ok(firmware::build(
            &format!("fault_{kind}"),
            &FirmwareConfig {
                fault_injection: Some(kind),
                ..Default::default()
            },
        ));
        let q = ok(Qemu::launch(&elf, TIMEOUT));
        let exit = ok(q.wait());
        assert_eq!(exit.code, Some(code), "{kind}; logs:\n{}", dump(&exit.logs));
        assert!(
            has_line(&exit.logs, needle),
            "{kind}; logs:\n{}",
            dump(&exit.logs)
        );
    }
}
