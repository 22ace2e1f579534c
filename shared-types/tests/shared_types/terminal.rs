//! The optional terminal-law section (tag 11, `shared_types::terminal`): round trips in both modes, the
//! evaluator's handover and terminal phase, and the decoder's refusals (lengths, a P_t that is not
//! symmetric positive definite, a negative radius, a terminal law with model maps).
#![allow(non_snake_case)]

use crate::common::{random_content, sections_of, two_partitions, with_sections};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shared_types::eval::{Controller, Status};
use shared_types::image::{decode, encode, Field, Image, ImageError, SectionKind};
use shared_types::terminal::TerminalLaw;

fn bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn encode_vec(img: &Image<'_>) -> Vec<u8> {
    let mut out = vec![0u8; img.encoded_len().unwrap()];
    let len = encode(img, &mut out).unwrap();
    assert_eq!(len, out.len());
    out
}

/// The parts of a terminal law for n, m: x_e = 0.5·1, K = −1 on the diagonal, v = 0.25, P = I, r̂ = 1.
struct Law {
    x_e: Vec<u8>,
    K: Vec<u8>,
    v: Vec<u8>,
    P: Vec<u8>,
    radius: f32,
}

impl Law {
    fn new(n: usize, m: usize) -> Self {
        let K: Vec<f32> = (0..m * n)
            .map(|i| if i / n == i % n { -1.0 } else { 0.0 })
            .collect();
        let P: Vec<f32> = (0..n * n)
            .map(|i| if i / n == i % n { 1.0 } else { 0.0 })
            .collect();
        Law {
            x_e: bytes(&vec![0.5; n]),
            K: bytes(&K),
            v: bytes(&vec![0.25; m]),
            P: bytes(&P),
            radius: 1.0,
        }
    }

    fn view(&self) -> TerminalLaw<'_> {
        TerminalLaw {
            x_e: &self.x_e,
            K: &self.K,
            v: &self.v,
            P: &self.P,
            radius: self.radius,
        }
    }

    /// The section body: the fields back to back, then the radius.
    fn body(&self) -> Vec<u8> {
        [
            &self.x_e[..],
            &self.K,
            &self.v,
            &self.P,
            &self.radius.to_le_bytes(),
        ]
        .concat()
    }
}

#[test]
fn a_terminal_law_round_trips_in_both_modes() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut images = vec![two_partitions().to_bytes().unwrap()];
    for _ in 0..10 {
        images.push(random_content(&mut rng, 4, 2, 3, 8).to_bytes().unwrap());
    }
    for plain in images {
        let img = decode(&plain).unwrap();
        assert!(img.terminal_law().is_none());
        let law = Law::new(img.n(), img.m());
        let with = encode_vec(&img.with_terminal_law(&law.body()).unwrap());
        let back = decode(&with).unwrap();
        assert_eq!(back.terminal_law(), Some(law.view()));
        assert_eq!(encode_vec(&back), with);
        assert!(sections_of(&with)
            .iter()
            .any(|(k, _)| *k == SectionKind::TerminalLaw as u16));
    }
}

/// Inside the ellipsoid the terminal law answers (and the phase begins); outside it before the handover
/// the task's own law answers; outside it after the handover the answer is out of the envelope, this
/// step only.
#[test]
fn the_evaluator_hands_over_inside_the_ellipsoid_and_holds_the_terminal_phase() {
    let plain = two_partitions().to_bytes().unwrap();
    let img = decode(&plain).unwrap();
    let (n, m) = (img.n(), img.m());
    assert_eq!((n, m), (2, 1));
    let law = Law::new(n, m);
    let with = encode_vec(&img.with_terminal_law(&law.body()).unwrap());
    let timg = decode(&with).unwrap();
    let mut plain_ctl = Controller::new(img);
    let mut ctl = Controller::new(timg);
    // Far from x_e = (0.5, 0.5): the PWA law, as without the section.
    let far = [-3.0f32, 2.0];
    assert_eq!(ctl.step(&far), plain_ctl.step(&far));
    assert!(!ctl.in_terminal_phase());
    // At (0.75, 0.5): inside (d² = 0.0625 ≤ 1); u = −0.75 + 0.25.
    let u = ctl.step(&[0.75, 0.5]).unwrap();
    assert_eq!(u.as_slice(), &[-0.75f32 + 0.25]);
    assert!(ctl.in_terminal_phase());
    // On the boundary (d² = 1 exactly): still accepted.
    assert!(ctl.step(&[1.5, 0.5]).is_ok());
    // Outside after the handover: out of the envelope, not latched.
    assert_eq!(ctl.step(&far), Err(Status::OutOfEnvelope));
    assert!(ctl.step(&[0.5, 0.5]).is_ok());
    // A bad frame stays a bad frame.
    assert_eq!(ctl.step(&[f32::NAN, 0.0]), Err(Status::BadFrame));
    ctl.reset();
    assert!(!ctl.in_terminal_phase());
}

#[test]
fn a_malformed_terminal_law_is_refused() {
    let plain = two_partitions().to_bytes().unwrap();
    let img = decode(&plain).unwrap();
    let (n, m) = (img.n(), img.m());
    // The body's length.
    let mut short = Law::new(n, m);
    short.x_e.truncate(4);
    assert!(matches!(
        img.with_terminal_law(&short.body()),
        Err(ImageError::FieldLength {
            field: Field::TerminalLaw,
            ..
        })
    ));
    // Not symmetric, not positive definite, a negative or NaN radius.
    let mut asym = Law::new(n, m);
    asym.P = bytes(&[1.0, 0.5, 0.0, 1.0]);
    let mut indefinite = Law::new(n, m);
    indefinite.P = bytes(&[1.0, 0.0, 0.0, -1.0]);
    let mut negative = Law::new(n, m);
    negative.radius = -1.0;
    let mut nan = Law::new(n, m);
    nan.radius = f32::NAN;
    for bad in [asym, indefinite, negative, nan] {
        assert_eq!(
            img.with_terminal_law(&bad.body()).map(|_| ()),
            Err(ImageError::BadTerminalLaw)
        );
    }
    // A non-finite gain.
    let mut inf = Law::new(n, m);
    inf.K = bytes(&[f32::INFINITY, 0.0]);
    assert!(matches!(
        img.with_terminal_law(&inf.body()),
        Err(ImageError::NonFinite {
            field: Field::TerminalK,
            ..
        })
    ));
    // The decoder refuses a malformed body (an empty one) rather than skipping it.
    let mut secs = sections_of(&plain);
    secs.push((SectionKind::TerminalLaw as u16, vec![]));
    assert!(decode(&with_sections(&plain, &secs)).is_err());
}
