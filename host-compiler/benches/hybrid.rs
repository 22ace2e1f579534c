//! Hybrid plants with internal switching (§4.2.2) and forced switching (§4.2.1): Example 5.5's certified δ from x0 = (−5, 1, 2) (one
//! run across x₁ = 0, planned and optimised by §5.3, `synth::hybrid::optimise`), and Example
//! 5.6's cover grown over Init (Algorithm 4 across the guard after the first run, δε = 0.4, as the text runs
//! it; the other covers with the planner from every seed, `synth`'s default): the coverage lower bound at
//! 99 % confidence, the trajectories, the wall time of the whole synthesis on this machine, and its Monte
//! Carlo against the exact hybrid flow (which must find no violation); the same for the forced-switching
//! Example 4.20 and the cart example (`coverage_hybrid_4_20`, `…_forced_cart`), and the cart with its task
//! an MTL formula (Def 4.18, `…_forced_cart_mtl`; its Monte Carlo judges the formula).
//!
//! The DC-DC boost converter (`examples/dcdc-boost.toml`, issue 48 item 4), no imports: its runs switch
//! every few samples, on schedules from the forced planner's schedule search; rows `coverage_dcdc_boost`
//! (the lower bound at 99 %, target ≥ 0.9), `trajectories_dcdc_boost`, `synth_dcdc_boost_s` and
//! `violations_dcdc_boost`, written to their own rows file (`hybrid_dcdc`). `cargo bench -p host-compiler
//! --bench hybrid -- dcdc` runs that part alone.
//!
//! A synthesis is seconds to minutes of deterministic (seeded) work, so it is timed directly.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::synth::hybrid::{plan_run, synthesize_hybrid, HybridOptions, HybridTask};
use host_compiler::synth::Generator;
use std::time::Instant;

fn task(file: &str) -> HybridTask {
    let path = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
    let problem = host_compiler::spec::load(&path).expect("the shipped example parses");
    HybridTask::new(problem).expect("the shipped example is a hybrid task")
}

/// The DC-DC boost converter's rows (module doc).
fn dcdc_boost() {
    let task = task("dcdc-boost.toml");
    let t = Instant::now();
    let rows = match synthesize_hybrid(&task, &HybridOptions::default()) {
        Ok(s) => {
            let secs = t.elapsed().as_secs_f64();
            let switches: Vec<usize> = s.runs.iter().map(|r| r.nominals.len() - 1).collect();
            println!(
                "DC-DC boost: {} runs ({} seeds tried; switches per run {}..{}), coverage {:.5} (lower {:.5} at {:.0} %), stop: {}; Monte Carlo {} runs ({} refused by the selection), {} violations; synth {secs:.1} s",
                s.runs.len(),
                s.seeds_tried,
                switches.iter().min().unwrap_or(&0),
                switches.iter().max().unwrap_or(&0),
                s.coverage.mean,
                s.coverage.lower,
                100.0 * s.coverage.confidence,
                s.stop,
                s.verify.runs - s.verify.rejected,
                s.verify.rejected,
                s.verify.violations
            );
            assert_eq!(s.verify.violations, 0, "{:?}", s.verify.first_violation);
            vec![
                Row::new(
                    "coverage_dcdc_boost",
                    s.coverage.lower,
                    "fraction of Init, 99 %",
                ),
                Row::new("trajectories_dcdc_boost", s.runs.len() as f64, "runs"),
                Row::new("synth_dcdc_boost_s", secs, "s"),
                Row::new("violations_dcdc_boost", s.verify.violations as f64, "runs"),
            ]
        }
        Err(why) => {
            let secs = t.elapsed().as_secs_f64();
            println!("DC-DC boost: no cover ({why}); {secs:.1} s");
            vec![
                Row::new("coverage_dcdc_boost", 0.0, "fraction of Init, 99 %"),
                Row::new("trajectories_dcdc_boost", 0.0, "runs"),
                Row::new("synth_dcdc_boost_s", secs, "s"),
            ]
        }
    };
    let path = write_rows("hybrid_dcdc", &rows).expect("rows written");
    println!("rows: {}", path.display());
}

fn main() {
    dcdc_boost();
    // `-- dcdc`: that part alone (cargo passes `--bench` itself).
    if std::env::args().skip(1).any(|a| a == "dcdc") {
        return;
    }
    let mut rows = Vec::new();
    // Example 5.5: one run from the text's x0.
    let t55 = task("hybrid-internal-5-5.toml");
    let delta = match plan_run(&t55, &[-5.0, 1.0, 2.0]) {
        Ok(run) => {
            let segs: Vec<String> = run
                .certificate
                .segments
                .iter()
                .map(|s| format!("δ = {:.4} ({})", s.delta, s.binding))
                .collect();
            println!(
                "Example 5.5 from (−5, 1, 2): δ = {:.4}; segments: {}",
                run.delta(),
                segs.join("; ")
            );
            run.delta()
        }
        Err(why) => {
            println!("Example 5.5 from (−5, 1, 2): no run ({why})");
            0.0
        }
    };
    rows.push(Row::new("delta_hybrid_5_5", delta, "CAF metric"));
    // Example 4.25 (Unsafe the ball): the same run's δ, for comparison.
    let t425 = task("hybrid-internal-4-25.toml");
    let d425 = plan_run(&t425, &[-5.0, 1.0, 2.0]).map_or(0.0, |r| r.delta());
    println!("Example 4.25 from (−5, 1, 2): δ = {d425:.4}");
    rows.push(Row::new("delta_hybrid_4_25", d425, "CAF metric"));
    // Example 5.6: the cover (Example 5.5's task with δε = 0.4); and the same growth on Example 4.25;
    // forced switching: Example 4.20 and the cart.
    let t420 = task("hybrid-forced-4-20.toml");
    let tcart = task("hybrid-forced-cart.toml");
    let tmtl = task("hybrid-forced-cart-mtl.toml");
    let scp = Generator::Scp;
    for (name, task, tag, generator) in [
        ("Example 5.6", &t55, "5_6", Generator::Algorithm4),
        ("Example 4.25", &t425, "4_25", scp),
        ("Example 4.20", &t420, "4_20", scp),
        ("The forced cart", &tcart, "forced_cart", scp),
        (
            "The forced cart with its MTL task",
            &tmtl,
            "forced_cart_mtl",
            scp,
        ),
    ] {
        let t = Instant::now();
        let options = HybridOptions {
            generator,
            ..HybridOptions::default()
        };
        let s = match synthesize_hybrid(task, &options) {
            Ok(s) => s,
            Err(why) => {
                let secs = t.elapsed().as_secs_f64();
                println!("{name}: no cover ({why}); {secs:.1} s");
                rows.push(Row::new(
                    &format!("coverage_hybrid_{tag}"),
                    0.0,
                    "fraction of Init, 99 %",
                ));
                rows.push(Row::new(&format!("trajectories_hybrid_{tag}"), 0.0, "runs"));
                rows.push(Row::new(&format!("synth_hybrid_{tag}_s"), secs, "s"));
                continue;
            }
        };
        let secs = t.elapsed().as_secs_f64();
        println!(
        "{name} ({generator}): {} runs ({} seeds tried), coverage {:.5} (lower {:.5} at {:.0} %), stop: {}; Monte Carlo {} runs ({} refused by the selection), {} violations; {secs:.1} s",
        s.runs.len(),
        s.seeds_tried,
        s.coverage.mean,
        s.coverage.lower,
        100.0 * s.coverage.confidence,
        s.stop,
        s.verify.runs - s.verify.rejected,
        s.verify.rejected,
        s.verify.violations
    );
        assert_eq!(s.verify.violations, 0, "{:?}", s.verify.first_violation);
        rows.push(Row::new(
            &format!("coverage_hybrid_{tag}"),
            s.coverage.lower,
            "fraction of Init, 99 %",
        ));
        rows.push(Row::new(
            &format!("trajectories_hybrid_{tag}"),
            s.runs.len() as f64,
            "runs",
        ));
        rows.push(Row::new(&format!("synth_hybrid_{tag}_s"), secs, "s"));
    }
    let path = write_rows("hybrid", &rows).expect("rows written");
    println!("rows: {}", path.display());
}
