//! Why an image is rejected: the small `Copy` error [`ImageError`] that decoding, validation and encoding
//! return, with [`Dim`], [`Field`] and [`Pos`] naming what is wrong and where, and their `Display` (DESIGN
//! §5). The enums grow with the format and are `#[non_exhaustive]`.

use core::fmt;

use crate::capacity::HEADER_LEN;
use crate::layout::{Mode, SectionKind, FORMAT_VERSION, MAGIC};

/// Which dimension an [`ImageError::DimOutOfRange`] is about.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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
    /// Segments of the feedforward table.
    Segments,
    /// Entries of the section directory.
    Sections,
    /// Bytes of a model program ([`crate::program`]).
    ProgramBytes,
    /// Constants of a model program.
    ProgramConsts,
    /// Input slots of a model program.
    ProgramInputs,
    /// Outputs of a model program.
    ProgramOutputs,
    /// Operand-stack depth of a model program.
    ProgramStack,
    /// The plant's state dimension `n_plant` of the model maps section.
    PlantN,
    /// The plant's input dimension `m_plant` of the model maps section.
    PlantM,
    /// The number of controller states `n_ext` (a dynamic extension) of the model maps section.
    ExtStates,
}

/// Which payload field an error is about.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Field {
    /// Feedback gains `K_ℓ`.
    K,
    /// CAF metrics `P_ℓ`.
    P,
    /// Exclusive end of each trajectory's run of segments.
    TrajEnd,
    /// Ball centres.
    Centre,
    /// Ball radii.
    Delta,
    /// Segment records of the feedforward table.
    Segment,
    /// Step table `v`.
    V,
    /// Fallback gain `K_fb`.
    FallbackK,
    /// Fallback `x_ref`.
    FallbackXRef,
    /// Fallback `u_ref`.
    FallbackURef,
    /// Constant fallback input `u`.
    FallbackInput,
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
    /// Segment-exit records (kind, â, b̂, θ).
    Exit,
    /// A model program as a whole (header, constant pool and code).
    Program,
    /// The constant pool of a model program.
    ProgramConst,
    /// The spec fingerprint's hashes.
    Fingerprint,
    /// The model maps section as a whole (its header's program lengths against its size).
    ModelMaps,
    /// The initial values ζ0 of the controller states of the model maps section.
    ExtInit,
    /// The terminal law section as a whole (its length against n and m).
    TerminalLaw,
    /// The selection test section as a whole (its length against n, the locations and trajectories).
    SelectionTest,
    /// The terminal law's equilibrium `x_e`.
    TerminalCentre,
    /// The terminal law's gain `K_t`.
    TerminalK,
    /// The terminal law's offset `v_t`.
    TerminalV,
    /// The terminal law's ellipsoid matrix `P_t`.
    TerminalP,
}

/// Which program of the model maps section an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelMap {
    /// `coords: x ↦ ξ`.
    Coords,
    /// `input_map: (x, w) ↦ u`.
    InputMap,
}

/// Position of a bad value. Its meaning depends on the field: `K`, `P`: (location, row, col); `Centre`:
/// (trajectory, component, 0); `Delta`: (trajectory, 0, 0); `V`: (trajectory, step, component);
/// `FallbackK`: (row, col, 0); `LawGain`: (partition, row, col); `LawOffset`: (partition, component, 0);
/// `NodeNormal`: (node, component, 0); `NodeOffset`: (node, 0, 0); `BallCentre`, `BallCentreZ`: (ball,
/// component, 0); `BallThreshold`: (ball, 0, 0); `Factor`: (location, row, col); vectors: (component, 0, 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pos(pub u16, pub u16, pub u16);

/// Why an image was rejected. Small and `Copy`; `Display` says what is wrong in words.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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
    /// A section's body is not a postcard encoding of its content.
    Malformed {
        /// The section.
        section: SectionKind,
    },
    /// Bytes are left in a section after its postcard content.
    TrailingBytes {
        /// The section.
        section: SectionKind,
    },
    /// A section decodes but is not in canonical postcard form.
    NotCanonical {
        /// The section.
        section: SectionKind,
    },
    /// The header declares more sections than fit in the image (the directory runs past its end).
    DirectoryTruncated {
        /// Sections declared.
        sections: u16,
    },
    /// A directory entry's reserved flags are not zero.
    SectionFlags {
        /// Index of the entry in the directory.
        index: u16,
    },
    /// A section does not start where the previous one (or the directory) ends: sections are stored in
    /// directory order without gaps or overlaps.
    SectionPlacement {
        /// Index of the entry in the directory.
        index: u16,
        /// Offset where it must start.
        expected: u32,
        /// Offset the directory gives.
        found: u32,
    },
    /// A section runs past the end of the image.
    SectionOutOfRange {
        /// Index of the entry in the directory.
        index: u16,
    },
    /// Bytes after the last section that no section claims.
    UnclaimedBytes {
        /// Offset of the first such byte.
        offset: u32,
    },
    /// Section kinds are not in strictly increasing tag order.
    SectionOrder {
        /// Index of the entry in the directory.
        index: u16,
        /// Its kind tag.
        kind: u16,
    },
    /// A section kind appears twice.
    DuplicateSection {
        /// The kind.
        kind: SectionKind,
    },
    /// A well-formed section of a kind this build does not know: rejected, because the certificate may
    /// depend on it and this firmware could not evaluate it.
    UnknownSection {
        /// The kind tag.
        kind: u16,
    },
    /// A known section that does not belong in an image of this mode.
    UnexpectedSection {
        /// The kind.
        kind: SectionKind,
        /// The image's mode.
        mode: Mode,
    },
    /// A section the mode requires is absent.
    MissingSection {
        /// The kind.
        kind: SectionKind,
    },
    /// A segment is empty, or does not start at the row where the previous segment ends (segments tile
    /// the step table in order).
    SegmentRows {
        /// The segment.
        segment: u16,
    },
    /// A segment continues the previous segment of the same trajectory in the same location (segments are
    /// maximal runs of one location, so that one content has one encoding).
    SegmentNotMaximal {
        /// The segment.
        segment: u16,
    },
    /// A segment-exit record has an unknown kind, a negative threshold, or a guard exit on the last
    /// segment of its trajectory (which has no next segment to move to).
    BadExit {
        /// The segment.
        segment: u16,
    },
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
    /// Trajectory segment ends are not strictly increasing (a trajectory without segments, or out of
    /// order).
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
    /// The terminal law's `P_t` is not exactly symmetric or not positive definite, or its radius is
    /// negative or not finite.
    BadTerminalLaw,
    /// A terminal law in an image with model maps (not certified for such plants).
    TerminalWithModelMaps,
    /// A selection test section in an image without model maps (only the model-maps step reads it).
    SelectionWithoutModelMaps,
    /// An image with the task's monitor given to a decoder built without it
    /// ([`crate::image::decode_for`]).
    MonitorNotSupported,
    /// A PWA-feedback image given to a decoder built without the PWA step ([`crate::image::decode_for`]).
    PwaNotSupported,
    /// The monitor section is malformed ([`crate::monitor::MonitorProgram::decode`]).
    BadMonitor {
        /// What is wrong.
        why: MonitorError,
    },
    /// An image with model maps (or a selection test) given to a decoder built without the model-maps
    /// step ([`crate::image::decode_without_model_maps`]).
    ModelMapsNotSupported,
    /// The constant fallback input lies outside the stored input box in some component.
    FallbackOutsideBox {
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
    /// A model program's code has a byte that is not a known opcode.
    UnknownOpcode {
        /// Offset of the byte within the code.
        offset: u16,
        /// The byte.
        opcode: u8,
    },
    /// A model program's instruction has a truncated operand, or one out of range (input slot, constant
    /// index, output index, or a power exponent outside `±1..=±MAX_PROGRAM_POWI`).
    ProgramOperand {
        /// Offset of the instruction within the code.
        offset: u16,
    },
    /// A model program's instruction pops more values than the stack holds.
    StackUnderflow {
        /// Offset of the instruction within the code.
        offset: u16,
    },
    /// A model program's instruction pushes the stack beyond
    /// [`crate::capacity::MAX_PROGRAM_STACK`].
    StackOverflow {
        /// Offset of the instruction within the code.
        offset: u16,
    },
    /// A model program's stored stack depth differs from the depth of its code.
    ProgramStackMismatch {
        /// Depth in the header.
        stored: u8,
        /// Depth the code reaches.
        actual: u8,
    },
    /// A model program stores an output twice.
    OutputStoredTwice {
        /// The output.
        output: u8,
    },
    /// A model program never stores an output.
    OutputNotStored {
        /// The output.
        output: u8,
    },
    /// A model program ends with values left on its stack.
    StackNotEmpty,
    /// A model program was evaluated with a slice of the wrong length.
    ProgramArity {
        /// Length the program declares.
        expected: u16,
        /// Length given.
        found: u16,
    },
    /// A reserved or padding byte of the model maps section is not zero.
    MapsPadding {
        /// Offset of the byte within the section.
        offset: u32,
    },
    /// A model map reads another number of input slots than the image's dimensions give it
    /// (`coords`: `n_plant + n_ext`; `input_map`: `n_plant + n_ext + m`).
    MapInputs {
        /// The map.
        map: ModelMap,
        /// Slots it must read.
        expected: u16,
        /// Slots it declares.
        found: u16,
    },
    /// A model map stores another number of outputs than the image's dimensions need (`coords`: `n`;
    /// `input_map`: `m_plant + n_ext`).
    MapOutputs {
        /// The map.
        map: ModelMap,
        /// Outputs it must store.
        expected: u16,
        /// Outputs it declares.
        found: u16,
    },
    /// A linear fallback in an image with model maps: its gain would act on the linear coordinates ξ,
    /// while the fallback must act on the plant's own state and input.
    LinearFallbackWithMaps,
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
            Dim::Segments => "number of segments",
            Dim::Sections => "number of sections",
            Dim::ProgramBytes => "model program length in bytes",
            Dim::ProgramConsts => "number of program constants",
            Dim::ProgramInputs => "number of program inputs",
            Dim::ProgramOutputs => "number of program outputs",
            Dim::ProgramStack => "program stack depth",
            Dim::PlantN => "plant state dimension n_plant",
            Dim::PlantM => "plant input dimension m_plant",
            Dim::ExtStates => "number of controller states n_ext",
        })
    }
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Field::K => "K",
            Field::P => "P",
            Field::TrajEnd => "trajectory segment ends",
            Field::Centre => "ball centres",
            Field::Delta => "delta",
            Field::V => "v",
            Field::FallbackK => "fallback K",
            Field::FallbackXRef => "fallback x_ref",
            Field::FallbackURef => "fallback u_ref",
            Field::FallbackInput => "fallback input",
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
            Field::Segment => "segment records",
            Field::Exit => "segment exits",
            Field::Program => "model program",
            Field::ProgramConst => "program constants",
            Field::Fingerprint => "spec fingerprint",
            Field::ModelMaps => "model maps section",
            Field::ExtInit => "controller states' initial values",
            Field::TerminalLaw => "terminal law section",
            Field::SelectionTest => "selection test section",
            Field::TerminalCentre => "terminal law x_e",
            Field::TerminalK => "terminal law K_t",
            Field::TerminalV => "terminal law v_t",
            Field::TerminalP => "terminal law P_t",
        })
    }
}

impl fmt::Display for ModelMap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ModelMap::Coords => "coords",
            ModelMap::InputMap => "input_map",
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
            Malformed { section } => {
                write!(f, "{section} is not a valid postcard encoding of its content")
            }
            TrailingBytes { section } => write!(f, "bytes left over at the end of the {section}"),
            NotCanonical { section } => write!(f, "{section} is not in canonical postcard form"),
            DirectoryTruncated { sections } => write!(
                f,
                "the directory of {sections} sections runs past the end of the image"
            ),
            SectionFlags { index } => write!(f, "directory entry {index}: reserved flags are not zero"),
            SectionPlacement { index, expected, found } => write!(
                f,
                "directory entry {index}: section starts at byte {found}, expected {expected} (gap or overlap)"
            ),
            SectionOutOfRange { index } => {
                write!(f, "directory entry {index}: section runs past the end of the image")
            }
            UnclaimedBytes { offset } => {
                write!(f, "bytes from offset {offset} on belong to no section")
            }
            SectionOrder { index, kind } => write!(
                f,
                "directory entry {index}: section kind {kind} is out of order (kinds must increase)"
            ),
            DuplicateSection { kind } => write!(f, "{kind} appears more than once"),
            UnknownSection { kind } => write!(
                f,
                "unknown section kind {kind}: this build cannot evaluate it, so it cannot run the image"
            ),
            UnexpectedSection { kind, mode } => {
                write!(f, "{kind} does not belong in a {mode} image")
            }
            MissingSection { kind } => write!(f, "required {kind} is missing"),
            SegmentRows { segment } => write!(
                f,
                "segment {segment}: empty, or does not start where the previous segment ends"
            ),
            SegmentNotMaximal { segment } => write!(
                f,
                "segment {segment}: continues the previous segment of its trajectory in the same location"
            ),
            BadExit { segment } => write!(
                f,
                "segment {segment}: exit of unknown kind, with a negative threshold, or a guard exit on \
                 the last segment of its trajectory"
            ),
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
                Field::ExtInit => write!(f, "controller state {a}: initial value is not finite"),
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
                "trajectory {trajectory}: segment end is not after the previous one (empty or out of order)"
            ),
            NegativeDelta { trajectory } => write!(f, "trajectory {trajectory}: delta is negative"),
            LocationOutOfRange { trajectory, step, value } => write!(
                f,
                "trajectory {trajectory} step {step}: location {value} is out of range"
            ),
            EmptyInputBox { input } => write!(f, "input box component {input}: lower bound above upper"),
            BadTerminalLaw => f.write_str(
                "terminal law: P_t is not symmetric positive definite, or the radius is negative or not finite",
            ),
            TerminalWithModelMaps => {
                f.write_str("a terminal law in an image with model maps (not certified for such plants)")
            }
            ModelMapsNotSupported => f.write_str(
                "an image with model maps, for a firmware built without the model-maps step",
            ),
            SelectionWithoutModelMaps => f.write_str(
                "a selection test section in an image without model maps (only the model-maps step reads it)",
            ),
            BadMonitor { why } => write!(f, "monitor section: {why}"),
            MonitorNotSupported => {
                f.write_str("an image with the task's monitor, for a firmware built without it")
            }
            PwaNotSupported => {
                f.write_str("a PWA-feedback image, for a firmware built without the PWA step")
            }
            FallbackOutsideBox { input } => write!(
                f,
                "fallback input component {input}: outside the input box"
            ),
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
            UnknownOpcode { offset, opcode } => {
                write!(f, "program byte {offset}: unknown opcode {opcode:#04x}")
            }
            ProgramOperand { offset } => write!(
                f,
                "program byte {offset}: operand truncated or out of range"
            ),
            StackUnderflow { offset } => {
                write!(f, "program byte {offset}: pops an empty stack")
            }
            StackOverflow { offset } => write!(
                f,
                "program byte {offset}: stack deeper than {}",
                crate::capacity::MAX_PROGRAM_STACK
            ),
            ProgramStackMismatch { stored, actual } => write!(
                f,
                "stored program stack depth {stored} differs from the code's depth {actual}"
            ),
            OutputStoredTwice { output } => write!(f, "program output {output} is stored twice"),
            OutputNotStored { output } => write!(f, "program output {output} is never stored"),
            StackNotEmpty => f.write_str("program ends with values left on its stack"),
            ProgramArity { expected, found } => write!(
                f,
                "program evaluated with {found} values where it declares {expected}"
            ),
            MapsPadding { offset } => write!(
                f,
                "model maps section byte {offset}: reserved or padding byte is not zero"
            ),
            MapInputs { map, expected, found } => write!(
                f,
                "model map {map} reads {found} input slots, the image gives it {expected}"
            ),
            MapOutputs { map, expected, found } => write!(
                f,
                "model map {map} stores {found} outputs, the image needs {expected}"
            ),
            LinearFallbackWithMaps => f.write_str(
                "a linear fallback in an image with model maps (its gain would act on the linear \
                 coordinates, not on the plant's state)",
            ),
            BufferTooSmall { needed } => write!(f, "output buffer too small: {needed} bytes needed"),
            Encode => f.write_str("payload could not be serialised"),
        }
    }
}

impl core::error::Error for ImageError {}

/// Why a monitor section is refused ([`crate::monitor::MonitorProgram::decode`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MonitorError {
    /// The body is shorter than its header says, or longer.
    Length,
    /// The state dimension differs from the image's, or a count is out of its range.
    Dims,
    /// Atom `i` is malformed (kind, coordinates, values).
    Atom(u16),
    /// Node `i` is malformed (operator, children, window), or the nodes are not one tree rooted at the
    /// last node.
    Node(u16),
    /// The arena given to [`Monitor::new`] is smaller than [`MonitorProgram::words`].
    Arena,
}

impl fmt::Display for MonitorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MonitorError::Length => {
                f.write_str("the monitor section's length disagrees with its header")
            }
            MonitorError::Dims => f.write_str("the monitor's dimensions are out of range"),
            MonitorError::Atom(i) => write!(f, "monitor atom {i} is malformed"),
            MonitorError::Node(i) => write!(f, "monitor node {i} is malformed or not in one tree"),
            MonitorError::Arena => f.write_str("the monitor's arena is too small"),
        }
    }
}
