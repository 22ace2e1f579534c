//! What `verify::run` judges: the reach-avoid task of Theorem 4.7 ends at the first sample in Goal.
//! Regression for optimised trajectories whose table §5.3 cut at k*: the terminal law that runs after
//! Goal left the input set and was counted as a violation although the certificate never covered it.
#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::emit::{ImageBuilder, Terminal, TrajectoryEntry};
use host_compiler::geometry::Ball;
use host_compiler::model::{DiscretePlant, LinearAffine};
use host_compiler::property::{InputBound, ReachAvoid};
use host_compiler::spec::InitBox;
use host_compiler::verify::{run, Judge};
use shared_types::image::decode;

/// x⁺ = x + u with K = −3: the one-step table (v = 1) takes x = 0 to 1; the held law u = −3x + 1
/// then leaves |u| ≤ 1.5 and drives x through −1, 3, −5.
fn image() -> Vec<u8> {
    let mut b = ImageBuilder::new(1, 1, 0.1);
    b.add_location(vec![-3.0], vec![1.0]);
    b.add_trajectory(TrajectoryEntry {
        x0: vec![0.0],
        delta: 0.01,
        v: vec![1.0],
        location: vec![0],
    });
    b.terminal = Terminal::HoldLast;
    b.to_bytes().expect("valid image")
}

fn judge_run(goal_centre: f64) -> host_compiler::verify::RunOutcome {
    let bytes = image();
    let img = decode(&bytes).expect("decodes");
    let A = Mat::from_fn(1, 1, |_, _| 1.0);
    let B = Mat::from_fn(1, 1, |_, _| 1.0);
    let plant = LinearAffine::discrete(DiscretePlant::new(A, B, vec![0.0], 0.1).unwrap());
    let property = ReachAvoid {
        goal: Box::new(Ball::new(vec![goal_centre], vec![1.0], 0.2).unwrap()),
        unsafe_set: Some(Box::new(Ball::new(vec![-5.0], vec![1.0], 0.5).unwrap())),
        input: InputBound::Box {
            lo: vec![-1.5],
            hi: vec![1.5],
        },
        horizon: 0.6,
    };
    let init = InitBox {
        lo: vec![0.0],
        hi: vec![0.0],
    };
    let judge = Judge {
        plant: &plant,
        property: &property,
        steps: 6,
        init: &init,
    };
    run(&judge, &img, &[0.0], true)
}

#[test]
fn the_terminal_law_after_goal_is_reported_not_judged() {
    let o = judge_run(1.0);
    assert_eq!(o.goal_step, Some(1));
    assert!(o.reached_goal);
    assert!(!o.input_violation && !o.entered_unsafe, "{o:?}");
    assert!(
        o.after_goal_input_excursion,
        "u = −2 at x = 1 leaves the set"
    );
    assert!(o.after_goal_unsafe, "x reaches −5 at step 4");
    assert!(!o.violated());
    // Margins describe the judged part only: the one input applied before Goal was 1 (slack 0.5).
    assert!((o.input_margin - 0.5).abs() < 1e-6, "{}", o.input_margin);
}

#[test]
fn the_same_excursions_before_goal_are_violations() {
    // Goal out of reach: the whole run is judged.
    let o = judge_run(100.0);
    assert_eq!(o.goal_step, None);
    assert!(o.input_violation && o.entered_unsafe, "{o:?}");
    assert!(!o.after_goal_input_excursion && !o.after_goal_unsafe);
    assert!(o.violated());
}
