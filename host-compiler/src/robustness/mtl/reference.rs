//! A direct transcription of the discrete-time robust semantics (Def 2.17, windows as in
//! [`super::eval`]): every temporal operator scans its window sample by sample, so it costs
//! O(length × window) per operator. It shares nothing with the streaming evaluator except the atomic
//! propositions, whose sets it measures point by point through `Region::signed_dist` (the streaming
//! evaluator through their compiled forms), and serves as the test oracle and the bench baseline.

// Index loops on purpose: a literal transcription of the definition.
#![allow(clippy::needless_range_loop)]
// Formula errors carry their source text for miette; they are built once per failed parse.
#![allow(clippy::result_large_err)]

use super::eval::{columns, fold, Atoms, Monitor, Node};
use super::trace::Trace;
use super::MtlError;

/// The robustness signal by the definition, testing every sample j of the trace for membership in the
/// window of every k: O(length²) per operator (O(length³) for U and R). The test oracle.
pub fn robustness_naive(m: &Monitor, trace: &Trace) -> Result<Vec<f64>, MtlError> {
    m.check_trace(trace)?;
    let cols = columns(trace);
    eval(m, &m.root, trace.times(), &cols, Scan::Full)
}

/// The robustness signal by scanning each window from j = k until t_j − t_k > b: O(length × window)
/// for F and G, O(length × window²) for U and R (the inner range is rescanned for every j). The baseline the streaming evaluator is measured against.
pub fn robustness_window_scan(m: &Monitor, trace: &Trace) -> Result<Vec<f64>, MtlError> {
    m.check_trace(trace)?;
    let cols = columns(trace);
    eval(m, &m.root, trace.times(), &cols, Scan::Window)
}

#[derive(Clone, Copy, PartialEq)]
enum Scan {
    /// j over the whole trace.
    Full,
    /// j from k while t_j − t_k ≤ b (valid because a ≥ 0 and differences grow with j).
    Window,
}

/// Indices j to test for window membership of sample k.
fn candidates(t: &[f64], k: usize, b: f64, scan: Scan) -> impl Iterator<Item = usize> + '_ {
    let start = if scan == Scan::Full { 0 } else { k };
    (start..t.len()).take_while(move |&j| scan == Scan::Full || t[j] - t[k] <= b)
}

fn eval(
    m: &Monitor,
    node: &Node,
    t: &[f64],
    cols: &[&[f64]],
    scan: Scan,
) -> Result<Vec<f64>, MtlError> {
    let n = t.len();
    Ok(match node {
        Node::Const(_) | Node::Linear { .. } | Node::Set { .. } => {
            m.atom(node, n, cols, Atoms::Pointwise)?
        }
        Node::Not(x) => eval(m, x, t, cols, scan)?.into_iter().map(|r| -r).collect(),
        Node::And(terms) => fold(
            terms,
            f64::INFINITY,
            f64::min,
            |x| eval(m, x, t, cols, scan),
            t,
        )?,
        Node::Or(terms) => fold(
            terms,
            f64::NEG_INFINITY,
            f64::max,
            |x| eval(m, x, t, cols, scan),
            t,
        )?,
        Node::Eventually(i, x) => {
            let v = eval(m, x, t, cols, scan)?;
            (0..n)
                .map(|k| {
                    let mut best = f64::NEG_INFINITY;
                    for j in candidates(t, k, i.b, scan) {
                        let d = t[j] - t[k];
                        if d >= i.a && d <= i.b {
                            best = best.max(v[j]);
                        }
                    }
                    best
                })
                .collect()
        }
        Node::Always(i, x) => {
            let v = eval(m, x, t, cols, scan)?;
            (0..n)
                .map(|k| {
                    let mut worst = f64::INFINITY;
                    for j in candidates(t, k, i.b, scan) {
                        let d = t[j] - t[k];
                        if d >= i.a && d <= i.b {
                            worst = worst.min(v[j]);
                        }
                    }
                    worst
                })
                .collect()
        }
        Node::Until(i, l, r) => {
            let (phi, psi) = (eval(m, l, t, cols, scan)?, eval(m, r, t, cols, scan)?);
            (0..n)
                .map(|k| {
                    let mut best = f64::NEG_INFINITY;
                    for j in candidates(t, k, i.b, scan) {
                        let d = t[j] - t[k];
                        if d >= i.a && d <= i.b {
                            // (2.13): φ₁ strictly between t_k and t_j.
                            let mut inner = f64::INFINITY;
                            for p in (k + 1)..j {
                                inner = inner.min(phi[p]);
                            }
                            best = best.max(psi[j].min(inner));
                        }
                    }
                    best
                })
                .collect()
        }
        Node::Release(i, l, r) => {
            let (phi, psi) = (eval(m, l, t, cols, scan)?, eval(m, r, t, cols, scan)?);
            (0..n)
                .map(|k| {
                    let mut worst = f64::INFINITY;
                    for j in candidates(t, k, i.b, scan) {
                        let d = t[j] - t[k];
                        if d >= i.a && d <= i.b {
                            let mut inner = f64::NEG_INFINITY;
                            for p in (k + 1)..j {
                                inner = inner.max(phi[p]);
                            }
                            worst = worst.min(psi[j].max(inner));
                        }
                    }
                    worst
                })
                .collect()
        }
    })
}
