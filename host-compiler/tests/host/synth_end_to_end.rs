//! The whole pipeline on the shipped double-integrator example: covered at the requested confidence,
//! verified with zero violations, deterministic to the byte, and recorded trajectories imported from CSV
//! are certified (or refused when they are not safe).

use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use host_compiler::trajectory::csv::parse_recording;

fn problem() -> host_compiler::spec::Problem {
    host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    ))
    .unwrap()
}

fn quick() -> SynthOptions {
    SynthOptions {
        verify_interior: 2_000,
        verify_per_ball: 16,
        progress: false,
        ..SynthOptions::default()
    }
}

#[test]
fn double_integrator_is_covered_verified_and_deterministic() {
    let p = problem();
    let a = synthesize(&Task::new(p.clone()).unwrap(), &quick()).unwrap();
    assert_eq!(
        a.stop,
        host_compiler::synth::StopReason::Covered,
        "{}",
        a.stop
    );
    assert!(
        a.coverage.lower >= p.synthesis.coverage_target,
        "{:?}",
        a.coverage
    );
    assert_eq!(a.verify.violations, 0, "{:?}", a.verify.first_violations);
    assert_eq!(a.verify.interior_runs, 2_000);
    for t in &a.trajectories {
        assert!(t.certificate.delta > 0.0 && t.certificate.r_crit < t.certificate.delta);
        assert!((t.certificate.delta_stored as f64) < t.certificate.delta);
    }
    let b = synthesize(&Task::new(p.clone()).unwrap(), &quick()).unwrap();
    assert_eq!(
        a.image, b.image,
        "same spec and seed must give the same image bytes"
    );
}

#[test]
fn recorded_trajectories_are_certified_or_refused() {
    let p = problem();
    let base = synthesize(&Task::new(p.clone()).unwrap(), &quick()).unwrap();
    // Re-record the first generated trajectory as a person's CSV: x0 and the reference inputs v.
    let t0 = &base.trajectories[0];
    let mut csv = format!(
        "# x0 = {}\nt,v1\n",
        t0.nominal.x[0]
            .iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (k, v) in t0.nominal.v.iter().enumerate() {
        csv.push_str(&format!("{},{}\n", k as f64 * p.plant.period, v[0]));
    }
    let good = parse_recording(&csv, "good.csv", 2, 1, p.plant.period, p.horizon_steps()).unwrap();
    // A recording that pushes at full force the whole time: it leaves through the velocity limit.
    let mut bad_csv = "# x0 = 0, 0\nt,v1\n".to_string();
    for k in 0..p.horizon_steps() {
        bad_csv.push_str(&format!("{},{}\n", k as f64 * p.plant.period, 1.0));
    }
    let bad =
        parse_recording(&bad_csv, "bad.csv", 2, 1, p.plant.period, p.horizon_steps()).unwrap();
    let opts = SynthOptions {
        imports: vec![("good.csv".into(), good), ("bad.csv".into(), bad)],
        ..quick()
    };
    let s = synthesize(&Task::new(p.clone()).unwrap(), &opts).unwrap();
    assert_eq!(s.trajectories[0].source, "csv:good.csv");
    assert_eq!(
        s.trajectories[0].certificate, t0.certificate,
        "the same recording certifies the same"
    );
    assert!(s.trajectories.iter().all(|t| t.source != "csv:bad.csv"));
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("bad.csv") && w.contains("not used")),
        "{:?}",
        s.warnings
    );
    assert_eq!(s.verify.violations, 0);
}
