//! The falsifier (`verify::attack`, `verify --attack`): on a certified image it finds no violation and
//! reports a positive least robustness; on an image whose balls were enlarged past what was certified
//! (CRC recomputed, so only the search can tell) it finds runs that fail; the generic search
//! (`verify::attack::falsify`) finds the failing part of a toy mode's ball. [`attack_json`] checks the
//! falsifier's part of `verify --attack --json` for the CLI tests of every image mode.

use crate::verify_refuses::{image, spec, text, verify, write_patched};
use host_compiler::task::Task;
use host_compiler::verify::attack::{attack, AttackError, AttackSettings};
use host_compiler::verify::Judge;
use shared_types::image::decode;

fn task() -> Task {
    Task::new(host_compiler::spec::load(spec()).unwrap()).unwrap()
}

#[test]
fn a_certified_image_survives_the_attack() {
    let task = task();
    let judge = Judge::new(&task);
    let img = decode(image()).unwrap();
    let s = AttackSettings::default();
    let r = attack(&judge, &img, &s).unwrap();
    assert_eq!(r.violations, 0, "{:?}", r.first_violations);
    assert!(r.worst_robustness > 0.0, "{}", r.worst_robustness);
    assert!(r.worst_robustness.is_finite());
    // Every ball was searched from both starts: at least the initial simplices.
    let n = img.n();
    assert!(
        r.evaluations >= img.n_trajectories() * s.starts_per_ball * (n + 1),
        "{}",
        r.evaluations
    );
    // Deterministic for a seed.
    let again = attack(&judge, &img, &s).unwrap();
    assert_eq!(
        (again.evaluations, again.worst_robustness),
        (r.evaluations, r.worst_robustness)
    );
}

#[test]
fn balls_enlarged_past_their_certificate_are_caught() {
    let bytes = image().to_vec();
    let img = decode(&bytes).unwrap();
    let base = img.payload().delta.as_ptr() as usize - bytes.as_ptr() as usize;
    let mut patched = bytes.clone();
    for t in 0..img.n_trajectories() {
        let at = base + 4 * t;
        let d = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        patched[at..at + 4].copy_from_slice(&(20.0 * d).to_le_bytes());
    }
    let p = write_patched("radius-x20-attack.img", patched);
    let patched = std::fs::read(&p).unwrap();
    let img = decode(&patched).unwrap();
    let task = task();
    let r = attack(&Judge::new(&task), &img, &AttackSettings::default()).unwrap();
    assert!(
        r.violations > 0 && r.worst_robustness < 0.0,
        "violations {}, least robustness {}",
        r.violations,
        r.worst_robustness
    );
    assert!(!r.first_violations.is_empty());
    // Each names its start (in the enlarged part of some ball) and what failed.
    assert!(r
        .first_violations
        .iter()
        .all(|v| v.x0.len() == img.n() && !v.what.is_empty()));
}

#[test]
fn the_budget_must_fit_the_dimension() {
    let task = task();
    let img = decode(image()).unwrap();
    let s = AttackSettings::builder()
        .evaluations_per_start(3)
        .build()
        .unwrap();
    match attack(&Judge::new(&task), &img, &s) {
        Err(AttackError::Budget { got: 3, n, need }) => assert_eq!(need, n + 2),
        other => panic!("{other:?}"),
    }
    assert!(AttackSettings::builder()
        .starts_per_ball(0)
        .build()
        .is_err());
}

#[test]
fn verify_attack_reports_the_search() {
    let p = write_patched("untouched-attack.img", image().to_vec());
    let o = verify(
        &p,
        &[
            "--runs",
            "50",
            "--per-ball",
            "2",
            "--attack",
            "--attack-evals",
            "40",
        ],
    );
    let out = text(&o);
    assert_eq!(o.status.code(), Some(0), "{out}");
    assert!(out.contains("attack: "), "{out}");
    assert!(out.contains("violations 0"), "{out}");
}

/// The library's Monte Carlo refuses a count beyond its documented maximum before drawing anything
/// (the CLI's flags are bounded the same way).
#[test]
fn monte_carlo_counts_are_bounded_in_the_library_too() {
    use host_compiler::verify::{monte_carlo, MonteCarloError, MAX_PER_BALL, MAX_RUNS};
    let task = task();
    let judge = Judge::new(&task);
    let img = decode(image()).unwrap();
    let too_many = MAX_RUNS as usize + 1;
    match monte_carlo(&judge, &img, too_many, 0, 1) {
        Err(MonteCarloError::TooManyRuns {
            what: "interior",
            got,
            max,
        }) => {
            assert_eq!((got, max), (too_many, MAX_RUNS))
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        monte_carlo(&judge, &img, 1, MAX_PER_BALL as usize + 1, 1),
        Err(MonteCarloError::TooManyRuns {
            what: "per_ball",
            ..
        })
    ));
    assert!(monte_carlo(&judge, &img, 10, 1, 1).is_ok());
}

/// The falsifier's part of `verify --json` output.
#[derive(Debug)]
pub(crate) struct AttackSeen {
    pub evaluations: u64,
    /// `None` when the JSON holds no finite number (serde writes ±∞ as null).
    pub worst_robustness: Option<f64>,
    pub violations: u64,
    pub first_violations: Vec<serde_json::Value>,
}

/// The `attack` object of a `verify --json` run's standard output.
pub(crate) fn attack_of(o: &std::process::Output) -> AttackSeen {
    let stdout = String::from_utf8_lossy(&o.stdout);
    let j: serde_json::Value = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!(
            "not JSON ({e}): {stdout}\n{}",
            String::from_utf8_lossy(&o.stderr)
        )
    });
    let at = &j["attack"];
    AttackSeen {
        evaluations: at["evaluations"].as_u64().expect("attack.evaluations"),
        worst_robustness: at["worst_robustness"].as_f64(),
        violations: at["violations"].as_u64().expect("attack.violations"),
        first_violations: at["first_violations"]
            .as_array()
            .cloned()
            .unwrap_or_default(),
    }
}

/// What a passing `verify --attack --json` reported (checked by [`attack_json`]).
#[derive(Debug)]
pub(crate) struct Passed {
    pub worst_robustness: f64,
}

/// The `attack` of a passing `verify --attack --json`, checked: exit 0, runs made, a finite least
/// robustness, no violation.
pub(crate) fn attack_json(o: &std::process::Output) -> Passed {
    // 3: every check passed, the image's coverage of the spec's Init short of its target (the tests'
    // one-run images).
    assert!(
        matches!(o.status.code(), Some(0 | 3)),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let at = attack_of(o);
    assert!(at.evaluations > 0, "{at:?}");
    assert_eq!(at.violations, 0, "{at:?}");
    let worst = at.worst_robustness.expect("a finite least robustness");
    Passed {
        worst_robustness: worst,
    }
}

/// The generic search ([`falsify`]) on a toy mode: a run from x0 in the unit ball of ℝ² fails when
/// |x0| > 0.8 (robustness 0.8 − |x0|), and the evaluator refuses starts beyond the stored radius 1. The
/// search finds failing starts (each reported with its start), its least robustness is that of a start
/// inside the ball (≥ 0.8 − 1.0001), and refused starts are neither violations nor scored.
#[test]
fn the_generic_search_finds_a_failing_region_of_a_ball() {
    use host_compiler::verify::attack::{falsify, Ball, Scored, Target};
    struct Toy(Vec<Ball>);
    impl Target for Toy {
        fn balls(&self) -> &[Ball] {
            &self.0
        }
        fn score(&self, x0: &[f64]) -> Scored {
            let r = x0.iter().map(|v| v * v).sum::<f64>().sqrt();
            if r > 1.0 {
                return Scored::Refused;
            }
            Scored::Run {
                robustness: 0.8 - r,
                violation: (r > 0.8).then(|| format!("|x0| = {r}")),
            }
        }
    }
    let toy = Toy(vec![Ball {
        centre: vec![0.0, 0.0],
        pis: vec![1.0, 0.0, 0.0, 1.0],
        reach: 1.0001,
    }]);
    let r = falsify(&toy, &AttackSettings::default()).unwrap();
    assert!(r.violations > 0, "{r:?}");
    assert!(
        r.worst_robustness < 0.0 && r.worst_robustness >= 0.8 - 1.0001,
        "{r:?}"
    );
    for v in &r.first_violations {
        let norm = v.x0.iter().map(|a| a * a).sum::<f64>().sqrt();
        assert!(norm > 0.8 && norm <= 1.0, "{v:?}");
    }
    // A ball whose runs all pass: no violation, a positive least robustness.
    let small = Toy(vec![Ball {
        centre: vec![0.0, 0.0],
        pis: vec![1.0, 0.0, 0.0, 1.0],
        reach: 0.5,
    }]);
    let r = falsify(&small, &AttackSettings::default()).unwrap();
    assert_eq!(r.violations, 0, "{r:?}");
    assert!(
        r.worst_robustness >= 0.3 && r.worst_robustness < 0.35,
        "{r:?}"
    );
}
