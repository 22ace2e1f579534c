//! Expressions over named states, inputs and parameters: the language a user writes a nonlinear plant in
//! (ẋ = f(x) + g(x)u, y = h(x) of (3.16); the flat maps of §3.1.3). This module owns the AST
//! ([`Expr`]), the names it refers to ([`Names`]), parsing with byte spans ([`parse`]), evaluation in
//! f64, symbolic derivatives, Jacobians and the Lie derivatives of Notation 3.4 with the relative degree
//! and decoupling matrix Γ of Def 3.5 ([`diff`]), compilation to the target's model program
//! (`shared_types::program`, [`compile`]), and interval enclosures with a sound bound on the f32
//! program's rounding error ([`interval`]).
//!
//! # Limits
//! Every expression is bounded before any work, so a hostile spec cannot exhaust the stack or memory:
//!
//! | size | limit | why |
//! |---|---|---|
//! | source text of one expression | [`MAX_EXPR_LEN`] = 4 096 bytes | parse work |
//! | parenthesis / unary-minus / call nesting | [`MAX_EXPR_NESTING`] = 64 | the parser's recursion |
//! | depth of a parsed tree | [`MAX_EXPR_DEPTH`] = 256 | every recursive walk of the tree |
//! | nodes of a derived expression (derivatives, Lie derivatives) | [`MAX_DERIVED_NODES`] = 50 000 | memory and work |
//! | depth of a derived expression | [`MAX_DERIVED_DEPTH`] = 1 024 | recursion of every walk |
//! | parameters of one name table | [`MAX_PARAMS`] = 256 | `u16` variable indices |
//! | integer power `x^k` | `1 ≤ |k| ≤` [`MAX_PROGRAM_POWI`] = 16 | the target's multiplication loop |
//!
//! Derivatives are symbolic (the tree of the derivative, simplified by the smart constructors), never
//! finite differences; derived trees are checked against the limits above as they are built.

pub mod compile;
pub mod diff;
pub mod interval;
mod parse;
pub mod tape;

pub use parse::parse;
pub use shared_types::capacity::MAX_PROGRAM_POWI;
pub use shared_types::program::Func;

use std::ops::Range;

/// Largest source text of one expression, in bytes.
pub const MAX_EXPR_LEN: usize = 4096;
/// Deepest nesting of parentheses, unary minus and function calls the parser accepts.
pub const MAX_EXPR_NESTING: usize = 64;
/// Deepest parsed tree (a long sum `a + b + …` is a deep tree without any nesting).
pub const MAX_EXPR_DEPTH: usize = 256;
/// Most parameters a name table may declare (variables are indexed by `u16`; states and inputs are
/// bounded by the image capacities).
pub const MAX_PARAMS: usize = 256;
/// Most nodes of a derived expression.
pub const MAX_DERIVED_NODES: usize = 50_000;
/// Deepest derived expression.
pub const MAX_DERIVED_DEPTH: usize = 1024;

/// What a name in an expression stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Var {
    /// State `x_i`.
    State(u16),
    /// Input `u_i`.
    Input(u16),
    /// Parameter `p_i` (a number given in the spec).
    Param(u16),
}

impl std::fmt::Display for Var {
    /// `state 2`, `input 0`, `parameter 1` (0-based; messages with names use [`Expr::display`]).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Var::State(i) => write!(f, "state {i}"),
            Var::Input(i) => write!(f, "input {i}"),
            Var::Param(i) => write!(f, "parameter {i}"),
        }
    }
}

/// An expression tree. Build it with [`parse`] or the simplifying constructors ([`Expr::add`], ...).
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    /// A number.
    Const(f64),
    /// A state, input or parameter.
    Var(Var),
    /// `−a`.
    Neg(Box<Expr>),
    /// `a + b`.
    Add(Box<Expr>, Box<Expr>),
    /// `a − b`.
    Sub(Box<Expr>, Box<Expr>),
    /// `a · b`.
    Mul(Box<Expr>, Box<Expr>),
    /// `a / b`.
    Div(Box<Expr>, Box<Expr>),
    /// `a^k`, `k` a non-zero integer with `|k| ≤ MAX_PROGRAM_POWI`.
    Pow(Box<Expr>, i8),
    /// A unary function.
    Func(Func, Box<Expr>),
    /// `atan2(y, x)`.
    Atan2(Box<Expr>, Box<Expr>),
}

/// The names an expression may use: states, inputs and parameters (with their values), plus the
/// built-in constant `pi`. Names are distinct and none is a function name or `pi`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Names {
    pub states: Vec<String>,
    pub inputs: Vec<String>,
    /// (name, value).
    pub params: Vec<(String, f64)>,
}

/// Why an expression or a name table was refused. `span` is a byte range in the expression's source text
/// (empty for derived expressions), which the spec layer shifts into the file.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ExprError {
    /// The text is not an expression.
    #[error("{message}")]
    Syntax { message: String, span: Range<usize> },
    /// A name that is not a state, input, parameter, function or `pi`.
    #[error("unknown name `{name}`{hint}")]
    UnknownName {
        name: String,
        span: Range<usize>,
        /// Nearby advice (e.g. "a function needs parentheses"), starting with "; " when present.
        hint: String,
    },
    /// A size beyond a documented limit (module docs).
    #[error("{what} is {value}, more than the limit {limit}")]
    TooLarge {
        what: &'static str,
        value: usize,
        limit: usize,
        span: Range<usize>,
    },
    /// A name declared twice, or one that shadows a function or `pi`.
    #[error("name `{}` {why}", crate::text::excerpt(name))]
    BadName { name: String, why: &'static str },
    /// Compilation to the target's program does not fit its capacities, or a value it would store is not
    /// finite in f32.
    #[error("model program: {0}")]
    Program(String),
}

impl ExprError {
    /// Byte range in the expression's text, if the error has one.
    pub fn span(&self) -> Option<Range<usize>> {
        match self {
            ExprError::Syntax { span, .. }
            | ExprError::UnknownName { span, .. }
            | ExprError::TooLarge { span, .. } => Some(span.clone()),
            _ => None,
        }
    }
}

impl Names {
    /// Checks that every name is an identifier, distinct, and neither a function name nor `pi`; and
    /// that parameter values are finite.
    pub fn validate(&self) -> Result<(), ExprError> {
        for (what, len, limit) in [
            ("number of states", self.states.len(), usize::from(u16::MAX)),
            ("number of inputs", self.inputs.len(), usize::from(u16::MAX)),
            ("number of parameters", self.params.len(), MAX_PARAMS),
        ] {
            if len > limit {
                return Err(ExprError::TooLarge {
                    what,
                    value: len,
                    limit,
                    span: 0..0,
                });
            }
        }
        let mut seen = std::collections::HashSet::new();
        let all = self
            .states
            .iter()
            .chain(&self.inputs)
            .chain(self.params.iter().map(|(n, _)| n));
        for name in all {
            let ident = name
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            let bad = |why| {
                Err(ExprError::BadName {
                    name: name.clone(),
                    why,
                })
            };
            if !ident {
                return bad("is not an identifier (a letter or `_`, then letters, digits, `_`)");
            }
            if name == "pi" || parse::function(name).is_some() {
                return bad("is reserved (a function name or `pi`)");
            }
            if !seen.insert(name.as_str()) {
                return bad("is declared twice");
            }
        }
        if let Some((name, _)) = self.params.iter().find(|(_, v)| !v.is_finite()) {
            return Err(ExprError::BadName {
                name: name.clone(),
                why: "has a value that is not finite",
            });
        }
        Ok(())
    }

    /// The variable a name stands for.
    pub fn lookup(&self, name: &str) -> Option<Var> {
        let pos = |v: &[String]| v.iter().position(|s| s == name).map(|i| i as u16);
        pos(&self.states)
            .map(Var::State)
            .or_else(|| pos(&self.inputs).map(Var::Input))
            .or_else(|| {
                self.params
                    .iter()
                    .position(|(s, _)| s == name)
                    .map(|i| Var::Param(i as u16))
            })
    }

    /// The name of a variable.
    pub fn name(&self, v: Var) -> &str {
        match v {
            Var::State(i) => &self.states[i as usize],
            Var::Input(i) => &self.inputs[i as usize],
            Var::Param(i) => &self.params[i as usize].0,
        }
    }

    /// The parameter values, in order.
    pub fn param_values(&self) -> Vec<f64> {
        self.params.iter().map(|(_, v)| *v).collect()
    }
}

/// A point: values of the states, inputs and parameters an expression is evaluated at.
#[derive(Clone, Copy, Debug)]
pub struct Point<'a> {
    pub x: &'a [f64],
    pub u: &'a [f64],
    pub p: &'a [f64],
}

impl Point<'_> {
    /// The value of a variable (NaN if its index is out of range, so a bad point shows in the result).
    pub fn get(&self, v: Var) -> f64 {
        let (s, i) = match v {
            Var::State(i) => (self.x, i),
            Var::Input(i) => (self.u, i),
            Var::Param(i) => (self.p, i),
        };
        s.get(i as usize).copied().unwrap_or(f64::NAN)
    }
}

/// The f64 value of a unary function.
pub fn apply_f64(f: Func, x: f64) -> f64 {
    match f {
        Func::Sin => x.sin(),
        Func::Cos => x.cos(),
        Func::Tan => x.tan(),
        Func::Exp => x.exp(),
        Func::Log => x.ln(),
        Func::Sqrt => x.sqrt(),
        Func::Abs => x.abs(),
        Func::Atan => x.atan(),
        Func::Tanh => x.tanh(),
    }
}

// The constructors test constants with guards (`z == 0.0` also takes −0.0), kept for clarity.
#[allow(clippy::redundant_guards)]
impl Expr {
    /// A number.
    pub fn c(v: f64) -> Expr {
        Expr::Const(v)
    }

    /// A variable.
    pub fn var(v: Var) -> Expr {
        Expr::Var(v)
    }

    /// The number, if this is one.
    pub fn as_const(&self) -> Option<f64> {
        match self {
            Expr::Const(v) => Some(*v),
            _ => None,
        }
    }

    /// Whether this is the constant 0 (a structural test: the simplifier folds what it can).
    pub fn is_zero(&self) -> bool {
        self.as_const() == Some(0.0)
    }

    /// Value in f64 at a point.
    pub fn eval(&self, at: &Point<'_>) -> f64 {
        match self {
            Expr::Const(v) => *v,
            Expr::Var(v) => at.get(*v),
            Expr::Neg(a) => -a.eval(at),
            Expr::Add(a, b) => a.eval(at) + b.eval(at),
            Expr::Sub(a, b) => a.eval(at) - b.eval(at),
            Expr::Mul(a, b) => a.eval(at) * b.eval(at),
            Expr::Div(a, b) => a.eval(at) / b.eval(at),
            Expr::Pow(a, k) => a.eval(at).powi((*k).into()),
            Expr::Func(f, a) => apply_f64(*f, a.eval(at)),
            Expr::Atan2(y, x) => y.eval(at).atan2(x.eval(at)),
        }
    }

    /// Number of nodes.
    pub fn size(&self) -> usize {
        match self {
            Expr::Const(_) | Expr::Var(_) => 1,
            Expr::Neg(a) | Expr::Pow(a, _) | Expr::Func(_, a) => 1 + a.size(),
            Expr::Add(a, b)
            | Expr::Sub(a, b)
            | Expr::Mul(a, b)
            | Expr::Div(a, b)
            | Expr::Atan2(a, b) => 1 + a.size() + b.size(),
        }
    }

    /// Length of the longest root-to-leaf path (a leaf has depth 1).
    pub fn depth(&self) -> usize {
        match self {
            Expr::Const(_) | Expr::Var(_) => 1,
            Expr::Neg(a) | Expr::Pow(a, _) | Expr::Func(_, a) => 1 + a.depth(),
            Expr::Add(a, b)
            | Expr::Sub(a, b)
            | Expr::Mul(a, b)
            | Expr::Div(a, b)
            | Expr::Atan2(a, b) => 1 + a.depth().max(b.depth()),
        }
    }

    /// Whether a variable occurs.
    pub fn uses(&self, v: Var) -> bool {
        match self {
            Expr::Const(_) => false,
            Expr::Var(w) => *w == v,
            Expr::Neg(a) | Expr::Pow(a, _) | Expr::Func(_, a) => a.uses(v),
            Expr::Add(a, b)
            | Expr::Sub(a, b)
            | Expr::Mul(a, b)
            | Expr::Div(a, b)
            | Expr::Atan2(a, b) => a.uses(v) || b.uses(v),
        }
    }

    /// The expression with every parameter replaced by its value (and folded).
    pub fn bind_params(&self, p: &[f64]) -> Expr {
        self.map_vars(&|v| match v {
            Var::Param(i) => p.get(i as usize).map(|&x| Expr::c(x)),
            _ => None,
        })
    }

    /// The expression with some variables replaced (`sub(v)` = `Some(e)`), rebuilt through the
    /// simplifying constructors.
    pub fn map_vars(&self, sub: &dyn Fn(Var) -> Option<Expr>) -> Expr {
        match self {
            Expr::Const(v) => Expr::c(*v),
            Expr::Var(v) => sub(*v).unwrap_or(Expr::Var(*v)),
            Expr::Neg(a) => Expr::neg(a.map_vars(sub)),
            Expr::Add(a, b) => Expr::add(a.map_vars(sub), b.map_vars(sub)),
            Expr::Sub(a, b) => Expr::sub(a.map_vars(sub), b.map_vars(sub)),
            Expr::Mul(a, b) => Expr::mul(a.map_vars(sub), b.map_vars(sub)),
            Expr::Div(a, b) => Expr::div(a.map_vars(sub), b.map_vars(sub)),
            Expr::Pow(a, k) => Expr::pow(a.map_vars(sub), *k),
            Expr::Func(f, a) => Expr::func(*f, a.map_vars(sub)),
            Expr::Atan2(y, x) => Expr::atan2(y.map_vars(sub), x.map_vars(sub)),
        }
    }

    /// The expression written with the names of `names` (for messages).
    pub fn display<'a>(&'a self, names: &'a Names) -> Display<'a> {
        Display { e: self, names }
    }

    /// Whether the expression is defined (finite) at every real point, whatever the values of its
    /// variables: built from finite numbers, variables, `+ − ·`, positive powers and the functions
    /// defined on all of ℝ (sin, cos, exp, abs, atan, tanh, atan2). Division, negative powers, log,
    /// sqrt and tan are partial. The simplifier folds `0·e` and `e − e` to 0 only for such an `e`.
    pub fn total(&self) -> bool {
        match self {
            Expr::Const(v) => v.is_finite(),
            Expr::Var(_) => true,
            Expr::Neg(a) => a.total(),
            Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Atan2(a, b) => {
                a.total() && b.total()
            }
            Expr::Div(..) => false,
            Expr::Pow(a, k) => *k > 0 && a.total(),
            Expr::Func(f, a) => !matches!(f, Func::Log | Func::Sqrt | Func::Tan) && a.total(),
        }
    }

    /// The innermost subterm whose value at `at` is not finite (NaN or ±∞) while its operands' are,
    /// with that value; `None` when every subterm is finite there. The spec refuses a term that is
    /// undefined at a point of its region with this subterm and the point.
    pub fn undefined_at(&self, at: &Point<'_>) -> Option<(&Expr, f64)> {
        fn walk<'e>(e: &'e Expr, at: &Point<'_>) -> Result<f64, (&'e Expr, f64)> {
            let v = match e {
                Expr::Const(v) => *v,
                Expr::Var(v) => at.get(*v),
                Expr::Neg(a) => -walk(a, at)?,
                Expr::Add(a, b) => walk(a, at)? + walk(b, at)?,
                Expr::Sub(a, b) => walk(a, at)? - walk(b, at)?,
                Expr::Mul(a, b) => walk(a, at)? * walk(b, at)?,
                Expr::Div(a, b) => walk(a, at)? / walk(b, at)?,
                Expr::Pow(a, k) => walk(a, at)?.powi((*k).into()),
                Expr::Func(f, a) => apply_f64(*f, walk(a, at)?),
                Expr::Atan2(y, x) => walk(y, at)?.atan2(walk(x, at)?),
            };
            if v.is_finite() {
                Ok(v)
            } else {
                Err((e, v))
            }
        }
        walk(self, at).err()
    }

    // ---- simplifying constructors: fold constants and drop the trivial terms 0 and 1, so that
    // derivatives stay small and structural zeros (Def 3.5's L_g L_f^k h = 0) are recognised. A fold
    // never changes the value where the expression is defined, and never makes an expression defined
    // where it is not (a constant is folded only when finite; `0·e`, `e − e` only for a total `e`; `0/e`
    // never), so every undefined term of a user's expression survives parsing to be refused.

    /// `−a`.
    #[allow(clippy::should_implement_trait)]
    pub fn neg(a: Expr) -> Expr {
        match a {
            Expr::Const(v) => Expr::c(-v),
            Expr::Neg(inner) => *inner,
            a => Expr::Neg(Box::new(a)),
        }
    }

    /// `a + b`.
    #[allow(clippy::should_implement_trait)]
    pub fn add(a: Expr, b: Expr) -> Expr {
        match (a, b) {
            (Expr::Const(x), Expr::Const(y)) if (x + y).is_finite() => Expr::c(x + y),
            (Expr::Const(z), e) | (e, Expr::Const(z)) if z == 0.0 => e,
            (a, Expr::Neg(b)) => Expr::sub(a, *b),
            (a, b) => Expr::Add(Box::new(a), Box::new(b)),
        }
    }

    /// `a − b`.
    #[allow(clippy::should_implement_trait)]
    pub fn sub(a: Expr, b: Expr) -> Expr {
        match (a, b) {
            (Expr::Const(x), Expr::Const(y)) if (x - y).is_finite() => Expr::c(x - y),
            (e, Expr::Const(z)) if z == 0.0 => e,
            (Expr::Const(z), e) if z == 0.0 => Expr::neg(e),
            (a, Expr::Neg(b)) => Expr::add(a, *b),
            // `a − a` is 0 only where a is defined: folded for a defined everywhere.
            (a, b) if a == b && a.total() => Expr::c(0.0),
            (a, b) => Expr::Sub(Box::new(a), Box::new(b)),
        }
    }

    /// `a · b`.
    #[allow(clippy::should_implement_trait)]
    pub fn mul(a: Expr, b: Expr) -> Expr {
        match (a, b) {
            (Expr::Const(x), Expr::Const(y)) if (x * y).is_finite() => Expr::c(x * y),
            // `0 · e` is 0 only where e is defined: folded for e defined everywhere, so that
            // `0*sqrt(-1)` stays undefined and is refused where the spec checks its terms.
            (Expr::Const(z), e) | (e, Expr::Const(z)) if z == 0.0 && e.total() => Expr::c(0.0),
            (Expr::Const(o), e) | (e, Expr::Const(o)) if o == 1.0 => e,
            (Expr::Const(o), e) | (e, Expr::Const(o)) if o == -1.0 => Expr::neg(e),
            (Expr::Neg(a), Expr::Neg(b)) => Expr::mul(*a, *b),
            (Expr::Neg(a), b) | (b, Expr::Neg(a)) => Expr::neg(Expr::mul(*a, b)),
            // Constants first, so that c1·(c2·e) folds.
            (e, Expr::Const(c)) => Expr::mul(Expr::c(c), e),
            (Expr::Const(c), Expr::Mul(a, b))
                if a.as_const()
                    .is_some_and(|k| (c * k).is_finite() && c * k != 0.0) =>
            {
                Expr::mul(Expr::c(c * a.as_const().unwrap_or(1.0)), *b)
            }
            (a, b) => Expr::Mul(Box::new(a), Box::new(b)),
        }
    }

    /// `a / b`.
    #[allow(clippy::should_implement_trait)]
    pub fn div(a: Expr, b: Expr) -> Expr {
        match (a, b) {
            (Expr::Const(x), Expr::Const(y)) if y != 0.0 && (x / y).is_finite() => Expr::c(x / y),
            // `0 / e` is not folded: it is undefined where e = 0 (and where e is), which the spec's
            // checks must see.
            (e, Expr::Const(o)) if o == 1.0 => e,
            (a, b) => Expr::Div(Box::new(a), Box::new(b)),
        }
    }

    /// `a^k`.
    pub fn pow(a: Expr, k: i8) -> Expr {
        match (a, k) {
            // Only derivatives build `p^0` (from `p^1`), where p is defined.
            (_, 0) => Expr::c(1.0),
            (a, 1) => a,
            (Expr::Const(x), k) if x.powi(k.into()).is_finite() => Expr::c(x.powi(k.into())),
            (a, k) => Expr::Pow(Box::new(a), k),
        }
    }

    /// A unary function.
    pub fn func(f: Func, a: Expr) -> Expr {
        match a {
            Expr::Const(x) if apply_f64(f, x).is_finite() => Expr::c(apply_f64(f, x)),
            a => Expr::Func(f, Box::new(a)),
        }
    }

    /// `atan2(y, x)`.
    pub fn atan2(y: Expr, x: Expr) -> Expr {
        match (y, x) {
            (Expr::Const(a), Expr::Const(b)) => Expr::c(a.atan2(b)),
            (y, x) => Expr::Atan2(Box::new(y), Box::new(x)),
        }
    }
}

/// An expression written out with names ([`Expr::display`]), fully parenthesised where precedence needs.
pub struct Display<'a> {
    e: &'a Expr,
    names: &'a Names,
}

impl std::fmt::Display for Display<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write_expr(f, self.e, self.names)
    }
}

fn write_expr(f: &mut std::fmt::Formatter<'_>, e: &Expr, names: &Names) -> std::fmt::Result {
    // An operand in parentheses unless it is a variable, a call or a non-negative number.
    let operand = |f: &mut std::fmt::Formatter<'_>, e: &Expr| {
        let bare = matches!(e, Expr::Const(v) if *v >= 0.0)
            || matches!(e, Expr::Var(_) | Expr::Func(..) | Expr::Atan2(..));
        if bare {
            write_expr(f, e, names)
        } else {
            f.write_str("(")?;
            write_expr(f, e, names)?;
            f.write_str(")")
        }
    };
    match e {
        Expr::Const(v) => write!(f, "{v}"),
        Expr::Var(v) => f.write_str(names.name(*v)),
        Expr::Neg(a) => {
            f.write_str("-")?;
            operand(f, a)
        }
        Expr::Add(a, b) | Expr::Sub(a, b) | Expr::Mul(a, b) | Expr::Div(a, b) => {
            let op = match e {
                Expr::Add(..) => " + ",
                Expr::Sub(..) => " - ",
                Expr::Mul(..) => "*",
                _ => "/",
            };
            operand(f, a)?;
            f.write_str(op)?;
            operand(f, b)
        }
        Expr::Pow(a, k) => {
            operand(f, a)?;
            if *k < 0 {
                write!(f, "^({k})")
            } else {
                write!(f, "^{k}")
            }
        }
        Expr::Func(g, a) => {
            write!(f, "{}(", g.name())?;
            write_expr(f, a, names)?;
            f.write_str(")")
        }
        Expr::Atan2(y, x) => {
            f.write_str("atan2(")?;
            write_expr(f, y, names)?;
            f.write_str(", ")?;
            write_expr(f, x, names)?;
            f.write_str(")")
        }
    }
}

#[cfg(test)]
mod tests;
