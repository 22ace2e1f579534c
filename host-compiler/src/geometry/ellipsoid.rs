//! Ellipsoids {x : (x − c)ᵀQ(x − c) ≤ 1} with Q positive definite or only semidefinite (degenerate ellipsoids:
//! unbounded cylinders and slabs, §7.2.2), and balls of a CAF metric {x : ‖x − c‖_P ≤ r} (3.2), as
//! [`Region`]s. Distance and depth both come from the boundary problem (7.2) solved by
//! [`EllipsoidBoundaryDistance`], factored once per metric and cached.

use super::cache::{Cached, MetricCache};
use super::ellipsoid_distance::EllipsoidBoundaryDistance;
use super::linalg::{self, SymEig};
use super::{check_query, GeometryError, Metric, Region, SignedDistanceFn, Witness};
use std::cell::RefCell;

thread_local! {
    /// One boundary workspace per thread for [`Ellipsoid`]'s distance and depth queries, which the
    /// certificates and the optimisers ask millions of times ([`EllipsoidBoundaryDistance::workspace_in`]).
    static BOUNDARY_WORKSPACE: RefCell<Option<super::ellipsoid_distance::BoundaryWorkspace>> =
        const { RefCell::new(None) };
}

/// {x ∈ ℝⁿ : (x − c)ᵀQ(x − c) ≤ 1}, Q symmetric PSD and nonzero.
///
/// For x outside, dist_R(x, E) is the minimum of ‖x − y‖_R over the boundary (a segment from x to any point of
/// E crosses the boundary no farther away); for x inside, depth_R(x, E) is the same minimum (the nonconvex
/// case of §7.2). With R singular the value may be 0 away from the boundary (zero-cost directions, §7.2.2).
pub struct Ellipsoid {
    c: Vec<f64>,
    Q: Vec<f64>,
    /// √λ_max(Q): the Lipschitz constant of y ↦ ‖y − c‖_Q ([`Region::sure_radius`]).
    sqrt_lmax: f64,
    cache: MetricCache<EllipsoidBoundaryDistance>,
}

impl Clone for Ellipsoid {
    fn clone(&self) -> Self {
        Self {
            c: self.c.clone(),
            Q: self.Q.clone(),
            sqrt_lmax: self.sqrt_lmax,
            cache: MetricCache::default(),
        }
    }
}

impl std::fmt::Debug for Ellipsoid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ellipsoid")
            .field("c", &self.c)
            .field("Q", &self.Q)
            .finish()
    }
}

impl Ellipsoid {
    /// Centre `c` (length n ≥ 1) and shape `Q` (row-major n×n): finite, symmetric (to 1e-9 relative, stored
    /// symmetrised), PSD (to 1e-10 relative) and not zero.
    pub fn new(c: Vec<f64>, Q: Vec<f64>) -> Result<Self, GeometryError> {
        let n = c.len();
        if n == 0 {
            return Err(GeometryError::ZeroDimension {
                what: "ellipsoid centre",
            });
        }
        linalg::check_finite("ellipsoid centre", &c)?;
        let Q = linalg::symmetrize_checked("ellipsoid Q", n, &Q)?;
        let e = SymEig::new("ellipsoid Q", n, &Q)?;
        e.check_psd("ellipsoid Q")?;
        if e.values.iter().all(|v| *v == 0.0) {
            return Err(GeometryError::ZeroMatrix {
                what: "ellipsoid Q",
            });
        }
        Ok(Self {
            c,
            Q,
            sqrt_lmax: e.max().sqrt(),
            cache: MetricCache::default(),
        })
    }

    /// The centre.
    pub fn center(&self) -> &[f64] {
        &self.c
    }
    /// The shape matrix (row-major, symmetric).
    pub fn shape(&self) -> &[f64] {
        &self.Q
    }
    /// (x − c)ᵀQ(x − c); the set is where this is ≤ 1. No validation of `x`'s length beyond a debug check.
    pub fn level(&self, x: &[f64]) -> f64 {
        linalg::quad_form_shifted(&self.Q, x, &self.c)
    }

    /// Factor the boundary-distance problem (7.2) for `metric` (uncached); use this to answer many points with
    /// the allocation-free [`EllipsoidBoundaryDistance::solve`].
    pub fn factor(&self, metric: &Metric) -> Result<EllipsoidBoundaryDistance, GeometryError> {
        if metric.n != self.c.len() {
            return Err(GeometryError::Dimension {
                what: "metric dimension",
                expected: self.c.len(),
                got: metric.n,
            });
        }
        EllipsoidBoundaryDistance::new(&self.c, &self.Q, &metric.R)
    }

    /// The cached factorisation for `metric`.
    pub fn factored(
        &self,
        metric: &Metric,
    ) -> Result<Cached<'_, EllipsoidBoundaryDistance>, GeometryError> {
        self.cache.get_or_try_insert(metric, || self.factor(metric))
    }

    fn boundary(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        let f = self.factored(metric)?;
        let mut point = vec![0.0; x.len()];
        // The thread's workspace (every value in it is written before it is read, so reuse changes no
        // result); a fresh one if it is in use further up this thread's stack.
        let s = BOUNDARY_WORKSPACE.with(|cell| match cell.try_borrow_mut() {
            Ok(mut slot) => f.solve(x, f.workspace_in(&mut slot), &mut point),
            Err(_) => f.solve(x, &mut f.workspace(), &mut point),
        })?;
        Ok(Witness {
            value: s.value,
            point,
        })
    }
}

impl Region for Ellipsoid {
    fn dim(&self) -> usize {
        self.c.len()
    }
    fn contains(&self, x: &[f64]) -> bool {
        x.len() == self.c.len() && self.level(x) <= 1.0
    }
    /// ‖y − c‖_Q differs from ‖x − c‖_Q by at most √λ_max(Q)‖y − x‖₂ (triangle inequality of the
    /// seminorm), so the ball of radius |‖x − c‖_Q − 1| / √λ_max(Q) stays on x's side of the boundary.
    fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
        if x.len() != self.c.len() {
            return None;
        }
        let s = self.level(x).sqrt();
        if !s.is_finite() {
            return None;
        }
        let inside = s <= 1.0;
        Some((
            inside,
            super::sure_margin((s - 1.0).abs(), s.max(1.0)) / self.sqrt_lmax,
        ))
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_dist(x, metric))
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_depth(x, metric))
    }
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.dim(), x, metric)?;
        if self.contains(x) {
            self.factored(metric)?; // validate the metric even when the answer is trivial
            return Ok(Witness {
                value: 0.0,
                point: x.to_vec(),
            });
        }
        self.boundary(x, metric)
    }
    fn compile(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        self.compiled(metric)
    }
    fn convex_pieces(&self) -> Option<Vec<&dyn Region>> {
        Some(vec![self])
    }
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.dim(), x, metric)?;
        if !self.contains(x) {
            self.factored(metric)?;
            return Ok(Witness {
                value: 0.0,
                point: x.to_vec(),
            });
        }
        self.boundary(x, metric)
    }
}

/// A ball of a CAF metric, {x : ‖x − c‖_P ≤ r} with ‖v‖_P = sqrt(vᵀPv) (3.2): the ellipsoid with Q = P/r².
#[derive(Clone, Debug)]
pub struct Ball {
    center: Vec<f64>,
    P: Vec<f64>,
    r: f64,
    inner: Ellipsoid,
}

impl Ball {
    /// Centre (length n ≥ 1), P (row-major n×n, symmetric PSD, nonzero; a CAF's P is positive definite) and
    /// radius r > 0, all finite.
    pub fn new(center: Vec<f64>, P: Vec<f64>, r: f64) -> Result<Self, GeometryError> {
        if !(r.is_finite() && r > 0.0) {
            return Err(GeometryError::NotPositive {
                what: "ball radius",
                value: r,
            });
        }
        let n = center.len();
        let Ps = linalg::symmetrize_checked("ball metric P", n, &P)?;
        let Q: Vec<f64> = Ps.iter().map(|p| p / (r * r)).collect();
        let inner = Ellipsoid::new(center.clone(), Q).map_err(|e| match e {
            GeometryError::NotPsd { min_eigenvalue, .. } => GeometryError::NotPsd {
                what: "ball metric P",
                min_eigenvalue: min_eigenvalue * r * r,
            },
            GeometryError::ZeroMatrix { .. } => GeometryError::ZeroMatrix {
                what: "ball metric P",
            },
            other => other,
        })?;
        Ok(Self {
            center,
            P: Ps,
            r,
            inner,
        })
    }
    /// The centre.
    pub fn center(&self) -> &[f64] {
        &self.center
    }
    /// The CAF matrix P (symmetrised).
    pub fn P(&self) -> &[f64] {
        &self.P
    }
    /// The radius.
    pub fn radius(&self) -> f64 {
        self.r
    }
    /// The same set as an ellipsoid (Q = P/r²).
    pub fn as_ellipsoid(&self) -> &Ellipsoid {
        &self.inner
    }
}

impl Region for Ball {
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn contains(&self, x: &[f64]) -> bool {
        self.inner.contains(x)
    }
    fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
        self.inner.sure_radius(x)
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        self.inner.dist(x, metric)
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        self.inner.depth(x, metric)
    }
    fn compile(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        self.inner.compiled(metric)
    }
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        self.inner.try_dist(x, metric)
    }
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        self.inner.try_depth(x, metric)
    }
    fn convex_pieces(&self) -> Option<Vec<&dyn Region>> {
        Some(vec![self])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ball_in_its_own_metric_has_radius_depth_at_centre() {
        let P = vec![4.0, 1.0, 1.0, 3.0];
        let b = Ball::new(vec![1.0, -2.0], P.clone(), 0.5).unwrap();
        let m = Metric::new(2, P).unwrap();
        let w = b.depth(&[1.0, -2.0], &m);
        assert!((w.value - 0.5).abs() < 1e-14, "{}", w.value);
        // Outside along any direction, the P-distance is ‖x − c‖_P − r.
        let x = [2.0, -1.0];
        let d = m.distance(&x, &[1.0, -2.0]);
        let w = b.dist(&x, &m);
        assert!(
            (w.value - (d - 0.5)).abs() < 1e-13,
            "{} vs {}",
            w.value,
            d - 0.5
        );
        assert!((b.as_ellipsoid().level(&w.point) - 1.0).abs() < 1e-12);
        assert!(matches!(
            Ball::new(vec![0.0], vec![1.0], 0.0),
            Err(GeometryError::NotPositive { .. })
        ));
        assert!(matches!(
            Ball::new(vec![0.0], vec![-1.0], 1.0),
            Err(GeometryError::NotPsd { .. })
        ));
    }

    #[test]
    fn signed_distance_convention() {
        let e = Ellipsoid::new(vec![0.0, 0.0], vec![1.0, 0.0, 0.0, 0.25]).unwrap(); // semi-axes 1 and 2
        let m = Metric::euclidean(2);
        assert!((e.signed_dist(&[0.0, 0.0], &m).value - 1.0).abs() < 1e-14);
        assert!((e.signed_dist(&[3.0, 0.0], &m).value + 2.0).abs() < 1e-13);
        assert_eq!(e.dist(&[0.2, 0.0], &m).value, 0.0);
        assert_eq!(e.depth(&[3.0, 0.0], &m).value, 0.0);
        // Wrong dimension: NaN witness from the infallible form, an error from try_*.
        assert!(e.dist(&[0.0], &m).value.is_nan());
        assert!(e.try_dist(&[0.0], &m).is_err());
        assert!(e
            .try_dist(
                &[0.0, 5.0],
                &Metric {
                    n: 2,
                    R: vec![1.0, 3.0, 3.0, 1.0]
                }
            )
            .is_err());
    }
}
