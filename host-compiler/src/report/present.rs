//! From a synthesis run to the plot-ready [`ReportData`]: projections of sets, tubes and balls onto the
//! plotting planes.

use super::data::{
    Ellipse2, ReportData, RouteReport, Shape2, TerminalReport, TrajectoryReport, VerifySummary,
};
use super::optimization::OptimizationReport;
use crate::linalg::{spectral_norm, sym_fn, PdRoots};
use crate::spec::sets::{Coords, SetDesc, Shape};
use crate::spec::{InputSet, Problem};
use crate::synth::Synthesis;
use faer::Mat;

/// The 2×2 matrix M with M Mᵀ = S (symmetric PSD), as an ellipse generator.
pub(super) fn root2(S: &Mat<f64>) -> [[f64; 2]; 2] {
    let R = sym_fn(S.as_ref(), |l| l.max(0.0).sqrt()).unwrap_or_else(|| Mat::zeros(2, 2));
    [[R[(0, 0)], R[(0, 1)]], [R[(1, 0)], R[(1, 1)]]]
}

/// Which two state coordinates a set constrains, if it is a set on exactly two state coordinates.
fn plane_of(s: &SetDesc, n: usize) -> Option<[usize; 2]> {
    match &s.coords {
        Coords::StateIndices(idx) if idx.len() == 2 => Some([idx[0], idx[1]]),
        Coords::State if n == 2 => Some([0, 1]),
        _ => None,
    }
}

/// A spec set drawn in the plane `pl` (only when it lives on exactly those coordinates).
fn shape2(s: &SetDesc, n: usize, pl: [usize; 2]) -> Option<Shape2> {
    if plane_of(s, n)? != pl {
        return None;
    }
    Some(match &s.shape {
        Shape::Ball { center, radius } => Shape2::Ellipse(Ellipse2 {
            center: [center[0], center[1]],
            M: [[*radius, 0.0], [0.0, *radius]],
        }),
        Shape::Ellipsoid { center, Q } => {
            let Qm = Mat::from_fn(2, 2, |i, j| Q.data[i * 2 + j]);
            let Qi = sym_fn(Qm.as_ref(), |l| if l > 0.0 { 1.0 / l } else { 0.0 })?;
            Shape2::Ellipse(Ellipse2 {
                center: [center[0], center[1]],
                M: root2(&Qi),
            })
        }
        Shape::Polytope { A, b } => Shape2::HalfPlanes {
            a: (0..A.rows)
                .map(|r| [A.data[r * 2], A.data[r * 2 + 1]])
                .collect(),
            b: b.clone(),
        },
        Shape::Box { lo, hi } => Shape2::Box {
            lo: [lo[0], lo[1]],
            hi: [hi[0], hi[1]],
        },
    })
}

/// Build the report's data.
pub fn report_data(
    problem: &Problem,
    spec_path: &str,
    s: &Synthesis,
    image_path: &str,
) -> ReportData {
    let n = problem.plant.n();
    let period = problem.plant.period;
    let mut warnings = s.warnings.clone();
    // Workspace plane: the goal's coordinates when it lives on two state coordinates, else x1, x2.
    let pl = plane_of(&problem.goal, n).unwrap_or([0, 1.min(n - 1)]);
    let label = |i: usize| format!("x{}", i + 1);
    let roots = PdRoots::new(s.P.as_ref());
    let Pinv = roots
        .as_ref()
        .map(|r| r.inv.clone())
        .unwrap_or_else(|| Mat::identity(n, n));
    let Sigma = Mat::from_fn(2, 2, |i, j| Pinv[(pl[i], pl[j])]);
    let Mtube = root2(&Sigma);
    let goal_plane: Vec<Shape2> = shape2(&problem.goal, n, pl).into_iter().collect();
    let unsafe_plane: Vec<Shape2> = problem
        .unsafe_sets
        .iter()
        .filter_map(|u| shape2(u, n, pl))
        .collect();
    if unsafe_plane.len() < problem.unsafe_sets.len() {
        warnings.push(
            "some Unsafe sets do not live on the plotted coordinates and are not drawn".into(),
        );
    }
    // Init plane: the first two free coordinates of Init.
    let free = problem.init.free_coords();
    let ipl = match free.as_slice() {
        [a, b, ..] => [*a, *b],
        [a] => [*a, if *a == 0 { 1.min(n - 1) } else { 0 }],
        [] => [0, 1.min(n - 1)],
    };
    let Pff = Mat::from_fn(2, 2, |i, j| s.P[(ipl[i], ipl[j])]);
    let Pff_inv = sym_fn(Pff.as_ref(), |l| if l > 0.0 { 1.0 / l } else { 0.0 })
        .unwrap_or_else(|| Mat::zeros(2, 2));
    let Mball = root2(&Pff_inv);
    let scale = |M: [[f64; 2]; 2], r: f64| [[M[0][0] * r, M[0][1] * r], [M[1][0] * r, M[1][1] * r]];
    let (input_bound_label, input_bound) = match &problem.input {
        InputSet::Ball { radius, .. } => (format!("‖u − u_c‖₂ ≤ {radius}"), *radius),
        InputSet::Box { lo, hi } => (
            "max_i |u_i| (box bound)".to_string(),
            lo.iter().chain(hi).fold(0.0f64, |a, b| a.max(b.abs())),
        ),
    };
    let sK = roots
        .as_ref()
        .map(|r| spectral_norm((&s.K * &r.inv_sqrt).as_ref()))
        .unwrap_or(0.0);
    let (routes, route_of) = routes_data(s, pl);
    let trajectories = s
        .trajectories
        .iter()
        .enumerate()
        .map(|(id, t)| {
            let c = &t.certificate;
            let r = c.delta;
            // The nominal input and the worst case over the tube, both measured as the bound measures them.
            let (u_nominal, u_worst): (Vec<f64>, Vec<f64>) = t
                .nominal
                .u
                .iter()
                .map(|u| match &problem.input {
                    InputSet::Ball { center, .. } => {
                        let nom = u
                            .iter()
                            .zip(center)
                            .map(|(a, b)| (a - b) * (a - b))
                            .sum::<f64>()
                            .sqrt();
                        (nom, nom + r * sK)
                    }
                    InputSet::Box { .. } => {
                        let nom = u.iter().fold(0.0f64, |a, b| a.max(b.abs()));
                        let worst = (0..u.len())
                            .map(|i| {
                                let Ki: Vec<f64> = (0..n).map(|j| s.K[(i, j)]).collect();
                                u[i].abs()
                                    + r * roots.as_ref().map(|q| q.dual_norm(&Ki)).unwrap_or(0.0)
                            })
                            .fold(0.0, f64::max);
                        (nom, worst)
                    }
                })
                .unzip();
            TrajectoryReport {
                id,
                source: t.source.to_string(),
                route: route_of[id],
                x0: t.nominal.x[0].clone(),
                delta: c.delta_stored as f64,
                delta_goal: c.delta_goal,
                delta_unsafe: c.delta_unsafe_intersample,
                delta_input: c.delta_input,
                t_star: c.k_star as f64 * period,
                times: (0..t.nominal.x.len()).map(|k| k as f64 * period).collect(),
                path: t.nominal.x.iter().map(|x| [x[pl[0]], x[pl[1]]]).collect(),
                tube: t
                    .nominal
                    .x
                    .iter()
                    .map(|x| Ellipse2 {
                        center: [x[pl[0]], x[pl[1]]],
                        M: scale(Mtube, r),
                    })
                    .collect(),
                u: t.nominal.u.clone(),
                u_nominal,
                u_worst,
            }
        })
        .collect();
    let balls = s
        .trajectories
        .iter()
        .map(|t| Ellipse2 {
            center: [t.nominal.x[0][ipl[0]], t.nominal.x[0][ipl[1]]],
            M: scale(Mball, t.certificate.delta_stored as f64),
        })
        .collect();
    let lo = &problem.init.lo;
    let hi = &problem.init.hi;
    let init_box = Shape2::Box {
        lo: [lo[ipl[0]], lo[ipl[1]]],
        hi: [hi[ipl[0]], hi[ipl[1]]],
    };
    let init_plane = Some(Shape2::Box {
        lo: [lo[pl[0]], lo[pl[1]]],
        hi: [hi[pl[0]], hi[pl[1]]],
    });
    let rows = |M: &Mat<f64>| crate::linalg::to_rows(M.as_ref());
    let eps = s
        .trajectories
        .iter()
        .map(|t| t.certificate.eps_f32)
        .fold(0.0, f64::max);
    ReportData {
        title: problem
            .name
            .clone()
            .unwrap_or_else(|| spec_path.to_string()),
        spec_path: spec_path.to_string(),
        n,
        m: problem.plant.m(),
        period,
        horizon: problem.horizon,
        plane_labels: [label(pl[0]), label(pl[1])],
        init_plane,
        goal_plane,
        unsafe_plane,
        trajectories,
        routes,
        init_labels: [label(ipl[0]), label(ipl[1])],
        init_box,
        balls,
        uncovered: s
            .uncovered
            .iter()
            .take(2000)
            .map(|x| [x[ipl[0]], x[ipl[1]]])
            .collect(),
        coverage: s.coverage.clone(),
        coverage_target: problem.synthesis.coverage_target,
        stop_reason: s.stop.to_string(),
        input_bound_label,
        input_bound,
        K: rows(&s.K),
        P: rows(&s.P),
        sigma_min: s.constants.sigma_min,
        eps_f32: eps,
        r_crit: s.constants.r_crit(eps),
        image_bytes: s.image.len(),
        image_path: image_path.to_string(),
        optimization: Some(optimization_data(s, pl, ipl, &|r| scale(Mtube, r))),
        verify: Some(VerifySummary {
            runs: s.verify.interior_runs + s.verify.boundary_runs - s.verify.boundary_rejected,
            violations: s.verify.violations,
            worst_goal_margin: s.verify.worst_goal_margin,
            worst_unsafe_margin: s.verify.worst_unsafe_margin,
            worst_input_margin: s.verify.worst_input_margin,
            after_goal_input_excursions: s.verify.after_goal_input_excursions,
            after_goal_unsafe: s.verify.after_goal_unsafe,
            after_goal_judged: s.verify.after_goal_judged,
            attack: s
                .attack
                .as_ref()
                .map(|a| (a.evaluations, a.worst_robustness, a.violations)),
        }),
        timings: s.timings.clone(),
        warnings,
        pwa: None,
        terminal: Some(terminal_report(s, pl)),
    }
}

/// The routes of the cover's searches in the workspace plane `pl`, and per trajectory the route (an
/// index into them) it came from ([`crate::cover::seeds::routes_of`]).
fn routes_data(s: &Synthesis, pl: [usize; 2]) -> (Vec<RouteReport>, Vec<Option<usize>>) {
    let of = crate::cover::seeds::routes_of(&s.trajectories, &s.routes);
    let several = s.routes.len() > 1;
    let mut first = Vec::with_capacity(s.routes.len());
    let mut routes = Vec::new();
    for (i, search) in s.routes.iter().enumerate() {
        first.push(routes.len());
        let at = |c: usize| search.coords.iter().position(|&j| j == c);
        let plane = at(pl[0]).zip(at(pl[1]));
        for (k, r) in search.routes.iter().enumerate() {
            routes.push(RouteReport {
                label: if several {
                    format!("route {} from seed {}", k + 1, i + 1)
                } else {
                    format!("route {}", k + 1)
                },
                seed: search.seed.clone(),
                length: r.length,
                clearance: r.clearance,
                points: plane.map_or_else(Vec::new, |(a, b)| {
                    r.points.iter().map(|p| [p[a], p[b]]).collect()
                }),
                trajectories: (0..of.len()).filter(|&t| of[t] == Some((i, k))).collect(),
            });
        }
    }
    let index = of.iter().map(|o| o.map(|(i, k)| first[i] + k)).collect();
    (routes, index)
}

/// The terminal law's section (issue 17): its ellipsoid {‖x − x_e‖_{P_t} ≤ 1} projected onto the plane
/// `pl` (the 2×2 block of P_t⁻¹ there), the law and the certificate's figures; or why there is none.
fn terminal_report(s: &Synthesis, pl: [usize; 2]) -> TerminalReport {
    use crate::synth::TerminalOutcome;
    let base = TerminalReport {
        status: String::new(),
        x_e: vec![],
        u_e: vec![],
        K: vec![],
        figures: vec![],
        ellipse: None,
        runs_leaving_goal: s.verify.runs_leaving_goal,
        handed_over: s.verify.handed_over,
        run_steps: s.verify.run_steps,
        not_handed_over: s.verify.not_handed_over,
        handover_radius: s.handover_radius,
        after_goal: shared_types::image::decode(&s.image)
            .map(|img| crate::report::after_goal_line(&img))
            .unwrap_or_default(),
    };
    match &s.terminal {
        TerminalOutcome::Certified(d) => {
            let st = &d.stored;
            let c = &d.certificate;
            let ellipse = PdRoots::new(st.P.as_ref()).map(|r| {
                let sigma = Mat::from_fn(2, 2, |i, j| r.inv[(pl[i], pl[j])]);
                Ellipse2 {
                    center: [st.x_e[pl[0]], st.x_e[pl[1]]],
                    M: root2(&sigma),
                }
            });
            let f = |name: &str, v: f64, note: &str| (name.to_string(), v, note.to_string());
            TerminalReport {
                status: "certified".into(),
                x_e: st.x_e.clone(),
                u_e: d.u_e.clone(),
                K: crate::linalg::to_rows(st.K.as_ref()),
                figures: vec![
                    f(
                        "‖A + BK_t‖ in the ellipsoid's metric",
                        c.contraction,
                        "contraction per sample",
                    ),
                    f("θ", c.theta, "the next sample lies within θ of x_e"),
                    f(
                        "accepted within",
                        c.acceptance_floor,
                        "the f32 handover test accepts every state this close (> θ)",
                    ),
                    f(
                        "between samples within",
                        c.between_samples,
                        "radius the run stays within between samples",
                    ),
                    f(
                        "Goal depth of x_e",
                        c.goal_depth,
                        "≥ the radius between samples",
                    ),
                    f(
                        "Unsafe distance of x_e",
                        c.unsafe_distance,
                        "> the radius between samples",
                    ),
                    f(
                        "input distance",
                        c.input_distance,
                        "≥ 1: every input of the law lies in the input set",
                    ),
                    f(
                        "ε_f32",
                        c.rounding,
                        "the evaluator's rounding over the ellipsoid (2-norm)",
                    ),
                ],
                ellipse,
                ..base
            }
        }
        TerminalOutcome::None(e) => TerminalReport {
            status: format!("none: {e}"),
            ..base
        },
        TerminalOutcome::NotAsked => TerminalReport {
            status: "none: the spec's [synthesis] terminal asks for none".into(),
            ..base
        },
    }
}

/// The optimisation section's data: every §5.3 run, the accepted Algorithm 4 trajectory with the largest
/// gain before and after (workspace plane `pl`), the cover after each round and any seed request (Init
/// plane `ipl`). `tube(r)` is the generator of a tube ellipse of radius r in the workspace plane.
fn optimization_data(
    s: &Synthesis,
    pl: [usize; 2],
    ipl: [usize; 2],
    tube: &dyn Fn(f64) -> [[f64; 2]; 2],
) -> OptimizationReport {
    use super::optimization::{CoverageFrame, OptRun, SeedRequest, TubeComparison};
    let runs = s
        .optimization
        .iter()
        .map(|r| OptRun {
            round: r.round,
            origin: r.origin,
            accepted: r.accepted,
            delta_before: r.delta_before,
            delta_after: r.delta_after,
            history: r.history.clone(),
            iterations: r.iterations,
            stop: format!("{:?}", r.stop),
        })
        .collect();
    let project =
        |xs: &[Vec<f64>]| -> Vec<[f64; 2]> { xs.iter().map(|x| [x[pl[0]], x[pl[1]]]).collect() };
    let tubes = |xs: &[Vec<f64>], r: f64| -> Vec<Ellipse2> {
        xs.iter()
            .map(|x| Ellipse2 {
                center: [x[pl[0]], x[pl[1]]],
                M: tube(r),
            })
            .collect()
    };
    // The showcase: an accepted Algorithm 4 seed with the largest finite gain, else any accepted run.
    let best = s
        .optimization
        .iter()
        .filter(|r| r.accepted.is_some() && r.origin.is_some() && r.gain().is_finite())
        .fold(None::<&crate::synth::OptRecord>, |b, r| match b {
            Some(b) if b.gain() >= r.gain() => Some(b),
            _ => Some(r),
        })
        .or_else(|| s.optimization.iter().find(|r| r.accepted.is_some()));
    let showcase = best.and_then(|r| {
        let t = s.trajectories.get(r.accepted?)?;
        Some(TubeComparison {
            trajectory: r.accepted?,
            delta_before: r.delta_before,
            delta_after: t.certificate.delta,
            before_path: project(&r.before.x),
            before_tube: tubes(&r.before.x, r.delta_before),
            after_path: project(&t.nominal.x),
            after_tube: tubes(&t.nominal.x, t.certificate.delta),
        })
    });
    let frames = s
        .snapshots
        .iter()
        .map(|f| CoverageFrame {
            round: f.round,
            trajectories: f.trajectories,
            uncovered: f.uncovered.iter().map(|x| [x[ipl[0]], x[ipl[1]]]).collect(),
            samples: s.working_samples,
        })
        .collect();
    let bx = |lo: &[f64], hi: &[f64]| Shape2::Box {
        lo: [lo[ipl[0]], lo[ipl[1]]],
        hi: [hi[ipl[0]], hi[ipl[1]]],
    };
    let needs_seed = match &s.stop {
        crate::synth::StopReason::NeedsSeed {
            region,
            description,
        } => Some(SeedRequest {
            description: description.clone(),
            region: bx(&region.lo, &region.hi),
            clusters: region.clusters.iter().map(|c| bx(&c.lo, &c.hi)).collect(),
        }),
        _ => None,
    };
    OptimizationReport {
        generator: s.generator.to_string(),
        runs,
        showcase,
        frames,
        needs_seed,
    }
}
