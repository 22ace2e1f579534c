//! PWA-feedback images (mode 2): round trips (fixed, random, at capacity), canonical re-encoding, and one
//! test per validation rule, each fed to `decode` as raw bytes with a correct CRC and checked to name what
//! is wrong (and `Image::new_pwa` to agree).
#![allow(non_snake_case)]

mod common;

use common::{
    random_pwa, random_spd, tree_depth, two_partitions, FallbackC, PwaContent, PwaShape, L0, L1,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{
    MAX_BALLS, MAX_BALL_REFS, MAX_IMAGE_LEN, MAX_LEAF_BALLS, MAX_LEAVES, MAX_M, MAX_N,
    MAX_PARTITIONS, MAX_TREE_DEPTH, MAX_TREE_NODES,
};
use shared_types::image::{decode, encode, Dim, Field, Header, ImageError, Mode, Pos};
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
    let c = common::random_content(&mut rng, 3, 2, 2, 3);
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

#[test]
fn a_chain_of_max_depth_is_accepted_one_longer_is_not() {
    let c = chain(MAX_TREE_DEPTH);
    let img_bytes = c.to_bytes().unwrap();
    assert_eq!(decode(&img_bytes).unwrap().tree_depth(), MAX_TREE_DEPTH);

    let mut c = chain(MAX_TREE_DEPTH + 1);
    c.depth = MAX_TREE_DEPTH as u8;
    assert_eq!(
        c.decode_err(),
        ImageError::TreeTooDeep {
            node: MAX_TREE_DEPTH as u16
        }
    );
    c.depth = (MAX_TREE_DEPTH + 1) as u8;
    assert_eq!(
        c.decode_err(),
        ImageError::DimOutOfRange {
            dim: Dim::TreeDepth,
            value: MAX_TREE_DEPTH as u32 + 1,
            min: 0,
            max: MAX_TREE_DEPTH as u32
        }
    );
    assert!(c.decode_err().to_string().contains("tree depth"));
}

#[test]
fn rejects_cycles_and_back_edges() {
    // Self loop.
    let mut c = two_partitions();
    c.node_child[2] = 1;
    assert_eq!(c.decode_err(), ImageError::BackEdge { node: 1, child: 1 });
    // Edge back to the root: a cycle 0 → 1 → 0.
    let mut c = two_partitions();
    c.node_child[3] = 0;
    assert_eq!(c.decode_err(), ImageError::BackEdge { node: 1, child: 0 });
    assert_eq!(
        c.decode_err().to_string(),
        "tree node 1: child node 0 does not come after its parent (back edge)"
    );
}

#[test]
fn rejects_children_out_of_range() {
    let mut c = two_partitions();
    c.node_child[1] = 2; // only nodes 0 and 1
    assert_eq!(
        c.decode_err(),
        ImageError::ChildOutOfRange { node: 0, child: 2 }
    );
    let mut c = two_partitions();
    c.node_child[1] = 0x7FFF;
    assert_eq!(
        c.decode_err(),
        ImageError::ChildOutOfRange {
            node: 0,
            child: 0x7FFF
        }
    );
    let mut c = two_partitions();
    c.node_child[2] = LEAF_BASE + 2; // only leaves 0 and 1
    assert_eq!(
        c.decode_err(),
        ImageError::LeafOutOfRange { node: 1, leaf: 2 }
    );
    let mut c = two_partitions();
    c.node_child[2] = OUTSIDE - 1;
    assert_eq!(
        c.decode_err(),
        ImageError::LeafOutOfRange {
            node: 1,
            leaf: OUTSIDE - 1 - LEAF_BASE
        }
    );
}

#[test]
fn rejects_unreachable_nodes_and_unreferenced_leaves() {
    // Node 2 exists but nothing points to it.
    let mut c = two_partitions();
    c.node_a.extend_from_slice(&[1.0, 1.0]);
    c.node_b.push(0.0);
    c.node_child.extend_from_slice(&[L0, L1]);
    assert_eq!(c.decode_err(), ImageError::UnreachableNode { node: 2 });
    // Leaf 2 exists but no node names it.
    let mut c = two_partitions();
    c.leaf_partition.push(0);
    c.leaf_balls.push(vec![0]);
    assert_eq!(c.decode_err(), ImageError::UnreferencedLeaf { leaf: 2 });
    // Leaf 0 replaced by OUTSIDE: leaf 0 is now unreferenced.
    let mut c = two_partitions();
    c.node_child[2] = OUTSIDE;
    assert_eq!(c.decode_err(), ImageError::UnreferencedLeaf { leaf: 0 });
    // Without nodes the tree is leaf 0 alone: a second leaf is unreferenced.
    let mut c = two_partitions();
    c.node_a.clear();
    c.node_b.clear();
    c.node_child.clear();
    c.depth = 0;
    assert_eq!(c.decode_err(), ImageError::UnreferencedLeaf { leaf: 1 });
    c.leaf_partition.pop();
    c.leaf_balls.pop();
    assert!(c.to_bytes().is_ok());
}

#[test]
fn rejects_a_wrong_stored_depth() {
    for stored in [0u8, 1, 3] {
        let mut c = two_partitions();
        c.depth = stored;
        assert_eq!(
            c.decode_err(),
            ImageError::TreeDepthMismatch { stored, actual: 2 }
        );
    }
    let mut c = two_partitions();
    c.node_a.clear();
    c.node_b.clear();
    c.node_child.clear();
    c.leaf_partition.pop();
    c.leaf_balls.pop();
    c.depth = 1;
    assert_eq!(
        c.decode_err(),
        ImageError::TreeDepthMismatch {
            stored: 1,
            actual: 0
        }
    );
}

#[test]
fn rejects_degenerate_and_non_finite_hyperplanes() {
    let mut c = two_partitions();
    c.node_a[2] = 0.0;
    c.node_a[3] = -0.0;
    assert_eq!(c.decode_err(), ImageError::DegenerateHyperplane { node: 1 });
    let mut c = two_partitions();
    c.node_a[3] = f32::NAN;
    assert_eq!(
        c.decode_err(),
        ImageError::NonFinite {
            field: Field::NodeNormal,
            pos: Pos(1, 1, 0)
        }
    );
    assert_eq!(c.decode_err().to_string(), "node 1: a[1] is not finite");
    let mut c = two_partitions();
    c.node_b[0] = f32::INFINITY;
    assert_eq!(
        c.decode_err(),
        ImageError::NonFinite {
            field: Field::NodeOffset,
            pos: Pos(0, 0, 0)
        }
    );
    assert_eq!(c.decode_err().to_string(), "node 0: b is not finite");
    // A node record short by one child code: the record table has the wrong length.
    let mut c = two_partitions();
    c.node_child.pop();
    assert_eq!(
        c.decode_err(),
        ImageError::FieldLength {
            field: Field::Node,
            expected: 32,
            found: 30
        }
    );
}

#[test]
fn rejects_bad_laws() {
    let mut c = two_partitions();
    c.gain[3] = f32::NEG_INFINITY;
    assert_eq!(
        c.decode_err(),
        ImageError::NonFinite {
            field: Field::LawGain,
            pos: Pos(1, 0, 1)
        }
    );
    let mut c = two_partitions();
    c.offset[1] = f32::NAN;
    assert_eq!(
        c.decode_err(),
        ImageError::NonFinite {
            field: Field::LawOffset,
            pos: Pos(1, 0, 0)
        }
    );
    let mut c = two_partitions();
    c.gain.pop();
    assert_eq!(
        c.decode_err(),
        ImageError::FieldLength {
            field: Field::LawGain,
            expected: 16,
            found: 12
        }
    );
}

#[test]
fn rejects_bad_leaves() {
    let mut c = two_partitions();
    c.leaf_partition[1] = 2;
    assert_eq!(
        c.decode_err(),
        ImageError::PartitionOutOfRange { leaf: 1, value: 2 }
    );
    // A leaf without balls: ends 2, 2.
    let mut c = two_partitions();
    c.leaf_balls[1].clear();
    assert_eq!(c.decode_err(), ImageError::LeafBallEnds { leaf: 1 });
    let mut c = two_partitions();
    c.leaf_balls[0] = vec![0; MAX_LEAF_BALLS + 1];
    assert_eq!(
        c.decode_err(),
        ImageError::LeafTooManyBalls {
            leaf: 0,
            count: MAX_LEAF_BALLS as u16 + 1
        }
    );
    let mut c = two_partitions();
    c.leaf_balls[0] = vec![0; MAX_LEAF_BALLS];
    assert!(c.to_bytes().is_ok());
    let mut c = two_partitions();
    c.leaf_balls[1] = vec![3];
    assert_eq!(
        c.decode_err(),
        ImageError::BallRefOutOfRange { leaf: 1, value: 3 }
    );
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
fn rejects_bad_balls() {
    let mut c = two_partitions();
    c.ball_threshold[2] = -0.5;
    assert_eq!(
        c.decode_err(),
        ImageError::NegativeBallThreshold { ball: 2 }
    );
    assert_eq!(c.decode_err().to_string(), "ball 2: threshold is negative");
    let mut c = two_partitions();
    c.ball_threshold[2] = -f32::MIN_POSITIVE;
    assert_eq!(
        c.decode_err(),
        ImageError::NegativeBallThreshold { ball: 2 }
    );
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut c = two_partitions();
        c.ball_threshold[2] = bad;
        assert_eq!(
            c.decode_err(),
            ImageError::NonFinite {
                field: Field::BallThreshold,
                pos: Pos(2, 0, 0)
            }
        );
        assert_eq!(
            c.decode_err().to_string(),
            "ball 2: threshold is not finite"
        );
    }
    let mut c = two_partitions();
    c.ball_centre[3] = f32::INFINITY;
    assert_eq!(
        c.decode_err(),
        ImageError::NonFinite {
            field: Field::BallCentre,
            pos: Pos(1, 1, 0)
        }
    );
    let mut c = two_partitions();
    c.ball_centre_z[5] = f32::NAN;
    assert_eq!(
        c.decode_err(),
        ImageError::NonFinite {
            field: Field::BallCentreZ,
            pos: Pos(2, 1, 0)
        }
    );
    let mut c = two_partitions();
    c.ball_centre_z.pop();
    assert_eq!(
        c.decode_err(),
        ImageError::FieldLength {
            field: Field::BallTest,
            expected: 36,
            found: 32
        }
    );
    let mut c = two_partitions();
    c.ball_threshold.pop();
    c.counts = Some((2, 2, 3));
    assert_eq!(
        c.decode_err(),
        ImageError::FieldLength {
            field: Field::BallTest,
            expected: 36,
            found: 32
        }
    );
    let mut c = two_partitions();
    c.ball_location[1] = 1;
    assert_eq!(
        c.decode_err(),
        ImageError::BallLocationOutOfRange { ball: 1, value: 1 }
    );
    let mut c = two_partitions();
    c.ball_partition[0] = 5;
    assert_eq!(
        c.decode_err(),
        ImageError::BallPartitionOutOfRange { ball: 0, value: 5 }
    );
    let mut c = two_partitions();
    c.ball_location.pop();
    assert_eq!(
        c.decode_err(),
        ImageError::FieldLength {
            field: Field::BallLocation,
            expected: 3,
            found: 2
        }
    );
    // A zero threshold is allowed (a single certified point), and so is −0.
    let mut c = two_partitions();
    c.ball_threshold[0] = 0.0;
    assert!(c.to_bytes().is_ok());
    c.ball_threshold[0] = -0.0;
    assert!(c.to_bytes().is_ok());
}

#[test]
fn rejects_counts_and_dimensions_outside_capacity() {
    let mut c = two_partitions();
    c.np = 0;
    c.gain.clear();
    c.offset.clear();
    assert_eq!(
        c.decode_err(),
        ImageError::DimOutOfRange {
            dim: Dim::Partitions,
            value: 0,
            min: 1,
            max: MAX_PARTITIONS as u32
        }
    );
    let mut c = two_partitions();
    c.np = MAX_PARTITIONS + 1;
    assert!(matches!(
        c.decode_err(),
        ImageError::DimOutOfRange {
            dim: Dim::Partitions,
            ..
        }
    ));
    let mut c = two_partitions();
    c.n_trajectories = 1;
    assert_eq!(
        c.decode_err(),
        ImageError::DimOutOfRange {
            dim: Dim::Trajectories,
            value: 1,
            min: 0,
            max: 0
        }
    );
    let mut c = two_partitions();
    c.counts = Some((MAX_TREE_NODES as u16 + 1, 2, 3));
    assert!(matches!(
        c.decode_err(),
        ImageError::DimOutOfRange {
            dim: Dim::TreeNodes,
            ..
        }
    ));
    let mut c = two_partitions();
    c.counts = Some((2, 0, 3));
    assert!(matches!(
        c.decode_err(),
        ImageError::DimOutOfRange {
            dim: Dim::Leaves,
            value: 0,
            ..
        }
    ));
    let mut c = two_partitions();
    c.counts = Some((2, 2, 0));
    assert!(matches!(
        c.decode_err(),
        ImageError::DimOutOfRange {
            dim: Dim::Balls,
            value: 0,
            ..
        }
    ));
    // Counts that disagree with the arrays: a field length error names the first array that disagrees.
    let mut c = two_partitions();
    c.counts = Some((3, 2, 3));
    assert_eq!(
        c.decode_err(),
        ImageError::FieldLength {
            field: Field::Node,
            expected: 48,
            found: 32
        }
    );
}

#[test]
fn rejects_bad_period_and_bad_P_in_pwa_mode_too() {
    let mut c = two_partitions();
    c.period = 0.0;
    assert_eq!(c.decode_err(), ImageError::BadPeriod);
    let mut c = two_partitions();
    c.P = vec![1.0, 2.0, 2.0, 1.0];
    assert_eq!(
        c.decode_err(),
        ImageError::NotPositiveDefinite { location: 0 }
    );
    let mut c = two_partitions();
    c.input_box = Some((vec![1.0], vec![0.0]));
    assert_eq!(c.decode_err(), ImageError::EmptyInputBox { input: 0 });
}

#[test]
fn rejects_a_factor_that_is_not_upper_triangular_with_positive_diagonal() {
    let mut c = two_partitions();
    c.R[2] = 0.5; // R[1,0]
    let e = c.decode_err();
    assert_eq!(
        e,
        ImageError::FactorNotUpperTriangular {
            location: 0,
            row: 1,
            col: 0
        }
    );
    assert_eq!(
        e.to_string(),
        "location 0: factor R is not upper triangular (R[1,0] != 0)"
    );
    // Above the diagonal anything finite is allowed.
    let mut c = two_partitions();
    c.R[1] = -3.0;
    assert!(c.to_bytes().is_ok());
    for bad in [0.0, -1.0, -0.0] {
        let mut c = two_partitions();
        c.R[3] = bad;
        let e = c.decode_err();
        assert_eq!(
            e,
            ImageError::FactorDiagonal {
                location: 0,
                row: 1
            }
        );
        assert_eq!(
            e.to_string(),
            "location 0: factor R has a non-positive diagonal entry R[1,1]"
        );
    }
    let mut c = two_partitions();
    c.R[1] = f32::INFINITY;
    assert_eq!(
        c.decode_err(),
        ImageError::NonFinite {
            field: Field::Factor,
            pos: Pos(0, 0, 1)
        }
    );
    let mut c = two_partitions();
    c.R.push(0.0);
    assert!(matches!(
        c.decode_err(),
        ImageError::FieldLength {
            field: Field::Factor,
            expected: 16,
            found: 20
        }
    ));
}

#[test]
fn shared_subtrees_are_allowed_and_counted_once_for_depth() {
    // Node 0 → node 1 both ways (a DAG); node 1 → leaves.
    let mut c = two_partitions();
    c.node_child = vec![1, 1, L0, L1];
    let img_bytes = c.to_bytes().unwrap();
    assert_eq!(decode(&img_bytes).unwrap().tree_depth(), 2);
}

#[test]
fn rejects_overlong_varints_and_trailing_bytes_in_pwa_payloads() {
    // The first payload field is K's byte string: length prefix 8 (0x08). Re-encode it as the overlong
    // varint 0x88 0x00: same content, non-canonical bytes.
    let b = two_partitions().to_bytes().unwrap();
    assert_eq!(b[32], 8);
    let mut x = b[..32].to_vec();
    x.extend_from_slice(&[0x88, 0x00]);
    x.extend_from_slice(&b[33..]);
    common::fix_header(&mut x);
    assert_eq!(decode(&x), Err(ImageError::NotCanonical));
    let mut x = b.clone();
    x.push(0);
    common::fix_header(&mut x);
    assert_eq!(decode(&x), Err(ImageError::TrailingBytes));
    let mut x = b[..b.len() - 1].to_vec();
    common::fix_header(&mut x);
    assert_eq!(decode(&x), Err(ImageError::Malformed));
}

#[test]
fn a_header_dimension_that_disagrees_with_the_payload_is_a_field_length_error() {
    let mut b = two_partitions().to_bytes().unwrap();
    b[8..10].copy_from_slice(&3u16.to_le_bytes()); // n = 3
    common::fix_header(&mut b);
    assert_eq!(
        decode(&b),
        Err(ImageError::FieldLength {
            field: Field::K,
            expected: 12,
            found: 8
        })
    );
    let mut b = two_partitions().to_bytes().unwrap();
    b[16..18].copy_from_slice(&3u16.to_le_bytes()); // 3 partitions
    common::fix_header(&mut b);
    assert_eq!(
        decode(&b),
        Err(ImageError::FieldLength {
            field: Field::LawGain,
            expected: 24,
            found: 16
        })
    );
}
