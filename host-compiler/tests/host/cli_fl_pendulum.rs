//! The torque-driven pendulum (`examples/fl-pendulum.toml`): a feedback-linearizable plant written only in
//! the spec whose law cancels (g/l) sin θ, a term in the linearised coordinates ξ, so it declares an
//! operating region (`plant.region`). The task's bounds are taken over the region and its complement is
//! Unsafe; `synth` covers Init with 0 violations on the plant itself and `verify` re-proves the image.
//! Without the region the same plant is refused naming the term and the state; a region that does not
//! contain Init, a Γ singular inside the region and zero dynamics that leave the region are refused
//! naming the equation or state and the point.

use host_compiler::spec::{self, ErrorKind, InputSet};
use host_compiler::task::Task;

fn example() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/fl-pendulum.toml"
    ))
    .unwrap()
}

/// The example with `from` (which must occur once) replaced by `to`.
fn variant(from: &str, to: &str) -> String {
    let src = example();
    assert_eq!(src.matches(from).count(), 1, "`{from}` must occur once");
    src.replace(from, to)
}

const REGION: &str = "region = { lo = [-0.6, -1.8], hi = [3.6, 0.5] }";

/// The task in ξ: the whole of α = (g/l) sin θ − b ω cancelled, W the torque box pulled back over the
/// region, and the region's complement (two half-spaces per ξ state) in Unsafe.
#[test]
fn the_pendulum_is_bounded_over_its_region() {
    let p = spec::parse(&example(), "fl-pendulum.toml").unwrap_or_else(|e| panic!("{e:?}"));
    let task = Task::new(p).unwrap_or_else(|e| panic!("{e}"));
    let maps = task.plant.linearization().expect("linearised");
    assert_eq!(maps.xi_states, vec![0, 1]);
    assert!(maps.zero_states.is_empty());
    let region = maps.region.as_ref().expect("a region");
    assert_eq!(region.lo, vec![-0.6, -1.8]);
    // sup |α_res| over the region: (g/l)·1 (θ passes π/2) + b·2.5, and a little enclosure slack.
    let a = 9.81 + 0.1 * 1.8;
    assert!(
        maps.alpha_res_norm >= a && maps.alpha_res_norm < a * 1.01,
        "{}",
        maps.alpha_res_norm
    );
    // W = [−ω, ω] with ω = 15 − sup|α_res| less the rounding.
    let InputSet::Box { hi, .. } = &task.problem.input else {
        panic!("a box")
    };
    assert!(hi[0] < 15.0 - a && hi[0] > 15.0 - a * 1.01, "{hi:?}");
    // D ≈ h·((g/l)·sup|ω| + b·sup|ω̇|): positive, below 0.1 at 200 Hz.
    assert!(
        maps.mismatch > 0.005 * 9.81 * 1.8 && maps.mismatch < 0.1,
        "{}",
        maps.mismatch
    );
    assert_eq!(task.problem.unsafe_sets.len(), 4);
    let us = task
        .property
        .unsafe_region()
        .expect("the region's complement");
    assert!(us.contains(&[3.6, 0.0]) && us.contains(&[0.0, -2.6]));
    assert!(!us.contains(&[std::f64::consts::PI, 0.0]));
}

/// Without `plant.region`, a law that depends on ξ cannot be bounded: refused naming the term, the
/// state, and the way out.
#[test]
fn a_law_on_xi_without_a_region_is_refused() {
    let src = variant(REGION, "");
    let p = spec::parse(&src, "fl.toml").unwrap_or_else(|e| panic!("{e:?}"));
    let err = Task::new(p).err().expect("refused").to_string();
    assert!(
        err.contains("α_1") && err.contains("depends on th") && err.contains("plant.region"),
        "{err}"
    );
}

/// A region that does not contain Init: a spanned diagnostic naming the state and a point of Init
/// outside the region.
#[test]
fn a_region_without_init_is_refused_naming_the_point() {
    let src = variant(REGION, "region = { lo = [-0.6, -1.8], hi = [3.1, 0.5] }");
    let e = spec::parse(&src, "fl.toml").expect_err("refused");
    assert_eq!(e.kind(), ErrorKind::Model);
    let msg = e.message();
    assert!(
        msg.contains("does not contain Init") && msg.contains("th") && msg.contains("th = 3.2416"),
        "{msg}"
    );
    // Pointed at the region's bound on θ.
    let (span, label) = &e.label_spans()[0];
    assert_eq!(label, "hi[0] = 3.1");
    assert_eq!(&src[span.clone()], "3.1");
}

/// A Γ that vanishes inside the region (a torque acting through cos θ, zero at θ = π/2) is refused over
/// the region, though it is nonsingular on Init.
#[test]
fn a_gamma_singular_in_the_region_is_refused() {
    let src = variant(
        r#"g = [["0"], ["1/(m*l^2)"]]"#,
        r#"g = [["0"], ["cos(th)"]]"#,
    );
    let e = spec::parse(&src, "fl.toml").expect_err("refused");
    assert_eq!(e.kind(), ErrorKind::Model);
    let msg = e.message();
    assert!(
        msg.contains("decoupling matrix Γ") && msg.contains("operating region"),
        "{msg}"
    );
}

/// Zero dynamics whose enclosure leaves the region (Example 4.9's turn rate, bounded by the region to
/// less than it reaches within T) are refused naming the state and both ranges.
#[test]
fn zero_dynamics_leaving_the_region_are_refused() {
    let src = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/fl-4-9.toml"
    ))
    .unwrap()
    .replace(
        "h = [\"X\", \"Y\"]",
        "h = [\"X\", \"Y\"]\nregion = { lo = [-5, -5, -5, -5, -5, -0.01], hi = [5, 5, 5, 5, 5, 0.01] }",
    );
    let p = spec::parse(&src, "fl.toml").unwrap_or_else(|e| panic!("{e:?}"));
    let err = Task::new(p).err().expect("refused").to_string();
    assert!(
        err.contains("zero dynamics leave the operating region") && err.contains("thd"),
        "{err}"
    );
}

/// `synth` covers Init with 0 violations on the plant, and `verify` re-proves the image
/// (`cli_fl::synth_then_verify`).
#[test]
fn pendulum_synth_then_verify() {
    let (dir, _, _) = crate::cli_fl::synth_then_verify(&example(), "fl-pendulum");
    std::fs::remove_dir_all(&dir).ok();
}
