//! What `synth` tells and leaves behind (issue 18): exit status 0 only when the coverage target is met,
//! 3 when the image is certified but short of it, 2 for bad input (documented in `--help`); a run that
//! fails leaves no earlier image in `--out`; a confidence is never printed rounded up to a claim the run
//! did not make; a spec that used to crash (an Init box spanning ±1e308) is bad input.

use host_compiler::report::format::{directed, pct_down, pct_up, Round};
use std::path::PathBuf;
use std::process::{Command, Output};

pub(crate) fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

pub(crate) fn base() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    ))
    .unwrap()
}

/// A scratch directory for one test.
pub(crate) fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-cli-exit-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn synth(spec: &str, dir: &std::path::Path) -> Output {
    let path = dir.join("spec.toml");
    std::fs::write(&path, spec).unwrap();
    bin()
        .arg("synth")
        .arg(&path)
        .arg("--out")
        .arg(dir.join("out"))
        .args(["--quiet", "--verify-runs", "200"])
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn help_documents_the_exit_codes() {
    let o = bin().arg("--help").output().unwrap();
    let help = String::from_utf8_lossy(&o.stdout);
    for line in ["Exit status:", "0 ", "1 ", "2 ", "3 ", "130 "] {
        assert!(help.contains(line), "--help lacks `{line}`:\n{help}");
    }
    assert!(help.contains("short of the coverage target"), "{help}");
}

#[test]
fn a_cover_short_of_the_target_exits_3_and_says_so() {
    let dir = scratch("short");
    let o = synth(
        &format!("{}\n[synthesis]\nmax_trajectories = 1\n", base()),
        &dir,
    );
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(err.contains("coverage target NOT met"), "{err}");
    // The image is certified and verified for its cover: it is written.
    assert!(dir.join("out/controller.img").is_file());
    // The covered example exits 0.
    let o = synth(&base(), &dir);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_failed_synth_leaves_no_earlier_result() {
    let dir = scratch("stale");
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    let outputs = ["controller.img", "certificate.json", "report.html"];
    let plant_old = || {
        for f in outputs {
            std::fs::write(out.join(f), b"from an earlier run").unwrap();
        }
    };
    // An invalid spec (bad input, exit 2).
    plant_old();
    let o = synth("seed = 1\n", &dir);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    for f in outputs {
        assert!(!out.join(f).exists(), "{f} from an earlier run is left");
    }
    // A valid spec whose plant no feedback stabilises (fails after the spec is read, exit 2 too); the
    // message names the mode and the spec keys.
    plant_old();
    let spec = base()
        .replacen(
            "[1.0, 0.1],\n  [0.0, 1.0],",
            "[1.0, 0.0],\n  [0.0, 1.5],",
            1,
        )
        .replacen("[0.005],\n  [0.1],", "[0.1],\n  [0.0],", 1);
    let o = synth(&spec, &dir);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("not stabilizable") && err.contains("plant.A and plant.B"),
        "{err}"
    );
    assert!(!err.contains("Complex {"), "{err}");
    for f in outputs {
        assert!(!out.join(f).exists(), "{f} from an earlier run is left");
    }
    // No temporary file is left either.
    let left: Vec<_> = std::fs::read_dir(&out).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_confidence_is_never_printed_rounded_up() {
    // 1 − 10⁻¹² is not 100 %: enough digits to show it is below, rounded down.
    assert_eq!(pct_down(1.0 - 1e-12), "99.9999999999 %");
    assert_eq!(pct_down(0.99), "99 %");
    assert_eq!(pct_down(1.0), "100 %");
    assert_eq!(pct_down(0.987654), "98.76 %");
    // An upper bound rounds up instead; a lower bound down.
    assert_eq!(pct_up(0.987651), "98.77 %");
    assert_eq!(directed(0.989996, 5, Round::Down, 1.0), "0.98999");
    assert_eq!(directed(0.99, 5, Round::Down, 1.0), "0.99");
    assert_eq!(directed(0.9999999, 2, Round::Down, 1.0), "0.9999999");
    // And `synth` prints it so.
    let dir = scratch("confidence");
    let o = synth(
        &format!("{}\n[synthesis]\nconfidence = 0.999999999999\n", base()),
        &dir,
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stdout.contains("at 99.9999999999 % confidence"), "{stdout}");
    assert!(!stdout.contains("100 % confidence"), "{stdout}");
    let html = std::fs::read_to_string(dir.join("out/report.html")).unwrap();
    assert!(!html.contains("100 % confidence"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_huge_init_box_is_bad_input_not_a_panic() {
    let dir = scratch("huge-init");
    let spec = base().replacen(
        "lo = [-0.1, 0.0]\nhi = [ 0.1, 0.0]",
        "lo = [-1e308, 0.0]\nhi = [ 1e308, 0.0]",
        1,
    );
    assert!(
        spec.contains("1e308"),
        "test bug: the example's Init changed"
    );
    let o = synth(&spec, &dir);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("init.lo[0]") && !err.contains("panicked"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// With stderr not a terminal (this pipe, a CI log) the growth's progress still shows, as one plain line
/// per round; `--quiet` hides it.
#[test]
fn progress_shows_as_plain_lines_when_stderr_is_not_a_terminal() {
    let dir = scratch("plain-progress");
    let path = dir.join("spec.toml");
    std::fs::write(
        &path,
        format!("{}\n[synthesis]\nmax_trajectories = 1\n", base()),
    )
    .unwrap();
    let run = |quiet: bool| {
        let mut c = bin();
        c.arg("synth")
            .arg(&path)
            .arg("--out")
            .arg(dir.join("out"))
            .args(["--verify-runs", "200"]);
        if quiet {
            c.arg("--quiet");
        }
        c.output().unwrap()
    };
    let o = run(false);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(err.contains("round 1: first seed (SCP + §5.3)"), "{err}");
    let o = run(true);
    assert!(!stderr(&o).contains("round 1:"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
}
