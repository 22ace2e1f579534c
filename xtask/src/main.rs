//! Project tasks, run as `cargo xtask <task>` (alias in `.cargo/config.toml`).
//!
//! * `test` (and `ci`, the same): everything CI checks, on a fresh machine:
//!   1. adds the rustup target `thumbv7em-none-eabihf` if missing;
//!   2. installs `qemu-system-arm` and `chromium` (the headless browser of `host-compiler play`'s
//!      end-to-end test) with apt-get if missing (as root; otherwise prints the command);
//!   3. `cargo test --workspace --exclude qemu-tests` (host crates, with that browser test);
//!   4. builds shared-types and the firmware for `thumbv7em-none-eabihf` (proves `no_std`);
//!   5. the QEMU hardware-in-the-loop suite: `cargo test -p qemu-tests`.
//!
//!   It keeps going after a failure where it can, lists every step, ends with the line
//!   `xtask: N passed, M failed`, and exits non-zero if any step failed.
//! * `bench`: `cargo bench -p host-compiler`, then the HIL measurement (`hil-bench`), then merges every
//!   `target/bench/rows/*.json` into `target/bench/summary.json` and prints one table.

use serde_json::Value;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::time::Instant;

const TARGET: &str = "thumbv7em-none-eabihf";
const QEMU: &str = "qemu-system-arm";
/// The Debian package and binary of the headless browser `host-compiler play`'s test drives.
const CHROMIUM: &str = "chromium";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("test") | Some("ci") => test(),
        Some("bench") => bench(),
        _ => {
            eprintln!("usage: cargo xtask <test|ci|bench>");
            ExitCode::from(2)
        }
    }
}

/// The workspace root (xtask lives one level below it).
fn root() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    root.canonicalize().unwrap_or(root)
}

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    c.current_dir(root());
    c
}

/// A cargo command for the firmware workspace: working directory `firmware/` (so that cargo reads
/// `firmware/.cargo/config.toml`), without the host's target settings.
fn firmware_cargo() -> Command {
    let mut c = cargo();
    c.current_dir(root().join("firmware"));
    for var in [
        "CARGO_TARGET_DIR",
        "CARGO_BUILD_TARGET",
        "RUSTFLAGS",
        "CARGO_ENCODED_RUSTFLAGS",
        "CARGO_BUILD_RUSTFLAGS",
    ] {
        c.env_remove(var);
    }
    c
}

fn show(cmd: &Command) -> String {
    let prog = Path::new(cmd.get_program())
        .file_name()
        .unwrap_or(OsStr::new("?"))
        .to_string_lossy()
        .into_owned();
    let args: Vec<String> = cmd
        .get_args()
        .map(|a| a.to_string_lossy().into_owned())
        .collect();
    let dir = cmd
        .get_current_dir()
        .map(|d| format!(" (in {})", d.display()))
        .unwrap_or_default();
    format!("{prog} {}{dir}", args.join(" "))
}

/// Runs a command with inherited output; Ok if it exits 0.
fn run(mut cmd: Command) -> Result<(), String> {
    let what = show(&cmd);
    println!("xtask: $ {what}");
    match cmd.status() {
        Ok(s) if s.success() => Ok(()),
        Ok(s) => Err(format!("`{what}` failed ({s})")),
        Err(e) => Err(format!("could not run `{what}`: {e}")),
    }
}

/// Runs a command quietly; its stdout if it exits 0.
fn output(mut cmd: Command) -> Option<String> {
    let out = cmd.output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

struct Steps {
    results: Vec<(String, Result<(), String>, f64)>,
}

impl Steps {
    fn run(&mut self, name: &str, f: impl FnOnce() -> Result<(), String>) -> bool {
        let n = self.results.len() + 1;
        println!("\nxtask: ── step {n}: {name} ──");
        let t = Instant::now();
        let r = f();
        let secs = t.elapsed().as_secs_f64();
        match &r {
            Ok(()) => println!("xtask: step {n} ({name}) passed in {secs:.1} s"),
            Err(e) => println!("xtask: step {n} ({name}) FAILED in {secs:.1} s: {e}"),
        }
        let ok = r.is_ok();
        self.results.push((name.to_string(), r, secs));
        ok
    }

    fn skip(&mut self, name: &str, why: &str) {
        let n = self.results.len() + 1;
        println!("\nxtask: ── step {n}: {name} ── not run: {why}");
        self.results
            .push((name.to_string(), Err(format!("not run: {why}")), 0.0));
    }

    fn finish(self) -> ExitCode {
        println!("\nxtask: summary");
        let mut failed = 0;
        for (i, (name, r, secs)) in self.results.iter().enumerate() {
            match r {
                Ok(()) => println!("xtask:   {}. {name:<72} passed  {secs:>7.1} s", i + 1),
                Err(e) => {
                    failed += 1;
                    println!("xtask:   {}. {name:<72} FAILED  {secs:>7.1} s  {e}", i + 1)
                }
            }
        }
        let passed = self.results.len() - failed;
        println!("xtask: {passed} passed, {failed} failed");
        if failed == 0 {
            ExitCode::SUCCESS
        } else {
            ExitCode::FAILURE
        }
    }
}

/// Step 1: the cross target for the pinned toolchain (rust-toolchain.toml in the root selects it).
fn ensure_target() -> Result<(), String> {
    let sysroot = output({
        let mut c = Command::new("rustc");
        c.current_dir(root()).args(["--print", "sysroot"]);
        c
    })
    .ok_or("`rustc --print sysroot` failed")?;
    let lib = Path::new(sysroot.trim())
        .join("lib")
        .join("rustlib")
        .join(TARGET);
    if lib.is_dir() {
        println!("xtask: target {TARGET} is installed ({})", lib.display());
        return Ok(());
    }
    let mut c = Command::new("rustup");
    c.current_dir(root()).args(["target", "add", TARGET]);
    run(c)
}

fn qemu_present() -> bool {
    output({
        let mut c = Command::new(QEMU);
        c.arg("--version");
        c
    })
    .map(|v| println!("xtask: {}", v.lines().next().unwrap_or(QEMU)))
    .is_some()
}

fn is_root() -> bool {
    output({
        let mut c = Command::new("id");
        c.arg("-u");
        c
    })
    .is_some_and(|s| s.trim() == "0")
}

/// Step 2: qemu-system-arm, from Debian/Ubuntu packages.
fn ensure_qemu() -> Result<(), String> {
    ensure_package(QEMU, QEMU, qemu_present)
}

fn chromium_present() -> bool {
    output({
        let mut c = Command::new(CHROMIUM);
        c.arg("--version");
        c
    })
    .map(|v| println!("xtask: {}", v.lines().next().unwrap_or(CHROMIUM)))
    .is_some()
}

/// Step 2: chromium (headless) for the end-to-end test of `host-compiler play`, from Debian packages.
fn ensure_chromium() -> Result<(), String> {
    ensure_package(CHROMIUM, CHROMIUM, chromium_present)
}

/// Installs the Debian package `package` with apt-get when `present` says `binary` is missing (as root;
/// otherwise the error gives the command to run).
fn ensure_package(binary: &str, package: &str, present: fn() -> bool) -> Result<(), String> {
    if present() {
        return Ok(());
    }
    let install = format!(
        "apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends {package}"
    );
    if !is_root() {
        return Err(format!(
            "{binary} is missing; install it with:\n    sudo sh -c '{install}'"
        ));
    }
    println!("xtask: {binary} is missing; installing it");
    let apt = |args: &[&str]| {
        let mut c = Command::new("apt-get");
        c.args(args).env("DEBIAN_FRONTEND", "noninteractive");
        c
    };
    run(apt(&["update"]))?;
    run(apt(&["install", "-y", "--no-install-recommends", package]))?;
    if present() {
        Ok(())
    } else {
        Err(format!("{binary} still not runnable after apt-get install"))
    }
}

fn test() -> ExitCode {
    let mut steps = Steps {
        results: Vec::new(),
    };
    let target_ok = steps.run("rustup target thumbv7em-none-eabihf", ensure_target);
    let qemu_ok = steps.run("qemu-system-arm", ensure_qemu);
    // Without it the host tests still run; the browser test then fails and says how to install it.
    steps.run(
        "chromium (the play page's end-to-end test)",
        ensure_chromium,
    );
    steps.run(
        "host tests: cargo test --workspace --exclude qemu-tests --no-fail-fast",
        || {
            let mut c = cargo();
            c.args([
                "test",
                "--workspace",
                "--exclude",
                "qemu-tests",
                "--no-fail-fast",
            ]);
            run(c)
        },
    );
    let no_std = "no_std: shared-types and firmware for thumbv7em-none-eabihf";
    if target_ok {
        steps.run(no_std, || {
            let mut c = cargo();
            c.args(["build", "-p", "shared-types", "--target", TARGET]);
            run(c)?;
            let mut c = firmware_cargo();
            c.args(["build", "--release"]);
            run(c)
        });
    } else {
        steps.skip(no_std, "the target is missing");
    }
    let hil = "HIL: cargo test -p qemu-tests --no-fail-fast";
    match (target_ok, qemu_ok) {
        (true, true) => {
            steps.run(hil, || {
                let mut c = cargo();
                c.args(["test", "-p", "qemu-tests", "--no-fail-fast"]);
                run(c)
            });
        }
        (false, _) => steps.skip(hil, "the target is missing"),
        (_, false) => steps.skip(hil, "qemu-system-arm is missing"),
    }
    steps.finish()
}

fn bench() -> ExitCode {
    let mut steps = Steps {
        results: Vec::new(),
    };
    let rows_dir = target_dir().join("bench").join("rows");
    // Rows of earlier runs would be mistaken for this run's.
    if let Ok(entries) = std::fs::read_dir(&rows_dir) {
        for e in entries.flatten() {
            if e.path().extension() == Some(OsStr::new("json")) {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    steps.run("host benches: cargo bench -p host-compiler", || {
        let mut c = cargo();
        c.args(["bench", "-p", "host-compiler"]);
        run(c)
    });
    let target_ok = steps.run("rustup target thumbv7em-none-eabihf", ensure_target);
    let qemu_ok = steps.run("qemu-system-arm", ensure_qemu);
    let hil = "HIL measurement: hil-bench";
    if target_ok && qemu_ok {
        steps.run(hil, || {
            let mut c = cargo();
            c.args(["run", "--release", "-p", "qemu-tests", "--bin", "hil-bench"]);
            run(c)
        });
    } else {
        steps.skip(hil, "the target or qemu-system-arm is missing");
    }
    steps.run("merge rows into target/bench/summary.json", || {
        merge(&rows_dir)
    });
    steps.finish()
}

fn field(row: &Value, key: &str) -> Value {
    row.get(key).cloned().unwrap_or(Value::Null)
}

fn fmt_num(v: &Value) -> String {
    match v.as_f64() {
        None => "-".into(),
        Some(x) if x.fract() == 0.0 && x.abs() < 1e15 => format!("{}", x as i64),
        Some(x) if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e6) => format!("{x:.4e}"),
        Some(x) => format!("{x:.4}"),
    }
}

/// Merges every rows file into `summary.json` (a list of {name, value, unit, baseline, ratio}) and prints
/// the table.
fn merge(rows_dir: &Path) -> Result<(), String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(rows_dir)
        .map_err(|e| format!("reading {}: {e}", rows_dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension() == Some(OsStr::new("json")))
        .collect();
    files.sort();
    let mut rows = Vec::new();
    for f in &files {
        let text =
            std::fs::read_to_string(f).map_err(|e| format!("reading {}: {e}", f.display()))?;
        let list: Vec<Value> =
            serde_json::from_str(&text).map_err(|e| format!("parsing {}: {e}", f.display()))?;
        for r in list {
            let mut o = serde_json::Map::new();
            for k in ["name", "value", "unit", "baseline", "ratio"] {
                o.insert(k.into(), field(&r, k));
            }
            rows.push(Value::Object(o));
        }
    }
    let summary = rows_dir.parent().unwrap_or(rows_dir).join("summary.json");
    let text = serde_json::to_string_pretty(&rows).map_err(|e| e.to_string())?;
    std::fs::write(&summary, text).map_err(|e| format!("writing {}: {e}", summary.display()))?;
    let cells: Vec<[String; 5]> = rows
        .iter()
        .map(|r| {
            [
                field(r, "name").as_str().unwrap_or("?").to_string(),
                fmt_num(&field(r, "value")),
                field(r, "unit").as_str().unwrap_or("").to_string(),
                fmt_num(&field(r, "baseline")),
                fmt_num(&field(r, "ratio")),
            ]
        })
        .collect();
    let header = ["name", "value", "unit", "baseline", "ratio"].map(String::from);
    let mut width = header.clone().map(|h| h.len());
    for c in &cells {
        for (w, s) in width.iter_mut().zip(c) {
            *w = (*w).max(s.chars().count());
        }
    }
    println!();
    let line = |c: &[String; 5]| {
        println!(
            "{:<w0$}  {:>w1$}  {:<w2$}  {:>w3$}  {:>w4$}",
            c[0],
            c[1],
            c[2],
            c[3],
            c[4],
            w0 = width[0],
            w1 = width[1],
            w2 = width[2],
            w3 = width[3],
            w4 = width[4]
        )
    };
    line(&header);
    for c in &cells {
        line(c);
    }
    println!(
        "\nxtask: {} rows from {} files → {}",
        rows.len(),
        files.len(),
        summary.display()
    );
    if rows.is_empty() {
        return Err("no bench rows were written".into());
    }
    Ok(())
}
