//! Distance from a point to the boundary of a (possibly degenerate) ellipsoid in a (semi)norm, §7.2.
//!
//! Problem (7.2): minimise (x − x̄)ᵀR(x − x̄) subject to (x − x_c)ᵀQ(x − x_c) = 1, with R and Q symmetric
//! positive semidefinite. The same problem gives the distance from an outside point and the depth of an inside
//! point (the nonconvex case), because in both cases the nearest point of the other side lies on the boundary.
//!
//! What lives here:
//! - [`StandardForm`]: problem (7.5), min ‖z − z̄‖² s.t. zᵀΛz = 1 with Λ diagonal positive definite, solved by
//!   Algorithm 7: Theorem 7.6 decides between the unique optimum (7.24), found by the iteration of Lemma 7.9
//!   started at (7.45), and the set of optima (7.25)–(7.26), of which one point is returned.
//! - [`EllipsoidBoundaryDistance`]: the reduction of (7.2) to (7.5) (transformation (7.3)–(7.5) and the
//!   degenerate cases of §7.2.2), computed once per (x_c, Q, R) with eigendecompositions, after which every
//!   point costs two small matrix–vector products and a few scalar iterations (Remark 7.11). The per-point
//!   path ([`EllipsoidBoundaryDistance::solve`]) allocates nothing: it works in a [`BoundaryWorkspace`].
//!
//! Numerics: the secular function G (7.21) is evaluated in the shifted variable δ = µ − µ̄ = µ + 1/λmax, so the
//! factors µλᵢ + 1 = (1 − λᵢ/λmax) + δλᵢ are formed without cancellation near the pole µ̄ (the case of points
//! close to the multiple-optima set of Remark 7.7). The Lemma 7.9 iteration is kept inside a bracket
//! [δ_lo, δ_hi] known to contain the root and falls back to bisection if rounding ever pushes it out.
//! Every returned point is checked against the constraint in the original coordinates (n² flops); when the
//! reduction lost accuracy — an ill-conditioned standard form, whose small eigenvalues are only known to
//! ε·λmax, or a reconstruction through an ill-conditioned P₂₂⁺ — the point is refined by Newton's method on the
//! KKT system of (7.2) in the original coordinates (the pencil R + µQ of Remark 7.11), still without
//! allocating.

use super::linalg::{self, SymEig};
use super::{GeometryError, Metric};
use crate::settings::{settings_builder, Check, SettingError};

/// Relative size (to max |eig Q|) under which Q·V₂ counts as zero, V₂ spanning the null space of R: then the
/// null space of R lies in that of Q (P₂₂ = 0 and P₂₁ = 0 in (7.7)), and moving along it never reaches the
/// boundary.
const NULL_CONTAINMENT_TOL: f64 = 1e-12;
/// Relative gap under which eigenvalues of Λ are treated as equal to λmax (they join the multiplicity M).
const EQUAL_EIG_TOL: f64 = 1e-14;

/// Settings of the root iteration (Lemma 7.9), with documented defaults. Build with
/// [`BoundaryDistanceSettings::builder`] (validated) or take [`Default`];
/// [`EllipsoidBoundaryDistance::with_settings`] checks them again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundaryDistanceSettings {
    /// Stop when |G(µ)| ≤ tol, i.e. the returned point satisfies the (scaled) constraint to `tol`.
    /// Finite, > 0. Default 1e-14.
    pub tol: f64,
    /// Iteration cap (safeguard; the iteration converges quadratically). ≥ 1. Default 100.
    pub max_iter: u32,
}

impl Default for BoundaryDistanceSettings {
    fn default() -> Self {
        Self {
            tol: 1e-14,
            max_iter: 100,
        }
    }
}

impl BoundaryDistanceSettings {
    /// Checks the ranges documented on the fields; the first violation is returned.
    pub fn validate(&self) -> Result<(), SettingError> {
        let c = Check("BoundaryDistanceSettings");
        c.positive("tol", self.tol)?;
        c.at_least_one("max_iter", self.max_iter as usize)
    }
}

settings_builder!(
    BoundaryDistanceSettings,
    BoundaryDistanceSettingsBuilder {
        tol: f64,
        max_iter: u32,
    }
);

/// Which case of the analysis produced the optimum.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OptimumKind {
    /// Theorem 7.6, G(µ̄⁺) > 0: the unique optimum (7.24) at the root µ* > µ̄ (unique up to the free
    /// directions of §7.2.2 when R or Q is singular).
    Unique,
    /// Theorem 7.6, G(µ̄⁺) < 0: the optima form a sphere (7.25)–(7.26); one of them is returned.
    Multiple,
    /// §7.2.2 with R singular: the boundary is reached at zero cost by moving along the null space of R
    /// (ȳ₁ᵀSȳ₁ ≤ 1); the value is 0.
    ZeroCost,
}

/// Result of (7.5) for one z̄.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoreSolution {
    /// The optimal value ‖z* − z̄‖² of (7.5).
    pub value_sq: f64,
    /// The multiplier µ* of (7.19) (µ* = µ̄ = −1/λmax in the multiple-optima case). µ* < 0 for points inside
    /// the ellipsoid, > 0 outside.
    pub mu: f64,
    pub kind: OptimumKind,
    /// Iterations of Lemma 7.9 taken.
    pub iterations: u32,
}

/// Problem (7.5): minimise ‖z − z̄‖² subject to zᵀΛz = 1, Λ = diag(λ) positive definite, λ sorted descending
/// (Notation 7.1).
#[derive(Clone, Debug)]
pub struct StandardForm {
    /// λ₁ ≥ … ≥ λ_q > 0; the first M equal λmax.
    lambda: Vec<f64>,
    /// 1 − λᵢ/λmax (0 for i < M, > 0 after).
    gap: Vec<f64>,
    /// Multiplicity M of λmax.
    M: usize,
}

impl StandardForm {
    /// From the diagonal of Λ (any order, all positive and finite). Eigenvalues within a relative 1e-14 of the
    /// largest are set equal to it.
    pub fn new(mut lambda: Vec<f64>) -> Result<Self, GeometryError> {
        if lambda.is_empty() {
            return Err(GeometryError::ZeroDimension {
                what: "standard form Λ",
            });
        }
        linalg::check_finite("standard form Λ", &lambda)?;
        if let Some(&v) = lambda.iter().find(|&&v| v <= 0.0) {
            return Err(GeometryError::NotPositive {
                what: "standard form eigenvalue",
                value: v,
            });
        }
        lambda.sort_by(|a, b| b.total_cmp(a));
        let lmax = lambda[0];
        let M = lambda
            .iter()
            .take_while(|&&l| l >= lmax * (1.0 - EQUAL_EIG_TOL))
            .count();
        let mut gap = vec![0.0; lambda.len()];
        for i in 0..lambda.len() {
            if i < M {
                lambda[i] = lmax;
            } else {
                gap[i] = (lmax - lambda[i]) / lmax;
            }
        }
        Ok(Self { lambda, gap, M })
    }

    /// Dimension q.
    pub fn dim(&self) -> usize {
        self.lambda.len()
    }
    /// λ, descending.
    pub fn lambda(&self) -> &[f64] {
        &self.lambda
    }
    /// 1 − λᵢ/λmax for each i.
    pub fn gaps(&self) -> &[f64] {
        &self.gap
    }
    /// Multiplicity M of λmax (Notation 7.1).
    pub fn multiplicity(&self) -> usize {
        self.M
    }

    /// G and dG/dµ of (7.21)–(7.22) at µ = µ̄ + δ (δ ≥ 0). Terms with z̄ᵢ = 0 are skipped, so δ = 0 is allowed
    /// when z̄ vanishes on W (then G(µ̄⁺) is finite, Lemma 7.5).
    #[inline]
    pub fn secular(&self, zbar: &[f64], delta: f64) -> (f64, f64) {
        let mut G = -1.0;
        let mut dG = 0.0;
        for ((&l, &g), &zb) in self.lambda.iter().zip(&self.gap).zip(zbar) {
            if zb == 0.0 {
                continue;
            }
            let inv = 1.0 / (g + delta * l);
            let t = zb * inv;
            let w = l * t * t;
            G += w;
            dG -= 2.0 * w * l * inv;
        }
        (G, dG)
    }

    /// Starting shift δ₀ = µ₀ − µ̄ of (7.45): sqrt(Σ_{i≤M} z̄ᵢ² / λmax). G(µ̄ + δ₀) ≥ 0 (Lemma 7.10).
    #[inline]
    pub fn start(&self, zbar: &[f64]) -> f64 {
        let sW: f64 = zbar[..self.M].iter().map(|z| z * z).sum();
        (sW / self.lambda[0]).sqrt()
    }

    /// An upper bound δ_hi on the root: G(µ̄ + δ_hi) ≤ 0, since every term of (7.21) is at most
    /// z̄ᵢ²/(δ²λᵢ) ≤ z̄ᵢ²/(δ²λ_min).
    #[inline]
    pub fn upper_bound(&self, zbar: &[f64]) -> f64 {
        let n2: f64 = zbar.iter().map(|z| z * z).sum();
        (n2 / self.lambda[self.lambda.len() - 1]).sqrt() * (1.0 + 1e-12)
    }

    /// Solve (7.5) for `zbar` (length q) into `zstar` (length q): Algorithm 7.
    ///
    /// Panics never; `zbar`/`zstar` shorter than q would be a caller bug (debug-asserted, then only the
    /// common prefix is used).
    pub fn solve(
        &self,
        zbar: &[f64],
        zstar: &mut [f64],
        settings: &BoundaryDistanceSettings,
    ) -> CoreSolution {
        let q = self.lambda.len();
        debug_assert!(zbar.len() >= q && zstar.len() >= q);
        let q = q.min(zbar.len()).min(zstar.len());
        let (lam, gap, M) = (&self.lambda[..q], &self.gap[..q], self.M.min(q));
        let zbar = &zbar[..q];
        let zstar = &mut zstar[..q];
        let lmax = lam[0];
        let mu_bar = -1.0 / lmax;

        let sW: f64 = zbar[..M].iter().map(|z| z * z).sum();
        let mut delta = if sW > 0.0 { (sW / lmax).sqrt() } else { 0.0 }; // (7.45)

        if sW == 0.0 {
            // z̄ vanishes on W: G(µ̄⁺) is finite (Theorem 7.6, proof case 2).
            let mut G_bar = -1.0;
            for i in M..q {
                let t = zbar[i] / gap[i];
                G_bar += lam[i] * t * t;
            }
            if G_bar <= 0.0 {
                // (7.25)–(7.26): q₂ᵢ = z̄ᵢ/(1 − λᵢ/λmax) on W⊥, q₁ on the sphere of radius sqrt(−G(µ̄⁺)/λmax)
                // in W; we return the point of that sphere on the first axis of W.
                let radius = (-G_bar / lmax).sqrt();
                zstar[..M].fill(0.0);
                zstar[0] = radius;
                for i in M..q {
                    zstar[i] = zbar[i] / gap[i];
                }
                let value_sq = zstar.iter().zip(zbar).map(|(a, b)| (a - b) * (a - b)).sum();
                let kind = if radius > 0.0 {
                    OptimumKind::Multiple
                } else {
                    OptimumKind::Unique
                };
                return CoreSolution {
                    value_sq,
                    mu: mu_bar,
                    kind,
                    iterations: 0,
                };
            }
        }

        // Unique root µ* ∈ (µ̄, ∞): Lemma 7.9 from µ₀ of (7.45), monotone from below. The bracket's upper end
        // is only computed if a step ever leaves (lo, ∞).
        let first = if sW > 0.0 { 0 } else { M };
        let mut lo = delta;
        let mut hi = f64::INFINITY;
        let mut iterations = 0;
        loop {
            // G, G' of (7.21)–(7.22) and, on the fly, z = (µΛ + I)⁻¹z̄ of (7.24) at the current µ. Every
            // factor gap + δλ is positive here (δ > 0, or i ≥ M where gap > 0).
            let mut G = -1.0;
            let mut dG = 0.0;
            for (((z, &zb), &l), &g) in zstar[first..]
                .iter_mut()
                .zip(&zbar[first..])
                .zip(&lam[first..])
                .zip(&gap[first..])
            {
                let inv = 1.0 / (g + delta * l);
                let t = zb * inv;
                *z = t;
                let w = l * t * t;
                G += w;
                dG -= 2.0 * w * l * inv;
            }
            if G.abs() <= settings.tol || iterations >= settings.max_iter {
                break;
            }
            if G > 0.0 {
                lo = lo.max(delta);
            } else {
                hi = hi.min(delta);
            }
            let a = 1.0 + G; // = ‖a(µ)‖² ≥ 0 in the notation of the proof of Lemma 7.9
                             // (7.36) rather than (7.37): with p₁ + µ = −2(1 + G)/G' of (7.34), µ⁺ = µ + (p₁ + µ)(√(1 + G) − 1). The
                             // square root and the division are independent (shorter latency chain than (7.37)); the
                             // cancellation in √(1 + G) − 1 costs an absolute error of about ε·|p₁ + µ| in µ⁺, the same order as
                             // the error with which G itself determines µ*.
            let mut next = delta + (-2.0 * a / dG) * (a.sqrt() - 1.0);
            if !(next > lo && next < hi) {
                if hi == f64::INFINITY {
                    hi = self.upper_bound(zbar).max(lo);
                }
                if !(next > lo && next < hi) {
                    next = 0.5 * (lo + hi);
                }
            }
            iterations += 1;
            if next == delta {
                break;
            }
            delta = next;
        }
        // (7.24): z* = (µ*Λ + I)⁻¹ z̄, already in `zstar` for i ≥ first; z̄ vanishes below.
        zstar[..first].fill(0.0);
        let value_sq = zstar
            .iter()
            .zip(zbar)
            .map(|(z, zb)| (z - zb) * (z - zb))
            .sum();
        CoreSolution {
            value_sq,
            mu: delta + mu_bar,
            kind: OptimumKind::Unique,
            iterations,
        }
    }
}

/// The answer for one point of problem (7.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundarySolution {
    /// min over the boundary of ‖x − x̄‖_R (the square root of the optimal value of (7.2)).
    pub value: f64,
    pub kind: OptimumKind,
    /// The multiplier of the standard form (NaN in the zero-cost case).
    pub mu: f64,
    pub iterations: u32,
}

/// Scratch space for [`EllipsoidBoundaryDistance::solve`]; make one with
/// [`EllipsoidBoundaryDistance::workspace`] and reuse it for every point.
#[derive(Clone, Debug)]
pub struct BoundaryWorkspace {
    u: Vec<f64>,
    zbar: Vec<f64>,
    zstar: Vec<f64>,
    t1: Vec<f64>,
    t2: Vec<f64>,
    /// Newton refinement: (n+1)² bordered KKT matrix, right-hand side, column permutation, step, saved point.
    kkt: Vec<f64>,
    rhs: Vec<f64>,
    perm: Vec<usize>,
    step: Vec<f64>,
    saved: Vec<f64>,
    /// Witness buffer of [`EllipsoidBoundaryDistance::distance`].
    witness: Vec<f64>,
}

/// The data of the zero-cost case of §7.2.2 (R singular and its null space not inside that of Q).
#[derive(Clone, Debug)]
struct Escape {
    /// Q, row-major n×n.
    Q: Vec<f64>,
    /// E = V₂ P₂₂⁺ V₂ᵀ: from an outside point, x̄ − E Q (x̄ − x_c) is the point of minimal (x − x_c)ᵀQ(x − x_c)
    /// reachable at zero cost, with value ȳ₁ᵀSȳ₁ (7.9)–(7.11).
    E: Vec<f64>,
    /// V₂ e with e the top eigenvector of P₂₂: a zero-cost direction along which Q grows fastest.
    dir: Vec<f64>,
}

/// Problem (7.2) for a fixed ellipsoid (x_c, Q) and metric R, reduced once to the standard form (7.5).
///
/// Coordinates (§7.2.1–7.2.2): R = V_R diag(ρ) V_Rᵀ with V_R = [V₁ V₂], V₁ spanning the range (rank r) and V₂
/// the null space of R; y = V_Rᵀ(x − x_c) = (y₁, y₂); P = V_RᵀQV_R in blocks (7.7); S = P₁₁ − P₁₂P₂₂⁺P₂₁ the
/// generalised Schur complement (Q̂ of §7.2.2). Then w = diag(ρ)^{1/2} y₁ and P' = diag(ρ)^{-1/2} S diag(ρ)^{-1/2}
/// = U diag(λ) Uᵀ, z = Uᵀw. The first q coordinates of z (λ > 0) form (7.5); the remaining r − q are free
/// (Q̂ singular, (7.18)): z₂* = z̄₂. Back: y₁* = diag(ρ)^{-1/2} U z*, y₂* = −P₂₂⁺P₂₁y₁* + Π_N ȳ₂ (7.17) with Π_N
/// the projector onto N(P₂₂) (the free part of y₂ is kept at its value in x̄).
#[derive(Clone, Debug)]
pub struct EllipsoidBoundaryDistance {
    n: usize,
    c: Vec<f64>,
    /// Rank of R.
    r: usize,
    /// z̄ = T (x̄ − x_c), T row-major r×n.
    T: Vec<f64>,
    /// x* = x_c + B z* + D (x̄ − x_c), B row-major n×r.
    B: Vec<f64>,
    /// Row-major n×n, `None` when R is nonsingular (then D = 0).
    D: Option<Vec<f64>>,
    /// (7.5) on the first q coordinates; `None` when q = 0.
    core: Option<StandardForm>,
    escape: Option<Escape>,
    settings: BoundaryDistanceSettings,
    /// Q and R (symmetrised, row-major) for the refinement in the original coordinates.
    Q: Vec<f64>,
    R: Vec<f64>,
    /// λmax/λmin of the standard form exceeds `ILL_CONDITIONED`: always refine.
    ill_conditioned: bool,
}

impl EllipsoidBoundaryDistance {
    /// Factor problem (7.2) for the ellipsoid {x : (x − c)ᵀQ(x − c) ≤ 1} and the metric R (both row-major n×n,
    /// symmetric PSD, Q ≠ 0) with default settings.
    pub fn new(c: &[f64], Q: &[f64], R: &[f64]) -> Result<Self, GeometryError> {
        Self::with_settings(c, Q, R, BoundaryDistanceSettings::default())
    }

    /// As [`EllipsoidBoundaryDistance::new`] with explicit settings.
    pub fn with_settings(
        c: &[f64],
        Q: &[f64],
        R: &[f64],
        settings: BoundaryDistanceSettings,
    ) -> Result<Self, GeometryError> {
        settings.validate()?;
        let n = c.len();
        if n == 0 {
            return Err(GeometryError::ZeroDimension {
                what: "ellipsoid centre",
            });
        }
        linalg::check_finite("ellipsoid centre", c)?;
        let Qs = linalg::symmetrize_checked("ellipsoid Q", n, Q)?;
        let eq = SymEig::new("ellipsoid Q", n, &Qs)?;
        eq.check_psd("ellipsoid Q")?;
        let qscale = eq.values.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        if qscale == 0.0 {
            return Err(GeometryError::ZeroMatrix {
                what: "ellipsoid Q",
            });
        }
        let (Rs, er) = Metric { n, R: R.to_vec() }.validated()?;
        Self::from_parts(c.to_vec(), Qs, Rs, qscale, &er, settings)
    }

    fn from_parts(
        c: Vec<f64>,
        Q: Vec<f64>,
        R: Vec<f64>,
        qscale: f64,
        er: &SymEig,
        settings: BoundaryDistanceSettings,
    ) -> Result<Self, GeometryError> {
        let n = c.len();
        // (7.3)/(7.6): split R's eigenvectors into range (ρ > threshold) and null space.
        let thr = er.zero_threshold();
        let range: Vec<usize> = (0..n)
            .filter(|&k| er.values[k] > thr && er.values[k] > 0.0)
            .collect();
        let null: Vec<usize> = (0..n).filter(|k| !range.contains(k)).collect();
        let r = range.len();
        let nr = n - r;
        let col = |k: usize| -> Vec<f64> { er.vector(k) };
        let mut V1 = vec![0.0; n * r];
        for (j, &k) in range.iter().enumerate() {
            let v = col(k);
            for i in 0..n {
                V1[i * r + j] = v[i];
            }
        }
        let mut V2 = vec![0.0; n * nr];
        for (j, &k) in null.iter().enumerate() {
            let v = col(k);
            for i in 0..n {
                V2[i * nr + j] = v[i];
            }
        }
        let rho: Vec<f64> = range.iter().map(|&k| er.values[k]).collect();

        let V1t = linalg::transpose(&V1, n, r);
        let V2t = linalg::transpose(&V2, n, nr);
        let QV1 = linalg::matmul(&Q, &V1, n, n, r);
        let QV2 = linalg::matmul(&Q, &V2, n, n, nr);
        let P11 = linalg::matmul(&V1t, &QV1, r, n, r);
        let P21 = linalg::matmul(&V2t, &QV1, nr, n, r);
        let P22 = linalg::matmul(&V2t, &QV2, nr, n, nr);

        // Is N(R) ⊂ N(Q)? Then P₂₁ = P₂₂ = 0 and y₂ never matters (§7.2.2, case P₂₂ = 0).
        let escapes = nr > 0 && linalg::max_abs(&QV2) > NULL_CONTAINMENT_TOL * qscale;

        let (S, K, D, escape) = if escapes {
            let e22 = SymEig::new("P22 block of (7.7)", nr, &P22)?;
            let P22p = e22.pinv();
            // S = P₁₁ − P₁₂ P₂₂⁺ P₂₁ (generalised Schur complement, Q̂ of §7.2.2).
            let X = linalg::matmul(&P22p, &P21, nr, nr, r); // P₂₂⁺P₂₁
            let P12 = linalg::transpose(&P21, nr, r);
            let P12X = linalg::matmul(&P12, &X, r, nr, r);
            let S: Vec<f64> = P11.iter().zip(&P12X).map(|(a, b)| a - b).collect();
            // K = V₁ − V₂ P₂₂⁺ P₂₁ maps y₁* to x* − x_c along (7.17).
            let V2X = linalg::matmul(&V2, &X, n, nr, r);
            let K: Vec<f64> = V1.iter().zip(&V2X).map(|(a, b)| a - b).collect();
            // D = V₂ Π_N V₂ᵀ keeps the free part (null space of P₂₂) of y₂ at its value in x̄.
            let (N, k) = e22.null_basis();
            let D = if k > 0 {
                let V2N = linalg::matmul(&V2, &N, n, nr, k);
                let V2Nt = linalg::transpose(&V2N, n, k);
                Some(linalg::matmul(&V2N, &V2Nt, n, k, n))
            } else {
                None
            };
            let E = linalg::matmul(&linalg::matmul(&V2, &P22p, n, nr, nr), &V2t, n, nr, n);
            let top = e22.vector(nr - 1);
            let mut dir = vec![0.0; n];
            linalg::matvec(&V2, n, nr, &top, &mut dir);
            (
                S,
                K,
                D,
                Some(Escape {
                    Q: Q.clone(),
                    E,
                    dir,
                }),
            )
        } else {
            let D = (nr > 0).then(|| linalg::matmul(&V2, &V2t, n, nr, n));
            (P11, V1.clone(), D, None)
        };

        // (7.4)–(7.5): P' = diag(ρ)^{-1/2} S diag(ρ)^{-1/2} = U diag(λ) Uᵀ.
        let mut Pp = vec![0.0; r * r];
        for i in 0..r {
            for j in 0..r {
                Pp[i * r + j] = S[i * r + j] / (rho[i] * rho[j]).sqrt();
            }
        }
        let ep = SymEig::new("whitened ellipsoid matrix of (7.4)", r, &Pp)?;
        // Descending order (Notation 7.1); λ under the rank threshold are free directions (7.18).
        let order: Vec<usize> = (0..r).rev().collect();
        let lmax = ep.max();
        let q = if lmax > 0.0 {
            order
                .iter()
                .filter(|&&k| ep.values[k] > RANK_TOL_REL * lmax)
                .count()
        } else {
            0
        };
        let mut U = vec![0.0; r * r];
        for (j, &k) in order.iter().enumerate() {
            for i in 0..r {
                U[i * r + j] = ep.vectors[i * r + k];
            }
        }
        let lambda: Vec<f64> = order.iter().take(q).map(|&k| ep.values[k]).collect();

        // T = Uᵀ diag(ρ)^{1/2} V₁ᵀ (r×n); B = K diag(ρ)^{-1/2} U (n×r).
        let mut T = vec![0.0; r * n];
        for a in 0..r {
            for j in 0..n {
                let mut s = 0.0;
                for i in 0..r {
                    s += U[i * r + a] * rho[i].sqrt() * V1[j * r + i];
                }
                T[a * n + j] = s;
            }
        }
        let mut B = vec![0.0; n * r];
        for i in 0..n {
            for a in 0..r {
                let mut s = 0.0;
                for k in 0..r {
                    s += K[i * r + k] * U[k * r + a] / rho[k].sqrt();
                }
                B[i * r + a] = s;
            }
        }

        if q == 0 && escape.is_none() {
            return Err(GeometryError::Degenerate {
                what: "ellipsoid boundary distance",
                reason: "Q vanishes on the range of the metric and the null space of the metric lies in that of \
                         Q, so the boundary constraint cannot be met"
                    .into(),
            });
        }
        let ill_conditioned = q > 0 && lambda[0] > ILL_CONDITIONED * lambda[q - 1];
        let core = if q > 0 {
            Some(StandardForm::new(lambda)?)
        } else {
            None
        };
        Ok(Self {
            n,
            c,
            r,
            T,
            B,
            D,
            core,
            escape,
            settings,
            Q,
            R,
            ill_conditioned,
        })
    }

    /// Ambient dimension n.
    pub fn dim(&self) -> usize {
        self.n
    }
    /// Rank r of R.
    pub fn metric_rank(&self) -> usize {
        self.r
    }
    /// The standard form (7.5) this problem reduces to (`None` when every point is a zero-cost case).
    pub fn standard_form(&self) -> Option<&StandardForm> {
        self.core.as_ref()
    }
    /// Whether R is singular with a null space that reaches the boundary at zero cost (§7.2.2).
    pub fn has_zero_cost_directions(&self) -> bool {
        self.escape.is_some()
    }
    /// `slot`'s workspace, made afresh ([`Self::workspace`]) only when it is empty or sized for another
    /// problem: a caller that answers many queries keeps one slot (per thread) instead of allocating
    /// eleven small vectors per point, which for n = 3 cost more than the solve.
    pub fn workspace_in<'w>(
        &self,
        slot: &'w mut Option<BoundaryWorkspace>,
    ) -> &'w mut BoundaryWorkspace {
        let fits = slot.as_ref().is_some_and(|ws| {
            ws.u.len() == self.n
                && ws.zbar.len() == self.r
                && ws.kkt.len() == (self.n + 1) * (self.n + 1)
        });
        if !fits {
            *slot = None;
        }
        slot.get_or_insert_with(|| self.workspace())
    }
    /// Scratch space for the per-point methods.
    pub fn workspace(&self) -> BoundaryWorkspace {
        BoundaryWorkspace {
            u: vec![0.0; self.n],
            zbar: vec![0.0; self.r],
            zstar: vec![0.0; self.r],
            t1: vec![0.0; self.n],
            t2: vec![0.0; self.n],
            kkt: vec![0.0; (self.n + 1) * (self.n + 1)],
            rhs: vec![0.0; self.n + 1],
            perm: vec![0; self.n + 1],
            step: vec![0.0; self.n + 1],
            saved: vec![0.0; self.n],
            witness: vec![0.0; self.n],
        }
    }

    fn check_point(&self, xbar: &[f64], ws: &BoundaryWorkspace) -> Result<(), GeometryError> {
        linalg::check_vector("query point", xbar, self.n)?;
        if ws.u.len() != self.n
            || ws.zbar.len() != self.r
            || ws.kkt.len() != (self.n + 1) * (self.n + 1)
        {
            return Err(GeometryError::Dimension {
                what: "boundary workspace",
                expected: self.n,
                got: ws.u.len(),
            });
        }
        Ok(())
    }

    /// The standard-form coordinates z̄ = T(x̄ − x_c) (length r; the first q enter (7.5)). No validation.
    #[inline]
    pub fn standardize(&self, xbar: &[f64], zbar: &mut [f64]) {
        for (z, row) in zbar.iter_mut().zip(self.T.chunks_exact(self.n)) {
            *z = row
                .iter()
                .zip(xbar)
                .zip(&self.c)
                .fold(0.0, |s, ((t, x), c)| s + t * (x - c));
        }
    }

    /// Map a standard-form optimum z* (length r) back to x* = x_c + B z* + D(x̄ − x_c). No validation.
    #[inline]
    pub fn destandardize(&self, xbar: &[f64], zstar: &[f64], x_star: &mut [f64]) {
        let (n, r) = (self.n, self.r);
        if r > 0 {
            for ((x, row), &c) in x_star.iter_mut().zip(self.B.chunks_exact(r)).zip(&self.c) {
                *x = row.iter().zip(zstar).fold(c, |s, (b, z)| s + b * z);
            }
        } else {
            x_star[..n].copy_from_slice(&self.c);
        }
        if let Some(D) = &self.D {
            for (x, row) in x_star.iter_mut().zip(D.chunks_exact(n)) {
                *x += row
                    .iter()
                    .zip(xbar)
                    .zip(&self.c)
                    .fold(0.0, |s, ((d, xb), c)| s + d * (xb - c));
            }
        }
    }

    /// Solve (7.2) for x̄: the optimal value (as a distance) and one optimal boundary point in `x_star`.
    /// Allocation-free. Errors only on a point of the wrong length or with non-finite entries, or a workspace
    /// made for another problem.
    pub fn solve(
        &self,
        xbar: &[f64],
        ws: &mut BoundaryWorkspace,
        x_star: &mut [f64],
    ) -> Result<BoundarySolution, GeometryError> {
        self.check_point(xbar, ws)?;
        if x_star.len() != self.n {
            return Err(GeometryError::Dimension {
                what: "witness buffer",
                expected: self.n,
                got: x_star.len(),
            });
        }
        let q = self.core.as_ref().map_or(0, |c| c.dim());
        self.standardize(xbar, &mut ws.zbar);
        if let Some(esc) = &self.escape {
            // §7.2.2: if ȳ₁ᵀSȳ₁ ≤ 1 the point (ȳ₁, some y₂) is on the boundary: zero cost.
            let level: f64 = match &self.core {
                Some(core) => core
                    .lambda()
                    .iter()
                    .zip(&ws.zbar)
                    .map(|(l, z)| l * z * z)
                    .sum(),
                None => 0.0,
            };
            if level <= 1.0 {
                self.zero_cost_point(esc, xbar, ws, x_star);
                return Ok(BoundarySolution {
                    value: 0.0,
                    kind: OptimumKind::ZeroCost,
                    mu: f64::NAN,
                    iterations: 0,
                });
            }
        }
        let Some(core) = &self.core else {
            // Unreachable by construction (q = 0 implies an escape, whose level is 0 ≤ 1).
            return Err(GeometryError::Degenerate {
                what: "ellipsoid boundary distance",
                reason: "empty standard form".into(),
            });
        };
        let sol = core.solve(&ws.zbar[..q], &mut ws.zstar[..q], &self.settings);
        ws.zstar[q..].copy_from_slice(&ws.zbar[q..]);
        self.destandardize(xbar, &ws.zstar, x_star);
        let mut value = sol.value_sq.sqrt();
        // Every point's constraint is checked in the original coordinates (n² flops): the transformations can
        // lose accuracy beyond what `ill_conditioned` predicts (e.g. through P₂₂⁺ of §7.2.2).
        if self.ill_conditioned || self.constraint_error(x_star, ws) > REFINE_TRIGGER {
            if let Some(v) = self.refine(xbar, sol.mu, ws, x_star) {
                value = v;
            }
        }
        Ok(BoundarySolution {
            value,
            kind: sol.kind,
            mu: sol.mu,
            iterations: sol.iterations,
        })
    }

    /// The optimal value of (7.2) as a distance, without keeping the witness point. Allocation-free.
    pub fn distance(&self, xbar: &[f64], ws: &mut BoundaryWorkspace) -> Result<f64, GeometryError> {
        let mut x = std::mem::take(&mut ws.witness);
        let r = self.solve(xbar, ws, &mut x);
        ws.witness = x;
        r.map(|s| s.value)
    }

    /// |h(x) − 1| relative to the size of the terms of h(x) = (x − x_c)ᵀQ(x − x_c). Uses `u`, `t1`.
    #[inline]
    fn constraint_error(&self, x: &[f64], ws: &mut BoundaryWorkspace) -> f64 {
        for ((u, &xi), &ci) in ws.u.iter_mut().zip(x).zip(&self.c) {
            *u = xi - ci;
        }
        let u = &ws.u;
        let mut h = 0.0;
        let mut scale = 0.0;
        for (&ui, row) in u.iter().zip(self.Q.chunks_exact(self.n)) {
            let qu = row.iter().zip(u).fold(0.0, |s, (q, v)| s + q * v);
            h += ui * qu;
            scale += (ui * qu).abs();
        }
        (h - 1.0).abs() / scale.max(1.0)
    }

    /// Newton's method on the KKT system of (7.2) in the original coordinates, from the standard-form answer:
    /// F(x, µ) = (R(x − x̄) + µQ(x − x_c), ½((x − x_c)ᵀQ(x − x_c) − 1)) = 0, whose Jacobian is the symmetric
    /// bordered matrix [[R + µQ, Q(x − x_c)], [(Q(x − x_c))ᵀ, 0]]. Used when the standard form is
    /// ill-conditioned: its small eigenvalues are only known to ε·λmax absolutely, which shows up as a
    /// constraint violation that these steps remove (quadratic convergence from the nearby KKT point).
    /// Returns the refined distance, or `None` (and leaves `x` unchanged) if refinement did not help.
    /// Allocation-free: works in the workspace.
    fn refine(
        &self,
        xbar: &[f64],
        mu0: f64,
        ws: &mut BoundaryWorkspace,
        x: &mut [f64],
    ) -> Option<f64> {
        let n = self.n;
        let m = n + 1;
        let err0 = self.constraint_error(x, ws);
        ws.saved.copy_from_slice(x);
        let mut mu = if mu0.is_finite() { mu0 } else { 0.0 };
        for _ in 0..6 {
            for ((u, &xi), &ci) in ws.u.iter_mut().zip(x.iter()).zip(&self.c) {
                *u = xi - ci;
            }
            linalg::matvec(&self.Q, n, n, &ws.u, &mut ws.t1); // g = Q u
            let h = linalg::dot(&ws.u, &ws.t1);
            for i in 0..n {
                let mut r = 0.0;
                for j in 0..n {
                    r += self.R[i * n + j] * (x[j] - xbar[j]);
                    ws.kkt[i * m + j] = self.R[i * n + j] + mu * self.Q[i * n + j];
                }
                ws.kkt[i * m + n] = ws.t1[i];
                ws.kkt[n * m + i] = ws.t1[i];
                ws.rhs[i] = -(r + mu * ws.t1[i]);
            }
            ws.kkt[n * m + n] = 0.0;
            ws.rhs[n] = -0.5 * (h - 1.0);
            solve_complete_pivoting(m, &mut ws.kkt, &mut ws.rhs, &mut ws.perm, &mut ws.step);
            let mut size = 0.0_f64;
            let mut xs = 0.0_f64;
            for (xi, &d) in x.iter_mut().zip(&ws.step[..n]) {
                *xi += d;
                size = size.max(d.abs());
                xs = xs.max(xi.abs());
            }
            mu += ws.step[n];
            if !(size.is_finite() && mu.is_finite()) {
                break;
            }
            if size <= 4.0 * f64::EPSILON * (1.0 + xs) {
                break;
            }
        }
        let err1 = self.constraint_error(x, ws);
        // Accept a local correction that improved feasibility.
        let mut moved = 0.0_f64;
        let mut size = 1.0_f64;
        for i in 0..n {
            moved = moved.max((x[i] - ws.saved[i]).abs());
            size = size
                .max((ws.saved[i] - self.c[i]).abs())
                .max((ws.saved[i] - xbar[i]).abs());
        }
        if err1.is_finite() && err1 <= err0 && moved <= 1e-4 * size {
            let mut v = 0.0;
            for i in 0..n {
                ws.u[i] = x[i] - xbar[i];
            }
            for i in 0..n {
                let mut r = 0.0;
                for j in 0..n {
                    r += self.R[i * n + j] * ws.u[j];
                }
                v += ws.u[i] * r;
            }
            Some(v.max(0.0).sqrt())
        } else {
            x.copy_from_slice(&ws.saved);
            None
        }
    }

    /// Many points at once: `points` is row-major N×n; writes N values and, if given, N witnesses (row-major
    /// N×n). One workspace for the whole batch.
    pub fn solve_batch(
        &self,
        points: &[f64],
        values: &mut [f64],
        mut witnesses: Option<&mut [f64]>,
    ) -> Result<(), GeometryError> {
        let n = self.n;
        if !points.len().is_multiple_of(n) {
            return Err(GeometryError::Dimension {
                what: "batch points (multiple of n)",
                expected: n,
                got: points.len() % n,
            });
        }
        let N = points.len() / n;
        if values.len() != N {
            return Err(GeometryError::Dimension {
                what: "batch values",
                expected: N,
                got: values.len(),
            });
        }
        if let Some(w) = witnesses.as_deref() {
            if w.len() != N * n {
                return Err(GeometryError::Dimension {
                    what: "batch witnesses",
                    expected: N * n,
                    got: w.len(),
                });
            }
        }
        let mut ws = self.workspace();
        for k in 0..N {
            let x = &points[k * n..(k + 1) * n];
            values[k] = match witnesses.as_deref_mut() {
                Some(w) => self.solve(x, &mut ws, &mut w[k * n..(k + 1) * n])?.value,
                None => self.distance(x, &mut ws)?,
            };
        }
        Ok(())
    }

    /// A boundary point reached from x̄ along the null space of R (zero cost), §7.2.2.
    fn zero_cost_point(
        &self,
        esc: &Escape,
        xbar: &[f64],
        ws: &mut BoundaryWorkspace,
        x_star: &mut [f64],
    ) {
        let n = self.n;
        for ((u, &xi), &ci) in ws.u.iter_mut().zip(xbar).zip(&self.c) {
            *u = xi - ci;
        }
        linalg::matvec(&esc.Q, n, n, &ws.u, &mut ws.t1); // t1 = Q u
        let h = linalg::dot(&ws.u, &ws.t1);
        if h >= 1.0 {
            // Outside: head for the minimiser of the constraint over x̄ + N(R): d = −E Q u, where the level is
            // ȳ₁ᵀSȳ₁ ≤ 1; the boundary is crossed on the segment.
            linalg::matvec(&esc.E, n, n, &ws.t1, &mut ws.t2);
            for v in ws.t2.iter_mut() {
                *v = -*v;
            }
        } else {
            // Inside: move along the zero-cost direction in which Q grows fastest.
            ws.t2.copy_from_slice(&esc.dir);
        }
        // h(x̄ + t d) − 1 = a t² + 2 b t + (h − 1).
        let b = linalg::dot(&ws.t2, &ws.t1);
        let a = linalg::quad_form(&esc.Q, &ws.t2);
        let t = linalg::smallest_nonneg_root(a, b, h - 1.0).unwrap_or_else(|| {
            if a > 0.0 {
                (-b / a).max(0.0)
            } else {
                0.0
            }
        });
        for i in 0..n {
            x_star[i] = xbar[i] + t * ws.t2[i];
        }
    }
}

/// Solve J s = b for a square m×m row-major J by Gaussian elimination with complete pivoting; pivots under
/// 1e-14 of the largest entry end the elimination and the corresponding unknowns are set to 0 (a basic
/// solution of a consistent singular system). Destroys `J` and `b`. Allocation-free.
fn solve_complete_pivoting(
    m: usize,
    J: &mut [f64],
    b: &mut [f64],
    perm: &mut [usize],
    out: &mut [f64],
) {
    for (k, p) in perm.iter_mut().enumerate().take(m) {
        *p = k;
    }
    let scale = J[..m * m].iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    let mut rank = m;
    for k in 0..m {
        let (mut p, mut q, mut best) = (k, k, -1.0);
        for i in k..m {
            for j in k..m {
                let v = J[i * m + j].abs();
                if v > best {
                    best = v;
                    p = i;
                    q = j;
                }
            }
        }
        if best.is_nan() || best <= 1e-14 * scale {
            rank = k;
            break;
        }
        if p != k {
            for j in 0..m {
                J.swap(k * m + j, p * m + j);
            }
            b.swap(k, p);
        }
        if q != k {
            for i in 0..m {
                J.swap(i * m + k, i * m + q);
            }
            perm.swap(k, q);
        }
        let piv = J[k * m + k];
        for i in k + 1..m {
            let f = J[i * m + k] / piv;
            if f == 0.0 {
                continue;
            }
            for j in k..m {
                J[i * m + j] -= f * J[k * m + j];
            }
            b[i] -= f * b[k];
        }
    }
    // Back substitution in permuted order, into b (reused as y).
    for k in (0..m).rev() {
        if k >= rank {
            b[k] = 0.0;
            continue;
        }
        let mut s = b[k];
        for j in k + 1..m {
            s -= J[k * m + j] * b[j];
        }
        b[k] = s / J[k * m + k];
    }
    for k in 0..m {
        out[perm[k]] = b[k];
    }
}

/// Condition λmax/λmin of the standard form above which every answer is refined in the original coordinates
/// (the smallest eigenvalues then carry a relative error of about ε·λmax/λmin).
const ILL_CONDITIONED: f64 = 1e6;
/// Constraint violation of a returned point, relative to the size of the terms of (x − x_c)ᵀQ(x − x_c), above
/// which it is refined (about 64 ε: rounding in evaluating the constraint itself stays below).
const REFINE_TRIGGER: f64 = 1.5e-14;

/// Relative threshold for the rank of the whitened ellipsoid matrix P' (its eigenvalues under it are free
/// directions of a degenerate ellipsoid, (7.18)).
const RANK_TOL_REL: f64 = linalg::RANK_TOL;

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> BoundaryDistanceSettings {
        BoundaryDistanceSettings::default()
    }

    #[test]
    fn the_builder_and_the_constructor_refuse_a_zero_tolerance() {
        let e = BoundaryDistanceSettings::builder()
            .tol(0.0)
            .build()
            .unwrap_err();
        assert_eq!(
            (e.settings, e.field, e.value),
            ("BoundaryDistanceSettings", "tol", 0.0)
        );
        let e = BoundaryDistanceSettings::builder()
            .max_iter(0)
            .build()
            .unwrap_err();
        assert_eq!(e.field, "max_iter");
        let bad = BoundaryDistanceSettings {
            tol: f64::NAN,
            ..settings()
        };
        let r = EllipsoidBoundaryDistance::with_settings(&[0.0], &[1.0], &[1.0], bad);
        assert!(
            matches!(
                r,
                Err(GeometryError::Settings(SettingError { field: "tol", .. }))
            ),
            "{r:?}"
        );
    }

    #[test]
    fn standard_form_sorts_and_groups() {
        let sf = StandardForm::new(vec![1.0, 9.0, 4.0, 9.0 * (1.0 - 1e-16)]).unwrap();
        assert_eq!(sf.lambda(), &[9.0, 9.0, 4.0, 1.0]);
        assert_eq!(sf.multiplicity(), 2);
        assert!((sf.gaps()[2] - 5.0 / 9.0).abs() < 1e-16);
        assert!(StandardForm::new(vec![]).is_err());
        assert!(StandardForm::new(vec![1.0, 0.0]).is_err());
        assert!(StandardForm::new(vec![1.0, f64::NAN]).is_err());
    }

    #[test]
    fn circle_inside_and_outside() {
        // Unit circle in the standard form: distance from (0.3, 0.4) (radius 0.5) is 0.5 inside, and from
        // (3, 4) it is 4 outside, both with the radial point as optimum.
        let sf = StandardForm::new(vec![1.0, 1.0]).unwrap();
        let mut z = [0.0; 2];
        let s = sf.solve(&[0.3, 0.4], &mut z, &settings());
        assert!((s.value_sq.sqrt() - 0.5).abs() < 1e-14);
        assert!((z[0] - 0.6).abs() < 1e-14 && (z[1] - 0.8).abs() < 1e-14);
        assert!(s.mu < 0.0);
        let s = sf.solve(&[3.0, 4.0], &mut z, &settings());
        assert!((s.value_sq.sqrt() - 4.0).abs() < 1e-13);
        assert!(s.mu > 0.0);
        // The centre: a whole circle of optima.
        let s = sf.solve(&[0.0, 0.0], &mut z, &settings());
        assert_eq!(s.kind, OptimumKind::Multiple);
        assert!((s.value_sq - 1.0).abs() < 1e-15);
    }

    #[test]
    fn lemma_7_9_converges_monotonically_and_fast() {
        let sf = StandardForm::new(vec![5.0, 2.0, 0.5]).unwrap();
        let zbar = [0.2, -0.7, 1.1];
        let mut delta = sf.start(&zbar);
        let mut prev_G = f64::INFINITY;
        let mut k = 0;
        loop {
            let (G, dG) = sf.secular(&zbar, delta);
            assert!(G >= -1e-15, "iterate overshot the root: G = {G}");
            assert!(G <= prev_G);
            prev_G = G;
            if G.abs() < 1e-15 {
                break;
            }
            let a = 1.0 + G;
            delta -= 2.0 * a / (1.0 + a.sqrt()) * G / dG;
            k += 1;
            assert!(k < 20);
        }
        let mut z = [0.0; 3];
        let s = sf.solve(&zbar, &mut z, &settings());
        assert!(s.iterations as usize <= k + 1);
        let h: f64 = sf.lambda().iter().zip(&z).map(|(l, z)| l * z * z).sum();
        assert!((h - 1.0).abs() < 1e-14);
    }

    #[test]
    fn rejects_bad_input() {
        let I2 = [1.0, 0.0, 0.0, 1.0];
        assert!(matches!(
            EllipsoidBoundaryDistance::new(&[0.0, 0.0], &[0.0; 4], &I2),
            Err(GeometryError::ZeroMatrix { .. })
        ));
        assert!(matches!(
            EllipsoidBoundaryDistance::new(&[0.0, 0.0], &[1.0, 0.0, 0.0, -1.0], &I2),
            Err(GeometryError::NotPsd { .. })
        ));
        assert!(matches!(
            EllipsoidBoundaryDistance::new(&[0.0, 0.0], &I2, &[1.0, 0.0, 0.0]),
            Err(GeometryError::Dimension { .. })
        ));
        assert!(matches!(
            EllipsoidBoundaryDistance::new(&[], &[], &[]),
            Err(GeometryError::ZeroDimension { .. })
        ));
        let e = EllipsoidBoundaryDistance::new(&[0.0, 0.0], &I2, &I2).unwrap();
        let mut ws = e.workspace();
        let mut x = [0.0; 2];
        assert!(e.solve(&[1.0], &mut ws, &mut x).is_err());
        assert!(e.solve(&[f64::NAN, 0.0], &mut ws, &mut x).is_err());
    }
}
