//! Polytope distance (QP (7.1) with clarabel + active-set polish) and depth (by facets) against independent
//! checks: brute force over all active sets for small problems, KKT verification for larger ones, and
//! sampled boundary points for the depth.
#![allow(non_snake_case)]

use crate::geometry_common;

use geometry_common::*;
use host_compiler::geometry::{Metric, Polytope, Region};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Solve a square system by Gaussian elimination with partial pivoting; `None` if (numerically) singular.
fn gauss(m: usize, mut A: Vec<f64>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let scale = A.iter().fold(0.0_f64, |a, v| a.max(v.abs())).max(1e-300);
    for k in 0..m {
        let p = (k..m).max_by(|&i, &j| A[i * m + k].abs().total_cmp(&A[j * m + k].abs()))?;
        if A[p * m + k].abs() <= 1e-12 * scale {
            return None;
        }
        for j in 0..m {
            A.swap(k * m + j, p * m + j);
        }
        b.swap(k, p);
        for i in k + 1..m {
            let f = A[i * m + k] / A[k * m + k];
            for j in k..m {
                A[i * m + j] -= f * A[k * m + j];
            }
            b[i] -= f * b[k];
        }
    }
    let mut x = vec![0.0; m];
    for k in (0..m).rev() {
        let s: f64 = (k + 1..m).map(|j| A[k * m + j] * x[j]).sum();
        x[k] = (b[k] - s) / A[k * m + k];
    }
    Some(x)
}

/// min ½dᵀRd s.t. A_J d = rhs_J via the KKT system (R positive definite); `None` if the rows are dependent.
fn equality_qp(n: usize, R: &[f64], A: &[f64], rhs: &[f64], J: &[usize]) -> Option<Vec<f64>> {
    let m = n + J.len();
    let mut K = vec![0.0; m * m];
    let mut f = vec![0.0; m];
    for i in 0..n {
        for j in 0..n {
            K[i * m + j] = R[i * n + j];
        }
    }
    for (r, &i) in J.iter().enumerate() {
        for j in 0..n {
            K[(n + r) * m + j] = A[i * n + j];
            K[j * m + n + r] = A[i * n + j];
        }
        f[n + r] = rhs[i];
    }
    let mut s = gauss(m, K, f)?;
    s.truncate(n);
    Some(s)
}

fn subsets(k: usize, max: usize) -> Vec<Vec<usize>> {
    let mut out = vec![vec![]];
    for i in 0..k {
        let mut more = Vec::new();
        for s in &out {
            if s.len() < max {
                let mut t = s.clone();
                t.push(i);
                more.push(t);
            }
        }
        out.extend(more);
    }
    out
}

struct Poly {
    n: usize,
    A: Vec<f64>,
    b: Vec<f64>,
    interior: Vec<f64>,
}

fn random_poly(n: usize, k: usize, rng: &mut ChaCha8Rng) -> Poly {
    let p0: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
    let mut A = Vec::with_capacity(k * n);
    let mut b = Vec::with_capacity(k);
    for _ in 0..k {
        let a: Vec<f64> = (0..n)
            .map(|_| rng.sample::<f64, _>(StandardNormal))
            .collect();
        let ap: f64 = a.iter().zip(&p0).map(|(x, y)| x * y).sum();
        b.push(ap + rng.random_range(0.2..1.5));
        A.extend(a);
    }
    Poly {
        n,
        A,
        b,
        interior: p0,
    }
}

fn random_pd(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let d: Vec<f64> = (0..n)
        .map(|_| 10f64.powf(rng.random_range(-1.0..1.0)))
        .collect();
    compose(n, &random_orthogonal(n, rng), &d)
}

fn violation(p: &Poly, x: &[f64]) -> f64 {
    let n = p.n;
    (0..p.b.len())
        .map(|i| (0..n).map(|j| p.A[i * n + j] * x[j]).sum::<f64>() - p.b[i])
        .fold(f64::NEG_INFINITY, f64::max)
}

#[test]
fn distance_matches_active_set_brute_force() {
    let config = Config {
        cases: 300,
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(71),
        ..Config::default()
    };
    let mut runner = TestRunner::new(config);
    let result = runner.run(
        &(2usize..=4, 0usize..4, any::<u64>()),
        |(n, extra, seed)| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let k = n + 1 + extra;
            let p = random_poly(n, k, &mut rng);
            let R = random_pd(n, &mut rng);
            let poly = Polytope::new(n, p.A.clone(), p.b.clone()).unwrap();
            let metric = Metric::new(n, R.clone()).unwrap();
            let x: Vec<f64> = p
                .interior
                .iter()
                .map(|v| v + 4.0 * rng.sample::<f64, _>(StandardNormal))
                .collect();
            if poly.contains(&x) {
                return Ok(());
            }
            let w = poly
                .try_dist(&x, &metric)
                .map_err(|e| TestCaseError::fail(e.to_string()))?;
            // Brute force: every active set of at most n rows.
            let rhs: Vec<f64> = (0..k)
                .map(|i| p.b[i] - (0..n).map(|j| p.A[i * n + j] * x[j]).sum::<f64>())
                .collect();
            let mut best = f64::INFINITY;
            for J in subsets(k, n) {
                if let Some(d) = equality_qp(n, &R, &p.A, &rhs, &J) {
                    let feas = (0..k).all(|i| {
                        (0..n).map(|j| p.A[i * n + j] * d[j]).sum::<f64>() <= rhs[i] + 1e-10
                    });
                    if feas {
                        best = best.min(quad(&R, &d).max(0.0).sqrt());
                    }
                }
            }
            prop_assert!(best.is_finite());
            prop_assert!(
                (w.value - best).abs() <= 1e-9 * best.max(1.0),
                "QP {} vs brute force {best}",
                w.value
            );
            prop_assert!(
                violation(&p, &w.point) <= 1e-9,
                "witness violates by {}",
                violation(&p, &w.point)
            );
            prop_assert!((rdist(&R, &w.point, &x) - w.value).abs() <= 1e-9 * w.value.max(1.0));
            prop_assert!(
                (poly.signed_dist(&x, &metric).value + w.value).abs() <= 1e-12 * w.value.max(1.0)
            );
            Ok(())
        },
    );
    if let Err(e) = result {
        panic!("{e}");
    }
}

/// Larger problems: the answer satisfies the KKT conditions of (7.1) — primal feasibility, and
/// R d + A_Jᵀν = 0 with ν ≥ 0 on the active rows J (ν by least squares).
#[test]
fn distance_satisfies_kkt_in_higher_dimension() {
    let mut rng = ChaCha8Rng::seed_from_u64(72);
    let mut checked = 0;
    for _ in 0..120 {
        let n = rng.random_range(5..=9);
        let k = rng.random_range(n + 1..=2 * n + 3);
        let p = random_poly(n, k, &mut rng);
        let R = random_pd(n, &mut rng);
        let poly = Polytope::new(n, p.A.clone(), p.b.clone()).unwrap();
        let metric = Metric::new(n, R.clone()).unwrap();
        let x: Vec<f64> = p
            .interior
            .iter()
            .map(|v| v + 4.0 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        if poly.contains(&x) {
            continue;
        }
        let w = poly.dist(&x, &metric);
        assert!(violation(&p, &w.point) <= 1e-9);
        let d: Vec<f64> = w.point.iter().zip(&x).map(|(a, b)| a - b).collect();
        let J: Vec<usize> = (0..k)
            .filter(|&i| (0..n).map(|j| p.A[i * n + j] * w.point[j]).sum::<f64>() - p.b[i] >= -1e-8)
            .collect();
        if J.is_empty() || J.len() > n {
            continue;
        }
        // Least squares for ν: (A_J A_Jᵀ) ν = −A_J R d.
        let Rd = matvec(&R, n, n, &d);
        let m = J.len();
        let mut G = vec![0.0; m * m];
        let mut f = vec![0.0; m];
        for (r, &i) in J.iter().enumerate() {
            for (s, &l) in J.iter().enumerate() {
                G[r * m + s] = (0..n).map(|j| p.A[i * n + j] * p.A[l * n + j]).sum();
            }
            f[r] = -(0..n).map(|j| p.A[i * n + j] * Rd[j]).sum::<f64>();
        }
        let Some(nu) = gauss(m, G, f) else { continue };
        let scale = 1.0 + Rd.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        for &v in &nu {
            assert!(v >= -1e-7 * scale, "negative multiplier {v}");
        }
        for (j, &rdj) in Rd.iter().enumerate() {
            let s: f64 = rdj
                + J.iter()
                    .enumerate()
                    .map(|(r, &i)| nu[r] * p.A[i * n + j])
                    .sum::<f64>();
            assert!(s.abs() <= 1e-7 * scale, "stationarity residual {s}");
        }
        checked += 1;
    }
    assert!(checked > 50, "only {checked} problems checked");
}

#[test]
fn depth_matches_nearest_facet_and_sampled_boundary() {
    let mut rng = ChaCha8Rng::seed_from_u64(73);
    let mut checked = 0;
    for _ in 0..200 {
        let n = rng.random_range(2..=6);
        let k = rng.random_range(n + 1..=2 * n + 2);
        let p = random_poly(n, k, &mut rng);
        let R = random_pd(n, &mut rng);
        let poly = Polytope::new(n, p.A.clone(), p.b.clone()).unwrap();
        let metric = Metric::new(n, R.clone()).unwrap();
        let x: Vec<f64> = p
            .interior
            .iter()
            .map(|v| v + 0.2 * rng.sample::<f64, _>(StandardNormal))
            .collect();
        if !poly.contains(&x) {
            continue;
        }
        let w = poly.depth(&x, &metric);
        // Independent: each facet's hyperplane distance from the equality QP with one row.
        let rhs: Vec<f64> = (0..k)
            .map(|i| p.b[i] - (0..n).map(|j| p.A[i * n + j] * x[j]).sum::<f64>())
            .collect();
        let best = (0..k)
            .filter_map(|i| equality_qp(n, &R, &p.A, &rhs, &[i]))
            .map(|d| quad(&R, &d).max(0.0).sqrt())
            .fold(f64::INFINITY, f64::min);
        assert!(
            (w.value - best).abs() <= 1e-12 * best.max(1.0),
            "{} vs {best}",
            w.value
        );
        // The witness is on the boundary at that distance.
        assert!(violation(&p, &w.point).abs() <= 1e-12);
        assert!((rdist(&R, &w.point, &x) - w.value).abs() <= 1e-12);
        // No sampled boundary point is closer.
        for _ in 0..50 {
            let i = rng.random_range(0..k);
            let y: Vec<f64> = x
                .iter()
                .map(|v| v + rng.sample::<f64, _>(StandardNormal))
                .collect();
            let a = &p.A[i * n..(i + 1) * n];
            let t = (p.b[i] - a.iter().zip(&y).map(|(u, v)| u * v).sum::<f64>())
                / a.iter().map(|v| v * v).sum::<f64>();
            let yb: Vec<f64> = y.iter().zip(a).map(|(v, ai)| v + t * ai).collect();
            if violation(&p, &yb) <= 1e-12 {
                assert!(rdist(&R, &yb, &x) >= w.value - 1e-12);
            }
        }
        checked += 1;
    }
    assert!(checked > 100, "only {checked} interior points");
}

/// With a singular metric, a facet whose normal has a component in the metric's null space is reached at
/// zero cost: generic rows then make the depth 0, with the witness on the boundary.
#[test]
fn depth_in_singular_metric() {
    let mut rng = ChaCha8Rng::seed_from_u64(74);
    for _ in 0..50 {
        let n = rng.random_range(2..=5);
        let k = rng.random_range(n + 1..=2 * n);
        let p = random_poly(n, k, &mut rng);
        let mut d: Vec<f64> = (0..n).map(|_| rng.random_range(0.5..2.0)).collect();
        d[0] = 0.0;
        let R = compose(n, &random_orthogonal(n, &mut rng), &d);
        let poly = Polytope::new(n, p.A.clone(), p.b.clone()).unwrap();
        let metric = Metric::new(n, R.clone()).unwrap();
        let w = poly.depth(&p.interior, &metric);
        assert_eq!(w.value, 0.0);
        assert!(
            violation(&p, &w.point).abs() <= 1e-10,
            "{}",
            violation(&p, &w.point)
        );
        let disp = w
            .point
            .iter()
            .zip(&p.interior)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            rdist(&R, &w.point, &p.interior)
                <= (n as f64 * f64::EPSILON * 2.0).sqrt() * disp + 1e-12
        );
    }
}
