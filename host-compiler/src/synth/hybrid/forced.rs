//! Runs of a hybrid plant with forced switching (§4.2.1, Def 4.15, Theorem 4.17; Example 4.20): the
//! controller chooses the location, so a run is a schedule of locations by sample and the image switches
//! by its table (a segment per location, no guard exits).
//!
//! **A nominal run.** From a seed x₀ in the initial location ℓ₀, the candidates are the run that stays in
//! ℓ₀, and for every forced edge ℓ₀ → ℓ₁ (whose guard holds the switching state) and every switching
//! fraction of [`SWITCH_FRACTIONS`], the run that switches at that sample. Each is generated over the
//! whole schedule at once by the SCP generator ([`crate::trajectory::generate::Schedule`]: the dynamics, the
//! gain and the tube metric of each step's location) over the horizons of [`HORIZONS`] (for an MTL task
//! the whole horizon only: the formula is judged over all of T, so the table must cover it), split into its
//! segments (the next segment starts at the reset of the last state, the identity for the resets the task
//! accepts) and certified backwards by [`crate::certify::forced`]. The run with the largest certified δ
//! is kept, then optimised segment by segment by §5.3 ([`optimise`]).
//!
//! **Many switches.** When no one-switch candidate certifies (a DC-DC boost converter switches every few
//! samples), the candidates are the whole schedules of the schedule search ([`schedule::search`]: a beam
//! over the locations sample by sample, scored by the plant's flow), generated and certified in the same
//! way. A task's runs whose one-switch candidates certify are planned as before; an MTL task's runs are
//! not searched (the search scores reach-avoid, not the formula).
//!
//! **Algorithm 4** (§5.4, [`grow_from`]): a run is grown from a point on another run's ball boundary by
//! that run's feedback law (its tables, locations and switching samples), then optimised the same way.
//!
//! The segments' tables are shipped as f32; each segment's nominal is simulated from the previous one's
//! shipped end, so the run is continuous across the switch as the certificate requires.

use super::{gen_problem, schedule, shipped_nominal, HybridRun, HybridTask};
use crate::certify::forced::{certify_forced, certify_forced_formula, ForcedSegment};
use crate::certify::internal::InternalCertificate;
use crate::model::hybrid::EdgeKind;
use crate::model::Location;
use crate::trajectory::generate::{generate, GenSettings, Schedule};
use crate::trajectory::Nominal;

/// Where in the run the switch is tried, as fractions of its length. An early switch (0.1) is what
/// carries a start whose own location's flow passes close to Unsafe away from it.
pub const SWITCH_FRACTIONS: [f64; 4] = [0.1, 0.3, 0.5, 0.7];
/// Run lengths tried, as fractions of the horizon T.
pub const HORIZONS: [f64; 3] = [0.5, 0.75, 1.0];

/// A candidate schedule: the location of each segment and the samples at which each but the first
/// begins.
struct Candidate {
    locations: Vec<Location>,
    edges: Vec<usize>,
    /// Steps of each segment.
    lengths: Vec<usize>,
}

/// Plan and certify a forced-switching run from `x0` (module doc): the best over the candidates, or why
/// none was certified. The run starts at `x0` rounded to f32 ([`super::f32_start`]).
pub fn plan_forced(task: &HybridTask, x0: &[f64]) -> Result<HybridRun, String> {
    let (run, edges) = planned(task, x0)?;
    Ok(optimise(task, run, &edges))
}

/// The best certified candidate from `x0` as generated (before §5.3), with its edges: the one-switch
/// candidates ([`plan_one_switch`]), and when none of them certifies, the schedules of the search
/// ([`schedule::search`], many switches).
fn planned(task: &HybridTask, x0: &[f64]) -> Result<(HybridRun, Vec<usize>), String> {
    let x0 = &super::f32_start(x0)[..];
    plan_one_switch(task, x0).or_else(|one| {
        best_of(task, x0, searched(task, x0)).map_err(|many| {
            if many == NO_CANDIDATE {
                one
            } else {
                format!("{one}; no searched schedule either: {many}")
            }
        })
    })
}

/// What [`best_of`] says of no candidates.
const NO_CANDIDATE: &str = "no candidate schedule";

/// The best certified run over the one-switch candidates from `x0` (module doc: stay, or switch once per
/// forced edge at each of [`SWITCH_FRACTIONS`], over [`HORIZONS`]), as generated, with its edges; or why
/// none certified. The run starts at `x0` rounded to f32.
pub fn plan_one_switch(task: &HybridTask, x0: &[f64]) -> Result<(HybridRun, Vec<usize>), String> {
    let x0 = &super::f32_start(x0)[..];
    let l0 = task.initial;
    let h = task.plant.period();
    let mut cands = Vec::new();
    for f in HORIZONS {
        // An MTL task is judged over the whole horizon, so its runs' tables cover all of T.
        if task.formula.is_some() && f < 1.0 {
            continue;
        }
        let total = ((f * task.problem.horizon / h).round() as usize).clamp(2, task.steps);
        cands.push(Candidate {
            locations: vec![l0],
            edges: vec![],
            lengths: vec![total],
        });
        for (e, edge) in task.plant.edges().iter().enumerate() {
            if edge.from != l0 || edge.to == l0 || edge.kind != EdgeKind::Forced {
                continue;
            }
            for s in SWITCH_FRACTIONS {
                let n0 = ((s * total as f64).round() as usize).clamp(1, total - 1);
                cands.push(Candidate {
                    locations: vec![l0, edge.to],
                    edges: vec![e],
                    lengths: vec![n0, total - n0],
                });
            }
        }
    }
    best_of(task, x0, cands)
}

/// The candidate whose generated run certifies the largest δ, with its edges; or the last reason one
/// was not certified.
fn best_of(
    task: &HybridTask,
    x0: &[f64],
    cands: Vec<Candidate>,
) -> Result<(HybridRun, Vec<usize>), String> {
    let mut best: Option<(HybridRun, Vec<usize>)> = None;
    let mut why = String::from(NO_CANDIDATE);
    for c in cands {
        match plan_schedule(task, x0, &c) {
            Ok(run) => {
                if best.as_ref().is_none_or(|(b, _)| run.delta() > b.delta()) {
                    best = Some((run, c.edges));
                }
            }
            Err(e) => why = e,
        }
    }
    best.ok_or(why)
}

/// The candidates of the schedule search ([`schedule::search`]) from `x0`, for a reach-avoid task (an
/// MTL task's runs cover the whole horizon and are judged by its formula, which the search does not
/// score): each whole schedule it found as segments joined by the forced edges between them.
fn searched(task: &HybridTask, x0: &[f64]) -> Vec<Candidate> {
    if task.formula.is_some() {
        return Vec::new();
    }
    let found = schedule::search(task, x0, task.steps, &schedule::ScheduleSettings::default());
    found
        .iter()
        .filter_map(|f| {
            let (locations, lengths): (Vec<Location>, Vec<usize>) =
                f.segments().into_iter().unzip();
            let edges = edges_of(task, &locations)?;
            Some(Candidate {
                locations,
                edges,
                lengths,
            })
        })
        .collect()
}

/// Forward sweeps of §5.3 over a run's segments ([`optimise`]).
pub const SWEEPS: usize = 2;
/// Relative change of a δ that [`optimise`] reads as rounding, not as a change.
const NOISE: f64 = 1e-6;

/// §5.3 over the segments of a forced-switching run (Theorem 4.17 read forwards), for a reach-avoid task.
///
/// Segment i's δ is the least of its own Unsafe and input parts and its depth in the safe transition into
/// segment i+1's ball; a run continuous across the switch ends at that ball's centre, so the depth is as
/// large as it can be and what binds is the segment's own parts (Example 4.20: Unsafe between samples).
/// Each sweep maximises, segment by segment from the first, the certified δ of the segment's own loop
/// ([`crate::certify::forced::with_segment_loop`]: its goal the safe transition into the next segment's
/// current ball, its table length fixed, since the table's end is the switching sample), then re-simulates
/// the later segments from the new end with their own tables (the run stays continuous), and lastly
/// maximises the last segment against Goal, its terminal step free within the horizon. A nominal that
/// keeps depth d in the transition ends within δᵢ₊₁ − d (roughly) of the old start, so the re-simulated
/// next segment keeps about d: a step trades the segment's transition depth for its own parts. A step is
/// kept when the re-certified run's δ does not fall and the optimised segment's δ rises; the answer is
/// always [`certify_run`]'s. An MTL task's runs are left as planned (its certificate, Def 4.18, is not
/// the pieces the optimiser differentiates).
fn optimise(task: &HybridTask, run: HybridRun, edges: &[usize]) -> HybridRun {
    use crate::optimize::{maximize_delta, BundleSettings};
    let iterations = task.problem.synthesis.max_iterations;
    if task.formula.is_some() || iterations == 0 {
        return run;
    }
    let settings = |terminal| {
        BundleSettings::builder()
            .max_iterations(iterations)
            .terminal_time(terminal)
            .build()
    };
    let (Ok(fixed), Ok(free)) = (settings(false), settings(true)) else {
        return run;
    };
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let last = run.nominals.len() - 1;
    let mut best = run;
    for _ in 0..SWEEPS {
        let before = best.delta();
        for i in 0..=last {
            let loc = best.locations[i];
            let earlier: usize = best.nominals[..i].iter().map(|n| n.steps()).sum();
            let nom = &best.nominals[i];
            let steps_max = if i == last {
                task.steps.saturating_sub(earlier).max(nom.steps())
            } else {
                nom.steps()
            };
            let next_delta = best
                .certificate
                .segments
                .get(i + 1)
                .map_or(0.0, |s| s.delta);
            let segs = segments(task, &best.locations, edges, &best.nominals);
            let opt = crate::certify::forced::with_segment_loop(&segs, i, next_delta, |lp| {
                maximize_delta(
                    lp,
                    &task.constants[loc],
                    &nom.x[0],
                    &nom.v,
                    steps_max,
                    if i == last { &free } else { &fixed },
                    &cancel,
                )
            });
            let Ok(opt) = opt else { break };
            if i < last && opt.nominal.steps() != nom.steps() {
                continue;
            }
            // The run with segment i's new table, the later segments re-simulated from each new end.
            let mut nominals = best.nominals[..i].to_vec();
            let tables = best.nominals[i..].iter().enumerate().map(|(j, old)| {
                if j == 0 {
                    &opt.nominal.v[..]
                } else {
                    &old.v[..]
                }
            });
            nominals.extend(chain(task, &nom.x[0], &best.locations[i..], tables));
            let Ok(certificate) = certify_run(task, &best.locations, edges, &nominals) else {
                continue;
            };
            let (old0, new0) = (best.delta(), certificate.delta());
            let (old_i, new_i) = (
                best.certificate.segments[i].delta,
                certificate.segments[i].delta,
            );
            // Re-certifying the first segment against a changed next ball moves its δ by rounding only
            // (its own parts are unchanged), so "does not fall" allows that.
            if new0 > old0 || (new0 >= old0 * (1.0 - NOISE) && new_i > old_i * (1.0 + NOISE)) {
                best = HybridRun {
                    nominals,
                    locations: best.locations.clone(),
                    certificate,
                };
            }
        }
        if best.delta() <= before {
            break;
        }
    }
    best
}

/// Generate, split and certify one schedule.
fn plan_schedule(task: &HybridTask, x0: &[f64], c: &Candidate) -> Result<HybridRun, String> {
    let total: usize = c.lengths.iter().sum();
    let loc: Vec<Location> = c
        .locations
        .iter()
        .zip(&c.lengths)
        .flat_map(|(&l, &n)| std::iter::repeat_n(l, n))
        .collect();
    let schedule = Schedule {
        loc,
        K: task.designs.iter().map(|d| d.K.as_ref()).collect(),
        P: task.designs.iter().map(|d| d.P.as_ref()).collect(),
    };
    let mut gp = gen_problem(task, c.locations[0], &task.convex, total);
    for &l in &c.locations {
        let lc = &task.constants[l];
        gp.gamma = gp.gamma.max(lc.gamma);
        gp.phi = gp.phi.max(lc.phi);
        gp.beta = gp.beta.max(lc.beta);
    }
    gp.schedule = Some(&schedule);
    let names: Vec<&str> = c
        .locations
        .iter()
        .map(|&l| task.plant.modes()[l].name.as_str())
        .collect();
    let g = generate(&gp, x0, &GenSettings::default())
        .map_err(|e| format!("schedule {}: {e}", names.join(" → ")))?;
    let tables = c.lengths.iter().scan(0usize, |k0, &n| {
        *k0 += n;
        Some(&g.nominal.v[*k0 - n..*k0])
    });
    let nominals = chain(task, x0, &c.locations, tables);
    let certificate = certify_run(task, &c.locations, &c.edges, &nominals)?;
    Ok(HybridRun {
        nominals,
        locations: c.locations.clone(),
        certificate,
    })
}

/// The nominals of a run from `x0` through `locations`, segment i under the i-th of `tables` (rounded to
/// f32 as shipped), each segment simulated from the previous one's shipped end: the identity reset, the
/// only one a forced-switching task accepts ([`HybridTask::new`]), so the run is continuous across every
/// switch.
fn chain<'v>(
    task: &HybridTask,
    x0: &[f64],
    locations: &[Location],
    tables: impl IntoIterator<Item = &'v [Vec<f64>]>,
) -> Vec<Nominal> {
    let mut start = x0.to_vec();
    locations
        .iter()
        .zip(tables)
        .map(|(&l, v)| {
            let nom = shipped_nominal(task, l, &start, v);
            start = nom.x.last().cloned().unwrap_or_default();
            nom
        })
        .collect()
}

/// The forced edge joining each pair of consecutive `locations` (the first from one to the next, as the
/// image's re-proof and the plant take it); `None` when a pair has none.
fn edges_of(task: &HybridTask, locations: &[Location]) -> Option<Vec<usize>> {
    locations
        .windows(2)
        .map(|w| task.plant.edge_index(w[0], w[1], EdgeKind::Forced))
        .collect()
}

/// Algorithm 4 (§5.4) for a forced-switching run: `parent`'s feedback law from `y` (a point on the
/// boundary of its ball, f32), i.e. the run through the same locations with the same tables, so switching
/// at the same samples (in the loop's form u = Kx + v the law u = K(x − x̃) + ũ is v = ṽ), certified,
/// then optimised by §5.3 ([`optimise`]). `Err` says why it was not certified.
pub fn grow_from(task: &HybridTask, parent: &HybridRun, y: &[f64]) -> Result<HybridRun, String> {
    let y = &super::f32_start(y)[..];
    let edges = edges_of(task, &parent.locations)
        .ok_or("no forced edge joins the parent run's locations")?;
    let tables = parent.nominals.iter().map(|n| &n.v[..]);
    let nominals = chain(task, y, &parent.locations, tables);
    let certificate = certify_run(task, &parent.locations, &edges, &nominals)?;
    let run = HybridRun {
        nominals,
        locations: parent.locations.clone(),
        certificate,
    };
    Ok(optimise(task, run, &edges))
}

/// Theorem 4.17 for a run of segments in `locations`, joined by `edges` (Def 4.18 when the task is an MTL
/// formula), as the hybrid pipeline stores a run's certificate ([`ForcedCertificate::as_segments`]).
pub fn certify_run(
    task: &HybridTask,
    locations: &[Location],
    edges: &[usize],
    nominals: &[Nominal],
) -> Result<InternalCertificate, String> {
    let segs = segments(task, locations, edges, nominals);
    let Some(tt) = &task.formula else {
        let cert = certify_forced(&segs).map_err(|e| e.to_string())?;
        return Ok(cert.as_segments(nominals));
    };
    // An MTL task (Def 4.18): each segment's radius is min(t, its own δ); name the formula where it binds.
    let cert = certify_forced_formula(&segs, tt).map_err(|e| e.to_string())?;
    let mut out = cert.base.as_segments(nominals);
    for (seg, &bound) in out.segments.iter_mut().zip(&cert.formula_bound) {
        if bound {
            seg.binding = "the formula (Def 4.18)";
        }
    }
    Ok(out)
}

/// The segments of a run in `locations`, joined by `edges`, as [`crate::certify::forced`] takes them.
fn segments<'a>(
    task: &'a HybridTask,
    locations: &[Location],
    edges: &[usize],
    nominals: &'a [Nominal],
) -> Vec<ForcedSegment<'a>> {
    locations
        .iter()
        .zip(nominals)
        .enumerate()
        .map(|(i, (&l, nom))| ForcedSegment {
            lp: task.lp(l),
            lc: &task.constants[l],
            nominal: nom,
            switch: edges.get(i).map(|&e| &task.plant.edges()[e]),
            invariant: task.plant.modes()[l].invariant.as_ref(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example_4_20() -> HybridTask {
        let path = format!(
            "{}/../examples/hybrid-forced-4-20.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        HybridTask::new(crate::spec::load(&path).expect("the example parses"))
            .expect("a hybrid task")
    }

    #[test]
    fn optimising_a_run_of_example_4_20_raises_its_certified_delta_and_keeps_its_switching_sample()
    {
        let task = example_4_20();
        let (run, edges) = planned(&task, &[3.5, -6.0, 0.0, 0.0]).expect("a run from the seed");
        assert_eq!(run.nominals.len(), 2, "the seed's best run switches once");
        let opt = optimise(&task, run.clone(), &edges);
        // The answer is the certificate of what it ships, continuous across the switch (certify_run
        // refuses a gap), switching at the same sample.
        let again = certify_run(&task, &opt.locations, &edges, &opt.nominals).expect("continuous");
        assert_eq!(again, opt.certificate);
        assert_eq!(opt.nominals[0].steps(), run.nominals[0].steps());
        assert_eq!(opt.locations, run.locations);
        assert!(
            opt.delta() > 1.03 * run.delta(),
            "δ {} → {}",
            run.delta(),
            opt.delta()
        );
    }

    #[test]
    fn algorithm_4_grows_a_run_of_example_4_20_from_its_ball_s_boundary_with_its_schedule() {
        let task = example_4_20();
        let parent = plan_forced(&task, &[3.5, -6.0, 0.0, 0.0]).expect("a run from the seed");
        // A point on the parent's ball boundary along x (velocities stay 0, as in Init).
        let P = task.designs[task.initial].P.as_ref();
        let c = &parent.nominals[0].x[0];
        let y = crate::cover::alg4::project_onto_boundary(
            P,
            &[c[0] + 1.0, c[1], c[2], c[3]],
            c,
            parent.certificate.delta_stored as f64,
        )
        .expect("off the centre");
        let grown = grow_from(&task, &parent, &y).expect("certified");
        assert!(grown.certificate.is_certified(), "{:?}", grown.certificate);
        assert_eq!(grown.nominals[0].x[0], y, "it starts where it was asked to");
        assert_eq!(grown.locations, parent.locations);
        assert_eq!(grown.nominals[0].steps(), parent.nominals[0].steps());
        let edges = edges_of(&task, &grown.locations).expect("joined by forced edges");
        let again =
            certify_run(&task, &grown.locations, &edges, &grown.nominals).expect("continuous");
        assert_eq!(again, grown.certificate, "the answer is what it ships");
        // Its ball reaches past the parent's: the point just outside the parent's ball along the ray.
        let out: Vec<f64> = y.iter().zip(c).map(|(a, b)| a + 0.5 * (a - b)).collect();
        let e: Vec<f64> = out.iter().zip(&y).map(|(a, b)| a - b).collect();
        assert!(
            crate::linalg::p_norm(P, &e) < grown.delta(),
            "δ = {} from y",
            grown.delta()
        );
    }
}
