//! Symbolic derivatives: ∂e/∂v by the rules of calculus on the tree (simplified by [`Expr`]'s
//! constructors), gradients and Jacobians, and for an input-affine system ẋ = f(x) + g(x)u, y = h(x)
//! (3.16) the Lie derivatives of Notation 3.4, the vector relative degree at a point and the decoupling
//! matrix Γ of Def 3.5, (3.18)–(3.19). No finite differences anywhere.
//!
//! Every derivative is built under a node budget ([`super::MAX_DERIVED_NODES`]: each copied subtree is
//! charged before it is copied) and its depth is checked ([`super::MAX_DERIVED_DEPTH`]), so a model
//! whose derivatives explode is refused with [`ExprError::TooLarge`] instead of exhausting memory.

use super::{Expr, ExprError, Func, Point, Var, MAX_DERIVED_DEPTH, MAX_DERIVED_NODES};

/// Nodes a derivative may still copy.
struct Budget(usize);

impl Budget {
    fn charge(&mut self, nodes: usize) -> Result<(), ExprError> {
        self.0 = self.0.checked_sub(nodes).ok_or(ExprError::TooLarge {
            what: "size of a derived expression (nodes)",
            value: MAX_DERIVED_NODES + 1,
            limit: MAX_DERIVED_NODES,
            span: 0..0,
        })?;
        Ok(())
    }

    /// A charged copy.
    fn copy(&mut self, e: &Expr) -> Result<Expr, ExprError> {
        self.charge(e.size())?;
        Ok(e.clone())
    }
}

/// Refuses a derived expression beyond the limits.
fn checked(e: Expr) -> Result<Expr, ExprError> {
    let depth = e.depth();
    if depth > MAX_DERIVED_DEPTH {
        return Err(ExprError::TooLarge {
            what: "depth of a derived expression",
            value: depth,
            limit: MAX_DERIVED_DEPTH,
            span: 0..0,
        });
    }
    let size = e.size();
    if size > MAX_DERIVED_NODES {
        return Err(ExprError::TooLarge {
            what: "size of a derived expression (nodes)",
            value: size,
            limit: MAX_DERIVED_NODES,
            span: 0..0,
        });
    }
    Ok(e)
}

/// ∂e/∂v.
pub fn derivative(e: &Expr, v: Var) -> Result<Expr, ExprError> {
    let mut budget = Budget(MAX_DERIVED_NODES);
    checked(d(e, v, &mut budget)?)
}

/// `a · b`, 0 when either factor is the constant 0. A derivative's (or a Lie derivative's) terms are
/// only read where the expression differentiated is defined, and there every factor of the rules below
/// is too; so a zero factor may drop its partner (`0 · 1/q` from the quotient rule), which the general
/// constructor [`Expr::mul`] keeps unless the partner is defined everywhere.
fn times(a: Expr, b: Expr) -> Expr {
    if a.is_zero() || b.is_zero() {
        Expr::c(0.0)
    } else {
        Expr::mul(a, b)
    }
}

/// `a / b`, 0 when `a` is the constant 0 (see [`times`]).
fn over(a: Expr, b: Expr) -> Expr {
    if a.is_zero() {
        Expr::c(0.0)
    } else {
        Expr::div(a, b)
    }
}

fn d(e: &Expr, v: Var, b: &mut Budget) -> Result<Expr, ExprError> {
    // A subtree without v has derivative 0: skip it without copying anything.
    if !e.uses(v) {
        return Ok(Expr::c(0.0));
    }
    b.charge(1)?;
    Ok(match e {
        Expr::Const(_) => Expr::c(0.0),
        Expr::Var(w) => Expr::c(if *w == v { 1.0 } else { 0.0 }),
        Expr::Neg(a) => Expr::neg(d(a, v, b)?),
        Expr::Add(p, q) => Expr::add(d(p, v, b)?, d(q, v, b)?),
        Expr::Sub(p, q) => Expr::sub(d(p, v, b)?, d(q, v, b)?),
        // (pq)' = p'q + pq'
        Expr::Mul(p, q) => Expr::add(
            times(d(p, v, b)?, b.copy(q)?),
            times(b.copy(p)?, d(q, v, b)?),
        ),
        // (p/q)' = p'/q − p q'/q²
        Expr::Div(p, q) => Expr::sub(
            over(d(p, v, b)?, b.copy(q)?),
            over(times(b.copy(p)?, d(q, v, b)?), Expr::pow(b.copy(q)?, 2)),
        ),
        // (p^k)' = k p^(k−1) p'
        Expr::Pow(p, k) => times(
            Expr::mul(Expr::c(f64::from(*k)), Expr::pow(b.copy(p)?, k - 1)),
            d(p, v, b)?,
        ),
        Expr::Func(f, p) => {
            let dp = d(p, v, b)?;
            let p = b.copy(p)?;
            let outer = match f {
                Func::Sin => Expr::func(Func::Cos, p),
                Func::Cos => Expr::neg(Expr::func(Func::Sin, p)),
                // 1 + tan²
                Func::Tan => Expr::add(Expr::c(1.0), Expr::pow(Expr::func(Func::Tan, p), 2)),
                Func::Exp => Expr::func(Func::Exp, p),
                Func::Log => Expr::div(Expr::c(1.0), p),
                Func::Sqrt => Expr::div(Expr::c(0.5), Expr::func(Func::Sqrt, p)),
                // sign(p) = p/|p| (undefined at 0, as |·|'s derivative is)
                Func::Abs => {
                    let q = b.copy(&p)?;
                    Expr::div(p, Expr::func(Func::Abs, q))
                }
                Func::Atan => Expr::div(Expr::c(1.0), Expr::add(Expr::c(1.0), Expr::pow(p, 2))),
                Func::Tanh => Expr::sub(Expr::c(1.0), Expr::pow(Expr::func(Func::Tanh, p), 2)),
            };
            times(outer, dp)
        }
        // atan2(y, x)' = (x y' − y x') / (x² + y²)
        Expr::Atan2(y, x) => {
            let num = Expr::sub(
                times(b.copy(x)?, d(y, v, b)?),
                times(b.copy(y)?, d(x, v, b)?),
            );
            let den = Expr::add(Expr::pow(b.copy(x)?, 2), Expr::pow(b.copy(y)?, 2));
            over(num, den)
        }
    })
}

/// ∂e/∂x_i for every state i < n.
pub fn gradient(e: &Expr, n: usize) -> Result<Vec<Expr>, ExprError> {
    (0..n)
        .map(|i| derivative(e, Var::State(i as u16)))
        .collect()
}

/// The Jacobian ∂eᵢ/∂vⱼ: one row per expression, one column per variable.
pub fn jacobian(es: &[Expr], wrt: &[Var]) -> Result<Vec<Vec<Expr>>, ExprError> {
    es.iter()
        .map(|e| wrt.iter().map(|&v| derivative(e, v)).collect())
        .collect()
}

/// The Lie derivative of `h` along the vector field `field` (one expression per state): Σᵢ ∂h/∂xᵢ ·
/// fieldᵢ (Notation 3.4).
pub fn lie(h: &Expr, field: &[Expr]) -> Result<Expr, ExprError> {
    let mut sum = Expr::c(0.0);
    for (i, fi) in field.iter().enumerate() {
        if fi.is_zero() {
            continue;
        }
        let dh = derivative(h, Var::State(i as u16))?;
        sum = Expr::add(sum, times(dh, fi.clone()));
    }
    checked(sum)
}

/// An input-affine system with outputs, (3.16): ẋ = f(x) + g(x)u, y = h(x), with as many outputs as
/// inputs. Expressions may use states and parameters, never inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct AffineSystem {
    /// f, n entries.
    pub f: Vec<Expr>,
    /// g, n rows of m entries (column j is the vector field of input j).
    pub g: Vec<Vec<Expr>>,
    /// h, m entries.
    pub h: Vec<Expr>,
}

/// Why Def 3.5 fails at a point.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RelativeDegreeError {
    /// A derived expression beyond the limits.
    #[error(transparent)]
    Expr(#[from] ExprError),
    /// No input reaches output `output` within n derivatives (L_g L_f^k h_i = 0 for every k < n).
    #[error("output {output}: no input appears in its first {n} derivatives (L_g L_f^k h = 0 for k < {n}), so it has no relative degree")]
    NoRelativeDegree { output: usize, n: usize },
}

/// The vector relative degree at a point and what Def 3.5 builds from it.
#[derive(Clone, Debug, PartialEq)]
pub struct RelativeDegree {
    /// r_i per output.
    pub r: Vec<usize>,
    /// L_f^k h_i for k = 0..=r_i, per output.
    pub lf: Vec<Vec<Expr>>,
    /// Γ (3.19): Γ_ij = L_{g_j} L_f^{r_i − 1} h_i.
    pub gamma: Vec<Vec<Expr>>,
}

impl AffineSystem {
    /// State dimension n.
    pub fn n(&self) -> usize {
        self.f.len()
    }

    /// Input (and output) dimension m.
    pub fn m(&self) -> usize {
        self.h.len()
    }

    /// Column j of g: the vector field of input j.
    pub fn g_col(&self, j: usize) -> Vec<Expr> {
        self.g.iter().map(|row| row[j].clone()).collect()
    }

    /// The vector relative degree at `at` (Def 3.5): r_i = 1 + the least k with L_{g_j} L_f^k h_i(at) ≠ 0
    /// for some j, where a value counts as zero if its expression simplifies to 0 or `|value| ≤ zero_tol`.
    /// Γ is returned symbolically; whether it is nonsingular is the caller's test (at points, or over a
    /// box by [`super::interval`]).
    pub fn relative_degree_at(
        &self,
        at: &Point<'_>,
        zero_tol: f64,
    ) -> Result<RelativeDegree, RelativeDegreeError> {
        let n = self.n();
        let cols: Vec<Vec<Expr>> = (0..self.m()).map(|j| self.g_col(j)).collect();
        let mut r = Vec::new();
        let mut lf = Vec::new();
        let mut gamma = Vec::new();
        for (i, hi) in self.h.iter().enumerate() {
            let mut tower = vec![hi.clone()];
            let mut found = None;
            for k in 0..n {
                let row: Vec<Expr> = cols
                    .iter()
                    .map(|g| lie(&tower[k], g))
                    .collect::<Result<_, _>>()?;
                let nonzero = row
                    .iter()
                    .any(|e| !e.is_zero() && e.eval(at).abs() > zero_tol);
                if nonzero {
                    found = Some((k + 1, row));
                    break;
                }
                tower.push(lie(&tower[k], &self.f)?);
            }
            let Some((ri, row)) = found else {
                return Err(RelativeDegreeError::NoRelativeDegree { output: i, n });
            };
            // Complete the tower to L_f^{r_i} h_i (the linearised output's r-th derivative's drift).
            if tower.len() == ri {
                tower.push(lie(&tower[ri - 1], &self.f)?);
            }
            r.push(ri);
            lf.push(tower);
            gamma.push(row);
        }
        Ok(RelativeDegree { r, lf, gamma })
    }
}

/// The values of a matrix of expressions at a point.
pub fn eval_matrix(m: &[Vec<Expr>], at: &Point<'_>) -> Vec<Vec<f64>> {
    m.iter()
        .map(|row| row.iter().map(|e| e.eval(at)).collect())
        .collect()
}
