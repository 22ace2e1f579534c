//! Feedback-linearizable plants (§3.1.2, Def 3.5, law (3.17)) as a [`Plant`] of the pipeline: the
//! certificate lives on the linear system in the coordinates ξ, the firmware maps the measured state to ξ
//! and the linear law's output w back to the plant's input u through two model programs, and the sampled
//! loop's departure from the linear model is a bounded disturbance in the w channel (Theorem 3.21).
//!
//! **Coordinates.** For outputs y_i = h_i(x) of relative degree r_i, ξ stacks (h_i, L_f h_i, …,
//! L_f^{r_i−1} h_i) per output, so ξ̇ is a chain of integrators per output ending in
//! ξ̇_{i,r_i−1} = α_i(x) + (Γ(x)u)_i, α_i = L_f^{r_i} h_i, Γ the decoupling matrix (3.19). This module takes
//! plants whose every ξ coordinate is one of the plant's states (mechanical systems written in positions
//! and velocities); the other states are the zero dynamics (Remark 3.6), which the certificate does not
//! track but bounds (below).
//!
//! **The law.** Where α_i is exactly affine in the ξ states, that affine part a_iᵀξ + c_i stays in the
//! linear model (Example 4.9's drift 1 − X + 0.1Ẋ, so κ = 0 there as in the text) and α_res,i = 0;
//! otherwise all of α_i is cancelled (α_res,i = α_i). The linear model is ξ̇ = A_ξ ξ + B_ξ w + c_ξ and the
//! firmware applies u = λ(x)(w − α_res(x)), λ = Γ⁻¹ = adj(Γ)/det Γ (symbolic, m ≤ 3): (3.17) with
//! κ = −λ α_res.
//!
//! **What is bounded, and how.** Without an operating region, this module takes plants whose zero
//! dynamics, λ and α_res depend only on the zero-dynamics states (and u), so every bound below is
//! independent of the nominal trajectory. With one (`plant.region`, a box over the plant's state that
//! contains Init, `spec::nonlinear`), they may depend on any state: the ξ states then range over the
//! region's box in every bound below, the zero-dynamics hull must lie in the region's zero part, and the
//! task's Unsafe gains the region's complement in ξ (two closed half-spaces per ξ state). This is sound
//! by a first-exit argument: let t* be the first time a run leaves the region. Up to t* every bound
//! below holds, so the certificate's induction (Theorem 4.7 with D, Theorem 3.21) keeps the run in its
//! tube, which stays a positive distance from Unsafe (sampled and between samples), hence inside the
//! region, so the run is strictly inside at t* and t* cannot end before the run does. Certified runs thus
//! never leave the region, and `verify::nonlinear` checks that on the plant, zero states included.
//! Every bound is still independent of the nominal trajectory; the price is the region's size:
//! 1. *Zero dynamics over [0, T]*: a validated first-order enclosure per sample period (Picard iteration
//!    of Z_k + [0, h]·F(Z̃) ⊆ Z̃, F the interval field with u in the input set: runs in the certified tube
//!    apply inputs in U, so this is an induction over samples), from Init's zero-dynamics box. Their hull
//!    Z is where every bound below is taken, over a grid of up to [`MAX_PIECES`] sub-boxes.
//! 2. *The input set pulled back* to w: ‖u − c‖ ≤ ‖λ‖(‖w‖ + ‖α_res‖) + ‖c‖ + e_prog, so the ball
//!    W = {‖w‖ ≤ (ρ − ‖c‖ − e_prog)/L − A} maps into U (for a box U, the analogous componentwise bound),
//!    with L ≥ ‖λ‖₂ from the enclosure of λᵀλ, A ≥ ‖α_res‖₂ and e_prog the input program's f32 rounding
//!    bound (`expr::interval::rounding_bound`). For Example 4.9 λ is a rotation and W is U shrunk by the
//!    enclosures' slack and the rounding.
//! 3. *The sampled-loop mismatch* D: with u_k held, ξ̇ of the last chain element is
//!    a_iᵀξ + c_i + w_k,i + φ_i(x(t)) − φ_i(x_k) with φ = α_res + Γ u_k (because Γ(x_k)u_k = w_k − α_res(x_k)),
//!    and |φ(x(t)) − φ(x_k)| ≤ h·sup‖E‖, E = the Lie derivative of φ along f + g u_k, a polynomial of degree
//!    2 in u bounded as ‖e₀‖ + ‖M‖₂R_u + ½‖Q‖R_u² over Z, R_u the radius of the inputs a certified run
//!    applies: the least of U's and L(sup_W ‖w‖ + A) + e_prog (the law's u for w in W, item 2;
//!    `applied_input_radius`). The input program's rounding enters the same
//!    channel through Γ: D = h·sup‖E‖ + sup‖Γ‖₂·e_prog. The certificate takes D as a w-channel disturbance
//!    that varies within the period (`certify::LoopConstants::mismatch`).
//!
//! **MTL tasks** (Problem 2.28, Theorem 4.2; issue #14). An `[mtl] formula` is the task on the linear
//! model in ξ exactly as for a linear plant (`certify::temporal`), with D the same w-channel disturbance
//! as for reach-avoid: r_crit and the inter-sample margin take it (`LoopConstants::r_crit`,
//! `held_disturbance`), and the radius left after summing it over the table, δ = (the formula's tube
//! bound) − S_N·(‖P^{1/2}B‖ε̄ + φβD), is the alternative Theorem 4.7's certificate also takes. The formula
//! is rewritten into ξ ([`formula_in_xi`]): its predicates' signals `x1 … xn` name the *plant's* states
//! and become the ξ index of that state; a predicate weighing a zero-dynamics state is refused
//! ([`FlError::PredicateOnZeroDynamics`]), as a named set on one is ([`FlError::SetOnZeroDynamics`]), since
//! the certificate does not track those states. The bounds above hold only while the run stays in the
//! operating region, which the formula need not mention; so with a region the task is
//! `φ ∧ G[0,T] (ξ in the region's ξ box)`: the simplest sound choice. A certified run's tube then has
//! positive depth in that box at every sample and between samples, so the first-exit argument above goes
//! through unchanged (the conjunct plays the part of the region's complement in Unsafe), and a run that
//! satisfies the rewritten formula satisfies φ. The price is that the formula's robustness is at most the
//! nominal's depth in the region, which a region chosen for the task leaves ample. Without a region no
//! conjunct is needed (every bound holds over all ξ). `verify::temporal::monte_carlo_temporal_fl` judges
//! the image on the nonlinear plant by the formula as rewritten, and counts leaving the region (zero
//! states included) as a violation.

use super::linear::{ContinuousPlant, DiscretePlant, LinearAffine};
use super::nonlinear::NonlinearPlant;
use super::{Location, ModelError, Plant};
use crate::expr::compile::{compile, Compiled};
use crate::expr::diff::{derivative, gradient, lie};
use crate::expr::interval::{enclose, rounding_bound, Interval, IntervalError, VarBox};
use crate::expr::tape::Tape;
use crate::expr::{Expr, ExprError, Point, Var};
use crate::spec::sets::{Coords, Shape};
use crate::spec::{InitBox, InputSet, Matrix, Plant as SpecPlant, Problem, SetDesc, TimeDomain};
use std::sync::Arc;

/// Most sub-boxes of the zero-dynamics hull a bound is taken over (a grid over the coordinates the
/// bounded expressions use).
pub const MAX_PIECES: usize = 4096;
/// Picard iterations allowed for one period's a-priori enclosure of the zero dynamics.
const PICARD_ITERATIONS: usize = 30;

/// Why a feedback-linearizable spec cannot be taken.
#[derive(Debug, thiserror::Error)]
pub enum FlError {
    #[error("{0}")]
    Expr(#[from] ExprError),
    #[error("plant: {0}")]
    Model(#[from] ModelError),
    #[error(
        "ξ coordinate {index} is L_f^{k} h_{output} = {expr}, which is not one of the plant's states; \
         this version takes plants whose outputs and their derivatives up to the relative degree are \
         states (write the model in those coordinates)"
    )]
    CoordinateNotAState {
        index: usize,
        output: usize,
        k: usize,
        expr: String,
    },
    #[error(
        "{what} depends on {state}, a state of the linearised coordinates ξ, and the spec declares no \
         operating region: without one the law and the zero dynamics are bounded over the \
         zero-dynamics states only; declare plant.region = {{ lo = [...], hi = [...] }} (a box over \
         the state containing Init) to bound them there, leaving it then counts as Unsafe"
    )]
    DependsOnXi { what: String, state: String },
    #[error(
        "the zero dynamics leave the operating region: {state} may reach [{hull_lo:.6}, {hull_hi:.6}] \
         within the horizon (a validated enclosure), but plant.region bounds it to [{lo}, {hi}]; widen \
         the region's bounds on {state}"
    )]
    ZeroDynamicsLeaveRegion {
        state: String,
        hull_lo: f64,
        hull_hi: f64,
        lo: f64,
        hi: f64,
    },
    #[error("the decoupling matrix Γ is {m}×{m}; its symbolic inverse is built for m ≤ 3")]
    TooManyInputs { m: usize },
    #[error(
        "{what} constrains {state}, a state of the zero dynamics; sets may only constrain the \
             linearised coordinates ξ (the outputs and their derivatives)"
    )]
    SetOnZeroDynamics { what: String, state: String },
    #[error(
        "the zero dynamics could not be enclosed over the horizon (period {k}: {why}); the \
             certificate needs them bounded"
    )]
    ZeroDynamicsUnbounded { k: usize, why: String },
    #[error("an interval bound of {what} failed: {why}")]
    Bound { what: String, why: String },
    #[error(
        "the input set pulled back through u = λ(x)(w − α_res(x)) is empty: {why} (‖λ‖₂ ≤ {lambda:.4}, \
         ‖α_res‖₂ ≤ {alpha:.4}, program rounding {e_prog:.3e})"
    )]
    EmptyInputSet {
        why: String,
        lambda: f64,
        alpha: f64,
        e_prog: f64,
    },
    #[error("the [mtl] formula does not parse: {0}")]
    Formula(String),
    #[error(
        "the [mtl] formula's predicate `{predicate}` constrains {state}, a state of the zero dynamics; \
         predicates may only constrain the linearised coordinates ξ (the outputs and their derivatives)"
    )]
    PredicateOnZeroDynamics { predicate: String, state: String },
    #[error(
        "the [mtl] formula's predicate `{predicate}` constrains {state}, which is not a flat \
         coordinate; predicates may only constrain the flat outputs and their derivatives"
    )]
    PredicateOffFlatState { predicate: String, state: String },
    #[error("the [mtl] formula uses {atom} the other way round: {why}")]
    FlatAtomPolarity { atom: String, why: &'static str },
    #[error(
        "a differentially flat plant's input set must be a box (kind = \"box\"): an extended \
         input is bounded by the operating region, the others by a box of the flat input"
    )]
    FlatInputBall,
    #[error(
        "the extended input {input} (a controller state) ranges over [{lo:.4}, {hi:.4}] on the \
         operating region, outside the input set's [{ulo}, {uhi}]; shrink plant.region's bounds on \
         the flat coordinates it depends on"
    )]
    FlatExtendedInput {
        input: String,
        lo: f64,
        hi: f64,
        ulo: f64,
        uhi: f64,
    },
    #[error(
        "the plant's inputs leave the input set over the operating region by {excess:.4e} with this \
         flat input (a box W = plant.flat_input, or w = 0 when none is set): shrink plant.region's \
         bounds (the higher derivatives bind first) or plant.flat_input, or widen [input]"
    )]
    FlatInputTooLarge { excess: f64 },
    #[error(
        "{what}: a differentially flat plant's sets are over the plant's states that are flat \
         coordinates (coords = [\"x1\", …]), as a box, polytope or ball"
    )]
    FlatSetCoords { what: String },
}

/// The maps and bounds of a linearised plant (module doc).
#[derive(Clone, Debug)]
pub struct FlMaps {
    /// The plant's own state and input dimensions.
    pub n_plant: usize,
    pub m_plant: usize,
    /// ξ_j is state `xi_states[j]`.
    pub xi_states: Vec<usize>,
    /// The zero-dynamics states, in state order.
    pub zero_states: Vec<usize>,
    /// x ↦ ξ (inputs: the n_plant states).
    pub coords: Compiled,
    /// (x, w) ↦ u (inputs: the n_plant states, then w).
    pub input_map: Compiled,
    /// u_i(x, w) as expressions (parameters bound), the f64 reference of `input_map` (a flat plant's over
    /// the extended state (x, ζ) and w).
    pub input_exprs: Vec<Expr>,
    /// The plant in f64 (for verification).
    pub plant: NonlinearPlant,
    /// The plant's input set U (the task's input set is W, in w).
    pub input: InputSet,
    /// The plant's Init (the task's Init is its ξ part).
    pub init: InitBox,
    /// The zero-dynamics hull Z over [0, T] (one interval per zero state).
    pub zero_hull: Vec<Interval>,
    /// The spec's operating region (`plant.region`, module doc), a box over the plant's state; the
    /// runs must stay inside it (its ξ part is in the task's Unsafe, its zero part contains Z).
    pub region: Option<InitBox>,
    /// L ≥ sup ‖λ‖₂, A ≥ sup ‖α_res‖₂, G ≥ sup ‖Γ‖₂ over Z, and the input program's rounding bound.
    pub lambda_norm: f64,
    pub alpha_res_norm: f64,
    pub gamma_norm: f64,
    pub e_prog: f64,
    /// D: the w-channel disturbance of the sampled loop (module doc, item 3), and its parts.
    pub mismatch: f64,
    pub mismatch_flow: f64,
    /// A differentially flat plant's coordinates (`model::flat`): ξ is then its flat state q, a function
    /// of the plant's state and the controller's own states, and `xi_states` is empty.
    pub flat: Option<FlatCoords>,
}

/// The flat state of a differentially flat plant (`model::flat`) and the disturbances its sampled loop
/// adds outside the w channel.
#[derive(Clone, Debug)]
pub struct FlatCoords {
    /// q(x, ζ) (parameters bound), the expressions the `coords` program computes, as one f64 tape
    /// ([`crate::expr::tape`]): the verifier's q of a plant state.
    pub coords_tape: Tape,
    /// The controller states' initial values ζ0.
    pub ext_init: Vec<f64>,
    /// The order of each extended input's chain in ζ, in ζ's order (its states ζ_0 … ζ_{o−1}).
    pub ext_orders: Vec<usize>,
    /// q_j is the plant's state s.
    pub q_states: Vec<Option<usize>>,
    /// The operating region, a box over q: leaving it is entering Unsafe.
    pub region: InitBox,
    /// Per q coordinate, bounds on a disturbance rate entering that coordinate's derivative (the held
    /// input the plant applies against the extension's model of it), and on a jump per period (the f32
    /// rounding of the stored controller states and of q).
    pub state_rate: Vec<f64>,
    pub jump: Vec<f64>,
    /// Per q coordinate, the part of `jump` from applying an extended input as its period mean rather than
    /// the model's ζ_0(t) (`model::flat`, item 3).
    pub held: Vec<f64>,
}

impl FlatCoords {
    /// The model's controller states at time t ∈ [0, h] of a period that began with ζ = `z0` and ended
    /// with ζ⁺ = `z1`: each chain's highest derivative u_e is held over the period, so it is
    /// (ζ⁺_{o−1} − ζ_{o−1})/h, and ζ_l(t) = Σ_{k ≥ l} ζ_k t^{k−l}/(k−l)! + u_e t^{o−l}/(o−l)!
    /// (`model::flat`, the law).
    pub fn zeta_within(&self, z0: &[f64], z1: &[f64], h: f64, t: f64) -> Vec<f64> {
        let mut out = Vec::with_capacity(z0.len());
        let mut at = 0;
        for &o in &self.ext_orders {
            let (c0, c1) = (&z0[at..at + o], &z1[at..at + o]);
            let ue = (c1[o - 1] - c0[o - 1]) / h;
            for l in 0..o {
                let mut v = 0.0;
                let mut term = 1.0; // t^{k−l}/(k−l)!
                for (i, zk) in c0[l..].iter().enumerate() {
                    if i > 0 {
                        term *= t / i as f64;
                    }
                    v += zk * term;
                }
                v += ue * term * t / (o - l) as f64;
                out.push(v);
            }
            at += o;
        }
        out
    }
}

impl FlMaps {
    /// ξ of a plant state (a flat plant's controller states at their initial values).
    pub fn xi_of(&self, x: &[f64]) -> Vec<f64> {
        match &self.flat {
            Some(fc) => self.xi_at(x, &fc.ext_init),
            None => self.xi_states.iter().map(|&s| x[s]).collect(),
        }
    }

    /// ξ of a plant state with the controller states `ext` (ignored when the plant has none).
    pub fn xi_at(&self, x: &[f64], ext: &[f64]) -> Vec<f64> {
        match &self.flat {
            Some(fc) => {
                let xe: Vec<f64> = x.iter().chain(ext).copied().collect();
                let at = Point {
                    x: &xe,
                    u: &[],
                    p: &[],
                };
                let mut q = vec![0.0; fc.coords_tape.len()];
                fc.coords_tape.eval_into(&at, &mut q);
                q
            }
            None => self.xi_states.iter().map(|&s| x[s]).collect(),
        }
    }

    /// The dimension of ξ.
    pub fn n_xi(&self) -> usize {
        match &self.flat {
            Some(fc) => fc.coords_tape.len(),
            None => self.xi_states.len(),
        }
    }

    /// The pairs (j, s) with ξ_j the plant's state s.
    pub fn state_coords(&self) -> Vec<(usize, usize)> {
        match &self.flat {
            Some(fc) => fc
                .q_states
                .iter()
                .enumerate()
                .filter_map(|(j, s)| s.map(|s| (j, s)))
                .collect(),
            None => self.xi_states.iter().copied().enumerate().collect(),
        }
    }
}

/// A feedback-linearizable plant as the pipeline sees it: the linear model in ξ (sampled exactly by the
/// zero-order hold, which is what the nominal and the CAF use) and the maps with their bounds.
#[derive(Clone, Debug)]
pub struct FeedbackLinearized {
    pub linear: LinearAffine,
    pub maps: Arc<FlMaps>,
}

impl Plant for FeedbackLinearized {
    fn n(&self) -> usize {
        self.linear.n()
    }
    fn m(&self) -> usize {
        self.linear.m()
    }
    fn period(&self) -> f64 {
        Plant::period(&self.linear)
    }
    fn error_dynamics(&self, loc: Location) -> &DiscretePlant {
        self.linear.error_dynamics(loc)
    }
    fn continuous(&self, loc: Location) -> Option<&ContinuousPlant> {
        self.linear.continuous(loc)
    }
    fn step(&self, loc: Location, x: &[f64], u: &[f64]) -> Vec<f64> {
        self.linear.step(loc, x, u)
    }
    fn step_into(&self, loc: Location, x: &[f64], u: &[f64], out: &mut [f64]) {
        self.linear.step_into(loc, x, u, out)
    }
    fn between_samples(&self, loc: Location, x: &[f64], u: &[f64], visit: &mut dyn FnMut(&[f64])) {
        self.linear.between_samples(loc, x, u, visit)
    }
    fn excursion(&self, loc: Location, x: &[f64], u: &[f64]) -> Option<f64> {
        self.linear.excursion(loc, x, u)
    }
    fn model_mismatch(&self) -> f64 {
        self.maps.mismatch
    }
    fn linearization(&self) -> Option<&FlMaps> {
        Some(&self.maps)
    }
}

pub(super) fn state_name(problem_names: &crate::expr::Names, s: usize) -> String {
    problem_names
        .states
        .get(s)
        .cloned()
        .unwrap_or_else(|| format!("x{}", s + 1))
}

/// Whether `e` uses a state outside `allowed`; the first such state.
fn uses_other_state(e: &Expr, n: usize, allowed: &[usize]) -> Option<usize> {
    (0..n).find(|&s| !allowed.contains(&s) && e.uses(Var::State(s as u16)))
}

/// The symbolic adjugate and determinant of a square matrix of expressions (m ≤ 3): Γ⁻¹ = adj(Γ)/det.
pub(super) fn adjugate(g: &[Vec<Expr>]) -> Result<(Vec<Vec<Expr>>, Expr), FlError> {
    let m = g.len();
    let e = |i: usize, j: usize| g[i][j].clone();
    let det2 = |a: Expr, b: Expr, c: Expr, d: Expr| Expr::sub(Expr::mul(a, d), Expr::mul(b, c));
    match m {
        1 => Ok((vec![vec![Expr::c(1.0)]], e(0, 0))),
        2 => Ok((
            vec![
                vec![e(1, 1), Expr::neg(e(0, 1))],
                vec![Expr::neg(e(1, 0)), e(0, 0)],
            ],
            det2(e(0, 0), e(0, 1), e(1, 0), e(1, 1)),
        )),
        3 => {
            // cof(i, j) = (−1)^{i+j} det of the minor without row i and column j.
            let cof = |i: usize, j: usize| {
                let r: Vec<usize> = (0..3).filter(|&k| k != i).collect();
                let c: Vec<usize> = (0..3).filter(|&k| k != j).collect();
                let d = det2(e(r[0], c[0]), e(r[0], c[1]), e(r[1], c[0]), e(r[1], c[1]));
                if (i + j) % 2 == 0 {
                    d
                } else {
                    Expr::neg(d)
                }
            };
            let det = (0..3).fold(Expr::c(0.0), |acc, j| {
                Expr::add(acc, Expr::mul(e(0, j), cof(0, j)))
            });
            // adj(Γ)_ij = cof(j, i).
            Ok((
                (0..3)
                    .map(|i| (0..3).map(|j| cof(j, i)).collect())
                    .collect(),
                det,
            ))
        }
        _ => Err(FlError::TooManyInputs { m }),
    }
}

/// The law u = Γ⁻¹(w − α) with Γ⁻¹ = adj/det, one division per input: u_i = (Σ_j adj_ij (w_j − α_j)) / det,
/// w the expressions' inputs.
pub(super) fn cancelling_law(adj: &[Vec<Expr>], det: &Expr, alpha: &[Expr]) -> Vec<Expr> {
    let w = |j: usize| Expr::var(Var::Input(j as u16));
    adj.iter()
        .map(|row| {
            let num = row
                .iter()
                .zip(alpha)
                .enumerate()
                .fold(Expr::c(0.0), |acc, (j, (a, al))| {
                    Expr::add(acc, Expr::mul(a.clone(), Expr::sub(w(j), al.clone())))
                });
            Expr::div(num, det.clone())
        })
        .collect()
}

/// The radius R_u over which the mismatch's quadratic in u is bounded (step 3 of the module doc): the
/// inputs a certified run applies are u = λ(x)(w − α_res(x)) with w in W, up to the input program's
/// rounding, so ‖u‖₂ ≤ L(sup_W ‖w‖₂ + A) + e_prog, with L ≥ ‖λ‖₂, A ≥ ‖α_res‖₂. W is built to map into
/// U, so for a ball U about 0 this is U's radius again; for a box U it is the box's radius only when W's
/// image fills the box's corners, and a box whose half-widths differ (a speed and a turn rate) leaves
/// most of it unused. Each radius is sound (the other is sup over all of U), so the smaller is taken,
/// when it is smaller by more than a relative 10⁻⁶ (else U's, so that nothing moves for a rounding's
/// difference).
fn applied_input_radius(
    w: &InputSet,
    lambda_norm: f64,
    alpha_res_norm: f64,
    e_prog: f64,
    r_u: f64,
) -> f64 {
    let applied = (lambda_norm * (sup_norm(w) + alpha_res_norm) + e_prog) * (1.0 + 1e-12);
    if applied.is_finite() && applied < r_u * (1.0 - 1e-6) {
        applied
    } else {
        r_u
    }
}

/// sup ‖u‖₂ over an input set: a box's farthest corner from 0, a ball's centre norm plus its radius.
fn sup_norm(u: &InputSet) -> f64 {
    match u {
        InputSet::Box { lo, hi } => lo
            .iter()
            .zip(hi)
            .map(|(l, h)| l.abs().max(h.abs()).powi(2))
            .sum::<f64>()
            .sqrt(),
        InputSet::Ball { center, radius } => {
            center.iter().map(|c| c * c).sum::<f64>().sqrt() + radius
        }
    }
}

/// The interval [0, h]·a.
pub(super) fn times_period(a: Interval, h: f64) -> Interval {
    a.mul(Interval::new(0.0, h))
}

/// How the input set bounds u: the interval box, and for a ball its centre and radius.
struct UBound {
    boxed: Vec<Interval>,
    ball: Option<(Vec<f64>, f64)>,
    /// sup ‖u‖₂ over the set.
    r_u: f64,
}

impl UBound {
    fn new(u: &InputSet) -> Self {
        match u {
            InputSet::Box { lo, hi } => Self {
                boxed: lo
                    .iter()
                    .zip(hi)
                    .map(|(&l, &h)| Interval::new(l, h))
                    .collect(),
                ball: None,
                r_u: sup_norm(u),
            },
            InputSet::Ball { center, radius } => Self {
                boxed: center
                    .iter()
                    .map(|&c| Interval::new(c - radius, c + radius))
                    .collect(),
                ball: Some((center.clone(), *radius)),
                r_u: sup_norm(u),
            },
        }
    }

    /// An enclosure of f + Σ_l g_l u_l over the state box, u in the set: for a ball, the g-part is
    /// bounded by ‖(|g_l|)_l‖₂·ρ around g·c (tighter than the ball's bounding box).
    fn field(&self, f: &Expr, g: &[Expr], b: &VarBox<'_>) -> Result<Interval, IntervalError> {
        let fi = enclose(f, b)?;
        match &self.ball {
            None => {
                let mut s = fi;
                for (gl, ul) in g.iter().zip(&self.boxed) {
                    if !gl.is_zero() {
                        s = s.add(enclose(gl, b)?.mul(*ul));
                    }
                }
                Ok(s)
            }
            Some((c, rho)) => {
                let mut s = fi;
                let mut mag2 = 0.0;
                for (gl, cl) in g.iter().zip(c) {
                    if !gl.is_zero() {
                        let gi = enclose(gl, b)?;
                        s = s.add(gi.mul(Interval::point(*cl)));
                        mag2 += gi.mag() * gi.mag();
                    }
                }
                Ok(s.widen(mag2.sqrt() * rho * (1.0 + 1e-12)))
            }
        }
    }
}

/// The supremum of `f` over a grid of sub-boxes of the state box `base` (the state coordinates in
/// `dims` split evenly, at most [`MAX_PIECES`] boxes in all). `base` holds, per state, the interval the
/// bounds are taken over: the zero-dynamics hull, and the operating region's range of a ξ state (a point
/// where there is no region: then no bounded expression uses a ξ state).
pub(super) fn sup_over_grid(
    base: &[Interval],
    dims: &[usize],
    f: &dyn Fn(&[Interval]) -> Result<f64, IntervalError>,
) -> Result<f64, IntervalError> {
    let d = dims.len();
    let per = if d == 0 {
        1
    } else {
        ((MAX_PIECES as f64).powf(1.0 / d as f64).floor() as usize).max(1)
    };
    let total = per.pow(d as u32);
    let mut best = f64::NEG_INFINITY;
    let mut x = base.to_vec();
    for idx in 0..total {
        let mut rest = idx;
        for &s in dims {
            let k = rest % per;
            rest /= per;
            let iv = base[s];
            let w = (iv.hi - iv.lo) / per as f64;
            let lo = if k == 0 { iv.lo } else { iv.lo + w * k as f64 };
            let hi = if k + 1 == per {
                iv.hi
            } else {
                iv.lo + w * (k + 1) as f64
            };
            // Outward by a hair so that the pieces' union covers the box despite rounding.
            x[s] = Interval::new(lo, hi).widen(1e-15 * (1.0 + iv.mag()));
        }
        best = best.max(f(&x)?);
    }
    Ok(best)
}

/// The states the expressions use whose range in `base` is not a point (the coordinates worth splitting).
pub(super) fn dims_used(es: &[&Expr], base: &[Interval]) -> Vec<usize> {
    (0..base.len())
        .filter(|&s| base[s].hi > base[s].lo && es.iter().any(|e| e.uses(Var::State(s as u16))))
        .collect()
}

/// Upper bound of ‖M‖₂ for an interval matrix given as expressions: sqrt of the largest absolute row
/// sum of the enclosure of MᵀM (built symbolically, so that the entries of a rotation collapse).
pub(super) fn norm2_bound(mtm: &[Vec<Expr>], b: &VarBox<'_>) -> Result<f64, IntervalError> {
    let mut worst = 0.0f64;
    for row in mtm {
        let mut s = 0.0;
        for e in row {
            s += enclose(e, b)?.mag();
        }
        worst = worst.max(s);
    }
    Ok(worst.sqrt())
}

/// MᵀM symbolically.
pub(super) fn gram(m: &[Vec<Expr>]) -> Vec<Vec<Expr>> {
    let cols = m.first().map_or(0, |r| r.len());
    (0..cols)
        .map(|a| {
            (0..cols)
                .map(|b| {
                    m.iter().fold(Expr::c(0.0), |acc, row| {
                        Expr::add(acc, Expr::mul(row[a].clone(), row[b].clone()))
                    })
                })
                .collect()
        })
        .collect()
}

pub(super) fn bound_err(what: &str) -> impl Fn(IntervalError) -> FlError + '_ {
    move |e| FlError::Bound {
        what: what.to_string(),
        why: e.to_string(),
    }
}

/// The two closed half-spaces {ξ_j ≤ lo} and {ξ_j ≥ hi} (one-row polytopes on coordinate j): leaving
/// an operating region's interval on that coordinate.
pub(super) fn outside_interval(j: usize, lo: f64, hi: f64) -> [SetDesc; 2] {
    [(1.0, lo), (-1.0, -hi)].map(|(a, b)| SetDesc {
        shape: Shape::Polytope {
            A: Matrix {
                rows: 1,
                cols: 1,
                data: vec![a],
            },
            b: vec![b],
        },
        coords: Coords::StateIndices(vec![j]),
    })
}

/// The linearised task of a validated feedback-linearizable spec: the spec in ξ coordinates (its plant
/// the linear model, Init, Goal and Unsafe on the ξ states, its input set W) and the maps with their
/// bounds (module doc).
pub fn linearize(problem: &Problem) -> Result<(Problem, FlMaps), FlError> {
    let desc = problem
        .nonlinear
        .as_ref()
        .expect("linearize is called on a nonlinear problem");
    let names = &desc.names;
    let p = names.param_values();
    let sys = &desc.system;
    let (n, m) = (sys.n(), sys.m());
    // The spec loader's Lie derivatives and Γ (uniform over Init).
    let rd = &desc.derivatives;
    // 1. ξ: every L_f^k h_i (k < r_i) must be a state.
    let mut xi_states = Vec::new();
    for (i, tower) in rd.lf.iter().enumerate() {
        for (k, e) in tower.iter().take(rd.r[i]).enumerate() {
            let e = e.bind_params(&p);
            match e {
                Expr::Var(Var::State(s)) if !xi_states.contains(&(s as usize)) => {
                    xi_states.push(s as usize)
                }
                _ => {
                    return Err(FlError::CoordinateNotAState {
                        index: xi_states.len(),
                        output: i + 1,
                        k,
                        expr: e.display(names).to_string(),
                    })
                }
            }
        }
    }
    let zero_states: Vec<usize> = (0..n).filter(|s| !xi_states.contains(s)).collect();
    let n_xi = xi_states.len();
    // 2. α, Γ, the kept affine part and α_res.
    let alpha: Vec<Expr> = rd
        .lf
        .iter()
        .zip(&rd.r)
        .map(|(t, &r)| t[r].bind_params(&p))
        .collect();
    let gamma: Vec<Vec<Expr>> = rd
        .gamma
        .iter()
        .map(|row| row.iter().map(|e| e.bind_params(&p)).collect())
        .collect();
    let zero_x = vec![0.0; n];
    let mut kept_a = vec![vec![0.0; n_xi]; m];
    let mut kept_c = vec![0.0; m];
    let mut alpha_res = Vec::with_capacity(m);
    for (i, a) in alpha.iter().enumerate() {
        let grad = gradient(a, n)?;
        let affine_in_xi = grad.iter().enumerate().all(|(s, d)| match d.as_const() {
            Some(v) => v == 0.0 || xi_states.contains(&s),
            None => false,
        });
        if affine_in_xi {
            for (j, &s) in xi_states.iter().enumerate() {
                kept_a[i][j] = grad[s].as_const().unwrap_or(0.0);
            }
            kept_c[i] = a.eval(&Point {
                x: &zero_x,
                u: &[],
                p: &[],
            });
            alpha_res.push(Expr::c(0.0));
        } else {
            alpha_res.push(a.clone());
        }
    }
    // 3. Without an operating region, what the bounds need must depend on the zero dynamics only; with
    // one, the ξ states range over the region (module doc).
    let region = desc.region.clone();
    let allowed: Vec<usize> = if region.is_some() {
        (0..n).collect()
    } else {
        zero_states.clone()
    };
    let check_zero = |what: String, e: &Expr| -> Result<(), FlError> {
        match uses_other_state(e, n, &allowed) {
            Some(s) => Err(FlError::DependsOnXi {
                what,
                state: state_name(names, s),
            }),
            None => Ok(()),
        }
    };
    for (i, a) in alpha_res.iter().enumerate() {
        check_zero(
            format!("α_{} (the part of L_f^r h the law cancels)", i + 1),
            a,
        )?;
    }
    for (i, row) in gamma.iter().enumerate() {
        for (j, e) in row.iter().enumerate() {
            check_zero(format!("Γ[{}][{}]", i + 1, j + 1), e)?;
        }
    }
    let f: Vec<Expr> = sys.f.iter().map(|e| e.bind_params(&p)).collect();
    let g: Vec<Vec<Expr>> = sys
        .g
        .iter()
        .map(|r| r.iter().map(|e| e.bind_params(&p)).collect())
        .collect();
    for &z in &zero_states {
        let nm = state_name(names, z);
        check_zero(format!("f for {nm} (zero dynamics)"), &f[z])?;
        for (j, e) in g[z].iter().enumerate() {
            check_zero(format!("g[{nm}][{}] (zero dynamics)", j + 1), e)?;
        }
    }
    // 4. λ = Γ⁻¹ = adj(Γ)/det and the two programs; u_i = (Σ_j adj_ij (w_j − α_res,j)) / det, one
    // division per input.
    let (adj, det) = adjugate(&gamma)?;
    let lambda: Vec<Vec<Expr>> = adj
        .iter()
        .map(|row| {
            row.iter()
                .map(|a| Expr::div(a.clone(), det.clone()))
                .collect()
        })
        .collect();
    let input_exprs = cancelling_law(&adj, &det, &alpha_res);
    let coords_exprs: Vec<Expr> = xi_states
        .iter()
        .map(|&s| Expr::var(Var::State(s as u16)))
        .collect();
    let coords = compile(&coords_exprs, n, 0, &[])?;
    let input_map = compile(&input_exprs, n, m, &[])?;
    // 5. The linear model in ξ.
    let mut A = Matrix::zeros(n_xi, n_xi);
    let mut B = Matrix::zeros(n_xi, m);
    let mut C = Matrix::zeros(m, n_xi);
    let mut c = vec![0.0; n_xi];
    let mut o = 0;
    for (i, &r) in rd.r.iter().enumerate() {
        for k in 0..r - 1 {
            A.data[(o + k) * n_xi + o + k + 1] = 1.0;
        }
        let last = o + r - 1;
        for j in 0..n_xi {
            A.data[last * n_xi + j] = kept_a[i][j];
        }
        c[last] = kept_c[i];
        B.data[last * m + i] = 1.0;
        C.data[i * n_xi + o] = 1.0;
        o += r;
    }
    // 6. The zero dynamics over the horizon, Init's zero box onwards.
    let ub = UBound::new(&problem.input);
    let h = desc.period;
    let steps = problem.horizon_steps();
    let mut zk: Vec<Interval> = zero_states
        .iter()
        .map(|&s| Interval::new(problem.init.lo[s], problem.init.hi[s]))
        .collect();
    let mut hull = zk.clone();
    // The ξ states over the region (when there is one; else nothing bounded here uses them).
    let xi_range = |s: usize| match &region {
        Some(r) => Interval::new(r.lo[s], r.hi[s]),
        None => Interval::point(0.0),
    };
    let mut xbox: Vec<Interval> = (0..n).map(xi_range).collect();
    let field =
        |zb: &[Interval], xbox: &mut Vec<Interval>| -> Result<Vec<Interval>, IntervalError> {
            for (zi, &s) in zero_states.iter().enumerate() {
                xbox[s] = zb[zi];
            }
            let b = VarBox {
                x: xbox,
                u: &[],
                p: &[],
            };
            zero_states
                .iter()
                .map(|&s| ub.field(&f[s], &g[s], &b))
                .collect()
        };
    for k in 0..steps {
        let mut tilde: Vec<Interval> = zk.iter().map(|z| z.widen(1e-9 * (1.0 + z.mag()))).collect();
        let mut ok = false;
        for _ in 0..PICARD_ITERATIONS {
            let fz = field(&tilde, &mut xbox).map_err(|e| FlError::ZeroDynamicsUnbounded {
                k,
                why: e.to_string(),
            })?;
            let cand: Vec<Interval> = zk
                .iter()
                .zip(&fz)
                .map(|(z, fi)| z.add(times_period(*fi, h)))
                .collect();
            if cand
                .iter()
                .zip(&tilde)
                .all(|(c, t)| t.lo <= c.lo && c.hi <= t.hi)
            {
                ok = true;
                zk = cand;
                break;
            }
            tilde = cand
                .iter()
                .zip(&tilde)
                .map(|(c, t)| {
                    let u = c.hull(*t);
                    u.widen(0.1 * (u.hi - u.lo) + 1e-12)
                })
                .collect();
        }
        if !ok {
            return Err(FlError::ZeroDynamicsUnbounded {
                k,
                why: "no a-priori enclosure within the Picard iterations".into(),
            });
        }
        // Z_k + [0, h]·F(Z̃) encloses the whole period (it lies in Z̃, which encloses the flow).
        for (hz, z) in hull.iter_mut().zip(&zk) {
            *hz = hz.hull(*z);
        }
    }
    // The hull must lie in the region's zero-dynamics part (the region is where the runs stay).
    if let Some(r) = &region {
        for (zi, &s) in zero_states.iter().enumerate() {
            let z = hull[zi];
            if z.lo < r.lo[s] || z.hi > r.hi[s] {
                return Err(FlError::ZeroDynamicsLeaveRegion {
                    state: state_name(names, s),
                    hull_lo: z.lo,
                    hull_hi: z.hi,
                    lo: r.lo[s],
                    hi: r.hi[s],
                });
            }
        }
    }
    // 7. The bounds over the box of the ξ states' region and the zero-dynamics hull.
    let mut base: Vec<Interval> = (0..n).map(xi_range).collect();
    for (zi, &s) in zero_states.iter().enumerate() {
        base[s] = hull[zi];
    }
    let us: Vec<Interval> = vec![Interval::point(0.0); m];
    let lam_gram = gram(&lambda);
    let lam_refs: Vec<&Expr> = lambda.iter().flatten().collect();
    let lambda_norm = sup_over_grid(&base, &dims_used(&lam_refs, &base), &|x| {
        norm2_bound(&lam_gram, &VarBox { x, u: &us, p: &[] })
    })
    .map_err(bound_err("‖λ‖₂"))?;
    let ar_refs: Vec<&Expr> = alpha_res.iter().collect();
    let alpha_res_norm = sup_over_grid(&base, &dims_used(&ar_refs, &base), &|x| {
        let b = VarBox { x, u: &us, p: &[] };
        let mut s = 0.0;
        for a in &alpha_res {
            s += enclose(a, &b)?.mag().powi(2);
        }
        Ok(s.sqrt())
    })
    .map_err(bound_err("‖α_res‖₂"))?;
    let g_gram = gram(&gamma);
    let g_refs: Vec<&Expr> = gamma.iter().flatten().collect();
    let gamma_norm = sup_over_grid(&base, &dims_used(&g_refs, &base), &|x| {
        norm2_bound(&g_gram, &VarBox { x, u: &us, p: &[] })
    })
    .map_err(bound_err("‖Γ‖₂"))?;
    // W before the rounding shrink, then the program's rounding over that W (monotone in |w|).
    let w_set = |e_prog: f64| -> Result<InputSet, FlError> {
        let empty = |why: String| FlError::EmptyInputSet {
            why,
            lambda: lambda_norm,
            alpha: alpha_res_norm,
            e_prog,
        };
        match &problem.input {
            InputSet::Ball { center, radius } => {
                let cn = center.iter().map(|v| v * v).sum::<f64>().sqrt();
                let r = (radius - cn - e_prog) / lambda_norm - alpha_res_norm;
                if !(r > 0.0) {
                    return Err(empty(format!("‖w‖ ≤ {r:.4e}")));
                }
                Ok(InputSet::Ball {
                    center: vec![0.0; m],
                    radius: r * (1.0 - 1e-12),
                })
            }
            InputSet::Box { lo, hi } => {
                // |u_i| ≤ Σ_j |λ_ij|(|w_j| + |α_j|) + e ≤ L(ω√m + A) + e in every component.
                let half = lo
                    .iter()
                    .zip(hi)
                    .map(|(l, h)| (-l).min(*h))
                    .fold(f64::INFINITY, f64::min);
                let om = ((half - e_prog) / lambda_norm - alpha_res_norm) / (m as f64).sqrt();
                if !(om > 0.0) {
                    return Err(empty(format!(
                        "the input box does not contain a neighbourhood of 0 large enough (ω = {om:.4e})"
                    )));
                }
                let om = om * (1.0 - 1e-12);
                Ok(InputSet::Box {
                    lo: vec![-om; m],
                    hi: vec![om; m],
                })
            }
        }
    };
    let w0 = w_set(0.0)?;
    let w_box: Vec<Interval> = match &w0 {
        InputSet::Ball { radius, .. } => vec![Interval::new(-radius, *radius); m],
        InputSet::Box { lo, hi } => lo
            .iter()
            .zip(hi)
            .map(|(&l, &h)| Interval::new(l, h))
            .collect(),
    };
    let in_refs: Vec<&Expr> = input_exprs.iter().collect();
    let e_prog = sup_over_grid(&base, &dims_used(&in_refs, &base), &|x| {
        let bounds = rounding_bound(&input_map, x, &w_box)?;
        Ok(bounds.iter().map(|b| b.error * b.error).sum::<f64>().sqrt())
    })
    .map_err(bound_err("the input program's rounding"))?;
    let w_final = w_set(e_prog)?;
    // 8. The mismatch D: E = L_{f+g u} φ, φ = α_res + Γ u, a quadratic in u.
    let field_u: Vec<Expr> = (0..n)
        .map(|s| {
            (0..m).fold(f[s].clone(), |acc, l| {
                Expr::add(
                    acc,
                    Expr::mul(g[s][l].clone(), Expr::var(Var::Input(l as u16))),
                )
            })
        })
        .collect();
    let mut e0 = Vec::with_capacity(m);
    let mut mlin = Vec::with_capacity(m);
    let mut quad = Vec::with_capacity(m);
    let zero_u = |e: &Expr| e.map_vars(&|v| matches!(v, Var::Input(_)).then(|| Expr::c(0.0)));
    for i in 0..m {
        let phi = (0..m).fold(alpha_res[i].clone(), |acc, l| {
            Expr::add(
                acc,
                Expr::mul(gamma[i][l].clone(), Expr::var(Var::Input(l as u16))),
            )
        });
        let e = lie(&phi, &field_u)?;
        e0.push(zero_u(&e));
        let mut row = Vec::with_capacity(m);
        let mut qrow = Vec::with_capacity(m * m);
        for l in 0..m {
            let dl = derivative(&e, Var::Input(l as u16))?;
            row.push(zero_u(&dl));
            for k in 0..m {
                qrow.push(derivative(&dl, Var::Input(k as u16))?);
            }
        }
        mlin.push(row);
        quad.push(qrow);
    }
    let m_gram = gram(&mlin);
    let mut e_refs: Vec<&Expr> = e0.iter().collect();
    e_refs.extend(mlin.iter().flatten());
    e_refs.extend(quad.iter().flatten());
    let r_u = applied_input_radius(&w_final, lambda_norm, alpha_res_norm, e_prog, ub.r_u);
    let sup_e = sup_over_grid(&base, &dims_used(&e_refs, &base), &|x| {
        let b = VarBox { x, u: &us, p: &[] };
        let mut n0 = 0.0;
        for e in &e0 {
            n0 += enclose(e, &b)?.mag().powi(2);
        }
        let mut nq = 0.0;
        for q in quad.iter().flatten() {
            nq += enclose(q, &b)?.mag().powi(2);
        }
        Ok(n0.sqrt() + norm2_bound(&m_gram, &b)? * r_u + 0.5 * nq.sqrt() * r_u * r_u)
    })
    .map_err(bound_err("the sampled-loop mismatch"))?;
    let mismatch_flow = h * sup_e;
    let mismatch = (mismatch_flow + gamma_norm * e_prog) * (1.0 + 1e-9);
    // 9. The problem in ξ.
    let remap = |what: &str, s: &SetDesc| -> Result<SetDesc, FlError> {
        let mut s = s.clone();
        s.coords = match &s.coords {
            Coords::State => {
                if let Some(&z) = zero_states.first() {
                    return Err(FlError::SetOnZeroDynamics {
                        what: what.to_string(),
                        state: state_name(names, z),
                    });
                }
                Coords::StateIndices(xi_states.clone())
            }
            Coords::StateIndices(idx) => Coords::StateIndices(
                idx.iter()
                    .map(|&i| {
                        xi_states.iter().position(|&s| s == i).ok_or_else(|| {
                            FlError::SetOnZeroDynamics {
                                what: what.to_string(),
                                state: state_name(names, i),
                            }
                        })
                    })
                    .collect::<Result<_, _>>()?,
            ),
            Coords::Output { C: cx } => {
                let mut cm = Matrix::zeros(cx.rows, n_xi);
                for r in 0..cx.rows {
                    for s in 0..n {
                        let v = cx.data[r * cx.cols + s];
                        match xi_states.iter().position(|&q| q == s) {
                            Some(j) => cm.data[r * n_xi + j] = v,
                            None if v != 0.0 => {
                                return Err(FlError::SetOnZeroDynamics {
                                    what: what.to_string(),
                                    state: state_name(names, s),
                                })
                            }
                            None => {}
                        }
                    }
                }
                Coords::Output { C: cm }
            }
        };
        Ok(s)
    };
    let mut xi = problem.clone();
    xi.plant = SpecPlant {
        time: TimeDomain::Continuous,
        A,
        B,
        offset: c,
        period: h,
        C,
    };
    xi.init = InitBox {
        lo: xi_states.iter().map(|&s| problem.init.lo[s]).collect(),
        hi: xi_states.iter().map(|&s| problem.init.hi[s]).collect(),
    };
    xi.goal = remap("Goal", &problem.goal)?;
    xi.unsafe_sets = problem
        .unsafe_sets
        .iter()
        .map(|s| remap("Unsafe", s))
        .collect::<Result<_, _>>()?;
    // Leaving the operating region is entering Unsafe: per ξ state s with region [lo, hi], the closed
    // half-spaces {ξ_j ≤ lo} and {ξ_j ≥ hi} (one-row polytopes on that coordinate).
    if let Some(r) = &region {
        for (j, &s) in xi_states.iter().enumerate() {
            xi.unsafe_sets.extend(outside_interval(j, r.lo[s], r.hi[s]));
        }
    }
    xi.sets = problem
        .sets
        .iter()
        .map(|(k, s)| Ok((k.clone(), remap(&format!("[sets.{k}]"), s)?)))
        .collect::<Result<_, FlError>>()?;
    xi.mtl = match &problem.mtl {
        None => None,
        Some(src) => Some(formula_in_xi(
            src,
            n,
            &xi_states,
            names,
            region.as_ref(),
            problem.horizon,
        )?),
    };
    xi.input = w_final;
    xi.nonlinear = None;
    let maps = FlMaps {
        n_plant: n,
        m_plant: m,
        xi_states,
        zero_states,
        coords,
        input_map,
        input_exprs,
        plant: NonlinearPlant::from_desc(desc),
        input: problem.input.clone(),
        init: problem.init.clone(),
        zero_hull: hull,
        region,
        lambda_norm,
        alpha_res_norm,
        gamma_norm,
        e_prog,
        mismatch,
        mismatch_flow,
        flat: None,
    };
    Ok((xi, maps))
}

/// The `[mtl]` formula of a plant-coordinate spec rewritten over ξ (module doc, *MTL tasks*): every
/// predicate's plant signal `x<s+1>` (state s) renamed `x<j+1>` (ξ_j = state s), a predicate that weighs a
/// zero-dynamics state refused; names that are not state signals are left as written (binding the task
/// reports them). With an operating region the formula becomes `(φ) & G[0,T] (ξ inside the region's ξ
/// box)`. The result is the fully parenthesised print of the rewritten tree (it parses back to it).
pub fn formula_in_xi(
    src: &str,
    n: usize,
    xi_states: &[usize],
    names: &crate::expr::Names,
    region: Option<&InitBox>,
    horizon: f64,
) -> Result<String, FlError> {
    use crate::robustness::mtl::{Expr as M, Interval as TI, LinearPredicate, Span};
    let parsed = crate::robustness::mtl::parse(src).map_err(|e| FlError::Formula(e.to_string()))?;
    let plant_signals = crate::property::state_signals(n);
    fn walk(
        e: &M,
        plant_signals: &[String],
        xi_states: &[usize],
        names: &crate::expr::Names,
    ) -> Result<M, FlError> {
        let go = |x: &M| walk(x, plant_signals, xi_states, names);
        Ok(match e {
            M::True | M::False | M::Set { .. } => e.clone(),
            M::Linear(p) => {
                let coord_of = |s: usize| xi_states.iter().position(|&q| q == s);
                let refuse = |predicate: String, state: String| FlError::PredicateOnZeroDynamics {
                    predicate,
                    state,
                };
                match predicate_in_coords(p, plant_signals, &coord_of, names, &refuse)? {
                    Renamed::Constant(true) => M::True,
                    Renamed::Constant(false) => M::False,
                    Renamed::Predicate(q, _) => M::Linear(q),
                }
            }
            M::Not(x) => M::Not(Box::new(go(x)?)),
            M::And(v) => M::And(v.iter().map(go).collect::<Result<_, _>>()?),
            M::Or(v) => M::Or(v.iter().map(go).collect::<Result<_, _>>()?),
            M::Implies(l, r) => M::Implies(Box::new(go(l)?), Box::new(go(r)?)),
            M::Eventually(i, x) => M::Eventually(*i, Box::new(go(x)?)),
            M::Always(i, x) => M::Always(*i, Box::new(go(x)?)),
            M::Until(i, l, r) => M::Until(*i, Box::new(go(l)?), Box::new(go(r)?)),
            M::Release(i, l, r) => M::Release(*i, Box::new(go(l)?), Box::new(go(r)?)),
        })
    }
    let mut out = walk(&parsed, &plant_signals, xi_states, names)?;
    if let Some(r) = region {
        // G[0,T] (lo_s ≤ ξ_j ≤ hi_s for every ξ state): its robustness is the depth in the region's ξ box,
        // so a certified run's tube stays strictly inside (the first-exit argument of the module doc).
        let span = Span::new(0, 0);
        let mut keep = Vec::with_capacity(2 * xi_states.len());
        for (j, &s) in xi_states.iter().enumerate() {
            let name = format!("x{}", j + 1);
            for (a, b) in [(1.0, r.hi[s]), (-1.0, -r.lo[s])] {
                keep.push(M::Linear(LinearPredicate {
                    terms: vec![(name.clone(), a, span)],
                    b,
                    span,
                }));
            }
        }
        let within = match keep.len() {
            0 => M::True,
            1 => keep.pop().expect("one"),
            _ => M::And(keep),
        };
        let t = TI::new(0.0, horizon).ok_or_else(|| {
            FlError::Formula(format!("the horizon {horizon} is not a time bound"))
        })?;
        out = M::And(vec![out, M::Always(t, Box::new(within))]);
    }
    Ok(out.to_string())
}

/// A formula predicate over the plant's state signals, renamed to the linear coordinates.
pub(super) enum Renamed {
    /// No term weighs a state: `0 ≤ b`, true or false.
    Constant(bool),
    /// The predicate over `x<j+1>`, with each term's coordinate j.
    Predicate(crate::robustness::mtl::LinearPredicate, Vec<usize>),
}

/// `p` with every term's plant signal `x<s+1>` (state s) renamed `x<j+1>` for the coordinate
/// j = `coord_of(s)`; a term with a nonzero coefficient on a state without one is refused by
/// `refuse(predicate, state)`, a zero one dropped; names that are not state signals are kept as written
/// (binding the task reports them).
pub(super) fn predicate_in_coords(
    p: &crate::robustness::mtl::LinearPredicate,
    plant_signals: &[String],
    coord_of: &dyn Fn(usize) -> Option<usize>,
    names: &crate::expr::Names,
    refuse: &dyn Fn(String, String) -> FlError,
) -> Result<Renamed, FlError> {
    let mut q = p.clone();
    let mut coords = Vec::with_capacity(q.terms.len());
    for (name, c, _) in q.terms.iter_mut() {
        let Some(s) = plant_signals.iter().position(|v| v == name) else {
            continue;
        };
        match coord_of(s) {
            Some(j) => {
                *name = format!("x{}", j + 1);
                coords.push(j);
            }
            None if *c != 0.0 => {
                return Err(refuse(
                    p.to_string(),
                    format!("{name} ({})", state_name(names, s)),
                ))
            }
            // A zero coefficient weighs nothing: the term is dropped below.
            None => name.clear(),
        }
    }
    q.terms.retain(|(name, _, _)| !name.is_empty());
    Ok(if q.terms.is_empty() {
        Renamed::Constant(0.0 <= p.b)
    } else {
        Renamed::Predicate(q, coords)
    })
}

/// The task's plant of a linearised spec.
pub fn plant(xi: &Problem, maps: FlMaps) -> Result<FeedbackLinearized, ModelError> {
    Ok(FeedbackLinearized {
        linear: LinearAffine::from_spec(&xi.plant)?,
        maps: Arc::new(maps),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ζ's model within a period: the thrust chain (T, Ṫ) under a held T̈ = 2 is T(t) = T0 + Ṫ0 t + t²,
    /// Ṫ(t) = Ṫ0 + 2t, recovered from ζ at the period's two ends.
    #[test]
    fn the_controller_states_between_samples_follow_their_chain() {
        let fc = FlatCoords {
            coords_tape: Tape::new(&[]),
            ext_init: vec![9.81, 0.0],
            ext_orders: vec![2],
            q_states: vec![],
            region: InitBox {
                lo: vec![],
                hi: vec![],
            },
            state_rate: vec![],
            jump: vec![],
            held: vec![],
        };
        let (h, z0) = (0.01, [9.81, 0.5]);
        let at = |t: f64| [z0[0] + z0[1] * t + t * t, z0[1] + 2.0 * t];
        for t in [0.0, 0.003, 0.005, 0.01] {
            let got = fc.zeta_within(&z0, &at(h), h, t);
            for (g, w) in got.iter().zip(at(t)) {
                assert!(
                    (g - w).abs() < 1e-12,
                    "t = {t}: {got:?} against {:?}",
                    at(t)
                );
            }
        }
    }

    fn ex49() -> Problem {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/fl-4-9.toml");
        crate::spec::load(path).expect("the shipped example")
    }

    /// Example 4.9: ξ = (X, Ẋ, Y, Ẏ) with the drift kept (κ = 0, (3.32)–(3.33)), θ and θ̇ the zero
    /// dynamics, λ a rotation, so W is U up to the enclosures' slack; the programs reproduce u = R(θ)w.
    #[test]
    fn example_4_9_linearises_as_the_text_says() {
        let p = ex49();
        let (xi, maps) = linearize(&p).expect("linearises");
        assert_eq!(maps.xi_states, vec![0, 1, 2, 3]);
        assert_eq!(maps.zero_states, vec![4, 5]);
        let a = &xi.plant.A;
        // Rows of ẋ2 and ẋ4: 1 − X + 0.1 Ẋ kept.
        assert_eq!(&a.data[4..8], &[-1.0, 0.1, 0.0, 0.0]);
        assert_eq!(&a.data[12..16], &[0.0, 0.0, -1.0, 0.1]);
        assert_eq!(xi.plant.offset, vec![0.0, 1.0, 0.0, 1.0]);
        assert_eq!(maps.alpha_res_norm, 0.0);
        assert!(
            maps.lambda_norm >= 1.0 && maps.lambda_norm < 1.02,
            "{}",
            maps.lambda_norm
        );
        let InputSet::Ball { radius, .. } = xi.input else {
            panic!("a ball")
        };
        assert!(radius < 2.0 && radius > 1.95, "{radius}");
        // θ̇ grows by at most ‖(a/I, −b/I)‖·2 per second from 0.
        let k = (0.1f64 * 0.1 + 0.1 * 0.1).sqrt() * 2.0 * p.horizon;
        let thd = maps.zero_hull[1];
        assert!(thd.hi >= k * 0.999 && thd.hi < k * 1.05, "{thd:?} vs {k}");
        assert!(maps.mismatch > 0.0 && maps.mismatch.is_finite());
        eprintln!(
            "L {} A {} G {} e_prog {:e} D {} Dflow {} hull {:?} W {:?}",
            maps.lambda_norm,
            maps.alpha_res_norm,
            maps.gamma_norm,
            maps.e_prog,
            maps.mismatch,
            maps.mismatch_flow,
            maps.zero_hull,
            xi.input
        );
        // u = R(θ) w through the program, against the expression in f64.
        let x = [0.05, 0.0, -0.03, 1.0, 0.7, 0.2];
        let w = [0.3, -1.1];
        let u = maps.input_map.eval_f32(&x, &w);
        let (s, c) = (0.7f64.sin(), 0.7f64.cos());
        let exact = [-s * w[0] + c * w[1], c * w[0] + s * w[1]];
        for (a, b) in u.iter().zip(exact) {
            assert!((*a as f64 - b).abs() <= maps.e_prog, "{a} vs {b}");
        }
        assert_eq!(maps.coords.eval_f32(&x, &[]), vec![0.05, 0.0, -0.03, 1.0]);
    }

    /// The SCOTS vehicle (relative degree (1, 1), ξ = (x, y), Γ = R(θ)·diag(1, ½), an input box of
    /// unequal half-widths): D bounds how far ξ̇ moves within a period under the inputs the law applies
    /// (u from the input program at w in W), seen on the plant's own flow, and is taken over those inputs
    /// rather than over the whole box (W's image leaves most of the box's turn rate unused).
    #[test]
    fn the_vehicle_s_mismatch_bounds_its_flow_under_the_applied_inputs() {
        use rand::{Rng, SeedableRng};
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/maze-scots-vehicle.toml"
        );
        let p = crate::spec::load(path).expect("the shipped example");
        let (xi, maps) = linearize(&p).expect("linearises");
        let InputSet::Box { hi: w_hi, .. } = &xi.input else {
            panic!("a box")
        };
        let h = maps.plant.period();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(48);
        let mut worst = 0.0f64;
        for _ in 0..2000 {
            let th = rng.random_range(-std::f64::consts::PI..std::f64::consts::PI);
            let x = [rng.random_range(0.0..10.0), rng.random_range(0.0..10.0), th];
            let w: Vec<f64> = w_hi.iter().map(|&r| rng.random_range(-r..=r)).collect();
            let u: Vec<f64> = maps
                .input_map
                .eval_f32(&x, &w)
                .iter()
                .map(|&v| v as f64)
                .collect();
            let f0 = maps.plant.field(&x, &u);
            let mut seen = |y: &[f64]| {
                let f = maps.plant.field(y, &u);
                worst = worst.max(((f[0] - f0[0]).powi(2) + (f[1] - f0[1]).powi(2)).sqrt());
            };
            let end = maps.plant.flow(&x, &u, h, 16, &mut seen).expect("flows");
            seen(&end);
        }
        assert!(worst <= maps.mismatch, "{worst} > D = {}", maps.mismatch);
        // Seen 0.046 against D = 0.296 (a bound by intervals over θ, quadratic in ‖u‖); over the whole
        // box D was 1.015, 22 times what was seen.
        assert!(
            worst > 0.1 * maps.mismatch,
            "D = {} against {worst} seen",
            maps.mismatch
        );
    }

    /// A set that constrains a zero-dynamics state is refused with the state's name.
    #[test]
    fn a_set_on_the_zero_dynamics_is_refused() {
        let mut p = ex49();
        p.goal.coords = Coords::StateIndices(vec![0, 4]);
        let err = linearize(&p).err().expect("refused");
        assert!(err.to_string().contains("th"), "{err}");
    }
}
