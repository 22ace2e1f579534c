//! Validation of a parsed spec: shapes of matrices and vectors, finiteness, ranges, symmetric PSD shape
//! matrices, boxes, settings, then the cross-set checks of `spec::checks`. Every error carries the span
//! of the offending TOML value (or table).

use std::ops::Range;

use toml::Spanned;

use super::checks::{self, GoalVerdict, Meet};
use super::error::{ErrorKind, SpecError};
use super::hybrid;
use super::limits::{self, max_rows, MAX_M, MAX_N, MAX_STEPS, MAX_TABLE_VALUES, MAX_TRAJECTORIES};
use super::raw::{RawF, RawInput, RawMat, RawSpec, RawSynthesis, RawTime, RawVec};
use super::sets::{named_sets, set_from_raw, SetCtx};
use super::settings::{ControllerMode, SynthesisSettings, TerminalChoice};
use super::{InitBox, InputSet, Matrix, Plant, Problem, TimeDomain, MAX_MAGNITUDE};

/// An expected dimension and why it is expected (for messages). `n: None` = not fixed yet; the first
/// vector or matrix that uses it fixes it.
#[derive(Clone, Debug)]
pub(crate) struct Dim {
    pub n: Option<usize>,
    pub why: String,
}

impl Dim {
    pub fn free() -> Self {
        Dim {
            n: None,
            why: String::new(),
        }
    }
}

/// Validate a vector: non-empty, length matching `dim`, finite entries.
pub(crate) fn vector(raw: &RawVec, name: &str, dim: &mut Dim) -> Result<Vec<f64>, SpecError> {
    let v = raw.get_ref();
    if v.is_empty() {
        return Err(
            SpecError::new(ErrorKind::Dimension, format!("{name} is empty"))
                .at(raw.span(), "empty"),
        );
    }
    match dim.n {
        Some(d) if d != v.len() => {
            return Err(SpecError::new(
                ErrorKind::Dimension,
                format!("{name} has {} entries, expected {d} ({})", v.len(), dim.why),
            )
            .at(raw.span(), format!("expected {d} entries")))
        }
        Some(_) => {}
        None => {
            dim.n = Some(v.len());
            dim.why = format!("{name} has {} entries", v.len());
        }
    }
    v.iter()
        .enumerate()
        .map(|(i, x)| finite(x, &format!("{name}[{i}]")))
        .collect()
}

/// Columns of a matrix: the same as its rows, or a given dimension.
pub(crate) enum Cols<'a> {
    Square,
    Of(&'a mut Dim),
}

/// Validate a matrix given as an array of rows: non-empty, rectangular, row and column counts matching,
/// finite entries.
pub(crate) fn matrix_cols(
    raw: &RawMat,
    name: &str,
    rows: &mut Dim,
    cols: Cols<'_>,
) -> Result<Matrix, SpecError> {
    let m = raw.get_ref();
    if m.is_empty() {
        return Err(
            SpecError::new(ErrorKind::Dimension, format!("{name} is empty"))
                .at(raw.span(), "empty"),
        );
    }
    let nr = m.len();
    match rows.n {
        Some(d) if d != nr => {
            return Err(SpecError::new(
                ErrorKind::Dimension,
                format!("{name} has {nr} rows, expected {d} ({})", rows.why),
            )
            .at(raw.span(), format!("expected {d} rows")))
        }
        Some(_) => {}
        None => {
            rows.n = Some(nr);
            rows.why = format!("{name} has {nr} rows");
        }
    }
    let (nc, why) = match cols {
        Cols::Square => (Some(nr), format!("{name} must be square")),
        Cols::Of(c) => {
            if c.n.is_none() && !m[0].get_ref().is_empty() {
                c.n = Some(m[0].get_ref().len());
                c.why = format!("{name} has {} columns", m[0].get_ref().len());
                (c.n, format!("row 1 has {}", m[0].get_ref().len()))
            } else {
                (c.n, c.why.clone())
            }
        }
    };
    for (i, row) in m.iter().enumerate() {
        let k = row.get_ref().len();
        if k == 0 {
            return Err(SpecError::new(
                ErrorKind::Dimension,
                format!("row {} of {name} is empty", i + 1),
            )
            .at(row.span(), "empty row"));
        }
        if let Some(d) = nc {
            if k != d {
                return Err(SpecError::new(
                    ErrorKind::Dimension,
                    format!(
                        "row {} of {name} has {k} entries, expected {d} ({why})",
                        i + 1
                    ),
                )
                .at(row.span(), format!("expected {d} entries")));
            }
        }
    }
    let ncols = m[0].get_ref().len();
    let mut data = Vec::with_capacity(nr * ncols);
    for (i, row) in m.iter().enumerate() {
        for (j, x) in row.get_ref().iter().enumerate() {
            data.push(finite(x, &format!("{name}[{}][{}]", i, j))?);
        }
    }
    Ok(Matrix {
        rows: nr,
        cols: ncols,
        data,
    })
}

/// Square-or-rectangular helper used by the set validation: rows and columns both given by `Dim`s.
/// When both are the same dimension pass a clone for `rows` once it is fixed.
pub(crate) fn matrix(
    raw: &RawMat,
    name: &str,
    rows: &mut Dim,
    cols: &mut Dim,
) -> Result<Matrix, SpecError> {
    matrix_cols(raw, name, rows, Cols::Of(cols))
}

/// A size beyond a limit of [`limits`]: a [`ErrorKind::Capacity`] error at `span`.
pub(crate) fn capacity(
    message: String,
    span: Range<usize>,
    label: impl Into<String>,
    help: impl Into<String>,
) -> SpecError {
    SpecError::new(ErrorKind::Capacity, message)
        .at(span, label)
        .help(help)
}

/// The state dimension of `A` (its row count, checked before its entries are read) within
/// [`MAX_N`].
pub(crate) fn state_dim(raw: &RawMat, name: &str) -> Result<(), SpecError> {
    let n = raw.get_ref().len();
    if n > MAX_N {
        return Err(capacity(
            format!("{name} has {n} rows: the state dimension n = {n} exceeds the image's capacity n ≤ {MAX_N}"),
            raw.span(),
            format!("n = {n} > {MAX_N}"),
            "the firmware evaluates at most 12 states; reduce the model (e.g. a balanced truncation)",
        ));
    }
    Ok(())
}

/// The input dimension of `B` within [`MAX_M`].
pub(crate) fn input_dim(B: &Matrix, raw: &RawMat, name: &str) -> Result<(), SpecError> {
    if B.cols > MAX_M {
        return Err(capacity(
            format!(
                "{name} has {} columns: the input dimension m = {} exceeds the image's capacity m ≤ {MAX_M}",
                B.cols, B.cols
            ),
            raw.span(),
            format!("m = {} > {MAX_M}", B.cols),
            "the firmware applies at most 6 inputs",
        ));
    }
    Ok(())
}

/// The rows of a polytope's `A` (counted before its entries are read) within
/// [`limits::MAX_POLYTOPE_ROWS`].
pub(crate) fn polytope_rows(raw: &RawMat, name: &str) -> Result<(), SpecError> {
    let k = raw.get_ref().len();
    if k > limits::MAX_POLYTOPE_ROWS {
        return Err(capacity(
            format!(
                "{name} has {k} rows: a polytope may have at most {} (every distance to it is a \
                 quadratic program over its rows, solved at every sample of every candidate trajectory)",
                limits::MAX_POLYTOPE_ROWS
            ),
            raw.span(),
            format!("{k} rows > {}", limits::MAX_POLYTOPE_ROWS),
            "remove redundant rows, or describe the set by a box or an ellipsoid",
        ));
    }
    Ok(())
}

/// A finite number of magnitude at most [`MAX_MAGNITUDE`]. Every number of a spec passes here (or
/// through [`bounded`]), so no sum, difference or product of a few of them overflows downstream.
pub(crate) fn finite(x: &RawF, name: &str) -> Result<f64, SpecError> {
    bounded(*x.get_ref(), x.span(), name)
}

/// [`finite`] for a value and its span.
pub(crate) fn bounded(v: f64, span: Range<usize>, name: &str) -> Result<f64, SpecError> {
    if !v.is_finite() {
        return Err(SpecError::new(
            ErrorKind::NonFinite,
            format!("{name} is {v}; numbers in a spec must be finite"),
        )
        .at(span, "not finite"));
    }
    if v.abs() > MAX_MAGNITUDE {
        return Err(SpecError::new(
            ErrorKind::OutOfRange,
            format!(
                "{name} is {v:e}; numbers in a spec must lie within ±{MAX_MAGNITUDE:e} (widths, \
                 distances and their squares must stay finite)"
            ),
        )
        .at(span, format!("beyond ±{MAX_MAGNITUDE:e}"))
        .help("rescale the state or input units"));
    }
    Ok(v)
}

/// lo ≤ hi componentwise (same lengths already checked).
pub(crate) fn check_box(
    lo: &[f64],
    hi: &[f64],
    lo_raw: &RawVec,
    hi_raw: &RawVec,
    what: &str,
) -> Result<(), SpecError> {
    if let Some(i) = (0..lo.len()).find(|&i| lo[i] > hi[i]) {
        return Err(SpecError::new(
            ErrorKind::InvertedBox,
            format!(
                "{what}: lo > hi in coordinate {} ({} > {})",
                i + 1,
                lo[i],
                hi[i]
            ),
        )
        .at(lo_raw.get_ref()[i].span(), format!("lo[{i}] = {}", lo[i]))
        .at(hi_raw.get_ref()[i].span(), format!("hi[{i}] = {}", hi[i]))
        .help("swap the two bounds, or set them equal to pin the coordinate"));
    }
    Ok(())
}

/// Q symmetric (to 1e-9 relative) and positive semidefinite (smallest eigenvalue ≥ −1e-10·max(1, |λ|max)).
pub(crate) fn check_psd(Q: &Matrix, raw: &RawMat, name: &str) -> Result<(), SpecError> {
    let n = Q.rows;
    let scale = Q.data.iter().fold(1.0f64, |a, x| a.max(x.abs()));
    for i in 0..n {
        for j in i + 1..n {
            if (Q.get(i, j) - Q.get(j, i)).abs() > 1e-9 * scale {
                let sp = |a: usize, b: usize| raw.get_ref()[a].get_ref()[b].span();
                return Err(SpecError::new(
                    ErrorKind::NotSymmetric,
                    format!(
                        "{name} is not symmetric: entry ({}, {}) is {} but ({}, {}) is {}",
                        i + 1,
                        j + 1,
                        Q.get(i, j),
                        j + 1,
                        i + 1,
                        Q.get(j, i)
                    ),
                )
                .at(sp(i, j), "this entry")
                .at(sp(j, i), "differs from this one"));
            }
        }
    }
    let lam = checks::sym_eigenvalues(Q).map_err(|e| {
        SpecError::new(
            ErrorKind::BadValue,
            format!("{name}: eigenvalue computation failed ({e})"),
        )
        .at(raw.span(), "here")
    })?;
    let lmin = lam.first().copied().unwrap_or(0.0);
    let lmax = lam.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    if lmin < -1e-10 * lmax.max(1.0) {
        return Err(SpecError::new(
            ErrorKind::NotPsd,
            format!("{name} is not positive semidefinite: its smallest eigenvalue is {lmin:.6e}"),
        )
        .at(raw.span(), format!("smallest eigenvalue {lmin:.3e}"))
        .help("an ellipsoid (y − center)ᵀ Q (y − center) ≤ 1 needs Q ⪰ 0"));
    }
    Ok(())
}

pub(crate) fn positive(
    x: &Spanned<f64>,
    name: &str,
    kind: ErrorKind,
    extra: &str,
) -> Result<f64, SpecError> {
    let v = finite(x, name)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(
            SpecError::new(kind, format!("{name} is {v}; it must be > 0{extra}"))
                .at(x.span(), "must be > 0"),
        )
    }
}

/// Parse the TOML and validate everything.
pub(crate) fn problem(src: &str) -> Result<Problem, SpecError> {
    let mut p = problem_of(src)?;
    p.fingerprint = super::fingerprint::SpecFingerprint::of(src)?;
    Ok(p)
}

/// [`problem`] before its fingerprint is set (the value it holds until then is all zero).
fn problem_of(src: &str) -> Result<Problem, SpecError> {
    if super::nonlinear::has_class(src) {
        // A plant written as expressions (`spec::nonlinear`): its own `[plant]` table, the rest alike.
        let raw: RawSpec<super::nonlinear::RawFlPlant> =
            toml::from_str(src).map_err(|e| SpecError::from_toml(&e))?;
        let model = super::nonlinear::model(&raw.plant, src)?;
        let (horizon, seed) = horizon_seed(&raw, model.period, raw.plant.get_ref().period.span())?;
        let init = init_box(&raw, model.n())?;
        let (plant, desc) = super::nonlinear::check(model, &init, &raw.plant, src)?;
        return problem_sets(raw, plant, None, Some(desc), horizon, seed, init);
    }
    let raw: RawSpec = toml::from_str(src).map_err(|e| SpecError::from_toml(&e))?;

    // ---- plant ----
    let p = raw.plant.get_ref();
    let (plant, hybrid) = if hybrid::is_hybrid(p) {
        let period = positive(&p.period, "plant.period", ErrorKind::Period, "")?;
        let (plant, h) = hybrid::plant(&raw.plant, period)?;
        (plant, Some(h))
    } else {
        (single_plant(&raw.plant)?, None)
    };
    let (horizon, seed) = horizon_seed(&raw, plant.period, p.period.span())?;
    let n_state = plant.n();

    // ---- init ----
    let init = init_box(&raw, n_state)?;
    if let Some(h) = &hybrid {
        hybrid::check_init(h, &init, &raw.plant, raw.init.span())?;
    }
    problem_sets(raw, plant, hybrid, None, horizon, seed, init)
}

/// The horizon (at least one period, at most [`MAX_STEPS`] samples) and the seed.
fn horizon_seed<P>(
    raw: &RawSpec<P>,
    period: f64,
    period_span: Range<usize>,
) -> Result<(f64, u64), SpecError> {
    let horizon = positive(&raw.horizon, "horizon", ErrorKind::Horizon, "")?;
    if horizon < period * (1.0 - 1e-12) {
        return Err(SpecError::new(
            ErrorKind::Horizon,
            format!("horizon {horizon} s is shorter than one sample period ({period} s)"),
        )
        .at(raw.horizon.span(), "shorter than plant.period")
        .at(period_span, "the period"));
    }
    let steps = limits::steps_in(horizon, period);
    if steps > MAX_STEPS {
        return Err(capacity(
            format!(
                "horizon {horizon} s at plant.period {period} s is {} samples; a trajectory's table may \
                 have at most {MAX_STEPS} rows (the image's capacity at one input), one per sample",
                if steps == usize::MAX { "more than 2⁶⁴".to_string() } else { steps.to_string() }
            ),
            raw.horizon.span(),
            format!("more than {MAX_STEPS} periods"),
            format!(
                "shorten the horizon to at most {} s or lengthen the period",
                MAX_STEPS as f64 * period
            ),
        )
        .at(period_span, "the period"));
    }
    let seed = *raw.seed.get_ref();
    let seed = u64::try_from(seed).map_err(|_| {
        SpecError::new(
            ErrorKind::Seed,
            format!("seed {seed} is out of range; it must be an integer in [0, 2⁶⁴ − 1]"),
        )
        .at(raw.seed.span(), "out of range")
    })?;
    Ok((horizon, seed))
}

/// A `[plant]` with one location: A and B required.
fn single_plant(raw: &Spanned<super::raw::RawPlant>) -> Result<Plant, SpecError> {
    let p = raw.get_ref();
    let missing = |k: &str| {
        SpecError::new(ErrorKind::MissingField, format!("plant: `{k}` is missing"))
            .at(raw.span(), format!("`{k}` missing in this table"))
            .help("a plant with one location gives A and B; a hybrid plant gives [[plant.location]] tables")
    };
    let (Some(pa), Some(pb)) = (&p.A, &p.B) else {
        return Err(missing(if p.A.is_none() { "A" } else { "B" }));
    };
    let mut n = Dim::free();
    state_dim(pa, "plant.A")?;
    let A = matrix_cols(pa, "plant.A", &mut n, Cols::Square)?;
    n.why = format!("plant.A is {0}×{0}", A.rows);
    let mut m = Dim::free();
    let B = matrix_cols(pb, "plant.B", &mut n, Cols::Of(&mut m))?;
    input_dim(&B, pb, "plant.B")?;
    let time = match p.time.get_ref() {
        RawTime::Continuous => TimeDomain::Continuous,
        RawTime::Discrete => TimeDomain::Discrete,
    };
    let (own, other) = match time {
        TimeDomain::Continuous => (&p.c, &p.g),
        TimeDomain::Discrete => (&p.g, &p.c),
    };
    let (own_key, other_key) = match time {
        TimeDomain::Continuous => ("c", "g"),
        TimeDomain::Discrete => ("g", "c"),
    };
    if let Some(o) = other {
        return Err(SpecError::new(
            ErrorKind::BadValue,
            format!(
                "plant.{other_key} is the affine term of a {} plant; this plant has time = \"{}\" and uses `{own_key}`",
                if other_key == "c" { "continuous-time" } else { "discrete-time" },
                if time == TimeDomain::Continuous { "continuous" } else { "discrete" },
            ),
        )
        .at(o.span(), format!("use `{own_key}` here")));
    }
    let offset = match own {
        Some(v) => vector(v, &format!("plant.{own_key}"), &mut n)?,
        None => vec![0.0; A.rows],
    };
    let period = positive(&p.period, "plant.period", ErrorKind::Period, "")?;
    let C = match &p.C {
        Some(c) => matrix_cols(c, "plant.C", &mut Dim::free(), Cols::Of(&mut n))?,
        None => Matrix::identity(A.rows),
    };
    Ok(Plant {
        time,
        A,
        B,
        offset,
        period,
        C,
    })
}

/// The sets, input, settings and cross-set checks of a spec whose plant, horizon, seed and Init are
/// validated.
#[allow(clippy::too_many_arguments)]
fn problem_sets<P>(
    mut raw: RawSpec<P>,
    plant: Plant,
    hybrid: Option<hybrid::HybridDesc>,
    nonlinear: Option<super::nonlinear::NonlinearDesc>,
    horizon: f64,
    seed: u64,
    init: InitBox,
) -> Result<Problem, SpecError> {
    let n_state = plant.n();
    // ---- goal, unsafe, named sets ----
    let goal_ctx = SetCtx {
        what: "goal".into(),
        n_state: Some(n_state),
        output: Some(&plant.C),
        check_empty: false,
    };
    let goal = set_from_raw(&raw.goal, &goal_ctx)?;
    let mut unsafe_sets = Vec::with_capacity(raw.unsafe_sets.len());
    for (i, u) in raw.unsafe_sets.iter().enumerate() {
        let ctx = SetCtx {
            what: format!("unsafe[{i}]"),
            n_state: Some(n_state),
            output: Some(&plant.C),
            check_empty: true,
        };
        unsafe_sets.push(set_from_raw(u, &ctx)?);
    }
    let sets = named_sets(
        std::mem::take(&mut raw.sets.0),
        Some(n_state),
        Some(&plant.C),
    )?;

    // ---- input ----
    let input = input_set(raw.input.get_ref(), raw.input.span(), plant.m())?;
    let fallback_input = fallback_input(raw.input.get_ref(), &input, plant.m())?;

    // ---- synthesis, mtl ----
    let synthesis = match &raw.synthesis {
        Some(s) => synthesis(s.get_ref(), n_state)?,
        None => SynthesisSettings::default(),
    };
    if let (Some(_), ControllerMode::Pwa) = (&hybrid, synthesis.mode) {
        let span = raw
            .synthesis
            .as_ref()
            .and_then(|s| s.get_ref().mode.as_ref().map(|m| m.span()))
            .unwrap_or_else(|| raw.plant.span());
        return Err(SpecError::new(
            ErrorKind::BadValue,
            "synthesis.mode = \"pwa\" is not available for a hybrid plant: its image is a feedforward \
             table per run, switched by the guards or the controller",
        )
        .at(span, "pwa on a hybrid plant")
        .help("remove synthesis.mode (or write mode = \"feedforward\")"));
    }
    // ---- sizes: the whole budget's table within the image ----
    // The image bounds the table's values (rows × m), so the rows it holds depend on the inputs. A hybrid
    // run keeps only the rows its certificate covers (each segment up to its guard or Goal, usually far
    // fewer than the horizon's), and its growth admits a run only while its rows fit the image
    // (`synth::hybrid::admit`), so there the budget is not bounded by the horizon's rows: one run's is.
    let steps = limits::steps_in(horizon, plant.period);
    let cap = max_rows(plant.m());
    let budget = if hybrid.is_some() {
        1
    } else {
        synthesis.max_trajectories
    };
    let rows = steps.saturating_mul(budget);
    if rows > cap {
        let max_traj = raw
            .synthesis
            .as_ref()
            .and_then(|s| s.get_ref().max_trajectories.as_ref().map(|v| v.span()))
            .filter(|_| hybrid.is_none());
        let m = plant.m();
        let mut e = capacity(
            format!(
                "{} of {steps} samples (horizon {horizon} s at period {} s): a table of \
                 {rows} rows; the image holds at most {cap} rows at m = {m} (its {MAX_TABLE_VALUES} values \
                 over the inputs)",
                if hybrid.is_some() { "a run".to_string() } else { format!("{budget} trajectories") },
                plant.period
            ),
            max_traj.clone().unwrap_or_else(|| raw.horizon.span()),
            if max_traj.is_some() {
                format!("{rows} rows with this budget")
            } else if hybrid.is_some() {
                format!("{rows} rows for one run")
            } else {
                format!("{rows} rows with the default max_trajectories = {}", synthesis.max_trajectories)
            },
            if hybrid.is_some() || steps > cap {
                format!(
                    "shorten the horizon to at most {} s or lengthen the period",
                    cap as f64 * plant.period
                )
            } else {
                format!("set synthesis.max_trajectories to at most {}, or shorten the horizon", cap / steps.max(1))
            },
        );
        if max_traj.is_some() {
            e = e.at(raw.horizon.span(), format!("{steps} samples"));
        }
        return Err(e);
    }
    let mtl = match &raw.mtl {
        Some(t) => {
            let f = t.get_ref().formula.get_ref();
            if f.trim().is_empty() {
                return Err(SpecError::new(ErrorKind::BadValue, "mtl.formula is empty")
                    .at(t.get_ref().formula.span(), "empty formula"));
            }
            if f.len() > limits::MAX_FORMULA_LEN {
                return Err(capacity(
                    format!(
                        "mtl.formula is {} bytes long, more than the limit {} (spec::limits)",
                        f.len(),
                        limits::MAX_FORMULA_LEN
                    ),
                    t.get_ref().formula.span(),
                    format!("beyond the limit {}", limits::MAX_FORMULA_LEN),
                    format!(
                        "a formula has at most {} bytes and {} atoms: name the sets in [sets.*] \
                         instead of spelling out many predicates",
                        limits::MAX_FORMULA_LEN,
                        limits::MAX_FORMULA_ATOMS
                    ),
                ));
            }
            Some(f.clone())
        }
        None => None,
    };

    // ---- cross-set checks ----
    for (i, u) in unsafe_sets.iter().enumerate() {
        match checks::box_meets_set(&init.lo, &init.hi, u) {
            Meet::Meets(x) => {
                return Err(SpecError::new(
                    ErrorKind::InitMeetsUnsafe,
                    format!("init and unsafe[{i}] meet: the initial state x = {} lies in both", fmt_vec(&x)),
                )
                .at(raw.unsafe_sets[i].span(), "this unsafe set")
                .at(raw.init.span(), "meets this init box")
                .help("every state of Init must start outside Unsafe; shrink Init or move the unsafe set"));
            }
            Meet::Disjoint | Meet::Undecided => {}
        }
    }
    match checks::goal_verdict(&goal, &unsafe_sets) {
        GoalVerdict::Ok => {}
        GoalVerdict::NoInterior(why) => {
            return Err(SpecError::new(
                ErrorKind::GoalUnreachable,
                format!("goal is unreachable by construction: {why}"),
            )
            .at(raw.goal.span(), "this goal set")
            .help("a trajectory reaches Goal robustly only if Goal has interior points"));
        }
        GoalVerdict::InsideUnsafe(j) => {
            return Err(SpecError::new(
                ErrorKind::GoalUnreachable,
                format!("goal is unreachable by construction: it lies entirely inside unsafe[{j}]"),
            )
            .at(raw.goal.span(), "this goal set")
            .at(raw.unsafe_sets[j].span(), "lies inside this unsafe set"));
        }
    }

    // A feedback-linearizable plant's runs stay in its operating region (leaving it is Unsafe), so a
    // Goal that misses the region cannot be reached: refused here, before any search.
    if let Some(region) = nonlinear
        .as_ref()
        .filter(|d| d.class == super::nonlinear::PlantClass::FeedbackLinearizable)
        .and_then(|d| d.region.as_ref())
    {
        if checks::box_meets_set(&region.lo, &region.hi, &goal) == Meet::Disjoint {
            return Err(SpecError::new(
                ErrorKind::GoalUnreachable,
                format!(
                    "goal is unreachable by construction: it lies outside the operating region \
                     plant.region (lo = {}, hi = {}), and a run that leaves the region counts as \
                     entering Unsafe",
                    fmt_vec(&region.lo),
                    fmt_vec(&region.hi)
                ),
            )
            .at(raw.goal.span(), "this goal set misses plant.region")
            .help("move Goal into plant.region, or widen the region to contain part of Goal"));
        }
    }

    let name = raw.name.as_ref().map(|s| s.get_ref().clone());
    Ok(Problem {
        name,
        plant,
        init,
        goal,
        unsafe_sets,
        input,
        fallback_input,
        horizon,
        seed,
        synthesis,
        mtl,
        sets,
        hybrid,
        nonlinear,
        fingerprint: super::fingerprint::SpecFingerprint(
            [0; shared_types::image::SPEC_FINGERPRINT_LEN],
        ),
    })
}

fn fmt_vec(x: &[f64]) -> String {
    let parts: Vec<String> = x.iter().map(|v| format!("{v:.4}")).collect();
    format!("({})", parts.join(", "))
}

fn init_box<P>(raw: &RawSpec<P>, n_state: usize) -> Result<InitBox, SpecError> {
    let r = raw.init.get_ref();
    let span = raw.init.span();
    if r.kind.get_ref() != "box" {
        return Err(SpecError::new(
            ErrorKind::BadValue,
            format!(
                "init must be a box (kind = \"box\"), found kind = \"{}\"",
                crate::text::excerpt(r.kind.get_ref())
            ),
        )
        .at(r.kind.span(), "init must be a box")
        .help("coverage samples Init uniformly, so it is a box; lo = hi pins a coordinate"));
    }
    if let Some(c) = &r.coords {
        if c.get_ref().as_str() != Some("state") {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                "init is a box in state coordinates; remove `coords`",
            )
            .at(c.span(), "init cannot use other coordinates"));
        }
    }
    for (key, present) in [
        ("center", r.center.as_ref().map(|v| v.span())),
        ("Q", r.Q.as_ref().map(|v| v.span())),
        ("radius", r.radius.as_ref().map(|v| v.span())),
        ("A", r.A.as_ref().map(|v| v.span())),
        ("b", r.b.as_ref().map(|v| v.span())),
    ] {
        if let Some(sp) = present {
            return Err(SpecError::new(
                ErrorKind::UnknownKey,
                format!("init: key `{key}` is not used by a box (it takes lo, hi)"),
            )
            .at(sp, "not a key of a box"));
        }
    }
    let need = |k: &str| {
        SpecError::new(ErrorKind::MissingField, format!("init: a box needs `{k}`"))
            .at(span.clone(), format!("`{k}` missing in this table"))
    };
    let lo_raw = r.lo.as_ref().ok_or_else(|| need("lo"))?;
    let hi_raw = r.hi.as_ref().ok_or_else(|| need("hi"))?;
    let mut d = Dim {
        n: Some(n_state),
        why: format!("the state has {n_state} coordinates"),
    };
    let lo = vector(lo_raw, "init.lo", &mut d)?;
    let hi = vector(hi_raw, "init.hi", &mut d)?;
    check_box(&lo, &hi, lo_raw, hi_raw, "init")?;
    Ok(InitBox { lo, hi })
}

fn input_set(r: &RawInput, span: Range<usize>, m: usize) -> Result<InputSet, SpecError> {
    let mut d = Dim {
        n: Some(m),
        why: format!("plant.B has {m} columns"),
    };
    let need = |k: &str, kind: &str| {
        SpecError::new(
            ErrorKind::MissingField,
            format!("input: kind = \"{kind}\" needs `{k}`"),
        )
        .at(span.clone(), format!("`{k}` missing in this table"))
    };
    let stray = |key: &str, sp: Range<usize>, kind: &str| {
        SpecError::new(
            ErrorKind::UnknownKey,
            format!("input: key `{key}` is not used by kind = \"{kind}\""),
        )
        .at(sp, format!("not a key of a {kind}"))
    };
    match r.kind.get_ref().as_str() {
        "box" => {
            if let Some(c) = &r.center {
                return Err(stray("center", c.span(), "box"));
            }
            if let Some(c) = &r.radius {
                return Err(stray("radius", c.span(), "box"));
            }
            let lo_raw = r.lo.as_ref().ok_or_else(|| need("lo", "box"))?;
            let hi_raw = r.hi.as_ref().ok_or_else(|| need("hi", "box"))?;
            let lo = vector(lo_raw, "input.lo", &mut d)?;
            let hi = vector(hi_raw, "input.hi", &mut d)?;
            check_box(&lo, &hi, lo_raw, hi_raw, "input")?;
            Ok(InputSet::Box { lo, hi })
        }
        "ball" => {
            if let Some(c) = &r.lo {
                return Err(stray("lo", c.span(), "ball"));
            }
            if let Some(c) = &r.hi {
                return Err(stray("hi", c.span(), "ball"));
            }
            let rad = r.radius.as_ref().ok_or_else(|| need("radius", "ball"))?;
            let radius = positive(rad, "input.radius", ErrorKind::BadValue, " (‖u − center‖ ≤ radius)")?;
            let center = match &r.center {
                Some(c) => vector(c, "input.center", &mut d)?,
                None => vec![0.0; m],
            };
            Ok(InputSet::Ball { center, radius })
        }
        other => Err(SpecError::new(
            ErrorKind::BadValue,
            format!("input: unknown kind `{}`; expected \"box\" (lo, hi) or \"ball\" (2-norm bound: radius, optional center)", crate::text::excerpt(other)),
        )
        .at(r.kind.span(), "unknown kind")),
    }
}

/// `input.fallback`, which must lie in the input set, or the set's point nearest 0; as the image
/// stores it ([`InputSet::storable`]).
fn fallback_input(r: &RawInput, input: &InputSet, m: usize) -> Result<Vec<f64>, SpecError> {
    let u = match &r.fallback {
        None => input.nearest_to_zero(),
        Some(raw) => {
            let mut d = Dim {
                n: Some(m),
                why: format!("plant.B has {m} columns"),
            };
            let u = vector(raw, "input.fallback", &mut d)?;
            if !input.contains(&u) {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!(
                        "input.fallback = {} lies outside the input set; the firmware applies it \
                         whenever the image gives no input, so it must be admissible",
                        fmt_vec(&u)
                    ),
                )
                .at(raw.span(), "outside the input set")
                .help(format!(
                    "choose a point of the input set, e.g. {} (its point nearest 0, the default when \
                     the key is omitted)",
                    fmt_vec(&input.nearest_to_zero())
                )));
            }
            u
        }
    };
    Ok(input.storable(&u))
}

fn synthesis(r: &RawSynthesis, n_state: usize) -> Result<SynthesisSettings, SpecError> {
    let mut s = SynthesisSettings::default();
    let mut spans: Vec<(&'static str, Range<usize>)> = Vec::new();
    if let Some(v) = &r.mode {
        s.mode = ControllerMode::from_name(v.get_ref()).ok_or_else(|| {
            SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "synthesis.mode = \"{}\" is unknown; expected \"feedforward\" or \"pwa\"",
                    crate::text::excerpt(v.get_ref())
                ),
            )
            .at(v.span(), "unknown mode")
        })?;
    }
    if let Some(v) = &r.terminal {
        s.terminal = TerminalChoice::from_name(v.get_ref()).ok_or_else(|| {
            SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "synthesis.terminal = \"{}\" is unknown; expected \"auto\", \"invariant\", \"hold\" or \"fallback\"",
                    crate::text::excerpt(v.get_ref())
                ),
            )
            .at(v.span(), "unknown terminal behaviour")
        })?;
    }
    let mut num = |field: &'static str, v: &Option<RawF>, dst: &mut f64| -> Result<(), SpecError> {
        if let Some(x) = v {
            *dst = finite(x, &format!("synthesis.{field}"))?;
            spans.push((field, x.span()));
        }
        Ok(())
    };
    num("confidence", &r.confidence, &mut s.confidence)?;
    num(
        "coverage_target",
        &r.coverage_target,
        &mut s.coverage_target,
    )?;
    num(
        "coverage_tolerance",
        &r.coverage_tolerance,
        &mut s.coverage_tolerance,
    )?;
    num("sigma_margin", &r.sigma_margin, &mut s.sigma_margin)?;
    num("min_robustness", &r.min_robustness, &mut s.min_robustness)?;
    for (field, v, dst) in [
        (
            "max_trajectories",
            &r.max_trajectories,
            &mut s.max_trajectories,
        ),
        ("max_iterations", &r.max_iterations, &mut s.max_iterations),
        ("reference_hold", &r.reference_hold, &mut s.reference_hold),
    ] {
        if let Some(x) = v {
            let k = *x.get_ref();
            if k < 1 {
                return Err(SpecError::new(
                    ErrorKind::Setting,
                    format!("synthesis.{field} = {k}: must be at least 1"),
                )
                .at(x.span(), "must be ≥ 1"));
            }
            *dst = usize::try_from(k).unwrap_or(usize::MAX);
            spans.push((field, x.span()));
        }
    }
    if let Err(e) = s.validate() {
        let span = spans
            .iter()
            .find(|(f, _)| *f == e.field)
            .map(|(_, s)| s.clone());
        let mut err = SpecError::new(ErrorKind::Setting, e.to_string());
        if let Some(sp) = span {
            err = err.at(sp, e.reason);
        } else if e.field == "coverage_tolerance" {
            // The default tolerance is incompatible with the target the user set: point at the target.
            if let Some((_, sp)) = spans.iter().find(|(f, _)| *f == "coverage_target") {
                err = err.at(
                    sp.clone(),
                    "with the default coverage_tolerance this exceeds 1",
                );
            }
        }
        return Err(err);
    }
    let span_of = |field: &str| {
        spans
            .iter()
            .find(|(f, _)| *f == field)
            .map(|(_, s)| s.clone())
    };
    if s.max_trajectories > MAX_TRAJECTORIES {
        return Err(capacity(
            format!(
                "synthesis.max_trajectories = {}: an image holds at most {MAX_TRAJECTORIES} trajectories",
                s.max_trajectories
            ),
            span_of("max_trajectories").unwrap_or_default(),
            format!("more than {MAX_TRAJECTORIES}"),
            format!("at most {MAX_TRAJECTORIES}"),
        ));
    }
    let samples = s.coverage_samples();
    let bytes = limits::sample_bytes(samples, n_state);
    if bytes > limits::MAX_SAMPLE_BYTES {
        let span = span_of("coverage_tolerance")
            .or_else(|| span_of("confidence"))
            .unwrap_or_default();
        return Err(capacity(
            format!(
                "synthesis.coverage_tolerance = {} at confidence {} needs {samples} samples of Init to \
                 estimate the coverage, about {} for n = {n_state}; the budget is {}",
                s.coverage_tolerance,
                s.confidence,
                limits::human_bytes(bytes),
                limits::human_bytes(limits::MAX_SAMPLE_BYTES)
            ),
            span,
            format!("needs {samples} samples"),
            "the samples grow as 1/tolerance²: a tolerance of 0.01 needs about 92 000 at 0.99 confidence",
        ));
    }
    Ok(s)
}
