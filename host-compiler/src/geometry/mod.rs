//! Sets and distances (ch. 7, Def 2.16): ellipsoids, polytopes, CAF balls, unions, complements and sets in
//! output coordinates, each with distance, depth and signed distance in a PSD metric ‖·‖_R.
//!
//! Sign convention (Def 2.16, (2.8)): `signed_dist(x) = depth(x)` when x ∈ S (≥ 0) and `-dist(x)` when x ∉ S.

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

/// A closed set in ℝⁿ with distance, depth and signed distance in a metric (Def 2.16).
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
}
