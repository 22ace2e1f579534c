//! Host image emission: ImageBuilder → bytes → decode → ImageBuilder round trips, the (3.6) table
//! construction checked through the shared evaluator, every refusal with its message, and `inspect`.
#![allow(non_snake_case)]

use host_compiler::cli::inspect::{render, InspectError};
use host_compiler::emit::{EmitError, FallbackLaw, ImageBuilder, Terminal, TrajectoryEntry};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use shared_types::capacity::{MAX_STEPS, MAX_TRAJECTORIES};
use shared_types::eval::Controller;
use shared_types::image::{decode, ImageError};

/// A two-location, three-trajectory builder with values exactly representable in f32.
fn builder() -> ImageBuilder {
    let mut b = ImageBuilder::new(2, 1, 0.05);
    b.add_location(vec![-1.0, -0.5], vec![2.0, 0.25, 0.25, 1.0]);
    b.add_location(vec![-2.0, 0.0], vec![1.0, 0.0, 0.0, 1.0]);
    b.add_trajectory(TrajectoryEntry {
        x0: vec![0.0, 0.0],
        delta: 0.5,
        v: vec![1.0, 2.0, 3.0],
        location: vec![0, 0, 1],
    });
    b.add_trajectory(TrajectoryEntry {
        x0: vec![1.0, -1.0],
        delta: 0.75,
        v: vec![4.0],
        location: vec![1],
    });
    b.fallback = FallbackLaw::Linear {
        K: vec![-0.5, -0.5],
        x_ref: vec![0.0, 0.0],
        u_ref: vec![0.0],
    };
    b.input_box = Some((vec![-2.0], vec![2.0]));
    b.terminal = Terminal::Fallback;
    b
}

#[test]
fn round_trip_through_bytes_is_exact_and_canonical() {
    let b = builder();
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    let back = ImageBuilder::from_image(&img);
    assert_eq!(back.period, 0.05f32 as f64);
    let mut expect = b.clone();
    expect.period = 0.05f32 as f64;
    assert_eq!(back, expect);
    assert_eq!(back.to_bytes().unwrap(), bytes);
}

#[test]
fn random_builders_round_trip() {
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    for _ in 0..100 {
        let n = rng.random_range(1..=12);
        let m = rng.random_range(1..=6);
        let mut b = ImageBuilder::new(n, m, rng.random_range(0.001..0.5));
        let nl = rng.random_range(1..=3);
        for _ in 0..nl {
            let K: Vec<f64> = (0..m * n).map(|_| rng.random_range(-5.0..5.0)).collect();
            // Diagonally dominant, symmetric: positive definite.
            let mut P = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..i {
                    let x: f64 = rng.random_range(-0.1..0.1);
                    P[i * n + j] = x;
                    P[j * n + i] = x;
                }
                P[i * n + i] = 1.0 + n as f64 * 0.1 + rng.random_range(0.0..1.0);
            }
            b.add_location(K, P);
        }
        for _ in 0..rng.random_range(1..=10) {
            let len = rng.random_range(1..=30);
            b.add_trajectory(TrajectoryEntry {
                x0: (0..n).map(|_| rng.random_range(-3.0..3.0)).collect(),
                delta: rng.random_range(0.0..2.0),
                v: (0..len * m)
                    .map(|_| rng.random_range(-10.0..10.0))
                    .collect(),
                location: (0..len).map(|_| rng.random_range(0..nl as u8)).collect(),
            });
        }
        let bytes = b.to_bytes().unwrap();
        let img = decode(&bytes).unwrap();
        let back = ImageBuilder::from_image(&img);
        // Every value is the f32 nearest the f64 one, except δ, which is rounded down.
        for (l0, l1) in b.locations.iter().zip(&back.locations) {
            for (x, y) in l0.K.iter().zip(&l1.K).chain(l0.P.iter().zip(&l1.P)) {
                assert_eq!(*y, *x as f32 as f64);
            }
        }
        for (t0, t1) in b.trajectories.iter().zip(&back.trajectories) {
            assert!(t1.delta <= t0.delta);
            assert!(t0.delta - t1.delta <= t0.delta * f64::from(f32::EPSILON));
            assert_eq!(t0.location, t1.location);
            for (x, y) in t0.v.iter().zip(&t1.v).chain(t0.x0.iter().zip(&t1.x0)) {
                assert_eq!(*y, *x as f32 as f64);
            }
        }
        assert_eq!(back.to_bytes().unwrap(), bytes);
    }
}

#[test]
fn delta_is_rounded_down_never_up() {
    // 0.1 rounds up to nearest f32 (0.100000001490116...); the stored radius must be below 0.1.
    let mut b = builder();
    b.trajectories[0].delta = 0.1;
    assert!((0.1f32 as f64) > 0.1);
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    let d = img.delta(0) as f64;
    assert!(d <= 0.1);
    assert_eq!(d, (0.1f32).next_down() as f64);
    // An exactly representable radius is kept.
    assert_eq!(img.delta(1), 0.75);
}

#[test]
fn nominal_trajectory_reproduces_nominal_input() {
    // (3.6): v = ũ − K x̃, so on the nominal states the law (3.5) gives back ũ (up to f32 rounding).
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (n, m, len) = (4, 2, 50);
    let mut b = ImageBuilder::new(n, m, 0.01);
    let K0: Vec<f64> = (0..m * n).map(|_| rng.random_range(-2.0..2.0)).collect();
    let K1: Vec<f64> = (0..m * n).map(|_| rng.random_range(-2.0..2.0)).collect();
    let I: Vec<f64> = (0..n * n)
        .map(|i| if i % (n + 1) == 0 { 1.0 } else { 0.0 })
        .collect();
    b.add_location(K0, I.clone());
    b.add_location(K1, I);
    let x_nom: Vec<f64> = (0..len * n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let u_nom: Vec<f64> = (0..len * m).map(|_| rng.random_range(-1.0..1.0)).collect();
    let location: Vec<u8> = (0..len).map(|k| u8::from(k >= 20)).collect();
    assert_eq!(
        b.add_nominal_trajectory(&x_nom, &u_nom, &location, 0.2)
            .unwrap(),
        0
    );
    let bytes = b.to_bytes().unwrap();
    let img = decode(&bytes).unwrap();
    let mut ctl = Controller::new(img);
    for k in 0..len {
        let x: Vec<f32> = x_nom[k * n..(k + 1) * n]
            .iter()
            .map(|&v| v as f32)
            .collect();
        let u = ctl.step(&x).unwrap();
        assert_eq!(ctl.active_trajectory(), Some(0));
        for j in 0..m {
            let err = (u.as_slice()[j] as f64 - u_nom[k * m + j]).abs();
            assert!(err < 1e-5, "step {k} input {j}: error {err}");
        }
    }
    // Shapes are checked.
    assert!(matches!(
        b.add_nominal_trajectory(&x_nom[..n], &u_nom, &location, 0.2),
        Err(EmitError::Shape { .. })
    ));
    assert!(matches!(
        b.add_nominal_trajectory(&x_nom[..n], &u_nom[..m], &[7], 0.2),
        Err(EmitError::Invalid { .. })
    ));
}

fn err(b: &ImageBuilder) -> String {
    b.to_bytes().expect_err("should be refused").to_string()
}

#[test]
fn refusals_say_what_is_wrong() {
    let mut b = builder();
    b.trajectories[1].v[0] = f64::NAN;
    assert_eq!(err(&b), "trajectory 1 step 0: v[0] is not finite (NaN)");

    let mut b = builder();
    b.locations[0].K[1] = 1e39;
    assert_eq!(err(&b), "location 0: K[1] = 1e39 is outside the f32 range");

    let mut b = builder();
    b.trajectories[0].delta = -1.0;
    assert_eq!(err(&b), "trajectory 0: delta is negative");

    let mut b = builder();
    b.trajectories[0].location[2] = 2;
    assert_eq!(err(&b), "trajectory 0 step 2: location 2 does not exist");

    let mut b = builder();
    b.locations[1].P = vec![1.0, 2.0, 2.0, 1.0];
    assert!(matches!(
        b.to_bytes(),
        Err(EmitError::Rejected(ImageError::NotPositiveDefinite {
            location: 1
        }))
    ));
    assert_eq!(
        err(&b),
        "image validation failed: location 1: P is not positive definite"
    );

    let mut b = builder();
    b.trajectories[0].v.pop();
    assert_eq!(err(&b), "trajectory 0: v: expected 3 values, found 2");

    let mut b = builder();
    b.n = 13;
    assert_eq!(
        err(&b),
        "state dimension n is 13, allowed 1..=12 (image capacity)"
    );

    let mut b = builder();
    for _ in 0..MAX_TRAJECTORIES {
        let t = b.trajectories[1].clone();
        b.add_trajectory(t);
    }
    assert_eq!(
        err(&b),
        format!(
            "number of trajectories is {}, allowed 1..={MAX_TRAJECTORIES} (image capacity)",
            MAX_TRAJECTORIES + 2
        )
    );

    let mut b = builder();
    b.trajectories[0].v = vec![0.0; MAX_STEPS];
    b.trajectories[0].location = vec![0; MAX_STEPS];
    assert_eq!(
        err(&b),
        format!(
            "total table rows is {}, allowed 1..={MAX_STEPS} (image capacity)",
            MAX_STEPS + 1
        )
    );

    let mut b = builder();
    b.input_box = Some((vec![1.0], vec![0.0]));
    assert_eq!(
        err(&b),
        "input box component 0 has its lower bound above its upper bound"
    );

    let mut b = builder();
    b.period = 0.0;
    assert_eq!(err(&b), "sample period is not positive");

    let mut b = builder();
    b.locations.clear();
    assert_eq!(
        err(&b),
        "number of locations is 0, allowed 1..=8 (image capacity)"
    );
}

#[test]
fn write_creates_the_file_inspect_reads() {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("emit_image_example.img");
    let bytes = builder().write(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    let bad = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("no/such/dir/x.img");
    assert!(matches!(builder().write(&bad), Err(EmitError::Io { .. })));
}

#[test]
fn inspect_json_contains_the_whole_content() {
    let bytes = builder().to_bytes().unwrap();
    let out = render(&bytes, "x.img", true).unwrap();
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j["header"]["magic"], "SFCI");
    assert_eq!(j["header"]["mode"], "feedforward");
    assert_eq!(j["header"]["n"], 2);
    assert_eq!(j["header"]["size"], bytes.len());
    let crc = u32::from_le_bytes(bytes[28..32].try_into().unwrap());
    assert_eq!(j["header"]["crc"], format!("{crc:#010x}"));
    assert_eq!(j["header"]["period"].as_f64().unwrap(), 0.05);
    assert_eq!(j["locations"][0]["K"], serde_json::json!([[-1.0, -0.5]]));
    assert_eq!(
        j["locations"][0]["P"],
        serde_json::json!([[2.0, 0.25], [0.25, 1.0]])
    );
    assert_eq!(
        j["trajectories"][0]["v"],
        serde_json::json!([[1.0], [2.0], [3.0]])
    );
    assert_eq!(
        j["trajectories"][0]["location"],
        serde_json::json!([0, 0, 1])
    );
    assert_eq!(
        j["trajectories"][1]["centre"],
        serde_json::json!([1.0, -1.0])
    );
    assert_eq!(j["trajectories"][1]["delta"], 0.75);
    assert_eq!(j["trajectories"][1]["first_row"], 3);
    assert_eq!(j["fallback"]["kind"], "linear");
    assert_eq!(j["fallback"]["K"], serde_json::json!([[-0.5, -0.5]]));
    assert_eq!(j["input_box"]["hi"], serde_json::json!([2.0]));
    assert_eq!(j["terminal"], "fallback");
    assert_eq!(j["total_steps"], 4);

    let text = render(&bytes, "x.img", false).unwrap();
    assert!(
        text.starts_with(&format!(
            "x.img: valid controller image, {} bytes",
            bytes.len()
        )),
        "{text}"
    );
    assert!(
        text.contains("trajectory 1: ball centre [1, -1], delta 0.75, 1 steps (rows 3..4)"),
        "{text}"
    );
    assert!(
        text.contains("fallback: u = K_fb (x - x_ref) + u_ref, saturated to the input box"),
        "{text}"
    );
}

#[test]
fn inspect_explains_rejection() {
    let mut bytes = builder().to_bytes().unwrap();
    let stored = u32::from_le_bytes(bytes[28..32].try_into().unwrap());
    let last = bytes.len() - 1;
    bytes[last] ^= 0xff;
    let e = render(&bytes, "bad.img", false).unwrap_err();
    let computed = shared_types::image::compute_crc(&bytes).unwrap();
    assert_eq!(
        e.to_string(),
        format!("bad.img: image rejected: CRC mismatch: header says {stored:#010x}, content has {computed:#010x}")
    );
    let InspectError::Rejected {
        header: Some(h), ..
    } = e
    else {
        panic!("header summary expected")
    };
    assert!(h.contains("n 2, m 1, locations 2, trajectories 2"), "{h}");

    let e = render(b"not an image", "junk", true).unwrap_err();
    assert_eq!(
        e.to_string(),
        "junk: image rejected: truncated: 12 bytes, shorter than the 32-byte header"
    );
}
