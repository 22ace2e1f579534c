//! The certificate of a terminal law as the image stores it (issue 17, item 2): the f32 values of
//! section 11 ([`shared_types::terminal`]) taken as exact numbers, checked against the task's plant and
//! sets. `synth` runs it before it writes the section and `verify` runs it again on the image bytes.
//!
//! Stored: x_e, K_t, v_t, P_t and the acceptance radius r̂. Let E_ρ = {x : ‖x − x_e‖_{P_t} ≤ ρ} and
//! u_e = K_t x_e + v_t. The law is certified when, for the sampled plant x⁺ = A x + B u + g (exact
//! zero-order hold of ẋ = A x + B u + c for a continuous plant):
//! 1. **acceptance lies in E_1**: the f32 handover test with r̂ accepts only states of E_1
//!    ([`super::selection_radius`] at radius 1 is at least r̂);
//! 2. **rounding**: on E_1 the evaluator's input is K_t x + v_t + ε with |ε_i| ≤ ε_i
//!    ([`super::evaluator_error_bound`] over the box hull of E_1);
//! 3. **inputs**: every such input lies in the input set (the P_t-distance from x_e to the states whose
//!    input leaves the set shrunk by ε is at least 1, [`super::input_distance`]);
//! 4. **invariance**: the next sample lies within θ = ‖A + BK_t‖_{P_t} + ‖A x_e + B u_e + g − x_e‖_{P_t} +
//!    ‖P_t^{1/2}B‖₂‖ε‖₂ of x_e, and every state within θ is accepted again ([`super::selection_floor`]):
//!    once handed over, the terminal law keeps the run and the test keeps passing, for ever;
//! 5. **between samples** (continuous plants): with the input held, x(κh + s) − x_e = M(s)(x_κ − x_e) +
//!    Γ(s)(B ε + f_e), M(s) = e^{As} + Γ(s)BK_t, Γ(s) = ∫₀ˢ e^{Aτ}dτ, f_e = A x_e + B u_e + c. So the run
//!    stays within R = sup_s ‖M(s)‖_{P_t} + sup_s ‖Γ(s)‖_{P_t}(‖P_t^{1/2}B‖₂‖ε‖₂ + ‖f_e‖_{P_t}) of x_e.
//!    sup_s ‖M(s)‖_{P_t} is bounded by its maximum over a grid of [0, h] plus half the spacing times
//!    the Lipschitz constant e^{‖A‖_{P_t}h}‖A + BK_t‖_{P_t} (M'(s) = e^{As}(A + BK_t)), and
//!    ‖Γ(s)‖_{P_t} ≤ s e^{‖A‖_{P_t}s}. R = 1 for a plant in discrete time;
//! 6. **Goal and Unsafe**: the P_t-depth of x_e in Goal is at least R and its P_t-distance to Unsafe
//!    exceeds R, so E_1 and everything between its samples lie in Goal and away from Unsafe.
//!
//! Together: a run handed over at any sample is in Goal then and at every later instant, never in Unsafe,
//! with every input in the input set. That is the reach-avoid property completed, so the handover may
//! happen whenever the test accepts (before T as well).
//!
//! # Handed over before it can leave Goal (issue 42, item 4)
//! A run that reaches Goal but not the handover test's acceptance would keep the table (its last row
//! after the end) or the PWA law, which certify nothing past Goal. So where a law is certified, the task
//! the cover is certified for has the **handover region** H = {x : ‖x − x_e‖_{P_t} ≤ ρ_h} as its Goal
//! ([`handover_radius`]: ρ_h is [`super::selection_floor`] of the stored r̂, within which the f32 test
//! provably accepts every state, its quantisation to f32 included, shrunk by a relative 10⁻⁶). H lies in
//! E_1, hence in Goal (item 6), so a run certified to reach H within T reaches Goal within T: the original
//! task is implied. At the sample κ* at which a certified ball's tube lies in H, the evaluator's first act
//! of the step is the handover test, which accepts: every run is handed over by κ* at the latest (earlier
//! where the test accepts earlier), and items 4–6 keep it in Goal and out of Unsafe from then on, between
//! samples too. Before the handover the cover's certificate holds as ever: Unsafe and the inputs over the
//! whole table, between samples too. And from the first sample at which the whole tube lies in Goal until
//! κ*, the tube stays in Goal at the samples and between them ([`super::LoopConstants::stay_in`]): in the
//! tube's terms, no run leaves Goal before its handover. A PWA image built from that cover ends its
//! successor chains in H too (`verify::pwa` rechecks liveness with H from the image's own bytes).

// Negated comparisons (`!(x >= y)`) are deliberate: they reject NaN as well.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::{evaluator_error_bound, input_distance, selection_floor, selection_radius, tube_abs};
use crate::geometry::Metric;
use crate::linalg::{mat_vec, p_norm, PdRoots};
use crate::model::{expm, Plant};
use crate::property::ReachAvoid;
use faer::{Mat, MatRef};

/// Grid intervals over one period for sup_s ‖M(s)‖ (item 5).
const INTERSAMPLE_GRID: usize = 32;

/// A terminal law in f64, holding exactly the values the image stores.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredTerminal {
    /// The equilibrium x_e (n).
    pub x_e: Vec<f64>,
    /// K_t (m×n).
    pub K: Mat<f64>,
    /// v_t = u_e − K_t x_e (m).
    pub v: Vec<f64>,
    /// P_t (n×n, symmetric).
    pub P: Mat<f64>,
    /// The acceptance radius r̂.
    pub radius: f32,
}

impl StoredTerminal {
    /// The law's input at the equilibrium, u_e = K_t x_e + v_t.
    pub fn u_e(&self) -> Vec<f64> {
        mat_vec(self.K.as_ref(), &self.x_e)
            .iter()
            .zip(&self.v)
            .map(|(a, b)| a + b)
            .collect()
    }
}

/// The figures of the certificate (module doc, items 1–6), all computed from the stored values.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TerminalCertificate {
    /// Item 1: the radius the f32 test's acceptance is proved inside (≥ 1 needed: selection_radius at
    /// radius 1 over r̂, as a ratio).
    pub acceptance_inside: f64,
    /// Item 2: ‖ε‖₂ over E_1.
    pub rounding: f64,
    /// Item 3: P_t-distance from x_e to the states whose input leaves the shrunk input set (≥ 1 needed).
    pub input_distance: f64,
    /// Item 4: ‖A + BK_t‖_{P_t}.
    pub contraction: f64,
    /// Item 4: θ, the radius the next sample lies within.
    pub theta: f64,
    /// Item 4: the radius within which the test accepts every state (> θ needed).
    pub acceptance_floor: f64,
    /// Item 5: R, the radius the run stays within between samples.
    pub between_samples: f64,
    /// Item 6: P_t-depth of x_e in Goal (≥ R needed).
    pub goal_depth: f64,
    /// Item 6: P_t-distance from x_e to Unsafe (> R needed; infinite without Unsafe).
    pub unsafe_distance: f64,
}

/// The first condition of the certificate that fails, with its figures.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TerminalRefusal {
    #[error("the terminal law's P_t is not positive definite")]
    Metric,
    #[error("the f32 handover test may accept states outside the certified ellipsoid (stored radius {stored} above the proved {proved})")]
    Acceptance { stored: f32, proved: f32 },
    #[error("inputs of the terminal law leave the input set inside its ellipsoid (distance {0:.4e} < 1)")]
    Input(f64),
    #[error("the ellipsoid is not invariant for the f32 loop: the next sample lies within {theta:.6}, but the handover test is only proved to accept within {floor:.6}")]
    Invariance { theta: f64, floor: f64 },
    #[error("the ellipsoid leaves Goal (between samples the run stays within {needed:.6}, the depth of x_e in Goal is {depth:.6}, in the ellipsoid's metric)")]
    Goal { needed: f64, depth: f64 },
    #[error("the ellipsoid comes within {distance:.6} of Unsafe (the run stays within {needed:.6} of x_e), in the ellipsoid's metric")]
    Unsafe { needed: f64, distance: f64 },
    #[error("{0}")]
    Compute(String),
}

/// The certificate of `law` for the task's plant (location 0) and sets; `Err` names the first condition
/// that fails. A plant with a model mismatch (a feedback-linearizable plant) is refused by the caller.
pub fn certify(
    plant: &dyn Plant,
    property: &ReachAvoid,
    law: &StoredTerminal,
) -> Result<TerminalCertificate, TerminalRefusal> {
    let n = plant.n();
    let d = plant.error_dynamics(0);
    let roots = PdRoots::new(law.P.as_ref()).ok_or(TerminalRefusal::Metric)?;
    let c = &law.x_e;
    // 1. Acceptance inside E_1.
    let proved = selection_radius(law.P.as_ref(), c, 1.0);
    if law.radius > proved {
        return Err(TerminalRefusal::Acceptance {
            stored: law.radius,
            proved,
        });
    }
    // 2. Rounding over the box hull of E_1.
    let axis: Vec<f64> = (0..n).map(|i| roots.inv[(i, i)].max(0.0).sqrt()).collect();
    let X = tube_abs(c, 1.0, &axis);
    let eps = evaluator_error_bound(law.K.as_ref(), &law.v, &X);
    let eps2 = eps.iter().map(|e| e * e).sum::<f64>().sqrt();
    // 3. Inputs.
    let u_e = law.u_e();
    let input_dist = input_distance(law.K.as_ref(), &roots, &u_e, &property.input, &eps);
    if !(input_dist >= 1.0) {
        return Err(TerminalRefusal::Input(input_dist));
    }
    // 4. Invariance at the samples.
    let A_cl = &d.A + &d.B * &law.K;
    let contraction = roots.induced_norm(A_cl.as_ref());
    let next_e: Vec<f64> = {
        let ax = mat_vec(d.A.as_ref(), c);
        let bu = mat_vec(d.B.as_ref(), &u_e);
        (0..n).map(|i| ax[i] + bu[i] + d.g[i] - c[i]).collect()
    };
    let b_eps = roots.norm_into(d.B.as_ref()) * eps2;
    let theta = contraction + p_norm(law.P.as_ref(), &next_e) + b_eps;
    let floor = selection_floor(law.P.as_ref(), c, law.radius, 1.0);
    if !(theta < floor) {
        return Err(TerminalRefusal::Invariance { theta, floor });
    }
    // 5. Between samples.
    let between = match plant.continuous(0) {
        None => 1.0,
        Some(cp) => {
            let h = plant.period();
            let f_e: Vec<f64> = {
                let ax = mat_vec(cp.A.as_ref(), c);
                let bu = mat_vec(cp.B.as_ref(), &u_e);
                (0..n).map(|i| ax[i] + bu[i] + cp.c[i]).collect()
            };
            let a_w = roots.induced_norm(cp.A.as_ref());
            let cl = &cp.A + &cp.B * &law.K;
            let lip = (a_w * h).exp() * roots.induced_norm(cl.as_ref());
            let sup_m = sup_m_on_grid(cp.A.as_ref(), cp.B.as_ref(), law.K.as_ref(), &roots, h)
                .map_err(TerminalRefusal::Compute)?
                + 0.5 * (h / INTERSAMPLE_GRID as f64) * lip;
            let gamma = h * (a_w * h).exp();
            sup_m + gamma * (roots.norm_into(cp.B.as_ref()) * eps2 + p_norm(law.P.as_ref(), &f_e))
        }
    };
    // 6. Goal and Unsafe in the metric P_t.
    let metric = Metric {
        n,
        R: crate::linalg::to_row_major(law.P.as_ref()),
    };
    let goal_depth = property
        .goal
        .try_depth(c, &metric)
        .map_err(|e| TerminalRefusal::Compute(e.to_string()))?
        .value;
    let goal_depth = if property.goal.contains(c) {
        goal_depth
    } else {
        0.0
    };
    if !(goal_depth >= between) {
        return Err(TerminalRefusal::Goal {
            needed: between,
            depth: goal_depth,
        });
    }
    let unsafe_distance = match property.unsafe_region() {
        None => f64::INFINITY,
        Some(u) if u.contains(c) => 0.0,
        Some(u) => {
            u.try_dist(c, &metric)
                .map_err(|e| TerminalRefusal::Compute(e.to_string()))?
                .value
        }
    };
    if !(unsafe_distance > between) {
        return Err(TerminalRefusal::Unsafe {
            needed: between,
            distance: unsafe_distance,
        });
    }
    Ok(TerminalCertificate {
        acceptance_inside: proved as f64 / law.radius.max(f32::MIN_POSITIVE) as f64,
        rounding: eps2,
        input_distance: input_dist,
        contraction,
        theta,
        acceptance_floor: floor,
        between_samples: between,
        goal_depth,
        unsafe_distance,
    })
}

/// ρ_h, the radius of the handover region H (module doc) in the law's metric: the f32 handover test with
/// the stored r̂ accepts every state within it ([`selection_floor`] at radius 1, the acceptance's own
/// bound), shrunk by a relative 10⁻⁶ so that a point a solver places on H's boundary is still accepted.
/// 0 when the rounding analysis does not apply (then nothing is known to be handed over).
pub fn handover_radius(law: &StoredTerminal) -> f64 {
    (selection_floor(law.P.as_ref(), &law.x_e, law.radius, 1.0) * (1.0 - 1e-6)).min(1.0)
}

/// H = {x : ‖x − x_e‖_{P_t} ≤ ρ_h} as a convex piece (the generator's form) and as a region (what
/// certification and verification evaluate); `None` when ρ_h is 0 or P_t is not usable.
pub fn handover_region(
    law: &StoredTerminal,
) -> Option<(
    crate::property::ConvexPiece,
    Box<dyn crate::geometry::Region>,
)> {
    let n = law.x_e.len();
    let rho = handover_radius(law);
    if !(rho > 0.0) {
        return None;
    }
    let Q = Mat::from_fn(n, n, |i, j| {
        0.5 * (law.P[(i, j)] + law.P[(j, i)]) / (rho * rho)
    });
    let region =
        crate::geometry::Ellipsoid::new(law.x_e.clone(), crate::linalg::to_row_major(Q.as_ref()))
            .ok()?;
    let piece = crate::property::ConvexPiece::Ellipsoid {
        C: Mat::identity(n, n),
        c: law.x_e.clone(),
        Q,
    };
    Some((piece, Box::new(region)))
}

/// max over s = ih/N (i = 0..=N) of ‖e^{As} + Γ(s)BK‖_P, with e^{As} and Γ(s)B from the exponential of
/// the augmented matrix [[A, B], [0, 0]]·s.
fn sup_m_on_grid(
    A: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    K: MatRef<'_, f64>,
    roots: &PdRoots,
    h: f64,
) -> Result<f64, String> {
    let (n, m) = (A.nrows(), B.ncols());
    let mut best = 1.0f64; // s = 0: M = I.
    for i in 1..=INTERSAMPLE_GRID {
        let s = h * i as f64 / INTERSAMPLE_GRID as f64;
        let aug = Mat::from_fn(n + m, n + m, |r, q| match (r < n, q < n) {
            (true, true) => A[(r, q)] * s,
            (true, false) => B[(r, q - n)] * s,
            _ => 0.0,
        });
        let E = expm(aug.as_ref()).map_err(|e| e.to_string())?;
        let M = Mat::from_fn(n, n, |r, q| {
            E[(r, q)] + (0..m).map(|j| E[(r, n + j)] * K[(j, q)]).sum::<f64>()
        });
        best = best.max(roots.induced_norm(M.as_ref()));
    }
    if !best.is_finite() {
        return Err("the inter-sample bound is not finite".into());
    }
    Ok(best)
}
