//! The game's state and rules (module doc of [`crate::play`]): sessions that step the task's plant,
//! finished runs certified through [`crate::cover::certify_recording`], the cover they build, and the
//! JSON answers of the page's requests.
//!
//! # Bounds
//! At most [`MAX_SESSIONS`] runs are in play at once (a session idle for [`IDLE_SECS`] is dropped when
//! room is needed); a run is at most the spec's horizon long; one request steps at most the horizon;
//! at most [`MAX_RUNS`] accepted runs and the last [`MAX_REFUSED`] refused ones are kept.
//!
//! # Runs and their files
//! A run ends when it enters Unsafe (at a sample or between samples), when it has entered Goal and its
//! depth in Goal stops growing, when its horizon is spent, or when the player finishes it. Its recording
//! (the `# x0 = …` line, a header `t,v1,…,vm`, one row of reference inputs per sample) is parsed by the
//! same parser as `synth --import` and certified; an accepted run is written to
//! `run-NNNN-<player>.csv` in the out directory, with the player and the time in comment lines. Runs
//! already in that directory when the game starts are certified again and join the cover.
//!
//! # Plants
//! The game asks only [`Played`] of the task (its module doc says, per plant class, how a period is
//! stepped and how a run is certified): a one-location task, linear affine or feedback linearizable
//! (the page draws ξ, the server flows the nonlinear plant); a hybrid automaton with internal switching
//! (runs split at their events and certified along the task's location path, Theorem 4.24); or one with
//! forced switching, where the player chooses the location (`"location"` in a step) and each row is
//! recorded with it (Theorem 4.17, Def 4.18 for a formula, whose runs go on to T). Each session keeps its
//! location; the answers report it (index and name) when the plant has more than one. The balls over
//! Init are in the initial location's metric; a hybrid run's tube is not drawn (its segments' metrics
//! differ).

use super::played::Played;
use crate::certify::{Binding, Certificate};
use crate::geometry::Metric;
use crate::property::InputBound;
use crate::synth::hybrid::HybridTask;
use crate::task::Task;
use crate::trajectory::csv::{parse_recording, Recording};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Runs in play at once.
pub const MAX_SESSIONS: usize = 16;
/// A session idle this long (seconds) is dropped when a new player needs its place.
pub const IDLE_SECS: u64 = 600;
/// Accepted runs kept (and written); beyond this, runs are certified but refused with a message.
pub const MAX_RUNS: usize = 1000;
/// Refused runs kept for the table (the oldest go first).
pub const MAX_REFUSED: usize = 100;
/// Coverage samples of Init (seeded by the spec's seed).
pub const COVERAGE_SAMPLES: usize = 2000;
/// Cells per side of the raster in which the page draws Goal and Unsafe.
pub const RASTER: usize = 120;
/// Longest player name (characters); longer names are refused.
pub const MAX_NAME: usize = 40;
/// Most points of an accepted run's path in `GET /api/state` (the finished run's answer has all).
pub const STATE_PATH_POINTS: usize = 100;
/// Samples of the "input held" preview (the text's game draws where the held input leads).
pub const PREVIEW_STEPS: usize = 150;

/// A request the game refuses; the server answers it with its message (and keeps running).
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PlayError {
    /// A malformed or invalid request: what is wrong with it.
    #[error("{0}")]
    BadRequest(String),
    #[error(
        "unknown session {0}: it never existed, its run has finished, or it was dropped after {IDLE_SECS} s idle"
    )]
    UnknownSession(u64),
    #[error("{MAX_SESSIONS} runs are in play already; try again when one finishes")]
    Busy,
    #[error("cannot write the run: {0}")]
    Io(String),
}

fn bad(msg: impl Into<String>) -> PlayError {
    PlayError::BadRequest(msg.into())
}

/// Choices of the game that are not in the spec.
#[derive(Clone, Debug)]
pub struct PlaySettings {
    /// Where accepted runs are written (and read from at start).
    pub out: PathBuf,
    /// The two state coordinates drawn (0-based); default: Goal's two coordinates when it names two,
    /// else x1, x2.
    pub projection: Option<[usize; 2]>,
    /// The page's default speed, a fraction of real time (the text played at 1/3).
    pub slow: f64,
}

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ending {
    Goal,
    Unsafe,
    Timeout,
    Finished,
}

impl Ending {
    fn parse(s: &str) -> Option<Self> {
        [
            Ending::Goal,
            Ending::Unsafe,
            Ending::Timeout,
            Ending::Finished,
        ]
        .into_iter()
        .find(|e| e.name() == s)
    }
    fn name(self) -> &'static str {
        match self {
            Ending::Goal => "goal",
            Ending::Unsafe => "unsafe",
            Ending::Timeout => "timeout",
            Ending::Finished => "finished",
        }
    }
}

/// One player's run in play.
struct Session {
    player: String,
    loc: crate::model::Location,
    x0: Vec<f64>,
    /// The states at the samples in the task's coordinates (ξ for a feedback-linearizable plant).
    xs: Vec<Vec<f64>>,
    /// The plant's own state now (the last of `xs` but for a feedback-linearizable plant, whose
    /// zero-dynamics states the task does not track).
    plant_x: Vec<f64>,
    /// The location of each row (forced switching records it).
    locs: Vec<crate::model::Location>,
    v: Vec<Vec<f64>>,
    u: Vec<Vec<f64>>,
    /// Euclidean depth in Goal at the last sample, once Goal is entered.
    goal_depth: Option<f64>,
    last_seen: Instant,
}

/// A finished run, accepted or refused.
struct Run {
    number: usize,
    player: String,
    when: String,
    ending: Ending,
    accepted: bool,
    delta: f64,
    /// Fraction of the coverage samples it covered that no earlier run did.
    new_coverage: f64,
    reason: String,
    file: Option<String>,
    /// The certified nominal's states, for the map.
    path: Vec<Vec<f64>>,
}

/// An accepted run's ball over Init (the initial location's metric, the stored radius).
struct Ball {
    center: Vec<f64>,
    delta_stored: f32,
}

/// The game (module doc).
pub struct Game {
    played: Played,
    settings: PlaySettings,
    proj: [usize; 2],
    base: Vec<f64>,
    samples: Vec<Vec<f64>>,
    covered: Vec<bool>,
    cover: Vec<Ball>,
    runs: Vec<Run>,
    sessions: BTreeMap<u64, Session>,
    next_session: u64,
    next_number: usize,
    world: Value,
}

impl Game {
    /// The game of a task: its CAF designed as `synth` designs it, the coverage samples drawn, and the
    /// runs already in the out directory certified again. Errors say what stops the game.
    pub fn new(task: Task, settings: PlaySettings) -> Result<Self, String> {
        if task.plant.linearization().is_some_and(|m| m.flat.is_some()) {
            return Err("a differentially flat plant is not playable yet: the game steps the plant \
                        through the law without the controller's own states (the dynamic extension); \
                        `synth` certifies it"
                .into());
        }
        Self::of(Played::one(task)?, settings)
    }

    /// The game of a hybrid task with internal switching (module doc, "Plants"), as [`Game::new`].
    pub fn hybrid(task: HybridTask, settings: PlaySettings) -> Result<Self, String> {
        Self::of(Played::hybrid(task)?, settings)
    }

    fn of(played: Played, settings: PlaySettings) -> Result<Self, String> {
        let n = played.plant().n();
        if n < 2 {
            return Err(format!(
                "the plant has n = {n} state coordinate; the game draws two"
            ));
        }
        if played.plant().m() < 1 {
            return Err("the plant has no input".into());
        }
        let proj = match settings.projection {
            Some(p) => p,
            None => default_projection(played.problem()),
        };
        if proj[0] >= n || proj[1] >= n || proj[0] == proj[1] {
            return Err(format!(
                "the projection x{},x{} must name two different coordinates of x1..x{n}",
                proj[0] + 1,
                proj[1] + 1
            ));
        }
        if !(settings.slow > 0.0 && settings.slow <= 10.0) {
            return Err(format!(
                "--slow must be in (0, 10] (a fraction of real time), got {}",
                settings.slow
            ));
        }
        std::fs::create_dir_all(&settings.out)
            .map_err(|e| format!("cannot create {}: {e}", settings.out.display()))?;
        let init = played.init();
        let base = init.centre();
        let mut rng = ChaCha8Rng::seed_from_u64(played.problem().seed ^ 0x91a7);
        let samples = crate::cover::SampleBox {
            lo: init.lo.clone(),
            hi: init.hi.clone(),
        }
        .samples(COVERAGE_SAMPLES, &mut rng);
        let covered = vec![false; samples.len()];
        let mut game = Self {
            played,
            settings,
            proj,
            base,
            samples,
            covered,
            cover: Vec::new(),
            runs: Vec::new(),
            sessions: BTreeMap::new(),
            next_session: 1,
            next_number: 1,
            world: Value::Null,
        };
        game.world = game.make_world(game.proj);
        game.load_out_dir()?;
        Ok(game)
    }

    /// The spec the game plays.
    pub fn problem(&self) -> &crate::spec::Problem {
        self.played.problem()
    }

    /// Accepted runs in the cover.
    pub fn accepted(&self) -> usize {
        self.cover.len()
    }

    /// Fraction of the coverage samples inside an accepted run's ball.
    pub fn coverage(&self) -> f64 {
        self.covered.iter().filter(|&&c| c).count() as f64 / self.covered.len().max(1) as f64
    }

    /// Certifies the recordings already in the out directory (sorted by name) and adds those accepted.
    fn load_out_dir(&mut self) -> Result<(), String> {
        let files =
            crate::trajectory::csv::recordings_in(&self.settings.out).map_err(|e| e.to_string())?;
        let plant = self.played.plant();
        let (n, m, h) = (plant.n(), plant.m(), plant.period());
        for f in files {
            let rec = crate::trajectory::csv::load_recording(&f, n, m, h, self.played.steps())
                .map_err(|e| format!("{e} (a file in the out directory; move it away to play)"))?;
            let text = std::fs::read_to_string(&f).unwrap_or_default();
            let player = comment(&text, "player").unwrap_or_else(|| "?".into());
            let when = comment(&text, "played").unwrap_or_default();
            let number = file_number(&f).unwrap_or(self.next_number);
            self.next_number = self.next_number.max(number + 1);
            let ending = comment(&text, "ending")
                .and_then(|e| Ending::parse(&e))
                .unwrap_or(Ending::Finished);
            let run = self.judge(&rec, player, when, ending, number);
            let mut run = run;
            run.file = f.file_name().map(|s| s.to_string_lossy().into_owned());
            self.push_run(run);
        }
        Ok(())
    }

    /// The static description of the task the page draws (`GET /api/world`), in the default projection
    /// or in `projection` (`?projection=i,j`, 0-based state coordinates).
    pub fn world(&self, projection: Option<&Value>) -> Result<Value, PlayError> {
        let proj = self.projection(projection)?;
        Ok(if proj == self.proj {
            self.world.clone()
        } else {
            self.make_world(proj)
        })
    }

    fn make_world(&self, proj: [usize; 2]) -> Value {
        let t = &self.played;
        let (problem, property, plant) = (t.problem(), t.property(), t.plant());
        let (n, m) = (plant.n(), plant.m());
        let [a, b] = proj;
        let init = t.init();
        // The view: Init and the sets' extents along the drawn coordinates, with a margin.
        let mut lo = [init.lo[a], init.lo[b]];
        let mut hi = [init.hi[a], init.hi[b]];
        let mut widen = |p: [f64; 2], r: f64| {
            for i in 0..2 {
                lo[i] = lo[i].min(p[i] - r);
                hi[i] = hi[i].max(p[i] + r);
            }
        };
        for s in std::iter::once(&problem.goal).chain(&problem.unsafe_sets) {
            if let Some((c, r)) = extent(s, n, &self.base, proj) {
                widen(c, r);
            }
        }
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-3);
        let mid = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        let half = 0.5 * span * 1.25;
        let view = [mid[0] - half, mid[0] + half, mid[1] - half, mid[1] + half];
        // Goal and Unsafe as rasters of the same membership tests the certificate uses, in the plane
        // through Init's centre.
        let raster = |region: Option<&dyn crate::geometry::Region>| -> Vec<String> {
            let Some(r) = region else {
                return vec![];
            };
            (0..RASTER)
                .map(|j| {
                    (0..RASTER)
                        .map(|i| {
                            let mut x = self.base.clone();
                            x[a] = view[0] + (i as f64 + 0.5) / RASTER as f64 * (view[1] - view[0]);
                            x[b] = view[2] + (j as f64 + 0.5) / RASTER as f64 * (view[3] - view[2]);
                            if r.contains(&x) {
                                '1'
                            } else {
                                '0'
                            }
                        })
                        .collect()
                })
                .collect()
        };
        let input = match &property.input {
            InputBound::Box { lo, hi } => json!({"kind": "box", "lo": lo, "hi": hi}),
            InputBound::Norm2 { center, max } => {
                json!({"kind": "ball", "center": center, "radius": max})
            }
        };
        let P = t.P();
        let Pinv = crate::linalg::to_rows(t.roots().inv.as_ref());
        // The tube's cross-section: the projection of {e : ‖e‖_P ≤ 1} onto the drawn plane, as a factor
        // L with L Lᵀ = (P⁻¹) restricted to (a, b); the ball over Init: the slice through its centre,
        // L Lᵀ = (P restricted to (a, b))⁻¹.
        let proj_shape = chol2([[Pinv[a][a], Pinv[a][b]], [Pinv[b][a], Pinv[b][b]]]);
        let slice_shape = inv2([[P[(a, a)], P[(a, b)]], [P[(b, a)], P[(b, b)]]]).map(chol2);
        let locations = plant.locations();
        json!({
            "name": problem.name.clone().unwrap_or_default(),
            "n": n,
            "m": m,
            "period": plant.period(),
            "steps": t.steps(),
            "horizon": problem.horizon,
            "locations": locations,
            "location_names": (0..locations).map(|l| t.location_name(l)).collect::<Vec<_>>(),
            "initial_location": t.initial(),
            // Forced switching: the edges the player can take (a key per target location).
            "switches": t.switches().iter().map(|&(f, to)| json!({
                "from": f, "to": to, "from_name": t.location_name(f), "to_name": t.location_name(to),
            })).collect::<Vec<_>>(),
            "formula": problem.mtl.clone(),
            // The names of the drawn state's and the input's coordinates (the task's: ξ and w for a
            // feedback-linearizable plant).
            "symbol": if t.maps().is_some() { "ξ" } else { "x" },
            "input_symbol": if t.maps().is_some() { "w" } else { "u" },
            "law": if t.maps().is_some() {
                "w = Kξ + v, u = λ(x)(w − α(x)) on the nonlinear plant (feedback linearised)"
            } else {
                "u = K̂x + v"
            },
            "projection": [a, b],
            // A feedback-linearizable task's coordinates are ξ (the plant's states `FlMaps::xi_states`).
            "labels": if t.maps().is_some() {
                [format!("ξ{}", a + 1), format!("ξ{}", b + 1)]
            } else {
                [format!("x{}", a + 1), format!("x{}", b + 1)]
            },
            "view": view,
            "raster": RASTER,
            "goal": raster(Some(property.goal.as_ref())),
            "unsafe": raster(property.unsafe_region()),
            "init": {"lo": init.lo, "hi": init.hi, "center": self.base},
            "input": input,
            "K": crate::linalg::to_rows(t.K(t.initial())),
            "tube_shape": if t.one_metric() { proj_shape } else { None },
            "ball_shape": slice_shape.flatten(),
            "samples": self.samples,
            "slow": self.settings.slow,
            "min_robustness": problem.synthesis.min_robustness,
        })
    }

    /// Runs, coverage, players in play and the suggested start (`GET /api/state`).
    pub fn state(&self) -> Value {
        let covered: String = self
            .covered
            .iter()
            .map(|&c| if c { '1' } else { '0' })
            .collect();
        let runs: Vec<Value> = self.runs.iter().map(|r| self.run_json(r, false)).collect();
        let players: Vec<Value> = self
            .sessions
            .values()
            .map(|s| {
                let x = s.xs.last().expect("a session holds x0");
                let mut p = json!({"player": s.player, "x": x, "t": s.v.len() as f64 * self.played.plant().period()});
                self.locate(&mut p, s.loc);
                p
            })
            .collect();
        json!({
            "accepted": self.cover.len(),
            "coverage": self.coverage(),
            "covered": covered,
            "runs": runs,
            "balls": self.cover.iter().map(|c| json!({
                "center": c.center, "delta": c.delta_stored as f64,
            })).collect::<Vec<_>>(),
            "players": players,
            "suggestion": self.suggestion(),
        })
    }

    /// A checked projection (two different coordinates of the state).
    fn projection(&self, v: Option<&Value>) -> Result<[usize; 2], PlayError> {
        let Some(v) = v else {
            return Ok(self.proj);
        };
        let n = self.played.plant().n();
        let ix: Option<Vec<usize>> = v
            .as_array()
            .map(|a| a.iter().map(|i| i.as_u64().map(|i| i as usize)).collect())
            .unwrap_or(None);
        match ix.as_deref() {
            Some(&[a, b]) if a < n && b < n && a != b => Ok([a, b]),
            _ => Err(bad(format!(
                "`projection` must be two different coordinate indices from 0 to {}",
                n - 1
            ))),
        }
    }

    /// The largest uncovered region's representative: the uncovered coverage sample farthest (in the
    /// CAF metric, beyond δ) from every accepted ball; Init's centre before any run is accepted.
    pub fn suggestion(&self) -> Option<Vec<f64>> {
        if self.cover.is_empty() {
            return Some(self.base.clone());
        }
        let P = self.played.P();
        self.samples
            .iter()
            .zip(&self.covered)
            .filter(|(_, &c)| !c)
            .filter_map(|(s, _)| {
                self.cover
                    .iter()
                    .map(|b| crate::cover::alg4::dist(P, s, &b.center) - b.delta_stored as f64)
                    .min_by(f64::total_cmp)
                    .map(|d| (d, s))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, s)| s.clone())
    }

    /// Starts a run (`POST /api/start`): `{"player": name, "x0": [n numbers]}` or `{"player": name,
    /// "at": [two numbers], "projection": [i, j]}` (the drawn coordinates, by default the game's pair;
    /// the others from Init's centre). The start must be in Init.
    pub fn start(&mut self, body: &Value) -> Result<Value, PlayError> {
        let obj = body
            .as_object()
            .ok_or_else(|| bad("the body must be a JSON object"))?;
        let player = obj
            .get("player")
            .and_then(Value::as_str)
            .ok_or_else(|| bad("`player` (the player's name, a string) is missing"))?
            .trim()
            .to_string();
        if player.is_empty() || player.chars().count() > MAX_NAME {
            return Err(bad(format!("`player` must be 1 to {MAX_NAME} characters")));
        }
        if player.chars().any(char::is_control) {
            return Err(bad("`player` must not contain control characters"));
        }
        let n = self.played.plant().n();
        let x0 = match (obj.get("x0"), obj.get("at")) {
            (Some(x), None) => numbers(x, n, "x0")?,
            (None, Some(p)) => {
                let [a, b] = self.projection(obj.get("projection"))?;
                let p = numbers(p, 2, "at")?;
                let mut x = self.base.clone();
                x[a] = p[0];
                x[b] = p[1];
                x
            }
            _ => {
                return Err(bad(
                    "give the start as `x0` (the whole state) or `at` (the two drawn coordinates), one of them",
                ))
            }
        };
        let init = self.played.init();
        if let Some(i) =
            (0..n).find(|&i| !(x0[i] >= init.lo[i] - 1e-12 && x0[i] <= init.hi[i] + 1e-12))
        {
            return Err(bad(format!(
                "the start is not in Init: x{} = {} is outside [{}, {}]",
                i + 1,
                x0[i],
                init.lo[i],
                init.hi[i]
            )));
        }
        // Clamped into Init (the tolerance above) and stored as f32, as the recording will be.
        let x0: Vec<f64> = (0..n)
            .map(|i| crate::linalg::round32(x0[i].clamp(init.lo[i], init.hi[i])))
            .collect();
        if self.sessions.len() >= MAX_SESSIONS {
            let now = Instant::now();
            let idle = self
                .sessions
                .iter()
                .filter(|(_, s)| now.duration_since(s.last_seen) > Duration::from_secs(IDLE_SECS))
                .map(|(&id, _)| id)
                .next();
            match idle {
                Some(id) => {
                    self.sessions.remove(&id);
                }
                None => return Err(PlayError::Busy),
            }
        }
        let id = self.next_session;
        self.next_session += 1;
        let plant_x = self.played.plant_start(&x0);
        let preview = self.preview(
            self.played.initial(),
            &plant_x,
            &vec![0.0; self.played.plant().m()],
        );
        self.sessions.insert(
            id,
            Session {
                player,
                loc: self.played.initial(),
                x0: x0.clone(),
                xs: vec![x0.clone()],
                plant_x,
                locs: Vec::new(),
                v: Vec::new(),
                u: Vec::new(),
                goal_depth: None,
                last_seen: Instant::now(),
            },
        );
        Ok(json!({
            "session": id,
            "x0": x0,
            "preview": preview,
        }))
    }

    /// Advances a run (`POST /api/step`): `{"session": id, "v": [m numbers], "steps": k}` holds the
    /// reference v for k samples (1 ≤ k ≤ the horizon); `"finish": true` ends the run after them. The
    /// answer has the new states (whole state vectors), the last applied input and reference, whether the
    /// input was clipped, the location when the plant has several, the run's status, the held-input
    /// preview, and, when the run ended, its certificate.
    ///
    /// For an automaton with forced switching, `"location": name` asks for that location from this
    /// sample on: the switch is taken when the state is in the forced edge's guard, and otherwise the
    /// answer's `switch` says why it waits (the run goes on in its location).
    pub fn step(&mut self, body: &Value) -> Result<Value, PlayError> {
        let obj = body
            .as_object()
            .ok_or_else(|| bad("the body must be a JSON object"))?;
        let id = session_id(obj)?;
        let m = self.played.plant().m();
        let v = numbers(
            obj.get("v")
                .ok_or_else(|| bad("`v` (the reference input) is missing"))?,
            m,
            "v",
        )?;
        let steps = match obj.get("steps") {
            None => 1,
            Some(s) => s
                .as_u64()
                .filter(|&k| k >= 1 && k as usize <= self.played.steps())
                .ok_or_else(|| {
                    bad(format!(
                        "`steps` must be an integer from 1 to {} (the horizon in samples)",
                        self.played.steps()
                    ))
                })? as usize,
        };
        let finish = obj.get("finish").and_then(Value::as_bool).unwrap_or(false);
        let want =
            match obj.get("location") {
                None | Some(Value::Null) => None,
                Some(Value::String(name)) if self.played.forced() => Some(name.clone()),
                Some(Value::String(_)) => return Err(bad(
                    "`location` is the discrete input of an automaton with forced switching; this \
                     plant's location is not the player's to choose",
                )),
                Some(_) => return Err(bad("`location` must be a location's name (a string)")),
            };
        if let Some(name) = &want {
            if !(0..self.played.plant().locations()).any(|l| self.played.location_name(l) == name) {
                return Err(bad(format!(
                    "`location`: `{}` is not a location of the automaton",
                    crate::text::excerpt(name)
                )));
            }
        }
        let horizon = self.played.steps();
        let formula = self.played.formula();
        let played = &self.played;
        let plant = played.plant();
        let property = played.property();
        let goal = property.goal.as_ref();
        let unsafe_set = property.unsafe_region();
        let euclid = Metric::euclidean(plant.n());
        let s = self
            .sessions
            .get_mut(&id)
            .ok_or(PlayError::UnknownSession(id))?;
        s.last_seen = Instant::now();
        let first = s.xs.len();
        let mut clipped = false;
        let mut ending = None;
        // A forced switch asked for: taken now when the state is in the edge's guard.
        let mut switch = Value::Null;
        if let Some(name) = want.filter(|n| played.location_name(s.loc) != n) {
            let x = s.xs.last().expect("a session holds x0");
            switch = match played.switch(s.loc, &name, x) {
                Ok(l) => {
                    s.loc = l;
                    json!({"done": true, "to": name, "t": s.v.len() as f64 * plant.period()})
                }
                Err(why) => json!({"done": false, "to": name, "reason": why}),
            };
        }
        for _ in 0..steps {
            if s.v.len() >= horizon {
                ending = Some(Ending::Timeout);
                break;
            }
            let x = s.xs.last().expect("a session holds x0").clone();
            let (u, vv, c) = applied(played.K(s.loc), &property.input, &x, &v);
            clipped |= c;
            let mut hit = false;
            let advanced = played.advance(
                s.loc,
                &s.plant_x,
                &u,
                Some(&mut |y| hit |= unsafe_set.is_some_and(|us| us.contains(y))),
            );
            let Ok((loc, pxn)) = advanced else {
                // A period the exact flow cannot step (Zeno, undecided) is not played: the run ends at
                // the last sample it reached and is certified as it is.
                ending = Some(Ending::Finished);
                break;
            };
            s.locs.push(s.loc);
            s.loc = loc;
            let xn = played.observe(&pxn);
            s.plant_x = pxn;
            hit |= unsafe_set.is_some_and(|us| us.contains(&xn));
            let depth = goal.contains(&xn).then(|| goal.depth(&xn, &euclid).value);
            s.v.push(vv);
            s.u.push(u);
            s.xs.push(xn);
            if hit
                || s.xs
                    .last()
                    .is_some_and(|x| x.iter().any(|v| !v.is_finite()))
            {
                ending = Some(Ending::Unsafe);
                break;
            }
            match (depth, s.goal_depth) {
                // A formula is judged over the whole horizon: its runs do not stop in Goal.
                _ if formula => {}
                (Some(d), Some(prev)) if d <= prev => {
                    ending = Some(Ending::Goal);
                    break;
                }
                _ => s.goal_depth = depth,
            }
            if s.v.len() >= horizon {
                ending = Some(if depth.is_some() {
                    Ending::Goal
                } else {
                    Ending::Timeout
                });
                break;
            }
        }
        if ending.is_none() && finish {
            ending = Some(Ending::Finished);
        }
        let s = &self.sessions[&id];
        let x = s.xs.last().expect("a session holds x0").clone();
        let mut answer = json!({
            "session": id,
            "t": s.v.len() as f64 * plant.period(),
            "k": s.v.len(),
            "states": &s.xs[first..],
            "u": s.u.last(),
            "v": s.v.last(),
            "clipped": clipped,
            "x": x,
            "status": ending.map_or("running", Ending::name),
        });
        self.locate(&mut answer, s.loc);
        if !switch.is_null() {
            answer["switch"] = switch;
        }
        match ending {
            None => {
                answer["preview"] = json!(self.preview(s.loc, &s.plant_x, &v));
            }
            Some(e) => {
                let result = self.end(id, e)?;
                answer["result"] = result;
            }
        }
        Ok(answer)
    }

    /// Ends a run now (`POST /api/finish`, `{"session": id}`) and certifies it.
    pub fn finish(&mut self, body: &Value) -> Result<Value, PlayError> {
        let obj = body
            .as_object()
            .ok_or_else(|| bad("the body must be a JSON object"))?;
        let id = session_id(obj)?;
        if !self.sessions.contains_key(&id) {
            return Err(PlayError::UnknownSession(id));
        }
        let result = self.end(id, Ending::Finished)?;
        Ok(json!({"session": id, "status": "finished", "result": result}))
    }

    /// The location in an answer (index and name), when the plant has more than one.
    fn locate(&self, answer: &mut Value, loc: crate::model::Location) {
        if self.played.plant().locations() > 1 {
            answer["location"] = json!(loc);
            answer["location_name"] = json!(self.played.location_name(loc));
        }
    }

    /// Where the held input leads from the plant state `x` ([`PREVIEW_STEPS`] samples, in the task's
    /// coordinates; across events for a hybrid plant).
    fn preview(&self, loc: usize, x: &[f64], v: &[f64]) -> Vec<Vec<f64>> {
        let (mut loc, mut x) = (loc, x.to_vec());
        let mut out = Vec::with_capacity(PREVIEW_STEPS);
        let p = &self.played;
        for _ in 0..PREVIEW_STEPS {
            let seen = p.observe(&x);
            let (u, _, _) = applied(p.K(loc), &p.property().input, &seen, v);
            let Ok((l, y)) = p.advance(loc, &x, &u, None) else {
                break;
            };
            if y.iter().any(|v| !v.is_finite()) {
                break;
            }
            (loc, x) = (l, y);
            out.push(p.observe(&x));
        }
        out
    }

    /// Ends session `id` and certifies its run; an accepted run is written and joins the cover.
    fn end(&mut self, id: u64, ending: Ending) -> Result<Value, PlayError> {
        let s = self
            .sessions
            .remove(&id)
            .ok_or(PlayError::UnknownSession(id))?;
        let when = now_utc();
        if s.v.is_empty() {
            return Ok(
                json!({"accepted": false, "reason": "the run has no samples: nothing to certify"}),
            );
        }
        let number = self.next_number;
        self.next_number += 1;
        // A forced run records each row's location (the discrete input the player chose).
        let names: Option<Vec<&str>> = self.played.forced().then(|| {
            s.locs
                .iter()
                .map(|&l| self.played.location_name(l))
                .collect()
        });
        let text = recording_text(
            &s.player,
            &when,
            ending,
            &s.x0,
            &s.v,
            names.as_deref(),
            self.played.plant().period(),
        );
        let file = format!("run-{number:04}-{}.csv", slug(&s.player));
        // The same parser and certification as `synth --import`.
        let plant = self.played.plant();
        let rec = parse_recording(
            &text,
            &file,
            plant.n(),
            plant.m(),
            plant.period(),
            self.played.steps(),
        )
        .map_err(|e| PlayError::Io(format!("the recording does not read back: {e}")))?;
        let mut run = self.judge(&rec, s.player.clone(), when, ending, number);
        if run.accepted {
            let path = self.settings.out.join(&file);
            let tmp = self.settings.out.join(format!(".{file}.tmp"));
            // The run is in the cover either way; a file that cannot be written is said in its reason.
            match std::fs::write(&tmp, &text).and_then(|()| std::fs::rename(&tmp, &path)) {
                Ok(()) => run.file = Some(file),
                Err(e) => {
                    let _ = std::fs::remove_file(&tmp);
                    run.reason = format!(
                        "{}; NOT written: cannot write {}: {e}",
                        run.reason,
                        path.display()
                    );
                }
            }
        }
        let answer = self.run_json(&run, true);
        self.push_run(run);
        Ok(answer)
    }

    /// Certifies a recording; when accepted, its ball joins the cover (the caller keeps the run).
    fn judge(
        &mut self,
        rec: &Recording,
        player: String,
        when: String,
        ending: Ending,
        number: usize,
    ) -> Run {
        let h = self.played.plant().period();
        let ended_at = rec.v.len() as f64 * h;
        let j = self.played.judge(rec);
        let full = self.cover.len() >= MAX_RUNS;
        let certified = j.verdict.is_ok();
        let accepted = certified && !full;
        let mut new_coverage = 0.0;
        if accepted {
            let P = self.played.P();
            let r = j.delta_stored as f64;
            let mut fresh = 0usize;
            for (s, c) in self.samples.iter().zip(self.covered.iter_mut()) {
                if !*c && crate::cover::alg4::dist(P, s, &j.centre) <= r {
                    *c = true;
                    fresh += 1;
                }
            }
            new_coverage = fresh as f64 / self.samples.len().max(1) as f64;
        }
        let mut reason = match (&j.certificate, &j.verdict) {
            (Some(cert), _) => reason(cert, ending, ended_at, h),
            (None, Ok(what)) => format!(
                "{}certified δ = {:.3e}, limited by {what}",
                ended(ending, ended_at),
                j.delta
            ),
            (None, Err(why)) => format!("{}refused: {why}", ended(ending, ended_at)),
        };
        if full && certified {
            reason = format!(
                "not added: the game keeps at most {MAX_RUNS} runs (run `synth --import` on the out directory); {reason}"
            );
        }
        if accepted {
            self.cover.push(Ball {
                center: j.centre.clone(),
                delta_stored: j.delta_stored,
            });
        }
        Run {
            number,
            player,
            when,
            ending,
            accepted,
            delta: if accepted { j.delta } else { 0.0 },
            new_coverage,
            reason,
            file: None,
            path: j.path,
        }
    }

    fn push_run(&mut self, run: Run) {
        self.runs.push(run);
        let refused = self.runs.iter().filter(|r| !r.accepted).count();
        if refused > MAX_REFUSED {
            if let Some(i) = self.runs.iter().position(|r| !r.accepted) {
                self.runs.remove(i);
            }
        }
    }

    fn run_json(&self, r: &Run, full: bool) -> Value {
        let mut v = json!({
            "number": r.number,
            "player": r.player,
            "when": r.when,
            "ending": r.ending.name(),
            "accepted": r.accepted,
            "delta": r.delta,
            "new_coverage": r.new_coverage,
            "reason": r.reason,
            "file": r.file,
        });
        if full {
            v["path"] = json!(r.path);
        } else if r.accepted {
            // The table's paths are thinned to at most STATE_PATH_POINTS points (ends kept), so that a
            // state with many runs stays small.
            let stride = r.path.len().div_ceil(STATE_PATH_POINTS).max(1);
            let mut thin: Vec<&Vec<f64>> = r.path.iter().step_by(stride).collect();
            if let Some(end) = r.path.last() {
                if !(r.path.len() - 1).is_multiple_of(stride) {
                    thin.push(end);
                }
            }
            v["path"] = json!(thin);
        }
        if full {
            v["coverage"] = json!(self.coverage());
        }
        v
    }
}

/// u = K̂ x + v clipped to the input bound, the reference v that is in effect (u − K̂ x), and whether
/// the input was clipped.
fn applied(
    K: faer::MatRef<'_, f64>,
    bound: &InputBound,
    x: &[f64],
    v: &[f64],
) -> (Vec<f64>, Vec<f64>, bool) {
    let kx: Vec<f64> = (0..K.nrows())
        .map(|i| (0..K.ncols()).map(|j| K[(i, j)] * x[j]).sum())
        .collect();
    let u: Vec<f64> = kx.iter().zip(v).map(|(a, b)| a + b).collect();
    let uc = clip(bound, &u);
    let clipped = uc != u;
    let vv = uc.iter().zip(&kx).map(|(a, b)| a - b).collect();
    (uc, vv, clipped)
}

/// The point of the input bound nearest `u` (a box clamps; a ball scales towards its centre, a hair
/// inside so that rounding cannot put it outside).
pub fn clip(bound: &InputBound, u: &[f64]) -> Vec<f64> {
    match bound {
        InputBound::Box { lo, hi } => u
            .iter()
            .zip(lo.iter().zip(hi))
            .map(|(&x, (&l, &h))| x.clamp(l, h))
            .collect(),
        InputBound::Norm2 { center, max } => {
            let d: Vec<f64> = u.iter().zip(center).map(|(a, c)| a - c).collect();
            let r = d.iter().map(|a| a * a).sum::<f64>().sqrt();
            if r <= *max {
                u.to_vec()
            } else {
                let s = max * (1.0 - 1e-12) / r;
                d.iter().zip(center).map(|(a, c)| c + s * a).collect()
            }
        }
    }
}

/// Why a run is refused (or what limits an accepted one), from its certificate: for a refusal every
/// part of Theorem 4.7 that is not positive (which set, at what time, by how much), for an acceptance
/// the part that binds δ ([`Certificate::binding`]). `ended` is how the played run ended and when.
fn reason(c: &Certificate, ending: Ending, ended_at: f64, h: f64) -> String {
    let at = |k: usize| format!("t = {:.2} s (sample {k})", k as f64 * h);
    let goal = |d: f64| {
        if d > 0.0 {
            format!(
                "Goal: δ_Goal = {d:.3e} at {}, its deepest sample",
                at(c.k_star)
            )
        } else {
            format!(
                "Goal: not reached with a margin within T; the best sample, at {}, is {:.3e} short (δ_Goal = {d:.3e})",
                at(c.k_star),
                -d
            )
        }
    };
    let unsafe_ = |d: f64| {
        if d > 0.0 {
            format!(
                "Unsafe: δ_Unsafe = {d:.3e} at {}, the closest approach",
                at(c.k_unsafe)
            )
        } else {
            format!(
                "Unsafe: the tube meets Unsafe at {} by {:.3e} (δ_Unsafe = {d:.3e}, between samples)",
                at(c.k_unsafe),
                -d
            )
        }
    };
    let input = |d: f64| {
        if d > 0.0 {
            format!("Input: δ_Input = {d:.3e} at {}", at(c.k_input))
        } else {
            format!(
                "Input: the input reaches its bound at {}, by {:.3e} (δ_Input = {d:.3e})",
                at(c.k_input),
                -d
            )
        }
    };
    let ended = ended(ending, ended_at);
    if c.is_certified() {
        let what = match c.binding() {
            Binding::Goal(d) => goal(d),
            Binding::Unsafe(d) => unsafe_(d),
            Binding::Input(d) => input(d),
            other => other.to_string(),
        };
        return format!("{ended}certified δ = {:.3e}, limited by {what}", c.delta);
    }
    let mut failing = Vec::new();
    if !(c.delta_unsafe_intersample > 0.0) {
        failing.push(unsafe_(c.delta_unsafe_intersample));
    }
    if !(c.delta_goal > 0.0) {
        failing.push(goal(c.delta_goal));
    }
    if !(c.delta_input > 0.0) {
        failing.push(input(c.delta_input));
    }
    if failing.is_empty() {
        failing.push(format!(
            "{} (δ_Goal = {:.3e} at {}, δ_Unsafe = {:.3e} at {}, δ_Input = {:.3e} at {})",
            c.binding(),
            c.delta_goal,
            at(c.k_star),
            c.delta_unsafe_intersample,
            at(c.k_unsafe),
            c.delta_input,
            at(c.k_input)
        ));
    }
    format!("{ended}refused: {}", failing.join("; "))
}

/// How a played run ended and when, as a message's opening.
fn ended(ending: Ending, ended_at: f64) -> String {
    match ending {
        Ending::Unsafe => format!("the run entered Unsafe at t = {ended_at:.2} s; "),
        Ending::Timeout => format!("the horizon T ran out at t = {ended_at:.2} s; "),
        Ending::Goal => format!("the run reached Goal (t = {ended_at:.2} s); "),
        Ending::Finished => String::new(),
    }
}

/// The recording as `synth --import` reads it, with the player and the time in comment lines.
fn recording_text(
    player: &str,
    when: &str,
    ending: Ending,
    x0: &[f64],
    v: &[Vec<f64>],
    locations: Option<&[&str]>,
    h: f64,
) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "# played with host-compiler play");
    let _ = writeln!(s, "# player = {player}");
    let _ = writeln!(s, "# played = {when}");
    let _ = writeln!(s, "# ending = {}", ending.name());
    let x0: Vec<String> = x0.iter().map(|a| format!("{a:?}")).collect();
    let _ = writeln!(s, "# x0 = {}", x0.join(", "));
    let head: Vec<String> = (1..=v.first().map_or(0, Vec::len))
        .map(|i| format!("v{i}"))
        .collect();
    let loc_col = locations.map_or(String::new(), |_| {
        format!(",{}", crate::trajectory::csv::LOCATION)
    });
    let _ = writeln!(s, "t,{}{loc_col}", head.join(","));
    for (k, r) in v.iter().enumerate() {
        let r: Vec<String> = r.iter().map(|a| format!("{a:?}")).collect();
        let loc = locations.map_or(String::new(), |l| format!(",{}", l.get(k).unwrap_or(&"")));
        let _ = writeln!(s, "{:?},{}{loc}", k as f64 * h, r.join(","));
    }
    s
}

/// The value of a `# key = value` comment line.
fn comment(text: &str, key: &str) -> Option<String> {
    text.lines().find_map(|l| {
        let r = l.trim().strip_prefix('#')?.trim().strip_prefix(key)?;
        Some(r.trim_start().strip_prefix('=')?.trim().to_string())
    })
}

/// NNNN of a `run-NNNN-….csv` file name.
fn file_number(p: &Path) -> Option<usize> {
    let name = p.file_name()?.to_str()?;
    name.strip_prefix("run-")?.get(..4)?.parse().ok()
}

/// A file-name-safe form of a player's name.
fn slug(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if s.trim_matches('_').is_empty() {
        "player".into()
    } else {
        s
    }
}

fn session_id(obj: &serde_json::Map<String, Value>) -> Result<u64, PlayError> {
    obj.get("session")
        .ok_or_else(|| bad("`session` (the id `start` answered) is missing"))?
        .as_u64()
        .ok_or_else(|| bad("`session` must be a non-negative integer"))
}

/// Exactly `len` finite numbers.
fn numbers(v: &Value, len: usize, what: &str) -> Result<Vec<f64>, PlayError> {
    let a = v
        .as_array()
        .ok_or_else(|| bad(format!("`{what}` must be an array of {len} numbers")))?;
    if a.len() != len {
        return Err(bad(format!(
            "`{what}` has {} numbers; the task needs {len}",
            a.len()
        )));
    }
    a.iter()
        .enumerate()
        .map(|(i, x)| {
            x.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
                bad(format!(
                    "`{what}`[{i}] is {}, not a finite number",
                    crate::text::excerpt(&x.to_string())
                ))
            })
        })
        .collect()
}

/// Goal's two state coordinates when it names two, else x1, x2.
fn default_projection(problem: &crate::spec::Problem) -> [usize; 2] {
    match &problem.goal.coords {
        crate::spec::Coords::StateIndices(ix) if ix.len() == 2 && ix[0] != ix[1] => [ix[0], ix[1]],
        _ => [0, 1],
    }
}

/// A set's centre and reach along the drawn coordinates, for the view (balls and boxes over state
/// coordinates; other sets are drawn but do not widen the view).
fn extent(
    s: &crate::spec::SetDesc,
    n: usize,
    base: &[f64],
    proj: [usize; 2],
) -> Option<([f64; 2], f64)> {
    use crate::spec::{Coords, Shape};
    let idx: Vec<usize> = match &s.coords {
        Coords::State => (0..n).collect(),
        Coords::StateIndices(ix) => ix.clone(),
        Coords::Output { .. } => return None,
    };
    let (c, r): (Vec<f64>, f64) = match &s.shape {
        Shape::Ball { center, radius } => (center.clone(), *radius),
        Shape::Box { lo, hi } => (
            lo.iter().zip(hi).map(|(a, b)| 0.5 * (a + b)).collect(),
            lo.iter()
                .zip(hi)
                .map(|(a, b)| 0.5 * (b - a))
                .fold(0.0, f64::max),
        ),
        _ => return None,
    };
    let at = |p: usize| idx.iter().position(|&i| i == p).map(|k| c[k]);
    Some((
        [
            at(proj[0]).unwrap_or(base[proj[0]]),
            at(proj[1]).unwrap_or(base[proj[1]]),
        ],
        if r.is_finite() { r.min(1e6) } else { 0.0 },
    ))
}

/// Lower Cholesky factor of a symmetric positive definite 2×2 matrix, row-major ([[l11, 0], [l21, l22]]).
fn chol2(m: [[f64; 2]; 2]) -> Option<[[f64; 2]; 2]> {
    let l11 = m[0][0].sqrt();
    if !(l11 > 0.0) {
        return None;
    }
    let l21 = m[1][0] / l11;
    let l22 = (m[1][1] - l21 * l21).sqrt();
    (l22 > 0.0).then_some([[l11, 0.0], [l21, l22]])
}

fn inv2(m: [[f64; 2]; 2]) -> Option<[[f64; 2]; 2]> {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    (det.abs() > 0.0 && det.is_finite()).then(|| {
        [
            [m[1][1] / det, -m[0][1] / det],
            [-m[1][0] / det, m[0][0] / det],
        ]
    })
}

/// The time now as `YYYY-MM-DDTHH:MM:SSZ` (UTC).
fn now_utc() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    // Days since 1970-01-01 to a civil date (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let mo = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(mo <= 2);
    format!(
        "{y:04}-{mo:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_keeps_inside_and_projects_outside() {
        let b = InputBound::Norm2 {
            center: vec![0.0, 0.0],
            max: 1.0,
        };
        assert_eq!(clip(&b, &[0.3, 0.4]), vec![0.3, 0.4]);
        let c = clip(&b, &[3.0, 4.0]);
        assert!((c[0] - 0.6).abs() < 1e-9 && (c[1] - 0.8).abs() < 1e-9);
        assert!(c[0].hypot(c[1]) < 1.0);
        let b = InputBound::Box {
            lo: vec![-1.0],
            hi: vec![2.0],
        };
        assert_eq!(clip(&b, &[5.0]), vec![2.0]);
        assert_eq!(clip(&b, &[-5.0]), vec![-1.0]);
    }

    #[test]
    fn a_recording_reads_back_with_its_comments() {
        let text = recording_text(
            "Ann",
            "2026-01-01T00:00:00Z",
            Ending::Goal,
            &[0.1, -0.2],
            &[vec![1.5], vec![-0.25]],
            None,
            0.01,
        );
        let rec = parse_recording(&text, "r.csv", 2, 1, 0.01, 10).unwrap();
        assert_eq!(rec.x0, vec![0.1, -0.2]);
        assert_eq!(rec.v, vec![vec![1.5], vec![-0.25]]);
        assert_eq!(rec.locations, None);

        assert_eq!(comment(&text, "player").as_deref(), Some("Ann"));
        assert_eq!(
            comment(&text, "ending").and_then(|e| Ending::parse(&e)),
            Some(Ending::Goal)
        );
        assert_eq!(
            comment(&text, "played").as_deref(),
            Some("2026-01-01T00:00:00Z")
        );
        // A forced run's rows carry their locations, which read back.
        let text = recording_text(
            "Ann",
            "2026-01-01T00:00:00Z",
            Ending::Timeout,
            &[0.1, -0.2],
            &[vec![1.5], vec![-0.25], vec![0.0]],
            Some(&["fwd", "fwd", "back"]),
            0.01,
        );
        let rec = parse_recording(&text, "r.csv", 2, 1, 0.01, 10).unwrap();
        assert_eq!(rec.v, vec![vec![1.5], vec![-0.25], vec![0.0]]);
        assert_eq!(
            rec.locations,
            Some(vec!["fwd".to_string(), "fwd".into(), "back".into()])
        );
    }

    #[test]
    fn dates_and_names() {
        let d = now_utc();
        assert_eq!(d.len(), 20, "{d}");
        assert!(d.starts_with("20"), "{d}");
        assert_eq!(slug("Ann B."), "ann_b_");
        assert_eq!(slug("ü"), "player");
        assert_eq!(file_number(Path::new("out/run-0042-ann.csv")), Some(42));
        let l = chol2([[4.0, 2.0], [2.0, 5.0]]).unwrap();
        assert_eq!(l, [[2.0, 0.0], [1.0, 2.0]]);
    }
}
