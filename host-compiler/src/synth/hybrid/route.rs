//! Routes of the global search ([`crate::trajectory::route`]) as seeds of runs with internal switching
//! (§4.2.2; issue 48 item 3): what answers [`crate::cover::seeds::Ask::Routes`] for an automaton whose
//! path crosses internal guards. This is how a seed gets a run in another homotopy class than the one the
//! planner's first iterate falls into — Example 5.6's corner near x₁ = −4, x₃ = −4, which "needs a
//! fundamentally new trajectory, possibly passing under the unsafe region".
//!
//! **Where the route crosses the guard.** The search runs once per seed in the state coordinates Goal and
//! Unsafe are written in, from the seed to Goal through the free space, with no notion of locations
//! ([`crate::cover::seeds::Routing`], the grid shared with the one-location loops). Goal lies in the
//! path's last location and the seed in its first, so every such route crosses each guard of the path;
//! it is split where it first enters each guard (the crossing point is the one the search chose, on the
//! shortest clear way in its class). The alternative — routes from the seed to the deep-guard polytope,
//! then the usual last segment — would choose the crossing without looking past the guard: it crosses
//! where the guard is nearest whatever lies beyond, and Example 5.5's wall straddles the guard, so the
//! way on from there may be closed. A route to Goal crosses where the way on is clear, and its rest is
//! the last segment's guide.
//!
//! **A route's run.** The planner of [`super::plan_run`] ([`super::plan_guided`]), with each segment's
//! first linearisation point a timed reference ([`crate::trajectory::route::timed_guess`]) along its
//! piece of the route: a segment but the last along the piece from its start (the seed, or the landing
//! of the previous segment in place of the route's crossing point) to the first route point the guard
//! holds `depth` deep, arriving at the segment's end; the last segment along the rest of the route to
//! Goal. From there everything is [`super::plan_run`]'s: the depths, the landing, the certificate
//! ([`super::certify_run`]) and §5.3 ([`super::optimise`]), over [`ROUTE_DURATIONS`]. A route only
//! proposes; the run is certified as shipped whatever it came from. Routes in distinct classes give
//! distinct proposals, [`Origin::Route`]`(k)`, best first.
//!
//! **Continuation.** The route keeps its clearance from Unsafe and moves at a constant pace, while the
//! plant reaches the guard on its own time: taken at once as the linearisation point, the supporting
//! half-spaces of Unsafe at the route's points (one per sample, in time) exclude the plant's way and the
//! first subproblem is infeasible. So the route is first the guess against Unsafe shrunk about its
//! centre ([`GROWTH`]), each generated trajectory the next guess, and the segment then meets Unsafe as
//! it is from a trajectory of the plant on the route's side. Example 5.5's way under the wall is thin
//! (the left location reaches x₁ = 0 below the wall only just, pumped across after settling under it),
//! which is why a direct guess fails there and why the δ of such runs is small.
//!
//! A guard constraining a state column outside the route coordinates is judged with the seed's value in
//! that column (the route does not move it); a route that then never enters a guard of the path
//! proposes nothing.

use super::{gen_problem, plan_guided, HybridRun, HybridTask, Leg, DURATIONS};
use crate::cover::seeds::{Origin, Proposal, Routing};
use crate::property::{ConvexPiece, ConvexSets};
use crate::trajectory::generate::{generate_from, GenSettings};
use crate::trajectory::route::{dist, timed_guess, Route};
use crate::trajectory::Nominal;

/// The sizes of Unsafe (fractions, about each ellipsoid's centre) a route's first linearisation point
/// is carried through before the generator meets Unsafe as it is (module doc).
pub const GROWTH: [f64; 3] = [0.6, 0.8, 0.9];

/// Segment durations tried along a route, as fractions of T: the planner's ([`DURATIONS`]) and two
/// between its 0.1 and 0.2, where a run that stays under Example 5.5's wall crosses the guard (it first
/// settles below the wall, then is pumped across x₁ = 0, later than the shorter durations allow).
pub const ROUTE_DURATIONS: [f64; 8] = [
    DURATIONS[0],
    DURATIONS[1],
    DURATIONS[2],
    DURATIONS[3],
    0.13,
    0.16,
    DURATIONS[4],
    DURATIONS[5],
];

/// The runs along the routes of the global search from `x0` (module doc), one proposal per route,
/// made as they are taken; none for forced switching or a path without guards.
pub fn routed_runs<'s>(
    task: &'s HybridTask,
    routing: &'s Routing<'_>,
    x0: &'s [f64],
) -> Box<dyn Iterator<Item = Proposal<Result<HybridRun, String>>> + 's> {
    if task.forced || task.path.len() < 2 {
        return Box::new(std::iter::empty());
    }
    let Some(map) = routing.map() else {
        return Box::new(std::iter::empty());
    };
    let routes = routing.routes(map, x0);
    let coords = map.coords();
    let arrive = routing.settings().arrive;
    // A route the search returned twice (its classes are not told apart outside the plane) is planned
    // once, under its first index.
    let distinct: Vec<(usize, Route)> = routes
        .iter()
        .enumerate()
        .filter(|(k, r)| routes[..*k].iter().all(|q| q.points != r.points))
        .map(|(k, r)| (k, r.clone()))
        .collect();
    Box::new(distinct.into_iter().map(move |(k, route)| Proposal {
        origin: Origin::Route(k),
        candidate: plan_along(task, &route, coords, arrive, x0, &ROUTE_DURATIONS),
    }))
}

/// The run planned along `route` (points in the route coordinates `coords`, the last segment's
/// reference reaching Goal at `arrive` of its samples) from `x0` over the first segments' `durations`
/// (fractions of T; [`ROUTE_DURATIONS`] in the cover) (module doc), or why there is none.
pub fn plan_along(
    task: &HybridTask,
    route: &Route,
    coords: &[usize],
    arrive: f64,
    x0: &[f64],
    durations: &[f64],
) -> Result<HybridRun, String> {
    let states = lift(route, coords, x0);
    // Where the route first enters each guard of the path, in order along it.
    let mut crossings = Vec::with_capacity(task.edges.len());
    let mut from = 0;
    for (i, &e) in task.edges.iter().enumerate() {
        let guard = &task.plant.edges()[e].guard;
        let at = (from..states.len())
            .find(|&j| guard.contains(&states[j]))
            .ok_or_else(|| format!("the route does not enter the guard of edge {i}"))?;
        crossings.push(at);
        from = at;
    }
    let gs = GenSettings::default();
    let guide = |leg: &Leg<'_>| -> Option<Nominal> {
        let i = leg.segment;
        let begin = if i == 0 { 0 } else { crossings[i - 1] };
        let (end, arrive) = match leg.depth {
            // The first route point the guard holds `depth` deep (or the route's end), reached at the
            // segment's end.
            Some(depth) => {
                let guard = &task.plant.edges()[task.edges[i]].guard;
                let end = (crossings[i]..states.len())
                    .find(|&j| guard.margin(&states[j]) <= -depth)
                    .unwrap_or(states.len() - 1);
                (end, 1.0)
            }
            None => (states.len() - 1, arrive),
        };
        // The piece from the segment's own start (the seed, or the landing for the route's crossing).
        let mut points = vec![coords.iter().map(|&j| leg.start[j]).collect::<Vec<f64>>()];
        points.extend(route.points[begin..=end].iter().skip(1).cloned());
        let piece = Route {
            length: points.windows(2).map(|w| dist(&w[0], &w[1])).sum(),
            points,
            clearance: route.clearance,
            signature: Vec::new(),
        };
        let m = task.plant.modes()[task.path[i]].flow.m();
        let mut guess = timed_guess(&piece, coords, leg.start, leg.steps, arrive, m);
        // Continuation: the route's class carried through Unsafe grown to its size.
        for &scale in &GROWTH {
            let sets = shrunk(leg.convex, scale);
            let gp = gen_problem(task, task.path[i], &sets, leg.steps);
            match generate_from(&gp, leg.start, &gs, &guess) {
                Ok(g) => guess = g.nominal,
                Err(_) => break,
            }
        }
        Some(guess)
    };
    plan_guided(task, x0, durations, &guide)
}

/// `convex` with each Unsafe ellipsoid shrunk about its centre to `scale` of its size (Q/scale²);
/// polytopes as they are.
fn shrunk(convex: &ConvexSets, scale: f64) -> ConvexSets {
    let unsafe_pieces = convex
        .unsafe_pieces
        .iter()
        .map(|p| match p {
            ConvexPiece::Ellipsoid { C, c, Q } => ConvexPiece::Ellipsoid {
                C: C.clone(),
                c: c.clone(),
                Q: Q * faer::Scale(1.0 / (scale * scale)),
            },
            ConvexPiece::Polytope { .. } => p.clone(),
        })
        .collect();
    ConvexSets {
        goal: convex.goal.clone(),
        unsafe_pieces,
    }
}

/// The route's points as states: `x0` with its route coordinates moved.
fn lift(route: &Route, coords: &[usize], x0: &[f64]) -> Vec<Vec<f64>> {
    route
        .points
        .iter()
        .map(|y| {
            let mut x = x0.to_vec();
            for (c, &j) in coords.iter().enumerate() {
                x[j] = y[c];
            }
            x
        })
        .collect()
}
