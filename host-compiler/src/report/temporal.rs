//! `report.html` for an MTL task (Problem 2.28): the formula, the verdict, the robustness signal of each
//! certified nominal over time in the CAF metric (Def 2.17 with the metric (2.14)) with the critical time
//! and atom that give ρ(0) marked, the nominal paths in the plane of the first two state coordinates with
//! the discs the formula names there, and a table of the balls (δ at the samples, in continuous time,
//! δ_Input, the stored radius).

use super::format::{escape, num};
use super::plots::{padded_span, trajectory_color, DynResult, GOAL_COLOR, UNSAFE_COLOR};
use crate::spec::{Coords, Problem, Shape};
use crate::synth::temporal::TemporalSynthesis;
use plotters::prelude::*;

/// Most nominals drawn in the plots.
const SHOWN: usize = 12;

/// The page, self-contained (inline SVG).
/// `formula` is the user's text; `in_task`, when given, the same formula over the task's coordinates
/// (a feedback-linearizable plant's ξ), which is what the atoms measure.
pub fn render(
    problem: &Problem,
    spec: &str,
    formula: &str,
    in_task: Option<&str>,
    s: &TemporalSynthesis,
) -> String {
    let mut h = String::new();
    h.push_str(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>MTL synthesis report</title>",
    );
    h.push_str("<style>body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}code{background:#f4f4f4;padding:1px 4px}</style></head><body>");
    let ok = s.verify.violations == 0 && s.recheck.iter().all(|c| c.ok);
    h.push_str(&format!(
        "<h1>{}</h1><p>Spec <code>{}</code>. Task: <code>{}</code> on [0, {}] s, atoms in the CAF metric.{}</p>",
        if ok {
            "Certified and verified"
        } else {
            "NOT certified"
        },
        escape(spec),
        escape(formula),
        num(problem.horizon),
        in_task.map_or(String::new(), |f| format!(
            " Over the linearizing coordinates ξ (the task's state) it reads <code>{}</code>.",
            escape(f)
        ))
    ));
    h.push_str(&format!(
        "<p>{} balls ({} seeds tried); coverage of Init {} (lower bound {} at {} confidence, {} samples); stop: {}.</p>",
        s.trajectories.len(),
        s.seeds_tried,
        num(s.coverage.mean),
        num(s.coverage.lower),
        num(s.coverage.confidence),
        s.coverage.samples,
        escape(&s.stop)
    ));
    h.push_str(&format!(
        "<p>Re-proved from the image bytes: {} of {} balls. Monte Carlo: {} runs judged by the formula at the samples and sampled 8× finer, <b>{} violations</b>; least robustness {} (Euclidean, every 16th run), least input slack {}.</p>",
        s.recheck.iter().filter(|c| c.ok).count(),
        s.recheck.len(),
        s.verify.runs,
        s.verify.violations,
        num(s.verify.min_robustness),
        num(s.verify.min_input_slack)
    ));
    let period = problem.plant.period;
    h.push_str("<h2>Robustness of the nominals over time</h2><p>ρ(t) = ⟦φ⟧(x̃, t) in the CAF metric (the formula judged from t on; only ρ(0) is the task). The dot at t = 0 is ρ(0); the dashed line marks the time of the atom it comes from (¬ when negated).</p>");
    match signal_plot(s, period) {
        Ok(svg) => h.push_str(&svg),
        Err(e) => h.push_str(&format!("<p>(plot failed: {})</p>", escape(&e.to_string()))),
    }
    if problem.plant.n() >= 2 {
        h.push_str("<h2>Nominal paths (x1, x2)</h2><p>Discs the spec names over (x1, x2) are drawn: Goal green, Unsafe red, the named sets grey.</p>");
        match path_plot(problem, s) {
            Ok(svg) => h.push_str(&svg),
            Err(e) => h.push_str(&format!("<p>(plot failed: {})</p>", escape(&e.to_string()))),
        }
    }
    h.push_str("<h2>Balls</h2><table><tr><th>#</th><th>source</th><th>ρ(0) samples</th><th>continuous</th><th>δ_Input</th><th>δ</th><th>stored</th><th>critical atom, t</th></tr>");
    for (i, t) in s.trajectories.iter().enumerate() {
        let c = &t.certificate;
        let crit = c
            .critical
            .as_ref()
            .map_or("—".to_string(), |(set, k, neg)| {
                format!(
                    "{}{} at {} s",
                    if *neg { "¬" } else { "" },
                    escape(set),
                    num(*k as f64 * period)
                )
            });
        h.push_str(&format!(
            "<tr><td>{i}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{crit}</td></tr>",
            escape(&t.source.to_string()),
            num(c.delta_samples),
            num(c.delta_continuous),
            num(c.delta_input),
            num(c.delta),
            num(c.delta_stored as f64)
        ));
    }
    h.push_str("</table></body></html>\n");
    h
}

fn signal_plot(s: &TemporalSynthesis, period: f64) -> DynResult<String> {
    let shown = &s.trajectories[..s.trajectories.len().min(SHOWN)];
    let finite = |v: &f64| v.is_finite();
    let (lo, hi) = shown
        .iter()
        .flat_map(|t| t.certificate.signal.iter().copied().filter(finite))
        .fold((0.0f64, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    let tmax = shown
        .iter()
        .map(|t| t.certificate.signal.len())
        .max()
        .unwrap_or(1) as f64
        * period;
    let pad = 0.05 * (hi - lo).max(1e-9);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 360)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..tmax.max(period), (lo - pad)..(hi + pad))?;
        chart
            .configure_mesh()
            .x_desc("t [s]")
            .y_desc("ρ(t), CAF metric")
            .draw()?;
        chart.draw_series(LineSeries::new(
            [(0.0, 0.0), (tmax, 0.0)],
            BLACK.stroke_width(1),
        ))?;
        for (i, t) in shown.iter().enumerate() {
            let color = trajectory_color(i);
            let pts: Vec<(f64, f64)> = t
                .certificate
                .signal
                .iter()
                .enumerate()
                .filter(|(_, v)| v.is_finite())
                .map(|(k, &v)| (k as f64 * period, v))
                .collect();
            chart.draw_series(LineSeries::new(pts, color.stroke_width(1)))?;
            // ρ(0) at t = 0, and a dashed line at the critical time of its atom.
            let v = t.certificate.delta_samples;
            chart.draw_series([Circle::new((0.0, v), 4, color.filled())])?;
            if let Some((set, k, neg)) = &t.certificate.critical {
                let tk = *k as f64 * period;
                chart.draw_series(DashedLineSeries::new(
                    [(tk, lo - pad), (tk, hi + pad)],
                    4,
                    3,
                    color.stroke_width(1),
                ))?;
                if i == 0 {
                    let at = if tk > 0.6 * tmax { tk - 0.3 * tmax } else { tk };
                    chart.draw_series([Text::new(
                        format!(
                            "ρ(0) = {v:.4} from {}{set} at {tk:.2} s",
                            if *neg { "¬" } else { "" }
                        ),
                        (at, hi + 0.5 * pad),
                        ("sans-serif", 13).into_font(),
                    )])?;
                }
            }
        }
        root.present()?;
    }
    Ok(svg)
}

fn path_plot(problem: &Problem, s: &TemporalSynthesis) -> DynResult<String> {
    // Discs over (x1, x2): Goal, Unsafe members, named sets.
    let mut discs: Vec<([f64; 2], f64, RGBColor)> = Vec::new();
    let mut disc = |d: &crate::spec::SetDesc, color: RGBColor| {
        if let (Shape::Ball { center, radius }, Coords::StateIndices(idx)) = (&d.shape, &d.coords) {
            if idx.as_slice() == [0, 1] {
                discs.push(([center[0], center[1]], *radius, color));
            }
        }
    };
    disc(&problem.goal, GOAL_COLOR);
    for u in &problem.unsafe_sets {
        disc(u, UNSAFE_COLOR);
    }
    for (_, d) in &problem.sets {
        disc(d, RGBColor(120, 120, 120));
    }
    let shown = &s.trajectories[..s.trajectories.len().min(SHOWN)];
    let mut xs: Vec<f64> = Vec::new();
    let mut ys: Vec<f64> = Vec::new();
    for t in shown {
        for x in &t.nominal.x {
            xs.push(x[0]);
            ys.push(x[1]);
        }
    }
    for (c, r, _) in &discs {
        xs.extend([c[0] - r, c[0] + r]);
        ys.extend([c[1] - r, c[1] + r]);
    }
    let ((x0, x1), (y0, y1)) = (padded_span(&xs, 0.05), padded_span(&ys, 0.05));
    let width = 600u32;
    let height = ((width as f64) * (y1 - y0) / (x1 - x0)).clamp(200.0, 900.0) as u32;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart.configure_mesh().x_desc("x1").y_desc("x2").draw()?;
        for (c, r, color) in &discs {
            let pts: Vec<(f64, f64)> = (0..=64)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / 64.0;
                    (c[0] + r * a.cos(), c[1] + r * a.sin())
                })
                .collect();
            chart.draw_series([Polygon::new(pts, color.mix(0.25).filled())])?;
        }
        for (i, t) in shown.iter().enumerate() {
            let pts: Vec<(f64, f64)> = t.nominal.x.iter().map(|x| (x[0], x[1])).collect();
            chart.draw_series(LineSeries::new(pts, trajectory_color(i).stroke_width(1)))?;
        }
        root.present()?;
    }
    Ok(svg)
}
