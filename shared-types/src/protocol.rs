//! UART protocol between the plant (host) and the firmware: COBS-framed postcard messages carrying a
//! sequence number and the state, answered by the input, a status, the step's cost, the location the
//! input belongs to and, from a firmware with the task's monitor, its bounds and verdict.
//!
//! # Wire format
//! Every message is one frame: the postcard encoding of a [`Request`] (host → firmware) or a [`Reply`]
//! (firmware → host), COBS-encoded, followed by a single `0x00` delimiter. Empty frames (a lone `0x00`) are
//! ignored by the receiver, so a sender may emit one to resynchronise.
//!
//! # Exchange
//! The firmware answers every non-empty frame with exactly one [`Reply`]:
//! - a [`Request::Step`] whose `seq` is the one expected (0 first, then one more after each accepted step) is
//!   evaluated; the reply echoes `seq`;
//! - anything else (not COBS, not postcard, trailing bytes, a non-canonical encoding, a dimension beyond the
//!   capacities, a non-finite state, a frame longer than [`MAX_FRAME`], or a wrong `seq`) is answered with
//!   [`Status::BadFrame`] and changes nothing; the reply's `seq` is the request's own when it could be
//!   decoded, else the sequence number the firmware expects next.
//!
//! [`Request::Shutdown`] ends the session: the firmware exits the emulator with success and sends no reply.
//!
//! # Strictness
//! [`decode_frame`] accepts a frame only if re-encoding the decoded message reproduces it byte for byte.
//! postcard alone ignores trailing bytes and accepts over-long varints; this check rejects both without a
//! hand-written COBS or postcard decoder.
//!
//! No allocation: all buffers are fixed arrays sized from the image capacities.

use crate::capacity::{MAX_M, MAX_N};
use crate::eval::Status;
use core::fmt;
use serde::de::{self, DeserializeOwned, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A vector of at most `N` `f32`, stored inline. Serialised as a postcard sequence (a varint length, then
/// the elements); deserialising more than `N` elements is an error, never a panic or an allocation.
///
/// Hand-written rather than `heapless::Vec`: a `heapless::Vec` is never `Copy` (it implements `Drop`),
/// and the messages built from this type ([`Request`], [`Reply`]) are `Copy` values that the firmware's
/// loop and the host harness pass around. Equality is bitwise (so `NaN == NaN` and `0.0 != -0.0`), which
/// is what "bit for bit" tests want.
#[derive(Clone, Copy)]
pub struct Vector<const N: usize> {
    len: usize,
    data: [f32; N],
}

impl<const N: usize> Vector<N> {
    /// The empty vector.
    pub const fn new() -> Self {
        Self {
            len: 0,
            data: [0.0; N],
        }
    }

    /// A copy of `xs`, or `None` if it is longer than `N`.
    pub fn from_slice(xs: &[f32]) -> Option<Self> {
        let mut v = Self::new();
        v.data.get_mut(..xs.len())?.copy_from_slice(xs);
        v.len = xs.len();
        Some(v)
    }

    /// Append one element; `Err(x)` if full.
    pub fn push(&mut self, x: f32) -> Result<(), f32> {
        match self.data.get_mut(self.len) {
            Some(slot) => {
                *slot = x;
                self.len += 1;
                Ok(())
            }
            None => Err(x),
        }
    }

    /// The elements.
    pub fn as_slice(&self) -> &[f32] {
        // `len <= N` is an invariant of every constructor; `get` keeps the panic path out of the firmware.
        self.data.get(..self.len).unwrap_or(&self.data)
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether every element is finite.
    pub fn is_finite(&self) -> bool {
        self.as_slice().iter().all(|x| x.is_finite())
    }
}

impl<const N: usize> Default for Vector<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> PartialEq for Vector<N> {
    fn eq(&self, other: &Self) -> bool {
        self.len == other.len
            && self
                .as_slice()
                .iter()
                .zip(other.as_slice())
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }
}

impl<const N: usize> Eq for Vector<N> {}

impl<const N: usize> fmt::Debug for Vector<N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl<const N: usize> Serialize for Vector<N> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.as_slice())
    }
}

impl<'de, const N: usize> Deserialize<'de> for Vector<N> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<const N: usize>;
        impl<'de, const N: usize> Visitor<'de> for V<N> {
            type Value = Vector<N>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "a sequence of at most {N} f32")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vector<N>, A::Error> {
                let mut v = Vector::new();
                while let Some(x) = seq.next_element::<f32>()? {
                    if v.push(x).is_err() {
                        return Err(de::Error::invalid_length(N + 1, &self));
                    }
                }
                Ok(v)
            }
        }
        d.deserialize_seq(V::<N>)
    }
}

/// A plant state, at most [`MAX_N`] components.
pub type State = Vector<MAX_N>;
/// A plant input, at most [`MAX_M`] components.
pub type InputVec = Vector<MAX_M>;

/// Host → firmware.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Request {
    /// Evaluate the controller at the sampled state `x`.
    Step {
        /// Sequence number: 0 for the first step, then one more each accepted step (wrapping).
        seq: u32,
        /// The sampled state.
        x: State,
    },
    /// End the session: the firmware exits the emulator with success, without a reply.
    Shutdown,
}

/// Firmware → host: the answer to one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Reply {
    /// The request's sequence number, or the one expected next when the frame could not be decoded.
    pub seq: u32,
    /// What happened.
    #[serde(with = "status_code")]
    pub status: Status,
    /// The input to apply until the next sample: the controller's on `Ok`, the fallback otherwise.
    pub u: InputVec,
    /// Cost of the evaluation in guest instructions (0 when nothing was evaluated).
    pub cost: u32,
    /// The location of the table row the input came from (`Controller::location`): the discrete input
    /// of a plant with forced switching (§4.2.1). 0 for one-location and PWA images.
    pub location: u8,
    /// The task's monitor after this step ([`crate::monitor`]), from a firmware built with one whose
    /// image carries one; `None` otherwise, and for a frame that carried no state.
    pub monitor: Option<MonitorReply>,
}

/// What the monitor says after a step: the running bounds of the robustness at time 0, the verdict, and
/// the cost of the monitor's update alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MonitorReply {
    /// The lower bound's bits (`f32::to_bits`, so that equality is bitwise).
    pub lo: u32,
    /// The upper bound's bits.
    pub hi: u32,
    /// [`crate::monitor::Verdict`] as its code.
    pub verdict: u8,
    /// Cost of the monitor's update in guest instructions.
    pub cost: u32,
}

impl MonitorReply {
    /// The reply of a report and its cost.
    pub fn new(r: &crate::monitor::Report, cost: u32) -> Self {
        Self {
            lo: r.lo.to_bits(),
            hi: r.hi.to_bits(),
            verdict: r.verdict as u8,
            cost,
        }
    }

    /// The lower bound.
    pub fn lo(&self) -> f32 {
        f32::from_bits(self.lo)
    }

    /// The upper bound.
    pub fn hi(&self) -> f32 {
        f32::from_bits(self.hi)
    }
}

/// [`Status`] on the wire: its `#[repr(u8)]` code.
mod status_code {
    use super::Status;
    use serde::{de, Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(s: &Status, ser: S) -> Result<S::Ok, S::Error> {
        ser.serialize_u8(*s as u8)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Status, D::Error> {
        let c = u8::deserialize(d)?;
        Status::from_u8(c).ok_or_else(|| {
            de::Error::invalid_value(de::Unexpected::Unsigned(c.into()), &"a status code 0..=3")
        })
    }
}

/// Largest postcard encoding of a varint-encoded `u32`.
const VARINT_U32_MAX: usize = 5;
/// Largest postcard encoding of a [`Request`]: tag, seq, length (one byte while `MAX_N < 128`), elements.
pub const MAX_REQUEST_LEN: usize = 1 + VARINT_U32_MAX + 1 + 4 * MAX_N;
/// Largest postcard encoding of a [`Reply`]: seq, status, length, elements, cost, location, and the
/// monitor's tag, bounds' bits, verdict and cost.
pub const MAX_REPLY_LEN: usize =
    VARINT_U32_MAX + 1 + 1 + 4 * MAX_M + VARINT_U32_MAX + 1 + 1 + 3 * VARINT_U32_MAX + 1;
const MAX_MESSAGE_LEN: usize = if MAX_REQUEST_LEN > MAX_REPLY_LEN {
    MAX_REQUEST_LEN
} else {
    MAX_REPLY_LEN
};
/// Largest frame, COBS overhead (one byte per 254 started) and the `0x00` delimiter included.
pub const MAX_FRAME: usize = MAX_MESSAGE_LEN + MAX_MESSAGE_LEN.div_ceil(254) + 1;

// The one-byte length prefix assumed above.
const _: () = assert!(MAX_N < 128 && MAX_M < 128);

/// Why a frame was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// Longer than [`MAX_FRAME`].
    Oversize,
    /// Not valid COBS, or not a valid postcard message of the expected type.
    Malformed,
    /// Decodes, but re-encoding does not reproduce the frame (trailing bytes, over-long varints).
    NonCanonical,
}

/// Encode `msg` as one frame (COBS, delimiter included) into `buf`; returns the frame.
pub fn encode_frame<'b, T: Serialize>(
    msg: &T,
    buf: &'b mut [u8],
) -> Result<&'b mut [u8], FrameError> {
    postcard::to_slice_cobs(msg, buf).map_err(|_| FrameError::Oversize)
}

/// Decode one frame (with or without its trailing `0x00`) strictly: see the module doc.
pub fn decode_frame<T: Serialize + DeserializeOwned>(frame: &[u8]) -> Result<T, FrameError> {
    let body = match frame.split_last() {
        Some((0, body)) => body,
        _ => frame,
    };
    // The longest body a valid frame can have is MAX_FRAME - 1 (the delimiter).
    if body.len() >= MAX_FRAME {
        return Err(FrameError::Oversize);
    }
    let mut scratch = [0u8; MAX_FRAME];
    let work = &mut scratch[..body.len()];
    work.copy_from_slice(body);
    let msg: T = postcard::from_bytes_cobs(work).map_err(|_| FrameError::Malformed)?;
    let mut again = [0u8; MAX_FRAME];
    match postcard::to_slice_cobs(&msg, &mut again) {
        Ok(enc) if enc.split_last().map(|(_, b)| b) == Some(body) => Ok(msg),
        _ => Err(FrameError::NonCanonical),
    }
}

/// What one received byte completed.
#[derive(Debug, PartialEq, Eq)]
pub enum FrameEvent<'a> {
    /// A whole non-empty frame (without its delimiter).
    Frame(&'a [u8]),
    /// A frame that exceeded the buffer; its bytes were dropped up to and including the delimiter.
    Oversize,
}

/// Splits a byte stream into frames at `0x00`, with a fixed buffer of `N` bytes (a `heapless::Vec`).
///
/// Hand-written (a dozen lines) rather than postcard's `CobsAccumulator`: after an overflow that one
/// restarts in the middle of the oversize frame and parses its tail as a new message, whereas a frame that
/// overflows must be dropped whole, up to its delimiter, and reported once.
pub struct FrameReader<const N: usize> {
    buf: heapless::Vec<u8, N>,
    /// The frame in `buf` was delivered (or dropped) at its delimiter; cleared at the next byte, so that
    /// the delivered frame can be borrowed until then.
    done: bool,
    overflow: bool,
}

impl<const N: usize> FrameReader<N> {
    /// An empty reader.
    pub const fn new() -> Self {
        Self {
            buf: heapless::Vec::new(),
            done: false,
            overflow: false,
        }
    }

    /// Feed one byte. Returns an event when `byte` is a delimiter that ends a non-empty frame.
    pub fn push(&mut self, byte: u8) -> Option<FrameEvent<'_>> {
        if self.done {
            self.buf.clear();
            self.done = false;
        }
        if byte == 0 {
            self.done = true;
            if core::mem::replace(&mut self.overflow, false) {
                Some(FrameEvent::Oversize)
            } else if self.buf.is_empty() {
                None
            } else {
                Some(FrameEvent::Frame(&self.buf))
            }
        } else {
            // A full buffer refuses the byte: the frame is dropped up to its delimiter.
            if self.overflow || self.buf.push(byte).is_err() {
                self.overflow = true;
            }
            None
        }
    }
}

impl<const N: usize> Default for FrameReader<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// The reader both sides use: room for the largest frame's body.
pub type Reader = FrameReader<{ MAX_FRAME - 1 }>;

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::vec::Vec;

    fn step(seq: u32, x: &[f32]) -> Request {
        Request::Step {
            seq,
            x: State::from_slice(x).unwrap(),
        }
    }

    /// Raw bytes, serialised verbatim (postcard writes a tuple of `u8` as the bytes themselves), so that
    /// hand-made payloads can be COBS-framed with the real encoder.
    struct Raw<'a>(&'a [u8]);
    impl Serialize for Raw<'_> {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            use serde::ser::SerializeTuple;
            let mut t = s.serialize_tuple(self.0.len())?;
            for b in self.0 {
                t.serialize_element(b)?;
            }
            t.end()
        }
    }

    fn frame_raw(raw: &[u8]) -> Vec<u8> {
        let mut buf = [0u8; 256];
        encode_frame(&Raw(raw), &mut buf).unwrap().to_vec()
    }

    /// Feed bytes; `Ok(frame)` per frame, `Err(())` per oversize report.
    fn feed<const N: usize>(r: &mut FrameReader<N>, bytes: &[u8]) -> Vec<Result<Vec<u8>, ()>> {
        let mut out = Vec::new();
        for &b in bytes {
            match r.push(b) {
                Some(FrameEvent::Frame(f)) => out.push(Ok(f.to_vec())),
                Some(FrameEvent::Oversize) => out.push(Err(())),
                None => {}
            }
        }
        out
    }

    #[test]
    fn worst_case_messages_fit_max_frame() {
        let req = step(u32::MAX, &[f32::MAX; MAX_N]);
        let mut buf = [0u8; MAX_FRAME];
        assert!(encode_frame(&req, &mut buf).is_ok());
        let u = InputVec::from_slice(&[f32::MIN; MAX_M]).unwrap();
        let rep = Reply {
            seq: u32::MAX,
            status: Status::ImageRejected,
            u,
            cost: u32::MAX,
            location: 0,
            monitor: Some(MonitorReply {
                lo: u32::MAX,
                hi: u32::MAX,
                verdict: u8::MAX,
                cost: u32::MAX,
            }),
        };
        let mut buf = [0u8; MAX_FRAME];
        assert!(encode_frame(&rep, &mut buf).is_ok());
        // One component more no longer fits the vector, so no valid message is longer.
        assert!(State::from_slice(&[0.0; MAX_N + 1]).is_none());
        assert!(InputVec::from_slice(&[0.0; MAX_M + 1]).is_none());
    }

    #[test]
    fn request_and_reply_round_trip_through_the_reader() {
        let req = step(7, &[1.5, -2.25, f32::MIN_POSITIVE]);
        let mut buf = [0u8; MAX_FRAME];
        let bytes = encode_frame(&req, &mut buf).unwrap().to_vec();
        let frames = feed(&mut Reader::new(), &bytes);
        assert_eq!(frames.len(), 1);
        assert_eq!(
            decode_frame::<Request>(frames[0].as_ref().unwrap()),
            Ok(req)
        );

        let u = InputVec::from_slice(&[-0.0, 3.0]).unwrap();
        let rep = Reply {
            seq: 7,
            status: Status::OutOfEnvelope,
            u,
            cost: 1234,
            location: 0,
            monitor: None,
        };
        let mut buf = [0u8; MAX_FRAME];
        let f = encode_frame(&rep, &mut buf).unwrap();
        assert_eq!(decode_frame::<Reply>(f), Ok(rep));
    }

    #[test]
    fn vector_equality_is_bitwise() {
        let a = InputVec::from_slice(&[f32::NAN]).unwrap();
        assert_eq!(a, a);
        assert_ne!(
            InputVec::from_slice(&[0.0]).unwrap(),
            InputVec::from_slice(&[-0.0]).unwrap()
        );
        assert_ne!(
            InputVec::from_slice(&[]).unwrap(),
            InputVec::from_slice(&[0.0]).unwrap()
        );
    }

    #[test]
    fn empty_frames_are_ignored_and_oversize_is_reported_once_then_resyncs() {
        let mut r = FrameReader::<4>::new();
        let ev = feed(&mut r, &[0, 0, 1, 2, 3, 4, 5, 6, 0, 9, 0]);
        assert_eq!(ev, [Err(()), Ok(std::vec![9])]);
        // Exactly N bytes still fit.
        assert_eq!(feed(&mut r, &[1, 2, 3, 4, 0]), [Ok(std::vec![1, 2, 3, 4])]);
    }

    #[test]
    fn oversize_frame_is_refused_by_decode() {
        assert_eq!(
            decode_frame::<Request>(&[1u8; MAX_FRAME]),
            Err(FrameError::Oversize)
        );
    }

    #[test]
    fn truncated_frames_are_refused() {
        let req = step(3, &[1.0, 2.0, 3.0, 4.0]);
        let mut buf = [0u8; MAX_FRAME];
        let f = encode_frame(&req, &mut buf).unwrap();
        let body = &f[..f.len() - 1];
        for cut in 1..body.len() {
            assert!(
                decode_frame::<Request>(&body[..cut]).is_err(),
                "cut at {cut} accepted"
            );
        }
    }

    #[test]
    fn trailing_bytes_and_long_varints_are_refused() {
        // Step { seq: 1, x: [] } is [tag 0, seq 1, len 0].
        assert_eq!(
            decode_frame::<Request>(&frame_raw(&[0, 1, 0])),
            Ok(step(1, &[]))
        );
        // seq 1 as the over-long varint 0x81 0x00: postcard accepts it, we must not.
        assert_eq!(
            decode_frame::<Request>(&frame_raw(&[0, 0x81, 0x00, 0])),
            Err(FrameError::NonCanonical)
        );
        assert_eq!(
            decode_frame::<Request>(&frame_raw(&[0, 1, 0, 42])),
            Err(FrameError::NonCanonical)
        );
    }

    #[test]
    fn too_many_components_is_malformed_not_a_panic() {
        let mut raw = std::vec![0u8, 0, (MAX_N + 1) as u8];
        raw.extend(std::iter::repeat_n(0x3f, 4 * (MAX_N + 1)));
        assert_eq!(
            decode_frame::<Request>(&frame_raw(&raw)),
            Err(FrameError::Malformed)
        );
    }

    #[test]
    fn unknown_status_code_is_malformed() {
        // seq 1, status 3, u [], cost 0, location 0, no monitor is valid; status 9 is not.
        let ok = Reply {
            seq: 1,
            status: Status::ImageRejected,
            u: InputVec::new(),
            cost: 0,
            location: 0,
            monitor: None,
        };
        assert_eq!(
            decode_frame::<Reply>(&frame_raw(&[1, 3, 0, 0, 0, 0])),
            Ok(ok)
        );
        assert_eq!(
            decode_frame::<Reply>(&frame_raw(&[1, 9, 0, 0, 0, 0])),
            Err(FrameError::Malformed)
        );
    }

    #[test]
    fn seeded_random_bytes_never_panic_and_rarely_decode() {
        let mut rng = ChaCha8Rng::seed_from_u64(0x5eed);
        let mut accepted = 0;
        for _ in 0..20_000 {
            let len = rng.random_range(1..MAX_FRAME + 8);
            let bytes: Vec<u8> = (0..len).map(|_| rng.random_range(1..=255u8)).collect();
            if let Ok(Request::Step { x, .. }) = decode_frame::<Request>(&bytes) {
                assert!(x.len() <= MAX_N);
                accepted += 1;
            }
        }
        // Canonical re-encoding makes accidental acceptance rare.
        assert!(accepted < 100, "{accepted} random frames accepted");
    }

    proptest! {
        #[test]
        fn any_state_round_trips(seq: u32, xs in proptest::collection::vec(any::<f32>(), 0..=MAX_N)) {
            let req = step(seq, &xs);
            let mut buf = [0u8; MAX_FRAME];
            let f = encode_frame(&req, &mut buf).unwrap();
            prop_assert!(f[..f.len() - 1].iter().all(|&b| b != 0));
            prop_assert_eq!(decode_frame::<Request>(f), Ok(req));
        }

        #[test]
        fn any_byte_string_is_handled(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = decode_frame::<Request>(&bytes);
            let _ = decode_frame::<Reply>(&bytes);
            let mut r = Reader::new();
            for b in bytes {
                if let Some(FrameEvent::Frame(f)) = r.push(b) {
                    prop_assert!(f.len() < MAX_FRAME);
                    prop_assert!(f.iter().all(|&b| b != 0));
                }
            }
        }
    }
}
