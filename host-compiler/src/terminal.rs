//! The terminal law (issue 17, item 2): its design for after the task, an equilibrium in Goal, a gain and
//! an invariant ellipsoid around it (LMIs in the manner of the CAF's, through `caf::sdp`). The
//! certificate of what the image stores is [`crate::certify::terminal`]; this module only proposes
//! candidates for it and keeps the certified one.
//!
//! 1. **Equilibrium** (a small conic program): (x_e, u_e) with A x_e + B u_e + c = 0 (continuous time) or
//!    (A − I) x_e + B u_e + g = 0 (discrete time), x_e in Goal and u_e in the input set, the smaller of the
//!    two depths, each relative to its set's size, as large as possible. First the input set's depth is
//!    maximised over the equilibria in Goal alone: when it is negative, no equilibrium in Goal can be held
//!    within the input bound, and the figure says by how much ([`NoTerminal::EquilibriumNeedsInput`]).
//! 2. **Gain and ellipsoid** (the LMIs of invariant-ellipsoid design, in Q = P_t⁻¹ and Y = K_t Q): for a
//!    contraction ρ, [[ρ²Q, (AQ + BY)ᵀ], [AQ + BY, Q]] ⪰ 0 makes ‖A + BK_t‖_{P_t} ≤ ρ; E = {‖x − x_e‖_{P_t}
//!    ≤ 1} inside Goal shrunk by γ (a polytope row i: h_iᵀQh_i ≤ ((b_i − h_iᵀx_e)/γ)²; an ellipsoid by the
//!    triangle inequality as an LMI); every input u_e + K_t(x − x_e) on E inside the input set with a
//!    margin (a box row j: [[s_j², y_j], [y_jᵀ, Q]] ⪰ 0; a ball: [[s²I, Y], [Yᵀ, Q]] ⪰ 0); each Unsafe
//!    piece beyond a separating hyperplane (the polytope row x_e violates most; for an ellipsoid the
//!    tangent plane normal to its gradient at x_e). Q ⪰ tI with t maximised.
//! 3. **Search**: ρ over a short list, and γ raised to the certificate's inter-sample radius when the
//!    candidate fails only on Goal; each candidate is rounded to f32 and certified, and the certified one
//!    of largest volume (log det Q) is kept.

// Negated comparisons (`!(x >= y)`) are deliberate: they reject NaN as well.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::caf::sdp::{rect_from, sym_from, sym_index, Sdp};
use crate::certify::selection_radius;
use crate::certify::terminal::{certify, StoredTerminal, TerminalCertificate, TerminalRefusal};
use crate::linalg::{mat_vec, round32, spectral_norm, sym_eigenvalues, PdRoots};
use crate::property::{ConvexPiece, InputBound};
use crate::task::Task;
use clarabel::solver::{DefaultSettings, DefaultSettingsBuilder, SolverStatus};
use faer::Mat;

/// Contractions tried, from the weakest (largest ellipsoids) down.
const CONTRACTIONS: [f64; 8] = [0.9999, 0.999, 0.995, 0.99, 0.97, 0.9, 0.8, 0.6];
/// Relative margin kept off the input set's bound in the LMIs (the certificate then adds the rounding).
const INPUT_MARGIN: f64 = 1e-3;
/// Re-solves with γ raised, per contraction, when only Goal fails.
const GAMMA_ROUNDS: usize = 3;

/// A certified terminal law: what the image stores, its certificate and the design figures.
#[derive(Clone, Debug)]
pub struct TerminalDesign {
    pub stored: StoredTerminal,
    pub certificate: TerminalCertificate,
    /// The equilibrium input u_e (f64, before rounding).
    pub u_e: Vec<f64>,
    /// The contraction ρ of the LMI that gave it.
    pub rho: f64,
    /// log det Q = −log det P_t (the ellipsoid's log volume up to a constant).
    pub log_volume: f64,
}

/// Why there is no terminal law for a task.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NoTerminal {
    #[error(
        "the terminal law is built for linear affine plants with one location (this plant: {0})"
    )]
    PlantClass(&'static str),
    #[error("no equilibrium of the plant lies in Goal")]
    NoEquilibrium,
    #[error(
        "every equilibrium of the plant in Goal needs an input {outside:.4} outside the input set (in its \
         norm), so no law can hold a run in Goal within the input bound"
    )]
    EquilibriumNeedsInput { outside: f64 },
    #[error("no gain and ellipsoid could be certified around the equilibrium x_e = {x_e:?} (u_e = {u_e:?}); the last refusal: {last}")]
    NotCertified {
        x_e: Vec<f64>,
        u_e: Vec<f64>,
        last: String,
    },
}

/// Designs and certifies a terminal law for the task (module doc), or says why there is none.
pub fn design_terminal(task: &Task) -> Result<TerminalDesign, NoTerminal> {
    let plant = task.plant.as_ref();
    if plant.locations() != 1 {
        return Err(NoTerminal::PlantClass("a hybrid automaton"));
    }
    if plant.linearization().is_some() || plant.model_mismatch() != 0.0 {
        return Err(NoTerminal::PlantClass("feedback linearizable"));
    }
    let (x_e, u_e) = equilibrium(task)?;
    let d = plant.error_dynamics(0);
    let mut best: Option<TerminalDesign> = None;
    let mut last = String::from("every LMI was infeasible");
    for &rho in &CONTRACTIONS {
        let mut gamma = 1.0;
        for _ in 0..GAMMA_ROUNDS {
            let Some((Q, K)) = solve_lmi(task, &d.A, &d.B, &x_e, &u_e, rho, gamma) else {
                last = format!("the LMI with contraction {rho} is infeasible");
                break;
            };
            let stored = round_to_image(&x_e, &u_e, &K, &Q);
            let log_volume = sym_eigenvalues(Q.as_ref())
                .map(|ev| ev.iter().map(|l| l.ln()).sum::<f64>())
                .unwrap_or(f64::NEG_INFINITY);
            match certify(plant, &task.property, &stored) {
                Ok(certificate) => {
                    if best.as_ref().is_none_or(|b| log_volume > b.log_volume) {
                        best = Some(TerminalDesign {
                            stored,
                            certificate,
                            u_e: u_e.clone(),
                            rho,
                            log_volume,
                        });
                    }
                    break;
                }
                Err(TerminalRefusal::Goal { needed, .. })
                | Err(TerminalRefusal::Unsafe { needed, .. }) => {
                    // Shrink by the inter-sample radius (and a little more for the f32 rounding).
                    gamma = gamma.max(needed) * (1.0 + 1e-3);
                    last = format!("contraction {rho}: the inter-sample radius {needed:.6}");
                }
                Err(e) => {
                    last = format!("contraction {rho}: {e}");
                    break;
                }
            }
        }
    }
    best.ok_or(NoTerminal::NotCertified { x_e, u_e, last })
}

fn clarabel() -> DefaultSettings<f64> {
    DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(300)
        .build()
        .unwrap_or_default()
}

fn solved(status: SolverStatus) -> bool {
    matches!(status, SolverStatus::Solved | SolverStatus::AlmostSolved)
}

/// Item 1 of the module doc: (x_e, u_e).
fn equilibrium(task: &Task) -> Result<(Vec<f64>, Vec<f64>), NoTerminal> {
    let plant = task.plant.as_ref();
    let (n, m) = (plant.n(), plant.m());
    let goal = &task.convex.goal;
    let input = &task.property.input;
    let goal_size = piece_size(goal, n).ok_or(NoTerminal::NoEquilibrium)?;
    let input_size = match input {
        InputBound::Box { lo, hi } => lo
            .iter()
            .zip(hi)
            .map(|(l, h)| 0.5 * (h - l))
            .fold(f64::INFINITY, f64::min),
        InputBound::Norm2 { max, .. } => *max,
    };
    // Pass 1: the input set's depth over the equilibria in Goal (goal depth ≥ 0); pass 2: balanced.
    let first = equilibrium_program(task, 0.0, 1.0, false).ok_or(NoTerminal::NoEquilibrium)?;
    let tau = first[n + m];
    if tau < 0.0 {
        return Err(NoTerminal::EquilibriumNeedsInput { outside: -tau });
    }
    let z = equilibrium_program(task, goal_size, input_size.max(1e-12), true)
        .ok_or(NoTerminal::NoEquilibrium)?;
    // The interior-point solver leaves round-off in components that are zero (e.g. 1e-18 for a velocity
    // at rest); they are set to 0 so that the stored law does not carry solver noise. The certificate
    // accounts for the equilibrium residual whatever it is.
    let clean = |v: &[f64]| -> Vec<f64> {
        let scale = v.iter().fold(1.0f64, |a, b| a.max(b.abs()));
        v.iter()
            .map(|&x| if x.abs() <= 1e-12 * scale { 0.0 } else { x })
            .collect()
    };
    Ok((clean(&z[..n]), clean(&z[n..n + m])))
}

/// max τ over (x, u, τ) with the equilibrium equations, Goal depth ≥ τ·g and input depth ≥ τ·s
/// (`balanced`), or Goal depth ≥ 0 and input depth ≥ τ·s with τ free (not `balanced`).
fn equilibrium_program(task: &Task, g: f64, s: f64, balanced: bool) -> Option<Vec<f64>> {
    let plant = task.plant.as_ref();
    let (n, m) = (plant.n(), plant.m());
    let t = n + m;
    let mut p = Sdp::new(n + m + 1);
    // Equilibrium equations, as two inequalities per row.
    let (A, B, c): (Mat<f64>, Mat<f64>, Vec<f64>) = match plant.continuous(0) {
        Some(cp) => (cp.A.clone(), cp.B.clone(), cp.c.clone()),
        None => {
            let d = plant.error_dynamics(0);
            let A = Mat::from_fn(n, n, |i, j| d.A[(i, j)] - if i == j { 1.0 } else { 0.0 });
            (A, d.B.clone(), d.g.clone())
        }
    };
    for i in 0..n {
        let row: Vec<(usize, f64)> = (0..n)
            .map(|j| (j, A[(i, j)]))
            .chain((0..m).map(|j| (n + j, B[(i, j)])))
            .collect();
        let neg: Vec<(usize, f64)> = row.iter().map(|&(v, a)| (v, -a)).collect();
        p.add_linear_le(&row, -c[i]);
        p.add_linear_le(&neg, c[i]);
    }
    let goal_weight = if balanced { g } else { 0.0 };
    match &task.convex.goal {
        ConvexPiece::Polytope { H, b } => {
            for i in 0..H.nrows() {
                let norm = (0..n).map(|j| H[(i, j)] * H[(i, j)]).sum::<f64>().sqrt();
                let mut row: Vec<(usize, f64)> = (0..n).map(|j| (j, H[(i, j)])).collect();
                row.push((t, goal_weight * norm));
                p.add_linear_le(&row, b[i]);
            }
        }
        ConvexPiece::Ellipsoid { C, c, Q } => {
            let root = PdRoots::new(Q.as_ref())?.sqrt;
            let S = &root * C;
            let k = spectral_norm(S.as_ref());
            let Sc = mat_vec(root.as_ref(), c);
            let pd = S.nrows();
            // [[1 − τ g k, wᵀ], [w, (1 − τ g k) I]] ⪰ 0 with w = S x − Q^{1/2} c.
            let constant = Mat::from_fn(pd + 1, pd + 1, |r, q| match (r, q) {
                (0, 0) => 1.0,
                (0, q) => -Sc[q - 1],
                (r, 0) => -Sc[r - 1],
                (r, q) if r == q => 1.0,
                _ => 0.0,
            });
            p.add_lmi(&constant, |z| {
                let w: Vec<f64> = (0..pd)
                    .map(|r| (0..n).map(|j| S[(r, j)] * z[j]).sum())
                    .collect();
                let d = -z[t] * goal_weight * k;
                Mat::from_fn(pd + 1, pd + 1, |r, q| match (r, q) {
                    (0, 0) => d,
                    (0, q) => w[q - 1],
                    (r, 0) => w[r - 1],
                    (r, q) if r == q => d,
                    _ => 0.0,
                })
            });
        }
    }
    match &task.property.input {
        InputBound::Box { lo, hi } => {
            for j in 0..m {
                p.add_linear_le(&[(n + j, -1.0), (t, s)], -lo[j]);
                p.add_linear_le(&[(n + j, 1.0), (t, s)], hi[j]);
            }
        }
        InputBound::Norm2 { center, max } => {
            let constant = Mat::from_fn(m + 1, m + 1, |r, q| match (r, q) {
                (0, 0) => *max,
                (0, q) => -center[q - 1],
                (r, 0) => -center[r - 1],
                (r, q) if r == q => *max,
                _ => 0.0,
            });
            p.add_lmi(&constant, |z| {
                let d = -z[t] * s;
                Mat::from_fn(m + 1, m + 1, |r, q| match (r, q) {
                    (0, 0) => d,
                    (0, q) => z[n + q - 1],
                    (r, 0) => z[n + r - 1],
                    (r, q) if r == q => d,
                    _ => 0.0,
                })
            });
        }
    }
    // τ ≤ 1 keeps the program bounded; τ ≥ −10⁶ keeps the first pass bounded below.
    p.add_linear_le(&[(t, 1.0)], 1.0);
    p.add_lower_bound(t, -1e6);
    p.add_linear_cost(t, -1.0);
    let r = p.solve(clarabel()).ok()?;
    (solved(r.status) && r.x.iter().all(|v| v.is_finite())).then_some(r.x)
}

/// A size of a Goal piece, in state units: the Chebyshev radius of a polytope (capped at 10⁶), the
/// smallest semi-axis of an ellipsoid.
fn piece_size(goal: &ConvexPiece, n: usize) -> Option<f64> {
    match goal {
        ConvexPiece::Ellipsoid { C, Q, .. } => {
            let S = PdRoots::new(Q.as_ref())?.sqrt * C;
            Some(1.0 / spectral_norm(S.as_ref()))
        }
        ConvexPiece::Polytope { H, b } => {
            let mut p = Sdp::new(n + 1);
            for i in 0..H.nrows() {
                let norm = (0..n).map(|j| H[(i, j)] * H[(i, j)]).sum::<f64>().sqrt();
                let mut row: Vec<(usize, f64)> = (0..n).map(|j| (j, H[(i, j)])).collect();
                row.push((n, norm));
                p.add_linear_le(&row, b[i]);
            }
            p.add_linear_le(&[(n, 1.0)], 1e6);
            p.add_linear_cost(n, -1.0);
            let r = p.solve(clarabel()).ok()?;
            let t = r.x.get(n).copied()?;
            (solved(r.status) && t > 0.0).then_some(t)
        }
    }
}

/// Item 2 of the module doc: Q and K_t = Y Q⁻¹, or `None` when the LMIs are infeasible.
fn solve_lmi(
    task: &Task,
    A: &Mat<f64>,
    B: &Mat<f64>,
    x_e: &[f64],
    u_e: &[f64],
    rho: f64,
    gamma: f64,
) -> Option<(Mat<f64>, Mat<f64>)> {
    let (n, m) = (A.nrows(), B.ncols());
    let nq = n * (n + 1) / 2;
    let (y0, t) = (nq, nq + m * n);
    let mut p = Sdp::new(nq + m * n + 1);
    let Qof = |z: &[f64]| sym_from(z, 0, n);
    let Yof = |z: &[f64]| rect_from(z, y0, m, n);
    // Invariance: [[ρ²Q, (AQ + BY)ᵀ], [AQ + BY, Q]] ⪰ 0.
    p.add_lmi(&Mat::zeros(2 * n, 2 * n), |z| {
        let (Q, Y) = (Qof(z), Yof(z));
        let F = A * &Q + B * &Y;
        Mat::from_fn(2 * n, 2 * n, |r, q| match (r < n, q < n) {
            (true, true) => rho * rho * Q[(r, q)],
            (true, false) => F[(q - n, r)],
            (false, true) => F[(r - n, q)],
            (false, false) => Q[(r - n, q - n)],
        })
    });
    // Q ⪰ tI.
    p.add_lmi(&Mat::zeros(n, n), |z| {
        let Q = Qof(z);
        Mat::from_fn(n, n, |r, q| Q[(r, q)] - if r == q { z[t] } else { 0.0 })
    });
    // A row hᵀQh ≤ s² (s > 0 needed).
    let quad_row = |p: &mut Sdp, h: &[f64], s: f64| -> bool {
        if !(s > 0.0) {
            return false;
        }
        let mut terms = vec![];
        for a in 0..n {
            for b in a..n {
                let coef = if a == b {
                    h[a] * h[a]
                } else {
                    2.0 * h[a] * h[b]
                };
                if coef != 0.0 {
                    terms.push((sym_index(a, b), coef));
                }
            }
        }
        p.add_linear_le(&terms, s * s);
        true
    };
    // Goal.
    match &task.convex.goal {
        ConvexPiece::Polytope { H, b } => {
            for i in 0..H.nrows() {
                let h: Vec<f64> = (0..n).map(|j| H[(i, j)]).collect();
                if h.iter().all(|v| *v == 0.0) {
                    continue;
                }
                let slack = b[i] - h.iter().zip(x_e).map(|(a, x)| a * x).sum::<f64>();
                if !quad_row(&mut p, &h, slack / gamma) {
                    return None;
                }
            }
        }
        ConvexPiece::Ellipsoid { C, c, Q } => {
            let root = PdRoots::new(Q.as_ref())?.sqrt;
            let S = &root * C;
            let w: Vec<f64> = mat_vec(C.as_ref(), x_e)
                .iter()
                .zip(c)
                .map(|(a, b)| a - b)
                .collect();
            let w0 = mat_vec(root.as_ref(), &w)
                .iter()
                .map(|v| v * v)
                .sum::<f64>()
                .sqrt();
            let s = (1.0 - w0) / gamma;
            if !(s > 0.0) {
                return None;
            }
            let pd = S.nrows();
            p.add_lmi(
                &Mat::from_fn(pd, pd, |r, q| if r == q { s * s } else { 0.0 }),
                |z| {
                    let M = &S * Qof(z) * S.transpose();
                    Mat::from_fn(pd, pd, |r, q| -M[(r, q)])
                },
            );
        }
    }
    // Inputs.
    match &task.property.input {
        InputBound::Box { lo, hi } => {
            for j in 0..m {
                let s = (hi[j] - u_e[j]).min(u_e[j] - lo[j]) * (1.0 - INPUT_MARGIN);
                if !(s > 0.0) {
                    return None;
                }
                let constant =
                    Mat::from_fn(
                        n + 1,
                        n + 1,
                        |r, q| {
                            if r == 0 && q == 0 {
                                s * s
                            } else {
                                0.0
                            }
                        },
                    );
                p.add_lmi(&constant, |z| {
                    let (Q, Y) = (Qof(z), Yof(z));
                    Mat::from_fn(n + 1, n + 1, |r, q| match (r, q) {
                        (0, 0) => 0.0,
                        (0, q) => Y[(j, q - 1)],
                        (r, 0) => Y[(j, r - 1)],
                        (r, q) => Q[(r - 1, q - 1)],
                    })
                });
            }
        }
        InputBound::Norm2 { center, max } => {
            let dist = u_e
                .iter()
                .zip(center)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt();
            let s = (max - dist) * (1.0 - INPUT_MARGIN);
            if !(s > 0.0) {
                return None;
            }
            let constant = Mat::from_fn(
                m + n,
                m + n,
                |r, q| {
                    if r == q && r < m {
                        s * s
                    } else {
                        0.0
                    }
                },
            );
            p.add_lmi(&constant, |z| {
                let (Q, Y) = (Qof(z), Yof(z));
                Mat::from_fn(m + n, m + n, |r, q| match (r < m, q < m) {
                    (true, true) => 0.0,
                    (true, false) => Y[(r, q - m)],
                    (false, true) => Y[(q, r - m)],
                    (false, false) => Q[(r - m, q - m)],
                })
            });
        }
    }
    // Unsafe: each piece beyond a separating hyperplane aᵀx ≥ β.
    for piece in &task.convex.unsafe_pieces {
        let Some((a, beta)) = separating_plane(piece, x_e) else {
            continue;
        };
        let margin = a.iter().zip(x_e).map(|(p, x)| p * x).sum::<f64>() - beta;
        if !quad_row(&mut p, &a, margin / gamma) {
            return None;
        }
    }
    // Objective: max t, with a small pull on trace(Q) so that directions Goal and Unsafe leave free stay
    // bounded.
    p.add_linear_cost(t, -1.0);
    for i in 0..n {
        p.add_linear_cost(sym_index(i, i), 1e-6);
    }
    let r = p.solve(clarabel()).ok()?;
    if !solved(r.status) || !r.x.iter().all(|v| v.is_finite()) {
        return None;
    }
    let Q = Qof(&r.x);
    let Qinv = PdRoots::new(Q.as_ref())?.inv;
    let K = Yof(&r.x) * &Qinv;
    Some((Q, K))
}

/// A hyperplane aᵀx = β with the Unsafe piece in aᵀx ≤ β and x_e strictly above it, if one of this
/// construction exists (module doc, item 2).
fn separating_plane(piece: &ConvexPiece, x_e: &[f64]) -> Option<(Vec<f64>, f64)> {
    let n = x_e.len();
    match piece {
        ConvexPiece::Polytope { H, b } => {
            // The row x_e violates most (relative to its norm); the piece lies in −h_i x ≥ −b_i... i.e. in
            // h_iᵀx ≤ b_i, so a = h_i, β = b_i.
            (0..H.nrows())
                .filter_map(|i| {
                    let h: Vec<f64> = (0..n).map(|j| H[(i, j)]).collect();
                    let norm = h.iter().map(|v| v * v).sum::<f64>().sqrt();
                    let gap = h.iter().zip(x_e).map(|(a, x)| a * x).sum::<f64>() - b[i];
                    (norm > 0.0 && gap > 0.0).then_some((gap / norm, h, b[i]))
                })
                .max_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, h, b)| (h, b))
        }
        ConvexPiece::Ellipsoid { C, c, Q } => {
            let y: Vec<f64> = mat_vec(C.as_ref(), x_e)
                .iter()
                .zip(c)
                .map(|(a, b)| a - b)
                .collect();
            let ay = mat_vec(Q.as_ref(), &y);
            let roots = PdRoots::new(Q.as_ref())?;
            // max over the piece of ayᵀ(y' − c) is ‖ay‖_{Q⁻¹}.
            let beta_y = roots.dual_norm(&ay) + ay.iter().zip(c).map(|(a, b)| a * b).sum::<f64>();
            let a: Vec<f64> = (0..n)
                .map(|j| (0..C.nrows()).map(|r| ay[r] * C[(r, j)]).sum())
                .collect();
            Some((a, beta_y))
        }
    }
}

/// The f32 values the image stores for (x_e, u_e, K_t, Q): P_t = Q⁻¹ rounded symmetrically, v_t =
/// u_e − K_t x_e from the stored K_t and x_e, and the acceptance radius at 1.
fn round_to_image(x_e: &[f64], u_e: &[f64], K: &Mat<f64>, Q: &Mat<f64>) -> StoredTerminal {
    let n = x_e.len();
    let P = PdRoots::new(Q.as_ref())
        .map(|r| r.inv)
        .unwrap_or_else(|| Mat::zeros(n, n));
    let P32 = Mat::from_fn(n, n, |i, j| {
        let (a, b) = if i <= j { (i, j) } else { (j, i) };
        round32(0.5 * (P[(a, b)] + P[(b, a)]))
    });
    let x32: Vec<f64> = x_e.iter().map(|v| round32(*v)).collect();
    let K32 = Mat::from_fn(K.nrows(), n, |i, j| round32(K[(i, j)]));
    let kx = mat_vec(K32.as_ref(), &x32);
    let v32: Vec<f64> = u_e.iter().zip(&kx).map(|(u, k)| round32(u - k)).collect();
    let radius = selection_radius(P32.as_ref(), &x32, 1.0);
    StoredTerminal {
        x_e: x32,
        K: K32,
        v: v32,
        P: P32,
        radius,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn task(example: &str) -> Task {
        let path = format!("{}/../examples/{example}", env!("CARGO_MANIFEST_DIR"));
        Task::new(crate::spec::load(&path).expect("the shipped example")).expect("a task")
    }

    /// The double integrator's Goal (position in [0.95, 1.05]) holds its equilibria at rest: a law is
    /// certified, centred there, inside Goal and away from the speed limit.
    #[test]
    fn the_double_integrator_gets_a_certified_terminal_law() {
        let d = design_terminal(&task("double-integrator.toml")).expect("a terminal law");
        eprintln!("{d:#?}");
        assert!((d.stored.x_e[0] - 1.0).abs() < 1e-3 && d.stored.x_e[1].abs() < 1e-6);
        assert!(d.u_e[0].abs() < 1e-6);
        let c = &d.certificate;
        assert!(c.goal_depth >= c.between_samples && c.theta < c.acceptance_floor);
        assert!(c.input_distance >= 1.0 && c.unsafe_distance > 1.0);
    }

    /// Example 4.8's vehicle is pulled by a constant force that an input of norm ≤ 1 cannot cancel
    /// anywhere in the Goal disc: every equilibrium there needs ‖u‖ ≥ √2 − 0.1.
    #[test]
    fn the_planar_vehicle_has_no_equilibrium_in_goal_within_the_input_bound() {
        match design_terminal(&task("planar-vehicle.toml")) {
            Err(NoTerminal::EquilibriumNeedsInput { outside }) => {
                assert!(
                    (outside - (2f64.sqrt() - 0.1 - 1.0)).abs() < 1e-4,
                    "{outside}"
                )
            }
            other => panic!("expected no equilibrium within the bound, got {other:?}"),
        }
    }
}
