//! A differentially flat plant written in the spec (§3.1.3, Def 3.12, Theorem 3.14): the plant
//! ẋ = f(x) + g(x)u with flat outputs y = h(x), the flat maps x = Ξ(q) and u = Υ(q, v) the user writes
//! over the flat state q (the outputs and their derivatives) and the flat input v (their highest
//! derivatives), and the controller states (a dynamic extension) the firmware keeps when the flat state
//! needs derivatives of an input (the planar quadrotor's thrust, Example 3.15):
//!
//! ```toml
//! [plant]
//! class = "differentially_flat"
//! time = "continuous"
//! period = 0.005
//! states = ["X", "Xd", "Y", "Yd", "th", "thd"]
//! inputs = ["T", "tau"]
//! params = { m = 1.0, g = 9.81 }
//! f = [...]; g = [[...], ...]             # as for feedback_linearizable
//! h = ["X", "Y"]                          # the flat outputs, as functions of the state
//! flat = ["px", "py"]                     # their names: px, px_1, px_2, … are px and its derivatives
//! extension = [{ input = "T", order = 2, init = [9.81, 0.0] }]   # the controller keeps T and Ṫ
//! state_of_flat = ["px", "px_1", "py", "py_1", "atan2(-px_2, py_2 + g)", "..."]   # Ξ, one per state
//! input_of_flat = ["m*sqrt(px_2^2 + (py_2 + g)^2)", "..."]                        # Υ, one per input
//! region = { lo = [...], hi = [...] }     # the operating region, a box over the flat state q
//! flat_input = { lo = [...], hi = [...] } # optional: the box W of the flat input the law applies
//! ```
//!
//! **The extended system.** An input with an extension of order o becomes o controller states
//! ζ = (u, u_1, …, u_{o−1}) (named `<input>`, `<input>_1`, …), and the chain's input is its o-th derivative
//! (`<input>_<o>`): ẋ = f(x) + Σ g_j u_j with u_j = ζ_0 for an extended input, ζ̇_k = ζ_{k+1}. The flat
//! outputs must have a vector relative degree (Def 3.5) on the extended system whose sum is its whole
//! dimension n + n_ext, so that the flat state q = (h_i, L_f h_i, …, L_f^{r_i−1} h_i)_i is a full set of
//! coordinates and the extended system is a chain of integrators in q with input v = α + Γu_e
//! (`model::flat`). The flat names follow r_i: output i's q entries are `<flat_i>`, `<flat_i>_1`, …,
//! `<flat_i>_{r_i−1}` and its flat input `<flat_i>_{r_i}`.
//!
//! **What is checked** (each refusal names the equation and the point): everything `spec::nonlinear`
//! checks of the expressions and names; the extension (declared inputs, order 1..=3, finite initial
//! values); the relative degree at Init's centre (with ζ at its initial values), uniform as in Def 3.5,
//! summing to n + n_ext; Ξ uses q only and Υ of an extended input and its first o − 1 derivatives along the
//! chain use q only (they give ζ from q); the region contains Init's flat state; at sample points of the
//! region (its centre, seeded random points) and of the flat input v ∈ [−10, 10]^m:
//! * Ξ inverts the flat coordinates: the q of the state and controller states Ξ gives is q again;
//! * Ξ and Υ reproduce f: d/dt Ξ_i(q) along the chain equals f_i(Ξ) + g_i(Ξ)Υ(q, v), for every state i;
//!
//! and the extended decoupling matrix Γ_e(Ξ(q), ζ(q)) is nonsingular over the whole region, proved by
//! interval enclosures on a bisection (the bound N(x0) of Theorem 3.14 is then constructive: the certified
//! ball in q, mapped by Ξ, over a region where every map is a proved diffeomorphism).
//!
//! **Init.** Init is a box over the plant's state; its flat state (with ζ at its initial values) must be a
//! box too: every q coordinate is either one of the plant's states (its Lie expression is that state, as
//! X and Ẋ are) or constant over Init (a point enclosure), so a uniform draw over Init is a uniform draw
//! over its flat box and coverage means the same in both.

use std::ops::Range;

use rand::{Rng, SeedableRng};
use serde::Deserialize;
use toml::Spanned;

use super::error::{ErrorKind, SpecError};
use super::limits::MAX_N;
use super::nonlinear::{
    expr_error, fmt_point, linearisation, prove_regular, Model, NonlinearDesc, PlantClass,
    RawFlPlant,
};
use super::raw::RawVec;
use super::validate::{check_box, vector, Dim};
use super::{InitBox, Plant};
use crate::expr::diff::{lie, AffineSystem, RelativeDegree};
use crate::expr::interval::{enclose, Interval, VarBox};
use crate::expr::{self, Expr, Names, Point, Var};

/// Most controller states a plant may declare (the image's `shared_types::capacity::MAX_EXT`).
pub const MAX_EXT: usize = 4;
/// Highest extension order of one input.
const MAX_ORDER: usize = 3;
/// Random sample points of the region at which the flat maps are checked.
const SAMPLE_POINTS: usize = 64;
/// The flat input's range at the sample points.
const V_RANGE: f64 = 10.0;
/// Relative tolerance of the identities checked at the sample points.
const IDENTITY_TOL: f64 = 1e-7;
/// A value of L_g L_f^k h whose magnitude is at most this counts as 0 at the centre of Init (Def 3.5).
const ZERO_TOL: f64 = 1e-12;

/// One entry of `plant.extension`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawExtension {
    pub input: Spanned<String>,
    pub order: Spanned<i64>,
    pub init: RawVec,
}

/// Controller states on one plant input: the input and its first `order − 1` derivatives, starting at
/// `init`.
#[derive(Clone, Debug, PartialEq)]
pub struct Extension {
    pub input: usize,
    pub order: usize,
    pub init: Vec<f64>,
}

/// A validated differentially flat plant (module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct FlatDesc {
    /// The extended system's names: the plant's states then the controller states; the chain's inputs
    /// (an extended input's `<input>_<order>`, the others as declared); the parameters.
    pub ext_names: Names,
    /// The extended system (parameters as variables).
    pub ext_system: AffineSystem,
    pub extension: Vec<Extension>,
    /// The flat names: states q, inputs v, the parameters.
    pub flat_names: Names,
    /// Ξ: the plant's state from q (n expressions over q; parameters as variables).
    pub state_of_flat: Vec<Expr>,
    /// Υ: the plant's input from q and v (m expressions).
    pub input_of_flat: Vec<Expr>,
    /// The controller states from q: Υ of each extended input and its derivatives along the chain.
    pub ext_of_flat: Vec<Expr>,
    /// q_j is the plant's state s when its Lie expression is that state.
    pub q_states: Vec<Option<usize>>,
    /// The operating region, a box over q.
    pub region: InitBox,
    /// Init's flat state, a box over q (module doc, *Init*).
    pub init_q: InitBox,
    /// `plant.flat_input`: the box W of the flat input the law may apply, when the spec sets it (else
    /// `model::flat` takes the largest symmetric box the input set allows).
    pub flat_input: Option<InitBox>,
}

impl FlatDesc {
    /// Number of controller states.
    pub fn n_ext(&self) -> usize {
        self.extension.iter().map(|e| e.order).sum()
    }

    /// The controller states' initial values, in order.
    pub fn ext_init(&self) -> Vec<f64> {
        self.extension
            .iter()
            .flat_map(|e| e.init.iter().copied())
            .collect()
    }
}

/// `flat`, `extension`, `state_of_flat` and `input_of_flat` belong to the differentially flat class.
pub(crate) fn refuse_flat_keys(p: &RawFlPlant) -> Result<(), SpecError> {
    let spans = [
        ("flat", p.flat.as_ref().map(|s| s.span())),
        ("extension", p.extension.as_ref().map(|s| s.span())),
        ("state_of_flat", p.state_of_flat.as_ref().map(|s| s.span())),
        ("input_of_flat", p.input_of_flat.as_ref().map(|s| s.span())),
        ("flat_input", p.flat_input.as_ref().map(|s| s.span())),
    ];
    for (key, span) in spans {
        if let Some(span) = span {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!("plant.{key} belongs to class = \"differentially_flat\""),
            )
            .at(span, "not for this class"));
        }
    }
    Ok(())
}

fn missing(raw: &Spanned<RawFlPlant>, key: &str, what: &str) -> SpecError {
    SpecError::new(
        ErrorKind::MissingField,
        format!("a differentially flat plant needs plant.{key}: {what}"),
    )
    .at(raw.span(), "this plant")
}

fn model_err(msg: String, span: Range<usize>, label: &str) -> SpecError {
    SpecError::new(ErrorKind::Model, msg).at(span, label.to_string())
}

fn capacity_err(e: impl std::fmt::Display, span: Range<usize>) -> SpecError {
    SpecError::new(ErrorKind::Capacity, format!("plant: {e}")).at(span, "these expressions")
}

/// `(px = 0.1, px_1 = −0.05, …)`.
fn fmt_named(names: &[String], x: &[f64]) -> String {
    let parts: Vec<String> = names
        .iter()
        .zip(x)
        .map(|(n, v)| format!("{n} = {v:.6}"))
        .collect();
    format!("({})", parts.join(", "))
}

/// The checks of the module doc, then the plant's linearisation at Init's centre as `Problem::plant`.
pub(crate) fn check(
    model: Model,
    init: &InitBox,
    raw: &Spanned<RawFlPlant>,
    src: &str,
) -> Result<(Plant, NonlinearDesc), SpecError> {
    let p = raw.get_ref();
    let Model {
        names,
        system,
        period,
        class: _,
    } = model;
    let (n, m) = (system.n(), system.m());
    let pv = names.param_values();

    // ---- the extension ----
    let mut extension: Vec<Extension> = Vec::new();
    if let Some(ext) = &p.extension {
        for e in ext.get_ref() {
            let r = e.get_ref();
            let Some(input) = names.inputs.iter().position(|s| s == r.input.get_ref()) else {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!(
                        "plant.extension names `{}`, which is not one of plant.inputs",
                        crate::text::excerpt(r.input.get_ref())
                    ),
                )
                .at(r.input.span(), "not an input"));
            };
            if extension.iter().any(|x| x.input == input) {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!("plant.extension names `{}` twice", r.input.get_ref()),
                )
                .at(r.input.span(), "again"));
            }
            let order = *r.order.get_ref();
            if !(1..=MAX_ORDER as i64).contains(&order) {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!(
                        "plant.extension order {order}: an input takes 1..={MAX_ORDER} integrators"
                    ),
                )
                .at(r.order.span(), "1, 2 or 3"));
            }
            let order = order as usize;
            let mut d = Dim {
                n: Some(order),
                why: format!("the extension of `{}` has order {order}", r.input.get_ref()),
            };
            let init = vector(&r.init, "plant.extension.init", &mut d)?;
            extension.push(Extension { input, order, init });
        }
    }
    let n_ext: usize = extension.iter().map(|e| e.order).sum();
    let ext_span = p
        .extension
        .as_ref()
        .map_or_else(|| raw.span(), |e| e.span());
    if n_ext > MAX_EXT || n + n_ext > MAX_N {
        return Err(SpecError::new(
            ErrorKind::Capacity,
            format!(
                "the extension adds {n_ext} controller states to {n} plant states: at most {MAX_EXT} \
                 controller states and {MAX_N} in all"
            ),
        )
        .at(ext_span, "too many"));
    }

    // ---- the extended system ----
    let ne = n + n_ext;
    let mut ext_states = names.states.clone();
    let mut chain_inputs = names.inputs.clone();
    // ζ index of each extended input's first controller state.
    let mut first = vec![None; m];
    for e in &extension {
        first[e.input] = Some(ext_states.len());
        let base = &names.inputs[e.input];
        ext_states.push(base.clone());
        for k in 1..e.order {
            ext_states.push(format!("{base}_{k}"));
        }
        chain_inputs[e.input] = format!("{base}_{}", e.order);
    }
    let ext_names = Names {
        states: ext_states,
        inputs: chain_inputs,
        params: names.params.clone(),
    };
    ext_names.validate().map_err(|e| {
        SpecError::new(
            ErrorKind::BadValue,
            format!("the extension's names clash with the plant's: {e}"),
        )
        .at(ext_span, "these controller states")
    })?;
    let mut f_e: Vec<Expr> = Vec::with_capacity(ne);
    let mut g_e: Vec<Vec<Expr>> = Vec::with_capacity(ne);
    for i in 0..n {
        let mut fi = system.f[i].clone();
        let mut gi = Vec::with_capacity(m);
        for (j, fj) in first.iter().enumerate() {
            match fj {
                Some(z) => {
                    fi = Expr::add(
                        fi,
                        Expr::mul(system.g[i][j].clone(), Expr::var(Var::State(*z as u16))),
                    );
                    gi.push(Expr::c(0.0));
                }
                None => gi.push(system.g[i][j].clone()),
            }
        }
        f_e.push(fi);
        g_e.push(gi);
    }
    for e in &extension {
        let z0 = first[e.input].unwrap_or(n);
        for k in 0..e.order {
            let last = k + 1 == e.order;
            f_e.push(if last {
                Expr::c(0.0)
            } else {
                Expr::var(Var::State((z0 + k + 1) as u16))
            });
            g_e.push(
                (0..m)
                    .map(|j| Expr::c(if last && j == e.input { 1.0 } else { 0.0 }))
                    .collect(),
            );
        }
    }
    let ext_system = AffineSystem {
        f: f_e,
        g: g_e,
        h: system.h.clone(),
    };

    // ---- the relative degree at Init's centre (ζ at its initial values), uniform ----
    let mut centre = init.centre();
    for e in &extension {
        centre.extend_from_slice(&e.init);
    }
    let at = Point {
        x: &centre,
        u: &[],
        p: &pv,
    };
    let rd: RelativeDegree = ext_system.relative_degree_at(&at, ZERO_TOL).map_err(|e| {
        model_err(
            format!(
                "the flat outputs have no relative degree on the extended system at Init's \
                     centre {}: {e}",
                fmt_named(&ext_names.states, &centre)
            ),
            p.h.span(),
            "these outputs",
        )
    })?;
    for (i, ri) in rd.r.iter().enumerate() {
        for k in 0..ri - 1 {
            for j in 0..m {
                let term = lie(&rd.lf[i][k], &ext_system.g_col(j))
                    .map_err(|e| capacity_err(e, p.h.span()))?;
                if !term.is_zero() {
                    return Err(model_err(
                        format!(
                            "the relative degree of plant.h[{i}] on the extended system is not \
                             uniform: L_g{j} L_f^{k} h{i} = {} vanishes at Init's centre but not \
                             identically (Def 3.5 (3.18))",
                            term.display(&ext_names)
                        ),
                        p.h.get_ref()[i].span(),
                        "this output",
                    ));
                }
            }
        }
    }
    let r_total: usize = rd.r.iter().sum();
    if r_total != ne {
        return Err(model_err(
            format!(
                "the flat outputs' relative degrees on the extended system are {:?}, summing to \
                 {r_total}, but it has {ne} states ({n} of the plant, {n_ext} of the controller): \
                 these outputs are not flat outputs with this extension (Def 3.12); a flat state \
                 needs the relative degrees to sum to the dimension (add integrators to an input \
                 with plant.extension, or change h)",
                rd.r
            ),
            p.h.span(),
            "these outputs",
        ));
    }

    // ---- the flat names and maps ----
    let Some(flat) = &p.flat else {
        return Err(missing(raw, "flat", "a name per flat output"));
    };
    if flat.get_ref().len() != m {
        return Err(SpecError::new(
            ErrorKind::Dimension,
            format!(
                "plant.flat has {} names; expected {m}, one per output",
                flat.get_ref().len()
            ),
        )
        .at(flat.span(), format!("expected {m}")));
    }
    let mut q_names = Vec::with_capacity(ne);
    let mut v_names = Vec::with_capacity(m);
    for (i, nm) in flat.get_ref().iter().enumerate() {
        let base = nm.get_ref();
        if names.lookup(base).is_some() || ext_names.lookup(base).is_some() {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!("plant.flat name `{base}` is already a state, input or parameter"),
            )
            .at(nm.span(), "taken"));
        }
        q_names.push(base.clone());
        for k in 1..rd.r[i] {
            q_names.push(format!("{base}_{k}"));
        }
        v_names.push(format!("{base}_{}", rd.r[i]));
    }
    let flat_names = Names {
        states: q_names,
        inputs: v_names,
        params: names.params.clone(),
    };
    if let Err(e) = flat_names.validate() {
        return Err(SpecError::new(
            ErrorKind::BadValue,
            format!("plant.flat: {e} (among the flat names, which include the derivatives' `_k`)"),
        )
        .at(flat.span(), "these names"));
    }
    let parse_list = |key: &str,
                      list: &Option<Spanned<Vec<Spanned<String>>>>,
                      want: usize,
                      what: &str,
                      allow_v: bool|
     -> Result<Vec<Expr>, SpecError> {
        let Some(list) = list else {
            return Err(missing(raw, key, what));
        };
        if list.get_ref().len() != want {
            return Err(SpecError::new(
                ErrorKind::Dimension,
                format!(
                    "plant.{key} has {} entries; expected {want} ({what})",
                    list.get_ref().len()
                ),
            )
            .at(list.span(), format!("expected {want}")));
        }
        list.get_ref()
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let e = expr::parse(s.get_ref(), &flat_names)
                    .map_err(|e| expr_error(e, s, src, &format!("plant.{key}[{i}]")))?;
                if !allow_v {
                    if let Some(j) = (0..m).find(|&j| e.uses(Var::Input(j as u16))) {
                        return Err(SpecError::new(
                            ErrorKind::Expression,
                            format!(
                                "plant.{key}[{i}] uses the flat input `{}`: Ξ gives the state \
                                 from the flat state q alone",
                                flat_names.inputs[j]
                            ),
                        )
                        .at(s.span(), "uses the flat input"));
                    }
                }
                Ok(e)
            })
            .collect()
    };
    let state_of_flat = parse_list(
        "state_of_flat",
        &p.state_of_flat,
        n,
        "Ξ, one expression per state over the flat state",
        false,
    )?;
    let input_of_flat = parse_list(
        "input_of_flat",
        &p.input_of_flat,
        m,
        "Υ, one expression per input over the flat state and input",
        true,
    )?;
    let ui_span = |j: usize| {
        p.input_of_flat
            .as_ref()
            .and_then(|l| l.get_ref().get(j).map(|s| s.span()))
            .unwrap_or_else(|| raw.span())
    };
    // The chain in q: q̇ = (q_2, …, v_1, …); a flat-state expression's time derivative is its Lie
    // derivative along this field.
    let mut chain: Vec<Expr> = Vec::with_capacity(ne);
    let mut o = 0;
    for (i, &ri) in rd.r.iter().enumerate() {
        for k in 0..ri {
            chain.push(if k + 1 == ri {
                Expr::var(Var::Input(i as u16))
            } else {
                Expr::var(Var::State((o + k + 1) as u16))
            });
        }
        o += ri;
    }
    let mut ext_of_flat = Vec::with_capacity(n_ext);
    for e in &extension {
        let mut d = input_of_flat[e.input].clone();
        for k in 0..e.order {
            if let Some(j) = (0..m).find(|&j| d.uses(Var::Input(j as u16))) {
                return Err(model_err(
                    format!(
                        "the controller state {} is d^{k}/dt^{k} of plant.input_of_flat[{}], which \
                         uses the flat input `{}`: the controller states must follow from the flat \
                         state alone (an extension of order {} needs Υ and its first {} derivatives \
                         free of the flat input)",
                        ext_names.states[first[e.input].unwrap_or(n) + k],
                        e.input,
                        flat_names.inputs[j],
                        e.order,
                        e.order - 1
                    ),
                    ui_span(e.input),
                    "this input's Υ",
                ));
            }
            if k + 1 < e.order {
                let next = lie(&d, &chain).map_err(|err| capacity_err(err, ui_span(e.input)))?;
                ext_of_flat.push(std::mem::replace(&mut d, next));
            } else {
                ext_of_flat.push(d);
                break;
            }
        }
    }

    // ---- the region over q, and Init's flat box ----
    let Some(region_raw) = &p.region else {
        return Err(missing(
            raw,
            "region",
            "the operating region, a box over the flat state (its bounds are where the maps are \
             proved and the law bounded)",
        ));
    };
    let rr = region_raw.get_ref();
    let mut d = Dim {
        n: Some(ne),
        why: format!("the flat state has {ne} entries {:?}", flat_names.states),
    };
    let lo = vector(&rr.lo, "plant.region.lo", &mut d)?;
    let hi = vector(&rr.hi, "plant.region.hi", &mut d)?;
    check_box(&lo, &hi, &rr.lo, &rr.hi, "plant.region")?;
    let region = InitBox { lo, hi };
    let q_exprs: Vec<Expr> = (0..m)
        .flat_map(|i| rd.lf[i].iter().take(rd.r[i]).map(|e| e.bind_params(&pv)))
        .collect();
    let q_states: Vec<Option<usize>> = q_exprs
        .iter()
        .map(|e| match e {
            Expr::Var(Var::State(s)) if (*s as usize) < n => Some(*s as usize),
            _ => None,
        })
        .collect();
    let mut init_ext: Vec<Interval> = init.intervals();
    for e in &extension {
        init_ext.extend(e.init.iter().map(|&v| Interval::point(v)));
    }
    let (mut ilo, mut ihi) = (Vec::with_capacity(ne), Vec::with_capacity(ne));
    for (j, e) in q_exprs.iter().enumerate() {
        let (l, h) = match q_states[j] {
            Some(s) => (init.lo[s], init.hi[s]),
            None => {
                let iv = enclose(
                    e,
                    &VarBox {
                        x: &init_ext,
                        u: &[],
                        p: &[],
                    },
                )
                .map_err(|err| {
                    model_err(
                        format!(
                            "the flat coordinate {} = {} cannot be bounded over Init: {err}",
                            flat_names.states[j],
                            e.display(&ext_names)
                        ),
                        raw.span(),
                        "this plant",
                    )
                })?;
                if iv.hi - iv.lo > 1e-9 * (1.0 + iv.mag()) {
                    return Err(model_err(
                        format!(
                            "the flat coordinate {} = {} ranges over [{:.6}, {:.6}] on Init: this \
                             version needs Init's flat state to be a box, each coordinate a plant \
                             state or constant over Init (pin the states it depends on)",
                            flat_names.states[j],
                            e.display(&ext_names),
                            iv.lo,
                            iv.hi
                        ),
                        raw.span(),
                        "this plant",
                    ));
                }
                (iv.mid(), iv.mid())
            }
        };
        if l < region.lo[j] || h > region.hi[j] {
            return Err(model_err(
                format!(
                    "plant.region does not contain Init: Init's {} ∈ [{l}, {h}] but the region's \
                     is [{}, {}]",
                    flat_names.states[j], region.lo[j], region.hi[j]
                ),
                region_raw.span(),
                "the region",
            ));
        }
        ilo.push(l);
        ihi.push(h);
    }
    let init_q = InitBox { lo: ilo, hi: ihi };
    let flat_input = match &p.flat_input {
        None => None,
        Some(fi) => {
            let r = fi.get_ref();
            let mut d = Dim {
                n: Some(m),
                why: format!("the flat input has {m} entries {:?}", flat_names.inputs),
            };
            let lo = vector(&r.lo, "plant.flat_input.lo", &mut d)?;
            let hi = vector(&r.hi, "plant.flat_input.hi", &mut d)?;
            check_box(&lo, &hi, &r.lo, &r.hi, "plant.flat_input")?;
            if let Some(j) = (0..m).find(|&j| !(lo[j] < 0.0 && 0.0 < hi[j])) {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!(
                        "plant.flat_input must contain 0 in its interior: {} ∈ [{}, {}]",
                        flat_names.inputs[j], lo[j], hi[j]
                    ),
                )
                .at(fi.span(), "the flat input's box"));
            }
            Some(InitBox { lo, hi })
        }
    };

    // ---- the identities at sample points of the region ----
    let bind = |es: &[Expr]| -> Vec<Expr> { es.iter().map(|e| e.bind_params(&pv)).collect() };
    let xi_b = bind(&state_of_flat);
    let ups_b = bind(&input_of_flat);
    let zeta_b = bind(&ext_of_flat);
    let f_b = bind(&system.f);
    let g_b: Vec<Vec<Expr>> = system.g.iter().map(|r| bind(r)).collect();
    // d/dt Ξ_i along the chain.
    let dxi: Vec<Expr> = xi_b
        .iter()
        .map(|e| lie(e, &chain))
        .collect::<Result<_, _>>()
        .map_err(|e| capacity_err(e, raw.span()))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0x5eed_f1a7);
    let mut pts: Vec<(Vec<f64>, Vec<f64>)> = vec![(region.centre(), vec![0.0; m])];
    for _ in 0..SAMPLE_POINTS {
        let q: Vec<f64> = region
            .lo
            .iter()
            .zip(&region.hi)
            .map(|(&l, &h)| if l < h { rng.random_range(l..=h) } else { l })
            .collect();
        let v: Vec<f64> = (0..m)
            .map(|_| rng.random_range(-V_RANGE..=V_RANGE))
            .collect();
        pts.push((q, v));
    }
    let close = |a: f64, b: f64| (a - b).abs() <= IDENTITY_TOL * (1.0 + a.abs().max(b.abs()));
    let list_span = |l: &Option<Spanned<Vec<Spanned<String>>>>, i: usize| {
        l.as_ref()
            .and_then(|l| l.get_ref().get(i).map(|s| s.span()))
            .unwrap_or_else(|| raw.span())
    };
    for (q, v) in &pts {
        let at = Point { x: q, u: v, p: &[] };
        let where_ = || {
            format!(
                "at the flat state {} and flat input {}",
                fmt_named(&flat_names.states, q),
                fmt_named(&flat_names.inputs, v)
            )
        };
        let x: Vec<f64> = xi_b.iter().map(|e| e.eval(&at)).collect();
        let u: Vec<f64> = ups_b.iter().map(|e| e.eval(&at)).collect();
        let zeta: Vec<f64> = zeta_b.iter().map(|e| e.eval(&at)).collect();
        for (i, val) in x.iter().enumerate() {
            if !val.is_finite() {
                let term = xi_b[i]
                    .undefined_at(&at)
                    .map(|(t, v)| {
                        format!(": {}", super::nonlinear::undefined_term(t, v, &flat_names))
                    })
                    .unwrap_or_default();
                return Err(model_err(
                    format!("plant.state_of_flat[{i}] is {val} {}{term}", where_()),
                    list_span(&p.state_of_flat, i),
                    "not finite there",
                ));
            }
        }
        for (j, val) in u.iter().enumerate() {
            if !val.is_finite() {
                let term = ups_b[j]
                    .undefined_at(&at)
                    .map(|(t, v)| {
                        format!(": {}", super::nonlinear::undefined_term(t, v, &flat_names))
                    })
                    .unwrap_or_default();
                return Err(model_err(
                    format!("plant.input_of_flat[{j}] is {val} {}{term}", where_()),
                    list_span(&p.input_of_flat, j),
                    "not finite there",
                ));
            }
        }
        // Ξ inverts the flat coordinates.
        let mut xe = x.clone();
        xe.extend_from_slice(&zeta);
        let ate = Point {
            x: &xe,
            u: &[],
            p: &[],
        };
        for (j, e) in q_exprs.iter().enumerate() {
            let back = e.eval(&ate);
            if !close(back, q[j]) {
                return Err(model_err(
                    format!(
                        "plant.state_of_flat does not invert the flat coordinates: {}, Ξ gives the \
                         state {} (controller states {}), whose {} = {} is {back:.9}, not {:.9}",
                        where_(),
                        fmt_point(&names, &x),
                        fmt_named(&ext_names.states[n..], &zeta),
                        flat_names.states[j],
                        e.display(&ext_names),
                        q[j]
                    ),
                    p.state_of_flat
                        .as_ref()
                        .map_or_else(|| raw.span(), |l| l.span()),
                    "Ξ",
                ));
            }
        }
        // Ξ and Υ reproduce f.
        let atx = Point {
            x: &x,
            u: &[],
            p: &[],
        };
        // f and g defined at the state (a term undefined there is refused by name, not as a mismatch).
        for i in 0..n {
            let terms = std::iter::once((format!("plant.f[{i}]"), &f_b[i]))
                .chain((0..m).map(|j| (format!("plant.g[{i}][{j}]"), &g_b[i][j])));
            for (what, e) in terms {
                if let Some((t, v)) = e.undefined_at(&atx) {
                    return Err(model_err(
                        format!(
                            "{what} is not defined at the state {} ({}): {}",
                            fmt_point(&names, &x),
                            where_(),
                            super::nonlinear::undefined_term(t, v, &names)
                        ),
                        p.f.span(),
                        "not finite there",
                    ));
                }
            }
        }
        for i in 0..n {
            let lhs = dxi[i].eval(&at);
            let rhs = f_b[i].eval(&atx) + (0..m).map(|j| g_b[i][j].eval(&atx) * u[j]).sum::<f64>();
            if !close(lhs, rhs) {
                return Err(model_err(
                    format!(
                        "Ξ and Υ do not reproduce the plant's equation for d{}/dt (plant.f[{i}], \
                         plant.g[{i}]): {}, d/dt Ξ_{i} = {lhs:.9} along the flat chain but \
                         f + g·Υ = {rhs:.9} at the state {} and input {}",
                        names.states[i],
                        where_(),
                        fmt_point(&names, &x),
                        fmt_named(&names.inputs, &u)
                    ),
                    list_span(&p.state_of_flat, i),
                    "this state's Ξ",
                ));
            }
        }
    }

    // ---- Γ_e nonsingular over the region ----
    let mut sub: Vec<Expr> = xi_b.clone();
    sub.extend(zeta_b.iter().cloned());
    let gamma_q: Vec<Vec<Expr>> = rd
        .gamma
        .iter()
        .map(|row| {
            row.iter()
                .map(|e| {
                    e.bind_params(&pv).map_vars(&|v| match v {
                        Var::State(s) => sub.get(s as usize).cloned(),
                        _ => None,
                    })
                })
                .collect()
        })
        .collect();
    let whole: Vec<Interval> = region.intervals();
    if let Err((mid, why, boxes)) = prove_regular(&gamma_q, whole, &[]) {
        return Err(model_err(
            format!(
                "the extended decoupling matrix Γ (Def 3.5 on the extended system) could not be \
                 proved nonsingular over the operating region: on the sub-box around {} ({why}) \
                 after {boxes} boxes",
                fmt_named(&flat_names.states, &mid)
            ),
            region_raw.span(),
            "the region",
        )
        .help(
            "Γ is singular where the flat maps are (a quadrotor at zero thrust); shrink the region",
        ));
    }
    let plant = linearisation(&system, &names, &pv, init, period, raw)?;
    Ok((
        plant,
        NonlinearDesc {
            class: PlantClass::DifferentiallyFlat,
            names,
            system,
            derivatives: rd,
            period,
            region: None,
            flat: Some(Box::new(FlatDesc {
                ext_names,
                ext_system,
                extension,
                flat_names,
                state_of_flat,
                input_of_flat,
                ext_of_flat,
                q_states,
                region,
                init_q,
                flat_input,
            })),
        },
    ))
}

#[cfg(test)]
mod tests {
    use crate::spec::{self, ErrorKind};

    fn example() -> String {
        spec::example_text("flat-quadrotor.toml")
    }

    fn variant(from: &str, to: &str) -> Result<spec::Problem, spec::SpecError> {
        spec::example_variant("flat-quadrotor.toml", from, to)
    }

    #[test]
    fn the_quadrotor_is_flat_with_a_thrust_extension_of_order_two() {
        let p = spec::parse(&example(), "flat-quadrotor.toml")
            .unwrap_or_else(|e| panic!("{}", e.headline()));
        let nl = p.nonlinear.as_ref().expect("a nonlinear plant");
        assert_eq!(nl.class, super::PlantClass::DifferentiallyFlat);
        assert_eq!(nl.relative_degree(), &[4, 4]);
        let fd = nl.flat.as_ref().expect("flat data");
        assert_eq!(fd.n_ext(), 2);
        assert_eq!(fd.ext_init(), vec![9.81, 0.0]);
        assert_eq!(
            fd.flat_names.states,
            ["px", "px_1", "px_2", "px_3", "py", "py_1", "py_2", "py_3"]
        );
        assert_eq!(fd.flat_names.inputs, ["px_4", "py_4"]);
        assert_eq!(fd.ext_names.states[6..], ["T", "T_1"]);
        assert_eq!(fd.ext_names.inputs, ["T_2", "tau"]);
        assert_eq!(
            fd.q_states,
            [Some(0), Some(1), None, None, Some(2), Some(3), None, None]
        );
    }

    #[test]
    fn a_map_that_does_not_reproduce_f_is_refused_with_its_equation_and_point() {
        // θ̇ with the wrong sign: Ξ no longer inverts the flat coordinates (x⃛ depends on θ̇).
        let e = variant(
            "\"(px_2*py_3 - (py_2 + g)*px_3)/(px_2^2 + (py_2 + g)^2)\"",
            "\"((py_2 + g)*px_3 - px_2*py_3)/(px_2^2 + (py_2 + g)^2)\"",
        )
        .unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model, "{}", e.message());
        assert!(e.message().contains("does not invert"), "{}", e.message());
        assert!(e.message().contains("px_3 ="), "{}", e.message());
        // τ off by a factor: d/dt Ξ for θ̇ no longer matches f + gΥ, named by its state.
        let e = variant(
            "\"(px_2*py_4 - (py_2 + g)*px_4)/(px_2^2",
            "\"2*(px_2*py_4 - (py_2 + g)*px_4)/(px_2^2",
        )
        .unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model, "{}", e.message());
        assert!(
            e.message().contains("equation for dthd/dt"),
            "{}",
            e.message()
        );
        assert!(
            e.message().contains("at the flat state (px ="),
            "{}",
            e.message()
        );
    }

    #[test]
    fn a_region_reaching_zero_thrust_is_refused_for_a_singular_gamma() {
        // Ÿ down to −g: the thrust m√(Ẍ² + (Ÿ + g)²) reaches 0 at Ẍ = 0, where Γ is singular.
        let e = variant(
            "lo = [-10.0, -6.0, -2.0, -1.0, 0.0, -6.0, -2.0, -1.0]",
            "lo = [-10.0, -6.0, -2.0, -1.0, 0.0, -6.0, -9.81, -1.0]",
        )
        .unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model, "{}", e.message());
        assert!(
            e.message().contains("could not be proved nonsingular"),
            "{}",
            e.message()
        );
    }

    #[test]
    fn wrong_flat_specs_are_refused_with_their_reason() {
        // Without the extension, at hover (θ = 0) the thrust does not reach X at all, so the outputs have
        // no vector relative degree (Def 3.5) on the plant itself.
        let e = variant(
            "extension = [{ input = \"T\", order = 2, init = [9.81, 0.0] }]",
            "",
        )
        .unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Model, "{}", e.message());
        assert!(
            e.message().contains("no relative degree"),
            "{}",
            e.message()
        );
        // An extension of order 1 on the thrust: the torque reaches X only through θ at hover, so the
        // relative degree is not uniform (Def 3.5).
        let e = variant("order = 2, init = [9.81, 0.0]", "order = 1, init = [9.81]").unwrap_err();
        assert!(e.message().contains("not uniform"), "{}", e.message());
        // θ free in Init: its flat acceleration varies, so Init's flat state is not a box.
        let e = variant(
            "lo = [-7.25, 0.0, 4.75, 0.0, 0.0, 0.0]",
            "lo = [-7.25, 0.0, 4.75, 0.0, -0.1, 0.0]",
        )
        .unwrap_err();
        assert!(e.message().contains("px_2"), "{}", e.message());
        assert!(e.message().contains("ranges over"), "{}", e.message());
        // An extension on an input that does not exist.
        let e = variant("input = \"T\"", "input = \"F\"").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::BadValue);
        // Ξ using the flat input.
        let e = variant("\"px\", \"px_1\", \"py\"", "\"px_4\", \"px_1\", \"py\"").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Expression, "{}", e.message());
        assert!(e.message().contains("state_of_flat[0]"), "{}", e.message());
        // The flat class's keys on a feedback-linearizable plant.
        let e = variant("\"differentially_flat\"", "\"feedback_linearizable\"").unwrap_err();
        assert!(e.message().contains("belongs to class"), "{}", e.message());
        // A parse error inside Υ points at its column.
        let e = variant("\"m*sqrt(px_2^2", "\"m*sqrt(pz_2^2").unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Expression);
        assert!(e.message().contains("`pz_2`"), "{}", e.message());
        assert!(e.line_col().is_some());
    }
}
