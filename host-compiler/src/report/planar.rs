//! Planar polygons for the report's plots: Sutherland–Hodgman clipping of half-plane sets to the plot's
//! bounding box, ellipse outlines, and the bounding boxes the plots are framed on. Pure 2-D geometry; no
//! drawing and no control theory.

use super::data::{Ellipse2, Shape2};

/// An axis-aligned rectangle [lo, hi] in a plotting plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    pub lo: [f64; 2],
    pub hi: [f64; 2],
}

impl Rect {
    /// The empty rectangle (the identity of [`Rect::include`]).
    pub const EMPTY: Rect = Rect {
        lo: [f64::INFINITY; 2],
        hi: [f64::NEG_INFINITY; 2],
    };

    pub fn new(lo: [f64; 2], hi: [f64; 2]) -> Self {
        Rect { lo, hi }
    }

    /// True when no point has been included.
    pub fn is_empty(&self) -> bool {
        !(self.lo[0] <= self.hi[0] && self.lo[1] <= self.hi[1])
    }

    /// Grows the rectangle to contain `p`; non-finite points are ignored.
    pub fn include(&mut self, p: [f64; 2]) {
        if p[0].is_finite() && p[1].is_finite() {
            self.lo = [self.lo[0].min(p[0]), self.lo[1].min(p[1])];
            self.hi = [self.hi[0].max(p[0]), self.hi[1].max(p[1])];
        }
    }

    pub fn include_all<'a>(&mut self, ps: impl IntoIterator<Item = &'a [f64; 2]>) {
        for p in ps {
            self.include(*p);
        }
    }

    pub fn union(&mut self, other: &Rect) {
        if !other.is_empty() {
            self.include(other.lo);
            self.include(other.hi);
        }
    }

    pub fn width(&self) -> f64 {
        self.hi[0] - self.lo[0]
    }

    pub fn height(&self) -> f64 {
        self.hi[1] - self.lo[1]
    }

    pub fn center(&self) -> [f64; 2] {
        [
            0.5 * (self.lo[0] + self.hi[0]),
            0.5 * (self.lo[1] + self.hi[1]),
        ]
    }

    /// The rectangle grown by `frac` of its larger side on every side, with degenerate (zero-width)
    /// sides opened up so that a plot on it has a non-empty range. An empty rectangle becomes [−1, 1]².
    pub fn padded(&self, frac: f64) -> Rect {
        if self.is_empty() {
            return Rect::new([-1.0, -1.0], [1.0, 1.0]);
        }
        let scale = self.width().max(self.height());
        let scale = if scale > 0.0 {
            scale
        } else {
            // A single point: open a unit-ish window around it.
            self.lo[0].abs().max(self.lo[1].abs()).max(1.0)
        };
        let pad = frac * scale;
        let mut r = Rect::new(
            [self.lo[0] - pad, self.lo[1] - pad],
            [self.hi[0] + pad, self.hi[1] + pad],
        );
        // A zero-width side of a non-degenerate rectangle still gets the padding above.
        for i in 0..2 {
            if r.hi[i] <= r.lo[i] {
                r.lo[i] -= 0.5;
                r.hi[i] += 0.5;
            }
        }
        r
    }

    /// The same centre, sides scaled to the pixel aspect `px_w : px_h`, never shrinking: one data unit
    /// is then the same number of pixels on both axes.
    pub fn with_aspect(&self, px_w: f64, px_h: f64) -> Rect {
        let s = (self.width() / px_w).max(self.height() / px_h);
        let c = self.center();
        let (hw, hh) = (0.5 * s * px_w, 0.5 * s * px_h);
        Rect::new([c[0] - hw, c[1] - hh], [c[0] + hw, c[1] + hh])
    }

    /// The four corners, counter-clockwise from `lo`.
    pub fn corners(&self) -> Vec<[f64; 2]> {
        vec![
            self.lo,
            [self.hi[0], self.lo[1]],
            self.hi,
            [self.lo[0], self.hi[1]],
        ]
    }

    /// True when `p` lies on the boundary of the rectangle (within a relative tolerance).
    fn on_boundary(&self, p: [f64; 2]) -> bool {
        let tol = 1e-9 * self.width().max(self.height()).max(1e-300);
        (p[0] - self.lo[0]).abs() <= tol
            || (p[0] - self.hi[0]).abs() <= tol
            || (p[1] - self.lo[1]).abs() <= tol
            || (p[1] - self.hi[1]).abs() <= tol
    }
}

/// One Sutherland–Hodgman step: the part of the (convex) polygon `poly` with `a · y ≤ b`.
///
/// A half-plane with `a = 0` keeps everything when `b ≥ 0` and nothing otherwise; non-finite data keep
/// nothing. Consecutive duplicate vertices (a cut exactly through a vertex) are dropped, and a result
/// with fewer than three vertices is returned empty.
pub fn clip_polygon_halfplane(poly: &[[f64; 2]], a: [f64; 2], b: f64) -> Vec<[f64; 2]> {
    if !(a[0].is_finite() && a[1].is_finite() && b.is_finite()) {
        return Vec::new();
    }
    if a[0] == 0.0 && a[1] == 0.0 {
        return if b >= 0.0 { poly.to_vec() } else { Vec::new() };
    }
    // Signed violation a·p − b, with points within `tol` of the line counted as inside.
    let scale = poly
        .iter()
        .map(|p| p[0].abs().max(p[1].abs()))
        .fold(b.abs(), f64::max)
        .max(1.0);
    let tol = 1e-12 * scale * a[0].abs().max(a[1].abs());
    let g = |p: [f64; 2]| a[0] * p[0] + a[1] * p[1] - b;
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(poly.len() + 1);
    let push = |q: [f64; 2], out: &mut Vec<[f64; 2]>| {
        if out.last() != Some(&q) {
            out.push(q);
        }
    };
    for i in 0..poly.len() {
        let p = poly[i];
        let q = poly[(i + 1) % poly.len()];
        let (gp, gq) = (g(p), g(q));
        let (p_in, q_in) = (gp <= tol, gq <= tol);
        if p_in {
            push(p, &mut out);
        }
        if p_in != q_in {
            // The edge crosses the line; clamping keeps the point on the edge when an endpoint is
            // inside only by the tolerance.
            let t = (gp / (gp - gq)).clamp(0.0, 1.0);
            push(
                [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])],
                &mut out,
            );
        }
    }
    if out.len() > 1 && out.first() == out.last() {
        out.pop();
    }
    if out.len() < 3 {
        out.clear();
    }
    out
}

/// {y : a_i · y ≤ b_i for all i} ∩ `bounds` as a convex polygon (counter-clockwise), by
/// Sutherland–Hodgman clipping of the box against each half-plane. Empty when the intersection has no
/// interior. Extra entries of the longer of `a` and `b` are ignored.
pub fn clip_halfplanes(a: &[[f64; 2]], b: &[f64], bounds: &Rect) -> Vec<[f64; 2]> {
    if bounds.is_empty() {
        return Vec::new();
    }
    let mut poly = bounds.corners();
    for (ai, &bi) in a.iter().zip(b) {
        poly = clip_polygon_halfplane(&poly, *ai, bi);
        if poly.is_empty() {
            break;
        }
    }
    poly
}

/// The half-plane set's polygon if it is bounded and lies strictly inside `probe` (so clipping did not
/// cut it), else `None`. Used to frame plots on bounded polytopes without letting unbounded ones
/// stretch the view.
pub fn bounded_halfplanes(a: &[[f64; 2]], b: &[f64], probe: &Rect) -> Option<Vec<[f64; 2]>> {
    let poly = clip_halfplanes(a, b, probe);
    if poly.is_empty() || poly.iter().any(|&p| probe.on_boundary(p)) {
        None
    } else {
        Some(poly)
    }
}

/// `k` points on the boundary of the ellipse, center + M·[cos θ, sin θ] for θ = 2πj/k.
pub fn ellipse_points(e: &Ellipse2, k: usize) -> Vec<[f64; 2]> {
    let M = e.M;
    (0..k)
        .map(|j| {
            let th = std::f64::consts::TAU * j as f64 / k as f64;
            let (s, c) = th.sin_cos();
            [
                e.center[0] + M[0][0] * c + M[0][1] * s,
                e.center[1] + M[1][0] * c + M[1][1] * s,
            ]
        })
        .collect()
}

/// The exact axis-aligned bounding box of an ellipse: centre ± the row norms of M.
pub fn ellipse_rect(e: &Ellipse2) -> Rect {
    let rx = e.M[0][0].hypot(e.M[0][1]);
    let ry = e.M[1][0].hypot(e.M[1][1]);
    let mut r = Rect::EMPTY;
    r.include([e.center[0] - rx, e.center[1] - ry]);
    r.include([e.center[0] + rx, e.center[1] + ry]);
    r
}

/// The shape as a polygon to draw, with half-plane sets clipped to `bounds` (ellipses get 96 vertices).
pub fn shape_polygon(shape: &Shape2, bounds: &Rect) -> Vec<[f64; 2]> {
    match shape {
        Shape2::Ellipse(e) => ellipse_points(e, 96),
        Shape2::HalfPlanes { a, b } => clip_halfplanes(a, b, bounds),
        Shape2::Box { lo, hi } => Rect::new(*lo, *hi).corners(),
    }
}

/// The part of the shape that should frame a plot: its bounding box, or for half-plane sets the
/// bounding box of their polygon if it is bounded within `probe` (else empty).
pub fn shape_rect(shape: &Shape2, probe: &Rect) -> Rect {
    let mut r = Rect::EMPTY;
    match shape {
        Shape2::Ellipse(e) => r = ellipse_rect(e),
        Shape2::HalfPlanes { a, b } => {
            if let Some(poly) = bounded_halfplanes(a, b, probe) {
                r.include_all(&poly);
            }
        }
        Shape2::Box { lo, hi } => {
            r.include(*lo);
            r.include(*hi);
        }
    }
    r
}

/// Signed area of a polygon (positive when counter-clockwise), by the shoelace formula.
pub fn polygon_area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    0.5 * (0..n)
        .map(|i| {
            let (p, q) = (poly[i], poly[(i + 1) % n]);
            p[0] * q[1] - q[0] * p[1]
        })
        .sum::<f64>()
}

/// The part of a convex polygon inside the rectangle (Sutherland–Hodgman against its four sides).
pub fn clip_to_rect(poly: &[[f64; 2]], r: &Rect) -> Vec<[f64; 2]> {
    let sides = [
        ([-1.0, 0.0], -r.lo[0]),
        ([1.0, 0.0], r.hi[0]),
        ([0.0, -1.0], -r.lo[1]),
        ([0.0, 1.0], r.hi[1]),
    ];
    let mut out = poly.to_vec();
    for (a, b) in sides {
        if out.is_empty() {
            break;
        }
        out = clip_polygon_halfplane(&out, a, b);
    }
    out
}
