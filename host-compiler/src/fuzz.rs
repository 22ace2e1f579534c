//! The functions the cargo-fuzz targets (`fuzz/fuzz_targets/*.rs`) call, one per target, so that the
//! replay test (`tests/host/fuzz_corpus.rs`) runs every committed corpus file through exactly the same
//! code on the stable toolchain. Each takes arbitrary bytes, must never panic, and panics (an assertion)
//! only when an invariant of the code under test is broken: a decoded image or frame that does not
//! re-encode to its own bytes, a parse that succeeds on one path and fails on its twin.

use shared_types::capacity::HEADER_LEN;
use shared_types::eval::Controller;
use shared_types::image::{decode, encode};
use shared_types::protocol::{decode_frame, encode_frame, FrameEvent, Reader, Reply, Request};

/// The image decoder, on the bytes as they are and on a copy whose header payload length and CRC are
/// made to match (so that mutations reach the checks after the CRC): any bytes give an error or an
/// image; an image re-encodes to exactly its bytes (the format is canonical) and steps through the shared
/// evaluator on a few states (zero, each of the first balls' centres, states taken from the input's own
/// bytes, a non-finite one) without panicking.
pub fn image(data: &[u8]) {
    decoded_image(data);
    if data.len() >= HEADER_LEN {
        let mut fixed = data.to_vec();
        let payload = u32::try_from(fixed.len() - HEADER_LEN).unwrap_or(u32::MAX);
        fixed[24..28].copy_from_slice(&payload.to_le_bytes());
        if let Ok(crc) = shared_types::image::compute_crc(&fixed) {
            fixed[28..32].copy_from_slice(&crc.to_le_bytes());
        }
        decoded_image(&fixed);
    }
}

/// [`image`] on one byte string.
fn decoded_image(data: &[u8]) {
    let Ok(img) = decode(data) else {
        return;
    };
    let mut again = vec![0u8; data.len()];
    let len = encode(&img, &mut again).expect("a decoded image re-encodes");
    assert_eq!(
        &again[..len],
        data,
        "a decoded image re-encodes to its bytes"
    );
    let n = img.n();
    let mut states: Vec<Vec<f32>> = vec![vec![0.0; n], vec![f32::NAN; n], vec![0.0; n + 1]];
    for t in 0..img.n_trajectories().min(3) {
        states.push((0..n).map(|i| img.centre(t, i)).collect());
    }
    for b in 0..img.n_balls().min(3) {
        states.push((0..n).map(|i| img.ball_centre(b, i)).collect());
    }
    states.push(
        data.chunks_exact(4)
            .rev()
            .take(n)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
    );
    let mut ctl = Controller::new(img);
    for x in states.iter().cycle().take(3 * states.len()) {
        let _ = ctl.step(x);
    }
    ctl.reset();
    for x in &states {
        let _ = ctl.step(x);
    }
}

/// The spec parser and validator, and the spec fingerprint: any text gives a problem or a diagnostic.
/// Text that parses as a spec has a fingerprint.
pub fn spec(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let parsed = crate::spec::parse(text, "fuzz.toml");
    let fp = crate::spec::SpecFingerprint::of(text);
    if let Ok(p) = parsed {
        assert_eq!(
            Some(p.fingerprint),
            fp.ok(),
            "a valid spec has its fingerprint"
        );
    }
}

/// The CSV readers: `mtl`'s trace reader and the import of a recording (n = 2, m = 1, period 0.1, at
/// most 4096 rows): any text gives a trace or recording, or an error.
pub fn csv(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = crate::robustness::mtl::Trace::from_csv_str(text, "fuzz.csv");
    let _ = crate::trajectory::csv::parse_recording(text, "fuzz.csv", 2, 1, 0.1, 4096);
    let _ = crate::trajectory::csv::parse_inputs(text, "fuzz.csv", 1, 0.1, 4096);
}

/// The MTL formula parser, and a parsed formula evaluated on a small trace of signals `x1` and `x2`
/// (names it does not know are an error): any text gives a formula or an error, never a stack overflow.
pub fn mtl(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if crate::robustness::mtl::Formula::parse(text).is_err() {
        return;
    }
    let trace = crate::robustness::mtl::Trace::new(
        vec![0.0, 0.5, 1.0, 1.5, 2.0],
        vec!["x1".into(), "x2".into()],
        vec![
            vec![0.0, 0.5, 1.0, -1.0, 2.0],
            vec![1.0, 0.0, -0.5, 3.0, 0.25],
        ],
    )
    .expect("a valid trace");
    let _ = crate::robustness::mtl::robustness(text, &trace, &[]);
}

/// The UART frame reader and decoder: the bytes as a stream through [`Reader`]; every frame it delivers
/// is decoded as a request and as a reply, and a decoded message re-encodes to exactly the frame.
pub fn uart(data: &[u8]) {
    let mut reader = Reader::new();
    for &byte in data {
        let Some(FrameEvent::Frame(frame)) = reader.push(byte) else {
            continue;
        };
        let mut buf = [0u8; shared_types::protocol::MAX_FRAME];
        if let Ok(req) = decode_frame::<Request>(frame) {
            let enc = encode_frame(&req, &mut buf).expect("a decoded request re-encodes");
            assert_eq!(enc.split_last().map(|(_, b)| b), Some(frame));
        }
        if let Ok(rep) = decode_frame::<Reply>(frame) {
            let enc = encode_frame(&rep, &mut buf).expect("a decoded reply re-encodes");
            assert_eq!(enc.split_last().map(|(_, b)| b), Some(frame));
        }
    }
}
