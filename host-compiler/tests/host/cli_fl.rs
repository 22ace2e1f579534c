//! `synth` and `verify` on a feedback-linearizable spec (Example 4.9, `examples/fl-4-9.toml`): synthesis
//! covers Init, the image runs on the plant itself with no violation (exit 0), `verify` re-proves the radii
//! from the bytes and runs the plant again (exit 0), `--attack` searches the balls on the plant itself
//! with no violation, `simulate` runs the plant itself (CSV and verdict); what is not built for this
//! class (PWA mode) is bad input (exit 2) with the reason (`--import` is tested with the game,
//! `play_plants`), and the same image against a spec
//! whose plant turns faster (a/I = b/I = 1, so its mismatch bound is larger) is refused (exit 1).

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

fn example() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/fl-4-9.toml"
    ))
    .unwrap()
}

/// `synth` of `spec_text` (written to `<tmp>/hc-cli-<tag>-<pid>/spec.toml`) covers Init with 0
/// violations on the plant, and `verify` of its image re-proves the radii and runs the plant again with
/// none: the directory, the spec's path and the image's path.
pub(crate) fn synth_then_verify(
    spec_text: &str,
    tag: &str,
) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    let dir = std::env::temp_dir().join(format!("hc-cli-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, spec_text).unwrap();
    let out = dir.join("out");
    let o = bin()
        .args(["synth", spec.to_str().unwrap(), "--out"])
        .arg(&out)
        .args(["--verify-runs", "200", "--quiet"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stdout}\n{stderr}");
    assert!(stdout.contains("Init covered"), "{stdout}");
    assert!(stdout.contains(", 0 violations"), "{stdout}");
    let img = out.join("controller.img");
    assert!(img.exists());
    let o = verify(&spec, &img, &[]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("0 failing"), "{stdout}");
    assert!(stdout.contains("violations 0"), "{stdout}");
    (dir, spec, img)
}

/// `verify spec img --runs 100 --per-ball 4` and `extra`.
fn verify(spec: &std::path::Path, img: &std::path::Path, extra: &[&str]) -> std::process::Output {
    bin()
        .args(["verify", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--runs", "100", "--per-ball", "4"])
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn fl_synth_then_verify() {
    let (dir, spec, img) = synth_then_verify(&example(), "fl");
    let verify = |spec: &std::path::Path, extra: &[&str]| verify(spec, &img, extra);

    // The falsifier on the nonlinear plant itself: it ran, scored its runs and found nothing.
    let o = verify(&spec, &["--attack", "--attack-evals", "8", "--json"]);
    let at = crate::verify_attack::attack_json(&o);
    assert!(at.worst_robustness > 0.0, "{at:?}");

    // The whitened selection test the model-maps step selects with (section 13) is re-proved from the
    // bytes as well: the last trajectory's threshold enlarged ×4 (CRC recomputed) is refused, naming it.
    let bytes = std::fs::read(&img).unwrap();
    let decoded = shared_types::image::decode(&bytes).unwrap();
    let test = decoded
        .selection_test()
        .expect("a feedback-linearizable image carries the selection test");
    let t = decoded.n_trajectories() - 1;
    let body = test.body();
    let at = body.as_ptr() as usize - bytes.as_ptr() as usize + body.len() - 4;
    assert_eq!(
        f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()),
        test.threshold(decoded.n(), t)
    );
    let mut patched = bytes.clone();
    patched[at..at + 4].copy_from_slice(&(4.0 * test.threshold(decoded.n(), t)).to_le_bytes());
    let patched = crate::verify_refuses::write_patched("fl-threshold-x4.img", patched);
    let o = crate::cli_fl::verify(&spec, &patched, &[]);
    let out = crate::verify_refuses::text(&o);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains(&format!(
            "trajectory {t}: its whitened selection test accepts states"
        )),
        "{out}"
    );

    // A faster-turning vehicle: refused at once by the spec fingerprint ...
    let faster = dir.join("faster.toml");
    std::fs::write(
        &faster,
        example().replace(
            "params = { aI = 0.1, bI = 0.1 }",
            "params = { aI = 0.2, bI = 0.2 }",
        ),
    )
    .unwrap();
    let o = verify(&faster, &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("[plant]"), "{stderr}");
    // ... and without the fingerprint, because its larger mismatch does not certify the stored radii.
    let bare = crate::spec_fingerprint::without_fingerprint(&img);
    let o = bin()
        .args(["verify", faster.to_str().unwrap(), bare.to_str().unwrap()])
        .args(["--runs", "100", "--per-ball", "4"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("certificate failure"), "{stdout}");

    // `simulate` runs the plant itself through the image's maps: a CSV of the plant's states and
    // inputs, and a verdict judged in ξ.
    let o = bin()
        .args(["simulate", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--x0", "0,0,0,1,0,0"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    let mut lines = stdout.lines();
    assert_eq!(lines.next(), Some("# x0 = 0, 0, 0, 1, 0, 0"));
    assert_eq!(lines.next(), Some("t,x1,x2,x3,x4,x5,x6,u1,u2,status"));
    assert!(lines.all(|l| l.ends_with(",ok")), "{stdout}");
    assert!(stderr.contains("verdict: Goal reached at step"), "{stderr}");
    assert!(
        stderr.contains("0 steps out of the certified envelope"),
        "{stderr}"
    );
    assert!(
        stderr.contains("0 inputs outside the input set"),
        "{stderr}"
    );
    let o = bin()
        .args(["simulate", spec.to_str().unwrap(), img.to_str().unwrap()])
        .args(["--x0", "0,0,0,1"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("the plant has n = 6"));

    let pwa = dir.join("pwa.toml");
    std::fs::write(
        &pwa,
        example().replace("[synthesis]\n", "[synthesis]\nmode = \"pwa\"\n"),
    )
    .unwrap();
    let o = bin()
        .args(["synth", pwa.to_str().unwrap(), "--out"])
        .arg(dir.join("out-pwa"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("pwa"));
    let _ = std::fs::remove_dir_all(&dir);
}
