//! Hand-computed robustness values for every MTL operator (Def 2.17 on discrete traces), precedence of
//! the parser, set atoms, non-uniform sample times and the end-of-trace rule.

use host_compiler::geometry::{Metric, Region, Witness};
use host_compiler::robustness::mtl::{self, robustness_naive, Formula, NamedSet, Trace};

const INF: f64 = f64::INFINITY;

/// t = 0..4; x1 = φ-values, x2 = ψ-values used throughout (hand computations in the comments).
fn trace() -> Trace {
    Trace::new(
        vec![0.0, 1.0, 2.0, 3.0, 4.0],
        vec!["x1".into(), "x2".into()],
        vec![
            vec![1.0, -1.0, 2.0, 0.5, 3.0],
            vec![-5.0, 4.0, -2.0, 1.0, 0.0],
        ],
    )
    .unwrap()
}

/// Evaluate with the streaming evaluator, check the naive oracle agrees exactly, return the signal.
fn rho(f: &str, tr: &Trace, sets: &[NamedSet]) -> Vec<f64> {
    let fast = mtl::robustness(f, tr, sets).unwrap_or_else(|e| panic!("{f}: {e}"));
    let m = Formula::parse(f).unwrap().bind(tr.names(), sets).unwrap();
    assert_eq!(
        fast,
        robustness_naive(&m, tr).unwrap(),
        "{f}: naive disagrees"
    );
    fast
}

fn close(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x == y || (x - y).abs() <= 1e-12)
}

#[track_caller]
fn check(f: &str, expected: &[f64]) {
    let got = rho(f, &trace(), &[]);
    assert!(
        close(&got, expected),
        "{f}: got {got:?}, expected {expected:?}"
    );
}

#[test]
fn atoms() {
    check("x1 >= 0.5", &[0.5, -1.5, 1.5, 0.0, 2.5]);
    check("x1 <= 0.5", &[-0.5, 1.5, -1.5, 0.0, -2.5]);
    check("0.5 <= x1", &[0.5, -1.5, 1.5, 0.0, 2.5]);
    // (1 − 2 x1 + x2)/√5.
    let s5 = 5f64.sqrt();
    check(
        "2*x1 - x2 <= 1",
        &[-6.0 / s5, 7.0 / s5, -5.0 / s5, 1.0 / s5, -5.0 / s5],
    );
    check(
        "x1*2 + -1*x2 < 1",
        &[-6.0 / s5, 7.0 / s5, -5.0 / s5, 1.0 / s5, -5.0 / s5],
    );
    // Terms on both sides and repeated names combine: 3 x1 − x1 ≥ x2 + 1 ⇔ 2 x1 − x2 ≥ 1.
    check(
        "3*x1 - x1 >= x2 + 1",
        &[6.0 / s5, -7.0 / s5, 5.0 / s5, -1.0 / s5, 5.0 / s5],
    );
    // The time column is a signal too.
    check("t >= 2", &[-2.0, -1.0, 0.0, 1.0, 2.0]);
    check("true", &[INF; 5]);
    check("false", &[-INF; 5]);
}

#[test]
fn boolean_connectives() {
    // φ = x1 ≥ 0: [1, −1, 2, 0.5, 3]; ψ = x2 ≥ 0: [−5, 4, −2, 1, 0].
    check("!(x1 >= 0)", &[-1.0, 1.0, -2.0, -0.5, -3.0]);
    check("x1 >= 0 & x2 >= 0", &[-5.0, -1.0, -2.0, 0.5, 0.0]);
    check("x1 >= 0 | x2 >= 0", &[1.0, 4.0, 2.0, 1.0, 3.0]);
    check("x1 >= 0 -> x2 >= 0", &[-1.0, 4.0, -2.0, 1.0, 0.0]);
    check("x1 >= 0 && x2 >= 0 || false", &[-5.0, -1.0, -2.0, 0.5, 0.0]);
}

#[test]
fn eventually_and_always() {
    // p = x1 ≥ 0.5: [0.5, −1.5, 1.5, 0, 2.5].
    check("F[1,2] x1 >= 0.5", &[1.5, 1.5, 2.5, 2.5, -INF]);
    check("G[0,2] x1 >= 0.5", &[-1.5, -1.5, 0.0, 0.0, 2.5]);
    check("G[1,1] x1 >= 0.5", &[-1.5, 1.5, 0.0, 2.5, INF]);
    check("F x1 >= 0.5", &[2.5; 5]);
    check("G x1 >= 0.5", &[-1.5, -1.5, 0.0, 0.0, 2.5]);
    check("F[0,inf] x1 >= 0.5", &[2.5; 5]);
    check("G[3,inf] x1 >= 0.5", &[0.0, 2.5, INF, INF, INF]);
    check("F[0,0] x1 >= 0.5", &[0.5, -1.5, 1.5, 0.0, 2.5]);
}

#[test]
fn until_with_strict_inner_interval() {
    // φ = x1 ≥ 0: [1, −1, 2, 0.5, 3]; ψ = x2 ≥ 0: [−5, 4, −2, 1, 0].
    // k=0: j=1 → 4; j=2 → min(−2, φ1) = −2.   k=1: j=2 → −2; j=3 → min(1, φ2) = 1.
    // k=2: j=3 → 1; j=4 → min(0, φ3) = 0.     k=3: j=4 → 0.  k=4: empty.
    check("x1 >= 0 U[1,2] x2 >= 0", &[4.0, 1.0, 1.0, 0.0, -INF]);
    // a = 0 includes j = k with an empty inner range.
    check("x1 >= 0 U[0,1] x2 >= 0", &[4.0, 4.0, 1.0, 1.0, 0.0]);
    // Only j = k + 2: inner range is exactly {k+1}; φ(k) must not count (k=1: φ1 = −1 would give −1).
    check("x1 >= 0 U[2,2] x2 >= 0", &[-2.0, 1.0, 0.0, -INF, -INF]);
    // Unbounded: k=0: max(−5, 4, min(−2,−1), min(1,−1,2), min(0,−1,2,0.5)) = 4.
    check("x1 >= 0 U x2 >= 0", &[4.0, 4.0, 1.0, 1.0, 0.0]);
    // φ ≡ true gives F, φ ≡ false leaves only j = k and j = k + 1 (empty inner ranges).
    check("true U[1,2] x2 >= 0", &[4.0, 1.0, 1.0, 0.0, -INF]);
    check("false U x2 >= 0", &[4.0, 4.0, 1.0, 1.0, 0.0]);
    check("false U[2,4] x2 >= 0", &[-INF; 5]);
}

#[test]
fn release_is_the_dual_of_until() {
    // k=0: min(ψ1=4, max(ψ2=−2, φ1=−1)) = −1; k=1: min(−2, max(1, φ2=2)) = −2;
    // k=2: min(1, max(0, φ3=0.5)) = 0.5; k=3: 0; k=4: empty → +∞.
    check("x1 >= 0 R[1,2] x2 >= 0", &[-1.0, -2.0, 0.5, 0.0, INF]);
    let r = rho("x1 >= 0 R[1,2] x2 >= 0", &trace(), &[]);
    let d = rho("!(!(x1 >= 0) U[1,2] !(x2 >= 0))", &trace(), &[]);
    assert_eq!(r, d);
    let g = rho("false R[0,2] x1 >= 0.5", &trace(), &[]);
    assert_eq!(g, rho("G[0,2] x1 >= 0.5", &trace(), &[]));
}

#[test]
fn non_uniform_times_map_windows_by_time() {
    let tr = Trace::new(
        vec![0.0, 0.5, 2.0, 2.1, 5.0],
        vec!["x1".into()],
        vec![vec![1.0, 2.0, 3.0, 4.0, 5.0]],
    )
    .unwrap();
    // F[1,2] at t=0: samples with t ∈ [1,2] → {2.0}; at 0.5: [1.5,2.5] → {2.0, 2.1}; later: none.
    let r = rho("F[1,2] x1 >= 0", &tr, &[]);
    assert_eq!(r, vec![3.0, 4.0, -INF, -INF, -INF]);
    // G[0,1.6]: t=0 → {0, 0.5}; 0.5 → {0.5, 2.0, 2.1}; 2.0 → {2.0, 2.1}; 2.1 → {2.1}; 5 → {5}.
    let r = rho("G[0,1.6] x1 >= 0", &tr, &[]);
    assert_eq!(r, vec![1.0, 2.0, 3.0, 4.0, 5.0]);
    // Closed bounds: 2.0 − 0.5 = 1.5 exactly, so G[1.5,1.5] at t=0.5 sees exactly x1(2.0).
    let r = rho("G[1.5,1.5] x1 >= 0", &tr, &[]);
    assert_eq!(r[1], 3.0);
}

/// The closed Euclidean unit disc around the origin in (x1, x2).
struct Disc;
impl Region for Disc {
    fn dim(&self) -> usize {
        2
    }
    fn contains(&self, x: &[f64]) -> bool {
        x[0].hypot(x[1]) <= 1.0
    }
    fn dist(&self, x: &[f64], _: &Metric) -> Witness {
        let r = x[0].hypot(x[1]);
        Witness {
            value: (r - 1.0).max(0.0),
            point: vec![x[0] / r, x[1] / r],
        }
    }
    fn depth(&self, x: &[f64], _: &Metric) -> Witness {
        let r = x[0].hypot(x[1]);
        Witness {
            value: (1.0 - r).max(0.0),
            point: vec![x[0] / r, x[1] / r],
        }
    }
}

#[test]
fn set_atoms_use_signed_distance() {
    let tr = Trace::new(
        vec![0.0, 1.0, 2.0],
        vec!["a".into(), "p".into(), "q".into()],
        vec![
            vec![9.0, 9.0, 9.0],
            vec![0.0, 3.0, 0.6],
            vec![0.5, 4.0, 0.8],
        ],
    )
    .unwrap();
    let sets = vec![NamedSet::euclidean(
        "Disc",
        vec!["p".into(), "q".into()],
        Box::new(Disc),
    )];
    // |(0, .5)| = .5 → depth .5; |(3,4)| = 5 → −4; |(.6,.8)| = 1 → 0.
    assert!(close(&rho("Disc", &tr, &sets), &[0.5, -4.0, 0.0]));
    assert!(close(&rho("!Disc", &tr, &sets), &[-0.5, 4.0, -0.0]));
    assert!(close(&rho("G !Disc", &tr, &sets), &[-0.5, 0.0, 0.0]));
    assert!(close(
        &rho("F[1,1] Disc & a >= 0", &tr, &sets),
        &[-4.0, 0.0, -INF]
    ));
}

#[test]
fn precedence_and_associativity() {
    let show = |s: &str| Formula::parse(s).unwrap().expr().to_string();
    assert_eq!(show("!a & b"), "(!a & b)");
    assert_eq!(show("a | b & c"), "(a | (b & c))");
    assert_eq!(show("a -> b -> c"), "(a -> (b -> c))");
    assert_eq!(show("a & b -> c | d"), "((a & b) -> (c | d))");
    assert_eq!(show("F[0,1] a U b"), "(F[0.0,1.0] a U[0.0,inf] b)");
    assert_eq!(show("a U b U[1,2] c"), "(a U[0.0,inf] (b U[1.0,2.0] c))");
    assert_eq!(show("a U b & c"), "((a U[0.0,inf] b) & c)");
    // `!` binds tighter than nothing but the atom: G (¬(x1 ≥ 0)); x1 ≥ 0 is stored as −x1 ≤ 0.
    assert_eq!(show("G[1,2] !x1 >= 0"), "G[1.0,2.0] !(-1.0*x1 <= 0.0)");
    // Printing and re-parsing gives the same tree (up to spans).
    for s in [
        "x1 - 2*x2 >= -1.5e-3 U[0.5,2] !(S | x3 < 4)",
        "G[0,10] (x1 >= 0.5 & !Unsafe) -> F Goal",
    ] {
        let once = show(s);
        assert_eq!(show(&once), once);
    }
}

#[test]
fn robustness_signal_has_one_value_per_sample_and_single_sample_traces_work() {
    let tr = Trace::new(vec![3.0], vec!["x".into()], vec![vec![2.0]]).unwrap();
    assert_eq!(rho("G[0,5] x >= 1", &tr, &[]), vec![1.0]);
    assert_eq!(rho("F[1,5] x >= 1", &tr, &[]), vec![-INF]);
    assert_eq!(rho("x >= 0 U[0,1] x >= 1", &tr, &[]), vec![1.0]);
}
