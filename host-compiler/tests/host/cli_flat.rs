//! The differentially flat planar quadrotor (`examples/flat-quadrotor.toml`, §3.1.3) through the CLI, from
//! one initial state so that one run covers Init: `synth` certifies it over the hill with 0 violations on
//! the plant itself (the Monte Carlo reading q with the evaluator's controller states ζ), `verify`
//! re-proves the image, and `simulate` flies it into Goal with the thrust the extension computes.

fn example() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/flat-quadrotor.toml"
    ))
    .unwrap()
}

/// The example with each `from` (which must occur once) replaced by its `to`.
fn variant(edits: &[(&str, &str)]) -> String {
    let mut src = example();
    for (from, to) in edits {
        assert_eq!(src.matches(from).count(), 1, "`{from}` must occur once");
        src = src.replace(from, to);
    }
    src
}

/// The example from one initial state (-7, 0, 5, 0, 0, 0) with one trajectory and 3 iterations of §5.3,
/// synthesised and verified once for every test of the binary that needs it (its synthesis is the
/// suite's slowest): the directory, the spec and the image. Callers copy the image before changing it.
pub(crate) fn one_state() -> &'static (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    static ONCE: std::sync::OnceLock<(std::path::PathBuf, std::path::PathBuf, std::path::PathBuf)> =
        std::sync::OnceLock::new();
    ONCE.get_or_init(|| {
        let spec = variant(&[
            (
                "lo = [-7.25, 0.0, 4.75, 0.0, 0.0, 0.0]",
                "lo = [-7.0, 0.0, 5.0, 0.0, 0.0, 0.0]",
            ),
            (
                "hi = [-6.75, 0.0, 5.25, 0.0, 0.0, 0.0]",
                "hi = [-7.0, 0.0, 5.0, 0.0, 0.0, 0.0]",
            ),
            ("max_trajectories = 32", "max_trajectories = 1"),
            ("max_iterations = 20", "max_iterations = 3"),
        ]);
        crate::cli_fl::synth_then_verify(&spec, "flat-quadrotor")
    })
}

#[test]
fn the_quadrotor_from_one_state_is_certified_over_the_hill_and_flies_into_goal() {
    let (dir, spec, img) = one_state();
    let csv = dir.join("run.csv");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .args(["simulate", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--x0", "-7,0,5,0,0,0", "--out", csv.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("Goal reached"), "{stderr}");
    assert!(
        stderr.contains("0 steps out of the certified envelope"),
        "{stderr}"
    );
    // Columns t, X, Ẋ, Y, Ẏ, θ, θ̇, T, τ, status: the run rises over the hill's top (Y > 4 at |X| ≤ 2)
    // on a thrust that the controller's states move off hover.
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with('t'))
        .map(|l| l.split(',').take(9).map(|v| v.parse().unwrap()).collect())
        .collect();
    assert!(rows.len() > 800, "{} rows", rows.len());
    assert!(rows
        .iter()
        .filter(|r| r[1].abs() <= 2.0)
        .all(|r| r[3] > 4.0));
    let (tmin, tmax) = rows.iter().fold((f64::INFINITY, 0.0f64), |(a, b), r| {
        (a.min(r[7]), b.max(r[7]))
    });
    assert!(tmin < 9.7 && tmax > 9.9, "thrust within [{tmin}, {tmax}]");
}
