//! Properties against brute force on seeded random plants: every solved CAF satisfies its certificate on
//! random directions, the closed loop is Schur stable, and Theorem 3.21's r_crit is invariant under the worst
//! disturbance found by search; r_crit matches the closed form of the scalar case.
#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::caf::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn rand_mat(r: &mut ChaCha8Rng, n: usize, m: usize, scale: f64) -> Mat<f64> {
    Mat::from_fn(n, m, |_, _| scale * r.random_range(-1.0..1.0))
}

fn quad(M: &Mat<f64>, x: &[f64]) -> f64 {
    let n = x.len();
    (0..n)
        .map(|i| x[i] * (0..n).map(|j| M[(i, j)] * x[j]).sum::<f64>())
        .sum()
}

fn spectral_radius(M: &Mat<f64>) -> f64 {
    M.eigenvalues()
        .unwrap()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

#[test]
fn random_plants_get_valid_certificates() {
    let mut r = ChaCha8Rng::seed_from_u64(100);
    let mut solved = 0;
    for trial in 0..24 {
        let n = 2 + trial % 5;
        let m = 1 + trial % 2;
        // Spectral radius around 1.1: some modes unstable; random B makes the pair controllable a.s.
        let A = rand_mat(&mut r, n, n, 1.1 / (n as f64).sqrt() * 1.7);
        let B = rand_mat(&mut r, n, m, 1.0);
        let sigma = [0.01, 0.05, 0.1][trial % 3];
        let formulation = if trial % 4 == 3 {
            Formulation::Joint
        } else {
            Formulation::Reduced
        };
        let s = CafSettings::builder()
            .sigma(sigma)
            .formulation(formulation)
            .build()
            .unwrap();
        let out = synthesize(TimeKind::Discrete, A.as_ref(), B.as_ref(), &s).unwrap();
        let CafOutcome::Solved(caf) = out else {
            panic!("trial {trial}: {out:?}")
        };
        solved += 1;
        let At = caf.A_cl();
        assert!(spectral_radius(&At) < 1.0, "trial {trial}");
        let D = &caf.P - At.transpose() * &caf.P * &At;
        for _ in 0..200 {
            let x: Vec<f64> = (0..n).map(|_| r.random_range(-1.0..1.0)).collect();
            let nx: f64 = x.iter().map(|v| v * v).sum();
            assert!(
                quad(&caf.P, &x) >= nx * (1.0 - 1e-12),
                "trial {trial}: P ⪰ I violated"
            );
            assert!(
                quad(&D, &x) >= sigma * nx * (1.0 - 1e-12),
                "trial {trial}: margin violated"
            );
        }
        assert!(caf.certificate.margin >= sigma && caf.certificate.condition >= 1.0);
    }
    assert_eq!(solved, 24);
}

#[test]
fn r_crit_scalar_closed_form() {
    // n = m = 1: Ã = a, P = p, E = b. Then ρ_crit = δ|b|/(1 − |a|), the exact radius of the invariant
    // interval of e⁺ = a e − b ε, and r_crit² = p ρ_crit² + p b² δ² (a²/(1 − a²) + 1).
    for &(a, b, p, delta) in &[
        (0.5, 1.0, 1.0, 0.1),
        (-0.9, 0.3, 2.5, 1e-3),
        (0.0, 2.0, 1.0, 1.0),
    ] {
        let rc = r_crit(
            Mat::from_fn(1, 1, |_, _| a).as_ref(),
            Mat::from_fn(1, 1, |_, _| p).as_ref(),
            Mat::from_fn(1, 1, |_, _| b).as_ref(),
            delta,
        )
        .unwrap();
        let f64_tol = 1e-12;
        let rho: f64 = delta * b.abs() / (1.0 - a.abs());
        assert!(
            (rc.rho_crit - rho).abs() <= 1e-9 * rho.max(1e-300) + f64_tol,
            "ρ_crit {} vs {rho}",
            rc.rho_crit
        );
        let r2 = p * rho * rho + p * b * b * delta * delta * (a * a / (1.0 - a * a) + 1.0);
        assert!(
            (rc.r_crit - r2.sqrt()).abs() <= 1e-9 * r2.sqrt(),
            "r_crit {} vs {}",
            rc.r_crit,
            r2.sqrt()
        );
        assert!(rc.r_crit >= rc.r_tilde && rc.r_tilde >= rc.rho_crit * p.sqrt() * (1.0 - 1e-12));
    }
}

/// The disturbance with ‖ε‖ ≤ δ that pushes e⁺ = Ã e − E ε furthest in ψ, approximately: the best of many
/// directions on the sphere (the maximiser of a convex function over a ball lies on its boundary).
fn worst_step(
    At: &Mat<f64>,
    P: &Mat<f64>,
    E: &Mat<f64>,
    e: &[f64],
    delta: f64,
    r: &mut ChaCha8Rng,
) -> (Vec<f64>, f64) {
    let n = e.len();
    let m = E.ncols();
    let ae: Vec<f64> = (0..n)
        .map(|i| (0..n).map(|j| At[(i, j)] * e[j]).sum())
        .collect();
    let mut best = (ae.clone(), quad(P, &ae));
    for k in 0..400 {
        let mut d: Vec<f64> = if k == 0 {
            // The first-order best: −E ε aligned with P Ã e.
            let pae: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| P[(i, j)] * ae[j]).sum())
                .collect();
            (0..m)
                .map(|j| -(0..n).map(|i| E[(i, j)] * pae[i]).sum::<f64>())
                .collect()
        } else {
            (0..m).map(|_| r.random_range(-1.0..1.0)).collect()
        };
        let nd = d.iter().map(|v| v * v).sum::<f64>().sqrt();
        if nd == 0.0 {
            continue;
        }
        d.iter_mut().for_each(|v| *v *= delta / nd);
        let next: Vec<f64> = (0..n)
            .map(|i| ae[i] - (0..m).map(|j| E[(i, j)] * d[j]).sum::<f64>())
            .collect();
        let q = quad(P, &next);
        if q > best.1 {
            best = (next, q);
        }
    }
    (best.0, best.1.sqrt())
}

#[test]
fn r_crit_ball_is_invariant_under_searched_worst_disturbances() {
    let mut r = ChaCha8Rng::seed_from_u64(101);
    for trial in 0..6 {
        let n = 3;
        let m = 2;
        let A = rand_mat(&mut r, n, n, 0.9);
        let B = rand_mat(&mut r, n, m, 1.0);
        let s = CafSettings::builder().sigma(0.05).build().unwrap();
        let caf = synthesize(TimeKind::Discrete, A.as_ref(), B.as_ref(), &s)
            .unwrap()
            .solved()
            .unwrap();
        let delta = 0.01;
        let rc = caf.r_crit(delta).unwrap();
        let At = caf.A_cl();
        // Start on the ψ-sphere of radius r_crit and at random points inside, push with the worst ε found,
        // many steps: ψ must stay ≤ r_crit (3.88).
        for start in 0..20 {
            let mut e: Vec<f64> = (0..n).map(|_| r.random_range(-1.0..1.0)).collect();
            let scale = if start % 2 == 0 {
                1.0
            } else {
                r.random_range(0.0..1.0)
            };
            let pe = quad(&caf.P, &e).sqrt();
            e.iter_mut().for_each(|v| *v *= scale * rc.r_crit / pe);
            for step in 0..30 {
                let (next, psi) = worst_step(&At, &caf.P, &caf.B, &e, delta, &mut r);
                assert!(
                    psi <= rc.r_crit * (1.0 + 1e-9),
                    "trial {trial} start {start} step {step}: {psi} > {}",
                    rc.r_crit
                );
                e = next;
            }
        }
    }
}
