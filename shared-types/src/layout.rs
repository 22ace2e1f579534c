//! The fixed vocabulary of the image layout: magic, format version, header field offsets, the controller
//! [`Mode`], the header [`Dims`] and the [`SectionKind`] tags of the section directory. Plain constants and
//! types with no behaviour beyond byte conversions, so that every other module (errors, header parsing,
//! the PWA tables, the image) can name them without depending on each other. The layout itself is
//! described in [`crate::image`].

/// First four bytes of every image ("safe controller image").
pub const MAGIC: [u8; 4] = *b"SFCI";

/// Version of the layout described in [`crate::image`]. Decoding rejects every other version. Version 2
/// added the whitened ball test of PWA images; version 3 stored PWA tree nodes and ball tests as one record
/// each; version 4 replaced the single postcard payload by a directory of typed sections and the per-row
/// location bytes of the feedforward table by segments.
pub const FORMAT_VERSION: u16 = 4;

/// Byte offset of the section count (`u16`) in the header.
pub const SECTION_COUNT_OFFSET: usize = 18;
/// Byte offset of the CRC in the header; the CRC covers the header bytes before it and everything after
/// the header.
pub const CRC_OFFSET: usize = 28;
/// Bytes of one section directory entry: kind (`u16`), flags (`u16`, 0), offset (`u32`, from the start of
/// the image), length (`u32`).
pub const DIR_ENTRY_LEN: usize = 12;
/// Bytes of one feedforward segment record: first row (`u32`), number of rows (`u32`), location (`u8`).
pub const SEGMENT_RECORD_LEN: usize = 9;

/// Bytes of one segment-exit record for state dimension n: the kind (`u32`: [`EXIT_TABLE`] or
/// [`EXIT_GUARD`]), then 2n + 2 `f32` values: â, b̂, θ, and the next segment's nominal start x̃(0) (what
/// its certificate is re-proved from; the evaluator does not read it). All zero for a table exit.
pub const fn exit_record_len(n: usize) -> usize {
    4 * (2 * n + 3)
}
/// A segment that ends with its table (forced switching by time, or the run's last segment).
pub const EXIT_TABLE: u32 = 0;
/// A segment that ends when fl(Σⱼ âⱼx̂ⱼ − b̂) ≤ −θ at a sample: the controller moves to the next segment, row 0.
pub const EXIT_GUARD: u32 = 1;

/// Bytes of one hash of the spec fingerprint (the first bytes of a SHA-256 digest, computed by the host).
pub const SPEC_HASH_LEN: usize = 8;

/// The parts of a spec the fingerprint section hashes, in their stored order: a part is a set of the
/// spec's top-level keys (its tables and values), named as messages print it. The order is part of the
/// format. `other` holds every top-level key no other part lists (the spec's `name`); `spec` is the whole
/// spec.
pub const SPEC_PARTS: [&str; 10] = [
    "[plant]",
    "[init]",
    "[goal]",
    "[unsafe]",
    "[input]",
    "horizon",
    "[mtl] with [sets]",
    "[synthesis] with seed",
    "other top-level keys",
    "spec",
];

/// Bytes of the fingerprint's hashes: [`SPEC_PARTS`] × [`SPEC_HASH_LEN`].
pub const SPEC_FINGERPRINT_LEN: usize = SPEC_PARTS.len() * SPEC_HASH_LEN;

/// How the controller computes its input.
#[repr(u8)]
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// Algorithm 2: select a robust ball at κ = 0, then `u = K x + v_i(κ)`.
    Feedforward = 1,
    /// PWA feedback (Ch. 6): locate the partition j of x with a bounded-depth tree, check that x lies in
    /// a certified ball of that leaf (the envelope F), then `u = K_j x + θ0_j` with `K_j = K + θ_j`.
    PwaFeedback = 2,
}

impl Mode {
    /// The mode with this byte value, if any.
    pub const fn from_u8(b: u8) -> Option<Mode> {
        match b {
            1 => Some(Mode::Feedforward),
            2 => Some(Mode::PwaFeedback),
            _ => None,
        }
    }

    /// The sections an image of this mode must carry, each exactly once (in kind order).
    pub const fn required_sections(self) -> &'static [SectionKind] {
        match self {
            Mode::Feedforward => &[
                SectionKind::Locations,
                SectionKind::Fallback,
                SectionKind::Trajectories,
                SectionKind::Segments,
                SectionKind::Steps,
            ],
            Mode::PwaFeedback => &[
                SectionKind::Locations,
                SectionKind::Fallback,
                SectionKind::PwaLaws,
                SectionKind::PwaTree,
                SectionKind::PwaBalls,
            ],
        }
    }

    /// Whether a section of `kind` belongs in an image of this mode: the required ones, the optional
    /// segment exits, model maps and selection test of a feedforward image, and the optional terminal
    /// law, spec fingerprint and monitor of either mode.
    pub fn admits(self, kind: SectionKind) -> bool {
        self.required_sections().contains(&kind)
            || (self == Mode::Feedforward
                && matches!(
                    kind,
                    SectionKind::SegmentExits | SectionKind::ModelMaps | SectionKind::SelectionTest
                ))
            || matches!(
                kind,
                SectionKind::TerminalLaw | SectionKind::SpecFingerprint | SectionKind::Monitor
            )
    }
}

/// Dimensions of an image, as declared in its header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dims {
    /// State dimension.
    pub n: usize,
    /// Input dimension.
    pub m: usize,
    /// Number of locations (≥ 1).
    pub n_locations: usize,
    /// Number of trajectories (0 in PWA mode).
    pub n_trajectories: usize,
    /// Number of partitions (0 in feedforward mode, ≥ 1 in PWA mode).
    pub n_partitions: usize,
}

/// The type tag of a section in the directory. The numbering is part of the format: a tag is never reused
/// for another meaning. Later issues add kinds (guards and resets, model programs for nonlinear plants,
/// controller states) after the existing ones, without touching these.
///
/// A decoder meets a tag it does not know in an image written for a newer firmware. It rejects it
/// ([`crate::image::ImageError::UnknownSection`]): the image's certificate may depend on that section (a
/// guard, a model program), and a firmware that cannot evaluate it cannot run what was certified.
#[repr(u16)]
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SectionKind {
    /// `K_ℓ` and `P_ℓ` per location.
    Locations = 1,
    /// The fallback law and the optional input box.
    Fallback = 2,
    /// Feedforward trajectories: terminal behaviour; per trajectory its ball and its run of segments.
    Trajectories = 3,
    /// Feedforward segments: per segment the location and its run of rows of the step table.
    Segments = 4,
    /// The feedforward step table `v` (rows × m).
    Steps = 5,
    /// PWA laws: `K_j` and `θ0_j` per partition.
    PwaLaws = 6,
    /// PWA point-location tree: node records and leaves with their ball references.
    PwaTree = 7,
    /// PWA certified balls and the per-location factors `R̂_ℓ` of their whitened test.
    PwaBalls = 8,
    /// Feedforward segment exits (optional): per segment, whether it ends with its table or when the
    /// measured state enters a guard half-space (internal switching, (4.41)–(4.42)).
    SegmentExits = 9,
    /// Model maps (optional, feedforward only): the programs `coords: x ↦ ξ` and `input_map: (x, w) ↦ u`
    /// of a feedback-linearizable plant, whose controller runs the linear law in ξ ([`crate::image`]).
    ModelMaps = 10,
    /// The terminal law (optional, both modes): a certified linear law and the invariant ellipsoid in
    /// Goal it hands over on, for after the task ([`crate::terminal`]).
    TerminalLaw = 11,
    /// The spec fingerprint (optional, both modes): [`SPEC_PARTS`] hashes of [`SPEC_HASH_LEN`] bytes of
    /// the spec the image was synthesised from, so that a tool can refuse an image whose spec changed
    /// since. The evaluator does not read it.
    SpecFingerprint = 12,
    /// The whitened selection test (optional, feedforward images with model maps): per location the f32
    /// Cholesky factor `R̂_ℓ` of `P_ℓ`, per trajectory the whitened centre and squared threshold of its
    /// ball, which the model-maps step selects with ([`crate::selection`]).
    SelectionTest = 13,
    /// The task's monitor (optional, both modes): the spec's formula (or a reach-avoid task as
    /// `!Unsafe U[0,T] Goal`) as a bounded MTL program over signed distances, which a firmware built with
    /// the monitor evaluates on the measured state every step ([`crate::monitor`]). Not part of the
    /// control law or its certificate.
    Monitor = 14,
}

impl SectionKind {
    /// Every kind this build knows, in tag order.
    pub const ALL: [SectionKind; 14] = [
        SectionKind::Locations,
        SectionKind::Fallback,
        SectionKind::Trajectories,
        SectionKind::Segments,
        SectionKind::Steps,
        SectionKind::PwaLaws,
        SectionKind::PwaTree,
        SectionKind::PwaBalls,
        SectionKind::SegmentExits,
        SectionKind::ModelMaps,
        SectionKind::TerminalLaw,
        SectionKind::SpecFingerprint,
        SectionKind::SelectionTest,
        SectionKind::Monitor,
    ];

    /// The kind with this tag, if this build knows it.
    pub const fn from_u16(tag: u16) -> Option<SectionKind> {
        match tag {
            1 => Some(SectionKind::Locations),
            2 => Some(SectionKind::Fallback),
            3 => Some(SectionKind::Trajectories),
            4 => Some(SectionKind::Segments),
            5 => Some(SectionKind::Steps),
            6 => Some(SectionKind::PwaLaws),
            7 => Some(SectionKind::PwaTree),
            8 => Some(SectionKind::PwaBalls),
            9 => Some(SectionKind::SegmentExits),
            10 => Some(SectionKind::ModelMaps),
            11 => Some(SectionKind::TerminalLaw),
            12 => Some(SectionKind::SpecFingerprint),
            13 => Some(SectionKind::SelectionTest),
            14 => Some(SectionKind::Monitor),
            _ => None,
        }
    }

    /// Index into [`SectionKind::ALL`] (its position there; tags need not be contiguous).
    pub const fn index(self) -> usize {
        let mut i = 0;
        while i < Self::ALL.len() {
            if Self::ALL[i] as u16 == self as u16 {
                return i;
            }
            i += 1;
        }
        Self::ALL.len()
    }

    /// Short lowercase name, as `inspect` prints it.
    pub const fn name(self) -> &'static str {
        match self {
            SectionKind::Locations => "locations",
            SectionKind::Fallback => "fallback",
            SectionKind::Trajectories => "trajectories",
            SectionKind::Segments => "segments",
            SectionKind::Steps => "steps",
            SectionKind::PwaLaws => "pwa_laws",
            SectionKind::PwaTree => "pwa_tree",
            SectionKind::PwaBalls => "pwa_balls",
            SectionKind::SegmentExits => "segment_exits",
            SectionKind::ModelMaps => "model_maps",
            SectionKind::TerminalLaw => "terminal_law",
            SectionKind::SpecFingerprint => "spec_fingerprint",
            SectionKind::SelectionTest => "selection_test",
            SectionKind::Monitor => "monitor",
        }
    }
}

impl core::fmt::Display for SectionKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{} section ({})", self.name(), *self as u16)
    }
}

impl core::fmt::Display for Mode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Mode::Feedforward => "feedforward",
            Mode::PwaFeedback => "PWA feedback",
        })
    }
}
