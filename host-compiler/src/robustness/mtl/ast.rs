//! The MTL syntax tree (Def 2.13 with the derived operators of §2.2), as produced by the parser and
//! before names are resolved against a trace.

use std::fmt;

/// A byte range `start..end` in the formula text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Span {
    pub start: usize,
    pub end: usize,
}

impl Span {
    pub fn new(start: usize, end: usize) -> Self {
        Self { start, end }
    }
    /// The smallest span covering both.
    pub fn join(self, other: Span) -> Span {
        Span {
            start: self.start.min(other.start),
            end: self.end.max(other.end),
        }
    }
}

/// A closed time interval [a, b] with 0 ≤ a ≤ b ≤ +∞, in the trace's time units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interval {
    pub a: f64,
    pub b: f64,
}

impl Interval {
    /// [0, +∞), the interval of an operator written without one.
    pub const UNBOUNDED: Interval = Interval {
        a: 0.0,
        b: f64::INFINITY,
    };
    /// Checked constructor: both finite-or-+∞ for b, 0 ≤ a ≤ b, a finite.
    pub fn new(a: f64, b: f64) -> Option<Self> {
        (a.is_finite() && a >= 0.0 && !b.is_nan() && a <= b).then_some(Self { a, b })
    }
}

impl fmt::Display for Interval {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.b == f64::INFINITY {
            write!(f, "[{:?},inf]", self.a)
        } else {
            write!(f, "[{:?},{:?}]", self.a, self.b)
        }
    }
}

/// A linear predicate in normal form aᵀx ≤ b over named signals (a ≠ 0). Its robustness is the signed
/// Euclidean distance to the half-space, (b − aᵀx)/‖a‖₂ (Def 2.16 for a half-space).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearPredicate {
    /// (signal name, coefficient a_i, span of the first occurrence); names are distinct.
    pub terms: Vec<(String, f64, Span)>,
    pub b: f64,
    /// Span of the whole predicate.
    pub span: Span,
}

impl LinearPredicate {
    /// ‖a‖₂.
    pub fn norm(&self) -> f64 {
        self.terms.iter().map(|(_, c, _)| c * c).sum::<f64>().sqrt()
    }
}

/// An MTL formula.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// ⊤, robustness +∞ (2.9).
    True,
    /// ⊥ = ¬⊤, robustness −∞.
    False,
    /// Atomic proposition naming a set: robustness Dist(x(t), S) (2.10).
    Set {
        name: String,
        span: Span,
    },
    /// Atomic proposition aᵀx ≤ b on named signals.
    Linear(LinearPredicate),
    Not(Box<Expr>),
    /// φ₁ ∧ … ∧ φₖ (k ≥ 2): a chain `a & b & c` is one n-ary node, so a long chain is flat, not deep.
    And(Vec<Expr>),
    /// φ₁ ∨ … ∨ φₖ (k ≥ 2), flat like [`Expr::And`].
    Or(Vec<Expr>),
    Implies(Box<Expr>, Box<Expr>),
    /// F_I φ = ⊤ U_I φ.
    Eventually(Interval, Box<Expr>),
    /// G_I φ = ¬F_I ¬φ.
    Always(Interval, Box<Expr>),
    /// φ₁ U_I φ₂, (2.13).
    Until(Interval, Box<Expr>, Box<Expr>),
    /// φ₁ R_I φ₂ = ¬(¬φ₁ U_I ¬φ₂).
    Release(Interval, Box<Expr>, Box<Expr>),
}

fn num(f: &mut fmt::Formatter<'_>, v: f64) -> fmt::Result {
    // `{:?}` prints the shortest text that parses back to the same f64.
    write!(f, "{v:?}")
}

impl fmt::Display for LinearPredicate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, (name, c, _)) in self.terms.iter().enumerate() {
            if i > 0 {
                write!(f, " + ")?;
            }
            num(f, *c)?;
            write!(f, "*{name}")?;
        }
        write!(f, " <= ")?;
        num(f, self.b)
    }
}

/// `(a op b op …)`.
fn chain(f: &mut fmt::Formatter<'_>, v: &[Expr], op: &str) -> fmt::Result {
    write!(f, "(")?;
    for (i, e) in v.iter().enumerate() {
        if i > 0 {
            write!(f, "{op}")?;
        }
        write!(f, "{e}")?;
    }
    write!(f, ")")
}

/// Prints a fully parenthesised formula that parses back to the same tree (up to spans and the order
/// of linear terms, which is kept).
impl fmt::Display for Expr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Expr::True => write!(f, "true"),
            Expr::False => write!(f, "false"),
            Expr::Set { name, .. } => write!(f, "{name}"),
            Expr::Linear(p) => write!(f, "({p})"),
            Expr::Not(e) => write!(f, "!{e}"),
            Expr::And(v) => chain(f, v, " & "),
            Expr::Or(v) => chain(f, v, " | "),
            Expr::Implies(l, r) => write!(f, "({l} -> {r})"),
            Expr::Eventually(i, e) => write!(f, "F{i} {e}"),
            Expr::Always(i, e) => write!(f, "G{i} {e}"),
            Expr::Until(i, l, r) => write!(f, "({l} U{i} {r})"),
            Expr::Release(i, l, r) => write!(f, "({l} R{i} {r})"),
        }
    }
}
