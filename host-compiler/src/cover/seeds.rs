//! The seed sources of every cover loop (Algorithm 1's seeds, Algorithm 4 of §5.4, the routes of the
//! global search, people's recordings) behind one interface, and the provenance each certified
//! trajectory keeps.
//!
//! A loop (`cover::grow`, `synth::hybrid`, `synth::temporal`) picks a [`Seed`]: a start state and, for
//! Algorithm 4, the ball it grows from with the point it starts at. It asks the seed's sources in the
//! order [`Seed::asks`] gives — Algorithm 4 from the ball, the generator from the start, then the routes
//! of the global search — through its [`Sources`], which answers each [`Ask`] with [`Proposal`]s, lazily
//! and in order (a route search runs only when the routes are asked for). The loop certifies each
//! candidate as it always has and keeps the first it accepts; a proposal never certifies anything. Every
//! accepted trajectory carries its [`Source`] (which recording, which route, which ball), which the
//! report reads. A recording is not a seed: it is certified as recorded ([`certify_recording`];
//! `synth::hybrid::import` for an automaton) and keeps [`Origin::Import`].
//!
//! [`Generators`] answers for a one-location task (the SCP generator, the routes of
//! [`crate::trajectory::route`] as its first linearisation points, a ball's reference table), and records
//! every route search it ran ([`RouteSearch`]); `synth::hybrid` answers for an automaton with its
//! planners.

use super::CoverTrajectory;
use crate::certify::{self, Certificate, Loop, LoopConstants};
use crate::linalg::round32;
use crate::property::ConvexSets;
use crate::trajectory::csv::Recording;
use crate::trajectory::generate::{generate, generate_from, GenError, GenProblem, GenSettings};
use crate::trajectory::route::{timed_guess, Route, RouteMap, RouteSettings};
use crate::trajectory::track::{references, TrackError};
use crate::trajectory::Nominal;
use std::sync::{Mutex, OnceLock};

/// Where a candidate came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Origin {
    /// A recording (`synth --import`, or a run `play` wrote), by name.
    Import(String),
    /// The generator from the seed itself (the SCP generator; an automaton's planner).
    Generator,
    /// Route k (from 0, best first) of the global search from the seed, the generator's first
    /// linearisation point.
    Route(usize),
    /// Algorithm 4: the reference (or run) of trajectory j of the cover, from a start near its ball.
    Algorithm4(usize),
}

/// A certified trajectory's provenance: its origin, and whether §5.3 maximised its δ afterwards.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Source {
    pub origin: Origin,
    pub optimised: bool,
}

impl Source {
    pub fn new(origin: Origin, optimised: bool) -> Self {
        Self { origin, optimised }
    }

    /// A recording's, by name.
    pub fn import(name: &str) -> Self {
        Self::new(Origin::Import(name.to_string()), false)
    }

    /// The route (from 0) it came from directly, if any.
    pub fn route(&self) -> Option<usize> {
        match self.origin {
            Origin::Route(k) => Some(k),
            _ => None,
        }
    }
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.origin {
            Origin::Import(name) => return write!(f, "csv:{name}"),
            Origin::Generator if self.optimised => f.write_str("generated (SCP)")?,
            Origin::Generator => f.write_str("generated")?,
            Origin::Route(k) => write!(f, "route {} (SCP)", k + 1)?,
            Origin::Algorithm4(j) => write!(f, "Algorithm 4 from #{j}")?,
        }
        if self.optimised {
            f.write_str(" + §5.3")?;
        }
        Ok(())
    }
}

impl serde::Serialize for Source {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl PartialEq<&str> for Source {
    fn eq(&self, other: &&str) -> bool {
        self.to_string() == *other
    }
}

/// A seed of a growth round: where a candidate starts, and for Algorithm 4 the ball (by index in the
/// cover) it grows from with the point it starts at (a projection onto that ball's boundary, or the seed
/// itself).
#[derive(Clone, Debug, PartialEq)]
pub struct Seed {
    pub x: Vec<f64>,
    pub grow: Option<(usize, Vec<f64>)>,
}

impl Seed {
    /// A seed the generator starts from.
    pub fn at(x: Vec<f64>) -> Self {
        Self { x, grow: None }
    }

    /// The order its sources are asked in: Algorithm 4 from its ball (when it has one), the generator,
    /// then the routes of the global search. A new seed source takes its place here.
    pub fn asks(&self) -> Vec<Ask> {
        let grow = self.grow.is_some().then_some(Ask::Grow);
        grow.into_iter()
            .chain([Ask::Generator, Ask::Routes])
            .collect()
    }
}

/// One source a seed asks ([`Seed::asks`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ask {
    /// Algorithm 4 from the seed's ball.
    Grow,
    /// The generator from the seed.
    Generator,
    /// The routes of the global search from the seed, best first.
    Routes,
}

/// A candidate from a source: a reference to certify, or a run a planner certified.
#[derive(Clone, Debug)]
pub struct Proposal<C> {
    pub origin: Origin,
    pub candidate: C,
}

/// What a loop's seed sources answer.
pub trait Sources {
    /// A candidate, or why the source gave none.
    type Candidate;

    /// The candidates one source gives from `seed`, in order, made as they are taken (none when that
    /// source has nothing from there).
    fn answer<'s>(
        &'s self,
        seed: &'s Seed,
        ask: Ask,
    ) -> Box<dyn Iterator<Item = Proposal<Self::Candidate>> + 's>;

    /// Every candidate from `seed`, in the order of [`Seed::asks`], made as they are taken.
    fn proposals<'s>(
        &'s self,
        seed: &'s Seed,
    ) -> impl Iterator<Item = Proposal<Self::Candidate>> + 's
    where
        Self: Sized,
    {
        seed.asks()
            .into_iter()
            .flat_map(move |a| self.answer(seed, a))
    }
}

/// The routes one search found from one seed (in the route coordinates: state columns `coords`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RouteSearch {
    pub seed: Vec<f64>,
    pub coords: Vec<usize>,
    pub routes: Vec<Route>,
}

/// The global search of a task: its grid, built on first use, and every search run so far (one per
/// seed, recalled when the seed asks again). Shared by every loop that asks for routes
/// ([`Generators::with_routes`]; `synth::hybrid::route` for internal switching).
pub struct Routing<'a> {
    convex: &'a ConvexSets,
    init: (&'a [f64], &'a [f64]),
    settings: RouteSettings,
    map: OnceLock<Option<RouteMap>>,
    found: Mutex<Vec<RouteSearch>>,
}

impl<'a> Routing<'a> {
    /// The search over `convex` (Goal and Unsafe in state coordinates), its grid spanning the Init box
    /// `lo`..`hi`, with the default settings.
    pub fn new(convex: &'a ConvexSets, lo: &'a [f64], hi: &'a [f64]) -> Self {
        Self {
            convex,
            init: (lo, hi),
            settings: RouteSettings::default(),
            map: OnceLock::new(),
            found: Mutex::new(Vec::new()),
        }
    }

    /// The search's settings.
    pub fn settings(&self) -> &RouteSettings {
        &self.settings
    }

    /// The grid (built on first use); `None` when the sets constrain no coordinate.
    pub fn map(&self) -> Option<&RouteMap> {
        self.map
            .get_or_init(|| RouteMap::new(self.convex, self.init.0, self.init.1, &self.settings))
            .as_ref()
    }

    /// The routes from `x0` (searched once per seed, then recalled).
    pub fn routes(&self, map: &RouteMap, x0: &[f64]) -> Vec<Route> {
        let lock = || self.found.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(s) = lock().iter().find(|s| s.seed == x0) {
            return s.routes.clone();
        }
        let routes = map.routes(x0);
        let mut found = lock();
        if !found.iter().any(|s| s.seed == x0) {
            found.push(RouteSearch {
                seed: x0.to_vec(),
                coords: map.coords().to_vec(),
                routes: routes.clone(),
            });
        }
        routes
    }

    /// Every route search run so far, ordered by seed (so independent of the thread count).
    pub fn searches(&self) -> Vec<RouteSearch> {
        let mut found = self.found.lock().unwrap_or_else(|e| e.into_inner()).clone();
        found.sort_by(|a, b| {
            a.seed
                .iter()
                .zip(&b.seed)
                .map(|(x, y)| x.total_cmp(y))
                .find(|o| o.is_ne())
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        found
    }
}

/// The seed sources of a one-location task (module doc): the SCP generator over `gp`, its references
/// held over blocks of `hold` samples, and optionally the routes of the global search.
pub struct Generators<'a> {
    gp: &'a GenProblem<'a>,
    settings: GenSettings,
    hold: usize,
    routing: Option<Routing<'a>>,
}

impl<'a> Generators<'a> {
    /// The generator alone.
    pub fn new(gp: &'a GenProblem<'a>, hold: usize) -> Self {
        Self {
            gp,
            settings: GenSettings::default(),
            hold,
            routing: None,
        }
    }

    /// With the routes of the global search over `convex`, its grid spanning the Init box `lo`..`hi`.
    pub fn with_routes(mut self, convex: &'a ConvexSets, lo: &'a [f64], hi: &'a [f64]) -> Self {
        self.routing = Some(Routing::new(convex, lo, hi));
        self
    }

    /// The generator's reference from `x0`, held, or why there is none.
    pub fn generated(&self, x0: &[f64]) -> Result<Vec<Vec<f64>>, GenError> {
        let mut v = generate(self.gp, x0, &self.settings)?.nominal.v;
        crate::trajectory::hold::project(&mut v, self.hold);
        Ok(v)
    }

    /// The generator's references from `x0` along each route, best route first (a route it cannot
    /// follow gives none), made as they are taken.
    pub fn routed<'s>(
        &'s self,
        x0: &'s [f64],
    ) -> impl Iterator<Item = Proposal<Vec<Vec<f64>>>> + 's {
        let routes = self
            .routing
            .as_ref()
            .and_then(|r| Some((r, r.map()?)))
            .map(|(r, map)| (map, r.routes(map, x0)));
        let (map, routes) = match routes {
            Some((map, routes)) => (Some(map), routes),
            None => (None, Vec::new()),
        };
        routes
            .into_iter()
            .enumerate()
            .filter_map(move |(k, route)| {
                let (map, gp) = (map?, self.gp);
                let arrive = self.routing.as_ref()?.settings.arrive;
                let (steps, m) = (gp.steps, gp.plant.m());
                let guess = timed_guess(&route, map.coords(), x0, steps, arrive, m);
                let mut v = generate_from(gp, x0, &self.settings, &guess)
                    .ok()?
                    .nominal
                    .v;
                crate::trajectory::hold::project(&mut v, self.hold);
                Some(Proposal {
                    origin: Origin::Route(k),
                    candidate: v,
                })
            })
    }

    /// Every route search run so far, ordered by seed (so independent of the thread count).
    pub fn searches(&self) -> Vec<RouteSearch> {
        self.routing
            .as_ref()
            .map_or_else(Vec::new, Routing::searches)
    }

    /// These sources over a cover whose balls have these reference tables (Algorithm 4's).
    pub fn over<'s>(&'s self, references: Vec<&'s [Vec<f64>]>) -> OneLocation<'s> {
        OneLocation {
            gens: self,
            references,
        }
    }
}

/// A one-location task's sources over its cover so far: a ball's reference is Algorithm 4's candidate
/// (for `cover::grow` §5.4's feedback law from the boundary, [`super::alg4::feedback_law_reference`]).
pub struct OneLocation<'s> {
    gens: &'s Generators<'s>,
    references: Vec<&'s [Vec<f64>]>,
}

impl Sources for OneLocation<'_> {
    type Candidate = Result<Vec<Vec<f64>>, GenError>;

    fn answer<'s>(
        &'s self,
        seed: &'s Seed,
        ask: Ask,
    ) -> Box<dyn Iterator<Item = Proposal<Self::Candidate>> + 's> {
        match ask {
            Ask::Grow => Box::new(seed.grow.iter().filter_map(|(j, _)| {
                Some(Proposal {
                    origin: Origin::Algorithm4(*j),
                    candidate: Ok(self.references.get(*j)?.to_vec()),
                })
            })),
            Ask::Generator => Box::new(std::iter::once_with(|| Proposal {
                origin: Origin::Generator,
                candidate: self.gens.generated(&seed.x),
            })),
            Ask::Routes => Box::new(self.gens.routed(&seed.x).map(|p| Proposal {
                origin: p.origin,
                candidate: Ok(p.candidate),
            })),
        }
    }
}

/// The one path from a recording (a person's run: `synth --import`, `host-compiler play`) to its nominal
/// and certificate on a one-location plant: the initial state rounded to f32 (what the image stores), the
/// references as recorded or derived from the recording's applied inputs or states along the replay of
/// the loop's model (`trajectory::track::references`, with the shipped gain), then [`certify::shipped`].
/// A recording is accepted when the certificate is certified; its trajectory's source is
/// [`Source::import`]. `Err`: why the recording gives no references (its states cannot be followed
/// within the input bound, or it does not fit the model).
pub fn certify_recording(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    rec: &Recording,
) -> Result<(Nominal, Certificate), TrackError> {
    let x0: Vec<f64> = rec.x0.iter().map(|&v| round32(v)).collect();
    let v = references(lp.model(), lp.K, lp.input, &x0, rec)?;
    Ok(certify::shipped(lp, lc, &x0, &v))
}

/// Why a recording's certificate refuses it, for the messages that name it: the binding part with the
/// sample where it binds and what it asks of the route (`period`: seconds per sample).
pub fn recording_refusal(c: &Certificate, period: f64) -> String {
    use crate::certify::Binding;
    let at = |k: usize| format!("sample {k}, t = {:.3} s", k as f64 * period);
    let what = match c.binding() {
        Binding::Goal(_) => format!(
            "it does not end inside Goal with room to spare (closest at {}): the run must end deeper in \
             Goal within the horizon",
            at(c.k_star)
        ),
        Binding::Unsafe(_) => format!(
            "it passes too close to Unsafe for its speed (nearest at the samples at {}; between samples \
             the margin also pays for the motion over a period): keep further off, or slow down there",
            at(c.k_unsafe)
        ),
        Binding::Input(_) => format!(
            "its inputs come too close to the input bound (at {}): the tube needs room in the inputs too",
            at(c.k_input)
        ),
        Binding::RCrit { .. } | Binding::NotComputed => String::from("see the binding part"),
    };
    format!(
        "bound by {}: {what} (δ_Goal {:.3e}, δ_Unsafe {:.3e} between samples, δ_Input {:.3e}, r_crit {:.3e})",
        c.binding(),
        c.delta_goal,
        c.delta_unsafe_intersample,
        c.delta_input,
        c.r_crit
    )
}

/// The route (an index into `searches`) each trajectory of a cover came from: its own route, or for
/// Algorithm 4 its ball's, transitively. A route is matched to its search by the trajectory's start
/// (the seed the search ran from).
pub fn routes_of(
    trajs: &[CoverTrajectory],
    searches: &[RouteSearch],
) -> Vec<Option<(usize, usize)>> {
    let mut out: Vec<Option<(usize, usize)>> = Vec::with_capacity(trajs.len());
    for t in trajs {
        let r = match t.source.origin {
            Origin::Route(k) => searches
                .iter()
                .position(|s| s.seed == t.nominal.x[0] && k < s.routes.len())
                .map(|s| (s, k)),
            Origin::Algorithm4(j) => out.get(j).copied().flatten(),
            _ => None,
        };
        out.push(r);
    }
    out
}
