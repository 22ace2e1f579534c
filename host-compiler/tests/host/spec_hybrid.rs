//! Hybrid automata in the spec (`spec::hybrid`): the shipped Example 4.25 reads as written and builds
//! an automaton whose flow crosses the plane; every mistake is a diagnostic at the offending value; the
//! pipeline refuses a hybrid task with a message rather than running its first location alone.

use crate::spec_errors::expect;
use host_compiler::model::hybrid::{EdgeKind, Hybrid};
use host_compiler::spec::{self, EdgeKindDesc, ErrorKind};
use host_compiler::task::{Task, TaskError};

const BASE: &str = r#"seed = 3
horizon = 2.0

[plant]
time = "continuous"
period = 0.1
initial = "left"

[[plant.location]]
name = "left"
A = [[0.0, 1.0], [0.0, 0.0]]
B = [[0.0], [1.0]]
invariant = { A = [[1.0, 0.0]], b = [0.0] }

[[plant.location]]
name = "right"
A = [[0.0, 1.0], [0.0, -1.0]]
B = [[0.0], [1.0]]
c = [0.0, 0.5]

[[plant.edge]]
from = "left"
to = "right"
kind = "internal"
guard = { A = [[-1.0, 0.0]], b = [0.0] }
reset = { R = [[1.0, 0.0], [0.0, 0.5]], r = [0.0, 0.0] }

[init]
kind = "box"
lo = [-1.0, 0.0]
hi = [-0.5, 0.0]

[goal]
kind = "ball"
center = [1.0, 0.0]
radius = 0.2

[input]
kind = "box"
lo = [-1.0]
hi = [1.0]
"#;

fn edit(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "test bug: `{from}` not in BASE");
    BASE.replacen(from, to, 1)
}

#[test]
fn a_hybrid_plant_reads_as_written() {
    let p = spec::parse(BASE, "spec.toml").expect("BASE must parse");
    let h = p.hybrid.as_ref().expect("a hybrid plant");
    assert_eq!(h.locations.len(), 2);
    assert_eq!(
        (h.locations[0].name.as_str(), h.locations[1].name.as_str()),
        ("left", "right")
    );
    assert_eq!(h.locations[1].c, vec![0.0, 0.5]);
    assert_eq!(h.initial, 0);
    assert_eq!(
        (h.edges[0].from, h.edges[0].to, h.edges[0].kind),
        (0, 1, EdgeKindDesc::Internal)
    );
    assert_eq!(h.edges[0].R.get(1, 1), 0.5);
    // The problem's plant is the initial location's model.
    assert_eq!((p.plant.n(), p.plant.m(), p.plant.period), (2, 1, 0.1));
    let hy = Hybrid::from_spec(h, p.plant.period).unwrap();
    assert_eq!(hy.edges()[0].kind, EdgeKind::Internal);
}

#[test]
fn example_4_25_builds_an_automaton_whose_flow_crosses_the_plane() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-internal-4-25.toml"
    );
    let p = spec::load(path).unwrap_or_else(|e| panic!("{}", e.headline()));
    let h = p.hybrid.as_ref().unwrap();
    assert_eq!(h.locations.len(), 2);
    assert_eq!(h.edges.len(), 2);
    let hy = Hybrid::from_spec(h, p.plant.period).unwrap();
    // From just left of the plane with u = 0.5 (ẋ₁ ≈ 2.6), Σ(1) carries the state across within one
    // period (0.01 s).
    let step = hy.flow(h.initial, &[-0.01, 1.0, 0.0], &[0.5]).unwrap();
    assert_eq!(step.loc, 1);
    assert_eq!(step.events.len(), 1);
    // The single-location task refuses it, naming what it is, instead of running location 0 alone
    // (`synth` takes it through `synth::hybrid`).
    match Task::new(p) {
        Err(TaskError::HybridNotSupported {
            locations: 2,
            edges: 2,
        }) => {}
        Err(e) => panic!("wrong refusal: {e}"),
        Ok(_) => panic!("a hybrid task must be refused until the pipeline takes it"),
    }
}

#[test]
fn an_edge_to_an_unknown_location() {
    let src = edit("to = \"right\"", "to = \"middle\"");
    let e = expect(&src, ErrorKind::BadValue, "to = ", "\"middle\"");
    assert!(
        e.message().contains("\"left\", \"right\""),
        "{}",
        e.message()
    );
}

#[test]
fn an_unknown_initial_location() {
    let src = edit("initial = \"left\"", "initial = \"lft\"");
    expect(&src, ErrorKind::BadValue, "initial", "\"lft\"");
}

#[test]
fn a_missing_initial_location() {
    let src = edit("initial = \"left\"\n", "");
    let e = expect(&src, ErrorKind::MissingField, "[plant]", "[plant]");
    assert!(e.message().contains("initial"), "{}", e.message());
}

#[test]
fn a_guard_of_the_wrong_dimension() {
    let src = edit(
        "guard = { A = [[-1.0, 0.0]]",
        "guard = { A = [[-1.0, 0.0, 0.0]]",
    );
    let e = expect(&src, ErrorKind::Dimension, "guard", "[-1.0, 0.0, 0.0]");
    assert!(
        e.message().contains("plant.edge[0].guard.A"),
        "{}",
        e.message()
    );
}

#[test]
fn a_zero_guard_row() {
    let src = edit("guard = { A = [[-1.0, 0.0]]", "guard = { A = [[0.0, 0.0]]");
    expect(&src, ErrorKind::BadValue, "guard", "[0.0, 0.0]");
}

#[test]
fn a_reset_that_is_not_an_affine_map_of_the_state() {
    let src = edit("R = [[1.0, 0.0], [0.0, 0.5]]", "R = [[1.0, 0.0]]");
    let e = expect(&src, ErrorKind::Dimension, "reset", "[[1.0, 0.0]]");
    assert!(e.message().contains("reset.R"), "{}", e.message());
    let src = edit("r = [0.0, 0.0]", "r = [0.0]");
    expect(&src, ErrorKind::Dimension, "reset", "[0.0]");
}

#[test]
fn an_invariant_that_excludes_init() {
    let src = edit("hi = [-0.5, 0.0]", "hi = [0.5, 0.0]");
    let e = expect(
        &src,
        ErrorKind::BadValue,
        "[[plant.location]]",
        "{ A = [[1.0, 0.0]]",
    );
    assert!(e.message().contains("\"left\""), "{}", e.message());
    assert!(e.message().contains("0.5"), "{}", e.message());
}

#[test]
fn locations_of_different_dimensions() {
    let src = edit(
        "A = [[0.0, 1.0], [0.0, -1.0]]",
        "A = [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 0.0]]",
    );
    expect(
        &src,
        ErrorKind::Dimension,
        "name = \"right\"",
        "[[0.0, 1.0, 0.0]",
    );
}

#[test]
fn a_repeated_location_name() {
    let src = edit("name = \"right\"", "name = \"left\"");
    // The second location's name (the first "left" after the first location's invariant).
    expect(&src, ErrorKind::BadValue, "invariant = {", "\"left\"");
}

#[test]
fn an_edge_kind_that_is_neither() {
    let src = edit("kind = \"internal\"", "kind = \"sometimes\"");
    expect(&src, ErrorKind::BadValue, "[[plant.edge]]", "\"sometimes\"");
}

#[test]
fn plant_matrices_given_twice() {
    let src = edit(
        "period = 0.1\n",
        "period = 0.1\nA = [[0.0, 1.0], [0.0, 0.0]]\n",
    );
    let e = expect(&src, ErrorKind::BadValue, "[plant]", "[[0.0, 1.0]");
    assert!(
        e.message().contains("[[plant.location]]"),
        "{}",
        e.message()
    );
}

#[test]
fn discrete_time_locations_are_refused() {
    let src = edit("time = \"continuous\"", "time = \"discrete\"");
    expect(&src, ErrorKind::BadValue, "[plant]", "\"discrete\"");
}

#[test]
fn a_plant_with_one_location_still_needs_a_and_b() {
    // The spec-limit tests' base spec without its `A`.
    let single = crate::spec_bounds::edit("A = [[0.0, 1.0], [0.0, 0.0]]\n", "");
    let e = expect(&single, ErrorKind::MissingField, "[plant]", "[plant]");
    assert!(e.message().contains("`A`"), "{}", e.message());
}

#[test]
fn an_internal_edge_without_a_guard() {
    let src = edit("guard = { A = [[-1.0, 0.0]], b = [0.0] }\n", "");
    let e = spec::parse(&src, "spec.toml").expect_err("an internal edge needs its guard");
    assert_eq!(e.kind(), ErrorKind::MissingField, "{}", e.message());
    assert!(
        e.message()
            .contains("plant.edge[0] is internal and has no guard"),
        "{}",
        e.message()
    );
    // The place is the edge's table.
    let (line, _) = e.line_col().expect("a located diagnostic");
    let edge_line = src
        .lines()
        .position(|l| l.starts_with("from = \"left\""))
        .unwrap()
        + 1;
    assert!(
        (edge_line - 1..=edge_line + 3).contains(&line),
        "line {line}"
    );
}

#[test]
fn a_forced_edge_without_a_guard_may_be_taken_anywhere() {
    let src = edit(
        "kind = \"internal\"\nguard = { A = [[-1.0, 0.0]], b = [0.0] }\n",
        "kind = \"forced\"\n",
    );
    let p = spec::parse(&src, "spec.toml").expect("a forced edge may omit its guard");
    let h = p.hybrid.as_ref().unwrap();
    assert_eq!(h.edges[0].kind, EdgeKindDesc::Forced);
    assert_eq!(h.edges[0].guard.b.len(), 0, "no rows: the whole space");
    let plant = Hybrid::from_spec(h, 0.1).unwrap();
    let guard = &plant.edges()[0].guard;
    assert!(guard.contains(&[-5.0, 3.0]) && guard.contains(&[7.0, -1.0]));
}

#[test]
fn forced_synthesis_refuses_a_reset_the_controller_would_measure_before() {
    use host_compiler::synth::hybrid::{HybridSynthError, HybridTask};
    // BASE's edge resets ẋ to half: as a forced edge the controller would apply the next segment's
    // law to the state before the reset.
    let src = edit("kind = \"internal\"", "kind = \"forced\"");
    let p = spec::parse(&src, "spec.toml").unwrap();
    match HybridTask::new(p) {
        Err(HybridSynthError::ForcedReset { edge: 0 }) => {}
        Err(e) => panic!("wrong refusal: {e}"),
        Ok(_) => panic!("a forced edge with a non-identity reset was accepted"),
    }
    // Both kinds in one automaton: refused by name.
    let src = edit(
        "[init]",
        "[[plant.edge]]\nfrom = \"right\"\nto = \"left\"\nkind = \"forced\"\n\n[init]",
    );
    let p = spec::parse(&src, "spec.toml").unwrap();
    match HybridTask::new(p) {
        Err(e @ HybridSynthError::MixedEdges { .. }) => {
            assert!(e.to_string().contains("both kinds"), "{e}")
        }
        Err(e) => panic!("wrong refusal: {e}"),
        Ok(_) => panic!("an automaton with both kinds of edge was accepted"),
    }
}
