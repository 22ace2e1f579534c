//! The game and `synth --import` beyond one linear location (issue #15 item 3, "any plant class"):
//!
//! * forced switching (§4.2.1, the forced cart `examples/hybrid-forced-cart.toml`): a planned run written
//!   as a recording with its `location` column certifies through the import path to the planned δ; a
//!   recording without the column, one that starts elsewhere, names an unknown location or switches by
//!   an edge the automaton lacks, or (for a formula task) is shorter than the horizon, is refused, saying
//!   so; in the game the player switches by `"location"`,
//!   a switch outside the edge's guard waits with the reason, and a played run is certified, written with
//!   its locations and reads back to the same δ;
//! * feedback linearizable (§3.1.2, Example 4.9 `examples/fl-4-9.toml`): the game flows the nonlinear
//!   plant (its ξ leaves the linear model's prediction), a tracking bot's run is accepted, its recording
//!   (in ξ) certifies again to the same δ through `cover::certify_recording`, and `synth --import` takes
//!   it;
//! * an MTL task on one location (`examples/planar-vehicle-waypoints.toml`): a run finished before T is
//!   refused (the formula is judged over the horizon), a planned ball's rows played to T certify to its δ
//!   by Theorem 4.2, and `synth --import` on the formula task takes the run.

use host_compiler::play::{Game, PlaySettings};
use host_compiler::synth::hybrid::{forced::plan_forced, import, HybridRun, HybridTask};
use host_compiler::trajectory::csv::{load_recording, recordings_in, Recording};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

fn example(name: &str) -> PathBuf {
    PathBuf::from(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR")))
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-play-plants-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn settings(out: &Path) -> PlaySettings {
    PlaySettings {
        out: out.to_path_buf(),
        projection: None,
        slow: 1.0 / 3.0,
    }
}

/// The forced cart's spec text with `edit` applied, written under `dir`.
fn cart_variant(dir: &Path, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(example("hybrid-forced-cart.toml")).unwrap();
    let p = dir.join("cart.toml");
    std::fs::write(&p, edit(text)).unwrap();
    p
}

fn forced_task(spec: &Path) -> HybridTask {
    HybridTask::new(host_compiler::spec::load(spec).unwrap()).unwrap()
}

/// A run's recording as `play` writes it: x0, every segment's rows, each with its location's name.
fn recording_of(t: &HybridTask, run: &HybridRun) -> Recording {
    let (mut v, mut names) = (Vec::new(), Vec::new());
    for (nom, &l) in run.nominals.iter().zip(&run.locations) {
        v.extend(nom.v.iter().cloned());
        names.extend(std::iter::repeat_n(
            t.plant.modes()[l].name.clone(),
            nom.v.len(),
        ));
    }
    Recording {
        x0: run.nominals[0].x[0].clone(),
        v,
        locations: Some(names),
        given: Default::default(),
    }
}

#[test]
fn a_forced_recording_with_its_locations_certifies_as_planned_and_bad_ones_are_refused() {
    let t = forced_task(&example("hybrid-forced-cart.toml"));
    let run = plan_forced(&t, &[0.0, 0.0]).unwrap();
    assert_eq!(run.locations, vec![0, 1], "forward then backward");
    let rec = recording_of(&t, &run);
    let got = import::certify_recording(&t, &rec).unwrap();
    assert_eq!(got.locations, run.locations);
    let (a, b) = (got.delta(), run.delta());
    assert!(
        a > 0.0 && (a - b).abs() <= 1e-12 * b,
        "imported {a}, planned {b}"
    );

    let with = |locations: Option<Vec<String>>| Recording {
        locations,
        ..rec.clone()
    };
    let e = import::certify_recording(&t, &with(None)).unwrap_err();
    assert_eq!(e, import::ImportError::Forced);
    assert!(e.to_string().contains("no `location` column"), "{e}");

    let mut names = rec.locations.clone().unwrap();
    names[0] = "backward".into();
    let e = import::certify_recording(&t, &with(Some(names))).unwrap_err();
    assert!(
        e.to_string()
            .contains("the run starts in backward; the task's initial location is forward"),
        "{e}"
    );

    let mut names = rec.locations.clone().unwrap();
    names[3] = "sideways".into();
    let e = import::certify_recording(&t, &with(Some(names))).unwrap_err();
    assert!(
        e.to_string().contains(
            "row 3 (t = 0.30 s): `sideways` is not a location of the automaton (its locations: \
             forward, backward)"
        ),
        "{e}"
    );

    // Switching on to the last row leaves the cart running forward past Goal: refused, with the segment.
    let last = rec.v.len() - 1;
    let names: Vec<String> = (0..rec.v.len())
        .map(|k| if k < last { "forward" } else { "backward" }.to_string())
        .collect();
    let e = import::certify_recording(&t, &with(Some(names))).unwrap_err();
    assert!(
        matches!(e, import::ImportError::Refused(_)) && e.to_string().contains("segment"),
        "{e}"
    );

    // With a formula as the task (the cart's MTL example), a recording must cover the horizon.
    let tf = forced_task(&example("hybrid-forced-cart-mtl.toml"));
    assert!(tf.formula.is_some());
    let short = Recording {
        x0: rec.x0.clone(),
        v: rec.v[..10].to_vec(),
        locations: Some(rec.locations.clone().unwrap()[..10].to_vec()),
        given: Default::default(),
    };
    let e = import::certify_recording(&tf, &short).unwrap_err();
    assert_eq!(
        e,
        import::ImportError::ShortForFormula {
            rows: 10,
            steps: tf.steps
        }
    );

    // Without the edge backward → forward, a run that switches back is refused by name.
    let dir = scratch("no-back-edge");
    let spec = cart_variant(&dir, |s| {
        s.replace(
            "[[plant.edge]]\nfrom = \"backward\"\nto = \"forward\"\nkind = \"forced\"\n",
            "",
        )
    });
    let one_way = forced_task(&spec);
    assert_eq!(one_way.plant.edges().len(), 1);
    let mut names = rec.locations.clone().unwrap();
    let k = names.len() - 2;
    names[k + 1] = "forward".into();
    let e = import::certify_recording(&one_way, &with(Some(names))).unwrap_err();
    assert!(
        e.to_string().contains(&format!(
            "row {} (t = {:.2} s): the run switches backward → forward, but no forced edge leads \
             from backward to forward",
            k + 1,
            (k + 1) as f64 * 0.1
        )),
        "{e}"
    );
}

/// `synth SPEC --import DIR` with a budget of one trajectory (the spec's): exit 3 (Init not covered), its
/// stdout and stderr.
fn synth_importing(spec: &Path, dir: &Path, out: &Path) -> (String, String) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .arg("synth")
        .arg(spec)
        .args(["--quiet", "--verify-runs", "200", "--import"])
        .arg(dir)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    let (so, se) = (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    );
    assert_eq!(o.status.code(), Some(3), "{so}\n{se}");
    (so, se)
}

/// `game.step` with `body`, which must be accepted.
fn step(game: &mut Game, body: Value) -> Value {
    game.step(&body).unwrap_or_else(|e| panic!("{body}: {e}"))
}

#[test]
fn the_player_switches_a_forced_automaton_within_the_guard_and_the_run_is_certified() {
    let dir = scratch("forced-game");
    // The switch forward → backward only from x1 ≥ 3 m (the shipped cart may switch anywhere).
    let spec = cart_variant(&dir, |s| {
        s.replacen(
            "to = \"backward\"\nkind = \"forced\"\n",
            "to = \"backward\"\nkind = \"forced\"\nguard = { A = [[-1.0, 0.0]], b = [-3.0] }\n",
            1,
        )
    });
    let t = forced_task(&spec);
    let run = plan_forced(&t, &[0.0, 0.0]).unwrap();
    let rec = recording_of(&t, &run);
    let out = dir.join("runs");
    let mut game = Game::hybrid(forced_task(&spec), settings(&out)).unwrap();
    let world = game.world(None).unwrap();
    assert_eq!(
        world["switches"][0],
        json!({"from": 0, "to": 1, "from_name": "forward", "to_name": "backward"})
    );

    let s = game.start(&json!({"player": "Ann", "x0": rec.x0})).unwrap();
    let id = s["session"].as_u64().unwrap();
    // A location that does not exist is a bad request; the run goes on.
    let e = game
        .step(&json!({"session": id, "v": [0.0], "location": "sideways"}))
        .unwrap_err();
    assert!(
        e.to_string().contains("`sideways` is not a location"),
        "{e}"
    );
    // At x1 = 0 the guard x1 ≥ 3 does not hold: the switch waits, saying why.
    let r = step(
        &mut game,
        json!({"session": id, "v": rec.v[0], "location": "backward"}),
    );
    assert_eq!(r["switch"]["done"], false, "{r}");
    assert!(
        r["switch"]["reason"]
            .as_str()
            .unwrap()
            .contains("not in the guard of forward → backward"),
        "{r}"
    );
    assert_eq!(r["location_name"], "forward");
    // The planned run's rows, each asking for its own location: the switch is taken where planned.
    let names = rec.locations.as_ref().unwrap();
    let mut last = r;
    let mut switched_at = None;
    for (k, v) in rec.v.iter().enumerate().skip(1) {
        last = step(
            &mut game,
            json!({"session": id, "v": v, "location": names[k]}),
        );
        if last["switch"]["done"] == true {
            switched_at = Some(k);
        }
        if last["status"] != "running" {
            break;
        }
    }
    assert_eq!(switched_at, Some(run.nominals[0].v.len()), "{last}");
    if last["status"] == "running" {
        last = game.finish(&json!({"session": id})).unwrap();
    }
    let result = &last["result"];
    assert_eq!(result["accepted"], true, "{last}");
    let delta = result["delta"].as_f64().unwrap();
    assert!(delta > 0.0);
    assert!(
        result["reason"]
            .as_str()
            .unwrap()
            .contains("segment 1 (backward)"),
        "{last}"
    );
    // Written with its locations; read back, it certifies to the same δ.
    let files = recordings_in(&out).unwrap();
    assert_eq!(files.len(), 1, "{files:?}");
    let text = std::fs::read_to_string(&files[0]).unwrap();
    assert!(text.contains("t,v1,location\n"), "{text}");
    let back = load_recording(&files[0], 2, 1, 0.1, t.steps).unwrap();
    assert_eq!(back.locations.as_ref().map(Vec::len), Some(back.v.len()));
    let again = import::certify_recording(&t, &back).unwrap();
    assert_eq!(again.delta(), delta);
}

#[test]
#[allow(non_snake_case)] // K, the gain, as the text writes it
fn the_game_flows_a_feedback_linearizable_plant_and_its_runs_import() {
    use host_compiler::certify::{Loop, LoopConstants};
    let out = scratch("fl-game");
    let spec = example("fl-4-9.toml");
    let task = host_compiler::task::Task::new(host_compiler::spec::load(&spec).unwrap()).unwrap();
    let mut game = Game::new(task, settings(&out)).unwrap();
    let world = game.world(None).unwrap();
    assert!(
        world["law"].as_str().unwrap().contains("nonlinear plant"),
        "{world}"
    );
    assert_eq!(world["labels"], json!(["ξ1", "ξ3"]));
    let K: Vec<Vec<f64>> = serde_json::from_value(world["K"].clone()).unwrap();
    let x0 = [0.0, 0.0, 0.0, 1.0];
    let s = game.start(&json!({"player": "bot", "x0": x0})).unwrap();
    let id = s["session"].as_u64().unwrap();
    // A tracking bot: a PD law to Goal's centre (2, 0) in w, the drift 1 − p + 0.1ṗ cancelled, |w| ≤ 1.6;
    // the reference is v = w − Kξ (found by playing; the server certifies it).
    let (mut x, mut last, mut first_step) = (x0.to_vec(), Value::Null, None);
    for _ in 0..500 {
        let a = [
            1.5 * (2.0 - x[0]) - 2.2 * x[1],
            4.0 * (0.0 - x[2]) - 5.0 * x[3],
        ];
        let mut w: [f64; 2] = [
            a[0] - (1.0 - x[0] + 0.1 * x[1]),
            a[1] - (1.0 - x[2] + 0.1 * x[3]),
        ];
        let nw = w[0].hypot(w[1]);
        if nw > 1.6 {
            w = [w[0] * 1.6 / nw, w[1] * 1.6 / nw];
        }
        let v: Vec<f64> = (0..2)
            .map(|i| w[i] - (0..4).map(|j| K[i][j] * x[j]).sum::<f64>())
            .collect();
        let before = x.clone();
        last = step(&mut game, json!({"session": id, "v": v}));
        x = serde_json::from_value(last["x"].clone()).unwrap();
        if first_step.is_none() {
            first_step = Some((before, last["v"].clone(), x.clone()));
        }
        if last["status"] != "running" {
            break;
        }
    }
    // The plant the game flows is the nonlinear one: one period departs from the linear model in ξ
    // (by the sampled-loop mismatch), though not by much.
    let (before, v, after) = first_step.unwrap();
    let v: Vec<f64> = serde_json::from_value(v).unwrap();
    let u: Vec<f64> = (0..2)
        .map(|i| v[i] + (0..4).map(|j| K[i][j] * before[j]).sum::<f64>())
        .collect();
    let task = host_compiler::task::Task::new(host_compiler::spec::load(&spec).unwrap()).unwrap();
    let linear = task.plant.step(0, &before, &u);
    let gap = linear
        .iter()
        .zip(&after)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(gap > 0.0 && gap < 1e-3, "one period's departure {gap:e}");

    assert_eq!(last["status"], "goal", "{last}");
    let result = &last["result"];
    assert_eq!(result["accepted"], true, "{last}");
    let delta = result["delta"].as_f64().unwrap();
    // The recording, in ξ, certifies again through the import path.
    let files = recordings_in(&out).unwrap();
    assert_eq!(files.len(), 1);
    let rec = load_recording(&files[0], 4, 2, 0.01, task.steps).unwrap();
    let design = host_compiler::caf::design(&task).unwrap();
    let lp = Loop::new(&task, &design);
    let lc = LoopConstants::new(&lp).unwrap();
    let (_, cert) = host_compiler::cover::certify_recording(&lp, &lc, &rec).unwrap();
    assert_eq!(cert.delta, delta);

    // `synth --import` takes the directory (a budget of one trajectory: the imported run, then exit 3).
    let dir = scratch("fl-import");
    let one = dir.join("fl.toml");
    let text = std::fs::read_to_string(&spec)
        .unwrap()
        .replace("[synthesis]\n", "[synthesis]\nmax_trajectories = 1\n");
    std::fs::write(&one, text).unwrap();
    let (so, se) = synth_importing(&one, &out, &dir.join("out"));
    assert!(so.contains("trajectories      1"), "{so}\n{se}");
    assert!(so.contains(", 0 violations"), "{so}\n{se}");
    let cert: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/certificate.json")).unwrap())
            .unwrap();
    let d = cert["trajectories"][0]["certificate"]["delta"]
        .as_f64()
        .unwrap();
    assert!(d >= delta, "the imported run, then §5.3: {d} vs {delta}");
}

#[test]
fn a_formula_task_plays_to_the_horizon_and_its_runs_import() {
    use host_compiler::property::TemporalTask;
    let spec = example("planar-vehicle-waypoints.toml");
    let problem = host_compiler::spec::load(&spec).unwrap();
    let tt = TemporalTask::from_problem(&problem).unwrap();
    let task = host_compiler::task::Task::new(problem).unwrap();
    let centre = task.problem.init.centre();
    let (ball, _) = host_compiler::synth::temporal::single_ball(&task, &tt, &centre).unwrap();
    assert!(ball.certificate.is_certified());
    let out = scratch("mtl-game");
    let mut game = Game::new(task, settings(&out)).unwrap();
    let world = game.world(None).unwrap();
    assert!(world["formula"].as_str().is_some(), "{world}");
    let x0 = ball.nominal.x[0].clone();

    // Finished before T: refused, the formula being judged over the whole horizon.
    let s = game.start(&json!({"player": "Ann", "x0": x0})).unwrap();
    let id = s["session"].as_u64().unwrap();
    let r = step(
        &mut game,
        json!({"session": id, "v": ball.nominal.v[0], "steps": 10, "finish": true}),
    );
    assert_eq!(r["result"]["accepted"], false, "{r}");
    assert!(
        r["result"]["reason"]
            .as_str()
            .unwrap()
            .contains("judged over the whole horizon"),
        "{r}"
    );

    // The ball's rows played sample by sample: the run does not stop in Goal, it goes on to T, and is
    // certified by the formula to the ball's δ (the game steps the same exact ZOH as the nominal).
    let s = game.start(&json!({"player": "Ann", "x0": x0})).unwrap();
    let id = s["session"].as_u64().unwrap();
    let mut last = Value::Null;
    for (k, v) in ball.nominal.v.iter().enumerate() {
        last = step(&mut game, json!({"session": id, "v": v}));
        if last["status"] != "running" {
            assert_eq!(k + 1, ball.nominal.v.len(), "{last}");
            break;
        }
    }
    // Ended at T, not before (the loop's check): in Goal there ("goal") or not ("timeout").
    assert!(
        last["status"] == "timeout" || last["status"] == "goal",
        "{last}"
    );
    let result = &last["result"];
    assert_eq!(result["accepted"], true, "{last}");
    let d = result["delta"].as_f64().unwrap();
    let want = ball.certificate.delta;
    assert!(
        (d - want).abs() <= 1e-6 * want,
        "played {d}, planned {want}"
    );
    assert!(
        result["reason"]
            .as_str()
            .unwrap()
            .contains("the formula (Theorem 4.2): ρ(0)"),
        "{last}"
    );

    // `synth --import` on the formula task takes it (a budget of one ball: the imported one).
    let dir = scratch("mtl-import");
    let one = dir.join("waypoints.toml");
    let text = std::fs::read_to_string(&spec)
        .unwrap()
        .replace("max_trajectories = 64\n", "max_trajectories = 1\n");
    assert!(text.contains("max_trajectories = 1\n"));
    std::fs::write(&one, text).unwrap();
    let (so, se) = synth_importing(&one, &out, &dir.join("out"));
    assert!(se.contains(": imported, δ = "), "{so}\n{se}");
    assert!(
        so.contains("trajectories      1 (0 seeds tried)"),
        "{so}\n{se}"
    );
    assert!(so.contains(", 0 violations"), "{so}\n{se}");
}
