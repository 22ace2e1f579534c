//! Small dense linear-algebra helpers on faer matrices used across synthesis and certification:
//! conversions, PSD square roots, spectral and P-induced norms.

use faer::{Mat, MatRef, Side};

/// A row-major slice (r×c) as a faer matrix.
pub fn from_row_major(r: usize, c: usize, data: &[f64]) -> Mat<f64> {
    Mat::from_fn(r, c, |i, j| data[i * c + j])
}

/// Rows of a faer matrix (row-major `Vec<Vec<f64>>`).
pub fn to_rows(m: MatRef<'_, f64>) -> Vec<Vec<f64>> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
        .collect()
}

/// Row-major flattening.
pub fn to_row_major(m: MatRef<'_, f64>) -> Vec<f64> {
    to_rows(m).concat()
}

/// y = M x.
pub fn mat_vec(m: MatRef<'_, f64>, x: &[f64]) -> Vec<f64> {
    (0..m.nrows())
        .map(|i| (0..m.ncols()).map(|j| m[(i, j)] * x[j]).sum())
        .collect()
}

/// Symmetrise (M + Mᵀ)/2.
pub fn sym(m: MatRef<'_, f64>) -> Mat<f64> {
    Mat::from_fn(m.nrows(), m.ncols(), |i, j| 0.5 * (m[(i, j)] + m[(j, i)]))
}

/// Eigenvalues (ascending) of a symmetric matrix; `None` if the decomposition fails.
pub fn sym_eigenvalues(m: MatRef<'_, f64>) -> Option<Vec<f64>> {
    sym(m).self_adjoint_eigenvalues(Side::Lower).ok()
}

/// f(M) for symmetric M via its eigendecomposition, applying `f` to each eigenvalue.
pub fn sym_fn(m: MatRef<'_, f64>, f: impl Fn(f64) -> f64) -> Option<Mat<f64>> {
    let s = sym(m);
    let evd = s.self_adjoint_eigen(Side::Lower).ok()?;
    let U = evd.U();
    let S = evd.S();
    let n = s.nrows();
    let d: Vec<f64> = (0..n).map(|k| f(S[k])).collect();
    Some(Mat::from_fn(n, n, |i, j| {
        (0..n).map(|k| U[(i, k)] * d[k] * U[(j, k)]).sum()
    }))
}

/// Largest singular value ‖M‖₂.
pub fn spectral_norm(m: MatRef<'_, f64>) -> f64 {
    if m.nrows() == 0 || m.ncols() == 0 {
        return 0.0;
    }
    m.singular_values()
        .ok()
        .and_then(|s| s.first().copied())
        .unwrap_or(f64::INFINITY)
}

/// The square root and inverse square root of a positive definite P.
#[derive(Clone, Debug)]
pub struct PdRoots {
    pub sqrt: Mat<f64>,
    pub inv_sqrt: Mat<f64>,
    pub inv: Mat<f64>,
}

impl PdRoots {
    /// `None` if P is not positive definite.
    pub fn new(P: MatRef<'_, f64>) -> Option<Self> {
        let ev = sym_eigenvalues(P)?;
        if ev.first().copied().unwrap_or(0.0) <= 0.0 {
            return None;
        }
        Some(Self {
            sqrt: sym_fn(P, f64::sqrt)?,
            inv_sqrt: sym_fn(P, |l| 1.0 / l.sqrt())?,
            inv: sym_fn(P, |l| 1.0 / l)?,
        })
    }

    /// ‖M‖ induced by ‖·‖_P on both sides: ‖P^{1/2} M P^{-1/2}‖₂.
    pub fn induced_norm(&self, M: MatRef<'_, f64>) -> f64 {
        spectral_norm((&self.sqrt * M * &self.inv_sqrt).as_ref())
    }

    /// ‖M‖ from the Euclidean norm to ‖·‖_P: ‖P^{1/2} M‖₂.
    pub fn norm_into(&self, M: MatRef<'_, f64>) -> f64 {
        spectral_norm((&self.sqrt * M).as_ref())
    }

    /// ‖M‖ from ‖·‖_P to the Euclidean norm: ‖M P^{-1/2}‖₂ (the largest value of ‖M e‖ over ‖e‖_P ≤ 1).
    pub fn norm_from(&self, M: MatRef<'_, f64>) -> f64 {
        spectral_norm((M * &self.inv_sqrt).as_ref())
    }

    /// ‖a‖_{P⁻¹} = max { aᵀe : ‖e‖_P ≤ 1 }.
    pub fn dual_norm(&self, a: &[f64]) -> f64 {
        let n = a.len();
        let mut s = 0.0;
        for i in 0..n {
            for j in 0..n {
                s += a[i] * self.inv[(i, j)] * a[j];
            }
        }
        s.max(0.0).sqrt()
    }
}

/// ‖x‖_P = sqrt(xᵀ P x).
pub fn p_norm(P: MatRef<'_, f64>, x: &[f64]) -> f64 {
    let n = x.len();
    let mut s = 0.0;
    for i in 0..n {
        for j in 0..n {
            s += x[i] * P[(i, j)] * x[j];
        }
    }
    s.max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_and_norms_of_a_diagonal_metric() {
        let P = from_row_major(2, 2, &[4.0, 0.0, 0.0, 1.0]);
        let r = PdRoots::new(P.as_ref()).unwrap();
        assert!((r.sqrt[(0, 0)] - 2.0).abs() < 1e-12);
        assert!((r.inv_sqrt[(0, 0)] - 0.5).abs() < 1e-12);
        // ‖e₁‖_{P⁻¹} = 1/2.
        assert!((r.dual_norm(&[1.0, 0.0]) - 0.5).abs() < 1e-12);
        // M = diag(1, 2): P^{1/2} M P^{-1/2} = M.
        let M = from_row_major(2, 2, &[1.0, 0.0, 0.0, 2.0]);
        assert!((r.induced_norm(M.as_ref()) - 2.0).abs() < 1e-12);
        assert!((p_norm(P.as_ref(), &[1.0, 1.0]) - 5f64.sqrt()).abs() < 1e-12);
        assert!(PdRoots::new(from_row_major(2, 2, &[1.0, 0.0, 0.0, -1.0]).as_ref()).is_none());
    }
}

/// f32 rounding (the values the image stores), widened back exactly.
pub fn round32(x: f64) -> f64 {
    x as f32 as f64
}
