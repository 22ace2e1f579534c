//! `synth` and `verify` on hybrid specs (Example 4.25, internal switching, and the forced cart, each with a
//! budget of one run): synth certifies,
//! re-proves and verifies an image, writes its report, and exits 3 (short of the coverage target); verify re-proves the
//! same image from its bytes and runs it against the exact hybrid flow (exit 0), `--attack` searches its
//! ball on that flow with no violation, and `verify` refuses an image
//! whose stored radius was enlarged (exit 1).

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

#[test]
fn hybrid_synth_then_verify() {
    let (dir, spec, out) = synth_one_run("hybrid", "hybrid-internal-4-25.toml", 16);
    let img = out.join("controller.img");
    assert!(img.exists());
    crate::spec_fingerprint::assert_stamped(&img, &spec);
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("certificate.json")).unwrap())
            .unwrap();
    assert_eq!(cert["runs"].as_array().unwrap().len(), 1);
    // The report: the verdict, the automaton with its identity resets, a plane per other coordinate
    // paired with the guard's x1, and the run's two segments with what binds each.
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        page.contains("<h1>Certified and verified</h1>"),
        "{page:.400}"
    );
    assert!(page.contains("left → right") && page.contains("identity"));
    assert_eq!(
        page.matches("<svg").count(),
        4,
        "planes (x1, x2) and (x1, x3), each for the runs and for the cover of Init"
    );
    assert!(
        page.contains("\nx3\n</text>"),
        "the second plane's axis label"
    );
    let delta = cert["runs"][0]["certificate"]["segments"][0]["delta"]
        .as_f64()
        .unwrap();
    assert!(
        page.contains(&format!(
            "<td>{}</td>",
            host_compiler::report::format::num(delta)
        )),
        "the table shows segment 0's δ {delta}"
    );
    assert!(page.contains("Theorem 4.7 (Goal, Unsafe, Input)"));
    // Where the cover came from (Figure 5.5's manner): the one run is the planner's, its ball above δε,
    // and the segments table names its origin.
    let legend = page
        .split("<p id=\"cover-origins\">")
        .nth(1)
        .and_then(|t| t.split("</p>").next())
        .expect("the cover's origin legend");
    assert!(
        legend.contains("the planner from a seed: 1") && !legend.contains("Algorithm 4 ("),
        "{legend}"
    );
    assert!(
        legend.contains("0 of 1 balls have a radius below δε"),
        "{legend}"
    );
    assert!(
        page.contains("<th>origin</th>")
            && page.contains("<td class=l>generated (SCP) + §5.3</td>")
    );
    assert_eq!(cert["runs"][0]["source"], "generated (SCP) + §5.3");

    verify_attack_and_enlarged_radius(&dir, &spec, &img);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Forced switching (§4.2.1) on the cart example with a budget of one run: the run switches from
/// `forward` to `backward` by its table, is re-proved from the bytes and verified on the automaton with
/// the controller's location as its discrete input; `verify` and its falsifier agree; an enlarged radius
/// is refused.
#[test]
fn hybrid_forced_synth_then_verify() {
    let (dir, spec, out) = synth_one_run("forced", "hybrid-forced-cart.toml", 64);
    // Every Monte Carlo run took the forced switch.
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("certificate.json")).unwrap())
            .unwrap();
    assert_eq!(cert["switching"], "forced");
    let run = &cert["runs"][0];
    assert_eq!(run["locations"], serde_json::json!(["forward", "backward"]));
    let segs = run["certificate"]["segments"].as_array().unwrap();
    assert_eq!(segs.len(), 2);
    assert!(segs[0]["delta"].as_f64().unwrap() > 0.0);
    assert_eq!(
        cert["verify"]["switched"], cert["verify"]["runs"],
        "{}",
        cert["verify"]
    );
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(page.contains("<h1>Certified and verified</h1>"));
    assert!(page.contains("forced (the controller's choice)") && page.contains("the whole space"));
    assert!(page.contains("Theorem 4.17"));

    let img = out.join("controller.img");
    verify_attack_and_enlarged_radius(&dir, &spec, &img);
    let bytes = std::fs::read(&img).unwrap();
    let decoded = shared_types::image::decode(&bytes).unwrap();
    // The same image without its switch (every row in `forward`): the run no longer re-proves.
    let mut b = host_compiler::emit::ImageBuilder::from_image(&decoded);
    for l in b.trajectories[0].location.iter_mut() {
        *l = 0;
    }
    let flat = dir.join("flat.img");
    std::fs::write(&flat, b.to_bytes().unwrap()).unwrap();
    let o = bin()
        .args(["verify", spec.to_str().unwrap(), flat.to_str().unwrap()])
        .args(["--runs", "16", "--per-ball", "1"])
        .output()
        .unwrap();
    assert_ne!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// An MTL task with forced switching (Def 4.18) on the cart: the run is certified for the formula (its
/// segments bound by it), re-proved from the bytes by the same certificate and verified by the formula as
/// written; `verify` and its falsifier agree; an enlarged radius is refused.
#[test]
fn hybrid_forced_mtl_synth_then_verify() {
    let (dir, spec, out) = synth_one_run("forced-mtl", "hybrid-forced-cart-mtl.toml", 64);
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("certificate.json")).unwrap())
            .unwrap();
    assert_eq!(cert["switching"], "forced");
    let segs = cert["runs"][0]["certificate"]["segments"]
        .as_array()
        .unwrap();
    assert!(
        segs.iter()
            .any(|s| s["binding"] == "the formula (Def 4.18)"),
        "{segs:?}"
    );
    assert_eq!(cert["verify"]["violations"], 0, "{}", cert["verify"]);
    let img = out.join("controller.img");
    verify_attack_and_enlarged_radius(&dir, &spec, &img);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `verify` re-proves the image's one run from its bytes and runs it on the exact hybrid flow, with no
/// violation; one run covers part of Init, so the image's coverage of the spec's Init is short of the
/// target (exit 3, as `synth`'s); the falsifier on that flow finds no violation; the run's stored radius
/// enlarged by 1 % (the CRC made right again) is not re-proved (exit 1).
fn verify_attack_and_enlarged_radius(
    dir: &std::path::Path,
    spec: &std::path::Path,
    img: &std::path::Path,
) {
    let o = bin()
        .args(["verify", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--runs", "16", "--per-ball", "4"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(3),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("re-proved         1 of 1 runs"), "{stdout}");
    assert!(stdout.contains(", 0 violations"), "{stdout}");
    assert!(stdout.contains("NOT met)"), "{stdout}");
    let o = bin()
        .args(["verify", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args([
            "--runs",
            "4",
            "--per-ball",
            "1",
            "--attack",
            "--attack-evals",
            "12",
        ])
        .arg("--json")
        .output()
        .unwrap();
    let at = crate::verify_attack::attack_json(&o);
    assert!(at.worst_robustness > 0.0, "{at:?}");
    let bytes = std::fs::read(img).unwrap();
    let decoded = shared_types::image::decode(&bytes).unwrap();
    let mut b = host_compiler::emit::ImageBuilder::from_image(&decoded);
    b.trajectories[0].delta *= 1.01;
    let big = dir.join("big.img");
    std::fs::write(&big, b.to_bytes().unwrap()).unwrap();
    let o = bin()
        .args(["verify", spec.to_str().unwrap(), big.to_str().unwrap()])
        .args(["--runs", "4", "--per-ball", "1"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("not re-proved"), "{stderr}");
}

/// `synth` of the shipped `example` with a budget of one run into a fresh directory, with
/// `verify_runs` Monte Carlo runs: exit 3 (short of the coverage target), the run re-proved from the
/// bytes, 0 violations. Returns the directory, the spec written there and the out directory.
fn synth_one_run(
    tag: &str,
    example: &str,
    verify_runs: usize,
) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("hc-cli-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = format!("{}/../examples/{example}", env!("CARGO_MANIFEST_DIR"));
    let src = std::fs::read_to_string(path).unwrap();
    let budget = src
        .lines()
        .find(|l| l.starts_with("max_trajectories"))
        .expect("the example states its budget")
        .to_string();
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, src.replace(&budget, "max_trajectories = 1")).unwrap();
    let out = dir.join("out");
    let o = bin()
        .args([
            "synth",
            spec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(["--verify-runs", &verify_runs.to_string(), "--quiet"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{stdout}\n{stderr}");
    assert!(stdout.contains("re-proved         1 of 1 runs"), "{stdout}");
    assert!(stdout.contains(", 0 violations"), "{stdout}");
    (dir, spec, out)
}
