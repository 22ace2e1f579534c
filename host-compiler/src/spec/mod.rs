//! The task spec: a TOML file describing one control task (Problem 2.26, optionally with an MTL formula
//! for Problem 2.28), its parsing, its validation with miette diagnostics that point at the offending
//! TOML span, and the validated, owned [`Problem`] the rest of the compiler consumes.
//!
//! Layout of a spec (every key is documented in `examples/README.md`):
//!
//! ```toml
//! name = "planar-vehicle"          # optional
//! seed = 7                         # RNG seed, integer ≥ 0 (required)
//! horizon = 5.0                    # T: reach Goal within [0, T] seconds (required, ≥ one period)
//!
//! [plant]
//! time = "continuous"              # dx/dt = A x + B u + c   |  "discrete": x⁺ = A x + B u + g
//! A = [[...], ...]                 # n×n, arrays of rows
//! B = [[...], ...]                 # n×m
//! c = [...]                        # n, optional (zero); `g` instead for a discrete plant
//! period = 0.01                    # sample period in seconds (ZOH for continuous plants)
//! C = [[...], ...]                 # output map y = C x, p×n, optional (identity)
//!
//! [init]                           # a box in state coordinates; lo = hi pins a coordinate
//! kind = "box"
//! lo = [...]
//! hi = [...]
//!
//! [goal]                           # any set (see `spec::sets` for the set syntax)
//! [[unsafe]]                       # zero or more sets; Unsafe is their union
//! [input]                          # kind = "box" (lo, hi) or kind = "ball" (radius, optional center);
//!                                  # fallback = [...]: optional, the input applied out of the envelope
//!                                  # (default: the input set's point nearest 0)
//! [synthesis]                      # optional, see `SynthesisSettings`
//! [mtl]                            # optional: formula = "..." (stored, not interpreted here)
//! [sets.<name>]                    # optional named sets an MTL formula may refer to
//! ```
//!
//! All matrices in the validated types are dense, row-major `Vec<f64>` in a [`Matrix`]
//! (`Matrix::to_faer` converts). Validation stops at the first error.
//!
//! # Limits
//! Every size a spec implies is bounded before any work ([`limits`], which has the table): n ≤ 12,
//! m ≤ 6, at most 8 locations, at most 524 288 / m samples in the horizon and as many table rows for the
//! whole trajectory budget (samples × `max_trajectories`, `max_trajectories` ≤ 1 024; the image bounds the
//! table's values, rows × m), at most 64 rows per
//! polytope, and coverage samples (from `coverage_tolerance` and `confidence`) within 512 MiB.

pub mod checks;
pub mod error;
pub mod fingerprint;
pub mod flat;
pub mod hybrid;
pub mod limits;
pub mod nonlinear;
mod raw;
pub mod sets;
pub mod settings;
mod validate;

pub use error::{ErrorKind, SpecError};
pub use fingerprint::SpecFingerprint;
pub use hybrid::{EdgeDesc, EdgeKindDesc, HybridDesc, LocationDesc, PolytopeDesc};
pub use sets::{load_named_sets, parse_named_sets, Coords, SetDesc, Shape};
pub use settings::{
    ControllerMode, SettingsError, SynthesisSettings, SynthesisSettingsBuilder, TerminalChoice,
};

/// The largest magnitude of any number in a spec. Far beyond any physical task in sensible units, and
/// small enough that the widths of boxes, distances and their squares (and the f32 values an image
/// stores) are finite: an Init box spanning ±1e308 is refused here rather than overflowing later.
pub const MAX_MAGNITUDE: f64 = 1e12;

/// A dense real matrix, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Matrix {
    pub rows: usize,
    pub cols: usize,
    /// Entry (i, j) is `data[i * cols + j]`.
    pub data: Vec<f64>,
}

impl Matrix {
    /// The rows×cols zero matrix.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            data: vec![0.0; rows * cols],
        }
    }

    /// The n×n identity.
    pub fn identity(n: usize) -> Self {
        let mut m = Self::zeros(n, n);
        for i in 0..n {
            m.data[i * n + i] = 1.0;
        }
        m
    }

    /// Entry (i, j).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.data[i * self.cols + j]
    }

    /// Row i as a slice.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.data[i * self.cols..(i + 1) * self.cols]
    }

    /// M x.
    pub fn mul_vec(&self, x: &[f64]) -> Vec<f64> {
        (0..self.rows)
            .map(|i| self.row(i).iter().zip(x).map(|(a, b)| a * b).sum())
            .collect()
    }

    /// dᵀ M d (M square).
    pub fn quad_form(&self, d: &[f64]) -> f64 {
        self.mul_vec(d).iter().zip(d).map(|(a, b)| a * b).sum()
    }

    /// A faer copy.
    pub fn to_faer(&self) -> faer::Mat<f64> {
        faer::Mat::from_fn(self.rows, self.cols, |i, j| self.get(i, j))
    }
}

/// Whether the plant equations are in continuous or discrete time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimeDomain {
    /// dx/dt = A x + B u + c; the firmware runs its exact zero-order-hold discretisation with `period`.
    Continuous,
    /// x[k+1] = A x[k] + B u[k] + g; step k happens at time k·`period`.
    Discrete,
}

/// A linear affine plant with an output map.
#[derive(Clone, Debug, PartialEq)]
pub struct Plant {
    pub time: TimeDomain,
    /// n×n.
    pub A: Matrix,
    /// n×m.
    pub B: Matrix,
    /// Affine term (length n): c of dx/dt = Ax + Bu + c, or g of x⁺ = Ax + Bu + g. Zero when omitted.
    pub offset: Vec<f64>,
    /// Sample period in seconds, > 0.
    pub period: f64,
    /// Output map y = C x, p×n; the identity when the spec has none.
    pub C: Matrix,
}

impl Plant {
    /// State dimension n.
    pub fn n(&self) -> usize {
        self.A.rows
    }
    /// Input dimension m.
    pub fn m(&self) -> usize {
        self.B.cols
    }
    /// Output dimension p.
    pub fn p(&self) -> usize {
        self.C.rows
    }
}

/// The admissible inputs.
#[derive(Clone, Debug, PartialEq)]
pub enum InputSet {
    /// lo ≤ u ≤ hi componentwise.
    Box { lo: Vec<f64>, hi: Vec<f64> },
    /// ‖u − center‖₂ ≤ radius, radius > 0.
    Ball { center: Vec<f64>, radius: f64 },
}

impl InputSet {
    /// Membership.
    pub fn contains(&self, u: &[f64]) -> bool {
        match self {
            InputSet::Box { lo, hi } => {
                u.len() == lo.len()
                    && u.iter()
                        .zip(lo.iter().zip(hi))
                        .all(|(v, (l, h))| l <= v && v <= h)
            }
            InputSet::Ball { center, radius } => {
                u.len() == center.len()
                    && u.iter()
                        .zip(center)
                        .map(|(a, b)| (a - b) * (a - b))
                        .sum::<f64>()
                        <= radius * radius
            }
        }
    }
}

impl InputSet {
    /// A point inside the set: the box's centre, or the ball's.
    fn centre(&self) -> Vec<f64> {
        match self {
            InputSet::Box { lo, hi } => lo.iter().zip(hi).map(|(l, h)| 0.5 * (l + h)).collect(),
            InputSet::Ball { center, .. } => center.clone(),
        }
    }

    /// The point of the set nearest 0: 0 itself when the set contains it; else 0 clamped
    /// componentwise (box) or projected onto the ball, `center + (0 − center)·radius/‖center‖`.
    pub fn nearest_to_zero(&self) -> Vec<f64> {
        match self {
            InputSet::Box { lo, hi } => lo
                .iter()
                .zip(hi)
                .map(|(&l, &h)| 0.0f64.max(l).min(h))
                .collect(),
            InputSet::Ball { center, radius } => {
                let norm = center.iter().map(|c| c * c).sum::<f64>().sqrt();
                if norm <= *radius {
                    vec![0.0; center.len()]
                } else {
                    let t = 1.0 - radius / norm;
                    center.iter().map(|c| c * t).collect()
                }
            }
        }
    }

    /// `u` (a point of the set) as the f32 values an image stores, still in the set: rounded to the
    /// nearest f32 if that lies in the set, else moved toward the set's centre by 10⁻⁶, 10⁻⁵, … of the
    /// way first (rounding can leave a box's face or a ball's sphere by a hair). Returns the f32 values
    /// widened to f64; a point already f32 and inside (such as 0) is returned unchanged.
    pub fn storable(&self, u: &[f64]) -> Vec<f64> {
        let c = self.centre();
        let round = |t: f64| -> Vec<f64> {
            u.iter()
                .zip(&c)
                .map(|(&a, &ci)| (a + t * (ci - a)) as f32 as f64)
                .collect()
        };
        [0.0, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0]
            .into_iter()
            .map(round)
            .find(|v| self.contains(v))
            .unwrap_or_else(|| round(1.0))
    }
}

/// The initial set: a box in state coordinates. `lo[i] == hi[i]` pins coordinate i.
#[derive(Clone, Debug, PartialEq)]
pub struct InitBox {
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
}

impl InitBox {
    /// Indices of the coordinates that are not pinned (lo < hi).
    pub fn free_coords(&self) -> Vec<usize> {
        (0..self.lo.len())
            .filter(|&i| self.lo[i] < self.hi[i])
            .collect()
    }

    /// The box as one interval per coordinate (for interval enclosures over it).
    pub fn intervals(&self) -> Vec<crate::expr::interval::Interval> {
        self.lo
            .iter()
            .zip(&self.hi)
            .map(|(&l, &h)| crate::expr::interval::Interval::new(l, h))
            .collect()
    }

    /// The box's centre, (lo + hi) / 2.
    pub fn centre(&self) -> Vec<f64> {
        self.lo
            .iter()
            .zip(&self.hi)
            .map(|(l, h)| 0.5 * (l + h))
            .collect()
    }
}

/// A validated task: everything the synthesis needs, owned, with the dimensions checked.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// `name` from the spec, if any.
    pub name: Option<String>,
    pub plant: Plant,
    /// Init (state coordinates).
    pub init: InitBox,
    pub goal: SetDesc,
    /// Unsafe = the union of these sets (possibly none).
    pub unsafe_sets: Vec<SetDesc>,
    pub input: InputSet,
    /// The input the firmware applies whenever the image gives none (out of the certified envelope, a
    /// bad frame): `input.fallback` from the spec, or the input set's point nearest 0; a point of the
    /// input set, already rounded to the f32 the image stores ([`InputSet::storable`]).
    pub fallback_input: Vec<f64>,
    /// T in seconds: Goal must be reached within [0, T].
    pub horizon: f64,
    pub seed: u64,
    pub synthesis: SynthesisSettings,
    /// The `[mtl] formula`, stored verbatim (not interpreted by this module).
    pub mtl: Option<String>,
    /// `[sets.<name>]` in file order.
    pub sets: Vec<(String, SetDesc)>,
    /// The hybrid automaton, when `[plant]` has locations; `plant` is then its initial location's model.
    pub hybrid: Option<HybridDesc>,
    /// The plant written as expressions, when `[plant]` has a `class` (`spec::nonlinear`); `plant` is then
    /// its linearisation at the centre of Init.
    pub nonlinear: Option<nonlinear::NonlinearDesc>,
    /// The hashes of the spec's parts an image stores ([`fingerprint`]), so that a tool can tell whether
    /// an image was synthesised from this spec as it is now.
    pub fingerprint: SpecFingerprint,
}

impl Problem {
    /// Number of sample periods that fit in the horizon: ⌊T / period⌋, rounding up when T / period is within
    /// 1e-9 (relative) of the next integer, so T = 5, period = 0.01 gives 500 steps.
    pub fn horizon_steps(&self) -> usize {
        limits::steps_in(self.horizon, self.plant.period)
    }
}

impl Problem {
    /// Unsafe as one geometry region on the state space (a [`crate::geometry::Union`] of the sets), or
    /// `None` when the spec has no unsafe set.
    pub fn unsafe_region(&self) -> Result<Option<Box<dyn crate::geometry::Region>>, SpecError> {
        if self.unsafe_sets.is_empty() {
            return Ok(None);
        }
        let n = self.plant.n();
        let members = self
            .unsafe_sets
            .iter()
            .map(|s| s.to_region(n))
            .collect::<Result<Vec<_>, _>>()?;
        let u = crate::geometry::Union::new(members).map_err(|e| {
            SpecError::new(ErrorKind::BadValue, format!("cannot build Unsafe: {e}"))
        })?;
        Ok(Some(Box::new(u)))
    }

    /// Goal as a geometry region on the state space.
    pub fn goal_region(&self) -> Result<Box<dyn crate::geometry::Region>, SpecError> {
        self.goal.to_region(self.plant.n())
    }
}

/// Parse and validate a spec from text; `name` is the file name shown in diagnostics.
pub fn parse(src: &str, name: &str) -> Result<Problem, SpecError> {
    validate::problem(src).map_err(|e| e.with_source(name, src))
}

/// Read, parse and validate a spec file.
pub fn load(path: impl AsRef<std::path::Path>) -> Result<Problem, SpecError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| SpecError::io(path, e))?;
    parse(&text, &path.display().to_string())
}

/// A shipped example's text (tests).
#[cfg(test)]
pub(crate) fn example_text(file: &str) -> String {
    std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../examples")
            .join(file),
    )
    .expect("the shipped example")
}

/// A shipped example with `from` (which must occur once) replaced by `to`, parsed (tests).
#[cfg(test)]
pub(crate) fn example_variant(file: &str, from: &str, to: &str) -> Result<Problem, SpecError> {
    let src = example_text(file);
    assert_eq!(src.matches(from).count(), 1, "`{from}` must occur once");
    parse(&src.replace(from, to), file)
}
