//! Forced switching (Theorem 4.17, `certify::forced`) on Example 3.19's two locations driven across by the
//! controller: the backward recursion against its closed form for identity resets, a guard that binds,
//! closed-loop runs from the first ball's boundary that must pass every switch and reach Goal, and the
//! refusals of runs that are not forced-switching runs.

#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::caf::{design_locations, CafSettings, Design};
use host_compiler::certify::{
    certify_forced, ForcedCertificate, ForcedError, ForcedSegment, Loop, LoopConstants,
};
use host_compiler::geometry::Ball;

use crate::model_hybrid::example_3_19_modes;
use host_compiler::model::hybrid::{Edge, EdgeKind, Hybrid, Polytope, Reset};
use host_compiler::model::Plant;
use host_compiler::property::{InputBound, ReachAvoid};
use host_compiler::trajectory::Nominal;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const H: f64 = 0.05;
const N0: usize = 40;
const N1: usize = 80;

fn plant(guard: Polytope, kind: EdgeKind) -> Hybrid {
    let edge = Edge {
        from: 0,
        to: 1,
        guard,
        reset: Reset::identity(3),
        kind,
    };
    Hybrid::new(example_3_19_modes(), vec![edge], H).unwrap()
}

fn whole_space() -> Polytope {
    Polytope {
        a: vec![vec![1.0, 0.0, 0.0]],
        b: vec![1e6],
    }
}

/// The run's nominal segments (zero reference input: each location's closed loop from x0 = (−5, 1, 2),
/// Example 4.25's start) and the task, Goal a unit ball around where the second segment ends.
struct Run {
    hy: Hybrid,
    designs: [Design; 2],
    noms: [Nominal; 2],
    task: ReachAvoid,
}

fn run(guard: Polytope) -> Run {
    let hy = plant(guard, EdgeKind::Forced);
    let designs: [Design; 2] = design_locations(&hy, CafSettings::default().sigma)
        .expect("both locations have a CAF")
        .try_into()
        .unwrap();
    let x0 = vec![-5.0, 1.0, 2.0];
    let n0 = host_compiler::trajectory::simulate(
        hy.error_dynamics(0),
        designs[0].K.as_ref(),
        &x0,
        &vec![vec![0.0]; N0],
    );
    let start1 = hy.edges()[0].reset.apply(n0.x.last().unwrap());
    let n1 = host_compiler::trajectory::simulate(
        hy.error_dynamics(1),
        designs[1].K.as_ref(),
        &start1,
        &vec![vec![0.0]; N1],
    );
    let goal_c = n1.x.last().unwrap().clone();
    let task = ReachAvoid {
        goal: Box::new(Ball::new(goal_c, vec![1., 0., 0., 0., 1., 0., 0., 0., 1.], 1.0).unwrap()),
        unsafe_set: Some(Box::new(
            Ball::new(
                vec![-5.0, -4.0, 2.0],
                vec![1., 0., 0., 0., 1., 0., 0., 0., 1.],
                1.0,
            )
            .unwrap(),
        )),
        input: InputBound::Box {
            lo: vec![-60.0],
            hi: vec![60.0],
        },
        horizon: (N0 + N1) as f64 * H,
    };
    Run {
        hy,
        designs,
        noms: [n0, n1],
        task,
    }
}

fn certify(r: &Run) -> ForcedCertificate {
    let lps = [0, 1].map(|l| Loop::reach_avoid(&r.hy, l, &r.designs[l], &r.task));
    let lcs = lps.each_ref().map(|lp| LoopConstants::new(lp).unwrap());
    let segs = [
        ForcedSegment {
            lp: lps[0],
            lc: &lcs[0],
            nominal: &r.noms[0],
            switch: Some(&r.hy.edges()[0]),
            invariant: None,
        },
        ForcedSegment {
            lp: lps[1],
            lc: &lcs[1],
            nominal: &r.noms[1],
            switch: None,
            invariant: None,
        },
    ];
    certify_forced(&segs).unwrap()
}

fn p_norm(P: &Mat<f64>, e: &[f64]) -> f64 {
    let n = e.len();
    (0..n)
        .map(|i| (0..n).map(|j| e[i] * P[(i, j)] * e[j]).sum::<f64>())
        .sum::<f64>()
        .max(0.0)
        .sqrt()
}

/// λmax(P0⁻¹P1), through the symmetric form P0^{-1/2} P1 P0^{-1/2}.
fn lambda_max_rel(P0: &Mat<f64>, P1: &Mat<f64>) -> f64 {
    let is = host_compiler::linalg::sym_fn(P0.as_ref(), |l| 1.0 / l.sqrt()).unwrap();
    let M = &is * P1 * &is;
    *host_compiler::linalg::sym_eigenvalues(host_compiler::linalg::sym(M.as_ref()).as_ref())
        .unwrap()
        .last()
        .unwrap()
}

/// Points on the P-sphere of radius `r` around `c`.
fn sphere(P: &Mat<f64>, c: &[f64], r: f64, count: usize, seed: u64) -> Vec<Vec<f64>> {
    use rand::Rng;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let is = host_compiler::linalg::sym_fn(P.as_ref(), |l| 1.0 / l.sqrt()).unwrap();
    (0..count)
        .map(|_| {
            let w: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
            let e: Vec<f64> = (0..3)
                .map(|i| (0..3).map(|j| is[(i, j)] * w[j]).sum())
                .collect();
            let s = r / p_norm(P, &e);
            (0..3).map(|i| c[i] + s * e[i]).collect()
        })
        .collect()
}

/// The switch itself: every state of the first metric's sphere of radius δ₀ around the switching state
/// is in the guard and resets into the second ball; returns the largest ‖reset − x̃₁(0)‖/δ₁ and the
/// least guard slack seen (how close the samples come to each bound).
fn switch_holds(r: &Run, c: &ForcedCertificate, guard: &Polytope) -> (f64, f64) {
    let (d0, d1) = (c.segments[0].delta, c.segments[1].delta);
    let (mut worst, mut slack) = (0.0f64, f64::INFINITY);
    for y in sphere(&r.designs[0].P, &r.noms[0].x[N0], 0.999 * d0, 2000, 5) {
        assert!(guard.contains(&y), "not in the guard: {y:?}");
        slack = slack.min(-guard.margin(&y));
        let z = r.hy.edges()[0].reset.apply(&y);
        let gap: Vec<f64> = z.iter().zip(&r.noms[1].x[0]).map(|(a, b)| a - b).collect();
        let d = p_norm(&r.designs[1].P, &gap);
        assert!(d <= d1, "the reset misses the second ball: {d} > {d1}");
        worst = worst.max(d / d1);
    }
    (worst, slack)
}

/// Closed-loop runs from the boundary of the first ball, the controller switching by its table: every
/// run is in the guard at the switch, its reset lies in the second ball, it reaches Goal at the second
/// segment's critical sample, it never enters Unsafe and every input is admissible.
fn runs_pass(r: &Run, c: &ForcedCertificate, guard: &Polytope) {
    let d1 = c.segments[1].delta;
    let kstar = c.segments[1].k_star;
    for x0 in sphere(
        &r.designs[0].P,
        &r.noms[0].x[0],
        0.999 * c.segments[0].delta,
        300,
        17,
    ) {
        let mut x = x0;
        for (seg, nom) in r.noms.iter().enumerate() {
            let K = &r.designs[seg].K;
            if seg == 1 {
                assert!(guard.contains(&x), "not in the guard at the switch: {x:?}");
                x = r.hy.edges()[0].reset.apply(&x);
                let gap: Vec<f64> = x.iter().zip(&nom.x[0]).map(|(a, b)| a - b).collect();
                let d = p_norm(&r.designs[1].P, &gap);
                assert!(d <= d1, "the reset misses the second ball: {d} > {d1}");
            }
            let end = if seg == 1 { kstar } else { N0 };
            for k in 0..end {
                assert!(!r.task.unsafe_region().unwrap().contains(&x));
                let u = [(0..3).map(|j| K[(0, j)] * x[j]).sum::<f64>() + nom.v[k][0]];
                assert!(u[0].abs() <= 60.0);
                x = r.hy.step(seg, &x, &u);
            }
        }
        assert!(r.task.goal.contains(&x), "Goal missed: {x:?}");
    }
}

#[test]
fn identity_resets_give_the_largest_ball_inside_the_next_one() {
    let r = run(whole_space());
    let c = certify(&r);
    assert!(c.is_certified(), "{c:?}");
    let d1 = c.segments[1].delta;
    let expected = d1 / lambda_max_rel(&r.designs[0].P, &r.designs[1].P).sqrt();
    let got = c.segments[0].delta_goal;
    assert!(
        (got - expected).abs() <= 1e-7 * expected,
        "δ_Guard {got} vs δ₁/√λmax(P₀⁻¹P₁) = {expected}"
    );
    assert_eq!(
        c.segments[0].k_star, N0,
        "a forced switch is judged at the segment's end"
    );
    let (worst, _) = switch_holds(&r, &c, &whole_space());
    assert!(
        worst > 0.9,
        "the samples do not approach the second ball's boundary ({worst})"
    );
    runs_pass(&r, &c, &whole_space());
}

#[test]
fn a_guard_close_to_the_switching_state_binds() {
    let probe = run(whole_space());
    let x_sw = probe.noms[0].x[N0].clone();
    // {x : x1 ≥ x̃₁(N₀) − 0.01}, written −x1 ≤ −(x̃₁ − 0.01).
    let guard = Polytope {
        a: vec![vec![-1.0, 0.0, 0.0]],
        b: vec![-(x_sw[0] - 0.01)],
    };
    let r = run(guard.clone());
    let c = certify(&r);
    assert!(c.is_certified(), "{c:?}");
    let Pinv = host_compiler::linalg::sym_fn(r.designs[0].P.as_ref(), |l| 1.0 / l).unwrap();
    let guard_depth = 0.01 / Pinv[(0, 0)].sqrt();
    let ball_depth = c.segments[1].delta / lambda_max_rel(&r.designs[0].P, &r.designs[1].P).sqrt();
    let expected = guard_depth.min(ball_depth);
    assert!(
        guard_depth < ball_depth,
        "the guard should bind: {guard_depth} vs {ball_depth}"
    );
    let got = c.segments[0].delta_goal;
    assert!(
        (got - expected).abs() <= 1e-9 * expected,
        "{got} vs {expected}"
    );
    let (_, slack) = switch_holds(&r, &c, &guard);
    assert!(
        slack < 0.1 * 0.01,
        "the samples do not approach the guard ({slack})"
    );
    runs_pass(&r, &c, &guard);
}

#[test]
fn runs_that_are_not_forced_switching_runs_are_refused() {
    let r = run(whole_space());
    let lps = [0, 1].map(|l| Loop::reach_avoid(&r.hy, l, &r.designs[l], &r.task));
    let lcs = lps.each_ref().map(|lp| LoopConstants::new(lp).unwrap());
    let edge = r.hy.edges()[0].clone();
    let mut internal = edge.clone();
    internal.kind = EdgeKind::Internal;
    let mut backwards = edge.clone();
    (backwards.from, backwards.to) = (1, 0);
    let mut shifted = r.noms[1].clone();
    shifted.x[0][2] += 1e-3;
    let make = |e0: Option<&Edge>,
                e1: Option<&Edge>,
                n1: &Nominal|
     -> Result<ForcedCertificate, ForcedError> {
        certify_forced(&[
            ForcedSegment {
                lp: lps[0],
                lc: &lcs[0],
                nominal: &r.noms[0],
                switch: e0,
                invariant: None,
            },
            ForcedSegment {
                lp: lps[1],
                lc: &lcs[1],
                nominal: n1,
                switch: e1,
                invariant: None,
            },
        ])
    };
    assert!(make(Some(&edge), None, &r.noms[1]).is_ok());
    assert!(matches!(
        make(Some(&internal), None, &r.noms[1]),
        Err(ForcedError::NotForced { segment: 0 })
    ));
    assert!(matches!(
        make(Some(&backwards), None, &r.noms[1]),
        Err(ForcedError::Locations { segment: 0, .. })
    ));
    assert!(matches!(
        make(None, None, &r.noms[1]),
        Err(ForcedError::MissingSwitch { segment: 0 })
    ));
    assert!(matches!(
        make(Some(&edge), Some(&edge), &r.noms[1]),
        Err(ForcedError::SwitchAfterLast { segment: 1 })
    ));
    let e = make(Some(&edge), None, &shifted).unwrap_err();
    assert!(
        matches!(
            e,
            ForcedError::Discontinuous {
                segment: 1,
                prev: 0,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        e.to_string().contains("not continuous across the switch"),
        "{e}"
    );
    assert!(matches!(certify_forced(&[]), Err(ForcedError::Empty)));
}

/// A location's invariant is kept like Unsafe: with the first location's invariant 0.02 beyond the
/// largest x1 its nominal reaches, the Unsafe part at the samples is that margin in the first metric.
#[test]
fn a_location_invariant_is_kept_like_unsafe() {
    let r = run(whole_space());
    let top = r.noms[0]
        .x
        .iter()
        .map(|x| x[0])
        .fold(f64::NEG_INFINITY, f64::max);
    let inv = Polytope {
        a: vec![vec![1.0, 0.0, 0.0]],
        b: vec![top + 0.02],
    };
    let lps = [0, 1].map(|l| Loop::reach_avoid(&r.hy, l, &r.designs[l], &r.task));
    let lcs = lps.each_ref().map(|lp| LoopConstants::new(lp).unwrap());
    let segs = |invariant| {
        [
            ForcedSegment {
                lp: lps[0],
                lc: &lcs[0],
                nominal: &r.noms[0],
                switch: Some(&r.hy.edges()[0]),
                invariant,
            },
            ForcedSegment {
                lp: lps[1],
                lc: &lcs[1],
                nominal: &r.noms[1],
                switch: None,
                invariant: None,
            },
        ]
    };
    let free = certify_forced(&segs(None)).unwrap();
    let kept = certify_forced(&segs(Some(&inv))).unwrap();
    let Pinv = host_compiler::linalg::sym_fn(r.designs[0].P.as_ref(), |l| 1.0 / l).unwrap();
    let margin = 0.02 / Pinv[(0, 0)].sqrt();
    let got = kept.segments[0].delta_unsafe;
    assert!((got - margin).abs() <= 1e-9 * margin, "{got} vs {margin}");
    assert!(free.segments[0].delta_unsafe > margin);
    assert!(kept.segments[0].delta <= free.segments[0].delta);
    assert!(kept.is_certified());
}

/// Def 4.18 on the forced cart (`examples/hybrid-forced-cart-mtl.toml`): the planned run from Init's
/// centre is certified for the formula with a radius below ρ(0) and below the formula's bound; the same
/// segments under a speed limit the nominal breaks (forward settles at 2..4 m/s, the limit is 1 m/s)
/// certify nothing, and neither does a formula about a set the run never visits.
#[test]
fn forced_run_certified_for_a_formula_and_refused_when_the_nominal_breaks_it() {
    use host_compiler::synth::hybrid::{forced, HybridTask};
    let path = format!(
        "{}/../examples/hybrid-forced-cart-mtl.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let src = std::fs::read_to_string(&path).unwrap();
    let task =
        |src: &str| HybridTask::new(host_compiler::spec::parse(src, "cart-mtl").unwrap()).unwrap();
    let good = task(&src);
    let run = forced::plan_forced(&good, &[0.0, 0.0]).expect("the centre's run is certified");
    assert_eq!(run.locations.len(), 2);
    let (l0, l1) = (run.locations[0], run.locations[1]);
    let edges = vec![good
        .plant
        .edges()
        .iter()
        .position(|e| e.from == l0 && e.to == l1)
        .expect("a forced edge forward → backward")];
    let again = forced::certify_run(&good, &run.locations, &edges, &run.nominals).unwrap();
    assert!(again.is_certified());
    assert_eq!(again.delta_stored, run.certificate.delta_stored);
    for src in [
        src.replace("(x2 <= 3.5)", "(x2 <= 1.0)"),
        src.replace("(x2 <= 3.5)", "F[0,8] (x1 <= -5)"),
    ] {
        let bad = task(&src);
        let c = forced::certify_run(&bad, &run.locations, &edges, &run.nominals).unwrap();
        assert!(!c.is_certified(), "{src}");
        assert_eq!(c.delta_stored, 0.0);
    }
}

/// A run planned from a seed that is not an f32 point starts at its f32 rounding, where the image stores
/// the ball's centre, so the bytes re-prove exactly the tables that were certified.
#[test]
fn a_run_planned_from_an_f64_seed_starts_where_the_image_stores_it_and_re_proves() {
    use host_compiler::synth::hybrid::{forced, image, HybridTask};
    use host_compiler::verify::hybrid::recheck;
    let path = format!(
        "{}/../examples/hybrid-forced-cart.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let task = HybridTask::new(host_compiler::spec::load(&path).unwrap()).unwrap();
    let seed = [0.1 + 1e-9 * std::f64::consts::PI, -0.05 + 3e-10];
    assert!(seed.iter().any(|&v| v as f32 as f64 != v));
    let run = forced::plan_forced(&task, &seed).expect("a run from near the centre");
    let start = &run.nominals[0].x[0];
    for (s, v) in start.iter().zip(&seed) {
        assert_eq!(*s, *v as f32 as f64, "the run starts at {start:?}");
    }
    let bytes = image(&task, std::slice::from_ref(&run)).unwrap();
    let rc = recheck(&task.plant, &task.property, None, task.steps, &bytes).unwrap();
    assert!(rc.iter().all(|r| r.ok), "{rc:?}");
}
