//! The search over switching schedules of a forced-switching task (§4.2.1; issue 48, item 4): which
//! location each sample of a run is in, when a run needs many switches (a DC-DC boost converter switches
//! about every five samples), so that [`super::forced`]'s fixed one-switch candidates have none to offer.
//!
//! **What it searches.** A schedule is a route in the discrete modes: from the seed in the initial
//! location, each sample either stays or takes a forced edge whose guard holds the state (and whose
//! target's invariant does), after at least [`ScheduleSettings::dwell`] samples in a location. A partial
//! schedule is scored by the plant's own flow under the input set's centre (the nominal with no trim, so
//! that the generator keeps the whole input set for the tube): its clearance from Unsafe at every sample
//! so far and its distance to Goal, both in the CAF metric of the sample's location (the metric δ is
//! read in), each by a cheap sound bound per convex piece (a polytope's faces, an ellipsoid's level; see
//! [`Margins`]). A schedule whose state reaches Goal with depth at least δε (`min_robustness`) is whole;
//! its proxy of δ is the least of its clearances and its Goal depth.
//!
//! **Why a beam search over samples, with states merged by cell.** The tree of schedules has L^N leaves
//! (2⁸⁰ for the converter); a mixed-integer program over it would be exact but needs a MIP solver the
//! project does not link, and its answer would still only be proposed. A graph search (Dijkstra/A*) over
//! an a-priori grid of the state space needs a grid whose size is a guess and grows as its resolution to
//! the n. The search here is breadth first by sample (every partial schedule of a layer has the same
//! length, so they compare fairly), and merges the partial schedules of a layer whose states fall in one
//! cell of a grid laid over that layer's own spread (keeping the one with the larger clearance, then fewer
//! switches): in low dimension that keeps every distinct reachable state, a reachable-set exploration,
//! and where the cells outnumber [`ScheduleSettings::width`] the closest to Goal are kept (a beam). A
//! schedule found this way is the shortest at that resolution, which keeps its table short. The search
//! only proposes: each whole schedule it returns is handed to the SCP generator over that schedule and
//! certified by Theorem 4.17 ([`crate::certify::forced`]) exactly as the one-switch candidates are.

use super::HybridTask;
use crate::linalg::{mat_vec, sym_fn};
use crate::model::{Location, Plant};
use crate::property::{ConvexPiece, InputBound};
use std::collections::HashMap;

/// Settings of the schedule search, with documented defaults.
#[derive(Clone, Debug)]
pub struct ScheduleSettings {
    /// Partial schedules kept per sample at most (default 4 096).
    pub width: usize,
    /// Samples a run stays in a location before it may switch again (default 1: a switch at any sample).
    pub dwell: usize,
    /// Whole schedules returned at most, best proxy δ first (default 3).
    pub schedules: usize,
}

impl Default for ScheduleSettings {
    fn default() -> Self {
        Self {
            width: 4096,
            dwell: 1,
            schedules: 3,
        }
    }
}

/// A whole schedule the search found: the location of each step (its length is the run's), its proxy δ
/// (the least clearance from Unsafe and the final Goal depth along the nominal without trim, in the CAF
/// metrics) and its number of switches.
#[derive(Clone, Debug, PartialEq)]
pub struct Found {
    pub steps: Vec<Location>,
    pub proxy: f64,
    pub switches: usize,
}

impl Found {
    /// The schedule as segments: each maximal run of one location and its length.
    pub fn segments(&self) -> Vec<(Location, usize)> {
        let mut out: Vec<(Location, usize)> = Vec::new();
        for &l in &self.steps {
            match out.last_mut() {
                Some((m, n)) if *m == l => *n += 1,
                _ => out.push((l, 1)),
            }
        }
        out
    }
}

/// Sound bounds on a convex piece's signed distance in one location's CAF metric: for a polytope
/// {Hx ≤ b}, g(x) = minᵢ (bᵢ − hᵢx)/‖hᵢ‖_{P⁻¹} (the depth inside, exactly; outside −g is at most the
/// distance); for an ellipsoid {‖Q^{1/2}(Cx − c)‖ ≤ 1}, g(x) = (1 − ‖Q^{1/2}(Cx − c)‖)/‖Q^{1/2}CP^{-1/2}‖
/// (at most the depth inside, at most the distance outside, negated).
enum Margin {
    Faces {
        H: Vec<Vec<f64>>,
        b: Vec<f64>,
        scale: Vec<f64>,
    },
    Level {
        M: faer::Mat<f64>,
        c: Vec<f64>,
        Qh: faer::Mat<f64>,
        lipschitz: f64,
    },
}

impl Margin {
    fn new(piece: &ConvexPiece, roots: &crate::linalg::PdRoots) -> Self {
        match piece {
            ConvexPiece::Polytope { H, b } => {
                let rows = crate::linalg::to_rows(H.as_ref());
                let scale = rows
                    .iter()
                    .map(|h| roots.dual_norm(h).max(1e-300))
                    .collect();
                Margin::Faces {
                    H: rows,
                    b: b.clone(),
                    scale,
                }
            }
            ConvexPiece::Ellipsoid { C, c, Q } => {
                // Q is positive definite (spec validation); its root exists.
                let Qh = sym_fn(Q.as_ref(), f64::sqrt).unwrap_or_else(|| Q.clone());
                let lipschitz = roots.norm_from((&Qh * C).as_ref()).max(1e-300);
                Margin::Level {
                    M: C.clone(),
                    c: c.clone(),
                    Qh,
                    lipschitz,
                }
            }
        }
    }

    fn at(&self, x: &[f64]) -> f64 {
        match self {
            Margin::Faces { H, b, scale } => H
                .iter()
                .zip(b)
                .zip(scale)
                .map(|((h, bi), s)| (bi - h.iter().zip(x).map(|(a, v)| a * v).sum::<f64>()) / s)
                .fold(f64::INFINITY, f64::min),
            Margin::Level {
                M,
                c,
                Qh,
                lipschitz,
            } => {
                let y: Vec<f64> = mat_vec(M.as_ref(), x)
                    .iter()
                    .zip(c)
                    .map(|(a, b)| a - b)
                    .collect();
                let level = mat_vec(Qh.as_ref(), &y)
                    .iter()
                    .map(|v| v * v)
                    .sum::<f64>()
                    .sqrt();
                (1.0 - level) / lipschitz
            }
        }
    }
}

/// Goal and the pieces of Unsafe as [`Margin`]s in one location's metric.
struct Margins {
    goal: Margin,
    unsafe_pieces: Vec<Margin>,
}

impl Margins {
    fn new(task: &HybridTask, loc: Location) -> Self {
        let roots = &task.constants[loc].roots;
        Self {
            goal: Margin::new(&task.convex.goal, roots),
            unsafe_pieces: task
                .convex
                .unsafe_pieces
                .iter()
                .map(|p| Margin::new(p, roots))
                .collect(),
        }
    }

    /// A lower bound on the distance from Unsafe (+∞ without Unsafe; ≤ 0 inside a piece).
    fn clearance(&self, x: &[f64]) -> f64 {
        self.unsafe_pieces
            .iter()
            .map(|m| -m.at(x))
            .fold(f64::INFINITY, f64::min)
    }
}

/// A partial schedule at one sample: its state, location, parent in the previous layer, the least
/// clearance so far, the samples spent in its location, and its switches.
#[derive(Clone)]
struct Node {
    x: Vec<f64>,
    loc: Location,
    parent: usize,
    clear: f64,
    dwell: usize,
    switches: usize,
    /// Goal's signed margin at x (positive inside).
    goal: f64,
}

/// The input the search flows the plant under: the input set's centre.
fn centre(input: &InputBound) -> Vec<f64> {
    match input {
        InputBound::Box { lo, hi } => lo.iter().zip(hi).map(|(l, h)| 0.5 * (l + h)).collect(),
        InputBound::Norm2 { center, .. } => center.clone(),
    }
}

/// Search schedules from `x0` in the task's initial location (module doc), at most `steps` samples long:
/// the whole ones found, best proxy δ first (then fewer switches), at most one per length. Empty when no
/// schedule reaches Goal clear of Unsafe under the search's input.
pub fn search(
    task: &HybridTask,
    x0: &[f64],
    steps: usize,
    settings: &ScheduleSettings,
) -> Vec<Found> {
    let locations = task.plant.locations();
    let margins: Vec<Margins> = (0..locations).map(|l| Margins::new(task, l)).collect();
    let floor = task.problem.synthesis.min_robustness.max(0.0);
    let u = centre(&task.property.input);
    let n = x0.len();
    let l0 = task.initial;
    let width = settings.width.max(1);
    // Cells per coordinate of a layer's spread: about 2·width cells in all.
    let resolution = (2.0 * width as f64).powf(1.0 / n.max(1) as f64).max(2.0);
    let start = Node {
        x: x0.to_vec(),
        loc: l0,
        parent: usize::MAX,
        clear: margins[l0].clearance(x0),
        dwell: 0,
        switches: 0,
        goal: margins[l0].goal.at(x0),
    };
    if start.clear < floor {
        return Vec::new();
    }
    let mut layers: Vec<Vec<Node>> = vec![vec![start]];
    // Whole schedules: (proxy, switches, layer, index).
    let mut whole: Vec<(f64, usize, usize, usize)> = Vec::new();
    for k in 1..=steps {
        let prev = &layers[k - 1];
        let mut next: Vec<Node> = Vec::new();
        for (i, node) in prev.iter().enumerate() {
            // Step k−1 → k is taken in `to`: the node's own location, or one a forced edge leads to.
            let stay = std::iter::once(node.loc);
            // The start's dwell is 0: the first step is taken in the initial location.
            let may_switch = node.dwell >= settings.dwell.max(1);
            let moves = task
                .plant
                .edges()
                .iter()
                .filter(|e| {
                    may_switch
                        && e.from == node.loc
                        && e.to != node.loc
                        && e.kind == crate::model::hybrid::EdgeKind::Forced
                        && e.guard.contains(&node.x)
                })
                .map(|e| e.to);
            for to in stay.chain(moves) {
                let invariant_holds = |x: &[f64]| {
                    task.plant.modes()[to]
                        .invariant
                        .as_ref()
                        .is_none_or(|p| p.contains(x))
                };
                if !invariant_holds(&node.x) {
                    continue;
                }
                let x = task.plant.step(to, &node.x, &u);
                if !x.iter().all(|v| v.is_finite()) || !invariant_holds(&x) {
                    continue;
                }
                let m = &margins[to];
                let clear = node.clear.min(m.clearance(&x));
                if clear < floor {
                    continue;
                }
                let switched = to != node.loc;
                next.push(Node {
                    goal: m.goal.at(&x),
                    x,
                    loc: to,
                    parent: i,
                    clear,
                    dwell: if switched { 1 } else { node.dwell + 1 },
                    switches: node.switches + usize::from(switched),
                });
            }
        }
        if next.is_empty() {
            break;
        }
        let merged = merge(next, resolution);
        let kept = beam(merged, width);
        for (i, node) in kept.iter().enumerate() {
            if node.goal >= floor {
                whole.push((node.clear.min(node.goal), node.switches, k, i));
            }
        }
        layers.push(kept);
    }
    whole.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut out: Vec<Found> = Vec::new();
    for (proxy, switches, k, i) in whole {
        if out.len() == settings.schedules {
            break;
        }
        if out.iter().any(|f| f.steps.len() == k) {
            continue;
        }
        out.push(Found {
            steps: path(&layers, k, i),
            proxy,
            switches,
        });
    }
    out
}

/// The locations of steps 0..k of the partial schedule `i` of layer `k` (step κ is taken in the location
/// of the node at sample κ + 1).
fn path(layers: &[Vec<Node>], k: usize, i: usize) -> Vec<Location> {
    let mut out = vec![0; k];
    let mut idx = i;
    for j in (1..=k).rev() {
        let node = &layers[j][idx];
        out[j - 1] = node.loc;
        idx = node.parent;
    }
    out
}

/// The nodes of one layer merged by cell (module doc): per location and cell of the layer's own spread
/// divided `resolution` times per coordinate, the node with the larger clearance, then fewer switches,
/// then the first. In the order of first appearance, so the result does not depend on hashing.
fn merge(nodes: Vec<Node>, resolution: f64) -> Vec<Node> {
    let n = nodes[0].x.len();
    let (mut lo, mut hi) = (vec![f64::INFINITY; n], vec![f64::NEG_INFINITY; n]);
    for node in &nodes {
        for (j, v) in node.x.iter().enumerate() {
            lo[j] = lo[j].min(*v);
            hi[j] = hi[j].max(*v);
        }
    }
    let cell: Vec<f64> = lo
        .iter()
        .zip(&hi)
        .map(|(l, h)| ((h - l) / resolution).max(1e-12 * (1.0 + l.abs().max(h.abs()))))
        .collect();
    let mut index: HashMap<(Location, Vec<i64>), usize> = HashMap::new();
    let mut out: Vec<Node> = Vec::new();
    for node in nodes {
        let key: Vec<i64> = node
            .x
            .iter()
            .zip(&lo)
            .zip(&cell)
            .map(|((v, l), c)| ((v - l) / c).floor() as i64)
            .collect();
        match index.get(&(node.loc, key.clone())) {
            Some(&at) => {
                let old = &out[at];
                if node.clear > old.clear
                    || (node.clear == old.clear && node.switches < old.switches)
                {
                    out[at] = node;
                }
            }
            None => {
                index.insert((node.loc, key), out.len());
                out.push(node);
            }
        }
    }
    out
}

/// At most `width` nodes of a layer: all of them when they fit, otherwise the closest to Goal (largest
/// Goal margin), then the clearest, in a stable order.
fn beam(mut nodes: Vec<Node>, width: usize) -> Vec<Node> {
    if nodes.len() > width {
        nodes.sort_by(|a, b| {
            b.goal
                .min(0.0)
                .total_cmp(&a.goal.min(0.0))
                .then(b.clear.total_cmp(&a.clear))
        });
        nodes.truncate(width);
    }
    nodes
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dcdc() -> HybridTask {
        let path = format!("{}/../examples/dcdc-boost.toml", env!("CARGO_MANIFEST_DIR"));
        HybridTask::new(crate::spec::load(&path).expect("the example parses"))
            .expect("a hybrid task")
    }

    #[test]
    fn the_search_finds_a_many_switch_schedule_of_the_dcdc_converter_into_goal_clear_of_unsafe() {
        let task = dcdc();
        let x0 = [1.2, 5.5];
        let found = search(&task, &x0, task.steps, &ScheduleSettings::default());
        let best = found.first().expect("a whole schedule");
        assert!(best.steps.len() <= task.steps);
        assert!(best.switches >= 4, "{} switches", best.switches);
        assert_eq!(best.segments().len(), best.switches + 1);
        assert_eq!(best.steps[0], task.initial);
        // Flowed under the search's input, it stays out of Unsafe and ends in Goal, as proposed.
        let u = centre(&task.property.input);
        let mut x = x0.to_vec();
        let unsafe_set = task
            .property
            .unsafe_region()
            .expect("the example has Unsafe");
        for &l in &best.steps {
            x = task.plant.step(l, &x, &u);
            assert!(!unsafe_set.contains(&x), "{x:?} in Unsafe");
        }
        assert!(task.property.goal.contains(&x), "ends at {x:?}");
        assert!(best.proxy >= task.problem.synthesis.min_robustness);
        // Best first.
        assert!(found.windows(2).all(|w| w[0].proxy >= w[1].proxy));
    }

    #[test]
    fn found_schedule_splits_into_its_segments() {
        let f = Found {
            steps: vec![0, 0, 1, 1, 1, 0],
            proxy: 1.0,
            switches: 2,
        };
        assert_eq!(f.segments(), vec![(0, 2), (1, 3), (0, 1)]);
    }
}
