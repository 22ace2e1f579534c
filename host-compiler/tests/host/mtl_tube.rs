//! The formula's robustness over a tube (`robustness::mtl::tube`, Theorem 4.2 for the sampled loop):
//! without margins it is the monitor's discrete-time semantics exactly; with margins its lower bound at
//! t = 0 never exceeds the robustness of any trajectory of the tube, sampled eight times finer than the
//! nominal (the coarse samples included), on random formulas over every operator.

use host_compiler::geometry::{Metric, Region, Witness};
use host_compiler::robustness::mtl::{Formula, Margins, NamedSet, Trace, TubeFormula};
use proptest::prelude::*;

/// Euclidean ball of radius 1.5 around (0.5, −0.5) in (x1, x2): a 1-Lipschitz signed distance.
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
    let b = prop_oneof![Just(0.0), Just(1.0), -2.0..2.0f64];
    let op = prop_oneof![Just("<="), Just(">=")];
    prop_oneof![
        (sig.clone(), op.clone(), b.clone()).prop_map(|(s, o, b)| format!("{s} {o} {b}")),
        (sig.clone(), sig, op, b).prop_map(|(s1, s2, o, b)| if s1 == s2 {
            format!("2*{s1} {o} {b}")
        } else {
            format!("{s1} - 0.5*{s2} {o} {b}")
        }),
        Just("S".to_string()),
        Just("true".to_string()),
    ]
}

fn formula() -> impl Strategy<Value = String> {
    atom().prop_recursive(4, 24, 2, |inner| {
        prop_oneof![
            inner.clone().prop_map(|f| format!("!({f})")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("({a}) & ({b})")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("({a}) | ({b})")),
            (interval(), inner.clone()).prop_map(|(i, f)| format!("F{i} ({f})")),
            (interval(), inner.clone()).prop_map(|(i, f)| format!("G{i} ({f})")),
            (inner.clone(), interval(), inner.clone())
                .prop_map(|(a, i, b)| format!("({a}) U{i} ({b})")),
            (inner.clone(), interval(), inner).prop_map(|(a, i, b)| format!("({a}) R{i} ({b})")),
        ]
    })
}

fn names() -> Vec<String> {
    vec!["x1".into(), "x2".into(), "x3".into()]
}

/// Samples at t = 0, 1, …, N of three signals, small integers and reals mixed (ties included).
fn nominal() -> impl Strategy<Value = Vec<[f64; 3]>> {
    (2usize..14).prop_flat_map(|n| {
        proptest::collection::vec(
            [
                prop_oneof![(-3i32..4).prop_map(f64::from), -4.0..4.0f64],
                prop_oneof![(-3i32..4).prop_map(f64::from), -4.0..4.0f64],
                prop_oneof![(-3i32..4).prop_map(f64::from), -4.0..4.0f64],
            ],
            n,
        )
    })
}

fn trace(t: Vec<f64>, rows: &[[f64; 3]]) -> Trace {
    let cols = (0..3)
        .map(|i| rows.iter().map(|r| r[i]).collect())
        .collect();
    Trace::new(t, names(), cols).unwrap()
}

/// A point within `m` (Euclidean) of `x`, from a direction and a fraction in [0, 1].
fn within(x: &[f64; 3], dir: &[f64; 3], frac: f64, m: f64) -> [f64; 3] {
    let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2])
        .sqrt()
        .max(1e-12);
    let s = frac * m / n;
    [x[0] + s * dir[0], x[1] + s * dir[1], x[2] + s * dir[2]]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 800, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn without_margins_the_tube_is_the_monitor(f in formula(), rows in nominal()) {
        let sets = vec![NamedSet::euclidean("S", vec!["x1".into(), "x2".into()], Box::new(B))];
        let tr = trace((0..rows.len()).map(|k| k as f64).collect(), &rows);
        let m = Formula::parse(&f).unwrap().bind(tr.names(), &sets).unwrap();
        let tube = TubeFormula::new(&m, &tr).unwrap();
        prop_assert_eq!(tube.samples(), m.robustness(&tr).unwrap(), "formula {}", f);
    }

    #[test]
    fn the_lower_bound_holds_for_every_trajectory_of_the_tube(
        f in formula(),
        rows in nominal(),
        r in 0.0..0.6f64,
        extra in proptest::collection::vec(0.0..0.4f64, 13),
        dirs in proptest::collection::vec([-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64], 8 * 14),
        fracs in proptest::collection::vec(prop_oneof![Just(1.0), 0.0..1.0f64], 8 * 14),
    ) {
        let sets = vec![NamedSet::euclidean("S", vec!["x1".into(), "x2".into()], Box::new(B))];
        let n = rows.len() - 1;
        let nom = trace((0..=n).map(|k| k as f64).collect(), &rows);
        let m = Formula::parse(&f).unwrap().bind(nom.names(), &sets).unwrap();
        let tube = TubeFormula::new(&m, &nom).unwrap();
        let between: Vec<f64> = (0..n).map(|k| r + extra[k]).collect();
        let lower = tube.lower_at_start(&Margins { r, between: &between });
        // A trajectory of the tube, eight points per interval: within r of the nominal at the samples,
        // within between[k] of the sample x̃(k) inside I_k.
        let mut t = Vec::new();
        let mut fine = Vec::new();
        for k in 0..=n {
            let i = k * 8;
            t.push(k as f64);
            fine.push(within(&rows[k], &dirs[i], fracs[i], r));
            if k < n {
                for s in 1..8 {
                    t.push(k as f64 + s as f64 / 8.0);
                    fine.push(within(&rows[k], &dirs[i + s], fracs[i + s], between[k]));
                }
            }
        }
        let run = trace(t, &fine);
        let value = m.robustness(&run).unwrap()[0];
        prop_assert!(lower <= value, "formula {}: lower bound {} > robustness {} of a tube trajectory", f, lower, value);
    }
}

#[test]
fn margins_lower_the_bound_by_at_least_the_margin() {
    // F[0,2] S on a nominal that enters S at sample 2 with depth 0.5: the bound at r is 0.5 − r at most.
    let sets = vec![NamedSet::euclidean(
        "S",
        vec!["x1".into(), "x2".into()],
        Box::new(B),
    )];
    let rows = [
        [3.0, 3.0, 0.0],
        [2.0, 1.0, 0.0],
        [0.5, -0.5, 0.0],
        [3.0, 3.0, 0.0],
    ];
    let tr = trace(vec![0.0, 1.0, 2.0, 3.0], &rows);
    let m = Formula::parse("F[0,2] S")
        .unwrap()
        .bind(tr.names(), &sets)
        .unwrap();
    let tube = TubeFormula::new(&m, &tr).unwrap();
    assert_eq!(tube.samples()[0], 1.5);
    let between = [0.3, 0.3, 0.3];
    assert_eq!(
        tube.lower_at_start(&Margins {
            r: 0.2,
            between: &between
        }),
        1.3
    );
    // G[0,3] !S: the nominal is in S at sample 2, so the bound is negative whatever the margin.
    let m = Formula::parse("G[0,3] !S")
        .unwrap()
        .bind(tr.names(), &sets)
        .unwrap();
    let tube = TubeFormula::new(&m, &tr).unwrap();
    assert!(
        tube.lower_at_start(&Margins {
            r: 0.0,
            between: &[0.0; 3]
        }) < 0.0
    );
}
