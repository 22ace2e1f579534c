//! `simulate` of hybrid images (issue 42 item 8) and of bad initial states (item 6): a one-run image of
//! Example 4.25 (internal switching) and of the forced cart, each simulated from its ball's centre. The
//! CSV's `location` column changes where the run switches (for internal switching in the period whose
//! `# event` line finds the flow on the guard; for forced switching at the sample the table switches);
//! its states are, sample for sample, those of `verify`'s Monte Carlo run
//! ([`host_compiler::verify::hybrid::run_hybrid`]); `mtl` reads the file as a trace and the import of
//! recordings as a recording of either kind of switching. `--x0` with a NaN or an infinity is bad input
//! naming the entry.

use host_compiler::synth::hybrid::{forced::plan_forced, image, import, HybridRun, HybridTask};
use host_compiler::trajectory::csv::parse_recording;
use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
}

/// A scratch directory of this test process.
fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hc-sim-hybrid-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The image of one certified run of `task`, written to `dir` (the spec's fingerprint stored).
fn write_image(dir: &Path, task: &HybridTask, run: &HybridRun) -> PathBuf {
    let img = dir.join("controller.img");
    std::fs::write(&img, image(task, std::slice::from_ref(run)).unwrap()).unwrap();
    img
}

/// The centre of the image's first ball.
fn centre(img: &Path) -> Vec<f64> {
    let bytes = std::fs::read(img).unwrap();
    let d = shared_types::image::decode(&bytes).unwrap();
    (0..d.n()).map(|i| d.centre(0, i) as f64).collect()
}

fn simulate(spec: &Path, img: &Path, x0: &str) -> std::process::Output {
    bin()
        .arg("simulate")
        .arg(spec)
        .arg(img)
        .args(["--x0", x0])
        .output()
        .unwrap()
}

fn x0_arg(x0: &[f64]) -> String {
    x0.iter()
        .map(|v| format!("{v:?}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// A simulated run's CSV: the header, the rows' fields, and each `# event` line with the number of rows
/// before it.
struct Run {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
    events: Vec<(usize, String)>,
}

impl Run {
    fn parse(text: &str) -> Run {
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        assert!(lines.next().unwrap().starts_with("# x0 = "), "{text:.300}");
        let mut header = Vec::new();
        let mut rows: Vec<Vec<String>> = Vec::new();
        let mut events = Vec::new();
        for l in lines {
            if let Some(e) = l.strip_prefix("# event ") {
                events.push((rows.len(), e.to_string()));
            } else if l.starts_with('#') {
                continue;
            } else if header.is_empty() {
                header = l.split(',').map(str::to_string).collect();
            } else {
                rows.push(l.split(',').map(str::to_string).collect());
            }
        }
        Run {
            header,
            rows,
            events,
        }
    }
    fn col(&self, name: &str) -> usize {
        self.header.iter().position(|h| h == name).unwrap()
    }
    fn location(&self, k: usize) -> &str {
        &self.rows[k][self.col("location")]
    }
    fn state(&self, k: usize, n: usize) -> Vec<f64> {
        (1..=n)
            .map(|i| self.rows[k][self.col(&format!("x{i}"))].parse().unwrap())
            .collect()
    }
    /// The rows at which the location changes.
    fn switches(&self) -> Vec<usize> {
        (1..self.rows.len())
            .filter(|&k| self.location(k) != self.location(k - 1))
            .collect()
    }
}

/// The states at the samples of `verify`'s Monte Carlo run of the image from x0 (up to Goal), which
/// must meet the task.
fn verify_samples(task: &HybridTask, img: &Path, x0: &[f64]) -> Vec<Vec<f64>> {
    use host_compiler::verify::hybrid::{run_hybrid, Judging, SUBSTEPS};
    let bytes = std::fs::read(img).unwrap();
    let image = shared_types::image::decode(&bytes).unwrap();
    let fine = task
        .plant
        .resampled(task.plant.period() / SUBSTEPS as f64)
        .unwrap();
    let mut samples = Vec::new();
    let r = run_hybrid(
        &fine,
        &task.property,
        task.initial,
        task.steps,
        &image,
        x0,
        Judging::ReachAvoid,
        &mut |x| samples.push(x.to_vec()),
    );
    assert!(!r.rejected && r.violation.is_none(), "{r:?}");
    assert!(r.events > 0, "the run switches");
    samples
}

/// The simulated run's states are those of `verify`'s run, bit for bit (the CSV prints f64 exactly).
fn assert_same_states(run: &Run, verify: &[Vec<f64>], n: usize) {
    assert!(verify.len() > 1 && run.rows.len() >= verify.len());
    for (k, x) in verify.iter().enumerate() {
        assert_eq!(&run.state(k, n), x, "sample {k}");
    }
}

#[test]
fn an_internally_switched_run_is_simulated_as_verify_runs_it() {
    // Example 4.25's run from Init's centre, planned once for this and `hybrid_import`'s tests.
    let (task, planned) = crate::hybrid_import::planned();
    let spec = crate::hybrid_import::spec_path();
    let dir = scratch("internal");
    let img = write_image(&dir, task, planned);
    let x0 = centre(&img);
    let o = simulate(&spec, &img, &x0_arg(&x0));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("Goal reached at step"), "{stderr}");
    assert!(stderr.contains("between samples"), "{stderr}");
    let text = String::from_utf8(o.stdout).unwrap();
    let run = Run::parse(&text);
    assert_eq!(
        run.header.join(","),
        "t,x1,x2,x3,u1,v1,location,status",
        "{text:.400}"
    );
    assert_eq!(run.rows.len(), task.steps + 1);
    let verify = verify_samples(task, &img, &x0);
    let goal = verify.len() - 1;
    assert_same_states(&run, &verify, 3);
    // Up to Goal one switch left → right, in the period of the run's one event there, where the flow
    // meets the guard (after Goal the run goes on, as `--steps` asks).
    assert_eq!(run.location(0), "left");
    let switches: Vec<usize> = run.switches().into_iter().filter(|&k| k <= goal).collect();
    assert_eq!(switches.len(), 1, "{switches:?}");
    let k = switches[0];
    assert_eq!(run.location(k), "right");
    let events: Vec<&(usize, String)> = run.events.iter().filter(|(r, _)| *r <= goal).collect();
    assert_eq!(events.len(), 1, "{:?}", run.events);
    assert_eq!(events[0].0, k, "the event line follows its period's row");
    let e = &events[0].1;
    assert!(e.contains("edge 0 (left → right)"), "{e}");
    let t: f64 = e["t = ".len()..e.find(" s:").unwrap()].parse().unwrap();
    let h = task.plant.period();
    assert!(t > (k - 1) as f64 * h && t <= k as f64 * h + 1e-12, "{e}");
    let guard = &task.plant.edges()[0].guard;
    let before: Vec<f64> = e[e.find("x = ").unwrap() + 4..]
        .split(", ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(guard.margin(&before).abs() < 1e-6, "{e}");
    assert!(
        guard.margin(&run.state(k - 1, 3)) > 0.0,
        "not in the guard before"
    );

    // `mtl` reads it as a trace (the location column skipped) and the import as a recording whose
    // locations the replay confirms.
    let trace = host_compiler::robustness::mtl::Trace::from_csv_str(&text, "run").unwrap();
    assert_eq!(trace.names(), ["x1", "x2", "x3", "u1", "v1"]);
    let rec = parse_recording(&text, "run", 3, 1, h, task.steps).unwrap();
    assert_eq!(rec.locations.as_ref().map(Vec::len), Some(task.steps));
    let replay = import::replay(task, &rec).unwrap();
    assert_eq!(replay.starts, vec![0, k]);
    // A row whose location the replay contradicts is refused at that row.
    let mut wrong = rec.clone();
    wrong.locations.as_mut().unwrap()[k] = "left".into();
    let err = import::replay(task, &wrong).unwrap_err().to_string();
    assert!(
        err.contains(&format!("row {k} ")) && err.contains("is left") && err.contains("in right"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_forced_run_switches_where_its_table_does_and_is_a_recording() {
    let spec = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-forced-cart.toml"
    ));
    let task = HybridTask::new(host_compiler::spec::load(&spec).unwrap()).unwrap();
    let planned = plan_forced(&task, &[0.0, 0.0]).unwrap();
    assert_eq!(planned.locations, vec![0, 1], "forward then backward");
    let dir = scratch("forced");
    let img = write_image(&dir, &task, &planned);
    let x0 = centre(&img);
    let o = simulate(&spec, &img, &x0_arg(&x0));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("Goal reached at step"), "{stderr}");
    let text = String::from_utf8(o.stdout).unwrap();
    let run = Run::parse(&text);
    assert_eq!(run.header.join(","), "t,x1,x2,u1,v1,location,status");
    // The image's one run: forward, then backward from the sample its table switches at.
    let bytes = std::fs::read(&img).unwrap();
    let d = shared_types::image::decode(&bytes).unwrap();
    let (s0, count) = d.trajectory_segments(0);
    assert_eq!(count, 2);
    let switch_row = d.segment(s0 + 1).unwrap().first_row - d.trajectory_rows(0).0;
    assert_eq!(run.location(0), "forward");
    assert_eq!(run.switches(), vec![switch_row]);
    assert_eq!(run.location(switch_row), "backward");
    assert_eq!(run.events.len(), 1, "{:?}", run.events);
    assert_eq!(
        run.events[0].0,
        switch_row + 1,
        "after the switching sample's row"
    );
    assert!(
        run.events[0]
            .1
            .contains("forced edge 0 (forward → backward)"),
        "{:?}",
        run.events
    );
    let verify = verify_samples(&task, &img, &x0);
    assert_same_states(&run, &verify, 2);
    // The references are the table's: v = u − K̂_ℓ x with the row's location's gain.
    for k in [0, switch_row, switch_row + 1] {
        let v: f64 = run.rows[k][run.col("v1")].parse().unwrap();
        assert!(
            (v - d.v(0, k, 0) as f64).abs() < 1e-5,
            "row {k}: {v} vs {}",
            d.v(0, k, 0)
        );
    }
    // The forced import reads the same column and certifies the run.
    let trace = host_compiler::robustness::mtl::Trace::from_csv_str(&text, "run").unwrap();
    assert_eq!(trace.names(), ["x1", "x2", "u1", "v1"]);
    let goal = verify.len() - 1;
    let rec = parse_recording(&text, "run", 2, 1, task.plant.period(), task.steps).unwrap();
    let rec = host_compiler::trajectory::csv::Recording {
        v: rec.v[..goal].to_vec(),
        locations: rec.locations.map(|l| l[..goal].to_vec()),
        ..rec
    };
    let r = import::certify_recording(&task, &rec).unwrap();
    assert_eq!(r.locations, vec![0, 1]);
    assert!(r.delta() > 0.0);

    // Bad initial states are bad input naming the entry.
    for (x0, what) in [
        ("nan,0", "entry 1 (x1) is NaN"),
        ("0,inf", "entry 2 (x2) is inf"),
    ] {
        let o = simulate(&spec, &img, x0);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{x0}: {stderr}");
        assert!(stderr.contains(what), "{x0}: {stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A one-location image (built here, without a fingerprint) of the double integrator: `--x0` with a
/// NaN is bad input naming it; a finite start runs.
#[test]
fn a_nan_initial_state_is_bad_input() {
    let spec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    );
    let mut b = host_compiler::emit::ImageBuilder::new(2, 1, 0.1);
    b.add_location(vec![-1.0, -1.5], vec![1.0, 0.0, 0.0, 1.0]);
    b.trajectories.push(host_compiler::emit::TrajectoryEntry {
        x0: vec![0.0, 0.0],
        delta: 0.5,
        v: vec![0.1; 4],
        location: vec![0; 4],
    });
    let dir = std::env::temp_dir().join(format!("hc-sim-nan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let img = dir.join("di.img");
    std::fs::write(&img, b.to_bytes().unwrap()).unwrap();
    let o = simulate(Path::new(spec), &img, "nan,0");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("--x0 entry 1 (x1) is NaN"), "{stderr}");
    let o = simulate(Path::new(spec), &img, "0.1,0");
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
