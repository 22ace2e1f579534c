//! Sizes a spec implies are bounded before any work (issue 18, class 2): dimensions, samples in the
//! horizon, the whole budget's table rows, polytope rows and coverage samples beyond `spec::limits` are
//! `Capacity` diagnostics at the key that implies them. Each case is refused by validation alone, so
//! these tests allocate nothing of the size they name.

use host_compiler::spec::{self, limits, ErrorKind};

use crate::spec_bounds::{edit, BASE};

/// 1-based (line, column) of the first `needle` in `src`, plus `skip` characters.
fn pos(src: &str, needle: &str, skip: usize) -> (usize, usize) {
    let off = src.find(needle).expect("test bug: needle not found") + skip;
    let line = src[..off].matches('\n').count() + 1;
    let start = src[..off].rfind('\n').map_or(0, |i| i + 1);
    (line, src[start..off].chars().count() + 1)
}

/// Refused as `Capacity` at the value after `key = ` (the first such line); returns the message.
#[track_caller]
fn refused_at(src: &str, key: &str) -> String {
    let e = spec::parse(src, "spec.toml").expect_err("must be refused");
    assert_eq!(e.kind(), ErrorKind::Capacity, "{}", e.message());
    let needle = format!("{key} = ");
    assert_eq!(
        e.line_col(),
        Some(pos(src, &needle, needle.len())),
        "{}",
        e.message()
    );
    e.message().to_string()
}

fn matrix(rows: usize, cols: usize) -> String {
    let row = format!("[{}]", vec!["0.0"; cols].join(", "));
    format!("[{}]", vec![row; rows].join(", "))
}

fn vector(n: usize, v: f64) -> String {
    format!("[{}]", vec![format!("{v:?}"); n].join(", "))
}

#[test]
fn a_horizon_beyond_the_table_capacity_is_refused_at_the_horizon() {
    // The cases of the issue: 1e9 s, and a period of 1e-9 s (1e18 and 2e9 samples).
    let msg = refused_at(&edit("horizon = 2.0", "horizon = 1e9"), "horizon");
    assert!(msg.contains("524288") && msg.contains("samples"), "{msg}");
    let msg = refused_at(&edit("period = 0.1", "period = 1e-9"), "horizon");
    assert!(msg.contains("2000000000 samples"), "{msg}");
    // Exactly the capacity with a budget of one trajectory is accepted.
    let src = edit("horizon = 2.0", "horizon = 52428.8").replace(
        "hi = [1.0]\n",
        "hi = [1.0]\n\n[synthesis]\nmax_trajectories = 1\n",
    );
    let p = spec::parse(&src, "spec.toml").unwrap();
    assert_eq!(p.horizon_steps(), limits::MAX_STEPS);
}

#[test]
fn a_budget_whose_table_exceeds_the_image_is_refused() {
    // 10 000 samples × the default 64 trajectories = 640 000 rows (m = 1: the image's 524 288 values are
    // as many rows): at the horizon, naming the default.
    let src = edit("horizon = 2.0", "horizon = 1000.0");
    let msg = refused_at(&src, "horizon");
    assert!(
        msg.contains("640000 rows")
            && msg.contains("64 trajectories")
            && msg.contains("524288 rows at m = 1"),
        "{msg}"
    );
    // With an explicit budget: at max_trajectories. 53 × 10 000 = 530 000 > 524 288 ≥ 52 × 10 000.
    let with = |k: usize| {
        src.replace(
            "hi = [1.0]\n",
            &format!("hi = [1.0]\n\n[synthesis]\nmax_trajectories = {k}\n"),
        )
    };
    let msg = refused_at(&with(53), "max_trajectories");
    assert!(msg.contains("530000 rows"), "{msg}");
    spec::parse(&with(52), "spec.toml").unwrap();
    // A budget beyond the image's trajectory capacity, whatever the horizon.
    let src = BASE.replace(
        "hi = [1.0]\n",
        "hi = [1.0]\n\n[synthesis]\nmax_trajectories = 1100\n",
    );
    let msg = refused_at(&src, "max_trajectories");
    assert!(msg.contains("1024"), "{msg}");
}

#[test]
fn a_coverage_tolerance_whose_samples_exceed_the_budget_is_refused() {
    // The case of the issue: 1e-4 (about 9·10⁸ samples, 22 GB and more).
    let src = BASE.replace(
        "hi = [1.0]\n",
        "hi = [1.0]\n\n[synthesis]\ncoverage_tolerance = 1e-4\n",
    );
    let msg = refused_at(&src, "coverage_tolerance");
    assert!(msg.contains("GB") && msg.contains("samples"), "{msg}");
    // The default tolerance (and a tenfold-tighter one at n = 2) is within the budget.
    let src = BASE.replace(
        "hi = [1.0]\n",
        "hi = [1.0]\n\n[synthesis]\ncoverage_tolerance = 0.005\n",
    );
    spec::parse(&src, "spec.toml").unwrap();
}

#[test]
fn dimensions_beyond_the_image_capacity_are_refused_at_the_matrix() {
    // The case of the issue: a 60-state plant.
    let src = edit(
        "A = [[0.0, 1.0], [0.0, 0.0]]",
        &format!("A = {}", matrix(60, 60)),
    )
    .replace("B = [[0.0], [1.0]]", &format!("B = {}", matrix(60, 1)));
    let msg = refused_at(&src, "A");
    assert!(msg.contains("n = 60") && msg.contains("n ≤ 12"), "{msg}");
    // Seven inputs.
    let src = edit("B = [[0.0], [1.0]]", &format!("B = {}", matrix(2, 7)))
        .replace("lo = [-1.0]", &format!("lo = {}", vector(7, -1.0)))
        .replace("hi = [1.0]", &format!("hi = {}", vector(7, 1.0)));
    let msg = refused_at(&src, "B");
    assert!(msg.contains("m = 7") && msg.contains("m ≤ 6"), "{msg}");
}

#[test]
fn a_polytope_with_too_many_rows_is_refused_at_its_matrix() {
    // The case of the issue: a Goal polytope with 1 000 (redundant) rows.
    let goal = "kind = \"ball\"\ncenter = [1.0, 0.0]\nradius = 0.2";
    let rows = |k: usize| {
        let a = format!("[{}]", vec!["[1.0, 0.0]"; k].join(", "));
        format!("kind = \"polytope\"\nA = {a}\nb = {}", vector(k, 1.2))
    };
    let src = edit(goal, &rows(1000));
    let e = spec::parse(&src, "spec.toml").expect_err("must be refused");
    assert_eq!(e.kind(), ErrorKind::Capacity, "{}", e.message());
    assert_eq!(e.line_col(), Some(pos(&src, "A = [[1.0", 4)));
    let msg = e.message();
    assert!(
        msg.contains("goal.A has 1000 rows") && msg.contains("at most 64"),
        "{msg}"
    );
    // At the limit the row count is accepted (the set itself is then judged as before).
    let e = spec::parse(&edit(goal, &rows(limits::MAX_POLYTOPE_ROWS)), "spec.toml");
    assert!(e
        .as_ref()
        .map_or_else(|e| e.kind() != ErrorKind::Capacity, |_| true));
}

#[test]
fn a_hybrid_plant_beyond_the_image_capacities_is_refused() {
    let src = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/hybrid-internal-4-25.toml"
    ))
    .unwrap();
    let left = "[[plant.location]]\nname = \"left\"";
    assert!(src.contains(left), "test bug: the example changed");
    // Nine locations (the image holds 8): refused at the ninth.
    let extra: String = (0..7)
        .map(|i| format!("[[plant.location]]\nname = \"extra{i}\"\nA = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]\nB = [[1.0], [0.0], [0.0]]\n\n"))
        .collect();
    let nine = src.replacen(left, &format!("{extra}{left}"), 1);
    let e = spec::parse(&nine, "spec.toml").expect_err("must be refused");
    assert_eq!(e.kind(), ErrorKind::Capacity, "{}", e.message());
    assert!(e.message().contains("9 locations"), "{}", e.message());
    let ninth = nine.match_indices("[[plant.location]]").nth(8).unwrap().0;
    assert_eq!(e.line_col(), Some(pos(&nine, &nine[ninth..], 0)));
    // A location of 13 states: refused at its A, before its entries or B are read.
    let a = "A = [\n  [-1.2,  2.1, -0.3],\n  [-8.4, -3.8, -0.6],\n  [-0.6,  4.3, -2.9],\n]";
    assert!(src.contains(a), "test bug: the example changed");
    let big = src.replacen(a, &format!("A = {}", matrix(13, 13)), 1);
    let e = spec::parse(&big, "spec.toml").expect_err("must be refused");
    assert_eq!(e.kind(), ErrorKind::Capacity, "{}", e.message());
    assert!(e.message().contains("n = 13"), "{}", e.message());
    assert_eq!(e.line_col(), Some(pos(&big, "A = [[0.0", 4)));
}
