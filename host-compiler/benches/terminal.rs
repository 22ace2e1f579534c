//! The terminal law (issue 17, item 2): what runs do after the task, to twice the horizon.
//!
//! * `examples/double-integrator.toml` synthesised as shipped (terminal law `auto`): the law's design
//!   time, and of the Monte Carlo's runs (10 000 interior + 16 per ball, each to 2T) those that reached
//!   Goal and were outside it again before 2T (target 0: the law exists here), and those handed over.
//! * `examples/planar-vehicle.toml` with 8 trajectories (Example 4.8's plant, whose every equilibrium in
//!   Goal needs ‖u‖ ≥ √2 − 0.1 > 1, so no law exists): the same count for today's behaviour past the
//!   table (the last row's law), as the baseline the issue describes; not a target.

use host_compiler::benchkit::{write_rows, Row};
use host_compiler::synth::{synthesize, SynthOptions, TerminalOutcome};
use host_compiler::task::Task;
use host_compiler::verify::{run_to, Judge};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::time::Instant;

fn task(example: &str) -> Task {
    let path = format!("{}/../examples/{example}", env!("CARGO_MANIFEST_DIR"));
    Task::new(host_compiler::spec::load(&path).expect("the shipped example")).expect("a task")
}

fn main() {
    let opts = SynthOptions {
        progress: false,
        ..SynthOptions::default()
    };
    // With a law.
    let di = task("double-integrator.toml");
    let t = Instant::now();
    let design = host_compiler::terminal::design_terminal(&di).expect("a terminal law");
    let design_ms = t.elapsed().as_secs_f64() * 1e3;
    let s = synthesize(&di, &opts).expect("synthesis");
    assert!(matches!(s.terminal, TerminalOutcome::Certified(_)));
    let runs = s.verify.interior_runs + s.verify.boundary_runs - s.verify.boundary_rejected;
    println!(
        "double integrator: law at x_e = {:?} (contraction {:.3}), {} runs to {} samples: {} outside Goal again, {} handed over, {} violations",
        design.stored.x_e,
        design.certificate.contraction,
        runs,
        s.verify.run_steps,
        s.verify.runs_leaving_goal,
        s.verify.handed_over,
        s.verify.violations
    );
    // Without one.
    let mut pv = task("planar-vehicle.toml");
    pv.problem.synthesis.max_trajectories = 8;
    let s_pv = synthesize(&pv, &opts).expect("synthesis");
    let why = match &s_pv.terminal {
        TerminalOutcome::None(e) => e.to_string(),
        other => panic!("expected no terminal law, got {other:?}"),
    };
    let img = shared_types::image::decode(&s_pv.image).expect("valid");
    let judge = Judge::new(&pv);
    // Uniform starts in Init that the image accepts (as `verify`'s Monte Carlo draws them).
    let ctl = shared_types::eval::Controller::new(img);
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let init = pv.init();
    let (mut leaving, mut total, mut unsafe_after) = (0, 0, 0);
    while total < 2_000 {
        let x0: Vec<f64> = init
            .lo
            .iter()
            .zip(&init.hi)
            .map(|(&l, &h)| if h > l { rng.random_range(l..=h) } else { l })
            .collect();
        let xf: Vec<f32> = x0.iter().map(|&v| v as f32).collect();
        if ctl.select(&xf).is_none() {
            continue;
        }
        let o = run_to(&judge, &img, &x0, 2 * judge.steps);
        total += 1;
        leaving += usize::from(o.left_goal);
        unsafe_after += usize::from(o.after_goal_unsafe);
    }
    println!(
        "planar vehicle (no law: {why}): of {total} runs from uniform starts in the cover to 2T, {leaving} were outside Goal again, {unsafe_after} entered Unsafe after Goal"
    );
    let rows = vec![
        Row::new(
            "terminal_runs_leaving_goal",
            s.verify.runs_leaving_goal as f64,
            &format!("runs of {runs} to 2T (double integrator, law certified)"),
        ),
        Row::new(
            "terminal_runs_handed_over",
            s.verify.handed_over as f64,
            &format!("runs of {runs}"),
        ),
        Row::new("terminal_design_ms", design_ms, "ms"),
        Row::new(
            "terminal_none_runs_leaving_goal_planar_vehicle",
            leaving as f64,
            &format!("runs of {total} to 2T (no law exists; the last row's law)"),
        ),
    ];
    let path = write_rows("terminal", &rows).expect("rows written");
    println!("rows: {}", path.display());
}
