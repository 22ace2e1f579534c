//! A hybrid automaton in the spec (§2.1, Def 2.1): named locations, each a linear affine plant, and
//! edges with a guard, an affine reset and who takes them. Read from `[plant]`:
//!
//! ```toml
//! [plant]
//! time = "continuous"          # hybrid locations are continuous-time plants
//! period = 0.05
//! initial = "left"             # the location Init is in
//!
//! [[plant.location]]
//! name = "left"
//! A = [[...]]                  # n×n, every location the same n
//! B = [[...]]                  # n×m, every location the same m
//! c = [...]                    # optional affine term (default 0)
//! invariant = { A = [[1, 0, 0]], b = [0] }   # optional polytope {x : A x ≤ b}
//!
//! [[plant.edge]]
//! from = "left"
//! to = "right"
//! kind = "internal"            # "internal": taken when the flow enters the guard (§4.2.2);
//!                              # "forced": taken when the controller chooses (§4.2.1)
//! guard = { A = [[-1, 0, 0]], b = [0] }      # polytope {x : A x ≤ b}; a forced edge may omit it
//!                                            # (the whole state space, Example 4.20)
//! reset = { R = [[...]], r = [...] }         # optional x ↦ R x + r (default: the identity)
//! ```
//!
//! Every mistake is a diagnostic at the offending value: an unknown or repeated location name, a guard,
//! invariant or reset of the wrong dimension, a zero guard row, an Init box that leaves the initial
//! location's invariant, and `A`/`B` given both in `[plant]` and per location.

use serde::Deserialize;
use toml::Spanned;

use super::error::{ErrorKind, SpecError};
use super::limits::MAX_LOCATIONS;
use super::raw::{RawMat, RawPlant, RawTime, RawVec};
use super::validate::{
    capacity, input_dim, matrix_cols, polytope_rows, state_dim, vector, Cols, Dim,
};
use super::{InitBox, Matrix, Plant, TimeDomain};

/// `[[plant.location]]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawLocation {
    pub name: Spanned<String>,
    pub A: RawMat,
    pub B: RawMat,
    pub c: Option<RawVec>,
    pub invariant: Option<Spanned<RawPolytope>>,
}

/// `[[plant.edge]]`.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawEdge {
    pub from: Spanned<String>,
    pub to: Spanned<String>,
    pub kind: Spanned<String>,
    pub guard: Option<Spanned<RawPolytope>>,
    pub reset: Option<Spanned<RawReset>>,
}

/// `{ A = [[...]], b = [...] }`: the polytope {x : A x ≤ b}.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPolytope {
    pub A: RawMat,
    pub b: RawVec,
}

/// `{ R = [[...]], r = [...] }`: x ↦ R x + r.
#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawReset {
    pub R: RawMat,
    pub r: Option<RawVec>,
}

/// Who takes an edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeKindDesc {
    Internal,
    Forced,
}

/// A polytope {x : A x ≤ b} as validated.
#[derive(Clone, Debug, PartialEq)]
pub struct PolytopeDesc {
    pub A: Matrix,
    pub b: Vec<f64>,
}

/// One location as validated.
#[derive(Clone, Debug, PartialEq)]
pub struct LocationDesc {
    pub name: String,
    pub A: Matrix,
    pub B: Matrix,
    pub c: Vec<f64>,
    pub invariant: Option<PolytopeDesc>,
}

/// One edge as validated: locations by index into [`HybridDesc::locations`].
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeDesc {
    pub from: usize,
    pub to: usize,
    pub kind: EdgeKindDesc,
    pub guard: PolytopeDesc,
    pub R: Matrix,
    pub r: Vec<f64>,
}

/// A validated hybrid automaton.
#[derive(Clone, Debug, PartialEq)]
pub struct HybridDesc {
    pub locations: Vec<LocationDesc>,
    pub edges: Vec<EdgeDesc>,
    /// The location Init is in.
    pub initial: usize,
}

/// Whether `[plant]` describes a hybrid automaton.
pub(crate) fn is_hybrid(p: &RawPlant) -> bool {
    !p.location.is_empty() || !p.edge.is_empty() || p.initial.is_some()
}

fn polytope(raw: &Spanned<RawPolytope>, what: &str, n: usize) -> Result<PolytopeDesc, SpecError> {
    let r = raw.get_ref();
    let mut rows = Dim::free();
    let mut cols = Dim {
        n: Some(n),
        why: format!("the state has n = {n}"),
    };
    polytope_rows(&r.A, &format!("{what}.A"))?;
    let A = matrix_cols(&r.A, &format!("{what}.A"), &mut rows, Cols::Of(&mut cols))?;
    rows.why = format!("{what}.A has {} rows", A.rows);
    let b = vector(&r.b, &format!("{what}.b"), &mut rows)?;
    for i in 0..A.rows {
        if (0..n).all(|j| A.get(i, j) == 0.0) {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!("row {} of {what}.A is zero: it constrains nothing", i + 1),
            )
            .at(r.A.get_ref()[i].span(), "a zero row"));
        }
    }
    Ok(PolytopeDesc { A, b })
}

/// The location named `name`, or a diagnostic listing the names there are.
fn find(names: &[String], name: &Spanned<String>, key: &str) -> Result<usize, SpecError> {
    names
        .iter()
        .position(|x| x == name.get_ref())
        .ok_or_else(|| {
            SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "{key} = \"{}\" is not a location; the locations are {}",
                    crate::text::excerpt(name.get_ref()),
                    names
                        .iter()
                        .map(|x| format!("\"{}\"", crate::text::excerpt(x)))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )
            .at(name.span(), "unknown location")
        })
}

/// Validates a hybrid `[plant]` (module doc). Returns the initial location's model as the problem's
/// `plant` (n, m, period and the output map are shared by every location) and the automaton.
pub(crate) fn plant(
    raw: &Spanned<RawPlant>,
    period: f64,
) -> Result<(Plant, HybridDesc), SpecError> {
    let p = raw.get_ref();
    for (key, span) in [
        ("A", p.A.as_ref().map(|v| v.span())),
        ("B", p.B.as_ref().map(|v| v.span())),
        ("c", p.c.as_ref().map(|v| v.span())),
        ("g", p.g.as_ref().map(|v| v.span())),
    ] {
        if let Some(span) = span {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "plant.{key} belongs to a plant with one location; a hybrid plant gives `{key}` \
                     in each [[plant.location]]"
                ),
            )
            .at(span, "move this into the locations"));
        }
    }
    if *p.time.get_ref() != RawTime::Continuous {
        return Err(SpecError::new(
            ErrorKind::BadValue,
            "a hybrid plant's locations are continuous-time plants (time = \"continuous\"); \
             discrete-time locations are not supported",
        )
        .at(p.time.span(), "must be \"continuous\""));
    }
    if p.location.is_empty() {
        return Err(SpecError::new(
            ErrorKind::MissingField,
            "a hybrid plant (it has `initial` or [[plant.edge]]) needs at least one [[plant.location]]",
        )
        .at(raw.span(), "no [[plant.location]] in this plant"));
    }
    if p.location.len() > MAX_LOCATIONS {
        return Err(capacity(
            format!(
                "the plant has {} locations; an image holds at most {MAX_LOCATIONS}",
                p.location.len()
            ),
            p.location[MAX_LOCATIONS].span(),
            format!("location {} of at most {MAX_LOCATIONS}", MAX_LOCATIONS + 1),
            "merge locations with the same dynamics",
        ));
    }
    let mut n = Dim::free();
    let mut m = Dim::free();
    let mut names: Vec<String> = Vec::new();
    let mut locations = Vec::with_capacity(p.location.len());
    for (i, l) in p.location.iter().enumerate() {
        let l = l.get_ref();
        let name = l.name.get_ref();
        if name.trim().is_empty() {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!("location {} has an empty name", i + 1),
            )
            .at(l.name.span(), "empty name"));
        }
        if let Some(j) = names.iter().position(|x| x == name) {
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "location name \"{name}\" is used twice (locations {} and {})",
                    j + 1,
                    i + 1
                ),
            )
            .at(l.name.span(), "repeated name")
            .at(p.location[j].get_ref().name.span(), "first used here"));
        }
        let key = format!("plant.location[{i}]");
        state_dim(&l.A, &format!("{key}.A"))?;
        let A = matrix_cols(&l.A, &format!("{key}.A"), &mut n, Cols::Square)?;
        if i == 0 {
            n.why = format!("{key}.A is {0}×{0}", A.rows);
        }
        let B = matrix_cols(&l.B, &format!("{key}.B"), &mut n, Cols::Of(&mut m))?;
        input_dim(&B, &l.B, &format!("{key}.B"))?;
        let c = match &l.c {
            Some(v) => vector(v, &format!("{key}.c"), &mut n)?,
            None => vec![0.0; A.rows],
        };
        let invariant = match &l.invariant {
            Some(inv) => Some(polytope(inv, &format!("{key}.invariant"), A.rows)?),
            None => None,
        };
        names.push(name.clone());
        locations.push(LocationDesc {
            name: name.clone(),
            A,
            B,
            c,
            invariant,
        });
    }
    let n = locations[0].A.rows;
    let initial = match &p.initial {
        Some(name) => find(&names, name, "plant.initial")?,
        None => {
            return Err(SpecError::new(
                ErrorKind::MissingField,
                "a hybrid plant needs `initial`: the location Init is in",
            )
            .at(raw.span(), "add initial = \"<location>\" here"))
        }
    };
    let mut edges = Vec::with_capacity(p.edge.len());
    for (e, raw_edge) in p.edge.iter().enumerate() {
        let r = raw_edge.get_ref();
        let key = format!("plant.edge[{e}]");
        let from = find(&names, &r.from, &format!("{key}.from"))?;
        let to = find(&names, &r.to, &format!("{key}.to"))?;
        let kind = match r.kind.get_ref().as_str() {
            "internal" => EdgeKindDesc::Internal,
            "forced" => EdgeKindDesc::Forced,
            other => {
                return Err(SpecError::new(
                    ErrorKind::BadValue,
                    format!(
                        "{key}.kind = \"{}\"; it must be \"internal\" or \"forced\"",
                        crate::text::excerpt(other)
                    ),
                )
                .at(r.kind.span(), "unknown kind")
                .help("internal: the flow takes the edge on entering the guard; forced: the controller does"))
            }
        };
        let guard = match (&r.guard, kind) {
            (Some(g), _) => polytope(g, &format!("{key}.guard"), n)?,
            // The controller may take the edge anywhere: no rows, the whole state space.
            (None, EdgeKindDesc::Forced) => PolytopeDesc {
                A: Matrix {
                    rows: 0,
                    cols: n,
                    data: Vec::new(),
                },
                b: Vec::new(),
            },
            (None, EdgeKindDesc::Internal) => {
                return Err(SpecError::new(
                    ErrorKind::MissingField,
                    format!(
                    "{key} is internal and has no guard: the flow takes it on entering its guard"
                ),
                )
                .at(
                    raw_edge.span(),
                    "add guard = { A = [[...]], b = [...] } here",
                )
                .help("only a forced edge (taken when the controller chooses) may omit its guard"))
            }
        };
        let (R, rr) = match &r.reset {
            None => (Matrix::identity(n), vec![0.0; n]),
            Some(reset) => {
                let rs = reset.get_ref();
                let mut dim = Dim {
                    n: Some(n),
                    why: format!("a reset maps the state (n = {n}) to the state"),
                };
                let R = matrix_cols(
                    &rs.R,
                    &format!("{key}.reset.R"),
                    &mut dim.clone(),
                    Cols::Of(&mut dim),
                )?;
                let rr = match &rs.r {
                    Some(v) => vector(v, &format!("{key}.reset.r"), &mut dim)?,
                    None => vec![0.0; n],
                };
                (R, rr)
            }
        };
        edges.push(EdgeDesc {
            from,
            to,
            kind,
            guard,
            R,
            r: rr,
        });
    }
    let first = &locations[initial];
    let plant = Plant {
        time: TimeDomain::Continuous,
        A: first.A.clone(),
        B: first.B.clone(),
        offset: first.c.clone(),
        period,
        C: Matrix::identity(n),
    };
    Ok((
        plant,
        HybridDesc {
            locations,
            edges,
            initial,
        },
    ))
}

/// Init must lie in the initial location's invariant: for a box, max over the box of aᵀx ≤ b for
/// every row (exact: the maximum of a linear function over a box is at a vertex).
pub(crate) fn check_init(
    h: &HybridDesc,
    init: &InitBox,
    raw_plant: &Spanned<RawPlant>,
    init_span: std::ops::Range<usize>,
) -> Result<(), SpecError> {
    let loc = &h.locations[h.initial];
    let Some(inv) = &loc.invariant else {
        return Ok(());
    };
    let n = init.lo.len();
    for i in 0..inv.A.rows {
        let worst: f64 = (0..n)
            .map(|j| {
                let a = inv.A.get(i, j);
                (a * init.lo[j]).max(a * init.hi[j])
            })
            .sum();
        if worst > inv.b[i] {
            let span = raw_plant.get_ref().location[h.initial]
                .get_ref()
                .invariant
                .as_ref()
                .map_or(raw_plant.span(), |s| s.span());
            return Err(SpecError::new(
                ErrorKind::BadValue,
                format!(
                    "Init leaves the invariant of the initial location \"{}\": row {} of its invariant \
                     reaches {worst} over the Init box, above its bound {}",
                    loc.name,
                    i + 1,
                    inv.b[i]
                ),
            )
            .at(span, "this invariant")
            .at(init_span, "excludes part of this Init box")
            .help("every initial state must satisfy the invariant of `initial`; shrink Init or choose another location"));
        }
    }
    Ok(())
}
