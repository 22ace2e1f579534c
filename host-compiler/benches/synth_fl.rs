//! Example 4.9 (issue 13), the torque-driven pendulum and the differentially flat planar quadrotor
//! synthesised as shipped (`examples/fl-4-9.toml`, `examples/fl-pendulum.toml`, whose law is bounded over
//! its operating region, and `examples/flat-quadrotor.toml`, the chain in its flat state): coverage of
//! Init (lower bound at 99 % confidence), wall time of the whole `synthesize` (CAF, cover, 10 000 + 32 per ball Monte Carlo
//! runs on the plant itself by adaptive integration), its violations (must be 0), the sampled-loop
//! mismatch D the certificate absorbs, and the bytes of the two model programs the image carries.
//!
//! A synthesis is seconds of deterministic (seeded) work, so it is timed directly.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use std::time::Instant;

fn main() {
    let mut rows = Vec::new();
    for (file, key, what) in [
        ("fl-4-9.toml", "fl_4_9", "Example 4.9"),
        ("fl-pendulum.toml", "fl_pendulum", "Torque-driven pendulum"),
        (
            "flat-quadrotor.toml",
            "flat_quadrotor",
            "Planar quadrotor (flat, §3.1.3)",
        ),
    ] {
        rows.extend(example_rows(file, key, what));
    }
    let path = write_rows("synth_fl", &rows).expect("rows written");
    println!("rows: {}", path.display());
}

/// One shipped example synthesised as shipped: its rows, keyed `coverage_<key>`, `synth_<key>_s`, ….
fn example_rows(file: &str, key: &str, what: &str) -> Vec<Row> {
    let path = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
    let task = Task::new(host_compiler::spec::load(&path).expect("the shipped example")).unwrap();
    let maps = task.plant.linearization().expect("a linearised plant");
    let program_bytes = maps.coords.bytes.len() + maps.input_map.bytes.len();
    // A flat plant has no λ (its input map is Υ, not κ + λw): its bound is NaN by construction.
    let lambda = if maps.lambda_norm.is_nan() {
        "none (flat plant)".to_string()
    } else {
        format!("≤ {:.5}", maps.lambda_norm)
    };
    println!(
        "{what}: D = {:.4e} (flow {:.4e}), ‖λ‖ {lambda}, program rounding {:.3e}, W = {:?}",
        maps.mismatch, maps.mismatch_flow, maps.e_prog, task.problem.input
    );
    let opts = SynthOptions {
        progress: false,
        ..SynthOptions::default()
    };
    let t = Instant::now();
    let s = synthesize(&task, &opts).expect("synthesis");
    let secs = t.elapsed().as_secs_f64();
    let d: Vec<f64> = s.trajectories.iter().map(|t| t.certificate.delta).collect();
    println!(
        "{what}: {} trajectories (δ {:.4}..{:.4}), coverage {:.5} (lower {:.5}), {} + {} Monte Carlo runs on the plant, {} violations, {secs:.1} s ({:?})",
        s.trajectories.len(),
        d.iter().copied().fold(f64::INFINITY, f64::min),
        d.iter().copied().fold(0.0, f64::max),
        s.coverage.mean,
        s.coverage.lower,
        s.verify.interior_runs,
        s.verify.boundary_runs,
        s.verify.violations,
        s.timings
    );
    vec![
        Row::new(
            &format!("coverage_{key}"),
            s.coverage.lower,
            "lower bound, 99 %",
        ),
        Row::new(&format!("synth_{key}_s"), secs, "s"),
        Row::new(
            &format!("{key}_verify_violations"),
            s.verify.violations as f64,
            "runs",
        ),
        Row::new(
            &format!("{key}_mismatch_bound"),
            maps.mismatch,
            "input units",
        ),
        Row::new(
            &format!("{key}_model_programs_bytes"),
            program_bytes as f64,
            "bytes",
        ),
    ]
}
