//! Interval enclosures over a box, and a sound bound on what the target's f32 model program computes.
//!
//! * [`enclose`]: an interval containing the exact real value of an expression over every point of a
//!   box (interval arithmetic in f64, every bound rounded outward). With [`super::diff`] this encloses a
//!   Jacobian or the decoupling matrix Γ over a region, and [`certainly_regular`] proves an interval
//!   matrix nonsingular (what Def 3.5 needs over the region the task uses).
//! * [`rounding_bound`]: for a [`Compiled`] program and a box of states and inputs, for every output an
//!   enclosure X of the exact value and a number e with |f32 program result − exact value| ≤ e at every
//!   point of the box (DESIGN §6: the rounding of a model program enters the certificate as a bounded
//!   input disturbance, as Thm 3.21 and (3.83)–(3.87) do for the evaluator's). "Exact" is the expression
//!   in real arithmetic with the spec's numbers as their f64 values; the program is given the f32
//!   roundings of the states and inputs.
//!
//! # The rounding model
//! The analysis follows the program instruction by instruction (the same `Program::ops` the evaluator
//! runs), carrying for every stack value an enclosure X of its exact value and a bound e on its error, so
//! the computed value lies in Y = X ± e:
//! * inputs: round to nearest f32, |fl(x) − x| ≤ 2⁻²⁴|x| + 2⁻¹⁵⁰; pool constants: the error is the exact
//!   distance |c − fl32(c)|;
//! * `+ − · /` are IEEE 754 binary32 operations rounded to nearest: fl(a∘b) = (a∘b)(1 + δ) + η with
//!   |δ| ≤ ε = 2⁻²⁴ and |η| ≤ 2⁻¹⁴⁹ (underflow), and the propagated error of the operands
//!   (e.g. |ŷ₁ŷ₂ − x₁x₂| ≤ |Y₁|e₂ + |X₂|e₁);
//! * `x^k` is followed as the `|k| − 1` multiplications (and one division) the target performs;
//! * a `libm` function φ: |φ₃₂(ŷ) − φ(x)| ≤ L·e + U·2⁻²³·|φ(Y)| + U·2⁻¹⁴⁹, with L a Lipschitz
//!   constant of φ on Y and U the accuracy in ulps. `sqrtf` is correctly rounded (U = ½, IEEE 754) and
//!   `fabsf` exact (U = 0). For `tanf expf logf atanf tanhf atan2f` we take U = [`LIBM_ULPS`] = 4:
//!   the `libm` crate ports musl, whose single-precision functions (from FreeBSD's msun) state errors
//!   below 1 ulp; we use four times that so that the bound holds with a wide margin and does not rest
//!   on a figure the crate itself does not promise. Sine and cosine are `shared_types::trig::sincos`
//!   (f32 only), within 2 ulps in this model plus an absolute term of its reduction by π/2
//!   (`shared_types::trig::REDUCTION_ABS`·(|x| + 2)) by its own tests; they are charged 4 ulps and
//!   that term. The proptests of this module check it at random points.
//!
//! Each error term is taken at its worst over the whole box (an absolute bound), so the bound is tight
//! on small boxes and loose where a wide box mixes large and small magnitudes (a quotient by a divisor
//! that ranges over orders of magnitude): subdividing the box tightens it.
//!
//! A value whose magnitude may exceed `f32::MAX`, a division whose divisor may be 0, and a function
//! outside its domain (log, sqrt, tan near a pole, atan2 across its branch cut) are reported as
//! [`IntervalError`]s rather than bounded.

use super::compile::Compiled;
use super::{Expr, Func, Var};
use shared_types::program::Op;
use std::f64::consts::{FRAC_PI_2, PI};

/// Accuracy assumed for `libm`'s `f32` transcendental functions, in ulps (see the module docs).
pub const LIBM_ULPS: f64 = 4.0;

/// ε = 2⁻²⁴: the unit roundoff of binary32.
const EPS32: f64 = 1.0 / 16_777_216.0;
/// 2⁻¹⁴⁹: the smallest positive binary32 (a bound on the absolute error of an underflowing operation).
const ETA32: f64 = 1.401298464324817e-45;

/// A closed interval [lo, hi] of reals (lo ≤ hi, both finite unless the interval is unbounded).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    pub lo: f64,
    pub hi: f64,
}

/// Why an enclosure or a rounding bound could not be given.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IntervalError {
    /// A divisor's enclosure contains 0.
    #[error("a divisor may be zero over the box (its enclosure is [{lo:.6e}, {hi:.6e}])")]
    DivisionByZero { lo: f64, hi: f64 },
    /// A function's argument leaves its domain (or crosses a pole or branch cut) over the box.
    #[error("{func} may be evaluated outside its domain over the box (argument in [{lo:.6e}, {hi:.6e}])")]
    Domain {
        func: &'static str,
        lo: f64,
        hi: f64,
    },
    /// A value may exceed the range of f32 (or of the enclosure arithmetic).
    #[error("a value may overflow f32 over the box (magnitude up to {mag:.6e})")]
    Overflow { mag: f64 },
    /// A variable without an interval (a box of the wrong length).
    #[error("the box gives no interval for {0}")]
    Unbound(Var),
}

fn dn(x: f64) -> f64 {
    x.next_down()
}

fn up(x: f64) -> f64 {
    x.next_up()
}

// Named like the operators on purpose: each rounds outward, which `std::ops` would hide.
#[allow(clippy::should_implement_trait)]
impl Interval {
    /// [lo, hi].
    pub fn new(lo: f64, hi: f64) -> Self {
        Self { lo, hi }
    }

    /// [v, v].
    pub fn point(v: f64) -> Self {
        Self { lo: v, hi: v }
    }

    /// max |x| over the interval.
    pub fn mag(self) -> f64 {
        self.lo.abs().max(self.hi.abs())
    }

    /// min |x| over the interval.
    pub fn mig(self) -> f64 {
        if self.lo <= 0.0 && self.hi >= 0.0 {
            0.0
        } else {
            self.lo.abs().min(self.hi.abs())
        }
    }

    /// Whether v lies in the interval.
    pub fn contains(self, v: f64) -> bool {
        self.lo <= v && v <= self.hi
    }

    /// The interval widened by r ≥ 0 on both sides (outward).
    pub fn widen(self, r: f64) -> Self {
        Self::new(dn(self.lo - r), up(self.hi + r))
    }

    /// The midpoint.
    pub fn mid(self) -> f64 {
        0.5 * self.lo + 0.5 * self.hi
    }

    fn finite(self) -> Result<Self, IntervalError> {
        if self.lo.is_finite() && self.hi.is_finite() {
            Ok(self)
        } else {
            Err(IntervalError::Overflow { mag: f64::INFINITY })
        }
    }

    /// a + b.
    pub fn add(self, b: Self) -> Self {
        Self::new(dn(self.lo + b.lo), up(self.hi + b.hi))
    }

    /// a − b.
    pub fn sub(self, b: Self) -> Self {
        Self::new(dn(self.lo - b.hi), up(self.hi - b.lo))
    }

    /// −a.
    pub fn neg(self) -> Self {
        Self::new(-self.hi, -self.lo)
    }

    /// a · b.
    pub fn mul(self, b: Self) -> Self {
        let c = [
            self.lo * b.lo,
            self.lo * b.hi,
            self.hi * b.lo,
            self.hi * b.hi,
        ];
        if c.iter().any(|v| v.is_nan()) {
            return Self::new(f64::NEG_INFINITY, f64::INFINITY);
        }
        let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Self::new(dn(lo), up(hi))
    }

    /// a / b; an error if b contains 0.
    pub fn div(self, b: Self) -> Result<Self, IntervalError> {
        if b.contains(0.0) {
            return Err(IntervalError::DivisionByZero { lo: b.lo, hi: b.hi });
        }
        let c = [
            self.lo / b.lo,
            self.lo / b.hi,
            self.hi / b.lo,
            self.hi / b.hi,
        ];
        let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Ok(Self::new(dn(lo), up(hi)))
    }

    /// aᵏ for an integer k (k < 0 needs 0 ∉ a).
    pub fn powi(self, k: i8) -> Result<Self, IntervalError> {
        if k == 0 {
            return Ok(Self::point(1.0));
        }
        let n = k.unsigned_abs() as u32;
        // |x|ⁿ rounded down / up by repeated multiplication.
        let pow = |x: f64, round: fn(f64) -> f64| (1..n).fold(x, |acc, _| round(acc * x));
        let p = if n % 2 == 1 {
            let lo = if self.lo >= 0.0 {
                pow(self.lo, dn)
            } else {
                -pow(-self.lo, up)
            };
            let hi = if self.hi >= 0.0 {
                pow(self.hi, up)
            } else {
                -pow(-self.hi, dn)
            };
            Self::new(lo, hi)
        } else {
            Self::new(pow(self.mig(), dn), pow(self.mag(), up))
        };
        if k < 0 {
            Self::point(1.0).div(p)
        } else {
            Ok(p)
        }
    }

    /// The smallest interval containing both.
    pub fn hull(self, b: Self) -> Self {
        Self::new(self.lo.min(b.lo), self.hi.max(b.hi))
    }
}

/// A value of a monotone f64 function widened by 2 ulps on each side (std's functions are within 1 ulp).
fn wide(v: f64) -> Interval {
    Interval::new(dn(dn(v)), up(up(v)))
}

/// Whether `lo ≤ c + 2πj ≤ hi` for some integer j (with a margin, so a near miss counts as a hit: that
/// only loosens the enclosure).
fn hits(a: Interval, c: f64) -> bool {
    let j = ((a.lo - c) / (2.0 * PI)).ceil() - 1.0;
    (0..3).any(|s| {
        let t = c + 2.0 * PI * (j + s as f64);
        t >= a.lo - 1e-9 && t <= a.hi + 1e-9
    })
}

/// φ over an interval.
pub fn func(f: Func, a: Interval) -> Result<Interval, IntervalError> {
    let dom = |lo, hi| IntervalError::Domain {
        func: f.name(),
        lo,
        hi,
    };
    a.finite()?;
    let mono = |g: fn(f64) -> f64| wide(g(a.lo)).hull(wide(g(a.hi)));
    match f {
        Func::Sin | Func::Cos => {
            if a.hi - a.lo >= 2.0 * PI {
                Interval::new(-1.0, 1.0)
            } else {
                let g = if f == Func::Sin { f64::sin } else { f64::cos };
                let (top, bottom) = if f == Func::Sin {
                    (FRAC_PI_2, -FRAC_PI_2)
                } else {
                    (0.0, PI)
                };
                let mut r = wide(g(a.lo)).hull(wide(g(a.hi)));
                if hits(a, top) {
                    r.hi = 1.0;
                }
                if hits(a, bottom) {
                    r.lo = -1.0;
                }
                Interval::new(r.lo.max(-1.0), r.hi.min(1.0))
            }
        }
        Func::Tan => {
            // The same branch (−π/2 + kπ, π/2 + kπ) at both ends, with a margin from the pole.
            let branch = |x: f64| ((x + FRAC_PI_2) / PI).floor();
            let margin = |x: f64| {
                let r = (x + FRAC_PI_2).rem_euclid(PI);
                r.min(PI - r)
            };
            if branch(a.lo) != branch(a.hi) || margin(a.lo) < 1e-9 || margin(a.hi) < 1e-9 {
                return Err(dom(a.lo, a.hi));
            }
            mono(f64::tan)
        }
        Func::Exp => {
            let r = mono(f64::exp);
            Interval::new(r.lo.max(0.0), r.hi)
        }
        Func::Log => {
            if a.lo <= 0.0 {
                return Err(dom(a.lo, a.hi));
            }
            mono(f64::ln)
        }
        Func::Sqrt => {
            if a.lo < 0.0 {
                return Err(dom(a.lo, a.hi));
            }
            let r = mono(f64::sqrt);
            Interval::new(r.lo.max(0.0), r.hi)
        }
        Func::Abs => Interval::new(a.mig(), a.mag()),
        Func::Atan => mono(f64::atan),
        Func::Tanh => {
            let r = mono(f64::tanh);
            Interval::new(r.lo.max(-1.0), r.hi.min(1.0))
        }
    }
    .finite()
}

/// atan2(y, x) over a box that neither contains the origin nor crosses the branch cut (y = 0, x < 0):
/// then the angle is continuous on the box and its extremes are at corners.
pub fn atan2(y: Interval, x: Interval) -> Result<Interval, IntervalError> {
    if x.lo <= 0.0 && y.contains(0.0) {
        return Err(IntervalError::Domain {
            func: "atan2",
            lo: x.lo.min(y.lo),
            hi: x.hi.max(y.hi),
        });
    }
    let corners = [
        y.lo.atan2(x.lo),
        y.lo.atan2(x.hi),
        y.hi.atan2(x.lo),
        y.hi.atan2(x.hi),
    ];
    let lo = corners.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = corners.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Ok(wide(lo).hull(wide(hi)))
}

/// Intervals of the states, inputs and parameters.
#[derive(Clone, Copy, Debug)]
pub struct VarBox<'a> {
    pub x: &'a [Interval],
    pub u: &'a [Interval],
    pub p: &'a [Interval],
}

impl VarBox<'_> {
    fn get(&self, v: Var) -> Result<Interval, IntervalError> {
        let (s, i) = match v {
            Var::State(i) => (self.x, i),
            Var::Input(i) => (self.u, i),
            Var::Param(i) => (self.p, i),
        };
        s.get(i as usize).copied().ok_or(IntervalError::Unbound(v))
    }
}

/// An interval containing the exact value of `e` at every point of the box.
pub fn enclose(e: &Expr, b: &VarBox<'_>) -> Result<Interval, IntervalError> {
    let r = match e {
        Expr::Const(v) => Interval::point(*v),
        Expr::Var(v) => b.get(*v)?,
        Expr::Neg(a) => enclose(a, b)?.neg(),
        Expr::Add(p, q) => enclose(p, b)?.add(enclose(q, b)?),
        Expr::Sub(p, q) => enclose(p, b)?.sub(enclose(q, b)?),
        Expr::Mul(p, q) => enclose(p, b)?.mul(enclose(q, b)?),
        Expr::Div(p, q) => enclose(p, b)?.div(enclose(q, b)?)?,
        Expr::Pow(p, k) => enclose(p, b)?.powi(*k)?,
        Expr::Func(f, p) => func(*f, enclose(p, b)?)?,
        Expr::Atan2(y, x) => atan2(enclose(y, b)?, enclose(x, b)?)?,
    };
    r.finite()
}

/// Enclosures of a matrix of expressions (e.g. a Jacobian from [`super::diff::jacobian`], or Γ).
pub fn enclose_matrix(
    m: &[Vec<Expr>],
    b: &VarBox<'_>,
) -> Result<Vec<Vec<Interval>>, IntervalError> {
    m.iter()
        .map(|row| row.iter().map(|e| enclose(e, b)).collect())
        .collect()
}

/// Whether every matrix in the square interval matrix `a` is nonsingular, proved by: R ≈ inverse of the
/// midpoint matrix (any R will do), M = R·[a] in interval arithmetic, and ‖I − M‖∞ < 1 with magnitudes
/// rounded up; then R·A is nonsingular for every A in [a], hence A is. `false` means "not proved".
#[allow(clippy::needless_range_loop)]
pub fn certainly_regular(a: &[Vec<Interval>]) -> bool {
    let m = a.len();
    if a.iter().any(|row| row.len() != m) || m == 0 {
        return false;
    }
    let mid: Vec<Vec<f64>> = a
        .iter()
        .map(|row| row.iter().map(|v| v.mid()).collect())
        .collect();
    let Some(r) = invert(&mid) else { return false };
    let mut norm = 0.0f64;
    for i in 0..m {
        let mut row_sum = 0.0f64;
        for j in 0..m {
            let mut acc = Interval::point(if i == j { 1.0 } else { 0.0 });
            for (k, ak) in a.iter().enumerate() {
                acc = acc.sub(Interval::point(r[i][k]).mul(ak[j]));
            }
            if !acc.lo.is_finite() || !acc.hi.is_finite() {
                return false;
            }
            row_sum = up(row_sum + acc.mag());
        }
        norm = norm.max(row_sum);
    }
    norm < 1.0
}

/// Gauss–Jordan inverse with partial pivoting (small m); `None` if a pivot vanishes.
fn invert(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let m = a.len();
    let mut w: Vec<Vec<f64>> = a
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let mut r = row.clone();
            r.extend((0..m).map(|j| if i == j { 1.0 } else { 0.0 }));
            r
        })
        .collect();
    for c in 0..m {
        let p = (c..m).max_by(|&i, &j| w[i][c].abs().total_cmp(&w[j][c].abs()))?;
        if w[p][c] == 0.0 || !w[p][c].is_finite() {
            return None;
        }
        w.swap(c, p);
        let pivot = w[c][c];
        for v in w[c].iter_mut() {
            *v /= pivot;
        }
        for i in 0..m {
            if i != c {
                let f = w[i][c];
                if f != 0.0 {
                    let (src, dst) = if i < c {
                        let (lo, hi) = w.split_at_mut(c);
                        (&hi[0], &mut lo[i])
                    } else {
                        let (lo, hi) = w.split_at_mut(i);
                        (&lo[c], &mut hi[0])
                    };
                    for (d, s) in dst.iter_mut().zip(src.iter()) {
                        *d -= f * s;
                    }
                }
            }
        }
    }
    Some(w.into_iter().map(|r| r[m..].to_vec()).collect())
}

/// One output of [`rounding_bound`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutputBound {
    /// Encloses the exact value over the box.
    pub exact: Interval,
    /// |f32 result − exact value| ≤ `error` over the box.
    pub error: f64,
}

impl OutputBound {
    /// Encloses the f32 result over the box.
    pub fn computed(&self) -> Interval {
        self.exact.widen(self.error)
    }
}

/// A stack value of the analysis: the exact value's enclosure and the error bound.
#[derive(Clone, Copy, Debug)]
struct Val {
    x: Interval,
    e: f64,
}

impl Val {
    /// The computed value's enclosure.
    fn y(self) -> Interval {
        self.x.widen(self.e)
    }
}

/// `a + b` rounded up, for error bounds (non-negative terms).
fn sum_up(terms: &[f64]) -> f64 {
    terms.iter().fold(0.0, |acc, &t| up(acc + t))
}

fn prod_up(a: f64, b: f64) -> f64 {
    if a == 0.0 || b == 0.0 {
        0.0
    } else {
        up(a * b)
    }
}

/// Refuses a value that may leave the f32 range.
fn in_f32(v: Val) -> Result<Val, IntervalError> {
    let mag = v.y().mag();
    // Negated so that a NaN magnitude is refused too.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let beyond = !(mag <= f32::MAX as f64);
    if beyond || !v.e.is_finite() {
        return Err(IntervalError::Overflow { mag });
    }
    Ok(v)
}

/// The rounding error of one basic binary32 operation whose exact result lies in `r`.
fn op_rounding(r: Interval) -> f64 {
    sum_up(&[prod_up(EPS32, r.mag()), ETA32])
}

fn mul_val(a: Val, b: Val) -> Result<Val, IntervalError> {
    let x = a.x.mul(b.x);
    let yr = a.y().mul(b.y());
    let e = sum_up(&[
        prod_up(a.y().mag(), b.e),
        prod_up(b.x.mag(), a.e),
        op_rounding(yr),
    ]);
    in_f32(Val { x, e })
}

fn div_val(a: Val, b: Val) -> Result<Val, IntervalError> {
    let (ya, yb) = (a.y(), b.y());
    if yb.contains(0.0) {
        return Err(IntervalError::DivisionByZero {
            lo: yb.lo,
            hi: yb.hi,
        });
    }
    let x = a.x.div(b.x)?;
    let yr = ya.div(yb)?;
    let den = dn(yb.mig() * b.x.mig());
    let num = sum_up(&[prod_up(a.e, b.x.mag()), prod_up(a.x.mag(), b.e)]);
    let e = sum_up(&[up(num / den), op_rounding(yr)]);
    in_f32(Val { x, e })
}

/// The f32 accuracy of a function in ulps and a Lipschitz constant of it on `y`.
fn func_constants(f: Func, y: Interval, e: f64) -> Result<(f64, f64), IntervalError> {
    Ok(match f {
        Func::Sin | Func::Cos => (LIBM_ULPS, 1.0),
        Func::Tan => {
            let t = func(Func::Tan, y)?;
            (LIBM_ULPS, up(1.0 + up(t.mag() * t.mag())))
        }
        Func::Exp => (LIBM_ULPS, func(Func::Exp, y)?.hi),
        Func::Log => {
            if y.lo <= 0.0 {
                return Err(IntervalError::Domain {
                    func: "log",
                    lo: y.lo,
                    hi: y.hi,
                });
            }
            (LIBM_ULPS, up(1.0 / y.lo))
        }
        Func::Sqrt => {
            // |√a − √b| ≤ min(|a − b| / (2√min), √|a − b|): returned as an equivalent constant.
            let l = if y.lo > 0.0 {
                up(0.5 / dn(y.lo.sqrt()))
            } else {
                f64::INFINITY
            };
            let l = if e > 0.0 {
                l.min(up(up(e.sqrt()) / e))
            } else {
                l
            };
            (0.5, l)
        }
        Func::Abs => (0.0, 1.0),
        Func::Atan | Func::Tanh => (LIBM_ULPS, 1.0),
    })
}

fn func_val(f: Func, a: Val) -> Result<Val, IntervalError> {
    let y = a.y();
    let x = func(f, a.x)?;
    let fy = func(f, y)?;
    let (ulps, lip) = func_constants(f, y, a.e)?;
    // Sine and cosine also carry their reduction's absolute error (`shared_types::trig`).
    let reduction = match f {
        Func::Sin | Func::Cos => prod_up(shared_types::trig::REDUCTION_ABS, up(y.mag() + 2.0)),
        _ => 0.0,
    };
    let e = sum_up(&[
        prod_up(lip, a.e),
        prod_up(ulps * 2.0 * EPS32, fy.mag()),
        prod_up(ulps, ETA32),
        reduction,
    ]);
    in_f32(Val { x, e })
}

fn atan2_val(yv: Val, xv: Val) -> Result<Val, IntervalError> {
    let (yy, yx) = (yv.y(), xv.y());
    let x = atan2(yv.x, xv.x)?;
    let r = atan2(yy, yx)?;
    // |∇ atan2| = 1/ρ, and ρ ≥ the distance from the origin to the box of computed and exact values.
    let rho = dn(dn(yy.mig() * yy.mig() + yx.mig() * yx.mig()).sqrt());
    if rho <= 0.0 {
        return Err(IntervalError::Domain {
            func: "atan2",
            lo: 0.0,
            hi: 0.0,
        });
    }
    let e = sum_up(&[
        up(sum_up(&[yv.e, xv.e]) / rho),
        prod_up(LIBM_ULPS * 2.0 * EPS32, r.mag()),
        prod_up(LIBM_ULPS, ETA32),
    ]);
    in_f32(Val { x, e })
}

fn pop(stack: &mut Vec<Val>) -> Val {
    stack.pop().expect("decode proved the stack depth")
}

/// For every output of `program`, an enclosure of its exact value and a bound on |f32 result − exact|
/// over the box `x` × `u` of states and inputs (the module docs give the model).
pub fn rounding_bound(
    program: &Compiled,
    x: &[Interval],
    u: &[Interval],
) -> Result<Vec<OutputBound>, IntervalError> {
    let p = program.program();
    let slots: Vec<Interval> = x.iter().chain(u).copied().collect();
    let mut stack: Vec<Val> = Vec::with_capacity(p.max_stack());
    let mut out: Vec<Option<OutputBound>> = vec![None; p.n_outputs()];
    // A register holds the value of the subexpression teed into it: the same enclosure and error bound
    // wherever it is recalled (the target recalls the very bits it computed).
    let mut regs: Vec<Option<Val>> = vec![None; shared_types::capacity::MAX_PROGRAM_REGS];
    for (_, op) in p.ops() {
        let v = match op {
            Op::Tee(r) => {
                regs[r as usize] = stack.last().copied();
                continue;
            }
            Op::Recall(r) => {
                regs[r as usize].expect("decode proved a register is written before read")
            }
            Op::Load(i) => {
                let i = i as usize;
                let xi = slots.get(i).copied().ok_or(IntervalError::Unbound(
                    if i < program.n_states {
                        Var::State(i as u16)
                    } else {
                        Var::Input((i - program.n_states) as u16)
                    },
                ))?;
                let e = sum_up(&[prod_up(EPS32, xi.mag()), ETA32]);
                in_f32(Val { x: xi, e })?
            }
            Op::Const(i) => {
                let c = program.consts[i as usize];
                let c32 = f64::from(c as f32);
                Val {
                    x: Interval::point(c),
                    e: up((c - c32).abs()),
                }
            }
            Op::Store(i) => {
                let v = pop(&mut stack);
                out[i as usize] = Some(OutputBound {
                    exact: v.x,
                    error: v.e,
                });
                continue;
            }
            Op::Add | Op::Sub => {
                let b = pop(&mut stack);
                let a = pop(&mut stack);
                let (x, yr) = if op == Op::Add {
                    (a.x.add(b.x), a.y().add(b.y()))
                } else {
                    (a.x.sub(b.x), a.y().sub(b.y()))
                };
                in_f32(Val {
                    x,
                    e: sum_up(&[a.e, b.e, op_rounding(yr)]),
                })?
            }
            Op::Mul => {
                let b = pop(&mut stack);
                let a = pop(&mut stack);
                mul_val(a, b)?
            }
            Op::Div => {
                let b = pop(&mut stack);
                let a = pop(&mut stack);
                div_val(a, b)?
            }
            Op::Neg => {
                let a = pop(&mut stack);
                Val {
                    x: a.x.neg(),
                    e: a.e,
                }
            }
            Op::Powi(k) => {
                let a = pop(&mut stack);
                // The target's operations: acc ← acc·a, |k| − 1 times, then 1/acc for k < 0; the exact
                // value of acc after j factors is aʲ, enclosed tightly by `powi`.
                let mut acc = a;
                for j in 2..=k.unsigned_abs() {
                    let step = mul_val(acc, a)?;
                    acc = Val {
                        x: a.x.powi(j as i8)?,
                        e: step.e,
                    };
                }
                if k < 0 {
                    acc = div_val(
                        Val {
                            x: Interval::point(1.0),
                            e: 0.0,
                        },
                        acc,
                    )?;
                }
                acc
            }
            Op::Func(f) => {
                let a = pop(&mut stack);
                func_val(f, a)?
            }
            Op::Atan2 => {
                let xv = pop(&mut stack);
                let yv = pop(&mut stack);
                atan2_val(yv, xv)?
            }
        };
        stack.push(v);
    }
    Ok(out
        .into_iter()
        .map(|o| o.expect("decode proved every output is stored"))
        .collect())
}
