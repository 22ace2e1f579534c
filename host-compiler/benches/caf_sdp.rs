//! CAF/feedback synthesis time (discrete time, default settings: σ = 0.1, reduced formulation) on seeded
//! random stabilizable pairs (A, B): n = 4 (m = 2) and n = 12 (m = 3), five plants each, the median time of one
//! synthesis (both clarabel stages and the validation). Baseline in the same run: the joint LMI (3.66)–(3.67)
//! in (Q, Y) on the same plants; ratio = joint / reduced time (how many times faster).
//!
//! Rows: `caf_sdp_n4_ms`, `caf_sdp_n12_ms` (targets ≤ 5 ms and ≤ 100 ms).

use criterion::{criterion_group, Criterion};
use faer::Mat;
use host_compiler::benchkit::{write_rows, Row};
use host_compiler::caf::{synthesize, CafOutcome, CafSettings, Formulation, TimeKind};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// Five seeded pairs: A with entries scaled so that its spectral radius is around 1.1 (typically some
/// unstable modes), B dense random (controllable with probability one). Each is checked to solve.
fn plants(n: usize, m: usize, seed: u64) -> Vec<(Mat<f64>, Mat<f64>)> {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    let scale = 1.1 * 1.7 / (n as f64).sqrt();
    (0..5)
        .map(|_| {
            let a = Mat::from_fn(n, n, |_, _| scale * r.random_range(-1.0..1.0));
            let b = Mat::from_fn(n, m, |_, _| r.random_range(-1.0..1.0));
            (a, b)
        })
        .collect()
}

fn settings(f: Formulation) -> CafSettings {
    CafSettings::builder().formulation(f).build().unwrap()
}

fn solve_all(ps: &[(Mat<f64>, Mat<f64>)], s: &CafSettings) {
    for (a, b) in ps {
        let out = synthesize(TimeKind::Discrete, a.as_ref(), b.as_ref(), s).unwrap();
        assert!(matches!(out, CafOutcome::Solved(_)), "{out:?}");
        black_box(out);
    }
}

/// Median wall time (ms) of one synthesis, over repeated passes through the plant set lasting at least `budget`.
fn median_ms(
    ps: &[(Mat<f64>, Mat<f64>)],
    s: &CafSettings,
    budget: Duration,
    min_passes: usize,
) -> f64 {
    let start = Instant::now();
    let mut times = Vec::new();
    let mut passes = 0;
    while start.elapsed() < budget || passes < min_passes {
        for (a, b) in ps {
            let t = Instant::now();
            black_box(synthesize(TimeKind::Discrete, a.as_ref(), b.as_ref(), s).unwrap());
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        passes += 1;
    }
    times.sort_by(|a, b| a.total_cmp(b));
    times[times.len() / 2]
}

fn bench(c: &mut Criterion) {
    let p4 = plants(4, 2, 4);
    let p12 = plants(12, 3, 12);
    let (red, joint) = (settings(Formulation::Reduced), settings(Formulation::Joint));
    solve_all(&p4, &red);
    solve_all(&p12, &red);
    solve_all(&p4, &joint);

    let mut grp = c.benchmark_group("caf_sdp");
    grp.sample_size(10)
        .measurement_time(Duration::from_secs(2))
        .warm_up_time(Duration::from_millis(500));
    grp.bench_function("n4_reduced_5_plants", |b| b.iter(|| solve_all(&p4, &red)));
    grp.bench_function("n12_reduced_5_plants", |b| b.iter(|| solve_all(&p12, &red)));
    grp.finish();

    let n4 = median_ms(&p4, &red, Duration::from_secs(1), 3);
    let n4_joint = median_ms(&p4, &joint, Duration::from_secs(1), 3);
    let n12 = median_ms(&p12, &red, Duration::from_secs(2), 2);
    let n12_joint = median_ms(&p12, &joint, Duration::from_secs(2), 1);
    write_rows(
        "caf_sdp",
        &[
            Row::with_baseline("caf_sdp_n4_ms", n4, "ms", n4_joint, n4_joint / n4),
            Row::with_baseline("caf_sdp_n12_ms", n12, "ms", n12_joint, n12_joint / n12),
        ],
    )
    .unwrap();
}

criterion_group!(benches, bench);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
}
