//! MTL tasks (Problem 2.28) as synthesised: Remark 2.29's embedding of Example 4.8 certifies Theorem 4.7's
//! δ (the ratio, worst over three starts), and the synthesis of the shipped waypoint and speed examples
//! and of the feedback-linearizable pendulum's swing-up formula (coverage lower bound at 99 % confidence, wall time, Monte Carlo violations, which must be 0). The
//! robustness of a 1 000-sample-window formula in the CAF metric is `mtl_caf_metric`.
//!
//! A synthesis is seconds of deterministic (seeded) work, so it is timed directly.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::certify::temporal::{certify_temporal, TemporalLoop};
use host_compiler::certify::{shipped, OwnedLoop};
use host_compiler::optimize::potential::{descend, DescentMethod, PotentialSettings};
use host_compiler::property::TemporalTask;
use host_compiler::synth::temporal::{synthesize_temporal, TemporalOptions};
use host_compiler::task::Task;
use std::time::Instant;

fn problem(file: &str) -> host_compiler::spec::Problem {
    let path = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
    host_compiler::spec::load(&path).expect("the shipped example parses")
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

    // The shipped MTL examples, synthesised: two on the planar vehicle, one on a feedback-linearizable
    // plant (the pendulum, its formula rewritten into ξ by the task and verified on the nonlinear plant).
    for (file, tag) in [
        ("planar-vehicle-waypoints.toml", "waypoints"),
        ("planar-vehicle-speed.toml", "speed"),
        ("fl-pendulum-mtl.toml", "fl_pendulum"),
    ] {
        let task = Task::new(problem(file)).unwrap();
        let tt = TemporalTask::from_problem(&task.problem).unwrap();
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
