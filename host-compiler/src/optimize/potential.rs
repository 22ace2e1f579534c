//! Potential-function descent (§5.2): a smooth cost that is zero exactly when the nominal keeps a desired
//! robustness δ_d, its adjoint gradient (§5.2.1), the adaptive-step gradient descent of Algorithm 3, an
//! L-BFGS alternative from `argmin`, and the time-optimal bisection over the terminal step of §5.2.3
//! (Example 5.2).
//!
//! **Potentials** (§5.2.3, in the CAF metric and on the same pieces the certificate takes, so that zero
//! cost means the certificate keeps δ_d). With δ_t = δ_d + 2μ (μ a small margin) and (·)₊ = max(·, 0):
//!
//! * Goal, terminal: G(x̃(N)) = α/2 · (δ_t − depth_P(x̃(N), Goal))₊²
//! * Unsafe, incremental: h Σ_κ ½ (δ_t − δ_Unsafe(κ))₊², δ_Unsafe(κ) with the inter-sample margin
//! * Input, incremental: β h Σ_κ ½ (δ_t − δ_Input(κ))₊², δ_Input(κ) with the f32 rounding margin
//!
//! (h the sample period, the text's integrals as sums). Example 5.2 uses a quadratic pull to the centre of
//! Goal and a log barrier at Unsafe; both are nonzero for some acceptable trajectories or infinite for
//! infeasible seeds, so here every potential is a squared hinge on the certificate's own piece: C¹, zero on
//! the acceptable set and finite everywhere (an infeasible seed can be repaired).
//!
//! **Termination.** As in Example 5.2, a bound on the cost bounds every violation: J ≤ ½·min(α, h, βh)·μ²
//! implies each piece is ≥ δ_t − μ = δ_d + μ. The answer is then re-certified through
//! [`crate::certify::shipped`]; `reached` is true only when that certificate keeps δ_d.
//!
//! **Which descent** (measured by `benches/optimize_planar.rs` on the planar vehicle, repairing the
//! infeasible constant seed to δ_d = 0.04 from five f32 points of Init): L-BFGS reaches zero cost in
//! 68–112 cost evaluations (median 84), Algorithm 3 in 28–318 (median 99); in wall time the medians are
//! close (about 0.09 s against 0.10 s) but L-BFGS's worst case is about 3× better, so it is the default
//! [`DescentMethod`]. In the time-optimal bisection the picture turns: most probes are infeasible, and
//! there L-BFGS's line searches spend many evaluations before giving up, so Algorithm 3 finishes the
//! bisection about 4× sooner (L-BFGS found a slightly shorter terminal time, 315 against 323 steps).
//! Both stay available.

use super::pieces::{adjoint, LocalGrad, Pieces};
use super::{check_inputs, OptimizeError};
use crate::certify::{self, Certificate, Loop, LoopConstants};
use crate::settings::{settings_builder, Check, SettingError};
use crate::trajectory::Nominal;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Settings of the potential-function descent, with documented defaults. Build with
/// [`PotentialSettings::builder`] (validated; `to_builder` starts from existing settings) or take
/// [`Default`]. Every entry point checks them again.
#[derive(Clone, Debug)]
pub struct PotentialSettings {
    /// δ_d, the robustness the trajectory must keep. Finite, > 0. Default 0.01.
    pub delta: f64,
    /// α, weight of the Goal potential. Finite, ≥ 0. Default 1.
    pub weight_goal: f64,
    /// β, weight of the Input potential relative to Unsafe. Finite, ≥ 0. Default 1.
    pub weight_input: f64,
    /// μ/δ_d, the margin that absorbs f32 rounding of v in the re-certification. Finite, ≥ 0.
    /// Default 1e-3.
    pub margin: f64,
    /// Algorithm 3: factor α on the step after a decrease. Finite, > 1. Default 2.
    pub grow: f64,
    /// Algorithm 3: factor β on the step after an increase. In (0, 1). Default 0.5.
    pub shrink: f64,
    /// Algorithm 3: first step λ. Finite, > 0. Default 1.
    pub initial_step: f64,
    /// Algorithm 3: stop when λ falls below ε. Finite, > 0. Default 1e-12.
    pub min_step: f64,
    /// Iterations at most, per descent. ≥ 1. Default 2000.
    pub max_iterations: usize,
    /// L-BFGS memory. ≥ 1. Default 10.
    pub lbfgs_memory: usize,
    /// Cost evaluations at most per descent (L-BFGS's line searches may take many per iteration). ≥ 1.
    /// Default 20 000.
    pub max_evaluations: usize,
    /// Show a progress bar over the probes of [`time_optimal`]. Default false.
    pub progress: bool,
    /// Reference hold L ([`crate::trajectory::hold`]): the start is projected onto block-constant
    /// sequences and so is every gradient, so the descent stays block-constant. ≥ 1. Default 1.
    pub hold: usize,
}

impl Default for PotentialSettings {
    fn default() -> Self {
        Self {
            delta: 0.01,
            weight_goal: 1.0,
            weight_input: 1.0,
            margin: 1e-3,
            grow: 2.0,
            shrink: 0.5,
            initial_step: 1.0,
            min_step: 1e-12,
            max_iterations: 2000,
            lbfgs_memory: 10,
            max_evaluations: 20_000,
            progress: false,
            hold: 1,
        }
    }
}

impl PotentialSettings {
    /// Checks the ranges documented on the fields; the first violation is returned.
    pub fn validate(&self) -> Result<(), SettingError> {
        let c = Check("PotentialSettings");
        c.positive("delta", self.delta)?;
        c.non_negative("weight_goal", self.weight_goal)?;
        c.non_negative("weight_input", self.weight_input)?;
        c.non_negative("margin", self.margin)?;
        c.rule(
            "grow",
            self.grow,
            self.grow.is_finite() && self.grow > 1.0,
            "must be finite and > 1",
        )?;
        c.open_unit("shrink", self.shrink)?;
        c.positive("initial_step", self.initial_step)?;
        c.positive("min_step", self.min_step)?;
        c.at_least_one("max_iterations", self.max_iterations)?;
        c.at_least_one("lbfgs_memory", self.lbfgs_memory)?;
        c.at_least_one("max_evaluations", self.max_evaluations)?;
        c.at_least_one("hold", self.hold)
    }
}

settings_builder!(
    PotentialSettings,
    PotentialSettingsBuilder {
        delta: f64,
        weight_goal: f64,
        weight_input: f64,
        margin: f64,
        grow: f64,
        shrink: f64,
        initial_step: f64,
        min_step: f64,
        max_iterations: usize,
        lbfgs_memory: usize,
        max_evaluations: usize,
        progress: bool,
        hold: usize,
    }
);

/// Which descent to run (default L-BFGS, the faster to zero cost; module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum DescentMethod {
    /// Algorithm 3: gradient steps with the adaptive step size.
    Algorithm3,
    /// `argmin`'s L-BFGS with a Moré–Thuente line search.
    #[default]
    Lbfgs,
}

/// The potential cost of §5.2.3 for one loop, start and terminal step count.
pub struct Potential<'a, 'b> {
    pc: Pieces<'a, 'b>,
    x0: Vec<f64>,
    steps: usize,
    m: usize,
    /// δ_t = δ_d + 2μ.
    target: f64,
    alpha: f64,
    beta: f64,
    h: f64,
    /// Componentwise rounding bound and its 2-norm, held fixed (taken from the start's certificate, ×2).
    eps: Vec<f64>,
    eps_f32: f64,
    /// J at or below this means every piece ≥ δ_d + μ.
    pub zero_tol: f64,
    evals: AtomicUsize,
    /// Reference hold L: gradients are projected onto block-constant sequences.
    hold: usize,
}

impl<'a, 'b> Potential<'a, 'b> {
    /// `eps_from`: a certificate whose rounding bound is taken (doubled) as the fixed ε of the Input and
    /// Unsafe pieces.
    pub fn new(
        lp: &'a Loop<'b>,
        lc: &'a LoopConstants,
        x0: &[f64],
        steps: usize,
        eps_from: &Certificate,
        s: &PotentialSettings,
    ) -> Self {
        let mu = s.margin * s.delta.abs() + 1e-12;
        let h = lp.continuous().map_or(1.0, |_| lp.plant.period());
        let alpha = s.weight_goal;
        let beta = s.weight_input;
        Self {
            pc: Pieces::new(lp, lc),
            x0: x0.to_vec(),
            steps,
            m: lp.K.nrows(),
            target: s.delta + 2.0 * mu,
            alpha,
            beta,
            h,
            eps: eps_from.eps_components.iter().map(|e| 2.0 * e).collect(),
            eps_f32: 2.0 * eps_from.eps_f32,
            zero_tol: 0.5 * alpha.min(h).min(beta * h) * mu * mu,
            evals: AtomicUsize::new(0),
            hold: s.hold,
        }
    }

    /// Number of cost evaluations so far.
    pub fn evaluations(&self) -> usize {
        self.evals.load(Ordering::Relaxed)
    }

    pub fn steps(&self) -> usize {
        self.steps
    }

    fn nominal(&self, v: &[Vec<f64>]) -> Nominal {
        let lp = self.pc.lp;
        lp.simulate(&self.x0, v)
    }

    /// J(v) and, when asked, ∂J/∂v by the adjoint sweep.
    pub fn eval(&self, v: &[Vec<f64>], want_grad: bool) -> (f64, Option<Vec<Vec<f64>>>) {
        self.evals.fetch_add(1, Ordering::Relaxed);
        let nom = self.nominal(v);
        let N = self.steps;
        let t = self.target;
        let mut J = 0.0;
        let mut local: Vec<(f64, LocalGrad)> = Vec::new();
        let (g, lg) = self.pc.goal_grad(&nom, N);
        if g < t {
            J += 0.5 * self.alpha * (t - g) * (t - g);
            local.push((-self.alpha * (t - g), lg));
        }
        let uns = self.pc.unsafe_values(&nom, self.eps_f32);
        for (k, &u) in uns.iter().enumerate() {
            if u < t {
                J += 0.5 * self.h * (t - u) * (t - u);
                if want_grad {
                    let (_, lg) = self.pc.unsafe_grad(&nom, k, self.eps_f32);
                    local.push((-self.h * (t - u), lg));
                }
            }
        }
        let inp = self.pc.input_values(&nom, &self.eps);
        for (k, &u) in inp.iter().enumerate() {
            if u < t {
                J += 0.5 * self.beta * self.h * (t - u) * (t - u);
                if want_grad {
                    let (_, lg) = self.pc.input_grad(&nom, k, &self.eps);
                    local.push((-self.beta * self.h * (t - u), lg));
                }
            }
        }
        if !J.is_finite() {
            return (f64::INFINITY, None);
        }
        if !want_grad {
            return (J, None);
        }
        let refs: Vec<(f64, &LocalGrad)> = local.iter().map(|(w, l)| (*w, l)).collect();
        let mut g = adjoint(&self.pc, N, &refs);
        crate::trajectory::hold::project(&mut g, self.hold);
        (J, Some(g))
    }

    fn unflatten(&self, z: &[f64]) -> Vec<Vec<f64>> {
        z.chunks(self.m).map(|c| c.to_vec()).collect()
    }
}

/// The result of one descent.
#[derive(Clone, Debug)]
pub struct Descent {
    /// The final reference inputs (before f32 rounding).
    pub v: Vec<Vec<f64>>,
    /// J of the final iterate.
    pub cost: f64,
    /// J reached the zero tolerance.
    pub zero_cost: bool,
    /// The shipped nominal and its certificate.
    pub nominal: Nominal,
    pub certificate: Certificate,
    /// Zero cost *and* the re-certified δ keeps δ_d.
    pub reached: bool,
    pub iterations: usize,
    pub evaluations: usize,
    pub seconds: f64,
}

/// Algorithm 3 on a potential: v ← v − λq; λ ← αλ after a decrease (the step is kept), λ ← βλ after an
/// increase (the step is dropped), until J reaches the zero tolerance, λ < ε or the iteration cap.
fn algorithm3(
    pot: &Potential<'_, '_>,
    v0: &[Vec<f64>],
    s: &PotentialSettings,
) -> (Vec<Vec<f64>>, f64, usize) {
    let mut v = v0.to_vec();
    let (mut J, mut q) = pot.eval(&v, true);
    let mut lam = s.initial_step;
    let mut it = 0;
    while lam > s.min_step && J > pot.zero_tol && it < s.max_iterations {
        let Some(qq) = q.as_ref() else { break };
        let trial: Vec<Vec<f64>> = v
            .iter()
            .zip(qq)
            .map(|(a, b)| a.iter().zip(b).map(|(x, y)| x - lam * y).collect())
            .collect();
        let (Jt, qt) = pot.eval(&trial, true);
        if Jt < J {
            v = trial;
            J = Jt;
            q = qt;
            lam *= s.grow;
        } else {
            lam *= s.shrink;
        }
        it += 1;
    }
    (v, J, it)
}

/// The potential as an `argmin` problem; it remembers the best point it evaluated and refuses to evaluate
/// past the budget (argmin has no evaluation cap of its own), so a run cut short still returns that point.
struct ArgminProblem<'p, 'a, 'b> {
    pot: &'p Potential<'a, 'b>,
    best: &'p std::sync::Mutex<(f64, Vec<f64>)>,
    max_evaluations: usize,
    gradients: &'p AtomicUsize,
}

/// A cost and, when asked for, its gradient per step.
type CostGrad = (f64, Option<Vec<Vec<f64>>>);

impl ArgminProblem<'_, '_, '_> {
    fn eval(&self, p: &[f64], grad: bool) -> Result<CostGrad, argmin::core::Error> {
        if self.pot.evaluations() >= self.max_evaluations {
            return Err(argmin::core::Error::msg("evaluation budget spent"));
        }
        let r = self.pot.eval(&self.pot.unflatten(p), grad);
        if let Ok(mut b) = self.best.lock() {
            if r.0 < b.0 {
                *b = (r.0, p.to_vec());
            }
        }
        Ok(r)
    }
}

impl argmin::core::CostFunction for ArgminProblem<'_, '_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.eval(p, false)?.0)
    }
}

impl argmin::core::Gradient for ArgminProblem<'_, '_, '_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, p: &Self::Param) -> Result<Vec<f64>, argmin::core::Error> {
        self.gradients.fetch_add(1, Ordering::Relaxed);
        let (_, g) = self.eval(p, true)?;
        let g = g.ok_or_else(|| argmin::core::Error::msg("cost is not finite"))?;
        Ok(g.into_iter().flatten().collect())
    }
}

/// L-BFGS from `argmin` (Moré–Thuente line search), stopped at the same zero tolerance.
fn lbfgs(
    pot: &Potential<'_, '_>,
    v0: &[Vec<f64>],
    s: &PotentialSettings,
) -> (Vec<Vec<f64>>, f64, usize) {
    use argmin::core::{Executor, State};
    use argmin::solver::linesearch::MoreThuenteLineSearch;
    use argmin::solver::quasinewton::LBFGS;
    let z0: Vec<f64> = v0.iter().flatten().copied().collect();
    let J0 = pot.eval(v0, false).0;
    if J0 <= pot.zero_tol {
        return (v0.to_vec(), J0, 0);
    }
    let solver = LBFGS::new(MoreThuenteLineSearch::new(), s.lbfgs_memory.max(1));
    let solver = match solver
        .with_tolerance_grad(0.0)
        .and_then(|sv| sv.with_tolerance_cost(0.0))
    {
        Ok(sv) => sv,
        Err(_) => return (v0.to_vec(), J0, 0),
    };
    let best = std::sync::Mutex::new((J0, z0.clone()));
    let gradients = AtomicUsize::new(0);
    let problem = ArgminProblem {
        pot,
        best: &best,
        max_evaluations: s.max_evaluations,
        gradients: &gradients,
    };
    let run = Executor::new(problem, solver)
        .configure(|st| {
            st.param(z0.clone())
                .max_iters(s.max_iterations as u64)
                .target_cost(pot.zero_tol)
        })
        .run();
    let iterations = run
        .as_ref()
        .map(|r| r.state().get_iter() as usize)
        // Cut short (budget, line search): count the gradients taken, one per iteration.
        .unwrap_or_else(|_| gradients.load(Ordering::Relaxed));
    // The best point evaluated, whether the run ended normally, on the evaluation budget or on a failed
    // line search.
    let (J, z) = best.into_inner().unwrap_or((J0, z0));
    (pot.unflatten(&z), J, iterations)
}

/// Descend the potential of §5.2.3 from `v0` (its length is the terminal step N) and re-certify the
/// answer through [`certify::shipped`].
pub fn descend(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    v0: &[Vec<f64>],
    s: &PotentialSettings,
    method: DescentMethod,
) -> Result<Descent, OptimizeError> {
    check_inputs(lp, x0, v0)?;
    if !(s.delta > 0.0 && s.delta.is_finite()) {
        return Err(OptimizeError::BadDelta(s.delta));
    }
    s.validate()?;
    Ok(descend_checked(lp, lc, x0, v0, s, method))
}

fn descend_checked(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    v0: &[Vec<f64>],
    s: &PotentialSettings,
    method: DescentMethod,
) -> Descent {
    let t = Instant::now();
    let mut v0 = v0.to_vec();
    crate::trajectory::hold::project(&mut v0, s.hold);
    let v0 = &v0[..];
    let (_, c0) = certify::shipped(lp, lc, x0, v0);
    let pot = Potential::new(lp, lc, x0, v0.len(), &c0, s);
    let (v, cost, iterations) = match method {
        DescentMethod::Algorithm3 => algorithm3(&pot, v0, s),
        DescentMethod::Lbfgs => lbfgs(&pot, v0, s),
    };
    let (nominal, certificate) = certify::shipped(lp, lc, x0, &v);
    let zero_cost = cost <= pot.zero_tol;
    let reached = zero_cost && certificate.is_certified() && certificate.delta >= s.delta;
    Descent {
        v,
        cost,
        zero_cost,
        nominal,
        certificate,
        reached,
        iterations,
        evaluations: pot.evaluations(),
        seconds: t.elapsed().as_secs_f64(),
    }
}

/// The result of the time-optimal bisection.
#[derive(Clone, Debug)]
pub struct TimeOptimal {
    /// Terminal step of the seed (its k*) and of the answer.
    pub steps_before: usize,
    pub steps_after: usize,
    /// δ the answer keeps (δ_d).
    pub delta_kept: f64,
    /// The shortest feasible descent found (None when even the seed's length failed).
    pub best: Option<Descent>,
    /// Every probe: (terminal step, feasible).
    pub probes: Vec<(usize, bool)>,
}

/// §5.2.3: the shortest terminal step N for which the descent reaches zero cost at δ_d (and the shipped
/// certificate keeps δ_d), by bisection between 0 and the seed's k*. Each probe starts from the shortest
/// feasible answer so far, cut to the probed length (the text starts from the person's input, cut).
pub fn time_optimal(
    lp: &Loop<'_>,
    lc: &LoopConstants,
    x0: &[f64],
    v_seed: &[Vec<f64>],
    s: &PotentialSettings,
    method: DescentMethod,
) -> Result<TimeOptimal, OptimizeError> {
    check_inputs(lp, x0, v_seed)?;
    if !(s.delta > 0.0 && s.delta.is_finite()) {
        return Err(OptimizeError::BadDelta(s.delta));
    }
    s.validate()?;
    let (_, c) = certify::shipped(lp, lc, x0, v_seed);
    let hi0 = c.k_star.max(1).min(v_seed.len());
    // One probe at k*, then ⌈log₂ k*⌉ bisection probes at most.
    let pb = if s.progress {
        let b = indicatif::ProgressBar::new(1 + (usize::BITS - hi0.leading_zeros()) as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template("{msg:>28} [{bar:30}] {pos}/{len} {elapsed}")
                .unwrap_or(indicatif::ProgressStyle::default_bar()),
        );
        b.set_message("time-optimal probes");
        b
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut probes = Vec::new();
    let first = descend_checked(lp, lc, x0, &v_seed[..hi0], s, method);
    probes.push((hi0, first.reached));
    pb.inc(1);
    if !first.reached {
        pb.finish_and_clear();
        return Ok(TimeOptimal {
            steps_before: hi0,
            steps_after: hi0,
            delta_kept: s.delta,
            best: None,
            probes,
        });
    }
    let (mut lo, mut hi) = (0usize, hi0);
    let mut best = first;
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        let d = descend_checked(lp, lc, x0, &best.v[..mid], s, method);
        probes.push((mid, d.reached));
        pb.inc(1);
        if d.reached {
            hi = mid;
            best = d;
        } else {
            lo = mid;
        }
    }
    pb.finish_and_clear();
    Ok(TimeOptimal {
        steps_before: hi0,
        steps_after: hi,
        delta_kept: s.delta,
        best: Some(best),
        probes,
    })
}

#[cfg(test)]
mod tests {
    use super::PotentialSettings;

    #[test]
    fn the_potential_builder_refuses_a_step_factor_that_does_not_grow() {
        let e = PotentialSettings::builder().grow(1.0).build().unwrap_err();
        assert_eq!(
            (e.settings, e.field, e.value),
            ("PotentialSettings", "grow", 1.0)
        );
        assert_eq!(e.rule, "must be finite and > 1");
        let e = PotentialSettings::builder()
            .delta(f64::NAN)
            .build()
            .unwrap_err();
        assert_eq!(e.field, "delta");
        assert!(PotentialSettings::builder()
            .lbfgs_memory(0)
            .build()
            .is_err());
        let s = PotentialSettings::builder().delta(0.02).build().unwrap();
        assert_eq!((s.delta, s.max_iterations), (0.02, 2000));
    }
}
