//! Set descriptions shared by task specs and named-sets files: the validated, owned [`SetDesc`]
//! (a shape plus the coordinates it constrains), the validation of one TOML set table, and
//! [`load_named_sets`] for the standalone `[sets.<name>]` files the MTL CLI reads.
//!
//! TOML syntax of a set table (same in `[goal]`, `[[unsafe]]`, `[sets.<name>]`):
//!
//! ```toml
//! kind = "ball"        # center + radius:        ‖y − center‖₂ ≤ radius
//! kind = "ellipsoid"   # center + Q (d×d, PSD):  (y − center)ᵀ Q (y − center) ≤ 1
//!                      #   (or center + radius, which is the same as a ball)
//! kind = "polytope"    # A (k×d) + b (k):        A y ≤ b
//! kind = "box"         # lo + hi (d each):       lo ≤ y ≤ hi
//! coords = ["x1", "x2"]  # optional: which coordinates y are (see below)
//! ```
//!
//! `coords` says what y is: absent or `"state"` — the whole state x; `"output"` — the whole output
//! y = C x of the plant; a list of names `"x1".."xn"` (state coordinates) or `"y1".."yp"` (output
//! coordinates), 1-based as in the text, all of one letter. A set on a list of coordinates is the
//! preimage of the shape under the map selecting them (a projection is just an output map).

use std::ops::Range;

use toml::Spanned;

use super::checks::box_rows;
use super::error::{ErrorKind, SpecError};
use super::raw::{RawSet, RawSetsFile};
use super::validate::{bounded, check_box, matrix, polytope_rows, vector, Dim};
use super::Matrix;
use crate::geometry::{Ball, Ellipsoid, GeometryError, InOutput, Polytope, Region};

/// The shape of a set in its own coordinates y ∈ ℝᵈ. Matrices are row-major.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// {y : ‖y − center‖₂ ≤ radius}, radius ≥ 0.
    Ball { center: Vec<f64>, radius: f64 },
    /// {y : (y − center)ᵀ Q (y − center) ≤ 1}, Q symmetric positive semidefinite (d×d). A singular Q gives
    /// an unbounded (cylindrical) set.
    Ellipsoid { center: Vec<f64>, Q: Matrix },
    /// {y : A y ≤ b}, A is k×d with k ≥ 1.
    Polytope { A: Matrix, b: Vec<f64> },
    /// {y : lo ≤ y ≤ hi}, lo ≤ hi componentwise.
    Box { lo: Vec<f64>, hi: Vec<f64> },
}

impl Shape {
    /// Dimension d of the shape's own space.
    pub fn dim(&self) -> usize {
        match self {
            Shape::Ball { center, .. } | Shape::Ellipsoid { center, .. } => center.len(),
            Shape::Polytope { A, .. } => A.cols,
            Shape::Box { lo, .. } => lo.len(),
        }
    }

    /// The TOML `kind` of this shape.
    pub fn kind_name(&self) -> &'static str {
        match self {
            Shape::Ball { .. } => "ball",
            Shape::Ellipsoid { .. } => "ellipsoid",
            Shape::Polytope { .. } => "polytope",
            Shape::Box { .. } => "box",
        }
    }

    /// Membership of a point of the shape's own space (closed set, no tolerance).
    pub fn contains(&self, y: &[f64]) -> bool {
        if y.len() != self.dim() {
            return false;
        }
        match self {
            Shape::Ball { center, radius } => {
                let r2: f64 = y.iter().zip(center).map(|(a, b)| (a - b) * (a - b)).sum();
                r2 <= radius * radius
            }
            Shape::Ellipsoid { center, Q } => {
                let d: Vec<f64> = y.iter().zip(center).map(|(a, b)| a - b).collect();
                Q.quad_form(&d) <= 1.0
            }
            Shape::Polytope { A, b } => (0..A.rows).all(|i| dot(A.row(i), y) <= b[i]),
            Shape::Box { lo, hi } => y
                .iter()
                .zip(lo.iter().zip(hi))
                .all(|(v, (l, h))| l <= v && v <= h),
        }
    }
}

/// Which coordinates a set's shape constrains.
#[derive(Clone, Debug, PartialEq)]
pub enum Coords {
    /// y = x, the whole state.
    State,
    /// y = (x_{i₁}, …, x_{i_d}): the listed state coordinates, 0-based, in the order given.
    StateIndices(Vec<usize>),
    /// y = C x with C (d×n) the plant's output map, or the rows of it named by a `"y…"` list.
    Output { C: Matrix },
}

/// A validated, owned set: `{x ∈ ℝⁿ : map(x) ∈ shape}`.
#[derive(Clone, Debug, PartialEq)]
pub struct SetDesc {
    pub shape: Shape,
    pub coords: Coords,
}

impl SetDesc {
    /// Dimension of the shape's space (number of constrained coordinates).
    pub fn dim(&self) -> usize {
        self.shape.dim()
    }

    /// The linear map y = M x from state to the shape's coordinates, as a d×n matrix; `None` when it is
    /// the identity (`Coords::State`). Errors if the coordinates do not fit an n-dimensional state.
    pub fn map_matrix(&self, n_state: usize) -> Result<Option<Matrix>, SpecError> {
        match &self.coords {
            Coords::State => {
                if self.dim() != n_state {
                    return Err(SpecError::new(
                        ErrorKind::Dimension,
                        format!(
                            "the set has dimension {} but the state has {n_state} coordinates",
                            self.dim()
                        ),
                    ));
                }
                Ok(None)
            }
            Coords::StateIndices(idx) => {
                if let Some(&bad) = idx.iter().find(|&&i| i >= n_state) {
                    return Err(SpecError::new(
                        ErrorKind::Dimension,
                        format!(
                            "coordinate x{} does not exist: the state has {n_state} coordinates",
                            bad + 1
                        ),
                    ));
                }
                let mut M = Matrix::zeros(idx.len(), n_state);
                for (r, &i) in idx.iter().enumerate() {
                    M.data[r * n_state + i] = 1.0;
                }
                Ok(Some(M))
            }
            Coords::Output { C } => {
                if C.cols != n_state {
                    return Err(SpecError::new(
                        ErrorKind::Dimension,
                        format!(
                            "the output map has {} columns but the state has {n_state} coordinates",
                            C.cols
                        ),
                    ));
                }
                Ok(Some(C.clone()))
            }
        }
    }

    /// The shape's coordinates of a state.
    pub fn project(&self, x: &[f64]) -> Vec<f64> {
        match &self.coords {
            Coords::State => x.to_vec(),
            Coords::StateIndices(idx) => idx
                .iter()
                .map(|&i| x.get(i).copied().unwrap_or(f64::NAN))
                .collect(),
            Coords::Output { C } => C.mul_vec(x),
        }
    }

    /// Membership of a state (closed set, no tolerance).
    pub fn contains(&self, x: &[f64]) -> bool {
        self.shape.contains(&self.project(x))
    }

    /// The set as a geometry [`Region`] on ℝⁿ (n = `n_state`), for distances and depths:
    /// ball → [`Ball`] with P = I; ellipsoid → [`Ellipsoid`]; polytope → [`Polytope`]; box (and a ball of
    /// radius 0) → [`Polytope`] with rows [I; −I]. A set on selected state coordinates or in output
    /// coordinates is wrapped in [`InOutput`] with its map (a selection matrix or rows of C).
    pub fn to_region(&self, n_state: usize) -> Result<Box<dyn Region>, SpecError> {
        let kind = self.shape.kind_name();
        let geo = |e: GeometryError| {
            SpecError::new(
                ErrorKind::BadValue,
                format!("cannot build the {kind} set: {e}"),
            )
        };
        let d = self.dim();
        let shape: Box<dyn Region> = match &self.shape {
            Shape::Ball { center, radius } if *radius > 0.0 => {
                Box::new(Ball::new(center.clone(), Matrix::identity(d).data, *radius).map_err(geo)?)
            }
            Shape::Ball { center, .. } => {
                let (A, b) = box_rows(center, center);
                Box::new(Polytope::new(d, A.data, b).map_err(geo)?)
            }
            Shape::Ellipsoid { center, Q } => {
                Box::new(Ellipsoid::new(center.clone(), Q.data.clone()).map_err(geo)?)
            }
            Shape::Polytope { A, b } => {
                Box::new(Polytope::new(d, A.data.clone(), b.clone()).map_err(geo)?)
            }
            Shape::Box { lo, hi } => {
                let (A, b) = box_rows(lo, hi);
                Box::new(Polytope::new(d, A.data, b).map_err(geo)?)
            }
        };
        match self.map_matrix(n_state)? {
            None => Ok(shape),
            Some(M) => Ok(Box::new(InOutput::new(M.data, M.rows, shape).map_err(geo)?)),
        }
    }
}

/// Where the set's dimension comes from, and what a validated set may refer to.
pub(crate) struct SetCtx<'a> {
    /// Name for messages: `goal`, `unsafe[1]`, `sets.obstacle`.
    pub what: String,
    /// State dimension, when known (always in a task spec).
    pub n_state: Option<usize>,
    /// The plant's output map (p×n); `None` in a named-sets file.
    pub output: Option<&'a Matrix>,
    /// Reject an empty polytope as a bad value (false for Goal, whose emptiness is reported as
    /// "unreachable" by the goal check).
    pub check_empty: bool,
}

const KINDS: &str = "\"ball\", \"ellipsoid\", \"polytope\" or \"box\"";

/// Validate one set table.
pub(crate) fn set_from_raw(raw: &Spanned<RawSet>, ctx: &SetCtx<'_>) -> Result<SetDesc, SpecError> {
    let table = raw.span();
    let r = raw.get_ref();
    let what = ctx.what.as_str();
    let check_empty = ctx.check_empty;
    let kind = r.kind.get_ref().as_str();
    let allowed: &[&str] = match kind {
        "ball" => &["center", "radius"],
        "ellipsoid" => &["center", "Q", "radius"],
        "polytope" => &["A", "b"],
        "box" => &["lo", "hi"],
        other => {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "{what}: unknown set kind `{}`; expected {KINDS}",
                    crate::text::excerpt(other)
                ),
            )
            .at(r.kind.span(), "unknown kind"))
        }
    };
    for (key, span) in present_keys(r) {
        if !allowed.contains(&key) {
            return Err(SpecError::new(
                ErrorKind::UnknownKey,
                format!(
                    "{what}: key `{key}` is not used by a set of kind \"{kind}\" (it takes {})",
                    allowed.join(", ")
                ),
            )
            .at(span, format!("not a key of a {kind}")));
        }
    }

    let coords = coords_from_raw(r, ctx)?;
    let (d, dim_why) = match &coords {
        Coords::State => (ctx.n_state, "the state dimension".to_string()),
        Coords::StateIndices(i) => (
            Some(i.len()),
            format!("it constrains {} coordinates", i.len()),
        ),
        Coords::Output { C } => (
            Some(C.rows),
            format!("it constrains {} output coordinates", C.rows),
        ),
    };
    let mut dim = Dim { n: d, why: dim_why };

    let need = |key: &str| {
        SpecError::new(
            ErrorKind::MissingField,
            format!("{what}: a set of kind \"{kind}\" needs `{key}`"),
        )
        .at(table.clone(), format!("`{key}` missing in this table"))
    };

    let shape = match kind {
        "ball" | "ellipsoid" => {
            let c_raw = r.center.as_ref().ok_or_else(|| need("center"))?;
            let center = vector(c_raw, &format!("{what}.center"), &mut dim)?;
            match (&r.Q, &r.radius) {
                (Some(_), Some(rad)) => {
                    return Err(SpecError::new(
                        ErrorKind::BadValue,
                        format!("{what}: give either `Q` or `radius`, not both"),
                    )
                    .at(rad.span(), "remove this or `Q`"))
                }
                (None, Some(rad)) => Shape::Ball {
                    center,
                    radius: radius(rad, what)?,
                },
                (Some(q), None) if kind == "ellipsoid" => {
                    let Q = matrix(q, &format!("{what}.Q"), &mut dim.clone(), &mut dim)?;
                    super::validate::check_psd(&Q, q, &format!("{what}.Q"))?;
                    if Q.data.iter().all(|v| *v == 0.0) {
                        return Err(SpecError::new(
                            ErrorKind::BadValue,
                            format!("{what}.Q is zero, so the set would be all of ℝ^{}", Q.rows),
                        )
                        .at(q.span(), "zero shape matrix"));
                    }
                    Shape::Ellipsoid { center, Q }
                }
                _ => {
                    return Err(need(if kind == "ball" {
                        "radius"
                    } else {
                        "Q` or `radius"
                    }))
                }
            }
        }
        "polytope" => {
            let a_raw = r.A.as_ref().ok_or_else(|| need("A"))?;
            let b_raw = r.b.as_ref().ok_or_else(|| need("b"))?;
            let mut rows = Dim {
                n: None,
                why: format!("{what}.b has one entry per row of A"),
            };
            polytope_rows(a_raw, &format!("{what}.A"))?;
            let A = matrix(a_raw, &format!("{what}.A"), &mut rows, &mut dim)?;
            let b = vector(b_raw, &format!("{what}.b"), &mut rows)?;
            if A.data.iter().all(|v| *v == 0.0) {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!(
                        "{what}.A is zero: the polytope would be all of ℝ^{} or empty",
                        A.cols
                    ),
                )
                .at(a_raw.span(), "every row is zero"));
            }
            if check_empty && super::checks::inscribed(&A, &b) == super::checks::Inscribed::Empty {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!("{what}: the inequalities A y ≤ b have no common solution, so the set is empty"),
                )
                .at(table.clone(), "this polytope is empty"));
            }
            Shape::Polytope { A, b }
        }
        "box" => {
            let lo_raw = r.lo.as_ref().ok_or_else(|| need("lo"))?;
            let hi_raw = r.hi.as_ref().ok_or_else(|| need("hi"))?;
            let lo = vector(lo_raw, &format!("{what}.lo"), &mut dim)?;
            let hi = vector(hi_raw, &format!("{what}.hi"), &mut dim)?;
            check_box(&lo, &hi, lo_raw, hi_raw, what)?;
            Shape::Box { lo, hi }
        }
        _ => unreachable!("kind checked above"),
    };
    Ok(SetDesc { shape, coords })
}

fn radius(rad: &Spanned<f64>, what: &str) -> Result<f64, SpecError> {
    let v = bounded(*rad.get_ref(), rad.span(), &format!("{what}.radius"))?;
    if v < 0.0 {
        return Err(SpecError::new(
            ErrorKind::BadValue,
            format!("{what}.radius is {v}; it must be ≥ 0"),
        )
        .at(rad.span(), "negative radius"));
    }
    Ok(v)
}

/// The keys present in a set table with the span of their values.
fn present_keys(r: &RawSet) -> Vec<(&'static str, Range<usize>)> {
    let mut v = Vec::new();
    if let Some(x) = &r.center {
        v.push(("center", x.span()));
    }
    if let Some(x) = &r.Q {
        v.push(("Q", x.span()));
    }
    if let Some(x) = &r.radius {
        v.push(("radius", x.span()));
    }
    if let Some(x) = &r.A {
        v.push(("A", x.span()));
    }
    if let Some(x) = &r.b {
        v.push(("b", x.span()));
    }
    if let Some(x) = &r.lo {
        v.push(("lo", x.span()));
    }
    if let Some(x) = &r.hi {
        v.push(("hi", x.span()));
    }
    v.sort_by_key(|(_, s)| s.start);
    v
}

/// Resolve `coords`.
fn coords_from_raw(r: &RawSet, ctx: &SetCtx<'_>) -> Result<Coords, SpecError> {
    let what = ctx.what.as_str();
    let Some(c) = &r.coords else {
        return Ok(Coords::State);
    };
    let span = c.span();
    let bad = |msg: String, label: &str| {
        SpecError::new(ErrorKind::BadValue, msg).at(span.clone(), label.to_string())
    };
    match c.get_ref() {
        toml::Value::String(s) if s == "state" => Ok(Coords::State),
        toml::Value::String(s) if s == "output" => match ctx.output {
            Some(C) => {
                full_row_rank(C, what, span)?;
                Ok(Coords::Output { C: C.clone() })
            }
            None => Err(bad(
                format!("{what}: coords = \"output\" needs a plant output map, and this file has no plant"),
                "no output map here",
            )),
        },
        toml::Value::String(s) => Err(bad(
            format!("{what}: coords = \"{s}\" is not understood; use \"state\", \"output\" or a list like [\"x1\", \"x2\"]"),
            "unknown coords",
        )),
        toml::Value::Array(items) => {
            if items.is_empty() {
                return Err(bad(format!("{what}: coords is an empty list"), "empty"));
            }
            let mut letter = None;
            let mut idx = Vec::with_capacity(items.len());
            for it in items {
                let Some(name) = it.as_str() else {
                    return Err(SpecError::new(
                        ErrorKind::WrongType,
                        format!("{what}: coords entries must be strings like \"x1\", found {}", it.type_str()),
                    )
                    .at(span.clone(), "expected coordinate names"));
                };
                let (l, rest) = name.split_at(name.chars().next().map_or(0, char::len_utf8));
                let k: Option<usize> = rest.parse().ok().filter(|&k| k >= 1 && !rest.starts_with('+'));
                let (l, k) = match (l, k) {
                    ("x", Some(k)) | ("y", Some(k)) => (l, k),
                    _ => {
                        return Err(bad(
                            format!("{what}: `{name}` is not a coordinate name; use \"x1\"…\"xn\" or \"y1\"…\"yp\" (1-based)"),
                            "bad coordinate name",
                        ))
                    }
                };
                if *letter.get_or_insert(l) != l {
                    return Err(bad(
                        format!("{what}: coords mixes state (x…) and output (y…) coordinates"),
                        "mixed x and y",
                    ));
                }
                if idx.contains(&(k - 1)) {
                    return Err(bad(format!("{what}: coordinate `{name}` is listed twice"), "repeated coordinate"));
                }
                idx.push(k - 1);
            }
            if letter == Some("x") {
                if let Some(n) = ctx.n_state {
                    if let Some(&i) = idx.iter().find(|&&i| i >= n) {
                        return Err(SpecError::new(
                            ErrorKind::Dimension,
                            format!("{what}: coordinate x{} does not exist; the state has {n} coordinates", i + 1),
                        )
                        .at(span, "out of range"));
                    }
                }
                Ok(Coords::StateIndices(idx))
            } else {
                let Some(C) = ctx.output else {
                    return Err(bad(
                        format!("{what}: output coordinates (y…) need a plant output map, and this file has no plant"),
                        "no output map here",
                    ));
                };
                if let Some(&i) = idx.iter().find(|&&i| i >= C.rows) {
                    return Err(SpecError::new(
                        ErrorKind::Dimension,
                        format!("{what}: coordinate y{} does not exist; the output has {} coordinates", i + 1, C.rows),
                    )
                    .at(span, "out of range"));
                }
                let mut sel = Matrix::zeros(idx.len(), C.cols);
                for (r, &i) in idx.iter().enumerate() {
                    sel.data[r * C.cols..(r + 1) * C.cols].copy_from_slice(C.row(i));
                }
                full_row_rank(&sel, what, span)?;
                Ok(Coords::Output { C: sel })
            }
        }
        other => Err(SpecError::new(
            ErrorKind::WrongType,
            format!("{what}: coords must be a string or a list of coordinate names, found {}", other.type_str()),
        )
        .at(span, "wrong type")),
    }
}

/// A set in output coordinates needs the rows of C it uses to be linearly independent (so that the set's
/// coordinates can vary independently); rank decided on the eigenvalues of C Cᵀ, relative 1e-12.
fn full_row_rank(C: &Matrix, what: &str, span: Range<usize>) -> Result<(), SpecError> {
    let mut G = Matrix::zeros(C.rows, C.rows);
    for i in 0..C.rows {
        for j in 0..C.rows {
            G.data[i * C.rows + j] = dot(C.row(i), C.row(j));
        }
    }
    let lam = super::checks::sym_eigenvalues(&G).unwrap_or_default();
    let top = lam.iter().fold(0.0f64, |a, v| a.max(*v));
    let rank = lam.iter().filter(|&&v| v > 1e-12 * top).count();
    if top <= 0.0 || rank < C.rows {
        return Err(SpecError::new(
            ErrorKind::BadValue,
            format!(
                "{what}: the output rows it uses are linearly dependent (rank {rank} of {}); a set in output \
                 coordinates needs independent rows of plant.C",
                C.rows
            ),
        )
        .at(span, "dependent output rows"));
    }
    Ok(())
}

/// Load a standalone named-sets file: `[sets.<name>]` tables in the set syntax of this module, in file
/// order. There is no plant, so `coords` may be `"state"` (the default) or a list of `"x…"` names; the
/// state dimension is checked later by [`SetDesc::to_region`] / [`SetDesc::map_matrix`].
pub fn load_named_sets(
    path: impl AsRef<std::path::Path>,
) -> Result<Vec<(String, SetDesc)>, SpecError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|e| SpecError::io(path, e))?;
    parse_named_sets(&text, &path.display().to_string())
}

/// [`load_named_sets`] on text; `name` is the file name used in diagnostics.
pub fn parse_named_sets(src: &str, name: &str) -> Result<Vec<(String, SetDesc)>, SpecError> {
    let go = || -> Result<Vec<(String, SetDesc)>, SpecError> {
        let raw: RawSetsFile = toml::from_str(src).map_err(|e| SpecError::from_toml(&e))?;
        named_sets(raw.sets.0, None, None)
    };
    go().map_err(|e| e.with_source(name, src))
}

/// Validate `[sets.<name>]` tables (file order restored from spans).
pub(crate) fn named_sets(
    mut pairs: Vec<(Spanned<String>, Spanned<RawSet>)>,
    n_state: Option<usize>,
    output: Option<&Matrix>,
) -> Result<Vec<(String, SetDesc)>, SpecError> {
    pairs.sort_by_key(|(k, _)| k.span().start);
    let mut out = Vec::with_capacity(pairs.len());
    for (key, raw) in &pairs {
        let name = key.get_ref();
        let ok_ident = name
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !ok_ident {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!("set name `{name}` must be an identifier (letters, digits, `_`, not starting with a digit) so formulas can name it"),
            )
            .at(key.span(), "bad set name"));
        }
        let ctx = SetCtx {
            what: format!("sets.{name}"),
            n_state,
            output,
            check_empty: true,
        };
        out.push((name.clone(), set_from_raw(raw, &ctx)?));
    }
    Ok(out)
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
