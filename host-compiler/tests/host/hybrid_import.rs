//! Recordings on a hybrid plant with internal switching (Example 4.25; issues #12 "import" and #15 item
//! 3): a recording written from a run `plan_run` certified is replayed on the automaton, split at its
//! event and certified by the synth path's certificate (its δ is `certify_run`'s of the replayed
//! segments, and its next segment starts inside the planned run's next ball, as Theorem 4.24 says it
//! must); it joins `synthesize_hybrid`'s runs first and is re-proved from the image bytes; recordings
//! that never cross the guard, or cross into Unsafe, are refused with their reason; `synth --import`
//! takes a hybrid spec; and the game plays the hybrid plant over HTTP, its answers carrying the location,
//! its finished runs certified or refused through the same path.

use host_compiler::synth::hybrid::{
    certify_run, import, plan_run, synthesize_hybrid, HybridOptions, HybridRun, HybridTask,
    GUARD_DEPTHS,
};
use host_compiler::trajectory::csv::Recording;
use serde_json::json;
use std::path::PathBuf;
use std::sync::OnceLock;

pub fn spec_path() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-internal-4-25.toml"
    ))
}

fn task() -> HybridTask {
    HybridTask::new(host_compiler::spec::load(spec_path()).unwrap()).unwrap()
}

/// The run `plan_run` certifies from Init's centre, planned once for the module's tests.
pub fn planned() -> &'static (HybridTask, HybridRun) {
    static RUN: OnceLock<(HybridTask, HybridRun)> = OnceLock::new();
    RUN.get_or_init(|| {
        let t = task();
        let run = plan_run(&t, &t.problem.init.centre()).unwrap();
        assert!(run.certificate.is_certified(), "{:?}", run.certificate);
        (t, run)
    })
}

/// The sample period in which the exact flow along segment 0's nominal switches.
fn switch_period(t: &HybridTask, run: &HybridRun) -> usize {
    let nom = &run.nominals[0];
    (0..nom.steps())
        .find(|&k| {
            !t.plant
                .flow(t.path[0], &nom.x[k], &nom.u[k])
                .unwrap()
                .events
                .is_empty()
        })
        .expect("the planned run switches")
}

/// The recording a person would have made of the planned run: x0, segment 0's rows up to its switch,
/// then segment 1's rows.
pub fn recording_of(t: &HybridTask, run: &HybridRun) -> Recording {
    let ke = switch_period(t, run);
    let mut v = run.nominals[0].v[..=ke].to_vec();
    v.extend_from_slice(&run.nominals[1].v);
    Recording {
        x0: run.nominals[0].x[0].clone(),
        v,
        locations: None,
        given: Default::default(),
    }
}

/// The recording as `play` and `synth --import` write and read it.
fn csv_of(rec: &Recording, h: f64) -> String {
    let x0: Vec<String> = rec.x0.iter().map(|a| format!("{a:?}")).collect();
    let mut s = format!("# x0 = {}\nt,v1\n", x0.join(", "));
    for (k, r) in rec.v.iter().enumerate() {
        s.push_str(&format!("{:?},{:?}\n", k as f64 * h, r[0]));
    }
    s
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-hybrid-import-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn a_recorded_certified_run_is_accepted_with_the_synth_paths_certificate() {
    let (t, run) = planned();
    let rec = recording_of(t, run);
    let ke = switch_period(t, run);
    let replay = import::replay(t, &rec).unwrap();
    // Split at the event: segment 1 starts at the first sample after it, its rows the recording's rest.
    assert_eq!(replay.starts, vec![0, ke + 1]);
    assert_eq!(replay.nominals[0].x[..=ke], run.nominals[0].x[..=ke]);
    assert_eq!(replay.nominals[1].v, run.nominals[1].v);
    // Where the replay lands is inside the planned run's next ball (Theorem 4.24's safe transition).
    let p1 = t.designs[t.path[1]].P.as_ref();
    let e: Vec<f64> = replay.nominals[1].x[0]
        .iter()
        .zip(&run.nominals[1].x[0])
        .map(|(a, b)| a - b)
        .collect();
    let d1 = host_compiler::linalg::p_norm(p1, &e);
    assert!(
        d1 < run.certificate.segments[1].delta,
        "{d1} vs {}",
        run.certificate.segments[1].delta
    );
    // Accepted, with exactly the certificate the synth path gives the replayed segments.
    let got = import::certify_recording(t, &rec).unwrap();
    assert!(got.delta() > 0.0);
    assert_eq!(
        got.certificate,
        certify_run(t, &got.nominals).unwrap(),
        "one certificate"
    );
    // Its segments are the replay's (segment 1 from the replayed landing or from the centre of the
    // landings, with the recorded rows), segment 0 extended to the first sample d deep in the guard;
    // the best of those candidates.
    let centred = replay.centred(t).unwrap();
    assert_eq!(centred.nominals[1].v, replay.nominals[1].v);
    let (mut best, mut found) = (0.0f64, false);
    for split in [&replay, &centred] {
        for &d in &GUARD_DEPTHS {
            let Some(ext) = split.extended(t, d) else {
                continue;
            };
            let k = ext[0].steps();
            assert!(k > ke && t.plant.edges()[t.edges[0]].guard.margin(&ext[0].x[k]) <= -d);
            let c = certify_run(t, &ext).unwrap();
            best = best.max(c.delta());
            if ext == got.nominals {
                assert_eq!(c, got.certificate);
                found = true;
            }
        }
    }
    assert!(found);
    assert_eq!(got.delta(), best);
    eprintln!(
        "planned δ = {:.4e}, imported δ = {:.4e} ({})",
        run.delta(),
        got.delta(),
        import::bindings(t, &got.locations, &got.certificate)
    );
}

#[test]
fn recordings_that_do_not_cross_or_cross_into_unsafe_are_refused_with_the_reason() {
    let (t, run) = planned();
    let rec = recording_of(t, run);
    // The first 20 rows only: the run is still far from the plane x1 = 0.
    let short = Recording {
        x0: rec.x0.clone(),
        v: rec.v[..20].to_vec(),
        locations: None,
        given: Default::default(),
    };
    let e = import::certify_recording(t, &short).unwrap_err();
    assert!(
        matches!(
            e,
            import::ImportError::NoSwitch {
                segment: 0,
                rows: 20,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains("never takes the path's edge 0 (left → right)"),
        "{e}"
    );
    // Cut right after the switch: the next segment has no samples.
    let ke = switch_period(t, run);
    let cut = Recording {
        x0: rec.x0.clone(),
        v: rec.v[..=ke].to_vec(),
        locations: None,
        given: Default::default(),
    };
    let e = import::certify_recording(t, &cut).unwrap_err();
    assert!(
        matches!(e, import::ImportError::EndsAtSwitch { segment: 0, .. }),
        "{e}"
    );
    // A wrong shape.
    let bad = Recording {
        x0: vec![0.0; 2],
        v: rec.v.clone(),
        locations: None,
        given: Default::default(),
    };
    assert!(matches!(
        import::certify_recording(t, &bad),
        Err(import::ImportError::Shape { x0: 2, n: 3, .. })
    ));
    // Into Unsafe: the same inputs from another start switch elsewhere and land inside the ball.
    let into = Recording {
        x0: unsafe_start(t, &rec),
        v: rec.v.clone(),
        locations: None,
        given: Default::default(),
    };
    let e = import::certify_recording(t, &into).unwrap_err();
    let why = e.to_string();
    assert!(matches!(e, import::ImportError::Refused(_)), "{why}");
    assert!(
        why.contains("segment 1 (right) certifies no radius"),
        "{why}"
    );
    assert!(why.contains("δ_Unsafe = -"), "{why}");
}

/// A start from which the recording's inputs cross the plane into Unsafe: the first of a grid over Init
/// and the strip beside it up to x1 = −3 (where the planned run's inputs land in the ball; a recording's
/// start need not lie in Init) whose replay lands there.
fn unsafe_start(t: &HybridTask, rec: &Recording) -> Vec<f64> {
    for i in (0..13).rev() {
        for j in 0..9 {
            for k in 0..17 {
                let x0 = vec![
                    -6.0 + 0.25 * i as f64,
                    0.25 * j as f64,
                    -4.0 + 0.5 * k as f64,
                ];
                let into = Recording {
                    x0: x0.clone(),
                    v: rec.v.clone(),
                    locations: None,
                    given: Default::default(),
                };
                let Ok(r) = import::replay(t, &into) else {
                    continue;
                };
                if r.nominals.len() > 1
                    && t.property
                        .unsafe_region()
                        .unwrap()
                        .contains(&r.nominals[1].x[0])
                {
                    return x0;
                }
            }
        }
    }
    panic!("no start of the grid over Init lands in Unsafe");
}

#[test]
fn an_imported_run_joins_the_synthesis_first_and_is_re_proved_from_the_image() {
    let (_, run) = planned();
    let mut problem = host_compiler::spec::load(spec_path()).unwrap();
    problem.synthesis.max_trajectories = 1;
    let t = HybridTask::new(problem).unwrap();
    let rec = recording_of(&t, run);
    let expected = import::certify_recording(&t, &rec).unwrap();
    let opts = HybridOptions {
        working_samples: 50,
        verify_interior: 16,
        verify_per_ball: 4,
        imports: vec![("rec.csv".into(), rec)],
        ..HybridOptions::default()
    };
    let s = synthesize_hybrid(&t, &opts).unwrap();
    assert_eq!(s.imported.len(), 1);
    assert_eq!(s.imported[0].1, Ok(expected.delta()));
    assert_eq!(s.runs.len(), 1, "the budget of one run is the import");
    assert_eq!(s.runs[0].certificate, expected.certificate);
    assert!(s.recheck[0].ok, "{:?}", s.recheck[0]);
    assert_eq!(s.verify.violations, 0);
    assert!(s.stop.contains("budget"), "{}", s.stop);
}

#[test]
fn synth_import_takes_a_hybrid_spec() {
    let (t, run) = planned();
    let dir = scratch("cli");
    let rec = recording_of(t, run);
    std::fs::write(dir.join("a.csv"), csv_of(&rec, t.plant.period())).unwrap();
    let far = Recording {
        x0: rec.x0.clone(),
        v: rec.v[..20].to_vec(),
        locations: None,
        given: Default::default(),
    };
    std::fs::write(dir.join("b.csv"), csv_of(&far, t.plant.period())).unwrap();
    let src = std::fs::read_to_string(spec_path())
        .unwrap()
        .replace("max_trajectories = 32", "max_trajectories = 1");
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, src).unwrap();
    let out = dir.join("out");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .args([
            "synth",
            spec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(["--verify-runs", "16", "--import", dir.to_str().unwrap()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{stdout}\n{stderr}");
    assert!(stderr.contains("a.csv: imported, δ = "), "{stderr}");
    assert!(
        stderr.contains("b.csv: not used: segment 0 (left): the run never takes the path's edge"),
        "{stderr}"
    );
    assert!(stdout.contains("re-proved         1 of 1 runs"), "{stdout}");
    let cert: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("certificate.json")).unwrap())
            .unwrap();
    let d = cert["imported"][0]["delta"].as_f64().unwrap();
    assert_eq!(
        cert["runs"][0]["certificate"]["segments"][0]["delta"].as_f64(),
        Some(d)
    );
    assert!(cert["imported"][1]["why"].as_str().is_some(), "{cert}");
}

#[test]
fn the_game_plays_the_hybrid_plant_and_certifies_its_runs() {
    use crate::play_server::{post, request};
    let (t, run) = planned();
    let rec = recording_of(t, run);
    let out = scratch("play");
    let game = host_compiler::play::Game::hybrid(
        task(),
        host_compiler::play::PlaySettings {
            out: out.clone(),
            projection: None,
            slow: 1.0 / 3.0,
        },
    )
    .unwrap();
    let srv = host_compiler::play::serve(game, "127.0.0.1:0".parse().unwrap()).unwrap();
    let a = srv.addr;
    let (code, w) = request(a, "GET", "/api/world", "");
    assert_eq!(code, 200, "{w}");
    assert_eq!(w["locations"], 2);
    assert_eq!(w["location_names"], json!(["left", "right"]));
    // The planned run's inputs, sample by sample, from its start.
    let (code, s) = post(a, "/api/start", &json!({"player": "Ann", "x0": rec.x0}));
    assert_eq!(code, 200, "{s}");
    let id = s["session"].as_u64().unwrap();
    let mut last = json!(null);
    let mut seen = Vec::new();
    for v in &rec.v {
        let (code, r) = post(a, "/api/step", &json!({"session": id, "v": v}));
        assert_eq!(code, 200, "{r}");
        seen.push(r["location_name"].as_str().unwrap().to_string());
        last = r;
        if last["status"] != "running" {
            break;
        }
    }
    assert_eq!(seen.first().map(String::as_str), Some("left"));
    assert!(seen.iter().any(|l| l == "right"), "the run switched");
    if last["status"] == "running" {
        let (code, r) = post(a, "/api/finish", &json!({"session": id}));
        assert_eq!(code, 200, "{r}");
        last = r;
    }
    let result = &last["result"];
    assert_eq!(result["accepted"], true, "{last}");
    assert!(result["delta"].as_f64().unwrap() > 0.0);
    let why = result["reason"].as_str().unwrap();
    assert!(why.contains("segment 1 (right)"), "{why}");
    // Its recording reads back through `synth --import`'s path to the same δ.
    let files = host_compiler::trajectory::csv::recordings_in(&out).unwrap();
    assert_eq!(files.len(), 1, "{files:?}");
    let back =
        host_compiler::trajectory::csv::load_recording(&files[0], 3, 1, 0.01, t.steps).unwrap();
    let again = import::certify_recording(t, &back).unwrap();
    assert_eq!(again.delta(), result["delta"].as_f64().unwrap());
    // A run that holds v = 0 for a few samples and stops is refused: it never reaches the guard.
    let (_, s) = post(a, "/api/start", &json!({"player": "Bob", "x0": rec.x0}));
    let id = s["session"].as_u64().unwrap();
    let (_, r) = post(
        a,
        "/api/step",
        &json!({"session": id, "v": [0.0], "steps": 10, "finish": true}),
    );
    assert_eq!(r["location"], 0, "{r}");
    assert_eq!(r["result"]["accepted"], false, "{r}");
    let why = r["result"]["reason"].as_str().unwrap();
    assert!(
        why.contains("refused: segment 0 (left): the run never takes the path's edge"),
        "{why}"
    );
    let (_, st) = request(a, "GET", "/api/state", "");
    assert_eq!(st["accepted"], 1);
    srv.stop();
}
