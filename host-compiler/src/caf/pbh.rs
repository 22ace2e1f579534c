//! Stabilizability by the Popov–Belevitch–Hautus test: a mode λ of A is uncontrollable exactly when
//! `[λI − A, B]` loses row rank, i.e. when some w ≠ 0 has `w* A = λ w*` and `w* B = 0`. No feedback moves such
//! a mode (w* (A + BK) = λ w* for every K), so the pair is stabilizable iff no uncontrollable mode lies in the
//! closed unstable region (|λ| ≥ 1 in discrete time, Re λ ≥ 0 in continuous time).
//!
//! Numerically the rank test is `σ_min([λI − A, B]) ≤ tol`; the left singular vector of that singular value is
//! the certificate w (it satisfies ‖w* [λI − A, B]‖ = σ_min). Using the SVD rather than eigenvectors handles
//! repeated eigenvalues with several independent left eigenvectors.

use super::CafError;
use faer::{c64, Mat, MatRef};

/// One uncontrollable mode: the eigenvalue and a unit left eigenvector w with w* B ≈ 0.
#[derive(Clone, Debug, PartialEq)]
pub struct UncontrollableMode {
    pub eigenvalue: c64,
    pub left_eigenvector: Vec<c64>,
    /// σ_min([λI − A, B]) = ‖w* [λI − A, B]‖₂, the residual of the certificate.
    pub residual: f64,
}

/// A complex number for people: `a`, or `a ± bi` when its imaginary part is not negligible.
fn complex(z: c64) -> String {
    if z.im.abs() <= 1e-12 * z.re.abs().max(1.0) {
        format!("{:.6}", z.re)
    } else {
        format!(
            "{:.6} {} {:.6}i",
            z.re,
            if z.im < 0.0 { '-' } else { '+' },
            z.im.abs()
        )
    }
}

/// For people: the eigenvalue and its left eigenvector, and what that means for the spec.
impl std::fmt::Display for UncontrollableMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let w: Vec<String> = self.left_eigenvector.iter().map(|&z| complex(z)).collect();
        write!(
            f,
            "the mode with eigenvalue λ = {} (|λ| = {:.6}) of the sampled A has left eigenvector \
             w = ({}) with w*B ≈ 0 (residual {:.1e}): no input reaches it (check plant.A and plant.B)",
            complex(self.eigenvalue),
            self.eigenvalue.norm(),
            w.join(", "),
            self.residual
        )
    }
}

/// Every eigenvalue λ of A for which `σ_min([λI − A, B]) ≤ tol · max(1, ‖[A B]‖_F)`, with its certificate.
/// Eigenvalues closer than that tolerance to one already reported are not repeated.
pub fn uncontrollable_modes(
    A: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    tol: f64,
) -> Result<Vec<UncontrollableMode>, CafError> {
    let n = A.nrows();
    let m = B.ncols();
    if n == 0 {
        return Ok(vec![]);
    }
    let scale = (A.squared_norm_l2() + B.squared_norm_l2()).sqrt().max(1.0);
    let threshold = tol * scale;
    let eigenvalues = A.eigenvalues().map_err(|_| CafError::NonFinite {
        what: "A (eigenvalues did not converge)",
    })?;
    let mut out: Vec<UncontrollableMode> = Vec::new();
    for lam in eigenvalues {
        if out.iter().any(|u| (u.eigenvalue - lam).norm() <= threshold) {
            continue;
        }
        let M = Mat::<c64>::from_fn(n, n + m, |i, j| {
            if j < n {
                let d = if i == j { lam } else { c64::new(0.0, 0.0) };
                d - c64::new(A[(i, j)], 0.0)
            } else {
                c64::new(B[(i, j - n)], 0.0)
            }
        });
        let svd = M.thin_svd().map_err(|_| CafError::NonFinite {
            what: "[λI − A, B] (SVD did not converge)",
        })?;
        let s = svd.S().column_vector();
        let k = s.nrows() - 1;
        let smin = s[k].re;
        if smin <= threshold {
            let U = svd.U();
            out.push(UncontrollableMode {
                eigenvalue: lam,
                left_eigenvector: (0..n).map(|i| U[(i, k)]).collect(),
                residual: smin,
            });
        }
    }
    Ok(out)
}
