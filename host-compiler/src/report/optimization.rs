//! The report's optimisation section: how the cover grew under Algorithm 4 (§5.4) with §5.3's
//! maximisation of δ. Owns its plot-ready data ([`OptimizationReport`]) and its HTML and SVG: δ per
//! iteration of every optimisation, one trajectory with its tube before and after, the coverage map
//! after each growth round, and, when Algorithm 4 stopped there, where a new seed trajectory is needed.

use std::fmt::Write as _;

use plotters::prelude::*;
use serde::Serialize;

use super::data::{Ellipse2, ReportData, Shape2};
use super::format::{count, escape, num, pct};
use super::planar::{clip_to_rect, ellipse_points, ellipse_rect, shape_polygon, shape_rect, Rect};
use super::plots::{
    closed, css_color, draw_region, equal_aspect_chart, finite2, plane_height, svg_or_note, tick,
    workspace_view, DynResult, BALL_COLOR, GOAL_COLOR, INIT_COLOR, PLANE_WIDTH, UNSAFE_COLOR,
};

/// One §5.3 optimisation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OptRun {
    /// Growth round.
    pub round: usize,
    /// The trajectory whose ball boundary it starts on (Algorithm 4), `None` for a seed of the SCP generator.
    pub origin: Option<usize>,
    /// Trajectory id when accepted into the cover.
    pub accepted: Option<usize>,
    /// Certified δ of the start and of the result (both as shipped: f32 v, f32 gain, sampled time).
    pub delta_before: f64,
    pub delta_after: f64,
    /// Certified δ per iteration ([0] = start).
    pub history: Vec<f64>,
    pub iterations: usize,
    /// Why the optimiser stopped.
    pub stop: String,
}

/// One trajectory before and after §5.3, in the workspace plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TubeComparison {
    pub trajectory: usize,
    pub delta_before: f64,
    pub delta_after: f64,
    pub before_path: Vec<[f64; 2]>,
    pub before_tube: Vec<Ellipse2>,
    pub after_path: Vec<[f64; 2]>,
    pub after_tube: Vec<Ellipse2>,
}

/// The cover after one growth round, in the Init plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CoverageFrame {
    pub round: usize,
    /// The first `trajectories` balls of [`ReportData::balls`].
    pub trajectories: usize,
    /// Working samples still uncovered.
    pub uncovered: Vec<[f64; 2]>,
    /// Working samples in all.
    pub samples: usize,
}

/// Algorithm 4's second stopping rule: where the samples lie that local variation does not reach.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SeedRequest {
    /// Plain-text description (bounding box and clusters).
    pub description: String,
    /// Bounding box and cluster boxes in the Init plane.
    pub region: Shape2,
    pub clusters: Vec<Shape2>,
}

/// Everything the optimisation section shows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OptimizationReport {
    /// "algorithm4" or "scp".
    pub generator: String,
    pub runs: Vec<OptRun>,
    pub showcase: Option<TubeComparison>,
    pub frames: Vec<CoverageFrame>,
    pub needs_seed: Option<SeedRequest>,
}

impl OptimizationReport {
    /// δ after ÷ δ before of the Algorithm 4 seeds (∞ where the start was not certified).
    pub fn gains(&self) -> Vec<f64> {
        self.runs
            .iter()
            .filter(|r| r.origin.is_some())
            .map(|r| {
                if r.delta_before > 0.0 {
                    r.delta_after / r.delta_before
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }

    /// Median of the finite [`Self::gains`] (the seeds that started certified); `None` when there are none.
    pub fn median_gain(&self) -> Option<f64> {
        let mut g: Vec<f64> = self.gains().into_iter().filter(|g| g.is_finite()).collect();
        if g.is_empty() {
            return None;
        }
        g.sort_by(|a, b| a.total_cmp(b));
        Some(g[g.len() / 2])
    }
}

/// Most coverage frames drawn (evenly spread over the rounds, the last always included).
pub const MAX_FRAMES: usize = 6;
/// Most δ-per-iteration lines drawn.
const MAX_HISTORIES: usize = 60;

const BEFORE_COLOR: RGBColor = RGBColor(255, 127, 14);
const AFTER_COLOR: RGBColor = RGBColor(31, 119, 180);
const REJECTED_COLOR: RGBColor = RGBColor(170, 170, 170);

/// The frames drawn: at most [`MAX_FRAMES`], evenly spread, first and last included.
pub fn frame_indices(len: usize) -> Vec<usize> {
    if len <= MAX_FRAMES {
        return (0..len).collect();
    }
    let mut v: Vec<usize> = (0..MAX_FRAMES)
        .map(|i| i * (len - 1) / (MAX_FRAMES - 1))
        .collect();
    v.dedup();
    v
}

/// The section (empty when the run has no optimisation data).
pub fn section(h: &mut String, data: &ReportData) {
    let Some(o) = &data.optimization else {
        return;
    };
    h.push_str("<section id=\"optimization\">\n<h2>Cover growth and δ optimisation</h2>\n");
    let accepted = o.runs.iter().filter(|r| r.accepted.is_some()).count();
    let gains = o.gains();
    let finite: Vec<f64> = gains.iter().copied().filter(|g| g.is_finite()).collect();
    let gen = match o.generator.as_str() {
        "algorithm4" => "Algorithm 4 (§5.4): each new trajectory starts where the nearest uncovered sample projects onto the boundary of the closest certified ball, follows that ball's feedback law, and has its certified δ maximised (§5.3) and re-certified as shipped",
        _ => "Algorithm 1 with the SCP generator per uncovered seed (no §5.3 optimisation)",
    };
    let _ = writeln!(h, "<p>Generator: {}.</p>", escape(gen));
    let median = o
        .median_gain()
        .map(num)
        .unwrap_or_else(|| "— (no seed started certified, so no ratio is finite)".into());
    super::html::kv(
        h,
        &[
            ("Optimisations (§5.3)", count(o.runs.len())),
            ("Accepted into the cover", count(accepted)),
            (
                "Algorithm 4 seeds",
                format!(
                    "{} ({} started uncertified)",
                    count(gains.len()),
                    count(gains.len() - finite.len())
                ),
            ),
            (
                "Median δ after ÷ δ before (seeds that started certified)",
                median,
            ),
            ("Growth rounds", count(o.frames.len())),
        ],
    );
    if let Some(s) = &o.needs_seed {
        let _ = writeln!(
            h,
            "<div id=\"needs-seed\" class=\"warnings\"><h2>Needs a new seed trajectory</h2><p>No uncovered \
             sample is reachable by local variation of the cover (every projection failed the δε floor or \
             covered nothing new, and a new SCP seed did not help). {}</p></div>",
            escape(&s.description)
        );
    }

    h.push_str("<div class=\"plots\">\n<figure id=\"delta-history\">\n<h3>Certified δ per iteration</h3>\n");
    h.push_str(&svg_or_note(draw_history(o)));
    let _ = writeln!(
        h,
        "<figcaption><div class=\"legend\"><span><span class=\"ln\" style=\"border-top-color:{}\"></span>accepted</span>\
         <span><span class=\"ln\" style=\"border-top-color:{}\"></span>not accepted</span></div>The certified δ of \
         each optimisation's iterates ([0] = the start){}.</figcaption>\n</figure>",
        css_color(AFTER_COLOR),
        css_color(REJECTED_COLOR),
        if o.runs.len() > MAX_HISTORIES {
            format!(", the first {MAX_HISTORIES} of {} runs", o.runs.len())
        } else {
            String::new()
        }
    );
    if let Some(c) = &o.showcase {
        h.push_str(
            "<figure id=\"tube-before-after\">\n<h3>One trajectory before and after §5.3</h3>\n",
        );
        h.push_str(&svg_or_note(draw_comparison(data, c)));
        let _ = writeln!(
            h,
            "<figcaption><div class=\"legend\"><span><span class=\"ln\" style=\"border-top-color:{}\"></span>before, δ = {}</span>\
             <span><span class=\"ln\" style=\"border-top-color:{}\"></span>after (trajectory #{}), δ = {}</span></div>\
             Nominal paths and their robust tubes (every k-th sample) in axes {} and {}.</figcaption>\n</figure>",
            css_color(BEFORE_COLOR),
            num(c.delta_before),
            css_color(AFTER_COLOR),
            c.trajectory,
            num(c.delta_after),
            escape(&data.plane_labels[0]),
            escape(&data.plane_labels[1])
        );
    }
    h.push_str("</div>\n");

    if !o.frames.is_empty() {
        h.push_str("<h3>Coverage map as the cover grew</h3>\n<div class=\"plots frames\">\n");
        let idx = frame_indices(o.frames.len());
        for (k, &i) in idx.iter().enumerate() {
            let f = &o.frames[i];
            let last = k + 1 == idx.len();
            let _ = writeln!(h, "<figure class=\"frame\" id=\"frame-{}\">", f.round);
            h.push_str(&svg_or_note(draw_frame(
                data,
                f,
                if last { o.needs_seed.as_ref() } else { None },
            )));
            let _ = writeln!(
                h,
                "<figcaption>After round {}: {} trajectories, {} of {} working samples uncovered ({} covered).</figcaption>\n</figure>",
                f.round,
                f.trajectories,
                count(f.uncovered.len()),
                count(f.samples),
                pct(1.0 - f.uncovered.len() as f64 / f.samples.max(1) as f64)
            );
        }
        h.push_str("</div>\n");
    }

    h.push_str(
        "<table id=\"optimization-table\">\n<thead><tr><th>round</th><th>from ball</th><th>trajectory</th>\
         <th>δ before</th><th>δ after</th><th>gain</th><th>iterations</th><th>stop</th></tr></thead>\n<tbody>\n",
    );
    for r in &o.runs {
        let gain = if r.delta_before > 0.0 {
            num(r.delta_after / r.delta_before)
        } else {
            "— (repaired from δ 0)".into()
        };
        let _ = writeln!(
            h,
            "<tr><td class=\"n\">{}</td><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            r.round,
            r.origin.map_or("SCP seed".into(), |m| format!("#{m}")),
            r.accepted
                .map_or("<span class=\"note\">not accepted</span>".into(), |t| format!("#{t}")),
            num(r.delta_before),
            num(r.delta_after),
            gain,
            r.iterations,
            escape(&r.stop)
        );
    }
    h.push_str("</tbody>\n</table>\n</section>\n");
}

fn draw_history(o: &OptimizationReport) -> DynResult<String> {
    let runs: Vec<&OptRun> = o.runs.iter().take(MAX_HISTORIES).collect();
    let iters = runs
        .iter()
        .map(|r| r.history.len())
        .max()
        .unwrap_or(1)
        .max(2);
    let top = runs
        .iter()
        .flat_map(|r| r.history.iter())
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0f64, f64::max);
    let top = if top > 0.0 { top * 1.08 } else { 1.0 };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (PLANE_WIDTH, 360)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..(iters - 1) as f64, 0.0..top)?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .y_desc("certified δ")
            .y_label_formatter(&tick)
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(215, 215, 215))
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 15))
            .draw()?;
        // Rejected first, so accepted ones are drawn on top.
        for accepted in [false, true] {
            for r in runs.iter().filter(|r| r.accepted.is_some() == accepted) {
                let color = if accepted {
                    AFTER_COLOR
                } else {
                    REJECTED_COLOR
                };
                let pts: Vec<(f64, f64)> = r
                    .history
                    .iter()
                    .enumerate()
                    .filter(|(_, d)| d.is_finite())
                    .map(|(i, &d)| (i as f64, d.max(0.0)))
                    .collect();
                if pts.len() == 1 {
                    chart.draw_series(std::iter::once(Circle::new(pts[0], 3, color.filled())))?;
                } else {
                    chart.draw_series(LineSeries::new(pts, color.mix(0.8).stroke_width(2)))?;
                }
            }
        }
        root.present()?;
    }
    Ok(svg)
}

/// Tube ellipses drawn per path in the comparison.
const COMPARISON_TUBES: usize = 16;

fn draw_comparison(data: &ReportData, c: &TubeComparison) -> DynResult<String> {
    let mut view = workspace_view(data);
    for p in [&c.before_path, &c.after_path] {
        view.include_all(p);
    }
    for e in c.before_tube.iter().chain(&c.after_tube) {
        view.union(&ellipse_rect(e));
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (PLANE_WIDTH, plane_height(&view)))
            .into_drawing_area();
        root.fill(&WHITE)?;
        let (mut chart, view) = equal_aspect_chart(&root, view, &data.plane_labels)?;
        for (shapes, color, fill) in [
            (data.init_plane.iter().collect::<Vec<_>>(), INIT_COLOR, 0.18),
            (data.unsafe_plane.iter().collect(), UNSAFE_COLOR, 0.28),
            (data.goal_plane.iter().collect(), GOAL_COLOR, 0.25),
        ] {
            for s in shapes {
                draw_region(
                    &mut chart,
                    &shape_polygon(s, &view),
                    &view,
                    color,
                    fill,
                    0.9,
                )?;
            }
        }
        for (path, tube, color) in [
            (&c.before_path, &c.before_tube, BEFORE_COLOR),
            (&c.after_path, &c.after_tube, AFTER_COLOR),
        ] {
            let step = (tube.len() / COMPARISON_TUBES).max(1);
            for (i, e) in tube.iter().enumerate() {
                if i % step == 0 || i + 1 == tube.len() {
                    draw_region(&mut chart, &ellipse_points(e, 48), &view, color, 0.08, 0.5)?;
                }
            }
            let pts: Vec<(f64, f64)> = path
                .iter()
                .filter(|p| finite2(p))
                .map(|p| (p[0], p[1]))
                .collect();
            chart.draw_series(LineSeries::new(pts, color.stroke_width(2)))?;
            if let Some(p) = path.first().filter(|p| finite2(p)) {
                chart.draw_series(std::iter::once(Circle::new(
                    (p[0], p[1]),
                    4,
                    color.filled(),
                )))?;
            }
        }
        root.present()?;
    }
    Ok(svg)
}

/// Width of one coverage frame.
const FRAME_WIDTH: u32 = 380;

fn draw_frame(
    data: &ReportData,
    f: &CoverageFrame,
    seed: Option<&SeedRequest>,
) -> DynResult<String> {
    let mut view = shape_rect(&data.init_box, &Rect::new([-1e6; 2], [1e6; 2]));
    if view.is_empty() {
        for b in &data.balls {
            view.union(&ellipse_rect(b));
        }
    }
    view.include_all(&f.uncovered);
    let view = view.padded(0.08);
    let mut svg = String::new();
    {
        let height =
            (plane_height(&view) as f64 * FRAME_WIDTH as f64 / PLANE_WIDTH as f64) as u32 + 20;
        let root = SVGBackend::with_string(&mut svg, (FRAME_WIDTH, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let (mut chart, view) = equal_aspect_chart(&root, view, &data.init_labels)?;
        for b in data.balls.iter().take(f.trajectories) {
            draw_region(
                &mut chart,
                &ellipse_points(b, 40),
                &view,
                BALL_COLOR,
                0.16,
                0.5,
            )?;
        }
        let init = clip_to_rect(&shape_polygon(&data.init_box, &view), &view);
        if !init.is_empty() {
            chart.draw_series(std::iter::once(PathElement::new(
                closed(&init),
                BLACK.stroke_width(2),
            )))?;
        }
        if let Some(s) = seed {
            for r in std::iter::once(&s.region).chain(&s.clusters) {
                let poly = clip_to_rect(&shape_polygon(r, &view), &view);
                if !poly.is_empty() {
                    chart.draw_series(std::iter::once(PathElement::new(
                        closed(&poly),
                        RGBColor(249, 168, 37).stroke_width(2),
                    )))?;
                }
            }
        }
        chart.draw_series(
            f.uncovered
                .iter()
                .filter(|p| finite2(p))
                .map(|p| Cross::new((p[0], p[1]), 2, UNSAFE_COLOR.stroke_width(1))),
        )?;
        root.present()?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_spread_and_keep_first_and_last() {
        assert_eq!(frame_indices(3), vec![0, 1, 2]);
        let v = frame_indices(20);
        assert_eq!(v.len(), MAX_FRAMES);
        assert_eq!(v[0], 0);
        assert_eq!(*v.last().unwrap(), 19);
        assert!(v.windows(2).all(|w| w[0] < w[1]));
    }
}
