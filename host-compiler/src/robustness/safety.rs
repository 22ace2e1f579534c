//! Safety robustness of one sampled nominal trajectory: the radius δ₀ of Theorem 4.7 and its parts.
//!
//! Given the nominal samples x̃(κ) at times t_κ, a time bound T, the sets Goal and Unsafe, per-sample
//! input constraints and the CAF metric ψ (as a [`Metric`]), Theorem 4.7 certifies every closed-loop
//! trajectory that stays ψ-closer than δ₀ to the nominal one, where
//!
//! * t* = argmax over samples with t_κ ≤ T of depth_ψ(x̃(κ), Goal)                        (4.12)
//! * δ_Goal = depth_ψ(x̃(t*), Goal)                                                      (4.13)
//! * δ_Unsafe = min over κ ≤ κ* of dist_ψ(x̃(κ), Unsafe)                                  (4.14)
//! * δ_Input = min over κ ≤ κ* of dist_ψ(x̃(κ), {x : k(κ, x) ∉ Input})                    (4.15)
//! * δ₀ = min(δ_Goal, δ_Unsafe, δ_Input)                                                 (4.11)
//!
//! Goal is a *max* over time (the trajectory only has to be in Goal once, at t*), while Unsafe and Input
//! are *mins* over the prefix up to and including t* (they must hold at every sample until Goal is
//! reached). Lemma 4.4 and Corollary 4.6 turn each part into a guarantee for the perturbed trajectory.
//!
//! **Signed values.** Instead of the unsigned depth and dist of (4.12)–(4.15) we use the signed distance
//! (2.8): `Dist(x̃, Goal)` for Goal and `−Dist(x̃, Unsafe)`, `Dist(x̃, A_κ)` for Unsafe and Input, where
//! A_κ = {x : k(κ, x) ∈ Input} is the set of states whose feedback input is admissible (so
//! dist(x̃, ℝⁿ∖A_κ) is the distance to the "unsafe input" set of (4.15)). Whenever a part is positive it
//! equals the theorem's value, and δ₀ > 0 exactly when the theorem certifies a neighbourhood; when the
//! nominal trajectory itself fails (never reaches Goal, touches Unsafe, saturates the input), the
//! negative value says by how much, and the critical time and point still give the optimiser a
//! direction (§5.3). The certified radius is `max(δ₀, 0)`.
//!
//! **Cost.** One pass over the samples up to T for Goal, then one pass over the samples up to t* for
//! Unsafe and Input: O(N) work. The passes ask for values only; witness points are computed once, at
//! the critical samples. Goal and Unsafe given as [`SafetySet::Ellipsoid`] (ellipsoids and CAF balls)
//! are factored once per call and solved without allocation by the §7.2 boundary-distance solver, and
//! most samples do not need that solve at all: cheap two-sided bounds on the signed distance (see
//! `EllipsoidBounds`) and its 1-Lipschitz continuity in ‖·‖_R prove that they cannot be the
//! maximiser, so the result is the full scan's. Any other [`Region`] goes through
//! [`Region::signed_dist`] at every sample. Ties in the argmax pick the earliest sample, which gives
//! the shortest prefix and hence the largest δ_Unsafe and δ_Input among the maximisers.
//!
//! [`safety_robustness_joint`] is a variant that chooses t* to maximise the combined radius instead of
//! the Goal depth alone (the robustness of the until embedding of Remark 2.29, with a closed prefix); it
//! is never smaller than the Theorem 4.7 value and is certified by the same proof, since the proof only
//! uses that x̃(t*) is δ₀-deep in Goal and the prefix up to t* is δ₀-far from the bad sets.

use crate::geometry::{
    Ball, BoundaryWorkspace, Ellipsoid, EllipsoidBoundaryDistance, GeometryError, Metric, Region,
    Witness,
};

/// Errors of the safety robustness computation: bad trajectories, mismatched dimensions and sets whose
/// distance routines return NaN.
#[derive(Debug, Clone, PartialEq, thiserror::Error, miette::Diagnostic)]
pub enum SafetyError {
    #[error("trajectory has no samples")]
    Empty,
    #[error("state dimension n must be positive")]
    ZeroDimension,
    #[error(
        "trajectory has {times} sample times but {states} state entries; expected {expected} (= {times} × n with n = {n})"
    )]
    LengthMismatch {
        times: usize,
        states: usize,
        n: usize,
        expected: usize,
    },
    #[error("sample time t[{index}] is not finite ({value})")]
    NonFiniteTime { index: usize, value: f64 },
    #[error("sample times must increase strictly: t[{index}] = {value} does not exceed t[{prev_index}] = {prev}", prev_index = .index - 1)]
    NonMonotoneTime { index: usize, prev: f64, value: f64 },
    #[error("component {component} of state sample {index} is not finite ({value})")]
    NonFiniteState {
        index: usize,
        component: usize,
        value: f64,
    },
    #[error("{what} has dimension {found}, but the trajectory has n = {n}")]
    DimensionMismatch {
        what: &'static str,
        found: usize,
        n: usize,
    },
    #[error("metric weight R has {found} entries, expected n × n = {expected}")]
    MetricShape { found: usize, expected: usize },
    #[error("metric weight R has a non-finite entry at row {row}, column {col}")]
    MetricNonFinite { row: usize, col: usize },
    #[error("time bound T = {T} is not a number")]
    HorizonNaN { T: f64 },
    #[error("time bound T = {T} is before the first sample time t[0] = {t0}; no sample to reach Goal at")]
    HorizonBeforeStart { T: f64, t0: f64 },
    #[error(
        "input constraints are given for {available} samples, but the horizon T covers {needed}"
    )]
    InputTooShort { needed: usize, available: usize },
    #[error("the signed distance to {what} at sample {index} is NaN")]
    NaNDistance { what: &'static str, index: usize },
    #[error("{what}: {source}")]
    Geometry {
        what: &'static str,
        #[source]
        source: GeometryError,
    },
}

/// A borrowed, validated sampled trajectory: times t_κ (finite, strictly increasing) and states x̃(κ)
/// stored row-major, `states[κ·n .. (κ+1)·n]`.
#[derive(Clone, Copy, Debug)]
pub struct SampledTrajectory<'a> {
    times: &'a [f64],
    states: &'a [f64],
    n: usize,
}

impl<'a> SampledTrajectory<'a> {
    /// Validate and wrap. Every state must be finite and the times strictly increasing.
    pub fn new(times: &'a [f64], states: &'a [f64], n: usize) -> Result<Self, SafetyError> {
        if n == 0 {
            return Err(SafetyError::ZeroDimension);
        }
        if times.is_empty() {
            return Err(SafetyError::Empty);
        }
        let expected = times.len().saturating_mul(n);
        if states.len() != expected {
            return Err(SafetyError::LengthMismatch {
                times: times.len(),
                states: states.len(),
                n,
                expected,
            });
        }
        for (index, &value) in times.iter().enumerate() {
            if !value.is_finite() {
                return Err(SafetyError::NonFiniteTime { index, value });
            }
            if index > 0 && value <= times[index - 1] {
                return Err(SafetyError::NonMonotoneTime {
                    index,
                    prev: times[index - 1],
                    value,
                });
            }
        }
        if let Some(pos) = states.iter().position(|v| !v.is_finite()) {
            return Err(SafetyError::NonFiniteState {
                index: pos / n,
                component: pos % n,
                value: states[pos],
            });
        }
        Ok(Self { times, states, n })
    }
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.times.len()
    }
    /// Always false: construction rejects empty trajectories.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }
    /// State dimension n.
    pub fn n(&self) -> usize {
        self.n
    }
    /// Sample times.
    pub fn times(&self) -> &'a [f64] {
        self.times
    }
    /// The state x̃(κ). Panics if κ ≥ len (an indexing bug, not bad input).
    pub fn state(&self, kappa: usize) -> &'a [f64] {
        &self.states[kappa * self.n..(kappa + 1) * self.n]
    }
}

/// Per-sample input constraints mapped into state space.
///
/// For sample κ the feedback input is u = k(κ, x) (for the linear laws of ch. 3, `K x + v(κ)`); the
/// *admissible-state set* is A_κ = {x : k(κ, x) ∈ Input}. An implementation returns the signed distance
/// (2.8) of x to A_κ in the given metric: positive (the depth, = distance to the unsafe-input set of
/// (4.15)) when the input at x is admissible, negative when it is not, with the witness point of the
/// set that attains it.
pub trait InputSets {
    /// How many samples (κ = 0, 1, …) are covered, or `None` when every index is.
    fn samples(&self) -> Option<usize>;
    /// Ambient dimension of the sets, when known.
    fn dim(&self) -> Option<usize> {
        None
    }
    /// Signed distance of `x` (the nominal state at sample `kappa`) to A_κ.
    fn signed_dist(&self, kappa: usize, x: &[f64], metric: &Metric) -> Witness;
    /// The value of [`InputSets::signed_dist`] alone; override when it is cheaper without the witness.
    fn signed_value(&self, kappa: usize, x: &[f64], metric: &Metric) -> f64 {
        self.signed_dist(kappa, x, metric).value
    }
}

/// One admissible-state set per sample, κ-th entry for sample κ.
impl InputSets for Vec<&dyn Region> {
    fn samples(&self) -> Option<usize> {
        Some(self.len())
    }
    fn dim(&self) -> Option<usize> {
        self.first().map(|r| r.dim())
    }
    fn signed_dist(&self, kappa: usize, x: &[f64], metric: &Metric) -> Witness {
        self[kappa].signed_dist(x, metric)
    }
}

/// One admissible-state set per sample, κ-th entry for sample κ.
impl InputSets for Vec<Box<dyn Region>> {
    fn samples(&self) -> Option<usize> {
        Some(self.len())
    }
    fn dim(&self) -> Option<usize> {
        self.first().map(|r| r.dim())
    }
    fn signed_dist(&self, kappa: usize, x: &[f64], metric: &Metric) -> Witness {
        self[kappa].signed_dist(x, metric)
    }
}

/// Input constraints given by a closure `(κ, x, metric) ↦ Dist(x, A_κ)` with its witness (see
/// [`InputSets`]); covers every sample index.
pub struct FnInput<F>(pub F);

impl<F> InputSets for FnInput<F>
where
    F: Fn(usize, &[f64], &Metric) -> Witness,
{
    fn samples(&self) -> Option<usize> {
        None
    }
    fn signed_dist(&self, kappa: usize, x: &[f64], metric: &Metric) -> Witness {
        (self.0)(kappa, x, metric)
    }
}

/// Goal or Unsafe as the safety passes query it.
#[derive(Clone, Copy)]
pub enum SafetySet<'a> {
    /// Any region, through [`Region::signed_dist`].
    Region(&'a dyn Region),
    /// An ellipsoid (a CAF ball via [`Ball::as_ellipsoid`]): factored once for the metric, then queried
    /// without allocation by the §7.2 boundary-distance solver.
    Ellipsoid(&'a Ellipsoid),
}

impl<'a> SafetySet<'a> {
    /// Ambient dimension.
    pub fn dim(&self) -> usize {
        match self {
            SafetySet::Region(r) => r.dim(),
            SafetySet::Ellipsoid(e) => e.dim(),
        }
    }
}

impl<'a> From<&'a dyn Region> for SafetySet<'a> {
    fn from(r: &'a dyn Region) -> Self {
        SafetySet::Region(r)
    }
}

impl<'a> From<&'a Ellipsoid> for SafetySet<'a> {
    fn from(e: &'a Ellipsoid) -> Self {
        SafetySet::Ellipsoid(e)
    }
}

impl<'a> From<&'a Ball> for SafetySet<'a> {
    fn from(b: &'a Ball) -> Self {
        SafetySet::Ellipsoid(b.as_ellipsoid())
    }
}

/// The sets, metric and time bound of one safety problem (Problem 2.26) in state coordinates.
/// Output-space sets are passed already pulled back to states (the geometry module's `InOutput`).
#[derive(Clone, Copy)]
pub struct SafetySpec<'a> {
    pub goal: SafetySet<'a>,
    pub unsafe_set: SafetySet<'a>,
    /// `None` when the problem has no input constraint (δ_Input = +∞).
    pub input: Option<&'a dyn InputSets>,
    /// The CAF metric ψ(x, x') = ‖x − x'‖_R.
    pub metric: &'a Metric,
    /// Time bound T: samples with t_κ ≤ T (compared exactly) may serve as t*.
    pub T: f64,
}

/// A [`SafetySet`] made ready for many queries in one metric (two per call, so size is no concern).
#[allow(clippy::large_enum_variant)]
enum Prepared<'a> {
    Region(&'a dyn Region),
    Ellipsoid {
        e: &'a Ellipsoid,
        f: crate::geometry::Cached<'a, EllipsoidBoundaryDistance>,
        ws: BoundaryWorkspace,
        bounds: EllipsoidBounds,
    },
}

impl<'a> Prepared<'a> {
    fn new(set: SafetySet<'a>, metric: &Metric, what: &'static str) -> Result<Self, SafetyError> {
        Ok(match set {
            SafetySet::Region(r) => Prepared::Region(r),
            SafetySet::Ellipsoid(e) => {
                let f = e
                    .factored(metric)
                    .map_err(|source| SafetyError::Geometry { what, source })?;
                let ws = f.workspace();
                let bounds = EllipsoidBounds::new(e.center(), e.shape(), metric);
                Prepared::Ellipsoid { e, f, ws, bounds }
            }
        })
    }
    /// Dist(x, S) (2.8), value only; NaN if the geometry reports an error.
    #[inline]
    fn value(&mut self, x: &[f64], metric: &Metric) -> f64 {
        match self {
            Prepared::Region(r) => r.signed_dist(x, metric).value,
            Prepared::Ellipsoid { e, f, ws, .. } => {
                // The boundary distance (7.2) is the depth inside and the distance outside.
                let d = f.distance(x, ws).unwrap_or(f64::NAN);
                if e.contains(x) {
                    d
                } else {
                    -d
                }
            }
        }
    }
    /// Cheap bounds lo ≤ Dist(x, S) ≤ hi, when the set has them.
    #[inline]
    fn bounds(&self, x: &[f64]) -> Option<(f64, f64)> {
        match self {
            Prepared::Region(_) => None,
            Prepared::Ellipsoid { bounds, .. } => Some(bounds.signed(x)),
        }
    }
    /// Dist(x, S) with its witness point.
    fn witness(&self, x: &[f64], metric: &Metric) -> Witness {
        match self {
            Prepared::Region(r) => r.signed_dist(x, metric),
            Prepared::Ellipsoid { e, .. } => e.signed_dist(x, metric),
        }
    }
}

/// Two-sided bounds on the signed distance Dist_R(x, E) to an ellipsoid E = {x : (x − c)ᵀQ(x − c) ≤ 1},
/// at the cost of two quadratic forms, so that samples that cannot be critical skip the (7.2) solve.
///
/// With g(x) = ((x − c)ᵀQ(x − c))^½ and ρ(x) = ‖x − c‖_R:
/// * the ray point c + (x − c)/g lies on ∂E at R-distance ρ·|g − 1|/g from x, so |Dist| ≤ ρ|g − 1|/g;
/// * g is a seminorm of x − c with |g(y) − g(x)| ≤ √λ̄ ‖y − x‖_R for any λ̄ ≥ sup vᵀQv / vᵀRv, and g = 1
///   on ∂E, so |Dist| ≥ |g − 1|/√λ̄.
///
/// Inside (g ≤ 1) Dist ∈ [(1 − g)/√λ̄, ρ(1 − g)/g]; outside Dist ∈ [−ρ(g − 1)/g, −(g − 1)/√λ̄]. λ̄ is
/// bounded through a Cholesky factor R = LLᵀ: λmax(L⁻¹QL⁻ᵀ) ≤ min(Frobenius norm, largest absolute row
/// sum); without one (R singular) the lower bound on |Dist| is dropped. Both bounds are widened by
/// 1e-9·(1 + ρ) to cover rounding here and in the exact solver.
struct EllipsoidBounds {
    c: Vec<f64>,
    Q: Vec<f64>,
    R: Vec<f64>,
    /// 1/√λ̄, or 0 when no bound on λmax is available.
    inv_sqrt_lambda: f64,
}

impl EllipsoidBounds {
    fn new(c: &[f64], Q: &[f64], metric: &Metric) -> Self {
        let n = c.len();
        let R = metric.R.clone();
        let inv_sqrt_lambda = match cholesky(&R, n) {
            Some(L) => {
                // M = L⁻¹ Q L⁻ᵀ: X = L⁻¹Q, then M = L⁻¹Xᵀ (M is symmetric).
                let X = lower_solve_columns(&L, Q, n);
                let mut Xt = vec![0.0; n * n];
                for i in 0..n {
                    for j in 0..n {
                        Xt[i * n + j] = X[j * n + i];
                    }
                }
                let M = lower_solve_columns(&L, &Xt, n);
                let frob = M.iter().map(|v| v * v).sum::<f64>().sqrt();
                let rows = (0..n)
                    .map(|i| M[i * n..(i + 1) * n].iter().map(|v| v.abs()).sum::<f64>())
                    .fold(0.0, f64::max);
                let lambda = frob.min(rows) * (1.0 + 1e-6);
                if lambda.is_finite() && lambda > 0.0 {
                    1.0 / lambda.sqrt()
                } else {
                    0.0
                }
            }
            None => 0.0,
        };
        Self {
            c: c.to_vec(),
            Q: Q.to_vec(),
            R,
            inv_sqrt_lambda,
        }
    }

    /// (lo, hi) with lo ≤ Dist_R(x, E) ≤ hi.
    #[inline]
    #[allow(clippy::needless_range_loop)]
    fn signed(&self, x: &[f64]) -> (f64, f64) {
        let n = self.c.len();
        let (mut h, mut r2) = (0.0, 0.0);
        for i in 0..n {
            let di = x[i] - self.c[i];
            let (mut qi, mut ri) = (0.0, 0.0);
            for j in 0..n {
                let dj = x[j] - self.c[j];
                qi += self.Q[i * n + j] * dj;
                ri += self.R[i * n + j] * dj;
            }
            h += di * qi;
            r2 += di * ri;
        }
        let g = h.max(0.0).sqrt();
        let rho = r2.max(0.0).sqrt();
        let m = 1e-9 * (1.0 + rho);
        let (lo, hi) = if g <= 1.0 {
            let hi = if g > 0.0 {
                rho * (1.0 - g) / g
            } else {
                f64::INFINITY
            };
            ((1.0 - g) * self.inv_sqrt_lambda, hi)
        } else {
            (-rho * (g - 1.0) / g, -(g - 1.0) * self.inv_sqrt_lambda)
        };
        if lo.is_nan() || hi.is_nan() {
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            (lo - m, hi + m)
        }
    }
}

/// Lower Cholesky factor L (A = LLᵀ, row-major, zeros above the diagonal) of a symmetric positive definite
/// n×n row-major matrix, from faer's LLᵀ factorisation (the lower triangle of A is read), or `None` when A is
/// not positive definite: faer finds a non-positive pivot, or a pivot L[i,i]² is not above 1e-12 times the
/// largest diagonal entry of A (numerically singular, the tolerance of the hand-written factorisation this
/// replaces), or an entry is not finite. Called once per ellipsoidal set per robustness call (setup, not per
/// sample), so faer's per-call overhead (about 0.6–1.5 µs against 0.05–0.4 µs hand-written, n = 2..12) is
/// not measurable in the safety_robustness bench.
fn cholesky(A: &[f64], n: usize) -> Option<Vec<f64>> {
    let scale = (0..n).map(|i| A[i * n + i].abs()).fold(0.0, f64::max);
    let llt = faer::Mat::from_fn(n, n, |i, j| A[i * n + j])
        .llt(faer::Side::Lower)
        .ok()?;
    let Lf = llt.L();
    let mut L = vec![0.0; n * n];
    for i in 0..n {
        #[allow(clippy::neg_cmp_op_on_partial_ord)] // also rejects NaN
        if !(Lf[(i, i)] * Lf[(i, i)] > 1e-12 * scale) {
            return None;
        }
        for j in 0..=i {
            L[i * n + j] = Lf[(i, j)];
        }
    }
    L.iter().all(|v| v.is_finite()).then_some(L)
}

/// L⁻¹B for lower-triangular L and B (both n×n, row-major), by forward substitution per column.
fn lower_solve_columns(L: &[f64], B: &[f64], n: usize) -> Vec<f64> {
    let mut X = vec![0.0; n * n];
    for col in 0..n {
        for i in 0..n {
            let mut s = B[i * n + col];
            for k in 0..i {
                s -= L[i * n + k] * X[k * n + col];
            }
            X[i * n + col] = s / L[i * n + i];
        }
    }
    X
}

/// Which part of δ₀ is smallest (ties resolved in the order Goal, Unsafe, Input).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    Goal,
    Unsafe,
    Input,
}

/// One part of δ₀ with where it is attained.
#[derive(Clone, Debug, PartialEq)]
pub struct Critical {
    /// The signed value of this part (see the module doc).
    pub value: f64,
    /// The critical sample index κ.
    pub index: usize,
    /// Its time t_κ.
    pub time: f64,
    /// The critical set point: the point of the set's boundary (or of the set, when the nominal state is
    /// outside it) that attains the distance from x̃(κ).
    pub point: Vec<f64>,
}

/// The result of Theorem 4.7 for one trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct SafetyRobustness {
    /// δ₀ = min(δ_Goal, δ_Unsafe, δ_Input), (4.11), signed.
    pub delta: f64,
    /// Which part attains δ₀.
    pub binding: Binding,
    /// δ_Goal, (4.13); its `index` is κ* (t*, (4.12)).
    pub goal: Critical,
    /// δ_Unsafe, (4.14), the minimum over samples 0..=κ*.
    pub unsafe_set: Critical,
    /// δ_Input, (4.15), the minimum over samples 0..=κ*; `None` without input constraints.
    pub input: Option<Critical>,
    /// Number of samples with t_κ ≤ T (the candidates for t*).
    pub horizon_samples: usize,
}

impl SafetyRobustness {
    /// The radius Theorem 4.7 certifies: max(δ₀, 0).
    pub fn certified_radius(&self) -> f64 {
        self.delta.max(0.0)
    }
    /// True when the theorem certifies a non-empty neighbourhood (δ₀ > 0).
    pub fn is_certified(&self) -> bool {
        self.delta > 0.0
    }
    /// The critical time t* (time of the Goal part).
    pub fn t_star(&self) -> f64 {
        self.goal.time
    }
}

/// The metric against the trajectory's dimension.
fn check_metric(n: usize, metric: &Metric) -> Result<(), SafetyError> {
    if metric.n != n {
        return Err(SafetyError::DimensionMismatch {
            what: "metric",
            found: metric.n,
            n,
        });
    }
    if metric.R.len() != n * n {
        return Err(SafetyError::MetricShape {
            found: metric.R.len(),
            expected: n * n,
        });
    }
    if let Some(pos) = metric.R.iter().position(|v| !v.is_finite()) {
        return Err(SafetyError::MetricNonFinite {
            row: pos / n,
            col: pos % n,
        });
    }
    Ok(())
}

fn check_set(n: usize, set: &SafetySet, what: &'static str) -> Result<(), SafetyError> {
    if set.dim() != n {
        return Err(SafetyError::DimensionMismatch {
            what,
            found: set.dim(),
            n,
        });
    }
    Ok(())
}

fn check_input(n: usize, input: &dyn InputSets, needed: usize) -> Result<(), SafetyError> {
    if let Some(d) = input.dim() {
        if d != n {
            return Err(SafetyError::DimensionMismatch {
                what: "input set",
                found: d,
                n,
            });
        }
    }
    if let Some(available) = input.samples() {
        if available < needed {
            return Err(SafetyError::InputTooShort { needed, available });
        }
    }
    Ok(())
}

/// Validate the spec against the trajectory and return the number of samples with t ≤ T.
fn check(traj: &SampledTrajectory, spec: &SafetySpec) -> Result<usize, SafetyError> {
    let n = traj.n();
    check_set(n, &spec.goal, GOAL)?;
    check_set(n, &spec.unsafe_set, UNSAFE)?;
    check_metric(n, spec.metric)?;
    if spec.T.is_nan() {
        return Err(SafetyError::HorizonNaN { T: spec.T });
    }
    let count = traj.times().partition_point(|&t| t <= spec.T);
    if count == 0 {
        return Err(SafetyError::HorizonBeforeStart {
            T: spec.T,
            t0: traj.times()[0],
        });
    }
    if let Some(input) = spec.input {
        check_input(n, input, count)?;
    }
    Ok(count)
}

fn not_nan(v: f64, what: &'static str, index: usize) -> Result<f64, SafetyError> {
    if v.is_nan() {
        Err(SafetyError::NaNDistance { what, index })
    } else {
        Ok(v)
    }
}

const GOAL: &str = "Goal";
const UNSAFE: &str = "Unsafe";
const INPUT: &str = "the admissible-input set";

/// One set's signed distances along one trajectory: the set prepared for the metric once, then queried
/// per sample (value only, cheap bounds, or with the witness at a critical sample).
struct SetScan<'a, 't> {
    traj: &'t SampledTrajectory<'t>,
    metric: &'a Metric,
    set: Prepared<'a>,
    what: &'static str,
}

impl<'a, 't> SetScan<'a, 't> {
    fn new(
        traj: &'t SampledTrajectory<'t>,
        set: SafetySet<'a>,
        metric: &'a Metric,
        what: &'static str,
    ) -> Result<Self, SafetyError> {
        Ok(Self {
            traj,
            metric,
            set: Prepared::new(set, metric, what)?,
            what,
        })
    }
    /// Dist(x̃(κ), S).
    #[inline]
    fn dist(&mut self, k: usize) -> Result<f64, SafetyError> {
        not_nan(
            self.set.value(self.traj.state(k), self.metric),
            self.what,
            k,
        )
    }
    /// Bounds on Dist(x̃(κ), S), when the set has them.
    #[inline]
    fn bounds(&self, k: usize) -> Option<(f64, f64)> {
        self.set.bounds(self.traj.state(k))
    }
    /// The part's value at κ with the witness of Dist(x̃(κ), S).
    fn critical(&self, value: f64, k: usize) -> Critical {
        critical(
            self.traj,
            value,
            k,
            self.set.witness(self.traj.state(k), self.metric),
        )
    }

    /// Dist(x̃(j)) + ‖x̃(κ) − x̃(j)‖_R (widened for rounding) ≥ Dist(x̃(κ)) for the anchor (j, Dist(x̃(j))).
    #[inline]
    fn lipschitz_bound(&self, (j, vj): (usize, f64), k: usize) -> f64 {
        let d = self.metric.distance(self.traj.state(k), self.traj.state(j));
        vj + d * (1.0 + 1e-9) + 1e-9 * (1.0 + vj.abs())
    }

    /// First index of the maximum of Dist(x̃(κ), S) over κ ∈ 0..end (end ≥ 1), and the maximum. When
    /// the set has bounds (lo, hi) bracketing the value, a first pass takes the sample with the largest
    /// lo as the incumbent, and the scan then solves only samples whose hi reaches the incumbent's value;
    /// every skipped sample is provably below the maximum, so the result equals the full scan's.
    fn first_argmax(&mut self, end: usize) -> Result<(usize, f64), SafetyError> {
        if end <= 1 || self.bounds(0).is_none() {
            let mut best = (0, self.dist(0)?);
            for k in 1..end {
                let v = self.dist(k)?;
                if v > best.1 {
                    best = (k, v);
                }
            }
            return Ok(best);
        }
        // Pass 1: bounds of every sample; the incumbent is the first sample with the largest lo.
        let mut hi = Vec::with_capacity(end);
        let (mut k0, mut lo0) = (0, f64::NEG_INFINITY);
        for k in 0..end {
            let (lo, h) = self.bounds(k).unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
            if lo > lo0 {
                lo0 = lo;
                k0 = k;
            }
            hi.push(h);
        }
        let v0 = self.dist(k0)?;
        // Pass 2: solve only where the value may reach the threshold max(v0, best so far). Besides the
        // set's bound, the signed distance is 1-Lipschitz in ‖·‖_R (the segment between a point inside
        // and one outside crosses the boundary), so the last solved sample j gives
        // Dist(x̃(κ)) ≤ Dist(x̃(j)) + ‖x̃(κ) − x̃(j)‖_R.
        let mut best: Option<(usize, f64)> = None;
        let mut anchor = (k0, v0);
        for (k, &h) in hi.iter().enumerate() {
            let threshold = best.map_or(v0, |(_, b)| b.max(v0));
            let v = if k == k0 {
                v0
            } else if h < threshold || self.lipschitz_bound(anchor, k) < threshold {
                continue;
            } else {
                let v = self.dist(k)?;
                anchor = (k, v);
                v
            };
            if best.is_none_or(|(_, b)| v > b) {
                best = Some((k, v));
            }
        }
        Ok(best.unwrap_or((k0, v0)))
    }
}

fn critical(traj: &SampledTrajectory, value: f64, index: usize, w: Witness) -> Critical {
    Critical {
        value,
        index,
        time: traj.times()[index],
        point: w.point,
    }
}

/// First index of the minimum over 0..end (end ≥ 1), and the minimum.
fn prefix_min(
    end: usize,
    mut f: impl FnMut(usize) -> Result<f64, SafetyError>,
) -> Result<(usize, f64), SafetyError> {
    let mut best = (0, f(0)?);
    for k in 1..end {
        let v = f(k)?;
        if v < best.1 {
            best = (k, v);
        }
    }
    Ok(best)
}

/// Dist(x̃(κ), A_κ) through an [`InputSets`].
#[inline]
fn input_value(
    traj: &SampledTrajectory,
    inp: &dyn InputSets,
    metric: &Metric,
    k: usize,
) -> Result<f64, SafetyError> {
    not_nan(inp.signed_value(k, traj.state(k), metric), INPUT, k)
}

fn input_critical(
    traj: &SampledTrajectory,
    inp: &dyn InputSets,
    metric: &Metric,
    value: f64,
    k: usize,
) -> Critical {
    critical(traj, value, k, inp.signed_dist(k, traj.state(k), metric))
}

/// The Goal part (4.12)–(4.13) over the samples 0..end: the first maximiser κ* of Dist(x̃(κ), Goal) and
/// its value, with the witness. One of the three scans of Theorem 4.7 that every caller shares:
/// [`safety_robustness`] and the certifier of the sampled f32 loop (`crate::certify`).
pub fn goal_part(
    traj: &SampledTrajectory,
    goal: SafetySet,
    metric: &Metric,
    end: usize,
) -> Result<Critical, SafetyError> {
    check_set(traj.n(), &goal, GOAL)?;
    check_metric(traj.n(), metric)?;
    let end = end.clamp(1, traj.len());
    let mut s = SetScan::new(traj, goal, metric, GOAL)?;
    let (k, v) = s.first_argmax(end)?;
    Ok(s.critical(v, k))
}

/// The Goal part at one given sample κ (a forced switch happens there, §4.2.1): Dist(x̃(κ), Goal) with
/// the witness.
pub fn goal_at(
    traj: &SampledTrajectory,
    goal: SafetySet,
    metric: &Metric,
    k: usize,
) -> Result<Critical, SafetyError> {
    check_set(traj.n(), &goal, GOAL)?;
    check_metric(traj.n(), metric)?;
    let k = k.min(traj.len() - 1);
    let mut s = SetScan::new(traj, goal, metric, GOAL)?;
    let v = s.dist(k)?;
    Ok(s.critical(v, k))
}

/// The Unsafe part (4.14) over the samples 0..end: the minimum of −Dist(x̃(κ), Unsafe) (the distance
/// outside Unsafe, minus the depth inside), first minimiser, with the witness; +∞ at κ = 0 when there is
/// no Unsafe set.
///
/// `margin`, when given, is a per-sample reduction (κ, d, d_min) ↦ d′ applied to that distance, d_min the
/// smallest distance over the samples (certification adds the inter-sample excursion and the rounding of
/// the input there; the rounding is bounded over a tube whose radius d_min bounds); the result then also
/// carries min over κ of d′ (the first minimiser and its value). Without it, ellipsoidal sets are scanned with
/// the pruning of [`goal_part`]; with it every sample is evaluated.
pub fn unsafe_part(
    traj: &SampledTrajectory,
    unsafe_set: Option<SafetySet>,
    metric: &Metric,
    end: usize,
    margin: Option<&dyn Fn(usize, f64, f64) -> f64>,
) -> Result<UnsafePart, SafetyError> {
    check_metric(traj.n(), metric)?;
    let end = end.clamp(1, traj.len());
    let Some(set) = unsafe_set else {
        let none = Critical {
            value: f64::INFINITY,
            index: 0,
            time: traj.times()[0],
            point: Vec::new(),
        };
        return Ok(UnsafePart {
            margined: margin.map(|_| none.clone()),
            at_samples: none,
        });
    };
    check_set(traj.n(), &set, UNSAFE)?;
    let mut s = SetScan::new(traj, set, metric, UNSAFE)?;
    let Some(margin) = margin else {
        // The minimum of −Dist is the first maximiser of Dist.
        let (k, d) = s.first_argmax(end)?;
        return Ok(UnsafePart {
            at_samples: s.critical(-d, k),
            margined: None,
        });
    };
    let dist: Vec<f64> = (0..end)
        .map(|k| s.dist(k).map(|d| -d))
        .collect::<Result<_, _>>()?;
    let (k, d) = prefix_min(end, |k| Ok(dist[k]))?;
    let (km, dm) = prefix_min(end, |k| not_nan(margin(k, dist[k], d), UNSAFE, k))?;
    Ok(UnsafePart {
        at_samples: s.critical(d, k),
        margined: Some(s.critical(dm, km)),
    })
}

/// The Unsafe part at the samples and, when a margin was given, after it.
#[derive(Clone, Debug, PartialEq)]
pub struct UnsafePart {
    pub at_samples: Critical,
    pub margined: Option<Critical>,
}

/// The Input part (4.15) over the samples 0..end: the minimum of Dist(x̃(κ), A_κ), first minimiser, with
/// the input sets' witness; `None` when end = 0 (no sample carries an input).
pub fn input_part(
    traj: &SampledTrajectory,
    input: &dyn InputSets,
    metric: &Metric,
    end: usize,
) -> Result<Option<Critical>, SafetyError> {
    check_metric(traj.n(), metric)?;
    let end = end.min(traj.len());
    check_input(traj.n(), input, end)?;
    if end == 0 {
        return Ok(None);
    }
    let (k, v) = prefix_min(end, |k| input_value(traj, input, metric, k))?;
    Ok(Some(input_critical(traj, input, metric, v, k)))
}

fn assemble(
    goal: Critical,
    unsafe_set: Critical,
    input: Option<Critical>,
    horizon_samples: usize,
) -> SafetyRobustness {
    let mut delta = goal.value;
    let mut binding = Binding::Goal;
    if unsafe_set.value < delta {
        delta = unsafe_set.value;
        binding = Binding::Unsafe;
    }
    if let Some(i) = &input {
        if i.value < delta {
            delta = i.value;
            binding = Binding::Input;
        }
    }
    SafetyRobustness {
        delta,
        binding,
        goal,
        unsafe_set,
        input,
        horizon_samples,
    }
}

/// Theorem 4.7: δ₀ with t* = argmax of the Goal depth over samples with t_κ ≤ T, (4.11)–(4.15).
///
/// Runs in O(N) signed-distance evaluations: one pass for Goal up to T, one for Unsafe and Input up to
/// κ*, plus one witness query per part ([`goal_part`], [`unsafe_part`], [`input_part`]). See the module
/// doc for the signed convention and the tie rule.
pub fn safety_robustness(
    traj: &SampledTrajectory,
    spec: &SafetySpec,
) -> Result<SafetyRobustness, SafetyError> {
    let count = check(traj, spec)?;
    // (4.12)–(4.13): first maximiser of the signed Goal distance.
    let goal = goal_part(traj, spec.goal, spec.metric, count)?;
    // (4.14)–(4.15): over the closed prefix 0..=κ*.
    let end = goal.index + 1;
    let unsafe_set = unsafe_part(traj, Some(spec.unsafe_set), spec.metric, end, None)?.at_samples;
    let input = match spec.input {
        Some(inp) => input_part(traj, inp, spec.metric, end)?,
        None => None,
    };
    Ok(assemble(goal, unsafe_set, input, count))
}

/// Variant of Theorem 4.7 that picks t* to maximise min(Dist(x̃(t*), Goal), the Unsafe and Input minima
/// over 0..=κ*) rather than the Goal depth alone: the robustness of the until embedding of Remark 2.29
/// (with the prefix closed at t*). Never smaller than [`safety_robustness`], equally sound (module doc).
///
/// One pass, O(N); it stops early once the prefix minimum cannot be beaten any more.
pub fn safety_robustness_joint(
    traj: &SampledTrajectory,
    spec: &SafetySpec,
) -> Result<SafetyRobustness, SafetyError> {
    let count = check(traj, spec)?;
    let mut g = SetScan::new(traj, spec.goal, spec.metric, GOAL)?;
    let mut u = SetScan::new(traj, spec.unsafe_set, spec.metric, UNSAFE)?;
    let (mut mu, mut ku) = (f64::INFINITY, 0); // running min of the Unsafe part
    let (mut mi, mut ki) = (f64::INFINITY, 0); // running min of the Input part
    let mut best = (f64::NEG_INFINITY, 0, 0, 0, f64::NEG_INFINITY); // (score, κ*, κ_U, κ_I, Goal value)
    let mut best_parts = (f64::INFINITY, f64::INFINITY);
    for k in 0..count {
        // −Dist(·, Unsafe) ≥ −hi: skip the solve when it cannot lower the running minimum.
        let skip_u = k > 0 && u.bounds(k).is_some_and(|b| -b.1 >= mu);
        if !skip_u {
            let v = -u.dist(k)?;
            if v < mu || k == 0 {
                mu = v;
                ku = k;
            }
        }
        if let Some(inp) = spec.input {
            let v = input_value(traj, inp, spec.metric, k)?;
            if v < mi || k == 0 {
                mi = v;
                ki = k;
            }
        }
        let prefix = mu.min(mi);
        if k > 0 && prefix <= best.0 {
            // The prefix minimum never increases, so no later sample can beat `best`.
            break;
        }
        if k > 0 && g.bounds(k).is_some_and(|b| b.1.min(prefix) <= best.0) {
            continue; // the score min(Goal, prefix) cannot exceed `best`
        }
        let gv = g.dist(k)?;
        let score = gv.min(prefix);
        if score > best.0 || k == 0 {
            best = (score, k, ku, ki, gv);
            best_parts = (mu, mi);
        }
    }
    let (_, kstar, ku, ki, gv) = best;
    let goal = g.critical(gv, kstar);
    let unsafe_set = u.critical(best_parts.0, ku);
    let input = spec
        .input
        .map(|inp| input_critical(traj, inp, spec.metric, best_parts.1, ki));
    Ok(assemble(goal, unsafe_set, input, count))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A random symmetric PSD n×n matrix B Bᵀ + shift·I with B n×rank.
    fn psd(rng: &mut ChaCha8Rng, n: usize, rank: usize, shift: f64) -> Vec<f64> {
        let B: Vec<f64> = (0..n * rank).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut A = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                A[i * n + j] = (0..rank)
                    .map(|k| B[i * rank + k] * B[j * rank + k])
                    .sum::<f64>()
                    + if i == j { shift } else { 0.0 };
            }
        }
        A
    }

    /// lo ≤ Dist_R(x, E) ≤ hi against the exact §7.2 solver, for full and degenerate ellipsoids and
    /// for positive definite and singular metrics, with points inside, outside and near the boundary.
    #[test]
    fn ellipsoid_bounds_bracket_the_exact_signed_distance() {
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        let (mut checked, mut informative) = (0, 0);
        for case in 0..300 {
            let n = rng.random_range(1..=4);
            let q_rank = if case % 3 == 0 {
                rng.random_range(1..=n)
            } else {
                n
            };
            let Q = psd(&mut rng, n, q_rank, if q_rank < n { 0.0 } else { 0.2 });
            let R = if case % 5 == 0 && n > 1 {
                psd(&mut rng, n, n - 1, 0.0)
            } else {
                psd(&mut rng, n, n, 0.1)
            };
            let c: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let Ok(e) = Ellipsoid::new(c.clone(), Q.clone()) else {
                continue;
            };
            let metric = Metric { n, R: R.clone() };
            let b = EllipsoidBounds::new(&c, e.shape(), &metric);
            for _ in 0..20 {
                let scale = [0.05, 0.5, 1.0, 3.0][rng.random_range(0..4)];
                let x: Vec<f64> = c
                    .iter()
                    .map(|ci| ci + scale * rng.random_range(-1.0..1.0))
                    .collect();
                let exact = e.signed_dist(&x, &metric).value;
                if exact.is_nan() {
                    continue;
                }
                let (lo, hi) = b.signed(&x);
                assert!(
                    lo <= exact && exact <= hi,
                    "case {case}: {lo} ≤ {exact} ≤ {hi} fails"
                );
                checked += 1;
                if hi - lo < 0.5 * exact.abs() {
                    informative += 1;
                }
            }
        }
        assert!(checked > 3000, "{checked}");
        assert!(
            informative > checked / 10,
            "bounds are too loose to prune anything ({informative}/{checked})"
        );
    }

    #[test]
    fn cholesky_rejects_singular_and_solves() {
        assert!(cholesky(&[1.0, 1.0, 1.0, 1.0], 2).is_none());
        let L = cholesky(&[4.0, 2.0, 2.0, 5.0], 2).unwrap();
        assert_eq!(L, vec![2.0, 0.0, 1.0, 2.0]);
        // L⁻¹ L = I.
        let X = lower_solve_columns(&L, &L, 2);
        assert_eq!(X, vec![1.0, 0.0, 0.0, 1.0]);
    }
}
