//! Ch. 5's optimisers on the planar vehicle (Example 4.8, examples/planar-vehicle.toml).
//!
//! * Potential descent (§5.2): from the infeasible constant seed v ≡ (1, −1) at five points of Init, the
//!   cost evaluations and wall time to zero cost at δ_d = 0.04 with `argmin`'s L-BFGS against Algorithm 3
//!   (baseline, measured in the same run). Ratio = Algorithm 3 / L-BFGS (> 1: L-BFGS faster).
//! * Time-optimal bisection (§5.2.3, Example 5.2): from a seed that keeps δ = 0.05 over the whole 5 s,
//!   the shortest terminal step at the kept δ. Row value = T after, baseline = T before, ratio =
//!   before/after; the δ kept is its own row.
//! * Direct δ maximisation (§5.3): the proximal bundle method from seeds that just keep δ = 0.02; median δ
//!   after, baseline the seeds' δ, ratio = gain (also the row `optimizer_gain_from_poor_seeds_median`).
//!
//! Everything is seeded and deterministic; only wall times vary. Runtime about half a minute.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::certify::LoopConstants;
use host_compiler::certify::OwnedLoop;
use host_compiler::optimize::potential::{descend, time_optimal, DescentMethod, PotentialSettings};
use host_compiler::optimize::{maximize_delta, BundleSettings};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

const STARTS: [[f64; 4]; 5] = [
    [0.0, 0.0, 0.0, 1.0],
    [-0.2, -0.2, 0.0, 1.0],
    [0.2, -0.2, 0.0, 1.0],
    [-0.2, 0.2, 0.0, 1.0],
    [0.2, 0.2, 0.0, 1.0],
];

fn descent_rows(ol: &OwnedLoop, lc: &LoopConstants, rows: &mut Vec<Row>) {
    let lp = ol.lp();
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let s = PotentialSettings::builder().delta(0.04).build().unwrap();
    let per = |method: DescentMethod| -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (mut ev, mut it, mut secs) = (vec![], vec![], vec![]);
        for x0 in &STARTS.map(|x| x.map(|a| a as f32 as f64)) {
            // Best of two timings (the results are identical).
            let a = descend(&lp, lc, x0, &v, &s, method).expect("valid input");
            let b = descend(&lp, lc, x0, &v, &s, method).expect("valid input");
            assert!(a.reached, "{method:?} from {x0:?}: cost {:.3e}", a.cost);
            println!(
                "descent {method:?} from {x0:?}: zero cost in {} iterations, {} evaluations, {:.3} s; δ {:.5}",
                a.iterations,
                a.evaluations,
                a.seconds.min(b.seconds),
                a.certificate.delta
            );
            ev.push(a.evaluations as f64);
            it.push(a.iterations as f64);
            secs.push(a.seconds.min(b.seconds));
        }
        (ev, it, secs)
    };
    let (ev3, it3, s3) = per(DescentMethod::Algorithm3);
    let (evq, itq, sq) = per(DescentMethod::Lbfgs);
    let (ev3, it3, s3, evq, itq, sq) = (
        median(ev3),
        median(it3),
        median(s3),
        median(evq),
        median(itq),
        median(sq),
    );
    rows.push(Row::with_baseline(
        "descent_planar_lbfgs_evaluations_median",
        evq,
        "evals",
        ev3,
        ev3 / evq,
    ));
    rows.push(Row::with_baseline(
        "descent_planar_lbfgs_iterations_median",
        itq,
        "iters",
        it3,
        it3 / itq,
    ));
    rows.push(Row::with_baseline(
        "descent_planar_lbfgs_s_median",
        sq,
        "s",
        s3,
        s3 / sq,
    ));
}

fn time_optimal_rows(ol: &OwnedLoop, lc: &LoopConstants, rows: &mut Vec<Row>) {
    let lp = ol.lp();
    let x0 = [0.0, 0.0, 0.0, 1.0];
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let seed = descend(
        &lp,
        lc,
        &x0,
        &v,
        &PotentialSettings::builder().delta(0.05).build().unwrap(),
        DescentMethod::Algorithm3,
    )
    .expect("valid input");
    assert!(seed.reached);
    let kept = seed.certificate.delta;
    for (method, name, iters) in [
        (DescentMethod::Algorithm3, "time_optimal_planar_steps", 300),
        (DescentMethod::Lbfgs, "time_optimal_planar_steps_lbfgs", 300),
    ] {
        let s = PotentialSettings::builder()
            .delta(kept)
            .max_iterations(iters)
            .max_evaluations(3000)
            .build()
            .unwrap();
        let t = Instant::now();
        let to = time_optimal(&lp, lc, &x0, &seed.v, &s, method).expect("valid input");
        let secs = t.elapsed().as_secs_f64();
        let best = to.best.as_ref().expect("the seed's length is feasible");
        println!(
            "Example 5.2, {method:?}: terminal time {} → {} steps ({:.2} s → {:.2} s) at δ {kept:.5} \
             (certified {:.5}); {} probes, {secs:.1} s",
            to.steps_before,
            to.steps_after,
            to.steps_before as f64 * ol.task.plant.period(),
            to.steps_after as f64 * ol.task.plant.period(),
            best.certificate.delta,
            to.probes.len()
        );
        rows.push(Row::with_baseline(
            name,
            to.steps_after as f64,
            "steps",
            to.steps_before as f64,
            to.steps_before as f64 / to.steps_after as f64,
        ));
        if method == DescentMethod::Algorithm3 {
            rows.push(Row::new("time_optimal_planar_delta_kept", kept, "delta"));
        }
    }
}

fn bundle_rows(ol: &OwnedLoop, lc: &LoopConstants, rows: &mut Vec<Row>) {
    let lp = ol.lp();
    let v = vec![vec![1.0, -1.0]; ol.task.steps];
    let cancel = AtomicBool::new(false);
    let (mut before, mut after, mut secs) = (vec![], vec![], vec![]);
    for x0 in &STARTS.map(|x| x.map(|a| a as f32 as f64)) {
        let seed = descend(
            &lp,
            lc,
            x0,
            &v,
            &PotentialSettings::builder().delta(0.02).build().unwrap(),
            DescentMethod::Algorithm3,
        )
        .expect("valid input");
        assert!(seed.reached);
        let t = Instant::now();
        let o = maximize_delta(
            &lp,
            lc,
            x0,
            &seed.v,
            ol.task.steps,
            &BundleSettings::default(),
            &cancel,
        );
        let dt = t.elapsed().as_secs_f64();
        println!(
            "bundle from {x0:?}: δ {:.5} → {:.5} in {} iterations ({:?}), steps {} → {}, {dt:.2} s",
            seed.certificate.delta,
            o.certificate.delta,
            o.iterations,
            o.stop,
            o.steps_before,
            o.steps_after
        );
        before.push(seed.certificate.delta);
        after.push(o.certificate.delta);
        secs.push(dt);
    }
    let gains: Vec<f64> = after.iter().zip(&before).map(|(a, b)| a / b).collect();
    let gain = median(gains);
    let (b, a) = (median(before), median(after));
    rows.push(Row::with_baseline(
        "bundle_planar_delta_median",
        a,
        "delta",
        b,
        gain,
    ));
    rows.push(Row::new("bundle_planar_s_median", median(secs), "s"));
    // The same gain under the name issue #17 gives it: δ after ÷ δ before from seeds repaired to δ = 0.02.
    rows.push(Row::with_baseline(
        "optimizer_gain_from_poor_seeds_median",
        gain,
        "δ after/before (target ≥ 5)",
        b,
        gain,
    ));
}

fn main() {
    let p = host_compiler::spec::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    ))
    .expect("the shipped example parses");
    let ol = OwnedLoop::from_problem(&p).expect("the planar vehicle has a CAF");
    let lc = ol.constants().expect("the shipped gain contracts");
    let mut rows = Vec::new();
    descent_rows(&ol, &lc, &mut rows);
    time_optimal_rows(&ol, &lc, &mut rows);
    bundle_rows(&ol, &lc, &mut rows);
    write_rows("optimize_planar", &rows).expect("rows written");
}
