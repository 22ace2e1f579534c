//! 115 000 random and mutated byte strings through the decoder: each gives an error or a valid image,
//! never a panic. The valid seeds are feedforward and PWA-feedback images in equal numbers. Mutations of
//! valid images get their payload length and CRC recomputed most of the time, so validation past the CRC is
//! exercised; images that still decode are run through the evaluator and must re-encode to exactly the same
//! bytes (the format is canonical).

use std::collections::BTreeMap;

use crate::common::{fix_header, random_content, random_pwa, sections_of, with_sections, PwaShape};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::HEADER_LEN;
use shared_types::eval::{Controller, Input, Status};
use shared_types::image::{decode, encode, ImageError, Mode, FORMAT_VERSION, MAGIC};
use shared_types::pwa::Region;

/// Name of an error variant, to count which checks the fuzzing reached.
fn kind(e: &ImageError) -> &'static str {
    use ImageError::*;
    match e {
        Truncated { .. } => "Truncated",
        BadMagic { .. } => "BadMagic",
        UnsupportedVersion { .. } => "UnsupportedVersion",
        ReservedNotZero => "ReservedNotZero",
        UnknownMode { .. } => "UnknownMode",
        UnsupportedMode { .. } => "UnsupportedMode",
        PayloadLength { .. } => "PayloadLength",
        CrcMismatch { .. } => "CrcMismatch",
        DimOutOfRange { .. } => "DimOutOfRange",
        BadPeriod => "BadPeriod",
        Malformed { .. } => "Malformed",
        TrailingBytes { .. } => "TrailingBytes",
        NotCanonical { .. } => "NotCanonical",
        DirectoryTruncated { .. } => "DirectoryTruncated",
        SectionFlags { .. } => "SectionFlags",
        SectionPlacement { .. } => "SectionPlacement",
        SectionOutOfRange { .. } => "SectionOutOfRange",
        UnclaimedBytes { .. } => "UnclaimedBytes",
        SectionOrder { .. } => "SectionOrder",
        DuplicateSection { .. } => "DuplicateSection",
        UnknownSection { .. } => "UnknownSection",
        UnexpectedSection { .. } => "UnexpectedSection",
        MissingSection { .. } => "MissingSection",
        SegmentRows { .. } => "SegmentRows",
        SegmentNotMaximal { .. } => "SegmentNotMaximal",
        FieldLength { .. } => "FieldLength",
        NonFinite { .. } => "NonFinite",
        NotSymmetric { .. } => "NotSymmetric",
        NotPositiveDefinite { .. } => "NotPositiveDefinite",
        TrajectoryEnds { .. } => "TrajectoryEnds",
        NegativeDelta { .. } => "NegativeDelta",
        LocationOutOfRange { .. } => "LocationOutOfRange",
        EmptyInputBox { .. } => "EmptyInputBox",
        ChildOutOfRange { .. } => "ChildOutOfRange",
        BackEdge { .. } => "BackEdge",
        LeafOutOfRange { .. } => "LeafOutOfRange",
        UnreachableNode { .. } => "UnreachableNode",
        UnreferencedLeaf { .. } => "UnreferencedLeaf",
        TreeTooDeep { .. } => "TreeTooDeep",
        TreeDepthMismatch { .. } => "TreeDepthMismatch",
        DegenerateHyperplane { .. } => "DegenerateHyperplane",
        PartitionOutOfRange { .. } => "PartitionOutOfRange",
        LeafBallEnds { .. } => "LeafBallEnds",
        LeafTooManyBalls { .. } => "LeafTooManyBalls",
        BallRefOutOfRange { .. } => "BallRefOutOfRange",
        BallLocationOutOfRange { .. } => "BallLocationOutOfRange",
        BallPartitionOutOfRange { .. } => "BallPartitionOutOfRange",
        NegativeBallThreshold { .. } => "NegativeBallThreshold",
        FactorNotUpperTriangular { .. } => "FactorNotUpperTriangular",
        FactorDiagonal { .. } => "FactorDiagonal",
        BufferTooSmall { .. } => "BufferTooSmall",
        Encode => "Encode",
        _ => "Other",
    }
}

/// Decodes; on success checks canonical re-encoding and drives the evaluator with random states.
fn exercise(bytes: &[u8], rng: &mut ChaCha8Rng, stats: &mut BTreeMap<&'static str, usize>) {
    // The decoder of a firmware without the model-maps step agrees, except that it refuses maps.
    let without = shared_types::image::decode_without_model_maps(bytes);
    match decode(bytes) {
        Ok(img) if img.model_maps().is_some() => {
            assert_eq!(without, Err(ImageError::ModelMapsNotSupported))
        }
        Ok(img) => assert_eq!(without, Ok(img)),
        Err(e) => assert!(without.is_err(), "{e}"),
    }
    // The decoder of a firmware without the PWA step agrees, except that it refuses PWA images.
    let without_pwa = shared_types::image::decode_for::<true, true, false>(bytes);
    match decode(bytes) {
        Ok(img) if img.mode() == Mode::PwaFeedback => {
            assert_eq!(without_pwa, Err(ImageError::PwaNotSupported))
        }
        Ok(img) => assert_eq!(without_pwa, Ok(img)),
        Err(e) => assert!(without_pwa.is_err(), "{e}"),
    }
    match decode(bytes) {
        Err(e) => {
            // Display must work for every error.
            assert!(!e.to_string().is_empty());
            *stats.entry(kind(&e)).or_default() += 1;
        }
        Ok(img) => {
            *stats.entry("Ok").or_default() += 1;
            if img.mode() == Mode::PwaFeedback {
                *stats.entry("OkPwa").or_default() += 1;
            }
            let mut again = vec![0u8; bytes.len()];
            assert_eq!(encode(&img, &mut again), Ok(bytes.len()));
            assert_eq!(
                again, bytes,
                "decoded image does not re-encode to the same bytes"
            );
            let mut ctl = Controller::new(img);
            // A feedforward image steps the same with the PWA step left out (`step_for::<false>`).
            let mut ff_only = (img.mode() == Mode::Feedforward).then(|| Controller::new(img));
            let n = img.n();
            for k in 0..8 {
                let len = if k == 3 { n + 1 } else { n };
                let x: Vec<f32> = (0..len).map(|_| rng.random_range(-3.0f32..3.0)).collect();
                let located = ctl.locate(&x);
                let answer = ctl.step(&x);
                if let Some(c) = ff_only.as_mut() {
                    assert_eq!(c.step_for::<false>(&x), answer);
                }
                match answer {
                    Ok(u) => {
                        assert_eq!(u.len(), img.m());
                        assert!(u.as_slice().iter().all(|v| v.is_finite()));
                        if img.mode() == Mode::PwaFeedback {
                            assert!(matches!(located, Some(Region::Inside { .. })));
                        }
                    }
                    Err(s) => assert!(matches!(s, Status::OutOfEnvelope | Status::BadFrame)),
                }
                let fb = ctl.fallback(&x, &Input::from_slice(&[1.0; 6][..img.m()]).unwrap());
                assert!(fb.as_slice().iter().all(|v| v.is_finite()));
            }
        }
    }
}

#[test]
fn decoder_never_panics_on_115k_random_and_mutated_inputs() {
    let mut rng = ChaCha8Rng::seed_from_u64(0xDEC0DE);
    let mut stats: BTreeMap<&'static str, usize> = BTreeMap::new();
    let shape = PwaShape {
        max_nodes: 12,
        max_leaf_balls: 3,
        ..PwaShape::default()
    };
    let valid: Vec<Vec<u8>> = (0..128)
        .map(|i| {
            if i % 2 == 0 {
                random_content(&mut rng, 6, 3, 6, 8).to_bytes().unwrap()
            } else {
                random_pwa(&mut rng, shape).to_bytes().unwrap()
            }
        })
        .collect();
    let mut total = 0usize;

    // 1. 15 000 uniformly random strings; half start with a plausible header prefix.
    for i in 0..15_000 {
        let len = rng.random_range(0..200);
        let mut b: Vec<u8> = (0..len).map(|_| rng.random()).collect();
        if i % 2 == 0 && b.len() >= 8 {
            b[..4].copy_from_slice(&MAGIC);
            b[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
            b[6] = 1 + (i % 3 == 0) as u8;
            b[7] = 0;
            if i % 4 == 0 {
                fix_header(&mut b);
            }
        }
        exercise(&b, &mut rng, &mut stats);
        total += 1;
    }

    // 2. 15 000 valid headers (dimensions from a valid image) over random payloads with correct length and
    //    CRC: exercises postcard parsing and field checks.
    for _ in 0..15_000 {
        let base = &valid[rng.random_range(0..valid.len())];
        let plen = rng.random_range(0..300);
        let mut b = base[..HEADER_LEN].to_vec();
        b.extend((0..plen).map(|_| rng.random::<u8>()));
        fix_header(&mut b);
        exercise(&b, &mut rng, &mut stats);
        total += 1;
    }

    // 3. 50 000 byte mutations of valid images (flips, random bytes, small integer nudges), with length and
    //    CRC fixed up in 90% of cases.
    for _ in 0..50_000 {
        let mut b = valid[rng.random_range(0..valid.len())].clone();
        let muts = rng.random_range(1..=4);
        for _ in 0..muts {
            let at = rng.random_range(0..b.len());
            match rng.random_range(0..4) {
                0 => b[at] ^= 1 << rng.random_range(0..8),
                1 => b[at] = rng.random(),
                2 => b[at] = b[at].wrapping_add(1),
                _ => b[at] = b[at].wrapping_sub(1),
            }
        }
        if rng.random_bool(0.9) {
            fix_header(&mut b);
        }
        exercise(&b, &mut rng, &mut stats);
        total += 1;
    }

    // 4. 20 000 truncations, extensions, and spliced byte ranges, header fixed up in 75% of cases.
    for _ in 0..20_000 {
        let mut b = valid[rng.random_range(0..valid.len())].clone();
        match rng.random_range(0..3) {
            0 => b.truncate(rng.random_range(0..b.len())),
            1 => {
                let extra = rng.random_range(1..64);
                b.extend((0..extra).map(|_| rng.random::<u8>()));
            }
            _ => {
                // Delete or duplicate a range inside the payload.
                let a = rng.random_range(HEADER_LEN..b.len());
                let e = rng.random_range(a..=b.len().min(a + 40));
                if rng.random_bool(0.5) {
                    b.drain(a..e);
                } else {
                    let dup: Vec<u8> = b[a..e].to_vec();
                    b.splice(a..a, dup);
                }
            }
        }
        if rng.random_bool(0.75) {
            fix_header(&mut b);
        }
        exercise(&b, &mut rng, &mut stats);
        total += 1;
    }

    // 5. 15 000 edits of the section directory and of section lengths, laid out again validly, so that
    //    the directory checks and the postcard parsing inside sections are both reached: a kind changed,
    //    sections dropped, duplicated or swapped, an unknown kind added, or bytes deleted, inserted or
    //    changed inside one section (its length and every later offset follow).
    for _ in 0..15_000 {
        let base = &valid[rng.random_range(0..valid.len())];
        let mut secs = sections_of(base);
        let i = rng.random_range(0..secs.len());
        match rng.random_range(0..6) {
            0 => secs[i].0 = rng.random_range(0..12),
            1 => {
                secs.remove(i);
            }
            2 => {
                let j = rng.random_range(0..secs.len());
                secs.swap(i, j);
            }
            3 => {
                let d = secs[i].clone();
                secs.insert(i, d);
            }
            4 => secs.push((rng.random_range(9..=u16::MAX), vec![rng.random(); 3])),
            _ => {
                let body = &mut secs[i].1;
                let a = rng.random_range(0..=body.len());
                let e = rng.random_range(a..=body.len().min(a + 12));
                match rng.random_range(0..3) {
                    0 => {
                        body.drain(a..e);
                    }
                    1 => {
                        let ins: Vec<u8> =
                            (0..rng.random_range(1..6)).map(|_| rng.random()).collect();
                        body.splice(a..a, ins);
                    }
                    _ => {
                        for x in &mut body[a..e] {
                            *x = rng.random();
                        }
                    }
                }
            }
        }
        exercise(&with_sections(base, &secs), &mut rng, &mut stats);
        total += 1;
    }

    assert_eq!(total, 115_000);
    eprintln!("{stats:#?}");
    // The fuzzing must reach the checks past the CRC, not just bounce off the header.
    for k in [
        "BadMagic",
        "CrcMismatch",
        "PayloadLength",
        "Malformed",
        "TrailingBytes",
        "FieldLength",
        "NonFinite",
        "DimOutOfRange",
        "UnknownMode",
        "NotSymmetric",
        "TrajectoryEnds",
        "LocationOutOfRange",
        "Ok",
        "OkPwa",
        "ChildOutOfRange",
        "BackEdge",
        "LeafOutOfRange",
        "PartitionOutOfRange",
        "LeafBallEnds",
        "BallRefOutOfRange",
        "BallPartitionOutOfRange",
        "BallLocationOutOfRange",
        "LeafTooManyBalls",
        "UnreachableNode",
        "UnreferencedLeaf",
        "TreeDepthMismatch",
        "NotCanonical",
        "DirectoryTruncated",
        "SectionPlacement",
        "SectionOutOfRange",
        "UnclaimedBytes",
        "SectionOrder",
        "DuplicateSection",
        "UnknownSection",
        "UnexpectedSection",
        "MissingSection",
        "SegmentRows",
    ] {
        assert!(
            stats.get(k).copied().unwrap_or(0) > 0,
            "fuzzing never produced {k}: {stats:?}"
        );
    }
}
