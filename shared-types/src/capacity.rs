//! Compile-time capacities of the controller image: the largest dimensions an image may declare and the
//! evaluator's fixed scratch sizes. Every runtime loop in `image`, `pwa` and `eval` is bounded by these
//! (DESIGN §4).
//!
//! The host refuses to emit an image that exceeds them, and the decoder rejects one that does.
//!
//! # Worst-case work per control step
//! * Feedforward (Algorithm 2): at κ = 0 one quadratic form per trajectory (`MAX_TRAJECTORIES` of them),
//!   then `m·n` multiply-adds per step.
//! * PWA feedback: at most [`MAX_TREE_DEPTH`] hyperplane tests (`n` multiply-adds each), then the
//!   whitening `z = R̂x` (`n(n+1)/2` multiply-adds, repeated only where consecutive listed balls change
//!   location) and at most [`MAX_LEAF_BALLS`] whitened ball tests (`n` subtractions and `n` multiply-adds
//!   each, [`crate::pwa`]), then `m·n` multiply-adds for the law; [`PWA_STEP_MAX_MULADDS`] is the total at
//!   capacity, counting a location change before every ball (a single-location image whitens once).
//! * A model program ([`crate::program`]): one pass over at most [`MAX_PROGRAM_LEN`] bytes of code, one
//!   instruction per 1–3 bytes, each an f32 operation, a `libm` call or (for `x^k`) at most
//!   [`MAX_PROGRAM_POWI`] multiplications and a division.
//! * Model maps ([`crate::maps`]): the two programs above around the feedforward law, plus copies of at
//!   most [`MAX_N`] + [`MAX_EXT`] + [`MAX_M`] slots and [`MAX_M`] + [`MAX_EXT`] outputs.

/// Largest state dimension `n`.
pub const MAX_N: usize = 12;
/// Largest input dimension `m`.
pub const MAX_M: usize = 6;
/// Largest number of locations (discrete modes of a hybrid plant), each with its own `K` and `P`.
pub const MAX_LOCATIONS: usize = 8;
/// Largest number of nominal trajectories (robust balls) in a feedforward image.
pub const MAX_TRAJECTORIES: usize = 1024;
/// Largest number of values of the feedforward table (rows × m), summed over all trajectories: 2 MiB of
/// f32, so an image at capacity (about 2.6 MB) fits the reference board's 4 MiB of flash. The table's size
/// in bytes is what the image bounds, not its rows: a plant with one input may have six times the rows of
/// one with six ([`max_rows`]).
pub const MAX_TABLE_VALUES: usize = 1 << 19;
/// Largest total number of rows of the feedforward table, summed over all trajectories, at any input
/// dimension (that of `m = 1`); [`max_rows`] gives it for `m` inputs.
pub const MAX_STEPS: usize = MAX_TABLE_VALUES;

/// Largest total number of rows of the feedforward table of a plant with `m` inputs (`m = 0` is read as 1).
pub const fn max_rows(m: usize) -> usize {
    MAX_TABLE_VALUES / if m == 0 { 1 } else { m }
}
/// Largest number of segments of the feedforward table (a segment is a run of rows of one trajectory in
/// one location; a trajectory of a single-location plant is one segment).
pub const MAX_SEGMENTS: usize = 4096;
/// Largest number of entries of an image's section directory.
pub const MAX_SECTIONS: usize = 16;

/// Largest number of partitions (affine laws `u = K_j x + θ0_j`) of a PWA-feedback image.
pub const MAX_PARTITIONS: usize = 256;
/// Largest number of hyperplane tests on any root-to-leaf path of a PWA point-location tree.
pub const MAX_TREE_DEPTH: usize = 24;
/// Largest number of internal (hyperplane) nodes of a PWA point-location tree.
pub const MAX_TREE_NODES: usize = 1024;
/// Largest number of leaves of a PWA point-location tree (each names one partition and its balls).
pub const MAX_LEAVES: usize = 1024;
/// Largest number of certified balls `B_P(x̃_i(κ), δ_i)` (the pieces of the envelope F of (6.2)) in a PWA
/// image.
pub const MAX_BALLS: usize = 2048;
/// Largest total number of ball references, summed over all leaves (a ball cut by a hyperplane is listed by
/// the leaves on both sides).
pub const MAX_BALL_REFS: usize = 4096;
/// Largest number of balls one leaf may list: bounds the envelope test of one control step.
pub const MAX_LEAF_BALLS: usize = 64;

/// Largest model program ([`crate::program`]) in bytes: header, constant pool and code together. One
/// instruction is one to three bytes, so this bounds the instructions one evaluation executes.
pub const MAX_PROGRAM_LEN: usize = 4096;
/// Largest number of `f32` constants in a model program's pool.
pub const MAX_PROGRAM_CONSTS: usize = 512;
/// Largest number of input slots a model program reads (states, inputs and parameters it is given).
pub const MAX_PROGRAM_INPUTS: usize = 64;
/// Largest number of outputs a model program stores.
pub const MAX_PROGRAM_OUTPUTS: usize = 64;
/// Largest operand-stack depth of a model program: the evaluator's stack is a `[f32; MAX_PROGRAM_STACK]`.
pub const MAX_PROGRAM_STACK: usize = 32;
/// Registers of a model program (`TEE` and `RECALL`: a shared subexpression computed once): the
/// evaluator keeps them in a `[f32; MAX_PROGRAM_REGS]`.
pub const MAX_PROGRAM_REGS: usize = 32;
/// Largest magnitude of an integer power `x^k` in a model program; the evaluator multiplies `|k| − 1`
/// times (and divides once for `k < 0`).
pub const MAX_PROGRAM_POWI: i8 = 16;
/// Largest number of controller states `n_ext` of the model maps section ([`crate::maps`]): a dynamic
/// extension the controller keeps between periods (a flat plant's thrust and its derivatives). The
/// evaluator keeps them in a `[f32; MAX_EXT]`, and a step copies at most this many values.
pub const MAX_EXT: usize = 4;

/// Worst-case multiply-adds of one PWA control step at capacity (see the module docs): tree, whitening
/// before every ball (the worst case of alternating locations), ball tests, law.
pub const PWA_STEP_MAX_MULADDS: usize =
    MAX_TREE_DEPTH * MAX_N + MAX_LEAF_BALLS * (MAX_N * (MAX_N + 1) / 2 + MAX_N) + MAX_M * MAX_N;

/// Size in bytes of the fixed image header that precedes the section directory.
pub const HEADER_LEN: usize = 32;

/// Bytes of the parts both modes share: `K` and `P` per location, the fallback law and the input box.
const COMMON_PAYLOAD_LEN: usize = 4
    * (MAX_LOCATIONS * MAX_M * MAX_N      // K per location
        + MAX_LOCATIONS * MAX_N * MAX_N   // P per location
        + MAX_M * MAX_N + MAX_N + MAX_M   // fallback linear law
        + 2 * MAX_M) // input box
    + crate::layout::SPEC_FINGERPRINT_LEN // the optional spec fingerprint
    + MAX_SECTIONS * (DIR_ENTRY_LEN + SECTION_FRAMING); // directory and per-section postcard framing

/// Largest feedforward payload.
const FEEDFORWARD_PAYLOAD_LEN: usize = COMMON_PAYLOAD_LEN
    + 4 * (MAX_TRAJECTORIES * MAX_N       // ball centres
        + MAX_TRAJECTORIES                // ball radii
        + MAX_TABLE_VALUES)               // v table
    + 2 * MAX_TRAJECTORIES                // trajectory segment ends (u16)
    + SEGMENT_RECORD_LEN * MAX_SEGMENTS // segment records
    + 4 * MAX_SEGMENTS * (2 * MAX_N + 3) // segment exits
    + MAX_MAPS_LEN; // model maps

/// Largest model maps section body ([`crate::maps`]): its header, the controller states' initial values
/// and two programs, each padded to 4 bytes.
const MAX_MAPS_LEN: usize = 12 + 4 * MAX_EXT + 2 * (MAX_PROGRAM_LEN + 3);

/// Largest PWA-feedback payload.
const PWA_PAYLOAD_LEN: usize = COMMON_PAYLOAD_LEN
    + 4 * (MAX_PARTITIONS * (MAX_M * MAX_N + MAX_M)  // gains K_j and offsets θ0_j
        + MAX_TREE_NODES * (MAX_N + 1)              // node records: a, b (f32)
        + MAX_LOCATIONS * MAX_N * MAX_N             // factors R̂_ℓ
        + MAX_BALLS * (2 * MAX_N + 1))              // ball centres; test records (whitened centre, ŝ)
    + 2 * (2 * MAX_TREE_NODES                       // node records: children (u16)
        + 2 * MAX_LEAVES                            // leaf partition and ball end (u16)
        + MAX_BALL_REFS                             // ball references (u16)
        + MAX_BALLS)                                // ball partition (u16)
    + MAX_BALLS; // ball location (u8)

/// Bytes of one directory entry (see [`crate::layout::DIR_ENTRY_LEN`]).
const DIR_ENTRY_LEN: usize = crate::layout::DIR_ENTRY_LEN;
/// Bytes of one segment record (see [`crate::layout::SEGMENT_RECORD_LEN`]).
const SEGMENT_RECORD_LEN: usize = crate::layout::SEGMENT_RECORD_LEN;
/// Allowance per section for postcard's length prefixes, counts and enum tags (at most 8 fields of at most
/// 3 varint bytes each, plus tags).
const SECTION_FRAMING: usize = 32;

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// Largest payload (directory and sections) an image within the capacities can have, in bytes (the larger
/// of the two modes). Used by the host to size buffers and by the firmware to size its image region.
/// Computed from the field sizes plus an allowance per section for the directory entry and postcard's
/// framing.
pub const MAX_PAYLOAD_LEN: usize = max(FEEDFORWARD_PAYLOAD_LEN, PWA_PAYLOAD_LEN);

/// Largest whole image (header and payload), in bytes.
pub const MAX_IMAGE_LEN: usize = HEADER_LEN + MAX_PAYLOAD_LEN;
