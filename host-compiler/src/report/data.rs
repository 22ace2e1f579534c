//! Plot-ready data of one synthesis run: everything the HTML report shows, already projected onto the
//! plotting planes, so that rendering needs no control theory.

use serde::Serialize;

/// An ellipse {c + M w : ‖w‖₂ ≤ 1} in a plotting plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Ellipse2 {
    pub center: [f64; 2],
    /// Columns map the unit circle onto the ellipse.
    pub M: [[f64; 2]; 2],
}

/// A set drawn in a plotting plane.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum Shape2 {
    Ellipse(Ellipse2),
    /// {y : a_i · y ≤ b_i for all i} — clip to the plot's bounding box before drawing (may be unbounded).
    HalfPlanes {
        a: Vec<[f64; 2]>,
        b: Vec<f64>,
    },
    /// An axis-aligned box [lo, hi].
    Box {
        lo: [f64; 2],
        hi: [f64; 2],
    },
}

/// One certified trajectory.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrajectoryReport {
    pub id: usize,
    /// Where it came from: "generated", "csv:<path>", "route 1 (SCP) + §5.3", …
    pub source: String,
    /// The route (index into [`ReportData::routes`]) it came from: directly, or through the balls
    /// Algorithm 4 grew it from.
    pub route: Option<usize>,
    /// Initial state x̃(0).
    pub x0: Vec<f64>,
    /// Certified radius δ (CAF metric) of the ball of initial states, as shipped.
    pub delta: f64,
    /// Theorem 4.7 parts before the f32/sampling margins: δ_Goal, δ_Unsafe, δ_Input.
    pub delta_goal: f64,
    pub delta_unsafe: f64,
    pub delta_input: f64,
    /// Critical time t* (s) at which Goal is certified.
    pub t_star: f64,
    /// Sample times (s), nominal path in the plotting plane, and the robust tube at each sample.
    pub times: Vec<f64>,
    pub path: Vec<[f64; 2]>,
    pub tube: Vec<Ellipse2>,
    /// Applied nominal inputs ũ(κ) (one row per sample period).
    pub u: Vec<Vec<f64>>,
    /// The nominal input measured as the bound measures it (‖ũ − u_c‖₂, or max_i |ũ_i|), per step.
    pub u_nominal: Vec<f64>,
    /// The largest input any state in the tube can apply at each step (same measure as `u_nominal`).
    pub u_worst: Vec<f64>,
}

/// A route the global search found (issue 48), with the trajectories that came from it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RouteReport {
    /// "route k" (with the seed's number when several seeds were searched).
    pub label: String,
    /// The seed it starts from (full state), its length and the clearance it keeps from Unsafe, in the
    /// route coordinates.
    pub seed: Vec<f64>,
    pub length: f64,
    pub clearance: f64,
    /// Its points in the workspace plane (empty when the route coordinates are not that plane's).
    pub points: Vec<[f64; 2]>,
    /// Ids of the trajectories that came from it.
    pub trajectories: Vec<usize>,
}

/// Summary of the closed-loop Monte Carlo re-check.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct VerifySummary {
    pub runs: usize,
    pub violations: usize,
    pub worst_goal_margin: f64,
    pub worst_unsafe_margin: f64,
    pub worst_input_margin: f64,
    /// Runs that left the input set / entered Unsafe after the task ended in Goal: violations when the
    /// image has a terminal law (`after_goal_judged`), else not judged (shown so that nobody mistakes
    /// what runs after Goal for something certified).
    pub after_goal_input_excursions: usize,
    pub after_goal_unsafe: usize,
    pub after_goal_judged: bool,
    /// The falsifier, when it ran: its runs, the least run robustness it found, its violations.
    pub attack: Option<(usize, f64, usize)>,
}

/// What the controller does after the task (issue 17): the certified terminal law with its invariant
/// ellipsoid, or why there is none, and what the Monte Carlo saw after Goal.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TerminalReport {
    /// "certified", or why there is none.
    pub status: String,
    /// Equilibrium, its input and the gain (empty without a law).
    pub x_e: Vec<f64>,
    pub u_e: Vec<f64>,
    pub K: Vec<Vec<f64>>,
    /// The certificate's figures as (name, value, note), computed from the stored f32 law.
    pub figures: Vec<(String, f64, String)>,
    /// The invariant ellipsoid's shadow in the workspace plane.
    pub ellipse: Option<Ellipse2>,
    /// Runs outside Goal again after reaching it, runs handed over, samples per run.
    pub runs_leaving_goal: usize,
    pub handed_over: usize,
    pub run_steps: usize,
    /// With a terminal law (judged after Goal, each a violation): runs not handed over within the
    /// horizon; and the radius ρ_h of the handover region the cover's runs are certified to reach.
    pub not_handed_over: usize,
    pub handover_radius: Option<f64>,
    /// What the image does after Goal, in one line ([`crate::report::after_goal_line`]).
    pub after_goal: String,
}

/// Everything `report.html` shows.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReportData {
    pub title: String,
    pub spec_path: String,
    /// State, input and output dimensions, sample period (s), horizon T (s).
    pub n: usize,
    pub m: usize,
    pub period: f64,
    pub horizon: f64,
    /// Axis labels of the workspace plane (e.g. "x1", "x2").
    pub plane_labels: [String; 2],
    pub init_plane: Option<Shape2>,
    pub goal_plane: Vec<Shape2>,
    pub unsafe_plane: Vec<Shape2>,
    pub trajectories: Vec<TrajectoryReport>,
    /// The routes of the global search, when the growth ran one.
    pub routes: Vec<RouteReport>,
    /// Axis labels of the Init plane (its two free coordinates) and the Init box there.
    pub init_labels: [String; 2],
    pub init_box: Shape2,
    /// Cross-sections of the certified balls with the Init plane.
    pub balls: Vec<Ellipse2>,
    /// Coverage samples that no ball covers, in the Init plane.
    pub uncovered: Vec<[f64; 2]>,
    pub coverage: crate::cover::CoverageEstimate,
    /// The coverage the spec asks for (its `coverage_target`).
    pub coverage_target: f64,
    /// "covered at the requested confidence" or why the loop stopped.
    pub stop_reason: String,
    /// Input bound description (e.g. "‖u‖₂ ≤ 1") and its value for plotting.
    pub input_bound_label: String,
    pub input_bound: f64,
    pub K: Vec<Vec<f64>>,
    pub P: Vec<Vec<f64>>,
    /// σ_min(P − ÃᵀPÃ) of the shipped (f32) gain, the f32 disturbance bound and r_crit (Thm 3.21).
    pub sigma_min: f64,
    pub eps_f32: f64,
    pub r_crit: f64,
    pub image_bytes: usize,
    pub image_path: String,
    pub verify: Option<VerifySummary>,
    /// How the cover grew and what §5.3 optimisation did (section `optimization`), when recorded.
    pub optimization: Option<super::optimization::OptimizationReport>,
    /// (phase, seconds).
    pub timings: Vec<(String, f64)>,
    pub warnings: Vec<String>,
    /// PWA-feedback section (Ch. 6), for `mode = "pwa"`.
    pub pwa: Option<super::pwa::PwaReport>,
    /// After the task: the terminal law or why there is none (`None`: not reported for this task).
    pub terminal: Option<TerminalReport>,
}
