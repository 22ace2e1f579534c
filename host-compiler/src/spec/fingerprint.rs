//! The spec fingerprint an image stores (its optional `SpecFingerprint` section): per part of the spec
//! ([`SPEC_PARTS`]: `[plant]`, `[init]`, `[goal]`, `[unsafe]`, `[input]`, `horizon`, `[mtl]` with
//! `[sets]`, `[synthesis]` with `seed`, the other top-level keys, and the whole spec) the first
//! [`SPEC_HASH_LEN`] bytes of the SHA-256 of the part's canonical form. The canonical form is built from
//! the *parsed* TOML: table keys sorted, numbers by value (an integer exactly representable as f64 is the
//! float of the same value, −0 is 0), strings by their bytes, with type tags and lengths so that no two
//! values share an encoding. Comments, whitespace, key order and the spelling of a number (`5`, `5.0`,
//! `5e0`) do not change it; any change of a value does. `verify` and `simulate` refuse an image whose
//! fingerprint differs from the spec's and name the parts that changed.

use serde::de::{Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use sha2::{Digest, Sha256};
use shared_types::image::{SPEC_FINGERPRINT_LEN, SPEC_HASH_LEN, SPEC_PARTS};

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
        let top: Value = toml::from_str(src).map_err(|e| SpecError::from_toml(&e))?;
        let Value::Map(table) = top else {
            return Err(SpecError::new(
                super::ErrorKind::Syntax,
                "a spec is a TOML table".to_string(),
            ));
        };
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
            let part: Vec<(String, Value)> = table
                .iter()
                .filter(|(k, _)| keep(k))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect();
            value(&mut h, &Value::Map(part));
            slot.copy_from_slice(&h.finalize()[..SPEC_HASH_LEN]);
        }
        Ok(SpecFingerprint(out))
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
            Value::Str(s) => bytes(h, b's', s.as_bytes()),
            Value::Int(i) => {
                if i.unsigned_abs() <= 1 << 53 {
                    number(h, *i as f64);
                } else {
                    h.update([b'i']);
                    h.update(i.to_le_bytes());
                }
            }
            Value::Float(f) => number(h, *f),
            Value::Bool(b) => h.update([b'b', u8::from(*b)]),
            Value::Seq(a) => {
                h.update([b'a']);
                h.update((a.len() as u64).to_le_bytes());
                stack.extend(a.iter().rev().map(Item::Value));
            }
            Value::Map(t) => {
                let mut e: Vec<&(String, Value)> = t.iter().collect();
                e.sort_by(|a, b| a.0.cmp(&b.0));
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

/// A parsed TOML value as the fingerprint sees it: integers of the whole u64 and i64 ranges (a `seed` may
/// exceed `i64::MAX`, which `toml::Value` cannot hold), tables as key–value lists (a datetime arrives as
/// the deserializer's one-key table, which encodes it faithfully).
#[derive(Clone, Debug)]
enum Value {
    Str(String),
    Int(i128),
    Float(f64),
    Bool(bool),
    Seq(Vec<Value>),
    Map(Vec<(String, Value)>),
}

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_any(ValueVisitor)
    }
}

struct ValueVisitor;

impl<'de> Visitor<'de> for ValueVisitor {
    type Value = Value;
    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a TOML value")
    }
    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Bool(v))
    }
    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::Int(v.into()))
    }
    fn visit_u64<E>(self, v: u64) -> Result<Value, E> {
        Ok(Value::Int(v.into()))
    }
    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(Value::Float(v))
    }
    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::Str(v.to_string()))
    }
    fn visit_string<E>(self, v: String) -> Result<Value, E> {
        Ok(Value::Str(v))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut a: A) -> Result<Value, A::Error> {
        let mut v = Vec::new();
        while let Some(x) = a.next_element()? {
            v.push(x);
        }
        Ok(Value::Seq(v))
    }
    fn visit_map<A: MapAccess<'de>>(self, mut a: A) -> Result<Value, A::Error> {
        let mut v = Vec::new();
        while let Some((k, x)) = a.next_entry::<String, Value>()? {
            v.push((k, x));
        }
        Ok(Value::Map(v))
    }
}
