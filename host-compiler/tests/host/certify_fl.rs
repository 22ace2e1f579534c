//! Example 4.9 through the feedback-linearizable pipeline: the certificate of a generated trajectory on the
//! linear model in ξ with the sampled-loop mismatch, and its image run on the plant itself.

use host_compiler::certify::{self, Loop, LoopConstants};
use host_compiler::task::Task;
use host_compiler::trajectory::generate::{generate, GenSettings};

fn ex49() -> Task {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/fl-4-9.toml");
    Task::new(host_compiler::spec::load(path).expect("spec")).expect("task")
}

#[test]
fn a_generated_trajectory_of_example_4_9_is_certified_with_the_mismatch() {
    let task = ex49();
    let design = host_compiler::caf::design(&task).expect("CAF");
    let lp = Loop::new(&task, &design);
    let lc = LoopConstants::new(&lp).expect("constants");
    let gp = host_compiler::synth::temporal::gen_problem(&task, &lp, &lc);
    let x0 = vec![0.0, 0.0, 0.0, 1.0];
    let g = generate(&gp, &x0, &GenSettings::default()).expect("generated");
    let (nom, cert) = certify::shipped(&lp, &lc, &x0, &g.nominal.v);
    // The mismatch is what a rotating vehicle makes of a held thrust: positive, and far below the input
    // bound.
    assert!(lc.mismatch > 0.0 && lc.mismatch < 0.05, "{}", lc.mismatch);
    // r_crit's one-step argument cannot absorb it; the sum over the table does.
    assert!(cert.r_crit > cert.parts_min(), "{cert:?}");
    assert!(cert.accumulated > 0.0 && cert.accumulated < cert.parts_min());
    assert!(cert.is_certified(), "{cert:?}");
    let expect = (cert.parts_min() - cert.accumulated) * (1.0 - 1e-9);
    assert!(
        (cert.delta - expect).abs() <= 1e-12 * expect,
        "{} vs {expect}",
        cert.delta
    );
    assert_eq!(nom.steps(), task.steps);
}
