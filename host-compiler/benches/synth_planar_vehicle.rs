//! End-to-end synthesis of Example 4.8 (examples/planar-vehicle.toml): wall time and the coverage it
//! certifies. One run is a whole pipeline of seconds, so this is timed directly rather than sampled by
//! criterion; the run is deterministic (seeded), so the figures other than time repeat exactly.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::synth::{synthesize, SynthOptions};
use std::time::Instant;

fn main() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the shipped example parses");
    let opts = SynthOptions {
        progress: false,
        ..SynthOptions::default()
    };
    let t = Instant::now();
    let s = synthesize(&problem, &opts).expect("synthesis succeeds on the shipped example");
    let secs = t.elapsed().as_secs_f64();
    assert_eq!(
        s.verify.violations, 0,
        "verification must find no violation"
    );
    println!(
        "planar vehicle: {} trajectories, coverage {:.5} (lower {:.5} at {:.0} %), {} verification runs, {} violations",
        s.trajectories.len(),
        s.coverage.mean,
        s.coverage.lower,
        100.0 * s.coverage.confidence,
        s.verify.interior_runs + s.verify.boundary_runs,
        s.verify.violations
    );
    write_rows(
        "synth_planar_vehicle",
        &[
            Row::new("synth_planar_vehicle_s", secs, "s"),
            Row::new(
                "coverage_planar_vehicle",
                s.coverage.lower,
                "fraction (lower bound, 99 % conf.)",
            ),
            Row::new(
                "trajectories_planar_vehicle",
                s.trajectories.len() as f64,
                "count",
            ),
        ],
    )
    .expect("bench rows written");
}
