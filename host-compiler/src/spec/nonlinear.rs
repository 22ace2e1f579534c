//! A nonlinear plant written in the spec as expressions (§3.1.2): the input-affine system with outputs
//! ẋ = f(x) + g(x)u, y = h(x) of (3.16), read from a `[plant]` table with a `class`, and the checks of
//! Def 3.5 over Init (a uniform vector relative degree and a nonsingular decoupling matrix Γ, (3.18)–
//! (3.19)), each refusal naming the equation and the point:
//!
//! ```toml
//! [plant]
//! class = "feedback_linearizable"
//! time = "continuous"                     # the only time domain of this class
//! period = 0.01                           # sample period of the controller, s
//! states = ["X", "Xd", "Y", "Yd", "th", "thd"]
//! inputs = ["F1", "F2"]
//! params = { aI = 1.0, bI = 1.0 }         # optional named numbers
//! f = ["Xd", "1 - X + 0.1*Xd", ...]       # n expressions over states and params
//! g = [["0", "0"], ["-sin(th)", "cos(th)"], ...]   # n rows of m expressions
//! h = ["X", "Y"]                          # m outputs, linear in the state (for now)
//! region = { lo = [...], hi = [...] }     # optional: the operating region, a box over the state
//! ```
//!
//! Expressions use `+ - * / ^` (integer powers), parentheses, numbers, `pi` and `sin cos tan exp log sqrt
//! abs atan tanh atan2` (`crate::expr`, whose limits bound every expression). A parse error
//! points at the line and column inside the string.
//!
//! What is checked, in order: the class and time domain; dimensions (n ≤ 12, m ≤ 6, as many outputs as
//! inputs); names (identifiers, distinct, none a function or `pi`); every expression parses and f, g, h
//! use no input; the relative degree at the centre of Init, and that the terms (3.18) that vanish there
//! vanish identically (so it is uniform over Init); f, g, h finite and Γ nonsingular at sample points of
//! Init (the centre, the corners of its free coordinates when there are at most 64, and 64 seeded random
//! points); and Γ nonsingular over all of Init, proved by interval enclosures of Γ on a bisection of Init
//! (of the states Γ depends on) into at most [`MAX_GAMMA_BOXES`] boxes (`expr::interval::certainly_regular`).
//!
//! **The operating region.** A plant whose law depends on the linearised coordinates ξ (a pendulum's
//! α = (g/l) sin θ) can only be bounded over a known range of ξ, and the certified tube's range is not
//! known when the task is built. `plant.region` declares that range: a box over the plant's state that
//! must contain Init (a refusal names the state and a point of Init outside it). The checks above then
//! run over the region instead of Init (Γ nonsingular over all of it), `model::feedback_linearizable`
//! bounds every state-dependent term over it, and leaving it counts as entering Unsafe.
//!
//! The validated [`NonlinearDesc`] goes into `Problem::nonlinear`; `Problem::plant` is then the
//! linearisation of f + g u at the centre of Init (u = 0) with C = ∂h/∂x, so that sets in output
//! coordinates and every size check read as for a linear plant. The task is built on the linear model in
//! ξ (`model::feedback_linearizable`).

use std::ops::Range;

use rand::{Rng, SeedableRng};
use serde::Deserialize;
use toml::Spanned;

use super::error::{ErrorKind, SpecError};
use super::limits::{MAX_M, MAX_N};
use super::raw::{Pairs, RawTime, RawVec};
use super::validate::{bounded, capacity, check_box, positive, vector, Dim};
use super::{InitBox, Matrix, Plant, TimeDomain};
use crate::expr::diff::{lie, AffineSystem, RelativeDegree, RelativeDegreeError};
use crate::expr::interval::{certainly_regular, enclose_matrix, Interval, VarBox};
use crate::expr::{self, Expr, ExprError, Names, Point, Var};

/// Most boxes the interval proof that Γ is nonsingular over Init may bisect Init into.
pub const MAX_GAMMA_BOXES: usize = 256;
/// Random sample points of Init at which Γ and the equations are evaluated.
const SAMPLE_POINTS: usize = 64;
/// A Γ whose smallest pivot (partial pivoting) is below this fraction of its largest entry is singular.
const SINGULAR_PIVOT: f64 = 1e-9;
/// A value of L_g L_f^k h whose magnitude is at most this counts as 0 at the centre of Init (Def 3.5).
const ZERO_TOL: f64 = 1e-12;

/// `[plant]` of a plant with a `class`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawFlPlant {
    pub class: Spanned<String>,
    pub time: Spanned<RawTime>,
    pub period: Spanned<f64>,
    pub states: Spanned<Vec<Spanned<String>>>,
    pub inputs: Spanned<Vec<Spanned<String>>>,
    pub params: Option<Spanned<Pairs<Spanned<String>, Spanned<f64>>>>,
    pub f: Spanned<Vec<Spanned<String>>>,
    pub g: Spanned<Vec<Spanned<Vec<Spanned<String>>>>>,
    pub h: Spanned<Vec<Spanned<String>>>,
    pub region: Option<Spanned<RawRegion>>,
    /// The differentially flat class's keys (`spec::flat`).
    pub flat: Option<Spanned<Vec<Spanned<String>>>>,
    pub extension: Option<Spanned<Vec<Spanned<super::flat::RawExtension>>>>,
    pub state_of_flat: Option<Spanned<Vec<Spanned<String>>>>,
    pub input_of_flat: Option<Spanned<Vec<Spanned<String>>>>,
    pub flat_input: Option<Spanned<RawRegion>>,
}

/// `plant.region`: the operating region, a box over the plant's state.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRegion {
    pub lo: RawVec,
    pub hi: RawVec,
}

/// The class of a nonlinear plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlantClass {
    /// Input-output linearizable by u = κ(x) + λ(x)w (§3.1.2).
    FeedbackLinearizable,
    /// Differentially flat (§3.1.3), with the flat maps Ξ, Υ and controller states (`spec::flat`).
    DifferentiallyFlat,
}

/// A validated nonlinear plant.
#[derive(Clone, Debug, PartialEq)]
pub struct NonlinearDesc {
    pub class: PlantClass,
    /// States, inputs and parameters with their values.
    pub names: Names,
    /// f, g, h (parameters as variables; `Expr::bind_params` with `names.param_values()` binds them).
    pub system: AffineSystem,
    /// Def 3.5 at the centre of Init, checked uniform over Init: the vector relative degree, the Lie
    /// derivatives L_f^k h_i (k ≤ r_i) and Γ, symbolically (parameters as variables).
    pub derivatives: RelativeDegree,
    /// Sample period, s.
    pub period: f64,
    /// The operating region (`plant.region`), a box over the plant's state that contains Init: the
    /// law's terms are bounded over it, and leaving it counts as entering Unsafe
    /// (`model::feedback_linearizable`). `None`: the law may depend on the zero dynamics only.
    pub region: Option<InitBox>,
    /// The differentially flat class's data (`spec::flat`); `derivatives` is then the extended system's.
    pub flat: Option<Box<super::flat::FlatDesc>>,
}

impl NonlinearDesc {
    /// The vector relative degree over Init (Def 3.5).
    pub fn relative_degree(&self) -> &[usize] {
        &self.derivatives.r
    }
}

/// Whether the spec's `[plant]` has a `class` (then it is read by this module). A text that is not TOML
/// answers `false`, and the ordinary path reports the syntax error.
pub(crate) fn has_class(src: &str) -> bool {
    toml::from_str::<toml::Table>(src)
        .ok()
        .and_then(|t| t.get("plant")?.as_table()?.get("class").map(|_| ()))
        .is_some()
}

/// A plant read and parsed, before the checks that need Init.
pub(crate) struct Model {
    pub(super) names: Names,
    pub(super) system: AffineSystem,
    pub period: f64,
    pub(super) class: PlantClass,
}

impl Model {
    /// State dimension n.
    pub fn n(&self) -> usize {
        self.system.n()
    }
}

/// The byte range in the file of `inner` (a range in the string's content), when the string is written
/// without escapes; else the whole string.
fn inner_span(s: &Spanned<String>, src: &str, inner: Range<usize>) -> Range<usize> {
    let whole = s.span();
    let Some(text) = src.get(whole.clone()) else {
        return whole;
    };
    let quoted = |q: &str| {
        text.len() >= 2 * q.len()
            && text.starts_with(q)
            && text.ends_with(q)
            && &text[q.len()..text.len() - q.len()] == s.get_ref().as_str()
    };
    if !text.starts_with("\"\"\"") && !text.starts_with("'''") && (quoted("\"") || quoted("'")) {
        let start = whole.start + 1;
        (start + inner.start)..(start + inner.end)
    } else {
        whole
    }
}

/// An expression error as a spec diagnostic at its place in the file.
pub(super) fn expr_error(e: ExprError, s: &Spanned<String>, src: &str, what: &str) -> SpecError {
    let span = e
        .span()
        .map(|r| inner_span(s, src, r))
        .unwrap_or_else(|| s.span());
    let kind = match e {
        ExprError::TooLarge { .. } => ErrorKind::Capacity,
        _ => ErrorKind::Expression,
    };
    let label = match &e {
        ExprError::UnknownName { .. } => "unknown name".to_string(),
        ExprError::TooLarge { limit, .. } => format!("beyond the limit {limit}"),
        _ => "here".to_string(),
    };
    SpecError::new(kind, format!("{what}: {e}"))
        .at(span, label)
        .help(
            "expressions use + - * / ^ (integer powers), parentheses, numbers, pi, the declared \
             states, inputs and params, and sin cos tan exp log sqrt abs atan tanh atan2",
        )
}

/// Reads and parses the plant: class, time, period, names, dimensions, expressions.
pub(crate) fn model(raw: &Spanned<RawFlPlant>, src: &str) -> Result<Model, SpecError> {
    let p = raw.get_ref();
    let class =
        match p.class.get_ref().as_str() {
            "feedback_linearizable" => {
                super::flat::refuse_flat_keys(p)?;
                PlantClass::FeedbackLinearizable
            }
            "differentially_flat" => PlantClass::DifferentiallyFlat,
            other => return Err(SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "plant.class = \"{}\" is not a plant class",
                    crate::text::excerpt(other)
                ),
            )
            .at(p.class.span(), "unknown class")
            .help(
                "the classes are: feedback_linearizable, differentially_flat (omit `class` for a \
                 linear plant)",
            )),
        };
    if *p.time.get_ref() != RawTime::Continuous {
        return Err(SpecError::new(
            ErrorKind::BadValue,
            "a nonlinear plant is stated in continuous time (ẋ = f(x) + g(x)u)",
        )
        .at(p.time.span(), "use time = \"continuous\""));
    }
    let period = positive(&p.period, "plant.period", ErrorKind::Period, "")?;
    let n = p.states.get_ref().len();
    let m = p.inputs.get_ref().len();
    if n == 0 || n > MAX_N {
        return Err(capacity(
            format!("plant.states has {n} names: the state dimension must be 1..={MAX_N}"),
            p.states.span(),
            format!("n = {n}"),
            "the firmware evaluates at most 12 states",
        ));
    }
    if m == 0 || m > MAX_M {
        return Err(capacity(
            format!("plant.inputs has {m} names: the input dimension must be 1..={MAX_M}"),
            p.inputs.span(),
            format!("m = {m}"),
            "the firmware applies at most 6 inputs",
        ));
    }
    let dim = |len: usize, want: usize, span: Range<usize>, what: String| {
        if len == want {
            Ok(())
        } else {
            Err(SpecError::new(
                ErrorKind::Dimension,
                format!("{what} has {len} entries; expected {want}"),
            )
            .at(span, format!("expected {want}")))
        }
    };
    dim(
        p.f.get_ref().len(),
        n,
        p.f.span(),
        "plant.f (one expression per state)".into(),
    )?;
    dim(
        p.g.get_ref().len(),
        n,
        p.g.span(),
        "plant.g (one row per state)".into(),
    )?;
    for (i, row) in p.g.get_ref().iter().enumerate() {
        dim(
            row.get_ref().len(),
            m,
            row.span(),
            format!("plant.g[{i}] (one entry per input)"),
        )?;
    }
    dim(
        p.h.get_ref().len(),
        m,
        p.h.span(),
        "plant.h (as many outputs as inputs, (3.16))".into(),
    )?;

    // ---- names ----
    let mut params = Vec::new();
    if let Some(ps) = &p.params {
        for (k, v) in &ps.get_ref().0 {
            let value = bounded(
                *v.get_ref(),
                v.span(),
                &format!("plant.params.{}", k.get_ref()),
            )?;
            params.push((k.get_ref().clone(), value));
        }
    }
    let names = Names {
        states: p
            .states
            .get_ref()
            .iter()
            .map(|s| s.get_ref().clone())
            .collect(),
        inputs: p
            .inputs
            .get_ref()
            .iter()
            .map(|s| s.get_ref().clone())
            .collect(),
        params,
    };
    match names.validate() {
        Ok(()) => {}
        Err(ExprError::BadName { name, why }) => {
            let span = p
                .states
                .get_ref()
                .iter()
                .chain(p.inputs.get_ref())
                .find(|s| *s.get_ref() == name)
                .map(|s| s.span())
                .or_else(|| {
                    p.params.as_ref().and_then(|ps| {
                        ps.get_ref()
                            .0
                            .iter()
                            .find(|(k, _)| *k.get_ref() == name)
                            .map(|(k, _)| k.span())
                    })
                })
                .unwrap_or_else(|| raw.span());
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!("plant: name `{}` {why}", crate::text::excerpt(&name)),
            )
            .at(span, "this name"));
        }
        Err(e) => {
            let span = p.params.as_ref().map_or_else(|| raw.span(), |ps| ps.span());
            return Err(
                SpecError::new(ErrorKind::Capacity, format!("plant: {e}")).at(span, "too many")
            );
        }
    }

    // ---- expressions ----
    let parse = |s: &Spanned<String>, what: String| -> Result<Expr, SpecError> {
        let e = expr::parse(s.get_ref(), &names).map_err(|e| expr_error(e, s, src, &what))?;
        if let Some(j) = (0..m).find(|&j| e.uses(Var::Input(j as u16))) {
            return Err(SpecError::new(
                ErrorKind::Expression,
                format!(
                    "{what} uses the input `{}`: the plant is ẋ = f(x) + g(x)u, so f, g and h are \
                     functions of the state (and params) only",
                    names.inputs[j]
                ),
            )
            .at(s.span(), "uses an input"));
        }
        Ok(e)
    };
    let f =
        p.f.get_ref()
            .iter()
            .enumerate()
            .map(|(i, s)| parse(s, format!("plant.f[{i}]")))
            .collect::<Result<Vec<_>, _>>()?;
    let g =
        p.g.get_ref()
            .iter()
            .enumerate()
            .map(|(i, row)| {
                row.get_ref()
                    .iter()
                    .enumerate()
                    .map(|(j, s)| parse(s, format!("plant.g[{i}][{j}]")))
                    .collect::<Result<Vec<_>, _>>()
            })
            .collect::<Result<Vec<_>, _>>()?;
    let h =
        p.h.get_ref()
            .iter()
            .enumerate()
            .map(|(i, s)| parse(s, format!("plant.h[{i}]")))
            .collect::<Result<Vec<_>, _>>()?;
    Ok(Model {
        names,
        system: AffineSystem { f, g, h },
        period,
        class,
    })
}

/// `(X = 0.1, Y = −0.05, …)`.
pub(super) fn fmt_point(names: &Names, x: &[f64]) -> String {
    let parts: Vec<String> = names
        .states
        .iter()
        .zip(x)
        .map(|(n, v)| format!("{n} = {v:.6}"))
        .collect();
    format!("({})", parts.join(", "))
}

/// The smallest pivot of Gaussian elimination with partial pivoting, relative to the largest entry (0
/// for a singular or non-finite matrix).
#[allow(clippy::needless_range_loop)]
pub(super) fn pivot_ratio(a: &[Vec<f64>]) -> f64 {
    let m = a.len();
    let scale = a.iter().flatten().fold(0.0f64, |s, v| s.max(v.abs()));
    if !(scale.is_finite() && scale > 0.0) {
        return 0.0;
    }
    let mut w = a.to_vec();
    let mut min_pivot = f64::INFINITY;
    for c in 0..m {
        let p = (c..m)
            .max_by(|&i, &j| w[i][c].abs().total_cmp(&w[j][c].abs()))
            .unwrap_or(c);
        w.swap(c, p);
        let piv = w[c][c];
        min_pivot = min_pivot.min(piv.abs());
        if piv == 0.0 {
            return 0.0;
        }
        for i in c + 1..m {
            let f = w[i][c] / piv;
            for j in c..m {
                w[i][j] -= f * w[c][j];
            }
        }
    }
    min_pivot / scale
}

/// The points of Init at which the equations and Γ are evaluated: the centre, the corners of the free
/// coordinates (when there are at most 64), and seeded random points.
pub(super) fn sample_points(init: &InitBox) -> Vec<Vec<f64>> {
    let centre = init.centre();
    let free = init.free_coords();
    let mut pts = vec![centre.clone()];
    if free.len() <= 6 {
        for mask in 0..(1usize << free.len()) {
            let mut x = centre.clone();
            for (b, &i) in free.iter().enumerate() {
                x[i] = if mask >> b & 1 == 1 {
                    init.hi[i]
                } else {
                    init.lo[i]
                };
            }
            pts.push(x);
        }
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5eed_0013);
    for _ in 0..SAMPLE_POINTS {
        pts.push(
            init.lo
                .iter()
                .zip(&init.hi)
                .map(|(&l, &h)| if l < h { rng.random_range(l..=h) } else { l })
                .collect(),
        );
    }
    pts
}

/// `its term `0/0` is NaN there`: the innermost undefined subterm of an equation
/// ([`Expr::undefined_at`]), quoted within [`crate::text::MAX_EXCERPT`].
pub(super) fn undefined_term(term: &Expr, v: f64, names: &Names) -> String {
    let shown = crate::text::excerpt(&term.display(names).to_string());
    let what = if v.is_nan() {
        "NaN (undefined)"
    } else {
        "infinite"
    };
    format!("its term `{shown}` is {what} there")
}

/// A point of the state space (no inputs: f, g and h do not use them).
pub(super) fn point<'a>(x: &'a [f64], p: &'a [f64]) -> Point<'a> {
    Point { x, u: &[], p }
}

/// `plant.region`, validated: a box of n finite bounds, lo ≤ hi, that contains Init (a refusal names the
/// state, both boxes' bounds and a point of Init outside the region).
fn region(
    raw: &Spanned<RawFlPlant>,
    init: &InitBox,
    names: &Names,
) -> Result<Option<InitBox>, SpecError> {
    let Some(r) = &raw.get_ref().region else {
        return Ok(None);
    };
    let n = init.lo.len();
    let mut d = Dim {
        n: Some(n),
        why: format!("the plant has {n} states"),
    };
    let rr = r.get_ref();
    let lo = vector(&rr.lo, "plant.region.lo", &mut d)?;
    let hi = vector(&rr.hi, "plant.region.hi", &mut d)?;
    check_box(&lo, &hi, &rr.lo, &rr.hi, "plant.region")?;
    for i in 0..n {
        let below = init.lo[i] < lo[i];
        if below || init.hi[i] > hi[i] {
            // A point of Init outside the region: Init's centre with coordinate i at the offending bound.
            let mut x = init.centre();
            x[i] = if below { init.lo[i] } else { init.hi[i] };
            let (span, label) = if below {
                (rr.lo.get_ref()[i].span(), format!("lo[{i}] = {}", lo[i]))
            } else {
                (rr.hi.get_ref()[i].span(), format!("hi[{i}] = {}", hi[i]))
            };
            return Err(SpecError::new(
                ErrorKind::Model,
                format!(
                    "plant.region does not contain Init: Init's {} ∈ [{}, {}] but the region's is \
                     [{}, {}], so the point {} of Init lies outside it",
                    names.states[i],
                    init.lo[i],
                    init.hi[i],
                    lo[i],
                    hi[i],
                    fmt_point(names, &x)
                ),
            )
            .at(span, label)
            .help(
                "the region is where the law's bounds hold; it must contain Init (and the runs)",
            ));
        }
    }
    Ok(Some(InitBox { lo, hi }))
}

/// The checks over Init (module docs), then the linearisation at Init's centre as the `Plant`.
pub(crate) fn check(
    model: Model,
    init: &InitBox,
    raw: &Spanned<RawFlPlant>,
    src: &str,
) -> Result<(Plant, NonlinearDesc), SpecError> {
    let p = raw.get_ref();
    if model.class == PlantClass::DifferentiallyFlat {
        return super::flat::check(model, init, raw, src);
    }
    let Model {
        names,
        system,
        period,
        class: _,
    } = model;
    let m = system.m();
    let pv = names.param_values();
    let region = region(raw, init, &names)?;
    // Where Def 3.5 must hold: the operating region when there is one (it contains Init), else Init.
    let (domain, within) = match &region {
        Some(r) => (r, "the operating region (plant.region)"),
        None => (init, "Init"),
    };
    let pts = sample_points(domain);
    let centre = pts[0].clone();
    let model_err = |msg: String, span: Range<usize>, label: &str| {
        SpecError::new(ErrorKind::Model, msg).at(span, label.to_string())
    };

    // ---- the equations are finite on the sample points ----
    for x in &pts {
        let pt = point(x, &pv);
        let eqs = system
            .f
            .iter()
            .enumerate()
            .map(|(i, e)| {
                (
                    e,
                    format!("plant.f[{i}] (d{}/dt)", names.states[i]),
                    p.f.get_ref()[i].span(),
                )
            })
            .chain(system.g.iter().enumerate().flat_map(|(i, row)| {
                row.iter().enumerate().map(move |(j, e)| {
                    (
                        e,
                        format!("plant.g[{i}][{j}]"),
                        p.g.get_ref()[i].get_ref()[j].span(),
                    )
                })
            }))
            .chain(
                system
                    .h
                    .iter()
                    .enumerate()
                    .map(|(i, e)| (e, format!("plant.h[{i}]"), p.h.get_ref()[i].span())),
            );
        for (e, what, span) in eqs {
            if let Some((term, v)) = e.undefined_at(&pt) {
                return Err(model_err(
                    format!(
                        "{what} is not defined at the point {} of {within}: {}",
                        fmt_point(&names, x),
                        undefined_term(term, v, &names)
                    ),
                    span,
                    "not finite there",
                ));
            }
        }
    }

    // ---- relative degree at the centre, uniform over Init ----
    let rd = system
        .relative_degree_at(&point(&centre, &pv), ZERO_TOL)
        .map_err(|e| match e {
            RelativeDegreeError::Expr(e) => {
                SpecError::new(ErrorKind::Capacity, format!("plant: {e}"))
                    .at(p.h.span(), "the derivatives of these outputs")
            }
            RelativeDegreeError::NoRelativeDegree { output, n } => model_err(
                format!(
                    "plant.h[{output}] has no relative degree at the centre {} of {within}: no \
                     input appears in its first {n} derivatives (L_g L_f^k h = 0 for k < {n}, Def 3.5)",
                    fmt_point(&names, &centre)
                ),
                p.h.get_ref()[output].span(),
                "no input reaches this output",
            ),
        })?;
    for (i, ri) in rd.r.iter().enumerate() {
        for k in 0..ri - 1 {
            for j in 0..m {
                let term = lie(&rd.lf[i][k], &system.g_col(j))
                    .map_err(|e| SpecError::new(ErrorKind::Capacity, format!("plant: {e}")))?;
                if !term.is_zero() {
                    return Err(model_err(
                        format!(
                            "the relative degree of plant.h[{i}] is not uniform over {within}: \
                             L_g{j} L_f^{k} h{i} = {} vanishes at the centre {} but not identically \
                             (Def 3.5 (3.18))",
                            term.display(&names),
                            fmt_point(&names, &centre)
                        ),
                        p.h.get_ref()[i].span(),
                        "this output",
                    ));
                }
            }
        }
    }

    // ---- Γ nonsingular at the sample points ----
    let gamma_span = p.g.span();
    for x in &pts {
        let g = crate::expr::diff::eval_matrix(&rd.gamma, &point(x, &pv));
        let ratio = pivot_ratio(&g);
        // Negated so that a NaN ratio counts as singular.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let singular = !(ratio > SINGULAR_PIVOT);
        if singular {
            return Err(model_err(
                format!(
                    "the decoupling matrix Γ (Def 3.5, (3.19)) is singular at the point {} of \
                     {within}: Γ = {g:?}; the plant is not input-output linearizable there",
                    fmt_point(&names, x)
                ),
                gamma_span.clone(),
                "g, with h, makes Γ",
            )
            .at(p.h.span(), "the outputs"));
        }
    }

    // ---- Γ nonsingular over all of Init: interval enclosures on a bisection ----
    let params: Vec<Interval> = pv.iter().map(|&v| Interval::point(v)).collect();
    let whole: Vec<Interval> = domain.intervals();
    if let Err((mid, why, boxes)) = prove_regular(&rd.gamma, whole, &params) {
        return Err(model_err(
            format!(
                "the decoupling matrix Γ (Def 3.5, (3.19)) could not be proved nonsingular over all \
                 of {within}: on the sub-box around {} ({why}) after {boxes} boxes",
                fmt_point(&names, &mid)
            ),
            gamma_span,
            "g, with h, makes Γ",
        )
        .at(raw.span(), "this plant")
        .help(if region.is_some() {
            "Γ may be singular or nearly so near that point; shrink plant.region or change the outputs"
        } else {
            "Γ may be singular or nearly so near that point; shrink Init or change the outputs"
        }));
    }

    let plant = linearisation(&system, &names, &pv, init, period, raw)?;
    Ok((
        plant,
        NonlinearDesc {
            class: PlantClass::FeedbackLinearizable,
            names,
            system,
            derivatives: rd,
            period,
            region,
            flat: None,
        },
    ))
}

/// The plant's linearisation at the centre of Init (u = 0) with C = ∂h/∂x, which must be constant (outputs
/// linear in the state, so that sets in output coordinates mean what they say): `Problem::plant` of a
/// nonlinear spec, which the size checks and output-coordinate sets read.
pub(super) fn linearisation(
    system: &AffineSystem,
    names: &Names,
    pv: &[f64],
    init: &InitBox,
    period: f64,
    raw: &Spanned<RawFlPlant>,
) -> Result<Plant, SpecError> {
    let p = raw.get_ref();
    let (n, m) = (system.n(), system.m());
    let model_err = |msg: String, span: Range<usize>, label: &str| {
        SpecError::new(ErrorKind::Model, msg).at(span, label.to_string())
    };
    let jac = |es: &[Expr]| {
        crate::expr::diff::jacobian(
            es,
            &(0..n).map(|j| Var::State(j as u16)).collect::<Vec<_>>(),
        )
        .map_err(|e| SpecError::new(ErrorKind::Capacity, format!("plant: {e}")))
    };
    let dh = jac(&system.h)?;
    let mut C = Matrix::zeros(m, n);
    for (i, row) in dh.iter().enumerate() {
        for (j, e) in row.iter().enumerate() {
            let Some(v) = e.bind_params(pv).as_const() else {
                return Err(model_err(
                    format!(
                        "plant.h[{i}] is not linear in the state (∂h{i}/∂{} = {}): outputs of a \
                         feedback-linearizable plant are linear for now, so that sets in output \
                         coordinates mean what they say",
                        names.states[j],
                        e.display(names)
                    ),
                    p.h.get_ref()[i].span(),
                    "not linear",
                ));
            };
            C.data[i * n + j] = v;
        }
    }
    let df = jac(&system.f)?;
    // The linearisation at Init's centre (whatever the domain of the checks above).
    let centre = init.centre();
    let cpt = point(&centre, pv);
    let mut A = Matrix::zeros(n, n);
    let mut B = Matrix::zeros(n, m);
    let mut offset = vec![0.0; n];
    for i in 0..n {
        let mut ax = 0.0;
        for j in 0..n {
            A.data[i * n + j] = df[i][j].eval(&cpt);
            ax += A.data[i * n + j] * centre[j];
        }
        for j in 0..m {
            B.data[i * m + j] = system.g[i][j].eval(&cpt);
        }
        offset[i] = system.f[i].eval(&cpt) - ax;
    }
    if A.data
        .iter()
        .chain(&B.data)
        .chain(&offset)
        .any(|v| !v.is_finite())
    {
        return Err(model_err(
            format!(
                "the linearisation of the plant at the centre {} of Init is not finite",
                fmt_point(names, &centre)
            ),
            p.f.span(),
            "these equations",
        ));
    }
    Ok(Plant {
        time: TimeDomain::Continuous,
        A,
        B,
        offset,
        period,
        C,
    })
}

/// Proves the square matrix of expressions `m` nonsingular at every point of the box `whole` (one
/// interval per state variable) by interval enclosures (`expr::interval::certainly_regular`) on a
/// bisection of the states `m` uses, into at most [`MAX_GAMMA_BOXES`] boxes. On failure: the centre of the
/// sub-box where the proof stopped, why, and how many boxes were tried.
pub(super) fn prove_regular(
    m: &[Vec<Expr>],
    whole: Vec<Interval>,
    params: &[Interval],
) -> Result<(), (Vec<f64>, String, usize)> {
    let n = whole.len();
    // The states m depends on: splitting any other leaves its enclosure as it is.
    let split: Vec<usize> = (0..n)
        .filter(|&s| m.iter().flatten().any(|e| e.uses(Var::State(s as u16))))
        .collect();
    let mut queue: Vec<Vec<Interval>> = vec![whole];
    let mut boxes = 0usize;
    while let Some(bx) = queue.pop() {
        boxes += 1;
        let enc = enclose_matrix(
            m,
            &VarBox {
                x: &bx,
                u: &[],
                p: params,
            },
        );
        if matches!(&enc, Ok(g) if certainly_regular(g)) {
            continue;
        }
        if boxes + queue.len() >= MAX_GAMMA_BOXES || split.is_empty() {
            let mid: Vec<f64> = bx.iter().map(|i| i.mid()).collect();
            let why = match enc {
                Err(e) => format!("its enclosure fails: {e}"),
                Ok(_) => "its interval enclosure contains matrices that are not proved nonsingular"
                    .into(),
            };
            return Err((mid, why, boxes));
        }
        // Bisect the widest coordinate m depends on.
        let Some(&i) = split
            .iter()
            .max_by(|&&a, &&b| (bx[a].hi - bx[a].lo).total_cmp(&(bx[b].hi - bx[b].lo)))
        else {
            continue;
        };
        let mid = bx[i].mid();
        let mut left = bx.clone();
        let mut right = bx;
        left[i].hi = mid;
        right[i].lo = mid;
        queue.push(left);
        queue.push(right);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::{self, ErrorKind};

    fn example() -> String {
        spec::example_text("fl-4-9.toml")
    }

    fn variant(from: &str, to: &str) -> Result<spec::Problem, spec::SpecError> {
        spec::example_variant("fl-4-9.toml", from, to)
    }

    #[test]
    fn example_4_9_has_relative_degree_two_two_and_its_linearisation_as_plant() {
        let p =
            spec::parse(&example(), "fl-4-9.toml").unwrap_or_else(|e| panic!("{}", e.headline()));
        let nl = p.nonlinear.as_ref().expect("a nonlinear plant");
        assert_eq!(nl.class, PlantClass::FeedbackLinearizable);
        assert_eq!(nl.relative_degree(), &[2, 2]);
        assert_eq!((p.plant.n(), p.plant.m(), p.plant.p()), (6, 2, 2));
        // C selects (X, Y); at θ = 0, B's velocity rows are g(x) = [[0, 1], [1, 0]].
        assert_eq!(p.plant.C.row(0), &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(p.plant.C.row(1), &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
        assert_eq!(p.plant.B.row(1), &[0.0, 1.0]);
        assert_eq!(p.plant.B.row(3), &[1.0, 0.0]);
        assert_eq!(p.plant.B.row(5), &[0.1, -0.1], "a/I = b/I = 0.1");
        // f is affine in the state, so the linearisation is exact: A row 1 = (−1, 0.1), c = (0, 1, 0, 1, 0, 0).
        assert_eq!(p.plant.A.row(1), &[-1.0, 0.1, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(p.plant.offset, vec![0.0, 1.0, 0.0, 1.0, 0.0, 0.0]);
    }

    #[test]
    fn a_parse_error_points_inside_the_string() {
        let e = variant("\"1 - X + 0.1*Xd\"", "\"1 - Xx + 0.1*Xd\"").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Expression);
        assert!(
            e.message().contains("plant.f[1]") && e.message().contains("`Xx`"),
            "{}",
            e.message()
        );
        let src = example();
        let line = src.lines().position(|l| l.starts_with("f = [")).unwrap() + 1;
        // The column of `X` in "1 - X + 0.1*Xd" (1-based), where `Xx` now stands.
        let col = src.lines().nth(line - 1).unwrap().find("1 - X +").unwrap() + 5;
        assert_eq!(e.line_col(), Some((line, col)));
    }

    #[test]
    fn a_singular_gamma_is_refused_naming_the_point() {
        // Γ = [[−sin θ, cos θ], [θ, 1]] has det −(sin θ + θ cos θ) = 0 at θ = 0, where Init pins θ.
        let e = variant("[\"cos(th)\",  \"sin(th)\"]", "[\"th\", \"1\"]").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model);
        assert!(e.message().contains("singular"), "{}", e.message());
        assert!(e.message().contains("th = 0.000000"), "{}", e.message());
    }

    #[test]
    fn a_relative_degree_that_is_not_uniform_is_refused() {
        // L_g h1 = (θ, 0): zero at θ = 0 (the centre) but not identically.
        let e = variant(
            "[\"0\",       \"0\"],\n  [\"-sin(th)\"",
            "[\"th\", \"0\"],\n  [\"-sin(th)\"",
        )
        .unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model);
        assert!(e.message().contains("not uniform"), "{}", e.message());
        assert!(e.message().contains("th"), "{}", e.message());
    }

    #[test]
    fn wrong_models_are_refused_with_their_equation() {
        let e = variant("h = [\"X\", \"Y\"]", "h = [\"1\", \"Y\"]").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model);
        assert!(
            e.message().contains("plant.h[0] has no relative degree"),
            "{}",
            e.message()
        );
        let e = variant("h = [\"X\", \"Y\"]", "h = [\"X + 0.01*X^2\", \"Y\"]").unwrap_err();
        assert!(e.message().contains("not linear"), "{}", e.message());
        let e = variant("\"thd\", \"0\"]", "\"thd\", \"F1\"]").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Expression);
        assert!(
            e.message().contains("uses the input `F1`"),
            "{}",
            e.message()
        );
        let e = variant("\"feedback_linearizable\"", "\"quadratic\"").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadValue);
        let e = variant("inputs = [\"F1\", \"F2\"]", "inputs = [\"F1\", \"X\"]").unwrap_err();
        assert!(e.message().contains("declared twice"), "{}", e.message());
        let e = variant("h = [\"X\", \"Y\"]", "h = [\"X\"]").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Dimension);
        let e = variant("\"Yd\", \"1 - Y", "\"Yd / (Y - Y)\", \"1 - Y").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model);
    }

    /// The example with θ free in [−1, 1] instead of pinned.
    fn theta_free(src: &str) -> String {
        src.replace(
            "lo = [-0.1, 0.0, -0.1, 1.0, 0.0, 0.0]",
            "lo = [-0.1, 0.0, -0.1, 1.0, -1.0, 0.0]",
        )
        .replace(
            "hi = [ 0.1, 0.0,  0.1, 1.0, 0.0, 0.0]",
            "hi = [ 0.1, 0.0,  0.1, 1.0, 1.0, 0.0]",
        )
    }

    #[test]
    fn gamma_is_proved_nonsingular_over_a_box_by_bisection() {
        // Over θ ∈ [−1, 1] one enclosure of R(θ) is too wide to prove; halves of it are not.
        let src = theta_free(&example());
        assert_ne!(src, example());
        let p = spec::parse(&src, "fl.toml").unwrap_or_else(|e| panic!("{}", e.headline()));
        assert_eq!(p.nonlinear.unwrap().relative_degree(), &[2, 2]);
    }

    #[test]
    fn gamma_nearly_singular_between_the_samples_is_refused_by_the_interval_proof() {
        // Γ = diag(1, (θ − 0.3)²): regular at every sample point (none lands within 3·10⁻⁵ of 0.3),
        // singular at θ = 0.3, which only the enclosure sees.
        let src = theta_free(&example())
            .replace("[\"-sin(th)\", \"cos(th)\"]", "[\"1\", \"0\"]")
            .replace("[\"cos(th)\",  \"sin(th)\"]", "[\"0\", \"(th - 0.3)^2\"]");
        let e = spec::parse(&src, "fl.toml").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model, "{}", e.message());
        assert!(
            e.message().contains("could not be proved nonsingular"),
            "{}",
            e.message()
        );
        assert!(e.message().contains("th = 0.30"), "{}", e.message());
    }
}
