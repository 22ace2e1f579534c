//! `report.html` for a hybrid plant with internal switching (§4.2.2, Examples 4.25, 5.5, 5.6) or forced
//! switching (§4.2.1; the task reach-avoid, or an MTL formula, Def 4.18): the automaton, the verdict, and per plotting plane the nominal segments coloured by location, their tubes
//! (the P_ℓ-balls of radius δᵢ around the samples, projected), the guard of the edge taken, the next
//! segment's start ball that the landings must hit (the "hole" of Lemma 4.23's safe transition, drawn
//! dashed: its section by the guard plane is the hole), and the cover of Init by the runs' first balls;
//! then a table of every run's segments (δᵢ, what binds it, the event samples, the rows kept, where the run
//! came from).
//!
//! **Where the cover came from** (in the manner of the text's Figure 5.5, one plot per plane framed on
//! Init): each run's first ball is filled in the colour of its origin (the planner from a seed, Algorithm 4
//! grown from another ball, a route of the global search, a recording), darker when its radius is below
//! δε (`min_robustness`, the balls Algorithm 4 no longer grows from), and a run grown by Algorithm 4 is
//! joined by a thin line to the centre of the ball it grew from.
//!
//! The planes pair the guard's main coordinate (the largest component of the first edge's normal) with
//! each other state coordinate, at most [`PLANES`] of them. Sets are projected: an ellipsoid or ball to
//! its shadow ellipse, a box to its sides; a set that does not constrain both coordinates is not drawn.

use super::format::{escape, num};
use super::plots::{css_color, padded_span, trajectory_color, DynResult, GOAL_COLOR, UNSAFE_COLOR};
use super::present::root2;
use crate::cover::seeds::{Origin, Source};
use crate::model::hybrid::EdgeKind;
use crate::spec::sets::{Coords, SetDesc, Shape};
use crate::synth::hybrid::{HybridSynthesis, HybridTask};
use faer::Mat;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// Most runs whose nominals and tubes are drawn (every run's first ball is drawn in the cover).
const SHOWN: usize = 8;
/// Most plotting planes.
const PLANES: usize = 3;
/// Tubes drawn per segment.
const TUBES: usize = 10;

/// Colour of location `loc` (the trajectory palette; a run's start dot takes its rank's colour).
fn location_color(loc: usize) -> RGBColor {
    trajectory_color(loc)
}

/// The cover's fill for a run of this origin (module doc).
fn origin_color(o: &Origin) -> RGBColor {
    match o {
        Origin::Generator => RGBColor(60, 110, 220),
        Origin::Algorithm4(_) => RGBColor(0, 150, 150),
        Origin::Route(_) => RGBColor(230, 140, 20),
        Origin::Import(_) => RGBColor(140, 70, 170),
    }
}

/// The origin classes in the legend's order, with their names.
const ORIGINS: [(Origin, &str); 4] = [
    (Origin::Generator, "the planner from a seed"),
    (Origin::Algorithm4(0), "Algorithm 4 (grown from a ball)"),
    (Origin::Route(0), "a route of the global search"),
    (Origin::Import(String::new()), "a recording"),
];

/// Whether two origins are of one class (the legend's).
fn same_class(a: &Origin, b: &Origin) -> bool {
    std::mem::discriminant(a) == std::mem::discriminant(b)
}

/// The cover's legend: a key and a count per origin class present, and how many balls are below δε.
fn origin_legend(s: &HybridSynthesis, delta_eps: f64) -> String {
    let mut h = String::from("<p id=\"cover-origins\">The cover by origin:");
    for (o, name) in &ORIGINS {
        let count = s
            .sources
            .iter()
            .filter(|x| same_class(&x.origin, o))
            .count();
        if count > 0 {
            h.push_str(&format!(
                "<span class=key style=\"background:{}\"></span>{}: {}",
                css_color(origin_color(o)),
                escape(name),
                count
            ));
        }
    }
    let low = s
        .runs
        .iter()
        .filter(|r| (r.certificate.delta_stored as f64) < delta_eps)
        .count();
    h.push_str(&format!(
        "; {low} of {} balls have a radius below δε = {} (drawn darker; Algorithm 4 does not grow from them). A thin line joins a ball grown by Algorithm 4 to the ball it grew from.</p>",
        s.runs.len(),
        num(delta_eps)
    ));
    h
}

/// The page, self-contained (inline SVG).
pub fn render(task: &HybridTask, spec: &str, s: &HybridSynthesis) -> String {
    let problem = &task.problem;
    let modes = task.plant.modes();
    let mut h = String::new();
    h.push_str(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>Hybrid synthesis report</title>",
    );
    h.push_str("<style>body{font-family:sans-serif;max-width:1000px;margin:2em auto;color:#222}table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}td.l{text-align:left}code{background:#f4f4f4;padding:1px 4px}.key{display:inline-block;width:1em;height:0.7em;margin:0 4px 0 12px}</style></head><body>");
    let unproved = s.recheck.iter().filter(|c| !c.ok).count();
    let ok = s.verify.violations == 0 && unproved == 0 && !s.runs.is_empty();
    h.push_str(&format!(
        "<h1>{}</h1><p>Spec <code>{}</code>: a hybrid automaton of {} locations and {} edges, {} on [0, {}] s sampled every {} s. Runs go {}.</p>",
        if ok { "Certified and verified" } else { "NOT certified" },
        escape(spec),
        modes.len(),
        task.plant.edges().len(),
        match (&task.formula, &problem.mtl) {
            (Some(_), Some(f)) => format!(
                "the MTL formula <code>{}</code> (Def 4.18: every run certified for the formula, its atoms in the initial location's CAF metric; the Monte Carlo judges each run by the formula as written, at the samples and between them)",
                escape(f)
            ),
            _ => "reach-avoid".to_string(),
        },
        num(problem.horizon),
        num(task.plant.period()),
        escape(&task.route()),
    ));
    h.push_str(&format!(
        "<p>{} runs ({} seeds tried, {} refused); coverage of Init {} (lower bound {} at {} confidence, {} samples); stop: {}; {} s.</p>",
        s.runs.len(),
        s.seeds_tried,
        s.refused.len(),
        num(s.coverage.mean),
        num(s.coverage.lower),
        num(s.coverage.confidence),
        s.coverage.samples,
        escape(&s.stop),
        num(s.seconds),
    ));
    h.push_str(&format!(
        "<p>Re-proved from the image bytes: {} of {} runs. Monte Carlo on the exact hybrid flow (events found between samples) through the shared evaluator: {} runs ({} switched, at most {} events; {} boundary starts refused by the f32 selection), <b>{} violations</b>{}.</p>",
        s.recheck.len() - unproved,
        s.recheck.len(),
        s.verify.runs - s.verify.rejected,
        s.verify.switched,
        s.verify.max_events,
        s.verify.rejected,
        s.verify.violations,
        // A formula's runs are judged by the formula, which measures no distance to Unsafe.
        if task.formula.is_some() {
            String::new()
        } else {
            format!("; least distance to Unsafe {}", num(s.verify.min_unsafe_distance))
        },
    ));
    if let Some(v) = &s.verify.first_violation {
        h.push_str(&format!("<p><b>First violation:</b> {}</p>", escape(v)));
    }
    if let Ok(img) = shared_types::image::decode(&s.image) {
        h.push_str(&format!(
            "<p id=\"after-goal-line\">{}.</p>",
            escape(&super::after_goal_line(&img))
        ));
    }

    h.push_str(
        "<h2>Automaton</h2><table><tr><th>edge</th><th>kind</th><th>guard</th><th>reset</th></tr>",
    );
    for e in task.plant.edges() {
        let mut guard = e
            .guard
            .a
            .iter()
            .zip(&e.guard.b)
            .map(|(a, b)| format!("{} ≤ {}", linear_form(a), num(*b)))
            .collect::<Vec<_>>()
            .join(", ");
        if guard.is_empty() {
            guard = "the whole space".into();
        }
        h.push_str(&format!(
            "<tr><td class=l>{} → {}</td><td class=l>{}</td><td class=l>{}</td><td class=l>{}</td></tr>",
            escape(&modes[e.from].name),
            escape(&modes[e.to].name),
            match e.kind {
                EdgeKind::Internal => "internal (taken when the flow enters the guard)",
                EdgeKind::Forced => "forced (the controller's choice)",
            },
            escape(&guard),
            escape(&reset_text(&e.reset)),
        ));
    }
    h.push_str("</table><p>");
    for (l, m) in modes.iter().enumerate() {
        h.push_str(&format!(
            "<span class=key style=\"background:{}\"></span>{}",
            css_color(location_color(l)),
            escape(&m.name)
        ));
    }
    h.push_str("</p>");

    h.push_str(if task.forced {
        "<h2>Runs in the state space</h2><p>Nominal segments in their location's colour, with tubes (the certified ball of each segment around its samples, projected); the next segment's start ball, dashed: the controller switches by its table, and every run near the nominal is, at the switching sample, inside the edge's guard and within that ball (the safe transition, Theorem 4.17); the runs' first balls over Init (the cover, coloured by origin as below). Goal green, Unsafe red, Init grey.</p>"
    } else {
        "<h2>Runs in the state space</h2><p>Nominal segments in their location's colour, with tubes (the certified ball of each segment around its samples, projected); the guard of the edge taken (black line); the next segment's start ball, dashed: every run near the nominal lands inside it (Lemma 4.23; its section by the guard is the safe hole); the runs' first balls over Init (the cover, coloured by origin as below). Goal green, Unsafe red, Init grey.</p>"
    });
    for pl in planes(task) {
        match plane_plot(task, s, pl) {
            Ok(svg) => h.push_str(&svg),
            Err(e) => h.push_str(&format!("<p>(plot failed: {})</p>", escape(&e.to_string()))),
        }
    }

    h.push_str("<h2>Cover of Init</h2><p>Each run's first ball over Init (grey), projected, in the manner of the text's Figure 5.5.</p>");
    h.push_str(&origin_legend(s, problem.synthesis.min_robustness));
    for pl in planes(task) {
        match cover_plot(task, s, pl) {
            Ok(svg) => h.push_str(&svg),
            Err(e) => h.push_str(&format!("<p>(plot failed: {})</p>", escape(&e.to_string()))),
        }
    }

    h.push_str("<h2>Segments</h2><table><tr><th>run</th><th>x̃(0)</th><th>δ stored</th><th>segment</th><th>location</th><th>δᵢ</th><th>what binds δᵢ</th><th>events (samples)</th><th>rows</th><th>origin</th></tr>");
    for (i, r) in s.runs.iter().enumerate() {
        let origin = s.sources.get(i).map_or(String::new(), Source::to_string);
        for (j, (seg, &loc)) in r.certificate.segments.iter().zip(&r.locations).enumerate() {
            let head = if j == 0 {
                format!(
                    "<td>{}</td><td class=l>{}</td><td>{}</td>",
                    i,
                    escape(&super::format::vector(&r.nominals[0].x[0])),
                    num(r.certificate.delta_stored as f64)
                )
            } else {
                "<td></td><td></td><td></td>".to_string()
            };
            h.push_str(&format!(
                "<tr>{head}<td>{j}</td><td class=l>{}</td><td>{}</td><td class=l>{}</td><td>{}</td><td>{}</td><td class=l>{}</td></tr>",
                escape(&modes[loc].name),
                num(seg.delta),
                escape(seg.binding),
                seg.events.map_or("—".to_string(), |(a, b)| format!("{a}–{b}")),
                seg.rows,
                if j == 0 { escape(&origin) } else { String::new() },
            ));
        }
    }
    h.push_str("</table>");
    if !s.refused.is_empty() {
        h.push_str("<h2>Refused seeds</h2><table><tr><th>x0</th><th>why</th></tr>");
        for (x, why) in s.refused.iter().take(20) {
            h.push_str(&format!(
                "<tr><td class=l>{}</td><td class=l>{}</td></tr>",
                escape(&super::format::vector(x)),
                escape(why)
            ));
        }
        if s.refused.len() > 20 {
            h.push_str(&format!(
                "<tr><td class=l colspan=2>… and {} more</td></tr>",
                s.refused.len() - 20
            ));
        }
        h.push_str("</table>");
    }
    h.push_str("</body></html>");
    h
}

/// `a₁x1 + a₂x2 …` with the zero terms left out.
fn linear_form(a: &[f64]) -> String {
    let terms: Vec<String> = a
        .iter()
        .enumerate()
        .filter(|(_, v)| **v != 0.0)
        .map(|(i, v)| match *v {
            1.0 => format!("x{}", i + 1),
            -1.0 => format!("−x{}", i + 1),
            v => format!("{}·x{}", num(v), i + 1),
        })
        .collect();
    if terms.is_empty() {
        "0".into()
    } else {
        terms.join(" + ")
    }
}

/// "identity", or x ↦ R x + r row by row.
fn reset_text(r: &crate::model::hybrid::Reset) -> String {
    let n = r.R.nrows();
    let identity = r.r.iter().all(|&v| v == 0.0)
        && (0..n).all(|i| (0..r.R.ncols()).all(|j| r.R[(i, j)] == if i == j { 1.0 } else { 0.0 }));
    if identity {
        return "identity".into();
    }
    (0..n)
        .map(|i| {
            let row: Vec<f64> = (0..r.R.ncols()).map(|j| r.R[(i, j)]).collect();
            format!("x{}′ = {} + {}", i + 1, linear_form(&row), num(r.r[i]))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The plotting planes (module doc).
fn planes(task: &HybridTask) -> Vec<[usize; 2]> {
    let n = task.plant.modes()[0].flow.n();
    if n < 2 {
        return vec![];
    }
    let g = task
        .edges
        .first()
        .and_then(|&e| task.plant.edges()[e].guard.a.first())
        .map(|a| {
            (0..n)
                .max_by(|&i, &j| a[i].abs().total_cmp(&a[j].abs()))
                .unwrap_or(0)
        })
        .unwrap_or(0);
    (0..n)
        .filter(|&j| j != g)
        .take(PLANES)
        .map(|j| [g, j])
        .collect()
}

/// The shadow of `{x : (x − c)ᵀ E (x − c) ≤ r²}` on the plane `pl`, as a polygon: the ellipse of centre
/// (c_i, c_j) and shape r²·(E⁻¹)[pl, pl].
fn shadow(E_inv: &Mat<f64>, c: &[f64], r: f64, pl: [usize; 2]) -> Vec<(f64, f64)> {
    let S = Mat::from_fn(2, 2, |a, b| r * r * E_inv[(pl[a], pl[b])]);
    let e = super::data::Ellipse2 {
        center: [c[pl[0]], c[pl[1]]],
        M: root2(&S),
    };
    super::planar::ellipse_points(&e, 64)
        .into_iter()
        .map(|p| (p[0], p[1]))
        .collect()
}

/// A spec set's shadow on the plane, as a polygon (`None` when it does not constrain both coordinates
/// or is a polytope).
fn set_shadow(d: &SetDesc, n: usize, pl: [usize; 2]) -> Option<Vec<(f64, f64)>> {
    let idx: Vec<usize> = match &d.coords {
        Coords::State => (0..n).collect(),
        Coords::StateIndices(v) => v.clone(),
        Coords::Output { .. } => return None,
    };
    let (a, b) = (
        idx.iter().position(|&i| i == pl[0])?,
        idx.iter().position(|&i| i == pl[1])?,
    );
    let d2 = idx.len();
    match &d.shape {
        Shape::Ball { center, radius } => {
            let I = Mat::<f64>::identity(d2, d2);
            Some(shadow(&I, center, *radius, [a, b]))
        }
        Shape::Ellipsoid { center, Q } => {
            let Qm = Mat::from_fn(d2, d2, |i, j| Q.data[i * d2 + j]);
            let Qi = crate::linalg::sym_fn(Qm.as_ref(), |l| if l > 0.0 { 1.0 / l } else { 0.0 })?;
            Some(shadow(&Qi, center, 1.0, [a, b]))
        }
        Shape::Box { lo, hi } => Some(vec![
            (lo[a], lo[b]),
            (hi[a], lo[b]),
            (hi[a], hi[b]),
            (lo[a], hi[b]),
        ]),
        Shape::Polytope { .. } => None,
    }
}

/// Init's box on the plane.
fn init_box(b: &crate::spec::InitBox, pl: [usize; 2]) -> Vec<(f64, f64)> {
    let (lo, hi) = (&b.lo, &b.hi);
    vec![
        (lo[pl[0]], lo[pl[1]]),
        (hi[pl[0]], lo[pl[1]]),
        (hi[pl[0]], hi[pl[1]]),
        (lo[pl[0]], hi[pl[1]]),
    ]
}

/// The cover on a plane's chart: every run's first ball in its origin's colour, darker below δε, and
/// Algorithm 4's links to the ball each run grew from (module doc).
fn draw_cover<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    task: &HybridTask,
    s: &HybridSynthesis,
    pl: [usize; 2],
) -> DynResult<()>
where
    DB::ErrorType: 'static,
{
    let inv = &task.constants[task.path[0]].roots.inv;
    let delta_eps = task.problem.synthesis.min_robustness;
    let centre = |r: &crate::synth::hybrid::HybridRun| {
        let x = &r.nominals[0].x[0];
        (x[pl[0]], x[pl[1]])
    };
    for (i, r) in s.runs.iter().enumerate() {
        let origin = s.sources.get(i).map_or(&Origin::Generator, |x| &x.origin);
        let delta = r.certificate.delta_stored as f64;
        let poly = shadow(inv, &r.nominals[0].x[0], delta, pl);
        let alpha = if delta < delta_eps { 0.45 } else { 0.18 };
        chart.draw_series([Polygon::new(poly, origin_color(origin).mix(alpha).filled())])?;
        if let Origin::Algorithm4(m) = origin {
            if let Some(parent) = s.runs.get(*m) {
                chart.draw_series(LineSeries::new(
                    [centre(parent), centre(r)],
                    RGBColor(90, 90, 90).mix(0.6).stroke_width(1),
                ))?;
            }
        }
    }
    Ok(())
}

/// The cover of Init on a plane, framed on Init and the balls (the text's Figure 5.5): Init grey, the
/// balls and links of [`draw_cover`].
fn cover_plot(task: &HybridTask, s: &HybridSynthesis, pl: [usize; 2]) -> DynResult<String> {
    let init = init_box(&task.problem.init, pl);
    let (mut xs, mut ys): (Vec<f64>, Vec<f64>) = init.iter().copied().unzip();
    for r in &s.runs {
        let x = &r.nominals[0].x[0];
        xs.push(x[pl[0]]);
        ys.push(x[pl[1]]);
    }
    plane_svg(600, &xs, &ys, pl, init, |chart, _| {
        draw_cover(chart, task, s, pl)
    })
}

/// The chart of a plane both plots draw on.
type PlaneChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// An SVG `width` wide framed on the points (`xs`, `ys`) padded by 8 %, with the plane's axes and Init
/// (grey), then `draw` on it, given the frame (x0, x1, y0, y1).
fn plane_svg(
    width: u32,
    xs: &[f64],
    ys: &[f64],
    pl: [usize; 2],
    init: Vec<(f64, f64)>,
    draw: impl for<'a, 'b> FnOnce(&mut PlaneChart<'a, 'b>, [f64; 4]) -> DynResult<()>,
) -> DynResult<String> {
    let ((x0, x1), (y0, y1)) = (padded_span(xs, 0.08), padded_span(ys, 0.08));
    let height = ((width as f64) * (y1 - y0) / (x1 - x0)).clamp(300.0, 700.0) as u32;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc(format!("x{}", pl[0] + 1))
            .y_desc(format!("x{}", pl[1] + 1))
            .draw()?;
        let grey = RGBColor(120, 120, 120);
        chart.draw_series([Polygon::new(init, grey.mix(0.25).filled())])?;
        draw(&mut chart, [x0, x1, y0, y1])?;
        root.present()?;
    }
    Ok(svg)
}

fn plane_plot(task: &HybridTask, s: &HybridSynthesis, pl: [usize; 2]) -> DynResult<String> {
    let problem = &task.problem;
    let n = task.plant.modes()[0].flow.n();
    let inv = |loc: usize| &task.constants[loc].roots.inv;
    let shown = &s.runs[..s.runs.len().min(SHOWN)];
    // Frame: the nominals, Init and Goal (Unsafe may be far larger; it is clipped).
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for r in shown {
        for nom in &r.nominals {
            for x in &nom.x {
                xs.push(x[pl[0]]);
                ys.push(x[pl[1]]);
            }
        }
    }
    let init = init_box(&problem.init, pl);
    for (x, y) in init
        .iter()
        .copied()
        .chain(set_shadow(&problem.goal, n, pl).unwrap_or_default())
    {
        xs.push(x);
        ys.push(y);
    }
    plane_svg(900, &xs, &ys, pl, init, |chart, [x0, x1, y0, y1]| {
        for (d, color) in std::iter::once((&problem.goal, GOAL_COLOR))
            .chain(problem.unsafe_sets.iter().map(|u| (u, UNSAFE_COLOR)))
        {
            if let Some(poly) = set_shadow(d, n, pl) {
                chart.draw_series([Polygon::new(poly, color.mix(0.25).filled())])?;
            }
        }
        draw_cover(chart, task, s, pl)?;
        // The guard of each edge taken, where its normal lies in the plane.
        for &e in &task.edges {
            for (a, &b) in task.plant.edges()[e]
                .guard
                .a
                .iter()
                .zip(&task.plant.edges()[e].guard.b)
            {
                let off: f64 = (0..n).filter(|i| !pl.contains(i)).map(|i| a[i].abs()).sum();
                let (p, q) = (a[pl[0]], a[pl[1]]);
                if off > 1e-12 || p.hypot(q) == 0.0 {
                    continue;
                }
                let line: Vec<(f64, f64)> = if p.abs() >= q.abs() {
                    vec![((b - q * y0) / p, y0), ((b - q * y1) / p, y1)]
                } else {
                    vec![(x0, (b - p * x0) / q), (x1, (b - p * x1) / q)]
                };
                chart.draw_series(LineSeries::new(line, BLACK.stroke_width(2)))?;
            }
        }
        for (ri, r) in shown.iter().enumerate() {
            for (j, (nom, seg)) in r.nominals.iter().zip(&r.certificate.segments).enumerate() {
                let loc = r.locations[j];
                let color = location_color(loc);
                let rows = seg.rows.clamp(1, nom.x.len());
                // Tubes at evenly spaced samples of the kept rows.
                for t in 0..TUBES {
                    let k = t * (rows - 1) / (TUBES - 1).max(1);
                    let poly = shadow(inv(loc), &nom.x[k], seg.delta, pl);
                    chart.draw_series([Polygon::new(poly, color.mix(0.10).filled())])?;
                }
                let pts: Vec<(f64, f64)> =
                    nom.x[..rows].iter().map(|x| (x[pl[0]], x[pl[1]])).collect();
                chart.draw_series(LineSeries::new(pts, color.stroke_width(2)))?;
                // The next segment's start ball: where the landings must fall.
                if let (Some(next), Some(nseg)) =
                    (r.nominals.get(j + 1), r.certificate.segments.get(j + 1))
                {
                    let nloc = r.locations[j + 1];
                    let mut poly = shadow(inv(nloc), &next.x[0], nseg.delta, pl);
                    poly.push(poly[0]);
                    chart.draw_series(DashedLineSeries::new(
                        poly,
                        5,
                        3,
                        location_color(nloc).stroke_width(2),
                    ))?;
                }
            }
            let x = &r.nominals[0].x[0];
            chart.draw_series([Circle::new(
                (x[pl[0]], x[pl[1]]),
                3,
                trajectory_color(ri).filled(),
            )])?;
        }
        Ok(())
    })
}
