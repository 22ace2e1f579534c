//! The sizes a spec may imply, checked during validation, before any synthesis work starts (issue 18,
//! "bounded before work"). A spec that implies more than the image can hold, or more work than the
//! memory budget allows, is refused with a [`super::ErrorKind::Capacity`] diagnostic at the key that
//! implies it.
//!
//! | size | limit | from |
//! |---|---|---|
//! | state dimension n (rows of `plant.A`) | [`MAX_N`] = 12 | image capacity |
//! | input dimension m (columns of `plant.B`) | [`MAX_M`] = 6 | image capacity |
//! | locations of a hybrid plant | [`MAX_LOCATIONS`] = 8 | image capacity |
//! | samples in the horizon, ⌊`horizon` / `plant.period`⌋ (one trajectory's table rows) | [`max_rows`]`(m)` = [`MAX_TABLE_VALUES`] / m = 524 288 / m | image capacity |
//! | table rows of a full budget, samples × `synthesis.max_trajectories` (one run's for a hybrid plant, whose growth admits runs while their rows fit) | [`max_rows`]`(m)` | image capacity |
//! | `synthesis.max_trajectories` | [`MAX_TRAJECTORIES`] = 1 024 | image capacity |
//! | rows of one polytope (`A` of a `kind = "polytope"` set, an invariant or a guard) | [`MAX_POLYTOPE_ROWS`] = 64 | work per distance |
//! | one expression of a nonlinear plant (`plant.f`, `g`, `h`): bytes, nesting, tree depth, integer power | 4 096, 64, 256, 16 ([`crate::expr`]) | parse work and recursion |
//! | derivatives of a nonlinear plant (Lie derivatives, Jacobians): nodes, depth | 50 000, 1 024 ([`crate::expr`]) | memory and recursion |
//! | boxes of the interval proof that Γ is nonsingular over Init | 256 ([`super::nonlinear::MAX_GAMMA_BOXES`]) | work |
//! | `[mtl] formula`: bytes of its text, atoms (set names, linear predicates, `true`, `false`) | [`MAX_FORMULA_LEN`] = 4 096, [`MAX_FORMULA_ATOMS`] = 256 (nesting 100: `crate::robustness::mtl::parse::MAX_DEPTH`) | every atom is a distance at every sample of every candidate run |
//! | coverage samples implied by `synthesis.coverage_tolerance` and `confidence` | [`MAX_SAMPLE_BYTES`] = 512 MiB of states | memory |
//!
//! Flags are bounded where they are parsed (`verify --runs`, `--per-ball`: see `crate::verify`), and an
//! imported recording by the horizon ([`crate::trajectory::csv`]).

pub use shared_types::capacity::{
    max_rows, MAX_LOCATIONS, MAX_M, MAX_N, MAX_STEPS, MAX_TABLE_VALUES, MAX_TRAJECTORIES,
};

/// Largest number of rows (inequalities) of one polytope in a spec. Every signed distance to a polytope
/// is a small quadratic program over its rows, evaluated at every sample of every candidate trajectory;
/// 64 rows describe any box up to n = 32 and any practical task set, and keep that work bounded.
pub const MAX_POLYTOPE_ROWS: usize = 64;

/// Largest text of an MTL formula (`[mtl] formula`, `host-compiler mtl`), in bytes.
pub const MAX_FORMULA_LEN: usize = 4096;

/// Most atoms (set names, linear predicates, `true`, `false`) of an MTL formula. Certification and
/// Monte Carlo evaluate every atom at every sample of every run (a signed distance each), so the
/// formula's size multiplies all the synthesis work.
pub const MAX_FORMULA_ATOMS: usize = 256;

/// Memory budget, in bytes, of the uniform samples of Init the coverage estimate draws
/// ([`super::SynthesisSettings::coverage_samples`]), estimated by [`sample_bytes`].
pub const MAX_SAMPLE_BYTES: u64 = 512 << 20;

/// Estimated bytes of `samples` states of dimension `n` held as vectors (the entries and each vector's
/// header), saturating.
pub fn sample_bytes(samples: usize, n: usize) -> u64 {
    let per = 8 * n as u64 + 24;
    (samples as u64).saturating_mul(per)
}

/// Samples in a horizon `horizon` of sample period `period`: ⌊T / period⌋, rounding up when T / period
/// is within 1e-9 (relative) of the next integer; saturates at `usize::MAX`.
pub fn steps_in(horizon: f64, period: f64) -> usize {
    let r = horizon / period;
    let up = r.ceil();
    if up - r <= 1e-9 * up.max(1.0) {
        up as usize
    } else {
        r.floor() as usize
    }
}

/// A byte count for people: `1.5 GB`, `20 MB`, `3 kB`.
pub fn human_bytes(b: u64) -> String {
    let b = b as f64;
    if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.0} MB", b / 1e6)
    } else {
        format!("{:.0} kB", b / 1e3)
    }
}
