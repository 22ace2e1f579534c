//! Signed distances (2.8) compiled for one metric: a region's metric-dependent factorisations looked up
//! once (from the sets' own caches), then every point answered without allocating, locking or
//! re-validating the metric. For many points of one set in one metric: an MTL atom over a whole trace.
//!
//! A compiled value is the one [`Region::signed_dist`] gives, bit for bit: the same operations in the
//! same order (membership by the same test, the same boundary solve). Only the witness point is not
//! formed. A set whose members have no compiled form ([`Region::compile`] is `None`) is not compiled at
//! all, so callers fall back to [`Region::signed_dist`] for the whole set. A polytope's compiled form
//! takes the same path as its own distance, the QP included where no closed form applies.

use super::combinators::{Complement, InOutput, Union};
use super::ellipsoid::Ellipsoid;
use super::ellipsoid_distance::{BoundaryWorkspace, EllipsoidBoundaryDistance};
use super::polytope::{FacetSteps, Polytope};
use super::{linalg, Metric, Region};

/// One point's answer: membership, and the depth inside or the distance outside (≥ 0; NaN for a point
/// of the wrong length or with a non-finite entry, where [`Region::signed_dist`] reports NaN too).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Signed {
    pub inside: bool,
    pub value: f64,
}

impl Signed {
    /// The answer of an invalid query.
    const INVALID: Signed = Signed {
        inside: false,
        value: f64::NAN,
    };

    /// The signed distance (2.8): depth inside, −dist outside.
    pub fn signed(self) -> f64 {
        if self.inside {
            self.value
        } else {
            -self.value
        }
    }
}

/// A region's signed distance in one metric, ready for many points; holds its own scratch space.
pub trait SignedDistanceFn: Send {
    /// Membership and depth or distance of `x` ([`Signed`]).
    fn eval(&mut self, x: &[f64]) -> Signed;
}

/// Whether `x` is a valid query point of dimension n (the check every `try_*` path starts with).
fn valid(x: &[f64], n: usize) -> bool {
    x.len() == n && x.iter().all(|v| v.is_finite())
}

/// [`Ellipsoid`]: membership by its level, the depth or distance by the cached boundary solve (7.2).
struct EllipsoidFn<'a> {
    set: &'a Ellipsoid,
    f: super::Cached<'a, EllipsoidBoundaryDistance>,
    ws: BoundaryWorkspace,
    point: Vec<f64>,
}

impl SignedDistanceFn for EllipsoidFn<'_> {
    fn eval(&mut self, x: &[f64]) -> Signed {
        if !valid(x, self.point.len()) {
            return Signed::INVALID;
        }
        let inside = self.set.contains(x);
        match self.f.solve(x, &mut self.ws, &mut self.point) {
            Ok(s) => Signed {
                inside,
                value: s.value,
            },
            Err(_) => Signed::INVALID,
        }
    }
}

impl Ellipsoid {
    /// The compiled form of [`Region::signed_dist`] in `metric` (`None` if the metric does not fit).
    pub(crate) fn compiled(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        let f = self.factored(metric).ok()?;
        let ws = f.workspace();
        Some(Box::new(EllipsoidFn {
            set: self,
            point: vec![0.0; self.dim()],
            f,
            ws,
        }))
    }
}

/// [`Polytope`]: membership by its rows; inside, the depth by the facet steps; outside, the distance by
/// [`Polytope::dist_outside`] (what its `try_dist` runs), with the metric's steps looked up once.
struct PolytopeFn<'a> {
    set: &'a Polytope,
    steps: super::Cached<'a, FacetSteps>,
}

impl SignedDistanceFn for PolytopeFn<'_> {
    fn eval(&mut self, x: &[f64]) -> Signed {
        if !valid(x, self.set.dim()) {
            return Signed::INVALID;
        }
        if self.set.contains(x) {
            Signed {
                inside: true,
                value: self.set.depth_inside(x, &self.steps).value,
            }
        } else {
            match self.set.dist_outside(x, &self.steps) {
                Ok(w) => Signed {
                    inside: false,
                    value: w.value,
                },
                Err(_) => Signed::INVALID,
            }
        }
    }
}

impl Polytope {
    /// The compiled form of [`Region::signed_dist`] in `metric` (`None` if the metric does not fit).
    pub(crate) fn compiled(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        if metric.n != self.dim() {
            return None;
        }
        Some(Box::new(PolytopeFn {
            set: self,
            steps: self.steps(metric).ok()?,
        }))
    }
}

/// [`InOutput`]: the inner set's answer at y = Cx in the induced output metric.
struct InOutputFn<'a> {
    set: &'a InOutput,
    inner: Box<dyn SignedDistanceFn + 'a>,
    y: Vec<f64>,
}

impl SignedDistanceFn for InOutputFn<'_> {
    fn eval(&mut self, x: &[f64]) -> Signed {
        let (n, p) = (self.set.dim(), self.y.len());
        if !valid(x, n) {
            return Signed::INVALID;
        }
        linalg::matvec(self.set.C(), p, n, x, &mut self.y);
        self.inner.eval(&self.y)
    }
}

impl InOutput {
    /// The compiled form of [`Region::signed_dist`] in `metric` (`None` if the metric does not fit or the
    /// output set has no compiled form).
    pub(crate) fn compiled(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        if metric.n != self.dim() {
            return None;
        }
        let Ry = self.output_metric(metric).ok()?;
        let inner = self.inner().compile(&Ry)?;
        Some(Box::new(InOutputFn {
            set: self,
            inner,
            y: vec![0.0; self.output_dim()],
        }))
    }
}

/// [`Union`]: inside, the largest depth of a member holding x; outside, the least distance to a member
/// (the first extremum, as [`Union`]'s own scans).
struct UnionFn<'a> {
    members: Vec<Box<dyn SignedDistanceFn + 'a>>,
}

impl SignedDistanceFn for UnionFn<'_> {
    fn eval(&mut self, x: &[f64]) -> Signed {
        let mut depth: Option<f64> = None;
        let mut dist: Option<f64> = None;
        for m in &mut self.members {
            let s = m.eval(x);
            if s.value.is_nan() {
                return Signed::INVALID;
            }
            if s.inside {
                if depth.is_none_or(|d| s.value > d) {
                    depth = Some(s.value);
                }
            } else if dist.is_none_or(|d| s.value < d) {
                dist = Some(s.value);
            }
        }
        match (depth, dist) {
            (Some(value), _) => Signed {
                inside: true,
                value,
            },
            (None, Some(value)) => Signed {
                inside: false,
                value,
            },
            (None, None) => Signed::INVALID,
        }
    }
}

impl Union {
    /// The compiled form of [`Region::signed_dist`] in `metric` (`None` unless every member has one).
    pub(crate) fn compiled(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        let members = self
            .members()
            .iter()
            .map(|m| m.compile(metric))
            .collect::<Option<Vec<_>>>()?;
        Some(Box::new(UnionFn { members }))
    }
}

/// [`Complement`]: membership flipped, the inner depth as the distance and the inner distance as the
/// depth.
struct ComplementFn<'a> {
    inner: Box<dyn SignedDistanceFn + 'a>,
}

impl SignedDistanceFn for ComplementFn<'_> {
    fn eval(&mut self, x: &[f64]) -> Signed {
        let s = self.inner.eval(x);
        Signed {
            inside: !s.inside,
            value: s.value,
        }
    }
}

impl Complement {
    /// The compiled form of [`Region::signed_dist`] in `metric` (`None` unless the inner set has one).
    pub(crate) fn compiled(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        Some(Box::new(ComplementFn {
            inner: self.inner().compile(metric)?,
        }))
    }
}
