//! PWA-feedback images (mode 2): round trips (fixed, random, at capacity), canonical re-encoding, and a
//! table of rejections, one row per validation check: each mutates the fixed content (fed to `decode` as
//! raw bytes with a correct CRC, and `Image::new_pwa` checked to agree) or its encoded bytes, and names the
//! error expected.
#![allow(non_snake_case)]

use crate::common::{
    random_pwa, random_spd, sections_of, tree_depth, two_partitions, with_sections, FallbackC,
    PwaContent, PwaShape, L0, L1,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{
    MAX_BALLS, MAX_BALL_REFS, MAX_IMAGE_LEN, MAX_LEAF_BALLS, MAX_LEAVES, MAX_M, MAX_N,
    MAX_PARTITIONS, MAX_TREE_DEPTH, MAX_TREE_NODES,
};
use shared_types::image::{decode, encode, Dim, Field, Header, ImageError, Mode, Pos, SectionKind};
use shared_types::pwa::{Child, LEAF_BASE, OUTSIDE};

#[test]
fn round_trip_fixed_content() {
    let c = two_partitions();
    let bytes = c.to_bytes().unwrap();
    let h = Header::parse(&bytes).unwrap();
    assert_eq!(h.mode, 2);
    assert_eq!(h.dims.n_trajectories, 0);
    assert_eq!(h.dims.n_partitions, 2);
    assert_eq!(h.payload_len as usize, bytes.len() - 32);
    let img = decode(&bytes).unwrap();
    assert_eq!(img.mode(), Mode::PwaFeedback);
    assert_eq!(img.n_partitions(), 2);
    assert_eq!(img.tree_depth(), 2);
    assert_eq!(img.n_nodes(), 2);
    assert_eq!(img.n_leaves(), 2);
    assert_eq!(img.n_balls(), 3);
    assert_eq!(img.n_ball_refs(), 3);
    assert_eq!(img.n_trajectories(), 0);
    assert_eq!(img.total_steps(), 0);
    assert_eq!(img.law_gain(0, 0, 1), -2.0);
    assert_eq!(img.law_offset(1, 0), -1.0);
    assert_eq!(img.node_children(0), Some((Child::Node(1), Child::Leaf(1))));
    assert_eq!(img.node_children(1), Some((Child::Leaf(0), Child::Outside)));
    assert_eq!(img.node_children(2), None);
    assert_eq!(img.leaf_refs(0), (0, 2));
    assert_eq!(img.leaf_refs(1), (2, 1));
    assert_eq!(img.leaf_ball(1, 0), Some(2));
    assert_eq!(img.leaf_ball(1, 1), None);
    assert_eq!(img.ball_threshold(1), 0.5625);
    assert_eq!(img.ball_centre_z(2, 0), 1.0);
    assert_eq!(img.node_normal(1, 1), 1.0);
    assert_eq!(img.node_offset(1), 2.0);
    assert_eq!(img.ball_partition(2), 1);
    // Out-of-range accessors are total.
    assert_eq!(img.law_gain(2, 0, 0), 0.0);
    assert_eq!(img.ball_centre(3, 0), 0.0);
    assert_eq!(PwaContent::from_image(&img), c);
    let mut again = vec![0u8; bytes.len()];
    assert_eq!(encode(&img, &mut again), Ok(bytes.len()));
    assert_eq!(again, bytes);
    assert_eq!(img.encoded_len(), Ok(bytes.len()));
    // The raw writer used by the rejection tests produces the same bytes for valid content.
    assert_eq!(c.raw_bytes(), bytes);
}

#[test]
fn feedforward_images_have_empty_pwa_tables() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let c = crate::common::random_content(&mut rng, 3, 2, 2, 3);
    let bytes = c.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert_eq!(img.n_partitions(), 0);
    assert_eq!(img.n_nodes(), 0);
    assert_eq!(img.n_leaves(), 0);
    assert_eq!(img.n_balls(), 0);
    assert_eq!(img.locate(&vec![0.0; c.n]), None);
}

#[test]
fn round_trip_random_contents() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let shapes = [
        PwaShape::default(),
        PwaShape {
            max_n: MAX_N,
            max_m: MAX_M,
            max_partitions: 40,
            max_depth: MAX_TREE_DEPTH,
            max_nodes: 60,
            p_outside: 0.05,
            max_leaf_balls: MAX_LEAF_BALLS,
            box_half: 10.0,
        },
    ];
    for k in 0..300 {
        let c = random_pwa(&mut rng, shapes[k % 2]);
        let bytes = c.to_bytes().unwrap();
        assert!(bytes.len() <= MAX_IMAGE_LEN);
        let img = decode(&bytes).unwrap();
        assert_eq!(img.tree_depth(), tree_depth(&c.node_child) as usize);
        assert_eq!(PwaContent::from_image(&img), c);
        let mut again = vec![0u8; bytes.len()];
        encode(&img, &mut again).unwrap();
        assert_eq!(again, bytes);
    }
}

/// A complete-as-possible tree of `nodes` nodes in breadth-first numbering (children of i are 2i+1 and
/// 2i+2 when they exist), terminals numbered left to right as leaves, the last terminal OUTSIDE if
/// `outside_last`. Returns (children, number of leaves).
fn heap_tree(nodes: usize, outside_last: bool) -> (Vec<u16>, usize) {
    let mut child = vec![0u16; 2 * nodes];
    let mut leaves = 0usize;
    let terminals = nodes + 1;
    for i in 0..nodes {
        for side in 0..2 {
            let c = 2 * i + 1 + side;
            child[2 * i + side] = if c < nodes {
                c as u16
            } else {
                leaves += 1;
                if outside_last && leaves == terminals {
                    leaves -= 1;
                    OUTSIDE
                } else {
                    LEAF_BASE + (leaves - 1) as u16
                }
            };
        }
    }
    (child, leaves)
}

#[test]
fn largest_image_fits_max_image_len() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (n, m, nl, np) = (MAX_N, MAX_M, 8, MAX_PARTITIONS);
    let (node_child, leaves) = heap_tree(MAX_TREE_NODES, true);
    assert_eq!(leaves, MAX_LEAVES);
    let per_leaf = MAX_BALL_REFS / MAX_LEAVES;
    let nb = MAX_BALLS;
    // Leaf l has partition l % np; ball b has partition b % np; leaf l lists per_leaf balls of its
    // partition.
    let leaf_partition: Vec<u16> = (0..leaves).map(|l| (l % np) as u16).collect();
    let leaf_balls: Vec<Vec<u16>> = (0..leaves)
        .map(|l| {
            (0..per_leaf)
                .map(|k| ((l % np) + np * ((l / np * per_leaf + k) % (nb / np))) as u16)
                .collect()
        })
        .collect();
    let c = PwaContent {
        n,
        m,
        nl,
        np,
        period: 0.01,
        K: vec![0.5; nl * m * n],
        P: (0..nl).flat_map(|_| random_spd(&mut rng, n)).collect(),
        gain: vec![-1.25; np * m * n],
        offset: vec![0.125; np * m],
        depth: tree_depth(&node_child),
        node_a: vec![1.0; MAX_TREE_NODES * n],
        node_b: vec![0.5; MAX_TREE_NODES],
        node_child,
        leaf_partition,
        leaf_balls,
        R: vec![],
        ball_centre: vec![0.25; nb * n],
        ball_centre_z: vec![],
        ball_threshold: vec![1.0; nb],
        ball_location: (0..nb).map(|b| (b % nl) as u8).collect(),
        ball_partition: (0..nb).map(|b| (b % np) as u16).collect(),
        fallback: FallbackC::Linear {
            K: vec![1.0; m * n],
            x_ref: vec![0.0; n],
            u_ref: vec![0.0; m],
        },
        input_box: Some((vec![-1.0; m], vec![1.0; m])),
        n_trajectories: 0,
        counts: None,
    }
    .whitened();
    let bytes = c.to_bytes().unwrap();
    assert!(
        bytes.len() <= MAX_IMAGE_LEN,
        "{} > {}",
        bytes.len(),
        MAX_IMAGE_LEN
    );
    let img = decode(&bytes).unwrap();
    assert_eq!(img.n_ball_refs(), MAX_BALL_REFS);
    assert_eq!(img.tree_depth(), 11);
    assert_eq!(PwaContent::from_image(&img), c);
}

/// A chain: node i goes left to node i+1 and right to leaf 0; the last node goes to leaf 0 both ways.
fn chain(len: usize) -> PwaContent {
    let mut c = two_partitions();
    c.node_a = (0..len).flat_map(|_| [1.0, 0.0]).collect();
    c.node_b = (0..len).map(|i| -(i as f32)).collect();
    c.node_child = (0..len)
        .flat_map(|i| {
            if i + 1 < len {
                [(i + 1) as u16, L0]
            } else {
                [L0, L0]
            }
        })
        .collect();
    c.leaf_partition = vec![0];
    c.leaf_balls = vec![vec![0, 1]];
    c.depth = len.min(255) as u8;
    c
}

/// Regression: a leaf whose cell meets balls certified for different laws lists them all (no ball of F is
/// dropped), and the law applied is that of the ball that contains the state, not the leaf's.
#[test]
fn a_mixed_leaf_applies_the_law_of_the_containing_ball() {
    use shared_types::pwa::Region;
    // Leaf 1 (main partition 1) also lists ball 0 (certified for partition 0), after ball 2.
    let mut c = two_partitions();
    c.leaf_balls[1] = vec![2, 0];
    let bytes = c.to_bytes().expect("a mixed leaf is a valid image");
    let img = shared_types::image::decode(&bytes).unwrap();
    // x = (0.2, 0.5): right of x1 = 0, below x2 = 2 → leaf 1; outside ball 2 ((1,0), δ 1.5)? |(−0.8, 0.5)| = 0.94
    // < 1.5, so ball 2 (partition 1) is found first.
    match img.locate(&[0.2, 0.5]) {
        Some(Region::Inside {
            leaf: 1,
            partition: 1,
            ball: 2,
        }) => {}
        other => panic!("{other:?}"),
    }
    // With ball 2 shrunk to δ 0.5 (threshold 0.25) and leaf 1 listing ball 1 ((−0.5, 1), δ 0.75, partition 0) after it, the
    // state (0.1, 1.0) (right of x1 = 0: leaf 1) lies only in ball 1, so partition 0's law applies.
    let mut c = two_partitions();
    c.leaf_balls[1] = vec![2, 1];
    c.ball_threshold[2] = 0.25;
    let bytes = c.to_bytes().unwrap();
    let img = shared_types::image::decode(&bytes).unwrap();
    match img.locate(&[0.1, 1.0]) {
        Some(Region::Inside {
            leaf: 1,
            partition: 0,
            ball: 1,
        }) => {}
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_chain_of_max_depth_is_accepted() {
    // One longer is rejected: see the "tree:" rows of `rejects_invalid_content`.
    let c = chain(MAX_TREE_DEPTH);
    let img_bytes = c.to_bytes().unwrap();
    assert_eq!(decode(&img_bytes).unwrap().tree_depth(), MAX_TREE_DEPTH);
}

#[test]
fn shared_subtrees_are_allowed_and_counted_once_for_depth() {
    // Node 0 → node 1 both ways (a DAG); node 1 → leaves.
    let mut c = two_partitions();
    c.node_child = vec![1, 1, L0, L1];
    let img_bytes = c.to_bytes().unwrap();
    assert_eq!(decode(&img_bytes).unwrap().tree_depth(), 2);
}

// ---- Rejection tables -----------------------------------------------------------------------------------

/// The error a row expects.
enum Expect {
    /// Exactly this error.
    Is(ImageError),
    /// An error matching a pattern (fields the pattern leaves out are free); the text is the pattern.
    Like(&'static str, fn(&ImageError) -> bool),
}
use Expect::Is;

/// `Expect::Like` from a pattern.
macro_rules! like {
    ($p:pat) => {
        Expect::Like(stringify!($p), |e| matches!(e, $p))
    };
}

/// What the error's `Display` must say, if anything.
enum Says {
    Anything,
    Exactly(&'static str),
    Contains(&'static str),
}

/// One rejection check: `mutate` applied to `two_partitions()` (or, for byte rows, to its encoded bytes,
/// after which the header's length and CRC are fixed) must be rejected with `expect`.
struct Row<T> {
    what: &'static str,
    mutate: fn(&mut T),
    expect: Expect,
    says: Says,
}

/// A row of the content table.
fn row(what: &'static str, mutate: fn(&mut PwaContent), expect: Expect) -> Row<PwaContent> {
    Row {
        what,
        mutate,
        expect,
        says: Says::Anything,
    }
}

/// A row of the byte table.
fn byte_row(what: &'static str, mutate: fn(&mut Vec<u8>), expect: Expect) -> Row<Vec<u8>> {
    Row {
        what,
        mutate,
        expect,
        says: Says::Anything,
    }
}

impl<T> Row<T> {
    fn says(self, text: &'static str) -> Self {
        Row {
            says: Says::Exactly(text),
            ..self
        }
    }
    fn says_something_with(self, text: &'static str) -> Self {
        Row {
            says: Says::Contains(text),
            ..self
        }
    }
}

/// `Err` with what is wrong if `e` is not what the row expects.
fn check_error<T>(row: &Row<T>, e: ImageError) -> Result<(), String> {
    match &row.expect {
        Is(want) if e != *want => return Err(format!("got {e:?}, expected {want:?}")),
        Expect::Like(pattern, ok) if !ok(&e) => {
            return Err(format!("got {e:?}, expected an error like {pattern}"))
        }
        _ => {}
    }
    let text = e.to_string();
    match row.says {
        Says::Exactly(want) if text != want => Err(format!("message {text:?}, expected {want:?}")),
        Says::Contains(want) if !text.contains(want) => {
            Err(format!("message {text:?} does not contain {want:?}"))
        }
        _ => Ok(()),
    }
}

/// Runs every row and fails naming each row whose check fails (all of them, not just the first).
fn run_rows<T>(rows: &[Row<T>], check: impl Fn(&Row<T>) -> Result<(), String>) {
    let mut names = std::collections::HashSet::new();
    for r in rows {
        assert!(
            names.insert(r.what),
            "duplicate row description {:?}",
            r.what
        );
    }
    let failures: Vec<String> = rows
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            check(r)
                .err()
                .map(|why| format!("  row {i} \"{}\": {why}", r.what))
        })
        .collect();
    assert!(
        failures.is_empty(),
        "{} of {} rows failed:\n{}",
        failures.len(),
        rows.len(),
        failures.join("\n")
    );
}

/// Content mutations: `decode` of the raw bytes (correct CRC) must report the expected error, and
/// `Image::new_pwa` must report the same.
#[test]
fn rejects_invalid_content() {
    #[rustfmt::skip]
    let rows: Vec<Row<PwaContent>> = vec![
        // Tree shape.
        row("tree: chain of MAX_TREE_DEPTH + 1 nodes, stored depth MAX_TREE_DEPTH",
            |c| { *c = chain(MAX_TREE_DEPTH + 1); c.depth = MAX_TREE_DEPTH as u8; },
            Is(ImageError::TreeTooDeep { node: MAX_TREE_DEPTH as u16 })),
        row("tree: chain of MAX_TREE_DEPTH + 1 nodes, stored depth MAX_TREE_DEPTH + 1",
            |c| { *c = chain(MAX_TREE_DEPTH + 1); c.depth = (MAX_TREE_DEPTH + 1) as u8; },
            Is(ImageError::DimOutOfRange { dim: Dim::TreeDepth, value: MAX_TREE_DEPTH as u32 + 1, min: 0, max: MAX_TREE_DEPTH as u32 }))
            .says_something_with("tree depth"),
        row("tree: self loop at node 1", |c| c.node_child[2] = 1,
            Is(ImageError::BackEdge { node: 1, child: 1 })),
        row("tree: edge back to the root (cycle 0 → 1 → 0)", |c| c.node_child[3] = 0,
            Is(ImageError::BackEdge { node: 1, child: 0 }))
            .says("tree node 1: child node 0 does not come after its parent (back edge)"),
        row("tree: child node 2 of 2 nodes", |c| c.node_child[1] = 2,
            Is(ImageError::ChildOutOfRange { node: 0, child: 2 })),
        row("tree: child node 0x7FFF", |c| c.node_child[1] = 0x7FFF,
            Is(ImageError::ChildOutOfRange { node: 0, child: 0x7FFF })),
        row("tree: leaf 2 of 2 leaves", |c| c.node_child[2] = LEAF_BASE + 2,
            Is(ImageError::LeafOutOfRange { node: 1, leaf: 2 })),
        row("tree: leaf code OUTSIDE - 1", |c| c.node_child[2] = OUTSIDE - 1,
            Is(ImageError::LeafOutOfRange { node: 1, leaf: OUTSIDE - 1 - LEAF_BASE })),
        row("tree: node 2 exists but nothing points to it",
            |c| { c.node_a.extend_from_slice(&[1.0, 1.0]); c.node_b.push(0.0); c.node_child.extend_from_slice(&[L0, L1]); },
            Is(ImageError::UnreachableNode { node: 2 })),
        row("tree: leaf 2 exists but no node names it",
            |c| { c.leaf_partition.push(0); c.leaf_balls.push(vec![0]); },
            Is(ImageError::UnreferencedLeaf { leaf: 2 })),
        row("tree: leaf 0 replaced by OUTSIDE", |c| c.node_child[2] = OUTSIDE,
            Is(ImageError::UnreferencedLeaf { leaf: 0 })),
        row("tree: no nodes (leaf 0 alone) but a second leaf",
            |c| { c.node_a.clear(); c.node_b.clear(); c.node_child.clear(); c.depth = 0; },
            Is(ImageError::UnreferencedLeaf { leaf: 1 })),
        row("tree: stored depth 0, actual 2", |c| c.depth = 0,
            Is(ImageError::TreeDepthMismatch { stored: 0, actual: 2 })),
        row("tree: stored depth 1, actual 2", |c| c.depth = 1,
            Is(ImageError::TreeDepthMismatch { stored: 1, actual: 2 })),
        row("tree: stored depth 3, actual 2", |c| c.depth = 3,
            Is(ImageError::TreeDepthMismatch { stored: 3, actual: 2 })),
        row("tree: no nodes, one leaf, stored depth 1",
            |c| { c.node_a.clear(); c.node_b.clear(); c.node_child.clear(); c.leaf_partition.pop(); c.leaf_balls.pop(); c.depth = 1; },
            Is(ImageError::TreeDepthMismatch { stored: 1, actual: 0 })),
        // Hyperplanes.
        row("node: normal (0, −0)", |c| { c.node_a[2] = 0.0; c.node_a[3] = -0.0; },
            Is(ImageError::DegenerateHyperplane { node: 1 })),
        row("node: NaN in a normal", |c| c.node_a[3] = f32::NAN,
            Is(ImageError::NonFinite { field: Field::NodeNormal, pos: Pos(1, 1, 0) }))
            .says("node 1: a[1] is not finite"),
        row("node: infinite offset", |c| c.node_b[0] = f32::INFINITY,
            Is(ImageError::NonFinite { field: Field::NodeOffset, pos: Pos(0, 0, 0) }))
            .says("node 0: b is not finite"),
        row("node: record short by one child code", |c| { c.node_child.pop(); },
            Is(ImageError::FieldLength { field: Field::Node, expected: 32, found: 30 })),
        // Laws.
        row("law: −∞ in a gain", |c| c.gain[3] = f32::NEG_INFINITY,
            Is(ImageError::NonFinite { field: Field::LawGain, pos: Pos(1, 0, 1) })),
        row("law: NaN in an offset", |c| c.offset[1] = f32::NAN,
            Is(ImageError::NonFinite { field: Field::LawOffset, pos: Pos(1, 0, 0) })),
        row("law: gain table one entry short", |c| { c.gain.pop(); },
            Is(ImageError::FieldLength { field: Field::LawGain, expected: 16, found: 12 })),
        // Leaves.
        row("leaf: partition 2 of 2", |c| c.leaf_partition[1] = 2,
            Is(ImageError::PartitionOutOfRange { leaf: 1, value: 2 })),
        row("leaf: no balls (ends 2, 2)", |c| c.leaf_balls[1].clear(),
            Is(ImageError::LeafBallEnds { leaf: 1 })),
        row("leaf: MAX_LEAF_BALLS + 1 balls", |c| c.leaf_balls[0] = vec![0; MAX_LEAF_BALLS + 1],
            Is(ImageError::LeafTooManyBalls { leaf: 0, count: MAX_LEAF_BALLS as u16 + 1 })),
        row("leaf: ball 3 of 3", |c| c.leaf_balls[1] = vec![3],
            Is(ImageError::BallRefOutOfRange { leaf: 1, value: 3 })),
        // Balls.
        row("ball: threshold −0.5", |c| c.ball_threshold[2] = -0.5,
            Is(ImageError::NegativeBallThreshold { ball: 2 }))
            .says("ball 2: threshold is negative"),
        row("ball: threshold −MIN_POSITIVE", |c| c.ball_threshold[2] = -f32::MIN_POSITIVE,
            Is(ImageError::NegativeBallThreshold { ball: 2 })),
        row("ball: threshold NaN", |c| c.ball_threshold[2] = f32::NAN,
            Is(ImageError::NonFinite { field: Field::BallThreshold, pos: Pos(2, 0, 0) }))
            .says("ball 2: threshold is not finite"),
        row("ball: threshold +∞", |c| c.ball_threshold[2] = f32::INFINITY,
            Is(ImageError::NonFinite { field: Field::BallThreshold, pos: Pos(2, 0, 0) }))
            .says("ball 2: threshold is not finite"),
        row("ball: threshold −∞", |c| c.ball_threshold[2] = f32::NEG_INFINITY,
            Is(ImageError::NonFinite { field: Field::BallThreshold, pos: Pos(2, 0, 0) }))
            .says("ball 2: threshold is not finite"),
        row("ball: infinite centre", |c| c.ball_centre[3] = f32::INFINITY,
            Is(ImageError::NonFinite { field: Field::BallCentre, pos: Pos(1, 1, 0) })),
        row("ball: NaN whitened centre", |c| c.ball_centre_z[5] = f32::NAN,
            Is(ImageError::NonFinite { field: Field::BallCentreZ, pos: Pos(2, 1, 0) })),
        row("ball: whitened centres one short", |c| { c.ball_centre_z.pop(); },
            Is(ImageError::FieldLength { field: Field::BallTest, expected: 36, found: 32 })),
        row("ball: thresholds one short (ball count kept at 3)",
            |c| { c.ball_threshold.pop(); c.counts = Some((2, 2, 3)); },
            Is(ImageError::FieldLength { field: Field::BallTest, expected: 36, found: 32 })),
        row("ball: location 1 of 1", |c| c.ball_location[1] = 1,
            Is(ImageError::BallLocationOutOfRange { ball: 1, value: 1 })),
        row("ball: partition 5 of 2", |c| c.ball_partition[0] = 5,
            Is(ImageError::BallPartitionOutOfRange { ball: 0, value: 5 })),
        row("ball: locations one short", |c| { c.ball_location.pop(); },
            Is(ImageError::FieldLength { field: Field::BallLocation, expected: 3, found: 2 })),
        // Counts and dimensions.
        row("dims: no partitions", |c| { c.np = 0; c.gain.clear(); c.offset.clear(); },
            Is(ImageError::DimOutOfRange { dim: Dim::Partitions, value: 0, min: 1, max: MAX_PARTITIONS as u32 })),
        row("dims: MAX_PARTITIONS + 1 partitions", |c| c.np = MAX_PARTITIONS + 1,
            like!(ImageError::DimOutOfRange { dim: Dim::Partitions, .. })),
        row("dims: a trajectory in a PWA image", |c| c.n_trajectories = 1,
            Is(ImageError::DimOutOfRange { dim: Dim::Trajectories, value: 1, min: 0, max: 0 })),
        row("dims: MAX_TREE_NODES + 1 nodes", |c| c.counts = Some((MAX_TREE_NODES as u16 + 1, 2, 3)),
            like!(ImageError::DimOutOfRange { dim: Dim::TreeNodes, .. })),
        row("dims: no leaves", |c| c.counts = Some((2, 0, 3)),
            like!(ImageError::DimOutOfRange { dim: Dim::Leaves, value: 0, .. })),
        row("dims: no balls", |c| c.counts = Some((2, 2, 0)),
            like!(ImageError::DimOutOfRange { dim: Dim::Balls, value: 0, .. })),
        row("dims: node count disagrees with the arrays", |c| c.counts = Some((3, 2, 3)),
            Is(ImageError::FieldLength { field: Field::Node, expected: 48, found: 32 })),
        // Period, P, input box.
        row("period 0", |c| c.period = 0.0,
            Is(ImageError::BadPeriod)),
        row("P not positive definite", |c| c.P = vec![1.0, 2.0, 2.0, 1.0],
            Is(ImageError::NotPositiveDefinite { location: 0 })),
        row("input box empty", |c| c.input_box = Some((vec![1.0], vec![0.0])),
            Is(ImageError::EmptyInputBox { input: 0 })),
        // The metric factor R.
        row("factor: R[1,0] = 0.5", |c| c.R[2] = 0.5,
            Is(ImageError::FactorNotUpperTriangular { location: 0, row: 1, col: 0 }))
            .says("location 0: factor R is not upper triangular (R[1,0] != 0)"),
        row("factor: R[1,1] = 0", |c| c.R[3] = 0.0,
            Is(ImageError::FactorDiagonal { location: 0, row: 1 }))
            .says("location 0: factor R has a non-positive diagonal entry R[1,1]"),
        row("factor: R[1,1] = −1", |c| c.R[3] = -1.0,
            Is(ImageError::FactorDiagonal { location: 0, row: 1 }))
            .says("location 0: factor R has a non-positive diagonal entry R[1,1]"),
        row("factor: R[1,1] = −0", |c| c.R[3] = -0.0,
            Is(ImageError::FactorDiagonal { location: 0, row: 1 }))
            .says("location 0: factor R has a non-positive diagonal entry R[1,1]"),
        row("factor: R[0,1] = +∞", |c| c.R[1] = f32::INFINITY,
            Is(ImageError::NonFinite { field: Field::Factor, pos: Pos(0, 0, 1) })),
        row("factor: one entry too many", |c| c.R.push(0.0),
            Is(ImageError::FieldLength { field: Field::Factor, expected: 16, found: 20 })),
    ];
    assert_eq!(rows.len(), 55);
    run_rows(&rows, |r| {
        let mut c = two_partitions();
        (r.mutate)(&mut c);
        check_error(r, c.decode_err()?)
    });
}

/// A change to the fixed content.
type Mutation = fn(&mut PwaContent);

/// Boundary cases next to the rejections above: `mutate` applied to `two_partitions()` must still encode.
#[test]
fn accepts_content_next_to_the_rejections() {
    #[rustfmt::skip]
    let rows: [(&str, Mutation); 5] = [
        ("tree: no nodes, leaf 0 alone",
            |c| { c.node_a.clear(); c.node_b.clear(); c.node_child.clear(); c.depth = 0; c.leaf_partition.pop(); c.leaf_balls.pop(); }),
        ("leaf: MAX_LEAF_BALLS balls", |c| c.leaf_balls[0] = vec![0; MAX_LEAF_BALLS]),
        ("ball: threshold 0 (a single certified point)", |c| c.ball_threshold[0] = 0.0),
        ("ball: threshold −0", |c| c.ball_threshold[0] = -0.0),
        ("factor: anything finite above the diagonal (R[0,1] = −3)", |c| c.R[1] = -3.0),
    ];
    let failures: Vec<String> = rows
        .iter()
        .filter_map(|(what, mutate)| {
            let mut c = two_partitions();
            mutate(&mut c);
            c.to_bytes()
                .err()
                .map(|e| format!("  \"{what}\": rejected with {e:?}"))
        })
        .collect();
    assert!(
        failures.is_empty(),
        "rows rejected:\n{}",
        failures.join("\n")
    );
}

/// Byte mutations of the encoded `two_partitions()` (header length and CRC fixed afterwards): `decode`
/// must report the expected error.
#[test]
fn rejects_invalid_payload_bytes() {
    #[rustfmt::skip]
    let rows: Vec<Row<Vec<u8>>> = vec![
        // The first field of the locations section is K's byte string: length prefix 8 (0x08).
        // Re-encode it as the overlong varint 0x88 0x00: same content, non-canonical bytes.
        byte_row("locations: overlong varint 0x88 0x00 for K's length 8",
            |b| { let mut s = sections_of(b); assert_eq!(s[0].1[0], 8); s[0].1.splice(0..1, [0x88, 0x00]);
                  *b = with_sections(b, &s); },
            Is(ImageError::NotCanonical { section: SectionKind::Locations })),
        byte_row("balls: a trailing zero byte", |b| { let mut s = sections_of(b); s[4].1.push(0);
                  *b = with_sections(b, &s); },
            Is(ImageError::TrailingBytes { section: SectionKind::PwaBalls })),
        byte_row("tree: last byte cut off", |b| { let mut s = sections_of(b); s[3].1.pop();
                  *b = with_sections(b, &s); },
            Is(ImageError::Malformed { section: SectionKind::PwaTree })),
        byte_row("directory: a feedforward section in a PWA image", |b| {
                  let mut s = sections_of(b); s.insert(2, (SectionKind::Steps as u16, vec![0]));
                  *b = with_sections(b, &s); },
            Is(ImageError::UnexpectedSection { kind: SectionKind::Steps, mode: Mode::PwaFeedback })),
        byte_row("directory: the tree section missing", |b| {
                  let mut s = sections_of(b); s.remove(3); *b = with_sections(b, &s); },
            Is(ImageError::MissingSection { kind: SectionKind::PwaTree })),
        byte_row("directory: an unknown section kind", |b| {
                  let mut s = sections_of(b); s.push((200, vec![])); *b = with_sections(b, &s); },
            Is(ImageError::UnknownSection { kind: 200 })),
        byte_row("directory: model maps (feedforward only)", |b| {
                  let mut s = sections_of(b); s.push((10, vec![0])); *b = with_sections(b, &s); },
            Is(ImageError::UnexpectedSection { kind: SectionKind::ModelMaps, mode: Mode::PwaFeedback })),
        byte_row("directory: segment exits (feedforward only)", |b| {
                  let mut s = sections_of(b); s.push((9, vec![0])); *b = with_sections(b, &s); },
            Is(ImageError::UnexpectedSection { kind: SectionKind::SegmentExits, mode: Mode::PwaFeedback })),
        byte_row("header: n = 3 (payload has n = 2)", |b| b[8..10].copy_from_slice(&3u16.to_le_bytes()),
            Is(ImageError::FieldLength { field: Field::K, expected: 12, found: 8 })),
        byte_row("header: 3 partitions (payload has 2)", |b| b[16..18].copy_from_slice(&3u16.to_le_bytes()),
            Is(ImageError::FieldLength { field: Field::LawGain, expected: 24, found: 16 })),
    ];
    let good = two_partitions().to_bytes().unwrap();
    run_rows(&rows, |r| {
        let mut b = good.clone();
        (r.mutate)(&mut b);
        crate::common::fix_header(&mut b);
        match decode(&b) {
            Ok(_) => Err("decode accepted the bytes".into()),
            Err(e) => check_error(r, e),
        }
    });
}
