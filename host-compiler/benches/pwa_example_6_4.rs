//! PWA feedback for the setting of Example 6.4 (examples/planar-vehicle-pwa.toml): the number of partitions
//! the learner (§6.2) needs, against the dissertation's 110 for its data; the learning time; and the PWA
//! image size against the feedforward image of the same cover. One learning run takes seconds to minutes,
//! so it is timed directly; it is deterministic (seeded), so every figure but the times repeats exactly.
//!
//! Rows: `pwa_partitions_example_6_4` (baseline 110), `pwa_learning_s`, and `pwa_image_bytes` (baseline:
//! feedforward image bytes) when the image could be built; when it cannot (capacity), the reason is printed
//! and the row is absent, so the table shows the gap.
//!
//! The same task sampled at 0.01 s (Ch. 5's step) shows what the reference hold buys:
//! `pwa_partitions_hold20_h001` is the partition count with 20-sample blocks (`reference_hold = 20`), its
//! baseline the count without blocks, both learned in this run (greedy search only, without the thermal
//! relaxation, which would take minutes on ~2 000 points).

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::pwa::{build_pwa, learn_laws, PwaContext, PwaSettings};
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use std::time::Instant;

fn main() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle-pwa.toml"
    );
    let problem = host_compiler::spec::load(spec).expect("the shipped example parses");
    let opts = SynthOptions {
        progress: false,
        verify_interior: 1_000,
        ..SynthOptions::default()
    };
    let task = Task::new(problem.clone()).expect("the shipped example is a task");
    let s = synthesize(&task, &opts).expect("the feedforward cover is synthesized");
    let ctx = PwaContext::new(&task, &s, PwaSettings::default()).expect("PWA context");
    let points = ctx.points.len();
    let t = Instant::now();
    let (laws, assignment) = learn_laws(&ctx);
    let learn_s = t.elapsed().as_secs_f64();
    let partitions = laws.len();
    println!(
        "pwa example 6.4: {} data points from {} trajectories, eps_fit {:.3e}, {} partitions (ratio to 110: {:.3}), learning {:.2} s",
        points,
        s.trajectories.len(),
        ctx.eps_fit,
        partitions,
        partitions as f64 / 110.0,
        learn_s
    );
    let mut rows = vec![
        Row::with_baseline(
            "pwa_partitions_example_6_4",
            partitions as f64,
            "partitions",
            110.0,
            partitions as f64 / 110.0,
        ),
        Row::new("pwa_learning_s", learn_s, "s"),
    ];
    let ff = s.image.len() as f64;
    match build_pwa(&task, ctx, laws, assignment, learn_s) {
        Ok(c) => {
            let b = c.image.len() as f64;
            println!(
                "pwa image {} bytes (feedforward image of the same cover {} bytes), tree depth {}",
                b, ff, c.stats.depth
            );
            rows.push(Row::with_baseline(
                "pwa_image_bytes",
                b,
                "bytes",
                ff,
                b / ff,
            ));
        }
        Err(e) => {
            println!("pwa image: NOT built ({e}); feedforward image of the same cover {ff} bytes")
        }
    }
    // Sampled at 0.01 s: without and with a 20-sample reference hold.
    let count = |hold: usize| -> (usize, usize, f64) {
        let mut p = problem.clone();
        p.plant.period = 0.01;
        p.synthesis.reference_hold = hold;
        let task = Task::new(p).expect("the 0.01 s task");
        let s = synthesize(&task, &opts).expect("the 0.01 s cover is synthesized");
        // Greedy search only: the thermal relaxation would take minutes on ~2 000 points.
        let ctx = PwaContext::new(
            &task,
            &s,
            PwaSettings::builder().thermal_cycles(0).build().unwrap(),
        )
        .expect("PWA context");
        let rho = ctx
            .points
            .iter()
            .map(|q| q.rho)
            .fold(f64::INFINITY, f64::min);
        let (laws, _) = learn_laws(&ctx);
        (laws.len(), ctx.points.len(), rho)
    };
    let (free, free_points, free_rho) = count(1);
    let (held, held_points, held_rho) = count(20);
    println!(
        "sampled at 0.01 s: {free} partitions for {free_points} points (radius {free_rho:.4}) without a hold; {held} partitions for {held_points} points (radius {held_rho:.4}) with reference_hold = 20"
    );
    rows.push(Row::with_baseline(
        "pwa_partitions_hold20_h001",
        held as f64,
        "partitions",
        free as f64,
        held as f64 / free as f64,
    ));
    write_rows("pwa_example_6_4", &rows).expect("rows written");
}
