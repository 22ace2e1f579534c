//! One CSV dialect for the tools (issue 18): a run `simulate` writes is read as it is by `mtl` (a trace)
//! and by `synth --import` (a recording whose reference inputs certify), also with a byte-order mark
//! and comment lines added.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

/// The command ended with status 0.
fn ok(o: std::process::Output, what: &str) {
    assert_eq!(
        o.status.code(),
        Some(0),
        "{what}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn a_simulated_run_is_imported_and_monitored_as_written() {
    let dir = std::env::temp_dir().join(format!("hc-csv-dialect-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    );
    let out = dir.join("out");
    ok(
        bin()
            .args(["synth", spec, "--out"])
            .arg(&out)
            .args(["--quiet", "--verify-runs", "100"])
            .output()
            .unwrap(),
        "synth",
    );
    let run = dir.join("run.csv");
    ok(
        bin()
            .args(["simulate", spec])
            .arg(out.join("controller.img"))
            .args(["--x0", "0.03,0", "--out"])
            .arg(&run)
            .output()
            .unwrap(),
        "simulate",
    );
    // The same run with a byte-order mark and a comment in the middle.
    let text = std::fs::read_to_string(&run).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    lines.insert(5, "# a note between rows");
    let marked = dir.join("marked.csv");
    std::fs::write(&marked, format!("\u{feff}{}\n", lines.join("\n"))).unwrap();
    for file in [&run, &marked] {
        ok(
            bin()
                .args(["mtl", "--formula", "F[0,4] x1 >= 0.95", "--trace"])
                .arg(file)
                .output()
                .unwrap(),
            &format!("mtl {}", file.display()),
        );
        let out2 = dir.join("imported");
        ok(
            bin()
                .args(["synth", spec, "--out"])
                .arg(&out2)
                .args(["--quiet", "--verify-runs", "100", "--import"])
                .arg(file)
                .output()
                .unwrap(),
            &format!("import {}", file.display()),
        );
        let cert: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out2.join("certificate.json")).unwrap())
                .unwrap();
        let first = &cert["trajectories"][0];
        assert!(
            first["source"].to_string().contains(".csv"),
            "the first trajectory is not the import: {first}"
        );
        let x0: Vec<f64> = serde_json::from_value(first["x0"].clone()).unwrap();
        assert!((x0[0] - 0.03).abs() < 1e-6 && x0[1] == 0.0, "{x0:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
