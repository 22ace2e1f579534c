//! §5.2 on the planar vehicle: the potential descent (Algorithm 3 and L-BFGS) repairs an infeasible seed
//! until the shipped certificate keeps the desired δ, and the time-optimal bisection of §5.2.3 (Example 5.2)
//! shortens the terminal time at the kept δ.

use host_compiler::certify::OwnedLoop;
use host_compiler::certify::{shipped, LoopConstants};
use host_compiler::optimize::potential::{descend, time_optimal, DescentMethod, PotentialSettings};

fn planar() -> (OwnedLoop, LoopConstants) {
    let p = host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    ))
    .unwrap();
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lc = ol.constants().unwrap();
    (ol, lc)
}

/// A start the image can store exactly (f32 components), as the pipeline's starts are.
fn f32x<const N: usize>(x: [f64; N]) -> [f64; N] {
    x.map(|a| a as f32 as f64)
}

#[test]
fn both_descents_repair_an_infeasible_seed_to_the_desired_delta() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([-0.2, 0.2, 0.0, 1.0]);
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let (_, c0) = shipped(&lp, &lc, &x0, &v);
    assert!(!c0.is_certified(), "the seed must start infeasible");
    for method in [DescentMethod::Algorithm3, DescentMethod::Lbfgs] {
        let s = PotentialSettings::builder().delta(0.04).build().unwrap();
        let d = descend(&lp, &lc, &x0, &v, &s, method).expect("valid input");
        println!(
            "{method:?}: cost {:.2e} in {} iterations, {} evaluations, {:.3}s; δ {:.5}",
            d.cost, d.iterations, d.evaluations, d.seconds, d.certificate.delta
        );
        assert!(d.zero_cost && d.reached, "{method:?}: cost {:.3e}", d.cost);
        assert!(d.certificate.delta >= 0.04);
        let (nom, cert) = shipped(&lp, &lc, &x0, &d.v);
        assert_eq!(nom, d.nominal);
        assert_eq!(cert, d.certificate);
    }
}

#[test]
fn a_short_horizon_cannot_reach_zero_cost() {
    // 0.5 s is not enough to travel 2 units with ‖u‖ ≤ 1: the descent must say so, not claim success.
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([0.0, 0.0, 0.0, 1.0]);
    let v = vec![vec![1.0, -1.0]; 50];
    let s = PotentialSettings::builder()
        .delta(0.02)
        .max_iterations(200)
        .build()
        .unwrap();
    let d = descend(&lp, &lc, &x0, &v, &s, DescentMethod::Algorithm3).expect("valid input");
    assert!(!d.zero_cost && !d.reached);
    assert!(d.cost > 0.0);
}

#[test]
fn time_optimal_bisection_shortens_the_terminal_time_at_the_kept_delta() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([0.0, 0.0, 0.0, 1.0]);
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let seed = descend(
        &lp,
        &lc,
        &x0,
        &v,
        &PotentialSettings::builder().delta(0.05).build().unwrap(),
        DescentMethod::Algorithm3,
    )
    .expect("valid input");
    assert!(seed.reached);
    let kept = seed.certificate.delta;
    let s = PotentialSettings::builder()
        .delta(kept)
        .max_iterations(300)
        .build()
        .unwrap();
    let to =
        time_optimal(&lp, &lc, &x0, &seed.v, &s, DescentMethod::Algorithm3).expect("valid input");
    println!(
        "terminal step {} → {} at δ {kept:.5}; probes {:?}",
        to.steps_before, to.steps_after, to.probes
    );
    let best = to.best.as_ref().expect("the seed's own length is feasible");
    assert_eq!(to.steps_before, seed.certificate.k_star);
    assert!(to.steps_after < to.steps_before);
    assert_eq!(best.v.len(), to.steps_after);
    assert!(best.reached && best.certificate.delta >= kept);
    let (_, cert) = shipped(&lp, &lc, &x0, &best.v);
    assert_eq!(cert, best.certificate);
    // Bisection: the step below the answer was probed and failed.
    assert!(to.probes.contains(&(to.steps_after - 1, false)));
}

#[test]
fn bad_input_is_refused_with_a_clear_error() {
    use host_compiler::optimize::{try_maximize_delta, BundleSettings, OptimizeError};
    let (ol, lc) = planar();
    let lp = ol.lp();
    let v = vec![vec![1.0, -1.0]; 10];
    let s = PotentialSettings::default();
    let e = descend(&lp, &lc, &[0.0; 3], &v, &s, DescentMethod::Algorithm3).unwrap_err();
    assert_eq!(e, OptimizeError::StateDimension { got: 3, n: 4 });
    let x0 = f32x([0.0, 0.0, 0.0, 1.0]);
    let mut bad = v.clone();
    bad[4] = vec![1.0];
    let e = descend(&lp, &lc, &x0, &bad, &s, DescentMethod::Lbfgs).unwrap_err();
    assert_eq!(e, OptimizeError::InputDimension { k: 4, got: 1, m: 2 });
    let e = time_optimal(&lp, &lc, &x0, &[], &s, DescentMethod::Algorithm3).unwrap_err();
    assert_eq!(e, OptimizeError::Empty);
    let e = descend(
        &lp,
        &lc,
        &x0,
        &v,
        &PotentialSettings {
            delta: -1.0,
            ..s.clone()
        },
        DescentMethod::Algorithm3,
    )
    .unwrap_err();
    assert_eq!(e, OptimizeError::BadDelta(-1.0));
    let mut nan = v.clone();
    nan[0][1] = f64::NAN;
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let e = try_maximize_delta(&lp, &lc, &x0, &nan, 10, &BundleSettings::default(), &cancel)
        .unwrap_err();
    assert_eq!(e, OptimizeError::NotFinite);
    assert!(e.to_string().contains("non-finite"));
}
