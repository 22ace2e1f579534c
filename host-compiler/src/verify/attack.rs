//! The falsifier (`verify --attack`): an optimisation-based search for the start whose closed-loop run
//! comes closest to failing the task, made without the certificate's reasoning.
//!
//! For every ball of a feedforward image, starts are parametrised by w ∈ ℝⁿ as
//! x0 = c + s(w)·P^{-1/2}w with s(w) = ρ·min(1, 1/‖w‖) and ρ = (1 + 10⁻⁴)·δ̂ (δ̂ the stored radius): the
//! unit ball of w fills the ball, everything beyond it lands on the shell of radius ρ, a hair outside the
//! stored radius, where the f32 selection test decides (the f32 neighbourhood of the ball). Each start's
//! run goes through the shared evaluator on the exact plant ([`super::run_visiting`]); its objective is the
//! robustness of its sampled trace against the task's property ([`crate::property::Property`]: reach Goal
//! within T while avoiding Unsafe, Euclidean), and a start the evaluator refuses scores a large constant
//! (it is outside the cover, not a counterexample). Multi-start Nelder–Mead (argmin) from seeded random w
//! minimises it; every run is also judged by membership at samples and between them, inputs included, so
//! a violation is reported whether or not the robustness noticed it.

use super::{run_visiting, Judge, RunOutcome};
use crate::property::Property;
use crate::robustness::mtl::Trace;
use crate::settings::{settings_builder, Check, SettingError};
use argmin::core::{CostFunction, Error as ArgminError, Executor};
use argmin::solver::neldermead::NelderMead;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use shared_types::image::Image;
use std::cell::RefCell;
use std::time::Instant;

/// Settings of the falsifier, with documented defaults; build with [`AttackSettings::builder`].
#[derive(Clone, Debug)]
pub struct AttackSettings {
    /// Nelder–Mead starts per ball. ≥ 1. Default 2.
    pub starts_per_ball: usize,
    /// Closed-loop runs per start, at most (the initial simplex included). ≥ n + 2. Default 120.
    pub evaluations_per_start: usize,
    /// Seed of the random starts. Default 0xa77ac.
    pub seed: u64,
}

impl Default for AttackSettings {
    fn default() -> Self {
        Self {
            starts_per_ball: 2,
            evaluations_per_start: 120,
            seed: 0xa77ac,
        }
    }
}

impl AttackSettings {
    /// Checks the ranges documented on the fields (`evaluations_per_start` against n when attacking).
    pub fn validate(&self) -> Result<(), SettingError> {
        let c = Check("AttackSettings");
        c.at_least_one("starts_per_ball", self.starts_per_ball)?;
        c.rule(
            "evaluations_per_start",
            self.evaluations_per_start as f64,
            self.evaluations_per_start >= 3,
            "must be at least n + 2 (the simplex and one step)",
        )
    }
}

settings_builder!(
    AttackSettings,
    AttackSettingsBuilder {
        starts_per_ball: usize,
        evaluations_per_start: usize,
        seed: u64,
    }
);

/// What the falsifier found.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AttackReport {
    /// Closed-loop runs made.
    pub evaluations: usize,
    pub seconds: f64,
    /// The least robustness of an accepted start's run (Euclidean; > 0: every run found meets the task
    /// with that margin), and that start.
    pub worst_robustness: f64,
    pub worst_start: Vec<f64>,
    /// Runs that failed the task (membership), at most 10 listed, and how many there were.
    pub violations: usize,
    pub first_violations: Vec<RunOutcome>,
}

/// Why the falsifier could not run.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum AttackError {
    #[error(transparent)]
    Settings(#[from] SettingError),
    #[error(transparent)]
    Metric(#[from] super::MetricError),
    #[error(
        "AttackSettings.evaluations_per_start = {got}: this image has n = {n}, so at least {need}"
    )]
    Budget { got: usize, n: usize, need: usize },
}

/// The score of a start the evaluator refuses (outside the cover).
const REFUSED: f64 = 1e6;

/// One ball's search state: what every evaluation saw.
struct Search<'a> {
    judge: &'a Judge<'a>,
    image: &'a Image<'a>,
    centre: Vec<f64>,
    /// P^{-1/2} (row-major n×n) and the search radius ρ.
    pis: Vec<f64>,
    reach: f64,
    names: Vec<String>,
    seen: RefCell<Seen>,
}

#[derive(Default)]
struct Seen {
    evaluations: usize,
    worst: Option<(f64, Vec<f64>)>,
    violations: usize,
    first_violations: Vec<RunOutcome>,
}

impl Search<'_> {
    fn start(&self, w: &[f64]) -> Vec<f64> {
        let n = w.len();
        let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt();
        let s = if norm > 1.0 {
            self.reach / norm
        } else {
            self.reach
        };
        (0..n)
            .map(|i| self.centre[i] + s * (0..n).map(|j| self.pis[i * n + j] * w[j]).sum::<f64>())
            .collect()
    }

    /// The run from the start of `w`: its robustness (or [`REFUSED`]), recording what it saw.
    fn score(&self, w: &[f64]) -> f64 {
        let x0 = self.start(w);
        let mut states: Vec<Vec<f64>> = Vec::new();
        let out = run_visiting(self.judge, self.image, &x0, false, &mut |x| {
            states.push(x.to_vec())
        });
        let mut seen = self.seen.borrow_mut();
        seen.evaluations += 1;
        if out.violated() {
            seen.violations += 1;
            if seen.first_violations.len() < 10 {
                seen.first_violations.push(out.clone());
            }
        }
        if out.rejected {
            return REFUSED;
        }
        let h = self.judge.plant.period();
        let times: Vec<f64> = (0..states.len()).map(|k| k as f64 * h).collect();
        let columns: Vec<Vec<f64>> = (0..x0.len())
            .map(|i| states.iter().map(|x| x[i]).collect())
            .collect();
        let rho = Trace::new(times, self.names.clone(), columns)
            .ok()
            .and_then(|t| self.judge.property.trace_robustness(&t).ok())
            // A run whose trace cannot be scored (it left the finite numbers) is as bad as it gets.
            .unwrap_or(f64::NEG_INFINITY);
        if seen.worst.as_ref().is_none_or(|(b, _)| rho < *b) {
            seen.worst = Some((rho, x0));
        }
        // Nelder–Mead needs finite values.
        rho.max(-REFUSED)
    }
}

impl CostFunction for &Search<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, w: &Self::Param) -> Result<f64, ArgminError> {
        Ok(self.score(w))
    }
}

/// Attacks every ball of a feedforward image (module doc). Deterministic for the settings' seed: each
/// ball's search is seeded by the seed and its index, and the balls run in parallel.
pub fn attack(
    judge: &Judge<'_>,
    image: &Image<'_>,
    settings: &AttackSettings,
) -> Result<AttackReport, AttackError> {
    settings.validate()?;
    let n = image.n();
    if settings.evaluations_per_start < n + 2 {
        return Err(AttackError::Budget {
            got: settings.evaluations_per_start,
            n,
            need: n + 2,
        });
    }
    let pis = crate::linalg::to_row_major(super::inverse_sqrt_metric(image)?.as_ref());
    let names: Vec<String> = (1..=n).map(|i| format!("x{i}")).collect();
    let t0 = Instant::now();
    let per_ball: Vec<Seen> = (0..image.n_trajectories())
        .into_par_iter()
        .map(|t| {
            let search = Search {
                judge,
                image,
                centre: (0..n).map(|i| image.centre(t, i) as f64).collect(),
                pis: pis.clone(),
                reach: image.delta(t) as f64 * (1.0 + 1e-4),
                names: names.clone(),
                seen: RefCell::new(Seen::default()),
            };
            let mut rng =
                ChaCha8Rng::seed_from_u64(settings.seed ^ (t as u64).wrapping_mul(0x9e37_79b9));
            for _ in 0..settings.starts_per_ball {
                let w0: Vec<f64> = (0..n).map(|_| rng.random_range(-0.9..0.9)).collect();
                let simplex: Vec<Vec<f64>> = std::iter::once(w0.clone())
                    .chain((0..n).map(|i| {
                        let mut v = w0.clone();
                        v[i] += if v[i] > 0.0 { -0.4 } else { 0.4 };
                        v
                    }))
                    .collect();
                // Each iteration costs one or two runs (a shrink n); the cap keeps the budget.
                let iters = ((settings.evaluations_per_start - (n + 1)) / 2) as u64;
                if let Ok(nm) = NelderMead::new(simplex).with_sd_tolerance(1e-10) {
                    // A failed search still counted its runs; nothing else to recover.
                    let _ = Executor::new(&search, nm)
                        .configure(|s| s.max_iters(iters))
                        .run();
                }
            }
            search.seen.into_inner()
        })
        .collect();
    let mut report = AttackReport {
        evaluations: 0,
        seconds: 0.0,
        worst_robustness: f64::INFINITY,
        worst_start: Vec::new(),
        violations: 0,
        first_violations: Vec::new(),
    };
    for s in per_ball {
        report.evaluations += s.evaluations;
        report.violations += s.violations;
        for v in s.first_violations {
            if report.first_violations.len() < 10 {
                report.first_violations.push(v);
            }
        }
        if let Some((w, x0)) = s.worst {
            if w < report.worst_robustness {
                report.worst_robustness = w;
                report.worst_start = x0;
            }
        }
    }
    report.seconds = t0.elapsed().as_secs_f64();
    Ok(report)
}
