//! "No certified trajectory" says why (issue 18, class 4): the binding δ part of the best attempt with
//! its value, and whether Goal was reached within T by any trajectory tried, as typed data
//! (`cover::Attempts`, `certify::Binding`) and in the message.

use host_compiler::certify::Binding;
use host_compiler::cover::GrowError;
use host_compiler::synth::{synthesize, SynthError, SynthOptions};
use host_compiler::task::Task;

fn example() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/double-integrator.toml"
    ))
    .unwrap()
}

fn edit(from: &str, to: &str) -> String {
    let s = example();
    assert!(s.contains(from), "test bug: `{from}` not in the example");
    s.replacen(from, to, 1)
}

/// Synthesis of `src`, which must end without any certified trajectory; its attempts and message.
fn nothing_certified(src: &str) -> (host_compiler::cover::Attempts, String) {
    let p = host_compiler::spec::parse(src, "spec.toml").unwrap();
    let opts = SynthOptions {
        verify_interior: 100,
        verify_per_ball: 1,
        progress: false,
        ..SynthOptions::default()
    };
    let e = match synthesize(&Task::new(p).unwrap(), &opts) {
        Ok(s) => panic!("certified {} trajectories", s.trajectories.len()),
        Err(e) => e,
    };
    let msg = e.to_string();
    match e {
        SynthError::Cover(GrowError::NoSeed { attempts, .. })
        | SynthError::Cover(GrowError::NothingCertified { attempts }) => (*attempts, msg),
        other => panic!("not a 'no certified trajectory' outcome: {other}"),
    }
}

#[test]
fn goal_unreachable_within_the_horizon_says_so() {
    // From rest near 0, |u| ≤ 1 moves the position at most 0.125 in 0.5 s: Goal at 1 is out of reach.
    let (a, msg) = nothing_certified(&edit("horizon = 4.0", "horizon = 0.5"));
    assert!(!a.goal_reached(), "{msg}");
    assert!(
        msg.contains("Goal was not reached within T = 0.5 s"),
        "{msg}"
    );
    // The generator finds nothing; the loop without a reference is certified instead, so the message
    // names the binding part with its value, and the generator's reason.
    let c = a.best.as_ref().expect("a certificate of the attempts");
    let Binding::Goal(v) = c.binding() else {
        panic!("binding {:?}: {msg}", c.binding())
    };
    assert!(v <= 0.0 && v == a.best_goal, "{msg}");
    assert!(msg.contains(&format!("bound by δ_Goal = {v:.3e}")), "{msg}");
    assert!(
        a.first_refusal.is_some() && msg.contains("in 5 steps"),
        "{msg}"
    );
}

#[test]
fn a_too_tight_input_box_names_the_binding_part() {
    // |u| ≤ 0.01: in 4 s the position moves at most 0.08.
    let (a, msg) = nothing_certified(&edit(
        "lo = [-1.0]\nhi = [ 1.0]",
        "lo = [-0.01]\nhi = [ 0.01]",
    ));
    assert!(!a.goal_reached(), "{msg}");
    assert!(msg.contains("Goal was not reached within T = 4 s"), "{msg}");
    let c = a.best.as_ref().expect("a certificate of the attempts");
    let b = c.binding();
    assert!(
        !matches!(b, Binding::NotComputed | Binding::RCrit { .. }),
        "{msg}"
    );
    assert!(msg.contains(&format!("bound by {b}")), "{msg}");
    assert!(msg.contains("δ_Input") && msg.contains("r_crit"), "{msg}");
}
