//! The controller image: its byte layout, the content types, `encode` and the validating, zero-copy
//! `decode` (DESIGN §5).
//!
//! # Layout
//! An image is a fixed 32-byte little-endian header, a directory of typed sections, then the sections.
//!
//! | bytes  | field                                                                          |
//! |--------|--------------------------------------------------------------------------------|
//! | 0..4   | [`MAGIC`]                                                                      |
//! | 4..6   | format version, [`FORMAT_VERSION`]                                             |
//! | 6      | mode ([`Mode`])                                                                |
//! | 7      | reserved, 0                                                                    |
//! | 8..18  | `n`, `m`, locations, trajectories, partitions (five `u16`)                     |
//! | 18..20 | number of sections in the directory (`u16`)                                    |
//! | 20..24 | sample period in seconds (`f32`)                                               |
//! | 24..28 | payload length: bytes after the header, directory and sections (`u32`)          |
//! | 28..32 | CRC-32/ISO-HDLC of header bytes 0..28 followed by everything after the header (`u32`) |
//!
//! The CRC is seeded with the header's first 28 bytes so that a corrupted period or dimension is caught as
//! surely as a corrupted payload byte.
//!
//! The directory follows the header: one 12-byte entry per section, `kind` (`u16`, a [`SectionKind`]
//! tag), `flags` (`u16`, reserved, 0), `offset` (`u32`, from the start of the image) and `length` (`u32`).
//! The sections follow the directory back to back, in directory order, and end at the end of the image;
//! kinds strictly increase along the directory. Each section body is the postcard encoding of its content
//! struct. Every float array is a byte string of little-endian `f32` values (row-major matrices), borrowed
//! in place by [`decode`], so decoding neither copies nor allocates. Postcard encodings are canonical here:
//! `decode` rejects a section whose re-encoding would not have exactly its length (overlong varints), and
//! the placement rules leave no choice of offsets, so one content has exactly one byte string.
//!
//! | tag | kind ([`SectionKind`])  | content                    | modes       |
//! |-----|-------------------------|----------------------------|-------------|
//! | 1   | `Locations`             | [`LocationsSection`]       | both        |
//! | 2   | `Fallback`              | [`FallbackSection`]        | both        |
//! | 3   | `Trajectories`          | [`TrajectoriesSection`]    | feedforward |
//! | 4   | `Segments`              | [`SegmentsSection`]        | feedforward |
//! | 5   | `Steps`                 | [`StepsSection`]           | feedforward |
//! | 6   | `PwaLaws`               | [`crate::pwa::PwaLaws`]    | PWA         |
//! | 7   | `PwaTree`               | [`crate::pwa::PwaTree`]    | PWA         |
//! | 8   | `PwaBalls`              | [`crate::pwa::PwaBalls`]   | PWA         |
//! | 9   | `SegmentExits`          | [`SegmentExitsSection`]    | feedforward, optional |
//! | 10  | `ModelMaps`             | raw, [`crate::maps`]       | feedforward, optional |
//! | 11  | `TerminalLaw`           | raw, [`crate::terminal`]   | both, optional, not with model maps |
//! | 12  | `SpecFingerprint`       | [`SpecFingerprintSection`] | both, optional |
//! | 13  | `SelectionTest`         | raw, [`crate::selection`]  | feedforward with model maps, optional |
//! | 14  | `Monitor`               | raw, [`crate::monitor`]    | both, optional |
//!
//! Every section a mode lists is required, exactly once; a known section of the other mode is refused.
//! Two bodies are not postcard. The model maps section's layout is [`crate::maps`]'s (two model
//! programs, which must keep their constant pools aligned), and with it the fallback and the input box are
//! in the plant's input space (`m_plant` values) and a linear fallback is refused. The terminal law's is a
//! fixed run of f32 values ([`crate::terminal`]), which decodes with one length check. So is the
//! selection test's ([`crate::selection`]), which only an image with model maps may carry.
//! The spec fingerprint is [`SPEC_FINGERPRINT_LEN`] bytes: per part of the spec ([`SPEC_PARTS`], in
//! that order) a hash of [`SPEC_HASH_LEN`] bytes that the host computes; the firmware only checks its
//! length.
//! **Growth.** Later issues add sections (guards and resets, model programs for nonlinear plants,
//! controller states) under new tags, without changing these. A decoder that meets a tag it does not know
//! refuses the image ([`ImageError::UnknownSection`]) rather than skipping the section: the certificate may
//! rest on it, and a firmware that cannot evaluate it cannot run what was certified. (The reserved flags
//! leave room to mark a future section as safely ignorable.)
//!
//! # Feedforward content (Algorithm 2, with the law (3.5)–(3.6))
//! * per location ℓ: the gain `K_ℓ` (m×n) and the CAF metric `P_ℓ` (n×n, symmetric positive definite);
//! * per trajectory i: the ball centre `x̃_i(0)`, its radius `δ_i` in the metric of `P_ℓ` of the location
//!   of its first segment, and a run of segments (`seg_end`, exclusive, `u16` per trajectory);
//! * per segment s: a record of [`SEGMENT_RECORD_LEN`] bytes, first row (`u32`), number of rows (`u32`)
//!   and location ℓ (`u8`): the rows of the step table the trajectory runs through in location ℓ.
//!   Segments tile the step table in order (each starts where the previous ends, none is empty) and each is
//!   a maximal run of one location within its trajectory, so a trajectory of a single-location plant is one
//!   segment and a hybrid run ((4.41)–(4.42)) has one segment per visited location;
//! * the step table: row κ of trajectory i holds `v_i(κ) = ũ_i(κ) − K_ℓ x̃_i(κ)` (m values);
//! * the fallback law (hold, zero, linear, or a constant input inside the input box), an optional input
//!   box, and the terminal behaviour past the end of a trajectory.
//!
//! # PWA-feedback content (Ch. 6, the law (6.1) on the envelope F of (6.2))
//! * per location ℓ: `K_ℓ` and `P_ℓ` as above (`P_ℓ` is the metric of the certified balls; `K_ℓ` is the CAF
//!   gain the laws were learned around, kept so that `θ_j = K_j − K` can be reported);
//! * the [`crate::pwa::PwaTables`] in three sections: per partition the full gain `K_j = K + θ_j` and offset
//!   `θ0_j`; the point-location tree and its leaves; the certified balls (centre; whitened centre and
//!   squared threshold, one record per ball) with per location the upper-triangular factor `R_ℓ` of `P_ℓ`
//!   used by the whitened ball test (layout, rationale and rounding analysis in [`crate::pwa`]);
//! * the fallback law and an optional input box. There are no trajectories (`trajectories = 0` in the
//!   header) and no terminal behaviour.
//!
//! # Validation
//! [`decode`] checks, before anything can read the data: magic, version, reserved byte, payload length,
//! CRC, mode, dimensions against [`crate::capacity`]; the directory
//! (1..=[`crate::capacity::MAX_SECTIONS`] entries, flags
//! zero, sections back to back without gap, overlap or unclaimed byte, kinds strictly increasing, every kind
//! known and belonging to the mode, every required kind present); each section canonical postcard filling
//! its section exactly. [`decode`], [`Image::new`] and [`Image::new_pwa`] then check the content: every
//! field's byte length, every float finite, `P` symmetric and positive definite, `δ ≥ 0`, trajectory
//! segment ends strictly increasing with at most [`MAX_SEGMENTS`] segments, a constant fallback input inside
//! the input box, segments tiling the step table
//! (non-empty, each starting where the previous ends, total rows within [`max_rows`]`(m)` and equal to the
//! table's), segment locations in range and maximal within their trajectory, and the input box non-empty;
//! for PWA images also everything listed in [`crate::pwa`] (tree well-formed and within depth, indices in
//! range, stored depth exact). An [`Image`] can only be obtained through them, so its accessors never meet
//! bad data.
#![allow(non_snake_case)]

use serde::{Deserialize, Serialize};

use crate::capacity::{
    max_rows, HEADER_LEN, MAX_LOCATIONS, MAX_M, MAX_N, MAX_PARTITIONS, MAX_SEGMENTS,
    MAX_TRAJECTORIES,
};
pub use crate::error::{Dim, Field, ImageError, ModelMap, Pos};
pub use crate::header::{
    compute_crc, image_len, write_image, DirEntry, Directory, Header, RawSection, SectionWrite,
};
pub use crate::layout::{
    exit_record_len, Dims, Mode, SectionKind, EXIT_GUARD, EXIT_TABLE, FORMAT_VERSION, MAGIC,
    SEGMENT_RECORD_LEN, SPEC_FINGERPRINT_LEN, SPEC_HASH_LEN, SPEC_PARTS,
};
pub use crate::maps::ModelMaps;
use crate::pwa::{node_child, node_value, Child, PwaBalls, PwaLaws, PwaTables, PwaTree, Region};
use crate::raw::{
    check_dim, check_finite, check_len, div, f32_at, f32_span, floats, positive_definite, rem,
    sat16, sat32, u16_le, u32_at_byte,
};
use crate::selection::SelectionTest;
use crate::terminal::TerminalLaw;

/// What the controller does once the active trajectory's table is exhausted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Terminal {
    /// Keep applying the feedback with the last row: `u = K_ℓ x + v_i(last)`.
    HoldLast,
    /// Apply the image's [`Fallback`].
    Fallback,
}

/// The image's fallback law, applied by the firmware whenever the answer is not `Ok` (and past the end of
/// the table if [`Terminal::Fallback`]). Float arrays are little-endian `f32` bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Fallback<'a> {
    /// Keep the last applied input.
    Hold,
    /// Apply zero input.
    Zero,
    /// Backup linear law `u = K_fb (x − x_ref) + u_ref`, saturated to the input box if one is stored.
    Linear {
        /// `K_fb`, m×n row-major.
        K: &'a [u8],
        /// `x_ref`, n values.
        x_ref: &'a [u8],
        /// `u_ref`, m values.
        u_ref: &'a [u8],
    },
    /// A constant input, whatever the state (for a spec whose input set excludes 0: the host stores a
    /// point of the input set). Validated finite and inside the input box when one is stored.
    Constant {
        /// `u`, m values.
        u: &'a [u8],
    },
}

/// Componentwise input bounds `lo ≤ u ≤ hi` (m values each, little-endian `f32`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputBox<'a> {
    /// Lower bounds.
    pub lo: &'a [u8],
    /// Upper bounds.
    pub hi: &'a [u8],
}

/// The feedforward content, as raw borrowed byte strings. Fill it to build an image, then pass it to
/// [`Image::new`], which validates it; nothing reads a `Payload` that has not been validated. [`encode`]
/// stores it as the sections `Locations`, `Fallback`, `Trajectories`, `Segments` and `Steps`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Payload<'a> {
    /// `K_ℓ` for each location ℓ: locations × m × n values, each m×n block row-major.
    pub K: &'a [u8],
    /// `P_ℓ` for each location ℓ: locations × n × n values.
    pub P: &'a [u8],
    /// Exclusive end of each trajectory's run of segments (`u16` little-endian, one per trajectory).
    /// Trajectory i owns segments `seg_end[i-1]..seg_end[i]` (with `seg_end[-1] = 0`).
    pub seg_end: &'a [u8],
    /// Ball centres `x̃_i(0)`: trajectories × n values.
    pub centre: &'a [u8],
    /// Ball radii `δ_i`: one value per trajectory.
    pub delta: &'a [u8],
    /// Segment records (module doc): per segment first row (`u32`), rows (`u32`), location (`u8`).
    pub segment: &'a [u8],
    /// Step table `v`: rows × m values.
    pub v: &'a [u8],
    /// Fallback law.
    pub fallback: Fallback<'a>,
    /// Optional input box, used to saturate the linear fallback.
    pub input_box: Option<InputBox<'a>>,
    /// Behaviour past the end of a trajectory.
    pub terminal: Terminal,
    /// Segment exits ([`crate::layout::exit_record_len`] bytes per segment), or empty: every segment then
    /// ends with its table. Stored as the optional `SegmentExits` section.
    pub exits: &'a [u8],
}

/// The content of a PWA-feedback image (mode 2), as raw borrowed byte strings. Build one and pass it to
/// [`Image::new_pwa`], which validates it. [`encode`] stores it as the sections `Locations`, `Fallback`,
/// `PwaLaws`, `PwaTree` and `PwaBalls`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PwaPayload<'a> {
    /// `K_ℓ` for each location ℓ (the CAF gain; not used by the evaluator in this mode).
    pub K: &'a [u8],
    /// `P_ℓ` for each location ℓ: the metric of the certified balls.
    pub P: &'a [u8],
    /// Laws, tree, leaves and balls.
    pub tables: PwaTables<'a>,
    /// Fallback law.
    pub fallback: Fallback<'a>,
    /// Optional input box, used to saturate the linear fallback.
    pub input_box: Option<InputBox<'a>>,
}

/// One segment of the feedforward table, as [`Image::segment`] reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Segment {
    /// Location ℓ whose `K_ℓ` the rows use.
    pub location: usize,
    /// First row of the step table.
    pub first_row: usize,
    /// Number of rows (≥ 1).
    pub len: usize,
}

impl Segment {
    /// The record of this segment as stored (first row, rows, location); `None` if a value does not fit.
    pub fn record(&self) -> Option<[u8; SEGMENT_RECORD_LEN]> {
        let first = u32::try_from(self.first_row).ok()?.to_le_bytes();
        let len = u32::try_from(self.len).ok()?.to_le_bytes();
        let loc = u8::try_from(self.location).ok()?;
        let mut r = [0u8; SEGMENT_RECORD_LEN];
        r[0..4].copy_from_slice(&first);
        r[4..8].copy_from_slice(&len);
        r[8] = loc;
        Some(r)
    }
}

/// Segment record `s` of `bytes` (total: missing bytes read as 0).
fn segment_at(bytes: &[u8], s: usize) -> Segment {
    let o = s.saturating_mul(SEGMENT_RECORD_LEN);
    Segment {
        first_row: u32_at_byte(bytes, o) as usize,
        len: u32_at_byte(bytes, o.saturating_add(4)) as usize,
        location: bytes.get(o.saturating_add(8)).copied().unwrap_or(0) as usize,
    }
}

// ---------------------------------------------------------------------------------------------------------
// Sections: the postcard content of each kind.

/// The `Locations` section: `K_ℓ` and `P_ℓ` per location (see [`Payload::K`], [`Payload::P`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LocationsSection<'a> {
    /// `K_ℓ`, locations × m × n values.
    pub K: &'a [u8],
    /// `P_ℓ`, locations × n × n values.
    pub P: &'a [u8],
}

/// The `Fallback` section: the fallback law and the optional input box.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FallbackSection<'a> {
    /// Fallback law.
    #[serde(borrow)]
    pub fallback: Fallback<'a>,
    /// Optional input box.
    #[serde(borrow)]
    pub input_box: Option<InputBox<'a>>,
}

/// The `Trajectories` section: terminal behaviour, and per trajectory its segment run and its ball.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TrajectoriesSection<'a> {
    /// Behaviour past the end of a trajectory.
    pub terminal: Terminal,
    /// See [`Payload::seg_end`].
    pub seg_end: &'a [u8],
    /// See [`Payload::centre`].
    pub centre: &'a [u8],
    /// See [`Payload::delta`].
    pub delta: &'a [u8],
}

/// The `Segments` section: the segment records (see [`Payload::segment`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SegmentsSection<'a> {
    /// Segment records.
    pub segment: &'a [u8],
}

/// The optional `SegmentExits` section (see [`Payload::exits`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SegmentExitsSection<'a> {
    /// Exit records.
    pub exit: &'a [u8],
}

/// The optional `SpecFingerprint` section: [`SPEC_FINGERPRINT_LEN`] bytes, one hash of
/// [`SPEC_HASH_LEN`] bytes per part of [`SPEC_PARTS`] in that order (see [`Image::fingerprint`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SpecFingerprintSection<'a> {
    /// The hashes, back to back.
    pub hash: &'a [u8],
}

/// How a segment ends, as [`Image::exit`] reads it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exit<'a> {
    /// With its table: the next segment starts when the row passes the segment's last.
    Table,
    /// When fl(Σⱼ âⱼx̂ⱼ − b̂) ≤ −θ at a sample (`a` is n little-endian `f32`): the next segment starts at
    /// that sample, row 0.
    Guard {
        /// â.
        a: &'a [u8],
        /// b̂.
        b: f32,
        /// θ ≥ 0.
        theta: f32,
        /// The next segment's nominal start (n little-endian `f32`), for re-proving its certificate.
        next: &'a [u8],
    },
}

/// The `Steps` section: the step table `v` (see [`Payload::v`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct StepsSection<'a> {
    /// Rows × m values.
    pub v: &'a [u8],
}

/// A section whose body is the postcard encoding of `content`, for [`write_image`]. `kind` is a
/// [`SectionKind`] tag (any `u16`, so that tests can write kinds this build does not know).
#[derive(Clone, Copy, Debug)]
pub struct PostcardSection<T> {
    /// Kind tag.
    pub kind: u16,
    /// Content.
    pub content: T,
}

impl<T: Serialize> PostcardSection<T> {
    /// A section of a known kind.
    pub fn new(kind: SectionKind, content: T) -> Self {
        PostcardSection {
            kind: kind as u16,
            content,
        }
    }
}

impl<T: Serialize> SectionWrite for PostcardSection<T> {
    fn kind(&self) -> u16 {
        self.kind
    }
    fn encoded_len(&self) -> Result<usize, ImageError> {
        postcard::serialize_with_flavor(&self.content, postcard::ser_flavors::Size::default())
            .map_err(|_| ImageError::Encode)
    }
    fn write(&self, out: &mut [u8]) -> Result<usize, ImageError> {
        postcard::to_slice(&self.content, out)
            .map(|w| w.len())
            .map_err(|_| ImageError::Encode)
    }
}

/// Parses the body of the section of `kind` of a parsed directory: postcard that must fill the section
/// exactly and be in canonical form.
fn parse_section<'a, T: Serialize + Deserialize<'a>>(
    dir: &Directory<'a>,
    kind: SectionKind,
) -> Result<T, ImageError> {
    let bytes = dir
        .section(kind)
        .ok_or(ImageError::MissingSection { kind })?;
    let (content, rest): (T, &[u8]) =
        postcard::take_from_bytes(bytes).map_err(|_| ImageError::Malformed { section: kind })?;
    if !rest.is_empty() {
        return Err(ImageError::TrailingBytes { section: kind });
    }
    let canonical =
        postcard::serialize_with_flavor(&content, postcard::ser_flavors::Size::default())
            .map_err(|_| ImageError::Malformed { section: kind })?;
    if canonical != bytes.len() {
        return Err(ImageError::NotCanonical { section: kind });
    }
    Ok(content)
}

// ---------------------------------------------------------------------------------------------------------
// Validation.

/// The header dimensions each mode allows: feedforward images have trajectories and no partitions, PWA
/// images partitions and no trajectories.
fn check_dims(mode: Mode, d: Dims) -> Result<(), ImageError> {
    check_dim(Dim::N, d.n, 1, MAX_N)?;
    check_dim(Dim::M, d.m, 1, MAX_M)?;
    check_dim(Dim::Locations, d.n_locations, 1, MAX_LOCATIONS)?;
    match mode {
        Mode::Feedforward => {
            check_dim(Dim::Trajectories, d.n_trajectories, 1, MAX_TRAJECTORIES)?;
            check_dim(Dim::Partitions, d.n_partitions, 0, 0)
        }
        Mode::PwaFeedback => {
            check_dim(Dim::Trajectories, d.n_trajectories, 0, 0)?;
            check_dim(Dim::Partitions, d.n_partitions, 1, MAX_PARTITIONS)
        }
    }
}

/// `maps`: the validated model maps, if the image has them (the fallback and the input box are then in
/// the plant's input space, and a linear fallback is refused).
fn validate(
    mode: Mode,
    dims: Dims,
    period: f32,
    p: &Payload<'_>,
    maps: Option<&ModelMaps<'_>>,
) -> Result<(), ImageError> {
    if mode != Mode::Feedforward {
        return Err(ImageError::UnsupportedMode { mode });
    }
    check_dims(mode, dims)?;
    if !(period.is_finite() && period > 0.0) {
        return Err(ImageError::BadPeriod);
    }
    let Dims {
        n,
        m,
        n_locations: nl,
        n_trajectories: nt,
        ..
    } = dims;
    // From here on all products are bounded by the capacities and cannot overflow. The clamps change
    // nothing (checked just above) but let the compiler see that no division below is by zero.
    let (n, m) = (n.clamp(1, MAX_N), m.clamp(1, MAX_M));
    let nt = nt.min(MAX_TRAJECTORIES);
    validate_K_P(n, m, nl, p.K, p.P)?;

    // Trajectory segment ends: strictly increasing (no trajectory without segments), within capacity.
    check_len(Field::TrajEnd, p.seg_end, 2 * nt)?;
    let mut prev = 0u16;
    for t in 0..nt {
        let e = u16_le(p.seg_end, t);
        if e <= prev {
            return Err(ImageError::TrajectoryEnds {
                trajectory: sat16(t),
            });
        }
        if e as usize > MAX_SEGMENTS {
            return Err(ImageError::DimOutOfRange {
                dim: Dim::Segments,
                value: e as u32,
                min: 1,
                max: sat32(MAX_SEGMENTS),
            });
        }
        prev = e;
    }
    let n_seg = prev as usize;

    // Segments: they tile the step table in order, each a maximal run of one location of its trajectory.
    check_len(Field::Segment, p.segment, SEGMENT_RECORD_LEN * n_seg)?;
    let mut rows = 0usize;
    let mut s0 = 0usize;
    for t in 0..nt {
        let s1 = u16_le(p.seg_end, t) as usize;
        let traj_first_row = rows;
        for s in s0..s1 {
            let seg = segment_at(p.segment, s);
            if seg.len == 0 || seg.first_row != rows {
                return Err(ImageError::SegmentRows { segment: sat16(s) });
            }
            if seg.location >= nl {
                return Err(ImageError::LocationOutOfRange {
                    trajectory: sat16(t),
                    step: sat16(rows - traj_first_row),
                    value: seg.location as u8,
                });
            }
            if s > s0 && segment_at(p.segment, s - 1).location == seg.location {
                return Err(ImageError::SegmentNotMaximal { segment: sat16(s) });
            }
            rows = rows.saturating_add(seg.len);
            if rows > max_rows(m) {
                return Err(ImageError::DimOutOfRange {
                    dim: Dim::Steps,
                    value: sat32(rows),
                    min: 1,
                    max: sat32(max_rows(m)),
                });
            }
        }
        s0 = s1;
    }

    // Segment exits (optional): kinds known, floats finite (zero for a table exit), θ ≥ 0, no guard exit
    // on a trajectory's last segment.
    if !p.exits.is_empty() {
        let rec = crate::layout::exit_record_len(n);
        check_len(Field::Exit, p.exits, rec * n_seg)?;
        let mut s0 = 0usize;
        for t in 0..nt {
            let s1 = u16_le(p.seg_end, t) as usize;
            for s in s0..s1 {
                let kind = u32_at_byte(p.exits, s * rec);
                let vals = f32_span(p.exits, s * (2 * n + 3) + 1, 2 * n + 2);
                let finite = floats(vals).all(|v| v.is_finite());
                let theta = f32_at(vals, n + 1);
                let ok = match kind {
                    // Zeros only, so that one content has one encoding.
                    crate::layout::EXIT_TABLE => floats(vals).all(|v| v.to_bits() == 0),
                    crate::layout::EXIT_GUARD => finite && theta >= 0.0 && s + 1 < s1,
                    _ => false,
                };
                if !ok {
                    return Err(ImageError::BadExit { segment: sat16(s) });
                }
            }
            s0 = s1;
        }
    }

    // Balls B_P(x̃_i(0), δ_i).
    check_len(Field::Centre, p.centre, 4 * nt * n)?;
    check_finite(Field::Centre, p.centre, |i| {
        Pos(sat16(div(i, n)), sat16(rem(i, n)), 0)
    })?;
    check_len(Field::Delta, p.delta, 4 * nt)?;
    check_finite(Field::Delta, p.delta, |i| Pos(sat16(i), 0, 0))?;
    for (t, d) in floats(p.delta).enumerate() {
        if d < 0.0 {
            return Err(ImageError::NegativeDelta {
                trajectory: sat16(t),
            });
        }
    }

    // Step table v (3.6): exactly the rows the segments cover.
    check_len(Field::V, p.v, 4 * rows * m)?;
    let mut start = 0usize;
    for t in 0..nt {
        let last = segment_at(p.segment, (u16_le(p.seg_end, t) as usize).saturating_sub(1));
        let end = last.first_row.saturating_add(last.len);
        let vt = f32_span(p.v, start * m, end.saturating_sub(start) * m);
        check_finite(Field::V, vt, |i| {
            Pos(sat16(t), sat16(div(i, m)), sat16(rem(i, m)))
        })?;
        start = end;
    }
    match maps {
        None => validate_fallback_box(n, m, p.fallback, p.input_box),
        Some(_) if matches!(p.fallback, Fallback::Linear { .. }) => {
            Err(ImageError::LinearFallbackWithMaps)
        }
        Some(mm) => validate_fallback_box(n, mm.m_plant(), p.fallback, p.input_box),
    }
}

/// The PWA counterpart of [`validate`]: dimensions, period, `K`, `P`, the tables (see [`crate::pwa`]), the
/// fallback law and the input box.
fn validate_pwa(dims: Dims, period: f32, p: &PwaPayload<'_>) -> Result<(), ImageError> {
    check_dims(Mode::PwaFeedback, dims)?;
    if !(period.is_finite() && period > 0.0) {
        return Err(ImageError::BadPeriod);
    }
    let (n, m) = (dims.n.clamp(1, MAX_N), dims.m.clamp(1, MAX_M));
    validate_K_P(n, m, dims.n_locations, p.K, p.P)?;
    crate::pwa::validate_tables(dims, &p.tables)?;
    validate_fallback_box(n, m, p.fallback, p.input_box)
}

/// `K_ℓ` (m×n) and `P_ℓ` (n×n, symmetric positive definite) for `nl` locations; `1 ≤ n ≤ MAX_N`,
/// `1 ≤ m ≤ MAX_M`, `nl ≤ MAX_LOCATIONS` already checked.
fn validate_K_P(n: usize, m: usize, nl: usize, K: &[u8], P: &[u8]) -> Result<(), ImageError> {
    let (n, m, nl) = (n.clamp(1, MAX_N), m.clamp(1, MAX_M), nl.min(MAX_LOCATIONS));
    // K_ℓ, m×n per location (the gain of (3.5)).
    check_len(Field::K, K, 4 * nl * m * n)?;
    check_finite(Field::K, K, |i| {
        Pos(
            sat16(div(i, m * n)),
            sat16(div(rem(i, m * n), n)),
            sat16(rem(i, n)),
        )
    })?;

    // P_ℓ, the CAF metric ψ(x, x') = ‖x − x'‖_P of (3.8): symmetric positive definite.
    check_len(Field::P, P, 4 * nl * n * n)?;
    check_finite(Field::P, P, |i| {
        Pos(
            sat16(div(i, n * n)),
            sat16(div(rem(i, n * n), n)),
            sat16(rem(i, n)),
        )
    })?;
    for l in 0..nl {
        let pl = f32_span(P, l * n * n, n * n);
        for r in 0..n {
            for c in (r + 1)..n {
                if f32_at(pl, r * n + c).to_bits() != f32_at(pl, c * n + r).to_bits() {
                    return Err(ImageError::NotSymmetric {
                        location: sat16(l),
                        row: sat16(r),
                        col: sat16(c),
                    });
                }
            }
        }
        if !positive_definite(pl, n) {
            return Err(ImageError::NotPositiveDefinite { location: sat16(l) });
        }
    }
    Ok(())
}

/// The fallback law and the input box (both modes).
fn validate_fallback_box(
    n: usize,
    m: usize,
    fallback: Fallback<'_>,
    input_box: Option<InputBox<'_>>,
) -> Result<(), ImageError> {
    let (n, m) = (n.clamp(1, MAX_N), m.clamp(1, MAX_M));
    // Fallback law.
    if let Fallback::Linear { K, x_ref, u_ref } = fallback {
        check_len(Field::FallbackK, K, 4 * m * n)?;
        check_finite(Field::FallbackK, K, |i| {
            Pos(sat16(div(i, n)), sat16(rem(i, n)), 0)
        })?;
        check_len(Field::FallbackXRef, x_ref, 4 * n)?;
        check_finite(Field::FallbackXRef, x_ref, |i| Pos(sat16(i), 0, 0))?;
        check_len(Field::FallbackURef, u_ref, 4 * m)?;
        check_finite(Field::FallbackURef, u_ref, |i| Pos(sat16(i), 0, 0))?;
    }
    if let Fallback::Constant { u } = fallback {
        check_len(Field::FallbackInput, u, 4 * m)?;
        check_finite(Field::FallbackInput, u, |i| Pos(sat16(i), 0, 0))?;
    }

    // Input box.
    if let Some(b) = input_box {
        check_len(Field::BoxLo, b.lo, 4 * m)?;
        check_finite(Field::BoxLo, b.lo, |i| Pos(sat16(i), 0, 0))?;
        check_len(Field::BoxHi, b.hi, 4 * m)?;
        check_finite(Field::BoxHi, b.hi, |i| Pos(sat16(i), 0, 0))?;
        for j in 0..m {
            if f32_at(b.lo, j) > f32_at(b.hi, j) {
                return Err(ImageError::EmptyInputBox { input: sat16(j) });
            }
        }
        if let Fallback::Constant { u } = fallback {
            for j in 0..m {
                let v = f32_at(u, j);
                if !(f32_at(b.lo, j) <= v && v <= f32_at(b.hi, j)) {
                    return Err(ImageError::FallbackOutsideBox { input: sat16(j) });
                }
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------------------
// The validated image.

/// A validated image: obtainable only from [`decode`], [`Image::new`] or [`Image::new_pwa`], so every
/// accessor reads data that passed all checks. Borrows the bytes it was decoded from; `Copy` (a handful of
/// slices).
///
/// Both modes keep the shared content (`K`, `P`, fallback, input box) in a [`Payload`]; for a PWA image its
/// trajectory fields are empty and its terminal is [`Terminal::HoldLast`] (unused), and the PWA tables are
/// in [`Image::pwa`] (empty for a feedforward image).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Image<'a> {
    pub(crate) mode: Mode,
    pub(crate) dims: Dims,
    pub(crate) period: f32,
    pub(crate) payload: Payload<'a>,
    pub(crate) pwa: PwaTables<'a>,
    /// The spec fingerprint's hashes, or empty when the image has none.
    pub(crate) fingerprint: &'a [u8],
    pub(crate) maps: Option<ModelMaps<'a>>,
    /// The terminal law (section 11) and its body, if the image has one.
    pub(crate) terminal_law: Option<(TerminalLaw<'a>, &'a [u8])>,
    /// The selection test (section 13), if the image has one.
    pub(crate) selection: Option<SelectionTest<'a>>,
    /// The task's monitor (section 14), if the image has one.
    pub(crate) monitor: Option<crate::monitor::MonitorProgram<'a>>,
}

impl<'a> Image<'a> {
    /// Validates `payload` against `mode`, `dims` and `period` and wraps it. This is how the host builds an
    /// image before [`encode`]; it runs exactly the content checks [`decode`] runs.
    pub fn new(
        mode: Mode,
        dims: Dims,
        period: f32,
        payload: Payload<'a>,
    ) -> Result<Self, ImageError> {
        Self::new_with_maps(mode, dims, period, payload, None)
    }

    /// [`Image::new`] for an image that may carry model maps: `maps` is the model maps section's body
    /// ([`crate::maps`]), validated against the dimensions, and with it the fallback and the input box
    /// are checked in the plant's input space.
    pub fn new_with_maps(
        mode: Mode,
        dims: Dims,
        period: f32,
        payload: Payload<'a>,
        maps: Option<&'a [u8]>,
    ) -> Result<Self, ImageError> {
        if mode != Mode::Feedforward {
            return Err(ImageError::UnsupportedMode { mode });
        }
        check_dims(mode, dims)?;
        let maps = match maps {
            Some(body) => Some(ModelMaps::decode(body, dims.n, dims.m)?),
            None => None,
        };
        Self::new_feedforward(mode, dims, period, payload, maps)
    }

    /// The content checks of a feedforward image whose model maps (if any) are decoded already; out of
    /// line, so that [`decode_without_model_maps`] links no model maps decoder.
    #[inline(never)]
    fn new_feedforward(
        mode: Mode,
        dims: Dims,
        period: f32,
        payload: Payload<'a>,
        maps: Option<ModelMaps<'a>>,
    ) -> Result<Self, ImageError> {
        if mode != Mode::Feedforward {
            return Err(ImageError::UnsupportedMode { mode });
        }
        check_dims(mode, dims)?;
        validate(mode, dims, period, &payload, maps.as_ref())?;
        Ok(Image {
            mode,
            dims,
            period,
            payload,
            pwa: PwaTables::EMPTY,
            fingerprint: &[],
            maps,
            terminal_law: None,
            selection: None,
            monitor: None,
        })
    }

    /// Validates a PWA-feedback payload against `dims` and `period` and wraps it (mode
    /// [`Mode::PwaFeedback`]); it runs exactly the content checks [`decode`] runs on such an image.
    pub fn new_pwa(dims: Dims, period: f32, payload: PwaPayload<'a>) -> Result<Self, ImageError> {
        validate_pwa(dims, period, &payload)?;
        Ok(Image {
            mode: Mode::PwaFeedback,
            dims,
            period,
            payload: Payload {
                K: payload.K,
                P: payload.P,
                seg_end: &[],
                centre: &[],
                delta: &[],
                segment: &[],
                v: &[],
                fallback: payload.fallback,
                input_box: payload.input_box,
                terminal: Terminal::HoldLast,
                exits: &[],
            },
            pwa: payload.tables,
            fingerprint: &[],
            maps: None,
            terminal_law: None,
            selection: None,
            monitor: None,
        })
    }

    /// This image with the spec fingerprint `hash` ([`SPEC_FINGERPRINT_LEN`] bytes, any values), stored as
    /// the optional `SpecFingerprint` section; refused with [`ImageError::FieldLength`] if its length is
    /// not exactly that.
    pub fn with_fingerprint(mut self, hash: &'a [u8]) -> Result<Self, ImageError> {
        check_len(Field::Fingerprint, hash, SPEC_FINGERPRINT_LEN)?;
        self.fingerprint = hash;
        Ok(self)
    }

    /// This image with the terminal law whose section body is `body` (section 11), decoded and validated
    /// against the dimensions ([`TerminalLaw::decode`]); refused with
    /// [`ImageError::TerminalWithModelMaps`] for an image with model maps.
    pub fn with_terminal_law(mut self, body: &'a [u8]) -> Result<Self, ImageError> {
        if self.maps.is_some() {
            return Err(ImageError::TerminalWithModelMaps);
        }
        let law = TerminalLaw::decode(body, self.dims.n, self.dims.m)?;
        self.terminal_law = Some((law, body));
        Ok(self)
    }

    /// This image with the selection test whose section body is `body` (section 13), decoded and
    /// validated against the dimensions ([`SelectionTest::decode`]); refused with
    /// [`ImageError::SelectionWithoutModelMaps`] for an image without model maps.
    pub fn with_selection_test(mut self, body: &'a [u8]) -> Result<Self, ImageError> {
        if self.maps.is_none() || self.mode != Mode::Feedforward {
            return Err(ImageError::SelectionWithoutModelMaps);
        }
        let d = self.dims;
        self.selection = Some(SelectionTest::decode(
            body,
            d.n,
            d.n_locations,
            d.n_trajectories,
        )?);
        Ok(self)
    }

    /// The selection test (section 13), if the image has one.
    pub fn selection_test(&self) -> Option<SelectionTest<'a>> {
        self.selection
    }

    /// This image with the monitor whose section body is `body` (section 14), decoded and validated for
    /// the plant's state dimension ([`crate::monitor::MonitorProgram::decode`]).
    pub fn with_monitor(mut self, body: &'a [u8]) -> Result<Self, ImageError> {
        let p = crate::monitor::MonitorProgram::decode(body, self.plant_n())
            .map_err(|why| ImageError::BadMonitor { why })?;
        self.monitor = Some(p);
        Ok(self)
    }

    /// The task's monitor (section 14), if the image has one.
    pub fn monitor(&self) -> Option<crate::monitor::MonitorProgram<'a>> {
        self.monitor
    }

    /// The terminal law (section 11), if the image has one.
    pub fn terminal_law(&self) -> Option<TerminalLaw<'a>> {
        self.terminal_law.map(|(law, _)| law)
    }

    /// The spec fingerprint's hashes ([`SPEC_FINGERPRINT_LEN`] bytes, part `i` of [`SPEC_PARTS`] at
    /// `i * SPEC_HASH_LEN`), or `None` for an image without the section.
    pub fn fingerprint(&self) -> Option<&'a [u8]> {
        (!self.fingerprint.is_empty()).then_some(self.fingerprint)
    }

    /// The PWA payload this image encodes to (meaningful for PWA images; for a feedforward image its
    /// tables are empty).
    pub fn pwa_payload(&self) -> PwaPayload<'a> {
        PwaPayload {
            K: self.payload.K,
            P: self.payload.P,
            tables: self.pwa,
            fallback: self.payload.fallback,
            input_box: self.payload.input_box,
        }
    }

    /// Controller mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }
    /// Dimensions.
    pub fn dims(&self) -> Dims {
        self.dims
    }
    /// State dimension n.
    pub fn n(&self) -> usize {
        self.dims.n
    }
    /// Input dimension m.
    pub fn m(&self) -> usize {
        self.dims.m
    }
    /// The model maps (section 10), if the image has them: the law then works on ξ = coords(x).
    pub fn model_maps(&self) -> Option<ModelMaps<'a>> {
        self.maps
    }
    /// The plant's state dimension: `n_plant` of the model maps, else n.
    pub fn plant_n(&self) -> usize {
        self.maps.as_ref().map_or(self.dims.n, ModelMaps::n_plant)
    }
    /// The plant's input dimension: `m_plant` of the model maps, else m. The fallback and the input box
    /// have this many values.
    pub fn plant_m(&self) -> usize {
        self.maps.as_ref().map_or(self.dims.m, ModelMaps::m_plant)
    }
    /// Number of locations.
    pub fn n_locations(&self) -> usize {
        self.dims.n_locations
    }
    /// Number of trajectories.
    pub fn n_trajectories(&self) -> usize {
        self.dims.n_trajectories
    }
    /// Sample period, seconds.
    pub fn period(&self) -> f32 {
        self.period
    }
    /// The content (validated). For a PWA image only `K`, `P`, `fallback` and `input_box` are meaningful
    /// (the trajectory fields are empty); its tables are [`Image::pwa`].
    pub fn payload(&self) -> &Payload<'a> {
        &self.payload
    }
    /// Behaviour past the end of a trajectory.
    pub fn terminal(&self) -> Terminal {
        self.payload.terminal
    }
    /// Fallback law (raw; read its values with [`Image::fallback_K`] etc.).
    pub fn fallback(&self) -> Fallback<'a> {
        self.payload.fallback
    }
    /// Whether an input box is stored.
    pub fn has_input_box(&self) -> bool {
        self.payload.input_box.is_some()
    }
    /// Total rows of the step table.
    pub fn total_steps(&self) -> usize {
        div(self.payload.v.len(), 4 * self.dims.m)
    }

    /// `K_ℓ[row, col]`; 0.0 for indices out of range.
    pub fn K(&self, location: usize, row: usize, col: usize) -> f32 {
        let Dims {
            n, m, n_locations, ..
        } = self.dims;
        if location >= n_locations || row >= m || col >= n {
            return 0.0;
        }
        f32_at(self.payload.K, (location * m + row) * n + col)
    }

    /// `P_ℓ[row, col]`; 0.0 for indices out of range.
    pub fn P(&self, location: usize, row: usize, col: usize) -> f32 {
        let Dims { n, n_locations, .. } = self.dims;
        if location >= n_locations || row >= n || col >= n {
            return 0.0;
        }
        f32_at(self.payload.P, (location * n + row) * n + col)
    }

    /// Component `i` of the ball centre `x̃_t(0)`; 0.0 out of range.
    pub fn centre(&self, trajectory: usize, i: usize) -> f32 {
        if trajectory >= self.dims.n_trajectories || i >= self.dims.n {
            return 0.0;
        }
        f32_at(self.payload.centre, trajectory * self.dims.n + i)
    }

    /// Ball radius `δ_t`; 0.0 out of range.
    pub fn delta(&self, trajectory: usize) -> f32 {
        if trajectory >= self.dims.n_trajectories {
            return 0.0;
        }
        f32_at(self.payload.delta, trajectory)
    }

    /// Number of segments of the step table (0 for a PWA image).
    pub fn n_segments(&self) -> usize {
        self.payload.segment.len() / SEGMENT_RECORD_LEN
    }

    /// Segment `s` (location and rows of the step table); `None` out of range.
    pub fn segment(&self, s: usize) -> Option<Segment> {
        (s < self.n_segments()).then(|| segment_at(self.payload.segment, s))
    }

    /// Whether the image stores segment exits (some segment may end at a guard).
    pub fn has_exits(&self) -> bool {
        !self.payload.exits.is_empty()
    }

    /// How segment `s` ends ([`Exit::Table`] without exits or out of range).
    pub fn exit(&self, s: usize) -> Exit<'a> {
        let n = self.n().clamp(1, MAX_N);
        let rec = crate::layout::exit_record_len(n);
        if s >= self.n_segments() || self.payload.exits.len() < (s + 1) * rec {
            return Exit::Table;
        }
        if u32_at_byte(self.payload.exits, s * rec) != crate::layout::EXIT_GUARD {
            return Exit::Table;
        }
        let vals = f32_span(self.payload.exits, s * (2 * n + 3) + 1, 2 * n + 2);
        Exit::Guard {
            a: f32_span(vals, 0, n),
            b: f32_at(vals, n),
            theta: f32_at(vals, n + 1),
            next: f32_span(vals, n + 2, n),
        }
    }

    /// First segment and number of segments of a trajectory; `(0, 0)` out of range.
    pub fn trajectory_segments(&self, trajectory: usize) -> (usize, usize) {
        if trajectory >= self.dims.n_trajectories {
            return (0, 0);
        }
        let start = match trajectory {
            0 => 0,
            _ => u16_le(self.payload.seg_end, trajectory - 1) as usize,
        };
        let end = u16_le(self.payload.seg_end, trajectory) as usize;
        (start, end.saturating_sub(start))
    }

    /// First table row and number of rows of a trajectory (its segments are contiguous); `(0, 0)` out of
    /// range.
    pub fn trajectory_rows(&self, trajectory: usize) -> (usize, usize) {
        let (s, count) = self.trajectory_segments(trajectory);
        if count == 0 {
            return (0, 0);
        }
        let first = segment_at(self.payload.segment, s);
        let last = segment_at(self.payload.segment, s + count - 1);
        let end = last.first_row.saturating_add(last.len);
        (first.first_row, end.saturating_sub(first.first_row))
    }

    /// Number of steps of a trajectory.
    pub fn trajectory_len(&self, trajectory: usize) -> usize {
        self.trajectory_rows(trajectory).1
    }

    /// `v_t(step)[j]`; 0.0 out of range.
    pub fn v(&self, trajectory: usize, step: usize, j: usize) -> f32 {
        let (start, len) = self.trajectory_rows(trajectory);
        if step >= len || j >= self.dims.m {
            return 0.0;
        }
        f32_at(self.payload.v, (start + step) * self.dims.m + j)
    }

    /// The segment of `trajectory` that holds its step `step` (a scan of the trajectory's segments);
    /// `None` out of range.
    pub fn segment_of(&self, trajectory: usize, step: usize) -> Option<usize> {
        let (start, len) = self.trajectory_rows(trajectory);
        if step >= len {
            return None;
        }
        let row = start + step;
        let (s0, count) = self.trajectory_segments(trajectory);
        (s0..s0 + count).find(|&s| {
            let g = segment_at(self.payload.segment, s);
            row >= g.first_row && row < g.first_row.saturating_add(g.len)
        })
    }

    /// Nominal location `ℓ_t(step)` (its segment's); 0 out of range.
    pub fn location(&self, trajectory: usize, step: usize) -> usize {
        self.segment_of(trajectory, step)
            .map_or(0, |s| segment_at(self.payload.segment, s).location)
    }

    /// Fallback gain `K_fb[row, col]`; 0.0 if the fallback is not linear or out of range.
    pub fn fallback_K(&self, row: usize, col: usize) -> f32 {
        match self.payload.fallback {
            Fallback::Linear { K, .. } if row < self.dims.m && col < self.dims.n => {
                f32_at(K, row * self.dims.n + col)
            }
            _ => 0.0,
        }
    }

    /// Fallback `x_ref[i]`; 0.0 if not linear or out of range.
    pub fn fallback_x_ref(&self, i: usize) -> f32 {
        match self.payload.fallback {
            Fallback::Linear { x_ref, .. } if i < self.dims.n => f32_at(x_ref, i),
            _ => 0.0,
        }
    }

    /// Constant fallback input `u[j]` (`j < plant_m`); 0.0 if the fallback is not constant or out of
    /// range.
    pub fn fallback_input(&self, j: usize) -> f32 {
        match self.payload.fallback {
            Fallback::Constant { u } if j < self.plant_m() => f32_at(u, j),
            _ => 0.0,
        }
    }

    /// Fallback `u_ref[j]`; 0.0 if not linear or out of range.
    pub fn fallback_u_ref(&self, j: usize) -> f32 {
        match self.payload.fallback {
            Fallback::Linear { u_ref, .. } if j < self.dims.m => f32_at(u_ref, j),
            _ => 0.0,
        }
    }

    /// Input box bounds `(lo_j, hi_j)`, if a box is stored and `j < plant_m`.
    pub fn input_bounds(&self, j: usize) -> Option<(f32, f32)> {
        match self.payload.input_box {
            Some(b) if j < self.plant_m() => Some((f32_at(b.lo, j), f32_at(b.hi, j))),
            _ => None,
        }
    }

    /// Size of the encoded image (header, directory and sections), in bytes.
    pub fn encoded_len(&self) -> Result<usize, ImageError> {
        self.with_sections(image_len)
    }

    /// Calls `f` with the sections this image is stored as, in directory order.
    fn with_sections<R>(&self, f: impl FnOnce(&[&dyn SectionWrite]) -> R) -> R {
        let p = &self.payload;
        let locations =
            PostcardSection::new(SectionKind::Locations, LocationsSection { K: p.K, P: p.P });
        let fallback = PostcardSection::new(
            SectionKind::Fallback,
            FallbackSection {
                fallback: p.fallback,
                input_box: p.input_box,
            },
        );
        let trajectories = PostcardSection::new(
            SectionKind::Trajectories,
            TrajectoriesSection {
                terminal: p.terminal,
                seg_end: p.seg_end,
                centre: p.centre,
                delta: p.delta,
            },
        );
        let segments = PostcardSection::new(
            SectionKind::Segments,
            SegmentsSection { segment: p.segment },
        );
        let steps = PostcardSection::new(SectionKind::Steps, StepsSection { v: p.v });
        let exits = PostcardSection::new(
            SectionKind::SegmentExits,
            SegmentExitsSection { exit: p.exits },
        );
        let maps = RawSection {
            kind: SectionKind::ModelMaps as u16,
            body: self.maps.as_ref().map_or(&[][..], ModelMaps::body),
        };
        let (laws, tree, balls) = self.pwa.sections();
        let laws = PostcardSection::new(SectionKind::PwaLaws, laws);
        let tree = PostcardSection::new(SectionKind::PwaTree, tree);
        let balls = PostcardSection::new(SectionKind::PwaBalls, balls);
        let terminal = RawSection {
            kind: SectionKind::TerminalLaw as u16,
            body: self.terminal_law.map_or(&[][..], |(_, body)| body),
        };
        let fingerprint = PostcardSection::new(
            SectionKind::SpecFingerprint,
            SpecFingerprintSection {
                hash: self.fingerprint,
            },
        );
        let selection = RawSection {
            kind: SectionKind::SelectionTest as u16,
            body: self.selection.as_ref().map_or(&[][..], SelectionTest::body),
        };
        let monitor = RawSection {
            kind: SectionKind::Monitor as u16,
            body: self
                .monitor
                .as_ref()
                .map_or(&[][..], crate::monitor::MonitorProgram::body),
        };
        let feedforward: [&dyn SectionWrite; 5] =
            [&locations, &fallback, &trajectories, &segments, &steps];
        let pwa: [&dyn SectionWrite; 5] = [&locations, &fallback, &laws, &tree, &balls];
        let ff = self.mode == Mode::Feedforward;
        let base: &[&dyn SectionWrite] = if ff { &feedforward } else { &pwa };
        // The optional sections, in kind order, only when present.
        let optional: [(bool, &dyn SectionWrite); 6] = [
            (ff && !p.exits.is_empty(), &exits),
            (ff && self.maps.is_some(), &maps),
            (self.terminal_law.is_some(), &terminal),
            (!self.fingerprint.is_empty(), &fingerprint),
            (ff && self.selection.is_some(), &selection),
            (self.monitor.is_some(), &monitor),
        ];
        let present = optional.iter().filter(|(on, _)| *on).map(|(_, s)| *s);
        // At most 10 sections (feedforward with exits, maps or a terminal law (never both), a
        // fingerprint, with maps a selection test, and a monitor).
        let mut list: [&dyn SectionWrite; 10] = [&locations; 10];
        let mut count = 0;
        for (slot, s) in list.iter_mut().zip(base.iter().copied().chain(present)) {
            *slot = s;
            count += 1;
        }
        f(list.get(..count).unwrap_or(&[]))
    }
}

/// Decodes and validates an image, borrowing `bytes` (zero copy, no allocation, never panics).
///
/// Order of checks: header (length, magic, version, reserved), payload length, CRC, mode, dimensions and
/// period, the section directory ([`Directory::parse`]), each section's postcard structure (no trailing
/// bytes, canonical form), then the content (see module docs).
pub fn decode(bytes: &[u8]) -> Result<Image<'_>, ImageError> {
    decode_sections::<true, true, true>(bytes)
}

/// [`decode`] for a firmware built without the model-maps step (it calls [`crate::eval::Controller::step`],
/// which reads the state as the law's own coordinates): an image with model maps or a selection test is
/// refused with [`ImageError::ModelMapsNotSupported`] (after the checks before the content), and neither
/// the model programs' decoder nor the selection test's is linked. Otherwise the same checks and the
/// same image as [`decode`].
pub fn decode_without_model_maps(bytes: &[u8]) -> Result<Image<'_>, ImageError> {
    decode_sections::<false, true, true>(bytes)
}

/// [`decode`] for a firmware, choosing at build time what it links: with `MAPS` false, as
/// [`decode_without_model_maps`]; with `MONITOR` false, an image carrying the task's monitor (section 14)
/// is refused with [`ImageError::MonitorNotSupported`] (a firmware builds the monitor in exactly when its
/// image carries one), and the monitor's decoder is not linked. Otherwise the same checks and the same
/// image as [`decode`]. With `PWA` false, a PWA-feedback image is refused with
/// [`ImageError::PwaNotSupported`] (after the checks before the content) and the PWA tables' validation
/// is not linked; such a firmware steps with [`crate::eval::Controller::step_for`]`::<false>`, which
/// links no point location either.
pub fn decode_for<const MAPS: bool, const MONITOR: bool, const PWA: bool>(
    bytes: &[u8],
) -> Result<Image<'_>, ImageError> {
    decode_sections::<MAPS, MONITOR, PWA>(bytes)
}

/// [`decode`], with the model maps and selection test sections admitted only when `MAPS`, the monitor
/// only when `MONITOR`, a PWA-feedback image only when `PWA`.
#[inline(always)]
fn decode_sections<const MAPS: bool, const MONITOR: bool, const PWA: bool>(
    bytes: &[u8],
) -> Result<Image<'_>, ImageError> {
    let h = Header::parse(bytes)?;
    let payload_bytes = bytes.get(HEADER_LEN..).unwrap_or(&[]);
    if payload_bytes.len() != h.payload_len as usize {
        return Err(ImageError::PayloadLength {
            header: h.payload_len,
            actual: sat32(payload_bytes.len()),
        });
    }
    let computed = compute_crc(bytes)?;
    if computed != h.crc {
        return Err(ImageError::CrcMismatch {
            stored: h.crc,
            computed,
        });
    }
    let mode = Mode::from_u8(h.mode).ok_or(ImageError::UnknownMode { found: h.mode })?;
    // Dimensions are checked again in `validate`; checking them before parsing gives the clearer error.
    let d = h.dims;
    check_dims(mode, d)?;
    let dir = Directory::parse(bytes, h.n_sections, mode)?;
    let locations: LocationsSection<'_> = parse_section(&dir, SectionKind::Locations)?;
    let fallback: FallbackSection<'_> = parse_section(&dir, SectionKind::Fallback)?;
    match mode {
        Mode::Feedforward => {
            let tr: TrajectoriesSection<'_> = parse_section(&dir, SectionKind::Trajectories)?;
            let seg: SegmentsSection<'_> = parse_section(&dir, SectionKind::Segments)?;
            let steps: StepsSection<'_> = parse_section(&dir, SectionKind::Steps)?;
            let exits: SegmentExitsSection<'_> = match dir.section(SectionKind::SegmentExits) {
                Some(_) => parse_section(&dir, SectionKind::SegmentExits)?,
                None => SegmentExitsSection { exit: &[] },
            };
            let maps = dir.section(SectionKind::ModelMaps);
            if !MAPS && (maps.is_some() || dir.section(SectionKind::SelectionTest).is_some()) {
                return Err(ImageError::ModelMapsNotSupported);
            }
            let payload = Payload {
                K: locations.K,
                P: locations.P,
                seg_end: tr.seg_end,
                centre: tr.centre,
                delta: tr.delta,
                segment: seg.segment,
                v: steps.v,
                fallback: fallback.fallback,
                input_box: fallback.input_box,
                terminal: tr.terminal,
                exits: exits.exit,
            };
            let img = match maps {
                Some(body) if MAPS => Image::new_with_maps(mode, d, h.period, payload, Some(body))?,
                _ => Image::new_feedforward(mode, d, h.period, payload, None)?,
            };
            let img = match dir.section(SectionKind::SelectionTest) {
                Some(body) if MAPS => img.with_selection_test(body)?,
                _ => img,
            };
            with_stored_optional::<MONITOR>(&dir, img)
        }
        Mode::PwaFeedback if !PWA => Err(ImageError::PwaNotSupported),
        Mode::PwaFeedback => {
            let laws: PwaLaws<'_> = parse_section(&dir, SectionKind::PwaLaws)?;
            let tree: PwaTree<'_> = parse_section(&dir, SectionKind::PwaTree)?;
            let balls: PwaBalls<'_> = parse_section(&dir, SectionKind::PwaBalls)?;
            let payload = PwaPayload {
                K: locations.K,
                P: locations.P,
                tables: PwaTables::from_sections(laws, tree, balls),
                fallback: fallback.fallback,
                input_box: fallback.input_box,
            };
            let img = Image::new_pwa(d, h.period, payload)?;
            with_stored_optional::<MONITOR>(&dir, img)
        }
    }
}

/// `img` with the directory's optional sections of both modes (terminal law, spec fingerprint, monitor),
/// validated.
fn with_stored_optional<'a, const MONITOR: bool>(
    dir: &Directory<'a>,
    img: Image<'a>,
) -> Result<Image<'a>, ImageError> {
    let img = match dir.section(SectionKind::TerminalLaw) {
        Some(body) => img.with_terminal_law(body)?,
        None => img,
    };
    let img = match dir.section(SectionKind::SpecFingerprint) {
        Some(_) => {
            let fp: SpecFingerprintSection<'a> = parse_section(dir, SectionKind::SpecFingerprint)?;
            img.with_fingerprint(fp.hash)?
        }
        None => img,
    };
    match dir.section(SectionKind::Monitor) {
        Some(body) if MONITOR => img.with_monitor(body),
        Some(_) => Err(ImageError::MonitorNotSupported),
        None => Ok(img),
    }
}

/// Writes the image (header, directory and sections) into `out` and returns the number of bytes written.
/// No allocation; fails with [`ImageError::BufferTooSmall`] if `out` is too short.
pub fn encode(image: &Image<'_>, out: &mut [u8]) -> Result<usize, ImageError> {
    image.with_sections(|sections| {
        write_image(out, image.mode as u8, image.dims, image.period, sections)
    })
}

/// The section directory of an image that [`decode`] accepted (for tools that show the layout); errors as
/// [`Directory::parse`] (and [`Header::parse`]) would.
pub fn directory(bytes: &[u8]) -> Result<Directory<'_>, ImageError> {
    let h = Header::parse(bytes)?;
    let mode = Mode::from_u8(h.mode).ok_or(ImageError::UnknownMode { found: h.mode })?;
    Directory::parse(bytes, h.n_sections, mode)
}

// PWA accessors (the layout of the tables is in [`crate::pwa`]).
impl<'a> Image<'a> {
    /// The PWA tables (empty for a feedforward image).
    pub fn pwa(&self) -> &PwaTables<'a> {
        &self.pwa
    }
    /// Number of partitions (0 for a feedforward image).
    pub fn n_partitions(&self) -> usize {
        self.dims.n_partitions
    }
    /// Worst-case number of hyperplane tests of one point location.
    pub fn tree_depth(&self) -> usize {
        self.pwa.depth as usize
    }
    /// Number of internal tree nodes.
    pub fn n_nodes(&self) -> usize {
        self.pwa.n_nodes as usize
    }
    /// Number of leaves.
    pub fn n_leaves(&self) -> usize {
        self.pwa.n_leaves as usize
    }
    /// Number of certified balls.
    pub fn n_balls(&self) -> usize {
        self.pwa.n_balls as usize
    }
    /// Number of ball references, summed over all leaves.
    pub fn n_ball_refs(&self) -> usize {
        self.pwa.ball_ref.len() / 2
    }

    /// `K_j[row, col]` (`K_j = K + θ_j`); 0.0 out of range.
    pub fn law_gain(&self, partition: usize, row: usize, col: usize) -> f32 {
        let (n, m) = (self.dims.n, self.dims.m);
        if partition >= self.n_partitions() || row >= m || col >= n {
            return 0.0;
        }
        f32_at(self.pwa.gain, (partition * m + row) * n + col)
    }

    /// `θ0_j[row]`; 0.0 out of range.
    pub fn law_offset(&self, partition: usize, row: usize) -> f32 {
        if partition >= self.n_partitions() || row >= self.dims.m {
            return 0.0;
        }
        f32_at(self.pwa.offset, partition * self.dims.m + row)
    }

    /// Component `i` of the normal `a` of node `node`; 0.0 out of range.
    pub fn node_normal(&self, node: usize, i: usize) -> f32 {
        if node >= self.n_nodes() || i >= self.dims.n {
            return 0.0;
        }
        node_value(self.pwa.node, self.dims.n, node, i)
    }

    /// Offset `b` of node `node`; 0.0 out of range.
    pub fn node_offset(&self, node: usize) -> f32 {
        if node >= self.n_nodes() {
            return 0.0;
        }
        node_value(self.pwa.node, self.dims.n, node, self.dims.n)
    }

    /// Children (left: `aᵀx ≤ b`, right: otherwise) of node `node`; `None` out of range.
    pub fn node_children(&self, node: usize) -> Option<(Child, Child)> {
        if node >= self.n_nodes() {
            return None;
        }
        Some((
            Child::from_code(node_child(self.pwa.node, self.dims.n, node, 0)),
            Child::from_code(node_child(self.pwa.node, self.dims.n, node, 1)),
        ))
    }

    /// Partition of leaf `leaf`; 0 out of range.
    pub fn leaf_partition(&self, leaf: usize) -> usize {
        if leaf >= self.n_leaves() {
            return 0;
        }
        u16_le(self.pwa.leaf_partition, leaf) as usize
    }

    /// First reference and number of references of leaf `leaf`; `(0, 0)` out of range.
    pub fn leaf_refs(&self, leaf: usize) -> (usize, usize) {
        if leaf >= self.n_leaves() {
            return (0, 0);
        }
        let start = match leaf {
            0 => 0,
            _ => u16_le(self.pwa.leaf_end, leaf - 1) as usize,
        };
        let end = u16_le(self.pwa.leaf_end, leaf) as usize;
        (start, end.saturating_sub(start))
    }

    /// Ball `k` of leaf `leaf` (its index in the ball table); `None` out of range.
    pub fn leaf_ball(&self, leaf: usize, k: usize) -> Option<usize> {
        let (start, len) = self.leaf_refs(leaf);
        (k < len).then(|| u16_le(self.pwa.ball_ref, start + k) as usize)
    }

    /// Component `i` of the centre of ball `ball`; 0.0 out of range.
    pub fn ball_centre(&self, ball: usize, i: usize) -> f32 {
        if ball >= self.n_balls() || i >= self.dims.n {
            return 0.0;
        }
        f32_at(self.pwa.ball_centre, ball * self.dims.n + i)
    }

    /// Component `i` of the whitened centre `ĉ_z = fl32(R̂ ĉ)` of ball `ball`; 0.0 out of range.
    pub fn ball_centre_z(&self, ball: usize, i: usize) -> f32 {
        if ball >= self.n_balls() || i >= self.dims.n {
            return 0.0;
        }
        f32_at(self.pwa.ball_test, ball * (self.dims.n + 1) + i)
    }

    /// `R̂_ℓ[row, col]`, the factor of location ℓ's metric used by the ball test; 0.0 out of range.
    pub fn factor(&self, location: usize, row: usize, col: usize) -> f32 {
        let n = self.dims.n;
        if self.mode != Mode::PwaFeedback
            || location >= self.dims.n_locations
            || row >= n
            || col >= n
        {
            return 0.0;
        }
        f32_at(self.pwa.R, (location * n + row) * n + col)
    }

    /// Stored squared threshold ŝ of ball `ball`: the whitened test accepts x̂ iff the computed
    /// `fl(‖fl(R̂x̂) − ĉ_z‖²) ≤ ŝ` (module doc), so accepted states have computed squared whitened
    /// distance ≤ ŝ; 0.0 out of range.
    pub fn ball_threshold(&self, ball: usize) -> f32 {
        if ball >= self.n_balls() {
            return 0.0;
        }
        let n = self.dims.n;
        f32_at(self.pwa.ball_test, ball * (n + 1) + n)
    }

    /// Location (metric) of ball `ball`; 0 out of range.
    pub fn ball_location(&self, ball: usize) -> usize {
        self.pwa.ball_location.get(ball).copied().unwrap_or(0) as usize
    }

    /// Partition ball `ball` is certified for; 0 out of range.
    pub fn ball_partition(&self, ball: usize) -> usize {
        if ball >= self.n_balls() {
            return 0;
        }
        u16_le(self.pwa.ball_partition, ball) as usize
    }

    /// Point location of `x` (length n, finite): the tree walk, then the envelope test against the
    /// leaf's balls. `None` for a feedforward image or an unusable `x`. Pure.
    pub fn locate(&self, x: &[f32]) -> Option<Region> {
        if self.mode != Mode::PwaFeedback {
            return None;
        }
        let n = self.dims.n.clamp(1, MAX_N);
        if x.len() != n || !x.iter().all(|v| v.is_finite()) {
            return None;
        }
        Some(self.pwa.locate_in(self.dims.n_locations, x, n))
    }

    /// [`Image::locate`] without the argument checks (`x.len() == n`, `1 ≤ n ≤ MAX_N`).
    pub(crate) fn locate_in(&self, x: &[f32], n: usize) -> Region {
        self.pwa.locate_in(self.dims.n_locations, x, n)
    }
}
