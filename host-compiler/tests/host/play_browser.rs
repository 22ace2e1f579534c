//! The game end to end in headless Chromium (issue 15): `host-compiler play` runs as a child process,
//! the page plays a scripted run (its `script=` URL parameter) to Goal, and the server certifies it
//! and the coverage map changes; a scripted run into Unsafe is refused, and the page shows why.
//!
//! Chromium is the Debian package `chromium` (`/usr/bin/chromium`, or `$CHROMIUM`); `cargo xtask test`
//! installs it. Without it this test fails and says how to install it.

use super::play_server::{script_param, spec_path, CRASH_SCRIPT, GOAL_SCRIPT};
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};

fn chromium() -> PathBuf {
    let p = std::env::var_os("CHROMIUM")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/bin/chromium"));
    assert!(
        p.exists(),
        "headless Chromium is needed for this test and {} does not exist: install it with \
         `apt-get install -y chromium` (as root), or run `cargo xtask test`, which installs it; \
         $CHROMIUM may name another binary",
        p.display()
    );
    p
}

/// The `play` child process, killed on drop.
struct Server {
    child: Child,
    url: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-play-browser-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn start(out: &std::path::Path) -> Server {
    start_spec(&spec_path(), out)
}

fn start_spec(spec: &std::path::Path, out: &std::path::Path) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .arg("play")
        .arg(spec)
        .args(["--port", "0", "--out"])
        .arg(out)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut line = String::new();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    stdout.read_line(&mut line).unwrap();
    // The rest of its output is read (and dropped) so that the child never writes to a closed pipe.
    std::thread::spawn(move || std::io::copy(&mut stdout, &mut std::io::sink()));
    let url = line
        .trim()
        .strip_prefix("play: ")
        .unwrap_or_else(|| panic!("`play` printed {line:?}, not its address"))
        .to_string();
    Server { child, url }
}

/// Runs headless Chromium on `url` with `extra` flags (`--dump-dom`, `--screenshot=…`); its stdout.
fn browse(url: &str, extra: &[String]) -> String {
    // One profile per call: tests run in parallel, and Chromium refuses a profile another instance holds.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let profile = scratch(&format!("profile-{call}"));
    let out = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--virtual-time-budget=30000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&profile);
    assert!(out.status.success(), "chromium failed: {out:?}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn get(url: &str) -> serde_json::Value {
    let rest = url.strip_prefix("http://").unwrap();
    let (host, path) = rest.split_once('/').unwrap();
    let mut s = std::net::TcpStream::connect(host).unwrap();
    use std::io::{Read, Write};
    write!(
        s,
        "GET /{path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut buf = String::new();
    s.read_to_string(&mut buf).unwrap();
    serde_json::from_str(buf.split_once("\r\n\r\n").unwrap().1).unwrap()
}

/// The text of the element with `id` in a dumped DOM.
fn element_text(dom: &str, id: &str) -> String {
    let at = dom
        .find(&format!("id=\"{id}\""))
        .unwrap_or_else(|| panic!("no #{id} in the page"));
    let rest = &dom[at..];
    let open = rest.find('>').unwrap() + 1;
    let close = rest[open..].find("</").unwrap();
    rest[open..open + close].to_string()
}

#[test]
fn scripted_runs_in_headless_chromium_are_certified_or_refused_with_the_reason_shown() {
    let out = scratch("runs");
    let srv = start(&out);
    let before = get(&format!("{}api/state", srv.url));
    assert_eq!(before["accepted"], 0);
    assert!(!before["covered"].as_str().unwrap().contains('1'));

    // A run to Goal: certified, written, and the coverage map changed.
    let url = format!(
        "{}?name=bot&start=0,0&script={}",
        srv.url,
        script_param(GOAL_SCRIPT)
    );
    let dom = browse(&url, &["--dump-dom".to_string()]);
    assert!(
        dom.contains("data-script=\"done\""),
        "the script did not finish: {dom}"
    );
    assert!(dom.contains("data-status=\"goal\""), "{dom}");
    assert!(dom.contains("data-accepted=\"yes\""), "{dom}");
    let shown = element_text(&dom, "result");
    assert!(shown.starts_with("ACCEPTED: δ = "), "{shown}");
    let after = get(&format!("{}api/state", srv.url));
    assert_eq!(after["accepted"], 1, "{after}");
    assert!(after["coverage"].as_f64().unwrap() > 0.0);
    assert_ne!(after["covered"], before["covered"]);
    let run = &after["runs"][0];
    assert_eq!(run["player"], "bot");
    assert!(run["delta"].as_f64().unwrap() > 0.0);
    assert!(
        shown.contains(&format!("{:.3e}", run["delta"].as_f64().unwrap())),
        "the page shows the server's δ: {shown}"
    );
    let files = host_compiler::trajectory::csv::recordings_in(&out).unwrap();
    assert_eq!(files.len(), 1);
    // The page's coverage figure is the server's.
    let cov = element_text(&dom, "coverage");
    assert_eq!(
        cov,
        format!("{:.1} %", 100.0 * after["coverage"].as_f64().unwrap())
    );

    // A run into Unsafe: refused, and the page says which set, when and by how much.
    let url = format!(
        "{}?name=crash&start=0.1,0.1&script={}",
        srv.url,
        script_param(CRASH_SCRIPT)
    );
    let dom = browse(&url, &["--dump-dom".to_string()]);
    assert!(dom.contains("data-status=\"unsafe\""), "{dom}");
    assert!(dom.contains("data-accepted=\"no\""), "{dom}");
    let shown = element_text(&dom, "result");
    assert!(shown.starts_with("REFUSED."), "{shown}");
    assert!(shown.contains("the run entered Unsafe at t = "), "{shown}");
    assert!(
        shown.contains("Unsafe: the tube meets Unsafe at t = ") && shown.contains(" by "),
        "{shown}"
    );
    let last = get(&format!("{}api/state", srv.url));
    assert_eq!(last["accepted"], 1, "the refused run is not in the cover");
    assert_eq!(last["runs"].as_array().unwrap().len(), 2);
    assert_eq!(last["covered"], after["covered"]);
    assert_eq!(
        host_compiler::trajectory::csv::recordings_in(&out)
            .unwrap()
            .len(),
        1
    );

    // The page renders (a screenshot of it after these runs, for a look by hand).
    let shot = out.join("page.png");
    browse(
        &format!("{}?name=viewer", srv.url),
        &[
            format!("--screenshot={}", shot.display()),
            "--window-size=1120,800".to_string(),
        ],
    );
    let png = std::fs::read(&shot).unwrap();
    assert!(png.starts_with(b"\x89PNG"), "a PNG screenshot");
}

/// The hybrid game (Example 4.25) in the page: the planned run's rows played sample by sample from Init's
/// centre (`start` gives x1, x2; x3 is the centre's) switch to the right location, and the run is
/// certified through the hybrid import path and shown accepted.
#[test]
fn a_scripted_run_on_a_hybrid_spec_is_certified_in_headless_chromium() {
    let (t, run) = crate::hybrid_import::planned();
    let rec = crate::hybrid_import::recording_of(t, run);
    let out = scratch("hybrid");
    let srv = start_spec(&crate::hybrid_import::spec_path(), &out);
    let script: Vec<String> = rec.v.iter().map(|v| format!("{}*1", v[0])).collect();
    let url = format!(
        "{}?name=bot&start={},{}&script={}",
        srv.url,
        rec.x0[0],
        rec.x0[1],
        script.join(";")
    );
    let dom = browse(&url, &["--dump-dom".to_string()]);
    assert!(
        dom.contains("data-script=\"done\""),
        "the script did not finish: {dom}"
    );
    assert!(dom.contains("data-accepted=\"yes\""), "{dom}");
    let shown = element_text(&dom, "result");
    assert!(shown.starts_with("ACCEPTED: δ = "), "{shown}");
    let st = get(&format!("{}api/state", srv.url));
    assert_eq!(st["accepted"], 1, "{st}");
    let reason = st["runs"][0]["reason"].as_str().unwrap();
    assert!(reason.contains("segment 1 (right)"), "{reason}");
}

#[test]
fn a_scripted_forced_run_switches_on_the_page_and_is_certified_in_headless_chromium() {
    use host_compiler::synth::hybrid::{forced::plan_forced, HybridTask};
    let spec = std::path::PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-forced-cart.toml"
    ));
    let t = HybridTask::new(host_compiler::spec::load(&spec).unwrap()).unwrap();
    let run = plan_forced(&t, &[0.0, 0.0]).unwrap();
    assert_eq!(run.locations, vec![0, 1]);
    let out = scratch("forced");
    let srv = start_spec(&spec, &out);
    // The planned rows, one per sample; the first row of segment 1 asks for `backward` (the page keeps
    // asking until the server takes the switch).
    let switch = run.nominals[0].v.len();
    let script: Vec<String> = run
        .nominals
        .iter()
        .flat_map(|n| n.v.iter())
        .enumerate()
        .map(|(k, v)| {
            let at = if k == switch { "@backward" } else { "" };
            format!("{}*1{at}", v[0])
        })
        .collect();
    let url = format!("{}?name=bot&start=0,0&script={}", srv.url, script.join(";"));
    let dom = browse(&url, &["--dump-dom".to_string()]);
    assert!(
        dom.contains("data-script=\"done\""),
        "the script did not finish: {dom}"
    );
    let msg = element_text(&dom, "switchmsg");
    assert_eq!(
        msg,
        format!("switched to backward at t = {:.2} s", switch as f64 * 0.1),
        "{dom}"
    );
    assert!(dom.contains("data-accepted=\"yes\""), "{dom}");
    let shown = element_text(&dom, "result");
    assert!(shown.starts_with("ACCEPTED: δ = "), "{shown}");
    let st = get(&format!("{}api/state", srv.url));
    assert_eq!(st["accepted"], 1, "{st}");
    let reason = st["runs"][0]["reason"].as_str().unwrap();
    assert!(reason.contains("segment 1 (backward)"), "{reason}");
}
