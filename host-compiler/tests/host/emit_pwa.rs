//! Host emission of PWA-feedback images (Ch. 6): PwaImageBuilder → bytes → decode → PwaImageBuilder round
//! trips, the law `K_j = K + θ_j` through the shared evaluator, every refusal with its message, and
//! `inspect` on PWA images.
#![allow(non_snake_case, clippy::needless_range_loop)]

use host_compiler::cli::inspect::render;
use host_compiler::emit::{
    CertifiedBall, Child, EmitError, FallbackLaw, ImageBuilder, PwaImageBuilder, PwaLaw, PwaLeaf,
    TrajectoryEntry, TreeNode,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{MAX_LEAF_BALLS, MAX_TREE_DEPTH};
use shared_types::eval::{Controller, Status};
use shared_types::image::{decode, ImageError, Mode};
use shared_types::pwa::Region;

/// n = 2, m = 1, one location (K = [−1, −1], P = I), two partitions:
/// * law 0: θ_0 = [0, −1], θ0 = 0.5 → K_0 = [−1, −2]; law 1: θ_1 = [−2, 1], θ0 = −1 → K_1 = [−3, 0];
/// * node 0: x₀ ≤ 0 → node 1, else leaf 1; node 1: x₁ ≤ 2 → leaf 0, else OUTSIDE;
/// * balls 0 (−1, 0) δ 1 and 1 (−0.5, 1) δ 0.75 for partition 0 (leaf 0); ball 2 (1, 0) δ 1.5 for
///   partition 1 (leaf 1).
fn builder() -> PwaImageBuilder {
    let K = vec![-1.0, -1.0];
    let mut b = PwaImageBuilder::new(2, 1, 0.05);
    b.add_location(K.clone(), vec![1.0, 0.0, 0.0, 1.0]);
    b.add_law(PwaLaw::from_theta(&K, &[0.0, -1.0], vec![0.5]).unwrap());
    b.add_law(PwaLaw::from_theta(&K, &[-2.0, 1.0], vec![-1.0]).unwrap());
    b.add_node(TreeNode {
        a: vec![1.0, 0.0],
        b: 0.0,
        left: Child::Node(1),
        right: Child::Leaf(1),
    });
    b.add_node(TreeNode {
        a: vec![0.0, 1.0],
        b: 2.0,
        left: Child::Leaf(0),
        right: Child::Outside,
    });
    b.add_leaf(PwaLeaf {
        partition: 0,
        balls: vec![0, 1],
    });
    b.add_leaf(PwaLeaf {
        partition: 1,
        balls: vec![2],
    });
    // Radii 1, 0.75, 1.5: thresholds (squared radii) 1, 0.5625, 2.25.
    for (centre, threshold, partition) in [
        (vec![-1.0, 0.0], 1.0, 0),
        (vec![-0.5, 1.0], 0.5625, 0),
        (vec![1.0, 0.0], 2.25, 1),
    ] {
        b.add_ball(CertifiedBall {
            centre,
            threshold,
            location: 0,
            partition,
        });
    }
    b.fallback = FallbackLaw::Linear {
        K: vec![-0.5, -0.5],
        x_ref: vec![0.0, 0.0],
        u_ref: vec![0.0],
    };
    b.input_box = Some((vec![-2.0], vec![2.0]));
    b
}

#[test]
fn round_trip_through_bytes_is_exact_and_canonical() {
    let b = builder();
    assert_eq!(b.laws[0].gain, vec![-1.0, -2.0]);
    assert_eq!(b.tree_depth().unwrap(), 2);
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert_eq!(img.mode(), Mode::PwaFeedback);
    assert_eq!(img.tree_depth(), 2);
    let back = PwaImageBuilder::from_image(&img).unwrap();
    let mut expect = b.clone();
    expect.period = 0.05f32 as f64;
    assert_eq!(back, expect);
    assert_eq!(back.to_bytes().unwrap(), bytes);
    // A feedforward image does not read back as a PWA builder.
    let mut ff = ImageBuilder::new(1, 1, 0.1);
    ff.add_location(vec![-1.0], vec![1.0]);
    ff.add_trajectory(TrajectoryEntry {
        x0: vec![0.0],
        delta: 1.0,
        v: vec![0.0],
        location: vec![0],
    });
    let ff_bytes = ff.to_bytes().unwrap();
    assert_eq!(
        PwaImageBuilder::from_image(&decode(&ff_bytes).unwrap()),
        None
    );
}

#[test]
fn emitted_laws_run_in_the_shared_evaluator() {
    let bytes = builder().to_bytes().unwrap();
    let mut ctl = Controller::new(decode(&bytes).unwrap());
    // Partition 0: u = −x₀ − 2x₁ + 0.5.
    assert_eq!(ctl.step(&[-1.0, 0.5]).unwrap().as_slice(), &[0.5]);
    // Partition 1: u = −3x₀ − 1.
    assert_eq!(ctl.step(&[1.5, 0.5]).unwrap().as_slice(), &[-5.5]);
    // Outside the tree, then outside the balls: out of envelope, no latch.
    assert_eq!(ctl.step(&[-1.0, 2.5]), Err(Status::OutOfEnvelope));
    assert_eq!(ctl.step(&[-3.0, 0.0]), Err(Status::OutOfEnvelope));
    assert_eq!(ctl.step(&[-0.5, 1.5]).unwrap().as_slice(), &[-2.0]);
    assert_eq!(ctl.step_index(), 3);
}

#[test]
fn ball_threshold_is_rounded_down_never_up() {
    let mut b = builder();
    b.balls[0].threshold = 0.1;
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    assert!((img.ball_threshold(0) as f64) <= 0.1);
    assert_eq!(img.ball_threshold(0), 0.1f32.next_down());
    assert_eq!(img.ball_threshold(1), 0.5625);
    // The whitened centre and the threshold sit in one record; the accessors read their own parts.
    assert_eq!(img.ball_centre_z(1, 0), -0.5);
    assert_eq!(img.ball_centre_z(1, 1), 1.0);
    assert_eq!(img.ball_threshold(3), 0.0);
    assert_eq!(img.ball_centre_z(3, 0), 0.0);
}

/// A random valid builder: a random tree in preorder, random laws around K, leaves listing balls of
/// their own partition.
fn random_builder(rng: &mut ChaCha8Rng) -> PwaImageBuilder {
    let n = rng.random_range(1..=12);
    let m = rng.random_range(1..=6);
    let mut b = PwaImageBuilder::new(n, m, rng.random_range(0.001..0.5));
    let K: Vec<f64> = (0..m * n).map(|_| rng.random_range(-5.0..5.0)).collect();
    let mut P = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..i {
            let x: f64 = rng.random_range(-0.1..0.1);
            P[i * n + j] = x;
            P[j * n + i] = x;
        }
        P[i * n + i] = 1.0 + n as f64 * 0.1 + rng.random_range(0.0..1.0);
    }
    b.add_location(K.clone(), P);
    let np = rng.random_range(1..=5);
    for _ in 0..np {
        let theta: Vec<f64> = (0..m * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let theta0: Vec<f64> = (0..m).map(|_| rng.random_range(-3.0..3.0)).collect();
        b.add_law(PwaLaw::from_theta(&K, &theta, theta0).unwrap());
    }
    fn grow(b: &mut PwaImageBuilder, rng: &mut ChaCha8Rng, level: usize, n: usize) -> Child {
        if level > 0 && (level >= 6 || b.nodes.len() >= 30 || rng.random_bool(0.4)) {
            if rng.random_bool(0.15) {
                return Child::Outside;
            }
            let partition = rng.random_range(0..b.laws.len());
            let mut balls = Vec::new();
            for _ in 0..rng.random_range(1..=4) {
                balls.push(b.add_ball(CertifiedBall {
                    centre: (0..n).map(|_| rng.random_range(-3.0..3.0)).collect(),
                    threshold: rng.random_range(0.0..4.0),
                    location: 0,
                    partition,
                }));
            }
            return Child::Leaf(b.add_leaf(PwaLeaf { partition, balls }) as u16);
        }
        let me = b.add_node(TreeNode {
            a: (0..n).map(|_| rng.random_range(0.1..1.0)).collect(),
            b: rng.random_range(-2.0..2.0),
            left: Child::Outside,
            right: Child::Outside,
        });
        let l = grow(b, rng, level + 1, n);
        let r = grow(b, rng, level + 1, n);
        b.nodes[me].left = l;
        b.nodes[me].right = r;
        Child::Node(me as u16)
    }
    grow(&mut b, rng, 0, n);
    if b.leaves.is_empty() {
        let c = b.add_ball(CertifiedBall {
            centre: vec![0.0; n],
            threshold: 1.0,
            location: 0,
            partition: 0,
        });
        b.add_leaf(PwaLeaf {
            partition: 0,
            balls: vec![c],
        });
        b.nodes[0].left = Child::Leaf(0);
    }
    b
}

#[test]
fn random_builders_round_trip_and_evaluate_like_f64() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x9A);
    let u_round = f64::from(f32::EPSILON) / 2.0;
    let mut inside = 0;
    for _ in 0..100 {
        let b = random_builder(&mut rng);
        let bytes = b.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        assert_eq!(img.tree_depth(), b.tree_depth().unwrap());
        let back = PwaImageBuilder::from_image(&img).unwrap();
        for (l0, l1) in b.laws.iter().zip(&back.laws) {
            for (x, y) in l0
                .gain
                .iter()
                .zip(&l1.gain)
                .chain(l0.offset.iter().zip(&l1.offset))
            {
                assert_eq!(*y, *x as f32 as f64);
            }
        }
        for (b0, b1) in b.balls.iter().zip(&back.balls) {
            assert!(b1.threshold <= b0.threshold);
            assert!(b0.threshold - b1.threshold <= b0.threshold * f64::from(f32::EPSILON));
        }
        assert_eq!(back.leaves, b.leaves);
        assert_eq!(back.to_bytes().unwrap(), bytes);

        // The f32 law against f64 on the stored values, at states near ball centres.
        let (n, m) = (b.n, b.m);
        let mut ctl = Controller::new(img);
        for _ in 0..20 {
            let c = &back.balls[rng.random_range(0..back.balls.len())].centre;
            let x: Vec<f32> = c
                .iter()
                .map(|&v| (v + rng.random_range(-0.2..0.2)) as f32)
                .collect();
            let Some(Region::Inside { partition, .. }) = ctl.locate(&x) else {
                continue;
            };
            let u = ctl.step(&x).unwrap();
            let law = &back.laws[partition as usize];
            for r in 0..m {
                let mut exact = law.offset[r];
                let mut abs = exact.abs();
                for i in 0..n {
                    let p = law.gain[r * n + i] * x[i] as f64;
                    exact += p;
                    abs += p.abs();
                }
                let k1 = (n + 1) as f64;
                let gamma = k1 * u_round / (1.0 - k1 * u_round);
                assert!((u.as_slice()[r] as f64 - exact).abs() <= gamma * abs + 1e-30);
            }
            inside += 1;
        }
    }
    assert!(inside > 300, "only {inside} states inside");
}

fn err(b: &PwaImageBuilder) -> String {
    b.to_bytes().expect_err("should be refused").to_string()
}

#[test]
fn refusals_say_what_is_wrong() {
    let mut b = builder();
    b.nodes[1].left = Child::Node(0);
    assert_eq!(
        err(&b),
        "tree node 1: left child node 0 does not come after its parent (children must have larger indices)"
    );

    let mut b = builder();
    b.nodes[0].left = Child::Node(5);
    assert_eq!(err(&b), "tree node 0: left child node 5 does not exist");

    let mut b = builder();
    b.nodes[1].right = Child::Leaf(2);
    assert_eq!(err(&b), "tree node 1: right child leaf 2 does not exist");

    // A mixed leaf (balls of several partitions) is valid: the law of the containing ball applies.
    let mut b = builder();
    b.leaves[1].balls = vec![2, 0];
    assert!(b.to_bytes().is_ok());

    let mut b = builder();
    b.leaves[0].balls.clear();
    assert_eq!(
        err(&b),
        "balls of one leaf is 0, allowed 1..=64 (image capacity)"
    );

    let mut b = builder();
    b.leaves[0].balls = vec![0; MAX_LEAF_BALLS + 1];
    assert_eq!(
        err(&b),
        "balls of one leaf is 65, allowed 1..=64 (image capacity)"
    );

    let mut b = builder();
    b.leaves[0].balls = vec![7];
    assert_eq!(err(&b), "leaf 0: ball 7 does not exist");

    let mut b = builder();
    b.leaves[0].partition = 2;
    assert_eq!(err(&b), "leaf 0: partition 2 does not exist");

    let mut b = builder();
    b.balls[1].location = 1;
    assert_eq!(err(&b), "ball 1: location 1 does not exist");

    let mut b = builder();
    b.balls[1].threshold = -0.5;
    assert_eq!(err(&b), "ball 1: threshold is negative");

    let mut b = builder();
    b.balls[2].centre[1] = f64::NAN;
    assert_eq!(err(&b), "ball 2: centre[1] is not finite (NaN)");

    let mut b = builder();
    b.laws[1].gain[0] = 1e39;
    assert_eq!(
        err(&b),
        "partition 1: K_j[0] = 1e39 is outside the f32 range"
    );

    let mut b = builder();
    b.laws[0].offset.push(0.0);
    assert_eq!(err(&b), "partition 0: theta0_j: expected 1 values, found 2");

    let mut b = builder();
    b.laws.clear();
    assert_eq!(
        err(&b),
        "number of partitions is 0, allowed 1..=256 (image capacity)"
    );

    assert!(matches!(
        PwaLaw::from_theta(&[1.0, 2.0], &[1.0], vec![0.0]),
        Err(EmitError::Shape { .. })
    ));

    // A chain deeper than the capacity.
    let mut b = builder();
    b.nodes.clear();
    for i in 0..=MAX_TREE_DEPTH {
        b.add_node(TreeNode {
            a: vec![1.0, 0.0],
            b: -(i as f64),
            left: if i < MAX_TREE_DEPTH {
                Child::Node(i as u16 + 1)
            } else {
                Child::Leaf(1)
            },
            right: Child::Leaf(0),
        });
    }
    assert_eq!(err(&b), "tree depth is 25, allowed 0..=24 (image capacity)");
    b.nodes.pop();
    b.nodes.last_mut().unwrap().left = Child::Leaf(1);
    assert_eq!(
        decode(&b.to_bytes().unwrap()).unwrap().tree_depth(),
        MAX_TREE_DEPTH
    );

    // What only the shared validation sees comes back as the decoder's error.
    let mut b = builder();
    b.add_node(TreeNode {
        a: vec![1.0, 1.0],
        b: 0.0,
        left: Child::Leaf(0),
        right: Child::Leaf(1),
    });
    assert!(matches!(
        b.to_bytes(),
        Err(EmitError::Rejected(ImageError::UnreachableNode { node: 2 }))
    ));
    assert_eq!(
        err(&b),
        "image validation failed: tree node 2 is unreachable from the root"
    );
    let mut b = builder();
    b.nodes[1].a = vec![0.0, 0.0];
    assert_eq!(
        err(&b),
        "image validation failed: tree node 1: hyperplane normal is zero"
    );
    let mut b = builder();
    b.nodes[1].left = Child::Outside;
    assert_eq!(
        err(&b),
        "image validation failed: leaf 0 is not referenced by the tree"
    );
}

#[test]
fn write_creates_the_file_inspect_reads() {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("emit_pwa_example.img");
    let bytes = builder().write(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    assert!(render(&bytes, "p.img", false).is_ok());
}

#[test]
fn inspect_json_contains_the_pwa_content() {
    let bytes = builder().to_bytes().unwrap();
    let out = render(&bytes, "p.img", true).unwrap();
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j["header"]["mode"], "pwa_feedback");
    assert_eq!(j["header"]["mode_value"], 2);
    assert_eq!(j["header"]["partitions"], 2);
    assert_eq!(j["header"]["trajectories"], 0);
    assert!(j.get("terminal").is_none());
    let p = &j["pwa"];
    assert_eq!(p["tree_depth"], 2);
    assert_eq!(p["nodes"], 2);
    assert_eq!(p["leaves"], 2);
    assert_eq!(p["balls"], 3);
    assert_eq!(p["ball_refs"], 3);
    assert_eq!(p["max_leaf_balls"], 2);
    // depth·n + (one whitening n(n+1)/2 + max_leaf_balls·n) + m·n = 4 + (3 + 4) + 2.
    assert_eq!(p["worst_case_muladds"], 13);
    assert_eq!(p["factors"][0], serde_json::json!([[1.0, 0.0], [0.0, 1.0]]));
    assert_eq!(
        p["ball_table"][2]["centre_z"],
        serde_json::json!([1.0, 0.0])
    );
    assert_eq!(p["laws"][0]["K"], serde_json::json!([[-1.0, -2.0]]));
    assert_eq!(p["laws"][0]["theta"], serde_json::json!([[0.0, -1.0]]));
    assert_eq!(p["laws"][1]["theta0"], serde_json::json!([-1.0]));
    assert_eq!(p["tree"][0]["left"], serde_json::json!({"node": 1}));
    assert_eq!(p["tree"][0]["right"], serde_json::json!({"leaf": 1}));
    assert_eq!(p["tree"][1]["right"], "outside");
    assert_eq!(p["tree"][1]["a"], serde_json::json!([0.0, 1.0]));
    assert_eq!(p["leaf_table"][0]["balls"], serde_json::json!([0, 1]));
    assert_eq!(p["ball_table"][2]["centre"], serde_json::json!([1.0, 0.0]));
    assert_eq!(p["ball_table"][2]["partition"], 1);
    assert_eq!(p["ball_table"][2]["threshold"], 2.25);
    assert_eq!(
        p["ball_table"][1]["centre_z"],
        serde_json::json!([-0.5, 1.0])
    );

    let text = render(&bytes, "p.img", false).unwrap();
    for line in [
        "mode: pwa_feedback (2), sample period 0.05 s",
        "n = 2, m = 1, locations = 1, partitions = 2",
        "tree: 2 nodes, depth 2 (worst case), 2 leaves; 3 certified balls (3 references, at most 2 per leaf)",
        "worst case per step: 2 hyperplane tests, 2 ball tests, 13 multiply-adds",
        "partition 1: u = K_j x + theta0_j, theta0_j = [-1]",
        "  K_j[0] = [-3, 0]",
        "  theta_j[0] = [-2, 1]",
        "  node 0: a = [1, 0], b = 0 -> left node 1, right leaf 1",
        "  node 1: a = [0, 1], b = 2 -> left leaf 0, right OUTSIDE",
        "leaf 0: partition 0, balls [0, 1]",
        "ball 1: centre [-0.5, 1], threshold 0.5625, location 0, partition 0",
    ] {
        assert!(text.contains(line), "missing {line:?} in\n{text}");
    }
    // No terminal law section; the after-Goal line says there is none.
    assert!(!text.contains("terminal law (section 11)"), "{text}");
    assert!(text.contains("after Goal: no terminal law"), "{text}");

    // A feedforward image's JSON has no PWA section.
    let mut ff = ImageBuilder::new(1, 1, 0.1);
    ff.add_location(vec![-1.0], vec![1.0]);
    ff.add_trajectory(TrajectoryEntry {
        x0: vec![0.0],
        delta: 1.0,
        v: vec![0.0],
        location: vec![0],
    });
    let out = render(&ff.to_bytes().unwrap(), "f.img", true).unwrap();
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(j.get("pwa").is_none());
    assert_eq!(j["terminal"], "hold_last");
}

#[test]
fn inspect_summarises_large_pwa_images() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let b = loop {
        let b = random_builder(&mut rng);
        if b.nodes.len() > 10 && b.balls.len() > 10 {
            break b;
        }
    };
    let bytes = b.to_bytes().unwrap();
    let text = render(&bytes, "big.img", false).unwrap();
    assert!(
        text.contains(&format!(
            "  ... {} more nodes (all with --json)",
            b.nodes.len() - 8
        )),
        "{text}"
    );
    assert!(text.contains(&format!(
        "  ... {} more balls (all with --json)",
        b.balls.len() - 8
    )));
}
