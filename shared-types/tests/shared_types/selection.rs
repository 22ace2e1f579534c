//! The selection test section (tag 13, `shared_types::selection`): an image with model maps and the
//! section round-trips byte for byte; the model-maps step selects exactly as the documented f32
//! operations do (a reference written here, over random metrics, centres, thresholds and states, for the
//! unrolled one-location n = 8 path and the general loop, which agree); every rule of the section is
//! refused with its own error, the section without model maps included.
#![allow(non_snake_case)]

use crate::common::{
    factor_of, random_spd, sections_of, whiten_centre, with_sections, Content, FallbackC,
};
use crate::program::assemble;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::MAX_IMAGE_LEN;
use shared_types::error::{Field, Pos};
use shared_types::eval::Controller;
use shared_types::image::{decode, encode, Image, ImageError, Mode, SectionKind, Terminal};
use shared_types::maps::{body_len, write_body};
use shared_types::program::Op;
use shared_types::selection;

/// Model maps of identity coordinates: n plant states, ξ = x, u = w (m inputs).
fn identity_maps(n: usize, m: usize) -> Vec<u8> {
    let coords: Vec<Op> = (0..n)
        .flat_map(|i| [Op::Load(i as u8), Op::Store(i as u8)])
        .collect();
    let input: Vec<Op> = (0..m)
        .flat_map(|j| [Op::Load((n + j) as u8), Op::Store(j as u8)])
        .collect();
    let c = assemble(n, n, &[], &coords, 1);
    let i = assemble(n + m, m, &[], &input, 1);
    let mut b = vec![0u8; body_len(0, c.len(), i.len())];
    assert_eq!(write_body(&mut b, n, m, &[], &c, &i), Ok(b.len()));
    b
}

/// A feedforward content of dimension n (m = 1) with `nt` one-step trajectories whose first steps run
/// in location `loc(t)` of `nl` (all with the metric P).
fn content(rng: &mut ChaCha8Rng, n: usize, nl: usize, nt: usize, P: &[f32]) -> Content {
    Content {
        n,
        m: 1,
        nl,
        period: 0.1,
        K: vec![0.0; nl * n],
        P: (0..nl).flat_map(|_| P.iter().copied()).collect(),
        traj_len: vec![1; nt],
        centre: (0..nt * n)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect(),
        delta: vec![1.0; nt],
        v: vec![0.0; nt],
        location: (0..nt).map(|t| (t % nl) as u8).collect(),
        fallback: FallbackC::Zero,
        input_box: None,
        terminal: Terminal::Fallback,
    }
}

/// The section body: the factor R̂ of P for each location, then per trajectory `[fl32(R̂c), ŝ]`.
fn section(c: &Content, R: &[f32], thresholds: &[f32]) -> Vec<u8> {
    let n = c.n;
    let mut v: Vec<f32> = (0..c.nl).flat_map(|_| R.iter().copied()).collect();
    for (t, &s) in thresholds.iter().enumerate() {
        v.extend(whiten_centre(R, &c.centre[t * n..(t + 1) * n]));
        v.push(s);
    }
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// The image of `c` with identity maps and the selection test `sel` (if any), or its refusal.
fn to_bytes(c: &Content, maps: Option<&[u8]>, sel: Option<&[u8]>) -> Result<Vec<u8>, ImageError> {
    let owned = c.owned();
    let img = Image::new_with_maps(Mode::Feedforward, c.dims(), c.period, owned.payload(), maps)?;
    let img = match sel {
        Some(body) => img.with_selection_test(body)?,
        None => img,
    };
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let len = encode(&img, &mut buf)?;
    buf.truncate(len);
    Ok(buf)
}

/// The selection of `shared_types::selection`'s module doc, written out: z = fl(R̂x) row by row from 0,
/// then per trajectory s = Σ fl(z − ĉ_z)² from 0, the least accepted s, ties to the lowest index.
fn reference(n: usize, R: &[f32], records: &[(Vec<f32>, f32)], x: &[f32]) -> Option<u16> {
    let z: Vec<f32> = (0..n)
        .map(|i| {
            let mut s = 0.0f32;
            for j in i..n {
                s += R[i * n + j] * x[j];
            }
            s
        })
        .collect();
    let mut best = None;
    let mut best_s = f32::INFINITY;
    for (t, (cz, thr)) in records.iter().enumerate() {
        let mut s = 0.0f32;
        for k in 0..n {
            let d = z[k] - cz[k];
            s += d * d;
        }
        if s <= *thr && s < best_s {
            best_s = s;
            best = Some(t as u16);
        }
    }
    best
}

#[test]
fn selection_test_round_trips_and_selects_as_documented() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let mut cases = 0;
    for case in 0..60 {
        let n = [2usize, 3, 4, 8][case % 4];
        let nt = rng.random_range(1..12usize);
        let P = random_spd(&mut rng, n);
        let R = factor_of(&P, n).unwrap();
        let one = content(&mut rng, n, 1, nt, &P);
        // The same balls over two locations with the same metric: the general loop, location changes
        // between consecutive trajectories included; it must agree with the one-location image.
        let two = Content {
            location: (0..nt).map(|t| (t % 2) as u8).collect(),
            ..content(&mut ChaCha8Rng::seed_from_u64(0), n, 2, nt, &P)
        };
        let two = Content {
            centre: one.centre.clone(),
            ..two
        };
        let thresholds: Vec<f32> = (0..nt).map(|_| rng.random_range(0.05f32..4.0)).collect();
        let maps = identity_maps(n, 1);
        let bytes = to_bytes(&one, Some(&maps), Some(&section(&one, &R, &thresholds))).unwrap();
        let bytes2 = to_bytes(&two, Some(&maps), Some(&section(&two, &R, &thresholds))).unwrap();
        // Round trip, and the section is last under tag 13.
        let img = decode(&bytes).unwrap();
        let secs = sections_of(&bytes);
        assert_eq!(secs.last().unwrap().0, SectionKind::SelectionTest as u16);
        assert_eq!(SectionKind::SelectionTest as u16, 13);
        assert_eq!(secs.last().unwrap().1.len(), selection::body_len(n, 1, nt));
        let mut again = vec![0u8; bytes.len()];
        assert_eq!(encode(&img, &mut again), Ok(bytes.len()));
        assert_eq!(again, bytes);
        let test = img.selection_test().expect("has the section");
        assert_eq!(test.threshold(n, nt - 1), thresholds[nt - 1]);
        let records: Vec<(Vec<f32>, f32)> = (0..nt)
            .map(|t| {
                (
                    (0..n).map(|i| test.centre_z(n, t, i)).collect(),
                    test.threshold(n, t),
                )
            })
            .collect();
        let img2 = decode(&bytes2).unwrap();
        let ctl = Controller::new(img);
        let ctl2 = Controller::new(img2);
        for _ in 0..200 {
            // States near a centre (scaled to the thresholds), so that most are accepted by some ball
            // and some lie near a boundary.
            let t = rng.random_range(0..nt);
            let scale = rng.random_range(0.0f32..1.5);
            let x: Vec<f32> = (0..n)
                .map(|i| one.centre[t * n + i] + scale * rng.random_range(-1.0f32..1.0))
                .collect();
            let want = reference(n, &R, &records, &x);
            assert_eq!(ctl.select_maps(&x), want, "case {case}, n {n}, x {x:?}");
            assert_eq!(
                ctl2.select_maps(&x),
                want,
                "two locations, case {case}, n {n}"
            );
            // The model-maps step selects with it (identity maps: ξ = x).
            let mut c = Controller::new(decode(&bytes).unwrap());
            let stepped = c.step_plant(&x);
            assert_eq!(c.active_trajectory(), want, "case {case}");
            assert_eq!(stepped.is_ok(), want.is_some());
            cases += usize::from(want.is_some());
        }
    }
    // The states exercised acceptance, not only refusal.
    assert!(cases > 3000, "{cases} accepted states");
}

#[test]
fn selection_test_rules_are_refused() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let n = 3;
    let P = random_spd(&mut rng, n);
    let R = factor_of(&P, n).unwrap();
    let c = content(&mut rng, n, 1, 2, &P);
    let maps = identity_maps(n, 1);
    let good = section(&c, &R, &[1.0, 2.0]);
    assert!(to_bytes(&c, Some(&maps), Some(&good)).is_ok());
    let err = |body: &[u8]| to_bytes(&c, Some(&maps), Some(body)).unwrap_err();
    let with_value = |i: usize, v: f32| {
        let mut b = good.clone();
        b[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
        b
    };
    assert_eq!(
        err(&good[..good.len() - 4]),
        ImageError::FieldLength {
            field: Field::SelectionTest,
            expected: good.len() as u32,
            found: good.len() as u32 - 4
        }
    );
    // Row 2, column 0 of R̂: below the diagonal.
    assert_eq!(
        err(&with_value(2 * n, 0.5)),
        ImageError::FactorNotUpperTriangular {
            location: 0,
            row: 2,
            col: 0
        }
    );
    assert_eq!(
        err(&with_value(n + 1, 0.0)),
        ImageError::FactorDiagonal {
            location: 0,
            row: 1
        }
    );
    assert_eq!(
        err(&with_value(1, f32::NAN)),
        ImageError::NonFinite {
            field: Field::Factor,
            pos: Pos(0, 0, 1)
        }
    );
    // Trajectory 1's threshold (its record follows the factor and record 0).
    let s1 = n * n + (n + 1) + n;
    assert_eq!(
        err(&with_value(s1, -1.0)),
        ImageError::NegativeBallThreshold { ball: 1 }
    );
    assert_eq!(
        err(&with_value(n * n + 1, f32::INFINITY)),
        ImageError::NonFinite {
            field: Field::BallCentreZ,
            pos: Pos(0, 1, 0)
        }
    );
    // Without model maps: refused when built, and when decoded from bytes that carry it.
    assert_eq!(
        to_bytes(&c, None, Some(&good)).unwrap_err(),
        ImageError::SelectionWithoutModelMaps
    );
    let plain = to_bytes(&c, None, None).unwrap();
    let mut secs = sections_of(&plain);
    secs.push((SectionKind::SelectionTest as u16, good.clone()));
    assert_eq!(
        decode(&with_sections(&plain, &secs)).map(|_| ()),
        Err(ImageError::SelectionWithoutModelMaps)
    );
    // In a PWA image: a section of the other mode.
    let pwa = crate::common::two_partitions().to_bytes().unwrap();
    let mut secs = sections_of(&pwa);
    secs.push((SectionKind::SelectionTest as u16, good));
    assert_eq!(
        decode(&with_sections(&pwa, &secs)).map(|_| ()),
        Err(ImageError::UnexpectedSection {
            kind: SectionKind::SelectionTest,
            mode: Mode::PwaFeedback
        })
    );
}

#[test]
fn the_decoder_without_model_maps_refuses_them_and_decodes_the_rest_alike() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let n = 4;
    let P = random_spd(&mut rng, n);
    let R = factor_of(&P, n).unwrap();
    let c = content(&mut rng, n, 1, 3, &P);
    let maps = identity_maps(n, 1);
    let sel = section(&c, &R, &[1.0, 1.0, 1.0]);
    for bytes in [
        to_bytes(&c, Some(&maps), Some(&sel)).unwrap(),
        to_bytes(&c, Some(&maps), None).unwrap(),
    ] {
        assert!(decode(&bytes).is_ok());
        assert_eq!(
            shared_types::image::decode_without_model_maps(&bytes).map(|_| ()),
            Err(ImageError::ModelMapsNotSupported)
        );
    }
    let plain = to_bytes(&c, None, None).unwrap();
    assert_eq!(
        shared_types::image::decode_without_model_maps(&plain),
        decode(&plain)
    );
    // A PWA image, and a corrupted one, alike too.
    let pwa = crate::common::two_partitions().to_bytes().unwrap();
    assert_eq!(
        shared_types::image::decode_without_model_maps(&pwa),
        decode(&pwa)
    );
    let mut bad = plain.clone();
    let last = bad.len() - 1;
    bad[last] ^= 0x55;
    assert_eq!(
        shared_types::image::decode_without_model_maps(&bad),
        decode(&bad)
    );
}
