//! The forced planner's schedule search (`synth::hybrid::schedule`, issue 48 item 4) on the DC-DC boost
//! converter of `examples/dcdc-boost.toml`: from Init's centre no one-switch schedule certifies a run,
//! the searched schedules do (a run of many switches, certified by Theorem 4.17 as shipped), and
//! Algorithm 4 grown from that run's ball boundary keeps its schedule.

#![allow(non_snake_case)]

use host_compiler::synth::hybrid::forced::{certify_run, grow_from, plan_forced, plan_one_switch};
use host_compiler::synth::hybrid::HybridTask;

fn dcdc() -> HybridTask {
    let path = format!("{}/../examples/dcdc-boost.toml", env!("CARGO_MANIFEST_DIR"));
    HybridTask::new(host_compiler::spec::load(&path).expect("the example parses"))
        .expect("a forced-switching task")
}

#[test]
fn the_searched_schedule_certifies_a_dcdc_run_the_one_switch_planner_cannot() {
    let task = dcdc();
    let x0 = [1.2, 5.5];
    let one = plan_one_switch(&task, &x0);
    assert!(
        one.is_err(),
        "a one-switch run certified: δ = {:?}",
        one.map(|(r, _)| r.delta())
    );
    let run = plan_forced(&task, &x0).expect("a searched schedule certifies");
    assert!(run.certificate.is_certified(), "{:?}", run.certificate);
    assert!(run.delta() >= task.problem.synthesis.min_robustness);
    assert!(
        run.nominals.len() >= 6,
        "a run of many switches, not {} segments",
        run.nominals.len()
    );
    // Consecutive segments alternate (each is a maximal run of one location), and the run's table fits
    // the horizon.
    assert!(run.locations.windows(2).all(|w| w[0] != w[1]));
    let rows: usize = run.nominals.iter().map(|n| n.steps()).sum();
    assert!(
        rows <= task.steps,
        "{rows} rows beyond {} steps",
        task.steps
    );
    // What it answers is the certificate of what it ships.
    let edges: Vec<usize> = run
        .locations
        .windows(2)
        .map(|w| {
            task.plant
                .edge_index(w[0], w[1], host_compiler::model::hybrid::EdgeKind::Forced)
                .expect("a forced edge")
        })
        .collect();
    let again = certify_run(&task, &run.locations, &edges, &run.nominals).expect("continuous");
    assert_eq!(again, run.certificate);

    // Algorithm 4 from the boundary of its ball follows the parent's schedule: the same locations,
    // switching at the same samples.
    let P = task.designs[task.initial].P.as_ref();
    let c = &run.nominals[0].x[0];
    let y = host_compiler::cover::alg4::project_onto_boundary(
        P,
        &[c[0] + 0.01, c[1] + 0.005],
        c,
        run.certificate.delta_stored as f64,
    )
    .expect("off the centre");
    let grown = grow_from(&task, &run, &y).expect("certified from the boundary");
    assert_eq!(grown.locations, run.locations);
    let lengths = |r: &host_compiler::synth::hybrid::HybridRun| -> Vec<usize> {
        r.nominals[..r.nominals.len() - 1]
            .iter()
            .map(|n| n.steps())
            .collect()
    };
    assert_eq!(lengths(&grown), lengths(&run));
}
