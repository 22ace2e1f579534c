//! The certification's bounds hold for the code that runs: the f32 evaluator's error bound, the f32 ball
//! selection's radius, and the inter-sample excursion bound — each checked against the real thing.

#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::certify::{evaluator_error_bound, selection_radius, Loop, LoopConstants};
use host_compiler::emit::{ImageBuilder, TrajectoryEntry};
use host_compiler::linalg::{mat_vec, p_norm};
use host_compiler::model::LinearAffine;
use host_compiler::property::{InputBound, ReachAvoid};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::eval::Controller;

fn f32r(x: f64) -> f64 {
    x as f32 as f64
}

/// A random symmetric positive definite matrix with condition number up to ~`cond`.
fn random_pd(n: usize, cond: f64, rng: &mut ChaCha8Rng) -> Mat<f64> {
    let M = Mat::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
    let qr = M.qr();
    let Q = qr.compute_Q();
    let d: Vec<f64> = (0..n)
        .map(|i| 1.0 + (cond - 1.0) * i as f64 / (n.max(2) - 1) as f64)
        .collect();
    let P = Mat::from_fn(n, n, |i, j| {
        (0..n).map(|k| Q[(i, k)] * d[k] * Q[(j, k)]).sum::<f64>()
    });
    // Exactly symmetric after rounding to f32 (the image requires it).
    Mat::from_fn(n, n, |i, j| {
        f32r(if i <= j { P[(i, j)] } else { P[(j, i)] })
    })
}

#[test]
fn f32_evaluator_stays_within_the_rounding_bound() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut worst_ratio: f64 = 0.0;
    for trial in 0..300 {
        let n = 1 + trial % 8;
        let m = 1 + trial % 3;
        let K: Vec<f64> = (0..m * n)
            .map(|_| f32r(rng.random_range(-50.0..50.0)))
            .collect();
        let v: Vec<f64> = (0..m)
            .map(|_| f32r(rng.random_range(-10.0..10.0)))
            .collect();
        let mut b = ImageBuilder::new(n, m, 0.01);
        let I: Vec<f64> = (0..n * n)
            .map(|k| if k % (n + 1) == 0 { 1.0 } else { 0.0 })
            .collect();
        b.add_location(K.clone(), I);
        b.add_trajectory(TrajectoryEntry {
            x0: vec![0.0; n],
            delta: 1e6,
            v: v.clone(),
            location: vec![0],
        });
        let bytes = b.to_bytes().unwrap();
        let img = shared_types::image::decode(&bytes).unwrap();
        let Km = Mat::from_fn(m, n, |i, j| K[i * n + j]);
        for _ in 0..20 {
            let scale = 10f64.powf(rng.random_range(-3.0..3.0));
            let x: Vec<f64> = (0..n)
                .map(|_| rng.random_range(-1.0..1.0) * scale)
                .collect();
            let xf: Vec<f32> = x.iter().map(|&a| a as f32).collect();
            let mut ctl = Controller::new(img);
            let u = ctl.step(&xf).unwrap();
            let exact: Vec<f64> = (0..m)
                .map(|i| (0..n).map(|j| K[i * n + j] * x[j]).sum::<f64>() + v[i])
                .collect();
            let X: Vec<f64> = x.iter().map(|a| a.abs()).collect();
            let bound = evaluator_error_bound(Km.as_ref(), &v, &X);
            for i in 0..m {
                let err = (u.as_slice()[i] as f64 - exact[i]).abs();
                assert!(
                    err <= bound[i],
                    "trial {trial}: |error| {err:e} exceeds the bound {:e}",
                    bound[i]
                );
                if bound[i] > 0.0 {
                    worst_ratio = worst_ratio.max(err / bound[i]);
                }
            }
        }
    }
    // The bound is not vacuous: some errors come within a factor 100 of it.
    assert!(
        worst_ratio > 0.01,
        "bound is loose by more than 100x everywhere: {worst_ratio}"
    );
}

#[test]
fn f32_selection_accepts_only_states_in_the_certified_ball() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let mut accepted_near = 0;
    for trial in 0..200 {
        let n = 2 + trial % 6;
        let P = random_pd(n, 1.0 + 50.0 * rng.random::<f64>(), &mut rng);
        let c: Vec<f64> = (0..n).map(|_| f32r(rng.random_range(-3.0..3.0))).collect();
        let delta = rng.random_range(0.01..1.0);
        let stored = selection_radius(P.as_ref(), &c, delta);
        assert!(stored > 0.0 && (stored as f64) < delta);
        let mut b = ImageBuilder::new(n, 1, 0.01);
        b.add_location(
            vec![0.0; n],
            host_compiler::linalg::to_row_major(P.as_ref()),
        );
        b.add_trajectory(TrajectoryEntry {
            x0: c.clone(),
            delta: stored as f64,
            v: vec![0.0],
            location: vec![0],
        });
        let bytes = b.to_bytes().unwrap();
        let ctl = Controller::new(shared_types::image::decode(&bytes).unwrap());
        let roots = host_compiler::linalg::PdRoots::new(P.as_ref()).unwrap();
        for _ in 0..200 {
            // Points on shells just inside and just outside the stored radius.
            let w: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let wn = w.iter().map(|a| a * a).sum::<f64>().sqrt();
            let e = mat_vec(roots.inv_sqrt.as_ref(), &w);
            let r = stored as f64 * (1.0 + rng.random_range(-1e-6..1e-6));
            let x: Vec<f64> = (0..n).map(|i| c[i] + r * e[i] / wn).collect();
            let xf: Vec<f32> = x.iter().map(|&a| a as f32).collect();
            if ctl.select(&xf).is_some() {
                accepted_near += 1;
                let d = p_norm(P.as_ref(), &(0..n).map(|i| x[i] - c[i]).collect::<Vec<_>>());
                assert!(
                    d <= delta,
                    "trial {trial}: accepted a state at P-distance {d} > certified {delta}"
                );
            }
        }
    }
    assert!(
        accepted_near > 1000,
        "the test must exercise acceptance near the boundary: {accepted_near}"
    );
}

/// The planar vehicle of Example 3.3 (A_c, B_c, c, the continuous plant) with a stabilising sampled
/// gain K.
fn planar_vehicle() -> (
    Mat<f64>,
    Mat<f64>,
    Vec<f64>,
    host_compiler::model::ContinuousPlant,
    Mat<f64>,
) {
    let Ac = Mat::from_fn(4, 4, |i, j| {
        [
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [-1.0, 0.0, 0.1, 0.0],
            [0.0, -1.0, 0.0, 0.1],
        ][i][j]
    });
    let Bc = Mat::from_fn(4, 2, |i, j| {
        [[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]][i][j]
    });
    let c = vec![0.0, 0.0, 1.0, 1.0];
    let plant =
        host_compiler::model::ContinuousPlant::new(Ac.clone(), Bc.clone(), c.clone()).unwrap();
    let K = Mat::from_fn(2, 4, |i, j| {
        [[-2.0, 0.0, -2.5, 0.0], [0.0, -2.0, 0.0, -2.5]][i][j]
    });
    (Ac, Bc, c, plant, K)
}

#[test]
fn inter_sample_excursion_is_bounded() {
    let (Ac, Bc, c, plant, K) = planar_vehicle();
    let h = 0.05;
    let d = host_compiler::model::zoh(&plant, h).unwrap();
    const SUB: usize = 50;
    let fine = host_compiler::model::zoh(&plant, h / SUB as f64).unwrap();
    let P = random_pd(4, 5.0, &mut ChaCha8Rng::seed_from_u64(3));
    let sampled = LinearAffine::sampled(plant.clone(), h).unwrap();
    let property = ReachAvoid {
        goal: Box::new(host_compiler::geometry::Empty(4)),
        unsafe_set: None,
        input: InputBound::Norm2 {
            center: vec![0.0, 0.0],
            max: 1e9,
        },
        horizon: 1.0,
    };
    let At = &d.A + &d.B * &K;
    let sigma = host_compiler::linalg::sym_eigenvalues((&P - At.transpose() * &P * &At).as_ref())
        .unwrap()[0];
    let lp = Loop {
        plant: &sampled,
        loc: 0,
        K: K.as_ref(),
        P: P.as_ref(),
        goal: property.goal.as_ref(),
        unsafe_set: property.unsafe_region(),
        input: &property.input,
    };
    if sigma <= 0.0 {
        // Not contracting in this random metric: then the constants must refuse the loop.
        assert!(LoopConstants::new(&lp).is_err());
        return;
    }
    let lc = LoopConstants::new(&lp).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut tight: f64 = 0.0;
    for _ in 0..500 {
        let xn: Vec<f64> = (0..4).map(|_| rng.random_range(-2.0..2.0)).collect();
        let un: Vec<f64> = (0..2).map(|_| rng.random_range(-1.0..1.0)).collect();
        let e: Vec<f64> = (0..4).map(|_| rng.random_range(-0.1..0.1)).collect();
        let eps: Vec<f64> = (0..2).map(|_| rng.random_range(-1e-3..1e-3)).collect();
        let r = p_norm(P.as_ref(), &e);
        let epsn = eps.iter().map(|a| a * a).sum::<f64>().sqrt();
        // The actual run: x = x̃ + e, u = ũ + K e + ε, held for one period.
        let ke = mat_vec(K.as_ref(), &e);
        let u: Vec<f64> = (0..2).map(|i| un[i] + ke[i] + eps[i]).collect();
        let mut x: Vec<f64> = (0..4).map(|i| xn[i] + e[i]).collect();
        let f = {
            let ax = mat_vec(Ac.as_ref(), &xn);
            let bu = mat_vec(Bc.as_ref(), &un);
            (0..4).map(|i| ax[i] + bu[i] + c[i]).collect::<Vec<_>>()
        };
        let bound = lc.gamma * r + lc.phi * p_norm(P.as_ref(), &f) + lc.phi * lc.beta * epsn;
        for _ in 0..SUB {
            let ax = mat_vec(fine.A.as_ref(), &x);
            let bu = mat_vec(fine.B.as_ref(), &u);
            x = (0..4).map(|i| ax[i] + bu[i] + fine.g[i]).collect();
            let dev = p_norm(
                P.as_ref(),
                &(0..4).map(|i| x[i] - xn[i]).collect::<Vec<_>>(),
            );
            assert!(
                dev <= bound * (1.0 + 1e-12),
                "excursion {dev} exceeds the bound {bound}"
            );
            tight = tight.max(dev / bound);
        }
    }
    assert!(tight > 0.3, "bound far from tight: {tight}");
}

/// The PWA evaluator's whitened ball test (`shared_types::pwa`) with the threshold of
/// [`host_compiler::certify::pwa_ball_threshold`] (the square of [`host_compiler::certify::pwa_ball_radius`]):
/// every f32 state it accepts, and the real state it was
/// rounded from, lies in the certified f64 ball `‖x − c‖_P ≤ δ` — probed on shells straddling both the
/// stored and the certified radius, for unit-scale and large-magnitude centres (f64 centres that are not
/// f32 values) and condition numbers up to 10³. The radius is not absurdly small: for unit-scale data
/// (|c| ≤ 3, δ ≥ 0.1, cond(P) ≤ 10) the relative shrink 1 − ρ̂/δ stays below 10⁻⁴. Conversely every state
/// within the completeness radius r_in ([`host_compiler::certify::pwa_complete_radius`]) is accepted, at
/// every scale, probed on the shell just inside r_in; for unit-scale data r_in is within 10⁻⁴ of ρ̂.
#[test]
fn pwa_whitened_test_accepts_only_states_in_the_certified_ball() {
    use host_compiler::certify::{
        pwa_accept_radius, pwa_ball_complete_radius, pwa_ball_radius, pwa_ball_threshold,
        pwa_complete_radius,
    };
    use host_compiler::emit::{CertifiedBall, PwaImageBuilder, PwaLaw, PwaLeaf};
    use shared_types::pwa::Region;
    let mut rng = ChaCha8Rng::seed_from_u64(0x3A11);
    let (mut accepted, mut rejected, mut inner) = (0usize, 0usize, 0usize);
    let (mut worst_unit_shrink, mut worst_shrink) = (0.0f64, 0.0f64);
    let mut worst_unit_gap = 0.0f64;
    for trial in 0..400 {
        let n = [1, 2, 3, 4, 4, 6, 8, 12][trial % 8];
        // Unit scale: |c| ≤ 3, δ ∈ [0.1, 1], cond(P) ≤ 10. Otherwise cond(P) up to 10³, δ down to 10⁻²·scale.
        let kind = (trial / 8) % 4;
        let scale = [1.0, 1.0, 1e2, 1e4][kind];
        let unit = kind == 0;
        let cond = if unit { 10.0 } else { 1e3 };
        let P = random_pd(n, 1.0 + cond * rng.random::<f64>().powi(2), &mut rng);
        let c: Vec<f64> = (0..n)
            .map(|_| scale * rng.random_range(-3.0..3.0))
            .collect();
        let delta = if unit {
            rng.random_range(0.1..1.0)
        } else {
            rng.random_range(0.01..1.0) * scale.max(1.0)
        };
        let rho = pwa_ball_radius(P.as_ref(), &c, delta)
            .unwrap_or_else(|| panic!("trial {trial}: no radius for δ = {delta}, scale {scale}"));
        let shrink = 1.0 - rho as f64 / delta;
        assert!(
            rho > 0.0 && shrink > 0.0,
            "trial {trial}: ρ̂ = {rho}, δ = {delta}"
        );
        if unit {
            worst_unit_shrink = worst_unit_shrink.max(shrink);
        }
        worst_shrink = worst_shrink.max(shrink);
        let Prm = host_compiler::linalg::to_row_major(P.as_ref());
        let mut b = PwaImageBuilder::new(n, 1, 0.01);
        b.add_location(vec![0.0; n], Prm);
        b.add_law(PwaLaw {
            gain: vec![0.0; n],
            offset: vec![0.0],
        });
        // The stored threshold is fl32(ρ̂·ρ̂), one f32 product.
        let threshold = pwa_ball_threshold(P.as_ref(), &c, delta).unwrap();
        assert_eq!(threshold, rho * rho);
        b.add_ball(CertifiedBall {
            centre: c.clone(),
            threshold: threshold as f64,
            location: 0,
            partition: 0,
        });
        b.add_leaf(PwaLeaf {
            partition: 0,
            balls: vec![0],
        });
        let bytes = b.to_bytes().unwrap();
        let img = shared_types::image::decode(&bytes).unwrap();
        // The bound read back from the image (from the stored threshold) agrees: certified within δ.
        let Rh: Vec<f64> = (0..n * n)
            .map(|i| img.factor(0, i / n, i % n) as f64)
            .collect();
        let cz: Vec<f64> = (0..n).map(|i| img.ball_centre_z(0, i) as f64).collect();
        assert_eq!(img.ball_threshold(0), threshold);
        assert!(pwa_accept_radius(P.as_ref(), &Rh, &c, &cz, threshold) <= delta);
        let r_in = pwa_complete_radius(P.as_ref(), &Rh, &c, &cz, threshold);
        assert_eq!(r_in, pwa_ball_complete_radius(P.as_ref(), &c, delta));
        assert!(
            r_in > 0.0 && r_in < rho as f64,
            "trial {trial}: r_in = {r_in}, ρ̂ = {rho}"
        );
        if unit {
            worst_unit_gap = worst_unit_gap.max(1.0 - r_in / rho as f64);
        }
        let roots = host_compiler::linalg::PdRoots::new(P.as_ref()).unwrap();
        let dist = |x: &[f64]| p_norm(P.as_ref(), &(0..n).map(|i| x[i] - c[i]).collect::<Vec<_>>());
        for k in 0..300 {
            let w: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let wn = w.iter().map(|a| a * a).sum::<f64>().sqrt();
            let e = mat_vec(roots.inv_sqrt.as_ref(), &w);
            // Shells: around ρ̂, across (ρ̂, δ] and just beyond δ, just inside r_in, and well inside.
            let r = match k % 5 {
                0 => rho as f64 * (1.0 + rng.random_range(-1e-6..1e-6)),
                1 => rho as f64 + (delta - rho as f64) * rng.random_range(0.0..1.5),
                2 => delta * (1.0 + rng.random_range(-1e-7..1e-7)),
                3 => r_in * (1.0 - 1e-12 * rng.random::<f64>()),
                _ => r_in * rng.random::<f64>(),
            };
            let x: Vec<f64> = (0..n).map(|i| c[i] + r * e[i] / wn).collect();
            let xf: Vec<f32> = x.iter().map(|&a| a as f32).collect();
            let xh: Vec<f64> = xf.iter().map(|&a| a as f64).collect();
            let inside = matches!(img.locate(&xf), Some(Region::Inside { .. }));
            if k % 5 >= 3 {
                assert!(
                    inside,
                    "trial {trial}: rejected a state at P-distance {} ≤ r_in = {r_in} (scale {scale})",
                    dist(&x)
                );
                inner += 1;
            }
            if inside {
                accepted += 1;
                for (what, d) in [("f32 state", dist(&xh)), ("real state", dist(&x))] {
                    assert!(
                        d <= delta,
                        "trial {trial}: accepted a {what} at P-distance {d} > certified {delta} \
                         (ρ̂ = {rho}, scale {scale})"
                    );
                }
            } else {
                rejected += 1;
            }
        }
    }
    eprintln!(
        "accepted {accepted}, rejected {rejected}, inner {inner}, worst shrink: unit scale \
         {worst_unit_shrink:e}, all {worst_shrink:e}; worst 1 − r_in/ρ̂ at unit scale {worst_unit_gap:e}"
    );
    assert!(worst_unit_gap < 1e-4, "r_in gap {worst_unit_gap}");
    assert!(
        accepted > 40_000 && rejected > 20_000,
        "{accepted} {rejected}"
    );
    assert!(worst_unit_shrink < 1e-4, "shrink {worst_unit_shrink}");
}

/// The Unsafe margin between samples with the drift against each convex piece (`Pieces::unsafe_margin`,
/// its directional part): for random nominal samples near a box and a ball (a fast vehicle, a stiff
/// random metric), every run from the margin's ball, with an input error within ε̄, held one period
/// and flowed on a grid of 200 sub-steps, stays out of Unsafe. The deviations are random and, half of
/// the time, aimed at the nearest piece. The directional part is not vacuous: it beats the isotropic
/// margin in a good share of the cases; and the check can fail (runs from four times the margin, aimed
/// at the nearest piece, do enter).
#[test]
fn the_directional_unsafe_margin_keeps_every_run_out_between_samples() {
    use host_compiler::certify::Pieces;
    use host_compiler::geometry::{Ball, Metric, Polytope, Union};
    use host_compiler::trajectory::Nominal;
    let (Ac, Bc, c, plant, K) = planar_vehicle();
    let h = 0.1;
    const SUB: usize = 200;
    let fine = host_compiler::model::zoh(&plant, h / SUB as f64).unwrap();
    let sampled = LinearAffine::sampled(plant.clone(), h).unwrap();
    // x1 ∈ [1, 2], x2 ∈ [-1, 1] (any velocity), and the unit ball around (-2, 0, 0, 0).
    let boxed = Polytope::new(
        4,
        vec![
            1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0,
        ],
        vec![2.0, -1.0, 1.0, 1.0],
    )
    .unwrap();
    let mut I4 = vec![0.0; 16];
    for i in 0..4 {
        I4[i * 5] = 1.0;
    }
    let ball = Ball::new(vec![-2.0, 0.0, 0.0, 0.0], I4, 1.0).unwrap();
    let property = ReachAvoid {
        goal: Box::new(host_compiler::geometry::Empty(4)),
        unsafe_set: Some(Box::new(
            Union::new(vec![Box::new(boxed), Box::new(ball)]).unwrap(),
        )),
        input: InputBound::Norm2 {
            center: vec![0.0, 0.0],
            max: 1e9,
        },
        horizon: 1.0,
    };
    let us = property.unsafe_region().unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let (mut cases, mut better, mut wide_entered) = (0usize, 0usize, 0usize);
    let d = host_compiler::model::zoh(&plant, h).unwrap();
    let At = &d.A + &d.B * &K;
    for trial in 0..40 {
        // A contracting metric of random shape: P = Σ_j (Ãᵀ)^j Q Ã^j for a random Q (condition ≤ 20).
        let Q = random_pd(4, 20.0, &mut ChaCha8Rng::seed_from_u64(100 + trial));
        let mut P = Q.clone();
        let mut term = Q.clone();
        for _ in 0..400 {
            term = At.transpose() * &term * &At;
            P += &term;
        }
        let P = Mat::from_fn(4, 4, |i, j| 0.5 * (P[(i, j)] + P[(j, i)]));
        let lp = Loop {
            plant: &sampled,
            loc: 0,
            K: K.as_ref(),
            P: P.as_ref(),
            goal: property.goal.as_ref(),
            unsafe_set: Some(us),
            input: &property.input,
        };
        let lc = LoopConstants::new(&lp).expect("a Lyapunov metric contracts");
        let pc = Pieces::new(&lp, &lc);
        let metric = Metric {
            n: 4,
            R: host_compiler::linalg::to_row_major(P.as_ref()),
        };
        for _ in 0..25 {
            // Around the obstacles, with speeds up to 6 along either axis.
            let xn: Vec<f64> = vec![
                rng.random_range(-4.0..4.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-6.0..6.0),
                rng.random_range(-6.0..6.0),
            ];
            let un: Vec<f64> = (0..2).map(|_| rng.random_range(-2.0..2.0)).collect();
            let eps_bar = 1e-3;
            let nom = Nominal {
                x: vec![xn.clone(), xn.clone()],
                v: vec![un.clone()],
                u: vec![un.clone()],
            };
            let d = -us.signed_dist(&xn, &metric).value;
            if !(d > 0.0) {
                continue;
            }
            let r = pc.unsafe_margin(&nom, 0, d, eps_bar);
            if !(r > 0.0) {
                continue;
            }
            cases += 1;
            let f = {
                let ax = mat_vec(Ac.as_ref(), &xn);
                let bu = mat_vec(Bc.as_ref(), &un);
                (0..4).map(|i| ax[i] + bu[i] + c[i]).collect::<Vec<_>>()
            };
            let iso =
                (d - lc.phi * p_norm(P.as_ref(), &f) - lc.held_disturbance(eps_bar)) / lc.gamma;
            if r > iso * (1.0 + 1e-6) {
                better += 1;
            }
            let towards = us.dist(&xn, &metric).point;
            // The check can fail: from four times the margin, aimed at the witness, some runs enter.
            {
                let dir: Vec<f64> = (0..4).map(|i| towards[i] - xn[i]).collect();
                let s = 4.0 * r / p_norm(P.as_ref(), &dir);
                let e: Vec<f64> = dir.iter().map(|v| v * s).collect();
                let ke = mat_vec(K.as_ref(), &e);
                let u: Vec<f64> = (0..2).map(|i| un[i] + ke[i]).collect();
                let mut x: Vec<f64> = (0..4).map(|i| xn[i] + e[i]).collect();
                let mut entered = us.contains(&x);
                for _ in 0..SUB {
                    let ax = mat_vec(fine.A.as_ref(), &x);
                    let bu = mat_vec(fine.B.as_ref(), &u);
                    x = (0..4).map(|i| ax[i] + bu[i] + fine.g[i]).collect();
                    entered |= us.contains(&x);
                }
                wide_entered += usize::from(entered);
            }
            for probe in 0..20 {
                // e with ‖e‖_P just below r: aimed at the nearest piece's witness, or random.
                let dir: Vec<f64> = if probe % 2 == 0 {
                    (0..4).map(|i| towards[i] - xn[i]).collect()
                } else {
                    (0..4).map(|_| rng.random_range(-1.0..1.0)).collect()
                };
                let s = r * 0.999 / p_norm(P.as_ref(), &dir);
                let e: Vec<f64> = dir.iter().map(|v| v * s).collect();
                let eps: Vec<f64> = {
                    let w: Vec<f64> = (0..2).map(|_| rng.random_range(-1.0..1.0)).collect();
                    let nw = w.iter().map(|a| a * a).sum::<f64>().sqrt();
                    w.iter().map(|a| a / nw * eps_bar).collect()
                };
                let ke = mat_vec(K.as_ref(), &e);
                let u: Vec<f64> = (0..2).map(|i| un[i] + ke[i] + eps[i]).collect();
                let mut x: Vec<f64> = (0..4).map(|i| xn[i] + e[i]).collect();
                assert!(!us.contains(&x), "the sample itself is in Unsafe: {x:?}");
                for sub in 0..SUB {
                    let ax = mat_vec(fine.A.as_ref(), &x);
                    let bu = mat_vec(fine.B.as_ref(), &u);
                    x = (0..4).map(|i| ax[i] + bu[i] + fine.g[i]).collect();
                    assert!(
                        !us.contains(&x),
                        "trial {trial}: the run from x̃ = {xn:?} + e (‖e‖_P = {:.4}, margin {r:.4}, isotropic {iso:.4}) is in Unsafe at sub-step {sub}: {x:?}",
                        p_norm(P.as_ref(), &e)
                    );
                }
            }
        }
    }
    eprintln!(
        "{cases} samples with a positive margin; the directional one larger in {better}; from 4× the margin {wide_entered} runs entered"
    );
    assert!(wide_entered > 0, "no run from 4× the margin entered Unsafe");
    assert!(cases >= 200, "only {cases} cases with a positive margin");
    assert!(
        better * 4 >= cases,
        "the directional margin beat the isotropic one in {better} of {cases} cases"
    );
}
