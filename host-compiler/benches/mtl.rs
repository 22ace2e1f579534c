//! Throughput of the streaming MTL evaluator: `G[0,1000] x1 >= 0` on 10⁶ samples with a unit time step,
//! against the naive window-scan evaluator in the same run (values asserted equal to 1e-12);
//! ratio = ours / naive throughput. Also, without baseline, bounded until and eventually on the same trace.
//!
//! Rows: `mtl_always1000_samples_per_s` (with baseline), `mtl_until1000_samples_per_s`,
//! `mtl_eventually1000_samples_per_s`.

use criterion::{criterion_group, Criterion};
use host_compiler::benchkit::{median_time, write_rows, Row};
use host_compiler::robustness::mtl::{robustness_window_scan, Formula, Trace};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::Duration;

const N: usize = 1_000_000;

/// A seeded random walk x1 and an independent noise x2, t = 0, 1, 2, ….
fn trace() -> Trace {
    let mut rng = ChaCha8Rng::seed_from_u64(2017);
    let mut x1 = Vec::with_capacity(N);
    let mut v = 0.0f64;
    for _ in 0..N {
        v = 0.999 * v + rng.random_range(-1.0..1.0);
        x1.push(v);
    }
    let x2: Vec<f64> = (0..N).map(|_| rng.random_range(-3.0..3.0)).collect();
    let t: Vec<f64> = (0..N).map(|k| k as f64).collect();
    Trace::new(t, vec!["x1".into(), "x2".into()], vec![x1, x2]).unwrap()
}

fn bench(c: &mut Criterion) {
    let tr = trace();
    let g = Formula::parse("G[0,1000] x1 >= 0").unwrap();
    let mg = g.bind(tr.names(), &[]).unwrap();
    let fast = mg.robustness(&tr).unwrap();
    let naive = robustness_window_scan(&mg, &tr).unwrap();
    assert_eq!(fast.len(), naive.len());
    for (k, (a, b)) in fast.iter().zip(&naive).enumerate() {
        assert!(
            (a - b).abs() <= 1e-12 || a == b,
            "sample {k}: streaming {a} vs naive {b}"
        );
    }
    let u = Formula::parse("x2 >= -2.9 U[0,1000] x1 >= 20").unwrap();
    let mu = u.bind(tr.names(), &[]).unwrap();
    let f = Formula::parse("F[0,1000] x1 >= 0").unwrap();
    let mf = f.bind(tr.names(), &[]).unwrap();

    let mut grp = c.benchmark_group("mtl");
    grp.sample_size(10)
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_secs(1));
    grp.throughput(criterion::Throughput::Elements(N as u64));
    grp.bench_function("always1000_streaming", |b| {
        b.iter(|| mg.robustness(black_box(&tr)).unwrap())
    });
    grp.bench_function("until1000_streaming", |b| {
        b.iter(|| mu.robustness(black_box(&tr)).unwrap())
    });
    grp.finish();

    let ours = N as f64
        / median_time(
            || {
                black_box(mg.robustness(black_box(&tr)).unwrap());
            },
            Duration::from_secs(2),
            5,
        );
    let base = N as f64
        / median_time(
            || {
                black_box(robustness_window_scan(&mg, black_box(&tr)).unwrap());
            },
            Duration::from_secs(3),
            3,
        );
    let until = N as f64
        / median_time(
            || {
                black_box(mu.robustness(black_box(&tr)).unwrap());
            },
            Duration::from_secs(2),
            5,
        );
    let ev = N as f64
        / median_time(
            || {
                black_box(mf.robustness(black_box(&tr)).unwrap());
            },
            Duration::from_secs(2),
            5,
        );
    write_rows(
        "mtl",
        &[
            Row::with_baseline(
                "mtl_always1000_samples_per_s",
                ours,
                "samples/s",
                base,
                ours / base,
            ),
            Row::new("mtl_until1000_samples_per_s", until, "samples/s"),
            Row::new("mtl_eventually1000_samples_per_s", ev, "samples/s"),
        ],
    )
    .unwrap();
}

criterion_group!(benches, bench);

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
}
