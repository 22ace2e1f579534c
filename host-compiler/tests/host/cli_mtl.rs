//! `synth` and `verify` on MTL specs (`[mtl] formula`, Problem 2.28): the waypoint example with a budget of
//! two balls certifies, re-proves and verifies an image and exits 3 (short of the coverage target);
//! `verify` re-proves it from its bytes and judges runs by the formula (exit 0), `--attack` finds no
//! violation on it and finds some once its balls are enlarged 20×; the same image against
//! another formula is refused (exit 1); a formula on a hybrid plant, and a predicate in time,
//! are bad input (exit 2) with the reason.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

fn example(name: &str) -> String {
    std::fs::read_to_string(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

#[test]
fn mtl_synth_then_verify() {
    let dir = std::env::temp_dir().join(format!("hc-cli-mtl-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = example("planar-vehicle-waypoints.toml")
        .replace("max_trajectories = 64", "max_trajectories = 2");
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, src).unwrap();
    let out = dir.join("out");
    let o = bin()
        .args(["synth", spec.to_str().unwrap(), "--out"])
        .arg(&out)
        .args(["--verify-runs", "64", "--quiet"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("re-proved         2 of 2 balls"),
        "{stdout}"
    );
    assert!(stdout.contains(", 0 violations"), "{stdout}");
    let img = out.join("controller.img");
    assert!(img.exists());
    crate::spec_fingerprint::assert_stamped(&img, &spec);
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("certificate.json")).unwrap())
            .unwrap();
    assert_eq!(cert["task"], "mtl");
    assert_eq!(cert["trajectories"].as_array().unwrap().len(), 2);
    assert!(
        cert["trajectories"][0]["certificate"]["delta"]
            .as_f64()
            .unwrap()
            > 0.0
    );

    let o = bin()
        .args(["verify", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--runs", "64", "--per-ball", "8"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    // Two balls cover part of the spec's Init: verified for their cover, short of the target (exit 3).
    assert_eq!(
        o.status.code(),
        Some(3),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("NOT met"), "{stdout}");
    assert!(
        stdout.contains("re-proved         2 of 2 balls"),
        "{stdout}"
    );
    assert!(stdout.contains(", 0 violations"), "{stdout}");
    // A line per stage on stderr as it starts, in order, with the seconds so far; none on stdout.
    let stderr = String::from_utf8_lossy(&o.stderr);
    let stages = [
        "re-proving 2 balls from the image's bytes (",
        "coverage of the spec's Init (",
        "Monte Carlo: 64 runs from the cover, 8 on each of 2 balls' boundary (",
    ];
    let at: Vec<Option<usize>> = stages.iter().map(|l| stderr.find(l)).collect();
    assert!(at.iter().all(Option::is_some) && at.is_sorted(), "{stderr}");
    assert!(!stdout.contains("Monte Carlo:"), "{stdout}");

    // The falsifier, scoring runs by the formula's robustness sampled finer: runs made, none violates.
    let attack = |img: &std::path::Path| {
        bin()
            .args(["verify", spec.to_str().unwrap(), img.to_str().unwrap()])
            .args([
                "--runs",
                "8",
                "--per-ball",
                "1",
                "--attack",
                "--attack-evals",
                "12",
            ])
            .arg("--json")
            .output()
            .unwrap()
    };
    let at = crate::verify_attack::attack_json(&attack(&img));
    assert!(at.worst_robustness > 0.0, "{at:?}");
    // Both balls enlarged 20× (CRC right): the falsifier finds runs that fail the formula, each with its
    // start, and the verification fails.
    let bytes = std::fs::read(&img).unwrap();
    let mut b = host_compiler::emit::ImageBuilder::from_image(
        &shared_types::image::decode(&bytes).unwrap(),
    );
    for t in &mut b.trajectories {
        t.delta *= 20.0;
    }
    let big = dir.join("big.img");
    std::fs::write(&big, b.to_bytes().unwrap()).unwrap();
    let o = attack(&big);
    assert_eq!(o.status.code(), Some(1));
    let at = crate::verify_attack::attack_of(&o);
    assert!(at.violations > 0, "{at:?}");
    assert!(at.worst_robustness.is_none_or(|w| w < 0.0), "{at:?}");
    assert_eq!(at.first_violations[0]["x0"].as_array().unwrap().len(), 4);

    // The same image against another formula (W2 first, within 1 s): its balls are not certified for it.
    let other = dir.join("other.toml");
    std::fs::write(
        &other,
        example("planar-vehicle-waypoints.toml").replace(
            "formula = \"G !Unsafe & F[0,2] (W1 & F[0,2.5] (W2 & F[0,2.5] Goal))\"",
            "formula = \"G !Unsafe & F[0,1] W2\"",
        ),
    )
    .unwrap();
    // Refused at once by its spec fingerprint (bad input) ...
    let o = bin()
        .args(["verify", other.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--runs", "64", "--per-ball", "8"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("[mtl] with [sets]"), "{stderr}");
    // ... and without the fingerprint, by the re-proof from the bytes (a failed check).
    let bare = crate::spec_fingerprint::without_fingerprint(&img);
    let o = bin()
        .args(["verify", other.to_str().unwrap(), bare.to_str().unwrap()])
        .args(["--runs", "64", "--per-ball", "8"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("not re-proved"), "{stderr}");
}

#[test]
fn mtl_refusals_name_the_reason() {
    let dir = std::env::temp_dir().join(format!("hc-cli-mtl-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        (
            // General switching with MTL is open in the text (§4.2.2); forced switching is synthesised.
            example("hybrid-internal-4-25.toml") + "\n[mtl]\nformula = \"F Goal\"\n",
            "internal switching",
        ),
        (
            example("planar-vehicle-waypoints.toml").replace(
                "formula = \"G !Unsafe",
                "formula = \"G[0,5] (x1 - t <= 3) & G !Unsafe",
            ),
            "involves time t",
        ),
        (
            example("planar-vehicle-waypoints.toml").replace("(W2 & F", "(W3 & F"),
            "unknown set `W3`",
        ),
    ];
    for (i, (src, why)) in cases.iter().enumerate() {
        let spec = dir.join(format!("bad{i}.toml"));
        std::fs::write(&spec, src).unwrap();
        let o = bin()
            .args(["synth", spec.to_str().unwrap(), "--out"])
            .arg(dir.join(format!("out{i}")))
            .arg("--quiet")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "case {i}: {stderr}");
        assert!(
            stderr.contains(why),
            "case {i}: expected `{why}` in {stderr}"
        );
    }
}
