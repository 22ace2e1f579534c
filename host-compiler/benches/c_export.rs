//! The C export against the Rust evaluator (#16 item 7): the exported evaluator compiled with the system
//! `cc` under the header's flags, run on 10⁵ seeded states per image mode (feedforward, feedforward with
//! segment exits, PWA feedback: synthetic images of every terminal behaviour and fallback law, one and
//! several locations), compared bit for bit.
//!
//! Rows: `c_export_mismatches` (steps whose status or an input bit differed; 0 expected) and
//! `c_export_states` (steps compared, all modes; the note gives each mode's count, ≥ 10⁵ each);
//! `monitor_c_mismatches` (the task's monitor, section 14: updates whose lo bits, hi bits or verdict
//! differed between the exported `sc_monitor_update` and `shared_types::monitor::Monitor`; 0 expected)
//! over ≥ 10⁴ seeded traces of the synthetic programs (`harness::MONITOR_FORMULAS`: every operator and
//! atom kind) and of the monitors of `planar-vehicle-waypoints` and `double-integrator`, half of them
//! with NaN, infinite, huge or wrongly sized states; the note gives the traces and updates compared.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::export::harness::{
    double_integrator_run, exits_image, feedforward_image, monitor_image, monitor_scenario,
    planar_waypoints_run, pwa_image, scenario, CHarness, MonitorPath, Op, MONITOR_FORMULAS,
};
use shared_types::image::{decode, Terminal};

fn main() {
    let images = [
        feedforward_image(100, 4, 2, 1, 12, Terminal::HoldLast, 0),
        feedforward_image(101, 5, 2, 3, 20, Terminal::Fallback, 2),
        feedforward_image(102, 3, 1, 2, 8, Terminal::Fallback, 3),
        feedforward_image(103, 12, 6, 1, 6, Terminal::Fallback, 1),
        exits_image(500, 3, 1, 1, 5, Terminal::HoldLast, 0),
        exits_image(501, 4, 2, 2, 10, Terminal::Fallback, 2),
        exits_image(502, 3, 2, 3, 12, Terminal::HoldLast, 3),
        exits_image(503, 5, 1, 3, 8, Terminal::Fallback, 1),
        pwa_image(200, 2, 1, 1, 3, 40, 1),
        pwa_image(201, 4, 2, 3, 5, 80, 2),
        pwa_image(202, 6, 3, 2, 4, 60, 0),
        pwa_image(203, 12, 6, 1, 2, 30, 3),
    ];
    let dir = host_compiler::benchkit::rows_dir()
        .join("..")
        .join("c_export");
    let (mut states, mut mismatches) = (0usize, 0usize);
    // Steps compared per mode: feedforward, feedforward with segment exits, PWA (4 images each).
    let mut per_mode = [0usize; 3];
    for (i, image) in images.iter().enumerate() {
        let sub = dir.join(format!("image{i}"));
        let h = CHarness::build(image, &sub).expect("the exported C compiles");
        let img = decode(image).expect("valid image");
        let ops = scenario(&img, 1000 + i as u64, 25_000);
        let c = h.compare(&ops).expect("the C driver runs");
        assert_eq!(
            c.init_mismatches, 0,
            "image {i}: the exported array is refused"
        );
        if let Some(first) = &c.first {
            eprintln!("image {i}: {first}");
        }
        states += c.states;
        mismatches += c.mismatches;
        per_mode[i / 4] += c.states;
    }
    let (traces, updates, monitor_mismatches) = monitors(&dir);
    let rows = [
        Row::new(
            "c_export_mismatches",
            mismatches as f64,
            &format!(
                "steps of {states} (4 feedforward, 4 feedforward with segment exits, 4 PWA images)"
            ),
        ),
        Row::new(
            "c_export_states",
            states as f64,
            &format!(
                "steps compared (feedforward {}, with segment exits {}, PWA {})",
                per_mode[0], per_mode[1], per_mode[2]
            ),
        ),
        Row::new(
            "monitor_c_mismatches",
            monitor_mismatches as f64,
            &format!(
                "monitor updates of {updates} in {traces} traces (synthetic programs, planar-vehicle-waypoints, double-integrator)"
            ),
        ),
    ];
    write_rows("c_export", &rows).expect("rows written");
}

/// The exported monitor against the Rust one: (traces, updates, mismatching updates, counting a differing
/// init as one).
fn monitors(dir: &std::path::Path) -> (usize, usize, usize) {
    let ff = feedforward_image(940, 3, 1, 1, 4, Terminal::HoldLast, 1);
    let h = CHarness::build(
        &monitor_image(&ff, MONITOR_FORMULAS[0].0, 12),
        &dir.join("monitor"),
    )
    .expect("the exported C compiles");
    // (image, traces, path): the synthetic programs, then the examples' runs and paths through their
    // sets.
    let mut cases: Vec<(Vec<u8>, usize, Option<MonitorPath<'_>>)> = MONITOR_FORMULAS
        .iter()
        .map(|&(text, horizon)| (monitor_image(&ff, text, horizon), 400, None))
        .collect();
    for (k, (name, path, runs)) in [
        (
            "planar-vehicle-waypoints.toml",
            &planar_waypoints_run as MonitorPath<'_>,
            300,
        ),
        ("double-integrator.toml", &double_integrator_run, 3000),
    ]
    .into_iter()
    .enumerate()
    {
        let spec = format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"));
        let problem = host_compiler::spec::load(&spec).expect("the example loads");
        let prog = host_compiler::monitor::Program::for_problem(&problem).expect("compiles");
        let base = feedforward_image(
            941 + k as u64,
            problem.plant.n(),
            problem.plant.m(),
            1,
            4,
            Terminal::Fallback,
            1,
        );
        let image = host_compiler::monitor::attach(&base, &prog.encode()).expect("attaches");
        cases.push((image.clone(), runs, Some(path)));
        cases.push((image, runs / 4, None));
    }
    let (mut traces, mut updates, mut mismatches) = (0usize, 0usize, 0usize);
    for (i, (image, n, path)) in cases.iter().enumerate() {
        let img = decode(image).expect("valid image");
        let mut ops = monitor_scenario(&img, 5000 + i as u64, *n, *path);
        ops[0] = Op::InitBytes(image.clone());
        let c = h.compare(&ops).expect("the C driver runs");
        if let Some(first) = &c.first {
            eprintln!("monitor case {i}: {first}");
        }
        traces += c.monitor_traces;
        updates += c.monitor_updates;
        mismatches += c.monitor_mismatches + c.monitor_init_mismatches + c.init_mismatches;
    }
    (traces, updates, mismatches)
}
