//! The task compiled for the on-target monitor (issue 46): a spec's `[mtl]` formula, or a reach-avoid
//! task as `!Unsafe U[0,T] Goal`, in negation normal form over signed distances to its sets, written as
//! the monitor section ([`shared_types::monitor`], section 14), and the host's f32 reference of the same
//! semantics ([`reference`], by definition rather than incrementally).
//!
//! Atoms: a box, a ball and a polytope (by its rows) over listed state coordinates, and a linear predicate
//! as a half-space; rows and half-spaces are normalised (‖a‖ = 1) in f64 before rounding. `Unsafe` (a
//! union) is the disjunction of its pieces, so `!Unsafe` the conjunction of their complements. An
//! ellipsoid is refused (its Euclidean distance has no closed form the firmware evaluates in bounded
//! time), as are sets over outputs other than state coordinates (an output whose rows of C are unit
//! vectors is read as those coordinates).
//!
//! Time bounds become samples of the period h: a → ⌈a/h − 10⁻⁹⌉, b → ⌊b/h + 10⁻⁹⌋ (the tolerance absorbs
//! the representation error of a/h), an unbounded b → N, and every bound above N → N + 1 (a window that
//! starts past the last sample stays empty). N is the task's horizon in samples, the samples being 0..=N.

pub mod reference;

/// `image` with the monitor section `body` added (section 14; any monitor it had is replaced). The
/// control law's sections, and so its certificate, are unchanged; the bytes are re-encoded (a new CRC).
pub fn attach(image: &[u8], body: &[u8]) -> Result<Vec<u8>, shared_types::error::ImageError> {
    let img = shared_types::image::decode(image)?.with_monitor(body)?;
    let mut out = vec![0u8; image.len() + body.len() + 64];
    let len = shared_types::image::encode(&img, &mut out)?;
    out.truncate(len);
    Ok(out)
}

use crate::robustness::mtl::{Expr, Interval};
use crate::spec::{Coords, SetDesc, Shape};
use shared_types::monitor as sm;

pub use crate::property::temporal::AtomSet;

/// A node of the compiled formula (negation normal form, binary ∧ and ∨, windows in samples), children
/// before parents, the root last.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    /// Atom `i`, negated or not.
    Atom(usize, bool),
    True,
    False,
    And(usize, usize),
    Or(usize, usize),
    Eventually(usize, usize, usize),
    Always(usize, usize, usize),
    /// φ U[a,b] ψ: (φ, ψ, a, b).
    Until(usize, usize, usize, usize),
    Release(usize, usize, usize, usize),
}

/// A monitor program before encoding.
#[derive(Clone, Debug)]
pub struct Program {
    /// State dimension.
    pub n: usize,
    /// The horizon N in samples.
    pub horizon: usize,
    /// Each atom's record words (kind, d, coordinates, values), as the section stores them.
    pub atoms: Vec<Vec<u32>>,
    pub nodes: Vec<Node>,
}

/// Why a task cannot be monitored.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MonitorCompileError {
    #[error("set `{0}` is an ellipsoid: the monitor evaluates boxes, balls, polytopes and half-spaces (an ellipsoid's Euclidean distance has no closed form the firmware evaluates in bounded time)")]
    Ellipsoid(String),
    #[error("set `{0}` is over output coordinates that are not state coordinates (a row of C that is not a unit vector): the monitor reads the state")]
    OutputCoords(String),
    #[error("the formula names `{0}`, which is not one of the task's sets")]
    UnknownSet(String),
    #[error("the formula has a linear predicate over signals other than the state's")]
    Predicate,
    #[error("the spec's formula: {0}")]
    Formula(String),
    #[error("the monitor program has {what} {found}, more than the firmware's {max}")]
    Capacity {
        what: &'static str,
        found: usize,
        max: usize,
    },
}

/// Samples of the bound `x` (module doc), capped at N.
fn samples(x: f64, h: f64, up: bool, horizon: usize) -> usize {
    if !x.is_finite() {
        return horizon;
    }
    let q = x / h;
    let s = if up {
        (q - 1e-9).ceil()
    } else {
        (q + 1e-9).floor()
    };
    // N + 1: a window starting past the last sample stays empty.
    (s.max(0.0) as usize).min(horizon + 1)
}

fn f(x: f64) -> u32 {
    (x as f32).to_bits()
}

/// The record words of one convex set (module doc).
fn atom_words(name: &str, set: &SetDesc, n: usize) -> Result<Vec<u32>, MonitorCompileError> {
    let idx: Vec<usize> = match &set.coords {
        Coords::State => (0..n).collect(),
        Coords::StateIndices(v) => v.clone(),
        // An output that reads state coordinates (each row of C a unit vector) is those coordinates.
        Coords::Output { C } => (0..C.rows)
            .map(|r| {
                let row = &C.data[r * C.cols..(r + 1) * C.cols];
                let ones: Vec<usize> = (0..C.cols).filter(|&j| row[j] != 0.0).collect();
                match ones.as_slice() {
                    [j] if row[*j] == 1.0 => Ok(*j),
                    _ => Err(MonitorCompileError::OutputCoords(name.into())),
                }
            })
            .collect::<Result<_, _>>()?,
    };
    let d = idx.len() as u32;
    let head = |kind: u32| {
        let mut w = vec![kind, d];
        w.extend(idx.iter().map(|&i| i as u32));
        w
    };
    Ok(match &set.shape {
        Shape::Box { lo, hi } => {
            let mut w = head(sm::ATOM_BOX);
            w.extend(lo.iter().map(|&v| f(v)));
            w.extend(hi.iter().map(|&v| f(v)));
            w
        }
        Shape::Ball { center, radius } => {
            let mut w = head(sm::ATOM_BALL);
            w.extend(center.iter().map(|&v| f(v)));
            w.push(f(*radius));
            w
        }
        Shape::Polytope { A, b } => {
            let mut w = head(sm::ATOM_POLYTOPE);
            w.push(A.rows as u32);
            let norms: Vec<f64> = (0..A.rows)
                .map(|r| {
                    let row = &A.data[r * A.cols..(r + 1) * A.cols];
                    row.iter()
                        .map(|v| v * v)
                        .sum::<f64>()
                        .sqrt()
                        .max(f64::MIN_POSITIVE)
                })
                .collect();
            for (r, nr) in norms.iter().enumerate() {
                w.extend(
                    A.data[r * A.cols..(r + 1) * A.cols]
                        .iter()
                        .map(|&v| f(v / nr)),
                );
            }
            w.extend(b.iter().zip(&norms).map(|(&v, nr)| f(v / nr)));
            w
        }
        Shape::Ellipsoid { .. } => return Err(MonitorCompileError::Ellipsoid(name.into())),
    })
}

fn halfspace_words(a: &[f64], b: f64) -> Vec<u32> {
    let nr = a
        .iter()
        .map(|v| v * v)
        .sum::<f64>()
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let mut w = vec![sm::ATOM_HALFSPACE, a.len() as u32];
    w.extend((0..a.len()).map(|i| i as u32));
    w.extend(a.iter().map(|&v| f(v / nr)));
    w.push(f(b / nr));
    w
}

struct Builder<'s> {
    sets: &'s [(String, AtomSet)],
    h: f64,
    horizon: usize,
    n: usize,
    prog: Program,
}

impl Builder<'_> {
    fn push(&mut self, node: Node) -> usize {
        self.prog.nodes.push(node);
        self.prog.nodes.len() - 1
    }

    fn window(&self, i: &Interval) -> (usize, usize) {
        let a = samples(i.a, self.h, true, self.horizon);
        let b = samples(i.b, self.h, false, self.horizon).max(a);
        (a, b)
    }

    fn atom(&mut self, words: Vec<u32>, neg: bool) -> usize {
        let i = self.prog.atoms.len();
        self.prog.atoms.push(words);
        self.push(Node::Atom(i, neg))
    }

    /// A binary chain of ∧ (or ∨) over `parts` (≥ 1).
    fn chain(&mut self, parts: Vec<usize>, and: bool) -> usize {
        let mut it = parts.into_iter();
        let mut acc = it.next().unwrap_or(usize::MAX);
        for p in it {
            acc = self.push(if and {
                Node::And(acc, p)
            } else {
                Node::Or(acc, p)
            });
        }
        acc
    }

    /// `e` (negated when `neg`) in negation normal form; returns its node.
    fn nnf(&mut self, e: &Expr, neg: bool) -> Result<usize, MonitorCompileError> {
        Ok(match e {
            Expr::True => self.push(if neg { Node::False } else { Node::True }),
            Expr::False => self.push(if neg { Node::True } else { Node::False }),
            Expr::Set { name, .. } => {
                let set = self
                    .sets
                    .iter()
                    .find(|(m, _)| m == name)
                    .map(|(_, s)| s.clone())
                    .ok_or_else(|| MonitorCompileError::UnknownSet(name.clone()))?;
                match set {
                    AtomSet::Set(d) => {
                        let w = atom_words(name, &d, self.n)?;
                        self.atom(w, neg)
                    }
                    AtomSet::HalfSpace { a, b } => self.atom(halfspace_words(&a, b), neg),
                    AtomSet::Union(members) => {
                        let mut parts = Vec::new();
                        for d in &members {
                            let w = atom_words(name, d, self.n)?;
                            parts.push(self.atom(w, neg));
                        }
                        if parts.is_empty() {
                            self.push(if neg { Node::True } else { Node::False })
                        } else {
                            // ¬(∪ Sᵢ) = ∩ ¬Sᵢ.
                            self.chain(parts, neg)
                        }
                    }
                }
            }
            Expr::Linear(_) => return Err(MonitorCompileError::Predicate),
            Expr::Not(x) => self.nnf(x, !neg)?,
            Expr::And(v) | Expr::Or(v) => {
                let and = matches!(e, Expr::And(_)) != neg;
                let parts = v
                    .iter()
                    .map(|x| self.nnf(x, neg))
                    .collect::<Result<Vec<_>, _>>()?;
                self.chain(parts, and)
            }
            Expr::Implies(l, r) => {
                // l → r = ¬l ∨ r; negated: l ∧ ¬r.
                let l = self.nnf(l, !neg)?;
                let r = self.nnf(r, neg)?;
                self.push(if neg { Node::And(l, r) } else { Node::Or(l, r) })
            }
            Expr::Eventually(i, x) | Expr::Always(i, x) => {
                let ev = matches!(e, Expr::Eventually(..)) != neg;
                let c = self.nnf(x, neg)?;
                let (a, b) = self.window(i);
                self.push(if ev {
                    Node::Eventually(c, a, b)
                } else {
                    Node::Always(c, a, b)
                })
            }
            Expr::Until(i, l, r) | Expr::Release(i, l, r) => {
                // ¬(φ U ψ) = ¬φ R ¬ψ.
                let until = matches!(e, Expr::Until(..)) != neg;
                let l = self.nnf(l, neg)?;
                let r = self.nnf(r, neg)?;
                let (a, b) = self.window(i);
                self.push(if until {
                    Node::Until(l, r, a, b)
                } else {
                    Node::Release(l, r, a, b)
                })
            }
        })
    }
}

impl Program {
    /// The formula `expr` over `sets` for a plant of state dimension `n`, period `h` and horizon N
    /// samples (module doc).
    pub fn compile(
        expr: &Expr,
        sets: &[(String, AtomSet)],
        n: usize,
        h: f64,
        horizon: usize,
    ) -> Result<Self, MonitorCompileError> {
        let mut b = Builder {
            sets,
            h,
            horizon,
            n,
            prog: Program {
                n,
                horizon,
                atoms: Vec::new(),
                nodes: Vec::new(),
            },
        };
        b.nnf(expr, false)?;
        let p = b.prog;
        for (what, found, max) in [
            ("atoms", p.atoms.len(), sm::MAX_MONITOR_ATOMS),
            ("nodes", p.nodes.len(), sm::MAX_MONITOR_NODES),
            ("samples", horizon + 1, sm::MAX_MONITOR_SAMPLES),
        ] {
            if found > max {
                return Err(MonitorCompileError::Capacity { what, found, max });
            }
        }
        Ok(p)
    }

    /// A reach-avoid task as `!Unsafe U[0,N] Goal`.
    pub fn reach_avoid(
        goal: &SetDesc,
        unsafe_sets: &[SetDesc],
        n: usize,
        horizon: usize,
    ) -> Result<Self, MonitorCompileError> {
        let sets = vec![
            ("Goal".to_string(), AtomSet::Set(goal.clone())),
            ("Unsafe".to_string(), AtomSet::Union(unsafe_sets.to_vec())),
        ];
        let span = crate::robustness::mtl::Span::new(0, 0);
        let set = |name: &str| Expr::Set {
            name: name.into(),
            span,
        };
        let expr = Expr::Until(
            Interval::UNBOUNDED,
            Box::new(Expr::Not(Box::new(set("Unsafe")))),
            Box::new(set("Goal")),
        );
        // The period is irrelevant for [0, ∞): every bound is 0 or N.
        Self::compile(&expr, &sets, n, 1.0, horizon)
    }

    /// The monitor of a spec as written (for a nonlinear plant the original spec, whose sets are over the
    /// plant's state): its `[mtl]` formula if it has one, else its reach-avoid task; N = the horizon's
    /// samples.
    pub fn for_problem(problem: &crate::spec::Problem) -> Result<Self, MonitorCompileError> {
        let n = problem.plant.n();
        let horizon = problem.horizon_steps();
        match &problem.mtl {
            Some(_) => {
                let task = crate::property::temporal::TemporalTask::from_problem(problem)
                    .map_err(|e| MonitorCompileError::Formula(e.to_string()))?;
                Self::compile(
                    task.formula().expr(),
                    &task.atom_sets(),
                    n,
                    problem.plant.period,
                    horizon,
                )
            }
            None => Self::reach_avoid(&problem.goal, &problem.unsafe_sets, n, horizon),
        }
    }

    /// The words of the evaluator's arena and the RAM the monitor takes (arena and state), as the
    /// firmware sizes them.
    pub fn footprint(&self) -> (usize, usize) {
        let body = self.encode();
        match sm::MonitorProgram::decode(&body, self.n) {
            Ok(p) => (p.words(), p.ram_bytes()),
            Err(_) => (0, 0),
        }
    }

    /// The section body ([`shared_types::monitor`]'s layout).
    pub fn encode(&self) -> Vec<u8> {
        let atom_words: usize = self.atoms.iter().map(Vec::len).sum();
        let mut w: Vec<u32> = vec![
            self.n as u32,
            self.horizon as u32,
            self.atoms.len() as u32,
            self.nodes.len() as u32,
            atom_words as u32,
        ];
        for a in &self.atoms {
            w.extend(a);
        }
        for node in &self.nodes {
            let u = |x: usize| x as u32;
            w.extend(match *node {
                Node::Atom(i, neg) => [sm::OP_ATOM, u(i), u32::from(neg), 0, 0],
                Node::True => [sm::OP_TRUE, 0, 0, 0, 0],
                Node::False => [sm::OP_FALSE, 0, 0, 0, 0],
                Node::And(l, r) => [sm::OP_AND, u(l), u(r), 0, 0],
                Node::Or(l, r) => [sm::OP_OR, u(l), u(r), 0, 0],
                Node::Eventually(c, a, b) => [sm::OP_EVENTUALLY, u(c), 0, u(a), u(b)],
                Node::Always(c, a, b) => [sm::OP_ALWAYS, u(c), 0, u(a), u(b)],
                Node::Until(l, r, a, b) => [sm::OP_UNTIL, u(l), u(r), u(a), u(b)],
                Node::Release(l, r, a, b) => [sm::OP_RELEASE, u(l), u(r), u(a), u(b)],
            });
        }
        w.iter().flat_map(|x| x.to_le_bytes()).collect()
    }
}
