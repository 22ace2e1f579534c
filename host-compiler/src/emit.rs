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
//! certified one), then runs the same validation the firmware runs at decode. The effect of rounding `K`,
//! `P`, `v` and the centres to f32 is for certification to bound (DESIGN §5), not for this module.
#![allow(non_snake_case)]

use std::path::Path;

use shared_types::capacity::{MAX_LOCATIONS, MAX_M, MAX_N, MAX_STEPS, MAX_TRAJECTORIES};
use shared_types::image::{self, Dims, Fallback, Image, ImageError, InputBox, Mode, Payload};

pub use shared_types::image::Terminal;

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
        }
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
        capacity("total table rows", self.total_steps(), 1, MAX_STEPS)?;
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

        let mut traj_end = Vec::new();
        let mut centre = Vec::new();
        let mut delta = Vec::new();
        let mut v = Vec::new();
        let mut location = Vec::new();
        let mut end = 0u32;
        for (t, tr) in self.trajectories.iter().enumerate() {
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
            location.extend_from_slice(&tr.location);
            end += len as u32; // ≤ MAX_STEPS, checked above
            traj_end.extend_from_slice(&end.to_le_bytes());
        }

        let fb = match &self.fallback {
            FallbackLaw::Linear { K, x_ref, u_ref } => Some((
                le_bytes("fallback K", K, m * n)?,
                le_bytes("fallback x_ref", x_ref, n)?,
                le_bytes("fallback u_ref", u_ref, m)?,
            )),
            _ => None,
        };
        let bx = match &self.input_box {
            Some((lo, hi)) => {
                for j in 0..m.min(lo.len()).min(hi.len()) {
                    if lo[j] > hi[j] {
                        return Err(EmitError::Invalid {
                            what: format!("input box component {j}"),
                            reason: "has its lower bound above its upper bound",
                        });
                    }
                }
                Some((
                    le_bytes("input box lo", lo, m)?,
                    le_bytes("input box hi", hi, m)?,
                ))
            }
            None => None,
        };

        let payload = Payload {
            K: &K,
            P: &P,
            traj_end: &traj_end,
            centre: &centre,
            delta: &delta,
            v: &v,
            location: &location,
            fallback: match (&self.fallback, &fb) {
                (_, Some((K, x_ref, u_ref))) => Fallback::Linear { K, x_ref, u_ref },
                (FallbackLaw::Hold, _) => Fallback::Hold,
                _ => Fallback::Zero,
            },
            input_box: bx.as_ref().map(|(lo, hi)| InputBox { lo, hi }),
            terminal: self.terminal,
        };
        let dims = Dims {
            n,
            m,
            n_locations: self.locations.len(),
            n_trajectories: self.trajectories.len(),
            n_partitions: 0,
        };
        let img = Image::new(Mode::Feedforward, dims, period, payload)?;
        let mut out = vec![0u8; img.encoded_len()?];
        let len = image::encode(&img, &mut out)?;
        out.truncate(len);
        Ok(out)
    }

    /// [`ImageBuilder::to_bytes`], then writes the file.
    pub fn write(&self, path: &Path) -> Result<Vec<u8>, EmitError> {
        let bytes = self.to_bytes()?;
        std::fs::write(path, &bytes).map_err(|source| EmitError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Ok(bytes)
    }

    /// Reads a decoded image back into owned data (each f32 widened exactly to f64). Building it again
    /// reproduces the same bytes.
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
        let fallback = match img.fallback() {
            Fallback::Hold => FallbackLaw::Hold,
            Fallback::Zero => FallbackLaw::Zero,
            Fallback::Linear { .. } => FallbackLaw::Linear {
                K: (0..m * n)
                    .map(|i| img.fallback_K(i / n, i % n) as f64)
                    .collect(),
                x_ref: (0..n).map(|i| img.fallback_x_ref(i) as f64).collect(),
                u_ref: (0..m).map(|j| img.fallback_u_ref(j) as f64).collect(),
            },
        };
        let input_box = img.has_input_box().then(|| {
            let b: Vec<(f32, f32)> = (0..m).filter_map(|j| img.input_bounds(j)).collect();
            (
                b.iter().map(|p| p.0 as f64).collect(),
                b.iter().map(|p| p.1 as f64).collect(),
            )
        });
        ImageBuilder {
            n,
            m,
            period: img.period() as f64,
            locations,
            trajectories,
            fallback,
            input_box,
            terminal: img.terminal(),
        }
    }
}
