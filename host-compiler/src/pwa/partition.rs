//! Partitions and the point-location tree (§6.3), emitted as a PWA image.
//!
//! The tree is grown top-down over *balls*, not points: a node holds the data points whose balls
//! `B_P(x̃_i(κ), δ_i)` may meet its cell. A hyperplane `aᵀx = b` sends a ball to the left child when
//! `aᵀx̃ − b ≤ ‖P^{-1/2}a‖ δ_i` and to the right child when `aᵀx̃ − b ≥ −‖P^{-1/2}a‖ δ_i` (the ball–face
//! test of §6.3 after the change of variables z = P^{1/2}x), so a ball cut by the hyperplane goes to both.
//!
//! A node becomes a leaf when one law is verified ([`super::check_point`]) for every ball it holds and it
//! holds at most `MAX_LEAF_BALLS` of them; the leaf lists them all with that law. This is the hypothesis of
//! Theorem 6.6 for the leaf's cell: every state of F in the cell lies in a ball whose law is the leaf's law.
//! It is also the effect of Algorithm 5: a state near a face that lies in a ball from the other side is
//! served by that ball's law, which here is possible because the ball is listed on both sides, under the
//! law of each side for which it is verified (a ball may be stored once per law).
//!
//! Otherwise the node is split. The separating hyperplane is the robust linear program of Bennett and
//! Mangasarian [192] between the centres of the most frequent cluster and the others (the sub-clusters of
//! §6.3 are the leaves' sets), solved with clarabel; when it does not split the set, or the node is too
//! full rather than mixed, the most balanced of the coordinate and principal-direction cuts at the
//! quartiles is used. Children with no ball are "outside the envelope".
//!
//! With [`TreeSplit::Balanced`] (chosen by `Auto` when the tree above exceeds a capacity) the laws play no
//! part in the cuts: every node is cut by the most balanced candidate until it holds at most a leaf size
//! of balls, the smallest of 16, 32 and `MAX_LEAF_BALLS` whose tree fits the capacities (a state outside
//! the balls tests all of its leaf's, so the worst step grows with the leaf size), and every leaf is a
//! mixed leaf as below. Where many balls overlap, the cuts
//! between laws list the overlapping balls on both sides level after level, and that tree outgrows the
//! capacities long before the balanced one does.
//!
//! A mixed node (no single law verified for all its balls) that is small (≤ `MIXED_LEAF_BALLS`), at the
//! depth limit, or that no hyperplane can split (its balls overlap) becomes a *mixed leaf*: it lists every
//! ball with a law verified for it, and the evaluator applies the law of the ball that contains the state
//! (`shared_types::pwa`). So every ball that meets a cell is listed by its leaf, which gives the induction of
//! [`super`] ("Reaching Goal within T"). Only `MAX_LEAF_BALLS` can leave balls out; they are counted in
//! [`PartitionStats::dropped`] and the build fails rather than shrink F silently.

use super::{CapacityExceeded, LearnedLaw, PwaContext, PwaError, TreeSplit};
use crate::emit::Child;
use crate::emit::{CertifiedBall, PwaImageBuilder, PwaLaw, PwaLeaf, TreeNode};
use crate::linalg::round32;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use shared_types::capacity::MAX_LEAF_BALLS;
use std::collections::HashMap;

/// Sizes of the emitted partition.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PartitionStats {
    /// Laws (partitions).
    pub partitions: usize,
    pub nodes: usize,
    pub leaves: usize,
    /// Worst-case hyperplane tests.
    pub depth: usize,
    /// Stored balls (a ball verified for several laws used in different leaves is stored once per law).
    pub balls: usize,
    pub ball_refs: usize,
    /// (leaf, ball) pairs left out of a leaf by `MAX_LEAF_BALLS` (the build fails when > 0).
    pub dropped: usize,
    /// Most balls listed by one leaf (ball tests of the worst control step).
    pub max_leaf_balls: usize,
    /// The cuts the tree was built with (`Laws` or `Balanced`).
    pub split: TreeSplit,
}

/// A cut `aᵀx ≤ b` with the balls its left and right sides list.
type Cut = (Vec<f64>, f64, Vec<usize>, Vec<usize>);

/// Largest mixed set (balls of several laws) that becomes a leaf without further cuts.
const MIXED_LEAF_BALLS: usize = 4;

struct Tree<'a> {
    ctx: &'a PwaContext,
    /// [`TreeSplit::Laws`] or [`TreeSplit::Balanced`] ([`build_image`] resolves `Auto`).
    split: TreeSplit,
    assignment: &'a [usize],
    admissible: &'a [Vec<usize>],
    b: PwaImageBuilder,
    ball_of: HashMap<(usize, usize), usize>,
    dropped: usize,
    /// [`TreeSplit::Balanced`]: a node becomes a leaf at this many balls (≤ `MAX_LEAF_BALLS`).
    leaf_cap: usize,
}

/// The leaf sizes [`TreeSplit::Balanced`] tries, smallest first: the first tree that fits the
/// capacities is kept. A leaf's balls are all tested when a state lies outside them, so the worst step
/// grows with the leaf size; a smaller leaf costs more references (balls cut by more hyperplanes are
/// listed on both sides), which is what a larger one saves when the capacity is short.
const BALANCED_LEAF_CAPS: [usize; 3] = [16, 32, MAX_LEAF_BALLS];

/// Robust LP [192]: min mean(s_A) + mean(s_B) s.t. aᵀx − b ≤ −1 + s (class A), aᵀx − b ≥ 1 − s (class B),
/// s ≥ 0. Coordinates are scaled by `scale`; returns (a, b) in the original coordinates.
fn separate(xa: &[&[f64]], xb: &[&[f64]], scale: &[f64]) -> Option<(Vec<f64>, f64)> {
    let n = scale.len();
    let (na, nb) = (xa.len(), xb.len());
    let nv = n + 1 + na + nb;
    let (mut I, mut J, mut V, mut rhs) = (vec![], vec![], vec![], vec![]);
    let mut row = 0;
    for (cls, pts, off) in [(1.0, xa, 0usize), (-1.0, xb, na)] {
        for (k, x) in pts.iter().enumerate() {
            // cls·(aᵀx − b) − s ≤ −1
            for j in 0..n {
                I.push(row);
                J.push(j);
                V.push(cls * x[j] / scale[j]);
            }
            I.push(row);
            J.push(n);
            V.push(-cls);
            I.push(row);
            J.push(n + 1 + off + k);
            V.push(-1.0);
            rhs.push(-1.0);
            row += 1;
        }
    }
    for k in 0..na + nb {
        I.push(row);
        J.push(n + 1 + k);
        V.push(-1.0);
        rhs.push(0.0);
        row += 1;
    }
    let mut q = vec![0.0; nv];
    for k in 0..na {
        q[n + 1 + k] = 1.0 / na as f64;
    }
    for k in 0..nb {
        q[n + 1 + na + k] = 1.0 / nb as f64;
    }
    let Am = CscMatrix::new_from_triplets(row, nv, I, J, V);
    let Pm = CscMatrix::<f64>::zeros((nv, nv));
    let cones = [SupportedConeT::NonnegativeConeT(row)];
    let st = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(100)
        .build()
        .ok()?;
    let mut s = DefaultSolver::new(&Pm, &q, &Am, &rhs, &cones, st).ok()?;
    s.solve();
    match s.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {}
        _ => return None,
    }
    let z = &s.solution.x;
    let a: Vec<f64> = (0..n).map(|j| z[j] / scale[j]).collect();
    let amax = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if !(amax > 1e-12) || !z[n].is_finite() {
        return None;
    }
    Some((a.iter().map(|v| v / amax).collect(), z[n] / amax))
}

impl Tree<'_> {
    fn dot(a: &[f64], x: &[f64]) -> f64 {
        a.iter().zip(x).map(|(a, x)| a * x).sum()
    }

    /// Balls of `set` that the evaluator can route to the left child ({fl(aᵀx) ≤ b}) and to the right child
    /// (module doc). `a`, `b` are the f32 values stored in the image. A ball B_P(c, δ) reaches the left side
    /// when aᵀc − b is at most [`crate::certify::hyperplane_reach`] (the ball's extent along a plus the
    /// rounding of the evaluator's dot product); the right side likewise. Listing a ball on every side a
    /// state of it can be routed to keeps the "every ball meeting the cell is listed" property of the
    /// liveness argument under f32 routing.
    fn split_set(&self, set: &[usize], a: &[f64], b: f64) -> (Vec<usize>, Vec<usize>) {
        let (mut l, mut r) = (vec![], vec![]);
        for &k in set {
            let p = &self.ctx.points[k];
            let s = Self::dot(a, &p.x) - b;
            let reach =
                crate::certify::hyperplane_reach(&self.ctx.roots, &self.ctx.axis, a, &p.x, p.delta);
            if s <= reach {
                l.push(k);
            }
            if s >= -reach {
                r.push(k);
            }
        }
        (l, r)
    }

    /// The cut that best balances the two children: every coordinate and the principal direction of the
    /// centres (in P-scaled units), each at its quartiles and median; minimises the larger child, then the
    /// sum. `None` if no candidate makes both children smaller than `set`.
    fn balanced_cut(&self, set: &[usize]) -> Option<Cut> {
        let n = self.ctx.n;
        let mut dirs: Vec<Vec<f64>> = (0..n)
            .map(|j| (0..n).map(|i| if i == j { 1.0 } else { 0.0 }).collect())
            .collect();
        // Principal direction of the centres by power iteration on their covariance (scaled by axis).
        let mean: Vec<f64> = (0..n)
            .map(|j| set.iter().map(|&k| self.ctx.points[k].x[j]).sum::<f64>() / set.len() as f64)
            .collect();
        let mut cov = vec![0.0; n * n];
        for &k in set {
            let d: Vec<f64> = (0..n)
                .map(|j| (self.ctx.points[k].x[j] - mean[j]) / self.ctx.axis[j])
                .collect();
            for i in 0..n {
                for j in 0..n {
                    cov[i * n + j] += d[i] * d[j];
                }
            }
        }
        let mut v = vec![1.0; n];
        for _ in 0..50 {
            let w: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| cov[i * n + j] * v[j]).sum())
                .collect();
            let nw = w.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(nw > 0.0) {
                break;
            }
            v = w.iter().map(|x| x / nw).collect();
        }
        dirs.push((0..n).map(|j| v[j] / self.ctx.axis[j]).collect());
        let mut best: Option<(usize, usize, Vec<f64>, f64, Vec<usize>, Vec<usize>)> = None;
        for a in dirs {
            if a.iter().all(|x| x.abs() < 1e-300) {
                continue;
            }
            let mut vals: Vec<f64> = set
                .iter()
                .map(|&k| Self::dot(&a, &self.ctx.points[k].x))
                .collect();
            vals.sort_by(|x, y| x.total_cmp(y));
            for q in 1usize..8 {
                let b = vals[(vals.len() * q / 8).min(vals.len() - 1)];
                let (l, r) = self.split_set(set, &a, b);
                if l.len() >= set.len() || r.len() >= set.len() {
                    continue;
                }
                let key = (l.len().max(r.len()), l.len() + r.len());
                if best.as_ref().is_none_or(|bb| key < (bb.0, bb.1)) {
                    best = Some((key.0, key.1, a.clone(), b, l, r));
                }
            }
        }
        best.map(|b| (b.2, b.3, b.4, b.5))
    }

    /// The cut as the image stores it (f32 values) and the balls each side lists for it, if it still makes
    /// progress on `set`.
    fn stored_cut(&self, set: &[usize], cut: Option<Cut>) -> Option<Cut> {
        let (a, b, _, _) = cut?;
        let a: Vec<f64> = a.iter().map(|&v| round32(v)).collect();
        let b = round32(b);
        let (l, r) = self.split_set(set, &a, b);
        (l.len() < set.len() && r.len() < set.len() && a.iter().any(|v| *v != 0.0))
            .then_some((a, b, l, r))
    }

    fn ball(&mut self, k: usize, law: usize) -> usize {
        if let Some(&i) = self.ball_of.get(&(k, law)) {
            return i;
        }
        let p = &self.ctx.points[k];
        let i = self.b.add_ball(CertifiedBall {
            centre: p.x.clone(),
            // ρ̂ is an f32 radius widened exactly; ŝ = fl32(ρ̂·ρ̂) is what the image stores (always finite for
            // the radii `pwa_ball_radius` returns; 0 would only shrink the ball).
            threshold: crate::certify::threshold_of_radius(p.rho as f32).unwrap_or(0.0) as f64,
            location: 0,
            partition: law,
        });
        self.ball_of.insert((k, law), i);
        i
    }

    /// A leaf labelled with law `law` listing every ball of `set`, each under its own cluster law (verified
    /// for it; the evaluator applies the law of the ball that contains the state), so that a ball listed by
    /// several leaves is stored once. Only the capacity `MAX_LEAF_BALLS` can leave balls out; they are
    /// counted in `dropped` and [`build_image`] then fails.
    fn leaf(&mut self, set: &[usize], law: usize) -> Child {
        let mut balls: Vec<usize> = vec![];
        // Order: by increasing time-to-go (the liveness argument of the module doc of `pwa`), then the
        // data order.
        let mut ks: Vec<(usize, usize)> = set.iter().map(|&k| (k, self.assignment[k])).collect();
        ks.sort_by_key(|&(k, _)| (self.ctx.points[k].to_go, k));
        for &(k, j) in ks.iter().take(MAX_LEAF_BALLS) {
            let i = self.ball(k, j);
            balls.push(i);
        }
        self.dropped += ks.len().saturating_sub(MAX_LEAF_BALLS);
        if balls.is_empty() {
            return Child::Outside;
        }
        let l = self.b.add_leaf(PwaLeaf {
            partition: law,
            balls,
        });
        Child::Leaf(l as u16)
    }

    /// The law verified for every ball of `set`, preferring the most common cluster.
    fn common_law(&self, set: &[usize]) -> Option<usize> {
        let mut counts: HashMap<usize, usize> = HashMap::new();
        for &k in set {
            *counts.entry(self.assignment[k]).or_default() += 1;
        }
        let mut cand: Vec<(usize, usize)> = counts.into_iter().collect();
        cand.sort_by_key(|&(j, c)| (std::cmp::Reverse(c), j));
        let all = |j: usize| set.iter().all(|&k| self.admissible[k].contains(&j));
        if let Some(&(j, _)) = cand.iter().find(|&&(j, _)| all(j)) {
            return Some(j);
        }
        let first = self.admissible[*set.first()?].clone();
        first.into_iter().find(|&j| all(j))
    }

    fn most_common(&self, set: &[usize]) -> usize {
        let mut counts: HashMap<usize, usize> = HashMap::new();
        for &k in set {
            *counts.entry(self.assignment[k]).or_default() += 1;
        }
        counts
            .into_iter()
            .max_by_key(|&(j, c)| (c, std::cmp::Reverse(j)))
            .map(|p| p.0)
            .unwrap_or(0)
    }

    fn node(&mut self, set: Vec<usize>, depth: usize) -> Result<Child, PwaError> {
        if set.is_empty() {
            return Ok(Child::Outside);
        }
        if self.split == TreeSplit::Balanced {
            return self.balanced_node(set, depth);
        }
        let common = self.common_law(&set);
        if let Some(j) = common {
            if set.len() <= self.ctx.settings.leaf_balls.min(MAX_LEAF_BALLS) {
                return Ok(self.leaf(&set, j));
            }
        }
        // Small mixed sets become mixed leaves once cutting stops paying: at most a few balls.
        if set.len() <= MIXED_LEAF_BALLS {
            let j = common.unwrap_or_else(|| self.most_common(&set));
            return Ok(self.leaf(&set, j));
        }
        if depth >= self.ctx.settings.max_depth
            || (common.is_some()
                && set.len() <= MAX_LEAF_BALLS
                && self.balanced_cut(&set).is_none())
        {
            let j = common.unwrap_or_else(|| self.most_common(&set));
            return Ok(self.leaf(&set, j));
        }
        // Choose the hyperplane.
        let mut cut = None;
        if common.is_none() {
            let major = self.most_common(&set);
            let xa: Vec<&[f64]> = set
                .iter()
                .filter(|&&k| self.assignment[k] == major)
                .map(|&k| self.ctx.points[k].x.as_slice())
                .collect();
            let xb: Vec<&[f64]> = set
                .iter()
                .filter(|&&k| self.assignment[k] != major)
                .map(|&k| self.ctx.points[k].x.as_slice())
                .collect();
            if let Some((a, b)) = separate(&xa, &xb, &self.ctx.axis) {
                let (l, r) = self.split_set(&set, &a, b);
                if l.len() < set.len() && r.len() < set.len() {
                    cut = Some((a, b, l, r));
                }
            }
        }
        // The hyperplane as the image stores it (f32), and the balls each side lists for it.
        let cut = self.stored_cut(&set, cut.or_else(|| self.balanced_cut(&set)));
        let (a, b, l, r) = match cut {
            Some(c) => c,
            None => {
                // No hyperplane makes progress (every cut meets all balls): stop here.
                let j = common.unwrap_or_else(|| self.most_common(&set));
                return Ok(self.leaf(&set, j));
            }
        };
        self.split(a, b, l, r, depth)
    }

    /// A node of [`TreeSplit::Balanced`]: a leaf once the set holds at most `leaf_cap` balls (or at the
    /// depth limit, or when no cut makes progress), labelled with its most frequent law; otherwise the
    /// most balanced cut.
    fn balanced_node(&mut self, set: Vec<usize>, depth: usize) -> Result<Child, PwaError> {
        let cut = (set.len() > self.leaf_cap && depth < self.ctx.settings.max_depth)
            .then(|| self.stored_cut(&set, self.balanced_cut(&set)))
            .flatten();
        match cut {
            Some((a, b, l, r)) => self.split(a, b, l, r, depth),
            None => {
                let j = self.most_common(&set);
                Ok(self.leaf(&set, j))
            }
        }
    }

    /// An internal node for the cut `aᵀx ≤ b` (f32 values) with the balls each side lists, and its children.
    fn split(
        &mut self,
        a: Vec<f64>,
        b: f64,
        l: Vec<usize>,
        r: Vec<usize>,
        depth: usize,
    ) -> Result<Child, PwaError> {
        if self.b.nodes.len() >= shared_types::capacity::MAX_TREE_NODES {
            return Err(PwaError::Capacity {
                exceeded: CapacityExceeded::TreeNodes {
                    max: shared_types::capacity::MAX_TREE_NODES,
                },
                learned: None,
            });
        }
        let idx = self.b.add_node(TreeNode {
            a,
            b,
            left: Child::Outside,
            right: Child::Outside,
        });
        let left = self.node(l, depth + 1)?;
        let right = self.node(r, depth + 1)?;
        self.b.nodes[idx].left = left;
        self.b.nodes[idx].right = right;
        Ok(Child::Node(idx as u16))
    }
}

/// Builds the tree and the image content for the learned laws (module doc) with the cuts of the settings'
/// [`TreeSplit`] (`Auto`: by laws, and on the data alone when that tree exceeds a capacity).
/// `admissible[k]` lists the laws verified for the ball of data point k. The caller sets the period and
/// input box.
pub fn build_image(
    ctx: &PwaContext,
    laws: &[LearnedLaw],
    assignment: &[usize],
    admissible: &[Vec<usize>],
) -> Result<(PwaImageBuilder, PartitionStats), PwaError> {
    let balanced = || {
        let mut last = None;
        for cap in BALANCED_LEAF_CAPS {
            match build_tree(ctx, laws, assignment, admissible, TreeSplit::Balanced, cap) {
                Err(e @ PwaError::Capacity { .. }) => last = Some(e),
                r => return r,
            }
        }
        Err(last.unwrap_or(PwaError::NoData))
    };
    match ctx.settings.split {
        TreeSplit::Auto => {
            match build_tree(
                ctx,
                laws,
                assignment,
                admissible,
                TreeSplit::Laws,
                MAX_LEAF_BALLS,
            ) {
                Err(PwaError::Capacity { .. }) => balanced(),
                r => r,
            }
        }
        TreeSplit::Balanced => balanced(),
        split => build_tree(ctx, laws, assignment, admissible, split, MAX_LEAF_BALLS),
    }
}

/// [`build_image`] with the cuts of `split` (`Laws` or `Balanced`, whose leaves hold at most `leaf_cap`
/// balls).
fn build_tree(
    ctx: &PwaContext,
    laws: &[LearnedLaw],
    assignment: &[usize],
    admissible: &[Vec<usize>],
    split: TreeSplit,
    leaf_cap: usize,
) -> Result<(PwaImageBuilder, PartitionStats), PwaError> {
    let mut b = PwaImageBuilder::new(ctx.n, ctx.m, 0.0);
    let K = crate::linalg::to_row_major(ctx.K.as_ref());
    b.add_location(K.clone(), crate::linalg::to_row_major(ctx.P.as_ref()));
    for l in laws {
        let th = crate::linalg::to_row_major(l.theta.as_ref());
        b.add_law(PwaLaw::from_theta(&K, &th, l.theta0.clone())?);
    }
    let mut t = Tree {
        ctx,
        split,
        assignment,
        admissible,
        b,
        ball_of: HashMap::new(),
        dropped: 0,
        leaf_cap: leaf_cap.min(MAX_LEAF_BALLS),
    };
    let all: Vec<usize> = (0..ctx.points.len()).collect();
    let root = t.node(all, 0)?;
    if let Child::Leaf(_) = root {
        // A tree without internal nodes is leaf 0 alone.
    } else if let Child::Outside = root {
        return Err(PwaError::NoData);
    }
    if t.dropped > 0 {
        return Err(PwaError::Capacity {
            exceeded: CapacityExceeded::LeafBalls {
                dropped: t.dropped,
                max: MAX_LEAF_BALLS,
            },
            learned: None,
        });
    }
    let refs = t.b.total_ball_refs();
    if refs > shared_types::capacity::MAX_BALL_REFS {
        return Err(PwaError::Capacity {
            exceeded: CapacityExceeded::BallRefs {
                refs,
                max: shared_types::capacity::MAX_BALL_REFS,
            },
            learned: None,
        });
    }
    let depth = t.b.tree_depth()?;
    let stats = PartitionStats {
        partitions: laws.len(),
        nodes: t.b.nodes.len(),
        leaves: t.b.leaves.len(),
        depth,
        balls: t.b.balls.len(),
        ball_refs: t.b.total_ball_refs(),
        dropped: t.dropped,
        max_leaf_balls: t.b.leaves.iter().map(|l| l.balls.len()).max().unwrap_or(0),
        split,
    };
    Ok((t.b, stats))
}
