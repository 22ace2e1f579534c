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

/// `certify::Ceiling` bounds the δ of every certificate of the loop, whatever the nominal: Example 4.9's
/// generated trajectories from several starts, their references scaled, and the loop without a
/// reference; and it does not refuse the example, whose cover certifies (its δ is below the ceiling by
/// the input margin the trajectories leave unused, not by orders of magnitude).
#[test]
fn the_ceiling_bounds_every_certificate_of_example_4_9() {
    let task = ex49();
    let design = host_compiler::caf::design(&task).expect("CAF");
    let lp = Loop::new(&task, &design);
    let lc = LoopConstants::new(&lp).expect("constants");
    let ceiling = certify::Ceiling::of(&lp, &lc, task.steps);
    assert!(ceiling.accumulated > 0.0, "{ceiling:?}");
    assert!(
        !ceiling.below(task.problem.synthesis.min_robustness),
        "{ceiling}"
    );
    let gp = host_compiler::synth::temporal::gen_problem(&task, &lp, &lc);
    let mut best = 0.0f64;
    let mut certified = 0;
    for x0 in [
        [0.0, 0.0, 0.0, 1.0],
        [0.2, -0.1, 0.0, 1.0],
        [-0.2, 0.2, 0.0, 1.0],
    ] {
        let x0 = x0.to_vec();
        let g = generate(&gp, &x0, &GenSettings::default()).expect("generated");
        for scale in [0.0, 0.5, 0.9, 1.0, 1.05, 1.3] {
            let v: Vec<Vec<f64>> = g
                .nominal
                .v
                .iter()
                .map(|r| r.iter().map(|a| a * scale).collect())
                .collect();
            let (_, cert) = certify::shipped(&lp, &lc, &x0, &v);
            assert!(
                cert.delta <= ceiling.value,
                "δ {} above the ceiling {ceiling}",
                cert.delta
            );
            certified += usize::from(cert.is_certified());
            best = best.max(cert.delta);
        }
    }
    assert!(certified >= 3, "{certified} certified");
    println!("best δ {best:.4e}, {ceiling:?}");
    assert!(ceiling.value < 20.0 * best, "{ceiling:?} against δ {best}");
}
