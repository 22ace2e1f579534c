//! Metric temporal logic: robust semantics (Def 2.16, Def 2.17) of formulas over discrete-time traces.
//!
//! * [`parse`] / [`Formula::parse`]: text to syntax tree ([`ast::Expr`]); the grammar is in
//!   [`parse`](mod@parse). Operators: `true false ! & | -> U[a,b] R[a,b] F[a,b] G[a,b]`; atomic
//!   propositions are set names ([`NamedSet`]) and linear predicates such as `2*x1 - x2 <= 1`.
//! * [`Formula::bind`]: resolve names against a trace's signals and the named sets → [`Monitor`].
//! * [`Monitor::robustness`]: the robustness signal ρ(k) = ⟦φ⟧(x̄, t_k) at every sample, in time linear
//!   in the trace length per operator (sliding-window min/max with monotone deques; two-stack clamp
//!   composition for bounded until). The discrete-time semantics, the window definition and the
//!   end-of-trace rule are documented in [`eval`].
//! * [`reference`]: the same semantics by direct window scans, the oracle for tests and benches.
//! * [`Trace`]: traces and their CSV form (`t,<signal names>`).
//!
//! Robustness of atoms: a set S gives Dist(x(t_k), S) in the set's metric (2.8), positive inside; a
//! predicate aᵀx ≤ b gives (b − aᵀx)/‖a‖₂, the signed Euclidean distance to the half-space. `true` is +∞
//! (2.9), `false` −∞. Time bounds are in the trace's time units.

// Formula errors carry their source text for miette; they are built once per failed parse.
#![allow(clippy::result_large_err)]

pub mod ast;
pub mod eval;
pub mod parse;
pub mod reference;
pub mod sets;
pub mod trace;
pub mod tube;
mod window;

pub use ast::{Expr, Interval, LinearPredicate, Span};
pub use eval::Monitor;
pub use parse::{parse, FormulaError, FormulaErrorKind};
pub use reference::{robustness_naive, robustness_window_scan};
pub use sets::NamedSet;
pub use trace::{Trace, TraceError};
pub use tube::{Margins, TubeError, TubeFormula};

/// Errors of MTL monitoring.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum MtlError {
    #[error(transparent)]
    #[diagnostic(transparent)]
    Formula(#[from] FormulaError),
    #[error(transparent)]
    #[diagnostic(transparent)]
    Trace(#[from] TraceError),
    #[error("the monitor was bound to signals [{bound}] but the trace has [{trace}]")]
    Layout { bound: String, trace: String },
    #[error("the signed distance to set `{set}` is NaN at sample {index}")]
    NaN { set: String, index: usize },
}

/// A parsed formula together with its source text (for diagnostics when binding).
#[derive(Clone, Debug, PartialEq)]
pub struct Formula {
    expr: Expr,
    src: String,
}

impl Formula {
    /// Parse formula text.
    pub fn parse(src: &str) -> Result<Self, FormulaError> {
        Ok(Self {
            expr: parse::parse(src)?,
            src: src.to_string(),
        })
    }
    /// The same source text with another tree (a rewriting of this one whose spans point into the same
    /// text, so that binding errors still quote the formula as written).
    pub fn with_expr(&self, expr: Expr) -> Self {
        Self {
            expr,
            src: self.src.clone(),
        }
    }
    /// The syntax tree.
    pub fn expr(&self) -> &Expr {
        &self.expr
    }
    /// The source text.
    pub fn source(&self) -> &str {
        &self.src
    }
    /// Resolve names against the signal names of a trace (in column order, without `t`) and the
    /// named sets.
    pub fn bind<'s>(
        &self,
        signals: &[String],
        sets: &'s [NamedSet],
    ) -> Result<Monitor<'s>, FormulaError> {
        Monitor::bind(&self.expr, &self.src, signals, sets)
    }
}

/// Parse, bind and evaluate in one call: the robustness signal of `formula` on `trace`.
pub fn robustness(formula: &str, trace: &Trace, sets: &[NamedSet]) -> Result<Vec<f64>, MtlError> {
    let f = Formula::parse(formula)?;
    let m = f.bind(trace.names(), sets)?;
    m.robustness(trace)
}
