//! The §7.2 ellipsoid boundary distance: the dissertation's worked examples (7.3, 7.8) and property tests
//! against an independent global brute force (tests/host/geometry_common) on random problems, n = 2..12, with
//! degenerate and near-degenerate shapes, repeated eigenvalues, singular metrics, and points inside, outside,
//! on the axes and at the centre.
#![allow(non_snake_case)]

use crate::geometry_common;

use geometry_common::*;
use host_compiler::geometry::ellipsoid_distance::StandardForm;
use host_compiler::geometry::{
    BoundaryDistanceSettings, Ellipsoid, EllipsoidBoundaryDistance, Metric, OptimumKind, Region,
};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::sync::atomic::{AtomicUsize, Ordering};

// ---------------------------------------------------------------------------------------------------------
// Worked examples.

/// Example 7.3. The example states P = (√2/2)·[[1,0,0],[0,½,½],[0,½,½]], but its own computation of Q̂ and its
/// answer y* = (1, 2, −2) use the matrix without the √2/2 factor (with the factor, y* would violate the
/// constraint: y*ᵀPy* = √2/2). We use the matrix the example computes with. R = diag(Λ_R, 0) = diag(1, 1, 0),
/// x_c = 0, x̄ = (2, 2, 2).
#[test]
fn example_7_3_degenerate_metric_and_cylinder() {
    let Q = [1.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.5, 0.5];
    let R = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0];
    let f = EllipsoidBoundaryDistance::new(&[0.0; 3], &Q, &R).unwrap();
    assert_eq!(f.metric_rank(), 2);
    assert!(f.has_zero_cost_directions());
    let mut ws = f.workspace();
    let mut x = [0.0; 3];
    let s = f.solve(&[2.0, 2.0, 2.0], &mut ws, &mut x).unwrap();
    assert_eq!(s.kind, OptimumKind::Unique);
    for (got, want) in x.iter().zip([1.0, 2.0, -2.0]) {
        assert!((got - want).abs() < 1e-12, "y* = {x:?}");
    }
    assert!((s.value - 1.0).abs() < 1e-12);
    // The reduced problem (z₁ − 2)² s.t. z₁² = 1 has value 1.
    let b = brute_force(&[0.0; 3], &Q, &R, &[2.0, 2.0, 2.0]);
    assert!((b.value - 1.0).abs() < 1e-9, "brute force {}", b.value);
}

/// Example 7.8: Q = diag(9, 4, 1), R = I, x̄ = (0, 0.25, 0.1) lies in the set (7.32) of points with multiple
/// optima; x* = (±0.1404, 0.45, 0.1125).
#[test]
fn example_7_8_multiple_optima() {
    let x1 = ((1.0 - 4.0 * 0.45_f64.powi(2) - 0.1125_f64.powi(2)) / 9.0).sqrt();
    assert!((x1 - 0.1404).abs() < 5e-5);
    let want_value = (x1 * x1 + 0.2_f64.powi(2) + 0.0125_f64.powi(2)).sqrt();

    // Directly in the standard form (7.5) (R = I and Q diagonal: the transformation is the identity).
    let sf = StandardForm::new(vec![9.0, 4.0, 1.0]).unwrap();
    let mut z = [0.0; 3];
    let s = sf.solve(
        &[0.0, 0.25, 0.1],
        &mut z,
        &BoundaryDistanceSettings::default(),
    );
    assert_eq!(s.kind, OptimumKind::Multiple);
    assert!((s.mu + 1.0 / 9.0).abs() < 1e-15);
    assert!(
        (z[0].abs() - x1).abs() < 1e-14
            && (z[1] - 0.45).abs() < 1e-14
            && (z[2] - 0.1125).abs() < 1e-14
    );
    assert!((s.value_sq.sqrt() - want_value).abs() < 1e-14);

    // Through the full pipeline.
    let Q = [9.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 1.0];
    let e = Ellipsoid::new(vec![0.0; 3], Q.to_vec()).unwrap();
    let w = e.depth(&[0.0, 0.25, 0.1], &Metric::euclidean(3));
    assert!((w.point[0].abs() - x1).abs() < 1e-12, "{:?}", w.point);
    assert!((w.point[1] - 0.45).abs() < 1e-12 && (w.point[2] - 0.1125).abs() < 1e-12);
    assert!((w.value - want_value).abs() < 1e-12);

    // (7.32): x̄₁ = 0 and (324/25)x̄₂² + (81/64)x̄₃² < 1 ⇔ multiple optima; just outside that ellipse, or off the
    // plane x̄₁ = 0, the optimum is unique.
    let inside = |x2: f64, x3: f64| 324.0 / 25.0 * x2 * x2 + 81.0 / 64.0 * x3 * x3 < 1.0;
    for (zb, multiple) in [
        ([0.0, 0.25, 0.1], true),
        ([0.0, 0.0, 0.8], true),
        ([0.0, 0.0, 0.95], false),
        ([0.0, 0.28, 0.0], false),
        ([1e-3, 0.25, 0.1], false),
    ] {
        assert_eq!(zb[0] == 0.0 && inside(zb[1], zb[2]), multiple);
        let s = sf.solve(&zb, &mut z, &BoundaryDistanceSettings::default());
        assert_eq!(s.kind == OptimumKind::Multiple, multiple, "z̄ = {zb:?}");
        let b = brute_force(&[0.0; 3], &Q, &Metric::euclidean(3).R, &zb);
        assert!(
            (s.value_sq.sqrt() - b.value).abs() < 1e-9,
            "z̄ = {zb:?}: {} vs {}",
            s.value_sq.sqrt(),
            b.value
        );
    }
}

/// Lemma 7.10: G(µ₀) ≥ 0 at the start (7.45), so the iteration climbs monotonically to µ*.
#[test]
fn start_point_is_below_the_root() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..2000 {
        let q = rng.random_range(1..=12);
        let lam: Vec<f64> = (0..q)
            .map(|_| 10f64.powf(rng.random_range(-3.0..3.0)))
            .collect();
        let sf = StandardForm::new(lam).unwrap();
        let zbar: Vec<f64> = (0..q)
            .map(|_| rng.sample::<f64, _>(StandardNormal) * 10f64.powf(rng.random_range(-3.0..2.0)))
            .collect();
        let d0 = sf.start(&zbar);
        let (G, _) = sf.secular(&zbar, d0);
        assert!(G >= -1e-12, "G(µ₀) = {G}");
        let hi = sf.upper_bound(&zbar);
        let (Gh, _) = sf.secular(&zbar, hi);
        assert!(Gh <= 1e-12, "G(hi) = {Gh}");
    }
}

// ---------------------------------------------------------------------------------------------------------
// Property tests against the brute force.

#[derive(Clone, Copy, Debug)]
enum QKind {
    Generic,
    Repeated,
    NearRepeated,
    NearDegenerate,
    Degenerate,
    AxisAlignedRepeated,
}

#[derive(Clone, Copy, Debug)]
enum RKind {
    Identity,
    RandomPd,
    NearSingular,
    Singular,
    NullInsideQNull,
}

#[derive(Clone, Copy, Debug)]
enum PointKind {
    Inside,
    Outside,
    Far,
    OnAxis,
    OffTopEigenspace,
    Centre,
    NearBoundary,
}

#[derive(Debug)]
struct Problem {
    c: Vec<f64>,
    Q: Vec<f64>,
    R: Vec<f64>,
    xbar: Vec<f64>,
}

fn pick<T: Copy>(rng: &mut ChaCha8Rng, xs: &[T]) -> T {
    xs[rng.random_range(0..xs.len())]
}

fn make_problem(n: usize, qk: QKind, rk: RKind, pk: PointKind, seed: u64) -> Problem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let c: Vec<f64> = (0..n).map(|_| rng.random_range(-3.0..3.0)).collect();
    // Q's spectrum.
    let mut sig: Vec<f64> = (0..n)
        .map(|_| 10f64.powf(rng.random_range(-1.0..1.0)))
        .collect();
    let repeated = |rng: &mut ChaCha8Rng| -> Vec<f64> {
        let m = rng.random_range(1..=3usize);
        let vals: Vec<f64> = (0..m)
            .map(|_| 10f64.powf(rng.random_range(-1.0..1.0)))
            .collect();
        let top = vals.iter().cloned().fold(f64::MIN, f64::max);
        let mut s: Vec<f64> = (0..n).map(|_| pick(rng, &vals)).collect();
        // Make the largest eigenvalue repeated (M ≥ 2) most of the time.
        if rng.random_bool(0.8) {
            s[0] = top;
            s[1] = top;
        }
        s
    };
    match qk {
        QKind::Generic => {}
        QKind::Repeated | QKind::AxisAlignedRepeated => sig = repeated(&mut rng),
        QKind::NearRepeated => {
            sig = repeated(&mut rng);
            let eps = pick(&mut rng, &[1e-13, 1e-10, 1e-7]);
            for s in sig.iter_mut() {
                *s *= 1.0 + eps * rng.random_range(-1.0..1.0);
            }
        }
        QKind::NearDegenerate => {
            let smax = sig.iter().cloned().fold(0.0, f64::max);
            let k = rng.random_range(1..=n.div_ceil(2));
            for s in sig.iter_mut().take(k) {
                *s = smax * 10f64.powf(rng.random_range(-6.0..-4.0));
            }
        }
        QKind::Degenerate => {
            let k = rng.random_range(1..n);
            for s in sig.iter_mut().take(k) {
                *s = 0.0;
            }
        }
    }
    // Shuffle so that the special eigenvalues are not always first.
    for i in (1..n).rev() {
        let j = rng.random_range(0..=i);
        sig.swap(i, j);
    }
    let V = match qk {
        QKind::AxisAlignedRepeated => {
            let mut V = vec![0.0; n * n];
            for i in 0..n {
                V[i * n + i] = 1.0;
            }
            V
        }
        _ => random_orthogonal(n, &mut rng),
    };
    let Q = compose(n, &V, &sig);
    // R.
    let rho_pd = |rng: &mut ChaCha8Rng| -> Vec<f64> {
        (0..n)
            .map(|_| 10f64.powf(rng.random_range(-0.7..0.7)))
            .collect()
    };
    let R = match rk {
        RKind::Identity => Metric::euclidean(n).R,
        RKind::RandomPd => compose(n, &random_orthogonal(n, &mut rng), &rho_pd(&mut rng)),
        RKind::NearSingular => {
            let mut r = rho_pd(&mut rng);
            r[0] = 1e-6;
            compose(n, &random_orthogonal(n, &mut rng), &r)
        }
        RKind::Singular => {
            let mut r = rho_pd(&mut rng);
            let k = rng.random_range(1..n);
            for v in r.iter_mut().take(k) {
                *v = 0.0;
            }
            compose(n, &random_orthogonal(n, &mut rng), &r)
        }
        RKind::NullInsideQNull => {
            // R's null space: a nonempty part of Q's null space (if Q has one; otherwise R is just PD).
            let mut r = rho_pd(&mut rng);
            let null: Vec<usize> = (0..n).filter(|&i| sig[i] == 0.0).collect();
            if !null.is_empty() {
                let k = rng.random_range(1..=null.len());
                for &i in null.iter().take(k) {
                    r[i] = 0.0;
                }
            }
            compose(n, &V, &r)
        }
    };
    // The point, built in Q's eigenbasis: u = V w.
    let smax = sig.iter().cloned().fold(0.0, f64::max);
    let level_scaled = |rng: &mut ChaCha8Rng, rho: f64| -> Vec<f64> {
        let w: Vec<f64> = (0..n)
            .map(|_| rng.sample::<f64, _>(StandardNormal))
            .collect();
        let h: f64 = (0..n).map(|i| sig[i] * w[i] * w[i]).sum();
        let s = rho / h.sqrt();
        w.iter().map(|x| x * s).collect()
    };
    let w: Vec<f64> = match pk {
        PointKind::Inside => {
            let rho = rng.random_range(0.05..0.95);
            level_scaled(&mut rng, rho)
        }
        PointKind::Outside => {
            let rho = rng.random_range(1.05..4.0);
            level_scaled(&mut rng, rho)
        }
        PointKind::Far => {
            let rho = rng.random_range(20.0..100.0);
            level_scaled(&mut rng, rho)
        }
        PointKind::NearBoundary => {
            let rho = 1.0 + pick(&mut rng, &[-1e-7, 1e-7, -1e-10, 1e-10]);
            level_scaled(&mut rng, rho)
        }
        PointKind::OnAxis => {
            let j = rng.random_range(0..n);
            let mut w = vec![0.0; n];
            let a = rng.random_range(0.05..3.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            w[j] = if sig[j] > 0.0 { a / sig[j].sqrt() } else { a };
            w
        }
        PointKind::OffTopEigenspace => (0..n)
            .map(|i| {
                if sig[i] >= smax * (1.0 - 1e-6) {
                    0.0
                } else {
                    rng.sample::<f64, _>(StandardNormal) * rng.random_range(0.0..0.6) / smax.sqrt()
                }
            })
            .collect(),
        PointKind::Centre => vec![0.0; n],
    };
    let u = matvec(&V, n, n, &w);
    let xbar = (0..n).map(|i| c[i] + u[i]).collect();
    Problem { c, Q, R, xbar }
}

static UNIQUE: AtomicUsize = AtomicUsize::new(0);
static MULTIPLE: AtomicUsize = AtomicUsize::new(0);
static ZERO_COST: AtomicUsize = AtomicUsize::new(0);
static INSIDE: AtomicUsize = AtomicUsize::new(0);
static OUTSIDE: AtomicUsize = AtomicUsize::new(0);

/// `singular_metric`: R was built with exact zero eigenvalues and then rotated, so its null space is only known
/// to rounding (eigenvalues ~±1e-16·‖R‖). A seminorm is square-root conditioned there: a displacement d along
/// the computed null space has ‖d‖_R up to sqrt(n·ε·‖R‖)·‖d‖, which no algorithm can resolve below. For those
/// problems that floor is added to the 1e-9 tolerances.
fn check_problem(p: &Problem, singular_metric: bool) -> Result<(), TestCaseError> {
    let n = p.c.len();
    let f = EllipsoidBoundaryDistance::new(&p.c, &p.Q, &p.R)
        .map_err(|e| TestCaseError::fail(format!("factor: {e}")))?;
    let mut ws = f.workspace();
    let mut x = vec![0.0; n];
    let s = f
        .solve(&p.xbar, &mut ws, &mut x)
        .map_err(|e| TestCaseError::fail(format!("solve: {e}")))?;
    match s.kind {
        OptimumKind::Unique => UNIQUE.fetch_add(1, Ordering::Relaxed),
        OptimumKind::Multiple => MULTIPLE.fetch_add(1, Ordering::Relaxed),
        OptimumKind::ZeroCost => ZERO_COST.fetch_add(1, Ordering::Relaxed),
    };
    // Feasible: on the boundary to 1e-9, plus 1e-12 of the rounding scale |u|ᵀ|Q||u| of evaluating the
    // constraint (which exceeds 1 when far-apart terms cancel, e.g. long thin ellipsoids in rotated coordinates).
    let u: Vec<f64> = x.iter().zip(&p.c).map(|(a, b)| a - b).collect();
    let h = quad(&p.Q, &u);
    let hscale = abs_quad(&p.Q, &u);
    prop_assert!(
        (h - 1.0).abs() <= 1e-9 + 1e-12 * hscale,
        "infeasible: h(x*) = {h} (scale {hscale}), kind {:?}",
        s.kind
    );
    // The value is the distance to the returned point.
    let floor_for = |d: &[f64]| -> f64 {
        if singular_metric {
            let disp = d
                .iter()
                .zip(&p.xbar)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            (n as f64 * f64::EPSILON * max_abs(&p.R)).sqrt() * disp
        } else {
            0.0
        }
    };
    let vx = rdist(&p.R, &x, &p.xbar);
    prop_assert!(
        (vx - s.value).abs() <= 1e-9 * s.value.max(1.0) + floor_for(&x),
        "value {} but ‖x* − x̄‖_R = {vx}",
        s.value
    );
    // Optimal: agrees with the global brute force.
    let b = brute_force(&p.c, &p.Q, &p.R, &p.xbar);
    prop_assert!(b.value.is_finite(), "brute force found no candidate");
    let tol = 1e-9 * b.value.max(1.0) + floor_for(&x).max(floor_for(&b.point));
    prop_assert!(
        (s.value - b.value).abs() <= tol,
        "value {} vs brute force {} (diff {:e}), kind {:?}, {} candidates",
        s.value,
        b.value,
        s.value - b.value,
        s.kind,
        b.candidates
    );
    // The batch form and the value-only path give the same numbers.
    let dv = f.distance(&p.xbar, &mut ws).unwrap();
    prop_assert!((dv - s.value).abs() <= 1e-15 * s.value.max(1.0));
    // Region semantics: signed distance is depth inside, −dist outside, with the same magnitude.
    let e = Ellipsoid::new(p.c.clone(), p.Q.clone()).unwrap();
    let m = Metric::new(n, p.R.clone()).unwrap();
    let sd = e.try_signed_dist(&p.xbar, &m).unwrap();
    if e.contains(&p.xbar) {
        INSIDE.fetch_add(1, Ordering::Relaxed);
        prop_assert!(sd.value >= 0.0 && (sd.value - s.value).abs() <= tol);
        prop_assert!(e.dist(&p.xbar, &m).value == 0.0);
    } else {
        OUTSIDE.fetch_add(1, Ordering::Relaxed);
        prop_assert!(sd.value <= 0.0 && (-sd.value - s.value).abs() <= tol);
        prop_assert!(e.depth(&p.xbar, &m).value == 0.0);
    }
    Ok(())
}

fn strategy() -> impl Strategy<Value = (usize, QKind, RKind, PointKind, u64)> {
    (
        2usize..=12,
        prop_oneof![
            Just(QKind::Generic),
            Just(QKind::Repeated),
            Just(QKind::NearRepeated),
            Just(QKind::NearDegenerate),
            Just(QKind::Degenerate),
            Just(QKind::AxisAlignedRepeated)
        ],
        prop_oneof![
            Just(RKind::Identity),
            Just(RKind::RandomPd),
            Just(RKind::NearSingular),
            Just(RKind::Singular),
            Just(RKind::NullInsideQNull)
        ],
        prop_oneof![
            Just(PointKind::Inside),
            Just(PointKind::Outside),
            Just(PointKind::Far),
            Just(PointKind::OnAxis),
            Just(PointKind::OffTopEigenspace),
            Just(PointKind::Centre),
            Just(PointKind::NearBoundary)
        ],
        any::<u64>(),
    )
}

#[test]
fn matches_global_brute_force() {
    let config = Config {
        cases: 1500,
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(0x724),
        ..Config::default()
    };
    let mut runner = TestRunner::new(config);
    let result = runner.run(&strategy(), |(n, qk, rk, pk, seed)| {
        let p = make_problem(n, qk, rk, pk, seed);
        let singular = matches!(rk, RKind::Singular | RKind::NullInsideQNull);
        check_problem(&p, singular).map_err(|e| {
            TestCaseError::fail(format!(
                "{e}\nproblem: n={n} {qk:?} {rk:?} {pk:?} seed={seed}"
            ))
        })
    });
    if let Err(e) = result {
        panic!("{e}");
    }
    let (u, m, z) = (
        UNIQUE.load(Ordering::Relaxed),
        MULTIPLE.load(Ordering::Relaxed),
        ZERO_COST.load(Ordering::Relaxed),
    );
    let (i, o) = (
        INSIDE.load(Ordering::Relaxed),
        OUTSIDE.load(Ordering::Relaxed),
    );
    println!("kinds: unique {u}, multiple {m}, zero-cost {z}; inside {i}, outside {o}");
    // Every branch of the algorithm was exercised.
    assert!(
        u > 100 && m > 5 && z > 20 && i > 100 && o > 100,
        "coverage: {u} {m} {z} {i} {o}"
    );
}

/// Points placed exactly in W⊥ of axis-aligned ellipsoids with repeated largest eigenvalue, R = I: the
/// multiple-optima branch (7.25)–(7.26), checked against the brute force.
#[test]
fn multiple_optima_branch_against_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(78);
    let mut multiple = 0;
    for _ in 0..300 {
        let n = rng.random_range(2..=8);
        let p = make_problem(
            n,
            QKind::AxisAlignedRepeated,
            RKind::Identity,
            PointKind::OffTopEigenspace,
            rng.random(),
        );
        let f = EllipsoidBoundaryDistance::new(&p.c, &p.Q, &p.R).unwrap();
        let mut ws = f.workspace();
        let mut x = vec![0.0; n];
        let s = f.solve(&p.xbar, &mut ws, &mut x).unwrap();
        if s.kind == OptimumKind::Multiple {
            multiple += 1;
        }
        let b = brute_force(&p.c, &p.Q, &p.R, &p.xbar);
        assert!(
            (s.value - b.value).abs() <= 1e-9 * b.value.max(1.0),
            "{} vs {}: {p:?}",
            s.value,
            b.value
        );
        let u: Vec<f64> = x.iter().zip(&p.c).map(|(a, b)| a - b).collect();
        assert!((quad(&p.Q, &u) - 1.0).abs() < 1e-12);
    }
    assert!(multiple > 50, "only {multiple} multiple-optima cases");
}

/// The batch form answers like the single-point form and validates its buffers.
#[test]
fn batch_matches_single_points() {
    let p = make_problem(5, QKind::Generic, RKind::RandomPd, PointKind::Inside, 11);
    let f = EllipsoidBoundaryDistance::new(&p.c, &p.Q, &p.R).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let N = 50;
    let pts: Vec<f64> = (0..N * 5)
        .map(|k| p.c[k % 5] + rng.random_range(-2.0..2.0))
        .collect();
    let mut vals = vec![0.0; N];
    let mut wit = vec![0.0; N * 5];
    f.solve_batch(&pts, &mut vals, Some(&mut wit)).unwrap();
    let mut ws = f.workspace();
    let mut x = vec![0.0; 5];
    for k in 0..N {
        let s = f.solve(&pts[k * 5..(k + 1) * 5], &mut ws, &mut x).unwrap();
        assert_eq!(s.value, vals[k]);
        assert_eq!(&x[..], &wit[k * 5..(k + 1) * 5]);
    }
    let mut vals2 = vec![0.0; N];
    f.solve_batch(&pts, &mut vals2, None).unwrap();
    assert_eq!(vals, vals2);
    assert!(f.solve_batch(&pts[..7], &mut vals, None).is_err());
    assert!(f.solve_batch(&pts, &mut vals[..3], None).is_err());
}

/// Regression: rank-one metric with a near-degenerate Q; the reconstruction through P₂₂⁺ (condition ~6e5) left
/// the point off the constraint by 2.7e-7, and with the multiplier µ* ≈ 1.3e4 the value was 1e-6 too small.
/// The per-point constraint check now triggers the refinement.
#[test]
fn singular_metric_reconstruction_is_refined() {
    let p = make_problem(
        5,
        QKind::NearDegenerate,
        RKind::Singular,
        PointKind::Far,
        4789014612021199497,
    );
    let f = EllipsoidBoundaryDistance::new(&p.c, &p.Q, &p.R).unwrap();
    assert_eq!(f.metric_rank(), 1);
    let mut ws = f.workspace();
    let mut x = vec![0.0; 5];
    let s = f.solve(&p.xbar, &mut ws, &mut x).unwrap();
    let u: Vec<f64> = x.iter().zip(&p.c).map(|(a, b)| a - b).collect();
    assert!(
        (quad(&p.Q, &u) - 1.0).abs() < 1e-10,
        "h(x*) = {}",
        quad(&p.Q, &u)
    );
    let b = brute_force(&p.c, &p.Q, &p.R, &p.xbar);
    assert!(
        (s.value - b.value).abs() <= 1e-9 * b.value,
        "{} vs {}",
        s.value,
        b.value
    );
}

/// Regression: a near-degenerate Q (λ ratio ~1e-5) in a near-singular metric (ρ ratio 1e-6) gives a standard
/// form with λmax/λmin ≈ 3e10, whose small eigenvalue is only known to ~1e-6 relative. Before the Newton
/// refinement in the original coordinates, the returned point violated the constraint by 3.7e-6.
#[test]
fn ill_conditioned_standard_form_is_refined() {
    let p = make_problem(
        2,
        QKind::NearDegenerate,
        RKind::NearSingular,
        PointKind::Far,
        4702353144985464639,
    );
    let f = EllipsoidBoundaryDistance::new(&p.c, &p.Q, &p.R).unwrap();
    let sf = f.standard_form().unwrap();
    assert!(
        sf.lambda()[0] / sf.lambda()[1] > 1e9,
        "the case is no longer ill-conditioned"
    );
    let mut ws = f.workspace();
    let mut x = vec![0.0; 2];
    let s = f.solve(&p.xbar, &mut ws, &mut x).unwrap();
    let u: Vec<f64> = x.iter().zip(&p.c).map(|(a, b)| a - b).collect();
    assert!(
        (quad(&p.Q, &u) - 1.0).abs() < 1e-12,
        "h(x*) = {}",
        quad(&p.Q, &u)
    );
    let b = brute_force(&p.c, &p.Q, &p.R, &p.xbar);
    assert!(
        (s.value - b.value).abs() <= 1e-9 * b.value,
        "{} vs {}",
        s.value,
        b.value
    );
    assert!((rdist(&p.R, &x, &p.xbar) - s.value).abs() <= 1e-12 * s.value);
}
