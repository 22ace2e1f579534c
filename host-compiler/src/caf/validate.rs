//! Independent check of a (K, P) pair, computed with faer from the matrices alone, so that an inaccurate
//! solver answer cannot become a certificate: the eigenvalues of P and of the decrease matrix
//! `P − ÃᵀPÃ` (discrete, (3.65)) or `−(ÃᵀP + PÃ)` (continuous, (3.7)), with Ã = A + BK.
//!
//! The reported bounds are made conservative by a rounding guard: the decrease matrix is formed in f64 and
//! its eigenvalues computed by a backward-stable method, so each computed eigenvalue is within
//! c·n·ε·‖M‖ of the exact one for a matrix within c'·(n+m)·ε·‖P‖(1+‖Ã‖)² of the exact decrease matrix
//! (Weyl's inequality). The guard `16 (n + m + 2) ε ‖P‖_F (1 + ‖A‖_F + ‖B‖_F ‖K‖_F)²` dominates both terms;
//! it is subtracted from every lower bound and added to every upper bound.

use super::TimeKind;
use faer::{Mat, MatRef, Side};

/// Validated facts about one (K, P).
#[derive(Clone, Debug, PartialEq)]
pub struct Certificate {
    /// Lower bound on λ_min(P).
    pub lambda_min_P: f64,
    /// Upper bound on λ_max(P).
    pub lambda_max_P: f64,
    /// Upper bound on the condition number λ_max(P)/λ_min(P).
    pub condition: f64,
    /// Lower bound on σ_min of the decrease matrix (= its smallest eigenvalue when positive): the σ of
    /// Theorem 3.21 / Remark 3.22 in discrete time.
    pub margin: f64,
    /// Per-step bound on ψ(x⁺, x'⁺)/ψ(x, x') in discrete time, `√(1 − margin/λ_max(P))`; in continuous time the
    /// exponential decay rate of ψ, `margin / (2 λ_max(P))`. Only meaningful when `margin > 0`.
    pub contraction: f64,
    /// The rounding guard used (see the module docs).
    pub guard: f64,
}

fn sym_eigs(M: &Mat<f64>) -> Option<Vec<f64>> {
    let n = M.nrows();
    if (0..n).any(|j| (0..n).any(|i| !M[(i, j)].is_finite())) {
        return None;
    }
    let S = Mat::from_fn(n, n, |i, j| 0.5 * (M[(i, j)] + M[(j, i)]));
    S.self_adjoint_eigenvalues(Side::Lower).ok()
}

/// Measure (K, P) for the plant (A, B). `None` when something is non-finite or an eigenvalue computation
/// fails (then nothing can be certified).
pub fn certify(
    time: TimeKind,
    A: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    K: MatRef<'_, f64>,
    P: MatRef<'_, f64>,
) -> Option<Certificate> {
    let (n, m) = (A.nrows(), B.ncols());
    if n == 0 || P.nrows() != n || P.ncols() != n || K.nrows() != m || K.ncols() != n {
        return None;
    }
    let At = A + B * K;
    let P = P.to_owned();
    let D = match time {
        TimeKind::Discrete => &P - At.transpose() * &P * &At,
        TimeKind::Continuous => {
            let AtP = At.transpose() * &P;
            Mat::from_fn(n, n, |i, j| -(AtP[(i, j)] + AtP[(j, i)]))
        }
    };
    let ep = sym_eigs(&P)?;
    let ed = sym_eigs(&D)?;
    let eps = f64::EPSILON;
    let scale = 1.0 + A.norm_l2() + B.norm_l2() * K.norm_l2();
    let guard = 16.0 * (n + m + 2) as f64 * eps * P.norm_l2() * scale * scale;
    let lmin = ep[0] - guard;
    let lmax = ep[n - 1] + guard;
    let margin = ed[0] - guard;
    let condition = if lmin > 0.0 {
        lmax / lmin
    } else {
        f64::INFINITY
    };
    let contraction = match time {
        TimeKind::Discrete => (1.0 - margin / lmax).clamp(0.0, f64::INFINITY).sqrt(),
        TimeKind::Continuous => margin / (2.0 * lmax),
    };
    Some(Certificate {
        lambda_min_P: lmin,
        lambda_max_P: lmax,
        condition,
        margin,
        contraction,
        guard,
    })
}
