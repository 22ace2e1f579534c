//! General switching in the sampled loop (§4.2.2: Assumption 4.21, Def 4.22, Lemma 4.23, Theorem 4.24):
//! the certificate of a nominal run whose segments are joined by *internal* edges, taken by the plant when
//! its flow enters a guard between two samples, and re-synchronised by the controller (4.41)–(4.42) at
//! the first sample where it sees the state inside the guard.
//!
//! **What runs.** Segment i runs in location ℓᵢ with its gain Kᵢ and table vᵢ, row κ − κᵢ at sample κ,
//! where κᵢ is the sample at which the controller entered the segment. Its exit is the half-space guard
//! G = {x : âᵀx ≤ b̂} (‖â‖ = 1) of edge ℓᵢ → ℓᵢ₊₁, with the identity reset. At every sample of segment i
//! the evaluator computes g = fl(Σⱼ âⱼx̂ⱼ − b̂) in f32 and moves to segment i+1, row 0, when g ≤ −θ. The
//! stored threshold θ is at least twice the largest rounding error of g over the states the certificate
//! allows (`guard_eval_bound`; synthesis stores [`THETA_SLACK`] times that, so a re-proof from the bytes
//! accepts it), so a state outside G is never taken for switched ("no early detection"), and one deeper
//! than θ_eff = θ + that error always is.
//!
//! **The certificate, backwards** (segment N is judged against Goal, as one location, [`super::certify`]).
//! For segment i < N with radius r, every quantity below is an affine bound in r, so the largest r is found
//! by bisection on their conjunction (each is monotone in r):
//! 1. *Before the switch* the run is an ordinary run of location ℓᵢ: within rκ of x̃ᵢ(κ) in Pᵢ at the
//!    samples, within Rκ = γrκ + ρκ + φβε̄ between them ([`super`]'s inter-sample bound). Its deviation
//!    obeys e(κ+1) = Ãe(κ) + B·(rounding), so rκ = min(r, ‖Ã^κ‖_P·r + S_κ·z) (variation of constants,
//!    z the rounding's P-norm per step; r itself by the CAF): the tube narrows towards the guard, and
//!    items 2–5 take rκ; Theorem 4.7's parts keep r. Unsafe and the input set are checked over the kept
//!    rows (Theorem 4.7's Unsafe and Input parts), with the run's other guards and the faces of ℓᵢ's
//!    invariant not implied by "outside G" counted as Unsafe.
//! 2. *Sample 0* lies outside G by more than θ_eff: the edge is armed and nothing is detected at once.
//! 3. *All switch by κ_f*: κ_f is the first sample whose runs lie in G at depth θ_eff (the ball's reach
//!    along â, or the image's: the deviation there is Ã^κe₀ plus at most the rounding's sum, so
//!    âᵀ(x − x̃) ≤ r‖âᵀÃ^κPᵢ⁻¹ᐟ²‖ + ‖â‖_{Pᵢ⁻¹}(S_κz + η); the smaller counts); a run still in ℓᵢ
//!    there would have crossed the plane of G continuously, so every run has switched (and been
//!    detected) by κ_f. The table keeps rows 0..κ_f.
//! 4. *Each event interval* κ < κ_f whose inter-sample ball (radius Rκ) meets G: the run crosses the
//!    plane at some s ∈ [0, h] of the period, and then flows in ℓᵢ₊₁ for τ = h − s with the input of
//!    row κ before its next sample. On a grid of τ with spacing Δτ, a run that crosses at
//!    s ∈ [h − τ, h − τ + Δτ] is within R′ = γrκ + φβε̄ + Δτ·(‖fᵢ(x̃ᵢ(κ), ũ)‖_{Pᵢ} + ‖Aᵢ‖_{Pᵢ}ρκ) of
//!    xₛ = x̃ᵢ(κ + h − τ), the nominal's own flow under the held input (its deviation from that flow, and
//!    the flow's motion over Δτ). Its crossing point p lies in the plane's slab |g| ≤ θ_eff and in that
//!    ball, so within sqrt(R′² − d²) + 2θ_eff/‖â‖_{Pᵢ⁻¹} (in Pᵢ) of p̂ₛ, the Pᵢ-projection of xₛ onto the
//!    plane (d: xₛ's Pᵢ-distance to the slab; parallel and normal parts are Pᵢ-orthogonal; none crosses
//!    there when d ≥ R′). The landing x(τ) = Φ′(τ)p + Γ′(τ)(B′u + c′), u = ũ(κ) + Kᵢe + ε, is then within
//!    ‖Φ′(τ)p̂ₛ + Γ′(τ)(B′ũ + c′) − x̃ᵢ₊₁(0)‖_{P′} + ‖Φ′(τ)‖_{Pᵢ→P′}(that radius) + ‖Γ′B′Kᵢ‖_{Pᵢ→P′}rκ +
//!    ‖P′^{1/2}Γ′B′‖ε̄ + LΔτ of the next segment's start (LΔτ: the flow time is up to Δτ shorter), with
//!    L = e^{μ′⁺h} sup‖fᵢ₊₁‖_{P′} (the speed of the flow after the switch); this must be below δᵢ₊₁
//!    (Lemma 4.23's safe transition, with the event time unknown within the period: the "hole").
//!    After the switch the states stay in the P′-ball of radius ρ_post = ‖I‖_{Pᵢ→P′}Rκ + φ′ sup‖fᵢ₊₁‖_{P′}
//!    around x̃ᵢ(κ): it must clear the next location's Unsafe, and the flow must go into G at a rate
//!    âᵀfᵢ₊₁ ≤ −ν (*transversality*), so the run neither returns across the plane (the edge back,
//!    armed once it leaves G) nor stays undetected for more than one sample.
//!
//!    *The landing through the crossing map* (a second bound; each cell keeps the smaller of the two, both
//!    sound). The ball bound above spreads every crossing over the plane's whole slice of the tube, which
//!    for an oblique crossing is long. The runs' deviations are not a ball, though: at sample κ,
//!    e(κ) = Ã^κe₀ + e_d with ‖e₀‖_{Pᵢ} ≤ r and ‖e_d‖_{Pᵢ} ≤ d_κ (the rounding's and mismatch's sum over
//!    the powers, plus η of item 5), and within the period δ(s) = x(κ + s) − x̃(κ + s) = N(s)e(κ) +
//!    Γ(s)Bᵢε with N(s) = Φ(s) + Γ(s)BᵢKᵢ. For any direction v with âᵀv ≠ 0 and any point p,
//!    p − p̂ = Π_v(p − x̃(κ + s_j)) + v·g(p)/(âᵀv), where p̂ = x̃(κ + s_j) − v·g(x̃(κ + s_j))/(âᵀv) is a point
//!    of the plane and Π_v = I − vâᵀ/(âᵀv) (exact algebra: no linearisation, no remainder). A run that
//!    crosses at s ∈ [s_j, s_j + Δτ] has its crossing point p = x̃(κ + s_j) + N(s_j)Ã^κe₀ + w with |g(p)|
//!    ≤ θ_eff and ‖w‖_{Pᵢ} ≤ ρₓ = d_κ‖N(s_j)‖ + ‖Γ(s_j)Bᵢ‖ε̄ + Δτ(the nominal's speed + ‖Aᵢ‖(Rκ + ρκ) +
//!    ‖BᵢKᵢ‖rκ + ‖Bᵢ‖ε̄) (N(s_j)e_d, the input rounding, and what the deviation and the nominal move within
//!    the cell). Its landing after τ_j is then within
//!    ‖Φ′(τ_j)p̂ + Γ′(τ_j)(B′ũ + c′) − x̃ᵢ₊₁(0)‖_{P′} + r‖P′¹ᐟ²(Φ′(τ_j)Π_vN(s_j) + Γ′(τ_j)B′Kᵢ)Ã^κPᵢ⁻¹ᐟ²‖
//!    + ‖Φ′(τ_j)Π_v‖_{Pᵢ→P′}ρₓ + ‖Γ′B′Kᵢ‖_{Pᵢ→P′}d_κ + ‖P′¹ᐟ²Γ′B′‖ε̄ + ‖Φ′(τ_j)v‖_{P′}θ_eff/|âᵀv| + LΔτ
//!    of the next segment's start: the crossing's first-order map (for v the flow's direction before the
//!    plane, Π_v is the saltation matrix's part for a run re-synchronised at the plane; the flow after it
//!    is the grid's τ_j) applied to the image of the ball, not to a ball around that image.
//!    The same decomposition rules a cell out when |g(x̃(κ + s_j))| > θ_eff + r‖âᵀN(s_j)Ã^κPᵢ⁻¹ᐟ²‖ +
//!    ‖â‖_{Pᵢ⁻¹}ρₓ. The direction is the nominal's own velocity at the cell (the path curves between
//!    cells, so one direction per segment would misplace p̂ far from the nominal's crossing), and
//!    ‖Φ′(τ_j)Π_v‖_{Pᵢ→P′} is taken as ‖Φ′(τ_j)‖_{Pᵢ→P′}‖v‖_{Pᵢ}‖â‖_{Pᵢ⁻¹}/|âᵀv| (an oblique
//!    projection's norm).
//! 5. *Late detection*: a run that switched in the last s_late = θ_eff/ν of a period may be seen at the
//!    next sample within θ_eff of the plane and not yet taken for switched; the controller then applies
//!    row κ+1 of segment i for one more period, which is interval κ+1 with s = 0 (item 4 covers it). Its
//!    state differs from the location-ℓᵢ run by at most η = L·s_late (in Pᵢ), so items 1–4 are checked at
//!    rκ + η.
//!
//! Entering segment i+1 (any segment with an entry edge), the tube must stay on G's side: at samples
//! 0..W the flow crosses into G (transversality as in item 4, over segment i+1's own balls), after W its
//! inter-sample balls lie inside G. This keeps the edge back (guard ℝⁿ \ G's closure, armed as soon as
//! the state leaves the plane) from firing and the invariant face that equals G satisfied.
//!
//! Accumulated time: runs enter segment i+1 at different samples; the run takes at most Σᵢ κ_f(i) + κ*
//! samples, which must fit the horizon.
//!
//! Restrictions, refused with a reason: guards of taken edges are half-spaces and their resets are the
//! identity (the controller detects the switch by the guard on the measured state).

use super::{certify_at, Certificate, GoalAt, Loop, LoopConstants};
use crate::geometry::{GeometryError, Metric, Polytope as Halfspaces, Region, Witness};
use crate::linalg::{mat_t_vec, mat_vec, p_norm, spectral_norm, sym_eigenvalues, to_row_major};
use crate::model::hybrid::{Edge, EdgeKind, Hybrid, Polytope};
use crate::model::{ContinuousPlant, Plant};
use crate::trajectory::Nominal;
use faer::{Mat, MatRef};

/// Points of the grid of flow times after a switch, per period (spacing h/(GRID − 1)).
pub const GRID: usize = 33;
/// s_late as a fraction of the period (item 5): the required transversality rate is θ_eff / s_late.
pub const LATE_FRACTION: f64 = 0.01;
/// How much larger than the next segment's ball (in the metrics' ratio) a segment's start ball may be
/// certified: the bisection's upper end. The landing is the image of the contracted tube, so it may fit a
/// larger start ball (Example 5.5's first run: δ 0.857 with the end at the next ball, 1.13 at twice it).
pub const LANDING_REACH: f64 = 2.0;
/// The detection threshold a synthesis stores, over the least sound one (twice the guard test's rounding
/// bound). That bound is taken over the nominal's extent and the next ball's radius, which a re-proof from
/// the stored rows (shortened to κ_f, started from f32 points) computes a little differently; the slack
/// lets it accept the stored θ whenever its own bound is at most this factor larger.
pub const THETA_SLACK: f64 = 1.25;

/// One segment of a run with internal switching.
#[derive(Clone, Copy)]
pub struct InternalSegment<'a> {
    /// The segment's loop: location, shipped gain, metric, the task's Unsafe and input set; its goal is
    /// the task's Goal (only the last segment is judged against it).
    pub lp: Loop<'a>,
    pub lc: &'a LoopConstants,
    /// The nominal: for a segment with an exit, continued past the guard in its own location (the extended
    /// segment of §4.2.2) far enough that the tube lies inside the guard.
    pub nominal: &'a Nominal,
    /// The detection threshold θ of the segment's exit as an image stores it, when re-proving one; `None`
    /// when synthesising. The firmware tests against the stored θ, so a re-proof certifies that one
    /// whenever it is at least the least sound threshold, twice the bound on the f32 guard test's
    /// rounding (any such θ is sound: it enters every condition through θ_eff); else it certifies its own
    /// choice, which the stored one then fails to match.
    pub theta_stored: Option<f32>,
}

/// The f32 guard test a segment exits by (module doc).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GuardExit {
    /// â, normalised, as stored.
    pub a: Vec<f32>,
    pub b: f32,
    /// The detection threshold θ (switched when fl(âᵀx̂ − b̂) ≤ −θ).
    pub theta: f32,
}

/// The certificate of one segment.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SegmentCertificate {
    /// Theorem 4.7's parts over the kept rows (for a segment with an exit the Goal part is the bisection's
    /// upper end, not a depth).
    pub base: Certificate,
    /// The certified radius of the segment's ball around x̃ᵢ(0) (0 if none).
    pub delta: f64,
    /// Rows of the table the image keeps (κ_f for a segment with an exit, the table for the last).
    pub rows: usize,
    /// The samples the segment can last: κ_f, or κ* for the last segment.
    pub samples: usize,
    pub exit: Option<GuardExit>,
    /// Event intervals (first, last) at the certified radius.
    pub events: Option<(usize, usize)>,
    /// η of item 5.
    pub eta: f64,
    /// What limits δ (for messages and the report).
    pub binding: &'static str,
}

/// The certificate of a run with internal switching, first segment first.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InternalCertificate {
    pub segments: Vec<SegmentCertificate>,
    /// The radius to store for the first segment's ball (selection in f32).
    pub delta_stored: f32,
}

impl InternalCertificate {
    pub fn delta(&self) -> f64 {
        self.segments.first().map_or(0.0, |s| s.delta)
    }
    pub fn is_certified(&self) -> bool {
        self.delta() > 0.0 && self.delta_stored > 0.0
    }
    /// The most samples a run takes (Σ κ_f + κ*).
    pub fn samples(&self) -> usize {
        self.segments.iter().map(|s| s.samples).sum()
    }
}

/// Why a run is not one this module certifies.
#[derive(Debug, thiserror::Error)]
pub enum InternalError {
    #[error("a run needs at least one segment")]
    Empty,
    #[error("{segments} segments need {need} edges between them, got {got}")]
    Edges {
        segments: usize,
        need: usize,
        got: usize,
    },
    #[error("segment {segment}: edge {edge} does not exist")]
    UnknownEdge { segment: usize, edge: usize },
    #[error("segment {segment}: edge {edge} is forced; this certificate is for internal switching (§4.2.2)")]
    NotInternal { segment: usize, edge: usize },
    #[error("segment {segment} runs in location {loc}, but edge {edge} goes {from} → {to} and the next segment runs in {next}")]
    Locations {
        segment: usize,
        edge: usize,
        loc: usize,
        from: usize,
        to: usize,
        next: usize,
    },
    #[error("segment {segment}: edge {edge}'s guard has {rows} rows; the controller detects a switch by one half-space")]
    GuardNotHalfspace {
        segment: usize,
        edge: usize,
        rows: usize,
    },
    #[error("segment {segment}: edge {edge}'s reset is not the identity; the controller detects a switch by the guard on the measured state")]
    ResetNotIdentity { segment: usize, edge: usize },
    #[error("segment {segment}'s nominal is empty or not finite")]
    BadNominal { segment: usize },
    #[error("segment {segment}: {source}")]
    Geometry {
        segment: usize,
        #[source]
        source: GeometryError,
    },
}

/// Unsafe with extra half-space regions (guards that must not fire, invariant faces that may not be left):
/// the distance is the least, the depth the largest (a lower bound, as for a union).
struct UnsafeWith<'a> {
    n: usize,
    unsafe_set: Option<&'a dyn Region>,
    extra: Vec<Halfspaces>,
}

impl Region for UnsafeWith<'_> {
    fn dim(&self) -> usize {
        self.n
    }
    fn contains(&self, x: &[f64]) -> bool {
        self.unsafe_set.is_some_and(|u| u.contains(x)) || self.extra.iter().any(|p| p.contains(x))
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        let mut best = self.unsafe_set.map(|u| u.dist(x, metric));
        for p in &self.extra {
            let w = p.dist(x, metric);
            if best.as_ref().is_none_or(|b| w.value < b.value) {
                best = Some(w);
            }
        }
        best.unwrap_or(Witness {
            value: f64::INFINITY,
            point: Vec::new(),
        })
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        let mut best = self.unsafe_set.map(|u| u.depth(x, metric));
        for p in &self.extra {
            let w = p.depth(x, metric);
            if best.as_ref().is_none_or(|b| w.value > b.value) {
                best = Some(w);
            }
        }
        best.unwrap_or(Witness {
            value: f64::NEG_INFINITY,
            point: Vec::new(),
        })
    }
}

/// A half-space a·x ≤ b, normalised (‖a‖ = 1).
#[derive(Clone, Debug)]
struct Half {
    a: Vec<f64>,
    b: f64,
}

impl Half {
    fn of(p: &Polytope, row: usize) -> Option<Half> {
        let a = p.a.get(row)?;
        let na = a.iter().map(|v| v * v).sum::<f64>().sqrt();
        (na > 0.0).then(|| Half {
            a: a.iter().map(|v| v / na).collect(),
            b: p.b[row] / na,
        })
    }
    /// a·x − b: negative inside.
    fn g(&self, x: &[f64]) -> f64 {
        dot(&self.a, x) - self.b
    }
    fn same(&self, o: &Half) -> bool {
        self.a.iter().zip(&o.a).all(|(p, q)| (p - q).abs() <= 1e-12)
            && (self.b - o.b).abs() <= 1e-12 * (1.0 + self.b.abs())
    }
    fn negated(&self) -> Half {
        Half {
            a: self.a.iter().map(|v| -v).collect(),
            b: -self.b,
        }
    }
    fn region(&self) -> Result<Halfspaces, GeometryError> {
        Halfspaces::new(self.a.len(), self.a.clone(), vec![self.b])
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(p, q)| p * q).sum()
}

/// ‖P_to^{1/2} M P_from^{-1/2}‖₂.
fn cross(to: &crate::linalg::PdRoots, M: MatRef<'_, f64>, from: &crate::linalg::PdRoots) -> f64 {
    spectral_norm((&to.sqrt * M * &from.inv_sqrt).as_ref())
}

/// The logarithmic norm of A in the P-metric, λmax(sym(P^{1/2}AP^{-1/2})).
fn log_norm(roots: &crate::linalg::PdRoots, A: MatRef<'_, f64>) -> f64 {
    let As = &roots.sqrt * A * &roots.inv_sqrt;
    let S = crate::linalg::sym(As.as_ref());
    sym_eigenvalues(S.as_ref())
        .and_then(|e| e.last().copied())
        .unwrap_or(f64::INFINITY)
}

/// The largest error of the evaluator's f32 guard value fl(Σⱼ âⱼx̂ⱼ − b̂) against âᵀx − b (exact â, b, x)
/// for |xⱼ| ≤ Xⱼ: storing â and b̂ (u each), quantising x (u), and n products and n sums (γ_{n+1}),
/// Higham §3.1, with a factor 2 for the products of these small terms.
fn guard_eval_bound(a: &[f64], b: f64, X: &[f64]) -> f64 {
    let n = a.len();
    let s: f64 = a.iter().zip(X).map(|(p, q)| p.abs() * q).sum::<f64>() + b.abs();
    2.0 * (3.0 * super::U32 + super::gamma_k(n + 1)) * s + 1e-40
}

/// Per-location constants the bounds use.
struct Loc<'a> {
    cp: &'a ContinuousPlant,
    K: MatRef<'a, f64>,
    lc: &'a LoopConstants,
}

impl Loc<'_> {
    /// Rκ = γ r + ρκ + φβε̄ (the inter-sample ball around x̃(κ)).
    fn inter(&self, r: f64, rho: f64, eps: f64) -> f64 {
        self.lc.gamma * r + rho + self.lc.held_disturbance(eps)
    }
}

/// The grid of times τ ∈ [0, h] a run flows in the next location before its first sample there:
/// Φ′(τ), Γ′(τ)B′, Γ′(τ)c′ and the norms the landing bound takes of them.
struct Grid {
    Phi: Vec<Mat<f64>>,
    GB: Vec<Mat<f64>>,
    Gc: Vec<Vec<f64>>,
    /// The switching location's flow over s = h − τ: Φ(s), Γ(s)B, Γ(s)c (where the nominal is when a
    /// run that lands after τ crossed).
    pre_Phi: Vec<Mat<f64>>,
    pre_GB: Vec<Mat<f64>>,
    pre_Gc: Vec<Vec<f64>>,
    /// ‖Φ′(τ)‖_{Pᵢ→P′}, ‖Γ′(τ)B′Kᵢ‖_{Pᵢ→P′}, ‖P′^{1/2}Γ′(τ)B′‖.
    norm_Phi: Vec<f64>,
    norm_GBK: Vec<f64>,
    norm_GB: Vec<f64>,
}

fn flow_parts(cp: &ContinuousPlant, s: f64) -> (Mat<f64>, Mat<f64>, Vec<f64>) {
    let n = cp.n();
    if s <= 0.0 {
        return (Mat::identity(n, n), Mat::zeros(n, cp.m()), vec![0.0; n]);
    }
    match cp.zoh(s) {
        Ok(d) => (d.A, d.B, d.g),
        Err(_) => (
            Mat::from_fn(n, n, |_, _| f64::NAN),
            Mat::from_fn(n, cp.m(), |_, _| f64::NAN),
            vec![f64::NAN; n],
        ),
    }
}

impl Grid {
    fn new(pre: &Loc<'_>, post: &Loc<'_>, h: f64) -> Self {
        let mut g = Grid {
            Phi: Vec::new(),
            GB: Vec::new(),
            Gc: Vec::new(),
            pre_Phi: Vec::new(),
            pre_GB: Vec::new(),
            pre_Gc: Vec::new(),
            norm_Phi: Vec::new(),
            norm_GBK: Vec::new(),
            norm_GB: Vec::new(),
        };
        for j in 0..GRID {
            let tau = h * j as f64 / (GRID - 1) as f64;
            let (Phi, GB, Gc) = flow_parts(post.cp, tau);
            let GBK = &GB * pre.K;
            g.norm_Phi
                .push(cross(&post.lc.roots, Phi.as_ref(), &pre.lc.roots));
            g.norm_GBK
                .push(cross(&post.lc.roots, GBK.as_ref(), &pre.lc.roots));
            g.norm_GB.push(post.lc.roots.norm_into(GB.as_ref()));
            g.Phi.push(Phi);
            g.GB.push(GB);
            g.Gc.push(Gc);
            let (Phi, GB, Gc) = flow_parts(pre.cp, h - tau);
            g.pre_Phi.push(Phi);
            g.pre_GB.push(GB);
            g.pre_Gc.push(Gc);
        }
        g
    }
}

/// Per-sample data of a segment with an exit, independent of r.
struct ExitSamples {
    /// g(x̃(κ)) = âᵀx̃ − b̂.
    g: Vec<f64>,
    /// ρκ = φ‖f(x̃(κ), ũ(κ))‖_P.
    rho: Vec<f64>,
    /// ‖fᵢ(x̃, ũ)‖_{P′}, ‖fᵢ₊₁(x̃, ũ)‖_{P′}, âᵀfᵢ₊₁(x̃, ũ).
    f_pre: Vec<f64>,
    f_post: Vec<f64>,
    trans: Vec<f64>,
    /// Signed P′-distance from x̃(κ) to the next location's Unsafe (with its extras).
    unsafe_next: Vec<f64>,
    /// Per grid point τ (s = h − τ): g(x̃(κ + s)), the guard at the nominal's flow within the period, and
    /// ‖Φ′(τ)p̂ₛ + Γ′(τ)(B′ũ + c′) − x̃ᵢ₊₁(0)‖_{P′}, p̂ₛ the Pᵢ-projection of x̃(κ + s) onto the plane.
    sub_g: Vec<Vec<f64>>,
    land: Vec<Vec<f64>>,
    /// ‖fᵢ(x̃(κ), ũ)‖_{Pᵢ} + ‖Aᵢ‖_{Pᵢ}ρκ: the nominal's speed within the period at most.
    speed: Vec<f64>,
    /// ‖Ã^κ‖_P and S_κ·z (z the rounding's P-norm per step): a run's sample-κ deviation is at most
    /// ‖Ã^κ‖_P·r + S_κ·z (variation of constants), and at most r (the CAF's invariant ball).
    power: Vec<f64>,
    disturbed: Vec<f64>,
    /// ‖âᵀÃ^κPᵢ⁻¹ᐟ²‖ per sample ([`ExitSamples::guard_reach`]).
    normal_reach: Vec<f64>,
    /// The crossing map per cell of the event grid, [κ][j] (item 4's second bound); `None` where the
    /// ball bound alone is taken (it rules a crossing there out at the largest radius tried), and rows
    /// past the last κ it was computed for.
    cells: Vec<Vec<Option<Cell>>>,
}

/// The first-order crossing map of one cell (κ, j) of the event grid: runs that cross the plane in
/// period κ at s ∈ [s_j, s_j + Δτ], s_j = h − τ_j (module doc, item 4's second bound).
struct Cell {
    /// ‖âᵀN(s_j)Ã^κP⁻¹ᐟ²‖₂: how far the image of the start ball reaches along the guard's normal.
    sig_g: f64,
    /// ‖N(s_j)‖_{P→P}, N(s) = Φ(s) + Γ(s)BK the deviation's flow within the period.
    n_N: f64,
    /// ‖Γ(s_j)B‖ into P (the input rounding's part of the deviation at s_j).
    n_GB: f64,
    /// No run crosses in this cell at the largest radius tried, so at none (its view is then not
    /// computed).
    ruled_out: bool,
    /// The bound with the crossing point projected along the nominal's velocity there (`None` where that
    /// is parallel to the plane).
    view: Option<View>,
}

impl Cell {
    /// ρₓ of the module doc at sample κ = `k`: what besides N(s_j)Ã^κe₀ separates the crossing point from
    /// x̃(κ + s_j) (N(s_j)e_d, the input rounding, and what the deviation and the nominal move within the
    /// cell), for a deviation `dk` besides Ã^κe₀, an inter-sample radius `R` and a sample radius `re`.
    fn rho_x(&self, c: &ExitConstants, d: &ExitSamples, k: usize, dk: f64, R: f64, re: f64) -> f64 {
        dk * self.n_N
            + self.n_GB * c.eps
            + c.dt * (d.speed[k] + c.a_pre * (R + d.rho[k]) + c.c_BK_pre * re + c.c_B_pre * c.eps)
    }
}

/// ‖G‖₂ of a small matrix: the square root of the largest eigenvalue of GᵀG (nalgebra's symmetric
/// eigensolver; a third of faer's SVD's time at n = 3, which is made for large matrices); ∞ for a matrix
/// with an entry that is not finite, as [`spectral_norm`] answers when it cannot.
fn spectral_norm_small(G: &nalgebra::DMatrix<f64>) -> f64 {
    if G.iter().any(|v| !v.is_finite()) {
        return f64::INFINITY;
    }
    let gram = G.transpose() * G;
    gram.symmetric_eigenvalues()
        .iter()
        .fold(0.0f64, |m, &l| m.max(l))
        .sqrt()
}

/// A [`Cell`]'s bound with the crossing point projected along v, the nominal's own velocity there.
struct View {
    /// ‖Φ′(τ_j)p̂ + Γ′(τ_j)(B′ũ + c′) − x̃ᵢ₊₁(0)‖_{P′}, p̂ the point of the plane x̃(κ + s_j) − (g/âᵀv)v.
    centre: f64,
    /// ‖P′¹ᐟ²(Φ′(τ_j)Π_vN(s_j) + Γ′(τ_j)B′K)Ã^κP⁻¹ᐟ²‖₂, Π_v = I − vâᵀ/(âᵀv): the landing's spread
    /// per unit of the start ball's radius.
    spread: f64,
    /// ‖Φ′(τ_j)Π_v‖_{P→P′}: what a deviation at the crossing adds to the landing.
    n_phi_pi: f64,
    /// ‖Φ′(τ_j)v‖_{P′}/|âᵀv|: what the crossing point's distance from the plane (≤ θ_eff) adds.
    n_phi_v: f64,
}

impl ExitSamples {
    /// The sample-κ radius of the runs from the r-ball at row 0 ([`ExitSamples::power`]), plus η.
    fn radius(&self, k: usize, r: f64, eta: f64) -> f64 {
        let contracted = match (self.power.get(k), self.disturbed.get(k)) {
            (Some(&p), Some(&z)) => (p * r + z).min(r),
            _ => r,
        };
        contracted + eta
    }

    /// How far along the guard's normal the runs from the r-ball at row 0 may be from x̃(κ) at sample
    /// κ = `k`: the ball's reach ‖â‖_{Pᵢ⁻¹}·[`ExitSamples::radius`], or the image's,
    /// r‖âᵀÃ^κPᵢ⁻¹ᐟ²‖ + ‖â‖_{Pᵢ⁻¹}(S_κz + η) (the deviation is Ã^κe₀ plus at most that), whichever is less.
    fn guard_reach(&self, k: usize, r: f64, eta: f64, dn: f64) -> f64 {
        (dn * self.radius(k, r, eta)).min(r * self.normal_reach[k] + dn * self.beside_image(k, eta))
    }

    /// How far a run's sample-κ deviation may be from the image Ã^κe₀ of its start (item 4's d_κ): the
    /// rounding's and mismatch's sum S_κz, plus η.
    fn beside_image(&self, k: usize, eta: f64) -> f64 {
        self.disturbed[k] + eta
    }
}

/// r-independent constants of a segment with an exit.
struct ExitConstants {
    dn: f64,
    theta_eff: f64,
    nu_min: f64,
    s_late: f64,
    /// Coefficients: ‖·‖_{Pᵢ→P′} of I, Aᵢ, BᵢKᵢ, A′, B′Kᵢ; ‖P′^{1/2}Bᵢ‖, ‖P′^{1/2}B′‖; e^{μ′⁺h}.
    c_id: f64,
    c_A: f64,
    c_BK: f64,
    c_A2: f64,
    c_BK2: f64,
    c_B: f64,
    c_B2: f64,
    grow: f64,
    /// Dual norms for transversality: ‖A′ᵀâ‖_{P′⁻¹}, ‖(B′Kᵢ)ᵀâ‖_{Pᵢ⁻¹}, ‖B′ᵀâ‖₂.
    t_A2: f64,
    t_BK2: f64,
    t_B2: f64,
    /// ‖P′^{1/2}Pᵢ^{-1/2}‖ back: ‖I‖_{P′→Pᵢ}.
    c_back: f64,
    phi2: f64,
    eps: f64,
    delta_next: f64,
    dt: f64,
    /// ‖Aᵢ‖_{Pᵢ}, ‖BᵢKᵢ‖_{Pᵢ} and ‖Bᵢ‖ into Pᵢ: how fast the deviation moves within a cell.
    a_pre: f64,
    c_BK_pre: f64,
    c_B_pre: f64,
}

/// Outcome of checking a radius.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Verdict {
    Ok {
        kappa_f: usize,
        first: Option<usize>,
        last: Option<usize>,
    },
    Fail(&'static str),
}

fn check_exit(
    r: f64,
    loc: &Loc<'_>,
    c: &ExitConstants,
    d: &ExitSamples,
    grid: &Grid,
    eta: f64,
) -> Verdict {
    let rows = d.g.len() - 1;
    // 2. Sample 0 outside G by more than θ_eff.
    if !(d.g[0] - c.dn * d.radius(0, r, eta) > c.theta_eff) {
        return Verdict::Fail("the first sample's ball reaches the guard");
    }
    // 3. κ_f.
    let Some(kappa_f) =
        (1..=rows).find(|&k| d.g[k] + d.guard_reach(k, r, eta, c.dn) <= -c.theta_eff)
    else {
        return Verdict::Fail("the extended segment's tube never lies inside the guard");
    };
    let (mut first, mut last) = (None, None);
    for k in 0..kappa_f {
        let re = d.radius(k, r, eta);
        let R = loc.inter(re, d.rho[k], c.eps);
        if d.g[k] - c.dn * R > 0.0 {
            continue;
        }
        first.get_or_insert(k);
        last = Some(k);
        let F_post = d.f_post[k] + c.c_A2 * R + c.c_BK2 * re + c.c_B2 * c.eps;
        let rho_post = c.c_id * R + c.phi2 * F_post;
        if !(d.unsafe_next[k] > rho_post) {
            return Verdict::Fail("Unsafe after a switch");
        }
        let t = d.trans[k] + c.t_A2 * rho_post + c.t_BK2 * re + c.t_B2 * c.eps;
        if !(t <= -c.nu_min) {
            return Verdict::Fail("transversality after a switch");
        }
        // A run that crosses at s ∈ [h − τ, h − τ + Δτ] of the period is then within R′ = γrκ + φβε̄ +
        // Δτ·speed of x̃(κ + h − τ) (its deviation from the nominal's own flow, and the nominal's motion over
        // the grid step), and flows τ′ ∈ [τ − Δτ, τ] after the switch (L·Δτ from the flow over τ). Its
        // crossing point lies in the slab |g| ≤ θ_eff and that ball: within sqrt(R′² − d²) + 2θ_eff/‖â‖ of
        // p̂ₛ (P-orthogonal parts), d the centre's distance to the slab; none crosses there if d ≥ R′.
        let L = c.grow * F_post;
        let R_sub = loc.inter(re, c.dt * d.speed[k], c.eps);
        let dk = d.beside_image(k, eta);
        for j in 0..d.land[k].len() {
            let d_slab = ((d.sub_g[k][j].abs() - c.theta_eff).max(0.0)) / c.dn;
            if d_slab >= R_sub {
                continue;
            }
            let rad_p =
                (R_sub * R_sub - d_slab * d_slab).max(0.0).sqrt() + 2.0 * c.theta_eff / c.dn;
            let mut reach = d.land[k][j]
                + grid.norm_Phi[j] * rad_p
                + grid.norm_GBK[j] * re
                + grid.norm_GB[j] * c.eps
                + L * c.dt;
            if let Some(cell) = d
                .cells
                .get(k)
                .and_then(|row| row.get(j))
                .and_then(Option::as_ref)
            {
                let rho_x = cell.rho_x(c, d, k, dk, R, re);
                if cell.ruled_out
                    || d.sub_g[k][j].abs() > c.theta_eff + r * cell.sig_g + c.dn * rho_x
                {
                    continue;
                }
                if let Some(v) = &cell.view {
                    reach = reach.min(
                        v.centre
                            + r * v.spread
                            + v.n_phi_pi * rho_x
                            + grid.norm_GBK[j] * dk
                            + grid.norm_GB[j] * c.eps
                            + v.n_phi_v * c.theta_eff
                            + L * c.dt,
                    );
                }
            }
            if !(reach < c.delta_next) {
                return Verdict::Fail("the landing misses the next segment's ball");
            }
        }
    }
    Verdict::Ok {
        kappa_f,
        first,
        last,
    }
}

/// What [`crossing_cells`] reads besides the samples and the constants.
struct CellInputs<'a> {
    pre: &'a Loc<'a>,
    post: &'a Loc<'a>,
    exit: &'a Half,
    nom: &'a Nominal,
    target: &'a [f64],
    grid: &'a Grid,
    /// x̃(κ + s_j): the nominal's flow within each period under its held input, [κ][j].
    sub: &'a [Vec<Vec<f64>>],
    /// Ã^κPᵢ⁻¹ᐟ² per sample: the image of the start ball's unit sphere.
    whitened: &'a [Mat<f64>],
}

/// The crossing map of every cell (κ, j), κ < `kf_max`, that neither the ball bound nor the ellipsoid's
/// reach along the normal rules out at the radius `r_max` (both then rule it out at every smaller radius
/// too). Π_v is I minus a rank-one term, so P′¹ᐟ²(Φ′Π_vN + Γ′B′K)Ã^κPᵢ⁻¹ᐟ² is the grid point's
/// P′¹ᐟ²(Φ′N + Γ′B′K)·Ã^κPᵢ⁻¹ᐟ² less (P′¹ᐟ²Φ′v)(Wᵀ(Nᵀâ))ᵀ/(âᵀv), and ‖Φ′Π_v‖_{Pᵢ→P′} is at most
/// ‖Φ′‖_{Pᵢ→P′}‖v‖_{Pᵢ}‖â‖_{Pᵢ⁻¹}/|âᵀv| (in Pᵢ's whitened coordinates Π_v is a projection Q, and
/// ‖Q‖ = ‖I − Q‖ for Q ≠ 0, I, here a rank-one matrix whose norm is that ratio).
fn crossing_cells(
    inp: &CellInputs<'_>,
    d: &ExitSamples,
    c: &ExitConstants,
    r_max: f64,
    eta: f64,
    kf_max: usize,
) -> Vec<Vec<Option<Cell>>> {
    let (pre, post, grid) = (inp.pre, inp.post, inp.grid);
    let n = inp.exit.a.len();
    let roots = &pre.lc.roots;
    let a = &inp.exit.a;
    // N(s_j) = Φ(s_j) + Γ(s_j)BᵢKᵢ and what depends on the grid point alone.
    let N: Vec<Mat<f64>> = (0..GRID)
        .map(|j| &grid.pre_Phi[j] + &grid.pre_GB[j] * pre.K)
        .collect();
    let aN: Vec<Vec<f64>> = N.iter().map(|m| mat_t_vec(m.as_ref(), a)).collect();
    let n_N: Vec<f64> = N.iter().map(|m| cross(roots, m.as_ref(), roots)).collect();
    let n_GB: Vec<f64> = (0..GRID)
        .map(|j| roots.norm_into(grid.pre_GB[j].as_ref()))
        .collect();
    let base: Vec<Mat<f64>> = (0..GRID)
        .map(|j| &post.lc.roots.sqrt * (&grid.Phi[j] * &N[j] + &grid.GB[j] * pre.K))
        .collect();
    let sqrt_phi: Vec<Mat<f64>> = (0..GRID)
        .map(|j| &post.lc.roots.sqrt * &grid.Phi[j])
        .collect();
    let mut cells = Vec::with_capacity(kf_max);
    for (k, W) in inp
        .whitened
        .iter()
        .enumerate()
        .take(kf_max.min(inp.sub.len()))
    {
        let re = d.radius(k, r_max, eta);
        let R = pre.inter(re, d.rho[k], c.eps);
        let R_sub = pre.inter(re, c.dt * d.speed[k], c.eps);
        let dk = d.beside_image(k, eta);
        let u = inp.nom.u.get(k).or(inp.nom.u.last()).expect("rows ≥ 1");
        let mut row = Vec::with_capacity(GRID);
        for j in 0..GRID {
            let g = d.sub_g[k][j];
            let d_slab = ((g.abs() - c.theta_eff).max(0.0)) / c.dn;
            if d.g[k] - c.dn * R > 0.0 || d_slab >= R_sub {
                row.push(None);
                continue;
            }
            // z = Wᵀ(N(s_j)ᵀâ): ‖z‖ = ‖âᵀN(s_j)Ã^κPᵢ⁻¹ᐟ²‖.
            let z: Vec<f64> = (0..n)
                .map(|q| (0..n).map(|p| W[(p, q)] * aN[j][p]).sum::<f64>())
                .collect();
            let sig_g = z.iter().map(|v| v * v).sum::<f64>().sqrt();
            let cell = Cell {
                sig_g,
                n_N: n_N[j],
                n_GB: n_GB[j],
                ruled_out: false,
                view: None,
            };
            if g.abs() > c.theta_eff + r_max * sig_g + c.dn * cell.rho_x(c, d, k, dk, R, re) {
                row.push(Some(Cell {
                    ruled_out: true,
                    ..cell
                }));
                continue;
            }
            let x = &inp.sub[k][j];
            // The direction: the nominal's own velocity there.
            let v = pre.cp.f(x, u);
            let av = dot(a, &v);
            let nv = v.iter().map(|q| q * q).sum::<f64>().sqrt();
            let view = (av.abs() > 1e-9 * nv).then(|| {
                let t = g / av;
                let fu = mat_vec(grid.GB[j].as_ref(), u);
                let centre: Vec<f64> = (0..n)
                    .map(|q| {
                        let phi_p: f64 = (0..n)
                            .map(|r| grid.Phi[j][(q, r)] * (x[r] - t * v[r]))
                            .sum();
                        phi_p + fu[q] + grid.Gc[j][q] - inp.target[q]
                    })
                    .collect();
                let w = mat_vec(sqrt_phi[j].as_ref(), &v);
                let G = nalgebra::DMatrix::from_fn(n, n, |p, q| {
                    (0..n).map(|r| base[j][(p, r)] * W[(r, q)]).sum::<f64>() - w[p] * z[q] / av
                });
                let nw = w.iter().map(|q| q * q).sum::<f64>().sqrt();
                View {
                    centre: p_norm(post.lc.P.as_ref(), &centre),
                    spread: spectral_norm_small(&G),
                    n_phi_pi: grid.norm_Phi[j] * p_norm(pre.lc.P.as_ref(), &v) * c.dn / av.abs(),
                    n_phi_v: nw / av.abs(),
                }
            });
            row.push(Some(Cell { view, ..cell }));
        }
        cells.push(row);
    }
    cells
}

/// Entry window (module doc): with radius r, ∃W: transversality into G at samples ≤ W, inter-sample balls
/// inside G after W (up to `end`).
fn check_entry(r: f64, loc: &Loc<'_>, entry: &Half, nom: &Nominal, end: usize, eps: f64) -> bool {
    let roots = &loc.lc.roots;
    let dn = roots.dual_norm(&entry.a);
    let tA = roots.dual_norm(&mat_t_vec(loc.cp.A.as_ref(), &entry.a));
    let BK = &loc.cp.B * loc.K;
    let tBK = roots.dual_norm(&mat_t_vec(BK.as_ref(), &entry.a));
    let tB = mat_t_vec(loc.cp.B.as_ref(), &entry.a)
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt();
    let radius = |k: usize| -> f64 {
        if k < nom.steps() {
            let f = loc.cp.f(&nom.x[k], &nom.u[k]);
            loc.inter(r, loc.lc.phi * p_norm(loc.lc.P.as_ref(), &f), eps)
        } else {
            r
        }
    };
    // deep[k]: the ball of sample k (with its interval) inside G.
    let deep: Vec<bool> = (0..=end)
        .map(|k| entry.g(&nom.x[k]) + dn * radius(k) < 0.0)
        .collect();
    let mut all_deep_after = vec![true; end + 2];
    for k in (0..=end).rev() {
        all_deep_after[k] = deep[k] && all_deep_after[k + 1];
    }
    for w in 0..=end {
        // Transversality at sample w (its interval), then all deep after w.
        if w < nom.steps() {
            let f = loc.cp.f(&nom.x[w], &nom.u[w]);
            let t = dot(&entry.a, &f) + tA * radius(w) + tBK * r + tB * eps;
            if !(t < 0.0) {
                return false;
            }
        } else {
            return all_deep_after[w];
        }
        if all_deep_after[w + 1] {
            return true;
        }
    }
    true
}

/// Largest r in (lo, hi] with `ok(r)` (ok monotone: true below some point), by bisection; 0 if none.
fn bisect(hi: f64, ok: impl Fn(f64) -> bool) -> f64 {
    if !(hi > 0.0) {
        return 0.0;
    }
    if ok(hi) {
        return hi;
    }
    let (mut lo, mut hi) = (0.0f64, hi);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if ok(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The first `rows` rows of a nominal and its states up to sample `rows` (all of it if shorter).
pub fn truncate(nom: &Nominal, rows: usize) -> Nominal {
    let rows = rows.min(nom.steps());
    Nominal {
        x: nom.x[..=rows].to_vec(),
        v: nom.v[..rows].to_vec(),
        u: nom.u[..rows].to_vec(),
    }
}

/// Theorem 4.24 for the sampled f32 loop (module doc). `edges[i]` is the index in `plant.edges()` of the
/// internal edge that ends segment i; `steps` is the horizon in samples.
pub fn certify_internal(
    plant: &Hybrid,
    segments: &[InternalSegment<'_>],
    edges: &[usize],
    steps: usize,
) -> Result<InternalCertificate, InternalError> {
    let last = segments.len().checked_sub(1).ok_or(InternalError::Empty)?;
    if edges.len() != last {
        return Err(InternalError::Edges {
            segments: segments.len(),
            need: last,
            got: edges.len(),
        });
    }
    let n = plant.n();
    let h = plant.period();
    // Validate the run and collect each segment's exit and entry half-spaces.
    let mut exits: Vec<Option<Half>> = vec![None; segments.len()];
    for (i, s) in segments.iter().enumerate() {
        let nom = s.nominal;
        if nom.x.is_empty() || nom.x.iter().flatten().any(|v| !v.is_finite()) || nom.steps() == 0 {
            return Err(InternalError::BadNominal { segment: i });
        }
        if i == last {
            continue;
        }
        let e = edges[i];
        let edge: &Edge = plant.edges().get(e).ok_or(InternalError::UnknownEdge {
            segment: i,
            edge: e,
        })?;
        if edge.kind != EdgeKind::Internal {
            return Err(InternalError::NotInternal {
                segment: i,
                edge: e,
            });
        }
        let next = segments[i + 1].lp.loc;
        if edge.from != s.lp.loc || edge.to != next {
            return Err(InternalError::Locations {
                segment: i,
                edge: e,
                loc: s.lp.loc,
                from: edge.from,
                to: edge.to,
                next,
            });
        }
        if edge.guard.a.len() != 1 {
            return Err(InternalError::GuardNotHalfspace {
                segment: i,
                edge: e,
                rows: edge.guard.a.len(),
            });
        }
        let id = (0..n)
            .all(|p| (0..n).all(|q| edge.reset.R[(p, q)] == if p == q { 1.0 } else { 0.0 }))
            && edge.reset.r.iter().all(|&v| v == 0.0);
        if !id {
            return Err(InternalError::ResetNotIdentity {
                segment: i,
                edge: e,
            });
        }
        exits[i] = Half::of(&edge.guard, 0);
        if exits[i].is_none() {
            return Err(InternalError::GuardNotHalfspace {
                segment: i,
                edge: e,
                rows: 0,
            });
        }
    }
    let entries: Vec<Option<Half>> = (0..segments.len())
        .map(|i| if i == 0 { None } else { exits[i - 1].clone() })
        .collect();
    // Each segment's Unsafe: the task's, plus the internal guards of its location that the run must not
    // take (all but its exit and the edge back across its entry plane, which the entry window keeps away),
    // plus the faces of its invariant implied neither by "outside its exit" nor by "inside its entry".
    let mut guarded: Vec<UnsafeWith> = Vec::with_capacity(segments.len());
    for (i, s) in segments.iter().enumerate() {
        let geo = |source| InternalError::Geometry { segment: i, source };
        let mut extra = Vec::new();
        for (e, edge) in plant.edges().iter().enumerate() {
            if edge.from != s.lp.loc || edge.kind != EdgeKind::Internal {
                continue;
            }
            if i < last && e == edges[i] {
                continue;
            }
            if let (Some(entry), Some(h0)) = (&entries[i], Half::of(&edge.guard, 0)) {
                if edge.guard.a.len() == 1 && h0.same(&entry.negated()) {
                    continue;
                }
            }
            let a: Vec<f64> = edge.guard.a.iter().flatten().copied().collect();
            extra.push(Halfspaces::new(n, a, edge.guard.b.clone()).map_err(geo)?);
        }
        if let Some(inv) = &plant.modes()[s.lp.loc].invariant {
            for row in 0..inv.a.len() {
                let Some(face) = Half::of(inv, row) else {
                    continue;
                };
                let implied_exit = exits[i].as_ref().is_some_and(|x| face.same(&x.negated()));
                let implied_entry = entries[i].as_ref().is_some_and(|x| face.same(x));
                if !(implied_exit || implied_entry) {
                    extra.push(face.negated().region().map_err(geo)?);
                }
            }
        }
        guarded.push(UnsafeWith {
            n,
            unsafe_set: s.lp.unsafe_set,
            extra,
        });
    }
    let lp_of = |i: usize| -> Loop<'_> {
        Loop {
            unsafe_set: Some(&guarded[i] as &dyn Region),
            ..segments[i].lp
        }
    };
    let loc_of = |i: usize| Loc {
        cp: &plant.modes()[segments[i].lp.loc].flow,
        K: segments[i].lp.K,
        lc: segments[i].lc,
    };

    let mut certs: Vec<SegmentCertificate> = Vec::with_capacity(segments.len());
    // The last segment: Goal, then the entry window.
    {
        let s = &segments[last];
        let base = certify_at(&lp_of(last), s.lc, s.nominal, GoalAt::Best);
        let mut delta = base.delta;
        let mut binding = "Theorem 4.7 (Goal, Unsafe, Input)";
        if let (Some(entry), true) = (&entries[last], delta > 0.0) {
            let loc = loc_of(last);
            let end = base.k_star.min(s.nominal.steps());
            let eps = base.eps_f32;
            let r = bisect(delta, |r| check_entry(r, &loc, entry, s.nominal, end, eps));
            if r < delta {
                binding = "the entry window (the run must stay across the plane it entered by)";
                delta = if r > base.r_crit {
                    r * (1.0 - 1e-9)
                } else {
                    0.0
                };
            }
        }
        certs.push(SegmentCertificate {
            // The table up to Goal (κ*): past it the task is over and the terminal behaviour applies.
            rows: (base.k_star + 1).min(s.nominal.steps()),
            samples: base.k_star,
            exit: None,
            events: None,
            eta: 0.0,
            binding,
            delta,
            base,
        });
    }
    for i in (0..last).rev() {
        let s = &segments[i];
        let next = &segments[i + 1];
        let next_cert = certs.last().expect("one per later segment");
        let delta_next = next_cert.delta;
        let exit = exits[i].clone().expect("checked above");
        let (pre, post) = (loc_of(i), loc_of(i + 1));
        let nom = s.nominal;
        let rows = nom.steps();
        let empty = |binding: &'static str, base: Certificate| SegmentCertificate {
            base,
            delta: 0.0,
            rows,
            samples: rows,
            exit: None,
            events: None,
            eta: 0.0,
            binding,
        };
        let roots = &pre.lc.roots;
        let dn = roots.dual_norm(&exit.a);
        let gs: Vec<f64> = nom.x.iter().map(|x| exit.g(x)).collect();
        // The bisection's upper end: a Pᵢ-ball [`LANDING_REACH`] times the size of the next ball's P′-ball
        // (the tube contracts before the plane, and the landing bound takes the ball's image Ã^κ·ball),
        // and deep enough somewhere. A higher end only widens η and θ, which are taken there.
        let c_id = cross(&post.lc.roots, Mat::<f64>::identity(n, n).as_ref(), roots);
        let c_back = cross(roots, Mat::<f64>::identity(n, n).as_ref(), &post.lc.roots);
        // A run's sample-κ radius is at least ‖Ã^κ‖_P·r ([`ExitSamples::radius`]), so some sample's ball
        // lies in G only if r ≤ −g(x̃(κ))/(‖â‖·‖Ã^κ‖_P) there.
        let power = pre.lc.power_norms(rows + 1);
        // Ã^κPᵢ⁻¹ᐟ², and ‖âᵀÃ^κPᵢ⁻¹ᐟ²‖: how far the image of the start ball reaches along the guard's
        // normal at κ.
        let whitened: Vec<Mat<f64>> =
            std::iter::successors(Some(roots.inv_sqrt.clone()), |W| Some(&pre.lc.At * W))
                .take(rows + 1)
                .collect();
        let normal_reach: Vec<f64> = whitened
            .iter()
            .map(|W| {
                mat_t_vec(W.as_ref(), &exit.a)
                    .iter()
                    .map(|v| v * v)
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        // The depth test of item 3 takes the smaller of the ball's and the image's reach
        // ([`ExitSamples::guard_reach`]), so the end is where either could lie inside.
        let deepest = gs
            .iter()
            .zip(&power)
            .zip(&normal_reach)
            .fold(f64::NEG_INFINITY, |a, ((&g, &p), &w)| {
                a.max(-g / (dn * p.min(1.0)).min(w))
            });
        let r_max = (LANDING_REACH * delta_next / c_id).min(deepest);
        if !(delta_next > 0.0) || !(r_max > 0.0) {
            let base = certify_at(&lp_of(i), s.lc, nom, GoalAt::Free(0.0));
            certs.push(empty(
                if delta_next > 0.0 {
                    "the extended segment never crosses the guard"
                } else {
                    "the next segment certifies nothing"
                },
                base,
            ));
            continue;
        }
        // κ_f at r_max bounds every κ_f below it: keep rows up to there for Theorem 4.7's parts.
        let base_full = certify_at(&lp_of(i), s.lc, nom, GoalAt::Free(r_max));
        let eps = base_full.eps_f32;
        // The rounding of the guard value, over the states the bounds allow (generously).
        let spread = (pre.inter(r_max, 0.0, eps) + 1.0) * 10.0;
        let X: Vec<f64> = (0..n)
            .map(|j| {
                let m = nom.x.iter().fold(0.0f64, |a, x| a.max(x[j].abs()));
                let axis = pre.lc.axis[j].max(post.lc.axis[j]);
                m + spread * axis + 1.0
            })
            .collect();
        let bound_g = guard_eval_bound(&exit.a, exit.b, &X);
        let required = 2.0 * bound_g;
        let theta = match s.theta_stored {
            Some(stored) if stored as f64 >= required => stored,
            _ => {
                let t = super::round_down_f32(THETA_SLACK * required);
                if (t as f64) < THETA_SLACK * required {
                    f32::from_bits(t.to_bits() + 1)
                } else {
                    t
                }
            }
        };
        let theta_eff = theta as f64 + bound_g;
        let s_late = LATE_FRACTION * h;
        let mu2 = log_norm(&post.lc.roots, post.cp.A.as_ref());
        let BK1 = &pre.cp.B * pre.K;
        let BK2 = &post.cp.B * pre.K;
        let a_pre = cross(roots, pre.cp.A.as_ref(), roots);
        let c = ExitConstants {
            dn,
            theta_eff,
            nu_min: theta_eff / s_late,
            s_late,
            c_id,
            c_A: cross(&post.lc.roots, pre.cp.A.as_ref(), roots),
            c_BK: cross(&post.lc.roots, BK1.as_ref(), roots),
            c_A2: cross(&post.lc.roots, post.cp.A.as_ref(), roots),
            c_BK2: cross(&post.lc.roots, BK2.as_ref(), roots),
            c_B: post.lc.roots.norm_into(pre.cp.B.as_ref()),
            c_B2: post.lc.roots.norm_into(post.cp.B.as_ref()),
            grow: (mu2.max(0.0) * h).exp(),
            t_A2: post
                .lc
                .roots
                .dual_norm(&mat_t_vec(post.cp.A.as_ref(), &exit.a)),
            t_BK2: roots.dual_norm(&mat_t_vec(BK2.as_ref(), &exit.a)),
            t_B2: mat_t_vec(post.cp.B.as_ref(), &exit.a)
                .iter()
                .map(|v| v * v)
                .sum::<f64>()
                .sqrt(),
            c_back,
            phi2: post.lc.phi,
            eps,
            delta_next,
            dt: h / (GRID - 1) as f64,
            a_pre,
            c_BK_pre: cross(roots, BK1.as_ref(), roots),
            c_B_pre: roots.norm_into(pre.cp.B.as_ref()),
        };
        let grid = Grid::new(&pre, &post, h);
        let metric2 = Metric {
            n,
            R: to_row_major(post.lc.P.as_ref()),
        };
        let target = &next.nominal.x[0];
        let next_unsafe = lp_of(i + 1).unsafe_set;
        // The nominal's flow within each period, at s = h − τ for the grid's τ, under the held input.
        let sub: Vec<Vec<Vec<f64>>> = (0..=rows)
            .map(|k| {
                let u = nom.u.get(k).or(nom.u.last()).expect("rows ≥ 1");
                (0..GRID)
                    .map(|j| {
                        let fx = mat_vec(grid.pre_Phi[j].as_ref(), &nom.x[k]);
                        let fu = mat_vec(grid.pre_GB[j].as_ref(), u);
                        (0..n).map(|q| fx[q] + fu[q] + grid.pre_Gc[j][q]).collect()
                    })
                    .collect()
            })
            .collect();
        // ‖fᵢ(x̃(κ), ũ(κ))‖_{Pᵢ} (the last sample with the last input), and ρκ = φ·that (0 at the last).
        let f_norm: Vec<f64> = (0..=rows)
            .map(|k| {
                let u = nom.u.get(k).or(nom.u.last()).expect("rows ≥ 1");
                p_norm(pre.lc.P.as_ref(), &pre.cp.f(&nom.x[k], u))
            })
            .collect();
        let rho: Vec<f64> = (0..=rows)
            .map(|k| {
                if k < rows {
                    pre.lc.phi * f_norm[k]
                } else {
                    0.0
                }
            })
            .collect();
        let speed: Vec<f64> = f_norm
            .iter()
            .zip(&rho)
            .map(|(f, r)| f + a_pre * r)
            .collect();
        let mut samples = ExitSamples {
            g: gs.clone(),
            rho,
            f_pre: (0..=rows)
                .map(|k| {
                    let u = nom.u.get(k).or(nom.u.last()).expect("rows ≥ 1");
                    p_norm(post.lc.P.as_ref(), &pre.cp.f(&nom.x[k], u))
                })
                .collect(),
            f_post: (0..=rows)
                .map(|k| {
                    let u = nom.u.get(k).or(nom.u.last()).expect("rows ≥ 1");
                    p_norm(post.lc.P.as_ref(), &post.cp.f(&nom.x[k], u))
                })
                .collect(),
            trans: (0..=rows)
                .map(|k| {
                    let u = nom.u.get(k).or(nom.u.last()).expect("rows ≥ 1");
                    dot(&exit.a, &post.cp.f(&nom.x[k], u))
                })
                .collect(),
            unsafe_next: (0..=rows)
                .map(|k| match next_unsafe {
                    Some(us) => -us.signed_dist(&nom.x[k], &metric2).value,
                    None => f64::INFINITY,
                })
                .collect(),
            sub_g: sub
                .iter()
                .map(|row| row.iter().map(|x| exit.g(x)).collect())
                .collect(),
            land: sub
                .iter()
                .enumerate()
                .map(|(k, row)| {
                    let u = nom.u.get(k).or(nom.u.last()).expect("rows ≥ 1");
                    let pinv_a = mat_vec(roots.inv.as_ref(), &exit.a);
                    row.iter()
                        .enumerate()
                        .map(|(j, x)| {
                            // p̂ₛ: the Pᵢ-projection of x̃(κ + s) onto the plane of G.
                            let t = exit.g(x) / (dn * dn);
                            let p: Vec<f64> = (0..n).map(|q| x[q] - t * pinv_a[q]).collect();
                            let fx = mat_vec(grid.Phi[j].as_ref(), &p);
                            let fu = mat_vec(grid.GB[j].as_ref(), u);
                            let e: Vec<f64> = (0..n)
                                .map(|q| fx[q] + fu[q] + grid.Gc[j][q] - target[q])
                                .collect();
                            p_norm(post.lc.P.as_ref(), &e)
                        })
                        .collect()
                })
                .collect(),
            speed,
            normal_reach,
            cells: Vec::new(),
            disturbed: {
                let per_step = (pre.lc.roots.norm_into(pre.lc.B.as_ref()) * eps
                    + pre.lc.mismatch_step())
                    * (1.0 + 1e-9);
                let mut sum = 0.0;
                let mut out = Vec::with_capacity(rows + 1);
                for &p in &power {
                    out.push(sum * per_step);
                    sum += p;
                }
                out
            },
            power,
        };
        // η (item 5) at the largest radius: L grows with r.
        let L_max = (0..rows)
            .map(|k| {
                let R = pre.inter(r_max, samples.rho[k], eps);
                let F_pre = samples.f_pre[k] + c.c_A * R + c.c_BK * r_max + c.c_B * eps;
                let F_post = samples.f_post[k] + c.c_A2 * R + c.c_BK2 * r_max + c.c_B2 * eps;
                c.grow * (F_pre + F_post)
            })
            .fold(0.0f64, f64::max);
        let eta = L_max * c.s_late * c.c_back;
        // Theorem 4.7's parts over the rows kept at r_max.
        let kf_max = (1..=rows)
            .find(|&k| gs[k] + samples.guard_reach(k, r_max, eta, dn) <= -theta_eff)
            .unwrap_or(rows);
        samples.cells = crossing_cells(
            &CellInputs {
                pre: &pre,
                post: &post,
                exit: &exit,
                nom,
                target,
                grid: &grid,
                sub: &sub,
                whitened: &whitened,
            },
            &samples,
            &c,
            r_max,
            eta,
            kf_max,
        );
        let kept = truncate(nom, kf_max);
        let base = certify_at(&lp_of(i), s.lc, &kept, GoalAt::Free(r_max));
        let parts = base.delta_unsafe_intersample.min(base.delta_input);
        let hi = (r_max.min(parts) - eta).max(0.0);
        let entry_ok = |r: f64| match &entries[i] {
            Some(entry) => check_entry(r, &pre, entry, &kept, kept.steps(), eps),
            None => true,
        };
        let ok = |r: f64| {
            matches!(
                check_exit(r, &pre, &c, &samples, &grid, eta),
                Verdict::Ok { .. }
            ) && entry_ok(r)
        };
        let r = bisect(hi, ok);
        let delta = if r > base.r_crit && r > 0.0 {
            r * (1.0 - 1e-9)
        } else {
            0.0
        };
        let binding = if delta == 0.0 {
            match check_exit(base.r_crit.max(1e-12), &pre, &c, &samples, &grid, eta) {
                Verdict::Fail(why) => why,
                Verdict::Ok { .. } if !entry_ok(base.r_crit.max(1e-12)) => {
                    "the entry window (the run must stay across the plane it entered by)"
                }
                _ => "Theorem 4.7 (Unsafe, Input) or r_crit",
            }
        } else if r >= hi * (1.0 - 1e-12) {
            if hi + eta >= r_max {
                "the search's upper end (LANDING_REACH times the next segment's ball, or the guard's depth)"
            } else {
                "Theorem 4.7 (Unsafe, Input)"
            }
        } else {
            match check_exit(hi, &pre, &c, &samples, &grid, eta) {
                Verdict::Fail(why) => why,
                _ => "the entry window (the run must stay across the plane it entered by)",
            }
        };
        let (kappa_f, events) = match check_exit(delta, &pre, &c, &samples, &grid, eta) {
            Verdict::Ok {
                kappa_f,
                first,
                last,
            } => (kappa_f, first.zip(last)),
            Verdict::Fail(_) => (rows, None),
        };
        let a32: Vec<f32> = exit.a.iter().map(|&v| v as f32).collect();
        certs.push(SegmentCertificate {
            base,
            delta,
            rows: kappa_f,
            samples: kappa_f,
            exit: Some(GuardExit {
                a: a32,
                b: exit.b as f32,
                theta,
            }),
            events,
            eta,
            binding,
        });
    }
    certs.reverse();
    let total: usize = certs.iter().map(|s| s.samples).sum();
    if total > steps {
        if let Some(first) = certs.first_mut() {
            first.delta = 0.0;
            first.binding =
                "the horizon: the slowest run's segments take more samples than T allows";
        }
    }
    let d0 = certs[0].delta;
    let delta_stored = super::selection_radius(segments[0].lp.P, &segments[0].nominal.x[0], d0);
    Ok(InternalCertificate {
        segments: certs,
        delta_stored,
    })
}
