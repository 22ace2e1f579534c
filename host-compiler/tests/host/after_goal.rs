//! After Goal (issue 42, item 4): where a terminal law exists, every certified run is handed over before
//! it can leave Goal, and what runs do after Goal is a judged result. A point mass that enters Goal at
//! speed with a wall just beyond it ran into the wall under the table's last row before the handover
//! (counted, not judged). Now its cover is certified to reach the law's handover region, and its runs,
//! verified to 2T, never leave Goal nor enter Unsafe; a run that does leave Goal after it is a violation.
#![allow(non_snake_case)]

use faer::Mat;
use host_compiler::certify::terminal::StoredTerminal;
use host_compiler::emit::{ImageBuilder, Terminal, TrajectoryEntry};
use host_compiler::geometry::Ball;
use host_compiler::model::{DiscretePlant, LinearAffine};
use host_compiler::property::{InputBound, ReachAvoid};
use host_compiler::spec::InitBox;
use host_compiler::synth::{synthesize, SynthOptions};
use host_compiler::task::Task;
use host_compiler::verify::{monte_carlo, run, Judge};
use shared_types::image::decode;

/// A 1-D point mass (position, velocity; the input its acceleration, |u| ≤ 1) from rest near 0 to a
/// Goal box of positions [0.9, 1.1] within 2.5 s (at rest there takes 2 s at least), with a wall at
/// position 1.15: a run still moving when it enters Goal hits the wall unless something stops it there.
/// Before the handover region was the cover's Goal, the nominal entered Goal at speed and every run went
/// on into the wall under the table's last row, never handed over.
const POINT_MASS: &str = r#"
name = "point-mass-wall"
seed = 3
horizon = 2.5

[plant]
time = "discrete"
A = [[1.0, 0.1], [0.0, 1.0]]
B = [[0.005], [0.1]]
period = 0.1

[init]
kind = "box"
lo = [-0.05, 0.0]
hi = [0.05, 0.0]

[goal]
kind = "box"
lo = [0.9, -10.0]
hi = [1.1, 10.0]

[[unsafe]]
kind = "polytope"
A = [[-1.0, 0.0]]
b = [-1.15]

[input]
kind = "box"
lo = [-1.0]
hi = [1.0]

[synthesis]
coverage_target = 0.9
"#;

#[test]
fn a_point_mass_is_handed_over_before_it_can_leave_goal_or_reach_the_wall() {
    let problem = host_compiler::spec::parse(POINT_MASS, "point-mass-wall.toml").unwrap();
    let task = Task::new(problem).unwrap();
    let opts = SynthOptions {
        verify_interior: 400,
        verify_per_ball: 8,
        working_samples: 400,
        progress: false,
        attack: None,
        ..SynthOptions::default()
    };
    let s = synthesize(&task, &opts).unwrap();
    let d = s.terminal.design().expect("a certified terminal law");
    let rho = s
        .handover_radius
        .expect("the cover aims at the handover region");
    assert!(rho > 0.0 && rho < 1.0, "{rho}");
    assert!(!s.trajectories.is_empty());
    // Every trajectory's tube lies in the handover region at κ*: its nominal there is within ρ_h of x_e
    // in the law's metric.
    for t in s
        .trajectories
        .iter()
        .filter(|t| t.certificate.is_certified())
    {
        let x = &t.nominal.x[t.certificate.k_star];
        let e: Vec<f64> = x.iter().zip(&d.stored.x_e).map(|(a, b)| a - b).collect();
        let q = host_compiler::linalg::p_norm(d.stored.P.as_ref(), &e);
        assert!(q < rho, "trajectory ends {q} from x_e, beyond {rho}");
    }
    let v = &s.verify;
    let runs = v.interior_runs + v.boundary_runs - v.boundary_rejected;
    assert!(runs > 300, "{runs}");
    assert!(v.after_goal_judged);
    assert_eq!(v.run_steps, 50, "runs last 2T");
    assert_eq!(v.violations, 0, "{:?}", v.first_violations);
    assert_eq!(v.runs_leaving_goal, 0);
    assert_eq!(v.after_goal_unsafe, 0);
    assert_eq!(v.after_goal_input_excursions, 0);
    assert_eq!(v.not_handed_over, 0);
    assert_eq!(v.handed_over, runs, "every accepted run is handed over");
}

/// x⁺ = x + u with K = 0, one table row v = 1 from x = 0 to Goal (a ball of radius 0.2 about 1), then the
/// last row held: x = 2, 3, … leaves Goal. The terminal law's ellipsoid is far away (about 50): no run is
/// ever handed over.
fn leaving_image(with_law: bool) -> Vec<u8> {
    let mut b = ImageBuilder::new(1, 1, 0.1);
    b.add_location(vec![0.0], vec![1.0]);
    b.add_trajectory(TrajectoryEntry {
        x0: vec![0.0],
        delta: 0.01,
        v: vec![1.0],
        location: vec![0],
    });
    b.terminal = Terminal::HoldLast;
    if with_law {
        b.terminal_law = Some(StoredTerminal {
            x_e: vec![50.0],
            K: Mat::from_fn(1, 1, |_, _| -1.0),
            v: vec![50.0],
            P: Mat::from_fn(1, 1, |_, _| 1.0),
            radius: 0.01,
        });
    }
    b.to_bytes().expect("valid image")
}

fn line_plant() -> LinearAffine {
    let A = Mat::from_fn(1, 1, |_, _| 1.0);
    let B = Mat::from_fn(1, 1, |_, _| 1.0);
    LinearAffine::discrete(DiscretePlant::new(A, B, vec![0.0], 0.1).unwrap())
}

fn line_property() -> ReachAvoid {
    ReachAvoid {
        goal: Box::new(Ball::new(vec![1.0], vec![1.0], 0.2).unwrap()),
        unsafe_set: None,
        input: InputBound::Box {
            lo: vec![-2.0],
            hi: vec![2.0],
        },
        horizon: 0.4,
    }
}

#[test]
fn with_a_terminal_law_a_run_leaving_goal_after_it_is_a_violation() {
    let plant = line_plant();
    let property = line_property();
    let init = InitBox {
        lo: vec![0.0],
        hi: vec![0.0],
    };
    let judge = Judge {
        plant: &plant,
        property: &property,
        steps: 4,
        init: &init,
    };
    // Without a terminal law the task ends at Goal: leaving it afterwards is recorded, not judged.
    let bytes = leaving_image(false);
    let img = decode(&bytes).unwrap();
    let o = run(&judge, &img, &[0.0], false);
    assert_eq!(o.goal_step, Some(1));
    assert!(o.left_goal && !o.violated(), "{o:?}");
    let r = monte_carlo(&judge, &img, 5, 0, 1).unwrap();
    assert!(!r.after_goal_judged);
    assert_eq!((r.violations, r.runs_leaving_goal), (0, 5));

    // With one, the run is judged to 2T: it leaves Goal and is never handed over, two violations of one
    // run.
    let bytes = leaving_image(true);
    let img = decode(&bytes).unwrap();
    let o = run(&judge, &img, &[0.0], false);
    assert_eq!(o.goal_step, Some(1));
    assert!(o.left_goal && o.not_handed_over && !o.handed_over, "{o:?}");
    assert!(o.terminal_violation && o.violated(), "{o:?}");
    let r = monte_carlo(&judge, &img, 5, 0, 1).unwrap();
    assert!(r.after_goal_judged);
    assert_eq!(r.run_steps, 8);
    assert_eq!(
        (r.violations, r.runs_leaving_goal, r.not_handed_over),
        (5, 5, 5)
    );
}

#[test]
fn the_image_says_in_one_line_what_it_does_after_goal() {
    let bytes = leaving_image(false);
    let line = host_compiler::report::after_goal_line(&decode(&bytes).unwrap());
    assert_eq!(
        line,
        "after Goal: no terminal law; the run's table goes on to its last row, then the last row's law \
         u = K x + v(last) is held (not certified after Goal)"
    );
    let bytes = leaving_image(true);
    let line = host_compiler::report::after_goal_line(&decode(&bytes).unwrap());
    assert!(
        line.starts_with("after Goal: the terminal law (section 11) takes over"),
        "{line}"
    );
    // `inspect` prints the same line.
    let text = host_compiler::cli::inspect::render(&leaving_image(false), "leaving.img", false)
        .expect("renders");
    assert!(
        text.contains("after Goal: no terminal law; the run's table goes on to its last row"),
        "{text}"
    );
}
