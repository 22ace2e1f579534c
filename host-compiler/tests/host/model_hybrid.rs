//! The hybrid automaton's exact flow across events (`model::hybrid`): the event time of Example 3.19's
//! crossing against an independent dense search, a guard grazed between probes, the Zeno bound, and the
//! checks on a malformed automaton.

#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::model::hybrid::{
    Edge, EdgeKind, FlowError, Hybrid, HybridError, Mode, Polytope, Reset,
};
use host_compiler::model::ContinuousPlant;

pub(crate) fn mat(rows: &[&[f64]]) -> Mat<f64> {
    Mat::from_fn(rows.len(), rows[0].len(), |i, j| rows[i][j])
}

pub(crate) fn half(a: &[f64], b: f64) -> Polytope {
    Polytope {
        a: vec![a.to_vec()],
        b: vec![b],
    }
}

/// Example 3.19's two locations of ℝ³ (flows and invariants).
pub(crate) fn example_3_19_modes() -> Vec<Mode> {
    let s1 = ContinuousPlant::new(
        mat(&[&[-1.2, 2.1, -0.3], &[-8.4, -3.8, -0.6], &[-0.6, 4.3, -2.9]]),
        mat(&[&[1.0], &[2.0], &[3.0]]),
        vec![0.0; 3],
    )
    .unwrap();
    let s2 = ContinuousPlant::new(
        mat(&[&[-0.7, 2.9, -0.6], &[0.2, -0.4, 3.6], &[0.1, 0.3, -4.2]]),
        mat(&[&[3.0], &[2.0], &[1.0]]),
        vec![6.0, 2.0, 0.0],
    )
    .unwrap();
    vec![
        Mode {
            name: "left".into(),
            flow: s1,
            invariant: Some(half(&[1.0, 0.0, 0.0], 0.0)),
        },
        Mode {
            name: "right".into(),
            flow: s2,
            invariant: Some(half(&[-1.0, 0.0, 0.0], 0.0)),
        },
    ]
}

/// Example 3.19: two locations of ℝ³ across the plane x1 = 0, identity resets.
fn example_3_19(h: f64) -> Hybrid {
    let edges = vec![
        Edge {
            from: 0,
            to: 1,
            guard: half(&[-1.0, 0.0, 0.0], 0.0),
            reset: Reset::identity(3),
            kind: EdgeKind::Internal,
        },
        Edge {
            from: 1,
            to: 0,
            guard: half(&[1.0, 0.0, 0.0], 0.0),
            reset: Reset::identity(3),
            kind: EdgeKind::Internal,
        },
    ];
    Hybrid::new(example_3_19_modes(), edges, h).unwrap()
}

#[test]
fn the_crossing_of_example_3_19_is_found_on_the_exact_flow() {
    let h = 0.1;
    let hy = example_3_19(h);
    let (x0, u) = ([-0.05, 1.0, 0.0], [0.5]);
    let step = hy.flow(0, &x0, &u).unwrap();
    assert_eq!(step.loc, 1);
    assert_eq!(step.events.len(), 1, "{:?}", step.events);
    let ev = &step.events[0];
    assert_eq!(ev.edge, 0);
    // Independent search: the first of 10⁵ exact sub-steps with x1 ≥ 0, then bisection on the exact flow.
    let s1 = &hy.modes()[0].flow;
    let at = |s: f64| s1.zoh(s).unwrap().step(&x0, &u);
    let fine = 100_000;
    let k = (1..=fine)
        .find(|&k| at(k as f64 * h / fine as f64)[0] >= 0.0)
        .expect("the flow crosses within the period");
    let (mut lo, mut hi) = ((k - 1) as f64 * h / fine as f64, k as f64 * h / fine as f64);
    for _ in 0..60 {
        let mid = (lo + hi) / 2.0;
        if at(mid)[0] >= 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    assert!(
        (ev.time - hi).abs() < 1e-11,
        "event at {} vs {}",
        ev.time,
        hi
    );
    assert!(
        ev.before[0].abs() < 1e-9,
        "x1 at the event: {}",
        ev.before[0]
    );
    // After it, location 2's flow for the rest of the period.
    let s2 = &hy.modes()[1].flow;
    let end = s2.zoh(h - hi).unwrap().step(&at(hi), &u);
    for (a, b) in step.x.iter().zip(&end) {
        assert!((a - b).abs() < 1e-8, "{:?} vs {:?}", step.x, end);
    }
    // Right after the reset the state sits on the guard back (x1 = 0): it must not bounce back.
    assert!(step.x[0] > 0.0);
}

#[test]
fn a_guard_entered_and_left_between_probes_is_not_missed() {
    // ẋ1 = x2, ẋ2 = −x1 from (0, 1): x1 = sin s peaks at s = π/2, inside {x1 ≥ 0.9999} only for
    // |s − π/2| < 0.0141, between the probes (every 3/8 s) that all lie outside it.
    let rot = || {
        ContinuousPlant::new(
            mat(&[&[0.0, 1.0], &[-1.0, 0.0]]),
            mat(&[&[0.0], &[1.0]]),
            vec![0.0, 0.0],
        )
        .unwrap()
    };
    let mode = |name: &str| Mode {
        name: name.into(),
        flow: rot(),
        invariant: None,
    };
    let hy = Hybrid::new(
        vec![mode("a"), mode("b")],
        vec![Edge {
            from: 0,
            to: 1,
            guard: half(&[-1.0, 0.0], -0.9999),
            reset: Reset::identity(2),
            kind: EdgeKind::Internal,
        }],
        3.0,
    )
    .unwrap();
    for k in 1..=8 {
        let s = k as f64 * 3.0 / 8.0;
        assert!(
            s.sin() < 0.9999,
            "probe {k} lies in the guard; the test would not test"
        );
    }
    let step = hy.flow(0, &[0.0, 1.0], &[0.0]).unwrap();
    assert_eq!(step.events.len(), 1, "{step:?}");
    let expected = 0.9999f64.asin();
    assert!(
        (step.events[0].time - expected).abs() < 1e-9,
        "{:?}",
        step.events
    );
    assert_eq!(step.loc, 1);
}

#[test]
fn zeno_behaviour_is_an_error_not_a_hang() {
    // ẋ1 = 100: every 0.015 s the state reaches x1 = 1 and is reset to x1 = −0.5.
    let fast = ContinuousPlant::new(mat(&[&[0.0]]), mat(&[&[0.0]]), vec![100.0]).unwrap();
    let hy = Hybrid::new(
        vec![Mode {
            name: "loop".into(),
            flow: fast,
            invariant: None,
        }],
        vec![Edge {
            from: 0,
            to: 0,
            guard: half(&[-1.0], -1.0),
            reset: Reset {
                R: mat(&[&[1.0]]),
                r: vec![-1.5],
            },
            kind: EdgeKind::Internal,
        }],
        1.0,
    )
    .unwrap();
    let e = hy.flow(0, &[0.0], &[0.0]).unwrap_err();
    assert_eq!(
        e,
        FlowError::Zeno {
            loc: 0,
            max: Hybrid::MAX_EVENTS_PER_PERIOD
        }
    );
    // A shorter period takes the events it has, each at x1 = 1.
    let hy = Hybrid::new(hy.modes().to_vec(), hy.edges().to_vec(), 0.05).unwrap();
    let step = hy.flow(0, &[0.0], &[0.0]).unwrap();
    assert_eq!(step.events.len(), 3, "{:?}", step.events);
    for (i, ev) in step.events.iter().enumerate() {
        assert!((ev.before[0] - 1.0).abs() < 1e-9, "{ev:?}");
        let t = 0.01 + 0.015 * i as f64;
        assert!((ev.time - t).abs() < 1e-9, "{ev:?}");
    }
    assert!(
        (step.x[0] - (-0.5 + 100.0 * (0.05 - 0.04))).abs() < 1e-9,
        "{:?}",
        step.x
    );
}

#[test]
fn a_forced_edge_is_never_taken_by_the_flow() {
    let mut hy = example_3_19(0.1);
    let mut edges = hy.edges().to_vec();
    edges[0].kind = EdgeKind::Forced;
    hy = Hybrid::new(hy.modes().to_vec(), edges, 0.1).unwrap();
    let step = hy.flow(0, &[-0.05, 1.0, 0.0], &[0.5]).unwrap();
    assert!(step.events.is_empty());
    assert_eq!(step.loc, 0);
    assert!(
        step.x[0] > 0.0,
        "the flow crossed the plane without switching"
    );
}

#[test]
fn a_malformed_automaton_is_refused_with_the_reason() {
    let hy = example_3_19(0.1);
    let mut edges = hy.edges().to_vec();
    edges[1].to = 5;
    let e = Hybrid::new(hy.modes().to_vec(), edges, 0.1).unwrap_err();
    assert_eq!(
        e,
        HybridError::UnknownLocation {
            edge: 1,
            index: 5,
            locations: 2
        }
    );
    let mut edges = hy.edges().to_vec();
    edges[0].guard = half(&[1.0, 0.0], 0.0);
    let e = Hybrid::new(hy.modes().to_vec(), edges, 0.1).unwrap_err();
    assert!(
        e.to_string()
            .contains("guard of edge 0: row 0 has 2 entries, the state has n = 3"),
        "{e}"
    );
    let mut edges = hy.edges().to_vec();
    edges[0].guard = half(&[0.0, 0.0, 0.0], 0.0);
    let e = Hybrid::new(hy.modes().to_vec(), edges, 0.1).unwrap_err();
    assert!(matches!(e, HybridError::BadRow { row: 0, .. }), "{e:?}");
    let mut modes = hy.modes().to_vec();
    modes[1].flow =
        ContinuousPlant::new(Mat::identity(2, 2), mat(&[&[1.0], &[0.0]]), vec![0.0; 2]).unwrap();
    let e = Hybrid::new(modes, hy.edges().to_vec(), 0.1).unwrap_err();
    assert!(e.to_string().contains("location `right` has n = 2"), "{e}");
    assert_eq!(
        Hybrid::new(vec![], vec![], 0.1).unwrap_err(),
        HybridError::NoLocations
    );
    assert!(matches!(
        Hybrid::new(hy.modes().to_vec(), hy.edges().to_vec(), 0.0).unwrap_err(),
        HybridError::Model(_)
    ));
    assert_eq!(
        hy.flow(7, &[0.0; 3], &[0.0]).unwrap_err(),
        FlowError::UnknownLocation(7)
    );
}

#[test]
fn a_flow_sliding_along_a_guard_is_undecided_not_a_hang() {
    // ẋ = (0, 1) at x1 = −10⁻¹³: parallel to the guard {x1 ≥ 0}, closer to it than the tolerance can
    // separate from an entry over a whole period.
    let slide =
        ContinuousPlant::new(Mat::zeros(2, 2), mat(&[&[0.0], &[0.0]]), vec![0.0, 1.0]).unwrap();
    let mode = |name: &str| Mode {
        name: name.into(),
        flow: slide.clone(),
        invariant: None,
    };
    let hy = Hybrid::new(
        vec![mode("a"), mode("b")],
        vec![Edge {
            from: 0,
            to: 1,
            guard: half(&[-1.0, 0.0], 0.0),
            reset: Reset::identity(2),
            kind: EdgeKind::Internal,
        }],
        1.0,
    )
    .unwrap();
    let e = hy.flow(0, &[-1e-13, 0.0], &[0.0]).unwrap_err();
    assert_eq!(
        e,
        FlowError::Undecided {
            loc: 0,
            max: Hybrid::MAX_PROBES_PER_PERIOD
        }
    );
    // A millimetre away the same flow is decided at once: no event.
    let step = hy.flow(0, &[-1e-3, 0.0], &[0.0]).unwrap();
    assert!(step.events.is_empty());
    assert_eq!(step.loc, 0);
}
