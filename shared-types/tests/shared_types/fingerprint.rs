//! The optional spec-fingerprint section (tag 12): round trips in both modes (byte-identical
//! re-encoding), images without it, and the decoder's refusal of a malformed section.

use crate::common::{random_content, sections_of, two_partitions, with_sections, Sections};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shared_types::image::{
    decode, encode, Field, Image, ImageError, Mode, SectionKind, SPEC_FINGERPRINT_LEN, SPEC_PARTS,
};

fn hash() -> Vec<u8> {
    (0..SPEC_FINGERPRINT_LEN)
        .map(|i| (i * 37 + 11) as u8)
        .collect()
}

fn encode_vec(img: &Image<'_>) -> Vec<u8> {
    let mut out = vec![0u8; img.encoded_len().unwrap()];
    let len = encode(img, &mut out).unwrap();
    assert_eq!(len, out.len());
    out
}

/// `bytes` (an image without a fingerprint) re-encoded with one: it decodes to the same hashes and
/// re-encodes to the same bytes; the section is the directory's last.
fn check_round_trip(bytes: &[u8]) {
    let img = decode(bytes).unwrap();
    assert_eq!(img.fingerprint(), None);
    let h = hash();
    let with = encode_vec(&img.with_fingerprint(&h).unwrap());
    assert!(with.len() > bytes.len());
    let back = decode(&with).unwrap();
    assert_eq!(back.fingerprint(), Some(&h[..]));
    assert_eq!(encode_vec(&back), with);
    let secs = sections_of(&with);
    assert_eq!(secs.last().unwrap().0, SectionKind::SpecFingerprint as u16);
    // Everything else is as before: dropping the fingerprint gives the original bytes.
    let without = match back.mode() {
        Mode::PwaFeedback => Image::new_pwa(back.dims(), back.period(), back.pwa_payload()),
        _ => Image::new(back.mode(), back.dims(), back.period(), *back.payload()),
    }
    .unwrap();
    assert_eq!(encode_vec(&without), bytes);
}

#[test]
fn fingerprint_round_trips_in_both_modes() {
    assert_eq!(SPEC_FINGERPRINT_LEN, 8 * SPEC_PARTS.len());
    check_round_trip(&two_partitions().to_bytes().unwrap());
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    for _ in 0..20 {
        check_round_trip(&random_content(&mut rng, 4, 2, 3, 8).to_bytes().unwrap());
    }
}

#[test]
fn with_fingerprint_refuses_a_wrong_length() {
    let bytes = two_partitions().to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    for len in [0, 1, SPEC_FINGERPRINT_LEN - 1, SPEC_FINGERPRINT_LEN + 1] {
        let h = vec![0u8; len];
        assert_eq!(
            img.with_fingerprint(&h).map(|_| ()),
            Err(ImageError::FieldLength {
                field: Field::Fingerprint,
                expected: SPEC_FINGERPRINT_LEN as u32,
                found: len as u32,
            })
        );
    }
}

/// Postcard body of a fingerprint section holding `hash` (a varint length, then the bytes).
fn body(hash: &[u8]) -> Vec<u8> {
    assert!(hash.len() < 128);
    let mut b = vec![hash.len() as u8];
    b.extend_from_slice(hash);
    b
}

#[test]
fn decoder_refuses_a_malformed_fingerprint() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let ff = random_content(&mut rng, 3, 1, 2, 4).to_bytes().unwrap();
    let pwa = two_partitions().to_bytes().unwrap();
    for bytes in [ff, pwa] {
        let secs = sections_of(&bytes);
        let with = |extra: &[(u16, Vec<u8>)]| {
            let mut s: Sections = secs.clone();
            s.extend_from_slice(extra);
            decode(&with_sections(&bytes, &s)).map(|img| img.fingerprint().map(<[u8]>::to_vec))
        };
        let tag = SectionKind::SpecFingerprint as u16;
        // The well-formed section is accepted.
        assert_eq!(with(&[(tag, body(&hash()))]), Ok(Some(hash())));
        // A hash of the wrong length, short or long, or empty.
        for len in [0, 8, SPEC_FINGERPRINT_LEN - 1, SPEC_FINGERPRINT_LEN + 1] {
            assert_eq!(
                with(&[(tag, body(&vec![7u8; len]))]),
                Err(ImageError::FieldLength {
                    field: Field::Fingerprint,
                    expected: SPEC_FINGERPRINT_LEN as u32,
                    found: len as u32,
                }),
                "length {len}"
            );
        }
        // A body that is no postcard byte string, one with trailing bytes, an overlong length prefix.
        assert_eq!(
            with(&[(tag, vec![])]),
            Err(ImageError::Malformed {
                section: SectionKind::SpecFingerprint
            })
        );
        let mut trailing = body(&hash());
        trailing.push(0);
        assert_eq!(
            with(&[(tag, trailing)]),
            Err(ImageError::TrailingBytes {
                section: SectionKind::SpecFingerprint
            })
        );
        let mut overlong = vec![0x80 | SPEC_FINGERPRINT_LEN as u8, 0x00];
        overlong.extend_from_slice(&hash());
        assert_eq!(
            with(&[(tag, overlong)]),
            Err(ImageError::NotCanonical {
                section: SectionKind::SpecFingerprint
            })
        );
        // Twice, and a tag after the last known one (15), which this build does not know.
        assert_eq!(
            with(&[(tag, body(&hash())), (tag, body(&hash()))]),
            Err(ImageError::DuplicateSection {
                kind: SectionKind::SpecFingerprint
            })
        );
        assert_eq!(
            with(&[(15, body(&hash()))]),
            Err(ImageError::UnknownSection { kind: 15 })
        );
    }
}
