//! The global route search (issue 48) on the SCOTS maze, with no recording.
//!
//! The point mass (`examples/maze-scots-pointmass.toml`):
//! * `route_search_ms`: the route search alone (the grid of the maze's sets and the routes from Init's
//!   centre), median of repeated runs;
//! * `route_maze_synth_s`: the whole `synthesize` of the example (CAF, terminal law, cover, 10 000 + 32
//!   per ball Monte Carlo runs, the falsifier), target ≤ 60 s;
//! * `route_maze_coverage`: its coverage of Init, the lower bound at the spec's 99 % confidence, target
//!   ≥ 0.99;
//! * `route_maze_violations`: violations the Monte Carlo and the falsifier found (must be 0).
//!
//! * `maze_pointmass_T_s` (issue 47): the shortest horizon T (s) at which the point mass's synthesis
//!   certifies ≥ 0.99 of Init (the coverage lower bound), target ≤ 80 s: the example's spec with only
//!   `horizon` replaced, scanned downwards in steps of `T_STEP` from the example's T while it certifies,
//!   then the last step halved once (each run with a short Monte Carlo and no falsifier, cancelled after
//!   `T_BUDGET`; the example's own run above keeps those);
//! * `intersample_margin_ratio`: on the first certified trajectory at that T, the certified lower bound
//!   on the nominal's distance from Unsafe between samples (the larger of the isotropic and the
//!   directional bound of `certify::pieces`, at r = 0 with the certificate's ε̄), least over the route,
//!   ÷ the least distance of the exact flow (the continuous plant, the input held, 400 instants per
//!   period). At most 1; the isotropic bound's ratio is printed beside it.
//!
//! The SCOTS vehicle (`examples/maze-scots-vehicle.toml`, feedback linearizable in its position):
//! * `route_maze_vehicle_synth_s`: its whole `synthesize` (or the time until it is refused), target
//!   ≤ 300 s; cancelled at 300 s (as by Ctrl-C), when what it certified by then is what counts;
//! * `route_maze_vehicle_coverage`: its coverage lower bound (0 when nothing is certified), target ≥ 0.99;
//! * per sample period h (the example's spec with only `plant.period` changed; `_h<h in s>`):
//!   `route_maze_vehicle_D_…` the sampled-loop mismatch D the plant reports (the w-channel disturbance),
//!   `route_maze_vehicle_accumulated_…` what the certificate subtracts for it over the table,
//!   S_N·(‖P^{1/2}B‖ε̄ + φβD) of the route's trajectory, and `route_maze_vehicle_route_delta_…` the
//!   certificate's parts minimum less that (the δ the route would certify by the accumulated bound;
//!   negative: refused), for the trajectory that follows the first route's timed reference exactly
//!   (no generator, no §5.3: the route itself, what a person's route would give);
//!   `route_maze_vehicle_ceiling_…` the largest δ any nominal of that loop and length can have
//!   (`certify::Ceiling`; 0: `synth` refuses the task before any seed).
//!
//! `ROUTE_BENCH=pointmass` or `ROUTE_BENCH=vehicle` runs one maze only (the rows file then holds its
//! rows only).

use host_compiler::benchkit::{median_time, write_rows, Row};
use host_compiler::certify::{shipped, Ceiling, Loop, LoopConstants};
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use host_compiler::trajectory::route::{timed_guess, RouteMap, RouteSettings};
use std::time::{Duration, Instant};

fn main() {
    let only = std::env::var("ROUTE_BENCH").ok();
    let mut rows = Vec::new();
    if only.as_deref() != Some("vehicle") {
        rows.extend(pointmass());
    }
    if only.as_deref() != Some("pointmass") {
        rows.extend(vehicle());
    }
    let path = write_rows("route", &rows).expect("rows written");
    println!("rows: {}", path.display());
}

fn example(name: &str) -> String {
    format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn centre(task: &Task) -> Vec<f64> {
    let init = task.init();
    init.lo
        .iter()
        .zip(&init.hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect()
}

fn pointmass() -> Vec<Row> {
    let path = example("maze-scots-pointmass.toml");
    let task = Task::new(host_compiler::spec::load(&path).expect("the shipped example")).unwrap();
    let init = task.init();
    let centre = centre(&task);
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
    let (secs, coverage, violations) = synth_rows("maze", &task, None);
    let mut rows = vec![
        Row::new("route_search_ms", search * 1e3, "ms"),
        Row::new("route_maze_synth_s", secs, "s"),
        Row::new("route_maze_coverage", coverage, "lower bound, 99 %"),
        Row::new("route_maze_violations", violations, "runs"),
    ];
    rows.extend(shortest_horizon(&path));
    rows
}

/// The horizon scan's step, seconds.
const T_STEP: f64 = 10.0;
/// The shortest horizon tried, seconds.
const T_MIN: f64 = 40.0;
/// Each horizon's synthesis is cancelled after this long.
const T_BUDGET: Duration = Duration::from_secs(150);

/// The spec text with its `horizon = …` line set to `t`.
fn with_horizon(src: &str, t: f64) -> String {
    src.lines()
        .map(|l| {
            if l.trim_start().starts_with("horizon =") {
                format!("horizon = {t:.1}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// `maze_pointmass_T_s` and `intersample_margin_ratio` (module doc).
fn shortest_horizon(path: &str) -> Vec<Row> {
    let src = std::fs::read_to_string(path).expect("the shipped example");
    let t0 = host_compiler::spec::parse(&src, path)
        .expect("the shipped example")
        .horizon;
    let opts = SynthOptions {
        progress: false,
        verify_interior: 1000,
        verify_per_ball: 4,
        attack: None,
        ..SynthOptions::default()
    };
    let mut best: Option<(f64, host_compiler::synth::Synthesis, Task)> = None;
    let mut t = t0;
    let mut failed = None;
    while t >= T_MIN - 1e-9 {
        match certifies(&src, path, t, &opts) {
            Some((s, task)) => best = Some((t, s, task)),
            None => {
                failed = Some(t);
                break;
            }
        }
        t -= T_STEP;
    }
    // One halving of the last step, between the last horizon that certified and the first that did not.
    if let (Some(bad), Some((good, ..))) = (failed, &best) {
        let mid = 0.5 * (bad + good);
        if let Some((s, task)) = certifies(&src, path, mid, &opts) {
            best = Some((mid, s, task));
        }
    }
    let Some((t, s, task)) = best else {
        println!("the maze certifies at no horizon tried (from {t0} s down)");
        return vec![Row::new("maze_pointmass_T_s", f64::INFINITY, "s")];
    };
    let (ratio, iso) = margin_ratio(&task, &s);
    println!(
        "maze_pointmass_T_s = {t:.1} s; intersample_margin_ratio = {ratio:.4} (the isotropic bound alone: \
         {iso:.4})"
    );
    vec![
        Row::new("maze_pointmass_T_s", t, "s, coverage ≥ 0.99"),
        Row::new(
            "intersample_margin_ratio",
            ratio,
            "certified ÷ exact least distance",
        ),
    ]
}

/// The example's synthesis with its horizon set to `t`, if it certifies ≥ 0.99 of Init (the coverage
/// lower bound) with no violation; cancelled (as by Ctrl-C) after `T_BUDGET`.
fn certifies(
    src: &str,
    path: &str,
    t: f64,
    opts: &SynthOptions,
) -> Option<(host_compiler::synth::Synthesis, Task)> {
    let task = Task::new(host_compiler::spec::parse(&with_horizon(src, t), path).unwrap())
        .expect("its task");
    let opts = SynthOptions {
        cancel: Default::default(),
        ..opts.clone()
    };
    let cancel = opts.cancel.clone();
    let done = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let finished = done.clone();
    std::thread::spawn(move || {
        let start = Instant::now();
        while start.elapsed() < T_BUDGET && !finished.load(std::sync::atomic::Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(200));
        }
        cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    });
    let start = Instant::now();
    let s = synthesize(&task, &opts);
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let secs = start.elapsed().as_secs_f64();
    match s {
        Ok(s) => {
            println!(
                "horizon {t:.1} s: {} trajectories, coverage lower bound {:.5}, {} violations, \
                 {secs:.1} s; stop: {}",
                s.trajectories.len(),
                s.coverage.lower,
                s.verify.violations,
                s.stop
            );
            (s.coverage.lower >= 0.99 && s.verify.violations == 0).then_some((s, task))
        }
        Err(e) => {
            println!("horizon {t:.1} s: refused after {secs:.1} s: {e}");
            None
        }
    }
}

/// The certified least distance from Unsafe between samples of the first trajectory's nominal ÷ the
/// exact flow's (module doc): (with the directional bound, the isotropic bound alone).
fn margin_ratio(task: &Task, s: &host_compiler::synth::Synthesis) -> (f64, f64) {
    use host_compiler::certify::Pieces;
    let tr = &s.trajectories[0];
    let lp = Loop {
        plant: &*task.plant,
        loc: 0,
        K: s.K.as_ref(),
        P: s.P.as_ref(),
        goal: task.property.goal.as_ref(),
        unsafe_set: task.property.unsafe_region(),
        input: &task.property.input,
    };
    let pc = Pieces::new(&lp, &s.constants);
    let us = lp.unsafe_set().expect("the maze has walls");
    let cp = lp.continuous().expect("a continuous plant");
    const SUB: usize = 400;
    let h = lp.plant.period();
    let fine = host_compiler::model::zoh(cp, h / SUB as f64).expect("a fine step");
    let nom = &tr.nominal;
    let (mut cert, mut iso_least, mut exact) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    // Up to the critical sample, where the run is handed over or ends.
    for k in 0..tr.certificate.k_star.min(nom.steps()) {
        let (iso, dir) = pc
            .unsafe_clearance(nom, k, 0.0, tr.certificate.eps_f32)
            .expect("a continuous plant with Unsafe");
        cert = cert.min(iso.max(dir.unwrap_or(f64::NEG_INFINITY)));
        iso_least = iso_least.min(iso);
        let mut x = nom.x[k].clone();
        for _ in 0..SUB {
            x = fine.step(&x, &nom.u[k]);
            exact = exact.min(-us.signed_dist(&x, pc.metric()).value);
        }
        exact = exact.min(-us.signed_dist(&nom.x[k], pc.metric()).value);
    }
    println!(
        "along the first trajectory ({} samples to κ*): certified least distance between samples \
         {cert:.4e} (isotropic {iso_least:.4e}), exact flow's {exact:.4e}",
        tr.certificate.k_star
    );
    (cert / exact, iso_least / exact)
}

/// The whole `synthesize` of a task: (seconds, coverage lower bound, violations); a refusal is printed
/// and counts as coverage 0. With a `budget`, synthesis is cancelled (as by Ctrl-C) when it runs out,
/// and what it certified by then is what counts.
fn synth_rows(what: &str, task: &Task, budget: Option<Duration>) -> (f64, f64, f64) {
    let opts = SynthOptions {
        progress: false,
        ..SynthOptions::default()
    };
    if let Some(b) = budget {
        let cancel = opts.cancel.clone();
        std::thread::spawn(move || {
            std::thread::sleep(b);
            cancel.store(true, std::sync::atomic::Ordering::Relaxed);
        });
    }
    let t = Instant::now();
    let s = synthesize(task, &opts);
    let secs = t.elapsed().as_secs_f64();
    if budget.is_some_and(|b| secs >= b.as_secs_f64()) {
        println!("{what}: cancelled at the {:.0} s budget", secs);
    }
    match s {
        Ok(s) => {
            let attack = s.attack.as_ref().map_or(0, |a| a.violations);
            let violations = s.verify.violations + attack;
            println!(
                "{what}: {} trajectories (first δ {:.4e} from {}), coverage {:.5} (lower {:.5} at {} \
                 confidence), {} + {} Monte Carlo runs, {} violations ({} by the falsifier), {secs:.1} s \
                 ({:?}); stop: {}",
                s.trajectories.len(),
                s.trajectories.first().map_or(0.0, |t| t.certificate.delta),
                s.trajectories.first().map_or("-".into(), |t| t.source.to_string()),
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
            (secs, s.coverage.lower, violations as f64)
        }
        Err(e) => {
            println!("{what}: refused after {secs:.1} s: {e}");
            (secs, 0.0, 0.0)
        }
    }
}

/// The vehicle's synthesis is cancelled after its row's target time (what it certified by then counts).
const VEHICLE_BUDGET: Duration = Duration::from_secs(300);

/// The sample periods of the vehicle's mismatch table, seconds.
const PERIODS: [f64; 6] = [0.3, 0.2, 0.1, 0.05, 0.025, 0.0125];

fn vehicle() -> Vec<Row> {
    let path = example("maze-scots-vehicle.toml");
    let src = std::fs::read_to_string(&path).expect("the shipped example");
    let mut rows = Vec::new();
    println!(
        "vehicle, the first route's timed reference followed exactly, per period h:\n\
         {:>7} {:>6} {:>10} {:>10} {:>10} {:>10} {:>12} {:>10} {:>10} {:>10}",
        "h [s]",
        "N",
        "D",
        "δ_Goal",
        "δ_Unsafe",
        "δ_Input",
        "accumulated",
        "δ",
        "input max",
        "ceiling"
    );
    for h in PERIODS {
        let f = route_figures(&with_period(&src, h));
        println!(
            "{h:>7.3} {:>6} {:>10.4e} {:>10.4e} {:>10.4e} {:>10.4e} {:>12.4e} {:>10.4e} {:>10.4e} {:>10.4e}",
            f.steps,
            f.mismatch,
            f.parts[0],
            f.parts[1],
            f.parts[2],
            f.accumulated,
            f.delta,
            f.input_max,
            f.ceiling
        );
        rows.push(Row::new(
            &format!("route_maze_vehicle_D_h{h}"),
            f.mismatch,
            "w-channel mismatch",
        ));
        rows.push(Row::new(
            &format!("route_maze_vehicle_accumulated_h{h}"),
            f.accumulated,
            "P-metric, over the table",
        ));
        rows.push(Row::new(
            &format!("route_maze_vehicle_route_delta_h{h}"),
            f.delta,
            "P-metric (< 0: refused)",
        ));
        rows.push(Row::new(
            &format!("route_maze_vehicle_ceiling_h{h}"),
            f.ceiling,
            "P-metric, the largest δ any nominal can have (0: none)",
        ));
    }
    let task = Task::new(host_compiler::spec::parse(&src, &path).expect("the shipped example"))
        .expect("its task");
    let (secs, coverage, violations) = synth_rows("vehicle maze", &task, Some(VEHICLE_BUDGET));
    rows.push(Row::new("route_maze_vehicle_synth_s", secs, "s"));
    rows.push(Row::new(
        "route_maze_vehicle_coverage",
        coverage,
        "lower bound, 99 %",
    ));
    rows.push(Row::new(
        "route_maze_vehicle_violations",
        violations,
        "runs",
    ));
    rows
}

/// The spec text with its (only) `period = …` line set to `h`, and `max_trajectories` lowered to what
/// the image's table holds at that many samples (the table's trajectory alone is certified here).
fn with_period(src: &str, h: f64) -> String {
    src.lines()
        .map(|l| {
            if l.trim_start().starts_with("period =") {
                format!("period = {h}")
            } else if l.trim_start().starts_with("max_trajectories =") {
                "max_trajectories = 8".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

struct Figures {
    steps: usize,
    mismatch: f64,
    parts: [f64; 3],
    accumulated: f64,
    delta: f64,
    /// `certify::Ceiling` of the loop for the table: the largest input part any nominal can have, and
    /// the largest δ any can be certified with.
    input_max: f64,
    ceiling: f64,
}

/// The certificate of the trajectory that follows the first route from Init's centre exactly: the
/// route's timed reference (`trajectory::route::timed_guess`) is a sequence of positions, and on the
/// chain in ξ = (x, y) (x⁺ = x + h·u, B diagonal) the input that moves between them is u_k =
/// (ξ_{k+1} − A ξ_k)/B_jj, the reference v_k = u_k − K̂ ξ_k.
fn route_figures(src: &str) -> Figures {
    let task =
        Task::new(host_compiler::spec::parse(src, "maze-scots-vehicle.toml").unwrap()).unwrap();
    let design = host_compiler::caf::design(&task).expect("a CAF");
    let lp = Loop::new(&task, &design);
    let lc = LoopConstants::new(&lp).expect("loop constants");
    let x0: Vec<f64> = centre(&task).iter().map(|&v| v as f32 as f64).collect();
    let init = task.init();
    let map =
        RouteMap::new(&task.convex, &init.lo, &init.hi, &RouteSettings::default()).expect("a grid");
    let route = map.routes(&x0).into_iter().next().expect("a route");
    let (n, m) = (task.plant.n(), task.plant.m());
    let guess = timed_guess(&route, map.coords(), &x0, task.steps, 0.8, m);
    let (a, b, k) = (lp.A(), lp.B(), lp.K);
    let v: Vec<Vec<f64>> = guess
        .x
        .windows(2)
        .map(|w| {
            (0..m)
                .map(|i| {
                    let ax: f64 = (0..n).map(|j| a[(i, j)] * w[0][j]).sum();
                    let u = (w[1][i] - ax) / b[(i, i)];
                    u - (0..n).map(|j| k[(i, j)] * w[0][j]).sum::<f64>()
                })
                .collect()
        })
        .collect();
    let (nom, c) = shipped(&lp, &lc, &x0, &v);
    let umax = nom
        .u
        .iter()
        .flat_map(|u| u.iter().map(|a| a.abs()))
        .fold(0.0f64, f64::max);
    println!(
        "  route length {:.2}, clearance {:.3}; W {:?}; largest |w| {umax:.4}; K {:?}",
        route.length,
        route.clearance,
        task.property.input,
        (0..m)
            .map(|i| (0..n).map(|j| k[(i, j)]).collect::<Vec<_>>())
            .collect::<Vec<_>>()
    );
    let parts = [c.delta_goal, c.delta_unsafe_intersample, c.delta_input];
    // Without the certificate's own sum (it is formed only when the parts are positive), the mismatch's
    // alone over the table, as the ceiling takes it.
    let ceiling = Ceiling::of(&lp, &lc, task.steps);
    let accumulated = if c.accumulated > 0.0 {
        c.accumulated
    } else {
        ceiling.accumulated
    };
    Figures {
        steps: task.steps,
        mismatch: task.plant.model_mismatch(),
        parts,
        accumulated,
        delta: c.parts_min() - accumulated,
        input_max: ceiling.input,
        ceiling: ceiling.value,
    }
}
