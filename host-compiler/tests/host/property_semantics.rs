//! The one interface for scoring a trace against a property ([`host_compiler::property::Property`]):
//! reach-avoid (through the shared Theorem 4.7 scans) and an MTL formula (through the streaming
//! monitor) are two independent implementations, and on the until embedding of Remark 2.29 they must
//! agree exactly, on random traces, with and without Unsafe.

#![allow(non_snake_case)]

use host_compiler::geometry::Ball;
use host_compiler::property::{InputBound, Property, ReachAvoid, SemanticsError, Temporal};
use host_compiler::robustness::mtl::{Formula, NamedSet, Trace};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn ball(c: [f64; 2], r: f64) -> Box<Ball> {
    Box::new(Ball::new(c.to_vec(), vec![1.0, 0.0, 0.0, 1.0], r).unwrap())
}

fn xy() -> Vec<String> {
    vec!["x1".into(), "x2".into()]
}

#[test]
fn reach_avoid_equals_its_until_embedding_in_mtl() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x0002_9229);
    let (mut positive, mut negative) = (0, 0);
    for case in 0..400 {
        let len = rng.random_range(1..40);
        let h = 0.1;
        let times: Vec<f64> = (0..len).map(|k| k as f64 * h).collect();
        // A random walk from near the origin towards (3, 0), passing near an obstacle at (1.5, y).
        let mut cols = vec![Vec::with_capacity(len), Vec::with_capacity(len)];
        let (mut x, mut y) = (rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
        for _ in 0..len {
            cols[0].push(x);
            cols[1].push(y);
            x += rng.random_range(0.0..0.25);
            y += rng.random_range(-0.15..0.15);
        }
        let trace = Trace::new(times, xy(), cols).unwrap();
        let goal_c = [rng.random_range(1.0..4.0), rng.random_range(-0.5..0.5)];
        let goal_r = rng.random_range(0.2..1.0);
        let uns_c = [rng.random_range(0.5..2.5), rng.random_range(-0.6..0.6)];
        let uns_r = rng.random_range(0.05..0.4);
        let with_unsafe = case % 4 != 0;
        let T = rng.random_range(0.0..4.0);
        let ra = ReachAvoid {
            goal: ball(goal_c, goal_r),
            unsafe_set: with_unsafe.then(|| ball(uns_c, uns_r) as _),
            input: InputBound::Box {
                lo: vec![-1.0],
                hi: vec![1.0],
            },
            horizon: T,
        };
        let mut sets = vec![NamedSet::euclidean("goal", xy(), ball(goal_c, goal_r))];
        let src = if with_unsafe {
            sets.push(NamedSet::euclidean("obstacle", xy(), ball(uns_c, uns_r)));
            format!("!obstacle & (!obstacle U[0,{T:?}] (goal & !obstacle))")
        } else {
            format!("F[0,{T:?}] goal")
        };
        let mtl = Temporal {
            formula: Formula::parse(&src).unwrap(),
            sets,
        };
        let a = ra.trace_robustness(&trace).unwrap();
        let b = mtl.trace_robustness(&trace).unwrap();
        assert_eq!(a, b, "case {case}: reach-avoid {a} vs `{src}` {b}");
        if a > 0.0 {
            positive += 1;
        } else {
            negative += 1;
        }
    }
    // Both outcomes occur, so the agreement is not only on one side of zero.
    assert!(positive > 40 && negative > 40, "{positive} / {negative}");
}

#[test]
fn a_trace_over_the_wrong_signals_is_refused() {
    let ra = ReachAvoid {
        goal: ball([1.0, 0.0], 0.5),
        unsafe_set: None,
        input: InputBound::Box {
            lo: vec![-1.0],
            hi: vec![1.0],
        },
        horizon: 1.0,
    };
    let trace = Trace::new(vec![0.0, 0.1], vec!["x1".into()], vec![vec![0.0, 0.1]]).unwrap();
    let e = ra.trace_robustness(&trace).unwrap_err();
    assert!(
        matches!(e, SemanticsError::Signals { found: 1, n: 2 }),
        "{e:?}"
    );
    assert!(
        e.to_string()
            .contains("1 signals but the property is over 2 states"),
        "{e}"
    );
}
