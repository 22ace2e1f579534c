//! Algorithm 4 (§5.4) in the pipeline, on the shipped double-integrator example: it covers Init, every
//! trajectory it ships is certified as shipped and starts f32-exact, the image does not depend on the
//! number of threads; an interrupted run still ends with a decodable image verified with 0 violations;
//! and a δε floor no local variation can meet ends the run with "needs a new seed trajectory".

use host_compiler::synth::{synthesize, AcceptHook, Generator, StopReason, SynthOptions};
use host_compiler::task::Task;
use std::sync::atomic::Ordering;
use std::sync::Arc;

fn problem() -> host_compiler::spec::Problem {
    host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    ))
    .unwrap()
}

fn quick() -> SynthOptions {
    SynthOptions {
        verify_interior: 1_000,
        verify_per_ball: 8,
        progress: false,
        ..SynthOptions::default()
    }
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn algorithm4_covers_and_is_independent_of_the_thread_count() {
    let p = problem();
    let a = in_pool(1, || {
        synthesize(&Task::new(p.clone()).unwrap(), &quick()).unwrap()
    });
    assert_eq!(a.stop, StopReason::Covered, "{}", a.stop);
    assert_eq!(a.generator, Generator::Algorithm4);
    assert_eq!(a.verify.violations, 0, "{:?}", a.verify.first_violations);
    // Every shipped trajectory went through §5.3 and meets the δε floor; starts are f32-exact.
    assert!(!a.optimization.is_empty());
    for (i, t) in a.trajectories.iter().enumerate() {
        assert!(t.certificate.is_certified());
        assert!(t.certificate.delta >= p.synthesis.min_robustness);
        assert!(t.nominal.x[0].iter().all(|&v| v as f32 as f64 == v));
        let r = a
            .optimization
            .iter()
            .find(|r| r.accepted == Some(i))
            .expect("each trajectory has its optimisation record");
        assert_eq!(r.delta_after, t.certificate.delta);
        assert!(r.delta_after >= r.delta_before, "§5.3 never loses δ");
        assert_eq!(
            r.history[0].max(0.0),
            r.delta_before,
            "history starts at the start's δ"
        );
    }
    // Later trajectories start on the boundary of an earlier ball (Algorithm 4, step 1).
    for r in a.optimization.iter().filter(|r| r.origin.is_some()) {
        assert!(r.origin.unwrap() < r.accepted.unwrap_or(usize::MAX));
    }
    // The cover grew round by round.
    assert!(a
        .snapshots
        .windows(2)
        .all(|w| w[0].trajectories <= w[1].trajectories));
    let b = in_pool(2, || {
        synthesize(&Task::new(p.clone()).unwrap(), &quick()).unwrap()
    });
    assert_eq!(
        a.image, b.image,
        "the image must not depend on the thread count"
    );
}

fn interrupted_after_first(p: &host_compiler::spec::Problem) -> host_compiler::synth::Synthesis {
    let opts = quick();
    let flag = opts.cancel.clone();
    let opts = SynthOptions {
        on_accept: Some(AcceptHook(Arc::new(move |count| {
            if count >= 1 {
                flag.store(true, Ordering::SeqCst);
            }
        }))),
        ..opts
    };
    synthesize(&Task::new(p.clone()).unwrap(), &opts).unwrap()
}

#[test]
fn interrupted_run_keeps_a_verified_image_of_what_is_certified() {
    let p = problem();
    let s = interrupted_after_first(&p);
    let StopReason::Interrupted { trajectories } = s.stop else {
        panic!("expected an interrupted run, got {}", s.stop)
    };
    assert!(trajectories >= 1);
    assert_eq!(trajectories, s.trajectories.len());
    let img = shared_types::image::decode(&s.image).expect("the image decodes");
    assert_eq!(img.n_trajectories(), s.trajectories.len());
    assert!(s.verify.interior_runs > 0);
    assert_eq!(s.verify.violations, 0, "{:?}", s.verify.first_violations);
    assert!(s.warnings.iter().any(|w| w.contains("interrupted")));
}

#[test]
fn unreachable_floor_asks_for_a_new_seed_trajectory() {
    let mut p = problem();
    // A recorded trajectory (imports are used whenever they are certified) and a δε floor that no
    // trajectory of this task reaches: no projection onto the recorded ball may be grown from, and the
    // new SCP seed fails the floor too.
    let first = interrupted_after_first(&p);
    let t = &first.trajectories[0];
    let rec = host_compiler::trajectory::csv::Recording {
        x0: t.nominal.x[0].clone(),
        v: t.nominal.v.clone(),
        locations: None,
        given: Default::default(),
    };
    p.synthesis.min_robustness = 10.0;
    let opts = SynthOptions {
        imports: vec![("recorded.csv".into(), rec)],
        ..quick()
    };
    let s = synthesize(&Task::new(p.clone()).unwrap(), &opts).unwrap();
    let StopReason::NeedsSeed {
        region,
        description,
    } = &s.stop
    else {
        panic!(
            "expected a request for a new seed trajectory, got {}",
            s.stop
        )
    };
    assert_eq!(s.trajectories.len(), 1, "only the recording");
    assert!(region.count > 0);
    for j in 0..2 {
        assert!(region.lo[j] >= p.init.lo[j] - 1e-12 && region.hi[j] <= p.init.hi[j] + 1e-12);
    }
    assert!(!region.clusters.is_empty());
    assert!(
        description.contains("uncovered samples in x1 ∈ ["),
        "{description}"
    );
    assert!(s.stop.to_string().contains("needs a new seed trajectory"));
    // The SCP fallback was tried once and recorded, and not accepted.
    assert_eq!(
        s.optimization
            .iter()
            .filter(|r| r.origin.is_none() && r.accepted.is_none())
            .count(),
        1
    );
    assert_eq!(s.verify.violations, 0);
}
