//! Compile-time capacities of the controller image: the largest dimensions an image may declare and the
//! evaluator's fixed scratch sizes. Every runtime loop in `image` and `eval` is bounded by these (DESIGN §4).
//!
//! The host refuses to emit an image that exceeds them, and the decoder rejects one that does.

/// Largest state dimension `n`.
pub const MAX_N: usize = 12;
/// Largest input dimension `m`.
pub const MAX_M: usize = 6;
/// Largest number of locations (discrete modes of a hybrid plant), each with its own `K` and `P`.
pub const MAX_LOCATIONS: usize = 8;
/// Largest number of nominal trajectories (robust balls) in a feedforward image.
pub const MAX_TRAJECTORIES: usize = 256;
/// Largest total number of rows of the feedforward table, summed over all trajectories.
pub const MAX_STEPS: usize = 4096;
/// Largest number of partitions of a PWA-feedback image (mode reserved, not yet supported).
pub const MAX_PARTITIONS: usize = 1024;

/// Size in bytes of the fixed image header that precedes the postcard payload.
pub const HEADER_LEN: usize = 32;

/// Largest payload an image within the capacities can have, in bytes. Used by the host to size buffers and
/// by the firmware to size its image region. Computed from the field sizes (each float is 4 bytes) plus a
/// generous allowance for postcard's length prefixes and enum tags.
pub const MAX_PAYLOAD_LEN: usize = 4
    * (MAX_LOCATIONS * MAX_M * MAX_N      // K per location
        + MAX_LOCATIONS * MAX_N * MAX_N   // P per location
        + MAX_TRAJECTORIES                // trajectory ends (u32)
        + MAX_TRAJECTORIES * MAX_N        // ball centres
        + MAX_TRAJECTORIES                // ball radii
        + MAX_STEPS * MAX_M               // v table
        + MAX_M * MAX_N + MAX_N + MAX_M   // fallback linear law
        + 2 * MAX_M)                      // input box
    + MAX_STEPS                           // location per step (u8)
    + 64; // length prefixes (≤ 5 bytes each), enum tags and option tag

/// Largest whole image (header and payload), in bytes.
pub const MAX_IMAGE_LEN: usize = HEADER_LEN + MAX_PAYLOAD_LEN;
