//! Project tasks, run as `cargo xtask <task>` (alias in `.cargo/config.toml`).
//!
//! * `test` (and `ci`, the same): everything CI checks, on a fresh machine:
//!   1. adds the rustup target `thumbv7em-none-eabihf` if missing;
//!   2. installs `qemu-system-arm` and `chromium` (the headless browser of `host-compiler play`'s
//!      end-to-end test) with apt-get if missing (as root; otherwise prints the command);
//!   3. `cargo test --workspace --features qemu-tests/skip-hil` (host crates, with that browser test; the
//!      HIL test binary compiled empty);
//!   4. the firmware's control loop on the host: `cargo test --target <host triple> -p control-loop` in
//!      `firmware/` (the loop crate is `no_std` but tested with std against a mock board; the explicit
//!      `--target` overrides the firmware workspace's default `thumbv7em-none-eabihf`);
//!   5. builds shared-types and every board ([`boards::BOARDS`]) for `thumbv7em-none-eabihf` (proves
//!      `no_std`; compile only, there is no probe);
//!   6. no panic, per board: builds the board's release firmware with the `panic-never` feature, whose
//!      panic handler calls a function defined nowhere, so the link fails if any panicking path survives
//!      optimisation; if it fails, traces every call into the panic machinery of the ordinary release ELF
//!      (`llvm-objdump`, `llvm-symbolizer`) to its origin and chain of inlined callers, and fails naming
//!      every origin not listed in `firmware/panic-allowlist.txt` (paths inside dependencies that remain,
//!      each with why);
//!   7. the QEMU hardware-in-the-loop suite: `cargo test --workspace --test hil` (the same package
//!      selection as step 3, so the same dependency features and no second compile; it synthesises the shipped
//!      examples' images and records every session's stack high-water mark);
//!   8. board budgets: every board built with the longest shipped example's image, its flash and its RAM
//!      (static + the HIL suite's largest stack mark) against [`boards::BUDGETS`]; fails naming the board
//!      and the figure over budget.
//!
//!   It keeps going after a failure where it can, lists every step, ends with the line
//!   `xtask: N passed, M failed`, and exits non-zero if any step failed.
//! * `no-panic`: step 6 of `test` alone.
//! * `budgets`: step 8 of `test` alone (needs the images and stack figures a HIL run left).
//! * `board-sizes`: the boards' bench rows alone (after a HIL run), merged into the table.
//! * `bench`: `cargo bench -p host-compiler`, then the HIL measurement (`hil-bench`), then the boards' rows
//!   `board_<name>_flash_bytes` and `board_<name>_ram_bytes` (RAM with hil-bench's
//!   `firmware_stack_bytes_bound`), then merges every `target/bench/rows/*.json` into
//!   `target/bench/summary.json` and prints one table; then keeps its `examples_*` rows in
//!   `docs/figures.json` and renders examples/README.md's table of figures from them (`figures`).
//! * `figures`: examples/README.md's table of figures rendered again from `docs/figures.json`.

mod boards;
mod figures;

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
        Some("figures") => {
            let mut steps = Steps {
                results: Vec::new(),
            };
            steps.run(
                "examples/README.md's figures from docs/figures.json",
                || figures::render_readme(&root()),
            );
            steps.finish()
        }
        Some("no-panic") => {
            let mut steps = Steps {
                results: Vec::new(),
            };
            for &board in boards::BOARDS {
                steps.run(&no_panic_step(board), || no_panic_check(board));
            }
            steps.finish()
        }
        Some("board-sizes") => {
            let mut steps = Steps {
                results: Vec::new(),
            };
            let rows_dir = target_dir().join("bench").join("rows");
            steps.run(BOARD_SIZES_STEP, || board_rows(&rows_dir));
            steps.run("merge rows into target/bench/summary.json", || {
                merge(&rows_dir)
            });
            steps.finish()
        }
        Some("budgets") => {
            let mut steps = Steps {
                results: Vec::new(),
            };
            steps.run(BUDGET_STEP, budget_check);
            steps.finish()
        }
        _ => {
            eprintln!("usage: cargo xtask <test|ci|bench|no-panic|budgets|board-sizes>");
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
        "CARGO_BUILD_TARGET_DIR",
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

/// The host's target triple (`rustc -vV`), for the firmware loop's host tests.
fn host_triple() -> Result<String, String> {
    let v = output({
        let mut c = Command::new("rustc");
        c.current_dir(root()).arg("-vV");
        c
    })
    .ok_or("`rustc -vV` failed")?;
    v.lines()
        .find_map(|l| l.strip_prefix("host: "))
        .map(|h| h.trim().to_string())
        .ok_or_else(|| "`rustc -vV` names no host".to_string())
}

/// Step 4: the control loop's unit tests on the host, from `firmware/` with an explicit host `--target`
/// (the firmware workspace's `[build] target` is the board's).
fn loop_host_tests() -> Result<(), String> {
    let host = host_triple()?;
    let mut c = firmware_cargo();
    c.args(["test", "--target", &host, "-p", "control-loop"]);
    run(c)
}

fn no_panic_step(board: &str) -> String {
    format!("no panic: {board} release firmware (panic-never link, or only paths in firmware/panic-allowlist.txt)")
}

const BUDGET_STEP: &str =
    "board budgets: every board, the longest shipped image of each configuration, flash and RAM + stack (xtask/src/boards.rs)";

/// Step 8: every board against the budgets, with the HIL suite's largest stack mark.
fn budget_check() -> Result<(), String> {
    let stack = boards::hil_stack_peak()?;
    let figures = boards::measure(stack)?;
    boards::check(&figures)
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
        "host tests: cargo test --workspace --features qemu-tests/skip-hil --no-fail-fast",
        || {
            let mut c = cargo();
            c.args([
                "test",
                "--workspace",
                "--features",
                "qemu-tests/skip-hil",
                "--no-fail-fast",
            ]);
            run(c)
        },
    );
    steps.run(
        "firmware loop on the host: cargo test --target <host> -p control-loop (in firmware/)",
        loop_host_tests,
    );
    let no_std = "no_std: shared-types and every board for thumbv7em-none-eabihf (compile only)";
    if target_ok {
        steps.run(no_std, || {
            let mut c = cargo();
            c.args(["build", "-p", "shared-types", "--target", TARGET]);
            run(c)?;
            let mut failed = Vec::new();
            for &board in boards::BOARDS {
                if let Err(e) = boards::build(board, None, false) {
                    failed.push(format!("{board}: {e}"));
                }
            }
            if failed.is_empty() {
                Ok(())
            } else {
                Err(failed.join("; "))
            }
        });
    } else {
        steps.skip(no_std, "the target is missing");
    }
    for &board in boards::BOARDS {
        let name = no_panic_step(board);
        if target_ok {
            steps.run(&name, || no_panic_check(board));
        } else {
            steps.skip(&name, "the target is missing");
        }
    }
    // The same package selection as the host tests' (`--workspace`), so that the dependencies resolve to
    // the same features and nothing the host step compiled is compiled again (qemu-tests' `skip-hil`).
    let hil = "HIL: cargo test --workspace --test hil --no-fail-fast";
    let hil_ok = match (target_ok, qemu_ok) {
        (true, true) => steps.run(hil, || {
            // Figures of an earlier run would be mistaken for this run's.
            let peaks = boards::stack_peaks_file();
            if peaks.exists() {
                std::fs::remove_file(&peaks)
                    .map_err(|e| format!("removing {}: {e}", peaks.display()))?;
            }
            let mut c = cargo();
            c.args(["test", "--workspace", "--test", "hil", "--no-fail-fast"]);
            run(c)
        }),
        (false, _) => {
            steps.skip(hil, "the target is missing");
            false
        }
        (_, false) => {
            steps.skip(hil, "qemu-system-arm is missing");
            false
        }
    };
    // The budget check needs the HIL suite's images and stack figures; after a failed HIL run they may
    // be partial, and the check still runs on what is there (and says what is missing).
    if target_ok && (hil_ok || boards::stack_peaks_file().exists()) {
        steps.run(BUDGET_STEP, budget_check);
    } else {
        steps.skip(BUDGET_STEP, "the HIL suite did not run");
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
    let sizes =
        "board sizes: board_<name>_flash_bytes, board_<name>_ram_bytes (against the budgets)";
    if target_ok {
        steps.run(sizes, || board_rows(&rows_dir));
    } else {
        steps.skip(sizes, "the target is missing");
    }
    steps.run("merge rows into target/bench/summary.json", || {
        merge(&rows_dir)
    });
    steps.run(
        "examples/README.md's figures: docs/figures.json from the summary, the table from it",
        || {
            let summary = target_dir().join("bench").join("summary.json");
            let text = std::fs::read_to_string(&summary)
                .map_err(|e| format!("reading {}: {e}", summary.display()))?;
            let rows: Vec<Value> = serde_json::from_str(&text).map_err(|e| e.to_string())?;
            figures::write(&root(), &rows)
        },
    );
    steps.finish()
}

const BOARD_SIZES_STEP: &str =
    "board sizes: board_<name>_flash_bytes, board_<name>_ram_bytes (against the budgets)";

/// The boards' bench rows, with hil-bench's `firmware_stack_bytes_bound` (`rows/hil.json`) as the stack,
/// or, without it (`cargo xtask board-sizes` after `cargo xtask test`), the HIL suite's largest stack
/// mark; written to `rows/boards.json` before the budgets are checked, so that the table shows the
/// figures either way.
fn board_rows(rows_dir: &Path) -> Result<(), String> {
    let hil = rows_dir.join("hil.json");
    let bound = std::fs::read_to_string(&hil).ok().and_then(|text| {
        let list: Vec<Value> = serde_json::from_str(&text).ok()?;
        list.iter()
            .find(|r| r.get("name").and_then(Value::as_str) == Some("firmware_stack_bytes_bound"))
            .and_then(|r| r.get("value").and_then(Value::as_f64))
    });
    let stack = match bound {
        Some(b) => {
            println!(
                "xtask: stack: firmware_stack_bytes_bound = {b} bytes ({})",
                hil.display()
            );
            b as u64
        }
        None => {
            let s = boards::hil_stack_peak()?;
            println!(
                "xtask: stack: no firmware_stack_bytes_bound in {}; the HIL suite's largest mark, {s} bytes",
                hil.display()
            );
            s
        }
    };
    std::fs::create_dir_all(rows_dir)
        .map_err(|e| format!("creating {}: {e}", rows_dir.display()))?;
    let figures = boards::measure(stack)?;
    let rows = Value::Array(boards::rows(&figures));
    let out = rows_dir.join("boards.json");
    let text = serde_json::to_string_pretty(&rows).map_err(|e| e.to_string())?;
    std::fs::write(&out, text).map_err(|e| format!("writing {}: {e}", out.display()))?;
    boards::check(&figures)
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

/// The symbol the `panic-never` panic handler calls (each board's `src/main.rs`); defined nowhere.
const PANIC_NEVER_SYMBOL: &str = "firmware_panic_path_is_reachable";

/// The known panicking paths that remain in dependencies (firmware/panic-allowlist.txt).
const PANIC_ALLOWLIST: &str = "firmware/panic-allowlist.txt";

/// The no-panic check of one board (step 6 of `test`): its release firmware with the `panic-never`
/// feature must link.
/// If the link fails on [`PANIC_NEVER_SYMBOL`], the ordinary release ELF (same code, with a defined
/// handler) is disassembled (`llvm-objdump`), every call into the panic machinery is traced through its
/// inlined frames (`llvm-symbolizer`) to its origin, the first frame outside `core`, and the check fails
/// naming every origin that [`PANIC_ALLOWLIST`] does not list.
fn no_panic_check(board: &str) -> Result<(), String> {
    let mut c = boards::board_cargo(board);
    c.args(["build", "--release", "--features", "panic-never"]);
    // Every path of the loop, the model maps' (program interpreter, libm), the task monitor's and PWA
    // feedback's included, whatever the image.
    c.env_remove("CONTROLLER_IMAGE")
        .env_remove("CONTROLLER_REJECTED_M")
        .env_remove("FIRMWARE_FAULT_INJECTION")
        .env("CONTROLLER_MODEL_MAPS", "1")
        .env("CONTROLLER_MONITOR", "1")
        .env("CONTROLLER_PWA", "1");
    let what = show(&c);
    println!("xtask: $ {what}");
    let out = c
        .output()
        .map_err(|e| format!("could not run `{what}`: {e}"))?;
    if out.status.success() {
        println!("xtask: {board}: the panic-never build links: no panicking path is reachable");
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !stderr.contains(PANIC_NEVER_SYMBOL) {
        eprintln!("{stderr}");
        return Err(format!("`{what}` failed ({})", out.status));
    }
    boards::build(board, None, true)?;
    let elf = boards::elf(board);
    let mut objdump = Command::new("llvm-objdump");
    objdump
        .args(["-d", "-C", "-l", "--no-show-raw-insn"])
        .arg(&elf);
    let listing = output(objdump).ok_or_else(|| {
        format!(
            "{board}: the release firmware has a reachable panicking path (the link needs \
             `{PANIC_NEVER_SYMBOL}`), and llvm-objdump (apt-get install llvm) is needed to name it"
        )
    })?;
    let mut calls = panic_calls(&listing);
    let elf_bytes = std::fs::read(&elf).map_err(|e| format!("reading {}: {e}", elf.display()))?;
    let file =
        object::File::parse(&*elf_bytes).map_err(|e| format!("reading {}: {e}", elf.display()))?;
    for c in &mut calls {
        c.location = c.constants.iter().find_map(|&a| panic_location(&file, a));
    }
    let chains = symbolize(&elf, &calls).ok_or_else(|| {
        "llvm-symbolizer (apt-get install llvm) is needed to trace the panicking paths".to_string()
    })?;
    let allow_text = std::fs::read_to_string(root().join(PANIC_ALLOWLIST)).unwrap_or_default();
    let allow = allowlist(&allow_text);
    let sites = origins(&calls, &chains);
    let (allowed, new): (Vec<_>, Vec<_>) = sites
        .iter()
        .partition(|s| allow.iter().any(|a| s.location.contains(a.as_str())));
    for s in &allowed {
        println!(
            "xtask: known panicking path (listed in {PANIC_ALLOWLIST}): {} ({}) -> {}",
            s.function, s.location, s.target
        );
    }
    if new.is_empty() {
        println!(
            "xtask: {board}: {} panicking path(s) remain, all in dependencies listed in {PANIC_ALLOWLIST}",
            allowed.len()
        );
        return Ok(());
    }
    let list: Vec<String> = new.iter().map(|s| format!("  {s}")).collect();
    Err(format!(
        "{board}: the release firmware has {} reachable panicking path(s) not listed in {PANIC_ALLOWLIST} \
         (origin, the first frame outside core, and the chain of inlined calls):\n{}",
        new.len(),
        list.join("\n")
    ))
}

/// Whether a (demangled) function name belongs to the panic machinery: core's panic entry points and the
/// helpers that only call them (`…_fail`, `…_failed`), defmt's panic, and the panic handler.
fn is_panic_machinery(name: &str) -> bool {
    let base = name.split('+').next().unwrap_or(name);
    base.contains("panic") || base.ends_with("_fail") || base.ends_with("_failed")
}

/// A call into the panic machinery found in the disassembly.
#[derive(Clone, Debug, PartialEq)]
struct PanicCall {
    /// The function the call instruction is in.
    function: String,
    /// The panic entry point called.
    target: String,
    /// Address of the call instruction (hex, without 0x).
    address: String,
    /// The last source line the listing gave before the call (used where the debug info says line 0).
    line: String,
    /// Values the call's argument registers r0–r3 were given by `movw`/`movt` before it: one of them is
    /// usually the address of the panic's `core::panic::Location` (see [`panic_location`]).
    constants: Vec<u32>,
    /// The panic's own `Location` (file:line:col, the `#[track_caller]` site), when found in the ELF.
    location: Option<String>,
}

/// Reads a `core::panic::Location` at `addr` in the ELF (`&str` file as pointer and length, then line and
/// column, 32-bit little-endian), if it is one: the file is UTF-8 and names a `.rs` file, line and column
/// are plausible. This is the exact site a panic reports, where the debug info of an inlined call may say
/// line 0.
fn panic_location(elf: &object::File, addr: u32) -> Option<String> {
    use object::{Object, ObjectSection};
    let read = |a: u32, n: u32| -> Option<&[u8]> {
        elf.sections().find_map(|s| {
            let start = s.address();
            let (a, n) = (u64::from(a), u64::from(n));
            if a < start || a + n > start + s.size() {
                return None;
            }
            let data = s.data().ok()?;
            data.get((a - start) as usize..(a - start + n) as usize)
        })
    };
    let raw = read(addr, 16)?;
    let word = |i: usize| -> Option<u32> {
        Some(u32::from_le_bytes(
            raw.get(4 * i..4 * i + 4)?.try_into().ok()?,
        ))
    };
    let (ptr, len, line, col) = (word(0)?, word(1)?, word(2)?, word(3)?);
    if !(1..=1024).contains(&len) || !(1..=1_000_000).contains(&line) || col > 10_000 {
        return None;
    }
    let file = std::str::from_utf8(read(ptr, len)?).ok()?;
    file.ends_with(".rs")
        .then(|| format!("{}:{line}:{col}", short_path(file)))
}

/// From an `llvm-objdump -d -C --no-show-raw-insn` listing: every call (`bl`, `blx`, `b`, `b.w`) from a
/// function outside the panic machinery into it.
fn panic_calls(listing: &str) -> Vec<PanicCall> {
    let mut function = String::new();
    let mut line = String::new();
    let mut found = Vec::new();
    // r0–r3 as set by movw/movt since the function's start or the last call (which clobbers them).
    let mut regs: [Option<u32>; 4] = [None; 4];
    for l in listing.lines() {
        let t = l.trim();
        if let Some(name) = t
            .strip_suffix(">:")
            .and_then(|h| h.split_once(" <"))
            .map(|(_, n)| n)
        {
            // `$t`, `$d`, `$a`: Arm mapping symbols (code/data markers inside a function), not functions.
            if !name.starts_with('$') {
                function = name.to_string();
                line.clear();
                regs = [None; 4];
            }
            continue;
        }
        if let Some(src) = t.strip_prefix("; ") {
            if src.contains(".rs:") {
                line = src.to_string();
            }
            continue;
        }
        if function.is_empty() || is_panic_machinery(&function) {
            continue;
        }
        let mut words = t.split_whitespace();
        let address = words.next().unwrap_or("").trim_end_matches(':');
        let op = words.next().unwrap_or("");
        if op == "movw" || op == "movt" {
            let reg = words.next().unwrap_or("").trim_end_matches(',');
            let imm = words
                .next()
                .and_then(|w| w.strip_prefix('#'))
                .and_then(|w| w.parse::<u32>().ok());
            let slot = match reg {
                "r0" => Some(0),
                "r1" => Some(1),
                "r2" => Some(2),
                "r3" => Some(3),
                _ => None,
            };
            if let (Some(i), Some(imm)) = (slot, imm) {
                regs[i] = Some(if op == "movw" {
                    imm
                } else {
                    (regs[i].unwrap_or(0) & 0xFFFF) | (imm << 16)
                });
            }
            continue;
        }
        let is_branch = op.starts_with("bl") || op == "b" || op.starts_with("b.");
        let target = t.split_once('<').and_then(|(_, r)| r.rsplit_once('>'));
        if let (true, Some((target, _))) = (is_branch, target) {
            let target = target.split('+').next().unwrap_or(target);
            if is_panic_machinery(target) {
                found.push(PanicCall {
                    function: function.clone(),
                    target: target.to_string(),
                    address: address.to_string(),
                    line: line.clone(),
                    constants: regs.iter().flatten().copied().collect(),
                    location: None,
                });
            }
        }
        if op.starts_with("bl") {
            regs = [None; 4];
        }
    }
    found
}

/// The inlined frames (function, location), innermost first, of each call's address, from
/// `llvm-symbolizer --inlining`; `None` if the tool is missing or fails.
fn symbolize(elf: &Path, calls: &[PanicCall]) -> Option<Vec<Vec<(String, String)>>> {
    use std::io::Write as _;
    let mut child = Command::new("llvm-symbolizer")
        .args(["--inlining", "--demangle"])
        .arg(format!("--obj={}", elf.display()))
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .ok()?;
    let input: String = calls.iter().map(|c| format!("0x{}\n", c.address)).collect();
    child.stdin.take()?.write_all(input.as_bytes()).ok()?;
    let out = child.wait_with_output().ok()?;
    if !out.status.success() {
        return None;
    }
    Some(parse_frames(&String::from_utf8_lossy(&out.stdout)))
}

/// llvm-symbolizer's output: per address, lines `function` / `file:line:col` in pairs, then a blank line.
fn parse_frames(text: &str) -> Vec<Vec<(String, String)>> {
    text.split("\n\n")
        .filter(|b| !b.trim().is_empty())
        .map(|b| {
            let lines: Vec<&str> = b.lines().filter(|l| !l.trim().is_empty()).collect();
            lines
                .chunks(2)
                .map(|p| {
                    (
                        demangle(p.first().copied().unwrap_or("")),
                        short_path(p.get(1).copied().unwrap_or("")),
                    )
                })
                .collect()
        })
        .collect()
}

/// Readable legacy Rust symbol names: hash suffix dropped, `$LT$`-style escapes replaced.
fn demangle(name: &str) -> String {
    let mut s = name.trim().to_string();
    if let Some(i) = s.rfind("::h") {
        if s.len() - i == 19 && s[i + 3..].chars().all(|c| c.is_ascii_hexdigit()) {
            s.truncate(i);
        }
    }
    for (from, to) in [
        ("$LT$", "<"),
        ("$GT$", ">"),
        ("$u20$", " "),
        ("$u7b$", "{"),
        ("$u7d$", "}"),
        ("$u5b$", "["),
        ("$u5d$", "]"),
        ("$u3b$", ";"),
        ("$RF$", "&"),
        ("$C$", ","),
        ("..", "::"),
    ] {
        s = s.replace(from, to);
    }
    s.strip_prefix('_')
        .filter(|r| r.starts_with('<'))
        .map(str::to_string)
        .unwrap_or(s)
}

/// A source path without the registry, toolchain or workspace prefix.
fn short_path(path: &str) -> String {
    let p = path.trim();
    if let Some(i) = p.find("index.crates.io-") {
        if let Some(j) = p[i..].find('/') {
            return p[i + j + 1..].to_string();
        }
    }
    if let Some(i) = p.find("/library/") {
        return format!("rust{}", &p[i..]);
    }
    let root = root().display().to_string();
    p.strip_prefix(&root)
        .map(|r| r.trim_start_matches('/').to_string())
        .unwrap_or_else(|| p.to_string())
}

/// One panicking path: its origin (the innermost frame outside Rust's own library), the panic entry point
/// it reaches, and the chain of inlined frames from the origin outwards.
#[derive(Clone, Debug, PartialEq)]
struct PanicSite {
    function: String,
    location: String,
    target: String,
    chain: Vec<String>,
}

impl std::fmt::Display for PanicSite {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({}) -> {}",
            self.function, self.location, self.target
        )?;
        if !self.chain.is_empty() {
            write!(
                f,
                "\n      called from {}",
                self.chain.join("\n      called from ")
            )?;
        }
        Ok(())
    }
}

/// The sites of `calls` (deduplicated by origin location and target).
fn origins(calls: &[PanicCall], chains: &[Vec<(String, String)>]) -> Vec<PanicSite> {
    let mut out: Vec<PanicSite> = Vec::new();
    for (i, call) in calls.iter().enumerate() {
        let frames = chains.get(i).cloned().unwrap_or_default();
        let k = frames
            .iter()
            .position(|(_, loc)| !loc.starts_with("rust/library/"))
            .unwrap_or(0);
        let (function, mut location) = frames
            .get(k)
            .cloned()
            .unwrap_or_else(|| (call.function.clone(), "?".into()));
        match &call.location {
            // The panic's own Location, outside Rust's library: the exact site, whatever the debug info
            // of the inlined frames says.
            Some(site) if !site.starts_with("rust/library/") => location = site.clone(),
            // Line 0: code the compiler made up (no line of its own); the listing's last line before the
            // call is the nearest source line.
            _ if (location.ends_with(":0:0") || location.contains(":0:"))
                && !call.line.is_empty() =>
            {
                location = format!("{} (nearest line before the call)", short_path(&call.line));
            }
            _ => {}
        }
        // Each frame's location is where the *next outer* frame's call happened, so the caller chain pairs
        // the outer function with the location one frame in.
        let chain = frames
            .iter()
            .skip(k + 1)
            .map(|(f, l)| format!("{f} ({l})"))
            .take(6)
            .collect();
        let site = PanicSite {
            function,
            location,
            target: call.target.clone(),
            chain,
        };
        if !out
            .iter()
            .any(|s| s.location == site.location && s.target == site.target)
        {
            out.push(site);
        }
    }
    out
}

/// The allowlist's entries: one path fragment per line; `#` starts a comment.
fn allowlist(text: &str) -> Vec<String> {
    text.lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .filter(|l| !l.is_empty())
        .map(str::to_string)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A listing shaped like `llvm-objdump -d -C -l --no-show-raw-insn` output for thumbv7em.
    const LISTING: &str = "
00000400 <firmware::app::App::on_frame>:
; /work/firmware/src/app.rs:140
     400:      \tpush\t{r4, r5, r7, lr}
; /work/shared-types/src/eval.rs:212
     404:      \tbl\t0x900 <core::panicking::panic_bounds_check> @ imm = #1276
     408:      \tbl\t0x500 <shared_types::eval::Controller::step>

00000480 <$t>:
     480:      \tb.w\t0x910 <core::slice::index::slice_index_fail+0x2>

00000900 <core::panicking::panic_bounds_check>:
     900:      \tbl\t0x920 <core::panicking::panic_fmt>
";

    #[test]
    fn finds_each_call_into_the_panic_machinery_and_its_function() {
        let calls = panic_calls(LISTING);
        let got: Vec<(&str, &str, &str)> = calls
            .iter()
            .map(|c| (c.function.as_str(), c.target.as_str(), c.address.as_str()))
            .collect();
        assert_eq!(
            got,
            [
                (
                    "firmware::app::App::on_frame",
                    "core::panicking::panic_bounds_check",
                    "404"
                ),
                // A mapping symbol is not a function: the call belongs to on_frame.
                (
                    "firmware::app::App::on_frame",
                    "core::slice::index::slice_index_fail",
                    "480"
                ),
            ]
        );
        let clean = LISTING
            .replace("0x900 <core::panicking::panic_bounds_check>", "0x900 <foo>")
            .replace(
                "0x910 <core::slice::index::slice_index_fail+0x2>",
                "0x910 <bar>",
            );
        assert!(panic_calls(&clean).is_empty());
    }

    #[test]
    fn the_argument_registers_set_before_a_panic_call_are_kept_for_its_location() {
        let listing = "
00001f00 <mps2_an386::__cortex_m_rt_main>:
    1f3c:      \tmovw\tr0, #1656
    1f40:      \tmovw\tr2, #916
    1f44:      \tmovt\tr0, #1
    1f48:      \tmovt\tr2, #1
    1f4c:      \tmovs\tr1, #27
    1f4e:      \tbl\t0x4a24 <core::panicking::panic> @ imm = #10962
    1f52:      \tmovw\tr5, #7
    1f60:      \tbl\t0x4a24 <core::panicking::panic> @ imm = #10926
";
        let calls = panic_calls(listing);
        assert_eq!(calls.len(), 2);
        // r0 = 0x10678 (the message), r2 = 0x10394 (the Location).
        assert_eq!(calls[0].constants, [0x1_0678, 0x1_0394]);
        // A call clobbers r0–r3, and r5 is no argument register.
        assert!(calls[1].constants.is_empty());
    }

    #[test]
    fn the_origin_is_the_first_frame_outside_core_and_the_allowlist_matches_it() {
        let symbolizer = "\
_$LT$core..ops..range..Range$LT$usize$GT$$GT$::index::h01ae804ad2a2d4d4
/rustc/5980/library/core/src/slice/index.rs:443:13
shared_types::protocol::Vector$LT$_$GT$::as_slice::h52113ec7db15a4b7
/root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/cobs-0.3.0/src/dec.rs:77:19
firmware::app::App::on_frame::h1c786a80a053fc5d
/somewhere/firmware/src/app.rs:104:46

";
        let chains = parse_frames(symbolizer);
        let calls = [PanicCall {
            function: "main".into(),
            target: "core::slice::index::slice_index_fail".into(),
            address: "3428".into(),
            line: String::new(),
            constants: Vec::new(),
            location: None,
        }];
        let sites = origins(&calls, &chains);
        assert_eq!(sites.len(), 1);
        assert_eq!(
            sites[0].function,
            "shared_types::protocol::Vector<_>::as_slice"
        );
        assert_eq!(sites[0].location, "cobs-0.3.0/src/dec.rs:77:19");
        assert_eq!(sites[0].chain.len(), 1);
        let allow = allowlist("# comment\ncobs-0.3.0/src/dec.rs  # why\n\n");
        assert_eq!(allow, ["cobs-0.3.0/src/dec.rs"]);
        assert!(allow.iter().any(|a| sites[0].location.contains(a.as_str())));
    }
}
