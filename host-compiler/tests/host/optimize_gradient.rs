//! The adjoint gradients of §5.2.1 against finite differences on seeded random cases: the adjoint sweep
//! against the explicit sensitivities (A+BK)^{κ−1−j}B, the potential cost's gradient, and the
//! subgradient of δ(0) (5.28) where its critical piece is unique.

#![allow(non_snake_case)]

use host_compiler::certify::OwnedLoop;
use host_compiler::certify::{shipped, LoopConstants};
use host_compiler::optimize::pieces::{adjoint_sweep, delta_subgradient, Pieces};
use host_compiler::optimize::potential::{Potential, PotentialSettings};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn planar() -> (OwnedLoop, LoopConstants) {
    let p = host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    ))
    .unwrap();
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lc = ol.constants().unwrap();
    (ol, lc)
}

fn random_v(rng: &mut ChaCha8Rng, steps: usize, base: [f64; 2], spread: f64) -> Vec<Vec<f64>> {
    (0..steps)
        .map(|_| {
            vec![
                base[0] + rng.random_range(-spread..spread),
                base[1] + rng.random_range(-spread..spread),
            ]
        })
        .collect()
}

fn axpy(v: &[Vec<f64>], h: f64, d: &[Vec<f64>]) -> Vec<Vec<f64>> {
    v.iter()
        .zip(d)
        .map(|(a, b)| a.iter().zip(b).map(|(x, y)| x + h * y).collect())
        .collect()
}

fn inner(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| x * y)
        .sum()
}

#[test]
fn adjoint_sweep_matches_explicit_sensitivities() {
    let (_, lc) = planar();
    let mut rng = ChaCha8Rng::seed_from_u64(51);
    let steps = 25;
    for _ in 0..5 {
        // J = Σ_κ c_κᵀ x(κ) + Σ_κ e_κᵀ v(κ) with x(κ) = Σ_{j<κ} Ã^{κ−1−j} B v(j) + (terms free of v).
        let gx: Vec<Vec<f64>> = (0..=steps)
            .map(|_| (0..4).map(|_| rng.random_range(-1.0..1.0)).collect())
            .collect();
        let gv: Vec<Vec<f64>> = (0..steps)
            .map(|_| (0..2).map(|_| rng.random_range(-1.0..1.0)).collect())
            .collect();
        let adj = adjoint_sweep(lc.At.as_ref(), lc.B.as_ref(), &gx, gv.clone());
        for j in 0..steps {
            // Explicit: ∂J/∂v(j) = e_j + Σ_{κ>j} Bᵀ (Ãᵀ)^{κ−1−j} c_κ.
            let mut M = lc.B.clone(); // Ã^{κ−1−j} B for κ = j+1
            let mut expect = gv[j].clone();
            for c in &gx[(j + 1)..=steps] {
                for i in 0..2 {
                    expect[i] += (0..4).map(|r| M[(r, i)] * c[r]).sum::<f64>();
                }
                M = &lc.At * &M;
            }
            for i in 0..2 {
                assert!(
                    (adj[j][i] - expect[i]).abs() <= 1e-10 * (1.0 + expect[i].abs()),
                    "j {j} i {i}: adjoint {} explicit {}",
                    adj[j][i],
                    expect[i]
                );
            }
        }
    }
}

#[test]
fn potential_gradient_matches_finite_differences() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let mut rng = ChaCha8Rng::seed_from_u64(52);
    let x0 = [0.0, 0.0, 0.0, 1.0];
    let steps = 120;
    let mut checked = 0;
    for case in 0..8 {
        let v = random_v(&mut rng, steps, [1.0, -1.0], 0.8);
        let (_, c) = shipped(&lp, &lc, &x0, &v);
        let s = PotentialSettings::builder()
            .delta(0.05 + 0.01 * case as f64)
            .build()
            .unwrap();
        let pot = Potential::new(&lp, &lc, &x0, steps, &c, &s);
        let (J, g) = pot.eval(&v, true);
        let g = g.unwrap();
        assert!(J > 0.0, "the random seeds violate the potentials");
        for _ in 0..3 {
            let d = random_v(&mut rng, steps, [0.0, 0.0], 1.0);
            let h = 1e-6;
            let fd = (pot.eval(&axpy(&v, h, &d), false).0 - pot.eval(&axpy(&v, -h, &d), false).0)
                / (2.0 * h);
            let an = inner(&g, &d);
            // The Unsafe piece between samples along the obstacle's normal differentiates with the
            // normal held fixed (`certify::pieces`' module doc); on the disc the normal turns with x,
            // which the finite difference sees: a few 10⁻⁴ relative.
            assert!(
                (fd - an).abs() <= 2e-3 * fd.abs().max(an.abs()) + 1e-9,
                "case {case}: finite difference {fd}, adjoint {an}"
            );
            checked += 1;
        }
    }
    assert_eq!(checked, 24);
}

#[test]
fn potential_gradient_matches_finite_differences_with_box_sets() {
    // Double integrator: box input, half-plane Unsafe, box Goal (the other branches of the pieces).
    let p = host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    ))
    .unwrap();
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lc = ol.constants().unwrap();
    let lp = ol.lp();
    let mut rng = ChaCha8Rng::seed_from_u64(54);
    let x0 = [0.05, 0.0];
    let steps = ol.task.steps;
    for case in 0..8 {
        let v: Vec<Vec<f64>> = (0..steps)
            .map(|_| vec![rng.random_range(-1.5..1.5)])
            .collect();
        let (_, c) = shipped(&lp, &lc, &x0, &v);
        let s = PotentialSettings::builder().delta(0.1).build().unwrap();
        let pot = Potential::new(&lp, &lc, &x0, steps, &c, &s);
        let (J, g) = pot.eval(&v, true);
        let g = g.unwrap();
        assert!(J > 0.0);
        let d: Vec<Vec<f64>> = (0..steps)
            .map(|_| vec![rng.random_range(-1.0..1.0)])
            .collect();
        let h = 1e-6;
        let fd = (pot.eval(&axpy(&v, h, &d), false).0 - pot.eval(&axpy(&v, -h, &d), false).0)
            / (2.0 * h);
        let an = inner(&g, &d);
        assert!(
            (fd - an).abs() <= 1e-4 * fd.abs().max(an.abs()) + 1e-9,
            "case {case}: finite difference {fd}, adjoint {an}"
        );
    }
}

#[test]
fn delta_subgradient_is_the_gradient_of_the_critical_piece() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let pc = Pieces::new(&lp, &lc);
    let mut rng = ChaCha8Rng::seed_from_u64(53);
    let x0 = [0.0, 0.0, 0.0, 1.0];
    let steps = 300;
    let mut checked = 0;
    for case in 0..10 {
        let v = random_v(&mut rng, steps, [1.0, -1.0], 0.3);
        let (_, c) = shipped(&lp, &lc, &x0, &v);
        let (eps, e2) = (c.eps_components.clone(), c.eps_f32);
        let delta = |v: &[Vec<f64>]| {
            let nom = lp.simulate(&x0, v);
            delta_subgradient(&pc, &nom, &eps, e2)
        };
        let (d, g) = delta(&v);
        for _ in 0..2 {
            let dir = random_v(&mut rng, steps, [0.0, 0.0], 1.0);
            let h = 1e-7;
            let (dp, gp) = delta(&axpy(&v, h, &dir));
            let (dm, gm) = delta(&axpy(&v, -h, &dir));
            // Only where the critical piece and sample stay the same (δ smooth there).
            if inner(&gp, &dir) - inner(&gm, &dir) != 0.0
                && (inner(&gp, &dir) - inner(&gm, &dir)).abs() > 1e-6 * inner(&g, &dir).abs()
            {
                continue;
            }
            let fd = (dp - dm) / (2.0 * h);
            let an = inner(&g, &dir);
            assert!(
                (fd - an).abs() <= 1e-4 * fd.abs().max(an.abs()) + 1e-8,
                "case {case}: δ {d}, finite difference {fd}, subgradient {an}"
            );
            checked += 1;
        }
    }
    println!("{checked} smooth directions checked");
    assert!(checked >= 10, "only {checked} smooth cases");
}

#[test]
fn the_pieces_give_the_certificates_value() {
    // The optimiser's model of (4.11) is the certifier's, on the shipped nominal, to the last bits.
    let (ol, lc) = planar();
    let lp = ol.lp();
    let pc = Pieces::new(&lp, &lc);
    let mut rng = ChaCha8Rng::seed_from_u64(55);
    for case in 0..10 {
        let x0 = [
            rng.random_range(-0.2..0.2),
            rng.random_range(-0.2..0.2),
            0.0,
            1.0,
        ];
        let v = random_v(&mut rng, 200 + 30 * case, [1.0, -1.0], 0.5);
        let (nom, c) = shipped(&lp, &lc, &x0, &v);
        let (d, _) = delta_subgradient(&pc, &nom, &c.eps_components, c.eps_f32);
        let d47 = c
            .delta_goal
            .min(c.delta_unsafe_intersample)
            .min(c.delta_input);
        assert!(
            (d - d47).abs() <= 1e-12 * d47.abs().max(1.0),
            "case {case}: pieces {d}, certificate {d47}"
        );
    }
}
