//! Accepted specs: optional parts (`[mtl]`, `[sets.*]`, `[synthesis]`, output maps, ellipsoids) are read
//! into the `Problem` as written, and set descriptions agree with the geometry regions built from them.
#![allow(non_snake_case)]

use host_compiler::spec::{self, ControllerMode, Coords, Matrix, SetDesc, Shape};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SPEC: &str = r#"
name = "features"
seed = 42
horizon = 1.0

[plant]
time = "discrete"
A = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.1], [0.0, 0.0, 1.0]]
B = [[0.0], [0.0], [0.1]]
period = 0.05
C = [[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]]

[init]
kind = "box"
lo = [-0.1, -0.1, 0.0]
hi = [0.1, 0.1, 0.0]

[goal]
kind = "ellipsoid"
center = [1.0, 0.0]
Q = [[4.0, 1.0], [1.0, 9.0]]
coords = "output"

[[unsafe]]
kind = "ball"
center = [0.5]
radius = 0.1
coords = ["y2"]

[[unsafe]]
kind = "polytope"
A = [[1.0, 0.0, 0.0]]
b = [-1.0]

[input]
kind = "ball"
center = [0.5]
radius = 2.0

[synthesis]
mode = "pwa"
confidence = 0.95
max_trajectories = 10

[mtl]
formula = "F[0,1] Goal & G !Wall"

[sets.Wall]
kind = "box"
lo = [2.0]
hi = [3.0]
coords = ["y1"]

[sets.Anywhere]
kind = "polytope"
A = [[0.0, 0.0, 1.0]]
b = [10.0]
"#;

#[test]
fn optional_parts_are_read_as_written() {
    let p = spec::parse(SPEC, "features.toml").unwrap_or_else(|e| panic!("{}", e.headline()));
    assert_eq!(p.name.as_deref(), Some("features"));
    assert_eq!(p.seed, 42);
    assert_eq!(p.plant.offset, vec![0.0; 3]); // g omitted
    assert_eq!(p.plant.p(), 2);
    assert_eq!(p.horizon_steps(), 20);
    assert_eq!(p.synthesis.mode, ControllerMode::Pwa);
    assert_eq!(p.synthesis.confidence, 0.95);
    assert_eq!(p.synthesis.max_trajectories, 10);
    // Unset settings keep their defaults.
    assert_eq!(
        p.synthesis.sigma_margin,
        spec::SynthesisSettings::default().sigma_margin
    );
    assert_eq!(p.mtl.as_deref(), Some("F[0,1] Goal & G !Wall"));
    let names: Vec<&str> = p.sets.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["Wall", "Anywhere"]);
    // y2 = x2 + x3: the selected row of C.
    match &p.unsafe_sets[0].coords {
        Coords::Output { C } => assert_eq!(
            C,
            &Matrix {
                rows: 1,
                cols: 3,
                data: vec![0.0, 1.0, 1.0]
            }
        ),
        other => panic!("{other:?}"),
    }
    assert!(p.unsafe_sets[0].contains(&[9.0, 0.2, 0.3]));
    assert!(!p.unsafe_sets[0].contains(&[0.0, 0.2, 0.5]));
    // Goal in output space: y = (x1, x2 + x3).
    assert!(p.goal.contains(&[1.0, 0.1, -0.1]));
    assert!(!p.goal.contains(&[1.0, 0.5, 0.0]));
    assert!(p.input.contains(&[2.4]) && !p.input.contains(&[-1.6]));
}

/// Random sets of every kind and every kind of coordinates: the description's membership and the geometry
/// region's membership agree at random points (skipping points within 1e-6 of the boundary).
#[test]
fn regions_agree_with_descriptions() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let n = 3;
    let mut checked = 0;
    for it in 0..120 {
        let (coords, d) = match it % 3 {
            0 => (Coords::State, n),
            1 => (Coords::StateIndices(vec![1, 2]), 2),
            _ => (
                Coords::Output {
                    C: Matrix {
                        rows: 2,
                        cols: 3,
                        data: vec![1.0, 0.5, 0.0, 0.0, 1.0, -1.0],
                    },
                },
                2,
            ),
        };
        let c: Vec<f64> = (0..d).map(|_| rng.random_range(-0.5..0.5)).collect();
        let shape = match (it / 3) % 4 {
            0 => Shape::Ball {
                center: c,
                radius: rng.random_range(0.2..1.0),
            },
            1 => {
                let L: Vec<f64> = (0..d * d).map(|_| rng.random_range(-1.0..1.0)).collect();
                let mut Q = Matrix::zeros(d, d);
                for i in 0..d {
                    for j in 0..d {
                        Q.data[i * d + j] =
                            (0..d).map(|k| L[i * d + k] * L[j * d + k]).sum::<f64>()
                                + if i == j { 0.5 } else { 0.0 };
                    }
                }
                Shape::Ellipsoid { center: c, Q }
            }
            2 => {
                let k = 4;
                let A = Matrix {
                    rows: k,
                    cols: d,
                    data: (0..k * d).map(|_| rng.random_range(-1.0..1.0)).collect(),
                };
                let b = (0..k).map(|_| rng.random_range(0.1..1.0)).collect();
                Shape::Polytope { A, b }
            }
            _ => Shape::Box {
                lo: c.iter().map(|v| v - 0.3).collect(),
                hi: c.iter().map(|v| v + 0.4).collect(),
            },
        };
        let set = SetDesc { shape, coords };
        let region = set
            .to_region(n)
            .unwrap_or_else(|e| panic!("{}", e.message()));
        assert_eq!(region.dim(), n);
        for _ in 0..200 {
            let x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.5..1.5)).collect();
            // Skip points near the boundary, where the two may differ by rounding.
            let near = (0..n).any(|i| {
                let mut a = x.clone();
                let mut b = x.clone();
                a[i] += 1e-6;
                b[i] -= 1e-6;
                set.contains(&a) != set.contains(&b)
            });
            if near {
                continue;
            }
            assert_eq!(set.contains(&x), region.contains(&x), "{set:?} at {x:?}");
            checked += 1;
        }
    }
    assert!(checked > 20_000);
}
