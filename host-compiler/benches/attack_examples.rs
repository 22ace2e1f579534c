//! The falsifier on every shipped example (issue #18: `verify --attack` runs on every example image with no
//! violation). Each `examples/*.toml` is synthesised with its own settings by the `host-compiler` binary
//! (`synth --out <tmp>`; exit 0, or 3 for an example short of its coverage target by design), then
//! `verify --attack --json` runs the falsifier at its default budget (two Nelder–Mead starts of at most
//! 120 runs per ball) on the image, scoring runs by the task's own robustness: reach-avoid, the MTL
//! formula sampled finer, the hybrid automaton's flow, the nonlinear plant of a feedback-linearizable task,
//! F of a PWA image. Per example it prints the runs made, runs per second, the least robustness found and
//! the violations, and writes them as rows `attack_example_<name>_{worst_margin,evals_per_s,violations}`.
//!
//! One file of `examples/` gives no image to attack, and is listed as such: `planar-vehicle-sets.toml`
//! is a set file for `mtl --sets`, not a task (no `[plant]`). A synthesis that certifies nothing (exit 1
//! without an image) is listed the same way. `ATTACK_EXAMPLES=name,name` runs only those examples (the
//! hybrid ones take minutes on two cores).
//!
//! A synthesis is seconds to minutes of deterministic (seeded) work, so it is timed directly, once.

use host_compiler::benchkit::{write_rows, Row};
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

fn main() {
    let examples = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let mut specs: Vec<PathBuf> = std::fs::read_dir(&examples)
        .expect("examples/ is readable")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    specs.sort();
    if let Ok(only) = std::env::var("ATTACK_EXAMPLES") {
        let only: Vec<&str> = only.split(',').map(str::trim).collect();
        specs.retain(|p| {
            p.file_stem()
                .is_some_and(|s| only.contains(&&*s.to_string_lossy()))
        });
    }
    let scratch = std::env::temp_dir().join(format!("hc-attack-examples-{}", std::process::id()));
    let mut rows = Vec::new();
    let mut failed = Vec::new();
    println!(
        "{:<28} {:>8} {:>10} {:>10} {:>12} {:>11} {:>6}",
        "example", "synth s", "balls", "runs", "runs/s", "least rob.", "viol."
    );
    for spec in &specs {
        let name = spec
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let out = scratch.join(&name);
        let text = std::fs::read_to_string(spec).unwrap_or_default();
        if !text.lines().any(|l| l.trim() == "[plant]") {
            println!("{name:<28} not a task spec (no [plant]): nothing to attack");
            continue;
        }
        let t0 = Instant::now();
        let o = bin()
            .arg("synth")
            .arg(spec)
            .arg("--out")
            .arg(&out)
            .args(["--quiet", "--verify-runs", "1000"])
            .output()
            .expect("host-compiler runs");
        let synth_s = t0.elapsed().as_secs_f64();
        let img = out.join("controller.img");
        // Exit 1 without an image: synthesis certified nothing, so there is no image to attack.
        if o.status.code() == Some(1) && !img.exists() {
            let why = String::from_utf8_lossy(&o.stderr);
            println!(
                "{name:<28} {synth_s:>8.1} no image: synth certified nothing ({})",
                why.split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" ")
                    .chars()
                    .take(120)
                    .collect::<String>()
            );
            continue;
        }
        if !matches!(o.status.code(), Some(0 | 3)) {
            println!(
                "{name}: synth exited {:?}: {}",
                o.status.code(),
                String::from_utf8_lossy(&o.stderr)
            );
            failed.push(name);
            continue;
        }
        let o = bin()
            .arg("verify")
            .arg(spec)
            .arg(&img)
            .args(["--runs", "100", "--per-ball", "1", "--attack", "--json"])
            .output()
            .expect("host-compiler runs");
        let j: serde_json::Value = match serde_json::from_slice(&o.stdout) {
            Ok(j) => j,
            Err(e) => {
                println!(
                    "{name}: verify printed no JSON ({e}): {}",
                    String::from_utf8_lossy(&o.stderr)
                );
                failed.push(name);
                continue;
            }
        };
        let at = &j["attack"];
        let evals = at["evaluations"].as_f64().unwrap_or(0.0);
        let secs = at["seconds"].as_f64().unwrap_or(f64::NAN);
        // serde_json writes a non-finite least robustness (no run scored) as null.
        let worst = at["worst_robustness"].as_f64().unwrap_or(f64::NAN);
        let violations = at["violations"].as_f64().unwrap_or(f64::NAN);
        let balls = shared_types::image::decode(&std::fs::read(&img).unwrap_or_default())
            .map(|i| i.n_trajectories().max(i.n_balls()))
            .unwrap_or(0);
        println!(
            "{name:<28} {synth_s:>8.1} {balls:>10} {evals:>10} {:>12.0} {worst:>11.4e} {violations:>6}",
            evals / secs
        );
        // A least robustness that is NaN (no run scored) fails too.
        if o.status.code() != Some(0) || violations != 0.0 || worst.is_nan() || worst <= 0.0 {
            println!(
                "{name}: verify exited {:?}: {}",
                o.status.code(),
                String::from_utf8_lossy(&o.stderr)
            );
            failed.push(name.clone());
        }
        let key = name.replace('-', "_");
        rows.push(Row::new(
            &format!("attack_example_{key}_worst_margin"),
            worst,
            &format!("least run robustness (target > 0), {evals} runs, 2 starts × ≤ 120 per ball"),
        ));
        rows.push(Row::new(
            &format!("attack_example_{key}_evals_per_s"),
            evals / secs,
            "closed-loop runs/s",
        ));
        rows.push(Row::new(
            &format!("attack_example_{key}_violations"),
            violations,
            "runs failing the task (target 0)",
        ));
    }
    let _ = std::fs::remove_dir_all(&scratch);
    write_rows("attack_examples", &rows).expect("bench rows written");
    assert!(
        failed.is_empty(),
        "the attack did not pass on: {}",
        failed.join(", ")
    );
}
