//! The PWA-feedback evaluator (Ch. 6, law (6.1)): the law per partition, the envelope test, no latch, bad
//! input; point location against a brute-force f64 reference that checks every root-to-leaf polytope of
//! random trees; the f32 law against f64 within the rounding bound; and the documented rounding bound of
//! the ball test.
#![allow(non_snake_case, clippy::needless_range_loop)]

use crate::common::{
    random_pwa, random_spd, two_partitions, FallbackC, PwaContent, PwaShape, L0, L1,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{MAX_N, MAX_TREE_DEPTH};
use shared_types::eval::{Controller, Input, Status};
use shared_types::image::decode;
use shared_types::pwa::{Child, Region, OUTSIDE};

fn with<R>(c: &PwaContent, f: impl FnOnce(Controller<'_>) -> R) -> R {
    let bytes = c.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    f(Controller::new(img))
}

#[test]
fn applies_the_law_of_the_partition_whose_ball_contains_the_state() {
    with(&two_partitions(), |mut ctl| {
        // Leaf 0, ball 0: u = −x₀ − 2x₁ + 0.5.
        assert_eq!(
            ctl.locate(&[-1.0, 0.5]),
            Some(Region::Inside {
                leaf: 0,
                partition: 0,
                ball: 0
            })
        );
        assert_eq!(ctl.step(&[-1.0, 0.5]).unwrap().as_slice(), &[0.5]);
        // Leaf 1, ball 2: u = −3x₀ − 1.
        assert_eq!(ctl.step(&[1.5, 0.5]).unwrap().as_slice(), &[-5.5]);
        // Leaf 0, not in ball 0 but in ball 1.
        assert_eq!(
            ctl.locate(&[-0.5, 1.5]),
            Some(Region::Inside {
                leaf: 0,
                partition: 0,
                ball: 1
            })
        );
        assert_eq!(ctl.step(&[-0.5, 1.5]).unwrap().as_slice(), &[-2.0]);
        assert_eq!(ctl.step_index(), 3);
        assert_eq!(ctl.last_input().as_slice(), &[-2.0]);
        // Feedback mode has no trajectory selection.
        assert_eq!(ctl.select(&[-1.0, 0.5]), None);
        assert_eq!(ctl.active_trajectory(), None);
    });
}

#[test]
fn outside_the_envelope_is_reported_for_that_step_only() {
    with(&two_partitions(), |mut ctl| {
        // The tree sends (−1, 2.5) to OUTSIDE.
        assert_eq!(ctl.locate(&[-1.0, 2.5]), Some(Region::OutsideTree));
        assert_eq!(ctl.step(&[-1.0, 2.5]), Err(Status::OutOfEnvelope));
        // (−3, 0) reaches leaf 0 but lies in none of its balls.
        assert_eq!(
            ctl.locate(&[-3.0, 0.0]),
            Some(Region::OutsideBalls {
                leaf: 0,
                partition: 0
            })
        );
        assert_eq!(ctl.step(&[-3.0, 0.0]), Err(Status::OutOfEnvelope));
        // (−0.1, −0.9) lies in ball 2 (partition 1), but the tree routes it to leaf 0, whose balls do not
        // contain it: ball 2 is not certified for partition 0's law, so no default applies.
        assert_eq!(
            ctl.locate(&[-0.1, -0.9]),
            Some(Region::OutsideBalls {
                leaf: 0,
                partition: 0
            })
        );
        assert_eq!(ctl.step_index(), 0);
        // No latch: back inside, the law applies again.
        assert_eq!(ctl.step(&[-1.0, 0.5]).unwrap().as_slice(), &[0.5]);
        assert_eq!(ctl.step(&[-3.0, 0.0]), Err(Status::OutOfEnvelope));
        assert_eq!(ctl.step(&[-1.0, 0.0]).unwrap().as_slice(), &[1.5]);
        assert_eq!(ctl.step_index(), 2);
    });
}

#[test]
fn hyperplane_and_ball_boundaries_are_inclusive() {
    with(&two_partitions(), |mut ctl| {
        // aᵀx = b goes left (leaf 0), and (0, 0) is on the boundary of ball 0: inside.
        assert_eq!(
            ctl.locate(&[0.0, 0.0]),
            Some(Region::Inside {
                leaf: 0,
                partition: 0,
                ball: 0
            })
        );
        assert_eq!(ctl.step(&[0.0, 0.0]).unwrap().as_slice(), &[0.5]);
        // Just right of the hyperplane: leaf 1.
        let eps = f32::from_bits(1); // smallest positive subnormal
        assert_eq!(
            ctl.locate(&[eps, 0.0]),
            Some(Region::Inside {
                leaf: 1,
                partition: 1,
                ball: 2
            })
        );
        // Just outside ball 0 on its far side.
        assert_eq!(
            ctl.locate(&[(-2.0f32).next_down(), 0.0]),
            Some(Region::OutsideBalls {
                leaf: 0,
                partition: 0
            })
        );
        assert!(matches!(
            ctl.locate(&[-2.0, 0.0]),
            Some(Region::Inside { ball: 0, .. })
        ));
    });
}

#[test]
fn bad_state_is_bad_frame_and_does_not_advance() {
    with(&two_partitions(), |mut ctl| {
        assert_eq!(ctl.step(&[0.0]), Err(Status::BadFrame));
        assert_eq!(ctl.step(&[0.0, 0.0, 0.0]), Err(Status::BadFrame));
        assert_eq!(ctl.step(&[f32::NAN, 0.0]), Err(Status::BadFrame));
        assert_eq!(ctl.step(&[0.0, f32::NEG_INFINITY]), Err(Status::BadFrame));
        assert_eq!(ctl.locate(&[0.0]), None);
        assert_eq!(ctl.locate(&[f32::NAN, 0.0]), None);
        assert_eq!(ctl.step_index(), 0);
    });
}

#[test]
fn overflowing_input_is_out_of_envelope() {
    let mut c = two_partitions();
    c.gain[2] = 3.0e38;
    c.ball_threshold[2] = 1.0e4;
    with(&c, |mut ctl| {
        assert_eq!(ctl.step(&[10.0, 0.0]), Err(Status::OutOfEnvelope));
        assert_eq!(ctl.step_index(), 0);
    });
}

#[test]
fn huge_states_are_routed_deterministically_and_never_accepted() {
    // a = (1e30, −1e30) overflows aᵀx to +inf − inf = NaN for x = (1e10, 1e10): the state goes right.
    let mut c = two_partitions();
    c.node_a[0] = 1.0e30;
    c.node_a[1] = -1.0e30;
    with(&c, |mut ctl| {
        assert_eq!(
            ctl.locate(&[1.0e10, 1.0e10]),
            Some(Region::OutsideBalls {
                leaf: 1,
                partition: 1
            })
        );
        assert_eq!(ctl.step(&[3.0e38, -3.0e38]), Err(Status::OutOfEnvelope));
    });
}

#[test]
fn fallback_applies_to_pwa_images() {
    let mut c = two_partitions();
    c.fallback = FallbackC::Linear {
        K: vec![1.0, -1.0],
        x_ref: vec![1.0, 2.0],
        u_ref: vec![0.125],
    };
    c.input_box = Some((vec![-2.0], vec![3.0]));
    with(&c, |ctl| {
        let l = Input::from_slice(&[7.0]).unwrap();
        assert_eq!(ctl.fallback(&[3.0, 2.0], &l).as_slice(), &[2.125]);
        assert_eq!(ctl.fallback(&[10.0, 2.0], &l).as_slice(), &[3.0]);
    });
}

#[test]
fn a_tree_without_nodes_is_leaf_zero() {
    let mut c = two_partitions();
    c.node_a.clear();
    c.node_b.clear();
    c.node_child.clear();
    c.depth = 0;
    c.leaf_partition = vec![1];
    c.leaf_balls = vec![vec![2]];
    with(&c, |mut ctl| {
        assert_eq!(ctl.step(&[1.0, 1.0]).unwrap().as_slice(), &[-4.0]);
        assert_eq!(
            ctl.locate(&[-1.0, 0.0]),
            Some(Region::OutsideBalls {
                leaf: 0,
                partition: 1
            })
        );
    });
}

#[test]
fn shared_subtree_routes_both_ways() {
    // Node 2 is reached from node 0 directly and through node 1.
    let mut c = two_partitions();
    c.node_a = vec![1.0, 0.0, 0.0, 1.0, 0.0, -1.0];
    c.node_b = vec![0.0, 2.0, 0.0];
    // 0: left → 1, right → 2;  1: left → 2, right → OUTSIDE;  2 (−x₁ ≤ 0, i.e. x₁ ≥ 0): leaf 0 / leaf 1.
    c.node_child = vec![1, 2, 2, OUTSIDE, L0, L1];
    c.depth = 3;
    c.leaf_partition = vec![0, 1];
    with(&c, |ctl| {
        assert_eq!(ctl.image().tree_depth(), 3);
        let leaf = |x: [f32; 2]| ctl.locate(&x).and_then(|r| r.leaf());
        assert_eq!(leaf([-1.0, 0.5]), Some(0)); // 0 → 1 → 2 → leaf 0
        assert_eq!(leaf([1.0, 0.5]), Some(0)); // 0 → 2 → leaf 0
        assert_eq!(leaf([1.0, -0.5]), Some(1)); // 0 → 2 → leaf 1
        assert_eq!(leaf([-1.0, -0.5]), Some(1)); // 0 → 1 → 2 → leaf 1
        assert_eq!(ctl.locate(&[-1.0, 3.0]), Some(Region::OutsideTree)); // 0 → 1 → OUTSIDE
        assert!(matches!(
            ctl.locate(&[-1.0, 0.5]),
            Some(Region::Inside {
                leaf: 0,
                ball: 0,
                ..
            })
        ));
    });
}

#[test]
fn the_deepest_path_is_walked_to_the_end() {
    // A chain of MAX_TREE_DEPTH nodes, node i: x₀ ≤ −i → node i+1 (the last: OUTSIDE), else leaf 0.
    let len = MAX_TREE_DEPTH;
    let mut c = two_partitions();
    c.node_a = (0..len).flat_map(|_| [1.0, 0.0]).collect();
    c.node_b = (0..len).map(|i| -(i as f32)).collect();
    c.node_child = (0..len)
        .flat_map(|i| {
            if i + 1 < len {
                [(i + 1) as u16, L0]
            } else {
                [OUTSIDE, L0]
            }
        })
        .collect();
    c.depth = len as u8;
    c.leaf_partition = vec![0];
    c.leaf_balls = vec![vec![0, 1]];
    let mut far = two_partitions().ball_centre;
    far[0] = -(len as f32) + 1.5; // ball 0 at x₀ = −22.5
    c.ball_centre = far;
    c.whiten();
    with(&c, |ctl| {
        assert_eq!(ctl.image().tree_depth(), MAX_TREE_DEPTH);
        // x₀ = −22.5 goes left at nodes 0..=22 and right at the last node: leaf 0, in ball 0.
        assert!(matches!(
            ctl.locate(&[-22.5, 0.0]),
            Some(Region::Inside { ball: 0, .. })
        ));
        // x₀ = −24 goes left at the last node: OUTSIDE.
        assert_eq!(ctl.locate(&[-24.0, 0.0]), Some(Region::OutsideTree));
    });
}

// ---- brute force ---------------------------------------------------------------------------------------

/// What the f64 reference says about x, with how close x is to each decision it depends on (relative
/// margins; small = near a boundary).
struct Reference {
    region: Region,
    /// Smallest relative margin |aᵀx − b| / (Σ|aᵢxᵢ| + |b|) over every hyperplane of every path.
    plane_margin: f64,
    /// Smallest relative margin |d² − ρ²| / (Σ_i (|e_i| + (|R̂||x|)_i + |ĉ_z,i|)² + ρ²) over the balls of the
    /// leaf reached, with e = R̂x − ĉ_z.
    ball_margin: f64,
}

fn dot(a: &[f32], x: &[f64]) -> (f64, f64) {
    let s: f64 = a.iter().zip(x).map(|(&a, &x)| a as f64 * x).sum();
    let abs: f64 = a.iter().zip(x).map(|(&a, &x)| (a as f64 * x).abs()).sum();
    (s, abs)
}

/// Checks every root-to-terminal path polytope {x : the path's half-spaces hold} in f64; exactly one
/// contains x (away from boundaries). Then the balls of that leaf in listing order.
fn reference(c: &PwaContent, paths: &[(Vec<(usize, bool)>, Child)], x: &[f64]) -> Reference {
    let n = c.n;
    let mut plane_margin = f64::INFINITY;
    let mut hits = Vec::new();
    for (path, terminal) in paths {
        let mut inside = true;
        for &(node, left) in path {
            let (s, abs) = dot(&c.node_a[node * n..(node + 1) * n], x);
            let b = c.node_b[node] as f64;
            plane_margin = plane_margin.min((s - b).abs() / (abs + b.abs() + 1e-300));
            if (s <= b) != left {
                inside = false;
            }
        }
        if inside {
            hits.push(*terminal);
        }
    }
    assert_eq!(hits.len(), 1, "path polytopes must partition the space");
    let mut ball_margin = f64::INFINITY;
    let region = match hits[0] {
        Child::Outside => Region::OutsideTree,
        Child::Node(_) => unreachable!(),
        Child::Leaf(l) => {
            let partition = c.leaf_partition[l as usize];
            let mut found = None;
            for &b in &c.leaf_balls[l as usize] {
                // The whitened test in f64: ‖R̂x − ĉ_z‖² ≤ ŝ.
                let bu = b as usize;
                let loc = c.ball_location[bu] as usize;
                let R = &c.R[loc * n * n..(loc + 1) * n * n];
                let (mut d2, mut abs) = (0.0, 0.0);
                for i in 0..n {
                    let (mut zi, mut zabs) = (0.0, 0.0);
                    for j in i..n {
                        zi += R[i * n + j] as f64 * x[j];
                        zabs += (R[i * n + j] as f64 * x[j]).abs();
                    }
                    let cz = c.ball_centre_z[bu * n + i] as f64;
                    let e = zi - cz;
                    d2 += e * e;
                    abs += (e.abs() + zabs + cz.abs()).powi(2);
                }
                let r2 = c.ball_threshold[bu] as f64;
                ball_margin = ball_margin.min((d2 - r2).abs() / (abs + r2 + 1e-300));
                if found.is_none() && d2 <= r2 {
                    found = Some(b);
                }
            }
            match found {
                Some(ball) => Region::Inside {
                    leaf: l,
                    partition,
                    ball,
                },
                None => Region::OutsideBalls { leaf: l, partition },
            }
        }
    };
    Reference {
        region,
        plane_margin,
        ball_margin,
    }
}

/// A random state: uniform in the box, or near a random ball centre.
fn random_state(rng: &mut ChaCha8Rng, c: &PwaContent, box_half: f32) -> Vec<f32> {
    let n = c.n;
    if rng.random_bool(0.5) {
        (0..n)
            .map(|_| rng.random_range(-box_half..box_half))
            .collect()
    } else {
        let b = rng.random_range(0..c.ball_threshold.len());
        (0..n)
            .map(|i| c.ball_centre[b * n + i] + rng.random_range(-1.0f32..1.0))
            .collect()
    }
}

#[test]
fn point_location_agrees_with_brute_force_on_random_trees() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x10CA7E);
    let shape = PwaShape::default();
    let tol = 1e-5;
    let (mut inside, mut outside_tree, mut outside_balls, mut near) = (0, 0, 0, 0);
    let mut points = 0;
    for _ in 0..400 {
        let c = random_pwa(&mut rng, shape);
        let paths = c.paths();
        let bytes = c.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        for _ in 0..100 {
            let x = random_state(&mut rng, &c, shape.box_half);
            let x64: Vec<f64> = x.iter().map(|&v| v as f64).collect();
            let got = img.locate(&x).unwrap();
            let want = reference(&c, &paths, &x64);
            points += 1;
            if got != want.region {
                assert!(
                    want.plane_margin <= tol || want.ball_margin <= tol,
                    "x = {x:?}: evaluator {got:?}, reference {:?} (margins {} {})",
                    want.region,
                    want.plane_margin,
                    want.ball_margin
                );
                near += 1;
                continue;
            }
            match got {
                Region::Inside { .. } => inside += 1,
                Region::OutsideTree => outside_tree += 1,
                Region::OutsideBalls { .. } => outside_balls += 1,
            }
        }
    }
    eprintln!(
        "{points} points: inside {inside}, outside tree {outside_tree}, outside balls {outside_balls}, \
         near-boundary disagreements {near}"
    );
    assert!(inside > 5000 && outside_tree > 2000 && outside_balls > 2000);
    assert!(near < 10, "{near} near-boundary disagreements");
}

#[test]
fn f32_law_matches_f64_reference_within_rounding_bound() {
    let mut rng = ChaCha8Rng::seed_from_u64(77);
    let u_round = f64::from(f32::EPSILON) / 2.0;
    let shape = PwaShape {
        max_n: MAX_N,
        max_m: 6,
        max_depth: 8,
        ..PwaShape::default()
    };
    let mut compared = 0;
    for _ in 0..300 {
        let c = random_pwa(&mut rng, shape);
        let bytes = c.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        let mut ctl = Controller::new(img);
        let (n, m) = (c.n, c.m);
        for _ in 0..60 {
            // Mostly just off a ball centre, so that most states are inside the envelope.
            let b = rng.random_range(0..c.ball_threshold.len());
            let x: Vec<f32> = (0..n)
                .map(|i| c.ball_centre[b * n + i] + rng.random_range(-0.2f32..0.2))
                .collect();
            let located = ctl.locate(&x).unwrap();
            let kappa = ctl.step_index();
            match (located, ctl.step(&x)) {
                (Region::Inside { partition, .. }, Ok(u)) => {
                    let j = partition as usize;
                    for r in 0..m {
                        let mut exact = c.offset[j * m + r] as f64;
                        let mut abs = exact.abs();
                        for i in 0..n {
                            let p = c.gain[(j * m + r) * n + i] as f64 * x[i] as f64;
                            exact += p;
                            abs += p.abs();
                        }
                        let k1 = (n + 1) as f64;
                        let gamma = k1 * u_round / (1.0 - k1 * u_round);
                        let err = (u.as_slice()[r] as f64 - exact).abs();
                        assert!(err <= gamma * abs + 1e-30, "err {err} > {}", gamma * abs);
                    }
                    assert_eq!(ctl.step_index(), kappa + 1);
                    compared += 1;
                }
                (Region::Inside { .. }, r) => panic!("inside but step gave {r:?}"),
                (_, r) => {
                    assert_eq!(r, Err(Status::OutOfEnvelope));
                    assert_eq!(ctl.step_index(), kappa);
                }
            }
        }
    }
    eprintln!("{compared} inputs compared");
    assert!(compared > 3000, "only {compared} inputs compared");
}

#[test]
fn ball_test_acceptance_respects_the_documented_rounding_bound() {
    // One leaf, one ball; states placed at relative distance 1 ± 1e-6 from the boundary of the whitened
    // ball ‖R̂x − ĉ_z‖² ≤ ŝ. An accepted state must satisfy steps 1–3 of `shared_types::pwa` ("Rounding of
    // the ball test") with the stored data (D = 0, e_c = 0): ‖R̂x̂ − ĉ_z‖ ≤ S(ŝ) + ‖γ_n|R̂||x̂|‖ + 2n^{3/2}η.
    let mut rng = ChaCha8Rng::seed_from_u64(4242);
    let u = f64::from(f32::EPSILON) / 2.0;
    let eta = 2f64.powi(-150);
    let (mut accepted, mut rejected) = (0, 0);
    for _ in 0..200 {
        let n = rng.random_range(1..=MAX_N);
        let P = random_spd(&mut rng, n);
        let scale: f32 = [1.0, 1e3, 1e-3][rng.random_range(0..3)];
        let centre: Vec<f32> = (0..n)
            .map(|_| rng.random_range(-5.0f32..5.0) * scale)
            .collect();
        let delta: f32 = rng.random_range(0.01..3.0) * scale;
        // The stored threshold as the host forms it from a radius: one f32 product.
        let threshold = delta * delta;
        let c = PwaContent {
            n,
            m: 1,
            nl: 1,
            np: 1,
            period: 0.1,
            K: vec![0.0; n],
            P: P.clone(),
            gain: vec![1.0; n],
            offset: vec![0.0],
            depth: 0,
            node_a: vec![],
            node_b: vec![],
            node_child: vec![],
            leaf_partition: vec![0],
            leaf_balls: vec![vec![0]],
            R: vec![],
            ball_centre: centre.clone(),
            ball_centre_z: vec![],
            ball_threshold: vec![threshold],
            ball_location: vec![0],
            ball_partition: vec![0],
            fallback: FallbackC::Zero,
            input_box: None,
            n_trajectories: 0,
            counts: None,
        }
        .whitened();
        let bytes = c.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        let R: Vec<f64> = c.R.iter().map(|&v| v as f64).collect();
        let cz: Vec<f64> = c.ball_centre_z.iter().map(|&v| v as f64).collect();
        // A direction v, scaled so that ‖R̂v‖ = √ŝ(1 ± 1e-6).
        let gn = n as f64 * u / (1.0 - n as f64 * u);
        let rho = (threshold as f64).sqrt();
        let S = ((threshold as f64 + (2 * n) as f64 * eta) / (1.0 - gn)).sqrt() / (1.0 - u);
        for _ in 0..50 {
            let dir: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let q: f64 = (0..n)
                .map(|i| (i..n).map(|j| R[i * n + j] * dir[j]).sum::<f64>().powi(2))
                .sum::<f64>()
                .sqrt();
            let t = rho * (1.0 + rng.random_range(-1e-6..1e-6)) / q;
            let x: Vec<f32> = (0..n)
                .map(|i| (centre[i] as f64 + t * dir[i]) as f32)
                .collect();
            if matches!(img.locate(&x), Some(Region::Inside { .. })) {
                accepted += 1;
                let (mut w2, mut g2) = (0.0, 0.0);
                for i in 0..n {
                    let zi: f64 = (i..n).map(|j| R[i * n + j] * x[j] as f64).sum();
                    let za: f64 = (i..n).map(|j| (R[i * n + j] * x[j] as f64).abs()).sum();
                    w2 += (zi - cz[i]).powi(2);
                    g2 += (gn * za).powi(2);
                }
                let bound = S + g2.sqrt() + 2.0 * (n as f64).powf(1.5) * eta;
                assert!(
                    w2.sqrt() <= bound,
                    "accepted with ‖R̂x̂ − ĉ_z‖ = {} > bound {bound}",
                    w2.sqrt()
                );
            } else {
                rejected += 1;
            }
        }
    }
    // States straddle the boundary: both outcomes must occur often.
    assert!(accepted > 2000 && rejected > 2000, "{accepted} {rejected}");
}
