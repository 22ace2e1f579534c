//! `report.html` from a small synthetic run (2-D, two trajectories, an ellipse Goal, a half-plane
//! Unsafe, a box Init): sections, table rows, one `<svg` per plot, the verdict, escaping, formatting;
//! and an example report written to `target/tmp/report-example/report.html` for looking at.

use host_compiler::cover::CoverageEstimate;
use host_compiler::report::data::{Ellipse2, ReportData, Shape2, TrajectoryReport, VerifySummary};
use host_compiler::report::format::{count, escape, num, pct, sig};
use host_compiler::report::plots::{
    init_plane_svg, input_measure, input_svg, tube_indices, workspace_svg,
};
use host_compiler::report::{render_html, verdict, write_report};

/// A trajectory from `x0` bending towards (4, 3), with a tube that shrinks from `r0` to `r0 / 4`.
fn trajectory(id: usize, source: &str, x0: [f64; 2], r0: f64, steps: usize) -> TrajectoryReport {
    let period = 0.1;
    let goal = [4.0, 3.0];
    let mut times = Vec::new();
    let mut path = Vec::new();
    let mut tube = Vec::new();
    let mut u = Vec::new();
    let mut u_nominal = Vec::new();
    let mut u_worst = Vec::new();
    for k in 0..=steps {
        let s = k as f64 / steps as f64;
        let w = 1.0 - (1.0 - s).powi(2);
        // A bend: first along x, then up.
        let p = [
            x0[0] + (goal[0] - x0[0]) * w.sqrt(),
            x0[1] + (goal[1] - x0[1]) * w * w,
        ];
        let r = r0 * (1.0 - 0.75 * s);
        let th = 0.6 * s;
        times.push(k as f64 * period);
        path.push(p);
        tube.push(Ellipse2 {
            center: p,
            M: [
                [r * th.cos(), -0.5 * r * th.sin()],
                [r * th.sin(), 0.5 * r * th.cos()],
            ],
        });
        if k < steps {
            let mag = 0.8 * (1.0 - s) + 0.05;
            u.push(vec![mag * (3.0 * s).cos(), mag * (3.0 * s).sin()]);
            u_nominal.push(mag); // ‖ũ − u_c‖₂ with u_c = 0
            u_worst.push(mag + 0.15 * (1.0 - s));
        }
    }
    TrajectoryReport {
        id,
        source: source.into(),
        route: None,
        x0: vec![x0[0], x0[1], 0.0, 0.0],
        delta: r0 * 0.98,
        delta_goal: r0 * 1.3,
        delta_unsafe: r0,
        delta_input: r0 * 2.0,
        t_star: 0.9 * steps as f64 * period,
        times,
        path,
        tube,
        u,
        u_nominal,
        u_worst,
    }
}

fn sample() -> ReportData {
    let mut trajectories = vec![
        // Deliberately out of id order: the table must sort.
        trajectory(7, "csv:examples/vehicle.csv", [0.8, 0.9], 0.35, 60),
        trajectory(2, "generated", [0.2, 0.2], 0.3, 50),
    ];
    trajectories[1].delta_goal = 0.25; // trajectory 2 is Goal-limited
    ReportData {
        title: "Planar vehicle (Example 4.8)".into(),
        spec_path: "examples/vehicle.toml".into(),
        n: 4,
        m: 2,
        period: 0.1,
        horizon: 6.0,
        plane_labels: ["x1 (m)".into(), "x2 (m)".into()],
        init_plane: Some(Shape2::Box {
            lo: [0.0, 0.0],
            hi: [1.0, 1.0],
        }),
        goal_plane: vec![Shape2::Ellipse(Ellipse2 {
            center: [4.0, 3.0],
            M: [[0.9, 0.0], [0.0, 0.6]],
        })],
        // x2 ≤ −0.25 (unbounded) and the triangle (3.4, 0.2), (3.4, 0.8), (4, 0.8).
        unsafe_plane: vec![
            Shape2::HalfPlanes {
                a: vec![[0.0, 1.0]],
                b: vec![-0.25],
            },
            Shape2::HalfPlanes {
                a: vec![[-1.0, 0.0], [0.0, 1.0], [1.0, -1.0]],
                b: vec![-3.4, 0.8, 3.2],
            },
        ],
        trajectories,
        routes: vec![],
        init_labels: ["x1 (m)".into(), "x2 (m)".into()],
        init_box: Shape2::Box {
            lo: [0.0, 0.0],
            hi: [1.0, 1.0],
        },
        balls: vec![
            Ellipse2 {
                center: [0.2, 0.2],
                M: [[0.3, 0.0], [0.0, 0.3]],
            },
            Ellipse2 {
                center: [0.8, 0.9],
                M: [[0.35, 0.05], [0.05, 0.3]],
            },
            Ellipse2 {
                center: [0.7, 0.3],
                M: [[0.3, 0.0], [0.0, 0.25]],
            },
        ],
        uncovered: vec![[0.02, 0.97], [0.05, 0.6]],
        coverage: CoverageEstimate {
            samples: 10_000,
            covered: 9_998,
            mean: 0.9998,
            confidence: 0.95,
            lower: 0.992,
            upper: 1.0,
        },
        coverage_target: 0.99,
        stop_reason: "Init covered at the requested confidence".into(),
        input_bound_label: "‖u − u_c‖₂ ≤ 1".into(),
        input_bound: 1.0,
        K: vec![vec![-1.2, 0.0, -0.8, 0.0], vec![0.0, -1.2, 0.0, -0.8]],
        P: vec![
            vec![2.1, 0.0, 0.4, 0.0],
            vec![0.0, 2.1, 0.0, 0.4],
            vec![0.4, 0.0, 0.9, 0.0],
            vec![0.0, 0.4, 0.0, 0.9],
        ],
        sigma_min: 0.0421,
        eps_f32: 3.2e-7,
        r_crit: 0.0123,
        image_bytes: 12_345,
        image_path: "target/vehicle.img".into(),
        verify: Some(VerifySummary {
            runs: 10_000,
            violations: 0,
            worst_goal_margin: 0.031,
            worst_unsafe_margin: 0.12,
            worst_input_margin: 0.004,
            after_goal_input_excursions: 3,
            after_goal_unsafe: 0,
            after_goal_judged: false,
            attack: Some((600, 0.0123, 0)),
        }),
        optimization: None,
        timings: vec![
            ("caf".into(), 0.042),
            ("trajectories".into(), 3.5),
            ("coverage".into(), 1.25),
            ("verify".into(), 8.0),
        ],
        warnings: vec!["δ of trajectory 7 shrank by 2 % for the f32 margin".into()],
        pwa: None,
        terminal: None,
    }
}

/// The text between `<table id="{id}"` and the next `</table>`.
fn table<'a>(html: &'a str, id: &str) -> &'a str {
    let start = html
        .find(&format!("<table id=\"{id}\""))
        .unwrap_or_else(|| panic!("no table {id}"));
    let end = start + html[start..].find("</table>").expect("closed table");
    &html[start..end]
}

fn body_rows(table: &str) -> usize {
    let body = &table[table.find("<tbody>").expect("tbody")..];
    let body = &body[..body.find("</tbody>").expect("closed tbody")];
    body.matches("<tr>").count()
}

#[test]
fn page_has_every_section_and_one_svg_per_plot() {
    let html = render_html(&sample());
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.contains("<meta charset=\"utf-8\">"));
    for id in [
        "verdict",
        "warnings",
        "workspace",
        "init-plane",
        "inputs",
        "trajectories",
        "delta-table",
        "coverage-table",
        "certificate",
        "image",
        "verification",
        "timings",
    ] {
        assert!(
            html.contains(&format!("id=\"{id}\"")),
            "missing section {id}"
        );
    }
    assert_eq!(
        html.matches("<svg").count(),
        3,
        "workspace, Init plane, inputs"
    );
    assert_eq!(html.matches("</svg>").count(), 3);
    // Self-contained: no scripts, no linked assets.
    assert!(!html.contains("<script"));
    assert!(!html.contains("<link"));
    assert!(!html.contains(" src="));
    assert!(!html.contains("href="));
    // Header facts.
    assert!(html.contains("examples/vehicle.toml"));
    assert!(html.contains("n = 4, m = 2"));
    assert!(html.contains("0.1 s") && html.contains("6 s"));
    assert!(html.contains("covered at the requested confidence"));
    assert!(html.contains(
        "<tr><th>Coverage target</th><td>99 % of Init at 95 % confidence (judged on the lower bound, 99.2 %)</td></tr>"
    ));
}

#[test]
fn delta_table_has_one_row_per_trajectory_sorted_by_id() {
    let data = sample();
    let html = render_html(&data);
    let t = table(&html, "delta-table");
    assert_eq!(body_rows(t), 2);
    assert_eq!(
        t.matches("<th>").count(),
        8,
        "id, source, x0, δ, δ_Goal, δ_Unsafe, δ_Input, t*"
    );
    let (i2, i7) = (
        t.find("generated").unwrap(),
        t.find("csv:examples/vehicle.csv").unwrap(),
    );
    assert!(i2 < i7, "id 2 before id 7");
    // Values: δ = 0.98·0.3, x0, t* = 0.9·50·0.1; the binding part of trajectory 2 is δ_Goal = 0.25.
    assert!(t.contains(">0.294<") && t.contains("[0.2, 0.2, 0, 0]") && t.contains(">4.5<"));
    assert!(t.contains("<td class=\"n binding\">0.25</td>"));
    // Coverage, matrices, timings.
    let c = table(&html, "coverage-table");
    assert_eq!(body_rows(c), 1);
    assert_eq!(c.matches("<th>").count(), 8);
    assert!(c.contains("<th>lower bound</th><th>target</th>"));
    assert!(c.contains("10\u{202F}000") && c.contains("9998") && c.contains(">95 %<"));
    // The lower bound (met: not marked) next to the target.
    assert!(c.contains("<td class=\"n\">99.2 %</td><td class=\"n\">99 %</td>"));
    assert_eq!(table(&html, "K").matches("<tr>").count(), 2);
    assert_eq!(table(&html, "P").matches("<tr>").count(), 4);
    assert_eq!(table(&html, "K").matches("<td>").count(), 8);
    assert_eq!(body_rows(table(&html, "timings-table")), 4);
    assert!(html.contains("3.2e-7"), "ε_f32 in scientific notation");
    assert!(html.contains("12\u{202F}345 B"));
}

#[test]
fn verdict_is_green_only_when_the_lower_bound_meets_the_target_and_verification_has_no_violations()
{
    let data = sample();
    let v = verdict(&data);
    assert!(v.ok && v.coverage_ok && v.verification_ok, "{}", v.text);
    assert!(v.text.starts_with('✔'));
    assert!(
        v.text
            .contains("≥ 99.2 % at 95 % confidence, which meets the target 99 %")
            && v.text.contains("10\u{202F}000 runs, 0 violations"),
        "{}",
        v.text
    );
    assert!(render_html(&data).contains("class=\"verdict ok\""));

    // The falsifier's row is shown; a violation it found turns the verdict red.
    assert!(render_html(&data).contains("600 runs (Nelder–Mead over each ball)"));
    let mut caught = data.clone();
    if let Some(v) = caught.verify.as_mut() {
        v.attack = Some((600, -0.02, 3));
    }
    let v = verdict(&caught);
    assert!(!v.ok && !v.verification_ok, "{}", v.text);
    assert!(v.text.contains("the falsifier found 3"), "{}", v.text);

    // Lower bound exactly at the target: met.
    let mut at = data.clone();
    at.coverage_target = at.coverage.lower;
    assert!(verdict(&at).ok);

    // Lower bound below the target (even though the estimate is above it): red, and the cell is marked.
    let mut short = data.clone();
    short.coverage_target = 0.995;
    assert!(short.coverage.mean > short.coverage_target);
    let v = verdict(&short);
    assert!(!v.ok && !v.coverage_ok && v.verification_ok);
    assert!(v.text.starts_with('✘'));
    assert!(
        v.text
            .contains("99.2 % at 95 % confidence, which is below the target 99.5 %"),
        "{}",
        v.text
    );
    let html = render_html(&short);
    assert!(html.contains("class=\"verdict fail\""));
    assert!(table(&html, "coverage-table")
        .contains("<td class=\"n bad\">99.2 %</td><td class=\"n\">99.5 %</td>"));
    let mut nan = data.clone();
    nan.coverage_target = f64::NAN;
    assert!(!verdict(&nan).coverage_ok, "an unknown target is not met");

    // One violation is red even with the coverage met.
    let mut bad = data.clone();
    bad.verify.as_mut().unwrap().violations = 1;
    let v = verdict(&bad);
    assert!(!v.ok && v.coverage_ok && !v.verification_ok);
    assert!(v.text.contains("1 violation") && !v.text.contains("1 violations"));
    let html = render_html(&bad);
    assert!(html.contains("class=\"verdict fail\""));
    assert!(html.contains("<span class=\"bad\">1</span>"));

    // No verification at all, or none that ran, is red.
    let mut none = data.clone();
    none.verify = None;
    let v = verdict(&none);
    assert!(!v.ok && !v.verification_ok && v.text.contains("verification not run"));
    assert!(render_html(&none).contains("Verification was not run."));
    let mut zero = data.clone();
    zero.verify.as_mut().unwrap().runs = 0;
    assert!(!verdict(&zero).ok);

    // The numbers decide, not the wording of the stop reason (which is still shown).
    let mut worded = data;
    worded.stop_reason = "trajectory budget (40) ran out before Init was covered".into();
    assert!(verdict(&worded).ok);
    assert!(render_html(&worded).contains("trajectory budget (40) ran out"));
}

#[test]
fn warnings_are_listed_in_the_header() {
    let html = render_html(&sample());
    let w = html.find("id=\"warnings\"").unwrap();
    assert!(
        w < html.find("id=\"workspace\"").unwrap(),
        "warnings before the plots"
    );
    assert!(html[w..].contains("<li>δ of trajectory 7 shrank by 2 % for the f32 margin</li>"));
    let mut quiet = sample();
    quiet.warnings.clear();
    assert!(!render_html(&quiet).contains("id=\"warnings\""));
}

#[test]
fn all_text_is_escaped() {
    let mut d = sample();
    d.title = "Vehicle <b>bold</b> & \"quoted\"".into();
    d.spec_path = "a<b>.toml".into();
    d.trajectories[0].source = "csv:<script>alert(1)</script>.csv".into();
    d.warnings = vec!["x < 1 & y > 2".into()];
    d.plane_labels = ["p<1>".into(), "q&r".into()];
    d.timings.push(("<phase>".into(), 1.0));
    let html = render_html(&d);
    assert!(!html.contains("<b>bold</b>") && !html.contains("<script>") && !html.contains("a<b>"));
    assert!(html.contains("Vehicle &lt;b&gt;bold&lt;/b&gt; &amp; &quot;quoted&quot;"));
    assert!(html.contains("csv:&lt;script&gt;alert(1)&lt;/script&gt;.csv"));
    assert!(html.contains("<li>x &lt; 1 &amp; y &gt; 2</li>"));
    assert!(html.contains("&lt;phase&gt;"));
    // Axis labels inside the SVG are escaped too.
    assert!(!html.contains("p<1>") && html.contains("p&lt;1&gt;") && html.contains("q&amp;r"));
    assert_eq!(escape("'&'"), "&#39;&amp;&#39;");
}

#[test]
fn plots_draw_the_sets_and_markers() {
    let d = sample();
    let ws = workspace_svg(&d);
    assert!(ws.starts_with("<svg"));
    // Goal and Unsafe fills in their colours; the axis labels.
    assert!(ws.to_lowercase().contains("#2ea043"), "Goal green");
    assert!(ws.to_lowercase().contains("#cf222e"), "Unsafe red");
    assert!(ws.contains("x1 (m)") && ws.contains("x2 (m)"));
    // One start marker per trajectory (filled circle plus its black ring).
    assert_eq!(ws.matches("<circle").count(), 4);
    let ip = init_plane_svg(&d);
    assert!(ip.starts_with("<svg"));
    // Two uncovered samples, each a cross of two lines.
    assert!(ip.matches("<line").count() >= 4);
    let inp = input_svg(&d);
    assert!(inp.starts_with("<svg") && inp.contains("t (s)"));
    // Degenerate data still gives plots, not panics.
    let mut empty = d.clone();
    empty.trajectories.clear();
    empty.balls.clear();
    empty.uncovered.clear();
    empty.goal_plane.clear();
    empty.init_plane = None;
    empty.input_bound = f64::INFINITY;
    let html = render_html(&empty);
    assert_eq!(html.matches("<svg").count(), 3);
    assert_eq!(body_rows(table(&html, "delta-table")), 0);
}

#[test]
fn tube_sampling_keeps_first_last_and_t_star() {
    assert_eq!(tube_indices(0, None, 24), Vec::<usize>::new());
    assert_eq!(tube_indices(5, Some(3), 24), vec![0, 1, 2, 3, 4]);
    let idx = tube_indices(100, Some(57), 10);
    assert_eq!(idx, vec![0, 10, 20, 30, 40, 50, 57, 60, 70, 80, 90, 99]);
}

#[test]
fn input_axis_is_named_after_the_bound_label() {
    assert_eq!(input_measure("‖u − u_c‖₂ ≤ 1"), "‖u − u_c‖₂");
    assert_eq!(input_measure("max_i |u_i| (box bound)"), "max_i |u_i|");
    assert_eq!(input_measure("‖u‖∞ <= 2"), "‖u‖∞");
    assert_eq!(input_measure(""), "input magnitude");
    let d = sample();
    let inp = input_svg(&d);
    assert!(
        inp.contains("‖u − u_c‖₂  (bound 1)"),
        "y axis: measure and bound"
    );
    let html = render_html(&d);
    assert!(html.contains("‖u − u_c‖₂ of each nominal input"));
    assert!(html.contains("against the bound ‖u − u_c‖₂ ≤ 1."));
}

#[test]
fn input_plot_draws_the_measured_nominal_input_not_raw_u() {
    let d = sample();
    let base = input_svg(&d);
    // Raw ũ is not what is plotted: changing it leaves the plot unchanged.
    let mut raw = d.clone();
    for t in &mut raw.trajectories {
        for u in &mut t.u {
            u.iter_mut().for_each(|x| *x = 50.0 + *x);
        }
    }
    assert_eq!(input_svg(&raw), base);
    // u_nominal is: raising it above the bound changes the plot and stretches the axis.
    let mut high = d.clone();
    for t in &mut high.trajectories {
        t.u_nominal.iter_mut().for_each(|x| *x += 2.0);
    }
    let high_svg = input_svg(&high);
    assert_ne!(high_svg, base);
    let tick = |svg: &str, v: &str| {
        svg.contains(&format!(">{v}</text>")) || svg.contains(&format!(">\n{v}\n</text>"))
    };
    assert!(
        tick(&high_svg, "2.5") && !tick(&base, "2.5"),
        "y axis reaches the raised nominal input"
    );
}

#[test]
fn numbers_have_four_significant_digits() {
    assert_eq!(num(0.0), "0");
    assert_eq!(num(123.456), "123.5");
    assert_eq!(num(0.5), "0.5");
    assert_eq!(num(-2.0), "-2");
    assert_eq!(num(0.012345678), "0.01235");
    assert_eq!(num(1.2346e-5), "1.235e-5");
    assert_eq!(num(3.0e-7), "3e-7");
    assert_eq!(num(12_345_678.0), "1.235e7");
    assert_eq!(num(9.99996), "10");
    assert_eq!(num(99_999.0), "99999");
    assert_eq!(num(f64::INFINITY), "∞");
    assert_eq!(num(f64::NAN), "NaN");
    assert_eq!(sig(std::f64::consts::PI, 3), "3.14");
    assert_eq!(pct(0.992), "99.2 %");
    assert_eq!(pct(0.99996), "99.996 %", "no rounding up to 100 %");
    assert_eq!(pct(1.0), "100 %");
    assert_eq!(count(999), "999");
    assert_eq!(count(1_234_567), "1\u{202F}234\u{202F}567");
}

#[test]
fn large_runs_stay_small_and_readable() {
    let mut d = sample();
    d.trajectories = (0..300)
        .map(|i| trajectory(i, "generated", [0.003 * i as f64, 0.5], 0.05, 100))
        .collect();
    d.balls = (0..3000)
        .map(|i| Ellipse2 {
            center: [(i % 60) as f64 / 60.0, (i / 60) as f64 / 50.0],
            M: [[0.02, 0.0], [0.0, 0.02]],
        })
        .collect();
    let html = render_html(&d);
    assert!(html.len() < 4_000_000, "page is {} bytes", html.len());
    assert!(html.contains("worst case, max over all tubes"));
    assert_eq!(body_rows(table(&html, "delta-table")), 300);
    assert!(
        html.contains("… and 288 more"),
        "the legend names 12 trajectories"
    );
    assert!(html.contains("at most 2 per trajectory"));
    write_report(
        &d,
        &std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("report-large"),
    )
    .unwrap();
}

/// Writes the sample report to `target/tmp/report-example/report.html`, for a person to look at.
#[test]
fn writes_example_report() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("report-example");
    let path = write_report(&sample(), &dir).unwrap();
    assert_eq!(path, dir.join("report.html"));
    let written = std::fs::read_to_string(&path).unwrap();
    assert_eq!(written, render_html(&sample()));
    println!("report written to {}", path.display());
}

/// The optimisation section: summary with the median gain, one δ-history plot, the before/after tube
/// plot, one frame per round (at most six), the run table, and the seed request when it is the stop reason.
#[test]
fn optimization_section_shows_history_tubes_frames_and_seed_request() {
    use host_compiler::report::optimization::{
        CoverageFrame, OptRun, OptimizationReport, SeedRequest, TubeComparison,
    };
    let mut d = sample();
    assert!(
        !render_html(&d).contains("id=\"optimization\""),
        "no data, no section"
    );
    let run = |origin: Option<usize>, accepted: Option<usize>, before: f64, after: f64| OptRun {
        round: 1,
        origin,
        accepted,
        delta_before: before,
        delta_after: after,
        history: vec![before, 0.5 * (before + after), after],
        iterations: 2,
        stop: "Converged".into(),
    };
    let t = &d.trajectories[1];
    let shrink = |e: &Ellipse2| Ellipse2 {
        center: e.center,
        M: [
            [0.5 * e.M[0][0], 0.5 * e.M[0][1]],
            [0.5 * e.M[1][0], 0.5 * e.M[1][1]],
        ],
    };
    d.optimization = Some(OptimizationReport {
        generator: "algorithm4".into(),
        runs: vec![
            run(None, Some(0), 0.1, 0.12),
            run(Some(0), Some(1), 0.05, 0.15),
            run(Some(0), None, 0.02, 0.03),
            run(Some(1), Some(2), 0.04, 0.1),
            // Started uncertified (δ 0): repaired, no finite ratio, left out of the median.
            run(Some(1), None, 0.0, 0.08),
        ],
        showcase: Some(TubeComparison {
            trajectory: 1,
            delta_before: 0.05,
            delta_after: 0.15,
            before_path: t.path.clone(),
            before_tube: t.tube.iter().map(shrink).collect(),
            after_path: t.path.clone(),
            after_tube: t.tube.clone(),
        }),
        frames: (1..=9)
            .map(|r| CoverageFrame {
                round: r,
                trajectories: r.min(3),
                uncovered: vec![[0.02, 0.97]; 10 - r],
                samples: 100,
            })
            .collect(),
        needs_seed: Some(SeedRequest {
            description: "2 uncovered samples in x1 ∈ [0.02, 0.05]".into(),
            region: Shape2::Box {
                lo: [0.02, 0.6],
                hi: [0.05, 0.97],
            },
            clusters: vec![],
        }),
    });
    let o = d.optimization.as_ref().unwrap();
    // Gains of the Algorithm 4 seeds: 3, 1.5, 2.5 and ∞ (from δ 0) → median of the finite ones 2.5.
    assert_eq!(o.median_gain(), Some(2.5));
    let html = render_html(&d);
    for id in [
        "optimization",
        "delta-history",
        "tube-before-after",
        "needs-seed",
        "frame-1",
        "frame-9",
    ] {
        assert!(html.contains(&format!("id=\"{id}\"")), "missing {id}");
    }
    assert_eq!(
        html.matches("class=\"frame\"").count(),
        6,
        "six of nine rounds drawn"
    );
    // 3 main plots + δ history + before/after + 6 frames.
    assert_eq!(html.matches("<svg").count(), 11);
    assert_eq!(body_rows(table(&html, "optimization-table")), 5);
    assert!(html.contains("4 (1 started uncertified)"));
    assert!(
        html.contains(
            "<tr><th>Median δ after ÷ δ before (seeds that started certified)</th><td>2.5</td></tr>"
        ),
        "{}",
        &html[html.find("id=\"optimization\"").unwrap()..][..1500]
    );
    assert!(
        html.contains("needs a new seed trajectory")
            || html.contains("Needs a new seed trajectory")
    );
    assert!(html.contains("x1 ∈ [0.02, 0.05]"));
    assert!(html.contains("not accepted"));
    write_report(
        &d,
        &std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("report-optimization"),
    )
    .unwrap();
}

#[test]
fn verification_shows_what_the_terminal_law_did_after_goal() {
    let html = render_html(&sample());
    assert!(
        html.contains("3 runs left the input set, 0 entered Unsafe after Goal"),
        "the after-Goal counts are missing from the verification section"
    );
    assert!(html.contains("first sample in Goal"));
}
