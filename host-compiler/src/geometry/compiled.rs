//! Signed distances (2.8) compiled for one metric: a region's metric-dependent factorisations looked up
//! once (from the sets' own caches), then every point answered without allocating, locking or
//! re-validating the metric. For many points of one set in one metric: an MTL atom over a whole trace.
//!
//! A compiled value is the one [`Region::signed_dist`] gives, bit for bit: the same operations in the
//! same order (membership by the same test, the same boundary solve). Only the witness point is not
//! formed. A set whose members have no compiled form ([`Region::compile`] is `None`, e.g. polytopes,
//! whose distance is a QP) is not compiled at all, so callers fall back to [`Region::signed_dist`] for
//! the whole set.

use super::combinators::{Complement, InOutput, Union};
use super::ellipsoid::Ellipsoid;
use super::ellipsoid_distance::{BoundaryWorkspace, EllipsoidBoundaryDistance};
use super::{linalg, Metric, Region};
use std::sync::Arc;

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
    f: Arc<EllipsoidBoundaryDistance>,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Ball, Polytope};
    use rand::{Rng, SeedableRng};

    /// A random symmetric positive definite n×n matrix (row-major).
    fn spd(rng: &mut impl Rng, n: usize) -> Vec<f64> {
        let a: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut m = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                m[i * n + j] = (0..n).map(|k| a[i * n + k] * a[j * n + k]).sum::<f64>()
                    + if i == j { 0.1 } else { 0.0 };
            }
        }
        m
    }

    /// Every compiled set agrees with `signed_dist` bit for bit, at random points near and far, in random
    /// metrics: ellipsoids, balls, sets over two of four coordinates (Schur-complement metrics), their
    /// unions and complements.
    #[test]
    fn compiled_equals_signed_dist() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
        for case in 0..40 {
            let n = 4;
            let metric = Metric::new(n, spd(&mut rng, n)).unwrap();
            let ell = |rng: &mut rand_chacha::ChaCha8Rng, d: usize| -> Box<dyn Region> {
                let c: Vec<f64> = (0..d).map(|_| rng.random_range(-1.0..1.0)).collect();
                if rng.random_bool(0.5) {
                    Box::new(Ellipsoid::new(c, spd(rng, d)).unwrap())
                } else {
                    let r = rng.random_range(0.1..1.0);
                    Box::new(Ball::new(c, spd(rng, d), r).unwrap())
                }
            };
            let proj = |i: usize, j: usize| {
                let mut C = vec![0.0; 2 * n];
                C[i] = 1.0;
                C[n + j] = 1.0;
                C
            };
            let members: Vec<Box<dyn Region>> = vec![
                Box::new(InOutput::new(proj(0, 2), 2, ell(&mut rng, 2)).unwrap()),
                Box::new(InOutput::new(proj(1, 3), 2, ell(&mut rng, 2)).unwrap()),
                ell(&mut rng, n),
            ];
            let set: Box<dyn Region> = if case % 2 == 0 {
                Box::new(Union::new(members).unwrap())
            } else {
                Box::new(Complement::new(Box::new(Union::new(members).unwrap())).unwrap())
            };
            let mut f = set.compile(&metric).expect("a compiled form");
            for _ in 0..200 {
                let scale = if rng.random_bool(0.5) { 0.5 } else { 4.0 };
                let x: Vec<f64> = (0..n).map(|_| rng.random_range(-scale..scale)).collect();
                let want = set.signed_dist(&x, &metric).value;
                let got = f.eval(&x).signed();
                assert_eq!(got.to_bits(), want.to_bits(), "case {case} at {x:?}");
            }
            assert!(f.eval(&[0.0, f64::NAN, 0.0, 0.0]).value.is_nan());
            assert!(f.eval(&[0.0; 3]).value.is_nan());
        }
        // A polytope has no compiled form, nor does a union with one.
        let p: Box<dyn Region> = Box::new(Polytope::new(1, vec![1.0], vec![0.0]).unwrap());
        let u = Union::new(vec![p]).unwrap();
        assert!(u.compile(&Metric::euclidean(1)).is_none());
    }
}
