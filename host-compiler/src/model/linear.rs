//! Linear affine plants (3.1)/(3.60) and their exact zero-order-hold discretisation.

use super::{check_finite, check_len, expm, Location, ModelError, Plant};
use faer::{Mat, MatRef};

/// ẋ = A x + B u + c (3.1).
#[derive(Clone, Debug, PartialEq)]
pub struct ContinuousPlant {
    /// n×n.
    pub A: Mat<f64>,
    /// n×m.
    pub B: Mat<f64>,
    /// Affine term, length n.
    pub c: Vec<f64>,
}

/// x⁺ = A x + B u + g (3.60), one step every `period` seconds.
#[derive(Clone, Debug, PartialEq)]
pub struct DiscretePlant {
    /// n×n.
    pub A: Mat<f64>,
    /// n×m.
    pub B: Mat<f64>,
    /// Affine term, length n.
    pub g: Vec<f64>,
    /// Seconds per step, > 0.
    pub period: f64,
}

/// A linear affine plant as the firmware controls it (the first [`Plant`] class): the sampled model the
/// loop runs on (DESIGN §6), with the continuous plant it was sampled from when the spec is in continuous
/// time (for the inter-sample bound) and the exact sub-period model the verifier checks between samples
/// with.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearAffine {
    pub discrete: DiscretePlant,
    pub continuous: Option<ContinuousPlant>,
    /// Exact ZOH over h / [`LinearAffine::SUBSTEPS`] (continuous plants only).
    sub: Option<DiscretePlant>,
    /// γ(h) of [`InterSampleBound`] (continuous plants only): the excursion within a period is at most
    /// γ(h)‖f‖₂ at the sample.
    excursion_gain: Option<f64>,
}

fn check_AB(A: MatRef<'_, f64>, B: MatRef<'_, f64>) -> Result<(), ModelError> {
    let n = A.nrows();
    if A.ncols() != n {
        return Err(ModelError::Dimension {
            what: "A",
            expected: "a square matrix".into(),
            got: format!("{}×{}", n, A.ncols()),
        });
    }
    if B.nrows() != n {
        return Err(ModelError::Dimension {
            what: "B",
            expected: format!("{n} rows"),
            got: format!("{} rows", B.nrows()),
        });
    }
    check_finite("A", A)?;
    check_finite("B", B)
}

/// A x + B u + c in one pass (one allocation), summing each row of A x and of B u in column order and
/// then adding them and c, the order every other evaluation of the plant uses.
fn affine(A: MatRef<'_, f64>, B: MatRef<'_, f64>, c: &[f64], x: &[f64], u: &[f64]) -> Vec<f64> {
    (0..A.nrows())
        .map(|i| affine_row(A, B, c, x, u, i))
        .collect()
}

/// Row `i` of `A x + B u + c` (the one summation order [`affine`] and the in-place forms share).
#[inline]
fn affine_row(
    A: MatRef<'_, f64>,
    B: MatRef<'_, f64>,
    c: &[f64],
    x: &[f64],
    u: &[f64],
    i: usize,
) -> f64 {
    // Row i of M times v by the row's iterator (no per-entry index checks), the products summed in
    // column order as before.
    let row_dot = |M: MatRef<'_, f64>, v: &[f64]| -> f64 {
        M.row(i)
            .iter()
            .zip(&v[..M.ncols()])
            .map(|(m, v)| m * v)
            .sum()
    };
    row_dot(A, x) + row_dot(B, u) + c[i]
}

impl ContinuousPlant {
    /// Checked constructor: A square, B with n rows, c of length n, all finite.
    pub fn new(A: Mat<f64>, B: Mat<f64>, c: Vec<f64>) -> Result<Self, ModelError> {
        check_AB(A.as_ref(), B.as_ref())?;
        check_len("c", &c, A.nrows())?;
        Ok(Self { A, B, c })
    }

    /// State dimension n.
    pub fn n(&self) -> usize {
        self.A.nrows()
    }

    /// Input dimension m.
    pub fn m(&self) -> usize {
        self.B.ncols()
    }

    /// The vector field A x + B u + c.
    pub fn f(&self, x: &[f64], u: &[f64]) -> Vec<f64> {
        affine(self.A.as_ref(), self.B.as_ref(), &self.c, x, u)
    }

    /// ‖f(x, u)‖₂, the squares summed in index order, without forming f.
    pub fn f_norm(&self, x: &[f64], u: &[f64]) -> f64 {
        (0..self.A.nrows())
            .map(|i| {
                let v = affine_row(self.A.as_ref(), self.B.as_ref(), &self.c, x, u, i);
                v * v
            })
            .sum::<f64>()
            .sqrt()
    }

    /// One classical Runge–Kutta step of length `dt` with u held constant (a reference integrator for tests and
    /// fine simulation; the exact sampled map is [`ContinuousPlant::zoh`]).
    pub fn rk4_step(&self, x: &[f64], u: &[f64], dt: f64) -> Vec<f64> {
        let add = |x: &[f64], k: &[f64], s: f64| -> Vec<f64> {
            x.iter().zip(k).map(|(a, b)| a + s * b).collect()
        };
        let k1 = self.f(x, u);
        let k2 = self.f(&add(x, &k1, dt / 2.0), u);
        let k3 = self.f(&add(x, &k2, dt / 2.0), u);
        let k4 = self.f(&add(x, &k3, dt), u);
        (0..x.len())
            .map(|i| x[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
            .collect()
    }

    /// Exact zero-order-hold discretisation with period `h`; see [`zoh`].
    pub fn zoh(&self, h: f64) -> Result<DiscretePlant, ModelError> {
        zoh(self, h)
    }
}

/// Exact zero-order-hold discretisation of ẋ = A x + B u + c with u held over each period h:
/// `A_d = e^{Ah}`, `B_d = (∫₀ʰ e^{As} ds) B`, `g_d = (∫₀ʰ e^{As} ds) c`.
///
/// All three come from one exponential of the augmented matrix (Van Loan's construction):
/// `exp([[A, B, c], [0, 0, 0], [0, 0, 0]]·h) = [[A_d, B_d, g_d], [0, I, 0], [0, 0, 1]]`, because the
/// augmented state (x, u, 1) has u and 1 constant, so its flow over h is exactly the held-input solution.
pub fn zoh(plant: &ContinuousPlant, h: f64) -> Result<DiscretePlant, ModelError> {
    if !(h.is_finite() && h > 0.0) {
        return Err(ModelError::Period(h));
    }
    check_AB(plant.A.as_ref(), plant.B.as_ref())?;
    let (n, m) = (plant.n(), plant.m());
    check_len("c", &plant.c, n)?;
    let size = n + m + 1;
    let aug = Mat::from_fn(size, size, |i, j| {
        if i >= n {
            0.0
        } else if j < n {
            plant.A[(i, j)] * h
        } else if j < n + m {
            plant.B[(i, j - n)] * h
        } else {
            plant.c[i] * h
        }
    });
    let e = expm(aug.as_ref()).map_err(|e| match e {
        ModelError::ExpOverflow { norm } => ModelError::SampledOverflow { period: h, norm },
        other => other,
    })?;
    Ok(DiscretePlant {
        A: Mat::from_fn(n, n, |i, j| e[(i, j)]),
        B: Mat::from_fn(n, m, |i, j| e[(i, n + j)]),
        g: (0..n).map(|i| e[(i, n + m)]).collect(),
        period: h,
    })
}

impl DiscretePlant {
    /// Checked constructor: A square, B with n rows, g of length n, all finite, period > 0.
    pub fn new(A: Mat<f64>, B: Mat<f64>, g: Vec<f64>, period: f64) -> Result<Self, ModelError> {
        check_AB(A.as_ref(), B.as_ref())?;
        check_len("g", &g, A.nrows())?;
        if !(period.is_finite() && period > 0.0) {
            return Err(ModelError::Period(period));
        }
        Ok(Self { A, B, g, period })
    }

    /// State dimension n.
    pub fn n(&self) -> usize {
        self.A.nrows()
    }

    /// Input dimension m.
    pub fn m(&self) -> usize {
        self.B.ncols()
    }

    /// x⁺ = A x + B u + g.
    pub fn step(&self, x: &[f64], u: &[f64]) -> Vec<f64> {
        affine(self.A.as_ref(), self.B.as_ref(), &self.g, x, u)
    }

    /// [`DiscretePlant::step`] into `out` (n values), the same values.
    pub fn step_into(&self, x: &[f64], u: &[f64], out: &mut [f64]) {
        for (i, o) in out.iter_mut().enumerate().take(self.A.nrows()) {
            *o = affine_row(self.A.as_ref(), self.B.as_ref(), &self.g, x, u, i);
        }
    }
}

impl LinearAffine {
    /// Sub-periods per period at which the verifier checks a continuous plant between samples.
    pub const SUBSTEPS: usize = 8;

    /// A plant given in discrete time.
    pub fn discrete(d: DiscretePlant) -> Self {
        Self {
            discrete: d,
            continuous: None,
            sub: None,
            excursion_gain: None,
        }
    }

    /// A plant given in continuous time, sampled with period `h` by an exact zero-order hold.
    pub fn sampled(c: ContinuousPlant, h: f64) -> Result<Self, ModelError> {
        let discrete = c.zoh(h)?;
        let sub = Some(c.zoh(h / Self::SUBSTEPS as f64)?);
        let excursion_gain = Some(c.inter_sample_bound(h)?.gain);
        Ok(Self {
            discrete,
            continuous: Some(c),
            sub,
            excursion_gain,
        })
    }

    /// The model of a validated spec plant: a continuous plant is discretised with its period (ZOH), a
    /// discrete plant is taken as is.
    pub fn from_spec(p: &crate::spec::Plant) -> Result<Self, ModelError> {
        let A = p.A.to_faer();
        let B = p.B.to_faer();
        match p.time {
            crate::spec::TimeDomain::Continuous => {
                Self::sampled(ContinuousPlant::new(A, B, p.offset.clone())?, p.period)
            }
            crate::spec::TimeDomain::Discrete => Ok(Self::discrete(DiscretePlant::new(
                A,
                B,
                p.offset.clone(),
                p.period,
            )?)),
        }
    }
}

impl Plant for LinearAffine {
    fn n(&self) -> usize {
        self.discrete.n()
    }
    fn m(&self) -> usize {
        self.discrete.m()
    }
    fn period(&self) -> f64 {
        self.discrete.period
    }
    fn error_dynamics(&self, _loc: Location) -> &DiscretePlant {
        &self.discrete
    }
    fn continuous(&self, _loc: Location) -> Option<&ContinuousPlant> {
        self.continuous.as_ref()
    }
    fn step(&self, _loc: Location, x: &[f64], u: &[f64]) -> Vec<f64> {
        self.discrete.step(x, u)
    }
    fn step_into(&self, _loc: Location, x: &[f64], u: &[f64], out: &mut [f64]) {
        self.discrete.step_into(x, u, out)
    }
    fn between_samples(&self, _loc: Location, x: &[f64], u: &[f64], visit: &mut dyn FnMut(&[f64])) {
        let Some(sub) = &self.sub else {
            return;
        };
        // Two buffers for the SUBSTEPS − 1 states between the samples, stepped in place (the verifier asks
        // this at every step of its 10⁴ runs, where a vector per sub-step cost more than the step).
        let mut a = x.to_vec();
        let mut b = vec![0.0; x.len()];
        for _ in 1..Self::SUBSTEPS {
            sub.step_into(&a, u, &mut b);
            visit(&b);
            std::mem::swap(&mut a, &mut b);
        }
    }
    fn excursion(&self, _loc: Location, x: &[f64], u: &[f64]) -> Option<f64> {
        let (c, gain) = (self.continuous.as_ref()?, self.excursion_gain?);
        if x.len() != c.n() || u.len() != c.m() {
            return None;
        }
        Some(gain * c.f_norm(x, u))
    }
}
