//! Named sets that atomic propositions of a formula refer to (Def 2.17, (2.10) with the observation
//! map O(p) = the set named p): a [`Region`] over a list of trace signals, and the metric its signed
//! distance is taken in.

use crate::geometry::{Metric, Region};

/// A set an atomic proposition can name: at sample k its robustness is
/// `region.signed_dist((x_{s₁}(k), …, x_{s_d}(k)), metric)` for the listed signals s₁…s_d.
pub struct NamedSet {
    /// The name formulas use (an identifier, not one of the reserved words).
    pub name: String,
    /// The trace signals forming the set's coordinates, in order (`t` allowed).
    pub signals: Vec<String>,
    /// The set, in those coordinates (`region.dim() == signals.len()`).
    pub region: Box<dyn Region>,
    /// The metric of Def 2.16 (`metric.n == signals.len()`).
    pub metric: Metric,
}

impl NamedSet {
    /// A set with the Euclidean metric on its coordinates.
    pub fn euclidean(
        name: impl Into<String>,
        signals: Vec<String>,
        region: Box<dyn Region>,
    ) -> Self {
        let metric = Metric::euclidean(signals.len());
        Self {
            name: name.into(),
            signals,
            region,
            metric,
        }
    }
}

impl std::fmt::Debug for NamedSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NamedSet")
            .field("name", &self.name)
            .field("signals", &self.signals)
            .field("dim", &self.region.dim())
            .finish()
    }
}

/// An error turning a named-sets file into [`NamedSet`]s for one trace.
#[derive(Debug, Clone, PartialEq, thiserror::Error, miette::Diagnostic)]
#[error("set `{name}`: {message}")]
#[diagnostic(code(mtl::sets))]
pub struct SetsError {
    pub name: String,
    pub message: String,
}

/// Turn validated set descriptions (as read by `spec::load_named_sets`) into [`NamedSet`]s over the
/// signals of a trace, with the Euclidean metric on each set's coordinates.
///
/// Coordinates: a set without `coords` (or `coords = "state"`) is over all the trace's signals in column
/// order; `coords = ["x1", "x3"]` selects the 1st and 3rd signal columns (after `t`), whatever their
/// names. Output coordinates need a plant and are refused here.
pub fn from_spec_sets(
    descs: Vec<(String, crate::spec::SetDesc)>,
    signals: &[String],
) -> Result<Vec<NamedSet>, SetsError> {
    use crate::geometry::{Ball, Ellipsoid, Polytope};
    use crate::spec::{Coords, Shape};
    let mut out = Vec::with_capacity(descs.len());
    for (name, desc) in descs {
        let err = |message: String| SetsError {
            name: name.clone(),
            message,
        };
        let chosen: Vec<String> = match &desc.coords {
            Coords::State => signals.to_vec(),
            Coords::StateIndices(idx) => idx
                .iter()
                .map(|&i| {
                    signals.get(i).cloned().ok_or_else(|| {
                        err(format!(
                            "coordinate x{} does not exist: the trace has {} signal columns ({})",
                            i + 1,
                            signals.len(),
                            signals.join(", ")
                        ))
                    })
                })
                .collect::<Result<_, _>>()?,
            Coords::Output { .. } => {
                return Err(err(
                    "output coordinates need a plant; for a trace, list signal columns as \
                                coords = [\"x1\", …]"
                        .into(),
                ))
            }
        };
        let d = desc.dim();
        if chosen.len() != d {
            return Err(err(format!(
                "the set has dimension {d} but is over {} signals ({})",
                chosen.len(),
                chosen.join(", ")
            )));
        }
        let geo = |e: crate::geometry::GeometryError| err(e.to_string());
        let region: Box<dyn Region> = match desc.shape {
            Shape::Ball { center, radius } => {
                Box::new(Ball::new(center, Metric::euclidean(d).R, radius).map_err(geo)?)
            }
            Shape::Ellipsoid { center, Q } => {
                Box::new(Ellipsoid::new(center, Q.data).map_err(geo)?)
            }
            Shape::Polytope { A, b } => Box::new(Polytope::new(d, A.data, b).map_err(geo)?),
            Shape::Box { lo, hi } => {
                // lo ≤ y ≤ hi as [I; −I] y ≤ [hi; −lo].
                let mut A = vec![0.0; 2 * d * d];
                let mut b = Vec::with_capacity(2 * d);
                for i in 0..d {
                    A[i * d + i] = 1.0;
                    A[(d + i) * d + i] = -1.0;
                }
                b.extend_from_slice(&hi);
                b.extend(lo.iter().map(|v| -v));
                Box::new(Polytope::new(d, A, b).map_err(geo)?)
            }
        };
        out.push(NamedSet::euclidean(name, chosen, region));
    }
    Ok(out)
}
