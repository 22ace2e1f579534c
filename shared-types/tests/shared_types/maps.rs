//! The model maps section (tag 10) and `Controller::step_plant`: a hand-assembled feedback-linearizable
//! image round-trips byte for byte, every rule of the section is refused with its own error, `step_plant`
//! is `coords`, then `step`, then `input_map` bit for bit (and `step` itself without maps), the fallback
//! acts in the plant's input space, and mutated bytes never panic the decoder or the evaluator. With
//! controller states (a dynamic extension): a body without them is the layout before the extension byte
//! for byte, ζ0 and the programs' counts are refused as the layout says, and `step_plant` carries ζ from
//! step to step (ζ0 at reset, unchanged by the fallback and by an error).

use crate::common::{fix_header, sections_of, with_sections, Content, FallbackC};
use crate::program::assemble;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{MAX_EXT, MAX_IMAGE_LEN, MAX_N};
use shared_types::error::{Dim, Field, ModelMap, Pos};
use shared_types::eval::{Controller, Status};
use shared_types::image::{decode, encode, Image, ImageError, Mode, SectionKind, Terminal};
use shared_types::maps::{body_len, write_body, ModelMaps, MAPS_HEADER_LEN};
use shared_types::program::{Func, Op, Program};

/// coords: ξ0 = x0 + 0.5·x1, ξ1 = sin(x2)·x1 (3 plant states, n = 2). 11 bytes of code: the body is
/// not a multiple of 4, so the section has padding.
fn coords() -> Vec<u8> {
    use Op::*;
    assemble(
        3,
        2,
        &[0.5],
        &[
            Load(0),
            Load(1),
            Const(0),
            Mul,
            Add,
            Store(0),
            Load(2),
            Func(self::Func::Sin),
            Load(1),
            Mul,
            Store(1),
        ],
        3,
    )
}

/// input_map: u0 = cos(x2)·w0 − x0, u1 = w0 / 4 (slots x0 x1 x2 w0; m_plant = 2).
fn input_map() -> Vec<u8> {
    use Op::*;
    assemble(
        4,
        2,
        &[4.0],
        &[
            Load(2),
            Func(self::Func::Cos),
            Load(3),
            Mul,
            Load(0),
            Sub,
            Store(0),
            Load(3),
            Const(0),
            Div,
            Store(1),
        ],
        2,
    )
}

fn body(n_plant: usize, m_plant: usize, c: &[u8], i: &[u8]) -> Vec<u8> {
    ext_body(n_plant, m_plant, &[], c, i)
}

fn ext_body(n_plant: usize, m_plant: usize, ext: &[f32], c: &[u8], i: &[u8]) -> Vec<u8> {
    let mut b = vec![0u8; body_len(ext.len(), c.len(), i.len())];
    assert_eq!(write_body(&mut b, n_plant, m_plant, ext, c, i), Ok(b.len()));
    b
}

/// The linear part: n = 2, m = 1, two trajectories (the table ends with the fallback), fallback a
/// constant plant input (m_plant = 2 values) inside a plant input box.
fn linear() -> Content {
    Content {
        n: 2,
        m: 1,
        nl: 1,
        period: 0.05,
        K: vec![-1.0, -1.5],
        P: vec![1.0, 0.0, 0.0, 1.0],
        traj_len: vec![4, 3],
        centre: vec![0.0, 0.0, 3.0, 0.0],
        delta: vec![1.0, 1.0],
        v: vec![0.1, 0.2, 0.3, 0.4, -0.1, -0.2, -0.3],
        location: vec![0; 7],
        fallback: FallbackC::Constant(vec![0.25, -0.5]),
        input_box: Some((vec![-1.0, -1.0], vec![1.0, 1.0])),
        terminal: Terminal::Fallback,
    }
}

/// Validates and encodes `c` with the maps body `maps`.
fn to_bytes(c: &Content, maps: &[u8]) -> Result<Vec<u8>, ImageError> {
    let owned = c.owned();
    let img = Image::new_with_maps(
        Mode::Feedforward,
        c.dims(),
        c.period,
        owned.payload(),
        Some(maps),
    )?;
    let mut buf = vec![0u8; MAX_IMAGE_LEN];
    let len = encode(&img, &mut buf)?;
    buf.truncate(len);
    Ok(buf)
}

fn good() -> Vec<u8> {
    to_bytes(&linear(), &body(3, 2, &coords(), &input_map())).unwrap()
}

#[test]
fn maps_image_round_trips_and_reads_back() {
    let bytes = good();
    let img = decode(&bytes).unwrap();
    assert_eq!(
        (img.n(), img.m(), img.plant_n(), img.plant_m()),
        (2, 1, 3, 2)
    );
    let maps = img.model_maps().expect("has maps");
    assert_eq!((maps.n_plant(), maps.m_plant()), (3, 2));
    assert_eq!(maps.coords(), Program::decode(&coords()).unwrap());
    assert_eq!(maps.input_map(), Program::decode(&input_map()).unwrap());
    assert_eq!(maps.body(), &body(3, 2, &coords(), &input_map())[..]);
    // The section is last in the directory, under tag 10, and the body pads the coords program.
    let secs = sections_of(&bytes);
    assert_eq!(secs.last().unwrap().0, SectionKind::ModelMaps as u16);
    assert_eq!(SectionKind::ModelMaps as u16, 10);
    let coords_len = coords().len();
    assert_ne!(coords_len % 4, 0);
    assert_eq!(
        secs.last().unwrap().1.len(),
        MAPS_HEADER_LEN + coords_len.next_multiple_of(4) + input_map().len().next_multiple_of(4)
    );
    let mut again = vec![0u8; bytes.len()];
    assert_eq!(encode(&img, &mut again), Ok(bytes.len()));
    assert_eq!(again, bytes);
    assert_eq!(img.fallback_input(1), -0.5);
    assert_eq!(img.input_bounds(1), Some((-1.0, 1.0)));
    // Without the section: plant dims are the image's.
    let plain = crate::common::Content {
        fallback: FallbackC::Zero,
        input_box: None,
        ..linear()
    }
    .to_bytes()
    .unwrap();
    let img = decode(&plain).unwrap();
    assert!(img.model_maps().is_none());
    assert_eq!((img.plant_n(), img.plant_m()), (2, 1));
}

#[test]
fn maps_section_rules_are_refused() {
    let c = linear();
    let (co, im) = (coords(), input_map());
    let err = |c: &Content, b: &[u8]| to_bytes(c, b).unwrap_err();
    // Plant dimensions.
    assert_eq!(
        err(&c, &body(0, 2, &co, &im)),
        ImageError::DimOutOfRange {
            dim: Dim::PlantN,
            value: 0,
            min: 1,
            max: MAX_N as u32
        }
    );
    assert!(matches!(
        err(&c, &body(3, 7, &co, &im)),
        ImageError::DimOutOfRange {
            dim: Dim::PlantM,
            ..
        }
    ));
    // Arity of each map against the dimensions.
    assert_eq!(
        err(&c, &body(4, 2, &co, &im)),
        ImageError::MapInputs {
            map: ModelMap::Coords,
            expected: 4,
            found: 3
        }
    );
    assert_eq!(
        err(&c, &body(3, 1, &co, &im)),
        ImageError::MapOutputs {
            map: ModelMap::InputMap,
            expected: 1,
            found: 2
        }
    );
    let swapped = body(3, 2, &im, &co);
    assert!(matches!(
        err(&c, &swapped),
        ImageError::MapInputs {
            map: ModelMap::Coords,
            ..
        }
    ));
    // Reserved and padding bytes, lengths.
    let good_body = body(3, 2, &co, &im);
    let mut b = good_body.clone();
    b[3] = 1;
    assert_eq!(err(&c, &b), ImageError::MapsPadding { offset: 3 });
    // Byte 2 is n_ext: one controller state more than the body holds.
    let mut b = good_body.clone();
    b[2] = 1;
    assert!(matches!(
        err(&c, &b),
        ImageError::FieldLength {
            field: Field::ModelMaps,
            ..
        }
    ));
    let mut b = good_body.clone();
    let pad = MAPS_HEADER_LEN + co.len();
    b[pad] = 7;
    assert_eq!(err(&c, &b), ImageError::MapsPadding { offset: pad as u32 });
    let mut b = good_body.clone();
    b.push(0);
    assert!(matches!(
        err(&c, &b),
        ImageError::FieldLength {
            field: Field::ModelMaps,
            ..
        }
    ));
    assert!(matches!(
        err(&c, &good_body[..MAPS_HEADER_LEN - 1]),
        ImageError::FieldLength {
            field: Field::ModelMaps,
            ..
        }
    ));
    let mut b = good_body.clone();
    b[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(err(&c, &b), ImageError::FieldLength { .. }));
    // A bad program inside: the program's own error.
    let mut bad = co.clone();
    *bad.last_mut().unwrap() = 5; // Store(5): output out of range
    assert!(matches!(
        err(&c, &body(3, 2, &bad, &im)),
        ImageError::ProgramOperand { .. }
    ));
    // The fallback and the box are in the plant's input space; a linear fallback is refused.
    let mut lin = c.clone();
    lin.fallback = FallbackC::Linear {
        K: vec![0.0, 0.0],
        x_ref: vec![0.0, 0.0],
        u_ref: vec![0.0],
    };
    lin.input_box = None;
    assert_eq!(err(&lin, &good_body), ImageError::LinearFallbackWithMaps);
    let mut short = c.clone();
    short.fallback = FallbackC::Constant(vec![0.25]);
    assert!(matches!(
        err(&short, &good_body),
        ImageError::FieldLength {
            field: Field::FallbackInput,
            ..
        }
    ));
    let mut short = c.clone();
    short.input_box = Some((vec![-1.0], vec![1.0]));
    assert!(matches!(
        err(&short, &good_body),
        ImageError::FieldLength {
            field: Field::BoxLo,
            ..
        }
    ));
    let mut outside = c.clone();
    outside.fallback = FallbackC::Constant(vec![0.25, -1.5]);
    assert_eq!(
        err(&outside, &good_body),
        ImageError::FallbackOutsideBox { input: 1 }
    );
}

#[test]
fn maps_section_in_a_pwa_image_is_refused() {
    let pwa = crate::common::two_partitions().to_bytes().unwrap();
    let mut secs = sections_of(&pwa);
    secs.push((
        SectionKind::ModelMaps as u16,
        body(3, 2, &coords(), &input_map()),
    ));
    assert_eq!(
        decode(&with_sections(&pwa, &secs)).map(|_| ()),
        Err(ImageError::UnexpectedSection {
            kind: SectionKind::ModelMaps,
            mode: Mode::PwaFeedback
        })
    );
    // Tag 10 is the model maps; the tags after 14 are not known to this build.
    let ff = good();
    let mut secs = sections_of(&ff);
    secs.push((15, vec![]));
    assert_eq!(
        decode(&with_sections(&ff, &secs)).map(|_| ()),
        Err(ImageError::UnknownSection { kind: 15 })
    );
}

/// What `step_plant` must give, composed from its parts: coords, a controller over the same image
/// stepping ξ (`step`), input_map; where `step` applies the fallback (m_plant = 2 values, not m = 1),
/// that fallback.
fn composed(reference: &mut Controller<'_>, maps: &ModelMaps<'_>, x: &[f32]) -> Option<Vec<f32>> {
    let mut xi = [0.0f32; 2];
    maps.coords().eval(x, &mut xi).unwrap();
    let w = reference.step(&xi).ok()?;
    if w.len() == 2 {
        return Some(w.as_slice().to_vec());
    }
    let mut slots = x.to_vec();
    slots.extend_from_slice(w.as_slice());
    let mut u = [0.0f32; 2];
    maps.input_map().eval(&slots, &mut u).unwrap();
    Some(u.to_vec())
}

#[test]
fn step_plant_is_coords_then_step_then_input_map_bit_for_bit() {
    let bytes = good();
    let img = decode(&bytes).unwrap();
    let maps = img.model_maps().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let (mut compared, mut fallbacks) = (0, 0);
    for _ in 0..200 {
        // x with ξ near one of the two centres (ξ0 ≈ x0 + x1/2, ξ1 = sin(x2)·x1).
        let c = if rng.random_bool(0.5) { 0.0 } else { 3.0 };
        let x: Vec<f32> = vec![
            c + rng.random_range(-0.6f32..0.6),
            rng.random_range(-0.6f32..0.6),
            rng.random_range(-3.0f32..3.0),
        ];
        let mut ctl = Controller::new(img);
        let mut reference = Controller::new(img);
        for k in 0..9 {
            let got = ctl.step_plant(&x);
            match composed(&mut reference, &maps, &x) {
                Some(u) => {
                    let got = got.expect("Ok where the composition is Ok");
                    if u == [0.25, -0.5] {
                        fallbacks += 1;
                    }
                    assert_eq!(got.len(), 2);
                    let bits = |v: &[f32]| v.iter().map(|a| a.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(got.as_slice()), bits(&u), "x = {x:?}, step {k}");
                    compared += 1;
                }
                None => assert_eq!(got, Err(Status::OutOfEnvelope), "x = {x:?}"),
            }
            assert_eq!(ctl.step_index(), reference.step_index());
        }
    }
    assert!(compared > 200 && fallbacks > 50, "{compared} {fallbacks}");
}

#[test]
fn step_plant_refuses_bad_states_and_non_finite_maps() {
    let bytes = good();
    let img = decode(&bytes).unwrap();
    let mut ctl = Controller::new(img);
    assert_eq!(ctl.last_input().len(), 2);
    assert_eq!(ctl.step_plant(&[0.0, 0.0]), Err(Status::BadFrame));
    assert_eq!(ctl.step_plant(&[0.0, f32::NAN, 0.0]), Err(Status::BadFrame));
    // ξ0 = x0 + x1/2 overflows: not finite, out of the envelope for this step (not latched).
    assert_eq!(
        ctl.step_plant(&[f32::MAX, f32::MAX, 0.0]),
        Err(Status::OutOfEnvelope)
    );
    assert_eq!(ctl.step_index(), 0);
    // A finite ξ in a ball: accepted, and the fallback (the firmware's answer to a failed step) has
    // m_plant values.
    let u = ctl.step_plant(&[0.1, 0.1, 0.3]).unwrap();
    assert_eq!(u.len(), 2);
    assert_eq!(ctl.step_index(), 1);
    assert_eq!(ctl.fallback(&[0.1, 0.1, 0.3], &u).as_slice(), &[0.25, -0.5]);
}

#[test]
fn step_plant_without_maps_is_step() {
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    for _ in 0..40 {
        let c = crate::common::random_content(&mut rng, 4, 3, 2, 6);
        let Ok(bytes) = c.to_bytes() else { continue };
        let img = decode(&bytes).unwrap();
        let (mut a, mut b) = (Controller::new(img), Controller::new(img));
        let x: Vec<f32> = (0..img.n()).map(|i| img.centre(0, i) + 0.01).collect();
        for _ in 0..10 {
            assert_eq!(a.step_plant(&x), b.step(&x));
        }
    }
}

#[test]
fn mutated_maps_images_never_panic() {
    let bytes = good();
    let secs = sections_of(&bytes);
    let (kind, maps) = secs.last().unwrap().clone();
    let mut rng = ChaCha8Rng::seed_from_u64(0x3a95);
    let (mut ok, mut refused) = (0, 0);
    for i in 0..4000 {
        let mut body = maps.clone();
        for _ in 0..rng.random_range(1..4) {
            let at = rng.random_range(0..body.len());
            body[at] = if i % 3 == 0 {
                rng.random()
            } else {
                body[at] ^ (1 << rng.random_range(0..8))
            };
        }
        let mut s = secs.clone();
        *s.last_mut().unwrap() = (kind, body);
        let mut image = with_sections(&bytes, &s);
        fix_header(&mut image);
        match decode(&image) {
            Err(e) => {
                assert!(!e.to_string().is_empty());
                refused += 1;
            }
            Ok(img) => {
                ok += 1;
                let mut ctl = Controller::new(img);
                for _ in 0..4 {
                    let x: Vec<f32> = (0..img.plant_n())
                        .map(|_| rng.random_range(-2.0f32..2.0))
                        .collect();
                    if let Ok(u) = ctl.step_plant(&x) {
                        assert_eq!(u.len(), img.plant_m());
                        assert!(u.as_slice().iter().all(|v| v.is_finite()));
                    }
                }
            }
        }
    }
    assert!(ok > 0 && refused > 0, "ok {ok}, refused {refused}");
}

// ---------------------------------------------------------------------------------------------------------
// Controller states (a dynamic extension): n_ext = 1 over the same linear part (n = 2, m = 1).

/// coords with one controller state: ξ = (x0, ζ0) (slots x0 ζ0).
fn ext_coords() -> Vec<u8> {
    use Op::*;
    assemble(2, 2, &[], &[Load(0), Store(0), Load(1), Store(1)], 1)
}

/// input_map with one controller state (slots x0 ζ0 w0): u0 = ζ0, u1 = 0.5·x0, ζ0⁺ = ζ0 + 0.25·w0 +
/// 0.125·x0² (the last term overflows for a huge x0 while u stays finite).
fn ext_input_map() -> Vec<u8> {
    use Op::*;
    assemble(
        3,
        3,
        &[0.5, 0.25, 0.125],
        &[
            Load(1),
            Store(0),
            Load(0),
            Const(0),
            Mul,
            Store(1),
            Load(1),
            Load(2),
            Const(1),
            Mul,
            Add,
            Load(0),
            Load(0),
            Mul,
            Const(2),
            Mul,
            Add,
            Store(2),
        ],
        3,
    )
}

/// ζ0 of the extension image.
const ZETA0: f32 = 0.0625;

fn ext_good_body() -> Vec<u8> {
    ext_body(1, 2, &[ZETA0], &ext_coords(), &ext_input_map())
}

fn ext_good() -> Vec<u8> {
    to_bytes(&linear(), &ext_good_body()).unwrap()
}

#[test]
fn a_body_without_controller_states_is_the_layout_before_them() {
    let (co, im) = (coords(), input_map());
    // The layout before the extension, by hand: n_plant, m_plant, two zero bytes, the two lengths, then
    // each program padded to 4.
    let mut before = vec![3u8, 2, 0, 0];
    before.extend_from_slice(&(co.len() as u32).to_le_bytes());
    before.extend_from_slice(&(im.len() as u32).to_le_bytes());
    for p in [&co, &im] {
        before.extend_from_slice(p);
        before.resize(before.len().next_multiple_of(4), 0);
    }
    assert_eq!(body(3, 2, &co, &im), before);
    assert_eq!(body_len(0, co.len(), im.len()), before.len());
    let img_bytes = good();
    let maps = decode(&img_bytes).unwrap().model_maps().unwrap();
    assert_eq!(maps.n_ext(), 0);
    assert_eq!(maps.ext_inits().count(), 0);
    assert_eq!(maps.ext_init(0), 0.0);
    assert!(Controller::new(decode(&img_bytes).unwrap())
        .extension()
        .is_empty());
}

#[test]
fn controller_states_round_trip_and_read_back() {
    let b = ext_good_body();
    assert_eq!(b[2], 1);
    assert_eq!(b[3], 0);
    assert_eq!(
        &b[MAPS_HEADER_LEN..MAPS_HEADER_LEN + 4],
        &ZETA0.to_le_bytes()
    );
    assert_eq!(
        b.len(),
        MAPS_HEADER_LEN
            + 4
            + ext_coords().len().next_multiple_of(4)
            + ext_input_map().len().next_multiple_of(4)
    );
    let bytes = ext_good();
    let img = decode(&bytes).unwrap();
    assert_eq!(
        (img.n(), img.m(), img.plant_n(), img.plant_m()),
        (2, 1, 1, 2)
    );
    let maps = img.model_maps().unwrap();
    assert_eq!((maps.n_plant(), maps.m_plant(), maps.n_ext()), (1, 2, 1));
    assert_eq!(maps.ext_init(0), ZETA0);
    assert_eq!(maps.ext_init(1), 0.0);
    assert_eq!(maps.ext_inits().collect::<Vec<_>>(), vec![ZETA0]);
    assert_eq!(maps.coords(), Program::decode(&ext_coords()).unwrap());
    assert_eq!(maps.input_map(), Program::decode(&ext_input_map()).unwrap());
    assert_eq!(maps.body(), &b[..]);
    let mut again = vec![0u8; bytes.len()];
    assert_eq!(encode(&img, &mut again), Ok(bytes.len()));
    assert_eq!(again, bytes);
    // Up to MAX_EXT states.
    let full = [0.5f32; MAX_EXT];
    let mut ops = vec![];
    for i in 0..2 + MAX_EXT {
        ops.push(Op::Load(i as u8));
        ops.push(Op::Store(i as u8));
    }
    let im_full = assemble(1 + MAX_EXT + 1, 2 + MAX_EXT, &[], &ops, 1);
    let co_full = assemble(1 + MAX_EXT, 2, &[], &ops[..4], 1);
    let full_bytes = to_bytes(&linear(), &ext_body(1, 2, &full, &co_full, &im_full)).unwrap();
    let img = decode(&full_bytes).unwrap();
    assert_eq!(img.model_maps().unwrap().n_ext(), MAX_EXT);
    assert_eq!(Controller::new(img).extension(), &full);
}

#[test]
fn controller_state_rules_are_refused() {
    let c = linear();
    let (co, im) = (ext_coords(), ext_input_map());
    let err = |b: &[u8]| to_bytes(&c, b).unwrap_err();
    // More states than MAX_EXT.
    let five = [0.0f32; MAX_EXT + 1];
    assert_eq!(
        err(&ext_body(1, 2, &five, &co, &im)),
        ImageError::DimOutOfRange {
            dim: Dim::ExtStates,
            value: MAX_EXT as u32 + 1,
            min: 0,
            max: MAX_EXT as u32
        }
    );
    // Byte 3 stays reserved.
    let mut b = ext_good_body();
    b[3] = 0x80;
    assert_eq!(err(&b), ImageError::MapsPadding { offset: 3 });
    // A non-finite ζ0.
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        assert_eq!(
            err(&ext_body(1, 2, &[bad], &co, &im)),
            ImageError::NonFinite {
                field: Field::ExtInit,
                pos: Pos(0, 0, 0)
            }
        );
    }
    // ζ0 is checked before the programs.
    assert_eq!(
        err(&ext_body(1, 2, &[0.0, f32::NAN], &co, &im)),
        ImageError::NonFinite {
            field: Field::ExtInit,
            pos: Pos(1, 0, 0)
        }
    );
    // The programs' counts: coords reads x and ζ, input_map reads x, ζ and w and stores u and ζ⁺.
    assert_eq!(
        err(&ext_body(1, 2, &[0.0, 0.0], &co, &im)),
        ImageError::MapInputs {
            map: ModelMap::Coords,
            expected: 3,
            found: 2
        }
    );
    // The feedback-linearizable programs with a state: coords reads 3 slots where 1 + 1 are given.
    assert_eq!(
        err(&ext_body(1, 2, &[0.0], &coords(), &im)),
        ImageError::MapInputs {
            map: ModelMap::Coords,
            expected: 2,
            found: 3
        }
    );
    // input_map storing u only (no ζ⁺).
    let u_only = {
        use Op::*;
        assemble(3, 2, &[], &[Load(1), Store(0), Load(2), Store(1)], 1)
    };
    assert_eq!(
        err(&ext_body(1, 2, &[0.0], &co, &u_only)),
        ImageError::MapOutputs {
            map: ModelMap::InputMap,
            expected: 3,
            found: 2
        }
    );
    // input_map not reading w (slots x, ζ only).
    let no_w = {
        use Op::*;
        assemble(
            2,
            3,
            &[],
            &[Load(1), Store(0), Load(0), Store(1), Load(1), Store(2)],
            1,
        )
    };
    assert_eq!(
        err(&ext_body(1, 2, &[0.0], &co, &no_w)),
        ImageError::MapInputs {
            map: ModelMap::InputMap,
            expected: 3,
            found: 2
        }
    );
    // A ζ0 word cut: the body is shorter than its header says.
    let mut b = ext_good_body();
    b[2] = 2;
    assert!(matches!(
        err(&b),
        ImageError::FieldLength {
            field: Field::ModelMaps,
            ..
        }
    ));
    for e in [
        ImageError::DimOutOfRange {
            dim: Dim::ExtStates,
            value: 5,
            min: 0,
            max: 4,
        },
        ImageError::NonFinite {
            field: Field::ExtInit,
            pos: Pos(1, 0, 0),
        },
    ] {
        assert!(!e.to_string().is_empty());
    }
    assert_eq!(
        ImageError::NonFinite {
            field: Field::ExtInit,
            pos: Pos(1, 0, 0)
        }
        .to_string(),
        "controller state 1: initial value is not finite"
    );
}

/// What the extension image's `step_plant` must give at x with controller state ζ: coords(x, ζ), a
/// reference controller stepping ξ, input_map(x, ζ, w) → (u, ζ⁺); where `step` applies the fallback,
/// that fallback and ζ unchanged. `None` where `step` refuses.
fn composed_ext(
    reference: &mut Controller<'_>,
    maps: &ModelMaps<'_>,
    x: f32,
    zeta: f32,
) -> Option<(Vec<f32>, f32)> {
    let mut xi = [0.0f32; 2];
    maps.coords().eval(&[x, zeta], &mut xi).unwrap();
    let w = reference.step(&xi).ok()?;
    if w.len() == 2 {
        return Some((w.as_slice().to_vec(), zeta));
    }
    let mut out = [0.0f32; 3];
    maps.input_map()
        .eval(&[x, zeta, w.as_slice()[0]], &mut out)
        .unwrap();
    Some((out[..2].to_vec(), out[2]))
}

#[test]
fn step_plant_carries_the_controller_states() {
    let bytes = ext_good();
    let img = decode(&bytes).unwrap();
    let maps = img.model_maps().unwrap();
    let bits = |v: &[f32]| v.iter().map(|a| a.to_bits()).collect::<Vec<_>>();
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let (mut laws, mut fallbacks) = (0, 0);
    let mut ctl = Controller::new(img);
    for run in 0..60 {
        // Every run starts from ζ0, whether by a new controller or by reset.
        if run % 2 == 0 {
            ctl = Controller::new(img);
        } else {
            ctl.reset();
        }
        assert_eq!(ctl.extension(), &[ZETA0]);
        let mut reference = Controller::new(img);
        let mut zeta = ZETA0;
        let c = if rng.random_bool(0.5) { 0.0 } else { 3.0 };
        for k in 0..7 {
            let x = c + rng.random_range(-0.8f32..0.8);
            let got = ctl.step_plant(&[x]);
            match composed_ext(&mut reference, &maps, x, zeta) {
                Some((u, next)) => {
                    let got = got.expect("Ok where the composition is Ok");
                    assert_eq!(bits(got.as_slice()), bits(&u), "run {run} step {k}");
                    if u == [0.25, -0.5] {
                        fallbacks += 1;
                        assert_eq!(next.to_bits(), zeta.to_bits(), "the fallback keeps ζ");
                    } else {
                        laws += 1;
                        assert_eq!(u[0].to_bits(), zeta.to_bits(), "u0 = ζ0 of this step");
                    }
                    zeta = next;
                }
                None => assert_eq!(got, Err(Status::OutOfEnvelope)),
            }
            assert_eq!(bits(ctl.extension()), bits(&[zeta]), "run {run} step {k}");
            assert_eq!(ctl.step_index(), reference.step_index());
        }
    }
    assert!(laws > 100 && fallbacks > 20, "{laws} {fallbacks}");
}

#[test]
fn a_failed_step_leaves_the_controller_states() {
    let bytes = ext_good();
    let img = decode(&bytes).unwrap();
    let mut ctl = Controller::new(img);
    assert_eq!(ctl.step_plant(&[0.0, 0.0]), Err(Status::BadFrame));
    assert_eq!(ctl.step_plant(&[f32::NAN]), Err(Status::BadFrame));
    assert_eq!(ctl.extension(), &[ZETA0]);
    let u = ctl.step_plant(&[0.1]).unwrap();
    assert_eq!(u.len(), 2);
    assert_eq!(u.as_slice()[0], ZETA0);
    let zeta1 = ctl.extension()[0];
    assert_ne!(zeta1, ZETA0);
    assert_eq!(ctl.step_index(), 1);
    // x0 = 1e20: w and u are finite, ζ⁺ (with 0.125·x0²) is not: out of the envelope, κ and ζ kept.
    assert_eq!(ctl.step_plant(&[1e20]), Err(Status::OutOfEnvelope));
    assert_eq!(ctl.step_index(), 1);
    assert_eq!(ctl.extension(), &[zeta1]);
    // u non-finite (0.5·x0 overflows): the same.
    assert_eq!(ctl.step_plant(&[f32::MAX]), Err(Status::OutOfEnvelope));
    assert_eq!(ctl.step_index(), 1);
    assert_eq!(ctl.extension(), &[zeta1]);
    // The run goes on from ζ1.
    let u = ctl.step_plant(&[0.1]).unwrap();
    assert_eq!(u.as_slice()[0], zeta1);
    assert_eq!(ctl.step_index(), 2);
    // Past the table's 4 rows the fallback applies and ζ stays.
    ctl.step_plant(&[0.1]).unwrap();
    ctl.step_plant(&[0.1]).unwrap();
    let zeta4 = ctl.extension()[0];
    assert_eq!(ctl.step_plant(&[0.1]).unwrap().as_slice(), &[0.25, -0.5]);
    assert_eq!(ctl.extension(), &[zeta4]);
    assert_eq!(ctl.step_index(), 5);
    ctl.reset();
    assert_eq!(ctl.extension(), &[ZETA0]);
    assert_eq!(ctl.step_index(), 0);
    // Outside every ball at κ = 0: latched, ζ kept.
    assert_eq!(ctl.step_plant(&[10.0]), Err(Status::OutOfEnvelope));
    assert_eq!(ctl.extension(), &[ZETA0]);
}

#[test]
fn mutated_extension_images_never_panic() {
    let bytes = ext_good();
    let secs = sections_of(&bytes);
    let (kind, maps) = secs.last().unwrap().clone();
    let mut rng = ChaCha8Rng::seed_from_u64(0x7a37);
    let (mut ok, mut refused) = (0, 0);
    for i in 0..3000 {
        let mut body = maps.clone();
        for _ in 0..rng.random_range(1..4) {
            // Half of the changes in the header and ζ0.
            let at = if i % 2 == 0 {
                rng.random_range(0..MAPS_HEADER_LEN + 4)
            } else {
                rng.random_range(0..body.len())
            };
            body[at] = if i % 3 == 0 {
                rng.random()
            } else {
                body[at] ^ (1 << rng.random_range(0..8))
            };
        }
        let mut s = secs.clone();
        *s.last_mut().unwrap() = (kind, body);
        let mut image = with_sections(&bytes, &s);
        fix_header(&mut image);
        match decode(&image) {
            Err(e) => {
                assert!(!e.to_string().is_empty());
                refused += 1;
            }
            Ok(img) => {
                ok += 1;
                let mut ctl = Controller::new(img);
                let ne = img.model_maps().map_or(0, |m| m.n_ext());
                for _ in 0..4 {
                    let x: Vec<f32> = (0..img.plant_n())
                        .map(|_| rng.random_range(-2.0f32..2.0))
                        .collect();
                    if let Ok(u) = ctl.step_plant(&x) {
                        assert_eq!(u.len(), img.plant_m());
                        assert!(u.as_slice().iter().all(|v| v.is_finite()));
                    }
                    assert_eq!(ctl.extension().len(), ne);
                    assert!(ctl.extension().iter().all(|v| v.is_finite()));
                }
            }
        }
    }
    assert!(ok > 0 && refused > 0, "ok {ok}, refused {refused}");
}
