//! MTL tasks on feedback-linearizable plants (issue #14; Problem 2.28, Theorem 4.2 with the sampled-loop
//! mismatch D of §3.1.2 / Theorem 3.21): the pendulum's swing-up profile (`examples/fl-pendulum-mtl.toml`)
//! is synthesised in ξ, every ball is re-proved from the image bytes, and the image run on the nonlinear
//! pendulum is judged by the formula with 0 violations, and the falsifier on the plant finds nothing; the
//! same image judged by a stricter speed limit fails, in the Monte Carlo and in the falsifier (the judges
//! can fail); a predicate on a zero-dynamics state is refused naming it.

use host_compiler::property::TemporalTask;
use host_compiler::spec;
use host_compiler::synth::temporal::{synthesize_temporal, TemporalOptions};
use host_compiler::task::Task;
use host_compiler::verify::temporal::monte_carlo_temporal_fl;

fn example(name: &str) -> String {
    std::fs::read_to_string(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

/// The task of a spec text and its formula in ξ.
fn task_of(text: &str) -> (Task, TemporalTask) {
    let p = spec::parse(text, "spec.toml").unwrap_or_else(|e| panic!("{e:?}"));
    let task = Task::new(p).unwrap_or_else(|e| panic!("{e}"));
    let tt = TemporalTask::from_problem(&task.problem).unwrap_or_else(|e| panic!("{e}"));
    (task, tt)
}

#[test]
fn fl_pendulum_mtl_synthesises_and_verifies_on_the_plant() {
    // A smaller Init (a quarter of the example's) keeps the test short; the pipeline is the example's.
    let text = example("fl-pendulum-mtl.toml")
        .replace("lo = [3.0416, -0.1]", "lo = [3.1166, -0.025]")
        .replace("hi = [3.2416,  0.1]", "hi = [3.1666,  0.025]");
    let (task, tt) = task_of(&text);
    // The formula in ξ carries the operating region's conjunct.
    let src = task.problem.mtl.clone().expect("a formula");
    assert!(src.contains("G[0.0,4.0]"), "{src}");
    assert!(src.contains("<= 3.6") && src.contains("<= 1.8"), "{src}");
    assert!(task.plant.model_mismatch() > 0.0);
    let opts = TemporalOptions {
        verify_interior: 200,
        verify_per_ball: 8,
        ..TemporalOptions::default()
    };
    let s = synthesize_temporal(&task, &tt, &opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(!s.trajectories.is_empty());
    for t in &s.trajectories {
        let c = &t.certificate;
        assert!(c.delta > 0.0 && c.delta_stored > 0.0, "{c:?}");
        // D > 0: the radius is what is left after the disturbances summed over the table.
        assert!(c.accumulated > 0.0, "{c:?}");
        assert!(c.delta < c.delta_samples.min(c.delta_continuous), "{c:?}");
    }
    assert!(s.recheck.iter().all(|c| c.ok), "{:?}", s.recheck);
    assert!(s.verify.runs >= 100, "{:?}", s.verify);
    assert_eq!(s.verify.violations, 0, "{:?}", s.verify.first_violation);
    assert!(s.coverage.mean > 0.5, "{:?}", s.coverage);

    // The falsifier on the plant itself, scored by the formula: it ran and found nothing.
    let settings = host_compiler::verify::attack::AttackSettings {
        starts_per_ball: 1,
        evaluations_per_start: 8,
        ..Default::default()
    };
    let img0 = shared_types::image::decode(&s.image).expect("decodes");
    let at = host_compiler::verify::attack::attack_temporal_fl(&task, &tt, &img0, &settings)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(at.evaluations > 0 && at.violations == 0, "{at:?}");
    assert!(
        at.worst_robustness > 0.0 && at.worst_robustness.is_finite(),
        "{at:?}"
    );

    // The same image judged by a formula it does not meet (no faster than 0.5 rad/s, which a 4 s raise
    // through π cannot keep): the runs on the plant violate it.
    let strict = text.replace("(x2 >= -1.6)", "(x2 >= -0.5)");
    let (task2, tt2) = task_of(&strict);
    let img = shared_types::image::decode(&s.image).expect("decodes");
    let starts = host_compiler::verify::hybrid::starts_from_image(
        &s.image,
        &host_compiler::cover::estimate::SampleBox {
            lo: task2.problem.init.lo.clone(),
            hi: task2.problem.init.hi.clone(),
        },
        20,
        0,
        7,
    )
    .expect("starts");
    let r = monte_carlo_temporal_fl(&task2, &tt2, &img, &starts, 7).expect("runs");
    assert!(r.runs > 0 && r.violations == r.runs, "{r:?}");
    // ... and the falsifier finds it too.
    let at = host_compiler::verify::attack::attack_temporal_fl(&task2, &tt2, &img, &settings)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(at.violations > 0 && at.worst_robustness < 0.0, "{at:?}");
}

#[test]
fn a_predicate_on_the_zero_dynamics_is_refused_naming_the_state() {
    // Example 4.9: ξ = (X, Ẋ, Y, Ẏ), θ = x5 and θ̇ = x6 are the zero dynamics.
    let base = example("fl-4-9.toml");
    let with = |formula: &str| format!("{base}\n[mtl]\nformula = \"{formula}\"\n");
    let p = spec::parse(&with("F[0,5] Goal & G[0,5] (x5 <= 0.5)"), "spec.toml")
        .unwrap_or_else(|e| panic!("{e:?}"));
    let err = Task::new(p).err().expect("refused").to_string();
    assert!(
        err.contains("x5 (th)") && err.contains("zero dynamics"),
        "{err}"
    );
    // A predicate on ξ states only is taken, renamed into ξ (x3 = Y is ξ_3 here; X is ξ_1).
    let p = spec::parse(&with("F[0,5] Goal & G[0,5] (x3 - x1 <= 2)"), "spec.toml")
        .unwrap_or_else(|e| panic!("{e:?}"));
    let task = Task::new(p).unwrap_or_else(|e| panic!("{e}"));
    let src = task.problem.mtl.clone().expect("a formula");
    assert!(src.contains("1.0*x3 + -1.0*x1 <= 2.0"), "{src}");
    TemporalTask::from_problem(&task.problem).unwrap_or_else(|e| panic!("{e}"));
}
