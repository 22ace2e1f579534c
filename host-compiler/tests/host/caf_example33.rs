//! Example 3.3 (the linear affine planar vehicle, (3.12)–(3.15)) as the reference case: the continuous LMI
//! (3.8) reproduces the dissertation's K and P; the sampled loop gets a strict certificate whose claims hold
//! in simulation (ψ non-increasing (3.64), Theorem 3.21 under disturbances).
#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::caf::*;
use host_compiler::model::{simulate_closed_loop, ContinuousPlant};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// (3.13).
fn vehicle() -> ContinuousPlant {
    let A = Mat::from_fn(4, 4, |i, j| match (i, j) {
        (0, 2) | (1, 3) => 1.0,
        (2, 0) | (3, 1) => -1.0,
        (2, 2) | (3, 3) => 0.1,
        _ => 0.0,
    });
    let B = Mat::from_fn(4, 2, |i, j| if i == j + 2 { 1.0 } else { 0.0 });
    ContinuousPlant::new(A, B, vec![0.0, 0.0, 1.0, 1.0]).unwrap()
}

/// (3.14).
fn dissertation_K() -> Mat<f64> {
    Mat::from_fn(2, 4, |i, j| if j == i + 2 { -0.1 } else { 0.0 })
}

#[test]
fn dissertation_gain_and_identity_metric_satisfy_3_7_with_equality() {
    let p = vehicle();
    let K = dissertation_K();
    let At = &p.A + &p.B * &K;
    // (3.15): A + BK is the skew-symmetric rotation generator.
    for i in 0..4 {
        for j in 0..4 {
            assert!((At[(i, j)] + At[(j, i)]).abs() < 1e-15);
        }
    }
    let eye = Mat::from_fn(4, 4, |i, j| if i == j { 1.0 } else { 0.0 });
    let c = certify(
        TimeKind::Continuous,
        p.A.as_ref(),
        p.B.as_ref(),
        K.as_ref(),
        eye.as_ref(),
    )
    .unwrap();
    // Non-strict: ÃᵀP + PÃ = 0, so the validated margin is 0 up to the rounding guard (and never positive).
    assert!(c.margin <= 0.0 && c.margin > -1e-12, "margin {}", c.margin);
    assert!(c.guard < 1e-11, "guard {}", c.guard);
    assert!((c.lambda_min_P - 1.0).abs() <= c.guard * 1.001 && (c.condition - 1.0).abs() < 1e-10);
}

#[test]
fn continuous_lmi_3_8_reproduces_example_3_3() {
    let settings = CafSettings::builder().sigma(0.0).build().unwrap();
    for formulation in [Formulation::Reduced, Formulation::Joint] {
        let s = CafSettings {
            formulation,
            ..settings.clone()
        };
        let caf = synthesize_continuous(&vehicle(), &s)
            .unwrap()
            .solved()
            .expect("Example 3.3 is solvable");
        // P = I is the best-conditioned metric (condition number 1) ...
        assert!(
            caf.certificate.condition < 1.0 + 1e-5,
            "{formulation:?}: condition {}",
            caf.certificate.condition
        );
        for i in 0..4 {
            for j in 0..4 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!(
                    (caf.P[(i, j)] - want).abs() < 1e-5,
                    "{formulation:?}: P[{i},{j}] = {}",
                    caf.P[(i, j)]
                );
            }
        }
        // ... and for P = I the position columns of K must vanish (the positions are not damped at all).
        for i in 0..2 {
            for j in 0..2 {
                assert!(
                    caf.K[(i, j)].abs() < 1e-4,
                    "{formulation:?}: K[{i},{j}] = {}",
                    caf.K[(i, j)]
                );
            }
        }
        if formulation == Formulation::Reduced {
            // The smallest gain with ÃᵀP + PÃ ⪯ 0 for P = I is exactly (3.14).
            let want = dissertation_K();
            for i in 0..2 {
                for j in 0..4 {
                    assert!(
                        (caf.K[(i, j)] - want[(i, j)]).abs() < 1e-4,
                        "K[{i},{j}] = {} vs {}",
                        caf.K[(i, j)],
                        want[(i, j)]
                    );
                }
            }
        } else {
            // Any feasible gain damps the velocities at least as much as (3.14).
            assert!(caf.K[(0, 2)] <= -0.1 + 1e-5 && caf.K[(1, 3)] <= -0.1 + 1e-5);
        }
    }
}

#[test]
fn continuous_margin_is_strict_and_costs_conditioning() {
    let s = CafSettings::builder().sigma(0.2).build().unwrap();
    let caf = synthesize_continuous(&vehicle(), &s)
        .unwrap()
        .solved()
        .unwrap();
    assert!(caf.certificate.margin >= 0.2);
    assert!(caf.certificate.lambda_min_P >= 1.0);
    // With positions undamped by any P = I design, a strict margin needs an anisotropic metric.
    assert!(caf.certificate.condition > 1.01);
    // Brute force: xᵀ(ÃᵀP + PÃ)x ≤ −σ‖x‖² on random directions.
    let At = caf.A_cl();
    let M = At.transpose() * &caf.P + &caf.P * &At;
    let mut r = ChaCha8Rng::seed_from_u64(33);
    for _ in 0..1000 {
        let x: Vec<f64> = (0..4).map(|_| r.random_range(-1.0..1.0)).collect();
        let q: f64 = (0..4)
            .map(|i| x[i] * (0..4).map(|j| M[(i, j)] * x[j]).sum::<f64>())
            .sum();
        let nx: f64 = x.iter().map(|v| v * v).sum();
        assert!(q <= -0.2 * nx * (1.0 - 1e-12));
    }
}

#[test]
fn sampled_vehicle_strict_certificate_holds_in_simulation() {
    let h = 0.05;
    let d = vehicle().zoh(h).unwrap();
    let sigma = 0.05;
    let s = CafSettings::builder().sigma(sigma).build().unwrap();
    let caf = synthesize_discrete(&d, &s)
        .unwrap()
        .solved()
        .expect("the sampled vehicle is stabilizable");
    assert!(caf.certificate.margin >= sigma && caf.certificate.lambda_min_P >= 1.0);
    // (3.64): two runs under the same reference input never get further apart in ψ.
    let mut r = ChaCha8Rng::seed_from_u64(34);
    let v: Vec<Vec<f64>> = (0..200)
        .map(|_| vec![r.random_range(-1.0..1.0), r.random_range(-1.0..1.0)])
        .collect();
    let x0 = vec![0.0, 0.0, 0.0, 1.0];
    let x1 = vec![0.15, -0.1, 0.05, 1.0];
    let a = simulate_closed_loop(&d, caf.K.as_ref(), &x0, &v, None).unwrap();
    let b = simulate_closed_loop(&d, caf.K.as_ref(), &x1, &v, None).unwrap();
    let mut prev = caf.psi(&a.x[0], &b.x[0]);
    for k in 1..=200 {
        let now = caf.psi(&a.x[k], &b.x[k]);
        // Strict: at least the certified contraction factor per step.
        assert!(
            now <= caf.certificate.contraction * prev * (1.0 + 1e-12) + 1e-15,
            "step {k}: {now} > {prev}"
        );
        prev = now;
    }
    // Theorem 3.21: with ‖ε‖₂ ≤ δ the disturbed run stays within max(r0, r_crit) of the undisturbed one.
    let delta = 1e-3;
    let rc = caf.r_crit(delta).unwrap();
    assert!(rc.r_crit > 0.0 && rc.r_crit.is_finite());
    for trial in 0..20 {
        let eps: Vec<Vec<f64>> = (0..200)
            .map(|_| {
                let t: f64 = r.random_range(0.0..std::f64::consts::TAU);
                vec![delta * t.cos(), delta * t.sin()]
            })
            .collect();
        let r0 = if trial % 2 == 0 { 0.0 } else { 2.0 * rc.r_crit };
        let start = if r0 == 0.0 {
            x0.clone()
        } else {
            vec![x0[0] + r0 / caf.P[(0, 0)].sqrt(), x0[1], x0[2], x0[3]]
        };
        let dist = simulate_closed_loop(&d, caf.K.as_ref(), &start, &v, Some(&eps)).unwrap();
        let bound = rc.invariant_radius(caf.psi(&start, &a.x[0]));
        for k in 0..=200 {
            assert!(
                caf.psi(&dist.x[k], &a.x[k]) <= bound * (1.0 + 1e-9),
                "trial {trial} step {k}"
            );
        }
    }
}

#[test]
fn reduced_and_joint_give_the_same_metric() {
    let d = vehicle().zoh(0.1).unwrap();
    let base = CafSettings::builder().sigma(0.02).build().unwrap();
    let red = synthesize_discrete(&d, &base).unwrap().solved().unwrap();
    let joint = synthesize_discrete(
        &d,
        &CafSettings {
            formulation: Formulation::Joint,
            ..base
        },
    )
    .unwrap()
    .solved()
    .unwrap();
    let (a, b) = (red.certificate.lambda_max_P, joint.certificate.lambda_max_P);
    assert!(
        (a - b).abs() <= 1e-4 * a,
        "λ_max(P): reduced {a}, joint {b}"
    );
    assert!(joint.certificate.margin >= 0.02);
}
