//! Importing what a user has (issue 47, items 2 and 3): a route as applied inputs `u` or as states alone
//! is certified through the references derived once K̂ is designed (`trajectory::track`), an untrackable
//! one is refused naming the sample, and the refusals say what limits the search and what to do.

use host_compiler::certify::OwnedLoop;
use host_compiler::cover::{certify_recording, GrowError};
use host_compiler::synth::{synthesize, SynthError, SynthOptions};
use host_compiler::task::Task;
use host_compiler::trajectory::csv::{parse_import, Coordinates, Given};
use host_compiler::trajectory::track::TrackError;
use std::process::Command;

fn example(name: &str) -> String {
    std::fs::read_to_string(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

fn double_integrator() -> host_compiler::spec::Problem {
    host_compiler::spec::parse(&example("double-integrator.toml"), "spec.toml").unwrap()
}

/// A route to Goal as applied accelerations: +a for the first half of the 40 samples, −a after, from
/// rest at 0 (a = 0.25 ends at rest at position 1, the centre of Goal).
fn bang_bang(a: f64) -> Vec<f64> {
    (0..40).map(|k| if k < 20 { a } else { -a }).collect()
}

/// The states of the double integrator (h = 0.1, exact ZOH) from rest at 0 under `u`.
fn states_of(u: &[f64]) -> Vec<[f64; 2]> {
    let mut x = vec![[0.0, 0.0]];
    for &a in u {
        let [p, v] = *x.last().unwrap();
        x.push([p + 0.1 * v + 0.005 * a, v + 0.1 * a]);
    }
    x
}

fn csv_applied(u: &[f64]) -> String {
    let mut s = "# x0 = 0, 0\nt,u1\n".to_string();
    for (k, a) in u.iter().enumerate() {
        s.push_str(&format!("{},{a}\n", k as f64 * 0.1));
    }
    s
}

fn csv_states(x: &[[f64; 2]]) -> String {
    let mut s = "t,x1,x2\n".to_string();
    for (k, r) in x.iter().enumerate() {
        s.push_str(&format!("{},{},{}\n", k as f64 * 0.1, r[0], r[1]));
    }
    s
}

#[test]
fn applied_inputs_certify_with_the_nominal_of_their_references() {
    let ol = OwnedLoop::from_problem(&double_integrator()).unwrap();
    let (lp, lc) = (ol.lp(), ol.constants().unwrap());
    let u = bang_bang(0.25);
    let rec = parse_import(&csv_applied(&u), "u.csv", 2, 1, 0.1, 40, Coordinates::Plant).unwrap();
    assert!(matches!(rec.given, Given::Applied(_)));
    let (nom, cert) = certify_recording(&lp, &lc, &rec).unwrap();
    assert!(cert.is_certified(), "{cert:?}");
    // The nominal is the run of the applied inputs.
    for (a, b) in nom.x.iter().zip(states_of(&u)) {
        assert!(
            (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6,
            "{a:?} {b:?}"
        );
    }
    // The equivalent references v = u − K̂x along the run, as a recording of v: the same nominal and
    // certificate.
    let gain = [lp.K[(0, 0)], lp.K[(0, 1)]];
    let mut v_csv = "# x0 = 0, 0\nt,v1\n".to_string();
    for (k, (a, x)) in u.iter().zip(states_of(&u)).enumerate() {
        v_csv.push_str(&format!(
            "{},{}\n",
            k as f64 * 0.1,
            a - gain[0] * x[0] - gain[1] * x[1]
        ));
    }
    let vrec = parse_import(&v_csv, "v.csv", 2, 1, 0.1, 40, Coordinates::Plant).unwrap();
    assert_eq!(vrec.given, Given::References);
    let (vnom, vcert) = certify_recording(&lp, &lc, &vrec).unwrap();
    for (a, b) in nom.x.iter().zip(&vnom.x) {
        assert!(
            a.iter().zip(b).all(|(p, q)| (p - q).abs() < 1e-9),
            "{a:?} {b:?}"
        );
    }
    assert!(
        (cert.delta - vcert.delta).abs() < 1e-9,
        "{} {}",
        cert.delta,
        vcert.delta
    );
}

#[test]
fn states_alone_are_followed_within_the_bound_and_certify() {
    let ol = OwnedLoop::from_problem(&double_integrator()).unwrap();
    let (lp, lc) = (ol.lp(), ol.constants().unwrap());
    let x = states_of(&bang_bang(0.25));
    let rec = parse_import(&csv_states(&x), "x.csv", 2, 1, 0.1, 40, Coordinates::Plant).unwrap();
    assert!(matches!(rec.given, Given::States(_)));
    let (nom, cert) = certify_recording(&lp, &lc, &rec).unwrap();
    assert!(cert.is_certified(), "{cert:?}");
    for (a, b) in nom.x.iter().zip(&x) {
        assert!(
            (a[0] - b[0]).abs() < 1e-5 && (a[1] - b[1]).abs() < 1e-5,
            "{a:?} {b:?}"
        );
    }
}

#[test]
fn states_the_input_bound_cannot_follow_are_refused_naming_the_sample() {
    let ol = OwnedLoop::from_problem(&double_integrator()).unwrap();
    let (lp, lc) = (ol.lp(), ol.constants().unwrap());
    // |u| ≤ 1, but this route brakes at 3 over its last ten samples.
    let u: Vec<f64> = (0..40).map(|k| if k < 30 { 0.5 } else { -3.0 }).collect();
    let rec = parse_import(
        &csv_states(&states_of(&u)),
        "fast.csv",
        2,
        1,
        0.1,
        40,
        Coordinates::Plant,
    )
    .unwrap();
    let e = certify_recording(&lp, &lc, &rec).unwrap_err();
    let TrackError::Untrackable {
        sample, residual, ..
    } = e
    else {
        panic!("{e}")
    };
    // The braking starts with the input of step 30, so sample 31 is the first the bound cannot reach.
    assert!(sample == 31 && residual > 0.0, "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains("from sample 31 on (t = 3.100 s") && msg.contains("within the input bound"),
        "{msg}"
    );
}

/// Synthesis of `src` with `imports`, which must end without a certified trajectory: its attempts and
/// message.
fn nothing_certified(
    src: &str,
    imports: Vec<(String, host_compiler::trajectory::csv::Recording)>,
) -> (host_compiler::cover::Attempts, usize, String) {
    let p = host_compiler::spec::parse(src, "spec.toml").unwrap();
    let opts = SynthOptions {
        verify_interior: 100,
        verify_per_ball: 1,
        progress: false,
        imports,
        ..SynthOptions::default()
    };
    let e = match synthesize(&Task::new(p).unwrap(), &opts) {
        Ok(s) => panic!("certified {} trajectories", s.trajectories.len()),
        Err(e) => e,
    };
    let msg = e.to_string();
    match e {
        SynthError::Cover(GrowError::NoSeed { attempts, failed }) => (*attempts, failed, msg),
        other => panic!("not a 'no seed' outcome: {other}"),
    }
}

#[test]
fn when_every_recording_given_is_refused_the_message_names_them_and_the_search_stops_after_a_round()
{
    // Goal out of reach in 1 s (|u| ≤ 1 moves the position at most 0.5): nothing certifies; a
    // recording given is refused too.
    let src = example("double-integrator.toml").replacen("horizon = 4.0", "horizon = 1.0", 1);
    let rec = parse_import(
        &csv_applied(&[0.5; 10]),
        "mine.csv",
        2,
        1,
        0.1,
        10,
        Coordinates::Plant,
    )
    .unwrap();
    let (a, failed, msg) = nothing_certified(&src, vec![("mine.csv".into(), rec)]);
    assert_eq!(a.imports.len(), 1, "{msg}");
    assert!(
        msg.contains("every recording given was refused: mine.csv: bound by δ_Goal"),
        "{msg}"
    );
    assert!(msg.contains("does not end inside Goal"), "{msg}");
    // The route given comes first: it is what the user mends.
    assert!(
        msg.find("mine.csv") < msg.find("the local generator"),
        "{msg}"
    );
    // One round of the batch (4 seeds) and no more.
    assert_eq!(a.stopped_after, Some(failed), "{msg}");
    assert_eq!(failed, 4, "{msg}");
    assert!(
        msg.contains("stopped after its first round (4 seeds"),
        "{msg}"
    );
    // The generator's refusal says what limits it and what to do.
    assert!(a.first_refusal.is_some(), "{msg}");
    for what in [
        "the local generator found no trajectory",
        "not a proof that none exists",
        "synth --import",
        "host-compiler play",
        "longer horizon T",
        "routes of the global search",
    ] {
        assert!(msg.contains(what), "`{what}` not in: {msg}");
    }
}

#[test]
fn without_recordings_the_search_goes_on_after_its_first_round() {
    let src = example("double-integrator.toml").replacen("horizon = 4.0", "horizon = 1.0", 1);
    let (a, failed, msg) = nothing_certified(&src, Vec::new());
    assert!(a.imports.is_empty() && a.stopped_after.is_none(), "{msg}");
    assert!(failed > 4, "{msg}");
    assert!(!msg.contains("every recording given"), "{msg}");
}

#[test]
fn a_hybrid_plant_refuses_applied_inputs_and_states_with_a_reason() {
    let dir = std::env::temp_dir().join(format!("import-inputs-hybrid-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let spec = format!(
        "{}/../examples/hybrid-forced-cart.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let p = host_compiler::spec::load(&spec).unwrap();
    let (n, m) = (p.plant.n(), p.plant.m());
    let h = p.plant.period;
    let mut csv = format!("# x0 = {}\nt", vec!["0"; n].join(", "));
    for j in 1..=m {
        csv.push_str(&format!(",u{j}"));
    }
    csv.push('\n');
    for k in 0..3 {
        csv.push_str(&format!("{}{}\n", k as f64 * h, ",0".repeat(m)));
    }
    let file = dir.join("u.csv");
    std::fs::write(&file, csv).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .args(["synth", &spec, "--quiet", "--import"])
        .arg(&file)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("applied inputs") && err.contains("hybrid plant"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_feedback_linearizable_plant_s_recording_is_in_its_linear_model_s_coordinates() {
    let p = host_compiler::spec::parse(&example("fl-pendulum.toml"), "spec.toml").unwrap();
    let ol = OwnedLoop::from_problem(&p).unwrap();
    let (lp, lc) = (ol.lp(), ol.constants().unwrap());
    let model = lp.model();
    let (n, m, h) = (model.A.nrows(), model.B.ncols(), model.period);
    let init = &ol.task.problem.init;
    let x0: Vec<f64> = (0..n)
        .map(|i| (0.5 * (init.lo[i] + init.hi[i])) as f32 as f64)
        .collect();
    // The states ξ and the inputs w of the linear model; x0 is the first row's state.
    let w: Vec<Vec<f64>> = (0..20)
        .map(|k| vec![0.05 * (k as f64 * 0.3).sin(); m])
        .collect();
    let mut csv = "t".to_string();
    (1..=n).for_each(|i| csv.push_str(&format!(",xi{i}")));
    (1..=m).for_each(|j| csv.push_str(&format!(",w{j}")));
    csv.push('\n');
    let x = host_compiler::trajectory::track::replay(model, &x0, &w);
    for (k, xk) in x.iter().enumerate() {
        let wk = w.get(k).map_or(vec![0.0; m], Clone::clone);
        let fields: Vec<String> = xk.iter().chain(&wk).map(|v| v.to_string()).collect();
        csv.push_str(&format!("{},{}\n", k as f64 * h, fields.join(",")));
    }
    let rec = parse_import(&csv, "xi.csv", n, m, h, 800, Coordinates::Linearized).unwrap();
    assert!(matches!(rec.given, Given::Applied(_)));
    let (nom, _) = certify_recording(&lp, &lc, &rec).unwrap();
    for (a, b) in nom.x.iter().zip(&x) {
        assert!(
            a.iter().zip(b).all(|(p, q)| (p - q).abs() < 1e-6),
            "{a:?} {b:?}"
        );
    }
    for (a, b) in nom.u.iter().zip(&w) {
        assert!(
            a.iter().zip(b).all(|(p, q)| (p - q).abs() < 1e-6),
            "{a:?} {b:?}"
        );
    }
    // `synth --import` reads such a plant's recordings in ξ: the plant's own x and u are refused.
    let dir = std::env::temp_dir().join(format!("import-inputs-fl-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("plant.csv");
    std::fs::write(&file, "# x0 = 0, 0\nt,x1,x2,u1\n0,0,0,0\n0.005,0,0,0\n").unwrap();
    let spec = format!(
        "{}/../examples/fl-pendulum.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let out = Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .args(["synth", &spec, "--quiet", "--import"])
        .arg(&file)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("linear model's"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
