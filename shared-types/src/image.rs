//! The controller image: its byte layout, `encode` and the validating, zero-copy `decode` (DESIGN §4).
//!
//! # Layout
//! An image is a fixed 32-byte little-endian header followed by a postcard payload.
//!
//! | bytes  | field                                                                 |
//! |--------|-----------------------------------------------------------------------|
//! | 0..4   | [`MAGIC`]                                                             |
//! | 4..6   | format version, [`FORMAT_VERSION`]                                    |
//! | 6      | mode ([`Mode`])                                                       |
//! | 7      | reserved, 0                                                           |
//! | 8..18  | `n`, `m`, locations, trajectories, partitions (five `u16`)            |
//! | 18..20 | reserved, 0                                                           |
//! | 20..24 | sample period in seconds (`f32`)                                      |
//! | 24..28 | payload length in bytes (`u32`)                                       |
//! | 28..32 | CRC-32/ISO-HDLC of header bytes 0..28 followed by the payload (`u32`) |
//!
//! The CRC is seeded with the header's first 28 bytes so that a corrupted period or dimension is caught as
//! surely as a corrupted payload byte.
//!
//! The payload is a postcard-serialised [`Payload`] (feedforward, mode 1) or [`PwaPayload`] (PWA feedback,
//! mode 2); the header's mode byte says which. Every float array is a byte string of little-endian
//! `f32` values (row-major matrices), borrowed in place by [`decode`], so decoding neither copies nor
//! allocates. Postcard encodings are canonical here: `decode` rejects a payload whose re-encoding would not
//! have exactly its length (overlong varints), so one content has exactly one byte string.
//!
//! # Feedforward content (Algorithm 2, with the law (3.5)–(3.6))
//! * per location ℓ: the gain `K_ℓ` (m×n) and the CAF metric `P_ℓ` (n×n, symmetric positive definite);
//! * per trajectory i: the ball centre `x̃_i(0)`, its radius `δ_i` in the metric of `P_{ℓ_i(0)}`, and a run
//!   of rows of the step table; row κ of trajectory i holds `v_i(κ) = ũ_i(κ) − K x̃_i(κ)` (m values) and the
//!   nominal location index `ℓ_i(κ)` (one byte), so hybrid plants fit ((4.41)–(4.42));
//! * the fallback law, an optional input box, and the terminal behaviour past the end of a trajectory.
//!
//! # PWA-feedback content (Ch. 6, the law (6.1) on the envelope F of (6.2))
//! * per location ℓ: `K_ℓ` and `P_ℓ` as above (`P_ℓ` is the metric of the certified balls; `K_ℓ` is the CAF
//!   gain the laws were learned around, kept so that `θ_j = K_j − K` can be reported);
//! * the [`crate::pwa::PwaTables`]: per partition the full gain `K_j = K + θ_j` and offset `θ0_j`, the
//!   point-location tree, its leaves, the certified balls (centre; whitened centre and squared threshold,
//!   one record per ball) and per location
//!   the upper-triangular factor `R_ℓ` of `P_ℓ` used by the whitened ball test (layout, rationale and
//!   rounding analysis in [`crate::pwa`]);
//! * the fallback law and an optional input box. There are no trajectories (`trajectories = 0` in the
//!   header) and no terminal behaviour.
//!
//! # Validation
//! [`decode`] and [`Image::new`] check, before anything can read the data: magic, version, reserved bytes,
//! lengths, CRC, mode, dimensions against [`crate::capacity`], every field's byte length, every float finite,
//! `P` symmetric and positive definite, `δ ≥ 0`, trajectory ends strictly increasing (every trajectory has
//! at least one step) with the total within capacity, location indices in range, and the input box
//! non-empty; for PWA images also everything listed in [`crate::pwa`] (tree well-formed and within depth,
//! indices in range, stored depth exact). An [`Image`] can only be obtained through them, so its accessors
//! never meet bad data.
#![allow(non_snake_case)]

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::capacity::{
    HEADER_LEN, MAX_LOCATIONS, MAX_M, MAX_N, MAX_PARTITIONS, MAX_STEPS, MAX_TRAJECTORIES,
};
use crate::pwa::PwaTables;

/// First four bytes of every image ("safe controller image").
pub const MAGIC: [u8; 4] = *b"SFCI";
/// Version of the layout described in this module. Decoding rejects every other version. Version 2 added
/// the whitened ball test of PWA images (per-location factor `R`, whitened ball centres; [`crate::pwa`]).
/// Version 3 stores PWA tree nodes as one record each (`a`, `b`, children) and each ball's test data as one
/// record (whitened centre and squared threshold ŝ instead of the radius ρ̂).
pub const FORMAT_VERSION: u16 = 3;

/// Byte offset of the CRC in the header; the CRC covers the header bytes before it and the payload.
const CRC_OFFSET: usize = 28;

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// How the controller computes its input.
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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
}

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
}

/// Componentwise input bounds `lo ≤ u ≤ hi` (m values each, little-endian `f32`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputBox<'a> {
    /// Lower bounds.
    pub lo: &'a [u8],
    /// Upper bounds.
    pub hi: &'a [u8],
}

/// The postcard payload, as raw borrowed byte strings. Fill it to build an image, then pass it to
/// [`Image::new`], which validates it; nothing reads a `Payload` that has not been validated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Payload<'a> {
    /// `K_ℓ` for each location ℓ: locations × m × n values, each m×n block row-major.
    pub K: &'a [u8],
    /// `P_ℓ` for each location ℓ: locations × n × n values.
    pub P: &'a [u8],
    /// Exclusive end row of each trajectory in the step table (`u32` little-endian, one per trajectory).
    /// Trajectory i owns rows `end[i-1]..end[i]` (with `end[-1] = 0`).
    pub traj_end: &'a [u8],
    /// Ball centres `x̃_i(0)`: trajectories × n values.
    pub centre: &'a [u8],
    /// Ball radii `δ_i`: one value per trajectory.
    pub delta: &'a [u8],
    /// Step table `v`: rows × m values.
    pub v: &'a [u8],
    /// Nominal location of each row (one byte per row).
    pub location: &'a [u8],
    /// Fallback law.
    #[serde(borrow)]
    pub fallback: Fallback<'a>,
    /// Optional input box, used to saturate the linear fallback.
    #[serde(borrow)]
    pub input_box: Option<InputBox<'a>>,
    /// Behaviour past the end of a trajectory.
    pub terminal: Terminal,
}

/// The postcard payload of a PWA-feedback image (mode 2), as raw borrowed byte strings. Build one and pass
/// it to [`Image::new_pwa`], which validates it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PwaPayload<'a> {
    /// `K_ℓ` for each location ℓ (the CAF gain; not used by the evaluator in this mode).
    pub K: &'a [u8],
    /// `P_ℓ` for each location ℓ: the metric of the certified balls.
    pub P: &'a [u8],
    /// Laws, tree, leaves and balls.
    #[serde(borrow)]
    pub tables: PwaTables<'a>,
    /// Fallback law.
    #[serde(borrow)]
    pub fallback: Fallback<'a>,
    /// Optional input box, used to saturate the linear fallback.
    #[serde(borrow)]
    pub input_box: Option<InputBox<'a>>,
}

/// Dimensions of an image.
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

/// The fixed header as read from the bytes, after checking only length, magic, version and reserved
/// bytes (see [`Header::parse`]); the rest is checked by [`decode`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    /// Format version (equal to [`FORMAT_VERSION`] once parsed).
    pub version: u16,
    /// Raw mode byte (see [`Mode::from_u8`]).
    pub mode: u8,
    /// Dimensions as declared.
    pub dims: Dims,
    /// Sample period, seconds, as stored (not yet checked).
    pub period: f32,
    /// Payload length declared by the header.
    pub payload_len: u32,
    /// CRC stored in the header.
    pub crc: u32,
}

/// Which dimension an [`ImageError::DimOutOfRange`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dim {
    /// `n`.
    N,
    /// `m`.
    M,
    /// Number of locations.
    Locations,
    /// Number of trajectories.
    Trajectories,
    /// Number of partitions.
    Partitions,
    /// Total rows of the step table.
    Steps,
    /// Internal nodes of the PWA tree.
    TreeNodes,
    /// Leaves of the PWA tree.
    Leaves,
    /// Certified balls of a PWA image.
    Balls,
    /// Ball references summed over all leaves.
    BallRefs,
    /// Stored worst-case depth of the PWA tree.
    TreeDepth,
}

/// Which payload field an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Field {
    /// Feedback gains `K_ℓ`.
    K,
    /// CAF metrics `P_ℓ`.
    P,
    /// Trajectory end rows.
    TrajEnd,
    /// Ball centres.
    Centre,
    /// Ball radii.
    Delta,
    /// Step table `v`.
    V,
    /// Per-row location indices.
    Location,
    /// Fallback gain `K_fb`.
    FallbackK,
    /// Fallback `x_ref`.
    FallbackXRef,
    /// Fallback `u_ref`.
    FallbackURef,
    /// Input box lower bounds.
    BoxLo,
    /// Input box upper bounds.
    BoxHi,
    /// PWA gains `K_j = K + θ_j`.
    LawGain,
    /// PWA offsets `θ0_j`.
    LawOffset,
    /// Tree node records `[a, b, left, right]` (the length check).
    Node,
    /// Hyperplane normals `a` of the tree nodes (within their records).
    NodeNormal,
    /// Hyperplane offsets `b` of the tree nodes (within their records).
    NodeOffset,
    /// Partition of each leaf.
    LeafPartition,
    /// Exclusive end of each leaf's run of ball references.
    LeafEnd,
    /// Ball references of the leaves.
    BallRef,
    /// Certified ball centres.
    BallCentre,
    /// Location (metric) of each certified ball.
    BallLocation,
    /// Partition (law) each certified ball is certified for.
    BallPartition,
    /// Upper-triangular factors `R_ℓ` (`P_ℓ = R_ℓᵀR_ℓ`) of the PWA ball test.
    Factor,
    /// Ball test records `[c_z, ŝ]` (the length check).
    BallTest,
    /// Whitened ball centres `c_z = fl32(R̂ c)` (within the test records).
    BallCentreZ,
    /// Squared ball thresholds ŝ (within the test records).
    BallThreshold,
}

/// Position of a bad value. Its meaning depends on the field: `K`, `P`: (location, row, col); `Centre`:
/// (trajectory, component, 0); `Delta`: (trajectory, 0, 0); `V`: (trajectory, step, component);
/// `FallbackK`: (row, col, 0); `LawGain`: (partition, row, col); `LawOffset`: (partition, component, 0);
/// `NodeNormal`: (node, component, 0); `NodeOffset`: (node, 0, 0); `BallCentre`, `BallCentreZ`: (ball,
/// component, 0); `BallThreshold`: (ball, 0, 0); `Factor`: (location, row, col); vectors: (component, 0, 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pos(pub u16, pub u16, pub u16);

/// Why an image was rejected. Small and `Copy`; `Display` says what is wrong in words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageError {
    /// Fewer bytes than the header.
    Truncated {
        /// Bytes present.
        len: u32,
    },
    /// The first four bytes are not [`MAGIC`].
    BadMagic {
        /// What was found.
        found: [u8; 4],
    },
    /// A format version this build does not read.
    UnsupportedVersion {
        /// What was found.
        found: u16,
    },
    /// A reserved header byte is not zero.
    ReservedNotZero,
    /// The mode byte is not a known mode.
    UnknownMode {
        /// What was found.
        found: u8,
    },
    /// A known mode this build does not evaluate, or [`Image::new`] given a mode whose payload it does not
    /// take (PWA images are built with [`Image::new_pwa`]).
    UnsupportedMode {
        /// The mode.
        mode: Mode,
    },
    /// The header's payload length disagrees with the bytes present.
    PayloadLength {
        /// Length declared in the header.
        header: u32,
        /// Bytes present after the header.
        actual: u32,
    },
    /// The stored CRC does not match the content.
    CrcMismatch {
        /// CRC in the header.
        stored: u32,
        /// CRC computed from the bytes.
        computed: u32,
    },
    /// A dimension outside `min..=max`.
    DimOutOfRange {
        /// Which dimension.
        dim: Dim,
        /// Its value.
        value: u32,
        /// Smallest allowed.
        min: u32,
        /// Largest allowed.
        max: u32,
    },
    /// The sample period is not finite and positive.
    BadPeriod,
    /// The payload is not a postcard `Payload`.
    Malformed,
    /// Bytes are left after the payload.
    TrailingBytes,
    /// The payload decodes but is not in canonical postcard form.
    NotCanonical,
    /// A field's byte length does not match the dimensions.
    FieldLength {
        /// Which field.
        field: Field,
        /// Expected bytes.
        expected: u32,
        /// Bytes present.
        found: u32,
    },
    /// A float is NaN or infinite.
    NonFinite {
        /// Which field.
        field: Field,
        /// Where.
        pos: Pos,
    },
    /// `P_ℓ` is not exactly symmetric.
    NotSymmetric {
        /// Location.
        location: u16,
        /// Row.
        row: u16,
        /// Column.
        col: u16,
    },
    /// `P_ℓ` is not positive definite.
    NotPositiveDefinite {
        /// Location.
        location: u16,
    },
    /// Trajectory ends are not strictly increasing (an empty trajectory, or out of order).
    TrajectoryEnds {
        /// The offending trajectory.
        trajectory: u16,
    },
    /// A ball radius is negative.
    NegativeDelta {
        /// The trajectory.
        trajectory: u16,
    },
    /// A row's location index is not below the number of locations.
    LocationOutOfRange {
        /// Trajectory.
        trajectory: u16,
        /// Step within the trajectory.
        step: u16,
        /// The index found.
        value: u8,
    },
    /// The input box has `lo > hi` in some component.
    EmptyInputBox {
        /// The component.
        input: u16,
    },
    /// A tree node's child names a node index at or past the node count.
    ChildOutOfRange {
        /// The parent node.
        node: u16,
        /// The child's node index.
        child: u16,
    },
    /// A tree node's child is a node whose index is not greater than its own: a back edge (the rule
    /// "children after parents" is what excludes cycles and bounds every path).
    BackEdge {
        /// The parent node.
        node: u16,
        /// The child's node index.
        child: u16,
    },
    /// A tree node's child names a leaf index at or past the leaf count.
    LeafOutOfRange {
        /// The parent node.
        node: u16,
        /// The leaf index.
        leaf: u16,
    },
    /// No path from the root reaches this node.
    UnreachableNode {
        /// The node.
        node: u16,
    },
    /// No node refers to this leaf (with no nodes, the tree is leaf 0 alone).
    UnreferencedLeaf {
        /// The leaf.
        leaf: u16,
    },
    /// A path from the root reaches this node after [`crate::capacity::MAX_TREE_DEPTH`] tests already.
    TreeTooDeep {
        /// The first node found too deep.
        node: u16,
    },
    /// The stored worst-case depth is not the tree's.
    TreeDepthMismatch {
        /// Depth stored in the image.
        stored: u8,
        /// Depth of the tree.
        actual: u8,
    },
    /// A hyperplane normal is zero (the test would be constant).
    DegenerateHyperplane {
        /// The node.
        node: u16,
    },
    /// A leaf's partition index is not below the number of partitions.
    PartitionOutOfRange {
        /// The leaf.
        leaf: u16,
        /// The index found.
        value: u16,
    },
    /// Leaf ball ends are not strictly increasing (a leaf without balls, or out of order).
    LeafBallEnds {
        /// The offending leaf.
        leaf: u16,
    },
    /// A leaf lists more than [`crate::capacity::MAX_LEAF_BALLS`] balls.
    LeafTooManyBalls {
        /// The leaf.
        leaf: u16,
        /// How many it lists.
        count: u16,
    },
    /// A leaf refers to a ball index not below the number of balls.
    BallRefOutOfRange {
        /// The leaf.
        leaf: u16,
        /// The index found.
        value: u16,
    },
    /// A ball's location index is not below the number of locations.
    BallLocationOutOfRange {
        /// The ball.
        ball: u16,
        /// The index found.
        value: u8,
    },
    /// A ball's partition index is not below the number of partitions.
    BallPartitionOutOfRange {
        /// The ball.
        ball: u16,
        /// The index found.
        value: u16,
    },
    /// A certified ball has a negative squared threshold ŝ.
    NegativeBallThreshold {
        /// The ball.
        ball: u16,
    },
    /// The factor `R_ℓ` of a PWA ball test has a non-zero entry below its diagonal.
    FactorNotUpperTriangular {
        /// Location.
        location: u16,
        /// Row.
        row: u16,
        /// Column (< row).
        col: u16,
    },
    /// The factor `R_ℓ` of a PWA ball test has a diagonal entry that is not positive.
    FactorDiagonal {
        /// Location.
        location: u16,
        /// Row (= column) of the entry.
        row: u16,
    },
    /// The output buffer of [`encode`] is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: u32,
    },
    /// Postcard failed to serialise the payload.
    Encode,
}

impl fmt::Display for Dim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Dim::N => "state dimension n",
            Dim::M => "input dimension m",
            Dim::Locations => "number of locations",
            Dim::Trajectories => "number of trajectories",
            Dim::Partitions => "number of partitions",
            Dim::Steps => "total table rows",
            Dim::TreeNodes => "number of tree nodes",
            Dim::Leaves => "number of leaves",
            Dim::Balls => "number of certified balls",
            Dim::BallRefs => "total ball references",
            Dim::TreeDepth => "tree depth",
        })
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Field::K => "K",
            Field::P => "P",
            Field::TrajEnd => "trajectory ends",
            Field::Centre => "ball centres",
            Field::Delta => "delta",
            Field::V => "v",
            Field::Location => "locations",
            Field::FallbackK => "fallback K",
            Field::FallbackXRef => "fallback x_ref",
            Field::FallbackURef => "fallback u_ref",
            Field::BoxLo => "input box lower bounds",
            Field::BoxHi => "input box upper bounds",
            Field::LawGain => "law gain K_j",
            Field::LawOffset => "law offset theta0_j",
            Field::Node => "tree node records",
            Field::NodeNormal => "node normal a",
            Field::NodeOffset => "node offset b",
            Field::LeafPartition => "leaf partitions",
            Field::LeafEnd => "leaf ball ends",
            Field::BallRef => "ball references",
            Field::BallCentre => "ball centres",
            Field::BallLocation => "ball locations",
            Field::BallPartition => "ball partitions",
            Field::Factor => "factor R",
            Field::BallTest => "ball test records",
            Field::BallCentreZ => "whitened ball centres",
            Field::BallThreshold => "ball thresholds",
        })
    }
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Mode::Feedforward => "feedforward",
            Mode::PwaFeedback => "PWA feedback",
        })
    }
}

impl fmt::Display for ImageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use ImageError::*;
        match *self {
            Truncated { len } => {
                write!(f, "truncated: {len} bytes, shorter than the {HEADER_LEN}-byte header")
            }
            BadMagic { found } => write!(f, "bad magic: expected {MAGIC:02x?}, found {found:02x?}"),
            UnsupportedVersion { found } => write!(
                f,
                "unsupported format version {found} (this build reads version {FORMAT_VERSION})"
            ),
            ReservedNotZero => f.write_str("a reserved header byte is not zero"),
            UnknownMode { found } => write!(f, "unknown mode {found}"),
            UnsupportedMode { mode } => {
                write!(f, "mode {} ({mode}) is not supported here", mode as u8)
            }
            PayloadLength { header, actual } => write!(
                f,
                "payload length: header says {header} bytes, {actual} bytes follow the header"
            ),
            CrcMismatch { stored, computed } => write!(
                f,
                "CRC mismatch: header says {stored:#010x}, content has {computed:#010x}"
            ),
            DimOutOfRange { dim, value, min, max } => {
                write!(f, "{dim} is {value}, allowed {min}..={max}")
            }
            BadPeriod => f.write_str("sample period is not finite and positive"),
            Malformed => f.write_str("payload is not a valid postcard encoding of the content"),
            TrailingBytes => f.write_str("bytes left over after the payload"),
            NotCanonical => f.write_str("payload is not in canonical postcard form"),
            FieldLength { field, expected, found } => {
                write!(f, "{field}: expected {expected} bytes, found {found}")
            }
            NonFinite { field, pos: Pos(a, b, c) } => match field {
                Field::K | Field::P | Field::Factor => {
                    write!(f, "location {a}: {field}[{b},{c}] is not finite")
                }
                Field::Centre => write!(f, "trajectory {a}: centre[{b}] is not finite"),
                Field::Delta => write!(f, "trajectory {a}: delta is not finite"),
                Field::V => write!(f, "trajectory {a} step {b}: v[{c}] is not finite"),
                Field::FallbackK => write!(f, "fallback K[{a},{b}] is not finite"),
                Field::LawGain => write!(f, "partition {a}: K_j[{b},{c}] is not finite"),
                Field::LawOffset => write!(f, "partition {a}: theta0_j[{b}] is not finite"),
                Field::NodeNormal => write!(f, "node {a}: a[{b}] is not finite"),
                Field::NodeOffset => write!(f, "node {a}: b is not finite"),
                Field::BallCentre => write!(f, "ball {a}: centre[{b}] is not finite"),
                Field::BallCentreZ => write!(f, "ball {a}: whitened centre[{b}] is not finite"),
                Field::BallThreshold => write!(f, "ball {a}: threshold is not finite"),
                _ => write!(f, "{field}[{a}] is not finite"),
            },
            NotSymmetric { location, row, col } => write!(
                f,
                "location {location}: P is not symmetric (P[{row},{col}] != P[{col},{row}])"
            ),
            NotPositiveDefinite { location } => {
                write!(f, "location {location}: P is not positive definite")
            }
            TrajectoryEnds { trajectory } => write!(
                f,
                "trajectory {trajectory}: end row is not after the previous one (empty or out of order)"
            ),
            NegativeDelta { trajectory } => write!(f, "trajectory {trajectory}: delta is negative"),
            LocationOutOfRange { trajectory, step, value } => write!(
                f,
                "trajectory {trajectory} step {step}: location {value} is out of range"
            ),
            EmptyInputBox { input } => write!(f, "input box component {input}: lower bound above upper"),
            ChildOutOfRange { node, child } => write!(
                f,
                "tree node {node}: child node {child} is out of range"
            ),
            BackEdge { node, child } => write!(
                f,
                "tree node {node}: child node {child} does not come after its parent (back edge)"
            ),
            LeafOutOfRange { node, leaf } => {
                write!(f, "tree node {node}: leaf {leaf} is out of range")
            }
            UnreachableNode { node } => write!(f, "tree node {node} is unreachable from the root"),
            UnreferencedLeaf { leaf } => write!(f, "leaf {leaf} is not referenced by the tree"),
            TreeTooDeep { node } => write!(
                f,
                "tree node {node} lies deeper than {} hyperplane tests",
                crate::capacity::MAX_TREE_DEPTH
            ),
            TreeDepthMismatch { stored, actual } => write!(
                f,
                "stored tree depth {stored} differs from the tree's depth {actual}"
            ),
            DegenerateHyperplane { node } => {
                write!(f, "tree node {node}: hyperplane normal is zero")
            }
            PartitionOutOfRange { leaf, value } => {
                write!(f, "leaf {leaf}: partition {value} is out of range")
            }
            LeafBallEnds { leaf } => write!(
                f,
                "leaf {leaf}: ball end is not after the previous one (no balls, or out of order)"
            ),
            LeafTooManyBalls { leaf, count } => write!(
                f,
                "leaf {leaf} lists {count} balls, more than {}",
                crate::capacity::MAX_LEAF_BALLS
            ),
            BallRefOutOfRange { leaf, value } => {
                write!(f, "leaf {leaf}: ball {value} is out of range")
            }
            BallLocationOutOfRange { ball, value } => {
                write!(f, "ball {ball}: location {value} is out of range")
            }
            BallPartitionOutOfRange { ball, value } => {
                write!(f, "ball {ball}: partition {value} is out of range")
            }
            NegativeBallThreshold { ball } => write!(f, "ball {ball}: threshold is negative"),
            FactorNotUpperTriangular { location, row, col } => write!(
                f,
                "location {location}: factor R is not upper triangular (R[{row},{col}] != 0)"
            ),
            FactorDiagonal { location, row } => write!(
                f,
                "location {location}: factor R has a non-positive diagonal entry R[{row},{row}]"
            ),
            BufferTooSmall { needed } => write!(f, "output buffer too small: {needed} bytes needed"),
            Encode => f.write_str("payload could not be serialised"),
        }
    }
}

impl core::error::Error for ImageError {}

// ---------------------------------------------------------------------------------------------------------
// Little helpers. All are total: out-of-range reads give 0.0 instead of panicking (validated images never
// take that path).

#[inline(always)]
pub(crate) fn f32_at(bytes: &[u8], i: usize) -> f32 {
    let Some(s) = i.checked_mul(4) else {
        return 0.0;
    };
    match bytes.get(s..s.wrapping_add(4)) {
        Some(&[a, b, c, d]) => f32::from_le_bytes([a, b, c, d]),
        _ => 0.0,
    }
}

#[inline(always)]
fn u32_at(bytes: &[u8], i: usize) -> u32 {
    let Some(s) = i.checked_mul(4) else { return 0 };
    match bytes.get(s..s.wrapping_add(4)) {
        Some(&[a, b, c, d]) => u32::from_le_bytes([a, b, c, d]),
        _ => 0,
    }
}

#[inline(always)]
fn u16_at(bytes: &[u8], off: usize) -> u16 {
    match bytes.get(off..off.saturating_add(2)) {
        Some(&[a, b]) => u16::from_le_bytes([a, b]),
        _ => 0,
    }
}

/// `bytes[4*start .. 4*(start+len)]`, or an empty slice if out of range.
#[inline(always)]
pub(crate) fn f32_span(bytes: &[u8], start: usize, len: usize) -> &[u8] {
    let s = start.saturating_mul(4);
    let e = start.saturating_add(len).saturating_mul(4);
    bytes.get(s..e).unwrap_or(&[])
}

/// Little-endian `f32` values of a byte string (a trailing partial value is ignored).
#[inline(always)]
pub(crate) fn floats(bytes: &[u8]) -> impl Iterator<Item = f32> + '_ {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
}

/// Little-endian `u16` number `i` of a byte string; 0 out of range.
#[inline(always)]
pub(crate) fn u16_le(bytes: &[u8], i: usize) -> u16 {
    u16_at(bytes, i.saturating_mul(2))
}

/// `a / b`, 0 if `b` is 0 (total, so position reporting has no panic path).
pub(crate) fn div(a: usize, b: usize) -> usize {
    a.checked_div(b).unwrap_or(0)
}

/// `a % b`, 0 if `b` is 0.
pub(crate) fn rem(a: usize, b: usize) -> usize {
    a.checked_rem(b).unwrap_or(0)
}

pub(crate) fn sat16(v: usize) -> u16 {
    u16::try_from(v).unwrap_or(u16::MAX)
}

pub(crate) fn sat32(v: usize) -> u32 {
    u32::try_from(v).unwrap_or(u32::MAX)
}

/// CRC over the header bytes before the CRC field and the payload.
fn crc_of(header_prefix: &[u8], payload: &[u8]) -> u32 {
    let mut d = CRC32.digest();
    d.update(header_prefix);
    d.update(payload);
    d.finalize()
}

/// The CRC that the header of `bytes` should carry for its current content (header bytes 0..28 and all
/// bytes after the header). Used by tools that patch images; errors if shorter than the header.
pub fn compute_crc(bytes: &[u8]) -> Result<u32, ImageError> {
    match (bytes.get(..CRC_OFFSET), bytes.get(HEADER_LEN..)) {
        (Some(prefix), Some(payload)) => Ok(crc_of(prefix, payload)),
        _ => Err(ImageError::Truncated {
            len: sat32(bytes.len()),
        }),
    }
}

impl Header {
    /// Reads the fixed header. Checks only what is needed to trust the layout: length, magic, version and
    /// reserved bytes.
    pub fn parse(bytes: &[u8]) -> Result<Header, ImageError> {
        let Some(h) = bytes.get(..HEADER_LEN) else {
            return Err(ImageError::Truncated {
                len: sat32(bytes.len()),
            });
        };
        let magic = [h[0], h[1], h[2], h[3]];
        if magic != MAGIC {
            return Err(ImageError::BadMagic { found: magic });
        }
        let version = u16_at(h, 4);
        if version != FORMAT_VERSION {
            return Err(ImageError::UnsupportedVersion { found: version });
        }
        if h[7] != 0 || u16_at(h, 18) != 0 {
            return Err(ImageError::ReservedNotZero);
        }
        Ok(Header {
            version,
            mode: h[6],
            dims: Dims {
                n: u16_at(h, 8) as usize,
                m: u16_at(h, 10) as usize,
                n_locations: u16_at(h, 12) as usize,
                n_trajectories: u16_at(h, 14) as usize,
                n_partitions: u16_at(h, 16) as usize,
            },
            // u32_at indexes 4-byte words: word 5 is bytes 20..24, 6 is 24..28, 7 is 28..32.
            period: f32::from_bits(u32_at(h, 5)),
            payload_len: u32_at(h, 6),
            crc: u32_at(h, 7),
        })
    }
}

// ---------------------------------------------------------------------------------------------------------
// The validated image.

/// A validated image: obtainable only from [`decode`], [`Image::new`] or [`Image::new_pwa`], so every
/// accessor reads data that passed all checks. Borrows the bytes it was decoded from; `Copy` (a handful of
/// slices).
///
/// Both modes keep the shared fields (`K`, `P`, fallback, input box) in a [`Payload`]; for a PWA image its
/// trajectory fields are empty and its terminal is [`Terminal::HoldLast`] (unused), and the PWA tables are
/// in [`Image::pwa`] (empty for a feedforward image).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Image<'a> {
    pub(crate) mode: Mode,
    pub(crate) dims: Dims,
    pub(crate) period: f32,
    pub(crate) payload: Payload<'a>,
    pub(crate) pwa: PwaTables<'a>,
}

pub(crate) fn check_dim(dim: Dim, value: usize, min: usize, max: usize) -> Result<(), ImageError> {
    if value < min || value > max {
        Err(ImageError::DimOutOfRange {
            dim,
            value: sat32(value),
            min: sat32(min),
            max: sat32(max),
        })
    } else {
        Ok(())
    }
}

pub(crate) fn check_len(field: Field, bytes: &[u8], expected: usize) -> Result<(), ImageError> {
    if bytes.len() != expected {
        Err(ImageError::FieldLength {
            field,
            expected: sat32(expected),
            found: sat32(bytes.len()),
        })
    } else {
        Ok(())
    }
}

/// Checks that every `f32` in `bytes` is finite; `pos(i)` maps the flat index to a position.
pub(crate) fn check_finite(
    field: Field,
    bytes: &[u8],
    pos: impl Fn(usize) -> Pos,
) -> Result<(), ImageError> {
    for (i, x) in floats(bytes).enumerate() {
        if !x.is_finite() {
            return Err(ImageError::NonFinite { field, pos: pos(i) });
        }
    }
    Ok(())
}

/// Positive definiteness of a symmetric n×n matrix (n ≤ MAX_N) by an LDLᵀ factorisation without pivoting,
/// in f64 so that the verdict on the stored f32 values is not itself an f32 rounding artefact. The matrix
/// is positive definite iff every pivot d_j is positive. Hand-written: it is a dozen lines, runs once per
/// location at decode, and must be no_std without allocation.
fn positive_definite(p: &[u8], n: usize) -> bool {
    let mut L = [[0.0f64; MAX_N]; MAX_N];
    let mut d = [0.0f64; MAX_N];
    let n = n.min(MAX_N);
    for j in 0..n {
        let mut dj = f32_at(p, j * n + j) as f64;
        for k in 0..j {
            dj -= L[j][k] * L[j][k] * d[k];
        }
        let pivot_ok = dj.is_finite() && dj > 0.0;
        if !pivot_ok {
            return false;
        }
        d[j] = dj;
        for i in (j + 1)..n {
            let mut s = f32_at(p, i * n + j) as f64;
            for k in 0..j {
                s -= L[i][k] * L[j][k] * d[k];
            }
            L[i][j] = s / dj;
        }
    }
    true
}

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

fn validate(mode: Mode, dims: Dims, period: f32, p: &Payload<'_>) -> Result<(), ImageError> {
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
    validate_K_P(n, m, nl, p.K, p.P)?;

    // Trajectory ends: strictly increasing (no empty trajectory), total within capacity.
    check_len(Field::TrajEnd, p.traj_end, 4 * nt)?;
    let mut prev = 0u32;
    for t in 0..nt {
        let e = u32_at(p.traj_end, t);
        if e <= prev {
            return Err(ImageError::TrajectoryEnds {
                trajectory: sat16(t),
            });
        }
        if e as usize > MAX_STEPS {
            return Err(ImageError::DimOutOfRange {
                dim: Dim::Steps,
                value: e,
                min: 1,
                max: sat32(MAX_STEPS),
            });
        }
        prev = e;
    }
    let rows = prev as usize;

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

    // Step table: v (3.6) and the nominal location of each row.
    check_len(Field::V, p.v, 4 * rows * m)?;
    check_len(Field::Location, p.location, rows)?;
    let mut start = 0usize;
    for t in 0..nt {
        let end = u32_at(p.traj_end, t) as usize;
        let vt = f32_span(p.v, start * m, (end - start) * m);
        check_finite(Field::V, vt, |i| {
            Pos(sat16(t), sat16(div(i, m)), sat16(rem(i, m)))
        })?;
        let lt = p.location.get(start..end).unwrap_or(&[]);
        for (s, &l) in lt.iter().enumerate() {
            if l as usize >= nl {
                return Err(ImageError::LocationOutOfRange {
                    trajectory: sat16(t),
                    step: sat16(s),
                    value: l,
                });
            }
        }
        start = end;
    }
    validate_fallback_box(n, m, p.fallback, p.input_box)
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
    }
    Ok(())
}

impl<'a> Image<'a> {
    /// Validates `payload` against `mode`, `dims` and `period` and wraps it. This is how the host builds an
    /// image before [`encode`]; it runs exactly the checks [`decode`] runs on the payload.
    pub fn new(
        mode: Mode,
        dims: Dims,
        period: f32,
        payload: Payload<'a>,
    ) -> Result<Self, ImageError> {
        validate(mode, dims, period, &payload)?;
        Ok(Image {
            mode,
            dims,
            period,
            payload,
            pwa: PwaTables::EMPTY,
        })
    }

    /// Validates a PWA-feedback payload against `dims` and `period` and wraps it (mode
    /// [`Mode::PwaFeedback`]); it runs exactly the checks [`decode`] runs on such a payload.
    pub fn new_pwa(dims: Dims, period: f32, payload: PwaPayload<'a>) -> Result<Self, ImageError> {
        validate_pwa(dims, period, &payload)?;
        Ok(Image {
            mode: Mode::PwaFeedback,
            dims,
            period,
            payload: Payload {
                K: payload.K,
                P: payload.P,
                traj_end: &[],
                centre: &[],
                delta: &[],
                v: &[],
                location: &[],
                fallback: payload.fallback,
                input_box: payload.input_box,
                terminal: Terminal::HoldLast,
            },
            pwa: payload.tables,
        })
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
    /// The raw payload (validated). For a PWA image only `K`, `P`, `fallback` and `input_box` are
    /// meaningful (the trajectory fields are empty); its tables are [`Image::pwa`].
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
        self.payload.location.len()
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

    /// First table row and number of rows of a trajectory; `(0, 0)` out of range.
    pub fn trajectory_rows(&self, trajectory: usize) -> (usize, usize) {
        if trajectory >= self.dims.n_trajectories {
            return (0, 0);
        }
        let start = if trajectory == 0 {
            0
        } else {
            u32_at(self.payload.traj_end, trajectory - 1) as usize
        };
        let end = u32_at(self.payload.traj_end, trajectory) as usize;
        (start, end.saturating_sub(start))
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

    /// Nominal location `ℓ_t(step)`; 0 out of range.
    pub fn location(&self, trajectory: usize, step: usize) -> usize {
        let (start, len) = self.trajectory_rows(trajectory);
        if step >= len {
            return 0;
        }
        self.payload
            .location
            .get(start + step)
            .copied()
            .unwrap_or(0) as usize
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

    /// Fallback `u_ref[j]`; 0.0 if not linear or out of range.
    pub fn fallback_u_ref(&self, j: usize) -> f32 {
        match self.payload.fallback {
            Fallback::Linear { u_ref, .. } if j < self.dims.m => f32_at(u_ref, j),
            _ => 0.0,
        }
    }

    /// Input box bounds `(lo_j, hi_j)`, if a box is stored and `j < m`.
    pub fn input_bounds(&self, j: usize) -> Option<(f32, f32)> {
        match self.payload.input_box {
            Some(b) if j < self.dims.m => Some((f32_at(b.lo, j), f32_at(b.hi, j))),
            _ => None,
        }
    }

    /// Size of the encoded image (header and payload), in bytes.
    pub fn encoded_len(&self) -> Result<usize, ImageError> {
        let size = match self.mode {
            Mode::Feedforward => postcard::serialize_with_flavor(
                &self.payload,
                postcard::ser_flavors::Size::default(),
            ),
            Mode::PwaFeedback => postcard::serialize_with_flavor(
                &self.pwa_payload(),
                postcard::ser_flavors::Size::default(),
            ),
        }
        .map_err(|_| ImageError::Encode)?;
        Ok(HEADER_LEN + size)
    }
}

/// Decodes and validates an image, borrowing `bytes` (zero copy, no allocation, never panics).
///
/// Order of checks: header (length, magic, version, reserved), payload length, CRC, mode, dimensions and
/// period, postcard structure (no trailing bytes, canonical form), then the content (see module docs).
pub fn decode(bytes: &[u8]) -> Result<Image<'_>, ImageError> {
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
    match mode {
        Mode::Feedforward => {
            let payload: Payload<'_> = parse_canonical(payload_bytes)?;
            Image::new(mode, d, h.period, payload)
        }
        Mode::PwaFeedback => {
            let payload: PwaPayload<'_> = parse_canonical(payload_bytes)?;
            Image::new_pwa(d, h.period, payload)
        }
    }
}

/// Parses a postcard payload that must fill `bytes` exactly and be in canonical form.
fn parse_canonical<'a, T: Serialize + Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, ImageError> {
    let (payload, rest): (T, &[u8]) =
        postcard::take_from_bytes(bytes).map_err(|_| ImageError::Malformed)?;
    if !rest.is_empty() {
        return Err(ImageError::TrailingBytes);
    }
    let canonical =
        postcard::serialize_with_flavor(&payload, postcard::ser_flavors::Size::default())
            .map_err(|_| ImageError::Malformed)?;
    if canonical != bytes.len() {
        return Err(ImageError::NotCanonical);
    }
    Ok(payload)
}

/// Writes the image (header and payload) into `out` and returns the number of bytes written. No
/// allocation; fails with [`ImageError::BufferTooSmall`] if `out` is too short.
pub fn encode(image: &Image<'_>, out: &mut [u8]) -> Result<usize, ImageError> {
    let total = image.encoded_len()?;
    let payload_len = total - HEADER_LEN;
    let Some(buf) = out.get_mut(..total) else {
        return Err(ImageError::BufferTooSmall {
            needed: sat32(total),
        });
    };
    let Some((header, payload)) = buf.split_at_mut_checked(HEADER_LEN) else {
        return Err(ImageError::Encode);
    };
    let written = match image.mode {
        Mode::Feedforward => postcard::to_slice(&image.payload, payload),
        Mode::PwaFeedback => postcard::to_slice(&image.pwa_payload(), payload),
    }
    .map_err(|_| ImageError::Encode)?
    .len();
    if written != payload_len {
        return Err(ImageError::Encode);
    }
    let d = image.dims;
    header[0..4].copy_from_slice(&MAGIC);
    header[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    header[6] = image.mode as u8;
    header[7] = 0;
    header[8..10].copy_from_slice(&sat16(d.n).to_le_bytes());
    header[10..12].copy_from_slice(&sat16(d.m).to_le_bytes());
    header[12..14].copy_from_slice(&sat16(d.n_locations).to_le_bytes());
    header[14..16].copy_from_slice(&sat16(d.n_trajectories).to_le_bytes());
    header[16..18].copy_from_slice(&sat16(d.n_partitions).to_le_bytes());
    header[18..20].copy_from_slice(&[0, 0]);
    header[20..24].copy_from_slice(&image.period.to_le_bytes());
    header[24..28].copy_from_slice(&sat32(payload_len).to_le_bytes());
    let crc = crc_of(&header[..CRC_OFFSET], payload);
    header[28..32].copy_from_slice(&crc.to_le_bytes());
    Ok(total)
}
