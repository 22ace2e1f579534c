//! What the game plays (§1.1.3): the task's plant, for each class how a period is stepped and how a
//! finished run is certified. The game asks only this of the task.
//!
//! * **One location** (linear affine): the plant's exact step; the one-location import path
//!   ([`crate::cover::certify_recording`], Theorem 4.7), or for an `[mtl]` task its formula's
//!   ([`crate::synth::temporal::certify_recording`], Theorem 4.2), judged over the whole horizon (a run goes
//!   on to T).
//! * **Feedback linearizable** (§3.1.2): the task is the linear model in ξ and the page draws ξ, but the
//!   server flows the *nonlinear plant* (`model::nonlinear`, Dop853) under the law the firmware runs:
//!   w = K ξ(x) + v clipped to the task's input set W, u = λ(x)(w − α_res(x)) (the model's f64 expressions;
//!   W is pulled back so that u is in the plant's input set). A run starts at the player's ξ with the
//!   zero-dynamics states at the centre of the plant's Init. Its recording is in the task's coordinates
//!   (x0 = ξ(0), rows the reference v) and is certified by the one-location path on the ξ model with the
//!   sampled-loop mismatch D (Theorem 3.21), exactly as `synth --import` certifies it; the certified
//!   nominal is the ξ model's run under the played v, which the played plant follows within the tube.
//! * **Hybrid, internal switching** (§4.2.2): the automaton's exact flow across events; runs certified
//!   along the task's location path by Theorem 4.24 ([`crate::synth::hybrid::import::certify_recording`]).
//! * **Hybrid, forced switching** (§4.2.1): the player is the discrete input. A switch to a location by a
//!   forced edge is taken at a sample whose state is in the edge's guard (the resets the task accepts are
//!   the identity); each row is recorded with its location, and the run is certified by Theorem 4.17 (Def
//!   4.18 when the task is a formula, which is then judged over the whole horizon, so the run goes on to T).

use crate::caf::Design;
use crate::certify::temporal::TemporalLoop;
use crate::certify::{Certificate, Loop, LoopConstants};
use crate::linalg::PdRoots;
use crate::model::feedback_linearizable::FlMaps;
use crate::model::hybrid::{EdgeKind, Hybrid};
use crate::model::{Location, Plant};
use crate::property::{ReachAvoid, TemporalTask};
use crate::spec::{InitBox, Problem};
use crate::synth::hybrid::{import, HybridRun, HybridTask};
use crate::task::Task;
use crate::trajectory::csv::Recording;
use faer::MatRef;

/// Probes of the exact hybrid flow per period at which a played run is checked against Unsafe.
pub const HYBRID_PROBES: usize = 8;

/// Where [`Played::advance`] shows the states it looks at between samples (none: not looked at).
pub type Visit<'a> = Option<&'a mut dyn FnMut(&[f64])>;

/// The task a game plays (one per game, so the variants' sizes do not matter).
#[allow(clippy::large_enum_variant)]
pub enum Played {
    /// A one-location task with its CAF as `synth` designs it.
    One {
        task: Task,
        design: Design,
        lc: LoopConstants,
        /// The task's formula, when the spec's task is one (runs certified by Theorem 4.2).
        temporal: Option<TemporalTask>,
    },
    /// A hybrid task (internal or forced switching); `fine` is its automaton sampled at
    /// h / [`HYBRID_PROBES`], to look between samples across events.
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
    /// A one-location task with its CAF designed as `synth` designs it. A task whose spec is an MTL
    /// formula is refused: this path certifies reach-avoid runs (Theorem 4.7).
    pub fn one(task: Task) -> Result<Self, String> {
        let temporal = match task.problem.mtl {
            Some(_) => Some(TemporalTask::from_problem(&task.problem).map_err(|e| e.to_string())?),
            None => None,
        };
        let design = crate::caf::design(&task).map_err(|e| format!("no CAF and feedback: {e}"))?;
        let lc = LoopConstants::new(&Loop::new(&task, &design)).map_err(|e| e.to_string())?;
        Ok(Played::One {
            task,
            design,
            lc,
            temporal,
        })
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

    /// A feedback-linearizable plant's maps (module doc), when the task is one.
    pub fn maps(&self) -> Option<&FlMaps> {
        match self {
            Played::One { task, .. } => task.plant.linearization(),
            Played::Hybrid { .. } => None,
        }
    }

    /// Whether the automaton's edges are forced (the player chooses the location).
    pub fn forced(&self) -> bool {
        matches!(self, Played::Hybrid { task, .. } if task.forced)
    }

    /// Whether the task is a formula (judged over the whole horizon: a run ends only at T, in Unsafe, or
    /// when the player finishes it).
    pub fn formula(&self) -> bool {
        match self {
            Played::One { temporal, .. } => temporal.is_some(),
            Played::Hybrid { task, .. } => task.formula.is_some(),
        }
    }

    /// The forced edges (from, to) the player can take, in the automaton's order.
    pub fn switches(&self) -> Vec<(Location, Location)> {
        match self {
            Played::Hybrid { task, .. } if task.forced => task
                .plant
                .edges()
                .iter()
                .filter(|e| e.kind == EdgeKind::Forced && e.from != e.to)
                .map(|e| (e.from, e.to))
                .collect(),
            _ => Vec::new(),
        }
    }

    /// The location a forced switch from `from` to the location named `to` lands in, when the state `x`
    /// is in the edge's guard; otherwise why not.
    pub fn switch(&self, from: Location, to: &str, x: &[f64]) -> Result<Location, String> {
        let Played::Hybrid { task, .. } = self else {
            return Err("the plant has one location".into());
        };
        if !task.forced {
            return Err("the automaton switches by itself (internal edges)".into());
        }
        let modes = task.plant.modes();
        let l = modes
            .iter()
            .position(|m| m.name == to)
            .ok_or_else(|| format!("`{to}` is not a location of the automaton"))?;
        if l == from {
            return Ok(l);
        }
        let e = task.plant.forced_edge(from, l).ok_or_else(|| {
            format!(
                "no forced edge leads from {} to {}",
                modes[from].name, modes[l].name
            )
        })?;
        let m = e.guard.margin(x);
        if m > 0.0 {
            return Err(format!(
                "the state is not in the guard of {} → {} (outside one of its faces by {m:.3e}); the switch \
                 waits",
                modes[from].name, modes[l].name
            ));
        }
        Ok(l)
    }

    /// The plant's own state at the start of a run from `x0` in the task's coordinates: for a
    /// feedback-linearizable plant ξ's states from `x0`, the zero-dynamics states at Init's centre.
    pub fn plant_start(&self, x0: &[f64]) -> Vec<f64> {
        let Some(maps) = self.maps() else {
            return x0.to_vec();
        };
        let mut x = maps.init.centre();
        for (j, &s) in maps.xi_states.iter().enumerate() {
            x[s] = x0[j];
        }
        x
    }

    /// The task's coordinates of a plant state (ξ for a feedback-linearizable plant).
    pub fn observe(&self, plant_x: &[f64]) -> Vec<f64> {
        match self.maps() {
            Some(maps) => maps.xi_of(plant_x),
            None => plant_x.to_vec(),
        }
    }

    /// One period from (`loc`, the plant state `x`) with the task's input `u` held: the location and the
    /// plant state at the next sample. With `visit`, every state looked at between the samples is passed
    /// to it in the task's coordinates: a one-location plant's states between samples; a hybrid one's
    /// exact flow across events ([`Hybrid::flow`]) looked at [`HYBRID_PROBES`] times in the period; a
    /// feedback-linearizable plant's integrated flow at as many instants. `Err`: the flow cannot be
    /// stepped (Zeno, undecided, the integrator failed).
    pub fn advance(
        &self,
        loc: Location,
        x: &[f64],
        u: &[f64],
        visit: Visit<'_>,
    ) -> Result<(Location, Vec<f64>), String> {
        if let Some(maps) = self.maps() {
            let uu = self.plant_input(maps, x, u);
            let h = maps.plant.period();
            let (sub, mut visit) = match visit {
                Some(v) => (HYBRID_PROBES, Some(v)),
                None => (1, None),
            };
            let next = maps
                .plant
                .flow(x, &uu, h, sub, &mut |y| {
                    if let Some(v) = visit.as_mut() {
                        v(&maps.xi_of(y))
                    }
                })
                .map_err(|e| e.to_string())?;
            return Ok((loc, next));
        }
        match (self, visit) {
            (Played::One { task, .. }, visit) => {
                if let Some(v) = visit {
                    task.plant.between_samples(loc, x, u, v);
                }
                Ok((loc, task.plant.step(loc, x, u)))
            }
            (Played::Hybrid { task, fine }, Some(visit)) => {
                let (mut l, mut y) = (loc, x.to_vec());
                for _ in 0..HYBRID_PROBES {
                    let s = fine.flow(l, &y, u).map_err(|e| e.to_string())?;
                    (l, y) = (s.loc, s.x);
                    visit(&y);
                }
                let s = task.plant.flow(loc, x, u).map_err(|e| e.to_string())?;
                Ok((s.loc, s.x))
            }
            (Played::Hybrid { task, .. }, None) => {
                let s = task.plant.flow(loc, x, u).map_err(|e| e.to_string())?;
                Ok((s.loc, s.x))
            }
        }
    }

    /// The plant's input of a feedback-linearizable plant at `x` for the linear law's output `w`:
    /// u = λ(x)(w − α_res(x)) in f64 (the model's expressions).
    pub fn plant_input(&self, maps: &FlMaps, x: &[f64], w: &[f64]) -> Vec<f64> {
        let at = crate::expr::Point { x, u: w, p: &[] };
        maps.input_exprs.iter().map(|e| e.eval(&at)).collect()
    }

    /// A finished run's recording certified by the import path of its class (module doc).
    pub fn judge(&self, rec: &Recording) -> Judged {
        match self {
            Played::One {
                task,
                design,
                lc,
                temporal: Some(tt),
            } => {
                let lp = Loop::new(task, design);
                let h = task.plant.period();
                let judged = TemporalLoop::new(tt, &lp)
                    .map_err(|e| e.to_string())
                    .and_then(|tl| {
                        crate::synth::temporal::certify_recording(&lp, lc, &tl, task.steps, rec)
                    });
                match judged {
                    Ok((nominal, c)) => Judged {
                        centre: nominal.x[0].clone(),
                        delta: c.delta,
                        delta_stored: c.delta_stored,
                        path: nominal.x,
                        verdict: if c.is_certified() {
                            Ok(format!(
                                "the formula (Theorem 4.2): {}",
                                crate::synth::temporal::certificate_text(&c, h)
                            ))
                        } else {
                            Err(format!(
                                "the formula certifies no radius (Theorem 4.2): {}",
                                crate::synth::temporal::certificate_text(&c, h)
                            ))
                        },
                        certificate: None,
                    },
                    Err(why) => Judged {
                        centre: rec.x0.clone(),
                        delta: 0.0,
                        delta_stored: 0.0,
                        path: Vec::new(),
                        verdict: Err(why),
                        certificate: None,
                    },
                }
            }
            Played::One {
                task, design, lc, ..
            } => match crate::cover::certify_recording(&Loop::new(task, design), lc, rec) {
                Ok((nominal, cert)) => Judged {
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
                },
                Err(why) => Judged {
                    centre: rec.x0.clone(),
                    delta: 0.0,
                    delta_stored: 0.0,
                    path: Vec::new(),
                    verdict: Err(why.to_string()),
                    certificate: None,
                },
            },
            Played::Hybrid { task, .. } => match import::certify_recording(task, rec) {
                // A forced run's map path is its segments' states (each ends where the next begins).
                Ok(run) if task.forced => Judged {
                    centre: run.nominals[0].x[0].clone(),
                    delta: run.delta(),
                    delta_stored: run.certificate.delta_stored,
                    path: run
                        .nominals
                        .iter()
                        .flat_map(|n| n.x.iter().cloned())
                        .collect(),
                    verdict: Ok(import::bindings(task, &run.locations, &run.certificate)),
                    certificate: None,
                },
                Ok(run) => Judged {
                    centre: run.nominals[0].x[0].clone(),
                    delta: run.delta(),
                    delta_stored: run.certificate.delta_stored,
                    path: hybrid_path(task, &run),
                    verdict: Ok(import::bindings(task, &run.locations, &run.certificate)),
                    certificate: None,
                },
                Err(e) => Judged {
                    centre: rec.x0.clone(),
                    delta: 0.0,
                    delta_stored: 0.0,
                    path: Vec::new(),
                    // The game says "refused" itself.
                    verdict: Err(match e {
                        import::ImportError::Refused(why) => why,
                        e => e.to_string(),
                    }),
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
