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
//! is kept.
//!
//! The segments' tables are shipped as f32; each segment's nominal is simulated from the previous one's
//! shipped end, so the run is continuous across the switch as the certificate requires.

use super::{gen_problem, shipped_nominal, HybridRun, HybridTask};
use crate::certify::forced::{certify_forced, certify_forced_formula, ForcedSegment};
use crate::certify::internal::InternalCertificate;
use crate::model::hybrid::EdgeKind;
use crate::model::Location;
use crate::trajectory::generate::{generate, GenSettings, Schedule};
use crate::trajectory::Nominal;

/// Where in the run the switch is tried, as fractions of its length.
pub const SWITCH_FRACTIONS: [f64; 3] = [0.3, 0.5, 0.7];
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
    let mut best: Option<HybridRun> = None;
    let mut why = String::from("no candidate schedule");
    for c in &cands {
        match plan_schedule(task, x0, c) {
            Ok(run) => {
                if best.as_ref().is_none_or(|b| run.delta() > b.delta()) {
                    best = Some(run);
                }
            }
            Err(e) => why = e,
        }
    }
    best.ok_or(why)
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
    // Split into segments, each simulated from the previous one's shipped end.
    let mut nominals: Vec<Nominal> = Vec::with_capacity(c.lengths.len());
    let mut start = x0.to_vec();
    let mut k0 = 0usize;
    for (&l, &n) in c.locations.iter().zip(&c.lengths) {
        let nom = shipped_nominal(task, l, &start, &g.nominal.v[k0..k0 + n]);
        start = nom.x.last().cloned().unwrap_or_default();
        k0 += n;
        nominals.push(nom);
    }
    let certificate = certify_run(task, &c.locations, &c.edges, &nominals)?;
    Ok(HybridRun {
        nominals,
        locations: c.locations.clone(),
        certificate,
    })
}

/// Theorem 4.17 for a run of segments in `locations`, joined by `edges` (Def 4.18 when the task is an MTL
/// formula), as the hybrid pipeline stores a run's certificate ([`ForcedCertificate::as_segments`]).
pub fn certify_run(
    task: &HybridTask,
    locations: &[Location],
    edges: &[usize],
    nominals: &[Nominal],
) -> Result<InternalCertificate, String> {
    let segs: Vec<ForcedSegment> = locations
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
        .collect();
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
