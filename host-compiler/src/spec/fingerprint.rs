//! The spec fingerprint an image stores (its optional `SpecFingerprint` section): per part of the spec
//! ([`SPEC_PARTS`]: `[plant]`, `[init]`, `[goal]`, `[unsafe]`, `[input]`, `horizon`, `[mtl]` with
//! `[sets]`, `[synthesis]` with `seed`, the other top-level keys, and the whole spec) the first
//! [`SPEC_HASH_LEN`] bytes of the SHA-256 of the part's canonical form. The canonical form is built from
//! the *parsed* TOML: table keys sorted, numbers by value (an integer exactly representable as f64 is the
//! float of the same value, −0 is 0), strings by their bytes, with type tags and lengths so that no two
//! values share an encoding. Comments, whitespace, key order and the spelling of a number (`5`, `5.0`,
//! `5e0`) do not change it; any change of a value does. `verify` and `simulate` refuse an image whose
//! fingerprint differs from the spec's and name the parts that changed.

use sha2::{Digest, Sha256};
use shared_types::image::{SPEC_FINGERPRINT_LEN, SPEC_HASH_LEN, SPEC_PARTS};
use toml::Value;

use super::error::SpecError;

/// The top-level keys of each part of [`SPEC_PARTS`] before `other` (index 8) and `spec` (index 9).
const PART_KEYS: [&[&str]; 8] = [
    &["plant"],
    &["init"],
    &["goal"],
    &["unsafe"],
    &["input"],
    &["horizon"],
    &["mtl", "sets"],
    &["synthesis", "seed"],
];
/// Index of the part that holds every top-level key [`PART_KEYS`] does not list.
const OTHER: usize = PART_KEYS.len();
/// Index of the whole-spec hash.
const WHOLE: usize = OTHER + 1;
const _: () = assert!(WHOLE + 1 == SPEC_PARTS.len());

/// The hashes of a spec's parts, in [`SPEC_PARTS`] order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpecFingerprint(pub [u8; SPEC_FINGERPRINT_LEN]);

impl SpecFingerprint {
    /// The fingerprint of spec text (a leading byte-order mark is ignored, as the spec parser does).
    /// Fails only on text that is not TOML.
    pub fn of(src: &str) -> Result<Self, SpecError> {
        let src = src.strip_prefix('\u{feff}').unwrap_or(src);
        let table: toml::Table = toml::from_str(src).map_err(|e| SpecError::from_toml(&e))?;
        Ok(Self::of_table(&table))
    }

    /// The fingerprint of a parsed spec.
    pub fn of_table(table: &toml::Table) -> Self {
        let mut out = [0u8; SPEC_FINGERPRINT_LEN];
        let listed = |k: &str| PART_KEYS.iter().any(|p| p.contains(&k));
        for (i, slot) in out.chunks_exact_mut(SPEC_HASH_LEN).enumerate() {
            let keep = |k: &str| match i {
                OTHER => !listed(k),
                WHOLE => true,
                _ => PART_KEYS.get(i).is_some_and(|p| p.contains(&k)),
            };
            let mut h = Sha256::new();
            // The part's name first, so that equal contents of two parts hash differently.
            bytes(
                &mut h,
                b'n',
                SPEC_PARTS.get(i).map_or(&b""[..], |s| s.as_bytes()),
            );
            table_entries(&mut h, table.iter().filter(|(k, _)| keep(k)));
            slot.copy_from_slice(&h.finalize()[..SPEC_HASH_LEN]);
        }
        SpecFingerprint(out)
    }

    /// The fingerprint an image stores; `None` for a slice of another length.
    pub fn from_bytes(b: &[u8]) -> Option<Self> {
        b.try_into().ok().map(SpecFingerprint)
    }

    /// The bytes as stored.
    pub fn as_bytes(&self) -> &[u8] {
        &self.0
    }

    /// The hash of part `i` of [`SPEC_PARTS`] (empty out of range).
    pub fn part(&self, i: usize) -> &[u8] {
        self.0
            .get(i * SPEC_HASH_LEN..(i + 1) * SPEC_HASH_LEN)
            .unwrap_or(&[])
    }

    /// The names ([`SPEC_PARTS`]) of the parts whose hashes differ from `other`'s, the whole spec last;
    /// empty when the fingerprints are equal.
    pub fn changed(&self, other: &SpecFingerprint) -> Vec<&'static str> {
        SPEC_PARTS
            .iter()
            .enumerate()
            .filter(|&(i, _)| self.part(i) != other.part(i))
            .map(|(_, &name)| name)
            .collect()
    }

    /// Part `i` as lowercase hex (for `inspect`).
    pub fn hex(&self, i: usize) -> String {
        self.part(i).iter().map(|b| format!("{b:02x}")).collect()
    }
}

/// A tagged byte string: the tag, the length (u64 little-endian), the bytes.
fn bytes(h: &mut Sha256, tag: u8, b: &[u8]) {
    h.update([tag]);
    h.update((b.len() as u64).to_le_bytes());
    h.update(b);
}

/// A table's entries in key order: a count, then per entry the key and its value.
fn table_entries<'a>(h: &mut Sha256, entries: impl Iterator<Item = (&'a String, &'a Value)>) {
    let mut e: Vec<(&String, &Value)> = entries.collect();
    e.sort_by(|a, b| a.0.cmp(b.0));
    h.update([b't']);
    h.update((e.len() as u64).to_le_bytes());
    for (k, v) in e {
        bytes(h, b'k', k.as_bytes());
        value(h, v);
    }
}

/// One item of the canonical walk: a value still to encode, or a key to write before its value.
enum Item<'a> {
    Value(&'a Value),
    Key(&'a str),
}

/// The canonical encoding of `v`, walked with an explicit stack (no recursion, whatever the nesting).
fn value(h: &mut Sha256, v: &Value) {
    let mut stack = vec![Item::Value(v)];
    while let Some(item) = stack.pop() {
        let v = match item {
            Item::Key(k) => {
                bytes(h, b'k', k.as_bytes());
                continue;
            }
            Item::Value(v) => v,
        };
        match v {
            Value::String(s) => bytes(h, b's', s.as_bytes()),
            Value::Integer(i) => {
                let f = *i as f64;
                if f.abs() <= 9_007_199_254_740_992.0 {
                    number(h, f);
                } else {
                    h.update([b'i']);
                    h.update(i.to_le_bytes());
                }
            }
            Value::Float(f) => number(h, *f),
            Value::Boolean(b) => h.update([b'b', u8::from(*b)]),
            Value::Datetime(d) => bytes(h, b'd', d.to_string().as_bytes()),
            Value::Array(a) => {
                h.update([b'a']);
                h.update((a.len() as u64).to_le_bytes());
                stack.extend(a.iter().rev().map(Item::Value));
            }
            Value::Table(t) => {
                let mut e: Vec<(&String, &Value)> = t.iter().collect();
                e.sort_by(|a, b| a.0.cmp(b.0));
                h.update([b't']);
                h.update((e.len() as u64).to_le_bytes());
                for (k, v) in e.into_iter().rev() {
                    stack.push(Item::Value(v));
                    stack.push(Item::Key(k));
                }
            }
        }
    }
}

/// A number by value: −0 as 0, every NaN as one NaN.
fn number(h: &mut Sha256, f: f64) {
    let f = if f == 0.0 {
        0.0
    } else if f.is_nan() {
        f64::NAN
    } else {
        f
    };
    h.update([b'f']);
    h.update(f.to_bits().to_le_bytes());
}
