//! Robustness of a 1 000-sample-window formula in the CAF metric (issue 14): `G[0,1000 samples] !Unsafe`
//! of Example 4.8's task on a 10⁵-sample seeded random walk of the vehicle's state, the obstacle measured
//! in P (its Schur complement on the position plane). The row is in samples per second, against the
//! Euclidean metric in the same run (ratio = CAF / Euclidean). The streaming evaluator's values are
//! asserted equal (to 1e-12) to the window-scan oracle's, whose atoms are measured point by point through
//! `Region::signed_dist`; its rate is printed as well.
//!
//! Row: `mtl_caf_metric_samples_per_s`. Cheap on its own: `cargo bench -p host-compiler --bench mtl_caf_metric`.

use host_compiler::benchkit::{median_time, write_rows, Row};
use host_compiler::certify::OwnedLoop;
use host_compiler::geometry::Metric;
use host_compiler::property::TemporalTask;
use host_compiler::robustness::mtl::{robustness_window_scan, Formula, Trace};
use rand::{Rng, SeedableRng};
use std::hint::black_box;
use std::time::{Duration, Instant};

fn main() {
    let path = format!(
        "{}/../examples/planar-vehicle.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let p = host_compiler::spec::load(&path).expect("the shipped example parses");
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lp = ol.lp();
    let n_samples = 100_000;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2017);
    let mut x = [0.0f64; 4];
    let mut cols: Vec<Vec<f64>> = (0..4).map(|_| Vec::with_capacity(n_samples)).collect();
    for _ in 0..n_samples {
        for (i, c) in cols.iter_mut().enumerate() {
            x[i] = 0.999 * x[i] + rng.random_range(-0.05..0.05);
            c.push(x[i]);
        }
    }
    let h = p.plant.period;
    let tr = Trace::new(
        (0..n_samples).map(|k| k as f64 * h).collect(),
        host_compiler::property::state_signals(4),
        cols,
    )
    .unwrap();
    let mut pw = p.clone();
    pw.mtl = Some(format!("G[0,{}] !Unsafe", 1000.0 * h));
    let tt = TemporalTask::from_problem(&pw).unwrap();
    let caf = Metric {
        n: 4,
        R: host_compiler::linalg::to_row_major(lp.P),
    };
    let sets_caf = tt.sets(&caf).unwrap();
    let sets_euc = tt.sets(&Metric::euclidean(4)).unwrap();
    let f: &Formula = tt.formula();
    let m_caf = f.bind(tr.names(), &sets_caf).unwrap();
    let m_euc = f.bind(tr.names(), &sets_euc).unwrap();

    let fast = m_caf.robustness(&tr).unwrap();
    let s = Instant::now();
    let oracle = robustness_window_scan(&m_caf, &tr).unwrap();
    let oracle_rate = n_samples as f64 / s.elapsed().as_secs_f64();
    for (k, (a, b)) in fast.iter().zip(&oracle).enumerate() {
        assert!(
            (a - b).abs() <= 1e-12 || a == b,
            "sample {k}: streaming {a} vs oracle {b}"
        );
    }

    let t_caf = median_time(
        || {
            black_box(m_caf.robustness(black_box(&tr)).unwrap());
        },
        Duration::from_secs(3),
        3,
    );
    let t_euc = median_time(
        || {
            black_box(m_euc.robustness(black_box(&tr)).unwrap());
        },
        Duration::from_secs(3),
        3,
    );
    let (caf_rate, euc_rate) = (n_samples as f64 / t_caf, n_samples as f64 / t_euc);
    println!(
        "G[0,1000 samples] !Unsafe on {n_samples} samples: {caf_rate:.3e} samples/s in the CAF metric, \
         {euc_rate:.3e} Euclidean; the window-scan oracle with pointwise atoms {oracle_rate:.3e} (values equal)"
    );
    write_rows(
        "mtl_caf_metric",
        &[Row::with_baseline(
            "mtl_caf_metric_samples_per_s",
            caf_rate,
            "samples/s",
            euc_rate,
            caf_rate / euc_rate,
        )],
    )
    .unwrap();
}
