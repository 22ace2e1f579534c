//! Closed-loop Monte Carlo of a hybrid image (§4.2.2): the shared-types evaluator in f32, with its segment
//! exits, against the automaton's exact flow ([`Hybrid::flow`]: events found between samples, resets
//! applied), independent of how the certificate was made.
//!
//! Each run starts in the initial location and is stepped over the horizon: the evaluator's input for the
//! measured state (rounded to f32), held for one period; where the evaluator's row is in another location
//! and a forced edge leads there (§4.2.1), the plant takes that edge first (its guard must hold the
//! state, its reset is applied); the flow is taken in [`SUBSTEPS`] exact
//! sub-periods, and Unsafe is checked at every sub-sample (so also shortly after each event). A run
//! meets the task at its first sample in Goal if, up to then, it never was in Unsafe, every input was in
//! the input set, and the evaluator never left its certified envelope. For an MTL task (forced switching,
//! Def 4.18) a run goes the whole horizon and meets the task when the formula as written holds on it at
//! the samples and at every sub-sample (Boolean semantics), every input was in the input set and the
//! evaluator never left its envelope ([`Judging`]).

use crate::model::hybrid::{FlowError, Hybrid};
use crate::model::Location;
use crate::property::ReachAvoid;
use rayon::prelude::*;
use shared_types::eval::Controller;

/// Exact sub-periods per control period at which Unsafe is checked.
pub const SUBSTEPS: usize = 8;

/// What the runs did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct HybridReport {
    pub runs: usize,
    /// Starts the evaluator did not accept at κ = 0 (outside every ball as the f32 selection test sees
    /// it; the firmware applies its fallback, and the certificate claims nothing there). Not judged.
    pub rejected: usize,
    pub violations: usize,
    /// The first violation, in words.
    pub first_violation: Option<String>,
    /// Runs that took at least one event, and the most events one run took.
    pub switched: usize,
    pub max_events: usize,
    /// The latest sample at which a run reached Goal.
    pub max_goal_step: usize,
    /// The least Euclidean distance to Unsafe seen at any sub-sample.
    pub min_unsafe_distance: f64,
}

impl HybridReport {
    /// Adds another batch's counts (the first violation kept in batch order).
    pub fn merge(&mut self, o: HybridReport) {
        self.runs += o.runs;
        self.rejected += o.rejected;
        self.violations += o.violations;
        if self.first_violation.is_none() {
            self.first_violation = o.first_violation;
        }
        self.switched += o.switched;
        self.max_events = self.max_events.max(o.max_events);
        self.max_goal_step = self.max_goal_step.max(o.max_goal_step);
        self.min_unsafe_distance = self.min_unsafe_distance.min(o.min_unsafe_distance);
    }
}

/// One run of a hybrid image ([`run_hybrid`]).
#[derive(Clone, Debug, PartialEq)]
pub struct HybridRun {
    /// The evaluator did not accept x0 (not run, not judged).
    pub rejected: bool,
    /// Events taken.
    pub events: usize,
    /// The first sample in Goal.
    pub goal_step: Option<usize>,
    /// The least Euclidean distance to Unsafe at any sub-sample.
    pub min_unsafe_distance: f64,
    /// Why the run fails the task, when it does.
    pub violation: Option<String>,
    /// A formula task's robustness of the run sampled finer, when it was asked for ([`Judging`]).
    pub robustness: Option<f64>,
}

/// How a run is judged.
#[derive(Clone, Copy)]
pub enum Judging<'a> {
    /// Reach-avoid: the run ends at its first sample in Goal; Unsafe is checked at every sub-sample.
    ReachAvoid,
    /// An MTL task (forced switching, Def 4.18): the run goes the whole horizon and is judged by the
    /// formula as written, at the samples and at every sub-sample (Boolean semantics), as
    /// [`super::temporal`] judges a one-location run; `robust` also scores it (the falsifier's objective).
    Formula {
        task: &'a crate::property::TemporalTask,
        judges: &'a super::temporal::Judges,
        robust: bool,
    },
}

/// The run of `image` from `x0` in location `initial` for `steps` samples on `fine`, the automaton
/// resampled at [`SUBSTEPS`] sub-periods per period, judged as `judging` says (module doc); `visit` sees
/// the state at every sample the run reaches (x0 first). A flow the automaton cannot continue fails the
/// run.
#[allow(clippy::too_many_arguments)]
pub fn run_hybrid(
    fine: &Hybrid,
    property: &ReachAvoid,
    initial: Location,
    steps: usize,
    image: &shared_types::image::Image<'_>,
    x0: &[f64],
    judging: Judging<'_>,
    visit: &mut dyn FnMut(&[f64]),
) -> HybridRun {
    let formula = matches!(judging, Judging::Formula { .. });
    let h = fine.period() * SUBSTEPS as f64;
    let mut record = super::temporal::RunRecord::new(x0, h);
    let euclid = crate::geometry::Metric::euclidean(x0.len());
    let mut out = HybridRun {
        rejected: false,
        events: 0,
        goal_step: None,
        min_unsafe_distance: f64::INFINITY,
        violation: None,
        robustness: None,
    };
    let mut ctl = Controller::new(*image);
    let x32: Vec<f32> = x0.iter().map(|&v| v as f32).collect();
    if ctl.select(&x32).is_none() {
        out.rejected = true;
        return out;
    }
    let (mut x, mut loc) = (x0.to_vec(), initial);
    let mut why: Option<String> = None;
    // Unsafe's distance at every sub-sample, compiled once for the run (the same values, bit for bit, as
    // `Region::dist`, without a witness or an allocation per point; a set without a compiled form is
    // asked directly).
    let unsafe_region = property.unsafe_region();
    let mut unsafe_fn = unsafe_region.and_then(|us| us.compile(&euclid));
    for k in 0..=steps {
        visit(&x);
        if !formula && property.goal.contains(&x) {
            out.goal_step = Some(k);
            break;
        }
        if k == steps {
            break;
        }
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let u = match ctl.step(&x32) {
            Ok(u) => u,
            Err(s) => {
                why = Some(format!(
                    "sample {k}: the evaluator answered: {s}, at x = {x:?}"
                ));
                break;
            }
        };
        // Forced switching (§4.2.1): the location of the evaluator's row is the discrete input.
        match take_forced(fine, &mut loc, &mut x, ctl.location()) {
            Ok(Some(_)) => out.events += 1,
            Ok(None) => {}
            Err(want) => {
                why = Some(format!(
                    "sample {k}: the controller switches to location {want}, but x = {x:?} is not in the edge's guard"
                ));
                break;
            }
        }
        let u64s: Vec<f64> = u.as_slice().iter().map(|&v| v as f64).collect();
        if super::input_slack(&property.input, &u64s) < 0.0 {
            why = Some(format!(
                "sample {k}: input {:?} outside the input set",
                u.as_slice()
            ));
            break;
        }
        let flowed = flow_period(fine, &mut loc, &mut x, &u64s, &mut |s| {
            out.events += s.events.len();
            if formula {
                if s.index < SUBSTEPS {
                    record.push_between(s.index as f64 * fine.period(), s.x);
                } else {
                    record.push_sample(s.x);
                }
                return Ok(());
            }
            if let Some(us) = unsafe_region {
                let (inside, d) = match unsafe_fn.as_mut() {
                    Some(f) => {
                        let r = f.eval(s.x);
                        (r.inside, if r.inside { 0.0 } else { r.value })
                    }
                    None => (us.contains(s.x), us.dist(s.x, &euclid).value),
                };
                out.min_unsafe_distance = out.min_unsafe_distance.min(d);
                if inside {
                    return Err(format!("sample {k}: in Unsafe at x = {:?}", s.x));
                }
            }
            Ok(())
        });
        match flowed {
            Ok(()) => {}
            Err(PeriodStop::Flow { from, error }) => {
                why = Some(format!(
                    "sample {k}: the flow failed at x = {from:?}: {error}"
                ));
                break;
            }
            Err(PeriodStop::Stopped(w)) => {
                why = Some(w);
                break;
            }
        }
    }
    match judging {
        Judging::Formula {
            task,
            judges,
            robust,
        } if why.is_none() => match judges.judge(task, &record, robust) {
            Ok((holds, holds_fine, robustness)) => {
                out.robustness = robustness;
                if !holds || !holds_fine {
                    why = Some(format!(
                        "the formula is {} at the samples and {} sampled finer",
                        if holds { "true" } else { "FALSE" },
                        if holds_fine { "true" } else { "FALSE" },
                    ));
                }
            }
            Err(e) => why = Some(format!("the run cannot be judged by the formula: {e}")),
        },
        Judging::Formula { .. } => {}
        Judging::ReachAvoid => {
            if why.is_none() && out.goal_step.is_none() {
                why = Some(format!("Goal not reached within {steps} samples"));
            }
        }
    }
    out.violation = why;
    out
}

/// Forced switching (§4.2.1) at a sample: where the evaluator's row is in location `want` ≠ `*loc` and
/// a forced edge leads there, the plant takes it (its guard must hold `x`; its reset is applied, and
/// `*loc` becomes `want`). `Ok(Some(edge))` when it did, `Ok(None)` when there is no forced edge to take
/// (the same location, or internal switching, where the row's location follows the plant's), `Err(want)`
/// when the edge's guard does not hold `x` (nothing changed).
pub fn take_forced(
    fine: &Hybrid,
    loc: &mut Location,
    x: &mut Vec<f64>,
    want: Location,
) -> Result<Option<usize>, Location> {
    if want == *loc {
        return Ok(None);
    }
    let Some(e) = fine.edge_index(*loc, want, crate::model::hybrid::EdgeKind::Forced) else {
        return Ok(None);
    };
    let edge = &fine.edges()[e];
    if !edge.guard.contains(x) {
        return Err(want);
    }
    *x = edge.reset.apply(x);
    *loc = want;
    Ok(Some(e))
}

/// One state between samples that [`flow_period`] reached.
pub struct SubSample<'a> {
    /// 1..=[`SUBSTEPS`]: the end of the `index`-th sub-period (the next sample at [`SUBSTEPS`]).
    pub index: usize,
    pub x: &'a [f64],
    pub loc: Location,
    /// The events the flow took within this sub-period, their times in seconds after the sub-period's
    /// start (`Event::time`).
    pub events: &'a [crate::model::hybrid::Event],
}

/// Why [`flow_period`] stopped before the period's end.
pub enum PeriodStop {
    /// The automaton's flow failed from `from` (Zeno, undecided, not finite).
    Flow { from: Vec<f64>, error: FlowError },
    /// The caller's `sub` stopped it, saying why.
    Stopped(String),
}

/// One control period of the automaton from (`*loc`, `*x`) with `u` held, on `fine` (the automaton
/// resampled at [`SUBSTEPS`] sub-periods per period): the exact flow of each sub-period ([`Hybrid::flow`],
/// internal events and resets), `sub` seeing the state after each. `*loc` and `*x` follow the flow up to
/// where it stopped.
pub fn flow_period(
    fine: &Hybrid,
    loc: &mut Location,
    x: &mut Vec<f64>,
    u: &[f64],
    sub: &mut dyn FnMut(SubSample<'_>) -> Result<(), String>,
) -> Result<(), PeriodStop> {
    for index in 1..=SUBSTEPS {
        let step = fine.flow(*loc, x, u).map_err(|error| PeriodStop::Flow {
            from: x.clone(),
            error,
        })?;
        *x = step.x;
        *loc = step.loc;
        sub(SubSample {
            index,
            x,
            loc: *loc,
            events: &step.events,
        })
        .map_err(PeriodStop::Stopped)?;
    }
    Ok(())
}

/// Runs the image `bytes` from each start (in location `initial`) for `steps` samples (module doc). A
/// start the evaluator does not select a ball for is counted as rejected, not run.
pub fn monte_carlo_hybrid(
    plant: &Hybrid,
    property: &ReachAvoid,
    formula: Option<&crate::property::TemporalTask>,
    initial: Location,
    steps: usize,
    bytes: &[u8],
    starts: &[Vec<f64>],
) -> Result<HybridReport, String> {
    let judges = formula
        .map(|tt| super::temporal::Judges::new(tt, crate::model::Plant::n(plant)))
        .transpose()
        .map_err(|e| e.to_string())?;
    let judging = match (formula, &judges) {
        (Some(task), Some(judges)) => Judging::Formula {
            task,
            judges,
            robust: false,
        },
        _ => Judging::ReachAvoid,
    };
    let image = shared_types::image::decode(bytes).map_err(|e| format!("image: {e}"))?;
    let fine = plant
        .resampled(plant.period() / SUBSTEPS as f64)
        .map_err(|e| e.to_string())?;
    let mut rep = HybridReport {
        min_unsafe_distance: f64::INFINITY,
        ..Default::default()
    };
    for x0 in starts {
        rep.runs += 1;
        let r = run_hybrid(
            &fine,
            property,
            initial,
            steps,
            &image,
            x0,
            judging,
            &mut |_| {},
        );
        if r.rejected {
            rep.rejected += 1;
            continue;
        }
        rep.min_unsafe_distance = rep.min_unsafe_distance.min(r.min_unsafe_distance);
        if let Some(k) = r.goal_step {
            rep.max_goal_step = rep.max_goal_step.max(k);
        }
        if r.events > 0 {
            rep.switched += 1;
        }
        rep.max_events = rep.max_events.max(r.events);
        if let Some(w) = r.violation {
            rep.violations += 1;
            if rep.first_violation.is_none() {
                rep.first_violation = Some(format!("start {x0:?}: {w}"));
            }
        }
    }
    Ok(rep)
}

/// The recomputed certificate of one stored run of a hybrid image ([`recheck`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RunCheck {
    pub trajectory: usize,
    pub stored: f32,
    /// The radius the bytes certify (selection radius of the recomputed δ).
    pub certified: f32,
    pub ok: bool,
    /// Why not, when not.
    pub why: Option<String>,
}

/// Re-proves every stored run of a hybrid image from its bytes and the spec's automaton and sets: per
/// location the stored K̂ and P̂ (widened exactly); per run each segment's nominal re-simulated from its
/// stored start (the ball's centre, then each guard exit's `next`) under its stored table; the edges
/// between segments found in the automaton (the internal edge between the two locations whose guard,
/// normalised and rounded, is the one stored; for a segment that ends with its table, the forced edge
/// between them, and the next segment then starts at the reset of this one's re-simulated end); the run
/// certified by the synthesiser's own code ([`crate::certify::internal::certify_internal`], or
/// [`crate::certify::forced::certify_forced`] for forced switching, or
/// [`crate::certify::forced::certify_forced_formula`] when the task is the MTL `formula`). A run passes when the stored guard and threshold are
/// the ones the certificate gives, every guard segment's rows reach its κ_f, and the stored radius is at
/// most the selection radius of the recomputed δ times 1 + (n + 2)uκ(P̂) (as for a single location,
/// [`super::feedforward::tolerance`]).
pub fn recheck(
    plant: &Hybrid,
    property: &ReachAvoid,
    formula: Option<&crate::property::TemporalTask>,
    steps: usize,
    bytes: &[u8],
) -> Result<Vec<RunCheck>, String> {
    use crate::certify::{Loop, LoopConstants};
    use faer::Mat;
    let img = shared_types::image::decode(bytes).map_err(|e| format!("image: {e}"))?;
    let (n, m) = (img.n(), img.m());
    if img.n_locations() != plant.modes().len() {
        return Err(format!(
            "the image has {} locations, the automaton {}",
            img.n_locations(),
            plant.modes().len()
        ));
    }
    let Ks: Vec<Mat<f64>> = (0..img.n_locations())
        .map(|l| Mat::from_fn(m, n, |i, j| img.K(l, i, j) as f64))
        .collect();
    let Ps: Vec<Mat<f64>> = (0..img.n_locations())
        .map(|l| crate::linalg::sym(Mat::from_fn(n, n, |i, j| img.P(l, i, j) as f64).as_ref()))
        .collect();
    let lps: Vec<Loop> = (0..img.n_locations())
        .map(|l| Loop {
            plant,
            loc: l,
            K: Ks[l].as_ref(),
            P: Ps[l].as_ref(),
            goal: property.goal.as_ref(),
            unsafe_set: property.unsafe_region(),
            input: &property.input,
        })
        .collect();
    let lcs: Vec<Option<LoopConstants>> =
        lps.iter().map(|lp| LoopConstants::new(lp).ok()).collect();
    let lcs: Vec<Option<&LoopConstants>> = lcs.iter().map(Option::as_ref).collect();
    Ok(recheck_runs(plant, formula, steps, &img, &lps, &lcs))
}

/// [`recheck`] of every run of the decoded image `img` with each location's loop `lps` (its K̂, P̂ and
/// the task's sets) and constants `lcs` (`None`: the location certifies nothing) given: from the image's
/// own K̂ and P̂ ([`recheck`]), or from the synthesis's designs when it checks a run before admitting it
/// (`synth::hybrid::admit`, the same K̂ and P̂ the image stores).
pub fn recheck_runs(
    plant: &Hybrid,
    formula: Option<&crate::property::TemporalTask>,
    steps: usize,
    img: &shared_types::image::Image<'_>,
    lps: &[crate::certify::Loop<'_>],
    lcs: &[Option<&crate::certify::LoopConstants>],
) -> Vec<RunCheck> {
    use crate::certify::forced::{certify_forced, certify_forced_formula, ForcedSegment};
    use crate::certify::internal::{certify_internal, InternalSegment};
    use crate::certify::selection_radius;
    use shared_types::image::Exit;
    let (n, m) = (img.n(), img.m());
    let f32s = |b: &[u8]| -> Vec<f64> {
        b.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
            .collect()
    };
    // Each run is re-proved on its own: in parallel, collected in the image's order.
    let check = |t: usize| -> RunCheck {
        let (s0, count) = img.trajectory_segments(t);
        let (tstart, _) = img.trajectory_rows(t);
        let stored = img.delta(t);
        let fail = |why: String| RunCheck {
            trajectory: t,
            stored,
            certified: 0.0,
            ok: false,
            why: Some(why),
        };
        let mut noms = Vec::new();
        let mut locs = Vec::new();
        let mut edges = Vec::new();
        let mut exits = Vec::new();
        let mut forced = false;
        let mut start: Vec<f64> = (0..n).map(|i| img.centre(t, i) as f64).collect();
        let mut bad = None;
        for s in s0..s0 + count {
            let Some(g) = img.segment(s) else { break };
            let lp = &lps[g.location];
            let v: Vec<Vec<f64>> = (0..g.len)
                .map(|k| {
                    (0..m)
                        .map(|j| img.v(t, g.first_row - tstart + k, j) as f64)
                        .collect()
                })
                .collect();
            let nom = lp.simulate(&start, &v);
            let end = nom.x.last().cloned().unwrap_or_default();
            noms.push(nom);
            locs.push(g.location);
            let ex = img.exit(s);
            if let Exit::Guard { next, .. } = ex {
                start = f32s(next);
            }
            exits.push(ex);
            if s + 1 < s0 + count {
                // A segment ending with its table is a forced switch (§4.2.1): the next segment starts at
                // the reset of this one's end; a guard exit is an internal one (§4.2.2).
                let kind = match ex {
                    Exit::Table => crate::model::hybrid::EdgeKind::Forced,
                    Exit::Guard { .. } => crate::model::hybrid::EdgeKind::Internal,
                };
                let to = img.segment(s + 1).map_or(usize::MAX, |h| h.location);
                match plant.edge_index(g.location, to, kind) {
                    Some(e) => {
                        if kind == crate::model::hybrid::EdgeKind::Forced {
                            forced = true;
                            start = plant.edges()[e].reset.apply(&end);
                        }
                        edges.push(e)
                    }
                    None => {
                        bad = Some(format!(
                            "segment {s}: no {kind:?} edge {} → {to}",
                            g.location
                        ))
                    }
                }
            }
        }
        if let Some(why) = bad {
            return fail(why);
        }
        if locs.iter().any(|&l| lcs[l].is_none()) {
            return fail("a location's stored K̂ and P̂ certify nothing".into());
        }
        if forced && exits.iter().any(|e| matches!(e, Exit::Guard { .. })) {
            return fail(
                "the run mixes forced switches and guard exits, which no certificate covers".into(),
            );
        }
        let cert = if forced {
            let segs: Vec<ForcedSegment> = locs
                .iter()
                .zip(&noms)
                .enumerate()
                .map(|(i, (&l, nom))| ForcedSegment {
                    lp: lps[l],
                    lc: lcs[l].expect("checked"),
                    nominal: nom,
                    switch: edges.get(i).map(|&e| &plant.edges()[e]),
                    invariant: plant.modes()[l].invariant.as_ref(),
                })
                .collect();
            let cert = match formula {
                Some(tt) => certify_forced_formula(&segs, tt).map(|c| c.base),
                None => certify_forced(&segs),
            };
            match cert {
                Ok(c) => c.as_segments(&noms),
                Err(e) => return fail(e.to_string()),
            }
        } else {
            let segs: Vec<InternalSegment> = locs
                .iter()
                .zip(&noms)
                .zip(&exits)
                .map(|((&l, nom), ex)| InternalSegment {
                    lp: lps[l],
                    lc: lcs[l].expect("checked"),
                    nominal: nom,
                    theta_stored: match ex {
                        Exit::Guard { theta, .. } => Some(*theta),
                        Exit::Table => None,
                    },
                })
                .collect();
            match certify_internal(plant, &segs, &edges, steps) {
                Ok(c) => c,
                Err(e) => return fail(e.to_string()),
            }
        };
        let mut why = None;
        for (i, (c, ex)) in cert.segments.iter().zip(&exits).enumerate() {
            if let (Some(g), Exit::Guard { a, b, theta, .. }) = (&c.exit, ex) {
                let a: Vec<f32> = f32s(a).iter().map(|&v| v as f32).collect();
                if a != g.a || *b != g.b {
                    why = Some(format!(
                        "segment {i}: the stored guard is not the plant's edge's"
                    ));
                } else if *theta != g.theta {
                    why = Some(format!(
                        "segment {i}: the stored threshold θ = {theta:e} is below what the guard test's rounding requires ({:e} certified)",
                        g.theta
                    ));
                }
                if c.rows > noms[i].steps() {
                    why = Some(format!(
                        "segment {i}: its {} rows end before κ_f = {}",
                        noms[i].steps(),
                        c.rows
                    ));
                }
            }
        }
        let P0 = &lps[locs[0]].P;
        let x0: Vec<f64> = (0..n).map(|i| img.centre(t, i) as f64).collect();
        let certified = selection_radius(*P0, &x0, cert.delta());
        let tol = super::feedforward::tolerance(*P0);
        if why.is_none()
            && !((stored as f64) <= certified as f64 * (1.0 + tol) && cert.delta() > 0.0)
        {
            why = Some(format!(
                "the stored radius {stored:e} exceeds the {certified:e} the stored tables certify"
            ));
        }
        RunCheck {
            trajectory: t,
            stored,
            certified,
            ok: why.is_none(),
            why,
        }
    };
    (0..img.n_trajectories())
        .into_par_iter()
        .map(check)
        .collect()
}

/// Monte Carlo starts for a hybrid image (and a temporal task's): `interior` uniform samples of Init that
/// the image's f32 selection accepts (at most 100 draws per start), and `per_ball` points just inside the
/// boundary of every stored ball (at [`super::boundary_radius`] in its stored metric), seeded.
pub fn starts_from_image(
    bytes: &[u8],
    init: &crate::cover::estimate::SampleBox,
    interior: usize,
    per_ball: usize,
    seed: u64,
) -> Result<Vec<Vec<f64>>, String> {
    use rand::SeedableRng;
    let img = shared_types::image::decode(bytes).map_err(|e| format!("image: {e}"))?;
    let n = img.n();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let ctl = Controller::new(img);
    let mut out = Vec::new();
    let mut draws = 0usize;
    while out.len() < interior && draws < 100 * interior.max(1) {
        draws += 1;
        let x = init.sample(&mut rng);
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        // The selection the image's own step runs (for an image with model maps, its whitened test).
        if ctl.select_maps(&x32).is_some() {
            out.push(x);
        }
    }
    for t in 0..img.n_trajectories() {
        let (s0, _) = img.trajectory_segments(t);
        let l = img.segment(s0).map_or(0, |s| s.location);
        let P = crate::linalg::sym(faer::Mat::from_fn(n, n, |i, j| img.P(l, i, j) as f64).as_ref());
        let Some(roots) = crate::linalg::PdRoots::new(P.as_ref()) else {
            continue;
        };
        let delta = super::boundary_radius(&img, t);
        let c: Vec<f64> = (0..n).map(|i| img.centre(t, i) as f64).collect();
        for _ in 0..per_ball {
            out.push(point_on_sphere(&mut rng, &roots, &c, delta));
        }
    }
    Ok(out)
}

/// A point at P-distance `radius` from `c` in a uniformly random direction (of the whitened coordinates
/// P^{1/2}(x − c)), drawn from `rng` (Box–Muller normals).
pub fn point_on_sphere<R: rand::Rng>(
    rng: &mut R,
    roots: &crate::linalg::PdRoots,
    c: &[f64],
    radius: f64,
) -> Vec<f64> {
    let n = c.len();
    let w: Vec<f64> = (0..n)
        .map(|_| {
            let (a, b): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        })
        .collect();
    let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
    let dir: Vec<f64> = w.iter().map(|v| v / norm * radius).collect();
    let e = crate::linalg::mat_vec(roots.inv_sqrt.as_ref(), &dir);
    (0..n).map(|i| c[i] + e[i]).collect()
}
