//! Small dense linear algebra for the geometry module: input validation of vectors and symmetric matrices,
//! symmetric eigendecompositions through faer (row-major in, row-major out, sequential), pseudo-inverses and
//! matrix–vector products. Everything here works on row-major `&[f64]` so that the rest of the module never
//! touches faer types.

use super::GeometryError;
use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{self_adjoint_evd, self_adjoint_evd_scratch, ComputeEigenvectors};
use faer::{Mat, Par};

/// Relative tolerance for symmetry checks of user-supplied matrices: |Aᵢⱼ − Aⱼᵢ| ≤ tol · max(1, maxₖₗ |Aₖₗ|).
pub(crate) const SYMMETRY_TOL: f64 = 1e-9;
/// Relative tolerance below which a negative eigenvalue is accepted as rounding of a PSD matrix.
pub(crate) const PSD_TOL: f64 = 1e-10;
/// Relative threshold (to the largest eigenvalue) below which an eigenvalue counts as zero when a rank or a
/// null space is needed.
pub(crate) const RANK_TOL: f64 = 1e-13;

/// Check that `v` has `expected` entries, all finite.
pub(crate) fn check_vector(
    what: &'static str,
    v: &[f64],
    expected: usize,
) -> Result<(), GeometryError> {
    if v.len() != expected {
        return Err(GeometryError::Dimension {
            what,
            expected,
            got: v.len(),
        });
    }
    check_finite(what, v)
}

/// Check that every entry of `v` is finite.
pub(crate) fn check_finite(what: &'static str, v: &[f64]) -> Result<(), GeometryError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(GeometryError::NotFinite {
            what,
            index,
            value: v[index],
        }),
        None => Ok(()),
    }
}

/// Largest absolute entry.
pub(crate) fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0_f64, |m, x| m.max(x.abs()))
}

/// Validate a row-major n×n matrix as symmetric and finite; return its symmetrised copy ½(A + Aᵀ).
pub(crate) fn symmetrize_checked(
    what: &'static str,
    n: usize,
    A: &[f64],
) -> Result<Vec<f64>, GeometryError> {
    check_vector(what, A, n * n)?;
    let scale = max_abs(A).max(1.0);
    let mut S = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            let (a, b) = (A[i * n + j], A[j * n + i]);
            if (a - b).abs() > SYMMETRY_TOL * scale {
                return Err(GeometryError::NotSymmetric { what, i, j, a, b });
            }
            S[i * n + j] = 0.5 * (a + b);
        }
    }
    Ok(S)
}

/// Symmetric eigendecomposition A = V diag(values) Vᵀ with eigenvalues in ascending order.
#[derive(Clone, Debug)]
pub(crate) struct SymEig {
    pub n: usize,
    /// Ascending.
    pub values: Vec<f64>,
    /// Row-major n×n; column j is the unit eigenvector of `values[j]`.
    pub vectors: Vec<f64>,
}

impl SymEig {
    /// Eigendecomposition of the symmetric part of the row-major n×n matrix `A` (assumed finite).
    pub fn new(what: &'static str, n: usize, A: &[f64]) -> Result<Self, GeometryError> {
        debug_assert_eq!(A.len(), n * n);
        if n == 0 {
            return Ok(Self {
                n,
                values: vec![],
                vectors: vec![],
            });
        }
        let M = Mat::<f64>::from_fn(n, n, |i, j| 0.5 * (A[i * n + j] + A[j * n + i]));
        let mut U = Mat::<f64>::zeros(n, n);
        let mut S = Diag::<f64>::zeros(n);
        let mut buf = MemBuffer::new(self_adjoint_evd_scratch::<f64>(
            n,
            ComputeEigenvectors::Yes,
            Par::Seq,
            Default::default(),
        ));
        self_adjoint_evd(
            M.as_ref(),
            S.as_mut(),
            Some(U.as_mut()),
            Par::Seq,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|_| GeometryError::EigenNoConvergence { what })?;
        let s = S.column_vector();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| s[a].total_cmp(&s[b]));
        let values: Vec<f64> = order.iter().map(|&k| s[k]).collect();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(GeometryError::EigenNoConvergence { what });
        }
        let mut vectors = vec![0.0; n * n];
        for (j, &k) in order.iter().enumerate() {
            for i in 0..n {
                vectors[i * n + j] = U[(i, k)];
            }
        }
        Ok(Self { n, values, vectors })
    }

    /// Largest eigenvalue (0 for n = 0).
    pub fn max(&self) -> f64 {
        self.values.last().copied().unwrap_or(0.0)
    }

    /// Smallest eigenvalue (0 for n = 0).
    pub fn min(&self) -> f64 {
        self.values.first().copied().unwrap_or(0.0)
    }

    /// Column j (an eigenvector) as a new vector.
    pub fn vector(&self, j: usize) -> Vec<f64> {
        (0..self.n).map(|i| self.vectors[i * self.n + j]).collect()
    }

    /// Threshold under which eigenvalues count as zero: `RANK_TOL · max(|λ|)`.
    pub fn zero_threshold(&self) -> f64 {
        let big = self.values.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        RANK_TOL * big
    }

    /// Check positive semidefiniteness up to rounding (`λ_min ≥ −PSD_TOL · max|λ|`).
    pub fn check_psd(&self, what: &'static str) -> Result<(), GeometryError> {
        let big = self.values.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        if self.min() < -PSD_TOL * big {
            return Err(GeometryError::NotPsd {
                what,
                min_eigenvalue: self.min(),
            });
        }
        Ok(())
    }

    /// Moore–Penrose pseudo-inverse, eigenvalues under `zero_threshold()` dropped. Row-major n×n.
    pub fn pinv(&self) -> Vec<f64> {
        let n = self.n;
        let tol = self.zero_threshold();
        let mut P = vec![0.0; n * n];
        for k in 0..n {
            let l = self.values[k];
            if l.abs() <= tol || l == 0.0 {
                continue;
            }
            for i in 0..n {
                let vi = self.vectors[i * n + k] / l;
                for j in 0..n {
                    P[i * n + j] += vi * self.vectors[j * n + k];
                }
            }
        }
        P
    }

    /// Orthonormal basis of the numerical null space (eigenvalues with |λ| ≤ `zero_threshold()`), as columns of
    /// a row-major n×k matrix; returns (basis, k).
    pub fn null_basis(&self) -> (Vec<f64>, usize) {
        let n = self.n;
        let tol = self.zero_threshold();
        let idx: Vec<usize> = (0..n).filter(|&k| self.values[k].abs() <= tol).collect();
        let k = idx.len();
        let mut B = vec![0.0; n * k];
        for (c, &j) in idx.iter().enumerate() {
            for i in 0..n {
                B[i * k + c] = self.vectors[i * n + j];
            }
        }
        (B, k)
    }
}

/// y = A x for row-major A (m×n).
#[inline]
pub(crate) fn matvec(A: &[f64], m: usize, n: usize, x: &[f64], y: &mut [f64]) {
    for i in 0..m {
        let row = &A[i * n..(i + 1) * n];
        let mut s = 0.0;
        for j in 0..n {
            s += row[j] * x[j];
        }
        y[i] = s;
    }
}

/// C = A B for row-major A (m×k), B (k×n).
pub(crate) fn matmul(A: &[f64], B: &[f64], m: usize, k: usize, n: usize) -> Vec<f64> {
    let mut C = vec![0.0; m * n];
    for i in 0..m {
        for l in 0..k {
            let a = A[i * k + l];
            if a == 0.0 {
                continue;
            }
            for j in 0..n {
                C[i * n + j] += a * B[l * n + j];
            }
        }
    }
    C
}

/// Aᵀ for row-major A (m×n), result n×m.
pub(crate) fn transpose(A: &[f64], m: usize, n: usize) -> Vec<f64> {
    let mut T = vec![0.0; m * n];
    for i in 0..m {
        for j in 0..n {
            T[j * m + i] = A[i * n + j];
        }
    }
    T
}

/// Quadratic form vᵀ A v for row-major n×n A.
#[inline]
pub(crate) fn quad_form(A: &[f64], v: &[f64]) -> f64 {
    let n = v.len();
    let mut s = 0.0;
    for i in 0..n {
        let mut r = 0.0;
        for j in 0..n {
            r += A[i * n + j] * v[j];
        }
        s += v[i] * r;
    }
    s
}

/// (x − c)ᵀ A (x − c) without allocating.
#[inline]
pub(crate) fn quad_form_shifted(A: &[f64], x: &[f64], c: &[f64]) -> f64 {
    let n = x.len();
    let mut s = 0.0;
    for i in 0..n {
        let mut r = 0.0;
        for j in 0..n {
            r += A[i * n + j] * (x[j] - c[j]);
        }
        s += (x[i] - c[i]) * r;
    }
    s
}

/// Dot product.
#[inline]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Smallest root t ≥ 0 of a t² + 2 b t + c = 0 (c ≤ 0 guarantees one when a > 0), computed without
/// cancellation; `None` when there is no nonnegative root.
pub(crate) fn smallest_nonneg_root(a: f64, b: f64, c: f64) -> Option<f64> {
    if c == 0.0 {
        return Some(0.0);
    }
    if a == 0.0 {
        if b == 0.0 {
            return None;
        }
        let t = -c / (2.0 * b);
        return (t >= 0.0).then_some(t);
    }
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let sq = disc.sqrt();
    // Roots are (−b ± sq)/a; use the product c/a for the one that cancels.
    let q = -(b + b.signum() * sq);
    let (r1, r2) = if q == 0.0 { (0.0, 0.0) } else { (q / a, c / q) };
    let (lo, hi) = if r1 <= r2 { (r1, r2) } else { (r2, r1) };
    if lo >= 0.0 {
        Some(lo)
    } else if hi >= 0.0 {
        Some(hi)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eig_reconstructs_and_sorts() {
        let A = [4.0, 1.0, 0.0, 1.0, 3.0, 0.5, 0.0, 0.5, 1.0];
        let e = SymEig::new("A", 3, &A).unwrap();
        assert!(e.values.windows(2).all(|w| w[0] <= w[1]));
        for i in 0..3 {
            for j in 0..3 {
                let r: f64 = (0..3)
                    .map(|k| e.vectors[i * 3 + k] * e.values[k] * e.vectors[j * 3 + k])
                    .sum();
                assert!(
                    (r - A[i * 3 + j]).abs() < 1e-13,
                    "({i},{j}): {r} vs {}",
                    A[i * 3 + j]
                );
            }
        }
    }

    #[test]
    fn pinv_and_null_space_of_singular_matrix() {
        // A = v vᵀ with v = (1, 2, 2)/3: rank one.
        let v = [1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0];
        let A: Vec<f64> = (0..9).map(|k| v[k / 3] * v[k % 3]).collect();
        let e = SymEig::new("A", 3, &A).unwrap();
        let (N, k) = e.null_basis();
        assert_eq!(k, 2);
        for c in 0..k {
            let col: Vec<f64> = (0..3).map(|i| N[i * k + c]).collect();
            assert!(dot(&col, &v).abs() < 1e-14);
        }
        // A⁺ = A for an orthogonal projector.
        let P = e.pinv();
        for (p, a) in P.iter().zip(&A) {
            assert!((p - a).abs() < 1e-13);
        }
    }

    #[test]
    fn roots_without_cancellation() {
        // t² − 2·1e8 t + 1 = 0: small root ≈ 5e-9.
        let t = smallest_nonneg_root(1.0, -1e8, 1.0).unwrap();
        assert!((t - 5e-9).abs() < 1e-20);
        // t² + 2t − 3 = 0: roots 1 and −3.
        assert_eq!(smallest_nonneg_root(1.0, 1.0, -3.0), Some(1.0));
        assert_eq!(smallest_nonneg_root(1.0, 1.0, 3.0), None);
    }

    #[test]
    fn rejects_asymmetric_and_nonfinite() {
        assert!(matches!(
            symmetrize_checked("Q", 2, &[1.0, 0.5, 0.0, 1.0]),
            Err(GeometryError::NotSymmetric { .. })
        ));
        assert!(matches!(
            symmetrize_checked("Q", 2, &[1.0, f64::NAN, f64::NAN, 1.0]),
            Err(GeometryError::NotFinite { .. })
        ));
        assert!(matches!(
            symmetrize_checked("Q", 2, &[1.0]),
            Err(GeometryError::Dimension { .. })
        ));
    }
}
