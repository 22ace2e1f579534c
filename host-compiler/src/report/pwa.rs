//! The report's PWA-feedback section (Ch. 6): the partitions over the explored region F (6.2) projected
//! onto the workspace plane, closed-loop runs of the PWA image, the tree's worst-case depth and sizes, and
//! the per-partition certificate table recomputed by [`crate::verify::pwa::recheck`].

use plotters::prelude::*;

use super::data::{Ellipse2, ReportData, Shape2};
use super::format::{escape, num};
use super::planar::{clip_to_rect, ellipse_points, ellipse_rect, shape_polygon, Rect};

/// What a PWA synthesis produced and how it was checked (also written to `certificate.json`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PwaSummary {
    pub data_points: usize,
    pub trajectories: usize,
    pub eps_fit: f64,
    pub stats: crate::pwa::PartitionStats,
    pub learn_seconds: f64,
    pub partition_seconds: f64,
    pub image_bytes: usize,
    pub feedforward_image_bytes: usize,
    pub recheck: crate::verify::pwa::PwaRecheck,
    pub monte_carlo: crate::verify::pwa::PwaMonteCarlo,
    /// Coverage of Init by the PWA image's own envelope ([`crate::pwa::coverage`]).
    pub coverage: crate::cover::estimate::CoverageEstimate,
}

/// Plot-ready PWA data.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PwaReport {
    /// Balls of F (projections onto the workspace plane) with the partition (law) of their cluster.
    pub balls: Vec<(Ellipse2, usize)>,
    /// Closed-loop paths of the PWA image in the workspace plane.
    pub paths: Vec<Vec<[f64; 2]>>,
    pub summary: PwaSummary,
}

/// Projects a P-ball onto coordinates (0, 1): the shadow of {x : (x − c)ᵀP(x − c) ≤ r²} is the ellipse with
/// shape r²·(P⁻¹)₀₁ (a Schur-complement fact), drawn as c + M w, M = r·chol((P⁻¹)₀₁).
fn shadow(Pinv: &faer::Mat<f64>, c: &[f64], r: f64) -> Ellipse2 {
    let (a, b, d) = (Pinv[(0, 0)], Pinv[(0, 1)], Pinv[(1, 1)]);
    let l11 = a.max(0.0).sqrt();
    let l21 = if l11 > 0.0 { b / l11 } else { 0.0 };
    let l22 = (d - l21 * l21).max(0.0).sqrt();
    Ellipse2 {
        center: [c[0], c[1]],
        M: [[r * l11, 0.0], [r * l21, r * l22]],
    }
}

/// The PWA section's data from the learned controller, its image and the checks.
pub fn pwa_report(
    pwa: &crate::pwa::PwaController,
    image: &shared_types::image::Image<'_>,
    summary: &PwaSummary,
) -> PwaReport {
    let n = image.n();
    let P = faer::Mat::from_fn(n, n, |i, j| image.P(0, i, j) as f64);
    let Pinv = crate::linalg::sym_fn(P.as_ref(), |l| 1.0 / l).unwrap_or(faer::Mat::identity(n, n));
    let balls = if n >= 2 {
        pwa.ctx
            .points
            .iter()
            .zip(&pwa.assignment)
            .map(|(p, &j)| (shadow(&Pinv, &p.x, p.rho), j))
            .collect()
    } else {
        vec![]
    };
    let paths = summary
        .monte_carlo
        .sample_paths
        .iter()
        .map(|p| {
            p.iter()
                .map(|x| [x[0], x.get(1).copied().unwrap_or(0.0)])
                .collect()
        })
        .collect();
    PwaReport {
        balls,
        paths,
        summary: summary.clone(),
    }
}

/// Partition colour: a fixed hue walk, so neighbouring laws differ.
fn law_color(j: usize) -> RGBColor {
    let h = (j as f64 * 0.618_033_988_75).fract();
    let (r, g, b) = hsv(h, 0.65, 0.85);
    RGBColor(r, g, b)
}

fn hsv(h: f64, s: f64, v: f64) -> (u8, u8, u8) {
    let i = (h * 6.0).floor();
    let f = h * 6.0 - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - f * s), v * (1.0 - (1.0 - f) * s));
    let (r, g, b) = match i as i32 % 6 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    ((r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8)
}

fn plot(data: &ReportData, r: &PwaReport) -> Result<String, Box<dyn std::error::Error>> {
    let mut view = Rect::EMPTY;
    for (e, _) in &r.balls {
        view.union(&ellipse_rect(e));
    }
    for p in &r.paths {
        view.include_all(p);
    }
    for s in &data.goal_plane {
        if !matches!(s, Shape2::HalfPlanes { .. }) {
            view.union(&super::planar::shape_rect(s, &Rect::EMPTY));
        }
    }
    let view = view.padded(0.06);
    let mut svg = String::new();
    {
        let w = 760u32;
        let ratio = (view.height() / view.width()).clamp(0.45, 1.25);
        let root = SVGBackend::with_string(&mut svg, (w, (w as f64 * ratio) as u32 + 60))
            .into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(view.lo[0]..view.hi[0], view.lo[1]..view.hi[1])?;
        chart
            .configure_mesh()
            .x_desc(data.plane_labels[0].as_str())
            .y_desc(data.plane_labels[1].as_str())
            .light_line_style(RGBColor(240, 240, 240))
            .draw()?;
        let fill = |chart: &mut ChartContext<_, _>,
                    poly: Vec<[f64; 2]>,
                    c: RGBColor,
                    a: f64|
         -> Result<(), Box<dyn std::error::Error>> {
            let poly = clip_to_rect(&poly, &view);
            if !poly.is_empty() {
                chart.draw_series(std::iter::once(Polygon::new(
                    poly.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
                    c.mix(a).filled(),
                )))?;
            }
            Ok(())
        };
        for s in &data.unsafe_plane {
            fill(
                &mut chart,
                shape_polygon(s, &view),
                super::plots::UNSAFE_COLOR,
                0.35,
            )?;
        }
        for s in &data.goal_plane {
            fill(
                &mut chart,
                shape_polygon(s, &view),
                super::plots::GOAL_COLOR,
                0.3,
            )?;
        }
        for (e, j) in &r.balls {
            fill(&mut chart, ellipse_points(e, 24), law_color(*j), 0.35)?;
        }
        for p in &r.paths {
            chart.draw_series(LineSeries::new(
                p.iter().map(|q| (q[0], q[1])),
                BLACK.mix(0.7).stroke_width(1),
            ))?;
        }
        root.present()?;
    }
    Ok(svg)
}

/// Appends the PWA section to the page.
pub fn section(h: &mut String, data: &ReportData, r: &PwaReport) {
    use std::fmt::Write;
    let s = &r.summary;
    let st = &s.stats;
    let mc = &s.monte_carlo;
    h.push_str("<section id=\"pwa\">\n<h2>Piecewise-affine feedback (Ch. 6)</h2>\n");
    let _ = write!(
        h,
        "<table class=\"kv\">\
         <tr><th>data points (x̃ᵢ(κ), ṽᵢ(κ))</th><td class=\"n\">{}</td></tr>\
         <tr><th>trajectories</th><td class=\"n\">{}</td></tr>\
         <tr><th>fitting tolerance ε_fit (§6.2, mod. 1)</th><td class=\"n\">{}</td></tr>\
         <tr><th>coverage of Init by F (the image's point location)</th><td class=\"n\">{} (lower bound {} at {} confidence, {} samples)</td></tr>\
         <tr><th>partitions (laws)</th><td class=\"n\">{} (dissertation: 110; ratio {})</td></tr>\
         <tr><th>tree</th><td class=\"n\">{} nodes, {} leaves, {} balls, {} references</td></tr>\
         <tr><th>worst-case depth</th><td class=\"n\">{} hyperplane tests, then at most {} ball tests</td></tr>\
         <tr><th>balls dropped</th><td class=\"n\">{}</td></tr>\
         <tr><th>learning time</th><td class=\"n\">{} s (partitioning {} s)</td></tr>\
         <tr><th>image</th><td class=\"n\">{} bytes (feedforward image of the same cover: {} bytes)</td></tr>\
         <tr><th>containment across boundaries</th><td class=\"n\">{} leaf visits, {} failing balls</td></tr>\
         <tr><th>Goal within T (time-to-go ranking)</th><td class=\"n\">{}</td></tr>\
         <tr><th>closed-loop runs from F</th><td class=\"n\">{} ({} over Init), {} violations, ≤ {} steps to Goal</td></tr>\
         </table>\n",
        s.data_points,
        s.trajectories,
        num(s.eps_fit),
        num(s.coverage.mean),
        num(s.coverage.lower),
        num(s.coverage.confidence),
        s.coverage.samples,
        st.partitions,
        num(st.partitions as f64 / 110.0),
        st.nodes,
        st.leaves,
        st.balls,
        st.ball_refs,
        st.depth,
        st.max_leaf_balls,
        st.dropped,
        num(s.learn_seconds),
        num(s.partition_seconds),
        s.image_bytes,
        s.feedforward_image_bytes,
        s.recheck.containment_checks,
        s.recheck.containment_failures,
        escape(&s.recheck.liveness.describe()),
        mc.runs,
        mc.init_runs,
        mc.violations,
        mc.max_steps_to_goal,
    );
    h.push_str("<figure id=\"pwa-plot\">\n");
    match plot(data, r) {
        Ok(svg) => h.push_str(&svg),
        Err(e) => {
            let _ = write!(
                h,
                "<p class=\"note\">Plot could not be drawn: {}</p>",
                escape(&e.to_string())
            );
        }
    }
    let _ = write!(
        h,
        "<figcaption>The explored region F: every certified ball B_P(x̃ᵢ(κ), δᵢ) projected onto ({}, {}), \
         coloured by the partition (law) of its cluster; black: {} closed-loop runs of the PWA image \
         (f32 evaluator). Red: Unsafe, green: Goal.</figcaption>\n</figure>\n",
        escape(&data.plane_labels[0]),
        escape(&data.plane_labels[1]),
        r.paths.len()
    );
    h.push_str(
        "<h3>Per-partition certificate (recomputed from the image)</h3>\n<table id=\"pwa-table\">\
         <tr><th>j</th><th>balls</th><th>σ_j = λ_min(P − Ã_jᵀPÃ_j) (6.6)</th><th>max r̃_crit/ρ (6.7)</th>\
         <th>max reach/ρ (6.5)</th><th>min input slack</th><th>min Unsafe clearance</th><th>ok</th></tr>\n",
    );
    for p in &s.recheck.partitions {
        let _ = writeln!(
            h,
            "<tr><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            p.partition,
            p.balls,
            num(p.sigma),
            num(p.worst_rcrit_ratio),
            num(p.worst_reach_ratio),
            num(p.worst_input_slack),
            num(p.worst_unsafe_clearance),
            if p.ok { "yes" } else { "<span class=\"bad\">NO</span>" }
        );
    }
    h.push_str("</table>\n</section>\n");
}
