//! Synthesis for hybrid plants with internal switching (§4.2.2, Examples 4.25, 5.5, 5.6): the task, the
//! location path, nominal runs (one extended segment per location, Def 4.22), their certificate
//! ([`crate::certify::internal`]) and the cover of Init by their balls (Algorithm 1 with the generator
//! from uncovered samples). An automaton whose edges are all forced is planned by [`forced`] instead
//! (§4.2.1: each run chooses its locations), through the same growth, image and verification.
//!
//! **A nominal run.** The path is the shortest chain of internal edges from the initial location to a
//! location whose invariant holds Goal's centre. Each segment but the last is generated in its location
//! with the SCP generator ([`crate::trajectory::generate`]) towards "the guard, d deep" (d from [`GUARD_DEPTHS`])
//! (the half-space shifted into the guard), which continues the segment past the plane far enough that
//! its tube lies inside the guard (the extended segment). The nominal hybrid run itself, flowing exactly
//! across the event ([`Hybrid::flow`]), gives the next segment's start: the first sample after its own
//! switch. The last segment is generated from there to Goal. Segment lengths are searched over a few
//! durations; the run with the largest certified δ is kept, and optimised (§5.3, [`optimise`]: the
//! tables before the last segment and the later starts by a derivative-free search on the certificate,
//! the last segment against Goal by the bundle method).
//!
//! **Recorded runs.** A person's recording (`synth --import`, `host-compiler play`) is replayed on the
//! automaton, split at its events into the path's segments and certified by the same [`certify_run`]
//! ([`import`]); an accepted one joins the runs through the same accept test ([`admit`]) before the
//! growth starts.
//!
//! **Routes.** Once a round certifies no run, a seed the other sources give nothing from asks the routes
//! of the global search through the guards ([`route`]: a route from the seed to Goal split where it
//! enters each guard, each piece a segment's first linearisation point), which reach classes the
//! planner's first iterate does not (Example 5.6's runs under the wall).

use crate::caf::{design_locations, Design};
use crate::certify::internal::{certify_internal, InternalCertificate, InternalSegment};
use crate::certify::{Loop, LoopConstants};
use crate::cover::seeds::{Ask, Origin, Proposal, RouteSearch, Routing, Seed, Source, Sources};
use crate::model::hybrid::{EdgeKind, Hybrid, HybridError};
use crate::model::Location;
use crate::property::{input_scale, ConvexPiece, ConvexSets, PropertyError, ReachAvoid};
use crate::spec::Problem;
use crate::synth::Generator;
use crate::trajectory::generate::{generate, generate_from, GenProblem, GenSettings};
use crate::trajectory::Nominal;
use faer::Mat;

pub mod forced;
pub mod import;
pub mod optimise;
pub mod reach;
pub mod route;
pub mod schedule;

/// How far past a guard's plane (Euclidean) a non-last segment's generated nominal must end: each is
/// tried (a deeper target makes the nominal cross the plane more steeply, so that the tube's crossing
/// points spread less; a location may not reach the deeper ones).
pub const GUARD_DEPTHS: [f64; 3] = [0.05, 0.2, 0.45];
/// Segment durations tried, as fractions of the horizon T. The short ones matter where the location's
/// own flow past the guard runs into Unsafe (Example 5.5: the left location's equilibria for |u| ≤ 3 lie
/// inside the wall), so the extended segment must end soon after its crossing.
pub const DURATIONS: [f64; 6] = [0.04, 0.05, 0.07, 0.1, 0.2, 0.35];
/// The tolerance of the KKT solves' iterative refinement in the planner's generator calls
/// ([`GenSettings::refinement_tol`]).
pub const PLAN_REFINEMENT_TOL: f64 = 1e-10;
/// The last segment's duration at most, as a fraction of T (what is left of T after the earlier
/// segments, if less).
pub const LAST_DURATION: f64 = 0.4;

/// A hybrid task, built once from a validated spec: the automaton, the reach-avoid property, a CAF and
/// shipped gain per location.
pub struct HybridTask {
    pub problem: Problem,
    pub plant: Hybrid,
    pub property: ReachAvoid,
    pub convex: ConvexSets,
    pub steps: usize,
    pub designs: Vec<Design>,
    pub constants: Vec<LoopConstants>,
    /// The initial location.
    pub initial: Location,
    /// The location path and the edges between them (internal switching); for forced switching the
    /// initial location alone and no edges: each run chooses its own locations ([`forced`]).
    pub path: Vec<Location>,
    pub edges: Vec<usize>,
    /// Whether the automaton's edges are forced (§4.2.1) rather than internal (§4.2.2).
    pub forced: bool,
    /// The spec's `[mtl]` formula, when the task is one (Problem 2.28): forced runs are then certified
    /// for it (Def 4.18, [`crate::certify::forced::certify_forced_formula`]) and judged by it.
    pub formula: Option<crate::property::TemporalTask>,
}

/// Why a hybrid task could not be built or a run planned.
#[derive(Debug, thiserror::Error)]
pub enum HybridSynthError {
    #[error("the spec has no hybrid automaton")]
    NotHybrid,
    #[error("plant: {0}")]
    Model(#[from] HybridError),
    #[error("sets: {0}")]
    Property(#[from] PropertyError),
    #[error("location {loc} ({name}) has no CAF and feedback: {reason}")]
    Caf {
        loc: Location,
        name: String,
        reason: String,
    },
    #[error("location {loc}: {reason}")]
    Certify { loc: Location, reason: String },
    #[error("no chain of internal edges leads from the initial location {from} to a location whose invariant holds Goal's centre")]
    NoPath { from: String },
    #[error("edges {internal} (internal) and {forced} (forced): an automaton with both kinds is not synthesised")]
    MixedEdges { internal: usize, forced: usize },
    #[error(
        "forced edge {edge} has a reset other than the identity: the controller measures the state before \
         the switch and would apply the next segment's law to the state before its reset"
    )]
    ForcedReset { edge: usize },
    #[error(
        "an [mtl] formula on an automaton with internal switching is not synthesised: the text leaves MTL \
         with general switching open (§4.2.2); forced switching (Def 4.18) is, and reach-avoid without \
         [mtl] is"
    )]
    FormulaWithInternal,
    #[error("[mtl]: {0}")]
    Formula(#[from] crate::property::TemporalError),
    #[error("{0}")]
    Run(String),
    /// No run can reach Goal (`reach`), found before any planning.
    #[error("goal is unreachable: {0}")]
    Unreachable(reach::Unreachable),
}

impl HybridTask {
    pub fn new(problem: Problem) -> Result<Self, HybridSynthError> {
        let desc = problem.hybrid.as_ref().ok_or(HybridSynthError::NotHybrid)?;
        let plant = Hybrid::from_spec(desc, problem.plant.period)?;
        let initial = desc.initial;
        let property = ReachAvoid::from_problem(&problem)?;
        let convex = ConvexSets::from_problem(&problem)?;
        let steps = problem.horizon_steps();
        let designs =
            design_locations(&plant, problem.synthesis.sigma_margin).map_err(|(loc, e)| {
                HybridSynthError::Caf {
                    loc,
                    name: plant.modes()[loc].name.clone(),
                    reason: e.to_string(),
                }
            })?;
        let mut constants = Vec::with_capacity(designs.len());
        for (loc, d) in designs.iter().enumerate() {
            let lp = Loop::reach_avoid(&plant, loc, d, &property);
            constants.push(
                LoopConstants::new(&lp).map_err(|e| HybridSynthError::Certify {
                    loc,
                    reason: e.to_string(),
                })?,
            );
        }
        let kind_of = |k: EdgeKind| plant.edges().iter().position(|e| e.kind == k);
        let forced = match (kind_of(EdgeKind::Internal), kind_of(EdgeKind::Forced)) {
            (Some(internal), Some(forced)) => {
                return Err(HybridSynthError::MixedEdges { internal, forced })
            }
            (_, f) => f.is_some(),
        };
        if forced {
            if let Some(edge) = plant.edges().iter().position(|e| !e.reset.is_identity()) {
                return Err(HybridSynthError::ForcedReset { edge });
            }
        }
        if forced && problem.mtl.is_none() {
            if let Some(why) = reach::goal_unreachable(
                &plant,
                initial,
                &problem.init,
                &problem.input,
                &problem.goal,
                steps,
            ) {
                return Err(HybridSynthError::Unreachable(why));
            }
        }
        let formula = match (&problem.mtl, forced) {
            (None, _) => None,
            (Some(_), false) => return Err(HybridSynthError::FormulaWithInternal),
            (Some(_), true) => Some(crate::property::TemporalTask::from_problem(&problem)?),
        };
        let (path, edges) = if forced {
            (vec![initial], Vec::new())
        } else {
            location_path(&plant, initial, goal_centre(&convex)).ok_or_else(|| {
                HybridSynthError::NoPath {
                    from: plant.modes()[initial].name.clone(),
                }
            })?
        };
        Ok(Self {
            problem,
            plant,
            property,
            convex,
            steps,
            designs,
            constants,
            initial,
            path,
            edges,
            forced,
            formula,
        })
    }

    /// How runs switch, in words: the location path (internal switching), or the controller's choice
    /// from the initial location (forced switching).
    pub fn route(&self) -> String {
        let name = |l: Location| self.plant.modes()[l].name.as_str();
        if self.forced {
            format!(
                "from {} through the locations each run's schedule chooses (forced switching)",
                name(self.initial)
            )
        } else {
            let path: Vec<&str> = self.path.iter().map(|&l| name(l)).collect();
            format!("{} (internal switching)", path.join(" → "))
        }
    }

    /// The loop of location `loc` with the task's sets.
    pub fn lp(&self, loc: Location) -> Loop<'_> {
        Loop::reach_avoid(&self.plant, loc, &self.designs[loc], &self.property)
    }
}

/// A point of Goal (its centre, or the Chebyshev-like centre of a box given as a polytope).
fn goal_centre(convex: &ConvexSets) -> Option<Vec<f64>> {
    match &convex.goal {
        ConvexPiece::Ellipsoid { C, c, .. } if C.nrows() == C.ncols() => Some(c.clone()),
        _ => None,
    }
}

/// Shortest chain of internal edges from `from` to a location whose invariant holds `goal` (breadth
/// first, edges in spec order; without a point of Goal, the initial location itself).
fn location_path(
    plant: &Hybrid,
    from: Location,
    goal: Option<Vec<f64>>,
) -> Option<(Vec<Location>, Vec<usize>)> {
    let holds = |loc: Location| match (&goal, &plant.modes()[loc].invariant) {
        (Some(g), Some(inv)) => inv.contains(g),
        _ => true,
    };
    let k = plant.modes().len();
    let mut prev: Vec<Option<(Location, usize)>> = vec![None; k];
    let mut seen = vec![false; k];
    let mut queue = std::collections::VecDeque::from([from]);
    seen[from] = true;
    while let Some(l) = queue.pop_front() {
        if holds(l) {
            let (mut path, mut edges) = (vec![l], vec![]);
            let mut cur = l;
            while let Some((p, e)) = prev[cur] {
                path.push(p);
                edges.push(e);
                cur = p;
            }
            path.reverse();
            edges.reverse();
            return Some((path, edges));
        }
        for (e, edge) in plant.edges().iter().enumerate() {
            if edge.from == l && edge.kind == EdgeKind::Internal && !seen[edge.to] {
                seen[edge.to] = true;
                prev[edge.to] = Some((l, e));
                queue.push_back(edge.to);
            }
        }
    }
    None
}

/// A planned, certified nominal run.
#[derive(Clone, Debug)]
pub struct HybridRun {
    /// One nominal per segment, the reference tables as shipped (f32 values).
    pub nominals: Vec<Nominal>,
    /// The location of each segment (the task's path for internal switching; the run's own choice for
    /// forced switching).
    pub locations: Vec<Location>,
    pub certificate: InternalCertificate,
}

impl HybridRun {
    pub fn delta(&self) -> f64 {
        self.certificate.delta()
    }
    /// The table rows the image keeps for this run (each segment's certified rows).
    pub fn rows(&self) -> usize {
        self.certificate.segments.iter().map(|c| c.rows).sum()
    }
}

/// A start the image stores, rounded to f32: a run's first ball centre, or a later segment's start. The
/// re-proof from the bytes simulates from the stored f32 point, so the segment certified here must start
/// there too; from an f64 point the two nominals differ by the rounding, which moves a small δ by more
/// than the re-proof's tolerance.
pub fn f32_start(x0: &[f64]) -> Vec<f64> {
    x0.iter().map(|&v| crate::linalg::round32(v)).collect()
}

/// The nominal of location `loc`'s loop from `x0` under `v` rounded to f32 (what ships).
pub fn shipped_nominal(task: &HybridTask, loc: Location, x0: &[f64], v: &[Vec<f64>]) -> Nominal {
    let v32: Vec<Vec<f64>> = v
        .iter()
        .map(|r| r.iter().map(|&a| a as f32 as f64).collect())
        .collect();
    task.lp(loc).simulate(x0, &v32)
}

/// Certify a run of nominals along the task's path.
pub fn certify_run(task: &HybridTask, nominals: &[Nominal]) -> Result<InternalCertificate, String> {
    let segs: Vec<InternalSegment> = task
        .path
        .iter()
        .zip(nominals)
        .map(|(&loc, nom)| InternalSegment {
            lp: task.lp(loc),
            lc: &task.constants[loc],
            nominal: nom,
            theta_stored: None,
        })
        .collect();
    certify_internal(&task.plant, &segs, &task.edges, task.steps).map_err(|e| e.to_string())
}

/// Where the next segment starts: the centre of the states at which runs near the nominal are first
/// sampled after their switch across `edge`. The nominal hybrid run (flowing segment `nom`'s inputs
/// exactly) switches in some period κₑ; runs near it switch in κₑ or κₑ + 1 at any time s of the period,
/// and land at x(h; s) = flow of the next location over h − s after the flow of this one over s. The
/// start is the mean of those landings over a grid of s (the certificate's landing ball is then as
/// central as the nominal allows). `None` if the nominal never switches within the segment.
fn landing(task: &HybridTask, loc: Location, nom: &Nominal, edge: usize) -> Option<Vec<f64>> {
    let mut x = nom.x[0].clone();
    let mut ke = None;
    for (k, u) in nom.u.iter().enumerate() {
        let step = task.plant.flow(loc, &x, u).ok()?;
        if let Some(ev) = step.events.first() {
            if ev.edge != edge {
                return None;
            }
            ke = Some(k);
            break;
        }
        x = step.x;
    }
    let ke = ke?;
    let h = task.plant.period();
    let (pre, post) = (
        &task.plant.modes()[loc].flow,
        &task.plant.modes()[task.plant.edges()[edge].to].flow,
    );
    let n = x.len();
    let mut sum = vec![0.0; n];
    let mut count = 0usize;
    for k in ke..(ke + 2).min(nom.u.len()) {
        for j in 0..=8 {
            let s = h * j as f64 / 8.0;
            let xs = if s > 0.0 {
                pre.zoh(s).ok()?.step(&nom.x[k], &nom.u[k])
            } else {
                nom.x[k].clone()
            };
            let xh = if s < h {
                post.zoh(h - s).ok()?.step(&xs, &nom.u[k])
            } else {
                xs
            };
            for (a, b) in sum.iter_mut().zip(&xh) {
                *a += b;
            }
            count += 1;
        }
    }
    Some(sum.into_iter().map(|v| v / count as f64).collect())
}

/// Generator problem for location `loc` with Goal replaced by `goal` and `steps` samples.
fn gen_problem<'a>(
    task: &'a HybridTask,
    loc: Location,
    convex: &'a ConvexSets,
    steps: usize,
) -> GenProblem<'a> {
    let lc = &task.constants[loc];
    GenProblem {
        loc,
        plant: &task.plant,
        K: task.designs[loc].K.as_ref(),
        P: task.designs[loc].P.as_ref(),
        property: &task.property,
        convex,
        steps,
        gamma: lc.gamma,
        phi: lc.phi,
        beta: lc.beta,
        input_margin: 1e-5 * input_scale(&task.property.input),
        schedule: None,
    }
}

/// Plan and certify a run from `x0` (module doc); the best over the durations tried, then optimised
/// (§5.3, [`optimise`], with half the spec's `max_iterations` per search), or why none. The run starts at
/// `x0` rounded to f32 ([`f32_start`]).
pub fn plan_run(task: &HybridTask, x0: &[f64]) -> Result<HybridRun, String> {
    plan_guided(task, x0, &DURATIONS, &|_: &Leg<'_>| None)
}

/// One segment [`plan_guided`] is about to generate: its index on the path, its start, its samples, its
/// sets (Goal: the guard `depth` deep, or the task's Goal for the last segment) and for a segment but
/// the last that depth.
pub struct Leg<'a> {
    pub segment: usize,
    pub start: &'a [f64],
    pub steps: usize,
    pub convex: &'a ConvexSets,
    pub depth: Option<f64>,
}

/// [`plan_run`] over the segment durations `durations` (fractions of T) with the generator's first
/// linearisation point per segment from `guide` (a route, [`route`]); a segment it gives none for is
/// generated as [`plan_run`] does.
pub fn plan_guided(
    task: &HybridTask,
    x0: &[f64],
    durations: &[f64],
    guide: &dyn Fn(&Leg<'_>) -> Option<Nominal>,
) -> Result<HybridRun, String> {
    let x0 = &f32_start(x0)[..];
    // The planner's generator calls (durations × guard depths per seed) are most of a hybrid synthesis,
    // and the KKT solves' refinement a large part of them: a looser one changes only what is proposed.
    let gs = GenSettings {
        refinement_tol: Some(PLAN_REFINEMENT_TOL),
        ..GenSettings::default()
    };
    let h = task.plant.period();
    let horizon = task.problem.horizon;
    let steps_of = |f: f64| ((f * horizon / h).round() as usize).clamp(2, task.steps);
    let mut best: Option<HybridRun> = None;
    let mut why = String::from("no duration tried");
    // Segments but the last: towards the guard, each duration; then the last segment from the landing.
    for (&f0, &depth) in durations
        .iter()
        .flat_map(|f| GUARD_DEPTHS.iter().map(move |d| (f, d)))
    {
        let mut nominals: Vec<Nominal> = Vec::new();
        let mut x = x0.to_vec();
        let mut ok = true;
        for (i, &loc) in task.path.iter().enumerate() {
            let last = i + 1 == task.path.len();
            let (convex, steps) = if last {
                (None, steps_of(horizon_left(task, &nominals, h, horizon)))
            } else {
                let edge = &task.plant.edges()[task.edges[i]];
                let (a, b) = (&edge.guard.a, &edge.guard.b);
                let rows = a.len();
                let H = Mat::from_fn(rows, a[0].len(), |r, c| a[r][c]);
                let deep: Vec<f64> = (0..rows)
                    .map(|r| {
                        let na = a[r].iter().map(|v| v * v).sum::<f64>().sqrt();
                        b[r] - depth * na
                    })
                    .collect();
                (
                    Some(ConvexSets {
                        goal: ConvexPiece::Polytope { H, b: deep },
                        unsafe_pieces: task.convex.unsafe_pieces.clone(),
                    }),
                    steps_of(f0),
                )
            };
            let conv = convex.as_ref().unwrap_or(&task.convex);
            let gp = gen_problem(task, loc, conv, steps);
            let leg = Leg {
                segment: i,
                start: &x,
                steps,
                convex: conv,
                depth: (!last).then_some(depth),
            };
            let generated = match guide(&leg) {
                Some(guess) => generate_from(&gp, &x, &gs, &guess),
                None => generate(&gp, &x, &gs),
            };
            let v = match generated {
                Ok(g) => g.nominal.v,
                Err(e) => {
                    why = format!("segment {i} ({}): {e}", task.plant.modes()[loc].name);
                    ok = false;
                    break;
                }
            };
            let nom = shipped_nominal(task, loc, &x, &v);
            if !last {
                match landing(task, loc, &nom, task.edges[i]) {
                    // f32-representable: the image stores it, and the certificate is re-proved from it.
                    Some(l) => x = f32_start(&l),
                    None => {
                        why = format!("segment {i}: the generated nominal does not switch");
                        ok = false;
                        break;
                    }
                }
            }
            nominals.push(nom);
        }
        if !ok {
            continue;
        }
        let cert = certify_run(task, &nominals)?;
        if best.as_ref().is_none_or(|b| cert.delta() > b.delta()) {
            best = Some(HybridRun {
                nominals,
                locations: task.path.clone(),
                certificate: cert,
            });
        }
    }
    // One refinement of a two-segment run: the next segment restarted from the centre of the landings
    // its certificate actually bounds.
    if let Some(b) = &best {
        if let Some(r) = refine_landing(task, b) {
            if r.delta() > b.delta() {
                best = Some(r);
            }
        }
    }
    // §5.3 over the planned run's tables and later starts ([`optimise`]).
    let iterations = (task.problem.synthesis.max_iterations / 2) as u64;
    best.map(|b| optimise::optimise(task, b, iterations))
        .ok_or(why)
}

/// For a run of two segments whose first certifies event intervals κ ∈ [a, b]: the landings the
/// certificate bounds are the next location's flow, for τ ∈ [0, h] with the input of row κ, from p̂(κ),
/// the projection of x̃(κ) onto the guard's plane in the first location's metric
/// ([`crate::certify::internal`], item 4). The next segment is generated again from the centre of their
/// bounding box (in the next location's metric) and the run certified again; `None` if that fails.
fn refine_landing(task: &HybridTask, run: &HybridRun) -> Option<HybridRun> {
    if task.path.len() != 2 {
        return None;
    }
    let (a, b) = run.certificate.segments[0].events?;
    let (l0, l1) = (task.path[0], task.path[1]);
    let edge = &task.plant.edges()[task.edges[0]];
    let row = edge.guard.a.first()?;
    let na = row.iter().map(|v| v * v).sum::<f64>().sqrt();
    let (an, bn): (Vec<f64>, f64) = (row.iter().map(|v| v / na).collect(), edge.guard.b[0] / na);
    let inv = &task.constants[l0].roots.inv;
    let pa = crate::linalg::mat_vec(inv.as_ref(), &an);
    let dn2: f64 = an.iter().zip(&pa).map(|(p, q)| p * q).sum();
    let post = &task.plant.modes()[l1].flow;
    let h = task.plant.period();
    let nom = &run.nominals[0];
    let roots1 = &task.constants[l1].roots;
    let n = an.len();
    let (mut lo, mut hi) = (vec![f64::INFINITY; n], vec![f64::NEG_INFINITY; n]);
    for k in a..=b.min(nom.steps().saturating_sub(1)) {
        let g: f64 = an.iter().zip(&nom.x[k]).map(|(p, q)| p * q).sum::<f64>() - bn;
        let p: Vec<f64> = (0..n).map(|q| nom.x[k][q] - g / dn2 * pa[q]).collect();
        for j in 0..=8 {
            let tau = h * j as f64 / 8.0;
            let x = if tau > 0.0 {
                post.zoh(tau).ok()?.step(&p, &nom.u[k])
            } else {
                p.clone()
            };
            let w = crate::linalg::mat_vec(roots1.sqrt.as_ref(), &x);
            for q in 0..n {
                lo[q] = lo[q].min(w[q]);
                hi[q] = hi[q].max(w[q]);
            }
        }
    }
    let mid: Vec<f64> = (0..n).map(|q| 0.5 * (lo[q] + hi[q])).collect();
    let start = f32_start(&crate::linalg::mat_vec(roots1.inv_sqrt.as_ref(), &mid));
    let gp = gen_problem(task, l1, &task.convex, run.nominals[1].steps());
    let v = generate(&gp, &start, &GenSettings::default())
        .ok()?
        .nominal
        .v;
    let last = shipped_nominal(task, l1, &start, &v);
    let nominals = vec![nom.clone(), last];
    let certificate = certify_run(task, &nominals).ok()?;
    Some(HybridRun {
        nominals,
        locations: task.path.clone(),
        certificate,
    })
}

/// Seconds left for the last segment after the earlier ones (their generated lengths).
fn horizon_left(_task: &HybridTask, earlier: &[Nominal], h: f64, horizon: f64) -> f64 {
    let used: usize = earlier.iter().map(|n| n.steps()).sum();
    ((horizon - used as f64 * h) / horizon).clamp(0.05, LAST_DURATION)
}

/// The feedforward image of certified runs: per location its gain and metric; per run its first ball
/// (radius as stored for f32 selection) and its segments, each keeping the rows its certificate covers,
/// with a guard exit on every segment but the last ([`crate::certify::internal::GuardExit`]).
pub fn image(task: &HybridTask, runs: &[HybridRun]) -> Result<Vec<u8>, crate::emit::EmitError> {
    use crate::emit::{ImageBuilder, SegmentExit, TrajectoryEntry};
    use crate::linalg::to_row_major;
    let (n, m) = (
        task.plant.modes()[0].flow.n(),
        task.plant.modes()[0].flow.m(),
    );
    let mut b = ImageBuilder::new(n, m, task.plant.period());
    for d in &task.designs {
        b.add_location(to_row_major(d.K.as_ref()), to_row_major(d.P.as_ref()));
    }
    for run in runs {
        let (mut v, mut location, mut exits) = (Vec::new(), Vec::new(), Vec::new());
        for (i, (nom, seg)) in run
            .nominals
            .iter()
            .zip(&run.certificate.segments)
            .enumerate()
        {
            let next: Vec<f32> = run
                .nominals
                .get(i + 1)
                .map(|m| m.x[0].iter().map(|&v| v as f32).collect())
                .unwrap_or_default();
            let rows = seg.rows.min(nom.steps());
            for row in &nom.v[..rows] {
                v.extend_from_slice(row);
            }
            location.extend(std::iter::repeat_n(run.locations[i] as u8, rows));
            exits.push(match &seg.exit {
                Some(g) => SegmentExit::Guard {
                    a: g.a.clone(),
                    b: g.b,
                    theta: g.theta,
                    next,
                },
                None => SegmentExit::Table,
            });
        }
        b.trajectories.push(TrajectoryEntry {
            x0: run.nominals[0].x[0].clone(),
            delta: run.certificate.delta_stored as f64,
            v,
            location,
        });
        // Forced switching ends every segment with its table: no exits section.
        if !task.forced {
            b.exits.push(exits);
        }
    }
    b.fingerprint = Some(task.problem.fingerprint.as_bytes().to_vec());
    b.to_bytes()
}

/// Starts for a Monte Carlo of a run's first ball B_P(x̃(0), δ): `interior` uniform in the ball and
/// `boundary` on its boundary sphere (in the metric), seeded.
pub fn ball_starts(
    task: &HybridTask,
    run: &HybridRun,
    interior: usize,
    boundary: usize,
    seed: u64,
) -> Vec<Vec<f64>> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let loc = task.path[0];
    let roots = &task.constants[loc].roots;
    let c = &run.nominals[0].x[0];
    let n = c.len();
    let delta = run.certificate.delta_stored as f64;
    let mut out = Vec::with_capacity(interior + boundary);
    for i in 0..interior + boundary {
        let radius = if i < interior {
            delta * rng.random::<f64>().powf(1.0 / n as f64)
        } else {
            // Just inside: the boundary itself is where the f32 selection test may go either way.
            delta * (1.0 - 1e-6)
        };
        out.push(crate::verify::hybrid::point_on_sphere(
            &mut rng, roots, c, radius,
        ));
    }
    out
}

/// Rounds in a row without a certified run after which the growth stops.
pub const MAX_EMPTY_ROUNDS: usize = 8;
/// Times the working samples are extended by as many fresh ones: when every uncovered one was tried, or
/// when they are covered to the target but fresh ones are not (the holes between balls shrink below the
/// samples' spacing as the cover fills, and the seeds were working samples).
pub const MAX_REFILLS: usize = 4;

/// Options of a hybrid synthesis run that are not part of the task (defaults per field).
#[derive(Clone)]
pub struct HybridOptions {
    /// Uniform samples of Init from which seeds are chosen (default 2 000).
    pub working_samples: usize,
    /// Monte Carlo runs from the cover's interior (default 500) and from each ball's boundary
    /// (default 8).
    pub verify_interior: usize,
    pub verify_per_ball: usize,
    /// Seeds planned per round, in parallel (default 4; fixed, so the image does not depend on the thread
    /// count).
    pub batch: usize,
    /// Set to stop the growth cleanly (Ctrl-C).
    pub cancel: std::sync::Arc<std::sync::atomic::AtomicBool>,
    /// Called with the count after each accepted run.
    pub on_accept: Option<std::sync::Arc<dyn Fn(usize, f64) + Send + Sync>>,
    /// Called with a line after each round of the growth (its seeds, the runs it certified, the working
    /// samples covered) and at each stage after it (image, re-proof, coverage, Monte Carlo).
    pub on_progress: Option<crate::cover::StageHook>,
    /// Recordings (name, recording) certified first ([`import::certify_recording`]); those accepted
    /// join the runs before the growth (default none).
    pub imports: Vec<(String, crate::trajectory::csv::Recording)>,
    /// How runs after the first are made (default [`Generator::Scp`]: the planner from each uncovered
    /// sample). [`Generator::Algorithm4`] grows a run from the nearest ball ([`forced::grow_from`]; across
    /// internal guards [`optimise::grow_from`]), falling back to the planner where that fails.
    pub generator: Generator,
    /// Whether, once a round certified no run (the growth stalls, as `cover::grow` asks its routes), a
    /// seed the other sources certify nothing from asks the routes of the global search ([`route`];
    /// internal switching only). Default false: each route is a continuation of generator calls over
    /// every duration and guard depth, minutes per seed, so `synth --guard-routes` asks for it.
    pub routes: bool,
}

impl Default for HybridOptions {
    fn default() -> Self {
        Self {
            working_samples: 2000,
            verify_interior: 500,
            verify_per_ball: 8,
            batch: 4,
            cancel: Default::default(),
            on_accept: None,
            on_progress: None,
            imports: Vec::new(),
            generator: Generator::Scp,
            routes: false,
        }
    }
}

/// What a hybrid synthesis produced.
pub struct HybridSynthesis {
    pub runs: Vec<HybridRun>,
    /// Where each run came from (`runs[i]`'s is `sources[i]`).
    pub sources: Vec<Source>,
    /// Seeds planned, and those that certified nothing (with the reason).
    pub seeds_tried: usize,
    pub refused: Vec<(Vec<f64>, String)>,
    /// Each imported recording by name: the δ of its run (the first runs, in this order), or why it was
    /// not used.
    pub imported: Vec<(String, Result<f64, String>)>,
    pub coverage: crate::cover::CoverageEstimate,
    pub image: Vec<u8>,
    pub verify: crate::verify::hybrid::HybridReport,
    /// Every run's certificate re-proved from the image bytes.
    pub recheck: Vec<crate::verify::hybrid::RunCheck>,
    /// Every route search run (by seed), for the report.
    pub routes: Vec<RouteSearch>,
    /// Why the growth stopped.
    pub stop: String,
    pub seconds: f64,
}

/// The one accept test of a certified run (planned or imported): its δ is at least `floor` (and
/// positive; [`admission_floor`]), the trajectory budget has room, and its kept rows and its segments fit
/// the image with the `rows_used` so far ([`no_room`]). `Err` says why not.
pub fn admit(
    task: &HybridTask,
    runs: &[HybridRun],
    rows_used: usize,
    run: &HybridRun,
    floor: f64,
) -> Result<usize, String> {
    let s = &task.problem.synthesis;
    if !run.certificate.is_certified() {
        return Err(import::refusal(task, &run.locations, &run.certificate));
    }
    // δ > 0 and finite here (certified).
    if run.delta() < floor {
        return Err(format!(
            "δ = {:.3e} is below min_robustness = {:.3e} ({})",
            run.delta(),
            floor,
            import::bindings(task, &run.locations, &run.certificate)
        ));
    }
    let rows = run.rows();
    if runs.len() >= s.max_trajectories {
        return Err(format!(
            "the budget of {} trajectories is spent",
            s.max_trajectories
        ));
    }
    if let Some(why) = no_room(task, runs, rows_used, run) {
        return Err(why);
    }
    reproved(task, run)?;
    Ok(rows)
}

/// The least δ a certified run needs to join the cover. With the planner from each uncovered sample
/// ([`Generator::Scp`]) that is δε (`min_robustness`): a smaller ball is not worth its table rows. With
/// Algorithm 4 (§5.4) δε instead bounds where the growth goes on: a sample whose projection falls on a
/// ball of radius below δε is discarded ([`algorithm4_seeds`]), and every certified run (δ > 0) joins the
/// cover, as the text's Example 5.6 keeps its 388 runs, those below δε among them (Figure 5.5 draws them
/// darker).
pub fn admission_floor(task: &HybridTask, generator: Generator) -> f64 {
    match generator {
        Generator::Algorithm4 => 0.0,
        _ => task.problem.synthesis.min_robustness,
    }
}

/// `Ok` when `run` re-proves from the bytes of an image holding it alone, as the final image's re-proof
/// ([`crate::verify::hybrid::recheck`]) will judge it (its stored tables, starts, guards and thresholds,
/// with the same K̂ and P̂); otherwise why not, so that a run the image would not certify is refused
/// when it is planned rather than at the end.
fn reproved(task: &HybridTask, run: &HybridRun) -> Result<(), String> {
    let bytes = image(task, std::slice::from_ref(run)).map_err(|e| format!("image: {e}"))?;
    let img = shared_types::image::decode(&bytes).map_err(|e| format!("image: {e}"))?;
    let lps: Vec<Loop<'_>> = (0..task.designs.len()).map(|l| task.lp(l)).collect();
    let lcs: Vec<Option<&LoopConstants>> = task.constants.iter().map(Some).collect();
    let checks = crate::verify::hybrid::recheck_runs(
        &task.plant,
        task.formula.as_ref(),
        task.steps,
        &img,
        &lps,
        &lcs,
    );
    match checks.into_iter().find(|c| !c.ok) {
        Some(c) => Err(format!(
            "its image bytes do not re-prove it: {}",
            c.why.unwrap_or_default()
        )),
        None => Ok(()),
    }
}

/// Why `run` does not fit the image after `runs` (their kept rows `rows_used`): its rows beyond the
/// table's, or its segments beyond [`MAX_SEGMENTS`](shared_types::capacity::MAX_SEGMENTS) (one per
/// nominal, an upper bound on the image's maximal runs of one location); `None` when it fits.
fn no_room(
    task: &HybridTask,
    runs: &[HybridRun],
    rows_used: usize,
    run: &HybridRun,
) -> Option<String> {
    let (rows, capacity) = (run.rows(), table_rows(task));
    if rows_used + rows > capacity {
        return Some(format!(
            "its {rows} rows do not fit the image's table ({rows_used} of {capacity} rows used)"
        ));
    }
    let max = shared_types::capacity::MAX_SEGMENTS;
    let used: usize = runs.iter().map(|r| r.nominals.len()).sum();
    let segments = run.nominals.len();
    (used + segments > max).then(|| {
        format!("its {segments} segments do not fit the image ({used} of {max} segments used)")
    })
}

/// The rows the image's table holds for this plant's inputs.
fn table_rows(task: &HybridTask) -> usize {
    shared_types::capacity::max_rows(task.problem.plant.m())
}

/// (5.32) over the runs' first balls: min over runs of ‖x − x̃(0)‖_P − δ (the metric of the initial
/// location, the stored radius), with the run that attains it; `None` when there is no run.
fn gap(task: &HybridTask, runs: &[HybridRun], x: &[f64]) -> Option<(f64, usize)> {
    let P = task.designs[task.path[0]].P.as_ref();
    runs.iter()
        .enumerate()
        .map(|(i, r)| {
            let d = crate::cover::alg4::dist(P, x, &r.nominals[0].x[0]);
            (d - r.certificate.delta_stored as f64, i)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// Whether `x` is in the first ball of some run.
fn covered(task: &HybridTask, runs: &[HybridRun], x: &[f64]) -> bool {
    gap(task, runs, x).is_some_and(|(d, _)| d <= 0.0)
}

/// The working samples extended by `fresh`, none of them tried yet.
fn extend_working(working: &mut Vec<Vec<f64>>, tried: &mut Vec<bool>, fresh: Vec<Vec<f64>>) {
    working.extend(fresh);
    tried.resize(working.len(), false);
}

/// The seeds of an Algorithm 4 round (§5.4; forced switching, or internal across the guards): the
/// untried uncovered working samples, nearest to the cover first (ties in sample order), each projected
/// onto the boundary of its nearest ball; a sample whose nearest ball has a radius below δε
/// (`min_robustness`) is discarded instead; a batch is spread by the runs' median radius (one seed per
/// neighbourhood). Marks them tried.
fn algorithm4_seeds(
    task: &HybridTask,
    runs: &[HybridRun],
    working: &[Vec<f64>],
    tried: &mut [bool],
    batch: usize,
) -> Vec<Seed> {
    let P = task.designs[task.path[0]].P.as_ref();
    let typical =
        crate::cover::alg4::median(runs.iter().map(|r| r.certificate.delta_stored as f64))
            .unwrap_or(0.0);
    let mut pool: Vec<(f64, usize, usize)> = working
        .iter()
        .enumerate()
        .filter(|(i, _)| !tried[*i])
        .filter_map(|(i, x)| gap(task, runs, x).map(|(d, m)| (d, m, i)))
        .filter(|&(d, _, _)| d > 0.0)
        .collect();
    pool.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
    let mut out: Vec<Seed> = Vec::new();
    let delta_eps = task.problem.synthesis.min_robustness;
    for (_, m, i) in pool {
        if out.len() == batch {
            break;
        }
        let r = &runs[m];
        // §5.4: y nearest a ball of radius below δε lies where local variation no longer reaches;
        // it is discarded (it may still be covered later by a ball grown elsewhere).
        if (r.certificate.delta_stored as f64) < delta_eps {
            tried[i] = true;
            continue;
        }
        let Some(yh) = crate::cover::alg4::project_onto_boundary(
            P,
            &working[i],
            &r.nominals[0].x[0],
            r.certificate.delta_stored as f64,
        ) else {
            continue;
        };
        let near = |s: &Seed| {
            s.grow
                .as_ref()
                .is_some_and(|(_, z)| crate::cover::alg4::dist(P, z, &yh) < typical)
        };
        if out.iter().any(near) {
            continue;
        }
        tried[i] = true;
        out.push(Seed {
            x: working[i].clone(),
            grow: Some((m, yh)),
        });
    }
    out
}

/// An automaton's seed sources over the runs so far ([`crate::cover::seeds`]): Algorithm 4 grows a run
/// from a ball's boundary ([`forced::grow_from`]; across internal guards [`optimise::grow_from`]); the generator is the planner
/// from the seed ([`forced::plan_forced`], or [`plan_run`] for internal switching); the routes of the
/// global search through the guards ([`route::routed_runs`]; internal switching only).
struct HybridSources<'a> {
    task: &'a HybridTask,
    runs: &'a [HybridRun],
    routing: Option<&'a Routing<'a>>,
}

impl Sources for HybridSources<'_> {
    type Candidate = Result<HybridRun, String>;

    fn answer<'s>(
        &'s self,
        seed: &'s Seed,
        ask: Ask,
    ) -> Box<dyn Iterator<Item = Proposal<Self::Candidate>> + 's> {
        let (task, runs) = (self.task, self.runs);
        match ask {
            Ask::Grow => Box::new(seed.grow.iter().map(move |(m, yh)| Proposal {
                origin: Origin::Algorithm4(*m),
                candidate: if task.forced {
                    forced::grow_from(task, &runs[*m], yh)
                } else {
                    let iterations = (task.problem.synthesis.max_iterations / 2) as u64;
                    optimise::grow_from(task, &runs[*m], yh, iterations)
                },
            })),
            Ask::Generator => Box::new(std::iter::once_with(move || Proposal {
                origin: Origin::Generator,
                candidate: if task.forced {
                    forced::plan_forced(task, &seed.x)
                } else {
                    plan_run(task, &seed.x)
                },
            })),
            Ask::Routes => match self.routing {
                Some(routing) => route::routed_runs(task, routing, &seed.x),
                None => Box::new(std::iter::empty()),
            },
        }
    }
}

/// Plan a run for `seed`: its sources in order ([`HybridSources`]), the first run certified at
/// `floor` ([`admission_floor`]) with the seed's sample in its ball; when there is none, the planner's answer
/// whatever it is (the accept test [`admit`] judges it and says why).
fn plan_seed(
    task: &HybridTask,
    runs: &[HybridRun],
    routing: Option<&Routing<'_>>,
    seed: &Seed,
    floor: f64,
) -> (Origin, Result<HybridRun, String>) {
    let kept = |r: &HybridRun| {
        r.certificate.is_certified()
            && r.delta() >= floor
            && covered(task, std::slice::from_ref(r), &seed.x)
    };
    let src = HybridSources {
        task,
        runs,
        routing,
    };
    let mut planned = None;
    for p in src.proposals(seed) {
        if p.candidate.as_ref().is_ok_and(kept) {
            return (p.origin, p.candidate);
        }
        if p.origin == Origin::Generator {
            planned = Some((p.origin, p.candidate));
        }
    }
    planned.unwrap_or((Origin::Generator, Err("no seed source answered".into())))
}

/// Algorithm 1 over hybrid runs: plan from Init's centre, then from uncovered samples of Init (the
/// working samples, extended up to [`MAX_REFILLS`] times when every uncovered one was tried or fresh
/// samples are less covered than they are; a batch per round, planned in parallel, accepted in sample
/// order; with [`Generator::Algorithm4`], grown from the nearest ball first,
/// [`algorithm4_seeds`] and [`plan_seed`]), until the working samples are covered to the target, the budget (`max_trajectories`, the table's rows) is spent, no uncovered sample is left
/// untried, or `cancel` is set; then the coverage estimate (§2.5.2), the image and its Monte Carlo.
pub fn synthesize_hybrid(
    task: &HybridTask,
    opts: &HybridOptions,
) -> Result<HybridSynthesis, String> {
    use rand::SeedableRng;
    use rayon::prelude::*;
    use std::sync::atomic::Ordering;
    let t0 = std::time::Instant::now();
    let s = &task.problem.synthesis;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(task.problem.seed);
    let floor = admission_floor(task, opts.generator);
    let init = crate::cover::estimate::SampleBox {
        lo: task.problem.init.lo.clone(),
        hi: task.problem.init.hi.clone(),
    };
    let mut working = init.samples(opts.working_samples.max(1), &mut rng);
    let mut refills = 0usize;
    let centre: Vec<f64> = init
        .lo
        .iter()
        .zip(&init.hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect();
    // The global route search (internal switching; [`HybridOptions::routes`]).
    let routing = (opts.routes && !task.forced)
        .then(|| Routing::new(&task.convex, &task.problem.init.lo, &task.problem.init.hi));
    let mut runs: Vec<HybridRun> = Vec::new();
    // Where each run came from (a recording, the planner, Algorithm 4 from a run).
    let mut sources: Vec<Source> = Vec::new();
    let mut refused: Vec<(Vec<f64>, String)> = Vec::new();
    let mut tried = vec![false; working.len()];
    let mut seeds_tried = 0usize;
    let mut rows_used = 0usize;
    // The final estimate's lower bound is its mean less the half-width `coverage_tolerance`; the working
    // estimate is noisier still, so it aims as far again above.
    let target = s.coverage_target + 2.0 * s.coverage_tolerance;
    let stop;
    let mut first = true;
    // Recorded runs first, through the same accept test.
    let mut imported = Vec::with_capacity(opts.imports.len());
    for (name, rec) in &opts.imports {
        let r = import::certify_recording(task, rec)
            .map_err(|e| e.to_string())
            .and_then(|run| admit(task, &runs, rows_used, &run, floor).map(|rows| (run, rows)));
        imported.push((
            name.clone(),
            r.map(|(run, rows)| {
                rows_used += rows;
                let d = run.delta();
                runs.push(run);
                sources.push(Source::import(name));
                if let Some(f) = &opts.on_accept {
                    f(runs.len(), d);
                }
                d
            }),
        ));
    }
    // Rounds in a row that certified nothing: after MAX_EMPTY_ROUNDS of them the growth stops and asks
    // for a new seed trajectory (planning a refused seed costs as much as an accepted one).
    let mut empty_rounds = 0usize;
    let progress = |line: String| {
        if let Some(f) = &opts.on_progress {
            f.stage(&line);
        }
    };
    // The last round's seeds and the runs it certified, reported with the cover it left.
    let mut round: Option<(usize, usize, usize)> = None;
    let mut rounds = 0usize;
    loop {
        if opts.cancel.load(Ordering::Relaxed) {
            stop = "interrupted".to_string();
            break;
        }
        let fraction = |xs: &[Vec<f64>]| {
            xs.iter().filter(|x| covered(task, &runs, x)).count() as f64 / xs.len() as f64
        };
        let frac = fraction(&working);
        if let Some((k, tried_now, certified)) = round.take() {
            progress(format!(
                "round {k}: {tried_now} seed(s), {certified} certified; {} runs, {:.1} % of {} working samples covered",
                runs.len(),
                100.0 * frac,
                working.len()
            ));
        }
        if frac >= target.min(1.0) {
            // The seeds were working samples, so the working set flatters the cover: confirm on fresh
            // samples, which join the working set when they fall short.
            let fresh = init.samples(opts.working_samples.max(1), &mut rng);
            let fresh_frac = fraction(&fresh);
            if fresh_frac >= target.min(1.0) || refills >= MAX_REFILLS {
                stop = format!(
                    "the working samples are covered ({:.1} %; {:.1} % of fresh ones)",
                    100.0 * frac,
                    100.0 * fresh_frac
                );
                break;
            }
            refills += 1;
            extend_working(&mut working, &mut tried, fresh);
            continue;
        }
        if runs.len() >= s.max_trajectories {
            stop = format!("the budget of {} trajectories is spent", s.max_trajectories);
            break;
        }
        let seeds: Vec<Seed> = if first && !covered(task, &runs, &centre) {
            first = false;
            vec![Seed {
                x: centre.clone(),
                grow: None,
            }]
        } else if !runs.is_empty() && opts.generator == Generator::Algorithm4 {
            first = false;
            algorithm4_seeds(task, &runs, &working, &mut tried, opts.batch.max(1))
        } else {
            first = false;
            let mut out = Vec::new();
            for (i, x) in working.iter().enumerate() {
                if out.len() == opts.batch.max(1) {
                    break;
                }
                if !tried[i] && !covered(task, &runs, x) {
                    tried[i] = true;
                    out.push(Seed {
                        x: x.clone(),
                        grow: None,
                    });
                }
            }
            out
        };
        if seeds.is_empty() {
            // The holes left are smaller than the working samples' spacing: draw more, up to a bound.
            if refills < MAX_REFILLS {
                refills += 1;
                let fresh = init.samples(opts.working_samples.max(1), &mut rng);
                extend_working(&mut working, &mut tried, fresh);
                continue;
            }
            stop =
                "every uncovered working sample was tried: a new seed trajectory is needed".into();
            break;
        }
        if empty_rounds >= MAX_EMPTY_ROUNDS {
            stop = format!(
                "{MAX_EMPTY_ROUNDS} rounds in a row certified no run: a new seed trajectory is needed"
            );
            break;
        }
        seeds_tried += seeds.len();
        let before = runs.len();
        rounds += 1;
        let round_seeds = seeds.len();
        let planned: Vec<(Origin, Result<HybridRun, String>)> = seeds
            .par_iter()
            .map(|seed| {
                plan_seed(
                    task,
                    &runs,
                    routing.as_ref().filter(|_| empty_rounds > 0),
                    seed,
                    floor,
                )
            })
            .collect();
        // Why a certified run of this round no longer fits the image (the first).
        let mut left_out: Option<String> = None;
        for (Seed { x, .. }, (origin, r)) in seeds.into_iter().zip(planned) {
            let full = r
                .as_ref()
                .ok()
                .and_then(|run| no_room(task, &runs, rows_used, run));
            match r
                .and_then(|run| admit(task, &runs, rows_used, &run, floor).map(|rows| (run, rows)))
            {
                Ok((run, rows)) => {
                    rows_used += rows;
                    runs.push(run);
                    // Every planned, routed or grown run went through §5.3 (`plan_guided`,
                    // `forced::plan_forced`, the two `grow_from`).
                    sources.push(Source::new(origin, true));
                    if let Some(f) = &opts.on_accept {
                        f(runs.len(), runs.last().map_or(0.0, |r| r.delta()));
                    }
                }
                Err(e) => {
                    if left_out.is_none() && full.as_ref() == Some(&e) {
                        left_out = full;
                    }
                    refused.push((x, e))
                }
            }
        }
        if let (Some(why), true) = (left_out, runs.len() == before) {
            stop = format!("the image is full: a certified run of this round does not fit ({why})");
            break;
        }
        round = Some((rounds, round_seeds, runs.len() - before));
        empty_rounds = if runs.len() > before {
            0
        } else {
            empty_rounds + 1
        };
    }
    if runs.is_empty() {
        return Err(format!(
            "no run was certified ({} seeds tried; first reason: {})",
            seeds_tried,
            refused.first().map_or("none", |r| r.1.as_str())
        ));
    }
    progress(format!(
        "growth stopped after {rounds} rounds, {} runs: {stop}",
        runs.len()
    ));
    let image = image(task, &runs).map_err(|e| format!("image: {e}"))?;
    progress(format!(
        "image: {} bytes; re-proving {} runs from its bytes",
        image.len(),
        runs.len()
    ));
    let recheck = crate::verify::hybrid::recheck(
        &task.plant,
        &task.property,
        task.formula.as_ref(),
        task.steps,
        &image,
    )?;
    // Coverage (§2.5.2) from fresh samples: a sample is covered when the image's f32 selection accepts it
    // (what it accepts lies in a certified ball; near a ball's boundary it may refuse a state the f64 test
    // would count).
    let decoded = shared_types::image::decode(&image).map_err(|e| format!("image: {e}"))?;
    let ctl = shared_types::eval::Controller::new(decoded);
    let accepted = |x: &[f64]| {
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        ctl.select(&x32).is_some()
    };
    let n_cov = s.coverage_samples();
    progress(format!("coverage from {n_cov} samples of Init"));
    let coverage =
        crate::cover::estimate::estimate(&init, n_cov, s.confidence, &mut rng, |x| accepted(x));
    // Monte Carlo: covered samples of Init, and the boundary of every ball.
    let mut starts = Vec::new();
    let mut draws = 0usize;
    while starts.len() < opts.verify_interior && draws < 100 * opts.verify_interior.max(1) {
        draws += 1;
        let x = init.sample(&mut rng);
        if accepted(&x) {
            starts.push(x);
        }
    }
    for (i, run) in runs.iter().enumerate() {
        let b = ball_starts(
            task,
            run,
            0,
            opts.verify_per_ball,
            task.problem.seed ^ (i as u64 + 1),
        );
        starts.extend(b);
    }
    progress(format!("Monte Carlo: {} closed-loop runs", starts.len()));
    let chunks: Vec<&[Vec<f64>]> = starts.chunks(64).collect();
    let reports: Vec<Result<crate::verify::hybrid::HybridReport, String>> = chunks
        .par_iter()
        .map(|c| {
            crate::verify::hybrid::monte_carlo_hybrid(
                &task.plant,
                &task.property,
                task.formula.as_ref(),
                task.initial,
                task.steps,
                &image,
                c,
            )
        })
        .collect();
    let mut verify = crate::verify::hybrid::HybridReport {
        min_unsafe_distance: f64::INFINITY,
        ..Default::default()
    };
    for r in reports {
        verify.merge(r?);
    }
    Ok(HybridSynthesis {
        runs,
        sources,
        seeds_tried,
        refused,
        coverage,
        image,
        verify,
        recheck,
        routes: routing.as_ref().map_or_else(Vec::new, Routing::searches),
        stop,
        imported,
        seconds: t0.elapsed().as_secs_f64(),
    })
}
