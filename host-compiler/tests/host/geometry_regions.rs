//! Composite regions: sets in output coordinates checked against the same set written in state coordinates
//! (two independent reductions of a singular problem), unions and complements against their members, the
//! Def 2.16 sign convention throughout, and compiled signed distances (`Region::compile`) against
//! `signed_dist`.
#![allow(non_snake_case)]

use crate::geometry_common;

use geometry_common::*;
use host_compiler::geometry::{
    Ball, Complement, Ellipsoid, InOutput, Metric, Polytope, Region, Union,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

fn gaussian(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    (0..n)
        .map(|_| rng.sample::<f64, _>(StandardNormal))
        .collect()
}

fn random_pd(n: usize, rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> Vec<f64> {
    let d: Vec<f64> = (0..n)
        .map(|_| 10f64.powf(rng.random_range(lo..hi)))
        .collect();
    compose(n, &random_orthogonal(n, rng), &d)
}

/// {x : Cx ∈ E_y} is the degenerate ellipsoid (x − c_x)ᵀ CᵀQ_yC (x − c_x) ≤ 1 with C c_x = c_y. The
/// output-metric route (InOutput) and the §7.2.2 route (Ellipsoid with a singular Q) must agree.
#[test]
fn output_ellipsoid_equals_state_cylinder() {
    let mut rng = ChaCha8Rng::seed_from_u64(81);
    let mut compared = 0;
    for case in 0..300 {
        let n = rng.random_range(2..=7);
        let p = rng.random_range(1..n);
        let C = gaussian(p * n, &mut rng);
        let Qy = random_pd(p, &mut rng, -0.5, 0.5);
        let cy = gaussian(p, &mut rng);
        // c_x = Cᵀ(CCᵀ)⁻¹ c_y
        let Ct = transpose(&C, p, n);
        let CCt = matmul(&C, &Ct, p, n, p);
        let w = matvec(&pinv_sym(p, &CCt), p, p, &cy);
        let cx = matvec(&Ct, n, p, &w);
        let Qx = matmul(&matmul(&Ct, &Qy, n, p, p), &C, n, p, n);
        let out = InOutput::new(
            C.clone(),
            p,
            Box::new(Ellipsoid::new(cy.clone(), Qy.clone()).unwrap()),
        )
        .unwrap();
        let cyl = Ellipsoid::new(cx.clone(), Qx.clone()).unwrap();
        // Metric: PD, or singular (then in the state-space route, zero-cost directions appear).
        let singular = case % 3 == 2;
        let R = if singular {
            let mut d: Vec<f64> = (0..n).map(|_| rng.random_range(0.3..3.0)).collect();
            d[0] = 0.0;
            compose(n, &random_orthogonal(n, &mut rng), &d)
        } else {
            random_pd(n, &mut rng, -0.5, 0.5)
        };
        let metric = Metric::new(n, R.clone()).unwrap();
        for _ in 0..5 {
            let x: Vec<f64> = cx
                .iter()
                .map(|v| v + 1.5 * rng.sample::<f64, _>(StandardNormal))
                .collect();
            assert_eq!(out.contains(&x), cyl.contains(&x));
            let a = out.try_signed_dist(&x, &metric).unwrap();
            let b = cyl.try_signed_dist(&x, &metric).unwrap();
            let disp = a
                .point
                .iter()
                .zip(&x)
                .map(|(u, v)| (u - v).powi(2))
                .sum::<f64>()
                .sqrt();
            let floor = if singular {
                (n as f64 * f64::EPSILON * max_abs(&R)).sqrt() * disp
            } else {
                0.0
            };
            assert!(
                (a.value - b.value).abs() <= 1e-9 * b.value.abs().max(1.0) + floor,
                "case {case}: output route {} vs state route {}",
                a.value,
                b.value
            );
            // The lifted witness is on the boundary and at the reported distance.
            let u: Vec<f64> = a.point.iter().zip(&cx).map(|(s, t)| s - t).collect();
            assert!((quad(&Qx, &u) - 1.0).abs() <= 1e-9 * abs_quad(&Qx, &u).max(1.0));
            assert!(
                (rdist(&R, &a.point, &x) - a.value.abs()).abs()
                    <= 1e-9 * a.value.abs().max(1.0) + floor
            );
            compared += 1;
        }
    }
    assert_eq!(compared, 1500);
}

/// {x : Cx ∈ {y : A_y y ≤ b}} = {x : A_y C x ≤ b}.
#[test]
fn output_polytope_equals_state_polytope() {
    let mut rng = ChaCha8Rng::seed_from_u64(82);
    for case in 0..60 {
        let n = rng.random_range(2..=5);
        let p = rng.random_range(1..=n);
        let C = gaussian(p * n, &mut rng);
        let k = rng.random_range(p + 1..=p + 4);
        let Ay = gaussian(k * p, &mut rng);
        let b: Vec<f64> = (0..k).map(|_| rng.random_range(0.3..1.5)).collect(); // 0 is inside
        let Ax = matmul(&Ay, &C, k, p, n);
        let out = InOutput::new(
            C.clone(),
            p,
            Box::new(Polytope::new(p, Ay, b.clone()).unwrap()),
        )
        .unwrap();
        let st = Polytope::new(n, Ax, b).unwrap();
        let R = random_pd(n, &mut rng, -0.5, 0.5);
        let metric = Metric::new(n, R.clone()).unwrap();
        for _ in 0..5 {
            let x = gaussian(n, &mut rng);
            assert_eq!(out.contains(&x), st.contains(&x));
            let a = out.signed_dist(&x, &metric);
            let s = st.signed_dist(&x, &metric);
            assert!(
                (a.value - s.value).abs() <= 1e-8 * s.value.abs().max(1.0),
                "case {case}: {} vs {}",
                a.value,
                s.value
            );
            assert!(
                (rdist(&R, &a.point, &x) - a.value.abs()).abs() <= 1e-8 * a.value.abs().max(1.0)
            );
        }
    }
}

/// A union's distance is its nearest member's; for disjoint members the depth is exact (upper bound equal);
/// the complement swaps distance and depth.
#[test]
fn union_and_complement_of_ellipsoids() {
    let mut rng = ChaCha8Rng::seed_from_u64(83);
    let metric = Metric::euclidean(3);
    for _ in 0..100 {
        // Two disjoint balls (centres 6 apart, radii ≤ 2).
        let c1 = gaussian(3, &mut rng);
        let dir = gaussian(3, &mut rng);
        let nd = dir.iter().map(|v| v * v).sum::<f64>().sqrt();
        let c2: Vec<f64> = c1.iter().zip(&dir).map(|(a, d)| a + 6.0 * d / nd).collect();
        let (r1, r2) = (rng.random_range(0.5..2.0), rng.random_range(0.5..2.0));
        let I = Metric::euclidean(3).R;
        let b1 = Ball::new(c1.clone(), I.clone(), r1).unwrap();
        let b2 = Ball::new(c2.clone(), I.clone(), r2).unwrap();
        let u = Union::new(vec![Box::new(b1.clone()), Box::new(b2.clone())]).unwrap();
        let x: Vec<f64> = c1
            .iter()
            .map(|v| v + 2.5 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        let d1 = rdist(&I, &x, &c1) - r1;
        let d2 = rdist(&I, &x, &c2) - r2;
        let sd = u.signed_dist(&x, &metric).value;
        if d1 > 0.0 && d2 > 0.0 {
            assert!((sd + d1.min(d2)).abs() < 1e-12);
        } else {
            let expect = (-d1).max(-d2);
            assert!((sd - expect).abs() < 1e-12, "{sd} vs {expect}");
            let (_, upper) = u.depth_bounds(&x, &metric).unwrap();
            assert!(
                (upper - sd).abs() < 1e-12,
                "disjoint members: depth is exact"
            );
        }
        let cu = Complement::new(Box::new(u)).unwrap();
        assert!((cu.signed_dist(&x, &metric).value + sd).abs() < 1e-12);
    }
}

/// Every compiled set gives `signed_dist`'s value bit for bit, at random points near and far, in random
/// metrics (diagonal ones too, where a box has its closed form): ellipsoids, balls, polytopes (boxes,
/// random rows, more rows than the active sets are enumerated for), sets over two of four coordinates
/// (Schur-complement metrics), their unions and complements; NaN for a bad point or a metric of another
/// dimension.
#[test]
fn compiled_signed_distance_equals_signed_dist() {
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let n = 4;
    for case in 0..40 {
        let metric = if case % 4 == 0 {
            let mut R = vec![0.0; n * n];
            (0..n).for_each(|i| R[i * n + i] = rng.random_range(0.5..2.0));
            Metric::new(n, R).unwrap()
        } else {
            Metric::new(n, random_pd(n, &mut rng, -1.0, 1.0)).unwrap()
        };
        // A box about a random centre, or k random rows about the origin (k up to 10).
        let poly = |rng: &mut ChaCha8Rng, d: usize| -> Box<dyn Region> {
            if rng.random_bool(0.5) {
                let c = gaussian(d, rng);
                let (mut A, mut b) = (vec![0.0; 2 * d * d], vec![0.0; 2 * d]);
                for i in 0..d {
                    let h = rng.random_range(0.2..1.5);
                    A[2 * i * d + i] = 1.0;
                    A[(2 * i + 1) * d + i] = -1.0;
                    b[2 * i] = c[i] + h;
                    b[2 * i + 1] = h - c[i];
                }
                Box::new(Polytope::new(d, A, b).unwrap())
            } else {
                let k = rng.random_range(d + 1..=10);
                let A: Vec<f64> = (0..k).flat_map(|_| gaussian(d, rng)).collect();
                let b: Vec<f64> = (0..k).map(|_| rng.random_range(0.3..1.5)).collect();
                Box::new(Polytope::new(d, A, b).unwrap())
            }
        };
        let ell = |rng: &mut ChaCha8Rng, d: usize| -> Box<dyn Region> {
            let c = gaussian(d, rng);
            if rng.random_bool(0.5) {
                Box::new(Ellipsoid::new(c, random_pd(d, rng, -0.5, 0.5)).unwrap())
            } else {
                let r = rng.random_range(0.1..1.0);
                Box::new(Ball::new(c, random_pd(d, rng, -0.5, 0.5), r).unwrap())
            }
        };
        let proj = |i: usize, j: usize| {
            let mut C = vec![0.0; 2 * n];
            C[i] = 1.0;
            C[n + j] = 1.0;
            C
        };
        let members: Vec<Box<dyn Region>> = vec![
            Box::new(InOutput::new(proj(0, 2), 2, ell(&mut rng, 2)).unwrap()),
            Box::new(InOutput::new(proj(1, 3), 2, ell(&mut rng, 2)).unwrap()),
            ell(&mut rng, n),
            Box::new(InOutput::new(proj(0, 1), 2, poly(&mut rng, 2)).unwrap()),
            poly(&mut rng, n),
        ];
        let set: Box<dyn Region> = if case % 2 == 0 {
            Box::new(Union::new(members).unwrap())
        } else {
            Box::new(Complement::new(Box::new(Union::new(members).unwrap())).unwrap())
        };
        let mut f = set.compile(&metric).expect("a compiled form");
        for _ in 0..200 {
            let scale = if rng.random_bool(0.5) { 0.5 } else { 4.0 };
            let x: Vec<f64> = (0..n).map(|_| rng.random_range(-scale..scale)).collect();
            let want = set.signed_dist(&x, &metric).value;
            let got = f.eval(&x).signed();
            assert_eq!(got.to_bits(), want.to_bits(), "case {case} at {x:?}");
        }
        assert!(f.eval(&[0.0, f64::NAN, 0.0, 0.0]).value.is_nan());
        assert!(f.eval(&[0.0; 3]).value.is_nan());
    }
    let p: Box<dyn Region> = Box::new(Polytope::new(1, vec![1.0], vec![0.0]).unwrap());
    let u = Union::new(vec![p]).unwrap();
    assert!(u.compile(&Metric::euclidean(2)).is_none());
}
