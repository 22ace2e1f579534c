//! Global route search (issue 48): routes from a seed state to Goal through the free space of Unsafe,
//! in several homotopy classes, that the SCP generator ([`super::generate`]) takes as its first
//! linearisation point; and the verdict that no route exists at all.
//!
//! What it owns: the grid over the *route coordinates* ([`route_coords`]: the state columns Goal
//! constrains and those of the Unsafe pieces that constrain any of them, so for a feedback-linearizable
//! or flat plant the coordinates of ξ or q the task's sets are written in, not every coordinate its
//! operating region bounds; pieces outside them are ignored, which only widens the free space), the
//! clearance of each cell, the route search on it, the distinct classes, the timed reference along a
//! route ([`timed_guess`]) and the "closed off" verdict ([`RouteMap::closed_off`]). A route only
//! *proposes*: the generator turns it into a trajectory of the plant and everything is certified
//! afterwards exactly as without it.
//!
//! # Method, and why
//! * **Region.** The box spanned by every finite extent of Init, Goal and the Unsafe pieces in the route
//!   coordinates (a half-plane x ≤ 0 contributes its 0), plus a margin of a tenth of its largest side.
//!   Unbounded pieces clip it simply by blocking the cells they hold.
//! * **Grid, bounded.** At most [`RouteSettings::max_cells`] cells (a square-ish cell, coarser in higher
//!   dimensions), so time and memory are bounded whatever the spec.
//! * **Clearance.** Per cell centre a lower bound of its Euclidean distance to each piece: for a
//!   polytope the largest facet distance max_r (h_r·y − b_r)/‖h_r‖, for an ellipsoid
//!   {(Cy − c)ᵀQ(Cy − c) ≤ 1} the bound (√((Cy−c)ᵀQ(Cy−c)) − 1)/(√λ_max(Q)·‖C‖). Both understate the
//!   distance, so a cell kept clear by them is clear.
//! * **Search.** A* (the `pathfinding` crate) over the cells whose clearance is at least c, with c half
//!   the largest clearance at which the seed still reaches Goal (found by bisection with flood fills),
//!   and step costs that grow as the clearance falls below that largest one, so routes keep to the middle
//!   of corridors where the tube has most room. Moves to all 3ᵈ − 1 neighbours up to d = 3 (no corner
//!   cut between blocked cells in the plane), to the 2d face neighbours above.
//! * **Classes.** In the plane, the classes of the free space are told apart by the h-signature: for
//!   each hole (a connected group of blocked cells that does not touch the grid's border) the winding
//!   angle of the route about a point of it; two routes with the same ends are in one class iff every
//!   winding agrees (to less than π). After each route a *cut* is blocked: the segment from the hole the
//!   route passes closest to, through the route, to the next blocked cell or the border, which closes
//!   that side of the hole, so the next search goes round it another way. Routes whose signature was
//!   seen are dropped. In other dimensions a band of width 2c around the route is blocked instead (the
//!   next route keeps that far from it).
//! * **No route at all.** [`RouteMap::closed_off`] floods, with face moves, the cells that are not
//!   wholly inside one Unsafe piece (all corners inside the convex piece), from every cell Init meets,
//!   with the world outside the grid as one more free node. If no cell that may meet Goal is reached,
//!   no continuous path from Init to Goal avoids Unsafe (a free path is open, so it can be moved off
//!   cell edges and corners, and every cell it visits holds a free point). The pieces holding the
//!   blocked cells around the reached region are the ones that close Goal off. This is sound for a
//!   continuous-time plant only (a sampled one may jump a wall between samples), which the caller checks.

use super::Nominal;
use crate::linalg::{mat_vec, spectral_norm, sym_eigenvalues};
use crate::property::{ConvexPiece, ConvexSets};
use faer::Mat;
use std::collections::VecDeque;

/// Settings of the route search, with documented defaults.
#[derive(Clone, Debug)]
pub struct RouteSettings {
    /// Cells of the grid at most. Default 65 536 (256² in the plane, 16⁴ in four dimensions).
    pub max_cells: usize,
    /// Routes (distinct classes) returned at most. Default 3.
    pub routes: usize,
    /// Fraction of the horizon by which the timed reference reaches the route's end. Default 0.8.
    pub arrive: f64,
}

impl Default for RouteSettings {
    fn default() -> Self {
        Self {
            max_cells: 1 << 16,
            routes: 3,
            arrive: 0.8,
        }
    }
}

/// One route: points in the route coordinates from the seed to a point deep in Goal.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Route {
    pub points: Vec<Vec<f64>>,
    /// Its length (Euclidean, in the route coordinates).
    pub length: f64,
    /// The clearance every cell of it keeps from Unsafe (the search's c).
    pub clearance: f64,
    /// Winding about each hole (the plane only; empty otherwise).
    pub signature: Vec<f64>,
}

/// One convex piece restricted to the route coordinates, with what the clearance bound needs.
#[derive(Clone, Debug)]
enum Piece {
    /// Rows (h, b) with ‖h‖ > 0; `empty` when a zero row has b < 0.
    Poly {
        rows: Vec<(Vec<f64>, f64, f64)>,
        empty: bool,
    },
    /// A piece outside the route coordinates, which blocks no cell.
    Ignored,
    /// C restricted, centre, Q, and the scale √λ_max(Q)·‖C‖.
    Ell {
        C: Mat<f64>,
        c: Vec<f64>,
        Q: Mat<f64>,
        scale: f64,
    },
}

impl Piece {
    fn of(p: &ConvexPiece, coords: &[usize]) -> Self {
        match p {
            ConvexPiece::Polytope { H, b } => {
                let mut rows = Vec::new();
                let mut empty = false;
                for r in 0..H.nrows() {
                    let h: Vec<f64> = coords.iter().map(|&j| H[(r, j)]).collect();
                    let nn = h.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if nn > 0.0 {
                        rows.push((h, b[r], nn));
                    } else if b[r] < 0.0 {
                        empty = true;
                    }
                }
                Piece::Poly { rows, empty }
            }
            ConvexPiece::Ellipsoid { C, c, Q } => {
                let Cr = Mat::from_fn(C.nrows(), coords.len(), |i, k| C[(i, coords[k])]);
                let lmax = sym_eigenvalues(Q.as_ref())
                    .and_then(|e| e.into_iter().reduce(f64::max))
                    .unwrap_or(f64::INFINITY)
                    .max(0.0);
                let scale = lmax.sqrt() * spectral_norm(Cr.as_ref());
                Piece::Ell {
                    C: Cr,
                    c: c.clone(),
                    Q: Q.clone(),
                    scale,
                }
            }
        }
    }

    /// A conservative signed distance: outside, at most the distance to the piece; inside, minus at most
    /// the depth. +∞ for an empty piece.
    fn sd(&self, y: &[f64]) -> f64 {
        match self {
            Piece::Poly { rows, empty } => {
                if *empty {
                    return f64::INFINITY;
                }
                rows.iter()
                    .map(|(h, b, nn)| (dot(h, y) - b) / nn)
                    .fold(f64::NEG_INFINITY, f64::max)
            }
            Piece::Ignored => f64::INFINITY,
            Piece::Ell { scale, .. } => {
                let s = self.q(y).sqrt();
                if *scale > 0.0 && scale.is_finite() {
                    (s - 1.0) / scale
                } else {
                    // No usable scale: nothing is claimed either way.
                    0.0
                }
            }
        }
    }

    /// (Cy − c)ᵀQ(Cy − c) of an ellipsoid (0 for a polytope).
    fn q(&self, y: &[f64]) -> f64 {
        match self {
            Piece::Ell { C, c, Q, .. } => {
                let d: Vec<f64> = mat_vec(C.as_ref(), y)
                    .iter()
                    .zip(c)
                    .map(|(a, b)| a - b)
                    .collect();
                let p = d.len();
                (0..p)
                    .map(|i| (0..p).map(|j| d[i] * Q[(i, j)] * d[j]).sum::<f64>())
                    .sum()
            }
            Piece::Poly { .. } | Piece::Ignored => 0.0,
        }
    }

    /// Exact membership (closed).
    fn contains(&self, y: &[f64]) -> bool {
        match self {
            Piece::Poly { rows, empty } => !empty && rows.iter().all(|(h, b, _)| dot(h, y) <= *b),
            Piece::Ell { .. } => self.q(y) <= 1.0,
            Piece::Ignored => false,
        }
    }

    /// The finite extents of the piece along coordinate `i`: (min, max), each `None` where unbounded (or
    /// not computed).
    fn extent(&self, i: usize) -> (Option<f64>, Option<f64>) {
        match self {
            Piece::Ignored => (None, None),
            Piece::Poly { rows, empty } => {
                if *empty || rows.is_empty() {
                    return (None, None);
                }
                (
                    lp_extent(rows, i, 1.0),
                    lp_extent(rows, i, -1.0).map(|v| -v),
                )
            }
            Piece::Ell { C, c, Q, .. } => {
                let d = C.ncols();
                if C.nrows() != d
                    || sym_eigenvalues(Q.as_ref()).is_none_or(|e| e.iter().any(|&l| !(l > 0.0)))
                {
                    return (None, None);
                }
                // y = C⁻¹(c + z), zᵀQz ≤ 1: centre C⁻¹c, half-width √(wᵀQ⁻¹w) with w = C⁻ᵀ e_i.
                let lu = C.as_ref().partial_piv_lu();
                let cc = faer::Mat::<f64>::from_fn(d, 1, |k, _| c[k]);
                let centre = faer::prelude::Solve::solve(&lu, &cc);
                let e = faer::Mat::<f64>::from_fn(d, 1, |k, _| f64::from(k == i));
                let w = faer::prelude::Solve::solve(&C.transpose().partial_piv_lu(), &e);
                let Some(Qi) = crate::linalg::sym_fn(Q.as_ref(), |l| 1.0 / l) else {
                    return (None, None);
                };
                let hw = (0..d)
                    .map(|a| {
                        (0..d)
                            .map(|b| w[(a, 0)] * Qi[(a, b)] * w[(b, 0)])
                            .sum::<f64>()
                    })
                    .sum::<f64>()
                    .max(0.0)
                    .sqrt();
                let m = centre[(i, 0)];
                if m.is_finite() && hw.is_finite() {
                    (Some(m - hw), Some(m + hw))
                } else {
                    (None, None)
                }
            }
        }
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// min s·y_i over {y : h·y ≤ b for every row}, or `None` when unbounded or not solved (a small LP).
fn lp_extent(rows: &[(Vec<f64>, f64, f64)], i: usize, s: f64) -> Option<f64> {
    use clarabel::algebra::CscMatrix;
    use clarabel::solver::{
        DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
    };
    let d = rows[0].0.len();
    let (mut I, mut J, mut V) = (vec![], vec![], vec![]);
    for (r, (h, _, _)) in rows.iter().enumerate() {
        for (j, &v) in h.iter().enumerate() {
            if v != 0.0 {
                I.push(r);
                J.push(j);
                V.push(v);
            }
        }
    }
    let A = CscMatrix::new_from_triplets(rows.len(), d, I, J, V);
    let b: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let P = CscMatrix::<f64>::zeros((d, d));
    let mut q = vec![0.0; d];
    q[i] = s;
    let cones = [SupportedConeT::NonnegativeConeT(rows.len())];
    let st = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(100)
        .build()
        .ok()?;
    let mut solver = DefaultSolver::new(&P, &q, &A, &b, &cones, st).ok()?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {
            let v = s * solver.solution.x[i];
            v.is_finite().then_some(v)
        }
        _ => None,
    }
}

/// The route coordinates of a task's sets (module doc): the state columns Goal constrains, closed under
/// "an Unsafe piece that constrains one of them adds all of its own"; every column some piece
/// constrains when Goal constrains none. So an operating region's bound on a coordinate neither Goal
/// nor an obstacle around it weighs (a feedback-linearizable or flat plant's velocities, whose
/// complement joins Unsafe as one-coordinate half-spaces) does not add a dimension to the grid.
pub fn route_coords(convex: &ConvexSets, n: usize) -> Vec<usize> {
    let uses = |p: &ConvexPiece, j: usize| match p {
        ConvexPiece::Polytope { H, .. } => (0..H.nrows()).any(|r| H[(r, j)] != 0.0),
        ConvexPiece::Ellipsoid { C, .. } => (0..C.nrows()).any(|r| C[(r, j)] != 0.0),
    };
    let mut on: Vec<bool> = (0..n).map(|j| uses(&convex.goal, j)).collect();
    if !on.contains(&true) {
        return (0..n)
            .filter(|&j| convex.unsafe_pieces.iter().any(|p| uses(p, j)))
            .collect();
    }
    loop {
        let mut grew = false;
        for p in &convex.unsafe_pieces {
            if (0..n).any(|j| on[j] && uses(p, j)) {
                for (j, o) in on.iter_mut().enumerate() {
                    if !*o && uses(p, j) {
                        *o = true;
                        grew = true;
                    }
                }
            }
        }
        if !grew {
            return (0..n).filter(|&j| on[j]).collect();
        }
    }
}

/// The grid over the route coordinates with each cell's clearance, Goal depth and the Unsafe piece
/// that wholly holds it (module doc).
#[derive(Clone, Debug)]
pub struct RouteMap {
    /// State columns of the route coordinates.
    coords: Vec<usize>,
    /// State dimension.
    n: usize,
    lo: Vec<f64>,
    cell: f64,
    dims: Vec<usize>,
    /// Per cell: conservative distance from its centre to Unsafe (≤ 0 inside).
    clearance: Vec<f64>,
    /// Per cell: conservative depth of its centre in Goal (≤ 0 outside).
    goal_depth: Vec<f64>,
    /// Per cell: the first Unsafe piece that holds the whole cell.
    full: Vec<Option<usize>>,
    /// Whether Goal is bounded in every route coordinate.
    goal_bounded: bool,
    settings: RouteSettings,
}

/// The result of [`RouteMap::closed_off`]: Goal cannot be reached from Init; the pieces that close it off.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClosedOff {
    /// Indices into `ConvexSets::unsafe_pieces`, ascending.
    pub pieces: Vec<usize>,
    /// The route coordinates (state columns) the search was done in, and its cell count.
    pub coords: Vec<usize>,
    pub cells: usize,
}

impl RouteMap {
    /// The grid of a task's sets and Init box (`init_lo`, `init_hi` in state coordinates); `None` when
    /// no coordinate is constrained (nothing to route around).
    pub fn new(
        convex: &ConvexSets,
        init_lo: &[f64],
        init_hi: &[f64],
        settings: &RouteSettings,
    ) -> Option<Self> {
        let n = init_lo.len();
        let uses = |p: &ConvexPiece, j: usize| match p {
            ConvexPiece::Polytope { H, .. } => (0..H.nrows()).any(|r| H[(r, j)] != 0.0),
            ConvexPiece::Ellipsoid { C, .. } => (0..C.nrows()).any(|r| C[(r, j)] != 0.0),
        };
        let coords = route_coords(convex, n);
        let d = coords.len();
        if d == 0 {
            return None;
        }
        let goal = Piece::of(&convex.goal, &coords);
        // A piece that constrains none of the route coordinates (an operating region's bound on a
        // velocity) blocks nothing here: ignoring it only widens the free space, so the routes and the
        // no-route verdict stay what they claim.
        let unsafe_: Vec<Piece> = convex
            .unsafe_pieces
            .iter()
            .map(|p| {
                if (0..n).all(|j| !uses(p, j) || coords.contains(&j)) {
                    Piece::of(p, &coords)
                } else {
                    Piece::Ignored
                }
            })
            .collect();
        // The region: every finite extent, plus a margin.
        let mut lo = vec![f64::INFINITY; d];
        let mut hi = vec![f64::NEG_INFINITY; d];
        let mut take = |k: usize, v: f64| {
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        };
        for (k, &j) in coords.iter().enumerate() {
            take(k, init_lo[j]);
            take(k, init_hi[j]);
        }
        let mut goal_bounded = true;
        for k in 0..d {
            let (a, b) = goal.extent(k);
            goal_bounded &= a.is_some() && b.is_some();
            for v in a.into_iter().chain(b) {
                take(k, v);
            }
            for p in &unsafe_ {
                let (a, b) = p.extent(k);
                for v in a.into_iter().chain(b) {
                    take(k, v);
                }
            }
        }
        let side = (0..d).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        let margin = (0.1 * side).max(1e-3);
        let lo: Vec<f64> = lo.iter().map(|v| v - margin).collect();
        let ext: Vec<f64> = (0..d).map(|k| hi[k] + margin - lo[k]).collect();
        let cap = settings.max_cells.max(2usize.pow(d.min(20) as u32));
        let mut cell = (ext.iter().product::<f64>() / cap as f64).powf(1.0 / d as f64);
        let count = |c: f64| -> Vec<usize> {
            ext.iter()
                .map(|e| ((e / c).ceil() as usize).max(1))
                .collect()
        };
        let mut dims = count(cell);
        while dims.iter().product::<usize>() > cap {
            cell *= 1.05;
            dims = count(cell);
        }
        let total: usize = dims.iter().product();
        let mut map = Self {
            coords,
            n,
            lo,
            cell,
            dims,
            clearance: vec![0.0; total],
            goal_depth: vec![0.0; total],
            full: vec![None; total],
            goal_bounded,
            settings: settings.clone(),
        };
        let half = 0.5 * cell;
        let corners = 1usize << d;
        for i in 0..total {
            let y = map.centre(i);
            let mut clr = f64::INFINITY;
            for (pi, p) in unsafe_.iter().enumerate() {
                let s = p.sd(&y);
                clr = clr.min(s);
                if s <= 0.0 && map.full[i].is_none() {
                    let inside = (0..corners).all(|m| {
                        let c: Vec<f64> = (0..d)
                            .map(|k| y[k] + if m >> k & 1 == 1 { half } else { -half })
                            .collect();
                        p.contains(&c)
                    });
                    if inside {
                        map.full[i] = Some(pi);
                    }
                }
            }
            map.clearance[i] = clr;
            map.goal_depth[i] = -goal.sd(&y);
        }
        Some(map)
    }

    /// The route coordinates (state columns).
    pub fn coords(&self) -> &[usize] {
        &self.coords
    }

    /// Cells of the grid.
    pub fn cells(&self) -> usize {
        self.clearance.len()
    }

    /// Side of a cell.
    pub fn cell_size(&self) -> f64 {
        self.cell
    }

    fn centre(&self, mut i: usize) -> Vec<f64> {
        let mut y = Vec::with_capacity(self.dims.len());
        for (k, &nk) in self.dims.iter().enumerate() {
            y.push(self.lo[k] + (i % nk) as f64 * self.cell + 0.5 * self.cell);
            i /= nk;
        }
        y
    }

    fn index(&self, idx: &[usize]) -> usize {
        let mut i = 0;
        for k in (0..self.dims.len()).rev() {
            i = i * self.dims[k] + idx[k];
        }
        i
    }

    fn unindex(&self, mut i: usize) -> Vec<usize> {
        self.dims
            .iter()
            .map(|&nk| {
                let v = i % nk;
                i /= nk;
                v
            })
            .collect()
    }

    /// The cell holding `y` (clamped to the grid).
    fn cell_of(&self, y: &[f64]) -> usize {
        let idx: Vec<usize> = (0..self.dims.len())
            .map(|k| {
                let t = ((y[k] - self.lo[k]) / self.cell).floor();
                (t.max(0.0) as usize).min(self.dims[k] - 1)
            })
            .collect();
        self.index(&idx)
    }

    fn on_border(&self, i: usize) -> bool {
        self.unindex(i)
            .iter()
            .zip(&self.dims)
            .any(|(&v, &nk)| v == 0 || v + 1 == nk)
    }

    /// Neighbours of cell `i`: face neighbours only (`faces`), or all 3ᵈ − 1 up to d = 3 (in the plane
    /// a diagonal only when both cells beside it pass `open`).
    fn neighbours(&self, i: usize, faces: bool, open: &dyn Fn(usize) -> bool) -> Vec<usize> {
        let d = self.dims.len();
        let idx = self.unindex(i);
        let mut out = Vec::new();
        if faces || d > 3 {
            for k in 0..d {
                for s in [-1i64, 1] {
                    let v = idx[k] as i64 + s;
                    if v >= 0 && (v as usize) < self.dims[k] {
                        let mut j = idx.clone();
                        j[k] = v as usize;
                        out.push(self.index(&j));
                    }
                }
            }
            return out;
        }
        let total = 3usize.pow(d as u32);
        'next: for m in 0..total {
            let mut j = idx.clone();
            let mut mm = m;
            let mut moved = 0;
            for k in 0..d {
                let s = (mm % 3) as i64 - 1;
                mm /= 3;
                let v = idx[k] as i64 + s;
                if v < 0 || v as usize >= self.dims[k] {
                    continue 'next;
                }
                j[k] = v as usize;
                moved += (s != 0) as usize;
            }
            if moved == 0 {
                continue;
            }
            if d == 2 && moved == 2 {
                let a = self.index(&[j[0], idx[1]]);
                let b = self.index(&[idx[0], j[1]]);
                if !open(a) || !open(b) {
                    continue;
                }
            }
            out.push(self.index(&j));
        }
        out
    }

    /// Whether Goal is unreachable from every cell Init's box meets, in the free space (module doc);
    /// `Some` with the pieces that close it off: those wholly holding cells next to both the region
    /// reached from Init and the one reached from Goal (or, if none lies next to both, next to the
    /// first). Sound for continuous-time plants.
    pub fn closed_off(&self, init_lo: &[f64], init_hi: &[f64]) -> Option<ClosedOff> {
        let d = self.dims.len();
        let total = self.cells();
        let rho = 0.5 * self.cell * (d as f64).sqrt();
        let maybe_goal = |i: usize| self.goal_depth[i] >= -rho;
        // Every cell Init's box meets.
        let a: Vec<f64> = self.coords.iter().map(|&j| init_lo[j]).collect();
        let b: Vec<f64> = self.coords.iter().map(|&j| init_hi[j]).collect();
        let (ia, ib) = (
            self.unindex(self.cell_of(&a)),
            self.unindex(self.cell_of(&b)),
        );
        let mut from_init = Vec::new();
        let mut idx = ia.clone();
        loop {
            from_init.push(self.index(&idx));
            let mut k = 0;
            while k < d {
                if idx[k] < ib[k] {
                    idx[k] += 1;
                    break;
                }
                idx[k] = ia[k];
                k += 1;
            }
            if k == d {
                break;
            }
        }
        if from_init.iter().all(|&i| self.full[i].is_some()) {
            // Init inside Unsafe is the spec check's to refuse, not this verdict's.
            return None;
        }
        let (init_side, reached) = self.flood(&from_init, &maybe_goal)?;
        debug_assert!(!reached);
        let goal_cells: Vec<usize> = (0..total).filter(|&i| maybe_goal(i)).collect();
        let goal_side = self
            .flood(&goal_cells, &|_| false)
            .map_or_else(Vec::new, |(p, _)| p);
        let both: Vec<usize> = init_side
            .iter()
            .copied()
            .filter(|p| goal_side.contains(p))
            .collect();
        Some(ClosedOff {
            pieces: if both.is_empty() { init_side } else { both },
            coords: self.coords.clone(),
            cells: total,
        })
    }

    /// Flood fill with face moves over the cells no Unsafe piece wholly holds, from `from`, with the
    /// world outside the grid as one more node: `None` as soon as a cell passing `stop` is reached (or
    /// the outside, when Goal is unbounded); else the pieces wholly holding the blocked cells met
    /// (ascending) and false.
    fn flood(&self, from: &[usize], stop: &dyn Fn(usize) -> bool) -> Option<(Vec<usize>, bool)> {
        let total = self.cells();
        let free = |i: usize| self.full[i].is_none();
        let outside = total;
        let mut seen = vec![false; total + 1];
        let mut queue = VecDeque::new();
        for &i in from {
            if free(i) && !seen[i] {
                seen[i] = true;
                queue.push_back(i);
            }
        }
        let mut blocking: Vec<usize> = Vec::new();
        let mut visit = |j: usize, seen: &mut Vec<bool>, queue: &mut VecDeque<usize>| {
            if free(j) {
                if !seen[j] {
                    seen[j] = true;
                    queue.push_back(j);
                }
            } else if let Some(p) = self.full[j] {
                blocking.push(p);
            }
        };
        while let Some(i) = queue.pop_front() {
            if i == outside {
                if !self.goal_bounded {
                    return None;
                }
                for j in (0..total).filter(|&j| self.on_border(j)) {
                    visit(j, &mut seen, &mut queue);
                }
                continue;
            }
            if stop(i) {
                return None;
            }
            if self.on_border(i) && !seen[outside] {
                seen[outside] = true;
                queue.push_back(outside);
            }
            for j in self.neighbours(i, true, &|_| true) {
                visit(j, &mut seen, &mut queue);
            }
        }
        blocking.sort_unstable();
        blocking.dedup();
        Some((blocking, false))
    }

    /// Routes from the state `x0` to Goal in distinct classes, best first (module doc); empty when the
    /// grid holds none.
    pub fn routes(&self, x0: &[f64]) -> Vec<Route> {
        let d = self.dims.len();
        let total = self.cells();
        let y0: Vec<f64> = self.coords.iter().map(|&j| x0[j]).collect();
        let start = self.cell_of(&y0);
        // Where a route ends: half the largest depth in Goal among cells clear of Unsafe.
        let dmax = (0..total)
            .filter(|&i| self.clearance[i] > 0.0)
            .map(|i| self.goal_depth[i])
            .fold(f64::NEG_INFINITY, f64::max);
        if !(dmax > 0.0) {
            return vec![];
        }
        let d_goal = 0.5 * dmax;
        let reaches = |c: f64, extra: &[bool]| -> bool {
            let open = |i: usize| i == start || (self.clearance[i] >= c && !extra[i]);
            let goal = |i: usize| self.goal_depth[i] >= d_goal && self.clearance[i] >= c;
            let mut seen = vec![false; total];
            seen[start] = true;
            let mut q = VecDeque::from([start]);
            while let Some(i) = q.pop_front() {
                if goal(i) {
                    return true;
                }
                for j in self.neighbours(i, false, &open) {
                    if !seen[j] && open(j) {
                        seen[j] = true;
                        q.push_back(j);
                    }
                }
            }
            false
        };
        let no_extra = vec![false; total];
        let tiny = 1e-9 * self.cell;
        if !reaches(tiny, &no_extra) {
            return vec![];
        }
        // The largest clearance at which the seed reaches Goal, by bisection.
        let cmax = self
            .clearance
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max);
        let (mut a, mut b) = (tiny, cmax.max(tiny));
        for _ in 0..24 {
            let m = 0.5 * (a + b);
            if reaches(m, &no_extra) {
                a = m;
            } else {
                b = m;
            }
        }
        let c_star = a;
        let c = 0.5 * c_star;
        let holes = if d == 2 { self.holes(c) } else { Vec::new() };
        let mut extra = vec![false; total];
        let mut found: Vec<Route> = Vec::new();
        let mut cut_holes: Vec<usize> = Vec::new();
        for _ in 0..3 * self.settings.routes.max(1) {
            let Some(cells) = self.astar(start, c, c_star, d_goal, &extra) else {
                break;
            };
            let mut points: Vec<Vec<f64>> = vec![y0.clone()];
            points.extend(cells.iter().skip(1).map(|&i| self.centre(i)));
            let signature: Vec<f64> = holes.iter().map(|(_, p)| winding(&points, p)).collect();
            let new = found.iter().all(|r| {
                d != 2
                    || r.signature
                        .iter()
                        .zip(&signature)
                        .any(|(a, b)| (a - b).abs() > std::f64::consts::PI)
            });
            if new {
                let length = points.windows(2).map(|w| dist(&w[0], &w[1])).sum();
                found.push(Route {
                    points: points.clone(),
                    length,
                    clearance: c,
                    signature,
                });
                if found.len() >= self.settings.routes {
                    break;
                }
            }
            if d == 2 {
                if !self.cut(&cells, &holes, &mut cut_holes, &mut extra, c, start) {
                    break;
                }
            } else if d == 1 {
                break;
            } else {
                // A band of width 2c around the route's middle (its ends stay open).
                let w = 2.0 * c + self.cell;
                let ends = [
                    self.centre(start),
                    self.centre(*cells.last().expect("a path")),
                ];
                for i in 0..total {
                    let y = self.centre(i);
                    if ends.iter().any(|e| dist(e, &y) <= w) {
                        continue;
                    }
                    if cells.iter().any(|&k| dist(&self.centre(k), &y) <= w) {
                        extra[i] = true;
                    }
                }
            }
        }
        found
    }

    /// A* from `start` to a cell at least `d_goal` deep in Goal, over cells of clearance ≥ `c` not in
    /// `extra`; a step costs its length times 1 + 2(1 − clearance/c_star)⁺.
    fn astar(
        &self,
        start: usize,
        c: f64,
        c_star: f64,
        d_goal: f64,
        extra: &[bool],
    ) -> Option<Vec<usize>> {
        let open = |i: usize| i == start || (self.clearance[i] >= c && !extra[i]);
        let goal_cells: Vec<usize> = (0..self.cells())
            .filter(|&i| self.goal_depth[i] >= d_goal && open(i))
            .collect();
        if goal_cells.is_empty() {
            return None;
        }
        let d = self.dims.len();
        let mut glo = vec![f64::INFINITY; d];
        let mut ghi = vec![f64::NEG_INFINITY; d];
        for &g in &goal_cells {
            let y = self.centre(g);
            for k in 0..d {
                glo[k] = glo[k].min(y[k]);
                ghi[k] = ghi[k].max(y[k]);
            }
        }
        const SCALE: f64 = 1e4;
        let unit = SCALE / self.cell;
        let (path, _) = pathfinding::prelude::astar(
            &start,
            |&i| {
                let yi = self.centre(i);
                self.neighbours(i, false, &open)
                    .into_iter()
                    .filter(|&j| open(j))
                    .map(|j| {
                        let len = dist(&yi, &self.centre(j));
                        let f = 1.0 + 2.0 * (1.0 - self.clearance[j] / c_star).max(0.0);
                        (j, (len * f * unit).round() as u64)
                    })
                    .collect::<Vec<_>>()
            },
            |&i| {
                let y = self.centre(i);
                let h = (0..d)
                    .map(|k| (glo[k] - y[k]).max(y[k] - ghi[k]).max(0.0))
                    .fold(0.0f64, f64::hypot);
                (h * unit * 0.999).floor() as u64
            },
            |&i| i != start && self.goal_depth[i] >= d_goal && open(i),
        )?;
        Some(path)
    }

    /// The holes of the grid at clearance `c` (plane only): 8-connected groups of blocked cells that do
    /// not touch the border, each with its cells and a point of it.
    fn holes(&self, c: f64) -> Vec<(Vec<usize>, Vec<f64>)> {
        let total = self.cells();
        let blocked = |i: usize| self.clearance[i] < c;
        let mut label = vec![usize::MAX; total];
        let mut out = Vec::new();
        for s in 0..total {
            if !blocked(s) || label[s] != usize::MAX {
                continue;
            }
            let mut comp = vec![s];
            label[s] = s;
            let mut k = 0;
            let mut border = false;
            while k < comp.len() {
                let i = comp[k];
                k += 1;
                border |= self.on_border(i);
                for j in self.neighbours(i, false, &|_| true) {
                    if blocked(j) && label[j] == usize::MAX {
                        label[j] = s;
                        comp.push(j);
                    }
                }
            }
            if !border {
                let p = self.centre(comp[0]);
                out.push((comp, p));
            }
        }
        out
    }

    /// Blocks the cut from the hole nearest the route (among those not cut yet) through the route to
    /// the next blocked cell or the border; false when no hole is left.
    fn cut(
        &self,
        cells: &[usize],
        holes: &[(Vec<usize>, Vec<f64>)],
        cut_holes: &mut Vec<usize>,
        extra: &mut [bool],
        c: f64,
        start: usize,
    ) -> bool {
        let pts: Vec<Vec<f64>> = cells.iter().map(|&i| self.centre(i)).collect();
        let mut best: Option<(f64, usize, Vec<f64>, Vec<f64>)> = None;
        for (h, (hc, _)) in holes.iter().enumerate() {
            if cut_holes.contains(&h) {
                continue;
            }
            for &q in hc {
                let yq = self.centre(q);
                for p in &pts {
                    let dd = dist(&yq, p);
                    if best.as_ref().is_none_or(|b| dd < b.0) {
                        best = Some((dd, h, yq.clone(), p.clone()));
                    }
                }
            }
        }
        let Some((_, h, q, p)) = best else {
            return false;
        };
        cut_holes.push(h);
        let dir: Vec<f64> = (0..2).map(|k| p[k] - q[k]).collect();
        let len = dir[0].hypot(dir[1]).max(1e-300);
        let step = 0.5 * self.cell;
        let goal_end = *cells.last().expect("a path");
        let mut t = 0.0;
        let mut passed = false;
        loop {
            t += step;
            let y = [q[0] + dir[0] / len * t, q[1] + dir[1] / len * t];
            if (0..2)
                .any(|k| y[k] < self.lo[k] || y[k] > self.lo[k] + self.dims[k] as f64 * self.cell)
            {
                break;
            }
            let i = self.cell_of(&y);
            passed |= t >= len;
            if passed && self.clearance[i] < c {
                break;
            }
            if self.clearance[i] < c {
                continue;
            }
            let idx = self.unindex(i);
            for (dx, dy) in [(0i64, 0i64), (1, 0), (-1, 0), (0, 1), (0, -1)] {
                let (a, b) = (idx[0] as i64 + dx, idx[1] as i64 + dy);
                if a < 0 || b < 0 || a as usize >= self.dims[0] || b as usize >= self.dims[1] {
                    continue;
                }
                let j = self.index(&[a as usize, b as usize]);
                if j != start && j != goal_end {
                    extra[j] = true;
                }
            }
        }
        true
    }

    /// The state dimension the map was built for.
    pub fn state_dim(&self) -> usize {
        self.n
    }
}

/// Euclidean distance between two points of the route coordinates.
pub(crate) fn dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

/// The winding angle of the polyline `pts` about `p` (plane).
fn winding(pts: &[Vec<f64>], p: &[f64]) -> f64 {
    pts.windows(2)
        .map(|w| {
            let (a0, a1) = (w[0][0] - p[0], w[0][1] - p[1]);
            let (b0, b1) = (w[1][0] - p[0], w[1][1] - p[1]);
            (a0 * b1 - a1 * b0).atan2(a0 * b0 + a1 * b1)
        })
        .sum()
}

/// The first linearisation point for the generator along `route`: the state `x0` with its route
/// coordinates moved along the route at constant speed, reaching the route's end at step
/// ⌈`arrive`·N⌉ and staying there; inputs zero. Not a trajectory of the plant: the generator's first
/// subproblem takes Unsafe's supporting half-spaces at these points (so in the route's class) and
/// finds the trajectory.
pub fn timed_guess(
    route: &Route,
    coords: &[usize],
    x0: &[f64],
    steps: usize,
    arrive: f64,
    m: usize,
) -> Nominal {
    let na = ((arrive.clamp(0.05, 1.0) * steps as f64).ceil() as usize).clamp(1, steps.max(1));
    let total = route.length.max(1e-300);
    // Cumulative arc length.
    let mut cum = vec![0.0];
    for w in route.points.windows(2) {
        cum.push(cum.last().expect("nonempty") + dist(&w[0], &w[1]));
    }
    let at = |s: f64| -> Vec<f64> {
        let s = s.clamp(0.0, total);
        let k = cum
            .partition_point(|&c| c < s)
            .clamp(1, route.points.len().max(2) - 1);
        let (a, b) = (
            &route.points[k - 1],
            &route.points[k.min(route.points.len() - 1)],
        );
        let seg = (cum[k] - cum[k - 1]).max(1e-300);
        let t = ((s - cum[k - 1]) / seg).clamp(0.0, 1.0);
        a.iter().zip(b).map(|(p, q)| p + t * (q - p)).collect()
    };
    let x: Vec<Vec<f64>> = (0..=steps)
        .map(|k| {
            let y = if route.points.len() < 2 {
                route.points.first().cloned().unwrap_or_default()
            } else {
                at(total * (k.min(na) as f64 / na as f64))
            };
            let mut xk = x0.to_vec();
            for (c, &j) in coords.iter().enumerate() {
                if let Some(v) = y.get(c) {
                    xk[j] = *v;
                }
            }
            xk
        })
        .collect();
    Nominal {
        x,
        v: vec![vec![0.0; m]; steps],
        u: vec![vec![0.0; m]; steps],
    }
}
