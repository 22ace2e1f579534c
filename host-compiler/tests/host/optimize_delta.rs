//! §5.3 on the planar vehicle (Example 4.8): the proximal bundle method at least doubles the certified δ(0)
//! of certified but unoptimised seeds, every answer re-certifies through the shipped path, a cancelled run
//! returns its start, and a run cut short still returns a certified trajectory no worse than its start.

use host_compiler::certify::OwnedLoop;
use host_compiler::certify::{shipped, LoopConstants};
use host_compiler::optimize::potential::{descend, DescentMethod, PotentialSettings};
use host_compiler::optimize::{
    maximize_delta, try_maximize_delta, BundleSettings, OptStop, Optimized,
};
use std::sync::atomic::AtomicBool;

fn planar() -> (OwnedLoop, LoopConstants) {
    example("planar-vehicle.toml")
}

fn example(name: &str) -> (OwnedLoop, LoopConstants) {
    let p = host_compiler::spec::load(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR")))
        .unwrap();
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lc = ol.constants().unwrap();
    (ol, lc)
}

/// A certified, unoptimised seed from a point of Init: the constant input that would hold the vehicle at
/// the goal centre (infeasible as it is), repaired by the potential descent of §5.2 just until it keeps
/// δ = 0.02.
fn seed(ol: &OwnedLoop, lc: &LoopConstants, x0: &[f64]) -> (Vec<Vec<f64>>, f64) {
    let lp = ol.lp();
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let s = PotentialSettings::builder().delta(0.02).build().unwrap();
    let d = descend(&lp, lc, x0, &v, &s, DescentMethod::Algorithm3).expect("valid input");
    assert!(d.reached, "seed descent: cost {:.3e}", d.cost);
    let (_, c) = shipped(&lp, lc, x0, &d.v);
    assert!(c.is_certified());
    (d.v, c.delta)
}

fn assert_shipped(ol: &OwnedLoop, lc: &LoopConstants, x0: &[f64], o: &Optimized) {
    let lp = ol.lp();
    assert_eq!(o.nominal.x[0], x0);
    // v is what the image stores: f32 values.
    for r in &o.nominal.v {
        for &a in r {
            assert_eq!(a, a as f32 as f64);
        }
    }
    let (nom, cert) = shipped(&lp, lc, x0, &o.nominal.v);
    assert_eq!(nom, o.nominal, "the returned nominal is the shipped one");
    assert_eq!(
        cert, o.certificate,
        "the returned certificate is the shipped one"
    );
    assert_eq!(o.steps_after, o.nominal.steps());
    assert_eq!(o.history.last().copied(), Some(o.certificate.delta));
    assert_eq!(
        o.history.len(),
        o.iterations + 1,
        "one certified δ per iteration"
    );
    for w in o.history.windows(2) {
        assert!(w[1] >= w[0], "best certified δ never decreases: {:?}", w);
    }
}

/// A start the image can store exactly (f32 components), as the pipeline's starts are.
fn f32x<const N: usize>(x: [f64; N]) -> [f64; N] {
    x.map(|a| a as f32 as f64)
}

#[test]
fn bundle_at_least_doubles_delta_from_two_seeds() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let cancel = AtomicBool::new(false);
    for x0 in [[0.0, 0.0, 0.0, 1.0], [-0.2, -0.2, 0.0, 1.0]].map(f32x) {
        let (v, d0) = seed(&ol, &lc, &x0);
        let o = maximize_delta(
            &lp,
            &lc,
            &x0,
            &v,
            ol.task.steps,
            &BundleSettings::default(),
            &cancel,
        );
        println!(
            "x0 {x0:?}: δ {d0:.5} → {:.5} in {} iterations ({:?}), steps {} → {}",
            o.certificate.delta, o.iterations, o.stop, o.steps_before, o.steps_after
        );
        assert_eq!(o.history[0], d0);
        assert!(o.certificate.is_certified());
        assert!(
            o.certificate.delta >= 2.0 * d0,
            "δ {d0} → {} is less than doubled",
            o.certificate.delta
        );
        assert!(o.steps_after <= ol.task.steps);
        assert!(o.stop != OptStop::Cancelled);
        assert_shipped(&ol, &lc, &x0, &o);
    }
}

#[test]
fn cancelled_before_start_returns_the_start_certified() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([0.1, -0.1, 0.0, 1.0]);
    let (v, d0) = seed(&ol, &lc, &x0);
    let cancel = AtomicBool::new(true);
    let o = maximize_delta(
        &lp,
        &lc,
        &x0,
        &v,
        ol.task.steps,
        &BundleSettings::default(),
        &cancel,
    );
    assert_eq!(o.stop, OptStop::Cancelled);
    assert_eq!(o.iterations, 0);
    assert_eq!(o.history, vec![d0]);
    assert_eq!(o.certificate.delta, d0);
    assert_eq!(o.steps_before, v.len());
    assert_eq!(o.steps_after, v.len());
    let (nom, _) = shipped(&lp, &lc, &x0, &v);
    assert_eq!(o.nominal, nom);
    assert_shipped(&ol, &lc, &x0, &o);
}

#[test]
fn stopped_early_the_answer_is_certified_and_no_worse() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([0.2, 0.2, 0.0, 1.0]);
    let (v, d0) = seed(&ol, &lc, &x0);
    let cancel = AtomicBool::new(false);
    let o = maximize_delta(
        &lp,
        &lc,
        &x0,
        &v,
        ol.task.steps,
        &BundleSettings::builder().max_iterations(3).build().unwrap(),
        &cancel,
    );
    assert_eq!(o.stop, OptStop::IterationLimit);
    assert!(o.iterations <= 3);
    assert!(o.certificate.is_certified());
    assert!(o.certificate.delta >= d0);
    assert_shipped(&ol, &lc, &x0, &o);
}

#[test]
fn bundle_on_the_double_integrator_box_sets() {
    // Box Goal, half-plane Unsafe, box input, discrete plant: the other branches of the pieces.
    let (ol, lc) = example("double-integrator.toml");
    let lp = ol.lp();
    let x0 = f32x([0.1, 0.0]);
    let v = vec![vec![0.0]; ol.task.steps];
    let s = PotentialSettings::builder().delta(0.005).build().unwrap();
    let d = descend(&lp, &lc, &x0, &v, &s, DescentMethod::Lbfgs).expect("valid input");
    assert!(d.reached);
    let d0 = d.certificate.delta;
    let cancel = AtomicBool::new(false);
    let o = maximize_delta(
        &lp,
        &lc,
        &x0,
        &d.v,
        ol.task.steps,
        &BundleSettings::default(),
        &cancel,
    );
    println!(
        "double integrator: δ {d0:.5} → {:.5} in {} iterations ({:?})",
        o.certificate.delta, o.iterations, o.stop
    );
    assert!(o.certificate.delta >= 2.0 * d0);
    assert_shipped(&ol, &lc, &x0, &o);
}

#[test]
fn a_tail_past_the_goal_is_cut_at_k_star() {
    // The seed reaches Goal at its end; 100 more steps holding the last input carry it away again.
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([0.0, 0.0, 0.0, 1.0]);
    let (mut v, _) = seed(&ol, &lc, &x0);
    let last = v.last().unwrap().clone();
    v.extend(std::iter::repeat_n(last, 100));
    let (_, c) = shipped(&lp, &lc, &x0, &v);
    assert!(c.k_star < v.len());
    let cancel = AtomicBool::new(false);
    let o = maximize_delta(
        &lp,
        &lc,
        &x0,
        &v,
        v.len(),
        &BundleSettings::default(),
        &cancel,
    );
    assert_eq!(o.steps_before, v.len());
    assert!(
        o.steps_after < v.len(),
        "steps {} → {}",
        o.steps_before,
        o.steps_after
    );
    assert!(o.certificate.delta >= c.delta);
    assert_shipped(&ol, &lc, &x0, &o);
}

#[test]
fn an_uncertified_start_is_repaired_then_maximised() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([0.2, 0.2, 0.0, 1.0]);
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let (_, c0) = shipped(&lp, &lc, &x0, &v);
    assert!(!c0.is_certified());
    let cancel = AtomicBool::new(false);
    let o = maximize_delta(
        &lp,
        &lc,
        &x0,
        &v,
        ol.task.steps,
        &BundleSettings::default(),
        &cancel,
    );
    println!(
        "uncertified start: δ → {:.5} in {} iterations ({:?}), steps {} → {}",
        o.certificate.delta, o.iterations, o.stop, o.steps_before, o.steps_after
    );
    assert!(o.certificate.is_certified());
    assert!(o.certificate.delta >= 0.05);
    assert_shipped(&ol, &lc, &x0, &o);
    // Without the repair the bundle method alone does not get there from this start.
    let o2 = maximize_delta(
        &lp,
        &lc,
        &x0,
        &v,
        ol.task.steps,
        &BundleSettings::builder().repair_delta(0.0).build().unwrap(),
        &cancel,
    );
    assert!(o2.certificate.delta < o.certificate.delta);
}

#[test]
fn same_input_same_answer_to_the_bit() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = f32x([-0.1, 0.15, 0.0, 1.0]);
    let (v, _) = seed(&ol, &lc, &x0);
    let cancel = AtomicBool::new(false);
    let run = || {
        maximize_delta(
            &lp,
            &lc,
            &x0,
            &v,
            ol.task.steps,
            &BundleSettings::default(),
            &cancel,
        )
    };
    let (a, b) = (run(), run());
    assert_eq!(a.nominal, b.nominal);
    assert_eq!(a.certificate, b.certificate);
    assert_eq!(a.history, b.history);
}

#[test]
fn a_held_reference_stays_held_and_is_still_improved() {
    // reference_hold: the descent and the bundle method keep v constant over blocks of 20 samples.
    let (ol, lc) = planar();
    let lp = ol.lp();
    let cancel = AtomicBool::new(false);
    let x0 = f32x([0.0, 0.0, 0.0, 1.0]);
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let s = PotentialSettings::builder()
        .delta(0.02)
        .hold(20)
        .build()
        .unwrap();
    let d = descend(&lp, &lc, &x0, &v, &s, DescentMethod::Lbfgs).expect("valid input");
    assert!(d.reached, "held descent: cost {:.3e}", d.cost);
    assert!(host_compiler::trajectory::hold::is_held(&d.v, 20));
    let d0 = d.certificate.delta;
    let o = maximize_delta(
        &lp,
        &lc,
        &x0,
        &d.v,
        ol.task.steps,
        &BundleSettings::builder().hold(20).build().unwrap(),
        &cancel,
    );
    println!(
        "held: δ {d0:.5} → {:.5} in {} iterations ({:?})",
        o.certificate.delta, o.iterations, o.stop
    );
    assert!(host_compiler::trajectory::hold::is_held(&o.nominal.v, 20));
    assert!(o.certificate.is_certified());
    assert!(
        o.certificate.delta > 1.5 * d0,
        "δ {d0} → {}",
        o.certificate.delta
    );
    assert_shipped(&ol, &lc, &x0, &o);
}

/// A nominal that leaves the finite numbers (an infinite reference input) certifies nothing: the shared scans
/// refuse it and the certificate says δ = 0 with NaN parts, rather than skipping the bad samples.
#[test]
fn a_non_finite_nominal_certifies_nothing() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = ol.task.init().lo.clone();
    let mut v = vec![vec![0.0, 0.0]; ol.task.steps];
    v[0] = vec![f64::INFINITY, f64::INFINITY];
    let nom = lp.simulate(&x0, &v);
    assert!(
        nom.x.iter().flatten().any(|x| !x.is_finite()),
        "the nominal must overflow"
    );
    let c = host_compiler::certify::certify(&lp, &lc, &nom);
    assert!(!c.is_certified());
    assert_eq!((c.delta, c.delta_stored), (0.0, 0.0));
    assert!(c.delta_goal.is_nan() && c.delta_unsafe.is_nan());
    // The same loop certifies a finite one (the refusal is about the nominal, not the loop).
    let (_, ok) = shipped(&lp, &lc, &x0, &vec![vec![0.0, 0.0]; ol.task.steps]);
    assert!(ok.delta_goal.is_finite());
}

/// `max_iterations = 0` without the terminal-time cut turns §5.3 off (what the bench row
/// `trajectories_without_optimisation_ratio` compares against): the start comes back unchanged and
/// re-certified.
#[test]
fn no_iterations_return_the_start() {
    let (ol, lc) = planar();
    let lp = ol.lp();
    let x0 = [0.0, 0.0, 0.0, 1.0];
    let (v, delta) = seed(&ol, &lc, &x0);
    let off = BundleSettings {
        max_iterations: 0,
        terminal_time: false,
        ..BundleSettings::default()
    };
    let cancel = AtomicBool::new(false);
    let o = try_maximize_delta(&lp, &lc, &x0, &v, ol.task.steps, &off, &cancel).unwrap();
    assert_eq!(o.iterations, 0);
    assert_eq!(o.certificate.delta, delta);
    let v32: Vec<Vec<f64>> = v
        .iter()
        .map(|r| r.iter().map(|&a| a as f32 as f64).collect())
        .collect();
    assert_eq!(o.nominal.v, v32);
}
