//! The certified cover of Init and how it grows (Algorithms 1 and 4, §5.4; the coverage estimate of
//! §2.5.2): the balls certified so far, the one path by which a trajectory joins them, the record of every
//! §5.3 optimisation, and the cover after each round.
//!
//! * [`estimate`]: uniform sampling of Init and the coverage estimate with its Chernoff bounds (§2.5.2);
//! * [`alg4`]: the geometry of Algorithm 4 (the gap (5.32), projection onto the closest ball, where the
//!   unreachable samples lie);
//! * [`seeds`]: the seed sources every cover loop asks (generator, routes, Algorithm 4, recordings) and
//!   the provenance each trajectory keeps;
//! * [`grow`]: the growth loop itself, from the first seed to the stop.

pub mod alg4;
pub mod estimate;
mod grow;
pub mod seeds;

pub use estimate::{CoverageEstimate, SampleBox};
pub use grow::{grow, Attempts, GrowError, GrowOptions, Grown};
pub use seeds::{certify_recording, RouteSearch, Source};

use crate::certify::Certificate;
use crate::emit::{EmitError, FallbackLaw, ImageBuilder, SelectionTestSpec, TrajectoryEntry};
use crate::optimize::{OptStop, Optimized};
use crate::task::Task;
use crate::trajectory::Nominal;
use faer::Mat;
use std::sync::Arc;

/// How the cover grows after its first trajectory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
pub enum Generator {
    /// Algorithm 4 (§5.4): the nearest uncovered sample projected onto the closest ball, that ball's
    /// feedback law simulated from there, δ maximised by §5.3 and re-certified (the default).
    #[default]
    #[value(name = "algorithm4")]
    Algorithm4,
    /// Algorithm 1: the generator from each uncovered seed (for a single-location plant the SCP
    /// generator without §5.3, the earlier pipeline; for a hybrid plant its planner, the default there).
    Scp,
}

impl std::fmt::Display for Generator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Generator::Algorithm4 => "algorithm4",
            Generator::Scp => "scp",
        })
    }
}

/// Told a line as each long stage of a run starts (the verification's Monte Carlo, the falsifier, …);
/// the CLI prints it on stderr with the seconds so far.
#[derive(Clone)]
pub struct StageHook(pub Arc<dyn Fn(&str) + Send + Sync>);

impl StageHook {
    /// Tell the receiver that stage `line` starts.
    pub fn stage(&self, line: &str) {
        (self.0)(line)
    }
}

impl std::fmt::Debug for StageHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("StageHook(..)")
    }
}

/// Called with the number of trajectories after each one is accepted (e.g. to interrupt a run).
#[derive(Clone)]
pub struct AcceptHook(pub Arc<dyn Fn(usize) + Send + Sync>);

impl std::fmt::Debug for AcceptHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("AcceptHook(..)")
    }
}

/// Why the growth loop stopped.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub enum StopReason {
    /// The coverage lower bound met the target at the requested confidence.
    Covered,
    /// The trajectory budget ran out first.
    Budget { trajectories: usize },
    /// No uncovered sample admits a certifiable trajectory.
    Stuck { failed_seeds: usize },
    /// Algorithm 4's second rule: no uncovered sample is reachable by local variation of the cover (and
    /// a new SCP seed did not help either); `region` says where they lie.
    NeedsSeed {
        region: alg4::UncoveredRegion,
        description: String,
    },
    /// Stopped on request (Ctrl-C) with this many certified trajectories.
    Interrupted { trajectories: usize },
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::Covered => write!(f, "Init covered at the requested confidence"),
            StopReason::Budget { trajectories } => {
                write!(f, "trajectory budget ({trajectories}) ran out before Init was covered")
            }
            StopReason::Stuck { failed_seeds } => write!(
                f,
                "stopped: {failed_seeds} uncovered seed states admit no certifiable trajectory (needs a new seed trajectory)"
            ),
            StopReason::NeedsSeed { description, .. } => write!(
                f,
                "no uncovered sample is reachable by local variation of the cover: needs a new seed trajectory ({description})"
            ),
            StopReason::Interrupted { trajectories } => write!(
                f,
                "interrupted: the image holds the {trajectories} trajectories certified so far"
            ),
        }
    }
}

/// One certified trajectory of the cover.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CoverTrajectory {
    /// Where it came from (a recording, the generator, a route, Algorithm 4 from a ball).
    pub source: Source,
    pub nominal: Nominal,
    pub certificate: Certificate,
}

/// One §5.3 optimisation of the growth loop (accepted or not).
#[derive(Clone, Debug, serde::Serialize)]
pub struct OptRecord {
    /// Growth round it belongs to.
    pub round: usize,
    /// The ball whose boundary it starts on (Algorithm 4), or `None` for an SCP seed.
    pub origin: Option<usize>,
    pub x0: Vec<f64>,
    /// The shipped nominal before optimisation and its certified δ (0 when not certified).
    #[serde(skip)]
    pub before: Nominal,
    pub delta_before: f64,
    /// Certified δ of the re-certified result.
    pub delta_after: f64,
    /// Certified δ per iteration ([0] = start).
    pub history: Vec<f64>,
    pub iterations: usize,
    pub stop: OptStop,
    /// Its index among the trajectories when accepted.
    pub accepted: Option<usize>,
}

impl OptRecord {
    fn new(
        round: usize,
        origin: Option<usize>,
        x0: &[f64],
        before: (Nominal, Certificate),
        after: &Certificate,
        opt: &Optimized,
        accepted: Option<usize>,
    ) -> Self {
        Self {
            round,
            origin,
            x0: x0.to_vec(),
            delta_before: before.1.delta.max(0.0),
            before: before.0,
            delta_after: after.delta.max(0.0),
            history: opt.history.clone(),
            iterations: opt.iterations,
            stop: opt.stop,
            accepted,
        }
    }

    /// δ after ÷ δ before (∞ when the start was not certified).
    pub fn gain(&self) -> f64 {
        if self.delta_before > 0.0 {
            self.delta_after / self.delta_before
        } else {
            f64::INFINITY
        }
    }
}

/// The cover after one growth round.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CoverSnapshot {
    pub round: usize,
    /// Trajectories (the first `trajectories` of the final list).
    pub trajectories: usize,
    /// Working samples still uncovered (full states), discarded ones included.
    #[serde(skip)]
    pub uncovered: Vec<Vec<f64>>,
}

impl CoverSnapshot {
    /// The cover `trajs` and the working samples (`work`, `discarded`) it does not cover yet.
    fn new(
        round: usize,
        P: faer::MatRef<'_, f64>,
        trajs: &[CoverTrajectory],
        work: &[Vec<f64>],
        discarded: &[Vec<f64>],
    ) -> Self {
        Self {
            round,
            trajectories: trajs.len(),
            uncovered: work
                .iter()
                .chain(discarded)
                .filter(|x| alg4::gap(P, x, trajs).is_none_or(|(d, _)| d > 0.0))
                .cloned()
                .collect(),
        }
    }
}

/// A §5.3 optimisation of the growth loop before its result is judged: where it started, the shipped
/// start and what the optimiser returned.
pub struct OptStart<'a> {
    round: usize,
    origin: Option<usize>,
    x0: &'a [f64],
    before: (Nominal, Certificate),
    opt: Optimized,
}

impl<'a> OptStart<'a> {
    pub fn new(
        round: usize,
        origin: Option<usize>,
        x0: &'a [f64],
        before: (Nominal, Certificate),
        opt: Optimized,
    ) -> Self {
        Self {
            round,
            origin,
            x0,
            before,
            opt,
        }
    }
}

/// The certified cover and its history.
#[derive(Clone, Debug)]
pub struct Cover {
    /// The CAF metric the balls live in.
    P: Mat<f64>,
    /// The certified trajectories, in the order they joined.
    pub trajectories: Vec<CoverTrajectory>,
    /// Every §5.3 optimisation the growth ran, accepted or not.
    pub records: Vec<OptRecord>,
    /// The cover after each round.
    pub snapshots: Vec<CoverSnapshot>,
    /// Every route search the growth ran (`seeds::Generators::searches`).
    pub routes: Vec<RouteSearch>,
}

impl Cover {
    /// An empty cover in the metric P.
    pub fn new(P: Mat<f64>) -> Self {
        Self {
            P,
            trajectories: Vec::new(),
            records: Vec::new(),
            snapshots: Vec::new(),
            routes: Vec::new(),
        }
    }

    /// A trajectory joins the cover (recorded, generated without §5.3); `on_accept` hears the new count.
    pub fn push(&mut self, t: CoverTrajectory, on_accept: Option<&dyn Fn(usize)>) {
        self.trajectories.push(t);
        if let Some(f) = on_accept {
            f(self.trajectories.len());
        }
    }

    /// The one accept path of an optimised candidate: its §5.3 run is recorded, and when `ok` the candidate
    /// joins the cover (the record names its index) and `on_accept` hears the new count.
    pub fn record(
        &mut self,
        start: OptStart<'_>,
        candidate: CoverTrajectory,
        ok: bool,
        on_accept: &dyn Fn(usize),
    ) {
        self.records.push(OptRecord::new(
            start.round,
            start.origin,
            start.x0,
            start.before,
            &candidate.certificate,
            &start.opt,
            ok.then_some(self.trajectories.len()),
        ));
        if ok {
            self.push(candidate, Some(on_accept));
        }
    }

    /// Records the cover after `round`, with the working samples it does not cover yet.
    pub fn snapshot(&mut self, round: usize, work: &[Vec<f64>], discarded: &[Vec<f64>]) {
        let s = CoverSnapshot::new(round, self.P.as_ref(), &self.trajectories, work, discarded);
        self.snapshots.push(s);
    }
}

/// The feedforward image of a cover (Algorithm 2): the f32 gain and metric, each ball with its stored
/// radius, and each reference table; terminal behaviour keeps the last law; the fallback applies the
/// spec's fallback input (a point of the input set).
pub fn feedforward_image(
    task: &Task,
    Khat: &Mat<f64>,
    P: &Mat<f64>,
    trajs: &[CoverTrajectory],
) -> Result<Vec<u8>, EmitError> {
    feedforward_image_of(
        task,
        Khat,
        P,
        trajs
            .iter()
            .map(|t| (&t.nominal, t.certificate.delta_stored)),
    )
}

/// The whitened selection test (`shared_types::selection`) of a one-location cover with metric `P`, for
/// balls given by their centre and stored radius: the f32 factor R̂ of P, and per ball its whitened
/// centre and the squared threshold whose acceptance the rounding bound of `shared_types::pwa` proves
/// inside the ball of the stored radius (so inside the certified ball, which is larger). `None` when
/// the bound does not apply to some ball; the image then selects with the P-metric test.
fn selection_test(P: &Mat<f64>, balls: &[(Vec<f64>, f32)]) -> Option<SelectionTestSpec> {
    let n = P.nrows();
    let Rh = crate::certify::metric_factor_f32(&crate::linalg::to_row_major(P.as_ref()), n)?;
    let mut records = Vec::with_capacity(balls.len() * (n + 1));
    for (c, r) in balls {
        let cz = crate::certify::whitened_centre(&Rh, c);
        let s = crate::certify::pwa_ball_threshold(P.as_ref(), c, *r as f64)?;
        records.extend(cz.iter().map(|&v| v as f32));
        records.push(s);
    }
    Some(SelectionTestSpec {
        factors: Rh.iter().map(|&v| v as f32).collect(),
        records,
    })
}

/// [`feedforward_image`] of nominals with their stored radii, whatever certified them (Theorem 4.7, or an
/// MTL task's [`crate::certify::temporal`]).
pub fn feedforward_image_of<'a>(
    task: &Task,
    Khat: &Mat<f64>,
    P: &Mat<f64>,
    balls: impl IntoIterator<Item = (&'a Nominal, f32)>,
) -> Result<Vec<u8>, EmitError> {
    let plant = &*task.plant;
    let mut b = ImageBuilder::new(plant.n(), plant.m(), plant.period());
    b.add_location(
        crate::linalg::to_row_major(Khat.as_ref()),
        crate::linalg::to_row_major(P.as_ref()),
    );
    let mut starts = Vec::new();
    for (nominal, delta_stored) in balls {
        starts.push((nominal.x[0].clone(), delta_stored));
        b.add_trajectory(TrajectoryEntry {
            x0: nominal.x[0].clone(),
            delta: delta_stored as f64,
            v: nominal.v.concat(),
            location: vec![0; nominal.v.len()],
        });
    }
    // A linearised plant's image carries its maps; its fallback and input box are the plant's (U, not
    // the linear model's W).
    let maps = plant.linearization();
    let input = maps.map_or(&task.problem.input, |m| &m.input);
    if let crate::spec::InputSet::Box { lo, hi } = input {
        b.input_box = Some((lo.clone(), hi.clone()));
    }
    if let Some(m) = maps {
        b.model_maps = Some(crate::emit::ModelMapsSpec::of(m));
        b.selection_test = selection_test(P, &starts);
    }
    b.fallback = FallbackLaw::constant(&task.problem.fallback_input);
    b.fingerprint = Some(task.problem.fingerprint.as_bytes().to_vec());
    b.to_bytes()
}
