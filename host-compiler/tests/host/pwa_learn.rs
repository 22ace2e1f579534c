//! PWA feedback learned from the double-integrator cover (Ch. 6): every data point fitted within ε_fit by
//! its partition's law, every emitted ball's law verified against (6.6)/(6.7) and the one-step inclusion
//! (6.5), the image decodes, and closed-loop Monte Carlo through the shared-types evaluator from the balls
//! at κ = 0 stays in the envelope until Goal and meets the spec.

#![allow(non_snake_case)]

use host_compiler::linalg::{mat_vec, sym_eigenvalues};
use host_compiler::pwa::{check_point, learn_pwa, PwaController, PwaSettings, StoredLaw};
use host_compiler::synth::{synthesize, SynthOptions, Synthesis};
use host_compiler::task::Task;
use host_compiler::verify::Judge;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::eval::Controller;
use std::sync::OnceLock;

struct Fixture {
    task: Task,
    syn: Synthesis,
    pwa: PwaController,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let mut problem = host_compiler::spec::load(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/double-integrator.toml"
        ))
        .unwrap();
        // The cover of the reach-avoid task itself, without a terminal law (whose handover region would
        // be the cover's Goal): its PWA tree, cut by laws, fits the image's capacities, which the tests
        // of the two tree cuts below need.
        problem.synthesis.terminal = host_compiler::spec::TerminalChoice::Hold;
        let opts = SynthOptions {
            verify_interior: 200,
            verify_per_ball: 4,
            progress: false,
            ..SynthOptions::default()
        };
        let task = Task::new(problem).unwrap();
        let syn = synthesize(&task, &opts).unwrap();
        let pwa = learn_pwa(&task, &syn, &PwaSettings::default()).unwrap();
        eprintln!(
            "pwa: {} data points from {} trajectories, eps_fit = {:.3e}, {:?}, learn {:.2}s, partition {:.2}s, image {} bytes",
            pwa.ctx.points.len(),
            syn.trajectories.len(),
            pwa.ctx.eps_fit,
            pwa.stats,
            pwa.learn_seconds,
            pwa.partition_seconds,
            pwa.image.len()
        );
        Fixture { task, syn, pwa }
    })
}

#[test]
fn every_data_point_is_fitted_by_its_law_within_the_bound() {
    let f = fixture();
    let pwa = &f.pwa;
    assert!(pwa.ctx.eps_fit > 0.0);
    assert!(
        pwa.laws.len() < pwa.ctx.points.len(),
        "no compression at all"
    );
    for (k, p) in pwa.ctx.points.iter().enumerate() {
        let j = pwa.assignment[k];
        assert!(j < pwa.laws.len());
        assert!(pwa.laws[j].members.contains(&k));
        // u = (K + θ_j) x + θ0_j against K x + ṽ, with the stored (f32) law.
        let law = &pwa.laws[j].stored;
        let u = law.input(&p.x);
        let kx = mat_vec(f.syn.K.as_ref(), &p.x);
        for c in 0..pwa.ctx.m {
            let err = (u[c] - (kx[c] + p.v[c])).abs();
            assert!(
                err <= pwa.ctx.eps_fit,
                "point {k} comp {c}: {err:e} > {:e}",
                pwa.ctx.eps_fit
            );
        }
    }
}

#[test]
fn every_emitted_ball_satisfies_6_6_and_6_7() {
    let f = fixture();
    let pwa = &f.pwa;
    let ctx = &pwa.ctx;
    for ball in &pwa.builder.balls {
        let k = ctx
            .points
            .iter()
            .position(|p| p.x == ball.centre)
            .expect("ball centre is a data point");
        let law = &pwa.builder.laws[ball.partition];
        // Rebuild the stored law from the image's gain and offset (f32), independently of the learner.
        let gain = faer::Mat::from_fn(ctx.m, ctx.n, |i, j| law.gain[i * ctx.n + j] as f32 as f64);
        let At = &ctx.A + &ctx.B * &gain;
        // (6.6): the block matrix [Q, ÃQ; (ÃQ)ᵀ, Q] is positive definite, Q = P⁻¹ the LMI variable of
        // (3.67) (the text's "P" in (3.65)–(3.67) and (6.6) is the inverse of the CAF metric).
        let n = ctx.n;
        let Q = ctx.roots.inv.clone();
        let AQ = &At * &Q;
        let big = faer::Mat::from_fn(2 * n, 2 * n, |i, j| match (i < n, j < n) {
            (true, true) => Q[(i, j)],
            (true, false) => AQ[(i, j - n)],
            (false, true) => AQ[(j, i - n)],
            (false, false) => Q[(i - n, j - n)],
        });
        let ev = sym_eigenvalues(big.as_ref()).unwrap();
        assert!(
            ev[0] > 0.0,
            "(6.6) fails for ball at {:?}: {ev:?}",
            ball.centre
        );
        // (6.7) and the one-step inclusion (6.5), with the check the learner uses.
        let theta = faer::Mat::from_fn(ctx.m, ctx.n, |i, j| gain[(i, j)] - ctx.K[(i, j)]);
        let stored = StoredLaw::new(ctx, &theta, &law.offset);
        let c = check_point(ctx, &stored, k);
        assert!(c.ok, "ball {k} law {}: {c:?}", ball.partition);
        assert!(c.r_crit < ctx.points[k].rho);
        // The stored threshold is fl32(ρ̂·ρ̂) of the point's certified radius ρ̂.
        let rho = ctx.points[k].rho as f32;
        assert_eq!(ball.threshold, (rho * rho) as f64);
    }
    // A leaf may list balls of several laws; the evaluator must apply the law of the ball it finds the
    // state in, and the image must route every ball centre to a ball that holds it.
    let img = shared_types::image::decode(&pwa.image).expect("PWA image decodes");
    for (b, ball) in pwa.builder.balls.iter().enumerate() {
        let x: Vec<f32> = ball.centre.iter().map(|&v| v as f32).collect();
        match img.locate(&x) {
            Some(shared_types::pwa::Region::Inside {
                partition,
                ball: hit,
                ..
            }) => assert_eq!(
                partition as usize, pwa.builder.balls[hit as usize].partition,
                "ball {b}: the evaluator applied another law than the ball's own"
            ),
            other => panic!("ball {b}: its centre is not located in a certified ball: {other:?}"),
        }
    }
}

#[test]
fn the_image_decodes() {
    let f = fixture();
    let img = shared_types::image::decode(&f.pwa.image).expect("PWA image decodes");
    assert_eq!(img.n(), 2);
    assert_eq!(img.m(), 1);
    assert!(f.pwa.stats.depth <= shared_types::capacity::MAX_TREE_DEPTH);
}

#[test]
fn closed_loop_from_initial_balls_stays_in_envelope_and_meets_the_spec() {
    let f = fixture();
    closed_loop(&f.pwa, &f.task);
}

/// A much tighter fitting tolerance (r_crit ≤ 2% of the radius) forces several partitions; the same
/// guarantees must hold.
#[test]
fn tight_tolerance_gives_several_partitions_and_the_same_guarantees() {
    let f = fixture();
    let pwa = learn_pwa(
        &f.task,
        &f.syn,
        &PwaSettings::builder().rcrit_fraction(0.02).build().unwrap(),
    )
    .unwrap();
    eprintln!(
        "tight: eps_fit = {:.3e}, {:?}, learn {:.2}s, partition {:.2}s",
        pwa.ctx.eps_fit, pwa.stats, pwa.learn_seconds, pwa.partition_seconds
    );
    assert!(pwa.laws.len() > 1, "{:?}", pwa.stats);
    for (k, p) in pwa.ctx.points.iter().enumerate() {
        let c = check_point(&pwa.ctx, &pwa.laws[pwa.assignment[k]].stored, k);
        assert!(c.ok && c.fit_err <= pwa.ctx.eps_fit, "{k}: {c:?} {p:?}");
    }
    shared_types::image::decode(&pwa.image).unwrap();
    closed_loop(&pwa, &f.task);
}

fn closed_loop(pwa: &PwaController, task: &Task) {
    let img = shared_types::image::decode(&pwa.image).unwrap();
    let goal = &task.property.goal;
    let unsafe_set = &task.property.unsafe_set;
    let input = &task.property.input;
    let model = task.plant.error_dynamics(0);
    let steps = task.steps;
    let ctx = &pwa.ctx;
    let starts: Vec<usize> = (0..ctx.points.len())
        .filter(|&k| ctx.points[k].kappa == 0)
        .collect();
    assert!(!starts.is_empty());
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let runs = 500;
    let mut failures = vec![];
    let mut rejected_start = 0;
    for r in 0..runs {
        let p = &ctx.points[starts[r % starts.len()]];
        // Uniform in the ψ-ball of radius ρ: x = x̃ + P^{-1/2} z, ‖z‖ ≤ ρ.
        let z: Vec<f64> = (0..ctx.n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let nz = z.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
        let rad = p.rho * (1.0 - 1e-6) * rng.random::<f64>().powf(1.0 / ctx.n as f64);
        let zz: Vec<f64> = z.iter().map(|v| v / nz * rad).collect();
        let e = mat_vec(ctx.roots.inv_sqrt.as_ref(), &zz);
        let mut x: Vec<f64> = p.x.iter().zip(&e).map(|(a, b)| a + b).collect();
        let mut ctl = Controller::new(img);
        let mut outcome = Err("goal not reached within T".to_string());
        for k in 0..=steps {
            if unsafe_set.as_ref().is_some_and(|u| u.contains(&x)) {
                outcome = Err(format!("unsafe at step {k}"));
                break;
            }
            if goal.contains(&x) {
                outcome = Ok(());
                break;
            }
            if k == steps {
                break;
            }
            let xf: Vec<f32> = x.iter().map(|&v| v as f32).collect();
            let u: Vec<f64> = match ctl.step(&xf) {
                Ok(u) => u.as_slice().iter().map(|&v| v as f64).collect(),
                Err(s) => {
                    if k == 0 {
                        rejected_start += 1;
                    }
                    outcome = Err(format!("evaluator {s:?} at step {k}, x = {x:?}"));
                    break;
                }
            };
            if let host_compiler::property::InputBound::Box { lo, hi } = input {
                if u.iter()
                    .zip(lo.iter().zip(hi))
                    .any(|(u, (l, h))| u < l || u > h)
                {
                    outcome = Err(format!("input {u:?} outside the box at step {k}"));
                    break;
                }
            }
            let ax = mat_vec(model.A.as_ref(), &x);
            let bu = mat_vec(model.B.as_ref(), &u);
            x = (0..ctx.n).map(|i| ax[i] + bu[i] + model.g[i]).collect();
        }
        if let Err(e) = outcome {
            failures.push((r, e));
        }
    }
    eprintln!(
        "monte carlo: {runs} runs, {} failures ({} rejected at κ = 0)",
        failures.len(),
        rejected_start
    );
    assert!(
        failures.is_empty(),
        "{:?}",
        &failures[..failures.len().min(5)]
    );
}

/// `verify::pwa` re-derives the certificate from the image bytes alone: every partition passes (6.6), (6.7),
/// the one-step inclusion, the input bound, and every ball is listed by every leaf its descent reaches; the
/// Monte Carlo from F (terminating at Goal) finds no violation.
#[test]
fn the_image_alone_rechecks_and_monte_carlo_from_f_finds_no_violation() {
    let f = fixture();
    let judge = Judge::new(&f.task);
    let img = shared_types::image::decode(&f.pwa.image).unwrap();
    let rc = host_compiler::verify::pwa::recheck(&judge, &img).unwrap();
    assert_eq!(rc.failures, 0, "{rc:?}");
    assert!(rc.containment_checks >= img.n_balls());
    assert!(rc.partitions.iter().all(|p| p.sigma > 0.0 && p.ok));
    let x0s: Vec<Vec<f64>> = f
        .syn
        .trajectories
        .iter()
        .map(|t| t.nominal.x[0].clone())
        .collect();
    let mc = host_compiler::verify::pwa::monte_carlo_pwa(&judge, &img, &x0s, 2_000, 7, 0).unwrap();
    assert_eq!(mc.runs, 2_000);
    assert!(mc.init_runs >= 1_000);
    assert_eq!(mc.violations, 0, "{:?}", mc.first_violations);
    assert!(mc.max_steps_to_goal <= f.task.steps);
    // Goal within T, proved from the bytes; no sampled run takes longer than the proved bound.
    let bound = rc
        .liveness
        .max_steps_to_goal
        .unwrap_or_else(|| panic!("{:?}", rc.liveness.failure));
    assert!(bound <= f.task.steps, "{:?}", rc.liveness);
    assert!(
        mc.max_steps_to_goal <= bound,
        "{} > {bound}",
        mc.max_steps_to_goal
    );
}

/// Goal within T depends on the order in which leaves list their balls (pwa module doc, "Reaching Goal
/// within T"): with every leaf's list reversed (largest time-to-go first) the invariance checks all still
/// pass, but the recheck finds no time-to-go ranking within the horizon.
#[test]
fn the_recheck_finds_leaf_orders_that_lose_goal_within_t() {
    let f = fixture();
    let judge = Judge::new(&f.task);
    let mut b = f.pwa.builder.clone();
    let mut reversed = 0;
    for leaf in &mut b.leaves {
        if leaf.balls.len() >= 2 {
            leaf.balls.reverse();
            reversed += 1;
        }
    }
    assert!(reversed >= 1);
    let bytes = b.to_bytes().unwrap();
    let img = shared_types::image::decode(&bytes).unwrap();
    let rc = host_compiler::verify::pwa::recheck(&judge, &img).unwrap();
    assert!(rc.partitions.iter().all(|p| p.ok), "{:?}", rc.partitions);
    assert_eq!(rc.containment_failures, 0);
    assert!(
        rc.liveness.failure.is_some() && rc.failures == 1,
        "{:?}",
        rc.liveness
    );
}

/// Regression for the recheck's power: a law whose gain no longer contracts ((6.6) fails) and a ball
/// removed from a leaf (containment across a boundary fails) are both found in the image bytes.
#[test]
fn the_recheck_finds_a_broken_law_and_a_missing_ball() {
    let f = fixture();
    let judge = Judge::new(&f.task);
    let mut b = f.pwa.builder.clone();
    for g in &mut b.laws[0].gain {
        *g = -*g; // positive feedback
    }
    let bytes = b.to_bytes().unwrap();
    let img = shared_types::image::decode(&bytes).unwrap();
    let rc = host_compiler::verify::pwa::recheck(&judge, &img).unwrap();
    assert!(
        rc.partitions[0].sigma < 0.0 && !rc.partitions[0].ok,
        "{:?}",
        rc.partitions[0]
    );

    let mut b = f.pwa.builder.clone();
    let l = (0..b.leaves.len())
        .find(|&l| b.leaves[l].balls.len() >= 2)
        .expect("a leaf with two balls");
    b.leaves[l].balls.pop();
    let bytes = b.to_bytes().unwrap();
    let img = shared_types::image::decode(&bytes).unwrap();
    let rc = host_compiler::verify::pwa::recheck(&judge, &img).unwrap();
    assert!(rc.containment_failures >= 1, "{rc:?}");
}

/// Regression: a leaf may list balls of several laws and the evaluator applies the law of the ball that
/// holds the state, but the re-check used to pair every listed ball with the leaf's law. A ball whose own
/// law is wrong went unchecked (and a correct ball failed against a law it never runs).
#[test]
fn the_recheck_judges_each_ball_with_its_own_law_in_mixed_leaves() {
    let f = fixture();
    let judge = Judge::new(&f.task);
    let mut b = f.pwa.builder.clone();
    let ball = b
        .leaves
        .iter()
        .flat_map(|leaf| leaf.balls.iter().map(move |&i| (leaf.partition, i)))
        .find(|&(p, i)| b.balls[i].partition != p)
        .map(|(_, i)| i)
        .expect("the fixture has a mixed leaf");
    // A stable law (same gain) whose offset pushes the ball's image far off: wrong for this ball only.
    let mut law = b.laws[b.balls[ball].partition].clone();
    for o in &mut law.offset {
        *o += 0.5;
    }
    b.laws.push(law);
    let q = b.laws.len() - 1;
    b.balls[ball].partition = q;
    let bytes = b.to_bytes().unwrap();
    let img = shared_types::image::decode(&bytes).unwrap();
    let rc = host_compiler::verify::pwa::recheck(&judge, &img).unwrap();
    assert!(rc.partitions[q].sigma > 0.0, "{:?}", rc.partitions[q]);
    assert!(
        !rc.partitions[q].ok && rc.failures >= 1,
        "the ball's own law must be checked: {:?}",
        rc.partitions[q]
    );
}

#[test]
fn every_leaf_lists_its_balls_by_increasing_time_to_go() {
    // The liveness argument (pwa module doc, "Reaching Goal within T"): the first listed ball containing a
    // state has the smallest time-to-go among the listed balls that contain it.
    let f = fixture();
    let image = shared_types::image::decode(&f.pwa.image).unwrap();
    let n = image.n();
    let to_go = |b: usize| -> usize {
        let c: Vec<f32> = (0..n).map(|i| image.ball_centre(b, i)).collect();
        let hits: Vec<usize> = f
            .pwa
            .ctx
            .points
            .iter()
            .filter(|p| p.x.iter().zip(&c).all(|(a, b)| *a as f32 == *b))
            .map(|p| p.to_go)
            .collect();
        assert!(!hits.is_empty(), "ball {b} is no data point's ball");
        // Coinciding centres (two trajectories through one point) take the smallest time-to-go.
        hits.into_iter().min().unwrap()
    };
    let mut ordered = 0;
    for l in 0..image.n_leaves() {
        let len = image.leaf_refs(l).1;
        let taus: Vec<usize> = (0..len)
            .map(|k| to_go(image.leaf_ball(l, k).unwrap()))
            .collect();
        assert!(
            taus.windows(2).all(|w| w[0] <= w[1]),
            "leaf {l}: time-to-go {taus:?}"
        );
        ordered += (len > 1) as usize;
    }
    assert!(
        ordered > 0,
        "no leaf with two balls: the check checked nothing"
    );
}

/// The tree cut on the data alone (`TreeSplit::Balanced`, what `Auto` falls back to when the cut by laws
/// outgrows a capacity) routes the same laws over the same balls: its image rechecks from the bytes, runs
/// without violation from F, and accepts exactly the states of Init the tree cut by laws accepts (both list
/// every ball meeting a leaf's cell, so each accepts the union of the balls).
#[test]
fn a_tree_cut_on_the_data_alone_rechecks_and_accepts_what_the_tree_cut_by_laws_accepts() {
    use host_compiler::pwa::{build_pwa, TreeSplit};
    let f = fixture();
    assert_eq!(f.pwa.stats.split, TreeSplit::Laws);
    let mut ctx = f.pwa.ctx.clone();
    ctx.settings = ctx
        .settings
        .clone()
        .to_builder()
        .split(TreeSplit::Balanced)
        .build()
        .unwrap();
    let balanced = build_pwa(
        &f.task,
        ctx,
        f.pwa.laws.clone(),
        f.pwa.assignment.clone(),
        0.0,
    )
    .unwrap();
    assert_eq!(balanced.stats.split, TreeSplit::Balanced);
    assert_eq!(balanced.stats.partitions, f.pwa.stats.partitions);
    assert!(balanced.stats.max_leaf_balls <= shared_types::capacity::MAX_LEAF_BALLS);
    let judge = Judge::new(&f.task);
    let img = shared_types::image::decode(&balanced.image).unwrap();
    let rc = host_compiler::verify::pwa::recheck(&judge, &img).unwrap();
    assert_eq!(rc.failures, 0, "{rc:?}");
    let x0s = f.syn.init_centres();
    let mc = host_compiler::verify::pwa::monte_carlo_pwa(&judge, &img, &x0s, 2_000, 7, 0).unwrap();
    assert_eq!(
        (mc.runs, mc.violations),
        (2_000, 0),
        "{:?}",
        mc.first_violations
    );
    let laws_img = shared_types::image::decode(&f.pwa.image).unwrap();
    let by_laws = host_compiler::pwa::coverage(&laws_img, &f.task.problem);
    let by_data = host_compiler::pwa::coverage(&img, &f.task.problem);
    assert!(by_data.covered > 0);
    assert_eq!(by_data, by_laws);
}
