//! Routes of the global search as seeds of runs with internal switching (`synth::hybrid::route`, issue 48
//! item 3): from Example 5.6's uncovered corner (x₁ ≈ −4, x₃ ≈ −4) the planner alone gives no run under
//! Example 5.5's wall, and a route through the guard gives one that certifies.
//!
//! Kept short for CI: §5.3 gets one iteration (`max_iterations = 2`, halved per search) and the route's
//! run is planned over one first-segment duration (0.16 T, where a run under the wall crosses the guard)
//! instead of all of `ROUTE_DURATIONS`.

use host_compiler::cover::seeds::{Origin, Routing};
use host_compiler::synth::hybrid::{
    certify_run, f32_start, plan_run, route, HybridRun, HybridTask,
};

fn task(file: &str, iterations: usize) -> HybridTask {
    let path = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
    let mut problem = host_compiler::spec::load(&path).expect("the shipped example parses");
    problem.synthesis.max_iterations = iterations;
    HybridTask::new(problem).expect("a hybrid task")
}

/// Where a run passes the wall (x₁ ∈ (−2, 2), its extent along x₁): under (x₃ below the wall's centre
/// 2.5 throughout), over (above throughout), or neither.
fn side(states: impl Iterator<Item = Vec<f64>>) -> &'static str {
    let x3: Vec<f64> = states.filter(|x| x[0].abs() < 2.0).map(|x| x[2]).collect();
    if x3.is_empty() {
        "none"
    } else if x3.iter().all(|&v| v < 2.5) {
        "under"
    } else if x3.iter().all(|&v| v > 2.5) {
        "over"
    } else {
        "through"
    }
}

fn run_side(run: &HybridRun) -> &'static str {
    side(run.nominals.iter().flat_map(|n| n.x.iter().cloned()))
}

#[test]
fn a_route_under_the_wall_gives_a_certified_run_from_example_5_6_s_corner_where_the_planner_gives_none(
) {
    let task = task("hybrid-internal-5-5.toml", 2);
    let x0 = [-4.2, 1.0, -3.8];
    // The planner alone: no certified run under the wall from here (from this corner it finds none).
    let plain = plan_run(&task, &x0);
    assert!(
        plain
            .as_ref()
            .map_or(true, |r| !r.certificate.is_certified()
                || run_side(r) != "under"),
        "the planner alone passed under: δ {:?}",
        plain.as_ref().map(|r| r.delta())
    );
    // The route search from the seed: the best route goes under the wall (it crosses x₁ = 0 below it).
    let routing = Routing::new(&task.convex, &task.problem.init.lo, &task.problem.init.hi);
    let map = routing.map().expect("a grid");
    let routes = routing.routes(map, &x0);
    assert!(!routes.is_empty());
    let best = &routes[0];
    let lift = |y: &Vec<f64>| -> Vec<f64> {
        let mut x = x0.to_vec();
        for (c, &j) in map.coords().iter().enumerate() {
            x[j] = y[c];
        }
        x
    };
    let crossing = best
        .points
        .iter()
        .map(lift)
        .find(|x| x[0] >= 0.0)
        .expect("the route crosses the guard");
    assert!(crossing[2] < 0.5, "crossing {crossing:?}");
    assert_eq!(side(best.points.iter().map(lift)), "under");
    // Its run: certified, under the wall, shipping what it certified, from the f32 start.
    let run = route::plan_along(&task, best, map.coords(), 0.8, &x0, &[0.16]).expect("a run");
    assert!(run.certificate.is_certified(), "δ {}", run.delta());
    assert!(run.delta() > 0.0);
    assert_eq!(run_side(&run), "under");
    assert_eq!(run.nominals[0].x[0], f32_start(&x0));
    assert_eq!(run.locations, task.path);
    assert_eq!(certify_run(&task, &run.nominals).unwrap(), run.certificate);
    // The run's crossing of the guard (the first sample past x₁ = 0) is below the wall.
    let cross = run.nominals[0]
        .x
        .iter()
        .find(|x| x[0] >= 0.0)
        .expect("the first segment crosses");
    assert!(cross[2] < 0.5, "crossing {cross:?}");
}

#[test]
fn forced_switching_proposes_no_route_runs() {
    let task = task("hybrid-forced-cart.toml", 2);
    assert!(task.forced);
    let routing = Routing::new(&task.convex, &task.problem.init.lo, &task.problem.init.hi);
    let x0: Vec<f64> = task
        .problem
        .init
        .lo
        .iter()
        .zip(&task.problem.init.hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect();
    let proposals: Vec<Origin> = route::routed_runs(&task, &routing, &x0)
        .map(|p| p.origin)
        .collect();
    assert!(proposals.is_empty(), "{proposals:?}");
}

/// `--guard-routes` where there is no internal guard is refused with exit 2, saying why, before any
/// work: a spec without a hybrid automaton, and one with forced switching.
#[test]
fn guard_routes_without_internal_switching_is_refused() {
    for (file, why) in [
        ("double-integrator.toml", "has no hybrid automaton"),
        ("hybrid-forced-cart.toml", "forced switching"),
    ] {
        let spec = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
        let out =
            std::env::temp_dir().join(format!("hc-guard-routes-{}-{file}", std::process::id()));
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"))
            .args(["synth", &spec, "--guard-routes", "--quiet", "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{file}: {stderr}");
        assert!(
            stderr.contains("--guard-routes") && stderr.contains(why),
            "{file}: {stderr}"
        );
        std::fs::remove_dir_all(&out).ok();
    }
}
