//! Hybrid automata over linear affine locations (§2.1, Def 2.1; §3.2): the plant, and its exact
//! simulation over one sample period with the events the flow meets between samples.
//!
//! A [`Hybrid`] has locations, each a continuous-time linear affine plant ẋ = A_ℓ x + B_ℓ u + c_ℓ sampled
//! with the same period h, and edges ℓ → ℓ′ with a guard (a polytope {x : a_jᵀx ≤ b_j}), an affine reset
//! x ↦ R x + r and a kind: *internal* (taken when the flow enters the guard, §4.2.2) or *forced* (taken
//! when the controller chooses it, §4.2.1; the flow never takes it by itself).
//!
//! **Events on the exact flow** ([`Hybrid::flow`]). With u held, the flow of a location from x is exact
//! (x(s) = e^{As}x + ∫₀ˢe^{Aτ}dτ (Bu + c), the ZOH of length s). An internal edge fires at the first
//! instant its guard is entered: where φ(s) = max_j (a_jᵀx(s) − b_j)/‖a_j‖ reaches 0 from above. φ is
//! Lipschitz along the flow with constant ‖ẋ‖ (the guard rows are normalised), and with u held ẍ = Aẋ,
//! so on [s₀, s₀ + Δ] ‖ẋ‖ ≤ e^{‖A‖_F Δ}‖ẋ(s₀)‖ =: L. Hence min φ ≥ (φ(s₀) + φ(s₀+Δ) − LΔ)/2 on the
//! interval: when that is positive the interval holds no event, otherwise it is halved. The first entry
//! is located to [`Hybrid::EVENT_TOLERANCE`]·h; a tangency that dips into a guard by less than
//! L·tolerance can go unseen, and nothing larger can. A flow that slides along a guard closer than the
//! tolerance resolves would need ever more halvings: after [`Hybrid::MAX_PROBES_PER_PERIOD`] evaluations
//! in one period the step is refused as undecided. The reset is applied at the event and the flow
//! continues in the new location with the same input for the rest of the period.
//!
//! As a [`Plant`], each location is its own linear affine plant sampled by an exact ZOH (the error
//! dynamics its CAF is designed for, §3.2 (3.69)); [`Plant::step`] is the flow of one location without
//! events, which is what a forced-switching run does between the controller's switches. The flow across
//! internal events is [`Hybrid::flow`].
//!
//! An edge is *armed* once φ > 0 has been seen in the current location (at its entry point or a later
//! probe): right after a reset onto the boundary of a guard back (x₁ = 0 in Example 3.19), the state
//! sits on that guard and must leave it before it can enter it again. At most
//! [`Hybrid::MAX_EVENTS_PER_PERIOD`] events are taken in one period; more is reported as Zeno
//! behaviour, not simulated.

use super::{check_len, ContinuousPlant, DiscretePlant, LinearAffine, Location, ModelError, Plant};
use faer::Mat;

/// A polytope {x : a_jᵀx ≤ b_j, j = 1..k} over the state (a guard or an invariant).
#[derive(Clone, Debug, PartialEq)]
pub struct Polytope {
    /// The rows a_j (each of length n, non-zero).
    pub a: Vec<Vec<f64>>,
    pub b: Vec<f64>,
}

impl Polytope {
    /// max_j (a_jᵀx − b_j)/‖a_j‖: ≤ 0 exactly inside; the Euclidean distance to the nearest violated
    /// face's plane outside (a lower bound on the distance to the polytope).
    pub fn margin(&self, x: &[f64]) -> f64 {
        self.a
            .iter()
            .zip(&self.b)
            .map(|(a, b)| {
                let ax: f64 = a.iter().zip(x).map(|(p, q)| p * q).sum();
                let na = a.iter().map(|v| v * v).sum::<f64>().sqrt();
                (ax - b) / na
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }
    /// Membership (closed).
    pub fn contains(&self, x: &[f64]) -> bool {
        self.margin(x) <= 0.0
    }
}

/// x ↦ R x + r.
#[derive(Clone, Debug, PartialEq)]
pub struct Reset {
    pub R: Mat<f64>,
    pub r: Vec<f64>,
}

impl Reset {
    /// The identity reset in ℝⁿ.
    pub fn identity(n: usize) -> Self {
        Self {
            R: Mat::identity(n, n),
            r: vec![0.0; n],
        }
    }
    /// Whether this is exactly x ↦ x.
    pub fn is_identity(&self) -> bool {
        let n = self.R.nrows();
        self.R.ncols() == n
            && (0..n).all(|i| (0..n).all(|j| self.R[(i, j)] == if i == j { 1.0 } else { 0.0 }))
            && self.r.iter().all(|&v| v == 0.0)
    }
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        (0..self.R.nrows())
            .map(|i| (0..x.len()).map(|j| self.R[(i, j)] * x[j]).sum::<f64>() + self.r[i])
            .collect()
    }
}

/// Who takes an edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum EdgeKind {
    /// Taken by the flow when it enters the guard (§4.2.2).
    Internal,
    /// Taken when the controller chooses it, with the state in the guard (§4.2.1).
    Forced,
}

/// An edge ℓ → ℓ′ of the automaton.
#[derive(Clone, Debug, PartialEq)]
pub struct Edge {
    pub from: Location,
    pub to: Location,
    pub guard: Polytope,
    pub reset: Reset,
    pub kind: EdgeKind,
}

/// One location: its flow and invariant.
#[derive(Clone, Debug, PartialEq)]
pub struct Mode {
    pub name: String,
    pub flow: ContinuousPlant,
    pub invariant: Option<Polytope>,
}

/// A hybrid automaton over continuous-time linear affine locations, sampled with period h (module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Hybrid {
    modes: Vec<Mode>,
    edges: Vec<Edge>,
    period: f64,
    /// ‖A_ℓ‖_F per location (the growth rate of ‖ẋ‖ along the flow).
    growth: Vec<f64>,
    /// Each location sampled with the period (exact ZOH).
    sampled: Vec<LinearAffine>,
    /// Per location, the exact ZOH of each sub-step [`Hybrid::flow`] probes a period with when it starts
    /// at the sample (keyed by the length's bits, so a hit is the very matrix `zoh` would compute).
    probes: Vec<Vec<(u64, DiscretePlant)>>,
    /// Per location, its internal edges in the spec's order (the ones [`Hybrid::flow`] watches).
    internal: Vec<Vec<usize>>,
}

/// Why an automaton is malformed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HybridError {
    #[error("an automaton needs at least one location")]
    NoLocations,
    #[error("internal edge {edge} has a guard without rows (the whole space): the flow would take it at once")]
    EmptyInternalGuard { edge: usize },
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error("location `{name}` has n = {n}, m = {m}; location `{first}` has n = {n0}, m = {m0}")]
    Dimensions {
        name: String,
        n: usize,
        m: usize,
        first: String,
        n0: usize,
        m0: usize,
    },
    #[error("edge {edge}: location index {index} does not exist ({locations} locations)")]
    UnknownLocation {
        edge: usize,
        index: usize,
        locations: usize,
    },
    #[error("{what}: row {row} has {found} entries, the state has n = {n}")]
    RowLength {
        what: String,
        row: usize,
        found: usize,
        n: usize,
    },
    #[error("{what}: row {row} is zero or not finite")]
    BadRow { what: String, row: usize },
    #[error("{what}: {rows} rows but {bs} right-hand sides")]
    RhsLength {
        what: String,
        rows: usize,
        bs: usize,
    },
    #[error("edge {edge}: the reset must be n×n with an offset of length n (n = {n})")]
    ResetShape { edge: usize, n: usize },
}

/// Why a period could not be simulated.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FlowError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error("location {0} does not exist")]
    UnknownLocation(Location),
    #[error("more than {max} events in one period from location {loc} (Zeno behaviour)")]
    Zeno { loc: Location, max: usize },
    #[error("the flow left the finite numbers in location {0}")]
    NonFinite(Location),
    /// The flow runs so close to a guard for so long that deciding whether it enters would take more
    /// than [`Hybrid::MAX_PROBES_PER_PERIOD`] exact-flow evaluations.
    #[error(
        "in location {loc} the flow grazes a guard too closely to decide within {max} evaluations of the \
         exact flow in one period"
    )]
    Undecided { loc: Location, max: usize },
}

/// An event the flow took inside a period.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// Seconds after the sample.
    pub time: f64,
    /// Index into [`Hybrid::edges`].
    pub edge: usize,
    /// The state reaching the guard (before the reset).
    pub before: Vec<f64>,
}

/// One period of the hybrid flow.
#[derive(Clone, Debug, PartialEq)]
pub struct HybridStep {
    pub loc: Location,
    pub x: Vec<f64>,
    pub events: Vec<Event>,
}

fn check_polytope(p: &Polytope, n: usize, what: &str) -> Result<(), HybridError> {
    if p.a.len() != p.b.len() {
        return Err(HybridError::RhsLength {
            what: what.into(),
            rows: p.a.len(),
            bs: p.b.len(),
        });
    }
    for (row, a) in p.a.iter().enumerate() {
        if a.len() != n {
            return Err(HybridError::RowLength {
                what: what.into(),
                row,
                found: a.len(),
                n,
            });
        }
        let norm = a.iter().map(|v| v * v).sum::<f64>();
        if !(norm > 0.0 && norm.is_finite() && p.b[row].is_finite()) {
            return Err(HybridError::BadRow {
                what: what.into(),
                row,
            });
        }
    }
    Ok(())
}

impl Hybrid {
    /// Events are located to this fraction of the period.
    pub const EVENT_TOLERANCE: f64 = 1e-12;
    /// Events taken in one period before the flow is declared Zeno.
    pub const MAX_EVENTS_PER_PERIOD: usize = 16;
    /// Probes per period (each probe interval is then halved only where an event may lie).
    const PROBES: usize = 8;
    /// Exact-flow evaluations the event search may spend in one period (a flow that slides along a guard
    /// at a distance near the tolerance would otherwise halve without end).
    pub const MAX_PROBES_PER_PERIOD: usize = 20_000;

    /// A checked automaton: every location of the same n and m, edges between existing locations,
    /// guards and invariants with rows of length n, resets n×n.
    pub fn new(modes: Vec<Mode>, edges: Vec<Edge>, period: f64) -> Result<Self, HybridError> {
        let first = modes.first().ok_or(HybridError::NoLocations)?;
        if !(period.is_finite() && period > 0.0) {
            return Err(ModelError::Period(period).into());
        }
        let (n0, m0) = (first.flow.n(), first.flow.m());
        for mode in &modes {
            let (n, m) = (mode.flow.n(), mode.flow.m());
            if (n, m) != (n0, m0) {
                return Err(HybridError::Dimensions {
                    name: mode.name.clone(),
                    n,
                    m,
                    first: first.name.clone(),
                    n0,
                    m0,
                });
            }
            if let Some(inv) = &mode.invariant {
                check_polytope(inv, n0, &format!("invariant of `{}`", mode.name))?;
            }
        }
        for (e, edge) in edges.iter().enumerate() {
            for index in [edge.from, edge.to] {
                if index >= modes.len() {
                    return Err(HybridError::UnknownLocation {
                        edge: e,
                        index,
                        locations: modes.len(),
                    });
                }
            }
            check_polytope(&edge.guard, n0, &format!("guard of edge {e}"))?;
            // A forced edge's guard may be the whole space (no rows); an internal one would fire at once.
            if edge.kind == EdgeKind::Internal && edge.guard.a.is_empty() {
                return Err(HybridError::EmptyInternalGuard { edge: e });
            }
            let R = &edge.reset.R;
            if R.nrows() != n0 || R.ncols() != n0 || edge.reset.r.len() != n0 {
                return Err(HybridError::ResetShape { edge: e, n: n0 });
            }
            super::check_finite("reset R", R.as_ref())?;
            check_len("reset r", &edge.reset.r, n0)?;
        }
        let growth = modes.iter().map(|m| m.flow.A.norm_l2()).collect();
        let sampled = modes
            .iter()
            .map(|m| LinearAffine::sampled(m.flow.clone(), period))
            .collect::<Result<_, _>>()?;
        let lengths = Self::probe_lengths(period);
        let probes = modes
            .iter()
            .map(|m| {
                let mut v: Vec<(u64, DiscretePlant)> = Vec::new();
                for &s in &lengths {
                    if s > 0.0 && !v.iter().any(|(b, _)| *b == s.to_bits()) {
                        v.push((s.to_bits(), m.flow.zoh(s)?));
                    }
                }
                Ok(v)
            })
            .collect::<Result<_, ModelError>>()?;
        let internal = (0..modes.len())
            .map(|l| {
                (0..edges.len())
                    .filter(|&e| edges[e].from == l && edges[e].kind == EdgeKind::Internal)
                    .collect()
            })
            .collect();
        Ok(Self {
            modes,
            edges,
            period,
            growth,
            sampled,
            probes,
            internal,
        })
    }

    /// The sub-step lengths [`Hybrid::flow`] probes a period with from its start, computed as it
    /// computes them.
    fn probe_lengths(h: f64) -> Vec<f64> {
        let mut s0 = 0.0;
        (1..=Self::PROBES)
            .map(|i| {
                let s1 = Self::probe_end(h, 0.0, i);
                let d = s1 - s0;
                s0 = s1;
                d
            })
            .collect()
    }

    /// The end of probe `i` (1..=PROBES) of the rest [t, h] of a period, as [`Hybrid::flow`] steps it.
    fn probe_end(h: f64, t: f64, i: usize) -> f64 {
        if i == Self::PROBES {
            h
        } else {
            t + i as f64 * ((h - t) / Self::PROBES as f64)
        }
    }

    /// The forced edge `from` → `to`, the one a controller that moves to location `to` takes (§4.2.1).
    pub fn forced_edge(&self, from: Location, to: Location) -> Option<&Edge> {
        self.edge_index(from, to, EdgeKind::Forced)
            .map(|e| &self.edges[e])
    }

    /// The index of the edge of `kind` from `from` to `to`: the first in the spec's order, the one the
    /// plant takes, the certificate joins segments by and the re-proof from the image finds.
    pub fn edge_index(&self, from: Location, to: Location, kind: EdgeKind) -> Option<usize> {
        self.edges
            .iter()
            .position(|e| e.from == from && e.to == to && e.kind == kind)
    }

    pub fn modes(&self) -> &[Mode] {
        &self.modes
    }
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }
    pub fn period(&self) -> f64 {
        self.period
    }

    /// The same automaton sampled with another period (e.g. a fraction of h, to look between samples).
    pub fn resampled(&self, period: f64) -> Result<Self, HybridError> {
        Self::new(self.modes.clone(), self.edges.clone(), period)
    }

    /// The state after `s` seconds of location `loc`'s flow from `x` with `u` held (exact ZOH of length s).
    fn advance(&self, loc: Location, x: &[f64], u: &[f64], s: f64) -> Result<Vec<f64>, FlowError> {
        let mut y = vec![0.0; x.len()];
        self.advance_into(loc, x, u, s, &mut y)?;
        Ok(y)
    }

    /// [`Hybrid::advance`] into `y` (n values).
    fn advance_into(
        &self,
        loc: Location,
        x: &[f64],
        u: &[f64],
        s: f64,
        y: &mut [f64],
    ) -> Result<(), FlowError> {
        if s <= 0.0 {
            y.copy_from_slice(x);
            return Ok(());
        }
        let cached = self.probes[loc].iter().find(|(b, _)| *b == s.to_bits());
        match cached {
            Some((_, d)) => d.step_into(x, u, y),
            None => self.modes[loc].flow.zoh(s)?.step_into(x, u, y),
        };
        if y.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(FlowError::NonFinite(loc))
        }
    }

    /// The first instant in [s0, s1] at which the flow from (s0, x0) enters `guard`, found by halving
    /// only the intervals the Lipschitz bound cannot clear (module doc).
    #[allow(clippy::too_many_arguments)]
    fn first_entry(
        &self,
        loc: Location,
        u: &[f64],
        guard: &Polytope,
        (s0, x0, p0): (f64, &[f64], f64),
        (s1, x1, p1): (f64, &[f64], f64),
        tol: f64,
        budget: &mut usize,
    ) -> Result<Option<(f64, Vec<f64>)>, FlowError> {
        if p0 <= 0.0 {
            return Ok(Some((s0, x0.to_vec())));
        }
        let dt = s1 - s0;
        let speed = self.modes[loc].flow.f_norm(x0, u);
        let lip = speed * (self.growth[loc] * dt).exp();
        if (p0 + p1 - lip * dt) / 2.0 > 0.0 {
            return Ok(None);
        }
        if dt <= tol {
            // Within the tolerance: an entry if the right end is inside, otherwise a graze shallower
            // than L·tol (module doc).
            return Ok((p1 <= 0.0).then(|| (s1, x1.to_vec())));
        }
        if *budget == 0 {
            return Err(FlowError::Undecided {
                loc,
                max: Self::MAX_PROBES_PER_PERIOD,
            });
        }
        *budget -= 1;
        let sm = s0 + dt / 2.0;
        let xm = self.advance(loc, x0, u, sm - s0)?;
        let pm = guard.margin(&xm);
        if let Some(hit) =
            self.first_entry(loc, u, guard, (s0, x0, p0), (sm, &xm, pm), tol, budget)?
        {
            return Ok(Some(hit));
        }
        self.first_entry(loc, u, guard, (sm, &xm, pm), (s1, x1, p1), tol, budget)
    }

    /// One sample period from (`loc`, `x`) with `u` held: the exact flow, every internal edge taken at the
    /// instant its guard is entered (module doc), resets applied.
    pub fn flow(&self, loc: Location, x: &[f64], u: &[f64]) -> Result<HybridStep, FlowError> {
        if loc >= self.modes.len() {
            return Err(FlowError::UnknownLocation(loc));
        }
        let h = self.period;
        let tol = Self::EVENT_TOLERANCE * h;
        let (mut loc, mut x, mut t) = (loc, x.to_vec(), 0.0f64);
        let mut events = Vec::new();
        let mut budget = Self::MAX_PROBES_PER_PERIOD;
        // The probe's ends, kept across probes (swapped, not reallocated).
        let mut x1 = vec![0.0; x.len()];
        'segment: loop {
            let internal = &self.internal[loc];
            let mut armed: Vec<bool> = internal
                .iter()
                .map(|&e| self.edges[e].guard.margin(&x) > 0.0)
                .collect();
            let (mut s0, mut x0) = (t, x.clone());
            for i in 1..=Self::PROBES {
                let s1 = Self::probe_end(h, t, i);
                self.advance_into(loc, &x0, u, s1 - s0, &mut x1)?;
                // The earliest entry over the armed edges in [s0, s1] (ties: the first edge listed).
                let mut hit: Option<(f64, Vec<f64>, usize)> = None;
                for (j, &e) in internal.iter().enumerate() {
                    let g = &self.edges[e].guard;
                    let (p0, p1) = (g.margin(&x0), g.margin(&x1));
                    if !armed[j] {
                        armed[j] = p1 > 0.0;
                        continue;
                    }
                    if let Some((s, xe)) =
                        self.first_entry(loc, u, g, (s0, &x0, p0), (s1, &x1, p1), tol, &mut budget)?
                    {
                        if hit.as_ref().is_none_or(|(sh, _, _)| s < *sh) {
                            hit = Some((s, xe, e));
                        }
                    }
                }
                if let Some((s, before, e)) = hit {
                    if events.len() == Self::MAX_EVENTS_PER_PERIOD {
                        return Err(FlowError::Zeno {
                            loc,
                            max: Self::MAX_EVENTS_PER_PERIOD,
                        });
                    }
                    let edge = &self.edges[e];
                    x = edge.reset.apply(&before);
                    loc = edge.to;
                    t = s;
                    events.push(Event {
                        time: s,
                        edge: e,
                        before,
                    });
                    if t >= h {
                        break 'segment;
                    }
                    continue 'segment;
                }
                s0 = s1;
                std::mem::swap(&mut x0, &mut x1);
            }
            x = x0;
            break;
        }
        Ok(HybridStep { loc, x, events })
    }
}

impl Plant for Hybrid {
    fn n(&self) -> usize {
        self.sampled[0].n()
    }
    fn m(&self) -> usize {
        self.sampled[0].m()
    }
    fn period(&self) -> f64 {
        self.period
    }
    fn locations(&self) -> usize {
        self.modes.len()
    }
    fn error_dynamics(&self, loc: Location) -> &DiscretePlant {
        &self.sampled[loc].discrete
    }
    fn continuous(&self, loc: Location) -> Option<&ContinuousPlant> {
        Some(&self.modes[loc].flow)
    }
    /// The flow of location `loc` alone (module doc).
    fn step(&self, loc: Location, x: &[f64], u: &[f64]) -> Vec<f64> {
        self.sampled[loc].step(0, x, u)
    }
    fn between_samples(&self, loc: Location, x: &[f64], u: &[f64], visit: &mut dyn FnMut(&[f64])) {
        self.sampled[loc].between_samples(0, x, u, visit)
    }
    fn excursion(&self, loc: Location, x: &[f64], u: &[f64]) -> Option<f64> {
        self.sampled[loc].excursion(0, x, u)
    }
}

impl Hybrid {
    /// The automaton of a validated spec (`spec::hybrid`), sampled with `period`.
    pub fn from_spec(h: &crate::spec::HybridDesc, period: f64) -> Result<Self, HybridError> {
        use crate::spec::EdgeKindDesc;
        let polytope = |p: &crate::spec::PolytopeDesc| Polytope {
            a: (0..p.A.rows)
                .map(|i| (0..p.A.cols).map(|j| p.A.get(i, j)).collect())
                .collect(),
            b: p.b.clone(),
        };
        let modes = h
            .locations
            .iter()
            .map(|l| {
                Ok(Mode {
                    name: l.name.clone(),
                    flow: ContinuousPlant::new(l.A.to_faer(), l.B.to_faer(), l.c.clone())?,
                    invariant: l.invariant.as_ref().map(polytope),
                })
            })
            .collect::<Result<Vec<_>, ModelError>>()?;
        let edges = h
            .edges
            .iter()
            .map(|e| Edge {
                from: e.from,
                to: e.to,
                guard: polytope(&e.guard),
                reset: Reset {
                    R: e.R.to_faer(),
                    r: e.r.clone(),
                },
                kind: match e.kind {
                    EdgeKindDesc::Internal => EdgeKind::Internal,
                    EdgeKindDesc::Forced => EdgeKind::Forced,
                },
            })
            .collect();
        Self::new(modes, edges, period)
    }
}
