//! Malformed task specs: each must be rejected with the right error kind, and the diagnostic must point
//! at the offending TOML (checked as 1-based line:col, computed here independently from the text, and
//! in miette's rendered report).
#![allow(non_snake_case)]

use host_compiler::spec::{self, ErrorKind, SpecError};

/// A small valid spec that the cases below break one thing at a time.
const BASE: &str = r#"seed = 3
horizon = 2.0

[plant]
time = "continuous"
A = [[0.0, 1.0], [0.0, 0.0]]
B = [[0.0], [1.0]]
c = [0.0, 0.0]
period = 0.1

[init]
kind = "box"
lo = [-0.1, 0.0]
hi = [0.1, 0.0]

[goal]
kind = "ball"
center = [1.0, 0.0]
radius = 0.2

[[unsafe]]
kind = "box"
lo = [0.4, 0.5]
hi = [0.6, 0.9]

[input]
kind = "box"
lo = [-1.0]
hi = [1.0]
"#;

/// Replace the first occurrence of `from` (which must exist) by `to`.
fn edit(from: &str, to: &str) -> String {
    assert!(BASE.contains(from), "test bug: `{from}` not in BASE");
    BASE.replacen(from, to, 1)
}

/// 1-based (line, col) of the first occurrence of `needle` at or after the first occurrence of `anchor`.
pub(crate) fn pos(src: &str, anchor: &str, needle: &str) -> (usize, usize) {
    let a = src
        .find(anchor)
        .unwrap_or_else(|| panic!("test bug: anchor `{anchor}` not found"));
    let off = a + src[a..]
        .find(needle)
        .unwrap_or_else(|| panic!("test bug: `{needle}` not after `{anchor}`"));
    let line = src[..off].matches('\n').count() + 1;
    let line_start = src[..off].rfind('\n').map_or(0, |i| i + 1);
    (line, src[line_start..off].chars().count() + 1)
}

pub(crate) fn render(e: &SpecError) -> String {
    let mut out = String::new();
    miette::GraphicalReportHandler::new_themed(miette::GraphicalTheme::unicode_nocolor())
        .with_width(400)
        .render_report(&mut out, e)
        .unwrap();
    out
}

/// Parse `src`, expect an error of `kind` whose primary label starts at `needle` (first occurrence after
/// `anchor`), and return the error for further checks.
#[track_caller]
pub(crate) fn expect(src: &str, kind: ErrorKind, anchor: &str, needle: &str) -> SpecError {
    let e = match spec::parse(src, "spec.toml") {
        Ok(_) => panic!("spec was accepted, expected {kind:?}\n{src}"),
        Err(e) => e,
    };
    let (l, c) = pos(src, anchor, needle);
    assert_eq!(e.kind(), kind, "wrong kind; message: {}", e.message());
    assert_eq!(
        e.line_col(),
        Some((l, c)),
        "wrong location for: {}",
        e.message()
    );
    let r = render(&e);
    assert!(
        r.contains(&format!("spec.toml:{l}:{c}")),
        "rendered report lacks spec.toml:{l}:{c}:\n{r}"
    );
    assert!(
        r.contains(e.message()),
        "rendered report lacks the message:\n{r}"
    );
    e
}

#[test]
fn base_spec_is_valid() {
    let p = spec::parse(BASE, "spec.toml").expect("BASE must parse");
    assert_eq!(p.plant.n(), 2);
    assert_eq!(p.plant.m(), 1);
    assert_eq!(p.unsafe_sets.len(), 1);
    assert_eq!(p.horizon_steps(), 20);
}

#[test]
fn unknown_top_level_key() {
    let src = edit("horizon = 2.0\n", "horizon = 2.0\ncolour = \"red\"\n");
    let e = expect(&src, ErrorKind::UnknownKey, "colour", "colour");
    assert!(e.message().contains("colour"));
}

#[test]
fn unknown_key_in_plant() {
    let src = edit("period = 0.1\n", "period = 0.1\nAd = [[1.0]]\n");
    expect(&src, ErrorKind::UnknownKey, "Ad =", "Ad");
}

#[test]
fn misspelt_key_in_set() {
    let src = edit("radius = 0.2", "radus = 0.2");
    expect(&src, ErrorKind::UnknownKey, "radus", "radus");
}

#[test]
fn key_not_used_by_the_set_kind() {
    let src = edit(
        "radius = 0.2\n",
        "radius = 0.2\nQ = [[1.0, 0.0], [0.0, 1.0]]\n",
    );
    let e = expect(&src, ErrorKind::UnknownKey, "Q = ", "[[");
    assert!(
        e.message().contains("`Q`") && e.message().contains("ball"),
        "{}",
        e.message()
    );
}

#[test]
fn missing_top_level_field() {
    let src = edit("horizon = 2.0\n", "");
    let e = spec::parse(&src, "spec.toml").unwrap_err();
    assert_eq!(e.kind(), ErrorKind::MissingField);
    assert!(e.message().contains("horizon"));
    // A missing top-level key has no better place than the start of the file.
    assert_eq!(e.line_col(), Some((1, 1)));
    assert!(render(&e).contains("spec.toml:1:1"));
}

#[test]
fn missing_field_in_plant_points_at_the_table() {
    let src = edit("period = 0.1\n", "");
    let e = expect(&src, ErrorKind::MissingField, "[plant]", "[plant]");
    assert!(e.message().contains("period"));
}

#[test]
fn ball_without_radius() {
    let src = edit("radius = 0.2\n", "");
    let e = expect(&src, ErrorKind::MissingField, "[goal]", "[goal]");
    assert!(e.message().contains("radius"));
}

#[test]
fn wrong_type_horizon_string() {
    let src = edit("horizon = 2.0", "horizon = \"2 s\"");
    expect(&src, ErrorKind::WrongType, "horizon", "\"2 s\"");
}

#[test]
fn wrong_type_matrix_entry() {
    let src = edit("B = [[0.0], [1.0]]", "B = [[0.0], [true]]");
    expect(&src, ErrorKind::WrongType, "B = ", "true");
}

#[test]
fn non_square_A_points_at_the_short_row() {
    let src = edit("A = [[0.0, 1.0], [0.0, 0.0]]", "A = [[0.0, 1.0], [0.0]]");
    let e = expect(&src, ErrorKind::Dimension, "A = [[0.0, 1.0], ", "[0.0]");
    assert!(
        e.message().contains("plant.A") && e.message().contains("expected 2"),
        "{}",
        e.message()
    );
}

#[test]
fn B_with_wrong_row_count() {
    let src = edit("B = [[0.0], [1.0]]", "B = [[0.0], [1.0], [2.0]]");
    let e = expect(&src, ErrorKind::Dimension, "B = ", "[[");
    assert!(
        e.message().contains("plant.B has 3 rows, expected 2"),
        "{}",
        e.message()
    );
}

#[test]
fn c_with_wrong_length() {
    let src = edit("c = [0.0, 0.0]", "c = [0.0, 0.0, 1.0]");
    let e = expect(&src, ErrorKind::Dimension, "c = ", "[");
    assert!(
        e.message().contains("plant.c has 3 entries, expected 2"),
        "{}",
        e.message()
    );
}

#[test]
fn output_map_with_wrong_column_count() {
    let src = edit("period = 0.1\n", "period = 0.1\nC = [[1.0, 0.0, 0.0]]\n");
    let e = expect(&src, ErrorKind::Dimension, "C = ", "[1.0, 0.0, 0.0]");
    assert!(e.message().contains("plant.C"), "{}", e.message());
}

#[test]
fn goal_center_does_not_match_coords() {
    let src = edit("radius = 0.2\n", "radius = 0.2\ncoords = [\"x1\"]\n");
    let e = expect(&src, ErrorKind::Dimension, "center = ", "[1.0, 0.0]");
    assert!(
        e.message()
            .contains("goal.center has 2 entries, expected 1"),
        "{}",
        e.message()
    );
}

#[test]
fn init_with_wrong_length() {
    let src = edit("hi = [0.1, 0.0]", "hi = [0.1, 0.0, 0.0]");
    expect(&src, ErrorKind::Dimension, "hi = [0.1", "[");
}

#[test]
fn nan_in_A() {
    let src = edit(
        "A = [[0.0, 1.0], [0.0, 0.0]]",
        "A = [[0.0, 1.0], [nan, 0.0]]",
    );
    let e = expect(&src, ErrorKind::NonFinite, "A = ", "nan");
    assert!(e.message().contains("plant.A[1][0]"), "{}", e.message());
}

#[test]
fn infinite_radius() {
    let src = edit("radius = 0.2", "radius = inf");
    expect(&src, ErrorKind::NonFinite, "radius", "inf");
}

#[test]
fn inverted_init_box_names_the_coordinate() {
    let src = edit(
        "lo = [-0.1, 0.0]\nhi = [0.1, 0.0]",
        "lo = [-0.1, 0.3]\nhi = [0.1, 0.0]",
    );
    let e = expect(&src, ErrorKind::InvertedBox, "lo = [-0.1, ", "0.3");
    assert!(e.message().contains("coordinate 2"), "{}", e.message());
    // The second label is on the matching hi entry.
    let hi_off = src.find("hi = [0.1, 0.0]").unwrap() + "hi = [0.1, ".len();
    assert_eq!(e.label_spans()[1].0.start, hi_off);
}

#[test]
fn inverted_unsafe_box() {
    let src = edit("lo = [0.4, 0.5]", "lo = [0.7, 0.5]");
    expect(&src, ErrorKind::InvertedBox, "lo = [0.7", "0.7");
}

#[test]
fn ellipsoid_shape_not_psd_reports_smallest_eigenvalue() {
    let src = edit(
        "kind = \"ball\"\ncenter = [1.0, 0.0]\nradius = 0.2",
        "kind = \"ellipsoid\"\ncenter = [1.0, 0.0]\nQ = [[1.0, 2.0], [2.0, 1.0]]",
    );
    let e = expect(&src, ErrorKind::NotPsd, "Q = ", "[[");
    // Eigenvalues of [[1,2],[2,1]] are 3 and -1.
    assert!(e.message().contains("-1.0"), "{}", e.message());
}

#[test]
fn ellipsoid_shape_not_symmetric() {
    let src = edit(
        "kind = \"ball\"\ncenter = [1.0, 0.0]\nradius = 0.2",
        "kind = \"ellipsoid\"\ncenter = [1.0, 0.0]\nQ = [[4.0, 0.5], [0.0, 4.0]]",
    );
    expect(&src, ErrorKind::NotSymmetric, "Q = [[4.0, ", "0.5");
}

#[test]
fn init_meets_unsafe_ball() {
    let src = edit(
        "[[unsafe]]\nkind = \"box\"\nlo = [0.4, 0.5]\nhi = [0.6, 0.9]",
        "[[unsafe]]\nkind = \"ball\"\ncenter = [0.15, 0.05]\nradius = 0.08",
    );
    let e = expect(&src, ErrorKind::InitMeetsUnsafe, "[[unsafe]]", "[[unsafe]]");
    assert!(e.message().contains("unsafe[0]"), "{}", e.message());
}

#[test]
fn init_meets_unsafe_half_plane_through_pinned_coordinate() {
    // x2 is pinned at 0 in Init; the half-plane x1 + x2 ≥ 0.1 contains Init's corner (0.1, 0).
    let src = edit(
        "[[unsafe]]\nkind = \"box\"\nlo = [0.4, 0.5]\nhi = [0.6, 0.9]",
        "[[unsafe]]\nkind = \"ball\"\ncenter = [5.0, 5.0]\nradius = 0.1\n\n[[unsafe]]\nkind = \"polytope\"\nA = [[-1.0, -1.0]]\nb = [-0.1]",
    );
    // The primary label is the second [[unsafe]] header.
    let e = expect(
        &src,
        ErrorKind::InitMeetsUnsafe,
        "radius = 0.1\n\n[[unsafe]]",
        "[[unsafe]]",
    );
    assert!(e.message().contains("unsafe[1]"), "{}", e.message());
}

#[test]
fn goal_inside_unsafe() {
    let src = edit(
        "[[unsafe]]\nkind = \"box\"\nlo = [0.4, 0.5]\nhi = [0.6, 0.9]",
        "[[unsafe]]\nkind = \"ball\"\ncenter = [1.05, 0.0]\nradius = 0.3",
    );
    let e = expect(&src, ErrorKind::GoalUnreachable, "[goal]", "[goal]");
    assert!(e.message().contains("inside unsafe[0]"), "{}", e.message());
}

#[test]
fn goal_polytope_with_no_interior() {
    let src = edit(
        "kind = \"ball\"\ncenter = [1.0, 0.0]\nradius = 0.2",
        "kind = \"polytope\"\nA = [[1.0, 0.0], [-1.0, 0.0]]\nb = [1.0, -1.0]",
    );
    let e = expect(&src, ErrorKind::GoalUnreachable, "[goal]", "[goal]");
    assert!(e.message().contains("no interior"), "{}", e.message());
}

#[test]
fn goal_polytope_empty() {
    let src = edit(
        "kind = \"ball\"\ncenter = [1.0, 0.0]\nradius = 0.2",
        "kind = \"polytope\"\nA = [[1.0, 0.0], [-1.0, 0.0]]\nb = [1.0, -2.0]",
    );
    let e = expect(&src, ErrorKind::GoalUnreachable, "[goal]", "[goal]");
    assert!(e.message().contains("empty"), "{}", e.message());
}

#[test]
fn horizon_zero() {
    let src = edit("horizon = 2.0", "horizon = 0.0");
    expect(&src, ErrorKind::Horizon, "horizon", "0.0");
}

#[test]
fn horizon_shorter_than_a_period() {
    let src = edit("horizon = 2.0", "horizon = 0.05");
    expect(&src, ErrorKind::Horizon, "horizon", "0.05");
}

#[test]
fn period_negative() {
    let src = edit("period = 0.1", "period = -0.1");
    expect(&src, ErrorKind::Period, "period", "-0.1");
}

#[test]
fn seed_negative() {
    let src = edit("seed = 3", "seed = -3");
    expect(&src, ErrorKind::Seed, "seed", "-3");
}

#[test]
fn confidence_out_of_range() {
    let src = format!("{BASE}\n[synthesis]\nconfidence = 1.0\n");
    let e = expect(&src, ErrorKind::Setting, "confidence = ", "1.0");
    assert!(e.message().contains("confidence"), "{}", e.message());
}

#[test]
fn max_trajectories_zero() {
    let src = format!("{BASE}\n[synthesis]\nmax_trajectories = 0\n");
    expect(&src, ErrorKind::Setting, "max_trajectories", "0");
}

#[test]
fn zero_reference_hold() {
    let src = format!("{BASE}\n[synthesis]\nreference_hold = 0\n");
    let e = expect(&src, ErrorKind::Setting, "reference_hold", "0");
    assert!(e.message().contains("at least 1"), "{}", e.message());
}

#[test]
fn unknown_synthesis_setting() {
    let src = format!("{BASE}\n[synthesis]\nconfidance = 0.9\n");
    expect(&src, ErrorKind::UnknownKey, "confidance", "confidance");
}

#[test]
fn unknown_set_kind() {
    let src = edit("kind = \"ball\"", "kind = \"disc\"");
    let e = expect(&src, ErrorKind::BadValue, "kind = \"disc\"", "\"disc\"");
    assert!(e.message().contains("disc"));
}

#[test]
fn bad_coordinate_name() {
    let src = edit(
        "radius = 0.2\n",
        "radius = 0.2\ncoords = [\"x1\", \"z2\"]\n",
    );
    expect(&src, ErrorKind::BadValue, "coords", "[");
}

#[test]
fn coordinate_out_of_range() {
    let src = edit(
        "radius = 0.2\n",
        "radius = 0.2\ncoords = [\"x1\", \"x5\"]\n",
    );
    let e = expect(&src, ErrorKind::Dimension, "coords", "[");
    assert!(e.message().contains("x5"));
}

#[test]
fn misspelt_time_domain() {
    let src = edit("time = \"continuous\"", "time = \"continous\"");
    expect(&src, ErrorKind::BadValue, "time", "\"continous\"");
}

#[test]
fn discrete_offset_in_continuous_plant() {
    let src = edit("c = [0.0, 0.0]", "g = [0.0, 0.0]");
    expect(&src, ErrorKind::BadValue, "g = ", "[");
}

#[test]
fn toml_syntax_error() {
    let src = edit("[input]", "[input");
    let e = spec::parse(&src, "spec.toml").unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Syntax);
    assert_eq!(
        e.line_col().map(|(l, _)| l),
        Some(pos(&src, "[input", "[input").0)
    );
}

#[test]
fn init_must_be_a_box() {
    let src = edit("[init]\nkind = \"box\"", "[init]\nkind = \"ball\"");
    expect(&src, ErrorKind::BadValue, "[init]\nkind = ", "\"ball\"");
}

#[test]
fn input_ball_radius_zero() {
    let src = edit(
        "[input]\nkind = \"box\"\nlo = [-1.0]\nhi = [1.0]",
        "[input]\nkind = \"ball\"\nradius = 0.0",
    );
    expect(&src, ErrorKind::BadValue, "[input]", "0.0");
}

#[test]
fn input_box_wrong_length() {
    let src = edit("lo = [-1.0]", "lo = [-1.0, -1.0]");
    let e = expect(&src, ErrorKind::Dimension, "lo = [-1.0, -1.0]", "[");
    assert!(
        e.message().contains("plant.B has 1 columns"),
        "{}",
        e.message()
    );
}

#[test]
fn negative_radius() {
    let src = edit("radius = 0.2", "radius = -0.2");
    expect(&src, ErrorKind::BadValue, "radius", "-0.2");
}

#[test]
fn named_set_with_bad_name() {
    let src = format!(
        "{BASE}\n[sets.\"2fast\"]\nkind = \"box\"\nlo = [0.0]\nhi = [1.0]\ncoords = [\"x2\"]\n"
    );
    expect(&src, ErrorKind::BadValue, "[sets.", "\"2fast\"");
}

#[test]
fn io_error_has_no_location() {
    let e = spec::load("/nonexistent/definitely/missing.toml").unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Io);
    assert_eq!(e.line_col(), None);
}

#[test]
fn named_sets_file_errors_point_into_that_file() {
    let src = "[sets.wall]\nkind = \"polytope\"\nA = [[1.0, 0.0]]\nb = [1.0]\n\n[sets.zone]\nkind = \"box\"\nlo = [0.0, 0.0]\nhi = [1.0, 1.0]\ncoords = \"output\"\n";
    let e = spec::parse_named_sets(src, "sets.toml").unwrap_err();
    assert_eq!(e.kind(), ErrorKind::BadValue);
    assert_eq!(e.line_col(), Some(pos(src, "coords", "\"output\"")));
    assert_eq!(e.file_name(), Some("sets.toml"));
}

#[test]
fn rendered_report_shows_code_label_and_help() {
    let src = edit(
        "lo = [-0.1, 0.0]\nhi = [0.1, 0.0]",
        "lo = [-0.1, 0.3]\nhi = [0.1, 0.0]",
    );
    let e = spec::parse(&src, "spec.toml").unwrap_err();
    let r = render(&e);
    if std::env::var_os("SHOW_REPORT").is_some() {
        eprintln!("{r}");
    }
    assert!(r.contains("spec::inverted_box"), "{r}");
    assert!(r.contains("lo[1] = 0.3"), "{r}");
    assert!(r.contains("hi[1] = 0"), "{r}");
    assert!(r.contains("pin the coordinate"), "{r}");
    assert_eq!(
        e.headline(),
        format!("spec.toml:{}:{}: {}", 13, 13, e.message())
    );
}

#[test]
fn zero_shape_matrix() {
    let src = edit(
        "kind = \"ball\"\ncenter = [1.0, 0.0]\nradius = 0.2",
        "kind = \"ellipsoid\"\ncenter = [1.0, 0.0]\nQ = [[0.0, 0.0], [0.0, 0.0]]",
    );
    expect(&src, ErrorKind::BadValue, "Q = ", "[[");
}

#[test]
fn empty_unsafe_polytope() {
    let src = edit(
        "[[unsafe]]\nkind = \"box\"\nlo = [0.4, 0.5]\nhi = [0.6, 0.9]",
        "[[unsafe]]\nkind = \"polytope\"\nA = [[1.0, 0.0], [-1.0, 0.0]]\nb = [0.5, -0.6]",
    );
    let e = expect(&src, ErrorKind::BadValue, "[[unsafe]]", "[[unsafe]]");
    assert!(e.message().contains("empty"), "{}", e.message());
}

#[test]
fn dependent_output_rows() {
    let src = edit(
        "period = 0.1\n",
        "period = 0.1\nC = [[1.0, 0.0], [2.0, 0.0]]\n",
    );
    let src = src.replacen("radius = 0.2\n", "radius = 0.2\ncoords = \"output\"\n", 1);
    let e = expect(&src, ErrorKind::BadValue, "coords", "\"output\"");
    assert!(e.message().contains("rank 1 of 2"), "{}", e.message());
}

#[test]
fn seed_too_large() {
    let src = edit("seed = 3", "seed = 18446744073709551616");
    expect(&src, ErrorKind::Seed, "seed", "18446744073709551616");
    // The largest u64 is accepted.
    let ok = edit("seed = 3", "seed = 18446744073709551615");
    assert_eq!(spec::parse(&ok, "spec.toml").unwrap().seed, u64::MAX);
}

#[test]
fn seed_as_float_is_a_type_error() {
    let src = edit("seed = 3", "seed = 3.0");
    expect(&src, ErrorKind::WrongType, "seed", "3.0");
}
