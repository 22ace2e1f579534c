//! General switching (Theorem 4.24 for the sampled loop, `certify::internal`) on Example 4.25.

use host_compiler::synth::hybrid::{plan_run, HybridTask};

fn task(period: f64) -> HybridTask {
    let src = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-internal-4-25.toml"
    ))
    .unwrap()
    .replace("period = 0.05", &format!("period = {period}"))
        + "\n[synthesis]\nmax_trajectories = 32\nsigma_margin = 0.002\n";
    let problem = host_compiler::spec::parse(&src, "4-25").unwrap();
    HybridTask::new(problem).unwrap()
}

#[test]
fn example_4_25_run_is_certified() {
    let t = task(0.01);
    let run = plan_run(&t, &[-5.0, 1.0, 2.0]).unwrap();
    for (i, s) in run.certificate.segments.iter().enumerate() {
        eprintln!(
            "segment {i}: delta {:.4} rows {} samples {} events {:?} eta {:.2e} exit {:?} binding {} | goal {:.3} unsafe {:.3} input {:.3} rcrit {:.2e}",
            s.delta, s.rows, s.samples, s.events, s.eta, s.exit, s.binding,
            s.base.delta_goal, s.base.delta_unsafe_intersample, s.base.delta_input, s.base.r_crit
        );
    }
    assert!(run.delta() > 0.0);
}
