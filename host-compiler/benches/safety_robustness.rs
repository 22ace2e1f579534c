//! Throughput of the Theorem 4.7 safety robustness on a 10⁵-sample trajectory in ℝ⁴ against ellipsoidal
//! Goal and Unsafe sets in a CAF metric (geometry's `Ellipsoid`, passed as `SafetySet::Ellipsoid`, the
//! prepared allocation-free path). Baseline in the same run: the same computation with the sets passed
//! as generic regions (`SafetySet::Region`, one `Region::signed_dist` per query); the results are
//! asserted equal. Ratio = ours / baseline throughput.
//!
//! Rows: `safety_robustness_samples_per_s`, `safety_robustness_joint_samples_per_s`.

#![allow(non_upper_case_globals, non_snake_case)]

use criterion::{criterion_group, Criterion};
use host_compiler::benchkit::{write_rows, Row};
use host_compiler::geometry::{Ellipsoid, Metric};
use host_compiler::robustness::{
    safety_robustness, safety_robustness_joint, SafetySet, SafetySpec, SampledTrajectory,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::{Duration, Instant};

const N: usize = 100_000;
const n: usize = 4;

struct Setup {
    t: Vec<f64>,
    x: Vec<f64>,
    goal: Ellipsoid,
    unsafe_set: Ellipsoid,
    metric: Metric,
}

fn diag(d: &[f64]) -> Vec<f64> {
    let k = d.len();
    let mut m = vec![0.0; k * k];
    for i in 0..k {
        m[i * k + i] = d[i];
    }
    m
}

/// Position (2s, 0.3 sin πs) and its velocity, s ∈ [0, 1], sampled N times over 5 s; Goal around the end
/// state, Unsafe a bump above the path; metric P = L Lᵀ + I with a seeded random L.
fn setup() -> Setup {
    let mut rng = ChaCha8Rng::seed_from_u64(47);
    let pi = std::f64::consts::PI;
    let t: Vec<f64> = (0..N).map(|k| 5.0 * k as f64 / (N - 1) as f64).collect();
    let mut x = Vec::with_capacity(N * n);
    for k in 0..N {
        let s = k as f64 / (N - 1) as f64;
        x.extend_from_slice(&[
            2.0 * s,
            0.3 * (pi * s).sin(),
            2.0,
            0.3 * pi * (pi * s).cos(),
        ]);
    }
    let goal = Ellipsoid::new(
        vec![2.0, 0.0, 2.0, -0.3 * pi],
        diag(&[100.0, 100.0, 4.0, 4.0]),
    )
    .unwrap();
    let unsafe_set =
        Ellipsoid::new(vec![1.0, 1.0, 0.0, 0.0], diag(&[11.0, 11.0, 0.25, 0.25])).unwrap();
    let L: Vec<f64> = (0..n * n).map(|_| rng.random_range(-0.3..0.3)).collect();
    let mut P = diag(&[1.0; n]);
    for i in 0..n {
        for j in 0..n {
            P[i * n + j] += (0..n).map(|k| L[i * n + k] * L[j * n + k]).sum::<f64>();
        }
    }
    let metric = Metric::new(n, P).unwrap();
    Setup {
        t,
        x,
        goal,
        unsafe_set,
        metric,
    }
}

/// Median wall time of one call over repeated runs lasting at least `budget`.
fn median_time(mut f: impl FnMut(), budget: Duration) -> f64 {
    f();
    let start = Instant::now();
    let mut times = Vec::new();
    while start.elapsed() < budget || times.len() < 5 {
        let s = Instant::now();
        f();
        times.push(s.elapsed().as_secs_f64());
    }
    times.sort_by(|a, b| a.total_cmp(b));
    times[times.len() / 2]
}

fn bench(c: &mut Criterion) {
    let s = setup();
    let traj = SampledTrajectory::new(&s.t, &s.x, n).unwrap();
    let spec = SafetySpec {
        goal: SafetySet::Ellipsoid(&s.goal),
        unsafe_set: SafetySet::Ellipsoid(&s.unsafe_set),
        input: None,
        metric: &s.metric,
        T: 5.0,
    };
    let r = safety_robustness(&traj, &spec).unwrap();
    let rj = safety_robustness_joint(&traj, &spec).unwrap();
    // The workload must be the intended one: Goal reached at the end, so both passes cover every sample.
    assert!(
        r.is_certified(),
        "bench trajectory should be certified: {r:?}"
    );
    assert!(r.goal.index > N * 9 / 10, "t* should be near the end");
    assert!(rj.delta >= r.delta);
    let generic = SafetySpec {
        goal: SafetySet::Region(&s.goal),
        unsafe_set: SafetySet::Region(&s.unsafe_set),
        ..spec
    };
    let rg = safety_robustness(&traj, &generic).unwrap();
    assert_eq!(
        (rg.goal.index, rg.unsafe_set.index),
        (r.goal.index, r.unsafe_set.index)
    );
    assert!(
        (rg.delta - r.delta).abs() <= 1e-12,
        "prepared {} vs generic {}",
        r.delta,
        rg.delta
    );
    eprintln!(
        "delta = {:.6} ({:?}), t* = {:.4}, delta_Unsafe = {:.6} at t = {:.4}; joint delta = {:.6}",
        r.delta,
        r.binding,
        r.t_star(),
        r.unsafe_set.value,
        r.unsafe_set.time,
        rj.delta
    );

    let mut g = c.benchmark_group("safety_robustness");
    g.sample_size(10)
        .measurement_time(Duration::from_secs(4))
        .warm_up_time(Duration::from_secs(1));
    g.throughput(criterion::Throughput::Elements(N as u64));
    g.bench_function("theorem_4_7", |b| {
        b.iter(|| safety_robustness(black_box(&traj), &spec).unwrap())
    });
    g.bench_function("joint", |b| {
        b.iter(|| safety_robustness_joint(black_box(&traj), &spec).unwrap())
    });
    g.finish();

    let budget = Duration::from_secs(2);
    let ours = N as f64
        / median_time(
            || {
                black_box(safety_robustness(black_box(&traj), &spec).unwrap());
            },
            budget,
        );
    let joint = N as f64
        / median_time(
            || {
                black_box(safety_robustness_joint(black_box(&traj), &spec).unwrap());
            },
            budget,
        );
    let base = N as f64
        / median_time(
            || {
                black_box(safety_robustness(black_box(&traj), &generic).unwrap());
            },
            budget,
        );
    write_rows(
        "safety_robustness",
        &[
            Row::with_baseline(
                "safety_robustness_samples_per_s",
                ours,
                "samples/s",
                base,
                ours / base,
            ),
            Row::with_baseline(
                "safety_robustness_joint_samples_per_s",
                joint,
                "samples/s",
                base,
                joint / base,
            ),
        ],
    )
    .unwrap();
}

criterion_group!(benches, bench);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
}
