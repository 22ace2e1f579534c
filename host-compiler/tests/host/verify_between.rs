//! The verifier's check between samples skips a period only where it provably passes
//! (`verify::between_clear`): the sets' sure radii (`Region::sure_radius`) are sound for every point they
//! vouch for, the plant's excursion bound (`Plant::excursion`) holds every state it visits, and a run's
//! outcome is the same, field for field, whether the periods are skipped or visited.
#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::emit::{ImageBuilder, Terminal, TrajectoryEntry};
use host_compiler::geometry::{
    Ball, Complement, Ellipsoid, InOutput, Intersection, Polytope, Region, Union,
};
use host_compiler::model::{ContinuousPlant, DiscretePlant, LinearAffine, Location, Plant};
use host_compiler::property::{InputBound, ReachAvoid};
use host_compiler::spec::InitBox;
use host_compiler::verify::{run, Judge};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::image::decode;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Sets of every kind with a closed-form sure radius, in ℝ³.
fn sets() -> Vec<(&'static str, Box<dyn Region>)> {
    let ball = || {
        Ball::new(
            vec![0.5, -0.2, 0.1],
            vec![2.0, 0.3, 0.0, 0.3, 1.0, 0.1, 0.0, 0.1, 0.5],
            0.8,
        )
    };
    let poly = || {
        Polytope::new(
            3,
            vec![
                1.0, 0.0, 0.0, -1.0, 0.5, 0.0, 0.0, -2.0, 1.0, 0.0, 0.0, -1.0,
            ],
            vec![1.0, 0.7, 1.2, 0.9],
        )
    };
    let disc = || {
        // A disc in (x1, x3) through an output map: an infinite cylinder along x2.
        InOutput::new(
            vec![1.0, 0.0, 0.0, 0.0, 0.2, 1.0],
            2,
            Box::new(Ellipsoid::new(vec![-0.4, 0.3], vec![4.0, 0.5, 0.5, 1.0]).unwrap()),
        )
    };
    vec![
        ("ball", Box::new(ball().unwrap())),
        ("polytope", Box::new(poly().unwrap())),
        ("output disc", Box::new(disc().unwrap())),
        (
            "union",
            Box::new(
                Union::new(vec![Box::new(ball().unwrap()), Box::new(disc().unwrap())]).unwrap(),
            ),
        ),
        (
            "intersection",
            Box::new(
                Intersection::new(vec![Box::new(poly().unwrap()), Box::new(ball().unwrap())])
                    .unwrap(),
            ),
        ),
        (
            "complement",
            Box::new(Complement::new(Box::new(poly().unwrap())).unwrap()),
        ),
    ]
}

#[test]
fn every_point_within_a_sure_radius_is_on_the_side_it_names() {
    let mut rng = ChaCha8Rng::seed_from_u64(46);
    for (name, set) in sets() {
        let (mut inside, mut outside) = (0, 0);
        for _ in 0..4000 {
            let x: Vec<f64> = (0..3).map(|_| rng.random_range(-2.5..2.5)).collect();
            let Some((side, r)) = set.sure_radius(&x) else {
                panic!("{name}: no sure radius at {x:?}");
            };
            assert_eq!(side, set.contains(&x), "{name} at {x:?}");
            assert!(r >= 0.0, "{name}: radius {r} at {x:?}");
            if r == 0.0 {
                continue;
            }
            if side {
                inside += 1;
            } else {
                outside += 1;
            }
            // Points up to the radius (on its sphere, just inside, and scattered within).
            for k in 0..12 {
                let w: Vec<f64> = (0..3).map(|_| rng.random_range(-1.0..1.0)).collect();
                let wn = w.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
                let t = if k < 6 {
                    0.999_999
                } else {
                    rng.random_range(0.0..1.0)
                };
                let y: Vec<f64> = x.iter().zip(&w).map(|(a, b)| a + t * r * b / wn).collect();
                assert_eq!(set.contains(&y), side, "{name}: {y:?} within {r} of {x:?}");
            }
        }
        // Both sides were vouched for somewhere, so the check above is not empty.
        assert!(
            inside > 50 && outside > 50,
            "{name}: {inside} inside, {outside} outside"
        );
    }
}

#[test]
fn a_sure_radius_is_close_to_the_distance_where_it_is_exact() {
    // A Euclidean ball of radius 1 about the origin: the sure radius is the distance to the sphere.
    let b = Ball::new(vec![0.0, 0.0], vec![1.0, 0.0, 0.0, 1.0], 1.0).unwrap();
    let (side, r) = b.sure_radius(&[2.0, 0.0]).unwrap();
    assert!(!side && (r - 1.0).abs() < 1e-8, "{r}");
    let (side, r) = b.sure_radius(&[0.25, 0.0]).unwrap();
    assert!(side && (r - 0.75).abs() < 1e-8, "{r}");
    // A point of the wrong length or not finite: no answer.
    assert!(b.sure_radius(&[0.0]).is_none());
    assert!(b.sure_radius(&[f64::NAN, 0.0]).is_none());
}

/// A damped double integrator sampled coarsely (h = 0.1), so that a run moves far within a period.
fn plant() -> LinearAffine {
    let A = Mat::from_fn(2, 2, |i, j| [[0.0, 1.0], [0.0, -0.5]][i][j]);
    let B = Mat::from_fn(2, 1, |i, _| [0.0, 1.0][i]);
    LinearAffine::sampled(ContinuousPlant::new(A, B, vec![0.0, 0.0]).unwrap(), 0.1).unwrap()
}

#[test]
fn the_excursion_bound_holds_every_state_visited_between_samples() {
    let p = plant();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let x: Vec<f64> = (0..2).map(|_| rng.random_range(-5.0..5.0)).collect();
        let u = [rng.random_range(-3.0..3.0)];
        let e = p
            .excursion(0, &x, &u)
            .expect("a continuous linear plant has one");
        let mut far = 0.0f64;
        p.between_samples(0, &x, &u, &mut |xs| {
            let d = xs
                .iter()
                .zip(&x)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt();
            far = far.max(d);
        });
        assert!(far <= e, "moved {far} > bound {e} from {x:?}");
        worst = worst.max(far / e);
    }
    // The bound is of the right size (γ(h)‖f‖ against the sub-sampled flow within the period).
    assert!(worst > 0.5, "{worst}");
    let discrete = LinearAffine::discrete(
        DiscretePlant::new(Mat::identity(1, 1), Mat::identity(1, 1), vec![0.0], 0.1).unwrap(),
    );
    assert!(discrete.excursion(0, &[0.0], &[0.0]).is_none());
}

/// [`plant`] with its periods counted, and with or without its excursion bound.
#[derive(Debug)]
struct Counted {
    inner: LinearAffine,
    bound: bool,
    visits: AtomicUsize,
}

impl Plant for Counted {
    fn n(&self) -> usize {
        self.inner.n()
    }
    fn m(&self) -> usize {
        self.inner.m()
    }
    fn period(&self) -> f64 {
        Plant::period(&self.inner)
    }
    fn error_dynamics(&self, loc: Location) -> &DiscretePlant {
        self.inner.error_dynamics(loc)
    }
    fn continuous(&self, loc: Location) -> Option<&ContinuousPlant> {
        self.inner.continuous(loc)
    }
    fn step(&self, loc: Location, x: &[f64], u: &[f64]) -> Vec<f64> {
        self.inner.step(loc, x, u)
    }
    fn between_samples(&self, loc: Location, x: &[f64], u: &[f64], visit: &mut dyn FnMut(&[f64])) {
        self.visits.fetch_add(1, Ordering::Relaxed);
        self.inner.between_samples(loc, x, u, visit)
    }
    fn excursion(&self, loc: Location, x: &[f64], u: &[f64]) -> Option<f64> {
        self.bound
            .then(|| self.inner.excursion(loc, x, u))
            .flatten()
    }
}

#[test]
fn skipping_the_periods_that_provably_pass_changes_no_outcome() {
    // u = −4x₁ − 0.5x₂ + 8 from every start, an underdamped loop about x₁ = 2: runs sweep right at
    // x₂ ≈ 2–4 through a small Unsafe disc (which some cross only between samples, h = 0.1), overshoot
    // into Goal (a band of x₁) and swing back out of it.
    let mut b = ImageBuilder::new(2, 1, 0.1);
    b.add_location(vec![-4.0, -0.5], vec![1.0, 0.0, 0.0, 1.0]);
    b.add_trajectory(TrajectoryEntry {
        x0: vec![0.0, 0.0],
        delta: 50.0,
        v: vec![8.0; 40],
        location: vec![0; 40],
    });
    b.terminal = Terminal::HoldLast;
    let bytes = b.to_bytes().expect("valid image");
    let img = decode(&bytes).expect("decodes");
    let property = ReachAvoid {
        goal: Box::new(
            InOutput::new(
                vec![1.0, 0.0],
                1,
                Box::new(Ball::new(vec![2.9], vec![1.0], 0.25).unwrap()),
            )
            .unwrap(),
        ),
        unsafe_set: Some(Box::new(
            Ball::new(vec![1.0, 2.9], vec![1.0, 0.0, 0.0, 1.0], 0.15).unwrap(),
        )),
        input: InputBound::Box {
            lo: vec![-20.0],
            hi: vec![20.0],
        },
        horizon: 4.0,
    };
    let init = InitBox {
        lo: vec![-0.5, -0.5],
        hi: vec![0.5, 0.5],
    };
    let counted = |bound| Counted {
        inner: plant(),
        bound,
        visits: AtomicUsize::new(0),
    };
    let (skipping, visiting) = (counted(true), counted(false));
    let judge = |p: &Counted| {
        let j = Judge {
            plant: p,
            property: &property,
            steps: 40,
            init: &init,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        (0..400)
            .map(|i| {
                let x0 = [rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5)];
                run(&j, &img, &x0, i % 2 == 0)
            })
            .collect::<Vec<_>>()
    };
    let (a, b) = (judge(&skipping), judge(&visiting));
    assert_eq!(a, b);
    // Not vacuous: runs entered Unsafe, reached Goal and left it, and periods were both skipped and
    // visited.
    let entered = a.iter().filter(|o| o.entered_unsafe).count();
    let left = a.iter().filter(|o| o.left_goal).count();
    let reached = a.iter().filter(|o| o.goal_step.is_some()).count();
    assert!(entered > 0 && entered < 400, "{entered} entered Unsafe");
    assert!(
        reached > 0 && left > 0,
        "{reached} reached Goal, {left} left it"
    );
    let (vs, vv) = (
        skipping.visits.load(Ordering::Relaxed),
        visiting.visits.load(Ordering::Relaxed),
    );
    assert!(
        vs > 0 && vs * 10 < vv * 9,
        "{vs} periods visited with the bound, {vv} without"
    );
}
