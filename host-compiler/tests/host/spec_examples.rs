//! Every shipped example under `examples/` parses, and the two task specs say what the text says.
#![allow(non_snake_case)]

use std::path::PathBuf;

use host_compiler::spec::{self, Coords, InputSet, Shape, TimeDomain};

fn examples_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

#[test]
fn every_shipped_example_parses() {
    let mut specs = 0;
    let mut set_files = 0;
    for entry in std::fs::read_dir(examples_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if name.ends_with("-sets.toml") {
            let sets = spec::load_named_sets(&path).unwrap_or_else(|e| panic!("{}", e.headline()));
            assert!(!sets.is_empty(), "{name} has no sets");
            set_files += 1;
        } else {
            spec::load(&path).unwrap_or_else(|e| panic!("{}", e.headline()));
            specs += 1;
        }
    }
    assert!(
        specs >= 2,
        "expected at least the two task specs, found {specs}"
    );
    assert!(set_files >= 1);
}

#[test]
fn planar_vehicle_is_example_4_8() {
    let p = spec::load(examples_dir().join("planar-vehicle.toml")).unwrap();
    let pl = &p.plant;
    assert_eq!(pl.time, TimeDomain::Continuous);
    assert_eq!((pl.n(), pl.m(), pl.p()), (4, 2, 4));
    // Row-major: the velocity rows carry the spring −x and the anti-friction +0.1 v.
    assert_eq!(pl.A.get(2, 0), -1.0);
    assert_eq!(pl.A.get(3, 3), 0.1);
    assert_eq!(pl.A.get(0, 2), 1.0);
    assert_eq!(pl.offset, vec![0.0, 0.0, 1.0, 1.0]);
    // With the gain (3.14), K = −0.1 on the velocities, A + BK is the closed loop (4.19).
    let K = [[0.0, 0.0, -0.1, 0.0], [0.0, 0.0, 0.0, -0.1]];
    let cl = [
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [-1.0, 0.0, 0.0, 0.0],
        [0.0, -1.0, 0.0, 0.0],
    ];
    for (i, row) in cl.iter().enumerate() {
        for (j, &want) in row.iter().enumerate() {
            let bk: f64 = (0..2).map(|k| pl.B.get(i, k) * K[k][j]).sum();
            assert!((pl.A.get(i, j) + bk - want).abs() < 1e-15, "({i},{j})");
        }
    }
    assert_eq!(pl.period, 0.01);
    assert_eq!(p.horizon, 5.0);
    assert_eq!(p.horizon_steps(), 500);
    // Init (4.16): positions free in ±0.2, velocities pinned to (0, 1).
    assert_eq!(p.init.free_coords(), vec![0, 1]);
    assert_eq!(p.init.lo, vec![-0.2, -0.2, 0.0, 1.0]);
    assert_eq!(p.init.hi, vec![0.2, 0.2, 0.0, 1.0]);
    // Goal (4.18) and Unsafe (4.17) are discs in (x1, x2), whatever the velocity.
    assert_eq!(p.goal.coords, Coords::StateIndices(vec![0, 1]));
    assert!(p.goal.contains(&[2.05, 0.05, 3.0, -7.0]));
    assert!(!p.goal.contains(&[2.1, 0.1, 0.0, 0.0]));
    assert_eq!(p.unsafe_sets.len(), 1);
    assert!(p.unsafe_sets[0].contains(&[1.2, 0.8, 0.0, 1.0]));
    assert!(!p.unsafe_sets[0].contains(&[1.25, 0.75, 0.0, 1.0]));
    assert_eq!(
        p.input,
        InputSet::Ball {
            center: vec![0.0, 0.0],
            radius: 1.0
        }
    );
    assert!(p.mtl.is_none());
    // Geometry regions agree with the descriptions.
    let g = p.goal_region().unwrap();
    let u = p.unsafe_region().unwrap().unwrap();
    assert_eq!(g.dim(), 4);
    assert!(g.contains(&[2.05, 0.05, 3.0, -7.0]));
    assert!(u.contains(&[1.2, 0.8, 0.0, 1.0]));
    assert!(!u.contains(&[0.0, 0.0, 0.0, 1.0]));
}

#[test]
fn double_integrator_is_the_exact_zoh_of_the_continuous_one() {
    let p = spec::load(examples_dir().join("double-integrator.toml")).unwrap();
    let pl = &p.plant;
    let h = pl.period;
    assert_eq!(pl.time, TimeDomain::Discrete);
    // x⁺ = [[1, h], [0, 1]] x + [h²/2, h] u.
    assert_eq!(pl.A.data, vec![1.0, h, 0.0, 1.0]);
    assert!((pl.B.get(0, 0) - h * h / 2.0).abs() < 1e-15);
    assert!((pl.B.get(1, 0) - h).abs() < 1e-15);
    assert_eq!(p.horizon_steps(), 40);
    // Goal in output coordinates: the position only.
    assert!(matches!(p.goal.coords, Coords::Output { .. }));
    assert!(p.goal.contains(&[1.0, 5.0]));
    assert!(!p.goal.contains(&[0.9, 0.0]));
    // The wall is the half-plane velocity ≥ 1.5.
    assert!(p.unsafe_sets[0].contains(&[0.0, 1.6]));
    assert!(!p.unsafe_sets[0].contains(&[0.0, 1.4]));
    assert_eq!(p.synthesis, spec::SynthesisSettings::default());
    assert!(matches!(p.goal.shape, Shape::Box { .. }));
}

#[test]
fn named_sets_example_keeps_file_order_and_coordinates() {
    let sets = spec::load_named_sets(examples_dir().join("planar-vehicle-sets.toml")).unwrap();
    let names: Vec<&str> = sets.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["Obstacle", "Target", "Slow", "LowerHalf"]);
    let slow = &sets[2].1;
    assert_eq!(slow.coords, Coords::StateIndices(vec![2, 3]));
    assert!(slow.contains(&[9.0, 9.0, 1.0, -1.0]));
    assert!(!slow.contains(&[0.0, 0.0, 1.6, 0.0]));
    let r = sets[3].1.to_region(4).unwrap();
    assert!(r.contains(&[1.0, 0.0, 0.0, 0.0]));
    assert!(!r.contains(&[0.0, 0.0, 0.0, 0.0]));
    // A state of the wrong dimension for the named coordinates is an error, not a panic.
    assert!(sets[2].1.to_region(3).is_err());
}
