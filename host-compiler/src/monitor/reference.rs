//! The f32 reference of the monitor's semantics ([`shared_types::monitor`]'s module doc), computed by
//! definition at every step from the samples so far, in O(N²) per step: no deque, no queue of maps, no
//! buffers. The atoms are the section's own (`MonitorProgram::atom`), so the firmware's, the shared
//! evaluator's and this reference's values agree bit for bit when the streaming is right; every other
//! operation is min, max or negation, which are exact.
//!
//! A node's value at t is known at step k when k = N or t + hor ≤ k (hor as the module doc defines it);
//! before that its bounds follow the operator rules stated there.

use super::{Node, Program};
use shared_types::monitor::{MonitorProgram, Report};

const NEG: f32 = f32::NEG_INFINITY;
const POS: f32 = f32::INFINITY;

struct Eval<'a> {
    prog: &'a Program,
    /// Exact values found so far: a known value never changes as samples arrive.
    memo: std::cell::RefCell<std::collections::HashMap<(usize, usize), f32>>,
    /// Atom values per sample known so far.
    atoms: Vec<Vec<f32>>,
    hor: Vec<usize>,
    k: usize,
    horizon: usize,
}

fn neg(x: f32) -> f32 {
    -x + 0.0
}

impl Eval<'_> {
    fn known(&self, i: usize, t: usize) -> bool {
        t <= self.horizon && (self.k == self.horizon || t + self.hor[i] <= self.k)
    }

    fn window(&self, t: usize, a: usize, b: usize) -> std::ops::RangeInclusive<usize> {
        (t + a)..=(t + b).min(self.horizon)
    }

    /// The exact value (only called where known).
    fn val(&self, i: usize, t: usize) -> f32 {
        if let Some(&v) = self.memo.borrow().get(&(i, t)) {
            return v;
        }
        let v = self.val_uncached(i, t);
        self.memo.borrow_mut().insert((i, t), v);
        v
    }

    fn val_uncached(&self, i: usize, t: usize) -> f32 {
        match self.prog.nodes[i] {
            Node::Atom(a, n) => {
                let v = self.atoms[t][a];
                if n {
                    neg(v)
                } else {
                    v
                }
            }
            Node::True => POS,
            Node::False => NEG,
            Node::And(l, r) => self.val(l, t).min(self.val(r, t)),
            Node::Or(l, r) => self.val(l, t).max(self.val(r, t)),
            Node::Eventually(c, a, b) => self
                .window(t, a, b)
                .map(|j| self.val(c, j))
                .fold(NEG, f32::max),
            Node::Always(c, a, b) => self
                .window(t, a, b)
                .map(|j| self.val(c, j))
                .fold(POS, f32::min),
            Node::Until(l, r, a, b) => self.until(l, r, a, b, t, false),
            Node::Release(l, r, a, b) => self.until(l, r, a, b, t, true),
        }
    }

    /// max over j of min(ψ(j), min over t < i < j of φ(i)); R as −U(−φ, −ψ).
    fn until(&self, l: usize, r: usize, a: usize, b: usize, t: usize, dual: bool) -> f32 {
        let d = |v: f32| if dual { neg(v) } else { v };
        let mut best = NEG;
        for j in self.window(t, a, b) {
            let mut v = d(self.val(r, j));
            for i in (t + 1)..j {
                v = v.min(d(self.val(l, i)));
            }
            best = best.max(v);
        }
        d(best)
    }

    fn bounds(&self, i: usize, t: usize) -> (f32, f32) {
        if self.known(i, t) {
            let v = self.val(i, t);
            return (v, v);
        }
        match self.prog.nodes[i] {
            Node::Atom(..) => (NEG, POS),
            Node::True => (POS, POS),
            Node::False => (NEG, NEG),
            Node::And(l, r) => {
                let (x, y) = (self.bounds(l, t), self.bounds(r, t));
                (x.0.min(y.0), x.1.min(y.1))
            }
            Node::Or(l, r) => {
                let (x, y) = (self.bounds(l, t), self.bounds(r, t));
                (x.0.max(y.0), x.1.max(y.1))
            }
            Node::Eventually(c, a, b) => {
                let lo = self
                    .window(t, a, b)
                    .filter(|&j| self.known(c, j))
                    .map(|j| self.val(c, j))
                    .fold(NEG, f32::max);
                (lo, POS)
            }
            Node::Always(c, a, b) => {
                let hi = self
                    .window(t, a, b)
                    .filter(|&j| self.known(c, j))
                    .map(|j| self.val(c, j))
                    .fold(POS, f32::min);
                (NEG, hi)
            }
            Node::Until(l, r, a, b) => self.until_bounds(l, r, a, b, t, false),
            Node::Release(l, r, a, b) => {
                let (lo, hi) = self.until_bounds(l, r, a, b, t, true);
                (neg(hi), neg(lo))
            }
        }
    }

    /// U's bounds (module doc of `shared_types::monitor`) on the values φ, ψ (negated when `dual`).
    fn until_bounds(
        &self,
        l: usize,
        r: usize,
        a: usize,
        b: usize,
        t: usize,
        dual: bool,
    ) -> (f32, f32) {
        let d = |v: f32| if dual { neg(v) } else { v };
        let n = self.horizon;
        let e = (t + b).min(n);
        let s = t + a;
        // With a = 0 the witness j = t needs no φ: a head term ψ(t), and the maps from t + 1.
        let q0 = t + a.max(1);
        // The minimum of φ over (t, t + a): its known prefix, and whether all of it is known.
        let mut m = POS;
        let mut known = true;
        for i in (t + 1)..(s.min(n + 1)) {
            if self.known(l, i) {
                m = m.min(d(self.val(l, i)));
            } else {
                known = false;
                break;
            }
        }
        // The maps pushed: j from q0 while j < e and φ(j), ψ(j) are known.
        let mut next = q0;
        while next < e && self.known(l, next) && self.known(r, next) {
            next += 1;
        }
        // Q(y) = max(max over j < next of min(ψ(j), φ(s..j)), min(φ(s..next), y)).
        let q = |y: f32| {
            let (mut best, mut run) = (NEG, POS);
            for j in q0..next {
                best = best.max(d(self.val(r, j)).min(run));
                run = run.min(d(self.val(l, j)));
            }
            best.max(run.min(y))
        };
        let psi_next = if next <= e && self.known(r, next) {
            d(self.val(r, next))
        } else {
            NEG
        };
        let (q_lo, q_hi) = if e >= q0 {
            (q(psi_next), q(POS))
        } else {
            (NEG, NEG)
        };
        let head = if a > 0 {
            (NEG, NEG)
        } else if self.known(r, t) {
            let v = d(self.val(r, t));
            (v, v)
        } else {
            (NEG, POS)
        };
        let lo = if known { m.min(head.0.max(q_lo)) } else { NEG };
        (lo, m.min(head.1.max(q_hi)))
    }
}

/// The node horizons (`shared_types::monitor`'s module doc), computed here on their own.
fn horizons(prog: &Program) -> Vec<usize> {
    let mut hor = vec![0usize; prog.nodes.len()];
    for (i, node) in prog.nodes.iter().enumerate() {
        hor[i] = match *node {
            Node::Atom(..) | Node::True | Node::False => 0,
            Node::And(l, r) | Node::Or(l, r) => hor[l].max(hor[r]),
            Node::Eventually(c, _, b) | Node::Always(c, _, b) => b + hor[c],
            Node::Until(l, r, a, b) | Node::Release(l, r, a, b) => {
                if a <= 1 && b <= 1 {
                    b + hor[r]
                } else {
                    b + hor[r].max(hor[l].saturating_sub(1))
                }
            }
        };
    }
    hor
}

/// The report after each sample of `trace` (at most N + 1 of them are read; later ones repeat the last
/// report, as the monitor does).
pub fn reports(prog: &Program, section: &MonitorProgram<'_>, trace: &[Vec<f32>]) -> Vec<Report> {
    let mut ev = Eval {
        prog,
        memo: Default::default(),
        atoms: Vec::new(),
        hor: horizons(prog),
        k: 0,
        horizon: prog.horizon,
    };
    let root = prog.nodes.len() - 1;
    let mut out: Vec<Report> = Vec::with_capacity(trace.len());
    for (k, x) in trace.iter().enumerate() {
        if k > prog.horizon {
            let last = *out.last().expect("a report before");
            out.push(last);
            continue;
        }
        ev.atoms
            .push((0..prog.atoms.len()).map(|a| section.atom(a, x)).collect());
        ev.k = k;
        let (lo, hi) = ev.bounds(root, 0);
        out.push(Report::of_bounds(lo, hi));
    }
    out
}

/// A bound on |atom in f32 − the same atom in f64| at the f32 state `x`: (d + 4)·2⁻²⁴·S, with S the sum of
/// the absolute values of the coordinates read and of the atom's stored values (its parameters are the
/// f64 ones rounded once). Derivation: each difference, square, product and the sum of d terms adds at
/// most (d + 1) units of relative rounding on magnitudes bounded by S (γ_{d+1}), the square root halves
/// the relative error of its argument and adds one, the final subtraction one, and the rounding of the
/// stored parameters at most one more on their magnitudes. The formula's value is 1-Lipschitz in its atoms
/// (min and max), so the largest of these bounds over the atoms and samples read bounds the formula's too.
pub fn atom_rounding_bound(words: &[u32], x: &[f32]) -> f64 {
    let d = words[1] as usize;
    let coords: f64 = words[2..2 + d]
        .iter()
        .map(|&i| x[i as usize].abs() as f64)
        .sum();
    let params: f64 = words[2 + d..]
        .iter()
        .map(|&w| f32::from_bits(w).abs() as f64)
        .filter(|v| v.is_finite())
        .sum();
    (d as f64 + 4.0) * f64::powi(2.0, -24) * (coords + params)
}
