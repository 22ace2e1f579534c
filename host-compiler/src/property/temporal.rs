//! An MTL task of a spec (Problem 2.28): the `[mtl] formula` over the sets the spec names, made ready to
//! be measured in any metric on the state space.
//!
//! The formula may name every `[sets.<name>]`, and `Goal` and `Unsafe` (the spec's `[goal]` and the union
//! of its `[[unsafe]]`) unless a named set takes those names. Signals are the state coordinates
//! `x1 … xn`. A linear predicate aᵀx ≤ b becomes the half-space set {x : aᵀx ≤ b}, so that every atom is
//! a signed distance to a set (2.10) and, in the CAF metric ‖·‖_P, 1-Lipschitz in the metric the tube of
//! the certificate is measured in (Theorem 4.2 with the metric (2.14)). A set over some coordinates (or
//! output coordinates) is the set of states whose coordinates lie in it; its P-distance is the distance
//! in the Schur-complement metric of those coordinates (Prop 3.13).
//!
//! The task's input set is not part of the formula: it is certified for every sample as in Theorem 4.7
//! (4.15), which is the `p_Input` conjunct of Remark 2.29's embedding.

use crate::geometry::{Metric, Polytope, Region};
use crate::robustness::mtl::{Expr, Formula, FormulaError, LinearPredicate, NamedSet};
use crate::spec::{Problem, SetDesc, SpecError};

/// What an atom of the formula names: a spec set, or a predicate turned into a half-space.
enum Atom {
    Set(SetDesc),
    Goal,
    Unsafe,
    HalfSpace { a: Vec<f64>, b: f64 },
}

/// A set an atom of a formula names, as written in the spec (what the on-target monitor reads,
/// [`crate::monitor`]).
#[derive(Clone, Debug)]
pub enum AtomSet {
    /// One set.
    Set(SetDesc),
    /// A union of sets (the spec's Unsafe).
    Union(Vec<SetDesc>),
    /// aᵀx ≤ b over the whole state.
    HalfSpace { a: Vec<f64>, b: f64 },
}

/// The formula of a spec with its sets, ready to be bound in a metric.
pub struct TemporalTask {
    /// The formula as written (for messages and the report).
    pub written: Formula,
    /// The formula with every predicate replaced by a half-space set.
    formula: Formula,
    atoms: Vec<(String, Atom)>,
    n: usize,
    goal: SetDesc,
    unsafe_sets: Vec<SetDesc>,
}

/// Why a spec's formula cannot be a task.
#[derive(Debug, thiserror::Error, miette::Diagnostic)]
pub enum TemporalError {
    #[error("the spec has no [mtl] formula")]
    NoFormula,
    #[error(transparent)]
    #[diagnostic(transparent)]
    Formula(#[from] Box<FormulaError>),
    #[error("the predicate `{predicate}` involves time t; a task formula may constrain only the state (use an operator's time bounds for timing)")]
    TimeInPredicate { predicate: String },
    #[error("set `{name}`: {source}")]
    Set { name: String, source: SpecError },
}

/// The state signal names x1 … xn.
pub fn state_signals(n: usize) -> Vec<String> {
    (1..=n).map(|i| format!("x{i}")).collect()
}

impl TemporalTask {
    /// The task of a validated spec's `[mtl] formula`. The formula is bound once here (over x1 … xn and
    /// the sets), so every unknown name is reported with its place in the formula.
    pub fn from_problem(problem: &Problem) -> Result<Self, TemporalError> {
        let src = problem.mtl.as_deref().ok_or(TemporalError::NoFormula)?;
        let written = Formula::parse(src).map_err(Box::new)?;
        let n = problem.plant.n();
        let signals = state_signals(n);
        let mut atoms: Vec<(String, Atom)> = problem
            .sets
            .iter()
            .map(|(name, d)| (name.clone(), Atom::Set(d.clone())))
            .collect();
        for (name, atom) in [("Goal", Atom::Goal), ("Unsafe", Atom::Unsafe)] {
            if !atoms.iter().any(|(m, _)| m == name)
                && (name == "Goal" || !problem.unsafe_sets.is_empty())
            {
                atoms.push((name.to_string(), atom));
            }
        }
        let mut preds = 0usize;
        let expr = rewrite(written.expr(), &signals, n, &mut atoms, &mut preds)?;
        let formula = written.with_expr(expr);
        let task = Self {
            written,
            formula,
            atoms,
            n,
            goal: problem.goal.clone(),
            unsafe_sets: problem.unsafe_sets.clone(),
        };
        // Bind once against the formula as written, so that errors point into the user's text.
        let sets = task.sets(&Metric::euclidean(n))?;
        task.written
            .bind(&signals, &sets)
            .map_err(|e| TemporalError::Formula(Box::new(e)))?;
        Ok(task)
    }

    /// The formula the certificate and the optimiser evaluate (predicates as half-space sets).
    pub fn formula(&self) -> &Formula {
        &self.formula
    }

    /// State dimension.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Every set the formula may name as written: a spec set, the union of Unsafe, or a predicate's
    /// half-space.
    pub fn atom_sets(&self) -> Vec<(String, AtomSet)> {
        self.atoms
            .iter()
            .map(|(name, atom)| {
                let set = match atom {
                    Atom::Set(d) => AtomSet::Set(d.clone()),
                    Atom::Goal => AtomSet::Set(self.goal.clone()),
                    Atom::Unsafe => AtomSet::Union(self.unsafe_sets.clone()),
                    Atom::HalfSpace { a, b } => AtomSet::HalfSpace {
                        a: a.clone(),
                        b: *b,
                    },
                };
                (name.clone(), set)
            })
            .collect()
    }

    /// Every set the formula may name, as regions on the state space with the given metric (n×n).
    pub fn sets(&self, metric: &Metric) -> Result<Vec<NamedSet>, TemporalError> {
        let signals = state_signals(self.n);
        self.atoms
            .iter()
            .map(|(name, atom)| {
                let err = |source: SpecError| TemporalError::Set {
                    name: name.clone(),
                    source,
                };
                let region: Box<dyn Region> = match atom {
                    Atom::Set(d) => d.to_region(self.n).map_err(err)?,
                    Atom::Goal => self.goal.to_region(self.n).map_err(err)?,
                    Atom::Unsafe => {
                        let members = self
                            .unsafe_sets
                            .iter()
                            .map(|s| s.to_region(self.n))
                            .collect::<Result<Vec<_>, _>>()
                            .map_err(err)?;
                        Box::new(crate::geometry::Union::new(members).map_err(|e| {
                            err(SpecError::new(
                                crate::spec::ErrorKind::BadValue,
                                format!("cannot build Unsafe: {e}"),
                            ))
                        })?)
                    }
                    Atom::HalfSpace { a, b } => {
                        Box::new(Polytope::new(self.n, a.clone(), vec![*b]).map_err(|e| {
                            err(SpecError::new(
                                crate::spec::ErrorKind::BadValue,
                                format!("cannot build the half-space: {e}"),
                            ))
                        })?)
                    }
                };
                Ok(NamedSet {
                    name: name.clone(),
                    signals: signals.clone(),
                    region,
                    metric: metric.clone(),
                })
            })
            .collect()
    }
}

/// The formula with every linear predicate over x1 … xn replaced by a fresh half-space set `__p<i>`.
/// Predicates naming other signals are left in place, so binding reports them with their span.
fn rewrite(
    e: &Expr,
    signals: &[String],
    n: usize,
    atoms: &mut Vec<(String, Atom)>,
    preds: &mut usize,
) -> Result<Expr, TemporalError> {
    let mut go = |x: &Expr| rewrite(x, signals, n, atoms, preds);
    Ok(match e {
        Expr::True | Expr::False | Expr::Set { .. } => e.clone(),
        Expr::Linear(p) => match half_space(p, signals, n)? {
            Some((a, b)) => {
                let name = format!("__p{}", *preds);
                *preds += 1;
                atoms.push((name.clone(), Atom::HalfSpace { a, b }));
                Expr::Set { name, span: p.span }
            }
            None => e.clone(),
        },
        Expr::Not(x) => Expr::Not(Box::new(go(x)?)),
        Expr::And(v) => Expr::And(v.iter().map(&mut go).collect::<Result<_, _>>()?),
        Expr::Or(v) => Expr::Or(v.iter().map(&mut go).collect::<Result<_, _>>()?),
        Expr::Implies(l, r) => Expr::Implies(Box::new(go(l)?), Box::new(go(r)?)),
        Expr::Eventually(i, x) => Expr::Eventually(*i, Box::new(go(x)?)),
        Expr::Always(i, x) => Expr::Always(*i, Box::new(go(x)?)),
        Expr::Until(i, l, r) => Expr::Until(*i, Box::new(go(l)?), Box::new(go(r)?)),
        Expr::Release(i, l, r) => Expr::Release(*i, Box::new(go(l)?), Box::new(go(r)?)),
    })
}

/// aᵀx ≤ b over the state, or `None` when a term names something that is not a state signal.
fn half_space(
    p: &LinearPredicate,
    signals: &[String],
    n: usize,
) -> Result<Option<(Vec<f64>, f64)>, TemporalError> {
    let mut a = vec![0.0; n];
    for (name, c, _) in &p.terms {
        if name == "t" {
            return Err(TemporalError::TimeInPredicate {
                predicate: p.to_string(),
            });
        }
        match signals.iter().position(|s| s == name) {
            Some(i) => a[i] += c,
            None => return Ok(None),
        }
    }
    Ok(Some((a, p.b)))
}
