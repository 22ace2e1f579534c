//! End-to-end synthesis of Example 4.8 (examples/planar-vehicle.toml): wall time, the coverage it
//! certifies and the trajectory count, with the default generator (Algorithm 4 with §5.3's δ
//! maximisation) against the earlier one (Algorithm 1 with the SCP generator, no optimisation) measured in
//! the same run as the baseline; and the median δ gain of §5.3 over Algorithm 4's seeds.
//!
//! One run is a whole pipeline of seconds, so this is timed directly rather than sampled by criterion;
//! the runs are deterministic (seeded), so the figures other than time repeat exactly.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::synth::{synthesize, Generator, SynthOptions, Synthesis};
use host_compiler::task::Task;
use std::time::Instant;

fn run(problem: &host_compiler::spec::Problem, generator: Generator) -> (Synthesis, f64) {
    let opts = SynthOptions {
        progress: false,
        generator,
        ..SynthOptions::default()
    };
    let t = Instant::now();
    let task = Task::new(problem.clone()).expect("the shipped example is a task");
    let s = synthesize(&task, &opts).expect("synthesis succeeds on the shipped example");
    let secs = t.elapsed().as_secs_f64();
    assert_eq!(
        s.verify.violations, 0,
        "verification must find no violation ({generator})"
    );
    println!(
        "planar vehicle, {generator}: {} trajectories, coverage {:.5} (lower {:.5} at {:.0} %), {} verification runs, {} violations, {secs:.3} s",
        s.trajectories.len(),
        s.coverage.mean,
        s.coverage.lower,
        100.0 * s.coverage.confidence,
        s.verify.interior_runs + s.verify.boundary_runs - s.verify.boundary_rejected,
        s.verify.violations
    );
    (s, secs)
}

/// Seconds of the growth phase (the part the generator changes; the rest of the pipeline is the same).
fn cover_secs(s: &Synthesis) -> f64 {
    s.timings
        .iter()
        .filter(|(k, _)| k.starts_with("cover"))
        .map(|(_, v)| v)
        .sum()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the shipped example parses");
    // Alternating runs; the fastest of three each, so that load from elsewhere on the machine distorts
    // the comparison less (the results themselves are identical run to run).
    let (before, mut secs_before) = run(&problem, Generator::Scp);
    let (after, mut secs_after) = run(&problem, Generator::Algorithm4);
    let (mut cover_before, mut cover_after) = (cover_secs(&before), cover_secs(&after));
    for _ in 0..2 {
        let (b, tb) = run(&problem, Generator::Scp);
        let (a, ta) = run(&problem, Generator::Algorithm4);
        assert_eq!(before.image, b.image, "deterministic");
        assert_eq!(after.image, a.image, "deterministic");
        secs_before = secs_before.min(tb);
        secs_after = secs_after.min(ta);
        cover_before = cover_before.min(cover_secs(&b));
        cover_after = cover_after.min(cover_secs(&a));
    }
    // δ after ÷ δ before of every seed Algorithm 4 started on a ball's boundary (accepted or not).
    let seeds: Vec<_> = after
        .optimization
        .iter()
        .filter(|r| r.origin.is_some())
        .collect();
    assert!(!seeds.is_empty(), "Algorithm 4 generated no seed");
    for r in &seeds {
        println!(
            "seed round {:>2} from #{:<2} δ {:.5} → {:.5} (×{:.3}, {} iterations, {:?}){}",
            r.round,
            r.origin.unwrap_or(0),
            r.delta_before,
            r.delta_after,
            r.gain(),
            r.iterations,
            r.stop,
            if r.accepted.is_some() {
                ""
            } else {
                " not accepted"
            }
        );
    }
    let gain = median(seeds.iter().map(|r| r.gain()).collect());
    let count = |s: &Synthesis| s.trajectories.len() as f64;
    write_rows(
        "synth_planar_vehicle",
        &[
            // ratio: baseline ÷ value (> 1: faster with Algorithm 4).
            Row::with_baseline(
                "synth_planar_vehicle_s",
                secs_after,
                "s",
                secs_before,
                secs_before / secs_after,
            ),
            // ratio: baseline ÷ value (> 1: faster with Algorithm 4).
            Row::with_baseline(
                "synth_planar_vehicle_cover_s",
                cover_after,
                "s",
                cover_before,
                cover_before / cover_after,
            ),
            // ratio: value ÷ baseline (≥ 1: no worse with Algorithm 4).
            Row::with_baseline(
                "coverage_planar_vehicle",
                after.coverage.lower,
                "fraction (lower bound, 99 % conf.)",
                before.coverage.lower,
                after.coverage.lower / before.coverage.lower,
            ),
            // ratio: baseline ÷ value (> 1: fewer trajectories with Algorithm 4).
            Row::with_baseline(
                "trajectories_planar_vehicle",
                count(&after),
                "count",
                count(&before),
                count(&before) / count(&after),
            ),
            Row::new(
                "optimizer_delta_gain_median",
                gain,
                &format!(
                    "δ after/before, median of {} seeds (target ≥ 2)",
                    seeds.len()
                ),
            ),
        ],
    )
    .expect("bench rows written");
}
