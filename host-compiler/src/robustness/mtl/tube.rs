//! The robustness of a formula over a *tube* of trajectories around a sampled nominal, in continuous
//! time: sound lower and upper bounds on ⟦φ⟧(x, t) for every trajectory x that stays within given margins
//! of the nominal, at the sample instants and over the whole closed interval between two samples. This is
//! what Theorem 4.2 needs for the sampled loop (the theorem itself assumes the tube in continuous time):
//! a formula certified here holds for the continuous run between samples, not only at them.
//!
//! **Time.** Samples are uniform, t_k = k·h, k = 0..N, and the formula is judged on [0, t_N] with the
//! end-of-trace rule of [`super::eval`] (a window is cut at t_N; F and U over an empty window are −∞, G
//! and R +∞). Interval I_k = [t_k, t_{k+1}], k = 0..N−1. Operator bounds a, b are converted to sample
//! counts α = a/h, β = b/h compared with a tolerance of 10⁻⁹ sample (the sample times are nominal).
//!
//! **Bounds per node ψ** (`Bounds`): at samples, s_lo(j) ≤ ψ(t_j) ≤ s_hi(j); over intervals,
//! l_lo(k) ≤ inf_{t∈I_k} ψ(t) and l_hi(k) ≥ sup_{t∈I_k} ψ(t). An atom (a signed distance in a metric in
//! which the tube is measured, 1-Lipschitz) with nominal value d has s = d ∓ r at samples and,
//! over I_k, the worse of d_k ∓ e_k (inside) and d_k ∓ r, d_{k+1} ∓ r (its ends), r and e_k the margins
//! ([`Margins`]). Then, by induction over the formula:
//!
//! * ¬ swaps and negates the bounds; ∧ and ∨ take min and max of each bound (inf min ≥ min inf, sup max
//!   = max sup).
//! * F_[a,b] ψ, lower: a witness must lie in the window for every t the bound speaks for. At sample k the
//!   window is [k+α, k+β], so samples j ∈ [k+⌈α⌉, k+⌊β⌋] witness with s_lo(j); for all t ∈ I_k the
//!   window contains [k+1+α, k+β], so samples j ∈ [k+1+⌈α⌉, k+⌊β⌋] witness, and when a = 0, t itself
//!   (l_lo(k)). Upper: every interval the window (or the union of windows over I_k) meets, with l_hi.
//! * G = ¬F¬ by duality.
//! * φ₁ U_[a,b] φ₂, lower: a witness sample j as for F, with φ₁ held over [t_k, t_j] (a superset of the
//!   open range the semantics asks for): min(s₂_lo(j), min_{i=k}^{j−1} l₁_lo(i)); j = k needs nothing of
//!   φ₁. Upper: F_[a,b] φ₂'s (dropping the φ₁ requirement only raises the value).
//! * φ₁ R φ₂ = ¬(¬φ₁ U ¬φ₂).
//!
//! **Directional clearance.** The interval bound d_k ∓ e_k takes the whole excursion from x̃(k) in every
//! direction. Where the caller knows more, a lower bound c_k > 0 on the distance from an atom's set of
//! every trajectory of the tube over I_k (for a union of convex pieces, the drift against each piece's
//! normal, `certify::pieces`' module doc), every such trajectory is outside the set over I_k with
//! signed distance ≤ −c_k, so l_hi(k) ≤ −c_k; the bound is the smaller of the two. The lower bound
//! l_lo is unchanged. With c_k non-increasing in r (as the caller's bounds are), l_hi stays
//! non-decreasing in r and the root keeps its monotonicity.
//!
//! Each bound passes values through min and max only, so a bound at the root equals one atom's bound at
//! one sample or interval (or ±∞). The windowed extrema are sliding min/max over index ranges whose
//! ends move forward (a monotone deque, O(N) per operator); the until's lower bound composes clamp maps
//! over its sliding witness window in a two-stack queue ([`windowed_until`]), O(N) as well.

use super::eval::{Atoms, Monitor, Node};
use super::window::{windowed_until, Wedge};
use super::{MtlError, NamedSet};

/// Sample-count tolerance when converting operator bounds to sample offsets.
const TOL: f64 = 1e-9;

/// How far any trajectory of the tube can be from the nominal, in the atoms' metric: `r` at every sample
/// instant, and `between[k]` from the sample x̃(k) anywhere strictly inside I_k = (t_k, t_{k+1})
/// (k = 0..N−1).
pub struct Margins<'m> {
    pub r: f64,
    pub between: &'m [f64],
}

/// The margins of a tube and the atoms' clearances between samples
/// ([`TubeFormula::lower_at_start_with`]).
type Tubed<'a, 'm> = (&'a Margins<'m>, &'a [Option<Vec<f64>>]);

/// Bounds of one node's robustness (module doc).
#[derive(Clone, Debug)]
struct Bounds {
    s_lo: Vec<f64>,
    s_hi: Vec<f64>,
    l_lo: Vec<f64>,
    l_hi: Vec<f64>,
}

impl Bounds {
    fn negate(self) -> Bounds {
        let neg = |v: Vec<f64>| v.into_iter().map(|x| -x).collect::<Vec<_>>();
        Bounds {
            s_lo: neg(self.s_hi),
            s_hi: neg(self.s_lo),
            l_lo: neg(self.l_hi),
            l_hi: neg(self.l_lo),
        }
    }
}

/// A formula bound to a nominal: its atoms' nominal values at every sample, ready to give the bounds of
/// the root for any margins.
pub struct TubeFormula<'m, 's> {
    monitor: &'m Monitor<'s>,
    /// Nominal value of each atom node at every sample, in the order [`TubeFormula::new`] visits them.
    atoms: Vec<Vec<f64>>,
    /// N: the number of intervals.
    intervals: usize,
    /// The sample period h.
    h: f64,
}

/// Why a nominal trace cannot carry a tube.
#[derive(Debug, thiserror::Error)]
pub enum TubeError {
    #[error("the trace needs at least two samples, uniformly spaced")]
    TooShort,
    #[error("sample {index} is at t = {t}, not at {expected} (uniform samples are required)")]
    NotUniform { index: usize, t: f64, expected: f64 },
    #[error(transparent)]
    Mtl(#[from] Box<MtlError>),
}

impl<'m, 's> TubeFormula<'m, 's> {
    /// The atoms of `monitor` evaluated on the nominal `trace` (uniform samples from t = 0).
    pub fn new(monitor: &'m Monitor<'s>, trace: &super::Trace) -> Result<Self, TubeError> {
        let t = trace.times();
        if t.len() < 2 {
            return Err(TubeError::TooShort);
        }
        let h = t[1] - t[0];
        for (k, &tk) in t.iter().enumerate() {
            let expected = t[0] + k as f64 * h;
            if !(h > 0.0) || (tk - expected).abs() > 1e-9 * h.max(1.0) {
                return Err(TubeError::NotUniform {
                    index: k,
                    t: tk,
                    expected,
                });
            }
        }
        monitor.check_trace(trace).map_err(Box::new)?;
        let cols = super::eval::columns(trace);
        let mut atoms = Vec::new();
        collect_atoms(monitor, &monitor.root, &cols, t.len(), &mut atoms).map_err(Box::new)?;
        Ok(Self {
            monitor,
            atoms,
            intervals: t.len() - 1,
            h,
        })
    }

    /// The atoms whose nominal value at some sample is `value` (or −`value`, under a negation): where a
    /// root value computed without margins comes from, since the semantics only passes values through
    /// min, max and negation. Each as (the set, the sample, whether the atom is negated there).
    pub fn critical(&self, value: f64) -> Vec<(&'s NamedSet, usize, bool)> {
        let mut sets = Vec::new();
        atom_sets(&self.monitor.root, &mut sets);
        let mut out = Vec::new();
        if !value.is_finite() {
            return out;
        }
        for (d, set) in self.atoms.iter().zip(sets) {
            let Some(set) = set.and_then(|i| self.monitor.sets.get(i)) else {
                continue;
            };
            for (k, &v) in d.iter().enumerate() {
                if v == value {
                    out.push((*set, k, false));
                } else if v == -value {
                    out.push((*set, k, true));
                }
            }
        }
        out
    }

    /// The nominal's robustness at the samples as the monitor computes it (discrete-time semantics).
    pub fn samples(&self) -> Vec<f64> {
        let mut next = 0;
        let b = self.eval(&self.monitor.root, &mut next, None);
        b.s_lo
    }

    /// A lower bound on ⟦φ⟧(x, 0) for every trajectory x of the tube: continuous-time semantics on [0, t_N].
    pub fn lower_at_start(&self, m: &Margins<'_>) -> f64 {
        self.lower_at_start_with(m, &[])
    }

    /// [`TubeFormula::lower_at_start`] with what is known of the atoms' sets between samples: `clear[i]`
    /// for the i-th atom in evaluation order ([`TubeFormula::atom_sets`]), where given, a lower bound on
    /// the distance from the atom's set of every trajectory of the tube over each interval I_k (a value
    /// ≤ 0 or NaN says nothing). Where positive, the atom's upper bound over I_k is at most −clear[i][k]
    /// (module doc, "Directional clearance").
    pub fn lower_at_start_with(&self, m: &Margins<'_>, clear: &[Option<Vec<f64>>]) -> f64 {
        let mut next = 0;
        let b = self.eval(&self.monitor.root, &mut next, Some((m, clear)));
        b.s_lo[0]
    }

    /// The set of each atom in evaluation order (`None` for a linear predicate over signals that are
    /// not a set): the order of [`TubeFormula::lower_at_start_with`]'s `clear`.
    pub fn atom_sets(&self) -> Vec<Option<&'s NamedSet>> {
        let mut sets = Vec::new();
        atom_sets(&self.monitor.root, &mut sets);
        sets.into_iter()
            .map(|i| i.and_then(|i| self.monitor.sets.get(i).copied()))
            .collect()
    }

    /// The bounds of the root signal for the margins (all four, for tests and reports).
    fn eval(&self, node: &Node, next: &mut usize, m: Option<Tubed<'_, '_>>) -> Bounds {
        let (ns, ni) = (self.intervals + 1, self.intervals);
        match node {
            Node::Const(c) => Bounds {
                s_lo: vec![*c; ns],
                s_hi: vec![*c; ns],
                l_lo: vec![*c; ni],
                l_hi: vec![*c; ni],
            },
            Node::Linear { .. } | Node::Set { .. } => {
                let d = &self.atoms[*next];
                *next += 1;
                match m {
                    // Without margins: the nominal itself, at samples only (the discrete semantics).
                    None => Bounds {
                        s_lo: d.clone(),
                        s_hi: d.clone(),
                        l_lo: d[..ni].to_vec(),
                        l_hi: d[..ni].to_vec(),
                    },
                    Some((m, clear)) => {
                        let clear = clear.get(*next - 1).and_then(|c| c.as_ref());
                        Bounds {
                            s_lo: d.iter().map(|v| v - m.r).collect(),
                            s_hi: d.iter().map(|v| v + m.r).collect(),
                            // The closed interval: its inside from x̃(k), its ends from their samples.
                            l_lo: (0..ni)
                                .map(|k| (d[k] - m.between[k]).min(d[k] - m.r).min(d[k + 1] - m.r))
                                .collect(),
                            l_hi: (0..ni)
                                .map(|k| {
                                    let iso =
                                        (d[k] + m.between[k]).max(d[k] + m.r).max(d[k + 1] + m.r);
                                    // Outside the set by at least c over the whole interval.
                                    match clear.and_then(|c| c.get(k)) {
                                        Some(&c) if c > 0.0 => iso.min(-c),
                                        _ => iso,
                                    }
                                })
                                .collect(),
                        }
                    }
                }
            }
            Node::Not(x) => self.eval(x, next, m).negate(),
            Node::And(v) => self.fold(v, next, m, f64::min),
            Node::Or(v) => self.fold(v, next, m, f64::max),
            Node::Eventually(i, x) => {
                let b = self.eval(x, next, m);
                self.eventually(&b, i.a, i.b, m.is_some())
            }
            Node::Always(i, x) => {
                let b = self.eval(x, next, m).negate();
                self.eventually(&b, i.a, i.b, m.is_some()).negate()
            }
            Node::Until(i, l, r) => {
                let bl = self.eval(l, next, m);
                let br = self.eval(r, next, m);
                self.until(&bl, &br, i.a, i.b, m.is_some())
            }
            Node::Release(i, l, r) => {
                let bl = self.eval(l, next, m).negate();
                let br = self.eval(r, next, m).negate();
                self.until(&bl, &br, i.a, i.b, m.is_some()).negate()
            }
        }
    }

    fn fold(
        &self,
        v: &[Node],
        next: &mut usize,
        m: Option<Tubed<'_, '_>>,
        op: fn(f64, f64) -> f64,
    ) -> Bounds {
        let mut acc: Option<Bounds> = None;
        for x in v {
            let b = self.eval(x, next, m);
            acc = Some(match acc {
                None => b,
                Some(mut a) => {
                    let z = |p: &mut Vec<f64>, q: &[f64]| {
                        p.iter_mut().zip(q).for_each(|(x, y)| *x = op(*x, *y))
                    };
                    z(&mut a.s_lo, &b.s_lo);
                    z(&mut a.s_hi, &b.s_hi);
                    z(&mut a.l_lo, &b.l_lo);
                    z(&mut a.l_hi, &b.l_hi);
                    a
                }
            });
        }
        acc.unwrap_or_else(|| {
            // An empty conjunction is true, an empty disjunction false.
            let c = op(f64::INFINITY, f64::NEG_INFINITY);
            let c = if c == f64::NEG_INFINITY {
                f64::INFINITY
            } else {
                f64::NEG_INFINITY
            };
            let (ns, ni) = (self.intervals + 1, self.intervals);
            Bounds {
                s_lo: vec![c; ns],
                s_hi: vec![c; ns],
                l_lo: vec![c; ni],
                l_hi: vec![c; ni],
            }
        })
    }

    /// Sample offsets of the witness windows: [⌈α⌉, ⌊β⌋] (β may be +∞ → usize::MAX).
    fn witness(&self, a: f64, b: f64) -> (usize, usize) {
        let lo = (a / self.h - TOL).ceil().max(0.0) as usize;
        let hi = if b.is_finite() {
            let f = (b / self.h + TOL).floor();
            if f < 0.0 {
                return (1, 0);
            }
            f.min(usize::MAX as f64 / 4.0) as usize
        } else {
            usize::MAX / 4
        };
        (lo, hi)
    }

    /// F_[a,b] of a node's bounds (module doc). `tube`: false for the discrete semantics at samples.
    fn eventually(&self, x: &Bounds, a: f64, b: f64, tube: bool) -> Bounds {
        let (n, ni) = (self.intervals, self.intervals);
        let (wa, wb) = self.witness(a, b);
        let at_zero = a / self.h <= TOL;
        // Lower bounds: witness samples.
        let s_lo = range_ext(
            &x.s_lo,
            (0..=n).map(|k| (k.saturating_add(wa), k.saturating_add(wb).min(n))),
            true,
        );
        if !tube {
            return Bounds {
                s_hi: s_lo.clone(),
                l_lo: s_lo[..ni].to_vec(),
                l_hi: s_lo[..ni].to_vec(),
                s_lo,
            };
        }
        let mut l_lo = range_ext(
            &x.s_lo,
            (0..ni).map(|k| (k + 1 + wa, k.saturating_add(wb).min(n))),
            true,
        );
        if at_zero {
            l_lo.iter_mut()
                .zip(&x.l_lo)
                .for_each(|(o, v)| *o = o.max(*v));
        }
        // Upper bounds: every interval the window meets. Interval i meets [k+α, k+β'] iff
        // i − k ∈ [α − 1, β'], widened to whole samples.
        let alpha = a / self.h;
        let lo_off = (alpha - 1.0 - TOL).ceil().max(-1.0) as i64; // ≥ −1
        let hi_off = |extra: f64| -> usize {
            if b.is_finite() {
                ((b / self.h + extra + TOL).floor().max(0.0)).min(usize::MAX as f64 / 4.0) as usize
            } else {
                usize::MAX / 4
            }
        };
        let (h0, h1) = (hi_off(0.0), hi_off(1.0));
        let meets = |k: usize, hi: usize| -> (usize, usize) {
            // The window starts at k + α; past t_N it is empty.
            if k as f64 + alpha > n as f64 + TOL {
                return (1, 0);
            }
            let lo = (k as i64 + lo_off).max(0) as usize;
            (lo, k.saturating_add(hi).min(ni - 1))
        };
        let s_hi = range_ext(&x.l_hi, (0..=n).map(|k| meets(k, h0)), true);
        let l_hi = range_ext(&x.l_hi, (0..ni).map(|k| meets(k, h1)), true);
        Bounds {
            s_lo,
            s_hi,
            l_lo,
            l_hi,
        }
    }

    /// φ₁ U_[a,b] φ₂ of the bounds (module doc).
    fn until(&self, p1: &Bounds, p2: &Bounds, a: f64, b: f64, tube: bool) -> Bounds {
        let (n, ni) = (self.intervals, self.intervals);
        let (wa, wb) = self.witness(a, b);
        let at_zero = a / self.h <= TOL;
        // What φ₁ must hold over between a start k and a witness j: the intervals k..j−1 (tube) or the
        // samples strictly between (discrete semantics).
        let (hold, from) = if tube { (&p1.l_lo, 0) } else { (&p1.s_lo, 1) };
        let last = |k: usize| k.saturating_add(wb).min(n);
        let s_lo = windowed_until(&p2.s_lo, hold, from, n + 1, |k| {
            (k.saturating_add(wa), last(k) + 1)
        });
        if !tube {
            return Bounds {
                s_hi: s_lo.clone(),
                l_lo: s_lo[..ni].to_vec(),
                l_hi: s_lo[..ni].to_vec(),
                s_lo,
            };
        }
        let mut l_lo = windowed_until(&p2.s_lo, hold, from, ni, |k| {
            ((k + 1).saturating_add(wa), last(k) + 1)
        });
        if at_zero {
            l_lo.iter_mut()
                .zip(&p2.l_lo)
                .for_each(|(o, v)| *o = o.max(*v));
        }
        let up = self.eventually(p2, a, b, true);
        Bounds {
            s_lo,
            s_hi: up.s_hi,
            l_lo,
            l_hi: up.l_hi,
        }
    }
}

/// The atoms' nominal signals, in evaluation order.
fn collect_atoms(
    monitor: &Monitor<'_>,
    node: &Node,
    cols: &[&[f64]],
    len: usize,
    out: &mut Vec<Vec<f64>>,
) -> Result<(), MtlError> {
    match node {
        Node::Const(_) => Ok(()),
        Node::Linear { .. } | Node::Set { .. } => {
            out.push(monitor.atom(node, len, cols, Atoms::Compiled)?);
            Ok(())
        }
        Node::Not(x) | Node::Eventually(_, x) | Node::Always(_, x) => {
            collect_atoms(monitor, x, cols, len, out)
        }
        Node::And(v) | Node::Or(v) => v
            .iter()
            .try_for_each(|x| collect_atoms(monitor, x, cols, len, out)),
        Node::Until(_, l, r) | Node::Release(_, l, r) => {
            collect_atoms(monitor, l, cols, len, out)?;
            collect_atoms(monitor, r, cols, len, out)
        }
    }
}

/// The set index of each atom in evaluation order (`None` for a linear predicate).
fn atom_sets(node: &Node, out: &mut Vec<Option<usize>>) {
    match node {
        Node::Const(_) => {}
        Node::Linear { .. } => out.push(None),
        Node::Set { set, .. } => out.push(Some(*set)),
        Node::Not(x) | Node::Eventually(_, x) | Node::Always(_, x) => atom_sets(x, out),
        Node::And(v) | Node::Or(v) => v.iter().for_each(|x| atom_sets(x, out)),
        Node::Until(_, l, r) | Node::Release(_, l, r) => {
            atom_sets(l, out);
            atom_sets(r, out);
        }
    }
}

/// max (or min) of `v` over the index ranges `lo..=hi` (empty when lo > hi or lo ≥ len: −∞ for max,
/// +∞ for min). Both ends must be non-decreasing over the sequence (clipped ends stay so).
fn range_ext(v: &[f64], ranges: impl Iterator<Item = (usize, usize)>, max: bool) -> Vec<f64> {
    let empty = if max {
        f64::NEG_INFINITY
    } else {
        f64::INFINITY
    };
    let dominates = move |x: f64, y: f64| if max { x >= y } else { x <= y };
    let mut q = Wedge::new();
    let mut pushed = 0usize;
    let mut out = Vec::new();
    for (lo, hi) in ranges {
        if lo > hi || lo >= v.len() {
            out.push(empty);
            continue;
        }
        let end = hi.min(v.len() - 1) + 1;
        while pushed < end {
            q.push(v, pushed, dominates);
            pushed += 1;
        }
        q.expire(lo);
        out.push(q.front().map_or(empty, |j| v[j]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::window::windowed_until;
    use rand::{Rng, SeedableRng};

    /// The until by definition: every witness of every start scanned.
    fn scanned(
        psi: &[f64],
        phi: &[f64],
        from: usize,
        starts: usize,
        window: impl Fn(usize) -> (usize, usize),
    ) -> Vec<f64> {
        (0..starts)
            .map(|k| {
                let (first, last) = window(k);
                (first..=last)
                    .map(|j| {
                        let hold = (k + from..j).map(|i| phi[i]).fold(f64::INFINITY, f64::min);
                        psi[j].min(hold)
                    })
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect()
    }

    /// Random signals with ties and infinities, every window rule the tube's until uses (witnesses from
    /// k + a or k + 1 + a, to k + b or the end, empty windows), both holds: the same values bit for bit.
    #[test]
    fn the_windowed_until_is_the_scan_of_every_witness() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(46);
        for case in 0..400 {
            let n = rng.random_range(1..40usize);
            let mut draw = |len: usize| -> Vec<f64> {
                (0..len)
                    .map(|_| match rng.random_range(0..12) {
                        0 => f64::INFINITY,
                        1 => f64::NEG_INFINITY,
                        _ => rng.random_range(-4..5) as f64 * 0.5,
                    })
                    .collect()
            };
            let psi = draw(n + 1);
            let (tube, from) = if case % 2 == 0 { (true, 0) } else { (false, 1) };
            let phi = draw(if tube { n } else { n + 1 });
            let wa = rng.random_range(0..6usize);
            let wb = if case % 7 == 0 {
                usize::MAX / 4
            } else {
                rng.random_range(0..12usize)
            };
            let starts = if case % 3 == 0 { n } else { n + 1 };
            let shift = (case % 3 == 0) as usize;
            let window = |k: usize| ((k + shift).saturating_add(wa), k.saturating_add(wb).min(n));
            let fast = windowed_until(&psi, &phi, from, starts, |k| {
                let (first, last) = window(k);
                (first, last + 1)
            });
            let slow = scanned(&psi, &phi, from, starts, window);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&fast),
                bits(&slow),
                "case {case}: n {n}, a {wa}, b {wb}, tube {tube}"
            );
        }
    }
}
