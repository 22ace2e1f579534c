//! The global route search (issue 48, `trajectory::route`): routes in distinct homotopy classes around
//! an obstacle, the "no route" verdict naming the pieces that wall Goal off (and `synth` refusing such a
//! spec at once as bad input), and a small maze the plain generator does not get through that certifies
//! from a route.

use host_compiler::linalg::from_row_major;
use host_compiler::property::{ConvexPiece, ConvexSets};
use host_compiler::synth::{synthesize, SynthError, SynthOptions};
use host_compiler::task::Task;
use host_compiler::trajectory::route::{RouteMap, RouteSettings};

/// The box lo ≤ x ≤ hi in the plane as a polytope.
fn rect(lo: [f64; 2], hi: [f64; 2]) -> ConvexPiece {
    ConvexPiece::Polytope {
        H: from_row_major(4, 2, &[1.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, -1.0]),
        b: vec![hi[0], -lo[0], hi[1], -lo[1]],
    }
}

/// Inside `piece` (a box from [`rect`]) grown by `c`?
fn near_box(lo: [f64; 2], hi: [f64; 2], p: &[f64], c: f64) -> bool {
    let gap = (0..2)
        .map(|j| (lo[j] - p[j]).max(p[j] - hi[j]).max(0.0))
        .fold(0.0f64, f64::hypot);
    gap < c
}

#[test]
fn two_routes_in_distinct_classes_pass_a_single_obstacle_on_either_side() {
    let obstacle = ([1.0, -0.5], [2.0, 0.5]);
    let sets = ConvexSets {
        goal: rect([2.8, -0.2], [3.2, 0.2]),
        unsafe_pieces: vec![rect(obstacle.0, obstacle.1)],
    };
    let map = RouteMap::new(&sets, &[0.0, 0.0], &[0.0, 0.0], &RouteSettings::default()).unwrap();
    let routes = map.routes(&[0.0, 0.0]);
    assert!(routes.len() >= 2, "{} routes", routes.len());
    // The classes differ: the obstacle is the one hole, and the windings about it differ by 2π.
    let (a, b) = (&routes[0], &routes[1]);
    assert_eq!(a.signature.len(), 1, "one hole: {:?}", a.signature);
    let dw = (a.signature[0] - b.signature[0]).abs();
    assert!(
        (dw - 2.0 * std::f64::consts::PI).abs() < 0.5,
        "windings {:?} {:?}",
        a.signature,
        b.signature
    );
    // One passes above, the other below; both keep their clearance and end in Goal.
    let side = |r: &host_compiler::trajectory::route::Route| {
        r.points
            .iter()
            .filter(|p| (1.0..=2.0).contains(&p[0]))
            .map(|p| p[1].signum())
            .sum::<f64>()
            .signum()
    };
    assert_eq!(side(a) * side(b), -1.0, "one above, one below");
    for r in [a, b] {
        assert!(r.clearance > 0.0);
        for p in r.points.iter().skip(1) {
            assert!(
                !near_box(obstacle.0, obstacle.1, p, r.clearance - 1e-9),
                "{p:?} within {} of the obstacle",
                r.clearance
            );
        }
        let end = r.points.last().unwrap();
        assert!((2.8..=3.2).contains(&end[0]) && (-0.2..=0.2).contains(&end[1]));
    }
}

/// The walled-off spec: a point mass in [0, 4]² whose Goal sits in a closed ring of four walls.
fn walled_off() -> String {
    r#"
name = "walled-off"
seed = 1
horizon = 10.0
[plant]
time = "continuous"
A = [[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]
B = [[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
period = 0.1
[init]
kind = "box"
lo = [0.4, 0.4, 0.0, 0.0]
hi = [0.6, 0.6, 0.0, 0.0]
[goal]
kind = "box"
lo = [2.8, 2.8]
hi = [3.2, 3.2]
coords = ["x1", "x2"]
[input]
kind = "box"
lo = [-1.0, -1.0]
hi = [1.0, 1.0]
[[unsafe]]
kind = "ball"
center = [0.5, 3.5]
radius = 0.2
coords = ["x1", "x2"]
[[unsafe]]
kind = "box"
lo = [2.4, 2.4]
hi = [3.6, 2.6]
coords = ["x1", "x2"]
[[unsafe]]
kind = "box"
lo = [2.4, 3.4]
hi = [3.6, 3.6]
coords = ["x1", "x2"]
[[unsafe]]
kind = "box"
lo = [2.4, 2.4]
hi = [2.6, 3.6]
coords = ["x1", "x2"]
[[unsafe]]
kind = "box"
lo = [3.4, 2.4]
hi = [3.6, 3.6]
coords = ["x1", "x2"]
"#
    .to_string()
}

#[test]
fn a_goal_walled_off_is_refused_at_once_naming_the_walls() {
    let p = host_compiler::spec::parse(&walled_off(), "walled-off.toml").unwrap();
    let task = Task::new(p).unwrap();
    let t = std::time::Instant::now();
    let e = match synthesize(
        &task,
        &SynthOptions {
            progress: false,
            ..SynthOptions::default()
        },
    ) {
        Ok(_) => panic!("a walled-off Goal was synthesised"),
        Err(e) => e,
    };
    assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
    let SynthError::NoRoute { pieces, .. } = &e else {
        panic!("not a no-route refusal: {e}");
    };
    // The four walls, and not the ball elsewhere.
    assert_eq!(pieces, "unsafe[1], unsafe[2], unsafe[3], unsafe[4]", "{e}");
    assert!(e.to_string().contains("Goal cannot be reached"), "{e}");
    // With one wall opened the verdict is gone (the same map says reachable).
    let mut open = host_compiler::spec::parse(&walled_off(), "open.toml").unwrap();
    open.unsafe_sets.remove(4);
    let task = Task::new(open).unwrap();
    let init = task.init();
    let map = RouteMap::new(&task.convex, &init.lo, &init.hi, &RouteSettings::default()).unwrap();
    assert_eq!(map.closed_off(&init.lo, &init.hi), None);
}

#[test]
fn synth_exits_2_on_a_walled_off_goal() {
    let dir = std::env::temp_dir().join(format!("route-walled-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let spec = dir.join("walled-off.toml");
    std::fs::write(&spec, walled_off()).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .args(["synth"])
        .arg(&spec)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("unsafe[1], unsafe[2], unsafe[3], unsafe[4]"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A small maze for a point mass: three walls that the way must pass over, under and over again.
fn small_maze() -> String {
    r#"
name = "small-maze"
seed = 7
horizon = 30.0
[plant]
time = "continuous"
A = [[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]
B = [[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
period = 0.3
[init]
kind = "box"
lo = [0.48, 0.48, 0.0, 0.0]
hi = [0.52, 0.52, 0.0, 0.0]
[goal]
kind = "box"
lo = [3.6, 0.2]
hi = [4.1, 0.7]
coords = ["x1", "x2"]
[input]
kind = "box"
lo = [-1.0, -1.0]
hi = [1.0, 1.0]
[[unsafe]]
kind = "box"
lo = [1.0, 0.0]
hi = [1.2, 3.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "box"
lo = [2.2, 1.0]
hi = [2.4, 4.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[1.0, 0.0]]
b = [0.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[-1.0, 0.0]]
b = [-4.5]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[0.0, 1.0]]
b = [0.0]
coords = ["x1", "x2"]
[[unsafe]]
kind = "polytope"
A = [[0.0, -1.0]]
b = [-4.0]
coords = ["x1", "x2"]
[synthesis]
max_trajectories = 4
"#
    .to_string()
}

#[test]
fn a_small_maze_certifies_from_a_route_where_the_plain_generator_fails() {
    use host_compiler::certify::{Loop, LoopConstants};
    use host_compiler::trajectory::generate::{generate, GenProblem, GenSettings};
    let p = host_compiler::spec::parse(&small_maze(), "small-maze.toml").unwrap();
    let task = Task::new(p).unwrap();
    // The plain generator from Init's centre finds no trajectory through the maze.
    let design = host_compiler::caf::design(&task).unwrap();
    let lp = Loop::new(&task, &design);
    let lc = LoopConstants::new(&lp).unwrap();
    let gp = GenProblem {
        loc: 0,
        plant: &*task.plant,
        K: lp.K,
        P: lp.P,
        property: &task.property,
        convex: &task.convex,
        steps: task.steps,
        gamma: lc.gamma,
        phi: lc.phi,
        beta: lc.beta,
        input_margin: 1e-5,
        schedule: None,
    };
    let x0 = [0.5, 0.5, 0.0, 0.0];
    let plain = generate(&gp, &x0, &GenSettings::default());
    let plain_ok = plain.as_ref().is_ok_and(|g| {
        host_compiler::certify::shipped(&lp, &lc, &x0, &g.nominal.v)
            .1
            .is_certified()
    });
    assert!(!plain_ok, "the plain generator already certifies this maze");
    // synth gets through from a route.
    let s = synthesize(
        &task,
        &SynthOptions {
            verify_interior: 500,
            verify_per_ball: 4,
            progress: false,
            attack: None,
            ..SynthOptions::default()
        },
    )
    .unwrap();
    assert!(
        s.trajectories[0].source.to_string().starts_with("route "),
        "{}",
        s.trajectories[0].source
    );
    assert!(s.trajectories.iter().all(|t| t.certificate.is_certified()));
    assert_eq!(s.verify.violations, 0, "{:?}", s.verify.first_violations);
}
