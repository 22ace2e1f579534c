//! PWA-feedback images (mode 2, Ch. 6): the tables, their sections, their validation and bounded-time point
//! location.
//!
//! # The law
//! On the envelope F of (6.2) (the union of the certified balls `B_P(x̃_i(κ), δ_i)`), the input is the
//! piecewise-affine law (6.1) around the CAF gain K: `u = (K + θ_j) x + θ0_j` on partition `X_j`. The image
//! stores the *full gain* `K_j = K + θ_j` of every partition, summed in f64 on the host and rounded once to
//! f32, so one step costs m·n multiply-adds and a single rounding per stored entry (storing `K` and `θ_j`
//! apart would double both). `K` itself stays in the payload's per-location `K` for reports; the evaluator
//! does not read it in this mode.
//!
//! # Point location
//! A binary tree over hyperplanes. Internal node i holds `a_i` (n values) and `b_i`; at node i the state
//! goes to the left child if `a_iᵀx ≤ b_i` and to the right child otherwise (a non-finite `a_iᵀx`, which
//! only huge states can produce, goes right). Each node is one record of `4n + 8` bytes,
//! `[a_0 … a_{n−1}, b]` (n + 1 little-endian f32) followed by the left and right child codes (two
//! little-endian `u16`), so one step reads one contiguous record per node (a single bounds check). A child
//! is a 16-bit code:
//!
//! | code              | meaning                                                    |
//! |-------------------|------------------------------------------------------------|
//! | `0x0000..=0x7FFF` | internal node of that index                                |
//! | `0x8000..=0xFFFE` | leaf `code − 0x8000` ([`LEAF_BASE`])                        |
//! | `0xFFFF`          | outside the certified envelope ([`OUTSIDE`])               |
//!
//! The root is node 0; a tree without internal nodes is leaf 0 alone. Decoding requires every child node
//! to have a larger index than its parent, so indices strictly increase along every path: there are no
//! cycles, and a single pass in index order computes every node's depth. Subtrees may be shared (the tree
//! may be a DAG); that changes neither the bound nor the meaning.
//!
//! # The envelope: balls at the leaves
//! F is a union of ellipsoids, not a polytope, so a leaf does not describe `cell ∩ F` by half-spaces (that
//! could only be an inner approximation, found by an LP at build time). Each leaf instead names its main
//! partition and lists the certified balls `B_P(x̃_i(κ), δ_i)` that meet its cell, each with the partition
//! (law) for which (6.5) (through (6.6)–(6.7)) was shown for that ball. A state gets `Ok(u)` only if it lies
//! in one of the listed balls, and the law applied is the law of the first listed ball that contains it:
//! exactly the hypothesis of Theorem 6.6 for that ball (the law maps the ball into
//! `B_P(x̃_i(κ+1), δ_i) ⊂ F`). This is the reassignment of Algorithm 5 (a state near a face that lies in a
//! ball certified for another law gets that law), decided per ball instead of per face. A state in no listed ball gets [`Region::OutsideBalls`], a state the
//! tree sends to [`OUTSIDE`] gets [`Region::OutsideTree`]; both are "out of envelope". So the tree only has
//! to route; a hyperplane cutting a ball near a partition boundary (the situation Algorithm 5 repairs by
//! moving the boundary to `b⁻_m`) is handled by listing the ball in the leaves on both sides of the cut
//! that use its law, and listing it in no other leaf. The same holds for f32 rounding of the hyperplane
//! tests: a misrouted state is either in a ball certified for the law it gets, or out of envelope.
//!
//! Balls live in one table (centre, test record, location whose `P_ℓ` is the metric, partition it is
//! certified for); leaves refer to them through a list of `u16` references (a leaf owns references
//! `end[l−1]..end[l]`), so a ball cut by a hyperplane is stored once per law. Each ball records its
//! partition.
//!
//! # The whitened ball test
//! With the upper-triangular Cholesky factor `R_ℓ` of the metric (`P_ℓ = R_ℓᵀR_ℓ`, positive diagonal),
//! `‖x − c‖_P = ‖R_ℓ x − R_ℓ c‖₂`. The image stores, per location, `R̂_ℓ = fl32(R_ℓ)` (n × n, row-major,
//! zeros below the diagonal) and, per ball, its centre ĉ = fl32(c) (for reports and re-checks; the
//! evaluator does not read it) and one *test record* of n + 1 f32 values `[ĉ_z,0 … ĉ_z,n−1, ŝ]`: the
//! whitened centre `ĉ_z = fl32(R̂ ĉ)` and the squared threshold ŝ (finite, ≥ 0), so one listed ball costs
//! one contiguous read with a single bounds check. The host computes `ŝ = fl32(ρ̂·ρ̂)` from a radius ρ̂
//! (below) with the same single f32 multiplication the evaluator of format version 2 performed per step,
//! so the decision is bit-identical to that evaluator; ρ̂ itself is not stored. Per step
//! the evaluator forms `z = fl(R̂_ℓ x̂)` once (row i: `Σ_{j=i}^{n−1} R̂_ij x̂_j` summed left to right from 0,
//! n(n+1)/2 multiply-adds; recomputed only when consecutive listed balls differ in location, so never for a
//! single-location image, whose ball loop is a separate instance without any per-ball location check), and
//! tests each listed ball with
//!
//! ```text
//! d_i = fl(z_i − ĉ_z,i),   s = fl(d_0·d_0 + d_1·d_1 + … + d_{n−1}·d_{n−1}),   accept ⇔ s ≤ ŝ
//! ```
//!
//! (n subtractions and n multiply-adds per ball, against n² + n multiply-adds for `(x − c)ᵀP(x − c)`).
//! Plain f32 multiply and add in this fixed order, without fused multiply-add (a non-fused `VMLA` on the
//! Cortex-M4F gives the same bits), so host and target agree bit for bit. A state whose arithmetic
//! overflows is rejected: an infinite or NaN `z_i`, `d_i` or `s` makes the comparison false.
//!
//! # Rounding of the ball test
//! What the host must guarantee is: every f32 state x̂ the evaluator accepts in a ball, and every real x with
//! `fl32(x) = x̂`, lies in the certified ball, `‖x − c‖_P ≤ δ` (δ and c the certificate's f64 radius and
//! centre, P its f64 metric). With u = 2⁻²⁴, γ_k = k·u/(1 − k·u) (Higham, *Accuracy and Stability of
//! Numerical Algorithms*, §3.1), η = 2⁻¹⁵⁰ (the absolute error of an underflowing f32 product), R the f64
//! Cholesky factor of P, `D = |R̂ − R|`, `e_c = ĉ_z − R c` and `w = R(x̂ − c)`, componentwise:
//!
//! 1. `|fl(R̂x̂) − R̂x̂| ≤ γ_n|R̂||x̂| + 2nη` (recursive summation of at most n products) and
//!    `|R̂x̂ − Rx̂| ≤ D|x̂|` (D ≤ u|R| + η when R̂ is R rounded to nearest), so
//!    `z − ĉ_z = w + f` with `|f| ≤ (γ_n|R̂| + D)|x̂| + |e_c| + 2nη`;
//! 2. `d = (z − ĉ_z)(1 + θ)`, |θ_i| ≤ u (a subtraction is exact when it underflows), so
//!    `‖d‖ ≥ (1 − u)‖w + f‖`;
//! 3. `s ≥ (1 − γ_n)‖d‖² − 2nη`, so acceptance (`s ≤ ŝ`, ŝ the stored threshold) gives
//!    `‖w + f‖ ≤ S(ŝ) := sqrt((ŝ + 2nη)/(1 − γ_n))/(1 − u)`. For `ŝ = fl32(ρ̂·ρ̂)`, `ŝ ≤ ρ̂²(1 + u) + η`, so
//!    `S(ŝ) ≤ S_ρ(ρ̂) := sqrt((ρ̂²(1 + u) + (2n + 1)η)/(1 − γ_n))/(1 − u)`;
//! 4. for a real x with `fl32(x) = x̂`, `|x − x̂| ≤ u|x̂| + η`, so `W := ‖w‖ + u‖|R||x̂|‖ + η‖|R|𝟙‖` bounds
//!    both `‖R(x̂ − c)‖` and `‖R(x − c)‖`, and with `G = γ_n|R̂| + D`,
//!    `W ≤ S + ‖G|x̂|‖ + u‖|R||x̂|‖ + ‖e_c‖ + 2n^{3/2}η + η‖|R|𝟙‖`;
//! 5. |x̂| is bounded by acceptance itself, with no assumption: `|x̂_j − c_j| ≤ a_j‖x̂ − c‖_P ≤ a_j' W`,
//!    `a_j = sqrt((P⁻¹)_jj)` and `a_j' = a_j·sqrt(1 + χ)` (χ below), so `|x̂| ≤ |c| + a'W` componentwise.
//!    With `α = ‖G a'‖ + u‖|R|a'‖` (< 1) and
//!    `β = ‖G|c|‖ + u‖|R||c|‖ + ‖e_c‖ + (2n^{3/2} + ‖|R|𝟙‖)η` step 4 is the linear inequality
//!    `W ≤ S + β + αW`, hence `W ≤ (S + β)/(1 − α)`;
//! 6. R is the f64 factor: `RᵀR = P + E`, `|E| ≤ γ⁽⁶⁴⁾_{n+1}|Rᵀ||R|` (Higham Thm 10.3), so
//!    `‖v‖²_P ≤ ‖Rv‖²(1 + χ)` with `χ = γ⁽⁶⁴⁾_{n+1}(‖|R|‖₂‖R⁻¹‖₂)²`.
//!
//! Together: an accepted state satisfies `‖x − c‖_P ≤ sqrt(1 + χ)·(S(ŝ) + β)/(1 − α)
//! ≤ sqrt(1 + χ)·(S_ρ(ρ̂) + β)/(1 − α)`. The host takes the largest f32 ρ̂ for which the right-hand bound
//! is ≤ δ (`host_compiler::certify::pwa_ball_radius`) and stores `ŝ = fl32(ρ̂·ρ̂)`
//! (`host_compiler::certify::pwa_ball_threshold`); the bound read backwards from an image, from the stored
//! ŝ directly, is `host_compiler::certify::pwa_accept_radius`, used by the verifier. For
//! unit-scale data the shrink `1 − ρ̂/δ` is of order γ_{n+2}·‖|R||c|‖/δ: below 10⁻⁴ for |c| ≤ 3,
//! δ ≥ 0.1, cond(P) ≤ 10, n ≤ 12 (measured in `host_compiler`'s `tests/host/certify_bounds.rs`).
//!
//! **Completeness** (the converse: states near c are accepted). For a real x with `‖x − c‖_P ≤ r` and
//! `x̂ = fl32(x)`, the same steps read as upper bounds give `‖w + f‖ ≤ t0 + t1·r`, where t1 ≈ 1 collects
//! step 6 read the other way (`‖R(x − c)‖ ≤ r/sqrt(1 − χ)`) and the G-, u- and η-terms of steps 1 and 4
//! evaluated at `|x| ≤ |c| + a'r`, and t0 is of the order of β; and `s ≤ (1 + γ_n)(1 + u)²‖w + f‖² + 2nη`.
//! Every x within the r that makes this ≤ ŝ is accepted (`host_compiler::certify::pwa_complete_radius`).
//! The host's certificate asks each step of a run to land within that radius of the next ball, and the
//! verifier recomputes it from the stored bytes.
//!
//! # Cost of one step
//! At most [`MAX_TREE_DEPTH`] hyperplane tests (n multiply-adds each; the stored depth is the exact worst
//! case of this image), the whitening (n(n+1)/2 multiply-adds, again at a change of location), at most
//! [`MAX_LEAF_BALLS`] ball tests (n subtractions and n multiply-adds each; the scan stops at the first ball
//! containing x) and m·n multiply-adds for the law: see [`crate::capacity::PWA_STEP_MAX_MULADDS`].
//!
//! # Sections
//! The tables are stored as three sections of the image ([`crate::image`]): the laws ([`PwaLaws`]), the
//! tree with its leaves and ball references ([`PwaTree`]), and the balls with the per-location factors
//! `R̂_ℓ` ([`PwaBalls`]). [`PwaTables`] is their union.
//!
//! # Validation (run by [`crate::image::decode`] and [`crate::image::Image::new_pwa`])
//! * counts within capacity: nodes ≤ [`MAX_TREE_NODES`], 1 ≤ leaves ≤ [`MAX_LEAVES`],
//!   1 ≤ balls ≤ [`MAX_BALLS`], stored depth ≤ [`MAX_TREE_DEPTH`], references ≤ [`MAX_BALL_REFS`];
//! * every field's byte length matches the counts and dimensions (node records `4n + 8` bytes, ball test
//!   records `4(n + 1)` bytes); every float finite; no zero normal;
//! * each leaf's partition in range; leaf ends strictly increasing (every leaf lists ≥ 1 ball) and at most
//!   [`MAX_LEAF_BALLS`] per leaf; every reference in range;
//! * per location, the factor `R̂_ℓ` upper triangular (every entry below the diagonal exactly 0) with a
//!   positive diagonal;
//! * balls: threshold `ŝ ≥ 0`, location and partition in range;
//! * tree: every child node in range and after its parent, every child leaf in range, every node reachable
//!   from the root, every leaf referenced, no node deeper than [`MAX_TREE_DEPTH`] tests, and the stored
//!   depth equal to the tree's worst case.
#![allow(non_snake_case)]

use serde::{Deserialize, Serialize};

use crate::capacity::{
    MAX_BALLS, MAX_BALL_REFS, MAX_LEAF_BALLS, MAX_LEAVES, MAX_LOCATIONS, MAX_M, MAX_N,
    MAX_PARTITIONS, MAX_TREE_DEPTH, MAX_TREE_NODES,
};
use crate::error::{Dim, Field, ImageError, Pos};
use crate::layout::Dims;
use crate::raw::{check_dim, check_finite, check_len, div, f32_at, rem, sat16, sat32, u16_le};

/// Child codes from here up to `OUTSIDE − 1` name leaves: leaf `code − LEAF_BASE`.
pub const LEAF_BASE: u16 = 0x8000;
/// Child code meaning "outside the certified envelope".
pub const OUTSIDE: u16 = 0xFFFF;

/// A decoded child code of a tree node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Child {
    /// Internal node of this index.
    Node(u16),
    /// Leaf of this index.
    Leaf(u16),
    /// Outside the certified envelope.
    Outside,
}

impl Child {
    /// The child a code stands for (every code means something; ranges are checked by validation).
    pub const fn from_code(code: u16) -> Child {
        if code == OUTSIDE {
            Child::Outside
        } else if code >= LEAF_BASE {
            Child::Leaf(code - LEAF_BASE)
        } else {
            Child::Node(code)
        }
    }

    /// The code of this child; `None` for an index the code space cannot hold (node ≥ 0x8000, leaf ≥
    /// 0x7FFF).
    pub const fn code(self) -> Option<u16> {
        match self {
            Child::Node(i) if i < LEAF_BASE => Some(i),
            Child::Leaf(l) if l < OUTSIDE - LEAF_BASE => Some(LEAF_BASE + l),
            Child::Outside => Some(OUTSIDE),
            _ => None,
        }
    }
}

/// The PWA tables of an image, as raw borrowed byte strings (`f32` and `u16` little-endian, matrices
/// row-major). Counts are stored explicitly; field lengths are checked against them. In the image they are
/// three sections ([`PwaLaws`], [`PwaTree`], [`PwaBalls`]); this is their union, as the evaluator reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PwaTables<'a> {
    /// Worst-case number of hyperplane tests from the root to a leaf (must equal the tree's).
    pub depth: u8,
    /// Number of internal nodes (0: the tree is leaf 0 alone).
    pub n_nodes: u16,
    /// Number of leaves.
    pub n_leaves: u16,
    /// Number of certified balls.
    pub n_balls: u16,
    /// `K_j = K + θ_j` per partition: partitions × m × n values.
    pub gain: &'a [u8],
    /// `θ0_j` per partition: partitions × m values.
    pub offset: &'a [u8],
    /// Tree node records (module doc): per node `[a_0 … a_{n−1}, b]` (n + 1 f32) then the child codes
    /// (left, right) as two `u16`; nodes × (4n + 8) bytes.
    pub node: &'a [u8],
    /// Partition of each leaf (`u16`).
    pub leaf_partition: &'a [u8],
    /// Exclusive end of each leaf's run in `ball_ref` (`u16`, strictly increasing).
    pub leaf_end: &'a [u8],
    /// Ball references (`u16` indices into the ball table).
    pub ball_ref: &'a [u8],
    /// Per location ℓ, the upper-triangular factor `R̂_ℓ = fl32(R_ℓ)` of the metric (`P_ℓ = R_ℓᵀR_ℓ`):
    /// locations × n × n values, zero below the diagonal.
    pub R: &'a [u8],
    /// Ball centres `x̃_i(κ)` (not read by the evaluator; for reports and re-checks): balls × n values.
    pub ball_centre: &'a [u8],
    /// Ball test records (module doc): per ball the whitened centre `ĉ_z = fl32(R̂ ĉ)` in the factor of the
    /// ball's location, then the squared threshold ŝ: balls × (n + 1) values.
    pub ball_test: &'a [u8],
    /// Location of each ball (one byte): its metric is that location's `P`.
    pub ball_location: &'a [u8],
    /// Partition each ball is certified for (`u16`).
    pub ball_partition: &'a [u8],
}

/// The PWA laws section ([`crate::layout::SectionKind::PwaLaws`]), postcard-encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PwaLaws<'a> {
    /// See [`PwaTables::gain`].
    pub gain: &'a [u8],
    /// See [`PwaTables::offset`].
    pub offset: &'a [u8],
}

/// The PWA tree section ([`crate::layout::SectionKind::PwaTree`]), postcard-encoded: the node records and
/// the leaves with their ball references.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PwaTree<'a> {
    /// See [`PwaTables::depth`].
    pub depth: u8,
    /// See [`PwaTables::n_nodes`].
    pub n_nodes: u16,
    /// See [`PwaTables::n_leaves`].
    pub n_leaves: u16,
    /// See [`PwaTables::node`].
    pub node: &'a [u8],
    /// See [`PwaTables::leaf_partition`].
    pub leaf_partition: &'a [u8],
    /// See [`PwaTables::leaf_end`].
    pub leaf_end: &'a [u8],
    /// See [`PwaTables::ball_ref`].
    pub ball_ref: &'a [u8],
}

/// The PWA balls section ([`crate::layout::SectionKind::PwaBalls`]), postcard-encoded: the certified balls
/// and the per-location factors of their whitened test.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PwaBalls<'a> {
    /// See [`PwaTables::n_balls`].
    pub n_balls: u16,
    /// See [`PwaTables::R`].
    pub R: &'a [u8],
    /// See [`PwaTables::ball_centre`].
    pub ball_centre: &'a [u8],
    /// See [`PwaTables::ball_test`].
    pub ball_test: &'a [u8],
    /// See [`PwaTables::ball_location`].
    pub ball_location: &'a [u8],
    /// See [`PwaTables::ball_partition`].
    pub ball_partition: &'a [u8],
}

impl<'a> PwaTables<'a> {
    /// The tables from their three sections.
    pub fn from_sections(laws: PwaLaws<'a>, tree: PwaTree<'a>, balls: PwaBalls<'a>) -> Self {
        PwaTables {
            depth: tree.depth,
            n_nodes: tree.n_nodes,
            n_leaves: tree.n_leaves,
            n_balls: balls.n_balls,
            gain: laws.gain,
            offset: laws.offset,
            node: tree.node,
            leaf_partition: tree.leaf_partition,
            leaf_end: tree.leaf_end,
            ball_ref: tree.ball_ref,
            R: balls.R,
            ball_centre: balls.ball_centre,
            ball_test: balls.ball_test,
            ball_location: balls.ball_location,
            ball_partition: balls.ball_partition,
        }
    }

    /// The three sections these tables are stored as.
    pub fn sections(&self) -> (PwaLaws<'a>, PwaTree<'a>, PwaBalls<'a>) {
        (
            PwaLaws {
                gain: self.gain,
                offset: self.offset,
            },
            PwaTree {
                depth: self.depth,
                n_nodes: self.n_nodes,
                n_leaves: self.n_leaves,
                node: self.node,
                leaf_partition: self.leaf_partition,
                leaf_end: self.leaf_end,
                ball_ref: self.ball_ref,
            },
            PwaBalls {
                n_balls: self.n_balls,
                R: self.R,
                ball_centre: self.ball_centre,
                ball_test: self.ball_test,
                ball_location: self.ball_location,
                ball_partition: self.ball_partition,
            },
        )
    }
}

impl PwaTables<'static> {
    /// No tables (what a feedforward image carries).
    pub const EMPTY: PwaTables<'static> = PwaTables {
        depth: 0,
        n_nodes: 0,
        n_leaves: 0,
        n_balls: 0,
        gain: &[],
        offset: &[],
        node: &[],
        leaf_partition: &[],
        leaf_end: &[],
        ball_ref: &[],
        R: &[],
        ball_centre: &[],
        ball_test: &[],
        ball_location: &[],
        ball_partition: &[],
    };
}

/// Where point location put a state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Region {
    /// The tree sent the state to an [`OUTSIDE`] child.
    OutsideTree,
    /// The state reached `leaf` (of `partition`) but lies in none of its certified balls.
    OutsideBalls {
        /// The leaf.
        leaf: u16,
        /// Its partition.
        partition: u16,
    },
    /// The state lies in certified ball `ball` of `leaf`: the law of `partition` applies.
    Inside {
        /// The leaf.
        leaf: u16,
        /// Its partition.
        partition: u16,
        /// The first listed ball containing the state.
        ball: u16,
    },
}

impl Region {
    /// The partition whose law applies, if the state is in the envelope.
    pub fn partition(&self) -> Option<u16> {
        match *self {
            Region::Inside { partition, .. } => Some(partition),
            _ => None,
        }
    }

    /// The leaf the tree reached, if any.
    pub fn leaf(&self) -> Option<u16> {
        match *self {
            Region::OutsideTree => None,
            Region::OutsideBalls { leaf, .. } | Region::Inside { leaf, .. } => Some(leaf),
        }
    }
}

/// Validates the tables of a PWA image whose header dimensions (`n`, `m`, locations, partitions) are
/// already within capacity. See the module docs for the list of rules.
pub(crate) fn validate_tables(dims: Dims, t: &PwaTables<'_>) -> Result<(), ImageError> {
    let n = dims.n.clamp(1, MAX_N);
    let m = dims.m.clamp(1, MAX_M);
    let n_loc = dims.n_locations.min(MAX_LOCATIONS);
    let np = dims.n_partitions.min(MAX_PARTITIONS);
    let (nn, nl, nb) = (t.n_nodes as usize, t.n_leaves as usize, t.n_balls as usize);
    check_dim(Dim::TreeNodes, nn, 0, MAX_TREE_NODES)?;
    check_dim(Dim::Leaves, nl, 1, MAX_LEAVES)?;
    check_dim(Dim::Balls, nb, 1, MAX_BALLS)?;
    check_dim(Dim::TreeDepth, t.depth as usize, 0, MAX_TREE_DEPTH)?;

    // Laws: K_j (m×n) and θ0_j (m) per partition.
    check_len(Field::LawGain, t.gain, 4 * np * m * n)?;
    check_finite(Field::LawGain, t.gain, |i| {
        Pos(
            sat16(div(i, m * n)),
            sat16(div(rem(i, m * n), n)),
            sat16(rem(i, n)),
        )
    })?;
    check_len(Field::LawOffset, t.offset, 4 * np * m)?;
    check_finite(Field::LawOffset, t.offset, |i| {
        Pos(sat16(div(i, m)), sat16(rem(i, m)), 0)
    })?;

    // Hyperplanes: one record [a_0 … a_{n−1}, b, left, right] per node.
    check_len(Field::Node, t.node, nn * node_record_len(n))?;
    for i in 0..nn {
        for k in 0..n {
            if !node_value(t.node, n, i, k).is_finite() {
                return Err(ImageError::NonFinite {
                    field: Field::NodeNormal,
                    pos: Pos(sat16(i), sat16(k), 0),
                });
            }
        }
        if !node_value(t.node, n, i, n).is_finite() {
            return Err(ImageError::NonFinite {
                field: Field::NodeOffset,
                pos: Pos(sat16(i), 0, 0),
            });
        }
        if (0..n).all(|k| node_value(t.node, n, i, k) == 0.0) {
            return Err(ImageError::DegenerateHyperplane { node: sat16(i) });
        }
    }

    // Leaves: partition and run of ball references.
    check_len(Field::LeafPartition, t.leaf_partition, 2 * nl)?;
    for l in 0..nl {
        let j = u16_le(t.leaf_partition, l);
        if j as usize >= np {
            return Err(ImageError::PartitionOutOfRange {
                leaf: sat16(l),
                value: j,
            });
        }
    }
    check_len(Field::LeafEnd, t.leaf_end, 2 * nl)?;
    let mut prev = 0u16;
    for l in 0..nl {
        let e = u16_le(t.leaf_end, l);
        if e <= prev {
            return Err(ImageError::LeafBallEnds { leaf: sat16(l) });
        }
        if (e - prev) as usize > MAX_LEAF_BALLS {
            return Err(ImageError::LeafTooManyBalls {
                leaf: sat16(l),
                count: e - prev,
            });
        }
        if e as usize > MAX_BALL_REFS {
            return Err(ImageError::DimOutOfRange {
                dim: Dim::BallRefs,
                value: e as u32,
                min: 1,
                max: sat32(MAX_BALL_REFS),
            });
        }
        prev = e;
    }
    let n_refs = prev as usize;

    validate_factors(t.R, n_loc, n)?;

    // Balls.
    check_len(Field::BallCentre, t.ball_centre, 4 * nb * n)?;
    check_finite(Field::BallCentre, t.ball_centre, |i| {
        Pos(sat16(div(i, n)), sat16(rem(i, n)), 0)
    })?;
    validate_ball_tests(t.ball_test, nb, n)?;
    check_len(Field::BallLocation, t.ball_location, nb)?;
    for (b, &l) in t.ball_location.iter().enumerate() {
        if l as usize >= n_loc {
            return Err(ImageError::BallLocationOutOfRange {
                ball: sat16(b),
                value: l,
            });
        }
    }
    check_len(Field::BallPartition, t.ball_partition, 2 * nb)?;
    for b in 0..nb {
        let j = u16_le(t.ball_partition, b);
        if j as usize >= np {
            return Err(ImageError::BallPartitionOutOfRange {
                ball: sat16(b),
                value: j,
            });
        }
    }

    // References: in range. A leaf may list balls of several partitions (the law applied is the law of the
    // ball that contains the state, module doc).
    check_len(Field::BallRef, t.ball_ref, 2 * n_refs)?;
    let mut start = 0usize;
    for l in 0..nl {
        let end = u16_le(t.leaf_end, l) as usize;
        for k in start..end {
            let b = u16_le(t.ball_ref, k);
            if b as usize >= nb {
                return Err(ImageError::BallRefOutOfRange {
                    leaf: sat16(l),
                    value: b,
                });
            }
        }
        start = end;
    }

    validate_tree(t, n, nn, nl)
}

/// Bytes of one tree node record: n + 1 f32 (`a`, `b`) and two `u16` child codes.
pub const fn node_record_len(n: usize) -> usize {
    4 * n + 8
}

/// Value `k` of node `i`'s record (`a_k` for k < n, `b` for k = n); 0.0 out of range.
pub(crate) fn node_value(node: &[u8], n: usize, i: usize, k: usize) -> f32 {
    let rec = node_record_len(n) / 4;
    f32_at(node, i.saturating_mul(rec).saturating_add(k))
}

/// Child code of node `i` on `side` (0 left, 1 right); 0 out of range (never for a validated image).
pub(crate) fn node_child(node: &[u8], n: usize, i: usize, side: usize) -> u16 {
    let rec = node_record_len(n) / 2;
    u16_le(
        node,
        i.saturating_mul(rec).saturating_add(2 * (n + 1) + side),
    )
}

/// Checks the per-location factors `R̂_ℓ` (`n_loc` × n × n little-endian f32): the length, every value
/// finite, upper triangular (every entry below the diagonal exactly 0) with a positive diagonal. Shared
/// with the selection test section ([`crate::selection`]); out of line, so the two share one copy.
#[inline(never)]
pub(crate) fn validate_factors(R: &[u8], n_loc: usize, n: usize) -> Result<(), ImageError> {
    // Factors R̂_ℓ: upper triangular with a positive diagonal.
    check_len(Field::Factor, R, 4 * n_loc * n * n)?;
    check_finite(Field::Factor, R, |i| {
        Pos(
            sat16(div(i, n * n)),
            sat16(div(rem(i, n * n), n)),
            sat16(rem(i, n)),
        )
    })?;
    for l in 0..n_loc {
        for r in 0..n {
            for c in 0..r {
                if f32_at(R, (l * n + r) * n + c) != 0.0 {
                    return Err(ImageError::FactorNotUpperTriangular {
                        location: sat16(l),
                        row: sat16(r),
                        col: sat16(c),
                    });
                }
            }
            let d = f32_at(R, (l * n + r) * n + r);
            if d.is_nan() || d <= 0.0 {
                return Err(ImageError::FactorDiagonal {
                    location: sat16(l),
                    row: sat16(r),
                });
            }
        }
    }
    Ok(())
}

/// Checks `nb` ball test records `[ĉ_z,0 … ĉ_z,n−1, ŝ]`: the length, every value finite, `ŝ ≥ 0`. Shared
/// with the selection test section ([`crate::selection`]); out of line, so the two share one copy.
#[inline(never)]
pub(crate) fn validate_ball_tests(tests: &[u8], nb: usize, n: usize) -> Result<(), ImageError> {
    // Test records [ĉ_z,0 … ĉ_z,n−1, ŝ], one per ball.
    check_len(Field::BallTest, tests, 4 * nb * (n + 1))?;
    for b in 0..nb {
        for k in 0..n {
            if !f32_at(tests, b * (n + 1) + k).is_finite() {
                return Err(ImageError::NonFinite {
                    field: Field::BallCentreZ,
                    pos: Pos(sat16(b), sat16(k), 0),
                });
            }
        }
        let s = f32_at(tests, b * (n + 1) + n);
        if !s.is_finite() {
            return Err(ImageError::NonFinite {
                field: Field::BallThreshold,
                pos: Pos(sat16(b), 0, 0),
            });
        }
        if s < 0.0 {
            return Err(ImageError::NegativeBallThreshold { ball: sat16(b) });
        }
    }
    Ok(())
}

/// The tree rules: children after parents and in range, everything reachable, depth within capacity and
/// equal to the stored one. One pass in index order: since every parent precedes its children, a node's
/// depth (tests up to and including it) is final when the pass reaches it.
fn validate_tree(t: &PwaTables<'_>, n: usize, nn: usize, nl: usize) -> Result<(), ImageError> {
    let nn = nn.min(MAX_TREE_NODES);
    let nl = nl.min(MAX_LEAVES);
    if nn == 0 {
        // The tree is leaf 0 alone.
        if nl > 1 {
            return Err(ImageError::UnreferencedLeaf { leaf: 1 });
        }
        if t.depth != 0 {
            return Err(ImageError::TreeDepthMismatch {
                stored: t.depth,
                actual: 0,
            });
        }
        return Ok(());
    }
    // depth[i] = 0: not reached (yet); else the largest number of tests on a path ending at node i.
    let mut depth = [0u8; MAX_TREE_NODES];
    let mut leaf_seen = [0u32; MAX_LEAVES.div_ceil(32)];
    depth[0] = 1;
    let mut worst = 0u8;
    for i in 0..nn {
        let d = depth.get(i).copied().unwrap_or(0);
        if d == 0 {
            return Err(ImageError::UnreachableNode { node: sat16(i) });
        }
        worst = worst.max(d);
        for side in 0..2 {
            match Child::from_code(node_child(t.node, n, i, side)) {
                Child::Outside => {}
                Child::Leaf(l) => {
                    if l as usize >= nl {
                        return Err(ImageError::LeafOutOfRange {
                            node: sat16(i),
                            leaf: l,
                        });
                    }
                    if let Some(w) = leaf_seen.get_mut(l as usize / 32) {
                        *w |= 1 << (l % 32);
                    }
                }
                Child::Node(c) => {
                    let cu = c as usize;
                    if cu >= nn {
                        return Err(ImageError::ChildOutOfRange {
                            node: sat16(i),
                            child: c,
                        });
                    }
                    if cu <= i {
                        return Err(ImageError::BackEdge {
                            node: sat16(i),
                            child: c,
                        });
                    }
                    if d as usize >= MAX_TREE_DEPTH {
                        return Err(ImageError::TreeTooDeep { node: c });
                    }
                    if let Some(dc) = depth.get_mut(cu) {
                        *dc = (*dc).max(d + 1);
                    }
                }
            }
        }
    }
    for l in 0..nl {
        let seen = leaf_seen
            .get(l / 32)
            .is_some_and(|w| w & (1 << (l % 32)) != 0);
        if !seen {
            return Err(ImageError::UnreferencedLeaf { leaf: sat16(l) });
        }
    }
    if worst != t.depth {
        return Err(ImageError::TreeDepthMismatch {
            stored: t.depth,
            actual: worst,
        });
    }
    Ok(())
}

impl PwaTables<'_> {
    /// Point location of `x` in tables validated for `n` and `n_locations` (`x.len() == n`,
    /// `1 ≤ n ≤ MAX_N`; the argument checks are [`crate::image::Image::locate`]'s). Every loop is
    /// bounded by a capacity; on validated tables the walk ends within `depth` tests. Dispatches to
    /// [`PwaTables::locate_n`] for the image's n, so that the n-length loops are unrolled at compile time (the
    /// arithmetic, and its order, is the same for every n).
    pub(crate) fn locate_in(&self, n_locations: usize, x: &[f32], n: usize) -> Region {
        match n {
            1 => self.locate_n::<1>(n_locations, x),
            2 => self.locate_n::<2>(n_locations, x),
            3 => self.locate_n::<3>(n_locations, x),
            4 => self.locate_n::<4>(n_locations, x),
            5 => self.locate_n::<5>(n_locations, x),
            6 => self.locate_n::<6>(n_locations, x),
            7 => self.locate_n::<7>(n_locations, x),
            8 => self.locate_n::<8>(n_locations, x),
            9 => self.locate_n::<9>(n_locations, x),
            10 => self.locate_n::<10>(n_locations, x),
            11 => self.locate_n::<11>(n_locations, x),
            12 => self.locate_n::<12>(n_locations, x),
            // Unreachable for a validated image (1 ≤ n ≤ MAX_N); total anyway.
            _ => Region::OutsideTree,
        }
    }

    /// Point location for state dimension `N` (module doc): the tree walk, then the whitened ball test of
    /// the leaf's balls in listing order. Reads are total (a short table reads as "outside"), which a
    /// validated image never meets.
    fn locate_n<const N: usize>(&self, n_locations: usize, x: &[f32]) -> Region {
        const { assert!(N <= MAX_N) };
        let Some(x) = load_x::<N>(x) else {
            return Region::OutsideTree;
        };
        let t = self;
        // The walk: at most MAX_TREE_DEPTH tests (validated: the tree's depth is at most that).
        let leaf = 'walk: {
            if t.n_nodes == 0 {
                break 'walk 0u16;
            }
            let mut i = 0usize;
            for _ in 0..MAX_TREE_DEPTH {
                let Some((a, b, children)) = load_node::<N>(t.node, i) else {
                    return Region::OutsideTree;
                };
                let mut s = 0.0f32;
                for k in 0..N {
                    s += a[k] * x[k];
                }
                let code = if s <= b { children[0] } else { children[1] };
                match Child::from_code(code) {
                    Child::Node(c) => i = c as usize,
                    Child::Leaf(l) => break 'walk l,
                    Child::Outside => return Region::OutsideTree,
                }
            }
            // Unreachable for a validated image (depth ≤ MAX_TREE_DEPTH); total anyway.
            return Region::OutsideTree;
        };
        let l = leaf as usize;
        let start = match l {
            0 => 0,
            _ => u16_le(t.leaf_end, l - 1) as usize,
        };
        let end = u16_le(t.leaf_end, l) as usize;
        // Validated: end − start ≤ MAX_LEAF_BALLS; the truncation makes the bound explicit.
        let refs = t.ball_ref.get(2 * start..2 * end).unwrap_or(&[]);
        let refs = refs.get(..2 * MAX_LEAF_BALLS).unwrap_or(refs);
        // The location check is hoisted out of the ball loop for a single-location image.
        let found = if n_locations == 1 {
            scan_balls::<N, true>(t, refs, &x)
        } else {
            scan_balls::<N, false>(t, refs, &x)
        };
        match found {
            Some(b) => Region::Inside {
                leaf,
                partition: u16_le(t.ball_partition, b as usize),
                ball: b,
            },
            None => Region::OutsideBalls {
                leaf,
                partition: u16_le(t.leaf_partition, l),
            },
        }
    }
}

/// The whitened ball test (module doc) of the balls referenced by `refs` (little-endian `u16`), in order:
/// the first ball containing `x`, or `None`. `z = fl(R̂_ℓ x)` is formed for the location ℓ of the ball being
/// tested: once, for location 0, when `SINGLE` (a single-location image, so the loop body has no location
/// check), else again whenever the location changes from one listed ball to the next.
#[inline(always)]
fn scan_balls<const N: usize, const SINGLE: bool>(
    t: &PwaTables<'_>,
    refs: &[u8],
    x: &[f32; N],
) -> Option<u16> {
    let mut z = [0.0f32; N];
    let mut z_loc = usize::MAX;
    if SINGLE {
        whiten::<N>(&mut z, t.R, 0, x);
    }
    for r in refs.chunks_exact(2) {
        let b = u16::from_le_bytes([r[0], r[1]]);
        let bu = b as usize;
        if !SINGLE {
            let loc = t.ball_location.get(bu).copied().unwrap_or(0) as usize;
            if loc != z_loc {
                whiten::<N>(&mut z, t.R, loc, x);
                z_loc = loc;
            }
        }
        let Some((cz, threshold)) = load_ball::<N>(t.ball_test, bu) else {
            continue;
        };
        let mut d2 = 0.0f32;
        for i in 0..N {
            let d = z[i] - cz[i];
            d2 += d * d;
        }
        if d2 <= threshold {
            return Some(b);
        }
    }
    None
}

/// `z_i = fl(Σ_{j=i}^{N−1} R̂_ij x_j)` for the factor of location `loc`, summed left to right from 0 (module
/// doc); a short table reads as zeros (never for a validated image).
#[inline(always)]
pub(crate) fn whiten<const N: usize>(z: &mut [f32; N], R: &[u8], loc: usize, x: &[f32; N]) {
    for (i, zi) in z.iter_mut().enumerate() {
        let row = load::<N>(R, (loc * N + i) * N).unwrap_or([0.0; N]);
        let mut s = 0.0f32;
        for j in i..N {
            s += row[j] * x[j];
        }
        *zi = s;
    }
}

/// The first `N` values of `x` as an array; `None` if `x` is shorter.
#[inline(always)]
fn load_x<const N: usize>(x: &[f32]) -> Option<[f32; N]> {
    let x = x.get(..N)?;
    let mut out = [0.0f32; N];
    out.copy_from_slice(x);
    Some(out)
}

/// `N` little-endian f32 values from the start of `b` (which holds at least `4N` bytes when called).
#[inline(always)]
fn floats_n<const N: usize>(b: &[u8]) -> [f32; N] {
    let mut out = [0.0f32; N];
    for (o, c) in out.iter_mut().zip(b.chunks_exact(4)) {
        *o = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    }
    out
}

/// `N` little-endian f32 values of `bytes` starting at value index `start`; `None` if out of range.
#[inline(always)]
fn load<const N: usize>(bytes: &[u8], start: usize) -> Option<[f32; N]> {
    let s = start.checked_mul(4)?;
    let b = bytes.get(s..s.checked_add(4 * N)?)?;
    Some(floats_n::<N>(b))
}

/// Record `i` of the tree node table: `(a, b, [left, right])`, read with one bounds check; `None` if out of
/// range.
#[inline(always)]
fn load_node<const N: usize>(bytes: &[u8], i: usize) -> Option<([f32; N], f32, [u16; 2])> {
    let len = node_record_len(N);
    let s = i.checked_mul(len)?;
    let rec = bytes.get(s..s.checked_add(len)?)?;
    let (head, &[l0, l1, r0, r1]) = rec.split_last_chunk::<4>()?;
    let (head, &b) = head.split_last_chunk::<4>()?;
    Some((
        floats_n::<N>(head),
        f32::from_le_bytes(b),
        [u16::from_le_bytes([l0, l1]), u16::from_le_bytes([r0, r1])],
    ))
}

/// Test record `i` of the ball table: `(ĉ_z, ŝ)`, read with one bounds check; `None` if out of range.
#[inline(always)]
pub(crate) fn load_ball<const N: usize>(bytes: &[u8], i: usize) -> Option<([f32; N], f32)> {
    let len = 4 * (N + 1);
    let s = i.checked_mul(len)?;
    let rec = bytes.get(s..s.checked_add(len)?)?;
    let (head, &t) = rec.split_last_chunk::<4>()?;
    Some((floats_n::<N>(head), f32::from_le_bytes(t)))
}
