//! Tests of the safety robustness of Theorem 4.7 (`host_compiler::robustness::safety`): hand-computed
//! cases, a brute-force oracle on random instances, soundness of the certified radius against random
//! perturbations, tightness via the critical points, and input validation.

#![allow(non_snake_case)]

use host_compiler::geometry::{Ball, Ellipsoid, Metric, Region, Witness};
use host_compiler::robustness::{
    goal_part, input_part, safety_robustness, safety_robustness_joint, unsafe_part, Binding,
    FnInput, InputSets, SafetyError, SafetySet, SafetySpec, SampledTrajectory,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// {x : ‖x − c‖_R ≤ r} for a fixed positive definite R; exact distances in that same metric.
struct NormBall {
    c: Vec<f64>,
    r: f64,
    metric: Metric,
}

fn quad(R: &[f64], v: &[f64]) -> f64 {
    let n = v.len();
    let mut s = 0.0;
    for i in 0..n {
        for j in 0..n {
            s += v[i] * R[i * n + j] * v[j];
        }
    }
    s
}

impl NormBall {
    fn norm(&self, v: &[f64]) -> f64 {
        quad(&self.metric.R, v).max(0.0).sqrt()
    }
    fn boundary_point(&self, x: &[f64]) -> Vec<f64> {
        let d: Vec<f64> = x.iter().zip(&self.c).map(|(a, b)| a - b).collect();
        let nd = self.norm(&d);
        if nd == 0.0 {
            // Any boundary point: along the first axis.
            let mut e = vec![0.0; x.len()];
            e[0] = 1.0;
            let ne = self.norm(&e);
            return self
                .c
                .iter()
                .zip(&e)
                .map(|(c, e)| c + self.r * e / ne)
                .collect();
        }
        self.c
            .iter()
            .zip(&d)
            .map(|(c, d)| c + self.r * d / nd)
            .collect()
    }
    fn gap(&self, x: &[f64]) -> f64 {
        let d: Vec<f64> = x.iter().zip(&self.c).map(|(a, b)| a - b).collect();
        self.norm(&d) - self.r
    }
}

impl Region for NormBall {
    fn dim(&self) -> usize {
        self.c.len()
    }
    fn contains(&self, x: &[f64]) -> bool {
        self.gap(x) <= 0.0
    }
    fn dist(&self, x: &[f64], m: &Metric) -> Witness {
        assert_eq!(m, &self.metric, "test ball queried in a different metric");
        if self.contains(x) {
            Witness {
                value: 0.0,
                point: x.to_vec(),
            }
        } else {
            Witness {
                value: self.gap(x),
                point: self.boundary_point(x),
            }
        }
    }
    fn depth(&self, x: &[f64], m: &Metric) -> Witness {
        assert_eq!(m, &self.metric, "test ball queried in a different metric");
        if self.contains(x) {
            Witness {
                value: -self.gap(x),
                point: self.boundary_point(x),
            }
        } else {
            Witness {
                value: 0.0,
                point: x.to_vec(),
            }
        }
    }
}

/// A region whose distances are NaN (a broken geometry routine).
struct NanRegion(usize);
impl Region for NanRegion {
    fn dim(&self) -> usize {
        self.0
    }
    fn contains(&self, _: &[f64]) -> bool {
        false
    }
    fn dist(&self, x: &[f64], _: &Metric) -> Witness {
        Witness {
            value: f64::NAN,
            point: x.to_vec(),
        }
    }
    fn depth(&self, x: &[f64], _: &Metric) -> Witness {
        Witness {
            value: f64::NAN,
            point: x.to_vec(),
        }
    }
}

fn ball(c: &[f64], r: f64, m: &Metric) -> NormBall {
    NormBall {
        c: c.to_vec(),
        r,
        metric: m.clone(),
    }
}

/// Straight line from (0,0) to (2,0) at unit speed, sampled every 0.01 (Example 4.8's geometry in the
/// plane): Goal = B((2,0), 0.1), Unsafe = B((1,1), 0.3).
fn line() -> (Vec<f64>, Vec<f64>) {
    let N = 201;
    let t: Vec<f64> = (0..N).map(|k| k as f64 * 0.01).collect();
    let x: Vec<f64> = t.iter().flat_map(|&s| [s, 0.0]).collect();
    (t, x)
}

#[test]
fn straight_line_hand_computed() {
    let m = Metric::euclidean(2);
    let goal = ball(&[2.0, 0.0], 0.1, &m);
    let unsafe_set = ball(&[1.0, 1.0], 0.3, &m);
    let (t, x) = line();
    let traj = SampledTrajectory::new(&t, &x, 2).unwrap();
    let spec = SafetySpec {
        goal: SafetySet::Region(&goal),
        unsafe_set: SafetySet::Region(&unsafe_set),
        input: None,
        metric: &m,
        T: 5.0,
    };
    let r = safety_robustness(&traj, &spec).unwrap();
    // Goal depth is largest at the end point (2,0), the centre: depth 0.1.
    assert_eq!(r.goal.index, 200);
    assert!((r.goal.value - 0.1).abs() < 1e-12);
    assert!((r.t_star() - 2.0).abs() < 1e-12);
    // Closest approach to Unsafe is at (1,0): 1 − 0.3 = 0.7, witness (1, 0.7).
    assert_eq!(r.unsafe_set.index, 100);
    assert!((r.unsafe_set.value - 0.7).abs() < 1e-12);
    assert!(
        (r.unsafe_set.point[0] - 1.0).abs() < 1e-12 && (r.unsafe_set.point[1] - 0.7).abs() < 1e-12
    );
    assert_eq!(r.binding, Binding::Goal);
    assert!((r.delta - 0.1).abs() < 1e-12);
    assert!(r.input.is_none());
    assert_eq!(r.horizon_samples, 201);

    // With T = 1.5 the goal is not reached: δ_Goal = −(distance to Goal) at the closest sample.
    let spec = SafetySpec { T: 1.5, ..spec };
    let r = safety_robustness(&traj, &spec).unwrap();
    assert_eq!(r.horizon_samples, 151);
    assert_eq!(r.goal.index, 150);
    assert!((r.goal.value - (-(0.5 - 0.1))).abs() < 1e-12);
    assert!(
        (r.goal.point[0] - 1.9).abs() < 1e-12,
        "witness is the nearest goal point"
    );
    assert!(!r.is_certified());
    assert_eq!(r.certified_radius(), 0.0);
}

#[test]
fn input_constraint_binds_and_only_counts_up_to_t_star() {
    // u = K x + v(κ) with K = [-1, 0], v(κ) = 0 and Input = {|u| ≤ 1.5}: admissible states |x1| ≤ 1.5,
    // i.e. A_κ = {x : x1 ≤ 1.5} on this trajectory (x1 ≥ 0). Its signed distance is 1.5 − x1.
    let m = Metric::euclidean(2);
    let goal = ball(&[1.0, 0.0], 0.2, &m);
    let unsafe_set = ball(&[1.0, 1.0], 0.3, &m);
    let input = FnInput(|_k: usize, x: &[f64], _m: &Metric| Witness {
        value: 1.5 - x[0],
        point: vec![1.5, x[1]],
    });
    let (t, x) = line();
    let traj = SampledTrajectory::new(&t, &x, 2).unwrap();
    let spec = SafetySpec {
        goal: SafetySet::Region(&goal),
        unsafe_set: SafetySet::Region(&unsafe_set),
        input: Some(&input),
        metric: &m,
        T: 10.0,
    };
    let r = safety_robustness(&traj, &spec).unwrap();
    // t* = 1.0 (centre of Goal); the input minimum over [0, t*] is at t* itself: 1.5 − 1.0 = 0.5,
    // although the trajectory later saturates the input (x1 = 2 gives −0.5).
    assert_eq!(r.goal.index, 100);
    let inp = r.input.clone().unwrap();
    assert_eq!(inp.index, 100);
    assert!((inp.value - 0.5).abs() < 1e-12);
    assert_eq!(inp.point, vec![1.5, 0.0]);
    // Unsafe: at (1,0) the distance is 0.7; δ₀ = min(0.2, 0.7, 0.5) = 0.2 (Goal).
    assert_eq!(r.binding, Binding::Goal);
    assert!((r.delta - 0.2).abs() < 1e-12);

    // Tighter input bound |u| ≤ 1.1: δ_Input = 0.1 binds.
    let input = FnInput(|_k: usize, x: &[f64], _m: &Metric| Witness {
        value: 1.1 - x[0],
        point: vec![1.1, x[1]],
    });
    let spec = SafetySpec {
        input: Some(&input),
        ..spec
    };
    let r = safety_robustness(&traj, &spec).unwrap();
    assert_eq!(r.binding, Binding::Input);
    assert!((r.delta - 0.1).abs() < 1e-12);
}

#[test]
fn trajectory_through_unsafe_is_negative_by_the_depth() {
    let m = Metric::euclidean(2);
    let goal = ball(&[2.0, 0.0], 0.1, &m);
    let unsafe_set = ball(&[1.0, 0.1], 0.3, &m); // the line passes 0.1 from its centre
    let (t, x) = line();
    let traj = SampledTrajectory::new(&t, &x, 2).unwrap();
    let spec = SafetySpec {
        goal: SafetySet::Region(&goal),
        unsafe_set: SafetySet::Region(&unsafe_set),
        input: None,
        metric: &m,
        T: 5.0,
    };
    let r = safety_robustness(&traj, &spec).unwrap();
    assert_eq!(r.binding, Binding::Unsafe);
    assert_eq!(r.unsafe_set.index, 100);
    assert!(
        (r.unsafe_set.value - (-0.2)).abs() < 1e-12,
        "−depth of (1,0) in Unsafe"
    );
    assert!(!r.is_certified());
}

/// A random instance: a random walk that tends towards a goal ball, an unsafe ball near the path, a
/// random positive definite metric and per-sample input sets as balls around moving centres.
struct Instance {
    t: Vec<f64>,
    x: Vec<f64>,
    n: usize,
    m: Metric,
    goal: NormBall,
    unsafe_set: NormBall,
    inputs: Vec<Box<dyn Region>>,
    T: f64,
}

fn instance(rng: &mut ChaCha8Rng) -> Instance {
    let n = rng.random_range(1..=3);
    let N = rng.random_range(1..=60);
    // R = L Lᵀ + 0.1 I.
    let L: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mut R = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            R[i * n + j] = (0..n).map(|k| L[i * n + k] * L[j * n + k]).sum::<f64>()
                + if i == j { 0.1 } else { 0.0 };
        }
    }
    let m = Metric { n, R };
    let mut t = Vec::with_capacity(N);
    let mut acc = 0.0;
    for _ in 0..N {
        acc += rng.random_range(0.05..0.5);
        t.push(acc);
    }
    let target: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
    let mut x = Vec::with_capacity(N * n);
    let mut p: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
    for _ in 0..N {
        x.extend_from_slice(&p);
        for i in 0..n {
            p[i] += 0.2 * (target[i] - p[i]) + rng.random_range(-0.2..0.2);
        }
    }
    let goal = NormBall {
        c: target,
        r: rng.random_range(0.05..1.0),
        metric: m.clone(),
    };
    let uc: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
    let unsafe_set = NormBall {
        c: uc,
        r: rng.random_range(0.05..1.0),
        metric: m.clone(),
    };
    let inputs: Vec<Box<dyn Region>> = (0..N)
        .map(|k| {
            let c: Vec<f64> = x[k * n..(k + 1) * n]
                .iter()
                .map(|v| v + rng.random_range(-0.5..0.5))
                .collect();
            Box::new(NormBall {
                c,
                r: rng.random_range(0.2..3.0),
                metric: m.clone(),
            }) as Box<dyn Region>
        })
        .collect();
    let T: f64 = t[0] + rng.random_range(-0.1..1.2) * (t[N - 1] - t[0] + 0.1);
    let T: f64 = T.max(t[0]);
    Instance {
        t,
        x,
        n,
        m,
        goal,
        unsafe_set,
        inputs,
        T,
    }
}

#[test]
fn matches_brute_force_on_random_instances() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5afe_7e57);
    let mut certified = 0;
    for case in 0..500 {
        let I = instance(&mut rng);
        let traj = SampledTrajectory::new(&I.t, &I.x, I.n).unwrap();
        let spec = SafetySpec {
            goal: SafetySet::Region(&I.goal),
            unsafe_set: SafetySet::Region(&I.unsafe_set),
            input: Some(&I.inputs as &dyn InputSets),
            metric: &I.m,
            T: I.T,
        };
        let r = safety_robustness(&traj, &spec).unwrap();
        let j = safety_robustness_joint(&traj, &spec).unwrap();

        let N = I.t.iter().filter(|&&s| s <= I.T).count();
        let st = |k: usize| &I.x[k * I.n..(k + 1) * I.n];
        let g: Vec<f64> = (0..N).map(|k| -I.goal.gap(st(k))).collect();
        let u: Vec<f64> = (0..N).map(|k| I.unsafe_set.gap(st(k))).collect();
        let v: Vec<f64> = (0..N)
            .map(|k| I.inputs[k].signed_dist(st(k), &I.m).value)
            .collect();
        let pre = |s: &[f64], k: usize| s[..=k].iter().cloned().fold(f64::INFINITY, f64::min);
        let score = |k: usize| g[k].min(pre(&u, k)).min(pre(&v, k));
        // Theorem 4.7 by definition: among all maximisers of the Goal depth, the certified radius.
        let gmax = g.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let brute_thm = (0..N)
            .filter(|&k| g[k] == gmax)
            .map(score)
            .fold(f64::NEG_INFINITY, f64::max);
        // The joint variant: max over all candidate t*.
        let brute_joint = (0..N).map(score).fold(f64::NEG_INFINITY, f64::max);

        assert_eq!(r.horizon_samples, N, "case {case}");
        assert_eq!(r.goal.value, gmax, "case {case}");
        assert!(
            (r.delta - brute_thm).abs() <= 1e-12,
            "case {case}: {} vs {}",
            r.delta,
            brute_thm
        );
        assert!(
            (j.delta - brute_joint).abs() <= 1e-12,
            "case {case}: {} vs {}",
            j.delta,
            brute_joint
        );
        assert!(
            j.delta >= r.delta - 1e-15,
            "case {case}: joint is never worse"
        );
        // Reported parts are consistent with δ₀ and with their critical samples.
        for res in [&r, &j] {
            let parts = [
                res.goal.value,
                res.unsafe_set.value,
                res.input.as_ref().unwrap().value,
            ];
            assert_eq!(
                res.delta,
                parts.iter().cloned().fold(f64::INFINITY, f64::min),
                "case {case}"
            );
            let ks = res.goal.index;
            assert!(
                res.unsafe_set.index <= ks && res.input.as_ref().unwrap().index <= ks,
                "case {case}"
            );
            assert_eq!(res.unsafe_set.value, u[res.unsafe_set.index], "case {case}");
            assert_eq!(res.unsafe_set.value, pre(&u, ks), "case {case}");
            assert_eq!(res.goal.time, I.t[ks], "case {case}");
        }
        if r.is_certified() {
            certified += 1;
        }
    }
    assert!(
        certified > 50,
        "too few certified instances ({certified}) for the test to mean much"
    );
}

/// Theorem 4.7's guarantee: a trajectory that stays ψ-closer than δ₀ at every sample reaches Goal at t*,
/// avoids Unsafe and keeps the input admissible up to t*. And the critical points show δ₀ cannot grow.
#[test]
fn certified_radius_is_sound_and_tight() {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut checked = 0;
    for _ in 0..400 {
        let I = instance(&mut rng);
        let traj = SampledTrajectory::new(&I.t, &I.x, I.n).unwrap();
        let spec = SafetySpec {
            goal: SafetySet::Region(&I.goal),
            unsafe_set: SafetySet::Region(&I.unsafe_set),
            input: Some(&I.inputs as &dyn InputSets),
            metric: &I.m,
            T: I.T,
        };
        for r in [
            safety_robustness(&traj, &spec).unwrap(),
            safety_robustness_joint(&traj, &spec).unwrap(),
        ] {
            if !r.is_certified() {
                continue;
            }
            checked += 1;
            let ks = r.goal.index;
            for _ in 0..50 {
                for k in 0..=ks {
                    let xk = &I.x[k * I.n..(k + 1) * I.n];
                    let dir: Vec<f64> = (0..I.n).map(|_| rng.random_range(-1.0..1.0)).collect();
                    let nd = quad(&I.m.R, &dir).sqrt();
                    let scale =
                        r.delta * (1.0 - 1e-9) * rng.random_range(0.0f64..1.0).powf(0.2) / nd;
                    let y: Vec<f64> = xk.iter().zip(&dir).map(|(a, d)| a + scale * d).collect();
                    assert!(
                        !I.unsafe_set.contains(&y),
                        "perturbed state entered Unsafe at {k}"
                    );
                    assert!(
                        I.inputs[k].contains(&y),
                        "perturbed state left the admissible input set at {k}"
                    );
                    if k == ks {
                        assert!(I.goal.contains(&y), "perturbed state is not in Goal at t*");
                    }
                }
            }
            // Tightness: the binding part's critical point is exactly δ₀ away and violates the spec.
            let (c, inside_ok) = match r.binding {
                Binding::Goal => (&r.goal, None),
                Binding::Unsafe => (&r.unsafe_set, Some(false)),
                Binding::Input => (r.input.as_ref().unwrap(), None),
            };
            let xk = &I.x[c.index * I.n..(c.index + 1) * I.n];
            let d: Vec<f64> = c.point.iter().zip(xk).map(|(a, b)| a - b).collect();
            assert!((quad(&I.m.R, &d).sqrt() - r.delta).abs() < 1e-9 * (1.0 + r.delta));
            if inside_ok == Some(false) {
                assert!(
                    I.unsafe_set.gap(&c.point) <= 1e-9,
                    "critical point lies on Unsafe"
                );
            }
        }
    }
    assert!(checked > 50, "too few certified instances ({checked})");
}

#[test]
fn bad_input_is_an_error() {
    let m = Metric::euclidean(2);
    let goal = ball(&[2.0, 0.0], 0.1, &m);
    let unsafe_set = ball(&[1.0, 1.0], 0.3, &m);
    assert_eq!(
        SampledTrajectory::new(&[], &[], 2).unwrap_err(),
        SafetyError::Empty
    );
    assert_eq!(
        SampledTrajectory::new(&[0.0], &[0.0, 0.0], 0).unwrap_err(),
        SafetyError::ZeroDimension
    );
    assert!(matches!(
        SampledTrajectory::new(&[0.0, 1.0], &[0.0; 3], 2),
        Err(SafetyError::LengthMismatch {
            times: 2,
            states: 3,
            n: 2,
            expected: 4
        })
    ));
    assert!(matches!(
        SampledTrajectory::new(&[0.0, 1.0, 1.0], &[0.0; 6], 2),
        Err(SafetyError::NonMonotoneTime { index: 2, .. })
    ));
    assert!(matches!(
        SampledTrajectory::new(&[0.0, f64::NAN], &[0.0; 4], 2),
        Err(SafetyError::NonFiniteTime { index: 1, .. })
    ));
    assert!(matches!(
        SampledTrajectory::new(&[0.0, 1.0], &[0.0, 0.0, 0.0, f64::INFINITY], 2),
        Err(SafetyError::NonFiniteState {
            index: 1,
            component: 1,
            ..
        })
    ));
    let msg = SampledTrajectory::new(&[0.0, 1.0, 0.5], &[0.0; 6], 2)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("t[2] = 0.5") && msg.contains("t[1] = 1"),
        "{msg}"
    );

    let (t, x) = line();
    let traj = SampledTrajectory::new(&t, &x, 2).unwrap();
    let spec = SafetySpec {
        goal: SafetySet::Region(&goal),
        unsafe_set: SafetySet::Region(&unsafe_set),
        input: None,
        metric: &m,
        T: -1.0,
    };
    assert!(matches!(
        safety_robustness(&traj, &spec),
        Err(SafetyError::HorizonBeforeStart { .. })
    ));
    let spec = SafetySpec {
        T: f64::NAN,
        ..spec
    };
    assert!(matches!(
        safety_robustness(&traj, &spec),
        Err(SafetyError::HorizonNaN { .. })
    ));
    let g3 = ball(&[2.0, 0.0, 0.0], 0.1, &Metric::euclidean(3));
    let spec = SafetySpec {
        T: 5.0,
        goal: SafetySet::Region(&g3),
        ..spec
    };
    assert!(matches!(
        safety_robustness(&traj, &spec),
        Err(SafetyError::DimensionMismatch {
            what: "Goal",
            found: 3,
            n: 2
        })
    ));
    let m3 = Metric::euclidean(3);
    let spec = SafetySpec {
        goal: SafetySet::Region(&goal),
        metric: &m3,
        ..spec
    };
    assert!(matches!(
        safety_robustness_joint(&traj, &spec),
        Err(SafetyError::DimensionMismatch { what: "metric", .. })
    ));
    let short: Vec<Box<dyn Region>> = (0..10)
        .map(|_| Box::new(ball(&[0.0, 0.0], 5.0, &m)) as Box<dyn Region>)
        .collect();
    let spec = SafetySpec {
        metric: &m,
        input: Some(&short as &dyn InputSets),
        ..spec
    };
    assert!(matches!(
        safety_robustness(&traj, &spec),
        Err(SafetyError::InputTooShort {
            needed: 201,
            available: 10
        })
    ));
    let nan = NanRegion(2);
    let spec = SafetySpec {
        input: None,
        unsafe_set: SafetySet::Region(&nan),
        ..spec
    };
    assert!(matches!(
        safety_robustness(&traj, &spec),
        Err(SafetyError::NaNDistance {
            what: "Unsafe",
            index: 0
        })
    ));
    assert!(matches!(
        safety_robustness_joint(&traj, &spec),
        Err(SafetyError::NaNDistance {
            what: "Unsafe",
            index: 0
        })
    ));
}

/// The prepared ellipsoid path gives the same result as the generic `Region` path on geometry's
/// ellipsoids and CAF balls (same critical samples, values and witness points).
#[test]
fn prepared_ellipsoid_path_matches_generic_region_path() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for case in 0..60 {
        let I = instance(&mut rng);
        let n = I.n;
        // Ellipsoid goal with a random positive definite shape, CAF ball as Unsafe.
        let Lq: Vec<f64> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut Q = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                Q[i * n + j] = (0..n).map(|k| Lq[i * n + k] * Lq[j * n + k]).sum::<f64>()
                    + if i == j { 0.5 } else { 0.0 };
            }
        }
        let goal = Ellipsoid::new(I.goal.c.clone(), Q).unwrap();
        let unsafe_set = Ball::new(I.unsafe_set.c.clone(), I.m.R.clone(), I.unsafe_set.r).unwrap();
        let traj = SampledTrajectory::new(&I.t, &I.x, n).unwrap();
        let fast = SafetySpec {
            goal: (&goal).into(),
            unsafe_set: (&unsafe_set).into(),
            input: Some(&I.inputs as &dyn InputSets),
            metric: &I.m,
            T: I.T,
        };
        let slow = SafetySpec {
            goal: SafetySet::Region(&goal),
            unsafe_set: SafetySet::Region(&unsafe_set),
            ..fast
        };
        for (a, b) in [
            (
                safety_robustness(&traj, &fast).unwrap(),
                safety_robustness(&traj, &slow).unwrap(),
            ),
            (
                safety_robustness_joint(&traj, &fast).unwrap(),
                safety_robustness_joint(&traj, &slow).unwrap(),
            ),
        ] {
            assert_eq!(a.goal.index, b.goal.index, "case {case}");
            assert_eq!(a.unsafe_set.index, b.unsafe_set.index, "case {case}");
            assert_eq!(a.binding, b.binding, "case {case}");
            assert!(
                (a.delta - b.delta).abs() <= 1e-12,
                "case {case}: {} vs {}",
                a.delta,
                b.delta
            );
            for (p, q) in a
                .goal
                .point
                .iter()
                .zip(&b.goal.point)
                .chain(a.unsafe_set.point.iter().zip(&b.unsafe_set.point))
            {
                assert!((p - q).abs() <= 1e-12, "case {case}");
            }
            // The Unsafe part of a CAF ball of radius r is ‖x̃ − c‖_P − r at its critical sample.
            let k = a.unsafe_set.index;
            let xk = &I.x[k * n..(k + 1) * n];
            assert!(
                (a.unsafe_set.value - I.unsafe_set.gap(xk)).abs()
                    <= 1e-9 * (1.0 + a.unsafe_set.value.abs()),
                "case {case}"
            );
        }
    }
}

/// The three scans certification shares ([`goal_part`], [`unsafe_part`] with a per-sample margin,
/// [`input_part`]) against direct scans of the same values: first extremum, its value, every range end,
/// no Unsafe set (+∞), and no input sample (`None`).
#[test]
fn shared_scans_match_direct_scans_over_any_range() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5ca7_0001);
    for case in 0..300 {
        let I = instance(&mut rng);
        let traj = SampledTrajectory::new(&I.t, &I.x, I.n).unwrap();
        let len = I.t.len();
        let end = rng.random_range(1..=len);
        let st = |k: usize| &I.x[k * I.n..(k + 1) * I.n];
        let first = |vals: &[f64], better: &dyn Fn(f64, f64) -> bool| {
            let mut b = (0, vals[0]);
            for (k, &v) in vals.iter().enumerate().skip(1) {
                if better(v, b.1) {
                    b = (k, v);
                }
            }
            b
        };
        let g: Vec<f64> = (0..end)
            .map(|k| I.goal.signed_dist(st(k), &I.m).value)
            .collect();
        let goal = goal_part(&traj, SafetySet::Region(&I.goal), &I.m, end).unwrap();
        let (kg, vg) = first(&g, &|a, b| a > b);
        assert_eq!((goal.index, goal.value), (kg, vg), "case {case}: Goal");

        let u: Vec<f64> = (0..end)
            .map(|k| -I.unsafe_set.signed_dist(st(k), &I.m).value)
            .collect();
        let umin = u.iter().cloned().fold(f64::INFINITY, f64::min);
        let margin = |k: usize, d: f64, dmin: f64| {
            assert_eq!(
                dmin, umin,
                "the margin sees the smallest distance at the samples"
            );
            (d - 0.01 * k as f64) / 1.5
        };
        let um: Vec<f64> = u
            .iter()
            .enumerate()
            .map(|(k, &d)| margin(k, d, umin))
            .collect();
        let up = unsafe_part(
            &traj,
            Some(SafetySet::Region(&I.unsafe_set)),
            &I.m,
            end,
            Some(&margin),
        )
        .unwrap();
        let (ku, vu) = first(&u, &|a, b| a < b);
        let (kum, vum) = first(&um, &|a, b| a < b);
        assert_eq!(
            (up.at_samples.index, up.at_samples.value),
            (ku, vu),
            "case {case}: Unsafe"
        );
        let m = up.margined.expect("a margin was given");
        assert_eq!(
            (m.index, m.value),
            (kum, vum),
            "case {case}: Unsafe after the margin"
        );
        let plain = unsafe_part(
            &traj,
            Some(SafetySet::Region(&I.unsafe_set)),
            &I.m,
            end,
            None,
        )
        .unwrap();
        assert_eq!(
            plain.at_samples, up.at_samples,
            "case {case}: with and without the margin"
        );
        assert!(plain.margined.is_none());

        let none = unsafe_part(&traj, None, &I.m, end, Some(&margin)).unwrap();
        assert_eq!(none.at_samples.value, f64::INFINITY);
        assert_eq!(none.margined.map(|c| c.value), Some(f64::INFINITY));

        let iend = rng.random_range(0..=end);
        let ip = input_part(&traj, &I.inputs as &dyn InputSets, &I.m, iend).unwrap();
        if iend == 0 {
            assert!(ip.is_none(), "case {case}: no input sample, no Input part");
        } else {
            let v: Vec<f64> = (0..iend)
                .map(|k| I.inputs[k].signed_dist(st(k), &I.m).value)
                .collect();
            let ip = ip.expect("input samples were given");
            assert_eq!(
                (ip.index, ip.value),
                first(&v, &|a, b| a < b),
                "case {case}: Input"
            );
        }
    }
}
