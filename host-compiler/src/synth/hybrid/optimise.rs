//! §5.3 for runs with internal switching (Examples 5.5, 5.6): the certified δ of a run
//! ([`crate::certify::internal`], Theorem 4.24 sampled) maximised over the tables of its segments
//! before the last, the start states of the segments after the first, and then the last segment's
//! table against Goal.
//!
//! The first segment's δ is what the run's ball is, and it is bound by everything downstream of it: the
//! event intervals its tube crosses the guard in, the landing of those crossings inside the next
//! segment's ball, transversality and late detection. Those are bisection outcomes of a certificate
//! that is cheap (milliseconds) but not differentiable as a whole, so the search is derivative-free:
//! Nelder–Mead (argmin) over a small smooth basis of table changes (hat functions over each non-last
//! segment's rows, per input) and an offset of each later segment's start from the centre of the
//! landings ([`super::landing`]); each trial re-simulates the run from the first segment's start (the
//! later segments with their own tables), so every point the search sees is a run that ships, and its
//! value is [`super::certify_run`]'s. The last segment is then maximised against Goal by the bundle
//! method of one location ([`crate::optimize::maximize_delta`]), which raises the ball the landing must
//! fit in, and the search is repeated once from there. A change is kept only if the run's δ rises.

use super::{certify_run, f32_start, landing, shipped_nominal, HybridRun, HybridTask};
use crate::property::InputBound;
use crate::trajectory::Nominal;
use argmin::core::{CostFunction, Error as ArgminError, Executor};
use argmin::solver::neldermead::NelderMead;

/// Hat functions per input channel over a non-last segment's rows.
pub const HATS: usize = 8;
/// Initial simplex step of a hat's coefficient, as a fraction of the input set's half-width.
const HAT_STEP: f64 = 0.15;
/// Initial simplex step of a start offset, as a fraction of the next segment's current δ (in its metric).
const OFFSET_STEP: f64 = 0.3;

/// The search's variables mapped to a run.
struct Trial<'a> {
    task: &'a HybridTask,
    base: &'a HybridRun,
    /// The first segment's start (f32): the base run's, or for Algorithm 4 a point on its ball's boundary.
    start: Vec<f64>,
    /// Input scale per channel (half-width of the input box).
    scale: Vec<f64>,
}

impl Trial<'_> {
    fn dims(&self) -> usize {
        let segs = self.base.nominals.len();
        let (n, m) = (self.base.nominals[0].x[0].len(), self.scale.len());
        (segs - 1) * (HATS * m + n)
    }

    /// The run for the variables `w` (`None` if a segment no longer switches).
    fn run(
        &self,
        w: &[f64],
    ) -> Option<(Vec<Nominal>, crate::certify::internal::InternalCertificate)> {
        let task = self.task;
        let segs = self.base.nominals.len();
        let (n, m) = (self.base.nominals[0].x[0].len(), self.scale.len());
        let per = HATS * m + n;
        let mut x = self.start.clone();
        let mut nominals = Vec::with_capacity(segs);
        for (i, old) in self.base.nominals.iter().enumerate() {
            let loc = self.base.locations[i];
            if i + 1 == segs {
                nominals.push(shipped_nominal(task, loc, &x, &old.v));
                break;
            }
            let c = &w[i * per..(i + 1) * per];
            let rows = old.steps();
            let v: Vec<Vec<f64>> = old
                .v
                .iter()
                .enumerate()
                .map(|(k, row)| {
                    row.iter()
                        .enumerate()
                        .map(|(j, &a)| {
                            a + self.scale[j]
                                * (0..HATS)
                                    .map(|h| c[j * HATS + h] * hat(h, k, rows))
                                    .sum::<f64>()
                        })
                        .collect()
                })
                .collect();
            let nom = shipped_nominal(task, loc, &x, &v);
            let centre = landing(task, loc, &nom, task.edges[i])?;
            // The offset is in the next location's metric, scaled by its segment's current radius.
            let next = self.base.locations[i + 1];
            let r = self.base.certificate.segments[i + 1].delta.max(1e-3);
            let off = &c[HATS * m..];
            let dx = crate::linalg::mat_vec(
                task.constants[next].roots.inv_sqrt.as_ref(),
                &off.iter().map(|o| o * r).collect::<Vec<_>>(),
            );
            x = f32_start(
                &centre
                    .iter()
                    .zip(&dx)
                    .map(|(a, b)| a + b)
                    .collect::<Vec<_>>(),
            );
            nominals.push(nom);
        }
        let cert = certify_run(task, &nominals).ok()?;
        Some((nominals, cert))
    }
}

/// Hat function h of HATS over rows 0..rows (peaks evenly spaced, the first at row 0, the last at the
/// last row).
fn hat(h: usize, k: usize, rows: usize) -> f64 {
    let span = (rows.max(2) - 1) as f64 / (HATS - 1) as f64;
    let peak = h as f64 * span;
    (1.0 - (k as f64 - peak).abs() / span).max(0.0)
}

impl CostFunction for &Trial<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, w: &Self::Param) -> Result<f64, ArgminError> {
        Ok(self.run(w).map_or(1.0, |(_, c)| -c.delta()))
    }
}

/// One Nelder–Mead search from `base` (module doc), at most `iterations` iterations; the better of the
/// two runs.
fn search(task: &HybridTask, base: HybridRun, iterations: u64) -> HybridRun {
    if base.nominals.len() < 2 || iterations == 0 {
        return base;
    }
    let m = base.nominals[0].v[0].len();
    let trial = Trial {
        task,
        base: &base,
        start: base.nominals[0].x[0].clone(),
        scale: input_half_widths(task, m),
    };
    let dim = trial.dims();
    let per = HATS * m + base.nominals[0].x[0].len();
    let w0 = vec![0.0; dim];
    let simplex: Vec<Vec<f64>> = std::iter::once(w0.clone())
        .chain((0..dim).map(|i| {
            let mut w = w0.clone();
            w[i] = if i % per < HATS * m {
                HAT_STEP
            } else {
                OFFSET_STEP
            };
            w
        }))
        .collect();
    let Ok(nm) = NelderMead::new(simplex).with_sd_tolerance(1e-9) else {
        return base;
    };
    let Ok(res) = Executor::new(&trial, nm)
        .configure(|s| s.max_iters(iterations))
        .run()
    else {
        return base;
    };
    let Some(w) = res.state.best_param.clone() else {
        return base;
    };
    match trial.run(&w) {
        Some((nominals, certificate)) if certificate.delta() > base.delta() => HybridRun {
            nominals,
            locations: base.locations.clone(),
            certificate,
        },
        _ => base,
    }
}

/// Half the input set's width per channel (the search's unit of a table change).
fn input_half_widths(task: &HybridTask, m: usize) -> Vec<f64> {
    match &task.property.input {
        InputBound::Box { lo, hi } => lo.iter().zip(hi).map(|(l, h)| 0.5 * (h - l)).collect(),
        InputBound::Norm2 { max, .. } => vec![*max; m],
    }
}

/// Algorithm 4 (§5.4) across internal guards: `parent`'s feedback law from `y` (a point on the boundary
/// of its ball). In the loop's form u = Kx + v the law u = K(x − x̃) + ũ is v = ṽ, so each segment keeps
/// the parent's table; the run re-synchronises at each guard as the image does, the next segment starting
/// from the centre of its own nominal's landings ([`super::landing`]). The run is certified as shipped,
/// then optimised by §5.3 ([`optimise`], `iterations` per search). `Err` says why it was not certified.
pub fn grow_from(
    task: &HybridTask,
    parent: &HybridRun,
    y: &[f64],
    iterations: u64,
) -> Result<HybridRun, String> {
    let m = parent.nominals[0].v.first().map_or(0, |r| r.len());
    let trial = Trial {
        task,
        base: parent,
        start: f32_start(y),
        scale: input_half_widths(task, m),
    };
    let (nominals, certificate) = trial.run(&vec![0.0; trial.dims()]).ok_or(
        "the parent's law from this start does not cross a guard, or the run is not certified",
    )?;
    let run = HybridRun {
        nominals,
        locations: parent.locations.clone(),
        certificate,
    };
    Ok(optimise(task, run, iterations))
}

/// The last segment's table maximised against Goal (its terminal step free within the horizon), the run
/// re-certified; kept if its δ rises.
fn last_segment(task: &HybridTask, run: HybridRun) -> HybridRun {
    use crate::optimize::{maximize_delta, BundleSettings};
    let Ok(free) = BundleSettings::builder()
        .max_iterations(task.problem.synthesis.max_iterations)
        .terminal_time(true)
        .build()
    else {
        return run;
    };
    let last = run.nominals.len() - 1;
    let loc = run.locations[last];
    let nom = &run.nominals[last];
    let earlier: usize = run.nominals[..last].iter().map(|n| n.steps()).sum();
    let steps_max = task.steps.saturating_sub(earlier).max(nom.steps());
    let cancel = std::sync::atomic::AtomicBool::new(false);
    let opt = maximize_delta(
        &task.lp(loc),
        &task.constants[loc],
        &nom.x[0],
        &nom.v,
        steps_max,
        &free,
        &cancel,
    );
    let mut nominals = run.nominals.clone();
    nominals[last] = shipped_nominal(task, loc, &nom.x[0], &opt.nominal.v);
    match certify_run(task, &nominals) {
        Ok(certificate) if certificate.delta() > run.delta() => HybridRun {
            nominals,
            locations: run.locations,
            certificate,
        },
        _ => run,
    }
}

/// §5.3 on a planned run (module doc): search, the last segment, search again.
pub fn optimise(task: &HybridTask, run: HybridRun, iterations: u64) -> HybridRun {
    let run = search(task, run, iterations);
    let run = last_segment(task, run);
    search(task, run, iterations)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example_5_5() -> HybridTask {
        let path = format!(
            "{}/../examples/hybrid-internal-5-5.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        HybridTask::new(crate::spec::load(&path).expect("the example parses"))
            .expect("a hybrid task")
    }

    /// Example 5.5 with one iteration of §5.3 (half of 1 is none for the search; the bundle gets one),
    /// and the planner's run from (−5, 1, 2), planned once for the tests below.
    fn planned_5_5() -> &'static (HybridTask, HybridRun) {
        static ONCE: std::sync::OnceLock<(HybridTask, HybridRun)> = std::sync::OnceLock::new();
        ONCE.get_or_init(|| {
            let mut task = example_5_5();
            task.problem.synthesis.max_iterations = 1;
            let run = super::super::plan_run(&task, &[-5.0, 1.0, 2.0]).expect("a run");
            (task, run)
        })
    }

    #[test]
    fn algorithm_4_grows_a_run_across_the_guard_from_a_point_on_its_parents_ball() {
        let (task, parent) = planned_5_5();
        let x0 = &parent.nominals[0].x[0];
        let r = parent.certificate.delta_stored as f64;
        // A point 0.9 of the way to the ball's boundary along the first axis of the first metric.
        let P = task.designs[task.path[0]].P.as_ref();
        let mut y = x0.clone();
        y[0] += 0.9 * r / P[(0, 0)].sqrt();
        let grown = grow_from(task, parent, &y, 0).expect("grown and certified");
        // It starts at the f32 point, keeps the parent's locations, crosses the guard, and ships what it
        // certified (the certificate recomputed from its nominals is the same).
        assert_eq!(grown.nominals[0].x[0], f32_start(&y));
        assert_eq!(grown.locations, parent.locations);
        assert_eq!(grown.nominals.len(), parent.nominals.len());
        assert!(grown.certificate.is_certified(), "δ {}", grown.delta());
        assert_eq!(
            certify_run(task, &grown.nominals).unwrap(),
            grown.certificate
        );
        // With no search the tables are the parent's: the law v = ṽ.
        assert_eq!(grown.nominals[0].v, parent.nominals[0].v);
        // A start the parent's law does not carry across the guard is refused, not certified.
        let far: Vec<f64> = x0.iter().map(|v| v + 1e3).collect();
        assert!(grow_from(task, parent, &far, 0).is_err());
    }

    #[test]
    fn optimising_example_5_5_s_run_raises_its_delta_and_ships_what_it_certified() {
        let (task, run) = planned_5_5();
        let (task, run) = (task, run.clone());
        let opt = optimise(&task, run.clone(), 100);
        assert!(
            opt.delta() > 1.02 * run.delta(),
            "δ {} → {}",
            run.delta(),
            opt.delta()
        );
        // The answer is the certificate of the nominals it ships: the first from the same f32 start,
        // each later one from an f32 start, and the run's certificate recomputed from them is the same.
        assert_eq!(opt.nominals[0].x[0], run.nominals[0].x[0]);
        for nom in &opt.nominals[1..] {
            assert_eq!(nom.x[0], f32_start(&nom.x[0]));
        }
        assert_eq!(opt.locations, run.locations);
        let again = certify_run(&task, &opt.nominals).expect("a run of the path");
        assert_eq!(again, opt.certificate);
        // No iterations: the search is the identity.
        let same = search(&task, run.clone(), 0);
        assert_eq!(same.certificate, run.certificate);
    }
}
