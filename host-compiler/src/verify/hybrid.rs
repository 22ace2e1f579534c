//! Closed-loop Monte Carlo of a hybrid image (§4.2.2): the shared-types evaluator in f32, with its segment
//! exits, against the automaton's exact flow ([`Hybrid::flow`]: events found between samples, resets
//! applied), independent of how the certificate was made.
//!
//! Each run starts in the initial location and is stepped over the horizon: the evaluator's input for the
//! measured state (rounded to f32), held for one period; the flow is taken in [`SUBSTEPS`] exact
//! sub-periods, and Unsafe is checked at every sub-sample (so also shortly after each event). A run
//! meets the task at its first sample in Goal if, up to then, it never was in Unsafe, every input was in
//! the input set, and the evaluator never left its certified envelope.

use crate::model::hybrid::{FlowError, Hybrid};
use crate::model::Location;
use crate::property::{InputBound, ReachAvoid};
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

fn input_ok(input: &InputBound, u: &[f32]) -> bool {
    match input {
        InputBound::Box { lo, hi } => u
            .iter()
            .zip(lo.iter().zip(hi))
            .all(|(&v, (&l, &h))| l <= v as f64 && v as f64 <= h),
        InputBound::Norm2 { center, max } => {
            u.iter()
                .zip(center)
                .map(|(&v, c)| (v as f64 - c).powi(2))
                .sum::<f64>()
                .sqrt()
                <= *max
        }
    }
}

/// Runs the image `bytes` from each start (in location `initial`) for `steps` samples (module doc). A
/// start the evaluator does not select a ball for is counted as rejected, not run.
pub fn monte_carlo_hybrid(
    plant: &Hybrid,
    property: &ReachAvoid,
    initial: Location,
    steps: usize,
    bytes: &[u8],
    starts: &[Vec<f64>],
) -> Result<HybridReport, String> {
    let image = shared_types::image::decode(bytes).map_err(|e| format!("image: {e}"))?;
    let fine = Hybrid::new(
        plant.modes().to_vec(),
        plant.edges().to_vec(),
        plant.period() / SUBSTEPS as f64,
    )
    .map_err(|e| e.to_string())?;
    let euclid = crate::geometry::Metric::euclidean(plant.modes()[0].flow.n());
    let mut rep = HybridReport {
        min_unsafe_distance: f64::INFINITY,
        ..Default::default()
    };
    for x0 in starts {
        rep.runs += 1;
        let mut ctl = Controller::new(image);
        let x32: Vec<f32> = x0.iter().map(|&v| v as f32).collect();
        if ctl.select(&x32).is_none() {
            rep.rejected += 1;
            continue;
        }
        let (mut x, mut loc) = (x0.clone(), initial);
        let mut events = 0usize;
        let mut why: Option<String> = None;
        let mut reached = false;
        'run: for k in 0..=steps {
            if property.goal.contains(&x) {
                rep.max_goal_step = rep.max_goal_step.max(k);
                reached = true;
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
                        "sample {k}: the evaluator answered {s:?} at x = {x:?}"
                    ));
                    break;
                }
            };
            if !input_ok(&property.input, u.as_slice()) {
                why = Some(format!(
                    "sample {k}: input {:?} outside the input set",
                    u.as_slice()
                ));
                break;
            }
            let u64s: Vec<f64> = u.as_slice().iter().map(|&v| v as f64).collect();
            for _ in 0..SUBSTEPS {
                let step = fine
                    .flow(loc, &x, &u64s)
                    .map_err(|e: FlowError| e.to_string())?;
                events += step.events.len();
                x = step.x;
                loc = step.loc;
                if let Some(us) = property.unsafe_region() {
                    let d = us.dist(&x, &euclid).value;
                    rep.min_unsafe_distance = rep.min_unsafe_distance.min(d);
                    if us.contains(&x) {
                        why = Some(format!("sample {k}: in Unsafe at x = {x:?}"));
                        break 'run;
                    }
                }
            }
        }
        if why.is_none() && !reached {
            why = Some(format!("Goal not reached within {steps} samples"));
        }
        if events > 0 {
            rep.switched += 1;
        }
        rep.max_events = rep.max_events.max(events);
        if let Some(w) = why {
            rep.violations += 1;
            if rep.first_violation.is_none() {
                rep.first_violation = Some(format!("start {x0:?}: {w}"));
            }
        }
    }
    Ok(rep)
}
