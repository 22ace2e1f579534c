//! The `synth`, `verify`, `simulate` and `inspect` commands on the shipped double-integrator example, run as
//! a user runs them.

use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

#[test]
fn synth_then_verify_simulate_and_inspect() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    );
    let out = std::env::temp_dir().join(format!("hc-cli-synth-{}", std::process::id()));
    let o = bin()
        .args(["synth", spec, "--out"])
        .arg(&out)
        .args(["--quiet", "--verify-runs", "500"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "synth failed: {stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("0 violations"), "{stdout}");
    for f in ["controller.img", "report.html", "certificate.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("<svg"));
    // Algorithm 4 by default: the report shows its optimisations and the cover after each round.
    for id in [
        "optimization",
        "delta-history",
        "tube-before-after",
        "optimization-table",
    ] {
        assert!(html.contains(&format!("id=\"{id}\"")), "report lacks {id}");
    }
    assert!(html.contains("class=\"frame\""));
    let img = out.join("controller.img");

    let o = bin()
        .args(["verify", spec])
        .arg(&img)
        .args(["--runs", "500"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "verify failed: {stdout}");
    assert!(
        stdout.lines().any(|l| l.trim() == "violations 0"),
        "{stdout}"
    );

    let o = bin()
        .args(["simulate", spec])
        .arg(&img)
        .args(["--x0", "0.05,0"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = String::from_utf8_lossy(&o.stdout);
    let all: Vec<&str> = csv.lines().collect();
    assert_eq!(all[0], "# x0 = 0.05, 0");
    let lines = &all[1..];
    assert_eq!(lines[0], "t,x1,x2,u1,v1,status");
    assert_eq!(lines.len(), 1 + 41, "header + horizon 4 s / 0.1 s + 1 rows");
    let last: Vec<&str> = lines.last().unwrap().split(',').collect();
    let x1: f64 = last[1].parse().unwrap();
    assert!(
        (0.95..=1.05).contains(&x1)
            || lines.iter().any(|l| {
                l.split(',')
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
                    .is_some_and(|v| (0.95..=1.05).contains(&v))
            }),
        "never reached the goal: {csv}"
    );
    assert!(lines[1..].iter().all(|l| l.ends_with(",ok")), "{csv}");
    // The CSV is a trace `mtl` reads as it is: the status column is skipped.
    let trace = host_compiler::robustness::mtl::Trace::from_csv_str(&csv, "simulate").unwrap();
    assert_eq!(trace.len(), 41);
    assert_eq!(trace.names(), ["x1", "x2", "u1", "v1"]);
    // The verdict on standard error agrees with the CSV: Goal reached at the first row inside the goal
    // box, nothing out of the envelope, a positive robustness.
    let err = String::from_utf8_lossy(&o.stderr);
    let first_in_goal = lines[1..]
        .iter()
        .position(|l| {
            l.split(',')
                .nth(1)
                .and_then(|v| v.parse::<f64>().ok())
                .is_some_and(|v| (0.95..=1.05).contains(&v))
        })
        .unwrap();
    assert!(
        err.contains(&format!("Goal reached at step {first_in_goal} ")),
        "{err}"
    );
    assert!(
        err.contains(" 0 steps out of the certified envelope"),
        "{err}"
    );
    let rho: f64 = err
        .rsplit("robustness of the samples ")
        .next()
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert!(rho > 0.0, "{err}");

    // An initial state outside every ball: the evaluator says so and the fallback is applied.
    let o = bin()
        .args(["simulate", spec])
        .arg(&img)
        .args(["--x0", "5,0", "--steps", "2"])
        .output()
        .unwrap();
    let csv = String::from_utf8_lossy(&o.stdout);
    assert!(
        csv.lines().nth(2).unwrap().ends_with("out-of-envelope") || csv.contains("envelope"),
        "{csv}"
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("3 steps out of the certified envelope"),
        "{err}"
    );
    assert!(err.contains("Goal not reached"), "{err}");

    let o = bin()
        .args(["inspect", "--json"])
        .arg(&img)
        .output()
        .unwrap();
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(j.is_object());

    // Bad input: wrong x0 length gets a clear error, not a panic.
    let o = bin()
        .args(["simulate", spec])
        .arg(&img)
        .args(["--x0", "1,2,3"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "bad input");
    assert!(String::from_utf8_lossy(&o.stderr).contains("--x0 has 3 values"));
    let _ = std::fs::remove_dir_all(&out);
}

/// Ctrl-C (SIGINT) during the growth loop: the run stops cleanly, exits non-zero saying it was
/// interrupted, and the image it wrote holds what was certified and passes `verify` with 0 violations.
#[test]
fn sigint_keeps_a_valid_verified_image() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    );
    let out = std::env::temp_dir().join(format!("hc-cli-sigint-{}", std::process::id()));
    let mut child = bin()
        .args(["synth", spec, "--out"])
        .arg(&out)
        .args(["--verify-runs", "300"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for the first certified trajectory (logged on stderr when it is not a terminal), then interrupt.
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        assert!(
            err.read_line(&mut line).unwrap() > 0,
            "synth ended before certifying a trajectory: {seen}"
        );
        seen.push_str(&line);
        if line.starts_with("certified trajectory 1") {
            break;
        }
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).unwrap();
    let o = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(130),
        "an interrupted run exits with 130"
    );
    assert!(rest.contains("interrupted"), "{rest}");
    // The stages after the cover each announce themselves on stderr, in order, with the seconds so far.
    let at = |l: &str| rest.find(l);
    let (mc, fal) = (
        at("verification: Monte Carlo of 300 runs from the cover, 32 on each of "),
        at("falsifier: a search for the least robust run over every ball ("),
    );
    assert!(mc.is_some() && fal.is_some() && mc < fal, "{rest}");
    assert!(!stdout.contains("verification: Monte Carlo"), "{stdout}");
    assert!(
        stdout.contains("interrupted: the image holds the"),
        "{stdout}"
    );
    assert!(stdout.contains(", 0 violations"), "{stdout}");
    for f in ["controller.img", "report.html", "certificate.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let o = bin()
        .args(["verify", spec])
        .arg(out.join("controller.img"))
        .args(["--runs", "300"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    // The interrupted cover is verified for what it covers; short of the target the status is 3.
    match o.status.code() {
        Some(0) => {}
        Some(3) => assert!(stdout.contains("NOT met"), "{stdout}"),
        c => panic!("verify exited {c:?}: {stdout}"),
    }
    assert!(
        stdout.lines().any(|l| l.trim() == "violations 0"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// `synth` on a spec with `mode = "pwa"` writes the PWA image (and the feedforward one it was learned from),
/// a report with the PWA section and re-checks it; `verify` on the PWA image rechecks every partition and runs
/// closed loops from F with 0 violations, and `--attack` from every ball of F finds none.
#[test]
fn synth_and_verify_a_pwa_spec() {
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    ))
    .unwrap();
    let out = std::env::temp_dir().join(format!("hc-cli-pwa-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let spec = out.join("di-pwa.toml");
    std::fs::write(&spec, format!("{base}\n[synthesis]\nmode = \"pwa\"\n")).unwrap();
    let o = bin()
        .arg("synth")
        .arg(&spec)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--verify-runs", "2000"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "synth failed: {stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains("2000 runs from F"), "{stdout}");
    assert!(stdout.contains(" 0 violations"), "{stdout}");
    assert!(stdout.contains("0 failing balls"), "{stdout}");
    for f in [
        "controller.img",
        "feedforward.img",
        "report.html",
        "certificate.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    for img in ["controller.img", "feedforward.img"] {
        crate::spec_fingerprint::assert_stamped(&out.join(img), &spec);
    }
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("id=\"pwa\"") && html.contains("id=\"pwa-table\""));
    let o = bin()
        .arg("verify")
        .arg(&spec)
        .arg(out.join("controller.img"))
        .args(["--runs", "2000"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "verify failed: {stdout}");
    assert!(
        stdout.lines().any(|l| l.trim() == "violations 0"),
        "{stdout}"
    );
    assert!(stdout.contains("0 failing balls"), "{stdout}");
    // The falsifier from every ball of F: runs made, none violates.
    let o = bin()
        .arg("verify")
        .arg(&spec)
        .arg(out.join("controller.img"))
        .args(["--runs", "16", "--attack", "--attack-evals", "8", "--json"])
        .output()
        .unwrap();
    crate::verify_attack::attack_json(&o);
    let _ = std::fs::remove_dir_all(&out);
}
