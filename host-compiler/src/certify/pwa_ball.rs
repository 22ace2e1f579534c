//! The stored threshold of a PWA ball for the evaluator's whitened f32 test (`shared_types::pwa`, "The
//! whitened ball test" and "Rounding of the ball test"), and the same bound read backwards for the
//! verifier.
//!
//! The image stores per location `R̂ = fl32(R)`, R the upper Cholesky factor of the CAF metric P
//! (`P = RᵀR`, (3.8)), and per ball the whitened centre `ĉ_z = fl32(R̂ ĉ)` (ĉ = fl32(c)) and a squared
//! threshold ŝ. The evaluator accepts x̂ when `fl(Σ_i fl(fl(R̂x̂)_i − ĉ_z,i)²) ≤ ŝ`. The derivation in
//! `shared_types::pwa` shows that every accepted x̂, and every real x with `fl32(x) = x̂`, satisfies
//!
//! ```text
//! ‖x − c‖_P ≤ sqrt(1 + χ) · (S(ŝ) + β) / (1 − α)  ≤  sqrt(1 + χ) · (S_ρ(ρ̂) + β) / (1 − α)   (ŝ = fl32(ρ̂·ρ̂))
//! ```
//!
//! with S, α, β, χ computed here from P, R̂, c and ĉ_z ([`pwa_accept_radius`], from ŝ). The discrepancies
//! `D = |R̂ − R|` and `e_c = ĉ_z − R c` are *measured* (not assumed to be the rounding bounds), so the same
//! function also bounds an image whose factor was computed from a slightly different P (the verifier
//! passes the image's f32 P). [`pwa_ball_radius`] returns the largest f32 ρ̂ whose bound (the right-hand
//! one) is ≤ δ, the certified radius (Theorem 6.6 needs every accepted state in `B_P(x̃_i(κ), δ_i)`), and
//! [`pwa_ball_threshold`] the threshold `ŝ = fl32(ρ̂·ρ̂)` the image stores: the single f32 product the
//! evaluator of image format 2 formed per step, so acceptance is bit-identical to it.
//!
//! # Completeness
//! The converse, that every state near enough to c *is* accepted, is what the PWA certificate's one-step
//! inclusion (6.5) needs of the ball a run steps into (the run must be recognised there, not reported out of
//! the envelope). For a real x with `‖x − c‖_P ≤ r` and `x̂ = fl32(x)`, with the same R, R̂, G, e_c, a' and
//! χ: `|x| ≤ X := |c| + a'r`, `|x̂| ≤ (1 + u)X + η`, `‖R(x − c)‖ ≤ r/sqrt(1 − χ)` (step 6 read the other
//! way), so by steps 1–2 `‖w + f‖ ≤ t0 + t1·r` with
//!
//! ```text
//! t1 = 1/sqrt(1 − χ) + u‖|R|a'‖ + (1 + u)‖G a'‖,
//! t0 = u‖|R||c|‖ + η‖|R|𝟙‖ + (1 + u)‖G|c|‖ + η‖G𝟙‖ + ‖e_c‖ + 2n^{3/2}η,
//! ```
//!
//! and the computed sum is `s ≤ (1 + γ_n)(1 + u)²‖w + f‖² + 2nη`. Acceptance `s ≤ ŝ` therefore holds for
//! every r up to [`pwa_complete_radius`]. For unit-scale data (|c| ≤ 3, δ ≥ 0.1,
//! cond(P) ≤ 10, n ≤ 12) it lies less than 10⁻⁴ (relative) below ρ̂ (`tests/host/certify_bounds.rs`).
//!
//! Host f64 rounding: every term of the bound is a sum of non-negative quantities except `e_c`, which
//! carries its own γ⁽⁶⁴⁾ term; the few dozen f64 operations on the positive terms are covered by a final
//! factor 1 + 10⁻¹², and the norms ‖|R|‖₂, ‖R⁻¹‖₂ of χ by their Frobenius upper bounds.
#![allow(non_snake_case)]

use super::{round_down_f32, U32};
use faer::MatRef;

/// Absolute error of an f32 product that underflows (half the smallest subnormal spacing), 2⁻¹⁵⁰.
const ETA: f64 = 7.006_492_321_624_085e-46;
/// Unit roundoff of f64, 2⁻⁵³.
const U64: f64 = 1.110_223_024_625_156_5e-16;
/// Relative allowance for the host's own f64 rounding of the (positive) bound terms.
const HOST_SLACK: f64 = 1e-12;

fn gamma(k: usize, u: f64) -> f64 {
    let ku = k as f64 * u;
    ku / (1.0 - ku)
}

fn norm2(v: impl Iterator<Item = f64>) -> f64 {
    v.map(|x| x * x).sum::<f64>().sqrt()
}

/// The upper Cholesky factor R of a symmetric positive definite n × n row-major `P` (`P = RᵀR`, positive
/// diagonal), row-major with zeros below the diagonal, from faer's LLᵀ factorisation (R = Lᵀ; the lower
/// triangle of P is read); `None` if P is not positive definite. Host and emitter call this one function,
/// so they get the same bits.
pub fn cholesky_upper(P: &[f64], n: usize) -> Option<Vec<f64>> {
    if P.len() != n * n {
        return None;
    }
    let m = faer::Mat::from_fn(n, n, |i, j| P[i * n + j]);
    let llt = m.llt(faer::Side::Lower).ok()?;
    let L = llt.L();
    let mut R = vec![0.0f64; n * n];
    for i in 0..n {
        for j in i..n {
            R[i * n + j] = L[(j, i)];
        }
    }
    (0..n)
        .all(|i| R[i * n + i] > 0.0 && R[i * n + i].is_finite())
        .then_some(R)
}

/// `R̂ = fl32(R)` for the metric `P` (n × n row-major), widened exactly to f64: the factor the image stores.
/// `None` if P is not positive definite or an entry leaves the f32 range or rounds to a zero diagonal.
pub fn metric_factor_f32(P: &[f64], n: usize) -> Option<Vec<f64>> {
    let R = cholesky_upper(P, n)?;
    let Rh: Vec<f64> = R.iter().map(|&r| r as f32 as f64).collect();
    let ok = Rh.iter().all(|r| r.is_finite()) && (0..n).all(|i| Rh[i * n + i] > 0.0);
    ok.then_some(Rh)
}

/// The whitened centre the image stores, `ĉ_z = fl32(R̂ ĉ)` with `ĉ = fl32(c)`: row i summed in f64 from
/// j = i upwards, then rounded once to f32 (widened exactly to f64). `Rh` is the n × n factor.
pub fn whitened_centre(Rh: &[f64], c: &[f64]) -> Vec<f64> {
    let n = c.len();
    (0..n)
        .map(|i| {
            let s: f64 = (i..n).map(|j| Rh[i * n + j] * (c[j] as f32 as f64)).sum();
            s as f32 as f64
        })
        .collect()
}

/// The constants of the acceptance bound of one ball (module doc).
struct AcceptBound {
    n: usize,
    /// α = ‖G a'‖ + u‖|R| a'‖.
    alpha: f64,
    /// β = ‖G|c|‖ + u‖|R||c|‖ + ‖e_c‖ + (2n^{3/2} + ‖|R|𝟙‖)η.
    beta: f64,
    /// sqrt(1 + χ).
    k: f64,
    /// Completeness (module doc, "Completeness"): ‖w + f‖ ≤ t0 + t1·r for every real x with ‖x − c‖_P ≤ r.
    t0: f64,
    t1: f64,
}

impl AcceptBound {
    fn new(P: MatRef<'_, f64>, Rh: &[f64], c: &[f64], cz: &[f64]) -> Option<Self> {
        let n = P.nrows();
        if P.ncols() != n || Rh.len() != n * n || c.len() != n || cz.len() != n {
            return None;
        }
        let Prm = crate::linalg::to_row_major(P);
        let R = cholesky_upper(&Prm, n)?;
        // R⁻¹ (upper triangular) by back substitution, column by column.
        let mut Ri = vec![0.0f64; n * n];
        for col in 0..n {
            for i in (0..=col).rev() {
                let mut s = if i == col { 1.0 } else { 0.0 };
                for k in (i + 1)..=col {
                    s -= R[i * n + k] * Ri[k * n + col];
                }
                Ri[i * n + col] = s / R[i * n + i];
            }
        }
        // χ = γ⁽⁶⁴⁾_{n+1} (‖|R|‖₂‖R⁻¹‖₂)², with Frobenius norms as upper bounds and a factor 2 for safety.
        let fr = norm2(R.iter().copied());
        let fri = norm2(Ri.iter().copied());
        let chi = 2.0 * gamma(n + 1, U64) * (fr * fri).powi(2);
        let k = (1.0 + chi).sqrt();
        // a_j = sqrt((P⁻¹)_jj) = ‖row j of R⁻¹‖₂ (P⁻¹ = R⁻¹R⁻ᵀ), with a relative allowance for the
        // computed inverse, then a' = a·sqrt(1 + χ).
        let a: Vec<f64> = (0..n)
            .map(|j| norm2((0..n).map(|q| Ri[j * n + q])) * (1.0 + 1e-6) * k)
            .collect();
        let gn = gamma(n, U32);
        // G = γ_n|R̂| + D and |R|, upper triangular.
        let G =
            |i: usize, j: usize| gn * Rh[i * n + j].abs() + (Rh[i * n + j] - R[i * n + j]).abs();
        let absR = |i: usize, j: usize| R[i * n + j].abs();
        let apply = |M: &dyn Fn(usize, usize) -> f64, v: &[f64]| -> f64 {
            norm2((0..n).map(|i| (i..n).map(|j| M(i, j) * v[j]).sum::<f64>()))
        };
        let absc: Vec<f64> = c.iter().map(|v| v.abs()).collect();
        let ones = vec![1.0; n];
        // e_c = ĉ_z − R c, measured, plus the f64 error of forming R c.
        let g64 = gamma(n + 1, U64);
        let ec = norm2((0..n).map(|i| {
            let rc: f64 = (i..n).map(|j| R[i * n + j] * c[j]).sum();
            let rc_abs: f64 = (i..n).map(|j| absR(i, j) * absc[j]).sum();
            (cz[i] - rc).abs() + g64 * (rc_abs + cz[i].abs())
        }));
        let alpha = apply(&G, &a) + U32 * apply(&absR, &a);
        let nf = n as f64;
        let beta = apply(&G, &absc)
            + U32 * apply(&absR, &absc)
            + ec
            + (2.0 * nf * nf.sqrt() + apply(&absR, &ones)) * ETA;
        // Completeness: X = |c| + a'r bounds |x|, X̂ = (1 + u)X + η𝟙 bounds |x̂|, and
        // ‖R(x − c)‖ ≤ r/sqrt(1 − χ), so ‖w + f‖ ≤ t0 + t1·r (module doc).
        let t1 = 1.0 / (1.0 - chi).sqrt() + U32 * apply(&absR, &a) + (1.0 + U32) * apply(&G, &a);
        let t0 = U32 * apply(&absR, &absc)
            + ETA * apply(&absR, &ones)
            + (1.0 + U32) * apply(&G, &absc)
            + ETA * apply(&G, &ones)
            + ec
            + 2.0 * nf * nf.sqrt() * ETA;
        (alpha.is_finite()
            && beta.is_finite()
            && alpha < 0.5
            && chi < 0.5
            && t0.is_finite()
            && t1.is_finite())
        .then_some(AcceptBound {
            n,
            alpha,
            beta,
            k,
            t0,
            t1,
        })
    }

    /// S_ρ(ρ̂) = sqrt((ρ̂²(1 + u) + (2n + 1)η)/(1 − γ_n))/(1 − u): the largest ‖w + f‖ acceptance allows
    /// with threshold fl32(ρ̂·ρ̂).
    fn s_of_rho(&self, rho: f64) -> f64 {
        let extra = (2 * self.n + 1) as f64 * ETA;
        ((rho * rho * (1.0 + U32) + extra) / (1.0 - gamma(self.n, U32))).sqrt() / (1.0 - U32)
    }

    /// S(ŝ) = sqrt((ŝ + 2nη)/(1 − γ_n))/(1 − u): the largest ‖w + f‖ acceptance allows with threshold ŝ.
    fn s_of_threshold(&self, s: f64) -> f64 {
        let extra = (2 * self.n) as f64 * ETA;
        ((s + extra) / (1.0 - gamma(self.n, U32))).sqrt() / (1.0 - U32)
    }

    /// Upper bound on ‖x − c‖_P over accepted states, from S.
    fn radius_of_s(&self, s_bound: f64) -> f64 {
        self.k * (s_bound + self.beta) / (1.0 - self.alpha) * (1.0 + HOST_SLACK)
    }

    /// Upper bound on ‖x − c‖_P over accepted states for threshold fl32(ρ̂·ρ̂).
    fn radius(&self, rho: f64) -> f64 {
        self.radius_of_s(self.s_of_rho(rho))
    }

    /// Radius r such that every real x with ‖x − c‖_P ≤ r is accepted with threshold ŝ: the largest r with
    /// (1 + γ_n)(1 + u)²(t0 + t1 r)² + 2nη ≤ ŝ, less the host's slack; 0 when none is positive.
    fn complete_radius(&self, s: f64) -> f64 {
        let extra = (2 * self.n) as f64 * ETA;
        let room = (s - extra) / ((1.0 + gamma(self.n, U32)) * (1.0 + U32).powi(2));
        if !(room > 0.0) {
            return 0.0;
        }
        let r = (room.sqrt() * (1.0 - HOST_SLACK) - self.t0) / self.t1 * (1.0 - HOST_SLACK);
        if r > 0.0 {
            r
        } else {
            0.0
        }
    }
}

/// Upper bound on `‖x − c‖_P` over every f32 state x̂ that the evaluator's whitened test accepts for a
/// ball stored as (`Rh`, `cz`, `threshold`), and every real x with `fl32(x) = x̂` (module doc; derivation
/// in `shared_types::pwa`): acceptance means the computed squared whitened distance is ≤ the stored
/// threshold ŝ. `P` is the metric (n × n), `Rh` the stored factor (n × n row-major, f32 values), `c` the
/// centre the bound is about, `cz` the stored whitened centre. `+∞` when the data do not admit a bound (P
/// not positive definite, shapes wrong, α ≥ 1/2, or ŝ negative or not finite).
pub fn pwa_accept_radius(
    P: MatRef<'_, f64>,
    Rh: &[f64],
    c: &[f64],
    cz: &[f64],
    threshold: f32,
) -> f64 {
    match AcceptBound::new(P, Rh, c, cz) {
        Some(b) if threshold >= 0.0 && threshold.is_finite() => {
            b.radius_of_s(b.s_of_threshold(threshold as f64))
        }
        _ => f64::INFINITY,
    }
}

/// Radius r_in about `c` such that every real state x with `‖x − c‖_P ≤ r_in` is accepted by the
/// evaluator's whitened f32 test of a ball stored as (`Rh`, `cz`, `threshold`), when the evaluator is given
/// `x̂ = fl32(x)` (module doc, "Completeness"; derivation in `shared_types::pwa`): the converse of
/// [`pwa_accept_radius`]. 0 when the data admit no positive radius (same failure cases as
/// [`pwa_accept_radius`], or a threshold too small for the rounding at c).
pub fn pwa_complete_radius(
    P: MatRef<'_, f64>,
    Rh: &[f64],
    c: &[f64],
    cz: &[f64],
    threshold: f32,
) -> f64 {
    match AcceptBound::new(P, Rh, c, cz) {
        Some(b) if threshold >= 0.0 && threshold.is_finite() => b.complete_radius(threshold as f64),
        _ => 0.0,
    }
}

/// [`pwa_complete_radius`] of the ball the emitter stores for `B_P(c, δ)`: factor [`metric_factor_f32`],
/// whitened centre [`whitened_centre`] of fl32(c), threshold [`pwa_ball_threshold`]. 0 where that ball
/// has no threshold.
pub fn pwa_ball_complete_radius(P: MatRef<'_, f64>, c: &[f64], delta: f64) -> f64 {
    let n = P.nrows();
    let (Some(Rh), Some(s)) = (
        metric_factor_f32(&crate::linalg::to_row_major(P), n),
        pwa_ball_threshold(P, c, delta),
    ) else {
        return 0.0;
    };
    let cz = whitened_centre(&Rh, c);
    pwa_complete_radius(P, &Rh, c, &cz, s)
}

/// The squared threshold ŝ to store for the certified ball `B_P(c, δ)` of a PWA image: `fl32(ρ̂·ρ̂)` with
/// ρ̂ = [`pwa_ball_radius`] (module doc; its [`pwa_accept_radius`] is ≤ δ). `None` where
/// [`pwa_ball_radius`] is `None` or the square overflows.
pub fn pwa_ball_threshold(P: MatRef<'_, f64>, c: &[f64], delta: f64) -> Option<f32> {
    pwa_ball_radius(P, c, delta).and_then(threshold_of_radius)
}

/// `fl32(ρ̂·ρ̂)`, the stored threshold for radius ρ̂ (one f32 multiplication, as the evaluator of image
/// format 2 computed it per step); `None` if ρ̂ is negative or the square is not finite.
pub fn threshold_of_radius(rho: f32) -> Option<f32> {
    let s = rho * rho;
    (rho >= 0.0 && s.is_finite()).then_some(s)
}

/// The radius ρ̂ behind the threshold ŝ = fl32(ρ̂·ρ̂) stored for the certified ball `B_P(c, δ)` of a PWA image (module doc): the largest f32
/// whose [`pwa_accept_radius`] is ≤ δ, with the factor [`metric_factor_f32`] and the whitened centre
/// [`whitened_centre`] of `fl32(c)` that the emitter stores. `None` if no radius ≥ 0 is certified (δ too
/// small for the f32 resolution at c, or P not positive definite).
pub fn pwa_ball_radius(P: MatRef<'_, f64>, c: &[f64], delta: f64) -> Option<f32> {
    let n = P.nrows();
    let Rh = metric_factor_f32(&crate::linalg::to_row_major(P), n)?;
    let cz = whitened_centre(&Rh, c);
    let b = AcceptBound::new(P, &Rh, c, &cz)?;
    if delta.is_nan() || delta < 0.0 || b.radius(0.0) > delta {
        return None;
    }
    // Closed form of radius(ρ) = δ, then step down until the forward bound holds (it is monotone in ρ).
    let s_star = delta * (1.0 - b.alpha) / (b.k * (1.0 + HOST_SLACK)) - b.beta;
    let gn = gamma(n, U32);
    let rho2 = (s_star.max(0.0).powi(2) * (1.0 - U32).powi(2) * (1.0 - gn)
        - (2 * n + 1) as f64 * ETA)
        / (1.0 + U32);
    let mut rho = round_down_f32(rho2.max(0.0).sqrt());
    while rho > 0.0 && b.radius(rho as f64) > delta {
        rho = rho.next_down();
    }
    (b.radius(rho as f64) <= delta).then_some(rho)
}
