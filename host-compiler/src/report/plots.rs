//! The report's three SVG plots, drawn with plotters' SVG backend into strings: the workspace (sets,
//! nominal paths, robust tubes), the Init plane (certified balls, uncovered samples) and input use
//! against time. Also the colour palette and sample choices the HTML legends share.

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::data::{ReportData, Shape2, TrajectoryReport};
use super::format::{escape, num};
use super::planar::{clip_to_rect, ellipse_points, ellipse_rect, shape_polygon, shape_rect, Rect};

pub(super) type Chart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;
pub(super) type DynResult<T> = Result<T, Box<dyn std::error::Error>>;

/// Tableau-10: distinguishable, and readable on white.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];
/// Colours of the sets (also used by the HTML legends).
pub const INIT_COLOR: RGBColor = RGBColor(110, 110, 110);
pub const GOAL_COLOR: RGBColor = RGBColor(46, 160, 67);
/// The terminal law's invariant ellipsoid (a darker green, inside Goal).
pub const TERMINAL_COLOR: RGBColor = RGBColor(20, 90, 40);
pub const UNSAFE_COLOR: RGBColor = RGBColor(207, 34, 46);
pub const BALL_COLOR: RGBColor = RGBColor(31, 119, 180);

/// Width of the equal-aspect plots' canvas, in pixels.
pub(super) const PLANE_WIDTH: u32 = 600;
/// Up to this many trajectories, plots and legends show each one individually.
pub const FEW_TRAJECTORIES: usize = 12;
/// Most tube ellipses drawn per trajectory (plus the first, the last and the one at t*).
pub const MAX_TUBES: usize = 24;
/// Most tube ellipses drawn over all trajectories together, so that large runs keep the page small.
const MAX_TUBES_TOTAL: usize = 800;

/// Tube ellipses drawn per trajectory when there are `trajectories` of them: [`MAX_TUBES`], fewer
/// when many trajectories share the [`MAX_TUBES_TOTAL`] budget (never fewer than 2).
pub fn tubes_per_trajectory(trajectories: usize) -> usize {
    (MAX_TUBES_TOTAL / trajectories.max(1)).clamp(2, MAX_TUBES)
}

/// Vertices per drawn ellipse when `count` ellipses are drawn: smooth for few, coarser for many.
fn ellipse_vertices(count: usize) -> usize {
    match count {
        0..=MANY_ELLIPSES => 72,
        301..=1000 => 40,
        _ => 24,
    }
}

/// Beyond this many ellipses in one plot, translucent ones are filled without outlines.
const MANY_ELLIPSES: usize = 300;

/// The colour of the `rank`-th trajectory (rank in the id-sorted order).
/// The range of `v` padded by `frac` of its width on each side ((−1, 1) for no finite value).
pub(super) fn padded_span(v: &[f64], frac: f64) -> (f64, f64) {
    let (a, b) = v
        .iter()
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if !a.is_finite() {
        return (-1.0, 1.0);
    }
    let p = frac * (b - a).max(1e-9);
    (a - p, b + p)
}

pub fn trajectory_color(rank: usize) -> RGBColor {
    PALETTE[rank % PALETTE.len()]
}

/// The colour of the `r`-th route of the global search.
pub fn route_color(r: usize) -> RGBColor {
    PALETTE[r % PALETTE.len()]
}

/// A trajectory that came from no route, where the report has routes.
pub const NO_ROUTE_COLOR: RGBColor = RGBColor(90, 90, 90);

/// The colour of trajectory `t` (rank `rank` in the id-sorted order): its route's when the report has
/// routes (so a plot shows which route each trajectory came from), else its rank's.
pub fn color_of(data: &ReportData, rank: usize, t: &TrajectoryReport) -> RGBColor {
    if data.routes.is_empty() {
        trajectory_color(rank)
    } else {
        t.route.map_or(NO_ROUTE_COLOR, route_color)
    }
}

/// `#rrggbb` of a colour, for CSS.
pub fn css_color(c: RGBColor) -> String {
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

/// Trajectories sorted by id; the position in this order is the colour rank.
pub fn sorted_trajectories(data: &ReportData) -> Vec<&TrajectoryReport> {
    let mut ts: Vec<&TrajectoryReport> = data.trajectories.iter().collect();
    ts.sort_by_key(|t| t.id);
    ts
}

/// Index of the sample closest to t* among the first `len` samples (`None` when there are none).
pub fn t_star_index(t: &TrajectoryReport, len: usize) -> Option<usize> {
    let len = len.min(t.times.len());
    (0..len).min_by(|&i, &j| {
        let (di, dj) = ((t.times[i] - t.t_star).abs(), (t.times[j] - t.t_star).abs());
        di.partial_cmp(&dj).unwrap_or(std::cmp::Ordering::Equal)
    })
}

/// Which of `len` tube samples to draw: every k-th so that at most `max` are chosen, plus the first,
/// the last and `extra` (the sample at t*). Sorted, without duplicates.
pub fn tube_indices(len: usize, extra: Option<usize>, max: usize) -> Vec<usize> {
    if len == 0 {
        return Vec::new();
    }
    let k = len.div_ceil(max.max(1)).max(1);
    let mut idx: Vec<usize> = (0..len).step_by(k).collect();
    idx.push(len - 1);
    if let Some(e) = extra.filter(|&e| e < len) {
        idx.push(e);
    }
    idx.sort_unstable();
    idx.dedup();
    idx
}

/// The measure the input bound applies to, read from its label: the text before the comparison, without
/// a trailing remark in parentheses ("‖u − u_c‖₂ ≤ 1" → "‖u − u_c‖₂", "max_i |u_i| (box bound)" →
/// "max_i |u_i|"); "input magnitude" when nothing is left. `u_nominal` and `u_worst` are already
/// measured so.
pub fn input_measure(label: &str) -> String {
    let cut = ["≤", "<", "="]
        .iter()
        .filter_map(|c| label.find(c))
        .min()
        .unwrap_or(label.len());
    let mut m = label[..cut].trim();
    if m.ends_with(')') {
        if let Some(i) = m.rfind(" (") {
            m = m[..i].trim_end();
        }
    }
    if m.is_empty() {
        "input magnitude".into()
    } else {
        m.into()
    }
}

/// An SVG string, or an HTML note saying why the plot could not be drawn.
pub(super) fn svg_or_note(r: DynResult<String>) -> String {
    match r {
        Ok(s) => s,
        Err(e) => format!(
            "<p class=\"note\">Plot could not be drawn: {}</p>",
            escape(&e.to_string())
        ),
    }
}

fn to_coords(ps: &[[f64; 2]]) -> Vec<(f64, f64)> {
    ps.iter().map(|p| (p[0], p[1])).collect()
}

pub(super) fn closed(ps: &[[f64; 2]]) -> Vec<(f64, f64)> {
    let mut v = to_coords(ps);
    if let Some(&f) = v.first() {
        v.push(f);
    }
    v
}

pub(super) fn finite2(p: &[f64; 2]) -> bool {
    p[0].is_finite() && p[1].is_finite()
}

/// Axis tick label: few digits, so ticks stay short.
pub(super) fn tick(v: &f64) -> String {
    if v.abs() < 1e-12 {
        "0".into()
    } else {
        super::format::sig(*v, 3)
    }
}

/// Canvas height for an equal-aspect plot of `view` on a `PLANE_WIDTH`-wide canvas.
pub(super) fn plane_height(view: &Rect) -> u32 {
    let plot_w = (PLANE_WIDTH - 90) as f64;
    let ratio = (view.height() / view.width()).clamp(0.45, 1.25);
    (plot_w * ratio) as u32 + 70
}

/// A chart on `root` showing at least `view` with one data unit equally long on both axes.
pub(super) fn equal_aspect_chart<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    view: Rect,
    labels: &[String; 2],
) -> DynResult<(Chart<'a, 'b>, Rect)> {
    let builder = |v: Rect| {
        ChartBuilder::on(root)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(v.lo[0]..v.hi[0], v.lo[1]..v.hi[1])
    };
    // Building does not draw: measure the plotting area first, then fix the ranges.
    let (w, h) = builder(view)?.plotting_area().dim_in_pixel();
    let view = view.with_aspect(w.max(1) as f64, h.max(1) as f64);
    let mut chart = builder(view)?;
    chart
        .configure_mesh()
        .x_desc(labels[0].as_str())
        .y_desc(labels[1].as_str())
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .light_line_style(RGBColor(240, 240, 240))
        .bold_line_style(RGBColor(215, 215, 215))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .draw()?;
    Ok((chart, view))
}

/// Fills and outlines a polygon, clipped to the view.
pub(super) fn draw_region(
    chart: &mut Chart,
    poly: &[[f64; 2]],
    view: &Rect,
    color: RGBColor,
    fill: f64,
    line: f64,
) -> DynResult<()> {
    let poly: Vec<[f64; 2]> = poly.iter().copied().filter(finite2).collect();
    let poly = clip_to_rect(&poly, view);
    if poly.is_empty() {
        return Ok(());
    }
    if fill > 0.0 {
        chart.draw_series(std::iter::once(Polygon::new(
            to_coords(&poly),
            color.mix(fill).filled(),
        )))?;
    }
    if line > 0.0 {
        chart.draw_series(std::iter::once(PathElement::new(
            closed(&poly),
            color.mix(line).stroke_width(1),
        )))?;
    }
    Ok(())
}

/// The view of the workspace plot: Init, Goal, bounded Unsafe parts, paths and the drawn tubes.
pub(super) fn workspace_view(data: &ReportData) -> Rect {
    let mut core = Rect::EMPTY;
    for t in &data.trajectories {
        core.include_all(&t.path);
        for e in &t.tube {
            core.union(&ellipse_rect(e));
        }
    }
    for s in data.init_plane.iter().chain(&data.goal_plane) {
        if !matches!(s, Shape2::HalfPlanes { .. }) {
            core.union(&shape_rect(s, &Rect::EMPTY));
        }
    }
    // Half-plane sets count when bounded within a generous probe around everything else.
    let c = core.padded(0.0);
    let size = c.width().max(c.height()).max(1.0);
    let probe = Rect::new(
        [c.lo[0] - 100.0 * size, c.lo[1] - 100.0 * size],
        [c.hi[0] + 100.0 * size, c.hi[1] + 100.0 * size],
    );
    for s in data
        .init_plane
        .iter()
        .chain(&data.goal_plane)
        .chain(&data.unsafe_plane)
    {
        if matches!(s, Shape2::HalfPlanes { .. }) {
            core.union(&shape_rect(s, &probe));
        }
    }
    core.padded(0.06)
}

/// Workspace plot (plane_labels axes, equal aspect): Init (grey), Goal (green), Unsafe (red), each
/// trajectory's nominal path with every k-th tube ellipse (translucent), its start point (●) and its
/// tube at t* (bold outline).
pub fn workspace_svg(data: &ReportData) -> String {
    svg_or_note(draw_workspace(data))
}

fn draw_workspace(data: &ReportData) -> DynResult<String> {
    let view = workspace_view(data);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (PLANE_WIDTH, plane_height(&view)))
            .into_drawing_area();
        root.fill(&WHITE)?;
        let (mut chart, view) = equal_aspect_chart(&root, view, &data.plane_labels)?;
        if let Some(init) = &data.init_plane {
            draw_region(
                &mut chart,
                &shape_polygon(init, &view),
                &view,
                INIT_COLOR,
                0.18,
                0.9,
            )?;
        }
        for s in &data.unsafe_plane {
            draw_region(
                &mut chart,
                &shape_polygon(s, &view),
                &view,
                UNSAFE_COLOR,
                0.28,
                0.9,
            )?;
        }
        for s in &data.goal_plane {
            draw_region(
                &mut chart,
                &shape_polygon(s, &view),
                &view,
                GOAL_COLOR,
                0.25,
                0.9,
            )?;
        }
        // The terminal law's invariant ellipsoid, darker, inside Goal.
        if let Some(e) = data.terminal.as_ref().and_then(|t| t.ellipse.as_ref()) {
            draw_region(
                &mut chart,
                &ellipse_points(e, 96),
                &view,
                TERMINAL_COLOR,
                0.35,
                1.0,
            )?;
        }
        let ts = sorted_trajectories(data);
        let per = tubes_per_trajectory(ts.len());
        let drawn = ts.len() * (per + 3);
        let (k, outline) = (
            ellipse_vertices(drawn),
            if drawn > MANY_ELLIPSES { 0.0 } else { 0.35 },
        );
        for (rank, t) in ts.iter().enumerate() {
            let color = color_of(data, rank, t);
            let star = t_star_index(t, t.tube.len());
            for i in tube_indices(t.tube.len(), star, per) {
                draw_region(
                    &mut chart,
                    &ellipse_points(&t.tube[i], k),
                    &view,
                    color,
                    0.07,
                    outline,
                )?;
            }
            let path: Vec<(f64, f64)> = t
                .path
                .iter()
                .filter(|p| finite2(p))
                .map(|p| (p[0], p[1]))
                .collect();
            chart.draw_series(LineSeries::new(path, color.stroke_width(2)))?;
        }
        draw_routes(&mut chart, data)?;
        // Markers last, so paths never hide them; small and without rings when there are many.
        let few = ts.len() <= FEW_TRAJECTORIES;
        for (rank, t) in ts.iter().enumerate() {
            let color = color_of(data, rank, t);
            if let Some(i) = t_star_index(t, t.tube.len()) {
                let poly = clip_to_rect(&ellipse_points(&t.tube[i], 72), &view);
                if !poly.is_empty() {
                    chart.draw_series(std::iter::once(PathElement::new(
                        closed(&poly),
                        color.stroke_width(3),
                    )))?;
                }
            }
            if let Some(p) = t.path.first().filter(|p| finite2(p)) {
                if few {
                    chart.draw_series(std::iter::once(Circle::new(
                        (p[0], p[1]),
                        5,
                        color.filled(),
                    )))?;
                    chart.draw_series(std::iter::once(Circle::new(
                        (p[0], p[1]),
                        5,
                        BLACK.stroke_width(1),
                    )))?;
                } else {
                    chart.draw_series(std::iter::once(Circle::new(
                        (p[0], p[1]),
                        3,
                        color.filled(),
                    )))?;
                }
            }
        }
        root.present()?;
    }
    Ok(svg)
}

/// The routes of the global search over the paths: each dashed in its colour, named at a point along
/// it (a third of its way, so labels of routes from one seed part).
fn draw_routes(chart: &mut Chart, data: &ReportData) -> DynResult<()> {
    for (r, route) in data.routes.iter().enumerate() {
        let pts: Vec<(f64, f64)> = route
            .points
            .iter()
            .filter(|p| finite2(p))
            .map(|p| (p[0], p[1]))
            .collect();
        if pts.len() < 2 {
            continue;
        }
        let color = route_color(r);
        chart.draw_series(std::iter::once(PathElement::new(
            pts.clone(),
            WHITE.mix(0.8).stroke_width(5),
        )))?;
        chart.draw_series(DashedLineSeries::new(
            pts.clone(),
            9,
            5,
            color.stroke_width(3),
        ))?;
        let at = pts[(pts.len() / 3).min(pts.len() - 1)];
        chart.draw_series(std::iter::once(Text::new(
            route.label.clone(),
            at,
            ("sans-serif", 14).into_font().color(&color),
        )))?;
    }
    Ok(())
}

/// Init-plane plot (init_labels axes, equal aspect): the Init box, the certified balls' cross-sections
/// (translucent blue) and the uncovered samples (red ×).
pub fn init_plane_svg(data: &ReportData) -> String {
    svg_or_note(draw_init_plane(data))
}

fn draw_init_plane(data: &ReportData) -> DynResult<String> {
    let mut frame = shape_rect(&data.init_box, &Rect::new([-1e6; 2], [1e6; 2]));
    if frame.is_empty() {
        for b in &data.balls {
            frame.union(&ellipse_rect(b));
        }
    }
    frame.include_all(&data.uncovered);
    let view = frame.padded(0.08);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (PLANE_WIDTH, plane_height(&view)))
            .into_drawing_area();
        root.fill(&WHITE)?;
        let (mut chart, view) = equal_aspect_chart(&root, view, &data.init_labels)?;
        let k = ellipse_vertices(data.balls.len());
        let outline = if data.balls.len() > MANY_ELLIPSES {
            0.0
        } else {
            0.55
        };
        for b in &data.balls {
            draw_region(
                &mut chart,
                &ellipse_points(b, k),
                &view,
                BALL_COLOR,
                0.16,
                outline,
            )?;
        }
        // Init on top of the balls, as an outline, so its edges stay visible.
        let init = clip_to_rect(&shape_polygon(&data.init_box, &view), &view);
        if !init.is_empty() {
            chart.draw_series(std::iter::once(PathElement::new(
                closed(&init),
                BLACK.stroke_width(2),
            )))?;
        }
        let size = if data.uncovered.len() > 500 { 3 } else { 5 };
        chart.draw_series(
            data.uncovered
                .iter()
                .filter(|p| finite2(p))
                .map(|p| Cross::new((p[0], p[1]), size, UNSAFE_COLOR.stroke_width(2))),
        )?;
        root.present()?;
    }
    Ok(svg)
}

/// Points (t, value) of a held signal, as drawn.
type Steps = Vec<(f64, f64)>;

/// (t, magnitude) steps of a zero-order-hold signal: value `v[k]` held on [t_k, t_k + period).
fn steps(t: &TrajectoryReport, v: &[f64], period: f64) -> Steps {
    let time = |k: usize| t.times.get(k).copied().unwrap_or(k as f64 * period);
    let mut out = Vec::with_capacity(2 * v.len());
    for (k, &x) in v.iter().enumerate() {
        if !x.is_finite() {
            continue;
        }
        let t0 = time(k);
        let t1 = t.times.get(k + 1).copied().unwrap_or(t0 + period);
        out.push((t0, x));
        out.push((t1, x));
    }
    out
}

/// Input plot: per trajectory the nominal ũ(κ) (`u_nominal`, solid) and the tube's worst case (`u_worst`,
/// dashed), both already measured as the bound measures them, as held steps against time, with the bound
/// as a red horizontal line. With more than [`FEW_TRAJECTORIES`] trajectories the worst case is drawn
/// once, as the maximum over all tubes (black dashed), and the nominal curves thinner.
pub fn input_svg(data: &ReportData) -> String {
    svg_or_note(draw_input(data))
}

fn draw_input(data: &ReportData) -> DynResult<String> {
    let ts = sorted_trajectories(data);
    let envelope = ts.len() > FEW_TRAJECTORIES;
    let mut series: Vec<(Steps, Steps)> = ts
        .iter()
        .map(|t| {
            let worst = if envelope {
                Vec::new()
            } else {
                steps(t, &t.u_worst, data.period)
            };
            (steps(t, &t.u_nominal, data.period), worst)
        })
        .collect();
    // Many trajectories: one worst-case curve, the maximum over all tubes at each step.
    let mut worst_envelope = Vec::new();
    if let Some(longest) = ts
        .iter()
        .filter(|_| envelope)
        .max_by_key(|t| t.u_worst.len())
    {
        let max_at = |k: usize| {
            ts.iter()
                .filter_map(|t| t.u_worst.get(k))
                .filter(|x| x.is_finite())
                .fold(f64::NEG_INFINITY, |m, &x| m.max(x))
        };
        let env: Vec<f64> = (0..longest.u_worst.len()).map(max_at).collect();
        worst_envelope = steps(longest, &env, data.period);
    }
    let all = series
        .iter()
        .flat_map(|(a, b)| a.iter().chain(b))
        .chain(&worst_envelope);
    let (mut t_max, mut y_max) = (0.0f64, 0.0f64);
    for &(t, y) in all {
        t_max = t_max.max(t);
        y_max = y_max.max(y);
    }
    let bound = data.input_bound.is_finite().then_some(data.input_bound);
    if let Some(b) = bound {
        y_max = y_max.max(b);
    }
    if t_max <= 0.0 {
        t_max = if data.horizon.is_finite() && data.horizon > 0.0 {
            data.horizon
        } else {
            1.0
        };
    }
    if y_max <= 0.0 {
        y_max = 1.0;
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 340)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_max, 0.0..1.1 * y_max)?;
        let measure = input_measure(&data.input_bound_label);
        let y_desc = match bound {
            Some(b) => format!("{measure}  (bound {})", num(b)),
            None => measure,
        };
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .y_desc(y_desc)
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(215, 215, 215))
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 15))
            .draw()?;
        if let Some(b) = bound {
            chart.draw_series(LineSeries::new(
                [(0.0, b), (t_max, b)],
                UNSAFE_COLOR.stroke_width(2),
            ))?;
        }
        for (rank, (nominal, worst)) in series.drain(..).enumerate() {
            let color = color_of(data, rank, ts[rank]);
            if envelope {
                chart.draw_series(LineSeries::new(nominal, color.mix(0.6).stroke_width(1)))?;
            } else {
                chart.draw_series(DashedLineSeries::new(worst, 6, 4, color.stroke_width(1)))?;
                chart.draw_series(LineSeries::new(nominal, color.stroke_width(2)))?;
            }
        }
        if !worst_envelope.is_empty() {
            chart.draw_series(DashedLineSeries::new(
                worst_envelope,
                6,
                4,
                BLACK.stroke_width(2),
            ))?;
        }
        root.present()?;
    }
    Ok(svg)
}

/// Short description of a set for legends and tables.
pub fn shape_summary(s: &Shape2) -> String {
    match s {
        Shape2::Ellipse(e) => format!(
            "ellipse centred at [{}, {}]",
            num(e.center[0]),
            num(e.center[1])
        ),
        Shape2::HalfPlanes { a, .. } => format!("{} half-plane(s)", a.len()),
        Shape2::Box { lo, hi } => {
            format!(
                "box [{}, {}] × [{}, {}]",
                num(lo[0]),
                num(hi[0]),
                num(lo[1]),
                num(hi[1])
            )
        }
    }
}
