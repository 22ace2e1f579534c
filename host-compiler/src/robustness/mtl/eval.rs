//! Binding a parsed formula to a trace layout and named sets ([`Monitor`]), and the streaming
//! evaluator of the robust semantics (Def 2.17) in time linear in the trace length.
//!
//! Discrete-time semantics (k, j, i are sample indices, t strictly increasing):
//!
//! * window of sample k for interval [a, b]: W(k) = { j : a ≤ t_j − t_k ≤ b } (f64 arithmetic exactly
//!   as written); since a ≥ 0 it only contains j ≥ k;
//! * ⟦F_I φ⟧(k) = max_{j∈W(k)} ⟦φ⟧(j), ⟦G_I φ⟧(k) = min_{j∈W(k)} ⟦φ⟧(j);
//! * ⟦φ₁ U_I φ₂⟧(k) = max_{j∈W(k)} min(⟦φ₂⟧(j), min_{k<i<j} ⟦φ₁⟧(i)), the strict inner range of (2.13):
//!   φ₁ is required strictly between k and j, neither at k nor at j;
//! * ⟦φ₁ R_I φ₂⟧(k) = −⟦¬φ₁ U_I ¬φ₂⟧(k) = min_{j∈W(k)} max(⟦φ₂⟧(j), max_{k<i<j} ⟦φ₁⟧(i));
//! * end of trace: the trace says nothing after its last sample, so windows are truncated to the
//!   samples present; an empty window gives −∞ for F and U (no witness) and +∞ for G and R (nothing to
//!   violate). With a = 0 the window always contains k itself, so only a > 0 windows can be empty.
//!
//! F and G use monotone-deque sliding windows, U uses a deque for the part of the inner range before
//! the window and a two-stack composition of clamp maps for the window itself (derivation at
//! [`until`]). Everything is O(length) per operator, independent of the window width.

// Formula errors carry their source text for miette; they are built once per failed parse.
#![allow(clippy::result_large_err)]

use super::ast::{Expr, Interval};
use super::parse::{FormulaError, FormulaErrorKind};
use super::sets::NamedSet;
use super::trace::Trace;
use super::window::{sliding_max, sliding_min, windowed_until, WindowCursor};
use super::MtlError;

/// A formula with names resolved: signal references are column indices into
/// `[t, signal 0, signal 1, …]` and set references indices into the monitor's set list.
#[derive(Clone, Debug)]
pub(crate) enum Node {
    Const(f64),
    Linear {
        cols: Vec<(usize, f64)>,
        b: f64,
        norm: f64,
    },
    Set {
        set: usize,
        cols: Vec<usize>,
    },
    Not(Box<Node>),
    /// min over the terms (≥ 1 of them), flat like [`Expr::And`].
    And(Vec<Node>),
    /// max over the terms (≥ 1 of them).
    Or(Vec<Node>),
    Eventually(Interval, Box<Node>),
    Always(Interval, Box<Node>),
    Until(Interval, Box<Node>, Box<Node>),
    Release(Interval, Box<Node>, Box<Node>),
}

/// A formula bound to a trace layout (signal names) and a list of named sets, ready to evaluate on any
/// trace with exactly those signal names.
pub struct Monitor<'s> {
    pub(crate) root: Node,
    signals: Vec<String>,
    pub(crate) sets: Vec<&'s NamedSet>,
}

impl<'s> Monitor<'s> {
    /// Resolve the names in `expr` (parsed from `src`). `signals` are the trace's signal names in column
    /// order (without `t`); predicates may use them and `t` itself. Bare names must be sets.
    pub fn bind(
        expr: &Expr,
        src: &str,
        signals: &[String],
        sets: &'s [NamedSet],
    ) -> Result<Self, FormulaError> {
        let mut m = Monitor {
            root: Node::Const(0.0),
            signals: signals.to_vec(),
            sets: Vec::new(),
        };
        m.root = m.node(expr, src, sets)?;
        Ok(m)
    }

    /// The signal names this monitor was bound to.
    pub fn signals(&self) -> &[String] {
        &self.signals
    }

    fn column(&self, name: &str) -> Option<usize> {
        if name == "t" {
            return Some(0);
        }
        self.signals.iter().position(|s| s == name).map(|i| i + 1)
    }

    fn known(&self, sets: &[NamedSet]) -> String {
        let sig: Vec<String> = std::iter::once("t".to_string())
            .chain(self.signals.iter().cloned())
            .collect();
        let set: Vec<&str> = sets.iter().map(|s| s.name.as_str()).collect();
        // Each list quoted within `text::MAX_EXCERPT` (a trace of a million columns lists no million names).
        format!(
            "signals: {}; sets: {}",
            crate::text::excerpt(&sig.join(", ")),
            if set.is_empty() {
                "(none; pass --sets)".to_string()
            } else {
                crate::text::excerpt(&set.join(", "))
            }
        )
    }

    fn node(&mut self, e: &Expr, src: &str, sets: &'s [NamedSet]) -> Result<Node, FormulaError> {
        let b = |n: Node| Box::new(n);
        Ok(match e {
            Expr::True => Node::Const(f64::INFINITY),
            Expr::False => Node::Const(f64::NEG_INFINITY),
            Expr::Linear(p) => {
                let mut cols = Vec::with_capacity(p.terms.len());
                for (name, c, span) in &p.terms {
                    let col = self.column(name).ok_or_else(|| {
                        FormulaError::new(
                            src,
                            *span,
                            FormulaErrorKind::UnknownName { name: name.clone() },
                            format!("unknown signal `{}`", crate::text::excerpt(name)),
                            "not a column of the trace".into(),
                        )
                        .with_help(self.known(sets))
                    })?;
                    cols.push((col, *c));
                }
                Node::Linear {
                    cols,
                    b: p.b,
                    norm: p.norm(),
                }
            }
            Expr::Set { name, span } => {
                let Some(set) = sets.iter().find(|s| &s.name == name) else {
                    let shown = crate::text::excerpt(name);
                    let msg = if self.column(name).is_some() {
                        format!("`{shown}` is a signal, not a set; compare it, e.g. `{shown} >= 0`")
                    } else {
                        format!("unknown set `{shown}`")
                    };
                    return Err(FormulaError::new(
                        src,
                        *span,
                        FormulaErrorKind::UnknownName { name: name.clone() },
                        msg,
                        "not a known set".into(),
                    )
                    .with_help(self.known(sets)));
                };
                let mismatch = |msg: String| {
                    FormulaError::new(
                        src,
                        *span,
                        FormulaErrorKind::SetMismatch { name: name.clone() },
                        msg,
                        "set does not fit the trace".into(),
                    )
                };
                let mut cols = Vec::with_capacity(set.signals.len());
                for s in &set.signals {
                    cols.push(self.column(s).ok_or_else(|| {
                        mismatch(format!(
                            "set `{}` is over signal `{}`, which the trace does not have",
                            crate::text::excerpt(name),
                            crate::text::excerpt(s)
                        ))
                        .with_help(self.known(sets))
                    })?);
                }
                if set.region.dim() != cols.len() || set.metric.n != cols.len() {
                    return Err(mismatch(format!(
                        "set `{name}` lists {} signals but its region has dimension {} and its metric {}",
                        cols.len(),
                        set.region.dim(),
                        set.metric.n
                    )));
                }
                let idx = match self.sets.iter().position(|s| std::ptr::eq(*s, set)) {
                    Some(i) => i,
                    None => {
                        self.sets.push(set);
                        self.sets.len() - 1
                    }
                };
                Node::Set { set: idx, cols }
            }
            Expr::Not(x) => Node::Not(b(self.node(x, src, sets)?)),
            Expr::And(v) => Node::And(self.nodes(v, src, sets)?),
            Expr::Or(v) => Node::Or(self.nodes(v, src, sets)?),
            Expr::Implies(l, r) => Node::Or(vec![
                Node::Not(b(self.node(l, src, sets)?)),
                self.node(r, src, sets)?,
            ]),
            Expr::Eventually(i, x) => Node::Eventually(*i, b(self.node(x, src, sets)?)),
            Expr::Always(i, x) => Node::Always(*i, b(self.node(x, src, sets)?)),
            Expr::Until(i, l, r) => {
                Node::Until(*i, b(self.node(l, src, sets)?), b(self.node(r, src, sets)?))
            }
            Expr::Release(i, l, r) => {
                Node::Release(*i, b(self.node(l, src, sets)?), b(self.node(r, src, sets)?))
            }
        })
    }

    fn nodes(
        &mut self,
        v: &[Expr],
        src: &str,
        sets: &'s [NamedSet],
    ) -> Result<Vec<Node>, FormulaError> {
        v.iter().map(|e| self.node(e, src, sets)).collect()
    }

    pub(crate) fn check_trace(&self, trace: &Trace) -> Result<(), MtlError> {
        if trace.names() != self.signals.as_slice() {
            return Err(MtlError::Layout {
                bound: self.signals.join(","),
                trace: trace.names().join(","),
            });
        }
        Ok(())
    }

    /// The robustness signal ρ(k) = ⟦φ⟧(trace, t_k) for every sample, in O(length · formula size).
    pub fn robustness(&self, trace: &Trace) -> Result<Vec<f64>, MtlError> {
        self.check_trace(trace)?;
        let cols = columns(trace);
        self.eval(&self.root, trace.times(), &cols)
    }

    fn eval(&self, node: &Node, t: &[f64], cols: &[&[f64]]) -> Result<Vec<f64>, MtlError> {
        Ok(match node {
            Node::Const(_) | Node::Linear { .. } | Node::Set { .. } => {
                self.atom(node, t.len(), cols, Atoms::Compiled)?
            }
            Node::Not(x) => {
                let mut v = self.eval(x, t, cols)?;
                v.iter_mut().for_each(|r| *r = -*r);
                v
            }
            Node::And(terms) => fold(terms, f64::INFINITY, f64::min, |x| self.eval(x, t, cols), t)?,
            Node::Or(terms) => fold(
                terms,
                f64::NEG_INFINITY,
                f64::max,
                |x| self.eval(x, t, cols),
                t,
            )?,
            Node::Eventually(i, x) => sliding_max(&self.eval(x, t, cols)?, t, i.a, i.b),
            Node::Always(i, x) => sliding_min(&self.eval(x, t, cols)?, t, i.a, i.b),
            Node::Until(i, l, r) => until(t, &self.eval(l, t, cols)?, &self.eval(r, t, cols)?, *i),
            Node::Release(i, l, r) => {
                let mut phi = self.eval(l, t, cols)?;
                let mut psi = self.eval(r, t, cols)?;
                phi.iter_mut().for_each(|r| *r = -*r);
                psi.iter_mut().for_each(|r| *r = -*r);
                let mut v = until(t, &phi, &psi, *i);
                v.iter_mut().for_each(|r| *r = -*r);
                v
            }
        })
    }

    /// The atomic propositions: constants (2.9), linear predicates and sets (2.10); a set's signed
    /// distances as `how` says (the same values either way).
    #[allow(clippy::needless_range_loop)]
    pub(crate) fn atom(
        &self,
        node: &Node,
        n: usize,
        cols: &[&[f64]],
        how: Atoms,
    ) -> Result<Vec<f64>, MtlError> {
        Ok(match node {
            Node::Const(c) => vec![*c; n],
            Node::Linear {
                cols: terms,
                b,
                norm,
            } => {
                let mut v = vec![*b; n];
                for &(c, a) in terms {
                    v.iter_mut().zip(cols[c]).for_each(|(r, x)| *r -= a * x);
                }
                v.iter_mut().for_each(|r| *r /= norm);
                v
            }
            Node::Set { set, cols: idx } => {
                let s = self.sets[*set];
                let mut compiled = match how {
                    Atoms::Compiled => s.region.compile(&s.metric),
                    Atoms::Pointwise => None,
                };
                let mut x = vec![0.0; idx.len()];
                let mut v = Vec::with_capacity(n);
                for k in 0..n {
                    for (xi, &c) in x.iter_mut().zip(idx) {
                        *xi = cols[c][k];
                    }
                    let r = match compiled.as_mut() {
                        Some(f) => f.eval(&x).signed(),
                        None => s.region.signed_dist(&x, &s.metric).value,
                    };
                    if r.is_nan() {
                        return Err(MtlError::NaN {
                            set: s.name.clone(),
                            index: k,
                        });
                    }
                    v.push(r);
                }
                v
            }
            _ => unreachable!("atom() is only called on atoms"),
        })
    }
}

/// How [`Monitor::atom`] measures a set: through its compiled signed distance
/// ([`crate::geometry::Region::compile`]: factored once for the whole trace; where the set has none, as
/// `Pointwise`), or point by point through [`crate::geometry::Region::signed_dist`] (the oracle's way).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Atoms {
    Compiled,
    Pointwise,
}

/// The pointwise `op` of the terms' signals (`start` for none): one loop over an n-ary node, so a long
/// chain costs no recursion depth.
pub(crate) fn fold(
    terms: &[Node],
    start: f64,
    op: fn(f64, f64) -> f64,
    mut eval: impl FnMut(&Node) -> Result<Vec<f64>, MtlError>,
    t: &[f64],
) -> Result<Vec<f64>, MtlError> {
    let mut v = vec![start; t.len()];
    for x in terms {
        let w = eval(x)?;
        v.iter_mut().zip(&w).for_each(|(a, b)| *a = op(*a, *b));
    }
    Ok(v)
}

/// `[t, signal 0, signal 1, …]`, the column layout [`Node`] indices refer to.
pub(crate) fn columns(trace: &Trace) -> Vec<&[f64]> {
    std::iter::once(trace.times())
        .chain(trace.columns().iter().map(|c| c.as_slice()))
        .collect()
}

/// Bounded or unbounded until (2.13) in O(n).
///
/// With W(k) = lo..=hi, let lo' = max(lo, k+1), Φ(p, q) = min_{p≤i≤q} φ(i) (+∞ when empty) and
/// U(p, q) = max_{p≤j≤q} min(ψ(j), Φ(p, j−1)). Splitting the inner range k+1..j−1 at lo' gives
///
///   ⟦φ U_I ψ⟧(k) = max( [lo = k] ψ(k),  min( Φ(k+1, lo'−1), U(lo', hi) ) ),
///
/// because min distributes over max. Φ(k+1, lo'−1) is a sliding minimum (both ends monotone).
/// U(p, q) satisfies U(p, q) = max(ψ(p), min(φ(p), U(p+1, q))), U(q+1, q) = −∞, i.e. it is
/// (f_p ∘ … ∘ f_q)(−∞) for the clamp maps f_j(x) = max(ψ(j), min(φ(j), x)); these compose in closed
/// form, so a two-stack queue gives the composition over the sliding window lo'..=hi in amortised O(1).
pub(crate) fn until(t: &[f64], phi: &[f64], psi: &[f64], i: Interval) -> Vec<f64> {
    let mut w = WindowCursor::new(t, i.a, i.b);
    windowed_until(psi, phi, 1, t.len(), |k| w.at(k))
}
