//! Theorem 4.2 for the sampled f32 loop (`certify::temporal`) on Example 4.8: Remark 2.29's embedding of
//! the reach-avoid task as a formula certifies the δ Theorem 4.7 certifies, and the critical-atom ascent
//! (`optimize::temporal`) turns a nominal that misses a waypoint into a certified one.

use host_compiler::certify::temporal::{certify_temporal, TemporalLoop};
use host_compiler::certify::{shipped, LoopConstants, OwnedLoop};
use host_compiler::optimize::potential::{descend, DescentMethod, PotentialSettings};
use host_compiler::optimize::temporal::{maximize_temporal, AscentSettings};
use host_compiler::property::TemporalTask;
use host_compiler::spec::Problem;
use std::sync::atomic::AtomicBool;

fn planar() -> (Problem, OwnedLoop, LoopConstants) {
    let p = host_compiler::spec::load(format!(
        "{}/../examples/planar-vehicle.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let lc = ol.constants().unwrap();
    (p, ol, lc)
}

/// A certified nominal of Example 4.8 from x0 (the §5.2 descent to δ = 0.02).
fn nominal(ol: &OwnedLoop, lc: &LoopConstants, x0: &[f64]) -> Vec<Vec<f64>> {
    let lp = ol.lp();
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let s = PotentialSettings::builder().delta(0.02).build().unwrap();
    let d = descend(&lp, lc, x0, &v, &s, DescentMethod::Algorithm3).expect("valid input");
    assert!(d.reached);
    d.v
}

fn temporal(p: &Problem, formula: &str, ol: &OwnedLoop) -> TemporalLoop {
    let mut p = p.clone();
    let w = host_compiler::spec::parse_named_sets(
        "[sets.W]\nkind = \"ball\"\ncenter = [2.0, 1.75]\nradius = 0.1\ncoords = [\"x1\", \"x2\"]\n",
        "W",
    )
    .unwrap();
    p.sets.extend(w);
    p.mtl = Some(formula.into());
    let tt = TemporalTask::from_problem(&p).unwrap();
    TemporalLoop::new(&tt, &ol.lp()).unwrap()
}

#[test]
fn remark_2_29_embedding_certifies_theorem_4_7s_delta() {
    let (p, ol, lc) = planar();
    let lp = ol.lp();
    for x0 in [
        [0.0, 0.0, 0.0, 1.0],
        [0.1, -0.15, 0.0, 1.0],
        [-0.2, 0.2, 0.0, 1.0],
    ] {
        let v = nominal(&ol, &lc, &x0);
        let (nom, c47) = shipped(&lp, &lc, &x0, &v);
        assert!(c47.is_certified());
        // Theorem 4.7 as shipped checks Unsafe over the whole table and Goal at its best sample.
        let tl = temporal(&p, "G[0,5] !Unsafe & F[0,5] Goal", &ol);
        let c = certify_temporal(&lp, &lc, &tl, &nom);
        let ratio = c.delta / c47.delta;
        assert!(
            (ratio - 1.0).abs() <= 1e-9,
            "x0 = {x0:?}: δ by formula {} / δ by Theorem 4.7 {} = {ratio}",
            c.delta,
            c47.delta
        );
        assert_eq!(c.delta_stored, c47.delta_stored);
        // The text's until form asks to avoid Unsafe only until Goal: never less.
        let tl = temporal(&p, "!Unsafe U[0,5] (Goal & !Unsafe)", &ol);
        let cu = certify_temporal(&lp, &lc, &tl, &nom);
        assert!(
            cu.delta >= c.delta * (1.0 - 1e-9),
            "{} < {}",
            cu.delta,
            c.delta
        );
    }
}

#[test]
fn a_formula_the_nominal_violates_certifies_nothing_and_the_ascent_repairs_it() {
    let (p, ol, lc) = planar();
    let lp = ol.lp();
    let x0 = [0.0, 0.0, 0.0, 1.0];
    let v = nominal(&ol, &lc, &x0);
    let (nom, _) = shipped(&lp, &lc, &x0, &v);
    // A waypoint above the path the descent found (it passes (1.80, 1.54) at t = 2): W, then Goal.
    let f = "G[0,5] !Unsafe & F[0,2.5] (W & F[0,2.5] Goal)";
    let tl = temporal(&p, f, &ol);
    let c = certify_temporal(&lp, &lc, &tl, &nom);
    assert!(
        !c.is_certified(),
        "the descent's nominal should miss the waypoint: {c:?}"
    );
    assert!(c.delta_samples < 0.0);
    let s = AscentSettings {
        iterations: 400,
        initial_step: 0.05,
        min_step: 1e-5,
    };
    let o = maximize_temporal(&lp, &lc, &tl, &x0, &v, &s, &AtomicBool::new(false));
    assert!(
        o.certificate.is_certified(),
        "after {} iterations: ρ(0) = {}, δ_Input = {}, history {:?}",
        o.iterations,
        o.certificate.delta_samples,
        o.certificate.delta_input,
        o.history.iter().step_by(20).collect::<Vec<_>>()
    );
    eprintln!(
        "ascent: {} iterations, objective {:?} -> δ = {:.4e} (ρ(0) {:.4e}, continuous {:.4e}, input {:.4e})",
        o.iterations,
        o.history.first(),
        o.certificate.delta,
        o.certificate.delta_samples,
        o.certificate.delta_continuous,
        o.certificate.delta_input
    );
    // What it returns is the shipped table, re-certified.
    let again = certify_temporal(&lp, &lc, &tl, &lp.simulate(&x0, &o.nominal.v));
    assert_eq!(again, o.certificate);
    for r in &o.nominal.v {
        for &a in r {
            assert_eq!(a, a as f32 as f64);
        }
    }
}
