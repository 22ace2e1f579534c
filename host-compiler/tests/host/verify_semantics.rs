//! What `verify::run` judges: the reach-avoid task of Theorem 4.7 ends at the first sample in Goal.
//! Regression for optimised trajectories whose table §5.3 cut at k*: the terminal law that runs after
//! Goal left the input set and was counted as a violation although the certificate never covered it.
#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::emit::{ImageBuilder, Terminal, TrajectoryEntry};
use host_compiler::geometry::Ball;
use host_compiler::trajectory::generate::InputBound;
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
    let goal = Ball::new(vec![goal_centre], vec![1.0], 0.2).unwrap();
    let unsafe_set = Ball::new(vec![-5.0], vec![1.0], 0.5).unwrap();
    let input = InputBound::Box {
        lo: vec![-1.5],
        hi: vec![1.5],
    };
    let judge = Judge {
        A: A.as_ref(),
        B: B.as_ref(),
        g: &[0.0],
        sub: None,
        goal: &goal,
        unsafe_set: Some(&unsafe_set),
        input: &input,
        steps: 6,
        init_lo: &[0.0],
        init_hi: &[0.0],
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
