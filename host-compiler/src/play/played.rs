//! What the game plays (§1.1.3; §4.2.2 for hybrid plants): a one-location task with its CAF, or a hybrid
//! automaton with internal switching with a CAF per location, and for each how a period is stepped and
//! how a finished run is certified: the one-location import path ([`crate::cover::certify_recording`],
//! Theorem 4.7) or the hybrid one ([`crate::synth::hybrid::import::certify_recording`], Theorem 4.24
//! along the task's location path). The game asks only this of the task.

use crate::caf::Design;
use crate::certify::{Certificate, Loop, LoopConstants};
use crate::linalg::PdRoots;
use crate::model::hybrid::Hybrid;
use crate::model::{Location, Plant};
use crate::property::ReachAvoid;
use crate::spec::{InitBox, Problem};
use crate::synth::hybrid::{import, HybridRun, HybridTask};
use crate::task::Task;
use crate::trajectory::csv::Recording;
use faer::MatRef;

/// Probes of the exact hybrid flow per period at which a played run is checked against Unsafe.
pub const HYBRID_PROBES: usize = 8;

/// The task a game plays (one per game, so the variants' sizes do not matter).
#[allow(clippy::large_enum_variant)]
pub enum Played {
    /// A one-location task with its CAF as `synth` designs it.
    One {
        task: Task,
        design: Design,
        lc: LoopConstants,
    },
    /// A hybrid task with internal switching; `fine` is its automaton sampled at h / [`HYBRID_PROBES`],
    /// to look between samples across events.
    Hybrid { task: HybridTask, fine: Hybrid },
}

/// A finished run certified: accepted (a ball over Init, the certified path) or refused with a reason.
pub struct Judged {
    /// The first ball's centre, its certified and stored radius (0 when refused).
    pub centre: Vec<f64>,
    pub delta: f64,
    pub delta_stored: f32,
    /// The certified nominal's states (the segments' states up to their switch, for a hybrid run).
    pub path: Vec<Vec<f64>>,
    /// `Ok`: what limits δ; `Err`: why it is refused.
    pub verdict: Result<String, String>,
    /// The one-location certificate (for the game's message of which part binds).
    pub certificate: Option<Certificate>,
}

impl Played {
    /// A one-location task with its CAF designed as `synth` designs it.
    pub fn one(task: Task) -> Result<Self, String> {
        let design = crate::caf::design(&task).map_err(|e| format!("no CAF and feedback: {e}"))?;
        let lc = LoopConstants::new(&Loop::new(&task, &design)).map_err(|e| e.to_string())?;
        Ok(Played::One { task, design, lc })
    }

    /// A hybrid task (its CAFs and path built by [`HybridTask::new`]).
    pub fn hybrid(task: HybridTask) -> Result<Self, String> {
        let fine = task
            .plant
            .resampled(task.plant.period() / HYBRID_PROBES as f64)
            .map_err(|e| e.to_string())?;
        Ok(Played::Hybrid { task, fine })
    }

    pub fn plant(&self) -> &dyn Plant {
        match self {
            Played::One { task, .. } => &*task.plant,
            Played::Hybrid { task, .. } => &task.plant,
        }
    }
    pub fn problem(&self) -> &Problem {
        match self {
            Played::One { task, .. } => &task.problem,
            Played::Hybrid { task, .. } => &task.problem,
        }
    }
    pub fn property(&self) -> &ReachAvoid {
        match self {
            Played::One { task, .. } => &task.property,
            Played::Hybrid { task, .. } => &task.property,
        }
    }
    /// Samples in the horizon.
    pub fn steps(&self) -> usize {
        match self {
            Played::One { task, .. } => task.steps,
            Played::Hybrid { task, .. } => task.steps,
        }
    }
    pub fn init(&self) -> &InitBox {
        &self.problem().init
    }
    /// The location a run starts in.
    pub fn initial(&self) -> Location {
        match self {
            Played::One { .. } => 0,
            Played::Hybrid { task, .. } => task.initial,
        }
    }
    /// The name of location `loc` (empty for a one-location plant).
    pub fn location_name(&self, loc: Location) -> &str {
        match self {
            Played::One { .. } => "",
            Played::Hybrid { task, .. } => {
                task.plant.modes().get(loc).map_or("", |m| m.name.as_str())
            }
        }
    }
    /// The shipped gain of location `loc`.
    pub fn K(&self, loc: Location) -> MatRef<'_, f64> {
        match self {
            Played::One { design, .. } => design.K.as_ref(),
            Played::Hybrid { task, .. } => task.designs[loc.min(task.designs.len() - 1)].K.as_ref(),
        }
    }
    /// The metric of the balls over Init (the initial location's CAF) and its roots.
    pub fn P(&self) -> MatRef<'_, f64> {
        match self {
            Played::One { design, .. } => design.P.as_ref(),
            Played::Hybrid { task, .. } => task.designs[task.initial].P.as_ref(),
        }
    }
    pub fn roots(&self) -> &PdRoots {
        match self {
            Played::One { lc, .. } => &lc.roots,
            Played::Hybrid { task, .. } => &task.constants[task.initial].roots,
        }
    }
    /// The tube's metric is the balls' along the whole run (one location only).
    pub fn one_metric(&self) -> bool {
        matches!(self, Played::One { .. })
    }

    /// One period from (`loc`, `x`) with `u` held: the location and state at the next sample, every
    /// state looked at between the samples passed to `visit`. A one-location plant: its step and states
    /// between samples; a hybrid one: the exact flow across events ([`Hybrid::flow`]), looked at
    /// [`HYBRID_PROBES`] times in the period. `Err`: the flow cannot be stepped (Zeno, undecided).
    pub fn advance(
        &self,
        loc: Location,
        x: &[f64],
        u: &[f64],
        visit: &mut dyn FnMut(&[f64]),
    ) -> Result<(Location, Vec<f64>), String> {
        match self {
            Played::One { task, .. } => {
                task.plant.between_samples(loc, x, u, visit);
                Ok((loc, task.plant.step(loc, x, u)))
            }
            Played::Hybrid { task, fine } => {
                let (mut l, mut y) = (loc, x.to_vec());
                for _ in 0..HYBRID_PROBES {
                    let s = fine.flow(l, &y, u).map_err(|e| e.to_string())?;
                    (l, y) = (s.loc, s.x);
                    visit(&y);
                }
                let s = task.plant.flow(loc, x, u).map_err(|e| e.to_string())?;
                Ok((s.loc, s.x))
            }
        }
    }

    /// A finished run's recording certified by the import path of its class (module doc).
    pub fn judge(&self, rec: &Recording) -> Judged {
        match self {
            Played::One { task, design, lc } => {
                let (nominal, cert) =
                    crate::cover::certify_recording(&Loop::new(task, design), lc, rec);
                Judged {
                    centre: nominal.x[0].clone(),
                    delta: cert.delta,
                    delta_stored: cert.delta_stored,
                    path: nominal.x,
                    verdict: if cert.is_certified() {
                        Ok(String::new())
                    } else {
                        Err(String::new())
                    },
                    certificate: Some(cert),
                }
            }
            Played::Hybrid { task, .. } => match import::certify_recording(task, rec) {
                Ok(run) => Judged {
                    centre: run.nominals[0].x[0].clone(),
                    delta: run.delta(),
                    delta_stored: run.certificate.delta_stored,
                    path: hybrid_path(task, &run),
                    verdict: Ok(import::bindings(task, &run.certificate)),
                    certificate: None,
                },
                Err(e) => Judged {
                    centre: rec.x0.clone(),
                    delta: 0.0,
                    delta_stored: 0.0,
                    path: Vec::new(),
                    verdict: Err(e.to_string()),
                    certificate: None,
                },
            },
        }
    }
}

/// A hybrid run's states for the map: each segment's nominal until it enters its exit guard (the extended
/// part past the switch is not where the run goes), the last one whole.
fn hybrid_path(task: &HybridTask, run: &HybridRun) -> Vec<Vec<f64>> {
    let mut out = Vec::new();
    for (i, nom) in run.nominals.iter().enumerate() {
        match task.edges.get(i) {
            Some(&e) => {
                let guard = &task.plant.edges()[e].guard;
                out.extend(nom.x.iter().take_while(|x| !guard.contains(x)).cloned());
            }
            None => out.extend(nom.x.iter().cloned()),
        }
    }
    out
}
