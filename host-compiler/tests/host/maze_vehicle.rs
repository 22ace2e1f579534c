//! The SCOTS vehicle in the SCOTS maze (issue 48, `examples/maze-scots-vehicle.toml`): the spec is
//! SCOTS' model after the change of input the file states, with the input bounds it states; the route
//! search runs in the coordinates the sets are written in (ξ = (x, y) here, and the flat quadrotor's
//! positions, not every coordinate its operating region bounds); and what the certificate says of the
//! trajectory that follows the first route.

use host_compiler::certify::{shipped, Ceiling, Loop, LoopConstants};
use host_compiler::spec::InputSet;
use host_compiler::task::Task;
use host_compiler::trajectory::route::{route_coords, timed_guess, RouteMap, RouteSettings};

fn example(name: &str) -> String {
    format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn vehicle() -> Task {
    let p = host_compiler::spec::load(example("maze-scots-vehicle.toml")).expect("the example");
    Task::new(p).expect("its task")
}

/// SCOTS' vector field at (θ, u1, u2): α = atan(tan(u2)/2), (u1 cos(α+θ)/cos α, u1 sin(α+θ)/cos α,
/// u1 tan u2).
fn scots(th: f64, u1: f64, u2: f64) -> [f64; 3] {
    let a = (u2.tan() / 2.0).atan();
    [
        u1 * (a + th).cos() / a.cos(),
        u1 * (a + th).sin() / a.cos(),
        u1 * u2.tan(),
    ]
}

/// The spec's plant, driven by (v, ω) = (u1, u1 tan u2), is SCOTS' vehicle at every sampled state and
/// input; its task lives in ξ = (x, y) with θ the zero dynamics, and the input box is the one the file
/// states, which keeps |u1| ≤ V and |u1 tan u2| ≤ Ω.
#[test]
fn the_vehicle_spec_is_scots_model_after_the_stated_change_of_input() {
    let task = vehicle();
    let maps = task
        .plant
        .linearization()
        .expect("a feedback-linearizable plant");
    assert_eq!((maps.n_plant, maps.m_plant), (3, 2));
    assert_eq!(maps.xi_states, vec![0, 1], "ξ = (x, y)");
    assert_eq!(maps.zero_states, vec![2], "θ is the zero dynamics");
    let InputSet::Box { lo, hi } = &maps.input else {
        panic!("a box input set: {:?}", maps.input)
    };
    let (vmax, omax) = (hi[0], hi[1]);
    assert_eq!(lo.as_slice(), [-vmax, -omax], "symmetric");
    assert!(vmax > 0.0 && vmax <= 1.0, "|u1| ≤ V ≤ 1: {vmax}");
    // Ω ≤ V tan 1: at full speed the box's turn rate needs no steering beyond SCOTS' |u2| ≤ 1.
    assert!(omax <= vmax * 1f64.tan() + 1e-12, "Ω {omax} ≤ V tan 1");
    let mut checked = 0;
    for i in 0..7 {
        let th = -3.0 + i as f64;
        for u1 in [-vmax, -0.3 * vmax, 0.5 * vmax, vmax] {
            for u2 in [-1.0, -0.4, 0.0, 0.7, 1.0] {
                let (v, om) = (u1, u1 * f64::tan(u2));
                if om.abs() > omax {
                    continue;
                }
                let got = maps.plant.field(&[0.3, 0.7, th], &[v, om]);
                let want = scots(th, u1, u2);
                for k in 0..3 {
                    assert!(
                        (got[k] - want[k]).abs() < 1e-12,
                        "θ {th}, u {u1} {u2}: {got:?} against SCOTS' {want:?}"
                    );
                }
                checked += 1;
            }
        }
    }
    assert!(checked > 60, "{checked} points");
}

/// The route search's grid is over the coordinates Goal and the obstacles around it are written in:
/// (x, y) for the vehicle; (X, Y) of the flat quadrotor's q = (X, Ẋ, Ẍ, X⃛, Y, Ẏ, Ÿ, Y⃛), whose operating
/// region adds half-spaces on all eight to Unsafe (with them the grid was eight-dimensional, 4 cells a
/// side, and no route fit).
#[test]
fn routes_are_searched_in_the_coordinates_the_sets_are_written_in() {
    let task = vehicle();
    assert_eq!(route_coords(&task.convex, task.plant.n()), vec![0, 1]);
    let quad =
        Task::new(host_compiler::spec::load(example("flat-quadrotor.toml")).unwrap()).unwrap();
    assert_eq!(quad.plant.n(), 8);
    assert!(
        quad.convex.unsafe_pieces.len() >= 2 + 16,
        "the region's complement is in Unsafe"
    );
    assert_eq!(route_coords(&quad.convex, 8), vec![0, 4]);
    let init = quad.init();
    let map = RouteMap::new(&quad.convex, &init.lo, &init.hi, &RouteSettings::default()).unwrap();
    assert_eq!(map.coords(), &[0, 4]);
    let x0: Vec<f64> = init
        .lo
        .iter()
        .zip(&init.hi)
        .map(|(l, h)| 0.5 * (l + h))
        .collect();
    let routes = map.routes(&x0);
    assert!(!routes.is_empty(), "no route over the hill");
    // Every route ends in Goal ([6, 8] × [1, 3] in (X, Y)) and keeps off the hill.
    for r in &routes {
        let end = r.points.last().unwrap();
        assert!(
            (6.0..=8.0).contains(&end[0]) && (1.0..=3.0).contains(&end[1]),
            "{end:?}"
        );
    }
}

/// Along the route search's first route, followed exactly at constant speed (its timed reference, the
/// generator's starting point), the vehicle fits the pulled-back input set and reaches Goal, yet the
/// certificate refuses the trajectory: the sampled-loop mismatch D, summed over the table, is larger
/// than every part's margin. This is what stops the example (its header), not the route.
#[test]
fn along_the_first_route_the_accumulated_mismatch_is_what_refuses_the_vehicle() {
    let task = vehicle();
    let design = host_compiler::caf::design(&task).expect("a CAF");
    let lp = Loop::new(&task, &design);
    let lc = LoopConstants::new(&lp).expect("loop constants");
    let init = task.init();
    let x0: Vec<f64> = init
        .lo
        .iter()
        .zip(&init.hi)
        .map(|(l, h)| (0.5 * (l + h)) as f32 as f64)
        .collect();
    let map = RouteMap::new(&task.convex, &init.lo, &init.hi, &RouteSettings::default()).unwrap();
    let route = map
        .routes(&x0)
        .into_iter()
        .next()
        .expect("a route through the maze");
    assert!(route.clearance > 0.1, "clearance {}", route.clearance);
    let (n, m) = (task.plant.n(), task.plant.m());
    assert_eq!((n, m), (2, 2));
    let guess = timed_guess(&route, map.coords(), &x0, task.steps, 0.8, m);
    // On the chain ξ⁺ = Aξ + Bu (B diagonal), the input that moves between the reference's positions.
    let (a, b, k) = (lp.A(), lp.B(), lp.K);
    let v: Vec<Vec<f64>> = guess
        .x
        .windows(2)
        .map(|w| {
            (0..m)
                .map(|i| {
                    let ax: f64 = (0..n).map(|j| a[(i, j)] * w[0][j]).sum();
                    (w[1][i] - ax) / b[(i, i)] - (0..n).map(|j| k[(i, j)] * w[0][j]).sum::<f64>()
                })
                .collect()
        })
        .collect();
    let (_, c) = shipped(&lp, &lc, &x0, &v);
    assert!(c.delta_goal > 0.0, "the route reaches Goal: {c:?}");
    assert!(c.delta_input > 0.0, "the route's speed fits W: {c:?}");
    assert!(!c.is_certified(), "certified: {c:?}");
    let d = task.plant.model_mismatch();
    // The mismatch alone, summed over the table (S_N·z, as the ceiling below takes it).
    let ceiling = Ceiling::of(&lp, &lc, task.steps);
    let accumulated = ceiling.accumulated;
    assert!(d > 0.0);
    assert!(
        accumulated > c.parts_min() && c.r_crit > c.parts_min(),
        "D {d}: accumulated {accumulated}, r_crit {}, parts {}",
        c.r_crit,
        c.parts_min()
    );
    // More: no nominal of the table's length can be certified, since even the input set's whole
    // half-width (over the gain's scale) is below the mismatch accumulated over the table and r_crit.
    assert!(ceiling.input >= c.delta_input, "{ceiling:?} against {c:?}");
    assert!(
        ceiling.input < ceiling.accumulated && ceiling.input < ceiling.r_crit,
        "{ceiling:?}"
    );
    assert_eq!(ceiling.value, 0.0);
    assert!(ceiling.below(task.problem.synthesis.min_robustness));
}

/// `synth` refuses the vehicle at once, before any seed, naming the input margin's ceiling, the
/// accumulated mismatch and r_crit, with the exit code of a spec that must change (2), not after the
/// search's budget.
#[test]
fn synth_refuses_the_vehicle_at_once_with_the_ceiling() {
    let out = std::env::temp_dir().join(format!("maze-vehicle-ceiling-{}", std::process::id()));
    let started = std::time::Instant::now();
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .args(["synth", &example("maze-scots-vehicle.toml"), "--out"])
        .arg(&out)
        .output()
        .expect("runs");
    let secs = started.elapsed().as_secs_f64();
    let err = String::from_utf8_lossy(&run.stderr).replace(['│', '\n'], " ");
    let err = err.split_whitespace().collect::<Vec<_>>().join(" ");
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(err.contains("none can be, so no seed was tried"), "{err}");
    assert!(
        err.contains("input margin") && err.contains("over a table of 1333 samples"),
        "{err}"
    );
    assert!(secs < 30.0, "{secs} s");
    assert!(!out.join("controller.img").exists());
    let _ = std::fs::remove_dir_all(&out);
}
