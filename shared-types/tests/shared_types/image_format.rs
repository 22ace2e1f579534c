//! Image format: round trips (fixed and property-based), canonical re-encoding, and one test per
//! validation rule checking that the decoder names what is wrong.
#![allow(non_snake_case)]

use crate::common::{
    fix_header, random_content, sections_of, with_sections, Content, FallbackC, Sections,
};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{
    max_rows, HEADER_LEN, MAX_IMAGE_LEN, MAX_N, MAX_SECTIONS, MAX_SEGMENTS, MAX_STEPS,
    MAX_TABLE_VALUES, MAX_TRAJECTORIES,
};
use shared_types::image::{
    decode, directory, encode, Dim, Field, Header, ImageError, Mode, Pos, SectionKind, Segment,
    Terminal, FORMAT_VERSION, MAGIC,
};

fn simple() -> Content {
    Content {
        n: 2,
        m: 1,
        nl: 1,
        period: 0.01,
        K: vec![-1.0, -2.0],
        P: vec![2.0, 0.5, 0.5, 1.0],
        traj_len: vec![3, 2],
        centre: vec![0.0, 0.0, 1.0, 1.0],
        delta: vec![0.5, 0.25],
        v: vec![1.0, 2.0, 3.0, 4.0, 5.0],
        location: vec![0; 5],
        fallback: FallbackC::Linear {
            K: vec![-0.5, -0.5],
            x_ref: vec![0.0, 0.0],
            u_ref: vec![0.0],
        },
        input_box: Some((vec![-1.0], vec![1.0])),
        terminal: Terminal::HoldLast,
    }
}

fn set_crc(bytes: &mut [u8]) {
    let crc = shared_types::image::compute_crc(bytes).unwrap();
    bytes[28..32].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn round_trip_fixed_content() {
    let c = simple();
    let bytes = c.to_bytes().unwrap();
    assert_eq!(&bytes[0..4], &MAGIC);
    let img = decode(&bytes).unwrap();
    assert_eq!(img.mode(), Mode::Feedforward);
    assert_eq!(img.n(), 2);
    assert_eq!(img.m(), 1);
    assert_eq!(img.n_trajectories(), 2);
    assert_eq!(img.total_steps(), 5);
    assert_eq!(img.trajectory_rows(1), (3, 2));
    assert_eq!(img.v(1, 1, 0), 5.0);
    assert_eq!(img.P(0, 0, 1), 0.5);
    assert_eq!(img.input_bounds(0), Some((-1.0, 1.0)));
    assert_eq!(Content::from_image(&img), c);
    let h = Header::parse(&bytes).unwrap();
    assert_eq!(h.version, FORMAT_VERSION);
    assert_eq!(h.payload_len as usize, bytes.len() - HEADER_LEN);
    assert_eq!(h.period, 0.01);
    let mut again = vec![0u8; bytes.len()];
    assert_eq!(encode(&img, &mut again).unwrap(), bytes.len());
    assert_eq!(again, bytes);
    assert_eq!(img.encoded_len().unwrap(), bytes.len());
}

#[test]
fn round_trip_random_contents_at_capacity_scale() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..200 {
        let c = random_content(&mut rng, MAX_N, 6, 16, 32);
        let bytes = c.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        assert_eq!(Content::from_image(&img), c);
        let mut again = vec![0u8; bytes.len()];
        encode(&img, &mut again).unwrap();
        assert_eq!(again, bytes);
    }
}

#[test]
fn largest_image_fits_max_image_len() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut c = random_content(&mut rng, 1, 1, 1, 1);
    let (n, m, nl, nt) = (MAX_N, 6, 8, MAX_TRAJECTORIES);
    c.n = n;
    c.m = m;
    c.nl = nl;
    c.K = vec![0.5; nl * m * n];
    c.P = (0..nl)
        .flat_map(|_| crate::common::random_spd(&mut rng, n))
        .collect();
    // Every row the table holds at m = 6 (MAX_TABLE_VALUES / 6, rounded down), split over the trajectories.
    let rows = max_rows(m);
    assert!(rows * m <= MAX_TABLE_VALUES && (rows + 1) * m > MAX_TABLE_VALUES);
    c.traj_len = vec![rows / nt; nt];
    c.traj_len[nt - 1] += rows % nt;
    c.centre = vec![0.0; nt * n];
    c.delta = vec![1.0; nt];
    c.v = vec![1.0; rows * m];
    c.fallback = FallbackC::Linear {
        K: vec![1.0; m * n],
        x_ref: vec![0.0; n],
        u_ref: vec![0.0; m],
    };
    c.input_box = Some((vec![-1.0; m], vec![1.0; m]));
    // A location change every row is more segments than the capacity allows...
    c.location = (0..rows).map(|i| (i % nl) as u8).collect();
    assert!(matches!(
        c.to_bytes(),
        Err(ImageError::DimOutOfRange { dim: Dim::Segments, max, .. }) if max as usize == MAX_SEGMENTS
    ));
    // ... MAX_SEGMENTS / nt segments in every trajectory (a location change at each quarter) fills it
    // exactly.
    let per = MAX_SEGMENTS / nt;
    assert_eq!(per * nt, MAX_SEGMENTS);
    c.location = c
        .traj_len
        .iter()
        .flat_map(|&len| (0..len).map(move |i| ((i * per / len) % nl) as u8))
        .collect();
    let bytes = c.to_bytes().unwrap();
    assert_eq!(decode(&bytes).unwrap().n_segments(), MAX_SEGMENTS);
    assert!(
        bytes.len() <= MAX_IMAGE_LEN,
        "{} > {}",
        bytes.len(),
        MAX_IMAGE_LEN
    );
    assert_eq!(Content::from_image(&decode(&bytes).unwrap()), c);
    // One row more is more values than the table holds at m = 6.
    c.traj_len[nt - 1] += 1;
    c.v.extend([1.0; 6]);
    c.location.push(*c.location.last().unwrap());
    assert!(matches!(
        c.to_bytes(),
        Err(ImageError::DimOutOfRange { dim: Dim::Steps, value, max, .. })
            if value as usize == rows + 1 && max as usize == rows
    ));
}

#[test]
fn encode_reports_small_buffer() {
    let c = simple();
    let bytes = c.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    let mut small = vec![0u8; bytes.len() - 1];
    assert_eq!(
        encode(&img, &mut small),
        Err(ImageError::BufferTooSmall {
            needed: bytes.len() as u32
        })
    );
}

fn finite_f32() -> impl Strategy<Value = f32> {
    use proptest::num::f32 as pf;
    pf::POSITIVE | pf::NEGATIVE | pf::NORMAL | pf::SUBNORMAL | pf::ZERO
}

fn content_strategy() -> impl Strategy<Value = Content> {
    (
        1..=5usize,
        1..=3usize,
        1..=3usize,
        prop::collection::vec(1..=5usize, 1..=4),
        0..3u8,
        any::<bool>(),
        any::<bool>(),
    )
        .prop_flat_map(|(n, m, nl, traj_len, fb, has_box, hold)| {
            let nt = traj_len.len();
            let rows: usize = traj_len.iter().sum();
            (
                (Just((n, m, nl, traj_len, fb, has_box, hold)), 1e-4f32..10.0),
                prop::collection::vec(finite_f32(), nl * m * n),
                prop::collection::vec(-1.0f32..1.0, nl * n * n),
                prop::collection::vec(finite_f32(), nt * n),
                prop::collection::vec(0.0f32..1e30, nt),
                prop::collection::vec(finite_f32(), rows * m),
                prop::collection::vec(0..nl as u8, rows),
                prop::collection::vec(finite_f32(), m * n + n + m),
                prop::collection::vec(-100.0f32..100.0, 2 * m),
            )
        })
        .prop_map(
            |((dims, period), K, A, centre, delta, v, location, fbv, bx)| {
                let (n, m, nl, traj_len, fb, has_box, hold) = dims;
                // P = AᵀA + I per location, symmetric by construction.
                let mut P = vec![0.0f32; nl * n * n];
                for l in 0..nl {
                    let a = &A[l * n * n..(l + 1) * n * n];
                    for i in 0..n {
                        for j in i..n {
                            let mut s: f64 = (0..n)
                                .map(|k| a[k * n + i] as f64 * a[k * n + j] as f64)
                                .sum();
                            if i == j {
                                s += 1.0;
                            }
                            P[l * n * n + i * n + j] = s as f32;
                            P[l * n * n + j * n + i] = s as f32;
                        }
                    }
                }
                let fallback = match fb {
                    0 => FallbackC::Hold,
                    1 => FallbackC::Zero,
                    _ => FallbackC::Linear {
                        K: fbv[..m * n].to_vec(),
                        x_ref: fbv[m * n..m * n + n].to_vec(),
                        u_ref: fbv[m * n + n..].to_vec(),
                    },
                };
                let input_box = has_box.then(|| {
                    let lo: Vec<f32> = (0..m).map(|j| bx[j].min(bx[m + j])).collect();
                    let hi: Vec<f32> = (0..m).map(|j| bx[j].max(bx[m + j])).collect();
                    (lo, hi)
                });
                Content {
                    n,
                    m,
                    nl,
                    period,
                    K,
                    P,
                    traj_len,
                    centre,
                    delta,
                    v,
                    location,
                    fallback,
                    input_box,
                    terminal: if hold {
                        Terminal::HoldLast
                    } else {
                        Terminal::Fallback
                    },
                }
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, rng_seed: proptest::test_runner::RngSeed::Fixed(11), ..ProptestConfig::default() })]
    #[test]
    fn prop_round_trip(c in content_strategy()) {
        let bytes = c.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        prop_assert_eq!(Content::from_image(&img), c.clone());
        let mut again = vec![0u8; bytes.len()];
        prop_assert_eq!(encode(&img, &mut again).unwrap(), bytes.len());
        prop_assert_eq!(again, bytes);
    }
}

// ---- one test per rule -------------------------------------------------------------------------------

fn err_of(c: &Content) -> ImageError {
    c.to_bytes().expect_err("content should be rejected")
}

#[test]
fn rejects_short_input_and_bad_magic_version_reserved() {
    let bytes = simple().to_bytes().unwrap();
    assert_eq!(decode(&bytes[..10]), Err(ImageError::Truncated { len: 10 }));
    assert_eq!(decode(&[]), Err(ImageError::Truncated { len: 0 }));
    let mut b = bytes.clone();
    b[0] = b'X';
    assert!(matches!(decode(&b), Err(ImageError::BadMagic { found }) if found[0] == b'X'));
    // Every other version is refused, the previous one (before the whitened PWA ball test) included.
    for v in [FORMAT_VERSION - 1, FORMAT_VERSION + 1] {
        let mut b = bytes.clone();
        b[4..6].copy_from_slice(&v.to_le_bytes());
        assert_eq!(decode(&b), Err(ImageError::UnsupportedVersion { found: v }));
    }
    let mut b = bytes.clone();
    b[7] = 1;
    assert_eq!(decode(&b), Err(ImageError::ReservedNotZero));
    // Bytes 18..20 hold the section count (they were reserved before format version 4).
    let mut b = bytes.clone();
    b[19] = 1;
    set_crc(&mut b);
    assert_eq!(
        decode(&b),
        Err(ImageError::DimOutOfRange {
            dim: Dim::Sections,
            value: 261,
            min: 1,
            max: MAX_SECTIONS as u32
        })
    );
}

#[test]
fn rejects_crc_mismatch_and_names_both_values() {
    let mut b = simple().to_bytes().unwrap();
    let stored = u32::from_le_bytes(b[28..32].try_into().unwrap());
    let last = b.len() - 1;
    b[last] ^= 0x40;
    let computed = shared_types::image::compute_crc(&b).unwrap();
    assert_eq!(
        decode(&b),
        Err(ImageError::CrcMismatch { stored, computed })
    );
    let msg = decode(&b).unwrap_err().to_string();
    assert!(
        msg.contains(&format!("{stored:#010x}")) && msg.contains(&format!("{computed:#010x}")),
        "{msg}"
    );
    // The header is covered too: change the period only.
    let mut b = simple().to_bytes().unwrap();
    b[20] ^= 1;
    assert!(matches!(decode(&b), Err(ImageError::CrcMismatch { .. })));
}

#[test]
fn rejects_payload_length_mismatch_and_trailing_bytes() {
    let b = simple().to_bytes().unwrap();
    let mut longer = b.clone();
    longer.push(0);
    assert_eq!(
        decode(&longer),
        Err(ImageError::PayloadLength {
            header: (b.len() - 32) as u32,
            actual: (b.len() - 31) as u32
        })
    );
    fix_header(&mut longer);
    assert_eq!(
        decode(&longer),
        Err(ImageError::UnclaimedBytes {
            offset: b.len() as u32
        })
    );
    let mut shorter = b[..b.len() - 1].to_vec();
    fix_header(&mut shorter);
    assert_eq!(
        decode(&shorter),
        Err(ImageError::SectionOutOfRange { index: 4 })
    );
    // Inside a section: a byte more or less in the last section (the directory fixed up) is a trailing
    // byte or a malformed section.
    let mut secs = sections_of(&b);
    secs[4].1.push(0);
    assert_eq!(
        decode(&with_sections(&b, &secs)),
        Err(ImageError::TrailingBytes {
            section: SectionKind::Steps
        })
    );
    let mut secs = sections_of(&b);
    secs[4].1.pop();
    assert_eq!(
        decode(&with_sections(&b, &secs)),
        Err(ImageError::Malformed {
            section: SectionKind::Steps
        })
    );
}

#[test]
fn rejects_unknown_modes_and_feedforward_content_under_the_pwa_mode() {
    let b = simple().to_bytes().unwrap();
    // Mode 2 is PWA feedback: a feedforward header (trajectories, no partitions) does not fit it.
    let mut pwa = b.clone();
    pwa[6] = 2;
    set_crc(&mut pwa);
    assert_eq!(
        decode(&pwa),
        Err(ImageError::DimOutOfRange {
            dim: Dim::Trajectories,
            value: 2,
            min: 0,
            max: 0
        })
    );
    // With the header dimensions made PWA-like, the feedforward sections do not belong in a PWA image.
    let mut pwa = b.clone();
    pwa[6] = 2;
    pwa[14..16].copy_from_slice(&0u16.to_le_bytes());
    pwa[16..18].copy_from_slice(&1u16.to_le_bytes());
    set_crc(&mut pwa);
    assert_eq!(
        decode(&pwa),
        Err(ImageError::UnexpectedSection {
            kind: SectionKind::Trajectories,
            mode: Mode::PwaFeedback
        })
    );
    // Image::new builds feedforward images only.
    let c = simple();
    let owned = c.owned();
    assert_eq!(
        shared_types::image::Image::new(Mode::PwaFeedback, c.dims(), c.period, owned.payload()),
        Err(ImageError::UnsupportedMode {
            mode: Mode::PwaFeedback
        })
    );
    for bad in [0u8, 3, 255] {
        let mut x = b.clone();
        x[6] = bad;
        set_crc(&mut x);
        assert_eq!(decode(&x), Err(ImageError::UnknownMode { found: bad }));
    }
}

#[test]
fn rejects_dimensions_outside_capacity() {
    let b = simple().to_bytes().unwrap();
    let cases = [
        (8usize, 13u16, Dim::N),
        (8, 0, Dim::N),
        (10, 7, Dim::M),
        (12, 9, Dim::Locations),
        (14, 0, Dim::Trajectories),
        (16, 1, Dim::Partitions),
    ];
    for (off, val, dim) in cases {
        let mut x = b.clone();
        x[off..off + 2].copy_from_slice(&val.to_le_bytes());
        set_crc(&mut x);
        assert!(
            matches!(decode(&x), Err(ImageError::DimOutOfRange { dim: d, value, .. }) if d == dim && value == val as u32),
            "{off}: {:?}",
            decode(&x)
        );
    }
    // A header dimension that disagrees with the payload shows up as a field length error.
    let mut x = b.clone();
    x[8..10].copy_from_slice(&3u16.to_le_bytes());
    set_crc(&mut x);
    assert_eq!(
        decode(&x),
        Err(ImageError::FieldLength {
            field: Field::K,
            expected: 12,
            found: 8
        })
    );
}

#[test]
fn rejects_bad_period() {
    for p in [0.0f32, -0.01, f32::NAN, f32::INFINITY] {
        let mut c = simple();
        c.period = p;
        assert_eq!(err_of(&c), ImageError::BadPeriod);
    }
}

#[test]
fn rejects_non_finite_values_with_position() {
    let mut c = simple();
    c.v[4] = f32::NAN; // trajectory 1, step 1
    let e = err_of(&c);
    assert_eq!(
        e,
        ImageError::NonFinite {
            field: Field::V,
            pos: Pos(1, 1, 0)
        }
    );
    assert_eq!(e.to_string(), "trajectory 1 step 1: v[0] is not finite");
    let mut c = simple();
    c.K[1] = f32::INFINITY;
    assert_eq!(
        err_of(&c),
        ImageError::NonFinite {
            field: Field::K,
            pos: Pos(0, 0, 1)
        }
    );
    let mut c = simple();
    c.centre[3] = f32::NEG_INFINITY;
    assert_eq!(
        err_of(&c),
        ImageError::NonFinite {
            field: Field::Centre,
            pos: Pos(1, 1, 0)
        }
    );
    let mut c = simple();
    c.delta[0] = f32::INFINITY;
    assert_eq!(
        err_of(&c),
        ImageError::NonFinite {
            field: Field::Delta,
            pos: Pos(0, 0, 0)
        }
    );
    let mut c = simple();
    c.fallback = FallbackC::Linear {
        K: vec![0.0, f32::NAN],
        x_ref: vec![0.0; 2],
        u_ref: vec![0.0],
    };
    assert_eq!(
        err_of(&c),
        ImageError::NonFinite {
            field: Field::FallbackK,
            pos: Pos(0, 1, 0)
        }
    );
    let mut c = simple();
    c.input_box = Some((vec![f32::NAN], vec![1.0]));
    assert_eq!(
        err_of(&c),
        ImageError::NonFinite {
            field: Field::BoxLo,
            pos: Pos(0, 0, 0)
        }
    );
}

#[test]
fn rejects_bad_P() {
    let mut c = simple();
    c.P = vec![2.0, 0.5, 0.4, 1.0];
    assert_eq!(
        err_of(&c),
        ImageError::NotSymmetric {
            location: 0,
            row: 0,
            col: 1
        }
    );
    let mut c = simple();
    c.P = vec![1.0, 2.0, 2.0, 1.0]; // eigenvalues 3 and -1
    assert_eq!(err_of(&c), ImageError::NotPositiveDefinite { location: 0 });
    let mut c = simple();
    c.P = vec![1.0, 1.0, 1.0, 1.0]; // singular
    assert_eq!(err_of(&c), ImageError::NotPositiveDefinite { location: 0 });
}

#[test]
fn rejects_bad_trajectory_structure() {
    let mut c = simple();
    c.delta[1] = -0.1;
    assert_eq!(err_of(&c), ImageError::NegativeDelta { trajectory: 1 });
    let mut c = simple();
    c.location[3] = 1; // only one location
    assert_eq!(
        err_of(&c),
        ImageError::LocationOutOfRange {
            trajectory: 1,
            step: 0,
            value: 1
        }
    );
    // An empty trajectory: ends 3, 3.
    let mut c = simple();
    c.traj_len = vec![3, 0, 2];
    c.centre.extend_from_slice(&[0.0, 0.0]);
    c.delta.push(0.1);
    assert_eq!(err_of(&c), ImageError::TrajectoryEnds { trajectory: 1 });
    let mut c = simple();
    c.input_box = Some((vec![1.0], vec![-1.0]));
    assert_eq!(err_of(&c), ImageError::EmptyInputBox { input: 0 });
    let mut c = simple();
    c.v.pop();
    assert_eq!(
        err_of(&c),
        ImageError::FieldLength {
            field: Field::V,
            expected: 20,
            found: 16
        }
    );
}

#[test]
fn rejects_too_many_rows() {
    // At m = 1 the table holds MAX_TABLE_VALUES rows (at m = 6, a sixth: `largest_image_fits_max_image_len`).
    assert_eq!(MAX_STEPS, max_rows(1));
    let mut c = simple();
    c.traj_len = vec![MAX_STEPS, 1];
    c.v = vec![0.0; MAX_STEPS + 1];
    c.location = vec![0; MAX_STEPS + 1];
    assert!(
        matches!(err_of(&c), ImageError::DimOutOfRange { dim: Dim::Steps, value, .. } if value as usize == MAX_STEPS + 1)
    );
}

#[test]
fn rejects_overlong_varint_as_not_canonical() {
    // The first field of the locations section is K's byte string: length prefix 8 (one byte, 0x08).
    // Re-encode the prefix as the overlong varint 0x88 0x00 and lay the sections out again: same content,
    // non-canonical bytes.
    let b = simple().to_bytes().unwrap();
    let mut secs = sections_of(&b);
    assert_eq!(secs[0].0, SectionKind::Locations as u16);
    assert_eq!(secs[0].1[0], 8);
    secs[0].1.splice(0..1, [0x88, 0x00]);
    let x = with_sections(&b, &secs);
    assert_eq!(
        decode(&x),
        Err(ImageError::NotCanonical {
            section: SectionKind::Locations
        })
    );
    // The untouched layout decodes.
    assert_eq!(with_sections(&b, &sections_of(&b)), b);
}

#[test]
fn directory_lists_the_feedforward_sections_back_to_back() {
    let b = simple().to_bytes().unwrap();
    let h = Header::parse(&b).unwrap();
    assert_eq!(h.n_sections, 5);
    let dir = directory(&b).unwrap();
    let mut next = HEADER_LEN + 12 * dir.len();
    let kinds: Vec<u16> = (0..dir.len())
        .map(|i| {
            let e = dir.entry(i).unwrap();
            assert_eq!((e.offset as usize, e.flags), (next, 0));
            next += e.len as usize;
            e.kind
        })
        .collect();
    assert_eq!(next, b.len());
    assert_eq!(
        kinds,
        Mode::Feedforward
            .required_sections()
            .iter()
            .map(|&k| k as u16)
            .collect::<Vec<_>>()
    );
    assert!(dir.entry(5).is_none());
}

#[test]
fn rejects_bad_directories() {
    let b = simple().to_bytes().unwrap();
    let secs = sections_of(&b);
    let with = |f: &dyn Fn(&mut Sections)| {
        let mut s = secs.clone();
        f(&mut s);
        decode(&with_sections(&b, &s)).map(|_| ())
    };
    // A well-formed section of a kind this build does not know: refused, not skipped.
    assert_eq!(
        with(&|s| s.push((200, vec![1, 2, 3]))),
        Err(ImageError::UnknownSection { kind: 200 })
    );
    assert_eq!(
        with(&|s| s.insert(0, (0, vec![]))),
        Err(ImageError::UnknownSection { kind: 0 })
    );
    // Twice the same kind, kinds out of order, a missing kind, a kind of the other mode.
    assert_eq!(
        with(&|s| {
            let d = s[1].clone();
            s.insert(1, d)
        }),
        Err(ImageError::DuplicateSection {
            kind: SectionKind::Fallback
        })
    );
    assert_eq!(
        with(&|s| s.swap(0, 1)),
        Err(ImageError::SectionOrder { index: 1, kind: 1 })
    );
    assert_eq!(
        with(&|s| {
            s.remove(3);
        }),
        Err(ImageError::MissingSection {
            kind: SectionKind::Segments
        })
    );
    assert_eq!(
        with(&|s| s.push((SectionKind::PwaBalls as u16, vec![]))),
        Err(ImageError::UnexpectedSection {
            kind: SectionKind::PwaBalls,
            mode: Mode::Feedforward
        })
    );
    assert_eq!(
        with(&|s| s.clear()),
        Err(ImageError::DimOutOfRange {
            dim: Dim::Sections,
            value: 0,
            min: 1,
            max: MAX_SECTIONS as u32
        })
    );

    // Entries patched in place (CRC fixed): flags, a gap, an overlap, a section past the end, a directory
    // longer than the image.
    let entry = |i: usize| HEADER_LEN + 12 * i;
    let patch = |at: usize, v: &[u8]| {
        let mut x = b.clone();
        x[at..at + v.len()].copy_from_slice(v);
        fix_header(&mut x);
        decode(&x).map(|_| ())
    };
    assert_eq!(
        patch(entry(2) + 2, &1u16.to_le_bytes()),
        Err(ImageError::SectionFlags { index: 2 })
    );
    let off1 = u32::from_le_bytes(b[entry(1) + 4..entry(1) + 8].try_into().unwrap());
    assert_eq!(
        patch(entry(1) + 4, &(off1 + 1).to_le_bytes()),
        Err(ImageError::SectionPlacement {
            index: 1,
            expected: off1,
            found: off1 + 1
        })
    );
    assert_eq!(
        patch(entry(1) + 4, &(off1 - 1).to_le_bytes()),
        Err(ImageError::SectionPlacement {
            index: 1,
            expected: off1,
            found: off1 - 1
        })
    );
    assert_eq!(
        patch(entry(4) + 8, &u32::MAX.to_le_bytes()),
        Err(ImageError::SectionOutOfRange { index: 4 })
    );
    let mut short = b[..HEADER_LEN + 24].to_vec();
    fix_header(&mut short);
    assert_eq!(
        decode(&short),
        Err(ImageError::DirectoryTruncated { sections: 5 })
    );
    // Every error names its section in words.
    let msg = with(&|s| s.push((200, vec![]))).unwrap_err().to_string();
    assert!(msg.contains("unknown section kind 200"), "{msg}");
}

/// A hybrid trajectory (locations 0, 1, 0) is three segments; the accessors read rows, locations and
/// segments consistently, and the evaluator-facing row ranges are unchanged.
#[test]
fn segments_follow_the_locations_of_each_trajectory() {
    let mut c = simple();
    c.nl = 2;
    c.K.extend_from_slice(&[7.0, 8.0]);
    let P0 = c.P.clone();
    c.P.extend_from_slice(&P0);
    c.traj_len = vec![4, 1];
    c.location = vec![0, 1, 1, 0, 1];
    let b = c.to_bytes().unwrap();
    let img = decode(&b).unwrap();
    assert_eq!(img.n_segments(), 4);
    assert_eq!(img.trajectory_segments(0), (0, 3));
    assert_eq!(img.trajectory_segments(1), (3, 1));
    assert_eq!(
        img.segment(1),
        Some(Segment {
            location: 1,
            first_row: 1,
            len: 2
        })
    );
    assert_eq!(img.segment(4), None);
    assert_eq!(img.trajectory_rows(1), (4, 1));
    assert_eq!(
        (0..4).map(|s| img.location(0, s)).collect::<Vec<_>>(),
        vec![0, 1, 1, 0]
    );
    assert_eq!(img.segment_of(0, 3), Some(2));
    assert_eq!(img.segment_of(0, 4), None);
    assert_eq!(Content::from_image(&img), c);
}

#[test]
fn rejects_segments_inconsistent_with_the_table() {
    let c = simple(); // trajectories of 3 and 2 rows, one segment each
    let b = c.to_bytes().unwrap();
    let secs = sections_of(&b);
    assert_eq!(secs[3].0, SectionKind::Segments as u16);
    // The segments section: postcard length prefix 18, then two 9-byte records.
    assert_eq!(secs[3].1[0], 18);
    let with_record = |s: usize, first: u32, len: u32, loc: u8| {
        let mut secs = secs.clone();
        let o = 1 + 9 * s;
        secs[3].1[o..o + 4].copy_from_slice(&first.to_le_bytes());
        secs[3].1[o + 4..o + 8].copy_from_slice(&len.to_le_bytes());
        secs[3].1[o + 8] = loc;
        decode(&with_sections(&b, &secs)).map(|_| ())
    };
    assert!(with_record(1, 3, 2, 0).is_ok());
    // A gap or overlap between segments, an empty segment.
    assert_eq!(
        with_record(1, 4, 1, 0),
        Err(ImageError::SegmentRows { segment: 1 })
    );
    assert_eq!(
        with_record(1, 2, 3, 0),
        Err(ImageError::SegmentRows { segment: 1 })
    );
    assert_eq!(
        with_record(1, 3, 0, 0),
        Err(ImageError::SegmentRows { segment: 1 })
    );
    // Segments covering more or fewer rows than the table holds.
    assert_eq!(
        with_record(1, 3, 3, 0),
        Err(ImageError::FieldLength {
            field: Field::V,
            expected: 24,
            found: 20
        })
    );
    assert_eq!(
        with_record(1, 3, 1, 0),
        Err(ImageError::FieldLength {
            field: Field::V,
            expected: 16,
            found: 20
        })
    );
    assert_eq!(
        with_record(1, 3, u32::MAX, 0),
        Err(ImageError::DimOutOfRange {
            dim: Dim::Steps,
            value: u32::MAX,
            min: 1,
            max: MAX_STEPS as u32
        })
    );
    assert_eq!(
        with_record(1, 3, 2, 1),
        Err(ImageError::LocationOutOfRange {
            trajectory: 1,
            step: 0,
            value: 1
        })
    );

    // A trajectory split into two segments of the same location is not canonical; more segments than the
    // trajectories name is a length error.
    let mut two = c.clone();
    two.nl = 2;
    two.K.extend_from_slice(&[7.0, 8.0]);
    let P0 = two.P.clone();
    two.P.extend_from_slice(&P0);
    two.location = vec![0, 1, 0, 0, 0];
    let o = two.owned();
    let mut split = o.segment.clone();
    split[9 + 8] = 0; // segment 1 (row 1) now in location 0, like segment 0
    let p = shared_types::image::Payload {
        segment: &split,
        ..o.payload()
    };
    assert_eq!(
        shared_types::image::Image::new(Mode::Feedforward, two.dims(), two.period, p),
        Err(ImageError::SegmentNotMaximal { segment: 1 })
    );
    let mut extra = o.segment.clone();
    extra.extend_from_slice(&[0; 9]);
    let p = shared_types::image::Payload {
        segment: &extra,
        ..o.payload()
    };
    assert_eq!(
        shared_types::image::Image::new(Mode::Feedforward, two.dims(), two.period, p),
        Err(ImageError::FieldLength {
            field: Field::Segment,
            expected: 36,
            found: 45
        })
    );
}

/// A constant fallback input (issue 18: the input set may exclude 0) round-trips, is validated finite, of
/// length m and inside the stored input box, and the evaluator applies it whatever the state.
#[test]
fn constant_fallback_round_trips_is_validated_and_applied() {
    let mut c = simple();
    c.fallback = FallbackC::Constant(vec![0.75]);
    let bytes = c.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert_eq!(Content::from_image(&img), c);
    let ctl = shared_types::eval::Controller::new(img);
    let last = shared_types::eval::Input::zero(1);
    for x in [[9.0f32, 9.0], [f32::NAN, 0.0]] {
        assert_eq!(ctl.fallback(&x, &last).as_slice(), &[0.75]);
    }
    // Outside the box, not finite: refused.
    c.fallback = FallbackC::Constant(vec![1.5]);
    assert_eq!(err_of(&c), ImageError::FallbackOutsideBox { input: 0 });
    c.fallback = FallbackC::Constant(vec![f32::INFINITY]);
    assert!(
        matches!(err_of(&c), ImageError::NonFinite { .. }),
        "{:?}",
        err_of(&c)
    );
    // Without a box any finite constant is stored.
    c.input_box = None;
    c.fallback = FallbackC::Constant(vec![1.5]);
    assert!(c.to_bytes().is_ok());
}
