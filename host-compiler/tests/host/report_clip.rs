//! The report's planar geometry: Sutherland–Hodgman clipping of half-plane sets to the plot box
//! (hand-computed cases and a property test against point-membership brute force), ellipse outlines
//! and equal-aspect framing.

#![allow(non_snake_case)]

use host_compiler::report::data::Ellipse2;
use host_compiler::report::planar::{
    bounded_halfplanes, clip_halfplanes, clip_polygon_halfplane, clip_to_rect, ellipse_points,
    ellipse_rect, polygon_area, Rect,
};
use proptest::prelude::*;

const UNIT: Rect = Rect {
    lo: [0.0, 0.0],
    hi: [1.0, 1.0],
};

fn close(a: [f64; 2], b: [f64; 2]) -> bool {
    (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12
}

/// The polygon has exactly these vertices (in any rotation, same order).
fn assert_same_polygon(got: &[[f64; 2]], want: &[[f64; 2]]) {
    assert_eq!(got.len(), want.len(), "got {got:?}, want {want:?}");
    let start = got
        .iter()
        .position(|&p| close(p, want[0]))
        .unwrap_or_else(|| panic!("{:?} not in {got:?}", want[0]));
    for (k, w) in want.iter().enumerate() {
        assert!(
            close(got[(start + k) % got.len()], *w),
            "got {got:?}, want {want:?}"
        );
    }
}

#[test]
fn vertical_cut_keeps_left_half() {
    // x ≤ 0.5 on [0,1]²: the rectangle [0, 0.5] × [0, 1].
    let p = clip_halfplanes(&[[1.0, 0.0]], &[0.5], &UNIT);
    assert_same_polygon(&p, &[[0.0, 0.0], [0.5, 0.0], [0.5, 1.0], [0.0, 1.0]]);
    assert!((polygon_area(&p) - 0.5).abs() < 1e-12);
}

#[test]
fn unbounded_diagonal_halfplane_becomes_triangle() {
    // x + y ≤ 1 is unbounded; inside [0,1]² it is the triangle (0,0), (1,0), (0,1), counter-clockwise.
    let p = clip_halfplanes(&[[1.0, 1.0]], &[1.0], &UNIT);
    assert_same_polygon(&p, &[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
    assert!((polygon_area(&p) - 0.5).abs() < 1e-12, "ccw, area 1/2");
    // Such a set does not frame a plot.
    assert!(bounded_halfplanes(&[[1.0, 1.0]], &[1.0], &UNIT).is_none());
}

#[test]
fn unbounded_halfplane_cutting_a_corner_gives_pentagon() {
    // y ≥ x − 0.5 ⇔ x − y ≤ 0.5 on [0,1]² cuts off the corner triangle (0.5,0),(1,0),(1,0.5).
    let p = clip_halfplanes(&[[1.0, -1.0]], &[0.5], &UNIT);
    assert_same_polygon(
        &p,
        &[[0.0, 0.0], [0.5, 0.0], [1.0, 0.5], [1.0, 1.0], [0.0, 1.0]],
    );
    assert!((polygon_area(&p) - (1.0 - 0.125)).abs() < 1e-12);
}

#[test]
fn halfplane_containing_the_box_keeps_the_box() {
    let p = clip_halfplanes(&[[1.0, 0.0], [0.0, -1.0]], &[5.0, 3.0], &UNIT);
    assert_same_polygon(&p, &UNIT.corners());
}

#[test]
fn empty_intersections() {
    // Entirely outside the box.
    assert!(clip_halfplanes(&[[1.0, 0.0]], &[-1.0], &UNIT).is_empty());
    // Contradictory: x ≤ 0.2 and x ≥ 0.8.
    assert!(clip_halfplanes(&[[1.0, 0.0], [-1.0, 0.0]], &[0.2, -0.8], &UNIT).is_empty());
    // Touching the box in a single corner (x + y ≤ 0) has no interior.
    assert!(clip_halfplanes(&[[1.0, 1.0]], &[0.0], &UNIT).is_empty());
    // Touching along an edge (x ≤ 0) has no interior either.
    assert!(clip_halfplanes(&[[1.0, 0.0]], &[0.0], &UNIT).is_empty());
    // a = 0: 0 ≤ −1 is never true, 0 ≤ 1 always.
    assert!(clip_halfplanes(&[[0.0, 0.0]], &[-1.0], &UNIT).is_empty());
    assert_eq!(clip_halfplanes(&[[0.0, 0.0]], &[1.0], &UNIT).len(), 4);
    // Non-finite data draw nothing.
    assert!(clip_halfplanes(&[[f64::NAN, 1.0]], &[1.0], &UNIT).is_empty());
    // An empty box clips to nothing.
    assert!(clip_halfplanes(&[], &[], &Rect::EMPTY).is_empty());
}

#[test]
fn bounded_triangle_is_recognised_and_not_cut() {
    // x ≥ 0, y ≥ 0, x + y ≤ 1 inside [−5, 5]².
    let (a, b) = (
        vec![[-1.0, 0.0], [0.0, -1.0], [1.0, 1.0]],
        vec![0.0, 0.0, 1.0],
    );
    let probe = Rect::new([-5.0, -5.0], [5.0, 5.0]);
    let p = bounded_halfplanes(&a, &b, &probe).expect("bounded");
    assert_same_polygon(&p, &[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]);
}

#[test]
fn clip_polygon_against_one_side() {
    // The square [0,2]² against y ≤ 1 gives [0,2] × [0,1].
    let sq = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
    let p = clip_polygon_halfplane(&sq, [0.0, 1.0], 1.0);
    assert_same_polygon(&p, &[[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]);
    // clip_to_rect of a square that straddles the unit box.
    let big = [[-1.0, 0.5], [0.5, -1.0], [2.0, 0.5], [0.5, 2.0]];
    let q = clip_to_rect(&big, &UNIT);
    assert!(
        (polygon_area(&q) - 1.0).abs() < 1e-12,
        "the diamond covers the unit box: {q:?}"
    );
}

#[test]
fn ellipse_points_lie_on_the_ellipse() {
    // M = R(30°)·diag(2, 0.5): points satisfy ‖M⁻¹(p − c)‖ = 1.
    let (s, c) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
    let M = [[2.0 * c, -0.5 * s], [2.0 * s, 0.5 * c]];
    let e = Ellipse2 {
        center: [1.0, -2.0],
        M,
    };
    let det = M[0][0] * M[1][1] - M[0][1] * M[1][0];
    for p in ellipse_points(&e, 40) {
        let d = [p[0] - 1.0, p[1] + 2.0];
        let w = [
            (M[1][1] * d[0] - M[0][1] * d[1]) / det,
            (-M[1][0] * d[0] + M[0][0] * d[1]) / det,
        ];
        assert!((w[0].hypot(w[1]) - 1.0).abs() < 1e-12);
    }
    // Its bounding box: half-widths are the row norms of M.
    let r = ellipse_rect(&e);
    let rx = (4.0 * c * c + 0.25 * s * s).sqrt();
    assert!((r.hi[0] - 1.0 - rx).abs() < 1e-12 && (1.0 - r.lo[0] - rx).abs() < 1e-12);
    // And the sampled outline never leaves it.
    for p in ellipse_points(&e, 360) {
        assert!(
            p[0] >= r.lo[0] - 1e-12
                && p[0] <= r.hi[0] + 1e-12
                && p[1] >= r.lo[1] - 1e-12
                && p[1] <= r.hi[1] + 1e-12
        );
    }
}

#[test]
fn equal_aspect_grows_the_short_side_only() {
    let r = Rect::new([0.0, 0.0], [4.0, 1.0]).with_aspect(400.0, 200.0);
    // 4 units over 400 px: 0.01 per px; 200 px then span 2 units, centred at y = 0.5.
    assert_eq!(r, Rect::new([0.0, -0.5], [4.0, 1.5]));
    let padded = Rect::new([1.0, 1.0], [1.0, 1.0]).padded(0.1);
    assert!(
        padded.width() > 0.0 && padded.height() > 0.0,
        "a point opens up to a window"
    );
}

fn inside_all(p: [f64; 2], a: &[[f64; 2]], b: &[f64], r: &Rect, slack: f64) -> bool {
    a.iter()
        .zip(b)
        .all(|(ai, bi)| ai[0] * p[0] + ai[1] * p[1] <= bi + slack)
        && p[0] >= r.lo[0] - slack
        && p[0] <= r.hi[0] + slack
        && p[1] >= r.lo[1] - slack
        && p[1] <= r.hi[1] + slack
}

/// Inside a convex counter-clockwise polygon (distance-to-edge sign, with a margin).
fn inside_polygon(p: [f64; 2], poly: &[[f64; 2]], margin: f64) -> bool {
    (0..poly.len()).all(|i| {
        let (u, v) = (poly[i], poly[(i + 1) % poly.len()]);
        let e = [v[0] - u[0], v[1] - u[1]];
        let cross = e[0] * (p[1] - u[1]) - e[1] * (p[0] - u[0]);
        cross >= margin * e[0].hypot(e[1])
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..ProptestConfig::default() })]

    /// Against brute force: every grid point clearly inside the constraints is inside the polygon and
    /// every grid point clearly outside is outside; every vertex satisfies all constraints.
    #[test]
    fn clipping_matches_point_membership(
        planes in proptest::collection::vec(((-1.0f64..1.0, -1.0f64..1.0), -1.0f64..1.5), 1..5),
    ) {
        let a: Vec<[f64; 2]> = planes.iter().map(|((x, y), _)| [*x, *y]).collect();
        let b: Vec<f64> = planes.iter().map(|(_, b)| *b).collect();
        let r = Rect::new([-1.0, -0.5], [1.5, 1.0]);
        let poly = clip_halfplanes(&a, &b, &r);
        for &v in &poly {
            prop_assert!(inside_all(v, &a, &b, &r, 1e-9), "vertex {v:?} violates a constraint");
        }
        if !poly.is_empty() {
            prop_assert!(polygon_area(&poly) > 0.0, "counter-clockwise with interior");
        }
        let m = 1e-6;
        for i in 0..=40 {
            for j in 0..=40 {
                let p = [r.lo[0] + r.width() * i as f64 / 40.0, r.lo[1] + r.height() * j as f64 / 40.0];
                let norm = |ai: &[f64; 2]| ai[0].hypot(ai[1]);
                let deep_in = a.iter().zip(&b).all(|(ai, bi)| ai[0] * p[0] + ai[1] * p[1] <= bi - m * norm(ai))
                    && p[0] > r.lo[0] + m && p[0] < r.hi[0] - m && p[1] > r.lo[1] + m && p[1] < r.hi[1] - m;
                let clearly_out = a.iter().zip(&b).any(|(ai, bi)| ai[0] * p[0] + ai[1] * p[1] > bi + m * norm(ai));
                if deep_in {
                    prop_assert!(!poly.is_empty() && inside_polygon(p, &poly, 0.0), "{p:?} should be inside {poly:?}");
                }
                if clearly_out && !poly.is_empty() {
                    prop_assert!(!inside_polygon(p, &poly, 0.0), "{p:?} should be outside {poly:?}");
                }
            }
        }
    }
}
