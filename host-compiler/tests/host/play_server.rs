//! `host-compiler play`'s server (issue 15): every malformed or invalid request is a clear JSON error
//! and the server keeps serving; two players play at once, each run certified on its own; an accepted
//! run is written as a recording that `synth --import DIR` reads and that certifies again to the same δ;
//! a restarted game takes the runs already in its directory; the number of runs in play is capped.

use host_compiler::play::{serve, Game, PlaySettings, Served};
use serde_json::{json, Value};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};

/// A run to Goal from (0, 0) on the planar vehicle (Example 4.8): the reference v held per segment for
/// the given samples (found by playing; the server certifies it, nothing here assumes a δ).
pub const GOAL_SCRIPT: &[([f64; 2], usize)] = &[
    ([0.11, -0.33], 187),
    ([0.21, -0.87], 190),
    ([-0.02, -0.77], 105),
];
/// Straight into the obstacle from (0.1, 0.1).
pub const CRASH_SCRIPT: &[([f64; 2], usize)] = &[([0.6, -0.8], 500)];

/// The script as the page's `script=` parameter.
pub fn script_param(s: &[([f64; 2], usize)]) -> String {
    s.iter()
        .map(|(v, k)| format!("{},{}*{k}", v[0], v[1]))
        .collect::<Vec<_>>()
        .join(";")
}

pub fn spec_path() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/planar-vehicle.toml"
    ))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-play-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn game(out: &Path) -> Game {
    let problem = host_compiler::spec::load(spec_path()).unwrap();
    let task = host_compiler::task::Task::new(problem).unwrap();
    Game::new(
        task,
        PlaySettings {
            out: out.to_path_buf(),
            projection: None,
            slow: 1.0 / 3.0,
        },
    )
    .unwrap()
}

fn start_server(out: &Path) -> Served {
    serve(game(out), "127.0.0.1:0".parse().unwrap()).unwrap()
}

/// One raw HTTP/1.1 exchange: the status code and the body.
fn raw(addr: SocketAddr, request: &[u8]) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(60)))
        .unwrap();
    s.write_all(request).unwrap();
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    let text = String::from_utf8_lossy(&buf).into_owned();
    let code = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let body = text
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_string())
        .unwrap_or_default();
    (code, body)
}

pub fn request(addr: SocketAddr, method: &str, path: &str, body: &str) -> (u16, Value) {
    let req = format!(
        "{method} {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    let (code, body) = raw(addr, req.as_bytes());
    let v = serde_json::from_str(&body).unwrap_or(Value::String(body));
    (code, v)
}

pub fn post(addr: SocketAddr, path: &str, body: &Value) -> (u16, Value) {
    request(addr, "POST", path, &body.to_string())
}

fn error_of(r: &(u16, Value)) -> String {
    r.1["error"].as_str().unwrap_or_default().to_string()
}

/// Plays a script from `at`; the final answer (with the run's result).
pub fn play(addr: SocketAddr, player: &str, at: [f64; 2], script: &[([f64; 2], usize)]) -> Value {
    let (code, s) = post(addr, "/api/start", &json!({"player": player, "at": at}));
    assert_eq!(code, 200, "{s}");
    let id = s["session"].as_u64().unwrap();
    for (v, k) in script {
        let (code, r) = post(
            addr,
            "/api/step",
            &json!({"session": id, "v": v, "steps": k}),
        );
        assert_eq!(code, 200, "{r}");
        if r["status"] != "running" {
            return r;
        }
    }
    let (code, r) = post(addr, "/api/finish", &json!({"session": id}));
    assert_eq!(code, 200, "{r}");
    r
}

#[test]
fn malformed_requests_get_clear_errors_and_the_server_keeps_serving() {
    let out = scratch("malformed");
    let srv = start_server(&out);
    let a = srv.addr;
    let r = request(a, "POST", "/api/start", "{not json");
    assert_eq!(r.0, 400);
    assert!(error_of(&r).starts_with("malformed JSON"), "{r:?}");
    let r = post(a, "/api/start", &json!([1, 2]));
    assert_eq!(
        (r.0, error_of(&r).as_str()),
        (400, "the body must be a JSON object")
    );
    let r = post(a, "/api/start", &json!({"at": [0, 0]}));
    assert!(error_of(&r).contains("`player`"), "{r:?}");
    let r = post(a, "/api/start", &json!({"player": "p", "at": [1.0, 0.0]}));
    assert_eq!(r.0, 400);
    assert_eq!(
        error_of(&r),
        "the start is not in Init: x1 = 1 is outside [-0.2, 0.2]"
    );
    let r = post(a, "/api/start", &json!({"player": "p", "x0": [0, 0, 0, 0]}));
    assert!(error_of(&r).contains("x4 = 0 is outside [1, 1]"), "{r:?}");
    let r = post(a, "/api/start", &json!({"player": "p", "at": [0, "a"]}));
    assert!(error_of(&r).contains("`at`[1]"), "{r:?}");
    let r = post(a, "/api/start", &json!({"player": "p", "at": [0]}));
    assert!(
        error_of(&r).contains("`at` has 1 numbers; the task needs 2"),
        "{r:?}"
    );
    let r = post(a, "/api/start", &json!({"player": "", "at": [0, 0]}));
    assert!(error_of(&r).contains("1 to 40 characters"), "{r:?}");
    // A run, then wrong input dimensions, steps and sessions.
    let (_, s) = post(a, "/api/start", &json!({"player": "p", "at": [0, 0]}));
    let id = s["session"].as_u64().unwrap();
    let r = post(a, "/api/step", &json!({"session": id, "v": [0, 0, 0]}));
    assert_eq!(r.0, 400);
    assert_eq!(error_of(&r), "`v` has 3 numbers; the task needs 2");
    let r = post(
        a,
        "/api/step",
        &json!({"session": id, "v": [0, 0], "steps": 0}),
    );
    assert!(error_of(&r).contains("from 1 to 500"), "{r:?}");
    let r = post(
        a,
        "/api/step",
        &json!({"session": id, "v": [0, 0], "steps": 501}),
    );
    assert!(error_of(&r).contains("from 1 to 500"), "{r:?}");
    let r = post(a, "/api/step", &json!({"session": 999, "v": [0, 0]}));
    assert_eq!(r.0, 404);
    assert!(error_of(&r).starts_with("unknown session 999"), "{r:?}");
    let r = post(a, "/api/step", &json!({"session": "x", "v": [0, 0]}));
    assert!(error_of(&r).contains("`session` must be"), "{r:?}");
    // Methods, paths, sizes, and bytes that are not HTTP at all.
    let r = request(a, "GET", "/api/step", "");
    assert_eq!(r.0, 405, "{r:?}");
    let r = request(a, "GET", "/nothing", "");
    assert_eq!(r.0, 404, "{r:?}");
    let big = format!("{{\"player\": \"{}\"}}", "a".repeat(70_000));
    let r = request(a, "POST", "/api/start", &big);
    assert_eq!(r.0, 413, "{r:?}");
    let _ = raw(a, b"\x00\x01garbage\r\n\r\n");
    // The run in play is untouched by all that, and the server still answers.
    let (code, r) = post(
        a,
        "/api/step",
        &json!({"session": id, "v": [0, 0], "steps": 3}),
    );
    assert_eq!(code, 200, "{r}");
    assert_eq!(r["k"], 3);
    assert_eq!(r["states"].as_array().unwrap().len(), 3);
    let (code, w) = request(a, "GET", "/api/world", "");
    assert_eq!(code, 200);
    assert_eq!(w["n"], 4);
    // Another projection of the state: drawn from the same sets; a bad one is refused.
    let (code, w) = request(a, "GET", "/api/world?projection=2,3", "");
    assert_eq!(code, 200, "{w}");
    assert_eq!(w["labels"], json!(["x3", "x4"]));
    for bad in ["1,1", "0,4", "a,b", "0"] {
        let r = request(a, "GET", &format!("/api/world?projection={bad}"), "");
        assert_eq!(r.0, 400, "{bad}: {r:?}");
        assert!(
            error_of(&r).contains("two different coordinate indices from 0 to 3"),
            "{r:?}"
        );
    }
    let r = post(
        a,
        "/api/start",
        &json!({"player": "p", "at": [0.5, 1.0], "projection": [2, 3]}),
    );
    assert_eq!(
        error_of(&r),
        "the start is not in Init: x3 = 0.5 is outside [0, 0]"
    );
    let (code, page) = raw(a, b"GET / HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n");
    assert_eq!(code, 200);
    assert!(page.contains("safety-compiler play"), "the page is served");
    srv.stop();
}

#[test]
fn two_players_at_once_each_certified_and_the_accepted_run_reads_back() {
    let out = scratch("two");
    let srv = start_server(&out);
    let a = srv.addr;
    let (r1, r2) = std::thread::scope(|s| {
        let t1 = s.spawn(|| play(a, "Ann", [0.0, 0.0], GOAL_SCRIPT));
        let t2 = s.spawn(|| play(a, "Bob", [0.1, 0.1], CRASH_SCRIPT));
        (t1.join().unwrap(), t2.join().unwrap())
    });
    assert_ne!(r1["session"], r2["session"]);
    assert_eq!(r1["status"], "goal", "{r1}");
    assert_eq!(r1["result"]["accepted"], true, "{r1}");
    let delta = r1["result"]["delta"].as_f64().unwrap();
    assert!(delta > 0.0);
    assert!(r1["result"]["new_coverage"].as_f64().unwrap() > 0.0);
    assert_eq!(r2["status"], "unsafe", "{r2}");
    assert_eq!(r2["result"]["accepted"], false, "{r2}");
    let why = r2["result"]["reason"].as_str().unwrap();
    assert!(why.contains("entered Unsafe at t = "), "{why}");
    assert!(
        why.contains("Unsafe: the tube meets Unsafe at t = "),
        "{why}"
    );
    // The table has both, and only Ann's run covers anything.
    let (_, st) = request(a, "GET", "/api/state", "");
    assert_eq!(st["accepted"], 1);
    let runs = st["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert!(st["coverage"].as_f64().unwrap() > 0.0);
    assert!(st["covered"].as_str().unwrap().contains('1'));
    // The state's paths are thinned, ends kept; the run's own answer had all its samples.
    let ann = runs.iter().find(|r| r["player"] == "Ann").unwrap();
    let thin = ann["path"].as_array().unwrap();
    let full = r1["result"]["path"].as_array().unwrap();
    assert!(thin.len() <= host_compiler::play::game::STATE_PATH_POINTS + 1);
    assert_eq!(full.len(), r1["k"].as_u64().unwrap() as usize + 1);
    assert_eq!((thin.first(), thin.last()), (full.first(), full.last()));
    assert!(runs
        .iter()
        .all(|r| r["accepted"] == true || r.get("path").is_none()));
    // Ann's recording is in the directory, and reads as `synth --import DIR` reads it.
    let files = host_compiler::trajectory::csv::recordings_in(&out).unwrap();
    assert_eq!(files.len(), 1, "{files:?}");
    let name = files[0].file_name().unwrap().to_string_lossy().into_owned();
    assert_eq!(Some(name.as_str()), r1["result"]["file"].as_str());
    assert!(name.ends_with("-ann.csv"), "{name}");
    let text = std::fs::read_to_string(&files[0]).unwrap();
    assert!(text.contains("# player = Ann"), "{text}");
    assert!(text.contains("# played = 20"), "{text}");
    assert!(text.contains("# ending = goal"), "{text}");
    let rec = host_compiler::trajectory::csv::load_recording(&files[0], 4, 2, 0.01, 500).unwrap();
    assert_eq!(rec.x0, vec![0.0, 0.0, 0.0, 1.0]);
    assert_eq!(rec.v.len(), r1["k"].as_u64().unwrap() as usize);
    srv.stop();
    // A new game on the same directory takes the run again, with the same coverage.
    let g = game(&out);
    assert_eq!(g.accepted(), 1);
    assert_eq!(g.coverage(), st["coverage"].as_f64().unwrap());
    let again = g.state();
    assert_eq!(again["runs"][0]["ending"], "goal");
    assert_eq!(again["runs"][0]["player"], "Ann");
    let ann = runs.iter().find(|r| r["player"] == "Ann").unwrap();
    assert_eq!(again["runs"][0]["delta"], ann["delta"]);
    assert_eq!(ann["delta"].as_f64().unwrap(), delta);
}

#[test]
fn a_run_that_idles_until_t_times_out_and_is_refused_for_goal() {
    let out = scratch("timeout");
    let srv = start_server(&out);
    let a = srv.addr;
    // A reference that holds the vehicle away from Goal and from the obstacle: T runs out.
    let (_, s) = post(
        a,
        "/api/start",
        &json!({"player": "idle", "at": [-0.1, 0.1]}),
    );
    let id = s["session"].as_u64().unwrap();
    let (_, r) = post(
        a,
        "/api/step",
        &json!({"session": id, "v": [-0.9, 0.0], "steps": 1}),
    );
    assert_eq!(r["status"], "running");
    assert_eq!(
        r["preview"].as_array().unwrap().len(),
        host_compiler::play::game::PREVIEW_STEPS
    );
    let (_, r) = post(
        a,
        "/api/step",
        &json!({"session": id, "v": [-0.9, 0.0], "steps": 500}),
    );
    assert_eq!(r["status"], "timeout", "{}", r["result"]["reason"]);
    assert_eq!(r["k"], 500);
    assert_eq!(r["result"]["accepted"], false);
    let why = r["result"]["reason"].as_str().unwrap();
    assert!(
        why.starts_with("the horizon T ran out at t = 5.00 s; refused: "),
        "{why}"
    );
    assert!(
        why.contains("Goal: not reached with a margin within T"),
        "{why}"
    );
    // The session is gone once its run ended.
    let r = post(a, "/api/step", &json!({"session": id, "v": [0, 0]}));
    assert_eq!(r.0, 404);
    assert!(host_compiler::trajectory::csv::recordings_in(&out)
        .unwrap()
        .is_empty());
    srv.stop();
}

#[test]
fn the_runs_in_play_are_capped() {
    let out = scratch("cap");
    let srv = start_server(&out);
    let a = srv.addr;
    for i in 0..host_compiler::play::game::MAX_SESSIONS {
        let r = post(
            a,
            "/api/start",
            &json!({"player": format!("p{i}"), "at": [0, 0]}),
        );
        assert_eq!(r.0, 200, "{r:?}");
    }
    let r = post(
        a,
        "/api/start",
        &json!({"player": "one more", "at": [0, 0]}),
    );
    assert_eq!(r.0, 503);
    assert!(error_of(&r).contains("runs are in play already"), "{r:?}");
    srv.stop();
}
