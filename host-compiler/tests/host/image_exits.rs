//! Segment exits in the image (section 9) and the evaluator's re-synchronisation at a guard ((4.41)–(4.42)):
//! the segment changes at the first sample whose state is θ deep in the guard, its table restarts at row
//! 0, and the image refuses exits that cannot be run; `inspect` shows them.

use host_compiler::emit::{ImageBuilder, SegmentExit, TrajectoryEntry};
use shared_types::eval::{Controller, Status};
use shared_types::image::{decode, ImageError};

/// Two locations (K₀ = [1, 0], K₁ = [0, 1]); one trajectory: 3 rows in location 0 (v = 10, 11, 12) whose
/// exit is the guard −x₁ ≤ 0 with θ = 0.5, then 2 rows in location 1 (v = 20, 21).
fn builder(exit: SegmentExit) -> ImageBuilder {
    let mut b = ImageBuilder::new(2, 1, 0.1);
    b.add_location(vec![1.0, 0.0], vec![1.0, 0.0, 0.0, 1.0]);
    b.add_location(vec![0.0, 1.0], vec![1.0, 0.0, 0.0, 1.0]);
    b.trajectories.push(TrajectoryEntry {
        x0: vec![-5.0, 0.0],
        delta: 1.0,
        v: vec![10.0, 11.0, 12.0, 20.0, 21.0],
        location: vec![0, 0, 0, 1, 1],
    });
    b.exits.push(vec![exit, SegmentExit::Table]);
    b
}

fn guard() -> SegmentExit {
    SegmentExit::Guard {
        a: vec![-1.0, 0.0],
        b: 0.0,
        theta: 0.5,
        next: vec![0.25, 1.0],
    }
}

#[test]
fn the_table_restarts_where_the_guard_is_seen() {
    let bytes = builder(guard()).to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert!(img.has_exits());
    let mut c = Controller::new(img);
    // κ = 0, 1: outside the guard (and 0.4 deep is not θ = 0.5 deep): location 0, rows 0 and 1.
    assert_eq!(c.step(&[-5.0, 0.5]).unwrap().as_slice(), &[-5.0 + 10.0]);
    assert_eq!(c.step(&[0.4, 2.0]).unwrap().as_slice(), &[0.4 + 11.0]);
    // κ = 2: 0.6 deep: location 1 from its row 0 (v = 20), u = x₂ + 20.
    assert_eq!(c.step(&[0.6, 3.0]).unwrap().as_slice(), &[3.0 + 20.0]);
    assert_eq!(c.step(&[0.1, 3.0]).unwrap().as_slice(), &[3.0 + 21.0]);
    // Past the last segment's rows: the terminal behaviour (hold the last row).
    assert_eq!(c.step(&[0.1, 4.0]).unwrap().as_slice(), &[4.0 + 21.0]);
    // Byte-identical round trip through the owned builder.
    let again = ImageBuilder::from_image(&img).to_bytes().unwrap();
    assert_eq!(again, bytes);
}

#[test]
fn a_guard_never_seen_leaves_the_envelope() {
    let bytes = builder(guard()).to_bytes().unwrap();
    let mut c = Controller::new(decode(&bytes).unwrap());
    for k in 0..3 {
        assert!(c.step(&[-5.0, 0.0]).is_ok(), "row {k}");
    }
    // Segment 0's three rows are used up without the guard: out of the certified envelope, latched.
    assert_eq!(c.step(&[-5.0, 0.0]), Err(Status::OutOfEnvelope));
    assert_eq!(c.step(&[1.0, 0.0]), Err(Status::OutOfEnvelope));
}

#[test]
fn exits_that_cannot_run_are_refused() {
    // A guard exit on the last segment (there is no next segment to move to).
    let mut b = builder(SegmentExit::Table);
    b.exits[0][1] = guard();
    assert!(matches!(
        b.to_bytes(),
        Err(host_compiler::emit::EmitError::Rejected(
            ImageError::BadExit { segment: 1 }
        ))
    ));
    // A negative threshold.
    let b = builder(SegmentExit::Guard {
        a: vec![-1.0, 0.0],
        b: 0.0,
        theta: -1.0,
        next: vec![0.0, 0.0],
    });
    assert!(matches!(
        b.to_bytes(),
        Err(host_compiler::emit::EmitError::Rejected(
            ImageError::BadExit { segment: 0 }
        ))
    ));
    // A flipped kind byte in an encoded image (CRC fixed up) is refused by decode.
    let mut bytes = builder(guard()).to_bytes().unwrap();
    // The exits section is the last: its two records of 4(2n + 3) bytes end the image, and the first
    // record's kind is its first byte.
    let pos = bytes.len() - 2 * 4 * (2 * 2 + 3);
    assert_eq!(bytes[pos], 1, "the guard exit's kind");
    bytes[pos] = 7;
    let crc = shared_types::image::compute_crc(&bytes).unwrap();
    bytes[28..32].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(
        decode(&bytes).err(),
        Some(ImageError::BadExit { segment: 0 })
    );
}

/// `inspect --json` shows each segment's exit as stored (kind, â, b̂, θ, the next start); an image without
/// the section shows none.
#[test]
fn inspect_shows_the_exits() {
    let bytes = builder(guard()).to_bytes().unwrap();
    let out = host_compiler::cli::inspect::render(&bytes, "exits.img", true).unwrap();
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let segs = j["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 2);
    assert_eq!(
        segs[0]["exit"],
        serde_json::json!({"kind": "guard", "a": [-1.0, 0.0], "b": 0.0, "theta": 0.5, "next": [0.25, 1.0]})
    );
    assert_eq!(segs[1]["exit"], serde_json::json!({"kind": "table"}));
    let mut plain = builder(SegmentExit::Table);
    plain.exits.clear();
    let bytes = plain.to_bytes().unwrap();
    let out = host_compiler::cli::inspect::render(&bytes, "plain.img", true).unwrap();
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(j["segments"][0].get("exit").is_none(), "{j}");
}
