//! Plant model: the matrix exponential and the zero-order hold against closed forms and fine RK4
//! integration, closed-loop simulation, and the inter-sample excursion bound against fine simulation.
#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::model::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn rand_mat(r: &mut ChaCha8Rng, n: usize, m: usize, scale: f64) -> Mat<f64> {
    Mat::from_fn(n, m, |_, _| scale * r.random_range(-1.0..1.0))
}

fn max_diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    let mut d: f64 = 0.0;
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            d = d.max((a[(i, j)] - b[(i, j)]).abs());
        }
    }
    d
}

fn vdiff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn double_integrator_closed_form() {
    let p = ContinuousPlant::new(
        Mat::from_fn(2, 2, |i, j| if i == 0 && j == 1 { 1.0 } else { 0.0 }),
        Mat::from_fn(2, 1, |i, _| if i == 1 { 1.0 } else { 0.0 }),
        vec![0.0, -9.81],
    )
    .unwrap();
    for &h in &[1e-3, 0.01, 0.1, 1.0, 10.0] {
        let d = p.zoh(h).unwrap();
        let tol = 1e-14 * (1.0 + h * h);
        assert!((d.A[(0, 0)] - 1.0).abs() < tol && (d.A[(0, 1)] - h).abs() < tol);
        assert!(d.A[(1, 0)].abs() < tol && (d.A[(1, 1)] - 1.0).abs() < tol);
        assert!((d.B[(0, 0)] - h * h / 2.0).abs() < tol && (d.B[(1, 0)] - h).abs() < tol);
        // Constant gravity: g_d = (−9.81 h²/2, −9.81 h).
        assert!(
            (d.g[0] + 9.81 * h * h / 2.0).abs() < 10.0 * tol
                && (d.g[1] + 9.81 * h).abs() < 10.0 * tol
        );
        assert_eq!(d.period, h);
    }
}

#[test]
fn scalar_exponential_closed_form_on_every_pade_branch() {
    // |a h| spans every degree (3, 5, 7, 9) and the scaled degree-13 branch.
    for &(a, h) in &[
        (0.5, 0.01),
        (-2.0, 0.1),
        (3.0, 0.3),
        (-1.5, 1.3),
        (0.7, 40.0),
        (-4.0, 10.0),
    ] {
        let (b, c) = (2.0, 0.25);
        let p = ContinuousPlant::new(
            Mat::from_fn(1, 1, |_, _| a),
            Mat::from_fn(1, 1, |_, _| b),
            vec![c],
        )
        .unwrap();
        let d = p.zoh(h).unwrap();
        let e = (a * h).exp();
        let phi = (a * h).exp_m1() / a;
        let rel = |x: f64, y: f64| ((x - y) / y).abs();
        assert!(
            rel(d.A[(0, 0)], e) < 1e-13,
            "a h = {}: {} vs {e}",
            a * h,
            d.A[(0, 0)]
        );
        assert!(rel(d.B[(0, 0)], b * phi) < 1e-13);
        assert!(rel(d.g[0], c * phi) < 1e-13);
    }
}

#[test]
fn rotation_and_inverse_identities() {
    // e^{[[0, w], [−w, 0]] t} is the rotation by −w t.
    for &(w, t) in &[(1.0, 0.1), (3.0, 7.0), (50.0, 2.0)] {
        let m = Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 1) => w * t,
            (1, 0) => -w * t,
            _ => 0.0,
        });
        let e = expm(m.as_ref()).unwrap();
        let (c, s) = ((w * t).cos(), (w * t).sin());
        let want = Mat::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) | (1, 1) => c,
            (0, 1) => s,
            _ => -s,
        });
        assert!(
            max_diff(&e, &want) < 1e-12 * (1.0 + w * t),
            "w t = {}",
            w * t
        );
    }
    // e^M e^{−M} = I for random matrices of several norms.
    let mut r = ChaCha8Rng::seed_from_u64(5);
    for &scale in &[0.001, 0.05, 0.3, 1.0, 4.0] {
        let m = rand_mat(&mut r, 6, 6, scale);
        let neg = Mat::from_fn(6, 6, |i, j| -m[(i, j)]);
        let (e, einv) = (expm(m.as_ref()).unwrap(), expm(neg.as_ref()).unwrap());
        let prod = &e * &einv;
        let id = Mat::from_fn(6, 6, |i, j| if i == j { 1.0 } else { 0.0 });
        // Rounding in the product alone is of order eps·‖e^M‖·‖e^{−M}‖.
        let cond = e.norm_l2() * einv.norm_l2();
        assert!(
            max_diff(&prod, &id) < 1e-13 * cond,
            "scale {scale}: {} (cond {cond})",
            max_diff(&prod, &id)
        );
    }
}

#[test]
fn expm_matches_a_long_taylor_series() {
    // Reference: Σ M^k / k! with enough terms, for norms where the series is accurate in f64.
    let mut r = ChaCha8Rng::seed_from_u64(6);
    for &scale in &[0.002, 0.04, 0.15, 0.35, 0.6] {
        let n = 5;
        let m = rand_mat(&mut r, n, n, scale);
        let mut sum = Mat::from_fn(n, n, |i, j| if i == j { 1.0 } else { 0.0 });
        let mut term = sum.clone();
        for k in 1..60 {
            term = &term * &m * (1.0 / k as f64);
            sum = &sum + &term;
        }
        assert!(
            max_diff(&expm(m.as_ref()).unwrap(), &sum) < 1e-14,
            "scale {scale}"
        );
    }
}

#[test]
fn zoh_matches_fine_rk4_integration() {
    let mut r = ChaCha8Rng::seed_from_u64(7);
    for trial in 0..6 {
        let (n, m) = (4, 2);
        let p = ContinuousPlant::new(
            rand_mat(&mut r, n, n, 1.5),
            rand_mat(&mut r, n, m, 1.0),
            (0..n).map(|_| r.random_range(-1.0..1.0)).collect(),
        )
        .unwrap();
        let h = [0.01, 0.1, 0.5][trial % 3];
        let d = p.zoh(h).unwrap();
        let x0: Vec<f64> = (0..n).map(|_| r.random_range(-2.0..2.0)).collect();
        let u: Vec<f64> = (0..m).map(|_| r.random_range(-1.0..1.0)).collect();
        let steps = 2000;
        let mut x = x0.clone();
        for _ in 0..steps {
            x = p.rk4_step(&x, &u, h / steps as f64);
        }
        let exact = d.step(&x0, &u);
        assert!(
            vdiff(&x, &exact) < 1e-11 * (1.0 + x.iter().map(|v| v.abs()).fold(0.0, f64::max)),
            "trial {trial}"
        );
    }
}

#[test]
fn closed_loop_reproduces_the_nominal_and_superposes() {
    let mut r = ChaCha8Rng::seed_from_u64(8);
    let (n, m) = (3, 2);
    let plant = DiscretePlant::new(
        rand_mat(&mut r, n, n, 0.6),
        rand_mat(&mut r, n, m, 1.0),
        vec![0.1, -0.2, 0.3],
        0.05,
    )
    .unwrap();
    let K = rand_mat(&mut r, m, n, 0.5);
    // A nominal trajectory from arbitrary inputs.
    let u_nom: Vec<Vec<f64>> = (0..20)
        .map(|_| (0..m).map(|_| r.random_range(-1.0..1.0)).collect())
        .collect();
    let mut x_nom = vec![vec![0.5, -0.5, 1.0]];
    for u in &u_nom {
        let next = plant.step(x_nom.last().unwrap(), u);
        x_nom.push(next);
    }
    let v = reference_inputs(K.as_ref(), &x_nom, &u_nom).unwrap();
    let run = simulate_closed_loop(&plant, K.as_ref(), &x_nom[0], &v, None).unwrap();
    for k in 0..=20 {
        assert!(vdiff(&run.x[k], &x_nom[k]) < 1e-12);
    }
    for k in 0..20 {
        assert!(vdiff(&run.u[k], &u_nom[k]) < 1e-12);
    }
    // A disturbance enters like an input: x_eps − x = Σ (A+BK)^{k−1−j} B ε_j.
    let eps: Vec<Vec<f64>> = (0..20).map(|_| vec![1e-3, -2e-3]).collect();
    let dist = simulate_closed_loop(&plant, K.as_ref(), &x_nom[0], &v, Some(&eps)).unwrap();
    let Acl = &plant.A + &plant.B * &K;
    let mut e = vec![0.0; n];
    for k in 0..20 {
        let be: Vec<f64> = (0..n)
            .map(|i| (0..m).map(|j| plant.B[(i, j)] * eps[k][j]).sum())
            .collect();
        e = (0..n)
            .map(|i| (0..n).map(|j| Acl[(i, j)] * e[j]).sum::<f64>() + be[i])
            .collect();
        let got: Vec<f64> = (0..n).map(|i| dist.x[k + 1][i] - run.x[k + 1][i]).collect();
        assert!(vdiff(&got, &e) < 1e-12);
    }
}

#[test]
fn inter_sample_bound_holds_and_is_tight_for_small_periods() {
    let mut r = ChaCha8Rng::seed_from_u64(9);
    let mut worst_ratio: f64 = 0.0;
    for trial in 0..40 {
        let (n, m) = (3, 1);
        let plant = ContinuousPlant::new(
            rand_mat(&mut r, n, n, 2.0),
            rand_mat(&mut r, n, m, 1.0),
            (0..n).map(|_| r.random_range(-1.0..1.0)).collect(),
        )
        .unwrap();
        let h = [0.01, 0.05, 0.2, 0.5][trial % 4];
        let bound = plant.inter_sample_bound(h).unwrap();
        let x: Vec<f64> = (0..n).map(|_| r.random_range(-1.0..1.0)).collect();
        let u: Vec<f64> = (0..m).map(|_| r.random_range(-1.0..1.0)).collect();
        let b = bound.excursion(&x, &u).unwrap();
        // Fine simulation of the held-input flow over one period.
        let steps = 400;
        let mut y = x.clone();
        let mut observed: f64 = 0.0;
        for _ in 0..steps {
            y = plant.rk4_step(&y, &u, h / steps as f64);
            observed = observed.max(
                y.iter()
                    .zip(&x)
                    .map(|(a, c)| (a - c) * (a - c))
                    .sum::<f64>()
                    .sqrt(),
            );
        }
        assert!(
            observed <= b * (1.0 + 1e-9),
            "trial {trial}: observed {observed} > bound {b}"
        );
        if h <= 0.01 {
            // For small h, x(t) − x_κ ≈ τ f_κ, so the bound is nearly attained.
            assert!(
                observed >= 0.9 * b,
                "trial {trial}: bound too loose ({observed} vs {b})"
            );
        }
        worst_ratio = worst_ratio.max(observed / b);
    }
    assert!(worst_ratio > 0.5);
}

#[test]
fn deviation_factor_bounds_two_runs_between_samples() {
    let mut r = ChaCha8Rng::seed_from_u64(10);
    let (n, m) = (4, 2);
    let plant = ContinuousPlant::new(
        rand_mat(&mut r, n, n, 1.0),
        rand_mat(&mut r, n, m, 1.0),
        vec![0.0; n],
    )
    .unwrap();
    let K = rand_mat(&mut r, m, n, 1.0);
    let h = 0.1;
    let bound = plant.inter_sample_bound(h).unwrap();
    let factor = bound.deviation_factor(K.as_ref()).unwrap();
    for _ in 0..10 {
        let x: Vec<f64> = (0..n).map(|_| r.random_range(-1.0..1.0)).collect();
        let xt: Vec<f64> = x.iter().map(|v| v + r.random_range(-0.1..0.1)).collect();
        let v: Vec<f64> = (0..m).map(|_| r.random_range(-1.0..1.0)).collect();
        let u = |s: &[f64]| -> Vec<f64> {
            (0..m)
                .map(|i| (0..n).map(|j| K[(i, j)] * s[j]).sum::<f64>() + v[i])
                .collect()
        };
        let (ua, ub) = (u(&x), u(&xt));
        let e0 = x
            .iter()
            .zip(&xt)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let (mut ya, mut yb) = (x.clone(), xt.clone());
        for _ in 0..200 {
            ya = plant.rk4_step(&ya, &ua, h / 200.0);
            yb = plant.rk4_step(&yb, &ub, h / 200.0);
            let e = ya
                .iter()
                .zip(&yb)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt();
            assert!(e <= factor * e0 * (1.0 + 1e-9));
        }
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let a = Mat::from_fn(2, 2, |_, _| 1.0);
    assert!(matches!(
        ContinuousPlant::new(a.clone(), Mat::zeros(3, 1), vec![0.0; 2]),
        Err(ModelError::Dimension { .. })
    ));
    assert!(matches!(
        ContinuousPlant::new(Mat::zeros(2, 3), Mat::zeros(2, 1), vec![0.0; 2]),
        Err(ModelError::Dimension { .. })
    ));
    assert!(matches!(
        ContinuousPlant::new(a.clone(), Mat::zeros(2, 1), vec![0.0; 3]),
        Err(ModelError::Dimension { .. })
    ));
    let mut nan = a.clone();
    nan[(0, 1)] = f64::NAN;
    assert!(matches!(
        ContinuousPlant::new(nan, Mat::zeros(2, 1), vec![0.0; 2]),
        Err(ModelError::NonFinite { .. })
    ));
    let p = ContinuousPlant::new(a.clone(), Mat::zeros(2, 1), vec![0.0; 2]).unwrap();
    assert!(matches!(p.zoh(0.0), Err(ModelError::Period(_))));
    assert!(matches!(p.zoh(f64::NAN), Err(ModelError::Period(_))));
    assert!(matches!(
        DiscretePlant::new(a.clone(), Mat::zeros(2, 1), vec![0.0; 2], -1.0),
        Err(ModelError::Period(_))
    ));
    assert!(expm(Mat::<f64>::zeros(2, 3).as_ref()).is_err());
    let bound = p.inter_sample_bound(0.1).unwrap();
    assert!(bound.excursion(&[0.0], &[0.0]).is_err());
    assert!(bound
        .deviation_factor(Mat::<f64>::zeros(2, 2).as_ref())
        .is_err());
    let d = p.zoh(0.1).unwrap();
    assert!(simulate_closed_loop(
        &d,
        Mat::<f64>::zeros(1, 2).as_ref(),
        &[0.0, 0.0],
        &[vec![0.0, 0.0]],
        None
    )
    .is_err());
}

#[test]
fn sampled_plant_from_spec() {
    use host_compiler::spec::{Matrix, Plant, TimeDomain};
    let spec = Plant {
        time: TimeDomain::Continuous,
        A: Matrix {
            rows: 2,
            cols: 2,
            data: vec![0.0, 1.0, 0.0, 0.0],
        },
        B: Matrix {
            rows: 2,
            cols: 1,
            data: vec![0.0, 1.0],
        },
        offset: vec![0.0, 0.0],
        period: 0.5,
        C: Matrix::identity(2),
    };
    let s = LinearAffine::from_spec(&spec).unwrap();
    assert!(s.continuous.is_some());
    assert!(
        (s.discrete.A[(0, 1)] - 0.5).abs() < 1e-15 && (s.discrete.B[(0, 0)] - 0.125).abs() < 1e-15
    );
    let d = LinearAffine::from_spec(&Plant {
        time: TimeDomain::Discrete,
        ..spec
    })
    .unwrap();
    assert!(d.continuous.is_none());
    assert_eq!(d.discrete.A[(0, 1)], 1.0);
}
