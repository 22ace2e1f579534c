//! A small front end for clarabel: affine matrix inequalities F(x) = F₀ + Σᵥ xᵥ Fᵥ ⪰ 0 turned into
//! `PSDTriangleConeT` rows, plus non-negativity rows and a (diagonal) quadratic objective.
//!
//! Clarabel's standard form is `min ½xᵀPx + qᵀx  s.t.  s = b − A x ∈ K`. For a PSD cone of size k the slack
//! is the vectorised matrix: the upper triangle taken column by column ((0,0), (0,1), (1,1), (0,2), …),
//! with every off-diagonal entry multiplied by √2 so that the Euclidean inner product of two vectors equals
//! the trace inner product of the matrices (clarabel's `mat_to_svec`/`svec_to_mat`). Hence
//! `b = svec(F₀)` and column v of A is `−svec(Fᵥ)`.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use faer::Mat;

use crate::solver::SetupError;

/// The vectorisation clarabel's PSD triangle cone uses (see the module docs).
pub(crate) fn svec(M: &Mat<f64>) -> Vec<f64> {
    let k = M.nrows();
    let mut out = Vec::with_capacity(k * (k + 1) / 2);
    for j in 0..k {
        for i in 0..=j {
            out.push(if i == j {
                M[(i, j)]
            } else {
                std::f64::consts::SQRT_2 * 0.5 * (M[(i, j)] + M[(j, i)])
            });
        }
    }
    out
}

/// An SDP under construction.
pub(crate) struct Sdp {
    nvars: usize,
    rows: Vec<usize>,
    cols: Vec<usize>,
    vals: Vec<f64>,
    b: Vec<f64>,
    cones: Vec<SupportedConeT<f64>>,
    q: Vec<f64>,
    quad: Vec<f64>,
}

/// What came back from clarabel.
pub(crate) struct SdpResult {
    pub status: SolverStatus,
    pub x: Vec<f64>,
    pub iterations: u32,
}

impl Sdp {
    pub fn new(nvars: usize) -> Self {
        Self {
            nvars,
            rows: vec![],
            cols: vec![],
            vals: vec![],
            b: vec![],
            cones: vec![],
            q: vec![0.0; nvars],
            quad: vec![0.0; nvars],
        }
    }

    /// Add `F₀ + L(x) ⪰ 0` (size k), where `lin` evaluates the linear part L at a point; it is probed at the
    /// unit vectors, so it must be linear (no constant term).
    pub fn add_lmi(&mut self, constant: &Mat<f64>, lin: impl Fn(&[f64]) -> Mat<f64>) {
        let k = constant.nrows();
        if k == 0 {
            return;
        }
        let row0 = self.b.len();
        self.b.extend(svec(constant));
        let mut e = vec![0.0; self.nvars];
        for v in 0..self.nvars {
            e[v] = 1.0;
            let Fv = lin(&e);
            e[v] = 0.0;
            for (r, val) in svec(&Fv).into_iter().enumerate() {
                if val != 0.0 {
                    self.rows.push(row0 + r);
                    self.cols.push(v);
                    self.vals.push(-val);
                }
            }
        }
        self.cones.push(SupportedConeT::PSDTriangleConeT(k));
    }

    /// Add `x_v ≥ lower`.
    pub fn add_lower_bound(&mut self, v: usize, lower: f64) {
        // s = −lower + x_v ≥ 0, i.e. b = −lower and A[row, v] = −1.
        self.rows.push(self.b.len());
        self.cols.push(v);
        self.vals.push(-1.0);
        self.b.push(-lower);
        self.cones.push(SupportedConeT::NonnegativeConeT(1));
    }

    /// Add `Σ a_v x_v ≤ rhs` (terms as (v, a_v)).
    pub fn add_linear_le(&mut self, terms: &[(usize, f64)], rhs: f64) {
        // s = rhs − aᵀx ≥ 0: b = rhs and A[row, v] = a_v.
        let row = self.b.len();
        for &(v, a) in terms {
            if a != 0.0 {
                self.rows.push(row);
                self.cols.push(v);
                self.vals.push(a);
            }
        }
        self.b.push(rhs);
        self.cones.push(SupportedConeT::NonnegativeConeT(1));
    }

    /// Add `c · x_v` to the objective.
    pub fn add_linear_cost(&mut self, v: usize, c: f64) {
        self.q[v] += c;
    }

    /// Add `½ w x_v²` to the objective.
    pub fn add_square_cost(&mut self, v: usize, w: f64) {
        self.quad[v] += w;
    }

    /// Solves the program; clarabel's refusal to set it up is an error, anything after that (including
    /// infeasibility) is the status in the result.
    pub fn solve(self, settings: DefaultSettings<f64>) -> Result<SdpResult, SetupError> {
        let m = self.b.len();
        let A = CscMatrix::new_from_triplets(m, self.nvars, self.rows, self.cols, self.vals);
        let mut pi = vec![];
        let mut pv = vec![];
        for v in 0..self.nvars {
            if self.quad[v] != 0.0 {
                pi.push(v);
                pv.push(self.quad[v]);
            }
        }
        let P = CscMatrix::new_from_triplets(self.nvars, self.nvars, pi.clone(), pi, pv);
        let mut solver = DefaultSolver::new(&P, &self.q, &A, &self.b, &self.cones, settings)?;
        solver.solve();
        Ok(SdpResult {
            status: solver.solution.status,
            x: solver.solution.x.clone(),
            iterations: solver.info.iterations,
        })
    }
}

/// Variables of a symmetric n×n matrix: one per upper-triangular entry (i ≤ j), column by column.
pub(crate) fn sym_index(i: usize, j: usize) -> usize {
    let (i, j) = if i <= j { (i, j) } else { (j, i) };
    j * (j + 1) / 2 + i
}

/// The symmetric matrix whose upper-triangular entries start at `x[offset]` (layout of [`sym_index`]).
pub(crate) fn sym_from(x: &[f64], offset: usize, n: usize) -> Mat<f64> {
    Mat::from_fn(n, n, |i, j| x[offset + sym_index(i, j)])
}

/// The m×n matrix stored row by row from `x[offset]`.
pub(crate) fn rect_from(x: &[f64], offset: usize, m: usize, n: usize) -> Mat<f64> {
    Mat::from_fn(m, n, |i, j| x[offset + i * n + j])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> DefaultSettings<f64> {
        clarabel::solver::DefaultSettingsBuilder::default()
            .verbose(false)
            .build()
            .unwrap()
    }

    #[test]
    fn svec_matches_clarabel_convention() {
        // maximise x subject to [[2, x], [x, 1/2]] ⪰ 0: the optimum is x = 1 (det = 0). A wrong off-diagonal
        // scaling (no √2, or √2 twice) would move it to √2 or 1/√2.
        let mut sdp = Sdp::new(1);
        let c = Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) => 2.0,
            (1, 1) => 0.5,
            _ => 0.0,
        });
        sdp.add_lmi(&c, |x| {
            Mat::from_fn(2, 2, |i, j| if i != j { x[0] } else { 0.0 })
        });
        sdp.add_linear_cost(0, -1.0);
        let r = sdp.solve(settings()).unwrap();
        assert_eq!(r.status, SolverStatus::Solved);
        assert!((r.x[0] - 1.0).abs() < 1e-6, "x = {}", r.x[0]);
    }

    #[test]
    fn upper_triangle_is_taken_column_by_column() {
        // 3×3: fix the (0,2) entry through one variable and the (1,1) entry through another; only the right
        // ordering gives λ_min = 0 at the optimum with x0 = 2, x1 = 4 (minimise x1 − x0 s.t. x0 ≤ 2 and
        // [[1, 0, x0], [0, x1, 0], [x0, 0, 4]] ⪰ 0, i.e. x0² ≤ 4, x1 ≥ 0 → x0 = 2, x1 = 0).
        let mut sdp = Sdp::new(2);
        let c = Mat::from_fn(3, 3, |i, j| match (i, j) {
            (0, 0) => 1.0,
            (2, 2) => 4.0,
            _ => 0.0,
        });
        sdp.add_lmi(&c, |x| {
            let mut m = Mat::zeros(3, 3);
            m[(0, 2)] = x[0];
            m[(2, 0)] = x[0];
            m[(1, 1)] = x[1];
            m
        });
        sdp.add_linear_cost(0, -1.0);
        sdp.add_linear_cost(1, 1.0);
        let r = sdp.solve(settings()).unwrap();
        assert_eq!(r.status, SolverStatus::Solved);
        assert!(
            (r.x[0] - 2.0).abs() < 1e-6 && r.x[1].abs() < 1e-6,
            "x = {:?}",
            r.x
        );
    }

    #[test]
    fn sym_layout_round_trips() {
        let n = 4;
        let x: Vec<f64> = (0..n * (n + 1) / 2).map(|k| k as f64).collect();
        let Q = sym_from(&x, 0, n);
        for j in 0..n {
            for i in 0..n {
                assert_eq!(Q[(i, j)], Q[(j, i)]);
                assert_eq!(Q[(i, j)], x[sym_index(i, j)]);
            }
        }
        assert_eq!(sym_index(0, 0), 0);
        assert_eq!(sym_index(0, 1), 1);
        assert_eq!(sym_index(1, 1), 2);
        assert_eq!(sym_index(2, 0), 3);
    }
}
