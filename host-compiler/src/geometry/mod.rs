//! Sets and distances (ch. 7, Def 2.16): ellipsoids, polytopes, CAF balls, unions, complements and sets in
//! output coordinates, each with distance, depth and signed distance in a PSD metric ‖·‖_R.
//!
//! Sign convention (Def 2.16, (2.8)): `signed_dist(x) = depth(x)` when x ∈ S (≥ 0) and `-dist(x)` when x ∉ S.
//!
//! When R is only positive semidefinite, ‖·‖_R is a seminorm: moving along the null space of R costs nothing,
//! so distances can be zero between distinct points (a pseudometric, Def 2.15). Every set here handles that
//! case exactly as §7.2.2 does for ellipsoids, and as documented per type.
//!
//! Submodules:
//! - [`ellipsoid_distance`]: the §7.2 algorithm (standard form (7.5), degenerate reductions §7.2.2,
//!   Theorem 7.6, Algorithm 7 with Lemma 7.9 / (7.45)), factored once per (Q, R) with an allocation-free
//!   per-point path (Remark 7.11);
//! - [`ellipsoid`]: [`Ellipsoid`] and CAF [`Ball`] regions built on it;
//! - [`polytope`]: [`Polytope`] {x : Ax ≤ b}, distance by the QP (7.1), depth by facets;
//! - [`combinators`]: [`Union`], [`Intersection`], [`Complement`], [`Empty`], [`InOutput`] (sets given
//!   in output coordinates y = Cx);
//! - [`compiled`]: a set's signed distance in one metric, factored once for many points
//!   ([`Region::compile`]), with the values of [`Region::signed_dist`].

pub mod combinators;
pub mod compiled;
pub mod ellipsoid;
pub mod ellipsoid_distance;
pub mod polytope;

mod cache;
pub(crate) mod linalg;

pub use cache::Cached;
pub use combinators::{Complement, Empty, InOutput, Intersection, Union};
pub use compiled::{Signed, SignedDistanceFn};
pub use ellipsoid::{Ball, Ellipsoid};
pub use ellipsoid_distance::{
    BoundaryDistanceSettings, BoundarySolution, BoundaryWorkspace, EllipsoidBoundaryDistance,
    OptimumKind, StandardForm,
};
pub use polytope::Polytope;

/// Bad input to a geometry constructor or query: says what was wrong and where.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeometryError {
    #[error("{what}: expected {expected} entries, got {got}")]
    Dimension {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("{what}: entry {index} is not finite ({value})")]
    NotFinite {
        what: &'static str,
        index: usize,
        value: f64,
    },
    #[error("{what}: not symmetric, entry ({i},{j}) = {a} but ({j},{i}) = {b}")]
    NotSymmetric {
        what: &'static str,
        i: usize,
        j: usize,
        a: f64,
        b: f64,
    },
    #[error("{what}: not positive semidefinite (smallest eigenvalue {min_eigenvalue:e})")]
    NotPsd {
        what: &'static str,
        min_eigenvalue: f64,
    },
    #[error("{what}: must not be the zero matrix")]
    ZeroMatrix { what: &'static str },
    #[error("{what}: must be positive and finite, got {value}")]
    NotPositive { what: &'static str, value: f64 },
    #[error(transparent)]
    Settings(#[from] crate::settings::SettingError),
    #[error("{what}: has rank {rank}, needs full row rank {expected}")]
    RankDeficient {
        what: &'static str,
        rank: usize,
        expected: usize,
    },
    #[error("{what}: the dimension must be at least 1")]
    ZeroDimension { what: &'static str },
    #[error("eigendecomposition of {what} did not converge")]
    EigenNoConvergence { what: &'static str },
    #[error("polytope: every row of A is zero, so the set is all of ℝⁿ (or empty); give at least one nonzero row")]
    NoConstraints,
    #[error("polytope: the set {{x : Ax ≤ b}} is empty")]
    EmptyPolytope,
    #[error("a union or an intersection needs at least one member")]
    EmptyUnion,
    #[error("{what}: member {index} lives in ℝ^{got}, expected ℝ^{expected}")]
    MemberDimension {
        what: &'static str,
        index: usize,
        expected: usize,
        got: usize,
    },
    #[error("{what}: quadratic-programming solver ended with status {status}")]
    Solver { what: &'static str, status: String },
    #[error("{what}: {reason}")]
    Degenerate { what: &'static str, reason: String },
}

/// A positive semidefinite weight R defining the (semi)norm ‖v‖_R = sqrt(vᵀ R v). Row-major n×n.
#[derive(Clone, Debug, PartialEq)]
pub struct Metric {
    pub n: usize,
    /// Row-major, symmetric, PSD.
    pub R: Vec<f64>,
}

impl Metric {
    /// The Euclidean metric on ℝⁿ.
    pub fn euclidean(n: usize) -> Self {
        let mut R = vec![0.0; n * n];
        for i in 0..n {
            R[i * n + i] = 1.0;
        }
        Self { n, R }
    }

    /// A validated metric: `R` row-major n×n, finite, symmetric (to 1e-9 relative; stored symmetrised) and
    /// positive semidefinite (to 1e-10 relative). A zero R is allowed (every distance is then 0).
    pub fn new(n: usize, R: Vec<f64>) -> Result<Self, GeometryError> {
        let m = Self { n, R };
        let (R, _) = m.validated()?;
        Ok(Self { n, R })
    }

    /// Check this metric (dimension ≥ 1, shape, finiteness, symmetry, PSD); return the symmetrised matrix and its
    /// eigendecomposition. Public fields can hold anything, so every factorisation goes through here.
    pub(crate) fn validated(&self) -> Result<(Vec<f64>, linalg::SymEig), GeometryError> {
        if self.n == 0 {
            return Err(GeometryError::ZeroDimension { what: "metric R" });
        }
        let R = linalg::symmetrize_checked("metric R", self.n, &self.R)?;
        let eig = linalg::SymEig::new("metric R", self.n, &R)?;
        eig.check_psd("metric R")?;
        Ok((R, eig))
    }

    /// ‖v‖_R = sqrt(max(0, vᵀRv)) (no validation; `v.len()` must be n).
    pub fn norm(&self, v: &[f64]) -> f64 {
        linalg::quad_form(&self.R, v).max(0.0).sqrt()
    }

    /// ‖x − y‖_R (no validation; lengths must be n).
    pub fn distance(&self, x: &[f64], y: &[f64]) -> f64 {
        linalg::quad_form_shifted(&self.R, x, y).max(0.0).sqrt()
    }
}

/// A distance together with the point of the set (or of its complement's closure) that attains it.
/// Robustness and optimisation need the point (critical point, §5.3).
#[derive(Clone, Debug, PartialEq)]
pub struct Witness {
    /// The distance value (≥ 0).
    pub value: f64,
    /// A minimiser y* on the boundary of the set (or inside it for `dist`), in state coordinates.
    pub point: Vec<f64>,
}

impl Witness {
    /// The witness reported by the infallible [`Region`] methods when the query itself is invalid (wrong
    /// dimension, bad metric): value NaN and no point. Use the `try_*` methods to get the error instead.
    pub fn invalid() -> Self {
        Self {
            value: f64::NAN,
            point: Vec::new(),
        }
    }

    /// Convert a `try_*` result to the infallible form, logging the error.
    pub(crate) fn or_invalid(r: Result<Witness, GeometryError>) -> Witness {
        r.unwrap_or_else(|e| {
            tracing::warn!(error = %e, "geometry query on invalid input; returning NaN witness");
            Witness::invalid()
        })
    }
}

/// A closed set in ℝⁿ with distance, depth and signed distance in a metric (Def 2.16).
///
/// The infallible methods return [`Witness::invalid`] (value NaN) on a bad query (point of the wrong
/// dimension, metric not symmetric PSD of the right size); the `try_*` methods return the error instead.
/// `contains` returns false for a point of the wrong dimension.
pub trait Region: Send + Sync {
    /// Dimension of the ambient state space.
    fn dim(&self) -> usize;
    /// Membership.
    fn contains(&self, x: &[f64]) -> bool;
    /// dist_R(x, S) with a minimiser; value 0 when x ∈ S.
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness;
    /// depth_R(x, S) = dist_R(x, ℝⁿ \ S) with a minimiser on ∂S; value 0 when x ∉ S.
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness;
    /// Signed distance (2.8): depth inside, −dist outside, with the witness point.
    fn signed_dist(&self, x: &[f64], metric: &Metric) -> Witness {
        if self.contains(x) {
            self.depth(x, metric)
        } else {
            let mut w = self.dist(x, metric);
            w.value = -w.value;
            w
        }
    }
    /// A cheap, conservative answer for a whole Euclidean ball about `x`: `Some((inside, r))` says that
    /// every point y with ‖y − x‖₂ < r has `contains(y) == inside` (r ≥ 0; 0 says nothing about other
    /// points). Closed form and allocation-free, with a relative 10⁻⁹ of the compared quantity kept back
    /// so that `contains`' own rounding cannot disagree ([`sure_margin`]): for the verifier's check between
    /// samples, where a period whose excursion is below r needs no test. `None` when the set has no such
    /// bound (the caller then tests its points one by one) or `x` is not a valid point.
    fn sure_radius(&self, _x: &[f64]) -> Option<(bool, f64)> {
        None
    }
    /// [`Region::signed_dist`] in `metric` compiled for many points ([`compiled`]): the same values, bit
    /// for bit, without the witness. `None` where the set has no compiled form or the metric does not
    /// fit; callers then use [`Region::signed_dist`].
    fn compile(&self, _metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        None
    }
    /// The set as a finite union of convex sets whose [`Region::dist`] witnesses are their nearest
    /// points in the metric (so that the witness gives a supporting half-space: the directional
    /// inter-sample bound of `certify` needs one per piece); `None` when it is not known to be one.
    fn convex_pieces(&self) -> Option<Vec<&dyn Region>> {
        None
    }
    /// [`Region::dist`] with errors reported.
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        Ok(self.dist(x, metric))
    }
    /// [`Region::depth`] with errors reported.
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        Ok(self.depth(x, metric))
    }
    /// [`Region::signed_dist`] with errors reported.
    fn try_signed_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.dim(), x, metric)?;
        if self.contains(x) {
            self.try_depth(x, metric)
        } else {
            let mut w = self.try_dist(x, metric)?;
            w.value = -w.value;
            Ok(w)
        }
    }
}

/// The part of a scalar test's slack `slack` (how far the compared quantity is from its threshold, both
/// of size about `scale`) that is sure whatever `contains`' rounding: the slack less a relative 10⁻⁹ of
/// the scale, clamped at 0 ([`Region::sure_radius`]).
pub(crate) fn sure_margin(slack: f64, scale: f64) -> f64 {
    (slack - 1e-9 * scale).max(0.0)
}

/// Membership of one set asked at many nearby points in turn (a run's states between samples, a
/// formula's trace sampled finer). Each answer is `contains`' own; where a point lies within the sure
/// radius ([`Region::sure_radius`]) of the point that last set it, it is that point's answer, with no
/// test. The anchor moves to a point the radius does not reach.
#[derive(Clone, Debug, Default)]
pub struct NearbyMembership {
    anchor: Vec<f64>,
    inside: bool,
    /// 0: no anchor.
    radius: f64,
}

impl NearbyMembership {
    pub fn new() -> Self {
        Self::default()
    }

    /// `set.contains(x)`, from the anchor's sure ball when `x` lies in it.
    pub fn contains(&mut self, set: &dyn Region, x: &[f64]) -> bool {
        if self.radius > 0.0 && x.len() == self.anchor.len() {
            let d2: f64 = x
                .iter()
                .zip(&self.anchor)
                .map(|(a, b)| (a - b) * (a - b))
                .sum();
            // The distance's own rounding (a few ulps) is kept back from the radius.
            if d2.sqrt() < self.radius * (1.0 - 1e-12) {
                return self.inside;
            }
        }
        match set.sure_radius(x) {
            Some((inside, r)) if r > 0.0 => {
                self.anchor.clear();
                self.anchor.extend_from_slice(x);
                self.inside = inside;
                self.radius = r;
                inside
            }
            _ => {
                self.radius = 0.0;
                set.contains(x)
            }
        }
    }
}

/// Check a query point and a metric against the ambient dimension (shape and finiteness only; the metric's
/// symmetry and PSD are checked when a set factors it).
pub(crate) fn check_query(n: usize, x: &[f64], metric: &Metric) -> Result<(), GeometryError> {
    linalg::check_vector("query point", x, n)?;
    if metric.n != n {
        return Err(GeometryError::Dimension {
            what: "metric dimension",
            expected: n,
            got: metric.n,
        });
    }
    linalg::check_vector("metric R", &metric.R, n * n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metric_new_validates() {
        assert!(Metric::new(2, vec![1.0, 0.0, 0.0, 1.0]).is_ok());
        assert!(matches!(
            Metric::new(2, vec![1.0, 2.0, 2.0, 1.0]),
            Err(GeometryError::NotPsd { .. })
        ));
        assert!(matches!(
            Metric::new(2, vec![1.0, 0.0, 0.0]),
            Err(GeometryError::Dimension { .. })
        ));
        assert!(matches!(
            Metric::new(0, vec![]),
            Err(GeometryError::ZeroDimension { .. })
        ));
        // PSD but singular is allowed: a seminorm.
        let m = Metric::new(2, vec![1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(m.distance(&[0.0, 0.0], &[0.0, 5.0]), 0.0);
        assert_eq!(m.distance(&[0.0, 0.0], &[3.0, 5.0]), 3.0);
    }

    /// A set that counts its membership tests.
    struct Counted<'a>(&'a dyn Region, std::sync::atomic::AtomicUsize);

    impl Region for Counted<'_> {
        fn dim(&self) -> usize {
            self.0.dim()
        }
        fn contains(&self, x: &[f64]) -> bool {
            self.1.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            self.0.contains(x)
        }
        fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
            self.0.dist(x, metric)
        }
        fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
            self.0.depth(x, metric)
        }
        fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
            self.0.sure_radius(x)
        }
    }

    /// Along random walks through and across a union (a polytope, an ellipsoid and a set seen through
    /// an output map), `NearbyMembership` answers exactly as `contains` at every point, while testing
    /// only a fraction of them; a set without sure radii is tested at every point.
    #[test]
    fn nearby_membership_is_contains_with_fewer_tests() {
        use rand::{Rng, SeedableRng};
        let square = Polytope::new(
            2,
            vec![1.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, -1.0, 1.0, 1.0],
            vec![1.0, 1.0, 1.0, 1.0, 1.5],
        )
        .unwrap();
        let disc = Ellipsoid::new(vec![2.0, 0.5], vec![4.0, 0.0, 0.0, 1.0]).unwrap();
        let band = InOutput::new(
            vec![1.0, -1.0],
            1,
            Box::new(Polytope::new(1, vec![1.0, -1.0], vec![-2.5, 3.0]).unwrap()),
        )
        .unwrap();
        let union = Union::new(vec![Box::new(square), Box::new(disc), Box::new(band)]).unwrap();
        let counted = Counted(&union, Default::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(46);
        let (mut points, mut inside) = (0usize, 0usize);
        for walk in 0..40 {
            let mut near = NearbyMembership::new();
            let mut x = [rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0)];
            let step = if walk % 2 == 0 { 0.01 } else { 0.2 };
            for _ in 0..400 {
                x[0] += rng.random_range(-step..step);
                x[1] += rng.random_range(-step..step);
                let got = near.contains(&counted, &x);
                assert_eq!(got, union.contains(&x), "at {x:?}");
                points += 1;
                inside += usize::from(got);
            }
        }
        let tests = counted.1.load(std::sync::atomic::Ordering::Relaxed);
        assert!(
            inside > points / 20 && inside < points - points / 20,
            "{inside} of {points}"
        );
        assert!(tests < points / 4, "{tests} tests for {points} points");
        // Without sure radii (the default), every point is tested.
        struct Plain<'a>(&'a dyn Region);
        impl Region for Plain<'_> {
            fn dim(&self) -> usize {
                self.0.dim()
            }
            fn contains(&self, x: &[f64]) -> bool {
                self.0.contains(x)
            }
            fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
                self.0.dist(x, metric)
            }
            fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
                self.0.depth(x, metric)
            }
        }
        let plain = Counted(&Plain(&union), Default::default());
        let mut near = NearbyMembership::new();
        for k in 0..100 {
            let x = [0.001 * k as f64, 0.0];
            assert_eq!(near.contains(&plain, &x), union.contains(&x));
        }
        assert_eq!(plain.1.load(std::sync::atomic::Ordering::Relaxed), 100);
    }
}
