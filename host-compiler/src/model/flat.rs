//! Differentially flat plants (§3.1.3, Def 3.12, Theorem 3.14; Example 3.15's quadrotor) as a plant of
//! the pipeline: the certificate lives on the chain of integrators in the flat state q, the firmware keeps
//! the controller states ζ of the dynamic extension (`spec::flat`), maps the measured state and ζ to q,
//! and maps the linear law's output w back to the plant's input and ζ's next value through two model
//! programs; the sampled loop's departures from the chain are bounded disturbances (Theorem 3.21).
//!
//! **The law.** On the extended system (states x_e = (x, ζ), inputs u_e: the extended inputs' highest
//! derivatives and the other inputs) the flat state is q = Φ(x_e) = (L_f^k h_i)_{k < r_i} and
//! q̇ = A q + B(α(x_e) + Γ(x_e)u_e) with A, B the chains (the spec loader proved Γ nonsingular over the
//! operating region). The firmware applies u_e = Γ⁻¹(w − α) (all of α cancelled, so the linear model is the
//! pure chain, K̂ and P of (3.41)). ζ advances by the exact zero-order-hold solution of its integrators
//! under the held u_e, ζ_k⁺ = Σ_{l ≥ k} ζ_l h^{l−k}/(l−k)! + u_e h^{o−k}/(o−k)!, so within the period the
//! model's extended input is the polynomial ζ_0(t) = Σ_l ζ_l t^l/l! + u_e t^o/o!. The plant can only hold
//! one value: it gets that polynomial's mean over the period, ζ̄ = Σ_l ζ_l h^l/(l+1)! + u_e h^o/(o+1)!
//! (the thrust, for the quadrotor), and the other inputs their u_e. Holding the mean rather than ζ_0 makes
//! the held error ζ̄ − ζ_0(t) average to zero over each period, which turns its first-order effect on the
//! state into a second-order one (item 3).
//!
//! **Every bound is over the operating region Q** (a box over q, `plant.region`), evaluated by interval
//! enclosures of the expressions with x_e = Ξ_e(q) substituted (Ξ the user's map, ζ(q) derived from Υ),
//! on a grid of sub-boxes of the coordinates they use. Leaving Q is entering Unsafe, which the certificate
//! excludes (its complement joins the task's Unsafe): the first-exit argument of
//! `model::feedback_linearizable` carries over unchanged.
//! 1. *The input set* pulled back to a box W of the flat input: the spec's `plant.flat_input` when set,
//!    else the largest cube {|w_j| ≤ ω} (by bisection); either way the enclosure of every non-extended
//!    input over Q × W, widened by the input program's rounding, must lie in U (else refused). So must an
//!    extended input's applied mean ζ̄ over Q × W (else refused: shrink Q or W).
//! 2. *The w-channel mismatch D*: with u_e held, the last chain element's derivative departs from w by
//!    φ(x_e(t)) − φ(x_e,k), φ = α + Γu_e, whose rate is the Lie derivative E of φ along the extended field
//!    under the held u_e, plus its Lie derivative along the extended input's column of g times how far the
//!    held ζ̄ is from the model's ζ_0(t) within a period, Δ = Σ_{k ≥ 1} c_k h^k/k!·|ζ_k| + c_o h^o/o!·|u_e|
//!    with c_k = k/(k+1) (|t^k/k! − h^k/(k+1)!| ≤ c_k h^k/k! on [0, h]). So
//!    D = h·sup(‖E‖ + ‖L_{g_T}φ‖Δ) + ‖Γ‖·e_u, e_u the input program's rounding of the non-extended inputs.
//! 3. *The state channel*: the held ζ̄ also enters q̇ directly, as c(t) = L(t)(ζ̄ − ζ_0(t)) with
//!    L_j = L_{g_T}Φ_j (the planar quadrotor's velocity rows). Over a period it moves q by
//!    ∫ e^{A(h−s)}c(s)ds = ∫ (F(s) − F(0))(ζ̄ − ζ_0(s))ds, F(s) = e^{A(h−s)}L(s), because ζ̄ − ζ_0 has mean
//!    zero; with |F'| ≤ A e^{Ah}|L| + e^{Ah}|L̇| entrywise (the chains' e^{At} is nonnegative and grows with
//!    t) that is a jump of at most h²/2·(A e^{Ah}·sup|L|Δ + e^{Ah}·sup|L̇|Δ) per coordinate (`held`), L̇
//!    the rate of L along the actual field (the extended field plus L_{g_T}L·Δ). The f32 rounding e_T of
//!    ζ̄ is a constant error over the period: a rate b_j = sup|L_j|·e_T (`state_rate`).
//! 4. *The jump per period*: the f32 rounding of ζ⁺ moves q by Σ_k |∂Φ_j/∂ζ_k|·e_ζ,k, and the f32
//!    rounding e_q of the coords program is a misreading of q, which moves the loop as a jump of
//!    (1 + ‖row_j(e^{Ah})‖₁)·e_q at most (the loop in the read coordinates q̃ = q + e is exact up to
//!    e_{k+1} − e^{Ah}e_k); the read state is within e_q of the true one, so Unsafe, the region's
//!    complement and Goal are moved by e_q (inflated, shrunk) before certification.
//!
//! `certify::LoopConstants` adds 3 and 4 to the per-step disturbance in the P-metric
//! (φ Σ b_j √P_jj + Σ J_j √P_jj), next to φβD.
//!
//! **The pipeline.** `task::Task::new` makes the task the chain in q with these maps on the plant
//! (`FeedbackLinearized`), so the CAF, the generator, §5.3 and the cover run on the chain as on any
//! feedback-linearizable task. The image carries ζ0 (model maps section) and the evaluator keeps ζ
//! (ζ⁺ from the input map on every accepted step); the Monte Carlo (`verify::nonlinear`), the falsifier
//! and `simulate` read q with the evaluator's ζ at the samples and with ζ's model over the period
//! between them ([`super::feedback_linearizable::FlatCoords::zeta_within`]). The game refuses a flat
//! plant.
//!
//! **MTL tasks** (Problem 2.28, Theorem 4.2): the formula is rewritten over q ([`formula_in_q`]) with its
//! atoms moved by the read error e_q by polarity (a required atom shrunk, a forbidden one inflated) and
//! the region as a conjunct; `certify::temporal` then certifies it on the chain exactly as a
//! feedback-linearizable task's, and `verify::temporal` judges the image on the plant with ζ kept.

use super::feedback_linearizable::{
    adjugate, bound_err, cancelling_law, dims_used, gram, norm2_bound, outside_interval,
    predicate_in_coords, sup_over_grid, FlError, FlMaps, FlatCoords, Renamed,
};
use super::nonlinear::NonlinearPlant;
use crate::expr::compile::compile;
use crate::expr::diff::{derivative, lie};
use crate::expr::interval::{enclose, rounding_bound, Interval, IntervalError, VarBox};
use crate::expr::tape::Tape;
use crate::expr::{Expr, Var};
use crate::spec::sets::{Coords, Shape};
use crate::spec::{InputSet, Matrix, Plant as SpecPlant, Problem, SetDesc, TimeDomain};

/// Bisection steps for the input box's half-width ω.
const OMEGA_BISECTIONS: usize = 40;
/// The largest ω tried.
const OMEGA_MAX: f64 = 1e4;

/// The task in the flat state q of a validated differentially flat spec and the maps with their bounds
/// (module doc).
pub fn flatten(problem: &Problem) -> Result<(Problem, FlMaps), FlError> {
    let desc = problem
        .nonlinear
        .as_ref()
        .expect("flatten is called on a nonlinear problem");
    let fd = desc
        .flat
        .as_deref()
        .expect("flatten is called on a flat plant");
    let pv = desc.names.param_values();
    let bind = |e: &Expr| e.bind_params(&pv);
    let rd = &desc.derivatives;
    let (n, m) = (desc.system.n(), desc.system.m());
    let n_ext = fd.n_ext();
    let ne = n + n_ext;
    let h = desc.period;
    // The first controller state of each extended input.
    let mut first: Vec<Option<usize>> = vec![None; m];
    let mut order: Vec<usize> = vec![0; m];
    let mut z = n;
    for e in &fd.extension {
        first[e.input] = Some(z);
        order[e.input] = e.order;
        z += e.order;
    }
    // 1. q, α, Γ, the law.
    let q_exprs: Vec<Expr> = (0..m)
        .flat_map(|i| rd.lf[i].iter().take(rd.r[i]).map(bind))
        .collect();
    let alpha: Vec<Expr> = (0..m).map(|i| bind(&rd.lf[i][rd.r[i]])).collect();
    let gamma: Vec<Vec<Expr>> = rd
        .gamma
        .iter()
        .map(|row| row.iter().map(bind).collect())
        .collect();
    let (adj, det) = adjugate(&gamma)?;
    let w = |j: usize| Expr::var(Var::Input(j as u16));
    let ue = cancelling_law(&adj, &det, &alpha);
    let state = |s: usize| Expr::var(Var::State(s as u16));
    let fact = |k: usize| (1..=k).product::<usize>() as f64;
    // The extension's polynomial from ζ_k on, integrated `shift` times over the period and divided by
    // h^shift: Σ_{l ≥ k} ζ_l h^{l−k}/(l−k+shift)! + u_e h^{o−k}/(o−k+shift)! (ζ_k⁺ for shift 0; for k = 0 and
    // shift 1 the mean of ζ_0(t) = Σ_l ζ_l t^l/l! + u_e t^o/o! over the period).
    let poly = |z0: usize, o: usize, k: usize, shift: usize, u: &Expr| -> Expr {
        let mut s = Expr::c(0.0);
        for l in k..o {
            s = Expr::add(
                s,
                Expr::mul(
                    Expr::c(h.powi((l - k) as i32) / fact(l - k + shift)),
                    state(z0 + l),
                ),
            );
        }
        Expr::add(
            s,
            Expr::mul(
                Expr::c(h.powi((o - k) as i32) / fact(o - k + shift)),
                u.clone(),
            ),
        )
    };
    // An extended input is applied as that mean (module doc, item 3); ζ advances to ζ⁺.
    let mut outputs: Vec<Expr> = (0..m)
        .map(|j| match first[j] {
            Some(z0) => poly(z0, order[j], 0, 1, &ue[j]),
            None => ue[j].clone(),
        })
        .collect();
    for e in &fd.extension {
        let z0 = first[e.input].unwrap_or(n);
        for k in 0..e.order {
            outputs.push(poly(z0, e.order, k, 0, &ue[e.input]));
        }
    }
    let coords = compile(&q_exprs, ne, 0, &[])?;
    let input_map = compile(&outputs, ne, m, &[])?;

    // 2. The substitution x_e = Ξ_e(q) and the region's box.
    let xe_of_q: Vec<Expr> = fd
        .state_of_flat
        .iter()
        .chain(&fd.ext_of_flat)
        .map(bind)
        .collect();
    let to_q = |e: &Expr| -> Expr {
        e.map_vars(&|v| match v {
            Var::State(s) => xe_of_q.get(s as usize).cloned(),
            _ => None,
        })
    };
    let region = &fd.region;
    let base: Vec<Interval> = region.intervals();
    let xe_box = |q: &[Interval]| -> Result<Vec<Interval>, IntervalError> {
        let b = VarBox {
            x: q,
            u: &[],
            p: &[],
        };
        xe_of_q.iter().map(|e| enclose(e, &b)).collect()
    };
    let input = match &problem.input {
        InputSet::Box { lo, hi } => (lo.clone(), hi.clone()),
        InputSet::Ball { .. } => return Err(FlError::FlatInputBall),
    };

    // 4. W by bisection on ω (the non-extended inputs over Q × W inside U, with the program's rounding).
    let free_inputs: Vec<usize> = (0..m).filter(|&j| first[j].is_none()).collect();
    let ue_q: Vec<Expr> = ue.iter().map(&to_q).collect();
    let refs_all: Vec<&Expr> = ue_q.iter().chain(&xe_of_q).collect();
    let dims = dims_used(&refs_all, &base);
    let fits = |wb: &[Interval]| -> Result<f64, IntervalError> {
        sup_over_grid(&base, &dims, &|q| {
            let b = VarBox {
                x: q,
                u: wb,
                p: &[],
            };
            let xe = xe_box(q)?;
            let rb = rounding_bound(&input_map, &xe, wb)?;
            let mut excess = f64::NEG_INFINITY;
            for &j in &free_inputs {
                let v = enclose(&ue_q[j], &b)?;
                let e = rb[j].error;
                excess = excess
                    .max(v.hi + e - input.1[j])
                    .max(input.0[j] - (v.lo - e));
            }
            Ok(excess)
        })
    };
    let cube = |om: f64| vec![Interval::new(-om, om); m];
    let wb: Vec<Interval> = match &fd.flat_input {
        Some(b) => {
            let wb: Vec<Interval> =
                b.lo.iter()
                    .zip(&b.hi)
                    .map(|(&l, &h)| Interval::new(l, h))
                    .collect();
            let excess = fits(&wb).map_err(bound_err("the input set over the flat input's box"))?;
            if excess > 0.0 {
                return Err(FlError::FlatInputTooLarge { excess });
            }
            wb
        }
        None => {
            let zero = fits(&cube(0.0)).map_err(bound_err("the input set pulled back"))?;
            if zero > 0.0 {
                return Err(FlError::FlatInputTooLarge { excess: zero });
            }
            let (mut lo_om, mut hi_om) = (0.0f64, OMEGA_MAX);
            for _ in 0..OMEGA_BISECTIONS {
                let mid = 0.5 * (lo_om + hi_om);
                if fits(&cube(mid)).map_err(bound_err("the input set pulled back"))? <= 0.0 {
                    lo_om = mid;
                } else {
                    hi_om = mid;
                }
            }
            cube(lo_om * (1.0 - 1e-9))
        }
    };
    if free_inputs.is_empty() && fd.flat_input.is_none() {
        return Err(FlError::FlatInputTooLarge { excess: f64::NAN });
    }

    // 5. Rounding of both programs over Q × W.
    let n_q = ne;
    let mut e_q = vec![0.0f64; n_q];
    let mut e_out = vec![0.0f64; outputs.len()];
    {
        let mut acc_q = vec![0.0f64; n_q];
        let mut acc_o = vec![0.0f64; outputs.len()];
        // The grid's cells are visited by `sup_over_grid`; their maxima are gathered per output here.
        let cell = std::cell::RefCell::new((&mut acc_q, &mut acc_o));
        sup_over_grid(&base, &dims, &|q| {
            let xe = xe_box(q)?;
            let rq = rounding_bound(&coords, &xe, &[])?;
            let ro = rounding_bound(&input_map, &xe, &wb)?;
            let mut c = cell.borrow_mut();
            for (a, b) in c.0.iter_mut().zip(&rq) {
                *a = a.max(b.error);
            }
            for (a, b) in c.1.iter_mut().zip(&ro) {
                *a = a.max(b.error);
            }
            Ok(0.0)
        })
        .map_err(bound_err("the programs' rounding"))?;
        e_q.copy_from_slice(&acc_q);
        e_out.copy_from_slice(&acc_o);
    }
    // 3. Extended inputs: the applied period mean over Q × W, widened by its rounding, inside U.
    for e in &fd.extension {
        let j = e.input;
        let applied = to_q(&outputs[j]);
        let range = std::cell::Cell::new((f64::INFINITY, f64::NEG_INFINITY));
        sup_over_grid(&base, &dims_used(&[&applied], &base), &|q| {
            let v = enclose(
                &applied,
                &VarBox {
                    x: q,
                    u: &wb,
                    p: &[],
                },
            )?;
            let (lo, hi) = range.get();
            range.set((lo.min(v.lo), hi.max(v.hi)));
            Ok(0.0)
        })
        .map_err(bound_err("an extended input over Q"))?;
        let (lo, hi) = range.get();
        let (lo, hi) = (lo - e_out[j], hi + e_out[j]);
        if lo < input.0[j] || hi > input.1[j] {
            return Err(FlError::FlatExtendedInput {
                input: desc.names.inputs[j].clone(),
                lo,
                hi,
                ulo: input.0[j],
                uhi: input.1[j],
            });
        }
    }
    let e_u: f64 = free_inputs
        .iter()
        .map(|&j| e_out[j] * e_out[j])
        .sum::<f64>()
        .sqrt();
    let e_zeta = &e_out[m..];

    // 6. The mismatch: φ = α + Γ U (U the held u_e, as input variables), E its rate along the extended
    // field, and the held-ζ_0 terms.
    let sys = &fd.ext_system;
    let f_e: Vec<Expr> = sys.f.iter().map(bind).collect();
    let g_e: Vec<Vec<Expr>> = sys.g.iter().map(|r| r.iter().map(bind).collect()).collect();
    let field_u: Vec<Expr> = (0..ne)
        .map(|s| {
            (0..m).fold(f_e[s].clone(), |acc, l| {
                Expr::add(acc, Expr::mul(g_e[s][l].clone(), w(l)))
            })
        })
        .collect();
    // The plant's g column of each extended input, padded with zeros for ζ.
    let g_ext: Vec<(usize, Vec<Expr>)> = fd
        .extension
        .iter()
        .map(|e| {
            let col: Vec<Expr> = (0..ne)
                .map(|s| {
                    if s < n {
                        bind(&desc.system.g[s][e.input])
                    } else {
                        Expr::c(0.0)
                    }
                })
                .collect();
            (e.input, col)
        })
        .collect();
    // An expression's rate along the actual field, in q: its Lie derivative along the extended field under
    // the held u_e, and along each extended input's column (the share of the held error ζ̄ − ζ_0(t)).
    let along_actual = |e: &Expr| -> Result<(Expr, Vec<Expr>), crate::expr::ExprError> {
        let held = g_ext
            .iter()
            .map(|(_, col)| lie(e, col).map(|d| to_q(&d)))
            .collect::<Result<_, _>>()?;
        Ok((to_q(&lie(e, &field_u)?), held))
    };
    let mut e_rate = Vec::with_capacity(m);
    let mut e_held: Vec<Vec<Expr>> = Vec::with_capacity(m);
    for i in 0..m {
        let phi = (0..m).fold(alpha[i].clone(), |acc, l| {
            Expr::add(acc, Expr::mul(gamma[i][l].clone(), w(l)))
        });
        let (rate, held) = along_actual(&phi)?;
        e_rate.push(rate);
        e_held.push(held);
    }
    // Δ per extended input, as an expression over q and U: the largest |ζ̄ − ζ_0(t)| over the period for
    // the applied mean ζ̄, Σ_{k≥1} c_k h^k/k!|ζ_k| + c_o h^o/o!|U| with c_k = k/(k+1) (module doc, item 3).
    let deltas: Vec<Expr> = fd
        .extension
        .iter()
        .map(|e| {
            let z0 = first[e.input].unwrap_or(n);
            let mut d = Expr::c(0.0);
            for k in 1..e.order {
                d = Expr::add(
                    d,
                    Expr::mul(
                        Expr::c(h.powi(k as i32) / fact(k) * k as f64 / (k + 1) as f64),
                        Expr::func(crate::expr::Func::Abs, xe_of_q[z0 + k].clone()),
                    ),
                );
            }
            Expr::add(
                d,
                Expr::mul(
                    Expr::c(
                        h.powi(e.order as i32) / fact(e.order) * e.order as f64
                            / (e.order + 1) as f64,
                    ),
                    Expr::func(crate::expr::Func::Abs, w(e.input)),
                ),
            )
        })
        .collect();
    // U's box over a cell: the enclosure of u_e over the cell × W.
    let u_box = |q: &[Interval]| -> Result<Vec<Interval>, IntervalError> {
        let b = VarBox {
            x: q,
            u: &wb,
            p: &[],
        };
        ue_q.iter().map(|e| enclose(e, &b)).collect()
    };
    let mut d_refs: Vec<&Expr> = e_rate.iter().collect();
    d_refs.extend(e_held.iter().flatten());
    d_refs.extend(deltas.iter());
    let d_dims = dims_used(&d_refs, &base);
    let sup_rate = sup_over_grid(&base, &d_dims, &|q| {
        let ub = u_box(q)?;
        let b = VarBox {
            x: q,
            u: &ub,
            p: &[],
        };
        let dv: Vec<f64> = deltas
            .iter()
            .map(|d| enclose(d, &b).map(|v| v.mag()))
            .collect::<Result<_, _>>()?;
        let mut s = 0.0;
        for i in 0..m {
            let mut v = enclose(&e_rate[i], &b)?.mag();
            for (k, e) in e_held[i].iter().enumerate() {
                v += enclose(e, &b)?.mag() * dv[k];
            }
            s += v * v;
        }
        Ok(s.sqrt())
    })
    .map_err(bound_err("the sampled-loop mismatch"))?;
    let g_gram = gram(&gamma);
    let gq_gram: Vec<Vec<Expr>> = g_gram
        .iter()
        .map(|r| r.iter().map(&to_q).collect())
        .collect();
    let g_refs: Vec<&Expr> = gq_gram.iter().flatten().collect();
    let gamma_norm = sup_over_grid(&base, &dims_used(&g_refs, &base), &|q| {
        norm2_bound(
            &gq_gram,
            &VarBox {
                x: q,
                u: &[],
                p: &[],
            },
        )
    })
    .map_err(bound_err("‖Γ‖₂"))?;
    let mismatch_flow = h * sup_rate;
    let mismatch = (mismatch_flow + gamma_norm * e_u) * (1.0 + 1e-9);

    // 7. The state-channel terms and the jump, per q coordinate (module doc, items 3–4).
    let mut state_rate = vec![0.0f64; n_q];
    let mut jump = vec![0.0f64; n_q];
    // Per q coordinate: sup Σ_k |L_jk|·Δ_k and sup Σ_k |L̇_jk|·Δ_k (L_jk = L_{g_k}q_j, L̇ its rate along the
    // actual flow), which the mean-zero held error turns into a jump below.
    let mut lag = vec![0.0f64; n_q];
    let mut lag_rate = vec![0.0f64; n_q];
    // e^{Ah} of the chains: row j's absolute sum is Σ_{l<r−k} h^l/l! for the k-th element of a chain of r.
    let mut ah_row = Vec::with_capacity(n_q);
    // Each q coordinate's chain: (its position k in the chain, the chain's length r).
    let mut chain_of = Vec::with_capacity(n_q);
    for &r in &rd.r {
        for k in 0..r {
            ah_row.push((0..r - k).map(|l| h.powi(l as i32) / fact(l)).sum::<f64>());
            chain_of.push((k, r));
        }
    }
    for j in 0..n_q {
        let qj = &q_exprs[j];
        let mut rate_terms: Vec<Expr> = Vec::new();
        // L̇_jk along the extended field under the held u_e, and L_{g_k'} L_jk for the held error's share.
        let mut ldot_terms: Vec<Expr> = Vec::new();
        let mut ll_terms: Vec<Vec<Expr>> = Vec::new();
        for (_, col) in &g_ext {
            let l = lie(qj, col)?;
            let (ldot, ll) = along_actual(&l)?;
            ldot_terms.push(ldot);
            ll_terms.push(ll);
            rate_terms.push(to_q(&l));
        }
        let mut dz_terms: Vec<Expr> = Vec::new();
        for s in n..ne {
            dz_terms.push(to_q(&derivative(qj, Var::State(s as u16))?));
        }
        let mut refs: Vec<&Expr> = rate_terms.iter().chain(&dz_terms).collect();
        refs.extend(ldot_terms.iter());
        refs.extend(ll_terms.iter().flatten());
        refs.extend(deltas.iter());
        let dj = dims_used(&refs, &base);
        let (rate, jz, a, b_rate) = {
            let best = std::cell::Cell::new((0.0f64, 0.0f64, 0.0f64, 0.0f64));
            sup_over_grid(&base, &dj, &|q| {
                let ub = u_box(q)?;
                let b = VarBox {
                    x: q,
                    u: &ub,
                    p: &[],
                };
                let dv: Vec<f64> = deltas
                    .iter()
                    .map(|d| enclose(d, &b).map(|v| v.mag()))
                    .collect::<Result<_, _>>()?;
                let (mut r, mut a, mut br) = (0.0, 0.0, 0.0);
                for (k, t) in rate_terms.iter().enumerate() {
                    let lk = enclose(t, &b)?.mag();
                    r += lk * e_out[g_ext[k].0];
                    a += lk * dv[k];
                    let mut ld = enclose(&ldot_terms[k], &b)?.mag();
                    for (k2, t2) in ll_terms[k].iter().enumerate() {
                        ld += enclose(t2, &b)?.mag() * dv[k2];
                    }
                    br += ld * dv[k];
                }
                let mut jz = 0.0;
                for (k, t) in dz_terms.iter().enumerate() {
                    jz += enclose(t, &b)?.mag() * e_zeta[k];
                }
                let (r0, j0, a0, b0) = best.get();
                best.set((r0.max(r), j0.max(jz), a0.max(a), b0.max(br)));
                Ok(0.0)
            })
            .map_err(bound_err("the held input's rate"))?;
            best.get()
        };
        state_rate[j] = rate * (1.0 + 1e-9);
        jump[j] = (jz + (1.0 + ah_row[j]) * e_q[j]) * (1.0 + 1e-9);
        lag[j] = a;
        lag_rate[j] = b_rate;
    }
    // The held mean's departure from the model over a period, c(s) = Σ_k L_k(s)(ζ̄_k − ζ_0,k(s)), has mean
    // zero in each factor ζ̄_k − ζ_0,k, so ∫ e^{A(h−s)}c(s)ds = ∫ (F(s) − F(0))(ζ̄ − ζ_0(s))ds with
    // F(s) = e^{A(h−s)}L(s), |F'| ≤ A e^{Ah}|L| + e^{Ah}|L̇| entrywise (the chains' e^{At} ≥ 0 grows with t):
    // a jump of at most h²/2·(A e^{Ah} lag + e^{Ah} lag_rate) per coordinate.
    let eah = |v: &[f64], j: usize| -> f64 {
        let (k, r) = chain_of[j];
        (0..r - k)
            .map(|l| h.powi(l as i32) / fact(l) * v[j + l])
            .sum()
    };
    let mut held = vec![0.0f64; n_q];
    for j in 0..n_q {
        let (k, r) = chain_of[j];
        let a_part = if k + 1 < r { eah(&lag, j + 1) } else { 0.0 };
        held[j] = 0.5 * h * h * (a_part + eah(&lag_rate, j)) * (1.0 + 1e-9);
        jump[j] = (jump[j] + held[j]) * (1.0 + 1e-9);
    }

    // 8. The linear model in q: the chains.
    let mut A = Matrix::zeros(ne, ne);
    let mut B = Matrix::zeros(ne, m);
    let mut C = Matrix::zeros(m, ne);
    let mut o = 0;
    for (i, &r) in rd.r.iter().enumerate() {
        for k in 0..r - 1 {
            A.data[(o + k) * ne + o + k + 1] = 1.0;
        }
        B.data[(o + r - 1) * m + i] = 1.0;
        C.data[i * ne + o] = 1.0;
        o += r;
    }

    // 9. The problem in q: sets on the plant's states that are flat coordinates, moved by e_q (module doc,
    // item 4); the region's complement in Unsafe.
    let names = &desc.names;
    let q_of_state = |s: usize| fd.q_states.iter().position(|&t| t == Some(s));
    let remap = |what: &str, s: &SetDesc, grow: bool| -> Result<SetDesc, FlError> {
        let mut out = s.clone();
        let idx: Vec<usize> = match &s.coords {
            Coords::State => (0..n).collect(),
            Coords::StateIndices(idx) => idx.clone(),
            Coords::Output { .. } => {
                return Err(FlError::FlatSetCoords {
                    what: what.to_string(),
                })
            }
        };
        let qidx: Vec<usize> = idx
            .iter()
            .map(|&i| {
                q_of_state(i).ok_or_else(|| FlError::SetOnZeroDynamics {
                    what: what.to_string(),
                    state: super::feedback_linearizable::state_name(names, i),
                })
            })
            .collect::<Result<_, _>>()?;
        let e: Vec<f64> = qidx.iter().map(|&j| e_q[j]).collect();
        let sign = if grow { 1.0 } else { -1.0 };
        out.shape = match &s.shape {
            Shape::Box { lo, hi } => Shape::Box {
                lo: lo.iter().zip(&e).map(|(l, e)| l - sign * e).collect(),
                hi: hi.iter().zip(&e).map(|(h, e)| h + sign * e).collect(),
            },
            Shape::Polytope { A: pa, b } => Shape::Polytope {
                A: pa.clone(),
                b: b.iter()
                    .enumerate()
                    .map(|(r, bv)| {
                        let row = &pa.data[r * pa.cols..(r + 1) * pa.cols];
                        bv + sign * row.iter().zip(&e).map(|(a, e)| a.abs() * e).sum::<f64>()
                    })
                    .collect(),
            },
            Shape::Ball { center, radius } => {
                let en = e.iter().map(|v| v * v).sum::<f64>().sqrt();
                Shape::Ball {
                    center: center.clone(),
                    radius: (radius + sign * en).max(0.0),
                }
            }
            Shape::Ellipsoid { .. } => {
                return Err(FlError::FlatSetCoords {
                    what: format!("{what} (an ellipsoid)"),
                })
            }
        };
        out.coords = Coords::StateIndices(qidx);
        Ok(out)
    };
    let mut q = problem.clone();
    q.plant = SpecPlant {
        time: TimeDomain::Continuous,
        A,
        B,
        offset: vec![0.0; ne],
        period: h,
        C,
    };
    q.init = fd.init_q.clone();
    q.goal = remap("Goal", &problem.goal, false)?;
    q.unsafe_sets = problem
        .unsafe_sets
        .iter()
        .map(|s| remap("Unsafe", s, true))
        .collect::<Result<_, _>>()?;
    for (j, e) in e_q.iter().enumerate() {
        q.unsafe_sets
            .extend(outside_interval(j, region.lo[j] + e, region.hi[j] - e));
    }
    q.sets = problem
        .sets
        .iter()
        .map(|(k, s)| Ok((k.clone(), remap(&format!("[sets.{k}]"), s, true)?)))
        .collect::<Result<_, FlError>>()?;
    if let Some(src) = &problem.mtl {
        let set_names: Vec<String> = problem.sets.iter().map(|(k, _)| k.clone()).collect();
        let (formula, held) = formula_in_q(
            src,
            n,
            &q_of_state,
            names,
            &e_q,
            region,
            problem.horizon,
            &set_names,
        )?;
        for (name, set) in problem.sets.iter().filter(|(k, _)| held.contains(k)) {
            let held_name = held_set_name(name);
            if problem.sets.iter().any(|(k, _)| *k == held_name) {
                return Err(FlError::Formula(format!(
                    "a set named `{held_name}` is taken: the set `{name}` shrunk by the read error \
                     of q is given that name"
                )));
            }
            q.sets
                .push((held_name, remap(&format!("[sets.{name}]"), set, false)?));
        }
        q.mtl = Some(formula);
    }
    q.input = InputSet::Box {
        lo: wb.iter().map(|i| i.lo).collect(),
        hi: wb.iter().map(|i| i.hi).collect(),
    };
    q.nonlinear = None;
    let maps = FlMaps {
        n_plant: n,
        m_plant: m,
        xi_states: Vec::new(),
        zero_states: Vec::new(),
        coords,
        input_map,
        input_exprs: outputs[..m].to_vec(),
        plant: NonlinearPlant::from_desc(desc),
        input: problem.input.clone(),
        init: problem.init.clone(),
        zero_hull: Vec::new(),
        region: None,
        lambda_norm: f64::NAN,
        alpha_res_norm: f64::NAN,
        gamma_norm,
        e_prog: e_u,
        mismatch,
        mismatch_flow,
        flat: Some(FlatCoords {
            coords_tape: Tape::new(&q_exprs),
            ext_init: fd.ext_init(),
            ext_orders: fd.extension.iter().map(|e| e.order).collect(),
            q_states: fd.q_states.clone(),
            region: region.clone(),
            state_rate,
            jump,
            held,
        }),
    };
    Ok((q, maps))
}

/// The name under which a named set, shrunk by the read error of q, stands where a formula requires it.
fn held_set_name(name: &str) -> String {
    format!("{name}_held")
}

/// The `[mtl]` formula of a flat spec rewritten over the flat state q (module doc, *MTL tasks*), with the
/// names of the sets it requires somewhere (which [`flatten`] adds shrunk, as [`held_set_name`]).
///
/// The controller reads q within `e_q` of the true flat state (item 4), so an atom is moved by that
/// error in the direction that makes it harder: where the formula requires an atom (positive polarity:
/// under an even number of negations, the left side of an implication counting as one), a predicate's
/// bound is tightened by Σ|a_j|·e_q,j and a named set is replaced by its shrunk copy; where it forbids it,
/// the predicate is loosened and the set is the inflated one `q.sets` already holds. `Goal` (shrunk) may
/// only be required and `Unsafe` (inflated) only forbidden. A predicate's plant signal must be a state that
/// is a flat coordinate (the flat outputs and their derivatives). The operating region over q, shrunk by
/// e_q, joins as `(φ) & G[0,T] (q inside it)`, as for a feedback-linearizable plant's region.
fn formula_in_q(
    src: &str,
    n: usize,
    q_of_state: &dyn Fn(usize) -> Option<usize>,
    names: &crate::expr::Names,
    e_q: &[f64],
    region: &crate::spec::InitBox,
    horizon: f64,
    set_names: &[String],
) -> Result<(String, Vec<String>), FlError> {
    use crate::robustness::mtl::{Expr as M, Interval as TI, LinearPredicate, Span};
    let parsed = crate::robustness::mtl::parse(src).map_err(|e| FlError::Formula(e.to_string()))?;
    let plant_signals = crate::property::state_signals(n);
    struct Walk<'a> {
        plant_signals: &'a [String],
        q_of_state: &'a dyn Fn(usize) -> Option<usize>,
        names: &'a crate::expr::Names,
        e_q: &'a [f64],
        sets: &'a [String],
        held: Vec<String>,
    }
    impl Walk<'_> {
        fn go(&mut self, e: &M, positive: bool) -> Result<M, FlError> {
            Ok(match e {
                M::True | M::False => e.clone(),
                M::Set { name, span } => {
                    match name.as_str() {
                        "Goal" if !positive => return Err(FlError::FlatAtomPolarity {
                            atom: "Goal".into(),
                            why: "it is shrunk by the read error of q, so it may only be required",
                        }),
                        "Unsafe" if positive => return Err(FlError::FlatAtomPolarity {
                            atom: "Unsafe".into(),
                            why: "it is inflated by the read error of q, so it may only be avoided",
                        }),
                        "Goal" | "Unsafe" => e.clone(),
                        // A name that is not a set of the spec is left as written: binding the task
                        // reports it, pointing into the formula.
                        _ if positive && self.sets.iter().any(|k| k == name) => {
                            if !self.held.contains(name) {
                                self.held.push(name.clone());
                            }
                            M::Set {
                                name: held_set_name(name),
                                span: *span,
                            }
                        }
                        _ => e.clone(),
                    }
                }
                M::Linear(p) => {
                    let refuse = |predicate: String, state: String| {
                        FlError::PredicateOffFlatState { predicate, state }
                    };
                    match predicate_in_coords(
                        p,
                        self.plant_signals,
                        self.q_of_state,
                        self.names,
                        &refuse,
                    )? {
                        Renamed::Constant(true) => M::True,
                        Renamed::Constant(false) => M::False,
                        Renamed::Predicate(mut q, coords) => {
                            // aᵀq̃ ≤ b − Σ|a_j|e_j implies aᵀq ≤ b for the true q; the loosened bound
                            // for a forbidden predicate likewise.
                            let moved: f64 = q
                                .terms
                                .iter()
                                .zip(&coords)
                                .map(|((_, c, _), &j)| c.abs() * self.e_q[j])
                                .sum();
                            q.b = if positive { p.b - moved } else { p.b + moved };
                            M::Linear(q)
                        }
                    }
                }
                M::Not(x) => M::Not(Box::new(self.go(x, !positive)?)),
                M::And(v) => M::And(
                    v.iter()
                        .map(|x| self.go(x, positive))
                        .collect::<Result<_, _>>()?,
                ),
                M::Or(v) => M::Or(
                    v.iter()
                        .map(|x| self.go(x, positive))
                        .collect::<Result<_, _>>()?,
                ),
                M::Implies(l, r) => M::Implies(
                    Box::new(self.go(l, !positive)?),
                    Box::new(self.go(r, positive)?),
                ),
                M::Eventually(i, x) => M::Eventually(*i, Box::new(self.go(x, positive)?)),
                M::Always(i, x) => M::Always(*i, Box::new(self.go(x, positive)?)),
                M::Until(i, l, r) => M::Until(
                    *i,
                    Box::new(self.go(l, positive)?),
                    Box::new(self.go(r, positive)?),
                ),
                M::Release(i, l, r) => M::Release(
                    *i,
                    Box::new(self.go(l, positive)?),
                    Box::new(self.go(r, positive)?),
                ),
            })
        }
    }
    let mut walk = Walk {
        plant_signals: &plant_signals,
        q_of_state,
        names,
        e_q,
        sets: set_names,
        held: Vec::new(),
    };
    let phi = walk.go(&parsed, true)?;
    // G[0,T] (q inside the region shrunk by e_q): the bounds of the law and of D hold only there.
    let span = Span::new(0, 0);
    let mut keep = Vec::with_capacity(2 * e_q.len());
    for (j, e) in e_q.iter().enumerate() {
        let name = format!("x{}", j + 1);
        for (a, b) in [(1.0, region.hi[j] - e), (-1.0, -(region.lo[j] + e))] {
            keep.push(M::Linear(LinearPredicate {
                terms: vec![(name.clone(), a, span)],
                b,
                span,
            }));
        }
    }
    let t = TI::new(0.0, horizon)
        .ok_or_else(|| FlError::Formula(format!("the horizon {horizon} is not a time bound")))?;
    let out = M::And(vec![phi, M::Always(t, Box::new(M::And(keep)))]);
    Ok((out.to_string(), walk.held))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quadrotor() -> Problem {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/flat-quadrotor.toml"
        );
        crate::spec::load(path).unwrap_or_else(|e| panic!("{}", e.headline()))
    }

    /// The speed task's formula over q: the plant's velocity signals renamed to q's, the sets it requires
    /// (Cruise under `!Cruise ->`, Slow) shrunk under new names, Unsafe and Goal as they are, the region's
    /// conjunct; a predicate on θ and a required Unsafe are refused, naming them.
    #[test]
    fn an_mtl_formula_is_rewritten_over_q_with_its_atoms_moved_by_polarity() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/flat-quadrotor-speed.toml"
        );
        let mut p = crate::spec::load(path).unwrap_or_else(|e| panic!("{}", e.headline()));
        let (q, _) = flatten(&p).unwrap_or_else(|e| panic!("{e}"));
        let f = q.mtl.as_deref().expect("the formula in q");
        assert!(f.contains("Slow_held") && f.contains("Cruise_held"), "{f}");
        assert!(f.contains("Unsafe") && !f.contains("Unsafe_held"), "{f}");
        assert!(f.contains("G[0.0,9.0] ((1.0*x1 <= 9.99999"), "{f}");
        let radius = |name: &str| match &q.sets.iter().find(|(k, _)| k == name).unwrap().1.shape {
            Shape::Ball { radius, .. } => *radius,
            _ => panic!("{name} is a ball"),
        };
        assert!(radius("Slow_held") < 3.2 && 3.2 < radius("Slow"));
        // The velocities X' and Y' are q's second and sixth coordinates.
        p.mtl = Some("G[0,9] (x2 <= 3.5 & x4 >= -3.5)".into());
        let (q, _) = flatten(&p).unwrap_or_else(|e| panic!("{e}"));
        let f = q.mtl.unwrap();
        // Required: each bound tightened by the read error of its coordinate.
        assert!(
            f.contains("1.0*x2 <= 3.49999") && f.contains("1.0*x6 <= 3.49999"),
            "{f}"
        );
        p.mtl = Some("G[0,9] (x5 <= 0.3)".into());
        let e = flatten(&p)
            .err()
            .expect("θ is not a flat coordinate")
            .to_string();
        assert!(
            e.contains("th") && e.contains("not a flat coordinate"),
            "{e}"
        );
        p.mtl = Some("F[0,9] Unsafe".into());
        let e = flatten(&p).err().expect("a required Unsafe").to_string();
        assert!(e.contains("Unsafe") && e.contains("only be avoided"), "{e}");
    }
    #[test]
    fn the_quadrotor_flattens_to_two_chains_of_four_with_its_bounds() {
        let p = quadrotor();
        let (q, maps) = flatten(&p).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((q.plant.n(), q.plant.m()), (8, 2));
        // The chains: q̇_k = q_{k+1} within each output's block of four, the snap as input.
        for i in 0..8 {
            for j in 0..8 {
                let want = if j == i + 1 && i % 4 != 3 { 1.0 } else { 0.0 };
                assert_eq!(q.plant.A.data[i * 8 + j], want, "A[{i}][{j}]");
            }
        }
        assert_eq!(q.plant.B.data[3 * 2], 1.0);
        assert_eq!(q.plant.B.data[7 * 2 + 1], 1.0);
        // Init in q: hover at rest, Ÿ = T/m − g = 0 with T = m g.
        assert_eq!(q.init.lo[0], -7.25);
        assert_eq!(q.init.hi[4], 5.25);
        assert!(q.init.lo[6].abs() < 1e-12 && q.init.hi[6].abs() < 1e-12);
        // The spec's flat input box is W; its inputs stay in U over the region (else refused).
        assert_eq!(
            q.input,
            InputSet::Box {
                lo: vec![-3.0; 2],
                hi: vec![3.0; 2]
            }
        );
        // The held thrust enters the velocities' derivatives only; the jumps are rounding-sized.
        let fc = maps.flat.as_ref().expect("flat coordinates");
        for (j, b) in fc.state_rate.iter().enumerate() {
            assert_eq!(*b > 0.0, j == 1 || j == 5, "rate {j}: {b}");
        }
        assert!(
            fc.jump.iter().all(|&j| j > 0.0 && j < 1e-3),
            "{:?}",
            fc.jump
        );
        assert!(maps.mismatch > 0.0 && maps.mismatch.is_finite());
        // The coords program evaluates q from (x, ζ): hover at (−7, 5) is q = (−7, 0, 0, 0, 5, 0, 0, 0).
        let x = [-7.0, 0.0, 5.0, 0.0, 0.0, 0.0];
        let got = maps.xi_of(&x);
        let want = [-7.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0];
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{got:?}");
        }
        assert_eq!(maps.state_coords(), vec![(0, 0), (1, 1), (4, 2), (5, 3)]);
        // The region's complement joins Unsafe: two half-spaces per flat coordinate.
        assert_eq!(q.unsafe_sets.len(), p.unsafe_sets.len() + 16);
    }

    /// The quadrotor's state derivative under a thrust and an angular acceleration (m = 1, g = 9.81).
    fn quadrotor_field(x: &[f64; 6], thrust: f64, tau: f64) -> [f64; 6] {
        [
            x[1],
            -thrust * x[4].sin(),
            x[3],
            thrust * x[4].cos() - 9.81,
            x[5],
            tau,
        ]
    }

    /// The model the chain is exact for: the thrust following its extension's polynomial
    /// T(t) = T0 + Ṫ0 t + T̈ t²/2 over the period, by classical Runge–Kutta on `steps` sub-steps.
    fn quadrotor_model(x: [f64; 6], z: [f64; 2], ue: f64, tau: f64, h: f64) -> [f64; 6] {
        let steps = 4000;
        let dt = h / steps as f64;
        let thrust = |t: f64| z[0] + z[1] * t + 0.5 * ue * t * t;
        let add = |x: &[f64; 6], k: &[f64; 6], a: f64| std::array::from_fn(|i| x[i] + a * k[i]);
        let mut x = x;
        for s in 0..steps {
            let t = s as f64 * dt;
            let k1 = quadrotor_field(&x, thrust(t), tau);
            let k2 = quadrotor_field(&add(&x, &k1, 0.5 * dt), thrust(t + 0.5 * dt), tau);
            let k3 = quadrotor_field(&add(&x, &k2, 0.5 * dt), thrust(t + 0.5 * dt), tau);
            let k4 = quadrotor_field(&add(&x, &k3, dt), thrust(t + dt), tau);
            x = std::array::from_fn(|i| {
                x[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            });
        }
        x
    }

    /// The firmware applies the thrust's period mean and holds it; the flat state at the period's end then
    /// departs from the model's (where the thrust follows its polynomial) by at most `held`, coordinate by
    /// coordinate, and that bound is far below the first-order one of holding ζ_0 (h·sup|sin θ|·|Ṫ| on Ẋ).
    #[test]
    fn holding_the_thrust_s_period_mean_departs_from_the_model_within_the_held_bound() {
        let p = quadrotor();
        let (_, maps) = flatten(&p).unwrap_or_else(|e| panic!("{e}"));
        let fc = maps.flat.as_ref().expect("flat coordinates");
        let h = p.plant.period;
        // (X, Ẋ, Y, Ẏ, θ, θ̇), (T, Ṫ) and the snap w: inside the region and W.
        let cases: [([f64; 6], [f64; 2], [f64; 2]); 3] = [
            ([0.0, 2.0, 8.0, -1.0, -0.1, 0.05], [9.9, 0.5], [2.0, -2.5]),
            (
                [-5.0, -1.0, 12.0, 0.5, 0.15, -0.06],
                [10.5, -0.6],
                [-2.8, 1.0],
            ),
            ([3.0, 0.5, 4.0, 0.0, 0.05, 0.05], [9.9, 0.5], [1.0, 1.0]),
        ];
        for (x, z, w) in cases {
            let xe: Vec<f64> = x.iter().chain(&z).copied().collect();
            let at = crate::expr::Point {
                x: &xe,
                u: &w,
                p: &[],
            };
            let q0 = maps.xi_at(&x, &z);
            for (j, v) in q0.iter().enumerate() {
                assert!(
                    fc.region.lo[j] <= *v && *v <= fc.region.hi[j],
                    "q0[{j}] = {v}"
                );
            }
            let (tbar, tau) = (maps.input_exprs[0].eval(&at), maps.input_exprs[1].eval(&at));
            // The extension's input T̈ from the applied mean T̄ = T0 + Ṫ0 h/2 + T̈ h²/6.
            let ue = (tbar - z[0] - 0.5 * z[1] * h) * 6.0 / (h * h);
            let actual = maps
                .plant
                .flow(&x, &[tbar, tau], h, 1, &mut |_| {})
                .expect("flow");
            let model = quadrotor_model(x, z, ue, tau, h);
            let zh = [z[0] + z[1] * h + 0.5 * ue * h * h, z[1] + ue * h];
            let (qa, qm) = (maps.xi_at(&actual, &zh), maps.xi_at(&model, &zh));
            for j in 0..qa.len() {
                let dev = (qa[j] - qm[j]).abs();
                assert!(
                    dev <= fc.held[j] + 1e-12,
                    "q[{j}]: departs {dev:.3e} > held bound {:.3e} at x = {x:?}",
                    fc.held[j]
                );
            }
            // Holding ζ_0 instead: the velocity alone departs by about h·|sin θ|·|Ṫ|·h/2.
            let first_order = 0.5 * h * h * x[4].sin().abs() * z[1].abs();
            let dev_v = (qa[1] - qm[1]).abs();
            assert!(
                dev_v < 0.05 * first_order,
                "{dev_v:.3e} vs {first_order:.3e}"
            );
        }
    }

    #[test]
    fn a_flat_input_the_torque_bound_cannot_take_is_refused() {
        let mut p = quadrotor();
        if let Some(fd) = p.nonlinear.as_mut().and_then(|d| d.flat.as_mut()) {
            fd.flat_input = Some(crate::spec::InitBox {
                lo: vec![-1e3; 2],
                hi: vec![1e3; 2],
            });
        }
        let Err(e) = flatten(&p) else {
            panic!("refused")
        };
        assert!(matches!(e, FlError::FlatInputTooLarge { .. }), "{e}");
    }
}
