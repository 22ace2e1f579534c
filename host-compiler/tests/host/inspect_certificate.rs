//! `inspect --json` for independent checkers (issue 18): with the certificate `synth` wrote beside the
//! image (or given with `--certificate`) it adds the certified f64 δ, K and P, each trajectory's Goal
//! step, nominal states and f32 rounding bound; without one it says which items are missing and why; a
//! certificate of other bytes (an image altered after synthesis) is refused with exit 2 naming both files.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-inspect-cert-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The double integrator synthesised once by the CLI: its output directory (image and certificate).
fn synthesised() -> &'static Path {
    static OUT: OnceLock<PathBuf> = OnceLock::new();
    OUT.get_or_init(|| {
        let out = scratch("synth");
        let o = bin()
            .arg("synth")
            .arg(crate::verify_refuses::spec())
            .arg("--out")
            .arg(&out)
            .args(["--quiet", "--verify-runs", "50"])
            .output()
            .unwrap();
        assert!(
            matches!(o.status.code(), Some(0 | 3)),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        out
    })
}

fn inspect(img: &Path, extra: &[&str]) -> Output {
    bin()
        .arg("inspect")
        .arg(img)
        .arg("--json")
        .args(extra)
        .output()
        .unwrap()
}

fn json(o: &Output) -> Value {
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn the_certificate_beside_the_image_gives_the_checker_items() {
    let img = synthesised().join("controller.img");
    let j = json(&inspect(&img, &[]));
    let c = &j["certificate"];
    assert_eq!(c["status"], "present", "{c}");
    assert_eq!(c["task"], "reach_avoid");
    assert_eq!(c["missing"].as_array().unwrap().len(), 0, "{c}");
    let n = j["header"]["n"].as_u64().unwrap() as usize;
    // f64 K (m×n) and P (n×n).
    assert_eq!(c["P"].as_array().unwrap().len(), n);
    assert_eq!(c["K"][0].as_array().unwrap().len(), n);
    let trajs = c["trajectories"].as_array().unwrap();
    assert_eq!(
        trajs.len(),
        j["header"]["trajectories"].as_u64().unwrap() as usize
    );
    for t in trajs {
        let delta = t["delta"].as_f64().unwrap();
        let stored = t["delta_stored"].as_f64().unwrap();
        assert!(delta > 0.0 && stored <= delta * (1.0 + 1e-6), "{t}");
        assert_eq!(t["stored_radius_matches_image"], true, "{t}");
        let k = t["goal_step"].as_u64().unwrap() as usize;
        let nominal = t["nominal"].as_array().unwrap();
        assert!(nominal.len() > k, "{t}");
        assert_eq!(nominal[0].as_array().unwrap().len(), n);
        assert!(t["f32_error_bound"].as_f64().unwrap() > 0.0, "{t}");
    }
    // The same certificate named explicitly gives the same items.
    let cert = synthesised().join("certificate.json");
    let again = json(&inspect(&img, &["--certificate", cert.to_str().unwrap()]));
    assert_eq!(again["certificate"]["trajectories"], c["trajectories"]);
}

#[test]
fn without_a_certificate_the_missing_items_are_named() {
    let dir = scratch("absent");
    let img = dir.join("controller.img");
    std::fs::copy(synthesised().join("controller.img"), &img).unwrap();
    let j = json(&inspect(&img, &[]));
    let c = &j["certificate"];
    assert_eq!(c["status"], "absent", "{c}");
    assert!(
        c["why"].as_str().unwrap().contains("certificate.json"),
        "{c}"
    );
    let missing: Vec<&str> = c["missing"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .collect();
    for item in [
        "delta",
        "K and P",
        "goal_step",
        "nominal",
        "f32_error_bound",
    ] {
        assert!(missing.iter().any(|m| m.starts_with(item)), "{missing:?}");
    }
    // The image's own content is still all there.
    assert!(j["trajectories"].as_array().is_some_and(|t| !t.is_empty()));
    // A named certificate that does not exist is bad input naming it.
    let o = inspect(&img, &["--certificate", "/nonexistent/certificate.json"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent/certificate.json"));
}

#[test]
fn a_certificate_of_other_bytes_is_refused() {
    // The image with one radius enlarged (CRC made right), beside the original's certificate.
    let dir = scratch("mismatch");
    let bytes = std::fs::read(synthesised().join("controller.img")).unwrap();
    let img = shared_types::image::decode(&bytes).unwrap();
    let mut b = host_compiler::emit::ImageBuilder::from_image(&img);
    b.trajectories[0].delta *= 1.5;
    let altered = dir.join("controller.img");
    std::fs::write(&altered, b.to_bytes().unwrap()).unwrap();
    let cert = dir.join("certificate.json");
    std::fs::copy(synthesised().join("certificate.json"), &cert).unwrap();
    for extra in [&[][..], &["--certificate", cert.to_str().unwrap()][..]] {
        let o = inspect(&altered, extra);
        let stderr = String::from_utf8_lossy(&o.stderr).replace(['│', '\n'], " ");
        assert_eq!(o.status.code(), Some(2), "{stderr}");
        assert!(o.stdout.is_empty());
        let words: String = stderr.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(words.contains("is not the certificate of"), "{words}");
        assert!(words.contains("SHA"), "{words}");
        for f in [&cert, &altered] {
            let name = f.file_name().unwrap().to_string_lossy();
            assert!(words.contains(&*name), "{name} not named: {words}");
        }
    }
}
