//! Polyhedra {x : Ax ≤ b} as [`Region`]s (§7.1).
//!
//! - **Distance** from an outside point: the quadratic program (7.1) in the metric R, written in the step
//!   d = x' − x as min ½dᵀRd s.t. A d ≤ b − Ax, solved with clarabel (tight tolerances) and then polished by
//!   solving the equality-constrained QP on the active set the interior-point solution identifies; the polished
//!   point is kept only when it is feasible and no worse. R may be singular (a seminorm).
//! - **Depth** of an inside point: ℝⁿ \ S is the union of the open half-spaces {aᵢᵀy > bᵢ}, so
//!   depth_R(x, S) = minᵢ dist_R(x, {aᵢᵀy ≥ bᵢ}), and the distance to a half-space that x does not violate is
//!   the distance to its hyperplane. Derivation, with sᵢ = bᵢ − aᵢᵀx ≥ 0: minimise dᵀRd subject to aᵢᵀd = sᵢ.
//!   * If aᵢ has a component a_N in the null space of R, the step d = sᵢ a_N/(aᵢᵀa_N) satisfies the constraint at
//!     zero cost: the distance is 0 (the hyperplane is reachable for free, as in §7.2.2).
//!   * Otherwise aᵢ ∈ range(R); by Cauchy–Schwarz in the R-inner product, sᵢ = aᵢᵀd = (R⁺aᵢ)ᵀR d ≤
//!     ‖R⁺aᵢ‖_R ‖d‖_R = sqrt(aᵢᵀR⁺aᵢ) ‖d‖_R, with equality at d = sᵢ R⁺aᵢ/(aᵢᵀR⁺aᵢ). So the distance is
//!     sᵢ / sqrt(aᵢᵀR⁺aᵢ); for R positive definite this is the familiar (bᵢ − aᵢᵀx)/sqrt(aᵢᵀR⁻¹aᵢ).
//!
//!   A component counts as "in the null space" when ‖a_N‖ > 1e-12‖aᵢ‖, the null space being the eigenvectors of
//!   R with eigenvalue ≤ 1e-13·λmax(R). The witness is the first boundary crossing on the segment from x to the
//!   minimising step (which is the step's end point whenever the depth is positive).
//! - **Distance from a small polytope, exactly** (k ≤ [`ENUMERATE_ROWS`] rows, every row in the range of R):
//!   the QP (7.1)'s Lagrangian ½dᵀRd + λᵀ(Ad − rhs) is stationary at d = −R⁺Aᵀλ, and its dual is
//!   max over λ ≥ 0 of −½λᵀHλ − λᵀrhs with H = AR⁺Aᵀ. For an active set J, λ_J solves H_JJ λ_J = −rhs_J
//!   (λ zero off J) and d = −(R⁺Aᵀ)_J λ_J. Any λ ≥ 0 makes the dual value a lower bound on ½‖d*‖²_R, and
//!   at this λ the dual value is ½λ_JᵀH_JJλ_J = ½‖d‖²_R; a d that is also feasible is then the optimum.
//!   So the sets J are tried by size (then in lexicographic order), and the first whose λ_J ≥ 0 and whose
//!   d satisfies every row (to 10⁻¹² of the right-hand side's scale, the polish's tolerance) is the
//!   answer: the QP's minimiser (the unique one when R is definite), with no interior-point solve. A polytope of a task (a box over two
//!   or three coordinates in a CAF's induced metric) has at most 2·3 rows and sets of at most 3; when no
//!   set qualifies (degenerate rounding) the QP answers as before.

use super::cache::{Cached, MetricCache};
use super::linalg::{self, SymEig};
use super::{check_query, GeometryError, Metric, Region, Witness};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
// clarabel's dense kernels call Fortran BLAS/LAPACK symbols; lapack-faer provides them at link time.
extern crate lapack_faer as _;

/// A row's normal counts as having a null-space component of R when ‖a_N‖ > FREE_TOL · ‖a‖.
const FREE_TOL: f64 = 1e-12;

/// Polytopes of at most this many rows are projected onto by enumerating active sets (module doc), at
/// most 2⁸ − 1 sets of at most 8 rows; larger ones by the QP.
const ENUMERATE_ROWS: usize = 8;

/// {x ∈ ℝⁿ : Ax ≤ b}, A row-major k×n. Nonempty, with at least one nonzero row (validated).
pub struct Polytope {
    n: usize,
    k: usize,
    A: Vec<f64>,
    b: Vec<f64>,
    cache: MetricCache<FacetSteps>,
}

impl Clone for Polytope {
    fn clone(&self) -> Self {
        Self {
            n: self.n,
            k: self.k,
            A: self.A.clone(),
            b: self.b.clone(),
            cache: MetricCache::default(),
        }
    }
}

impl std::fmt::Debug for Polytope {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Polytope")
            .field("n", &self.n)
            .field("A", &self.A)
            .field("b", &self.b)
            .finish()
    }
}

/// Per-metric data for the depth: for each row, how to reach its hyperplane.
#[derive(Debug)]
pub(super) struct FacetSteps {
    rows: Vec<FacetStep>,
    /// The symmetrised metric matrix (for the QP).
    R: Vec<f64>,
    /// For the active-set projection (module doc), when k ≤ [`ENUMERATE_ROWS`] and every row is in the
    /// range of R.
    dual: Option<DualData>,
}

/// R⁺Aᵀ (n×k, row-major) and H = AR⁺Aᵀ (k×k), the data of the QP (7.1)'s dual.
#[derive(Debug)]
struct DualData {
    W: Vec<f64>,
    H: Vec<f64>,
}

#[derive(Debug)]
enum FacetStep {
    /// a = 0: never violated.
    Never,
    /// Reachable at zero cost: step per unit slack, a_N/(aᵀa_N).
    Free(Vec<f64>),
    /// Step per unit slack R⁺a/(aᵀR⁺a); distance = slack / dual, dual = sqrt(aᵀR⁺a).
    Norm { dual: f64, step: Vec<f64> },
}

impl Polytope {
    /// {x ∈ ℝⁿ : Ax ≤ b} with A row-major k×n (k ≥ 1) and b of length k, all finite. Errors when a length is
    /// wrong, an entry is not finite, every row of A is zero, or the set is empty (checked with an LP).
    pub fn new(n: usize, A: Vec<f64>, b: Vec<f64>) -> Result<Self, GeometryError> {
        if n == 0 {
            return Err(GeometryError::ZeroDimension { what: "polytope" });
        }
        let k = b.len();
        if k == 0 {
            return Err(GeometryError::NoConstraints);
        }
        linalg::check_vector("polytope A", &A, k * n)?;
        linalg::check_finite("polytope b", &b)?;
        let mut any = false;
        for i in 0..k {
            if A[i * n..(i + 1) * n].iter().all(|a| *a == 0.0) {
                if b[i] < 0.0 {
                    return Err(GeometryError::EmptyPolytope);
                }
            } else {
                any = true;
            }
        }
        if !any {
            return Err(GeometryError::NoConstraints);
        }
        let p = Self {
            n,
            k,
            A,
            b,
            cache: MetricCache::default(),
        };
        p.check_nonempty()?;
        Ok(p)
    }

    /// Ambient dimension n.
    pub fn n(&self) -> usize {
        self.n
    }
    /// Number of rows k.
    pub fn rows(&self) -> usize {
        self.k
    }
    /// A, row-major k×n.
    pub fn A(&self) -> &[f64] {
        &self.A
    }
    /// b.
    pub fn b(&self) -> &[f64] {
        &self.b
    }
    /// The largest violation maxᵢ (aᵢᵀx − bᵢ) (≤ 0 inside). No length check beyond a debug assertion.
    pub fn max_violation(&self, x: &[f64]) -> f64 {
        (0..self.k)
            .map(|i| linalg::dot(&self.A[i * self.n..(i + 1) * self.n], x) - self.b[i])
            .fold(f64::NEG_INFINITY, f64::max)
    }

    fn check_nonempty(&self) -> Result<(), GeometryError> {
        let n = self.n;
        let P = CscMatrix::new(n, n, vec![0; n + 1], vec![], vec![]);
        let Ac = csc_from_dense(self.k, n, |i, j| self.A[i * n + j], false);
        let q = vec![0.0; n];
        let settings = qp_settings();
        let mut solver = DefaultSolver::new(
            &P,
            &q,
            &Ac,
            &self.b,
            &[SupportedConeT::NonnegativeConeT(self.k)],
            settings,
        )
        .map_err(|e| GeometryError::Solver {
            what: "polytope feasibility LP",
            status: e.to_string(),
        })?;
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(()),
            SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
                Err(GeometryError::EmptyPolytope)
            }
            s => Err(GeometryError::Solver {
                what: "polytope feasibility LP",
                status: s.to_string(),
            }),
        }
    }

    pub(super) fn steps(&self, metric: &Metric) -> Result<Cached<'_, FacetSteps>, GeometryError> {
        self.cache.get_or_try_insert(metric, || {
            let (R, er) = metric.validated()?;
            let Rp = er.pinv();
            let (N, nk) = er.null_basis();
            let n = self.n;
            let mut rows = Vec::with_capacity(self.k);
            for i in 0..self.k {
                let a = &self.A[i * n..(i + 1) * n];
                let na = a.iter().map(|v| v * v).sum::<f64>().sqrt();
                if na == 0.0 {
                    rows.push(FacetStep::Never);
                    continue;
                }
                // a_N = N Nᵀ a
                let mut aN = vec![0.0; n];
                for c in 0..nk {
                    let coef: f64 = (0..n).map(|j| N[j * nk + c] * a[j]).sum();
                    for j in 0..n {
                        aN[j] += coef * N[j * nk + c];
                    }
                }
                let nN = aN.iter().map(|v| v * v).sum::<f64>().sqrt();
                if nN > FREE_TOL * na {
                    let s = linalg::dot(a, &aN);
                    rows.push(FacetStep::Free(aN.iter().map(|v| v / s).collect()));
                    continue;
                }
                let mut g = vec![0.0; n];
                linalg::matvec(&Rp, n, n, a, &mut g);
                let aRa = linalg::dot(a, &g);
                if aRa > 0.0 && aRa.is_finite() {
                    rows.push(FacetStep::Norm {
                        dual: aRa.sqrt(),
                        step: g.iter().map(|v| v / aRa).collect(),
                    });
                } else {
                    // R⁺a vanished numerically: a is (numerically) in the null space after all.
                    let s = linalg::dot(a, a);
                    rows.push(FacetStep::Free(a.iter().map(|v| v / s).collect()));
                }
            }
            let dual = self.dual_data(&rows);
            Ok(FacetSteps { rows, R, dual })
        })
    }

    /// R⁺Aᵀ and AR⁺Aᵀ from the rows' steps (R⁺aᵢ = stepᵢ · dualᵢ²), or `None` when the polytope has too
    /// many rows or a row is not in the range of R.
    fn dual_data(&self, rows: &[FacetStep]) -> Option<DualData> {
        let (n, k) = (self.n, self.k);
        if k > ENUMERATE_ROWS {
            return None;
        }
        let mut W = vec![0.0; n * k];
        for (i, row) in rows.iter().enumerate() {
            let FacetStep::Norm { dual, step } = row else {
                return None;
            };
            let aRa = dual * dual;
            for j in 0..n {
                W[j * k + i] = step[j] * aRa;
            }
        }
        let mut H = vec![0.0; k * k];
        for i in 0..k {
            let a = &self.A[i * n..(i + 1) * n];
            for c in 0..k {
                H[i * k + c] = (0..n).map(|j| a[j] * W[j * k + c]).sum();
            }
        }
        Some(DualData { W, H })
    }

    /// The rows' slacks b − Ax (each row's right-hand side for a step from x).
    fn slacks(&self, x: &[f64]) -> Vec<f64> {
        let n = self.n;
        (0..self.k)
            .map(|i| self.b[i] - linalg::dot(&self.A[i * n..(i + 1) * n], x))
            .collect()
    }

    /// The QP (7.1)'s minimiser by its active set (module doc), `None` when the data is missing or no set
    /// of rows qualifies (the QP answers then).
    fn project_active_set(&self, x: &[f64], steps: &FacetSteps) -> Option<Witness> {
        let dual = steps.dual.as_ref()?;
        let (n, k) = (self.n, self.k);
        let rhs = self.slacks(x);
        let tol = 1e-12 * (1.0 + linalg::max_abs(&rhs));
        let mut d = vec![0.0; n];
        for size in 1..=k.min(n) {
            for set in (0u32..1 << k).filter(|s| s.count_ones() as usize == size) {
                let J: Vec<usize> = (0..k).filter(|&i| set & (1 << i) != 0).collect();
                let Some(lambda) = solve_spd(&J, dual, &rhs) else {
                    continue;
                };
                if lambda.iter().any(|l| !(*l >= 0.0)) {
                    continue;
                }
                for (j, dj) in d.iter_mut().enumerate() {
                    *dj = -J
                        .iter()
                        .zip(&lambda)
                        .map(|(&i, l)| dual.W[j * k + i] * l)
                        .sum::<f64>();
                }
                let feasible =
                    (0..k).all(|i| linalg::dot(&self.A[i * n..(i + 1) * n], &d) <= rhs[i] + tol);
                if feasible {
                    let value = linalg::quad_form(&steps.R, &d).max(0.0).sqrt();
                    let point = x.iter().zip(&d).map(|(a, b)| a + b).collect();
                    return Some(Witness { value, point });
                }
            }
        }
        None
    }

    /// The QP (7.1) from an outside point: the nearest point of S in ‖·‖_R and its distance.
    fn project(&self, x: &[f64], R: &[f64]) -> Result<Witness, GeometryError> {
        let (n, k) = (self.n, self.k);
        // Constraint A d ≤ rhs = b − A x.
        let rhs = self.slacks(x);
        let P = csc_from_dense(n, n, |i, j| R[i * n + j], true);
        let Ac = csc_from_dense(k, n, |i, j| self.A[i * n + j], false);
        let q = vec![0.0; n];
        let mut solver = DefaultSolver::new(
            &P,
            &q,
            &Ac,
            &rhs,
            &[SupportedConeT::NonnegativeConeT(k)],
            qp_settings(),
        )
        .map_err(|e| GeometryError::Solver {
            what: "polytope distance QP (7.1)",
            status: e.to_string(),
        })?;
        solver.solve();
        let sol = &solver.solution;
        match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {}
            s => {
                return Err(GeometryError::Solver {
                    what: "polytope distance QP (7.1)",
                    status: s.to_string(),
                })
            }
        }
        let d_ipm = sol.x.clone();
        let obj_ipm = linalg::quad_form(R, &d_ipm);
        let viol = |d: &[f64]| -> f64 {
            (0..k)
                .map(|i| linalg::dot(&self.A[i * n..(i + 1) * n], d) - rhs[i])
                .fold(f64::NEG_INFINITY, f64::max)
        };
        let scale = 1.0 + linalg::max_abs(&rhs);
        let mut d = d_ipm.clone();
        // Polish on the active set {i : zᵢ > sᵢ} (complementarity picks the larger of dual and slack).
        let active: Vec<usize> = (0..k).filter(|&i| sol.z[i] > sol.s[i]).collect();
        if let Some(dp) = polish(n, R, &self.A, &rhs, &active) {
            let obj_p = linalg::quad_form(R, &dp);
            if viol(&dp) <= 1e-12 * scale && obj_p <= obj_ipm + 1e-12 * (1.0 + obj_ipm) {
                d = dp;
            }
        }
        let value = linalg::quad_form(R, &d).max(0.0).sqrt();
        let point: Vec<f64> = x.iter().zip(&d).map(|(a, b)| a + b).collect();
        Ok(Witness { value, point })
    }

    /// The distance from an outside point to a half-space {aᵀy ≤ b} (one row), in closed form: with
    /// v = aᵀx − b > 0 the violation, minimise ‖d‖_R subject to aᵀd ≤ −v, the depth's derivation (module
    /// doc) mirrored: 0 through a null-space component of R, else v / sqrt(aᵀR⁺a) at d = −v R⁺a/(aᵀR⁺a).
    /// The QP (7.1) has this solution; solving it per point is what an operating region's half-spaces
    /// (`model::feedback_linearizable`) cannot afford at every sample of every candidate.
    fn dist_half_space(&self, x: &[f64], steps: &FacetSteps) -> Witness {
        let v = linalg::dot(&self.A[..self.n], x) - self.b[0];
        let (value, step) = match &steps.rows[0] {
            FacetStep::Free(g) => (0.0, g),
            FacetStep::Norm { dual, step } => (v / dual, step),
            // Unreachable: construction guarantees a nonzero row.
            FacetStep::Never => {
                return Witness {
                    value: f64::INFINITY,
                    point: Vec::new(),
                }
            }
        };
        let point = x.iter().zip(step).map(|(a, g)| a - v * g).collect();
        Witness { value, point }
    }

    /// The distance from an outside point to an axis-aligned box (every nonzero row of A has one nonzero
    /// entry) in a diagonal metric, in closed form: the QP (7.1) separates by coordinate, and each
    /// coordinate's nearest value is x's clamped to the box's interval on that axis. `None` when the set
    /// is not such a box or R is not diagonal (the QP answers then). The goal and obstacle boxes of a task
    /// meet this at every sample of a verifier's margin runs, where the QP was most of the run's cost.
    fn dist_box(&self, x: &[f64], R: &[f64]) -> Option<Witness> {
        let n = self.n;
        let diagonal = (0..n).all(|i| (0..n).all(|j| i == j || R[i * n + j] == 0.0));
        if !diagonal {
            return None;
        }
        let mut lo = vec![f64::NEG_INFINITY; n];
        let mut hi = vec![f64::INFINITY; n];
        for (row, &b) in self.A.chunks_exact(n).zip(&self.b) {
            let mut nonzero = row.iter().enumerate().filter(|(_, a)| **a != 0.0);
            let Some((j, &a)) = nonzero.next() else {
                continue;
            };
            if nonzero.next().is_some() {
                return None;
            }
            let bound = b / a;
            if a > 0.0 {
                hi[j] = hi[j].min(bound);
            } else {
                lo[j] = lo[j].max(bound);
            }
        }
        if lo.iter().zip(&hi).any(|(l, h)| l > h) {
            return None;
        }
        let point: Vec<f64> = (0..n).map(|j| x[j].clamp(lo[j], hi[j])).collect();
        let value = (0..n)
            .map(|j| R[j * n + j] * (point[j] - x[j]).powi(2))
            .sum::<f64>()
            .max(0.0)
            .sqrt();
        Some(Witness { value, point })
    }

    /// The distance of a point outside (module doc): a half-space's closed form, a box's in a diagonal
    /// metric, the active-set enumeration, else the QP.
    pub(super) fn dist_outside(
        &self,
        x: &[f64],
        steps: &FacetSteps,
    ) -> Result<Witness, GeometryError> {
        if self.k == 1 {
            return Ok(self.dist_half_space(x, steps));
        }
        if let Some(w) = self.dist_box(x, &steps.R) {
            return Ok(w);
        }
        if let Some(w) = self.project_active_set(x, steps) {
            return Ok(w);
        }
        self.project(x, &steps.R)
    }

    pub(super) fn depth_inside(&self, x: &[f64], steps: &FacetSteps) -> Witness {
        let n = self.n;
        let slack = self.slacks(x);
        let mut best: Option<(f64, usize)> = None;
        for (i, st) in steps.rows.iter().enumerate() {
            let s = slack[i].max(0.0);
            let v = match st {
                FacetStep::Never => continue,
                FacetStep::Free(_) => 0.0,
                FacetStep::Norm { dual, .. } => s / dual,
            };
            if best.is_none_or(|(bv, _)| v < bv) {
                best = Some((v, i));
            }
        }
        let Some((value, i)) = best else {
            // Unreachable: construction guarantees a nonzero row.
            return Witness {
                value: f64::INFINITY,
                point: Vec::new(),
            };
        };
        let s = slack[i].max(0.0);
        let step: Vec<f64> = match &steps.rows[i] {
            FacetStep::Free(g) | FacetStep::Norm { step: g, .. } => {
                g.iter().map(|v| v * s).collect()
            }
            FacetStep::Never => vec![0.0; n],
        };
        // First crossing of the boundary on the segment x → x + step.
        let mut t = 1.0_f64;
        for (row, &s) in self.A.chunks_exact(n).zip(&slack) {
            let ad = linalg::dot(row, &step);
            if ad > 0.0 {
                t = t.min(s.max(0.0) / ad);
            }
        }
        let point = x.iter().zip(&step).map(|(a, d)| a + t * d).collect();
        Witness { value, point }
    }
}

/// Tight interior-point settings for the small QPs here.
fn qp_settings() -> DefaultSettings<f64> {
    DefaultSettings::<f64> {
        verbose: false,
        tol_gap_abs: 1e-11,
        tol_gap_rel: 1e-11,
        tol_feas: 1e-11,
        max_iter: 200,
        ..DefaultSettings::default()
    }
}

/// Row/column-major dense → CSC (optionally the upper triangle only, as clarabel wants for P).
fn csc_from_dense(
    m: usize,
    n: usize,
    get: impl Fn(usize, usize) -> f64,
    upper: bool,
) -> CscMatrix<f64> {
    let mut colptr = Vec::with_capacity(n + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for j in 0..n {
        for i in 0..m {
            if upper && i > j {
                continue;
            }
            let v = get(i, j);
            if v != 0.0 {
                rowval.push(i);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(m, n, colptr, rowval, nzval)
}

/// λ_J with H_JJ λ_J = −rhs_J by nalgebra's Cholesky factorisation, `None` when H_JJ is not numerically
/// positive definite (the rows of J dependent in R⁺'s inner product, as opposite faces of a box).
fn solve_spd(J: &[usize], dual: &DualData, rhs: &[f64]) -> Option<Vec<f64>> {
    let k = rhs.len();
    let m = J.len();
    let H = nalgebra::DMatrix::from_fn(m, m, |r, c| dual.H[J[r] * k + J[c]]);
    let scale = (0..m).map(|r| H[(r, r)]).fold(0.0, f64::max);
    let chol = H.cholesky()?;
    let l = chol.l_dirty();
    if (0..m).any(|r| !(l[(r, r)] * l[(r, r)] > 1e-12 * scale)) {
        return None;
    }
    let f = nalgebra::DVector::from_fn(m, |r, _| -rhs[J[r]]);
    Some(chol.solve(&f).iter().copied().collect())
}

/// Solve min ½dᵀRd s.t. A_J d = rhs_J through the symmetric KKT system [[R, A_Jᵀ], [A_J, 0]] by a pseudo-inverse
/// (so dependent active rows are tolerated); `None` if the system is inconsistent.
fn polish(n: usize, R: &[f64], A: &[f64], rhs: &[f64], active: &[usize]) -> Option<Vec<f64>> {
    let m = active.len();
    let N = n + m;
    let mut K = vec![0.0; N * N];
    for i in 0..n {
        for j in 0..n {
            K[i * N + j] = R[i * n + j];
        }
    }
    for (r, &i) in active.iter().enumerate() {
        for j in 0..n {
            K[(n + r) * N + j] = A[i * n + j];
            K[j * N + n + r] = A[i * n + j];
        }
    }
    let mut f = vec![0.0; N];
    for (r, &i) in active.iter().enumerate() {
        f[n + r] = rhs[i];
    }
    let e = SymEig::new("polish KKT", N, &K).ok()?;
    let Kp = e.pinv();
    let mut sol = vec![0.0; N];
    linalg::matvec(&Kp, N, N, &f, &mut sol);
    // Consistency: K sol = f.
    let mut res = vec![0.0; N];
    linalg::matvec(&K, N, N, &sol, &mut res);
    let err = res
        .iter()
        .zip(&f)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    if err.is_nan() || err > 1e-10 * (1.0 + linalg::max_abs(&f)) {
        return None;
    }
    sol.truncate(n);
    Some(sol)
}

impl Region for Polytope {
    fn dim(&self) -> usize {
        self.n
    }
    fn contains(&self, x: &[f64]) -> bool {
        x.len() == self.n
            && (0..self.k)
                .all(|i| linalg::dot(&self.A[i * self.n..(i + 1) * self.n], x) <= self.b[i])
    }
    /// A row a·x ≤ b changes by at most ‖a‖‖y − x‖₂: inside, the least row slack over ‖a‖ keeps y inside;
    /// outside, the largest violation over ‖a‖ keeps y outside (a row without coefficients is constant).
    fn sure_radius(&self, x: &[f64]) -> Option<(bool, f64)> {
        if x.len() != self.n || !x.iter().all(|v| v.is_finite()) {
            return None;
        }
        let xn = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        let (mut inner, mut outer) = (f64::INFINITY, None::<f64>);
        for i in 0..self.k {
            let a = &self.A[i * self.n..(i + 1) * self.n];
            let an = a.iter().map(|v| v * v).sum::<f64>().sqrt();
            let ax = linalg::dot(a, x);
            let scale = self.b[i].abs() + an * xn;
            if ax <= self.b[i] {
                if an > 0.0 {
                    inner = inner.min(super::sure_margin(self.b[i] - ax, scale) / an);
                }
            } else {
                let r = if an > 0.0 {
                    super::sure_margin(ax - self.b[i], scale) / an
                } else {
                    f64::INFINITY
                };
                outer = Some(outer.map_or(r, |o| o.max(r)));
            }
        }
        Some(match outer {
            Some(r) => (false, r),
            None => (true, inner),
        })
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_dist(x, metric))
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        Witness::or_invalid(self.try_depth(x, metric))
    }
    fn try_dist(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.n, x, metric)?;
        let steps = self.steps(metric)?;
        if self.contains(x) {
            return Ok(Witness {
                value: 0.0,
                point: x.to_vec(),
            });
        }
        self.dist_outside(x, &steps)
    }
    fn try_depth(&self, x: &[f64], metric: &Metric) -> Result<Witness, GeometryError> {
        check_query(self.n, x, metric)?;
        let steps = self.steps(metric)?;
        if !self.contains(x) {
            return Ok(Witness {
                value: 0.0,
                point: x.to_vec(),
            });
        }
        Ok(self.depth_inside(x, &steps))
    }
    fn convex_pieces(&self) -> Option<Vec<&dyn Region>> {
        Some(vec![self])
    }
    fn compile(&self, metric: &Metric) -> Option<Box<dyn super::SignedDistanceFn + '_>> {
        self.compiled(metric)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box(n: usize) -> Polytope {
        let mut A = vec![0.0; 2 * n * n];
        let mut b = vec![1.0; 2 * n];
        for i in 0..n {
            A[(2 * i) * n + i] = 1.0;
            A[(2 * i + 1) * n + i] = -1.0;
            b[2 * i] = 1.0;
        }
        Polytope::new(n, A, b).unwrap()
    }

    #[test]
    fn box_distance_and_depth_euclidean() {
        let p = unit_box(2);
        let m = Metric::euclidean(2);
        let w = p.dist(&[3.0, 4.0], &m);
        assert!((w.value - 13.0_f64.sqrt()).abs() < 1e-10, "{}", w.value);
        assert!((w.point[0] - 1.0).abs() < 1e-10 && (w.point[1] - 1.0).abs() < 1e-10);
        let w = p.depth(&[0.5, -0.2], &m);
        assert!((w.value - 0.5).abs() < 1e-15);
        assert_eq!(w.point, vec![1.0, -0.2]);
        assert!((p.signed_dist(&[2.0, 0.0], &m).value + 1.0).abs() < 1e-10);
    }

    /// Random small polytopes (2 to 4 dimensions, 3 to 8 rows) in random definite metrics, from random
    /// outside points: the active set's answer is the QP's to 10⁻⁸, on faces and at corners alike, and
    /// it answers nearly every case (a case it leaves is the QP's).
    #[test]
    fn the_active_set_projection_is_the_qp_minimiser() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(46);
        let (mut answered, mut corners) = (0, 0);
        for case in 0..600 {
            let n = 2 + case % 3;
            let k = 3 + case % 6;
            // Rows tangent to the unit sphere at random normals (so the set is bounded and nonempty
            // once k > n), a random positive definite metric, a start outside.
            let mut A = vec![0.0; k * n];
            for row in A.chunks_exact_mut(n) {
                row.iter_mut()
                    .for_each(|v| *v = rng.random_range(-1.0..1.0));
            }
            let b: Vec<f64> = A
                .chunks_exact(n)
                .map(|r| r.iter().map(|v| v * v).sum::<f64>().sqrt())
                .collect();
            let p = Polytope::new(n, A, b).unwrap();
            let G: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut R = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    R[i * n + j] = (0..n).map(|c| G[i * n + c] * G[j * n + c]).sum::<f64>()
                        + if i == j { 0.1 } else { 0.0 };
                }
            }
            let m = Metric::new(n, R).unwrap();
            let steps = p.steps(&m).unwrap();
            let x: Vec<f64> = (0..n).map(|_| rng.random_range(-4.0..4.0)).collect();
            if p.contains(&x) {
                continue;
            }
            let qp = p.project(&x, &steps.R).unwrap();
            let Some(exact) = p.project_active_set(&x, &steps) else {
                continue;
            };
            answered += 1;
            assert!(
                (exact.value - qp.value).abs() <= 1e-8 * (1.0 + qp.value),
                "case {case}: {exact:?} against the QP's {qp:?}"
            );
            for (a, b) in exact.point.iter().zip(&qp.point) {
                assert!((a - b).abs() < 1e-6, "case {case}: {exact:?} {qp:?}");
            }
            // The nearest point is a vertex (n rows active) in some cases, on a face in others.
            let active = (0..k)
                .filter(|&i| {
                    (p.b[i] - linalg::dot(&p.A[i * n..(i + 1) * n], &exact.point)).abs() < 1e-9
                })
                .count();
            corners += usize::from(active >= 2);
        }
        assert!(
            answered > 450,
            "{answered} of 600 answered by the active set"
        );
        assert!(
            corners > 50 && corners < answered - 50,
            "{corners} of {answered} at a corner"
        );
    }

    #[test]
    fn a_box_in_a_diagonal_metric_is_answered_in_closed_form_as_the_qp_answers() {
        // A box with a redundant row, in a diagonal metric: the closed form against the QP itself.
        let (A, b) = (
            vec![1.0, 0.0, -2.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 3.0],
            vec![1.0, 2.0, 2.0, 1.0, 9.0],
        );
        let p = Polytope::new(2, A, b).unwrap();
        let m = Metric::new(2, vec![4.0, 0.0, 0.0, 0.25]).unwrap();
        let steps = p.steps(&m).unwrap();
        for x in [[3.0, 4.0], [-5.0, 0.5], [0.0, -7.0], [-2.0, 2.5]] {
            let closed = p.dist(&x, &m);
            let qp = p.project(&x, &steps.R).unwrap();
            assert!(
                (closed.value - qp.value).abs() < 1e-9,
                "{x:?}: {closed:?} {qp:?}"
            );
            for (a, b) in closed.point.iter().zip(&qp.point) {
                assert!((a - b).abs() < 1e-8, "{x:?}: {closed:?} {qp:?}");
            }
        }
        // x₀ ∈ [−1, 1], x₁ ∈ [−1, 2]: from (3, 4) the nearest point is (1, 2), at √(4·4 + 0.25·4).
        let w = p.dist(&[3.0, 4.0], &m);
        assert_eq!(w.point, vec![1.0, 2.0]);
        assert!((w.value - 17.0_f64.sqrt()).abs() < 1e-15);
        // A non-diagonal metric or a slanted row is the QP's.
        let full = Metric::new(2, vec![2.0, 0.5, 0.5, 1.0]).unwrap();
        assert!(p
            .dist_box(&[3.0, 4.0], &p.steps(&full).unwrap().R)
            .is_none());
        let slanted =
            Polytope::new(2, vec![1.0, 1.0, -1.0, 0.0, 0.0, -1.0], vec![1.0, 0.0, 0.0]).unwrap();
        assert!(slanted.dist_box(&[3.0, 4.0], &steps.R).is_none());
    }

    #[test]
    fn depth_in_singular_metric_is_zero_through_free_facets() {
        let p = unit_box(2);
        // ‖·‖_R only sees x₀: the facets x₁ = ±1 are reachable for free.
        let m = Metric::new(2, vec![1.0, 0.0, 0.0, 0.0]).unwrap();
        let w = p.depth(&[0.0, 0.5], &m);
        assert_eq!(w.value, 0.0);
        assert!((w.point[1].abs() - 1.0).abs() < 1e-15 && w.point[0] == 0.0);
        // Distance from outside only counts the x₀ excursion.
        let w = p.dist(&[3.0, 7.0], &m);
        assert!((w.value - 2.0).abs() < 1e-9, "{}", w.value);
    }

    #[test]
    fn weighted_depth_matches_formula() {
        // Half-plane x₀ + x₁ ≤ 1 intersected with a far box; R = diag(4, 1).
        let p = Polytope::new(
            2,
            vec![1.0, 1.0, -1.0, 0.0, 0.0, -1.0],
            vec![1.0, 10.0, 10.0],
        )
        .unwrap();
        let m = Metric::new(2, vec![4.0, 0.0, 0.0, 1.0]).unwrap();
        let x = [0.0, 0.0];
        let expect = 1.0 / (0.25_f64 + 1.0).sqrt();
        let w = p.depth(&x, &m);
        assert!((w.value - expect).abs() < 1e-15);
        assert!((w.point[0] + w.point[1] - 1.0).abs() < 1e-15);
        assert!((m.distance(&x, &w.point) - expect).abs() < 1e-15);
    }

    #[test]
    fn half_space_distance_is_the_qp_answer_in_closed_form() {
        // {2y₀ − y₁ ≤ 1} in a weighted metric, from an outside point: the closed form against the QP.
        let h = Polytope::new(2, vec![2.0, -1.0], vec![1.0]).unwrap();
        let m = Metric::new(2, vec![2.0, 0.5, 0.5, 1.0]).unwrap();
        let x = [3.0, -1.0];
        let steps = h.steps(&m).unwrap();
        let closed = h.dist_half_space(&x, &steps);
        let qp = h.project(&x, &steps.R).unwrap();
        assert!(
            (closed.value - qp.value).abs() < 1e-9,
            "{closed:?} vs {qp:?}"
        );
        assert!(h.contains(&closed.point) || h.max_violation(&closed.point) < 1e-12);
        assert_eq!(h.dist(&x, &m).value, closed.value);
    }

    #[test]
    fn constructor_errors() {
        assert!(matches!(
            Polytope::new(2, vec![1.0, 0.0], vec![1.0, 2.0]),
            Err(GeometryError::Dimension { .. })
        ));
        assert!(matches!(
            Polytope::new(1, vec![0.0], vec![1.0]),
            Err(GeometryError::NoConstraints)
        ));
        assert!(matches!(
            Polytope::new(1, vec![0.0], vec![-1.0]),
            Err(GeometryError::EmptyPolytope)
        ));
        assert!(matches!(
            Polytope::new(1, vec![1.0, -1.0], vec![0.0, -1.0]),
            Err(GeometryError::EmptyPolytope)
        ));
        assert!(matches!(
            Polytope::new(1, vec![f64::INFINITY], vec![1.0]),
            Err(GeometryError::NotFinite { .. })
        ));
        assert!(Polytope::new(1, vec![1.0, -1.0], vec![0.0, 0.0]).is_ok()); // a single point is fine
    }
}
