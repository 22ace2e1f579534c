//! Image format: round trips (fixed and property-based), canonical re-encoding, and one test per
//! validation rule checking that the decoder names what is wrong.
#![allow(non_snake_case)]

mod common;

use common::{fix_header, random_content, Content, FallbackC};
use proptest::prelude::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{HEADER_LEN, MAX_IMAGE_LEN, MAX_N, MAX_STEPS, MAX_TRAJECTORIES};
use shared_types::image::{
    decode, encode, Dim, Field, Header, ImageError, Mode, Pos, Terminal, FORMAT_VERSION, MAGIC,
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
        .flat_map(|_| common::random_spd(&mut rng, n))
        .collect();
    c.traj_len = vec![MAX_STEPS / nt; nt];
    c.centre = vec![0.0; nt * n];
    c.delta = vec![1.0; nt];
    c.v = vec![1.0; MAX_STEPS * m];
    c.location = (0..MAX_STEPS).map(|i| (i % nl) as u8).collect();
    c.fallback = FallbackC::Linear {
        K: vec![1.0; m * n],
        x_ref: vec![0.0; n],
        u_ref: vec![0.0; m],
    };
    c.input_box = Some((vec![-1.0; m], vec![1.0; m]));
    let bytes = c.to_bytes().unwrap();
    assert!(
        bytes.len() <= MAX_IMAGE_LEN,
        "{} > {}",
        bytes.len(),
        MAX_IMAGE_LEN
    );
    assert_eq!(Content::from_image(&decode(&bytes).unwrap()), c);
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
    let mut b = bytes.clone();
    b[19] = 1;
    assert_eq!(decode(&b), Err(ImageError::ReservedNotZero));
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
    assert_eq!(decode(&longer), Err(ImageError::TrailingBytes));
    let mut shorter = b[..b.len() - 1].to_vec();
    fix_header(&mut shorter);
    assert_eq!(decode(&shorter), Err(ImageError::Malformed));
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
    // With the header dimensions made PWA-like, the feedforward payload does not parse as a PWA payload.
    let mut pwa = b.clone();
    pwa[6] = 2;
    pwa[14..16].copy_from_slice(&0u16.to_le_bytes());
    pwa[16..18].copy_from_slice(&1u16.to_le_bytes());
    set_crc(&mut pwa);
    assert!(
        matches!(
            decode(&pwa),
            Err(ImageError::Malformed | ImageError::TrailingBytes | ImageError::FieldLength { .. })
        ),
        "{:?}",
        decode(&pwa)
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
    // The first payload field is K's byte string: length prefix 8 (one byte, 0x08). Re-encode the prefix
    // as the overlong varint 0x88 0x00 and fix up the header: same content, non-canonical bytes.
    let b = simple().to_bytes().unwrap();
    assert_eq!(b[HEADER_LEN], 8);
    let mut x = b[..HEADER_LEN].to_vec();
    x.extend_from_slice(&[0x88, 0x00]);
    x.extend_from_slice(&b[HEADER_LEN + 1..]);
    fix_header(&mut x);
    assert_eq!(decode(&x), Err(ImageError::NotCanonical));
}
