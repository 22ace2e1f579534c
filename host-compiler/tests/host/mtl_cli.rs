//! End-to-end tests of `host-compiler mtl`: runs the built binary on CSV traces and set files.

use std::path::PathBuf;
use std::process::Command;

fn tmp(name: &str, text: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("mtl_cli");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn run(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .arg("mtl")
        .args(args)
        .output()
        .unwrap();
    let flat = |b: &[u8]| {
        // miette wraps long messages and draws a gutter; undo both for matching.
        String::from_utf8_lossy(b)
            .replace('│', " ")
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ")
    };
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        flat(&out.stderr),
    )
}

fn last_token(s: &str) -> f64 {
    s.split_whitespace()
        .last()
        .expect("no output")
        .parse()
        .expect("last token is not a number")
}

const TRACE: &str = "t,x1,x2\n0,1,-5\n1,-1,4\n2,2,-2\n3,0.5,1\n4,3,0\n";

#[test]
fn prints_the_robustness_at_time_zero_last() {
    let p = tmp("basic.csv", TRACE);
    let p = p.to_str().unwrap();
    let (ok, out, err) = run(&["--trace", p, "--formula", "x1 >= 0 U[1,2] x2 >= 0"]);
    assert!(ok, "{err}");
    assert_eq!(last_token(&out), 4.0);
    let (ok, out, _) = run(&["--trace", p, "--formula", "G[0,2] x1 >= 0.5"]);
    assert!(ok);
    assert_eq!(last_token(&out), -1.5);
    let (ok, out, _) = run(&["--trace", p, "--formula", "2*x1 - x2 <= 1"]);
    assert!(ok);
    assert!((last_token(&out) - (-6.0 / 5f64.sqrt())).abs() < 1e-12);
}

#[test]
fn all_prints_the_whole_signal() {
    let p = tmp("all.csv", TRACE);
    let (ok, out, err) = run(&[
        "--trace",
        p.to_str().unwrap(),
        "--formula",
        "F[1,2] x1 >= 0.5",
        "--all",
    ]);
    assert!(ok, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "t,rho");
    let rows: Vec<(f64, f64)> = lines[1..6]
        .iter()
        .map(|l| {
            let (t, r) = l.split_once(',').unwrap();
            (t.parse().unwrap(), r.parse().unwrap())
        })
        .collect();
    assert_eq!(
        rows,
        vec![
            (0.0, 1.5),
            (1.0, 1.5),
            (2.0, 2.5),
            (3.0, 2.5),
            (4.0, f64::NEG_INFINITY)
        ]
    );
    assert_eq!(last_token(&out), 1.5);
}

#[test]
fn named_sets_from_toml() {
    let p = tmp("sets.csv", "t,px,py\n0,0,0.5\n1,3,4\n");
    let s = tmp(
        "sets.toml",
        "[sets.Disc]\nkind = \"ball\"\ncenter = [0.0, 0.0]\nradius = 1.0\n\n\
         [sets.Right]\nkind = \"box\"\nlo = [2.0]\nhi = [10.0]\ncoords = [\"x1\"]\n",
    );
    let (p, s) = (p.to_str().unwrap(), s.to_str().unwrap());
    // Disc at t=0: depth 1 − 0.5 = 0.5.
    let (ok, out, err) = run(&["--trace", p, "--sets", s, "--formula", "Disc"]);
    assert!(ok, "{err}");
    assert!((last_token(&out) - 0.5).abs() < 1e-9, "{out}");
    // F Right: px = 3 at t=1 is 1 inside [2, 10].
    let (ok, out, err) = run(&[
        "--trace",
        p,
        "--sets",
        s,
        "--formula",
        "F Right & G[0,0] !Right",
    ]);
    assert!(ok, "{err}");
    assert!((last_token(&out) - 1.0).abs() < 1e-9, "{out}");
    // Unknown set: error names it and lists the known ones.
    let (ok, _, err) = run(&["--trace", p, "--sets", s, "--formula", "F Goal"]);
    assert!(!ok);
    assert!(
        err.contains("unknown set `Goal`") && err.contains("Disc"),
        "{err}"
    );
}

#[test]
fn errors_are_reported_with_location() {
    let good = tmp("good.csv", TRACE);
    let good = good.to_str().unwrap();
    let (ok, out, err) = run(&["--trace", good, "--formula", "G[0,1 x1 >= 0"]);
    assert!(!ok && out.is_empty());
    assert!(err.contains("column 7") && err.contains("`]`"), "{err}");

    let bad = tmp("bad.csv", "t,x1\n0,1\n1,oops\n");
    let (ok, _, err) = run(&["--trace", bad.to_str().unwrap(), "--formula", "x1 >= 0"]);
    assert!(!ok);
    assert!(
        err.contains("bad.csv:3:3") && err.contains("`oops` is not a number"),
        "{err}"
    );

    let back = tmp("back.csv", "t,x1\n0,1\n2,1\n1,1\n");
    let (ok, _, err) = run(&["--trace", back.to_str().unwrap(), "--formula", "x1 >= 0"]);
    assert!(!ok);
    assert!(
        err.contains("back.csv:4") && err.contains("increase strictly"),
        "{err}"
    );

    let empty = tmp("empty.csv", "");
    let (ok, _, err) = run(&["--trace", empty.to_str().unwrap(), "--formula", "x1 >= 0"]);
    assert!(!ok);
    assert!(err.contains("empty"), "{err}");

    let short = tmp("short.csv", "t,x1,x2\n0,1\n");
    let (ok, _, err) = run(&["--trace", short.to_str().unwrap(), "--formula", "x1 >= 0"]);
    assert!(!ok);
    assert!(err.contains("missing `x2`"), "{err}");

    let (ok, _, err) = run(&["--trace", "/nonexistent/trace.csv", "--formula", "x1 >= 0"]);
    assert!(!ok);
    assert!(err.contains("cannot read"), "{err}");
}
