//! The synthesis programs: the metric stage (condition number of P), the gain stage (smallest K), the joint
//! alternative, and the normalisation/validation that turns a solver answer into a [`Caf`].
// A status (`CafOutcome`) travels in the inner `Err` of the stage helpers; its size does not matter here.
#![allow(clippy::result_large_err)]

use super::pbh::uncontrollable_modes;
use super::sdp::{rect_from, sym_from, Sdp};
use super::validate::certify;
use super::{Caf, CafError, CafOutcome, CafSettings, Formulation, TimeKind};
use crate::model::{ContinuousPlant, DiscretePlant};
use clarabel::solver::{DefaultSettings, DefaultSettingsBuilder, SolverStatus};
use faer::{Mat, MatRef, Side};

/// Discrete-time synthesis for x⁺ = A x + B u + g: LMIs (3.66)–(3.67) with the margin of Remark 3.22.
pub fn synthesize_discrete(
    plant: &DiscretePlant,
    settings: &CafSettings,
) -> Result<CafOutcome, CafError> {
    synthesize(
        TimeKind::Discrete,
        plant.A.as_ref(),
        plant.B.as_ref(),
        settings,
    )
}

/// Continuous-time synthesis for ẋ = A x + B u + c: LMI (3.8) with a margin, for reporting.
pub fn synthesize_continuous(
    plant: &ContinuousPlant,
    settings: &CafSettings,
) -> Result<CafOutcome, CafError> {
    synthesize(
        TimeKind::Continuous,
        plant.A.as_ref(),
        plant.B.as_ref(),
        settings,
    )
}

fn identity(n: usize) -> Mat<f64> {
    Mat::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 })
}

fn check_inputs(A: MatRef<'_, f64>, B: MatRef<'_, f64>) -> Result<(), CafError> {
    let n = A.nrows();
    if n == 0 || A.ncols() != n {
        return Err(CafError::Dimension {
            what: "A",
            expected: "a non-empty square matrix".into(),
            got: format!("{}×{}", n, A.ncols()),
        });
    }
    if B.nrows() != n || B.ncols() == 0 {
        return Err(CafError::Dimension {
            what: "B",
            expected: format!("{n}×m with m ≥ 1"),
            got: format!("{}×{}", B.nrows(), B.ncols()),
        });
    }
    let finite =
        |M: MatRef<'_, f64>| (0..M.ncols()).all(|j| (0..M.nrows()).all(|i| M[(i, j)].is_finite()));
    if !finite(A) {
        return Err(CafError::NonFinite { what: "A" });
    }
    if !finite(B) {
        return Err(CafError::NonFinite { what: "B" });
    }
    Ok(())
}

fn clarabel_settings(s: &CafSettings) -> DefaultSettings<f64> {
    DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(s.max_iter)
        .time_limit(s.time_limit)
        .tol_gap_abs(s.solver_tol)
        .tol_gap_rel(s.solver_tol)
        .tol_feas(s.solver_tol)
        .build()
        .expect("every field set here is in clarabel's valid range")
}

/// Orthonormal basis of the left null space of B (columns), and the numerical rank of B.
fn left_null_space(B: MatRef<'_, f64>) -> Result<(Mat<f64>, usize), CafError> {
    let n = B.nrows();
    let svd = B.svd().map_err(|_| CafError::NonFinite {
        what: "B (SVD did not converge)",
    })?;
    let s = svd.S().column_vector();
    let smax = if s.nrows() > 0 { s[0] } else { 0.0 };
    let tol = smax * (n.max(B.ncols()) as f64) * f64::EPSILON * 16.0;
    let r = (0..s.nrows()).filter(|&i| s[i] > tol).count();
    let U = svd.U();
    Ok((Mat::from_fn(n, n - r, |i, j| U[(i, r + j)]), r))
}

/// What a clarabel status means for us: `Ok(())` to go on, or the outcome to report.
fn interpret(status: SolverStatus, stage: &str) -> Result<(), CafOutcome> {
    match status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(()),
        SolverStatus::PrimalInfeasible | SolverStatus::AlmostPrimalInfeasible => {
            Err(CafOutcome::Infeasible {
                stage: stage.into(),
                status: format!("{status:?}"),
            })
        }
        other => Err(CafOutcome::SolverFailed {
            stage: stage.into(),
            status: format!("{other:?}"),
        }),
    }
}

/// The common driver; see the `caf` module docs for the programs.
pub fn synthesize(
    time: TimeKind,
    A: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    settings: &CafSettings,
) -> Result<CafOutcome, CafError> {
    settings.validate()?;
    check_inputs(A, B)?;
    let sigma = settings.sigma;
    if time == TimeKind::Discrete && sigma >= 1.0 {
        return Err(CafError::Settings {
            field: "sigma",
            value: sigma,
            rule: "must be < 1 in discrete time (P − ÃᵀPÃ ⪯ P)",
        });
    }
    let (n, m) = (A.nrows(), B.ncols());

    // Decay asked of the metric stage, γ₁ = (1 + η)σ, capped below what the plant allows.
    let mut gamma1 = sigma * (1.0 + settings.stage_slack);
    if time == TimeKind::Discrete {
        gamma1 = gamma1.min(0.5 * (1.0 + sigma));
    }
    // PBH: unstable uncontrollable modes make the problem unsolvable; slow ones bound the decay.
    for mode in uncontrollable_modes(A, B, settings.pbh_tol)? {
        let lam = mode.eigenvalue;
        // The fastest ψ-decay any gain can give along this mode, in the units of σ.
        let (unstable, max_decay) = match time {
            TimeKind::Discrete => (lam.norm() >= 1.0, 1.0 - lam.norm_sqr()),
            TimeKind::Continuous => (lam.re >= 0.0, -2.0 * lam.re),
        };
        if unstable {
            return Ok(CafOutcome::NotStabilizable { mode });
        }
        if max_decay <= sigma {
            return Ok(CafOutcome::MarginUnachievable {
                mode,
                max_sigma: max_decay,
            });
        }
        if max_decay < gamma1 {
            gamma1 = 0.5 * (sigma + max_decay);
        }
    }

    // ---- Stage 1: the metric. Variables: Q (upper triangle), [Y row-major if joint], s. ----
    let nq = n * (n + 1) / 2;
    let joint = settings.formulation == Formulation::Joint;
    let ny = if joint { m * n } else { 0 };
    let nvars = nq + ny + 1;
    let s_var = nvars - 1;
    let mut sdp = Sdp::new(nvars);
    // (3.66) read as a normalisation of P = Q⁻¹: Q ⪯ I, i.e. P ⪰ I (3.62).
    sdp.add_lmi(&identity(n), |x| -sym_from(x, 0, n));
    // Q ⪰ s I, i.e. λ_max(P) ≤ 1/s: maximising s minimises the condition-number bound of P.
    sdp.add_lmi(&Mat::zeros(n, n), |x| {
        sym_from(x, 0, n) - identity(n) * x[s_var]
    });
    sdp.add_lower_bound(s_var, 1.0 / settings.max_condition);
    sdp.add_linear_cost(s_var, -1.0);
    let At = A.transpose();
    match (time, joint) {
        (TimeKind::Discrete, false) => {
            // ∃Y with (3.67)+margin ⇔ N_Bᵀ((1−γ₁)Q − A Q Aᵀ) N_B ⪰ 0 (projection lemma).
            let (N, _) = left_null_space(B)?;
            let k = N.ncols();
            if k > 0 {
                sdp.add_lmi(&Mat::zeros(k, k), |x| {
                    let Q = sym_from(x, 0, n);
                    let inner = &Q * (1.0 - gamma1) - A * &Q * At;
                    N.transpose() * inner * &N
                });
            }
        }
        (TimeKind::Continuous, false) => {
            // ∃Y with A Q + Q Aᵀ + B Y + Yᵀ Bᵀ + γ₁ Q ⪯ 0 ⇔ N_Bᵀ(A Q + Q Aᵀ + γ₁ Q) N_B ⪯ 0.
            let (N, _) = left_null_space(B)?;
            let k = N.ncols();
            if k > 0 {
                sdp.add_lmi(&Mat::zeros(k, k), |x| {
                    let Q = sym_from(x, 0, n);
                    let AQ = A * &Q;
                    let inner = &AQ + AQ.transpose() + &Q * gamma1;
                    -(N.transpose() * inner * &N)
                });
            }
        }
        (TimeKind::Discrete, true) => {
            // (3.67) with the margin: [[(1−γ₁)Q, AQ + BY], [(AQ + BY)ᵀ, Q]] ⪰ 0.
            sdp.add_lmi(&Mat::zeros(2 * n, 2 * n), |x| {
                let Q = sym_from(x, 0, n);
                let Y = rect_from(x, nq, m, n);
                let M = A * &Q + B * &Y;
                Mat::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
                    (true, true) => (1.0 - gamma1) * Q[(i, j)],
                    (true, false) => M[(i, j - n)],
                    (false, true) => M[(j, i - n)],
                    (false, false) => Q[(i - n, j - n)],
                })
            });
        }
        (TimeKind::Continuous, true) => {
            // (3.8) with the margin: −(A Q + B Y + Q Aᵀ + Yᵀ Bᵀ + γ₁ Q) ⪰ 0.
            sdp.add_lmi(&Mat::zeros(n, n), |x| {
                let Q = sym_from(x, 0, n);
                let Y = rect_from(x, nq, m, n);
                let M = A * &Q + B * &Y;
                -(&M + M.transpose() + &Q * gamma1)
            });
        }
    }
    let res = sdp
        .solve(clarabel_settings(settings))
        .map_err(CafError::Solver)?;
    tracing::debug!(status = ?res.status, iterations = res.iterations, s = res.x[s_var], "CAF metric stage");
    if let Err(outcome) = interpret(res.status, "metric") {
        return Ok(outcome);
    }
    let Q = sym_from(&res.x, 0, n);

    // P = λ_max(Q) Q⁻¹, so that λ_min(P) = 1.
    let Some(P) = normalised_inverse(&Q) else {
        return Ok(CafOutcome::ValidationFailed {
            reason: "the metric stage returned a Q that is not positive definite".into(),
        });
    };

    // ---- Stage 2: the gain. ----
    let K = if joint {
        let Y = rect_from(&res.x, nq, m, n);
        // K = Y Q⁻¹, solved as Q Kᵀ = Yᵀ.
        let Kt = Q
            .llt(Side::Lower)
            .map(|c| faer::linalg::solvers::Solve::solve(&c, Y.transpose().to_owned()));
        match Kt {
            Ok(Kt) => Kt.transpose().to_owned(),
            Err(_) => {
                return Ok(CafOutcome::ValidationFailed {
                    reason: "the metric stage returned a Q that is not positive definite".into(),
                })
            }
        }
    } else {
        match gain_stage(time, A, B, &P, sigma, settings)? {
            Ok(K) => K,
            Err(outcome) => return Ok(outcome),
        }
    };

    finish(time, A, B, K, P, settings)
}

/// λ_max(Q) Q⁻¹ (symmetrised), or `None` if Q is not positive definite.
fn normalised_inverse(Q: &Mat<f64>) -> Option<Mat<f64>> {
    let n = Q.nrows();
    let evd = Q.self_adjoint_eigen(Side::Lower).ok()?;
    let lam = evd.S().column_vector();
    if !(lam[0] > 0.0) || !lam[n - 1].is_finite() {
        return None;
    }
    let U = evd.U();
    let top = lam[n - 1];
    let P = Mat::from_fn(n, n, |i, j| {
        (0..n)
            .map(|k| U[(i, k)] * (top / lam[k]) * U[(j, k)])
            .sum::<f64>()
    });
    Some(Mat::from_fn(n, n, |i, j| 0.5 * (P[(i, j)] + P[(j, i)])))
}

/// The smallest-Frobenius-norm gain K certifying the margin σ for the fixed metric P.
fn gain_stage(
    time: TimeKind,
    A: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    P: &Mat<f64>,
    sigma: f64,
    settings: &CafSettings,
) -> Result<Result<Mat<f64>, CafOutcome>, CafError> {
    let (n, m) = (A.nrows(), B.ncols());
    let nk = m * n;
    let mut sdp = Sdp::new(nk);
    for v in 0..nk {
        sdp.add_square_cost(v, 1.0);
    }
    let PB = P * B;
    match time {
        TimeKind::Discrete => {
            // P − σI − ÃᵀPÃ ⪰ 0 with ÃᵀPÃ = ZᵀZ + CᵀC, where P = L Lᵀ, Lᵀ B = U_b Σ_b V_bᵀ (rank r),
            // Z = U_bᵀ Lᵀ A + Σ_b V_bᵀ K and C = (I − U_b U_bᵀ) Lᵀ A: equivalently
            // [[I_r, Z], [Zᵀ, P − σI − CᵀC]] ⪰ 0, an LMI of size r + n.
            let Some(L) = P.llt(Side::Lower).ok().map(|c| c.L().to_owned()) else {
                return Ok(Err(CafOutcome::ValidationFailed {
                    reason: "the normalised metric P is not positive definite".into(),
                }));
            };
            let LtB = L.transpose() * B;
            let svd = LtB.thin_svd().map_err(|_| CafError::NonFinite {
                what: "LᵀB (SVD did not converge)",
            })?;
            let s = svd.S().column_vector();
            let tol = if s.nrows() > 0 {
                s[0] * 16.0 * (n.max(m) as f64) * f64::EPSILON
            } else {
                0.0
            };
            let r = (0..s.nrows()).filter(|&i| s[i] > tol).count();
            if r == 0 {
                return Ok(Ok(Mat::zeros(m, n)));
            }
            let Ub = svd.U().subcols(0, r).to_owned();
            let Vb = svd.V().subcols(0, r).to_owned();
            let sv: Vec<f64> = (0..r).map(|i| s[i]).collect();
            let LtA = L.transpose() * A;
            let Z0 = Ub.transpose() * &LtA;
            let C = &LtA - &Ub * &Z0;
            let corner = P - identity(n) * sigma - C.transpose() * &C;
            let constant = Mat::from_fn(r + n, r + n, |i, j| match (i < r, j < r) {
                (true, true) => {
                    if i == j {
                        1.0
                    } else {
                        0.0
                    }
                }
                (true, false) => Z0[(i, j - r)],
                (false, true) => Z0[(j, i - r)],
                (false, false) => corner[(i - r, j - r)],
            });
            let SVt = Mat::from_fn(r, m, |i, j| sv[i] * Vb[(j, i)]);
            sdp.add_lmi(&constant, |x| {
                let Kx = rect_from(x, 0, m, n);
                let Z = &SVt * &Kx;
                Mat::from_fn(r + n, r + n, |i, j| match (i < r, j < r) {
                    (true, true) | (false, false) => 0.0,
                    (true, false) => Z[(i, j - r)],
                    (false, true) => Z[(j, i - r)],
                })
            });
        }
        TimeKind::Continuous => {
            // −(ÃᵀP + PÃ) − σI ⪰ 0, linear in K.
            let AtP = A.transpose() * P;
            let constant = Mat::from_fn(n, n, |i, j| {
                -(AtP[(i, j)] + AtP[(j, i)]) - if i == j { sigma } else { 0.0 }
            });
            sdp.add_lmi(&constant, |x| {
                let Kx = rect_from(x, 0, m, n);
                let PBK = &PB * &Kx;
                Mat::from_fn(n, n, |i, j| -(PBK[(i, j)] + PBK[(j, i)]))
            });
        }
    }
    let res = sdp
        .solve(clarabel_settings(settings))
        .map_err(CafError::Solver)?;
    tracing::debug!(status = ?res.status, iterations = res.iterations, "CAF gain stage");
    if let Err(outcome) = interpret(res.status, "gain") {
        return Ok(Err(outcome));
    }
    Ok(Ok(rect_from(&res.x, 0, m, n)))
}

/// Validate (K, P) independently; if the solver's tolerance left λ_min(P) or the margin a hair short, scale P
/// up (both scale linearly with P) and validate again.
fn finish(
    time: TimeKind,
    A: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    K: Mat<f64>,
    mut P: Mat<f64>,
    settings: &CafSettings,
) -> Result<CafOutcome, CafError> {
    let sigma = settings.sigma;
    let Some(c0) = certify(time, A, B, K.as_ref(), P.as_ref()) else {
        return Ok(CafOutcome::ValidationFailed {
            reason: "non-finite gain or metric".into(),
        });
    };
    let mut factor: f64 = 1.0;
    if c0.lambda_min_P > 0.0 && c0.lambda_min_P < 1.0 {
        factor = factor.max(1.0 / c0.lambda_min_P);
    }
    if sigma > 0.0 && c0.margin > 0.0 && c0.margin < sigma {
        factor = factor.max(sigma / c0.margin);
    }
    if factor > 1.0 {
        // A shortfall beyond the solver tolerance means the answer is wrong, not imprecise.
        if factor > 1.0 + 1e-4 {
            return Ok(CafOutcome::ValidationFailed {
                reason: format!(
                    "validated λ_min(P) = {:.3e}, margin = {:.3e} (required 1 and {sigma:.3e})",
                    c0.lambda_min_P, c0.margin
                ),
            });
        }
        let f = factor * (1.0 + 1e-9);
        P = Mat::from_fn(P.nrows(), P.ncols(), |i, j| P[(i, j)] * f);
    }
    let Some(cert) = certify(time, A, B, K.as_ref(), P.as_ref()) else {
        return Ok(CafOutcome::ValidationFailed {
            reason: "non-finite gain or metric".into(),
        });
    };
    let margin_ok = if sigma > 0.0 {
        cert.margin >= sigma
    } else {
        cert.margin >= -settings.nonstrict_tol * cert.lambda_max_P
    };
    if !(cert.lambda_min_P >= 1.0) || !margin_ok {
        return Ok(CafOutcome::ValidationFailed {
            reason: format!(
                "validated λ_min(P) = {:.3e}, margin = {:.3e} (required 1 and {sigma:.3e})",
                cert.lambda_min_P, cert.margin
            ),
        });
    }
    if cert.condition > settings.max_condition {
        return Ok(CafOutcome::Infeasible {
            stage: "validation".into(),
            status: format!(
                "condition number {:.3e} exceeds max_condition",
                cert.condition
            ),
        });
    }
    Ok(CafOutcome::Solved(Caf {
        time,
        A: A.to_owned(),
        B: B.to_owned(),
        K,
        P,
        sigma,
        formulation: settings.formulation,
        certificate: cert,
    }))
}
