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
//! pure chain, K̂ and P of (3.41)): the plant gets an extended input's ζ_0 (the thrust it keeps), the
//! others their u_e, and ζ advances by the exact zero-order-hold solution of its integrators under the held
//! u_e: ζ_k⁺ = Σ_{l ≥ k} ζ_l h^{l−k}/(l−k)! + u_e h^{o−k}/(o−k)!.
//!
//! **Every bound is over the operating region Q** (a box over q, `plant.region`), evaluated by interval
//! enclosures of the expressions with x_e = Ξ_e(q) substituted (Ξ the user's map, ζ(q) derived from Υ),
//! on a grid of sub-boxes of the coordinates they use. Leaving Q is entering Unsafe, which the certificate
//! excludes (its complement joins the task's Unsafe): the first-exit argument of
//! `model::feedback_linearizable` carries over unchanged.
//! 1. *The input set* pulled back to a box W of the flat input: the spec's `plant.flat_input` when set,
//!    else the largest cube {|w_j| ≤ ω} (by bisection); either way the enclosure of every non-extended
//!    input over Q × W, widened by the input program's rounding, must lie in U (else refused). An
//!    extended input is ζ_0 = Υ_j(q), whose enclosure over Q must lie in U (else refused: shrink Q).
//! 2. *The w-channel mismatch D*: with u_e held, the last chain element's derivative departs from w by
//!    φ(x_e(t)) − φ(x_e,k), φ = α + Γu_e, whose rate is the Lie derivative E of φ along the extended field
//!    under the held u_e, plus its Lie derivative along the extended input's column of g times how far the
//!    held ζ_0 is from the model's ζ_0(t) within a period, Δ = Σ_{k ≥ 1} h^k/k!·|ζ_k| + h^o/o!·|u_e|. So
//!    D = h·sup(‖E‖ + ‖L_{g_T}φ‖Δ) + ‖Γ‖·e_u, e_u the input program's rounding of the non-extended inputs.
//! 3. *The state-channel rate*: the held ζ_0 also enters q̇ directly, through ∂Φ/∂x·g_T: per coordinate
//!    b_j = sup|L_{g_T}Φ_j|·Δ (the planar quadrotor's velocity rows).
//! 4. *The jump per period*: the f32 rounding of ζ⁺ moves q by Σ_k |∂Φ_j/∂ζ_k|·e_ζ,k, and the f32
//!    rounding e_q of the coords program is a misreading of q, which moves the loop as a jump of
//!    (1 + ‖row_j(e^{Ah})‖₁)·e_q at most (the loop in the read coordinates q̃ = q + e is exact up to
//!    e_{k+1} − e^{Ah}e_k); the read state is within e_q of the true one, so Unsafe, the region's
//!    complement and Goal are moved by e_q (inflated, shrunk) before certification.
//!
//! `certify::LoopConstants` adds 3 and 4 to the per-step disturbance in the P-metric
//! (φ Σ b_j √P_jj + Σ J_j √P_jj), next to φβD.
//!
//! **Not yet synthesised.** `task::Task::new` builds all of this and then refuses the task
//! (`TaskError::FlatNotSynthesised`). The image carries the controller's states ζ (ζ0 in the model maps
//! section, ζ⁺ from the input map on every accepted step), but the closed-loop Monte Carlo, `simulate`
//! and `play` still judge a plant state without them, so no certificate could be re-checked. The bounds
//! it reports (W, D) are the ones the certificate will take.

use super::feedback_linearizable::{
    adjugate, bound_err, cancelling_law, dims_used, gram, norm2_bound, outside_interval,
    sup_over_grid, FlError, FlMaps, FlatCoords,
};
use super::nonlinear::NonlinearPlant;
use crate::expr::compile::compile;
use crate::expr::diff::{derivative, lie};
use crate::expr::interval::{enclose, rounding_bound, Interval, IntervalError, VarBox};
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
    if problem.mtl.is_some() {
        return Err(FlError::FlatMtl);
    }
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
    let mut outputs: Vec<Expr> = (0..m)
        .map(|j| match first[j] {
            Some(z0) => state(z0),
            None => ue[j].clone(),
        })
        .collect();
    let fact = |k: usize| (1..=k).product::<usize>() as f64;
    for e in &fd.extension {
        let (z0, o) = (first[e.input].unwrap_or(n), e.order);
        for k in 0..o {
            let mut next = Expr::c(0.0);
            for l in k..o {
                next = Expr::add(
                    next,
                    Expr::mul(Expr::c(h.powi((l - k) as i32) / fact(l - k)), state(z0 + l)),
                );
            }
            next = Expr::add(
                next,
                Expr::mul(
                    Expr::c(h.powi((o - k) as i32) / fact(o - k)),
                    ue[e.input].clone(),
                ),
            );
            outputs.push(next);
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

    // 3. Extended inputs: ζ_0 over Q inside U.
    for e in &fd.extension {
        let z0 = to_q(&state(first[e.input].unwrap_or(n)));
        let lo_hi = grid_range(&base, &z0).map_err(bound_err("an extended input over Q"))?;
        let j = e.input;
        if lo_hi.0 < input.0[j] || lo_hi.1 > input.1[j] {
            return Err(FlError::FlatExtendedInput {
                input: desc.names.inputs[j].clone(),
                lo: lo_hi.0,
                hi: lo_hi.1,
                ulo: input.0[j],
                uhi: input.1[j],
            });
        }
    }

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
    let mut e_rate = Vec::with_capacity(m);
    let mut e_held: Vec<Vec<Expr>> = Vec::with_capacity(m);
    for i in 0..m {
        let phi = (0..m).fold(alpha[i].clone(), |acc, l| {
            Expr::add(acc, Expr::mul(gamma[i][l].clone(), w(l)))
        });
        e_rate.push(to_q(&lie(&phi, &field_u)?));
        e_held.push(
            g_ext
                .iter()
                .map(|(_, col)| lie(&phi, col).map(|e| to_q(&e)))
                .collect::<Result<_, _>>()?,
        );
    }
    // Δ per extended input, as an expression over q and U: Σ_{k≥1} h^k/k!|ζ_k| + h^o/o!|U|.
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
                        Expr::c(h.powi(k as i32) / fact(k)),
                        Expr::func(crate::expr::Func::Abs, xe_of_q[z0 + k].clone()),
                    ),
                );
            }
            Expr::add(
                d,
                Expr::mul(
                    Expr::c(h.powi(e.order as i32) / fact(e.order)),
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

    // 7. The state-channel rate and the jump, per q coordinate.
    let mut state_rate = vec![0.0f64; n_q];
    let mut jump = vec![0.0f64; n_q];
    // e^{Ah} of the chains: row j's absolute sum is Σ_{l<r−k} h^l/l! for the k-th element of a chain of r.
    let mut ah_row = Vec::with_capacity(n_q);
    for &r in &rd.r {
        for k in 0..r {
            ah_row.push((0..r - k).map(|l| h.powi(l as i32) / fact(l)).sum::<f64>());
        }
    }
    for j in 0..n_q {
        let qj = &q_exprs[j];
        let mut rate_terms: Vec<Expr> = Vec::new();
        for (_, col) in &g_ext {
            rate_terms.push(to_q(&lie(qj, col)?));
        }
        let mut dz_terms: Vec<Expr> = Vec::new();
        for s in n..ne {
            dz_terms.push(to_q(&derivative(qj, Var::State(s as u16))?));
        }
        let mut refs: Vec<&Expr> = rate_terms.iter().chain(&dz_terms).collect();
        refs.extend(deltas.iter());
        let dj = dims_used(&refs, &base);
        let (rate, jz) = {
            let best = std::cell::Cell::new((0.0f64, 0.0f64));
            sup_over_grid(&base, &dj, &|q| {
                let ub = u_box(q)?;
                let b = VarBox {
                    x: q,
                    u: &ub,
                    p: &[],
                };
                let mut r = 0.0;
                for (k, t) in rate_terms.iter().enumerate() {
                    r += enclose(t, &b)?.mag() * enclose(&deltas[k], &b)?.mag();
                }
                let mut jz = 0.0;
                for (k, t) in dz_terms.iter().enumerate() {
                    jz += enclose(t, &b)?.mag() * e_zeta[k];
                }
                let (r0, j0) = best.get();
                best.set((r0.max(r), j0.max(jz)));
                Ok(0.0)
            })
            .map_err(bound_err("the held input's rate"))?;
            best.get()
        };
        state_rate[j] = rate * (1.0 + 1e-9);
        jump[j] = (jz + (1.0 + ah_row[j]) * e_q[j]) * (1.0 + 1e-9);
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
            coords_exprs: q_exprs,
            ext_init: fd.ext_init(),
            q_states: fd.q_states.clone(),
            region: region.clone(),
            state_rate,
            jump,
        }),
    };
    Ok((q, maps))
}

/// The range of `e` over the box `base` (a grid of sub-boxes of the coordinates it uses).
fn grid_range(base: &[Interval], e: &Expr) -> Result<(f64, f64), IntervalError> {
    let dims = dims_used(&[e], base);
    let hi = sup_over_grid(base, &dims, &|q| {
        Ok(enclose(
            e,
            &VarBox {
                x: q,
                u: &[],
                p: &[],
            },
        )?
        .hi)
    })?;
    let lo = -sup_over_grid(base, &dims, &|q| {
        Ok(-enclose(
            e,
            &VarBox {
                x: q,
                u: &[],
                p: &[],
            },
        )?
        .lo)
    })?;
    Ok((lo, hi))
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
                lo: vec![-10.0; 2],
                hi: vec![10.0; 2]
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
