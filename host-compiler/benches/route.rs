//! The global route search (issue 48) on the SCOTS maze with a point mass
//! (`examples/maze-scots-pointmass.toml`), with no recording:
//!
//! * `route_search_ms`: the route search alone (the grid of the maze's sets and the routes from Init's
//!   centre), median of repeated runs;
//! * `route_maze_synth_s`: the whole `synthesize` of the example (CAF, terminal law, cover, 10 000 + 32
//!   per ball Monte Carlo runs, the falsifier), target ≤ 60 s;
//! * `route_maze_coverage`: its coverage of Init, the lower bound at the spec's 99 % confidence, target
//!   ≥ 0.99;
//! * `route_maze_violations`: violations the Monte Carlo and the falsifier found (must be 0).

use host_compiler::benchkit::{median_time, write_rows, Row};
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use host_compiler::trajectory::route::{RouteMap, RouteSettings};
use std::time::{Duration, Instant};

fn main() {
    let path = format!(
        "{}/../examples/maze-scots-pointmass.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let task = Task::new(host_compiler::spec::load(&path).expect("the shipped example")).unwrap();
    let init = task.init();
    let centre: Vec<f64> = init
        .lo
        .iter()
        .zip(&init.hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect();
    let settings = RouteSettings::default();
    let mut found = Vec::new();
    let search = median_time(
        || {
            let map = RouteMap::new(&task.convex, &init.lo, &init.hi, &settings).expect("a grid");
            found = map.routes(&centre);
        },
        Duration::from_secs(3),
        3,
    );
    println!(
        "route search: {} routes (lengths {:?}, clearance {:.3}) in {:.1} ms",
        found.len(),
        found.iter().map(|r| r.length).collect::<Vec<_>>(),
        found.first().map_or(0.0, |r| r.clearance),
        search * 1e3
    );
    let opts = SynthOptions {
        progress: false,
        ..SynthOptions::default()
    };
    let t = Instant::now();
    let s = synthesize(&task, &opts).expect("synthesis");
    let secs = t.elapsed().as_secs_f64();
    let attack = s.attack.as_ref().map_or(0, |a| a.violations);
    let violations = s.verify.violations + attack;
    println!(
        "maze: {} trajectories (first δ {:.4e} from {}), coverage {:.5} (lower {:.5} at {} confidence), \
         {} + {} Monte Carlo runs, {} violations ({} by the falsifier), {secs:.1} s ({:?}); stop: {}",
        s.trajectories.len(),
        s.trajectories.first().map_or(0.0, |t| t.certificate.delta),
        s.trajectories.first().map_or("-", |t| t.source.as_str()),
        s.coverage.mean,
        s.coverage.lower,
        s.coverage.confidence,
        s.verify.interior_runs,
        s.verify.boundary_runs,
        violations,
        attack,
        s.timings,
        s.stop
    );
    let rows = vec![
        Row::new("route_search_ms", search * 1e3, "ms"),
        Row::new("route_maze_synth_s", secs, "s"),
        Row::new("route_maze_coverage", s.coverage.lower, "lower bound, 99 %"),
        Row::new("route_maze_violations", violations as f64, "runs"),
    ];
    let path = write_rows("route", &rows).expect("rows written");
    println!("rows: {}", path.display());
}
