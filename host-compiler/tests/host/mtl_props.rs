//! Property tests: the streaming MTL evaluator equals the direct transcription of Def 2.17 (full window
//! scans) exactly, on random traces (uniform, dyadic and irregular sample times, with ties in the values)
//! and random formulas over every operator, also with a set measured in a random ellipsoidal metric (the
//! streaming evaluator through the set's compiled signed distance, the definition point by point);
//! printing and re-parsing a formula preserves it.

use host_compiler::geometry::{
    Ball, Complement, Ellipsoid, InOutput, Metric, Region, Union, Witness,
};
use host_compiler::robustness::mtl::{
    robustness_naive, robustness_window_scan, Formula, NamedSet, Trace,
};
use proptest::prelude::*;

/// Euclidean ball of radius 1.5 around (0.5, −0.5) in (x1, x2).
struct B;
impl Region for B {
    fn dim(&self) -> usize {
        2
    }
    fn contains(&self, x: &[f64]) -> bool {
        (x[0] - 0.5).hypot(x[1] + 0.5) <= 1.5
    }
    fn dist(&self, x: &[f64], _: &Metric) -> Witness {
        Witness {
            value: ((x[0] - 0.5).hypot(x[1] + 0.5) - 1.5).max(0.0),
            point: x.to_vec(),
        }
    }
    fn depth(&self, x: &[f64], _: &Metric) -> Witness {
        Witness {
            value: (1.5 - (x[0] - 0.5).hypot(x[1] + 0.5)).max(0.0),
            point: x.to_vec(),
        }
    }
}

fn interval() -> impl Strategy<Value = String> {
    let a = prop_oneof![
        Just(0.0),
        Just(0.5),
        Just(1.0),
        Just(2.0),
        Just(3.3),
        0.0..4.0f64
    ];
    let w = prop_oneof![
        Just(Some(0.0)),
        Just(Some(0.5)),
        Just(Some(1.0)),
        Just(Some(2.5)),
        Just(None),
        (0.0..6.0f64).prop_map(Some)
    ];
    let explicit = (a, w).prop_map(|(a, w)| match w {
        Some(w) => format!("[{a},{}]", a + w),
        None => format!("[{a},inf]"),
    });
    prop_oneof![1 => Just(String::new()), 6 => explicit]
}

fn atom() -> impl Strategy<Value = String> {
    let sig = prop_oneof![Just("x1"), Just("x2"), Just("x3")];
    let c = prop_oneof![Just(1.0), Just(-1.0), Just(2.0), -3.0..3.0f64]
        .prop_filter("nonzero", |c: &f64| *c != 0.0);
    let b = prop_oneof![Just(0.0), Just(1.0), -2.0..2.0f64];
    let op = prop_oneof![Just("<="), Just(">="), Just("<"), Just(">")];
    prop_oneof![
        (sig.clone(), op.clone(), b.clone()).prop_map(|(s, o, b)| format!("{s} {o} {b}")),
        (c.clone(), sig.clone(), c, sig, op, b).prop_map(|(c1, s1, c2, s2, o, b)| {
            // Avoid cancelling the same signal to zero.
            if s1 == s2 {
                format!("{c1}*{s1} {o} {b}")
            } else {
                format!("{c1}*{s1} + {c2}*{s2} {o} {b}")
            }
        }),
        Just("S".to_string()),
        Just("true".to_string()),
        Just("false".to_string()),
    ]
}

fn formula() -> impl Strategy<Value = String> {
    atom().prop_recursive(4, 32, 2, |inner| {
        prop_oneof![
            inner.clone().prop_map(|f| format!("!({f})")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("({a}) & ({b})")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("({a}) | ({b})")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("({a}) -> ({b})")),
            (interval(), inner.clone()).prop_map(|(i, f)| format!("F{i} ({f})")),
            (interval(), inner.clone()).prop_map(|(i, f)| format!("G{i} ({f})")),
            (inner.clone(), interval(), inner.clone())
                .prop_map(|(a, i, b)| format!("({a}) U{i} ({b})")),
            (inner.clone(), interval(), inner).prop_map(|(a, i, b)| format!("({a}) R{i} ({b})")),
        ]
    })
}

fn trace() -> impl Strategy<Value = Trace> {
    (1usize..28)
        .prop_flat_map(|n| {
            let step = prop_oneof![
                Just(vec![1.0; n]),
                proptest::collection::vec(
                    prop_oneof![Just(0.25), Just(0.5), Just(1.0), Just(1.5)],
                    n
                ),
                proptest::collection::vec(0.01..2.0f64, n),
            ];
            // Small integers give many ties, which exercise the deques' tie handling.
            let val = || {
                proptest::collection::vec(
                    prop_oneof![(-3i32..4).prop_map(f64::from), -5.0..5.0f64],
                    n,
                )
            };
            (step, val(), val(), val(), -3.0..3.0f64)
        })
        .prop_map(|(steps, x1, x2, x3, t0)| {
            let mut t = Vec::with_capacity(steps.len());
            let mut acc = t0;
            for s in steps {
                t.push(acc);
                acc += s;
            }
            Trace::new(
                t,
                vec!["x1".into(), "x2".into(), "x3".into()],
                vec![x1, x2, x3],
            )
            .unwrap()
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1500, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn streaming_equals_definition(f in formula(), tr in trace()) {
        let sets = vec![NamedSet::euclidean("S", vec!["x1".into(), "x2".into()], Box::new(B))];
        let formula = Formula::parse(&f).unwrap();
        let m = formula.bind(tr.names(), &sets).unwrap();
        let fast = m.robustness(&tr).unwrap();
        let naive = robustness_naive(&m, &tr).unwrap();
        let scan = robustness_window_scan(&m, &tr).unwrap();
        prop_assert_eq!(fast.len(), tr.len());
        // Only min, max and negation act on the atoms' values: agreement is exact.
        prop_assert_eq!(&fast, &naive, "formula {}", f);
        prop_assert_eq!(&scan, &naive, "formula {}", f);
    }

    #[test]
    fn streaming_equals_definition_in_an_ellipsoidal_metric(
        f in formula(),
        tr in trace(),
        a in proptest::collection::vec(-1.0..1.0f64, 9),
        flip in any::<bool>(),
    ) {
        // r = AAᵀ + 0.1 I, the metric; S: a disc in (x1, x2) (measured in r's Schur complement) or an ellipsoid in
        // all three signals, or the complement of that union.
        let mut r = vec![0.0; 9];
        for i in 0..3 {
            for j in 0..3 {
                r[i * 3 + j] = (0..3).map(|k| a[i * 3 + k] * a[j * 3 + k]).sum::<f64>()
                    + if i == j { 0.1 } else { 0.0 };
            }
        }
        let metric = Metric::new(3, r).unwrap();
        let disc = Ball::new(vec![0.5, -0.5], vec![1.0, 0.0, 0.0, 1.0], 1.5).unwrap();
        let members: Vec<Box<dyn Region>> = vec![
            Box::new(InOutput::new(vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0], 2, Box::new(disc)).unwrap()),
            Box::new(Ellipsoid::new(vec![-1.0, 1.0, 0.0], vec![0.5, 0.1, 0.0, 0.1, 0.8, 0.0, 0.0, 0.0, 0.3]).unwrap()),
        ];
        let union = Union::new(members).unwrap();
        let region: Box<dyn Region> = if flip {
            Box::new(Complement::new(Box::new(union)).unwrap())
        } else {
            Box::new(union)
        };
        prop_assert!(region.compile(&metric).is_some());
        let sets = vec![NamedSet {
            name: "S".into(),
            signals: vec!["x1".into(), "x2".into(), "x3".into()],
            region,
            metric,
        }];
        let m = Formula::parse(&f).unwrap().bind(tr.names(), &sets).unwrap();
        prop_assert_eq!(&m.robustness(&tr).unwrap(), &robustness_naive(&m, &tr).unwrap(), "formula {}", f);
    }

    #[test]
    fn printing_and_reparsing_preserves_the_formula(f in formula()) {
        let once = Formula::parse(&f).unwrap();
        let printed = once.expr().to_string();
        let twice = Formula::parse(&printed).unwrap();
        prop_assert_eq!(twice.expr().to_string(), printed);
    }

    #[test]
    fn bounded_operators_on_long_uniform_traces(
        vals in proptest::collection::vec(-100i32..100, 200..600),
        a in 0usize..40, w in 0usize..80,
    ) {
        // Wide windows relative to the trace: exercise deque expiry and the two-stack flips.
        let n = vals.len();
        let t: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let x: Vec<f64> = vals.iter().map(|&v| f64::from(v)).collect();
        let y: Vec<f64> = x.iter().rev().cloned().collect();
        let tr = Trace::new(t, vec!["x1".into(), "x2".into()], vec![x, y]).unwrap();
        for f in [
            format!("G[{a},{}] x1 >= 0", a + w),
            format!("F[{a},{}] x1 >= 3", a + w),
            format!("x1 >= -50 U[{a},{}] x2 >= 20", a + w),
            format!("x1 >= 10 R[{a},{}] x2 <= 20", a + w),
        ] {
            let m = Formula::parse(&f).unwrap().bind(tr.names(), &[]).unwrap();
            prop_assert_eq!(m.robustness(&tr).unwrap(), robustness_window_scan(&m, &tr).unwrap(), "formula {}", f);
        }
    }
}
