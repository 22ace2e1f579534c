//! Automatic trajectory generation: from one initial state, find reference inputs v(0..N) that drive the
//! closed loop u = K x + v into Goal at step N while a tube of CAF radius δ around the trajectory keeps
//! clear of Unsafe and inside the input bounds — and make δ as large as possible.
//!
//! The conditions are those of Theorem 4.7 written for a ball ‖x − x̃(κ)‖_P ≤ δ around each sample:
//!
//! * Goal (4.13): the δ-ball around x̃(N) lies in Goal. For an ellipsoid {(Cx−c)ᵀQ(Cx−c) ≤ 1} this is implied
//!   by ‖Q^{1/2}(Cx̃(N)−c)‖ + δ‖Q^{1/2}CP^{-1/2}‖ ≤ 1 (a second-order cone); for a polytope by
//!   hᵢᵀx̃(N) + δ‖hᵢ‖_{P⁻¹} ≤ bᵢ.
//! * Unsafe (4.14): each convex piece is replaced by a supporting half-space {nᵀ(x − p) ≤ 0} ⊇ piece, taken at
//!   a boundary point p chosen from the previous iterate; staying δγ + ρ away from the half-space in the
//!   P-metric keeps the tube (and the inter-sample excursion ρ, grown by γ) out of the piece.
//! * Input (4.15): u = K(x̃ + e) + ṽ for ‖e‖_P ≤ δ stays in the input set shrunk by the rounding margin.
//!
//! Because every half-space contains its piece, each iterate is feasible for the true problem; iterating
//! (sequential convex programming) moves the linearisation points with the trajectory. The first iterate
//! ignores Unsafe, so it may run straight through a piece; the half-spaces at the nearest boundary points
//! of the samples inside it then push the samples before the piece's centre out one side and those after
//! it out the other, which no input within the bounds may achieve. And a fast run is held off every face
//! by the isotropic inter-sample excursion, its speed along the face counted against it (Example 4.20's
//! discs, passed at 8 m/s, are kept 1–2 m further off than the run can move towards them in a period).
//! When the iteration fails, it is run again with one half-space per crossing, on the side the crossing
//! already passes ([`crossing_halfspace`]), and with the drift against each half-space's normal
//! ([`crate::model::drift_against`]) where it is smaller. The first pass is kept as it is so that what it
//! proposes does not change. [`generate_from`] starts instead from a given first linearisation point, a
//! timed reference along a route of the global search ([`super::route`]), so that the first subproblem
//! already holds the route's side of every piece (the route's homotopy class). Each subproblem is a
//! second-order cone program solved with clarabel. The certified δ is computed afterwards, independently,
//! by the robustness library; this module only proposes trajectories.

use super::{simulate, Nominal};
use crate::linalg::{mat_vec, p_norm, spectral_norm, sym_fn, PdRoots};
use crate::model::{DiscretePlant, Plant};
use crate::property::{ConvexSets, ReachAvoid};
use crate::settings::{settings_builder, Check, SettingError};
use crate::solver::SetupError;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
    SupportedConeT::{NonnegativeConeT, SecondOrderConeT, ZeroConeT},
};
use faer::MatRef;

pub use crate::property::{ConvexPiece, InputBound};

/// Settings of the generator, with documented defaults. Build with [`GenSettings::builder`] (validated) or
/// take [`Default`].
#[derive(Clone, Debug)]
pub struct GenSettings {
    /// Sequential-convex iterations at most. ≥ 1. Default 12.
    pub max_iter: usize,
    /// Stop when δ improves by less than this, relative. Finite, ≥ 0. Default 1e-4.
    pub tol: f64,
    /// Weight of Σ‖v(κ+1) − v(κ)‖² against δ, for smooth inputs. Finite, ≥ 0. Default 1e-4.
    pub smooth_weight: f64,
    /// Upper bound on δ in the subproblems, keeping them bounded. Finite, > 0. Default 10.
    pub delta_max: f64,
    /// The tolerance (relative and absolute) at which clarabel's iterative refinement of each KKT solve
    /// stops; `None`: clarabel's defaults (10⁻¹³ relative, 10⁻¹² absolute). A subproblem only proposes a
    /// trajectory, which is certified afterwards, so a looser refinement changes proposals, never what
    /// is certified. Finite, > 0 when given. Default `None`.
    pub refinement_tol: Option<f64>,
}

impl Default for GenSettings {
    fn default() -> Self {
        Self {
            max_iter: 12,
            tol: 1e-4,
            smooth_weight: 1e-4,
            delta_max: 10.0,
            refinement_tol: None,
        }
    }
}

impl GenSettings {
    /// Checks the ranges documented on the fields; the first violation is returned.
    pub fn validate(&self) -> Result<(), SettingError> {
        let c = Check("GenSettings");
        c.at_least_one("max_iter", self.max_iter)?;
        c.non_negative("tol", self.tol)?;
        c.non_negative("smooth_weight", self.smooth_weight)?;
        c.positive("delta_max", self.delta_max)?;
        match self.refinement_tol {
            Some(t) => c.positive("refinement_tol", t),
            None => Ok(()),
        }
    }
}

settings_builder!(
    GenSettings,
    GenSettingsBuilder {
        max_iter: usize,
        tol: f64,
        smooth_weight: f64,
        delta_max: f64,
        refinement_tol: Option<f64>,
    }
);

/// What the generator needs of the task.
pub struct GenProblem<'a> {
    /// The plant; the nominal is simulated with the sampled model x⁺ = A x + B u + g of location `loc`.
    pub plant: &'a dyn Plant,
    pub loc: crate::model::Location,
    /// Feedback and CAF metric.
    pub K: MatRef<'a, f64>,
    pub P: MatRef<'a, f64>,
    /// The input set.
    pub property: &'a ReachAvoid,
    /// Goal and Unsafe as convex pieces.
    pub convex: &'a ConvexSets,
    /// Number of steps N; Goal is required at step N.
    pub steps: usize,
    /// Inter-sample growth of the tube radius γ and the constants φ, β of the inter-sample bound (1, 0, 0
    /// for discrete-time plants; `certify::LoopConstants`).
    pub gamma: f64,
    pub phi: f64,
    pub beta: f64,
    /// Margin subtracted from the input bounds (f32 rounding of the evaluator).
    pub input_margin: f64,
    /// A forced-switching schedule ([`Schedule`]); `None`: every step in `loc` under `K` and `P`.
    pub schedule: Option<&'a Schedule<'a>>,
}

/// A forced-switching schedule (§4.2.1): the location of every step κ < N and, per location, its gain
/// and metric. Step κ is then simulated in `loc[κ]`'s sampled model under that location's gain, and
/// sample κ's tube and input conditions are written in its metric (sample N in the last step's): the one
/// radius δ is read in each location's metric. This only proposes a run; its certificate
/// (`certify::forced`) accounts for the change of metric at each switch. γ, φ and β are then the
/// largest over the locations the caller passes.
pub struct Schedule<'a> {
    pub loc: Vec<crate::model::Location>,
    /// Gain and metric per location (index = location).
    pub K: Vec<MatRef<'a, f64>>,
    pub P: Vec<MatRef<'a, f64>>,
}

/// What [`GenError::Infeasible`] says: what the search it ran can and cannot find, and what to do. The
/// generator is local (module doc): an infeasible subproblem proves nothing about the task.
fn infeasible_text(
    x0: &[f64],
    steps: &usize,
    status: &SubproblemStatus,
    switches: &Option<usize>,
) -> String {
    let along = match switches {
        Some(k) => format!(
            " along a schedule of {k} location switch{} (the forced planner tries staying, then one switch \
             per forced edge, and many-switch schedules only when none of those certifies and its \
             schedule search runs)",
            if *k == 1 { "" } else { "es" }
        ),
        None => String::new(),
    };
    format!(
        "the local generator found no trajectory from x0 = {x0:?} into Goal in {steps} steps within the \
         input bounds{along} (solver: {status}). This is not a proof that none exists: each of its \
         subproblems keeps the run on the side of every Unsafe piece that its previous iterate was on, \
         starting from a run that ignores Unsafe, so a way around a wall that run crosses is not found. \
         To go on: give a route with `synth --import` (its states, applied inputs or references), play \
         one with `host-compiler play`, allow a longer horizon T, or let the routes of the global search \
         propose the way (a one-location task asks them where this generator fails; an automaton with internal \
         switching with `synth --guard-routes`)"
    )
}

impl GenProblem<'_> {
    /// The number of location switches of the schedule, when there is one.
    fn switches(&self) -> Option<usize> {
        self.schedule
            .map(|s| s.loc.windows(2).filter(|w| w[0] != w[1]).count())
    }

    /// The location of step κ (the last step's for κ ≥ N).
    fn loc_at(&self, k: usize) -> crate::model::Location {
        match self.schedule {
            None => self.loc,
            Some(s) => s
                .loc
                .get(k.min(s.loc.len().saturating_sub(1)))
                .copied()
                .unwrap_or(self.loc),
        }
    }

    fn model_at(&self, k: usize) -> &DiscretePlant {
        self.plant.error_dynamics(self.loc_at(k))
    }

    fn K_at(&self, k: usize) -> MatRef<'_, f64> {
        match self.schedule {
            None => self.K,
            Some(s) => s.K[self.loc_at(k)],
        }
    }

    fn P_at(&self, k: usize) -> MatRef<'_, f64> {
        match self.schedule {
            None => self.P,
            Some(s) => s.P[self.loc_at(k)],
        }
    }

    /// The metric of sample κ and its roots (index into `roots`).
    fn metric_at(&self, k: usize) -> usize {
        self.schedule.map_or(0, |_| self.loc_at(k))
    }

    /// Roots of every metric `metric_at` indexes, or `None` if one is not positive definite.
    fn roots(&self) -> Option<Vec<PdRoots>> {
        match self.schedule {
            None => Some(vec![PdRoots::new(self.P)?]),
            Some(s) => s.P.iter().map(|P| PdRoots::new(*P)).collect(),
        }
    }

    /// The nominal from `x0` under `v`, each step in its location.
    fn simulate(&self, x0: &[f64], v: &[Vec<f64>]) -> Nominal {
        if self.schedule.is_none() {
            return simulate(self.model_at(0), self.K, x0, v);
        }
        let mut nom = Nominal {
            x: vec![x0.to_vec()],
            v: v.to_vec(),
            u: Vec::with_capacity(v.len()),
        };
        for (k, vk) in v.iter().enumerate() {
            let step = simulate(
                self.model_at(k),
                self.K_at(k),
                &nom.x[k],
                std::slice::from_ref(vk),
            );
            nom.u.push(step.u[0].clone());
            nom.x.push(step.x[1].clone());
        }
        nom
    }

    /// The nominal's drift over the period after sample κ ([`Drift`]), in the metric of sample κ; with
    /// `directional` false only the isotropic bound is taken.
    fn drift(&self, k: usize, x: &[f64], u: &[f64], roots: &PdRoots, directional: bool) -> Drift {
        let loc = self.loc_at(k);
        let (Some(f), Some(cp)) = (
            self.plant.vector_field(loc, x, u),
            self.plant.continuous(loc),
        ) else {
            return Drift::default();
        };
        let f_p = p_norm(self.P_at(k), &f);
        Drift {
            a_f: mat_vec(cp.A.as_ref(), &f),
            f,
            f_p,
            a_p: roots.induced_norm(cp.A.as_ref()),
            h: self.plant.period(),
            phi: self.phi,
            beta_margin: self.beta * self.input_margin,
            directional,
        }
    }
}

/// The nominal's motion within one period after a sample (continuous-time plants; zero for discrete-time
/// ones): the vector field f at the sample, A f, their norms, and the held input's margin.
#[derive(Default)]
struct Drift {
    f: Vec<f64>,
    a_f: Vec<f64>,
    f_p: f64,
    a_p: f64,
    h: f64,
    phi: f64,
    /// β·margin: the held input's rounding margin through B_c.
    beta_margin: f64,
    directional: bool,
}

impl Drift {
    /// How far it moves the state against the direction `n` (‖n‖_{P⁻¹} = `dn`), in units of nᵀx: the
    /// isotropic bound ‖n‖_{P⁻¹}φ‖f‖_P, or the smaller of it and the directional one
    /// ([`crate::model::drift_against`]), plus the held input's margin.
    fn against(&self, n: &[f64], dn: f64) -> f64 {
        if self.f.is_empty() {
            return 0.0;
        }
        if !self.directional {
            // ‖n‖_{P⁻¹}ρ with ρ = φ(‖f‖_P + β·margin), evaluated as the first pass always has.
            return dn * (self.phi * (self.f_p + self.beta_margin));
        }
        let isotropic = dn * self.phi * self.f_p;
        isotropic.min(crate::model::drift_against(
            n, &self.f, &self.a_f, self.h, dn, self.f_p, self.a_p,
        )) + dn * self.phi * self.beta_margin
    }
}

/// A generated trajectory.
#[derive(Clone, Debug)]
pub struct Generated {
    pub nominal: Nominal,
    /// The tube radius the last convex subproblem certified (a lower bound on Theorem 4.7's δ).
    pub delta_lin: f64,
    pub iterations: usize,
}

/// Why the sequential-convex iteration stopped without a trajectory: the outcome of its last subproblem.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SubproblemStatus {
    /// Clarabel ran and ended without a solution (infeasible, iteration limit, numerical trouble).
    #[error("{0:?}")]
    Solver(SolverStatus),
    /// Clarabel refused to set the subproblem up.
    #[error("{0}")]
    Setup(#[from] SetupError),
    /// The Goal ellipsoid's shape matrix Q has no real square root Q^{1/2} (its eigen-decomposition failed).
    #[error("goal shape has no square root")]
    GoalShape,
    /// Only the first subproblem, which ignores Unsafe, was solved: no iterate is safe.
    #[error("no iterate with Unsafe constraints")]
    NoUnsafeIterate,
}

/// Why no trajectory was found.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum GenError {
    #[error(transparent)]
    Settings(#[from] SettingError),
    #[error("{}", infeasible_text(.x0, .steps, .status, .switches))]
    Infeasible {
        x0: Vec<f64>,
        steps: usize,
        status: SubproblemStatus,
        /// The number of location switches of the schedule searched along (forced switching); `None`
        /// for one location.
        switches: Option<usize>,
    },
    #[error("the CAF matrix P is not positive definite")]
    BadMetric,
    #[error(
        "dimension mismatch: n = {n}, m = {m}, x0 has {x0}, K is {k_rows}×{k_cols} (expected {m}×{n})"
    )]
    Dimension {
        /// States and inputs of the plant.
        n: usize,
        m: usize,
        /// Entries of x0.
        x0: usize,
        /// Shape of the feedback gain K.
        k_rows: usize,
        k_cols: usize,
    },
}

/// Generate a trajectory from `x0` that maximises the tube radius δ (see the module doc).
pub fn generate(
    prob: &GenProblem<'_>,
    x0: &[f64],
    settings: &GenSettings,
) -> Result<Generated, GenError> {
    settings.validate()?;
    let model = prob.model_at(0);
    let n = model.n();
    let m = model.m();
    if x0.len() != n || prob.K.nrows() != m || prob.K.ncols() != n {
        return Err(GenError::Dimension {
            n,
            m,
            x0: x0.len(),
            k_rows: prob.K.nrows(),
            k_cols: prob.K.ncols(),
        });
    }
    let roots = prob.roots().ok_or(GenError::BadMetric)?;
    match iterate(prob, &roots, x0, settings, Sides::Nearest, None) {
        Err(e) if !prob.convex.unsafe_pieces.is_empty() => {
            // A first iterate through Unsafe can get half-spaces that exclude each other (module doc):
            // the second pass takes one side per crossing. Tried only when the first fails, so every
            // trajectory the first pass finds is proposed as before.
            iterate(prob, &roots, x0, settings, Sides::PerCrossing, None).map_err(|_| e)
        }
        r => r,
    }
}

/// [`generate`] from a given first linearisation point `guess` (a timed reference along a route,
/// [`super::route::timed_guess`]) instead of the first iterate that ignores Unsafe: the first subproblem
/// already keeps the samples on the side of each piece the guess passes, so the trajectory stays in the
/// guess's homotopy class. `guess.x` must hold N + 1 states of the plant's dimension and `guess.u` N
/// inputs (only its states and inputs are read).
pub fn generate_from(
    prob: &GenProblem<'_>,
    x0: &[f64],
    settings: &GenSettings,
    guess: &Nominal,
) -> Result<Generated, GenError> {
    settings.validate()?;
    let model = prob.model_at(0);
    let n = model.n();
    let m = model.m();
    let fits = guess.x.len() == prob.steps + 1
        && guess.u.len() == prob.steps
        && guess.x.iter().all(|x| x.len() == n)
        && guess.u.iter().all(|u| u.len() == m);
    if x0.len() != n || prob.K.nrows() != m || prob.K.ncols() != n || !fits {
        return Err(GenError::Dimension {
            n,
            m,
            x0: x0.len(),
            k_rows: prob.K.nrows(),
            k_cols: prob.K.ncols(),
        });
    }
    let roots = prob.roots().ok_or(GenError::BadMetric)?;
    iterate(
        prob,
        &roots,
        x0,
        settings,
        Sides::Nearest,
        Some(guess.clone()),
    )
}

/// How the Unsafe rows of a subproblem are written from an iterate (module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Sides {
    /// Each sample's half-space at the boundary point nearest it, kept clear by the isotropic
    /// inter-sample excursion ‖n‖_{P⁻¹}φ‖f‖_P.
    Nearest,
    /// Outside the piece as `Nearest`; the samples of one crossing (a maximal run of consecutive samples
    /// inside the piece) share one half-space, on the side of the piece the crossing passes. The
    /// excursion is the smaller of the isotropic one and the drift against the half-space's normal
    /// ([`crate::model::drift_against`]), so a fast run is not held off every face by its speed along
    /// the others.
    PerCrossing,
}

/// The sequential convex iteration of [`generate`] with one rule for the Unsafe half-spaces.
fn iterate(
    prob: &GenProblem<'_>,
    roots: &[PdRoots],
    x0: &[f64],
    settings: &GenSettings,
    sides: Sides,
    guess: Option<Nominal>,
) -> Result<Generated, GenError> {
    let mut best: Option<Generated> = None;
    // Without a guess, the first subproblem ignores Unsafe and only seeds the next one.
    let mut lin: Option<Nominal> = guess;
    // δ of the subproblem that gave `lin` (0 for a given guess), where the screening measures slack.
    let mut lin_delta = 0.0;
    let mut solves = 0;
    for it in 0..settings.max_iter.max(1) {
        let linearised = Linearised {
            lin: lin.as_ref(),
            lin_delta,
            sides,
        };
        let sol = solve_subproblem(
            prob,
            roots,
            x0,
            &linearised,
            settings,
            SCREEN_SLACK,
            &mut solves,
        );

        match sol {
            Ok((v, delta)) => {
                let nominal = prob.simulate(x0, &v);
                let improved = best
                    .as_ref()
                    .map(|b| delta - b.delta_lin)
                    .unwrap_or(f64::INFINITY);
                // The first iterate ignores Unsafe (no linearisation point yet); it only seeds the next one.
                if lin.is_some() && best.as_ref().is_none_or(|b| delta >= b.delta_lin) {
                    best = Some(Generated {
                        nominal: nominal.clone(),
                        delta_lin: delta,
                        iterations: it + 1,
                    });
                }
                let done = lin.is_some() && improved.abs() <= settings.tol * delta.abs().max(1e-9);
                lin = Some(nominal);
                lin_delta = delta;
                if done {
                    break;
                }
            }
            Err(status) => {
                if let Some(b) = best {
                    return Ok(b);
                }
                return Err(GenError::Infeasible {
                    x0: x0.to_vec(),
                    steps: prob.steps,
                    status,
                    switches: prob.switches(),
                });
            }
        }
    }
    best.ok_or_else(|| GenError::Infeasible {
        x0: x0.to_vec(),
        steps: prob.steps,
        status: SubproblemStatus::NoUnsafeIterate,
        switches: prob.switches(),
    })
}

/// Row builder for clarabel's `A z + s = b, s ∈ K` form.
#[derive(Default)]
struct Rows {
    I: Vec<usize>,
    J: Vec<usize>,
    V: Vec<f64>,
    b: Vec<f64>,
    cones: Vec<SupportedConeT<f64>>,
}

impl Rows {
    fn row(&mut self, entries: &[(usize, f64)], rhs: f64) {
        let r = self.b.len();
        for &(j, v) in entries {
            if v != 0.0 {
                self.I.push(r);
                self.J.push(j);
                self.V.push(v);
            }
        }
        self.b.push(rhs);
    }

    /// Appends `other`'s rows and cones after these.
    fn extend(&mut self, other: &Rows) {
        let r0 = self.b.len();
        self.I.extend(other.I.iter().map(|&r| r + r0));
        self.J.extend_from_slice(&other.J);
        self.V.extend_from_slice(&other.V);
        self.b.extend_from_slice(&other.b);
        self.cones.extend(other.cones.iter().cloned());
    }
}

/// One linear inequality `aᵀz ≤ b` of a subproblem that may be left out while it is slack
/// ([`solve_subproblem`]'s screening).
struct Inequality {
    entries: Vec<(usize, f64)>,
    rhs: f64,
}

impl Inequality {
    /// `b − aᵀz`, over the norm of a's entries other than `skip` (δ's column): how far `z` is inside the
    /// row, in the units of the state and the input.
    fn slack(&self, z: &[f64], skip: usize) -> f64 {
        let (mut dot, mut norm) = (0.0, 0.0f64);
        for &(j, v) in &self.entries {
            dot += v * z[j];
            if j != skip {
                norm = norm.hypot(v);
            }
        }
        (self.rhs - dot) / norm.max(f64::MIN_POSITIVE)
    }
}

/// Rows of a subproblem whose slack at the previous iterate exceeds this (in state and input units,
/// [`Inequality::slack`]) are left out of its first solve (see [`solve_subproblem`]).
const SCREEN_SLACK: f64 = 1.0;

/// Where a subproblem is linearised: the previous iterate (none for the first, which ignores Unsafe),
/// the δ of the subproblem that gave it (0 for a given guess), the rule for the Unsafe rows.
#[derive(Clone, Copy)]
struct Linearised<'a> {
    lin: Option<&'a Nominal>,
    lin_delta: f64,
    sides: Sides,
}

/// One SOCP: returns v(0..N) and δ, or why it has none.
///
/// The Unsafe and input-box rows far from the previous iterate `lin` (slack above [`SCREEN_SLACK`]) are
/// left out of a first solve; every row left out is then checked at its solution, and those it
/// violates join for a new solve, until none is violated. The problem solved last is a relaxation of
/// the whole one whose optimum satisfies every row, so it is the whole problem's optimum (to clarabel's
/// tolerance), and a relaxation without a solution means the whole problem has none. Most rows of a
/// long horizon are far from every piece (a flat plant's region faces, an input bound the run never
/// nears), and the solve's cost grows with the rows.
///
/// `screen` is the slack past which a row is left out of the first solve ([`SCREEN_SLACK`];
/// `f64::INFINITY` leaves none out); `solves` counts clarabel's solves.
fn solve_subproblem(
    prob: &GenProblem<'_>,
    roots_of: &[PdRoots],
    x0: &[f64],
    linearised: &Linearised<'_>,
    settings: &GenSettings,
    screen: f64,
    solves: &mut usize,
) -> Result<(Vec<Vec<f64>>, f64), SubproblemStatus> {
    let Linearised {
        lin,
        lin_delta,
        sides,
    } = *linearised;
    let model = prob.model_at(0);
    let n = model.A.nrows();
    let m = model.B.ncols();
    let N = prob.steps;
    let xi = |k: usize, i: usize| k * n + i;
    let vi = |k: usize, i: usize| n * (N + 1) + k * m + i;
    let d = n * (N + 1) + m * N;
    let nvar = d + 1;
    let mut rows = Rows::default();

    // Equalities: x(0) = x0; x(κ+1) − A x(κ) − B v(κ) − B K x(κ) = g (step κ's location).
    for i in 0..n {
        rows.row(&[(xi(0, i), 1.0)], x0[i]);
    }
    for k in 0..N {
        let model = prob.model_at(k);
        let B = model.B.as_ref();
        let Acl = model.A.as_ref() + B * prob.K_at(k);
        for i in 0..n {
            let mut e = vec![(xi(k + 1, i), 1.0)];
            for j in 0..n {
                e.push((xi(k, j), -Acl[(i, j)]));
            }
            for j in 0..m {
                e.push((vi(k, j), -B[(i, j)]));
            }
            rows.row(&e, model.g[i]);
        }
    }
    let n_eq = rows.b.len();
    rows.cones.push(ZeroConeT(n_eq));

    // Nonnegative rows: always kept, and the screened ones (`screened`).
    let start = rows.b.len();
    rows.row(&[(d, -1.0)], 0.0); // δ ≥ 0
    rows.row(&[(d, 1.0)], settings.delta_max); // δ ≤ δmax
    let mut screened: Vec<Inequality> = Vec::new();
    // Unsafe: supporting half-spaces at the previous iterate.
    if let Some(nom) = lin {
        let planes: Vec<Vec<(Vec<f64>, f64)>> = prob
            .convex
            .unsafe_pieces
            .iter()
            .enumerate()
            .map(|(i, piece)| {
                let others: Vec<&ConvexPiece> = prob
                    .convex
                    .unsafe_pieces
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .map(|(_, o)| o)
                    .collect();
                halfspaces(piece, &others, &nom.x, sides)
            })
            .collect();
        for k in 0..=N {
            let xk = &nom.x[k];
            let uk = if k < N {
                nom.u[k].clone()
            } else {
                nom.u[N - 1].clone()
            };
            let roots = &roots_of[prob.metric_at(k)];
            let drift = prob.drift(k, xk, &uk, roots, sides == Sides::PerCrossing);
            for plane in &planes {
                let (nrm, off) = &plane[k];
                let dn = roots.dual_norm(nrm);
                // Keep nᵀx ≥ off + γ‖n‖_{P⁻¹}δ + (how far the period's drift moves the state against n).
                let mut e: Vec<(usize, f64)> = (0..n).map(|i| (xi(k, i), -nrm[i])).collect();
                e.push((d, prob.gamma * dn));
                screened.push(Inequality {
                    entries: e,
                    rhs: -*off - drift.against(nrm, dn),
                });
            }
        }
    }
    // Input box.
    if let InputBound::Box { lo, hi } = &prob.property.input {
        for k in 0..N {
            let (K, roots) = (prob.K_at(k), &roots_of[prob.metric_at(k)]);
            for i in 0..m {
                let Ki: Vec<f64> = (0..n).map(|j| K[(i, j)]).collect();
                let s = roots.dual_norm(&Ki);
                let mut e: Vec<(usize, f64)> = (0..n).map(|j| (xi(k, j), Ki[j])).collect();
                e.push((vi(k, i), 1.0));
                e.push((d, s));
                screened.push(Inequality {
                    entries: e,
                    rhs: hi[i] - prob.input_margin,
                });
                let mut e: Vec<(usize, f64)> = (0..n).map(|j| (xi(k, j), -Ki[j])).collect();
                e.push((vi(k, i), -1.0));
                e.push((d, s));
                screened.push(Inequality {
                    entries: e,
                    rhs: -lo[i] - prob.input_margin,
                });
            }
        }
    }
    // Polytope goal, in the metric of sample N.
    let roots = &roots_of[prob.metric_at(N)];
    if let ConvexPiece::Polytope { H, b } = &prob.convex.goal {
        for r in 0..H.nrows() {
            let h: Vec<f64> = (0..n).map(|j| H[(r, j)]).collect();
            let mut e: Vec<(usize, f64)> = (0..n).map(|j| (xi(N, j), h[j])).collect();
            e.push((d, roots.dual_norm(&h)));
            rows.row(&e, b[r]);
        }
    }
    let kept = rows.b.len() - start;

    // Second-order cones.
    let mut cones = Rows::default();
    if let InputBound::Norm2 { center, max } = &prob.property.input {
        for k in 0..N {
            let K = prob.K_at(k);
            let sK = spectral_norm((K * &roots_of[prob.metric_at(k)].inv_sqrt).as_ref());
            cones.row(&[(d, sK)], max - prob.input_margin);
            for i in 0..m {
                let mut e: Vec<(usize, f64)> = (0..n).map(|j| (xi(k, j), -K[(i, j)])).collect();
                e.push((vi(k, i), -1.0));
                cones.row(&e, -center[i]);
            }
            cones.cones.push(SecondOrderConeT(m + 1));
        }
    }
    if let ConvexPiece::Ellipsoid { C, c, Q } = &prob.convex.goal {
        let Qh = sym_fn(Q.as_ref(), |l| l.max(0.0).sqrt()).ok_or(SubproblemStatus::GoalShape)?;
        let QhC = &Qh * C;
        let sg = spectral_norm((&QhC * &roots.inv_sqrt).as_ref());
        let Qhc = mat_vec(Qh.as_ref(), c);
        let p = C.nrows();
        cones.row(&[(d, sg)], 1.0);
        for i in 0..p {
            let e: Vec<(usize, f64)> = (0..n).map(|j| (xi(N, j), -QhC[(i, j)])).collect();
            cones.row(&e, -Qhc[i]);
        }
        cones.cones.push(SecondOrderConeT(p + 1));
    }

    // Objective: −δ + w Σ‖v(κ+1) − v(κ)‖² (+ a tiny ‖v‖² for strict convexity); clarabel takes ½zᵀPz, upper part.
    let w = settings.smooth_weight;
    let mut PI = vec![];
    let mut PJ = vec![];
    let mut PV = vec![];
    for k in 0..N {
        for i in 0..m {
            let deg = (k > 0) as usize + (k + 1 < N) as usize;
            PI.push(vi(k, i));
            PJ.push(vi(k, i));
            PV.push(2.0 * w * deg as f64 + 2e-8);
            if k + 1 < N {
                PI.push(vi(k, i));
                PJ.push(vi(k + 1, i));
                PV.push(-2.0 * w);
            }
        }
    }
    let Pm = CscMatrix::new_from_triplets(nvar, nvar, PI, PJ, PV);
    let mut q = vec![0.0; nvar];
    q[d] = -1.0;
    let mut b = DefaultSettingsBuilder::default();
    b.verbose(false).max_iter(200);
    if let Some(t) = settings.refinement_tol {
        b.iterative_refinement_reltol(t)
            .iterative_refinement_abstol(t);
    }
    let st = b.build().expect(
        "verbose, max_iter = 200 and a validated refinement tolerance are in clarabel's range",
    );

    // The previous iterate as a point of the subproblem's variables, for the screening.
    let z_lin: Option<Vec<f64>> = lin.map(|nom| {
        let mut z = vec![0.0; nvar];
        for k in 0..=N {
            for i in 0..n {
                z[xi(k, i)] = nom.x[k][i];
            }
        }
        for k in 0..N {
            for i in 0..m {
                z[vi(k, i)] = nom.v[k][i];
            }
        }
        z[d] = lin_delta;
        z
    });
    let mut active: Vec<bool> = match &z_lin {
        Some(z) => screened.iter().map(|r| r.slack(z, d) <= screen).collect(),
        None => vec![true; screened.len()],
    };
    loop {
        let mut all = Rows::default();
        all.extend(&rows);
        for (r, _) in screened.iter().zip(&active).filter(|(_, &a)| a) {
            all.row(&r.entries, r.rhs);
        }
        let n_nn = all.b.len() - start;
        all.cones.push(NonnegativeConeT(n_nn));
        all.extend(&cones);
        debug_assert!(n_nn >= kept);
        let Am = CscMatrix::new_from_triplets(all.b.len(), nvar, all.I, all.J, all.V);
        let mut solver = DefaultSolver::new(&Pm, &q, &Am, &all.b, &all.cones, st.clone())
            .map_err(|e| SubproblemStatus::Setup(e.into()))?;
        solver.solve();
        *solves += 1;
        let status = solver.solution.status;
        let z = &solver.solution.x;
        let solved = matches!(status, SolverStatus::Solved | SolverStatus::AlmostSolved);
        // Rows left out that the solution violates join the next solve.
        let mut added = false;
        if solved {
            for (r, a) in screened.iter().zip(active.iter_mut()) {
                if !*a && r.slack(z, usize::MAX) < 0.0 {
                    *a = true;
                    added = true;
                }
            }
        } else if active.iter().any(|a| !a) && status != SolverStatus::PrimalInfeasible {
            // A relaxation clarabel could not solve says nothing of the whole problem: solve that.
            active.iter_mut().for_each(|a| *a = true);
            continue;
        }
        if added {
            continue;
        }
        if !solved {
            return Err(SubproblemStatus::Solver(status));
        }
        let v: Vec<Vec<f64>> = (0..N)
            .map(|k| (0..m).map(|i| z[vi(k, i)]).collect())
            .collect();
        return Ok((v, z[d].max(0.0)));
    }
}

/// The supporting half-space of `piece` for every sample of an iterate `xs`, by the rule `sides`
/// (`others`: Unsafe's other pieces, which a crossing must not be pushed into).
fn halfspaces(
    piece: &ConvexPiece,
    others: &[&ConvexPiece],
    xs: &[Vec<f64>],
    sides: Sides,
) -> Vec<(Vec<f64>, f64)> {
    let mut out: Vec<(Vec<f64>, f64)> = xs.iter().map(|x| supporting_halfspace(piece, x)).collect();
    if sides == Sides::Nearest {
        return out;
    }
    let mut k = 0;
    while k < xs.len() {
        if !piece_contains(piece, &xs[k]) {
            k += 1;
            continue;
        }
        let first = k;
        while k < xs.len() && piece_contains(piece, &xs[k]) {
            k += 1;
        }
        // The crossing enters after sample a and leaves before sample b (the run's ends when it starts at
        // the first sample or ends at the last).
        let a = &xs[first.saturating_sub(1)];
        let b = &xs[k.min(xs.len() - 1)];
        let plane = crossing_halfspace(piece, others, a, b, &xs[first..k]);
        for o in &mut out[first..k] {
            *o = plane.clone();
        }
    }
    out
}

/// One supporting half-space for a crossing of `piece` from `a` to `b` through the samples `inside`.
/// An ellipsoid {(Cx − c)ᵀQ(Cx − c) ≤ 1}: tangent where the ray from its centre through the point of the
/// chord [Ca, Cb] nearest the centre meets the boundary, so the crossing is pushed out on the side it
/// already passes (perpendicular to the chord, deterministically, when the chord meets the centre). A
/// polytope: a facet the crossing can pass along: preferably one whose far side (where the crossing's
/// mean point would leave through it) is not in another piece of Unsafe (a hill of two stacked boxes is
/// crossed over its top, not between them), then one that the crossing's entry a and exit b both lie
/// within (it runs along the way, not across it), then the one its mean point penetrates least.
fn crossing_halfspace(
    piece: &ConvexPiece,
    others: &[&ConvexPiece],
    a: &[f64],
    b: &[f64],
    inside: &[Vec<f64>],
) -> (Vec<f64>, f64) {
    match piece {
        ConvexPiece::Ellipsoid { C, c, .. } => {
            let ya = mat_vec(C.as_ref(), a);
            let yb = mat_vec(C.as_ref(), b);
            let p = c.len();
            let dir: Vec<f64> = (0..p).map(|i| yb[i] - ya[i]).collect();
            let dd: f64 = dir.iter().map(|v| v * v).sum();
            let t = if dd > 0.0 {
                ((0..p).map(|i| (c[i] - ya[i]) * dir[i]).sum::<f64>() / dd).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut off: Vec<f64> = (0..p).map(|i| ya[i] + t * dir[i] - c[i]).collect();
            let scale = c.iter().chain(&ya).fold(1.0f64, |s, v| s.max(v.abs()));
            if off.iter().map(|v| v * v).sum::<f64>().sqrt() <= 1e-9 * scale && p >= 2 {
                // Through the centre: the chord's perpendicular in the first two coordinates.
                off = vec![0.0; p];
                (off[0], off[1]) = (-dir[1], dir[0]);
            }
            // A point of y-space on that ray, lifted to x by least change from a (only C x matters).
            let target: Vec<f64> = (0..p).map(|i| c[i] + off[i]).collect();
            supporting_halfspace(piece, &lift(C.as_ref(), a, &ya, &target))
        }
        ConvexPiece::Polytope { H, b: off } => {
            let n = a.len();
            let mean: Vec<f64> = (0..n)
                .map(|j| inside.iter().map(|x| x[j]).sum::<f64>() / inside.len().max(1) as f64)
                .collect();
            let dot = |r: usize, x: &[f64]| (0..n).map(|j| H[(r, j)] * x[j]).sum::<f64>() - off[r];
            let norm = |r: usize| (0..n).map(|j| H[(r, j)] * H[(r, j)]).sum::<f64>().sqrt();
            // Where the mean point leaves through facet r: its projection onto the facet's plane, moved
            // a step past it (a thousandth of the piece's scale, at least 10⁻³).
            let scale = off.iter().fold(1e-3f64, |s, v| s.max(1e-3 * v.abs()));
            let beyond = |r: usize| -> Vec<f64> {
                let nn = norm(r).max(1e-150);
                let t = (scale * nn - dot(r, &mean)) / (nn * nn);
                (0..n).map(|j| mean[j] + t * H[(r, j)]).collect()
            };
            // Facets ranked: not covered by another piece, then not facing the crossing's entry or exit
            // (a facet that a or b lies beyond sends the crossing back where it came from or ahead of
            // where it goes), then least penetrated by the mean (ties: facet order).
            let r = (0..H.nrows())
                .map(|r| {
                    let covered = others.iter().any(|o| piece_contains(o, &beyond(r)));
                    let facing = dot(r, a) > 0.0 || dot(r, b) > 0.0;
                    (covered, facing, -dot(r, &mean) / norm(r).max(1e-300), r)
                })
                .min_by(|x, y| {
                    (x.0, x.1)
                        .cmp(&(y.0, y.1))
                        .then(x.2.total_cmp(&y.2))
                        .then(x.3.cmp(&y.3))
                })
                .map_or(0, |t| t.3);
            ((0..n).map(|j| H[(r, j)]).collect(), off[r])
        }
    }
}

/// A state x with C x = `target`, found as x = a + Cᵀ z with C Cᵀ z = target − C a (C has full row rank
/// for the sets the spec builds: coordinate selections).
fn lift(C: MatRef<'_, f64>, a: &[f64], ya: &[f64], target: &[f64]) -> Vec<f64> {
    let p = C.nrows();
    let CCt = C * C.transpose();
    let rhs = faer::Mat::<f64>::from_fn(p, 1, |i, _| target[i] - ya[i]);
    let z = faer::prelude::Solve::solve(&CCt.as_ref().partial_piv_lu(), &rhs);
    (0..a.len())
        .map(|j| a[j] + (0..p).map(|i| C[(i, j)] * z[(i, 0)]).sum::<f64>())
        .collect()
}

/// Whether `x` lies in `piece` (boundary included).
fn piece_contains(piece: &ConvexPiece, x: &[f64]) -> bool {
    match piece {
        ConvexPiece::Polytope { H, b } => {
            (0..H.nrows()).all(|r| (0..x.len()).map(|j| H[(r, j)] * x[j]).sum::<f64>() <= b[r])
        }
        ConvexPiece::Ellipsoid { C, c, Q } => {
            let p = C.nrows();
            let y: Vec<f64> = (0..p)
                .map(|i| (0..x.len()).map(|j| C[(i, j)] * x[j]).sum::<f64>() - c[i])
                .collect();
            (0..p)
                .map(|i| (0..p).map(|j| y[i] * Q[(i, j)] * y[j]).sum::<f64>())
                .sum::<f64>()
                <= 1.0
        }
    }
}

/// A half-space {x : nᵀx ≤ off} containing `piece`, supporting it at a boundary point chosen from `x`:
/// for an ellipsoid the radial projection of C x onto its boundary (the tangent plane there); for a polytope
/// the facet that `x` is farthest outside of (or least inside of).
pub fn supporting_halfspace(piece: &ConvexPiece, x: &[f64]) -> (Vec<f64>, f64) {
    match piece {
        ConvexPiece::Ellipsoid { C, c, Q } => {
            let p = C.nrows();
            let y = mat_vec(C.as_ref(), x);
            let mut dy: Vec<f64> = (0..p).map(|i| y[i] - c[i]).collect();
            let mut q: f64 = (0..p)
                .map(|i| (0..p).map(|j| dy[i] * Q[(i, j)] * dy[j]).sum::<f64>())
                .sum();
            if q <= 1e-300 {
                dy = vec![0.0; p];
                dy[0] = 1.0;
                q = Q[(0, 0)];
            }
            let s = 1.0 / q.sqrt();
            let py: Vec<f64> = (0..p).map(|i| c[i] + s * dy[i]).collect();
            // Outward normal in y: Q (py − c); in x: Cᵀ Q (py − c).
            let ny: Vec<f64> = (0..p)
                .map(|i| (0..p).map(|j| Q[(i, j)] * s * dy[j]).sum())
                .collect();
            let nx: Vec<f64> = (0..x.len())
                .map(|j| (0..p).map(|i| C[(i, j)] * ny[i]).sum())
                .collect();
            let off: f64 = (0..p).map(|i| ny[i] * py[i]).sum();
            (nx, off)
        }
        ConvexPiece::Polytope { H, b } => {
            let mut best = 0;
            let mut best_val = f64::NEG_INFINITY;
            for r in 0..H.nrows() {
                let h: Vec<f64> = (0..x.len()).map(|j| H[(r, j)]).collect();
                let nn = h.iter().map(|a| a * a).sum::<f64>().sqrt().max(1e-300);
                let val = (h.iter().zip(x).map(|(a, b)| a * b).sum::<f64>() - b[r]) / nn;
                if val > best_val {
                    best_val = val;
                    best = r;
                }
            }
            ((0..x.len()).map(|j| H[(best, j)]).collect(), b[best])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_infeasible_search_says_it_proves_nothing_what_limits_it_and_what_to_do() {
        let e = |switches| GenError::Infeasible {
            x0: vec![0.5, 0.0],
            steps: 40,
            status: SubproblemStatus::Solver(SolverStatus::PrimalInfeasible),
            switches,
        };
        let one = e(None).to_string();
        for what in [
            "the local generator found no trajectory from x0 = [0.5, 0.0] into Goal in 40 steps",
            "(solver: PrimalInfeasible)",
            "not a proof that none exists",
            "the side of every Unsafe piece that its previous iterate was on",
            "`synth --import`",
            "`host-compiler play`",
            "longer horizon T",
        ] {
            assert!(one.contains(what), "`{what}` not in: {one}");
        }
        assert!(!one.contains("schedule"), "{one}");
        let forced = e(Some(1)).to_string();
        assert!(
            forced.contains("along a schedule of 1 location switch (the forced planner tries staying, then one switch per forced edge")
                && forced.contains("its schedule search runs"),
            "{forced}"
        );
    }
    use crate::geometry::Ball;
    use crate::linalg::from_row_major;
    use crate::model::LinearAffine;
    use faer::Mat;

    /// The generator's view of a task on the contracting 2-D plant x⁺ = 0.9 x + u with P = I, K = 0.
    fn solve(
        goal: ConvexPiece,
        goal_at: [f64; 3],
        unsafe_pieces: Vec<ConvexPiece>,
        input: InputBound,
        steps: usize,
    ) -> Result<Generated, GenError> {
        solve_with(goal, goal_at, unsafe_pieces, input, steps, None)
    }

    /// [`solve`] by [`generate`] (`sides` None), or by one pass of [`iterate`] with that rule.
    fn solve_with(
        goal: ConvexPiece,
        goal_at: [f64; 3],
        unsafe_pieces: Vec<ConvexPiece>,
        input: InputBound,
        steps: usize,
        sides: Option<Sides>,
    ) -> Result<Generated, GenError> {
        with_problem(
            goal,
            goal_at,
            unsafe_pieces,
            input,
            steps,
            |prob| match sides {
                None => generate(prob, &[0.0, 0.0], &GenSettings::default()),
                Some(sides) => iterate(
                    prob,
                    &prob.roots().unwrap(),
                    &[0.0, 0.0],
                    &GenSettings::default(),
                    sides,
                    None,
                ),
            },
        )
    }

    /// `f` of [`solve`]'s problem.
    fn with_problem<R>(
        goal: ConvexPiece,
        goal_at: [f64; 3],
        unsafe_pieces: Vec<ConvexPiece>,
        input: InputBound,
        steps: usize,
        f: impl FnOnce(&GenProblem<'_>) -> R,
    ) -> R {
        let A = from_row_major(2, 2, &[0.9, 0.0, 0.0, 0.9]);
        let plant = LinearAffine::discrete(
            DiscretePlant::new(A, Mat::identity(2, 2), vec![0.0, 0.0], 0.1).unwrap(),
        );
        let K = Mat::<f64>::zeros(2, 2);
        let P = Mat::<f64>::identity(2, 2);
        let property = ReachAvoid {
            goal: Box::new(
                Ball::new(goal_at[..2].to_vec(), vec![1.0, 0.0, 0.0, 1.0], goal_at[2]).unwrap(),
            ),
            unsafe_set: None,
            input,
            horizon: steps as f64 * 0.1,
        };
        let convex = ConvexSets {
            goal,
            unsafe_pieces,
        };
        let prob = GenProblem {
            loc: 0,
            plant: &plant,
            K: K.as_ref(),
            P: P.as_ref(),
            property: &property,
            convex: &convex,
            steps,
            gamma: 1.0,
            phi: 0.0,
            beta: 0.0,
            input_margin: 0.0,
            schedule: None,
        };
        f(&prob)
    }

    /// A subproblem linearised at a detour far above a disc on the straight path leaves out the rows of
    /// the samples far from the disc; its solution runs straight through the disc, so the rows it
    /// violates join a second solve. The answer is the whole subproblem's: the same δ and references, to
    /// clarabel's tolerance.
    #[test]
    fn the_screened_subproblem_is_the_whole_one() {
        let input = InputBound::Box {
            lo: vec![-0.4, -0.4],
            hi: vec![0.4, 0.4],
        };
        let (steps, on_the_way) = (30, vec![disc(1.0, 0.0, 0.3)]);
        with_problem(
            disc(2.0, 0.0, 0.3),
            [2.0, 0.0, 0.3],
            on_the_way,
            input,
            steps,
            |prob| {
                let roots = prob.roots().unwrap();
                // Up for half the horizon, down for the other: up to 4.7 above the disc.
                let v: Vec<Vec<f64>> = (0..steps)
                    .map(|k| vec![0.21, if k < steps / 2 { 0.5 } else { -0.5 }])
                    .collect();
                let lin = prob.simulate(&[0.0, 0.0], &v);
                let at = Linearised {
                    lin: Some(&lin),
                    lin_delta: 0.0,
                    sides: Sides::Nearest,
                };
                let settings = GenSettings::default();
                let solve = |screen: f64| {
                    let mut solves = 0;
                    let r = solve_subproblem(
                        prob,
                        &roots,
                        &[0.0, 0.0],
                        &at,
                        &settings,
                        screen,
                        &mut solves,
                    )
                    .expect("solved");
                    (r, solves)
                };
                let ((v_all, d_all), once) = solve(f64::INFINITY);
                let ((v_scr, d_scr), more) = solve(SCREEN_SLACK);
                assert_eq!(once, 1);
                assert!(
                    more >= 2,
                    "the rows it violated joined a new solve ({more} solves)"
                );
                assert!(d_all > 0.05, "δ {d_all}");
                assert!(
                    (d_all - d_scr).abs() <= 1e-6 * d_all,
                    "δ {d_all} against {d_scr}"
                );
                // The references themselves are the optimum's only to the solver's tolerance (the
                // smoothness weight leaves them loosely held); every row holds at the screened answer.
                assert_eq!(v_all.len(), v_scr.len());
                let run = prob.simulate(&[0.0, 0.0], &v_scr);
                for xk in &run.x {
                    let gap = (xk[0] - 1.0).hypot(xk[1]) - 0.3;
                    assert!(
                        gap >= d_scr - 1e-6,
                        "{xk:?} is {gap} from the disc, δ = {d_scr}"
                    );
                }
                for vk in v_scr.iter().flatten() {
                    assert!(vk.abs() <= 0.4 + 1e-6, "input {vk}");
                }
                let end = &run.x[steps];
                assert!(
                    (end[0] - 2.0).hypot(end[1]) + d_scr <= 0.3 + 1e-6,
                    "goal {end:?}"
                );
            },
        )
    }

    /// A disc centred on the straight path to Goal: the first iterate runs through it, and the nearest
    /// boundary points push its samples out on both sides. One side per crossing clears it; `generate`
    /// falls back to that rule, and its trajectory keeps the tube out of the disc.
    #[test]
    fn a_crossing_through_a_disc_gets_one_side_and_clears_it() {
        let input = InputBound::Box {
            lo: vec![-0.4, -0.4],
            hi: vec![0.4, 0.4],
        };
        let obstacle = || vec![disc(1.0, 0.0, 0.3)];
        let run = |sides| {
            solve_with(
                disc(2.0, 0.0, 0.3),
                [2.0, 0.0, 0.3],
                obstacle(),
                input.clone(),
                30,
                sides,
            )
        };
        let nearest = run(Some(Sides::Nearest));
        let crossing = run(Some(Sides::PerCrossing)).expect("one side per crossing");
        let fallback = run(None).expect("generate falls back");
        assert!(
            matches!(
                nearest,
                Err(GenError::Infeasible {
                    status: SubproblemStatus::Solver(SolverStatus::PrimalInfeasible),
                    ..
                })
            ),
            "{:?}",
            nearest.map(|g| g.delta_lin)
        );
        assert_eq!(fallback.delta_lin, crossing.delta_lin);
        let d = crossing.delta_lin;
        assert!(d > 0.0, "delta {d}");
        for xk in &crossing.nominal.x {
            let gap = (xk[0] - 1.0).hypot(xk[1]) - 0.3;
            assert!(gap >= d - 1e-6, "{xk:?} is {gap} from the disc, δ = {d}");
        }
    }

    /// A hill of two stacked boxes, crossed by the first iterate low through the top box: the facet it
    /// penetrates least is the top box's floor, which the lower box covers. One side per crossing takes
    /// the top box's roof instead, and the tube clears both boxes (with the floor, it found nothing).
    #[test]
    fn a_crossing_of_a_stacked_box_is_pushed_over_it_not_into_the_box_below() {
        let input = InputBound::Box {
            lo: vec![-0.6, -0.6],
            hi: vec![0.6, 0.6],
        };
        let hill = || {
            vec![
                rect([0.3, -3.0], [3.7, -0.5]),
                rect([0.8, -0.5], [3.2, 1.0]),
            ]
        };
        let run = |sides| {
            solve_with(
                disc(4.0, -0.1, 0.3),
                [4.0, -0.1, 0.3],
                hill(),
                input.clone(),
                40,
                sides,
            )
        };
        let crossing = run(Some(Sides::PerCrossing)).expect("over the top");
        let d = crossing.delta_lin;
        assert!(d > 0.0, "delta {d}");
        for xk in &crossing.nominal.x {
            for (lo, hi) in [([0.3, -3.0], [3.7, -0.5]), ([0.8, -0.5], [3.2, 1.0])] {
                let gap = (0..2)
                    .map(|j| (lo[j] - xk[j]).max(xk[j] - hi[j]).max(0.0))
                    .fold(0.0f64, f64::hypot);
                assert!(gap >= d - 1e-6, "{xk:?} is {gap} from a box, δ = {d}");
            }
        }
        assert!(
            crossing
                .nominal
                .x
                .iter()
                .any(|x| (0.8..=3.2).contains(&x[0]) && x[1] > 1.0),
            "the run passes over the top box"
        );
    }

    /// The box lo ≤ x ≤ hi in the plane as a polytope.
    fn rect(lo: [f64; 2], hi: [f64; 2]) -> ConvexPiece {
        ConvexPiece::Polytope {
            H: from_row_major(4, 2, &[1.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, -1.0]),
            b: vec![hi[0], -lo[0], hi[1], -lo[1]],
        }
    }

    fn disc(cx: f64, cy: f64, r: f64) -> ConvexPiece {
        ConvexPiece::Ellipsoid {
            C: Mat::<f64>::identity(2, 2),
            c: vec![cx, cy],
            Q: from_row_major(2, 2, &[1.0 / (r * r), 0.0, 0.0, 1.0 / (r * r)]),
        }
    }

    /// A contracting 2-D plant with P = I: the tube conditions can be checked by hand.
    #[test]
    fn avoids_the_obstacle_reaches_goal_and_respects_the_bound() {
        let input = InputBound::Norm2 {
            center: vec![0.0, 0.0],
            max: 0.5,
        };
        let out = solve(
            disc(2.0, 0.0, 0.3),
            [2.0, 0.0, 0.3],
            vec![disc(1.0, 0.05, 0.3)],
            input,
            30,
        )
        .unwrap();
        let d = out.delta_lin;
        assert!(d > 0.02, "delta {d}");
        let x = &out.nominal.x;
        let end = &x[30];
        let to_goal = ((end[0] - 2.0).powi(2) + end[1].powi(2)).sqrt();
        assert!(to_goal + d <= 0.3 + 1e-6, "goal: {to_goal} + {d}");
        for xk in x {
            let to_obs = ((xk[0] - 1.0).powi(2) + (xk[1] - 0.05).powi(2)).sqrt();
            assert!(to_obs >= 0.3 + d - 1e-6, "obstacle: {to_obs} vs {d}");
        }
        for uk in &out.nominal.u {
            assert!((uk[0] * uk[0] + uk[1] * uk[1]).sqrt() <= 0.5 + 1e-6);
        }
    }

    #[test]
    fn the_builder_refuses_a_non_positive_delta_max() {
        let e = GenSettings::builder().delta_max(0.0).build().unwrap_err();
        assert_eq!(
            (e.settings, e.field, e.value),
            ("GenSettings", "delta_max", 0.0)
        );
        assert!(e.to_string().contains("GenSettings.delta_max = 0"), "{e}");
        assert!(GenSettings::builder().max_iter(0).build().is_err());
        let s = GenSettings::builder().max_iter(3).build().unwrap();
        assert_eq!(
            (s.max_iter, s.delta_max),
            (3, GenSettings::default().delta_max)
        );
    }

    #[test]
    fn an_unreachable_goal_is_reported() {
        let input = InputBound::Box {
            lo: vec![-0.1, -0.1],
            hi: vec![0.1, 0.1],
        };
        assert!(matches!(
            solve(disc(20.0, 0.0, 0.3), [20.0, 0.0, 0.3], vec![], input, 10),
            Err(GenError::Infeasible { .. })
        ));
    }
}
