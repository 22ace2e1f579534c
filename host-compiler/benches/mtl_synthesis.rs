//! MTL tasks (Problem 2.28) as synthesised: Remark 2.29's embedding of Example 4.8 certifies Theorem 4.7's
//! δ (the ratio, worst over three starts), the robustness of a 1 000-sample-window formula in the CAF
//! metric (samples per second, against the Euclidean metric in the same run), and the synthesis of the
//! shipped waypoint and speed examples (coverage lower bound at 99 % confidence, wall time, Monte Carlo
//! violations, which must be 0).
//!
//! A synthesis is seconds of deterministic (seeded) work, so it is timed directly.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::certify::temporal::{certify_temporal, TemporalLoop};
use host_compiler::certify::{shipped, OwnedLoop};
use host_compiler::geometry::Metric;
use host_compiler::optimize::potential::{descend, DescentMethod, PotentialSettings};
use host_compiler::property::TemporalTask;
use host_compiler::robustness::mtl::{Formula, Trace};
use host_compiler::synth::temporal::{synthesize_temporal, TemporalOptions};
use host_compiler::task::Task;
use rand::{Rng, SeedableRng};
use std::hint::black_box;
use std::time::{Duration, Instant};

fn problem(file: &str) -> host_compiler::spec::Problem {
    let path = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
    host_compiler::spec::load(&path).expect("the shipped example parses")
}

/// Median wall time of one call over repeated runs lasting at least `budget` (at least 3 runs).
fn median_time(mut f: impl FnMut(), budget: Duration) -> f64 {
    let start = Instant::now();
    let mut times = Vec::new();
    while start.elapsed() < budget || times.len() < 3 {
        let s = Instant::now();
        f();
        times.push(s.elapsed().as_secs_f64());
    }
    times.sort_by(|a, b| a.total_cmp(b));
    times[times.len() / 2]
}

fn main() {
    let mut rows = Vec::new();
    // Remark 2.29 on Example 4.8.
    let p = problem("planar-vehicle.toml");
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lc = ol.constants().unwrap();
    let lp = ol.lp();
    let mut pe = p.clone();
    pe.mtl = Some("G[0,5] !Unsafe & F[0,5] Goal".into());
    let tl = TemporalLoop::new(&TemporalTask::from_problem(&pe).unwrap(), &lp).unwrap();
    let mut worst: f64 = 1.0;
    for x0 in [
        [0.0, 0.0, 0.0, 1.0],
        [0.1, -0.15, 0.0, 1.0],
        [-0.2, 0.2, 0.0, 1.0],
    ] {
        let s = PotentialSettings::builder().delta(0.02).build().unwrap();
        let d = descend(
            &lp,
            &lc,
            &x0,
            &vec![vec![1.0, -1.0]; ol.task.steps],
            &s,
            DescentMethod::Algorithm3,
        )
        .unwrap();
        let (nom, c47) = shipped(&lp, &lc, &x0, &d.v);
        let c = certify_temporal(&lp, &lc, &tl, &nom);
        let ratio = c.delta / c47.delta;
        println!(
            "Example 4.8 from {x0:?}: δ by formula {:.9e}, by Theorem 4.7 {:.9e}, ratio {ratio:.12}",
            c.delta, c47.delta
        );
        if (ratio - 1.0).abs() > (worst - 1.0).abs() {
            worst = ratio;
        }
    }
    rows.push(Row::new("mtl_delta_equals_thm47", worst, "ratio"));

    // Robustness in the CAF metric: G[0,1000 samples] !Unsafe on a 10⁵-sample random walk of the vehicle's
    // state, the obstacle measured in P (its Schur complement on the position plane) against Euclidean.
    let n_samples = 100_000;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2017);
    let mut x = [0.0f64; 4];
    let mut cols = vec![Vec::with_capacity(n_samples); 4];
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
    let t_caf = median_time(
        || {
            black_box(m_caf.robustness(black_box(&tr)).unwrap());
        },
        Duration::from_secs(3),
    );
    let t_euc = median_time(
        || {
            black_box(m_euc.robustness(black_box(&tr)).unwrap());
        },
        Duration::from_secs(3),
    );
    let (caf_rate, euc_rate) = (n_samples as f64 / t_caf, n_samples as f64 / t_euc);
    println!(
        "G[0,1000 samples] !Unsafe on {n_samples} samples: {caf_rate:.3e} samples/s in the CAF metric, \
         {euc_rate:.3e} Euclidean"
    );
    rows.push(Row::with_baseline(
        "mtl_caf_metric_samples_per_s",
        caf_rate,
        "samples/s",
        euc_rate,
        caf_rate / euc_rate,
    ));

    // The shipped MTL examples, synthesised.
    for (file, tag) in [
        ("planar-vehicle-waypoints.toml", "waypoints"),
        ("planar-vehicle-speed.toml", "speed"),
    ] {
        let p = problem(file);
        let tt = TemporalTask::from_problem(&p).unwrap();
        let task = Task::new(p).unwrap();
        let opts = TemporalOptions::default();
        let t = Instant::now();
        match synthesize_temporal(&task, &tt, &opts) {
            Ok(s) => {
                let secs = t.elapsed().as_secs_f64();
                println!(
                    "{file}: {} balls, coverage {:.5} (lower {:.5}), {} Monte Carlo runs, {} violations, {}/{} re-proved, {secs:.1} s ({:?})",
                    s.trajectories.len(),
                    s.coverage.mean,
                    s.coverage.lower,
                    s.verify.runs,
                    s.verify.violations,
                    s.recheck.iter().filter(|c| c.ok).count(),
                    s.recheck.len(),
                    s.timings
                );
                rows.push(Row::new(
                    &format!("coverage_mtl_{tag}"),
                    s.coverage.lower,
                    "lower bound, 99 %",
                ));
                rows.push(Row::new(&format!("synth_mtl_{tag}_s"), secs, "s"));
                rows.push(Row::new(
                    &format!("mtl_{tag}_violations"),
                    s.verify.violations as f64,
                    "runs",
                ));
            }
            Err(why) => println!("{file}: no cover ({why})"),
        }
    }
    write_rows("mtl_synthesis", &rows).unwrap();
}
