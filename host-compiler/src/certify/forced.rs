//! Forced switching (§4.2.1, Def 4.15, Theorem 4.17): the certificate of a nominal run made of segments,
//! each in one location of a hybrid plant, joined by edges the controller takes when a segment's table
//! ends.
//!
//! Segment i runs in location ℓᵢ with its own shipped gain K̂ᵢ and metric Pᵢ. At its last sample Nᵢ the
//! controller takes edge eᵢ (guard Gᵢ, reset x ↦ Rᵢx + rᵢ), and segment i+1 starts from the reset of the
//! nominal state, x̃ᵢ₊₁(0) = Rᵢx̃ᵢ(Nᵢ) + rᵢ. The recursion runs backwards (Thm 4.17):
//!
//! * the last segment is certified against Goal, as a run of one location ([`super::certify`]);
//! * segment i < last is certified against its **safe transition**
//!   Sᵢ = Gᵢ ∩ {x : ‖Rᵢx + rᵢ − x̃ᵢ₊₁(0)‖_{Pᵢ₊₁} ≤ δᵢ₊₁} (OutputGuard ∩ OutputReset†(Bᵢ₊₁), Notation
//!   4.13), judged at the switching sample Nᵢ ([`super::GoalAt::Last`]). Its depth is δ_Guard, the
//!   depth of a point inside the reset preimage of the next ball: §7.2's inside problem for the
//!   ellipsoid {x : (x − c′)ᵀRᵀPᵢ₊₁R(x − c′) ≤ δᵢ₊₁²}, c′ = R⁻¹(x̃ᵢ₊₁(0) − r), and the depth in the guard's
//!   polytope; the depth in an intersection is the least of the two
//!   ([`crate::geometry::Intersection`]).
//!
//! Why this certifies the run: a state within δᵢ of x̃ᵢ(0) stays within δᵢ of the nominal in Pᵢ over the
//! segment (the single-location certificate, f32 rounding and all; a location's invariant is kept by
//! treating its outside as Unsafe), so at Nᵢ it is δᵢ-close to x̃ᵢ(Nᵢ),
//! which is δᵢ-deep in Sᵢ: the state is in the guard, and its reset lies in the ball certified for
//! segment i+1. Unsafe and the input set are checked over every segment's whole table. The switching
//! times of perturbed runs equal the nominal's (the controller switches by its table), so no event time
//! is uncertain. With identity resets and guards that are the whole space (Example 4.20) the depth is
//! δᵢ₊₁/√λmax(Pᵢ⁻¹Pᵢ₊₁), the largest Pᵢ-ball inside the Pᵢ₊₁-ball; a test holds the recursion to it.

use super::internal::{InternalCertificate, SegmentCertificate};
use super::{certify_at, Certificate, GoalAt, Loop, LoopConstants};
use crate::geometry::{
    Complement, Ellipsoid, Empty, GeometryError, Intersection, Metric, Polytope, Region, Witness,
};
use crate::linalg::to_row_major;
use crate::model::hybrid::{Edge, EdgeKind};
use crate::trajectory::Nominal;
use faer::linalg::solvers::Solve;
use faer::Mat;

/// One segment of a forced-switching run.
#[derive(Clone, Copy)]
pub struct ForcedSegment<'a> {
    /// The segment's loop: its location, shipped gain and metric, Unsafe and the input set. Its `goal` is
    /// the task's Goal, which only the last segment is judged against.
    pub lp: Loop<'a>,
    pub lc: &'a LoopConstants,
    pub nominal: &'a Nominal,
    /// The edge the controller takes at the segment's last sample; `None` for the last segment.
    pub switch: Option<&'a Edge>,
    /// The location's invariant, if it has one: the segment's tube must stay inside it, so leaving it
    /// counts as entering Unsafe.
    pub invariant: Option<&'a crate::model::hybrid::Polytope>,
}

/// The certificates of a forced-switching run, one per segment, first segment first. The run is
/// certified from the ball of radius `segments[0].delta` (stored as `segments[0].delta_stored`) around
/// the first segment's start.
#[derive(Clone, Debug, PartialEq)]
pub struct ForcedCertificate {
    pub segments: Vec<Certificate>,
}

impl ForcedCertificate {
    /// The certified radius of the ball of initial states.
    pub fn delta(&self) -> f64 {
        self.segments.first().map_or(0.0, |c| c.delta)
    }
    pub fn is_certified(&self) -> bool {
        self.segments.first().is_some_and(|c| c.is_certified())
    }

    /// A forced-switching certificate in the form the hybrid pipeline (image, cover, report) reads: a
    /// segment per location, each ending with its table (no guard exit, no event interval), every row kept.
    pub fn as_segments(&self, nominals: &[Nominal]) -> InternalCertificate {
        let last = self.segments.len().saturating_sub(1);
        let segments = self
            .segments
            .iter()
            .zip(nominals)
            .enumerate()
            .map(|(i, (c, nom))| SegmentCertificate {
                base: c.clone(),
                delta: c.delta,
                rows: nom.steps(),
                samples: nom.steps(),
                exit: None,
                events: None,
                eta: 0.0,
                binding: binding(c, i == last),
            })
            .collect();
        InternalCertificate {
            segments,
            delta_stored: self.segments.first().map_or(0.0, |c| c.delta_stored),
        }
    }
}

/// Why a run of segments is not a forced-switching run this module can certify.
#[derive(Debug, thiserror::Error)]
pub enum ForcedError {
    #[error("a forced-switching run needs at least one segment")]
    Empty,
    #[error("segment {segment} has no edge to the next segment")]
    MissingSwitch { segment: usize },
    #[error("the last segment ({segment}) has an edge after it")]
    SwitchAfterLast { segment: usize },
    #[error("segment {segment}'s edge is internal: only forced edges are taken by the controller (§4.2.1)")]
    NotForced { segment: usize },
    #[error(
        "segment {segment} runs in location {loc}, but its edge goes from location {from} to {to} \
         and the next segment runs in location {next}"
    )]
    Locations {
        segment: usize,
        loc: usize,
        from: usize,
        to: usize,
        next: usize,
    },
    #[error("segment {segment}'s nominal is empty")]
    EmptyNominal { segment: usize },
    #[error(
        "segment {segment} starts {gap:.3e} away from the reset of segment {prev}'s last state: the nominal \
         run is not continuous across the switch"
    )]
    Discontinuous {
        segment: usize,
        prev: usize,
        gap: f64,
    },
    #[error(
        "segment {segment}'s reset matrix is singular: its preimage of a ball is not an ellipsoid"
    )]
    SingularReset { segment: usize },
    #[error("the formula: {0}")]
    Formula(String),
    #[error("segment {segment}'s safe transition: {source}")]
    Geometry {
        segment: usize,
        #[source]
        source: GeometryError,
    },
}

/// Unsafe ∪ (ℝⁿ \\ invariant), over borrowed sets: the distance is the least of the two (exact); the
/// depth is the larger of the two depths (a lower bound, as for [`crate::geometry::Union`]).
struct UnsafeOrOutside<'a> {
    unsafe_set: Option<&'a dyn Region>,
    outside: Complement,
}

impl Region for UnsafeOrOutside<'_> {
    fn dim(&self) -> usize {
        self.outside.dim()
    }
    fn contains(&self, x: &[f64]) -> bool {
        self.outside.contains(x) || self.unsafe_set.is_some_and(|u| u.contains(x))
    }
    fn dist(&self, x: &[f64], metric: &Metric) -> Witness {
        let o = self.outside.dist(x, metric);
        match self.unsafe_set.map(|u| u.dist(x, metric)) {
            Some(u) if u.value < o.value => u,
            _ => o,
        }
    }
    fn depth(&self, x: &[f64], metric: &Metric) -> Witness {
        let o = self.outside.depth(x, metric);
        match self.unsafe_set.map(|u| u.depth(x, metric)) {
            Some(u) if u.value > o.value => u,
            _ => o,
        }
    }
}

/// The polytope of a guard or invariant as a geometry region.
fn region(p: &crate::model::hybrid::Polytope, n: usize) -> Result<Polytope, GeometryError> {
    let a: Vec<f64> = p.a.iter().flatten().copied().collect();
    Polytope::new(n, a, p.b.clone())
}

/// The safe transition of `edge` into the ball B_P(c, δ) (module doc).
fn safe_transition(
    segment: usize,
    edge: &Edge,
    P: faer::MatRef<'_, f64>,
    c: &[f64],
    delta: f64,
) -> Result<Box<dyn Region>, ForcedError> {
    let n = c.len();
    let geo = |source| ForcedError::Geometry { segment, source };
    let R = &edge.reset.R;
    // c′ = R⁻¹(c − r), checked by its residual (R invertible to working precision).
    let rhs = Mat::from_fn(n, 1, |i, _| c[i] - edge.reset.r[i]);
    let cp = R.full_piv_lu().solve(&rhs);
    let resid = (R * &cp - &rhs).norm_l2();
    let scale = 1.0 + rhs.norm_l2();
    let cp: Vec<f64> = (0..n).map(|i| cp[(i, 0)]).collect();
    if !(resid <= 1e-9 * scale) || cp.iter().any(|v| !v.is_finite()) {
        return Err(ForcedError::SingularReset { segment });
    }
    let Q = R.transpose() * P * R * (1.0 / (delta * delta));
    let ball =
        Ellipsoid::new(cp, to_row_major(crate::linalg::sym(Q.as_ref()).as_ref())).map_err(geo)?;
    if edge.guard.a.is_empty() {
        // A guard without rows is the whole space: the safe transition is the reset's preimage alone.
        return Ok(Box::new(ball));
    }
    let guard = region(&edge.guard, n).map_err(geo)?;
    Ok(Box::new(
        Intersection::new(vec![Box::new(guard), Box::new(ball)]).map_err(geo)?,
    ))
}

/// Theorem 4.17 for a run of segments (module doc): checks that the run is a forced-switching run
/// (edges forced, locations chained, the nominal continuous across each reset), then certifies the
/// segments backwards.
pub fn certify_forced(segments: &[ForcedSegment<'_>]) -> Result<ForcedCertificate, ForcedError> {
    let last = check_chain(segments)?;
    let guarded = guarded_unsafe(segments)?;
    let lp_of = |i: usize| lp_with_invariant(segments, &guarded, i);
    let mut certs: Vec<Certificate> = Vec::with_capacity(segments.len());
    let last_cert = certify_at(
        &lp_of(last),
        segments[last].lc,
        segments[last].nominal,
        GoalAt::Best,
    );
    certs.push(last_cert);
    for i in (0..last).rev() {
        let next_delta = certs.last().expect("one per later segment").delta;
        certs.push(certify_switching(segments, &lp_of(i), i, next_delta)?);
    }
    certs.reverse();
    Ok(ForcedCertificate { segments: certs })
}

/// The certificate of a forced-switching run for an MTL task (Def 4.18, Theorem 4.19), sampled and in
/// f32 ([`certify_forced_formula`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ForcedFormulaCertificate {
    /// Each segment's certificate with its radius rᵢ as `delta` (the first one's stored radius is the
    /// ball's).
    pub base: ForcedCertificate,
    /// ρ(0) of the whole nominal run at the samples, every atom in the first segment's metric.
    pub delta_samples: f64,
    /// The largest bound t the formula admits: rᵢ = min(t, the segment's own δ).
    pub t: f64,
    /// Whether each segment's radius is the formula's bound t rather than its own parts.
    pub formula_bound: Vec<bool>,
    /// ρ(κ) of the whole run at every sample, and where ρ(0) comes from (set, sample, negated).
    pub signal: Vec<f64>,
    pub critical: Option<(String, usize, bool)>,
}

/// Grid of the formula bound t over (0, ρ(0)] before the bisection ([`certify_forced_formula`]).
const FORMULA_GRID: usize = 32;
/// Bisection steps after the grid.
const FORMULA_BISECTION: usize = 40;

/// Def 4.18 and Theorem 4.19 for the sampled f32 loop: a forced-switching run certified for an MTL
/// formula.
///
/// The text sets δ⁽ᴺ⁾ = δ_φ and δ⁽ⁱ⁾ = min(δ_φ, δ_Guard⁽ⁱ⁾), with the atoms of δ_φ measured in each
/// segment's own metric ψᵢ. Here the atoms are measured in one metric, the first segment's P₀ (bound once,
/// as [`crate::certify::temporal`] does for one location), and the segments' tubes are carried into it:
/// ‖e‖_{P₀} ≤ cᵢ‖e‖_{Pᵢ} with cᵢ = ‖P₀^{1/2}Pᵢ^{-1/2}‖₂. For a bound t, the radii are chosen backwards:
/// the last segment's rᴺ = min(t, its Unsafe (invariant included) and input parts, above r_crit)
/// ([`GoalAt::Free`]), and each earlier rᵢ = min(t, its certificate against the safe transition into the
/// ball of radius rᵢ₊₁), so Lemma 4.16's chain holds as in [`certify_forced`]. Every run from the first
/// ball then stays, at the samples of segment i, within cᵢrᵢ of the nominal in P₀, and between samples
/// within cᵢ(γᵢrᵢ + φᵢ‖fₖ‖_{Pᵢ} + φᵢβᵢε̄ᵢ) of the sample before (and, for an atom whose set is a union of
/// convex pieces, at least min_j (base_j − slope_j·cᵢ(γᵢrᵢ + φᵢβᵢε̄ᵢ)) from it, the directional bound of
/// [`super::pieces`] taken in P₀ with segment i's plant); the formula holds for it when ρ(0) of the
/// concatenated nominal exceeds maxᵢ cᵢrᵢ (the samples) and the tube's lower bound
/// ([`crate::robustness::mtl::TubeFormula`]) with those margins is positive (between samples). Both
/// margins grow with t; the largest admitted t is sought on a grid and refined by bisection, keeping only
/// admitted points, and the run is certified from the ball of radius r₀. The input set is each segment's
/// Theorem 4.7 part (4.15). The concatenated run puts the switching sample in the next segment, which is
/// the state itself only for identity resets: an edge with another reset is refused.
pub fn certify_forced_formula(
    segments: &[ForcedSegment<'_>],
    task: &crate::property::TemporalTask,
) -> Result<ForcedFormulaCertificate, ForcedError> {
    use super::pieces::PieceClearance;
    use crate::robustness::mtl::{Margins, Trace, TubeFormula};
    let formula = |e: String| ForcedError::Formula(e);
    let last = check_chain(segments)?;
    if let Some(i) = segments
        .iter()
        .position(|s| s.switch.is_some_and(|e| !e.reset.is_identity()))
    {
        return Err(formula(format!(
            "segment {i}'s edge resets the state: the formula is judged on one state trajectory, so only \
             identity resets are taken"
        )));
    }
    let guarded = guarded_unsafe(segments)?;
    let lp_of = |i: usize| lp_with_invariant(segments, &guarded, i);
    let tl = crate::certify::temporal::TemporalLoop::new(task, &segments[0].lp)
        .map_err(|e| formula(e.to_string()))?;
    // The concatenated run: every segment's samples but its last (the next segment starts there, reset by
    // the identity), then the whole last segment; `at[k]` = (segment, its own sample).
    let mut at: Vec<(usize, usize)> = Vec::new();
    for (i, s) in segments.iter().enumerate() {
        let take = s.nominal.x.len() - usize::from(i != last);
        at.extend((0..take).map(|k| (i, k)));
    }
    let h = segments[0].lp.plant.period();
    let n = segments[0].lp.P.nrows();
    let times: Vec<f64> = (0..at.len()).map(|k| k as f64 * h).collect();
    let cols: Vec<Vec<f64>> = (0..n)
        .map(|j| {
            at.iter()
                .map(|&(i, k)| segments[i].nominal.x[k][j])
                .collect()
        })
        .collect();
    let trace =
        Trace::new(times, tl.signals().to_vec(), cols).map_err(|e| formula(e.to_string()))?;
    let monitor = tl.monitor().map_err(|e| formula(e.to_string()))?;
    let signal = monitor
        .robustness(&trace)
        .map_err(|e| formula(e.to_string()))?;
    let tube = TubeFormula::new(&monitor, &trace).map_err(|e| formula(e.to_string()))?;
    let rho0 = signal[0];
    let critical = tube
        .critical(rho0)
        .first()
        .map(|(s, k, neg)| (s.name.clone(), *k, *neg));
    // cᵢ, rounded up.
    let c: Vec<f64> = segments
        .iter()
        .map(|s| segments[0].lc.roots.norm_into(s.lc.roots.inv_sqrt.as_ref()) * (1.0 + 1e-9))
        .collect();
    // φᵢ‖fₖ‖_{Pᵢ} at every sample that applies an input (none for discrete-time plants).
    let continuous = segments.iter().all(|s| s.lp.continuous().is_some());
    let drift: Vec<f64> = at[..at.len() - 1]
        .iter()
        .map(|&(i, k)| {
            let s = &segments[i];
            let f =
                s.lp.plant
                    .vector_field(s.lp.loc, &s.nominal.x[k], &s.nominal.u[k])
                    .unwrap_or_else(|| vec![f64::INFINITY; n]);
            s.lc.phi * crate::linalg::p_norm(s.lp.P, &f)
        })
        .collect();
    // Each set atom's convex pieces between samples, in P₀ (`certify::pieces`' module doc, "Between
    // samples along a direction", taken in P₀ for segment i's plant: its φ and ‖A‖ in P₀, and a deviation
    // from the nominal's held flow of at most cᵢ(γᵢrᵢ + held) there).
    let metric0 = crate::geometry::Metric {
        n,
        R: crate::linalg::to_row_major(segments[0].lp.P),
    };
    let roots0 = &segments[0].lc.roots;
    let seg_consts: Vec<Option<(f64, f64)>> = segments
        .iter()
        .map(|s| {
            let cp = s.lp.continuous()?;
            let (phi0, _) = crate::certify::intersample_phi_beta(roots0, cp, s.lp.plant.period());
            Some((phi0, roots0.induced_norm(cp.A.as_ref()) * (1.0 + 1e-9)))
        })
        .collect();
    let pieces: Vec<Option<Vec<Option<Vec<PieceClearance>>>>> = if continuous {
        tube.atom_sets()
            .into_iter()
            .map(|set| {
                let set = set?;
                set.region.convex_pieces()?;
                Some(
                    at[..at.len() - 1]
                        .iter()
                        .map(|&(i, k)| {
                            let sg = &segments[i];
                            let cp = sg.lp.continuous()?;
                            let (phi0, a0) = seg_consts[i]?;
                            let f = sg.lp.plant.vector_field(
                                sg.lp.loc,
                                &sg.nominal.x[k],
                                &sg.nominal.u[k],
                            )?;
                            crate::certify::pieces::piece_clearances(
                                set.region.as_ref(),
                                &metric0,
                                segments[0].lp.P,
                                roots0,
                                cp.A.as_ref(),
                                a0,
                                sg.lp.plant.period(),
                                phi0,
                                &sg.nominal.x[k],
                                &f,
                            )
                        })
                        .collect(),
                )
            })
            .collect()
    } else {
        Vec::new()
    };
    // The radii for a bound t, backwards, with each segment's certificate.
    let radii = |t: f64| -> Result<(Vec<f64>, Vec<Certificate>), ForcedError> {
        let mut r = vec![0.0; segments.len()];
        let mut certs = Vec::with_capacity(segments.len());
        let s = &segments[last];
        let cert = certify_at(&lp_of(last), s.lc, s.nominal, GoalAt::Free(t));
        r[last] = cert.delta;
        certs.push(cert);
        for i in (0..last).rev() {
            let cert = certify_switching(segments, &lp_of(i), i, r[i + 1])?;
            let ri = cert.delta.min(t);
            r[i] = if ri > 0.0 && ri > cert.r_crit {
                ri
            } else {
                0.0
            };
            certs.push(cert);
        }
        certs.reverse();
        Ok((r, certs))
    };
    let admits = |r: &[f64], certs: &[Certificate]| -> bool {
        if !(r[0] > 0.0) {
            return false;
        }
        let reach = r.iter().zip(&c).map(|(r, c)| r * c).fold(0.0, f64::max);
        if !(rho0 > reach * (1.0 + 1e-9)) {
            return false;
        }
        if !continuous {
            return true;
        }
        let between: Vec<f64> = at[..at.len() - 1]
            .iter()
            .zip(&drift)
            .map(|(&(i, _), d)| {
                let lc = segments[i].lc;
                c[i] * (lc.gamma * r[i] + d + lc.held_disturbance(certs[i].eps_f32))
            })
            .collect();
        // The deviation from the nominal's held flow over each interval, in P₀.
        let w: Vec<f64> = at[..at.len() - 1]
            .iter()
            .map(|&(i, _)| {
                let lc = segments[i].lc;
                c[i] * (lc.gamma * r[i] + lc.held_disturbance(certs[i].eps_f32))
            })
            .collect();
        let clear: Vec<Option<Vec<f64>>> = pieces
            .iter()
            .map(|p| {
                p.as_ref()
                    .map(|per_k| super::pieces::least_clearances(per_k, w.iter().copied()))
            })
            .collect();
        tube.lower_at_start_with(
            &Margins {
                r: reach,
                between: &between,
            },
            &clear,
        ) > 0.0
    };
    let mut best: Option<(f64, Vec<f64>, Vec<Certificate>)> = None;
    if rho0 > 0.0 && rho0.is_finite() {
        let mut infeasible = f64::NAN;
        for j in (1..=FORMULA_GRID).rev() {
            let t = rho0 * j as f64 / FORMULA_GRID as f64;
            let (r, certs) = radii(t)?;
            if admits(&r, &certs) {
                best = Some((t, r, certs));
                break;
            }
            infeasible = t;
        }
        if let Some((lo, ..)) = &best {
            let (mut lo, mut hi) = (*lo, infeasible);
            if hi.is_finite() {
                for _ in 0..FORMULA_BISECTION {
                    let mid = 0.5 * (lo + hi);
                    let (r, certs) = radii(mid)?;
                    if admits(&r, &certs) {
                        lo = mid;
                        best = Some((mid, r, certs));
                    } else {
                        hi = mid;
                    }
                }
            }
        }
    }
    let (t, r, mut certs) = match best {
        Some(b) => b,
        None => {
            let (_, certs) = radii(rho0.max(0.0))?;
            (0.0, vec![0.0; segments.len()], certs)
        }
    };
    let formula_bound = r
        .iter()
        .map(|&ri| ri > 0.0 && ri >= t * (1.0 - 1e-8))
        .collect();
    for ((cert, &ri), s) in certs.iter_mut().zip(&r).zip(segments) {
        cert.delta = ri;
        cert.delta_stored = crate::certify::selection_radius(s.lp.P, &s.nominal.x[0], ri);
    }
    Ok(ForcedFormulaCertificate {
        base: ForcedCertificate { segments: certs },
        delta_samples: rho0,
        t,
        formula_bound,
        signal,
        critical,
    })
}

/// Runs `f` on the loop segment `i` of a forced-switching run is certified in by [`certify_forced`]: the
/// task's Unsafe with the outside of the location's invariant, and as its goal the safe transition into
/// segment i+1's ball of radius `next_delta` around its start (Goal itself for the last segment). The
/// optimiser (§5.3 over a run's segments) maximises δ in exactly this loop. The run must be a
/// forced-switching run ([`certify_forced`]'s checks).
pub fn with_segment_loop<R>(
    segments: &[ForcedSegment<'_>],
    i: usize,
    next_delta: f64,
    f: impl FnOnce(&Loop<'_>) -> R,
) -> Result<R, ForcedError> {
    let last = check_chain(segments)?;
    let guarded = guarded_unsafe(segments)?;
    let lp = lp_with_invariant(segments, &guarded, i.min(last));
    if i >= last {
        return Ok(f(&lp));
    }
    let target = transition_target(segments, i, next_delta)?;
    Ok(f(&Loop {
        goal: target.as_ref(),
        ..lp
    }))
}

/// Segment `i < last`'s target: the safe transition into the next segment's ball of radius
/// `next_delta` (an empty target when that ball is empty).
fn transition_target(
    segments: &[ForcedSegment<'_>],
    i: usize,
    next_delta: f64,
) -> Result<Box<dyn Region>, ForcedError> {
    let s = &segments[i];
    let next = &segments[i + 1];
    let edge = s.switch.expect("checked by check_chain");
    Ok(if next_delta > 0.0 {
        safe_transition(i, edge, next.lp.P, &next.nominal.x[0], next_delta)?
    } else {
        Box::new(Empty(s.lp.P.nrows()))
    })
}

/// Segment `i < last` certified against its safe transition into the next segment's ball of radius
/// `next_delta`, judged at its last sample (an empty target when that ball is empty).
fn certify_switching(
    segments: &[ForcedSegment<'_>],
    lp: &Loop<'_>,
    i: usize,
    next_delta: f64,
) -> Result<Certificate, ForcedError> {
    let s = &segments[i];
    let target = transition_target(segments, i, next_delta)?;
    let lp = Loop {
        goal: target.as_ref(),
        ..*lp
    };
    Ok(certify_at(&lp, s.lc, s.nominal, GoalAt::Last))
}

/// Checks that the segments are a forced-switching run (edges forced, locations chained, the nominal
/// continuous across each reset); the index of the last segment.
fn check_chain(segments: &[ForcedSegment<'_>]) -> Result<usize, ForcedError> {
    let last = segments.len().checked_sub(1).ok_or(ForcedError::Empty)?;
    for (i, s) in segments.iter().enumerate() {
        if s.nominal.x.is_empty() {
            return Err(ForcedError::EmptyNominal { segment: i });
        }
        match (s.switch, i == last) {
            (Some(_), true) => return Err(ForcedError::SwitchAfterLast { segment: i }),
            (None, false) => return Err(ForcedError::MissingSwitch { segment: i }),
            (None, true) => {}
            (Some(e), false) => {
                if e.kind != EdgeKind::Forced {
                    return Err(ForcedError::NotForced { segment: i });
                }
                let next = &segments[i + 1];
                if e.from != s.lp.loc || e.to != next.lp.loc {
                    return Err(ForcedError::Locations {
                        segment: i,
                        loc: s.lp.loc,
                        from: e.from,
                        to: e.to,
                        next: next.lp.loc,
                    });
                }
                let end = s.nominal.x.last().expect("checked non-empty");
                let start = next
                    .nominal
                    .x
                    .first()
                    .ok_or(ForcedError::EmptyNominal { segment: i + 1 })?;
                let gap = e
                    .reset
                    .apply(end)
                    .iter()
                    .zip(start)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f64>()
                    .sqrt();
                let scale = 1.0 + start.iter().map(|v| v * v).sum::<f64>().sqrt();
                if !(gap <= 1e-9 * scale) {
                    return Err(ForcedError::Discontinuous {
                        segment: i + 1,
                        prev: i,
                        gap,
                    });
                }
            }
        }
    }
    Ok(last)
}

/// Each segment's Unsafe, with the outside of its location's invariant added.
fn guarded_unsafe<'a>(
    segments: &[ForcedSegment<'a>],
) -> Result<Vec<Option<UnsafeOrOutside<'a>>>, ForcedError> {
    segments
        .iter()
        .enumerate()
        .map(|(i, s)| {
            s.invariant
                .map(|inv| {
                    let n = s.lp.P.nrows();
                    let inside = region(inv, n)
                        .map_err(|source| ForcedError::Geometry { segment: i, source })?;
                    let outside = Complement::new(Box::new(inside))
                        .map_err(|source| ForcedError::Geometry { segment: i, source })?;
                    Ok(UnsafeOrOutside {
                        unsafe_set: s.lp.unsafe_set,
                        outside,
                    })
                })
                .transpose()
        })
        .collect()
}

/// Segment `i`'s loop with its Unsafe widened by the outside of its invariant.
fn lp_with_invariant<'s>(
    segments: &[ForcedSegment<'s>],
    guarded: &'s [Option<UnsafeOrOutside<'s>>],
    i: usize,
) -> Loop<'s> {
    match &guarded[i] {
        Some(g) => Loop {
            unsafe_set: Some(g as &dyn Region),
            ..segments[i].lp
        },
        None => segments[i].lp,
    }
}

/// What limits a segment's δ, in words.
fn binding(c: &Certificate, last: bool) -> &'static str {
    let parts = [c.delta_goal, c.delta_unsafe_intersample, c.delta_input];
    let least = parts.iter().copied().fold(f64::INFINITY, f64::min);
    if c.delta <= 0.0 && least > 0.0 {
        "the f32 rounding bound (r_crit)"
    } else if least == c.delta_goal {
        if last {
            "Goal (Theorem 4.7)"
        } else {
            "the safe transition into the next segment's ball (Theorem 4.17)"
        }
    } else if least == c.delta_unsafe_intersample {
        "Unsafe, between samples (Theorem 4.7)"
    } else {
        "the input set (Theorem 4.7)"
    }
}
