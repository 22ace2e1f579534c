//! Sets built from other sets: finite unions, complements, and sets given in output coordinates
//! ({x : Cx ∈ S_y}), each with distance and depth (Def 2.16) in a state metric ‖·‖_R.

use super::cache::{Cached, MetricCache};
use super::linalg::{self, SymEig};
use super::{check_query, GeometryError, Metric, Region, SignedDistanceFn, Witness};

/// A finite union S₁ ∪ … ∪ S_m of sets of the same dimension.
///
/// - dist(x, ∪Sᵢ) = minᵢ dist(x, Sᵢ) (exact).
/// - depth(x, ∪Sᵢ) is reported as maxᵢ depth(x, Sᵢ) over the members containing x. This is always a lower bound
///   (ℝⁿ \ ∪Sᵢ ⊂ ℝⁿ \ Sᵢ), the sound direction for a robustness certificate. It is exact when the witness
///   returned lies in no other member (then points just past it are outside the union), in particular whenever
///   the members are pairwise disjoint. [`Union::depth_bounds`] also returns an upper bound.
pub struct Union {
    n: usize,
    members: Vec<Box<dyn Region>>,
}

impl Union {
    /// At least one member, all of the same dimension.
    pub fn new(members: Vec<Box<dyn Region>>) -> Result<Self, GeometryError> {
        let n = common_dim(&members, "union")?;
        Ok(Self { n, members })
    }

    /// The members.
    pub fn members(&self) -> &[Box<dyn Region>] {
        &self.members
    }

    /// For x in the union: (the reported depth with its witness, an upper bound on the true depth). The upper
    /// bound is the smallest member depth whose witness lies in no other member (+∞ if there is none); when it
    /// equals the reported value, the depth is exact. For x outside: (zero witness, 0).
    pub fn depth_bounds(
        &self,
        x: &[f64],
        metric: &Metric,
    ) -> Result<(Witness, f64), GeometryError> {
        check_query(self.n, x, metric)?;
        let mut best: Option<Witness> = None;
        let mut upper = f64::INFINITY;
        for (j, m) in self.members.iter().enumerate() {
            if !m.contains(x) {
                continue;
            }
            let w = m.try_depth(x, metric)?;
            let covered = self
                .members
                .iter()
                .enumerate()
                .any(|(k, o)| k != j && o.contains(&w.point));
            if !covered {
                upper = upper.min(w.value);
            }
            if best.as_ref().is_none_or(|b| w.value > b.value) {
                best = Some(w);
            }
        }
        match best {
            Some(w) => Ok((w, upper)),
            None => Ok((
                Witness {
                    value: 0.0,
                    point: x.to_vec(),
                },
                0.0,
            )),
        }
    }
}

impl Region for Union {
    fn dim(&self) -> usize {
        self.n
    }
    fn contains(&self, x: &[f64]) -> bool {
        self.members.iter().any(|m| m.contains(x))
    }
    /// Inside within the largest radius a member is sure to hold x; outside within the least radius of
    /// all members sure to exclude it ([`sure_radius_of`]).
    fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
        sure_radius_of(&self.members, x, true)
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_dist(x, metric))
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_depth(x, metric))
    }
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.n, x, metric)?;
        let mut best: Option<Witness> = None;
        for m in &self.members {
            let w = m.try_dist(x, metric)?;
            if best.as_ref().is_none_or(|b| w.value < b.value) {
                best = Some(w);
            }
        }
        best.ok_or(GeometryError::EmptyUnion)
    }
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        Ok(self.depth_bounds(x, metric)?.0)
    }
    fn convex_pieces(&self) -> Option<Vec<&dyn Region>> {
        let mut out = Vec::new();
        for m in &self.members {
            out.extend(m.convex_pieces()?);
        }
        Some(out)
    }
    fn compile(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        self.compiled(metric)
    }
}

/// [`Region::sure_radius`] of a union (`decisive` = true: one member holding x decides) or an
/// intersection (`decisive` = false: one member excluding x decides): a member sure of the decisive side
/// decides within its radius (the largest such); otherwise every member must be sure of the other side,
/// within the least of their radii; else nothing is sure.
fn sure_radius_of(members: &[Box<dyn Region>], x: &[f64], decisive: bool) -> Option<(bool, f64)> {
    let (mut decided, mut other) = (None::<f64>, f64::INFINITY);
    let mut all_known = true;
    for m in members {
        match m.sure_radius(x) {
            Some((side, r)) if side == decisive => decided = Some(decided.map_or(r, |d| d.max(r))),
            Some((_, r)) => other = other.min(r),
            None => all_known = false,
        }
    }
    match decided {
        Some(r) => Some((decisive, r)),
        None if all_known => Some((!decisive, other)),
        None => None,
    }
}

/// The dimension every member shares (at least one member).
fn common_dim(members: &[Box<dyn Region>], what: &'static str) -> Result<usize, GeometryError> {
    let Some(first) = members.first() else {
        return Err(GeometryError::EmptyUnion);
    };
    let n = first.dim();
    for (index, m) in members.iter().enumerate() {
        if m.dim() != n {
            return Err(GeometryError::MemberDimension {
                what,
                index,
                expected: n,
                got: m.dim(),
            });
        }
    }
    Ok(n)
}

/// The empty set in ℝⁿ: every point lies outside it, infinitely far (a task without Unsafe; the target
/// of a segment whose successor certifies nothing).
pub struct Empty(pub usize);

impl Region for Empty {
    fn dim(&self) -> usize {
        self.0
    }
    fn contains(&self, _: &[f64]) -> bool {
        false
    }
    fn sure_radius(&self, _: &[f64]) -> Option<(bool, f64)> {
        Some((false, f64::INFINITY))
    }
    fn dist(&self, _: &[f64], _: &Metric) -> Witness {
        Witness {
            value: f64::INFINITY,
            point: Vec::new(),
        }
    }
    fn depth(&self, _: &[f64], _: &Metric) -> Witness {
        Witness {
            value: 0.0,
            point: Vec::new(),
        }
    }
    fn convex_pieces(&self) -> Option<Vec<&dyn Region>> {
        Some(Vec::new())
    }
}

/// The intersection ∩Sᵢ of regions of one dimension (a hybrid segment's safe transition: a guard and the
/// reset preimage of the next ball, Notation 4.13).
/// - depth(x, ∩Sᵢ) = minᵢ depth(x, Sᵢ) (exact: ℝⁿ \ ∩Sᵢ = ∪(ℝⁿ \ Sᵢ), and the distance to a union is the
///   least distance to a member), with that member's witness.
/// - dist(x, ∩Sᵢ) is reported as maxᵢ dist(x, Sᵢ), a lower bound (each Sᵢ contains the intersection): the
///   sound direction for a set to be avoided; a set to be reached is only ever credited with its depth.
pub struct Intersection {
    n: usize,
    members: Vec<Box<dyn Region>>,
}

impl Intersection {
    /// At least one member, all of the same dimension.
    pub fn new(members: Vec<Box<dyn Region>>) -> Result<Self, GeometryError> {
        let n = common_dim(&members, "intersection")?;
        Ok(Self { n, members })
    }
}

impl Region for Intersection {
    fn dim(&self) -> usize {
        self.n
    }
    fn contains(&self, x: &[f64]) -> bool {
        self.members.iter().all(|m| m.contains(x))
    }
    /// The dual of the union's: outside within the largest radius a member is sure to exclude x, inside
    /// within the least radius of all members sure to hold it ([`sure_radius_of`]).
    fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
        sure_radius_of(&self.members, x, false)
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_dist(x, metric))
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_depth(x, metric))
    }
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.n, x, metric)?;
        let mut best: Option<Witness> = None;
        for m in &self.members {
            let w = m.try_dist(x, metric)?;
            if best.as_ref().is_none_or(|b| w.value > b.value) {
                best = Some(w);
            }
        }
        best.ok_or(GeometryError::EmptyUnion)
    }
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.n, x, metric)?;
        if !self.contains(x) {
            return Ok(Witness {
                value: 0.0,
                point: x.to_vec(),
            });
        }
        let mut best: Option<Witness> = None;
        for m in &self.members {
            let w = m.try_depth(x, metric)?;
            if best.as_ref().is_none_or(|b| w.value < b.value) {
                best = Some(w);
            }
        }
        best.ok_or(GeometryError::EmptyUnion)
    }
}

/// The complement ℝⁿ \ S. Distances are those of its closure: dist(x, ℝⁿ \ S) = depth(x, S) and
/// depth(x, ℝⁿ \ S) = dist(x, S) (Def 2.16), with membership decided by `!S.contains(x)` (so points of ∂S are
/// outside the complement, at distance 0).
pub struct Complement {
    inner: Box<dyn Region>,
}

impl Complement {
    /// The complement of `inner` (any dimension ≥ 1).
    pub fn new(inner: Box<dyn Region>) -> Result<Self, GeometryError> {
        if inner.dim() == 0 {
            return Err(GeometryError::ZeroDimension { what: "complement" });
        }
        Ok(Self { inner })
    }
    /// The complemented set.
    pub fn inner(&self) -> &dyn Region {
        self.inner.as_ref()
    }
}

impl Region for Complement {
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn contains(&self, x: &[f64]) -> bool {
        x.len() == self.inner.dim() && !self.inner.contains(x)
    }
    fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
        if x.len() != self.inner.dim() {
            return None;
        }
        self.inner.sure_radius(x).map(|(inside, r)| (!inside, r))
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_dist(x, metric))
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_depth(x, metric))
    }
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        // x ∉ complement ⇔ x ∈ S: distance to the complement = depth in S (0 for x in the complement).
        self.inner.try_depth(x, metric)
    }
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        self.inner.try_dist(x, metric)
    }
    fn compile(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        self.compiled(metric)
    }
}

/// A set given in output coordinates: {x ∈ ℝⁿ : Cx ∈ S_y}, S_y ⊂ ℝᵖ, C (p×n) of full row rank p.
///
/// Distances are in the state metric R. Because C is onto, dist_R(x, S) = inf over y' ∈ S_y of φ(y' − Cx) with
/// φ(w) = min{‖d‖_R : Cd = w}, and likewise for the depth; φ is the (semi)norm of the induced output metric
/// R_y = (Π C R⁺ Cᵀ Π)⁺, where K = C·N(R) is the set of output moves that cost nothing and Π projects onto K⊥.
/// (If R is nonsingular, K = {0} and R_y = (C R⁻¹ Cᵀ)⁻¹.) The state witness is x + L(y* − Cx), L the minimum-cost
/// lift: L = R⁺CᵀΠR_yΠ + N (CN)⁺ (I − C R⁺CᵀΠR_yΠ), N a basis of N(R).
pub struct InOutput {
    n: usize,
    p: usize,
    C: Vec<f64>,
    /// ‖C‖₂ (rounded up): the Lipschitz constant of x ↦ Cx ([`Region::sure_radius`]).
    c_norm: f64,
    inner: Box<dyn Region>,
    cache: MetricCache<OutputMetric>,
}

#[derive(Debug)]
struct OutputMetric {
    Ry: Metric,
    /// Row-major n×p.
    L: Vec<f64>,
}

impl InOutput {
    /// C row-major p×n (its length a positive multiple of p), finite and of full row rank p; `inner` of
    /// dimension p.
    pub fn new(C: Vec<f64>, p: usize, inner: Box<dyn Region>) -> Result<Self, GeometryError> {
        if p == 0 {
            return Err(GeometryError::ZeroDimension {
                what: "output map C (rows)",
            });
        }
        if C.is_empty() || !C.len().is_multiple_of(p) {
            return Err(GeometryError::Dimension {
                what: "output map C (a positive multiple of p entries)",
                expected: p * (C.len() / p).max(1),
                got: C.len(),
            });
        }
        let n = C.len() / p;
        linalg::check_finite("output map C", &C)?;
        if inner.dim() != p {
            return Err(GeometryError::MemberDimension {
                what: "output set",
                index: 0,
                expected: p,
                got: inner.dim(),
            });
        }
        // Full row rank: CCᵀ positive definite (relative threshold).
        let Ct = linalg::transpose(&C, p, n);
        let CCt = linalg::matmul(&C, &Ct, p, n, p);
        let e = SymEig::new("C Cᵀ", p, &CCt)?;
        let rank = e.values.iter().filter(|&&v| v > 1e-12 * e.max()).count();
        if rank < p || e.max() <= 0.0 {
            return Err(GeometryError::RankDeficient {
                what: "output map C",
                rank,
                expected: p,
            });
        }
        Ok(Self {
            n,
            p,
            C,
            c_norm: e.max().sqrt() * (1.0 + 1e-12),
            inner,
            cache: MetricCache::default(),
        })
    }

    /// Output dimension p.
    pub fn output_dim(&self) -> usize {
        self.p
    }
    /// C, row-major p×n.
    pub fn C(&self) -> &[f64] {
        &self.C
    }
    /// The output set.
    pub fn inner(&self) -> &dyn Region {
        self.inner.as_ref()
    }
    /// y = Cx.
    pub fn output(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.p];
        linalg::matvec(&self.C, self.p, self.n, x, &mut y);
        y
    }

    /// The induced output metric R_y for the state metric `metric` (see the type's documentation).
    pub fn output_metric(&self, metric: &Metric) -> Result<Metric, GeometryError> {
        check_query(self.n, &vec![0.0; self.n], metric)?;
        Ok(self.induced(metric)?.Ry.clone())
    }

    fn induced(&self, metric: &Metric) -> Result<Cached<'_, OutputMetric>, GeometryError> {
        let (n, p) = (self.n, self.p);
        self.cache.get_or_try_insert(metric, || {
            let (_, er) = metric.validated()?;
            let Rp = er.pinv();
            let (N, k) = er.null_basis();
            let C = &self.C;
            let Ct = linalg::transpose(C, p, n);
            let RpCt = linalg::matmul(&Rp, &Ct, n, n, p); // R⁺Cᵀ (n×p)
            let M = linalg::matmul(C, &RpCt, p, n, p); // C R⁺ Cᵀ
                                                       // K = range(CN); Π = I − Π_K.
            let CN = linalg::matmul(C, &N, p, n, k); // p×k
            let CNt = linalg::transpose(&CN, p, k);
            let G = linalg::matmul(&CN, &CNt, p, k, p);
            let eg = SymEig::new("C N Nᵀ Cᵀ", p, &G)?;
            let thr = 1e-12 * eg.max().max(0.0);
            let mut Pi = vec![0.0; p * p];
            for i in 0..p {
                Pi[i * p + i] = 1.0;
            }
            for c in 0..p {
                if eg.values[c] > thr && eg.values[c] > 0.0 {
                    for i in 0..p {
                        for j in 0..p {
                            Pi[i * p + j] -= eg.vectors[i * p + c] * eg.vectors[j * p + c];
                        }
                    }
                }
            }
            let PiMPi = linalg::matmul(&linalg::matmul(&Pi, &M, p, p, p), &Pi, p, p, p);
            let Ry = SymEig::new("induced output metric", p, &PiMPi)?.pinv();
            // Symmetrise against rounding.
            let mut Rys = vec![0.0; p * p];
            for i in 0..p {
                for j in 0..p {
                    Rys[i * p + j] = 0.5 * (Ry[i * p + j] + Ry[j * p + i]);
                }
            }
            // L = R⁺CᵀΠR_yΠ + N (CN)⁺ (I − C R⁺CᵀΠR_yΠ).
            let W = linalg::matmul(&linalg::matmul(&Pi, &Rys, p, p, p), &Pi, p, p, p); // ΠR_yΠ
            let Lr = linalg::matmul(&RpCt, &W, n, p, p); // n×p
            let mut L = Lr.clone();
            if k > 0 {
                let CLr = linalg::matmul(C, &Lr, p, n, p);
                let mut Res = vec![0.0; p * p];
                for i in 0..p {
                    for j in 0..p {
                        Res[i * p + j] = if i == j { 1.0 } else { 0.0 } - CLr[i * p + j];
                    }
                }
                let Gp = eg.pinv();
                let CNp = linalg::matmul(&CNt, &Gp, k, p, p); // (CN)⁺ = (CN)ᵀ (CN (CN)ᵀ)⁺
                let Ln = linalg::matmul(&linalg::matmul(&N, &CNp, n, k, p), &Res, n, p, p);
                for (l, v) in L.iter_mut().zip(&Ln) {
                    *l += v;
                }
            }
            Ok(OutputMetric {
                Ry: Metric { n: p, R: Rys },
                L,
            })
        })
    }

    fn lift(&self, x: &[f64], y: &[f64], w: Witness, om: &OutputMetric) -> Witness {
        if w.point.len() != self.p {
            return Witness {
                value: w.value,
                point: Vec::new(),
            };
        }
        let dy: Vec<f64> = w.point.iter().zip(y).map(|(a, b)| a - b).collect();
        let mut dx = vec![0.0; self.n];
        linalg::matvec(&om.L, self.n, self.p, &dy, &mut dx);
        Witness {
            value: w.value,
            point: x.iter().zip(&dx).map(|(a, b)| a + b).collect(),
        }
    }
}

impl Region for InOutput {
    fn dim(&self) -> usize {
        self.n
    }
    fn contains(&self, x: &[f64]) -> bool {
        if x.len() != self.n {
            return false;
        }
        // A small output on the stack: membership is asked at every sample, and between samples, of every
        // verifier run, where allocating y cost more than the test itself.
        let mut buf = [0.0; 8];
        match buf.get_mut(..self.p) {
            Some(y) => {
                linalg::matvec(&self.C, self.p, self.n, x, y);
                self.inner.contains(y)
            }
            None => self.inner.contains(&self.output(x)),
        }
    }
    /// The output set's sure radius at y = Cx over ‖C‖₂: a state move of d moves y by at most ‖C‖₂‖d‖.
    fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
        if x.len() != self.n {
            return None;
        }
        let mut buf = [0.0; 8];
        let (inside, r) = match buf.get_mut(..self.p) {
            Some(y) => {
                linalg::matvec(&self.C, self.p, self.n, x, y);
                self.inner.sure_radius(y)?
            }
            None => self.inner.sure_radius(&self.output(x))?,
        };
        Some((inside, r / self.c_norm))
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_dist(x, metric))
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_depth(x, metric))
    }
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.n, x, metric)?;
        let om = self.induced(metric)?;
        let y = self.output(x);
        let w = self.inner.try_dist(&y, &om.Ry)?;
        Ok(self.lift(x, &y, w, &om))
    }
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.n, x, metric)?;
        let om = self.induced(metric)?;
        let y = self.output(x);
        let w = self.inner.try_depth(&y, &om.Ry)?;
        Ok(self.lift(x, &y, w, &om))
    }
    fn compile(&self, metric: &Metric) -> Option<Box<dyn SignedDistanceFn + '_>> {
        self.compiled(metric)
    }
    /// {x : Cx ∈ S_y} is convex when S_y is, and its witness is the nearest point (the lift of the
    /// output-metric witness by the least change).
    fn convex_pieces(&self) -> Option<Vec<&dyn Region>> {
        match self.inner.convex_pieces()?.len() {
            1 => Some(vec![self as &dyn Region]),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Ellipsoid, Polytope};

    fn interval(lo: f64, hi: f64) -> Box<dyn Region> {
        Box::new(Polytope::new(1, vec![1.0, -1.0], vec![hi, -lo]).unwrap())
    }

    #[test]
    fn union_of_intervals() {
        let u = Union::new(vec![interval(0.0, 1.0), interval(3.0, 5.0)]).unwrap();
        let m = Metric::euclidean(1);
        assert!((u.dist(&[2.0], &m).value - 1.0).abs() < 1e-9);
        assert!((u.dist(&[6.5], &m).value - 1.5).abs() < 1e-9);
        let (w, upper) = u.depth_bounds(&[4.5], &m).unwrap();
        assert!((w.value - 0.5).abs() < 1e-15 && upper == w.value);
        // Overlapping members: the reported depth is a lower bound, the upper bound says so.
        let v = Union::new(vec![interval(0.0, 2.0), interval(1.0, 5.0)]).unwrap();
        let (w, upper) = v.depth_bounds(&[1.2], &m).unwrap();
        assert!((w.value - 0.8).abs() < 1e-15, "{}", w.value); // depth in [0, 2]; the true depth is 1.2
        assert!(upper >= 1.2 - 1e-15);
        assert!(matches!(Union::new(vec![]), Err(GeometryError::EmptyUnion)));
        let bad = Union::new(vec![
            interval(0.0, 1.0),
            Box::new(Ellipsoid::new(vec![0.0, 0.0], vec![1.0, 0.0, 0.0, 1.0]).unwrap()),
        ]);
        assert!(matches!(
            bad,
            Err(GeometryError::MemberDimension { index: 1, .. })
        ));
    }

    #[test]
    fn complement_swaps_distance_and_depth() {
        let e = Ellipsoid::new(vec![0.0, 0.0], vec![1.0, 0.0, 0.0, 1.0]).unwrap();
        let c = Complement::new(Box::new(e)).unwrap();
        let m = Metric::euclidean(2);
        assert!(!c.contains(&[0.5, 0.0]));
        assert!((c.signed_dist(&[0.5, 0.0], &m).value + 0.5).abs() < 1e-14);
        assert!((c.signed_dist(&[0.0, 3.0], &m).value - 2.0).abs() < 1e-13);
    }

    #[test]
    fn output_set_rejects_bad_C() {
        let inner = || -> Box<dyn Region> { interval(0.0, 1.0) };
        assert!(matches!(
            InOutput::new(vec![0.0, 0.0], 1, inner()),
            Err(GeometryError::RankDeficient { .. })
        ));
        assert!(matches!(
            InOutput::new(vec![], 1, inner()),
            Err(GeometryError::Dimension { .. })
        ));
        assert!(matches!(
            InOutput::new(vec![1.0, 0.0], 2, inner()),
            Err(GeometryError::MemberDimension { .. })
        ));
        assert!(matches!(
            InOutput::new(vec![1.0, f64::NAN], 1, inner()),
            Err(GeometryError::NotFinite { .. })
        ));
    }

    #[test]
    fn output_interval_in_weighted_state_metric() {
        // S = {x ∈ ℝ² : x₀ + x₁ ∈ [0, 1]}, R = diag(1, 4): φ(w)² = w²/(CR⁻¹Cᵀ) = w²/(1 + 1/4).
        let s = InOutput::new(vec![1.0, 1.0], 1, interval(0.0, 1.0)).unwrap();
        let m = Metric::new(2, vec![1.0, 0.0, 0.0, 4.0]).unwrap();
        let x = [2.0, 1.0]; // Cx = 3, two past the set
        let w = s.dist(&x, &m);
        let expect = 2.0 / (1.25_f64).sqrt();
        assert!((w.value - expect).abs() < 1e-9, "{} vs {expect}", w.value);
        assert!((w.point[0] + w.point[1] - 1.0).abs() < 1e-9);
        assert!((m.distance(&x, &w.point) - expect).abs() < 1e-9);
        // With R = diag(1, 0) moving x₁ is free: every output is reachable at zero cost.
        let m0 = Metric::new(2, vec![1.0, 0.0, 0.0, 0.0]).unwrap();
        let w = s.dist(&x, &m0);
        assert!(w.value.abs() < 1e-9);
        let y = w.point[0] + w.point[1];
        assert!(
            (-1e-9..=1.0 + 1e-9).contains(&y) && (w.point[0] - 2.0).abs() < 1e-9,
            "{:?}",
            w.point
        );
    }
}
