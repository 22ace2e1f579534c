//! Emission of controller images: owned host data (f64) → validated f32 image bytes via
//! `shared_types::image::encode` (DESIGN §4, §5), and the reverse reading of an image into owned data.
//!
//! [`ImageBuilder`] holds what synthesis produced for the feedforward controller of Algorithm 2: per
//! location the gain `K` and the CAF metric `P` ((3.5), (3.8)), per trajectory the ball centre `x̃_i(0)`,
//! its radius `δ_i` and the table `v_i(κ) = ũ_i(κ) − K x̃_i(κ)` (3.6) with the nominal location of each
//! step ((4.41)–(4.42)), plus the fallback law, an optional input box and the terminal behaviour.
//!
//! [`ImageBuilder::to_bytes`] checks shapes and capacities, converts to f32 (refusing non-finite values and
//! values beyond the f32 range, and rounding every `δ_i` *down* so that the stored ball never exceeds the
//! certified one), splits each trajectory's rows into segments (maximal runs of one location, the image's
//! segments section), then runs the same validation the firmware runs at decode. The effect of rounding `K`,
//! `P`, `v` and the centres to f32 is for certification to bound (DESIGN §5), not for this module.
//!
//! A feedback-linearizable plant's image also carries its model maps ([`ModelMapsSpec`]: the programs
//! `coords: x ↦ ξ` and `input_map: (x, w) ↦ u`, section 10, layout in `shared_types::maps`): the table,
//! balls, `K` and `P` are then in ξ (dims n, m), while the fallback and the input box are in the plant's
//! input space (`m_plant` values) and a linear fallback is refused. A differentially flat plant's maps
//! also carry the controller's own states (`ext_init`: ζ0 of at most `MAX_EXT` states, which the programs
//! read after x and `input_map` advances); with none the section is the feedback-linearizable one. Such an
//! image may carry the whitened selection test the model-maps step selects with ([`SelectionTestSpec`],
//! section 13, `shared_types::selection`).
//!
//! [`PwaImageBuilder`] is its sibling for the PWA-feedback image of Ch. 6 (layout and rationale in
//! `shared_types::pwa`): per partition j the law `u = K_j x + θ0_j` with the full gain `K_j = K + θ_j`
//! (summed in f64 here, see [`PwaLaw::from_theta`], and rounded once), the point-location tree over
//! hyperplanes, its leaves (a partition and the certified balls that may use its law) and the ball table
//! (the pieces `B_P(x̃_i(κ), δ_i)` of the envelope F of (6.2), each with the partition it is certified for).
//! It checks shapes, capacities and indices with errors that name the offending item, computes the tree's
//! worst-case depth, rounds every ball threshold down as above, stores per location the f32 Cholesky
//! factor R̂ of `P` and per ball its whitened centre `fl32(R̂ ĉ)` with its squared threshold (the
//! evaluator's whitened ball test; the threshold a ball needs for it comes from
//! `crate::certify::pwa_ball_threshold`), and then runs the decoder's validation
//! (which also refuses unreachable nodes, unreferenced leaves and zero normals).
#![allow(non_snake_case)]

use std::path::Path;

use shared_types::capacity::{
    max_rows, MAX_BALLS, MAX_BALL_REFS, MAX_EXT, MAX_LEAF_BALLS, MAX_LEAVES, MAX_LOCATIONS, MAX_M,
    MAX_N, MAX_PARTITIONS, MAX_SEGMENTS, MAX_TRAJECTORIES, MAX_TREE_DEPTH, MAX_TREE_NODES,
};
use shared_types::image::{
    self, Dims, Fallback, Image, ImageError, InputBox, Mode, Payload, PwaPayload, EXIT_GUARD,
    EXIT_TABLE,
};
use shared_types::maps;
use shared_types::pwa::PwaTables;
use shared_types::terminal::TerminalLaw;

use crate::certify::terminal::StoredTerminal;

pub use shared_types::image::Terminal;
pub use shared_types::pwa::Child;

/// Why an image could not be emitted.
#[derive(Debug, thiserror::Error)]
pub enum EmitError {
    /// An array has the wrong number of values for the dimensions.
    #[error("{what}: expected {expected} values, found {found}")]
    Shape {
        /// Which array.
        what: String,
        /// Expected count.
        expected: usize,
        /// Count found.
        found: usize,
    },
    /// A dimension or count exceeds the image capacity (or is zero where one is needed).
    #[error("{what} is {value}, allowed {min}..={max} (image capacity)")]
    Capacity {
        /// Which dimension.
        what: &'static str,
        /// Its value.
        value: usize,
        /// Smallest allowed.
        min: usize,
        /// Largest allowed.
        max: usize,
    },
    /// A value is NaN or infinite.
    #[error("{what} is not finite ({value})")]
    NonFinite {
        /// Which value.
        what: String,
        /// The value.
        value: f64,
    },
    /// A finite value beyond the f32 range.
    #[error("{what} = {value:e} is outside the f32 range")]
    Overflow {
        /// Which value.
        what: String,
        /// The value.
        value: f64,
    },
    /// A value that is finite but not allowed (negative radius, bad index, empty box, ...).
    #[error("{what} {reason}")]
    Invalid {
        /// Which value.
        what: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// The f32 content failed the image validation the decoder runs (e.g. `P` not positive definite after
    /// rounding).
    #[error("image validation failed: {0}")]
    Rejected(#[from] ImageError),
    /// Writing the image file failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
}

/// Gain and metric of one location.
#[derive(Clone, Debug, PartialEq)]
pub struct LocationLaw {
    /// Feedback gain `K`, m×n row-major.
    pub K: Vec<f64>,
    /// CAF metric `P`, n×n row-major, symmetric positive definite.
    pub P: Vec<f64>,
}

/// One nominal trajectory: its robust ball and its feedforward table.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryEntry {
    /// Ball centre `x̃_i(0)`, n values.
    pub x0: Vec<f64>,
    /// Ball radius `δ_i` in the metric of `P` of the first step's location.
    pub delta: f64,
    /// `v_i(κ)` for κ = 0..len, len×m row-major.
    pub v: Vec<f64>,
    /// Nominal location `ℓ_i(κ)` of each step, len values.
    pub location: Vec<u8>,
}

impl TrajectoryEntry {
    /// Number of steps.
    pub fn len(&self) -> usize {
        self.location.len()
    }

    /// Whether the table is empty (never valid in an image).
    pub fn is_empty(&self) -> bool {
        self.location.is_empty()
    }
}

/// The image's fallback law (see `shared_types::image::Fallback`).
#[derive(Clone, Debug, PartialEq)]
pub enum FallbackLaw {
    /// Keep the last applied input.
    Hold,
    /// Zero input.
    Zero,
    /// `u = K (x − x_ref) + u_ref`, saturated to the input box if one is stored.
    Linear {
        /// m×n row-major.
        K: Vec<f64>,
        /// n values.
        x_ref: Vec<f64>,
        /// m values.
        u_ref: Vec<f64>,
    },
    /// A constant input (m values), e.g. the spec's fallback input when 0 is not admissible.
    Constant(Vec<f64>),
}

impl FallbackLaw {
    /// The law that applies the constant input `u`: [`FallbackLaw::Zero`] when `u` is 0 (the form
    /// images had before a spec could choose the fallback), else [`FallbackLaw::Constant`].
    pub fn constant(u: &[f64]) -> Self {
        if u.iter().all(|&v| v == 0.0) {
            FallbackLaw::Zero
        } else {
            FallbackLaw::Constant(u.to_vec())
        }
    }
}

/// Owned content of a feedforward image. Defaults from [`ImageBuilder::new`]: no locations, no
/// trajectories, fallback [`FallbackLaw::Zero`], no input box, terminal [`Terminal::HoldLast`].
#[derive(Clone, Debug, PartialEq)]
pub struct ImageBuilder {
    /// State dimension.
    pub n: usize,
    /// Input dimension.
    pub m: usize,
    /// Sample period, seconds.
    pub period: f64,
    /// Per-location laws (index = location).
    pub locations: Vec<LocationLaw>,
    /// Trajectories (index = trajectory).
    pub trajectories: Vec<TrajectoryEntry>,
    /// Fallback law.
    pub fallback: FallbackLaw,
    /// Optional input box `(lo, hi)`, m values each.
    pub input_box: Option<(Vec<f64>, Vec<f64>)>,
    /// Behaviour past the end of a trajectory.
    pub terminal: Terminal,
    /// How each segment ends, per trajectory (its segments are the maximal runs of one location of its
    /// rows); empty: every segment ends with its table, and the image has no exits section.
    pub exits: Vec<Vec<SegmentExit>>,
    /// The spec fingerprint to store (`crate::spec::SpecFingerprint`'s bytes), or none.
    pub fingerprint: Option<Vec<u8>>,
    /// The model maps of a feedback-linearizable plant (section 10), if any.
    pub model_maps: Option<ModelMapsSpec>,
    /// The certified terminal law (section 11), if any.
    pub terminal_law: Option<StoredTerminal>,
    /// The whitened selection test (section 13, only with model maps), if any.
    pub selection_test: Option<SelectionTestSpec>,
    /// The task's monitor section body (section 14, [`crate::monitor`]), if any.
    pub monitor: Option<Vec<u8>>,
}

/// The whitened selection test of an image with model maps (`shared_types::selection`), as f32 values in
/// the stored order: per location the factor `R̂_ℓ` (n × n, row-major, 0 below the diagonal), per
/// trajectory its test record `[ĉ_z, ŝ]` (n + 1 values). The thresholds come from
/// `crate::certify::pwa_ball_threshold` (see `cover::selection_test`).
#[derive(Clone, Debug, PartialEq)]
pub struct SelectionTestSpec {
    /// `n_locations × n × n` values.
    pub factors: Vec<f32>,
    /// `n_trajectories × (n + 1)` values.
    pub records: Vec<f32>,
}

/// The model maps of a feedback-linearizable or differentially flat plant (`shared_types::maps`): the
/// plant's dimensions, the initial values of the controller's own states (a dynamic extension; none for
/// a feedback-linearizable plant) and the two program bodies as `crate::expr::compile::compile` produces
/// them (`.bytes`).
#[derive(Clone, Debug, PartialEq)]
pub struct ModelMapsSpec {
    /// The plant's state dimension (the first slots of `coords` and of `input_map`).
    pub n_plant: usize,
    /// The plant's input dimension (the first outputs of `input_map`).
    pub m_plant: usize,
    /// ζ0: the initial values of the controller states, `n_ext = ext_init.len() ≤ MAX_EXT` of them
    /// (stored as f32; each must be finite and within the f32 range). Empty: no dynamic extension, and
    /// the section's bytes are those of a feedback-linearizable plant.
    pub ext_init: Vec<f32>,
    /// `coords: (x, ζ) ↦ ξ`: `n_plant + n_ext` inputs (x, then ζ), n outputs.
    pub coords: Vec<u8>,
    /// `input_map: (x, ζ, w) ↦ (u, ζ⁺)`: `n_plant + n_ext + m` inputs (x, then ζ, then w),
    /// `m_plant + n_ext` outputs (u, then ζ⁺).
    pub input_map: Vec<u8>,
}

impl ModelMapsSpec {
    /// The section a plant's maps give: what `synth` writes and what `verify` re-derives from the spec
    /// and requires equal. A flat plant's controller states start at the extension's ζ0, stored as f32
    /// (the jump bound of `model::flat` covers that rounding).
    pub fn of(m: &crate::model::feedback_linearizable::FlMaps) -> Self {
        Self {
            n_plant: m.n_plant,
            m_plant: m.m_plant,
            ext_init: m
                .flat
                .as_ref()
                .map_or_else(Vec::new, |f| f.ext_init.iter().map(|&z| z as f32).collect()),
            coords: m.coords.bytes.clone(),
            input_map: m.input_map.bytes.clone(),
        }
    }
}

/// How a segment ends ([`shared_types::image::Exit`]), owned, with the f32 values stored (serialised as
/// `inspect --json` shows it: `{"kind": "table"}` or `{"kind": "guard", "a", "b", "theta", "next"}`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SegmentExit {
    Table,
    /// The guard half-space, the detection threshold, and the next segment's nominal start.
    Guard {
        a: Vec<f32>,
        b: f32,
        theta: f32,
        next: Vec<f32>,
    },
}

impl SegmentExit {
    /// The exit as a decoded image stores it.
    pub fn of(exit: image::Exit<'_>) -> Self {
        let f32s = |b: &[u8]| -> Vec<f32> {
            b.chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect()
        };
        match exit {
            image::Exit::Table => SegmentExit::Table,
            image::Exit::Guard { a, b, theta, next } => SegmentExit::Guard {
                a: f32s(a),
                b,
                theta,
                next: f32s(next),
            },
        }
    }
}

/// f64 → f32, refusing non-finite values and values beyond the f32 range (rounding to nearest).
fn to_f32(what: impl Fn() -> String, x: f64) -> Result<f32, EmitError> {
    if !x.is_finite() {
        return Err(EmitError::NonFinite {
            what: what(),
            value: x,
        });
    }
    let y = x as f32;
    if !y.is_finite() {
        return Err(EmitError::Overflow {
            what: what(),
            value: x,
        });
    }
    Ok(y)
}

/// Converts a slice to little-endian f32 bytes after checking its length.
fn le_bytes(what: &str, xs: &[f64], expected: usize) -> Result<Vec<u8>, EmitError> {
    if xs.len() != expected {
        return Err(EmitError::Shape {
            what: what.to_string(),
            expected,
            found: xs.len(),
        });
    }
    let mut out = Vec::with_capacity(4 * xs.len());
    for (i, &x) in xs.iter().enumerate() {
        out.extend_from_slice(&to_f32(|| format!("{what}[{i}]"), x)?.to_le_bytes());
    }
    Ok(out)
}

fn capacity(what: &'static str, value: usize, min: usize, max: usize) -> Result<(), EmitError> {
    if value < min || value > max {
        Err(EmitError::Capacity {
            what,
            value,
            min,
            max,
        })
    } else {
        Ok(())
    }
}

/// The largest f32 not above `x` (x finite, non-negative, within f32 range): the stored radius never
/// exceeds the certified one.
fn f32_round_down(x: f32, exact: f64) -> f32 {
    if x as f64 > exact {
        x.next_down()
    } else {
        x
    }
}

impl ImageBuilder {
    /// An empty builder with the defaults listed on the type.
    pub fn new(n: usize, m: usize, period: f64) -> Self {
        ImageBuilder {
            n,
            m,
            period,
            locations: Vec::new(),
            trajectories: Vec::new(),
            fallback: FallbackLaw::Zero,
            input_box: None,
            terminal: Terminal::HoldLast,
            exits: Vec::new(),
            fingerprint: None,
            terminal_law: None,
            model_maps: None,
            selection_test: None,
            monitor: None,
        }
    }

    /// Attaches the model maps of a feedback-linearizable plant (the image's law then works on ξ).
    pub fn model_maps(&mut self, maps: ModelMapsSpec) -> &mut Self {
        self.model_maps = Some(maps);
        self
    }

    /// Adds a location with gain `K` (m×n row-major) and metric `P` (n×n); returns its index.
    pub fn add_location(&mut self, K: Vec<f64>, P: Vec<f64>) -> usize {
        self.locations.push(LocationLaw { K, P });
        self.locations.len() - 1
    }

    /// Adds a trajectory given its table directly; returns its index.
    pub fn add_trajectory(&mut self, entry: TrajectoryEntry) -> usize {
        self.trajectories.push(entry);
        self.trajectories.len() - 1
    }

    /// Adds a trajectory from its nominal samples, computing `v(κ) = ũ(κ) − K_{ℓ(κ)} x̃(κ)` (3.6) in f64.
    /// `x_nom` is len×n, `u_nom` len×m (row-major), `location` len values; the ball is centred at
    /// `x̃(0)` with radius `delta`. Locations must have been added first. Returns the index.
    pub fn add_nominal_trajectory(
        &mut self,
        x_nom: &[f64],
        u_nom: &[f64],
        location: &[u8],
        delta: f64,
    ) -> Result<usize, EmitError> {
        let (n, m, len) = (self.n, self.m, location.len());
        if len == 0 {
            return Err(EmitError::Invalid {
                what: "nominal trajectory".into(),
                reason: "has no steps",
            });
        }
        for (what, got, want) in [
            ("x_nom", x_nom.len(), len * n),
            ("u_nom", u_nom.len(), len * m),
        ] {
            if got != want {
                return Err(EmitError::Shape {
                    what: what.into(),
                    expected: want,
                    found: got,
                });
            }
        }
        let mut v = Vec::with_capacity(len * m);
        for (k, &l) in location.iter().enumerate() {
            let Some(law) = self.locations.get(l as usize) else {
                return Err(EmitError::Invalid {
                    what: format!("nominal trajectory step {k}: location {l}"),
                    reason: "does not exist",
                });
            };
            if law.K.len() != m * n {
                return Err(EmitError::Shape {
                    what: format!("location {l}: K"),
                    expected: m * n,
                    found: law.K.len(),
                });
            }
            let x = &x_nom[k * n..(k + 1) * n];
            for j in 0..m {
                let kx: f64 = (0..n).map(|i| law.K[j * n + i] * x[i]).sum();
                v.push(u_nom[k * m + j] - kx);
            }
        }
        Ok(self.add_trajectory(TrajectoryEntry {
            x0: x_nom[..n].to_vec(),
            delta,
            v,
            location: location.to_vec(),
        }))
    }

    /// Total number of table rows.
    pub fn total_steps(&self) -> usize {
        self.trajectories.iter().map(|t| t.len()).sum()
    }

    /// Checks everything, converts to f32 and encodes the image.
    pub fn to_bytes(&self) -> Result<Vec<u8>, EmitError> {
        let (n, m) = (self.n, self.m);
        capacity("state dimension n", n, 1, MAX_N)?;
        capacity("input dimension m", m, 1, MAX_M)?;
        capacity(
            "number of locations",
            self.locations.len(),
            1,
            MAX_LOCATIONS,
        )?;
        capacity(
            "number of trajectories",
            self.trajectories.len(),
            1,
            MAX_TRAJECTORIES,
        )?;
        capacity("total table rows", self.total_steps(), 1, max_rows(m))?;
        let period = to_f32(|| "sample period".into(), self.period)?;
        if period <= 0.0 {
            return Err(EmitError::Invalid {
                what: "sample period".into(),
                reason: "is not positive",
            });
        }

        let mut K = Vec::new();
        let mut P = Vec::new();
        for (l, law) in self.locations.iter().enumerate() {
            K.extend(le_bytes(&format!("location {l}: K"), &law.K, m * n)?);
            P.extend(le_bytes(&format!("location {l}: P"), &law.P, n * n)?);
        }

        let mut seg_end = Vec::new();
        let mut centre = Vec::new();
        let mut delta = Vec::new();
        let mut v = Vec::new();
        let mut segment = Vec::new();
        let mut n_segments = 0usize;
        let mut exits = Vec::new();
        let mut row = 0usize;
        for (t, tr) in self.trajectories.iter().enumerate() {
            let seg_before = n_segments;
            let len = tr.len();
            if len == 0 {
                return Err(EmitError::Invalid {
                    what: format!("trajectory {t}"),
                    reason: "has no steps",
                });
            }
            centre.extend(le_bytes(&format!("trajectory {t}: x0"), &tr.x0, n)?);
            let d32 = to_f32(|| format!("trajectory {t}: delta"), tr.delta)?;
            if tr.delta < 0.0 {
                return Err(EmitError::Invalid {
                    what: format!("trajectory {t}: delta"),
                    reason: "is negative",
                });
            }
            delta.extend_from_slice(&f32_round_down(d32, tr.delta).to_le_bytes());
            if tr.v.len() != len * m {
                return Err(EmitError::Shape {
                    what: format!("trajectory {t}: v"),
                    expected: len * m,
                    found: tr.v.len(),
                });
            }
            for (i, &x) in tr.v.iter().enumerate() {
                let y = to_f32(|| format!("trajectory {t} step {}: v[{}]", i / m, i % m), x)?;
                v.extend_from_slice(&y.to_le_bytes());
            }
            for (s, &l) in tr.location.iter().enumerate() {
                if l as usize >= self.locations.len() {
                    return Err(EmitError::Invalid {
                        what: format!("trajectory {t} step {s}: location {l}"),
                        reason: "does not exist",
                    });
                }
            }
            // Segments: the maximal runs of one location of this trajectory's rows.
            let mut s = 0;
            while s < len {
                let l = tr.location[s];
                let run = tr.location[s..].iter().take_while(|&&x| x == l).count();
                let record = image::Segment {
                    location: l as usize,
                    first_row: row + s,
                    len: run,
                }
                .record()
                .ok_or_else(|| invalid(format!("trajectory {t}: segment"), "does not fit"))?;
                segment.extend_from_slice(&record);
                n_segments += 1;
                s += run;
            }
            capacity("number of segments", n_segments, 1, MAX_SEGMENTS)?;
            if !self.exits.is_empty() {
                let ex = self.exits.get(t).map(Vec::as_slice).unwrap_or(&[]);
                let here = n_segments - seg_before;
                if ex.len() != here {
                    return Err(EmitError::Shape {
                        what: format!("trajectory {t}: segment exits"),
                        expected: here,
                        found: ex.len(),
                    });
                }
                for e in ex {
                    match e {
                        SegmentExit::Table => {
                            exits.extend_from_slice(&EXIT_TABLE.to_le_bytes());
                            exits.extend(std::iter::repeat_n(0u8, 4 * (2 * n + 2)));
                        }
                        SegmentExit::Guard { a, b, theta, next } => {
                            if a.len() != n || next.len() != n {
                                return Err(EmitError::Shape {
                                    what: format!("trajectory {t}: guard normal and next start"),
                                    expected: n,
                                    found: if a.len() != n { a.len() } else { next.len() },
                                });
                            }
                            exits.extend_from_slice(&EXIT_GUARD.to_le_bytes());
                            for v in a.iter().chain([b, theta]).chain(next) {
                                exits.extend_from_slice(&v.to_le_bytes());
                            }
                        }
                    }
                }
            }
            row += len; // ≤ max_rows(m), checked above
            seg_end.extend_from_slice(&(n_segments as u16).to_le_bytes());
        }

        // With model maps the fallback and the box act on the plant's input.
        let maps = match &self.model_maps {
            Some(mm) => {
                capacity("plant state dimension n_plant", mm.n_plant, 1, MAX_N)?;
                capacity("plant input dimension m_plant", mm.m_plant, 1, MAX_M)?;
                capacity(
                    "number of controller states n_ext",
                    mm.ext_init.len(),
                    0,
                    MAX_EXT,
                )?;
                for (i, &z) in mm.ext_init.iter().enumerate() {
                    if !z.is_finite() {
                        return Err(EmitError::NonFinite {
                            what: format!("controller state {i}: initial value"),
                            value: z as f64,
                        });
                    }
                }
                if matches!(self.fallback, FallbackLaw::Linear { .. }) {
                    return Err(invalid(
                        "a linear fallback".into(),
                        "cannot go with model maps (its gain would act on the linear coordinates)",
                    ));
                }
                let len = maps::body_len(mm.ext_init.len(), mm.coords.len(), mm.input_map.len());
                let mut body = vec![0u8; len];
                maps::write_body(
                    &mut body,
                    mm.n_plant,
                    mm.m_plant,
                    &mm.ext_init,
                    &mm.coords,
                    &mm.input_map,
                )?;
                Some(body)
            }
            None => None,
        };
        let m_fb = self.model_maps.as_ref().map_or(m, |mm| mm.m_plant);
        let (fb, bx) = fallback_box_bytes(n, m_fb, &self.fallback, &self.input_box)?;
        let payload = Payload {
            K: &K,
            P: &P,
            seg_end: &seg_end,
            centre: &centre,
            delta: &delta,
            segment: &segment,
            v: &v,
            fallback: fallback_of(&self.fallback, &fb),
            input_box: bx.as_ref().map(|(lo, hi)| InputBox { lo, hi }),
            terminal: self.terminal,
            exits: &exits,
        };
        let dims = Dims {
            n,
            m,
            n_locations: self.locations.len(),
            n_trajectories: self.trajectories.len(),
            n_partitions: 0,
        };
        let img = Image::new_with_maps(Mode::Feedforward, dims, period, payload, maps.as_deref())?;
        let terminal = self.terminal_law.as_ref().map(terminal_body);
        let selection: Option<Vec<u8>> = self.selection_test.as_ref().map(|t| {
            t.factors
                .iter()
                .chain(&t.records)
                .flat_map(|v| v.to_le_bytes())
                .collect()
        });
        let img = match &selection {
            Some(body) => img.with_selection_test(body)?,
            None => img,
        };
        encode_to_vec(&with_optional(
            img,
            &self.fingerprint,
            terminal.as_ref(),
            self.monitor.as_deref(),
        )?)
    }

    /// [`ImageBuilder::to_bytes`], then writes the file.
    pub fn write(&self, path: &Path) -> Result<Vec<u8>, EmitError> {
        write_file(path, self.to_bytes()?)
    }

    /// Reads a decoded feedforward image back into owned data (each f32 widened exactly to f64). Building
    /// it again reproduces the same bytes. (A PWA image reads back through [`PwaImageBuilder::from_image`].)
    pub fn from_image(img: &Image<'_>) -> Self {
        let (n, m) = (img.n(), img.m());
        let locations = (0..img.n_locations())
            .map(|l| LocationLaw {
                K: (0..m * n).map(|i| img.K(l, i / n, i % n) as f64).collect(),
                P: (0..n * n).map(|i| img.P(l, i / n, i % n) as f64).collect(),
            })
            .collect();
        let trajectories = (0..img.n_trajectories())
            .map(|t| {
                let len = img.trajectory_len(t);
                TrajectoryEntry {
                    x0: (0..n).map(|i| img.centre(t, i) as f64).collect(),
                    delta: img.delta(t) as f64,
                    v: (0..len * m)
                        .map(|i| img.v(t, i / m, i % m) as f64)
                        .collect(),
                    location: (0..len).map(|s| img.location(t, s) as u8).collect(),
                }
            })
            .collect();
        ImageBuilder {
            n,
            m,
            period: img.period() as f64,
            locations,
            trajectories,
            fallback: fallback_from_image(img),
            input_box: input_box_from_image(img),
            terminal: img.terminal(),
            exits: if img.has_exits() {
                (0..img.n_trajectories())
                    .map(|t| {
                        let (s0, count) = img.trajectory_segments(t);
                        (s0..s0 + count)
                            .map(|s| SegmentExit::of(img.exit(s)))
                            .collect()
                    })
                    .collect()
            } else {
                Vec::new()
            },
            fingerprint: img.fingerprint().map(<[u8]>::to_vec),
            terminal_law: img
                .terminal_law()
                .map(|t| stored_terminal(&t, img.n(), img.m())),
            model_maps: img.model_maps().map(|mm| ModelMapsSpec {
                n_plant: mm.n_plant(),
                m_plant: mm.m_plant(),
                ext_init: mm.ext_inits().collect(),
                coords: mm.coords_bytes().to_vec(),
                input_map: mm.input_map_bytes().to_vec(),
            }),
            selection_test: img.selection_test().map(|t| {
                let nl = img.n_locations();
                let factors = (0..nl * n * n)
                    .map(|i| t.factor(n, i / (n * n), (i / n) % n, i % n))
                    .collect();
                let records = (0..img.n_trajectories())
                    .flat_map(|b| {
                        (0..n)
                            .map(move |i| t.centre_z(n, b, i))
                            .chain([t.threshold(n, b)])
                    })
                    .collect();
                SelectionTestSpec { factors, records }
            }),
            monitor: img.monitor().map(|p| p.body().to_vec()),
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// PWA feedback (Ch. 6).

/// The affine law of one partition: `u = K_j x + θ0_j`.
#[derive(Clone, Debug, PartialEq)]
pub struct PwaLaw {
    /// Full gain `K_j = K + θ_j`, m×n row-major.
    pub gain: Vec<f64>,
    /// Offset `θ0_j`, m values.
    pub offset: Vec<f64>,
}

impl PwaLaw {
    /// The law (6.1) of a partition given around the CAF gain: `K_j = K + θ_j` summed in f64 (so the image
    /// rounds each entry once). `K` and `theta` are m×n row-major and must have the same length.
    pub fn from_theta(K: &[f64], theta: &[f64], theta0: Vec<f64>) -> Result<PwaLaw, EmitError> {
        if K.len() != theta.len() {
            return Err(EmitError::Shape {
                what: "theta".into(),
                expected: K.len(),
                found: theta.len(),
            });
        }
        Ok(PwaLaw {
            gain: K.iter().zip(theta).map(|(k, t)| k + t).collect(),
            offset: theta0,
        })
    }
}

/// An internal node of the point-location tree: `aᵀx ≤ b` goes to `left`, otherwise to `right`.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeNode {
    /// Normal `a`, n values (not all zero).
    pub a: Vec<f64>,
    /// Offset `b`.
    pub b: f64,
    /// Child when `aᵀx ≤ b`. A child node must have a larger index than its parent.
    pub left: Child,
    /// Child otherwise.
    pub right: Child,
}

/// A leaf of the tree: the partition whose law applies and the certified balls (indices into
/// [`PwaImageBuilder::balls`], all certified for that partition) that make up the leaf's part of F.
#[derive(Clone, Debug, PartialEq)]
pub struct PwaLeaf {
    /// Partition index.
    pub partition: usize,
    /// Ball indices, 1..=`MAX_LEAF_BALLS` of them; the evaluator tests them in this order.
    pub balls: Vec<usize>,
}

/// A certified ball `B_P(x̃_i(κ), δ_i)`: the law of `partition` maps it into the next ball of its
/// trajectory ((6.5) via (6.6)–(6.7)).
#[derive(Clone, Debug, PartialEq)]
pub struct CertifiedBall {
    /// Centre `x̃_i(κ)`, n values (stored as f32; the whitened centre is computed from that f32 value).
    pub centre: Vec<f64>,
    /// Stored squared threshold ŝ of the evaluator's whitened test (rounded down to f32 when emitted; the
    /// test accepts iff the computed squared whitened distance is ≤ ŝ). For the evaluator to accept only
    /// states within the certified δ_i, pass `crate::certify::pwa_ball_threshold(P, centre, δ_i)`.
    pub threshold: f64,
    /// Location whose `P` is the ball's metric.
    pub location: u8,
    /// Partition whose law the ball is certified for.
    pub partition: usize,
}

/// Owned content of a PWA-feedback image. Defaults from [`PwaImageBuilder::new`]: nothing stored,
/// fallback [`FallbackLaw::Zero`], no input box.
#[derive(Clone, Debug, PartialEq)]
pub struct PwaImageBuilder {
    /// State dimension.
    pub n: usize,
    /// Input dimension.
    pub m: usize,
    /// Sample period, seconds.
    pub period: f64,
    /// Per-location CAF gain `K` (kept for reports) and ball metric `P`.
    pub locations: Vec<LocationLaw>,
    /// Per location, the factor `R̂ = fl32(R)` of its `P = RᵀR` (n × n row-major, f32 values widened),
    /// stored for the whitened ball test: computed by [`PwaImageBuilder::add_location`]
    /// ([`crate::certify::metric_factor_f32`]; empty if `P` is not positive definite), read back by
    /// [`PwaImageBuilder::from_image`].
    pub factors: Vec<Vec<f64>>,
    /// Per-partition laws (index = partition).
    pub laws: Vec<PwaLaw>,
    /// Internal tree nodes; node 0 is the root. Empty: the tree is leaf 0 alone.
    pub nodes: Vec<TreeNode>,
    /// Leaves (index = leaf).
    pub leaves: Vec<PwaLeaf>,
    /// Certified balls (index = ball).
    pub balls: Vec<CertifiedBall>,
    /// Fallback law.
    pub fallback: FallbackLaw,
    /// Optional input box `(lo, hi)`, m values each.
    pub input_box: Option<(Vec<f64>, Vec<f64>)>,
    /// The spec fingerprint to store (`crate::spec::SpecFingerprint`'s bytes), or none.
    pub fingerprint: Option<Vec<u8>>,
    /// The certified terminal law (section 11), if any.
    pub terminal_law: Option<StoredTerminal>,
    /// The task's monitor section body (section 14, [`crate::monitor`]), if any.
    pub monitor: Option<Vec<u8>>,
}

fn invalid(what: String, reason: &'static str) -> EmitError {
    EmitError::Invalid { what, reason }
}

/// Fallback and input box as f32 bytes (shared by both builders).
type FallbackBytes = Option<(Vec<u8>, Vec<u8>, Vec<u8>)>;
type BoxBytes = Option<(Vec<u8>, Vec<u8>)>;

fn fallback_box_bytes(
    n: usize,
    m: usize,
    fallback: &FallbackLaw,
    input_box: &Option<(Vec<f64>, Vec<f64>)>,
) -> Result<(FallbackBytes, BoxBytes), EmitError> {
    let fb = match fallback {
        FallbackLaw::Linear { K, x_ref, u_ref } => Some((
            le_bytes("fallback K", K, m * n)?,
            le_bytes("fallback x_ref", x_ref, n)?,
            le_bytes("fallback u_ref", u_ref, m)?,
        )),
        FallbackLaw::Constant(u) => {
            Some((Vec::new(), Vec::new(), le_bytes("fallback input", u, m)?))
        }
        _ => None,
    };
    let bx = match input_box {
        Some((lo, hi)) => {
            for j in 0..m.min(lo.len()).min(hi.len()) {
                if lo[j] > hi[j] {
                    return Err(invalid(
                        format!("input box component {j}"),
                        "has its lower bound above its upper bound",
                    ));
                }
            }
            Some((
                le_bytes("input box lo", lo, m)?,
                le_bytes("input box hi", hi, m)?,
            ))
        }
        None => None,
    };
    Ok((fb, bx))
}

fn fallback_of<'a>(law: &FallbackLaw, fb: &'a FallbackBytes) -> Fallback<'a> {
    match (law, fb) {
        (FallbackLaw::Constant(_), Some((_, _, u))) => Fallback::Constant { u },
        (_, Some((K, x_ref, u_ref))) => Fallback::Linear { K, x_ref, u_ref },
        (FallbackLaw::Hold, _) => Fallback::Hold,
        _ => Fallback::Zero,
    }
}

fn fallback_from_image(img: &Image<'_>) -> FallbackLaw {
    let (n, m) = (img.n(), img.m());
    match img.fallback() {
        Fallback::Hold => FallbackLaw::Hold,
        Fallback::Zero => FallbackLaw::Zero,
        Fallback::Constant { .. } => FallbackLaw::Constant(
            (0..img.plant_m())
                .map(|j| img.fallback_input(j) as f64)
                .collect(),
        ),
        Fallback::Linear { .. } => FallbackLaw::Linear {
            K: (0..m * n)
                .map(|i| img.fallback_K(i / n, i % n) as f64)
                .collect(),
            x_ref: (0..n).map(|i| img.fallback_x_ref(i) as f64).collect(),
            u_ref: (0..m).map(|j| img.fallback_u_ref(j) as f64).collect(),
        },
    }
}

fn input_box_from_image(img: &Image<'_>) -> Option<(Vec<f64>, Vec<f64>)> {
    img.has_input_box().then(|| {
        let b: Vec<(f32, f32)> = (0..img.plant_m())
            .filter_map(|j| img.input_bounds(j))
            .collect();
        (
            b.iter().map(|p| p.0 as f64).collect(),
            b.iter().map(|p| p.1 as f64).collect(),
        )
    })
}

fn le_u16(v: impl IntoIterator<Item = u16>) -> Vec<u8> {
    v.into_iter().flat_map(|x| x.to_le_bytes()).collect()
}

impl PwaImageBuilder {
    /// An empty builder with the defaults listed on the type.
    pub fn new(n: usize, m: usize, period: f64) -> Self {
        PwaImageBuilder {
            n,
            m,
            period,
            locations: Vec::new(),
            factors: Vec::new(),
            laws: Vec::new(),
            nodes: Vec::new(),
            leaves: Vec::new(),
            balls: Vec::new(),
            fallback: FallbackLaw::Zero,
            input_box: None,
            fingerprint: None,
            terminal_law: None,
            monitor: None,
        }
    }

    /// Adds a location with CAF gain `K` (m×n) and metric `P` (n×n), and the factor of `P` for the ball
    /// test; returns its index.
    pub fn add_location(&mut self, K: Vec<f64>, P: Vec<f64>) -> usize {
        self.factors
            .push(crate::certify::metric_factor_f32(&P, self.n).unwrap_or_default());
        self.locations.push(LocationLaw { K, P });
        self.locations.len() - 1
    }

    /// Adds a partition's law; returns the partition index.
    pub fn add_law(&mut self, law: PwaLaw) -> usize {
        self.laws.push(law);
        self.laws.len() - 1
    }

    /// Adds a tree node; returns its index (the first node added is the root).
    pub fn add_node(&mut self, node: TreeNode) -> usize {
        self.nodes.push(node);
        self.nodes.len() - 1
    }

    /// Adds a leaf; returns its index.
    pub fn add_leaf(&mut self, leaf: PwaLeaf) -> usize {
        self.leaves.push(leaf);
        self.leaves.len() - 1
    }

    /// Adds a certified ball; returns its index.
    pub fn add_ball(&mut self, ball: CertifiedBall) -> usize {
        self.balls.push(ball);
        self.balls.len() - 1
    }

    /// Checks that every child is in range and every child node comes after its parent, and returns the
    /// worst-case number of hyperplane tests from the root to a leaf (0 without nodes).
    pub fn tree_depth(&self) -> Result<usize, EmitError> {
        let nn = self.nodes.len();
        let mut depth = vec![0usize; nn];
        if let Some(d) = depth.first_mut() {
            *d = 1;
        }
        for (i, node) in self.nodes.iter().enumerate() {
            for (side, c) in [("left", node.left), ("right", node.right)] {
                match c {
                    Child::Outside => {}
                    Child::Leaf(l) => {
                        if l as usize >= self.leaves.len() {
                            return Err(invalid(
                                format!("tree node {i}: {side} child leaf {l}"),
                                "does not exist",
                            ));
                        }
                    }
                    Child::Node(k) => {
                        let k = k as usize;
                        if k >= nn {
                            return Err(invalid(
                                format!("tree node {i}: {side} child node {k}"),
                                "does not exist",
                            ));
                        }
                        if k <= i {
                            return Err(invalid(
                                format!("tree node {i}: {side} child node {k}"),
                                "does not come after its parent (children must have larger indices)",
                            ));
                        }
                        depth[k] = depth[k].max(depth[i] + 1);
                    }
                }
            }
        }
        Ok(depth.into_iter().max().unwrap_or(0))
    }

    /// Total number of ball references over all leaves.
    pub fn total_ball_refs(&self) -> usize {
        self.leaves.iter().map(|l| l.balls.len()).sum()
    }

    /// Checks everything, converts to f32 and encodes the image.
    pub fn to_bytes(&self) -> Result<Vec<u8>, EmitError> {
        let (n, m) = (self.n, self.m);
        capacity("state dimension n", n, 1, MAX_N)?;
        capacity("input dimension m", m, 1, MAX_M)?;
        capacity(
            "number of locations",
            self.locations.len(),
            1,
            MAX_LOCATIONS,
        )?;
        capacity("number of partitions", self.laws.len(), 1, MAX_PARTITIONS)?;
        capacity("number of tree nodes", self.nodes.len(), 0, MAX_TREE_NODES)?;
        capacity("number of leaves", self.leaves.len(), 1, MAX_LEAVES)?;
        capacity("number of certified balls", self.balls.len(), 1, MAX_BALLS)?;
        capacity(
            "total ball references",
            self.total_ball_refs(),
            1,
            MAX_BALL_REFS,
        )?;
        let depth = self.tree_depth()?;
        capacity("tree depth", depth, 0, MAX_TREE_DEPTH)?;
        let period = to_f32(|| "sample period".into(), self.period)?;
        if period <= 0.0 {
            return Err(invalid("sample period".into(), "is not positive"));
        }

        let mut K = Vec::new();
        let mut P = Vec::new();
        let mut R = Vec::new();
        for (l, law) in self.locations.iter().enumerate() {
            K.extend(le_bytes(&format!("location {l}: K"), &law.K, m * n)?);
            P.extend(le_bytes(&format!("location {l}: P"), &law.P, n * n)?);
            let f = self.factors.get(l).map_or(&[][..], |f| &f[..]);
            if f.is_empty() {
                return Err(invalid(
                    format!("location {l}: P"),
                    "has no Cholesky factor (not positive definite)",
                ));
            }
            R.extend(le_bytes(&format!("location {l}: factor R"), f, n * n)?);
        }

        let mut gain = Vec::new();
        let mut offset = Vec::new();
        for (j, law) in self.laws.iter().enumerate() {
            gain.extend(le_bytes(&format!("partition {j}: K_j"), &law.gain, m * n)?);
            offset.extend(le_bytes(
                &format!("partition {j}: theta0_j"),
                &law.offset,
                m,
            )?);
        }

        // One record per node: a (n f32), b (f32), left and right child codes (u16).
        let mut node_rec = Vec::new();
        for (i, node) in self.nodes.iter().enumerate() {
            node_rec.extend(le_bytes(&format!("tree node {i}: a"), &node.a, n)?);
            let b = to_f32(|| format!("tree node {i}: b"), node.b)?;
            node_rec.extend_from_slice(&b.to_le_bytes());
            for c in [node.left, node.right] {
                // In range (checked by tree_depth), so the code exists.
                let code = c
                    .code()
                    .ok_or_else(|| invalid(format!("tree node {i}: child {c:?}"), "has no code"))?;
                node_rec.extend_from_slice(&code.to_le_bytes());
            }
        }

        let mut leaf_end = Vec::new();
        let mut ball_ref = Vec::new();
        let mut refs = 0u16;
        for (l, leaf) in self.leaves.iter().enumerate() {
            if leaf.partition >= self.laws.len() {
                return Err(invalid(
                    format!("leaf {l}: partition {}", leaf.partition),
                    "does not exist",
                ));
            }
            capacity("balls of one leaf", leaf.balls.len(), 1, MAX_LEAF_BALLS)?;
            for &b in &leaf.balls {
                let Some(_ball) = self.balls.get(b) else {
                    return Err(invalid(format!("leaf {l}: ball {b}"), "does not exist"));
                };
                // A leaf may list balls of other partitions (mixed leaf): the evaluator applies the law of
                // the ball that contains the state.
                ball_ref.extend_from_slice(&(b as u16).to_le_bytes());
            }
            refs += leaf.balls.len() as u16; // ≤ MAX_BALL_REFS, checked above
            leaf_end.extend_from_slice(&refs.to_le_bytes());
        }
        let leaf_partition = le_u16(self.leaves.iter().map(|l| l.partition as u16));

        let mut ball_centre = Vec::new();
        // One test record per ball: whitened centre (n f32), squared threshold ŝ (f32).
        let mut ball_test = Vec::new();
        let mut ball_location = Vec::new();
        for (b, ball) in self.balls.iter().enumerate() {
            ball_centre.extend(le_bytes(&format!("ball {b}: centre"), &ball.centre, n)?);
            let s32 = to_f32(|| format!("ball {b}: threshold"), ball.threshold)?;
            if ball.threshold < 0.0 {
                return Err(invalid(format!("ball {b}: threshold"), "is negative"));
            }
            let s32 = f32_round_down(s32, ball.threshold);
            if ball.location as usize >= self.locations.len() {
                return Err(invalid(
                    format!("ball {b}: location {}", ball.location),
                    "does not exist",
                ));
            }
            // The factor has n × n values (checked above); the centre n finite f32 values.
            let cz = crate::certify::whitened_centre(
                &self.factors[ball.location as usize],
                &ball.centre,
            );
            ball_test.extend(le_bytes(&format!("ball {b}: whitened centre"), &cz, n)?);
            ball_test.extend_from_slice(&s32.to_le_bytes());
            ball_location.push(ball.location);
            if ball.partition >= self.laws.len() {
                return Err(invalid(
                    format!("ball {b}: partition {}", ball.partition),
                    "does not exist",
                ));
            }
        }
        let ball_partition = le_u16(self.balls.iter().map(|b| b.partition as u16));

        let (fb, bx) = fallback_box_bytes(n, m, &self.fallback, &self.input_box)?;
        let payload = PwaPayload {
            K: &K,
            P: &P,
            tables: PwaTables {
                depth: depth as u8, // ≤ MAX_TREE_DEPTH, checked above
                n_nodes: self.nodes.len() as u16,
                n_leaves: self.leaves.len() as u16,
                n_balls: self.balls.len() as u16,
                gain: &gain,
                offset: &offset,
                node: &node_rec,
                leaf_partition: &leaf_partition,
                leaf_end: &leaf_end,
                ball_ref: &ball_ref,
                R: &R,
                ball_centre: &ball_centre,
                ball_test: &ball_test,
                ball_location: &ball_location,
                ball_partition: &ball_partition,
            },
            fallback: fallback_of(&self.fallback, &fb),
            input_box: bx.as_ref().map(|(lo, hi)| InputBox { lo, hi }),
        };
        let dims = Dims {
            n,
            m,
            n_locations: self.locations.len(),
            n_trajectories: 0,
            n_partitions: self.laws.len(),
        };
        let img = Image::new_pwa(dims, period, payload)?;
        let terminal = self.terminal_law.as_ref().map(terminal_body);
        encode_to_vec(&with_optional(
            img,
            &self.fingerprint,
            terminal.as_ref(),
            self.monitor.as_deref(),
        )?)
    }

    /// [`PwaImageBuilder::to_bytes`], then writes the file.
    pub fn write(&self, path: &Path) -> Result<Vec<u8>, EmitError> {
        write_file(path, self.to_bytes()?)
    }

    /// Reads a decoded PWA image back into owned data (each f32 widened exactly to f64); `None` for a
    /// feedforward image. Building it again reproduces the same bytes.
    pub fn from_image(img: &Image<'_>) -> Option<Self> {
        if img.mode() != Mode::PwaFeedback {
            return None;
        }
        let (n, m) = (img.n(), img.m());
        Some(PwaImageBuilder {
            n,
            m,
            period: img.period() as f64,
            locations: (0..img.n_locations())
                .map(|l| LocationLaw {
                    K: (0..m * n).map(|i| img.K(l, i / n, i % n) as f64).collect(),
                    P: (0..n * n).map(|i| img.P(l, i / n, i % n) as f64).collect(),
                })
                .collect(),
            factors: (0..img.n_locations())
                .map(|l| {
                    (0..n * n)
                        .map(|i| img.factor(l, i / n, i % n) as f64)
                        .collect()
                })
                .collect(),
            laws: (0..img.n_partitions())
                .map(|j| PwaLaw {
                    gain: (0..m * n)
                        .map(|i| img.law_gain(j, i / n, i % n) as f64)
                        .collect(),
                    offset: (0..m).map(|r| img.law_offset(j, r) as f64).collect(),
                })
                .collect(),
            nodes: (0..img.n_nodes())
                .map(|i| {
                    let (left, right) = img
                        .node_children(i)
                        .unwrap_or((Child::Outside, Child::Outside));
                    TreeNode {
                        a: (0..n).map(|k| img.node_normal(i, k) as f64).collect(),
                        b: img.node_offset(i) as f64,
                        left,
                        right,
                    }
                })
                .collect(),
            leaves: (0..img.n_leaves())
                .map(|l| PwaLeaf {
                    partition: img.leaf_partition(l),
                    balls: (0..img.leaf_refs(l).1)
                        .filter_map(|k| img.leaf_ball(l, k))
                        .collect(),
                })
                .collect(),
            balls: (0..img.n_balls())
                .map(|b| CertifiedBall {
                    centre: (0..n).map(|i| img.ball_centre(b, i) as f64).collect(),
                    threshold: img.ball_threshold(b) as f64,
                    location: img.ball_location(b) as u8,
                    partition: img.ball_partition(b),
                })
                .collect(),
            fallback: fallback_from_image(img),
            input_box: input_box_from_image(img),
            fingerprint: img.fingerprint().map(<[u8]>::to_vec),
            terminal_law: img
                .terminal_law()
                .map(|t| stored_terminal(&t, img.n(), img.m())),
            monitor: img.monitor().map(|p| p.body().to_vec()),
        })
    }
}

/// `img` with the terminal law's section body, the spec fingerprint and the monitor's section body, each
/// if given (validated by the image).
fn with_optional<'a>(
    img: Image<'a>,
    fp: &'a Option<Vec<u8>>,
    terminal: Option<&'a Vec<u8>>,
    monitor: Option<&'a [u8]>,
) -> Result<Image<'a>, EmitError> {
    let img = match terminal {
        Some(body) => img.with_terminal_law(body)?,
        None => img,
    };
    let img = match fp {
        Some(f) => img.with_fingerprint(f)?,
        None => img,
    };
    match monitor {
        Some(body) => Ok(img.with_monitor(body)?),
        None => Ok(img),
    }
}

/// A terminal law's section body (`shared_types::terminal`): its values as f32, in the stored order.
fn terminal_body(t: &StoredTerminal) -> Vec<u8> {
    let (m, n) = (t.K.nrows(), t.K.ncols());
    let values = t
        .x_e
        .iter()
        .copied()
        .chain((0..m * n).map(|i| t.K[(i / n, i % n)]))
        .chain(t.v.iter().copied())
        .chain((0..n * n).map(|i| t.P[(i / n, i % n)]));
    let mut out: Vec<u8> = values.flat_map(|v| (v as f32).to_le_bytes()).collect();
    out.extend_from_slice(&t.radius.to_le_bytes());
    out
}

/// The terminal law an image stores, each f32 widened exactly.
pub fn stored_terminal(t: &TerminalLaw<'_>, n: usize, m: usize) -> StoredTerminal {
    let f = |b: &[u8]| -> Vec<f64> {
        b.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
            .collect()
    };
    let (K, P) = (f(t.K), f(t.P));
    StoredTerminal {
        x_e: f(t.x_e),
        K: faer::Mat::from_fn(m, n, |i, j| K.get(i * n + j).copied().unwrap_or(0.0)),
        v: f(t.v),
        P: faer::Mat::from_fn(n, n, |i, j| P.get(i * n + j).copied().unwrap_or(0.0)),
        radius: t.radius,
    }
}

/// Encodes a validated image into a vector of exactly its length.
fn encode_to_vec(img: &Image<'_>) -> Result<Vec<u8>, EmitError> {
    let mut out = vec![0u8; img.encoded_len()?];
    let len = image::encode(img, &mut out)?;
    out.truncate(len);
    Ok(out)
}

/// Writes image bytes to `path` and hands them back.
fn write_file(path: &Path, bytes: Vec<u8>) -> Result<Vec<u8>, EmitError> {
    std::fs::write(path, &bytes).map_err(|source| EmitError::Io {
        path: path.display().to_string(),
        source,
    })?;
    Ok(bytes)
}
