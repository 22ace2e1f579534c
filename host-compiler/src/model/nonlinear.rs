//! A nonlinear input-affine plant written in the spec (§3.1.2, (3.16)): ẋ = f(x) + g(x)u with its
//! parameters bound, evaluated in f64 and flowed over a sample period with the input held by an adaptive
//! Dormand–Prince 8(5,3) integrator (`ode_solvers::Dop853`) at a tight tolerance. This is the plant the
//! verifier and the QEMU harness run a nonlinear task's controller against: it is never exactly
//! discretised, so the certificate treats the sampled loop's departure from the linear model as a bounded
//! disturbance (`certify::nonlinear`), and this flow is the independent judge of that.

use super::ModelError;
use crate::expr::tape::Tape;
use crate::expr::{Expr, Point};
use crate::spec::nonlinear::NonlinearDesc;
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OVector};
use ode_solvers::dop_shared::OutputType;
use ode_solvers::{DVector, Dop853, SVector, System};

/// Relative tolerance of the integrator.
pub const RTOL: f64 = 1e-10;
/// Absolute tolerance of the integrator.
pub const ATOL: f64 = 1e-12;

/// The plant of a nonlinear spec, parameters bound to their values.
#[derive(Clone, Debug)]
pub struct NonlinearPlant {
    /// g's entries, kept so that the field skips the zero ones.
    g: Vec<Vec<Expr>>,
    /// f's entries, then g's row by row, as one tape ([`crate::expr::tape`]).
    tape: Tape,
    n: usize,
    m: usize,
    period: f64,
}

/// The vector field with the input held, as `ode_solvers` asks for it; `V` is a stack vector of the
/// state's dimension (the integrator's stages then allocate nothing), or a heap vector beyond 12.
struct Held<'a> {
    plant: &'a NonlinearPlant,
    u: &'a [f64],
}

impl<const N: usize> System<f64, SVector<f64, N>> for Held<'_> {
    fn system(&self, _t: f64, y: &SVector<f64, N>, dy: &mut SVector<f64, N>) {
        self.plant
            .field_into(y.as_slice(), self.u, dy.as_mut_slice());
    }
}

impl System<f64, DVector<f64>> for Held<'_> {
    fn system(&self, _t: f64, y: &DVector<f64>, dy: &mut DVector<f64>) {
        self.plant
            .field_into(y.as_slice(), self.u, dy.as_mut_slice());
    }
}

impl NonlinearPlant {
    /// The plant of a validated nonlinear spec.
    pub fn from_desc(desc: &NonlinearDesc) -> Self {
        let p = desc.names.param_values();
        let sys = &desc.system;
        let f: Vec<Expr> = sys.f.iter().map(|e| e.bind_params(&p)).collect();
        let g: Vec<Vec<Expr>> = sys
            .g
            .iter()
            .map(|row| row.iter().map(|e| e.bind_params(&p)).collect())
            .collect();
        let tape = Tape::new(f.iter().chain(g.iter().flatten()));
        Self {
            g,
            tape,
            n: sys.n(),
            m: sys.m(),
            period: desc.period,
        }
    }

    pub fn n(&self) -> usize {
        self.n
    }
    pub fn m(&self) -> usize {
        self.m
    }
    /// The controller's sample period, s.
    pub fn period(&self) -> f64 {
        self.period
    }

    /// f(x) + g(x)u.
    pub fn field(&self, x: &[f64], u: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n];
        self.field_into(x, u, &mut out);
        out
    }

    /// f(x) + g(x)u into `out` (length n): each entry's value as its tree gives it, summed in the order
    /// f_i + g_i1 u_1 + … (zero entries of g skipped).
    fn field_into(&self, x: &[f64], u: &[f64], out: &mut [f64]) {
        let at = Point { x, u: &[], p: &[] };
        self.tape.with_values(&at, |vals| {
            let (f, g) = vals.split_at(self.n);
            for (i, o) in out.iter_mut().enumerate() {
                let mut s = f[i];
                for (j, (gij, uj)) in self.g[i].iter().zip(u).enumerate() {
                    if !gij.is_zero() {
                        s += g[i * self.m + j] * uj;
                    }
                }
                *o = s;
            }
        })
    }

    /// The state `t` seconds after `x` with `u` held, and the states at `sub − 1` equally spaced instants
    /// strictly inside `(0, t)` passed to `visit` in time order (`sub ≤ 1`: none).
    pub fn flow(
        &self,
        x: &[f64],
        u: &[f64],
        t: f64,
        sub: usize,
        visit: &mut dyn FnMut(&[f64]),
    ) -> Result<Vec<f64>, ModelError> {
        super::check_len("nonlinear flow: state", x, self.n)?;
        super::check_len("nonlinear flow: input", u, self.m)?;
        if !(t.is_finite() && t > 0.0) {
            return Err(ModelError::Period(t));
        }
        let sub = sub.max(1);
        macro_rules! fixed {
            ($($k:literal)*) => {
                match self.n {
                    $($k => self.flow_in::<nalgebra::Const<$k>>(SVector::<f64, $k>::from_column_slice(x), u, t, sub, visit)?,)*
                    _ => self.flow_in::<nalgebra::Dyn>(DVector::from_column_slice(x), u, t, sub, visit)?,
                }
            };
        }
        let y = fixed!(1 2 3 4 5 6 7 8 9 10 11 12);
        if y.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::NonFinite {
                what: "the nonlinear flow",
            });
        }
        Ok(y)
    }

    /// [`NonlinearPlant::flow`] with the integrator's vectors of dimension `D` (on the stack for a fixed
    /// size). The instants inside come from a dense run, which only the verifier's membership checks
    /// read. The state at t is that run's end when it took one step; otherwise a sparse run's (the
    /// integrator's own solution: over several steps the dense output's value at t was seen up to 10⁻³
    /// off, relative, on Example 4.9 at a 3 s period).
    fn flow_in<D: Dim>(
        &self,
        x0: OVector<f64, D>,
        u: &[f64],
        t: f64,
        sub: usize,
        visit: &mut dyn FnMut(&[f64]),
    ) -> Result<Vec<f64>, ModelError>
    where
        DefaultAllocator: Allocator<D>,
        OVector<f64, D>: std::ops::Mul<f64, Output = OVector<f64, D>>,
        for<'a> Held<'a>: System<f64, OVector<f64, D>>,
    {
        let failed = ModelError::NonFinite {
            what: "the nonlinear flow (integration failed)",
        };
        let run = |out: OutputType| {
            let mut solver = Dop853::new(
                Held { plant: self, u },
                0.0,
                t,
                t / sub as f64,
                x0.clone(),
                RTOL,
                ATOL,
            );
            solver.set_output(out);
            solver.integrate().map(|stats| (solver, stats))
        };
        if sub > 1 {
            let (solver, stats) = run(OutputType::Dense).map_err(|_| failed.clone())?;
            for y in solver.y_out().iter().skip(1).take(sub - 1) {
                visit(y.as_slice());
            }
            // One accepted step spans the whole period (the integrator's last step is cut to end at t),
            // so the interpolant's value at t is taken at θ = 1 up to the rounding of the output
            // instants: the step's own solution, to the rounding of y₀ + (y₁ − y₀)θ. Over several steps
            // it is not (the module's test).
            if stats.accepted_steps == 1 {
                if let Some(y) = solver.y_out().last() {
                    return Ok(y.as_slice().to_vec());
                }
            }
        }
        let (solver, _) = run(OutputType::Sparse).map_err(|_| failed.clone())?;
        solver
            .y_out()
            .last()
            .map(|y| y.as_slice().to_vec())
            .ok_or(ModelError::NonFinite {
                what: "the nonlinear flow (no end state)",
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flow of Example 3.7's plant with θ̇ = 0 and F = 0 is the affine oscillator ẍ = 1 − x + 0.1ẋ in
    /// each position, whose exact solution from rest at x = 1 stays at 1; from x = 0 it is checked against
    /// the closed-form solution of the damped (here anti-damped) oscillator.
    #[test]
    fn flow_matches_a_closed_form_solution() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/fl-4-9.toml");
        let problem = crate::spec::load(path).expect("the shipped example");
        let plant = NonlinearPlant::from_desc(problem.nonlinear.as_ref().expect("nonlinear"));
        let x0 = [0.0, 0.0, 1.0, 0.0, 0.3, 0.0];
        let mut inside = Vec::new();
        let x1 = plant
            .flow(&x0, &[0.0, 0.0], 1.0, 4, &mut |s| inside.push(s.to_vec()))
            .expect("flows");
        assert_eq!(inside.len(), 3);
        // X'' = 1 − X + 0.1 X', X(0) = 0, X'(0) = 0: X = 1 − e^{0.05t}(cos ωt − (0.05/ω) sin ωt),
        // ω = sqrt(1 − 0.05²).
        let w = (1.0f64 - 0.0025).sqrt();
        let exact = |t: f64| 1.0 - (0.05 * t).exp() * ((w * t).cos() - 0.05 / w * (w * t).sin());
        assert!(
            (x1[0] - exact(1.0)).abs() < 1e-9,
            "{} vs {}",
            x1[0],
            exact(1.0)
        );
        assert!((inside[1][0] - exact(0.5)).abs() < 1e-9);
        assert!((x1[2] - 1.0).abs() < 1e-9, "Y at rest at its equilibrium");
        assert_eq!(x1[4], 0.3, "θ does not move without thrust");
        assert!(plant.flow(&x0, &[0.0], 1.0, 1, &mut |_| {}).is_err());
    }

    /// The state at the end of a period does not depend on whether the instants inside are asked for:
    /// with them (one dense run, its end taken when it is one step; else a sparse run too) and without
    /// (a sparse run alone) it agrees to a few units of rounding, on plants whose period is one step of
    /// the integrator (the flat quadrotor, the pendulum) and on Example 4.9 at periods of several steps,
    /// where the dense output's end is far off.
    #[test]
    fn the_end_state_is_the_integrator_s_own_with_or_without_instants_inside() {
        let cases = [
            ("flat-quadrotor.toml", None),
            ("fl-pendulum.toml", None),
            ("fl-4-9.toml", Some(0.1)),
            ("fl-4-9.toml", Some(3.0)),
        ];
        for (file, period) in cases {
            let path = format!("{}/../examples/{file}", env!("CARGO_MANIFEST_DIR"));
            let problem = crate::spec::load(&path).expect("the shipped example");
            let plant = NonlinearPlant::from_desc(problem.nonlinear.as_ref().expect("nonlinear"));
            let h = period.unwrap_or(plant.period());
            let (n, m) = (plant.n(), plant.m());
            let mut seed = 0x2545_f491_4f6c_dd1du64;
            let mut draw = || {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            };
            for _ in 0..200 {
                let x: Vec<f64> = (0..n).map(|_| draw()).collect();
                let u: Vec<f64> = (0..m).map(|_| draw()).collect();
                let mut inside = 0;
                let with = plant
                    .flow(&x, &u, h, 8, &mut |_| inside += 1)
                    .expect("flows");
                let without = plant.flow(&x, &u, h, 1, &mut |_| {}).expect("flows");
                assert_eq!(inside, 7);
                let scale = x.iter().chain(&without).fold(1.0f64, |a, v| a.max(v.abs()));
                for (a, b) in with.iter().zip(&without) {
                    assert!(
                        (a - b).abs() <= 8.0 * f64::EPSILON * scale,
                        "{file} at h = {h}: {with:?} against {without:?}"
                    );
                }
            }
        }
    }
}
