//! Flags and files are bounded before any work (issue 18, class 2): `verify --runs`/`--per-ball`,
//! `synth --verify-runs` and `simulate --steps` beyond their documented maxima, an imported recording
//! longer than the horizon, and a spec beyond `spec::limits` are bad input (exit 2) that names the flag,
//! file or key, before anything is simulated or synthesised.

use std::path::PathBuf;
use std::process::{Command, Output};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

fn example() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    ))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-cli-limits-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[track_caller]
fn bad_input(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    for n in needles {
        assert!(e.contains(n), "stderr lacks `{n}`:\n{e}");
    }
}

#[test]
fn run_counts_beyond_their_maxima_are_refused_and_documented() {
    use host_compiler::verify::{MAX_PER_BALL, MAX_RUNS};
    let spec = example();
    // The case of the issue: `verify --runs 1000000000` (24 GB of starts). Refused while parsing the
    // flags: the image named here does not even exist.
    let o = bin()
        .args(["verify"])
        .arg(&spec)
        .args(["nothing.img", "--runs", "1000000000"])
        .output()
        .unwrap();
    bad_input(&o, &["--runs", "1000000000", &MAX_RUNS.to_string()]);
    let over = (MAX_PER_BALL + 1).to_string();
    let o = bin()
        .args(["verify"])
        .arg(&spec)
        .args(["nothing.img", "--per-ball", &over])
        .output()
        .unwrap();
    bad_input(&o, &["--per-ball", &over]);
    let over = (MAX_RUNS + 1).to_string();
    let o = bin()
        .arg("synth")
        .arg(&spec)
        .args(["--verify-runs", &over])
        .output()
        .unwrap();
    bad_input(&o, &["--verify-runs", &over]);
    let o = bin()
        .arg("simulate")
        .arg(&spec)
        .args(["nothing.img", "--x0", "0,0", "--steps", "1000000000"])
        .output()
        .unwrap();
    bad_input(&o, &["--steps", "1000000000"]);
    // The maxima are where the user sees them.
    let help = bin().args(["verify", "--help"]).output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains(&format!("at most {MAX_RUNS}")), "{help}");
    assert!(help.contains(&format!("at most {MAX_PER_BALL}")), "{help}");
}

#[test]
fn a_recording_longer_than_the_horizon_is_refused_before_synthesis() {
    // double-integrator: horizon 4 s at 0.1 s, 40 samples; the recording has 41 rows.
    let dir = scratch("import");
    let mut csv = String::from("# x0 = 0.0, 0.0\nt,v1\n");
    for k in 0..41 {
        csv.push_str(&format!("{:.1},0.0\n", k as f64 * 0.1));
    }
    let rec = dir.join("long.csv");
    std::fs::write(&rec, csv).unwrap();
    let o = bin()
        .arg("synth")
        .arg(example())
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--quiet")
        .arg("--import")
        .arg(&rec)
        .output()
        .unwrap();
    bad_input(&o, &["long.csv:43", "more than 40 rows"]);
    assert!(
        !String::from_utf8_lossy(&o.stdout).contains("trajectories"),
        "synthesis ran"
    );
}

#[test]
fn a_spec_beyond_the_limits_is_bad_input_at_its_key() {
    let dir = scratch("spec");
    let text = std::fs::read_to_string(example()).unwrap();
    assert!(
        text.contains("horizon = 4.0"),
        "test bug: the example changed"
    );
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, text.replace("horizon = 4.0", "horizon = 1e9")).unwrap();
    let o = bin()
        .arg("synth")
        .arg(&spec)
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--quiet")
        .output()
        .unwrap();
    bad_input(&o, &["spec::capacity", "horizon", "524288"]);
}
