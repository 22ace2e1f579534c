//! Cross-set sanity checks of a spec, each a small convex computation with a certificate:
//!
//! * **Init meets Unsafe** ([`box_meets_set`]). For the box Init and one Unsafe set S (with its coordinate
//!   map y = M x) we minimise a convex "violation" over the box:
//!   - ellipsoid / ball: f(x) = (Mx − c)ᵀQ(Mx − c), meets ⇔ min f ≤ 1. Solved by exact coordinate
//!     descent (convex quadratic, box constraints); the Frank–Wolfe gap gives a rigorous lower bound
//!     L = f(z) + min_{w ∈ box} ∇f(z)ᵀ(w − z) ≤ min f.
//!   - polytope / box (rows normalised to unit length): t(x) = maxᵢ (âᵢ·Mx − b̂ᵢ), meets ⇔ min t ≤ 0.
//!     Solved as an LP with clarabel; the LP duals λ (normalised to the simplex) give the rigorous lower
//!     bound L = min_{x ∈ box} Σ λᵢ(âᵢ·Mx − b̂ᵢ) ≤ min t.
//!
//!   "Meets" is reported only with a witness x in Init whose violation is ≤ 1e-7 (relative; touching
//!   counts as meeting); "disjoint" only when the lower bound is positive. If neither is certified (the
//!   sets are within ~1e-7 of touching and the solver cannot separate them), the check says
//!   [`Meet::Undecided`] and the spec is accepted.
//! * **Goal unreachable by construction** ([`goal_verdict`]). A trajectory needs a point of Goal at
//!   positive depth that is not in Unsafe. We report:
//!   - Goal has an empty interior in its own coordinates (ball of radius 0, box with lo = hi somewhere,
//!     polytope whose largest inscribed ball has radius ≤ 1e-9·scale — an LP — or an infeasible row
//!     0 ≤ b < 0), i.e. Goal is empty after shrinking it by any ε > 0;
//!   - Goal lies inside a single Unsafe set stated in the same coordinates (to 1e-9), decided for:
//!     polytope/box Unsafe with any Goal (support functions; an LP for a polytope Goal), and
//!     ball/ellipsoid Unsafe with a ball, positive-definite ellipsoid (trust-region bound, exact) or box
//!     (vertices, d ≤ 16) Goal.
//!
//!   Not checked (never reported): Goal covered only by a union of several Unsafe sets, Goal and Unsafe
//!   in different coordinates, a polytope Goal inside an ellipsoid Unsafe.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

use super::sets::{SetDesc, Shape};
use super::Matrix;

/// Why a symmetric eigen-decomposition could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EigenError {
    #[error("{rows}×{cols} is not square")]
    NotSquare { rows: usize, cols: usize },
    #[error("non-finite entry")]
    NonFinite,
    /// faer's iteration did not converge.
    #[error("the eigenvalue iteration did not converge")]
    NoConvergence,
}

/// Eigenvalues of a symmetric matrix (lower triangle used), ascending.
pub fn sym_eigenvalues(Q: &Matrix) -> Result<Vec<f64>, EigenError> {
    Ok(sym_eigen(Q)?.0)
}

/// Eigen-decomposition of a symmetric matrix: (eigenvalues ascending, eigenvectors as the columns of a
/// row-major matrix).
pub fn sym_eigen(Q: &Matrix) -> Result<(Vec<f64>, Matrix), EigenError> {
    if Q.rows != Q.cols {
        return Err(EigenError::NotSquare {
            rows: Q.rows,
            cols: Q.cols,
        });
    }
    if Q.data.iter().any(|v| !v.is_finite()) {
        return Err(EigenError::NonFinite);
    }
    let n = Q.rows;
    if n == 0 {
        return Ok((Vec::new(), Matrix::zeros(0, 0)));
    }
    let m = faer::Mat::from_fn(n, n, |i, j| 0.5 * (Q.get(i, j) + Q.get(j, i)));
    let e = m
        .self_adjoint_eigen(faer::Side::Lower)
        .map_err(|_| EigenError::NoConvergence)?;
    let s = e.S().column_vector();
    let u = e.U();
    let vals: Vec<f64> = (0..n).map(|i| s[i]).collect();
    let mut V = Matrix::zeros(n, n);
    for i in 0..n {
        for j in 0..n {
            V.data[i * n + j] = u[(i, j)];
        }
    }
    Ok((vals, V))
}

/// Outcome of the Init/Unsafe test.
#[derive(Clone, Debug, PartialEq)]
pub enum Meet {
    /// A point of Init that lies in the set (to the tolerance in the module doc).
    Meets(Vec<f64>),
    /// Certified disjoint.
    Disjoint,
    /// Neither certified (touching to within the solver's accuracy, or a solver failure).
    Undecided,
}

/// Does the box [lo, hi] (state coordinates, lo ≤ hi, lo = hi allowed) meet `set`?
pub fn box_meets_set(lo: &[f64], hi: &[f64], set: &SetDesc) -> Meet {
    let n = lo.len();
    let M = match set.map_matrix(n) {
        Ok(Some(M)) => M,
        Ok(None) => Matrix::identity(n),
        Err(_) => return Meet::Undecided,
    };
    match &set.shape {
        Shape::Ball { center, radius } if *radius > 0.0 => {
            let d = center.len();
            let mut Q = Matrix::identity(d);
            Q.data.iter_mut().for_each(|v| *v /= radius * radius);
            ellipsoid_meets_box(lo, hi, &M, center, &Q)
        }
        Shape::Ball { center, .. } => polytope_meets_box(lo, hi, &M, &box_rows(center, center)),
        Shape::Ellipsoid { center, Q } => ellipsoid_meets_box(lo, hi, &M, center, Q),
        Shape::Polytope { A, b } => polytope_meets_box(lo, hi, &M, &(A.clone(), b.clone())),
        Shape::Box { lo: l, hi: h } => polytope_meets_box(lo, hi, &M, &box_rows(l, h)),
    }
}

/// Rows [I; −I] y ≤ [hi; −lo].
pub(crate) fn box_rows(lo: &[f64], hi: &[f64]) -> (Matrix, Vec<f64>) {
    let d = lo.len();
    let mut A = Matrix::zeros(2 * d, d);
    let mut b = vec![0.0; 2 * d];
    for i in 0..d {
        A.data[i * d + i] = 1.0;
        b[i] = hi[i];
        A.data[(d + i) * d + i] = -1.0;
        b[d + i] = -lo[i];
    }
    (A, b)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn clamp_box(z: &mut [f64], lo: &[f64], hi: &[f64]) {
    for i in 0..z.len() {
        z[i] = z[i].max(lo[i]).min(hi[i]);
    }
}

/// min over the box of (Mx − c)ᵀQ(Mx − c) ≤ 1 ?
fn ellipsoid_meets_box(lo: &[f64], hi: &[f64], M: &Matrix, c: &[f64], Q: &Matrix) -> Meet {
    let n = lo.len();
    let d = M.rows;
    let form = |x: &[f64]| {
        let y = M.mul_vec(x);
        let r: Vec<f64> = y.iter().zip(c).map(|(a, b)| a - b).collect();
        Q.quad_form(&r)
    };
    // The quadratic in x: f(x) = xᵀHx + 2gᵀx + k with H = MᵀQM, g = −MᵀQc.
    let Qc = Q.mul_vec(c);
    let mut H = Matrix::zeros(n, n);
    let mut QM = Matrix::zeros(d, n); // Q M
    for i in 0..d {
        for j in 0..n {
            QM.data[i * n + j] = (0..d).map(|k| Q.get(i, k) * M.get(k, j)).sum();
        }
    }
    for i in 0..n {
        for j in 0..n {
            H.data[i * n + j] = (0..d).map(|k| M.get(k, i) * QM.get(k, j)).sum();
        }
    }
    let g: Vec<f64> = (0..n)
        .map(|j| -(0..d).map(|k| M.get(k, j) * Qc[k]).sum::<f64>())
        .collect();
    let grad_half = |x: &[f64]| -> Vec<f64> { (0..n).map(|i| dot(H.row(i), x) + g[i]).collect() };

    let mut x: Vec<f64> = (0..n).map(|i| 0.5 * (lo[i] + hi[i])).collect();
    const TOL: f64 = 1e-7;
    for sweep in 0..200_000usize {
        if sweep % 8 == 0 {
            clamp_box(&mut x, lo, hi);
            let U = form(&x);
            if U <= 1.0 + TOL {
                return Meet::Meets(x);
            }
            let w = grad_half(&x);
            let fw: f64 = (0..n)
                .map(|j| (2.0 * w[j] * (lo[j] - x[j])).min(2.0 * w[j] * (hi[j] - x[j])))
                .sum();
            let L = U + fw;
            if L > 1.0 {
                return Meet::Disjoint;
            }
        }
        let mut w = grad_half(&x);
        for j in 0..n {
            let hjj = H.get(j, j);
            if hjj <= 0.0 || lo[j] == hi[j] {
                continue;
            }
            let new = (x[j] - w[j] / hjj).max(lo[j]).min(hi[j]);
            let delta = new - x[j];
            if delta != 0.0 {
                x[j] = new;
                for (i, wi) in w.iter_mut().enumerate() {
                    *wi += delta * H.get(i, j);
                }
            }
        }
    }
    Meet::Undecided
}

/// Normalise the rows of A y ≤ b to unit length. Returns None when a zero row has b < 0 (empty set);
/// drops zero rows with b ≥ 0.
fn normalise_rows(A: &Matrix, b: &[f64]) -> Option<(Vec<Vec<f64>>, Vec<f64>)> {
    let mut rows = Vec::new();
    let mut rhs = Vec::new();
    for (i, &bi) in b.iter().enumerate().take(A.rows) {
        let a = A.row(i);
        let nrm = dot(a, a).sqrt();
        if nrm == 0.0 {
            if bi < 0.0 {
                return None;
            }
            continue;
        }
        rows.push(a.iter().map(|v| v / nrm).collect());
        rhs.push(bi / nrm);
    }
    Some((rows, rhs))
}

/// Solve min cᵀx s.t. G x ≤ h (all rows inequalities) with clarabel. Returns (status, x, z duals, objective).
fn lp(c: &[f64], G: &[Vec<f64>], h: &[f64]) -> Option<(SolverStatus, Vec<f64>, Vec<f64>, f64)> {
    let nv = c.len();
    let m = G.len();
    let (mut I, mut J, mut V) = (Vec::new(), Vec::new(), Vec::new());
    for (i, row) in G.iter().enumerate() {
        for (j, &v) in row.iter().enumerate() {
            if v != 0.0 {
                I.push(i);
                J.push(j);
                V.push(v);
            }
        }
    }
    let A = CscMatrix::new_from_triplets(m, nv, I, J, V);
    let P = CscMatrix::<f64>::zeros((nv, nv));
    let cones = [SupportedConeT::NonnegativeConeT(m)];
    let settings = DefaultSettings::<f64> {
        verbose: false,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&P, c, &A, h, &cones, settings).ok()?;
    solver.solve();
    let s = &solver.solution;
    Some((s.status, s.x.clone(), s.z.clone(), s.obj_val))
}

/// min over the box of maxᵢ (âᵢ·Mx − b̂ᵢ) ≤ 0 ?
fn polytope_meets_box(lo: &[f64], hi: &[f64], M: &Matrix, (A, b): &(Matrix, Vec<f64>)) -> Meet {
    let n = lo.len();
    let Some((rows, rhs)) = normalise_rows(A, b) else {
        return Meet::Disjoint;
    };
    let mut x: Vec<f64> = (0..n).map(|i| 0.5 * (lo[i] + hi[i])).collect();
    if rows.is_empty() {
        return Meet::Meets(x);
    }
    let scale = lo
        .iter()
        .chain(hi)
        .chain(&rhs)
        .fold(1.0f64, |a, v| a.max(v.abs()));
    let tol = 1e-7 * scale;
    // Rows in x: eᵢ = Mᵀâᵢ.
    let E: Vec<Vec<f64>> = rows
        .iter()
        .map(|a| {
            (0..n)
                .map(|j| (0..M.rows).map(|k| a[k] * M.get(k, j)).sum())
                .collect()
        })
        .collect();
    let viol = |x: &[f64]| -> f64 {
        let y = M.mul_vec(x);
        rows.iter()
            .zip(&rhs)
            .map(|(a, bb)| dot(a, &y) - bb)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let free: Vec<usize> = (0..n).filter(|&i| lo[i] < hi[i]).collect();
    if free.is_empty() {
        return if viol(&x) <= tol {
            Meet::Meets(x)
        } else {
            Meet::Disjoint
        };
    }
    // Variables (x_free, t): min t s.t. e_F·z − t ≤ b̂ − e_fixed·x_fixed; z ≤ hi_F; −z ≤ −lo_F.
    let f = free.len();
    let mut G = Vec::new();
    let mut h = Vec::new();
    for (e, bb) in E.iter().zip(&rhs) {
        let mut row: Vec<f64> = free.iter().map(|&j| e[j]).collect();
        row.push(-1.0);
        G.push(row);
        let fixed: f64 = (0..n)
            .filter(|j| lo[*j] == hi[*j])
            .map(|j| e[j] * lo[j])
            .sum();
        h.push(bb - fixed);
    }
    for (k, &j) in free.iter().enumerate() {
        let mut r = vec![0.0; f + 1];
        r[k] = 1.0;
        G.push(r.clone());
        h.push(hi[j]);
        r[k] = -1.0;
        G.push(r);
        h.push(-lo[j]);
    }
    let mut cvec = vec![0.0; f + 1];
    cvec[f] = 1.0;
    let Some((status, sol, z, _)) = lp(&cvec, &G, &h) else {
        return Meet::Undecided;
    };
    if !matches!(status, SolverStatus::Solved | SolverStatus::AlmostSolved) {
        return Meet::Undecided;
    }
    for (k, &j) in free.iter().enumerate() {
        x[j] = sol[k];
    }
    clamp_box(&mut x, lo, hi);
    if viol(&x) <= tol {
        return Meet::Meets(x);
    }
    // Lower bound from the duals of the first rows.
    let k = rows.len();
    let lam: Vec<f64> = z[..k].iter().map(|v| v.max(0.0)).collect();
    let s: f64 = lam.iter().sum();
    if s > 0.0 {
        let cvec: Vec<f64> = (0..n)
            .map(|j| (0..k).map(|i| lam[i] / s * E[i][j]).sum())
            .collect();
        let L: f64 = (0..n)
            .map(|j| (cvec[j] * lo[j]).min(cvec[j] * hi[j]))
            .sum::<f64>()
            - (0..k).map(|i| lam[i] / s * rhs[i]).sum::<f64>();
        if L > 0.0 {
            return Meet::Disjoint;
        }
    }
    Meet::Undecided
}

/// Verdict on Goal.
#[derive(Clone, Debug, PartialEq)]
pub enum GoalVerdict {
    /// Nothing found that makes Goal unreachable.
    Ok,
    /// Goal has no interior; the reason.
    NoInterior(String),
    /// Goal lies inside `unsafe[j]`.
    InsideUnsafe(usize),
}

/// Check Goal for emptiness of its interior and for containment in one Unsafe set (see module doc).
pub fn goal_verdict(goal: &SetDesc, unsafe_sets: &[SetDesc]) -> GoalVerdict {
    if let Some(why) = no_interior(&goal.shape) {
        return GoalVerdict::NoInterior(why);
    }
    for (j, u) in unsafe_sets.iter().enumerate() {
        if u.coords == goal.coords && u.dim() == goal.dim() && contained(&goal.shape, &u.shape) {
            return GoalVerdict::InsideUnsafe(j);
        }
    }
    GoalVerdict::Ok
}

/// Why the shape has no interior, if it has none.
pub fn no_interior(s: &Shape) -> Option<String> {
    match s {
        Shape::Ball { radius, .. } if *radius <= 0.0 => Some("its radius is 0".into()),
        Shape::Ball { .. } | Shape::Ellipsoid { .. } => None,
        Shape::Box { lo, hi } => (0..lo.len())
            .find(|&i| lo[i] >= hi[i])
            .map(|i| format!("lo = hi = {} in coordinate {}, so the box is flat", lo[i], i + 1)),
        Shape::Polytope { A, b } => match inscribed(A, b) {
            Inscribed::Interior | Inscribed::Unknown => None,
            Inscribed::Empty => Some("the inequalities A y ≤ b have no common solution (the polytope is empty)".into()),
            Inscribed::Flat(r) => Some(format!(
                "the largest ball inside the polytope has radius {r:.1e}, zero to solver accuracy, so it has no interior"
            )),
        },
    }
}

/// What the largest inscribed ball of {y : A y ≤ b} says about it.
#[derive(Clone, Debug, PartialEq)]
pub enum Inscribed {
    /// A point with every (normalised) row slack > 1e-9·scale was found.
    Interior,
    /// Nonempty (to 1e-7·scale) but the largest inscribed ball has radius ≤ 1e-9·scale (the value).
    Flat(f64),
    /// No point satisfies all rows to within 1e-7·scale (or a zero row has b < 0).
    Empty,
    /// The LP did not solve.
    Unknown,
}

/// Chebyshev-ball LP: min t s.t. âᵢ·y − t ≤ b̂ᵢ (unit rows), t ≥ −1; −t* is the inscribed radius (capped at 1).
pub fn inscribed(A: &Matrix, b: &[f64]) -> Inscribed {
    let Some((rows, rhs)) = normalise_rows(A, b) else {
        return Inscribed::Empty;
    };
    if rows.is_empty() {
        return Inscribed::Interior;
    }
    let d = A.cols;
    let scale = rhs.iter().fold(1.0f64, |a, v| a.max(v.abs()));
    let mut G: Vec<Vec<f64>> = rows
        .iter()
        .map(|a| {
            let mut r = a.clone();
            r.push(-1.0);
            r
        })
        .collect();
    let mut h = rhs.clone();
    let mut last = vec![0.0; d + 1];
    last[d] = -1.0;
    G.push(last);
    h.push(1.0);
    let mut c = vec![0.0; d + 1];
    c[d] = 1.0;
    let Some((status, sol, _, _)) = lp(&c, &G, &h) else {
        return Inscribed::Unknown;
    };
    if !matches!(status, SolverStatus::Solved | SolverStatus::AlmostSolved) {
        return Inscribed::Unknown;
    }
    let y = &sol[..d];
    let worst = rows
        .iter()
        .zip(&rhs)
        .map(|(a, bb)| dot(a, y) - bb)
        .fold(f64::NEG_INFINITY, f64::max);
    if worst < -1e-9 * scale {
        Inscribed::Interior
    } else if worst > 1e-7 * scale {
        Inscribed::Empty
    } else {
        Inscribed::Flat((-sol[d]).max(0.0))
    }
}

/// Support function h_S(a) = max_{y ∈ S} a·y; None if unbounded or not computed.
fn support(s: &Shape, a: &[f64]) -> Option<f64> {
    match s {
        Shape::Ball { center, radius } => Some(dot(a, center) + radius * dot(a, a).sqrt()),
        Shape::Ellipsoid { center, Q } => {
            let (mu, V) = sym_eigen(Q).ok()?;
            let mmax = mu.iter().fold(0.0f64, |x, v| x.max(v.abs()));
            if mu.first().copied().unwrap_or(0.0) <= 1e-12 * mmax.max(1.0) {
                return None;
            }
            let d = mu.len();
            let q: f64 = (0..d)
                .map(|k| {
                    let vk: f64 = (0..d).map(|i| V.get(i, k) * a[i]).sum();
                    vk * vk / mu[k]
                })
                .sum();
            Some(dot(a, center) + q.sqrt())
        }
        Shape::Box { lo, hi } => Some(
            (0..lo.len())
                .map(|i| (a[i] * lo[i]).max(a[i] * hi[i]))
                .sum(),
        ),
        Shape::Polytope { A, b } => {
            let G: Vec<Vec<f64>> = (0..A.rows).map(|i| A.row(i).to_vec()).collect();
            let c: Vec<f64> = a.iter().map(|v| -v).collect();
            let (status, x, _, _) = lp(&c, &G, b)?;
            if status != SolverStatus::Solved {
                return None;
            }
            Some(dot(a, &x))
        }
    }
}

/// Is G ⊆ U (both in the same coordinates), to 1e-9? Only the cases in the module doc; others say no.
pub fn contained(G: &Shape, U: &Shape) -> bool {
    match U {
        Shape::Polytope { .. } | Shape::Box { .. } => {
            let (A, b) = match U {
                Shape::Polytope { A, b } => (A.clone(), b.clone()),
                Shape::Box { lo, hi } => box_rows(lo, hi),
                _ => return false,
            };
            let Some((rows, rhs)) = normalise_rows(&A, &b) else {
                return false;
            };
            let scale = rhs.iter().fold(1.0f64, |x, v| x.max(v.abs()));
            rows.iter()
                .zip(&rhs)
                .all(|(a, bb)| support(G, a).is_some_and(|s| s <= bb + 1e-9 * scale))
        }
        Shape::Ball { center, radius } => {
            if *radius <= 0.0 {
                return false;
            }
            let d = center.len();
            let mut Q = Matrix::identity(d);
            Q.data.iter_mut().for_each(|v| *v /= radius * radius);
            inside_ellipsoid(G, center, &Q)
        }
        Shape::Ellipsoid { center, Q } => inside_ellipsoid(G, center, Q),
    }
}

/// max over G of (y − cu)ᵀQu(y − cu) ≤ 1 + 1e-9 ?
fn inside_ellipsoid(G: &Shape, cu: &[f64], Qu: &Matrix) -> bool {
    let d = cu.len();
    match G {
        Shape::Box { lo, hi } => {
            if d > 16 {
                return false;
            }
            let mut v = vec![0.0; d];
            (0..1usize << d).all(|mask| {
                for i in 0..d {
                    v[i] = if mask >> i & 1 == 1 { hi[i] } else { lo[i] } - cu[i];
                }
                Qu.quad_form(&v) <= 1.0 + 1e-9
            })
        }
        Shape::Ball { center, radius } => {
            let mut L = Matrix::identity(d);
            L.data.iter_mut().for_each(|v| *v *= radius);
            trs_upper_bound(&L, center, cu, Qu).is_some_and(|ub| ub <= 1.0 + 1e-9)
        }
        Shape::Ellipsoid { center, Q } => {
            let Some((mu, V)) = sym_eigen(Q).ok() else {
                return false;
            };
            let mmax = mu.iter().fold(0.0f64, |x, v| x.max(v.abs()));
            if mu.first().copied().unwrap_or(0.0) <= 1e-12 * mmax.max(1.0) {
                return false;
            }
            // L = V diag(μ^{-1/2}) Vᵀ, so G = {center + L w : ‖w‖ ≤ 1}.
            let mut L = Matrix::zeros(d, d);
            for i in 0..d {
                for j in 0..d {
                    L.data[i * d + j] = (0..d)
                        .map(|k| V.get(i, k) * V.get(j, k) / mu[k].sqrt())
                        .sum();
                }
            }
            trs_upper_bound(&L, center, cu, Qu).is_some_and(|ub| ub <= 1.0 + 1e-9)
        }
        Shape::Polytope { .. } => false,
    }
}

/// An upper bound (tight at the optimum) on max_{‖w‖ ≤ 1} (Lw + d)ᵀQu(Lw + d), d = cg − cu:
/// for any λ > λmax(M), with M = LQuL, b = LQud, e = dᵀQud,
/// max ≤ λ + e + bᵀ(λI − M)⁻¹b (Lagrangian relaxation, exact for this trust-region problem).
fn trs_upper_bound(L: &Matrix, cg: &[f64], cu: &[f64], Qu: &Matrix) -> Option<f64> {
    let d = cg.len();
    let dv: Vec<f64> = cg.iter().zip(cu).map(|(a, b)| a - b).collect();
    let QL = mat_mul(Qu, L);
    let M = mat_mul(&transpose(L), &QL);
    let bvec = transpose(L).mul_vec(&Qu.mul_vec(&dv));
    let e = Qu.quad_form(&dv);
    let (m, W) = sym_eigen(&M).ok()?;
    let beta: Vec<f64> = (0..d)
        .map(|k| (0..d).map(|i| W.get(i, k) * bvec[i]).sum())
        .collect();
    let mmax = m.iter().copied().fold(0.0f64, f64::max);
    let ub = |lam: f64| {
        lam + e
            + (0..d)
                .map(|k| beta[k] * beta[k] / (lam - m[k]))
                .sum::<f64>()
    };
    let phi = |lam: f64| {
        (0..d)
            .map(|k| (beta[k] / (lam - m[k])).powi(2))
            .sum::<f64>()
    };
    let eps = 1e-12 * mmax.max(1.0);
    let mut lo = mmax + eps;
    if phi(lo) <= 1.0 {
        return Some(ub(lo));
    }
    let bn = dot(&beta, &beta).sqrt();
    let mut hi = mmax + bn + eps; // φ(hi) ≤ ‖β‖² / (‖β‖ + ε)² < 1
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if phi(mid) > 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(ub(hi).min(ub(lo)))
}

fn mat_mul(A: &Matrix, B: &Matrix) -> Matrix {
    let mut C = Matrix::zeros(A.rows, B.cols);
    for i in 0..A.rows {
        for j in 0..B.cols {
            C.data[i * B.cols + j] = (0..A.cols).map(|k| A.get(i, k) * B.get(k, j)).sum();
        }
    }
    C
}

fn transpose(A: &Matrix) -> Matrix {
    let mut T = Matrix::zeros(A.cols, A.rows);
    for i in 0..A.rows {
        for j in 0..A.cols {
            T.data[j * A.rows + i] = A.get(i, j);
        }
    }
    T
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::sets::Coords;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn rand_psd(rng: &mut ChaCha8Rng, d: usize, scale: f64) -> Matrix {
        let L: Vec<f64> = (0..d * d).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut Q = Matrix::zeros(d, d);
        for i in 0..d {
            for j in 0..d {
                Q.data[i * d + j] = scale
                    * ((0..d).map(|k| L[i * d + k] * L[j * d + k]).sum::<f64>()
                        + if i == j { 0.05 } else { 0.0 });
            }
        }
        Q
    }

    fn rand_box(rng: &mut ChaCha8Rng, n: usize) -> (Vec<f64>, Vec<f64>) {
        let mut lo = vec![0.0; n];
        let mut hi = vec![0.0; n];
        for i in 0..n {
            let a: f64 = rng.random_range(-1.0..1.0);
            // About one coordinate in four is pinned.
            let w = if rng.random_range(0..4) == 0 {
                0.0
            } else {
                rng.random_range(0.0..1.0)
            };
            lo[i] = a;
            hi[i] = a + w;
        }
        (lo, hi)
    }

    /// Uniform samples of the box plus all its vertices (n small).
    fn box_points(rng: &mut ChaCha8Rng, lo: &[f64], hi: &[f64], k: usize) -> Vec<Vec<f64>> {
        let n = lo.len();
        let mut pts: Vec<Vec<f64>> = (0..1usize << n)
            .map(|m| {
                (0..n)
                    .map(|i| if m >> i & 1 == 1 { hi[i] } else { lo[i] })
                    .collect()
            })
            .collect();
        for _ in 0..k {
            pts.push(
                (0..n)
                    .map(|i| lo[i] + (hi[i] - lo[i]) * rng.random::<f64>())
                    .collect(),
            );
        }
        pts
    }

    fn in_box(x: &[f64], lo: &[f64], hi: &[f64]) -> bool {
        (0..x.len()).all(|i| lo[i] <= x[i] && x[i] <= hi[i])
    }

    fn rand_coords(rng: &mut ChaCha8Rng, n: usize) -> (Coords, usize) {
        match rng.random_range(0..3) {
            0 => (Coords::State, n),
            1 => (Coords::StateIndices(vec![2, 0]), 2),
            _ => {
                let C = Matrix {
                    rows: 2,
                    cols: n,
                    data: (0..2 * n).map(|_| rng.random_range(-1.0..1.0)).collect(),
                };
                (Coords::Output { C }, 2)
            }
        }
    }

    /// Init/ellipsoid: a reported meeting has a verified witness; a reported disjointness is never
    /// contradicted by dense sampling of the box; planted meetings are found.
    #[test]
    fn box_meets_ellipsoid_against_sampling() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 3;
        let (mut meets, mut disjoint) = (0, 0);
        for _ in 0..300 {
            let (lo, hi) = box_box(&mut rng, n);
            let (coords, d) = rand_coords(&mut rng, n);
            let sc = rng.random_range(1.0..20.0);
            let Q = rand_psd(&mut rng, d, sc);
            let center: Vec<f64> = (0..d).map(|_| rng.random_range(-1.5..1.5)).collect();
            let set = SetDesc {
                shape: Shape::Ellipsoid { center, Q },
                coords,
            };
            match box_meets_set(&lo, &hi, &set) {
                Meet::Meets(x) => {
                    meets += 1;
                    assert!(in_box(&x, &lo, &hi));
                    let Shape::Ellipsoid { center, Q } = &set.shape else {
                        unreachable!()
                    };
                    let y = set.project(&x);
                    let r: Vec<f64> = y.iter().zip(center).map(|(a, b)| a - b).collect();
                    assert!(Q.quad_form(&r) <= 1.0 + 1e-6);
                }
                Meet::Disjoint => {
                    disjoint += 1;
                    for p in box_points(&mut rng, &lo, &hi, 2000) {
                        assert!(!set.contains(&p), "disjoint reported but {p:?} is in both");
                    }
                }
                Meet::Undecided => panic!("undecided on a random instance"),
            }
        }
        assert!(
            meets > 30 && disjoint > 30,
            "meets {meets}, disjoint {disjoint}"
        );

        // Planted: the ellipsoid is centred (in its coordinates) at the image of a point of the box.
        for _ in 0..100 {
            let (lo, hi) = box_box(&mut rng, n);
            let (coords, d) = rand_coords(&mut rng, n);
            let p: Vec<f64> = (0..n)
                .map(|i| lo[i] + (hi[i] - lo[i]) * rng.random::<f64>())
                .collect();
            let probe = SetDesc {
                shape: Shape::Box {
                    lo: vec![0.0; d],
                    hi: vec![0.0; d],
                },
                coords: coords.clone(),
            };
            let center = probe.project(&p);
            let set = SetDesc {
                shape: Shape::Ellipsoid {
                    center,
                    Q: rand_psd(&mut rng, d, 50.0),
                },
                coords,
            };
            assert!(matches!(box_meets_set(&lo, &hi, &set), Meet::Meets(_)));
        }
    }

    fn box_box(rng: &mut ChaCha8Rng, n: usize) -> (Vec<f64>, Vec<f64>) {
        rand_box(rng, n)
    }

    /// Init/polytope and Init/box: same properties via the LP with dual certificates.
    #[test]
    fn box_meets_polytope_against_sampling() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let n = 3;
        let (mut meets, mut disjoint, mut undecided) = (0, 0, 0);
        for it in 0..300 {
            let (lo, hi) = rand_box(&mut rng, n);
            let (coords, d) = rand_coords(&mut rng, n);
            let shape = if it % 3 == 0 {
                let a: Vec<f64> = (0..d).map(|_| rng.random_range(-1.5..1.5)).collect();
                let w: Vec<f64> = (0..d).map(|_| rng.random_range(0.0..0.6)).collect();
                Shape::Box {
                    lo: a.clone(),
                    hi: a.iter().zip(&w).map(|(x, y)| x + y).collect(),
                }
            } else {
                let k = rng.random_range(1..5);
                let A = Matrix {
                    rows: k,
                    cols: d,
                    data: (0..k * d).map(|_| rng.random_range(-1.0..1.0)).collect(),
                };
                let b = (0..k).map(|_| rng.random_range(-1.0..0.5)).collect();
                Shape::Polytope { A, b }
            };
            let set = SetDesc { shape, coords };
            match box_meets_set(&lo, &hi, &set) {
                Meet::Meets(x) => {
                    meets += 1;
                    assert!(in_box(&x, &lo, &hi));
                    // Within the documented tolerance of the set.
                    let y = set.project(&x);
                    let ok = match &set.shape {
                        Shape::Polytope { A, b } => (0..A.rows).all(|i| {
                            let a = A.row(i);
                            dot(a, &y) - b[i] <= 1e-6 * dot(a, a).sqrt().max(1e-300) + 1e-12
                        }),
                        Shape::Box { lo, hi } => {
                            (0..y.len()).all(|i| y[i] >= lo[i] - 1e-6 && y[i] <= hi[i] + 1e-6)
                        }
                        _ => unreachable!(),
                    };
                    assert!(ok, "witness {x:?} is not in the set");
                }
                Meet::Disjoint => {
                    disjoint += 1;
                    for p in box_points(&mut rng, &lo, &hi, 2000) {
                        assert!(!set.contains(&p), "disjoint reported but {p:?} is in both");
                    }
                }
                Meet::Undecided => undecided += 1,
            }
        }
        assert!(
            meets > 30 && disjoint > 30,
            "meets {meets}, disjoint {disjoint}"
        );
        assert!(undecided <= 3, "undecided {undecided}");
    }

    #[test]
    fn touching_boxes_meet_and_separated_ones_do_not() {
        let set = |l: f64| SetDesc {
            shape: Shape::Box {
                lo: vec![l, -5.0],
                hi: vec![l + 1.0, 5.0],
            },
            coords: Coords::State,
        };
        assert!(matches!(
            box_meets_set(&[0.0, 0.0], &[1.0, 0.0], &set(1.0)),
            Meet::Meets(_)
        ));
        assert_eq!(
            box_meets_set(&[0.0, 0.0], &[1.0, 0.0], &set(1.001)),
            Meet::Disjoint
        );
        // The ball that touches the box at one corner.
        let ball = SetDesc {
            shape: Shape::Ball {
                center: vec![2.0, 1.0],
                radius: 2f64.sqrt(),
            },
            coords: Coords::State,
        };
        assert!(matches!(
            box_meets_set(&[0.0, 0.0], &[1.0, 0.0], &ball),
            Meet::Meets(_)
        ));
        let ball = SetDesc {
            shape: Shape::Ball {
                center: vec![2.0, 1.0],
                radius: 1.41,
            },
            coords: Coords::State,
        };
        assert_eq!(
            box_meets_set(&[0.0, 0.0], &[1.0, 0.0], &ball),
            Meet::Disjoint
        );
    }

    /// Brute-force max of (y − cu)ᵀQu(y − cu) over the boundary of a 2-D ellipsoid {(y−c)ᵀQ(y−c) ≤ 1}.
    fn brute_max(cg: &[f64], Qg: &Matrix, cu: &[f64], Qu: &Matrix) -> f64 {
        let mut best = f64::NEG_INFINITY;
        for k in 0..20000 {
            let th = k as f64 * std::f64::consts::TAU / 20000.0;
            let dir = [th.cos(), th.sin()];
            let s = 1.0 / Qg.quad_form(&dir).sqrt();
            let y = [cg[0] + s * dir[0] - cu[0], cg[1] + s * dir[1] - cu[1]];
            best = best.max(Qu.quad_form(&y));
        }
        best
    }

    #[test]
    fn ellipsoid_containment_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let (mut yes, mut no) = (0, 0);
        for _ in 0..400 {
            let sg = rng.random_range(5.0..40.0);
            let Qg = rand_psd(&mut rng, 2, sg);
            let su = rng.random_range(0.5..4.0);
            let Qu = rand_psd(&mut rng, 2, su);
            let cg: Vec<f64> = (0..2).map(|_| rng.random_range(-0.5..0.5)).collect();
            let cu: Vec<f64> = (0..2).map(|_| rng.random_range(-0.5..0.5)).collect();
            let bm = brute_max(&cg, &Qg, &cu, &Qu);
            let got = contained(
                &Shape::Ellipsoid { center: cg, Q: Qg },
                &Shape::Ellipsoid { center: cu, Q: Qu },
            );
            if bm > 1.0 + 1e-6 {
                assert!(
                    !got,
                    "reported contained but a boundary point has form {bm}"
                );
                no += 1;
            } else if bm < 1.0 - 1e-3 {
                assert!(got, "not reported contained, brute max {bm}");
                yes += 1;
            }
        }
        assert!(yes > 30 && no > 30, "yes {yes}, no {no}");
    }

    #[test]
    fn ball_and_box_containment() {
        let ball = |c: [f64; 2], r: f64| Shape::Ball {
            center: c.to_vec(),
            radius: r,
        };
        assert!(contained(&ball([1.0, 0.0], 0.2), &ball([1.05, 0.0], 0.3)));
        assert!(!contained(&ball([1.0, 0.0], 0.2), &ball([1.15, 0.0], 0.3)));
        let bx = Shape::Box {
            lo: vec![-1.0, -1.0],
            hi: vec![1.0, 1.0],
        };
        assert!(contained(&bx, &ball([0.0, 0.0], 2f64.sqrt() + 1e-6)));
        assert!(!contained(&bx, &ball([0.0, 0.0], 1.41)));
        assert!(contained(&ball([0.0, 0.0], 1.0), &bx));
        assert!(!contained(&ball([0.0, 0.1], 1.0), &bx));
        let tri = Shape::Polytope {
            A: Matrix {
                rows: 3,
                cols: 2,
                data: vec![-1.0, 0.0, 0.0, -1.0, 1.0, 1.0],
            },
            b: vec![0.0, 0.0, 1.0],
        };
        assert!(contained(&tri, &bx));
        assert!(!contained(
            &tri,
            &Shape::Box {
                lo: vec![0.0, 0.0],
                hi: vec![0.9, 1.0]
            }
        ));
        // Polytope goal inside an ellipsoid is documented as not checked.
        assert!(!contained(&tri, &ball([0.0, 0.0], 10.0)));
    }

    #[test]
    fn support_of_ellipsoid_matches_sampling() {
        let mut rng = ChaCha8Rng::seed_from_u64(14);
        for _ in 0..50 {
            let Q = rand_psd(&mut rng, 2, 3.0);
            let c = vec![rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)];
            let a = [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)];
            let s = support(
                &Shape::Ellipsoid {
                    center: c.clone(),
                    Q: Q.clone(),
                },
                &a,
            )
            .unwrap();
            let mut best = f64::NEG_INFINITY;
            for k in 0..20000 {
                let th = k as f64 * std::f64::consts::TAU / 20000.0;
                let dir = [th.cos(), th.sin()];
                let r = 1.0 / Q.quad_form(&dir).sqrt();
                best = best.max(a[0] * (c[0] + r * dir[0]) + a[1] * (c[1] + r * dir[1]));
            }
            assert!(
                s >= best - 1e-12 && s <= best + 1e-4 * (1.0 + best.abs()),
                "support {s} vs sampled {best}"
            );
        }
    }

    #[test]
    fn interior_of_polytopes() {
        let P = |data: Vec<f64>, b: Vec<f64>| Shape::Polytope {
            A: Matrix {
                rows: b.len(),
                cols: 2,
                data,
            },
            b,
        };
        // Triangle: interior.
        assert_eq!(
            no_interior(&P(
                vec![-1.0, 0.0, 0.0, -1.0, 1.0, 1.0],
                vec![0.0, 0.0, 1.0]
            )),
            None
        );
        // Half-plane: interior (unbounded is fine).
        assert_eq!(no_interior(&P(vec![1.0, 0.0], vec![0.0])), None);
        // A line x1 = 0.5: no interior.
        assert!(no_interior(&P(vec![1.0, 0.0, -1.0, 0.0], vec![0.5, -0.5])).is_some());
        // Empty.
        assert!(no_interior(&P(vec![1.0, 0.0, -1.0, 0.0], vec![0.0, -1.0])).is_some());
        // Zero row with negative b.
        assert!(no_interior(&P(vec![0.0, 0.0], vec![-1.0])).is_some());
        // Thin but open slab of width 1e-3: interior.
        assert_eq!(
            no_interior(&P(vec![1.0, 0.0, -1.0, 0.0], vec![1e-3, 0.0])),
            None
        );
        assert!(no_interior(&Shape::Box {
            lo: vec![0.0, 1.0],
            hi: vec![1.0, 1.0]
        })
        .is_some());
        assert!(no_interior(&Shape::Ball {
            center: vec![0.0],
            radius: 0.0
        })
        .is_some());
    }

    #[test]
    fn eigen_decomposition_reconstructs() {
        let mut rng = ChaCha8Rng::seed_from_u64(15);
        let Q = rand_psd(&mut rng, 4, 1.0);
        let (lam, V) = sym_eigen(&Q).unwrap();
        assert!(lam.windows(2).all(|w| w[0] <= w[1]));
        for i in 0..4 {
            for j in 0..4 {
                let r: f64 = (0..4).map(|k| V.get(i, k) * lam[k] * V.get(j, k)).sum();
                assert!((r - Q.get(i, j)).abs() < 1e-12);
            }
        }
    }
}
